"""The classifier C (SPEC 8): the NumPy forward pass against the PyTorch network, the skip path,
softmax, and its configuration's checks."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from helpers import K, M, assert_weights_equal
from terrapref.learning.network import ClassifierConfig, numpy_forward, softmax
from torch_net import UtilityClassifier

# --- the NumPy forward pass is the PyTorch network ------------------------------------------------


CONFIGS = [
    ClassifierConfig(),
    ClassifierConfig(activation="tanh"),
    ClassifierConfig(activation="elu"),
    ClassifierConfig(skip=True),
    ClassifierConfig(activation="tanh", skip=True),
    ClassifierConfig(activation="elu", skip=True, hidden=17, depth=2),
    ClassifierConfig(compress=False),
    ClassifierConfig(activation="elu", compress=False, depth=1),
    ClassifierConfig(m=7, n_features=3, hidden=5, depth=4, activation="tanh", skip=True),
]


@pytest.mark.parametrize(
    "config",
    CONFIGS,
    ids=lambda c: f"{c.activation}-d{c.depth}-h{c.hidden}-m{c.m}k{c.n_features}{'-skip' if c.skip else ''}{'' if c.compress else '-flat'}",
)
def test_numpy_forward_equals_torch(config: ClassifierConfig):
    torch.manual_seed(3)
    net = UtilityClassifier(config).eval()
    weights = {k: v.detach().numpy().copy() for k, v in net.state_dict().items()}
    # Wider than [0, 1] so that every activation's negative side is exercised.
    U = np.random.default_rng(1).uniform(-2, 2, (9, config.m, config.n_features)).astype(np.float32)
    U_before, w_before = U.copy(), {k: v.copy() for k, v in weights.items()}
    with torch.no_grad():
        expected = net(torch.from_numpy(U)).numpy()
    batch = numpy_forward(config, weights, U)
    assert batch.shape == (9, config.m)
    np.testing.assert_allclose(batch, expected, atol=1e-5, rtol=0)
    for b in range(len(U)):
        single = numpy_forward(config, weights, U[b])
        assert single.shape == (config.m,)
        np.testing.assert_allclose(single, expected[b], atol=1e-5, rtol=0)
    # The forward pass works in place on its own buffers, never on the caller's.
    np.testing.assert_array_equal(U, U_before)
    assert_weights_equal(weights, w_before)


def test_skip_adds_the_compressed_scores_to_the_logits():
    config = ClassifierConfig(skip=True, hidden=4)
    torch.manual_seed(0)
    weights = {k: v.detach().numpy().copy() for k, v in UtilityClassifier(config).state_dict().items()}
    U = np.random.default_rng(0).uniform(0, 1, (M, K)).astype(np.float32)
    plain = numpy_forward(replace(config, skip=False), weights, U)
    scores = U @ weights["compress.weight"][0] + weights["compress.bias"][0]
    np.testing.assert_allclose(numpy_forward(config, weights, U), plain + scores, atol=1e-6)


def test_headers_of_older_files_with_one_channel_load_and_others_are_refused():
    """Model files from before the compression's ``channels`` option left say ``channels: 1``
    (what C is); any other count names the field."""
    header = {**ClassifierConfig(skip=True).to_dict(), "channels": 1}
    assert ClassifierConfig.from_dict(header) == ClassifierConfig(skip=True)
    with pytest.raises(ValueError, match="channels"):
        ClassifierConfig.from_dict({**header, "channels": 2})


def test_softmax_is_a_distribution_over_the_last_axis():
    logits = np.array([[1000.0, 1000.0, 0.0], [-5.0, 0.0, 5.0]])
    p = softmax(logits)
    assert np.all(np.isfinite(p))  # no overflow for huge logits
    np.testing.assert_allclose(p.sum(axis=-1), 1.0)
    np.testing.assert_allclose(p[0], [0.5, 0.5, 0.0], atol=1e-12)
    np.testing.assert_array_equal(np.argmax(p, axis=-1), np.argmax(logits, axis=-1))


@pytest.mark.parametrize("bad", [dict(activation="sigmoid"), dict(m=1), dict(hidden=0), dict(depth=0), dict(skip=True, compress=False)])
def test_classifier_config_is_validated(bad: dict):
    with pytest.raises(ValueError):
        ClassifierConfig(**bad)


# --- the members stacked give each member's own bits ---------------------------------------------


def _per_member_forward(config: ClassifierConfig, weights: dict[str, np.ndarray], U: np.ndarray) -> np.ndarray:
    """numpy_forward as it was before the members were stacked: one network at a time."""
    from terrapref.learning.network import _act, member_prefix

    single = U.ndim == 2
    x = U[None] if single else U
    if config.ignore:
        x = x.copy()
        x[..., list(config.ignore)] = 0.0

    def one(prefix: str) -> np.ndarray:
        if config.compress:
            per_row = x @ weights[f"{prefix}compress.weight"].T + weights[f"{prefix}compress.bias"]
            scores, h = per_row[..., 0], per_row.reshape(len(x), -1)
        else:
            scores = h = x.reshape(len(x), -1)
        for i in range(config.depth):
            h = _act(config.activation, h @ weights[f"{prefix}layers.{i}.weight"].T + weights[f"{prefix}layers.{i}.bias"])
        logits = h @ weights[f"{prefix}layers.{config.depth}.weight"].T + weights[f"{prefix}layers.{config.depth}.bias"]
        return logits + scores if config.skip else logits

    if config.members == 1:
        logits = one("")
    else:
        probs = sum(softmax(one(member_prefix(j))) for j in range(config.members))
        logits = np.log(probs * (1.0 / config.members) + 1e-30)
    return logits[0] if single else logits


@pytest.mark.parametrize(
    "config",
    [
        *CONFIGS[:7],
        ClassifierConfig(members=3, skip=True),
        ClassifierConfig(members=2, activation="tanh", ignore=(1, 3)),
        ClassifierConfig(members=3, compress=False, activation="elu"),
        ClassifierConfig(members=1, ignore=(0,)),
    ],
    ids=lambda c: (
        f"{c.activation}-d{c.depth}-M{c.members}{'-skip' if c.skip else ''}{'' if c.compress else '-flat'}{'-ignore' if c.ignore else ''}"
    ),
)
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_stacked_members_give_the_per_member_bits(config: ClassifierConfig, dtype):
    rng = np.random.default_rng(8)
    weights: dict[str, np.ndarray] = {}
    for j in range(config.members):
        torch.manual_seed(j)
        prefix = f"members.{j}." if config.members > 1 else ""
        member = UtilityClassifier(replace(config, members=1))
        weights.update({prefix + k: v.detach().numpy().copy() for k, v in member.state_dict().items()})
    for _ in range(30):
        U = (rng.uniform(-0.5, 1.5, (config.m, config.n_features)) * (rng.random((config.m, config.n_features)) < 0.6)).astype(dtype)
        for x in (U, np.stack([U, U[::-1], U * 0.5])):
            got, expected = numpy_forward(config, weights, x), _per_member_forward(config, weights, x)
            assert got.dtype == expected.dtype and got.shape == expected.shape
            assert np.array_equal(got, expected), "the stacked forward pass moved a bit"
