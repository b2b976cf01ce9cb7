"""What a ROS node of the planner does with its messages, without ROS (the ROS 1 node and the
rclpy node of docs/robot.md both wrap it).

Messages come in as they would from rospy or rclpy (attribute access: ``header.stamp``,
``pose.pose``, ``data``, ...). The calibration makes the planner (a model trained for another
camera is refused); odometry is kept for the last seconds and interpolated to each image's
stamp; the reference path comes from a Path message or a waypoint file; each label image is
decoded through the robot file's label map and decided on by :class:`PlannerRuntime`, which
ignores frames older than the last one and holds a command for ``hold_s`` after its frame.
"""

from __future__ import annotations

import math
import threading
from collections import deque
from collections.abc import Callable
from types import SimpleNamespace
from typing import TYPE_CHECKING

import numpy as np

from terrapref.errors import UserError
from terrapref.interop.bag_import import _decode, _yaw, camera_from_info
from terrapref.interop.robot import RobotConfig
from terrapref.interop.labels import unlisted_message
from terrapref.interop.runtime import PlannerRuntime, RuntimeDecision
from terrapref.learning.model_file import LoadedModel
from terrapref.planner.costmap import Costmap
from terrapref.scenario.path import ReferencePath
from terrapref.stops import STALE
from terrapref.terrain import UNKNOWN
from terrapref.vehicle import Command, Pose

if TYPE_CHECKING:
    from terrapref.interop.live import LiveRun, LiveView

ODOMETRY_KEPT_S = 5.0  # how far back odometry is kept for interpolating to an image's stamp [s]
ODOMETRY_WAIT_S = 0.5  # how long an image newer than the odometry waits for it [s]


def stamp_s(header) -> float:
    """A header's stamp [s] (ROS 1's ``secs``/``nsecs`` or ROS 2's ``sec``/``nanosec``)."""
    stamp = header.stamp
    sec = getattr(stamp, "sec", None)
    if sec is None:
        sec = stamp.secs
    nsec = getattr(stamp, "nanosec", None)
    if nsec is None:
        nsec = stamp.nsecs
    return int(sec) + int(nsec) * 1e-9


class PlannerNodeCore:
    """The planner behind a ROS node: messages in, decisions, commands and costmaps out.

    Args:
        model: the model the node drives with.
        robot: the robot file (topics, camera mounting, label map, the odometry's gaps).
        path: the reference path (N, 2) [m] in the odometry frame, when it comes from a file;
            otherwise the first Path message sets it.
        hold_s: how long a decision's command stays in force after its frame's stamp [s].
    """

    def __init__(self, model: LoadedModel, robot: RobotConfig, path: np.ndarray | None = None, hold_s: float = 0.3) -> None:
        self.model, self.robot, self.hold_s, self.stop = model, robot, hold_s, robot.stop
        self.runtime: PlannerRuntime | None = None
        self.path = None if path is None else np.asarray(path, dtype=float)
        self.odometry: deque[tuple[float, float, float, float]] = deque()  # (stamp [s], x, y, yaw)
        self.skipped = {"before the calibration or the path": 0, "without odometry at the stamp": 0, "out of order": 0,
                        "superseded while waiting for odometry": 0, "paths of fewer than two distinct points": 0}
        self.decided = 0  # frames decided on
        self.on_decision: Callable[[RuntimeDecision], None] | None = None  # told of every decision, whichever message brought it
        self._pending: tuple[str, object, str, float] | None = None  # an image waiting for odometry at its stamp
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
    def ready(self) -> bool:
        return self.runtime is not None and self.path is not None

    def on_camera_info(self, info) -> None:
        """The first calibration makes the planner; a model for another camera is refused (UserError)."""
        with self._lock:
            if self.runtime is not None:
                return
            camera, self._undistort = camera_from_info(info, self.robot, self.robot.source)
            runtime = PlannerRuntime(self.model, camera, hold_s=self.hold_s, stop=self.stop)  # fed class ids, mapped and undistorted here
            labels = self.robot.labels
            # An id the label map does not list becomes one the class table does not name, and is refused with it.
            self._lut = labels.lut(self.model.classes, UNKNOWN if labels.unlisted == "unknown" else runtime.foreign.unnamed)
            self.runtime = runtime
            if self.path is not None:
                self.runtime.set_path(self.path)

    def on_path(self, msg) -> None:
        """A nav_msgs/Path of two distinct points or more (re)sets the reference path; another is skipped (counted)."""
        with self._lock:
            xy = np.array([(p.pose.position.x, p.pose.position.y) for p in msg.poses], dtype=float).reshape(-1, 2)
            try:
                ReferencePath(xy)
            except ValueError:  # fewer than two distinct finite points: the path in force stays
                self.skipped["paths of fewer than two distinct points"] += 1
                return
            self.path = xy
            self._live = None  # the live view shows a new run along the new path
            if self.runtime is not None:
                self.runtime.set_path(xy)

    def on_odometry(self, msg) -> RuntimeDecision | None:
        """nav_msgs/Odometry, or a PoseStamped / PoseWithCovarianceStamped; the decision on an
        image that waited for it, if one did."""
        with self._lock:
            p = msg.pose.pose if hasattr(msg.pose, "pose") else msg.pose
            t = stamp_s(msg.header)
            if self.odometry and t < self.odometry[-1][0]:
                return None  # an older pose than one kept: odometry arrives in order or not at all
            self.odometry.append((t, float(p.position.x), float(p.position.y), _yaw(p.orientation)))
            while self.odometry and self.odometry[0][0] < t - ODOMETRY_KEPT_S:
                self.odometry.popleft()
            if self._pending is None or self._pending[3] > t:
                return None
            (msgtype, image, topic, stamp), self._pending = self._pending, None
            pose = self.pose_at(stamp)
            if pose is None:
                self.skipped["without odometry at the stamp"] += 1
                return None
            return self._decide(msgtype, image, topic, stamp, pose)

    def pose_at(self, t: float) -> Pose | None:
        """The odometry interpolated to ``t`` [s]; None outside what is kept or across a gap."""
        if not self.odometry:
            return None
        times = np.array([o[0] for o in self.odometry])
        j = int(np.searchsorted(times, t, side="right"))
        if j == 0 or (j == len(times) and t > times[-1]):
            return None
        if j == len(times) or times[j - 1] == t:
            return Pose(*self.odometry[j - 1][1:])
        (t0, x0, y0, a0), (t1, x1, y1, a1) = self.odometry[j - 1], self.odometry[j]
        if t1 - t0 > self.robot.max_gap_s:
            return None
        f = (t - t0) / (t1 - t0)
        da = (a1 - a0 + math.pi) % (2 * math.pi) - math.pi
        return Pose(x0 + f * (x1 - x0), y0 + f * (y1 - y0), a0 + f * da)

    def on_image(self, msgtype: str, msg, topic: str = "") -> RuntimeDecision | None:
        """A label image (``sensor_msgs/msg/Image`` or ``.../CompressedImage``): the decision on
        it, or None when it is skipped (counted in :attr:`skipped`) or waits for odometry.

        An image newer than the last odometry (they travel on separate topics and either may
        come first) waits, the newest one only, until odometry at or past its stamp arrives
        (:meth:`on_odometry` then decides on it), for up to :data:`ODOMETRY_WAIT_S`.
        """
        with self._lock:
            if not self.ready:
                self.skipped["before the calibration or the path"] += 1
                return None
            t = stamp_s(msg.header)
            pose = self.pose_at(t)
            if pose is None:
                if self.odometry and 0 < t - self.odometry[-1][0] <= ODOMETRY_WAIT_S:
                    if self._pending is not None:
                        self.skipped["superseded while waiting for odometry"] += 1
                    if self._pending is None or t > self._pending[3]:  # the newest image waits
                        self._pending = (msgtype, msg, topic, t)
                else:
                    self.skipped["without odometry at the stamp"] += 1
                return None
            return self._decide(msgtype, msg, topic, t, pose)

    def _decide(self, msgtype: str, msg, topic: str, t: float, pose: Pose) -> RuntimeDecision | None:
        raw = _decode(SimpleNamespace(topic=topic, msgtype=msgtype), msg, self.robot.source, self.robot.labels, t)
        if raw.shape != self.runtime.shape:
            raise UserError(self.robot.source, f"a label image of {raw.shape[1]} x {raw.shape[0]} px; the calibration says "
                            f"{self.runtime.shape[1]} x {self.runtime.shape[0]}", field="topics.segmentation")
        ids = self._lut[raw]
        if self.runtime.foreign(ids):
            raise UserError(self.robot.labels.source or self.robot.source, unlisted_message(self.robot.labels.unlisted_in(raw), "a label image"),
                            field="ids")
        if self._undistort is not None:  # a lens with distortion: each pinhole pixel from where the lens put it
            ids = np.where(self._undistort >= 0, ids.reshape(-1)[np.maximum(self._undistort, 0)], UNKNOWN).astype(np.uint8)
        decision = self.runtime.decide(ids, t, pose)
        if decision is None:
            self.skipped["out of order"] += 1
            return None
        self.decided += 1
        if self.view is not None:
            self._send(decision, ids, pose)
        if self.on_decision is not None:
            self.on_decision(decision)
        return decision

    def _send(self, decision: RuntimeDecision, ids: np.ndarray, pose: Pose) -> None:
        """One decision to the live view, stamped with its frame's ROS time."""
        from terrapref.interop.live import LiveRun
        from terrapref.interop.mcap_export import FrameData
        from terrapref.interop.ros_messages import EPOCH_S

        runtime, model = self.runtime, self.model
        if self._live is None:
            self._live = LiveRun.start(self.view, self.path, runtime.planner.camera.config, model.classes, model.features.preference, clock_s=EPOCH_S)
        self._live.frame(FrameData(decision.stamp_s, (pose.x, pose.y, pose.yaw), (float(decision.command.v), float(decision.command.w)),
                                   ids, decision.index, decision.probs, stop=decision.stop), self.costmap)

    def command_at(self, now_s: float) -> Command:
        """The command to send now: the last decision's while fresh, else a stop."""
        return self.status_at(now_s)[0]

    def status_at(self, now_s: float) -> tuple[Command, str | None]:
        """The command to send now and why it stops (None while it drives; ``stale`` before any frame)."""
        with self._lock:
            return self.runtime.status_at(now_s) if self.runtime is not None else (Command(0.0, 0.0), STALE)

    def costmap(self) -> Costmap | None:
        """The learned preference over the ground seen, when the planner keeps a ground map."""
        with self._lock:
            if self.runtime is None or not self.runtime.planner.runner.keeps_ground_map:
                return None
            return self.runtime.costmap()
