"""The ``argmax`` stage: drive the trajectory C ranks first (the paper's planner, SPEC 9)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from terrapref.features import FeatureConfig
from terrapref.planner.stages.base import Choice, Stage, StageConfig, StageContext, StageInput, StageRunner, Where
from terrapref.vehicle import Command, ControlSet


@dataclass(frozen=True)
class ArgmaxStage(Stage, StageConfig):
    """Nothing to fit: the argmax of F_t."""

    type: ClassVar[str] = "argmax"

    def fit(self, data: object) -> ArgmaxStage:
        return self

    def header(self) -> dict[str, Any]:
        return {"type": self.type}

    @classmethod
    def from_header(cls, block: Mapping[str, Any], features: FeatureConfig, where: Where) -> ArgmaxStage:
        return cls()

    def runner(self, context: StageContext) -> StageRunner:
        return _Argmax(context.features.preference.control)

    def describe(self, names: tuple[str, ...], lethal: frozenset[str]) -> str:
        return "argmax: the trajectory C ranks first"


class _Argmax(StageRunner):
    def __init__(self, control: ControlSet) -> None:
        self.control = control

    def decide(self, frame: StageInput) -> Choice:
        i = int(np.argmax(frame.probs))
        return Choice(i, Command(*self.control.command(i)))
