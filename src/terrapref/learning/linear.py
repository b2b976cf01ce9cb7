"""The linear utility model: one weight per utility, a bias per trajectory, softmax over the set.

It scores trajectory i with ``w . U_i + b_i``: the multi-criteria decision function with learned
weights. Fitted by full-batch Adam on the cross entropy, with :mod:`terrapref.learning.exact`'s
arithmetic (the same bits on every CPU), each fit one compiled loop over its steps (Numba,
without fast-math; tests/learning/test_linear.py holds the NumPy form and compares the bits). Used three ways: to check that demonstrations identify the preference
(the weights come out in the profile's order), as a baseline planner, and to initialise C's
row-wise compression so that training starts from a utility that already ranks the terrain.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from terrapref.learning import exact


@dataclass(frozen=True)
class LinearUtility:
    """Fitted weights: ``w`` (K + 1,) over the utility columns, ``b`` (m,) per trajectory."""

    w: np.ndarray
    b: np.ndarray

    def logits(self, U: np.ndarray) -> np.ndarray:
        return U @ self.w + self.b


def fit_linear_utility(
    U: np.ndarray, labels: np.ndarray, steps: int = 1500, lr: float = 0.05, sample_weight: np.ndarray | None = None
) -> LinearUtility:
    """Maximum-likelihood fit of the linear utility model to (U (N, m, K + 1), labels (N,)).

    The arithmetic is :mod:`terrapref.learning.exact`'s, so the fit is the same on every CPU.
    """
    U = np.asarray(U, dtype=np.float64)
    n, m, k = U.shape
    rows = exact.rounded(U.reshape(n * m, k), 18)  # constant: rounded once, 18 bits leave room for sums of 2 ** 17
    sw = np.ones(n) if sample_weight is None else np.asarray(sample_weight, dtype=np.float64)
    sw = sw / exact.fsum(sw)
    columns = np.ascontiguousarray(rows.ints.T, dtype=np.float32)  # exact: integers of at most 18 bits
    params = _fit_frames(columns, rows.unit, rows.bits, np.asarray(labels, dtype=np.int64), sw, m, steps, lr)
    return LinearUtility(params[:k].copy(), params[k:].copy())


@njit(cache=True, nogil=True)
def _fit_frames(rows: np.ndarray, unit: float, bits: int, labels: np.ndarray, sw: np.ndarray, m: int, steps: int, lr: float) -> np.ndarray:
    """The frame-by-frame fit's full-batch Adam, compiled: ``params`` (K + 1 + m,) = w, then b.

    ``rows`` holds the rounded utilities by columns, (K + 1, N m) (integers of at most 18 bits,
    exact in float32). Per step, the NumPy form (the exact products as :func:`exact.matmul`
    rounds and sums them)::

        logits = matmul(rows.T, params[:k, None]).reshape(n, m) + params[k:]
        p = exp(logits - logits.max(axis=1, keepdims=True)); p /= row_sum(p)[:, None]
        p[arange(n), labels] -= 1.0; g = p * sw[:, None]
        grad = concatenate([matmul(g.reshape(1, n m), rows.T)[0], matmul(ones((1, n)), g)[0]])
        power1, power2 = power1 * 0.9, power2 * 0.999
        mom = 0.9 mom + 0.1 grad; vel = 0.999 vel + 0.001 (grad grad)
        params -= lr (mom / (1 - power1)) / (sqrt(vel / (1 - power2)) + 1e-8)

    g is made a block of frames at a time (the block's arrays stay in the cache and its loops
    are vectorised), then rounded and summed into both products in one more pass.
    """
    k, nm = rows.shape
    params, mom, vel = np.zeros(k + m), np.zeros(k + m), np.zeros(k + m)
    power1 = power2 = 1.0
    w_bits = min(26, exact.chunk_bits(k) - bits)
    w_ints, g, grad = np.empty(k), np.empty(nm), np.empty(k + m)
    for _ in range(steps):
        u = exact.round_into(params[:k], w_bits, w_ints) * unit
        _frame_gradients(rows, w_ints, u, params[k:], labels, sw, m, g)
        _fit_products(g, rows, unit, bits, m, grad)
        power1, power2 = power1 * 0.9, power2 * 0.999
        _adam_step(params, mom, vel, grad, lr, power1, power2)
    return params


_BLOCK_FRAMES = 64  # frames whose arrays a step works on together (64 x 21 x 8 bytes per array)


@njit(cache=True, nogil=True)
def _frame_gradients(
    rows: np.ndarray, w_ints: np.ndarray, u: float, b: np.ndarray, labels: np.ndarray, sw: np.ndarray, m: int, g: np.ndarray
) -> None:
    """g (N m,): ``softmax(rows.T @ w_ints * u + b by frames) - onehot(labels)``, times each frame's
    weight (see :func:`_fit_frames`); the products of integers are exact, so summed in any order."""
    k, n = rows.shape[0], rows.shape[1] // m
    size = _BLOCK_FRAMES * m
    z, e = np.empty(size), np.empty(size)
    for f0 in range(0, n, _BLOCK_FRAMES):
        f1 = min(n, f0 + _BLOCK_FRAMES)
        r0, length = f0 * m, (f1 - f0) * m
        block = z[:length]
        block[:] = 0.0
        for c in range(k):
            wc = w_ints[c]
            column = rows[c, r0 : r0 + length]  # a 1-D view: the loop vectorises (2-D indexing kept it scalar)
            for t in range(length):
                block[t] += np.float64(column[t]) * wc
        for f in range(f1 - f0):
            base = f * m
            for j in range(m):
                z[base + j] = z[base + j] * u + b[j]
            top = z[base]
            for j in range(1, m):
                if z[base + j] > top or z[base + j] != z[base + j]:
                    top = z[base + j]
            for j in range(m):
                e[base + j] = z[base + j] - top
        for t in range(length):
            e[t] = exact.exp1(e[t])
        for f in range(f1 - f0):
            base = f * m
            total = e[base]
            for j in range(1, m):
                total = total + e[base + j]
            weight = sw[f0 + f]
            for j in range(m):
                p = e[base + j] / total
                if j == labels[f0 + f]:
                    p -= 1.0
                g[r0 + base + j] = p * weight


@njit(cache=True, nogil=True)
def _fit_products(g: np.ndarray, rows: np.ndarray, unit: float, bits: int, m: int, grad: np.ndarray) -> None:
    """``grad`` (K + 1 + m,) = ``matmul(g[None], Rounded(rows.T, unit, bits))[0]`` then
    ``matmul(ones((1, N)), g.reshape(N, m))[0]``, as :func:`exact.matmul` rounds and sums them."""
    k = rows.shape[0]
    exact.vec_mat_rounded(g, rows, unit, bits, grad[:k])
    exact.vec_mat(np.ones(g.shape[0] // m), g, m, grad[k:])


@njit(cache=True, nogil=True)
def _exact_scores(columns: np.ndarray, w_ints: np.ndarray, out: np.ndarray) -> None:
    """``out[r] = sum_c columns[c, r] * w_ints[c]``, every sum exact (integers on their grids)."""
    out[:] = 0.0
    for c in range(columns.shape[0]):
        wc = w_ints[c]
        column = columns[c]  # a 1-D view: the loop vectorises
        for r in range(column.shape[0]):
            out[r] += column[r] * wc


@njit(cache=True, nogil=True)
def _softmax_minus_label(z: np.ndarray, labels: np.ndarray, m: int) -> np.ndarray:
    """Per row of ``z`` (n m,): ``p = exp(z - max); p /= row_sum(p); p[label] -= 1`` (flat, n m)."""
    n = z.shape[0] // m
    shifted = np.empty_like(z)
    for i in range(n):
        top = z[i * m]
        for j in range(1, m):
            v = z[i * m + j]
            if v > top or v != v:
                top = v
        for j in range(m):
            shifted[i * m + j] = z[i * m + j] - top
    p = exact.exp_flat(shifted)
    for i in range(n):
        total = p[i * m]
        for j in range(1, m):
            total = total + p[i * m + j]
        for j in range(m):
            p[i * m + j] = p[i * m + j] / total
        p[i * m + labels[i]] -= 1.0
    return p


@njit(cache=True, nogil=True)
def _adam_step(params: np.ndarray, mom: np.ndarray, vel: np.ndarray, grad: np.ndarray, lr: float, power1: float, power2: float) -> None:
    """The fits' Adam update in place (betas 0.9 and 0.999, eps 1e-8), element by element."""
    for q in range(params.shape[0]):
        mom[q] = 0.9 * mom[q] + 0.1 * grad[q]
        vel[q] = 0.999 * vel[q] + 0.001 * (grad[q] * grad[q])
        params[q] -= lr * (mom[q] / (1 - power1)) / (np.sqrt(vel[q] / (1 - power2)) + 1e-8)


@dataclass(frozen=True)
class LookaheadFit:
    """The linear utility fitted through the look-ahead, and the weight its value got in the fit."""

    utility: LinearUtility
    gamma: float


def fit_lookahead_utility(
    U: np.ndarray, U2: np.ndarray, labels: np.ndarray, steps: int = 300, lr: float = 0.05, start: LinearUtility | None = None
) -> LookaheadFit:
    """Fit the linear utility through the planner's look-ahead (SPEC 8's loss over a planning rule).

    Trajectory i scores ``f(U_i) + gamma * max_j f(U2_ij)`` with ``f(u) = w . u + b``: its own
    utility plus the best of the second pieces that continue it (terrapref.rules.second.lookahead);
    a softmax over i is fitted to the demonstrated labels by full-batch Adam, ``w``, ``b`` and
    ``gamma`` together, from ``start`` (default: the frame-wise fit) and gamma = 1.

    A frame-wise fit sees only "this trajectory, not that one". Through the look-ahead, a lone
    patch that a short swerve clears and a pair of wide patches that no swerve clears become
    different situations for the same w, so the weights say how much each class costs against
    grass, not only against each other.

    Args:
        U: (N, m, K + 1) the trajectories' utility features (terrain shares, distance).
        U2: (N, m, m, K + 1) look-ahead utilities of the same frames.
        labels: (N,) demonstrated trajectory indices.
    """
    U = np.asarray(U, dtype=np.float64)
    n, m, k = U.shape
    if U2.shape != (n, m, m, k):
        raise ValueError(f"U2 must have shape {(n, m, m, k)}, got {U2.shape}")
    start = start or fit_linear_utility(U, labels)
    first = exact.rounded(U.reshape(n * m, k), 18)
    # U2 rounded as exact.rounded(U2, 18) would, held as int32 columns (k, N m m): what each step reads.
    second = np.asarray(U2, dtype=np.float32).reshape(n * m * m, k)
    second_unit, second_ints = _round_columns(second, 18)
    distinct, which = _distinct_columns(second_ints)
    del second, second_ints
    params = np.concatenate([start.w, start.b, [1.0]])
    params = _fit_through(
        np.ascontiguousarray(first.ints.T),
        first.unit,
        distinct,
        which,
        second_unit,
        18,
        np.asarray(labels, dtype=np.int64),
        params,
        m,
        steps,
        lr,
    )
    return LookaheadFit(LinearUtility(params[:k].copy(), params[k : k + m].copy()), float(params[-1]))


def _round_columns(x: np.ndarray, bits: int) -> tuple[float, np.ndarray]:
    """``exact.rounded(x, bits)`` of an (R, k) float32 array, its integers transposed to (k, R) int32."""
    top = max(float(x.max()), -float(x.min())) if x.size else 0.0
    _, e = math.frexp(top)
    return math.ldexp(1.0, e - bits), _scaled_rint_columns(x, math.ldexp(1.0, bits - e))


@njit(cache=True, nogil=True)
def _scaled_rint_columns(x: np.ndarray, scale: float) -> np.ndarray:
    """``np.rint(x.astype(float64) * scale).T`` as int32 (|values| <= 2 ** 26)."""
    out = np.empty((x.shape[1], x.shape[0]), np.int32)
    for i in range(x.shape[0]):
        for c in range(x.shape[1]):
            out[c, i] = np.int32(np.rint(np.float64(x[i, c]) * scale))
    return out


@njit(cache=True, nogil=True)
def _distinct_columns(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct columns of ``x`` (k, R) int32, in the order they first appear, and the index
    of each column among them: ``x == distinct[:, which]``.

    The look-ahead's utilities repeat a lot (most second pieces see the same few shares), so the
    fit scores each distinct column once a step and reads the scores by index.
    """
    k, n = x.shape
    if n >= 2**30:
        raise ValueError("_distinct_columns indexes columns with 32-bit integers: at most 2 ** 30 columns")
    size = 1
    while size < 2 * n:
        size *= 2
    slots = np.full(size, -1, np.int32)  # open addressing: the distinct index held by each slot
    which = np.empty(n, np.int32)
    firsts = np.empty(n, np.int64)  # the column where each distinct one first appears
    count = 0
    for r in range(n):
        h = np.uint64(0)
        for c in range(k):  # the column's values, each added and mixed by a multiply and a shift
            h = (h + np.uint64(np.uint32(x[c, r])) + np.uint64(0x9E3779B97F4A7C15)) * np.uint64(0xBF58476D1CE4E5B9)
            h ^= h >> np.uint64(31)
        slot = np.int64(h & np.uint64(size - 1))
        while True:
            u = slots[slot]
            if u < 0:
                slots[slot] = count
                firsts[count] = r
                which[r] = count
                count += 1
                break
            f = firsts[u]
            same = True
            for c in range(k):
                if x[c, f] != x[c, r]:
                    same = False
                    break
            if same:
                which[r] = u
                break
            slot = (slot + 1) & (size - 1)
    distinct = np.empty((k, count), np.int32)
    for u in range(count):
        for c in range(k):
            distinct[c, u] = x[c, firsts[u]]
    return distinct, which


@njit(cache=True, nogil=True, inline="always")
def _add_times(out: np.ndarray, start: int, factor: float, v: np.ndarray) -> None:
    """``out[start + i] = out[start + i] + factor * v[i]`` for every i."""
    for i in range(v.shape[0]):
        out[start + i] = out[start + i] + factor * v[i]


@njit(cache=True, nogil=True)
def _with_continuations(z: np.ndarray, u1: float, b: np.ndarray, gamma: float, value: np.ndarray) -> None:
    """First pieces' logits in place: each (N m) exact score ``z`` times its unit ``u1``, plus its
    trajectory's bias ``b`` (m,), plus ``gamma`` times the value of its best continuation."""
    m = b.shape[0]
    for i in range(z.shape[0] // m):
        for j in range(m):
            r = i * m + j
            z[r] = (z[r] * u1 + b[j]) + gamma * value[r]


@njit(cache=True, nogil=True)
def _per_frame(d: np.ndarray, n: int, best: np.ndarray, counts: np.ndarray) -> None:
    """The softmax's residuals ``d`` (N m) divided by the frames ``n``, in place, and summed by the
    trajectory of each piece's best continuation into ``counts`` (m,)."""
    counts[:] = 0.0
    for r in range(d.shape[0]):
        d[r] = d[r] / n
        counts[best[r]] += d[r]


@njit(cache=True, nogil=True)
def _gather_rows(by_rows: np.ndarray, rows: np.ndarray, out: np.ndarray) -> None:
    """``out[:, r] = by_rows[rows[r]]`` for every piece r: the utilities of each best continuation, by columns."""
    for r in range(rows.shape[0]):
        u = rows[r]
        for c in range(out.shape[0]):
            out[c, r] = by_rows[u, c]


@njit(cache=True, nogil=True)
def _fit_through(
    first: np.ndarray,
    first_unit: float,
    distinct: np.ndarray,
    which: np.ndarray,
    second_unit: float,
    bits: int,
    labels: np.ndarray,
    params: np.ndarray,
    m: int,
    steps: int,
    lr: float,
) -> np.ndarray:
    """The fit through the look-ahead, compiled: ``params`` (K + 1 + m + 1,) = w, b, gamma.

    ``first`` holds the rounded utilities (N m) by columns, (K + 1, N m); the rounded look-ahead
    utilities (N m m) are ``second = distinct[:, which]`` (:func:`_distinct_columns`). Each
    product of integers is exact, so a distinct column's score is the score of each column equal
    to it. Per step, the NumPy form (the exact products as :func:`exact.matmul` rounds and sums
    them)::

        f2 = matmul(second.T, w[:, None]).reshape(n m, m) + b
        best = argmax(f2, axis=1); value = f2[arange(n m), best].reshape(n, m)
        z = matmul(first.T, w[:, None]).reshape(n, m) + b + gamma * value
        p = softmax of z by rows; p[arange(n), labels] -= 1.0; d = p / n
        chosen = second.T[arange(n m) * m + best]
        grad_w = matmul(d.reshape(1, n m), first.T)[0] + gamma * matmul(d.reshape(1, n m), chosen)[0]
        grad_b = matmul(ones((1, n)), d)[0] + gamma * bincount(best, weights=d.ravel(), minlength=m)
        grad = concatenate([grad_w, grad_b, matmul(d.reshape(1, n m), value.reshape(n m, 1))[0]])
        then Adam as in _fit_frames
    """
    k, nm, n = first.shape[0], first.shape[1], first.shape[1] // m
    params = params.copy()
    mom, vel, power1, power2 = np.zeros_like(params), np.zeros_like(params), 1.0, 1.0
    w_bits = min(26, exact.chunk_bits(k) - bits)
    w_ints, grad, ones, scores = np.empty(k), np.empty(params.shape[0]), np.ones(n), np.empty(distinct.shape[1])
    best, value, z = np.empty(nm, np.int64), np.empty(nm), np.empty(nm)
    chosen, spare, counts = np.empty((k, nm)), np.empty(k), np.empty(m)
    by_rows = np.ascontiguousarray(distinct.T)  # a chosen column's k values in one cache line
    best_row = np.empty(nm, np.int32)  # the distinct row of each first piece's best continuation
    for _ in range(steps):
        gamma = params[-1]
        w_unit = exact.round_into(params[:k], w_bits, w_ints)
        _exact_scores(distinct, w_ints, scores)
        _best_continuations(scores, which, second_unit * w_unit, params[k : k + m], best, value, best_row)
        _exact_scores(first, w_ints, z)
        _with_continuations(z, first_unit * w_unit, params[k : k + m], gamma, value)
        d = _softmax_minus_label(z, labels, m)
        _per_frame(d, n, best, counts)
        _gather_rows(by_rows, best_row, chosen)
        exact.vec_mat_rounded(d, first, first_unit, bits, grad[:k])
        exact.vec_mat_rounded(d, chosen, second_unit, bits, spare)
        exact.vec_mat(ones, d, m, grad[k : k + m])
        exact.vec_mat(d, value, 1, grad[k + m :])
        _add_times(grad, 0, gamma, spare)
        _add_times(grad, k, gamma, counts)
        power1, power2 = power1 * 0.9, power2 * 0.999
        _adam_step(params, mom, vel, grad, lr, power1, power2)
    return params


@njit(cache=True, nogil=True)
def _best_continuations(
    scores: np.ndarray, which: np.ndarray, unit: float, b: np.ndarray, best: np.ndarray, value: np.ndarray, best_row: np.ndarray
) -> None:
    """For each row r of (N m) first pieces: the first argmax over j of ``f2 = scores[which[r m +
    j]] unit + b[j]`` into ``best[r]``, its score into ``value[r]`` and its distinct row
    ``which[r m + best[r]]`` into ``best_row[r]`` (NumPy's argmax: the first of equal maxima, the
    first NaN if any)."""
    m = b.shape[0]
    finite = math.isfinite(unit)
    for j in range(m):
        finite = finite and math.isfinite(b[j])
    for u in range(scores.shape[0]):
        finite = finite and math.isfinite(scores[u])
    if finite:  # no NaN can arise: a plain running maximum
        for r in range(best.shape[0]):
            base = r * m
            top, top_f = 0, scores[which[base]] * unit + b[0]
            for j in range(1, m):
                f = scores[which[base + j]] * unit + b[j]
                if f > top_f:
                    top, top_f = j, f
            best[r], value[r], best_row[r] = top, top_f, which[base + top]
        return
    f2 = np.empty(m)
    for r in range(best.shape[0]):
        base = r * m
        top = 0
        for j in range(m):
            f2[j] = scores[which[base + j]] * unit + b[j]
            if j > 0 and (f2[j] > f2[top] or (f2[j] != f2[j] and f2[top] == f2[top])):
                top = j
        best[r], value[r], best_row[r] = top, f2[top], which[base + top]
