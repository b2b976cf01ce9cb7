"""The relief renderer's inner loop, compiled (Numba): a frame's classes and depth over a height
field, one image column at a time.

An image column back-projects to a plane through the optical centre. The loop walks that plane's
trace on the ground away from the camera, sampling the height field; each sample projects to a
(continuous) row of the column. Rows fill from the bottom of the image up: the rows whose
centres lie between two samples' rows see the ground between them, where the pixel's ray meets
the segment joining the two ground points (the ground is taken as linear between samples, so
on a plane every pixel is exact). A sample projecting below the rows already filled is hidden
(behind a crest), and fills nothing. Steps are two grid cells near the camera and about a pixel
row's ground farther out.

Float64 throughout. Compiled on first use and cached beside this file.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from terrapref.world.height_compiled import height_at


@njit(cache=True, nogil=True)
def render_relief(
    axes: np.ndarray,
    centre: np.ndarray,
    ray_a: np.ndarray,
    ray_b: np.ndarray,
    max_range_m: float,
    fy: float,
    heights: np.ndarray,
    res: float,
    raster: np.ndarray,
    nx: int,
    x_max: float,
    y_max: float,
    unknown: int,
    ids: np.ndarray,
    depth: np.ndarray,
) -> None:
    """Fill ``ids`` (H, W) uint8 and ``depth`` (H, W) float32 of a camera over a height field.

    Args:
        axes: (3, 3) the camera's axes in the world frame (rows: right, down, forward).
        centre: (3,) the optical centre in the world frame [m].
        ray_a, ray_b: (W,) and (H,) each column's and row's ray offset through the pixel
            centres, ``(col + 0.5 - cx) / fx`` and ``(row + 0.5 - cy) / fy``.
        max_range_m: pixels whose ray meets the ground farther from the centre see nothing.
        fy: the vertical focal length [px] (sets the step far from the camera).
        heights: (ny, nx) float32 ground heights at the cell centres [m].
        res: the grid's cell size [m].
        raster: the padded class raster, flat (uint8), ``nx`` cells a row.
        x_max, y_max: the largest cell coordinates clipped to (just inside the padded border).
        unknown: the class id of a pixel that sees no ground.
        ids, depth: filled: class ids, and metres along the optical axis (NaN: no ground).
    """
    height, width = ids.shape
    ids[:, :] = unknown
    depth[:, :] = np.nan
    per_m = 1.0 / res
    below = height_at(heights, per_m, centre[0], centre[1]) - centre[2]  # the ground under the camera, from it [m]
    clearance = max(-below, 0.2)
    # Every column's state: its trace's direction, the lowest row not yet filled, its last sample
    # (first, the ground under the camera) in camera coordinates, down and forward.
    hx, hy, row = _traces(axes, ray_a, height)
    columns = np.stack((hx, hy, np.full(width, below * axes[1, 2]), np.full(width, below * axes[2, 2])))
    cells = (raster, nx, x_max, y_max)
    _march(columns, row, axes, centre, ray_a, ray_b, max_range_m, clearance, fy, heights, per_m, cells, ids, depth)


@njit(cache=True, nogil=True)
def _march(
    columns: np.ndarray,
    row: np.ndarray,
    axes: np.ndarray,
    centre: np.ndarray,
    ray_a: np.ndarray,
    ray_b: np.ndarray,
    max_range_m: float,
    clearance: float,
    fy: float,
    heights: np.ndarray,
    per_m: float,
    cells: tuple[np.ndarray, int, float, float],
    ids: np.ndarray,
    depth: np.ndarray,
) -> None:
    """Step every column's trace out together (so that neighbouring columns read neighbouring
    cells), filling each column's rows from ``row`` up. ``columns`` (4, W): each column's trace's
    direction (x, y) and its last sample's camera coordinates (down, forward); ``cells``: the
    padded raster, its row length and the largest cell coordinates. Steps: two cells, or
    farther out about a pixel row's ground, (r^2 + c^2) / (c fy) at r for a camera
    ``clearance`` c over the ground."""
    d0, d1, d2 = axes[1, 0], axes[1, 1], axes[1, 2]
    f0, f1, f2 = axes[2, 0], axes[2, 1], axes[2, 2]
    cx, cy, cz = centre[0], centre[1], centre[2]
    hx, hy, vd, vf = columns[0], columns[1], columns[2], columns[3]
    range2, step_m, per_row = max_range_m * max_range_m, 2.0 / per_m, 1.0 / (clearance * fy)
    open_columns = np.sum(row >= 0)
    r = 0.0
    while open_columns > 0 and r <= max_range_m:  # no ground farther horizontally is in range
        r += max(step_m, (r * r + clearance * clearance) * per_row)
        for col in range(row.shape[0]):
            if row[col] < 0:
                continue
            px, py = cx + r * hx[col], cy + r * hy[col]
            wx, wy, wz = px - cx, py - cy, height_at(heights, per_m, px, py) - cz
            wd = wx * d0 + wy * d1 + wz * d2
            wf = wx * f0 + wy * f1 + wz * f2
            if wf > 1e-9:
                segment = (vd[col], vf[col], wd, wf)
                k = _fill(col, row[col], ray_b, ray_a[col], axes, centre, segment, range2, per_m, cells, ids, depth)
                row[col] = k
                open_columns -= k < 0
            vd[col], vf[col] = wd, wf


@njit(cache=True, nogil=True)
def _traces(axes: np.ndarray, ray_a: np.ndarray, height: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each column's plane's trace on the ground: the horizontal direction in it away from the
    camera, (W,) x and y; and the lowest row to fill, (W,): ``height - 1``, or -1 for a column
    whose plane is level (it sees no ground)."""
    width = ray_a.shape[0]
    hx, hy, row = np.zeros(width), np.zeros(width), np.full(width, height - 1, np.int64)
    for col in range(width):
        a = ray_a[col]
        # The plane holds the column's centre ray (a, 0, 1) and the camera's down axis.
        px, py, pz = a * axes[0, 0] + axes[2, 0], a * axes[0, 1] + axes[2, 1], a * axes[0, 2] + axes[2, 2]
        nxv = py * axes[1, 2] - pz * axes[1, 1]
        nyv = pz * axes[1, 0] - px * axes[1, 2]
        nzv = px * axes[1, 1] - py * axes[1, 0]
        norm = math.sqrt(nxv * nxv + nyv * nyv)  # of the normal x up
        if norm < 1e-9 * math.sqrt(nxv * nxv + nyv * nyv + nzv * nzv):
            row[col] = -1
            continue
        x, y = nyv / norm, -nxv / norm
        sign = 1.0 if x * px + y * py >= 0.0 else -1.0
        hx[col], hy[col] = sign * x, sign * y
    return hx, hy, row


@njit(cache=True, nogil=True, inline="always")
def _fill(
    col: int,
    row: int,
    ray_b: np.ndarray,
    a: float,
    axes: np.ndarray,
    centre: np.ndarray,
    segment: tuple[float, float, float, float],
    range2: float,
    per_m: float,
    cells: tuple[np.ndarray, int, float, float],
    ids: np.ndarray,
    depth: np.ndarray,
) -> int:
    """Fill column ``col`` (ray offset ``a``) from ``row`` up with the rows whose rays meet the
    ground between the last sample (camera coordinates down ``vd`` and forward ``vf``) and this
    one (``wd``, ``wf``), ``segment = (vd, vf, wd, wf)``: the rows whose centres lie at or below
    this sample's. A row's ray (offsets a and b: forward s, down b s) meets the segment's line at
    depth s; its ground point is the centre plus s times the ray's direction in the world. The
    lowest row left unfilled."""
    vd, vf, wd, wf = segment
    raster, nx, x_max, y_max = cells
    ax, ay = a * axes[0, 0] + axes[2, 0], a * axes[0, 1] + axes[2, 1]  # the ray's direction at b = 0, across the ground
    d0, d1, cx, cy, scale = axes[1, 0], axes[1, 1], centre[0], centre[1], 1.0 + a * a
    top = wd / wf  # this sample's ray offset: rows with ray_b >= top see it or nearer
    dd, df = wd - vd, wf - vf
    cross = vf * dd - vd * df
    while row >= 0 and ray_b[row] >= top:
        b = ray_b[row]
        den = dd - b * df
        along = cross / den if den != 0.0 else wf  # depth along the optical axis [m]
        if along > 0.0 and along * along * (scale + b * b) <= range2:
            ux = min(max((cx + along * (ax + b * d0)) * per_m + 1.0, 0.0), x_max)
            uy = min(max((cy + along * (ay + b * d1)) * per_m + 1.0, 0.0), y_max)
            ids[row, col] = raster[np.int64(uy) * nx + np.int64(ux)]
            depth[row, col] = along
        row -= 1
    return row
