"""Disturbed demonstrations: random yaw-rate pushes on what the vehicle executes, while the
label stays the demonstrator's own command."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from helpers import SHORT_COURSE
from terrapref.demos.expert import ExpertDriver
from terrapref.demos.meta import ExpertInfo, RecordingMeta, RecordingSetup
from terrapref.demos.recording import FRAMES, RecordingWriter, read_recording
from terrapref.demos.session import DisturbanceConfig, Disturber, RunSettings, record_run
from terrapref.features import PreferenceSetConfig
from terrapref.scenario import resolve_scenario
from terrapref.sim import Simulation
from terrapref.terrain import PreferenceProfile
from terrapref.vehicle import Command

DT = 0.1  # 10 Hz camera frames


# --- DisturbanceConfig ---------------------------------------------------------------------------


def test_default_config_is_valid():
    c = DisturbanceConfig()
    assert c.rate_hz > 0 and c.min_yaw_rate_rps <= c.max_yaw_rate_rps and c.min_duration_s <= c.max_duration_s
    assert DisturbanceConfig(**c.to_dict()) == c
    DisturbanceConfig(rate_hz=0.0)  # off is allowed
    DisturbanceConfig(min_yaw_rate_rps=0.4, max_yaw_rate_rps=0.4, min_duration_s=1.0, max_duration_s=1.0)  # fixed pushes


@pytest.mark.parametrize(
    "kw",
    [
        {"rate_hz": -0.1},
        {"min_yaw_rate_rps": -0.1},
        {"min_yaw_rate_rps": 0.7, "max_yaw_rate_rps": 0.5},
        {"min_duration_s": 2.0, "max_duration_s": 1.0},
        {"min_duration_s": 0.0},
        {"max_command_rps": 0.0},
        {"clear_m": -0.5},
        {"clear_s": float("nan")},
        {"clear_m": float("inf")},
    ],
)
def test_invalid_config_is_refused(kw: dict):
    with pytest.raises(ValueError):
        DisturbanceConfig(**kw)


# --- Disturber -----------------------------------------------------------------------------------


def test_rate_zero_never_pushes():
    d = Disturber(DisturbanceConfig(rate_hz=0.0), np.random.default_rng(0), DT)
    for i in range(500):
        c = Command(1.0, 0.05 * (i % 21) - 0.5)
        assert d(c) is c


def _pushes(config: DisturbanceConfig, n: int, seed: int = 0, w: float = 0.0) -> tuple[list[SimpleNamespace], list[Command]]:
    """Drive a Disturber for n frames with a constant command and collect the pushes it starts."""
    d = Disturber(config, np.random.default_rng(seed), DT)
    command = Command(1.0, w)
    pushes: list[SimpleNamespace] = []
    outputs = []
    for _ in range(n):
        before = d.left_s
        out = d(command)
        outputs.append(out)
        if before <= 0.0 and out != command:  # a new push starts on this frame
            pushes.append(SimpleNamespace(push=d.push, duration=d.left_s + DT, frames=1))
        elif before > 0.0:  # a push goes on
            assert out != command
            pushes[-1].frames += 1
    return pushes, outputs


def test_pushes_stay_within_the_configured_ranges():
    config = DisturbanceConfig(rate_hz=5.0, min_yaw_rate_rps=0.2, max_yaw_rate_rps=0.5, min_duration_s=0.3, max_duration_s=1.0)
    pushes, outputs = _pushes(config, 3000)
    assert len(pushes) > 100
    mags = np.array([abs(p.push) for p in pushes])
    assert np.all(mags >= 0.2) and np.all(mags <= 0.5)
    assert mags.max() - mags.min() > 0.2  # drawn across the range, not fixed
    signs = np.sign([p.push for p in pushes])
    assert 0.3 < np.mean(signs > 0) < 0.7  # both directions
    durations = np.array([p.duration for p in pushes])
    assert np.all(durations >= 0.3 - 1e-9) and np.all(durations <= 1.0 + 1e-9)
    for p in pushes[:-1]:  # the last may be cut by the end of the run
        # A push is executed on every frame until its time is used up.
        assert p.duration - 1e-9 <= p.frames * DT < p.duration + DT + 1e-9
        assert 3 <= p.frames <= 10
    # The executed yaw rate is the command plus the push (no clipping needed at w = 0); v is untouched.
    assert all(isinstance(o, Command) and o.v == 1.0 for o in outputs)
    pushed = [o[1] for o in outputs if o[1] != 0.0]
    assert pushed and all(0.2 - 1e-12 <= abs(w) <= 0.5 + 1e-12 for w in pushed)
    share = len(pushed) / len(outputs)
    assert 0.5 < share < 1.0  # pushes cover most frames at this rate


@pytest.mark.parametrize(("v", "share"), [(0.0, 0.0), (0.05, 0.25), (0.1, 0.5), (0.2, 1.0), (0.3, 1.0), (1.6, 1.0)])
def test_a_push_turns_a_crawling_vehicle_in_proportion_to_its_speed(v: float, share: float):
    """Below FULL_PUSH_MPS (0.2 m/s) a push is the ground's on a vehicle rolling slowly: a share of
    it, as the command's speed is of 0.2 m/s; at and above it, whole (every speed style's)."""
    from terrapref.demos.disturbance import FULL_PUSH_MPS

    assert FULL_PUSH_MPS == 0.2
    config = DisturbanceConfig(rate_hz=1000.0, min_yaw_rate_rps=0.5, max_yaw_rate_rps=0.5)
    d = Disturber(config, np.random.default_rng(0), DT)
    out = d(Command(v, 0.1))
    assert abs(d.push) == 0.5 and out.v == v
    assert out.w == pytest.approx(0.1 + d.push * share, abs=1e-12)


def test_a_driver_crawling_up_a_grade_through_pushes_still_reaches_the_goal(tmp_path: Path):
    """A relief style that sheds 0.2 m/s per degree crawls (0.1 m/s) over tiny_relief's mound;
    with whole pushes at a crawl the vehicle was turned round within centimetres and drove off its
    line until the time ran out ("timed out"). Driven as `terrapref record` drives it, with the
    recommended pushes, kept in memory."""
    from helpers import TINY_RELIEF
    from terrapref.demos.expert import ExpertConfig
    from terrapref.demos.recording import MemoryRecordingWriter
    from terrapref.demos.relief_style import parse_relief_style
    from terrapref.demos.session import DriveSetup
    from terrapref.recipes import DEFAULT_RECIPE, RECIPES

    setup = DriveSetup.of(resolve_scenario(str(TINY_RELIEF)))
    config = ExpertConfig(relief=parse_relief_style("default,up_mps_per_deg=0.2")[1])  # the default style, as record's
    pushes = RECIPES[DEFAULT_RECIPE].disturbance
    pushed = []

    class Kept(MemoryRecordingWriter):
        def append(self, time_s, pose, image, command, label, executed=None) -> None:
            pushed.append(executed is not None and tuple(executed) != tuple(command))
            super().append(time_s, pose, image, command, label, executed)

    writer = Kept(
        tmp_path / "mem", setup.meta(ExpertInfo.of(0, "default", config, pushes), PreferenceProfile.default()), setup.scenario.to_dict()
    )
    log = record_run(setup.simulation(), ExpertDriver(config), writer, RunSettings(setup.preference, pushes), np.random.default_rng(0))
    assert log.completed and log.tips == 0, log.summary()
    assert writer.recording().commands[:, 0].min() < 0.2 and any(pushed)


@pytest.mark.slow  # a whole drive, course or training end to end; the default run keeps the test suite's time
def test_a_cautious_driver_is_not_pushed_onto_ground_that_could_tip_the_vehicle(tmp_path: Path):
    """A mound on the path, then a ridge 0.5 m beside it whose flanks would roll the vehicle past
    its 25 deg. The cautious style (7 deg of roll, 9 of grade), pushed as `terrapref record`
    pushes, was pushed onto the ridge's flank: shedding its speed to 0.1 m/s there, its steering
    fell under its hand's deadzone, and it crept along the flank for 40 s at up to 19 deg, turned
    by each push (93 s for the 46 m). A push now begins only clear of ground that would tilt the
    vehicle past its limits, as of lethal terrain, and a driver slowed by relief still steers."""
    from terrapref.demos.expert import ExpertConfig
    from terrapref.demos.recording import MemoryRecordingWriter
    from terrapref.demos.relief_style import parse_relief_style
    from terrapref.demos.session import DriveSetup
    from terrapref.recipes import DEFAULT_RECIPE, RECIPES
    from terrapref.scenario import parse_scenario

    scenario = parse_scenario(
        {
            "format": "terrapref-scenario/1",
            "name": "mound_and_ridge",
            "world": {"size_m": [50.0, 20.0], "resolution_m": 0.05, "background": "grass"},
            "terrain": [],
            "path": {"waypoints": [[2.0, 10.0], [48.0, 10.0]]},
            "relief": [
                {"mound": {"center": [12.0, 10.0], "radius": 3.0, "height_m": 0.8}},
                {"ridge": {"polyline": [[20.0, 8.0], [30.0, 8.0]], "width_m": 3.0, "height_m": 0.6}},
            ],
        }
    )
    setup = DriveSetup.of(scenario)
    config = ExpertConfig(relief=parse_relief_style("cautious")[1])
    pushes = RECIPES[DEFAULT_RECIPE].disturbance
    for seed in range(3):
        writer = MemoryRecordingWriter(
            tmp_path / f"mem{seed}",
            setup.meta(ExpertInfo.of(seed, "default", config, pushes), PreferenceProfile.default()),
            scenario.to_dict(),
        )
        run = record_run(
            setup.simulation(), ExpertDriver(config), writer, RunSettings(setup.preference, pushes), np.random.default_rng(seed)
        )
        assert run.completed and run.tips == 0 and run.stuck == 0, run.summary()
        summary = run.summary()
        assert summary["max_roll_deg"] < 9.0 and summary["duration_s"] < 65.0, summary
        assert writer.recording().commands[:, 0].min() > 0.3  # never crawling


def test_push_rate_matches_rate_hz():
    config = DisturbanceConfig(rate_hz=0.5, min_duration_s=0.1, max_duration_s=0.1)
    pushes, _ = _pushes(config, 20000, seed=1)
    rate = len(pushes) / (20000 * DT)
    assert 0.4 < rate < 0.6


def test_pushed_command_is_clipped():
    config = DisturbanceConfig(rate_hz=50.0, min_yaw_rate_rps=0.6, max_yaw_rate_rps=0.6, max_command_rps=1.0)
    _, outputs = _pushes(config, 500, w=0.9)
    ws = np.array([o[1] for o in outputs])
    assert np.all(np.abs(ws) <= 1.0 + 1e-12)
    assert np.any(ws == 1.0)  # 0.9 + 0.6 clipped to the limit
    assert np.any(np.isclose(ws, 0.3))  # 0.9 - 0.6
    config = DisturbanceConfig(rate_hz=50.0, min_yaw_rate_rps=0.6, max_yaw_rate_rps=0.6, max_command_rps=0.7)
    _, outputs = _pushes(config, 500, w=-0.5)
    ws = np.array([o[1] for o in outputs])
    assert np.all(np.abs(ws) <= 0.7 + 1e-12) and np.any(ws == -0.7) and np.any(np.isclose(ws, 0.1))


def test_disturber_is_reproducible():
    config = DisturbanceConfig(rate_hz=2.0)
    a = _pushes(config, 300, seed=5)[1]
    b = _pushes(config, 300, seed=5)[1]
    c = _pushes(config, 300, seed=6)[1]
    assert a == b and a != c


def test_no_push_begins_within_reach_of_lethal_terrain_and_the_others_are_drawn_as_before():
    config = DisturbanceConfig(rate_hz=2.0, clear_m=1.0, clear_s=1.5)
    free = Disturber(config, np.random.default_rng(3), DT)
    near = Disturber(config, np.random.default_rng(3), DT)
    asked: list[float] = []
    command = Command(1.2, 0.0)
    pushed_free, pushed_near = [], []
    for i in range(400):
        lethal_near = 100 <= i < 200  # lethal terrain within reach for these frames only

        def within(r: float, lethal_near: bool = lethal_near) -> bool:
            asked.append(r)
            return lethal_near

        pushed_free.append(free(command, 1.2, lambda r: False) != command)
        pushed_near.append(near(command, 1.2, within) != command)
    assert asked and all(r == pytest.approx(1.0 + 1.5 * 1.2) for r in asked)  # the reach grows with speed
    assert any(pushed_free[100:200]) and not any(pushed_near[110:200])  # a push begun before 100 may run on
    # The same pushes before and after: the left-out pushes' time passed as if they had run.
    assert pushed_near[:100] == pushed_free[:100] and pushed_near[200:] == pushed_free[200:] and any(pushed_near[200:])


def test_without_a_clearance_pushes_begin_anywhere():
    config = DisturbanceConfig(rate_hz=2.0)
    a, b = Disturber(config, np.random.default_rng(4), DT), Disturber(config, np.random.default_rng(4), DT)
    command = Command(1.0, 0.0)
    assert [a(command, 1.0, lambda r: True) for _ in range(300)] == [b(command) for _ in range(300)]


# --- disturbed recordings ------------------------------------------------------------------------


def _record(out: Path, seed: int, disturbance: DisturbanceConfig | None, time_limit_s: float | None = None):
    """Record the short course (tests/data/short_course.yaml; the first ``time_limit_s`` seconds only, if given)."""
    scenario = resolve_scenario(str(SHORT_COURSE))
    sim = Simulation(scenario)
    if time_limit_s is not None:
        sim.time_limit_s = time_limit_s
    driver = ExpertDriver()
    preference = PreferenceSetConfig()
    meta = RecordingMeta.driven(
        scenario,
        RecordingSetup(sim.camera.config, preference, sim.config),
        ExpertInfo.of(seed, "default", driver.config, disturbance),
        PreferenceProfile.default(),
    )
    log = record_run(
        sim, driver, RecordingWriter(out, meta, scenario.to_dict()), RunSettings(preference, disturbance), np.random.default_rng(seed)
    )
    lines = [json.loads(line) for line in (out / FRAMES).read_text().splitlines()]
    return SimpleNamespace(log=log, rec=read_recording(out), lines=lines, sim=sim, preference=preference)


@pytest.fixture(scope="module")
def disturbed(tmp_path_factory) -> SimpleNamespace:
    return _record(tmp_path_factory.mktemp("rec") / "a", 0, DisturbanceConfig(rate_hz=1.0))


def test_disturbed_recording_marks_the_executed_frames(disturbed):
    lines, rec, log = disturbed.lines, disturbed.rec, disturbed.log
    assert rec.complete and rec.meta["status"] == "complete"
    assert len(lines) == len(rec) == len(log.commands) > 100
    with_exec = [ln for ln in lines if "executed" in ln]
    assert 0 < len(with_exec) < len(lines)
    for ln in with_exec:
        assert ln["executed"] != ln["cmd"]
        assert ln["executed"][0] == ln["cmd"][0]  # only the yaw rate is pushed
        assert abs(ln["executed"][1]) <= DisturbanceConfig().max_command_rps + 1e-12


def test_disturbed_labels_come_from_the_demonstrated_command(disturbed):
    lines, rec = disturbed.lines, disturbed.rec
    control = disturbed.preference.control
    np.testing.assert_array_equal(rec.labels, control.label_of(rec.commands[:, 1]))
    executed_labels = [control.label_of(ln["executed"][1]) for ln in lines if "executed" in ln]
    own_labels = [ln["label"] for ln in lines if "executed" in ln]
    assert executed_labels != own_labels  # the executed command would have given other labels


def test_the_vehicle_executes_the_pushed_command(disturbed):
    """The simulation logged what the vehicle did: the executed command where there is one."""
    executed = np.array([ln.get("executed", ln["cmd"]) for ln in disturbed.lines])
    np.testing.assert_allclose(disturbed.log.commands, executed)
    assert not np.allclose(disturbed.log.commands, disturbed.rec.commands)


def test_disturbed_recording_is_deterministic(disturbed, tmp_path: Path):
    again = _record(tmp_path / "b", 0, DisturbanceConfig(rate_hz=1.0), time_limit_s=20.0)
    n = len(again.rec)
    assert n == 200 and any("executed" in ln for ln in again.lines)
    np.testing.assert_array_equal(again.rec.poses, disturbed.rec.poses[:n])
    np.testing.assert_array_equal(again.rec.commands, disturbed.rec.commands[:n])
    assert [ln.get("executed") for ln in again.lines] == [ln.get("executed") for ln in disturbed.lines[:n]]
    other = _record(tmp_path / "e", 1, DisturbanceConfig(rate_hz=1.0), time_limit_s=20.0)
    assert [ln.get("executed") for ln in other.lines] != [ln.get("executed") for ln in again.lines]  # the seed matters


def test_disturbance_changes_the_drive(disturbed, tmp_path: Path):
    clean = _record(tmp_path / "c", 0, None, time_limit_s=20.0)
    assert not any("executed" in ln for ln in clean.lines)
    n = len(clean.rec)
    assert not np.array_equal(clean.rec.poses, disturbed.rec.poses[:n])
    off = _record(tmp_path / "d", 0, DisturbanceConfig(rate_hz=0.0), time_limit_s=20.0)
    np.testing.assert_array_equal(off.rec.poses, clean.rec.poses)  # rate 0 is no disturbance at all


def _push_starts(run: SimpleNamespace) -> list[tuple[float, float, float]]:
    """(x, y, speed) where each push of a recorded run began (a push's first frame)."""
    lines = run.lines
    out = []
    for j in range(1, len(lines)):
        if "executed" in lines[j] and "executed" not in lines[j - 1]:
            x, y, _ = lines[j]["pose"]
            out.append((x, y, float(np.hypot(*np.subtract(lines[j]["pose"][:2], lines[j - 1]["pose"][:2]))) / DT))
    return out


@pytest.mark.slow  # a whole drive, course or training end to end; the default run keeps the test suite's time
def test_the_teaching_protocol_pushes_only_away_from_lethal_terrain(tmp_path: Path):
    """The short course, with and without the clearance: without it some push begins with lethal
    terrain within reach; with it none does."""
    config = DisturbanceConfig(rate_hz=1.0, clear_m=3.0, clear_s=2.0)
    world = Simulation(resolve_scenario(str(SHORT_COURSE))).world
    free = _push_starts(_record(tmp_path / "f", 0, DisturbanceConfig(rate_hz=1.0), time_limit_s=60.0))
    assert any(world.lethal_within(x, y, config.clearance_m(v) - 0.1) for x, y, v in free)
    kept = _push_starts(_record(tmp_path / "k", 0, config, time_limit_s=60.0))
    assert kept and len(kept) < len(free)
    assert not any(world.lethal_within(x, y, config.clearance_m(v) - 0.1) for x, y, v in kept)
