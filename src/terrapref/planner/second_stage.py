"""A second stage of trajectories beyond the first, scored by a learned linear utility.

For each of the ``candidates`` trajectories C ranks highest, the look-ahead
(terrapref.features.lookahead) lays the preference set out again from a point along it, and
each of those second pieces is scored with the linear utility model ``w . U'_j + b_j`` fitted
to the same demonstrations as C (terrapref.learning.linear). The planner then drives the argmax of

    log F_t(i) + weight * max_j (w . U'_ij + b_j)

over the candidates. The linear model is a softmax over trajectories too, so its scores are in
the same units (log-probabilities up to a constant) as log F_t. With ``weight`` 0 the planner
is the paper's argmax of F_t.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from terrapref.camera import PinholeCamera, SegmentationView
from terrapref.features import UtilityFeaturizer, kernels
from terrapref.features.lookahead import Lookahead
from terrapref.features.utility import LookaheadConfig
from terrapref.learning.linear import LinearUtility
from terrapref.scenario.path import ReferencePath
from terrapref.vehicle import Pose


@dataclass(frozen=True)
class SecondStageConfig:
    """The second stage's decision rule (defaults chosen on generated courses, docs/notebook.md).

    Attributes:
        after_s: where along each candidate trajectory the second stage starts [s]
            (LookaheadConfig.after_s).
        weight: weight of the second stage's value against log F_t.
        candidates: how many of C's highest-ranked trajectories are looked beyond.
        stride: the second stage's terrain shares read every ``stride``-th point
            (LookaheadConfig.stride).
    """

    after_s: float = 2.4
    weight: float = 1.5
    candidates: int = 7
    stride: int = 2

    def __post_init__(self) -> None:
        if not (math.isfinite(self.after_s) and self.after_s > 0 and math.isfinite(self.weight) and self.weight >= 0
                and self.candidates >= 1 and self.stride >= 1):
            raise ValueError("the second stage needs after_s > 0, weight >= 0, candidates >= 1 and stride >= 1")

    @property
    def lookahead(self) -> LookaheadConfig:
        return LookaheadConfig(self.after_s, self.stride)


class SecondStage(Lookahead):
    """The look-ahead of one featurizer (preference set and camera), scored by a linear utility."""

    def __init__(self, config: SecondStageConfig, featurizer: UtilityFeaturizer, camera: PinholeCamera, utility: LinearUtility) -> None:
        super().__init__(config.lookahead, featurizer, camera)
        k = self.k
        if utility.w.shape != (k + 1,) or utility.b.shape != (self.m,):
            raise ValueError("the linear utility does not match the feature configuration")
        self.config = config
        self.w, self.b = np.asarray(utility.w, dtype=float), np.asarray(utility.b, dtype=float)
        # By class id: each point's terrain weight w_k / n'; 0 for classes U does not count.
        self._point_weight = np.append(self.w[:k] / self.points, 0.0)[featurizer.class_columns]

    def scores(self, log_probs: np.ndarray, view: SegmentationView, pose: Pose, path: ReferencePath, progress_s: float) -> np.ndarray:
        """log F_t + weight * value of the second stage for the candidates; -inf elsewhere, shape (m,)."""
        rows = np.argsort(-log_probs, kind="stable")[: self.config.candidates]
        # w . U'_ij + b_j without building U' (the same sums as utilities() @ w + b, the terrain
        # weights summed point by point in one compiled pass), then the best continuation.
        ids = view.pixels(self.pix[rows].ravel())
        distance = self.distance_utility(pose, path, progress_s, rows)
        return kernels.stage_scores(log_probs, self.config.weight, rows, ids, self._point_weight, self.seen, distance, float(self.w[self.k]), self.b)
