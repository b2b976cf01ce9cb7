"""Shared test helpers (not collected: pytest only collects test_*.py)."""

from __future__ import annotations

from terrapref.camera import CameraConfig
from terrapref.features import FeatureConfig
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
