"""Scoring runs (SPEC 12): zone choices, collisions, cross-track error, distance by class."""

from terrapref.evaluation.scoring import RunMetrics, ZoneResult, score_run, score_zones

__all__ = ["RunMetrics", "ZoneResult", "score_run", "score_zones"]
