"""The linear utility model: one weight per utility, a bias per trajectory, softmax over the set.

It scores trajectory i with ``w . U_i + b_i``: the multi-criteria decision function with learned
weights. Fitted by full-batch Adam on the cross entropy (NumPy; a few hundred milliseconds for
minutes of driving). Used three ways: to check that demonstrations identify the preference
(the weights come out in the profile's order), as a baseline planner, and to initialise C's
row-wise compression so that training starts from a utility that already ranks the terrain.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class LinearUtility:
    """Fitted weights: ``w`` (K + 1,) over the utility columns, ``b`` (m,) per trajectory."""

    w: np.ndarray
    b: np.ndarray

    def logits(self, U: np.ndarray) -> np.ndarray:
        return U @ self.w + self.b


def fit_linear_utility(U: np.ndarray, labels: np.ndarray, steps: int = 1500, lr: float = 0.05,
                       sample_weight: np.ndarray | None = None) -> LinearUtility:
    """Maximum-likelihood fit of the linear utility model to (U (N, m, K + 1), labels (N,))."""
    U = np.asarray(U, dtype=np.float64)
    n, m, k = U.shape
    sw = np.ones(n) if sample_weight is None else np.asarray(sample_weight, dtype=np.float64)
    sw = sw / sw.sum()
    params = np.zeros(k + m)
    mom, vel = np.zeros_like(params), np.zeros_like(params)
    onehot = np.eye(m)[labels]
    for t in range(1, steps + 1):
        logits = U @ params[:k] + params[k:]
        p = np.exp(logits - logits.max(axis=1, keepdims=True))
        p /= p.sum(axis=1, keepdims=True)
        g = (p - onehot) * sw[:, None]  # d loss / d logits, (n, m)
        grad = np.concatenate([np.einsum("nm,nmk->k", g, U), g.sum(axis=0)])
        mom = 0.9 * mom + 0.1 * grad
        vel = 0.999 * vel + 0.001 * grad**2
        params -= lr * (mom / (1 - 0.9**t)) / (np.sqrt(vel / (1 - 0.999**t)) + 1e-8)
    return LinearUtility(params[:k].copy(), params[k:].copy())
