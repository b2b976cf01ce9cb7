"""The planner: at each camera frame, U from the image and the path, the policy's F_t, and the
command its driving rule (terrapref.rules) chooses.

It sees only what a real robot has: the segmentation image, its own pose and the waypoints.
It never reads the world map.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

import numpy as np

from terrapref.camera import CameraConfig, PinholeCamera, SegmentationView, as_view
from terrapref.features import UtilityFeaturizer
from terrapref.groundmap.costmap import Costmap, with_layers
from terrapref.groundmap.height import DepthImage, GeometryLimits
from terrapref.groundmap.map import GroundMap
from terrapref.groundmap.settings import MapSettings
from terrapref.learning.model_file import LoadedModel, check_compatible
from terrapref.planner.goal import GoalCheck, PathState
from terrapref.planner.policy import ClassifierPolicy, Observation, Policy
from terrapref.planner.stop import StopConfig, StopRule
from terrapref.rules import Choice, Rule, RuleContext, RuleInput, chosen_rule, speed_rule
from terrapref.rules.settings import RuleSettings
from terrapref.scenario import Scenario
from terrapref.scenario.path import PathTracker, ReferencePath
from terrapref.sim.loop import Frame
from terrapref.terrain import UNKNOWN
from terrapref.vehicle import MIN_CRUISE_MPS, Command, Pose, VehicleConfig
from terrapref.vehicle.ground import LEVEL, Attitude


class Decision:
    """One planning step.

    Attributes:
        index: chosen trajectory (steered continuously, the nearest one).
        command: its (v [m/s], w [rad/s]); (0, 0) when the planner stops.
        progress_m: the vehicle's progress along the path [m].
        probs: F_t, shape (m,).
        U: utility features, shape (m, K + 1).
        stop: why the planner stops (terrapref.stops.REASONS), None while it drives.

    When the driving rule steers without F_t (the offset rule), U and F_t are computed when
    first read, from the frame's view, pose and path: the same values, and a control loop that
    does not report them does not wait for C.
    """

    __slots__ = ("index", "command", "progress_m", "stop", "_outputs", "_pending")

    def __init__(
        self,
        index: int,
        command: Command,
        progress_m: float,
        outputs: tuple[np.ndarray, np.ndarray] | None = None,
        pending: Callable[[], tuple[np.ndarray, np.ndarray]] | None = None,
        stop: str | None = None,
    ) -> None:
        if (outputs is None) == (pending is None):
            raise ValueError("a decision needs either its (probs, U) or the function that computes them")
        self.index, self.command, self.progress_m, self.stop = index, command, progress_m, stop
        self._outputs, self._pending = outputs, pending

    def _computed(self) -> tuple[np.ndarray, np.ndarray]:
        if self._outputs is None:
            self._outputs, self._pending = self._pending(), None  # the frame is let go once read
        return self._outputs

    @property
    def probs(self) -> np.ndarray:
        return self._computed()[0]

    @property
    def U(self) -> np.ndarray:  # noqa: N802 (the paper's name)
        return self._computed()[1]


STOP_COMMAND = Command(0.0, 0.0)
DEFAULT_HALF_WIDTH_M = 0.6  # the vehicle's half width where the model's features do not say it [m]
PATH_AHEAD_M = np.arange(1.0, 9.0)  # where Observation.path_ahead samples the path [m]


class Planner:
    """A policy (the trained classifier C, or a baseline) driving by the preference set.

    Each frame: U, the policy's F_t, and the command of the driving rule
    (terrapref.rules): by default the one the model file names to drive, or C's
    argmax when it lists none; the goal check (terrapref.planner.goal), which stops at the end
    of the path or far off it, caps the speed on the approach to the goal and turns back to a
    path that lies behind; the robot's limits (top speed and yaw rate: a faster command keeps
    its curvature at the top speed); then the stop rule (terrapref.planner.stop), which commands a
    stop, with its reason, when no way ahead is free or the frames have been blind too long.

    The planner keeps the ground maps the rules read (terrapref.groundmap): one for each distinct
    settings the rules name (the steering rule's, the speed rule's; the stop rule reads the
    steering rule's, or a small one of its own settings where that rule reads none), each updated
    once a frame before any rule reads it, and forgotten with the path.

    Args:
        model: a loaded model file (C) or any :class:`Policy`.
        camera: the robot's camera; a model trained for another camera is refused.
        rule: the rule that drives instead of the one the file names: one of the file's by its
            type (or ``"argmax"``, which every policy has), or a :class:`Rule` (e.g. with another
            configuration).
        stop: when to stop, the goal check's settings included (default: :class:`StopConfig`'s defaults).
        vehicle: the robot's limits, which bound every command (default: the default vehicle's).
        settings: a robot's settings of the model's rules, in place of the file's
            (terrapref.rules.settings); a value a rule cannot take is a UserError.
    """

    def __init__(
        self,
        model: LoadedModel | Policy,
        camera: CameraConfig | None = None,
        rule: Rule | str | None = None,
        stop: StopConfig | None = None,
        vehicle: VehicleConfig | None = None,
        settings: RuleSettings | None = None,
    ) -> None:
        policy = model if isinstance(model, Policy) else ClassifierPolicy(model)
        camera = camera or policy.camera
        if isinstance(model, LoadedModel):
            check_compatible(model, camera)
        elif not policy.camera.same_geometry(camera):
            raise ValueError(f"{policy.name}: built for another camera")
        self.policy = policy
        self.camera = PinholeCamera(camera)
        self.featurizer = UtilityFeaturizer(policy.features, self.camera, policy.classes)
        self.rules = rules_with_settings(policy, settings)
        self.rule = rule if isinstance(rule, Rule) else chosen_rule(self.rules, policy.drives, rule, policy.path or policy.name)
        context = RuleContext(self.camera, self.featurizer, policy.features, policy.classes)
        self.runner = self.rule.runner(context)
        self.control = control = policy.features.preference.control
        self.vehicle = vehicle or VehicleConfig()
        speed = speed_rule(self.rules)
        self.speed = speed.runner(context) if speed is not None else None
        self._set_v, self._max_w = float(control.v_mps), float(np.max(np.abs(control.w_rps)))
        half_width = self.runner.half_width_m
        self.stop_rule = StopRule(
            self.camera,
            context.terrain,
            float(np.max(np.abs(control.w_rps))),
            half_width if half_width is not None else DEFAULT_HALF_WIDTH_M,
            stop,
        )
        self._maps: dict[MapSettings, GroundMap] = {}  # one per distinct settings, updated in this order
        self.ground_map = self._map(context, self.runner.map_settings)  # the steering rule's (None: it reads none)
        # The speed rule reads the steering rule's map, or where that rule reads none, its own (as the stop rule).
        speed_map = (self.runner.map_settings or self.speed.map_settings) if self.speed is not None else None
        self._speed_map = self._map(context, speed_map)
        self._stop_map = self.ground_map if self.ground_map is not None else self._map(context, self.stop_rule.map_settings)
        self.goal = GoalCheck(self.stop_rule.config, min(self._max_w, self.vehicle.max_yaw_rate_rps))
        self.path: ReferencePath | None = None
        self.tracker: PathTracker | None = None

    def set_path(self, waypoints: np.ndarray) -> None:
        """Start following a new reference path (the driving rule and the stop rule forget what they kept, e.g. the ground seen)."""
        self.path = ReferencePath(np.asarray(waypoints, dtype=float))
        self.tracker = PathTracker(self.path)
        self.runner.reset()
        self.stop_rule.reset()
        self.goal.reset()
        if self.speed is not None:
            self.speed.reset()
        self.forget_ground()

    def _map(self, context: RuleContext, settings: MapSettings | None) -> GroundMap | None:
        """The ground map of ``settings`` (None: none), one for all the rules that name the same settings."""
        if settings is None:
            return None
        if settings not in self._maps:
            self._maps[settings] = GroundMap(self.camera, context.terrain, settings)
            self._maps[settings].limits = GeometryLimits.of(self.vehicle)  # ground it cannot cross, where depth shows it
        return self._maps[settings]

    def forget_ground(self) -> None:
        """Forget the ground seen: every ground map the planner keeps is emptied."""
        for ground_map in self._maps.values():
            ground_map.reset()

    def observe(
        self, image: np.ndarray | SegmentationView, pose: Pose, depth: np.ndarray | None = None, attitude: Attitude = LEVEL
    ) -> None:
        """Take in a frame (H, W) uint8 at ``pose`` without deciding: every ground map the planner
        keeps gathers it. With its ``depth`` image (H, W) [m, NaN: no return], the camera placed
        by the pose and the body's ``attitude``, the maps place what it shows where the depth
        says, gather the ground's heights, and block the ground past the robot's limits
        (terrapref.groundmap.height)."""
        view = as_view(image)
        seen = DepthImage(depth, *self.camera.placement(pose, attitude)) if depth is not None else None
        for ground_map in self._maps.values():
            ground_map.update(view, pose, seen)

    def warm_up(self) -> None:
        """Decide once on a blank frame along a straight path, then forget that path.

        The compiled loops (docs/design.md) are loaded now, or compiled if this machine has no
        cached copy yet, instead of in the first step of a control loop.
        """
        path, tracker = self.path, self.tracker
        self.set_path(np.array([[0.0, 0.0], [20.0, 0.0]]))
        self.decide(np.full(self.camera.shape, UNKNOWN, dtype=np.uint8), Pose(0.0, 0.0, 0.0))
        self.path, self.tracker = path, tracker
        self.runner.reset()  # the blank frame is not ground seen
        self.stop_rule.reset()
        self.goal.reset()
        if self.speed is not None:
            self.speed.reset()
        self.forget_ground()

    def decide_frame(self, frame: Frame) -> Decision:
        """:meth:`decide` on a simulated robot's frame (as it reached the robot): its view, pose,
        time and odometry speed, and on relief its depth image and the body's attitude."""
        depth = frame.view.depth if frame.view.carries_depth else None
        return self.decide(frame.view, frame.pose, frame.time_s, frame.speed_mps, depth, frame.attitude)

    def decide(
        self,
        image: np.ndarray | SegmentationView,
        pose: Pose,
        time_s: float | None = None,
        speed_mps: float | None = None,
        depth: np.ndarray | None = None,
        attitude: Attitude = LEVEL,
    ) -> Decision:
        """Choose a command for one segmentation frame (H, W) uint8 at ``pose``, taken at ``time_s``
        [s] (None: frames 0.1 s apart; the stop rule times blind frames by it), the vehicle going
        at ``speed_mps`` [m/s] by its odometry (None: unknown; a speed rule then takes the vehicle
        to go at the speed it commands); with the frame's ``depth`` image and the body's
        ``attitude``, the ground maps gather heights too (:meth:`observe`).

        ``image`` may be a :class:`SegmentationView`, of which only the pixels the policy reads
        are rendered (the preference set's, for C). Given a view, a rule that steers without
        F_t leaves U and F_t to be computed when the decision's ``probs`` or ``U`` is first read
        (a view's pixels do not change); given an array, they are computed now.
        """
        if self.path is None or self.tracker is None:
            raise RuntimeError("call set_path() first")
        # An image in hand carries its depth image with it: the stop rule reads where it has returns.
        view = as_view(image) if depth is None or isinstance(image, SegmentationView) else SegmentationView.of(image, depth, attitude)
        s = self.tracker.update(np.array(pose[:2]))
        state = self.goal.check(pose, self.path, s, self.tracker.lateral_m)
        outputs = functools.partial(_outputs, self.featurizer, self.policy, view, pose, self.path, s)
        if state.stop is not None:  # at the goal or off the path: nothing to steer for (and a pose far off is not computed with)
            if self.speed is not None:
                self.speed.commanded(0.0)
            return Decision(int(self.control.label_of(0.0)), STOP_COMMAND, s, pending=outputs, stop=state.stop)
        if not self.runner.reads_probs and view is image:  # an array the caller may reuse is read now
            probs = U = None
        else:
            probs, U = outputs()
        self.observe(view, pose, depth, attitude)  # every ground map updated, once
        frame = RuleInput(probs, view, pose, self.path, s, self._going(speed_mps), self.ground_map)
        choice = self.runner.decide(frame)  # the steering rule
        choice = self._bounded(self._at_speed(choice, frame), state)  # the speed rule, within the goal check's and the robot's limits
        choice, stop = self._stop(choice, view, pose, time_s, state)  # the stop rule
        command = STOP_COMMAND if stop else choice.command
        if probs is None:
            return Decision(choice.index, command, s, pending=outputs, stop=stop)
        return Decision(choice.index, command, s, (probs, U), stop=stop)

    def _going(self, speed_mps: float | None) -> float | None:
        """How fast the vehicle goes as the steering rule is told (RuleInput.speed_mps): the faster
        of its odometry's speed and the speed commanded last; None without a speed rule."""
        return self.speed.going_mps(speed_mps) if self.speed is not None else None

    def _stop(
        self, choice: Choice, view: SegmentationView, pose: Pose, time_s: float | None, state: PathState
    ) -> tuple[Choice, str | None]:
        """``choice`` and why the stop rule stops instead (None: it does not); where the choice's
        own way is not free and another is, ``choice`` steered onto the nearest free one, no harder
        sideways than the speed rule's lateral limit (:meth:`_within_lateral`) (a turn back to the
        path blocked one way, turned the other way where that is free); the speed rule is told
        the speed commanded."""
        stop, way = self.stop_rule.check(self._stop_map, view, pose, choice.command.v, choice.command.w, time_s)
        if stop is None and state.turn_rps is not None and choice.command.v > 0:
            choice, stop = self._free_turn(choice, pose)
        elif stop is None and way != choice.command.w:
            choice = Choice(int(self.control.label_of(way)), Command(*self._within_lateral(choice.command.v, way)))
        if self.speed is not None:
            self.speed.commanded(0.0 if stop else choice.command.v)
        return choice, stop

    def _within_lateral(self, v_mps: float, w_rps: float) -> tuple[float, float]:
        """(``v_mps``, ``w_rps``) no harder sideways than the speed rule's lateral limit
        (SpeedModel.lateral_limit_mps2: the drive's): the same arc, slower where it would be. The
        stop rule's ways span the stick's range at the speed commanded, and the nearest free one
        may turn harder than anything the driver did at that speed; slower, the way is still free
        (the same arc, a shorter stopping distance)."""
        limit = self.speed.rule.model.lateral_limit_mps2 if self.speed is not None else None
        if limit is None or v_mps <= 0 or abs(v_mps * w_rps) <= limit:
            return v_mps, w_rps
        scale = math.sqrt(limit / abs(v_mps * w_rps))
        return v_mps * scale, w_rps * scale

    def _free_turn(self, choice: Choice, pose: Pose) -> tuple[Choice, str | None]:
        """A turn back to the path on its own arc where that is free, else the other way round
        where that is, else a stop (``no_free_way``)."""
        v, w = choice.command
        for turn in (w, -w):
            if self.stop_rule.arc_free(self._stop_map, pose, v, turn):
                return Choice(int(self.control.label_of(float(turn))), Command(v, turn)), None
        return choice, self.stop_rule.closed_by(self._stop_map, pose, v, np.array([w, -w]))

    def _bounded(self, choice: Choice, state: PathState) -> Choice:
        """``choice`` within the goal check's say and the robot's limits: the turn the check asks
        for instead of the rule's, or the rule's command no faster than the approach to the goal
        and the robot's top speed allow (the same curvature, slower), and no harder a turn than its
        yaw rate allows. A command within them comes back as it was."""
        v, w = choice.command
        if state.turn_rps is not None:
            v, w = min(state.turn_mps, self.vehicle.max_speed_mps), state.turn_rps
        else:
            top = min(state.cap_mps, self.vehicle.max_speed_mps)
            if v > top:
                v, w = top, w * (top / v)
        limit = self.vehicle.max_yaw_rate_rps
        w = min(max(w, -limit), limit)
        if (v, w) == tuple(choice.command):
            return choice
        index = choice.index if state.turn_rps is None else int(self.control.label_of(float(w)))
        return Choice(index, Command(v, w))

    def _at_speed(self, choice: Choice, frame: RuleInput) -> Choice:
        """The steering rule's choice at the speed rule's speed along its way (the same curvature,
        turned no harder than the rule's lateral acceleration allows at the vehicle's speed);
        as chosen without a speed rule."""
        if self.speed is None:
            return choice
        return self.speed.along(self._speed_map, frame, choice, self._set_v, self._max_w)

    def costmap(self) -> Costmap | None:
        """The ground seen so far as the driving rule prices it (terrapref.groundmap.costmap),
        with the speed the speed rule drives each cell at and the ground's height and geometry
        as further layers (:func:`terrapref.groundmap.costmap.with_layers`); None when the
        driving rule reads no ground map (only the offset rule does)."""
        if self.ground_map is None:
            return None
        shed = (0.0, 0.0)
        if self.speed is not None and self.speed.rule.model.sheds_on_grades:
            m = self.speed.rule.model
            shed = (max(m.up_mps_per_deg or 0.0, m.down_mps_per_deg or 0.0), MIN_CRUISE_MPS)
        return with_layers(self.runner.costmap(self.ground_map), self.ground_map, self._cell_speeds(), self.vehicle.max_speed_mps, shed)

    def _cell_speeds(self) -> np.ndarray | None:
        """The speed [m/s] (K + 2,) the speed rule cruises at on each map column (the K terrain
        columns, the background; never-seen ground NaN, lethal ground 0), within its top speed
        and the robot's; None without a speed rule."""
        if self.speed is None:
            return None
        rule = self.speed.rule
        top = min(rule.config.max_speed_mps, self.vehicle.max_speed_mps)
        speeds = np.append(np.minimum(np.asarray(rule.model.speeds_mps, dtype=float), top), np.nan)
        speeds[list(rule.model.lethal)] = 0.0
        return speeds


def rules_with_settings(policy: Policy, settings: RuleSettings | None) -> tuple[Rule, ...]:
    """The policy's rules with a robot's ``settings`` in place of the file's; a value a rule
    cannot take is a UserError naming where the settings came from."""
    if not settings:
        return policy.rules
    lethal = frozenset({policy.classes.lethal_column} if policy.classes.lethal else ())
    return settings.applied(policy.rules, tuple(policy.features.feature_classes), lethal)


def _outputs(
    featurizer: UtilityFeaturizer, policy: Policy, view: SegmentationView, pose: Pose, path: ReferencePath, progress_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """(F_t, U) of one frame: the features, then the policy's probabilities."""
    U = featurizer(view, pose, path, progress_m)
    ahead = path_ahead(path, pose, progress_m) if policy.uses_path_ahead else _NO_POINTS
    return policy.probabilities(Observation(U, view, ahead)), U


def path_ahead(path: ReferencePath, pose: Pose, progress_m: float) -> np.ndarray:
    """The path 1, 2, ... m (PATH_AHEAD_M) ahead of ``progress_m`` in the vehicle frame (P, 2) [m]."""
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    d = path.point_at(progress_m + PATH_AHEAD_M) - (x, y)
    return np.stack([d[:, 0] * c + d[:, 1] * s, -d[:, 0] * s + d[:, 1] * c], axis=1)


_NO_POINTS = np.zeros((0, 2))


class PlannerDriver:
    """The planner as a :class:`terrapref.sim.Driver`; with ``keep``, keeps its decisions for later
    pictures with the number of the frame each was made on (``frames``), and the image decided on
    for the frame numbers in ``images`` (``image_of``)."""

    def __init__(self, planner: Planner, keep: bool = False, images: tuple[int, ...] = ()) -> None:
        self.planner = planner
        self.keep = keep
        self.images = frozenset(images)
        self.decisions: list[Decision] = []
        self.frames: list[int] = []
        self.image_of: dict[int, np.ndarray] = {}
        self.last: Decision | None = None  # the latest decision

    @property
    def stop_reason(self) -> str | None:
        """Why the latest decision stops (terrapref.planner.stop), None while it drives."""
        return self.last.stop if self.last is not None else None

    def reset(self, scenario: Scenario, rng: np.random.Generator) -> None:
        self.planner.set_path(scenario.waypoints)
        self.decisions, self.frames, self.image_of, self.last = [], [], {}, None

    def stale(self, now_s: float, frame_s: float | None, hold_s: float) -> bool:
        """Whether a command decided on a frame stamped ``frame_s`` is stale at ``now_s``: the
        planner's stop rule says (a robot that holds commands asks it: terrapref.perception)."""
        return self.planner.stop_rule.stale(now_s, frame_s, hold_s)

    def act(self, frame: Frame) -> Command:
        d = self.last = self.planner.decide_frame(frame)
        if self.keep:
            d.probs  # noqa: B018 (computed now, so that the kept decisions do not hold their frames)
            self.decisions.append(d)
            self.frames.append(frame.index)
            if frame.index in self.images:
                self.image_of[frame.index] = frame.view.image.copy()
        return d.command
