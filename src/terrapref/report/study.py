"""`terrapref study`: the paper's claims as measured figures, over seeds, with one evaluation.

Stages (each parallel across processes):
1. Demonstrations: per training seed, the synthetic driver demonstrates on ``train_course``
   with the protocol of the recipe ``ours`` (two runs with disturbances), once under the
   default profile and once under another profile.
2. Featurisation: utility features (and, for the ablation, other horizons) and the CNN's
   downsampled images, each read from the recordings once.
3. Training: C (recipe ``ours``, without the planner's second stage: the study measures C
   itself), the linear utility model and the CNN on the same
   recordings; the same three on the first 0.5 ... 10 minutes of them; C under the other
   profile; C's ablations.
4. Teaching: per training seed, one drive of ``teach_course`` and a model by the default recipe
   (``teach``), for each of several preference orders (default driver style) and for each
   driver style (default order).
5. Closed-loop evaluation on ``test_course`` and the figure variations: every model, pure
   pursuit, the hand-tuned cost planner and the synthetic driver; C again under segmentation
   noise, pose noise and dropped or delayed frames. The taught models, and the driver of each
   order and style, on generated layouts none of them has seen.
6. STUDY.md with tables and figures, and study.json with every run's metrics.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from terrapref.fileio import write_text_atomic
from terrapref.evaluation.perturb import Perturbation
from terrapref.grid import Engine, run_grid
from terrapref.evaluation.runner import EXPERT, HAND_COST, PLANNER, PURE_PURSUIT, RunSpec, run_many
from terrapref.features import FeatureConfig
from terrapref.progress import every_tenth
from terrapref.recipes import OURS, TEACH
from terrapref.report.reproduce import TEST_SET, scenario_length, variations
from terrapref.report.study_report import ALT_PROFILE, write_study
from terrapref.terrain import PreferenceProfile

LEARNED = ("C", "linear", "cnn")  # methods trained from demonstrations
# The orders the teaching study trains on: the paper's, then the others that put each of rock
# and water first (non_traversable last: it is lethal to every driver).
TEACH_ORDERS = (
    ("mud", "rock", "water", "non_traversable"),
    ("rock", "mud", "water", "non_traversable"),
    ("water", "mud", "rock", "non_traversable"),
    ("rock", "water", "mud", "non_traversable"),
)
DEMONSTRATIONS = OURS  # the study's data: ours' runs of train_course


@dataclass(frozen=True)
class StudyPlan:
    """How much of everything a study runs.

    Attributes:
        seeds: training seeds (each: its own demonstrations and initialisation).
        minutes: demonstration budgets for the data-efficiency curve [min]; the curve ends with
            all of it (two runs of train_course, about 11 min).
        epochs: C's training epochs (recipe ``ours`` uses 300).
        cnn_epochs: the CNN's training epochs.
        noise: perturbation levels, by kind (see :class:`Perturbation`).
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
    epochs: int = 300
    cnn_epochs: int = 30
    noise: dict[str, tuple[float, ...]] = field(default_factory=lambda: {
        "flip_rate": (0.1, 0.3, 0.5),
        "blobs": (2.0, 6.0),
        "pose_noise_m": (0.25, 0.5, 1.0),
        "drop_rate": (0.5, 0.8),
        "delay_frames": (2.0, 5.0),
    })
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
    noise={"flip_rate": (0.2,), "blobs": (2.0,), "pose_noise_m": (0.25,), "drop_rate": (0.5,), "delay_frames": (3.0,)},
    horizons=(), widths=(16,), orders=TEACH_ORDERS[:2], styles=("default", "wide"), layouts=("gen:5000", "gen:5001"),
)

# Pose noise's heading error grows with its position error: degrees per metre.
POSE_DEG_PER_M = 10.0


def perturbation(kind: str, level: float) -> Perturbation:
    if kind == "pose_noise_m":
        return Perturbation(pose_noise_m=level, pose_noise_deg=POSE_DEG_PER_M * level)
    if kind == "delay_frames":
        return Perturbation(delay_frames=int(level))
    return Perturbation(**{kind: level})


# -- jobs (module level: they run in worker processes) ---------------------------------------


def _record_job(args: tuple[str, int, tuple[str, ...]]) -> list[str]:
    from terrapref.recipes import record_demonstrations

    workdir, seed, profile = args
    return [str(p) for p in record_demonstrations(DEMONSTRATIONS, workdir, seed, PreferenceProfile.parse(list(profile)))]


def _featurise_job(args: tuple[list[str], str, str, int | None]) -> str:
    """Featurise recordings into ``out``: a dataset (``kind`` "U", with horizon n) or CNN samples."""
    from terrapref.demos.dataset import build_dataset, save_dataset
    from terrapref.demos.recording import read_recording
    from terrapref.tensorfile import write_tensor_file

    recs, out, kind, n = args
    recordings = [read_recording(r) for r in recs]
    features = FeatureConfig()
    if n is not None:
        features = replace(features, preference=replace(features.preference, n_steps=n))
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


def _train_job(job: dict) -> dict:
    """Train one model (C, linear or CNN) on the first ``minutes`` of a featurised set."""
    from terrapref.demos.dataset import Dataset, load_dataset
    from terrapref.learning.linear import fit_linear_utility
    from terrapref.learning.pipeline import train_and_save
    from terrapref.learning.train import TrainConfig
    from terrapref.planner.policy import save_linear
    from terrapref.tensorfile import read_tensor_file

    t0 = time.perf_counter()
    n = _frames_for(job.get("minutes"))
    if job["method"] == "cnn":
        from terrapref.baselines.cnn import CnnConfig, save_cnn, train_cnn

        tensors, meta = read_tensor_file(job["data"], "terrapref-cnn-samples/1", "no such file", "not CNN samples")
        images, paths, labels = (tensors[k][:n] for k in ("images", "paths", "labels"))
        config = CnnConfig(epochs=job["cnn_epochs"], seed=job["seed"])
        result = train_cnn(images, paths, labels.astype(np.int64), FeatureConfig().preference.m, config)
        meta = {k: meta[k] for k in ("camera", "classes", "profile")} | {"features": FeatureConfig().to_dict()}
        save_cnn(job["out"], result, config, images.shape[1:], meta)
        samples = len(labels)
    else:
        ds = load_dataset(job["data"])
        if n is not None:
            ds = Dataset(ds.U[:n], ds.labels[:n], ds.w[:n], ds.source[:n], ds.meta)
        samples = len(ds)
        meta = {k: ds.meta[k] for k in ("features", "camera", "classes", "profile")}
        if job["method"] == "linear":
            save_linear(job["out"], fit_linear_utility(ds.U, ds.labels), meta)
        else:
            # The study compares C itself with the baselines: its models drive without the second stage.
            config = TrainConfig(**{**OURS.train.to_dict(), "utility": False, "epochs": job["epochs"], "seed": job["seed"], **job.get("train", {})})
            train_and_save(ds, job["out"], config, checkpoints=False)
    return {**job, "samples": samples, "train_s": time.perf_counter() - t0}


def _teach_job(job: dict) -> dict:
    """The recipe's drive(s) by the synthetic driver of ``order`` and ``style``, and its model."""
    from terrapref.recipes import recipe_named, run_recipe

    t0 = time.perf_counter()
    named = recipe_named(job["recipe"])
    recipe = replace(named, train=replace(named.train, epochs=job["epochs"]))
    out = run_recipe(recipe, job["workdir"], job["seed"], PreferenceProfile(tuple(job["order"])), style=job["style"])
    return {**job, "out": str(out.model), "demo_minutes": out.demo_minutes, "train_s": time.perf_counter() - t0}


def teach_jobs(plan: StudyPlan, work: Path) -> list[dict]:
    """The teaching study's models: every order under the default style, every style under the default order."""
    default = plan.orders[0]
    combos = [(o, "default") for o in plan.orders] + [(default, st) for st in plan.styles if st != "default"]
    return [{"study": "teach", "method": "C", "seed": s, "order": list(o), "style": st, "epochs": plan.epochs, "recipe": plan.recipe,
             "workdir": str(work / "teach" / f"{'_'.join(c[:2] for c in o[:3])}_{st}_s{s}")}
            for s in range(plan.seeds) for o, st in combos]


def _pool_map(fn: Callable, jobs: list, engine: Engine, log: Callable[[str], None], what: str) -> list:
    """Map over jobs on ``engine`` (in order), logging progress."""
    return run_grid(fn, jobs, engine, lambda k, n: log(f"      {what} {k}/{n}"), describe=lambda j: f"{what} {j!r}")


# -- the study -------------------------------------------------------------------------------


def run_study(out_dir: str | Path, plan: StudyPlan = FULL, engine: Engine | None = None, log: Callable[[str], None] = print) -> Path:
    """Run every stage into ``out_dir`` on ``engine`` (default: local processes, one per core);
    returns the path of STUDY.md."""
    out = Path(out_dir)
    work = out / "work"
    work.mkdir(parents=True, exist_ok=True)
    engine = engine or Engine()
    default = PreferenceProfile.default().order
    timings: dict[str, float] = {}
    seeds = list(range(plan.seeds))

    t0 = time.perf_counter()
    log(f"[1/6] demonstrations: {len(seeds)} seed(s) x 2 profiles x {DEMONSTRATIONS.demonstrations} runs ...")
    rec_jobs = [(str(work / f"{tag}_s{s}"), s, prof) for s in seeds for tag, prof in (("default", default), ("alt", ALT_PROFILE))]
    recs = dict(zip([(j[1], j[2]) for j in rec_jobs], _pool_map(_record_job, rec_jobs, engine, log, "demonstration set")))
    timings["demonstrations"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    feat_jobs = []
    for s in seeds:
        base = work / f"default_s{s}"
        feat_jobs += [(recs[(s, default)], str(base / "U.safetensors"), "U", None), (recs[(s, default)], str(base / "cnn.safetensors"), "cnn", None),
                      (recs[(s, ALT_PROFILE)], str(work / f"alt_s{s}" / "U.safetensors"), "U", None)]
        feat_jobs += [(recs[(s, default)], str(base / f"U_n{n}.safetensors"), "U", n) for n in plan.horizons]
    log(f"[2/6] featurisation: {len(feat_jobs)} sets ...")
    _pool_map(_featurise_job, feat_jobs, engine, log, "set")
    timings["featurisation"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    jobs: list[dict] = []
    models = work / "models"
    models.mkdir(exist_ok=True)

    def add(study: str, method: str, s: int, data: Path, tag: str, **extra) -> None:
        jobs.append({"study": study, "method": method, "seed": s, "data": str(data), "out": str(models / f"{tag}_s{s}.safetensors"),
                     "epochs": plan.epochs, "cnn_epochs": plan.cnn_epochs, "tag": tag, **extra})

    for s in seeds:
        base = work / f"default_s{s}"
        for method in LEARNED:
            add("baselines", method, s, base / ("cnn.safetensors" if method == "cnn" else "U.safetensors"), method)
            for minutes in plan.minutes:
                add("efficiency", method, s, base / ("cnn.safetensors" if method == "cnn" else "U.safetensors"), f"{method}_{minutes:g}min", minutes=minutes)
        add("profile", "C", s, work / f"alt_s{s}" / "U.safetensors", "C_alt")
        add("ablation", "C", s, base / "U.safetensors", "C_no_distance", train={"ignore_features": ["distance"]}, variant="without the distance utility")
        add("ablation", "C", s, base / "U.safetensors", "C_flat", train={"compress": False, "skip": False}, variant="without the row-wise compression (flat MLP)")
        for n in plan.horizons:
            add("ablation", "C", s, base / f"U_n{n}.safetensors", f"C_n{n}", variant=f"horizon n = {n}")
        for w in plan.widths:
            add("ablation", "C", s, base / "U.safetensors", f"C_h{w}", train={"hidden": w}, variant=f"hidden width {w}")
    jobs.sort(key=lambda j: -(j.get("minutes") or 99) * (3 if j["method"] != "linear" else 0.1))  # long jobs first
    log(f"[3/6] training: {len(jobs)} models ...")
    trained = _pool_map(_train_job, jobs, engine, log, "model")
    timings["training"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    taught_jobs = teach_jobs(plan, work)
    from terrapref.recipes import recipe_named

    log(f"[4/6] teaching: {len(taught_jobs)} drives of {recipe_named(plan.recipe).course} and models (recipe {plan.recipe}; "
        f"{len(plan.orders)} orders, {len(plan.styles)} driver styles, {plan.seeds} seed(s)) ...")
    taught = _pool_map(_teach_job, taught_jobs, engine, log, "taught model")
    timings["teaching"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    scenarios = plan.scenarios()
    specs: list[RunSpec] = []
    tags: list[dict] = []

    def spec(run: RunSpec, **tag) -> None:
        specs.append(run)
        tags.append(tag)

    for sc in scenarios:
        for t in trained:
            profile = ALT_PROFILE if t["study"] == "profile" else default
            spec(RunSpec(sc, 0, PLANNER, t["out"], profile), study=t["study"], method=t["method"], seed=t["seed"], minutes=t.get("minutes"),
                 variant=t.get("variant"), scored_under="model")
            if t["study"] == "profile":  # the same run's choices, scored under the default profile
                spec(RunSpec(sc, 0, PLANNER, t["out"], default), study="profile_cross", method="C", seed=t["seed"], scored_under="default")
            if t["study"] == "baselines" and t["method"] == "C":
                spec(RunSpec(sc, 0, PLANNER, t["out"], ALT_PROFILE), study="profile_cross", method="C_default", seed=t["seed"], scored_under="alt")
                for kind, levels in plan.noise.items():
                    for level in levels:
                        spec(RunSpec(sc, 0, PLANNER, t["out"], default, perturb=perturbation(kind, level)),
                             study="robustness", method="C", seed=t["seed"], kind=kind, level=level)
        for s in seeds:
            for method in (HAND_COST, PURE_PURSUIT, EXPERT):
                spec(RunSpec(sc, s, method, None, default), study="baselines", method=method, seed=s)
            spec(RunSpec(sc, s, EXPERT, None, ALT_PROFILE), study="profile", method=EXPERT, seed=s, scored_under="model")
    for layout in plan.layouts:
        for t in taught:
            spec(RunSpec(layout, 0, PLANNER, t["out"], tuple(t["order"])), study="teach", method="C", seed=t["seed"], order=t["order"], style=t["style"])
        for order, style in sorted({(tuple(t["order"]), t["style"]) for t in taught}):
            spec(RunSpec(layout, 0, EXPERT, None, order, style=style), study="teach", method=EXPERT, seed=0, order=list(order), style=style)
    # Longest scenarios first, so that no worker is left with a long run at the end.
    order = sorted(range(len(specs)), key=lambda i: -scenario_length(specs[i].scenario))
    specs, tags = [specs[i] for i in order], [tags[i] for i in order]
    log(f"[5/6] closed-loop evaluation: {len(specs)} runs over {len(scenarios) + len(plan.layouts)} scenarios ...")
    results = run_many(specs, progress=every_tenth(log), engine=engine)
    timings["evaluation"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    log("[6/6] tables, figures and STUDY.md ...")
    runs = [{**tag, "scenario": r["scenario"], "metrics": r["metrics"]} for tag, r in zip(tags, results)]
    trained += taught
    write_text_atomic(out / "study.json", json.dumps({"plan": _plan_dict(plan), "trained": trained, "runs": runs}, indent=1, default=float))
    return write_study(out, plan, trained, runs, timings, report_started=t0)


def _plan_dict(plan: StudyPlan) -> dict:
    return {"seeds": plan.seeds, "minutes": list(plan.minutes), "epochs": plan.epochs, "cnn_epochs": plan.cnn_epochs,
            "noise": {k: list(v) for k, v in plan.noise.items()}, "horizons": list(plan.horizons), "widths": list(plan.widths),
            "scenarios": plan.scenarios(), "orders": [list(o) for o in plan.orders], "styles": list(plan.styles), "layouts": list(plan.layouts),
            "recipe": plan.recipe}
