"""Recipes: how demonstrations become a model, end to end (demonstrate, correct, train).

Named recipes (:data:`RECIPES`, ``terrapref recipes``; ``--recipe NAME`` in ``train``,
``reproduce`` and ``study``):

- ``teach`` (the default, :data:`DEFAULT_RECIPE`): the product's. One drive of ``teach_course``
  with disturbances; C with a residual path, a class-balanced loss and mirrored samples, 100
  epochs at learning rate 3e-3, an ensemble of three; labels from a moving average of w when the
  hand shakes (terrapref.learning.steady); rules: the second stage, fitted through the
  look-ahead, then the offset rule, which drives (terrapref.rules).
- ``ours``: the paper's setting done well: two drives of ``train_course`` with disturbances,
  the same C (one network); rules: the second stage, fitted frame by frame, which drives. Used
  by ``terrapref reproduce`` beside ``paper``.
- ``paper``: the published recipe: one drive of ``train_course``, 15 epochs of the paper's C;
  no rule: C's argmax drives.

How each recipe scored is measured, not written here: docs/learning.md and the reports of
``terrapref reproduce`` and ``terrapref select``.

A recipe also holds the options a user may choose on purpose (more drives, correction
sessions).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from terrapref.dataset import Dataset, build_dataset
from terrapref.demos.expert import ExpertConfig, ExpertDriver
from terrapref.demos.meta import CorrectionRoundInfo, ExpertInfo
from terrapref.demos.recording import MemoryRecordingWriter, Recording, RecordingWriter, read_recording
from terrapref.demos.relief_style import ReliefStyle
from terrapref.demos.session import DisturbanceConfig, DriveSetup, RunSettings, record_run
from terrapref.features import FeatureConfig
from terrapref.learning.identify import FollowUp
from terrapref.learning.model_file import load_model
from terrapref.learning.network import ClassifierConfig
from terrapref.learning.pipeline import RunOptions, train_and_save
from terrapref.learning.train import DataOptions, OptimiserConfig, TrainConfig, TrainResult
from terrapref.perception import PerceptionModel
from terrapref.planner import Planner, PlannerDriver
from terrapref.recipes.corrections import CorrectionDrivers, record_corrections
from terrapref.registry import Registry
from terrapref.rules import OffsetConfig, RuleConfig, SecondStageConfig, SpeedConfig
from terrapref.rules.second.rule import with_second_stage
from terrapref.scenario import resolve_scenario
from terrapref.sim.loop import Simulation
from terrapref.terrain import ClassTable, PreferenceProfile
from terrapref.vehicle import VehicleConfig


@dataclass(frozen=True)
class Recipe:
    """One way of turning a person's driving into a model.

    Attributes:
        name: label in reports.
        demonstrations: demonstration runs of the training course.
        corrections: correction sessions after the first model (one run of the course each,
            the model retrained on everything after each).
        train: training hyperparameters.
        disturbance: pushes injected while demonstrating, so that recoveries are shown
            (None: the driver drives undisturbed).
        rules: the decision rules fitted with C, in order: the last steering rule steers (none:
            C's argmax), a speed rule sets the speed (terrapref.rules). Each says what its fit
            reads of the frames.
        course: the demonstration course.
        summary: one line on what the recipe is for (``terrapref recipes``).
    """

    name: str
    demonstrations: int = 1
    corrections: int = 0
    train: TrainConfig = field(default_factory=TrainConfig)
    disturbance: DisturbanceConfig | None = None
    rules: tuple[RuleConfig, ...] = ()
    course: str = "train_course"
    summary: str = ""

    def __post_init__(self) -> None:
        if self.demonstrations < 1 or self.corrections < 0:
            raise ValueError("a recipe needs demonstrations >= 1 and corrections >= 0")

    def features(self, base: FeatureConfig | None = None) -> FeatureConfig:
        """The feature configuration C trains with (``base``, else the default); what the rules'
        fits read besides is theirs (:attr:`rules`)."""
        return base or FeatureConfig()

    def to_dict(self) -> dict:
        return {**asdict(self), "rules": [{"type": r.type, **asdict(r)} for r in self.rules]}


PAPER = Recipe(
    "paper", summary="the published recipe: one drive of train_course, 15 epochs of the paper's C, C's argmax drives (reproduction only)"
)
# What recipes ours and teach train: 100 epochs of C at learning rate 3e-3 (chosen on generated
# layouts against 300 epochs at 1e-3: the same agreement with the driver for a third of the
# steps; docs/learning.md) with the residual path, a class-balanced loss and mirrored samples,
# (the second stage's linear utility is fitted to the same samples).
_RECOMMENDED = TrainConfig(OptimiserConfig(epochs=100, lr=3e-3), ClassifierConfig(skip=True), DataOptions(class_balance=True, mirror=True))
OURS = Recipe(
    "ours",
    demonstrations=2,
    train=_RECOMMENDED,
    rules=(SecondStageConfig(),),
    disturbance=DisturbanceConfig(rate_hz=0.3),
    summary="two drives of train_course: the paper's setting done well (the reproduction's Tables 1 and 2); the second stage drives",
)
TEACH = Recipe(
    "teach",
    course="teach_course",
    train=replace(_RECOMMENDED, classifier=ClassifierConfig(skip=True, members=3), data=replace(_RECOMMENDED.data, steady_labels=True)),
    rules=(SecondStageConfig(weight=5.0, lookahead=True), OffsetConfig(), SpeedConfig()),
    disturbance=DisturbanceConfig(rate_hz=0.6, clear_m=3.0, clear_s=2.0),
    summary="one drive of teach_course: any preference order from five minutes (the default); the offset rule steers, the speed rule sets the speed (docs/learning.md)",
)
RECIPES: Registry[Recipe] = Registry("recipe")
for _recipe in (TEACH, OURS, PAPER):
    RECIPES.register(_recipe.name, _recipe, _recipe.summary)
DEFAULT_RECIPE = TEACH.name


def recipe_named(name: str, flag: str = "--recipe") -> Recipe:
    """A named recipe; an unknown name is a user error (naming ``flag``) listing the known ones."""
    return RECIPES.get(name, flag)


def rules_with(recipe: Recipe, second_stage: bool | None = None, stage_weight: float | None = None) -> tuple[RuleConfig, ...]:
    """The recipe's rules with the second stage added, left out or reweighed
    (terrapref.rules.second.rule.with_second_stage; ``train --second-stage/--no-second-stage/--stage-weight``)."""
    return with_second_stage(recipe.rules, second_stage, stage_weight, f"recipe {recipe.name}")


@dataclass(frozen=True)
class RecipeSetup:
    """What a recipe is run with, besides the recipe itself.

    Attributes:
        seed: seeds the demonstrations (run ``k``: ``seed * 100 + k``), training and the correction rounds.
        profile: the synthetic driver's preference order (None: the course's class table's).
        course: the course demonstrated (None: the recipe's own).
        features: C's feature configuration (None: the default).
        style: the synthetic driver's style (terrapref.demos.expert.STYLES).
        perception: what the robot receives instead of the truth in the demonstrations (None: the truth).
        classes: the class table the course is read with (None: the default).
        follow_up: after the demonstrations, drive a follow-up course of the pairs of classes they
            left unidentified (terrapref.scenario.teaching.follow_up), and train on both.
        vehicle: the vehicle driven (None: the default, a field UGV; ``VehicleConfig.paper()`` for
            the paper's setting).
        speeds: the synthetic driver's cruising speeds by class, over its style's [m/s].
        relief: the synthetic driver's relief style (None: it drives relief as if it were flat).
    """

    seed: int
    profile: PreferenceProfile | None = None
    course: str | None = None
    features: FeatureConfig | None = None
    style: str = "default"
    perception: PerceptionModel | None = None
    classes: ClassTable | None = None
    follow_up: bool = False
    vehicle: VehicleConfig | None = None
    speeds: tuple[tuple[str, float], ...] = ()
    relief: ReliefStyle | None = None


@dataclass
class RecipeOutput:
    """What :func:`run_recipe` made: the model, the recordings it wrote (none when the
    demonstrations were kept in memory), how training went, and the minutes demonstrated and
    corrected."""

    model: Path
    recordings: list[Path]
    result: TrainResult
    demo_minutes: float
    correction_minutes: float


@dataclass(frozen=True)
class _Drive:
    """One synthetic-driver run of a course: where its recording goes, and how it is driven."""

    course: str
    out: Path
    seed: int
    disturbance: DisturbanceConfig | None
    profile: PreferenceProfile | None
    style: str
    perception: PerceptionModel | None = None
    classes: ClassTable | None = None
    vehicle: VehicleConfig | None = None
    speeds: tuple[tuple[str, float], ...] = ()
    relief: ReliefStyle | None = None


def _drive(drive: _Drive, features: FeatureConfig, write: bool) -> tuple[Recording, bool]:
    """The run's recording, and whether it was driven now (False: a matching recording on disk was reused).

    Written to ``drive.out`` with ``write``, else kept in memory (the same frames and labels,
    featurised from the simulation's own views). A complete recording on disk of the same
    course under the same driver, profile, seed, disturbances and perception is reused either
    way, so recipes sharing a seed share their demonstrations.
    """
    scenario = resolve_scenario(drive.course, drive.classes)
    profile = drive.profile or PreferenceProfile.default(scenario.classes)
    setup = DriveSetup.of(scenario, drive.vehicle, preference=features.preference)
    expert_cfg = replace(ExpertConfig.styled(drive.style, profile.order, drive.speeds), relief=drive.relief)
    pushes = drive.disturbance.to_dict() if drive.disturbance is not None else None
    perception = drive.perception or PerceptionModel()
    if (drive.out / "meta.json").exists():
        existing = read_recording(drive.out)
        driver = existing.meta["driver"]
        if (
            existing.complete
            and existing.meta.get("scenario") == scenario.name
            and existing.meta.get("profile") == list(profile.order)
            and driver.get("seed") == drive.seed
            and driver.get("disturbance") == pushes
            and driver.get("config") == expert_cfg.to_dict()
            and existing.meta.get("perception", PerceptionModel().to_dict()) == perception.to_dict()
            and existing.meta.get("sim", {}).get("vehicle") == setup.sim.vehicle.to_dict()
        ):
            return existing, False
    meta = setup.meta(ExpertInfo.of(drive.seed, drive.style, expert_cfg, drive.disturbance), profile, perception)
    writer = (
        RecordingWriter(drive.out, meta, scenario.to_dict(), overwrite=True)
        if write
        else MemoryRecordingWriter(drive.out, meta, scenario.to_dict())
    )
    settings = RunSettings(setup.preference, drive.disturbance, perception)
    driver = ExpertDriver(expert_cfg, setup.sim.camera_rate_hz)
    record_run(setup.simulation(), driver, writer, settings, np.random.default_rng(drive.seed))
    return (read_recording(drive.out) if write else writer.recording()), True


def demonstrate(
    recipe: Recipe, workdir: str | Path, setup: RecipeSetup, log: Callable[[str], None] | None = None, write: bool = True
) -> list[Recording]:
    """The recipe's demonstration runs by the synthetic driver, as ``setup`` says.

    Run ``k`` of the course (seed ``setup.seed * 100 + k``) is recorded as ``workdir/COURSE_K`` (a
    name that ends in ``_disturbed`` with disturbances, and then ``_perceived`` when its frames went
    through an active perception model) with ``write``; without, it is kept in memory under that
    name. A complete run already on disk under the same course, driver, profile, seed,
    disturbances and perception is reused, so recipes sharing a seed share their demonstrations.
    """
    workdir = Path(workdir)
    features = setup.features or FeatureConfig()
    course = setup.course or recipe.course
    tail = "" if recipe.disturbance is None else "_disturbed"
    if setup.perception is not None and setup.perception.active:
        tail += "_perceived"
    name = Path(course).stem if course.endswith((".yaml", ".yml")) else course
    drives = [
        _Drive(
            course,
            workdir / f"{name}_{k}{tail}",
            setup.seed * 100 + k,
            recipe.disturbance,
            setup.profile,
            setup.style,
            setup.perception,
            setup.classes,
            setup.vehicle,
            setup.speeds,
            setup.relief,
        )
        for k in range(recipe.demonstrations)
    ]
    recordings = []
    for i, drive in enumerate(drives):
        recording, driven = _drive(drive, features, write)
        recordings.append(recording)
        if driven and log:
            log(f"demonstration {i + 1}/{len(drives)} ({course}): {len(recording)} frames")
    return recordings


def follow_up_plan(
    recordings: list[Recording],
    recipe: Recipe,
    features: FeatureConfig | None = None,
    cache: dict | None = None,
    frames: Callable[[int, int], None] | None = None,
) -> FollowUp:
    """What a follow-up course after ``recordings`` (in the order driven) shows, and what it
    leaves (:func:`~terrapref.learning.identify.plan_follow_up`): the drives featurised (with
    ``recipe.features(features)``; ``cache`` and ``frames``, the progress by frame, as
    build_dataset takes them) and steadied as ``recipe`` trains; the report ``inspect`` prints
    of all of them, and of all but the last. After the first drive of a table whose compact
    course leaves its strips to the follow-up (:func:`~terrapref.scenario.teaching.ladder_follows`;
    whatever course that drive was of), on flat ground, it shows the ladder of the learned order
    in place of the open pairs' neighbours (:func:`~terrapref.scenario.teaching.ladder`); else
    its neighbours are those the course can show
    (:func:`~terrapref.scenario.teaching.neighbours_within`)."""
    from terrapref.learning.identify import plan_follow_up
    from terrapref.learning.train import comparisons_by_drive, identify
    from terrapref.recipes.lessons import relief_plan
    from terrapref.scenario.teaching import ladder_follows, neighbours_within

    cache = {} if cache is None else cache  # the drives before the last are featurised once for both reports
    steady = recipe.train.data.steady_labels

    def dataset(recs: list[Recording], progress: Callable | None = None) -> Dataset:
        return build_dataset(recs, recipe.features(features), rules=recipe.rules, cache=cache, progress=progress)

    pooled = dataset(recordings, None if frames is None else lambda p: frames(p.frames_done, p.frames))
    before = dataset(recordings[:-1]) if len(recordings) > 1 else None
    earlier = identify(before, steady=steady) if before is not None else None
    last = str(recordings[-1].path)
    learned = identify(pooled, steady=steady)
    plan = plan_follow_up(learned, comparisons_by_drive(pooled, steady), earlier, last)
    relief, relief_left, on_relief = relief_plan(pooled, before, last)
    classes = recordings[0].classes
    if len(recordings) == 1 and not on_relief and ladder_follows(classes):
        order = tuple(c for c in learned.order if c in classes.terrain_names)
        return replace(plan, neighbours=(), relief=relief, relief_left=relief_left, ladder=order)
    neighbours = neighbours_within(classes, plan.open, plan.neighbours, relief)
    return replace(plan, neighbours=tuple(neighbours), relief=relief, relief_left=relief_left, on_relief=on_relief)


def _follow_up(
    recipe: Recipe,
    recordings: list[Recording],
    workdir: Path,
    setup: RecipeSetup,
    log: Callable[[str], None] | None,
    cache: dict | None = None,
) -> list[Recording]:
    """The synthetic driver's drive of the follow-up course of what ``recordings`` left open
    (written as ``workdir/<course>_more.yaml``); none when they identify every pair. ``cache``
    keeps the recordings' features for training (build_dataset)."""
    from terrapref.fileio import write_text_atomic
    from terrapref.scenario.teaching import Beside, follow_up_course

    plan = follow_up_plan(recordings, recipe, setup.features, cache)
    if not (plan.open or plan.ladder):
        return []
    scenario = resolve_scenario(str(setup.course), setup.classes)
    name = f"{scenario.name}_more"
    course = follow_up_course(scenario.classes, plan.open, name, [scenario.name], Beside(plan.neighbours, order=plan.ladder))
    path = workdir / f"{name}_s{setup.seed}_{'_'.join(c[:2] for c in (setup.profile.order if setup.profile else ()))}.yaml"
    workdir.mkdir(parents=True, exist_ok=True)
    write_text_atomic(path, course.to_yaml())
    if log:
        shown = [f"{len(plan.open)} pairs open ({', '.join(f'{a} vs {b}' for a, b in plan.open)})"] if plan.open else []
        shown += [f"the ladder of {' > '.join(plan.ladder)}"] if plan.ladder else []
        log(f"follow-up course: {'; '.join(shown)}")
    return demonstrate(replace(recipe, demonstrations=1), workdir, replace(setup, course=str(path)), log, write=False)


def record_demonstrations(recipe: Recipe, workdir: str | Path, setup: RecipeSetup, log: Callable[[str], None] | None = None) -> list[Path]:
    """The recipe's demonstration runs (:func:`demonstrate`), written as recordings in ``workdir``; their folders."""
    return [r.path for r in demonstrate(recipe, workdir, setup, log, write=True)]


def run_recipe(
    recipe: Recipe, workdir: str | Path, setup: RecipeSetup, log: Callable[[str], None] | None = None, write_recordings: bool = False
) -> RecipeOutput:
    """Demonstrate, correct, train, as ``setup`` says; write into ``workdir``.

    Demonstrations come from :func:`demonstrate` (shared by recipes with the same seed and
    protocol, through the recordings on disk), kept in memory unless ``write_recordings``;
    corrections and the model go to ``workdir/<recipe name>/``.
    """
    workdir = Path(workdir)
    own = workdir / recipe.name.replace(" ", "_")
    own.mkdir(parents=True, exist_ok=True)
    course = setup.course or recipe.course
    scenario = resolve_scenario(course, setup.classes)
    profile = setup.profile or PreferenceProfile.default(scenario.classes)
    features = recipe.features(setup.features)
    setup = replace(setup, profile=profile, course=course, features=features)
    recordings = demonstrate(recipe, workdir, setup, log, write=write_recordings)
    cache: dict = {}  # the recordings' features, computed once for the follow-up's question, training and retraining
    if setup.follow_up:
        recordings += _follow_up(recipe, recordings, workdir, setup, log, cache)
    paths = [r.path for r in recordings if not r.in_memory]
    demo_s = sum(r.duration_s for r in recordings)
    model = own / "model.safetensors"
    result = _trained(recipe, recordings, model, setup, cache)
    corr_s = 0.0
    if recipe.corrections:  # the planner drives the course; only then is a simulation needed here
        drive = DriveSetup.of(scenario, setup.vehicle, preference=features.preference)
        sim = drive.simulation()
    for r in range(recipe.corrections):
        out = own / f"corrections_{r}"
        corr_s += _correction_round(drive, sim, setup, model, out, r)
        recordings.append(read_recording(out))
        paths.append(out)
        result = _trained(recipe, recordings, model, setup, cache)
        if log:
            log(f"correction session {r + 1}/{recipe.corrections}: {len(recordings[-1])} frames, retrained")
    return RecipeOutput(model, paths, result, demo_s / 60.0, corr_s / 60.0)


def _trained(recipe: Recipe, recordings: list[Recording], model: Path, setup: RecipeSetup, cache: dict) -> TrainResult:
    """The recipe's model trained on ``recordings`` and written to ``model``."""
    return train_and_save(
        build_dataset(recordings, setup.features, cache=cache, rules=recipe.rules),
        model,
        replace(recipe.train, seed=setup.seed),
        rules=recipe.rules,
        recipe=recipe.name,
        options=RunOptions(checkpoints=False),
    )


def _correction_round(drive: DriveSetup, sim: Simulation, setup: RecipeSetup, model: Path, out: Path, r: int) -> float:
    """Correction round ``r`` in ``sim``: the planner of ``model`` drives the course, the driver
    takes over where it would not have done the same, recorded into ``out``; its duration [s]."""
    expert_cfg = replace(ExpertConfig.styled(setup.style, setup.profile.order, setup.speeds), relief=setup.relief)
    meta = drive.meta(CorrectionRoundInfo(r, setup.seed), setup.profile)
    writer = RecordingWriter(out, meta, drive.scenario.to_dict(), overwrite=True)
    planner = PlannerDriver(Planner(load_model(model)))
    drivers = CorrectionDrivers(planner, ExpertDriver(expert_cfg, drive.sim.camera_rate_hz))
    rng = np.random.default_rng(setup.seed * 100 + 50 + r)
    return record_corrections(sim, drivers, writer, setup.features.preference, rng).duration_s
