"""Training C on a featurised dataset (paper, section 5.2; SPEC 8).

Paper recipe: 80/20 train/validation split, 15 epochs, learning rate 1e-3, batch 256, Adam
(our assumption), a checkpoint every epoch; we keep the epoch with the lowest validation loss.
Seeded and the same on every CPU: the split, the initialisation and the batch order all come
from one seed, and the network trains in NumPy with arithmetic whose bits do not depend on the
instruction set, the BLAS kernel or the thread count (terrapref.learning.mlp, .exact).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, fields, is_dataclass, replace
from typing import Any, Protocol, get_args, get_type_hints

import numpy as np

from terrapref.configargs import option
from terrapref.dataset import Dataset
from terrapref.errors import UserError
from terrapref.learning import exact
from terrapref.learning import layers_compiled as kernels
from terrapref.learning.identify import Comparisons, FittedLookahead, Identifiability, TableNames, count_comparisons, identifiability
from terrapref.learning.linear import LinearUtility, fit_linear_utility, fit_lookahead_utility
from terrapref.learning.mlp import Adam, TrainableClassifier, cross_entropy, init_weights, round_inputs
from terrapref.learning.network import ClassifierConfig, member_prefix
from terrapref.learning.steady import Steadying, steady_labels
from terrapref.records import to_plain
from terrapref.terrain import ClassTable

MEMBER_SEED_STEP = 1000  # member j of an ensemble trains from seed + MEMBER_SEED_STEP * j
INIT_STREAM = 17  # the initial weights come from the stream (seed, INIT_STREAM), apart from the split's and batches'


@dataclass(frozen=True)
class OptimiserConfig:
    """Adam over shuffled mini-batches; the epoch with the lowest validation loss is kept.

    Attributes:
        epochs: passes over the training split (paper: 15).
        lr: Adam's learning rate (paper: 1e-3).
        batch_size: samples per step (paper: 256).
        val_fraction: share of the samples held out for validation (paper: 0.2).
    """

    epochs: int = option(15, "passes over the training split")
    lr: float = option(1e-3, "Adam's learning rate")
    batch_size: int = option(256, "samples per step")
    val_fraction: float = 0.2

    def __post_init__(self) -> None:
        _check(
            [
                (self.epochs >= 1, "epochs must be >= 1"),
                (self.batch_size >= 1, "batch_size must be >= 1"),
                (self.lr > 0, "lr must be > 0"),
                (0.0 <= self.val_fraction < 1.0, "val_fraction must be in [0, 1)"),
            ]
        )


@dataclass(frozen=True)
class DataOptions:
    """How the samples are weighted and augmented before C sees them.

    Attributes:
        class_balance: weight the loss by inverse label frequency (off in the paper's recipe).
        mirror: add every training sample mirrored left-right (trajectory i <-> m-1-i, label
            likewise): the preference does not depend on the side a patch is on, and a
            demonstration shows each pair on one side only. Needs a symmetric w grid.
        ignore_features: utility columns (by name: "distance", "mud", ...) that C never sees.
        steady_labels: when the demonstrating hand's tremor exceeds half the spacing of the
            control set's yaw rates, take the labels from a moving average of w
            (terrapref.learning.steady); a steadier hand's labels stay as recorded.
    """

    class_balance: bool = option(False, "weight the loss by inverse label frequency")
    mirror: bool = option(False, "add left-right mirrored copies of the training samples")
    steady_labels: bool = option(False, "labels from a moving average of w when the hand shakes more than half the w grid's spacing")
    ignore_features: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "ignore_features", tuple(self.ignore_features))


@dataclass(frozen=True)
class TrainConfig:
    """How C is trained (defaults: the paper's recipe), in its parts.

    Attributes:
        optimiser: epochs, learning rate, batches, the validation split.
        classifier: C's shape (hidden width, activation, depth, residual path, ensemble
            members); its ``m``, ``n_features`` and ``ignore`` are set from the data.
        data: loss weighting and augmentation.
        seed: seeds the split, the initialisation and the batch order; member j of an ensemble
            trains from ``seed + MEMBER_SEED_STEP * j`` (its own split, initialisation and order).
    """

    optimiser: OptimiserConfig = field(default_factory=OptimiserConfig)
    classifier: ClassifierConfig = field(default_factory=ClassifierConfig)
    data: DataOptions = field(default_factory=DataOptions)
    seed: int = option(0, "seeds the split, the initialisation and the batch order")

    def __post_init__(self) -> None:
        parts = [
            (self.optimiser, OptimiserConfig, "optimiser"),
            (self.classifier, ClassifierConfig, "classifier"),
            (self.data, DataOptions, "data"),
        ]
        _check(
            [(isinstance(part, kind), f"{name}: expected {kind.__name__}") for part, kind, name in parts]
            + [(isinstance(self.seed, int) and not isinstance(self.seed, bool) and self.seed >= 0, "seed must be an integer >= 0")]
        )
        self.classifier.check_trainable()

    @property
    def member_seeds(self) -> tuple[int, ...]:
        """The seed each member of an ensemble trains from (one: ``seed``)."""
        return tuple(self.seed + MEMBER_SEED_STEP * j for j in range(self.classifier.members))

    def with_epochs(self, epochs: int) -> TrainConfig:
        """The same configuration, trained for ``epochs``."""
        return replace(self, optimiser=replace(self.optimiser, epochs=epochs))

    def updated(self, changes: Mapping[str, Any]) -> TrainConfig:
        """This configuration with ``changes`` applied part by part, e.g. ``{"classifier":
        {"hidden": 16}, "seed": 3}`` (a variant named in data, such as a study's ablation); a
        part that is off (None) is built from its defaults first.

        Raises:
            ValueError: an unknown name, or a value the configuration's checks refuse.
        """
        return _updated(self, changes)

    def to_dict(self) -> dict:
        """As a model's metadata holds it (``training``); the classifier's m, n_features and
        ignored columns come from the data and are in the model's ``classifier``."""
        shape = {k: v for k, v in self.classifier.to_dict().items() if k not in ("m", "n_features", "ignore")}
        return {"optimiser": to_plain(self.optimiser), "classifier": shape, "data": to_plain(self.data), "seed": self.seed}


def _updated(config: Any, changes: Mapping[str, Any]) -> Any:
    names = {f.name: f for f in fields(config)}
    parts = {}
    for name, value in changes.items():
        if name not in names:
            raise ValueError(f"{type(config).__name__} has no {name!r} (it has {', '.join(names)})")
        current = getattr(config, name)
        if isinstance(value, Mapping):
            part = current if current is not None else _part_type(type(config), name)()
            if not is_dataclass(part):
                raise ValueError(f"{type(config).__name__}.{name} is not a part with fields")
            value = _updated(part, value)
        parts[name] = value
    return replace(config, **parts)


def _part_type(cls: type, name: str) -> type:
    """The configuration class a field holds (``X | None`` gives X)."""
    hint = get_type_hints(cls)[name]
    return next(a for a in (hint, *get_args(hint)) if is_dataclass(a))


def _check(checks: list[tuple[bool, str]]) -> None:
    for ok, message in checks:
        if not ok:
            raise ValueError(message)


@dataclass(frozen=True)
class EpochMetrics:
    epoch: int
    train_loss: float
    val_loss: float
    train_acc: float
    val_acc: float
    val_top3: float


@dataclass
class TrainResult:
    """What training produced. For an ensemble, ``history`` and ``best_epoch`` are member 0's,
    a checkpoint holds every member at that epoch, and ``members`` holds each member's result."""

    classifier: ClassifierConfig
    weights: dict[str, np.ndarray]  # the chosen epoch's weights
    history: list[EpochMetrics]
    best_epoch: int
    checkpoints: list[dict[str, np.ndarray]]
    steps: int
    members: list[TrainResult] = field(default_factory=list)
    identifiability: Identifiability | None = None  # what the data show of the preference (terrapref.learning.identify)
    steadying: Steadying | None = None  # the hand's tremor and what was done about it, with DataOptions.steady_labels
    rules: list[Any] = field(default_factory=list)  # the decision rules fitted with C (terrapref.rules), in order

    @property
    def drives(self) -> str | None:
        """The type of the rule that steers the model: the last steering rule fitted (None: none
        was, C's argmax steers). A rule's ``kind`` is terrapref.rules.base's (``steering``, ``speed``)."""
        steering = [r for r in self.rules if r.kind == "steering"]
        return steering[-1].type if steering else None

    @property
    def sets_speed(self) -> str | None:
        """The type of the rule that sets the model's speed (None: none was fitted; the control set's speed)."""
        return next((r.type for r in self.rules if r.kind == "speed"), None)


def _ensemble(results: list[TrainResult]) -> TrainResult:
    """One result whose weights hold every member's, under ``members.{j}.`` names."""

    def merged(per_member: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
        return {member_prefix(j) + name: v for j, w in enumerate(per_member) for name, v in w.items()}

    first = results[0]
    checkpoints = [merged(list(epoch)) for epoch in zip(*(r.checkpoints for r in results))]
    return TrainResult(
        replace(first.classifier, members=len(results)),
        merged([r.weights for r in results]),
        first.history,
        first.best_epoch,
        checkpoints,
        sum(r.steps for r in results),
        results,
    )


def class_weights(labels: np.ndarray, m: int) -> np.ndarray:
    """Loss weight per class (m,) float64: the square root of inverse label frequency, so that
    rare labels count more without exploding; 0 for labels never seen."""
    counts = np.bincount(labels, minlength=m).astype(np.float64)
    w = np.where(counts > 0, counts.sum() / np.maximum(counts, 1) / m, 0.0)
    return np.sqrt(w)


def split_indices(n: int, val_fraction: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Random train/validation split of n samples."""
    perm = rng.permutation(n)
    n_val = min(n - 1, max(1, int(round(n * val_fraction)))) if n > 1 and val_fraction > 0 else 0
    return np.sort(perm[n_val:]), np.sort(perm[:n_val])


EpochHook = Callable[[int, ClassifierConfig, dict[str, np.ndarray], EpochMetrics], None]  # (member, classifier, weights, metrics)


DATASET = "the dataset"  # the source a UserError of the samples' own content names (train names the file instead)


class FitData:
    """What the decision rules are fitted to: the samples C was trained on (labels steadied when
    asked), whether mirrored copies join them, and the linear utility over them, fitted once
    (the identifiability report and the second stage share it)."""

    def __init__(self, dataset: Dataset, mirror: bool) -> None:
        self.dataset, self.mirror = dataset, mirror
        self._utility: tuple[LinearUtility, float] | None = None

    def linear_utility(self) -> tuple[LinearUtility, float]:
        """The linear utility over the terrain columns and the distance utility, and the
        look-ahead's weight in its fit (:func:`_fit_utility`)."""
        if self._utility is None:
            self._utility = _fit_utility(self.dataset, self.mirror)
        return self._utility

    def rule_data(self, rule: str) -> tuple[dict[str, Any], dict[str, np.ndarray]] | None:
        """The configuration ``rule``'s arrays were read with, and the arrays (:meth:`Dataset.rule_data`)."""
        return self.dataset.rule_data(rule)

    def rule_config(self, rule: str, read: Callable[[dict[str, Any]], Any]) -> tuple[Any, dict[str, np.ndarray]] | None:
        """:meth:`rule_data` with the configuration as ``read`` reads it; what ``read`` cannot
        read (a dataset edited by hand) is a UserError naming the field, not an error inside a fit."""
        found = self.rule_data(rule)
        if found is None:
            return None
        try:
            return read(found[0]), found[1]
        except (KeyError, TypeError, ValueError) as exc:
            raise UserError(DATASET, f"unreadable ({type(exc).__name__}: {exc})", field=f"rules.{rule}.config") from None

    @property
    def has_utility(self) -> bool:
        return self._utility is not None


class RuleFit(Protocol):
    """A decision rule before fitting, as a recipe names it (terrapref.rules.RuleConfig)."""

    def fit(self, data: FitData) -> Any:
        """The fitted rule, or None when the data lack what it needs."""


def train(
    dataset: Dataset,
    config: TrainConfig | None = None,
    progress: Callable[[EpochMetrics], None] | None = None,
    on_epoch: EpochHook | None = None,
    identify: bool = True,
    rules: Sequence[RuleFit] = (),
) -> TrainResult:
    """Train C on ``dataset``, then fit the decision ``rules`` to the same samples; returns the
    lowest-validation-loss epoch's weights, the history and the fitted rules.

    ``on_epoch`` sees every epoch's weights as they are made (member by member), so that a
    caller can write checkpoints as training goes. The same dataset and configuration give the
    same weights, bit for bit, on any CPU and thread count (:mod:`terrapref.learning.exact`).
    Without ``identify`` (and with no rule that fits the linear utility) the result carries no
    identifiability report: for a caller that trains many models to compare C alone (the study).
    """
    config = config or TrainConfig()
    steadying = None
    if config.data.steady_labels:
        dataset, steadying = steady_labels(dataset)
    result = _train_classifier(dataset, config, progress, on_epoch)
    result.steadying = steadying
    data = FitData(dataset, config.data.mirror)
    result.rules = [fitted for rule in rules if (fitted := rule.fit(data)) is not None]
    if identify or data.has_utility:
        utility, gamma = data.linear_utility()
        result.identifiability = _identifiability(dataset, utility, gamma)
    return result


def _train_classifier(
    dataset: Dataset, config: TrainConfig, progress: Callable[[EpochMetrics], None] | None, on_epoch: EpochHook | None
) -> TrainResult:
    """C alone: one network, or an ensemble of members trained one after another."""
    if config.classifier.members == 1:
        result = _train(dataset, config, progress, on_epoch and (lambda *a: on_epoch(0, *a)))
    else:
        one = replace(config.classifier, members=1)
        result = _ensemble(
            [
                _train(dataset, replace(config, seed=seed, classifier=one), progress, on_epoch and (lambda *a, j=j: on_epoch(j, *a)))
                for j, seed in enumerate(config.member_seeds)
            ]
        )
    return result


def identify(dataset: Dataset, mirror: bool = True, steady: bool = False) -> Identifiability:
    """What ``dataset`` shows of the driver's preference, without training C (``terrapref inspect``):
    the same report ``train`` stores in the model (``steady``: labels as ``DataOptions.steady_labels`` makes them)."""
    if steady:
        dataset, _ = steady_labels(dataset)
    utility, gamma = _fit_utility(dataset, mirror)
    return _identifiability(dataset, utility, gamma)


def comparisons_by_drive(dataset: Dataset, steady: bool = False) -> list[Comparisons]:
    """Each recording's comparisons of every pair of classes (:func:`~terrapref.learning.identify.count_comparisons`),
    in the dataset's order, the labels steadied over the whole dataset as :func:`identify` steadies them."""
    if steady:
        dataset, _ = steady_labels(dataset)
    U, classes, background = _terrain_and_distance(dataset)
    drives = range(int(dataset.source.max()) + 1 if len(dataset) else 0)
    return [count_comparisons(U[dataset.source == k], dataset.labels[dataset.source == k], classes, background) for k in drives]


def _terrain_and_distance(dataset: Dataset) -> tuple[np.ndarray, tuple[str, ...], str]:
    """The utilities the identifiability report reads (terrain shares, distance), the terrain
    columns' names and the background's."""
    features = dataset.feature_config
    U = dataset.U[..., [*range(features.n_terrain), features.n_features - 1]]
    return U, tuple(features.feature_classes), ClassTable.from_dict(dataset.meta["classes"], "dataset").background


def _identifiability(dataset: Dataset, utility: LinearUtility, gamma: float) -> Identifiability:
    U, classes, _ = _terrain_and_distance(dataset)
    table = ClassTable.from_dict(dataset.meta["classes"], "dataset")
    names = TableNames(table.background, (table.lethal_column,) if table.lethal else ())
    lookahead = FittedLookahead(dataset.U2, gamma) if dataset.U2 is not None else None
    return identifiability(U, dataset.labels, classes, utility, lookahead, names)


def _fit_utility(dataset: Dataset, mirror: bool) -> tuple[LinearUtility, float]:
    """The linear utility over the terrain columns and the distance utility, and the look-ahead's
    weight in its fit: fitted through the look-ahead when the data carry it (``Dataset.U2``),
    else frame by frame (weight 1, unused)."""
    features = dataset.feature_config
    U, labels = dataset.U[..., [*range(features.n_terrain), features.n_features - 1]], dataset.labels
    U2 = dataset.U2
    if mirror and features.preference.control.symmetric:
        U_m, labels_m = mirrored(U, labels)
        U, labels = np.concatenate([U, U_m]), np.concatenate([labels, labels_m])
        U2 = None if U2 is None else np.concatenate([U2, U2[:, ::-1, ::-1]])
    frames = fit_linear_utility(U, labels)
    if U2 is None:
        return frames, 1.0
    fit = fit_lookahead_utility(U, U2, labels, start=frames)
    return fit.utility, fit.gamma


def mirrored(U: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Samples (N, m, k) and labels mirrored left-right: trajectory i <-> m - 1 - i (a symmetric w grid)."""
    return U[:, ::-1, :], U.shape[1] - 1 - labels


@dataclass(frozen=True)
class _Samples:
    """The training data as C's arithmetic sees it: inputs rounded once (batches index them),
    labels, the two splits (mirrored copies appended to the training split only), and each
    class's loss weight."""

    inputs: exact.Rounded
    labels: np.ndarray  # (N,) int64
    train: np.ndarray  # indices
    val: np.ndarray
    class_w: np.ndarray  # (m,)


def _samples(dataset: Dataset, config: TrainConfig, rng: np.random.Generator) -> _Samples:
    """Split (from ``rng``), mirror the training split if asked, and weight the classes."""
    n, m, _ = dataset.U.shape
    tr, va = split_indices(n, config.optimiser.val_fraction, rng)
    U_np, y_np = dataset.U, dataset.labels
    if config.data.mirror:
        if not dataset.feature_config.preference.control.symmetric:
            raise ValueError("mirror needs a w grid symmetric about zero")
        # Mirrored copies are appended and join the training split only; validation stays real.
        U_m, y_m = mirrored(U_np[tr], y_np[tr])
        U_np, y_np = np.concatenate([U_np, U_m]), np.concatenate([y_np, y_m])
        tr = np.concatenate([tr, np.arange(n, n + len(tr))])
    class_w = class_weights(y_np[tr], m) if config.data.class_balance else np.ones(m)
    return _Samples(round_inputs(U_np), np.asarray(y_np, dtype=np.int64), tr, va, class_w)


def _classifier_for(dataset: Dataset, config: TrainConfig) -> ClassifierConfig:
    """C's shape for this data: the configured one with the data's m and k and the ignored columns."""
    _, m, k = dataset.U.shape
    names = dataset.feature_config.column_names
    unknown = set(config.data.ignore_features) - set(names)
    if unknown:
        raise ValueError(f"ignore_features: no column {sorted(unknown)} (columns: {', '.join(names)})")
    ignore = tuple(names.index(n) for n in config.data.ignore_features)
    return replace(config.classifier, m=m, n_features=k, ignore=ignore)


def _evaluate(net: TrainableClassifier, data: _Samples, idx: np.ndarray) -> tuple[float, float, float]:
    """Loss, accuracy and top-3 accuracy of ``net`` on the samples ``idx`` (NaN for none)."""
    if len(idx) == 0:
        return math.nan, math.nan, math.nan
    y = data.labels
    logits, _ = net.forward(data.inputs._replace(ints=data.inputs.ints[idx]))
    loss, _ = cross_entropy(logits, y[idx])
    top = np.argsort(-logits, axis=1, kind="stable")[:, : min(3, logits.shape[1])]
    acc = float(np.count_nonzero(top[:, 0] == y[idx]) / len(idx))
    top3 = float(np.count_nonzero((top == y[idx, None]).any(axis=1)) / len(idx))
    return exact.fsum(loss) / len(idx), acc, top3


def _epoch(net: TrainableClassifier, opt: Adam, data: _Samples, order: np.ndarray, batch_size: int) -> tuple[float, float, int]:
    """One pass over ``order`` in batches; the training loss and accuracy as the batches saw them, and the steps."""
    y = data.labels
    seen_loss, seen_hits, steps = [], 0, 0
    buffer = np.empty_like(net.params)  # each step's gradient, laid out as the weights
    for start in range(0, len(order), batch_size):
        batch = order[start : start + batch_size]
        logits, cache = net.forward(data.inputs._replace(ints=data.inputs.ints[batch]), keep=True)
        # d (sum_i c_{y_i} CE_i / n) / d logits = c_{y_i} (p_i - onehot_i) / n
        loss, grad, hits = kernels.cross_entropy_grad(logits, y[batch], data.class_w)
        seen_loss.append(loss)
        seen_hits += hits
        opt.step(net.gradient(cache, grad, out=buffer))
        steps += 1
    n = len(order)
    return exact.fsum(np.concatenate(seen_loss)) / n, seen_hits / n, steps


def _train(
    dataset: Dataset,
    config: TrainConfig,
    progress: Callable[[EpochMetrics], None] | None,
    on_epoch: Callable[[ClassifierConfig, dict[str, np.ndarray], EpochMetrics], None] | None = None,
) -> TrainResult:
    """One network: split, initialise, train every epoch, keep the lowest-validation-loss one."""
    rng = np.random.default_rng(config.seed)
    data = _samples(dataset, config, rng)
    classifier = _classifier_for(dataset, config)
    net = TrainableClassifier(classifier, init_weights(classifier, np.random.default_rng([config.seed, INIT_STREAM])))
    opt = Adam(net.params, config.optimiser.lr)  # all weights in one pass
    history: list[EpochMetrics] = []
    checkpoints: list[dict[str, np.ndarray]] = []
    steps = 0
    for epoch in range(1, config.optimiser.epochs + 1):
        train_loss, train_acc, batches = _epoch(net, opt, data, data.train[rng.permutation(len(data.train))], config.optimiser.batch_size)
        steps += batches
        vl, vacc, vtop3 = _evaluate(net, data, data.val)
        metrics = EpochMetrics(epoch, train_loss, vl, train_acc, vacc, vtop3)
        history.append(metrics)
        checkpoints.append({name: v.astype(np.float32) for name, v in net.weights.items()})
        if on_epoch is not None:
            on_epoch(classifier, checkpoints[-1], metrics)
        if progress is not None:
            progress(metrics)
    losses = [h.val_loss if not math.isnan(h.val_loss) else h.train_loss for h in history]
    best = int(np.argmin(losses))
    return TrainResult(classifier, copy.deepcopy(checkpoints[best]), history, best + 1, checkpoints, steps)
