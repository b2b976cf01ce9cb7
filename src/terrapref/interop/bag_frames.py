"""A robot log's streams synchronised into the frames of a recording.

The small topics (odometry, commands, the path, the camera's calibration, /tf_static) are read
whole into :class:`Streams`; the label images are then streamed one at a time
(:func:`stream_images`), so memory stays flat however large the log. Each kept image becomes a
frame (:class:`Frames`) whose pose is the odometry interpolated to the image's header stamp and
whose label is the operator's command in force at that stamp (zero-order hold: commands may come
at their own rate or only on change).

A robot file without ``topics.command`` labels each frame by the vehicle's measured motion (v, w)
instead (:class:`Motion`): an Odometry's twist (``twist.twist.linear.x``,
``twist.twist.angular.z``) interpolated to the stamp, or, for a pose topic (PoseStamped,
PoseWithCovarianceStamped) and for an Odometry whose twist is zero throughout while its pose
moves (a driver that never fills it), a centred difference of the poses around the stamp. The
report (:class:`ImportReport`) says which. A command topic the robot file names but
the bag lacks stays an error: a misspelt topic must not turn into a quiet fallback.

What real logs contain is handled and reported: topics at their own rates (images are thinned
to ``rate_hz``), stamp jitter, out-of-order images (a short reorder buffer; older stragglers are
dropped), gaps in odometry (frames inside a gap are skipped), label ids the label map does not
list (their share is reported), the operator stopped or reversing (no trajectory choice: skipped).
Each frame keeps the operator's command as it was logged (or the motion measured), at its own
speed (v, w), so that a speed rule learns the speeds driven; its label is the trajectory of the
preference set of the same curvature, at the set's speed: w x v_set / v.

With a depth topic (``topics.depth``), each label image is paired with the depth image of the
nearest header stamp, within :data:`DEPTH_PAIRING_S` (terrapref.interop.depth_pairing, the rule
the ROS nodes pair by too); a label image with none that near is skipped and counted, for a
frame whose ground cannot be placed is not the frames around it. Depth images
are read in the same pass as the label images and held only until the label images near their
stamps have been paired (:class:`DepthImages`). The frame then keeps the body's attitude at its
stamp: the odometry's height (``position.z``, taken as the ground's height under the robot: a
base frame above the ground raises every height alike, which slope and step do not see) and its
orientation's pitch and roll, interpolated; a planar odometry (z 0, no pitch or roll) gives a
level body.
"""

from __future__ import annotations

import heapq
import math
from collections import Counter
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np

from terrapref.camera import SegmentationView
from terrapref.demos.recording import RecordingWriter
from terrapref.errors import UserError
from terrapref.interop.bag_reader import Bag
from terrapref.interop.depth_pairing import DEPTH_PAIRING_S, DepthPairing
from terrapref.interop.labels import LabelMap
from terrapref.interop.robot import RobotConfig
from terrapref.interop.ros_decode import (
    label_ids,
    message_time_s,
    path_xy,
    pitch_roll_rad,
    registered_depth,
    static_transforms,
    undistorted,
    unit_quaternion,
    yaw_rad,
)
from terrapref.pngio import depth_to_millimetres, millimetres_to_depth
from terrapref.progress import Progress
from terrapref.terrain.classes import UNKNOWN
from terrapref.vehicle import ControlSet, wrap_angle
from terrapref.vehicle.ground import Attitude
from terrapref.vehicle.kinematics import POSE_DIFFERENCE_HALF_S, pose_velocities

REORDER_FRAMES = 16  # images held back to put slightly out-of-order stamps right
MIN_SPEED_MPS = 0.1  # slower than this the operator is stopped: no trajectory choice
STILL_TWIST_MOVED_M = 1.0  # an Odometry whose twist is zero throughout while its pose goes farther than this never filled it
SPEED_SOURCES = {  # where each frame's speed (v, w) comes from, as the report names it
    "commands": "the commands",
    "twist": "the odometry's twist",
    "poses": f"differences of odometry poses over {2 * POSE_DIFFERENCE_HALF_S:g} s",
}
CLOCK_TOLERANCE_S = 5.0  # header stamps this far from the log's receive times are on another clock (simulated time)
MAX_HEIGHT_M = 1e5  # an odometry pose higher or lower than this [m] is in other units, or garbage
DEPTH_HELD = 128  # depth images held at most while they wait for label images near their stamps (the newest kept)


@dataclass
class ImportReport:
    """What an import kept, skipped and noticed."""

    bag: str
    images: int = 0
    frames: int = 0
    skipped: Counter = field(default_factory=Counter)
    unmapped_share: float = 0.0  # pixels whose id the label map does not list
    unknown_share: float = 0.0  # pixels that are unknown after mapping (listed as unknown, or unlisted)
    image_gaps: int = 0
    longest_gap_s: float = 0.0
    path_source: str = ""
    order: str = ""  # the preference order the recording carries, and where it came from
    duration_s: float = 0.0
    speed_mps: tuple[float, float, float] | None = None  # the kept frames' slowest, mean and fastest speed [m/s]
    speed_source: str = "commands"  # a key of SPEED_SOURCES
    depth: str = ""  # the depth images the frames carry, and from where (empty: none)
    notes: list[str] = field(default_factory=list)

    def lines(self) -> list[str]:
        out = [f"images read      {self.images}", f"frames kept      {self.frames} ({self.duration_s:.1f} s)"]
        out += [f"skipped          {n} {reason}" for reason, n in sorted(self.skipped.items())]
        out.append(
            f"label ids        {100 * self.unmapped_share:.2f}% of pixels not in the label map; {100 * self.unknown_share:.1f}% unknown after mapping"
        )
        if self.image_gaps:
            out.append(
                f"image gaps       {self.image_gaps} longer than max_gap_s (longest {self.longest_gap_s:.2f} s); frames on either side kept"
            )
        if self.speed_mps is not None:
            slow, mean, fast = self.speed_mps
            out.append(f"speed            {mean:.2f} m/s on average ({slow:.2f}-{fast:.2f}), {self.speed_how}")
        if self.depth:
            out.append(f"depth            {self.depth}")
        out.append(f"path             {self.path_source}")
        out.append(f"order            {self.order}")
        out += [f"note             {n}" for n in self.notes]
        return out

    @property
    def speed_how(self) -> str:
        """Where the frames' speeds come from, in words."""
        if self.speed_source == "commands":
            return "kept as the commands give it"
        return f"measured by {SPEED_SOURCES[self.speed_source]} (no command topic)"


@dataclass
class Streams:
    """A log's small topics, read whole (:func:`read_small_topics`): each stream sorted by time,
    without non-finite samples."""

    odom_t: np.ndarray  # (N,) [s]
    odom: np.ndarray  # (N, 3) x, y [m], yaw [rad], unwrapped
    odom_twist: np.ndarray  # (N, 2) v [m/s], w [rad/s] of each pose as an Odometry's twist gives it; NaN: a pose without twist
    cmd_t: np.ndarray  # (M,) [s]
    cmd: np.ndarray  # (M, 2) v, w
    path: np.ndarray | None  # (K, 2) [m], the path topic's first path of two or more poses; None: none
    info: object  # the first camera_info
    static: dict[str, tuple[str, np.ndarray, np.ndarray]] = field(default_factory=dict)  # child -> (parent, t, R)
    receive_shift_s: float = 0.0  # added to a receive time to put it on the header stamps' clock
    odom_attitude: np.ndarray | None = None  # (N, 3) the body's z [m], pitch, roll [rad] at each pose (None: level)
    depth_info: object = None  # the depth topic's first camera_info (None: none named)
    notes: list[str] = field(default_factory=list)  # what reading them left out or put right, for the report


def read_small_topics(bag: Bag, robot: RobotConfig) -> Streams:
    """Odometry, commands, the path, the calibration and (for ``camera.tf``) /tf_static, read whole."""
    topics = robot.topics
    wanted = [role for role in ("odometry", "command", "camera_info", "path", "depth_info") if role in topics]
    if topics.get("depth_info") == topics["camera_info"]:  # the label camera's own calibration: nothing to compare
        wanted.remove("depth_info")
    by_role = {role: bag.connections(topics[role], role, robot.source) for role in wanted}  # each checked for its own type
    roles = {topics[role]: role for role in wanted}
    conns = list({id(c): c for cs in by_role.values() for c in cs}.values())
    if "tf" in robot.camera:
        tf_conns = [c for c in bag.reader.connections if c.topic == "/tf_static" and c.msgtype == "tf2_msgs/msg/TFMessage"]
        if not tf_conns:
            raise UserError(bag.source, "camera.tf asks for /tf_static, which the bag does not hold", field="camera.tf")
        roles["/tf_static"] = "tf_static"
        conns += tf_conns
    read = _SmallTopics()
    for conn, t_ns, msg in bag.messages(conns):
        role = roles[conn.topic]
        try:
            read.take(role, conn, t_ns, msg)
        except (AttributeError, TypeError, ValueError) as exc:
            raise UserError(
                bag.source, f"topic {conn.topic}: a {conn.msgtype} without the expected fields ({exc})", field=f"topics.{role}"
            ) from None
    if read.info is None:
        raise UserError(bag.source, f"topic {topics['camera_info']} holds no camera calibration", field="topics.camera_info")
    if len(read.odom_t) < 2:
        raise UserError(bag.source, f"topic {topics['odometry']} has fewer than two poses", field="topics.odometry")
    streams = read.checked(bag.source, topics["odometry"])
    if len(streams.odom_t) < 2:
        raise UserError(bag.source, f"topic {topics['odometry']} has fewer than two usable poses", field="topics.odometry")
    return streams


@dataclass
class _SmallTopics:
    """The small topics as they are read, in bag order."""

    odom_t: list[float] = field(default_factory=list)
    odom: list[tuple[float, float, float]] = field(default_factory=list)
    odom_twist: list[tuple[float, float]] = field(default_factory=list)
    odom_attitude: list[tuple[float, float, float]] = field(default_factory=list)  # z [m], pitch, roll [rad]
    cmd_t: list[float] = field(default_factory=list)
    cmd: list[tuple[float, float]] = field(default_factory=list)
    path: np.ndarray | None = None  # the first path of two or more poses
    info: object = None  # the first camera_info
    depth_info: object = None  # the depth topic's first camera_info
    static: dict[str, tuple[str, np.ndarray, np.ndarray]] = field(default_factory=dict)  # child -> (parent, t, R)
    stamp_minus_receive: list[float] = field(default_factory=list)  # of stamped odometry [s]
    stamped_received: list[float] = field(default_factory=list)  # when the log received each of those [s]
    cmd_received: list[bool] = field(default_factory=list)  # each command timed by receive time (Twist carries no stamp)
    unturned: int = 0  # poses whose quaternion is zero or not finite (left out)
    rescaled: int = 0  # poses whose quaternion was not of unit length (normalised)

    def take(self, role: str, conn, t_ns: int, msg) -> None:
        """Keep what ``msg`` (of ``role``, from ``conn``, at bag time ``t_ns`` [ns]) says."""
        if role == "odometry":
            pose = msg.pose.pose if conn.msgtype != "geometry_msgs/msg/PoseStamped" else msg.pose
            stamp = message_time_s(msg, 0)
            if stamp > 0:
                self.stamp_minus_receive.append(stamp - t_ns * 1e-9)
                self.stamped_received.append(t_ns * 1e-9)
            self.odom_t.append(message_time_s(msg, t_ns))
            turn = self._unit(pose.orientation)
            x, y = (pose.position.x, pose.position.y) if turn is not None else (math.nan, math.nan)  # no heading: left out
            turn = turn or SimpleNamespace(x=0.0, y=0.0, z=0.0, w=1.0)
            self.odom.append((x, y, yaw_rad(turn)))
            self.odom_attitude.append((pose.position.z, *pitch_roll_rad(turn)))
            moving = msg.twist.twist if conn.msgtype == "nav_msgs/msg/Odometry" else None  # in the robot's own frame: x ahead
            self.odom_twist.append((moving.linear.x, moving.angular.z) if moving is not None else (math.nan, math.nan))
        elif role == "command":
            twist = msg.twist if conn.msgtype == "geometry_msgs/msg/TwistStamped" else msg
            stamp = message_time_s(msg, 0) if conn.msgtype == "geometry_msgs/msg/TwistStamped" else 0.0
            self.cmd_t.append(stamp if stamp > 0 else t_ns * 1e-9)
            self.cmd_received.append(stamp <= 0)
            self.cmd.append((twist.linear.x, twist.angular.z))
        elif role == "path" and self.path is None and len(msg.poses) >= 2:
            self.path = path_xy(msg)
        elif role == "camera_info" and self.info is None:
            self.info = msg
        elif role == "depth_info" and self.depth_info is None:
            self.depth_info = msg
        elif role == "tf_static":
            self.static.update(static_transforms(msg))

    def _unit(self, q) -> SimpleNamespace | None:
        """The quaternion ``q`` (x, y, z, w) of unit length, counted where it had to be normalised;
        None (counted) for one that is zero or not finite, which turns the body no known way."""
        unit, rescaled = unit_quaternion(q)
        self.unturned += unit is None
        self.rescaled += rescaled
        return unit

    def checked(self, source: str, topic: str) -> Streams:
        """:meth:`streams`, with what was left out or put right said in its notes; odometry heights
        no robot reaches, or stamps that jump against the log's own clock, are a UserError about
        ``source`` (the bag) and ``topic`` (the odometry's)."""
        z = np.array([a[0] for a in self.odom_attitude], dtype=float)
        high = np.flatnonzero(np.isfinite(z) & (np.abs(z) > MAX_HEIGHT_M))
        if len(high):
            raise UserError(
                source,
                f"topic {topic}: a pose {z[high[0]]:g} m high; expected heights within +-{MAX_HEIGHT_M:g} m (odometry in other units?)",
                field="topics.odometry",
            )
        # A clock reset sends the stamps back, or ahead of the log's own clock; a simulator paused
        # while the log records only holds them still, which is no jump.
        ahead = np.diff(self.stamp_minus_receive)
        back = ahead + np.diff(self.stamped_received)  # each stamp less the one before
        jumps = np.where(back < -CLOCK_TOLERANCE_S, back, np.where(ahead > CLOCK_TOLERANCE_S, ahead, 0.0))
        if len(jumps) and jumps.any():
            at = int(np.flatnonzero(jumps)[0])
            raise UserError(
                source,
                f"topic {topic}: header stamps jump by {jumps[at]:+.1f} s against the log's receive times (a clock reset, "
                "or two runs in one log): cut the log at the jump and import each part",
                field="topics.odometry",
            )
        streams = self.streams()
        unknown = len(self.odom_t) - len(streams.odom_t) - self.unturned
        if self.unturned:
            streams.notes.append(f"left out {self.unturned} pose(s) of {topic} whose orientation is a zero or non-finite quaternion")
        if unknown:
            streams.notes.append(f"left out {unknown} pose(s) of {topic} with a non-finite position or stamp")
        if self.rescaled:
            streams.notes.append(f"normalised {self.rescaled} quaternion(s) of {topic} that were not of unit length")
        return streams

    def streams(self) -> Streams:
        """The streams without non-finite samples, each sorted by time, yaw unwrapped."""
        o_t, o = np.array(self.odom_t), np.array(self.odom, dtype=float)
        o_twist = np.array(self.odom_twist, dtype=float).reshape(-1, 2)
        o_att = np.array(self.odom_attitude, dtype=float).reshape(-1, 3)
        o_att[~np.isfinite(o_att)] = 0.0  # a pose's height or tilt not given: level
        c_t, c = np.array(self.cmd_t), np.array(self.cmd, dtype=float).reshape(-1, 2)  # (0, 2) without a command topic
        # Stamps on another clock than the log's (simulated time recorded by wall clock): what
        # is timed by receive time is moved onto the stamps' clock, by the odometry's offset.
        offset = float(np.median(self.stamp_minus_receive)) if self.stamp_minus_receive else 0.0
        shift = offset if abs(offset) > CLOCK_TOLERANCE_S else 0.0
        c_t = c_t + shift * np.array(self.cmd_received, dtype=bool)
        if not (np.isfinite(o).all() and np.isfinite(o_t).all()):
            keep = np.isfinite(o).all(axis=1) & np.isfinite(o_t)
            o_t, o, o_twist, o_att = o_t[keep], o[keep], o_twist[keep], o_att[keep]
        keep = np.isfinite(c).all(axis=1) & np.isfinite(c_t)
        c_t, c = c_t[keep], c[keep]
        order = np.argsort(o_t, kind="stable")
        o_t, o, o_twist, o_att = o_t[order], o[order], o_twist[order], o_att[order]
        o[:, 2] = np.unwrap(o[:, 2])  # so interpolation between stamps never spins the long way round
        order = np.argsort(c_t, kind="stable")
        return Streams(o_t, o, o_twist, c_t[order], c[order], self.path, self.info, self.static, shift, o_att, self.depth_info)


@dataclass(frozen=True)
class Conversion:
    """How a label image at a stamp becomes a frame of the recording."""

    rate_hz: float  # the recording's frame rate; faster images are thinned
    max_gap_s: float  # longer gaps in odometry hold no frame
    control: ControlSet
    lut: np.ndarray  # (65536,) uint8: label id -> class id
    listed: np.ndarray  # (65536,) bool: the ids the label map lists
    undistort: np.ndarray | None  # (H, W) flat index of each pinhole pixel in the lens's image (-1: outside); None: no distortion
    shift: np.ndarray  # (2,) [m] odometry frame -> map
    labels: LabelMap  # the label map (whether ids it does not list are an error)


@dataclass(frozen=True)
class Motion:
    """Each frame's (v, w) over time: the operator's commands, each in force until the next
    (zero-order hold), or the vehicle's motion measured at the odometry's stamps, interpolated."""

    t: np.ndarray  # (N,) [s], sorted
    vw: np.ndarray  # (N, 2) v [m/s], w [rad/s]
    held: bool  # commands, held; else measured motion, interpolated

    @classmethod
    def of(cls, streams: Streams, robot: RobotConfig, source: str, report: ImportReport) -> Motion:
        """The commands where the robot file names a command topic; else the odometry's twist, or
        differences of its poses where it has none (or fills none); the source goes in ``report``.
        Poses that all carry one stamp, which measure no motion, are an error about ``source`` (the bag)."""
        if robot.command_topic is not None:
            return cls(streams.cmd_t, streams.cmd, held=True)
        twist, poses = streams.odom_twist, streams.odom
        filled = np.isfinite(twist).all(axis=1)
        moved_m = float(np.hypot(*(poses[:, :2] - poses[0, :2]).T).max())  # the farthest from the first pose
        never_filled = filled.any() and not np.any(twist[filled]) and moved_m > STILL_TWIST_MOVED_M
        if filled.any() and not never_filled:
            report.speed_source = "twist"
            return cls(streams.odom_t[filled], twist[filled], held=False)
        if never_filled:
            report.notes.append(
                f"the twist of {robot.topics['odometry']} is zero throughout while its pose moves {moved_m:.1f} m "
                "(its driver fills no twist): the speed is measured by differences of its poses"
            )
        report.speed_source = "poses"
        vw = pose_velocities(streams.odom_t, poses, POSE_DIFFERENCE_HALF_S)
        known = np.isfinite(vw).all(axis=1)
        if not known.any():
            odometry = robot.topics["odometry"]
            raise UserError(source, f"topic {odometry}: every pose has one stamp, so no motion can be measured", field="topics.odometry")
        return cls(streams.odom_t[known], vw[known], held=False)

    def at(self, t: float) -> tuple[float, float] | None:
        """(v, w) at ``t`` [s]; None before the first command."""
        if self.held:
            k = int(np.searchsorted(self.t, t, side="right")) - 1
            return None if k < 0 else (float(self.vw[k, 0]), float(self.vw[k, 1]))
        return float(np.interp(t, self.t, self.vw[:, 0])), float(np.interp(t, self.t, self.vw[:, 1]))


@dataclass
class DepthImages:
    """The depth topic's images read so far that a label image still to come may pair with
    (:class:`DepthPairing`'s rule). They are held as whole millimetres, as the recording stores
    them, and at most :data:`DEPTH_HELD` of them (the newest): a label image waits in the reorder
    buffer for :data:`REORDER_FRAMES` more, so a depth camera up to eight times as fast as the
    label images pairs every one."""

    topic: str
    connections: list  # the bag's connections of the topic
    shape: tuple[int, int]  # the label camera's (H, W), which each depth image must have
    pairing: DepthPairing = field(default_factory=lambda: DepthPairing(DEPTH_HELD))  # depth (H, W) uint16 [mm, 0: none] by stamp
    paired: int = 0  # label images paired so far
    largest_offset_s: float = 0.0  # the largest stamp difference of a pair [s]
    returns: int = 0  # paired images holding at least one return

    def take_in(self, bag: Bag, conn, t_ns: int, msg, shift_s: float) -> None:
        """Decode and hold a depth message of the log (received at ``t_ns`` [ns]); its stamp moved
        by ``shift_s`` [s] when it has none. Another encoding or size is a UserError naming the topic."""
        try:
            t = message_time_s(msg, t_ns, shift_s)
        except AttributeError as exc:
            raise UserError(bag.source, f"topic {conn.topic}: no header stamp ({exc})", field="topics.depth") from None
        depth = registered_depth(msg, conn.topic, bag.source, self.shape, (t_ns - bag.reader.start_time) * 1e-9)
        self.pairing.put(t, depth_to_millimetres(depth))

    def take(self, t: float) -> np.ndarray | None:
        """The depth image [m] of the stamp nearest ``t`` [s] within :data:`DEPTH_PAIRING_S`, or None."""
        paired = self.pairing.nearest(t)
        if paired is None:
            return None
        offset, mm = paired
        self.paired += 1
        self.returns += bool(mm.any())
        self.largest_offset_s = max(self.largest_offset_s, offset)
        return millimetres_to_depth(mm)

    def summary(self) -> str:
        """What the frames' depth images are, for the import's report."""
        empty = self.paired - self.returns
        return (
            f"{self.paired} frames carry a depth image of {self.topic} "
            f"(paired by stamp, at most {1000 * self.largest_offset_s:.0f} ms apart; {1000 * DEPTH_PAIRING_S:.0f} ms allowed)"
            + (
                f"; WARNING: {empty} of them hold no return at all (every pixel 0, NaN, negative or out of range: check the topic's encoding and units)"
                if empty
                else ""
            )
        )


@dataclass
class Frames:
    """The recording being written: each image kept gets the odometry pose interpolated at its
    stamp and the command in force then (or the motion measured then), and with a depth topic
    the depth image of its stamp and the body's attitude then; what is skipped is counted in the
    report."""

    streams: Streams
    motion: Motion
    conversion: Conversion
    writer: RecordingWriter
    report: ImportReport
    depth: DepthImages | None = None  # the depth topic's images (None: the frames carry none)
    pixels: int = 0
    unmapped: int = 0  # pixels whose id the label map does not list
    unknown: int = 0  # pixels unknown after mapping
    last_t: float = -math.inf  # the stamp of the last frame kept [s]
    due_t: float | None = None  # when the next frame is due at the recording's rate [s] (None: before the first)
    t_first: float | None = None  # the stamp of the first frame kept [s]
    times: list[float] = field(default_factory=list)  # the stamps of the frames kept [s]
    image_span: tuple[float, float] = (math.inf, -math.inf)  # the images' first and last stamps [s]
    speeds: list[float] = field(default_factory=list)  # the speed of each frame kept [m/s]

    def emit(self, t: float, ids: np.ndarray) -> None:
        """The image ``ids`` (H, W) stamped ``t`` [s] as the next frame, unless it is skipped."""
        self.image_span = (min(self.image_span[0], t), max(self.image_span[1], t))
        vw = self.motion.at(t)
        reason = self._skip_reason(t, vw)
        if reason is not None:
            self.report.skipped[reason] += 1
            return
        depth = self.depth.take(t) if self.depth is not None else None
        if self.depth is not None and depth is None:
            self.report.skipped[f"images without a depth image within {1000 * DEPTH_PAIRING_S:.0f} ms"] += 1
            return
        c = self.conversion
        v, w = vw  # not None, and v >= MIN_SPEED_MPS: _skip_reason refuses the others
        w_set = float(np.clip(w * c.control.v_mps / v, min(c.control.w_rps), max(c.control.w_rps)))  # same curvature at the set's speed
        pose = self._pose_at(t)
        image = self._classes(ids, t)
        if self.t_first is None:
            self.t_first = t
        seen = image if depth is None else SegmentationView.of(image, self._undistorted(depth), self._attitude_at(t))
        self.writer.append(t - self.t_first, pose, seen, (v, w), int(c.control.label_of(w_set)))
        self.speeds.append(v)
        self.times.append(t)
        self.last_t = t
        # The frames keep to a grid at the recording's rate; after a gap it starts again there.
        period = 1.0 / c.rate_hz
        self.due_t = t + period if self.due_t is None or t > self.due_t + period else self.due_t + period

    def _skip_reason(self, t: float, vw: tuple[float, float] | None) -> str | None:
        """Why the image stamped ``t`` [s], whose (v, w) is ``vw``, makes no frame, or None."""
        rate_hz, odom_t = self.conversion.rate_hz, self.streams.odom_t
        if t <= self.last_t:
            return "images out of order beyond the reorder buffer"
        # On a grid at the rate, a quarter period of slack for stamp jitter; never two frames within half a period.
        if self.due_t is not None and (t < self.due_t - 0.25 / rate_hz or t - self.last_t < 0.5 / rate_hz):
            return f"images thinned to {rate_hz:g} Hz"
        j = self._odom_index(t)
        if j == 0 or j == len(odom_t):
            return "images outside the odometry's time span"
        t0, t1 = odom_t[j - 1], odom_t[j]
        if t1 - t0 > self.conversion.max_gap_s and t != t0 and t != t1:  # a pose at the very stamp needs no interpolation
            return "images in an odometry gap"
        if vw is None:
            return "images before the first command"
        if vw[0] < MIN_SPEED_MPS:
            return "images while stopped or reversing"
        return None

    def _odom_index(self, t: float) -> int:
        """j with odom_t[j - 1] <= t < odom_t[j] (or t on the last pose)."""
        odom_t = self.streams.odom_t
        j = int(np.searchsorted(odom_t, t, side="right"))
        if j == len(odom_t) and t == odom_t[-1]:
            j -= 1  # exactly on the last pose
        return j

    def _pose_at(self, t: float) -> tuple[float, float, float]:
        """The pose (x, y [m], yaw [rad]) in the map at ``t`` [s], interpolated between odometry poses."""
        odom_t, odom, shift = self.streams.odom_t, self.streams.odom, self.conversion.shift
        j = self._odom_index(t)
        t0, t1 = odom_t[j - 1], odom_t[j]
        if t == t1 or t == t0:  # a pose at the image's own stamp is taken as it is, bit for bit
            x, y, yaw = odom[j if t == t1 else j - 1]
        else:
            x, y, yaw = odom[j - 1] + (t - t0) / (t1 - t0) * (odom[j] - odom[j - 1])
        if abs(yaw) > math.pi:  # unwrapped for the interpolation; wrapped back only where needed
            yaw = wrap_angle(yaw)
        return x + shift[0], y + shift[1], yaw

    def _attitude_at(self, t: float) -> Attitude:
        """The body's attitude at ``t`` [s] (z [m], pitch, roll [rad]), interpolated between odometry poses."""
        odom_t, tilt = self.streams.odom_t, self.streams.odom_attitude
        if tilt is None:
            return Attitude(0.0, 0.0, 0.0)
        j = self._odom_index(t)
        t0, t1 = odom_t[j - 1], odom_t[j]
        if t == t1 or t == t0:
            return Attitude(*(float(a) for a in tilt[j if t == t1 else j - 1]))
        return Attitude(*(float(a) for a in tilt[j - 1] + (t - t0) / (t1 - t0) * (tilt[j] - tilt[j - 1])))

    def _undistorted(self, depth: np.ndarray) -> np.ndarray:
        """A depth image (H, W) [m] through the label images' undistortion (NaN where no lens pixel falls)."""
        return undistorted(depth, self.conversion.undistort, np.float32(np.nan))

    def _classes(self, ids: np.ndarray, t: float) -> np.ndarray:
        """Class ids (H, W) uint8 of the label ids ``ids`` (the image stamped ``t`` [s]), undistorted;
        the pixels counted. An id the label map does not list is an error unless the map makes it unknown."""
        c = self.conversion
        counts = np.bincount(ids.ravel())  # pixels per label id: what the checks and the shares count
        unmapped = int(counts[~c.listed[: len(counts)]].sum())
        if unmapped:
            c.labels.refuse_unlisted(ids, f"the image stamped {t:.3f} s")
        image = np.take(c.lut, ids)
        self.pixels += ids.size
        self.unmapped += unmapped
        if c.undistort is None:
            self.unknown += int(counts[c.lut[: len(counts)] == UNKNOWN].sum())
            return image
        image = undistorted(image, c.undistort, UNKNOWN)
        self.unknown += int(np.count_nonzero(image == UNKNOWN))
        return image

    def close(self, source: str, progress: Progress) -> None:
        """Finish the recording and the report; with no frame kept, an error about ``source`` (the bag)."""
        writer, report = self.writer, self.report
        progress.close(f"{writer.count} frames from {report.images} images")
        if writer.count == 0:
            writer.abort()
            spans = [
                (name, t)
                for name, t in (("images", self.image_span), ("odometry", self.streams.odom_t), ("commands", self.streams.cmd_t))
                if len(t)
            ]
            when = "; ".join(f"{name} {min(t):.1f}-{max(t):.1f} s" for name, t in spans if np.isfinite(min(t)))
            raise UserError(
                source,
                f"no usable frame: {', '.join(f'{n} {r}' for r, n in report.skipped.items()) or 'no images'}"
                + (f"; speeds {report.speed_how}" if report.speed_source != "commands" else "")
                + (f" (stamps: {when})" if when else ""),
                field="topics.segmentation",
            )
        report.frames = writer.count
        report.speed_mps = (min(self.speeds), float(np.mean(self.speeds)), max(self.speeds))
        # As the recording reads it: frames x their median step (0.1 s with one frame).
        report.duration_s = len(self.times) * (float(np.median(np.diff(self.times))) if len(self.times) > 1 else 0.1)
        report.unmapped_share = self.unmapped / max(self.pixels, 1)
        report.unknown_share = self.unknown / max(self.pixels, 1)
        if self.depth is not None:
            report.depth = self.depth.summary()
        writer.close({"completed": True, "collisions": 0, "duration_s": round(report.duration_s, 3), "import": report.lines()})


def stream_images(bag: Bag, robot: RobotConfig, seg_conns: list, shape: tuple[int, int], frames: Frames, progress: Progress) -> None:
    """Decode the segmentation images one at a time, put back in stamp order through a short
    reorder buffer, and hand each to ``frames``; ``shape`` is the camera's (H, W). The depth
    topic's images, if any, are read in the same pass (in the log's order) and held for the
    label images near their stamps (:class:`DepthImages`)."""
    report, depth = frames.report, frames.depth
    heap: list = []
    last_image_t = None
    for seq, (conn, t_ns, msg) in enumerate(bag.messages(seg_conns + (depth.connections if depth is not None else []))):
        if depth is not None and conn.topic == depth.topic:
            depth.take_in(bag, conn, t_ns, msg, frames.streams.receive_shift_s)
            continue
        try:
            t = message_time_s(msg, t_ns, frames.streams.receive_shift_s)
        except AttributeError as exc:
            raise UserError(bag.source, f"topic {conn.topic}: no header stamp ({exc})", field="topics.segmentation") from None
        ids = label_ids(msg, conn.msgtype, conn.topic, bag.source, robot.labels, (t_ns - bag.reader.start_time) * 1e-9)
        report.images += 1
        if ids.shape != shape:
            raise UserError(
                bag.source,
                f"topic {conn.topic}: image {ids.shape[1]} x {ids.shape[0]}, camera_info says {shape[1]} x {shape[0]}",
                field="topics.segmentation",
            )
        if last_image_t is not None and t - last_image_t > robot.max_gap_s:
            report.image_gaps += 1
            report.longest_gap_s = max(report.longest_gap_s, t - last_image_t)
        last_image_t = t if last_image_t is None else max(last_image_t, t)
        heapq.heappush(heap, (t, seq, ids))
        if len(heap) > REORDER_FRAMES:
            frames.emit(*heapq.heappop(heap)[::2])
        progress.update(report.images, f"{frames.writer.count} frames")
    while heap:
        frames.emit(*heapq.heappop(heap)[::2])
