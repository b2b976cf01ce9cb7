"""C's forward pass for the control loop: F_t of one frame in one compiled call, the same bits on every CPU.

The planner asks C for F_t once per frame, on one U of 21 x 5 numbers: a few thousand
multiply-adds, where NumPy's and BLAS's per-call cost, not the arithmetic, set the time (five
batched products and a dozen elementwise calls for an ensemble of three). Here the whole pass
runs as one compiled loop (Numba, without fast-math) in float64: each product is summed over
its inputs in order, the exponential and logarithm are :mod:`terrapref.learning.exact`'s, and
nothing is left to a library whose kernels differ between CPUs (BLAS's sum order, NumPy's SIMD
``exp``), so the same model and frame give the same F_t, and the same decision, on any machine.

:func:`terrapref.learning.network.numpy_forward` stays as the readable NumPy form; the two agree
to float32 rounding (tests/learning/test_forward.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from terrapref.learning import exact
from terrapref.learning.network import ACTIVATIONS, ClassifierConfig, member_prefix


@dataclass(frozen=True, eq=False)
class PackedNetwork:
    """C's weights laid out for :func:`probabilities`, float64.

    Attributes:
        weights: every member's layers, flat: each layer's weight as (in, out) row-major, then its bias.
        layout: (members, layers, 4) int64: per layer, the weight's offset, the bias's offset, in, out.
        compress: (members, k + 1): the row-wise compression's weights, then its bias ((members, 0) without it).
        ignore: (k,) 1.0 for the columns C sees, 0.0 for the ignored ones.
        activation: index into :data:`ACTIVATIONS`.
        skip: the residual path adds the compressed scores to the logits.
    """

    weights: np.ndarray
    layout: np.ndarray
    compress: np.ndarray
    ignore: np.ndarray
    activation: int
    skip: bool

    @classmethod
    def of(cls, config: ClassifierConfig, weights: dict[str, np.ndarray]) -> PackedNetwork:
        prefixes = [member_prefix(j) for j in range(config.members)] if config.members > 1 else [""]
        flat: list[np.ndarray] = []
        layout = np.zeros((len(prefixes), config.depth + 1, 4), np.int64)
        offset = 0
        for a, p in enumerate(prefixes):
            for i in range(config.depth + 1):
                w = np.asarray(weights[f"{p}layers.{i}.weight"], dtype=np.float64)  # (out, in)
                b = np.asarray(weights[f"{p}layers.{i}.bias"], dtype=np.float64)
                layout[a, i] = (offset, offset + w.size, w.shape[1], w.shape[0])
                flat += [np.ascontiguousarray(w.T).ravel(), b]
                offset += w.size + b.size
        if config.compress:
            compress = np.stack(
                [
                    np.concatenate(
                        [
                            np.asarray(weights[f"{p}compress.weight"], np.float64).ravel(),
                            np.asarray(weights[f"{p}compress.bias"], np.float64),
                        ]
                    )
                    for p in prefixes
                ]
            )
        else:
            compress = np.zeros((len(prefixes), 0))
        ignore = np.ones(config.n_features)
        ignore[list(config.ignore)] = 0.0
        return cls(np.concatenate(flat), layout, compress, ignore, ACTIVATIONS.index(config.activation), config.skip)


def probabilities(net: PackedNetwork, U: np.ndarray) -> np.ndarray:
    """F_t (m,) float64 of C for one frame's U (m, k): the softmax, or for an ensemble the mean
    of its members' softmaxes."""
    return _probabilities(np.asarray(U), net.weights, net.layout, net.compress, net.ignore, net.activation, net.skip)


@njit(cache=True, nogil=True)
def _probabilities(
    U: np.ndarray, weights: np.ndarray, layout: np.ndarray, compress: np.ndarray, ignore: np.ndarray, activation: int, skip: bool
) -> np.ndarray:
    m, k = U.shape
    x = np.empty((m, k))
    for i in range(m):
        for c in range(k):
            x[i, c] = np.float64(U[i, c]) * ignore[c]
    members, layers = layout.shape[0], layout.shape[1]
    probs = np.zeros(m)
    for a in range(members):
        if compress.shape[1]:
            h = np.empty(m)
            for i in range(m):
                total = 0.0
                for c in range(k):
                    total += x[i, c] * compress[a, c]
                h[i] = total + compress[a, k]
        else:
            h = x.reshape(-1).copy()
        scores = h
        for layer in range(layers):
            h = _layer(h, weights, layout[a, layer], activation if layer < layers - 1 else -1)
        if skip:
            for i in range(m):
                h[i] = h[i] + scores[i]
        p = _softmax(h)
        for i in range(m):
            probs[i] = probs[i] + p[i]
    if members > 1:
        for i in range(m):
            probs[i] = probs[i] / members
    return probs


@njit(cache=True, nogil=True)
def _layer(h: np.ndarray, weights: np.ndarray, where: np.ndarray, activation: int) -> np.ndarray:
    """``act(h @ W + b)`` for one layer (``where``: the weight's offset, the bias's, in, out);
    each output summed over the inputs in order. ``activation`` -1: none (the output layer)."""
    w_at, b_at, n_in, n_out = where[0], where[1], where[2], where[3]
    z = np.zeros(n_out)
    for i in range(n_in):
        hi = h[i]
        row = w_at + i * n_out
        for j in range(n_out):
            z[j] += hi * weights[row + j]
    for j in range(n_out):
        z[j] = z[j] + weights[b_at + j]
    if activation == 0:  # relu, as np.maximum(z, 0.0)
        for j in range(n_out):
            z[j] = z[j] if (z[j] > 0.0 or z[j] != z[j]) else 0.0
    elif activation == 1:  # tanh = 1 - 2 / (e^2z + 1)
        e = exact.exp_flat(2.0 * z)
        for j in range(n_out):
            z[j] = 1.0 - 2.0 / (e[j] + 1.0)
    elif activation == 2:  # elu, alpha 1
        e = exact.exp_flat(np.minimum(z, 0.0))
        for j in range(n_out):
            z[j] = z[j] if z[j] > 0.0 else e[j] - 1.0
    return z


@njit(cache=True, nogil=True)
def _softmax(z: np.ndarray) -> np.ndarray:
    """``e = exp(z - max(z)); e / sum(e)``, the sum added in order."""
    top = z[0]
    for i in range(1, z.shape[0]):
        if z[i] > top or z[i] != z[i]:
            top = z[i]
    e = exact.exp_flat(z - top)
    total = e[0]
    for i in range(1, e.shape[0]):
        total = total + e[i]
    for i in range(e.shape[0]):
        e[i] = e[i] / total
    return e
