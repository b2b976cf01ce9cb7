"""The ground map's votes and reads, compiled (Numba) (terrapref.groundmap.map): the
samples of a frame voting in their cells, a cell's column decided from its evidence, and the
map read at world points or beside the path.

The map's samples are a loop, not a vector. Each loop does, element by element, exactly the IEEE 754 operations of the NumPy form its
docstring gives, in the same order (compiled without fast-math: nothing is reassociated or
fused into a multiply-add), so the results, and every decision made from them, are the same
bits as the NumPy forms give.
(tests/rules/test_offset_kernels.py compares.)
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

UNSETTLED = 255  # a ground-map cell voted on since its column was last decided (columns run 0..K + 1)


class MapLayers(NamedTuple):
    """The ground map as a compiled read takes it (terrapref.groundmap.map.GroundMap.layers).

    Attributes:
        cells: each cell's column (rows y, columns x) (n, n) uint8, :data:`UNSETTLED` where voted
            on since it was last decided (:func:`map_decide` decides it when it is read).
        evidence: each cell's evidence per column (n, n, K + 1) float32.
        lethal: which columns are lethal (K + 2,) bool.
        shares: the lethal share, the terrain share and the least evidence that decide a column (3,) float32.
        ox, oy: the map's corner in the world [m].
        inv_res: cells per metre.
    """

    cells: np.ndarray
    evidence: np.ndarray
    lethal: np.ndarray
    shares: np.ndarray
    ox: float
    oy: float
    inv_res: float


@njit(cache=True, nogil=True)
def map_vote(
    evidence: np.ndarray,
    stamp: np.ndarray,
    cells: np.ndarray,
    ox: float,
    oy: float,
    inv_res: float,
    x: float,
    y: float,
    c: float,
    s: float,
    vx: np.ndarray,
    vy: np.ndarray,
    weight: np.ndarray,
    ids: np.ndarray,
    pixel_of: np.ndarray,
    columns: np.ndarray,
    frame: int,
    fade: np.ndarray,
    tilted: bool,
    ray: np.ndarray,
    ground0: np.ndarray,
    axes: np.ndarray,
    t: np.ndarray,
) -> None:
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
    ``terrapref.groundmap.map._ground``.
    """
    # First every sample's cell, in a loop without stores to the map, then the votes.
    n_rows, n_cols = cells.shape
    column_of = columns[ids[pixel_of]]  # each sample's column
    cell = _sample_cells(
        n_rows, n_cols, x - ox, y - oy, inv_res, c, s, vx, vy, column_of, evidence.shape[2] - 1, tilted, ray, ground0, axes, t
    )
    map_vote_cells(evidence, stamp, cells, cell, column_of, weight, frame, fade)


@njit(cache=True, nogil=True)
def map_vote_cells(
    evidence: np.ndarray,
    stamp: np.ndarray,
    cells: np.ndarray,
    cell: np.ndarray,
    column_of: np.ndarray,
    weight: np.ndarray,
    frame: int,
    fade: np.ndarray,
) -> None:
    """Each sample's vote (``column_of``, ``weight``) added to the evidence of its ``cell`` (flat
    index; -1: none), faded first, the cell marked :data:`UNSETTLED`; :func:`map_vote` says how.
    On relief, where a sample votes at its pixel's depth return, the samples are the distinct
    pixels, each weighing its samples' weights together (terrapref.groundmap.map). The map is read
    through flat views (2-D indexing cost the loop a fifth)."""
    k = evidence.shape[2] - 1
    votes, stamps, columns_of = evidence.reshape(-1), stamp.reshape(-1), cells.reshape(-1)
    for p in range(cell.shape[0]):
        here = cell[p]
        if here < 0:
            continue
        col = column_of[p]
        gap = frame - stamps[here]
        at = here * (k + 1)
        if gap != 0:
            f = fade[min(gap, fade.shape[0] - 1)]
            for q in range(k + 1):
                votes[at + q] *= f
            stamps[here] = frame
        votes[at + col] += weight[p]
        columns_of[here] = UNSETTLED


@njit(cache=True, nogil=True)
def _sample_cells(
    n_rows: int,
    n_cols: int,
    ex: float,
    ey: float,
    inv_res: float,
    c: float,
    s: float,
    vx: np.ndarray,
    vy: np.ndarray,
    column_of: np.ndarray,
    k: int,
    tilted: bool,
    ray: np.ndarray,
    ground0: np.ndarray,
    axes: np.ndarray,
    t: np.ndarray,
) -> np.ndarray:
    """Each sample's cell of the map (j * n_cols + i; -1: no vote), the vehicle at (``ex``, ``ey``)
    from the map's corner [m]; :func:`map_vote` says how."""
    n = vx.shape[0]
    cell = np.empty(n, np.int64)
    # The tilted camera's axes and centre in locals: read once, not again after every store.
    a00, a01, a02, a10, a11, a12 = axes[0, 0], axes[0, 1], axes[0, 2], axes[1, 0], axes[1, 1], axes[1, 2]
    a20, a21, a22, t0, t1, t2 = axes[2, 0], axes[2, 1], axes[2, 2], t[0], t[1], t[2]
    for p in range(n):
        cell[p] = -1
        if column_of[p] > k:
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
        i = math.floor((ex + px * c - py * s) * inv_res)
        j = math.floor((ey + px * s + py * c) * inv_res)
        if 0 <= i < n_cols and 0 <= j < n_rows:
            cell[p] = j * n_cols + i
    return cell


@njit(cache=True, nogil=True, inline="always")
def map_decide(
    evidence: np.ndarray, lethal: np.ndarray, lethal_share: np.float32, terrain_share: np.float32, min_evidence: np.float32, j: int, i: int
) -> int:
    """The column of ground-map cell ``(j, i)``, decided from its evidence.

    The map's readers read a cell as ``col = cells[j, i]``, and if ``col == UNSETTLED`` (voted on
    since it was last decided) as ``col = cells[j, i] = map_decide(...)``. A cell's column depends
    only on its evidence, which changes only when it is voted on, so deciding it when it is read
    gives the column that deciding it after every vote would; a frame reads a few thousand of the
    fifteen thousand cells it votes on. (The test stays in each reader's loop, and the shares come
    as numbers: each array a compiled helper takes costs every call more than the decision.)

    The column: K + 1 (never seen) while the evidence totals less than ``min_evidence``, lethal
    or not (a far glimpse of a lethal class, which a network's errors give, waits for the views
    that confirm or outvote it, as the rest does); else the lethal column (``lethal``, by column)
    with the most evidence when the lethal columns hold at least ``lethal_share`` of it; else the
    other terrain column with the most when those columns hold at least ``terrain_share``; else
    K. Ties go to the lowest column; float32 sums in column order, so every CPU agrees.

    Compiled into its callers, here and in terrapref.rules.offset.reach_compiled (see
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
def map_read(layers: MapLayers, px: np.ndarray, py: np.ndarray, never: int) -> np.ndarray:
    """The ground map's column at each point (flat arrays ``px``, ``py``); ``never`` outside it.

    The NumPy form: ``cells[floor((py - oy) * inv_res), floor((px - ox) * inv_res)]`` where
    inside, each cell decided first if it is :data:`UNSETTLED` (:func:`map_decide`, with
    ``evidence``, ``lethal`` and the three ``shares``).
    """
    cells, evidence, lethal, shares, ox, oy, inv_res = layers
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
def map_read_split(layers: MapLayers, px: np.ndarray, py: np.ndarray, never: int, lead: np.float32, second: np.float32) -> np.ndarray:
    """:func:`map_read`, where a cell split between two terrain classes reads as ``never``: its
    column a terrain column that is not lethal and holds less than ``lead`` of the cell's evidence,
    while another such column holds at least ``second`` of it.

    The NumPy form: ``col = map_read(...)``; where ``col < K`` and not lethal, with ``e`` the
    cell's evidence and ``total`` its float32 sum (column K first, then 0..K-1), ``never`` if ``e[col] <
    lead * total`` and ``max(e[q] for q < K, q != col, not lethal) >= second * total``.
    """
    cols = map_read(layers, px, py, never)
    _, evidence, lethal, _, ox, oy, inv_res = layers
    k = evidence.shape[2] - 1
    for p in range(px.shape[0]):
        col = cols[p]
        if col >= k or lethal[col]:
            continue
        i = math.floor((px[p] - ox) * inv_res)
        j = math.floor((py[p] - oy) * inv_res)
        total = evidence[j, i, k]
        other = np.float32(-1.0)  # no other terrain column: not split
        for q in range(k):
            e = evidence[j, i, q]
            total += e
            if q != col and not lethal[q] and e > other:
                other = e
        if evidence[j, i, col] < lead * total and other >= second * total:
            cols[p] = never
    return cols


@njit(cache=True, nogil=True)
def path_frame(
    path_s: np.ndarray, path_a: np.ndarray, path_d: np.ndarray, path_len: np.ndarray, s: float
) -> tuple[float, float, float, float]:
    """(x, y, ux, uy): the point at arc length ``s`` (clamped to the path) and the unit direction
    there, as ``ReferencePath.frame_at`` gives them (segments: ``path.segments``).

    Compiled into its callers, here and in terrapref.rules.offset.reach_compiled, whose cached copies
    Numba does not recompile when only this file changes: after editing it, delete the
    ``__pycache__`` folders' ``*.nbi``/``*.nbc`` files (``scripts/setup.sh`` does when a module with
    compiled loops changed; ``python -m terrapref.warm_up`` rebuilds them)."""
    n_seg = path_len.shape[0]
    s = min(max(s, 0.0), path_s[-1])
    i = min(max(np.searchsorted(path_s, s, side="right") - 1, 0), n_seg - 1)
    f = (s - path_s[i]) / path_len[i]
    return (path_a[i, 0] + f * path_d[i, 0], path_a[i, 1] + f * path_d[i, 1], path_d[i, 0] / path_len[i], path_d[i, 1] / path_len[i])


@njit(cache=True, nogil=True)
def map_read_beside(
    layers: MapLayers,
    path_s: np.ndarray,
    path_a: np.ndarray,
    path_d: np.ndarray,
    path_len: np.ndarray,
    s: np.ndarray,
    lat: np.ndarray,
    never: int,
) -> np.ndarray:
    """The ground map's column (O, S, F) at the points ``lat[o, f]`` [m] left of the path at arc
    lengths ``s`` (S,), ``never`` outside the map.

    The NumPy form: :func:`map_read` of ``centre[None, :, None, :] + lat[:, None, :, None] *
    normal[None, :, None, :]``, ``centre = path.point_at(s)``, ``normal`` the path's direction
    there turned left.
    """
    cells, evidence, lethal, shares, ox, oy, inv_res = layers
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
