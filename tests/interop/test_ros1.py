"""The ROS 1 node against a real ROS master: a recording's frames published one by one, each with
the depth image of level ground (32FC1), the node's commands the same as PlannerRuntime's on the
same frames, and its GridMap the runtime's costmap layer for layer.

Needs Debian's ROS 1 packages (``roscore``, ``python3-rospy`` and the message packages); skipped
with the reason where they are missing.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
import textwrap
import threading
import time
from types import SimpleNamespace

import numpy as np
import pytest

FIRST, FRAMES = 200, 40  # the short recording's frames published: the drive comes up to the non_traversable patch


def _ros1_missing() -> str | None:
    if shutil.which("roscore") is None:
        return "roscore is not installed (Debian: apt install ros-core)"
    probe = subprocess.run(
        [
            sys.executable,
            "-c",
            "from terrapref.interop.ros1 import import_rospy; import_rospy(); "
            "import sensor_msgs.msg, nav_msgs.msg, geometry_msgs.msg, visualization_msgs.msg",
        ],
        capture_output=True,
        text=True,
    )
    return None if probe.returncode == 0 else f"rospy or ROS 1 message packages are missing ({probe.stderr.strip().splitlines()[-1:]})"


_MISSING = _ros1_missing()
pytestmark = pytest.mark.skipif(_MISSING is not None, reason=str(_MISSING))

PLAYER = textwrap.dedent('''
    """Publish a recording's first frames to the node, one at a time, each with a depth image, and keep
    the command each gets, then the GridMap the node publishes once it has all of them."""
    import json, sys, time
    from terrapref.interop.ros1 import import_rospy
    rospy = import_rospy()
    import numpy as np
    from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped, TwistStamped
    from nav_msgs.msg import Path
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import CameraInfo, Image
    from terrapref.demos.recording import read_recording
    from terrapref.interop.ros_messages import typestore

    rec_dir, first, frames, out, depth_file = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], sys.argv[5]
    rec = read_recording(rec_dir)
    level = np.load(depth_file).astype("<f4")  # REP 118's 32FC1: metres, NaN where nothing is seen
    rospy.init_node("player")
    info_pub = rospy.Publisher("/cam/info", CameraInfo, queue_size=1, latch=True)
    path_pub = rospy.Publisher("/plan", Path, queue_size=1, latch=True)
    odom_pub = rospy.Publisher("/odom", PoseWithCovarianceStamped, queue_size=10)  # a localiser's pose, as the robot file allows
    seg_pub = rospy.Publisher("/seg", Image, queue_size=10)
    depth_pub = rospy.Publisher("/depth", Image, queue_size=10)
    clock_pub = rospy.Publisher("/clock", Clock, queue_size=10)  # the log's clock, as rosbag play --clock gives it
    got = {}
    rospy.Subscriber("/cmd", TwistStamped, lambda m: got.__setitem__(round(m.header.stamp.to_sec(), 3), (m.twist.linear.x, m.twist.angular.z)))
    maps = []  # each GridMap heard: its connection header and bytes (grid_map_msgs has no Python class here)
    rospy.Subscriber("/terrapref/grid_map", rospy.AnyMsg, lambda m: maps.append((m._connection_header, bytes(m._buff))))
    while min(p.get_num_connections() for p in (seg_pub, depth_pub, odom_pub, clock_pub)) == 0:  # the node subscribes
        time.sleep(0.05)
    from terrapref.camera import CameraConfig
    fx, fy, cx, cy = CameraConfig().intrinsics  # the camera the model was trained for
    cx, cy = cx - 0.5, cy - 0.5  # in ROS's pixel coordinates, a pixel's centre at its index
    info = CameraInfo(width=640, height=480, distortion_model="plumb_bob", D=[0.0] * 5,
                      K=[fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0], P=[fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0])
    info.header.frame_id = "camera"
    info_pub.publish(info)
    path = Path()
    path.header.frame_id = "odom"
    for x, y in np.asarray(rec.meta.get("path") or rec.scenario["path"]["waypoints"], dtype=float):
        p = PoseStamped()
        p.pose.position.x, p.pose.position.y, p.pose.orientation.w = float(x), float(y), 1.0
        path.poses.append(p)
    path_pub.publish(path)
    def messages(i, t):
        x, y, yaw = (float(v) for v in rec.poses[i])
        odom = PoseWithCovarianceStamped()
        odom.header.stamp = rospy.Time.from_sec(t)
        odom.header.frame_id = "odom"
        odom.pose.pose.position.x, odom.pose.pose.position.y = x, y
        odom.pose.pose.orientation.z, odom.pose.pose.orientation.w = np.sin(yaw / 2), np.cos(yaw / 2)
        image = Image(height=480, width=640, encoding="mono8", step=640, data=rec.image(i).tobytes())
        image.header.stamp = rospy.Time.from_sec(t)
        depth = Image(height=480, width=640, encoding="32FC1", is_bigendian=0, step=4 * 640, data=level.tobytes())
        depth.header.stamp = rospy.Time.from_sec(t)
        return odom, depth, image
    # The first frame before any /clock (the node's time still 0), sent for 2 s while the node takes
    # its calibration and path: no command can be timed by that clock, and none comes.
    for _ in range(8):
        for msg, pub in zip(messages(first, 100.0 + 0.1 * first), (odom_pub, depth_pub, seg_pub)):
            pub.publish(msg)
        time.sleep(0.25)
    before_clock = got.get(round(100.0 + 0.1 * first, 3))
    results = []
    for i in range(first, first + frames):
        t = 100.0 + 0.1 * i
        odom, depth, image = messages(i, t)
        clock_pub.publish(Clock(clock=rospy.Time.from_sec(t)))
        while round(t, 3) not in got:  # sent again until decided on (the node may not have the calibration yet)
            odom_pub.publish(odom)
            depth_pub.publish(depth)
            seg_pub.publish(image)
            deadline = time.time() + 1.0
            while round(t, 3) not in got and time.time() < deadline:
                time.sleep(0.005)
        results.append(got[round(t, 3)])
    # The node's clock moved on by more than its costmap's period: the GridMap stamped then holds every frame.
    ts, later = typestore(ros1=True), t + 1.5
    def stamp(raw):
        s = ts.deserialize_ros1(raw, "grid_map_msgs/msg/GridMap").info.header.stamp
        return s.sec + 1e-9 * s.nanosec
    while not any(stamp(raw) >= later - 1e-6 for _, raw in maps):
        clock_pub.publish(Clock(clock=rospy.Time.from_sec(later)))
        time.sleep(0.1)
    header, raw = next((h, raw) for h, raw in maps if stamp(raw) >= later - 1e-6)
    heard = {k: header[k] for k in ("type", "md5sum", "latching")} | {"raw": raw.hex()}
    json.dump({"commands": results, "before_clock": before_clock, "grid_map": heard}, open(out, "w"))
''')


@pytest.fixture(scope="module")
def setup(tmp_path_factory, short_recording):
    from test_offset_rule import DRIVER_LIKE, _offset_meta

    from helpers import flat_depth, skip_path_weights
    from terrapref.camera import CameraConfig, PinholeCamera
    from terrapref.learning.model_file import save_model
    from terrapref.learning.network import ClassifierConfig

    root = tmp_path_factory.mktemp("ros1")
    (root / "rec").symlink_to(short_recording, target_is_directory=True)
    config = ClassifierConfig(hidden=8, skip=True)
    model = save_model(root / "m.safetensors", config, skip_path_weights(config), _offset_meta(DRIVER_LIKE))
    (root / "robot.yaml").write_text(
        "format: terrapref-robot/1\n"
        "topics: {segmentation: /seg, camera_info: /cam/info, odometry: /odom, command: /cmd, path: /plan, depth: /depth}\n"
        "camera: {height_m: 1.0, pitch_deg: 30.0}\nlabels: terrapref\n"
        "limits: {max_accel_mps2: null}\n"  # the base ramps its speed itself: the command sent is the decision's
    )
    np.save(root / "level.npy", flat_depth(PinholeCamera(CameraConfig()))[0].astype(np.float32))  # the camera the robot file mounts
    return root, model


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_the_node_commands_what_the_runtime_commands_on_the_same_frames(setup, tmp_path):
    from test_grid_map_msgs import GRID_MAP_MD5
    from test_live import _watch

    from terrapref.demos.recording import read_recording
    from terrapref.interop.ros_messages import grid_map_layer, typestore
    from terrapref.runtime import DepthFrame, PlannerRuntime

    root, model = setup
    port, live_port, seen = _free_port(), _free_port(), {}
    env = {**os.environ, "ROS_MASTER_URI": f"http://127.0.0.1:{port}", "ROS_HOME": str(tmp_path / "ros"), "ROS_IP": "127.0.0.1"}
    master = subprocess.Popen(
        ["roscore", "-p", str(port)], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True
    )
    node = player = None
    try:
        # TwistStamped through the node's private ROS parameter, as a launch file would set it, and
        # the node's clock the player's (a command is in force until its frame is 0.3 s old by it).
        for _ in range(100):
            if subprocess.run(["rosparam", "set", "/terrapref/stamped", "true"], env=env, capture_output=True).returncode == 0:
                break
            time.sleep(0.1)
        subprocess.run(["rosparam", "set", "/use_sim_time", "true"], env=env, check=True, capture_output=True)
        node = subprocess.Popen(
            [
                sys.executable,
                "-c",
                "import sys; from terrapref.cli import main; sys.exit(main())",
                "ros1",
                "--model",
                str(model),
                "--robot",
                str(root / "robot.yaml"),
                "--live",
                "--live-port",
                str(live_port),
            ],
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,
        )
        client = threading.Thread(target=_watch, args=(live_port, seen), daemon=True)
        client.start()
        (tmp_path / "player.py").write_text(PLAYER)
        player = subprocess.run(
            [
                sys.executable,
                str(tmp_path / "player.py"),
                str(root / "rec"),
                str(FIRST),
                str(FRAMES),
                str(tmp_path / "got.json"),
                str(root / "level.npy"),
            ],
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert player.returncode == 0, player.stderr[-2000:]
    finally:
        for proc in (node, master):
            if proc is not None:
                os.killpg(proc.pid, 15)
                proc.wait(timeout=30)
    said = node.stdout.read() + node.stderr.read()
    assert "terrapref: limits: 2 m/s, 1 rad/s; on relief 25 deg of roll, 30 of pitch, a step of 0.15 m" in said, said[
        -2000:
    ]  # as ROS 2's start
    heard = json.loads((tmp_path / "got.json").read_text())
    assert heard["before_clock"] is None  # a frame before the first /clock is skipped, not answered with a stop
    got = np.array(heard["commands"])
    rec = read_recording(root / "rec")
    runtime = PlannerRuntime(model)
    runtime.set_path(np.asarray(rec.meta.get("path") or rec.scenario["path"]["waypoints"], dtype=float))
    depth = DepthFrame(np.load(root / "level.npy"))
    expected = np.array(
        [runtime.decide(rec.image(i), 100.0 + 0.1 * i, tuple(rec.poses[i]), depth=depth).command for i in range(FIRST, FIRST + FRAMES)]
    )
    assert got.shape == (FRAMES, 2)
    np.testing.assert_allclose(got, expected, atol=1e-6)
    assert len(np.unique(expected[:, 1])) > 1  # the frames make it steer, not only drive straight
    # Beside its OccupancyGrid, the costmap's layers as ROS 1's grid_map_msgs/GridMap (latched),
    # cell for cell the runtime's after the same frames.
    grid_map = heard["grid_map"]
    assert (grid_map["type"], grid_map["md5sum"], grid_map["latching"]) == ("grid_map_msgs/GridMap", GRID_MAP_MD5, "1")
    msg = typestore(ros1=True).deserialize_ros1(bytes.fromhex(grid_map["raw"]), "grid_map_msgs/msg/GridMap")
    costmap = runtime.costmap()
    layers = costmap.grid_layers()
    assert list(msg.layers) == list(layers) and {"cost", "elevation", "slope", "roughness", "step"} <= set(layers)
    assert (msg.info.header.frame_id, msg.info.resolution) == ("odom", costmap.resolution_m)
    for name, layer in layers.items():  # the node's pose and attitude are read back from odometry's quaternion: equal to rounding
        np.testing.assert_allclose(grid_map_layer(msg, name), layer, rtol=0, atol=1e-6, err_msg=name)
    # The ground seen, and through the depth images (within the height layer's range) its height: level, 0 m.
    ground, height = np.isfinite(layers["cost"]), np.isfinite(layers["elevation"])
    assert ground.sum() > 1000 and (height & ground).sum() > 1000 and np.abs(layers["elevation"][height]).max() < 0.01
    # The live view carried the decisions as they were made, stamped with the frames' ROS times.
    client.join(timeout=30)
    labels = seen.get("/terrapref/labels", [])
    assert "error" not in seen and len(labels) >= FRAMES // 2
    stamps = sorted(log_ns for log_ns, _ in labels)
    assert abs(stamps[-1] * 1e-9 - (100.0 + 0.1 * (FIRST + FRAMES - 1))) < 1e-6
    assert seen.get("/terrapref/costmap") and seen.get("/terrapref/trajectories")


def test_node_options_come_from_the_command_line_then_ros_parameters_then_defaults():
    from terrapref.errors import UserError
    from terrapref.interop.ros1 import NodeOptions

    params = {"~rate": 50, "~stamped": True, "~cmd_topic": "/robot/cmd"}
    got = NodeOptions(rate=10.0).resolved(lambda name, default: params.get(name, default))
    assert (got.rate, got.stamped, got.cmd_topic, got.path_file, got.hold_s) == (10.0, True, "/robot/cmd", None, 0.3)
    for bad, field in (
        ({"~rate": "fast"}, "~rate"),
        ({"~hold_s": -1}, "~hold_s"),
        ({"~stamped": "yes"}, "~stamped"),
        ({"~cmd_topic": ""}, "~cmd_topic"),
    ):
        with pytest.raises(UserError, match=field):
            NodeOptions().resolved(lambda name, default, bad=bad: bad.get(name, default))
    with pytest.raises(UserError, match="--rate"):
        NodeOptions(rate=float("nan")).resolved(lambda name, default: default)


def test_without_rosbags_the_node_says_once_that_its_grid_map_needs_the_robot_extra(monkeypatch):
    from terrapref.interop.ros1 import _GridMaps

    monkeypatch.setitem(sys.modules, "rosbags", None)  # not installed
    said: list[str] = []
    assert _GridMaps.made(None, SimpleNamespace(warn=said.append)) is None
    assert said == [
        "terrapref: ~grid_map (grid_map_msgs/GridMap): needs the robot extra: pip install 'terrapref[robot]' "
        "(rosbags is not installed); the costmap goes out as an OccupancyGrid only"
    ]


def test_the_node_ends_with_a_stop_that_stays_the_last_command(monkeypatch, capsys):
    """As ROS shuts the node down (Ctrl-C, SIGTERM) while it commands motion, its last command is
    a stop, given a moment to go out, and neither its ticks nor a decision send another after it."""
    import threading

    import terrapref.interop.ros1 as ros1
    from terrapref.interop.node_core import NodeOptions

    class Twist:
        def __init__(self) -> None:
            self.linear, self.angular = SimpleNamespace(x=0.0), SimpleNamespace(z=0.0)

    sent: list[tuple[float, float]] = []
    node = object.__new__(ros1._Node)  # the node's parts close() and the commands use, without a ROS master
    node.rospy = SimpleNamespace(get_time=lambda: 5.0)
    node.core = SimpleNamespace(lock=threading.RLock(), status_at=lambda now_s: ((1.5, 0.1), None), skipped={}, decided=3)
    node.opts, node.Twist, node.ended, node.done, node.last_stamp = NodeOptions(), Twist, False, threading.Event(), 4.9
    node.log = SimpleNamespace(status=lambda reason: None, refused=0)
    node.cmd_pub = SimpleNamespace(publish=lambda msg: sent.append((msg.linear.x, msg.angular.z)))
    monkeypatch.setattr(ros1, "STOP_DELIVERY_S", 0.0)
    monkeypatch.setattr("terrapref.interop.node_core.report_line", lambda core, command, log: "decided 3")
    node.publish_command(4.9)
    node.close()
    node.publish_command(4.9)
    assert sent == [(1.5, 0.1), (0.0, 0.0)] and node.done.is_set()
    assert capsys.readouterr().out == "decided 3\n"


def test_an_exported_ros1_bag_reads_with_ros1s_own_rosbag(tmp_path, tiny_recording):
    """``export --format rosbag1`` writes lz4 chunks that ROS 1's own reader (roslz4: ``rosbag
    play``, the rosbag Python API) decompresses; rosbags' default lz4 frames it refuses as
    "malformed data to decompress"."""
    from terrapref.cli import main

    out = tmp_path / "run.bag"
    assert main(["export", str(tiny_recording), "--format", "rosbag1", "--out", str(out)]) == 0
    reader = (
        "import sys, collections; from terrapref.interop.ros1 import import_rospy; import_rospy(); import rosbag\n"
        "with rosbag.Bag(sys.argv[1]) as bag:\n"
        "    print(bag.get_compression_info().compression, collections.Counter(t for t, _, _ in bag.read_messages())['/terrapref/labels'])"
    )
    got = subprocess.run([sys.executable, "-c", reader, str(out)], capture_output=True, text=True, timeout=120)
    assert got.returncode == 0, got.stderr[-1000:]
    frames = sum(1 for _ in (tiny_recording / "frames.jsonl").open())
    assert got.stdout.split() == ["lz4", str(frames)]
