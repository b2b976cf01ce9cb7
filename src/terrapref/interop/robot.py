"""Robot files (``terrapref-robot/1``): which topics of a bag hold what, and how the camera sits.

::

    format: terrapref-robot/1
    topics:
      segmentation: /warthog/seg/labels        # sensor_msgs/Image (mono8/mono16 ids) or CompressedImage (png)
      camera_info: /warthog/camera/camera_info # sensor_msgs/CameraInfo (K; plumb_bob distortion)
      odometry: /warthog/odom                  # nav_msgs/Odometry, PoseStamped or PoseWithCovarianceStamped
      command: /warthog/cmd_vel                # optional: geometry_msgs/Twist or TwistStamped, the label
      path: /route/plan                        # nav_msgs/Path; optional (see path_file)
      depth: /warthog/camera/depth             # optional: sensor_msgs/Image 32FC1 [m] or 16UC1 [mm, 0: none]
      depth_info: /warthog/camera/depth_info   # optional: its CameraInfo (default: camera_info's)
    camera:
      height_m: 1.0                            # optical centre above the ground [m]
      pitch_deg: 30.0                          # downward tilt [deg]
      # tf: base_link                          # instead of height_m and pitch_deg (and forward_m,
      #                                        # yaw_deg): the bag's /tf_static from this frame to
      #                                        # the camera_info's frame
      forward_m: 0.0                           # optional: ahead of base_link [m]
      yaw_deg: 0.0                             # optional: left of the heading [deg]
      max_range_m: 30.0                        # optional: farther ground is not used
    labels: rellis3d                           # a packaged label map, or a terrapref-labels/1 file
    path_file: route.yaml                      # optional: waypoints [[x, y], ...] in the odometry frame
    profile: [mud, rock, water, non_traversable]  # optional: the operator's declared order
    max_gap_s: 0.5                             # optional: longer gaps in odometry or images are skipped
    stop:                                      # optional: when the planner stops (terrapref.planner.stop)
      decel_mps2: 1.0                          # the robot's braking [m/s^2]
      reaction_s: 0.2                          # frame to brakes [s]
      margin_m: 0.3                            # kept from lethal or unseen ground when stopped [m]
      blind_after_s: 0.5                       # blind frames tolerated before a stop [s]
      goal_tolerance_m: 0.5                    # at the goal within this of the path's last point [m]
      goal_yaw_tolerance_deg: null             # a number: also turn in place to the path's last direction
      off_path_m: 10.0                         # farther from the path: stop, off_path [m]
    limits:                                    # optional: what the robot may be commanded, whatever the model asks
      max_speed_mps: 2.0                       # top speed [m/s]
      max_yaw_rate_rps: 1.0                    # [rad/s]
      max_accel_mps2: 1.0                      # the speed given out rises no faster [m/s^2]; null: the base ramps it
      max_roll_deg: 25.0                       # on relief: ground that would roll it further is lethal [deg]
      max_pitch_deg: 30.0                      # ... that would pitch it further [deg]
      max_step_m: 0.15                         # ... a step higher than it climbs [m]
    rules:                                     # optional: the robot's settings of the model's rules (terrapref.rules.settings)
      offset: {switch_margin: 0.3}             # RULE: {NAME: value}; docs/robot.md lists them
      speed: {max_speed_mps: 1.5, class_max_mps: {mud: 0.5}}

Without ``topics.command`` each frame is labelled by the vehicle's measured motion (v, w): the
odometry's twist, or differences of its poses where it carries none (terrapref.interop.bag_frames).
A command topic that is named must be in the bag. Without ``topics.path`` or ``path_file`` the
reference path is the driven odometry, smoothed.

``topics.depth`` is a depth image registered to the label images (REP 118): the same camera, or
one resampled onto it, as an RGB-D driver's aligned depth is; each label image is paired with the
depth image of the nearest stamp (terrapref.interop.bag_frames). Its ``depth_info`` must give the
label camera's size and intrinsics (absent: the depth images are taken to be the label camera's,
and must have its size); a depth camera of other intrinsics is refused, not resampled.
Relative file names are relative to the robot file.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np
import yaml

from terrapref.errors import ConfigError, Problem, UserError, described, finite_number
from terrapref.interop.labels import LabelMap, load_label_map
from terrapref.planner.stop import StopConfig
from terrapref.rules import RULES
from terrapref.rules.settings import RuleSettings
from terrapref.scenario.path import FARTHEST_M, ReferencePath
from terrapref.terrain import ClassTable, default_classes
from terrapref.terrain.profile import PreferenceProfile
from terrapref.vehicle import VehicleConfig
from terrapref.vehicle.kinematics import MIN_CRUISE_MPS
from terrapref.yamlio import load_yaml_text, read_capped, read_yaml_mapping

ROBOT_FORMAT = "terrapref-robot/1"
_TOPIC_NAME = re.compile(r"^(?:/[A-Za-z_][A-Za-z0-9_]*)+$")  # a global ROS name
# A topic name as a node's option or remapping may give it: global, relative to the node's
# namespace, or private (``~/x`` in ROS 2, ``~x`` in ROS 1).
GIVEN_TOPIC_NAME = re.compile(r"^(?:~/?|/)?[A-Za-z_][A-Za-z0-9_]*(?:/[A-Za-z_][A-Za-z0-9_]*)*$")
_TOP = {"format", "topics", "camera", "labels", "path_file", "profile", "max_gap_s", "description", "stop", "limits", "rules"}
# The robot's limits a file (or a node's parameters) may set: what it may be commanded, and on
# relief what it crosses (ground past them is lethal: terrapref.groundmap.height.GeometryLimits).
LIMITS = ("max_speed_mps", "max_yaw_rate_rps", "max_accel_mps2", "max_roll_deg", "max_pitch_deg", "max_step_m")
_TOPICS_REQUIRED = ("segmentation", "camera_info", "odometry")
_TOPICS_OPTIONAL = ("command", "path", "depth", "depth_info")
_TOPICS = set(_TOPICS_REQUIRED) | set(_TOPICS_OPTIONAL)
_CAMERA = {
    "height_m": (0.05, 10.0),
    "pitch_deg": (-89.0, 89.0),
    "forward_m": (-10.0, 10.0),
    "yaw_deg": (-180.0, 180.0),
    "max_range_m": (1.0, 500.0),
}


@dataclass(frozen=True)
class RobotConfig:
    """A checked robot file."""

    source: str
    topics: dict[str, str]
    camera: dict[str, float | str]  # height_m, pitch_deg, forward_m, yaw_deg, max_range_m; or tf (a base frame) and max_range_m
    labels: LabelMap
    profile: PreferenceProfile | None  # the operator's declared order; None when the file declares none
    path_file: Path | None
    max_gap_s: float
    stop: StopConfig = field(default_factory=StopConfig)
    limits: VehicleConfig = field(default_factory=VehicleConfig)
    rules: RuleSettings = field(default_factory=RuleSettings)

    @property
    def path_topic(self) -> str | None:
        return self.topics.get("path")

    @property
    def command_topic(self) -> str | None:
        """The operator's commands; None: frames are labelled by the odometry's measured motion."""
        return self.topics.get("command")

    @property
    def depth_topic(self) -> str | None:
        """The depth images registered to the label images; None: the frames carry none."""
        return self.topics.get("depth")


def _number(value: object) -> float | None:
    if not finite_number(value):
        return None
    return float(value)


def load_robot(path: str | Path, classes: ClassTable | None = None, table_of: str | None = None) -> RobotConfig:
    """Read and check a robot file; every problem names the file and the field (exit 2 in the CLI).
    ``table_of`` says whose class table ``classes`` is (a model's, say), where its label map
    names a class the table lacks."""
    classes = classes or default_classes()
    source = str(path)
    data = read_yaml_mapping(path, ROBOT_FORMAT)
    problems = [Problem(k, f"unknown key; expected {', '.join(sorted(_TOP))}") for k in data if k not in _TOP]
    topics = _check_topics(data.get("topics"), problems)
    camera = _check_camera(data.get("camera"), problems)
    problems += _other_problems(data)
    if problems:
        raise ConfigError(source, problems)
    here = Path(path).parent
    labels = _load_labels(data["labels"], here, classes, source, table_of)
    profile_data = data.get("profile")
    profile = PreferenceProfile.parse(profile_data, classes, f"{source}: profile") if profile_data is not None else None
    path_file = data.get("path_file")
    resolved = None
    if path_file is not None:
        resolved = Path(path_file) if Path(path_file).is_absolute() else here / path_file
    return RobotConfig(
        source,
        topics,
        camera,
        labels,
        profile,
        resolved,
        float(data.get("max_gap_s", 0.5)),
        _stop(data.get("stop"), source),
        _limits(data.get("limits"), source),
        RuleSettings.from_block(data.get("rules"), source, RULES),
    )


def load_robot_topics(path: str | Path) -> dict[str, str]:
    """The topics of a robot file by role, checked (the rest of the file is not read)."""
    data = read_yaml_mapping(path, ROBOT_FORMAT)
    problems: list[Problem] = []
    topics = _check_topics(data.get("topics"), problems)
    if problems:
        raise ConfigError(str(path), problems)
    return topics


def stop_value_problem(name: str, value: object) -> str | None:
    """What is wrong with ``value`` for the stop rule's setting ``name`` (a StopConfig field), by
    its kind; None: nothing (its range is StopConfig's to check). The robot file's ``stop`` block
    and a node's ``stop.NAME`` parameters are read so."""
    if value is None and name == "goal_yaw_tolerance_deg":  # the heading not checked
        return None
    if isinstance(value, bool) or not isinstance(value, int if name == "arcs" else (int, float)):
        return "expected a whole number" if name == "arcs" else "expected a number"
    return None


def _stop(block: object, source: str) -> StopConfig:
    """The stop rule's settings from the file's ``stop`` block (absent: the defaults)."""
    if block is None:
        return StopConfig()
    names = [f.name for f in fields(StopConfig)]
    if not isinstance(block, dict):
        raise ConfigError(source, f"expected a mapping of {', '.join(names)}", field="stop")
    for key, value in block.items():
        if key not in names:
            raise ConfigError(source, f"unknown key; expected {', '.join(names)}", field=f"stop.{key}")
        problem = stop_value_problem(key, value)
        if problem is not None:
            raise ConfigError(source, problem, field=f"stop.{key}")
    try:
        return StopConfig(**block)
    except ValueError as exc:
        raise ConfigError(source, str(exc), field="stop") from None


LIMIT_RANGES = {  # the least and the most a robot file or a node's parameter may set each limit to
    "max_speed_mps": (MIN_CRUISE_MPS, 30.0),
    "max_yaw_rate_rps": (0.05, 10.0),
    "max_accel_mps2": (0.05, 50.0),
    "max_roll_deg": (1.0, 89.0),
    "max_pitch_deg": (1.0, 89.0),
    "max_step_m": (0.01, 2.0),
}


def limit_problem(name: str, value: object) -> str | None:
    """What is wrong with ``value`` for the robot's limit ``name`` (one of :data:`LIMITS`); None: nothing."""
    least, most = LIMIT_RANGES[name]
    if value is None and name == "max_accel_mps2":  # a base that ramps its speed itself
        return None
    if _number(value) is None:
        return "expected a finite number" + (" (or null)" if name == "max_accel_mps2" else "")
    if not least <= value <= most:
        return f"expected {least:g} to {most:g}, got {value:g}"
    return None


def _limits(block: object, source: str) -> VehicleConfig:
    """The robot's limits from the file's ``limits`` block (absent: the default vehicle's)."""
    if block is None:
        return VehicleConfig()
    if not isinstance(block, dict):
        raise ConfigError(source, f"expected a mapping of {', '.join(LIMITS)}", field="limits")
    for key, value in block.items():
        if key not in LIMITS:
            raise ConfigError(source, f"unknown key; expected {', '.join(LIMITS)}", field=f"limits.{key}")
        problem = limit_problem(key, value)
        if problem is not None:
            raise ConfigError(source, problem, field=f"limits.{key}")
    try:
        return VehicleConfig(**block)
    except ValueError as exc:
        raise ConfigError(source, str(exc), field="limits") from None


def _check_topics(topics: object, problems: list[Problem]) -> dict[str, str]:
    """The topic of each role in ``topics`` (the file's ``topics``); what is wrong goes in ``problems``."""
    if not isinstance(topics, dict):  # one problem, not one per topic
        problems.append(
            Problem("topics", f"expected a mapping with {', '.join(_TOPICS_REQUIRED)} (and optionally {', '.join(_TOPICS_OPTIONAL)})")
        )
        return {}
    out: dict[str, str] = {}
    for key, value in topics.items():
        if key not in _TOPICS:
            problems.append(Problem(f"topics.{key}", f"unknown key; expected {', '.join(sorted(_TOPICS))}"))
        elif not isinstance(value, str) or not _TOPIC_NAME.match(value):
            shown = f"; got {described(value)}" if isinstance(value, str) else ""
            problems.append(
                Problem(
                    f"topics.{key}",
                    f"expected a topic name such as /robot/odom (ROS's: words of letters, digits and _ after each /){shown}",
                )
            )
        else:
            out[key] = value
    problems += [Problem(f"topics.{k}", "missing") for k in _TOPICS_REQUIRED if k not in topics]
    if "depth_info" in out and "depth" not in out:
        problems.append(Problem("topics.depth_info", "is the depth images' calibration; name their topic as topics.depth too"))
    if "depth" in out and out["depth"] == out.get("segmentation"):
        problems.append(Problem("topics.depth", "is the segmentation topic; the depth images come on a topic of their own"))
    roles: dict[str, str] = {}
    for key, value in out.items():  # each role its own topic (a topic holds one kind of message)
        if value in roles and {key, roles[value]} != {"depth", "segmentation"}:
            problems.append(Problem(f"topics.{key}", f"is topics.{roles[value]}'s topic too; each role comes on a topic of its own"))
        roles.setdefault(value, key)
    return out


def _check_camera(camera: object, problems: list[Problem]) -> dict[str, float | str]:
    """The camera's mounting from ``camera`` (the file's ``camera``), optional entries at their
    defaults, or its base frame as ``tf``; what is wrong goes in ``problems``."""
    out: dict[str, float | str] = {"forward_m": 0.0, "yaw_deg": 0.0, "max_range_m": 30.0}
    if not isinstance(camera, dict):
        problems.append(Problem("camera", "expected a mapping with height_m and pitch_deg (or tf: BASE_FRAME)"))
        return out
    tf_frame = camera.get("tf")
    if tf_frame is not None and (not isinstance(tf_frame, str) or not tf_frame):
        problems.append(Problem("camera.tf", "expected the robot's base frame name, such as base_link"))
    for key, value in camera.items():
        if key != "tf":
            number = _camera_number(key, value, problems)
            if number is not None:
                out[key] = number
        elif isinstance(tf_frame, str) and tf_frame and set(camera) & {"height_m", "pitch_deg", "forward_m", "yaw_deg"}:
            problems.append(Problem("camera.tf", "give either tf or height_m and pitch_deg, not both"))
    if tf_frame is None:
        problems += [Problem(f"camera.{k}", "missing (or give tf: BASE_FRAME)") for k in ("height_m", "pitch_deg") if k not in camera]
    else:
        out["tf"] = tf_frame
    return out


def _camera_number(key: str, value: object, problems: list[Problem]) -> float | None:
    """The number ``camera.<key>`` holds, or None with the problem appended to ``problems``."""
    if key not in _CAMERA:
        problems.append(Problem(f"camera.{key}", f"unknown key; expected {', '.join(_CAMERA)} or tf"))
        return None
    lo, hi = _CAMERA[key]
    number = _number(value)
    if number is None or not lo <= number <= hi:
        problems.append(Problem(f"camera.{key}", f"expected a number in [{lo:g}, {hi:g}]"))
        return None
    return number


def _other_problems(data: dict) -> list[Problem]:
    """What is wrong with the file's max_gap_s, path_file and labels."""
    problems = []
    max_gap = data.get("max_gap_s", 0.5)
    if _number(max_gap) is None or not 0.05 <= max_gap <= 60:
        problems.append(Problem("max_gap_s", "expected a number of seconds in [0.05, 60]"))
    path_file = data.get("path_file")
    if path_file is not None and (not isinstance(path_file, str) or not path_file):
        problems.append(Problem("path_file", "expected a file name"))
    if "labels" not in data or not isinstance(data["labels"], str):
        problems.append(Problem("labels", "expected a packaged label map name (rellis3d) or a terrapref-labels/1 file"))
    return problems


def _load_labels(ref: str, here: Path, classes: ClassTable, source: str, table_of: str | None = None) -> LabelMap:
    """The label map ``ref`` names: a packaged one, or a file (a relative name is in ``here``,
    the robot file's folder), of the class table ``classes`` (``table_of``'s, where given)."""
    if Path(ref).suffix in (".yaml", ".yml") and not Path(ref).is_absolute():
        ref = str(here / ref)
    try:
        return load_label_map(ref, classes, source=f"{source}: labels")
    except UserError as exc:
        whose = (
            f" (the class table of {table_of}: a model of another table than the log's?)"
            if table_of and "not in the class table" in str(exc)
            else ""
        )
        raise ConfigError(source, exc.lines()[0] + whose, field="labels") from None


def load_waypoints(path: Path, source: str | None) -> np.ndarray:
    """Waypoints (N, 2) from a YAML file: a list of [x, y], a mapping with ``waypoints``, or a
    scenario file (its ``path: waypoints``, as ``terrapref route`` writes). ``source``: the robot
    file that names it (its errors are that file's ``path_file``), or None for a node's parameter
    (they are the path file's own)."""

    def refused(problem: str) -> UserError:
        return UserError(source, f"{path}: {problem}", field="path_file") if source else UserError(str(path), problem, field="path_file")

    data = None
    try:
        data = load_yaml_text(read_capped(path).decode("utf-8"))
    except FileNotFoundError:
        raise refused("no such file") from None
    except (OSError, UnicodeDecodeError, ValueError, yaml.YAMLError) as exc:
        raise refused(f"unreadable ({exc})") from None
    if isinstance(data, dict):
        data = data["path"].get("waypoints") if isinstance(data.get("path"), dict) and "waypoints" not in data else data.get("waypoints")
    try:
        points = np.asarray(data, dtype=float)
    except (TypeError, ValueError):
        points = np.zeros((0,))
    try:
        ReferencePath(points)
    except ValueError:
        raise refused(f"expected at least two distinct finite [x, y] waypoints (within +-{FARTHEST_M:g} m of the origin)") from None
    return points
