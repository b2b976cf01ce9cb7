"""The linear utility model: one weight per utility, a bias per trajectory, softmax over the set.

It scores trajectory i with ``w . U_i + b_i``: the multi-criteria decision function with learned
weights. Fitted by full-batch Adam on the cross entropy (NumPy, the same bits on every CPU; a few
seconds for minutes of driving). Used three ways: to check that demonstrations identify the preference
(the weights come out in the profile's order), as a baseline planner, and to initialise C's
row-wise compression so that training starts from a utility that already ranks the terrain.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from terrapref.learning import exact


@dataclass(frozen=True)
class LinearUtility:
    """Fitted weights: ``w`` (K + 1,) over the utility columns, ``b`` (m,) per trajectory."""

    w: np.ndarray
    b: np.ndarray

    def logits(self, U: np.ndarray) -> np.ndarray:
        return U @ self.w + self.b


def fit_linear_utility(U: np.ndarray, labels: np.ndarray, steps: int = 1500, lr: float = 0.05,
                       sample_weight: np.ndarray | None = None) -> LinearUtility:
    """Maximum-likelihood fit of the linear utility model to (U (N, m, K + 1), labels (N,)).

    The arithmetic is :mod:`terrapref.learning.exact`'s, so the fit is the same on every CPU.
    """
    U = np.asarray(U, dtype=np.float64)
    n, m, k = U.shape
    rows = exact.rounded(U.reshape(n * m, k), 18)  # constant: rounded once, 18 bits leave room for sums of 2 ** 17
    sw = np.ones(n) if sample_weight is None else np.asarray(sample_weight, dtype=np.float64)
    sw = sw / exact.fsum(sw)
    params = np.zeros(k + m)
    mom, vel = np.zeros_like(params), np.zeros_like(params)
    power1 = power2 = 1.0  # 0.9 ** t and 0.999 ** t by repeated products
    at_label = (np.arange(n), labels)
    ones = np.ones((1, n))
    for _ in range(steps):
        logits = exact.matmul(rows, params[:k, None]).reshape(n, m) + params[k:]
        p = exact.exp(logits - np.max(logits, axis=1, keepdims=True))
        p /= exact.row_sum(p)[:, None]
        p[at_label] -= 1.0
        g = p * sw[:, None]  # d loss / d logits, (n, m)
        grad = np.concatenate([exact.matmul(g.reshape(1, n * m), rows)[0], exact.matmul(ones, g)[0]])
        power1, power2 = power1 * 0.9, power2 * 0.999
        mom = 0.9 * mom + 0.1 * grad
        vel = 0.999 * vel + 0.001 * (grad * grad)
        params -= lr * (mom / (1 - power1)) / (np.sqrt(vel / (1 - power2)) + 1e-8)
    return LinearUtility(params[:k].copy(), params[k:].copy())


@dataclass(frozen=True)
class LookaheadFit:
    """The linear utility fitted through the look-ahead, and the weight its value got in the fit."""

    utility: LinearUtility
    gamma: float


def fit_lookahead_utility(U: np.ndarray, U2: np.ndarray, labels: np.ndarray, steps: int = 300, lr: float = 0.05,
                          start: LinearUtility | None = None) -> LookaheadFit:
    """Fit the linear utility through the planner's look-ahead (SPEC 8's loss over a planning rule).

    Trajectory i scores ``f(U_i) + gamma * max_j f(U2_ij)`` with ``f(u) = w . u + b``: its own
    utility plus the best of the second pieces that continue it (terrapref.features.lookahead);
    a softmax over i is fitted to the demonstrated labels by full-batch Adam, ``w``, ``b`` and
    ``gamma`` together, from ``start`` (default: the frame-wise fit) and gamma = 1.

    A frame-wise fit sees only "this trajectory, not that one". Through the look-ahead, a lone
    patch that a short swerve clears and a pair of wide patches that no swerve clears become
    different situations for the same w, so the weights say how much each class costs against
    grass, not only against each other.

    Args:
        U: (N, m, K + 1) first-stage utilities (terrain shares, distance).
        U2: (N, m, m, K + 1) look-ahead utilities of the same frames.
        labels: (N,) demonstrated trajectory indices.
    """
    U = np.asarray(U, dtype=np.float64)
    n, m, k = U.shape
    if U2.shape != (n, m, m, k):
        raise ValueError(f"U2 must have shape {(n, m, m, k)}, got {U2.shape}")
    start = start or fit_linear_utility(U, labels)
    first = exact.rounded(U.reshape(n * m, k), 18)
    second = exact.rounded(np.asarray(U2, dtype=np.float64).reshape(n * m * m, k), 18)
    params = np.concatenate([start.w, start.b, [1.0]])
    mom, vel = np.zeros_like(params), np.zeros_like(params)
    power1 = power2 = 1.0
    at_label = (np.arange(n), labels)
    ones = np.ones((1, n))
    flat = np.arange(n * m) * m
    for _ in range(steps):
        w, b, gamma = params[:k], params[k : k + m], params[-1]
        f2 = exact.matmul(second, w[:, None]).reshape(n * m, m) + b
        best = np.argmax(f2, axis=1)  # the best continuation of every (frame, trajectory)
        value = f2[np.arange(n * m), best].reshape(n, m)
        z = exact.matmul(first, w[:, None]).reshape(n, m) + b + gamma * value
        p = exact.exp(z - np.max(z, axis=1, keepdims=True))
        p /= exact.row_sum(p)[:, None]
        p[at_label] -= 1.0
        d = p / n  # d loss / d z, (n, m)
        chosen = exact.Rounded(second.ints[flat + best], second.unit, second.bits)
        grad_w = exact.matmul(d.reshape(1, n * m), first)[0] + gamma * exact.matmul(d.reshape(1, n * m), chosen)[0]
        # bincount adds its weights one by one in index order: the same order on every CPU
        grad_b = exact.matmul(ones, d)[0] + gamma * np.bincount(best, weights=d.ravel(), minlength=m)
        grad = np.concatenate([grad_w, grad_b, exact.matmul(d.reshape(1, n * m), value.reshape(n * m, 1))[0]])
        power1, power2 = power1 * 0.9, power2 * 0.999
        mom = 0.9 * mom + 0.1 * grad
        vel = 0.999 * vel + 0.001 * (grad * grad)
        params -= lr * (mom / (1 - power1)) / (np.sqrt(vel / (1 - power2)) + 1e-8)
    return LookaheadFit(LinearUtility(params[:k].copy(), params[k : k + m].copy()), float(params[-1]))
