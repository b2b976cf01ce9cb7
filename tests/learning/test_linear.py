"""The linear utility's two fits run as compiled loops; they must give the bits of their NumPy forms.

The NumPy forms below are the fits as terrapref.learning.linear computed them before they were
compiled (exact.matmul's rounded products, exact.exp, exact.row_sum, a NumPy Adam): every
trained model's second stage and identifiability report are made from these fits, so a
compiled loop that moved a last bit would move them.
"""

from __future__ import annotations

import numpy as np
import pytest

from terrapref.learning import exact
from terrapref.learning.linear import LinearUtility, fit_linear_utility, fit_lookahead_utility


def _numpy_fit_frames(
    U: np.ndarray, labels: np.ndarray, steps: int, lr: float = 0.05, sample_weight: np.ndarray | None = None
) -> LinearUtility:
    U = np.asarray(U, dtype=np.float64)
    n, m, k = U.shape
    rows = exact.rounded(U.reshape(n * m, k), 18)
    sw = np.ones(n) if sample_weight is None else np.asarray(sample_weight, dtype=np.float64)
    sw = sw / exact.fsum(sw)
    params = np.zeros(k + m)
    mom, vel = np.zeros_like(params), np.zeros_like(params)
    power1 = power2 = 1.0
    at_label = (np.arange(n), labels)
    ones = np.ones((1, n))
    for _ in range(steps):
        logits = exact.matmul(rows, params[:k, None]).reshape(n, m) + params[k:]
        p = exact.exp(logits - np.max(logits, axis=1, keepdims=True))
        p /= exact.row_sum(p)[:, None]
        p[at_label] -= 1.0
        g = p * sw[:, None]
        grad = np.concatenate([exact.matmul(g.reshape(1, n * m), rows)[0], exact.matmul(ones, g)[0]])
        power1, power2 = power1 * 0.9, power2 * 0.999
        mom = 0.9 * mom + 0.1 * grad
        vel = 0.999 * vel + 0.001 * (grad * grad)
        params -= lr * (mom / (1 - power1)) / (np.sqrt(vel / (1 - power2)) + 1e-8)
    return LinearUtility(params[:k].copy(), params[k:].copy())


def _numpy_fit_through(
    U: np.ndarray, U2: np.ndarray, labels: np.ndarray, steps: int, start: LinearUtility, lr: float = 0.05
) -> tuple[LinearUtility, float]:
    U = np.asarray(U, dtype=np.float64)
    n, m, k = U.shape
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
        best = np.argmax(f2, axis=1)
        value = f2[np.arange(n * m), best].reshape(n, m)
        z = exact.matmul(first, w[:, None]).reshape(n, m) + b + gamma * value
        p = exact.exp(z - np.max(z, axis=1, keepdims=True))
        p /= exact.row_sum(p)[:, None]
        p[at_label] -= 1.0
        d = p / n
        chosen = exact.Rounded(second.ints[flat + best], second.unit, second.bits)
        grad_w = exact.matmul(d.reshape(1, n * m), first)[0] + gamma * exact.matmul(d.reshape(1, n * m), chosen)[0]
        grad_b = exact.matmul(ones, d)[0] + gamma * np.bincount(best, weights=d.ravel(), minlength=m)
        grad = np.concatenate([grad_w, grad_b, exact.matmul(d.reshape(1, n * m), value.reshape(n * m, 1))[0]])
        power1, power2 = power1 * 0.9, power2 * 0.999
        mom = 0.9 * mom + 0.1 * grad
        vel = 0.999 * vel + 0.001 * (grad * grad)
        params -= lr * (mom / (1 - power1)) / (np.sqrt(vel / (1 - power2)) + 1e-8)
    return LinearUtility(params[:k].copy(), params[k : k + m].copy()), float(params[-1])


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


def _utilities(rng: np.random.Generator, n: int, m: int = 21) -> tuple[np.ndarray, np.ndarray]:
    """U like the features': terrain shares (mostly zero, multiples of 1/30) and a distance utility in [0, 1]."""
    shares = rng.integers(0, 31, size=(n, m, 4)) * (rng.random((n, m, 4)) < 0.2) / 30.0
    U = np.concatenate([shares, rng.random((n, m, 1))], axis=2)
    labels = np.argmax(U @ np.array([-3.0, -2.0, -1.0, -0.5, 2.0]) + 0.3 * rng.standard_normal((n, m)), axis=1)
    return U.astype(np.float32), labels


@pytest.mark.parametrize("n", [40, 6300])  # 6300 frames of 21: past one exact chunk (2 ** 17 terms)
def test_frame_fit_gives_the_numpy_forms_bits(n: int):
    rng = np.random.default_rng(n)
    U, labels = _utilities(rng, n)
    steps = 60 if n > 1000 else 400
    got = fit_linear_utility(U, labels, steps=steps)
    want = _numpy_fit_frames(U, labels, steps)
    assert _same_bits(got.w, want.w) and _same_bits(got.b, want.b)
    weights = rng.random(n) * (rng.random(n) < 0.8)
    got = fit_linear_utility(U, labels, steps=30, lr=0.1, sample_weight=weights)
    want = _numpy_fit_frames(U, labels, 30, lr=0.1, sample_weight=weights)
    assert _same_bits(got.w, want.w) and _same_bits(got.b, want.b)


@pytest.mark.parametrize("n", [30, 300])  # 300 frames: 132,300 second pieces, past one exact chunk
def test_lookahead_fit_gives_the_numpy_forms_bits(n: int):
    rng = np.random.default_rng(100 + n)
    U, labels = _utilities(rng, n)
    U2 = np.stack([_utilities(rng, n)[0] for _ in range(21)], axis=2).astype(np.float16)  # (n, m, m, k)
    U2[..., -1] = np.round(U2[..., -1] * 3) / 3  # continuations that tie, as grass ahead does
    start = fit_linear_utility(U, labels, steps=50)
    steps = 25 if n > 100 else 120
    got = fit_lookahead_utility(U, U2, labels, steps=steps, start=start)
    want, gamma = _numpy_fit_through(U, U2, labels, steps, start)
    assert _same_bits(got.utility.w, want.w) and _same_bits(got.utility.b, want.b) and _same_bits(got.gamma, gamma)
    assert got.gamma != 1.0  # it moved: the comparison is of a fit, not of its start
    even = LinearUtility(start.w, np.zeros(21))  # equal biases: continuations tie, the first one wins
    got = fit_lookahead_utility(U, U2, labels, steps=3, start=even)
    want, gamma = _numpy_fit_through(U, U2, labels, 3, even)
    assert _same_bits(got.utility.w, want.w) and _same_bits(got.utility.b, want.b) and _same_bits(got.gamma, gamma)


def test_exact_helpers_give_matmuls_bits_past_a_chunk():
    rng = np.random.default_rng(3)
    for k in (7, 1000, exact.MAX_EXACT + 4321):
        a = rng.standard_normal(k) * 10.0 ** rng.integers(-3, 3)
        b = rng.random((k, 5)) * (rng.random((k, 5)) < 0.5)
        b_round = exact.rounded(b, 18)
        out = np.empty(5)
        exact.vec_mat_rounded(a, np.ascontiguousarray(b_round.ints.T), b_round.unit, 18, out)
        assert _same_bits(out, exact.matmul(a[None], b_round)[0])
        for p in (1, 5):
            out = np.empty(p)
            exact.vec_mat(a, np.ascontiguousarray(b[:, :p]).ravel(), p, out)
            assert _same_bits(out, exact.matmul(a[None], b[:, :p])[0])


def test_distinct_columns_index_every_column():
    from terrapref.learning.linear import _distinct_columns

    rng = np.random.default_rng(9)
    x = rng.integers(-3, 3, size=(5, 4000), dtype=np.int32)  # 6 ** 5 possible columns: many repeats
    x[:, 17] = [2**26, -(2**26), 0, 1, -1]  # values at the grid's extremes
    distinct, which = _distinct_columns(x)
    assert np.array_equal(distinct[:, which], x)
    assert np.unique(distinct.T, axis=0).shape[0] == distinct.shape[1]  # each once
    firsts = np.unique(which, return_index=True)[1]
    assert np.all(np.diff(firsts) > 0)  # in the order they first appear
    empty, none = _distinct_columns(np.zeros((5, 0), dtype=np.int32))
    assert empty.shape == (5, 0) and none.shape == (0,)


def test_lookahead_fit_takes_numpys_argmax_with_a_nan_bias():
    rng = np.random.default_rng(5)
    U, labels = _utilities(rng, 20)
    U2 = np.stack([_utilities(rng, 20)[0] for _ in range(21)], axis=2).astype(np.float16)
    start = fit_linear_utility(U, labels, steps=20)
    b = start.b.copy()
    b[4] = np.nan  # the compiled argmax's slow path: the first NaN wins, as NumPy's
    nan_start = LinearUtility(start.w, b)
    got = fit_lookahead_utility(U, U2, labels, steps=2, start=nan_start)
    want, gamma = _numpy_fit_through(U, U2, labels, 2, nan_start)
    assert _same_bits(got.utility.w, want.w) and _same_bits(got.utility.b, want.b) and _same_bits(got.gamma, gamma)
