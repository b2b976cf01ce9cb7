"""The interface every decision stage implements (terrapref.planner.stages), and the checks its file blocks share."""

from __future__ import annotations

import abc
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from terrapref.camera import PinholeCamera, SegmentationView
from terrapref.errors import UserError
from terrapref.features import FeatureConfig, UtilityFeaturizer
from terrapref.features.corridor import GroundMap, TerrainColumns
from terrapref.scenario.path import ReferencePath
from terrapref.terrain import ClassTable
from terrapref.vehicle import Command, Pose

if TYPE_CHECKING:
    from terrapref.learning.train import FitData
    from terrapref.planner.costmap import Costmap


@dataclass(frozen=True)
class StageContext:
    """What a stage is bound to: one planner's camera, featurizer, features and class table."""

    camera: PinholeCamera
    featurizer: UtilityFeaturizer
    features: FeatureConfig
    classes: ClassTable

    @property
    def terrain(self) -> TerrainColumns:
        """The terrain columns of the class table, named by the features' classes."""
        return TerrainColumns.of(self.featurizer.class_columns, self.features.n_terrain, self.classes, self.features.feature_classes)


@dataclass(frozen=True)
class StageInput:
    """One frame as a stage sees it.

    Attributes:
        probs: F_t, C's distribution over the m trajectories (m,); None for a stage that does
            not read it (``StageRunner.reads_probs``).
        view: the segmentation image.
        pose: the vehicle's pose.
        path: the reference path.
        progress_m: the vehicle's progress along it [m].
    """

    probs: np.ndarray | None
    view: SegmentationView
    pose: Pose
    path: ReferencePath
    progress_m: float


@dataclass(frozen=True)
class Choice:
    """What a stage drives: the command, and the trajectory it is (or, steered continuously, the nearest one)."""

    index: int
    command: Command


class StageRunner(abc.ABC):
    """A stage bound to one planner: decides each frame, and forgets what it kept when a run starts.

    A stage that keeps a ground map (``keeps_ground_map``) also takes in frames without deciding
    (:meth:`observe`) and prices what it has seen (:meth:`costmap`). A stage that steers without
    C's F_t (``reads_probs`` False) is given none, and the planner computes it only when asked.
    """

    keeps_ground_map: ClassVar[bool] = False
    reads_probs: ClassVar[bool] = True

    @abc.abstractmethod
    def decide(self, frame: StageInput) -> Choice:
        """The command for this frame."""

    def reset(self) -> None:
        """Start a new run (a new path)."""

    def observe(self, view: SegmentationView, pose: Pose) -> None:
        """Take in a frame's view without deciding (a stage that keeps no ground map ignores it)."""

    def costmap(self) -> Costmap | None:
        """The ground seen so far priced by what the stage learned (terrapref.planner.costmap),
        for a stage that keeps a ground map; None otherwise."""
        return None

    @property
    def ground_map(self) -> GroundMap | None:
        """The ground map the stage keeps, updated as it decides (the stop rule reads it); None for a stage that keeps none."""
        return None


class Stage(abc.ABC):
    """A fitted decision stage: its configuration and what was fitted, as one block of a model
    file's ``stages`` list (``type`` names it in :data:`STAGES`)."""

    type: ClassVar[str]

    @abc.abstractmethod
    def header(self) -> dict[str, Any]:
        """The block in the model file: ``{"type": ..., ...}`` (JSON values only)."""

    @classmethod
    @abc.abstractmethod
    def from_header(cls, block: Mapping[str, Any], features: FeatureConfig, where: Where) -> Stage:
        """The stage a block describes, checked against the model's features; a problem is a
        :class:`UserError` naming the file and the block's field (``where.field(name)``)."""

    @abc.abstractmethod
    def runner(self, context: StageContext) -> StageRunner:
        """This stage bound to one planner."""

    def describe(self, names: tuple[str, ...], lethal: frozenset[str]) -> str:
        """One line on what was fitted (``terrapref train``, ``terrapref info``); ``names`` the terrain columns' classes."""
        return self.type


class StageConfig(abc.ABC):
    """What a recipe names: a stage before fitting."""

    type: ClassVar[str]

    def features(self, base: FeatureConfig) -> FeatureConfig:
        """The feature configuration the training data need for this stage's fit (``base`` with its parts)."""
        return base

    @abc.abstractmethod
    def fit(self, data: FitData) -> Stage | None:
        """The stage fitted to the samples C was trained on; None when the data lack what the fit needs."""


@dataclass(frozen=True)
class Where:
    """Where a stage's block sits: the file and the block's position in ``stages``."""

    source: str
    index: int

    def field(self, name: str = "") -> str:
        return f"stages[{self.index}]" + (f".{name}" if name else "")

    def error(self, name: str, message: str) -> UserError:
        return UserError(self.source, message, field=self.field(name))


def number(block: Mapping[str, Any], name: str, where: Where, default: float | None = None, low: float = -np.inf,
           positive: bool = False) -> float:
    """A finite number field of a block (``default`` when absent, if given), >= ``low`` (> 0 with ``positive``)."""
    value = block.get(name, default)
    ok = not isinstance(value, bool) and isinstance(value, (int, float)) and np.isfinite(value) and value >= low
    if not ok or (positive and value <= 0):
        raise where.error(name, "missing" if value is None else f"expected a finite number {'> 0' if positive else f'>= {low:g}' if np.isfinite(low) else ''}".rstrip())
    return float(value)


def vector(block: Mapping[str, Any], name: str, size: int, where: Where) -> np.ndarray:
    """A field of ``size`` finite numbers."""
    try:
        value = np.asarray(block[name], dtype=float)
    except (KeyError, TypeError, ValueError):
        value = None
    if value is None or value.shape != (size,) or not np.isfinite(value).all():
        raise where.error(name, f"expected {size} finite numbers")
    return value
