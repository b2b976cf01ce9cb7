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
