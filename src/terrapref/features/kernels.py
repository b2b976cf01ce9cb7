"""The utility features' per-frame arithmetic, compiled (Numba) for the planner's control loop.

On one frame the features are a few hundred pixels and a few dozen distances: NumPy's call
overhead, not its arithmetic, set their cost. Each loop here does, element by element, exactly
the IEEE 754 operations of the NumPy form its docstring gives, in the same order (compiled
without fast-math: nothing is reassociated or fused into a multiply-add), so the features, and
every decision made from them, are the same bits as before (tests/test_features.py compares).
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
def numpy_sum(a: np.ndarray) -> float:
    """``a.sum()`` of a 1-D float64 array as NumPy adds it: from 0, in eight interleaved partial
    sums added pairwise, then the last ``n % 8`` terms in order (its pairwise summation for
    n <= 128; longer arrays are not summed here)."""
    n = a.shape[0]
    if n > 128:
        raise ValueError("numpy_sum follows NumPy's summation order for at most 128 terms")
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[i]
        return 0.0 + res
    r0, r1, r2, r3, r4, r5, r6, r7 = a[0], a[1], a[2], a[3], a[4], a[5], a[6], a[7]
    i = 8
    while i < n - n % 8:
        r0 += a[i]
        r1 += a[i + 1]
        r2 += a[i + 2]
        r3 += a[i + 3]
        r4 += a[i + 4]
        r5 += a[i + 5]
        r6 += a[i + 6]
        r7 += a[i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[i]
        i += 1
    return 0.0 + res


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
def map_write(cells: np.ndarray, ox: float, oy: float, inv_res: float, x: float, y: float, c: float, s: float,
              vx: np.ndarray, vy: np.ndarray, cols: np.ndarray) -> None:
    """Write each ground sample's column into the ground map's cells (rows y, columns x), in order.

    The NumPy form: ``i = floor((x - ox + vx * c - vy * s) * inv_res)``, ``j = floor((y - oy +
    vx * s + vy * c) * inv_res)``, ``cells[j[ok], i[ok]] = cols[ok]`` for the samples inside.
    """
    n_rows, n_cols = cells.shape
    for p in range(vx.shape[0]):
        i = math.floor((x - ox + vx[p] * c - vy[p] * s) * inv_res)
        j = math.floor((y - oy + vx[p] * s + vy[p] * c) * inv_res)
        if 0 <= i < n_cols and 0 <= j < n_rows:
            cells[j, i] = cols[p]


@njit(cache=True, nogil=True)
def map_vote(evidence: np.ndarray, stamp: np.ndarray, cells: np.ndarray, ox: float, oy: float, inv_res: float, x: float, y: float,
             c: float, s: float, vx: np.ndarray, vy: np.ndarray, weight: np.ndarray, cols: np.ndarray, frame: int, fade: np.ndarray,
             lethal: np.ndarray, lethal_share: float, terrain_share: float, min_evidence: float) -> None:
    """Add each ground sample's vote to the evidence of its cell, and set the cell's column.

    A cell's evidence (``evidence[j, i]``, one float32 per column 0..K, K the background) fades by
    ``fade[g]`` when it is next voted on ``g`` frames later (``stamp`` holds the frame of its last
    vote; gaps beyond the table fade by its last entry), then gains the sample's ``weight`` in the
    sample's column. Samples of column K + 1 (nothing seen) cast no vote. The cell's column
    (``cells``): K + 1 (never seen) while its evidence totals less than ``min_evidence``; else the
    lethal column with the most evidence when the lethal columns hold at least ``lethal_share`` of
    it; else the other terrain column with the most when those columns hold at least
    ``terrain_share``; else K. Ties go to the lowest column. Cells are found as in
    :func:`map_write`; float32 sums in a fixed order, so every CPU agrees.
    """
    n_rows, n_cols = cells.shape
    k = evidence.shape[2] - 1
    for p in range(vx.shape[0]):
        col = cols[p]
        if col > k:
            continue
        i = math.floor((x - ox + vx[p] * c - vy[p] * s) * inv_res)
        j = math.floor((y - oy + vx[p] * s + vy[p] * c) * inv_res)
        if not (0 <= i < n_cols and 0 <= j < n_rows):
            continue
        gap = frame - stamp[j, i]
        if gap != 0:
            f = fade[min(gap, fade.shape[0] - 1)]
            for q in range(k + 1):
                evidence[j, i, q] *= f
            stamp[j, i] = frame
        evidence[j, i, col] += weight[p]
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
            cells[j, i] = k + 1
        elif best_lethal >= 0 and deadly >= lethal_share * total:
            cells[j, i] = best_lethal
        elif best_terrain >= 0 and terrain >= terrain_share * total:
            cells[j, i] = best_terrain
        else:
            cells[j, i] = k


@njit(cache=True, nogil=True)
def map_read(cells: np.ndarray, ox: float, oy: float, inv_res: float, px: np.ndarray, py: np.ndarray, never: int) -> np.ndarray:
    """The ground map's column at each point (flat arrays ``px``, ``py``); ``never`` outside it.

    The NumPy form: ``cells[floor((py - oy) * inv_res), floor((px - ox) * inv_res)]`` where inside.
    """
    n_rows, n_cols = cells.shape
    out = np.empty(px.shape[0], np.uint8)
    for p in range(px.shape[0]):
        i = math.floor((px[p] - ox) * inv_res)
        j = math.floor((py[p] - oy) * inv_res)
        out[p] = cells[j, i] if 0 <= i < n_cols and 0 <= j < n_rows else never
    return out


@njit(cache=True, nogil=True)
def map_read_beside(cells: np.ndarray, ox: float, oy: float, inv_res: float, centre: np.ndarray, normal: np.ndarray, lat: np.ndarray,
                    never: int) -> np.ndarray:
    """The ground map's column (O, S, F) at the points ``centre[s] + lat[o, f] * normal[s]``.

    The NumPy form: :func:`map_read` of ``centre[None, :, None, :] + lat[:, None, :, None] * normal[None, :, None, :]``.
    """
    n_rows, n_cols = cells.shape
    n_off, n_st, n_f = lat.shape[0], centre.shape[0], lat.shape[1]
    out = np.empty((n_off, n_st, n_f), np.uint8)
    for o in range(n_off):
        for s in range(n_st):
            for f in range(n_f):
                i = math.floor((centre[s, 0] + lat[o, f] * normal[s, 0] - ox) * inv_res)
                j = math.floor((centre[s, 1] + lat[o, f] * normal[s, 1] - oy) * inv_res)
                out[o, s, f] = cells[j, i] if 0 <= i < n_cols and 0 <= j < n_rows else never
    return out
