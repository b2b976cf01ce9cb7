"""Training C's per-layer arithmetic around the matrix products, compiled (Numba).

A training step of C is about sixty small array operations around a dozen BLAS products; NumPy's
per-call overhead, not the arithmetic, set its cost. Each loop here does, element by element,
exactly the IEEE 754 operations of the NumPy form its docstring gives, in the same order
(compiled without fast-math: nothing is reassociated or fused into a multiply-add), so a trained
model keeps its bits (tests/learning/test_mlp.py keeps the NumPy forms and compares). The products
themselves stay in BLAS on integers (:mod:`terrapref.learning.exact`), exact in any order.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from terrapref.learning import exact


@njit(cache=True, nogil=True)
def compress_forward(x: np.ndarray, x_unit: float, x_bits: int, weight: np.ndarray, bias: np.ndarray) -> np.ndarray:
    """The row-wise compression's output (B m,): ``matmul(Rounded(x, x_unit, x_bits), weight.T)[:, 0] + bias[0]``.

    ``x`` (B m, k) holds the rounded inputs; ``weight`` (1, k) is rounded to what they leave of a
    sum of k exact products (at most 26 bits), relative to its largest entry.
    """
    rows, k = x.shape
    w_ints = np.empty(k)
    unit = x_unit * exact.round_into(weight.reshape(-1), min(26, exact.chunk_bits(k) - x_bits), w_ints)
    out = np.empty(rows)
    b = bias[0]
    for r in range(rows):
        total = 0.0
        for c in range(k):
            total += x[r, c] * w_ints[c]
        out[r] = total * unit + b
    return out


@njit(cache=True, nogil=True)
def affine(
    product: np.ndarray, unit: float, bias: np.ndarray, relu: bool, skip: np.ndarray, next_bits: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """A layer's output from its exact integer product (B, out): ``z = product * unit + bias``
    (``+ skip`` when ``skip`` has rows, the residual path) and, with ``relu``,
    ``h = np.maximum(z, 0.0)`` (z where z > 0 or NaN, else +0.0; without, ``h`` is ``z``); with
    ``next_bits`` > 0 also ``h`` on the grid of the next layer's product
    (``exact.rounded(h, next_bits)``: its integers and unit; else an empty array and 0)."""
    n, p = product.shape
    z = np.empty((n, p))
    h = np.empty((n, p)) if relu else z
    add = skip.shape[0] > 0
    for i in range(n):
        for j in range(p):
            v = product[i, j] * unit + bias[j]
            if add:
                v = v + skip[i, j]
            z[i, j] = v
            if relu:
                h[i, j] = v if (v > 0.0 or v != v) else 0.0
    if next_bits <= 0:
        return z, h, np.empty((0, 0)), 0.0
    ints = np.empty((n, p))
    return z, h, ints, exact.round_into(h.reshape(-1), next_bits, ints.reshape(-1))


@njit(cache=True, nogil=True)
def round_twice(x: np.ndarray, bits_a: int, bits_b: int) -> tuple[np.ndarray, float, np.ndarray, float]:
    """``exact.rounded(x, bits_a)`` and ``exact.rounded(x, bits_b)`` of a C-contiguous array: both
    grids relative to the one largest magnitude, in one pass for it and one for the integers."""
    flat = x.reshape(-1)
    e = math.frexp(exact.largest_magnitude(flat))[1] if flat.shape[0] else 0
    scale_a, scale_b = math.ldexp(1.0, bits_a - e), math.ldexp(1.0, bits_b - e)
    a, b = np.empty(x.shape), np.empty(x.shape)
    fa, fb = a.reshape(-1), b.reshape(-1)
    for i in range(flat.shape[0]):
        fa[i] = np.rint(flat[i] * scale_a)
        fb[i] = np.rint(flat[i] * scale_b)
    return a, math.ldexp(1.0, e - bits_a), b, math.ldexp(1.0, e - bits_b)


@njit(cache=True, nogil=True)
def round_spans(params: np.ndarray, spans: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every span of ``params`` on its own grid: ``spans`` (S, 3) holds (start, stop, bits); the
    integers of span s are ``out[offset_s : offset_s + stop - start]`` (spans in order) and its
    unit ``units[s]``, as ``exact.rounded(params[start:stop], bits)``."""
    total = 0
    for s in range(spans.shape[0]):
        total += spans[s, 1] - spans[s, 0]
    out = np.empty(total)
    units = np.empty(spans.shape[0])
    at = 0
    for s in range(spans.shape[0]):
        size = spans[s, 1] - spans[s, 0]
        units[s] = exact.round_into(params[spans[s, 0] : spans[s, 1]], spans[s, 2], out[at : at + size])
        at += size
    return out, units


@njit(cache=True, nogil=True)
def scale_into(product: np.ndarray, unit: float, grads: np.ndarray, w_at: int, b_at: int) -> None:
    """A layer's weight and bias gradients from ``[inputs, 1]^T g``'s exact integer product (out,
    in + 1): ``product * unit``, its first ``in`` columns to ``grads[w_at:]`` (row-major (out, in)),
    the last to ``grads[b_at:]``."""
    n_out, n_in = product.shape[0], product.shape[1] - 1
    for o in range(n_out):
        for i in range(n_in):
            grads[w_at + o * n_in + i] = product[o, i] * unit
        grads[b_at + o] = product[o, n_in] * unit


@njit(cache=True, nogil=True)
def round_with_ones(x: np.ndarray, bits: int) -> tuple[np.ndarray, float]:
    """``exact.rounded(concatenate([x, ones((B, 1))], axis=1), bits)`` for x (B, p): the integers (B, p + 1) and the unit."""
    n, p = x.shape
    joined = np.empty((n, p + 1))
    for i in range(n):
        for j in range(p):
            joined[i, j] = x[i, j]
        joined[i, p] = 1.0
    flat = joined.reshape(-1)
    unit = exact.round_into(flat, bits, flat)
    return joined, unit


@njit(cache=True, nogil=True)
def scaled_slope(product: np.ndarray, unit: float, pre: np.ndarray, slope: np.ndarray) -> np.ndarray:
    """The gradient below a hidden layer: ``(product * unit) * slope``, the slope of a ReLU
    ``(pre > 0).astype(float64)`` when ``slope`` is empty, else ``slope`` as given."""
    n, p = product.shape
    out = np.empty((n, p))
    relu = slope.shape[0] == 0
    for i in range(n):
        for j in range(p):
            out[i, j] = (product[i, j] * unit) * ((1.0 if pre[i, j] > 0.0 else 0.0) if relu else slope[i, j])
    return out


@njit(cache=True, nogil=True)
def cross_entropy_grad(logits: np.ndarray, labels: np.ndarray, class_w: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Per-sample cross entropy (B,), d (sum_i c_{y_i} CE_i / B) / d logits (B, m), and how many
    rows have their label as the first argmax.

    The NumPy form: ``top = logits.max(axis=1); e = exp(logits - top[:, None]); total = row_sum(e);
    loss = log(total) + top - logits[i, y]; p = e / total[:, None]; p[i, y] -= 1.0;
    grad = p * (class_w[y] / float(B))[:, None]``, with :mod:`exact`'s exp and log.
    """
    n, m = logits.shape
    shifted = np.empty((n, m))
    top = np.empty(n)
    hits = 0
    for i in range(n):
        t, arg = logits[i, 0], 0
        for j in range(1, m):
            v = logits[i, j]
            if v > t or (v != v and t == t):
                t, arg = v, j
        top[i] = t
        hits += arg == labels[i]
        for j in range(m):
            shifted[i, j] = logits[i, j] - t
    e = exact.exp_flat(shifted.reshape(-1)).reshape(n, m)
    total = np.empty(n)
    for i in range(n):
        s = e[i, 0]
        for j in range(1, m):
            s = s + e[i, j]
        total[i] = s
    logs = exact.log_flat(total)
    loss = np.empty(n)
    grad = np.empty((n, m))
    size = float(n)
    for i in range(n):
        y = labels[i]
        loss[i] = logs[i] + top[i] - logits[i, y]
        scale = class_w[y] / size
        for j in range(m):
            p = e[i, j] / total[i]
            if j == y:
                p -= 1.0
            grad[i, j] = p * scale
    return loss, grad, hits


@njit(cache=True, nogil=True)
def compress_grads(flat: np.ndarray, x_columns: np.ndarray, x_unit: float, x_bits: int) -> tuple[np.ndarray, np.ndarray]:
    """The compression's weight (1, k) and bias (1,) gradients from d loss / d its output ``flat``
    (B m,): ``matmul(flat[None], Rounded(x_columns.T, x_unit, x_bits))`` and
    ``matmul(ones((1, B m)), flat[:, None])[0]``, the rounded inputs given by columns (k, B m)."""
    weight = np.empty(x_columns.shape[0])
    exact.vec_mat_rounded(flat, x_columns, x_unit, x_bits, weight)
    bias = np.empty(1)
    exact.vec_mat(np.ones(flat.shape[0]), flat, 1, bias)
    return weight.reshape(1, -1), bias
