"""Intervals for the rates the reports give (SPEC 12: a 95% interval on every rate)."""

from __future__ import annotations

import math


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
