"""Intervals for the rates the reports give (SPEC 12: a 95% interval on every rate), and for the
mean of paired differences (a cluster bootstrap)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np


def wilson(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval for a binomial rate (95% by default); (0, 1) when n is 0.

    Unlike the normal approximation it stays inside [0, 1] and is honest at 0/n and n/n, which
    is where a planner that gets (almost) every zone right sits.
    """
    if n <= 0:
        return 0.0, 1.0
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def rate_text(successes: int, n: int) -> str:
    """``"96.0% (72/75, 95% CI 88.9%-98.6%)"``."""
    if n <= 0:
        return "- (0 zones)"
    lo, hi = wilson(successes, n)
    return f"{successes / n:.1%} ({successes}/{n}, 95% CI {lo:.1%}-{hi:.1%})"


def cluster_bootstrap(groups: Sequence[Sequence[float]], draws: int = 2000, seed: int = 0) -> tuple[float, float, float]:
    """Mean of every value in ``groups``, and its 95% percentile interval resampling whole groups.

    A group is what varies together (a run's zones on one layout); resampling groups rather than
    values keeps the interval honest when values within a group are alike. The draws come from a
    fixed seed, so the same groups give the same interval on any machine. (nan, nan, nan) when
    there are no values.
    """
    kept = [np.asarray(g, dtype=float) for g in groups if len(g)]
    if not kept:
        return math.nan, math.nan, math.nan
    sums = np.array([g.sum() for g in kept])
    counts = np.array([len(g) for g in kept], dtype=float)
    picks = np.random.default_rng(seed).integers(0, len(kept), size=(draws, len(kept)))
    means = sums[picks].sum(axis=1) / counts[picks].sum(axis=1)
    lo, hi = np.quantile(means, [0.025, 0.975])
    return float(sums.sum() / counts.sum()), float(lo), float(hi)
