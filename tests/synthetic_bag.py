"""Realistic robot logs made from the simulator: a drive by the synthetic driver, written as a ROS 1
bag, a ROS 2 sqlite3 bag or a ROS 2 MCAP bag, with what real logs contain.

The quirks (``quirks=True``): label images in RELLIS-3D ids (plus a few ids no map lists), header
stamps from an epoch-like clock with jitter and a transport delay, odometry at 30 Hz in a frame
that starts at the robot, commands published only when they change, the path published once,
an unrelated topic, dropped images, pairs of images whose stamps arrive out of order, and a
one-second gap in the odometry. Without commands (``commands=False``) the log has no command
topic, and its odometry may carry the vehicle's measured motion as Odometry's twist (``twist=True``;
else the twist is zero, as some drivers leave it) or be PoseStamped, which has none. Used by the tests, the import benchmark and
examples/robot_logs.py (which import it from this folder); not part of the package. Writing the
bags needs the robot extra (rosbags).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np

from terrapref.camera import CameraConfig
from terrapref.demos.expert import ExpertConfig, ExpertDriver
from terrapref.demos.session import Disturber
from terrapref.interop.ros_messages import (
    OPTICAL_FRAME,
    Message,
    Topics,
    add_topics,
    camera_info,
    camera_mount,
    compressed_image,
    epoch_ns,
    header,
    odometry,
    path_message,
    png,
    pose,
    tf_message,
    twist,
    typestore,
    yaw_quaternion,
)
from terrapref.recipes import DEFAULT_RECIPE, RECIPES
from terrapref.scenario import Scenario, resolve_scenario
from terrapref.sim import Frame, Simulation
from terrapref.terrain import ClassTable, default_classes
from terrapref.vehicle import Command

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

Storage = Literal["rosbag1", "sqlite3", "mcap"]
Encoding = Literal["mono8", "mono16", "png", "rgb8"]
OdometryType = Literal["nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped"]
TOPICS = {
    "segmentation": "/robot/seg/labels",
    "camera_info": "/robot/camera/camera_info",
    "odometry": "/robot/odom",
    "command": "/robot/cmd_vel",
    "path": "/route/plan",
}
RELLIS = {"grass": 3, "mud": 33, "rock": 34, "water": 6, "non_traversable": 19}  # and unknown (sky) -> 7
# The classes of examples/classes/rellis3d.yaml as a RELLIS-3D network labels them: grass as
# "downhill" (30) and water as "deep water" (32), which RELLIS-3D's own conversion maps to grass
# and water, so that a log of this table needs its label map's every kind of entry.
RELLIS_OF_EXAMPLE = {
    "grass": 30,
    "dirt": 1,
    "gravel": 34,
    "mud": 33,
    "puddle": 31,
    "water": 32,
    "bush": 19,
    "tree": 4,
    "log": 15,
    "fence": 18,
    "building": 12,
    "vehicle": 8,
    "person": 17,
}
UNLISTED_ID = 50  # an id the rellis3d map does not list
COLORS = {
    3: (0, 102, 0),
    33: (255, 128, 0),
    34: (170, 170, 170),
    6: (0, 128, 255),
    19: (204, 153, 255),
    7: (135, 206, 235),
}  # for rgb8 logs
ODOMETRY_RATE_HZ = 30.0
ODOMETRY_GAP_S = (8.0, 9.0)  # with quirks, no odometry in this span of the drive
# With quirks, what a robot's clocks and transport add: image and odometry stamps arrive this much
# after the moment they stamp, and image stamps scatter by the jitter's standard deviation.
IMAGE_DELAY_S, ODOMETRY_DELAY_S, STAMP_JITTER_S = 0.03, 0.004, 0.003


def colour_label_map() -> str:
    """A terrapref-labels/1 file with rellis3d's ids and :data:`COLORS` as its colour table (a
    colour it lacks, as the quirks' unlisted id's, is unknown)."""
    names = {0: "unknown", 3: "grass", 33: "mud", 34: "rock", 6: "water", 19: "non_traversable", 7: "unknown"}
    ids = "\n".join(f"  {k}: {v}" for k, v in names.items())
    colors = "\n".join(f"  {k}: [{r}, {g}, {b}]" for k, (r, g, b) in COLORS.items())
    return f"format: terrapref-labels/1\nname: colour_rellis\nunlisted: unknown\nids:\n{ids}\ncolors:\n{colors}\n"


LENIENT_LABELS = "rellis3d_unlisted_unknown.yaml"  # rellis3d's map, its unlisted ids (UNLISTED_ID) unknown


def lenient_label_map() -> str:
    """The packaged rellis3d label map with ``unlisted: unknown``: the quirky logs' unlisted ids import as unknown."""
    from importlib import resources

    return resources.files("terrapref.data").joinpath("labels/rellis3d.yaml").read_text() + "unlisted: unknown\n"


def write_robot(path: Path, text: str | None = None) -> Path:
    """Write a robot file (``text``, default :func:`robot_yaml`'s) and :data:`LENIENT_LABELS` beside it."""
    path.write_text(robot_yaml() if text is None else text)
    (path.parent / LENIENT_LABELS).write_text(lenient_label_map())
    return path


def robot_yaml(labels: str = LENIENT_LABELS, path_topic: bool = True, profile: bool = True, command: bool = True) -> str:
    """The robot file that matches :func:`write_synthetic_bag`'s topics (by default with the
    label map :func:`write_robot` writes beside it, which makes the quirks' unlisted ids unknown,
    and with the order the synthetic operator drives by, the default's; ``profile=False``: none
    declared; ``command=False``: no command topic, for a log without commands)."""
    left_out = {k for k, keep in (("path", path_topic), ("command", command)) if not keep}
    topics = "\n".join(f"  {k}: {v}" for k, v in TOPICS.items() if k not in left_out)
    order = f"profile: [{', '.join(default_classes().profile)}]\n" if profile else ""
    return f"format: terrapref-robot/1\ntopics:\n{topics}\ncamera:\n  height_m: 1.0\n  pitch_deg: 30.0\nlabels: {labels}\n{order}"


@dataclass(frozen=True)
class _LogOptions:
    """What the drive's log holds besides the messages themselves: see :func:`write_synthetic_bag`."""

    quirks: bool
    max_seconds: float | None
    repeat_images: int
    classes: ClassTable | None = None
    speed_mps: float | None = None
    commands: bool = True
    odometry_type: OdometryType = "nav_msgs/msg/Odometry"
    twist: bool = False


def write_synthetic_bag(
    out: str | Path,
    storage: Storage = "mcap",
    scenario: str = "demo_course",
    seed: int = 0,
    profile: tuple[str, ...] | None = None,
    encoding: Encoding = "mono8",
    quirks: bool = True,
    max_seconds: float | None = None,
    repeat_images: int = 1,
    classes: ClassTable | None = None,
    speed_mps: float | None = None,
    commands: bool = True,
    odometry_type: OdometryType = "nav_msgs/msg/Odometry",
    twist: bool = False,
) -> Path:
    """Drive ``scenario`` with the synthetic driver and write the log; returns the bag's path.

    ``repeat_images`` > 1 publishes each frame that many times per 0.1 s (a faster camera), to
    make large logs for benchmarks. ``classes``: the scenario's class table (None: the
    default; examples/classes/rellis3d.yaml's classes are labelled by :data:`RELLIS_OF_EXAMPLE`).
    ``speed_mps``: the driver's cruising speed [m/s] (None: the default driver's, 1 m/s).
    ``commands=False``: no command topic. ``odometry_type``: the odometry's message type; an
    Odometry's twist is zero unless ``twist``, which fills it with the vehicle's speed and yaw rate.
    """
    out = Path(out)
    options = _LogOptions(quirks, max_seconds, repeat_images, classes, speed_mps, commands, odometry_type, twist)
    ros1 = storage == "rosbag1"
    sc = resolve_scenario(scenario, classes)
    sim = Simulation(sc)
    messages = _Messages(typestore(ros1), ros1, encoding, sim.camera.config)
    odom = _OdomFrame(*(sc.start if quirks else (0.0, 0.0, 0.0)))
    with _open_writer(out, storage) as writer:
        log = _Log(messages, _Queue(add_topics(writer, messages.ts, _topics(encoding, options), ros1)), odom, options)
        _put_fixed(log, [odom.pose(x, y, 0.0)[:2] for x, y in sc.waypoints])
        _drive(sim, sc, seed, profile, log)
        log.queue.flush(math.inf)
    return out


def _open_writer(out: Path, storage: Storage) -> Any:
    """A rosbags writer (not yet open) of a ROS 1 bag, or a ROS 2 bag in MCAP or sqlite3."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2

    if storage == "rosbag1":
        return Writer1(out)
    return Writer2(out, version=9, storage_plugin=StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3)


def _topics(encoding: Encoding, options: _LogOptions) -> dict[str, tuple[str, str]]:
    """The log's roles as (topic, type), in the order the bag lists them."""
    seg_type = "sensor_msgs/msg/CompressedImage" if encoding == "png" else "sensor_msgs/msg/Image"
    topics = {
        "segmentation": (TOPICS["segmentation"], seg_type),
        "camera_info": (TOPICS["camera_info"], "sensor_msgs/msg/CameraInfo"),
        "odometry": (TOPICS["odometry"], options.odometry_type),
        "command": (TOPICS["command"], "geometry_msgs/msg/Twist"),
        "path": (TOPICS["path"], "nav_msgs/msg/Path"),
        "other": ("/diagnostics/status", "std_msgs/msg/String"),
        "tf_static": ("/tf_static", "tf2_msgs/msg/TFMessage"),
    }
    if not options.commands:
        del topics["command"]
    return topics


@dataclass(frozen=True)
class _Messages:
    """The log's own messages: ROS 1 or ROS 2 types, the segmentation's encoding, the camera."""

    ts: Typestore
    ros1: bool
    encoding: Encoding
    camera: CameraConfig

    def header(self, t_s: float, frame_id: str) -> Message:
        """std_msgs/Header stamped ``t_s`` [s] in ``frame_id``."""
        return header(self.ts, t_s, frame_id, self.ros1)

    def camera_info(self, t_s: float) -> Message:
        """The camera's calibration, stamped ``t_s`` [s] in the optical frame."""
        return camera_info(self.ts, self.header(t_s, OPTICAL_FRAME), self.camera, self.ros1)

    def image(self, t_s: float, ids: np.ndarray) -> Message:
        """The segmentation ``ids`` (H, W) in RELLIS-3D ids, in the log's encoding."""
        stamped = self.header(t_s, OPTICAL_FRAME)
        if self.encoding == "png":
            return compressed_image(self.ts, stamped, "mono8; png compressed", png(ids.astype(np.uint8)))
        if self.encoding == "rgb8":  # a colour segmentation: the RELLIS ids through COLORS
            rgb = np.zeros((*ids.shape, 3), np.uint8)
            for rid, colour in COLORS.items():
                rgb[ids == rid] = colour
            return self._raw_image(stamped, 3 * self.camera.width_px, rgb.reshape(-1))
        data = ids.astype("<u2" if self.encoding == "mono16" else np.uint8)
        return self._raw_image(stamped, self.camera.width_px * data.itemsize, np.frombuffer(data.tobytes(), np.uint8))

    def _raw_image(self, stamped: Message, step: int, data: np.ndarray) -> Message:
        """sensor_msgs/Image of rows of ``step`` bytes, little-endian."""
        return self.ts.types["sensor_msgs/msg/Image"](
            header=stamped,
            height=self.camera.height_px,
            width=self.camera.width_px,
            encoding=self.encoding,
            is_bigendian=0,
            step=step,
            data=data,
        )

    def odometry(self, t_s: float, x: float, y: float, yaw: float, moving: tuple[float, float] | None = None) -> Message:
        """Odometry of base_link at (x, y [m], yaw [rad]) in the odom frame, stamped ``t_s``; its
        twist ``moving`` (v [m/s], w [rad/s] in base_link), or zero when None."""
        msg = odometry(self.ts, self.header(t_s, "odom"), pose(self.ts, x, y, yaw_quaternion(self.ts, yaw)))
        if moving is not None:
            msg.twist.twist = twist(self.ts, *moving)
        return msg

    def pose_stamped(self, t_s: float, x: float, y: float, yaw: float) -> Message:
        """geometry_msgs/PoseStamped of base_link at (x, y [m], yaw [rad]) in the odom frame, stamped ``t_s``."""
        at = pose(self.ts, x, y, yaw_quaternion(self.ts, yaw))
        return self.ts.types["geometry_msgs/msg/PoseStamped"](header=self.header(t_s, "odom"), pose=at)


class _Queue:
    """Messages held until the log's time passes them, then written in bag-time order (messages
    of one time in the order they were put)."""

    def __init__(self, topics: Topics) -> None:
        self.topics = topics
        self.held: list[tuple[float, str, Message]] = []  # (bag time [s], role, message)

    def put(self, bag_t_s: float, role: str, msg: Message) -> None:
        """Hold ``msg`` for ``role`` until bag time ``bag_t_s`` [s] is flushed."""
        self.held.append((bag_t_s, role, msg))

    def flush(self, upto_s: float) -> None:
        """Write every message held of bag time up to ``upto_s`` [s]."""
        self.held.sort(key=lambda q: q[0])
        while self.held and self.held[0][0] <= upto_s:
            bag_t_s, role, msg = self.held.pop(0)
            self.topics.write(role, epoch_ns(bag_t_s), msg)


@dataclass(frozen=True)
class _OdomFrame:
    """The odometry frame: it starts at the pose (x, y [m], yaw [rad]) of the world frame."""

    x_m: float
    y_m: float
    yaw_rad: float

    def pose(self, x: float, y: float, yaw: float) -> tuple[float, float, float]:
        """The world pose (x, y [m], yaw [rad]) in this frame."""
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        dx, dy = x - self.x_m, y - self.y_m
        return c * dx + s * dy, -s * dx + c * dy, yaw - self.yaw_rad


@dataclass(frozen=True)
class _Log:
    """Where a drive's messages go, and how."""

    messages: _Messages
    queue: _Queue
    odom: _OdomFrame
    options: _LogOptions


@dataclass
class _DriveState:
    """What the drive carries from one frame to the next."""

    last_command: Command | None = None  # the last command published
    swap_stamp_s: float | None = None  # a held-back image stamp, given to the next image
    tick: int = 0  # vehicle steps published as odometry


def _put_fixed(log: _Log, path_xy: list[tuple[float, float]]) -> None:
    """The path (``path_xy`` [m] in the odom frame), and the camera's mounting."""
    messages, cam = log.messages, log.messages.camera
    ts = messages.ts
    log.queue.put(0.0, "path", path_message(ts, path_xy, messages.ros1))
    log.queue.put(0.0, "tf_static", tf_message(ts, camera_mount(ts, cam, messages.ros1)))


def _drive(sim: Simulation, sc: Scenario, seed: int, profile: tuple[str, ...] | None, log: _Log) -> None:
    """Drive ``sc`` as ``terrapref record`` does, publishing each step as it goes."""
    rng = np.random.default_rng(seed)
    config = ExpertConfig.styled("default", profile)
    if log.options.speed_mps is not None:
        config = replace(config, speed_mps=log.options.speed_mps)
    driver = ExpertDriver(config, world=sim.world)
    protocol = RECIPES[DEFAULT_RECIPE].disturbance
    frame = sim.reset()
    driver.reset(sc, rng)  # then the pushes' stream, in the order `terrapref record` draws them: the same drive
    disturb = Disturber(protocol, np.random.default_rng(rng.integers(2**63)), 0.1) if protocol is not None else None
    jitter = np.random.default_rng(seed + 1)
    to_ids = _rellis_ids(log.options.classes)
    state = _DriveState()
    max_seconds = log.options.max_seconds
    while not sim.done and (max_seconds is None or frame.time_s < max_seconds):
        command = driver.act(frame)
        _put_camera(log, frame, to_ids[frame.image], jitter, state)
        _put_command(log, frame.time_s, command, state)
        frame = sim.step(disturb(command) if disturb is not None else command)
        _put_odometry(log, sim, state)
        log.queue.flush(frame.time_s - 0.2)


def _rellis_ids(classes: ClassTable | None) -> np.ndarray:
    """(256,) uint16: class id of ``classes`` (None: the default table) -> RELLIS-3D id (7,
    unknown, for any id not in RELLIS)."""
    rellis = RELLIS if classes is None else RELLIS_OF_EXAMPLE
    classes = classes or default_classes()
    to_ids = np.full(256, 7, np.uint16)
    for name, rid in rellis.items():
        to_ids[classes.id_of(name)] = rid
    return to_ids


def _put_camera(log: _Log, frame: Frame, ids: np.ndarray, jitter: np.random.Generator, state: _DriveState) -> None:
    """The frame's segmentation ``ids`` (H, W) in RELLIS-3D ids (with quirks, a corner of ids no
    map lists, and now and then no image), and every tenth frame the calibration and the
    unrelated topic."""
    quirks, t = log.options.quirks, frame.time_s
    if quirks:
        ids[:4, :40] = UNLISTED_ID
    stamp = t + (jitter.normal(0.0, STAMP_JITTER_S) if quirks else 0.0)
    if not (quirks and frame.index % 50 == 49):  # else a dropped image
        _put_images(log, frame.index, ids, stamp, state)
    if frame.index % 10 == 0:
        log.queue.put(t + 0.001, "camera_info", log.messages.camera_info(t))
        log.queue.put(t + 0.002, "other", log.messages.ts.types["std_msgs/msg/String"](data="ok"))


def _put_images(log: _Log, index: int, ids: np.ndarray, stamp: float, state: _DriveState) -> None:
    """Frame ``index``'s image ``repeat_images`` times over 0.1 s; with quirks, now and then
    a pair whose stamps arrive out of order."""
    quirks, repeat, image = log.options.quirks, log.options.repeat_images, log.messages.image
    for r in range(repeat):
        st = stamp + r * 0.1 / repeat
        if quirks and index % 37 == 5 and r == 0:
            state.swap_stamp_s = st  # this image's stamp goes to the next one: a pair out of order
            continue
        if state.swap_stamp_s is not None:
            log.queue.put(state.swap_stamp_s + IMAGE_DELAY_S, "segmentation", image(st, ids))
            log.queue.put(st + IMAGE_DELAY_S, "segmentation", image(state.swap_stamp_s, ids))
            state.swap_stamp_s = None
            continue
        log.queue.put(st + (IMAGE_DELAY_S if quirks else 0.0), "segmentation", image(st, ids))


def _put_command(log: _Log, t_s: float, command: Command, state: _DriveState) -> None:
    """The operator's command (with quirks, only when it changes; none in a log without commands)."""
    if not log.options.commands:
        return
    if command != state.last_command or not log.options.quirks:
        log.queue.put(t_s + 0.005, "command", twist(log.messages.ts, command[0], command[1]))
        state.last_command = command


def _put_odometry(log: _Log, sim: Simulation, state: _DriveState) -> None:
    """The vehicle's steps since the last call, in the odom frame at ODOMETRY_RATE_HZ (with
    quirks, delayed, and none in ODOMETRY_GAP_S); with ``twist``, each Odometry moving at the
    vehicle's speed after its tick and the yaw rate it held (the command it executed)."""
    options, messages = log.options, log.messages
    gap = ODOMETRY_GAP_S if options.quirks else (math.inf, math.inf)
    for x, y, yaw in sim.trace[state.tick + 1 :]:
        state.tick += 1
        t_odom = state.tick / ODOMETRY_RATE_HZ
        if gap[0] <= t_odom < gap[1]:
            continue
        ox, oy, oyaw = log.odom.pose(x, y, yaw)
        if options.odometry_type == "geometry_msgs/msg/PoseStamped":
            msg = messages.pose_stamped(t_odom, ox, oy, oyaw)
        else:
            moving = (sim.speeds[state.tick - 1], sim.vehicle.command.w) if options.twist else None  # speeds[k - 1]: after tick k
            msg = messages.odometry(t_odom, ox, oy, oyaw, moving)
        log.queue.put(t_odom + (ODOMETRY_DELAY_S if options.quirks else 0.0), "odometry", msg)
