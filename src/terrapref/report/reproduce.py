"""`terrapref reproduce`: demonstrations -> models -> closed-loop evaluation -> REPORT.md.

For each training seed, the synthetic driver demonstrates on each recipe's course
(``train_course`` for the paper's recipe and ``ours``, ``teach_course`` for the default recipe
``teach``) and a model is trained by each recipe; every model then drives ``train_course``,
``test_course`` and the figure variations, and so does the synthetic driver. The report gives
the paper's Table 1 and Table 2 with success over seeds (and the planner's agreement with the
driver), each rate with its 95% Wilson interval, the figures, and each step's time; then every
recipe's models once more on the test courses under each perception model asked for (the planner
receives what a robot would; the driver sees the truth), in one table.
"""

from __future__ import annotations

import functools
import json
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from terrapref.evaluation.runner import (
    EXPERT,
    PLANNER,
    RunResult,
    RunSpec,
    Summary,
    annotate_agreement,
    compared_zones,
    run_many,
    summarise,
)
from terrapref.evaluation.stats import rate_text
from terrapref.fileio import write_text_atomic
from terrapref.grid import Engine, run_grid
from terrapref.perception import PerceptionModel
from terrapref.progress import every_tenth
from terrapref.recipes import OURS, PAPER, TEACH, Recipe, RecipeSetup, run_recipe
from terrapref.report.reproduce_relief import FIGURE_COURSE as RELIEF_FIGURE_COURSE
from terrapref.report.reproduce_relief import ReliefPart, relief_lines
from terrapref.report.reproduce_speed import SpeedPart, run_speed_part, speed_figure, speed_lines
from terrapref.report.workload import Workload, core_seconds, count
from terrapref.scenario import packaged_scenarios, resolve_scenario
from terrapref.terrain import ClassTable, PreferenceProfile
from terrapref.vehicle import VehicleConfig

if TYPE_CHECKING:
    from terrapref.learning.train import EpochMetrics

TEST_SET = ("test_course",)
PAPER_VEHICLE = VehicleConfig.paper()  # the reproduction is driven in the paper's setting: 1 m/s, commands applied at once
TRACK_COLOURS = ("orange", "red", "magenta", "limegreen")  # the planners' tracks, by recipe
# The rates of the estimate `reproduce` prints before it starts, of one core, as docs/benchmarks.md measures them.
MODEL_CORE_S = 12.0  # one recipe's model for one seed: its demonstrations, corrections and training
RUN_CORE_S = 0.6  # one closed-loop run of the courses (train_course, test_course, the figures' variations)
SPEED_SEED_CORE_S = 44.0  # one seed of the speed part: its teaching drive, its model and their runs
RELIEF_SEED_CORE_S = 228.0  # one seed of the relief part: its drive of teach_relief, its model and their runs


def variations() -> list[str]:
    return [n for n in packaged_scenarios() if n.startswith("fig")]


@dataclass(frozen=True)
class RecipeModel:
    """A model one recipe trained for one seed, and how its training went."""

    recipe: str
    seed: int
    model: str  # the model file
    history: tuple[EpochMetrics, ...]  # per epoch (for an ensemble, member 0's)
    best_epoch: int
    demo_minutes: float
    correction_minutes: float
    seconds: float  # demonstrating, correcting and training, wall clock
    members: tuple[tuple[tuple[EpochMetrics, ...], int], ...] = ()  # an ensemble's members: (history, chosen epoch) each


@dataclass(frozen=True)
class RecipeRun:
    """A run of the reproduction: which recipe's model drove (``driver``: the synthetic driver)
    and the seed it was trained with (the driver's: its run's seed)."""

    result: RunResult
    recipe: str
    train_seed: int
    perception: str = "clean"  # the perception model's name (what the planner received)

    def to_dict(self) -> dict:
        """As results.json holds it: the run's metrics, without its path."""
        return self.result.to_dict() | {"recipe": self.recipe, "train_seed": self.train_seed, "perception": self.perception}


@dataclass(frozen=True)
class Reproduction:
    """What a reproduction runs.

    Attributes:
        recipes: the recipes trained and compared.
        seeds: training seeds per recipe (and the synthetic driver's runs per course).
        eval_seeds: closed-loop runs per model and course.
        profile: the driver's preference order.
        write_recordings: also write the synthetic driver's demonstrations as recordings under
            ``OUT/work`` (they are featurised as they are driven and kept in memory either way).
        perceptions: each drives the test courses once more (the clean model among them adds
            nothing: the runs above are clean).
        speed_seeds: training seeds of the speed part (recipe teach taught by a driver with speed
            preferences on the field UGV: terrapref.report.reproduce_speed); 0: none.
        relief_seeds: training seeds of the relief part (recipe teach taught on the relief
            teaching course by a driver with a relief style: terrapref.report.reproduce_relief); 0: none.
    """

    recipes: tuple[Recipe, ...] = (PAPER, OURS, TEACH)
    seeds: int = 5
    eval_seeds: int = 1
    profile: PreferenceProfile = field(default_factory=PreferenceProfile.default)
    write_recordings: bool = False
    perceptions: tuple[PerceptionModel, ...] = ()
    speed_seeds: int = 2
    relief_seeds: int = 1

    @functools.cached_property
    def scenarios(self) -> tuple[str, ...]:
        """The courses driven: the training course, the test set and the figures' variations."""
        return ("train_course", *TEST_SET, *variations())


def _train_job(args: tuple[tuple[Recipe, ...], str, int, tuple[str, ...], bool]) -> list[RecipeModel]:
    """Recipes of one seed that share demonstrations, in one process (they never record twice)."""
    recipes, workdir, seed, profile, write = args
    rows = []
    for recipe in recipes:
        t0 = time.perf_counter()
        out = run_recipe(recipe, workdir, RecipeSetup(seed, PreferenceProfile(profile), vehicle=PAPER_VEHICLE), write_recordings=write)
        members = tuple((tuple(m.history), m.best_epoch) for m in out.result.members or [out.result])
        rows.append(
            RecipeModel(
                recipe.name,
                seed,
                str(out.model),
                tuple(out.result.history),
                out.result.best_epoch,
                out.demo_minutes,
                out.correction_minutes,
                time.perf_counter() - t0,
                members,
            )
        )
    return rows


def reproduce(
    out_dir: str | Path, setup: Reproduction | None = None, engine: Engine | None = None, log: Callable[[str], None] = print
) -> Path:
    """Run the whole reproduction ``setup`` (default: :class:`Reproduction`'s) into ``out_dir``
    and return the path of REPORT.md; ``engine`` runs its jobs (default: local processes, one
    per core)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    setup = setup or Reproduction()
    engine = engine or Engine()
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    trained = _train_all(setup, out, engine, log)
    timings["demonstrate + correct + train"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    runs = _evaluate(setup, trained, engine, log)
    timings["closed-loop evaluation"] = time.perf_counter() - t0
    speed = None
    if setup.speed_seeds > 0 and any(r.name == TEACH.name for r in setup.recipes):
        t0 = time.perf_counter()
        part = SpeedPart(setup.speed_seeds, setup.profile.order, (*TEST_SET, *variations()))
        speed = (part, run_speed_part(part, out, engine, log))
        timings["speed: demonstrate, train, drive"] = time.perf_counter() - t0
    relief = None
    if setup.relief_seeds > 0 and any(r.name == TEACH.name for r in setup.recipes):
        t0 = time.perf_counter()
        relief_part = ReliefPart(setup.relief_seeds, setup.profile.order)
        relief = (relief_part, run_speed_part(relief_part.drives, out, engine, log))
        timings["relief: demonstrate, train, drive"] = time.perf_counter() - t0
    log("[3/3] figures and REPORT.md ...")
    return _write_report(out, setup, _Outcome(runs, trained, timings, speed, relief), engine)


def _train_all(setup: Reproduction, out: Path, engine: Engine, log: Callable[[str], None]) -> list[RecipeModel]:
    """Rule 1: every recipe's model for every seed, by seed and then in the recipes' order."""
    # One job per seed and demonstration protocol (recipes recording the same demonstrations stay
    # together), the costliest first, so that both cores stay busy to the end.
    groups: dict = {}
    for r in setup.recipes:
        groups.setdefault((r.course, r.disturbance), []).append(r)
    cost = {
        key: max(
            r.demonstrations * (1 + r.train.classifier.members * r.train.optimiser.epochs * (2 if r.train.data.mirror else 1) / 100)
            for r in g
        )
        for key, g in groups.items()
    }
    jobs = [
        (tuple(g), str(out / "work" / f"seed{s}"), s, setup.profile.order, setup.write_recordings)
        for key, g in sorted(groups.items(), key=lambda kv: -cost[kv[0]])
        for s in range(setup.seeds)
    ]
    log(
        f"[1/3] demonstrations, corrections and training: {len(setup.recipes) * setup.seeds} models "
        f"({', '.join(r.name for r in setup.recipes)} x {setup.seeds} seeds) ..."
    )
    done = run_grid(
        _train_job,
        jobs,
        engine,
        lambda k, n: log(f"      trained {k}/{n} job(s)"),
        describe=lambda j: f"recipes {', '.join(r.name for r in j[0])}, seed {j[2]}",
    )
    order = {r.name: i for i, r in enumerate(setup.recipes)}
    return sorted((row for rows in done for row in rows), key=lambda t: (t.seed, order[t.recipe]))


def _evaluate(setup: Reproduction, trained: list[RecipeModel], engine: Engine, log: Callable[[str], None]) -> list[RecipeRun]:
    """Rule 2: every model and the synthetic driver on every course, the planners' agreement with the driver."""
    specs = evaluation_specs(setup, trained)
    log(f"[2/3] closed-loop evaluation: {len(specs)} runs ...")
    results = annotate_agreement(run_many(specs, progress=every_tenth(log), engine=engine))
    return [_recipe_run(r, spec, trained) for r, spec in zip(results, specs, strict=True)]


def evaluation_specs(setup: Reproduction, trained: list[RecipeModel]) -> list[RunSpec]:
    """The runs of rule 2, the longest first (no core idles at the end): every model on every
    course, again on the test courses under each perception model that perturbs anything, and the
    synthetic driver on every course once per seed."""
    specs = [
        RunSpec(sc, e, PLANNER, t.model, setup.profile.order, vehicle=PAPER_VEHICLE)
        for t in trained
        for sc in setup.scenarios
        for e in range(setup.eval_seeds)
    ]
    specs += [
        RunSpec(sc, e, PLANNER, t.model, setup.profile.order, perception=p, vehicle=PAPER_VEHICLE, perception_draw=t.seed)
        for p in setup.perceptions
        if p.active
        for t in trained
        for sc in (*TEST_SET, *variations())
        for e in range(setup.eval_seeds)
    ]
    specs += [
        RunSpec(sc, s, EXPERT, None, setup.profile.order, vehicle=PAPER_VEHICLE) for sc in setup.scenarios for s in range(setup.seeds)
    ]
    return sorted(specs, key=lambda sp: -scenario_length(sp.scenario))


def reproduction_workload(setup: Reproduction) -> Workload:
    """How much ``setup`` trains and drives, counted without listing a job (any number of seeds):
    the models and runs of rules 1 and 2 (:func:`evaluation_specs`), and those of the speed and
    relief parts, at the rates of :data:`MODEL_CORE_S` and the like."""
    taught = any(r.name == TEACH.name for r in setup.recipes)
    speed, relief = (setup.speed_seeds, setup.relief_seeds) if taught else (0, 0)
    models = len(setup.recipes) * setup.seeds
    perceived = sum(p.active for p in setup.perceptions) * len((*TEST_SET, *variations()))
    runs = (models * (len(setup.scenarios) + perceived)) * setup.eval_seeds + setup.seeds * len(setup.scenarios)
    relief_courses = ReliefPart(relief, setup.profile.order).courses if relief else ()
    part_runs = (speed * len((*TEST_SET, *variations())) + relief * len(relief_courses)) * 2  # each model's and its driver's
    factors = f"{count(len(setup.recipes), 'recipe')} x {count(setup.seeds, 'seed')}"
    if speed or relief:
        factors += f", and {speed + relief} of recipe teach for the speed and relief parts"
    core_s = core_seconds((models, MODEL_CORE_S), (runs, RUN_CORE_S), (speed, SPEED_SEED_CORE_S), (relief, RELIEF_SEED_CORE_S))
    where = count(len(setup.scenarios) + len(relief_courses), "course")
    return Workload(models + speed + relief, factors, runs + part_runs, core_s, where)


def _recipe_run(result: RunResult, spec: RunSpec, trained: list[RecipeModel]) -> RecipeRun:
    """A run with the recipe and training seed of the model that drove it (the driver's: ``driver`` and the run's seed)."""
    model = next((t for t in trained if t.model == spec.model_path), None)
    return RecipeRun(result, model.recipe, model.seed, spec.perceived_as) if model is not None else RecipeRun(result, "driver", result.seed)


@functools.lru_cache(maxsize=64)
def scenario_length(scenario: str, classes: ClassTable | None = None) -> float:
    """Length of a scenario's reference path [m] (to start the longest runs first), read with ``classes``."""
    return resolve_scenario(scenario, classes).path_length_m()


def _zone_rows(runs: list[RecipeRun], scenario: str, recipes: tuple[Recipe, ...]) -> list[str]:
    """One table row per zone of ``scenario``: its expectation, the driver's choice, each recipe's choice and successes."""
    s = resolve_scenario(scenario)
    rows = []
    for zone in s.zones:
        drv = _choices(runs, scenario, "driver", zone.id)
        expect = drv[0][2] if drv else zone.expect
        cells = [zone.id, zone.label or "", expect, _mode(drv)]
        for recipe in recipes:
            c = _choices(runs, scenario, recipe.name, zone.id)
            lethal = sum(ch == ex and not ok for ch, ok, ex in c)
            note = f" ({lethal} touched non_traversable)" if lethal else ""
            cells += [_mode(c), f"{sum(ok for _, ok, _ in c)}/{len(c)}{note}"]
        rows.append("| " + " | ".join(cells) + " |")
    return rows


def _choices(runs: list[RecipeRun], scenario: str, recipe: str, zone_id: str) -> list[tuple[str, bool, str]]:
    """(choice, success, expectation) in one zone of every run of ``recipe`` (or ``driver``) on ``scenario``."""
    out = []
    for r in runs:
        if r.result.scenario == scenario and r.recipe == recipe:
            z = next(z for z in r.result.metrics.zones if z.id == zone_id)
            out.append((z.choice, z.success, z.expect))
    return out


def _mode(choices: list[tuple[str, bool, str]]) -> str:
    if not choices:
        return "-"
    names = [c for c, _, _ in choices]
    top = max(set(names), key=names.count)
    return top if names.count(top) == len(names) else f"{top} ({names.count(top)}/{len(names)})"


class _Outcome(NamedTuple):
    """What a reproduction ran: the runs, the models, the time per step, and the speed part's and
    the relief part's runs (None: not run)."""

    runs: list[RecipeRun]
    trained: list[RecipeModel]
    timings: dict[str, float]
    speed: tuple[SpeedPart, list[RunResult]] | None
    relief: tuple[ReliefPart, list[RunResult]] | None = None


def _write_report(out: Path, setup: Reproduction, outcome: _Outcome, engine: Engine) -> Path:
    """REPORT.md, its figures and results.json (every run's metrics and the time per step)."""
    runs, trained, timings, speed, relief = outcome
    t_fig = time.perf_counter()
    figs = out / "figures"
    figs.mkdir(exist_ok=True)
    clean = [r for r in runs if r.perception == "clean"]
    _draw_figures(figs, setup, clean, trained, engine)
    lines = _introduction(setup) + _summary_table(setup.recipes, clean) + _perception_table(setup, runs)
    lines += _zone_tables(setup.recipes, clean) + _training_lines(setup.recipes, trained)
    if speed is not None:
        part, results = speed
        speed_figure(figs / "speed.png", results)
        lines += [""] + speed_lines(part, results, "figures/speed.png")
    if relief is not None:
        relief_part, relief_results = relief
        speed_figure(figs / "relief.png", relief_results, RELIEF_FIGURE_COURSE)
        lines += [""] + relief_lines(relief_part, relief_results, "figures/relief.png")
    lines += ["", "## Figures", ""] + [f"- `figures/{sc}.png`" for sc in setup.scenarios]
    timings = {**timings, "figures": time.perf_counter() - t_fig}
    lines += ["", "## Time per step (wall clock)", "", "| step | seconds |", "|---|---|"]
    lines += [f"| {k} | {v:.1f} |" for k, v in timings.items()] + [f"| total | {sum(timings.values()):.1f} |"]
    speed_runs = [r.to_dict() for r in speed[1]] if speed is not None else []
    relief_runs = [r.to_dict() for r in relief[1]] if relief is not None else []
    results = {"runs": [r.to_dict() for r in runs], "speed_runs": speed_runs, "relief_runs": relief_runs, "timings": timings}
    write_text_atomic(out / "results.json", json.dumps(results, indent=1))
    return write_text_atomic(out / "REPORT.md", "\n".join(lines) + "\n")


def _draw_figures(figs: Path, setup: Reproduction, runs: list[RecipeRun], trained: list[RecipeModel], engine: Engine) -> None:
    """Each course with the driver's and the planners' seed-0 paths; each recipe's seed-0 training
    curve; drawn as a grid of jobs (a dozen figures of half a second each)."""
    jobs: list[tuple] = [("map", str(figs / f"{sc}.png"), sc, _tracks(runs, sc, setup.recipes)) for sc in setup.scenarios]
    jobs += [
        ("curve", str(figs / f"training_{t.recipe}.png"), t.recipe, [([asdict(h) for h in history], best) for history, best in t.members])
        for t in trained
        if t.seed == 0
    ]
    run_grid(_figure_job, jobs, engine, describe=lambda j: f"figure {j[1]}")


def _figure_job(job: tuple) -> str:
    """Draw one of the reproduction's figures: a course's map with its tracks, or a training curve."""
    from terrapref.plots import save_loss_curve, save_map
    from terrapref.world import rasterise

    kind, path, name, content = job
    if kind == "map":
        scenario = resolve_scenario(name)
        save_map(path, scenario, rasterise(scenario), content, title=f"{name}: reference, driver and planner paths")
    else:
        save_loss_curve(path, content, title=f"training, recipe {name}, seed 0")
    return path


def _tracks(runs: list[RecipeRun], scenario: str, recipes: tuple[Recipe, ...]) -> list[tuple[str, np.ndarray, str]]:
    """(label, path, colour) of the driver's and of every recipe's seed-0 model's seed-0 run on ``scenario``."""
    tracks = []
    for r in runs:
        if r.result.scenario != scenario or r.result.seed != 0:
            continue
        if r.recipe == "driver":
            tracks.append(("driver (seed 0)", r.result.xy, "deepskyblue"))
        elif r.train_seed == 0:
            color = TRACK_COLOURS[[x.name for x in recipes].index(r.recipe) % len(TRACK_COLOURS)]
            tracks.append((f"planner, {r.recipe} (seed 0)", r.result.xy, color))
    return tracks


def _introduction(setup: Reproduction) -> list[str]:
    """The title, the setting and one line per recipe."""
    lines = [
        "# terrapref: reproduction of the paper's Tables 1 and 2",
        "",
        f"Preference profile: {setup.profile} (grass preferred over every patch). Synthetic driver as the human;",
        f"{setup.seeds} training seeds per recipe (each seed: its own demonstrations and training initialisation),",
        f"{setup.eval_seeds} evaluation run(s) per model and scenario. Every number below comes from driving the simulator.",
        "",
        "Recipes:",
    ]
    return lines + _recipe_lines(setup.recipes)


def _recipe_lines(recipes: tuple[Recipe, ...]) -> list[str]:
    """One line per recipe: its demonstrations, pushes, corrections and training."""
    lines = []
    for r in recipes:
        d = r.disturbance
        clear = (
            f", beginning {d.clear_m:g} m + {d.clear_s:g} s x the speed from lethal terrain"
            if d is not None and (d.clear_m or d.clear_s)
            else ""
        )
        pushes = (
            f"with disturbances ({d.rate_hz:g} pushes/s of {d.min_yaw_rate_rps:g}-{d.max_yaw_rate_rps:g} rad/s{clear})"
            if d is not None
            else "undisturbed"
        )
        lines.append(
            f"- **{r.name}**: {r.demonstrations} demonstration run(s) of {r.course}, {pushes}, {r.corrections} correction session(s), "
            f"{r.train.optimiser.epochs} epochs, residual path {'on' if r.train.classifier.skip else 'off'}, class-balanced loss {'on' if r.train.data.class_balance else 'off'}, "
            f"mirrored samples {'on' if r.train.data.mirror else 'off'}"
            + (f", {r.train.classifier.members} ensemble members" if r.train.classifier.members > 1 else "")
            + "".join(f", {summary}" for rule in r.rules if (summary := rule.summary()))
            + (
                "; labels from a moving average of w if the driver's hand shakes more than half the w grid's spacing"
                if r.train.data.steady_labels
                else ""
            )
            + "."
        )
    return lines


def _summary_table(recipes: tuple[Recipe, ...], runs: list[RecipeRun]) -> list[str]:
    """Each recipe's and the driver's zone success, agreement, collisions and completion over the test courses."""
    test_names = [*TEST_SET, *variations()]
    lines = [
        "",
        "## Summary (test_course and the figure variations)",
        "",
        "Zone success against the zones' expectations; agreement: the planner's choice equals the synthetic driver's in the same "
        "zone of the same run (evaluation seed). 95% Wilson intervals over all zones of all training seeds. Only what was "
        "driven counts: a zone the vehicle did not get past is a failure (not reached); stops are the planner's (terrapref.planner.stop).",
        "",
        "| who | zone success | agreement with the driver | collisions | completed | not reached | stops (per 100 m) | runs |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name in [*(r.name for r in recipes), "driver"]:
        chosen = [r.result for r in runs if r.recipe == name and r.result.scenario in test_names]
        zones = [z for r in chosen for z in r.metrics.zones]
        compared = compared_zones(chosen)
        s = summarise(chosen, PLANNER if name != "driver" else EXPERT)
        agreement = rate_text(sum(a.agrees for a in compared), len(compared)) if compared else "—"
        lines.append(
            f"| {name} | {rate_text(sum(z.success for z in zones), len(zones))} | {agreement} | {s.collision_count} | "
            f"{s.completed_rate:.0%} | {s.not_reached} | {_stops_text(s)} | {s.runs} |"
        )
    return lines


def _perception_table(setup: Reproduction, runs: list[RecipeRun]) -> list[str]:
    """Each recipe on the test courses under each perception model: agreement with the driver (who sees
    the truth), zone success and collisions."""
    names = ["clean", *(p.name for p in setup.perceptions if p.active)]
    if len(names) == 1:
        return []
    test_names = {*TEST_SET, *variations()}
    lines = [
        "",
        "## Under what a robot sees (test_course and the figure variations)",
        "",
        "The same models, each planner receiving what a robot's segmentation, localisation and camera would give instead of "
        "the truth (terrapref.perception; `terrapref perception` lists the presets, docs/perception.md derives them), each "
        "training seed's model meeting errors of its own draw; the driver sees the truth. Each cell: agreement with the "
        "driver, zone success, collisions, runs completed and stops; 95% Wilson intervals.",
        "",
        "| recipe | " + " | ".join(names) + " |",
        "|---|" + "---|" * len(names),
    ]
    for recipe in setup.recipes:
        cells = []
        for name in names:
            chosen = [r.result for r in runs if r.recipe == recipe.name and r.perception == name and r.result.scenario in test_names]
            compared = compared_zones(chosen)
            zones = [z for r in chosen for z in r.metrics.zones]
            s = summarise(chosen, PLANNER)
            cells.append(
                f"{rate_text(sum(a.agrees for a in compared), len(compared))}; success {rate_text(sum(z.success for z in zones), len(zones))}; "
                f"{s.collision_count} collisions; completed {s.completed_rate:.0%}; stops {_stops_text(s)}"
            )
        lines.append(f"| {recipe.name} | " + " | ".join(cells) + " |")
    return lines


def _stops_text(s: Summary) -> str:
    """A summary's stops: how many, per 100 m driven, and the seconds stood still by reason."""
    if not s.stop_count:
        return "0"
    reasons = ", ".join(f"{why} {seconds:.1f} s" for why, seconds in s.stops_s.items())
    per = f" ({s.stops_per_100m:.2f})" if s.stops_per_100m is not None else ""
    return f"{s.stop_count}{per}: {reasons}"


def _zone_tables(recipes: tuple[Recipe, ...], runs: list[RecipeRun]) -> list[str]:
    """Table 1 (train_course), Table 2 (test_course) and the figure variations, zone by zone."""
    header = "| zone | terrains | expected | driver | " + " | ".join(f"{r.name} planner | {r.name} success" for r in recipes) + " |"
    sep = "|" + "---|" * (4 + 2 * len(recipes))
    lines = []
    for title, names in (
        ("Table 1: training scenarios (train_course)", ["train_course"]),
        ("Table 2: test scenarios (test_course)", ["test_course"]),
    ):
        lines += ["", f"## {title}", "", header, sep]
        for sc in names:
            lines += _zone_rows(runs, sc, recipes)
    lines += ["", "## Figure 7 and 8 variations", "", header.replace("| zone |", "| scenario |"), sep]
    for sc in variations():
        for row in _zone_rows(runs, sc, recipes):
            lines.append(row.replace("| 1 |", f"| {sc} |", 1))
    return lines


def _training_lines(recipes: tuple[Recipe, ...], trained: list[RecipeModel]) -> list[str]:
    """Per recipe: the epochs chosen, the validation accuracy there, and the minutes demonstrated and corrected."""
    lines = ["", "## Training", ""]
    for r in recipes:
        ts = [t for t in trained if t.recipe == r.name]
        lines.append(
            f"- {r.name}: chosen epochs {[t.best_epoch for t in ts]}; validation accuracy at the chosen epoch "
            f"{[round(t.history[t.best_epoch - 1].val_acc, 3) for t in ts]}; demonstration {np.mean([t.demo_minutes for t in ts]):.1f} min, "
            f"corrections {np.mean([t.correction_minutes for t in ts]):.1f} min per seed. Curve: `figures/training_{r.name}.png`."
        )
    return lines
