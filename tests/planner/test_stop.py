"""The planner's stop rule (terrapref.planner.stop), unknown ids at the boundary, contact counted
under the whole footprint, and scores that count only what was driven."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from helpers import linear_model
from terrapref.errors import UserError
from terrapref.evaluation.runner import PURE_PURSUIT, RunSpec, run_one, summarise
from terrapref.evaluation.scoring import NOT_REACHED, score_run, score_zones
from terrapref.features import FeatureConfig
from terrapref.interop.labels import parse_label_map
from terrapref.interop.robot import load_robot
from terrapref.learning.linear import LinearUtility
from terrapref.perception.model import load_perception
from terrapref.planner import Planner, PlannerDriver
from terrapref.planner.policy import LinearPolicy, PurePursuitPolicy
from terrapref.planner.stop import StopConfig, StopRule
from terrapref.runtime import PlannerRuntime
from terrapref.scenario import resolve_scenario
from terrapref.sim import SimConfig, Simulation, run_episode
from terrapref.stops import BLIND, NO_FREE_WAY, STALE
from terrapref.terrain import PreferenceProfile, default_classes
from terrapref.terrain.classes import UNKNOWN, ForeignIds, load_classes
from terrapref.vehicle import Command, Pose
from terrapref.world import rasterise

PROFILE = ("mud", "rock", "water", "non_traversable")
WALL = """format: terrapref-scenario/1
name: wall
world: {size_m: [40.0, 20.0], resolution_m: 0.05, background: grass}
terrain:
  - {class: non_traversable, rectangle: {center: [20.0, 10.0], size: [2.0, 20.0], yaw_deg: 0.0}}
path: {waypoints: [[2.0, 10.0], [38.0, 10.0]]}
zones:
  - {id: "1", label: beyond the wall, rectangle: {center: [30.0, 10.0], size: [6.0, 6.0], yaw_deg: 0.0}, expect: avoid}
"""
OPEN = WALL.replace("  - {class: non_traversable, rectangle: {center: [20.0, 10.0], size: [2.0, 20.0], yaw_deg: 0.0}}\n", "").replace(
    "terrain:\n", "terrain: []\n"
)


@pytest.fixture(scope="module")
def wall(tmp_path_factory) -> str:
    path = tmp_path_factory.mktemp("stop") / "wall.yaml"
    path.write_text(WALL)
    return str(path)


@pytest.fixture(scope="module")
def model(tmp_path_factory) -> Path:
    return linear_model(tmp_path_factory.mktemp("stop_model") / "linear.safetensors")


# --- the rule's settings --------------------------------------------------------------------------


def test_the_stopping_distance_is_reaction_braking_and_margin():
    c = StopConfig(reaction_s=0.2, decel_mps2=1.0, margin_m=0.3)
    assert c.stopping_distance_m(1.0) == pytest.approx(0.2 + 0.5 + 0.3)  # 1 m/s: 0.2 m reacting, 0.5 m braking
    assert c.stopping_distance_m(2.0) == pytest.approx(0.4 + 2.0 + 0.3)  # twice the speed, four times the braking
    assert c.stopping_distance_m(0.0) == pytest.approx(0.3)


@pytest.mark.parametrize(
    "bad",
    [
        {"decel_mps2": 0.0},
        {"margin_m": -0.1},
        {"seen_share": 0.0},
        {"seen_share": 1.5},
        {"arcs": 0},
        {"reaction_s": math.nan},
        {"look_m": math.inf},
        {"arcs": True},
    ],
)
def test_bad_settings_are_refused(bad: dict):
    with pytest.raises(ValueError):
        StopConfig(**bad)


@pytest.mark.parametrize(
    ("name", "value"),
    [
        ("step_m", 5.0),
        ("step_m", 1e9),
        ("look_m", 1e9),
        ("arcs", 10**8),
        ("decel_mps2", 1e3),
        ("blind_after_s", 1e9),
        ("lethal_evidence", 1e300),
    ],
)
def test_settings_past_what_they_can_mean_are_refused_naming_the_setting(name: str, value: float):
    """A step of 5 m between the points checked along each way stepped over the lethal ground
    ahead (the vehicle drove at it at full speed); a look 1e9 m ahead asked for 75 GB; 10^8 arcs
    never finished a decision."""
    with pytest.raises(ValueError, match=f"^{name} must be at most"):
        StopConfig(**{name: value})
    StopConfig(**{name: {"arcs": 201}.get(name, 0.5 if name == "step_m" else 10.0)})  # the bound itself is taken


# --- stopping in the simulator ---------------------------------------------------------------------


@pytest.mark.parametrize("driver", ["linear", PURE_PURSUIT])
def test_a_wall_of_lethal_terrain_across_the_map_ends_in_a_stop_not_in_contact(wall: str, model: Path, driver: str):
    spec = RunSpec(wall, 0, "planner" if driver == "linear" else driver, str(model) if driver == "linear" else None, PROFILE)
    m = run_one(spec).metrics
    assert m.collisions == 0 and m.contact_s == 0.0
    assert m.ended == "stopped" and not m.completed and set(m.stops_s) == {NO_FREE_WAY}
    assert 17.5 < m.progress_m + 2.0 < 19.0  # stood still with the footprint's front about a metre short of the wall at x = 19
    assert [z.choice for z in m.zones] == [NOT_REACHED] and not m.zones[0].success


def test_a_decision_picture_of_a_stop_says_the_planner_stood(wall: str, model: Path, tmp_path: Path):
    """A frame kept for a picture where the planner stood: the picture said "chosen" and "planner's
    choice" over the steering's way while the vehicle stood still."""
    from terrapref import plots

    result = run_one(RunSpec(wall, 0, "planner", str(model), PROFILE, keep_frames=(5, 300)))
    moving, standing = result.frames
    assert moving.stop is None and standing.stop == NO_FREE_WAY
    drawn = []
    original = plots.Line2D
    plots.Line2D = lambda *a, **kw: drawn.append(kw.get("label")) or original(*a, **kw)
    try:
        uv, visible = np.zeros((21, 2, 2)), np.ones((21, 2), dtype=bool)
        plots.save_decision(
            tmp_path / "d.png",
            np.zeros((480, 640, 3), np.uint8),
            plots.Decision(uv, visible, standing.probs, standing.index, [0.0] * 21, standing.stop),
        )
    finally:
        plots.Line2D = original
    assert drawn[0] == "the steering's choice; the planner stood (no_free_way)"


def test_a_planner_whose_own_way_is_blocked_drives_the_nearest_free_one_rather_than_its_own(tmp_path: Path):
    # Pure pursuit knows no terrain: from the start, 5 m right of the path, it heads for the path
    # and so for a lethal strip that begins 0.5 m left of it, under the footprint's left edge. A
    # way to its right stays free all along, so the stop rule never stops it; the command driven
    # is then that way, not pure pursuit's own, and it runs beside the strip to the goal.
    scenario = resolve_scenario(_strip_scenario(tmp_path, 10.5))
    driver = PlannerDriver(Planner(PurePursuitPolicy()), keep=True)
    log = run_episode(Simulation(scenario), driver, np.random.default_rng(0))
    assert log.collisions == 0 and log.contact_s == 0.0
    assert log.completed and NO_FREE_WAY not in log.stops  # some way was free at every frame
    # Right of the path, pure pursuit turns left to it; the commands turned right, off the strip.
    assert any(d.command[1] < 0 and d.stop is None for d in driver.decisions)


def test_the_planner_says_why_it_stops_and_the_run_counts_it(wall: str):
    scenario = resolve_scenario(wall)
    driver = PlannerDriver(Planner(PurePursuitPolicy()), keep=True)
    log = run_episode(Simulation(scenario), driver, np.random.default_rng(0))
    stopped = [d for d in driver.decisions if d.stop is not None]
    assert stopped and all(d.stop == NO_FREE_WAY and tuple(d.command) == (0.0, 0.0) for d in stopped)
    assert all(d.stop is None and d.command[0] > 0 for d in driver.decisions[: -len(stopped)])  # it drove until it stopped
    assert log.stop_count == 1 and log.stops[NO_FREE_WAY] == pytest.approx(0.1 * len(stopped))


def test_blind_frames_stop_the_planner_before_the_lethal_patch_it_avoids_on_clean_frames(tmp_path: Path, model: Path):
    blind = tmp_path / "blind.yaml"
    blind.write_text("format: terrapref-perception/1\nlabels:\n  max_range_m: 0.1\n")
    m = run_one(RunSpec("demo_course", 0, "planner", str(model), PROFILE, perception=load_perception(str(blind)))).metrics
    assert m.collisions == 0 and m.ended == "stopped" and m.progress_m < 1.0
    assert m.stops_s.get(BLIND, 0.0) > 15.0
    assert all(z.choice == NOT_REACHED and not z.success for z in m.zones)  # a run that never moved scores nothing


def test_a_run_that_never_moved_scores_zero_and_says_why(tmp_path: Path, model: Path):
    blind = tmp_path / "blind.yaml"
    blind.write_text("format: terrapref-perception/1\nlabels:\n  max_range_m: 0.1\n")
    result = run_one(RunSpec("demo_course", 0, "planner", str(model), PROFILE, perception=load_perception(str(blind))))
    s = summarise([result], "planner")
    assert s.zone_success_rate == 0.0 and s.not_reached == s.zones == 3 and s.completed_rate == 0.0
    text = " ".join(s.driving_lines())
    assert "3 of 3 zones not reached" in text and "blind" in text and "stopped 1" in text


def test_a_linear_model_with_nan_weights_is_not_flattered(tmp_path: Path):
    features = FeatureConfig()
    policy = LinearPolicy(LinearUtility(np.full(features.n_features, np.nan), np.zeros(features.preference.m)), features)
    scenario = resolve_scenario("demo_course")
    sim = Simulation(scenario, config=None)
    log = run_episode(sim, PlannerDriver(Planner(policy)), np.random.default_rng(0))
    m = score_run(log, scenario, sim.world, PreferenceProfile.parse(list(PROFILE), scenario.classes))
    assert not m.completed and m.zone_successes == 0  # it circles: no zone reached is a success


# --- the runtime: blind, all lethal, unknown ids ----------------------------------------------------


def _runtime(model: Path, **kwargs) -> PlannerRuntime:
    runtime = PlannerRuntime(model, **kwargs)
    runtime.set_path(np.array([[0.0, 0.0], [30.0, 0.0]]))
    return runtime


def _ground(
    runtime: PlannerRuntime, class_id: int, patch: Callable[[np.ndarray], np.ndarray] | None = None, patch_id: int = 0
) -> np.ndarray:
    """A frame whose ground pixels all show ``class_id`` (the sky 255), or ``patch_id`` where
    ``patch`` holds (given each pixel's ground point (H, W, 2) in the vehicle frame [m])."""
    camera = runtime.planner.camera
    h, w = camera.shape
    v, u = np.mgrid[0:h, 0:w]
    points, hit = camera.back_project(np.stack([u + 0.5, v + 0.5], axis=-1))
    ids = np.where(patch(points), patch_id, class_id) if patch is not None else class_id
    return np.where(hit, ids, UNKNOWN).astype(np.uint8)


def test_every_pixel_unknown_stops_the_runtime_and_a_clear_frame_moves_it_on(model: Path):
    runtime = _runtime(model)
    covered = np.full(runtime.shape, UNKNOWN, np.uint8)
    reasons = [runtime.decide(covered, 0.1 * i, (0.0, 0.0, 0.0)).stop for i in range(8)]
    assert reasons[0] == NO_FREE_WAY  # nothing seen yet: no way is known to be free
    assert reasons[5:] == [BLIND] * 3  # 0.5 s of covered frames: blind
    grass = _ground(runtime, default_classes().id_of("grass"))
    reasons = [runtime.decide(grass, 0.8 + 0.1 * i, (0.0, 0.0, 0.0)).stop for i in range(5)]
    assert reasons == [NO_FREE_WAY] * 3 + [None] * 2  # a free way for resume_after_s (0.3 s): it moves on
    d = runtime.last
    assert d.command[0] > 0 and runtime.status_at(d.stamp_s + 0.05) == (d.command, None)
    assert runtime.status_at(d.stamp_s + 2.0) == (Command(0.0, 0.0), STALE)  # no fresh frame: stale


def test_every_ground_pixel_lethal_stops_the_runtime(model: Path):
    runtime = _runtime(model)
    lethal = _ground(runtime, default_classes().id_of("non_traversable"))
    for i in range(3):
        d = runtime.decide(lethal, 0.1 * i, (0.0, 0.0, 0.0))
        assert d.stop == NO_FREE_WAY and tuple(d.command) == (0.0, 0.0)


def test_the_way_driven_is_the_commands_own_where_free_else_the_nearest_free_one(model: Path):
    runtime = _runtime(model)
    classes = default_classes()

    def ahead(points: np.ndarray) -> np.ndarray:  # a lethal patch straight ahead
        return (points[..., 0] > 0.8) & (points[..., 0] < 2.0) & (np.abs(points[..., 1]) < 0.3)

    frame = _ground(runtime, classes.id_of("grass"), ahead, classes.id_of("non_traversable"))
    for i in range(3):
        runtime.decide(frame, 0.1 * i, (0.0, 0.0, 0.0))
    rule, ground = runtime.planner.stop_rule, runtime.planner._stop_map
    pose = Pose(0.0, 0.0, 0.0)
    free = [float(r) for r in rule.yaw_rates if rule.arc_free(ground, pose, 1.0, r)]
    assert free and not rule.arc_free(ground, pose, 1.0, 0.0)  # straight ahead is closed, some way is not
    for own in free:
        assert rule.way_rps(ground, pose, 1.0, own) == own  # a command whose own way is free is driven as it is
    for own in (0.0, -0.05, 0.33, -1.0, 1.0):
        if not rule.arc_free(ground, pose, 1.0, own):  # else the free way nearest to it, the lower on a tie
            assert rule.way_rps(ground, pose, 1.0, own) == min(free, key=lambda r: (abs(r - own), r))
    lethal = _ground(runtime, classes.id_of("non_traversable"))
    for i in range(3, 8):
        runtime.decide(lethal, 0.1 * i, (0.0, 0.0, 0.0))
    assert rule.way_rps(ground, pose, 1.0, 0.0) is None and runtime.last.stop == NO_FREE_WAY


def test_ids_no_class_table_names_are_refused_or_unknown_by_choice(model: Path):
    runtime = _runtime(model)
    frame = _ground(runtime, 0)
    frame[400:410, 300:310] = 7  # an id the default table does not name
    with pytest.raises(ValueError, match=r"class id 7 .*not in the model's class table"):
        runtime.decide(frame, 0.0, (0.0, 0.0, 0.0))
    assert runtime.last is None  # nothing decided on
    lenient = _runtime(model, unknown_ids="unknown")
    assert lenient.decide(frame, 0.0, (0.0, 0.0, 0.0)) is not None
    with pytest.raises(ValueError, match="unknown_ids"):
        _runtime(model, unknown_ids="ignore")


def test_ids_a_label_map_does_not_list_are_refused_unless_it_says_unknown(model: Path):
    strict = parse_label_map({"format": "terrapref-labels/1", "name": "net", "ids": {10: "grass", 11: "mud"}}, "net.yaml")
    frame = np.full((480, 640), 10, np.uint16)
    frame[470:, :4] = 12
    with pytest.raises(ValueError, match=r"label id 12 in a label image not listed.*unlisted: unknown.*net\.yaml"):
        _runtime(model, labels=strict).decide(frame, 0.0, (0.0, 0.0, 0.0))
    lenient = parse_label_map(
        {"format": "terrapref-labels/1", "name": "net", "ids": {10: "grass", 11: "mud"}, "unlisted": "unknown"}, "net.yaml"
    )
    assert _runtime(model, labels=lenient).decide(frame, 0.0, (0.0, 0.0, 0.0)) is not None
    with pytest.raises(UserError, match="unlisted"):
        parse_label_map({"format": "terrapref-labels/1", "ids": {1: "grass"}, "unlisted": "ignore"}, "bad.yaml")


def test_foreign_ids_are_found_in_any_table(tmp_path: Path):
    sparse = tmp_path / "sparse.yaml"
    sparse.write_text("""format: terrapref-classes/1
name: sparse
background: grass
lethal: [tree]
classes:
  - {id: 3, name: grass, color: [0, 128, 0]}
  - {id: 9, name: mud, color: [120, 80, 40]}
  - {id: 200, name: tree, color: [20, 60, 20]}
profile: [mud, tree]
""")
    foreign = ForeignIds(load_classes(sparse))
    image = np.full((4, 5), 3, np.uint8)
    assert foreign(image) == []
    image[0, 0], image[1, 1], image[2, 2], image[3, 3] = 255, 9, 200, 0
    assert foreign(image) == [0]
    image[0, 1], image[0, 2] = 201, 254
    assert foreign(image) == [0, 201, 254]
    assert foreign.unnamed not in (3, 9, 200, 255)


# --- contact under the footprint ---------------------------------------------------------------------


def _strip_scenario(tmp_path: Path, y_min: float) -> str:
    """A straight path along y = 10 with a lethal strip from ``y_min`` to 20, beside it; the file's
    start is clear of it (a file may not start on lethal terrain), the tests put the vehicle there."""
    text = WALL.replace("center: [20.0, 10.0], size: [2.0, 20.0]", f"center: [20.0, {(y_min + 20.0) / 2}], size: [40.0, {20.0 - y_min}]")
    text += "start: [2.0, 5.0, 0.0]\n"
    path = tmp_path / "strip.yaml"
    path.write_text(text)
    return str(path)


def test_contact_counts_under_the_whole_footprint_not_only_its_centre(tmp_path: Path):
    scenario = resolve_scenario(_strip_scenario(tmp_path, 10.4))  # the strip starts 0.4 m left of the path: under the footprint
    sim = Simulation(scenario, config=SimConfig.paper())  # at 1 m/s from the first tick
    sim.reset(Pose(2.0, 10.0, 0.0))
    assert sim.collisions == 1 and sim.started_in_contact  # a start in contact is a collision
    for _ in range(10):
        sim.step(Command(1.0, 0.0))
    assert sim.collisions == 1  # one entry, held
    assert sim.contact_s == pytest.approx(1.0) and sim.contact_m == pytest.approx(1.0)  # every tick counted, 1 s at 1 m/s


def test_contact_is_counted_wherever_it_starts_and_in_every_zone(tmp_path: Path):
    scenario = resolve_scenario(_strip_scenario(tmp_path, 9.0))  # the path itself runs on lethal terrain
    scenario = replace(scenario, start=(2.0, 10.0, 0.0))  # on it from the start, as a seed's shifted start may be
    sim = Simulation(scenario)
    log = run_episode(sim, _Straight(), np.random.default_rng(0))
    assert log.collisions == 1 and log.contact_s > 30.0
    m = score_run(log, scenario, sim.world, PreferenceProfile.parse(list(PROFILE), scenario.classes))
    assert m.contact_s == pytest.approx(log.contact_s, abs=1e-3) and m.zones[0].touched_lethal and not m.zones[0].success


class _Straight:
    """Drives straight ahead at 1 m/s."""

    def reset(self, scenario, rng) -> None: ...

    def act(self, frame) -> Command:
        return Command(1.0, 0.0)


def test_a_zone_the_run_did_not_get_past_is_not_reached(tmp_path: Path):
    path = tmp_path / "open.yaml"
    path.write_text(OPEN)
    scenario = resolve_scenario(str(path))
    world = rasterise(scenario)
    profile = PreferenceProfile.parse(list(PROFILE), scenario.classes)
    xs = np.arange(2.0, 29.0, 0.05)  # stops inside the zone (x 27 to 33), short of where the path leaves it
    trace = np.stack([xs, np.full_like(xs, 10.0), np.zeros_like(xs)], axis=1)
    (inside,) = score_zones(trace, scenario, world, profile, progress_m=27.0)
    assert not inside.reached and inside.choice == NOT_REACHED and not inside.success
    xs = np.arange(2.0, 36.0, 0.05)
    trace = np.stack([xs, np.full_like(xs, 10.0), np.zeros_like(xs)], axis=1)
    (past,) = score_zones(trace, scenario, world, profile, progress_m=34.0)
    assert past.reached and past.choice == "avoid" and past.success


# --- the Gymnasium env and the robot file --------------------------------------------------------------


def test_the_env_refuses_a_start_in_contact(tmp_path: Path):
    from terrapref.sim.env import OffRoadNavEnv

    env = OffRoadNavEnv(_strip_scenario(tmp_path, 10.4))
    with pytest.raises(ValueError, match="footprint on lethal terrain"):
        env.reset(seed=0, options={"start": [5.0, 10.0, 0.0]})
    env.reset(seed=0, options={"start": [5.0, 9.0, 0.0]})  # clear of it: fine


def test_the_robot_file_sets_the_stop_rule(tmp_path: Path):
    from synthetic_bag import robot_yaml, write_robot

    robot = write_robot(tmp_path / "robot.yaml", robot_yaml() + "stop:\n  decel_mps2: 0.5\n  margin_m: 0.5\n")
    assert load_robot(robot).stop == StopConfig(decel_mps2=0.5, margin_m=0.5)
    assert load_robot(write_robot(tmp_path / "plain.yaml")).stop == StopConfig()
    for tail, field in [
        ("stop:\n  brake: 1.0\n", "stop.brake"),
        ("stop:\n  decel_mps2: fast\n", "stop.decel_mps2"),
        ("stop:\n  decel_mps2: -1\n", "stop"),
        ("stop: 3\n", "stop"),
    ]:
        with pytest.raises(UserError) as info:
            load_robot(write_robot(tmp_path / "bad.yaml", robot_yaml() + tail))
        (line,) = info.value.lines()
        assert "bad.yaml" in line and f"{field}:" in line, line


def test_the_rule_reads_the_offset_stages_map_and_keeps_its_own_otherwise(model: Path):
    from terrapref.learning.model_file import load_model

    planner = Planner(load_model(model))  # C's argmax: it reads no map, the stop rule its own small one
    assert planner.ground_map is None and planner._stop_map.settings == StopRule.map_settings
    assert 0.4 <= planner.stop_rule.near_m < 0.5  # the footprint's whole width is in view from the image's bottom edge, 0.43 m (SPEC 5)


def test_the_offset_stage_stops_at_the_wall_reading_its_own_ground_map(tmp_path: Path, wall: str):
    from test_offset_rule import DRIVER_LIKE, _offset_meta

    from helpers import skip_path_weights
    from terrapref.learning.model_file import load_model, save_model
    from terrapref.learning.network import ClassifierConfig

    config = ClassifierConfig(hidden=8, skip=True)
    path = save_model(tmp_path / "offset.safetensors", config, skip_path_weights(config), _offset_meta(DRIVER_LIKE))
    planner = Planner(load_model(path))
    assert planner._stop_map is planner.ground_map is not None and len(planner._maps) == 1  # one map, the stage's
    m = run_one(RunSpec(wall, 0, "planner", str(path), PROFILE)).metrics
    assert m.collisions == 0 and m.ended == "stopped" and set(m.stops_s) == {NO_FREE_WAY}


@pytest.mark.slow  # a whole drive, course or training end to end; the default run keeps the test suite's time
def test_a_runs_mcap_says_when_and_why_the_planner_stopped(tmp_path: Path, wall: str, model: Path):
    from rosbags.highlevel import AnyReader

    from terrapref.evaluation.evaluate import Evaluation, evaluate_model
    from terrapref.grid import Engine

    evaluate_model(Evaluation(str(model), (wall,), seeds=1, with_driver=False, mcap=True), tmp_path / "ev", engine=Engine(workers=1))
    (path,) = (tmp_path / "ev" / "runs").glob("*.mcap")
    with AnyReader([path]) as reader:
        connections = [c for c in reader.connections if c.topic == "/terrapref/status"]
        said = [reader.deserialize(raw, c.msgtype).data for c, _, raw in reader.messages(connections=connections)]
    assert said[0] == "driving" and said[-1].startswith("stopped: no_free_way (")
    assert said.index(said[-1]) == said.count("driving")  # it drove, then stood, and never drove again


@pytest.mark.slow  # a whole drive or export end to end, its steps tested apart in the default run
def test_a_drive_through_lethal_terrain_says_so_and_training_on_it_warns(tmp_path: Path, wall: str, capsys):
    from terrapref.cli import main
    from terrapref.cli.train import _warn_recordings
    from terrapref.demos.recording import read_recording

    rec = tmp_path / "rec"
    assert main(["record", wall, "--out", str(rec), "--quiet"]) == 0  # the synthetic driver cannot go round a wall: it crosses
    out = capsys.readouterr().out
    assert "1 collisions (" in out and "with lethal terrain under the vehicle" in out
    contact = read_recording(rec).lethal_contact()
    assert contact is not None and contact.startswith("1 entry, ")
    assert main(["inspect", str(rec)]) == 0
    assert "the drive had lethal terrain under the vehicle: 1 entry" in capsys.readouterr().out
    _warn_recordings([rec])
    assert f"warning: {rec}: the drive had lethal terrain under the vehicle" in capsys.readouterr().err
