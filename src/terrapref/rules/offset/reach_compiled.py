"""The offset rule's per-frame loops, compiled (Numba) for the planner's control loop.

Each follows the NumPy form its docstring gives, element by element, without fast-math.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from terrapref.groundmap.map_compiled import UNSETTLED, MapLayers, map_decide, path_frame


@njit(cache=True, nogil=True)
def swept_reach(
    x0: float,
    y0: float,
    yaw0: float,
    offsets: np.ndarray,
    progress_m: float,
    v: float,
    dt: float,
    steps: int,
    pursuit_m: float,
    path_s: np.ndarray,
    path_a: np.ndarray,
    path_d: np.ndarray,
    path_len: np.ndarray,
    clear: np.ndarray,
    layers: MapLayers,
    lethal: np.ndarray,
    never: int,
) -> np.ndarray:
    """Per offset (O,): the step at which pure pursuit toward the path shifted by it, driven for
    ``steps`` steps of ``dt`` from the pose, first brings a point across the footprint (``clear``,
    every other step) onto a lethal column of the map (``lethal`` by column, ``never`` for cells
    outside the map); ``steps`` where it never does. The map's cells (``layers``) are read as
    :func:`terrapref.groundmap.map_compiled.map_decide` says.

    The NumPy form: pure pursuit as :func:`terrapref.rules.offset.steering.steer` gives it (clipped
    to +-1 rad/s, but with the C library's ``hypot``, as ``np.hypot``, where steer has Python's)
    toward every offset at progress ``progress_m + step * dt * v``, then ``yaw += w dt``, ``x += v
    cos(yaw) dt``, ``y += v sin(yaw) dt``.
    """
    out = np.full(offsets.shape[0], steps, np.int64)
    for o in range(offsets.shape[0]):
        x, y, yaw = x0, y0, yaw0
        for k in range(steps):
            target_s = min(progress_m + k * dt * v + pursuit_m, path_s[-1])
            px0, py0, cos_h, sin_h = path_frame(path_s, path_a, path_d, path_len, target_s)
            tx = px0 - offsets[o] * sin_h - x
            ty = py0 + offsets[o] * cos_h - y
            alpha = (math.atan2(ty, tx) - yaw + math.pi) % (2 * math.pi) - math.pi
            w = 2.0 * v * math.sin(alpha) / max(math.hypot(tx, ty), 1e-6)
            w = min(max(w, -1.0), 1.0)
            yaw = yaw + w * dt
            x = x + v * math.cos(yaw) * dt
            y = y + v * math.sin(yaw) * dt
            if k % 2 == 0 and _lethal_across(x, y, yaw, clear, layers, lethal, never):
                out[o] = k
            if out[o] < steps:
                break
    return out


@njit(cache=True, nogil=True, inline="always")
def _lethal_across(x: float, y: float, yaw: float, clear: np.ndarray, layers: MapLayers, lethal: np.ndarray, never: int) -> bool:
    """Whether a point across the footprint (``clear``, left positive) at the pose stands on a
    lethal column of the map (``never`` outside it), its undecided cells decided as read."""
    cells, evidence, map_lethal, shares, ox, oy, inv_res = layers
    n_rows, n_cols = cells.shape
    for c in range(clear.shape[0]):
        px = x - clear[c] * math.sin(yaw)
        py = y + clear[c] * math.cos(yaw)
        ci = math.floor((px - ox) * inv_res)
        cj = math.floor((py - oy) * inv_res)
        col = never
        if 0 <= ci < n_cols and 0 <= cj < n_rows:
            col = cells[cj, ci]
            if col == UNSETTLED:
                col = cells[cj, ci] = map_decide(evidence, map_lethal, shares[0], shares[1], shares[2], cj, ci)
        if lethal[col]:
            return True
    return False


@njit(cache=True, nogil=True)
def lethal_hits(
    layers: MapLayers,
    path_s: np.ndarray,
    path_a: np.ndarray,
    path_d: np.ndarray,
    path_len: np.ndarray,
    progress_m: float,
    stations: np.ndarray,
    offsets: np.ndarray,
    across: np.ndarray,
    lethal: np.ndarray,
    never: int,
) -> np.ndarray:
    """(O, S): whether any point ``offsets[o] + across[a]`` [m] left of the path, at station
    ``stations[s]`` from ``progress_m`` (capped at the path's end), lies on a lethal column of
    the map (``lethal`` by column, ``never`` outside it).

    The NumPy form: ``lethal[map_read_beside(layers, ..., minimum(progress_m + stations, length),
    offsets[:, None] + across[None, :])].any(axis=2)``.
    """
    cells, evidence, map_lethal, shares, ox, oy, inv_res = layers
    n_rows, n_cols = cells.shape
    length = path_s[-1]
    out = np.zeros((offsets.shape[0], stations.shape[0]), np.bool_)
    for q in range(stations.shape[0]):
        cx, cy, ux, uy = path_frame(path_s, path_a, path_d, path_len, min(progress_m + stations[q], length))
        nx, ny = -uy, ux
        for o in range(offsets.shape[0]):
            for a in range(across.shape[0]):
                lat = offsets[o] + across[a]
                i = math.floor((cx + lat * nx - ox) * inv_res)
                j = math.floor((cy + lat * ny - oy) * inv_res)
                col = never
                if 0 <= i < n_cols and 0 <= j < n_rows:
                    col = cells[j, i]
                    if col == UNSETTLED:
                        col = cells[j, i] = map_decide(evidence, map_lethal, shares[0], shares[1], shares[2], j, i)
                if lethal[col]:
                    out[o, q] = True
                    break
    return out
