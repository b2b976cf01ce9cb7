"""``terrapref ros1``: the planner as a ROS 1 node (rospy), around :class:`PlannerNodeCore`.

Subscribes to the robot file's label image, camera calibration, odometry, (where it names them)
depth image and depth calibration, and (without a path file) path topics; publishes the command on the robot file's command topic (``Twist``, or
``TwistStamped`` with ``--stamped``, stamped with the frame it was decided on; a stop once that
frame is ``hold_s`` old by the node's clock) at the control rate and at once on each decision, the 21 trajectories with F_t and the chosen one
(``~trajectories``, ``visualization_msgs/MarkerArray``) on each decision, the learned costmap
(``~costmap``, ``nav_msgs/OccupancyGrid``, latched) once a second with its layers beside it
(``~grid_map``, ``grid_map_msgs/GridMap``, latched), and whether it stands at the end of its
path (``~arrived``, ``std_msgs/Bool``, latched). The command is sent from a wall-clock timer, so
that a ``/clock`` that stops (under ``use_sim_time``) cannot stop the node from sending the stop
that follows: once no frame has been decided on for ``watchdog_s`` by the wall clock it stops
(``stale``). Its options come from the command line or its private ROS parameters (:class:`NodeOptions`). What is not ROS 1 transport lives in
:mod:`terrapref.interop.node_core`, which the ROS 2 node shares.

ROS 1's Python packages come from Debian (``ros-core``, ``python3-rospy`` and the message
packages) and live in its Python 3.11 ``dist-packages``: where ``rospy`` is not importable from
terrapref's own environment, that folder is added to the import path.
"""

from __future__ import annotations

import importlib
import os
import socket
import sys
import threading
import time
import urllib.parse
from pathlib import Path
from typing import TYPE_CHECKING

from terrapref.errors import UserError
from terrapref.interop.node_core import NodeOptions

if TYPE_CHECKING:
    from terrapref.groundmap.costmap import Costmap

__all__ = ["NodeOptions", "check_master", "import_rospy", "run_node"]

DEBIAN_DIST_PACKAGES = Path("/usr/lib/python3/dist-packages")
ROS_PACKAGES = (
    "ros-core python3-rospy python3-geometry-msgs python3-sensor-msgs python3-nav-msgs python3-visualization-msgs python3-std-msgs"
)
COSTMAP_PERIOD_S = 1.0
STOP_DELIVERY_S = 0.5  # how long the node gives its last stop command to go out as it ends [s]
DEPTH_BUFFER_BYTES = 1 << 24  # a depth subscriber's receive buffer: a 32FC1 image of 2 megapixels


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


def run_node(model_path: str, robot_path: str, options: NodeOptions | None = None, live=None) -> None:
    """Run the node until ROS shuts it down; with ``live`` (a terrapref.interop.live.LiveView),
    every decision is also sent there."""
    rospy = import_rospy()
    from terrapref.interop.node_core import AHEAD_S, SIM_AHEAD_S, PlannerNodeCore, Watchdog, nested_rule_params
    from terrapref.interop.robot import load_robot, load_waypoints
    from terrapref.learning.model_file import load_model

    model = load_model(model_path)
    robot = load_robot(robot_path, model.classes, f"the model {model_path}")
    check_master(os.environ.get("ROS_MASTER_URI", DEFAULT_MASTER_URI))  # rospy would wait for one for ever
    rospy.init_node("terrapref", anonymous=False)
    opts = (options or NodeOptions()).with_rule_params(nested_rule_params(rospy.get_param), "~RULE/NAME")
    opts = opts.resolved(rospy.get_param)
    robot = opts.applied_to(robot)
    path = (
        load_waypoints(Path(opts.path_file), None)
        if opts.path_file
        else (load_waypoints(robot.path_file, robot.source) if robot.path_file else None)
    )
    ahead = SIM_AHEAD_S if rospy.get_param("/use_sim_time", False) is True else AHEAD_S
    core = PlannerNodeCore(model, robot, path, float(opts.hold_s), ahead, Watchdog(float(opts.watchdog_s)))
    if live is not None:
        core.watch(live)
    node = _Node(rospy, core, model, robot, opts)
    rospy.on_shutdown(node.close)
    rospy.spin()
    node.done.set()
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
        raise UserError(
            "ROS_MASTER_URI",
            f"no ROS master at {uri} ({exc.strerror or exc}); start roscore there or point ROS_MASTER_URI at the robot's master",
        ) from None


class _Node:
    """The node's publishers, subscribers and timers around a :class:`PlannerNodeCore`."""

    def __init__(self, rospy, core, model, robot, opts: NodeOptions) -> None:
        from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped, Twist, TwistStamped
        from nav_msgs.msg import OccupancyGrid, Odometry
        from nav_msgs.msg import Path as PathMsg
        from sensor_msgs.msg import CameraInfo, CompressedImage, Image
        from std_msgs.msg import Bool
        from visualization_msgs.msg import MarkerArray

        from terrapref.interop.node_core import NodeLog, limits_line

        self.rospy, self.core, self.robot, self.opts = rospy, core, robot, opts
        self.failure: list[UserError] = []
        self.log = NodeLog(rospy.loginfo, rospy.logwarn, rospy.logerr)
        self.last_stamp: float | None = None  # the frame of the command in force
        self.ended = False  # the node has sent its last command, a stop
        self.Twist, self.TwistStamped, self.OccupancyGrid = Twist, TwistStamped, OccupancyGrid
        self.image_types = {
            "sensor_msgs/Image": (Image, "sensor_msgs/msg/Image"),
            "sensor_msgs/CompressedImage": (CompressedImage, "sensor_msgs/msg/CompressedImage"),
        }
        self.pose_types = {
            "nav_msgs/Odometry": Odometry,
            "geometry_msgs/PoseStamped": PoseStamped,
            "geometry_msgs/PoseWithCovarianceStamped": PoseWithCovarianceStamped,
        }
        self.cmd_pub = rospy.Publisher(opts.command_topic(robot), TwistStamped if opts.stamped else Twist, queue_size=10)
        self.traj_pub = rospy.Publisher("~trajectories", MarkerArray, queue_size=2)
        self.cost_pub = rospy.Publisher("~costmap", OccupancyGrid, queue_size=1, latch=True)
        self.grid_maps = _GridMaps.made(rospy, self.log)
        self.arrived_pub, self.Bool, self.arrived = rospy.Publisher("~arrived", Bool, queue_size=1, latch=True), Bool, None
        self.markers = _TrajectoryMarkers(model, rospy)
        core.on_decision = self.on_decision
        core.on_problem = self.log.say
        rospy.Subscriber(robot.topics["camera_info"], CameraInfo, self.on_camera_info, queue_size=1)
        rospy.Subscriber(robot.topics["odometry"], rospy.AnyMsg, self.on_odometry, queue_size=50)
        if core.path is None and robot.path_topic:
            rospy.Subscriber(robot.path_topic, PathMsg, self.on_path, queue_size=1)
        rospy.Subscriber(robot.topics["segmentation"], rospy.AnyMsg, self.on_image, queue_size=1)
        if robot.depth_topic:
            self.Image = Image
            # Every depth image near a label image's stamp is wanted, not the newest only; a buffer that
            # holds a whole one, for rospy's default (64 KiB) makes a large message wait.
            rospy.Subscriber(robot.depth_topic, rospy.AnyMsg, self.on_depth, queue_size=10, buff_size=DEPTH_BUFFER_BYTES)
            if core.depth_info_topic:
                rospy.Subscriber(core.depth_info_topic, CameraInfo, self.on_depth_info, queue_size=1)
        self.publish_arrived()
        self.log.info(f"terrapref: {limits_line(robot, core.watchdog.limit_s)}")  # as the ROS 2 node says it
        if robot.rules:
            self.log.info(f"terrapref: rule settings over the model file's: {'; '.join(robot.rules.lines())}")
        self.done = threading.Event()
        threading.Thread(target=self.ticks, name="terrapref-commands", daemon=True).start()  # the wall clock's, not ROS time's
        rospy.Timer(rospy.Duration(COSTMAP_PERIOD_S), self.publish_costmap)

    def publish_command(self, stamp_s: float) -> None:
        """The command in force now (a stop once its frame is ``hold_s`` old), stamped with its frame;
        each time the planner stops, or moves on, the log says so and why."""
        if self.ended:  # the stop the node ended with stays the last command
            return
        (v, w), reason = self.core.status_at(self.rospy.get_time())
        self.log.status(reason)
        self.cmd_pub.publish(self._twist_message(v, w, stamp_s))

    def on_decision(self, decision) -> None:
        """Each decision, whether its image or the odometry it waited for brought it."""
        self.last_stamp = decision.stamp_s
        self.publish_command(decision.stamp_s)
        self.traj_pub.publish(self.markers.of(decision, self.rospy.Time.from_sec(decision.stamp_s)))
        self.publish_arrived()

    def publish_arrived(self) -> None:
        """``~arrived`` when it changes (true once the planner stands at its goal, false on a new path)."""
        arrived = self.core.arrived
        if arrived != self.arrived:
            self.arrived = arrived
            self.arrived_pub.publish(self.Bool(data=arrived))
            if arrived:
                self.log.info("terrapref: arrived at the end of the path (goal)")

    def on_path(self, msg) -> None:
        problem = self.core.on_path(msg)
        if problem is not None:
            self.log.say(problem)
        self.publish_arrived()

    def on_camera_info(self, msg) -> None:
        first = self.core.runtime is None
        try:
            self.core.on_camera_info(msg)
            if first:  # the planner is made now: what it holds the model to is said once
                for note in self.core.runtime.notes:
                    self.log.warn(f"terrapref: {note}")
        except UserError as exc:  # a model for another camera, a depth camera not registered to it: said once, and the node stops
            self.fail(exc)
        except ValueError as exc:  # a later calibration of another size: said once, ignored
            self.log.say(str(exc))

    def on_depth_info(self, msg) -> None:
        """The depth camera's calibration: one not registered to the label camera ends the node."""
        try:
            self.core.on_depth_info(msg)
        except UserError as exc:
            self.fail(exc)

    def fail(self, exc: UserError) -> None:
        """A calibration the node cannot drive with: the node stops with its line (exit 2)."""
        self.failure.append(exc)
        self.rospy.signal_shutdown(exc.lines()[0])

    def on_depth(self, raw) -> None:
        """A depth image (sensor_msgs/Image 32FC1 or 16UC1), held for the label images near its stamp."""
        topic = self.robot.depth_topic
        kind = raw._connection_header.get("type", "")
        if kind != "sensor_msgs/Image":
            return self.log.say(f"{topic}: {kind} is not a depth image (sensor_msgs/Image 32FC1 or 16UC1, REP 118); ignored")
        now = self.rospy.get_time()
        self.log.guarded(lambda: self.core.on_depth(self.Image().deserialize(raw._buff), topic, now or None))

    def on_image(self, raw) -> None:
        """A label image, Image or CompressedImage, as the robot publishes it on the topic."""
        kind = raw._connection_header.get("type", "")
        if kind not in self.image_types:
            return self.log.say(
                f"{self.robot.topics['segmentation']}: {kind} is not a label image (sensor_msgs/Image or CompressedImage); ignored"
            )
        cls, msgtype = self.image_types[kind]
        now = self.rospy.get_time()  # 0 under use_sim_time before /clock ticks: the image is skipped
        self.log.guarded(lambda: self.core.on_image(msgtype, cls().deserialize(raw._buff), self.robot.topics["segmentation"], now))

    def on_odometry(self, raw) -> None:
        """Odometry, or a PoseStamped or PoseWithCovarianceStamped, as the robot file allows."""
        kind = raw._connection_header.get("type", "")
        if kind not in self.pose_types:
            return self.log.say(
                f"{self.robot.topics['odometry']}: {kind} is not Odometry, PoseStamped or PoseWithCovarianceStamped; ignored"
            )
        self.log.guarded(lambda: self.core.on_odometry(self.pose_types[kind]().deserialize(raw._buff), self.rospy.get_time()))

    def ticks(self) -> None:
        """The command at the control rate by the wall clock, until the node shuts down."""
        period = 1.0 / float(self.opts.rate)
        while not (self.done.is_set() or self.rospy.is_shutdown()):
            time.sleep(period)
            if self.last_stamp is not None:
                with self.core.lock:
                    self.publish_command(self.last_stamp)

    def publish_costmap(self, event) -> None:
        """The learned costmap, when the model keeps a ground map, and its layers as a GridMap,
        both stamped now in the odom frame."""
        grid = self.core.costmap()
        if grid is None:
            return
        stamp = self.rospy.Time.now()
        self.cost_pub.publish(_occupancy_grid(grid, self.OccupancyGrid, stamp))
        if self.grid_maps is not None:
            self.grid_maps.publish(grid, stamp)

    def close(self) -> None:
        """As ROS shuts the node down: a stop, once it has commanded anything (a base that keeps
        its last command until told otherwise would drive on at it after the node had gone),
        given a moment to go out, then the line of what it decided and skipped."""
        from terrapref.interop.node_core import report_line

        self.done.set()
        with self.core.lock:
            self.ended = True
            try:
                if self.last_stamp is not None:
                    self.cmd_pub.publish(self._twist_message(0.0, 0.0, self.rospy.get_time()))
            except Exception as exc:  # noqa: BLE001  (said: the node ends all the same)
                self.log.warn(f"terrapref: the last stop command could not be sent ({type(exc).__name__}: {exc})")
        if self.last_stamp is not None:
            time.sleep(STOP_DELIVERY_S)  # rospy sends from a thread of its own; teardown would drop what waits
        print(report_line(self.core, "ros1", self.log), flush=True)

    def _twist_message(self, v: float, w: float, stamp_s: float):
        """The command (v, w) as the node publishes it: a Twist, or a TwistStamped stamped ``stamp_s`` in base_link."""
        twist = self.Twist()
        twist.linear.x, twist.angular.z = float(v), float(w)
        if not self.opts.stamped:
            return twist
        msg = self.TwistStamped()
        msg.header.stamp, msg.header.frame_id, msg.twist = self.rospy.Time.from_sec(stamp_s), "base_link", twist
        return msg


class _TrajectoryMarkers:
    """The trajectories as line strips in base_link, shaded by F_t, the chosen one green
    (:class:`terrapref.interop.node_core.TrajectoryShapes`), as rospy messages."""

    def __init__(self, model, rospy) -> None:
        from terrapref.interop.node_core import TrajectoryShapes

        self.shapes = TrajectoryShapes(model)
        self.rospy = rospy

    def of(self, decision, stamp):
        from geometry_msgs.msg import Point
        from std_msgs.msg import ColorRGBA
        from visualization_msgs.msg import Marker, MarkerArray

        out = MarkerArray()
        for j, (pts, (width_m, rgba)) in enumerate(zip(self.shapes.paths, self.shapes.styles(decision))):
            m = Marker()
            m.header.stamp, m.header.frame_id = stamp, "base_link"
            m.ns, m.id, m.type, m.action = "trajectories", j, Marker.LINE_STRIP, Marker.ADD
            m.pose.orientation.w = 1.0
            m.scale.x = width_m
            m.color = ColorRGBA(*rgba)
            m.points = [Point(float(x), float(y), 0.02) for x, y in pts]
            m.lifetime = self.rospy.Duration(0.5)
            out.markers.append(m)
        return out


COSTMAP_FRAME = "odom"  # the frame the costmap and its layers are stamped in


class _GridMaps:
    """``~grid_map``: the costmap's layers as grid_map_msgs/GridMap, latched.

    No Debian package carries grid_map_msgs' Python classes, so the message is built and
    serialised with rosbags' ROS 1 typestore, as a ROS 1 bag's (:func:`terrapref.interop.ros_messages.grid_map`),
    and published as its bytes through a rospy.AnyMsg whose class names the type, its md5sum
    and its definition: what rospy sends for a message class, so that grid_map's own
    subscribers (rviz's GridMap display, grid_map_visualization) match it.
    """

    MSGTYPE = "grid_map_msgs/msg/GridMap"

    def __init__(self, rospy) -> None:
        from terrapref.interop.ros_messages import typestore

        self.ts = typestore(ros1=True)
        definition, md5sum = self.ts.generate_msgdef(self.MSGTYPE, ros_version=1)
        attrs = {"_type": "grid_map_msgs/GridMap", "_md5sum": md5sum, "_full_text": definition, "__slots__": []}
        self.Raw = type("GridMap", (rospy.AnyMsg,), attrs)
        self.pub = rospy.Publisher("~grid_map", self.Raw, queue_size=1, latch=True)

    @classmethod
    def made(cls, rospy, log) -> _GridMaps | None:
        """The publisher; without rosbags (the robot extra), None and a warning that says so once."""
        from terrapref.extras import MissingExtra, check

        try:
            check("robot", "~grid_map (grid_map_msgs/GridMap)", "rosbags")
        except MissingExtra as exc:
            log.warn(f"terrapref: {exc.lines()[0]}; the costmap goes out as an OccupancyGrid only")
            return None
        return cls(rospy)

    def publish(self, grid: Costmap, stamp) -> None:
        """The layers of ``grid`` (:meth:`Costmap.grid_layers`), stamped ``stamp`` (a rospy.Time)."""
        from terrapref.interop.ros_messages import grid_map

        T = self.ts.types
        when = T["builtin_interfaces/msg/Time"](sec=stamp.secs, nanosec=stamp.nsecs)
        header = T["std_msgs/msg/Header"](seq=0, stamp=when, frame_id=COSTMAP_FRAME)
        msg = grid_map(self.ts, header, grid.grid_layers(), grid.resolution_m, grid.origin, ros1=True)
        raw = self.Raw()
        raw._buff = bytes(self.ts.serialize_ros1(msg, self.MSGTYPE))
        self.pub.publish(raw)


def _occupancy_grid(grid: Costmap, OccupancyGrid, stamp):
    msg = OccupancyGrid()
    msg.header.stamp = stamp
    msg.header.frame_id = COSTMAP_FRAME
    h, w = grid.cost.shape
    msg.info.resolution = grid.resolution_m
    msg.info.width, msg.info.height = w, h
    msg.info.origin.position.x, msg.info.origin.position.y = grid.origin
    msg.info.origin.orientation.w = 1.0
    msg.data = grid.cost.ravel().tolist()
    return msg
