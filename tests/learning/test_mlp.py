"""C's training arithmetic runs as compiled loops around BLAS products; it must keep the bits of
its NumPy form.

The NumPy form below is the forward and backward pass as terrapref.learning.mlp computed them
before the loops were compiled (every product through exact.matmul): a model trained today must be
the same file as one trained then, on any CPU.
"""

from __future__ import annotations

import numpy as np
import pytest

from terrapref.learning import exact
from terrapref.learning import layers_compiled as kernels
from terrapref.learning.mlp import Adam, TrainableClassifier, _activate, _activation_slope, cross_entropy, init_weights, round_inputs
from terrapref.learning.network import ClassifierConfig


def _numpy_forward(config: ClassifierConfig, w: dict[str, np.ndarray], U: exact.Rounded):
    c = config
    n = len(U.ints)
    x = U._replace(ints=U.ints.reshape(n * c.m, c.n_features))
    if c.ignore:
        ints = x.ints.copy()
        ints[:, list(c.ignore)] = 0.0
        x = x._replace(ints=ints)
    scores = None
    if c.compress:
        per_row = exact.matmul(x, w["compress.weight"].T) + w["compress.bias"]
        scores = per_row.reshape(n, c.m, 1)[:, :, 0]
        h = per_row.reshape(n, c.m)
    else:
        h = (x.ints * x.unit).reshape(n, c.m * c.n_features)
    inputs, pre, post = [], [], []
    for i in range(c.depth):
        inputs.append(h)
        z = exact.matmul(h, w[f"layers.{i}.weight"].T) + w[f"layers.{i}.bias"]
        h = _activate(c.activation, z)
        pre.append(z)
        post.append(h)
    inputs.append(h)
    logits = exact.matmul(h, w[f"layers.{c.depth}.weight"].T) + w[f"layers.{c.depth}.bias"]
    if c.skip:
        logits = logits + scores
    return logits, (x, inputs, pre, post)


def _numpy_backward(config: ClassifierConfig, w: dict[str, np.ndarray], cache, grad_logits: np.ndarray) -> dict[str, np.ndarray]:
    c = config
    x, inputs_, pre, post = cache
    n = len(grad_logits)
    grads = {}
    g = grad_logits
    for i in range(c.depth, -1, -1):
        inputs = inputs_[i]
        both = exact.matmul(g.T, np.concatenate([inputs, np.ones((n, 1))], axis=1))
        grads[f"layers.{i}.weight"], grads[f"layers.{i}.bias"] = both[:, :-1], both[:, -1]
        dh = exact.matmul(g, w[f"layers.{i}.weight"])
        g = dh * _activation_slope(c.activation, pre[i - 1], post[i - 1]) if i > 0 else dh
    if c.compress:
        per_row = g.reshape(n, c.m, 1)
        if c.skip:
            per_row = per_row.copy()
            per_row[:, :, 0] += grad_logits
        flat = per_row.reshape(n * c.m, 1)
        grads["compress.weight"] = exact.matmul(flat.T, x)
        grads["compress.bias"] = exact.matmul(np.ones((1, len(flat))), flat)[0]
    return grads


def _numpy_loss_grad(logits: np.ndarray, y: np.ndarray, class_w: np.ndarray):
    loss, probs = cross_entropy(logits, y)
    hits = int(np.count_nonzero(np.argmax(logits, axis=1) == y))
    scale = class_w[y] / float(len(y))
    probs[np.arange(len(y)), y] -= 1.0
    return loss, probs * scale[:, None], hits


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


CONFIGS = [
    ClassifierConfig(hidden=64, skip=True),
    ClassifierConfig(hidden=16),
    ClassifierConfig(hidden=16, activation="tanh"),
    ClassifierConfig(hidden=16, activation="elu", depth=2),
    ClassifierConfig(hidden=16, compress=False),
    ClassifierConfig(m=7, n_features=3, hidden=5, depth=4, activation="tanh", skip=True, ignore=(1,)),
]


@pytest.mark.parametrize("config", CONFIGS, ids=lambda c: f"{c.activation}-h{c.hidden}-skip{c.skip}-compress{c.compress}-d{c.depth}")
@pytest.mark.parametrize("batch", [1, 52, 256])
def test_training_step_gives_the_numpy_forms_bits(config: ClassifierConfig, batch: int):
    rng = np.random.default_rng(batch)
    weights = init_weights(config, rng)
    U = round_inputs(rng.uniform(0, 1, (batch, config.m, config.n_features)) * (rng.random((batch, config.m, config.n_features)) < 0.5))
    y = rng.integers(0, config.m, batch)
    class_w = rng.uniform(0.5, 2.0, config.m)
    net = TrainableClassifier(config, {k: v.copy() for k, v in weights.items()})
    logits, cache = net.forward(U, keep=True)
    want_logits, want_cache = _numpy_forward(config, weights, U)
    assert _same_bits(logits, want_logits)
    loss, grad, hits = kernels.cross_entropy_grad(logits, y, class_w)
    want_loss, want_grad, want_hits = _numpy_loss_grad(want_logits, y, class_w)
    assert _same_bits(loss, want_loss) and _same_bits(grad, want_grad) and hits == want_hits
    grads = net.backward(cache, grad)
    want = _numpy_backward(config, weights, want_cache, want_grad)
    assert grads.keys() == want.keys()
    for name in want:
        assert _same_bits(grads[name], want[name]), name


def test_a_batch_longer_than_one_exact_sum_of_compression_terms():
    """6,300 frames of 21 trajectories: the compression's gradient is a sum of 132,300 terms, cut into exact chunks."""
    config = ClassifierConfig(hidden=4, skip=True)
    rng = np.random.default_rng(9)
    weights = init_weights(config, rng)
    U = round_inputs(rng.uniform(0, 1, (6300, 21, 5)))
    y = rng.integers(0, 21, 6300)
    net = TrainableClassifier(config, weights)
    logits, cache = net.forward(U, keep=True)
    _, grad, _ = kernels.cross_entropy_grad(logits, y, np.ones(21))
    grads = net.backward(cache, grad)
    want = _numpy_backward(config, weights, _numpy_forward(config, weights, U)[1], grad)
    assert all(_same_bits(grads[k], want[k]) for k in want)


def test_flat_gradient_and_adam_give_the_named_forms_bits():
    """Training updates every weight in one pass over the flat buffer: the same bits as by name."""
    config = ClassifierConfig(hidden=16, skip=True)
    rng = np.random.default_rng(4)
    weights = init_weights(config, rng)
    by_name = TrainableClassifier(config, {k: v.copy() for k, v in weights.items()})
    flat = TrainableClassifier(config, {k: v.copy() for k, v in weights.items()})
    assert all(np.shares_memory(flat.weights[k], flat.params) for k in weights)
    named_opt, flat_opt = Adam(by_name.weights, lr=0.01), Adam(flat.params, lr=0.01)
    for _ in range(5):
        U = round_inputs(rng.uniform(0, 1, (64, 21, 5)))
        y = rng.integers(0, 21, 64)
        for net, opt in ((by_name, named_opt), (flat, flat_opt)):
            logits, cache = net.forward(U, keep=True)
            _, grad, _ = kernels.cross_entropy_grad(logits, y, np.ones(21))
            if opt is named_opt:
                opt.step(net.backward(cache, grad))
            else:
                buffer = net.gradient(cache, grad)
                assert all(
                    _same_bits(buffer[net._at[k] : net._at[k] + v.size], net.backward(cache, grad)[k].ravel())
                    for k, v in net.weights.items()
                )
                opt.step(buffer)
    assert all(_same_bits(by_name.weights[k], flat.weights[k]) for k in weights)
    with pytest.raises(ValueError, match="values for"):
        flat_opt.step(np.zeros(3))
