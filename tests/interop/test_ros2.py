"""The ROS 2 node (terrapref.interop.ros2) as a ROS 2 system over DDS on this machine: the node in
one process; in this one, a recording exported as ROS 2 MCAP published frame by frame with
/clock (terrapref.interop.play), a subscriber of the node's topics, and DDS discovery read back.
Each frame carries the depth image of level ground (16UC1), which the robot file names.

Every participant keeps to the loopback interface (a Cyclone DDS configuration in CYCLONEDDS_URI)
and to a domain of its own test run, so that parallel runs never hear each other.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

FIRST, FRAMES = 200, 40  # the short recording's frames published: the drive comes up to the non_traversable patch
SILENT_S = 1.5  # the idle node's -p silent_s: it says nobody publishes this long after its start (not the default 5 s)
IDLE_FRAMES = 6  # the first of them, that `terrapref play` publishes to the node that waited (at a quarter of real time)
LOOPBACK = (
    '<CycloneDDS><Domain Id="any"><General><Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces>'
    "<AllowMulticast>false</AllowMulticast></General><Discovery><ParticipantIndex>auto</ParticipantIndex>"
    '<MaxAutoParticipantIndex>60</MaxAutoParticipantIndex><Peers><Peer address="127.0.0.1"/></Peers></Discovery></Domain></CycloneDDS>'
)
NODE_TYPES = (
    "sensor_msgs/msg/Image",
    "sensor_msgs/msg/CompressedImage",
    "sensor_msgs/msg/CameraInfo",
    "nav_msgs/msg/Odometry",
    "geometry_msgs/msg/PoseStamped",
    "geometry_msgs/msg/PoseWithCovarianceStamped",
    "nav_msgs/msg/Path",
    "rosgraph_msgs/msg/Clock",
    "geometry_msgs/msg/Twist",
    "geometry_msgs/msg/TwistStamped",
    "visualization_msgs/msg/MarkerArray",
    "nav_msgs/msg/OccupancyGrid",
    "tf2_msgs/msg/TFMessage",
)
# As `ros2 topic info --verbose` prints them on ROS 2 Jazzy: hashes of the real message packages.
JAZZY_HASHES = {
    "geometry_msgs/msg/Twist": "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a",
    "geometry_msgs/msg/PoseStamped": "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8",
}


def _domains() -> tuple[int, int]:
    """Two DDS domains where no other participant is heard (pytest-xdist runs workers side by
    side, and another run may share the machine): tried from one the process id picks."""
    from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsParticipant
    from cyclonedds.domain import DomainParticipant

    quiet, start = [], os.getpid() % 200
    for k in range(0, 200, 2):  # two domains listened to at once
        domains = [20 + (start + k + i) % 200 for i in range(2)]
        listeners = [(dp, BuiltinDataReader(dp, BuiltinTopicDcpsParticipant)) for dp in map(DomainParticipant, domains)]
        time.sleep(0.3)  # a participant there announces itself within this on loopback
        for domain, (dp, reader) in zip(domains, listeners, strict=True):
            if not [p for p in reader.take(N=20) if p.key != dp.get_guid()]:
                quiet.append(domain)
        del listeners
        if len(quiet) >= 2:
            return quiet[0], quiet[1]
    raise AssertionError("no quiet DDS domain")


# The node as `terrapref ros2` runs, with every thread's stack written to stderr on SIGUSR1: what a node that
# does not end on Ctrl-C was doing is then in the test's failure.
NODE_MAIN = (
    "import faulthandler, signal, sys; faulthandler.register(signal.SIGUSR1, all_threads=True); "
    "from terrapref.cli import main; sys.exit(main())"
)


def _end(proc: subprocess.Popen, readers: list[threading.Thread], output: Callable[[], str], what: str) -> str | None:
    """Ctrl-C has been sent to ``proc``: wait for it to end. If it does not within 30 s, write
    its threads' stacks (SIGUSR1), kill it, and return what it was doing, for the failure."""
    stuck = None
    try:
        proc.wait(timeout=30)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGUSR1)
        time.sleep(2.0)
        proc.kill()
        proc.wait()
        stuck = f"{what} did not end within 30 s of Ctrl-C; its threads then:\n"
    for reader in readers:
        reader.join(timeout=10)
    return None if stuck is None else stuck + output()[-12000:]


def _node(
    model: Path, robot: Path, env: dict, *ros_args: str, flags: tuple[str, ...] = (), sigint_ignored: bool = False
) -> subprocess.Popen:
    """The node in a process of its own; ``sigint_ignored``: started as a script's background job
    is (SIGINT ignored, which a child inherits), and Ctrl-C must end it all the same."""
    return subprocess.Popen(
        [sys.executable, "-c", NODE_MAIN, "ros2", "--model", str(model), "--robot", str(robot), *flags, "--ros-args", *ros_args],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=(lambda: signal.signal(signal.SIGINT, signal.SIG_IGN)) if sigint_ignored else None,
    )


def _publish_until_commanded(player, heard, t_ns: int, group: list, stamp: float, tries: int = 20) -> None:
    """Publish the clock at ``t_ns`` and the messages of one stamp, again until a command of the
    image's ``stamp`` is heard (best effort: a message may be lost), at most ``tries`` times."""
    from terrapref.interop.ros_decode import stamp_s

    for _ in range(tries):
        player.publish_clock(t_ns)
        for m in group:
            player.publish(m)
        try:
            _wait(lambda: any(round(stamp_s(c.header), 6) == stamp for c in heard.get("cmd")), timeout_s=1.0, what="a command")
            return
        except AssertionError:
            continue


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait(condition, timeout_s: float = 20.0, what: str = "") -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.01)


class _Heard:
    """What a subscriber of the node's topics received, by topic."""

    def __init__(self) -> None:
        self.lock, self.by_topic = threading.Lock(), {}

    def keeper(self, topic: str):
        def keep(msg) -> None:
            with self.lock:
                self.by_topic.setdefault(topic, []).append(msg)

        return keep

    def get(self, topic: str) -> list:
        with self.lock:
            return list(self.by_topic.get(topic, []))


def _listen(dds, heard: _Heard) -> list:
    """Subscriptions to the node's topics, kept in ``heard``: the readers."""
    from terrapref.interop.dds import DEFAULT, LATCHED

    return [
        dds.subscribe("/terrapref/cmd_vel", "geometry_msgs/msg/TwistStamped", DEFAULT, heard.keeper("cmd")),
        dds.subscribe("/terrapref/trajectories", "visualization_msgs/msg/MarkerArray", DEFAULT, heard.keeper("trajectories")),
        dds.subscribe("/terrapref/costmap", "nav_msgs/msg/OccupancyGrid", LATCHED, heard.keeper("costmap")),
        dds.subscribe("/terrapref/grid_map", "grid_map_msgs/msg/GridMap", LATCHED, heard.keeper("grid_map")),
        dds.subscribe("/tf_static", "tf2_msgs/msg/TFMessage", LATCHED, heard.keeper("tf_static")),
    ]


def _endpoints(dp, own) -> list:
    """The publications and subscriptions discovery reports for participants other than ``own``."""
    from cyclonedds.builtin import BuiltinDataReader, BuiltinTopicDcpsPublication, BuiltinTopicDcpsSubscription

    out = []
    for kind, topic in (("publishes", BuiltinTopicDcpsPublication), ("hears", BuiltinTopicDcpsSubscription)):
        reader = BuiltinDataReader(dp, topic)
        out += [(kind, s) for s in reader.take(N=500) if s.participant_key != own]
    return out


@pytest.fixture(scope="module")
def system(tmp_path_factory, short_recording):
    """Two nodes: one driven frame by frame from this process (with bad input after the drive),
    one that starts in a domain where nobody publishes and is then driven by `terrapref play`."""
    from test_live import _watch
    from test_offset_rule import DRIVER_LIKE, _offset_meta

    from helpers import flat_depth, skip_path_weights
    from terrapref.camera import PinholeCamera
    from terrapref.demos.recording import read_recording
    from terrapref.interop.dds import MessageTypes, Participant
    from terrapref.interop.mcap_export import recording_frames, write_bag
    from terrapref.interop.play import BagPlayer
    from terrapref.interop.ros_decode import stamp_s
    from terrapref.interop.ros_messages import typestore
    from terrapref.learning.model_file import save_model
    from terrapref.learning.network import ClassifierConfig
    from terrapref.pngio import depth_to_millimetres, millimetres_to_depth
    from terrapref.vehicle.ground import LEVEL

    root = tmp_path_factory.mktemp("ros2")
    config = ClassifierConfig(hidden=8, skip=True)
    model = save_model(root / "m.safetensors", config, skip_path_weights(config), _offset_meta(DRIVER_LIKE))
    rec = read_recording(short_recording)
    frames = recording_frames(rec)
    part = slice(FIRST, FIRST + FRAMES + 1)  # one frame more, for after the bad input
    level = flat_depth(PinholeCamera(frames.camera))[0].astype(np.float32)  # the depth image of level ground
    frames = replace(
        frames,
        times=frames.times[part],
        poses=frames.poses[part],
        commands=frames.commands[part],
        chosen=frames.chosen[part],
        image=lambda i: rec.image(FIRST + i),
        depth=lambda i: level,
        attitude=lambda i: LEVEL,
    )
    bag = write_bag(root / "drive.mcap", frames)  # the robot file beside it names the depth topic
    first = slice(0, IDLE_FRAMES)
    idle_bag = write_bag(
        root / "idle.mcap",
        replace(frames, times=frames.times[first], poses=frames.poses[first], commands=frames.commands[first], chosen=frames.chosen[first]),
        robot_file=False,
    )
    robot = root / "drive.mcap.robot.yaml"
    with robot.open("a") as f:  # the base ramps its speed itself: the command sent is the decision's, as the runtime's
        f.write("limits: {max_accel_mps2: null}\n")

    previous_uri = os.environ.get("CYCLONEDDS_URI")
    os.environ["CYCLONEDDS_URI"] = LOOPBACK  # this process's participants, before its first one
    driven, idle_domain = _domains()
    env = {**os.environ, "CYCLONEDDS_URI": LOOPBACK, "TERRAPREF_DEBUG": ""}
    idle_node = _node(
        model,
        robot,
        {**env, "ROS_DOMAIN_ID": str(idle_domain)},
        *("-p", "use_sim_time:=true", "-p", "stamped:=true", "-p", f"silent_s:={SILENT_S}"),
        sigint_ignored=True,
    )
    idle_log: list[str] = []  # read as it comes: the node says it waits, then play starts
    idle_reader = threading.Thread(target=lambda: idle_log.extend(idle_node.stderr), daemon=True)
    idle_reader.start()
    live_port, live = _free_port(), {}
    node = _node(
        model,
        robot,
        {**env, "ROS_DOMAIN_ID": str(driven)},
        "-p",
        "use_sim_time:=true",
        "-p",
        "stamped:=true",
        "-p",
        "rate:=50",
        flags=("--live", "--live-port", str(live_port)),
    )
    node_output: dict[str, list[str]] = {"stdout": [], "stderr": []}  # read as it comes: a pipe nobody reads fills and stops the node
    node_readers = [
        threading.Thread(target=lambda name=name: node_output[name].extend(getattr(node, name)), daemon=True)
        for name in ("stdout", "stderr")
    ]
    for reader in node_readers:
        reader.start()
    live_client = threading.Thread(target=_watch, args=(live_port, live), daemon=True)
    live_client.start()
    out = {"model": model, "bag": bag, "rec": rec, "depth": millimetres_to_depth(depth_to_millimetres(level))}  # as 16UC1 carries it
    idle_done: dict[str, BaseException | None] = {"error": None}

    def drive_idle() -> None:
        """The idle node heard nobody for its first seconds; now `terrapref play` drives it, and a
        subscriber sees it drive: in its own domain, beside the other node's drive."""
        try:
            idle_heard, idle_listener = _Heard(), Participant(idle_domain, MessageTypes(typestore()))
            readers = _listen(idle_listener, idle_heard)
            # From the start of both nodes: the idle one says so once it has heard nobody for SILENT_S.
            _wait(lambda: all(r.get_matched_publications() for r in readers), timeout_s=60.0, what="the idle node's publications")
            _wait(
                lambda: any("/clock: no publisher" in line for line in idle_log),
                timeout_s=60.0,
                what="the idle node to say nobody publishes",
            )
            play = subprocess.run(
                [
                    sys.executable,
                    "-c",
                    "import sys; from terrapref.cli import main; sys.exit(main())",
                    "play",
                    str(idle_bag),
                    "--robot",
                    str(robot),
                    "--rate",
                    "0.25",  # a quarter of real time: a node starved of a core (a busy machine) still hears and decides on some frames
                    "--delay",
                    "0.5",
                ],
                env={**env, "ROS_DOMAIN_ID": str(idle_domain)},
                capture_output=True,
                text=True,
                timeout=120,
            )
            # A node on a slow machine decides on the frames it kept up with after the log has ended:
            # its markers are awaited, not read as they stood when `play` returned.
            _wait(
                lambda: idle_heard.get("costmap") and idle_heard.get("trajectories"),
                timeout_s=20.0,
                what="the idle node's costmap and markers",
            )
            out["play"], out["idle_heard"] = play, idle_heard
            idle_listener.close()
        except BaseException as exc:  # re-raised by the fixture once the thread is joined
            idle_done["error"] = exc

    idle = threading.Thread(target=drive_idle, daemon=True)
    idle.start()
    player = listener = None
    interrupted: list[subprocess.Popen] = []
    try:
        player = BagPlayer(
            bag, driven, topics=["/terrapref/labels", "/terrapref/depth", "/terrapref/camera_info", "/terrapref/odom", "/terrapref/path"]
        )
        listener = Participant(driven, MessageTypes(typestore()))
        heard = _Heard()
        _listen(listener, heard)
        _wait(lambda: all(w.matched() for w in player.writers.values()), what="the node's subscriptions")
        messages = list(player.messages())
        times = sorted({m.t_ns for m in messages})
        # the stamp of each image of the log -> its frame
        out["frame_of"] = {round(stamp_s(m.msg.header), 6): times.index(m.t_ns) for m in messages if m.topic == "/terrapref/labels"}
        got: dict[float, tuple[float, float]] = {}
        for t_ns in times[:FRAMES]:
            group = [m for m in messages if m.t_ns == t_ns]
            image = next(m for m in group if m.topic == "/terrapref/labels")
            stamp = round(stamp_s(image.msg.header), 6)
            _publish_until_commanded(player, heard, t_ns, group, stamp)
            got[stamp] = next((c.twist.linear.x, c.twist.angular.z) for c in heard.get("cmd") if round(stamp_s(c.header), 6) == stamp)
        out["commands"] = [got[s] for s in sorted(got)]
        out["stamps"] = sorted(got)
        out["discovered"] = _endpoints(listener.dp, listener.dp.get_guid())
        out["own_endpoints"] = {("publishes", t) for t, _ in player.writers} | {("publishes", "/clock")}
        _bad_input(player, messages, times, heard, out)
        _wait(lambda: heard.get("costmap"), timeout_s=5.0, what="a costmap")
        out["heard"] = heard
        # Its part is done: Ctrl-C now (it is awaited below), for a costmap a second heard is a costly message to read.
        node.send_signal(signal.SIGINT)
        interrupted.append(node)
        idle.join()
        if idle_done.get("error") is not None:
            raise idle_done["error"]
    finally:
        for proc in (node, idle_node):
            if proc not in interrupted:  # once: a second Ctrl-C may end a node that has sent its last stop at once
                proc.send_signal(signal.SIGINT)
        stuck = [_end(node, node_readers, lambda: "".join(node_output["stderr"]), "the node")]
        out["node"] = (node.returncode, "".join(node_output["stdout"]), "".join(node_output["stderr"]))
        live_client.join(timeout=30)
        out["live"] = live
        stuck.append(_end(idle_node, [idle_reader], lambda: "".join(idle_log), "the idle node"))
        out["idle"] = (idle_node.returncode, idle_node.stdout.read(), "".join(idle_log))
        for dds in (player, listener):
            if dds is not None:
                dds.close()
        if previous_uri is None:
            os.environ.pop("CYCLONEDDS_URI", None)
        else:
            os.environ["CYCLONEDDS_URI"] = previous_uri
    assert not any(stuck), "\n".join(s for s in stuck if s)
    return out


def _bad_input(player, messages, times, heard, out) -> None:
    """Each bad message twice, then the next good frame, which is decided on as ever."""
    from terrapref.interop.ros_decode import stamp_s

    ts = player.types.ts
    t_ns = times[FRAMES - 1]
    group = {m.topic: m for m in messages if m.t_ns == t_ns}
    image, info, odom = group["/terrapref/labels"].msg, group["/terrapref/camera_info"].msg, group["/terrapref/odom"].msg
    future = ts.types["nav_msgs/msg/Odometry"](
        header=ts.types["std_msgs/msg/Header"](
            stamp=ts.types["builtin_interfaces/msg/Time"](sec=odom.header.stamp.sec + 3600, nanosec=0), frame_id="odom"
        ),
        child_frame_id="base_link",
        pose=odom.pose,
        twist=odom.twist,
    )
    smaller = replace_fields(ts, info, "sensor_msgs/msg/CameraInfo", width=320, height=240)
    depth = group["/terrapref/depth"].msg
    small_depth = replace_fields(ts, depth, "sensor_msgs/msg/Image", width=320, height=240, step=640)
    garbled = replace_fields(ts, image, "sensor_msgs/msg/CompressedImage", data=np.frombuffer(b"not a png at all", dtype=np.uint8))
    for _ in range(2):
        player.writers["/terrapref/odom", "nav_msgs/msg/Odometry"].publish(future)
        player.writers["/terrapref/camera_info", "sensor_msgs/msg/CameraInfo"].publish(smaller)
        player.writers["/terrapref/labels", "sensor_msgs/msg/CompressedImage"].publish(garbled)
        player.writers["/terrapref/depth", "sensor_msgs/msg/Image"].publish(small_depth)
        time.sleep(0.1)
    last = [m for m in messages if m.t_ns == times[FRAMES]]
    stamp = round(stamp_s(next(m for m in last if m.topic == "/terrapref/labels").msg.header), 6)
    _publish_until_commanded(player, heard, times[FRAMES], last, stamp)
    out["after_bad"] = any(round(stamp_s(c.header), 6) == stamp for c in heard.get("cmd"))


def replace_fields(ts, msg, msgtype: str, **fields):
    """A copy of rosbags' ``msg`` with ``fields`` changed."""
    from dataclasses import fields as dc_fields

    return ts.types[msgtype](**{f.name: fields.get(f.name, getattr(msg, f.name)) for f in dc_fields(msg)})


def test_the_node_commands_what_the_runtime_commands_frame_by_frame(system):
    """Each image's command, matched by its stamp (TwistStamped), is the runtime's on the same frame
    with its depth image; the GridMap's elevation is the level ground's where its depth reached."""
    from terrapref.interop.runtime import DepthFrame, PlannerRuntime
    from terrapref.learning.model_file import load_model

    rec, depth = system["rec"], DepthFrame(system["depth"])
    runtime = PlannerRuntime(load_model(system["model"]))
    runtime.set_path(np.asarray(rec.meta.get("path") or rec.scenario["path"]["waypoints"], dtype=float))
    expected = np.array(
        [runtime.decide(rec.image(FIRST + k), s, tuple(rec.poses[FIRST + k]), depth=depth).command for k, s in enumerate(system["stamps"])]
    )
    got = np.array(system["commands"])
    assert got.shape == (FRAMES, 2)
    np.testing.assert_allclose(got, expected, atol=1e-6)
    assert len(np.unique(expected[:, 1])) > 1  # the frames make it steer, not only drive straight
    code, stdout, stderr = system["node"]
    assert code == 0, stderr[-2000:]
    assert f"terrapref ros2: {FRAMES + 1} frames decided on" in stdout, stdout
    markers = system["heard"].get("trajectories")[-1].markers
    assert len(markers) == 21 and markers[0].header.frame_id == "base_link" and len(markers[0].points) > 2
    costmap = system["heard"].get("costmap")[-1]
    assert costmap.header.frame_id == "odom" and costmap.info.width * costmap.info.height == len(costmap.data) > 0
    layers = system["heard"].get("grid_map")[-1]  # the same cells' layers, as grid_map lays them out
    from terrapref.interop.ros_messages import grid_map_layer

    assert layers.header.frame_id == "odom" and layers.info.length_x == pytest.approx(costmap.info.width * costmap.info.resolution)
    cost = np.asarray(costmap.data, dtype=np.int8).reshape(costmap.info.height, costmap.info.width)
    np.testing.assert_array_equal(grid_map_layer(layers, "cost"), np.where(cost == -1, np.nan, cost).astype(np.float32))
    seen, elevation = cost != -1, grid_map_layer(layers, "elevation")
    height = np.isfinite(elevation)  # where the depth images reached (the height layer's range)
    assert seen.sum() > 1000 and (height & seen).sum() > 1000 and np.abs(elevation[height]).max() < 0.01  # level: 0 m
    live = system["live"]  # --live: the decisions also went to the live view, stamped with the frames' ROS times
    assert "error" not in live and len(live.get("/terrapref/labels", [])) >= FRAMES // 2 and live.get("/terrapref/trajectories")
    assert abs(max(ns for ns, _ in live["/terrapref/labels"]) * 1e-9 - system["stamps"][-1]) < 0.2
    transforms = [t for m in system["heard"].get("tf_static") for t in m.transforms]
    assert [(t.header.frame_id, t.child_frame_id) for t in transforms] == [
        ("base_link", "terrapref_camera_link"),
        ("terrapref_camera_link", "terrapref_camera_optical"),
    ]
    assert transforms[0].transform.translation.z == pytest.approx(1.0)


def test_every_endpoint_is_named_typed_and_offered_as_ros2_expects(system):
    """Read back from DDS discovery: rt/ topic names, pkg::msg::dds_::T_ types, QoS and the type hash."""
    from cyclonedds.core import Policy

    from terrapref.interop.ros_messages import typestore

    ts = typestore()
    seen = {}
    for kind, e in system["discovered"]:
        if (kind, e.topic_name[2:]) in system["own_endpoints"]:
            continue
        assert e.topic_name.startswith("rt/"), e.topic_name
        pkg, msg, dds_, name = e.type_name.split("::")
        assert msg == "msg" and dds_ == "dds_" and name.endswith("_")
        msgtype = f"{pkg}/msg/{name[:-1]}"
        assert e.qos[Policy.Userdata].data == f"typehash={ts.hash_rihs01(msgtype)};".encode()
        assert e.qos[Policy.DataRepresentation] == Policy.DataRepresentation(use_cdrv0_representation=True)  # XCDR1, as ROS 2's middlewares
        reliable = isinstance(e.qos[Policy.Reliability], Policy.Reliability.Reliable)
        latched = e.qos[Policy.Durability] == Policy.Durability.TransientLocal
        seen.setdefault((kind, e.topic_name[2:]), set()).add((msgtype, reliable, latched, e.qos[Policy.History].depth))
    assert seen == {
        ("hears", "/terrapref/labels"): {("sensor_msgs/msg/Image", False, False, 5), ("sensor_msgs/msg/CompressedImage", False, False, 5)},
        ("hears", "/terrapref/camera_info"): {("sensor_msgs/msg/CameraInfo", False, False, 5)},
        ("hears", "/terrapref/depth"): {("sensor_msgs/msg/Image", False, False, 5)},
        ("hears", "/terrapref/odom"): {
            (t, False, False, 5)
            for t in ("nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped")
        },
        ("hears", "/terrapref/path"): {("nav_msgs/msg/Path", True, False, 10), ("nav_msgs/msg/Path", True, True, 1)},
        ("hears", "/clock"): {("rosgraph_msgs/msg/Clock", False, False, 1)},
        ("publishes", "/terrapref/cmd_vel"): {("geometry_msgs/msg/TwistStamped", True, False, 10)},
        ("publishes", "/terrapref/trajectories"): {("visualization_msgs/msg/MarkerArray", True, False, 10)},
        ("publishes", "/terrapref/costmap"): {("nav_msgs/msg/OccupancyGrid", True, True, 1)},
        ("publishes", "/terrapref/grid_map"): {("grid_map_msgs/msg/GridMap", True, True, 1)},
        ("publishes", "/terrapref/speed_filter_info"): {("nav2_msgs/msg/CostmapFilterInfo", True, True, 1)},
        ("publishes", "/terrapref/speed_mask"): {("nav_msgs/msg/OccupancyGrid", True, True, 1)},
        ("publishes", "/terrapref/arrived"): {("std_msgs/msg/Bool", True, True, 1)},
        ("publishes", "/tf_static"): {("tf2_msgs/msg/TFMessage", True, True, 1)},
    }


def test_bad_input_is_said_once_and_skipped(system):
    """An undecodable image, a calibration of another size, odometry from the future and a depth
    image of another size, each sent twice: each said once, counted, and the next good frame is
    decided on as ever."""
    import re

    code, stdout, stderr = system["node"]
    for said in (
        "topic /terrapref/labels: not a decodable png",
        "/terrapref/camera_info: a camera_info of another image size than the 640 x 480 px",
        "/terrapref/odom: odometry stamped more than 10 s ahead of the node's clock",  # a simulated clock: 10 s of lag allowed
        "topics.depth: topic /terrapref/depth: depth image 320 x 240, the label camera's is 640 x 480",
    ):
        assert sum(said in line for line in stderr.splitlines()) == 1, (said, stderr)
    assert "Traceback" not in stderr and "internal error" not in stderr and system["after_bad"]
    for counted in ("odometry ahead of the clock", "calibrations of another size", "depth images of another encoding or size"):
        found = re.search(rf"(\d+) {counted}", stdout)
        assert found and 1 <= int(found.group(1)) <= 2, stdout


def test_play_drives_a_node_that_waited_in_an_empty_domain(system):
    """A node alone in its domain says once that nobody publishes its inputs, then `terrapref play`
    publishes a log there and a DDS subscriber sees the node's commands, markers and costmap; started
    with SIGINT ignored (as a script's background job is), it ends on Ctrl-C all the same.

    Played at a quarter of real time, a node on a slow machine keeps up with only some of the frames (it
    hears the others too late, or not at all): what is checked is what it decided on those, not
    how many they were."""
    from terrapref.interop.ros_decode import stamp_s
    from terrapref.interop.runtime import DepthFrame, PlannerRuntime
    from terrapref.learning.model_file import load_model

    play = system["play"]
    assert play.returncode == 0, play.stderr[-2000:]
    assert "played" in play.stdout and "/clock" in play.stdout and "/terrapref/depth" in play.stdout  # the robot file's depth topic
    code, stdout, stderr = system["idle"]
    assert code == 0, stderr[-2000:]
    for topic in ("/terrapref/labels", "/terrapref/depth", "/terrapref/camera_info", "/terrapref/odom", "/terrapref/path", "/clock"):
        assert sum(f"{topic}: no publisher of" in line and f"after {SILENT_S:g} s" in line for line in stderr.splitlines()) == 1, stderr
    heard = system["idle_heard"]
    assert heard.get("costmap")
    # Each decision's markers, stamped with its frame's time in the log: the frame, and the trajectory drawn as chosen.
    chosen = {
        round(stamp_s(m.markers[0].header), 6): [j for j, k in enumerate(m.markers) if k.scale.x > 0.05] for m in heard.get("trajectories")
    }
    decided = int(stdout.split("terrapref ros2: ")[1].split()[0])
    assert 1 <= len(chosen) <= decided <= len(system["frame_of"]), stdout
    assert heard.get("cmd") and {round(stamp_s(c.header), 6) for c in heard.get("cmd")} <= set(system["frame_of"])  # in the log's time
    # The planner fed the frames the node decided on, in their order, chooses what the node chose.
    rec, frame_of = system["rec"], system["frame_of"]
    runtime = PlannerRuntime(load_model(system["model"]))
    runtime.set_path(np.asarray(rec.meta.get("path") or rec.scenario["path"]["waypoints"], dtype=float))
    for stamp in sorted(chosen):
        k = FIRST + frame_of[stamp]
        planned = runtime.decide(rec.image(k), stamp, tuple(rec.poses[k]), depth=DepthFrame(system["depth"]))
        assert chosen[stamp] == [planned.index], (stamp, stdout)


def test_a_participant_without_subscriptions_waits_instead_of_spinning(monkeypatch):
    """A publisher alone (`terrapref play`'s) has nothing on its wait set: its thread must still
    wait there, up to WAIT_NS at a time, not loop on a wait that returns at once and take a core
    from the node it feeds. (A slower machine only waits fewer times.)"""
    from terrapref.interop.dds import WAIT_NS, MessageTypes, Participant
    from terrapref.interop.ros_messages import typestore

    monkeypatch.setenv("CYCLONEDDS_URI", LOOPBACK)

    class Counted:
        def __init__(self, waitset) -> None:
            self.waitset, self.waits = waitset, 0

        def wait(self, timeout_ns: int) -> int:
            self.waits += 1
            return self.waitset.wait(timeout_ns)

    participant = Participant(230, MessageTypes(typestore()))
    try:
        participant._waitset = counted = Counted(participant._waitset)
        time.sleep(0.5)
        assert counted.waits <= 0.5 / (WAIT_NS * 1e-9) + 5, counted.waits
    finally:
        participant._waitset = counted.waitset
        participant.close()


def test_each_message_type_is_cdr_identical_to_rosbags_and_announces_its_rihs01():
    """Two independent serialisers (cyclonedds' from the generated types, rosbags') give the same
    bytes for every type the node sends or reads, filled in as the node fills them."""
    from terrapref.camera import CameraConfig
    from terrapref.interop import ros_messages as rm
    from terrapref.interop.dds import MessageTypes, dds_topic, dds_type

    ts = rm.typestore()
    types = MessageTypes(ts)
    T = ts.types
    h = rm.header(ts, 1.25, "camera_optical")
    pose = rm.pose(ts, 3.0, -4.5, rm.yaw_quaternion(ts, 0.7))
    odom = rm.odometry(ts, rm.header(ts, 1.25, "odom"), pose)
    odom.pose.covariance = np.arange(36, dtype=float)
    info = rm.camera_info(ts, h, CameraConfig())
    info.d = np.array([-0.2, 0.05, 0.001, 0.0, 0.0])
    ids = np.arange(48, dtype=np.uint8).reshape(6, 8)
    marker = rm.zeroed(
        ts,
        "visualization_msgs/msg/Marker",
        header=h,
        ns="trajectories",
        id=3,
        type=4,
        action=0,
        scale=rm.vector3(ts, x=0.06),
        color=T["std_msgs/msg/ColorRGBA"](r=0.1, g=0.9, b=0.2, a=1.0),
        points=[rm.point(ts, 0.1 * k, 0.01 * k * k, 0.02) for k in range(30)],
    )
    messages = {
        "sensor_msgs/msg/Image": T["sensor_msgs/msg/Image"](
            header=h, height=6, width=8, encoding="mono8", is_bigendian=0, step=8, data=ids.ravel()
        ),
        "sensor_msgs/msg/CompressedImage": rm.compressed_image(ts, h, "png", rm.png(ids)),
        "sensor_msgs/msg/CameraInfo": info,
        "nav_msgs/msg/Odometry": odom,
        "geometry_msgs/msg/PoseStamped": T["geometry_msgs/msg/PoseStamped"](header=h, pose=pose),
        "geometry_msgs/msg/PoseWithCovarianceStamped": T["geometry_msgs/msg/PoseWithCovarianceStamped"](header=h, pose=odom.pose),
        "nav_msgs/msg/Path": rm.path_message(ts, [(0.0, 0.0), (5.0, 1.0), (9.5, -2.0)], t_s=2.0),
        "rosgraph_msgs/msg/Clock": T["rosgraph_msgs/msg/Clock"](clock=h.stamp),
        "geometry_msgs/msg/Twist": rm.twist(ts, 1.0, -0.3),
        "geometry_msgs/msg/TwistStamped": T["geometry_msgs/msg/TwistStamped"](header=h, twist=rm.twist(ts, 0.5, 0.25)),
        "visualization_msgs/msg/MarkerArray": T["visualization_msgs/msg/MarkerArray"](markers=[marker, marker]),
        "nav_msgs/msg/OccupancyGrid": rm.occupancy_grid(ts, h, np.array([[-1, 0, 50], [99, 100, 7]], np.int8), 0.25, (-3.0, 4.0)),
        "tf2_msgs/msg/TFMessage": rm.tf_message(ts, rm.camera_mount(ts, CameraConfig(), t_s=1.0, frames=("a", "b"))),
    }
    assert set(messages) == set(NODE_TYPES)
    for msgtype, msg in messages.items():
        ours = types.to_idl(msg, msgtype).serialize()
        theirs = bytes(ts.serialize_cdr(msg, msgtype))
        assert ours[:4] == b"\x00\x01\x00\x00", msgtype  # CDR little endian, XCDR1
        assert ours == theirs, msgtype
        back = types.idl(msgtype).deserialize(theirs)  # and each reads the other's
        assert back.serialize() == theirs, msgtype
        cls = types.idl(msgtype)
        assert cls.__idl_typename__ == dds_type(msgtype) == msgtype.replace("/msg/", "::msg::dds_::") + "_"
        assert cls.__idl__.keyless, msgtype
        assert types.user_data(msgtype) == f"typehash={ts.hash_rihs01(msgtype)};".encode(), msgtype
        assert types.type_hash(msgtype).startswith("RIHS01_") and len(types.type_hash(msgtype)) == 7 + 64
    for msgtype, known in JAZZY_HASHES.items():
        assert types.type_hash(msgtype) == known
    assert dds_topic("/terrapref/cmd_vel") == "rt/terrapref/cmd_vel"


def test_a_camera_sized_image_and_map_sized_grids_go_out_as_arrays_and_stay_cdr_identical():
    """Sequences of numbers (an image's bytes, an occupancy grid's cells, a grid map's floats) go out
    from their arrays in one copy, with rosbags' bytes on the wire, and an image's come back as
    bytes; a grid's signed cells still read back as numbers, and a list still goes out."""
    from terrapref.camera import CameraConfig
    from terrapref.interop import ros_messages as rm
    from terrapref.interop.dds import MessageTypes

    ts = rm.typestore()
    types = MessageTypes(ts)
    rng = np.random.default_rng(0)
    camera = CameraConfig()
    ids = rng.integers(0, 256, (camera.height_px, camera.width_px)).astype(np.uint8)
    h = rm.header(ts, 1.25, "camera_optical")
    image = ts.types["sensor_msgs/msg/Image"](
        header=h, height=ids.shape[0], width=ids.shape[1], encoding="mono8", is_bigendian=0, step=ids.shape[1], data=ids.ravel()
    )
    cells = rng.integers(-1, 101, (200, 300)).astype(np.int8)
    grid = rm.occupancy_grid(ts, h, cells, 0.1, (-10.0, -15.0))
    layers = {"cost": rng.uniform(0.0, 1.0, (200, 300)).astype(np.float32), "height": np.full((200, 300), np.nan, np.float32)}
    messages = {
        "sensor_msgs/msg/Image": image,
        "nav_msgs/msg/OccupancyGrid": grid,
        "grid_map_msgs/msg/GridMap": rm.grid_map(ts, h, layers, 0.1, (-10.0, -15.0)),
    }
    for msgtype, msg in messages.items():
        ours = types.to_idl(msg, msgtype).serialize()
        assert ours == bytes(ts.serialize_cdr(msg, msgtype)), msgtype
        assert types.idl(msgtype).deserialize(ours).serialize() == ours, msgtype
    back = types.idl("sensor_msgs/msg/Image").deserialize(types.to_idl(image, "sensor_msgs/msg/Image").serialize())
    assert isinstance(back.data, bytes) and np.array_equal(np.frombuffer(back.data, np.uint8).reshape(ids.shape), ids)
    cells_back = types.idl("nav_msgs/msg/OccupancyGrid").deserialize(types.to_idl(grid, "nav_msgs/msg/OccupancyGrid").serialize()).data
    assert cells_back == cells.ravel().tolist()  # signed, as sent
    listed = types.idl("nav_msgs/msg/OccupancyGrid")(**{**vars(types.to_idl(grid, "nav_msgs/msg/OccupancyGrid")), "data": [-1, 5]})
    assert types.idl("nav_msgs/msg/OccupancyGrid").deserialize(listed.serialize()).data == [-1, 5]


def test_a_number_in_exponent_form_is_a_number_as_ros_2_reads_it():
    """YAML 1.1 reads ``1e-9`` (no point) as a string; ROS 2's parameter parser as a double."""
    from terrapref.interop.ros2 import RosArgs

    params = RosArgs.parse(["-p", "stop.decel_mps2:=2e0", "-p", "hold_s:=5E-1", "-p", "cmd_topic:=e5"]).params
    assert params == {"stop.decel_mps2": 2.0, "hold_s": 0.5, "cmd_topic": "e5"}


def test_ros_args_set_parameters_and_remap_names():
    from terrapref.errors import UserError
    from terrapref.interop.node_core import NodeOptions
    from terrapref.interop.ros2 import Names, RosArgs

    args = RosArgs.parse(
        [
            "-p",
            "rate:=10",
            "-p",
            "stamped:=true",
            "-p",
            "use_sim_time:=true",
            "-p",
            "silent_s:=20",
            "-r",
            "__ns:=/robot",
            "-r",
            "/seg:=/cam/labels",
            "-r",
            "cmd_vel:=/mux/planner",
        ]
    )
    opts = NodeOptions().resolved(args.get_param, param=lambda name: f"-p {name}")
    assert (opts.rate, opts.stamped, args.use_sim_time, args.silent_s) == (10, True, True, 20.0)
    assert RosArgs.parse([]).silent_s == 5.0
    names = Names(args.remaps)
    assert names.fqn == "/robot/terrapref"
    assert names.resolve("~/trajectories") == "/robot/terrapref/trajectories"
    assert names.resolve("/seg") == "/cam/labels" and names.resolve("cmd_vel") == "/mux/planner" and names.resolve("/odom") == "/odom"
    for bad, match in (
        (["-p", "rate:=fast"], "-p rate"),
        (["-p", "speed:=1"], "no such parameter"),
        (["--log-level", "debug"], "--log-level"),
        (["-r", "a"], "-r needs"),
    ):
        with pytest.raises(UserError, match=match):
            NodeOptions().resolved(RosArgs.parse(bad).get_param, param=lambda name: f"-p {name}")


@pytest.mark.parametrize(
    "argv, env, words",
    [
        (["ros2", "--model", "M", "--robot", "R", "--ros-args", "-p", "rate:=0"], {}, ["-p rate", "(0, 200]"]),
        (["ros2", "--model", "M", "--robot", "R", "--ros-args", "-p", "silent_s:=0"], {}, ["-p silent_s", "(0, 600]"]),
        (["ros2", "--model", "M", "--robot", "R", "--ros-args", "-p", "silent_s:=.nan"], {}, ["-p silent_s", "(0, 600]"]),
        (["ros2", "--model", "M", "--robot", "R", "--ros-args", "-p", "silent_s:=1" + "0" * 400], {}, ["-p silent_s", "(0, 600]"]),
        (["ros2", "--model", "M", "--robot", "R", "--ros-args", "-p", "rate:=1" + "0" * 400], {}, ["-p rate", "(0, 200]"]),
        (["ros2", "--model", "M", "--robot", "R", "--ros-args", "-p", "max_speed_mps:=1" + "0" * 400], {}, ["-p max_speed_mps", "finite"]),
        (["ros2", "--model", "M", "--robot", "R"], {"ROS_DOMAIN_ID": "999"}, ["ROS_DOMAIN_ID", "[0, 232]"]),
        (["play", "nowhere.mcap"], {}, ["nowhere.mcap", "no such file"]),
        (["play", "drive.bag"], {}, ["ROS 1 bag", "rosbag play"]),
        (["play", "nowhere.mcap", "--rate", "0"], {}, ["--rate"]),
        (["ros2", "--model", "M", "--robot", "R", "--ros-args", "-p", "rate:=1"], {}, ["-p rate", "1 / hold_s"]),
        (["ros2", "--model", "M", "--robot", "R", "--cmd-topic", "a b"], {}, ["--cmd-topic", "ROS topic name"]),
        (["ros2", "--model", "M", "--robot", "R", "--ros-args", "-p", "cmd_topic:=/a//b"], {}, ["-p cmd_topic", "ROS topic name"]),
        (["ros2", "--model", "M", "--robot", "R", "--ros-args", "-r", "/c:=bad?name"], {}, ["-r /c:=bad?name"]),
        (["ros2", "--model", "M", "--robot", "R", "--ros-args", "-r", "~/costmap:=/a/{b}"], {}, ["-r ~/costmap:=/a/{b}"]),
        (["ros2", "--model", "M", "--robot", "R", "--ros-args", "-r", "__node:=9abc"], {}, ["__node:=9abc", "not starting with a digit"]),
        (["ros2", "--model", "M", "--robot", "R", "--ros-args", "-r", "__ns:=/~/robot"], {}, ["__ns:=/~/robot", "letters, digits and _"]),
    ],
)
def test_a_bad_argument_is_one_line_naming_it(argv, env, words, capsys, monkeypatch, tmp_path):
    from helpers import linear_model, one_line_error
    from terrapref.cli import main

    monkeypatch.chdir(tmp_path)
    (tmp_path / "drive.bag").write_bytes(b"")
    linear_model(tmp_path / "M")
    (tmp_path / "R").write_text(
        "format: terrapref-robot/1\ntopics: {segmentation: /s, camera_info: /i, odometry: /o, command: /c}\n"
        "camera: {height_m: 1.0, pitch_deg: 30.0}\nlabels: terrapref\n"
    )
    for key, value in env.items():
        monkeypatch.setenv(key, value)
    assert main(argv) == 2
    one_line_error(capsys, *words)


def test_a_simulated_clock_that_stops_is_seen_by_the_wall_clock(monkeypatch):
    """The node's /clock: how long it has not moved on by the wall clock (what the node says, and
    stops for, when the log player dies); the system's clock never stands still."""
    from types import SimpleNamespace

    from terrapref.interop import ros2

    wall = [50.0]
    monkeypatch.setattr(ros2.time, "monotonic", lambda: wall[0])
    clock = ros2.NodeClock(sim=True)
    assert clock.still_s() == 0.0 and not clock.running()
    for t in (10.0, 10.1):
        clock.on_clock(SimpleNamespace(clock=SimpleNamespace(sec=int(t), nanosec=round((t % 1) * 1e9))))
        wall[0] += 0.1
    assert clock.now() == pytest.approx(10.1) and clock.still_s() == pytest.approx(0.1)
    wall[0] += 1.5  # the player died: no /clock for 1.5 s
    clock.on_clock(SimpleNamespace(clock=SimpleNamespace(sec=10, nanosec=100_000_000)))  # the same time again is not moving on
    assert clock.still_s() == pytest.approx(1.6)
    assert ros2.NodeClock(sim=False).still_s() == 0.0


def _node_on_a_fake_participant(tmp_path, **options):
    """A node (its core, and a participant that records what it publishes and hands a latched
    path to a subscription the moment it is made) with a small model, no DDS."""
    from types import SimpleNamespace

    from test_offset_rule import DRIVER_LIKE, _offset_meta

    from helpers import skip_path_weights
    from terrapref.interop.dds import MessageTypes
    from terrapref.interop.node_core import NodeOptions, PlannerNodeCore
    from terrapref.interop.robot import load_robot
    from terrapref.interop.ros2 import Names, NodeClock, _Node
    from terrapref.interop.ros_messages import path_message, typestore
    from terrapref.learning.model_file import load_model, save_model
    from terrapref.learning.network import ClassifierConfig

    ts = typestore()

    class Latched:
        """A participant whose subscriptions to a path hear one the moment they are made."""

        def __init__(self) -> None:
            self.types, self.domain, self.on_error, self.published = MessageTypes(ts), 0, None, []

        def writer(self, topic: str, msgtype: str, profile) -> SimpleNamespace:
            return SimpleNamespace(publish=lambda msg: self.published.append((topic, msg)), delivered=lambda timeout_s: True)

        def close(self) -> None:
            self.published.append(("closed", None))

        def subscribe(self, topic: str, msgtype: str, profile, callback, newest_only: bool = False) -> SimpleNamespace:
            if msgtype == "nav_msgs/msg/Path":
                callback(path_message(ts, [(0.0, 0.0), (10.0, 0.0)]))
            return SimpleNamespace()

    config = ClassifierConfig(hidden=8, skip=True)
    model = load_model(save_model(tmp_path / "m.safetensors", config, skip_path_weights(config), _offset_meta(DRIVER_LIKE)))
    (tmp_path / "robot.yaml").write_text(
        "format: terrapref-robot/1\ntopics: {segmentation: /seg, camera_info: /info, odometry: /odom, command: /cmd, path: /plan}\n"
        "camera: {height_m: 1.0, pitch_deg: 30.0}\nlabels: terrapref\n"
    )
    core = PlannerNodeCore(model, load_robot(tmp_path / "robot.yaml"), None)
    dds = Latched()
    return core, _Node(core, NodeOptions(**options), Names({}), NodeClock(False), dds), dds


def test_a_message_heard_as_the_node_subscribes_finds_its_publishers_made(tmp_path):
    """A latched path that comes the moment the node subscribes to it, before the node has made
    the rest of its endpoints, is taken and answered on ``~/arrived``: the node makes its
    publishers before its subscriptions (a player's path that beat them was once said as "internal
    error handling a message (KeyError: 'arrived')")."""
    core, _, dds = _node_on_a_fake_participant(tmp_path)
    assert np.asarray(core.path).tolist() == [[0.0, 0.0], [10.0, 0.0]]  # the path was taken
    arrived = [msg.data for topic, msg in dds.published if topic.endswith("/arrived")]
    assert arrived == [False]


def test_the_speed_filters_info_is_sent_again_only_when_it_changes(tmp_path):
    """Nav2 takes each CostmapFilterInfo as a new filter (it warns and subscribes to the mask
    again): the node sends it once, latched, and the mask with every costmap."""
    from types import SimpleNamespace

    core, node, dds = _node_on_a_fake_participant(tmp_path)
    speed = np.array([[1.0, np.nan], [0.5, 2.0]])
    grid = SimpleNamespace(
        cost=np.zeros((2, 2), np.int8),
        resolution_m=0.1,
        origin=(0.0, 0.0),
        top_speed_mps=2.0,
        layers={"speed": speed},
        grid_layers=lambda: {"speed": speed.astype(np.float32)},
    )
    core.costmap = lambda: grid
    for _ in range(3):
        node.publish_costmap()
    topics = [topic.rsplit("/", 1)[-1] for topic, _ in dds.published]
    assert topics.count("speed_filter_info") == 1 and topics.count("speed_mask") == 3
    mask = [msg for topic, msg in dds.published if topic.endswith("/speed_mask")][-1]
    assert list(mask.data) == [50, 0, 25, 100]  # percent of the top speed; unseen 0, no limit


def test_a_command_sent_by_the_timer_carries_the_stamp_of_the_decision_it_sends(tmp_path, monkeypatch):
    """The timer's command is stamped with the frame of the decision in force when it takes the
    lock: one made between the timer's tick and then is the one sent, with its own stamp (it
    once went out with the frame before's)."""
    import contextlib

    core, node, dds = _node_on_a_fake_participant(tmp_path, stamped=True)
    node.last_stamp = 1.0
    lock = core.lock

    @contextlib.contextmanager
    def decided_meanwhile():
        with lock:
            node.last_stamp = 2.0  # a decision that took the lock first
            yield

    monkeypatch.setattr(type(core), "lock", property(lambda self: decided_meanwhile()))
    node.publish_command()
    (sent,) = [msg for topic, msg in dds.published if topic.endswith("cmd")]
    assert sent.header.stamp.sec == 2


def test_the_node_ends_with_a_stop_that_stays_the_last_command(tmp_path, monkeypatch):
    """A base that keeps its last command until told otherwise would drive on after the node had
    gone: the node's last command, sent before it leaves the domain, is a stop, and nothing it
    would send after (a decision or the timer's tick on the way out) goes out."""
    from terrapref.vehicle import Command

    core, node, dds = _node_on_a_fake_participant(tmp_path)
    monkeypatch.setattr(core, "status_at", lambda now_s: (Command(1.5, 0.1), None))
    node.last_stamp = 1.0
    node.publish_command()
    node.close()
    node.publish_command()
    sent = [(topic, msg) for topic, msg in dds.published if topic.endswith("cmd") or topic == "closed"]
    assert [(topic, msg and (msg.linear.x, msg.angular.z)) for topic, msg in sent] == [
        ("/cmd", (1.5, 0.1)),
        ("/cmd", (0.0, 0.0)),
        ("closed", None),
    ]


def test_a_node_that_never_commanded_ends_without_a_command(tmp_path):
    core, node, dds = _node_on_a_fake_participant(tmp_path)
    node.close()
    assert not [msg for topic, msg in dds.published if topic.endswith("cmd")]


def test_a_stop_that_cannot_be_sent_is_said_and_the_node_leaves_the_domain_all_the_same(tmp_path, capsys):
    from types import SimpleNamespace

    core, node, dds = _node_on_a_fake_participant(tmp_path)
    node.last_stamp = 1.0

    def broken(msg):
        raise RuntimeError("the participant is gone")

    node.writers["command"] = SimpleNamespace(publish=broken, delivered=lambda timeout_s: True)
    node.close()
    assert dds.published[-1] == ("closed", None)
    assert "the last stop command could not be sent (RuntimeError: the participant is gone)" in capsys.readouterr().err


def test_a_second_ctrl_c_while_the_node_ends_does_not_cut_its_last_stop_short(tmp_path, monkeypatch, capsys):
    """Ctrl-C twice in quick succession: the second comes while the node sends its last stop and
    leaves the domain. It is ignored there: the stop goes out, the node leaves, and its summary is
    said (it once died of the second SIGINT, exit -2, before either)."""
    from terrapref.interop import ros2

    _, _, dds = _node_on_a_fake_participant(tmp_path)
    participants = []
    monkeypatch.setattr(ros2, "Participant", lambda domain, types: participants.append(type(dds)()) or participants[-1])
    close = ros2._Node.close

    def interrupted_close(node) -> None:
        node.last_stamp = 1.0  # it had commanded: a stop is owed
        os.kill(os.getpid(), signal.SIGINT)
        close(node)

    monkeypatch.setattr(ros2._Node, "close", interrupted_close)
    ended = threading.Event()
    ended.set()  # spin returns at once: the node ends as after a first Ctrl-C
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)  # as a node started in a terminal has it
    try:
        ros2.run_node(str(tmp_path / "m.safetensors"), str(tmp_path / "robot.yaml"), stop=ended)
    except KeyboardInterrupt:
        pytest.fail("the second SIGINT cut the node's last stop short")
    finally:
        after = signal.signal(signal.SIGINT, previous)
    assert after is signal.default_int_handler  # as before the node ran
    (dds,) = participants
    sent = [(topic, msg and (msg.linear.x, msg.angular.z)) for topic, msg in dds.published if topic.endswith("cmd") or topic == "closed"]
    assert sent == [("/cmd", (0.0, 0.0)), ("closed", None)]
    assert "terrapref ros2: " in capsys.readouterr().out
