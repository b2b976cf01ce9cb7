"""The study's plan and the records of the models it trains, shared by the study
(terrapref.report.study) and its report (terrapref.report.study_report)."""

from __future__ import annotations

from dataclasses import dataclass

from terrapref.recipes import TEACH
from terrapref.records import to_plain
from terrapref.report.reproduce import TEST_SET, variations

# The orders the teaching study trains on: the paper's, then the others that put each of rock
# and water first (non_traversable last: it is lethal to every driver).
TEACH_ORDERS = (
    ("mud", "rock", "water", "non_traversable"),
    ("rock", "mud", "water", "non_traversable"),
    ("water", "mud", "rock", "non_traversable"),
    ("rock", "water", "mud", "non_traversable"),
)


@dataclass(frozen=True)
class StudyPlan:
    """How much of everything a study runs.

    Attributes:
        seeds: training seeds (each: its own demonstrations and initialisation).
        minutes: demonstration budgets for the data-efficiency curve [min]; the curve ends with
            all of it (two runs of train_course, about 11 min).
        epochs: C's training epochs (recipes ``ours`` and ``teach`` use 100).
        cnn_epochs: the CNN's training epochs.
        presets: perception presets the default style's taught models drive the layouts under
            (terrapref.perception; ``clean`` is the teaching section's own runs).
        sweep_base: the preset whose parts (labels, pose, camera, frames) are swept one at a time.
        sweep: the levels of each part, as multiples of the base preset's, in rising order; a
            part's sweep stops at the first level where agreement falls below 90%.
        horizons: trajectory lengths n for the horizon ablation (the default is always in).
        widths: hidden widths for the width ablation.
        courses: evaluation scenarios.
        orders: preference orders taught by one drive of teach_course (the default order first).
        styles: driver styles taught the same way, under the default order ("default" first).
        layouts: generated layouts the taught models are evaluated on (never used for choosing
            the recipe, and apart from the final measurement's gen:2000-2031).
        recipe: the named recipe the teaching section trains (its epochs set by ``epochs``).
    """

    seeds: int = 3
    minutes: tuple[float, ...] = (0.5, 1.0, 2.0, 5.0)
    epochs: int = 100
    cnn_epochs: int = 30
    presets: tuple[str, ...] = ("clean", "rellis", "field")
    sweep_base: str = "field"
    sweep: tuple[float, ...] = (1.0, 2.0, 4.0, 8.0)
    horizons: tuple[int, ...] = (15, 45)
    widths: tuple[int, ...] = (16, 256)
    courses: tuple[str, ...] = ()
    orders: tuple[tuple[str, ...], ...] = TEACH_ORDERS
    styles: tuple[str, ...] = ("default", "wide", "late", "shaky", "reluctant")
    layouts: tuple[str, ...] = tuple(f"gen:{5000 + i}" for i in range(8))
    recipe: str = TEACH.name

    def scenarios(self) -> list[str]:
        return list(self.courses) or [*TEST_SET, *variations()]


FULL = StudyPlan()
QUICK = StudyPlan(
    seeds=1, minutes=(2.0,), epochs=100, cnn_epochs=15,
    presets=("clean", "field"), sweep=(1.0, 4.0),
    horizons=(), widths=(16,), orders=TEACH_ORDERS[:2], styles=("default", "wide"), layouts=("gen:5000", "gen:5001"),
)


@dataclass(frozen=True)
class TrainJob:
    """One model the study trains (stage 3): what, from which featurised set, into which file."""

    study: str  # the report's part: baselines, efficiency, profile or ablation
    method: str  # C, linear or cnn
    seed: int
    data: str  # the featurised set: utilities, or the CNN's samples
    out: str  # the model file
    epochs: int  # C's
    cnn_epochs: int
    tag: str  # the model's name, in its file name
    minutes: float | None = None  # train on the first minutes of the set; None: all of it
    train: dict | None = None  # C's training settings that differ from recipe ours (an ablation)
    variant: str | None = None  # the ablation, described

    def to_dict(self) -> dict:
        """As study.json holds it: the optional fields only where set."""
        return to_plain(self, omit_none=("minutes", "train", "variant"))


@dataclass(frozen=True)
class TrainedModel:
    """A trained model: its job, the samples it learned from and the wall time it took [s]."""

    job: TrainJob
    samples: int
    train_s: float

    def to_dict(self) -> dict:
        return {**self.job.to_dict(), "samples": self.samples, "train_s": self.train_s}
