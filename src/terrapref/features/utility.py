"""Utility features U(S, P) in R^{m x (K + 1)} (SPEC 7): K terrain shares and a distance utility.

Terrain utility u^k(T) is the share of T's n points whose pixel shows class k; a point outside
the image counts for no class but still counts in n. The distance utility scores where each
trajectory ends relative to the reference path, normalised over the set:
u^5 = 1 - (d - d_min) / (d_max - d_min), or 1 for all when the range is (near) zero.

Three definitions of d, recorded with every dataset and model:
- ``paper``: distance from the trajectory's end to the nearest path point, all of P.
- ``window``: nearest path point among those ahead of the vehicle's progress, within
  ``window_m``, so that a path passing near itself or behind the vehicle cannot capture it.
- ``progress`` (default; ``lookahead`` in older files): distance to the single path point at progress + the trajectory's
  travel distance (where a perfect follower would be). With the window starting at the
  vehicle, the tightest arcs (w = +-1 over 6 m) curl back to end beside the vehicle, next to
  the path, and get the best ``window`` score; the look-ahead point ranks them last.
The path is resampled every ``path_spacing_m`` so that sparse waypoints still give a dense P.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from terrapref.camera import PinholeCamera, SegmentationView, as_view
from terrapref.features import utility_compiled as kernels
from terrapref.features.preference_set import PreferenceSet, PreferenceSetConfig
from terrapref.records import to_plain
from terrapref.scenario.path import ReferencePath
from terrapref.terrain import ClassTable, default_classes
from terrapref.vehicle import Pose

NORMALISE_EPS = 1e-9  # a distance range below this normalises to all ones


class DistanceMode(str, Enum):
    PAPER = "paper"
    WINDOW = "window"
    PROGRESS = "progress"

    @classmethod
    def _missing_(cls, value: object) -> DistanceMode | None:
        # ``lookahead``: this mode's name in files and flags before "look-ahead" was the second stage's alone
        return cls.PROGRESS if value == "lookahead" else None


@dataclass(frozen=True)
class FeatureConfig:
    """How U is computed; carried with every dataset and model.

    Attributes:
        preference: the preference set S (control set, n, dt).
        distance_mode: definition of d (see module docstring).
        window_m: length of the candidate window ahead of the progress for ``window`` mode
            [m]; None means twice the trajectory length.
        path_spacing_m: resampling step of the reference path [m].
        feature_classes: class names of the terrain columns, in order (the table's
            non-background classes in id order).
    """

    preference: PreferenceSetConfig = field(default_factory=PreferenceSetConfig)
    distance_mode: DistanceMode = DistanceMode.PROGRESS
    window_m: float | None = None
    path_spacing_m: float = 0.25
    feature_classes: tuple[str, ...] = field(default_factory=lambda: default_classes().feature_names)

    def __post_init__(self) -> None:
        object.__setattr__(self, "distance_mode", DistanceMode(self.distance_mode))
        if not self.path_spacing_m >= 0.01 or (self.window_m is not None and not self.window_m > 0):
            raise ValueError("path_spacing_m must be >= 0.01 m (a path is resampled at it) and window_m > 0")

    @property
    def effective_window_m(self) -> float:
        return self.window_m if self.window_m is not None else 2.0 * self.preference.horizon_m

    @property
    def n_terrain(self) -> int:
        """Terrain columns: the shares of each class on each trajectory's points."""
        return len(self.feature_classes)

    @property
    def n_features(self) -> int:
        return len(self.column_names)

    @property
    def column_names(self) -> tuple[str, ...]:
        return (*self.feature_classes, "distance")

    def to_dict(self) -> dict:
        return to_plain(self)

    @classmethod
    def from_dict(cls, data: dict) -> FeatureConfig:
        if float(data.get("lane_m", 0.0)) != 0.0:
            # Lane columns beyond the trajectories' ends and a near distance column are not
            # features this code computes: a file that asks for them is refused rather than
            # read without them (docs/notebook.md names the commit that reads such files).
            raise ValueError(f"lane columns (lane_m {data['lane_m']}) are no longer supported; featurise the recordings again")
        if float(data.get("near_m", 0.0)) != 0.0:  # likewise the near distance column
            raise ValueError(f"the near distance column (near_m {data['near_m']}) is no longer supported; featurise the recordings again")
        return cls(
            PreferenceSetConfig.from_dict(data["preference"]),
            DistanceMode(data["distance_mode"]),
            data.get("window_m"),
            float(data["path_spacing_m"]),
            tuple(data["feature_classes"]),
        )  # a file written before the rules owned their data may also hold ``lookahead`` and ``corridor``: the rules read those


class UtilityFeaturizer:
    """Computes U from a segmentation image, the vehicle pose and the path (vectorised)."""

    def __init__(self, config: FeatureConfig, camera: PinholeCamera, classes: ClassTable | None = None) -> None:
        classes = classes or default_classes()
        self.config = config
        self.pset = PreferenceSet(config.preference, camera)
        m, k = self.pset.m, len(config.feature_classes)
        pix = self.pset.pixel_index  # (m, n): one row of pixels per trajectory
        # Every trajectory gets k + 1 bincount bins; unseen points all fall in one extra,
        # discarded row.
        self._rows = m
        row = np.repeat(np.arange(m), pix.shape[1])
        pix = pix.ravel()
        self._column = np.full(256, k, dtype=np.intp)  # class id -> terrain column (k: none)
        for j, name in enumerate(config.feature_classes):
            self._column[list(classes.ids_of(name))] = j
        self._point_row = np.where(pix >= 0, row, self._rows)  # m: a point outside the image
        self._pix_flat = np.where(pix >= 0, pix, 0)
        self._pix_flat.flags.writeable = False  # read-only: a renderer may prepare it once
        self._scale = 1.0 / self.pset.pixel_index.shape[1]  # the share of one point
        self._ends = self.pset.endpoints  # (m, 2) vehicle frame
        self._ex, self._ey = np.ascontiguousarray(self._ends[:, 0]), np.ascontiguousarray(self._ends[:, 1])

    @property
    def m(self) -> int:
        return self.pset.m

    @property
    def class_columns(self) -> np.ndarray:
        """Terrain column of each class id (256,); K (no column) for classes U does not count."""
        return self._column

    def terrain(self, image: np.ndarray | SegmentationView) -> np.ndarray:
        """Terrain utilities, shape (m, K): the share of each trajectory's points on each class."""
        ids = as_view(image).pixels(self._pix_flat)
        return kernels.terrain_shares(ids, self._column, self._point_row, self._rows, len(self.config.feature_classes), self._scale)

    def distances(self, pose: Pose, path: ReferencePath, progress_m: float | None = None) -> np.ndarray:
        """d(T^i, P) [m] for each trajectory, shape (m,)."""
        x, y, yaw = pose
        c, s = math.cos(yaw), math.sin(yaw)
        ex, ey = self._ends[:, 0], self._ends[:, 1]
        mode = self.config.distance_mode
        if mode is DistanceMode.PROGRESS:
            if progress_m is None:
                raise ValueError("the progress distance mode needs the vehicle's progress along the path")
            tx, ty = path.point_at(progress_m + self.config.preference.horizon_m)
            # Endpoint minus target, in the world frame, without building the (m, 2) array.
            return kernels.end_distances(ex, ey, c, s, x - tx, y - ty)
        ends = self._ends @ np.array([[c, s], [-s, c]]) + (x, y)  # endpoints in the world frame
        pts, arc = path.resampled(self.config.path_spacing_m)
        if mode is DistanceMode.WINDOW:
            if progress_m is None:
                raise ValueError("windowed distance needs the vehicle's progress along the path")
            lo = np.searchsorted(arc, progress_m, side="left")
            hi = np.searchsorted(arc, progress_m + self.config.effective_window_m, side="right")
            pts = pts[max(0, min(lo, len(pts) - 1)) : max(hi, lo + 1)]
        diff = ends[:, None, :] - pts[None, :, :]
        return np.sqrt(np.min(np.einsum("mpj,mpj->mp", diff, diff), axis=1))

    @staticmethod
    def normalise(d: np.ndarray, eps: float = NORMALISE_EPS) -> np.ndarray:
        """u^5 = 1 - (d - d_min) / (d_max - d_min); all ones when the range is below ``eps``."""
        return kernels.normalise(np.asarray(d, dtype=np.float64), eps)

    def __call__(
        self, image: np.ndarray | SegmentationView, pose: Pose, path: ReferencePath, progress_m: float | None = None
    ) -> np.ndarray:
        """U, shape (m, n_features) float32: terrain shares, then the distance utility."""
        if self.config.distance_mode is DistanceMode.PROGRESS and progress_m is not None:  # the usual case, in one compiled call
            x, y, yaw = pose
            tx, ty = path.point_at(progress_m + self.config.preference.horizon_m)
            ids = as_view(image).pixels(self._pix_flat)
            return kernels.utilities(
                ids,
                self._column,
                self._point_row,
                len(self.config.feature_classes),
                self._scale,
                self._ex,
                self._ey,
                math.cos(yaw),
                math.sin(yaw),
                x - tx,
                y - ty,
                NORMALISE_EPS,
            )
        u = np.empty((self.m, self.config.n_features), dtype=np.float32)
        u[:, :-1] = self.terrain(image)
        u[:, -1] = self.normalise(self.distances(pose, path, progress_m))
        return u
