"""The ``second_stage`` stage: trajectories beyond the first, scored by a learned linear utility.

For each of the ``candidates`` trajectories C ranks highest, the look-ahead
(terrapref.features.lookahead) lays the preference set out again from a point along it, and
each of those second pieces is scored with the linear utility model ``w . U'_j + b_j`` fitted
to the same demonstrations as C (terrapref.learning.linear; through the look-ahead when the
data carry it, :attr:`SecondStageConfig.lookahead`). The planner then drives the argmax of

    log F_t(i) + weight * max_j (w . U'_ij + b_j)

over the candidates. The linear model is a softmax over trajectories too, so its scores are in
the same units (log-probabilities up to a constant) as log F_t. With ``weight`` 0 the planner
is the paper's argmax of F_t.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from terrapref.camera import PinholeCamera, SegmentationView
from terrapref.features import FeatureConfig, UtilityFeaturizer, kernels
from terrapref.features.lookahead import Lookahead
from terrapref.features.utility import LookaheadConfig
from terrapref.learning import exact
from terrapref.learning.linear import LinearUtility
from terrapref.planner.stages.base import Choice, Stage, StageConfig, StageContext, StageInput, StageRunner, Where, number, vector
from terrapref.scenario.path import ReferencePath
from terrapref.vehicle import Command, ControlSet, Pose

if TYPE_CHECKING:
    from terrapref.learning.train import FitData

FITS = ("lookahead", "frames")  # how the utility was fitted: through the look-ahead, or frame by frame


@dataclass(frozen=True)
class SecondStageConfig(StageConfig):
    """The second stage's decision rule (defaults chosen on generated courses, docs/notebook.md).

    Attributes:
        after_s: where along each candidate trajectory the second stage starts [s]
            (LookaheadConfig.after_s).
        weight: weight of the second stage's value against log F_t.
        candidates: how many of C's highest-ranked trajectories are looked beyond.
        stride: the second stage's terrain shares read every ``stride``-th point
            (LookaheadConfig.stride).
        lookahead: the training data carry the look-ahead utilities U' (``FeatureConfig.lookahead``)
            and the utility is fitted through them; otherwise frame by frame, on U.
    """

    type: ClassVar[str] = "second_stage"

    after_s: float = 2.4
    weight: float = 1.5
    candidates: int = 7
    stride: int = 2
    lookahead: bool = False

    def __post_init__(self) -> None:
        if not (math.isfinite(self.after_s) and self.after_s > 0 and math.isfinite(self.weight) and self.weight >= 0
                and self.candidates >= 1 and self.stride >= 1):
            raise ValueError("the second stage needs after_s > 0, weight >= 0, candidates >= 1 and stride >= 1")

    @property
    def lookahead_config(self) -> LookaheadConfig:
        return LookaheadConfig(self.after_s, self.stride)

    def features(self, base: FeatureConfig) -> FeatureConfig:
        return replace(base, lookahead=self.lookahead_config) if self.lookahead else base

    def fit(self, data: FitData) -> SecondStage:
        """The linear utility over the samples C was trained on (through the look-ahead when they carry it)."""
        utility, _ = data.linear_utility()
        look = data.dataset.feature_config.lookahead if data.dataset.U2 is not None else None
        config = replace(self, after_s=look.after_s, stride=look.stride) if look is not None else self
        return SecondStage(config, utility, "lookahead" if look is not None else "frames")


@dataclass(frozen=True)
class SecondStage(Stage):
    """A fitted second stage: its rule and the linear utility (w over the K terrain columns and the
    distance utility, b per trajectory) it scores the second pieces with."""

    type: ClassVar[str] = "second_stage"

    config: SecondStageConfig
    utility: LinearUtility
    fit: str = "lookahead"

    def header(self) -> dict[str, Any]:
        c = self.config
        return {"type": self.type, "weight": c.weight, "after_s": c.after_s, "stride": c.stride, "candidates": c.candidates,
                "w": self.utility.w.tolist(), "b": self.utility.b.tolist(), "fit": self.fit}

    @classmethod
    def from_header(cls, block: Mapping[str, Any], features: FeatureConfig, where: Where) -> SecondStage:
        d = SecondStageConfig()
        weight = number(block, "weight", where, d.weight, low=0.0)
        after_s = number(block, "after_s", where, d.after_s, positive=True)
        counts = {}
        for name in ("stride", "candidates"):
            value = block.get(name, getattr(d, name))
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise where.error(name, "expected an integer >= 1")
            counts[name] = value
        fit = block.get("fit", "frames")
        if fit not in FITS:
            raise where.error("fit", f"expected one of {', '.join(FITS)}")
        w = vector(block, "w", features.n_terrain + 1, where)
        b = vector(block, "b", features.preference.m, where)
        try:
            config = SecondStageConfig(after_s, weight, counts["candidates"], counts["stride"], lookahead=fit == "lookahead")
        except ValueError as exc:
            raise where.error("", str(exc)) from None
        return cls(config, LinearUtility(w, b), fit)

    def runner(self, context: StageContext) -> StageRunner:
        return SecondStageScores(self.config, context.featurizer, context.camera, self.utility)

    def describe(self, names: tuple[str, ...], lethal: frozenset[str]) -> str:
        return f"second stage: weight {self.config.weight:g}, linear utility fitted {'through the look-ahead' if self.fit == 'lookahead' else 'frame by frame'}"


class SecondStageScores(Lookahead, StageRunner):
    """The look-ahead of one featurizer (preference set and camera), scored by a linear utility."""

    def __init__(self, config: SecondStageConfig, featurizer: UtilityFeaturizer, camera: PinholeCamera, utility: LinearUtility) -> None:
        super().__init__(config.lookahead_config, featurizer, camera)
        k = self.k
        if utility.w.shape != (k + 1,) or utility.b.shape != (self.m,):
            raise ValueError("the linear utility does not match the feature configuration")
        self.config = config
        self.control: ControlSet = featurizer.config.preference.control
        self.w, self.b = np.asarray(utility.w, dtype=float), np.asarray(utility.b, dtype=float)
        # By class id: each point's terrain weight w_k / n'; 0 for classes U does not count.
        self._point_weight = np.append(self.w[:k] / self.points, 0.0)[featurizer.class_columns]

    def decide(self, frame: StageInput) -> Choice:
        # a probability of exactly 0 is -inf, never chosen
        i = int(np.argmax(self.scores(exact.log(frame.probs), frame.view, frame.pose, frame.path, frame.progress_m)))
        return Choice(i, Command(*self.control.command(i)))

    def scores(self, log_probs: np.ndarray, view: SegmentationView, pose: Pose, path: ReferencePath, progress_m: float) -> np.ndarray:
        """log F_t + weight * value of the second stage for the candidates; -inf elsewhere, shape (m,)."""
        rows = np.argsort(-log_probs, kind="stable")[: self.config.candidates]
        # w . U'_ij + b_j without building U' (the same sums as utilities() @ w + b, the terrain
        # weights summed point by point in one compiled pass), then the best continuation.
        ids = view.pixels(self.pix[rows].ravel())
        distance = self.distance_utility(pose, path, progress_m, rows)
        return kernels.stage_scores(log_probs, self.config.weight, rows, ids, self._point_weight, self.seen, distance, float(self.w[self.k]), self.b)
