"""The ``second_stage`` rule: trajectories beyond the first, scored by a learned linear utility.

For each of the ``candidates`` trajectories C ranks highest, the look-ahead
(terrapref.rules.second.lookahead) lays the preference set out again from a point along it, and
each of those second pieces is scored with the linear utility model ``w . U'_j + b_j`` fitted
to the same demonstrations as C (terrapref.learning.linear; through the look-ahead when the
data carry it, :attr:`SecondStageConfig.lookahead`). The planner then drives the argmax of

    log F_t(i) + weight * max_j (w . U'_ij + b_j)

over the candidates. The linear model is a softmax over trajectories too, so its scores are in
the same units (log-probabilities up to a constant) as log F_t. With ``weight`` 0 the planner
is the paper's argmax of F_t.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from terrapref.camera import PinholeCamera, SegmentationView
from terrapref.errors import UserError
from terrapref.features import UtilityFeaturizer
from terrapref.learning import exact
from terrapref.learning.linear import LinearUtility
from terrapref.rules.base import (
    MOST_NUMBER,
    Choice,
    FrameReader,
    HeaderContext,
    Rule,
    RuleConfig,
    RuleContext,
    RuleInput,
    SteeringRunner,
    Where,
    number,
    vector,
)
from terrapref.rules.second import scores_compiled as kernels
from terrapref.rules.second.lookahead import Lookahead, LookaheadConfig
from terrapref.scenario.path import ReferencePath
from terrapref.terrain import ClassTable
from terrapref.vehicle import Command, ControlSet, Pose

if TYPE_CHECKING:
    from terrapref.demos.recording import Recording
    from terrapref.learning.train import FitData

FITS = ("lookahead", "frames")  # how the utility was fitted: through the look-ahead, or frame by frame
LEGACY_WEIGHT = 1.5  # the second stage's weight in files whose ``utility`` names none


@dataclass(frozen=True)
class SecondStageConfig(RuleConfig):
    """The second stage's decision rule (defaults chosen on generated courses, docs/notebook.md).

    Attributes:
        after_s: where along each candidate trajectory the second stage starts [s]
            (LookaheadConfig.after_s).
        weight: weight of the second stage's value against log F_t.
        candidates: how many of C's highest-ranked trajectories are looked beyond.
        stride: the second stage's terrain shares read every ``stride``-th point
            (LookaheadConfig.stride).
        lookahead: the training data carry the look-ahead utilities U' (:meth:`reader`) and the
            utility is fitted through them; otherwise frame by frame, on U.
    """

    type: ClassVar[str] = "second_stage"
    arrays: ClassVar[dict[str, str]] = {"U2": "finite"}
    without_data: ClassVar[str] = "the second stage is fitted frame by frame"

    after_s: float = 2.4
    weight: float = 1.5
    candidates: int = 7
    stride: int = 2
    lookahead: bool = False

    def __post_init__(self) -> None:
        if not (
            math.isfinite(self.after_s)
            and self.after_s > 0
            and math.isfinite(self.weight)
            and 0 <= self.weight <= MOST_NUMBER  # as its file's block is read back
            and self.candidates >= 1
            and self.stride >= 1
        ):
            raise ValueError(
                f"the second stage needs after_s > 0, weight 0 to {MOST_NUMBER:g}, candidates >= 1 and stride >= 1; "
                f"got after_s {self.after_s:g}, weight {self.weight:g}, candidates {self.candidates}, stride {self.stride}"
            )

    @property
    def lookahead_config(self) -> LookaheadConfig:
        return LookaheadConfig(self.after_s, self.stride)

    def summary(self) -> str:
        return (
            "the planner's second stage scoring second pieces of trajectory beyond the first with the linear utility fitted to the same "
            "samples" + (" through the look-ahead" if self.lookahead else "")
        )

    def data(self) -> dict[str, Any] | None:
        return {"lookahead": self.lookahead_config.to_dict()} if self.lookahead else None

    def reader(self, featurizer: UtilityFeaturizer, camera: PinholeCamera, classes: ClassTable, n: int) -> LookaheadReader:
        return LookaheadReader(Lookahead(self.lookahead_config, featurizer, camera), n)

    def fit(self, data: FitData) -> SecondStageRule:
        """The linear utility over the samples C was trained on (through the look-ahead when they carry it)."""
        utility, _ = data.linear_utility()
        found = data.rule_config(self.type, lambda recorded: LookaheadConfig.from_dict(recorded["lookahead"]))
        look = found[0] if found is not None else None
        config = replace(self, after_s=look.after_s, stride=look.stride) if look is not None else self
        return SecondStageRule(config, utility, "lookahead" if look is not None else "frames")


def check_lookahead(rules: Sequence[RuleConfig], n_steps: int, dt_s: float) -> None:
    """ValueError where a second stage among ``rules`` would start its look-ahead outside
    trajectories of ``n_steps`` steps of ``dt_s`` [s] (LookaheadConfig.step)."""
    for rule in rules:
        if isinstance(rule, SecondStageConfig):
            rule.lookahead_config.step(n_steps, dt_s)


def with_second_stage(
    rules: Sequence[RuleConfig], on: bool | None = None, weight: float | None = None, recipe: str = "the recipe"
) -> tuple[RuleConfig, ...]:
    """``rules`` (a recipe's) with the second stage added first (``on`` True; kept where they have
    one) or left out (False), and its weight against log F_t set (``weight``); None leaves them
    as they are (``train --second-stage/--no-second-stage/--stage-weight``).

    Raises:
        UserError: a weight with no second stage to take it, or a weight the stage refuses (naming ``--stage-weight``).
    """
    out = list(rules)
    second = next((i for i, r in enumerate(out) if isinstance(r, SecondStageConfig)), None)
    if on is False and second is not None:
        del out[second]
        second = None
    elif on and second is None:
        out.insert(0, SecondStageConfig())
        second = 0
    if weight is not None:
        if second is None:
            raise UserError("--stage-weight", f"{recipe} has no second stage here (add --second-stage)")
        try:
            out[second] = replace(out[second], weight=weight)
        except ValueError as exc:
            raise UserError("--stage-weight", str(exc)) from None
    return tuple(out)


class LookaheadReader(FrameReader):
    """The look-ahead utilities U' of each frame of one recording: array ``U2`` (N, m, m, K + 1) float16."""

    def __init__(self, lookahead: Lookahead, n: int) -> None:
        self.lookahead = lookahead
        self.U2 = np.empty((n, lookahead.m, lookahead.m, lookahead.k + 1), dtype=np.float16)

    def read(self, j: int, view: SegmentationView, pose: Pose, path: ReferencePath, progress_m: float) -> None:
        self.U2[j] = self.lookahead.utilities(view, pose, path, progress_m)

    def arrays(self, recording: Recording, keep: np.ndarray, path: ReferencePath) -> dict[str, np.ndarray]:
        return {"U2": self.U2}


@dataclass(frozen=True)
class SecondStageRule(Rule):
    """A fitted second stage: its rule and the linear utility (w over the K terrain columns and the
    distance utility, b per trajectory) it scores the second pieces with."""

    type: ClassVar[str] = "second_stage"

    config: SecondStageConfig
    utility: LinearUtility
    fit: str = "lookahead"

    def header(self) -> dict[str, Any]:
        c = self.config
        return {
            "type": self.type,
            "weight": c.weight,
            "after_s": c.after_s,
            "stride": c.stride,
            "candidates": c.candidates,
            "w": self.utility.w.tolist(),
            "b": self.utility.b.tolist(),
            "fit": self.fit,
        }

    @classmethod
    def from_header(cls, block: Mapping[str, Any], context: HeaderContext, where: Where) -> SecondStageRule:
        features = context.features
        d = SecondStageConfig()
        weight = number(block, "weight", where, d.weight, low=0.0)
        after_s = number(block, "after_s", where, d.after_s, positive=True)
        counts = {}
        for name in ("stride", "candidates"):
            value = block.get(name, getattr(d, name))
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise where.error(name, "expected an integer >= 1")
            counts[name] = value
        fit = block.get("fit", "frames")
        if fit not in FITS:
            raise where.error("fit", f"expected one of {', '.join(FITS)}")
        w = vector(block, "w", features.n_terrain + 1, where)
        b = vector(block, "b", features.preference.m, where)
        try:
            config = SecondStageConfig(after_s, weight, counts["candidates"], counts["stride"], lookahead=fit == "lookahead")
        except ValueError as exc:
            raise where.error("", str(exc)) from None
        return cls(config, LinearUtility(w, b), fit)

    @classmethod
    def legacy_block(cls, meta: Mapping[str, Any], source: str) -> dict[str, Any] | None:
        """A file before the ``stages`` list carried the linear utility as ``utility``: the second
        stage, of weight :data:`LEGACY_WEIGHT` unless it names one, fitted through the features'
        look-ahead (at its ``after_s`` and ``stride``) when they had one."""
        data = meta.get("utility")
        if data is None:
            return None
        if not isinstance(data, dict):
            raise UserError(source, "expected a mapping", field="utility")
        features = meta.get("features")
        look = features.get("lookahead") if isinstance(features, dict) else None
        look = {"after_s": look.get("after_s"), "stride": look.get("stride")} if isinstance(look, dict) else {}
        return {"type": cls.type, "weight": LEGACY_WEIGHT, **look, **data}

    def runner(self, context: RuleContext) -> SteeringRunner:
        return SecondStageScores(self.config, context.featurizer, context.camera, self.utility)

    def describe(self, names: tuple[str, ...], lethal: frozenset[str]) -> str:
        return f"second stage: weight {self.config.weight:g}, linear utility fitted {'through the look-ahead' if self.fit == 'lookahead' else 'frame by frame'}"


class SecondStageScores(Lookahead, SteeringRunner):
    """The look-ahead of one featurizer (preference set and camera), scored by a linear utility."""

    def __init__(self, config: SecondStageConfig, featurizer: UtilityFeaturizer, camera: PinholeCamera, utility: LinearUtility) -> None:
        super().__init__(config.lookahead_config, featurizer, camera)
        k = self.k
        if utility.w.shape != (k + 1,) or utility.b.shape != (self.m,):
            raise ValueError("the linear utility does not match the feature configuration")
        self.config = config
        self.control: ControlSet = featurizer.config.preference.control
        self.w, self.b = np.asarray(utility.w, dtype=float), np.asarray(utility.b, dtype=float)
        # By class id: each point's terrain weight w_k / n'; 0 for classes U does not count.
        self._point_weight = np.append(self.w[:k] / self.points, 0.0)[featurizer.class_columns]

    def decide(self, frame: RuleInput) -> Choice:
        # a probability of exactly 0 is -inf, never chosen
        i = int(np.argmax(self.scores(exact.log(frame.probs), frame.view, frame.pose, frame.path, frame.progress_m)))
        return Choice(i, Command(*self.control.command(i)))

    def scores(self, log_probs: np.ndarray, view: SegmentationView, pose: Pose, path: ReferencePath, progress_m: float) -> np.ndarray:
        """log F_t + weight * value of the second stage for the candidates; -inf elsewhere, shape (m,)."""
        rows = np.argsort(-log_probs, kind="stable")[: self.config.candidates]
        # w . U'_ij + b_j without building U' (the same sums as utilities() @ w + b, the terrain
        # weights summed point by point in one compiled pass), then the best continuation.
        ids = view.pixels(self.pix[rows].ravel())
        distance = self.distance_utility(pose, path, progress_m, rows)
        return kernels.stage_scores(
            log_probs, self.config.weight, rows, ids, self._point_weight, self.seen, distance, float(self.w[self.k]), self.b
        )
