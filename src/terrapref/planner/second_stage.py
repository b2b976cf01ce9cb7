"""A second stage of trajectories beyond the first, scored by a learned linear utility.

The trajectories end 5.8 m ahead, and a driver commits to a side of a patch about 5 m before it,
weighing terrain further away (docs/learning.md). The second stage lets the planner see that far
without changing S or C. For each of the ``candidates`` trajectories C ranks highest, it takes
the pose reached after ``after_s`` seconds along that trajectory and lays the whole preference
set out again from there. Every point of that second stage lies on the flat ground at a fixed
place in the vehicle frame, so its pixel in the current frame is precomputed like the first
stage's (a point outside the image counts for no class, as in U). Each second stage gets its
own utilities U': terrain shares, and the distance utility of its trajectories' ends against
the path point one horizon beyond its start, normalised over all the second stages together,
so that a candidate that has left the path scores lower than one that has not. Its value is
the best of its trajectories under the linear utility model ``w . U'_j + b_j`` fitted to the
same demonstrations as C (terrapref.learning.linear). The planner then drives the argmax of

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
from terrapref.features import UtilityFeaturizer
from terrapref.learning.linear import LinearUtility
from terrapref.scenario.path import ReferencePath
from terrapref.vehicle import Pose


@dataclass(frozen=True)
class SecondStageConfig:
    """The second stage's decision rule (defaults chosen on generated courses, docs/learning.md).

    Attributes:
        after_s: where along each candidate trajectory the second stage starts [s]; rounded to
            a trajectory point (point j is j dt along; the last, (n - 1) dt).
        weight: weight of the second stage's value against log F_t.
        candidates: how many of C's highest-ranked trajectories are looked beyond.
        stride: the second stage's terrain shares read every ``stride``-th point of each
            trajectory, ending with its last.
    """

    after_s: float = 2.4
    weight: float = 1.5
    candidates: int = 7
    stride: int = 2

    def __post_init__(self) -> None:
        if not (math.isfinite(self.after_s) and self.after_s > 0 and math.isfinite(self.weight) and self.weight >= 0
                and self.candidates >= 1 and self.stride >= 1):
            raise ValueError("the second stage needs after_s > 0, weight >= 0, candidates >= 1 and stride >= 1")


class SecondStage:
    """Precomputed second stage for one featurizer (preference set and camera) and utility."""

    def __init__(self, config: SecondStageConfig, featurizer: UtilityFeaturizer, camera: PinholeCamera, utility: LinearUtility) -> None:
        pset = featurizer.pset
        step = int(round(config.after_s / featurizer.config.preference.dt_s))
        if not 1 <= step < pset.config.n_steps:
            raise ValueError(f"the second stage's after_s must be within the trajectories (1 to {pset.config.n_steps - 1} steps of dt)")
        if featurizer.config.lanes:
            raise ValueError("the second stage works on U without lanes")
        m, k = pset.m, featurizer.config.n_terrain
        if utility.w.shape != (k + 1,) or utility.b.shape != (m,):
            raise ValueError("the linear utility does not match the feature configuration")
        self.config = config
        self.featurizer = featurizer
        self.w, self.b = np.asarray(utility.w, dtype=float), np.asarray(utility.b, dtype=float)
        self.starts = pset.trajectories[:, step].copy()  # (m, 3): the pose after_s along each trajectory
        n = pset.config.n_steps
        pts = pset.trajectories[:, n - 1 - (n - 1) // config.stride * config.stride :: config.stride, :2]  # (m, n', 2), own frame
        x0, y0, yaw0 = (self.starts[:, j, None, None] for j in range(3))
        c, s = np.cos(yaw0), np.sin(yaw0)
        second = np.stack([x0 + pts[None, ..., 0] * c - pts[None, ..., 1] * s,
                           y0 + pts[None, ..., 0] * s + pts[None, ..., 1] * c], axis=-1)  # (m, m, n', 2) vehicle frame
        pix = camera.pixel_indices(second)  # (m, m, n')
        self._pix = np.where(pix >= 0, pix, 0)
        self._seen = (pix >= 0).astype(float)  # 1 where a point is in the image, 0 where it is not
        self.ends = second[:, :, -1].copy()  # (m, m, 2): each second-stage trajectory's end, vehicle frame
        self._ends = self.ends @ (1.0, 1j)  # the same as complex numbers
        self._x_lo, self._x_hi = float(self.starts[:, 0].min()), float(self.starts[:, 0].max())
        self._n = pts.shape[1]
        self._k = k
        self._horizon_m = featurizer.config.preference.horizon_m
        # By class id: each point's share of every terrain column (1 / n' in its own), and its
        # terrain weight w_k / n' for the scores; 0 for classes U does not count.
        self._point_share = np.eye(k + 1)[featurizer.class_columns, :k] / self._n
        self._point_weight = np.append(self.w[:k] / self._n, 0.0)[featurizer.class_columns]

    def pixels_of(self, i: int) -> np.ndarray:
        """Flat pixel indices (row * width + col) that trajectory ``i``'s second stage reads."""
        return self._pix[i][self._seen[i] > 0]

    def utilities(self, view: SegmentationView, pose: Pose, path: ReferencePath, progress_s: float, rows: np.ndarray) -> np.ndarray:
        """U' of the second stage after each trajectory in ``rows``: shape (len(rows), m, K + 1)."""
        r, m, k = len(rows), self.featurizer.m, self._k
        shares = np.take(self._point_share, view.pixels(self._pix[rows].ravel()), axis=0)
        shares *= self._seen[rows].reshape(-1, 1)
        U = np.empty((r, m, k + 1))
        U[..., :k] = shares.reshape(r, m, self._n, k).sum(axis=2)
        U[..., k] = self._distance_utility(pose, path, progress_s, rows)
        return U

    def _distance_utility(self, pose: Pose, path: ReferencePath, progress_s: float, rows: np.ndarray) -> np.ndarray:
        """u^5 of the second stages after ``rows``, (r, m): each end against the path point one
        horizon beyond its start's progress (the start's forward offset added to the vehicle's)."""
        x, y, yaw = pose
        targets = self._targets(path, progress_s + self._horizon_m, rows)
        d = np.abs(self._ends[rows] * complex(math.cos(yaw), math.sin(yaw)) + (complex(x, y) - targets[:, None]))
        # One range for every second stage: they are compared with one another, and a candidate
        # that has left the path must not find a continuation scored 1 as if it had not.
        return UtilityFeaturizer.normalise(d)

    def _targets(self, path: ReferencePath, s0: float, rows: np.ndarray) -> np.ndarray:
        """Path points at ``s0`` plus each start's forward offset, world frame, complex (r,)."""
        line = path.straight_between(s0 + self._x_lo, s0 + self._x_hi)
        if line is None:
            return path.point_at(s0 + self.starts[rows, 0]) @ (1.0, 1j)
        x, y, ux, uy = line  # the usual case: one straight segment, points along it
        return complex(x, y) + (self.starts[rows, 0] - self._x_lo) * complex(ux, uy)

    def scores(self, log_probs: np.ndarray, view: SegmentationView, pose: Pose, path: ReferencePath, progress_s: float) -> np.ndarray:
        """log F_t + weight * value of the second stage for the candidates; -inf elsewhere, shape (m,)."""
        rows = np.argsort(-log_probs, kind="stable")[: self.config.candidates]
        # w . U'_ij + b_j without building U' (the same sums as utilities() @ w + b, in fewer
        # NumPy calls): terrain weights summed point by point, then the distance term.
        r, m = len(rows), self.featurizer.m
        terrain = np.take(self._point_weight, view.pixels(self._pix[rows].ravel()))
        terrain *= self._seen[rows].ravel()
        distance = self._distance_utility(pose, path, progress_s, rows)
        value = (terrain.reshape(r, m, self._n).sum(axis=2) + self.w[self._k] * distance + self.b).max(axis=1)
        out = np.full(log_probs.shape, -np.inf)
        out[rows] = log_probs[rows] + self.config.weight * value
        return out
