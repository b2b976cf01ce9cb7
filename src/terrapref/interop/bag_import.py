"""ROS 1 and ROS 2 bags (sqlite3 or MCAP) to terrapref recordings.

An import reads the log (:mod:`terrapref.interop.bag_reader`) in two passes: the small topics
whole, then the label images one at a time, each decoded (:mod:`terrapref.interop.ros_decode`)
and synchronised with the odometry and the commands into a frame
(:mod:`terrapref.interop.bag_frames`, which says how real logs' quirks are handled), with the
depth image of its stamp where the robot file names a depth topic. Here the recording is
written: the camera from the log's calibration (a depth camera's must be the same), the
reference path (the path topic's, the robot file's path_file, or the driven odometry smoothed),
the map placed around the drive, and the frames.

The recording is written to a temporary folder beside ``out`` and renamed into place only when
complete; an error leaves nothing behind.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from terrapref.camera import CameraConfig
from terrapref.demos.meta import ImportedInfo, RecordingMeta, SimMeta
from terrapref.demos.recording import RecordingWriter, is_recording
from terrapref.errors import UserError
from terrapref.features import PreferenceSetConfig
from terrapref.fileio import new_folder, release_folder, replace_dir
from terrapref.interop.bag_frames import Conversion, DepthImages, Frames, ImportReport, Motion, Streams, read_small_topics, stream_images
from terrapref.interop.bag_reader import Bag
from terrapref.interop.robot import RobotConfig, load_waypoints
from terrapref.interop.ros_decode import camera_from_info, check_depth_info
from terrapref.interop.runtime import fastest_plausible_mps
from terrapref.progress import Progress
from terrapref.terrain import ClassTable, default_classes
from terrapref.terrain.profile import PreferenceProfile

MAP_MARGIN_M = 15.0
PATH_SMOOTHING_M = 5.0  # half-width of the moving average that turns driven odometry into a path


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

    bag: Bag
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
    bag = Bag(bag_path)
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
        release_folder(tmp)
    return report


def _import(req: _Request, out: Path, show_progress: bool, report: ImportReport) -> None:
    """The recording of ``req.bag`` at ``out``: the small topics read first, then the images streamed."""
    bag, robot = req.bag, req.robot
    roles = ("segmentation", "odometry", "command", "camera_info", "path", "depth", "depth_info")
    bag.check_topics(robot, [role for role in roles if role in robot.topics])
    if bag.unreadable:
        shown = ", ".join(f"{topic} ({msgtype})" for topic, (msgtype, _) in sorted(bag.unreadable.items())[:4])
        report.notes.append(
            f"left out {len(bag.unreadable)} topic(s) whose message definition in the log cannot be read: {shown}"
            + (" ..." if len(bag.unreadable) > 4 else "")
        )
    seg_conns = bag.connections(robot.topics["segmentation"], "segmentation", robot.source)
    streams = read_small_topics(bag, robot)
    report.notes.extend(streams.notes)
    if robot.command_topic is not None and len(streams.cmd_t) == 0:
        raise UserError(bag.source, f"topic {robot.command_topic} holds no usable command", field="topics.command")
    _check_command_speeds(streams, robot, bag.source)
    motion = Motion.of(streams, robot, bag.source, report)
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
    conversion = Conversion(
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
    frames = Frames(streams, motion, conversion, RecordingWriter(out, meta, scenario), report, _depth_images(req, streams, camera))
    try:
        stream_images(bag, robot, seg_conns, (camera.height_px, camera.width_px), frames, progress)
    except UserError:
        frames.writer.abort()  # nothing half-written: a replaced recording stays as it was
        raise
    frames.close(bag.source, progress)


def _check_command_speeds(streams: Streams, robot: RobotConfig, source: str) -> None:
    """Refuse commands faster than any this robot drives (as the runtime refuses such odometry):
    speeds in other units, or garbage, would make every frame's label a straight line."""
    if not len(streams.cmd):
        return
    fastest = float(np.abs(streams.cmd[:, 0]).max())
    top = robot.limits.max_speed_mps
    if fastest > fastest_plausible_mps(top):
        raise UserError(
            source,
            f"topic {robot.command_topic}: a command of {fastest:g} m/s is past any this robot drives (its top speed "
            f"{top:g} m/s, limits.max_speed_mps in {robot.source}): commands in other units?",
            field="topics.command",
        )


def _depth_images(req: _Request, streams: Streams, camera: CameraConfig) -> DepthImages | None:
    """The depth topic's images as the frames will pair them (None: the robot file names none);
    a depth camera whose calibration is not the label camera's is refused."""
    robot = req.robot
    if robot.depth_topic is None:
        return None
    check_depth_info(streams.depth_info, streams.info, robot, req.bag.source)
    conns = req.bag.connections(robot.depth_topic, "depth", robot.source)
    return DepthImages(robot.depth_topic, conns, (camera.height_px, camera.width_px))


def _reference_path(req: _Request, streams: Streams, report: ImportReport) -> np.ndarray:
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


def bag_path_name(source: str) -> str:
    """A scenario name from a bag's file name."""
    stem = Path(source.rstrip("/")).name.split(".")[0] or "bag"
    name = "".join(ch if ch.isalnum() or ch == "_" else "_" for ch in stem)
    return name if name[0].isalpha() else f"bag_{name}"
