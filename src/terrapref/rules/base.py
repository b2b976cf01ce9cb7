"""The interface every decision rule implements (terrapref.rules), and the checks its file blocks share.

Rules are of three kinds (:data:`RULE_KINDS`): a steering rule chooses the way, the speed rule
sets the speed along it, the stop rule (terrapref.planner.stop, the robot's) stops. A rule of a
model file is three objects: its configuration before fitting (:class:`RuleConfig`, what a recipe
names), the fitted rule (:class:`Rule`, one block of a model file's ``rules`` list), and the
fitted rule bound to one planner, a runner of its kind (:class:`SteeringRunner`,
:class:`SpeedRunner`; the stop rule is a :class:`StopRunner`). A rule whose
fit needs more than C's samples reads it from each frame while recordings are featurised
(:meth:`RuleConfig.reader`), and the dataset keeps those arrays under the rule's name.
"""

from __future__ import annotations

import abc
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, NamedTuple

import numpy as np

from terrapref.camera import PinholeCamera, SegmentationView
from terrapref.errors import UserError, finite_number
from terrapref.features import FeatureConfig, UtilityFeaturizer
from terrapref.groundmap.columns import TerrainColumns
from terrapref.groundmap.map import GroundMap
from terrapref.groundmap.settings import MapSettings
from terrapref.scenario.path import ReferencePath
from terrapref.terrain import ClassTable
from terrapref.vehicle import Command, Pose

if TYPE_CHECKING:
    from terrapref.demos.recording import Recording
    from terrapref.groundmap.costmap import Costmap
    from terrapref.learning.train import FitData
    from terrapref.world import WorldMap


@dataclass(frozen=True)
class RuleContext:
    """What a rule is bound to: one planner's camera, featurizer, features and class table."""

    camera: PinholeCamera
    featurizer: UtilityFeaturizer
    features: FeatureConfig
    classes: ClassTable

    @property
    def terrain(self) -> TerrainColumns:
        """The terrain columns of the class table, named by the features' classes."""
        return TerrainColumns.of(self.featurizer.class_columns, self.features.n_terrain, self.classes, self.features.feature_classes)


@dataclass(frozen=True)
class RuleInput:
    """One frame as a rule sees it.

    Attributes:
        probs: F_t, C's distribution over the m trajectories (m,); None for a rule that does
            not read it (``SteeringRunner.reads_probs``).
        view: the segmentation image.
        pose: the vehicle's pose.
        path: the reference path.
        progress_m: the vehicle's progress along it [m].
        speed_mps: how fast the vehicle goes: its odometry's speed, or the speed commanded last
            if that is faster [m/s]; None where the planner sets no speed (the control set's).
        ground_map: the ground map of the rule's ``map_settings``, which the planner keeps and
            has updated with this frame; None for a rule that reads none.
    """

    probs: np.ndarray | None
    view: SegmentationView
    pose: Pose
    path: ReferencePath
    progress_m: float
    speed_mps: float | None = None
    ground_map: GroundMap | None = None


@dataclass(frozen=True)
class Choice:
    """What the steering rule chose: the command, the trajectory it is (or, steered continuously,
    the nearest one), and for a rule that holds a lateral offset from the path, that offset (left
    positive [m]; the speed rule reads the way along the path shifted by it; None: an arc)."""

    index: int
    command: Command
    offset_m: float | None = None


@dataclass(frozen=True)
class RoutePrices:
    """What a rule offers a route search (terrapref.planner.route): a prior map priced as it
    learned, and its price of holding off the path.

    Attributes:
        prior: the costmap of a prior map (every cell known).
        detour_price: per metre along and per square metre of offset held off the path.
        span_m: the metres a detour adds, swerving in and out [m].
    """

    prior: Callable[[WorldMap], Costmap]
    detour_price: float
    span_m: float


STEERING, SPEED, STOP = "steering", "speed", "stop"
"""The three kinds of rule: one steers (a yaw rate, or a choice of trajectory), one sets the speed
along the way it steers, one stops (v = 0, with a reason). A model file lists steering and speed
rules; the stop rule is the robot's (terrapref.planner.stop), set by its robot file."""
RULE_KINDS = (STEERING, SPEED, STOP)


class SteeringRunner(abc.ABC):
    """A steering rule bound to one planner: decides each frame, and forgets what it kept when a run starts.

    A rule that reads a ground map names its settings (``map_settings``); the planner keeps that
    map (terrapref.groundmap), updates it once a frame and hands it to the rule in
    :class:`RuleInput`, and the rule prices what it shows (:meth:`costmap`). A rule that steers
    without C's F_t (``reads_probs`` False) is given none, and the planner computes it only when asked.
    """

    map_settings: MapSettings | None = None  # the ground map the rule reads (None: none)
    reads_probs: ClassVar[bool] = True
    half_width_m: float | None = None  # the footprint's half width the rule keeps clear [m] (None: the planner's default)

    @abc.abstractmethod
    def decide(self, frame: RuleInput) -> Choice:
        """The command for this frame."""

    def reset(self) -> None:
        """Start a new run (a new path)."""

    @property
    def keeps_ground_map(self) -> bool:
        """Whether the rule reads a ground map (``map_settings``), which the planner keeps for it and prices by it."""
        return self.map_settings is not None

    def costmap(self, ground_map: GroundMap) -> Costmap | None:
        """``ground_map`` (the map of the rule's ``map_settings``) priced by what the rule learned
        (terrapref.groundmap.costmap); None for a rule that learned no prices."""
        return None

    def route_prices(self) -> RoutePrices | None:
        """What a route search prices ground with (terrapref.planner.route); None for a rule that learned no prices."""
        return None


class SpeedRunner(abc.ABC):
    """A speed rule bound to one planner: the speed along the way the steering rule chose, read
    from the ground map of ``map_settings`` that the planner keeps."""

    map_settings: MapSettings | None = None

    @abc.abstractmethod
    def reset(self) -> None:
        """Start a new run (a new path): forget the speed commanded last."""

    @abc.abstractmethod
    def commanded(self, v_mps: float) -> None:
        """The speed [m/s] the planner commanded (0 when it stopped)."""

    @abc.abstractmethod
    def going_mps(self, speed_mps: float | None) -> float:
        """How fast the vehicle may be going [m/s], its odometry saying ``speed_mps`` (None: unknown)."""

    @abc.abstractmethod
    def along(self, ground_map: GroundMap, frame: RuleInput, choice: Choice, max_yaw_rate_rps: float) -> Choice:
        """``choice`` (steered at the control set's speed) at this rule's speed along its way: the
        same curvature, turned no harder than the rule allows at the vehicle's speed."""


class Verdict(NamedTuple):
    """What the stop rule says of one frame's command.

    Attributes:
        stop: why the command must be a stop (terrapref.stops.REASONS); None: it is driven.
        w_rps: the yaw rate to drive it with [rad/s]: the command's own, or, where its way is not
            free and another is, that other way's.
    """

    stop: str | None
    w_rps: float


class StopRunner(abc.ABC):
    """The stop rule bound to one planner (terrapref.planner.stop): whether to command v = 0, and
    why (terrapref.stops.REASONS), given the frame, the command chosen and the frames' times."""

    map_settings: MapSettings | None = None

    @abc.abstractmethod
    def reset(self) -> None:
        """Start a new run (a new path)."""

    @abc.abstractmethod
    def check(self, ground_map: GroundMap, view: SegmentationView, pose: Pose, v: float, w: float, time_s: float | None) -> Verdict:
        """Why the command (``v``, ``w``) chosen on this frame, taken at ``time_s``, must be a stop
        (None: it need not), and the yaw rate to drive it with."""

    @abc.abstractmethod
    def stale(self, now_s: float, frame_s: float | None, hold_s: float) -> bool:
        """Whether a command decided on a frame stamped ``frame_s`` (None: none yet) is stale at
        ``now_s`` after holding ``hold_s`` [s]: a stop, ``stale``."""


@dataclass(frozen=True)
class HeaderContext:
    """What a rule's block is read against: the model's features, and the raw ``features``
    section of the file (older files kept a rule's geometry there, as ``corridor`` or ``lookahead``)."""

    features: FeatureConfig
    raw_features: Mapping[str, Any]


class Rule(abc.ABC):
    """A fitted decision rule: its configuration and what was fitted, as one block of a model
    file's ``rules`` list (``type`` names it in :data:`terrapref.rules.RULES`).

    ``kind``: :data:`STEERING` (it chooses the way) or :data:`SPEED` (it sets the speed along the
    way the steering rule chose). ``graph``: the rule's decision is C's graph (what ``terrapref
    export --format onnx`` writes); otherwise the graph holds C alone and the rule runs in the planner.
    """

    type: ClassVar[str]
    kind: ClassVar[str] = STEERING  # or SPEED: it sets the speed along the way another rule steers
    graph: ClassVar[bool] = False
    # What a robot may set of the rule at run time (terrapref.rules.settings): name -> (kind:
    # "number" or "class", a number per class; what it sets, with its unit).
    settable: ClassVar[dict[str, tuple[str, str]]] = {}

    @abc.abstractmethod
    def header(self) -> dict[str, Any]:
        """The block in the model file: ``{"type": ..., ...}`` (JSON values only)."""

    @classmethod
    @abc.abstractmethod
    def from_header(cls, block: Mapping[str, Any], context: HeaderContext, where: Where) -> Rule:
        """The rule a block describes, checked against the model's features; a problem is a
        :class:`UserError` naming the file and the block's field (``where.field(name)``)."""

    @classmethod
    def legacy_block(cls, meta: Mapping[str, Any], source: str) -> dict[str, Any] | None:
        """This rule's block in a file written before the ``stages`` list (its own key of the
        header), or None; read as a block of ``rules`` is. A key that is not a mapping is a
        :class:`UserError` naming ``source`` and the key."""
        return None

    @abc.abstractmethod
    def runner(self, context: RuleContext) -> SteeringRunner | SpeedRunner:
        """This rule bound to one planner (a runner of its kind)."""

    @classmethod
    def setting_problem(cls, name: str, value: float) -> str | None:
        """What is wrong with ``value`` for the setting ``name`` whatever the model (a robot file
        or a node's parameter is refused for it before any model is read); None: nothing."""
        return None

    def with_settings(self, values: Mapping[str, Any], names: tuple[str, ...], lethal: frozenset[str]) -> Rule:
        """This rule with a robot's ``values`` of its :attr:`settable` settings in place of its
        file's (``names``: the terrain columns' classes; ``lethal``: the lethal ones). A value the
        rule cannot take is a ValueError saying why."""
        raise ValueError(f"the {self.type} rule takes no settings")

    @property
    def reads_relief(self) -> bool:
        """Whether the rule was taught the ground's relief (it reads the height layer a depth image
        gives: without one it drives the ground as flat)."""
        return False

    def describe(self, names: tuple[str, ...], lethal: frozenset[str]) -> str:
        """One line on what was fitted (``terrapref train``, ``terrapref info``); ``names`` the terrain columns' classes."""
        return self.type

    def warnings(self, names: tuple[str, ...], lethal: frozenset[str]) -> list[str]:
        """What the drive did not show the fit, and what the rule does there instead, a line each
        (``train``, ``inspect`` and ``info`` print them as warnings)."""
        return []


class FrameReader(abc.ABC):
    """What one rule reads of each frame of one recording while it is featurised, for its fit."""

    @abc.abstractmethod
    def read(self, j: int, view: SegmentationView, pose: Pose, path: ReferencePath, progress_m: float) -> None:
        """Take in frame ``j`` (frames come in order). A ``view`` that carries a depth image
        (relief) gives it with the body's attitude: a reader's ground map places the frame's
        classes where its returns lie and gathers their heights, as the planner's does
        (terrapref.groundmap.height.DepthImage.of); the robot's limits are not applied there
        (they are the robot's, applied where it drives, never learned)."""

    @abc.abstractmethod
    def arrays(self, recording: Recording, keep: np.ndarray, path: ReferencePath) -> dict[str, np.ndarray]:
        """The arrays of the frames read, by name, each with one row per frame (``keep``: the
        recording's frames they were)."""


class RuleConfig(abc.ABC):
    """What a recipe names: a rule before fitting.

    ``arrays``: the arrays its reader gives, each with what it may hold besides finite numbers
    (terrapref.dataset.ARRAY_KINDS), checked when a dataset is read. ``without_data``: what
    becomes of the rule when the training data lack them (said as a warning by ``terrapref train``).
    """

    type: ClassVar[str]
    arrays: ClassVar[dict[str, str]] = {}
    without_data: ClassVar[str] = ""

    def summary(self) -> str:
        """What the rule adds to a recipe, in a few words for a report (``terrapref reproduce``); empty: nothing to say."""
        return ""

    def data(self) -> dict[str, Any] | None:
        """The configuration of what the rule's fit reads of each frame, as the dataset records
        it under the rule's name; None: it needs nothing beyond C's samples."""
        return None

    def reader(self, featurizer: UtilityFeaturizer, camera: PinholeCamera, classes: ClassTable, n: int) -> FrameReader:
        """Reads :meth:`data`'s arrays from ``n`` frames of one recording."""
        raise NotImplementedError(f"the {self.type} rule reads nothing of the frames")

    @abc.abstractmethod
    def fit(self, data: FitData) -> Rule | None:
        """The rule fitted to the samples C was trained on; None when the data lack what the fit needs."""


@dataclass(frozen=True)
class Where:
    """Where a rule's block sits: the file, the list (``rules``; ``stages`` in older files) and the block's position in it."""

    source: str
    index: int
    key: str = "rules"

    def field(self, name: str = "") -> str:
        return f"{self.key}[{self.index}]" + (f".{name}" if name else "")

    def error(self, name: str, message: str) -> UserError:
        return UserError(self.source, message, field=self.field(name))


# The largest number a rule's block may hold, either way: no fitted weight, price, speed or count
# comes near it, and past it the utility's sums and the lines that print them overflow.
MOST_NUMBER = 1e9


def number(
    block: Mapping[str, Any], name: str, where: Where, default: float | None = None, low: float = -np.inf, positive: bool = False
) -> float:
    """A finite number field of a block (``default`` when absent, if given), >= ``low`` (> 0 with
    ``positive``), within :data:`MOST_NUMBER` either way."""
    value = block.get(name, default)
    if finite_number(value) and abs(value) > MOST_NUMBER:
        raise where.error(name, f"expected a number within +-{MOST_NUMBER:g}, got {value:g}")
    ok = finite_number(value) and value >= low
    if not ok or (positive and value <= 0):
        raise where.error(
            name,
            "missing"
            if value is None
            else f"expected a finite number {'> 0' if positive else f'>= {low:g}' if np.isfinite(low) else ''}".rstrip(),
        )
    return float(value)


def vector(block: Mapping[str, Any], name: str, size: int, where: Where) -> np.ndarray:
    """A field of ``size`` finite numbers."""
    value = finite_array(block.get(name), (size,))
    if value is None:
        raise where.error(name, f"expected {size} finite numbers within +-{MOST_NUMBER:g}")
    return value


def finite_array(value: Any, shape: tuple[int, ...]) -> np.ndarray | None:
    """``value`` (nested lists of numbers, as a file's JSON holds them) as a float array of
    ``shape``; None where it is not one: another shape, an entry not a number (a string, a
    boolean), or one not finite, past what a float holds or past :data:`MOST_NUMBER` either way."""

    def numbers(v: Any) -> bool:
        return all(numbers(x) for x in v) if isinstance(v, list) else isinstance(v, (int, float)) and not isinstance(v, bool)

    if not isinstance(value, list) or not numbers(value):
        return None
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError, OverflowError):
        return None
    return array if array.shape == shape and np.isfinite(array).all() and (np.abs(array) <= MOST_NUMBER).all() else None
