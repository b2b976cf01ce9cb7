"""The second stage's scores, compiled (Numba): the look-ahead's distances and each candidate's
best continuation weighed against log F_t (terrapref.rules.second).

Each loop does, element by element, exactly the IEEE 754 operations of the NumPy form its
docstring gives, in the same order (compiled without fast-math: nothing is reassociated or
fused into a multiply-add), so the results, and every decision made from them, are the same
bits as the NumPy forms give.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from terrapref.features.utility_compiled import normalise
from terrapref.sums import numpy_sum


@njit(cache=True, nogil=True)
def stage_scores(
    log_probs: np.ndarray,
    weight: float,
    rows: np.ndarray,
    ids: np.ndarray,
    point_weight: np.ndarray,
    seen: np.ndarray,
    distance: np.ndarray,
    w_distance: float,
    b: np.ndarray,
) -> np.ndarray:
    """The second stage's scores (m,): ``log_probs + weight * value`` for the candidates, where a
    candidate's value is the best of its second pieces' linear utilities; -inf elsewhere.

    The NumPy form (terrapref.rules.second.rule)::

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
def stage_distances(
    rows: np.ndarray,
    ends_x: np.ndarray,
    ends_y: np.ndarray,
    start_x: np.ndarray,
    x_lo: float,
    line: tuple[float, float, float, float],
    targets: np.ndarray,
    c: float,
    s: float,
    x: float,
    y: float,
    eps: float,
) -> np.ndarray:
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
