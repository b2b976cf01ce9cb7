"""Shared test helpers (not collected: pytest only collects test_*.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from terrapref.camera import CameraConfig
from terrapref.features import FeatureConfig
from terrapref.learning.model_file import save_model
from terrapref.learning.network import ClassifierConfig
from terrapref.terrain import default_classes


def model_meta(features: FeatureConfig | None = None, camera: CameraConfig | None = None, profile: tuple[str, ...] | None = None) -> dict:
    """The configuration a model or dataset file carries, defaults unless given."""
    classes = default_classes()
    return {
        "features": (features or FeatureConfig()).to_dict(),
        "camera": (camera or CameraConfig()).to_dict(),
        "classes": classes.to_dict(),
        "profile": list(profile or classes.profile),
    }


def linear_model(path: Path) -> Path:
    """C reduced to its skip path, logits = U @ w: follows the path, shies from terrain; drives the
    demo course to the end in about a minute of simulated time."""
    config = ClassifierConfig(hidden=8, skip=True)
    dims = [config.m] + [config.hidden] * config.depth + [config.m]
    weights = {"compress.weight": np.array([[-8.0, -4.0, -2.0, -1.0, 6.0]], np.float32), "compress.bias": np.zeros(1, np.float32)}
    for i, (a, b) in enumerate(zip(dims[:-1], dims[1:])):
        weights[f"layers.{i}.weight"] = np.zeros((b, a), np.float32)
        weights[f"layers.{i}.bias"] = np.zeros(b, np.float32)
    return save_model(path, config, weights, model_meta())
