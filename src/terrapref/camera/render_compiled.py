"""The renderer's two inner loops, compiled (Numba): a whole frame, and any set of its pixels.

The arithmetic is the row-affine formula of :mod:`terrapref.camera.render`, written out per
pixel with exactly the IEEE 754 operations, types and order of its vectorised NumPy form: the
cell of column offset 0 and the change per column in float64 and then rounded to float32, the
pixel's cell ``B * u + A`` in float32, clipped into the padded raster and truncated. Numba
compiles without fast-math, so nothing is reassociated or fused into a multiply-add, and the
class ids are the same, pixel for pixel, as the NumPy form gives (tests/camera/test_camera.py keeps that
form and compares). One pass per frame instead of a dozen, and no index arrays: the frame is
written once, and the raster read once per pixel.

Compiled on first use and cached beside this file, so later processes load it in milliseconds.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def render_frame(
    P: np.ndarray,
    Q: np.ndarray,
    u: np.ndarray,
    first: np.ndarray,
    last: np.ndarray,
    x: float,
    y: float,
    c: float,
    s: float,
    res: float,
    raster: np.ndarray,
    nx: int,
    x_max: np.float32,
    y_max: np.float32,
    unknown: int,
    out: np.ndarray,
) -> None:
    """Fill ``out`` (H, W) uint8, a whole frame, of which the last n rows see the ground.

    Args:
        P, Q: (n, 2) float64, each visible row's ground point at column offset 0 and its change
            per column in the vehicle frame [m].
        u: (W,) float32 column offsets from the principal point.
        first, last: (n,) int64, the columns that see the ground within range,
            ``first[r]:last[r]``; the others are ``unknown``, as are the rows above the n.
        x, y, c, s: the pose's position [m] and the cosine and sine of its yaw.
        res: the raster's cell size [m].
        raster: the padded class raster, flat (ny * nx,) uint8, fewer than 2 ** 31 cells.
        nx: its row length.
        x_max, y_max: the largest cell coordinates clipped to (just inside the border).
    """
    height, width = out.shape
    n = P.shape[0]
    zero = np.float32(0.0)
    nx32 = np.int32(nx)
    out[: height - n] = unknown
    # Unsigned cell indices and loops over slices from 0, so that no index can be negative:
    # the cells are then computed in a loop the compiler vectorises, and read without the
    # wrap-around test a signed index costs.
    cells = np.empty(width, np.uint32)
    for r in range(n):
        # The padded-raster cell of column offset 0 and the change per column (+1 for the border).
        a0 = np.float32((x + (P[r, 0] * c - P[r, 1] * s)) / res + 1.0)
        a1 = np.float32((y + (P[r, 0] * s + P[r, 1] * c)) / res + 1.0)
        b0 = np.float32((Q[r, 0] * c - Q[r, 1] * s) / res)
        b1 = np.float32((Q[r, 0] * s + Q[r, 1] * c) / res)
        lo, hi = first[r], last[r]
        row = out[height - n + r]
        row[:lo] = unknown
        row[hi:] = unknown
        run = u[lo:hi]
        for j in range(run.shape[0]):
            gx = min(max(b0 * run[j] + a0, zero), x_max)
            gy = min(max(b1 * run[j] + a1, zero), y_max)
            cells[j] = np.int32(gy) * nx32 + np.int32(gx)
        seen = row[lo:hi]
        for j in range(seen.shape[0]):
            seen[j] = raster[cells[j]]


@njit(cache=True, nogil=True, inline="always")
def row_col(k: int, width: int, per_row: float) -> tuple[int, int]:
    """(k // width, k % width) of a pixel index k >= 0, ``per_row`` = 1 / width: by a product
    instead of an integer division (exact while (k + 0.5) / width lies far from an integer in
    float64, as for any image under 2 ** 40 pixels; checked, with the division as the fallback).

    Inlined into its callers, here and in terrapref.perception.labels, whose cached copies Numba
    does not recompile when only this file changes: after editing it, delete the ``__pycache__``
    folders' ``*.nbi``/``*.nbc`` files (``python -m terrapref.warm_up`` rebuilds them)."""
    row = np.int64((k + 0.5) * per_row)
    col = k - row * width
    if col < 0 or col >= width:
        return k // width, k % width
    return row, col


@njit(cache=True, nogil=True)
def pixels_at(
    flat_index: np.ndarray,
    width: int,
    row0: int,
    valid: np.ndarray,
    P: np.ndarray,
    Q: np.ndarray,
    u: np.ndarray,
    x: float,
    y: float,
    c: float,
    s: float,
    res: float,
    raster: np.ndarray,
    nx: int,
    x_max: np.float32,
    y_max: np.float32,
    unknown: int,
) -> np.ndarray:
    """Class ids (len(flat_index),) uint8 of the pixels ``flat_index`` (row * width + col).

    ``valid`` (H * W,) says which pixels see the ground within range; ``P`` and ``Q`` (n, 2)
    float64 are the visible rows' ground point at column offset 0 and its change per column in
    the vehicle frame [m] (row ``row0`` first); ``(x, y)``, ``c``, ``s`` the pose's position and
    the cosine and sine of its yaw; ``res`` the raster's cell size [m]. A row's cell and change
    per column are computed once, when its first pixel is read.
    """
    none = np.empty(0, np.int64)
    return _pixels(flat_index, none, none, False, width, row0, valid, P, Q, u, x, y, c, s, res, raster, nx, x_max, y_max, unknown)


@njit(cache=True, nogil=True)
def rows_and_columns(flat_index: np.ndarray, width: int, row0: int, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each pixel's row less ``row0`` (-1 where ``valid`` (H * W,) says it sees no ground in
    range) and its column, for :func:`pixels_of_rows`; IndexError for a pixel outside the image."""
    rows = np.empty(flat_index.shape[0], np.int64)
    cols = np.empty(flat_index.shape[0], np.int64)
    per_row = 1.0 / width
    for i in range(flat_index.shape[0]):
        k = flat_index[i]
        if k < 0 or k >= valid.shape[0]:
            raise IndexError("a pixel index is outside the image")
        row, col = row_col(k, width, per_row)
        rows[i] = row - row0 if valid[k] else -1
        cols[i] = col
    return rows, cols


@njit(cache=True, nogil=True)
def pixels_of_rows(
    rows: np.ndarray,
    cols: np.ndarray,
    P: np.ndarray,
    Q: np.ndarray,
    u: np.ndarray,
    x: float,
    y: float,
    c: float,
    s: float,
    res: float,
    raster: np.ndarray,
    nx: int,
    x_max: np.float32,
    y_max: np.float32,
    unknown: int,
) -> np.ndarray:
    """:func:`pixels_at` of pixels given by their row among the visible rows (-1: ``unknown``)
    and column (:func:`rows_and_columns`): the same float32 operations, the same class ids."""
    none = np.empty(0, np.int64)
    return _pixels(none, rows, cols, True, 1, 0, np.empty(0, np.bool_), P, Q, u, x, y, c, s, res, raster, nx, x_max, y_max, unknown)


@njit(cache=True, nogil=True)
def _pixels(
    flat_index: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
    prepared: bool,
    width: int,
    row0: int,
    valid: np.ndarray,
    P: np.ndarray,
    Q: np.ndarray,
    u: np.ndarray,
    x: float,
    y: float,
    c: float,
    s: float,
    res: float,
    raster: np.ndarray,
    nx: int,
    x_max: np.float32,
    y_max: np.float32,
    unknown: int,
) -> np.ndarray:
    """:func:`pixels_at` (``prepared`` False: from ``flat_index``) and :func:`pixels_of_rows`
    (True: from ``rows`` and ``cols``) in one loop, so that both keep one pass over the pixels."""
    n = rows.shape[0] if prepared else flat_index.shape[0]
    out = np.empty(n, np.uint8)
    zero = np.float32(0.0)
    cells = np.empty((P.shape[0], 4), np.float32)
    done = np.zeros(P.shape[0], np.bool_)
    n_pixels = valid.shape[0]
    per_row = 1.0 / width
    for i in range(n):
        if prepared:
            visible, col = rows[i], cols[i]
            if visible < 0:
                out[i] = unknown
                continue
        else:
            k = flat_index[i]
            if k < 0 or k >= n_pixels:
                raise IndexError("a pixel index is outside the image")
            if not valid[np.uint64(k)]:
                out[i] = unknown
                continue
            row, col = row_col(k, width, per_row)
            visible = row - row0
        r = np.uint64(visible)  # unsigned indices: no wrap-around test on each read
        if not done[r]:
            # The cell of the row's column offset 0 and its change per column, as render_frame's.
            cells[r, 0] = np.float32((x + (P[r, 0] * c - P[r, 1] * s)) / res + 1.0)
            cells[r, 1] = np.float32((y + (P[r, 0] * s + P[r, 1] * c)) / res + 1.0)
            cells[r, 2] = np.float32((Q[r, 0] * c - Q[r, 1] * s) / res)
            cells[r, 3] = np.float32((Q[r, 0] * s + Q[r, 1] * c) / res)
            done[r] = True
        uj = u[np.uint64(col)]
        gx = min(max(cells[r, 2] * uj + cells[r, 0], zero), x_max)
        gy = min(max(cells[r, 3] * uj + cells[r, 1], zero), y_max)
        out[i] = raster[np.uint64(gy) * np.uint64(nx) + np.uint64(gx)]
    return out


@njit(cache=True, nogil=True)
def take(image: np.ndarray, flat_index: np.ndarray) -> np.ndarray:
    """``image.reshape(-1)[flat_index]`` of a C-contiguous (H, W) uint8 image, any index shape flattened."""
    flat = image.reshape(-1)
    index = flat_index.reshape(-1)
    out = np.empty(index.shape[0], np.uint8)
    for i in range(index.shape[0]):
        k = index[i]
        if k < 0 or k >= flat.shape[0]:
            raise IndexError("a pixel index is outside the image")
        out[i] = flat[k]
    return out


@njit(cache=True, nogil=True)
def ray_pixels(
    flat_index: np.ndarray,
    width: int,
    ray_a: np.ndarray,
    ray_b: np.ndarray,
    axes: np.ndarray,
    t: np.ndarray,
    max_range_m: float,
    x: float,
    y: float,
    c: float,
    s: float,
    res: float,
    raster: np.ndarray,
    nx: int,
    x_max: np.float32,
    y_max: np.float32,
    unknown: int,
) -> np.ndarray:
    """Class ids (len(flat_index),) uint8 of the pixels ``flat_index`` of a camera at any attitude.

    Each pixel's ray through its centre, ``axes`` (3, 3) rows (right, down, forward in the
    vehicle frame) weighted by the pixel's offsets (``ray_a[col] = (col + 0.5 - cx) / fx``,
    ``ray_b[row] = (row + 0.5 - cy) / fy``, worked out once per camera), meets the ground z = 0 from the optical
    centre ``t`` (3,); ``unknown`` where it does not, or farther than ``max_range_m``. The point
    goes to the world at the pose ((x, y), cosine ``c`` and sine ``s`` of the yaw) and to a cell
    of the padded raster as the row-affine renderer clips it. Used for a camera whose attitude
    is off its mount (roll breaks the row-affine form); float64 throughout.
    """
    out = np.empty(flat_index.shape[0], np.uint8)
    per_row = 1.0 / width
    # The axes and the centre in locals: read once, not again after every store to ``out``.
    a0, a1, a2 = axes[0, 0], axes[0, 1], axes[0, 2]
    b0, b1, b2 = axes[1, 0], axes[1, 1], axes[1, 2]
    f0, f1, f2 = axes[2, 0], axes[2, 1], axes[2, 2]
    t0, t1, t2 = t[0], t[1], t[2]
    for i in range(flat_index.shape[0]):
        k = flat_index[i]
        row, col = row_col(k, width, per_row)
        a = ray_a[col]
        b = ray_b[row]
        dx = a * a0 + b * b0 + f0
        dy = a * a1 + b * b1 + f1
        dz = a * a2 + b * b2 + f2
        if dz >= -1e-12:
            out[i] = unknown
            continue
        scale = -t2 / dz
        if scale * math.sqrt(dx * dx + dy * dy + dz * dz) > max_range_m:
            out[i] = unknown
            continue
        gx, gy = t0 + scale * dx, t1 + scale * dy
        wx = min(max((x + gx * c - gy * s) / res + 1.0, 0.0), np.float64(x_max))
        wy = min(max((y + gx * s + gy * c) / res + 1.0, 0.0), np.float64(y_max))
        out[i] = raster[np.int64(wy) * nx + np.int64(wx)]
    return out
