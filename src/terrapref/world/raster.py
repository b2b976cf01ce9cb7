"""Rasterise a scenario's terrain shapes into a class-id grid and its relief into a height grid, and
look classes and heights up by position."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from terrapref.scenario.model import Scenario
from terrapref.scenario.shapes import Shape
from terrapref.terrain import UNKNOWN, ClassTable
from terrapref.world.height_compiled import height_at, roughness_at
from terrapref.world.relief import height_field

ROUGH_RADIUS_M = 0.3  # the disc a point's roughness is read over [m]: as the planner's height layer reads it


@dataclass(frozen=True, eq=False)
class WorldMap:
    """A class raster over the map ``[0, width] x [0, height]``.

    Attributes:
        raster: class ids, shape (ny, nx) uint8; row r covers y in [r*res, (r+1)*res),
            column c covers x in [c*res, (c+1)*res) (row 0 is the southern edge).
        resolution_m: cell size [m].
        classes: the class table the ids refer to.
        height: the ground's height at each cell centre, shape (ny, nx) float32 [m], z up; None
            where the ground is flat (z = 0 everywhere: nothing is built for it).
    """

    raster: np.ndarray
    resolution_m: float
    classes: ClassTable
    height: np.ndarray | None = None

    @property
    def has_relief(self) -> bool:
        """Whether the ground has a height layer (else it is the plane z = 0)."""
        return self.height is not None

    def height_at(self, xy: np.ndarray) -> np.ndarray:
        """The ground's height [m] at world points (..., 2) [m], shape (...,) float64: bilinear
        between the four nearest cell centres; beyond the outermost centres, the edge's heights
        (the ground goes on level off the map); NaN at a non-finite point. 0 on flat ground."""
        xy = np.asarray(xy, dtype=float)
        if self.height is None:
            return np.zeros(xy.shape[:-1])
        ny, nx = self.height.shape
        finite = np.isfinite(xy).all(axis=-1)
        with np.errstate(invalid="ignore"):
            u = np.clip(np.where(finite, xy[..., 0], 0.0) / self.resolution_m - 0.5, 0.0, nx - 1)  # in cell-centre units
            v = np.clip(np.where(finite, xy[..., 1], 0.0) / self.resolution_m - 0.5, 0.0, ny - 1)
        c0, r0 = np.floor(u).astype(np.int64), np.floor(v).astype(np.int64)
        c1, r1 = np.minimum(c0 + 1, nx - 1), np.minimum(r0 + 1, ny - 1)
        fu, fv = u - c0, v - r0
        z = self.height.astype(np.float64, copy=False)
        south = z[r0, c0] * (1.0 - fu) + z[r0, c1] * fu
        north = z[r1, c0] * (1.0 - fu) + z[r1, c1] * fu
        return np.where(finite, south * (1.0 - fv) + north * fv, np.nan)

    def height_at_point(self, x: float, y: float) -> float:
        """:meth:`height_at` of one point (the vehicle asks it at every tick), by the compiled kernel
        the renderer's rays read the heights with."""
        if self.height is None:
            return 0.0
        if not (math.isfinite(x) and math.isfinite(y)):
            return math.nan
        return height_at(self.height, 1.0 / self.resolution_m, float(x), float(y))

    def roughness_at(self, xy: np.ndarray) -> np.ndarray:
        """The ground's roughness [m] (N,) at world points (N, 2): the standard deviation of the
        heights within :data:`ROUGH_RADIUS_M` of the cell under each about their least-squares
        plane, as the planner's height layer reads it; 0 off the map and on flat ground."""
        xy = np.ascontiguousarray(xy, dtype=np.float64).reshape(-1, 2)
        if self.height is None:
            return np.zeros(len(xy))
        return roughness_at(self.height, self.resolution_m, xy, rough_reach(self.resolution_m))

    @property
    def size_m(self) -> tuple[float, float]:
        ny, nx = self.raster.shape
        return nx * self.resolution_m, ny * self.resolution_m

    def cells_of(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Cell indices (row, col) of world points (..., 2) and a mask of those on the map (a
        non-finite point is off it; its indices are 0)."""
        col = np.floor(xy[..., 0] / self.resolution_m)
        row = np.floor(xy[..., 1] / self.resolution_m)
        ny, nx = self.raster.shape
        inside = (col >= 0) & (col < nx) & (row >= 0) & (row < ny)  # in floats: NaN and huge values are outside on every CPU
        return np.where(inside, row, 0).astype(np.int64), np.where(inside, col, 0).astype(np.int64), inside

    def class_at_point(self, x: float, y: float) -> int:
        """:meth:`class_at` of one point, in plain floats (the simulator asks it at every tick)."""
        x, y = float(x), float(y)  # float64, as class_at divides (a float32 would divide in float32)
        if not (math.isfinite(x) and math.isfinite(y)):
            return UNKNOWN
        col, row = math.floor(x / self.resolution_m), math.floor(y / self.resolution_m)
        ny, nx = self.raster.shape
        return int(self.raster[row, col]) if 0 <= col < nx and 0 <= row < ny else UNKNOWN

    def lethal_within(self, x: float, y: float, radius_m: float) -> bool:
        """Whether the centre of a lethal cell lies within ``radius_m`` of the point ``(x, y)`` [m]
        (the map's edge is not lethal)."""
        r0, r1, c0, c1 = self._window(x, y, radius_m, 0)
        if r1 <= r0 or c1 <= c0:
            return False
        return bool((self._lethal[r0:r1, c0:c1] & self._disc(x, y, radius_m, (r0, r1, c0, c1))).any())

    def steep_within(self, x: float, y: float, radius_m: float, max_slope_deg: float, across_m: float) -> bool:
        """Whether a cell centre within ``radius_m`` of the point ``(x, y)`` [m] lies on ground
        steeper than ``max_slope_deg``, its slope read from the heights ``across_m`` either side of
        it (a body's half track: the tilt a vehicle there would take, not a bump under one wheel);
        never on a flat world."""
        if self.height is None:
            return False
        res, a = self.resolution_m, max(1, round(across_m / self.resolution_m))
        r0, r1, c0, c1 = self._window(x, y, radius_m, a)
        h = self.height[r0:r1, c0:c1].astype(np.float64)
        if h.shape[0] <= 2 * a or h.shape[1] <= 2 * a:
            return False
        gx = (h[a:-a, 2 * a :] - h[a:-a, : -2 * a]) / (2 * a * res)
        gy = (h[2 * a :, a:-a] - h[: -2 * a, a:-a]) / (2 * a * res)
        near = self._disc(x, y, radius_m, (r0 + a, r1 - a, c0 + a, c1 - a))
        steepest = math.tan(math.radians(max_slope_deg))
        return bool((near & (gx * gx + gy * gy > steepest * steepest)).any())

    def _window(self, x: float, y: float, radius_m: float, pad: int) -> tuple[int, int, int, int]:
        """The rows and columns (first, past the last) of the cells within ``radius_m`` of (``x``,
        ``y``) [m] along each axis, ``pad`` cells more either side, clipped to the map."""
        res = self.resolution_m
        ny, nx = self.raster.shape
        rows = max(math.floor((y - radius_m) / res) - pad, 0), min(math.floor((y + radius_m) / res) + pad + 1, ny)
        cols = max(math.floor((x - radius_m) / res) - pad, 0), min(math.floor((x + radius_m) / res) + pad + 1, nx)
        return (*rows, *cols)

    def _disc(self, x: float, y: float, radius_m: float, window: tuple[int, int, int, int]) -> np.ndarray:
        """Which cells of ``window`` (:meth:`_window`) have their centre within ``radius_m`` of (``x``, ``y``)."""
        r0, r1, c0, c1 = window
        res = self.resolution_m
        rows, cols = np.arange(r0, r1), np.arange(c0, c1)
        return ((rows[:, None] + 0.5) * res - y) ** 2 + ((cols[None, :] + 0.5) * res - x) ** 2 <= radius_m**2

    @functools.cached_property
    def _lethal(self) -> np.ndarray:
        """Which cells are lethal (ny, nx), made on first use."""
        return np.isin(self.raster, np.asarray(self.classes.lethal_ids, dtype=self.raster.dtype))

    def class_at(self, xy: np.ndarray) -> np.ndarray:
        """Class id at world points (..., 2) [m]; 255 (unknown) off the map."""
        row, col, inside = self.cells_of(np.asarray(xy, dtype=float))
        out = np.full(row.shape, UNKNOWN, dtype=np.uint8)
        out[inside] = self.raster[row[inside], col[inside]]
        return out


def paint(raster: np.ndarray, shape: Shape, class_id: int, resolution_m: float) -> None:
    """Set every cell whose centre lies inside ``shape`` to ``class_id`` (in place)."""
    ny, nx = raster.shape
    # Clip the bounds to the map first: a huge shape must not overflow the cell arithmetic.
    x0, y0, x1, y1 = (
        float(np.clip(v, -resolution_m, lim + resolution_m)) for v, lim in zip(shape.bounds(), (nx * resolution_m, ny * resolution_m) * 2)
    )
    c0, c1 = max(0, math.floor(x0 / resolution_m)), min(nx, math.ceil(x1 / resolution_m) + 1)
    r0, r1 = max(0, math.floor(y0 / resolution_m)), min(ny, math.ceil(y1 / resolution_m) + 1)
    if c0 >= c1 or r0 >= r1:
        return
    cx = (np.arange(c0, c1) + 0.5) * resolution_m
    cy = (np.arange(r0, r1) + 0.5) * resolution_m
    gx, gy = np.meshgrid(cx, cy)
    inside = shape.contains(np.stack([gx.ravel(), gy.ravel()], axis=1)).reshape(gx.shape)
    raster[r0:r1, c0:c1][inside] = class_id


def rasterise(scenario: Scenario) -> WorldMap:
    """Paint the scenario's terrain, in order, over its background class; and build its height
    layer where it has relief (a flat scenario's world has none)."""
    classes = scenario.classes
    raster = np.full(scenario.grid_shape, classes.id_of(scenario.background), dtype=np.uint8)
    for patch in scenario.terrain:
        paint(raster, patch.shape, classes.id_of(patch.class_name), scenario.resolution_m)
    height = height_field(scenario.relief, scenario.grid_shape, scenario.resolution_m) if scenario.has_relief else None
    return WorldMap(raster, scenario.resolution_m, classes, height)


def rough_reach(resolution_m: float) -> int:
    """The cells :data:`ROUGH_RADIUS_M` spans on a grid of ``resolution_m`` (at least one)."""
    return max(1, int(math.floor(ROUGH_RADIUS_M / resolution_m + 1e-9)))
