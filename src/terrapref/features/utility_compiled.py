"""The utility features U of one frame, compiled (Numba) for the planner's control loop: each
trajectory's terrain shares and its distance utility (terrapref.features.utility).

On one frame they are a few hundred pixels and a few dozen distances: NumPy's call overhead, not
its arithmetic, set their cost. Each loop does, element by element, exactly the IEEE 754 operations of the NumPy form its
docstring gives, in the same order (compiled without fast-math: nothing is reassociated or
fused into a multiply-add), so the results, and every decision made from them, are the same
bits as the NumPy forms give.
(tests/features/test_features.py compares.)
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def terrain_shares(ids: np.ndarray, column: np.ndarray, row: np.ndarray, m: int, k: int, scale: float) -> np.ndarray:
    """Terrain utilities (m, k) float64: per trajectory, ``scale`` times the count of its points
    on each terrain column.

    The NumPy form: ``bincount(column[ids] + row * (k + 1)).reshape(m + 1, k + 1)[:-1, :k] * scale``.

    Args:
        ids: (m * n,) class id of every point's pixel.
        column: (256,) terrain column of each class id (k: none).
        row: (m * n,) the trajectory of every point; m for a point outside the image.
    """
    counts = np.zeros((m + 1, k + 1), dtype=np.int64)
    for i in range(ids.shape[0]):
        counts[row[i], column[ids[i]]] += 1
    out = np.empty((m, k))
    for i in range(m):
        for j in range(k):
            out[i, j] = counts[i, j] * scale
    return out


@njit(cache=True, nogil=True)
def end_distances(ex: np.ndarray, ey: np.ndarray, c: float, s: float, dx: float, dy: float) -> np.ndarray:
    """Distances (m,) of endpoints (ex, ey) rotated by (c, s) and shifted by (dx, dy) from the origin.

    The NumPy form: ``np.hypot(ex * c - ey * s + dx, ex * s + ey * c + dy)``.
    """
    out = np.empty(ex.shape[0])
    for i in range(ex.shape[0]):
        out[i] = math.hypot(ex[i] * c - ey[i] * s + dx, ex[i] * s + ey[i] * c + dy)
    return out


@njit(cache=True, nogil=True)
def normalise(d: np.ndarray, eps: float) -> np.ndarray:
    """``1 - (d - d_min) / (d_max - d_min)``, all ones when the range is below ``eps``; any shape.

    The NumPy form: ``(d.max() - d) * (1.0 / (d.max() - d.min()))``.
    """
    flat = d.ravel()
    lo, hi = flat.min(), flat.max()
    if hi - lo < eps:
        return np.ones_like(d)
    inv = 1.0 / (hi - lo)
    out = np.empty_like(flat)
    for i in range(flat.shape[0]):
        out[i] = (hi - flat[i]) * inv
    return out.reshape(d.shape)


@njit(cache=True, nogil=True)
def utilities(
    ids: np.ndarray,
    column: np.ndarray,
    row: np.ndarray,
    k: int,
    scale: float,
    ex: np.ndarray,
    ey: np.ndarray,
    c: float,
    s: float,
    dx: float,
    dy: float,
    eps: float,
) -> np.ndarray:
    """U (m, k + 1) float32 of one frame with the look-ahead distance: :func:`terrain_shares`,
    then :func:`normalise` of :func:`end_distances`, each converted to float32 as NumPy assigns
    float64 into a float32 array (one call where the features made five)."""
    m = ex.shape[0]
    out = np.empty((m, k + 1), np.float32)
    shares = terrain_shares(ids, column, row, m, k, scale)
    u = normalise(end_distances(ex, ey, c, s, dx, dy), eps)
    for i in range(m):
        for j in range(k):
            out[i, j] = np.float32(shares[i, j])
        out[i, k] = np.float32(u[i])
    return out
