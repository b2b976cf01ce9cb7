"""`terrapref study`: the paper's claims as measured figures, over seeds, with one evaluation.

Steps (each parallel across processes):
1. Demonstrations: per training seed, the synthetic driver demonstrates on ``train_course`` (with
   a class table of one's own: the table's teaching course) with the protocol of the recipe
   ``ours`` (two runs with disturbances), once under the default profile and once under another
   profile.
2. Featurisation: utility features (and, for the ablation, other horizons) and the CNN's
   downsampled images, each read from the recordings once.
3. Training: C (recipe ``ours``, without the planner's second stage: the study measures C
   itself), the linear utility model and the CNN on the same
   recordings; the same three on the first 0.5 ... 10 minutes of them; C under the other
   profile; C's ablations.
4. Teaching: per training seed, one drive of ``teach_course`` (or the table's teaching course)
   and a model by the default recipe (``teach``), for each of several preference orders (default
   driver style) and for each driver style (default order).
5. Closed-loop evaluation on ``test_course`` and the figure variations (with a table of one's
   own: its generated layouts): every model, pure
   pursuit, the hand-tuned cost planner and the synthetic driver. The taught models, and the
   driver of each order and style, on generated layouts none of them has seen; the default
   style's taught models again under each perception preset (terrapref.perception).
6. Robustness sweep: the default style's taught models under each part of a preset alone
   (labels, pose, camera, frames), at rising multiples of it, until agreement with the driver
   falls below 90%.
7. STUDY.md with tables and figures, and study.json with every run's metrics.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from terrapref.evaluation.runner import EXPERT, HAND_COST, PLANNER, PURE_PURSUIT, RunSpec, run_many
from terrapref.features import FeatureConfig
from terrapref.fileio import write_text_atomic
from terrapref.grid import Engine, run_grid
from terrapref.perception import PerceptionModel, load_perception
from terrapref.progress import every_tenth
from terrapref.recipes import OURS
from terrapref.records import to_plain
from terrapref.report.reproduce import scenario_length
from terrapref.report.study_plan import DEMONSTRATIONS, FULL, StudyPlan, TrainedModel, TrainJob, course_name
from terrapref.report.study_report import ModelVariant, RunTag, StudyRun, agreement, write_study
from terrapref.report.workload import Workload, core_seconds, count
from terrapref.terrain import ClassTable, PreferenceProfile

if TYPE_CHECKING:
    from terrapref.learning.train import TrainConfig
    from terrapref.recipes import Recipe

LEARNED = ("C", "linear", "cnn")  # methods trained from demonstrations


# The rates of the estimate `study` prints before it starts, of one core, as docs/benchmarks.md measures them.
DEMONSTRATION_CORE_S = 9.0  # one seed and profile's demonstrations, featurised
TRAINED_CORE_S = 5.0  # one model trained from them (C, the linear model or the CNN)
TAUGHT_CORE_S = 40.0  # one teaching drive and its model (select's rate: recipe teach on its course)
RUN_CORE_S = 0.6  # one closed-loop run of a course or a generated layout
SWEPT_RUN_CORE_S = 3.5  # one run of the robustness sweep (a part of a preset, at a multiple of it)

PARTS = ("labels", "pose", "camera", "frames")  # the parts of a perception model the robustness sweep varies one at a time
SWEEP_FLOOR = 0.9  # a part's sweep stops at the first level where agreement falls below this


def swept(plan: StudyPlan, part: str, level: float) -> PerceptionModel:
    """The robustness sweep's perception model: one part of the plan's base preset alone, ``level`` times as large."""
    return load_perception(plan.sweep_base, plan.classes).part(part).scaled(level)


# -- jobs (module level: they run in worker processes) ---------------------------------------


@dataclass(frozen=True)
class DemonstrationJob:
    """One seed's demonstrations of ``course`` under one profile (step 1), kept in memory and
    featurised into ``sets``: (file, kind, horizon) each, a dataset (``kind`` "U", with horizon n)
    or the CNN's samples."""

    workdir: str
    seed: int
    profile: tuple[str, ...]
    sets: tuple[tuple[str, str, int | None], ...]
    course: str
    classes: ClassTable | None = None

    def to_dict(self) -> dict:
        return {"workdir": self.workdir, "seed": self.seed, "profile": list(self.profile), "course": self.course}


def _demonstration_job(job: DemonstrationJob) -> list[str]:
    """Drive and featurise one :class:`DemonstrationJob`; returns the files written."""
    from terrapref.recipes import RecipeSetup, demonstrate

    setup = RecipeSetup(job.seed, PreferenceProfile.parse(list(job.profile), job.classes), course=job.course, classes=job.classes)
    recordings = demonstrate(DEMONSTRATIONS, job.workdir, setup, write=False)
    return [_featurise_set(recordings, out, kind, n) for out, kind, n in job.sets]


def _featurise_set(recordings: list, out: str, kind: str, n: int | None) -> str:
    """Featurise recordings into ``out``: a dataset (``kind`` "U", with horizon n) or CNN samples."""
    from terrapref.dataset import build_dataset, save_dataset
    from terrapref.tensorfile import write_tensor_file

    features = FeatureConfig()
    if n is not None:
        features = replace(features, preference=replace(features.preference, n_steps=n))
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    if kind == "U":
        save_dataset(build_dataset(recordings, features), out)
    else:
        from terrapref.baselines.cnn import CnnConfig, cnn_samples

        images, paths, labels = cnn_samples(recordings, features, CnnConfig().stride)
        meta = {"format": "terrapref-cnn-samples/1", **{k: recordings[0].meta[k] for k in ("camera", "classes", "profile")}}
        write_tensor_file(out, {"images": images, "paths": paths, "labels": labels}, meta)
    return out


def _frames_for(minutes: float | None, rate_hz: float = 10.0) -> int | None:
    return None if minutes is None else int(round(minutes * 60.0 * rate_hz))


@dataclass(frozen=True)
class TeachJob:
    """One drive of the teaching recipe's course by the driver of ``order`` and ``style``, and its model (step 4)."""

    seed: int
    order: tuple[str, ...]
    style: str
    epochs: int
    recipe: str
    workdir: str
    course: str | None = None  # None: the recipe's own
    follow_up: bool = False
    classes: ClassTable | None = None  # study.json holds the plan's, once

    def to_dict(self) -> dict:
        """As study.json holds it, as the teaching part's C."""
        return {"study": "teach", "method": "C", **to_plain(replace(self, classes=None), omit_none=("course", "classes"))}


@dataclass(frozen=True)
class TaughtModel:
    """A taught model: its job, the model file, the minutes demonstrated and the wall time it took [s]."""

    job: TeachJob
    out: str
    demo_minutes: float
    train_s: float

    def to_dict(self) -> dict:
        return {**self.job.to_dict(), "out": self.out, "demo_minutes": self.demo_minutes, "train_s": self.train_s}


def _train_job(job: TrainJob) -> TrainedModel:
    """Train one model (C, linear or CNN) on the first ``minutes`` of a featurised set."""
    t0 = time.perf_counter()
    samples = _train_cnn(job) if job.method == "cnn" else _train_on_utilities(job)
    return TrainedModel(job, samples, time.perf_counter() - t0)


def _train_cnn(job: TrainJob) -> int:
    """Train the CNN on the job's samples; returns how many it learned from."""
    from terrapref.baselines.cnn import CnnConfig, save_cnn, train_cnn
    from terrapref.tensorfile import read_tensor_file

    n = _frames_for(job.minutes)
    tensors, meta = read_tensor_file(job.data, "terrapref-cnn-samples/1", "no such file", "not CNN samples")
    images, paths, labels = (tensors[k][:n] for k in ("images", "paths", "labels"))
    table = ClassTable.from_dict(meta["classes"], job.data)
    features = FeatureConfig(feature_classes=table.feature_names)
    config = CnnConfig(n_classes=max(c.id for c in table.classes) + 1, epochs=job.cnn_epochs, seed=job.seed)  # a one-hot channel per id
    result = train_cnn(images, paths, labels.astype(np.int64), features.preference.m, config)
    meta = {k: meta[k] for k in ("camera", "classes", "profile")} | {"features": features.to_dict()}
    save_cnn(job.out, result, config, images.shape[1:], meta)
    return len(labels)


def _train_on_utilities(job: TrainJob) -> int:
    """Fit the linear utility, or train C, on the job's utilities; returns how many samples it learned from."""
    from terrapref.dataset import Dataset, load_dataset
    from terrapref.learning.linear import fit_linear_utility
    from terrapref.learning.pipeline import RunOptions, train_and_save
    from terrapref.planner.policy import save_linear

    n = _frames_for(job.minutes)
    ds = load_dataset(job.data)
    if n is not None:
        ds = Dataset(ds.U[:n], ds.labels[:n], ds.w[:n], ds.source[:n], ds.meta)
    meta = {k: ds.meta[k] for k in ("features", "camera", "classes", "profile")}
    if job.method == "linear":
        save_linear(job.out, fit_linear_utility(ds.U, ds.labels), meta)
    else:
        # C's models are compared by how they drive; what the data identify is the teaching section's question
        train_and_save(ds, job.out, _c_config(job), options=RunOptions(checkpoints=False, identify=False))
    return len(ds)


def _c_config(job: TrainJob) -> TrainConfig:
    """C's training settings for a job: recipe ours's, with the job's seed, epochs and changes."""
    # The study compares C itself with the baselines: its models are trained without decision rules (C's argmax steers).
    return OURS.train.updated({"seed": job.seed, "optimiser": {"epochs": job.epochs}, **(job.train or {})})


def _teach_job(job: TeachJob) -> TaughtModel:
    """The recipe's drive(s) by the synthetic driver of ``order`` and ``style``, and its model."""
    from terrapref.recipes import RecipeSetup, run_recipe

    t0 = time.perf_counter()
    recipe = _teach_recipe(job)
    setup = RecipeSetup(
        job.seed, PreferenceProfile(job.order), course=job.course, style=job.style, classes=job.classes, follow_up=job.follow_up
    )
    out = run_recipe(recipe, job.workdir, setup)
    return TaughtModel(job, str(out.model), out.demo_minutes, time.perf_counter() - t0)


def _teach_recipe(job: TeachJob) -> Recipe:
    """The named recipe of a teaching job, trained for the job's epochs."""
    from terrapref.recipes import recipe_named

    named = recipe_named(job.recipe)
    return replace(named, train=named.train.with_epochs(job.epochs))


def teach_jobs(plan: StudyPlan, work: Path) -> list[TeachJob]:
    """The teaching study's models: every order under the default style, every style under the default order."""
    from terrapref.report.select import order_tag

    default, lethal = plan.orders[0], plan.table.lethal_column
    combos = [(o, "default") for o in plan.orders] + [(default, st) for st in plan.styles if st != "default"]
    return [
        TeachJob(
            s,
            tuple(o),
            st,
            plan.epochs,
            plan.recipe,
            str(work / "teach" / f"{order_tag(o, lethal)}_{st}_s{s}"),
            plan.course,
            plan.follow_up,
            plan.classes,
        )
        for s in range(plan.seeds)
        for o, st in combos
    ]


def study_workload(plan: StudyPlan) -> Workload:
    """How much ``plan`` trains and drives, counted without listing a job (any number of seeds):
    per seed the models of :func:`_train_jobs` and :func:`teach_jobs`, and the runs of
    :func:`_evaluation_runs` and, at most (a part drops out early), of :func:`_sweep`."""
    per_seed = len(LEARNED) * (1 + len(plan.minutes)) + (plan.alt is not None) + 2 + len(plan.horizons) + len(plan.widths)
    drives = len(plan.orders) + sum(style != "default" for style in plan.styles)  # an order and style each: teach_jobs' combos
    active = sum(model.active for model in plan.perceptions())
    base = load_perception(plan.sweep_base, plan.classes) if plan.sweep_base is not None else None
    parts = sum(base.part(part).active for part in PARTS) if base is not None else 0
    alt = int(plan.alt is not None)
    runs = len(plan.scenarios()) * plan.seeds * (per_seed + 2 * alt + 3 + alt)  # _course_runs: the models, the three drivers
    runs += len(plan.layouts) * (drives + plan.seeds * (drives + len(plan.orders) * active))  # _layout_runs
    swept = len(plan.layouts) * plan.seeds * len(plan.orders) * parts * len(plan.sweep)
    core_s = core_seconds(
        (plan.seeds * (1 + alt), DEMONSTRATION_CORE_S),
        (plan.seeds * per_seed, TRAINED_CORE_S),
        (plan.seeds * drives, TAUGHT_CORE_S),
        (runs, RUN_CORE_S),
        (swept, SWEPT_RUN_CORE_S),
    )
    factors = f"{count(plan.seeds, 'seed')} x {per_seed + drives} models a seed"
    where = f"{count(len(plan.scenarios()), 'course')} and {count(len(plan.layouts), 'layout')}"
    return Workload(plan.seeds * (per_seed + drives), factors, runs + swept, core_s, where, up_to=swept > 0)


# -- the study -------------------------------------------------------------------------------


@dataclass(frozen=True)
class _Workspace:
    """What every step of a study shares: the plan, the work folder, where the jobs run, the log."""

    plan: StudyPlan
    work: Path
    engine: Engine
    log: Callable[[str], None]

    def map(self, fn: Callable, jobs: list, what: str) -> list:
        """Map ``fn`` over ``jobs`` on the engine (results in order), logging progress; a failed job is named by its inputs."""

        def describe(job: object) -> str:
            return f"{what} {job.to_dict() if isinstance(job, (TrainJob, TeachJob, DemonstrationJob)) else job!r}"

        return run_grid(fn, jobs, self.engine, lambda k, n: self.log(f"      {what} {k}/{n}"), describe=describe)


@contextmanager
def _timed(timings: dict[str, float], step: str) -> Iterator[None]:
    """Record the wall time of the ``with`` block as ``timings[step]`` [s]."""
    t0 = time.perf_counter()
    yield
    timings[step] = time.perf_counter() - t0


def run_study(out_dir: str | Path, plan: StudyPlan = FULL, engine: Engine | None = None, log: Callable[[str], None] = print) -> Path:
    """Run every step into ``out_dir`` on ``engine`` (default: local processes, one per core);
    returns the path of STUDY.md."""
    out = Path(out_dir)
    work = out / "work"
    work.mkdir(parents=True, exist_ok=True)
    if plan.classes is not None and plan.course is None:
        from terrapref.scenario.teaching import write_teaching_course

        plan = replace(plan, course=str(write_teaching_course(out, plan.classes)))
    ws = _Workspace(plan, work, engine or Engine(), log)
    timings: dict[str, float] = {}
    with _timed(timings, "demonstrations and featurisation"):
        _demonstrate(ws)
    with _timed(timings, "training and teaching"):
        trained, taught = _train_and_teach(ws)
    with _timed(timings, "evaluation"):
        runs = _evaluate(ws, trained, taught)
    with _timed(timings, "robustness sweep"):
        runs += _sweep(ws, taught, runs)
    report_started = time.perf_counter()
    log("[5/5] tables, figures and STUDY.md ...")
    study = {"plan": _plan_dict(plan), "trained": [t.to_dict() for t in [*trained, *taught]], "runs": [r.to_dict() for r in runs]}
    write_text_atomic(out / "study.json", json.dumps(study, indent=1, default=float))
    return write_study(out, plan, trained, runs, timings, report_started=report_started)


def _demonstrate(ws: _Workspace) -> None:
    """Rule 1: per seed, the demonstrations under the default profile and under the other (kept in
    memory, as the reproduction's are), and from them the utilities and the CNN's samples of the
    default ones, the utilities of the other profile's, and the utilities at every ablated horizon."""
    plan = ws.plan
    profiles = [("default", plan.default_order())] + ([("alt", plan.alt)] if plan.alt else [])
    jobs = []
    for s in range(plan.seeds):
        for name, order in profiles:
            base = ws.work / f"{name}_s{s}"
            sets = [(str(base / "U.safetensors"), "U", None)]
            if name == "default":
                sets += [
                    (str(base / "cnn.safetensors"), "cnn", None),
                    *((str(base / f"U_n{n}.safetensors"), "U", n) for n in plan.horizons),
                ]
            jobs.append(DemonstrationJob(str(base), s, order, tuple(sets), plan.demo_course(), plan.classes))
    ws.log(
        f"[1/5] demonstrations and featurisation: {plan.seeds} seed(s) x {len(profiles)} profile(s) x {DEMONSTRATIONS.demonstrations} runs "
        f"of {course_name(plan.demo_course())}: {len(jobs)} demonstration sets, featurised as {sum(len(j.sets) for j in jobs)} datasets ..."
    )
    ws.map(_demonstration_job, jobs, "demonstration set")


def _train_and_teach(ws: _Workspace) -> tuple[list[TrainedModel], list[TaughtModel]]:
    """Rule 2: every model trained from the demonstrations, and (section 6) every drive of the
    teaching recipe's course and its model: one grid, so that neither kind waits for the other's
    last job."""
    plan = ws.plan
    train, teach = _train_jobs(plan, ws.work), teach_jobs(plan, ws.work)
    ws.log(
        f"[2/5] training and teaching: {len(train)} models, and {len(teach)} drives of {course_name(plan.teach_course())} and "
        f"their models (recipe {plan.recipe}; {len(plan.orders)} orders, {len(plan.styles)} driver styles, {plan.seeds} seed(s)) ..."
    )
    done = ws.map(_model_job, [*teach, *train], "model")  # the drives and their recipe's training first: the longest jobs
    return done[len(teach) :], done[: len(teach)]


def _model_job(job: TrainJob | TeachJob) -> TrainedModel | TaughtModel:
    """A job of step 3: a model trained from the demonstrations, or a drive taught by the recipe."""
    return _teach_job(job) if isinstance(job, TeachJob) else _train_job(job)


def _train_jobs(plan: StudyPlan, work: Path) -> list[TrainJob]:
    """Per seed: each learned method on all and on the first minutes of the demonstrations, C on the
    other profile's, and C's ablations; the longest to train first."""
    jobs: list[TrainJob] = []
    models = work / "models"
    models.mkdir(exist_ok=True)

    def add(study: str, method: str, s: int, data: Path, tag: str, **extra) -> None:
        jobs.append(
            TrainJob(study, method, s, str(data), str(models / f"{tag}_s{s}.safetensors"), plan.epochs, plan.cnn_epochs, tag, **extra)
        )

    for s in range(plan.seeds):
        base = work / f"default_s{s}"
        for method in LEARNED:
            add("baselines", method, s, base / ("cnn.safetensors" if method == "cnn" else "U.safetensors"), method)
            for minutes in plan.minutes:
                add(
                    "efficiency",
                    method,
                    s,
                    base / ("cnn.safetensors" if method == "cnn" else "U.safetensors"),
                    f"{method}_{minutes:g}min",
                    minutes=minutes,
                )
        if plan.alt is not None:
            add("profile", "C", s, work / f"alt_s{s}" / "U.safetensors", "C_alt")
        add(
            "ablation",
            "C",
            s,
            base / "U.safetensors",
            "C_no_distance",
            train={"data": {"ignore_features": ["distance"]}},
            variant="without the distance utility",
        )
        add(
            "ablation",
            "C",
            s,
            base / "U.safetensors",
            "C_flat",
            train={"classifier": {"compress": False, "skip": False}},
            variant="without the row-wise compression (flat MLP)",
        )
        for n in plan.horizons:
            add("ablation", "C", s, base / f"U_n{n}.safetensors", f"C_n{n}", variant=f"horizon n = {n}")
        for w in plan.widths:
            add("ablation", "C", s, base / "U.safetensors", f"C_h{w}", train={"classifier": {"hidden": w}}, variant=f"hidden width {w}")
    jobs.sort(key=lambda j: -(j.minutes or 99) * (3 if j.method != "linear" else 0.1))  # long jobs first
    return jobs


def _evaluate(ws: _Workspace, trained: list[TrainedModel], taught: list[TaughtModel]) -> list[StudyRun]:
    """Rule 3: every closed-loop run, tagged with its place in the study."""
    planned = _evaluation_runs(ws.plan, trained, taught)
    ws.log(f"[3/5] closed-loop evaluation: {len(planned)} runs over {len(ws.plan.scenarios()) + len(ws.plan.layouts)} scenarios ...")
    results = run_many([spec for spec, _ in planned], progress=every_tenth(ws.log), engine=ws.engine)
    return [StudyRun(tag, r.scenario, r.metrics) for (_, tag), r in zip(planned, results, strict=True)]


def _evaluation_runs(plan: StudyPlan, trained: list[TrainedModel], taught: list[TaughtModel]) -> list[tuple[RunSpec, RunTag]]:
    """Every run with its tag: the evaluation courses, then the teaching layouts; the longest courses
    first, so that no worker is left with a long run at the end."""
    runs = [run for sc in plan.scenarios() for run in _course_runs(plan, sc, trained)]
    runs += [run for layout in plan.layouts for run in _layout_runs(plan, layout, taught)]
    return sorted(runs, key=lambda run: -scenario_length(run[0].scenario, plan.classes))


def _course_runs(plan: StudyPlan, sc: str, trained: list[TrainedModel]) -> list[tuple[RunSpec, RunTag]]:
    """One evaluation course: every trained model's runs, then per seed the drivers without a model,
    and the synthetic driver under the other profile."""
    default, alt, classes = plan.default_order(), plan.alt, plan.classes
    runs = [run for t in trained for run in _model_runs(plan, sc, t.job, default)]
    for s in range(plan.seeds):
        runs += [
            (RunSpec(sc, s, method, None, default, classes=classes), RunTag("baselines", method, s))
            for method in (HAND_COST, PURE_PURSUIT, EXPERT)
        ]
        if alt is not None:
            runs.append((RunSpec(sc, s, EXPERT, None, alt, classes=classes), RunTag("profile", EXPERT, s, scored_under="own")))
    return runs


def _model_runs(plan: StudyPlan, sc: str, job: TrainJob, default: tuple[str, ...]) -> list[tuple[RunSpec, RunTag]]:
    """A trained model's run on a course under the profile it learned; the other profile's C again
    under the default profile, and the default C under the other profile and under every perturbation."""
    alt, classes = plan.alt, plan.classes
    own = alt if job.study == "profile" else default
    runs = [
        (
            RunSpec(sc, 0, PLANNER, job.out, own, classes=classes),
            RunTag(job.study, job.method, job.seed, ModelVariant(job.minutes, job.variant), scored_under="own"),
        )
    ]
    if job.study == "profile":  # the same run's choices, scored under the default profile
        runs.append(
            (RunSpec(sc, 0, PLANNER, job.out, default, classes=classes), RunTag("profile_cross", "C", job.seed, scored_under="default"))
        )
    if job.study == "baselines" and job.method == "C" and alt is not None:
        runs.append(
            (RunSpec(sc, 0, PLANNER, job.out, alt, classes=classes), RunTag("profile_cross", "C_default", job.seed, scored_under="alt"))
        )
    return runs


def _layout_runs(plan: StudyPlan, layout: str, taught: list[TaughtModel]) -> list[tuple[RunSpec, RunTag]]:
    """One teaching layout: every taught model, and the driver of every order and style taught; the
    default style's models again under every perception preset but clean."""
    classes = plan.classes
    runs = [
        (
            RunSpec(layout, 0, PLANNER, t.out, t.job.order, classes=classes),
            RunTag("teach", "C", t.job.seed, order=t.job.order, style=t.job.style),
        )
        for t in taught
    ]
    runs += [
        (RunSpec(layout, 0, EXPERT, None, order, style=style, classes=classes), RunTag("teach", EXPERT, 0, order=order, style=style))
        for order, style in sorted({(t.job.order, t.job.style) for t in taught})
    ]
    for model in plan.perceptions():
        if model.active:
            runs += [
                (
                    RunSpec(layout, 0, PLANNER, t.out, t.job.order, perception=model, classes=classes),
                    RunTag("robustness", "C", t.job.seed, kind=model.name, order=t.job.order, style=t.job.style),
                )
                for t in taught
                if t.job.style == "default"
            ]
    return runs


def _sweep(ws: _Workspace, taught: list[TaughtModel], runs: list[StudyRun]) -> list[StudyRun]:
    """Rule 4: each part of the plan's base preset alone, at each level of the sweep in turn, on the
    default style's taught models; a part drops out after the first level where agreement with
    the driver (the teaching section's driver runs) falls below SWEEP_FLOOR."""
    plan = ws.plan
    models = [t for t in taught if t.job.style == "default"]
    driver = [r for r in runs if r.tag.study == "teach" and r.tag.method == EXPERT and r.tag.style == "default"]
    base = load_perception(plan.sweep_base, plan.classes) if plan.sweep_base is not None else None
    left, swept_runs = [part for part in PARTS if base is not None and base.part(part).active], []
    for level in plan.sweep:
        if not left or not models:
            break
        planned = [
            (
                RunSpec(layout, 0, PLANNER, t.out, t.job.order, perception=swept(plan, part, level), classes=plan.classes),
                RunTag("robustness", "C", t.job.seed, kind=part, level=level, order=t.job.order, style="default"),
            )
            for part in left
            for layout in plan.layouts
            for t in models
        ]
        ws.log(f"[4/5] robustness sweep at {level:g} x {plan.sweep_name()}'s: {', '.join(left)} ({len(planned)} runs) ...")
        results = run_many([spec for spec, _ in planned], progress=every_tenth(ws.log), engine=ws.engine)
        done = [StudyRun(tag, r.scenario, r.metrics) for (_, tag), r in zip(planned, results, strict=True)]
        swept_runs += done
        for part in list(left):
            ok, n = agreement([r for r in done if r.tag.kind == part], driver)
            if n and ok / n < SWEEP_FLOOR:
                left.remove(part)
    return swept_runs


def _plan_dict(plan: StudyPlan) -> dict:
    return {
        "seeds": plan.seeds,
        "minutes": list(plan.minutes),
        "epochs": plan.epochs,
        "cnn_epochs": plan.cnn_epochs,
        "presets": [p.name for p in plan.perceptions()],
        "sweep_base": plan.sweep_name(),
        "sweep": list(plan.sweep),
        "horizons": list(plan.horizons),
        "widths": list(plan.widths),
        "scenarios": plan.scenarios(),
        "orders": [list(o) for o in plan.orders],
        "styles": list(plan.styles),
        "layouts": list(plan.layouts),
        "recipe": plan.recipe,
        "classes": plan.classes.to_dict() if plan.classes is not None else None,
        "course": plan.course,
        "follow_up": plan.follow_up,
        "alt": list(plan.alt) if plan.alt else None,
    }
