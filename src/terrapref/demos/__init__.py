"""Demonstrations: recordings, the synthetic driver standing in for a human, and featurisation."""
