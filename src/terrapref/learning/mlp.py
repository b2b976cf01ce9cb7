"""C for training: forward, backward and Adam in NumPy, with arithmetic that is the same on every CPU.

The same network as :func:`terrapref.learning.network.numpy_forward` (and the same weight
names, those of a PyTorch state dict), written out with its gradient by hand. Every product goes
through :func:`terrapref.learning.exact.matmul` and every exponential through
:func:`terrapref.learning.exact.exp`, so a training run gives the same weights, bit for bit,
on any x86_64 or arm64 CPU, whatever BLAS kernel or thread count it has (docs/design.md).
The network is a few thousand weights, small enough that NumPy trains it as fast as PyTorch does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from terrapref.learning import exact
from terrapref.learning import layers_compiled as kernels
from terrapref.learning.network import ClassifierConfig


def init_weights(config: ClassifierConfig, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Initial weights (float64) under the state-dict names: each layer U(-1/sqrt(fan_in), 1/sqrt(fan_in)).

    The same bounds as PyTorch's ``nn.Linear`` default, drawn from ``rng`` (whose streams are
    the same on every platform).
    """
    weights: dict[str, np.ndarray] = {}

    def linear(name: str, fan_in: int, fan_out: int) -> None:
        bound = 1.0 / math.sqrt(fan_in)
        weights[f"{name}.weight"] = rng.uniform(-bound, bound, (fan_out, fan_in))
        weights[f"{name}.bias"] = rng.uniform(-bound, bound, fan_out)

    if config.compress:
        linear("compress", config.n_features, 1)
    dims = [config.width_in] + [config.hidden] * config.depth + [config.m]
    for i, (a, b) in enumerate(zip(dims[:-1], dims[1:])):
        linear(f"layers.{i}", a, b)
    return weights


INPUT_BITS = 20  # U's entries lie in [0, 1]: rounded to multiples of 2 ** -20


def round_inputs(U: np.ndarray) -> exact.Rounded:
    """U (B, m, k) on the fixed-point grid of C's inputs; round a dataset once and index it."""
    top = float(np.max(np.abs(U))) if np.size(U) else 0.0
    # One grid for every batch: relative to 1 (U's range), or to the largest entry if larger.
    return (
        exact.rounded(np.asarray(U, dtype=np.float64), INPUT_BITS)
        if top > 1.0
        else exact.Rounded(np.rint(np.asarray(U, dtype=np.float64) * 2.0**INPUT_BITS), 2.0**-INPUT_BITS, INPUT_BITS)
    )


def _activate(name: str, z: np.ndarray) -> np.ndarray:
    if name == "relu":
        return np.maximum(z, 0.0)
    if name == "tanh":
        return 1.0 - 2.0 / (exact.exp(2.0 * z) + 1.0)
    return np.where(z > 0, z, exact.exp(np.minimum(z, 0.0)) - 1.0)  # elu, alpha = 1


def _activation_slope(name: str, z: np.ndarray, h: np.ndarray) -> np.ndarray:
    """d act / d z at ``z``, given ``h = act(z)``."""
    if name == "relu":
        return (z > 0).astype(np.float64)
    if name == "tanh":
        return 1.0 - h * h
    return np.where(z > 0, 1.0, h + 1.0)


@dataclass
class _Cache:
    """What the backward pass needs from the forward pass of one batch."""

    x: exact.Rounded  # (B * m, k) inputs, ignored columns zeroed
    inputs: list[np.ndarray]  # input of each hidden and output layer
    pre: list[np.ndarray]  # pre-activation of each hidden layer
    post: list[np.ndarray]  # activation of each hidden layer
    weights: list[tuple[exact.Rounded, exact.Rounded]]  # each layer's weight on its forward and its backward grid


def _bits(k: int) -> tuple[int, int]:
    """The bits :func:`exact.matmul` gives two plain operands of a sum of ``k`` exact products:
    the first half the room the sum leaves, the second the rest (at most 26)."""
    room = 53 - exact.sum_bits(k)
    return room // 2, min(26, room - room // 2)


class TrainableClassifier:
    """C's weights (float64) with an exact forward pass and its gradient.

    Each product is :func:`exact.matmul`'s (operands rounded to their grids, integers multiplied
    in BLAS, exact in any order); the rounding and the elementwise work around the products run
    as compiled loops (:mod:`terrapref.learning.layers_compiled`), with the bits of the NumPy forms.
    The weights live in one flat buffer, ``params``; ``weights`` holds a view of each under its
    state-dict name, and :meth:`gradient` fills a buffer laid out the same way, so that Adam
    updates all of them in one pass.
    """

    def __init__(self, config: ClassifierConfig, weights: dict[str, np.ndarray]) -> None:
        self.config = config
        self.params = np.concatenate([np.asarray(w, dtype=np.float64).ravel() for w in weights.values()])
        self._shapes = {name: tuple(np.shape(w)) for name, w in weights.items()}
        sizes = [int(np.prod(shape)) for shape in self._shapes.values()]
        self._at = dict(zip(self._shapes, np.cumsum([0] + sizes[:-1]).tolist()))  # each weight's offset in params
        self.weights = self._views(self.params, self._shapes)
        # Every layer's weight is rounded twice a step: for the forward product (K = its inputs)
        # and for the backward one (K = its outputs).
        spans = []
        for i in range(config.depth + 1):
            out, inp = self._shapes[f"layers.{i}.weight"]
            at = self._at[f"layers.{i}.weight"]
            spans += [(at, at + out * inp, _bits(inp)[1]), (at, at + out * inp, _bits(out)[1])]
        self._spans = np.array(spans, dtype=np.int64)

    @staticmethod
    def _views(buffer: np.ndarray, shapes: dict[str, tuple[int, ...]]) -> dict[str, np.ndarray]:
        views, at = {}, 0
        for name, shape in shapes.items():
            size = int(np.prod(shape))
            views[name] = buffer[at : at + size].reshape(shape)
            at += size
        return views

    def forward(self, U: np.ndarray | exact.Rounded, keep: bool = False) -> tuple[np.ndarray, _Cache | None]:
        """Logits (B, m) for U (B, m, k), or U already rounded (:func:`round_inputs`); with
        ``keep``, also what :meth:`backward` needs."""
        c, w = self.config, self.weights
        if not isinstance(U, exact.Rounded):
            U = round_inputs(U)
        n = len(U.ints)
        x = U._replace(ints=np.ascontiguousarray(U.ints, dtype=np.float64).reshape(n * c.m, c.n_features))
        if c.ignore:
            ints = x.ints.copy()
            ints[:, list(c.ignore)] = 0.0
            x = x._replace(ints=ints)
        scores = _NO_ROWS
        if c.compress:
            h = scores = kernels.compress_forward(x.ints, x.unit, x.bits, w["compress.weight"], w["compress.bias"]).reshape(n, c.m)
        else:
            h = (x.ints * x.unit).reshape(n, c.m * c.n_features)
        layers = self._rounded_weights()
        inputs, pre, post = [], [], []
        rounded = _rounded(h, _bits(h.shape[1])[0]) if h.shape[1] <= exact.MAX_EXACT else None
        for i in range(c.depth):
            inputs.append(h)
            z, h, rounded = self._layer(h, rounded, layers[i][0], i, c.activation, _NO_ROWS)
            pre.append(z)
            post.append(h)
        inputs.append(h)
        logits, _, _ = self._layer(h, rounded, layers[c.depth][0], c.depth, None, scores if c.skip else _NO_ROWS)
        return logits, (_Cache(x, inputs, pre, post, layers) if keep else None)

    def _rounded_weights(self) -> list[tuple[exact.Rounded, exact.Rounded]]:
        """Each layer's weight (out, in) on its forward and its backward grid, in one compiled call."""
        ints, units = kernels.round_spans(self.params, self._spans)
        out, at = [], 0
        for i in range(self.config.depth + 1):
            shape = self._shapes[f"layers.{i}.weight"]
            size = shape[0] * shape[1]
            pair = tuple(
                exact.Rounded(
                    ints[at + j * size : at + (j + 1) * size].reshape(shape), float(units[2 * i + j]), int(self._spans[2 * i + j, 2])
                )
                for j in range(2)
            )
            out.append(pair)
            at += 2 * size
        return out

    def _layer(
        self, h: np.ndarray, rounded: exact.Rounded | None, weight: exact.Rounded, i: int, activation: str | None, skip: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, exact.Rounded | None]:
        """``z = matmul(h, W_i.T) + b_i (+ skip)``, the activation of z (z itself for the output
        layer) and that activation on the next layer's grid (``rounded`` is ``h`` on this one's)."""
        bias = self.weights[f"layers.{i}.bias"]
        if rounded is None:  # a sum longer than one exact chunk: exact.matmul cuts it
            product, unit = exact.matmul(h, self.weights[f"layers.{i}.weight"].T), 1.0
        else:
            product, unit = rounded.ints @ weight.ints.T, rounded.unit * weight.unit
        width = weight.ints.shape[0]
        next_bits = _bits(width)[0] if activation is not None and width <= exact.MAX_EXACT else 0
        relu = activation == "relu"
        z, out, ints, out_unit = kernels.affine(product, unit, bias, relu, skip, next_bits if relu else 0)
        if activation is not None and not relu:
            out = _activate(activation, z)
            return z, out, _rounded(out, next_bits) if next_bits else None
        return z, out, exact.Rounded(ints, out_unit, next_bits) if next_bits else None

    def backward(self, cache: _Cache, grad_logits: np.ndarray) -> dict[str, np.ndarray]:
        """Gradients of the loss under the weight names, given d loss / d logits (B, m)."""
        return self._views(self.gradient(cache, grad_logits), self._shapes)

    def gradient(self, cache: _Cache, grad_logits: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """The gradient as one flat buffer laid out as ``params`` (into ``out`` when given)."""
        c = self.config
        grads = np.empty_like(self.params) if out is None else out
        g = np.ascontiguousarray(grad_logits, dtype=np.float64)
        batch = len(g)
        a_bits, b_bits = _bits(batch)  # g's and [inputs, 1]'s grids for the weight gradients, the same for every layer
        for i in range(c.depth, -1, -1):
            out_i = cache.weights[i][1].ints.shape[0]
            if batch <= exact.MAX_EXACT and out_i <= exact.MAX_EXACT:
                # g on the grids of both its products at once (one pass for its largest magnitude):
                # the weight and bias gradients, [inputs, 1]^T g, and d loss / d the layer's input.
                g_w, g_w_unit, g_in, g_in_unit = kernels.round_twice(np.ascontiguousarray(g, dtype=np.float64), a_bits, _bits(out_i)[0])
                ones_ints, ones_unit = kernels.round_with_ones(np.ascontiguousarray(cache.inputs[i], dtype=np.float64), b_bits)
                kernels.scale_into(
                    g_w.T @ ones_ints, g_w_unit * ones_unit, grads, self._at[f"layers.{i}.weight"], self._at[f"layers.{i}.bias"]
                )
                weight = cache.weights[i][1]
                product, unit = g_in @ weight.ints, g_in_unit * weight.unit
            else:
                # The weight and bias gradients in one exact product, [inputs, 1]^T g, into the buffer.
                self._weight_grads(g, cache.inputs[i], i, grads)
                # d loss / d the layer's input, through the activation below it.
                if out_i > exact.MAX_EXACT:  # a sum longer than one exact chunk: exact.matmul cuts it
                    product, unit = exact.matmul(g, self.weights[f"layers.{i}.weight"]), 1.0
                else:
                    a = _rounded(g, _bits(out_i)[0])
                    weight = cache.weights[i][1]
                    product, unit = a.ints @ weight.ints, a.unit * weight.unit
            if i == 0:
                g = product * unit
            else:
                slope = _NO_ROWS if c.activation == "relu" else _activation_slope(c.activation, cache.pre[i - 1], cache.post[i - 1])
                g = kernels.scaled_slope(product, unit, cache.pre[i - 1], slope)
        if c.compress:
            per_row = g + grad_logits if c.skip else g
            columns = np.ascontiguousarray(cache.x.ints.T)
            weight, bias = kernels.compress_grads(np.ascontiguousarray(per_row).reshape(-1), columns, cache.x.unit, cache.x.bits)
            grads[self._at["compress.weight"] : self._at["compress.weight"] + weight.size] = weight.ravel()
            grads[self._at["compress.bias"]] = bias[0]
        return grads

    def _weight_grads(self, g: np.ndarray, inputs: np.ndarray, i: int, grads: np.ndarray) -> None:
        """``exact.matmul(g.T, concatenate([inputs, ones((B, 1))], axis=1))`` split into layer i's
        weight (out, in) and bias (out,) gradients, written into ``grads``."""
        n = len(g)
        w_at, b_at = self._at[f"layers.{i}.weight"], self._at[f"layers.{i}.bias"]
        if n > exact.MAX_EXACT:  # a batch longer than one exact sum: exact.matmul cuts it into chunks
            kernels.scale_into(exact.matmul(g.T, np.concatenate([inputs, np.ones((n, 1))], axis=1)), 1.0, grads, w_at, b_at)
            return
        a_bits, b_bits = _bits(n)
        a = _rounded(g, a_bits)
        ones_ints, ones_unit = kernels.round_with_ones(np.ascontiguousarray(inputs, dtype=np.float64), b_bits)
        kernels.scale_into(a.ints.T @ ones_ints, a.unit * ones_unit, grads, w_at, b_at)


_NO_ROWS = np.zeros((0, 0))  # kernels.affine: no residual path to add; kernels.scaled_slope: a ReLU's slope


def _rounded(x: np.ndarray, bits: int) -> exact.Rounded:
    """:func:`exact.rounded` of a float64 array, in one compiled call."""
    flat = np.ascontiguousarray(x, dtype=np.float64).reshape(-1)
    ints = np.empty_like(flat)
    return exact.Rounded(ints.reshape(x.shape), exact.round_into(flat, bits, ints), bits)


class Adam:
    """Adam (Kingma and Ba), with PyTorch's defaults; elementwise only.

    Args:
        weights: the weights it updates in place, by name (writeable C-contiguous float64
            arrays), or one flat buffer of them (``TrainableClassifier.params``), which it then
            updates in one pass from a flat gradient.
    """

    def __init__(
        self, weights: dict[str, np.ndarray] | np.ndarray, lr: float, betas: tuple[float, float] = (0.9, 0.999), eps: float = 1e-8
    ) -> None:
        self.weights, self.lr, self.betas, self.eps = weights, lr, betas, eps
        arrays = [weights] if isinstance(weights, np.ndarray) else list(weights.values())
        if not all(w.dtype == np.float64 and w.flags.c_contiguous and w.flags.writeable for w in arrays):
            raise ValueError("Adam updates the weights in place: they must be writeable C-contiguous float64 arrays")
        if isinstance(weights, np.ndarray):
            self.m, self.v = np.zeros_like(weights), np.zeros_like(weights)
        else:
            self.m = {k: np.zeros_like(v) for k, v in weights.items()}
            self.v = {k: np.zeros_like(v) for k, v in weights.items()}
        self.power1 = self.power2 = 1.0  # beta ** t by repeated products (no pow(), whose last bit may vary)

    def step(self, grads: dict[str, np.ndarray] | np.ndarray) -> None:
        """One update from the gradients: by name, or one flat buffer for a flat buffer of weights."""
        b1, b2 = self.betas
        self.power1 *= b1
        self.power2 *= b2
        step = self.lr / (1.0 - self.power1)
        root2 = math.sqrt(1.0 - self.power2)
        if isinstance(self.weights, np.ndarray):
            g = np.ascontiguousarray(grads, dtype=np.float64).reshape(-1)
            if g.size != self.weights.size:
                raise ValueError(f"gradient: {g.size} values for {self.weights.size} weights")
            _adam_update(self.weights.reshape(-1), self.m.reshape(-1), self.v.reshape(-1), g, b1, b2, step, root2, self.eps)
            return
        for name, p in self.weights.items():
            g = np.ascontiguousarray(grads[name], dtype=np.float64).reshape(-1)
            if g.size != p.size:
                raise ValueError(f"gradient of {name}: {g.size} values for {p.size} weights")
            _adam_update(p.reshape(-1), self.m[name].reshape(-1), self.v[name].reshape(-1), g, b1, b2, step, root2, self.eps)


@njit(cache=True, nogil=True)
def _adam_update(
    p: np.ndarray, m: np.ndarray, v: np.ndarray, g: np.ndarray, b1: float, b2: float, step: float, root2: float, eps: float
) -> None:
    """In place, per element, the NumPy form ``m = b1 m + (1 - b1) g; v = b2 v + (1 - b2) g g;
    p -= step m / (sqrt(v) / root2 + eps)``, in one pass (the same operations in the same order)."""
    for i in range(p.shape[0]):
        m[i] = b1 * m[i] + (1.0 - b1) * g[i]
        v[i] = b2 * v[i] + (1.0 - b2) * (g[i] * g[i])
        p[i] -= step * m[i] / (math.sqrt(v[i]) / root2 + eps)


def cross_entropy(logits: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-sample cross entropy (B,) and the softmax (B, m), with CPU-independent exp and log."""
    top = np.max(logits, axis=1, keepdims=True)
    e = exact.exp(logits - top)
    total = exact.row_sum(e)
    loss = exact.log(total) + top[:, 0] - logits[np.arange(len(labels)), labels]
    return loss, e / total[:, None]
