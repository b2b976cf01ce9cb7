"""``terrapref ros1``: the planner as a ROS 1 node (rospy), around :class:`PlannerNodeCore`.

Subscribes to the robot file's label image, camera calibration, odometry and (without a path
file) path topics; publishes the command on the robot file's command topic (``Twist``, or
``TwistStamped`` with ``--stamped``, stamped with the frame it was decided on; a stop once that
frame is ``hold_s`` old by the node's clock) at the control rate and at once on each decision, the 21 trajectories with F_t and the chosen one
(``~trajectories``, ``visualization_msgs/MarkerArray``) on each decision, and the learned costmap
(``~costmap``, ``nav_msgs/OccupancyGrid``) once a second. Its options come from the command
line or its private ROS parameters (:class:`NodeOptions`).

ROS 1's Python packages come from Debian (``ros-core``, ``python3-rospy`` and the message
packages) and live in its Python 3.11 ``dist-packages``: where ``rospy`` is not importable from
terrapref's own environment, that folder is added to the import path.
"""

from __future__ import annotations

import importlib
import math
import os
import socket
import sys
import urllib.parse
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from terrapref.errors import UserError
from terrapref.stops import REASONS

DEBIAN_DIST_PACKAGES = Path("/usr/lib/python3/dist-packages")
ROS_PACKAGES = "ros-core python3-rospy python3-geometry-msgs python3-sensor-msgs python3-nav-msgs python3-visualization-msgs python3-std-msgs"
COSTMAP_PERIOD_S = 1.0


def import_rospy():
    """rospy, from this environment or Debian's; a clear error where ROS 1 is not installed."""
    try:
        return importlib.import_module("rospy")
    except ImportError:
        if DEBIAN_DIST_PACKAGES.is_dir() and str(DEBIAN_DIST_PACKAGES) not in sys.path:
            sys.path.append(str(DEBIAN_DIST_PACKAGES))
            try:
                return importlib.import_module("rospy")
            except ImportError:
                pass
    raise UserError("ros1", f"ROS 1's Python packages are not installed (Debian: apt install {ROS_PACKAGES})")


@dataclass(frozen=True)
class NodeOptions:
    """How the node runs: each from the command line (``hold_s`` has no flag), else from the
    node's private ROS parameter of the same name (``~stamped``, ``~rate``, ``~path_file``,
    ``~cmd_topic``, ``~hold_s``), else the default.

    Attributes:
        stamped: publish TwistStamped instead of Twist (default False).
        rate: commands per second between decisions (default 20).
        path_file: waypoints of the reference path, instead of the path topic.
        cmd_topic: where the command goes (default: the robot file's command topic).
        hold_s: how long a decision's command holds after its frame's stamp [s] (default 0.3).
    """

    stamped: bool | None = None
    rate: float | None = None
    path_file: str | None = None
    cmd_topic: str | None = None
    hold_s: float | None = None

    def resolved(self, get_param: Callable[[str, Any], Any]) -> NodeOptions:
        """Every option set: the given ones, the rest from ``get_param("~name", default)`` (rospy's
        ``get_param``), checked (a bad value is a UserError naming the option and where it came from)."""
        defaults = {"stamped": False, "rate": 20.0, "path_file": None, "cmd_topic": None, "hold_s": 0.3}
        values, origin = {}, {}
        for name, default in defaults.items():
            given = getattr(self, name)
            values[name], origin[name] = (given, f"--{name.replace('_', '-')}") if given is not None else (get_param(f"~{name}", default), f"~{name}")
        if not isinstance(values["stamped"], bool):
            raise UserError(origin["stamped"], f"expected true or false, got {values['stamped']!r}")
        for name, top in (("rate", 200.0), ("hold_s", 5.0)):
            v = values[name]
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and 0 < v <= top):
                raise UserError(origin[name], f"expected a number in (0, {top:g}], got {v!r}")
        for name in ("path_file", "cmd_topic"):
            if values[name] is not None and (not isinstance(values[name], str) or not values[name]):
                raise UserError(origin[name], f"expected a non-empty string, got {values[name]!r}")
        return NodeOptions(**values)


def run_node(model_path: str, robot_path: str, options: NodeOptions | None = None, live=None) -> None:
    """Run the node until ROS shuts it down; with ``live`` (a terrapref.interop.live.LiveView),
    every decision is also sent there."""
    rospy = import_rospy()
    from terrapref.interop.node_core import PlannerNodeCore
    from terrapref.interop.robot import load_robot, load_waypoints
    from terrapref.learning.model_file import load_model

    model = load_model(model_path)
    robot = load_robot(robot_path, model.classes)
    check_master(os.environ.get("ROS_MASTER_URI", DEFAULT_MASTER_URI))  # rospy would wait for one for ever
    rospy.init_node("terrapref", anonymous=False)
    opts = (options or NodeOptions()).resolved(rospy.get_param)
    path = load_waypoints(Path(opts.path_file), "path_file") if opts.path_file else \
        (load_waypoints(robot.path_file, robot.source) if robot.path_file else None)
    core = PlannerNodeCore(model, robot, path, hold_s=float(opts.hold_s))
    if live is not None:
        core.watch(live)
    node = _Node(rospy, core, model, robot, opts)
    rospy.on_shutdown(node.report)
    rospy.spin()
    if node.failure:
        raise node.failure[0]


DEFAULT_MASTER_URI = "http://localhost:11311"
MASTER_TIMEOUT_S = 3.0


def check_master(uri: str, timeout_s: float = MASTER_TIMEOUT_S) -> None:
    """Refuse, within ``timeout_s``, a ROS_MASTER_URI that is not http://HOST:PORT or where nothing
    answers (rospy.init_node would wait for a master for ever)."""
    try:
        parsed = urllib.parse.urlsplit(uri)
        scheme, host, port = parsed.scheme, parsed.hostname, parsed.port
    except ValueError:  # a port that is not a number or out of range, a bracket left open
        scheme = host = port = None
    if scheme not in ("http", "https") or not host or port is None:
        raise UserError("ROS_MASTER_URI", f"{uri!r} is not a ROS master's URI; expected http://HOST:PORT (e.g. {DEFAULT_MASTER_URI})")
    try:
        socket.create_connection((host, port), timeout=timeout_s).close()
    except OSError as exc:
        raise UserError("ROS_MASTER_URI", f"no ROS master at {uri} ({exc.strerror or exc}); start roscore there or point ROS_MASTER_URI "
                                          "at the robot's master") from None


class _Node:
    """The node's publishers, subscribers and timers around a :class:`PlannerNodeCore`."""

    def __init__(self, rospy, core, model, robot, opts: NodeOptions) -> None:
        from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped, Twist, TwistStamped
        from nav_msgs.msg import OccupancyGrid, Odometry, Path as PathMsg
        from sensor_msgs.msg import CameraInfo, CompressedImage, Image
        from visualization_msgs.msg import MarkerArray

        self.rospy, self.core, self.robot, self.opts = rospy, core, robot, opts
        self.failure: list[UserError] = []
        self.said: set[str] = set()  # problems with incoming messages, each logged once
        self.last_stamp: float | None = None  # the frame of the command in force
        self.stop_reason: str | None = None  # why the command in force stops (None: it drives)
        self.Twist, self.TwistStamped, self.OccupancyGrid = Twist, TwistStamped, OccupancyGrid
        self.image_types = {"sensor_msgs/Image": (Image, "sensor_msgs/msg/Image"),
                            "sensor_msgs/CompressedImage": (CompressedImage, "sensor_msgs/msg/CompressedImage")}
        self.pose_types = {"nav_msgs/Odometry": Odometry, "geometry_msgs/PoseStamped": PoseStamped,
                           "geometry_msgs/PoseWithCovarianceStamped": PoseWithCovarianceStamped}
        self.cmd_pub = rospy.Publisher(opts.cmd_topic or robot.topics["command"], TwistStamped if opts.stamped else Twist, queue_size=10)
        self.traj_pub = rospy.Publisher("~trajectories", MarkerArray, queue_size=2)
        self.cost_pub = rospy.Publisher("~costmap", OccupancyGrid, queue_size=1, latch=True)
        self.markers = _TrajectoryMarkers(model, rospy)
        core.on_decision = self.on_decision
        rospy.Subscriber(robot.topics["camera_info"], CameraInfo, self.on_camera_info, queue_size=1)
        rospy.Subscriber(robot.topics["odometry"], rospy.AnyMsg, self.on_odometry, queue_size=50)
        if core.path is None and robot.path_topic:
            rospy.Subscriber(robot.path_topic, PathMsg, core.on_path, queue_size=1)
        rospy.Subscriber(robot.topics["segmentation"], rospy.AnyMsg, self.on_image, queue_size=1)
        rospy.Timer(rospy.Duration(1.0 / float(opts.rate)), self.tick)
        rospy.Timer(rospy.Duration(COSTMAP_PERIOD_S), self.publish_costmap)

    def publish_command(self, stamp_s: float) -> None:
        """The command in force now (a stop once its frame is ``hold_s`` old), stamped with its frame;
        each time the planner stops, or moves on, the log says so and why."""
        (v, w), reason = self.core.status_at(self.rospy.get_time())
        if reason != self.stop_reason:
            self.stop_reason = reason
            if reason is None:
                self.rospy.loginfo("terrapref: moving on")
            else:
                self.rospy.logwarn(f"terrapref: stopping: {reason} ({REASONS.get(reason, reason)})")
        twist = self.Twist()
        twist.linear.x, twist.angular.z = float(v), float(w)
        if not self.opts.stamped:
            self.cmd_pub.publish(twist)
            return
        msg = self.TwistStamped()
        msg.header.stamp, msg.header.frame_id, msg.twist = self.rospy.Time.from_sec(stamp_s), "base_link", twist
        self.cmd_pub.publish(msg)

    def on_decision(self, decision) -> None:
        """Each decision, whether its image or the odometry it waited for brought it."""
        self.last_stamp = decision.stamp_s
        self.publish_command(decision.stamp_s)
        self.traj_pub.publish(self.markers.of(decision, self.rospy.Time.from_sec(decision.stamp_s)))

    def on_camera_info(self, msg) -> None:
        try:
            self.core.on_camera_info(msg)
        except UserError as exc:  # a model for another camera: said once, and the node stops
            self.failure.append(exc)
            self.rospy.signal_shutdown(exc.lines()[0])

    def on_image(self, raw) -> None:
        """A label image, Image or CompressedImage, as the robot publishes it on the topic."""
        kind = raw._connection_header.get("type", "")
        if kind not in self.image_types:
            return self._say(f"{self.robot.topics['segmentation']}: {kind} is not a label image (sensor_msgs/Image or CompressedImage); ignored")
        cls, msgtype = self.image_types[kind]
        self._guarded(lambda: self.core.on_image(msgtype, cls().deserialize(raw._buff), self.robot.topics["segmentation"]))

    def on_odometry(self, raw) -> None:
        """Odometry, or a PoseStamped or PoseWithCovarianceStamped, as the robot file allows."""
        kind = raw._connection_header.get("type", "")
        if kind not in self.pose_types:
            return self._say(f"{self.robot.topics['odometry']}: {kind} is not Odometry, PoseStamped or PoseWithCovarianceStamped; ignored")
        self._guarded(lambda: self.core.on_odometry(self.pose_types[kind]().deserialize(raw._buff)))

    def _guarded(self, handle: Callable[[], Any]) -> None:
        """Handle one message; a message the node cannot use (an image it cannot decode, of the
        wrong size) is skipped and said once, not a traceback per frame."""
        try:
            handle()
        except (UserError, ValueError) as exc:
            self._say(exc.lines()[0] if isinstance(exc, UserError) else str(exc))

    def _say(self, problem: str) -> None:
        if problem not in self.said:
            self.said.add(problem)
            self.rospy.logerr(f"terrapref: {problem} (said once; such messages are skipped)")

    def tick(self, event) -> None:
        if self.last_stamp is not None:
            self.publish_command(self.last_stamp)

    def publish_costmap(self, event) -> None:
        grid = self.core.costmap()
        if grid is not None:
            self.cost_pub.publish(_occupancy_grid(grid, self.OccupancyGrid, self.rospy))

    def report(self) -> None:
        skipped = ", ".join(f"{n} {why}" for why, n in self.core.skipped.items() if n) or "none"
        print(f"terrapref ros1: {self.core.decided} frames decided on; skipped: {skipped}", flush=True)


class _TrajectoryMarkers:
    """The 21 trajectories as line strips in base_link, shaded by F_t, the chosen one green."""

    def __init__(self, model, rospy) -> None:
        from terrapref.features.preference_set import forward_simulate

        pref = model.features.preference
        c = pref.control
        self.paths = forward_simulate(np.full(c.m, c.v_mps), np.asarray(c.w_rps), pref.n_steps, pref.dt_s)[..., :2]
        self.rospy = rospy

    def of(self, decision, stamp):
        from geometry_msgs.msg import Point
        from std_msgs.msg import ColorRGBA
        from visualization_msgs.msg import Marker, MarkerArray

        out = MarkerArray()
        top = float(np.max(decision.probs)) or 1.0
        for j, pts in enumerate(self.paths):
            m = Marker()
            m.header.stamp, m.header.frame_id = stamp, "base_link"
            m.ns, m.id, m.type, m.action = "trajectories", j, Marker.LINE_STRIP, Marker.ADD
            m.pose.orientation.w = 1.0
            m.scale.x = 0.06 if j == decision.index else 0.03
            shade = float(decision.probs[j]) / top
            m.color = ColorRGBA(0.1, 0.9, 0.2, 1.0) if j == decision.index else ColorRGBA(1.0, 1.0, 1.0, 0.2 + 0.8 * shade)
            m.points = [Point(float(x), float(y), 0.02) for x, y in pts]
            m.lifetime = self.rospy.Duration(0.5)
            out.markers.append(m)
        return out


def _occupancy_grid(grid, OccupancyGrid, rospy):
    msg = OccupancyGrid()
    msg.header.stamp = rospy.Time.now()
    msg.header.frame_id = "odom"
    h, w = grid.cost.shape
    msg.info.resolution = grid.resolution_m
    msg.info.width, msg.info.height = w, h
    msg.info.origin.position.x, msg.info.origin.position.y = grid.origin
    msg.info.origin.orientation.w = 1.0
    msg.data = grid.cost.ravel().tolist()
    return msg
