"""The ground map's height layer (SPEC 19): elevation per cell from depth images and the camera's
pose, and the ground's geometry read from it as grid_map's traversability filters read theirs.

Each frame's depth image, read at the pixels the map reads its classes at (the ground every
0.1 m ahead, as a level camera over flat ground sees it: about one return a cell), gives returns
in the world: the optical centre plus the depth times the pixel's ray (the camera placed by the
robot's pose, its height, pitch and roll). Each cell keeps the mean height of the returns that
fell in it, how many did and their spread (the ``elevation``, ``returns`` and ``spread`` layers,
terrapref.groundmap.layers); its height is trusted once enough returns agree
(:class:`HeightSettings`). A cell's geometry comes from the trusted cells within ``radius_m`` of
it: the slope of the least-squares plane through them and the roughness (their heights' standard
deviation about that plane), unknown (NaN) where fewer than three are trusted; and the step, the
height range over the cell and its eight neighbours, unknown where fewer than two of them are.

Ground the vehicle cannot cross within its limits is lethal, from its config and never learned
(:class:`GeometryLimits`): a slope past its roll or its pitch limit, whichever is smaller (a
slope may have to be driven across as well as up), or a step higher than it climbs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from terrapref.groundmap import height_compiled as kernels

if TYPE_CHECKING:
    from terrapref.camera import PinholeCamera, SegmentationView
    from terrapref.vehicle import Pose, VehicleConfig


@dataclass(frozen=True)
class HeightSettings:
    """How the height layer is read from depth and its geometry from the layer.

    Attributes:
        radius_m: the disc round a cell its plane is fitted in [m] (0.3 m: half the vehicle's
            width, as grid_map's slope filter is set for a robot of this size).
        min_returns: a cell's elevation counts toward geometry once this many returns fell in it.
        max_error_m: ... and once the standard error of their mean is at most this [m]: a noisy
            depth camera's far returns count once enough of them agree (a stereo camera's error
            grows with the square of the range), as an elevation map's variance gates its cells.
        max_range_m: returns deeper than this [m along the optical axis] are not gathered (a
            camera's attitude known to a degree or two puts far ground's heights that far off).
        block_range_m: the ground this near the vehicle has its geometry checked against the
            limits as returns fall in it [m]; farther ground is checked as the vehicle nears it.
    """

    radius_m: float = 0.3
    min_returns: int = 2
    max_error_m: float = 0.03
    max_range_m: float = 30.0
    block_range_m: float = 10.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.radius_m) and self.radius_m > 0):
            raise ValueError(f"radius_m must be finite and > 0, got {self.radius_m!r}")


class DepthImage(NamedTuple):
    """A frame's depth image and where its camera was.

    Attributes:
        image: (H, W) float32 [m along the optical axis, NaN: no return].
        axes: (3, 3) the camera's axes in the world (rows right, down, forward).
        centre: (3,) its optical centre in the world [m].
    """

    image: np.ndarray
    axes: np.ndarray
    centre: np.ndarray

    @classmethod
    def of(cls, view: SegmentationView, camera: PinholeCamera, pose: Pose) -> DepthImage | None:
        """``view``'s depth image with ``camera`` placed by ``pose`` and the view's attitude
        (:attr:`SegmentationView.attitude`); None when the view carries none (flat ground)."""
        return cls(view.depth, *camera.placement(pose, view.attitude)) if view.carries_depth else None


@dataclass(frozen=True)
class GeometryLimits:
    """The ground a vehicle cannot cross: a slope past ``max_slope_rad``, a step over ``max_step_m``;
    kept ``reach_m`` further off than lethal terrain is, since the planner's footprint is the line
    across the vehicle at its reference point, and its wheels reach half the wheelbase ahead of it."""

    max_slope_rad: float
    max_step_m: float
    reach_m: float = 0.0

    @classmethod
    def of(cls, vehicle: VehicleConfig) -> GeometryLimits:
        """The limits of ``vehicle``: its smaller tilt limit (roll or pitch), its step, half its wheelbase."""
        return cls(math.radians(min(vehicle.max_roll_deg, vehicle.max_pitch_deg)), vehicle.max_step_m, 0.5 * vehicle.wheelbase_m)

    def lethal(self, geometry: np.ndarray) -> np.ndarray:
        """Which cells of ``geometry`` (..., 3: slope, roughness, step) are past the limits;
        unknown geometry (NaN) is not."""
        slope, step = geometry[..., 0], geometry[..., 2]
        return (slope > self.max_slope_rad) | (step > self.max_step_m)


class DepthRays:
    """The pixels of a camera's depth image the height layer reads, and their rays.

    Args:
        camera: the camera.
        flat_index: the pixels (row * width + col).
    """

    def __init__(self, camera: PinholeCamera, flat_index: np.ndarray) -> None:
        self.rows, self.cols = np.divmod(np.asarray(flat_index, dtype=np.int64), camera.config.width_px)
        # Each pixel's ray in the camera frame (right, down, forward = 1): depth times it is the point.
        self.ray = np.stack(
            [(self.cols + 0.5 - camera.cx) / camera.fx, (self.rows + 0.5 - camera.cy) / camera.fy, np.ones(len(self.rows))], axis=1
        )

    def points(self, depth: np.ndarray, axes: np.ndarray, centre: np.ndarray) -> np.ndarray:
        """The returns (N, 3) in the world [m] of ``depth`` (H, W) [m along the optical axis, NaN:
        none] seen by a camera with ``axes`` (3, 3; rows right, down, forward in the world) at
        ``centre`` (3,); NaN rows for pixels without a return."""
        d = depth[self.rows, self.cols].astype(np.float64)
        return centre + (d[:, None] * self.ray) @ axes


class Heights(NamedTuple):
    """A ground map's height layers: ``elevation`` (n, n) float32 [m, NaN: none], ``returns`` (n, n)
    uint32, ``spread`` (n, n) float32 (the returns' sum of squared deviations from the mean [m^2])."""

    elevation: np.ndarray
    returns: np.ndarray
    spread: np.ndarray


def vote_heights(heights: Heights, corner: tuple[float, float], res_m: float, points: np.ndarray, mark: np.ndarray) -> np.ndarray:
    """Fold the returns ``points`` (N, 3) [m] into the layers of a map whose corner is ``corner``;
    the cells they fell in (flat indices, each once). ``mark``: scratch (n * n,) uint8, all 0."""
    points = np.ascontiguousarray(points, dtype=np.float64)
    return kernels.height_vote(*heights, corner[0], corner[1], 1.0 / res_m, points, mark)


def clustered(cells: np.ndarray, n: int) -> np.ndarray:
    """Those of ``cells`` (flat indices of an n by n grid, sorted) with another of them among their
    eight neighbours: a lone cell past the limits is a speckle of noise (a ledge or a bank is a
    line of cells), as a lone lethal cell is to the stop rule."""
    rows, cols = cells // n, cells % n
    has = np.zeros(len(cells), dtype=bool)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            if dr or dc:
                r, c = rows + dr, cols + dc
                inside = (r >= 0) & (r < n) & (c >= 0) & (c < n)
                at = np.searchsorted(cells, r * n + c)
                found = inside & (at < len(cells)) & (cells[np.minimum(at, len(cells) - 1)] == r * n + c)
                has |= found
    return cells[has]


def within_reach(cells: np.ndarray, n: int, reach: int) -> np.ndarray:
    """The cells (flat indices of an n by n grid, each once) within ``reach`` cells (a disc) of any of ``cells``."""
    dr, dc = np.mgrid[-reach : reach + 1, -reach : reach + 1]
    disc = dr * dr + dc * dc <= reach * reach
    rows = cells[:, None] // n + dr[disc][None, :]
    cols = cells[:, None] % n + dc[disc][None, :]
    inside = (rows >= 0) & (rows < n) & (cols >= 0) & (cols < n)
    return np.unique(rows[inside] * n + cols[inside])


def geometry_of_cells(heights: Heights, rows: np.ndarray, cols: np.ndarray, res_m: float, settings: HeightSettings) -> np.ndarray:
    """Slope [rad], roughness [m] and step [m] of the cells (``rows``, ``cols``), (N, 3), from the
    trusted elevations round them (``settings``); NaN where unknown."""
    out = np.empty((len(rows), 3))
    reach = max(1, int(math.floor(settings.radius_m / res_m + 1e-9)))
    trust = (settings.min_returns, settings.max_error_m**2)
    rows, cols = np.asarray(rows, dtype=np.int64), np.asarray(cols, dtype=np.int64)
    kernels.cell_geometry(tuple(heights), trust, rows, cols, reach, res_m, out)
    return out
