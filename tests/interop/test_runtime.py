"""What no clock and no file can make the runtime do (terrapref.interop.runtime): hold a command
from a frame stamped in the future, or go faster than the robot may."""

from __future__ import annotations

import numpy as np
import pytest
from test_interop import speed_block
from test_offset_rule import DRIVER_LIKE, _offset_meta

from helpers import REPO, skip_path_weights
from terrapref.errors import UserError
from terrapref.interop.runtime import FRAME_AHEAD_S, DepthFrame, PlannerRuntime, RobotSettings
from terrapref.learning.model_file import save_model
from terrapref.learning.network import ClassifierConfig
from terrapref.rules import RULES
from terrapref.rules.settings import RuleSettings
from terrapref.vehicle import VehicleConfig

PATH = np.array([[0.0, 0.0], [200.0, 0.0]])
GRASS = np.zeros((480, 640), dtype=np.uint8)  # grass all round: nothing to stop for


def _model(root, v_mps: float, top_mps: float = 2.0):
    config = ClassifierConfig(hidden=8, skip=True)
    meta = _offset_meta(DRIVER_LIKE)
    meta["rules"] = [*meta["rules"], {**speed_block(v_mps), "max_speed_mps": top_mps, "background": "grass"}]
    return save_model(root / f"v{v_mps}.safetensors", config, skip_path_weights(config), meta)


@pytest.fixture(scope="module")
def cruising(tmp_path_factory):
    return _model(tmp_path_factory.mktemp("runtime"), 1.6)


def _runtime(model, **options) -> PlannerRuntime:
    runtime = PlannerRuntime(model, **options)
    runtime.set_path(PATH)
    return runtime


def test_a_frame_stamped_far_ahead_of_the_clock_is_refused(cruising):
    runtime = _runtime(cruising)
    with pytest.raises(ValueError, match="ahead of the clock"):
        runtime.decide(GRASS, 1e6, (5.0, 0.0, 0.0), now_s=10.0)
    assert runtime.refused["stamped ahead of the clock"] == 1 and runtime.last is None
    assert runtime.decide(GRASS, 10.0, (5.0, 0.0, 0.0), now_s=10.0) is not None  # the clock's own frames are taken
    assert runtime.decide(GRASS, 10.0 + FRAME_AHEAD_S / 2, (5.0, 0.0, 0.0), now_s=10.0) is not None  # a little ahead is skew


@pytest.mark.parametrize("clock", [float("nan"), float("inf"), float("-inf")])
def test_a_clock_that_is_not_a_number_of_seconds_is_refused_and_changes_nothing(cruising, clock):
    """A NaN or infinite clock skipped the check against frames from the future, and a frame
    stamped 1e9 s then made every later frame look old."""
    runtime = _runtime(cruising)
    with pytest.raises(ValueError, match="clock must be a finite number"):
        runtime.decide(GRASS, 1e9, (5.0, 0.0, 0.0), now_s=clock)
    assert runtime.last is None and runtime.decide(GRASS, 2.0, (5.0, 0.0, 0.0), now_s=2.0) is not None
    assert runtime.status_at(clock) == ((0.0, 0.0), "stale")  # nothing is fresh by such a clock ...
    assert runtime.status_at(2.1) == ((pytest.approx(0.1), 0.0), None)  # ... and the next call is as if it never came


@pytest.mark.parametrize("speed", [1e6, -1e6, 3.6])
def test_an_odometry_speed_past_any_the_robot_drives_is_refused_not_ramped_from(cruising, speed):
    """The commands rise from the robot's speed by its odometry no faster than its acceleration:
    a speed of 1e6 m/s (or 3.6, km/h given for m/s at 1 m/s) would have let full speed out at once."""
    runtime = _runtime(cruising)
    with pytest.raises(ValueError, match="past any this robot drives"):
        runtime.decide(GRASS, 1.0, (5.0, 0.0, 0.0), speed_mps=speed, now_s=1.0)
    runtime.decide(GRASS, 1.0, (5.0, 0.0, 0.0), speed_mps=0.0, now_s=1.0)
    assert runtime.status_at(1.01)[0].v == pytest.approx(0.01)  # from standstill, at 1 m/s^2
    assert runtime.decide(GRASS, 1.1, (5.0, 0.0, 0.0), speed_mps=2.5, now_s=1.1) is not None  # odometry a little past the top: taken


@pytest.mark.parametrize(
    ("call", "says"),
    [
        ({"stamp_s": "1.0"}, "stamp_s must be a finite number"),
        ({"stamp_s": None}, "stamp_s must be a finite number"),
        ({"pose": (5.0, 0.0)}, "pose must be 3 finite numbers"),
        ({"pose": (5.0, "0", 0.0)}, "pose must be 3 finite numbers"),
        ({"depth": np.zeros((480, 640), np.float32)}, "depth must be a DepthFrame"),
    ],
)
def test_an_argument_of_the_wrong_kind_is_named(cruising, call: dict, says: str):
    """Python's own TypeError and AttributeError named no argument."""
    runtime = _runtime(cruising)
    args = {"image": GRASS, "stamp_s": 1.0, "pose": (5.0, 0.0, 0.0), **call}
    with pytest.raises(ValueError, match=says):
        runtime.decide(**args)
    assert runtime.decide(GRASS, np.float32(1.0), np.array([5.0, 0.0, 0.0], np.float32), speed_mps=np.float32(0.5)) is not None


def test_a_decision_from_the_future_does_not_latch_the_command(cruising):
    """Without a clock to check frames against, a frame stamped 1e6 s is decided on; the first
    command asked for at the clock's time is a stop, and the next frame stamped by that clock is
    taken rather than ignored as older."""
    runtime = _runtime(cruising)
    runtime.decide(GRASS, 10.0, (5.0, 0.0, 0.0))
    assert runtime.status_at(10.1)[0].v > 0
    runtime.decide(GRASS, 1e6, (5.1, 0.0, 0.0))
    assert runtime.status_at(10.6) == ((0.0, 0.0), "stale")
    assert runtime.status_at(5000.0) == ((0.0, 0.0), "stale")
    assert runtime.refused["decisions the clock found in its future"] == 1
    assert runtime.decide(GRASS, 10.7, (5.2, 0.0, 0.0)) is not None
    assert runtime.status_at(10.75)[1] is None


def test_no_model_file_raises_the_robots_top_speed(tmp_path):
    """A speed block asking for 8 m/s: held to the robot's 2 m/s (its curvature kept), and said."""
    runtime = _runtime(_model(tmp_path, 8.0, top_mps=8.0))
    assert runtime.notes and "8 m/s" in runtime.notes[0] and "2 m/s" in runtime.notes[0]
    commands = []
    for i in range(60):
        t = 0.1 * i
        runtime.decide(GRASS, t, (5.0 + 0.15 * i, 0.0, 0.0), speed_mps=1.5)
        commands.append(runtime.status_at(t + 0.05)[0])
    assert max(c.v for c in commands) == pytest.approx(2.0)
    slower = _runtime(_model(tmp_path, 8.0, top_mps=8.0), robot=RobotSettings(limits=VehicleConfig(max_speed_mps=1.2)))
    slower.decide(GRASS, 0.0, (5.0, 0.0, 0.0), speed_mps=1.2)
    assert slower.status_at(3.0 - 2.9)[0].v <= 1.2 and "1.2 m/s" in slower.notes[0]


def test_the_speed_given_out_rises_no_faster_than_the_robot_accelerates(cruising):
    runtime = _runtime(cruising, robot=RobotSettings(limits=VehicleConfig(max_accel_mps2=0.5)))
    runtime.decide(GRASS, 0.0, (5.0, 0.0, 0.0), speed_mps=0.0)
    given = [runtime.status_at(0.05 * k)[0].v for k in range(6)]  # a node's timer at 20 Hz
    assert given == pytest.approx([0.0, 0.025, 0.05, 0.075, 0.1, 0.125])
    moving = _runtime(cruising)  # a robot already going at 1.2 m/s by its odometry: from there
    moving.decide(GRASS, 0.0, (5.0, 0.0, 0.0), speed_mps=1.2)
    assert moving.status_at(0.1)[0].v == pytest.approx(1.3)
    moving.decide(GRASS, 0.9, (6.2, 0.0, 0.0), speed_mps=1.4)
    assert moving.status_at(1.0)[0].v == pytest.approx(1.6)  # and on to the speed rule's 1.6 m/s


def test_a_stop_is_never_held_back(cruising):
    runtime = _runtime(cruising)
    runtime.decide(GRASS, 0.0, (5.0, 0.0, 0.0), speed_mps=1.6)
    assert runtime.status_at(0.05)[0].v == pytest.approx(1.6)
    assert runtime.status_at(1.0) == ((0.0, 0.0), "stale")  # at once, not ramped down


def test_the_runtime_example_in_the_docs_runs(tmp_path, monkeypatch, capsys):
    """docs/robot.md's control-loop example, as written, with a model file of its name."""
    import re

    page = (REPO / "docs" / "robot.md").read_text()
    code = re.search(r"A control loop around it.*?```python\n(.*?)```", page, re.S).group(1)
    _model(tmp_path, 8.0, top_mps=8.0).rename(tmp_path / "me.safetensors")  # a speed rule faster than the example's robot
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "docs/robot.md", "exec"), {})
    printed = capsys.readouterr().out.splitlines()
    assert "1.5 m/s" in printed[-1] and "8 m/s" in printed[-1]  # the note: held to the example robot's 1.5 m/s
    assert printed[0].split()[0].isdigit()  # the decision's trajectory, then its command and the one given out


def _settings(**flat) -> RobotSettings:
    """Settings of the model's rules as a node's parameters give them: ``offset__switch_margin`` for ``offset.switch_margin``."""
    return RobotSettings(rules=RuleSettings.parse({k.replace("__", "."): v for k, v in flat.items()}, "--ros-args", RULES))


def test_a_robot_sets_a_speed_cap_overall_and_per_class_over_the_model_files(cruising):
    """The model cruises at 1.6 m/s on every class: a robot's cap of 1.2 m/s holds every command
    to it, a cap on grass alone (the background, all this frame shows) to that, and both are said."""
    for settings, top in (
        (_settings(speed__max_speed_mps=1.2), 1.2),
        (_settings(speed__class_max_mps__grass=0.7, speed__class_max_mps__mud=0.4), 0.7),
    ):
        runtime = _runtime(cruising, robot=settings)
        for i in range(30):
            runtime.decide(GRASS, 0.1 * i, (5.0 + 0.1 * i, 0.0, 0.0), speed_mps=top)
        assert runtime.last.command.v == pytest.approx(top)
        assert any(line.startswith("rule settings over the model file's: speed.") for line in runtime.notes)
    plain = _runtime(cruising)
    plain.decide(GRASS, 0.0, (5.0, 0.0, 0.0), speed_mps=1.6)
    assert plain.last.command.v == pytest.approx(1.6)  # the file's own, where the robot sets nothing


def test_a_robot_sets_the_offset_rules_switch_margin(cruising):
    runtime = _runtime(cruising, robot=_settings(offset__switch_margin=0.3))
    offset = next(r for r in runtime.planner.rules if r.type == "offset")
    assert offset.config.switch_margin == 0.3 and runtime.planner.rule is offset
    assert runtime.planner.runner.config.switch_margin == 0.3  # what the rule decides with


@pytest.mark.parametrize(
    "flat, words",
    [
        ({"offset.switch_margin": -1.0}, ["--ros-args", "offset.switch_margin", ">= 0"]),
        ({"speed.class_max_mps.sand": 0.5}, ["--ros-args", "speed.class_max_mps", "'sand'", "grass"]),
        ({"speed.class_max_mps.non_traversable": 0.5}, ["--ros-args", "non_traversable"]),  # lethal: no speed is kept there
        ({"speed.class_max_mps.mud": 0.01}, ["--ros-args", "least cruising speed"]),
        ({"speed.max_speed_mps": 0.0}, ["--ros-args", "speed.max_speed_mps", "top speed > 0"]),
    ],
)
def test_a_setting_a_rule_cannot_take_is_refused_in_one_line(cruising, flat, words):
    with pytest.raises(UserError) as caught:
        PlannerRuntime(cruising, robot=RobotSettings(rules=RuleSettings.parse(flat, "--ros-args", RULES)))
    assert len(caught.value.lines()) == 1 and all(w in caught.value.lines()[0] for w in words), caught.value.lines()


def test_settings_of_a_rule_the_model_lacks_are_said_unused(tmp_path):
    from helpers import linear_model

    runtime = PlannerRuntime(linear_model(tmp_path / "m.safetensors"), robot=_settings(speed__max_speed_mps=1.0))
    assert "the model lists no speed rule: its settings are not used" in runtime.notes


def test_a_depth_image_places_the_ground_and_one_that_does_not_fit_the_camera_is_refused(cruising):
    """A frame of flat ground at the origin with its depth image: the ground map gathers heights
    of about 0 m (the plane z = 0) where the returns fall; without one, none."""
    from terrapref.camera import PinholeCamera, SegmentationRenderer
    from terrapref.scenario import resolve_scenario
    from terrapref.world import rasterise

    renderer = SegmentationRenderer(PinholeCamera(), rasterise(resolve_scenario("demo_course")))
    pose = (5.0, 12.0, 0.0)
    ids, depth = renderer.render_with_depth(pose)
    flat, seen = _runtime(cruising), _runtime(cruising)
    for runtime in (flat, seen):
        runtime.set_path(PATH + [0.0, 12.0])
    flat.decide(ids, 1.0, pose)
    assert flat.planner.ground_map.layer("returns").sum() == 0
    seen.decide(ids, 1.0, pose, depth=DepthFrame(depth))
    returns, elevation = seen.planner.ground_map.layer("returns"), seen.planner.ground_map.layer("elevation")
    assert returns.sum() > 1000 and np.nanmax(np.abs(elevation[returns > 0])) < 1e-3
    with pytest.raises(ValueError, match="depth image of shape"):
        seen.decide(ids, 1.1, pose, depth=DepthFrame(depth[:-1]))
    with pytest.raises(ValueError, match="attitude must be the body's"):
        seen.decide(ids, 1.2, pose, depth=DepthFrame(depth, (0.0, float("nan"), 0.0)))


def _relief_frame(pose=(5.0, 12.0, 0.0)):
    """A frame of flat ground and its depth image, on a path along y = 12 m."""
    from terrapref.camera import PinholeCamera, SegmentationRenderer
    from terrapref.scenario import resolve_scenario
    from terrapref.world import rasterise

    return SegmentationRenderer(PinholeCamera(), rasterise(resolve_scenario("demo_course"))).render_with_depth(pose)


@pytest.mark.parametrize(
    "attitude",
    [(0.0, 0.1), (0.0, 0.1, 0.0, 1.0), np.zeros((1, 3)), {"z_m": 0.0}, "level", (0.0, 2.0, 0.0), (0.0, 0.0, 1e6)],
)
def test_an_attitude_that_is_not_one_is_refused_naming_it(cruising, attitude):
    """Two numbers, four, an array of another shape, a mapping, a pitch past the vertical: each a
    ValueError naming the attitude and its form, where they were TypeErrors or drove on."""
    ids, depth = _relief_frame()
    runtime = _runtime(cruising)
    runtime.set_path(PATH + [0.0, 12.0])
    with pytest.raises(ValueError, match=r"attitude must be the body's \(z_m, pitch_rad, roll_rad\)"):
        runtime.decide(ids, 1.0, (5.0, 12.0, 0.0), depth=DepthFrame(depth, attitude))


def test_a_depth_image_checked_as_a_robot_s_come(cruising):
    """None is a level attitude; millimetres are refused as the nodes refuse them; a depth image
    stamped 0.4 s from its label image (a depth camera that froze) is refused and counted; after
    frames with depth, a frame without is refused, so that the command goes stale."""
    ids, depth = _relief_frame()
    runtime = _runtime(cruising)
    runtime.set_path(PATH + [0.0, 12.0])
    pose = (5.0, 12.0, 0.0)
    with pytest.raises(ValueError, match="millimetres as it seems"):
        runtime.decide(ids, 1.0, pose, depth=DepthFrame(depth * 1000.0))
    assert runtime.decide(ids, 1.0, pose, depth=DepthFrame(depth, None, 1.03)).stop is None  # level; 30 ms apart
    with pytest.raises(ValueError, match="stamped -0.4 s from its label image"):
        runtime.decide(ids, 1.1, pose, depth=DepthFrame(depth, None, 0.7))
    assert runtime.decide(ids, 0.9, pose) is None  # out of order: it changes nothing, with depth or without
    with pytest.raises(ValueError, match="without its depth image, after frames with one"):
        runtime.decide(ids, 1.2, pose)
    assert runtime.refused["with a depth image stamped more than 50 ms from it"] == 1
    assert runtime.refused["without a depth image, after frames with one"] == 1
    assert runtime.status_at(1.0 + runtime.hold_s + 0.1) == ((0.0, 0.0), "stale")
    assert not runtime.notes  # a model of flat ground: nothing to say of frames without depth
    fresh = _runtime(cruising)
    fresh.set_path(PATH + [0.0, 12.0])
    with pytest.raises(ValueError, match="ahead of the clock"):  # a frame refused commits the runtime to nothing
        fresh.decide(ids, 1e6, pose, now_s=10.0, depth=DepthFrame(depth))
    assert fresh.decide(ids, 10.0, pose, now_s=10.0) is not None


@pytest.mark.parametrize("dead", [np.nan, 0.0, np.inf])
def test_a_depth_camera_that_sees_nothing_is_blind(cruising, dead):
    """A depth image without a return (a covered or dead depth camera) stopped the planner for
    ever as `no_free_way`: it is `blind`, as a covered lens is."""
    ids, depth = _relief_frame()
    runtime = _runtime(cruising)
    runtime.set_path(PATH + [0.0, 12.0])
    reasons = [runtime.decide(ids, 1.0 + 0.1 * i, (5.0, 12.0, 0.0), depth=DepthFrame(np.full_like(depth, dead))).stop for i in range(8)]
    assert reasons[-1] == "blind"


def test_a_model_taught_relief_without_depth_images_is_said(cruising, tmp_path):
    """A model whose speed rule learned grades, given frames without depth: said once in the
    notes (it drove on without a word); and a node whose robot file names no depth topic says it
    at its start."""
    from terrapref.learning.model_file import load_model
    from terrapref.planner.model import Model

    loaded = load_model(cruising)
    meta = {
        **loaded.meta,
        "rules": [{**r, "up_mps_per_deg": 0.05, "down_mps_per_deg": 0.02} if r["type"] == "speed" else r for r in loaded.meta["rules"]],
    }
    relief = save_model(tmp_path / "relief.safetensors", ClassifierConfig(hidden=8, skip=True), loaded.weights, meta)
    assert Model.load(relief).reads_relief and not Model.load(cruising).reads_relief
    runtime = _runtime(relief)
    assert not runtime.notes
    for i in range(2):
        runtime.decide(GRASS, 1.0 + 0.1 * i, (5.0, 0.0, 0.0))
    assert [n for n in runtime.notes if "taught relief" in n] == [
        "the model was taught relief (slopes, steps, rough ground) but its frames come without depth images: "
        "the ground is taken as flat, and no ground is blocked by its geometry"
    ]


@pytest.mark.parametrize("value", [-0.1, float("nan"), float("inf"), True, "0.3", 10**400])
def test_a_hold_or_lead_that_is_not_a_finite_number_at_least_0_is_refused(value):
    """An integer beyond the float range (YAML reads 1 followed by 400 zeros as one) included: refused, not an OverflowError."""
    for name in ("hold_s", "ahead_s"):
        with pytest.raises(ValueError, match=f"{name} must be a finite number >= 0"):
            RobotSettings(**{name: value})
