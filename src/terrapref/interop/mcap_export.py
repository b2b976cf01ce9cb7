"""Recordings and closed-loop runs as ROS 2 MCAP, with standard message types, for Foxglove or RViz.

Topics (all in the ``odom`` frame, the recording's world frame; stamps from an epoch-like clock):

    /terrapref/labels           sensor_msgs/CompressedImage   class ids as a single-channel png
    /terrapref/labels_color     sensor_msgs/CompressedImage   the same frame in the class colours
    /terrapref/camera_info      sensor_msgs/CameraInfo        K of the camera, no distortion
    /terrapref/odom             nav_msgs/Odometry             the pose at each frame
    /terrapref/cmd_vel          geometry_msgs/Twist           the command (label) of each frame
    /terrapref/path             nav_msgs/Path                 the reference path, once
    /terrapref/trajectories     visualization_msgs/MarkerArray the 21 trajectories, the chosen one green
    /tf, /tf_static             tf2_msgs/TFMessage            odom -> base_link, base_link -> camera

Importing an exported recording with the robot file written beside it (``FILE.robot.yaml``)
gives back the same frames, so it featurises to the same dataset.
"""

from __future__ import annotations

import io
import math
import shutil
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image as PILImage

from terrapref.camera import CameraConfig
from terrapref.features import PreferenceSetConfig
from terrapref.features.preference_set import forward_simulate
from terrapref.fileio import write_text_atomic
from terrapref.terrain import ClassTable

EPOCH_S = 1_700_000_000
PREFIX = "/terrapref"


@dataclass
class RunFrames:
    """What one MCAP file holds: per-frame times, poses, commands, images and choices."""

    times: np.ndarray  # (F,) [s]
    poses: np.ndarray  # (F, 3) [m, m, rad]
    commands: np.ndarray  # (F, 2) [m/s, rad/s]
    image: Callable[[int], np.ndarray]  # frame index -> (H, W) uint8 class ids
    chosen: np.ndarray  # (F,) index of the chosen (or demonstrated) trajectory
    path: np.ndarray  # (N, 2) [m]
    camera: CameraConfig
    classes: ClassTable
    preference: PreferenceSetConfig
    probs: np.ndarray | None = None  # (F, m) F_t, when a planner drove


def _defaults(ts, msgtype: str):
    """A message of ``msgtype`` with every field at its zero value (nested types included)."""
    from rosbags.typesys.store import Nodetype

    numeric = {"bool": bool, "byte": np.uint8, "char": np.uint8, "int8": np.int8, "uint8": np.uint8, "int16": np.int16, "uint16": np.uint16,
               "int32": np.int32, "uint32": np.uint32, "int64": np.int64, "uint64": np.uint64, "float32": np.float32, "float64": np.float64}

    def value(node):
        kind, detail = node
        if kind == Nodetype.BASE:
            name = detail[0]
            return "" if name == "string" else (False if name == "bool" else (0.0 if name.startswith("float") else 0))
        if kind == Nodetype.NAME:
            return _defaults(ts, detail)
        sub, length = detail
        if sub[0] == Nodetype.BASE and sub[1][0] in numeric:
            return np.zeros(length if kind == Nodetype.ARRAY else 0, dtype=numeric[sub[1][0]])
        return [value(sub) for _ in range(length)] if kind == Nodetype.ARRAY else []

    _, fields = ts.fielddefs[msgtype]
    return ts.types[msgtype](**{name: value(node) for name, node in fields})


def _png(ids: np.ndarray, palette: np.ndarray | None = None) -> np.ndarray:
    """A single-channel png of ``ids``; with ``palette`` (256, 3), an indexed-colour one that
    viewers show in the class colours (a third of the work of an RGB image)."""
    buf = io.BytesIO()
    image = PILImage.fromarray(ids)
    if palette is not None:
        image.putpalette(palette.astype(np.uint8).ravel().tolist())
    image.save(buf, format="PNG", compress_level=1)
    return np.frombuffer(buf.getvalue(), dtype=np.uint8)


def write_mcap(out: str | Path, run: RunFrames, robot_file: bool = True, progress: Callable[[int, int], None] | None = None) -> Path:
    """Write ``run`` as a ROS 2 MCAP file at ``out`` (atomically); with ``robot_file``, also the
    terrapref-robot/1 file that imports it back (``out`` with ``.robot.yaml``)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    out = Path(out)
    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types

    def make(msgtype: str, **fields):
        msg = _defaults(ts, msgtype)
        for k, v in fields.items():
            setattr(msg, k, v)
        return msg

    def stamp(t: float):
        ns = int(round((EPOCH_S + t) * 1e9))
        return T["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    def header(t: float, frame: str):
        return T["std_msgs/msg/Header"](stamp=stamp(t), frame_id=frame)

    def quat(roll: float, pitch: float, yaw: float):
        cr, sr, cp, sp, cy, sy = math.cos(roll / 2), math.sin(roll / 2), math.cos(pitch / 2), math.sin(pitch / 2), math.cos(yaw / 2), math.sin(yaw / 2)
        return T["geometry_msgs/msg/Quaternion"](x=sr * cp * cy - cr * sp * sy, y=cr * sp * cy + sr * cp * sy, z=cr * cp * sy - sr * sp * cy, w=cr * cp * cy + sr * sp * sy)

    def point(x: float, y: float, z: float = 0.0):
        return T["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=float(z))

    def vec(x: float = 0.0, y: float = 0.0, z: float = 0.0):
        return T["geometry_msgs/msg/Vector3"](x=float(x), y=float(y), z=float(z))

    def color(r: float, g: float, b: float, a: float = 1.0):
        return T["std_msgs/msg/ColorRGBA"](r=float(r), g=float(g), b=float(b), a=float(a))

    cam = run.camera
    fx, fy, cx, cy = cam.intrinsics
    palette = run.classes.palette()
    c = run.preference.control
    trajectories = forward_simulate(np.full(c.m, c.v_mps), np.asarray(c.w_rps), run.preference.n_steps, run.preference.dt_s)
    t0 = float(run.times[0]) if len(run.times) else 0.0

    def bag_ns(t: float) -> int:
        return int(round((EPOCH_S + t - t0) * 1e9))

    tmpdir = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".writing", dir=out.parent if out.parent.exists() else None))
    try:
        with Writer(tmpdir / "bag", version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            topics = {
                "labels": ("sensor_msgs/msg/CompressedImage", "labels"), "labels_color": ("sensor_msgs/msg/CompressedImage", "labels_color"),
                "camera_info": ("sensor_msgs/msg/CameraInfo", "camera_info"), "odom": ("nav_msgs/msg/Odometry", "odom"),
                "cmd_vel": ("geometry_msgs/msg/Twist", "cmd_vel"), "path": ("nav_msgs/msg/Path", "path"),
                "trajectories": ("visualization_msgs/msg/MarkerArray", "trajectories"),
            }
            conns = {k: writer.add_connection(f"{PREFIX}/{name}", msgtype, typestore=ts) for k, (msgtype, name) in topics.items()}
            conns["tf"] = writer.add_connection("/tf", "tf2_msgs/msg/TFMessage", typestore=ts)
            conns["tf_static"] = writer.add_connection("/tf_static", "tf2_msgs/msg/TFMessage", typestore=ts)

            def put(key: str, t_ns: int, msg, msgtype: str) -> None:
                writer.write(conns[key], t_ns, ts.serialize_cdr(msg, msgtype))

            first = bag_ns(t0)
            path_msg = make("nav_msgs/msg/Path", header=header(0.0, "odom"), poses=[
                make("geometry_msgs/msg/PoseStamped", header=header(0.0, "odom"), pose=make("geometry_msgs/msg/Pose", position=point(x, y), orientation=quat(0, 0, 0)))
                for x, y in run.path])
            put("path", first, path_msg, "nav_msgs/msg/Path")
            mount = make("geometry_msgs/msg/TransformStamped", header=header(0.0, "base_link"), child_frame_id="camera",
                         transform=T["geometry_msgs/msg/Transform"](translation=vec(cam.mount_forward_m, 0.0, cam.mount_height_m),
                                                                     rotation=quat(0.0, math.radians(cam.pitch_deg), math.radians(cam.yaw_deg))))
            put("tf_static", first, T["tf2_msgs/msg/TFMessage"](transforms=[mount]), "tf2_msgs/msg/TFMessage")
            info = make("sensor_msgs/msg/CameraInfo", height=cam.height_px, width=cam.width_px, distortion_model="plumb_bob",
                        d=np.zeros(5), k=np.array([fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0]), r=np.eye(3).ravel(),
                        p=np.array([fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0]))
            # The trajectories are fixed in base_link: one marker each, restamped and recoloured per frame.
            markers = [make("visualization_msgs/msg/Marker", ns="trajectories", id=j, type=4, action=0, pose=make("geometry_msgs/msg/Pose", orientation=quat(0, 0, 0)),
                            lifetime=T["builtin_interfaces/msg/Duration"](sec=0, nanosec=200_000_000),
                            points=[point(px, py, 0.02) for px, py in trajectories[j, :, :2]]) for j in range(c.m)]
            marker_array = T["visualization_msgs/msg/MarkerArray"](markers=markers)
            for i in range(len(run.times)):
                t = float(run.times[i]) - t0
                ns = bag_ns(float(run.times[i]))
                x, y, yaw = (float(v) for v in run.poses[i])
                ids = run.image(i)
                info.header = header(t, "camera")
                put("camera_info", ns, info, "sensor_msgs/msg/CameraInfo")
                put("labels", ns, make("sensor_msgs/msg/CompressedImage", header=header(t, "camera"), format="mono8; png compressed class ids", data=_png(ids)), "sensor_msgs/msg/CompressedImage")
                put("labels_color", ns, make("sensor_msgs/msg/CompressedImage", header=header(t, "camera"), format="png", data=_png(ids, palette)), "sensor_msgs/msg/CompressedImage")
                pose = make("geometry_msgs/msg/PoseWithCovariance", pose=make("geometry_msgs/msg/Pose", position=point(x, y), orientation=quat(0, 0, yaw)))
                put("odom", ns, make("nav_msgs/msg/Odometry", header=header(t, "odom"), child_frame_id="base_link", pose=pose), "nav_msgs/msg/Odometry")
                tf = make("geometry_msgs/msg/TransformStamped", header=header(t, "odom"), child_frame_id="base_link",
                          transform=T["geometry_msgs/msg/Transform"](translation=vec(x, y, 0.0), rotation=quat(0, 0, yaw)))
                put("tf", ns, T["tf2_msgs/msg/TFMessage"](transforms=[tf]), "tf2_msgs/msg/TFMessage")
                v, w = (float(u) for u in run.commands[i])
                put("cmd_vel", ns, T["geometry_msgs/msg/Twist"](linear=vec(x=v), angular=vec(z=w)), "geometry_msgs/msg/Twist")
                frame_header = header(t, "base_link")
                for j, marker in enumerate(markers):
                    chosen = j == int(run.chosen[i])
                    p = float(run.probs[i, j]) if run.probs is not None else 0.0
                    marker.header = frame_header
                    marker.scale = vec(x=0.08 if chosen else 0.03)
                    marker.color = color(0.1, 0.9, 0.2) if chosen else color(1.0, 1.0 - p, 1.0 - p, 0.4 + 0.6 * p)
                put("trajectories", ns, marker_array, "visualization_msgs/msg/MarkerArray")
                if progress is not None:
                    progress(i + 1, len(run.times))
        written = next((tmpdir / "bag").glob("*.mcap"))
        out.parent.mkdir(parents=True, exist_ok=True)
        written.replace(out)
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)
    if robot_file:
        robot = out.with_name(out.name + ".robot.yaml")
        write_text_atomic(
            robot,
            "format: terrapref-robot/1\n"
            f"topics:\n  segmentation: {PREFIX}/labels\n  camera_info: {PREFIX}/camera_info\n  odometry: {PREFIX}/odom\n"
            f"  command: {PREFIX}/cmd_vel\n  path: {PREFIX}/path\n"
            f"camera:\n  height_m: {cam.mount_height_m!r}\n  pitch_deg: {cam.pitch_deg!r}\n  forward_m: {cam.mount_forward_m!r}\n"
            f"  yaw_deg: {cam.yaw_deg!r}\n  max_range_m: {cam.max_range_m!r}\n"
            "labels: terrapref   # the ids are terrapref's own classes\n"
        )
    return out


def recording_frames(rec) -> RunFrames:
    """A recording (terrapref.demos.recording.Recording) as the frames of one MCAP file."""
    from terrapref.features import PreferenceSetConfig

    classes = ClassTable.from_dict(rec.meta["classes"], str(rec.path / "meta.json"))
    path = np.asarray(rec.meta.get("path") or rec.scenario["path"]["waypoints"], dtype=float)
    return RunFrames(times=rec.times, poses=rec.poses, commands=rec.commands, image=rec.image, chosen=rec.labels, path=path,
                     camera=CameraConfig.from_dict(rec.meta["camera"]), classes=classes,
                     preference=PreferenceSetConfig.from_dict(rec.meta["preference_set"]))
