"""The planner for a robot's control loop, without the simulator: label images in, commands out.

A ROS 2 node (docs/robot.md, "A ROS 2 node") wraps :class:`PlannerRuntime`: it passes each label image
with its stamp and the robot's pose at that stamp, sends ``command_at(now)`` at its own rate,
and publishes the trajectory probabilities if it likes. Nothing here needs ROS.

Safety: the planner stops, and says why, when no way ahead is free of lethal or unseen ground
within its stopping distance, or when its frames have seen too little ground for too long
(terrapref.planner.stop), at the end of its path (``goal``) and farther from it than it may be
(``off_path``: terrapref.planner.goal); the last decision's command is held for ``hold_s`` after
its frame's stamp, and past that (the camera stopped, frames are late) the runtime commands a
stop, reason ``stale``, until a fresh frame arrives. A frame stamped more than ``ahead_s``
ahead of the caller's clock is refused (given the clock), and a decision that the clock finds
that far in its future is dropped (a stop, ``stale``) rather than held until the clock catches up. Every command stays within the robot's limits (``limits``: top
speed and yaw rate in the planner, keeping the way's curvature; the speed rising no faster than
its acceleration from the last command given out, as a velocity smoother does; a stop is never
held back). An image of the wrong size, a camera other than the model's, or ids that neither the
class table (nor the label map) names are refused with a ``ValueError`` rather than driven on,
unless ``unknown_ids="unknown"`` says such ids are unknown ground (255), which is then never free
for the stop rule.

On uneven ground each label image may come with its depth image (:class:`DepthFrame`: REP 118
metres along the optical axis, of the label camera's size and intrinsics, and the body's
attitude when it was taken): the planner's ground maps then place what the image shows where
the depth returns lie, gather the ground's heights, and block ground past the robot's limits
(terrapref.groundmap.height). Without one, the ground is taken as flat: a model taught on relief
is noted (:attr:`PlannerRuntime.notes`), and once frames have come with depth images a frame
without one is refused, so that a depth camera that stops stops the robot (``stale``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from terrapref.camera import CameraConfig
from terrapref.errors import described, finite_number
from terrapref.groundmap.costmap import Costmap
from terrapref.interop.depth_pairing import DEPTH_PAIRING_S
from terrapref.interop.labels import LabelMap, unlisted_message
from terrapref.interop.ros_decode import millimetres_median
from terrapref.learning.model_file import LoadedModel
from terrapref.planner.model import Model
from terrapref.planner.stop import StopConfig
from terrapref.rules.settings import RuleSettings
from terrapref.scenario.path import ReferencePath
from terrapref.stops import STALE
from terrapref.terrain.classes import UNKNOWN, ForeignIds
from terrapref.vehicle import Command, Pose, VehicleConfig
from terrapref.vehicle.ground import LEVEL, Attitude

STOP = Command(0.0, 0.0)
ODOMETRY_SLACK = 1.5  # an odometry speed past this times the robot's top speed (and 0.5 m/s) is refused, not ramped from


def fastest_plausible_mps(top_mps: float) -> float:
    """The fastest an odometry speed or a logged command of a robot whose top speed is ``top_mps``
    may be [m/s]: faster is in other units, or garbage (:data:`ODOMETRY_SLACK`)."""
    return ODOMETRY_SLACK * top_mps + 0.5


FRAME_AHEAD_S = 1.0  # by default, a frame (or a decision) stamped further ahead of the caller's clock is refused [s]
UNKNOWN_IDS = ("error", "unknown")  # what the runtime makes of an id no table or map names (PlannerRuntime's unknown_ids)
NO_DEPTH = "without a depth image, after frames with one"  # why a frame is refused (PlannerRuntime.refused)
DEPTH_APART = f"with a depth image stamped more than {1000 * DEPTH_PAIRING_S:.0f} ms from it"
# Said of a model taught on relief whose frames come without depth images.
FLAT_NOTE = (
    "the model was taught relief (slopes, steps, rough ground) but its frames come without depth images: "
    "the ground is taken as flat, and no ground is blocked by its geometry"
)


class DepthFrame(NamedTuple):
    """A label image's depth image and the body's attitude when it was taken.

    Attributes:
        image: (H, W) float [m along the optical axis, NaN where nothing is seen; REP 118],
            registered to the label image (its camera's size and intrinsics).
        attitude: the body's height [m], pitch and roll [rad] (REP 103: pitch positive nose
            down, roll positive left side up; each within +-pi/2); level (or None) where the
            robot does not know it.
        stamp_s: when the depth image was taken [s]: one more than
            :data:`~terrapref.interop.depth_pairing.DEPTH_PAIRING_S` from its label image's stamp
            is refused (a depth camera that froze); None: taken with the label image.
    """

    image: np.ndarray
    attitude: Attitude | None = LEVEL
    stamp_s: float | None = None


@dataclass(frozen=True)
class RuntimeDecision:
    """One frame's decision.

    Attributes:
        stamp_s: the frame's stamp [s].
        command: (v [m/s], w [rad/s]): the chosen way at the speed the model's speed rule sets
            along it (the same curvature, w = curvature x v), or at the control set's speed for a
            model without one; (0, 0) when the planner stops. This is what a node sends.
        index: the chosen trajectory (0..m-1, the control set's order).
        probs: C's F_t over the m trajectories.
        progress_m: progress along the path [m].
        U: the frame's utility features (m, K + 1), as C saw them.
        stop: why the planner stops (terrapref.stops.REASONS), None while it drives.
    """

    stamp_s: float
    command: Command
    index: int
    probs: np.ndarray
    progress_m: float
    U: np.ndarray
    stop: str | None = None


@dataclass(frozen=True)
class RobotSettings:
    """What the robot sets of the runtime, never a model file: when it stops, what it may be
    commanded, and how it reads time.

    Attributes:
        stop: when the planner stops, its goal check included (terrapref.planner.stop.StopConfig).
        limits: the robot's limits (top speed, yaw rate, acceleration), which bound every command
            whatever the model asks for, and on relief its tilt and step limits, past which
            ground is lethal (default: the default vehicle's: 2 m/s, 1 rad/s, 1 m/s^2; 25 deg of
            roll, 30 of pitch, a step of 0.15 m).
        hold_s: how long a decision's command stays in force after its frame's stamp [s].
        ahead_s: how far a frame's stamp may be ahead of the caller's clock [s]: clock skew, or a
            simulated clock whose messages come late (default :data:`FRAME_AHEAD_S`).
        rules: the robot's settings of the model's rules, in place of the file's (a speed cap,
            overall or per class, the offset rule's switch margin: terrapref.rules.settings).
    """

    stop: StopConfig = field(default_factory=StopConfig)
    limits: VehicleConfig = field(default_factory=VehicleConfig)
    hold_s: float = 0.3
    ahead_s: float = FRAME_AHEAD_S
    rules: RuleSettings = field(default_factory=RuleSettings)

    def __post_init__(self) -> None:
        for name in ("hold_s", "ahead_s"):
            value = getattr(self, name)
            if not (finite_number(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0")


class PlannerRuntime:
    """A trained model driving from label images.

    Args:
        model: a model file (``terrapref train``, or a learned baseline's), or one loaded
            (terrapref.planner.model.Model; C's file as terrapref.learning.model_file.load_model reads it).
        camera: the robot's camera; a model trained for another one is refused (default: the
            model's own).
        labels: the segmentation network's label map; images then hold its ids (uint8 or
            uint16) and are mapped onto the model's classes. None: images hold terrapref class
            ids (uint8, 255 unknown).
        robot: what the robot sets: when to stop, its limits, how long a command holds and how
            far ahead of the clock a frame may be (:class:`RobotSettings`; default: its defaults).
        unknown_ids: what an id that neither the class table nor the label map names is:
            ``"error"`` (a ValueError naming it) or ``"unknown"`` (unknown ground, 255). A label
            map whose file says ``unlisted: unknown`` makes its unlisted ids unknown either way.

    Attributes:
        notes: what the runtime holds the model to that the model asks to exceed (a speed rule
            faster than the robot's top speed), a line each, for a node to log at its start.
        refused: frames refused, and decisions dropped, by why.
    """

    def __init__(
        self,
        model: str | Path | Model | LoadedModel,
        camera: CameraConfig | None = None,
        labels: LabelMap | None = None,
        robot: RobotSettings | None = None,
        unknown_ids: str = "error",
    ) -> None:
        if unknown_ids not in UNKNOWN_IDS:
            raise ValueError(f"unknown_ids must be one of {', '.join(UNKNOWN_IDS)}, got {unknown_ids!r}")
        self.robot = robot = robot or RobotSettings()
        self.hold_s, self.ahead_s, self.limits = robot.hold_s, robot.ahead_s, robot.limits
        self.model = model if isinstance(model, Model) else Model.of(model) if isinstance(model, LoadedModel) else Model.load(model)
        # Refuses a camera the model was not trained for, and a rule setting a rule cannot take.
        self.planner = self.model.planner(camera, stop=robot.stop, vehicle=robot.limits, settings=robot.rules)
        self.notes = limit_notes(self.model, self.limits) + settings_notes(self.model, robot.rules)
        self.refused = {"stamped ahead of the clock": 0, "decisions the clock found in its future": 0, NO_DEPTH: 0, DEPTH_APART: 0}
        self._with_depth = False  # whether a frame came with a depth image: later ones must too
        self._sent: tuple[float, float] | None = None  # (time [s], v [m/s]) of the last command given out (or the first frame's speed)
        self.planner.warm_up()  # the compiled loops ready before the first frame
        self.shape = self.planner.camera.shape
        self.labels = labels
        self.unknown_ids = unknown_ids
        self.foreign = ForeignIds(self.model.classes)
        if labels is not None:  # ids the map does not list become an id the table does not name, found with the rest
            lenient = unknown_ids == "unknown" or labels.unlisted == "unknown"
            self.lut = labels.lut(self.model.classes, UNKNOWN if lenient else self.foreign.unnamed)
        else:
            self.lut = None
        self.last: RuntimeDecision | None = None

    def set_path(self, waypoints: np.ndarray) -> None:
        """Follow a new reference path, (N, 2) [m] in the frame the poses are given in."""
        waypoints = np.asarray(waypoints, dtype=float)
        ReferencePath(waypoints)  # refuses (ValueError) fewer than two distinct finite points, before anything changes
        self.planner.set_path(waypoints)
        self.last = None
        self._sent = None

    def decide(
        self,
        image: np.ndarray,
        stamp_s: float,
        pose: Pose | tuple[float, float, float],
        speed_mps: float | None = None,
        now_s: float | None = None,
        depth: DepthFrame | None = None,
    ) -> RuntimeDecision | None:
        """Decide on one label image taken at ``stamp_s`` from ``pose`` (x [m], y [m], yaw [rad]),
        the robot going at ``speed_mps`` [m/s] by its odometry (None: not known; a model's speed
        rule then keeps its lateral acceleration at the speed it commands), the caller's clock
        reading ``now_s`` [s] (None: not given), with the image's ``depth`` image and the body's
        attitude (None: the ground is taken as flat).

        Returns None for a frame older than the last one decided on (out of order); such a frame
        changes nothing.

        Raises:
            ValueError: a frame stamped more than ``ahead_s`` ahead of ``now_s`` (its
                clock and the caller's disagree: kept, it would make every later frame look old),
                a frame without a depth image after frames with one, or with one stamped apart
                from it (:class:`DepthFrame`), each counted in :attr:`refused`; or a frame the
                runtime cannot read (size, type, ids, a depth image of another size, not of
                floats or in millimetres, an attitude that is not one); a
                clock not finite; a speed past :data:`ODOMETRY_SLACK` times the robot's top
                speed (and 0.5 m/s), which the commands would rise from at once.
        """
        if self.planner.path is None:
            raise RuntimeError("call set_path() before decide()")
        image = self._ids(np.asarray(image))
        if depth is not None and not isinstance(depth, DepthFrame):
            raise ValueError(f"depth must be a DepthFrame (its image and the body's attitude), got {type(depth).__name__}")
        if len(pose) != 3 or not all(_finite(v) for v in pose):
            raise ValueError(f"pose must be 3 finite numbers (x [m], y [m], yaw [rad]), got {pose!r}")
        pose = Pose(*(float(v) for v in pose))
        if not _finite(stamp_s):
            raise ValueError(f"stamp_s must be a finite number of seconds, got {stamp_s!r}")
        depth_image, attitude = self._depth(depth, float(stamp_s))
        if speed_mps is not None and not _finite(speed_mps):
            raise ValueError(f"speed must be finite, got {speed_mps!r}")
        top = self.limits.max_speed_mps
        if speed_mps is not None and abs(speed_mps) > fastest_plausible_mps(top):  # the speed the commands rise from
            raise ValueError(f"speed {speed_mps:g} m/s is past any this robot drives (its top speed {top:g} m/s): odometry in other units?")
        _check_clock(now_s)
        if now_s is not None and stamp_s > now_s + self.ahead_s:
            self.refused["stamped ahead of the clock"] += 1
            raise ValueError(
                f"a frame stamped {stamp_s - now_s:.3g} s ahead of the clock; refused (another clock, or use_sim_time unset while a log plays?)"
            )
        if self.last is not None and stamp_s <= self.last.stamp_s:
            return None
        self._taken_with(depth_image)
        if self._sent is None:  # nothing given out yet: the robot's speed at this frame is where the speed rises from
            self._sent = (float(stamp_s), 0.0 if speed_mps is None else abs(float(speed_mps)))
        going = None if speed_mps is None else abs(float(speed_mps))
        d = self.planner.decide(image, pose, float(stamp_s), going, depth_image, attitude)
        self.last = RuntimeDecision(float(stamp_s), d.command, d.index, d.probs, d.progress_m, d.U, d.stop)
        return self.last

    def _ids(self, image: np.ndarray) -> np.ndarray:
        """The class ids (H, W) uint8 of a label image: of the camera's size, its ids through the
        label map or named by the class table (a ValueError says what is wrong)."""
        if image.shape != self.shape:
            raise ValueError(f"label image of shape {image.shape}; the model's camera gives {self.shape}")
        if self.lut is not None:
            if image.dtype not in (np.uint8, np.uint16):
                raise ValueError(f"label image of dtype {image.dtype}; expected uint8 or uint16 label ids")
            raw, image = image, self.lut[image]
            if self.foreign(image):
                raise ValueError(
                    unlisted_message(self.labels.unlisted_in(raw), "a label image")
                    + f" (label map {self.labels.source or self.labels.name})"
                )
            return image
        if image.dtype != np.uint8:
            raise ValueError(f"label image of dtype {image.dtype}; expected uint8 class ids (or give a label map)")
        return self._named(image)

    def _depth(self, depth: DepthFrame | None, stamp_s: float) -> tuple[np.ndarray | None, Attitude]:
        """``depth``'s image as float32 and its attitude, checked against the camera and the
        label image's ``stamp_s`` (a ValueError says what is wrong; refused frames are counted);
        (None, level) without one (:meth:`_taken_with` then says what a frame without one is)."""
        if depth is None:
            return None, LEVEL
        image = np.asarray(depth.image)
        if image.shape != self.shape or image.dtype.kind != "f":
            raise ValueError(
                f"depth image of shape {image.shape} and dtype {image.dtype}; expected floats [m] of the label image's shape {self.shape}"
            )
        median = None if self._with_depth else millimetres_median(image)  # a stream's unit, read from its first image taken
        if median is not None:
            raise ValueError(f"depth image of a median {median:g} m: millimetres as it seems; DepthFrame takes metres (REP 118)")
        attitude = _attitude(depth.attitude)
        if depth.stamp_s is not None:
            if not _finite(depth.stamp_s):
                raise ValueError(f"the depth image's stamp_s must be a finite number of seconds, got {depth.stamp_s!r}")
            if abs(float(depth.stamp_s) - stamp_s) > DEPTH_PAIRING_S + 1e-9:
                self.refused[DEPTH_APART] += 1
                raise ValueError(
                    f"a depth image stamped {float(depth.stamp_s) - stamp_s:+.3g} s from its label image; refused "
                    f"(more than {1000 * DEPTH_PAIRING_S:.0f} ms: a depth camera that froze, or another frame's)"
                )
        return image.astype(np.float32, copy=False), attitude

    def _taken_with(self, depth_image: np.ndarray | None) -> None:
        """A frame to be decided on, with its depth image or without: once frames have come with
        one, a frame without is refused (counted); a model taught relief without one is noted."""
        if depth_image is not None:
            self._with_depth = True
            return
        if self._with_depth:
            self.refused[NO_DEPTH] += 1
            raise ValueError(
                "a frame without its depth image, after frames with one: refused (a depth camera that stopped), "
                "so the command in force goes stale; give each label image its DepthFrame"
            )
        if self.model.reads_relief and not any(note.startswith(FLAT_NOTE) for note in self.notes):
            self.notes.append(FLAT_NOTE)

    def _named(self, image: np.ndarray) -> np.ndarray:
        """``image`` with class ids the table does not name refused (ValueError), or made unknown."""
        foreign = self.foreign(image)
        if not foreign:
            return image
        if self.unknown_ids == "error":
            shown = ", ".join(str(i) for i in foreign[:8]) + (" ..." if len(foreign) > 8 else "")
            raise ValueError(
                f"class id{'s' if len(foreign) > 1 else ''} {shown} in a label image "
                f"{'are' if len(foreign) > 1 else 'is'} not in the model's class table ({', '.join(self.model.classes.names)}); "
                "give a label map, or unknown_ids='unknown' to take them as unknown ground"
            )
        return np.where(self.foreign.allowed[image], image, np.uint8(UNKNOWN)).astype(np.uint8)

    def costmap(self) -> Costmap:
        """The learned preference over the ground seen so far, in the frame of the poses given
        (terrapref.groundmap.costmap): 0-99 by learned price, 100 lethal, -1 never seen.

        Raises:
            ValueError: the rule that drives keeps no ground map (recipe teach's offset rule does).
        """
        costmap = self.planner.costmap()
        if costmap is None:
            raise ValueError(
                f"this model drives by rule {self.planner.rule.type}, which keeps no ground map (recipe teach's offset rule does)"
            )
        return costmap

    def command_at(self, now_s: float) -> Command:
        """The command to send at ``now_s``: the last decision's while it is fresh, else a stop."""
        return self.status_at(now_s)[0]

    def status_at(self, now_s: float) -> tuple[Command, str | None]:
        """The command to send at ``now_s`` and why it stops (None while it drives): the last
        decision's while it is fresh (its speed rising no faster than the robot's acceleration
        from the last command given out), else a stop for ``stale`` frames. A decision stamped
        more than ``ahead_s`` after ``now_s`` is dropped, counted in :attr:`refused`. At a clock
        that is not a finite number of seconds, a stop for ``stale`` (nothing is fresh by it),
        which changes nothing for the next call."""
        if not _finite(now_s):
            return STOP, STALE
        if self.last is not None and now_s - self.last.stamp_s < -self.ahead_s:
            self.refused["decisions the clock found in its future"] += 1
            self.last = None  # a later frame stamped by the clock is then taken, not ignored as older
        if self.planner.stop_rule.stale(now_s, None if self.last is None else self.last.stamp_s, self.hold_s):
            return self._given(now_s, STOP), STALE
        return self._given(now_s, self.last.command), self.last.stop

    def _given(self, now_s: float, command: Command) -> Command:
        """``command`` as given out at ``now_s``: its speed no more than the robot's acceleration
        allows above the last one given out (the robot's speed by odometry before the first), its
        curvature kept; a slower command, a stop among them, at once."""
        v, w = command
        accel = self.limits.max_accel_mps2
        if v > 0.0 and accel is not None:
            since, before = self._sent if self._sent is not None else (now_s, 0.0)
            allowed = before + accel * max(0.0, now_s - since)
            if v > allowed:
                v, w = allowed, w * (allowed / v)
        self._sent = (now_s, v)
        return Command(v, w)


def _finite(value: object) -> bool:
    """:func:`terrapref.errors.finite_number`, NumPy's scalars taken as the Python numbers they hold."""
    return finite_number(value.item() if isinstance(value, np.generic) else value)


def _attitude(given: object) -> Attitude:
    """The body's attitude a :class:`DepthFrame` gives (None: level), as an :class:`Attitude`; a
    ValueError naming it where it is not three finite numbers, pitch and roll within +-pi/2."""
    if given is None:
        return LEVEL
    try:
        values = tuple(float(v) for v in given) if not isinstance(given, (str, bytes, dict)) else ()
    except (TypeError, ValueError):
        values = ()
    if len(values) != 3 or not all(math.isfinite(v) for v in values) or max(abs(values[1]), abs(values[2])) > math.pi / 2:
        shown = repr(given) if isinstance(given, tuple) else described(given)
        raise ValueError(
            "a DepthFrame's attitude must be the body's (z_m, pitch_rad, roll_rad): 3 finite numbers, pitch and roll "
            f"within +-pi/2 (None: level); got {shown}"
        )
    return Attitude(*values)


def _check_clock(now_s: float | None) -> None:
    """A ValueError where the caller's clock ``now_s`` is given and not a finite number of seconds."""
    if now_s is not None and not _finite(now_s):
        raise ValueError(f"the clock must be a finite number of seconds, got {now_s!r}")


SPEED_WINDOW_S = 0.2  # a robot's speed at a frame: its odometry's forward motion over this long before the frame's stamp [s]


def odometry_speed_mps(now: Pose, before: Pose, window_s: float = SPEED_WINDOW_S) -> float:
    """The robot's speed [m/s] by its odometry: its motion along its heading at ``now`` since
    ``before``, ``window_s`` [s] earlier (reversing counts as going: the speed is its magnitude)."""
    forward = (now.x - before.x) * math.cos(now.yaw) + (now.y - before.y) * math.sin(now.yaw)
    return abs(forward) / window_s


def settings_notes(model: Model, settings: RuleSettings) -> list[str]:
    """The robot's settings of the model's rules, a line, and a line for those of rules it does not list."""
    if not settings:
        return []
    lines = [f"rule settings over the model file's: {'; '.join(settings.lines())}"]
    unused = settings.unused(model.rules)
    if unused:
        lines.append(f"the model lists no {' or '.join(unused)} rule: its settings are not used")
    return lines


def limit_notes(model: Model, limits: VehicleConfig) -> list[str]:
    """What ``model`` asks for beyond the robot's ``limits``, a line each (its speed rule's top speed)."""
    top = model.top_speed_mps
    if top is None or top <= limits.max_speed_mps:
        return []
    return [
        f"the model's speed rule goes up to {top:g} m/s; the robot's top speed is "
        f"{limits.max_speed_mps:g} m/s: its commands are held to that"
    ]
