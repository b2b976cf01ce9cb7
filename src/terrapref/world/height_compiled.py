"""The ground's height at a point, compiled (Numba): the renderer's rays and the vehicle's wheels
read the height field through it; and the least-squares plane through heights, which the planner's
height layer and the synthetic driver read slope and roughness from."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, inline="always")
def height_at(heights: np.ndarray, per_m: float, x: float, y: float) -> float:
    """The ground's height at (x, y) [m], bilinear between cell centres as
    :meth:`terrapref.world.WorldMap.height_at` (the edge's heights beyond the outermost
    centres); ``per_m`` is cells per metre."""
    ny, nx = heights.shape
    u = min(max(x * per_m - 0.5, 0.0), nx - 1.0)
    v = min(max(y * per_m - 0.5, 0.0), ny - 1.0)
    c0, r0 = int(math.floor(u)), int(math.floor(v))
    c1, r1 = min(c0 + 1, nx - 1), min(r0 + 1, ny - 1)
    fu, fv = u - c0, v - r0
    south = np.float64(heights[r0, c0]) * (1.0 - fu) + np.float64(heights[r0, c1]) * fu
    north = np.float64(heights[r1, c0]) * (1.0 - fu) + np.float64(heights[r1, c1]) * fu
    return south * (1.0 - fv) + north * fv


@njit(cache=True, nogil=True, inline="always")
def plane_fit(sums: tuple[float, ...]) -> tuple[float, float]:
    """Slope [rad] and roughness [m] of the least-squares plane through the points of ``sums``
    (the normal equations' sums m, x, y, z, xx, yy, xy, xz, yz, zz, as the height layer's disc gives them,
    terrapref.groundmap.height_compiled;
    x and y offsets from any point); NaN where the points are on a line (the plane is not determined)."""
    m, sx, sy, sz, sxx, syy, sxy, sxz, syz, szz = sums
    # Centred second moments.
    cxx, cyy, cxy = sxx - sx * sx / m, syy - sy * sy / m, sxy - sx * sy / m
    cxz, cyz, czz = sxz - sx * sz / m, syz - sy * sz / m, szz - sz * sz / m
    det = cxx * cyy - cxy * cxy
    if det <= 1e-12 * max(cxx * cyy, 1e-300):
        return np.nan, np.nan
    a = (cxz * cyy - cyz * cxy) / det
    b = (cyz * cxx - cxz * cxy) / det
    residual = czz - a * cxz - b * cyz  # the residual sum of squares
    return math.atan(math.sqrt(a * a + b * b)), math.sqrt(max(residual, 0.0) / m)


@njit(cache=True, nogil=True, inline="always")
def roughness(heights: np.ndarray, r0: int, c0: int, res: float, reach: int) -> float:
    """The standard deviation of the heights within ``reach`` cells (a disc) of cell (r0, c0)
    about their least-squares plane [m] (as the planner's height layer reads its roughness:
    :func:`plane_fit`); 0 where the plane is not determined."""
    n_rows, n_cols = heights.shape
    m = sx = sy = sz = sxx = syy = sxy = sxz = syz = szz = 0.0
    for dr in range(-reach, reach + 1):
        for dc in range(-reach, reach + 1):
            r, c = r0 + dr, c0 + dc
            if dr * dr + dc * dc > reach * reach or not (0 <= r < n_rows and 0 <= c < n_cols):
                continue
            x, y, z = dc * res, dr * res, np.float64(heights[r, c])
            m, sx, sy, sz = m + 1.0, sx + x, sy + y, sz + z
            sxx, syy, sxy, sxz, syz, szz = sxx + x * x, syy + y * y, sxy + x * y, sxz + x * z, syz + y * z, szz + z * z
    rough = plane_fit((m, sx, sy, sz, sxx, syy, sxy, sxz, syz, szz))[1]
    return 0.0 if math.isnan(rough) else rough


@njit(cache=True, nogil=True)
def roughness_at(heights: np.ndarray, res: float, xy: np.ndarray, reach: int) -> np.ndarray:
    """:func:`roughness` of the cell under each point ``xy`` (N, 2) [m]; 0 off the map."""
    n_rows, n_cols = heights.shape
    out = np.zeros(xy.shape[0])
    for i in range(xy.shape[0]):
        r0, c0 = int(math.floor(xy[i, 1] / res)), int(math.floor(xy[i, 0] / res))
        if 0 <= r0 < n_rows and 0 <= c0 < n_cols:
            out[i] = roughness(heights, r0, c0, res, reach)
    return out
