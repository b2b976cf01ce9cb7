"""How much a command that trains and drives many models (select, study, reproduce) makes,
counted before any work: its models and closed-loop runs, about how long they take, and the
bound beyond which it runs only when asked (``--large``)."""

from __future__ import annotations

import math
import os
from typing import NamedTuple

from terrapref.progress import duration_text

LARGE_MODELS = 1_000  # a command making more models than this, or more runs than LARGE_RUNS, runs only when asked (--large)
LARGE_RUNS = 100_000


class Workload(NamedTuple):
    """What a command will make, counted without listing a job.

    Attributes:
        models: the models it trains.
        factors: what the models are, in words (``1 recipe x 6 orders x 5 seeds``).
        runs: the closed-loop runs it drives (``up to``: a bound, where some may not be needed).
        core_s: about how long it all takes on one core [s].
        where: what the runs drive, in words (``32 layouts``).
        up_to: ``runs`` is a bound (the study's robustness sweep stops a part early).
    """

    models: int
    factors: str
    runs: int
    core_s: float
    where: str
    up_to: bool = False

    @property
    def large(self) -> bool:
        """Beyond :data:`LARGE_MODELS` models or :data:`LARGE_RUNS` runs: run only when asked."""
        return self.models > LARGE_MODELS or self.runs > LARGE_RUNS

    def describe(self, workers: int | None) -> str:
        """One line: the models, the runs and about how long they take on ``workers`` workers, as
        many at once as this machine has cores (None: a cluster's, unknown here: one core's time
        alone)."""
        when = f"{rough_duration(self.core_s)} of one core"
        if workers is not None:
            cores = min(workers, os.cpu_count() or 1)  # workers beyond the cores share them: no faster
            more = f", {cores} core{'s' if cores > 1 else ''} here" if cores < workers else ""
            when = f"{rough_duration(self.core_s / cores)} on {workers} worker{'s' if workers > 1 else ''}{more} ({when})"
        runs = f"{'up to ' if self.up_to else ''}{count(self.runs, 'closed-loop run')}"
        return f"{count(self.models, 'model')} ({self.factors}) and {runs} on {self.where}: {when}"

    def refusal(self) -> str:
        """Why a workload beyond the bound is refused without ``--large``."""
        return f"{self.models:,} models and {self.runs:,} runs are more than {LARGE_MODELS:,} models or {LARGE_RUNS:,} runs"


def core_seconds(*terms: tuple[int, float]) -> float:
    """About how long ``(count, seconds of one core each)`` take together [s]; inf where the
    counts are too large for a float (a flag given hundreds of digits)."""
    try:
        return math.fsum(n * rate for n, rate in terms)
    except OverflowError:
        return math.inf


def count(n: int, what: str) -> str:
    """``1 seed``, ``5 seeds``, ``3,628,800 orders``."""
    return f"{n:,} {what}{'s' if n != 1 else ''}"


def rough_duration(seconds: float) -> str:
    """An estimate's duration: ``about`` minutes and hours as :func:`duration_text` gives them,
    then days, then years, up to ``more than a billion years``."""
    if not seconds < 1e9 * 365 * 86400:
        return "more than a billion years"
    if seconds < 2 * 86400:
        return f"about {duration_text(seconds)}"
    if seconds < 2 * 365 * 86400:
        return f"about {seconds / 86400:,.0f} days"
    return f"about {seconds / (365 * 86400):,.0f} years"
