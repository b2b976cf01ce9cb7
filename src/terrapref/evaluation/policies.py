"""Model files of every kind as planner policies: one table from a file's ``kind`` to its loader.

The classifier C, the linear utility model and the end-to-end CNN baseline are all saved as
safetensors files whose metadata names their kind; ``load_policy`` reads the file (no code is
ever run from it) and builds the policy that kind's loader makes. The table lives here, above
the planner and the baselines, so that neither has to know the other.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

from terrapref.baselines.cnn import CnnPolicy
from terrapref.errors import UserError
from terrapref.learning.linear import LinearUtility
from terrapref.learning.model_file import CLASSIFIER, classifier_from, model_context, read_model_file
from terrapref.planner.policy import CNN, LINEAR, ClassifierPolicy, LinearPolicy, Policy


def _classifier(tensors: dict[str, np.ndarray], meta: dict, source: str) -> Policy:
    return ClassifierPolicy(classifier_from(tensors, meta, source))


def _linear(tensors: dict[str, np.ndarray], meta: dict, source: str) -> Policy:
    features, camera, classes, profile = model_context(meta, source)
    k, m = features.n_features, features.preference.m
    for name, shape in (("w", (k,)), ("b", (m,))):
        if name not in tensors or tuple(tensors[name].shape) != shape:
            raise UserError(source, f"expected shape {shape}", field=f"weights.{name}")
    return LinearPolicy(LinearUtility(tensors["w"].astype(float), tensors["b"].astype(float)), features, camera, classes, profile, source)


def _cnn(tensors: dict[str, np.ndarray], meta: dict, source: str) -> Policy:
    features, camera, classes, profile = model_context(meta, source)
    return CnnPolicy.from_tensors(tensors, meta, features, camera, classes, profile, source)


LOADERS: dict[str, Callable[[dict[str, np.ndarray], dict, str], Policy]] = {CLASSIFIER: _classifier, LINEAR: _linear, CNN: _cnn}
"""Model kind (the file's ``kind``) -> the function that builds its policy from tensors, metadata and the file's name."""


def load_policy(path: str | Path) -> Policy:
    """Any model file (C, linear, CNN) as a policy; loading never runs code from the file."""
    source = str(path)
    tensors, meta = read_model_file(path)
    kind = meta["kind"]
    if kind not in LOADERS:
        raise UserError(source, f"unknown model kind {kind!r}; kinds: {', '.join(LOADERS)}", field="kind")
    return LOADERS[kind](tensors, meta, source)
