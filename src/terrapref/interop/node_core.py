"""What a ROS node of the planner does with its messages, without ROS (the ROS 1 node and the
ROS 2 node both wrap it, each around its own transport).

Messages come in as they would from rospy or rclpy (attribute access: ``header.stamp``,
``pose.pose``, ``data``, ...). The calibration makes the planner (a model trained for another
camera is refused); odometry is kept for the last seconds and interpolated to each image's
stamp; the reference path comes from a Path message or a waypoint file; each label image is
decoded through the robot file's label map and decided on by :class:`PlannerRuntime`, which
ignores frames older than the last one and holds a command for ``hold_s`` after its frame. With
a depth topic in the robot file, each label image is decided on with the depth image of the
nearest stamp within :data:`DEPTH_PAIRING_S`, as ``import`` pairs them
(terrapref.interop.depth_pairing), and the body's attitude from the odometry at its stamp; one
with no depth image that near is skipped and counted, never decided on as if the ground were
flat: on a robot that declared depth, that would drop the limits its geometry sets. The
command sent is the decision's (v, w): the way chosen at the speed the model's speed rule sets
(the control set's speed for a model without one); the trajectories drawn for display are the
control set's, at its speed.
"""

from __future__ import annotations

import math
import re
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from terrapref.errors import UserError, described, finite_number
from terrapref.groundmap.costmap import Costmap
from terrapref.interop.depth_pairing import DEPTH_PAIRING_S, DepthPairing
from terrapref.interop.labels import unlisted_message
from terrapref.interop.robot import GIVEN_TOPIC_NAME, LIMITS, RobotConfig, limit_problem, stop_value_problem
from terrapref.interop.ros_decode import (
    camera_from_info,
    check_depth_info,
    label_ids,
    path_xy,
    pitch_roll_rad,
    registered_depth,
    stamp_s,
    undistorted,
    unit_quaternion,
    yaw_rad,
)
from terrapref.interop.runtime import (
    FLAT_NOTE,
    SPEED_WINDOW_S,
    DepthFrame,
    PlannerRuntime,
    RobotSettings,
    RuntimeDecision,
    odometry_speed_mps,
)
from terrapref.learning.model_file import LoadedModel
from terrapref.planner.model import Model
from terrapref.planner.stop import StopConfig
from terrapref.rules import RULES
from terrapref.rules.settings import RuleSettings
from terrapref.scenario.path import ReferencePath
from terrapref.stops import REASONS, STALE
from terrapref.terrain import UNKNOWN
from terrapref.vehicle import Command, Pose, VehicleConfig, wrap_angle
from terrapref.vehicle.ground import Attitude

if TYPE_CHECKING:
    from terrapref.interop.live import LiveRun, LiveView

ODOMETRY_KEPT_S = 5.0  # how far back odometry is kept for interpolating to an image's stamp [s]
ODOMETRY_WAIT_S = 0.5  # how long an image newer than the odometry waits for it [s]
DEPTH_WAIT_S = 0.5  # how far an image's stamp may be past the newest depth image's for it to wait for a nearer one [s]
# The images kept waiting at once: a depth camera's images that come later than the next label image
# (its pipeline slower than the segmentation's) are each still waited for (1.6 s of a 10 Hz camera).
PENDING_KEPT = 16
DEPTH_KEPT = 32  # depth images held at most for label images still to come (the newest): about 1 s of a 30 Hz camera
BEFORE_CLOCK = "images before the node's clock started"  # why an image that came before a simulated clock's first tick is skipped
NO_DEPTH = f"without a depth image within {1000 * DEPTH_PAIRING_S:.0f} ms"  # why a frame on a robot with depth is skipped
AHEAD_S = 1.0  # odometry and images stamped further ahead of the node's clock are refused [s] (the system's clock)
SIM_AHEAD_S = 10.0  # the same under a simulated clock, whose /clock messages may come late (a node busy making its planner) [s]


class Watchdog:
    """A stop once nothing has fed it for ``limit_s`` by the wall clock, whatever the node's own
    clock says: a simulated clock that froze (the log player died) would otherwise hold the last
    command for ever.

    Args:
        limit_s: how long it waits [s].
        wall: the wall clock [s] (a monotonic one).
    """

    def __init__(self, limit_s: float = 1.0, wall: Callable[[], float] = time.monotonic) -> None:
        self.limit_s, self.wall = limit_s, wall
        self._fed: float | None = None

    def feed(self) -> None:
        """Something happened (a frame was decided on)."""
        self._fed = self.wall()

    @property
    def fed_s(self) -> float | None:
        """When it was last fed, by its wall clock [s] (None: not yet)."""
        return self._fed

    def barks(self, stale: Callable[[float, float | None, float], bool]) -> bool:
        """Whether it has waited longer than its limit since it was last fed (never before the
        first time), as ``stale`` (the stop rule's: terrapref.planner.stop.StopRule.stale) says."""
        return self._fed is not None and stale(self.wall(), self._fed, self.limit_s)


class PlannerNodeCore:
    """The planner behind a ROS node: messages in, decisions, commands and costmaps out.

    Args:
        model: the model the node drives with.
        robot: the robot file (topics, camera mounting, label map, the odometry's gaps, when to
            stop, the robot's limits).
        path: the reference path (N, 2) [m] in the odometry frame, when it comes from a file;
            otherwise the first Path message sets it.
        hold_s: how long a decision's command stays in force after its frame's stamp [s].
        ahead_s: how far ahead of the node's clock an input's stamp may be [s] (:data:`AHEAD_S`, or
            :data:`SIM_AHEAD_S` under a simulated clock).
        watchdog: stops the node (``stale``) once no frame has been decided on for its limit by
            the wall clock (default: 1 s).
    """

    def __init__(
        self,
        model: LoadedModel,
        robot: RobotConfig,
        path: np.ndarray | None = None,
        hold_s: float = 0.3,
        ahead_s: float = AHEAD_S,
        watchdog: Watchdog | None = None,
    ) -> None:
        self.model, self.robot, self.stop = model, robot, robot.stop
        if "tf" in robot.camera:  # import reads the mounting from a log's /tf_static; a node reads no tf
            raise UserError(
                robot.source,
                "tf: the nodes read no /tf_static; give the camera's height_m and pitch_deg (and forward_m, yaw_deg) for them",
                field="camera",
            )
        Model.of(model).rules_with(robot.rules)  # a setting the model's rules cannot take is refused now, not at the first frame
        self.settings = RobotSettings(robot.stop, robot.limits, hold_s, ahead_s, robot.rules)
        self.hold_s, self.ahead_s = hold_s, ahead_s
        self.watchdog = watchdog or Watchdog()
        self.runtime: PlannerRuntime | None = None
        self.path = None if path is None else np.asarray(path, dtype=float)
        # (stamp [s], x [m], y [m], yaw [rad], z [m], pitch [rad], roll [rad])
        self.odometry: deque[tuple[float, float, float, float, float, float, float]] = deque()
        # The depth images held for the label images near their stamps (None: the robot file names no depth topic).
        self.depth: DepthPairing[np.ndarray] | None = DepthPairing(DEPTH_KEPT) if robot.depth_topic else None
        depth_info = robot.topics.get("depth_info")
        self.depth_info_topic = depth_info if depth_info not in (None, robot.topics["camera_info"]) else None
        self._info = self._depth_info = None  # the first calibrations of the label and the depth camera
        self.skipped = {
            "before the calibration or the path": 0,
            "without odometry at the stamp": 0,
            NO_DEPTH: 0,
            "out of order": 0,
            "superseded while waiting for odometry or depth": 0,
            "paths of fewer than two distinct points": 0,
            "odometry ahead of the clock": 0,
            "images ahead of the clock": 0,
            BEFORE_CLOCK: 0,
            "calibrations of another size": 0,
            "depth images ahead of the clock": 0,
            "depth images of another encoding or size": 0,
        }
        self.decided = 0  # frames decided on
        self.on_decision: Callable[[RuntimeDecision], None] | None = None  # told of every decision, whichever message brought it
        self.on_problem: Callable[[str], None] = lambda line: None  # told why a frame is skipped, where the log should say it
        # Images waiting for odometry or a depth image at their stamps, oldest first.
        self._pending: list[tuple[str, object, str, float]] = []
        self._lut: np.ndarray | None = None  # the robot's label ids -> class ids, once the calibration has come
        self._undistort: np.ndarray | None = None  # a distorted lens's pinhole pixel -> its pixel (flat; -1 outside)
        self._lock = threading.RLock()  # ROS calls back from a thread per topic
        self.view: LiveView | None = None
        self._live: LiveRun | None = None

    def watch(self, view: LiveView) -> None:
        """Send every decision to the live view ``view`` (terrapref.interop.live), with the frame,
        the pose and the command, and once a second the costmap."""
        self.view, self._live = view, None

    @property
    def lock(self) -> threading.RLock:
        """The lock every message handler holds (re-entrant): a node that sends commands from a
        timer as well as from decisions holds it too, so that the two never cross."""
        return self._lock

    @property
    def ready(self) -> bool:
        """Whether frames can be decided on: the calibration (and a depth camera's of its own,
        where the robot file names one, checked against it) and the path have come."""
        return self.runtime is not None and self.path is not None and (self.depth_info_topic is None or self._depth_info is not None)

    def on_camera_info(self, info) -> None:
        """The first calibration makes the planner; a model for another camera is refused
        (UserError). A later one of another image size than the planner's is refused
        (ValueError, counted): the planner keeps the calibration it was made with."""
        with self._lock:
            if self.runtime is not None:
                h, w = self.runtime.shape
                if (int(info.width), int(info.height)) != (w, h):
                    self.skipped["calibrations of another size"] += 1
                    raise ValueError(f"a camera_info of another image size than the {w} x {h} px the planner was made with; ignored")
                return
            camera, self._undistort = camera_from_info(info, self.robot, self.robot.source)
            check_depth_info(self._depth_info, info, self.robot, self.robot.source)
            self._info = info
            # fed class ids, mapped and undistorted here
            runtime = PlannerRuntime(self.model, camera, robot=self.settings)
            if runtime.model.reads_relief and "depth" not in self.robot.topics:  # said at the start, where the node logs its notes
                runtime.notes.append(f"{FLAT_NOTE} ({self.robot.source} names no topics.depth)")
            labels = self.robot.labels
            # An id the label map does not list becomes one the class table does not name, and is refused with it.
            self._lut = labels.lut(self.model.classes, UNKNOWN if labels.unlisted == "unknown" else runtime.foreign.unnamed)
            self.runtime = runtime
            if self.path is not None:
                self.runtime.set_path(self.path)

    def on_depth_info(self, info) -> None:
        """The depth camera's calibration, where the robot file names one of its own: the first is
        checked against the label camera's (now, or when that comes): a depth camera of another
        size or intrinsics is refused (UserError), for its images are not registered to the
        label images. Frames wait for it (:attr:`ready`)."""
        with self._lock:
            if self._depth_info is not None:
                return
            if self._info is not None:
                check_depth_info(info, self._info, self.robot, self.robot.source)
            self._depth_info = info

    def on_depth(self, msg, topic: str = "", now_s: float | None = None) -> RuntimeDecision | None:
        """A depth image (sensor_msgs/Image 32FC1 [m] or 16UC1 [mm], REP 118), held for the label
        images near its stamp; the decision on an image that waited for it, if one did. One
        before the calibration is let go (its size cannot be checked yet).

        Raises:
            UserError: another encoding, or another size than the label camera's (counted).
            ValueError: stamped more than ``ahead_s`` ahead of the node's clock ``now_s`` (counted):
                kept, it would be the newest for ever and no label image would wait for a nearer one.
        """
        with self._lock:
            if self.depth is None or self.runtime is None:
                return None
            t = stamp_s(msg.header)
            if self._ahead(t, now_s, "depth images"):
                raise ValueError(
                    f"{topic}: a depth image stamped more than {self.ahead_s:g} s ahead of the node's clock; refused "
                    "(another clock, or use_sim_time unset while a log plays?)"
                )
            try:
                depth = registered_depth(msg, topic, self.robot.source, self.runtime.shape)
            except UserError:
                self.skipped["depth images of another encoding or size"] += 1
                raise
            self.depth.put(t, depth)
            return self._resume()

    def on_path(self, msg) -> str | None:
        """A nav_msgs/Path of two distinct points or more (re)sets the reference path; another is
        skipped (counted), and what is wrong with it returned, for the node to say."""
        with self._lock:
            xy = path_xy(msg)
            try:
                ReferencePath(xy)
            except ValueError:  # fewer than two distinct finite points: the path in force stays
                self.skipped["paths of fewer than two distinct points"] += 1
                finite = np.isfinite(xy).all()
                why = "with a point that is not a number" if not finite else f"of {len(xy)} pose(s), fewer than two distinct points"
                stays = "the path in force stays" if self.path is not None else "no path yet: nothing is commanded"
                return f"a path {why}; {stays}"
            if self.path is not None and np.array_equal(xy, self.path):
                return None  # the path in force, sent again (a planner's periodic plan, a latched topic heard twice): the progress along it stays
            self.path = xy
            self._live = None  # the live view shows a new run along the new path
            if self.runtime is not None:
                self.runtime.set_path(xy)
            return None

    def on_odometry(self, msg, now_s: float | None = None) -> RuntimeDecision | None:
        """nav_msgs/Odometry, or a PoseStamped / PoseWithCovarianceStamped; the decision on an
        image that waited for it, if one did.

        With ``now_s``, the node's clock [s] (None before it runs), a pose stamped more than
        ``ahead_s`` ahead of it is refused (ValueError, counted): kept, it would
        make every later pose look older than the newest and be dropped.
        """
        with self._lock:
            p = msg.pose.pose if hasattr(msg.pose, "pose") else msg.pose
            t = stamp_s(msg.header)
            if self._ahead(t, now_s, "odometry"):
                raise ValueError(
                    f"odometry stamped more than {self.ahead_s:g} s ahead of the node's clock (another clock, or "
                    "use_sim_time unset while a log plays?)"
                )
            if self.odometry and t < self.odometry[-1][0]:
                return None  # an older pose than one kept: odometry arrives in order or not at all
            turn, _ = unit_quaternion(p.orientation)  # one not of unit length is normalised, as tf2 does
            if turn is None:
                raise ValueError("odometry whose orientation is a zero or non-finite quaternion (no heading); skipped")
            # The body's height, pitch and roll beside the pose, as import keeps them: a planar odometry's are level.
            tilt = (float(p.position.z), *pitch_roll_rad(turn))
            tilt = tuple(a if math.isfinite(a) else 0.0 for a in tilt)
            self.odometry.append((t, float(p.position.x), float(p.position.y), yaw_rad(turn), *tilt))
            while self.odometry and self.odometry[0][0] < t - ODOMETRY_KEPT_S:
                self.odometry.popleft()
            return self._resume()

    def _resume(self) -> RuntimeDecision | None:
        """The decision on the newest image waiting whose wait is over (odometry at or past its
        stamp, and on a robot with depth, a depth image at or past it, or none still worth waiting
        for); the images older than it are superseded, the newer ones wait on."""
        ready = [
            i
            for i, (_, _, _, t) in enumerate(self._pending)
            if self.odometry and self.odometry[-1][0] >= t and not self._waits_for_depth(t)
        ]
        if not ready:
            return None
        i = ready[-1]
        self.skipped["superseded while waiting for odometry or depth"] += i
        (msgtype, image, topic, stamp), self._pending = self._pending[i], self._pending[i + 1 :]
        pose = self.pose_at(stamp)
        if pose is None:
            self.skipped["without odometry at the stamp"] += 1
            return None
        return self._decide(msgtype, image, topic, stamp, pose)

    def _waits_for_depth(self, t: float) -> bool:
        """Whether an image stamped ``t`` [s] waits for a depth image nearer its stamp than those
        held: none at or past its stamp has come yet, and the newest is at most
        :data:`DEPTH_WAIT_S` older (a depth stream that stopped is not waited for)."""
        depth = self.depth
        return depth is not None and depth.newest_s is not None and not depth.settled(t) and t - depth.newest_s <= DEPTH_WAIT_S

    def _odometry_at(self, t: float) -> tuple[float, ...] | None:
        """The odometry (x, y, yaw, z, pitch, roll) interpolated to ``t`` [s]; None outside what is
        kept or across a gap."""
        if not self.odometry:
            return None
        times = np.array([o[0] for o in self.odometry])
        j = int(np.searchsorted(times, t, side="right"))
        if j == 0 or (j == len(times) and t > times[-1]):
            return None
        if j == len(times) or times[j - 1] == t:
            return self.odometry[j - 1][1:]
        before, after = self.odometry[j - 1], self.odometry[j]
        if after[0] - before[0] > self.robot.max_gap_s:
            return None
        f = (t - before[0]) / (after[0] - before[0])
        x, y, _, z, pitch, roll = (a + f * (b - a) for a, b in zip(before[1:], after[1:]))
        return x, y, before[3] + f * wrap_angle(after[3] - before[3]), z, pitch, roll

    def _ahead(self, t: float, now_s: float | None, inputs: str) -> bool:
        """Whether a stamp ``t`` [s] lies more than ``ahead_s`` past the node's clock ``now_s`` (None or
        0: not running yet), counted as one of the ``inputs`` ahead of the clock if it does."""
        if now_s is not None and now_s > 0 and t > now_s + self.ahead_s:
            self.skipped[f"{inputs} ahead of the clock"] += 1
            return True
        return False

    def pose_at(self, t: float) -> Pose | None:
        """The odometry interpolated to ``t`` [s]; None outside what is kept or across a gap."""
        at = self._odometry_at(t)
        return None if at is None else Pose(*at[:3])

    def attitude_at(self, t: float) -> Attitude | None:
        """The body's height [m], pitch and roll [rad] by the odometry, interpolated to ``t`` [s]
        (its ``position.z`` and orientation, as import reads them); None where :meth:`pose_at` is."""
        at = self._odometry_at(t)
        return None if at is None else Attitude(*at[3:])

    def speed_at(self, t: float) -> float | None:
        """The robot's forward speed [m/s] at ``t`` [s]: its odometry's motion along its heading
        over the :data:`SPEED_WINDOW_S` before ``t``; None where odometry does not span it."""
        now, before = self.pose_at(t), self.pose_at(t - SPEED_WINDOW_S)
        if now is None or before is None:
            return None
        return odometry_speed_mps(now, before)

    def on_image(self, msgtype: str, msg, topic: str = "", now_s: float | None = None) -> RuntimeDecision | None:
        """A label image (``sensor_msgs/msg/Image`` or ``.../CompressedImage``): the decision on
        it, or None when it is skipped (counted in :attr:`skipped`) or waits for odometry.

        An image newer than the last odometry (they travel on separate topics and either may
        come first) waits until odometry at or past its stamp arrives (:meth:`on_odometry` then
        decides on the newest image whose wait is over, and drops the older ones), for up to
        :data:`ODOMETRY_WAIT_S`; up to :data:`PENDING_KEPT` images wait at once. On a robot
        with depth it waits the same way for a depth image at or past its stamp, while the
        newest depth image is at most :data:`DEPTH_WAIT_S` older (:meth:`on_depth` then decides
        on it, with the nearest one within :data:`DEPTH_PAIRING_S`); with none that near it is
        skipped (counted). With ``now_s``, the node's clock [s], an image stamped ahead of it by
        more than the runtime allows is refused (ValueError, counted); a clock of 0 is a simulated
        one that has not ticked yet (ROS's time before the first ``/clock``), and the image is
        skipped (counted): the command decided on it could not be timed, and would be refused as
        lying in the clock's future. None: no clock to check against.
        """
        with self._lock:
            if not self.ready:
                self.skipped["before the calibration or the path"] += 1
                return None
            if now_s == 0.0:
                self.skipped[BEFORE_CLOCK] += 1
                return None
            t = stamp_s(msg.header)
            if self._ahead(t, now_s, "images"):
                raise ValueError(
                    f"an image stamped {t - now_s:.3g} s ahead of the node's clock; refused (another clock, or use_sim_time unset while a log plays?)"
                )
            pose = self.pose_at(t)
            if pose is None and self.odometry and t < self.odometry[0][0] - ODOMETRY_KEPT_S:  # not late: on another clock
                raise ValueError(
                    f"a label image stamped {self.odometry[-1][0] - t:.3g} s before the newest odometry (stamped 0, or on another "
                    "clock than the odometry's?); skipped"
                )
            if pose is None and not (self.odometry and 0 < t - self.odometry[-1][0] <= ODOMETRY_WAIT_S):
                self.skipped["without odometry at the stamp"] += 1
                return None
            if pose is not None and not self._waits_for_depth(t):
                older = [p for p in self._pending if p[3] <= t]  # decided on a newer image, the runtime would ignore them
                self.skipped["superseded while waiting for odometry or depth"] += len(older)
                self._pending = [p for p in self._pending if p[3] > t]
                return self._decide(msgtype, msg, topic, t, pose)
            self._pending = sorted([*self._pending, (msgtype, msg, topic, t)], key=lambda p: p[3])
            if len(self._pending) > PENDING_KEPT:  # the oldest gives way
                self.skipped["superseded while waiting for odometry or depth"] += len(self._pending) - PENDING_KEPT
                self._pending = self._pending[-PENDING_KEPT:]
            return None

    def _decide(self, msgtype: str, msg, topic: str, t: float, pose: Pose) -> RuntimeDecision | None:
        depth = None
        if self.depth is not None:
            paired = self.depth.nearest(t)
            if paired is None:
                self.skipped[NO_DEPTH] += 1
                self.on_problem(
                    f"{self.robot.depth_topic}: a label image {NO_DEPTH} of its stamp: skipped, and the robot stops (stale) while they are"
                )
                return None
            depth = DepthFrame(undistorted(paired[1], self._undistort, np.float32(np.nan)), self.attitude_at(t))
        # No time in the error: a node says each problem once, and a stream of bad frames is one problem.
        raw = label_ids(msg, msgtype, topic, self.robot.source, self.robot.labels)
        if raw.shape != self.runtime.shape:
            raise UserError(
                self.robot.source,
                f"a label image of {raw.shape[1]} x {raw.shape[0]} px; the calibration says "
                f"{self.runtime.shape[1]} x {self.runtime.shape[0]}",
                field="topics.segmentation",
            )
        ids = self._lut[raw]
        if self.runtime.foreign(ids):
            raise UserError(
                self.robot.labels.source or self.robot.source,
                unlisted_message(self.robot.labels.unlisted_in(raw), "a label image"),
                field="ids",
            )
        ids = undistorted(ids, self._undistort, UNKNOWN)  # a lens with distortion: each pinhole pixel from where the lens put it
        decision = self.runtime.decide(ids, t, pose, self.speed_at(t), depth=depth)
        if decision is None:
            self.skipped["out of order"] += 1
            return None
        self.decided += 1
        self.watchdog.feed()
        # The command goes out first: the live view's frame (a server started on the first) must
        # neither delay it nor, by the wall clock, make the watchdog call the decision stale.
        if self.on_decision is not None:
            self.on_decision(decision)
        if self.view is not None:
            self._send(decision, ids, pose)
        return decision

    def _send(self, decision: RuntimeDecision, ids: np.ndarray, pose: Pose) -> None:
        """One decision to the live view, stamped with its frame's ROS time."""
        from terrapref.interop.live import LiveRun
        from terrapref.interop.mcap_export import FrameData
        from terrapref.interop.ros_messages import EPOCH_S

        runtime, model = self.runtime, self.model
        if self._live is None:
            self._live = LiveRun.start(
                self.view, self.path, runtime.planner.camera.config, model.classes, model.features.preference, clock_s=EPOCH_S
            )
        self._live.frame(
            FrameData(
                decision.stamp_s,
                (pose.x, pose.y, pose.yaw),
                (float(decision.command.v), float(decision.command.w)),
                ids,
                decision.index,
                decision.probs,
                stop=decision.stop,
            ),
            self.costmap,
        )

    def command_at(self, now_s: float) -> Command:
        """The command to send now: the last decision's while fresh, else a stop."""
        return self.status_at(now_s)[0]

    def status_at(self, now_s: float) -> tuple[Command, str | None]:
        """The command to send now and why it stops (None while it drives; ``stale`` before any
        frame, and once none has been decided on for the watchdog's limit by the wall clock)."""
        with self._lock:
            if self.runtime is None:
                return Command(0.0, 0.0), STALE
            command, reason = self.runtime.status_at(now_s)
            return (Command(0.0, 0.0), STALE) if self.watchdog.barks(self.runtime.planner.stop_rule.stale) else (command, reason)

    @property
    def arrived(self) -> bool:
        """Whether the planner stands at the end of its path (its goal: terrapref.planner.goal)."""
        with self._lock:
            return self.runtime is not None and self.runtime.planner.goal.reached

    def costmap(self) -> Costmap | None:
        """The learned preference over the ground seen, when the planner keeps a ground map."""
        with self._lock:
            if self.runtime is None or not self.runtime.planner.runner.keeps_ground_map:
                return None
            return self.runtime.costmap()


# The parameters that set the robot's limits and when it stops, over its robot file's (None: the file's).
ROBOT_PARAMETERS = (*LIMITS, "goal_tolerance_m", "goal_yaw_tolerance_deg", "off_path_m")


def nested_rule_params(get_param: Callable[[str, Any], Any], prefix: str = "~") -> dict[str, Any]:
    """The rule settings of a parameter server that nests them (ROS 1: ``~offset/switch_margin``,
    read as ``get_param("~offset")``, a dict), flat as ``RULE.NAME[.CLASS]`` -> value."""
    flat: dict[str, Any] = {}
    for rule in [*(r for r in RULES if RULES[r].settable), "stop"]:
        named = get_param(f"{prefix}{rule}", None)
        if named is None:
            continue
        if not isinstance(named, Mapping):
            raise UserError(f"{prefix}{rule}", f"expected the {rule} rule's settings by name, got {named!r}")
        for name, value in named.items():
            items = value.items() if isinstance(value, Mapping) else [(None, value)]
            flat |= {f"{rule}.{name}" + ("" if c is None else f".{c}"): v for c, v in items}
    return flat


@dataclass(frozen=True)
class NodeOptions:
    """How a node runs: each from the command line (``hold_s``, ``watchdog_s`` and the robot's
    parameters have no flag), else from the node's ROS parameter of the same name (ROS 1: the
    private ``~stamped``, ``~rate``, ``~path_file``, ``~cmd_topic``, ``~hold_s``, ...; ROS 2:
    ``-p stamped:=true`` and so on), else the default.

    Attributes:
        stamped: publish TwistStamped instead of Twist (default False).
        rate: commands per second between decisions [Hz] (default 20).
        path_file: waypoints of the reference path, instead of the path topic.
        cmd_topic: where the command goes (default: the robot file's command topic).
        hold_s: how long a decision's command holds after its frame's stamp [s] (default 0.3).
        watchdog_s: a stop once no frame has been decided on for this long by the wall clock [s]
            (default 1).
        max_speed_mps, max_yaw_rate_rps, max_accel_mps2, max_roll_deg, max_pitch_deg, max_step_m:
            the robot's limits (robot file ``limits``).
        goal_tolerance_m, goal_yaw_tolerance_deg, off_path_m: the goal check's settings (robot file ``stop``).
        rules: the robot's settings of the model's rules, given over the robot file's ``rules``
            (ROS 2: ``-p offset.switch_margin:=0.3``; ROS 1: ``~offset/switch_margin``;
            terrapref.rules.settings); read by each transport (:meth:`with_rule_params`).
        stop: the stop rule's settings given the same way (``stop.decel_mps2`` and so on: its
            stopping distance), over the robot file's ``stop`` block.
    """

    stamped: bool | None = None
    rate: float | None = None
    path_file: str | None = None
    cmd_topic: str | None = None
    hold_s: float | None = None
    watchdog_s: float | None = None
    max_speed_mps: float | None = None
    max_yaw_rate_rps: float | None = None
    max_accel_mps2: float | None = None
    max_roll_deg: float | None = None
    max_pitch_deg: float | None = None
    max_step_m: float | None = None
    goal_tolerance_m: float | None = None
    goal_yaw_tolerance_deg: float | None = None
    off_path_m: float | None = None
    rules: RuleSettings = field(default_factory=RuleSettings)
    stop: tuple[tuple[str, float | None], ...] = ()

    def with_rule_params(self, flat: Mapping[str, Any], origin: str) -> NodeOptions:
        """These options with the rule settings ``flat`` gives (``RULE.NAME`` or
        ``RULE.NAME.CLASS`` -> value; ``stop.NAME`` for the stop rule's, over the robot file's
        ``stop`` block), checked by name and kind (a UserError naming ``origin`` and the
        parameter); their ranges are checked against the model when the node starts."""
        stop = {k: v for k, v in flat.items() if str(k).startswith("stop.")}
        rules = {k: v for k, v in flat.items() if k not in stop}
        names = [f.name for f in fields(StopConfig)]
        for key, value in stop.items():
            name = str(key).removeprefix("stop.")
            if name not in names:
                raise UserError(origin, f"the stop rule has no setting {name!r}; its settings: {', '.join(names)}", field=str(key))
            problem = stop_value_problem(name, value)
            if problem is not None:
                raise UserError(origin, f"{problem}, got {described(value)}", field=str(key))
        given = tuple((str(k).removeprefix("stop."), v) for k, v in stop.items())
        return replace(self, rules=RuleSettings.parse(rules, origin, RULES) if rules else self.rules, stop=self.stop + given)

    def resolved(self, get_param: Callable[[str, Any], Any], param: Callable[[str], str] = lambda name: f"~{name}") -> NodeOptions:
        """Every option set: the given ones, the rest from ``get_param(param(name), default)``
        (rospy's ``get_param`` with ``~name`` by default), checked (a bad value is a UserError
        naming the option and where it came from). The robot's parameters stay None where not
        given: the robot file's values hold."""
        defaults = {"stamped": False, "rate": 20.0, "path_file": None, "cmd_topic": None, "hold_s": 0.3, "watchdog_s": 1.0}
        defaults |= dict.fromkeys(ROBOT_PARAMETERS)
        values, origin = {}, {}
        for name, default in defaults.items():
            given = getattr(self, name)
            values[name], origin[name] = (
                (given, f"--{name.replace('_', '-')}") if given is not None else (get_param(param(name), default), param(name))
            )
        if not isinstance(values["stamped"], bool):
            raise UserError(origin["stamped"], f"expected true or false, got {values['stamped']!r}")
        for name, top in (("rate", 200.0), ("hold_s", 5.0), ("watchdog_s", 60.0)):
            v = values[name]
            if not (finite_number(v) and 0 < v <= top):
                raise UserError(origin[name], f"expected a number in (0, {top:g}], got {v!r}")
        if values["rate"] * values["hold_s"] < 1.0:  # the stop once a command's hold runs out goes out at the next tick
            raise UserError(
                origin["rate"],
                f"expected at least 1 / hold_s = {1.0 / values['hold_s']:g} Hz, so that a command held {values['hold_s']:g} s "
                f"after its frame is followed by a stop within a tick; got {values['rate']!r}",
            )
        for name in ROBOT_PARAMETERS:  # a limit within its range (as a robot file's), the stop's settings > 0
            v = values[name]
            if name in LIMITS:
                problem = limit_problem(name, v) if v is not None else None
            else:
                problem = None if v is None or (finite_number(v) and v > 0) else f"expected a number > 0, got {v!r}"
            if problem is not None:
                raise UserError(origin[name], problem)
        for name in ("path_file", "cmd_topic"):
            if values[name] is not None and (not isinstance(values[name], str) or not values[name]):
                raise UserError(origin[name], f"expected a non-empty string, got {values[name]!r}")
        if values["cmd_topic"] is not None and not GIVEN_TOPIC_NAME.match(values["cmd_topic"]):
            raise UserError(
                origin["cmd_topic"], f"expected a ROS topic name (letters, digits and _ between slashes), got {values['cmd_topic']!r}"
            )
        resolved = NodeOptions(**values, rules=self.rules, stop=self.stop)
        resolved._settings(StopConfig(), VehicleConfig(), origin)  # checked together now, over the defaults
        return resolved

    def applied_to(self, robot: RobotConfig) -> RobotConfig:
        """``robot`` with the robot's parameters given here in place of its file's (checked
        together: a goal tolerance beyond the off-path distance is a UserError naming them)."""
        stop, limits = self._settings(robot.stop, robot.limits, {})
        try:
            stop = replace(stop, **dict(self.stop))
        except ValueError as exc:
            raise UserError(", ".join(f"stop.{name}" for name, _ in self.stop), str(exc)) from None
        rules = self.rules.over(robot.rules) if self.rules else robot.rules
        same = (stop, limits, rules) == (robot.stop, robot.limits, robot.rules)
        return robot if same else replace(robot, stop=stop, limits=limits, rules=rules)

    def _settings(self, stop: StopConfig, limits: VehicleConfig, origin: dict[str, str]) -> tuple[StopConfig, VehicleConfig]:
        """``stop`` and ``limits`` with the robot's parameters given here in their place."""
        given = {name: getattr(self, name) for name in ROBOT_PARAMETERS if getattr(self, name) is not None}
        for name in LIMITS:
            problem = limit_problem(name, given[name]) if name in given else None
            if problem is not None:
                raise UserError(origin.get(name, name), problem)
        stop_names = {f.name for f in fields(StopConfig)}
        try:
            return (
                replace(stop, **{k: v for k, v in given.items() if k in stop_names}),
                replace(limits, **{k: v for k, v in given.items() if k in LIMITS}),
            )
        except ValueError as exc:
            raise UserError(", ".join(origin.get(name, name) for name in given), str(exc)) from None

    def command_topic(self, robot: RobotConfig) -> str:
        """Where the command goes: ``cmd_topic``, else the robot file's command topic (a robot file
        may leave it out: its logs are then labelled by odometry); neither is a UserError."""
        topic = self.cmd_topic or robot.command_topic
        if topic is None:
            raise UserError(
                robot.source,
                "names no command topic for the node to publish on: give --cmd-topic (ROS parameter cmd_topic) or topics.command",
                field="topics.command",
            )
        return topic


_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?|\b(?:nan|inf)\b", re.IGNORECASE)  # a number in a problem's words


class NodeLog:
    """What a node says about its work, whatever its transport: each problem with an incoming
    message once (such messages are skipped, not a traceback per frame), and each time the
    planner stops or moves on, with the reason.

    Args:
        info, warn, error: the transport's logging calls, each taking one line.
        prefix: what each line starts with (ROS 2's log lines name the node already).
    """

    def __init__(
        self, info: Callable[[str], None], warn: Callable[[str], None], error: Callable[[str], None], prefix: str = "terrapref: "
    ) -> None:
        self.info, self.warn, self.error, self.prefix = info, warn, error, prefix
        self.said: set[str] = set()
        self.stop_reason: str | None = None  # why the command in force stops (None: it drives)
        self.refused = 0  # messages skipped for a problem said (guarded)

    def say(self, problem: str) -> None:
        """``problem`` with an incoming message, logged the first time only: the first time a
        problem of its kind comes, that is, the same words with other numbers in them (a pose
        from the future, each a little further ahead, is one problem)."""
        kind = _NUMBER.sub("#", problem)
        if kind not in self.said:
            self.said.add(kind)
            self.error(f"{self.prefix}{problem} (said once; such messages are skipped)")

    def guarded(self, handle: Callable[[], Any]) -> Any:
        """Handle one message; one the node cannot use (an image it cannot decode, of the wrong
        size, a pose from the future) is skipped and said once."""
        try:
            return handle()
        except (UserError, ValueError) as exc:
            self.refused += 1
            self.say(exc.lines()[0] if isinstance(exc, UserError) else str(exc))
            return None

    def status(self, reason: str | None) -> None:
        """The reason the command in force stops (None: it drives); a change is logged."""
        if reason != self.stop_reason:
            self.stop_reason = reason
            if reason is None:
                self.info(f"{self.prefix}moving on")
            else:
                self.warn(f"{self.prefix}stopping: {reason} ({REASONS.get(reason, reason)})")


def limits_line(robot: RobotConfig, watchdog_s: float) -> str:
    """What the node holds the robot to, the line it logs at its start."""
    limits, stop = robot.limits, robot.stop
    return (
        f"limits: {limits.max_speed_mps:g} m/s, {limits.max_yaw_rate_rps:g} rad/s"
        + (f", speeding up at {limits.max_accel_mps2:g} m/s^2 at most" if limits.max_accel_mps2 is not None else "")
        + f"; on relief {limits.max_roll_deg:g} deg of roll, {limits.max_pitch_deg:g} of pitch, a step of {limits.max_step_m:g} m"
        + f"; at the goal within {stop.goal_tolerance_m:g} m"
        + (f" and {stop.goal_yaw_tolerance_deg:g} deg" if stop.goal_yaw_tolerance_deg is not None else "")
        + f"; off the path beyond {stop.off_path_m:g} m; brakes at {stop.decel_mps2:g} m/s^2 {stop.reaction_s:g} s after a frame,"
        + f" {stop.margin_m:g} m short; stops {watchdog_s:g} s after its last decision by the wall clock"
    )


def report_line(core: PlannerNodeCore, command: str, log: NodeLog | None = None) -> str:
    """The line a node prints when it ends: frames decided on, and those skipped and why (with
    the node's ``log``, the messages it refused for a problem it said)."""
    counts = [f"{n} {why}" for why, n in core.skipped.items() if n]
    if log is not None and log.refused:
        counts.append(f"{log.refused} message{'s' if log.refused != 1 else ''} refused (the log says why)")
    return f"terrapref {command}: {core.decided} frames decided on; skipped: {', '.join(counts) or 'none'}"


class TrajectoryShapes:
    """The trajectories of a model's preference set as a node draws them: line strips in
    base_link, shaded by F_t, the chosen one thick and green.

    Attributes:
        paths: (m, n, 2) the trajectories' points in base_link [m].
    """

    def __init__(self, model: LoadedModel) -> None:
        from terrapref.features.preference_set import forward_simulate

        pref = model.features.preference
        c = pref.control
        self.paths = forward_simulate(np.full(c.m, c.v_mps), np.asarray(c.w_rps), pref.n_steps, pref.dt_s)[..., :2]

    def styles(self, decision: RuntimeDecision) -> list[tuple[float, tuple[float, float, float, float]]]:
        """Per trajectory, its line width [m] and colour (r, g, b, a) for ``decision``."""
        top = float(np.max(decision.probs)) or 1.0
        return [
            (0.06, (0.1, 0.9, 0.2, 1.0)) if j == decision.index else (0.03, (1.0, 1.0, 1.0, 0.2 + 0.8 * float(decision.probs[j]) / top))
            for j in range(len(self.paths))
        ]
