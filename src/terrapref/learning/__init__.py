"""Learning the preference: the classifier C (SPEC 8), training, and safe model files."""

from terrapref.learning.model_file import LoadedModel, load_model, save_model
from terrapref.learning.network import ClassifierConfig, numpy_forward

__all__ = ["ClassifierConfig", "LoadedModel", "load_model", "numpy_forward", "save_model"]
