"""The classifier C (SPEC 8): a shared row-wise 5 -> 1 compression, three hidden layers, m logits.

This is C's readable NumPy forward pass (the ONNX export's reference, and the tests'); the
planner's control loop runs the same network as one compiled loop
(:mod:`terrapref.learning.forward`, the same F_t on every CPU). Training runs its own forward and backward pass with
CPU-independent arithmetic (:mod:`terrapref.learning.mlp`) over the same named weights; the
PyTorch definition (tests/torch_net.py) remains as an independent reference that the tests
check both against.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass

import numpy as np

from terrapref.configargs import option
from terrapref.records import from_plain, to_plain

ACTIVATIONS = ("relu", "tanh", "elu")
MAX_WEIGHTS = 50_000_000  # 200 MB of float32 per model; C has about 10,000


@dataclass(frozen=True)
class ClassifierConfig:
    """Shape of C.

    Attributes:
        m: trajectories (logits).
        n_features: utilities per trajectory (K terrain classes + distance).
        hidden: width of each of the three hidden layers (our choice: 64).
        activation: hidden activation, one of relu (default), tanh, elu.
        depth: number of hidden layers (paper: 3).
        compress: True for the paper's shared row-wise compression; False flattens U into
            an m * n_features vector instead (an ablation).
        skip: add the compressed scores to the logits (a residual path, so the identity
            "pick the best-scored trajectory" is the starting point); False is the paper's C.
        ignore: indices of U's columns the classifier never sees (set to zero): an ablation.
        members: networks of this shape, trained apart from different seeds; C's F_t is the
            mean of their softmax outputs (1: the paper's single network).
    """

    m: int = 21
    n_features: int = 5
    hidden: int = option(64, "width of each hidden layer")
    activation: str = option("relu", "hidden activation", choices=ACTIVATIONS)
    depth: int = 3
    compress: bool = True
    skip: bool = option(False, "add the compressed scores to the logits (a residual path)")
    ignore: tuple[int, ...] = ()
    members: int = option(1, "networks trained from different seeds; the model averages their F_t")

    def __post_init__(self) -> None:
        object.__setattr__(self, "ignore", tuple(int(i) for i in self.ignore))
        sizes = (self.m, self.n_features, self.hidden, self.depth, self.members)
        if any(isinstance(v, bool) or not isinstance(v, numbers.Integral) for v in sizes):
            raise ValueError("m, n_features, hidden, depth and members must be integers")
        if any(not 0 <= i < self.n_features for i in self.ignore):
            raise ValueError("ignore: column index out of range")
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"activation must be one of {', '.join(ACTIVATIONS)}")
        for name, low in (("m", 2), ("n_features", 1), ("hidden", 1), ("depth", 1), ("members", 1)):
            if getattr(self, name) < low:
                raise ValueError(f"{name} must be >= {low}")
        if self.skip and not self.compress:
            raise ValueError("skip needs the row-wise compression")

    def check_trainable(self) -> None:
        """Refuse, before anything is allocated, networks too large to train (a header read from
        a file is checked against the weights it holds instead)."""
        if self.weight_count > MAX_WEIGHTS:
            raise ValueError(
                f"hidden {self.hidden} x depth {self.depth} x members {self.members} gives about {self.weight_count:,} weights "
                f"({self.weight_count * 4 / 2**30:,.1f} GiB); at most {MAX_WEIGHTS:,}"
            )

    @property
    def weight_count(self) -> int:
        """How many weights the networks hold (all members), before any is allocated."""
        h = self.hidden
        per_member = self.width_in * h + h + (self.depth - 1) * (h * h + h) + h * self.m + self.m
        return self.members * per_member

    def to_dict(self) -> dict:
        return to_plain(self)

    @property
    def width_in(self) -> int:
        """Inputs of the first hidden layer."""
        return self.m if self.compress else self.m * self.n_features

    @classmethod
    def from_dict(cls, data: dict) -> ClassifierConfig:
        """The configuration a model file's header holds. A header may name ``channels``, the
        row-wise compression's outputs per trajectory: 1 is what C is; more are refused."""
        data = dict(data)
        if data.get("channels", 1) != 1:
            raise ValueError(
                f"channels {data['channels']!r}: more than one compression output per trajectory is no longer supported; train the model again"
            )
        data.pop("channels", None)
        return from_plain(cls, data)


def _act(name: str, x: np.ndarray) -> np.ndarray:
    if name == "relu":
        return np.maximum(x, 0.0, out=x)
    if name == "tanh":
        return np.tanh(x, out=x)
    return np.where(x > 0, x, np.expm1(np.minimum(x, 0.0)))  # elu, alpha = 1


MEMBERS = "members"  # weight names of an ensemble's members start with this


def member_prefix(j: int) -> str:
    """Weight-name prefix of member ``j`` of an ensemble (as an ``nn.ModuleList`` of members would name it)."""
    return f"{MEMBERS}.{j}."


def numpy_forward(config: ClassifierConfig, weights: dict[str, np.ndarray], U: np.ndarray) -> np.ndarray:
    """Logits of C for U of shape (m, k) or (B, m, k); returns (m,) or (B, m).

    ``weights`` uses the PyTorch state-dict names: compress.weight (1, k),
    compress.bias (1,), layers.{i}.weight (out, in), layers.{i}.bias (out,); each
    prefixed by ``members.{j}.`` in an ensemble, whose logits are the log of the members' mean
    softmax (so that the softmax of the result is that mean). A caller that runs the same
    weights on many frames builds their :class:`StackedWeights` once and calls
    :func:`stacked_forward`.
    """
    return stacked_forward(config, StackedWeights.of(config, weights), U)


@dataclass(frozen=True)
class StackedWeights:
    """C's weights with the members stacked on a first axis, transposed as the forward pass
    multiplies them: every member's product is then one slice of one batched ``matmul``, the
    same BLAS call on the same strided operands as a member on its own (so the same bits).

    Attributes:
        compress: (M, k, 1) and (M, 1), the row-wise compression's weight and bias (None
            without the compression).
        layers: per layer, (M, in, out) and (M, out).
    """

    compress: tuple[np.ndarray, np.ndarray] | None
    layers: tuple[tuple[np.ndarray, np.ndarray], ...]

    @classmethod
    def of(cls, config: ClassifierConfig, weights: dict[str, np.ndarray]) -> StackedWeights:
        prefixes = [member_prefix(j) for j in range(config.members)] if config.members > 1 else [""]

        def stack(name: str) -> np.ndarray:
            return np.stack([weights[p + name] for p in prefixes])

        def transposed(name: str) -> np.ndarray:
            return stack(name).transpose(0, 2, 1)  # (M, in, out): each slice a view like W.T

        compress = (transposed("compress.weight"), stack("compress.bias")) if config.compress else None
        return cls(compress, tuple((transposed(f"layers.{i}.weight"), stack(f"layers.{i}.bias")) for i in range(config.depth + 1)))


def stacked_forward(config: ClassifierConfig, stacked: StackedWeights, U: np.ndarray) -> np.ndarray:
    """:func:`numpy_forward` with the weights already stacked."""
    single = U.ndim == 2
    x = U[None] if single else U
    if config.ignore:
        x = x.copy()
        x[..., list(config.ignore)] = 0.0
    n = len(x)
    members = len(stacked.layers[0][0])
    if stacked.compress is not None:
        w, b = stacked.compress
        per_row = x[None] @ w[:, None] + b[:, None, None, :]  # (M, B, m, 1)
        scores = per_row[..., 0]
        h = per_row.reshape(members, n, -1)
    else:
        scores = h = np.broadcast_to(x.reshape(1, n, -1), (members, n, x.shape[1] * x.shape[2]))
    for w, b in stacked.layers[:-1]:
        h = _act(config.activation, h @ w + b[:, None, :])
    w, b = stacked.layers[-1]
    logits = h @ w + b[:, None, :]  # (M, B, m)
    if config.skip:
        logits = logits + scores
    if members == 1:
        logits = logits[0]
    else:
        p = softmax(logits)
        probs = p[0]
        for j in range(1, members):  # in member order, as learning/forward.py adds them (a sum over the axis may not)
            probs = probs + p[j]
        logits = np.log(probs * (1.0 / members) + 1e-30)
    return logits[0] if single else logits


def softmax(logits: np.ndarray) -> np.ndarray:
    z = np.exp(logits - logits.max(axis=-1, keepdims=True))
    return z / z.sum(axis=-1, keepdims=True)
