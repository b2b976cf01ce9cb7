"""What a ROS node of the planner does with its messages (terrapref.interop.node_core), without
ROS: messages built with rosbags' ROS 2 types stand in for rospy's or rclpy's."""

from __future__ import annotations

import math
import re
from types import SimpleNamespace

import numpy as np
import pytest
from test_offset_rule import DRIVER_LIKE, _offset_meta

from helpers import skip_path_weights
from terrapref.camera import CameraConfig, PinholeCamera, SegmentationRenderer
from terrapref.interop.node_core import BEFORE_CLOCK, PlannerNodeCore, Watchdog
from terrapref.interop.robot import load_robot
from terrapref.interop.ros_messages import camera_info, compressed_image, header, odometry, png, pose, typestore, yaw_quaternion
from terrapref.interop.runtime import PlannerRuntime
from terrapref.learning.model_file import load_model, save_model
from terrapref.learning.network import ClassifierConfig
from terrapref.scenario import resolve_scenario
from terrapref.world import rasterise

TS = typestore()
POSES = [(20.0 + 0.1 * i, 15.0, 0.0) for i in range(6)]  # 0.1 m a frame along fig7's path, frames 0.1 s apart


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    root = tmp_path_factory.mktemp("node")
    config = ClassifierConfig(hidden=8, skip=True)
    model = save_model(root / "m.safetensors", config, skip_path_weights(config), _offset_meta(DRIVER_LIKE))
    (root / "robot.yaml").write_text(
        "format: terrapref-robot/1\ntopics: {segmentation: /seg, camera_info: /info, odometry: /odom, command: /cmd}\n"
        "camera: {height_m: 1.0, pitch_deg: 30.0}\nlabels: terrapref\n"
        "limits: {max_accel_mps2: null}\n"  # the base ramps its speed itself: the command sent is the decision's
    )
    scenario = resolve_scenario("fig7_rock_vs_non_traversable_left")
    renderer = SegmentationRenderer(PinholeCamera(CameraConfig()), rasterise(scenario))
    images = [renderer.render(p) for p in POSES]
    return load_model(model), load_robot(root / "robot.yaml"), scenario.waypoints, images


def _core(setup) -> tuple[PlannerNodeCore, list]:
    model, robot, path, _ = setup
    core, told = PlannerNodeCore(model, robot, path), []
    core.on_decision = told.append
    core.on_camera_info(camera_info(TS, header(TS, 0.0, "camera_optical"), CameraConfig()))
    return core, told


def _odom(i: int):
    x, y, yaw = POSES[i]
    return odometry(TS, header(TS, 0.1 * i, "odom"), pose(TS, x, y, yaw_quaternion(TS, yaw)))


def _image(setup, i: int):
    return compressed_image(TS, header(TS, 0.1 * i, "camera_optical"), "png", png(setup[3][i]))


def test_an_image_before_its_odometry_waits_for_it_and_is_decided_as_the_runtime_decides(setup):
    model, _, path, images = setup
    core, told = _core(setup)
    runtime = PlannerRuntime(model)
    runtime.set_path(path)
    stamps = [1_700_000_000 + 0.1 * i for i in range(6)]  # header() stamps on the epoch-like clock
    expected = [runtime.decide(images[i], stamps[i], POSES[i]) for i in range(6)]
    core.on_odometry(_odom(0))
    assert core.on_image("sensor_msgs/msg/CompressedImage", _image(setup, 0)) is not None  # its pose is there: decided at once
    for i in range(1, 6):  # each image comes before the odometry of its stamp, as on separate topics it may
        assert core.on_image("sensor_msgs/msg/CompressedImage", _image(setup, i)) is None
        decision = core.on_odometry(_odom(i))
        assert decision is not None and decision.stamp_s == pytest.approx(stamps[i])
    assert [d.command for d in told] == [e.command for e in expected] and core.decided == 6
    assert sum(core.skipped.values()) == 0


def test_a_newer_image_supersedes_one_waiting_and_one_far_ahead_of_the_odometry_is_skipped(setup):
    core, told = _core(setup)
    core.on_odometry(_odom(0))
    core.on_image("sensor_msgs/msg/CompressedImage", _image(setup, 2))
    core.on_image("sensor_msgs/msg/CompressedImage", _image(setup, 3))  # the newer one waits instead
    core.on_odometry(_odom(3))
    assert [round(d.stamp_s - 1_700_000_000, 6) for d in told] == [0.3] and core.skipped[
        "superseded while waiting for odometry or depth"
    ] == 1
    far = compressed_image(TS, header(TS, 5.0, "camera_optical"), "png", png(setup[3][0]))
    assert core.on_image("sensor_msgs/msg/CompressedImage", far) is None and core.skipped["without odometry at the stamp"] == 1


def test_a_distorted_lens_is_undone_before_the_planner_sees_the_frame(setup):
    model, robot, path, images = setup
    core = PlannerNodeCore(model, robot, path)
    info = camera_info(TS, header(TS, 0.0, "camera_optical"), CameraConfig())
    info.d = np.array([-0.2, 0.05, 0.0, 0.0, 0.0])
    core.on_camera_info(info)
    core.on_odometry(_odom(0))
    seen = []
    core.runtime.decide = lambda ids, t, p, v=None, depth=None: seen.append(ids)  # what the planner is handed
    core.on_image("sensor_msgs/msg/CompressedImage", _image(setup, 0))
    assert seen[0].shape == images[0].shape and not np.array_equal(seen[0], images[0])
    centre = (slice(200, 280), slice(280, 360))  # barrel distortion leaves the middle as it was
    np.testing.assert_array_equal(seen[0][centre], images[0][centre])


def test_an_image_of_another_size_than_the_calibration_is_refused_by_name(setup):
    from terrapref.errors import UserError

    core, _ = _core(setup)
    core.on_odometry(_odom(0))
    small = compressed_image(TS, header(TS, 0.0, "camera_optical"), "png", png(setup[3][0][::2, ::2].copy()))
    with pytest.raises(UserError, match="320 x 240 px; the calibration says 640 x 480"):
        core.on_image("sensor_msgs/msg/CompressedImage", small)


def test_an_older_image_does_not_displace_a_newer_one_waiting_for_odometry(setup):
    core, told = _core(setup)
    core.on_odometry(_odom(0))
    core.on_image("sensor_msgs/msg/CompressedImage", _image(setup, 3))
    core.on_image("sensor_msgs/msg/CompressedImage", _image(setup, 2))  # late: the newer one keeps waiting
    core.on_odometry(_odom(3))
    assert [round(d.stamp_s - 1_700_000_000, 6) for d in told] == [0.3]


def test_an_id_the_label_map_does_not_list_is_refused_by_name_and_nothing_is_decided(setup):
    from terrapref.errors import UserError

    core, told = _core(setup)  # labels: terrapref (ids 0-4 and 255)
    core.on_odometry(_odom(0))
    ids = setup[3][0].copy()
    ids[470:, :8] = 9  # a class nobody mapped
    with pytest.raises(UserError, match=r"terrapref\.yaml: ids: label id 9 in a label image not listed"):
        core.on_image("sensor_msgs/msg/CompressedImage", compressed_image(TS, header(TS, 0.0, "camera_optical"), "png", png(ids)))
    assert told == [] and core.decided == 0


def test_the_node_says_why_it_stops(setup):
    core, told = _core(setup)
    assert core.status_at(0.0)[1] == "stale"  # nothing decided yet
    core.on_odometry(_odom(0))
    decision = core.on_image("sensor_msgs/msg/CompressedImage", _image(setup, 0))
    command, reason = core.status_at(decision.stamp_s + 0.05)
    assert (command, reason) == (decision.command, decision.stop)
    assert core.status_at(decision.stamp_s + 1.0) == ((0.0, 0.0), "stale")


def test_the_node_commands_the_speed_the_models_speed_rule_sets(setup, tmp_path):
    """A model whose speed rule cruises at 1.3 m/s: the node sends 1.3 m/s along the way the offset
    rule chose (its curvature kept), not the control set's 1 m/s."""
    from test_interop import speed_block

    model, robot, path, _ = setup
    meta = {**model.meta, "rules": [*model.meta["rules"], speed_block(1.3)]}
    fast = load_model(save_model(tmp_path / "fast.safetensors", model.classifier, model.weights, meta))
    core = PlannerNodeCore(fast, robot, path)
    core.on_camera_info(camera_info(TS, header(TS, 0.0, "camera_optical"), CameraConfig()))
    core.on_odometry(_odom(0))
    decision = core.on_image("sensor_msgs/msg/CompressedImage", _image(setup, 0))
    slow = PlannerRuntime(model)  # the same model without its speed rule
    slow.set_path(path)
    plain = slow.decide(setup[3][0], decision.stamp_s, POSES[0])
    assert decision.stop is None and plain.stop is None
    (v, w), reason = core.status_at(decision.stamp_s + 0.05)
    assert reason is None and v == pytest.approx(1.3) and w == pytest.approx(plain.command.w * 1.3)


def test_the_robots_speed_at_an_image_is_its_odometrys_forward_motion(setup):
    """1 m/s along the path (0.1 m every 0.1 s), going forward or reversing; None before the
    odometry spans the window the speed is read over."""
    core, _ = _core(setup)
    t0 = 1_700_000_000  # header() stamps on the epoch-like clock
    for i in range(6):
        core.on_odometry(_odom(i))
    assert core.speed_at(t0 + 0.05) is None  # the odometry begins at t0: no 0.2 s before it
    assert core.speed_at(t0 + 0.5) == pytest.approx(1.0)
    assert core.speed_at(t0 + 0.35) == pytest.approx(1.0)  # between poses: interpolated
    backwards, _ = _core(setup)
    for i in range(6):
        x, y, _ = POSES[i]
        backwards.on_odometry(odometry(TS, header(TS, 0.1 * i, "odom"), pose(TS, x, y, yaw_quaternion(TS, np.pi))))
    assert backwards.speed_at(t0 + 0.5) == pytest.approx(1.0)  # reversing at 1 m/s: a speed of 1 m/s


def test_a_node_publishes_on_the_robot_files_command_topic_or_its_flag_and_refuses_neither(setup, tmp_path):
    from terrapref.errors import UserError
    from terrapref.interop.node_core import NodeOptions

    _, robot, _, _ = setup
    assert NodeOptions().command_topic(robot) == "/cmd" and NodeOptions(cmd_topic="/out").command_topic(robot) == "/out"
    (tmp_path / "robot.yaml").write_text(
        "format: terrapref-robot/1\ntopics: {segmentation: /seg, camera_info: /info, odometry: /odom}\n"
        "camera: {height_m: 1.0, pitch_deg: 30.0}\nlabels: terrapref\n"
    )
    bare = load_robot(tmp_path / "robot.yaml")  # a robot file for logs without commands
    assert NodeOptions(cmd_topic="/out").command_topic(bare) == "/out"
    with pytest.raises(UserError) as raised:
        NodeOptions().command_topic(bare)
    assert raised.value.problems[0].field == "topics.command" and "--cmd-topic" in str(raised.value)


# --- clocks, limits and the goal on a robot -------------------------------------------------------


def test_an_image_stamped_far_ahead_of_the_nodes_clock_is_refused_and_counted(setup):
    core, told = _core(setup)
    core.on_odometry(_odom(0))
    now = 1_700_000_000.0  # the node's clock, at the first frame's stamp
    with pytest.raises(ValueError, match="ahead of the node's clock"):
        core.on_image("sensor_msgs/msg/CompressedImage", _image(setup, 0), now_s=now - 3600.0)
    assert core.skipped["images ahead of the clock"] == 1 and told == []
    assert core.on_image("sensor_msgs/msg/CompressedImage", _image(setup, 0), now_s=now) is not None


def test_an_image_that_comes_before_a_simulated_clock_ticks_is_skipped_not_driven_as_a_stop(setup):
    """Under use_sim_time the node's time is 0 until the first /clock, which may come after the
    first frame: a command decided on it would be found in the clock's future and turned into a
    stop; the image is skipped instead, counted, and the next one, once the clock ticks, decided on."""
    core, _ = _core(setup)
    core.on_odometry(_odom(0))
    assert core.on_image("sensor_msgs/msg/CompressedImage", _image(setup, 0), now_s=0.0) is None
    assert core.skipped[BEFORE_CLOCK] == 1 and core.decided == 0
    t = 1_700_000_000.0  # the first frame's stamp, which the clock reaches now
    assert core.on_image("sensor_msgs/msg/CompressedImage", _image(setup, 0), now_s=t) is not None
    command, reason = core.status_at(t)
    assert reason is None and command.v > 0.0


def test_the_node_stops_when_no_frame_has_been_decided_on_for_a_while_by_the_wall_clock(setup):
    """A simulated clock that froze (the log player died) holds the node's time still, so by its
    own clock the last command would stay fresh for ever; the wall clock's watchdog stops it."""
    model, robot, path, _ = setup
    wall = [100.0]
    core = PlannerNodeCore(model, robot, path, watchdog=Watchdog(1.0, wall=lambda: wall[0]))
    core.on_camera_info(camera_info(TS, header(TS, 0.0, "camera_optical"), CameraConfig()))
    core.on_odometry(_odom(0))
    decision = core.on_image("sensor_msgs/msg/CompressedImage", _image(setup, 0))
    frozen = decision.stamp_s + 0.05  # the node's clock, stuck here
    assert core.status_at(frozen) == (decision.command, None)
    wall[0] += 0.9
    assert core.status_at(frozen)[1] is None
    wall[0] += 0.2  # 1.1 s by the wall clock without a decision
    assert core.status_at(frozen) == ((0.0, 0.0), "stale")


def test_a_decision_goes_out_before_the_live_view_and_is_not_stale_however_long_the_view_takes(setup, monkeypatch):
    """The live view's first frame starts its server (seconds on a loaded machine): sent before
    the command, it made the watchdog call the decision it was sending stale."""
    import terrapref.interop.live as live

    model, robot, path, _ = setup
    wall, sent = [100.0], []

    class SlowRun:  # the live view, two seconds of the wall clock a frame
        @classmethod
        def start(cls, *args, **kwargs):
            return cls()

        def frame(self, frame, costmap=None):
            wall[0] += 2.0
            sent.append(frame.t_s)

    monkeypatch.setattr(live, "LiveRun", SlowRun)
    core = PlannerNodeCore(model, robot, path, watchdog=Watchdog(1.0, wall=lambda: wall[0]))
    core.watch(object())
    told = []
    core.on_decision = lambda decision: told.append((core.status_at(decision.stamp_s), len(sent)))
    core.on_camera_info(camera_info(TS, header(TS, 0.0, "camera_optical"), CameraConfig()))
    for i in range(2):
        core.on_odometry(_odom(i))
        decision = core.on_image("sensor_msgs/msg/CompressedImage", _image(setup, i))
        assert decision is not None
        (command, reason), views_before = told[-1]
        assert reason is None and command == decision.command, "the decision's own command, not a stale stop"
        assert views_before == i, "the command went out before the live view's frame"
    assert len(sent) == 2


def test_the_robots_limits_and_goal_come_from_its_file_then_its_parameters(setup, tmp_path):
    from terrapref.errors import UserError
    from terrapref.interop.node_core import NodeOptions

    text = (
        "format: terrapref-robot/1\ntopics: {segmentation: /seg, camera_info: /info, odometry: /odom, command: /cmd}\n"
        "camera: {height_m: 1.0, pitch_deg: 30.0}\nlabels: terrapref\n"
        "limits: {max_speed_mps: 1.2, max_accel_mps2: 0.5}\nstop: {goal_tolerance_m: 1.0, goal_yaw_tolerance_deg: null}\n"
    )
    (tmp_path / "robot.yaml").write_text(text)
    robot = load_robot(tmp_path / "robot.yaml")
    assert (robot.limits.max_speed_mps, robot.limits.max_yaw_rate_rps, robot.limits.max_accel_mps2) == (1.2, 1.0, 0.5)
    assert robot.stop.goal_tolerance_m == 1.0 and robot.stop.goal_yaw_tolerance_deg is None
    params = {"~max_speed_mps": 0.8, "~goal_tolerance_m": 0.3}
    opts = NodeOptions().resolved(lambda name, default: params.get(name, default))
    applied = opts.applied_to(robot)
    assert applied.limits.max_speed_mps == 0.8 and applied.limits.max_accel_mps2 == 0.5 and applied.stop.goal_tolerance_m == 0.3
    for name, value, said in (
        ("~max_speed_mps", -1.0, "expected 0.1 to 30, got -1"),
        ("~max_roll_deg", 0.0, "expected 1 to 89, got 0"),  # a limit's range, as a robot file's, from 0 up as past its top
        ("~goal_tolerance_m", 0.0, "expected a number > 0, got 0.0"),
    ):
        with pytest.raises(UserError, match=f"^{name}: {re.escape(said)}$"):
            NodeOptions().resolved(lambda n, default, name=name, value=value: value if n == name else default)
    with pytest.raises(UserError, match="~goal_tolerance_m"):  # beyond the off-path distance
        NodeOptions().resolved(lambda name, default: 50.0 if name == "~goal_tolerance_m" else default)
    with pytest.raises(UserError, match=r"~max_speed_mps: expected 0.1 to 30, got 1e\+09"):
        NodeOptions().resolved(lambda name, default: 1e9 if name == "~max_speed_mps" else default)
    limits = "limits: {max_speed_mps: 1.2, max_accel_mps2: 0.5}"
    _refused_by_field(
        tmp_path,
        text.replace(limits, "{}"),
        [
            ("limits: {max_speed_mps: fast}", "limits.max_speed_mps"),
            ("limits: {top: 1}", "limits.top"),
            ("limits: {max_speed_mps: 1e-9}", "limits.max_speed_mps"),  # no robot drives that slow, or 1e9 m/s fast
            ("limits: {max_speed_mps: 1e9}", "limits.max_speed_mps"),
            ("limits: {max_accel_mps2: 1e12}", "limits.max_accel_mps2"),
            ("limits: {max_yaw_rate_rps: 0.001}", "limits.max_yaw_rate_rps"),
        ],
    )


def _refused_by_field(tmp_path, text: str, cases: list[tuple[str, str]]) -> None:
    """A robot file ``text`` with each case's block in place of its "{}" is refused naming the case's field."""
    from terrapref.errors import ConfigError

    for bad, field in cases:
        (tmp_path / "bad.yaml").write_text(text.replace("{}", bad))
        with pytest.raises(ConfigError) as raised:
            load_robot(tmp_path / "bad.yaml")
        assert raised.value.problems[0].field == field


def test_the_robots_tilt_and_step_limits_come_from_its_file_then_its_parameters(tmp_path):
    """On relief the robot file's limits say what the robot crosses (they could not: the nodes
    always held the default vehicle's 25 deg, 30 deg and 0.15 m), and its node's parameters over them."""
    from terrapref.groundmap.height import GeometryLimits
    from terrapref.interop.node_core import NodeOptions

    text = (
        "format: terrapref-robot/1\ntopics: {segmentation: /seg, camera_info: /info, odometry: /odom}\n"
        "camera: {height_m: 1.0, pitch_deg: 30.0}\nlabels: terrapref\n"
        "limits: {max_roll_deg: 15.0, max_pitch_deg: 20.0, max_step_m: 0.08}\n"
    )
    (tmp_path / "robot.yaml").write_text(text)
    robot = load_robot(tmp_path / "robot.yaml")
    limits = GeometryLimits.of(robot.limits)
    assert (round(math.degrees(limits.max_slope_rad), 9), limits.max_step_m) == (15.0, 0.08)  # the smaller of roll and pitch
    params = {"~max_step_m": 0.3, "~max_roll_deg": 22.0}
    applied = NodeOptions().resolved(lambda name, default: params.get(name, default)).applied_to(robot)
    assert (applied.limits.max_roll_deg, applied.limits.max_pitch_deg, applied.limits.max_step_m) == (22.0, 20.0, 0.3)
    _refused_by_field(
        tmp_path,
        text.replace("limits: {max_roll_deg: 15.0, max_pitch_deg: 20.0, max_step_m: 0.08}", "{}"),
        [
            ("limits: {max_roll_deg: 90}", "limits.max_roll_deg"),
            ("limits: {max_pitch_deg: .nan}", "limits.max_pitch_deg"),
            ("limits: {max_step_m: 0.001}", "limits.max_step_m"),
            ("limits: {max_step_m: tall}", "limits.max_step_m"),
        ],
    )


def test_the_node_holds_a_fast_model_to_the_robots_limits_and_says_it_arrived(setup, tmp_path):
    """A model asking for 8 m/s on a robot of 1.2 m/s: 1.2 m/s at most, said; along a 0.3 m path the
    node stands at its goal at once and says it arrived; a new path, and it has not."""
    from dataclasses import replace

    from test_interop import speed_block

    from terrapref.vehicle import VehicleConfig

    model, robot, _, _ = setup
    meta = {**model.meta, "rules": [*model.meta["rules"], {**speed_block(8.0), "max_speed_mps": 8.0}]}
    fast = load_model(save_model(tmp_path / "fast.safetensors", model.classifier, model.weights, meta))
    slow_robot = replace(robot, limits=VehicleConfig(max_speed_mps=1.2, max_accel_mps2=None))
    core = PlannerNodeCore(fast, slow_robot, np.array([[20.0, 15.0], [60.0, 15.0]]))
    core.on_camera_info(camera_info(TS, header(TS, 0.0, "camera_optical"), CameraConfig()))
    assert any("8 m/s" in note and "1.2 m/s" in note for note in core.runtime.notes)
    core.on_odometry(_odom(0))
    decision = core.on_image("sensor_msgs/msg/CompressedImage", _image(setup, 0))
    assert decision.command.v == pytest.approx(1.2) and not core.arrived
    near = PlannerNodeCore(fast, slow_robot, np.array([[20.0, 15.0], [20.3, 15.0]]))
    near.on_camera_info(camera_info(TS, header(TS, 0.0, "camera_optical"), CameraConfig()))
    near.on_odometry(_odom(0))
    decision = near.on_image("sensor_msgs/msg/CompressedImage", _image(setup, 0))
    assert decision.stop == "goal" and decision.command == (0.0, 0.0) and near.arrived
    near.on_path(
        SimpleNamespace(poses=[SimpleNamespace(pose=SimpleNamespace(position=SimpleNamespace(x=x, y=15.0))) for x in (20.0, 40.0)])
    )
    assert not near.arrived


def test_a_node_says_at_its_start_that_a_model_taught_relief_gets_no_depth(setup, tmp_path):
    """A model whose speed rule learned grades, on a robot whose file names no depth topic: the
    node's start says the ground is taken as flat (it said nothing, and drove into a ledge)."""
    from test_interop import speed_block

    model, robot, _, _ = setup
    relief = {**speed_block(1.0), "up_mps_per_deg": 0.05, "down_mps_per_deg": 0.02}
    meta = {**model.meta, "rules": [*model.meta["rules"], relief]}
    taught = load_model(save_model(tmp_path / "relief.safetensors", model.classifier, model.weights, meta))
    assert "depth" not in robot.topics
    for m, said in ((taught, True), (model, False)):
        core = PlannerNodeCore(m, robot, np.array([[20.0, 15.0], [60.0, 15.0]]))
        core.on_camera_info(camera_info(TS, header(TS, 0.0, "camera_optical"), CameraConfig()))
        notes = [n for n in core.runtime.notes if "taught relief" in n]
        assert bool(notes) == said and all(f"{robot.source} names no topics.depth" in n for n in notes)


def test_the_rules_settings_come_from_the_robot_file_then_the_nodes_parameters(setup, tmp_path):
    """The robot file's ``rules`` block, then a node's parameters over it (ROS 2's flat
    ``offset.switch_margin``, ROS 1's nested ``~offset``), are what the node's planner decides
    with; an unknown name or a value a rule cannot take is refused in one line when the node starts."""
    from terrapref.errors import ConfigError, UserError
    from terrapref.interop.node_core import NodeOptions, nested_rule_params
    from terrapref.interop.ros2 import RosArgs

    model, _, path, images = setup
    text = (
        "format: terrapref-robot/1\ntopics: {segmentation: /seg, camera_info: /info, odometry: /odom, command: /cmd}\n"
        "camera: {height_m: 1.0, pitch_deg: 30.0}\nlabels: terrapref\nrules: {offset: {switch_margin: 0.25, pursuit_m: 3.0}}\n"
    )
    (tmp_path / "robot.yaml").write_text(text)
    robot = load_robot(tmp_path / "robot.yaml")
    args = RosArgs.parse(["-p", "offset.switch_margin:=0.3", "-p", "rate:=10"])
    opts = NodeOptions().with_rule_params(args.rule_params, "--ros-args").resolved(args.get_param, param=lambda name: f"-p {name}")
    core = PlannerNodeCore(model, opts.applied_to(robot), path)
    core.on_camera_info(camera_info(TS, header(TS, 0.0, "camera_optical"), CameraConfig()))
    held = core.runtime.planner.runner.config
    assert (held.switch_margin, held.pursuit_m) == (0.3, 3.0)  # the parameter over the file, the file over the model
    assert "offset.switch_margin 0.3" in core.runtime.notes[0] and "offset.pursuit_m 3" in core.runtime.notes[0]
    ros1 = {"~offset": {"switch_margin": 0.4}}
    assert nested_rule_params(lambda name, default: ros1.get(name, default)) == {"offset.switch_margin": 0.4}
    with pytest.raises(UserError, match=r"^--ros-args: offset.switch_margn: the offset rule has no setting 'switch_margn'"):
        NodeOptions().with_rule_params(RosArgs.parse(["-p", "offset.switch_margn:=0.3"]).rule_params, "--ros-args")
    with pytest.raises(UserError, match=r"^--ros-args: offset.switch_margin: expected a value >= 0, got -0.1"):  # before any model
        NodeOptions().with_rule_params({"offset.switch_margin": -0.1}, "--ros-args")
    stopping = NodeOptions().with_rule_params(
        RosArgs.parse(["-p", "stop.decel_mps2:=0.5", "-p", "stop.margin_m:=0.6"]).rule_params, "--ros-args"
    )
    braking = stopping.applied_to(robot).stop  # the stop rule's stopping distance, over the robot file's
    assert (braking.decel_mps2, braking.margin_m, braking.reaction_s) == (0.5, 0.6, robot.stop.reaction_s)
    assert nested_rule_params(lambda name, default: {"~stop": {"margin_m": 0.6}}.get(name, default)) == {"stop.margin_m": 0.6}
    with pytest.raises(UserError, match=r"^--ros-args: stop.brakes: the stop rule has no setting 'brakes'"):
        NodeOptions().with_rule_params({"stop.brakes": 1.0}, "--ros-args")
    with pytest.raises(UserError, match=r"^--ros-args: stop.arcs: expected a whole number, got number 21.5"):
        NodeOptions().with_rule_params({"stop.arcs": 21.5}, "--ros-args")  # not cut to 21
    with pytest.raises(UserError, match=r"^stop.decel_mps2: "):
        NodeOptions().with_rule_params({"stop.decel_mps2": -1.0}, "--ros-args").applied_to(robot)
    (tmp_path / "bad.yaml").write_text(text.replace("switch_margin: 0.25", "margin: 0.25"))
    with pytest.raises(ConfigError) as raised:
        load_robot(tmp_path / "bad.yaml")
    assert raised.value.problems[0].field == "rules.offset.margin"


# --- depth on a robot that names a depth topic ----------------------------------------------------

EPOCH = 1_700_000_000  # header() stamps on the epoch-like clock [s]
TILT_PER_S = (0.5, 0.1, -0.05)  # the odometry's height [m], pitch and roll [rad] per second of the drive


def _depth_core(setup, tmp_path, depth_info: bool = False, info: bool = True) -> tuple[PlannerNodeCore, list]:
    """A node whose robot file names a depth topic (and its calibration), odometry over 1 s with
    the body's height and tilt changing, and what its runtime is handed: (stamp, DepthFrame)."""
    from terrapref.interop.ros_messages import rpy_quaternion

    model, _, path, _ = setup
    topics = "segmentation: /seg, camera_info: /info, odometry: /odom, command: /cmd, depth: /depth"
    (tmp_path / "robot.yaml").write_text(
        f"format: terrapref-robot/1\ntopics: {{{topics}{', depth_info: /depth_info' if depth_info else ''}}}\n"
        "camera: {height_m: 1.0, pitch_deg: 30.0}\nlabels: terrapref\nlimits: {max_accel_mps2: null}\n"
    )
    core, handed = PlannerNodeCore(model, load_robot(tmp_path / "robot.yaml"), path), []
    if info:
        core.on_camera_info(camera_info(TS, header(TS, 0.0, "camera_optical"), CameraConfig()))
        decide = core.runtime.decide
        core.runtime.decide = lambda ids, t, p, v=None, depth=None: (
            handed.append((round(t - EPOCH, 6), depth)) or decide(ids, t, p, v, depth=depth)
        )
    for i in range(11):
        t = 0.1 * i
        z, pitch, roll = (k * t for k in TILT_PER_S)
        core.on_odometry(odometry(TS, header(TS, t, "odom"), pose(TS, 20.0 + t, 15.0, rpy_quaternion(TS, roll, pitch, 0.0), z)))
    return core, handed


def _label(setup, t: float):
    return compressed_image(TS, header(TS, t, "camera_optical"), "png", png(setup[3][0]))


def _depth(t: float, metres: float, shape: tuple[int, int] = (480, 640), encoding: str = "16UC1"):
    """A depth image stamped ``t`` [s], ``metres`` everywhere (which one the node pairs, by its value)."""
    from terrapref.interop.ros_messages import depth_image

    msg = depth_image(TS, header(TS, t, "camera_optical"), np.full(shape, metres, np.float32))
    msg.encoding = encoding
    return msg


def test_on_a_robot_with_depth_each_image_takes_the_depth_image_of_the_nearest_stamp_and_waits_for_a_nearer_one(setup, tmp_path):
    """Within 50 ms, as import pairs them, with the body's attitude from the odometry at the
    image's stamp; an image newer than every depth image waits for the next; one with none that
    near is skipped and counted, never decided on as if the ground were flat."""
    from terrapref.interop.node_core import NO_DEPTH
    from terrapref.vehicle.ground import Attitude

    core, handed = _depth_core(setup, tmp_path)
    said = []
    core.on_problem = said.append  # the nodes' logs say it once
    seg = "sensor_msgs/msg/CompressedImage"
    core.on_depth(_depth(0.07, 7.0), "/depth")
    core.on_depth(_depth(0.11, 11.0), "/depth")
    assert core.on_image(seg, _label(setup, 0.1)) is not None  # 10 ms from 0.11, 30 from 0.07
    assert core.on_image(seg, _label(setup, 0.25)) is None  # newer than every depth image: it waits
    assert core.on_depth(_depth(0.24, 24.0), "/depth") is None  # a nearer one may still come
    decision = core.on_depth(_depth(0.27, 27.0), "/depth")  # past its stamp: the nearest is 0.24
    assert decision is not None and round(decision.stamp_s - EPOCH, 6) == 0.25
    assert core.on_image(seg, _label(setup, 0.4)) is None
    assert core.on_depth(_depth(0.46, 46.0), "/depth") is None  # 60 ms away: skipped
    assert core.on_image(seg, _label(setup, 1.0)) is None  # the depth images stopped 0.54 s before: skipped at once
    assert [(t, float(np.nanmax(d.image))) for t, d in handed] == [(0.1, 11.0), (0.25, 24.0)]
    expected = Attitude(*(k * 0.25 for k in TILT_PER_S))  # interpolated between the poses at 0.2 and 0.3 s
    np.testing.assert_allclose(handed[1][1].attitude, expected, atol=1e-6)  # (stamps on the epoch-like clock: to 2e-7 s)
    assert core.decided == 2 and core.skipped[NO_DEPTH] == 2 and sum(core.skipped.values()) == 2
    # A skipped frame is said where it happens (the log named no depth while the node stood still).
    assert (
        said
        == ["/depth: a label image without a depth image within 50 ms of its stamp: skipped, and the robot stops (stale) while they are"]
        * 2
    )


def test_depth_images_that_come_after_the_next_label_image_are_each_waited_for(setup, tmp_path):
    """A depth pipeline 0.25 s behind the segmentation at 10 Hz: each label image's depth comes
    after two more label images. Only the newest image waited, so each was superseded before its
    depth came and the node never decided (246 of 247 frames superseded on a log)."""
    core, handed = _depth_core(setup, tmp_path)
    seg = "sensor_msgs/msg/CompressedImage"
    core.on_depth(_depth(0.0, 5.0), "/depth")
    decided = []
    for k in range(1, 9):  # label image k at 0.1 k s; its depth image comes after label image k + 2
        if (d := core.on_image(seg, _label(setup, 0.1 * k))) is not None:
            decided.append(d)
        if k >= 3 and (d := core.on_depth(_depth(0.1 * (k - 2), 10.0 * (k - 2)), "/depth")) is not None:
            decided.append(d)
    assert [round(d.stamp_s - EPOCH, 6) for d in decided] == [0.1, 0.2, 0.3, 0.4, 0.5, 0.6]
    assert [float(np.nanmax(d.image)) for _, d in handed] == [10.0, 20.0, 30.0, 40.0, 50.0, 60.0]  # each with its own
    assert core.skipped["superseded while waiting for odometry or depth"] == 0


def test_a_depth_image_the_node_cannot_use_is_refused_by_name_and_counted(setup, tmp_path):
    from terrapref.errors import UserError

    core, _ = _depth_core(setup, tmp_path)
    for bad, said in (
        (_depth(0.1, 2.0, encoding="mono16"), "/depth: depth image encoding 'mono16'; expected 32FC1 (metres) or 16UC1"),
        (_depth(0.1, 2.0, shape=(240, 320)), "/depth: depth image 320 x 240, the label camera's is 640 x 480"),
    ):
        with pytest.raises(UserError, match=re.escape(said)) as raised:
            core.on_depth(bad, "/depth")
        assert raised.value.problems[0].field == "topics.depth" and raised.value.source.endswith("robot.yaml")
    with pytest.raises(ValueError, match="/depth: a depth image stamped more than 1 s ahead of the node's clock"):
        core.on_depth(_depth(3600.0, 2.0), "/depth", now_s=EPOCH + 0.0)
    assert core.skipped["depth images of another encoding or size"] == 2 and core.skipped["depth images ahead of the clock"] == 1
    assert core.depth.held == []
    early, _ = _depth_core(setup, tmp_path, info=False)
    assert early.on_depth(_depth(0.1, 2.0), "/depth") is None and early.depth.held == []  # before the calibration: let go


def test_a_depth_camera_of_its_own_calibration_must_be_the_label_cameras_and_frames_wait_for_it(setup, tmp_path):
    from dataclasses import replace

    from terrapref.errors import UserError

    core, _ = _depth_core(setup, tmp_path, depth_info=True)
    core.on_depth(_depth(0.1, 2.0), "/depth")
    assert core.on_image("sensor_msgs/msg/CompressedImage", _label(setup, 0.1)) is None
    assert core.skipped["before the calibration or the path"] == 1
    label_info = camera_info(TS, header(TS, 0.0, "camera_optical"), CameraConfig())
    core.on_depth_info(label_info)  # the label camera's: registered
    assert core.on_image("sensor_msgs/msg/CompressedImage", _label(setup, 0.1)) is not None
    other = camera_info(TS, header(TS, 0.0, "camera_optical"), replace(CameraConfig(), hfov_deg=60.0))
    for depth_first in (True, False):  # whichever comes first, the second is checked against it
        late, _ = _depth_core(setup, tmp_path, depth_info=True, info=False)
        first, then = (late.on_depth_info, late.on_camera_info) if depth_first else (late.on_camera_info, late.on_depth_info)
        first(other if depth_first else label_info)
        with pytest.raises(
            UserError,
            match="/depth_info says the depth camera is 640 x 480, fx 554.256 .*the label camera \\(/info\\) is 640 x 480, fx 320",
        ) as raised:
            then(label_info if depth_first else other)
        assert raised.value.problems[0].field == "topics.depth_info"


def test_a_rate_too_low_for_the_hold_is_refused():
    """At 1 Hz with a hold of 0.3 s, a stop once a command's hold runs out would wait up to a second."""
    from terrapref.errors import UserError
    from terrapref.interop.node_core import NodeOptions

    with pytest.raises(UserError, match=r"~rate: expected at least 1 / hold_s = 3.33333 Hz"):
        NodeOptions().resolved(lambda name, default: {"~rate": 1.0}.get(name, default))
    assert NodeOptions(rate=2.0, hold_s=0.5).resolved(lambda name, default: default).rate == 2.0


def test_odometry_without_a_heading_is_refused_and_one_not_of_unit_length_normalised(setup):
    """A zero or non-finite quaternion turns the body no known way (tf2 refuses it): read as a
    heading of 0 it once drove the robot on a heading it never reported. One of another length is
    the same turn, normalised."""
    from terrapref.interop.ros_messages import quaternion

    core, _ = _core(setup)
    x, y, _ = POSES[0]
    for xyzw in ((0.0, 0.0, 0.0, 0.0), (0.0, 0.0, float("nan"), 1.0)):
        with pytest.raises(ValueError, match="zero or non-finite quaternion"):
            core.on_odometry(odometry(TS, header(TS, 0.0, "odom"), pose(TS, x, y, quaternion(TS, xyzw))))
    assert not core.odometry
    core.on_odometry(odometry(TS, header(TS, 0.0, "odom"), pose(TS, x, y, quaternion(TS, (0.0, 0.0, 2.0, 2.0)))))
    assert core.odometry[-1][3] == pytest.approx(math.pi / 2)


def test_a_problem_is_said_once_whatever_numbers_it_carries_and_each_refusal_is_counted(setup):
    """A pose refused for its speed, each a little different, was said once a frame, each line
    ending "(said once ...)", and the closing line left the refused frames out."""
    from terrapref.interop.node_core import NodeLog, report_line

    said: list[str] = []
    log = NodeLog(said.append, said.append, said.append)
    core, _ = _core(setup)

    def refused(speed: float):
        raise ValueError(f"speed {speed:g} m/s is past any this robot drives")

    for speed in (3.598, 3.61, 1e3):
        assert log.guarded(lambda speed=speed: refused(speed)) is None
    log.guarded(lambda: (_ for _ in ()).throw(ValueError("an image of 48 x 64, expected 480 x 640")))
    assert said == [
        "terrapref: speed 3.598 m/s is past any this robot drives (said once; such messages are skipped)",
        "terrapref: an image of 48 x 64, expected 480 x 640 (said once; such messages are skipped)",
    ]
    assert report_line(core, "ros2", log) == "terrapref ros2: 0 frames decided on; skipped: 4 messages refused (the log says why)"
    assert report_line(core, "ros2") == "terrapref ros2: 0 frames decided on; skipped: none"


def test_a_robot_file_whose_camera_is_mounted_by_tf_is_refused_as_the_node_starts(setup, tmp_path):
    """Import reads the camera's mounting from a log's /tf_static; the nodes read no tf, and such a
    robot file once ended a node at its first camera_info, saying no transform was in /tf_static."""
    from terrapref.errors import UserError
    from terrapref.interop.node_core import PlannerNodeCore

    model, _, path, _ = setup
    robot = tmp_path / "robot.yaml"
    robot.write_text(
        "format: terrapref-robot/1\ntopics: {segmentation: /seg, camera_info: /info, odometry: /odom, command: /cmd}\n"
        "camera: {tf: base_link}\nlabels: terrapref\n"
    )
    with pytest.raises(UserError, match=r"robot.yaml: camera: tf: the nodes read no /tf_static; give the camera's height_m"):
        PlannerNodeCore(model, load_robot(robot), path)


def test_a_label_image_on_another_clock_than_the_odometry_is_refused_saying_so(setup):
    """A segmentation node that does not copy the camera's stamp sends 0: each image was counted as
    without odometry at its stamp, and nothing was said while the node ran."""
    core, told = _core(setup)
    core.on_odometry(_odom(0))
    zero = compressed_image(TS, header(TS, 0.0, "camera_optical"), "png", png(setup[3][0]))
    zero.header.stamp.sec, zero.header.stamp.nanosec = 0, 0
    with pytest.raises(ValueError, match=r"before the newest odometry \(stamped 0, or on another clock than the odometry's\?\)"):
        core.on_image("sensor_msgs/msg/CompressedImage", zero)
    assert told == [] and core.skipped["without odometry at the stamp"] == 0
    late = compressed_image(TS, header(TS, -1.0, "camera_optical"), "png", png(setup[3][0]))  # a second late: counted, not refused
    assert core.on_image("sensor_msgs/msg/CompressedImage", late) is None and core.skipped["without odometry at the stamp"] == 1
