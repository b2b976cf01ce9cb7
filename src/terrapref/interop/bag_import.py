"""ROS 1 and ROS 2 bags (sqlite3 or MCAP) to terrapref recordings, read with ``rosbags``.

Two passes over the bag. The first reads the small topics (odometry, commands, the path, the
camera's calibration) into memory; the second streams the label images one at a time, so memory
stays flat however large the bag. Each kept image becomes a frame whose pose is the odometry
interpolated to the image's header stamp and whose label is the operator's command in force at
that stamp (zero-order hold: commands may come at their own rate or only on change).

A robot file without ``topics.command`` labels each frame by the vehicle's measured motion (v, w)
instead: an Odometry's twist (``twist.twist.linear.x``, ``twist.twist.angular.z``) interpolated to
the stamp, or, for a pose topic (PoseStamped, PoseWithCovarianceStamped) and for an Odometry whose
twist is zero throughout while its pose moves (a driver that never fills it), a centred difference
of the poses around the stamp. The report says which. A command topic the robot file names but
the bag lacks stays an error: a misspelt topic must not turn into a quiet fallback.

What real logs contain is handled and reported: topics at their own rates (images are thinned
to ``rate_hz``), stamp jitter, out-of-order images (a short reorder buffer; older stragglers are
dropped), gaps in odometry (frames inside a gap are skipped), label ids the label map does not
list (their share is reported), the operator stopped or reversing (no trajectory choice: skipped).
Each frame keeps the operator's command as it was logged (or the motion measured), at its own
speed (v, w), so that a speed rule learns the speeds driven; its label is the trajectory of the
preference set of the same curvature, at the set's speed: w x v_set / v.

The recording is written to a temporary folder beside ``out`` and renamed into place only when
complete; an error leaves nothing behind.
"""

from __future__ import annotations

import heapq
import io
import math
import re
import shutil
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image as PILImage

from terrapref.camera import CameraConfig
from terrapref.demos.meta import ImportedInfo, RecordingMeta, SimMeta
from terrapref.demos.recording import RecordingWriter, is_recording
from terrapref.errors import UserError
from terrapref.extras import needs
from terrapref.features import PreferenceSetConfig
from terrapref.fileio import new_folder, replace_dir
from terrapref.interop.labels import LabelMap
from terrapref.interop.robot import RobotConfig, load_waypoints
from terrapref.progress import Progress
from terrapref.terrain import ClassTable, default_classes
from terrapref.terrain.classes import UNKNOWN
from terrapref.terrain.profile import PreferenceProfile
from terrapref.vehicle import ControlSet, wrap_angle

TYPES = {
    "segmentation": ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage"),
    "camera_info": ("sensor_msgs/msg/CameraInfo",),
    "odometry": ("nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped"),
    "command": ("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped"),
    "path": ("nav_msgs/msg/Path",),
}
REORDER_FRAMES = 16  # images held back to put slightly out-of-order stamps right
MIN_SPEED_MPS = 0.1  # slower than this the operator is stopped: no trajectory choice
POSE_DIFFERENCE_HALF_S = 0.1  # a pose's motion: the poses this long before and after it, differenced (centred, over 0.2 s)
STILL_TWIST_MOVED_M = 1.0  # an Odometry whose twist is zero throughout while its pose goes farther than this never filled it
SPEED_SOURCES = {  # where each frame's speed (v, w) comes from, as the report names it
    "commands": "the commands",
    "twist": "the odometry's twist",
    "poses": f"differences of odometry poses over {2 * POSE_DIFFERENCE_HALF_S:g} s",
}
MAP_MARGIN_M = 15.0
PATH_SMOOTHING_M = 5.0  # half-width of the moving average that turns driven odometry into a path


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


CLOCK_TOLERANCE_S = 5.0  # header stamps this far from the log's receive times are on another clock (simulated time)


def _stamp(msg, fallback_ns: int, shift_s: float = 0.0) -> float:
    """The header stamp [s]; an unstamped message is timed by when the log received it, moved by
    ``shift_s`` onto the stamps' clock."""
    stamp = msg.header.stamp
    ns = int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
    return ns * 1e-9 if ns > 0 else fallback_ns * 1e-9 + shift_s


def _yaw(q) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _field(msg, *names):
    for name in names:
        if hasattr(msg, name):
            return getattr(msg, name)
    raise AttributeError(names[0])


def _one_line(exc: BaseException, limit: int = 160) -> str:
    """An exception's text on one line (a reader's errors quote whole message definitions), without
    the memory addresses some quote (PIL's ``<_io.BytesIO object at 0x...>``), so that the same
    problem reads the same each time."""
    text = re.sub(r" at 0x[0-9a-fA-F]+", "", " ".join(str(exc).split()))
    return f"{type(exc).__name__}: {text[:limit]}{'...' if len(text) > limit else ''}"


class _Bag:
    """The bag, opened with rosbags; every failure of the reader is a one-line UserError.

    A topic whose message definition in the log cannot be read (``ros2 bag record -a`` stores
    service events' ``*_Event`` types as the raw service definition) is left out and listed in
    ``unreadable``; only a topic the robot file asks for makes that an error."""

    def __init__(self, path: Path) -> None:
        self.source = str(path)
        if not path.exists():
            raise UserError(self.source, "no such bag")
        try:
            self.reader = open_reader(path)
        except UserError:  # the robot extra is missing
            raise
        except Exception as exc:  # the reader's errors on a damaged or foreign file are many kinds
            raise UserError(self.source, f"not a readable ROS 1 bag, ROS 2 bag or MCAP file ({_one_line(exc)})") from None
        self.unreadable: dict[str, tuple[str, str]] = self.reader.unreadable  # topic -> (type, why)

    def check_topics(self, robot: RobotConfig, roles: Sequence[str]) -> None:
        """Every topic of ``roles`` in the robot file is in the bag, of a type it may have, with
        messages; what is not is said at once, every topic in one message."""
        problems = [p for role in roles if (p := self._topic_problem(robot.topics[role], role))]
        if problems:
            have = sorted({c.topic for c in self.reader.connections})
            shown = ", ".join(have[:12]) + (" ..." if len(have) > 12 else "")
            raise UserError(
                self.source, f"{'; '.join(problems)} (topics in {robot.source}; the bag has {shown or 'no topics'})", field="topics"
            )

    def _topic_problem(self, topic: str, role: str) -> str | None:
        conns = [c for c in self.reader.connections if c.topic == topic]
        if not conns and topic in self.unreadable:
            msgtype, why = self.unreadable[topic]
            return f"topics.{role} {topic} has type {msgtype}, whose definition in the log cannot be read ({why})"
        if not conns:
            return f"topics.{role} {topic} is not in the bag"
        wrong = sorted({c.msgtype for c in conns if c.msgtype not in TYPES[role]})
        if wrong:
            return f"topics.{role} {topic} has type {', '.join(wrong)}, expected {' or '.join(TYPES[role])}"
        if sum(c.msgcount for c in conns) == 0:
            return f"topics.{role} {topic} has no messages"
        return None

    def connections(self, topic: str, role: str, source: str) -> list:
        problem = self._topic_problem(topic, role)
        if problem:
            raise UserError(self.source, f"{problem} (topics in {source})", field=f"topics.{role}")
        return [c for c in self.reader.connections if c.topic == topic]

    def messages(self, conns: list):
        """(connection, bag time [ns], message), deserialised; a damaged message is a UserError."""
        return read_messages(self.reader, conns, self.source)

    def close(self) -> None:
        try:
            self.reader.close()
        except Exception:  # closing a half-read damaged file must not hide the real error
            pass


@dataclass
class _Streams:
    odom_t: np.ndarray
    odom: np.ndarray  # (N, 3) x, y, yaw
    odom_twist: np.ndarray  # (N, 2) v [m/s], w [rad/s] of each pose as an Odometry's twist gives it; NaN: a pose without twist
    cmd_t: np.ndarray
    cmd: np.ndarray  # (N, 2) v, w
    path: np.ndarray | None
    info: object
    static: dict[str, tuple[str, np.ndarray, np.ndarray]] = field(default_factory=dict)  # child -> (parent, t, R)
    receive_shift_s: float = 0.0  # added to a receive time to put it on the header stamps' clock


def _rotation(q) -> np.ndarray:
    x, y, z, w = q.x, q.y, q.z, q.w
    n = math.sqrt(x * x + y * y + z * z + w * w) or 1.0
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def camera_mount_from_tf(static: dict, base: str, camera_frame: str, source: str, notes: list[str]) -> dict[str, float]:
    """height_m, forward_m, pitch_deg, yaw_deg of the camera from the static transforms base -> camera.

    The optical axis is the camera frame's z for an optical frame (REP 103: its name ends in
    ``optical`` or ``optical_frame``), else its x.
    """
    chain, frame = [], camera_frame
    while frame != base:
        if frame not in static or len(chain) > 32:
            have = ", ".join(sorted(f"{p} -> {c}" for c, (p, _, _) in static.items())) or "none"
            raise UserError(
                source,
                f"no static transform chain from {base} to the camera frame {camera_frame!r} in /tf_static (transforms: {have})",
                field="camera.tf",
            )
        parent, t, r = static[frame]
        chain.append((t, r))
        frame = parent
    t_total, r_total = np.zeros(3), np.eye(3)
    for t, r in reversed(chain):  # base -> ... -> camera
        t_total = t_total + r_total @ t
        r_total = r_total @ r
    optical = camera_frame.rstrip("/").endswith(("optical", "optical_frame"))
    axis = r_total @ (np.array([0.0, 0.0, 1.0]) if optical else np.array([1.0, 0.0, 0.0]))
    if abs(t_total[1]) > 0.05:
        notes.append(f"the camera sits {t_total[1]:+.2f} m to the side of {base}; terrapref's camera model ignores a lateral offset")
    return {
        "height_m": float(t_total[2]),
        "forward_m": float(t_total[0]),
        "pitch_deg": math.degrees(math.asin(float(np.clip(-axis[2], -1, 1)))),
        "yaw_deg": math.degrees(math.atan2(axis[1], axis[0])),
    }


def _definition_types(connection) -> dict:
    """The message types a connection's own definition declares (none when it carries none)."""
    from rosbags.interfaces import MessageDefinitionFormat
    from rosbags.typesys import get_types_from_idl, get_types_from_msg

    definition = connection.msgdef
    if definition.format == MessageDefinitionFormat.MSG:
        return get_types_from_msg(definition.data, connection.msgtype)
    if definition.format == MessageDefinitionFormat.IDL:
        sep = "=" * 80 + "\n"
        parts = (
            [p.split("\n", 1)[1] for p in definition.data.split(sep)[1:]]
            if definition.data.startswith(f"{sep}IDL: ")
            else [definition.data]
        )
        types: dict = {}
        for idl in parts:
            types.update(get_types_from_idl(idl))
        return types
    return {}


def read_messages(reader, connections: list, source: str) -> Iterator[tuple[Any, int, Any]]:
    """(connection, log time [ns], message) of ``connections`` in the log's order, deserialised,
    from a reader :func:`open_reader` opened. A damaged chunk or message stops the read with a
    one-line UserError naming ``source`` and where the damage was met, once everything before it
    has been yielded.

    Raises:
        UserError: a chunk or message of the log cannot be read.
    """
    it = reader.messages(connections=connections)
    n, last_ns = 0, None
    while True:
        try:
            conn, t_ns, raw = next(it)
            msg = reader.deserialize(raw, conn.msgtype)
        except StopIteration:
            return
        except Exception as exc:  # damaged chunk or message: the reader's own error types vary
            after = "at its start" if last_ns is None else f"{(last_ns - reader.start_time) * 1e-9:.3f} s into the log"
            raise UserError(source, f"damaged: message {n + 1} of the read ({after}) cannot be read ({_one_line(exc)})") from None
        n, last_ns = n + 1, t_ns
        yield conn, t_ns, msg


def open_reader(path: Path):
    """rosbags' AnyReader over ``path``, opened, except that a connection whose message definition
    cannot be parsed (or whose hash does not match it) is left out, in ``unreadable``, instead of
    failing the whole log. As AnyReader, the ROS 2 Humble types serve a log that carries no
    definitions at all."""
    with needs("robot", "reading ROS bags"):
        from rosbags.highlevel import AnyReader
        from rosbags.interfaces import MessageDefinitionFormat
        from rosbags.typesys import Stores, get_typestore

    class TolerantReader(AnyReader):
        def _open(self) -> None:
            for reader in self.readers:
                self.stack.enter_context(reader)
            connections = [c for reader in self.readers for c in reader.connections]
            defined = any(c.msgdef.format != MessageDefinitionFormat.NONE for c in connections)
            types = {} if defined else dict(self.default_typestore.fielddefs)
            self.unreadable, self.connections = {}, []
            for connection in connections:
                try:
                    own = _definition_types(connection)
                    if own and connection.digest:  # a definition and its hash: checked against each other
                        trial = get_typestore(Stores.EMPTY)
                        trial.register({**types, **own})
                        digest = trial.hash_rihs01(connection.msgtype) if self.is2 else trial.generate_msgdef(connection.msgtype)[1]
                        if digest != connection.digest:
                            raise ValueError("its hash does not match its definition")
                except Exception as exc:  # the type system's errors vary with the definition's flaw
                    self.unreadable[connection.topic] = (connection.msgtype, _one_line(exc, 80))
                    continue
                types.update(own)
                self.connections.append(connection)
            self.typestore = get_typestore(Stores.EMPTY)
            self.typestore.register(types)

    reader = TolerantReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
    reader.open()
    return reader


def _read_small_topics(bag: _Bag, robot: RobotConfig) -> _Streams:
    """Odometry, commands, the path, the calibration and (for ``camera.tf``) /tf_static, read whole."""
    topics = robot.topics
    wanted = [role for role in ("odometry", "command", "camera_info", "path") if role in topics]
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
    return read.streams()


@dataclass
class _SmallTopics:
    """The small topics as they are read, in bag order."""

    odom_t: list[float] = field(default_factory=list)
    odom: list[tuple[float, float, float]] = field(default_factory=list)
    odom_twist: list[tuple[float, float]] = field(default_factory=list)
    cmd_t: list[float] = field(default_factory=list)
    cmd: list[tuple[float, float]] = field(default_factory=list)
    path: np.ndarray | None = None  # the first path of two or more poses
    info: object = None  # the first camera_info
    static: dict[str, tuple[str, np.ndarray, np.ndarray]] = field(default_factory=dict)  # child -> (parent, t, R)
    stamp_minus_receive: list[float] = field(default_factory=list)  # of stamped odometry [s]
    cmd_received: list[bool] = field(default_factory=list)  # each command timed by receive time (Twist carries no stamp)

    def take(self, role: str, conn, t_ns: int, msg) -> None:
        """Keep what ``msg`` (of ``role``, from ``conn``, at bag time ``t_ns`` [ns]) says."""
        if role == "odometry":
            pose = msg.pose.pose if conn.msgtype != "geometry_msgs/msg/PoseStamped" else msg.pose
            stamp = _stamp(msg, 0)
            if stamp > 0:
                self.stamp_minus_receive.append(stamp - t_ns * 1e-9)
            self.odom_t.append(_stamp(msg, t_ns))
            self.odom.append((pose.position.x, pose.position.y, _yaw(pose.orientation)))
            moving = msg.twist.twist if conn.msgtype == "nav_msgs/msg/Odometry" else None  # in the robot's own frame: x ahead
            self.odom_twist.append((moving.linear.x, moving.angular.z) if moving is not None else (math.nan, math.nan))
        elif role == "command":
            twist = msg.twist if conn.msgtype == "geometry_msgs/msg/TwistStamped" else msg
            stamp = _stamp(msg, 0) if conn.msgtype == "geometry_msgs/msg/TwistStamped" else 0.0
            self.cmd_t.append(stamp if stamp > 0 else t_ns * 1e-9)
            self.cmd_received.append(stamp <= 0)
            self.cmd.append((twist.linear.x, twist.angular.z))
        elif role == "path" and self.path is None and len(msg.poses) >= 2:
            self.path = np.array([(p.pose.position.x, p.pose.position.y) for p in msg.poses], dtype=float)
        elif role == "camera_info" and self.info is None:
            self.info = msg
        elif role == "tf_static":
            for tr in msg.transforms:
                v = tr.transform.translation
                self.static[str(tr.child_frame_id).lstrip("/")] = (
                    str(tr.header.frame_id).lstrip("/"),
                    np.array([v.x, v.y, v.z]),
                    _rotation(tr.transform.rotation),
                )

    def streams(self) -> _Streams:
        """The streams without non-finite samples, each sorted by time, yaw unwrapped."""
        o_t, o = np.array(self.odom_t), np.array(self.odom, dtype=float)
        o_twist = np.array(self.odom_twist, dtype=float).reshape(-1, 2)
        c_t, c = np.array(self.cmd_t), np.array(self.cmd, dtype=float).reshape(-1, 2)  # (0, 2) without a command topic
        # Stamps on another clock than the log's (simulated time recorded by wall clock): what
        # is timed by receive time is moved onto the stamps' clock, by the odometry's offset.
        offset = float(np.median(self.stamp_minus_receive)) if self.stamp_minus_receive else 0.0
        shift = offset if abs(offset) > CLOCK_TOLERANCE_S else 0.0
        c_t = c_t + shift * np.array(self.cmd_received, dtype=bool)
        if not (np.isfinite(o).all() and np.isfinite(o_t).all()):
            keep = np.isfinite(o).all(axis=1) & np.isfinite(o_t)
            o_t, o, o_twist = o_t[keep], o[keep], o_twist[keep]
        keep = np.isfinite(c).all(axis=1) & np.isfinite(c_t)
        c_t, c = c_t[keep], c[keep]
        order = np.argsort(o_t, kind="stable")
        o_t, o, o_twist = o_t[order], o[order], o_twist[order]
        o[:, 2] = np.unwrap(o[:, 2])  # so interpolation between stamps never spins the long way round
        order = np.argsort(c_t, kind="stable")
        return _Streams(o_t, o, o_twist, c_t[order], c[order], self.path, self.info, self.static, shift)


def camera_from_info(
    info, robot: RobotConfig, source: str, static: dict | None = None, notes: list[str] | None = None
) -> tuple[CameraConfig, np.ndarray | None]:
    """The camera (CameraConfig) and, for a distorted lens, the nearest-pixel undistortion map;
    the mounting from the robot file, or from ``static`` transforms when it says ``tf``."""
    try:
        width, height = int(info.width), int(info.height)
        k = np.asarray(_field(info, "k", "K"), dtype=float).reshape(3, 3)
        d = np.asarray(_field(info, "d", "D"), dtype=float)
        model = str(info.distortion_model)
    except (AttributeError, TypeError, ValueError) as exc:
        raise UserError(source, f"camera_info unreadable ({exc})", field="topics.camera_info") from None
    fx, fy, cx, cy = k[0, 0], k[1, 1], k[0, 2], k[1, 2]
    if width <= 0 or height <= 0 or not (fx > 0 and fy > 0 and np.isfinite([fx, fy, cx, cy]).all()):
        raise UserError(
            source, f"camera_info: image {width} x {height}, K {k.ravel().tolist()} is not a calibration", field="topics.camera_info"
        )
    cam = dict(robot.camera)
    if "tf" in cam:
        cam.update(
            camera_mount_from_tf(
                static or {}, str(cam["tf"]).lstrip("/"), str(info.header.frame_id).lstrip("/"), source, notes if notes is not None else []
            )
        )
        if not (0.05 <= cam["height_m"] <= 10.0 and -89.0 <= cam["pitch_deg"] <= 89.0):
            raise UserError(
                source,
                f"/tf_static puts the camera {cam['height_m']:.2f} m high, pitched {cam['pitch_deg']:.1f} deg: not a ground-looking camera",
                field="camera.tf",
            )
    mount = dict(
        mount_height_m=cam["height_m"],
        mount_forward_m=cam["forward_m"],
        pitch_deg=cam["pitch_deg"],
        yaw_deg=cam["yaw_deg"],
        max_range_m=cam["max_range_m"],
    )
    hfov = math.degrees(2 * math.atan(width / (2 * fx)))
    camera = CameraConfig(width_px=width, height_px=height, hfov_deg=hfov, fx=fx, fy=fy, cx=cx, cy=cy, **mount)
    # A centred pinhole with square pixels is written by its field of view, as terrapref's own
    # cameras are, so that a model trained in the simulator and a log of the same camera match.
    plain = CameraConfig(width_px=width, height_px=height, hfov_deg=round(hfov, 6), **mount)
    if plain.intrinsics == (fx, fy, cx, cy):
        camera = plain
    if not d.size or not np.any(d):
        return camera, None
    if model not in ("plumb_bob", "rational_polynomial") or d.size < 4:
        raise UserError(source, f"camera_info: distortion model {model!r} is not supported (plumb_bob is)", field="topics.camera_info")
    k1, k2, p1, p2 = d[:4]
    k3 = d[4] if d.size > 4 else 0.0
    v, u = np.mgrid[0:height, 0:width].astype(float)
    x, y = (u - cx) / fx, (v - cy) / fy
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    ud, vd = np.rint(fx * xd + cx).astype(np.int64), np.rint(fy * yd + cy).astype(np.int64)
    inside = (ud >= 0) & (ud < width) & (vd >= 0) & (vd < height)
    index = np.where(inside, vd * width + ud, -1)  # -1: the pinhole pixel falls outside the lens's image
    return camera, index


COMPRESSED_DEPTH_HEADER = 12  # compressed_depth_image_transport's ConfigHeader before the png: format, two floats


def _decode(conn, msg, source: str, labels=None, t_s: float | None = None) -> np.ndarray:
    """Label ids (H, W) uint8 or uint16 of one segmentation message (rgb8 through the label
    map's colour table); ``t_s``, when the log received it from its start [s], names it in an error."""
    if conn.msgtype == "sensor_msgs/msg/CompressedImage":
        return _decode_png(conn, msg, source, t_s)
    encoding = str(msg.encoding).lower()
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    if encoding in ("mono8", "8uc1"):
        dtype = np.dtype(np.uint8)
    elif encoding in ("mono16", "16uc1"):
        dtype = np.dtype(">u2" if msg.is_bigendian else "<u2")
    elif encoding in ("rgb8", "bgr8"):
        if labels is None or not labels.colors:
            raise UserError(
                source, f"topic {conn.topic}: {msg.encoding} colour images need a colour table (colors) in the label map", field="labels"
            )
        data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
        if step < 3 * w or len(data) < step * h:
            raise UserError(
                source, f"topic {conn.topic}: image data of {len(data)} bytes does not hold {h} rows of {step}", field="topics.segmentation"
            )
        rgb = data[: step * h].reshape(h, step)[:, : 3 * w].reshape(h, w, 3)
        return labels.decode_rgb(rgb[..., ::-1] if encoding == "bgr8" else rgb)
    else:
        raise UserError(
            source,
            f"topic {conn.topic}: image encoding {msg.encoding!r}; label ids come as mono8 or mono16 (or rgb8 with a colour table)",
            field="topics.segmentation",
        )
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    if step < w * dtype.itemsize or len(data) < step * h:
        raise UserError(
            source, f"topic {conn.topic}: image data of {len(data)} bytes does not hold {h} rows of {step}", field="topics.segmentation"
        )
    rows = data[: step * h].reshape(h, step)[:, : w * dtype.itemsize]
    return np.ascontiguousarray(rows).view(dtype).reshape(h, w).astype(np.uint16 if dtype.itemsize == 2 else np.uint8)


def _decode_png(conn, msg, source: str, t_s: float | None) -> np.ndarray:
    """Label ids of a png CompressedImage, plain or as compressedDepth (16UC1 only: a 32FC1
    depth png holds quantised inverse depth, not ids)."""
    fmt = str(msg.format).lower()
    data = bytes(msg.data)
    where = f"topic {conn.topic}, message received {t_s:.3f} s into the log" if t_s is not None else f"topic {conn.topic}"
    if "png" not in fmt:
        raise UserError(source, f"{where}: CompressedImage format {msg.format!r}; label ids need lossless png", field="topics.segmentation")
    if "compresseddepth" in fmt:
        if not fmt.startswith(("16uc1", "mono16")):
            raise UserError(
                source,
                f"{where}: compressedDepth of {msg.format.split(';')[0].strip()!r} holds depth, not label ids; "
                "publish the ids as 16UC1 (or mono8/mono16 png)",
                field="topics.segmentation",
            )
        data = data[COMPRESSED_DEPTH_HEADER:]
    try:
        with PILImage.open(io.BytesIO(data)) as im:
            if im.mode not in ("L", "I;16", "I;16B", "I"):
                raise UserError(source, f"{where}: png of mode {im.mode}; expected single-channel label ids", field="topics.segmentation")
            ids = np.asarray(im)
    except (OSError, ValueError, SyntaxError) as exc:  # PIL's errors on data that is not a png (UnidentifiedImageError is an OSError)
        raise UserError(source, f"{where}: not a decodable png ({_one_line(exc, 80)})", field="topics.segmentation") from None
    return ids.astype(np.uint16) if ids.dtype != np.uint8 else ids


def smooth_path(xy: np.ndarray, spacing_m: float = 1.0) -> np.ndarray:
    """A path along driven positions: resampled by arc length, averaged over +-PATH_SMOOTHING_M."""
    steps = np.hypot(*np.diff(xy, axis=0).T)
    s = np.concatenate([[0.0], np.cumsum(steps)])
    if s[-1] < 2 * spacing_m:
        raise ValueError("the drive is too short to make a path of")
    grid = np.arange(0.0, s[-1], 0.25)
    pts = np.stack([np.interp(grid, s, xy[:, 0]), np.interp(grid, s, xy[:, 1])], axis=1)
    half = min(int(PATH_SMOOTHING_M / 0.25), len(pts) - 1)
    # Odd reflection at both ends: the path starts and ends where the drive did, and straight runs stay straight.
    padded = np.concatenate([2 * pts[0] - pts[half:0:-1], pts, 2 * pts[-1] - pts[-2 : -half - 2 : -1]])
    kernel = np.ones(2 * half + 1) / (2 * half + 1)
    smooth = np.stack([np.convolve(padded[:, k], kernel, mode="valid") for k in range(2)], axis=1)
    take = np.arange(0, len(smooth), int(spacing_m / 0.25))
    return smooth[np.unique(np.concatenate([take, [len(smooth) - 1]]))]


def _scenario(name: str, path: np.ndarray, start: tuple[float, float, float], size: tuple[float, float], classes: ClassTable) -> dict:
    return {
        "format": "terrapref-scenario/1",
        "name": name,
        "description": "imported from a robot log: the path and the driven poses, no terrain map and no zones",
        "world": {"size_m": [round(float(size[0]), 3), round(float(size[1]), 3)], "resolution_m": 0.5, "background": classes.background},
        "terrain": [],
        "path": {"waypoints": path.round(4).tolist()},
        "start": [round(float(start[0]), 4), round(float(start[1]), 4), round(math.degrees(float(start[2])), 4)],
    }


@dataclass(frozen=True)
class _Request:
    """One import: the bag, the robot file that reads it, and the recording's classes and frame rate [Hz]."""

    bag: _Bag
    robot: RobotConfig
    classes: ClassTable
    rate_hz: float
    check_camera: Callable[[CameraConfig], None] | None = None
    profile: PreferenceProfile | None = None  # the driver's declared order (None: none declared)


@dataclass(frozen=True)
class ImportOptions:
    """How a bag is imported.

    Attributes:
        rate_hz: frames per second of the recording [Hz], in (0, 100].
        force: replace a recording already at the destination.
        classes: the recording's class table; None: the default one.
        check_camera: may refuse the log's camera (raising) before any image is read.
        profile: the driver's preference order, over the robot file's; with neither, the
            recording declares none (and says so), for training needs the order its driver had.
    """

    rate_hz: float = 10.0
    force: bool = False
    classes: ClassTable | None = None
    check_camera: Callable[[CameraConfig], None] | None = None
    profile: PreferenceProfile | None = None


def import_bag(
    bag_path: str | Path, robot: RobotConfig, out: str | Path, options: ImportOptions = ImportOptions(), show_progress: bool = True
) -> ImportReport:
    """Turn a bag into a recording at ``out`` that inspect, featurize and train accept."""
    bag_path, out = Path(bag_path), Path(out)
    rate_hz, force, check_camera = options.rate_hz, options.force, options.check_camera
    classes = options.classes or default_classes()
    if not (math.isfinite(rate_hz) and 0 < rate_hz <= 100):
        raise UserError("--rate", "expected frames per second in (0, 100]")
    if out.exists() and (not out.is_dir() or (any(out.iterdir()) and not (force and is_recording(out)))):
        raise UserError(str(out), "exists; choose another --out (or --force to replace a recording)", field="--out")
    out.parent.mkdir(parents=True, exist_ok=True)
    bag = _Bag(bag_path)
    report = ImportReport(str(bag_path))
    profile = options.profile or robot.profile
    if options.profile is not None:
        report.order = f"{' > '.join(profile.order)} (--profile)"
    elif profile is not None:
        report.order = f"{' > '.join(profile.order)} (the robot file's profile)"
    else:
        report.order = (
            "none declared (the robot file has no profile:); a model trained on it names no order, and evaluate "
            "then asks for --profile: import again with --profile, or add profile: to the robot file, to keep the driver's"
        )
    tmp = new_folder(out, ".importing")
    try:
        _import(_Request(bag, robot, classes, rate_hz, check_camera, profile), tmp / "rec", show_progress, report)
        replace_dir(tmp / "rec", out)
    finally:
        bag.close()
        shutil.rmtree(tmp, ignore_errors=True)
    return report


def _import(req: _Request, out: Path, show_progress: bool, report: ImportReport) -> None:
    """The recording of ``req.bag`` at ``out``: the small topics read first, then the images streamed."""
    bag, robot = req.bag, req.robot
    bag.check_topics(robot, [role for role in ("segmentation", "odometry", "command", "camera_info", "path") if role in robot.topics])
    if bag.unreadable:
        shown = ", ".join(f"{topic} ({msgtype})" for topic, (msgtype, _) in sorted(bag.unreadable.items())[:4])
        report.notes.append(
            f"left out {len(bag.unreadable)} topic(s) whose message definition in the log cannot be read: {shown}"
            + (" ..." if len(bag.unreadable) > 4 else "")
        )
    seg_conns = bag.connections(robot.topics["segmentation"], "segmentation", robot.source)
    streams = _read_small_topics(bag, robot)
    if robot.command_topic is not None and len(streams.cmd_t) == 0:
        raise UserError(bag.source, f"topic {robot.command_topic} holds no usable command", field="topics.command")
    motion = _Motion.of(streams, robot, bag.source, report)
    if streams.receive_shift_s:
        report.notes.append(
            f"header stamps run {streams.receive_shift_s:+.1f} s from when the log received the messages (simulated time?); "
            "unstamped messages (a Twist command) are moved onto the stamps' clock"
        )
    camera, undistort = camera_from_info(streams.info, robot, bag.source, streams.static, report.notes)
    if req.check_camera is not None:
        req.check_camera(camera)
    placement = _Placement.of(streams.odom[:, :2], _reference_path(req, streams, report))
    preference = PreferenceSetConfig()
    conversion = _Conversion(
        req.rate_hz,
        robot.max_gap_s,
        preference.control,
        robot.labels.lut(req.classes),
        robot.labels.listed(),
        undistort,
        placement.shift,
        robot.labels,
    )
    scenario = _scenario(bag_path_name(bag.source), placement.path, placement.start(streams.odom[0]), tuple(placement.size), req.classes)
    meta = _meta(req, scenario, camera, preference, placement)
    progress = Progress("import", sum(c.msgcount for c in seg_conns), enabled=show_progress)
    frames = _Frames(streams, motion, conversion, RecordingWriter(out, meta, scenario), report)
    try:
        _stream_images(req, seg_conns, (camera.height_px, camera.width_px), frames, progress)
    except UserError:
        frames.writer.abort()  # nothing half-written: a replaced recording stays as it was
        raise
    frames.close(bag.source, progress)


def _reference_path(req: _Request, streams: _Streams, report: ImportReport) -> np.ndarray:
    """The path (N, 2) [m] in the odometry frame: the path topic's, the path file's, or else the
    driven odometry smoothed; where it came from goes in the report."""
    robot = req.robot
    if streams.path is not None:
        report.path_source = f"{robot.path_topic} ({len(streams.path)} poses)"
        return streams.path
    if robot.path_file is not None:
        path = load_waypoints(robot.path_file, robot.source)
        report.path_source = f"{robot.path_file} (path_file)"
        return path
    try:
        path = smooth_path(streams.odom[:, :2])
    except ValueError as exc:
        raise UserError(req.bag.source, f"no path topic or path_file, and {exc}", field="topics.path") from None
    report.path_source = f"the driven odometry, smoothed over {2 * PATH_SMOOTHING_M:g} m ({len(path)} points)"
    return path


@dataclass(frozen=True)
class _Placement:
    """Where the odometry frame lies in the recording's map, which starts at 0."""

    shift: np.ndarray  # (2,) [m] added to odometry x and y
    size: np.ndarray  # (2,) [m] the map's extent
    path: np.ndarray  # (N, 2) [m] the reference path, shifted

    @classmethod
    def of(cls, odom_xy: np.ndarray, path: np.ndarray) -> _Placement:
        """The map around the driven positions ``odom_xy`` (N, 2) and ``path`` (M, 2) [m]."""
        everything = np.concatenate([odom_xy, path])
        # The odometry frame may start anywhere (often at the robot); the recording's map starts at 0,
        # so an axis with negative coordinates is shifted (coordinates already >= 0 stay as they are).
        low = everything.min(axis=0)
        shift = np.where(low >= 0.0, 0.0, MAP_MARGIN_M - low)
        return cls(shift, everything.max(axis=0) + shift + MAP_MARGIN_M, path + shift)

    def start(self, odom_pose: np.ndarray) -> tuple[float, float, float]:
        """An odometry pose (x, y [m], yaw [rad]) in the map."""
        x0, y0, yaw0 = odom_pose
        return x0 + self.shift[0], y0 + self.shift[1], yaw0


def _meta(req: _Request, scenario: dict, camera: CameraConfig, preference: PreferenceSetConfig, placement: _Placement) -> RecordingMeta:
    """The recording's meta.json entries of an import."""
    return RecordingMeta(
        scenario=scenario["name"],
        camera=camera,
        preference_set=preference,
        sim=SimMeta(req.rate_hz),
        classes=req.classes,
        profile=tuple(req.profile.order) if req.profile is not None else None,
        driver=ImportedInfo(req.bag.source, req.robot.source, req.robot.labels.name),
        path=tuple((x, y) for x, y in placement.path.tolist()),
        origin_shift_m=(float(placement.shift[0]), float(placement.shift[1])),
    )


def _stream_images(req: _Request, seg_conns: list, shape: tuple[int, int], frames: _Frames, progress: Progress) -> None:
    """Decode the segmentation images one at a time, put back in stamp order through a short
    reorder buffer, and hand each to ``frames``; ``shape`` is the camera's (H, W)."""
    bag, report = req.bag, frames.report
    heap: list = []
    last_image_t = None
    for seq, (conn, t_ns, msg) in enumerate(bag.messages(seg_conns)):
        try:
            t = _stamp(msg, t_ns, frames.streams.receive_shift_s)
        except AttributeError as exc:
            raise UserError(bag.source, f"topic {conn.topic}: no header stamp ({exc})", field="topics.segmentation") from None
        ids = _decode(conn, msg, bag.source, req.robot.labels, (t_ns - bag.reader.start_time) * 1e-9)
        report.images += 1
        if ids.shape != shape:
            raise UserError(
                bag.source,
                f"topic {conn.topic}: image {ids.shape[1]} x {ids.shape[0]}, camera_info says {shape[1]} x {shape[0]}",
                field="topics.segmentation",
            )
        if last_image_t is not None and t - last_image_t > req.robot.max_gap_s:
            report.image_gaps += 1
            report.longest_gap_s = max(report.longest_gap_s, t - last_image_t)
        last_image_t = t if last_image_t is None else max(last_image_t, t)
        heapq.heappush(heap, (t, seq, ids))
        if len(heap) > REORDER_FRAMES:
            frames.emit(*heapq.heappop(heap)[::2])
        progress.update(report.images, f"{frames.writer.count} frames")
    while heap:
        frames.emit(*heapq.heappop(heap)[::2])


@dataclass(frozen=True)
class _Conversion:
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
class _Motion:
    """Each frame's (v, w) over time: the operator's commands, each in force until the next
    (zero-order hold), or the vehicle's motion measured at the odometry's stamps, interpolated."""

    t: np.ndarray  # (N,) [s], sorted
    vw: np.ndarray  # (N, 2) v [m/s], w [rad/s]
    held: bool  # commands, held; else measured motion, interpolated

    @classmethod
    def of(cls, streams: _Streams, robot: RobotConfig, source: str, report: ImportReport) -> _Motion:
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
        vw = _pose_differences(streams.odom_t, poses)
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


def _pose_differences(t: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """(v [m/s], w [rad/s]) (N, 2) at each of ``poses`` (N, 3: x, y, unwrapped yaw) stamped ``t`` (N,) [s], sorted.

    A centred difference of the poses POSE_DIFFERENCE_HALF_S before and after each one
    (interpolated; one-sided at the log's ends), over a window rather than between neighbours so
    that jitter in the stamps and positions averages out: v is the displacement along the heading
    (negative when reversing) over dt, w the yaw change, wrapped, over dt. NaN where dt is 0.
    """
    lo = np.maximum(t - POSE_DIFFERENCE_HALF_S, t[0])
    hi = np.minimum(t + POSE_DIFFERENCE_HALF_S, t[-1])
    before = np.stack([np.interp(lo, t, poses[:, k]) for k in range(3)], axis=1)
    after = np.stack([np.interp(hi, t, poses[:, k]) for k in range(3)], axis=1)
    step = after - before
    forward = step[:, 0] * np.cos(poses[:, 2]) + step[:, 1] * np.sin(poses[:, 2])
    turn = wrap_angle(step[:, 2])
    dt = np.where(hi > lo, hi - lo, math.nan)
    return np.stack([forward / dt, turn / dt], axis=1)


@dataclass
class _Frames:
    """The recording being written: each image kept gets the odometry pose interpolated at its
    stamp and the command in force then (or the motion measured then); what is skipped is counted
    in the report."""

    streams: _Streams
    motion: _Motion
    conversion: _Conversion
    writer: RecordingWriter
    report: ImportReport
    pixels: int = 0
    unmapped: int = 0  # pixels whose id the label map does not list
    unknown: int = 0  # pixels unknown after mapping
    last_t: float = -math.inf  # the stamp of the last frame kept [s]
    t_first: float | None = None  # the stamp of the first frame kept [s]
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
        c = self.conversion
        v, w = vw  # not None, and v >= MIN_SPEED_MPS: _skip_reason refuses the others
        w_set = float(np.clip(w * c.control.v_mps / v, min(c.control.w_rps), max(c.control.w_rps)))  # same curvature at the set's speed
        pose = self._pose_at(t)
        image = self._classes(ids, t)
        if self.t_first is None:
            self.t_first = t
        self.writer.append(t - self.t_first, pose, image, (v, w), int(c.control.label_of(w_set)))
        self.speeds.append(v)
        self.last_t = t

    def _skip_reason(self, t: float, vw: tuple[float, float] | None) -> str | None:
        """Why the image stamped ``t`` [s], whose (v, w) is ``vw``, makes no frame, or None."""
        rate_hz, odom_t = self.conversion.rate_hz, self.streams.odom_t
        if t <= self.last_t:
            return "images out of order beyond the reorder buffer"
        if t - self.last_t < 0.75 / rate_hz:  # a quarter period of slack for stamp jitter
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

    def _classes(self, ids: np.ndarray, t: float) -> np.ndarray:
        """Class ids (H, W) uint8 of the label ids ``ids`` (the image stamped ``t`` [s]), undistorted;
        the pixels counted. An id the label map does not list is an error unless the map makes it unknown."""
        c = self.conversion
        unmapped = int(np.count_nonzero(~c.listed[ids]))
        if unmapped:
            c.labels.refuse_unlisted(ids, f"the image stamped {t:.3f} s")
        image = c.lut[ids]
        if c.undistort is not None:
            image = np.where(c.undistort >= 0, image.reshape(-1)[np.maximum(c.undistort, 0)], UNKNOWN).astype(np.uint8)
        self.pixels += ids.size
        self.unmapped += unmapped
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
        report.duration_s = float(self.last_t - self.t_first) + 1.0 / self.conversion.rate_hz
        report.unmapped_share = self.unmapped / max(self.pixels, 1)
        report.unknown_share = self.unknown / max(self.pixels, 1)
        writer.close({"completed": True, "collisions": 0, "duration_s": round(report.duration_s, 3), "import": report.lines()})


def bag_path_name(source: str) -> str:
    """A scenario name from a bag's file name."""
    stem = Path(source.rstrip("/")).name.split(".")[0] or "bag"
    name = "".join(ch if ch.isalnum() or ch == "_" else "_" for ch in stem)
    return name if name[0].isalpha() else f"bag_{name}"
