"""Utility features (SPEC 6-7): the trajectory library S projected into the image, and U (m x 5)."""

from terrapref.features.preference_set import PreferenceSet, PreferenceSetConfig
from terrapref.features.utility import DistanceMode, FeatureConfig, UtilityFeaturizer

__all__ = ["DistanceMode", "FeatureConfig", "PreferenceSet", "PreferenceSetConfig", "UtilityFeaturizer"]
