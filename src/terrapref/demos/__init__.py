"""Demonstrations: the synthetic driver standing in for a human, disturbances, driving sessions and
recordings (featurising recordings into datasets is :mod:`terrapref.dataset`)."""
