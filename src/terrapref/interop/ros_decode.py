"""ROS messages decoded into what terrapref uses: header stamps, yaw and the body's attitude,
paths, label images of every encoding a robot sends ids in, depth images (REP 118), the camera's
calibration, and its mounting from /tf_static.

Messages are read by attribute (``header.stamp``, ``pose.orientation``, ``data``), so the same
functions serve rosbags' messages (an import, ``play``), rospy's (the ROS 1 node) and the
cyclonedds structs of the ROS 2 node; none needs a typestore. The other direction, terrapref's
data built into ROS messages, is :mod:`terrapref.interop.ros_messages`.
"""

from __future__ import annotations

import io
import math
from types import SimpleNamespace

import numpy as np
from PIL import Image as PILImage

from terrapref.camera import CameraConfig
from terrapref.camera.pinhole import ROS_PIXEL_CENTRE_PX
from terrapref.errors import UserError, one_line
from terrapref.interop.labels import LabelMap
from terrapref.interop.robot import RobotConfig
from terrapref.pngio import millimetres_to_depth

COMPRESSED_DEPTH_HEADER = 12  # compressed_depth_image_transport's ConfigHeader before the png: format, two floats


def time_s(stamp) -> float:
    """A ROS time [s] (ROS 1's ``secs``/``nsecs`` or ROS 2's ``sec``/``nanosec``)."""
    sec = getattr(stamp, "sec", None)
    if sec is None:
        sec = stamp.secs
    nsec = getattr(stamp, "nanosec", None)
    if nsec is None:
        nsec = stamp.nsecs
    return int(sec) + int(nsec) * 1e-9


def stamp_s(header) -> float:
    """A header's stamp [s] (ROS 1's or ROS 2's)."""
    return time_s(header.stamp)


def message_time_s(msg, fallback_ns: int, shift_s: float = 0.0) -> float:
    """The stamp [s] of ``msg``'s header (rosbags' ``sec``/``nanosec``); an unstamped message
    (stamp 0) is timed by ``fallback_ns``, when the log received it [ns], moved by ``shift_s`` [s]
    onto the stamps' clock."""
    stamp = msg.header.stamp
    ns = int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
    return ns * 1e-9 if ns > 0 else fallback_ns * 1e-9 + shift_s


UNIT_QUATERNION_LEAST = 1e-6  # a quaternion shorter than this turns the body no known way
UNIT_QUATERNION_SLACK = 1e-3  # a quaternion's length further than this from 1 is normalised, and said so


def unit_quaternion(q) -> tuple[SimpleNamespace | None, bool]:
    """The quaternion ``q`` (x, y, z, w) of unit length (None for one that is zero or not finite,
    which turns the body no known way: tf2 refuses it too), and whether it had to be normalised."""
    n = math.sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w)
    if not (math.isfinite(n) and n > UNIT_QUATERNION_LEAST):
        return None, False
    return SimpleNamespace(x=q.x / n, y=q.y / n, z=q.z / n, w=q.w / n), abs(n - 1.0) > UNIT_QUATERNION_SLACK


def yaw_rad(q) -> float:
    """The yaw [rad] of the quaternion ``q`` (x, y, z, w): its turn about z."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def pitch_roll_rad(q) -> tuple[float, float]:
    """The pitch and roll [rad] of the quaternion ``q`` (x, y, z, w), as yaw, pitch and roll turn
    the body in that order (REP 103: pitch positive nose down, roll positive left side up)."""
    pitch = math.asin(max(-1.0, min(1.0, 2.0 * (q.w * q.y - q.z * q.x))))
    roll = math.atan2(2.0 * (q.w * q.x + q.y * q.z), 1.0 - 2.0 * (q.x * q.x + q.y * q.y))
    return pitch, roll


def _rotation(q) -> np.ndarray:
    """The rotation matrix (3, 3) of the quaternion ``q`` (x, y, z, w), normalised first."""
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


def path_xy(msg) -> np.ndarray:
    """The positions (K, 2) x, y [m] of a nav_msgs/Path's poses (K may be 0 or 1)."""
    return np.array([(p.pose.position.x, p.pose.position.y) for p in msg.poses], dtype=float).reshape(-1, 2)


def static_transforms(msg) -> dict[str, tuple[str, np.ndarray, np.ndarray]]:
    """The transforms of a tf2_msgs/TFMessage: child frame -> (parent frame, translation (3,) [m],
    rotation (3, 3)), the frames named without a leading slash."""
    static = {}
    for tr in msg.transforms:
        v = tr.transform.translation
        static[str(tr.child_frame_id).lstrip("/")] = (
            str(tr.header.frame_id).lstrip("/"),
            np.array([v.x, v.y, v.z]),
            _rotation(tr.transform.rotation),
        )
    return static


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


def _field(msg, *names):
    """The first of the fields ``names`` that ``msg`` has (ROS 2 spells CameraInfo's matrices k and d, ROS 1 K and D)."""
    for name in names:
        if hasattr(msg, name):
            return getattr(msg, name)
    raise AttributeError(names[0])


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
    cx, cy = cx + ROS_PIXEL_CENTRE_PX, cy + ROS_PIXEL_CENTRE_PX  # K's principal point in this camera's pixel coordinates
    camera = CameraConfig(width_px=width, height_px=height, hfov_deg=hfov, fx=fx, fy=fy, cx=cx, cy=cy, **mount)
    # A centred pinhole with square pixels is written by its field of view, as terrapref's own
    # cameras are, so that a model trained in the simulator and a log of the same camera match.
    plain = CameraConfig(width_px=width, height_px=height, hfov_deg=round(hfov, 6), **mount)
    if plain.intrinsics == (fx, fy, cx, cy):
        camera = plain
    if not d.size or not np.any(d):
        return camera, None
    return camera, _undistortion(k, d, model, (height, width), source)


def check_depth_info(depth_info, info, robot: RobotConfig, source: str) -> None:
    """Refuse a depth camera calibration ``depth_info`` (None: none named, the label camera's is
    taken) whose image size or intrinsics K are not the label camera's ``info``: its images are
    not registered to the label images, and terrapref does not resample them."""
    if depth_info is None:
        return
    try:
        sizes = [(int(i.width), int(i.height)) for i in (depth_info, info)]
        ks = [np.asarray(_field(i, "k", "K"), dtype=float).reshape(3, 3) for i in (depth_info, info)]
    except (AttributeError, TypeError, ValueError) as exc:
        raise UserError(source, f"camera_info unreadable ({exc})", field="topics.depth_info") from None
    if sizes[0] != sizes[1] or not np.allclose(ks[0], ks[1], rtol=1e-6, atol=1e-9):
        (w, h), (lw, lh) = sizes
        fx, fy, cx, cy = (float(ks[0][0, 0]), float(ks[0][1, 1]), float(ks[0][0, 2]), float(ks[0][1, 2]))
        lfx, lfy, lcx, lcy = (float(ks[1][0, 0]), float(ks[1][1, 1]), float(ks[1][0, 2]), float(ks[1][1, 2]))
        raise UserError(
            source,
            f"{robot.topics['depth_info']} says the depth camera is {w} x {h}, fx {fx:g} fy {fy:g} cx {cx:g} cy {cy:g}; "
            f"the label camera ({robot.topics['camera_info']}) is {lw} x {lh}, fx {lfx:g} fy {lfy:g} cx {lcx:g} cy {lcy:g}: "
            f"depth must be registered to the label images (the same size and intrinsics; topics in {robot.source})",
            field="topics.depth_info",
        )


def _undistortion(k: np.ndarray, d: np.ndarray, model: str, shape: tuple[int, int], source: str) -> np.ndarray:
    """The nearest-pixel undistortion map (H, W) of a lens of intrinsics ``k`` (3, 3) and
    distortion ``d`` (plumb_bob's k1, k2, p1, p2[, k3]; rational_polynomial's k1, k2, p1, p2, k3,
    k4, k5, k6, the last three dividing the radial factor): the flat index of each pinhole pixel
    in the lens's image of ``shape`` (H, W), -1 where it falls outside; another model, too few or
    non-finite coefficients, or a lens that would show less than half the image, is a UserError."""
    fx, fy, cx, cy = k[0, 0], k[1, 1], k[0, 2], k[1, 2]
    height, width = shape
    if model not in ("plumb_bob", "rational_polynomial"):
        raise UserError(
            source,
            f"camera_info: distortion model {model!r} is not supported (plumb_bob and rational_polynomial are)",
            field="topics.camera_info",
        )
    if d.size < 4 or not np.isfinite(d).all():
        raise UserError(
            source,
            f"camera_info: {model} distortion {d.tolist()}: expected at least 4 finite coefficients (k1, k2, p1, p2, ...)",
            field="topics.camera_info",
        )
    k1, k2, p1, p2 = d[:4]
    k3 = d[4] if d.size > 4 else 0.0
    k4, k5, k6 = (d[5:8].tolist() + [0.0, 0.0, 0.0])[:3] if model == "rational_polynomial" else (0.0, 0.0, 0.0)
    v, u = np.mgrid[0:height, 0:width].astype(float)
    x, y = (u - cx) / fx, (v - cy) / fy
    r2 = x * x + y * y
    with np.errstate(all="ignore"):  # a wild lens overflows; its pixels fall outside and are counted below
        below = 1 + k4 * r2 + k5 * r2**2 + k6 * r2**3
        radial = (1 + k1 * r2 + k2 * r2**2 + k3 * r2**3) / np.where(below > 0, below, np.nan)
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        ud, vd = np.rint(fx * xd + cx), np.rint(fy * yd + cy)
        inside = (ud >= 0) & (ud < width) & (vd >= 0) & (vd < height)
    if np.count_nonzero(inside) < inside.size / 2:
        raise UserError(
            source,
            f"camera_info: {model} distortion {d.tolist()} maps {100 * (1 - np.count_nonzero(inside) / inside.size):.0f}% of the "
            "image outside the lens's own image: not a calibration",
            field="topics.camera_info",
        )
    flat = np.where(inside, vd, 0).astype(np.int64) * width + np.where(inside, ud, 0).astype(np.int64)
    return np.where(inside, flat, -1)  # -1: the pinhole pixel falls outside the lens's image


def label_ids(msg, msgtype: str, topic: str, source: str, labels: LabelMap | None = None, t_s: float | None = None) -> np.ndarray:
    """Label ids (H, W) uint8 or uint16 of one segmentation message ``msg`` of ``msgtype``
    (sensor_msgs/msg/Image or .../CompressedImage) on ``topic``: mono8, mono16, rgb8 or bgr8 (through
    the label map's colour table ``labels``), png or a 16UC1 compressedDepth png. ``t_s``, when the
    log received it from its start [s], names it in an error.

    Raises:
        UserError: about ``source``: an encoding that holds no label ids, or data that does not hold the image.
    """
    if msgtype == "sensor_msgs/msg/CompressedImage":
        return _decode_png(msg, topic, source, t_s)
    encoding = str(msg.encoding).lower()
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    if encoding in ("mono8", "8uc1"):
        dtype = np.dtype(np.uint8)
    elif encoding in ("mono16", "16uc1"):
        dtype = np.dtype(">u2" if msg.is_bigendian else "<u2")
    elif encoding in ("rgb8", "bgr8"):
        if labels is None or not labels.colors:
            raise UserError(
                source, f"topic {topic}: {msg.encoding} colour images need a colour table (colors) in the label map", field="labels"
            )
        rgb = _rows(msg, (h, w, step), 3, (source, f"topic {topic}: image", "topics.segmentation")).reshape(h, w, 3)
        return labels.decode_rgb(rgb[..., ::-1] if encoding == "bgr8" else rgb)
    else:
        raise UserError(
            source,
            f"topic {topic}: image encoding {msg.encoding!r}; label ids come as mono8 or mono16 (or rgb8 with a colour table)",
            field="topics.segmentation",
        )
    rows = _rows(msg, (h, w, step), dtype.itemsize, (source, f"topic {topic}: image", "topics.segmentation"))
    return np.ascontiguousarray(rows).view(dtype).reshape(h, w).astype(np.uint16 if dtype.itemsize == 2 else np.uint8)


def _decode_png(msg, topic: str, source: str, t_s: float | None) -> np.ndarray:
    """Label ids of a png CompressedImage, plain or as compressedDepth (16UC1 only: a 32FC1
    depth png holds quantised inverse depth, not ids)."""
    fmt = str(msg.format).lower()
    data = bytes(msg.data)
    where = f"topic {topic}, message received {t_s:.3f} s into the log" if t_s is not None else f"topic {topic}"
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
        raise UserError(source, f"{where}: not a decodable png ({one_line(exc, 80)})", field="topics.segmentation") from None
    return ids.astype(np.uint16) if ids.dtype != np.uint8 else ids


MILLIMETRES_LIKE_M = 500.0  # a 32FC1 depth image whose returns' median lies past this [m] holds millimetres, not metres
DEPTH_CHECK_STRIDE = 61  # every this many pixels of a depth image are sampled for that check
DEPTH_ENCODINGS = ("32FC1", "16UC1")  # REP 118: metres as float32; millimetres as uint16, 0 where nothing is seen


def millimetres_median(metres: np.ndarray) -> float | None:
    """The median [m] of a float depth image's returns (finite and above 0, sampled every
    :data:`DEPTH_CHECK_STRIDE` pixels) where it lies past :data:`MILLIMETRES_LIKE_M`: the image
    holds millimetres, not metres; None where it does not."""
    sample = np.asarray(metres).reshape(-1)[::DEPTH_CHECK_STRIDE]  # a prime stride: no row's pattern
    seen = sample[np.isfinite(sample) & (sample > 0)]
    median = float(np.median(seen)) if len(seen) else 0.0
    return median if median > MILLIMETRES_LIKE_M else None


def depth_metres(msg, topic: str, source: str, t_s: float | None = None) -> np.ndarray:
    """The depth image (H, W) float32 [m along the optical axis, NaN where nothing is seen] of a
    sensor_msgs/Image on ``topic``: 32FC1 metres (not finite or not above 0: nothing seen) or
    16UC1 millimetres (0: nothing seen). ``t_s``, when the log received it from its start [s],
    names it in an error.

    Raises:
        UserError: about ``source``, naming the topic: another encoding, or data that does not hold the image.
    """
    where = f"topic {topic}, message received {t_s:.3f} s into the log" if t_s is not None else f"topic {topic}"
    encoding = str(msg.encoding).upper()
    if encoding not in DEPTH_ENCODINGS:
        raise UserError(
            source,
            f"{where}: depth image encoding {msg.encoding!r}; expected 32FC1 (metres) or 16UC1 (millimetres, 0: no return), REP 118",
            field="topics.depth",
        )
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    dtype = np.dtype(("f4" if encoding == "32FC1" else "u2")).newbyteorder(">" if msg.is_bigendian else "<")
    values = (
        np.ascontiguousarray(_rows(msg, (h, w, step), dtype.itemsize, (source, f"{where}: depth", "topics.depth")))
        .view(dtype)
        .reshape(h, w)
    )
    if encoding == "16UC1":
        return millimetres_to_depth(values)
    metres = values.astype(np.float32)
    median = millimetres_median(metres)
    if median is not None:
        raise UserError(
            source,
            f"{where}: depth of a median {median:g} m, millimetres as it seems; 32FC1 is metres (REP 118), millimetres come as 16UC1",
            field="topics.depth",
        )
    return np.where(np.isfinite(metres) & (metres > 0), metres, np.float32(np.nan)).astype(np.float32)


def registered_depth(msg, topic: str, source: str, shape: tuple[int, int], t_s: float | None = None) -> np.ndarray:
    """The depth image (H, W) float32 [m, NaN where nothing is seen] of ``msg`` on ``topic``
    (:func:`depth_metres`), which must be of the label camera's ``shape`` (H, W): registered to
    the label images, as terrapref does not resample a depth camera onto them. ``t_s``, when the
    log received it from its start [s], names it in an error.

    Raises:
        UserError: about ``source``, naming the topic: another encoding, data that does not hold
            the image, or another size than the label camera's.
    """
    depth = depth_metres(msg, topic, source, t_s)
    if depth.shape != tuple(shape):
        where = f"topic {topic}, message received {t_s:.3f} s into the log" if t_s is not None else f"topic {topic}"
        raise UserError(
            source,
            f"{where}: depth image {depth.shape[1]} x {depth.shape[0]}, the label camera's is {shape[1]} x {shape[0]}; "
            "the depth images must be registered to the label images",
            field="topics.depth",
        )
    return depth


def _rows(msg, size: tuple[int, int, int], pixel_bytes: int, about: tuple[str, str, str]) -> np.ndarray:
    """The bytes (H, W * ``pixel_bytes``) of an Image ``msg``'s rows, its padding cut (``size``: its
    height, width and step); a step shorter than a row, or data shorter than the rows, is a
    UserError (``about``: the log, what the message is, the field)."""
    h, w, step = size
    source, what, field = about
    data = np.frombuffer(bytes(msg.data), dtype=np.uint8)
    if step < w * pixel_bytes:
        raise UserError(source, f"{what} step of {step} bytes is shorter than a row of {w} pixels of {pixel_bytes} bytes", field=field)
    if len(data) < step * h:
        raise UserError(source, f"{what} data of {len(data)} bytes does not hold {h} rows of {step}", field=field)
    return data[: step * h].reshape(h, step)[:, : w * pixel_bytes]


def undistorted(image: np.ndarray, undistort: np.ndarray | None, fill: float | int) -> np.ndarray:
    """``image`` (H, W) through a distorted lens's undistortion map (the flat index of each
    pinhole pixel in the lens's image, -1 outside: :func:`camera_from_info`), ``fill`` where no
    lens pixel falls; ``image`` itself without one. Label ids and depth images alike."""
    if undistort is None:
        return image
    return np.where(undistort >= 0, image.reshape(-1)[np.maximum(undistort, 0)], fill).astype(image.dtype)
