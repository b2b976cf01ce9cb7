"""Training C's per-layer arithmetic around the matrix products, compiled (Numba).

A training step of C is about sixty small array operations around a dozen BLAS products; NumPy's
per-call overhead, not the arithmetic, set its cost. Each loop here does, element by element,
exactly the IEEE 754 operations of the NumPy form its docstring gives, in the same order
(compiled without fast-math: nothing is reassociated or fused into a multiply-add), so a trained
model keeps its bits (tests/test_mlp.py keeps the NumPy forms and compares). The products
themselves stay in BLAS on integers (:mod:`terrapref.learning.exact`), exact in any order.
"""

from __future__ import annotations

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
    unit = x_unit * exact.round_into(weight.reshape(-1), min(26, exact._chunk_bits(k) - x_bits), w_ints)
    out = np.empty(rows)
    b = bias[0]
    for r in range(rows):
        total = 0.0
        for c in range(k):
            total += x[r, c] * w_ints[c]
        out[r] = total * unit + b
    return out


@njit(cache=True, nogil=True)
def affine(product: np.ndarray, unit: float, bias: np.ndarray, relu: bool, skip: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A layer's output from its exact integer product (B, out): ``z = product * unit + bias``
    (``+ skip`` when ``skip`` has rows, the residual path) and, with ``relu``,
    ``np.maximum(z, 0.0)`` (z where z > 0 or NaN, else +0.0); without, the second array is ``z``."""
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
    return z, h


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
def scaled_slope(product: np.ndarray, unit: float, pre: np.ndarray) -> np.ndarray:
    """The gradient below a ReLU layer: ``(product * unit) * (pre > 0).astype(float64)``."""
    n, p = product.shape
    out = np.empty((n, p))
    for i in range(n):
        for j in range(p):
            out[i, j] = (product[i, j] * unit) * (1.0 if pre[i, j] > 0.0 else 0.0)
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
    e = exact._exp(shifted.reshape(-1)).reshape(n, m)
    total = np.empty(n)
    for i in range(n):
        s = e[i, 0]
        for j in range(1, m):
            s = s + e[i, j]
        total[i] = s
    logs = exact._log(total)
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
