"""Each candidate offset's features and utility, compiled (Numba) (terrapref.rules.offset.features).

Each loop does, element by element, exactly the IEEE 754 operations of the NumPy form its
docstring gives, in the same order (compiled without fast-math: nothing is reassociated or
fused into a multiply-add), so the results, and every decision made from them, are the same
bits as the NumPy forms give.
(tests/rules/test_offset_kernels.py compares.)
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def offset_features(
    col: np.ndarray,
    steep: np.ndarray,
    centre: int,
    k: int,
    gap: int,
    beyond: int,
    step: float,
    stations: np.ndarray,
    offsets: np.ndarray,
    span: float,
) -> tuple[np.ndarray, float, int]:
    """The offsets' features (O, K + 2), the distance to the first terrain on the path [m]
    (inf: none) and the stations counted, from the terrain column (O, S, F) under every
    footprint point and where the path's own ground is steep (``steep`` (S,), all False on flat
    ground or for a utility that prices no relief).

    As terrapref.rules.offset.features' module docstring says, and as the NumPy form that
    tests/rules/test_offset_kernels.py keeps computes it: the first patch on the path (row
    ``centre``, terrain or steep ground; gaps of at most ``gap`` stations do not split it) and
    ``beyond`` stations after it are counted, metres per column (count * step / F), the
    never-seen column, and the detour's price ``offset^2 * (on-path metres + span)``.
    """
    n_off, n_st, n_f = col.shape
    first, last = -1, -1
    for q in range(n_st):
        on = steep[q]
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
    return out, near_m, upto


@njit(cache=True, nogil=True)
def gated_value(features: np.ndarray, offsets: np.ndarray, gate: bool, weights: np.ndarray) -> np.ndarray:
    """Each offset's utility (O,): its features (O, K + 2), then the gate column (``offset^2`` while
    ``gate``, else 0), times ``weights`` (K + 3,), summed column by column in order. The NumPy form:
    ``terrapref.rules.offset.features.gated``, then the weighted sum column by column
    (tests/rules/test_offset_kernels.py keeps it)."""
    n_off, n_feat = features.shape
    g = 1.0 if gate else 0.0
    out = np.empty(n_off)
    for o in range(n_off):
        value = features[o, 0] * weights[0]
        for j in range(1, n_feat):
            value = value + features[o, j] * weights[j]
        out[o] = value + offsets[o] * offsets[o] * g * weights[n_feat]
    return out


@njit(cache=True, nogil=True)
def relief_metres(attitudes: np.ndarray, upto: int, bands: np.ndarray, step: float) -> np.ndarray:
    """Each offset's relief columns (O, 2 B): over its first ``upto`` stations, the metres (the
    stations counted times ``step``) at which the body's side slope, then its grade
    (``attitudes`` (O, S, 2) [deg]; NaN: unknown, past none), is past each of ``bands`` (B,)
    [deg]. The NumPy form: ``(attitudes[:, :upto, :, None] > bands).sum(axis=1).reshape(O, -1)
    * step`` (terrapref.rules.offset.features)."""
    n_off, n_st, n_bands = attitudes.shape[0], min(upto, attitudes.shape[1]), bands.shape[0]
    counts = np.zeros((n_off, 2 * n_bands), np.int64)
    for o in range(n_off):
        for q in range(n_st):
            for a in range(2):
                value = attitudes[o, q, a]
                for b in range(n_bands):
                    if value > bands[b]:
                        counts[o, a * n_bands + b] += 1
    return counts * step
