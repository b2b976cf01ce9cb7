"""The ground's height at a point, compiled (Numba): the renderer's rays and the vehicle's wheels
read the height field through it."""

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
