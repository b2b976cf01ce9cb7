"""The features' per-frame arithmetic, compiled (Numba) for the planner's control loop: the
utility features U, the ground map's votes and reads, the corridor's features, and the camera's
attitude from the sky line.

On one frame the utility features are a few hundred pixels and a few dozen distances, the
corridor a few thousand map cells: NumPy's call overhead, not its arithmetic, set their cost,
and the ground map's samples are a loop, not a vector. Each loop here does, element by element, exactly
the IEEE 754 operations of the NumPy form its docstring gives, in the same order (compiled
without fast-math: nothing is reassociated or fused into a multiply-add), so the features, and
every decision made from them, are the same bits as the NumPy forms give (tests/test_features.py
and tests/test_offset_kernels.py compare).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from terrapref.sums import numpy_sum

UNSETTLED = 255  # a ground-map cell voted on since its column was last decided (columns run 0..K + 1)


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
def utilities(ids: np.ndarray, column: np.ndarray, row: np.ndarray, k: int, scale: float, ex: np.ndarray, ey: np.ndarray,
              c: float, s: float, dx: float, dy: float, eps: float) -> np.ndarray:
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


@njit(cache=True, nogil=True)
def stage_scores(log_probs: np.ndarray, weight: float, rows: np.ndarray, ids: np.ndarray, point_weight: np.ndarray,
                 seen: np.ndarray, distance: np.ndarray, w_distance: float, b: np.ndarray) -> np.ndarray:
    """The second stage's scores (m,): ``log_probs + weight * value`` for the candidates, where a
    candidate's value is the best of its second pieces' linear utilities; -inf elsewhere.

    The NumPy form (terrapref.planner.stages.second)::

        terrain = point_weight[ids] * seen[rows].ravel()                            # (r * m * n',)
        value = (terrain.reshape(r, m, n').sum(axis=2) + w_distance * distance + b).max(axis=1)
        out = np.full(m, -np.inf); out[rows] = log_probs[rows] + weight * value

    Args:
        log_probs: (m,) log F_t.
        weight: the second stage's weight against log F_t.
        rows: (r,) the candidate trajectories.
        ids: (r * m * n',) class id of each of their second pieces' points.
        point_weight: (256,) each class's weight per point.
        seen: (m, m, n') 1 where a point is in the image, else 0.
        distance: (r, m) the distance utility of each second piece.
    """
    r, m, n = rows.shape[0], seen.shape[1], seen.shape[2]
    terms = np.empty(n)
    out = np.full(log_probs.shape[0], -np.inf)
    for a in range(r):
        best = -np.inf
        for j in range(m):
            base = (a * m + j) * n
            for p in range(n):
                terms[p] = point_weight[ids[base + p]] * seen[rows[a], j, p]
            v = numpy_sum(terms) + w_distance * distance[a, j] + b[j]
            if v > best or v != v:  # NumPy's max: the largest, NaN if any is NaN
                best = v
                if v != v:
                    break
        out[rows[a]] = log_probs[rows[a]] + weight * best
    return out


@njit(cache=True, nogil=True)
def stage_distances(rows: np.ndarray, ends_x: np.ndarray, ends_y: np.ndarray, start_x: np.ndarray, x_lo: float, line: tuple[float, float, float, float],
                    targets: np.ndarray, c: float, s: float, x: float, y: float, eps: float) -> np.ndarray:
    """The second pieces' distance utility (r, m) after the trajectories ``rows``, normalised over
    all of them together (:func:`normalise`).

    Each end (``ends_x``, ``ends_y`` (m, m), vehicle frame) is rotated by the yaw's (c, s), moved
    to the pose (x, y) and measured against its first trajectory's target: ``targets[a]`` (r, 2),
    or, when ``targets`` is empty, the point ``(tx + t ux, ty + t uy)`` of the straight ``line``
    (tx, ty, ux, uy), ``t = start_x[i] - x_lo``. The arithmetic: ``hypot((ex c - ey s) + (x - tx),
    (ex s + ey c) + (y - ty))``, the product of complex numbers written out (NumPy's complex
    product and absolute value pick SIMD versions per CPU whose last bits differ; these are the
    same everywhere).
    """
    r, m = rows.shape[0], ends_x.shape[1]
    d = np.empty((r, m))
    lx, ly, ux, uy = line
    for a in range(r):
        i = rows[a]
        if targets.shape[0]:
            tx, ty = targets[a, 0], targets[a, 1]
        else:
            t = start_x[i] - x_lo
            tx, ty = lx + t * ux, ly + t * uy
        dx, dy = x - tx, y - ty
        for j in range(m):
            ex, ey = ends_x[i, j], ends_y[i, j]
            d[a, j] = math.hypot((ex * c - ey * s) + dx, (ex * s + ey * c) + dy)
    return normalise(d, eps)


@njit(cache=True, nogil=True)
def map_vote(evidence: np.ndarray, stamp: np.ndarray, cells: np.ndarray, ox: float, oy: float, inv_res: float, x: float, y: float,
             c: float, s: float, vx: np.ndarray, vy: np.ndarray, weight: np.ndarray, ids: np.ndarray, pixel_of: np.ndarray,
             columns: np.ndarray, frame: int, fade: np.ndarray,
             tilted: bool, ray: np.ndarray, ground0: np.ndarray, axes: np.ndarray, t: np.ndarray) -> None:
    """Add each ground sample's vote to the evidence of its cell, and mark the cell's column
    :data:`UNSETTLED` (:func:`map_decide` decides it when it is read).

    A cell's evidence (``evidence[j, i]``, one float32 per column 0..K, K the background) fades by
    ``fade[g]`` when it is next voted on ``g`` frames later (``stamp`` holds the frame of its last
    vote; gaps beyond the table fade by its last entry), then gains the sample's ``weight`` in the
    sample's column. Samples of column K + 1 (nothing seen) cast no vote. A sample's cell:
    ``i = floor((x - ox + vx * c - vy * s) * inv_res)``, ``j = floor((y - oy + vx * s + vy * c) *
    inv_res)`` (rows y, columns x); float32 sums in a fixed order, so every CPU agrees.

    A sample's column is ``columns[ids[pixel_of[p]]]`` (the class id of its pixel, ``ids`` holding
    each distinct pixel's). With ``tilted``, the camera is off its mount (``axes``, rows right, down, forward in the vehicle frame; optical centre
    ``t``): a sample moves by where its pixel's ray ``ray[p]`` (camera frame, z = 1) now meets the
    ground less where the mount's camera saw it meet it (``ground0[p]``), and a ray that no longer
    meets it casts no vote; the NumPy form of that point is
    ``terrapref.features.corridor._ground``.
    """
    n_rows, n_cols = cells.shape
    k = evidence.shape[2] - 1
    # First every sample's cell (j * n_cols + i; -1: no vote), in a loop without stores to the
    # map, then the votes, reading the map through flat views (2-D indexing cost the loop a fifth).
    n = vx.shape[0]
    cell = np.empty(n, np.int64)
    # The tilted camera's axes and centre in locals: read once, not again after every store.
    a00, a01, a02, a10, a11, a12 = axes[0, 0], axes[0, 1], axes[0, 2], axes[1, 0], axes[1, 1], axes[1, 2]
    a20, a21, a22, t0, t1, t2 = axes[2, 0], axes[2, 1], axes[2, 2], t[0], t[1], t[2]
    for p in range(n):
        cell[p] = -1
        if columns[ids[pixel_of[p]]] > k:
            continue
        px, py = vx[p], vy[p]
        if tilted:
            r0, r1 = ray[p, 0], ray[p, 1]
            dz = r0 * a02 + r1 * a12 + a22
            if not dz < -1e-12:
                continue
            scale = -t2 / dz
            gx = t0 + scale * (r0 * a00 + r1 * a10 + a20)
            gy = t1 + scale * (r0 * a01 + r1 * a11 + a21)
            px, py = px + (gx - ground0[p, 0]), py + (gy - ground0[p, 1])
            if not (math.isfinite(px) and math.isfinite(py)):
                continue
        i = math.floor((x - ox + px * c - py * s) * inv_res)
        j = math.floor((y - oy + px * s + py * c) * inv_res)
        if 0 <= i < n_cols and 0 <= j < n_rows:
            cell[p] = j * n_cols + i
    votes, stamps, columns_of = evidence.reshape(-1), stamp.reshape(-1), cells.reshape(-1)
    for p in range(n):
        here = cell[p]
        if here < 0:
            continue
        col = columns[ids[pixel_of[p]]]
        gap = frame - stamps[here]
        at = here * (k + 1)
        if gap != 0:
            f = fade[min(gap, fade.shape[0] - 1)]
            for q in range(k + 1):
                votes[at + q] *= f
            stamps[here] = frame
        votes[at + col] += weight[p]
        columns_of[here] = UNSETTLED


@njit(cache=True, nogil=True, inline="always")
def map_decide(evidence: np.ndarray, lethal: np.ndarray, lethal_share: np.float32, terrain_share: np.float32,
               min_evidence: np.float32, j: int, i: int) -> int:
    """The column of ground-map cell ``(j, i)``, decided from its evidence.

    The map's readers read a cell as ``col = cells[j, i]``, and if ``col == UNSETTLED`` (voted on
    since it was last decided) as ``col = cells[j, i] = map_decide(...)``. A cell's column depends
    only on its evidence, which changes only when it is voted on, so deciding it when it is read
    gives the column that deciding it after every vote would; a frame reads a few thousand of the
    fifteen thousand cells it votes on. (The test stays in each reader's loop, and the shares come
    as numbers: each array a compiled helper takes costs every call more than the decision.)

    The column: K + 1 (never seen) while the evidence totals less than ``min_evidence``; else the
    lethal column (``lethal``, by column) with the most evidence when the lethal columns hold at
    least ``lethal_share`` of it; else the other terrain column with the most when those columns
    hold at least ``terrain_share``; else K. Ties go to the lowest column; float32 sums in column
    order, so every CPU agrees.

    Compiled into its callers, here and in terrapref.planner.stages.kernels (see
    :func:`path_frame` on their cached copies).
    """
    k = evidence.shape[2] - 1
    total = evidence[j, i, k]
    deadly = np.float32(0.0)
    terrain = np.float32(0.0)
    best_lethal, best_terrain = -1, -1
    for q in range(k):
        e = evidence[j, i, q]
        total += e
        if lethal[q]:
            deadly += e
            if best_lethal < 0 or e > evidence[j, i, best_lethal]:
                best_lethal = q
        else:
            terrain += e
            if best_terrain < 0 or e > evidence[j, i, best_terrain]:
                best_terrain = q
    if total < min_evidence:
        return k + 1
    if best_lethal >= 0 and deadly >= lethal_share * total:
        return best_lethal
    if best_terrain >= 0 and terrain >= terrain_share * total:
        return best_terrain
    return k


@njit(cache=True, nogil=True)
def map_settle(cells: np.ndarray, evidence: np.ndarray, lethal: np.ndarray, shares: np.ndarray) -> None:
    """Decide every cell of the map still :data:`UNSETTLED` (:func:`map_decide`; ``shares``:
    its three shares, float32)."""
    for j in range(cells.shape[0]):
        for i in range(cells.shape[1]):
            if cells[j, i] == UNSETTLED:
                cells[j, i] = map_decide(evidence, lethal, shares[0], shares[1], shares[2], j, i)


@njit(cache=True, nogil=True)
def map_read(cells: np.ndarray, evidence: np.ndarray, lethal: np.ndarray, shares: np.ndarray, ox: float, oy: float, inv_res: float,
             px: np.ndarray, py: np.ndarray, never: int) -> np.ndarray:
    """The ground map's column at each point (flat arrays ``px``, ``py``); ``never`` outside it.

    The NumPy form: ``cells[floor((py - oy) * inv_res), floor((px - ox) * inv_res)]`` where
    inside, each cell decided first if it is :data:`UNSETTLED` (:func:`map_decide`, with
    ``evidence``, ``lethal`` and the three ``shares``).
    """
    n_rows, n_cols = cells.shape
    out = np.empty(px.shape[0], np.uint8)
    for p in range(px.shape[0]):
        i = math.floor((px[p] - ox) * inv_res)
        j = math.floor((py[p] - oy) * inv_res)
        col = never
        if 0 <= i < n_cols and 0 <= j < n_rows:
            col = cells[j, i]
            if col == UNSETTLED:
                col = cells[j, i] = map_decide(evidence, lethal, shares[0], shares[1], shares[2], j, i)
        out[p] = col
    return out


@njit(cache=True, nogil=True)
def path_frame(path_s: np.ndarray, path_a: np.ndarray, path_d: np.ndarray, path_len: np.ndarray, s: float) -> tuple[float, float, float, float]:
    """(x, y, ux, uy): the point at arc length ``s`` (clamped to the path) and the unit direction
    there, as ``ReferencePath.frame_at`` gives them (segments: ``path.segments``).

    Compiled into its callers, here and in terrapref.planner.stages.kernels, whose cached copies
    Numba does not recompile when only this file changes: after editing it, delete the
    ``__pycache__`` folders' ``*.nbi``/``*.nbc`` files (``python -m terrapref.warm_up`` rebuilds them)."""
    n_seg = path_len.shape[0]
    s = min(max(s, 0.0), path_s[-1])
    i = min(max(np.searchsorted(path_s, s, side="right") - 1, 0), n_seg - 1)
    f = (s - path_s[i]) / path_len[i]
    return (path_a[i, 0] + f * path_d[i, 0], path_a[i, 1] + f * path_d[i, 1], path_d[i, 0] / path_len[i], path_d[i, 1] / path_len[i])


@njit(cache=True, nogil=True)
def map_read_beside(cells: np.ndarray, evidence: np.ndarray, lethal: np.ndarray, shares: np.ndarray, ox: float, oy: float, inv_res: float,
                    path_s: np.ndarray, path_a: np.ndarray, path_d: np.ndarray, path_len: np.ndarray, s: np.ndarray, lat: np.ndarray,
                    never: int) -> np.ndarray:
    """The ground map's column (O, S, F) at the points ``lat[o, f]`` [m] left of the path at arc
    lengths ``s`` (S,), ``never`` outside the map.

    The NumPy form: :func:`map_read` of ``centre[None, :, None, :] + lat[:, None, :, None] *
    normal[None, :, None, :]``, ``centre = path.point_at(s)``, ``normal`` the path's direction
    there turned left.
    """
    n_rows, n_cols = cells.shape
    n_off, n_st, n_f = lat.shape[0], s.shape[0], lat.shape[1]
    out = np.empty((n_off, n_st, n_f), np.uint8)
    for q in range(n_st):
        cx, cy, ux, uy = path_frame(path_s, path_a, path_d, path_len, s[q])
        nx, ny = -uy, ux
        for o in range(n_off):
            for f in range(n_f):
                i = math.floor((cx + lat[o, f] * nx - ox) * inv_res)
                j = math.floor((cy + lat[o, f] * ny - oy) * inv_res)
                col = never
                if 0 <= i < n_cols and 0 <= j < n_rows:
                    col = cells[j, i]
                    if col == UNSETTLED:
                        col = cells[j, i] = map_decide(evidence, lethal, shares[0], shares[1], shares[2], j, i)
                out[o, q, f] = col
    return out


@njit(cache=True, nogil=True)
def sky_line(ids: np.ndarray, rows: np.ndarray, n_cols: int, unknown: int) -> np.ndarray:
    """The first band row of each column below which ground is seen, (n_cols,) float; NaN where none.

    ``ids`` (len(rows) * n_cols,) are the class ids of the band, row by row. The NumPy form
    (tests/test_offset_kernels.py keeps it): ``ground = ids != unknown``, the first row r with at
    least 3 of rows r..r+3 ground; all NaN when the band holds fewer than 4 rows.
    """
    out = np.full(n_cols, np.nan)
    if rows.shape[0] < 4:
        return out
    for c in range(n_cols):
        for r in range(rows.shape[0] - 3):
            seen = 0
            for q in range(4):
                if ids[(r + q) * n_cols + c] != unknown:
                    seen += 1
            if seen >= 3:
                out[c] = rows[r]
                break
    return out


@njit(cache=True, nogil=True)
def column_medians(history: np.ndarray, count: int, rows: np.ndarray) -> np.ndarray:
    """Median of each column of ``history[:count]`` (M, C) over its non-NaN entries, (C,); NaN
    where a column has none. Every entry is NaN or one of ``rows`` (increasing), so each column is
    counted into their bins. The NumPy form: ``np.nanmedian(history[:count], axis=0)`` (for an even
    count, the mean of the two middle values)."""
    n_cols, n_bins = history.shape[1], rows.shape[0]
    step = rows[1] - rows[0] if n_bins > 1 else 0.0
    out = np.empty(n_cols)
    counts = np.zeros(n_bins, np.int64)
    for c in range(n_cols):
        counts[:] = 0
        n = 0
        for m in range(count):
            v = history[m, c]
            if not np.isnan(v):
                # Evenly spaced rows (the band's) give the bin at once; a search otherwise.
                b = int((v - rows[0]) / step + 0.5) if step > 0.0 else -1
                if not (0 <= b < n_bins and rows[b] == v):
                    b = np.searchsorted(rows, v)
                    if b >= n_bins or rows[b] != v:
                        raise ValueError("a history entry is not one of the rows")
                counts[b] += 1
                n += 1
        if n == 0:
            out[c] = np.nan
            continue
        # The values of rank n // 2 (and n // 2 - 1, for an even n), counting from 0.
        low, high = np.nan, np.nan
        seen = 0
        for b in range(n_bins):
            seen += counts[b]
            if np.isnan(low) and seen > (n - 1) // 2:
                low = rows[b]
            if seen > n // 2:
                high = rows[b]
                break
        out[c] = high if n % 2 == 1 else (low + high) / 2.0
    return out


@njit(cache=True, nogil=True)
def exact_sum(values: np.ndarray) -> float:
    """The sum of finite ``values``, exactly rounded (to nearest, ties to even): ``math.fsum``'s
    result, by the same method (Shewchuk's non-overlapping partials), so the same bits on every CPU."""
    partials = np.empty(values.shape[0] + 1)
    n = 0
    for x in values:
        i = 0
        for j in range(n):
            y = partials[j]
            if abs(x) < abs(y):
                x, y = y, x
            hi = x + y
            lo = y - (hi - x)
            if lo != 0.0:
                partials[i] = lo
                i += 1
            x = hi
        n = i
        if x != 0.0:
            partials[n] = x
            n += 1
    if n == 0:
        return 0.0
    n -= 1
    hi = partials[n]
    lo = 0.0
    while n > 0:
        x = hi
        n -= 1
        y = partials[n]
        hi = x + y
        lo = y - (hi - x)
        if lo != 0.0:
            break
    # Half-even rounding across several partials.
    if n > 0 and ((lo < 0.0 and partials[n - 1] < 0.0) or (lo > 0.0 and partials[n - 1] > 0.0)):
        y = lo * 2.0
        x = hi + y
        if y == x - hi:
            hi = x
    return hi


@njit(cache=True, nogil=True)
def _interp(x: float, xp: np.ndarray, fp: np.ndarray) -> float:
    """``np.interp(x, xp, fp)`` for increasing ``xp`` (the ends held beyond it)."""
    n = xp.shape[0]
    if x <= xp[0]:
        return fp[0]
    if x >= xp[n - 1]:
        return fp[n - 1]
    j = np.searchsorted(xp, x, side="right") - 1
    if x == xp[j]:
        return fp[j]
    slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
    out = slope * (x - xp[j]) + fp[j]
    if np.isnan(out):
        out = slope * (x - xp[j + 1]) + fp[j + 1]
        if np.isnan(out) and fp[j] == fp[j + 1]:
            out = fp[j]
    return out


@njit(cache=True, nogil=True)
def _gradient(f: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``np.gradient(f, x)`` of 1-D ``f`` at coordinates ``x`` (at least 2): second-order central
    differences inside (numpy's uniform form when every step of ``x`` is equal), first-order at the ends."""
    n = f.shape[0]
    out = np.empty(n)
    dx = np.empty(n - 1)
    uniform = True
    for i in range(n - 1):
        dx[i] = x[i + 1] - x[i]
        if dx[i] != dx[0]:
            uniform = False
    if uniform:
        for i in range(1, n - 1):
            out[i] = (f[i + 1] - f[i - 1]) / (2.0 * dx[0])
        out[0] = (f[1] - f[0]) / dx[0]
        out[n - 1] = (f[n - 1] - f[n - 2]) / dx[0]
        return out
    for i in range(1, n - 1):
        dx1, dx2 = dx[i - 1], dx[i]
        a = -dx2 / (dx1 * (dx1 + dx2))
        b = (dx2 - dx1) / (dx1 * dx2)
        c = dx1 / (dx2 * (dx1 + dx2))
        out[i] = a * f[i - 1] + b * f[i] + c * f[i + 1]
    out[0] = (f[1] - f[0]) / dx[0]
    out[n - 1] = (f[n - 1] - f[n - 2]) / dx[n - 2]
    return out


@njit(cache=True, nogil=True)
def attitude_fit(departure: np.ndarray, reference: np.ndarray, u: np.ndarray, fy: float, cy: float, max_rad: float) -> tuple[float, float]:
    """(pitch, roll) [rad] off the mount from the sky line's ``departure`` (C,) [rows] from its
    ``reference`` (C,) at column offsets ``u`` (C,) [px]; (0, 0) when fewer than half the columns
    support it, or the estimate exceeds ``max_rad``. The least squares of
    terrapref.features.attitude's module docstring, twice (the second time without the columns
    that miss the first fit by more than 3 rows), with exactly rounded sums (:func:`exact_sum`);
    tests/test_offset_kernels.py keeps its NumPy form and compares."""
    n = departure.shape[0]
    if n < 2:  # no slope to read along a single column
        return 0.0, 0.0
    ok = np.empty(n, np.bool_)
    good = 0
    for i in range(n):
        ok[i] = np.isfinite(departure[i]) and np.isfinite(reference[i])
        good += ok[i]
    if good < n // 2:
        return 0.0, 0.0
    xp, fp = np.empty(good), np.empty(good)
    g = 0
    for i in range(n):
        if ok[i]:
            xp[g], fp[g] = u[i], reference[i]
            g += 1
    filled = np.empty(n)
    for i in range(n):
        filled[i] = reference[i] if ok[i] else _interp(u[i], xp, fp)
    slope = _gradient(filled, u)
    d0, d1 = np.empty(n), np.empty(n)
    for i in range(n):
        y = (reference[i] + 0.5 - cy) / fy
        d0[i] = -fy * (1.0 + y * y)
        d1[i] = -u[i] - slope[i] * (reference[i] + 0.5 - cy)
    keep = ok.copy()
    dp = dr = 0.0
    pp, pq, qq, pr, qr = np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    for _ in range(2):
        m = 0
        for i in range(n):
            if keep[i]:
                pp[m], pq[m], qq[m] = d0[i] * d0[i], d0[i] * d1[i], d1[i] * d1[i]
                pr[m], qr[m] = d0[i] * departure[i], d1[i] * departure[i]
                m += 1
        if m < n // 2:
            return 0.0, 0.0
        spp, spq, sqq = exact_sum(pp[:m]), exact_sum(pq[:m]), exact_sum(qq[:m])
        spr, sqr = exact_sum(pr[:m]), exact_sum(qr[:m])
        det = spp * sqq - spq * spq
        if not det > 1e-12 * max(spp * sqq, 1e-300):
            dp, dr = 0.0, 0.0
        else:
            dp, dr = (sqq * spr - spq * sqr) / det, (spp * sqr - spq * spr) / det
        for i in range(n):
            keep[i] = ok[i] and abs(d0[i] * dp + d1[i] * dr - (departure[i] if ok[i] else 0.0)) <= 3.0
    if not (abs(dp) <= max_rad and abs(dr) <= max_rad):
        return 0.0, 0.0
    return dp, dr


@njit(cache=True, nogil=True)
def corridor_features(col: np.ndarray, centre: int, k: int, gap: int, beyond: int, step: float, stations: np.ndarray,
                      offsets: np.ndarray, span: float) -> tuple[np.ndarray, float]:
    """The corridor's features (O, K + 2) and the distance to the first terrain on the path [m]
    (inf: none), from the terrain column (O, S, F) under every footprint point.

    As terrapref.features.corridor's module docstring says, and as the NumPy form that
    tests/test_offset_kernels.py keeps computes it: the first patch on the path (row ``centre``; gaps of at most ``gap`` stations do not split
    it) and ``beyond`` stations after it are counted, metres per column (count * step / F), the
    never-seen column, and the detour's price ``offset^2 * (on-path metres + span)``.
    """
    n_off, n_st, n_f = col.shape
    first, last = -1, -1
    for q in range(n_st):
        on = False
        for f in range(n_f):
            if col[centre, q, f] < k:
                on = True
                break
        if not on:
            continue
        if first < 0:
            first = last = q
        elif q - last > gap:
            break
        else:
            last = q
    upto, on_path_m, near_m = n_st, 0.0, np.inf
    if first >= 0:
        upto = min(n_st, last + 1 + beyond)
        on_path_m = (last - first + 1) * step
        near_m = stations[first]
    scale = step / n_f
    out = np.empty((n_off, k + 2))
    counts = np.zeros(k + 2, np.int64)
    for o in range(n_off):
        counts[:] = 0
        for q in range(upto):
            for f in range(n_f):
                counts[col[o, q, f]] += 1
        for v in range(k):
            out[o, v] = counts[v] * scale
        out[o, k] = counts[k + 1] * scale
        out[o, k + 1] = offsets[o] * offsets[o] * (on_path_m + span)
    return out, near_m


@njit(cache=True, nogil=True)
def gated_value(features: np.ndarray, offsets: np.ndarray, gate: bool, weights: np.ndarray) -> np.ndarray:
    """Each offset's utility (O,): its features (O, K + 2), then the gate column (``offset^2`` while
    ``gate``, else 0), times ``weights`` (K + 3,), summed column by column in order. The NumPy form:
    ``terrapref.features.corridor.gated``, then the weighted sum column by column
    (tests/test_offset_kernels.py keeps it)."""
    n_off, n_feat = features.shape
    g = 1.0 if gate else 0.0
    out = np.empty(n_off)
    for o in range(n_off):
        value = features[o, 0] * weights[0]
        for j in range(1, n_feat):
            value = value + features[o, j] * weights[j]
        out[o] = value + offsets[o] * offsets[o] * g * weights[n_feat]
    return out

