"""Choosing a recipe: every candidate taught by every driver, judged on generated layouts.

For each recipe, preference order and training seed, the synthetic driver of that order (and
style) demonstrates the recipe's course, a model is trained (terrapref.recipes), and the
model and the same driver drive every generated layout. A zone agrees when the planner's choice
equals the driver's in the same zone of the same layout (terrapref.evaluation.runner.zone_agrees).

Layouts ``gen:1000``-``gen:1999`` are where recipes are chosen; a choice is confirmed on layouts
no choice has seen (``gen:2000`` and on, docs/learning.md). Both the trainings and the runs are
grids (terrapref.grid), so ``--engine ray`` spreads them over a cluster.

With relief styles (``--relief-style``), each is one more dimension of the drivers: every order
and seed's driver, with each relief style in turn, demonstrates the relief teaching course
(``teach_relief``, or a class table's ``terrapref course --relief``), and the models and drivers
drive the same layouts with relief (``genrelief:N``). The relief zones (the stretches of the path
that tilt the body past 4 deg, terrapref.evaluation.scoring.relief_zones) are scored beside the
terrain zones, as ``evaluate`` scores them.
"""

from __future__ import annotations

import itertools
import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from terrapref.demos.relief_style import ReliefStyle, parse_relief_style
from terrapref.evaluation.runner import EXPERT, PLANNER, RunResult, RunSpec, relief_agreement, run_many, zone_agrees
from terrapref.evaluation.scoring import NOT_REACHED, RunMetrics
from terrapref.evaluation.speed import SpeedComparison, driver_lateral_limit, run_fields
from terrapref.evaluation.stats import cluster_bootstrap, rate_text
from terrapref.fileio import write_text_atomic
from terrapref.grid import Engine, run_grid
from terrapref.perception import PRESETS, PerceptionModel
from terrapref.planner.model import Model
from terrapref.plots import RateRow, save_intervals
from terrapref.progress import every_tenth
from terrapref.recipes import RecipeSetup, recipe_named, run_recipe
from terrapref.report.workload import Workload, core_seconds, count
from terrapref.scenario.generate import zone_kind
from terrapref.terrain import ClassTable, PreferenceProfile, default_classes
from terrapref.terrain.classes import LETHAL_COLUMN

RANDOM_ORDERS_SEED = 4343  # `--orders random:N` draws its orders with this seed (stated in the report)
RANDOM_SPEEDS_SEED = 6464  # `--speeds random` draws each order and seed's speeds with this seed and theirs
BACKGROUND_SPEEDS_MPS = (1.0, 2.0)  # `--speeds random`: the range of the background's cruising speed [m/s]
FEATURE_SPEEDS_MPS = (0.3, 1.5)  # and of every feature class's [m/s]
TARGET = 0.95  # agreement the default recipe must keep on clean frames
PERCEIVED_TARGET = 0.90  # and under a perception model's errors (docs/perception.md)
# The rates of the estimate `select` prints before it starts, as docs/benchmarks.md states and measures them.
MODEL_CORE_S = 40.0  # one model: its order and seed's demonstration and its training [s of one core]
RUN_CORE_S = 0.8  # one closed-loop run of a generated layout, the planner's or the driver's [s of one core]
RELIEF_MODEL_CORE_S = 115.0  # the same with relief: a drive of the relief teaching course and its training ...
RELIEF_RUN_CORE_S = 12.0  # ... and a run of a generated layout with relief (its frames rendered with depth)
RELIEF_ZONE = "relief"  # the zone kind of a relief zone in select.json's rows (beside generate.zone_kind's)


@dataclass(frozen=True)
class Selection:
    """What to compare: recipes x orders x seeds, on layouts ``gen:first`` .. ``gen:first + courses - 1``."""

    recipes: tuple[str, ...]
    orders: tuple[tuple[str, ...], ...]
    seeds: int = 5
    first: int = 1000
    courses: int = 32
    style: str = "default"
    perceptions: tuple[PerceptionModel, ...] = ()  # what the planner receives driving the layouts, each in turn (none: the truth)
    taught_under: PerceptionModel | None = None  # what the demonstrations recorded (None: the truth)
    classes: ClassTable | None = None  # the class table of the layouts and demonstrations (None: the default)
    course: str | None = None  # the course every recipe demonstrates (None: each recipe's own)
    follow_up: bool = False  # also drive a follow-up course of the pairs the demonstrations left open
    speeds: str | None = None  # the driver's cruising speeds: ``random`` (drawn per order and seed) or CLASS=MPS,...; None: the style's
    relief_styles: tuple[str, ...] = ()  # the drivers' relief styles, as record takes them (none: flat layouts and courses)

    @property
    def driven_under(self) -> tuple[PerceptionModel, ...]:
        """The perception models every model drives the layouts under (the truth when none is given)."""
        return self.perceptions or (PerceptionModel(),)

    @property
    def layouts(self) -> list[str]:
        """The generated layouts: ``gen:N``, or with relief styles ``genrelief:N`` (the same layouts with relief)."""
        family = "genrelief" if self.relief_styles else "gen"
        return [f"{family}:{self.first + i}" for i in range(self.courses)]

    @property
    def relief_drivers(self) -> tuple[str | None, ...]:
        """Each relief style the drivers drive with, in turn (None alone: flat, no relief style)."""
        return self.relief_styles or (None,)


def parse_orders(text: str, classes: ClassTable | None = None) -> tuple[tuple[str, ...], ...]:
    """``all`` (every order of the feature classes, the lethal column last), ``random:N`` (N of
    them drawn at random, with :data:`RANDOM_ORDERS_SEED`) or ``a,b,c;d,e,f`` (the lethal column
    appended if missing); a ValueError for an empty item (``rock,,mud``, ``a,b;;c,d``)."""
    classes = classes or default_classes()
    last = (classes.lethal_column,) if classes.lethal else ()
    if text == "all":  # in the order of the table's profile
        return tuple((*p, *last) for p in itertools.permutations(c for c in classes.profile if c in classes.terrain_names))
    if text.startswith("random:"):
        n = _random_count(text, classes)
        return tuple((*order, *last) for order in _draw_orders(classes.terrain_names, n, np.random.default_rng(RANDOM_ORDERS_SEED)))
    orders = []
    for item in text.split(";"):
        names = tuple(n.strip() for n in item.split(","))
        if not all(names):
            raise ValueError(
                f"has an empty {'order' if not item.strip() else 'class'}: {text!r}; expected orders separated by ';', each of classes separated by ','"
            )
        orders.append(names if not last or last[0] in names else (*names, *last))
    return tuple(orders)


def count_orders(text: str, classes: ClassTable | None = None) -> int:
    """How many orders :func:`parse_orders` makes of ``text``, without drawing or listing them
    (``all`` of ten classes is 3,628,800); a ValueError for a bad ``random:N``."""
    classes = classes or default_classes()
    if text == "all":
        return math.factorial(len(classes.terrain_names))
    if text.startswith("random:"):
        return _random_count(text, classes)
    return len(text.split(";"))


def _random_count(text: str, classes: ClassTable) -> int:
    """The N of ``random:N``, checked: 1 to the number of orders of the table's feature classes."""
    try:
        n = int(text[len("random:") :])
    except ValueError:
        raise ValueError(f"random:N needs an integer N, got {text!r}") from None
    total = math.factorial(len(classes.terrain_names))
    if not 1 <= n <= total:
        raise ValueError(f"random:N needs 1 <= N <= {total} (the orders of {len(classes.terrain_names)} classes), got {n}")
    return n


class SelectionSize(NamedTuple):
    """How much a selection trains and drives, known before anything is drawn or run.

    Attributes:
        recipes, orders, seeds: the models are every recipe for every order and seed.
        courses: the generated layouts each model and driver drives.
        perceptions: the perception models every model drives them under, in turn.
        drivers: the distinct synthetic drivers driving them (one per order; per order and seed
            where the speeds are drawn for each; each of those per relief style).
        relief_styles: the relief styles each order and seed's driver drives with in turn (0:
            none, flat courses and layouts).
    """

    recipes: int
    orders: int
    seeds: int
    courses: int
    perceptions: int
    drivers: int
    relief_styles: int = 0

    @classmethod
    def of(cls, recipes: int, orders: int, seeds: int, courses: int, perceptions: int, random_speeds: bool) -> SelectionSize:
        return cls(recipes, orders, seeds, courses, perceptions, orders * seeds if random_speeds else orders)

    def with_relief(self, styles: int) -> SelectionSize:
        """The same selection with each driver driving with ``styles`` relief styles in turn (0: flat)."""
        return self._replace(drivers=self.drivers * max(styles, 1), relief_styles=styles)

    @property
    def models(self) -> int:
        return self.recipes * self.orders * self.seeds * max(self.relief_styles, 1)

    @property
    def runs(self) -> int:
        """Closed-loop runs: every model under every perception model, and every driver, on every layout."""
        return (self.models * self.perceptions + self.drivers) * self.courses

    @property
    def core_s(self) -> float:
        """The estimated time of it all on one core [s] (:data:`MODEL_CORE_S`, :data:`RUN_CORE_S`, or
        on relief :data:`RELIEF_MODEL_CORE_S`, :data:`RELIEF_RUN_CORE_S`)."""
        if self.relief_styles:
            return core_seconds((self.models, RELIEF_MODEL_CORE_S), (self.runs, RELIEF_RUN_CORE_S))
        return core_seconds((self.models, MODEL_CORE_S), (self.runs, RUN_CORE_S))

    @property
    def workload(self) -> Workload:
        """The models, the runs and their time, as every command of many models says them (terrapref.report.workload)."""
        named = ((self.recipes, "recipe"), (self.orders, "order"), (self.seeds, "seed"), (self.relief_styles, "relief style"))
        factors = " x ".join(count(n, what) for n, what in named if n or what != "relief style")
        return Workload(self.models, factors, self.runs, self.core_s, count(self.courses, "layout"))

    @property
    def large(self) -> bool:
        """Beyond the bound of terrapref.report.workload: run only when asked."""
        return self.workload.large

    def describe(self, workers: int | None) -> str:
        """One line: the models, the runs and about how long they take on ``workers`` cores
        (None: a cluster's, unknown here: one core's time alone)."""
        return self.workload.describe(workers)


def _draw_orders(names: tuple[str, ...], n: int, rng: np.random.Generator) -> list[tuple[str, ...]]:
    """``n`` distinct orders of ``names`` drawn at random: permutations drawn until ``n`` differ while
    that takes few draws (at most half of all orders wanted), else ``n`` ranks of all orders drawn
    without replacement and unranked, so that no ``n`` takes more than one draw per order."""
    total = math.factorial(len(names))
    if n <= total // 2:
        orders: dict[tuple[str, ...], None] = {}  # insertion-ordered, with constant-time membership
        while len(orders) < n:
            orders.setdefault(tuple(str(c) for c in rng.permutation(list(names))), None)
        return list(orders)
    return [_unrank(names, int(rank)) for rank in rng.choice(total, size=n, replace=False)]


def _unrank(names: tuple[str, ...], rank: int) -> tuple[str, ...]:
    """The ``rank``-th order of ``names`` (lexicographic by position, factorial number system)."""
    left, order = list(names), []
    for k in range(len(names) - 1, -1, -1):
        digit, rank = divmod(rank, math.factorial(k))
        order.append(left.pop(digit))
    return tuple(order)


@dataclass(frozen=True)
class _OrderJob:
    """Every recipe for one order and seed, trained one after another in one work folder: they share its demonstrations."""

    recipes: tuple[str, ...]
    order: tuple[str, ...]
    seed: int
    style: str
    workdir: str
    perception: PerceptionModel | None = None  # what the demonstrations recorded
    classes: ClassTable | None = None  # the class table of the course
    course: str | None = None  # the course demonstrated (None: each recipe's own)
    follow_up: bool = False  # and a follow-up course of what it left open
    speeds: tuple[tuple[str, float], ...] = ()  # the driver's cruising speeds by class (none: its style's)
    relief: str | None = None  # the driver's relief style, as record takes it (None: flat)


def relief_of(text: str | None) -> ReliefStyle | None:
    """The relief style ``text`` names (as ``record --relief-style`` takes it); None for None (flat) and ``none``."""
    return None if text is None else parse_relief_style(text)[1]


def job_speeds(sel: Selection, order_index: int, seed: int) -> tuple[tuple[str, float], ...]:
    """The driver's cruising speeds of one order and seed: drawn (``random``: the background in
    :data:`BACKGROUND_SPEEDS_MPS`, each feature class in :data:`FEATURE_SPEEDS_MPS`, to 0.05 m/s),
    as given, or none (the style's)."""
    if sel.speeds is None:
        return ()
    if sel.speeds != "random":
        from terrapref.demos.speed_style import parse_speeds

        return parse_speeds(sel.speeds)
    classes = sel.classes or default_classes()
    rng = np.random.default_rng([RANDOM_SPEEDS_SEED, order_index, seed])
    drawn = [(classes.background, rng.uniform(*BACKGROUND_SPEEDS_MPS))]
    drawn += [(name, rng.uniform(*FEATURE_SPEEDS_MPS)) for name in classes.terrain_names]
    return tuple((name, round(round(v / 0.05) * 0.05, 2)) for name, v in drawn)


@dataclass(frozen=True)
class _Model:
    """A trained model: its recipe, and the order-and-seed job that trained it."""

    recipe: str
    job: _OrderJob


def _train(job: _OrderJob) -> list[str]:
    """Every recipe for one order and seed, one after another: they share the work folder's demonstrations."""
    setup = RecipeSetup(
        job.seed,
        PreferenceProfile(job.order),
        job.course,
        style=job.style,
        perception=job.perception,
        classes=job.classes,
        follow_up=job.follow_up,
        speeds=job.speeds,
        relief=relief_of(job.relief),
    )
    return [str(run_recipe(recipe_named(r), job.workdir, setup).model) for r in job.recipes]


def job_folder(
    out: Path,
    order: Sequence[str],
    seed: int,
    taught_under: PerceptionModel | None = None,
    lethal: str | None = "non_traversable",
    relief: str | None = None,
) -> Path:
    """The work folder of one order and seed in a selection's ``out``: its demonstrations, and
    each recipe's model in ``<recipe>/model.safetensors`` (drives recorded under a perception
    model, or with a ``relief`` style, in a folder of their own). ``lethal``: the order's lethal
    column, left out of the name."""
    tail = f"_{perception_tag(taught_under)}" if taught_under is not None and taught_under.active else ""
    tail += f"_relief-{_folder_safe(relief, keep='-_.')}" if relief is not None else ""
    return out / "work" / f"{order_tag(order, lethal)}_s{seed}{tail}"


def _folder_safe(text: str, keep: str = "-_") -> str:
    """``text`` in a folder name: letters, digits and the characters of ``keep`` kept, the rest ``_``."""
    return "".join(ch if ch.isalnum() or ch in keep else "_" for ch in text)


def order_tag(order: Sequence[str], lethal: str | None = "non_traversable") -> str:
    """An order in a folder name: the first two letters of each class a driver chooses between
    (``mu_ro_wa``), or the whole names where two would share them; the lethal column left out."""
    chosen = _chosen(order, lethal)
    short = [c[:2] for c in chosen]
    return "_".join(short if len(set(short)) == len(short) else chosen)


def _chosen(order: Sequence[str], lethal: str | None = "non_traversable") -> Sequence[str]:
    """An order's classes a driver chooses between: the lethal column (last, worst for every
    driver) left out; the default table's ``non_traversable`` unless ``lethal`` names another."""
    return order[:-1] if order and order[-1] in (lethal, LETHAL_COLUMN) else order


def _lethal_of(sel: dict) -> str | None:
    """The lethal column of the class table select.json's selection names (the default table's when none)."""
    return _table_of(sel).lethal_column


def _table_of(sel: dict) -> ClassTable:
    """The class table select.json's selection names (the default table when none)."""
    return ClassTable.from_dict(sel["classes"], "select.json") if "classes" in sel else default_classes()


def perception_tag(model: PerceptionModel) -> str:
    """A short name of a perception model for folder names: a preset's name, else a file's stem."""
    name = Path(model.name).stem if model.name not in PRESETS else model.name
    return _folder_safe(name.replace(":", "-"))


def _describe(job: _OrderJob) -> str:
    relief = f", relief style {job.relief}" if job.relief is not None else ""
    return f"recipes {', '.join(job.recipes)}, order {'>'.join(job.order)}, seed {job.seed}{relief}"


def run_selection(out: str | Path, sel: Selection, engine: Engine | None = None, log: Callable[[str], None] = print) -> Path:
    """Train and drive everything; write SELECT.md, select.json (every zone) and select.png into ``out``."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    engine = engine or Engine()
    t0 = time.perf_counter()
    models = _train_all(out, sel, engine, log)
    t_train = time.perf_counter() - t0

    layouts = sel.layouts
    specs = [
        RunSpec(c, 0, PLANNER, path, m.job.order, perception=p, classes=sel.classes)
        for p in sel.driven_under
        for path, m in models.items()
        for c in layouts
    ]
    drivers = dict.fromkeys((tuple(m.job.order), m.job.speeds, m.job.relief) for m in models.values())  # each driver once
    specs += [
        RunSpec(c, 0, EXPERT, None, o, style=sel.style, classes=sel.classes, speeds=v, relief=relief_of(rs))
        for o, v, rs in drivers
        for c in layouts
    ]
    log(f"[2/2] closed-loop runs: {len(specs)} on {len(layouts)} layouts ...")
    results = run_many(specs, progress=every_tenth(log), engine=engine)
    t_eval = time.perf_counter() - t0 - t_train

    rows, runs = _zones_and_runs(specs, results, models)
    saved = {
        "selection": {
            "recipes": list(sel.recipes),
            "orders": [list(o) for o in sel.orders],
            "seeds": sel.seeds,
            "layouts": layouts,
            "style": sel.style,
            "perceptions": [p.to_dict() for p in sel.driven_under],
            "taught_under": (sel.taught_under or PerceptionModel()).to_dict(),
            **({"classes": sel.classes.to_dict()} if sel.classes is not None else {}),
            **({"course": sel.course} if sel.course is not None else {}),
            **({"follow_up": True} if sel.follow_up else {}),
            **({"speeds": sel.speeds} if sel.speeds is not None else {}),
            **({"relief_styles": list(sel.relief_styles)} if sel.relief_styles else {}),
        },
        "engine": engine.describe(),
        "zones": rows,
        "runs": runs,
        "train_s": round(t_train, 1),
        "eval_s": round(t_eval, 1),
    }
    write_text_atomic(out / "select.json", json.dumps(saved, indent=0))
    path = write_selection_report(out, saved)
    log(f"wrote {path}")
    return path


def _train_all(out: Path, sel: Selection, engine: Engine, log: Callable[[str], None]) -> dict[str, _Model]:
    """Every recipe for every order and seed; model file -> the model, in the order trained."""
    # One job per order and seed: its recipes share the demonstrations recorded in its work folder.
    jobs = [
        _OrderJob(
            tuple(sel.recipes),
            tuple(o),
            s,
            sel.style,
            str(job_folder(out, o, s, sel.taught_under, (sel.classes or default_classes()).lethal_column, rs)),
            sel.taught_under,
            sel.classes,
            sel.course,
            sel.follow_up,
            job_speeds(sel, i, s),
            rs,
        )
        for rs in sel.relief_drivers
        for i, o in enumerate(sel.orders)
        for s in range(sel.seeds)
    ]
    relief = f" x {len(sel.relief_styles)} relief styles" if sel.relief_styles else ""
    log(
        f"[1/2] demonstrations and training: {len(jobs) * len(sel.recipes)} models ({len(sel.recipes)} recipes x {len(sel.orders)} orders "
        f"x {sel.seeds} seeds{relief}) on {engine.describe()} ..."
    )
    trained = run_grid(_train, jobs, engine, lambda k, n: log(f"      trained {k}/{n} order-and-seed jobs"), describe=_describe)
    return {m: _Model(r, j) for j, ms in zip(jobs, trained, strict=True) for r, m in zip(j.recipes, ms, strict=True)}


def _zones_and_runs(specs: list[RunSpec], results: list[RunResult], models: dict[str, _Model]) -> tuple[list[dict], list[dict]]:
    """select.json's rows: every planner zone beside the same driver in the same zone (on relief,
    every relief zone too), and every planner run's collisions."""
    driver_runs = {_driver_key(s, r.scenario): r.metrics for s, r in zip(specs, results, strict=True) if r.driver == EXPERT}
    limits: dict[str, float | None] = {}  # by model file: its driver's lateral-acceleration limit
    rows, runs = [], []
    for spec, r in zip(specs, results, strict=True):
        if r.driver != PLANNER:
            continue
        model = models[spec.model_path]
        who = {
            "recipe": model.recipe,
            "order": list(model.job.order),
            "seed": model.job.seed,
            "scenario": r.scenario,
            "perception": spec.perceived_as,
            **({"relief_style": model.job.relief} if model.job.relief is not None else {}),
        }
        m, speeds = r.metrics, model.job.speeds
        dm = driver_runs[_driver_key(spec, r.scenario, model.job)]
        if spec.model_path not in limits:
            limits[spec.model_path] = driver_lateral_limit(model.job.style, speeds, Model.load(spec.model_path).rules)
        runs.append(
            {
                **who,
                "collisions": m.collisions,
                "tips": m.tips,
                "stuck": m.stuck,
                "ended": m.ending,
                "contact_s": m.contact_s,
                "driven_m": round(m.driven_m, 3),
                "stops": m.stop_count,
                "stops_s": m.stops_s,
                **run_fields(m, dm, limits[spec.model_path]),
                **({"speeds": [list(p) for p in speeds]} if speeds else {}),
            }
        )
        rows += _zone_rows(who, m, dm)
    return rows, runs


def _driver_key(spec: RunSpec, scenario: str, job: _OrderJob | None = None) -> tuple:
    """Which driver run a run is compared with: its order, speeds and relief style (a planner run's
    from the ``job`` that trained its model), and the layout."""
    if job is None:
        return tuple(spec.profile), spec.speeds, spec.relief, scenario
    return tuple(job.order), job.speeds, relief_of(job.relief), scenario


def _zone_rows(who: dict, mine: RunMetrics, theirs: RunMetrics) -> list[dict]:
    """A planner run's zone rows beside its driver's run of the same layout: each terrain zone, and
    on relief each relief zone (kind :data:`RELIEF_ZONE`; no success or speed of its own)."""
    driver = {z.id: z for z in theirs.zones}
    rows = []
    for z in mine.zones:
        d = driver[z.id]
        rows.append(
            {
                **who,
                "zone": z.id,
                "kind": zone_kind(z.label),
                "choice": z.choice,
                "driver_choice": d.choice,
                "agrees": zone_agrees(z, d) if d.choice != NOT_REACHED else None,  # the driver made no choice here
                "success": z.success,
                "driver_success": d.success,
                "speed_mps": z.speed_mps,
                "driver_speed_mps": d.speed_mps,
            }
        )
    agrees = relief_agreement(mine.relief_zones, theirs.relief_zones) or ()
    for i, (z, d, a) in enumerate(zip(mine.relief_zones or (), theirs.relief_zones or (), agrees, strict=False)):
        zone = {
            "zone": f"relief{i}",
            "kind": RELIEF_ZONE,
            "choice": z.choice,
            "driver_choice": d.choice,
            "agrees": a if d.choice != NOT_REACHED else None,
        }
        rows.append({**who, **zone, "success": None, "driver_success": None, "from_m": z.from_m, "to_m": z.to_m})
    return rows


def _rate(rows: Sequence[dict], key: str) -> str:
    """The rate of ``key`` over the rows that have it (a relief zone has no success of its own)."""
    rows = [r for r in rows if r.get(key) is not None]
    return rate_text(sum(r[key] for r in rows), len(rows))


def _completion(runs: Sequence[dict]) -> str:
    """Runs completed and stops per 100 m driven, two cells (``-`` for a select.json written before they were kept)."""
    if not runs or "completed" not in runs[0]:
        return "- | -"
    driven = sum(r["driven_m"] for r in runs)
    per = f"{100 * sum(r['stops'] for r in runs) / driven:.2f}" if driven > 0 else "-"
    return f"{rate_text(sum(r['completed'] for r in runs), len(runs))} | {per}"


def layout_interval(rows: Sequence[dict]) -> tuple[float, float, float]:
    """Agreement of ``rows`` and its 95% interval resampling whole layouts (a cluster bootstrap).

    A layout's zones are alike across training seeds (the same patch geometry makes the same
    near-tie for every model), so the zones are not independent draws; resampling layouts
    gives the spread a new set of layouts would show, which the Wilson interval over zones
    understates.
    """
    by_layout: dict[str, list[bool]] = {}
    for r in rows:
        if r["agrees"] is not None:  # a zone the driver did not reach is not compared
            by_layout.setdefault(r["scenario"], []).append(r["agrees"])
    return cluster_bootstrap(list(by_layout.values()))


def _drives(sel: dict) -> str:
    """What each model was taught from, in a few words."""
    return "one drive and, where it left pairs open, its follow-up" if sel.get("follow_up") else "one drive"


def _perception_line(model: dict | None) -> str:
    """A perception model as select.json holds it, in a few words."""
    if not model or model.get("name", "clean") == "clean":
        return "the truth (clean)"
    return f"{model['name']}"


def write_selection_report(out: Path, saved: dict) -> Path:
    """SELECT.md and select.png from select.json's content."""
    sel, rows, runs = saved["selection"], saved["zones"], saved["runs"]
    layouts = sel["layouts"]
    seen = [p["name"] for p in sel.get("perceptions", [{"name": "clean"}])]
    lines = _selection_preamble(sel, seen)
    points: list[RateRow] = []
    targets: list[float] = []
    styles = sel.get("relief_styles") or [None]
    for name, style in itertools.product(seen, styles):
        part = [r for r in rows if r.get("perception", "clean") == name and r.get("relief_style") == style]
        part_runs = [r for r in runs if r.get("perception", "clean") == name and r.get("relief_style") == style]
        heading = ", ".join(x for x in (f"perception `{name}`" if len(seen) > 1 else "", f"relief style `{style}`" if style else "") if x)
        if heading:
            lines += [f"## {heading[0].upper()}{heading[1:]}", ""]
        # Several perception models or relief styles: a bar per recipe and each in the figure (the orders are in the tables).
        table, bars = _selection_table(sel, part, part_runs, order_bars=len(seen) == 1 and len(styles) == 1)
        lines += table + [""]
        if sel.get("speeds") is not None or style is not None:
            lines += speed_section(part, part_runs, _table_of(sel).background) + [""]
        if style is not None:  # on relief, each recipe's terrain zones and relief zones apart: each has its target
            bars = _relief_bars(sel["recipes"], part)
        for label, rate, interval in bars:
            tail = ", ".join(x for x in (name if len(seen) > 1 else "", f"relief {style}" if len(styles) > 1 else "") if x)
            points.append(RateRow(f"{label}, {tail}" if tail else label, rate, interval))
            targets.append(TARGET if name == "clean" else PERCEIVED_TARGET)
    lines += [
        f"Training {saved['train_s']:.0f} s, runs {saved['eval_s']:.0f} s (wall; {saved['engine']}).",
        "",
        "![selection](select.png)",
        "",
    ]
    save_intervals(
        out / "select.png",
        points,
        "agreement with the driver",
        target=targets or TARGET,
        title=f"{_drives(sel)} per model, {len(layouts)} layouts x {sel['seeds']} seeds; 95% intervals, layouts resampled",
    )
    path = out / "SELECT.md"
    write_text_atomic(path, "\n".join(lines))
    return path


def _selection_preamble(sel: dict, seen: list[str]) -> list[str]:
    """SELECT.md's title and what was run: the recipes, orders, seeds and layouts, the
    perception models (``seen``), the class table and the course."""
    layouts = sel["layouts"]
    lines = [
        "# Recipe selection: agreement with the driver on generated layouts",
        "",
        f"{len(sel['recipes'])} recipe(s) x {len(sel['orders'])} order(s) x {sel['seeds']} training seed(s), {_drives(sel)} each; every model and "
        f"its driver (style {sel['style']}) drive {len(layouts)} generated layouts ({layouts[0]} to {layouts[-1]}). Rates with 95% Wilson "
        "intervals over all zones; the layouts column resamples whole layouts instead (a cluster bootstrap: a layout's zones are "
        "alike across seeds), the spread another set of layouts would show.",
        "",
        *_relief_preamble(sel),
        f"The demonstrations recorded: {_perception_line(sel.get('taught_under'))}. The models drive the layouts receiving "
        + ", then ".join(f"`{name}`" for name in seen)
        + " (terrapref.perception); the driver always sees the truth.",
        "",
    ]
    lethal = _lethal_of(sel)
    if "classes" in sel:
        table = sel["classes"]
        lines += [
            f"Class table: background {table['background']}; feature classes "
            f"{', '.join(c['name'] for c in table['classes'] if c['name'] != table['background'] and c['name'] not in table['lethal'])}; "
            f"lethal {', '.join(table['lethal']) or 'none'}. Orders: "
            + "; ".join(" > ".join(_chosen(o, lethal)) for o in sel["orders"])
            + ".",
            "",
        ]
    if "course" in sel or sel.get("follow_up"):
        course = f"`{Path(sel['course']).name}`" if "course" in sel else "its own course"
        lines += [
            f"Every recipe demonstrated {course}"
            f"{', then, where its drive left pairs open, a follow-up course of them, beside their neighbours (or the ladder of the order it learned)' if sel.get('follow_up') else ''}.",
            "",
        ]
    return lines


def _relief_bars(recipes: Sequence[str], rows: list[dict]) -> list[tuple[str, float, tuple[float, float]]]:
    """The figure's bars on relief: each recipe's agreement over all orders on its terrain zones and
    on its relief zones apart, with their intervals resampling layouts (a kind no zone of is left out)."""
    bars = []
    for recipe, relief in itertools.product(recipes, (False, True)):
        sub = [r for r in rows if r["recipe"] == recipe and (r["kind"] == RELIEF_ZONE) == relief]
        if sub:
            rate, lo, hi = layout_interval(sub)
            bars.append((f"{recipe}, all orders, {'relief' if relief else 'terrain'} zones", rate, (lo, hi)))
    return bars


def _relief_preamble(sel: dict) -> list[str]:
    """SELECT.md's words on relief: the drivers' relief styles and what a relief zone is (none on flat layouts)."""
    styles = sel.get("relief_styles")
    if not styles:
        return []
    return [
        f"Relief: every order and seed's driver drives with each relief style in turn ({', '.join(f'`{s}`' for s in styles)}), "
        "on the relief teaching course and on the layouts with relief. Relief zones are the stretches of the path that tilt "
        "the body past 4 deg (at least 1 m long); the planner agrees in one when it goes over it, or round it on the same side, as "
        "its driver did; they have no zone success or speed of their own (the speed by grade band below compares whole runs).",
        "",
    ]


def speed_section(rows: Sequence[dict], runs: Sequence[dict], background: str) -> list[str]:
    """The planner's speed against its own driver's (terrapref.evaluation.speed), a line each (the
    zones passed by counted for the ``background`` class)."""
    compared = SpeedComparison.of(rows, runs, background)
    lines = [
        "Speed against the driver (each order and seed's model against its own driver): per class the driver took, the mean "
        "absolute error of the mean speed through a zone over the zones where the planner took it too; 95% intervals "
        "resampling layouts.",
        "",
    ]
    return lines + [f"- {line}" for line in compared.lines()]


def _selection_table(
    sel: dict, rows: list[dict], runs: list[dict], order_bars: bool = True
) -> tuple[list[str], list[tuple[str, float, tuple[float, float]]]]:
    """One perception's table (per recipe and order, then all orders) and its disagreements; and the
    bars of the figure: (label, agreement, its interval resampling layouts), each recipe's over all
    orders, and with ``order_bars`` each order's too when there is one recipe."""
    kinds = sorted({r["kind"] for r in rows})
    every = " (terrain and relief zones)" if RELIEF_ZONE in kinds else ""  # each kind has its own column after them
    lines = [
        f"| recipe | order | agreement with the driver{every} | agreement, layouts resampled | "
        + " | ".join(f"agreement, {k} zones" for k in kinds)
        + " | zone success | the driver's zone success | collisions | runs completed | stops per 100 m | per seed |",
        "|---|---|---|---|" + "---|" * len(kinds) + "---|---|---|---|---|---|",
    ]
    bars = []
    for recipe in sel["recipes"]:
        for order in [*sel["orders"], None]:
            sub = [r for r in rows if r["recipe"] == recipe and (order is None or r["order"] == order)]
            if not sub:
                continue
            its = [r for r in runs if r["recipe"] == recipe and (order is None or r["order"] == order)]
            coll = str(sum(r["collisions"] for r in its))
            tips, stuck = sum(r.get("tips", 0) for r in its), sum(r.get("stuck", 0) for r in its)
            coll += f" (and {tips} tips, {stuck} stuck)" if tips or stuck else ""
            completed = _completion(its)
            per_seed = {}
            for r in sub:  # every seed in its place, "-" where no zone of it was compared
                per_seed.setdefault(r["seed"], [])
                if r["agrees"] is not None:
                    per_seed[r["seed"]].append(r["agrees"])
            seeds = ", ".join(f"{sum(v) / len(v):.0%}" if v else "-" for v in per_seed.values()) if order is not None else "-"
            name = "**all**" if order is None else " > ".join(order)
            rate, lo, hi = layout_interval(sub)
            lines.append(
                f"| {recipe} | {name} | {_rate(sub, 'agrees')} | {rate:.1%} (95% CI {lo:.1%}-{hi:.1%}) | "
                + " | ".join(_rate([r for r in sub if r["kind"] == k], "agrees") for k in kinds)
                + f" | {_rate(sub, 'success')} | {_rate(sub, 'driver_success')} | {coll} | {completed} | {seeds} |"
            )
            if order is None or (order_bars and len(sel["recipes"]) == 1):
                bars.append((f"{recipe}, all orders" if order is None else " > ".join(_chosen(order, _lethal_of(sel))), rate, (lo, hi)))
    misses: dict[tuple, int] = {}
    for r in rows:
        if r["agrees"] is False:
            key = (r["recipe"], r["kind"], r["choice"], r["driver_choice"])
            misses[key] = misses.get(key, 0) + 1
    if misses:
        lines += [
            "",
            "Disagreements (recipe, zone kind: planner's choice / driver's choice, count): "
            + "; ".join(f"{rc}, {k}: {p} / {d}, {n}" for (rc, k, p, d), n in sorted(misses.items(), key=lambda kv: -kv[1])),
        ]
    return lines, bars
