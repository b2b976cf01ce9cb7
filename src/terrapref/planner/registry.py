"""Policies by name, as Gymnasium registers environments (one :class:`terrapref.registry.Registry`,
as every named choice; the decision rules are in :data:`terrapref.rules.RULES`).

``register(kind, entry_point)`` names a way to build a :class:`~terrapref.planner.policy.Policy`;
``make(kind, **kwargs)`` builds one (the baselines that need no file: ``pure_pursuit``,
``hand_cost``); ``load_policy(path)`` builds the one a model file's ``kind`` names (``classifier``,
``linear``, ``cnn``), from the file's tensors and metadata, never running code from it.

An entry point is a callable or a ``"module:attribute"`` string imported on first use, so
that kinds defined above the planner (the CNN baseline) register here without the planner
importing them:

>>> sorted(kinds())
['classifier', 'cnn', 'hand_cost', 'linear', 'pure_pursuit']
>>> make("pure_pursuit", pursuit_m=3.0).pursuit_m
3.0
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from terrapref.errors import UserError
from terrapref.learning.linear import LinearUtility
from terrapref.learning.model_file import CLASSIFIER, classifier_from, model_context, read_model_file
from terrapref.planner.policy import CNN, LINEAR, ClassifierPolicy, CostPolicy, LinearPolicy, Policy, PurePursuitPolicy
from terrapref.registry import Registry


@dataclass(frozen=True)
class PolicySpec:
    """One registered kind.

    Attributes:
        kind: its name (a model file's ``kind``, or a baseline's).
        entry_point: builds the policy: from ``(tensors, meta, source)`` for a file kind, from
            keyword arguments otherwise; or ``"module:attribute"`` naming such a callable.
        from_file: the kind is stored in model files (``load_policy``) rather than built by ``make``.
    """

    kind: str
    entry_point: Callable[..., Policy] | str
    from_file: bool = False

    def build(self, *args, **kwargs) -> Policy:
        entry = self.entry_point
        if isinstance(entry, str):
            module, _, attribute = entry.partition(":")
            entry = getattr(importlib.import_module(module), attribute)
        return entry(*args, **kwargs)


POLICIES: Registry[PolicySpec] = Registry("policy kind")


def register(kind: str, entry_point: Callable[..., Policy] | str, from_file: bool = False) -> None:
    """Name a way to build a policy; a kind is registered once."""
    POLICIES.register(kind, PolicySpec(kind, entry_point, from_file))


def kinds(from_file: bool | None = None) -> list[str]:
    """Registered kinds, in the order registered (only file kinds, or only the others, if asked)."""
    return [k for k, spec in POLICIES.items() if from_file is None or spec.from_file == from_file]


def make(kind: str, **kwargs) -> Policy:
    """A policy of a kind that needs no model file (``pure_pursuit``, ``hand_cost``)."""
    if kind not in POLICIES or POLICIES[kind].from_file:
        raise ValueError(f"unknown policy {kind!r}; policies without a file: {', '.join(kinds(from_file=False))}")
    return POLICIES[kind].build(**kwargs)


def load_policy(path: str | Path) -> Policy:
    """Any model file (C, linear, CNN) as its policy; loading never runs code from the file."""
    tensors, meta = read_model_file(path)
    return policy_from(tensors, meta, str(path))


def policy_from(tensors: dict[str, np.ndarray], meta: dict, source: str) -> Policy:
    """The policy of a model file's tensors and header (any kind: ``meta["kind"]``), checked."""
    kind = meta["kind"]
    if kind not in POLICIES or not POLICIES[kind].from_file:
        raise UserError(source, f"unknown model kind {kind!r}; kinds: {', '.join(kinds(from_file=True))}", field="kind")
    return POLICIES[kind].build(tensors, meta, source)


def _classifier(tensors: dict[str, np.ndarray], meta: dict, source: str) -> Policy:
    return ClassifierPolicy(classifier_from(tensors, meta, source))


def _linear(tensors: dict[str, np.ndarray], meta: dict, source: str) -> Policy:
    features, camera, classes, profile = model_context(meta, source)
    k, m = features.n_features, features.preference.m
    for name, shape in (("w", (k,)), ("b", (m,))):
        if name not in tensors or tuple(tensors[name].shape) != shape:
            raise UserError(source, f"expected shape {shape}", field=f"weights.{name}")
    return LinearPolicy(LinearUtility(tensors["w"].astype(float), tensors["b"].astype(float)), features, camera, classes, profile, source)


register(CLASSIFIER, _classifier, from_file=True)
register(LINEAR, _linear, from_file=True)
register(CNN, "terrapref.baselines.cnn:cnn_from_file", from_file=True)
register(PurePursuitPolicy.name, PurePursuitPolicy)
register(CostPolicy.name, CostPolicy)
