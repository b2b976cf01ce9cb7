"""Recordings and closed-loop runs as ROS 2 MCAP, with standard message types, for Foxglove or RViz.

Topics (all in the ``odom`` frame, the recording's world frame; stamps from an epoch-like clock):

    /terrapref/labels           sensor_msgs/CompressedImage   class ids as a single-channel png
    /terrapref/labels_color     sensor_msgs/CompressedImage   the same frame in the class colours
    /terrapref/depth            sensor_msgs/Image             the frame's depth image (16UC1: millimetres,
                                                              0 no return; REP 118), where frames carry one
    /terrapref/camera_info      sensor_msgs/CameraInfo        K of the camera, no distortion (the depth
                                                              image's too: it is the same camera's)
    /terrapref/odom             nav_msgs/Odometry             the pose at each frame (with depth, its
                                                              height, pitch and roll: the body's attitude)
    /terrapref/cmd_vel          geometry_msgs/Twist           the command (label) of each frame
    /terrapref/path             nav_msgs/Path                 the reference path, once
    /terrapref/trajectories     visualization_msgs/MarkerArray the 21 trajectories, the chosen one green
    /terrapref/costmap          nav_msgs/OccupancyGrid        the learned preference over the ground seen
                                                              (a run of a model with an offset rule; 1 Hz)
    /terrapref/costmap_grid     foxglove_msgs/Grid            the same costmap as Foxglove's Grid: cost
                                                              (int8, -1 unknown) and its colour per cell
    /terrapref/grid_map         grid_map_msgs/GridMap         the same cells' layers: cost, speed, elevation,
                                                              slope, roughness, step (float32, NaN unknown)
    /terrapref/speed_filter_info nav2_msgs/CostmapFilterInfo  the learned speed as Nav2's speed filter (a model
    /terrapref/speed_mask       nav_msgs/OccupancyGrid        with a speed rule): percent of the top speed
    /tf, /tf_static             tf2_msgs/TFMessage            odom -> base_link; base_link -> camera_link ->
                                                              camera_optical (z forward, x right, y down), the
                                                              frame of the images and calibration; /tf_static
                                                              offered transient-local, so a player latches it

An MCAP file's chunks are compressed with zstd, a ROS 1 bag's with lz4 (each format's own
compression, which Foxglove, ``ros2 bag`` and ``rosbag play`` read as they are). Importing an
exported recording with the robot file written beside it (``FILE.robot.yaml``) gives back the
same frames (their depth images and the body's attitude among them), so it featurises to the
same dataset.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from terrapref.camera import CameraConfig
from terrapref.extras import needs
from terrapref.features import PreferenceSetConfig
from terrapref.features.preference_set import forward_simulate
from terrapref.fileio import new_folder, release_folder, write_text_atomic
from terrapref.groundmap.costmap import Costmap
from terrapref.interop.ros_messages import (
    EPOCH_S,
    OPTICAL_FRAME,
    Message,
    Topics,
    add_topics,
    camera_info,
    camera_mount,
    compressed_image,
    depth_image,
    filter_info_said,
    foxglove_grid,
    grid_map,
    header,
    occupancy_grid,
    odometry,
    path_message,
    png,
    point,
    pose,
    rpy_quaternion,
    speed_filter,
    tf_message,
    transform,
    twist,
    typestore,
    vector3,
    zeroed,
)
from terrapref.stops import REASONS
from terrapref.terrain import ClassTable, default_classes
from terrapref.terrain.classes import UNKNOWN, ForeignIds
from terrapref.vehicle.ground import LEVEL, Attitude
from terrapref.vehicle.kinematics import pose_velocities

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

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
    costmap: Callable[[int, np.ndarray], Costmap | None] | None = None  # frame, its class ids -> the costmap to publish then
    stops: tuple[str | None, ...] | None = None  # (F,) why the planner stopped at each frame (None: it drove), when a planner drove
    profile: tuple[str, ...] | None = None  # the driver's declared preference order (a recording's), for the robot file
    depth: Callable[[int], np.ndarray | None] | None = None  # frame index -> (H, W) [m, NaN: none] or None; None: no frame has one
    attitude: Callable[[int], Attitude] | None = None  # frame index -> the body's attitude (with depth; None: level)


COSTMAP_TOPICS = {
    "costmap": (f"{PREFIX}/costmap", "nav_msgs/msg/OccupancyGrid"),
    "costmap_grid": (f"{PREFIX}/costmap_grid", "foxglove_msgs/msg/Grid"),
    "grid_map": (f"{PREFIX}/grid_map", "grid_map_msgs/msg/GridMap"),
    "speed_filter_info": (f"{PREFIX}/speed_filter_info", "nav2_msgs/msg/CostmapFilterInfo"),
    "speed_mask": (f"{PREFIX}/speed_mask", "nav_msgs/msg/OccupancyGrid"),
}
ROS1_COSTMAP_ROLES = ("costmap", "grid_map")  # a ROS 1 bag's (Foxglove's Grid and Nav2's filter are ROS 2's)
# Frames between two costmaps: 1 Hz at 10 frames a second. The ground map the costmap shows
# grows by about a metre of driving per second while the camera sees 20-30 m ahead, so a
# costmap a second shows every change a viewer can see; compressed (zstd), the costmaps are
# about a tenth of a file, the camera's images most of the rest (docs/robot-logs.md).
COSTMAP_EVERY = 10
_TOPICS = {  # role: (topic, type), in the order the file lists them
    "labels": (f"{PREFIX}/labels", "sensor_msgs/msg/CompressedImage"),
    "labels_color": (f"{PREFIX}/labels_color", "sensor_msgs/msg/CompressedImage"),
    "camera_info": (f"{PREFIX}/camera_info", "sensor_msgs/msg/CameraInfo"),
    "odom": (f"{PREFIX}/odom", "nav_msgs/msg/Odometry"),
    "cmd_vel": (f"{PREFIX}/cmd_vel", "geometry_msgs/msg/Twist"),
    "path": (f"{PREFIX}/path", "nav_msgs/msg/Path"),
    "trajectories": (f"{PREFIX}/trajectories", "visualization_msgs/msg/MarkerArray"),
    "status": (f"{PREFIX}/status", "std_msgs/msg/String"),  # the planner's: "driving", or "stopped: REASON (what it means)"
    "tf": ("/tf", "tf2_msgs/msg/TFMessage"),
    "tf_static": ("/tf_static", "tf2_msgs/msg/TFMessage"),
}
DEPTH_TOPIC = {"depth": (f"{PREFIX}/depth", "sensor_msgs/msg/Image")}  # a file whose frames carry depth images
TOPICS = {**_TOPICS, **COSTMAP_TOPICS}  # every channel of a live view (and of a file, with DEPTH_TOPIC), by role


def _topics_of(run: RunFrames, ros1: bool) -> dict[str, tuple[str, str]]:
    """The channels of ``run``'s file, in the order it lists them: with a depth topic where its
    frames carry depth, with the costmap's where it has one (a ROS 1 bag's costmap as
    OccupancyGrid and GridMap alone: Foxglove's Grid and Nav2's filter are ROS 2's)."""
    topics = {**_TOPICS, **(DEPTH_TOPIC if run.depth is not None else {})}
    if run.probs is None:  # no planner drove: no status to say
        del topics["status"]
    if run.costmap is not None:
        topics |= {role: COSTMAP_TOPICS[role] for role in (ROS1_COSTMAP_ROLES if ros1 else COSTMAP_TOPICS)}
    return topics


@dataclass(frozen=True)
class Scene:
    """What every frame of one file shares: the types, the clock's origin, the colours and the
    trajectory markers (fixed in base_link: restamped and recoloured per frame)."""

    ts: Typestore
    run: RunFrames
    t0_s: float  # the first frame's time: bag time 0 on the epoch-like clock
    palette: np.ndarray  # (256, 3) class colours
    markers: list[Message]  # one visualization_msgs/Marker per trajectory
    marker_array: Message
    ros1: bool = False  # ROS 1 messages (headers with seq, CameraInfo's matrices in upper case)
    velocity: np.ndarray | None = None  # (F, 2) each frame's v [m/s] and w [rad/s], from the poses (the odometry's twist)

    @classmethod
    def of(cls, ts: Typestore, run: RunFrames, ros1: bool = False) -> Scene:
        """The shared part of ``run``'s file, in the types of ``ts`` (ROS 1's with ``ros1``)."""
        c = run.preference.control
        trajectories = forward_simulate(np.full(c.m, c.v_mps), np.asarray(c.w_rps), run.preference.n_steps, run.preference.dt_s)
        lifetime = ts.types["builtin_interfaces/msg/Duration"](sec=0, nanosec=200_000_000)
        markers = [
            zeroed(
                ts,
                "visualization_msgs/msg/Marker",
                ns="trajectories",
                id=j,
                type=4,
                action=0,
                pose=zeroed(ts, "geometry_msgs/msg/Pose", orientation=rpy_quaternion(ts, 0, 0, 0)),
                lifetime=lifetime,
                points=[point(ts, px, py, 0.02) for px, py in trajectories[j, :, :2]],
            )
            for j in range(c.m)
        ]
        t0_s = float(run.times[0]) if len(run.times) else 0.0
        velocity = _velocities(run.times, run.poses)
        return cls(
            ts, run, t0_s, run.classes.palette(), markers, ts.types["visualization_msgs/msg/MarkerArray"](markers=markers), ros1, velocity
        )

    def header(self, t_s: float, frame_id: str) -> Message:
        """std_msgs/Header stamped ``t_s`` [s] after the first frame, in ``frame_id``."""
        return header(self.ts, t_s, frame_id, self.ros1)

    def bag_ns(self, t_s: float) -> int:
        """Bag time [ns] of the run's time ``t_s`` [s]."""
        return int(round((EPOCH_S + t_s - self.t0_s) * 1e9))


def _velocities(times: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Each frame's v [m/s] and w [rad/s] (F, 2), as ``import`` measures a log's motion from its
    poses (:func:`~terrapref.vehicle.kinematics.pose_velocities`); 0 where the frames' times
    cannot tell (one frame, or one stamp)."""
    if len(times) < 2:
        return np.zeros((len(times), 2))
    poses = np.asarray(poses, dtype=float)
    unwrapped = np.column_stack([poses[:, :2], np.unwrap(poses[:, 2])])
    return np.nan_to_num(pose_velocities(np.asarray(times, dtype=float), unwrapped), nan=0.0)


def write_mcap(out: str | Path, run: RunFrames, robot_file: bool = True, progress: Callable[[int, int], None] | None = None) -> Path:
    """Write ``run`` as a ROS 2 MCAP file at ``out`` (atomically); with ``robot_file``, also the
    terrapref-robot/1 file that imports it back (``out`` with ``.robot.yaml``)."""
    return write_bag(out, run, ros1=False, robot_file=robot_file, progress=progress)


def write_bag(
    out: str | Path, run: RunFrames, ros1: bool = False, robot_file: bool = True, progress: Callable[[int, int], None] | None = None
) -> Path:
    """Write ``run`` at ``out`` (atomically) as a ROS 2 MCAP file, or with ``ros1`` as a ROS 1 bag
    (the same topics, ROS 1's types; the costmap as OccupancyGrid alone, Foxglove's Grid being a
    ROS 2 type); with ``robot_file``, also the terrapref-robot/1 file that imports it back."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmpdir = new_folder(out, ".writing")  # beside it, never in the system's tmp: the rename below stays on one file system
    try:
        written = _write_ros1(tmpdir / "run.bag", run, progress) if ros1 else _write_ros2(tmpdir / "bag", run, progress)
        written.replace(out)
    finally:
        release_folder(tmpdir)
    if robot_file:
        labels = "terrapref   # the ids are terrapref's own classes"
        labels_file = out.with_name(out.name + ".labels.yaml")
        if run.classes.same_classes(default_classes()):
            labels_file.unlink(missing_ok=True)  # an earlier file's, replaced (--force): this bag's ids need no map
        else:  # the ids are another table's: a map of them by name, beside the robot file
            write_text_atomic(labels_file, _label_map_yaml(run.classes))
            labels = f"{labels_file.name}   # the ids of the class table the run was made with (terrapref import --classes FILE)"
        write_text_atomic(out.with_name(out.name + ".robot.yaml"), _robot_yaml(run.camera, labels, run.profile, run.depth is not None))
    return out


def _write_ros2(bag_dir: Path, run: RunFrames, progress: Callable[[int, int], None] | None) -> Path:
    """The ROS 2 MCAP bag of ``run`` in the folder ``bag_dir``; its file."""
    with needs("robot", "writing MCAP"):
        from rosbags.rosbag2 import StoragePlugin, Writer
        from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

    ts = typestore()
    writer = Writer(bag_dir, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.set_compression(
        CompressionMode.STORAGE, CompressionFormat.ZSTD
    )  # MCAP's own zstd chunks: Foxglove and ros2 bag read them as they are
    with writer:
        _write_frames(add_topics(writer, ts, _topics_of(run, ros1=False)), Scene.of(ts, run), progress)
    return next(bag_dir.glob("*.mcap"))


def _write_ros1(path: Path, run: RunFrames, progress: Callable[[int, int], None] | None) -> Path:
    """The ROS 1 bag of ``run`` at ``path``."""
    with needs("robot", "writing ROS 1 bags"):
        from rosbags.rosbag1 import Writer

    ts = typestore(ros1=True)
    writer = Writer(path)
    writer.set_compression(Writer.CompressionFormat.LZ4)  # a ROS 1 bag's own chunk compression (zstd is not one)
    writer.compressor = roslz4_frame  # the frames rosbag play reads (rosbags' own take none of what it needs)
    with writer:
        _write_frames(add_topics(writer, ts, _topics_of(run, ros1=True), ros1=True), Scene.of(ts, run, ros1=True), progress)
    return path


def roslz4_frame(data: bytes) -> bytes:
    """``data`` as one LZ4 frame that ROS 1's own reader (roslz4, which ``rosbag play`` and the
    rosbag Python API use) decompresses: blocks independent of each other, a checksum of the
    content, and no content size in the header; a frame with any of these otherwise is refused
    as "malformed data"."""
    import lz4.frame

    return lz4.frame.compress(data, 0, store_size=False, content_checksum=True, block_linked=False)


def _write_frames(topics: Topics, scene: Scene, progress: Callable[[int, int], None] | None) -> None:
    """The path and the camera's mounting once, then each frame."""
    write_fixed(topics, scene)
    n = len(scene.run.times)
    for i in range(n):
        _write_frame(topics, scene, i)
        if progress is not None:
            progress(i + 1, n)


def write_fixed(topics: Topics, scene: Scene, t_s: float | None = None) -> None:
    """The reference path and the camera's mounting (base_link -> camera_optical), at the run's
    time ``t_s`` [s] (default: its first frame's)."""
    ts, cam = scene.ts, scene.run.camera
    t = scene.t0_s if t_s is None else t_s
    at = scene.bag_ns(t)
    topics.write("path", at, path_message(ts, scene.run.path, scene.ros1, t - scene.t0_s))
    topics.write("tf_static", at, tf_message(ts, camera_mount(ts, cam, scene.ros1, t - scene.t0_s)))


@dataclass(frozen=True)
class FrameData:
    """One frame as the files and the live view carry it."""

    t_s: float  # on the run's clock [s]
    pose: tuple[float, float, float]  # x [m], y [m], yaw [rad]
    command: tuple[float, float]  # v [m/s], w [rad/s]
    ids: np.ndarray  # (H, W) uint8 class ids
    chosen: int  # the trajectory chosen (or demonstrated)
    probs: np.ndarray | None = None  # F_t (m,), when a planner drove
    costmap: Costmap | None = None  # the costmap to publish with this frame
    stop: str | None = None  # why the planner stopped (None: it drove), when a planner drove
    depth: np.ndarray | None = None  # (H, W) [m, NaN where nothing is seen], when the frame carries one
    attitude: Attitude | None = None  # the body's height, pitch and roll (None: level at height 0)
    velocity: tuple[float, float] | None = None  # the body's v [m/s] and w [rad/s], the odometry's twist (None: not known, 0)


def _write_frame(topics: Topics, scene: Scene, i: int) -> None:
    """Frame ``i`` of the scene's run."""
    run = scene.run
    ids = run.image(i)
    x, y, yaw = (float(v) for v in run.poses[i])
    v, w = (float(u) for u in run.commands[i])
    write_frame(
        topics,
        scene,
        FrameData(
            float(run.times[i]),
            (x, y, yaw),
            (v, w),
            ids,
            int(run.chosen[i]),
            run.probs[i] if run.probs is not None else None,
            run.costmap(i, ids) if run.costmap is not None else None,
            run.stops[i] if run.stops is not None else None,
            run.depth(i) if run.depth is not None else None,
            run.attitude(i) if run.attitude is not None else None,
            (float(scene.velocity[i, 0]), float(scene.velocity[i, 1])),
        ),
    )


def _write_costmap(topics: Topics, scene: Scene, t: float, ns: int, costmap: Costmap) -> None:
    """The costmap as an OccupancyGrid and its layers as a GridMap; in ROS 2, also as Foxglove's
    Grid and, with a speed layer, the speed as Nav2's speed filter."""
    ts, res, origin = scene.ts, costmap.resolution_m, costmap.origin
    topics.write("costmap", ns, occupancy_grid(ts, scene.header(t, "odom"), costmap.cost, res, origin))
    topics.write("grid_map", ns, grid_map(ts, scene.header(t, "odom"), costmap.grid_layers(), res, origin, scene.ros1))
    if scene.ros1:
        return
    topics.write("costmap_grid", ns, foxglove_grid(ts, t, "odom", costmap))
    if "speed" in costmap.layers and costmap.top_speed_mps is not None:
        mask_topic = COSTMAP_TOPICS["speed_mask"][0]
        info, mask = speed_filter(ts, scene.header(t, "odom"), costmap.layers["speed"], costmap.top_speed_mps, mask_topic)
        topics.write_changed("speed_filter_info", ns, info, filter_info_said(info))
        topics.write("speed_mask", ns, occupancy_grid(ts, scene.header(t, "odom"), mask, res, origin))


def write_frame(topics: Topics, scene: Scene, frame: FrameData) -> None:
    """One frame: calibration, class ids and their colours, pose, costmap, command and trajectories."""
    ts = scene.ts
    t = frame.t_s - scene.t0_s
    ns = scene.bag_ns(frame.t_s)
    x, y, yaw = frame.pose
    z, pitch, roll = frame.attitude if frame.attitude is not None else (0.0, 0.0, 0.0)
    turn = rpy_quaternion(ts, roll, pitch, yaw)
    # The pose first: a player sends messages of one stamp in the order written, and a node that
    # interpolates odometry to an image's stamp needs the pose of that stamp when the image comes.
    topics.write("odom", ns, odometry(ts, scene.header(t, "odom"), pose(ts, x, y, turn, z), frame.velocity))
    topics.write("tf", ns, tf_message(ts, [transform(ts, scene.header(t, "odom"), "base_link", (x, y, z), turn)]))
    optical = scene.header(t, OPTICAL_FRAME)
    topics.write("camera_info", ns, camera_info(ts, optical, scene.run.camera, scene.ros1))
    topics.write("labels", ns, compressed_image(ts, optical, "mono8; png compressed class ids", png(frame.ids)))
    topics.write("labels_color", ns, compressed_image(ts, optical, "png", png(frame.ids, scene.palette)))
    if frame.depth is not None:
        topics.write("depth", ns, depth_image(ts, optical, frame.depth))
    if frame.costmap is not None:
        _write_costmap(topics, scene, t, ns, frame.costmap)
    topics.write("cmd_vel", ns, twist(ts, *frame.command))
    _restyle_markers(scene, frame.chosen, frame.probs, scene.header(t, "base_link"))
    topics.write("trajectories", ns, scene.marker_array)
    if frame.probs is not None:  # a planner drove: whether it drives or stops, and why
        topics.write("status", ns, ts.types["std_msgs/msg/String"](data=status_text(frame.stop)))


def status_text(stop: str | None) -> str:
    """The planner's status as the status topic and the logs say it: ``driving``, or ``stopped: REASON (what it means)``."""
    return "driving" if stop is None else f"stopped: {stop} ({REASONS.get(stop, stop)})"


def _restyle_markers(scene: Scene, chosen: int, probs: np.ndarray | None, stamped: Message) -> None:
    """The markers of one frame: the chosen trajectory thick and green, the others white to
    red, more opaque the likelier the planner found them (F_t, when a planner drove)."""
    for j, marker in enumerate(scene.markers):
        p = float(probs[j]) if probs is not None else 0.0
        marker.header = stamped
        marker.scale = vector3(scene.ts, x=0.08 if j == chosen else 0.03)
        marker.color = _color(scene.ts, 0.1, 0.9, 0.2) if j == chosen else _color(scene.ts, 1.0, 1.0 - p, 1.0 - p, 0.4 + 0.6 * p)


def _color(ts: Typestore, r: float, g: float, b: float, a: float = 1.0) -> Message:
    """std_msgs/ColorRGBA, each channel in [0, 1]."""
    return ts.types["std_msgs/msg/ColorRGBA"](r=float(r), g=float(g), b=float(b), a=float(a))


def _label_map_yaml(classes: ClassTable) -> str:
    """A terrapref-labels/1 file naming the class of each of ``classes``' ids."""
    ids = "".join(f"  {c.id}: {c.name}\n" for c in classes.classes)
    return (
        f"format: terrapref-labels/1\nname: exported\ndescription: the class ids of the table {', '.join(classes.names)}\n"
        f"ids:\n{ids}  {UNKNOWN}: unknown\n"
    )


def _robot_yaml(cam: CameraConfig, labels: str, profile: tuple[str, ...] | None = None, depth: bool = False) -> str:
    """The terrapref-robot/1 file that imports the exported topics back with ``cam``'s mounting,
    ``labels`` (the robot file's ``labels`` entry), the driver's declared ``profile``, if any,
    and with ``depth`` the depth topic (the label camera's own: no calibration of its own)."""
    order = f"profile: [{', '.join(profile)}]   # the driver's declared order, from the recording\n" if profile else ""
    depth_topic = (
        f"  depth: {DEPTH_TOPIC['depth'][0]}   # 16UC1, registered to the labels (camera_info is its calibration)\n" if depth else ""
    )
    return (
        "format: terrapref-robot/1\n"
        f"topics:\n  segmentation: {PREFIX}/labels\n  camera_info: {PREFIX}/camera_info\n  odometry: {PREFIX}/odom\n"
        f"  command: {PREFIX}/cmd_vel\n  path: {PREFIX}/path\n{depth_topic}"
        f"camera:\n  height_m: {cam.mount_height_m!r}\n  pitch_deg: {cam.pitch_deg!r}\n  forward_m: {cam.mount_forward_m!r}\n"
        f"  yaw_deg: {cam.yaw_deg!r}\n  max_range_m: {cam.max_range_m!r}\n"
        f"labels: {labels}\n" + order
    )


def costmaps_of(
    planner, poses: np.ndarray, depth: Callable[[int], np.ndarray | None] | None = None, attitude: Callable[[int], Attitude] | None = None
) -> Callable[[int, np.ndarray], Costmap | None]:
    """The costmaps of one run for :attr:`RunFrames.costmap`: ``planner`` (a terrapref.planner.Planner
    whose steering rule reads a ground map), its maps emptied, takes each frame in turn as
    it was seen from ``poses`` (F, 3), with its ``depth`` image and the body's ``attitude``
    where the run has them (:attr:`RunFrames.depth`, :attr:`RunFrames.attitude`), and every
    :data:`COSTMAP_EVERY`-th frame gives its costmap. Frames are to be asked for in order."""
    from terrapref.camera import SegmentationView
    from terrapref.vehicle import Pose

    planner.forget_ground()

    def costmap(i: int, ids: np.ndarray) -> Costmap | None:
        seen = depth(i) if depth is not None else None
        planner.observe(
            SegmentationView.of(ids), Pose(*poses[i]), seen, attitude(i) if seen is not None and attitude is not None else LEVEL
        )
        return planner.costmap() if i % COSTMAP_EVERY == 0 else None

    return costmap


def model_costmaps(model, frames: RunFrames) -> Callable[[int, np.ndarray], Costmap | None]:
    """The costmaps ``model`` (a terrapref.planner.model.Model) sees in ``frames`` (a recording's):
    its driving rule's ground map fed each frame at the pose recorded (:func:`costmaps_of`).

    Raises:
        ValueError: the model is for another class table, or its driving rule keeps no ground map.
    """
    if not model.classes.same_classes(frames.classes):
        raise ValueError("was trained for another class table than the recording's")
    planner = model.planner(frames.camera)
    if planner.ground_map is None:
        raise ValueError("has no offset rule, whose ground map the costmap prices (train it with recipe teach)")
    return costmaps_of(planner, frames.poses, frames.depth, frames.attitude)


def recording_frames(rec) -> RunFrames:
    """A recording (terrapref.demos.recording.Recording) as the frames of one MCAP file."""
    from terrapref.features import PreferenceSetConfig

    classes = rec.classes
    path = np.asarray(rec.meta.get("path") or rec.scenario["path"]["waypoints"], dtype=float)
    camera = CameraConfig.from_dict(rec.meta["camera"])
    return RunFrames(
        times=rec.times,
        poses=rec.poses,
        commands=rec.commands,
        image=partial(_known_ids, rec, ForeignIds(classes), (camera.height_px, camera.width_px)),
        chosen=rec.labels,
        path=path,
        camera=camera,
        classes=classes,
        preference=PreferenceSetConfig.from_dict(rec.meta["preference_set"]),
        profile=_declared_order(rec.meta.get("profile")),
        depth=partial(_sized_depth, rec, (camera.height_px, camera.width_px)) if rec.has_depth else None,
        attitude=rec.attitude if rec.has_depth else None,
    )


def _known_ids(rec, foreign: ForeignIds, shape: tuple[int, int], i: int) -> np.ndarray:
    """Frame ``i``'s class ids, refused where the image is not the camera's ``shape`` (H, W) or
    an id is none of the recording's classes (``foreign``), as featurize refuses them."""
    from terrapref.errors import UserError

    ids = rec.image(i)
    if ids.shape != shape:
        raise UserError(str(rec.path / rec.image_files[i]), f"is {ids.shape[1]} x {ids.shape[0]}, the camera's {shape[1]} x {shape[0]}")
    unknown = foreign(ids)
    if unknown:
        raise UserError(str(rec.path / rec.image_files[i]), f"holds class ids {unknown[:5]} that the class table does not have")
    return ids


def _sized_depth(rec, shape: tuple[int, int], i: int) -> np.ndarray | None:
    """Frame ``i``'s depth image, refused where it is not the camera's ``shape`` (H, W)."""
    from terrapref.errors import UserError

    depth = rec.depth(i)
    if depth is not None and depth.shape != shape:
        raise UserError(str(rec.path / rec.depth_files[i]), f"is {depth.shape[1]} x {depth.shape[0]}, the camera's {shape[1]} x {shape[0]}")
    return depth


def _declared_order(profile: object) -> tuple[str, ...] | None:
    """A recording's ``profile`` entry as an order, or None when it declares none."""
    return tuple(str(name) for name in profile) if isinstance(profile, list) and profile else None
