"""The relief renderer's inner loops, compiled (Numba): a frame's classes and depth over a height
field, in two passes.

**March**, every image column together, one sample each at a time. An image column
back-projects to a plane through the optical centre, tilted when the camera is pitched or
rolled. Each column walks the ground's trace in its plane away from the camera, a sample at each
horizontal distance ``u`` along the plane's level direction: the plane's point at a drop
``delta`` below the optical centre lies ``delta * m`` to the side of that line (``m``: the
plane's level offset per metre of drop), so the drop at which the plane meets the ground is
found by one Newton step on the bilinear height field from the drop the last two samples
predict. Each sample projects to a (continuous) row of its column, and rows fill from the bottom
of the image up: the rows whose centres lie between two samples' rows see the ground between
them, where the pixel's ray meets the segment joining the two ground points (the ground is taken
as straight between samples, so on a plane every pixel is exact). A sample projecting below the
rows already filled is hidden (behind a crest) and fills nothing. Along a segment the inverse of
the depth is affine in the row's ray offset, so the march keeps the segments alone (each one's
column, the rows it fills, the inverse depth at its lowest row and its change per row) and writes
no pixel: a frame is row-major, and writing it a column at a time touches a cache line a pixel.

The step after a sample is the longer of two: the ground of about one pixel row of a flat
ground's image there, ``(u^2 + c^2) / (c fy)`` for a camera ``c`` over the ground (a crest
between samples then moves a silhouette by less than a row); and the longest over which the
ground, taken as straight, stays within a tolerance of the height field around the sample
(:func:`step_lengths`, from the field's curvature, at least two cells: a wall or a ledge is
walked two cells a step, smooth ground in longer strides).

**Shade**, one image row at a time: each pixel's inverse depth from its column's segment over
that row (the march chains the segments that begin on each row, so that each row takes up
those that begin there, with no sort), then its depth, the range check and the class of its
ground point, in loops the compiler vectorises, as the flat renderer's. The same depths, bit for
bit, as writing each pixel in the march gave.

The march's loops over the columns are split so that the compiler vectorises the arithmetic
(the height field's four corners are read in a loop of their own). Float64 in the march; the
shading in float32 (depths are float32, and a class cell is found to within 1e-4 of a cell).
Compiled on first use and cached beside this file.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from terrapref.world.height_compiled import height_at

# A sample is in front of the camera when it lies more than this [m] ahead of the plane of its
# optical centre (the plane of the image, moved to the centre).
IN_FRONT_M = 1e-9

# A Newton step that moves a column's drop by more than this [m] is checked and, if need be,
# settled by a bracketing search (:func:`settle_drops`).
SETTLE_M = 0.01


@njit(cache=True, nogil=True)
def step_lengths(heights: np.ndarray, res: float, shift: int, tolerance_m: float, near_m: float) -> np.ndarray:
    """The longest step of the march [m] from a point in each block of ``2**shift`` x
    ``2**shift`` cells of the height field ``heights`` (ny, nx) [m] (cells of ``res`` [m]):
    shape (ceil(ny / 2**shift), ceil(nx / 2**shift)) float64.

    Ground taken as straight over a step of ``L`` strays from the height field by at most
    ``K L^2 / 8``, where ``K`` bounds the field's second derivative along the step; ``K`` is
    taken from the cells' second differences (across, along, and the twist) over the block and
    the blocks around it (a step is at most a block long, so it stays among them). The step is
    the ``L`` that keeps this within ``tolerance_m``, at least ``near_m`` and at most a block.
    """
    ny, nx = heights.shape
    block = 1 << shift
    by, bx = (ny + block - 1) >> shift, (nx + block - 1) >> shift
    bend = np.zeros((by, bx))
    for r in range(ny):
        rm, rp = max(r - 1, 0), min(r + 1, ny - 1)
        for c in range(nx):
            cm, cp = max(c - 1, 0), min(c + 1, nx - 1)
            h = np.float64(heights[r, c])
            across = abs(np.float64(heights[r, cp]) - 2.0 * h + np.float64(heights[r, cm]))
            along = abs(np.float64(heights[rp, c]) - 2.0 * h + np.float64(heights[rm, c]))
            twist = abs(np.float64(heights[rp, cp]) - np.float64(heights[rp, c]) - np.float64(heights[r, cp]) + h)
            bend[r >> shift, c >> shift] = max(bend[r >> shift, c >> shift], across + along + twist)
    out = np.empty((by, bx))
    longest = block * res
    for i in range(by):
        for j in range(bx):
            k = 0.0  # [m per cell^2]
            for ii in range(max(i - 1, 0), min(i + 2, by)):
                for jj in range(max(j - 1, 0), min(j + 2, bx)):
                    k = max(k, bend[ii, jj])
            step = res * math.sqrt(8.0 * tolerance_m / k) if k > 0.0 else longest
            out[i, j] = min(max(step, near_m), longest)
    return out


@njit(cache=True, nogil=True)
def render_relief(
    axes: np.ndarray,
    centre: np.ndarray,
    ray_a: np.ndarray,
    ray_b: np.ndarray,
    max_range_m: float,
    fy: float,
    cy: float,
    heights: np.ndarray,
    res: float,
    steps: np.ndarray,
    shift: int,
    span: tuple[float, float],
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
        fy, cy: the vertical focal length and principal point [px].
        heights: (ny, nx) float32 ground heights at the cell centres [m], at least 2 x 2.
        res: the grid's cell size [m].
        steps, shift: the longest step from each block of ``2**shift`` cells
            (:func:`step_lengths`).
        span: the height field's lowest and highest heights [m].
        raster: the padded class raster, flat (uint8), ``nx`` cells a row.
        x_max, y_max: the largest cell coordinates clipped to (just inside the padded border).
        unknown: the class id of a pixel that sees no ground.
        ids, depth: filled: class ids, and metres along the optical axis (NaN: no ground).
    """
    per_m = 1.0 / res
    below = height_at(heights, per_m, centre[0], centre[1]) - centre[2]  # the ground under the camera, from it [m]
    clearance = max(-below, 0.2)
    planes = _planes(axes, ray_a)
    ground = (heights, per_m, steps, shift, span)
    filled, segments, heads = _march(planes, -below, clearance, fy, cy, max_range_m, centre, ray_b, ground, depth.shape)
    _shade(filled, segments, heads, axes, centre, ray_a, ray_b, max_range_m, per_m, raster, nx, x_max, y_max, unknown, ids, depth)


@njit(cache=True, nogil=True)
def _planes(axes: np.ndarray, ray_a: np.ndarray) -> np.ndarray:
    """Each column's plane, (9, W): its level direction away from the camera (x, y); its level
    offset per metre of drop ``m`` (x, y); the down and forward camera coordinates of a metre
    along the level direction (``Dh``, ``Fh``) and of a metre of drop (``Dm``, ``Fm``); and 1
    where the plane meets the ground (0 for a level plane, which sees none). The plane's point
    at ``u`` along the level direction and a drop ``delta`` lies at ``(u Dh + delta Dm, u Fh +
    delta Fm)`` in the column's camera coordinates (down, forward)."""
    width = ray_a.shape[0]
    out = np.zeros((9, width))
    r0, r1, r2 = axes[0, 0], axes[0, 1], axes[0, 2]
    d0, d1, d2 = axes[1, 0], axes[1, 1], axes[1, 2]
    f0, f1, f2 = axes[2, 0], axes[2, 1], axes[2, 2]
    for col in range(width):
        a = ray_a[col]
        # The plane holds the column's centre ray p = (a, 0, 1) and the camera's down axis.
        px, py, pz = a * r0 + f0, a * r1 + f1, a * r2 + f2
        nxv = py * d2 - pz * d1
        nyv = pz * d0 - px * d2
        nzv = px * d1 - py * d0
        level2 = nxv * nxv + nyv * nyv
        if level2 < 1e-18 * (level2 + nzv * nzv):
            continue
        norm = math.sqrt(level2)
        hx, hy = nyv / norm, -nxv / norm
        if hx * px + hy * py < 0.0:
            hx, hy = -hx, -hy
        mx, my = nzv * nxv / level2, nzv * nyv / level2  # n . (m, -1) = 0: the plane's point a metre lower
        out[0, col], out[1, col], out[2, col], out[3, col] = hx, hy, mx, my
        out[4, col], out[5, col] = d0 * hx + d1 * hy, f0 * hx + f1 * hy
        out[6, col], out[7, col] = d0 * mx + d1 * my - d2, f0 * mx + f1 * my - f2
        out[8, col] = 1.0
    return out


@njit(cache=True, nogil=True)
def _march(
    planes: np.ndarray,
    drop: float,
    clearance: float,
    fy: float,
    cy: float,
    max_range_m: float,
    centre: np.ndarray,
    ray_b: np.ndarray,
    ground: tuple[np.ndarray, float, np.ndarray, int, tuple[float, float]],
    shape: tuple[int, int],
) -> tuple[np.ndarray, Segments, np.ndarray]:
    """Walk every column's plane (``planes``, :func:`_planes`) of a frame of ``shape`` (H, W) from
    the ground under the camera (``drop`` [m] below it) to the first sample past ``max_range_m``,
    filling its rows from the bottom up. ``ground``: the height field, its cells per metre, the
    step lengths and their block's shift (:func:`step_lengths`), its lowest and highest heights.
    Returns each column's lowest row left unfilled (W,), the :data:`Segments` filling the rest,
    and the first of those that begin on each row (H,), -1 for none. A sample at a time for every
    column, rather than a column at a time: a column's sample waits on its last (the drop it
    predicts), and neighbouring columns read neighbouring cells."""
    heights, per_m, steps, shift, span = ground
    height, width = shape
    hx, hy, mx, my, dh, fh, dm, fm = planes[0], planes[1], planes[2], planes[3], planes[4], planes[5], planes[6], planes[7]
    row = np.where(planes[8] != 0.0, height - 1, -1)
    live = planes[8] != 0.0
    n_live = np.sum(live)
    # Each column's state: its sample's distance [m], the step to it and that step over the one
    # before; the drops of its last two samples [m]; its last sample, down and forward.
    u, taken, ratio = np.zeros(width), np.zeros(width), np.zeros(width)
    last, before, new = np.full(width, drop), np.full(width, drop), np.empty(width)
    vd, vf, wd, wf = np.zeros(width), np.zeros(width), np.zeros(width), np.zeros(width)
    # The sample's cell, its place in it, the cell's corner heights and the longest next step.
    cell, block, fu, fv = np.empty(width, np.int64), np.empty(width, np.int64), np.empty(width), np.empty(width)
    corners = np.empty((4, width), np.float32)
    longest = np.empty(width)
    stop = np.empty(width, np.int64)  # the highest row a sample fills to
    moved = np.empty(width)  # how far the Newton step moved each column's drop, signed [m]
    ny, nx = heights.shape
    where = (centre[0] * per_m - 0.5, centre[1] * per_m - 0.5, per_m, nx - 1.0 - 1e-9, ny - 1.0 - 1e-9, nx, shift, steps.shape[1])
    per_row, clearance2, cap = 1.0 / (clearance * fy), clearance * clearance, 2.0 * max_range_m + 1.0
    segments, n_segments, heads = _no_segments(64 * width), 0, np.full(height, -1, np.int64)
    first = True
    while n_live > 0:
        _where(u, ratio, last, before, hx, hy, mx, my, where, new, fu, fv, cell, block)
        _read(cell, block, heights.reshape(-1), nx, steps.reshape(-1), corners, longest)
        if _newton(corners, fu, fv, mx, my, new, centre[2], per_m, moved):
            settle_drops(moved, new, u, planes, centre, heights, per_m, span)
        _project(new, u, dh, dm, fh, fm, wd, wf, stop, fy, cy)
        before, last, new = last, new, before
        if not first:
            segments = _with_room(segments, n_segments, width)
            stopped, n_segments = _fill(row, live, stop, (vd, vf, wd, wf), u, max_range_m, ray_b, segments, n_segments, heads)
            n_live -= stopped
        first = False
        vd, wd = wd, vd
        vf, wf = wf, vf
        _advance(u, taken, ratio, longest, per_row, clearance2, cap)
    return row, _taken(segments, n_segments), heads


Segments = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]
"""Segments of image columns that see the ground (:func:`_fill`): each one's column, the next
segment that begins on the same row as it (-1 for none; the first is in the march's ``heads``),
its last row, its inverse depth at its last row [1/m] and that inverse's fall per row up. A
column's segments begin on different rows, so a row's chain holds each column once at most."""


@njit(cache=True, nogil=True)
def _no_segments(room: int) -> Segments:
    """Room for ``room`` segments (:data:`Segments`)."""
    return np.empty(room, np.int64), np.empty(room, np.int64), np.empty(room, np.int64), np.empty(room), np.empty(room)


@njit(cache=True, nogil=True, inline="always")
def _taken(segments: Segments, held: int) -> Segments:
    """The first ``held`` of ``segments``."""
    cols, nexts, lasts, inverses, changes = segments
    return cols[:held], nexts[:held], lasts[:held], inverses[:held], changes[:held]


@njit(cache=True, nogil=True)
def _with_room(segments: Segments, held: int, width: int) -> Segments:
    """``segments`` (the first ``held`` of them taken) with room for a sample's, at most one for
    each of ``width`` columns: as they are where there is, else the ``held`` in twice the room."""
    if held + width <= segments[0].shape[0]:
        return segments
    grown = _no_segments(2 * segments[0].shape[0])
    grown[0][:held], grown[1][:held], grown[2][:held] = segments[0][:held], segments[1][:held], segments[2][:held]
    grown[3][:held], grown[4][:held] = segments[3][:held], segments[4][:held]
    return grown


@njit(cache=True, nogil=True)
def _fill(
    row: np.ndarray,
    live: np.ndarray,
    stop: np.ndarray,
    samples: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    u: np.ndarray,
    max_range_m: float,
    ray_b: np.ndarray,
    segments: Segments,
    held: int,
    heads: np.ndarray,
) -> tuple[int, int]:
    """Fill each live column's rows from ``row`` up to ``stop`` (its sample's, :func:`_project`)
    and move ``row`` past them; ``samples``: each column's last sample and this one, down and
    forward (``vd``, ``vf``, ``wd``, ``wf``). The rows filled are added to ``segments``, after the
    ``held`` there (:data:`Segments`), each at the head of its first row's chain (``heads``):
    row ``last - k`` of a segment has the inverse depth ``inverse - k * change``. A column stops
    (``live``) at the image's top row or with its sample past ``max_range_m``. Returns how many
    stopped, and how many segments there are."""
    vd, vf, wd, wf = samples
    cols, nexts, lasts, inverses, changes = segments
    height = ray_b.shape[0]
    down = ray_b[1] - ray_b[0] if height > 1 else 0.0  # the ray offset's change from one row to the next
    stopped = 0
    for col in range(row.shape[0]):
        if not live[col]:
            continue
        r = row[col]
        lo = max(stop[col], 0)
        if wf[col] <= IN_FRONT_M < vf[col] and vd[col] + (wd[col] - vd[col]) * vf[col] / (vf[col] - wf[col]) < 0.0:
            lo = 0  # up a face past the plane of the optical centre (a wall taller than the view): it fills the rows to the top
        if lo <= r:
            # Rows lo..r see this sample or nearer: their rays meet the segment from the last
            # sample at depth cross / (dd - b df), so 1 / depth = p + q b.
            d, f = wd[col], wf[col]
            dd, df = d - vd[col], f - vf[col]
            cross = vf[col] * dd - vd[col] * df
            if cross != 0.0:
                p, q = dd / cross, -df / cross
            else:
                p, q = 1.0 / f, 0.0
            cols[held], nexts[held], lasts[held], inverses[held], changes[held] = col, heads[lo], r, p + q * ray_b[r], q * down
            heads[lo] = held
            held += 1
            row[col] = lo - 1
        if row[col] < 0 or u[col] > max_range_m:
            live[col] = False
            stopped += 1
    return stopped, held


@njit(cache=True, nogil=True)
def _where(
    u: np.ndarray,
    ratio: np.ndarray,
    last: np.ndarray,
    before: np.ndarray,
    hx: np.ndarray,
    hy: np.ndarray,
    mx: np.ndarray,
    my: np.ndarray,
    where: tuple[float, float, float, float, float, int, int, int],
    guess: np.ndarray,
    fu: np.ndarray,
    fv: np.ndarray,
    cell: np.ndarray,
    block: np.ndarray,
) -> None:
    """Each column's next sample: the drop its last two predict (into ``guess``), the plane's
    point there, its cell (flat index of the lower-left of the four centres around it), its place
    in that cell (``fu``, ``fv``) and its block of the step lengths. ``where``: the optical
    centre in cell-centre units, cells per metre, the largest cell coordinates, the grid's row
    length, the blocks' shift and their row length."""
    x0, y0, per_m, x_top, y_top, nx, shift, blocks = where
    for col in range(u.shape[0]):
        g = last[col] + (last[col] - before[col]) * ratio[col]
        guess[col] = g
        # Just inside the outermost centres, so that the four corners are on the grid.
        x = min(max(x0 + (u[col] * hx[col] + g * mx[col]) * per_m, 0.0), x_top)
        y = min(max(y0 + (u[col] * hy[col] + g * my[col]) * per_m, 0.0), y_top)
        c0, r0 = np.int64(x), np.int64(y)
        fu[col], fv[col] = x - c0, y - r0
        cell[col] = r0 * nx + c0
        block[col] = (r0 >> shift) * blocks + (c0 >> shift)


@njit(cache=True, nogil=True)
def _read(
    cell: np.ndarray, block: np.ndarray, heights: np.ndarray, nx: int, steps: np.ndarray, corners: np.ndarray, longest: np.ndarray
) -> None:
    """The four corner heights (4, W) of each column's cell and its block's longest step."""
    for col in range(cell.shape[0]):
        i = np.uint64(cell[col])
        corners[0, col] = heights[i]
        corners[1, col] = heights[i + np.uint64(1)]
        corners[2, col] = heights[i + np.uint64(nx)]
        corners[3, col] = heights[i + np.uint64(nx + 1)]
        longest[col] = steps[np.uint64(block[col])]


@njit(cache=True, nogil=True)
def _newton(
    corners: np.ndarray,
    fu: np.ndarray,
    fv: np.ndarray,
    mx: np.ndarray,
    my: np.ndarray,
    drop: np.ndarray,
    cz: float,
    per_m: float,
    moved: np.ndarray,
) -> int:
    """Each column's drop where its plane meets the ground, from its guess in ``drop``: one Newton
    step on the bilinear field (its height and gradient at the guess's point); how far it moved
    the drop into ``moved`` (signed: the step's result less the guess). How many it moved by
    more than :data:`SETTLE_M`."""
    h00, h01, h10, h11 = corners[0], corners[1], corners[2], corners[3]
    for col in range(drop.shape[0]):
        a, b, c, d = np.float64(h00[col]), np.float64(h01[col]), np.float64(h10[col]), np.float64(h11[col])
        south = a + (b - a) * fu[col]
        north = c + (d - c) * fu[col]
        z = south + (north - south) * fv[col]
        gx = ((b - a) + ((d - c) - (b - a)) * fv[col]) * per_m
        gy = (north - south) * per_m
        # The gap between the plane and the ground closes by this much per metre of drop; kept
        # from vanishing where the plane runs along a steep face.
        closing = max(1.0 + gx * mx[col] + gy * my[col], 0.5)
        g = drop[col]
        drop[col] = g + (cz - g - z) / closing
        moved[col] = drop[col] - g
    far = 0
    for col in range(drop.shape[0]):
        far += abs(moved[col]) > SETTLE_M
    return far


@njit(cache=True, nogil=True)
def settle_drops(
    moved: np.ndarray,
    drop: np.ndarray,
    u: np.ndarray,
    planes: np.ndarray,
    centre: np.ndarray,
    heights: np.ndarray,
    per_m: float,
    span: tuple[float, float],
) -> None:
    """The drop of each column whose Newton step moved it by more than :data:`SETTLE_M` and left
    its plane's point more than a tenth of that off the ground (it met a wall, a ledge or a
    crest's far side, where the ground is not near its tangent), found again where the point
    meets the ground to :data:`SETTLE_M` / 100, by regula falsi (Illinois)
    between the guess and the step's result, or, where both lie on one side, between the result
    and the nearest drop past which the gap turns (:func:`_bracket`, within the field's lowest and
    highest heights, ``span``): one Newton step alone can leave the point in the air,
    and the rows it fills above the true silhouette then show ground that is not there."""
    for col in range(drop.shape[0]):
        if not abs(moved[col]) > SETTLE_M:
            continue
        point = (centre[0] + u[col] * planes[0, col], centre[1] + u[col] * planes[1, col], planes[2, col], planes[3, col], centre[2])
        b = drop[col]
        fb = _gap(point, b, heights, per_m)
        if abs(fb) <= 0.1 * SETTLE_M:  # on smooth ground the step lands on it: a tenth of a pixel row at 10 m
            continue
        guess = b - moved[col]
        a = guess if fb * _gap(point, guess, heights, per_m) <= 0.0 else _bracket(point, b, fb, heights, per_m, span)
        drop[col] = _root(point, a, b, heights, per_m)


@njit(cache=True, nogil=True, inline="always")
def _bracket(
    point: tuple[float, float, float, float, float], b: float, fb: float, heights: np.ndarray, per_m: float, span: tuple[float, float]
) -> float:
    """The drop nearest ``b`` on the side that closes its gap ``fb`` at which the gap's sign has
    turned, stepping out from ``b`` by a centimetre doubled each step: down (a larger drop) from a
    point in the air, up from one under the ground. The field's lowest (highest) height bounds
    the search: there the gap has turned for certain, so the nearest crossing wins over a farther one."""
    end = point[4] - span[0] if fb > 0.0 else point[4] - span[1]
    step = SETTLE_M if fb > 0.0 else -SETTLE_M
    at = b
    while (end - at) * step > 0.0:
        at = min(at + step, end) if step > 0.0 else max(at + step, end)
        if fb * _gap(point, at, heights, per_m) <= 0.0:
            return at
        step *= 2.0
    return end


@njit(cache=True, nogil=True, inline="always")
def _gap(point: tuple[float, float, float, float, float], drop: float, heights: np.ndarray, per_m: float) -> float:
    """How far a column's plane's point at ``drop`` lies above the ground [m] (``point``: the
    point at no drop, x and y, the plane's level offset per metre of drop, the optical centre's z)."""
    x, y, mx, my, cz = point
    return cz - drop - height_at(heights, per_m, x + drop * mx, y + drop * my)


@njit(cache=True, nogil=True, inline="always")
def _root(point: tuple[float, float, float, float, float], a: float, b: float, heights: np.ndarray, per_m: float) -> float:
    """The drop between ``a`` and ``b`` (the gap of opposite signs at them, :func:`_gap`) at which
    the gap closes to within :data:`SETTLE_M` / 100, by the Illinois method (at most 60 steps)."""
    fa, fb = _gap(point, a, heights, per_m), _gap(point, b, heights, per_m)
    side = 0
    for _ in range(60):
        if abs(fb) <= 0.01 * SETTLE_M or fa == fb:
            break
        c = b - fb * (b - a) / (fb - fa)
        fc = _gap(point, c, heights, per_m)
        if fc * fb < 0.0:
            a, fa = b, fb
            side = 0
        else:
            fa = 0.5 * fa if side == 1 else fa
            side = 1
        b, fb = c, fc
    return b


@njit(cache=True, nogil=True)
def _project(
    drop: np.ndarray,
    u: np.ndarray,
    dh: np.ndarray,
    dm: np.ndarray,
    fh: np.ndarray,
    fm: np.ndarray,
    wd: np.ndarray,
    wf: np.ndarray,
    stop: np.ndarray,
    fy: float,
    cy: float,
) -> None:
    """Each column's sample in its camera coordinates (down ``wd``, forward ``wf``) and the
    highest row it fills to: rows whose ray offset is at least ``wd / wf``
    (a number past the image where the sample is not in front of the camera)."""
    for col in range(drop.shape[0]):
        d = u[col] * dh[col] + drop[col] * dm[col]
        f = u[col] * fh[col] + drop[col] * fm[col]
        wd[col], wf[col] = d, f
        at = min(max(d / f * fy + cy - 0.5, -1.0), 1e9) if f > IN_FRONT_M else 1e9
        stop[col] = np.int64(math.ceil(at))


@njit(cache=True, nogil=True)
def _advance(
    u: np.ndarray, taken: np.ndarray, ratio: np.ndarray, longest: np.ndarray, per_row: float, clearance2: float, cap: float
) -> None:
    """Each column's next distance: a step of a pixel row's ground (``(u^2 + c^2) per_row``) or
    the ground's ``longest``, whichever is longer; ``taken`` and ``ratio`` follow (the step, and
    it over the one before, 0 for the second sample). Distances stop at ``cap``."""
    for col in range(u.shape[0]):
        r = u[col]
        step = max((r * r + clearance2) * per_row, longest[col])
        ratio[col] = step / taken[col] if taken[col] > 0.0 else 0.0
        taken[col] = step
        u[col] = min(r + step, cap)


@njit(cache=True, nogil=True)
def _shade(
    filled: np.ndarray,
    segments: Segments,
    heads: np.ndarray,
    axes: np.ndarray,
    centre: np.ndarray,
    ray_a: np.ndarray,
    ray_b: np.ndarray,
    max_range_m: float,
    per_m: float,
    raster: np.ndarray,
    nx: int,
    x_max: float,
    y_max: float,
    unknown: int,
    ids: np.ndarray,
    depth: np.ndarray,
) -> None:
    """Each pixel's depth, NaN where none or out of range, and class, row by row, from the inverse
    depths of its column's ``segments`` (:data:`Segments`, ``heads`` the first to begin on each
    row; rows below ``filled`` (W,))."""
    height, width = ids.shape
    top = filled.min()
    lowest = filled.astype(np.int32)  # compared in 32 bits, as wide as the float32 lanes it masks
    range2 = max_range_m * max_range_m
    ax, ay, reach = _column_rays(ray_a, axes, per_m, range2)
    x0, y0 = np.float32(centre[0] * per_m + 1.0), np.float32(centre[1] * per_m + 1.0)
    xm, ym = np.float32(x_max), np.float32(y_max)
    cells = np.empty(width, np.uint32)
    nx32 = np.uint32(nx)
    zero, one, nan = np.float32(0.0), np.float32(1.0), np.float32(np.nan)
    # Each column's segment over the row, its last row, inverse there and fall per row up (a
    # column with none reads an inverse of 0: no ground).
    seg_last, seg_inverse, seg_change = np.zeros(width, np.int64), np.zeros(width), np.zeros(width)
    row_inverse = np.empty(width, np.float32)
    for row in range(height):
        out_ids, out_depth = ids[row], depth[row]
        _take_up(heads[row], segments, seg_last, seg_inverse, seg_change)
        if row <= top:
            out_ids[:] = unknown
            out_depth[:] = np.nan
            continue
        for col in range(width):
            row_inverse[col] = seg_inverse[col] - (seg_last[col] - row) * seg_change[col]
        b, row32 = ray_b[row], np.int32(row)
        kx, ky = np.float32((b * axes[1, 0] + axes[2, 0]) * per_m), np.float32((b * axes[1, 1] + axes[2, 1]) * per_m)
        bb = np.float32(b * b / range2)
        for col in range(width):
            inverse = row_inverse[col]
            # Within range: depth^2 (1 + a^2 + b^2) <= R^2.
            seen = (row32 > lowest[col]) & (inverse > zero) & (inverse * inverse >= reach[col] + bb)
            along = one / inverse if seen else zero
            gx = min(max(x0 + along * (ax[col] + kx), zero), xm)
            gy = min(max(y0 + along * (ay[col] + ky), zero), ym)
            cells[col] = np.uint32(gy) * nx32 + np.uint32(gx) if seen else np.uint32(0)  # cell 0: the border, unknown
            out_depth[col] = along if seen else nan
        for col in range(width):
            out_ids[col] = raster[cells[col]]


@njit(cache=True, nogil=True, inline="always")
def _take_up(first: int, segments: Segments, seg_last: np.ndarray, seg_inverse: np.ndarray, seg_change: np.ndarray) -> None:
    """The segments of a row's chain (:data:`Segments`, from ``first``; -1: none) set as their
    columns' segment: each one's last row, inverse depth there and its fall per row up."""
    cols, nexts, lasts, inverses, changes = segments
    k = first
    while k >= 0:
        seg_last[cols[k]], seg_inverse[cols[k]], seg_change[cols[k]] = lasts[k], inverses[k], changes[k]
        k = nexts[k]


@njit(cache=True, nogil=True, inline="always")
def _column_rays(ray_a: np.ndarray, axes: np.ndarray, per_m: float, range2: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per column of ray offset ``ray_a`` (W,): its ray's change along x and y per metre of depth
    in raster cells (``per_m`` a metre; ``axes`` the camera's), and (1 + a^2) / R^2 (``range2``: R^2),
    float32."""
    width = ray_a.shape[0]
    ax, ay, reach = np.empty(width, np.float32), np.empty(width, np.float32), np.empty(width, np.float32)
    for col in range(width):
        a = ray_a[col]
        ax[col] = a * axes[0, 0] * per_m
        ay[col] = a * axes[0, 1] * per_m
        reach[col] = (1.0 + a * a) / range2
    return ax, ay, reach
