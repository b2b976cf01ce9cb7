"""``terrapref ros2``: the planner as a ROS 2 node, speaking DDS itself (no rclpy), around
:class:`PlannerNodeCore`.

The same node as ``terrapref ros1`` (:mod:`terrapref.interop.ros1`), on ROS 2's wire
(:mod:`terrapref.interop.dds`): it subscribes to the robot file's label image
(``sensor_msgs/Image`` or ``CompressedImage``, whichever the robot publishes), camera
calibration, odometry (``nav_msgs/Odometry``, ``PoseStamped`` or ``PoseWithCovarianceStamped``),
where the robot file names them its depth images (``sensor_msgs/Image`` 32FC1 or 16UC1) and
their calibration, and, without a path file, path (``nav_msgs/Path``); it publishes the command (``Twist``, or
``TwistStamped`` with ``stamped``) at the control rate and at once on each decision, the
trajectories with F_t (``~/trajectories``) on each decision, the learned costmap (``~/costmap``,
transient local) once a second, whether it stands at the end of its path (``~/arrived``,
``std_msgs/Bool``, transient local: false until it arrives, false again on a new path), and the
camera mounting it assumes on ``/tf_static``.

Its options come from the command line or ROS 2 parameters (``--ros-args -p rate:=10``), its
topic names can be remapped (``-r /cmd_vel:=/robot/cmd_vel``, ``-r __node:=NAME``,
``-r __ns:=/NS``), ``ROS_DOMAIN_ID`` picks the domain, and ``-p use_sim_time:=true`` takes the
node's clock from ``/clock``. Whatever its clock says, it stops (``stale``) once no frame has been
decided on for ``watchdog_s`` by the wall clock, and says why: a ``/clock`` that stopped (the log
player died) would otherwise hold the last command for ever.
"""

from __future__ import annotations

import contextlib
import re
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from terrapref.errors import UserError, finite_number
from terrapref.interop.dds import CLOCK, DEFAULT, LATCHED, SENSOR_DATA, MessageTypes, Participant, QosProfile, domain_id
from terrapref.interop.node_core import (
    AHEAD_S,
    ROBOT_PARAMETERS,
    SIM_AHEAD_S,
    NodeLog,
    NodeOptions,
    PlannerNodeCore,
    TrajectoryShapes,
    Watchdog,
    limits_line,
    report_line,
)
from terrapref.interop.robot import GIVEN_TOPIC_NAME
from terrapref.interop.ros_decode import time_s

NODE_NAME = "terrapref"
COSTMAP_PERIOD_S = 1.0  # between two costmaps [s]
SILENT_S = 5.0  # an input topic without a publisher this long after the start is said [s] (default of -p silent_s)
SILENT_TOP_S = 600.0  # the longest silent_s may be [s]
MARKER_LIFETIME_S = 0.5
STOP_DELIVERY_S = 1.0  # the longest the node waits, as it ends, for its last stop command to reach the base [s]
MOUNT_FRAMES = ("terrapref_camera_link", "terrapref_camera_optical")  # the node's own names: never a second parent in the robot's tree
IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
POSE_TYPES = ("nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped")
PARAMETERS = ("stamped", "rate", "path_file", "cmd_topic", "hold_s", "watchdog_s", *ROBOT_PARAMETERS, "use_sim_time", "silent_s")


@dataclass(frozen=True)
class Endpoint:
    """One topic of the node: its role, name (resolved and remapped), types and QoS profile."""

    role: str
    topic: str
    msgtypes: tuple[str, ...]
    profile: QosProfile
    publishes: bool


@dataclass(frozen=True)
class RosArgs:
    """What ``--ros-args`` gives: parameters (``-p NAME:=VALUE``, the value read as YAML, as ROS 2
    reads it) and remappings (``-r FROM:=TO``; ``__node`` and ``__ns`` rename the node)."""

    params: dict[str, Any] = field(default_factory=dict)
    remaps: dict[str, str] = field(default_factory=dict)

    @classmethod
    def parse(cls, tokens: Sequence[str]) -> RosArgs:
        """Parse the words after ``--ros-args``; anything else is a UserError naming it."""
        params, remaps = {}, {}
        words = list(tokens)
        while words:
            flag = words.pop(0)
            if flag == "--ros-args":
                continue
            if flag not in ("-p", "--param", "-r", "--remap"):
                raise UserError("--ros-args", f"{flag!r}: expected -p NAME:=VALUE or -r FROM:=TO")
            if not words or ":=" not in words[0]:
                raise UserError("--ros-args", f"{flag} needs NAME:=VALUE, got {words[0] if words else 'nothing'}")
            name, _, value = words.pop(0).partition(":=")
            if flag in ("-p", "--param"):
                if name not in PARAMETERS and "." not in name:  # RULE.NAME: a rule's setting, checked by NodeOptions
                    raise UserError(
                        "--ros-args", f"-p {name}: no such parameter; the node's are {', '.join(PARAMETERS)}, and RULE.NAME (its rules')"
                    )
                params[name] = _param_value(value)
            else:
                if not name or not value:
                    raise UserError("--ros-args", f"-r {name}:={value}: expected FROM:=TO, both names")
                remaps[name] = value
        return cls(params, remaps)

    @property
    def rule_params(self) -> dict[str, Any]:
        """The parameters that set the model's rules (``RULE.NAME``; terrapref.rules.settings)."""
        return {name: value for name, value in self.params.items() if "." in name}

    def get_param(self, key: str, default: Any) -> Any:
        """A parameter's value (``key`` as :meth:`NodeOptions.resolved` asks: ``-p NAME``), else ``default``."""
        return self.params.get(key.removeprefix("-p "), default)

    @property
    def use_sim_time(self) -> bool:
        value = self.params.get("use_sim_time", False)
        if not isinstance(value, bool):
            raise UserError("-p use_sim_time", f"expected true or false, got {value!r}")
        return value

    @property
    def silent_s(self) -> float:
        """How long after its start the node says which of its inputs nobody publishes [s]."""
        value = self.params.get("silent_s", SILENT_S)
        if not (finite_number(value) and 0 < value <= SILENT_TOP_S):
            raise UserError("-p silent_s", f"expected a number in (0, {SILENT_TOP_S:g}], got {value!r}")
        return float(value)


def _param_value(text: str) -> Any:
    """A ``-p`` value as ROS 2 reads it: YAML, but a number in exponent form without a point
    (``1e-9``, a string to YAML 1.1) a number too."""
    try:
        value = yaml.safe_load(text) if text else ""
    except yaml.YAMLError:
        return text
    if isinstance(value, str) and _EXPONENT.fullmatch(value.strip()):
        return float(value)
    return value


_EXPONENT = re.compile(r"[-+]?\d+[eE][-+]?\d+")
_ROS_WORD = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")  # a node's name, or a part of a namespace


class Names:
    """ROS 2 name resolution for one node: ``~/x`` under the node, relative names under its
    namespace, then the remappings.

    Args:
        remaps: ``-r`` rules; ``__node`` and ``__ns`` set the node's name and namespace.
    """

    def __init__(self, remaps: Mapping[str, str]) -> None:
        self.node = remaps.get("__node", NODE_NAME)
        self.namespace = "/" + remaps.get("__ns", "/").strip("/")
        if not _ROS_WORD.fullmatch(self.node) or not all(_ROS_WORD.fullmatch(p) for p in self.namespace.strip("/").split("/") if p):
            raise UserError(
                "--ros-args", f"-r __node:={self.node} / __ns:={self.namespace}: names are letters, digits and _, not starting with a digit"
            )
        self.fqn = self.namespace.rstrip("/") + "/" + self.node
        rules = {a: b for a, b in remaps.items() if a not in ("__node", "__ns")}
        odd = next(((a, b) for a, b in rules.items() if not (GIVEN_TOPIC_NAME.match(a) and GIVEN_TOPIC_NAME.match(b))), None)
        if odd is not None:
            raise UserError("--ros-args", f"-r {odd[0]}:={odd[1]}: expected ROS topic names (letters, digits and _ between slashes)")
        self.remaps = {self._expand(a): self._expand(b) for a, b in rules.items()}

    def _expand(self, name: str) -> str:
        if name.startswith("~"):
            return self.fqn + "/" + name[1:].lstrip("/")
        return name if name.startswith("/") else self.namespace.rstrip("/") + "/" + name

    def resolve(self, name: str) -> str:
        """The topic ``name`` names for this node, remapped."""
        full = self._expand(name)
        return self.remaps.get(full, full)


class NodeClock:
    """The node's clock [s]: the system's, or with ``use_sim_time`` the newest ``/clock`` (0
    until one comes, as ROS 2's)."""

    def __init__(self, sim: bool) -> None:
        self.sim = sim
        self._sim_s: float | None = None
        self._moved_wall: float | None = None  # when /clock last moved on, by the wall clock [s]

    def on_clock(self, msg) -> None:
        """A rosgraph_msgs/Clock from /clock."""
        t = time_s(msg.clock)
        if self._sim_s is None or t > self._sim_s:
            self._moved_wall = time.monotonic()
        self._sim_s = t

    def still_s(self) -> float:
        """How long a simulated clock has not moved on, by the wall clock [s] (0 for the system's clock, or before /clock speaks)."""
        return 0.0 if not self.sim or self._moved_wall is None else time.monotonic() - self._moved_wall

    def now(self) -> float:
        """The node's time now [s]."""
        return (self._sim_s or 0.0) if self.sim else time.time()

    def running(self) -> bool:
        """Whether the clock has started (a simulated one, once /clock has spoken)."""
        return not self.sim or self._sim_s is not None


def _stderr(level: str, node: str) -> Callable[[str], None]:
    """A logging call that writes one line as ROS 2's console does: ``[LEVEL] [time] [node]: line``."""

    def log(line: str) -> None:
        print(f"[{level}] [{time.time():.6f}] [{node}]: {line}", file=sys.stderr, flush=True)

    return log


def run_node(
    model_path: str,
    robot_path: str,
    options: NodeOptions | None = None,
    ros_args: Sequence[str] = (),
    live: Any = None,
    stop: threading.Event | None = None,
) -> None:
    """Run the node until Ctrl-C or SIGTERM (or ``stop`` is set); with ``live`` (a
    terrapref.interop.live.LiveView), every decision is also sent there. Ends with a line of
    what it decided and skipped; a calibration the model refuses ends it with that UserError."""
    from terrapref.interop.robot import load_robot, load_waypoints
    from terrapref.interop.ros_messages import typestore
    from terrapref.learning.model_file import load_model

    args = RosArgs.parse(ros_args)
    names = Names(args.remaps)
    opts = (options or NodeOptions()).with_rule_params(args.rule_params, "--ros-args")
    opts = opts.resolved(args.get_param, param=lambda name: f"-p {name}")
    clock, silent_s = NodeClock(args.use_sim_time), args.silent_s
    domain = domain_id()
    model = load_model(model_path)
    robot = opts.applied_to(load_robot(robot_path, model.classes, f"the model {model_path}"))
    path = (
        load_waypoints(Path(opts.path_file), None)
        if opts.path_file
        else (load_waypoints(robot.path_file, robot.source) if robot.path_file else None)
    )
    ahead = SIM_AHEAD_S if clock.sim else AHEAD_S
    core = PlannerNodeCore(model, robot, path, float(opts.hold_s), ahead, Watchdog(float(opts.watchdog_s)))
    if live is not None:
        core.watch(live)
    node = _Node(core, opts, names, clock, Participant(domain, MessageTypes(typestore())), silent_s)
    with _sigint(signal.SIG_IGN):  # once the spin ends, a second Ctrl-C must not cut the last stop short
        try:
            with interruptible():
                node.spin(stop or threading.Event())
        finally:
            node.close()
            print(report_line(core, "ros2", node.log), flush=True)
    if node.failure:
        raise node.failure[0]


@contextlib.contextmanager
def interruptible() -> Iterator[None]:
    """SIGINT raises KeyboardInterrupt while the node (or ``play``) runs, as rclpy's nodes (and
    rospy's) install for themselves: one started by a script in the background inherits SIGINT
    ignored, and ``ros2 launch`` or a supervisor's SIGINT would then never end it. Off the main
    thread (a node run in-process, ended by ``stop``) nothing is installed."""
    with _sigint(signal.default_int_handler):
        yield


@contextlib.contextmanager
def _sigint(handler) -> Iterator[None]:
    """SIGINT handled by ``handler`` within the block, then as before; off the main thread
    (where no handler can be installed) nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def endpoints(robot, opts: NodeOptions, names: Names, sim: bool, path_topic: bool) -> list[Endpoint]:
    """Every topic of the node, with its types and QoS profile.

    Subscriptions to streams (images, calibration, odometry) are best effort, which hears
    reliable and best-effort publishers alike (a reliable subscription would not match a
    best-effort publisher); the path is heard both reliable and transient local, so that a
    path published once before the node started still arrives.
    """
    t = robot.topics
    out = [
        Endpoint("segmentation", names.resolve(t["segmentation"]), IMAGE_TYPES, SENSOR_DATA, False),
        Endpoint("camera_info", names.resolve(t["camera_info"]), ("sensor_msgs/msg/CameraInfo",), SENSOR_DATA, False),
        Endpoint("odometry", names.resolve(t["odometry"]), POSE_TYPES, SENSOR_DATA, False),
    ]
    if robot.depth_topic:  # a camera stream like the label images: sensor-data QoS
        out.append(Endpoint("depth", names.resolve(robot.depth_topic), ("sensor_msgs/msg/Image",), SENSOR_DATA, False))
        if t.get("depth_info") not in (None, t["camera_info"]):
            out.append(Endpoint("depth_info", names.resolve(t["depth_info"]), ("sensor_msgs/msg/CameraInfo",), SENSOR_DATA, False))
    if path_topic:
        out += [
            Endpoint("path", names.resolve(robot.path_topic), ("nav_msgs/msg/Path",), DEFAULT, False),
            Endpoint("path", names.resolve(robot.path_topic), ("nav_msgs/msg/Path",), LATCHED, False),
        ]
    if sim:
        out.append(Endpoint("clock", "/clock", ("rosgraph_msgs/msg/Clock",), CLOCK, False))
    twist = "geometry_msgs/msg/TwistStamped" if opts.stamped else "geometry_msgs/msg/Twist"
    out += [
        Endpoint("command", names.resolve(opts.command_topic(robot)), (twist,), DEFAULT, True),
        Endpoint("trajectories", names.resolve("~/trajectories"), ("visualization_msgs/msg/MarkerArray",), DEFAULT, True),
        Endpoint("costmap", names.resolve("~/costmap"), ("nav_msgs/msg/OccupancyGrid",), LATCHED, True),
        Endpoint("grid_map", names.resolve("~/grid_map"), ("grid_map_msgs/msg/GridMap",), LATCHED, True),
        Endpoint("speed_filter_info", names.resolve("~/speed_filter_info"), ("nav2_msgs/msg/CostmapFilterInfo",), LATCHED, True),
        Endpoint("speed_mask", names.resolve("~/speed_mask"), ("nav_msgs/msg/OccupancyGrid",), LATCHED, True),
        Endpoint("arrived", names.resolve("~/arrived"), ("std_msgs/msg/Bool",), LATCHED, True),
    ]
    if "tf" not in robot.camera:  # the mounting comes from the robot file; with camera.tf the robot's own tree has it
        out.append(Endpoint("tf_static", "/tf_static", ("tf2_msgs/msg/TFMessage",), LATCHED, True))
    return out


class _Node:
    """The node's DDS endpoints and timers around a :class:`PlannerNodeCore`."""

    def __init__(
        self, core: PlannerNodeCore, opts: NodeOptions, names: Names, clock: NodeClock, dds: Participant, silent_s: float = SILENT_S
    ) -> None:
        robot = core.robot
        self.core, self.robot, self.opts, self.names, self.clock, self.dds = core, robot, opts, names, clock, dds
        self.ts, self.domain, self.silent_s = dds.types.ts, dds.domain, silent_s
        self.failure: list[UserError] = []
        self.log = NodeLog(_stderr("INFO", names.node), _stderr("WARN", names.node), _stderr("ERROR", names.node), prefix="")
        self.last_stamp: float | None = None  # the frame of the command in force
        self.arrived: bool | None = None  # what ~/arrived last said
        self.clock_said, self.ended = False, False  # a /clock that stopped has been said; the last command, a stop, sent
        self.odom_frame, self.filter_said = "odom", None  # the costmap's frame; the speed filter's info last sent
        self.shapes = TrajectoryShapes(core.model)
        self.failed = threading.Event()
        dds.on_error = self._on_error
        self.endpoints = endpoints(robot, opts, names, clock.sim, core.path is None and bool(robot.path_topic))
        self.writers: dict[str, Any] = {}
        self.readers: dict[str, list[Any]] = {}
        handlers = {
            "segmentation": self.on_image,
            "camera_info": self.on_camera_info,
            "odometry": self.on_odometry,
            "depth": self.on_depth,
            "depth_info": self.on_depth_info,
            "path": self.on_path,
            "clock": clock.on_clock,
        }
        core.on_decision = self.on_decision
        core.on_problem = self.log.say
        # Publishers first: a subscription may hear a message (a latched path) the moment it is
        # made, and its handler publishes (~/arrived, a command).
        for e in self.endpoints:
            if e.publishes:
                self.writers[e.role] = self.dds.writer(e.topic, e.msgtypes[0], e.profile)
        for e in (e for e in self.endpoints if not e.publishes):
            for msgtype in e.msgtypes:
                handle = handlers[e.role]
                callback = (
                    (lambda msg, handle=handle, msgtype=msgtype: handle(msg, msgtype)) if e.role in ("segmentation", "odometry") else handle
                )
                self.readers.setdefault(e.role, []).append(
                    self.dds.subscribe(e.topic, msgtype, e.profile, callback, newest_only=e.role == "segmentation")
                )
        self.publish_mount()
        self.publish_arrived()
        self.log.info(limits_line(robot, core.watchdog.limit_s))
        if robot.rules:
            self.log.info(f"rule settings over the model file's: {'; '.join(robot.rules.lines())}")
        self.log.info(
            f"in ROS_DOMAIN_ID {self.domain} as {names.fqn}: "
            + "; ".join(
                f"{'publishes' if e.publishes else 'hears'} {e.topic} ({' or '.join(m.split('/')[-1] for m in e.msgtypes)}, {e.profile.describe()})"
                for e in self.endpoints
            )
        )

    def _on_error(self, exc: BaseException) -> None:
        """A callback's exception that is not about the message (a bug): said once, the node goes on."""
        if isinstance(exc, UserError):
            self.log.say(exc.lines()[0])
        else:
            self.log.say(f"internal error handling a message ({type(exc).__name__}: {exc})")

    def header(self, t_s: float, frame_id: str) -> Any:
        """std_msgs/Header stamped ``t_s`` [s] (the node's clock) in ``frame_id``."""
        ns = int(round(t_s * 1e9))
        return self.ts.types["std_msgs/msg/Header"](
            stamp=self.ts.types["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000), frame_id=frame_id
        )

    def publish_mount(self) -> None:
        """The camera's mounting the planner assumes (base_link -> terrapref_camera_link ->
        terrapref_camera_optical), once, transient local as tf2's static broadcaster."""
        from terrapref.camera import CameraConfig
        from terrapref.interop.ros_messages import EPOCH_S, camera_mount, tf_message

        if "tf_static" not in self.writers:
            return
        cam = self.robot.camera
        mount = CameraConfig(
            mount_height_m=cam["height_m"], pitch_deg=cam["pitch_deg"], mount_forward_m=cam["forward_m"], yaw_deg=cam["yaw_deg"]
        )
        self.writers["tf_static"].publish(
            tf_message(self.ts, camera_mount(self.ts, mount, t_s=self.clock.now() - EPOCH_S, frames=MOUNT_FRAMES))
        )

    def publish_command(self) -> None:
        """The command in force now (a stop once its frame is ``hold_s`` old by the node's clock),
        stamped with its frame; each time the planner stops, or moves on, the log says so and why."""
        with self.core.lock:  # a decision's command and the timer's never cross (the lock a decision is made under)
            if self.ended:  # the stop the node ended with stays the last command
                return
            stamp = self.last_stamp  # read under the lock: a decision between the timer's tick and here is the one sent
            (v, w), reason = self.core.status_at(self.clock.now())
            self.log.status(reason)
            self.writers["command"].publish(self.command_message(float(v), float(w), stamp))

    def command_message(self, v: float, w: float, stamp_s: float) -> Any:
        """The command (v, w) as the node publishes it: a Twist, or with ``stamped`` a TwistStamped stamped ``stamp_s`` in base_link."""
        from terrapref.interop.ros_messages import twist

        msg = twist(self.ts, v, w)
        if self.opts.stamped:
            msg = self.ts.types["geometry_msgs/msg/TwistStamped"](header=self.header(stamp_s, "base_link"), twist=msg)
        return msg

    def on_decision(self, decision) -> None:
        """Each decision, whether its image or the odometry it waited for brought it."""
        self.last_stamp = decision.stamp_s
        self.publish_command()
        self.writers["trajectories"].publish(self.markers(decision))
        self.publish_arrived()

    def publish_arrived(self) -> None:
        """``~/arrived`` when it changes: true once the planner stands at its goal, false until then
        and again on a new path; the log says when it arrives."""
        arrived = self.core.arrived
        if arrived == self.arrived:
            return
        self.arrived = arrived
        self.writers["arrived"].publish(self.ts.types["std_msgs/msg/Bool"](data=arrived))
        if arrived:
            self.log.info("arrived at the end of the path (goal)")

    def on_path(self, msg) -> None:
        """A path message: the core's to take; a new path means not arrived."""
        problem = self.core.on_path(msg)
        if problem is not None:
            self.log.say(problem)
        self.publish_arrived()

    def markers(self, decision) -> Any:
        """The trajectories of ``decision`` as visualization_msgs/MarkerArray (line strips in base_link)."""
        from terrapref.interop.ros_messages import point, vector3, zeroed

        T = self.ts.types
        stamped = self.header(decision.stamp_s, "base_link")
        lifetime = T["builtin_interfaces/msg/Duration"](sec=0, nanosec=int(MARKER_LIFETIME_S * 1e9))
        out = []
        for j, (pts, (width_m, rgba)) in enumerate(zip(self.shapes.paths, self.shapes.styles(decision))):
            out.append(
                zeroed(
                    self.ts,
                    "visualization_msgs/msg/Marker",
                    header=stamped,
                    ns="trajectories",
                    id=j,
                    type=4,
                    action=0,
                    pose=zeroed(
                        self.ts, "geometry_msgs/msg/Pose", orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)
                    ),
                    scale=vector3(self.ts, x=width_m),
                    color=T["std_msgs/msg/ColorRGBA"](r=rgba[0], g=rgba[1], b=rgba[2], a=rgba[3]),
                    lifetime=lifetime,
                    points=[point(self.ts, x, y, 0.02) for x, y in pts],
                )
            )
        return T["visualization_msgs/msg/MarkerArray"](markers=out)

    def on_camera_info(self, msg) -> None:
        first = self.core.runtime is None
        try:
            self.core.on_camera_info(msg)
            if first:  # the planner is made now: what it holds the model to is said once
                for note in self.core.runtime.notes:
                    self.log.warn(note)
        except UserError as exc:  # a model for another camera, a depth camera not registered to it: said once, and the node stops
            self.fail(exc)
        except ValueError as exc:  # a later calibration of another size: said once, ignored
            self.log.say(f"{self.names.resolve(self.robot.topics['camera_info'])}: {exc}")

    def on_depth_info(self, msg) -> None:
        """The depth camera's calibration: one not registered to the label camera ends the node."""
        try:
            self.core.on_depth_info(msg)
        except UserError as exc:
            self.fail(exc)

    def fail(self, exc: UserError) -> None:
        """A calibration the node cannot drive with: said, and the node stops (exit 2)."""
        self.failure.append(exc)
        self.log.error(exc.lines()[0])
        self.failed.set()

    def on_image(self, msg, msgtype: str) -> None:
        """A label image, Image or CompressedImage, as the robot publishes it on the topic."""
        topic = self.names.resolve(self.robot.topics["segmentation"])
        self.log.guarded(lambda: self.core.on_image(msgtype, msg, topic, self.clock.now()))  # 0 before /clock ticks: skipped

    def on_depth(self, msg) -> None:
        """A depth image, held for the label images near its stamp."""
        topic = self.names.resolve(self.robot.depth_topic)
        now = self.clock.now() if self.clock.running() else None
        self.log.guarded(lambda: self.core.on_depth(msg, topic, now))

    def on_odometry(self, msg, msgtype: str) -> None:
        """Odometry, or a PoseStamped or PoseWithCovarianceStamped, as the robot file allows."""
        topic = self.names.resolve(self.robot.topics["odometry"])
        self.odom_frame = str(msg.header.frame_id).lstrip("/") or self.odom_frame

        def handle() -> None:
            try:
                self.core.on_odometry(msg, self.clock.now() if self.clock.running() else None)
            except ValueError as exc:
                raise ValueError(f"{topic}: {exc}") from None

        self.log.guarded(handle)

    def publish_costmap(self) -> None:
        """The learned costmap, when the model keeps a ground map, in the odometry's frame; its
        layers as a GridMap, and with a speed rule the learned speed as Nav2's speed filter."""
        from terrapref.interop.ros_messages import filter_info_said, grid_map, occupancy_grid, speed_filter

        grid = self.core.costmap()
        if grid is None:
            return
        stamped = self.header(self.clock.now(), self.odom_frame)
        self.writers["costmap"].publish(occupancy_grid(self.ts, stamped, grid.cost, grid.resolution_m, grid.origin))
        self.writers["grid_map"].publish(grid_map(self.ts, stamped, grid.grid_layers(), grid.resolution_m, grid.origin))
        if "speed" in grid.layers and grid.top_speed_mps is not None:
            mask_topic = next(e.topic for e in self.endpoints if e.role == "speed_mask")
            info, mask = speed_filter(self.ts, stamped, grid.layers["speed"], grid.top_speed_mps, mask_topic)
            said = filter_info_said(info)
            if said != self.filter_said:  # Nav2 takes each new info as a new filter: it warns and subscribes again
                self.writers["speed_filter_info"].publish(info)
                self.filter_said = said
            self.writers["speed_mask"].publish(occupancy_grid(self.ts, stamped, mask, grid.resolution_m, grid.origin))

    def check_publishers(self) -> None:
        """Each input topic that no publisher in the domain offers, said once: a robot in
        another ROS_DOMAIN_ID, or not on this network, looks just like a silent one."""
        for role, readers in self.readers.items():
            if not any(r.get_matched_publications() for r in readers):
                topic = next(e for e in self.endpoints if e.role == role)
                self.log.warn(
                    f"{topic.topic}: no publisher of {' or '.join(topic.msgtypes)} in ROS_DOMAIN_ID {self.domain} after "
                    f"{self.silent_s:g} s (is the robot in this domain, and its DDS on this network?); waiting"
                )

    def spin(self, stop: threading.Event) -> None:
        """Commands at the control rate, the costmap once a second, until ``stop`` or a failure."""
        period = 1.0 / float(self.opts.rate)
        start = time.monotonic()
        next_costmap, checked = start + COSTMAP_PERIOD_S, False
        while not (stop.is_set() or self.failed.is_set()):
            time.sleep(period)
            now = time.monotonic()
            if self.last_stamp is not None:
                self.publish_command()
            self.check_clock()
            if now >= next_costmap:
                next_costmap = now + COSTMAP_PERIOD_S
                self.publish_costmap()
            if not checked and now - start >= self.silent_s:
                checked = True
                self.check_publishers()

    def check_clock(self) -> None:
        """A simulated clock that has not moved on for the watchdog's limit by the wall clock, said once
        (until it moves again): the node has stopped (``stale``) by then, as no frame came."""
        still = self.clock.still_s()
        if still > self.core.watchdog.limit_s and not self.clock_said:
            self.clock_said = True
            self.log.warn(f"/clock has not moved for {still:.1f} s by the wall clock (did the log player stop?); stopping")
        elif still <= self.core.watchdog.limit_s:
            self.clock_said = False

    def publish_stop(self) -> None:
        """A zero command as the node ends, once it has commanded anything, waited on until the
        base has it (a second at most): a base that keeps its last command until told otherwise
        would drive on at it after the node had gone."""
        with self.core.lock:
            self.ended = True
            if self.last_stamp is None:
                return
            self.writers["command"].publish(self.command_message(0.0, 0.0, self.clock.now()))
        if not self.writers["command"].delivered(STOP_DELIVERY_S):
            self.log.warn(f"the last stop command was not acknowledged within {STOP_DELIVERY_S:g} s")

    def close(self) -> None:
        """Send a stop, then leave the domain: subscribers see the node's publishers go."""
        try:
            self.publish_stop()
        except Exception as exc:  # noqa: BLE001  (said: the node ends all the same, and the base's own timeout is left to stop it)
            self.log.warn(f"the last stop command could not be sent ({type(exc).__name__}: {exc})")
        finally:
            self.dds.close()
