"""The ground map's height layer, compiled (Numba) (terrapref.groundmap.height): depth returns
voting their heights into cells, and a cell's geometry read from the cells round it as grid_map's
traversability filters read it (the slope of the gradient within a radius, from the differences
between neighbours; the returns' deviation from a plane fitted within the radius in each frame:
the roughness; the height range over the cell and its neighbours: the step)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from terrapref.world.height_compiled import plane_fit


@njit(cache=True, nogil=True)
def trusted_window(
    heights: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    trust: tuple[float, float, bool],
    rows: tuple[int, int],
    cols: tuple[int, int],
) -> np.ndarray:
    """The elevations of the height layers ``heights`` (elevation, returns, spread, weight:
    terrapref.groundmap.height.Heights) over the window ``rows`` x ``cols`` (each [first, past the
    last)), where trusted, else NaN: (rows, columns) float32. Trusted (``trust``: the least
    returns, the limit [m^2] and whether the weight is one, else the returns weigh one each): at
    least the least returns, and the standard error of their mean at most the square root of the
    limit, both as the weights put it and as the spread shows it."""
    elevation, returns, spread, weight = heights
    least, limit, weighed = trust
    (r0, r1), (c0, c1) = rows, cols
    out = np.empty((r1 - r0, c1 - c0), np.float32)
    for r in range(r0, r1):
        for c in range(c0, c1):
            k = np.float64(returns[r, c])
            w = np.float64(weight[r, c]) if weighed else k
            ok = k >= least and np.float64(spread[r, c]) <= limit * w * (k - 1.0) and (not weighed or w * limit >= 1.0)
            out[r - r0, c - c0] = elevation[r, c] if ok else np.float32(np.nan)
    return out


@njit(cache=True, nogil=True, inline="always")
def _disc_rows(reach: int, r0: int, n_rows: int) -> tuple[int, int]:
    """The rows of a disc of ``reach`` cells round row ``r0`` that lie on a grid of ``n_rows``,
    as offsets from it: [first, past the last)."""
    return max(-reach, -r0), min(reach, n_rows - 1 - r0) + 1


@njit(cache=True, nogil=True, inline="always")
def _disc_columns(reach: int, dr: int, c0: int, n_cols: int) -> tuple[int, int]:
    """The columns of a disc of ``reach`` cells round column ``c0``, in its row ``dr`` rows from the
    centre, that lie on a grid of ``n_cols``, as offsets from it: [first, past the last) (the
    cells within ``reach`` of the centre: dr^2 + dc^2 <= reach^2)."""
    span = int(math.sqrt(reach * reach - dr * dr) + 1e-9)
    return max(-span, -c0), min(span, n_cols - 1 - c0) + 1


@njit(cache=True, nogil=True)
def near_blocked(blocked: np.ndarray, reach: int, mark: np.ndarray) -> np.ndarray:
    """The cells (flat indices, each once) within ``reach`` cells (a disc) of a cell of
    ``blocked`` (n, n) uint8 that has another blocked cell among its eight neighbours (a lone
    one is a speckle of noise: a ledge or a bank is a line of cells, as a lone lethal cell is to
    the stop rule). ``mark`` (n * n,) uint8, all 0: scratch, left all 0."""
    n = blocked.shape[0]
    out = np.empty(1024, np.int64)
    count = 0
    for row in range(n):
        for col in range(n):
            if not blocked[row, col] or not _blocked_beside(blocked, row, col):
                continue
            out, count = _mark_disc(row, col, reach, mark, n, out, count)
    for i in range(count):
        mark[out[i]] = 0
    return out[:count]


@njit(cache=True, nogil=True, inline="always")
def _mark_disc(row: int, col: int, reach: int, mark: np.ndarray, n: int, out: np.ndarray, count: int) -> tuple[np.ndarray, int]:
    """The cells within ``reach`` cells (a disc) of (``row``, ``col``) on an n by n grid not yet in
    ``mark`` (n * n,) uint8, marked and listed after the first ``count`` of ``out`` (flat
    indices; grown when full): the list and how many it holds."""
    for dr in range(-reach, reach + 1):
        for dc in range(-reach, reach + 1):
            r, c = row + dr, col + dc
            if dr * dr + dc * dc > reach * reach or not (0 <= r < n and 0 <= c < n) or mark[r * n + c]:
                continue
            mark[r * n + c] = 1
            if count == out.shape[0]:
                grown = np.empty(2 * count, np.int64)
                grown[:count] = out
                out = grown
            out[count] = r * n + c
            count += 1
    return out, count


@njit(cache=True, nogil=True, inline="always")
def _blocked_beside(blocked: np.ndarray, row: int, col: int) -> bool:
    """Whether a cell among the eight round (``row``, ``col``) is blocked."""
    n = blocked.shape[0]
    for dr in range(-1, 2):
        for dc in range(-1, 2):
            r, c = row + dr, col + dc
            if (dr or dc) and 0 <= r < n and 0 <= c < n and blocked[r, c]:
                return True
    return False


# A frame's returns summed per cell (:func:`depth_frame`'s ``sums``, one row per cell the frame's
# returns fall in): weighed by the sensor's errors alone (the frame's shape) ...
SUM_WX, SUM_WY, SUM_WZ, SUM_W = 0, 1, 2, 3
# ... and with the attitude's error too (its heights), with their squares, and how many.
SUM_VZ, SUM_VZZ, SUM_V, SUM_COUNT = 4, 5, 6, 7
FRAME_SUMS = 8

# Each cell's values in the ground's shape (the ``shape`` layer, terrapref.groundmap.layers): its
# difference along x, the run between the returns it is read between, its weight, then likewise
# along y. A difference along an axis is read at its first value (SHAPE_X or SHAPE_Y) and the two
# after it. One array, not six: a kernel's helper handed an array costs its reference count,
# more than the helper's own reading of a few cells.
SHAPE_X, SHAPE_Y = 0, 3
RISE, RUN, WEIGHT = 0, 1, 2
SHAPE_VALUES = 6


@njit(cache=True, nogil=True)
def depth_frame(
    depth: np.ndarray,
    pixels: tuple[np.ndarray, np.ndarray, np.ndarray],
    axes: np.ndarray,
    centre: np.ndarray,
    grid: tuple[float, float, float],
    max_range_m: float,
    errors: tuple[float, float, float],
    votes: tuple[np.ndarray, np.ndarray, int, np.ndarray, np.ndarray],
    heights: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    shape: np.ndarray,
    scratch: tuple[np.ndarray, np.ndarray],
    rough: tuple[np.ndarray, np.ndarray, int, float],
) -> np.ndarray:
    """Fold one frame's depth image into a ground map's height layers and its ground's shape.

    ``depth`` (H, W) [m along the optical axis, NaN: no return] is read at ``pixels`` (rows,
    columns, and each one's ray (N, 3) in the camera frame, forward 1): a return is the optical
    ``centre`` (3,) plus the depth times the ray turned by ``axes`` (3, 3; rows right, down,
    forward in the world), and falls in the cell of the map ``grid`` (its corner x, y [m] and
    cells per metre) under it. ``votes`` (each pixel's class id, the columns of the ids, K, and
    the two outputs: each pixel's cell (flat index; -1: no vote, for a pixel without a return
    or one seeing no ground) and column) says where each pixel votes its class
    (terrapref.groundmap.map_compiled.map_vote_cells).

    The returns no deeper than ``max_range_m`` are summed per cell, each weighed by the inverse
    of its variance: ``errors``' base [m] and its per m^2 of depth times the depth squared,
    added in quadrature, and, for the heights, its attitude's tangent times the return's
    distance from the centre across the ground as well. Then each cell they fell in gets:

    - in ``heights`` (elevation (n, n) float32, NaN where nothing fell yet, returns, spread,
      weight; terrapref.groundmap.height.Heights) the frame's returns, folded in as the
      weighted mean and sum of squared deviations of all its returns would take them one by one
      (the frame's sums combined with the cell's, as Chan's parallel update combines two sets);
    - in ``shape`` ((n, n, :data:`SHAPE_VALUES`) float32, terrapref.groundmap.layers) its
      height difference to its neighbour along x (and the run between them along x, and their
      weight), and likewise along y, as this frame
      alone shows them: its mean return differenced with theirs, each difference folded into
      the cell's means of them weighed by the inverse of its variance (``shape`` holds the
      weighted means and the weights' sums). The attitude's error is left out of these: it tilts
      all the frame's returns as one plane through the camera, which changes a difference over
      a cell by a few millimetres (0.035 of its run for 2 deg). Gathered over frames whose
      attitudes erred differently, differences agree where heights do not; but each frame's
      differences read the ground tilted by its own error (2 deg of a camera's jitter is 2 deg
      of grade in that frame), and their means keep what of it the frames weighed most did not
      average out;
    - in ``rough`` the cell's roughness as this frame alone shows it (:func:`_fold_roughness`).

    ``scratch``: ``slot`` (n * n,) int32, all -1 (each cell's row of the frame's sums), left all
    -1, and room for the sums ((N, :data:`FRAME_SUMS`) float64). The cells the frame's returns
    fell in (flat indices, each once, in the order first fallen in)."""
    slot, sums = scratch
    count, touched = _gather_returns(depth, pixels, axes, centre, grid, max_range_m, errors, votes, slot, sums)
    _fold_heights(heights, sums, touched, count)
    _fold_shape(shape, sums, slot, touched, count)
    _fold_roughness(rough, sums, slot, touched, count, (centre[0], centre[1]), errors)
    for i in range(count):
        slot[touched[i]] = -1
    return touched[:count]


@njit(cache=True, nogil=True, inline="always")
def _gather_returns(
    depth: np.ndarray,
    pixels: tuple[np.ndarray, np.ndarray, np.ndarray],
    axes: np.ndarray,
    centre: np.ndarray,
    grid: tuple[float, float, float],
    max_range_m: float,
    errors: tuple[float, float, float],
    votes: tuple[np.ndarray, np.ndarray, int, np.ndarray, np.ndarray],
    slot: np.ndarray,
    sums: np.ndarray,
) -> tuple[int, np.ndarray]:
    """:func:`depth_frame`'s first part: each pixel's return, its vote's cell, and the returns
    within range summed into their cell's row of ``sums`` (rows in the order the cells are first
    fallen in, each zeroed then; ``slot``: each cell's row): how many cells, and which."""
    rows, cols, ray = pixels
    base, per_m2, tilt = errors
    ids, columns, k, vote_cell, vote_column = votes
    n = int(math.sqrt(slot.shape[0]) + 0.5)
    touched = np.empty(rows.shape[0], np.int64)
    count = 0
    # The ray's turn and the centre as numbers: an array handed to a helper costs its reference count.
    turn = (axes[0, 0], axes[1, 0], axes[2, 0], axes[0, 1], axes[1, 1], axes[2, 1], axes[0, 2], axes[1, 2], axes[2, 2])
    origin = (centre[0], centre[1], centre[2])
    for i in range(rows.shape[0]):
        vote_cell[i] = -1
        d = np.float64(depth[rows[i], cols[i]])
        x, y, z, cell = _return_at(d, (ray[i, 0], ray[i, 1], ray[i, 2]), turn, origin, grid, n)
        if cell < 0:
            continue
        column = columns[ids[i]]
        vote_column[i] = column
        if column <= k:
            vote_cell[i] = cell
        if not d <= max_range_m:
            continue
        row = slot[cell]
        if row < 0:
            row = count
            slot[cell] = count
            touched[count] = cell
            count += 1
            for j in range(FRAME_SUMS):
                sums[row, j] = 0.0
        noise = base * base + (per_m2 * d * d) ** 2
        w = 1.0 / noise
        wv = 1.0 / (noise + tilt * tilt * ((x - centre[0]) ** 2 + (y - centre[1]) ** 2))
        sums[row, SUM_WX] += w * x
        sums[row, SUM_WY] += w * y
        sums[row, SUM_WZ] += w * z
        sums[row, SUM_W] += w
        sums[row, SUM_VZ] += wv * z
        sums[row, SUM_VZZ] += wv * z * z
        sums[row, SUM_V] += wv
        sums[row, SUM_COUNT] += 1.0
    return count, touched


@njit(cache=True, nogil=True, inline="always")
def _return_at(
    d: float,
    ray: tuple[float, float, float],
    turn: tuple[float, float, float, float, float, float, float, float, float],
    centre: tuple[float, float, float],
    grid: tuple[float, float, float],
    n: int,
) -> tuple[float, float, float, int]:
    """The return of depth ``d`` along ``ray`` (x, y, z in the camera frame; ``turn``: the world's
    x, y and z of the camera's axes, each as right, down, forward; :func:`depth_frame`) and the cell of the n by
    n ``grid`` it falls in (flat index; -1 where it falls off the grid or there is no return)."""
    ox, oy, inv_res = grid
    x = centre[0] + d * (ray[0] * turn[0] + ray[1] * turn[1] + ray[2] * turn[2])
    y = centre[1] + d * (ray[0] * turn[3] + ray[1] * turn[4] + ray[2] * turn[5])
    z = centre[2] + d * (ray[0] * turn[6] + ray[1] * turn[7] + ray[2] * turn[8])
    if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(z)):
        return x, y, z, -1
    u, v = (x - ox) * inv_res, (y - oy) * inv_res
    if not (0.0 <= u < n and 0.0 <= v < n):
        return x, y, z, -1
    return x, y, z, int(v) * n + int(u)


@njit(cache=True, nogil=True, inline="always")
def _fold_heights(heights: tuple[np.ndarray, ...], sums: np.ndarray, touched: np.ndarray, count: int) -> None:
    """:func:`depth_frame`'s heights: each cell's returns of the frame combined with those it holds."""
    elevation, returns, spread, weight = heights
    n = elevation.shape[0]
    for i in range(count):
        row, col = touched[i] // n, touched[i] % n
        w = sums[i, SUM_V]
        mean = sums[i, SUM_VZ] / w
        scatter = max(sums[i, SUM_VZZ] - mean * sums[i, SUM_VZ], 0.0)  # the frame's own squared deviations, weighted
        k = returns[row, col]
        if k == 0:
            elevation[row, col], spread[row, col], weight[row, col] = mean, scatter, w
        else:
            held = np.float64(weight[row, col])
            total = held + w
            delta = mean - np.float64(elevation[row, col])
            elevation[row, col] = np.float64(elevation[row, col]) + delta * (w / total)
            spread[row, col] = np.float64(spread[row, col]) + scatter + delta * delta * (held * w / total)
            weight[row, col] = total
        returns[row, col] = k + np.uint32(sums[i, SUM_COUNT])


@njit(cache=True, nogil=True, inline="always")
def _fold_shape(shape: np.ndarray, sums: np.ndarray, slot: np.ndarray, touched: np.ndarray, count: int) -> None:
    """:func:`depth_frame`'s shape: each cell's differences to its neighbours along x and y, as
    the frame shows them. Each cell's sums (its row of ``sums``) become its mean return and the
    variance of that mean (the inverse of its weight) first."""
    n = shape.shape[0]
    for i in range(count):
        variance = 1.0 / sums[i, SUM_W]
        sums[i, SUM_WX], sums[i, SUM_WY], sums[i, SUM_WZ] = (
            sums[i, SUM_WX] * variance,
            sums[i, SUM_WY] * variance,
            sums[i, SUM_WZ] * variance,
        )
        sums[i, SUM_W] = variance
    for i in range(count):
        t = touched[i]
        row, col = t // n, t % n
        right = slot[t + 1] if col + 1 < n else -1
        above = slot[t + n] if row + 1 < n else -1
        if right >= 0:
            w = 1.0 / (sums[i, SUM_W] + sums[right, SUM_W])
            _fold_difference(shape, SHAPE_X, row, col, w, sums[right, SUM_WZ] - sums[i, SUM_WZ], sums[right, SUM_WX] - sums[i, SUM_WX])
        if above >= 0:
            w = 1.0 / (sums[i, SUM_W] + sums[above, SUM_W])
            _fold_difference(shape, SHAPE_Y, row, col, w, sums[above, SUM_WZ] - sums[i, SUM_WZ], sums[above, SUM_WY] - sums[i, SUM_WY])


@njit(cache=True, nogil=True, inline="always")
def _fold_difference(shape: np.ndarray, axis: int, row: int, col: int, w: float, rise: float, run: float) -> None:
    """A difference (``rise`` over ``run`` [m]) of weight ``w`` along ``axis`` (its first value in
    ``shape``: :data:`SHAPE_X` or :data:`SHAPE_Y`) folded into cell (``row``, ``col``)'s weighted
    means of them and their weights' sum."""
    total = np.float64(shape[row, col, axis + WEIGHT]) + w
    share = w / total
    held_rise, held_run = np.float64(shape[row, col, axis + RISE]), np.float64(shape[row, col, axis + RUN])
    shape[row, col, axis + RISE] = held_rise + (rise - held_rise) * share
    shape[row, col, axis + RUN] = held_run + (run - held_run) * share
    shape[row, col, axis + WEIGHT] = total


# A frame's roughness of a cell is read from at least this many of its cells in the cell's disc,
# and weighed as if the ground were at least this rough [m^2] (so that the frames whose returns
# are known best, not those which happen to find the ground smoothest, weigh most).
ROUGH_LEAST_CELLS = 6
ROUGH_FLOOR_M2 = 1e-4


@njit(cache=True, nogil=True, inline="always")
def _fold_roughness(
    rough: tuple[np.ndarray, np.ndarray, int, float],
    sums: np.ndarray,
    slot: np.ndarray,
    touched: np.ndarray,
    count: int,
    centre: tuple[float, float],
    errors: tuple[float, float, float],
) -> None:
    """:func:`depth_frame`'s roughness, read within the frame: its returns are not moved against
    each other by its pose's error or its attitude's, which blur heights fused over frames into
    smoother ground than there is. ``rough``: the mean and weight layers, the disc's reach in
    cells, and the range [m] across the ground from the optical centre ``centre`` (x, y) within
    which a cell is read. For each cell whose mean return lies within it, the plane fitted through
    the frame's mean returns (:func:`_fold_shape` made them) of the cells within the reach (a
    disc) and the mean squared deviation about it, less the share of the depth noise it holds
    (the mean variance of those means by the depth's error, ``errors``' base taken out of what
    :func:`_gather_returns` weighed them by, times (m - 3) / m over m cells); folded into the
    cell's mean of them, each weighed by m over the square of that variance plus
    :data:`ROUGH_FLOOR_M2`."""
    mean, weight, reach, range_m = rough
    base2 = errors[0] * errors[0]
    n = mean.shape[0]
    disc = np.empty((2 * reach + 1) ** 2, np.int64)  # the disc's cells as offsets of flat indices
    size = 0
    for dr in range(-reach, reach + 1):
        for dc in range(-reach, reach + 1):
            if dr * dr + dc * dc <= reach * reach:
                disc[size] = dr * n + dc
                size += 1
    depth_var = np.empty(count)  # each cell's mean return's variance by the depth's error alone
    for i in range(count):
        depth_var[i] = sums[i, SUM_W] - base2 / sums[i, SUM_COUNT]
    for i in range(count):
        x0, y0 = sums[i, SUM_WX], sums[i, SUM_WY]
        t = touched[i]
        r0, c0 = t // n, t % n
        if (x0 - centre[0]) ** 2 + (y0 - centre[1]) ** 2 > range_m * range_m or not (reach <= r0 < n - reach and reach <= c0 < n - reach):
            continue
        m = sx = sy = sz = sxx = syy = sxy = sxz = syz = szz = noise = 0.0
        for k in range(size):
            j = slot[t + disc[k]]
            if j < 0:
                continue
            x, y, z = sums[j, SUM_WX] - x0, sums[j, SUM_WY] - y0, sums[j, SUM_WZ]
            m, sx, sy, sz = m + 1.0, sx + x, sy + y, sz + z
            sxx, syy, sxy, sxz, syz, szz = sxx + x * x, syy + y * y, sxy + x * y, sxz + x * z, syz + y * z, szz + z * z
            noise += depth_var[j]
        if m < ROUGH_LEAST_CELLS:
            continue
        _, deviation = plane_fit((m, sx, sy, sz, sxx, syy, sxy, sxz, syz, szz))
        if math.isnan(deviation):
            continue
        variance = noise / m
        w = m / (variance + ROUGH_FLOOR_M2) ** 2
        total = np.float64(weight[r0, c0]) + w
        held = np.float64(mean[r0, c0])
        mean[r0, c0] = held + (deviation * deviation - variance * (m - 3.0) / m - held) * (w / total)
        weight[r0, c0] = total


@njit(cache=True, nogil=True)
def read_roughness(rough: tuple[np.ndarray, np.ndarray], rows: np.ndarray, cols: np.ndarray, out: np.ndarray) -> None:
    """The roughness [m] of the cells (``rows``, ``cols``) into ``out`` (N,), as the frames read
    it (``rough``: the mean and weight layers, :func:`depth_frame`): the square root of the mean,
    0 where the noise took it below 0; NaN where no frame read it or off the grid."""
    mean, weight = rough
    n = mean.shape[0]
    for i in range(rows.shape[0]):
        r, c = rows[i], cols[i]
        out[i] = np.nan
        if 0 <= r < n and 0 <= c < n and weight[r, c] > 0:
            out[i] = math.sqrt(max(np.float64(mean[r, c]), 0.0))


# Each cell's sums over its disc (the ``disc`` layer, terrapref.groundmap.layers): the read
# differences along x, their runs and how many are known, then likewise along y.
DISC_RISE_X, DISC_RUN_X, DISC_KNOWN_X, DISC_RISE_Y, DISC_RUN_Y, DISC_KNOWN_Y = range(6)
DISC_SUMS = 6


@njit(cache=True, nogil=True)
def shape_geometry(
    shape: np.ndarray,
    reading: tuple[float, float],
    disc: np.ndarray,
    rows: np.ndarray,
    cols: np.ndarray,
    out: np.ndarray,
) -> None:
    """Slope [rad] and step [m] of the cells (``rows``, ``cols``) into ``out`` (N, 3: slope, NaN
    for the roughness, which heights give, step), from the ground's ``shape`` (:func:`depth_frame`)
    as :func:`shape_to_check` last read it: ``reading`` is the weight from which a difference
    counts (its standard error at most 1 / sqrt of it) and the map's cell [m]. The slope is that of the
    gradient over the cells within a disc round the cell (``disc``: its sums, :func:`disc_sums`):
    along x, the rise of their differences along x over their run, and along y likewise; NaN
    where fewer than three differences are known along either. A step within the disc adds its
    height once to each row (or column) it crosses, however the returns fell about it, so it
    reads as the slope of its height over the disc, not as a wall. The step is the height range
    over the cell and its eight neighbours, their heights relative to it summed from the
    differences between them (a corner by either way round, averaged where both are known), each
    referred to a cell's run (:func:`_rise`); NaN where fewer than two of the nine are known."""
    n = disc.shape[0]
    rises = np.empty((2, 9))
    for i in range(rows.shape[0]):
        r0, c0 = rows[i], cols[i]
        out[i, 0] = out[i, 1] = out[i, 2] = np.nan
        if 1 <= r0 < n - 1 and 1 <= c0 < n - 1:
            out[i, 0], out[i, 2] = _slope_and_step(shape, reading, disc, r0, c0, rises)


@njit(cache=True, nogil=True)
def block_cells(
    shape: np.ndarray,
    reading: tuple[float, float],
    disc: np.ndarray,
    cells: np.ndarray,
    limits: tuple[float, float],
    blocked: np.ndarray,
) -> bool:
    """Each cell of ``cells`` (flat indices) blocked in ``blocked`` (n, n) uint8 where its slope or
    its step (:func:`shape_geometry`) is past ``limits`` (the steepest slope [rad], the highest
    step [m]; unknown geometry is past neither, as terrapref.groundmap.height.GeometryLimits.lethal
    has it), unblocked where neither is: whether any cell's block changed. The cells lie in
    discs round the cells the frame read again, so most of the differences a cell's step reads
    are its neighbours' too: each is read once (:func:`_rises_round`)."""
    n = disc.shape[0]
    max_slope, max_step = limits
    rises, box = _rises_round(shape, reading, cells)
    changed = False
    for i in range(cells.shape[0]):
        r0, c0 = cells[i] // n, cells[i] % n
        lethal = False
        if 1 <= r0 < n - 1 and 1 <= c0 < n - 1:
            here = (r0 - box[0]) * box[2] + c0 - box[1]
            lethal = _slope(disc, r0, c0) > max_slope or _step_of(rises, here, box[2]) > max_step
        if bool(blocked[r0, c0]) != lethal:
            blocked[r0, c0] = 1 if lethal else 0
            changed = True
    return changed


@njit(cache=True, nogil=True)
def _rises_round(shape: np.ndarray, reading: tuple[float, float], cells: np.ndarray) -> tuple[np.ndarray, tuple[int, int, int]]:
    """The differences (:func:`_rise`) the steps of ``cells`` (flat indices, each at least a cell
    from the grid's edge to count) read, over the box round them: (2, box rows * box columns),
    along x then along y, row-major in the box (NaN where no cell's step reads it), and the box's
    first row, first column and row length."""
    n = shape.shape[0]
    least, cell = reading
    r_lo, r_hi, c_lo, c_hi = n, 0, n, 0
    for i in range(cells.shape[0]):
        r0, c0 = cells[i] // n, cells[i] % n
        if 1 <= r0 < n - 1 and 1 <= c0 < n - 1:
            r_lo, r_hi, c_lo, c_hi = min(r_lo, r0 - 1), max(r_hi, r0 + 2), min(c_lo, c0 - 1), max(c_hi, c0 + 2)
    width = max(c_hi - c_lo, 0)
    size = max(r_hi - r_lo, 0) * width
    rises = np.full((2, size), np.nan)
    need = np.zeros((2, size), np.uint8)
    for i in range(cells.shape[0]):
        r0, c0 = cells[i] // n, cells[i] % n
        if 1 <= r0 < n - 1 and 1 <= c0 < n - 1:
            k = (r0 - r_lo) * width + c0 - c_lo
            for dr in (-1, 0, 1):  # along x: the rows round the cell, its column and the one before
                need[0, k + dr * width - 1] = need[0, k + dr * width] = 1
            for dc in (-1, 0, 1):  # along y: the columns round it, its row and the one before
                need[1, k - width + dc] = need[1, k + dc] = 1
    for k in range(size):
        r, c = r_lo + k // width, c_lo + k % width
        if need[0, k]:
            rises[0, k] = _rise(shape, SHAPE_X, least, cell, r, c)
        if need[1, k]:
            rises[1, k] = _rise(shape, SHAPE_Y, least, cell, r, c)
    return rises, (r_lo, c_lo, width)


@njit(cache=True, nogil=True, inline="always")
def _slope_and_step(
    shape: np.ndarray, reading: tuple[float, float], disc: np.ndarray, r0: int, c0: int, rises: np.ndarray
) -> tuple[float, float]:
    """Cell (``r0``, ``c0``)'s slope [rad] and step [m] (:func:`shape_geometry`; ``rises`` (2, 9): scratch)."""
    least, cell = reading
    rises[:] = np.nan
    for dr in (-1, 0, 1):  # the differences :func:`_step_of` reads, in the 3 x 3 box round the cell
        for dc in (-1, 0, 1):
            if dc < 1:
                rises[0, 4 + 3 * dr + dc] = _rise(shape, SHAPE_X, least, cell, r0 + dr, c0 + dc)
            if dr < 1:
                rises[1, 4 + 3 * dr + dc] = _rise(shape, SHAPE_Y, least, cell, r0 + dr, c0 + dc)
    return _slope(disc, r0, c0), _step_of(rises, 4, 3)


@njit(cache=True, nogil=True, inline="always")
def _slope(disc: np.ndarray, r0: int, c0: int) -> float:
    """Cell (``r0``, ``c0``)'s slope [rad]: that of its gradient over the disc (:func:`_disc_gradient`)."""
    gx, gy = _disc_gradient(disc, r0, c0)
    return math.atan(math.hypot(gx, gy))


@njit(cache=True, nogil=True)
def shape_gradient(disc: np.ndarray, rows: np.ndarray, cols: np.ndarray, out: np.ndarray) -> None:
    """The ground's gradient (rise per metre along x, along y) of the cells (``rows``, ``cols``)
    into ``out`` (N, 2), as :func:`shape_geometry` reads its slope from it; NaN where unknown."""
    n = disc.shape[0]
    for i in range(rows.shape[0]):
        r0, c0 = rows[i], cols[i]
        out[i, 0] = out[i, 1] = np.nan
        if 1 <= r0 < n - 1 and 1 <= c0 < n - 1:
            out[i, 0], out[i, 1] = _disc_gradient(disc, r0, c0)


@njit(cache=True, nogil=True, inline="always")
def _disc_gradient(disc: np.ndarray, r0: int, c0: int) -> tuple[float, float]:
    """The gradient over the disc round cell (``r0``, ``c0``) from its sums (``disc``,
    :func:`disc_sums`): along x the rise of the known differences along x over their run, along
    y likewise; NaN where fewer than three are known along either (:func:`shape_geometry`)."""
    rise_x, run_x, mx = np.float64(disc[r0, c0, DISC_RISE_X]), np.float64(disc[r0, c0, DISC_RUN_X]), disc[r0, c0, DISC_KNOWN_X]
    rise_y, run_y, my = np.float64(disc[r0, c0, DISC_RISE_Y]), np.float64(disc[r0, c0, DISC_RUN_Y]), disc[r0, c0, DISC_KNOWN_Y]
    if mx >= 3.0 and my >= 3.0 and run_x > 0.0 and run_y > 0.0:
        return rise_x / run_x, rise_y / run_y
    return np.nan, np.nan


@njit(cache=True, nogil=True)
def disc_sums(checked: tuple[np.ndarray, ...], reach: int, cells: np.ndarray, disc: np.ndarray) -> None:
    """The sums of the cells (flat indices ``cells``) over their discs into ``disc`` (n, n,
    :data:`DISC_SUMS`) float32, worked out afresh: over the cells within ``reach`` cells (a disc) of each,
    the differences along x of ``checked`` (along x, its runs, along y, its runs: (n, n) float32
    each) that are numbers, their runs and how many, and likewise along y. :func:`shape_to_check`
    keeps them up to date as it reads the differences; the map works them out afresh where it
    was re-centred (a disc that reached past the old square)."""
    checked_x, checked_x_run, checked_y, checked_y_run = checked
    n = disc.shape[0]
    sums = np.empty(DISC_SUMS)
    for i in range(cells.shape[0]):
        r0, c0 = cells[i] // n, cells[i] % n
        sums[:] = 0.0
        for dr in range(*_disc_rows(reach, r0, n)):
            r = r0 + dr
            for dc in range(*_disc_columns(reach, dr, c0, n)):
                c = c0 + dc
                if math.isfinite(checked_x[r, c]):
                    sums[DISC_RISE_X] += np.float64(checked_x[r, c])
                    sums[DISC_RUN_X] += np.float64(checked_x_run[r, c])
                    sums[DISC_KNOWN_X] += 1.0
                if math.isfinite(checked_y[r, c]):
                    sums[DISC_RISE_Y] += np.float64(checked_y[r, c])
                    sums[DISC_RUN_Y] += np.float64(checked_y_run[r, c])
                    sums[DISC_KNOWN_Y] += 1.0
        for j in range(DISC_SUMS):
            disc[r0, c0, j] = sums[j]


@njit(cache=True, nogil=True, inline="always")
def _move_in_discs(
    disc: np.ndarray, first: int, row: int, col: int, reach: int, was: tuple[float, float], now: tuple[float, float]
) -> None:
    """Cell (``row``, ``col``)'s read difference and run along one axis (``first``: that axis's
    first sum) moved from ``was`` to ``now`` (each (difference, run); the difference not a
    number: not counted) in the sums of the discs it lies in (those of the cells within ``reach``
    of it: a disc is symmetric), each sum moved by the change once (one rounding to float32)."""
    n = disc.shape[0]
    take, add = math.isfinite(was[0]), math.isfinite(now[0])
    rise = (now[0] if add else 0.0) - (was[0] if take else 0.0)
    run = (now[1] if add else 0.0) - (was[1] if take else 0.0)
    known = (1.0 if add else 0.0) - (1.0 if take else 0.0)
    for dr in range(*_disc_rows(reach, row, n)):
        r = row + dr
        for dc in range(*_disc_columns(reach, dr, col, n)):
            c = col + dc
            disc[r, c, first] = np.float64(disc[r, c, first]) + rise
            disc[r, c, first + 1] = np.float64(disc[r, c, first + 1]) + run
            disc[r, c, first + 2] = np.float64(disc[r, c, first + 2]) + known


@njit(cache=True, nogil=True, inline="always")
def _step_of(rises: np.ndarray, k: int, width: int) -> float:
    """The height range over a cell and its eight neighbours (:func:`shape_geometry`), from the
    differences round it (``rises``: along x, along y, each (rows * ``width``,) row-major, the
    cell at ``k``; :func:`_rise`); NaN where fewer than two of the nine heights are known. A
    neighbour's height relative to the cell sums the differences between them: along the row
    and the column through the cell, one; a corner, from its row's middle cell along x and from
    its column's middle cell along y, averaged where both are known."""
    along_x, along_y = rises[0], rises[1]
    # h[a, b]: row a, column b of the 3 x 3 (a cell's x difference is to the next column, its y difference to the next row).
    h01, h10, h12, h21 = -along_y[k - width], -along_x[k - 1], along_x[k], along_y[k]
    h00 = _corner(h01 - along_x[k - width - 1], h10 - along_y[k - width - 1])
    h02 = _corner(h01 + along_x[k - width], h12 - along_y[k - width + 1])
    h20 = _corner(h21 - along_x[k + width - 1], h10 + along_y[k - 1])
    h22 = _corner(h21 + along_x[k + width], h12 + along_y[k + 1])
    low, high, known = np.inf, -np.inf, 0
    for h in (h00, h01, h02, h10, 0.0, h12, h20, h21, h22):
        if not math.isnan(h):
            low, high, known = min(low, h), max(high, h), known + 1
    return high - low if known >= 2 else np.nan


@njit(cache=True, nogil=True, inline="always")
def _corner(by_row: float, by_column: float) -> float:
    """A corner's height from its row's middle cell and from its column's (either NaN: not
    known that way): their mean where both are known (:func:`_step_of`)."""
    total, ways = 0.0, 0
    if not math.isnan(by_row):
        total, ways = total + by_row, ways + 1
    if not math.isnan(by_column):
        total, ways = total + by_column, ways + 1
    return total / ways if ways else np.nan


@njit(cache=True, nogil=True, inline="always")
def _rise(shape: np.ndarray, first: int, least: float, cell: float, r: int, c: int) -> float:
    """The difference at (``r``, ``c``) along the axis whose first value in ``shape`` is ``first``
    (:data:`SHAPE_X` or :data:`SHAPE_Y`) referred to a cell's run: NaN where its weight is under
    ``least``.

    A difference is the rise between two cells' mean returns, which lie anywhere in their cells:
    on a slope, returns gathered at a far cell's near edge lengthen its run to up to twice a
    cell, and its rise with it. So the rise is moved by the ground's grade times the run's
    excess over ``cell``, the grade taken from it and its known neighbours along the axis: the
    gentlest of them where all rise the same way, none otherwise, and none where it has no known
    neighbour. On a plane every difference then reads as a cell's; at a ledge its neighbours are
    level and its rise is kept whole."""
    at_rise, at_run, at_weight = first + RISE, first + RUN, first + WEIGHT  # where in a cell's values
    along_x = 1 if first == SHAPE_X else 0  # the neighbours it is compared with: along x (columns) or along y (rows)
    n = shape.shape[0]
    if not (0 <= r < n and 0 <= c < n) or shape[r, c, at_weight] < least:
        return np.nan
    here = np.float64(shape[r, c, at_rise])
    if not shape[r, c, at_run] > 0.0:
        return here
    grade, known = here / np.float64(shape[r, c, at_run]), 0
    for k in (-1, 1):
        rr, cc = r + k * (1 - along_x), c + k * along_x
        if not (0 <= rr < n and 0 <= cc < n) or shape[rr, cc, at_weight] < least or not shape[rr, cc, at_run] > 0.0:
            continue
        theirs = np.float64(shape[rr, cc, at_rise]) / np.float64(shape[rr, cc, at_run])
        if theirs * grade <= 0.0:
            return here
        grade = theirs if abs(theirs) < abs(grade) else grade
        known += 1
    return here + grade * (cell - np.float64(shape[r, c, at_run])) if known else here


@njit(cache=True, nogil=True)
def shape_to_check(
    touched: np.ndarray,
    shape: np.ndarray,
    least_weight: float,
    checked: tuple[np.ndarray, ...],
    disc: np.ndarray,
    tolerance_m: float,
    near: tuple[float, float, float, float, float, float],
    reach: int,
    mark: np.ndarray,
) -> np.ndarray:
    """Read the ground's shape where this frame changed it: the cells of ``touched`` near the
    vehicle whose difference along x or along y (``shape``, counted from ``least_weight``:
    :func:`shape_geometry`) moved by more than ``tolerance_m`` since it was last read, or came to
    be known, are read again (``checked``: the differences along x then, their runs, along y,
    their runs, (n, n) float32 each; a difference NaN where not known then, +inf never read), and
    the sums of the discs they lie in (``disc``, :func:`disc_sums`) moved with them. The cells
    whose slope or step may have changed: those within ``reach`` cells (a disc) of a cell read
    again (flat indices, each once). ``near``: the map's corner (x, y), its resolution, the
    vehicle's (x, y) and the range within which cells are read [m]; ``mark`` (n * n,) uint8, all
    0: scratch, left all 0."""
    checked_x, checked_x_run, checked_y, checked_y_run = checked
    n = shape.shape[0]
    ox, oy, res, x, y, range_m = near
    out = np.empty(1024, np.int64)
    count = 0
    for i in range(touched.shape[0]):
        t = touched[i]
        row, col = t // n, t % n
        ex, ey = ox + (col + 0.5) * res - x, oy + (row + 0.5) * res - y
        if ex * ex + ey * ey > range_m * range_m:
            continue
        now_x = shape[row, col, SHAPE_X + RISE] if shape[row, col, SHAPE_X + WEIGHT] >= least_weight else np.nan
        now_y = shape[row, col, SHAPE_Y + RISE] if shape[row, col, SHAPE_Y + WEIGHT] >= least_weight else np.nan
        moved_x = not _same(now_x, checked_x[row, col], tolerance_m)
        moved_y = not _same(now_y, checked_y[row, col], tolerance_m)
        if not (moved_x or moved_y):
            continue
        if moved_x:
            was = (np.float64(checked_x[row, col]), np.float64(checked_x_run[row, col]))
            checked_x[row, col], checked_x_run[row, col] = now_x, shape[row, col, SHAPE_X + RUN]
            now = (np.float64(checked_x[row, col]), np.float64(checked_x_run[row, col]))
            _move_in_discs(disc, DISC_RISE_X, row, col, reach, was, now)
        if moved_y:
            was = (np.float64(checked_y[row, col]), np.float64(checked_y_run[row, col]))
            checked_y[row, col], checked_y_run[row, col] = now_y, shape[row, col, SHAPE_Y + RUN]
            now = (np.float64(checked_y[row, col]), np.float64(checked_y_run[row, col]))
            _move_in_discs(disc, DISC_RISE_Y, row, col, reach, was, now)
        out, count = _mark_disc(row, col, reach, mark, n, out, count)
    for i in range(count):
        mark[out[i]] = 0
    return out[:count]


@njit(cache=True, nogil=True, inline="always")
def _same(now: float, then: float, tolerance: float) -> bool:
    """Whether a difference ``now`` (NaN: unknown) is ``then`` (NaN: unknown; +inf: never read)
    within ``tolerance``: one still unknown changes no cell's geometry, read or not."""
    return (math.isnan(now) and not math.isfinite(then)) or abs(now - then) <= tolerance


@njit(cache=True, nogil=True)
def chord_grades(
    disc: np.ndarray,
    grid: tuple[float, float, float],
    centre: np.ndarray,
    heading: np.ndarray,
    chord: tuple[np.ndarray, np.ndarray],
    out: np.ndarray,
) -> None:
    """The grade [deg, positive up] (S,) into ``out`` a body would be pitched at, centred at the
    points ``centre`` (S, 2) heading ``heading`` (S,) [rad]: the ground's gradient (:func:`_disc_gradient`)
    along the heading at the ``chord``'s offsets along it [m], weighed by its weights, as
    terrapref.rules.speed.model.body_grade reads it from any gradient; NaN where the gradient is
    known under less than half the chord's weight. ``grid``: the map's origin (x, y) [m] and its
    cell size [m]."""
    offsets, weights = chord
    for i in range(centre.shape[0]):
        c, s = math.cos(heading[i]), math.sin(heading[i])
        total = weight = 0.0
        for j in range(offsets.shape[0]):
            gx, gy = _gradient_under(disc, grid, centre[i, 0] + offsets[j] * c, centre[i, 1] + offsets[j] * s)
            if gx == gx:
                total += weights[j] * (gx * c + gy * s)
                weight += weights[j]
        out[i] = math.degrees(math.atan(total / weight)) if weight >= 0.5 else np.nan


@njit(cache=True, nogil=True)
def beside_attitudes(
    disc: np.ndarray,
    grid: tuple[float, float, float],
    centre: np.ndarray,
    normal: np.ndarray,
    offsets: np.ndarray,
    chord: tuple[int, int],
    out: np.ndarray,
) -> None:
    """The side slope and the grade [deg, both >= 0] (O - 2c, S - 2a, 2) into ``out`` of a body
    heading along a path, on a lattice of the points ``offsets`` (O,) [m, evenly spaced] left of
    the path's points ``centre`` (S, 2, evenly spaced along it; ``normal`` (S, 2): the unit
    vectors to their left): the ground's gradient (:func:`_disc_gradient`) across the way averaged
    over ``2c + 1`` lattice points across (the track), and along it over ``2a + 1`` points along
    (the wheelbase), ``chord`` = (a, c), each by the trapezoid rule (the rise between the chord's
    ends over its length, as the heights under the wheels tilt the body). Body (o, q) stands at
    lattice point (o + c, q + a). NaN where the gradient is known under less than half the chord's
    weight. ``grid``: the map's origin (x, y) [m] and its cell size [m]."""
    along, across = chord
    n_off, n_st = offsets.shape[0], centre.shape[0]
    across_slope = np.empty((n_off, n_st))
    along_slope = np.empty((n_off, n_st))
    for o in range(n_off):
        for q in range(n_st):
            nx, ny = normal[q, 0], normal[q, 1]
            gx, gy = _gradient_under(disc, grid, centre[q, 0] + offsets[o] * nx, centre[q, 1] + offsets[o] * ny)
            across_slope[o, q] = gx * nx + gy * ny  # NaN where unknown
            along_slope[o, q] = gx * ny - gy * nx  # along the tangent (ny, -nx)
    for o in range(n_off - 2 * across):
        for q in range(n_st - 2 * along):
            out[o, q, 0] = _chord_mean(across_slope[o : o + 2 * across + 1, q + along])
            out[o, q, 1] = _chord_mean(along_slope[o + across, q : q + 2 * along + 1])


@njit(cache=True, nogil=True, inline="always")
def _gradient_under(disc: np.ndarray, grid: tuple[float, float, float], x: float, y: float) -> tuple[float, float]:
    """The ground's gradient (:func:`_disc_gradient`) of the cell under the world point (``x``,
    ``y``) [m]; NaN off the map (or its edge) and where unknown. ``grid``: the map's origin (x, y)
    [m] and its cell size [m]."""
    n = disc.shape[0]
    x0, y0, res = grid
    col, row = math.floor((x - x0) / res), math.floor((y - y0) / res)
    if 1 <= row < n - 1 and 1 <= col < n - 1:
        return _disc_gradient(disc, int(row), int(col))
    return np.nan, np.nan


@njit(cache=True, nogil=True, inline="always")
def _chord_mean(values: np.ndarray) -> float:
    """The trapezoid-rule mean of ``values`` (evenly spaced along a chord; one value: itself) as
    an angle [deg, >= 0], over the known ones; NaN where they weigh less than half the chord."""
    total = weight = 0.0
    last = values.shape[0] - 1
    for k in range(values.shape[0]):
        w = 0.5 if last > 0 and (k == 0 or k == last) else 1.0
        if values[k] == values[k]:
            total += w * values[k]
            weight += w
    return math.degrees(math.atan(abs(total / weight))) if weight > 0.0 and weight >= 0.5 * last else np.nan
