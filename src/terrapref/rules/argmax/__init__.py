"""The ``argmax`` rule: drive the trajectory C ranks first (the paper's planner, SPEC 9)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from terrapref.rules.base import Choice, HeaderContext, Rule, RuleConfig, RuleContext, RuleInput, SteeringRunner, Where
from terrapref.vehicle import Command, ControlSet


@dataclass(frozen=True)
class ArgmaxRule(Rule, RuleConfig):
    """Nothing to fit: the argmax of F_t."""

    type: ClassVar[str] = "argmax"
    graph: ClassVar[bool] = True  # its decision is C's graph, and the argmax of its output

    def fit(self, data: object) -> ArgmaxRule:
        return self

    def header(self) -> dict[str, Any]:
        return {"type": self.type}

    @classmethod
    def from_header(cls, block: Mapping[str, Any], context: HeaderContext, where: Where) -> ArgmaxRule:
        return cls()

    def runner(self, context: RuleContext) -> SteeringRunner:
        return _Argmax(context.features.preference.control)

    def describe(self, names: tuple[str, ...], lethal: frozenset[str]) -> str:
        return "argmax: the trajectory C ranks first"


class _Argmax(SteeringRunner):
    def __init__(self, control: ControlSet) -> None:
        self.control = control

    def decide(self, frame: RuleInput) -> Choice:
        i = int(np.argmax(frame.probs))
        return Choice(i, Command(*self.control.command(i)))
