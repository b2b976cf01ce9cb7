"""The study's plan and the records of the models it trains, shared by the study
(terrapref.report.study) and its report (terrapref.report.study_report)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

from terrapref.perception import PerceptionModel, load_perception
from terrapref.recipes import OURS, TEACH, recipe_named
from terrapref.records import to_plain
from terrapref.report.reproduce import TEST_SET, variations
from terrapref.terrain import ClassTable, PreferenceProfile, default_classes

DEMONSTRATIONS = OURS  # the study's data: ours' runs of train_course (or of a table's teaching course)

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
        presets: perception models (a preset's name, a file or a model) the default style's taught
            models drive the layouts under (terrapref.perception; ``clean`` is the teaching
            section's own runs).
        sweep_base: the perception model whose parts (labels, pose, camera, frames) are swept one
            at a time (None: no sweep).
        sweep: the levels of each part, as multiples of the base preset's, in rising order; a
            part's sweep stops at the first level where agreement falls below 90%.
        horizons: trajectory lengths n for the horizon ablation (the default is always in).
        widths: hidden widths for the width ablation.
        courses: evaluation scenarios (empty: test_course and the figure variations).
        orders: preference orders taught by one drive of the teaching course (the table's default
            order first).
        styles: driver styles taught the same way, under the default order ("default" first).
        layouts: generated layouts the taught models are evaluated on (never used for choosing
            the recipe, and apart from the final measurement's gen:2000-2031).
        recipe: the named recipe the teaching section trains (its epochs set by ``epochs``).
        classes: the class table every course and layout is read with (None: the default).
        course: the course the demonstrations and the teaching drives go over (None: each
            recipe's own, train_course and teach_course).
        follow_up: the teaching drives are followed by a drive of what they left open
            (terrapref.scenario.teaching.follow_up) and train on both.
        alt: the other preference profile of section 3 (None: none, for a table of one class
            besides the lethal column).
    """

    seeds: int = 3
    minutes: tuple[float, ...] = (0.5, 1.0, 2.0, 5.0)
    epochs: int = 100
    cnn_epochs: int = 30
    presets: tuple[str | PerceptionModel, ...] = ("clean", "rellis", "field")
    sweep_base: str | PerceptionModel | None = "field"
    sweep: tuple[float, ...] = (1.0, 2.0, 4.0, 8.0)
    horizons: tuple[int, ...] = (15, 45)
    widths: tuple[int, ...] = (16, 256)
    courses: tuple[str, ...] = ()
    orders: tuple[tuple[str, ...], ...] = TEACH_ORDERS
    styles: tuple[str, ...] = ("default", "wide", "late", "shaky", "reluctant")
    layouts: tuple[str, ...] = tuple(f"gen:{5000 + i}" for i in range(8))
    recipe: str = TEACH.name
    classes: ClassTable | None = None
    course: str | None = None
    follow_up: bool = False
    alt: tuple[str, ...] | None = ("rock", "mud", "water", "non_traversable")

    def __post_init__(self) -> None:
        columns = sorted(self.table.feature_names)
        for order in (*self.orders, *((self.alt,) if self.alt else ())):
            if sorted(order) != columns:
                raise ValueError(
                    f"order {' > '.join(order)} is not an order of the class table's columns ({', '.join(columns)}); "
                    "a table of one's own takes its plan from for_table"
                )

    @property
    def table(self) -> ClassTable:
        return self.classes or default_classes()

    def scenarios(self) -> list[str]:
        return list(self.courses) or [*TEST_SET, *variations()]

    def demo_course(self) -> str:
        """The course the demonstrations of sections 1-3 and 5 go over."""
        return self.course or DEMONSTRATIONS.course

    def teach_course(self) -> str:
        """The course the teaching drives of section 6 go over."""
        return self.course or recipe_named(self.recipe).course

    def perceptions(self) -> list[PerceptionModel]:
        """The robustness section's perception models, in the plan's order."""
        return [load_perception(spec, self.classes) for spec in self.presets]

    def sweep_name(self) -> str | None:
        """The name of the perception model the robustness sweep varies (None: no sweep)."""
        return None if self.sweep_base is None else load_perception(self.sweep_base, self.classes).name

    def default_order(self) -> tuple[str, ...]:
        return PreferenceProfile.default(self.classes).order


def course_name(course: str) -> str:
    """A course as the study's log and report name it: a packaged scenario's name, a file's name."""
    return Path(course).name if course.endswith((".yaml", ".yml")) else course


def reversed_order(table: ClassTable) -> tuple[str, ...] | None:
    """The default order of ``table`` reversed, the lethal column still last: every pair of classes
    the other way round; None where the table has one class besides the lethal column."""
    if len(table.terrain_names) < 2:
        return None
    order = PreferenceProfile.default(table).order
    last = (table.lethal_column,) if table.lethal_column else ()
    return (*reversed([c for c in order if c not in last]), *last)


def for_table(
    plan: StudyPlan,
    table: ClassTable,
    course: str | Path | None = None,
    perceptions: tuple[PerceptionModel, ...] = (),
    follow_up: bool = False,
) -> StudyPlan:
    """The plan for a class table of one's own: ``course`` for the demonstrations and the teaching
    drives (None: the table's teaching course, which run_study writes beside STUDY.md); as many of its orders as the plan has (its default
    first, then drawn at random as ``select --orders random:N`` draws them); its generated layouts
    gen:6000... for the evaluation courses, as many as the plan's teaching layouts; its default
    order reversed as the other profile (every pair the other way round); and as perception,
    clean and ``perceptions`` (the last active one swept; none: no sweep)."""
    from terrapref.report.select import parse_orders

    default = PreferenceProfile.default(table).order
    n = min(len(plan.orders), math.factorial(len(table.terrain_names)))
    drawn = [o for o in parse_orders(f"random:{n}", table) if o != default]
    plan = replace(
        plan,
        classes=table,
        course=None if course is None else str(course),
        follow_up=follow_up,
        alt=reversed_order(table),
        orders=(default, *drawn[: n - 1]),
        courses=tuple(f"gen:{6000 + i}" for i in range(len(plan.layouts))),
    )
    return with_perception(plan, perceptions)


def with_perception(plan: StudyPlan, perceptions: tuple[PerceptionModel, ...]) -> StudyPlan:
    """The plan with clean and the active ones of ``perceptions`` as its presets, the last of them
    swept part by part (none: no sweep)."""
    active = [p for p in perceptions if p.active]
    return replace(plan, presets=("clean", *active), sweep_base=active[-1] if active else None)


FULL = StudyPlan()
QUICK = StudyPlan(
    seeds=1,
    minutes=(2.0,),
    epochs=100,
    cnn_epochs=15,
    presets=("clean", "field"),
    sweep=(1.0, 4.0),
    horizons=(),
    widths=(16,),
    orders=TEACH_ORDERS[:2],
    styles=("default", "wide"),
    layouts=("gen:5000", "gen:5001"),
)


@dataclass(frozen=True)
class TrainJob:
    """One model the study trains (step 3): what, from which featurised set, into which file."""

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
