"""ROS messages built with ``rosbags``: the stamps, headers, poses, transforms, images and camera
calibration that the synthetic robot logs and the MCAP export both write, and the connections
they are written to.

Every builder takes the typestore whose message classes it makes, so the same builders serve
ROS 1 (``ros1=True``: headers with ``seq``, CameraInfo's matrices in upper case) and ROS 2.
Stamps come from an epoch-like clock: time 0 [s] is :data:`EPOCH_S` seconds after 1970.
The other direction, ROS messages decoded into terrapref's data, is :mod:`terrapref.interop.ros_decode`.
"""

from __future__ import annotations

import functools
import io
import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from PIL import Image as PILImage

from terrapref.camera.pinhole import ROS_PIXEL_CENTRE_PX
from terrapref.extras import needs
from terrapref.pngio import depth_to_millimetres

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

    from terrapref.camera import CameraConfig
    from terrapref.groundmap.costmap import Costmap

Message = Any  # an instance of a message class that rosbags makes at run time from the typestore
EPOCH_S = 1_700_000_000
_NUMERIC = {
    "bool": bool,
    "byte": np.uint8,
    "char": np.uint8,
    "int8": np.int8,
    "uint8": np.uint8,
    "int16": np.int16,
    "uint16": np.uint16,
    "int32": np.int32,
    "uint32": np.uint32,
    "int64": np.int64,
    "uint64": np.uint64,
    "float32": np.float32,
    "float64": np.float64,
}


def typestore(ros1: bool = False) -> Typestore:
    """ROS 1 Noetic's or ROS 2 Humble's message types, tf2_msgs/TFMessage among them: one store
    a process, shared (read it, register nothing into it), so that each type's serialisers are
    generated once a process, not again at each export, import or node within it (about 0.1 s
    each time)."""
    return _typestore(bool(ros1))


@functools.cache
def _typestore(ros1: bool) -> Typestore:
    """:func:`typestore`'s store, made on its first call."""
    with needs("robot", "ROS messages"):
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    if "tf2_msgs/msg/TFMessage" not in ts.fielddefs:  # not in rosbags' ROS 1 store: registered from its definition
        ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    own = (_GRID_MAP_MSGS_ROS1 if ros1 else {**_FOXGLOVE_MSGS, **_GRID_MAP_MSGS, **_NAV2_MSGS}).items()
    for name, definition in own:  # one at a time: each may use the ones before it
        ts.register(get_types_from_msg(definition, name))
    return ts


# Foxglove's own message types (the foxglove_msgs package), as far as the files use them.
_FOXGLOVE_MSGS = {
    "foxglove_msgs/msg/Vector2": "float64 x\nfloat64 y\n",
    "foxglove_msgs/msg/PackedElementField": "uint8 UINT8=1\nuint8 INT8=2\nstring name\nuint32 offset\nuint8 type\n",
    "foxglove_msgs/msg/Grid": (
        "builtin_interfaces/Time timestamp\nstring frame_id\ngeometry_msgs/Pose pose\nuint32 column_count\n"
        "foxglove_msgs/Vector2 cell_size\nuint32 row_stride\nuint32 cell_stride\n"
        "foxglove_msgs/PackedElementField[] fields\nuint8[] data\n"
    ),
}


# grid_map's message types (the grid_map_msgs package), ROS 2's and ROS 1's (whose GridMapInfo
# holds the header), and Nav2's costmap filter description (nav2_msgs).
_GRID_MAP = (
    "string[] layers\nstring[] basic_layers\nstd_msgs/Float32MultiArray[] data\nuint16 outer_start_index\nuint16 inner_start_index\n"
)
_GRID_MAP_INFO = "float64 resolution\nfloat64 length_x\nfloat64 length_y\ngeometry_msgs/Pose pose\n"
_GRID_MAP_MSGS = {
    "grid_map_msgs/msg/GridMapInfo": _GRID_MAP_INFO,
    "grid_map_msgs/msg/GridMap": "std_msgs/Header header\ngrid_map_msgs/GridMapInfo info\n" + _GRID_MAP,
}
_GRID_MAP_MSGS_ROS1 = {
    "grid_map_msgs/msg/GridMapInfo": "std_msgs/Header header\n" + _GRID_MAP_INFO,
    "grid_map_msgs/msg/GridMap": "grid_map_msgs/GridMapInfo info\n" + _GRID_MAP,
}
_NAV2_MSGS = {
    "nav2_msgs/msg/CostmapFilterInfo": "std_msgs/Header header\nuint8 type\nstring filter_mask_topic\nfloat32 base\nfloat32 multiplier\n",
}


@dataclass(frozen=True)
class Topics:
    """A bag writer's connections by role; each message is serialised for its connection's type."""

    writer: Any  # a rosbags rosbag1 or rosbag2 Writer, open
    typestore: Typestore
    connections: dict[str, Any]
    ros1: bool = False
    said: dict[str, Any] = field(default_factory=dict)  # what :meth:`write_changed` last wrote, by role

    def write(self, role: str, t_ns: int, msg: Message) -> None:
        """Write ``msg`` on the connection of ``role`` at bag time ``t_ns`` [ns]."""
        conn = self.connections[role]
        data = self.typestore.serialize_ros1(msg, conn.msgtype) if self.ros1 else self.typestore.serialize_cdr(msg, conn.msgtype)
        self.writer.write(conn, t_ns, data)

    def write_changed(self, role: str, t_ns: int, msg: Message, content: Any) -> None:
        """Write ``msg`` as :meth:`write` does where its ``content`` differs from the last written on
        ``role`` (or none was): Nav2 takes each speed filter info as a new filter, and subscribes
        to its mask again."""
        if self.said.get(role) != content:
            self.write(role, t_ns, msg)
            self.said[role] = content


# Kept for late subscribers, as a robot's static transform publisher and map servers keep theirs:
# the static transforms, and the maps a run writes (the costmap and its layers, and Nav2's speed
# filter, whose info and mask Nav2 subscribes to transient-local and would not hear otherwise).
LATCHED_TOPICS = frozenset(
    {
        "/tf_static",
        "/terrapref/costmap",
        "/terrapref/costmap_grid",
        "/terrapref/grid_map",
        "/terrapref/speed_filter_info",
        "/terrapref/speed_mask",
    }
)


def add_topics(writer: Any, ts: Typestore, topics: dict[str, tuple[str, str]], ros1: bool = False) -> Topics:
    """Connections for ``{role: (topic, msgtype)}``, added to ``writer`` in that order; the topics
    of :data:`LATCHED_TOPICS` offered latched (ROS 1) or transient-local (ROS 2), so that a bag's
    player hands them to subscribers that come late, and to those that ask for them
    transient-local (a transient-local subscription does not match a volatile publisher)."""
    connections = {
        role: writer.add_connection(topic, msgtype, typestore=ts, **(_latched(ros1) if topic in LATCHED_TOPICS else {}))
        for role, (topic, msgtype) in topics.items()
    }
    return Topics(writer, ts, connections, ros1)


def _latched(ros1: bool) -> dict[str, Any]:
    """The keyword arguments of rosbags' ``add_connection`` that offer a topic latched."""
    if ros1:
        return {"latching": 1}
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    unset = QosTime(0, 0)
    return {
        "offered_qos_profiles": [
            Qos(
                QosHistory.KEEP_LAST,
                1,
                QosReliability.RELIABLE,
                QosDurability.TRANSIENT_LOCAL,
                unset,
                unset,
                QosLiveliness.AUTOMATIC,
                unset,
                False,
            )
        ]
    }


def zeroed(ts: Typestore, msgtype: str, **fields: Any) -> Message:
    """A message of ``msgtype`` with ``fields`` set and every other field at its zero value
    (nested messages included)."""
    _, defs = ts.fielddefs[msgtype]
    msg = ts.types[msgtype](**{name: _zero(ts, node) for name, node in defs})
    for name, value in fields.items():
        setattr(msg, name, value)
    return msg


def _zero(ts: Typestore, node: tuple) -> Any:
    """The zero value of one field definition of rosbags' typestore."""
    from rosbags.typesys.store import Nodetype

    kind, detail = node
    if kind == Nodetype.BASE:
        name = detail[0]
        return "" if name == "string" else (False if name == "bool" else (0.0 if name.startswith("float") else 0))
    if kind == Nodetype.NAME:
        return zeroed(ts, detail)
    sub, length = detail
    if sub[0] == Nodetype.BASE and sub[1][0] in _NUMERIC:
        return np.zeros(length if kind == Nodetype.ARRAY else 0, dtype=_NUMERIC[sub[1][0]])
    return [_zero(ts, sub) for _ in range(length)] if kind == Nodetype.ARRAY else []


def epoch_ns(t_s: float) -> int:
    """Time ``t_s`` [s] on the epoch-like clock, in ns."""
    return int(round((EPOCH_S + t_s) * 1e9))


def stamp(ts: Typestore, t_s: float) -> Message:
    """builtin_interfaces/Time of ``t_s`` [s] on the epoch-like clock."""
    ns = epoch_ns(t_s)
    return ts.types["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def header(ts: Typestore, t_s: float, frame_id: str, ros1: bool = False) -> Message:
    """std_msgs/Header stamped ``t_s`` [s] in ``frame_id`` (with ``seq`` 0 in ROS 1)."""
    H = ts.types["std_msgs/msg/Header"]
    return H(seq=0, stamp=stamp(ts, t_s), frame_id=frame_id) if ros1 else H(stamp=stamp(ts, t_s), frame_id=frame_id)


def point(ts: Typestore, x: float, y: float, z: float = 0.0) -> Message:
    """geometry_msgs/Point at (x, y, z) [m]."""
    return ts.types["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=float(z))


def vector3(ts: Typestore, x: float = 0.0, y: float = 0.0, z: float = 0.0) -> Message:
    """geometry_msgs/Vector3 (x, y, z)."""
    return ts.types["geometry_msgs/msg/Vector3"](x=float(x), y=float(y), z=float(z))


def quaternion(ts: Typestore, xyzw: tuple[float, float, float, float]) -> Message:
    """geometry_msgs/Quaternion of the components (x, y, z, w) as given."""
    return ts.types["geometry_msgs/msg/Quaternion"](x=xyzw[0], y=xyzw[1], z=xyzw[2], w=xyzw[3])


def yaw_quaternion(ts: Typestore, yaw_rad: float) -> Message:
    """geometry_msgs/Quaternion of a turn by ``yaw_rad`` about z."""
    return quaternion(ts, (0.0, 0.0, math.sin(yaw_rad / 2), math.cos(yaw_rad / 2)))


def rpy_quaternion(ts: Typestore, roll_rad: float, pitch_rad: float, yaw_rad: float) -> Message:
    """geometry_msgs/Quaternion of roll about x, then pitch about y, then yaw about z (fixed axes)."""
    cr, sr, cp, sp = math.cos(roll_rad / 2), math.sin(roll_rad / 2), math.cos(pitch_rad / 2), math.sin(pitch_rad / 2)
    cy, sy = math.cos(yaw_rad / 2), math.sin(yaw_rad / 2)
    return quaternion(
        ts, (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)
    )


def pose(ts: Typestore, x: float, y: float, orientation: Message, z: float = 0.0) -> Message:
    """geometry_msgs/Pose at (x, y, z) [m] turned by ``orientation`` (a Quaternion)."""
    return ts.types["geometry_msgs/msg/Pose"](position=point(ts, x, y, z), orientation=orientation)


def path_message(ts: Typestore, xy: Iterable[tuple[float, float]], ros1: bool = False, t_s: float = 0.0) -> Message:
    """nav_msgs/Path through the points ``xy`` [m] of the odom frame, stamped at ``t_s`` [s]."""
    PoseStamped = ts.types["geometry_msgs/msg/PoseStamped"]
    poses = [PoseStamped(header=header(ts, t_s, "odom", ros1), pose=pose(ts, x, y, yaw_quaternion(ts, 0.0))) for x, y in xy]
    return ts.types["nav_msgs/msg/Path"](header=header(ts, t_s, "odom", ros1), poses=poses)


def transform(ts: Typestore, parent: Message, child_frame_id: str, xyz: tuple[float, float, float], rotation: Message) -> Message:
    """geometry_msgs/TransformStamped from the frame of the header ``parent`` to ``child_frame_id``:
    the child's origin at ``xyz`` [m], turned by ``rotation`` (a Quaternion)."""
    moved = ts.types["geometry_msgs/msg/Transform"](translation=vector3(ts, *xyz), rotation=rotation)
    return ts.types["geometry_msgs/msg/TransformStamped"](header=parent, child_frame_id=child_frame_id, transform=moved)


OPTICAL_FRAME = "camera_optical"  # the frame images and calibration are stamped in: z forward, x right, y down (REP 103)


def camera_mount(
    ts: Typestore, camera: CameraConfig, ros1: bool = False, t_s: float = 0.0, frames: tuple[str, str] = ("camera_link", OPTICAL_FRAME)
) -> list[Message]:
    """The camera's mounting as a robot publishes it on /tf_static, stamped ``t_s`` [s]:
    base_link -> camera_link (x forward, pitched down by the mount's pitch and turned by its yaw)
    -> :data:`OPTICAL_FRAME` (or the two ``frames`` named)."""
    link, optical_frame = frames
    mount = transform(
        ts,
        header(ts, t_s, "base_link", ros1),
        link,
        (camera.mount_forward_m, 0.0, camera.mount_height_m),
        rpy_quaternion(ts, 0.0, math.radians(camera.pitch_deg), math.radians(camera.yaw_deg)),
    )
    optical = transform(ts, header(ts, t_s, link, ros1), optical_frame, (0.0, 0.0, 0.0), quaternion(ts, (-0.5, 0.5, -0.5, 0.5)))
    return [mount, optical]


def tf_message(ts: Typestore, transforms: list[Message]) -> Message:
    """tf2_msgs/TFMessage holding ``transforms``."""
    return ts.types["tf2_msgs/msg/TFMessage"](transforms=transforms)


def twist(ts: Typestore, v_mps: float, w_rps: float) -> Message:
    """geometry_msgs/Twist of forward speed ``v_mps`` [m/s] and turn rate ``w_rps`` [rad/s]."""
    return ts.types["geometry_msgs/msg/Twist"](linear=vector3(ts, x=v_mps), angular=vector3(ts, z=w_rps))


def occupancy_grid(ts: Typestore, stamped: Message, cost: np.ndarray, resolution_m: float, origin: tuple[float, float]) -> Message:
    """nav_msgs/OccupancyGrid of ``cost`` (H, W) int8 (row i along y, 0-100, -1 unknown) with
    cell (0, 0)'s corner at ``origin`` [m] in the frame of the header ``stamped``."""
    T = ts.types
    h, w = cost.shape
    info = T["nav_msgs/msg/MapMetaData"](
        map_load_time=stamped.stamp,
        resolution=float(resolution_m),
        width=w,
        height=h,
        origin=pose(ts, float(origin[0]), float(origin[1]), rpy_quaternion(ts, 0.0, 0.0, 0.0)),
    )
    return T["nav_msgs/msg/OccupancyGrid"](header=stamped, info=info, data=np.ascontiguousarray(cost, dtype=np.int8).ravel())


def grid_map(
    ts: Typestore, stamped: Message, layers: dict[str, np.ndarray], resolution_m: float, origin: tuple[float, float], ros1: bool = False
) -> Message:
    """grid_map_msgs/GridMap of ``layers`` (each (H, W) float32, row i along y, NaN unknown) whose
    cell (0, 0) has its corner at ``origin`` [m] in the frame of the header ``stamped``.

    grid_map's layout: the map's pose is its centre; its matrices have a row per x (index 0 at
    the largest x) and a column per y (index 0 at the largest y), and are stored column-major
    (``column_index`` outer), so each layer goes out as ``layer[::-1, ::-1]`` row by row."""
    T = ts.types
    h, w = next(iter(layers.values())).shape
    centre = pose(ts, origin[0] + 0.5 * w * resolution_m, origin[1] + 0.5 * h * resolution_m, rpy_quaternion(ts, 0.0, 0.0, 0.0))
    info = {"resolution": float(resolution_m), "length_x": w * float(resolution_m), "length_y": h * float(resolution_m), "pose": centre}
    dim = T["std_msgs/msg/MultiArrayDimension"]
    layout = T["std_msgs/msg/MultiArrayLayout"](
        dim=[dim(label="column_index", size=h, stride=h * w), dim(label="row_index", size=w, stride=w)], data_offset=0
    )
    data = [
        T["std_msgs/msg/Float32MultiArray"](layout=layout, data=np.ascontiguousarray(layer[::-1, ::-1], dtype=np.float32).ravel())
        for layer in layers.values()
    ]
    grid = {"layers": list(layers), "basic_layers": [], "data": data, "outer_start_index": 0, "inner_start_index": 0}
    if ros1:
        return T["grid_map_msgs/msg/GridMap"](info=T["grid_map_msgs/msg/GridMapInfo"](header=stamped, **info), **grid)
    return T["grid_map_msgs/msg/GridMap"](header=stamped, info=T["grid_map_msgs/msg/GridMapInfo"](**info), **grid)


def grid_map_layer(msg: Message, name: str) -> np.ndarray:
    """The layer ``name`` of a grid_map_msgs/GridMap, (H, W) float32 with row i along y as
    :func:`grid_map` takes it."""
    array = msg.data[list(msg.layers).index(name)]
    h, w = array.layout.dim[0].size, array.layout.dim[1].size
    return np.asarray(array.data, dtype=np.float32).reshape(h, w)[::-1, ::-1]


SPEED_PERCENT, SPEED_ABSOLUTE = 1, 2  # CostmapFilterInfo's types of a speed filter: percent of the top speed, or m/s


SPEED_MASK_NO_LIMIT = 0  # Nav2's speed-filter mask value for no limit (its filter_values.hpp)


def speed_filter(
    ts: Typestore, stamped: Message, speed_mps: np.ndarray, top_mps: float, mask_topic: str, percent: bool = True
) -> tuple[Message, np.ndarray]:
    """Nav2's speed filter of ``speed_mps`` (H, W) [m/s, NaN unknown]: its nav2_msgs/CostmapFilterInfo
    (naming ``mask_topic``) and the mask's values (H, W) int8 for an OccupancyGrid. Nav2 reads a
    cell's limit as ``base + multiplier * value`` and 0 as no limit: in percent of ``top_mps``
    (type 1: base 0, multiplier 1) or in m/s (type 2: base 0, multiplier ``top_mps / 100``), each
    value rounded to the nearest step and at least 1 (a learned speed is never "no limit");
    unknown ground 0, no limit (Nav2's speed filter takes -1 as an invalid cell: it logs an
    error and keeps the last limit)."""
    known = np.isfinite(speed_mps)
    share = np.clip(np.where(known, speed_mps, 0.0) / top_mps, 0.0, 1.0)
    mask = np.where(known, np.maximum(np.round(100.0 * share), 1), SPEED_MASK_NO_LIMIT).astype(np.int8)
    info = ts.types["nav2_msgs/msg/CostmapFilterInfo"](
        header=stamped,
        type=SPEED_PERCENT if percent else SPEED_ABSOLUTE,
        filter_mask_topic=mask_topic,
        base=0.0,
        multiplier=1.0 if percent else float(top_mps) / 100.0,
    )
    return info, mask


def filter_info_said(info: Message) -> tuple:
    """What a speed filter's nav2_msgs/CostmapFilterInfo says, its header aside: Nav2 takes an info
    that says something else as a new filter (it warns and subscribes to the mask again), so one
    is sent again only when this changes."""
    return (info.type, info.filter_mask_topic, info.base, info.multiplier)


GRID_FIELDS = (
    ("cost", 0, 2),
    ("red", 1, 1),
    ("green", 2, 1),
    ("blue", 3, 1),
    ("alpha", 4, 1),
)  # name, byte offset, PackedElementField type (2 int8, 1 uint8)


def foxglove_grid(ts: Typestore, t_s: float, frame_id: str, costmap: Costmap) -> Message:
    """foxglove_msgs/Grid of ``costmap`` in ``frame_id``, stamped ``t_s`` [s]: per cell its cost as
    int8 (0-100, -1 unknown, as in OccupancyGrid) and its colour
    (:func:`terrapref.groundmap.costmap.cost_colours`), 5 bytes a cell."""
    from terrapref.groundmap.costmap import cost_colours

    T = ts.types
    h, w = costmap.cost.shape
    cells = np.zeros((h, w), dtype=[("cost", "i1"), ("rgba", "u1", 4)])
    cells["cost"] = costmap.cost
    cells["rgba"] = cost_colours(costmap.cost)
    fields = [T["foxglove_msgs/msg/PackedElementField"](name=name, offset=offset, type=kind) for name, offset, kind in GRID_FIELDS]
    corner = pose(ts, float(costmap.origin[0]), float(costmap.origin[1]), rpy_quaternion(ts, 0.0, 0.0, 0.0))
    return T["foxglove_msgs/msg/Grid"](
        timestamp=stamp(ts, t_s),
        frame_id=frame_id,
        pose=corner,
        column_count=w,
        cell_size=T["foxglove_msgs/msg/Vector2"](x=costmap.resolution_m, y=costmap.resolution_m),
        row_stride=5 * w,
        cell_stride=5,
        fields=fields,
        data=cells.view(np.uint8).ravel(),
    )


def odometry(ts: Typestore, stamped: Message, base_pose: Message, velocity: tuple[float, float] | None = None) -> Message:
    """nav_msgs/Odometry of base_link at ``base_pose`` in the frame of the header ``stamped``, its
    twist (in base_link) the ``velocity`` v [m/s] forward and w [rad/s] (None: 0); zero covariances."""
    T = ts.types
    v, w = velocity if velocity is not None else (0.0, 0.0)
    at = T["geometry_msgs/msg/PoseWithCovariance"](pose=base_pose, covariance=np.zeros(36))
    moving = T["geometry_msgs/msg/TwistWithCovariance"](
        twist=T["geometry_msgs/msg/Twist"](linear=vector3(ts, v, 0.0, 0.0), angular=vector3(ts, 0.0, 0.0, w)), covariance=np.zeros(36)
    )
    return T["nav_msgs/msg/Odometry"](header=stamped, child_frame_id="base_link", pose=at, twist=moving)


def camera_info(ts: Typestore, stamped: Message, camera: CameraConfig, ros1: bool = False) -> Message:
    """sensor_msgs/CameraInfo of ``camera``: its image size and K (its principal point in ROS's
    pixel coordinates: :data:`~terrapref.camera.pinhole.ROS_PIXEL_CENTRE_PX`), no distortion."""
    fx, fy, cx, cy = camera.intrinsics
    cx, cy = cx - ROS_PIXEL_CENTRE_PX, cy - ROS_PIXEL_CENTRE_PX
    roi = ts.types["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    matrices = {
        "d": np.zeros(5),
        "k": np.array([fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0]),
        "r": np.eye(3).ravel(),
        "p": np.array([fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0]),
    }
    return ts.types["sensor_msgs/msg/CameraInfo"](
        header=stamped,
        height=camera.height_px,
        width=camera.width_px,
        distortion_model="plumb_bob",
        binning_x=0,
        binning_y=0,
        roi=roi,
        **{(k.upper() if ros1 else k): v for k, v in matrices.items()},
    )


def png(ids: np.ndarray, palette: np.ndarray | None = None) -> np.ndarray:
    """The bytes (as uint8) of a single-channel png of ``ids`` (H, W) uint8; with ``palette``
    (256, 3), an indexed-colour one that viewers show in its colours (a third of the work of
    an RGB image)."""
    buf = io.BytesIO()
    image = PILImage.fromarray(ids)
    if palette is not None:
        image.putpalette(palette.astype(np.uint8).ravel().tolist())
    image.save(buf, format="PNG", compress_level=1)
    return np.frombuffer(buf.getvalue(), dtype=np.uint8)


def depth_image(ts: Typestore, stamped: Message, depth: np.ndarray) -> Message:
    """sensor_msgs/Image of a depth image (H, W) [m, NaN where nothing is seen] as REP 118's 16UC1:
    little-endian millimetres, 0 where nothing is seen (terrapref.pngio.depth_to_millimetres)."""
    mm = depth_to_millimetres(depth).astype("<u2")
    h, w = mm.shape
    data = np.frombuffer(mm.tobytes(), dtype=np.uint8)
    return ts.types["sensor_msgs/msg/Image"](header=stamped, height=h, width=w, encoding="16UC1", is_bigendian=0, step=2 * w, data=data)


def compressed_image(ts: Typestore, stamped: Message, image_format: str, data: np.ndarray) -> Message:
    """sensor_msgs/CompressedImage of the encoded bytes ``data`` (uint8) in ``image_format``."""
    return ts.types["sensor_msgs/msg/CompressedImage"](header=stamped, format=image_format, data=data)
