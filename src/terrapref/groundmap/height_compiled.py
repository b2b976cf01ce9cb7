"""The ground map's height layer, compiled (Numba) (terrapref.groundmap.height): depth returns
voting their heights into cells, and a cell's geometry read from the cells round it as grid_map's
traversability filters read it (a plane fitted within a radius: its slope and the returns'
deviation from it; the height range within the radius: the step)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def height_vote(
    elevation: np.ndarray,
    returns: np.ndarray,
    spread: np.ndarray,
    ox: float,
    oy: float,
    inv_res: float,
    points: np.ndarray,
    mark: np.ndarray,
) -> np.ndarray:
    """Fold the returns ``points`` (N, 3) world [m] (NaN rows: no return) into each cell's mean
    height (``elevation`` (n, n) float32, NaN where none fell yet), count (``returns``) and sum
    of squared deviations from the mean (``spread``, Welford's update); the cells they fell in
    (flat indices, each once, in the order first fallen in). ``mark`` (n * n,) uint8, all 0:
    scratch, left all 0."""
    n = elevation.shape[0]
    touched = np.empty(points.shape[0], np.int64)
    count = 0
    for i in range(points.shape[0]):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
            continue
        u, v = (x - ox) * inv_res, (y - oy) * inv_res
        if not (0.0 <= u < n and 0.0 <= v < n):
            continue
        col, row = int(u), int(v)
        k = returns[row, col] + 1
        if mark[row * n + col] == 0:
            mark[row * n + col] = 1
            touched[count] = row * n + col
            count += 1
        returns[row, col] = k
        old = np.float64(elevation[row, col]) if k > 1 else z
        mean = old + (z - old) / k
        elevation[row, col] = mean
        spread[row, col] += (z - old) * (z - mean)
    for i in range(count):
        mark[touched[i]] = 0
    return touched[:count]


@njit(cache=True, nogil=True)
def cell_geometry(
    heights: tuple[np.ndarray, np.ndarray, np.ndarray],
    trust: tuple[int, float],
    rows: np.ndarray,
    cols: np.ndarray,
    reach: int,
    res: float,
    out: np.ndarray,
) -> None:
    """Slope [rad], roughness [m] and step [m] of the cells (``rows``, ``cols``) into ``out`` (N, 3),
    from the cells with a trusted elevation within ``reach`` cells (a disc) of each. ``heights``:
    the elevation, returns and spread layers; ``trust`` (least returns, largest variance of the
    mean [m^2]): a cell's elevation counts when at least that many returns fell in it and its
    mean's variance (spread / (n (n - 1))) is at most that. The least-squares
    plane z = a x + b y + c through them gives the slope, atan(sqrt(a^2 + b^2)), and the roughness,
    the standard deviation of their heights about it. The step is the height range over the cell
    and its eight neighbours (a slope adds little to it there: 0.13 m over a 25 deg slope of
    0.1 m cells). A cell no return fell in still has a geometry from the cells round it (the
    ground between the returns of far, sparsely sampled ground); slope and roughness are NaN
    where fewer than three cells of the disc are known, the step where fewer than two of the
    nine are."""
    n = heights[0].shape[0]
    for i in range(rows.shape[0]):
        r0, c0 = rows[i], cols[i]
        out[i, 0] = out[i, 1] = out[i, 2] = np.nan
        if not (0 <= r0 < n and 0 <= c0 < n):
            continue
        sums, near, step = _disc(heights, trust, r0, c0, reach, res)
        if sums[0] >= 3.0:
            out[i, 0], out[i, 1] = _plane(sums)
        if near >= 2:
            out[i, 2] = step


@njit(cache=True, nogil=True, inline="always")
def _disc(
    heights: tuple[np.ndarray, np.ndarray, np.ndarray], trust: tuple[int, float], r0: int, c0: int, reach: int, res: float
) -> tuple[tuple[float, ...], int, float]:
    """The normal equations' sums (m, x, y, z, xx, yy, xy, xz, yz, zz; x, y the offsets from cell
    (r0, c0) [m]) over the trusted cells within ``reach`` of it, how many of its nine (the cell
    and its neighbours) are trusted, and their height range."""
    elevation, returns, spread = heights
    least, largest = trust
    n = elevation.shape[0]
    m = sx = sy = sz = sxx = syy = sxy = sxz = syz = szz = 0.0
    near, low, high = 0, np.inf, -np.inf
    for dr in range(-reach, reach + 1):
        for dc in range(-reach, reach + 1):
            r, c = r0 + dr, c0 + dc
            if dr * dr + dc * dc > reach * reach or not (0 <= r < n and 0 <= c < n):
                continue
            k = returns[r, c]
            if k < least or k < 2 or spread[r, c] > largest * k * (k - 1):
                continue
            z, x, y = np.float64(elevation[r, c]), dc * res, dr * res
            m, sx, sy, sz = m + 1.0, sx + x, sy + y, sz + z
            sxx, syy, sxy, sxz, syz, szz = sxx + x * x, syy + y * y, sxy + x * y, sxz + x * z, syz + y * z, szz + z * z
            if abs(dr) <= 1 and abs(dc) <= 1:
                near, low, high = near + 1, min(low, z), max(high, z)
    return (m, sx, sy, sz, sxx, syy, sxy, sxz, syz, szz), near, high - low


@njit(cache=True, nogil=True, inline="always")
def _plane(sums: tuple[float, ...]) -> tuple[float, float]:
    """Slope [rad] and roughness [m] of the least-squares plane through the points of ``sums``
    (:func:`_disc`); NaN where the points are on a line (the plane is not determined)."""
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
