"""The synthetic demonstrator (SPEC 10) drives the packaged courses cleanly, deterministically and
like a person holding a gamepad, without looking at the planner's features."""

from __future__ import annotations

import ast
import inspect
from dataclasses import dataclass, replace

import numpy as np
import pytest

import terrapref.demos.expert as expert_module
from terrapref.demos.expert import ExpertConfig, ExpertDriver
from terrapref.evaluation import RunMetrics, score_run
from terrapref.scenario import Scenario, resolve_scenario
from terrapref.sim import EpisodeLog, SimConfig, Simulation, run_episode
from terrapref.terrain import PreferenceProfile


@dataclass
class DrivenRun:
    scenario: Scenario
    sim: Simulation
    log: EpisodeLog
    metrics: RunMetrics

    @property
    def frame_poses(self) -> np.ndarray:
        """Pose at each decision, shape (F, 3): the trace holds every controller tick."""
        return self.log.trace[:: self.sim.config.ticks_per_frame][: len(self.log.commands)]


def _drive(name: str, seed: int, config: SimConfig | None = None) -> DrivenRun:
    scenario = resolve_scenario(name)
    sim = Simulation(scenario, config=config)
    log = run_episode(sim, ExpertDriver(), np.random.default_rng(seed))
    metrics = score_run(log, scenario, sim.world, PreferenceProfile.default())
    return DrivenRun(scenario, sim, log, metrics)


def _assert_clean(run: DrivenRun) -> None:
    failed = [(z.id, z.label, f"chose {z.choice}, expected {z.expect}", z.distance_m) for z in run.metrics.zones if not z.success]
    assert run.log.completed, f"did not reach the goal in {run.log.duration_s} s"
    assert run.log.collisions == 0
    assert len(run.metrics.zones) == len(run.scenario.zones) > 0
    assert not failed, failed


@pytest.fixture(scope="module")
def train_seed0() -> DrivenRun:
    return _drive("train_course", 0)


# --- driving the courses ----------------------------------------------------------------------


def test_train_course_every_zone_succeeds(train_seed0: DrivenRun):
    _assert_clean(train_seed0)
    assert len(train_seed0.metrics.zones) == 10


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(5))
def test_train_course_every_zone_succeeds_for_every_seed(seed: int):
    _assert_clean(_drive("train_course", seed))


def test_test_course_every_zone_succeeds():
    run = _drive("test_course", 0)
    _assert_clean(run)
    assert len(run.metrics.zones) == 7


# --- driving like a person with a gamepad ------------------------------------------------------


def test_commands_stay_in_the_joystick_range(train_seed0: DrivenRun):
    cmd = train_seed0.log.commands
    assert len(cmd) > 3000  # about 5.5 minutes at 10 Hz
    np.testing.assert_array_equal(cmd[:, 0], 1.0)
    assert np.all(np.abs(cmd[:, 1]) <= 1.0)


def test_stick_rests_at_exactly_zero_on_a_clear_straight(train_seed0: DrivenRun):
    # train_course starts at (5, 10) on a straight trail along +x; its first patch begins at x = 23.5.
    poses = train_seed0.frame_poses
    assert poses[0, 0] == pytest.approx(5.0) and poses[0, 2] == pytest.approx(0.0)
    first_10_m = poses[:, 0] < 15.0
    assert first_10_m.sum() >= 95  # 10 m at 1 m/s, 10 frames a second
    w = train_seed0.log.commands[first_10_m, 1]
    assert np.all(w == 0.0), f"stick moved on the clear straight: {w[w != 0.0][:5]}"
    # ...and it does move for the patches later on.
    assert np.any(train_seed0.log.commands[:, 1] != 0.0)


def test_the_stick_returns_to_exactly_zero_after_a_detour(train_seed0: DrivenRun):
    w = train_seed0.log.commands[:, 1]
    after = w[np.flatnonzero(w != 0.0)[0] :]
    # After the first detour the stick comes back to rest for whole seconds, not near-zero jitter.
    edges = np.diff(np.concatenate([[0], (after == 0.0).astype(int), [0]]))
    rest_frames = np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)
    assert rest_frames.size >= 2 and rest_frames.max() >= 10, rest_frames


# --- determinism (STYLE 6) ----------------------------------------------------------------------


def test_same_seed_same_trace_other_seed_differs():
    # The first 25 s of demo_course: a lone water patch and the mud-vs-rock pair, where the
    # seeded tremor and side choices act.
    config = SimConfig(time_limit_s=25.0)
    a, b, c = (_drive("demo_course", seed, config).log for seed in (0, 0, 1))
    np.testing.assert_array_equal(a.trace, b.trace)
    np.testing.assert_array_equal(a.commands, b.commands)
    assert a.trace.shape == c.trace.shape
    assert not np.array_equal(a.commands, c.commands)
    assert not np.array_equal(a.trace, c.trace)


def test_reset_restarts_the_driver():
    scenario = resolve_scenario("demo_course")
    config = SimConfig(time_limit_s=15.0)
    driver = ExpertDriver()
    first = run_episode(Simulation(scenario, config=config), driver, np.random.default_rng(7))
    again = run_episode(Simulation(scenario, config=config), driver, np.random.default_rng(7))
    np.testing.assert_array_equal(first.trace, again.trace)


# --- independence from the learner (SPEC 10) ---------------------------------------------------


def test_driver_never_imports_the_feature_pipeline():
    tree = ast.parse(inspect.getsource(expert_module))
    imported: list[str] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            imported += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            imported.append(node.module or "")
    assert imported  # the walk did find the imports
    assert not [m for m in imported if m == "terrapref.features" or m.startswith("terrapref.features.")]
    for name, value in vars(expert_module).items():
        owner = getattr(value, "__module__", "") or ""
        assert not owner.startswith("terrapref.features"), f"{name} comes from {owner}"


def test_expert_config_to_dict_is_plain_data():
    data = ExpertConfig().to_dict()
    assert data["profile"] == ["mud", "rock", "water", "non_traversable"]
    assert data["speed_mps"] == 1.0
    assert all(v is None or isinstance(v, (int, float, str, list)) for v in data.values())


@pytest.mark.parametrize("n_f", [4, 5, 7, 9])
def test_offset_costs_and_hits_give_the_numpy_forms(n_f: int):
    """The driver's per-offset costs and lethal hits, compiled, against the NumPy expressions they
    replace over _offset_classes: the same bits (NumPy's summation order), the same hits."""
    rng = np.random.default_rng(n_f)
    raster = rng.integers(0, 5, (300, 400)).astype(np.uint8)
    raster[rng.random(raster.shape) < 0.001] = 5  # lethal here and there
    cost = rng.random(256) * 10.0 ** rng.integers(-3, 3, 256)  # magnitudes apart: a different order would show
    lethal = np.zeros(256, dtype=bool)
    lethal[5] = True
    for upto in (1, 7, 8, 49, 128):
        centre = np.stack([rng.uniform(-2.0, 22.0, upto), rng.uniform(-2.0, 17.0, upto)], axis=1)  # some points off the map
        heading = rng.uniform(-np.pi, np.pi, upto)
        normal = np.stack([-np.sin(heading), np.cos(heading)], axis=1)
        lat = np.round(rng.uniform(-3.0, 3.0, 30), 6)[:, None] + np.linspace(-0.9, 0.9, n_f)[None, :]
        classes = expert_module._offset_classes(centre, normal, lat, upto, raster, 0.05)
        got = expert_module._offset_costs(centre, normal, lat, upto, raster, 0.05, cost)
        want = cost[classes].mean(axis=2).sum(axis=1)
        assert np.array_equal(got.view(np.int64), want.view(np.int64)), upto
        hits = expert_module._offset_hits(centre, normal, lat, upto, raster, 0.05, lethal)
        assert np.array_equal(hits, lethal[classes].any(axis=(1, 2))), upto
        assert upto < 49 or (hits.any() and not hits.all())  # the long reaches hit on some offsets only


def _disc_ahead(centre_y: float, radius_m: float) -> Scenario:
    """A straight path along y = 10 from x = 2, with a lethal disc centred at x = 20."""
    from terrapref.scenario import parse_scenario

    return parse_scenario(
        {
            "format": "terrapref-scenario/1",
            "name": "disc_ahead",
            "world": {"size_m": [40.0, 20.0], "resolution_m": 0.05, "background": "grass"},
            "terrain": [{"class": "non_traversable", "circle": {"center": [20.0, centre_y], "radius": radius_m}}],
            "path": {"waypoints": [[2.0, 10.0], [38.0, 10.0]]},
        }
    )


def _committed(scenario: Scenario, held_m: float) -> ExpertDriver:
    driver = ExpertDriver(ExpertConfig.styled("shaky"))
    driver.reset(scenario, np.random.default_rng(0))
    driver.offset = held_m
    return driver


class _Scripted(ExpertDriver):
    """A driver whose offsets are scripted up to given distances along the path, its own after."""

    def __init__(self, script: list[tuple[float, float]], way_check: bool) -> None:
        super().__init__(replace(ExpertConfig.styled("shaky"), stick_noise_rps=0.0))
        self.script, self.way_check = script, way_check

    def choose_offset(self, s_now: float, pose=None, v_mps=None) -> float:
        for until_m, offset_m in self.script:
            if s_now < until_m:
                return offset_m
        return super().choose_offset(s_now, pose if self.way_check else None, v_mps)


def test_a_driver_late_in_front_of_lethal_terrain_keeps_to_its_side():
    """A lethal disc on the path reaches 1.45 m left of it and 1.25 m right. The driver heads
    for 2.4 m left of the path from 5.5 m before the disc, and decides on its own 1.4 m later:
    the left line at 2.4 m is then grazed (it keeps 1.4 m), the right one at 2.4 m is clear and
    cheaper than the left one at 2.6 m. By the lines alone it swaps sides and cuts across the
    disc; its way to the right checked as its hand would steer it, it keeps left."""
    scenario = _disc_ahead(10.1, 1.35)
    edge_m = 20.0 - 1.35 - 2.0  # the disc's near edge along the path
    script = [(edge_m - 5.5, 0.0), (edge_m - 4.1, 2.4)]
    contact_s = {}
    for way_check in (False, True):
        driver = _Scripted(script, way_check)
        sim = Simulation(scenario)
        frame = sim.reset()
        driver.reset(scenario, np.random.default_rng(0))
        offsets = set()
        while frame.pose[0] < 26.0:
            frame = sim.step(driver.act(frame))
            offsets.add(driver.offset)
        contact_s[way_check] = sim.contact_s
        assert min(offsets) < 0.0 if not way_check else max(offsets) >= 2.6
    assert contact_s[False] > 0.5 and contact_s[True] == 0.0


def test_the_way_check_passes_a_driver_settled_on_a_clear_line_and_flags_one_too_late():
    scenario = _disc_ahead(10.0, 1.0)
    driver = _committed(scenario, 2.4)

    def way_hits(s_now: float, lateral_m: float) -> np.ndarray:
        s = s_now + driver._s_rel
        centre, heading = driver.path.point_at(s), driver.path.heading_at(s)
        return driver._way_hits((s - s_now, len(s), centre, heading), (2.0 + s_now, 10.0 + lateral_m, 0.0), 1.4)

    hits, offsets = way_hits(10.0, 2.4), driver.offsets
    # On its line and straight: nothing pending, the way is the line, and lines 1.6 m or more
    # from the path clear a disc of 1 m (the footprint's half-width 0.6 m).
    assert not hits[np.isclose(offsets, 2.4)].any()
    assert hits[np.abs(offsets) < 0.8].all()  # the path itself crosses the disc
    # On the path 1.5 m before the disc: no way off it is quick enough (the path's own way is
    # its line, which the line's check flags).
    assert way_hits(15.5, 0.0)[offsets != 0.0].all()


@pytest.mark.parametrize(("s_now", "lateral_m", "held_m"), [(10.0, 2.4, 2.4), (11.0, 0.5, 2.4), (12.0, 0.0, 0.0), (15.5, 0.0, 0.0)])
@pytest.mark.parametrize("can_hold", [False, True])
def test_following_only_the_ways_that_can_decide_decides_as_following_every_way(
    s_now: float, lateral_m: float, held_m: float, can_hold: bool
):
    driver = _committed(_disc_ahead(10.1, 1.35), held_m)
    s = s_now + driver._s_rel
    stations = (s - s_now, len(s), driver.path.point_at(s), driver.path.heading_at(s))
    pose = (2.0 + s_now, 10.0 + lateral_m, 0.0)
    rng = np.random.default_rng(int(s_now))
    terrain = rng.choice([0.0, 1000.0], len(driver.offsets), p=[0.8, 0.2]) + rng.uniform(0.0, 3.0, len(driver.offsets))
    detour = 0.08 * driver.offsets**2 * 10.0
    held = int(np.argmin(np.abs(driver.offsets - held_m)))

    def decision(total: np.ndarray) -> object:  # choose_offset's: the hold, else the best and its ties
        best = total.min()
        if can_hold and total[held] <= best * 1.15 + 1e-6:
            return "hold"
        return best, tuple(np.flatnonzero(total <= best + 1e-6))

    every = (terrain + driver._way_hits(stations, pose, 1.4) * 1000.0) + detour
    some = driver._way_totals(terrain, detour, (held, can_hold), stations, pose, 1.4)
    assert decision(some) == decision(every)
