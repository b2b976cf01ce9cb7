"""One type for every kind of model file: :class:`Model` loads and saves C's files (with the
decision rules fitted with it) and the learned baselines' (``linear``, ``cnn``) alike, the way a
policy class of Stable-Baselines3 owns both its ``save`` and its ``load``.

A model file is safetensors: the weights as tensors and a JSON header (``kind`` says which kind;
terrapref.planner.registry builds each kind's policy). Loading never runs code from the file.
What the file holds is read once, with checks, here; the runtime, ``evaluate``, ``route``,
``info`` and ``export`` all take a :class:`Model`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from terrapref.camera import CameraConfig
from terrapref.features import FeatureConfig
from terrapref.learning.model_file import CLASSIFIER, LoadedModel, read_model_file, write_model_file
from terrapref.planner.planner import Planner, rules_with_settings
from terrapref.planner.policy import ClassifierPolicy, Policy
from terrapref.planner.registry import policy_from
from terrapref.planner.stop import StopConfig
from terrapref.rules import Rule, chosen_rule, speed_rule
from terrapref.rules.settings import RuleSettings
from terrapref.terrain import ClassTable
from terrapref.vehicle import VehicleConfig


@dataclass(frozen=True)
class Model:
    """A model file of any kind, read and checked.

    Attributes:
        path: the file it was read from.
        kind: its kind (``classifier`` for C; a baseline's otherwise).
        policy: what scores the trajectories (C with its decision rules, or a baseline).
        meta: the header as the file holds it (entries this version does not read included).
        tensors: the weights, by name, as the file holds them.
    """

    path: str
    kind: str
    policy: Policy
    meta: dict[str, Any] = field(repr=False)
    tensors: dict[str, np.ndarray] = field(repr=False)

    @classmethod
    def load(cls, path: str | Path) -> Model:
        """Read a model file of any kind; every problem is a :class:`terrapref.errors.UserError`
        naming the file and the field."""
        tensors, meta = read_model_file(path)
        return cls(str(path), str(meta["kind"]), policy_from(tensors, meta, str(path)), meta, tensors)

    @classmethod
    def of(cls, loaded: LoadedModel) -> Model:
        """A model of C already read (terrapref.learning.model_file.load_model)."""
        return cls(loaded.path, CLASSIFIER, ClassifierPolicy(loaded), loaded.meta, loaded.weights)

    def save(self, path: str | Path) -> Path:
        """Write the model to ``path`` as it was read (its weights and header), atomically."""
        return write_model_file(path, self.tensors, self.meta)

    @property
    def classifier(self) -> LoadedModel | None:
        """C and its header, for a model of C; None for a baseline."""
        return self.policy.model if isinstance(self.policy, ClassifierPolicy) else None

    @property
    def rules(self) -> tuple[Rule, ...]:
        """The decision rules fitted with the model, in the file's order (none for a baseline)."""
        return self.policy.rules

    def rules_with(self, settings: RuleSettings) -> tuple[Rule, ...]:
        """The rules as a robot's ``settings`` set them (a value a rule cannot take: a UserError)."""
        return rules_with_settings(self.policy, settings)

    @property
    def driving(self) -> Rule:
        """The rule that drives: the one the file names, else the last listed; C's argmax when none is."""
        return chosen_rule(self.policy.rules, self.policy.drives, None, self.path)

    @property
    def features(self) -> FeatureConfig:
        return self.policy.features

    @property
    def camera(self) -> CameraConfig:
        return self.policy.camera

    @property
    def classes(self) -> ClassTable:
        return self.policy.classes

    @property
    def profile(self) -> tuple[str, ...]:
        return tuple(self.policy.profile or ())

    @property
    def reads_relief(self) -> bool:
        """Whether a rule of the model was taught the ground's relief (it needs depth images to read it)."""
        return any(rule.reads_relief for rule in self.rules)

    @property
    def top_speed_mps(self) -> float | None:
        """The fastest its speed rule commands [m/s]; None without one (the control set's speed)."""
        speed = speed_rule(self.policy.rules)
        return None if speed is None else float(speed.config.max_speed_mps)

    def planner(
        self,
        camera: CameraConfig | None = None,
        rule: Rule | str | None = None,
        stop: StopConfig | None = None,
        vehicle: VehicleConfig | None = None,
        settings: RuleSettings | None = None,
    ) -> Planner:
        """The planner this model drives (``rule``: another of its rules, or ``argmax``) within the
        robot's limits ``vehicle`` (default: the default vehicle's), its rules set as the robot's
        ``settings`` say where they do; a model trained for another camera than ``camera`` is refused."""
        return Planner(self.classifier or self.policy, camera, rule=rule, stop=stop, vehicle=vehicle, settings=settings)
