"""CPU-independent arithmetic (terrapref.learning.exact) and C's hand-written gradient.

Training gives the same weights, bit for bit, whatever BLAS kernel, SIMD level or thread count
the machine has: checked here by training in fresh processes under settings that change how
plain NumPy products and exponentials come out.
"""

from __future__ import annotations

import math
import platform

import numpy as np
import pytest
import torch

from cpu_settings import SETTINGS, CpuCheck
from helpers import TESTS
from terrapref.learning import exact
from terrapref.learning.mlp import Adam, TrainableClassifier, cross_entropy, init_weights, round_inputs
from terrapref.learning.network import ClassifierConfig, numpy_forward
from torch_net import UtilityClassifier

# --- elementary functions ------------------------------------------------------------------------


def test_exp_matches_numpy_to_the_last_bits():
    rng = np.random.default_rng(0)
    x = np.concatenate([rng.uniform(-700, 700, 20000), rng.uniform(-3, 3, 20000), [0.0, -0.0, 1e-300, -1e-300, 709.0, -740.0]])
    np.testing.assert_allclose(exact.exp(x), np.exp(x), rtol=4.5e-16, atol=0)
    assert exact.exp(np.array([0.0]))[0] == 1.0
    assert 0.0 <= exact.exp(np.array([-1e4]))[0] < 1e-320  # far below the smallest normal float: no error


def test_log_matches_numpy_and_handles_the_edges():
    rng = np.random.default_rng(1)
    x = np.concatenate([np.exp(rng.uniform(-700, 700, 20000)), rng.uniform(0.5, 2.0, 20000), [1.0, 2.0, 0.5, 1e-300, 1e300]])
    np.testing.assert_allclose(exact.log(x), np.log(x), rtol=4.5e-16, atol=4.5e-16)
    assert exact.log(np.array([1.0]))[0] == 0.0
    out = exact.log(np.array([0.0, -1.0]))
    assert out[0] == -np.inf and np.isnan(out[1])


def test_fsum_and_row_sum_do_not_depend_on_order():
    rng = np.random.default_rng(2)
    v = rng.normal(size=1000) * 10.0 ** rng.integers(-8, 8, 1000)
    assert exact.fsum(v) == exact.fsum(v[::-1]) == math.fsum(v.tolist())
    x = rng.normal(size=(4, 21))
    np.testing.assert_array_equal(exact.row_sum(x), [_left_to_right(x[i]) for i in range(4)])


# The NumPy forms of the compiled loops, as exact.py computed them before they were compiled: the
# loops must give the same bits (training's weights, and so every model, depend on them).


def _numpy_exp(x: np.ndarray) -> np.ndarray:
    x = np.clip(np.asarray(x, dtype=np.float64), -740.0, 709.0)
    k = np.rint(x * exact._INV_LN2)
    r = (x - k * exact._LN2_HI) - k * exact._LN2_LO
    p = np.full_like(r, exact._EXP_COEF[-1])
    for c in exact._EXP_COEF[-2::-1]:
        p = p * r + c
    return np.ldexp(p, k.astype(np.int64))


def _numpy_log(x: np.ndarray) -> np.ndarray:
    f, e = np.frexp(np.where(x > 0, x, 1.0))
    low = f < exact._SQRT_HALF
    f = np.where(low, f * 2.0, f)
    e = np.where(low, e - 1, e).astype(np.float64)
    s = (f - 1.0) / (f + 1.0)
    series = np.full_like(s, 1.0 / 21.0)
    for j in range(19, 0, -2):
        series = series * (s * s) + 1.0 / j
    out = 2.0 * s * series + e * exact._LN2_LO + e * exact._LN2_HI
    return np.where(x > 0, out, np.where(x == 0, -np.inf, np.nan))


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


def test_compiled_loops_give_the_numpy_forms_bits():
    rng = np.random.default_rng(7)
    x = np.concatenate(
        [rng.standard_normal(30000) * scale for scale in (1.0, 30.0, 400.0)]
        + [[0.0, -0.0, 709.0, 709.5, -740.0, -745.0, 1e-310, -1e-310, np.inf, -np.inf]]
    )
    with np.errstate(invalid="ignore"):
        assert _same_bits(exact.exp(x), _numpy_exp(x))
        assert _same_bits(exact.exp(x.reshape(-1, 10)[:, ::2]), _numpy_exp(x.reshape(-1, 10)[:, ::2]))  # any shape and strides
        assert np.isnan(exact.exp(np.array([np.nan]))[0])
        # Every scaling the range reduction can ask for, results subnormal ones included.
        sweep = np.concatenate(
            [np.linspace(-745.0, -700.0, 200001), np.linspace(700.0, 710.0, 20001), np.arange(-1068, 1024) * math.log(2)]
        )
        assert _same_bits(exact.exp(sweep), _numpy_exp(sweep))
        y = np.concatenate([np.abs(x), rng.random(1000) * 1e-300, [5e-324, 1e308, -1.0, np.nan]])
        np.testing.assert_array_equal(exact.log(y), _numpy_log(y))  # NaN where NaN
        assert _same_bits(exact.log(y[y > 0]), _numpy_log(y[y > 0]))
        assert np.signbit(exact.log(np.array([-0.0, 0.0]))).all()  # -inf for both zeros
    for bits in (8, 18, 26):
        for a in (x[:3000].reshape(30, 100), x[:3000].reshape(30, 100)[:, ::3], rng.random((3, 4, 5)) - 0.7, -np.ones((2, 2))):
            got = exact.rounded(a, bits)
            top = max(float(a.max()), -float(a.min()))
            e = math.frexp(top)[1]
            assert _same_bits(got.ints, np.rint(a * math.ldexp(1.0, bits - e))) and got.unit == math.ldexp(1.0, e - bits)
    nan_in = exact.rounded(np.array([1.0, np.nan]), 10)
    assert np.isnan(nan_in.ints[1]) and nan_in.unit == math.ldexp(1.0, -10)  # as NumPy's max: NaN wins, frexp(NaN) has exponent 0
    z = rng.normal(size=(5, 3, 21))
    assert _same_bits(exact.row_sum(z), _numpy_row_sum(z))


def _numpy_row_sum(x: np.ndarray) -> np.ndarray:
    total = x[..., 0].copy()
    for j in range(1, x.shape[-1]):
        total = total + x[..., j]
    return total


def _left_to_right(row: np.ndarray) -> float:
    total = float(row[0])
    for value in row[1:]:
        total += float(value)
    return total


# --- exact products ------------------------------------------------------------------------------


@pytest.mark.parametrize("k", [1, 5, 64, 300, 5000])
def test_matmul_is_the_exact_product_of_the_rounded_operands(k: int):
    """Every entry equals the correctly rounded sum of exact products of the rounded operands,
    which is what makes the result independent of the summation order."""
    rng = np.random.default_rng(k)
    a, b = rng.normal(size=(6, k)) * 3.0, rng.normal(size=(k, 4)) / 7.0
    out = exact.matmul(a, b)
    ra = exact.rounded(a, (53 - exact.sum_bits(k)) // 2)
    rb = exact.rounded(b, min(26, 53 - exact.sum_bits(k) - ra.bits))
    for i in range(6):
        for j in range(4):
            terms = (ra.ints[i] * rb.ints[:, j]).tolist()  # products of integers below 2 ** 53: exact
            assert out[i, j] == math.fsum(terms) * (ra.unit * rb.unit)
    # ... and close to the plain product: about 2 ** -(bits - 1) of the largest terms
    scale = np.abs(a).max() * np.abs(b).max() * k
    np.testing.assert_allclose(out, a @ b, rtol=0, atol=scale * 2.0**-16)


def test_matmul_does_not_depend_on_the_order_of_the_terms():
    rng = np.random.default_rng(3)
    a, b = rng.normal(size=(50, 777)) * 10.0 ** rng.integers(-3, 3, (50, 1)), rng.normal(size=(777, 30))
    perm = rng.permutation(777)
    np.testing.assert_array_equal(exact.matmul(a, b), exact.matmul(a[:, perm], b[perm]))
    # a plain float64 product generally does: the reason for all this
    assert not np.array_equal(a @ b, a[:, perm] @ b[perm])


def test_long_sums_are_cut_into_exact_chunks():
    rng = np.random.default_rng(4)
    k = exact.MAX_EXACT + 1000
    a, b = rng.normal(size=(1, k)), rng.normal(size=(k, 2))
    first = exact.matmul(a[:, : exact.MAX_EXACT], b[: exact.MAX_EXACT])
    rest = exact.matmul(a[:, exact.MAX_EXACT :], b[exact.MAX_EXACT :])
    np.testing.assert_array_equal(exact.matmul(a, b), first + rest)


def test_a_pre_rounded_operand_is_used_as_it_is_and_checked():
    rng = np.random.default_rng(5)
    a, b = rng.uniform(size=(8, 5)), rng.normal(size=(5, 3))
    ra = exact.rounded(a, 20)
    np.testing.assert_allclose(exact.matmul(ra, b), a @ b, rtol=0, atol=1e-5)
    with pytest.raises(ValueError, match="cannot be summed exactly"):
        exact.matmul(exact.rounded(a, 30), exact.rounded(b, 30))
    with pytest.raises(ValueError, match="needs"):
        exact.matmul(a, b.T)


def test_matmul_of_empty_and_zero_operands():
    assert exact.matmul(np.zeros((3, 0)), np.zeros((0, 2))).shape == (3, 2)
    np.testing.assert_array_equal(exact.matmul(np.zeros((2, 4)), np.ones((4, 3))), np.zeros((2, 3)))


# --- C's gradient against PyTorch's autograd ------------------------------------------------------


GRAD_CONFIGS = [
    ClassifierConfig(hidden=16, skip=True),
    ClassifierConfig(hidden=16, activation="tanh"),
    ClassifierConfig(hidden=16, activation="elu", depth=2),
    ClassifierConfig(hidden=16, compress=False),
    ClassifierConfig(m=7, n_features=3, hidden=5, depth=4, activation="tanh", skip=True, ignore=(1,)),
]


@pytest.mark.parametrize("config", GRAD_CONFIGS, ids=lambda c: f"{c.activation}-skip{c.skip}-compress{c.compress}-d{c.depth}")
def test_forward_and_gradient_equal_pytorch(config: ClassifierConfig):
    rng = np.random.default_rng(0)
    weights = init_weights(config, rng)
    net = TrainableClassifier(config, weights)
    U = rng.uniform(0, 1, (40, config.m, config.n_features))
    y = rng.integers(0, config.m, 40)
    logits, cache = net.forward(U, keep=True)
    loss, probs = cross_entropy(logits, y)
    grad_logits = probs.copy()
    grad_logits[np.arange(40), y] -= 1.0
    grads = net.backward(cache, grad_logits / 40)

    reference = UtilityClassifier(config).double()
    reference.load_state_dict({k: torch.tensor(v) for k, v in weights.items()})
    t_logits = reference(torch.tensor(U))
    t_loss = torch.nn.functional.cross_entropy(t_logits, torch.tensor(y))
    t_loss.backward()
    np.testing.assert_allclose(logits, t_logits.detach().numpy(), rtol=0, atol=2e-6)
    assert abs(float(np.mean(loss)) - float(t_loss.detach())) < 1e-7
    for name, p in reference.named_parameters():
        g = p.grad.numpy()
        np.testing.assert_allclose(grads[name], g, rtol=0, atol=2e-5 * max(1e-3, np.abs(g).max()), err_msg=name)
    # the planner's NumPy forward pass agrees as well
    np.testing.assert_allclose(numpy_forward(config, weights, U), logits, rtol=0, atol=2e-6)


def test_inputs_are_rounded_once_to_a_fixed_grid():
    U = np.array([[[0.0, 0.5, 1.0]]])
    r = round_inputs(U)
    assert r.unit == 2.0**-20 and r.bits == 20
    np.testing.assert_array_equal(r.ints * r.unit, U)
    assert round_inputs(np.array([[[3.0]]])).ints[0, 0, 0] * round_inputs(np.array([[[3.0]]])).unit == 3.0


def test_adam_follows_the_closed_form_first_step():
    """Adam's first step moves every weight by lr against the sign of its gradient."""
    w = {"a": np.array([1.0, -2.0, 0.5])}
    Adam(w, lr=0.1).step({"a": np.array([3.0, -0.01, 0.0])})
    np.testing.assert_allclose(w["a"], [0.9, -1.9, 0.5], atol=1e-6)


def test_adam_gives_the_numpy_forms_bits_over_many_steps():
    rng = np.random.default_rng(3)
    w = {"a": rng.normal(size=(4, 5)), "b": rng.normal(size=7)}
    ref = {k: v.copy() for k, v in w.items()}
    m = {k: np.zeros_like(v) for k, v in w.items()}
    v2 = {k: np.zeros_like(v) for k, v in w.items()}
    opt = Adam(w, lr=0.01)
    power1 = power2 = 1.0
    for _ in range(50):
        grads = {"a": rng.normal(size=(5, 4)).T, "b": rng.normal(size=7) * 1e-3}  # a transposed (strided) gradient too
        opt.step(grads)
        power1, power2 = power1 * 0.9, power2 * 0.999
        step, root2 = 0.01 / (1.0 - power1), math.sqrt(1.0 - power2)
        for k, g in grads.items():  # the NumPy form
            m[k] = 0.9 * m[k] + (1.0 - 0.9) * g
            v2[k] = 0.999 * v2[k] + (1.0 - 0.999) * (g * g)
            ref[k] -= step * m[k] / (np.sqrt(v2[k]) / root2 + 1e-8)
    for k in w:
        assert np.array_equal(w[k], ref[k])
    with pytest.raises(ValueError, match="C-contiguous"):
        Adam({"a": np.ones((3, 2)).T}, lr=0.1)


def test_init_uses_the_fan_in_bounds():
    w = init_weights(ClassifierConfig(hidden=64), np.random.default_rng(0))
    assert np.abs(w["layers.1.weight"]).max() <= 1 / 8 and np.abs(w["layers.1.weight"]).max() > 0.12
    assert np.abs(w["compress.weight"]).max() <= 1 / math.sqrt(5)


# --- the same weights under every instruction set, BLAS kernel and thread count -------------------

_TRAIN = """
import hashlib, numpy as np
from terrapref.dataset import Dataset
from terrapref.learning.train import TrainConfig, train
import sys; sys.path.insert(0, {tests!r})
from helpers import model_meta, train_config
rng = np.random.default_rng(0)
U = rng.uniform(0, 1, (500, 21, 5)).astype(np.float32)
labels = np.argmax(U @ np.array([-3.0, -1.5, -0.5, 0.5, 2.0], np.float32), axis=1)
data = Dataset(U, labels, np.zeros(500, np.float32), np.zeros(500, np.int64), {{"format": "terrapref-dataset/1", **model_meta()}})
from terrapref.rules import SecondStageConfig
r = train(data, train_config(epochs=4, batch_size=64, hidden=16, skip=True, class_balance=True, mirror=True), rules=[SecondStageConfig()])
h = hashlib.sha256()
for name in sorted(r.weights):
    h.update(r.weights[name].tobytes())
h.update(r.rules[0].utility.w.tobytes() + r.rules[0].utility.b.tobytes())
a, b = rng.normal(size=(256, 300)), rng.normal(size=(300, 64))
plain = hashlib.sha256((a @ b).tobytes() + np.exp(rng.normal(size=10000)).tobytes()).hexdigest()
print(h.hexdigest(), plain)
"""


CPU_CHECK = CpuCheck.of("training", _TRAIN.format(tests=str(TESTS)), SETTINGS)


def _same_training(runs: list) -> None:
    outputs = [(extra, *out.split()) for extra, out in runs]
    trained = {h for _, h, _ in outputs}
    assert len(trained) == 1, outputs
    if platform.machine().lower() in ("x86_64", "amd64"):
        # The settings do change plain float64 products or exponentials: the check above has teeth.
        assert len({p for _, _, p in outputs}) > 1, outputs


def test_training_gives_the_same_bits_under_an_older_blas_kernel(cpu_outputs):
    _same_training(cpu_outputs["training"])


@pytest.mark.slow
def test_training_gives_the_same_bits_under_every_cpu_setting(cpu_outputs_every):
    _same_training(cpu_outputs_every["training"])
