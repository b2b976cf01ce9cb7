"""Look-ahead utilities U': the preference set laid out again from a point along each trajectory.

The trajectories end 5.8 m ahead, and a driver commits to a side of a patch about 5 m before
it, weighing terrain further away (docs/learning.md). For each trajectory i, take the pose
reached after ``after_s`` seconds along it and lay the whole preference set out again from
there: 21 x 21 two-piece paths. Every point of a second piece lies on the flat ground at a fixed
place in the vehicle frame, so its pixel in the current frame is precomputed like those of the
trajectories themselves (a point outside the image counts for no class, as in U). Each second piece gets its
own utilities: terrain shares, and the distance utility of its end against the path point one
horizon beyond its start, normalised over all the second pieces together, so that a first
trajectory that has left the path scores its continuations lower than one that has not.

The planner's second stage (terrapref.rules.second.rule) scores these with a learned linear
utility; training fits that utility through the same look-ahead (terrapref.learning.linear).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from terrapref.camera import PinholeCamera, SegmentationView
from terrapref.features.utility import NORMALISE_EPS, UtilityFeaturizer
from terrapref.records import to_plain
from terrapref.rules.second import scores_compiled as kernels
from terrapref.scenario.path import ReferencePath
from terrapref.vehicle import Pose

_NO_TARGETS = np.zeros((0, 2))
_NO_LINE = (0.0, 0.0, 0.0, 0.0)


@dataclass(frozen=True)
class LookaheadConfig:
    """Where the second pieces start and which of their points are read.

    Attributes:
        after_s: where along each first trajectory the second piece starts [s]; rounded to a
            trajectory point (point j is j dt along; the last, (n - 1) dt).
        stride: terrain shares read on every ``stride``-th point of each second piece, ending
            with its last.
    """

    after_s: float = 2.4
    stride: int = 2

    def __post_init__(self) -> None:
        if not (math.isfinite(self.after_s) and self.after_s > 0 and isinstance(self.stride, int) and self.stride >= 1):
            raise ValueError("the look-ahead needs after_s > 0 and an integer stride >= 1")

    def to_dict(self) -> dict:
        return to_plain(self)

    def step(self, n_steps: int, dt_s: float) -> int:
        """The trajectories' step (of ``dt_s`` [s]) the second piece starts at, for trajectories of
        ``n_steps``; ValueError where that lies outside them (from the first step to the last)."""
        step = int(round(self.after_s / dt_s)) if math.isfinite(self.after_s / dt_s) else -1
        if not 1 <= step < n_steps:
            raise ValueError(
                f"the look-ahead starts {self.after_s:g} s along each trajectory, at step {step} of {dt_s:g} s, "
                f"past trajectories of {n_steps} steps (it must start at step 1 to {n_steps - 1})"
            )
        return step

    @classmethod
    def from_dict(cls, data: dict) -> LookaheadConfig:
        return cls(float(data["after_s"]), int(data["stride"]))


class Lookahead:
    """Precomputed second pieces for one featurizer (preference set and camera)."""

    def __init__(self, config: LookaheadConfig, featurizer: UtilityFeaturizer, camera: PinholeCamera) -> None:
        pset = featurizer.pset
        step = config.step(pset.config.n_steps, featurizer.config.preference.dt_s)
        k = featurizer.config.n_terrain
        self.config = config
        self.featurizer = featurizer
        self.starts = pset.trajectories[:, step].copy()  # (m, 3): the pose after_s along each trajectory
        n = pset.config.n_steps
        pts = pset.trajectories[:, n - 1 - (n - 1) // config.stride * config.stride :: config.stride, :2]  # (m, n', 2), own frame
        x0, y0, yaw0 = (self.starts[:, j, None, None] for j in range(3))
        c, s = np.cos(yaw0), np.sin(yaw0)
        second = np.stack(
            [x0 + pts[None, ..., 0] * c - pts[None, ..., 1] * s, y0 + pts[None, ..., 0] * s + pts[None, ..., 1] * c], axis=-1
        )  # (m, m, n', 2) vehicle frame
        pix = camera.pixel_indices(second)  # (m, m, n')
        self.pix = np.where(pix >= 0, pix, 0)
        self.seen = (pix >= 0).astype(float)  # 1 where a point is in the image, 0 where it is not
        self.ends = second[:, :, -1].copy()  # (m, m, 2): each second piece's end, vehicle frame
        self._ends_x, self._ends_y = np.ascontiguousarray(self.ends[..., 0]), np.ascontiguousarray(self.ends[..., 1])
        self._x_lo, self._x_hi = float(self.starts[:, 0].min()), float(self.starts[:, 0].max())
        self._start_x = np.ascontiguousarray(self.starts[:, 0])
        self.points = pts.shape[1]  # points read per second piece
        self.k = k
        self._horizon_m = featurizer.config.preference.horizon_m
        # By class id: each point's share of every terrain column (1 / n' in its own); 0 for classes U does not count.
        self._point_share = np.eye(k + 1)[featurizer.class_columns, :k] / self.points

    @property
    def m(self) -> int:
        return self.featurizer.m

    def pixels_of(self, i: int) -> np.ndarray:
        """Flat pixel indices (row * width + col) that trajectory ``i``'s second pieces read."""
        return self.pix[i][self.seen[i] > 0]

    def utilities(
        self, view: SegmentationView, pose: Pose, path: ReferencePath, progress_m: float, rows: np.ndarray | None = None
    ) -> np.ndarray:
        """U' of the second pieces after each trajectory in ``rows`` (all: None): shape (len(rows), m, K + 1)."""
        rows = np.arange(self.m) if rows is None else rows
        r, m, k = len(rows), self.m, self.k
        shares = np.take(self._point_share, view.pixels(self.pix[rows].ravel()), axis=0)
        shares *= self.seen[rows].reshape(-1, 1)
        U = np.empty((r, m, k + 1))
        U[..., :k] = shares.reshape(r, m, self.points, k).sum(axis=2)
        U[..., k] = self.distance_utility(pose, path, progress_m, rows)
        return U

    def distance_utility(self, pose: Pose, path: ReferencePath, progress_m: float, rows: np.ndarray) -> np.ndarray:
        """u^5 of the second pieces after ``rows``, (r, m): each end against the path point one
        horizon beyond its start's progress (the start's forward offset added to the vehicle's).

        One range normalises every second piece: they are compared with one another, and a first
        trajectory that has left the path must not find a continuation scored 1 as if it had not.
        """
        x, y, yaw = pose
        # Each start's target: the path point at s0 plus the start's forward offset. Usually the
        # path runs straight there and the kernel places the targets along that line itself.
        s0 = progress_m + self._horizon_m
        line = path.straight_between(s0 + self._x_lo, s0 + self._x_hi)
        targets = path.point_at(s0 + self.starts[rows, 0]) if line is None else _NO_TARGETS
        return kernels.stage_distances(
            rows,
            self._ends_x,
            self._ends_y,
            self._start_x,
            self._x_lo,
            line or _NO_LINE,
            targets,
            math.cos(yaw),
            math.sin(yaw),
            x,
            y,
            NORMALISE_EPS,
        )
