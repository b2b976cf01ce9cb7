"""STUDY.md and its figures, from the study's runs (terrapref.report.study)."""

from __future__ import annotations

import math
import time
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from terrapref.evaluation.runner import EXPERT, HAND_COST, PURE_PURSUIT, zone_agrees
from terrapref.evaluation.scoring import RunMetrics
from terrapref.evaluation.stats import cluster_bootstrap, rate_text, wilson
from terrapref.fileio import write_text_atomic
from terrapref.report.study_plan import DEMONSTRATIONS, StudyPlan, TrainedModel, course_name

TARGET = 0.9  # the success level the data-efficiency question asks about
ALL = "all"  # the data-efficiency point that uses every demonstrated minute: the baselines' runs
METHOD_NAMES = {
    "C": "C (ours)",
    "linear": "linear utility (learned)",
    "cnn": "end-to-end CNN",
    HAND_COST: "hand-tuned cost",
    PURE_PURSUIT: "pure pursuit",
    EXPERT: "synthetic driver",
}
BASELINES = ("C", "linear", "cnn", HAND_COST, PURE_PURSUIT, EXPERT)  # the rows of section 1, in order
CURVES = ("C", "linear", "cnn")  # the methods of the data-efficiency curve


@dataclass(frozen=True)
class ModelVariant:
    """What a trained model learned from: the first ``minutes`` of its demonstrations (None: all
    of them), as the ablation ``variant`` (None: recipe ours)."""

    minutes: float | None = None
    variant: str | None = None


@dataclass(frozen=True)
class RunTag:
    """Where a run belongs in the study; fields that do not apply to it are None and not written."""

    study: str  # baselines, efficiency, profile, profile_cross, robustness, ablation or teach
    method: str  # C, linear, cnn, a driver without a model, or C_default (the default profile's C, scored under the other)
    seed: int  # the training seed; for drivers without a model, the evaluation seed
    model: ModelVariant | None = None  # a trained model's own run, scored under the profile it learned
    scored_under: str | None = (
        None  # the profile its zones resolve under: "own" (the one its model learned or its driver drove by), "default" or "alt"
    )
    kind: str | None = None  # robustness: the perception preset, or the part swept and its level (x the preset's)
    level: float | None = None
    order: tuple[str, ...] | None = None  # teaching: the preference order and style of the driver
    style: str | None = None

    @property
    def minutes(self) -> float | None:
        return self.model.minutes if self.model is not None else None

    @property
    def variant(self) -> str | None:
        return self.model.variant if self.model is not None else None

    def to_dict(self) -> dict:
        """As study.json holds it: a trained model's own run names its minutes and variant even when None."""
        tag: dict = {"study": self.study, "method": self.method, "seed": self.seed}
        if self.model is not None:
            tag |= {"minutes": self.model.minutes, "variant": self.model.variant}
        rest = {
            "scored_under": self.scored_under,
            "kind": self.kind,
            "level": self.level,
            "order": list(self.order) if self.order is not None else None,
            "style": self.style,
        }
        return tag | {k: v for k, v in rest.items() if v is not None}

    @classmethod
    def from_dict(cls, data: dict) -> RunTag:
        """A tag as :meth:`to_dict` wrote it."""
        model = ModelVariant(data["minutes"], data["variant"]) if "minutes" in data else None
        order = tuple(data["order"]) if data.get("order") is not None else None
        return cls(
            data["study"],
            data["method"],
            data["seed"],
            model,
            data.get("scored_under"),
            data.get("kind"),
            data.get("level"),
            order,
            data.get("style"),
        )


@dataclass(frozen=True)
class StudyRun:
    """One closed-loop run of the study: where it belongs, the course driven and its scores."""

    tag: RunTag
    scenario: str
    metrics: RunMetrics

    def to_dict(self) -> dict:
        """As study.json holds it: the tag's fields, the course and the metrics."""
        return {**self.tag.to_dict(), "scenario": self.scenario, "metrics": self.metrics.to_dict()}

    @classmethod
    def from_dict(cls, data: dict) -> StudyRun:
        """A run as study.json holds it."""
        return cls(RunTag.from_dict(data), data["scenario"], RunMetrics.from_dict(data["metrics"]))


def _rate(runs: list[StudyRun]) -> float:
    zones = [z.success for r in runs for z in r.metrics.zones]
    return float(np.mean(zones)) if zones else float("nan")


def _per_seed(runs: list[StudyRun]) -> list[float]:
    by: dict[int, list[StudyRun]] = defaultdict(list)
    for r in runs:
        by[r.tag.seed].append(r)
    return [_rate(v) for _, v in sorted(by.items())]


def _cell(runs: list[StudyRun]) -> tuple[str, float, float]:
    """'mean ± std [lo-hi]': the mean and std of the per-seed zone success, and the 95% Wilson
    interval of the success rate pooled over every zone of the runs."""
    rates = _per_seed(runs)
    if not rates:
        return "—", float("nan"), float("nan")
    m, s = float(np.mean(rates)), float(np.std(rates))
    zones = [z.success for r in runs for z in r.metrics.zones]
    lo, hi = wilson(int(sum(zones)), len(zones))
    return (f"{m:.1%} ± {s:.1%}" if len(rates) > 1 else f"{m:.1%}") + f" [{lo:.0%}-{hi:.0%}]", m, s


def _collisions(runs: list[StudyRun]) -> int:
    return int(sum(r.metrics.collisions for r in runs))


def _completed(runs: list[StudyRun]) -> float:
    """Share of the runs that reached the goal (NaN for none)."""
    return float(np.mean([r.metrics.completed for r in runs])) if runs else float("nan")


def _select(runs: list[StudyRun], **keys) -> list[StudyRun]:
    """The runs whose tag has every one of ``keys`` (a field of :class:`RunTag`) at the value given."""
    return [r for r in runs if all(getattr(r.tag, k) == v for k, v in keys.items())]


@dataclass(frozen=True)
class _Baselines:
    """Section 1's runs by method, and each method's cell (text, mean, std over seeds)."""

    runs: dict[str, list[StudyRun]]
    cells: dict[str, tuple[str, float, float]]

    @classmethod
    def of(cls, runs: list[StudyRun]) -> _Baselines:
        base = {m: _select(runs, study="baselines", method=m) for m in BASELINES}
        return cls(base, {m: _cell(base[m]) for m in BASELINES})


@dataclass(frozen=True)
class _Efficiency:
    """Section 2's curves: per learned method, (minutes, mean, std) at each budget shorter than the
    demonstrations (a longer one is all of them), the last all of it."""

    full_minutes: float  # all of a seed's demonstrations [min]
    points: tuple[float | str, ...]  # the budgets [min], then ALL
    curves: dict[str, list[tuple[float, float, float]]]

    @classmethod
    def of(cls, plan: StudyPlan, trained: Sequence[TrainedModel], runs: list[StudyRun], base: _Baselines) -> _Efficiency:
        full_minutes = _demo_minutes(trained)
        points = (*(m for m in plan.minutes if not m >= full_minutes), ALL)
        curves = {
            m: [
                (full_minutes, *base.cells[m][1:])
                if mins == ALL
                else (mins, *_cell(_select(runs, study="efficiency", method=m, minutes=mins))[1:])
                for mins in points
            ]
            for m in CURVES
        }
        return cls(full_minutes, points, curves)

    def minutes_to_target(self, method: str) -> str:
        """The first budget at which ``method`` reaches TARGET, or the best it did with all of it."""
        reach = next((mins for mins, mean, _ in self.curves[method] if mean >= TARGET), None)
        if reach is not None:
            return f"{reach:.3g} min"
        return f"not reached with all {self.full_minutes:.1f} min (best {max(e[1] for e in self.curves[method]):.0%})"


@dataclass(frozen=True)
class _Profiles:
    """Section 3's runs: C trained on the other profile and that profile's driver (both scored
    under it), and each profile's C scored under the other profile."""

    alt: list[StudyRun]
    alt_driver: list[StudyRun]
    alt_as_default: list[StudyRun]
    default_as_alt: list[StudyRun]

    @classmethod
    def of(cls, runs: list[StudyRun]) -> _Profiles:
        return cls(
            _select(runs, study="profile", method="C"),
            _select(runs, study="profile", method=EXPERT),
            _select(runs, study="profile_cross", method="C"),
            _select(runs, study="profile_cross", method="C_default"),
        )


def write_study(
    out: Path,
    plan: StudyPlan,
    trained: Sequence[TrainedModel],
    runs: list[StudyRun],
    timings: dict[str, float],
    report_started: float | None = None,
) -> Path:
    """Write STUDY.md and the figures; ``report_started`` (perf_counter) times this step in the table."""
    figs = out / "figures"
    figs.mkdir(exist_ok=True)
    base = _Baselines.of(runs)
    efficiency = _Efficiency.of(plan, trained, runs, base)
    lines = _introduction(plan, runs)
    lines += _answers(plan, runs, base, efficiency)
    lines += _baselines_section(plan, base, figs)
    lines += _efficiency_section(trained, runs, base, efficiency, figs)
    lines += _profile_section(plan, runs)
    lines += _robustness_section(plan, runs, figs)
    lines += _ablation_section(runs, base)
    lines += teaching_section(plan, runs, figs)
    if report_started is not None:
        timings = {**timings, "tables and figures": time.perf_counter() - report_started}
    lines += ["", "## Time per step (wall clock)", "", "| step | seconds |", "|---|---|"]
    lines += [f"| {k} | {v:.1f} |" for k, v in timings.items()] + [f"| total | {sum(timings.values()):.1f} |", ""]
    return write_text_atomic(out / "STUDY.md", "\n".join(lines))


def _introduction(plan: StudyPlan, runs: list[StudyRun]) -> list[str]:
    """The title and what every number rests on."""
    zones_per_pass = sum(len(r.metrics.zones) for r in _select(runs, study="baselines", method=EXPERT, seed=0))
    table = (
        (
            f"The class table: background {plan.table.background}; terrain columns {', '.join(plan.table.terrain_names)}"
            + (f"; lethal {', '.join(plan.table.lethal)}" if plan.table.lethal else "")
            + ". "
        )
        if plan.classes is not None
        else ""
    )
    return [
        "# terrapref study: baselines, data efficiency, preference profiles, robustness, ablations",
        "",
        f"{table}Every number comes from closed-loop runs in the simulator on {', '.join(plan.scenarios())} "
        f"({zones_per_pass} zones per pass), "
        f"{plan.seeds} training seed(s): each seed has its own demonstrations ({DEMONSTRATIONS.demonstrations} runs of "
        f"{course_name(plan.demo_course())} with disturbances) and its own initialisation. Zone success is given as the mean over seeds ± its standard deviation; "
        "collisions are summed over all runs; brackets give the 95% Wilson interval of the rate pooled over all zones. One zone is "
        f"{1 / max(zones_per_pass, 1):.1%} of a seed's score, so differences of a few points are within the spread between seeds.",
        "",
    ]


def _answers(plan: StudyPlan, runs: list[StudyRun], base: _Baselines, efficiency: _Efficiency) -> list[str]:
    """The study's questions, each answered in one bullet."""
    cells = base.cells
    lines = ["## Answers", ""]
    lines.append(
        f"- **Minutes of demonstration to reach {TARGET:.0%} zone success:** C {efficiency.minutes_to_target('C')}; "
        f"linear utility {efficiency.minutes_to_target('linear')}; end-to-end CNN {efficiency.minutes_to_target('cnn')}."
    )
    lines.append(
        f"- **Learned planner against hand-tuned and linear:** C {cells['C'][0]}, hand-tuned cost {cells[HAND_COST][0]} "
        f"({(cells['C'][1] - cells[HAND_COST][1]) * 100:+.1f} points), learned linear utility {cells['linear'][0]} "
        f"({(cells['C'][1] - cells['linear'][1]) * 100:+.1f} points); the end-to-end CNN {cells['cnn'][0]} "
        f"({(cells['C'][1] - cells['cnn'][1]) * 100:+.1f} points)."
    )
    lines.append(_profile_answer(plan, runs))
    lines.append(_Robustness.of(plan, runs).answer())
    lines.append("")
    return lines


def _profile_answer(plan: StudyPlan, runs: list[StudyRun]) -> str:
    """Whether the other profile is learned: overall, and in the zones where the profiles disagree."""
    if plan.alt is None:
        return f"- **Another profile:** none; the table has one class besides {plan.table.lethal_column or 'the background'}."
    profiles = _Profiles.of(runs)
    keep = disagreement_zones(runs)
    a_ok, a_n = _zone_success(profiles.alt, keep)
    d_ok, d_n = _zone_success(profiles.default_as_alt, keep)
    return (
        f"- **Another profile ({' > '.join(plan.alt)}) is learned:** C trained on demonstrations driven under it reaches "
        f"{_cell(profiles.alt)[0]} scored under that profile (the driver: {_cell(profiles.alt_driver)[0]}). In the {len(keep)} test zones where the two "
        f"profiles expect different choices, it makes the other profile's choice in {a_ok}/{a_n} runs; the model trained "
        f"on the default profile does so in {d_ok}/{d_n}. (All zones: the other-profile model scored under the default "
        f"profile {_cell(profiles.alt_as_default)[0]}, the default model under the other profile {_cell(profiles.default_as_alt)[0]}.)"
    )


def _baselines_section(plan: StudyPlan, base: _Baselines, figs: Path) -> list[str]:
    """Section 1: every method under the same planner interface, and its bar chart."""
    from terrapref.planner.policy import HAND_DISTANCE_WEIGHT, hand_costs
    from terrapref.plots import save_bars

    lines = [
        "## 1. Baselines",
        "",
        "Each is a driver under the same planner interface, scored by the same code.",
        "",
        "| method | zone success | collisions | completed |",
        "|---|---|---|---|",
    ]
    for m in BASELINES:
        lines.append(f"| {METHOD_NAMES[m]} | {base.cells[m][0]} | {_collisions(base.runs[m])} | {_completed(base.runs[m]):.0%} |")
    lines += [
        "",
        f"Hand-tuned costs per unit share: {', '.join(f'{k} {v:g}' for k, v in hand_costs(plan.table).items())}; distance utility weight "
        f"{HAND_DISTANCE_WEIGHT:g}. Pure pursuit: 2.5 m look-ahead, nearest trajectory. For the deterministic baselines, "
        "'seeds' are the evaluation seeds (start offset and heading).",
        "",
        "![baselines](figures/baselines.png)",
        "",
    ]
    save_bars(
        figs / "baselines.png",
        [METHOD_NAMES[m] for m in BASELINES],
        [base.cells[m][1] for m in BASELINES],
        [base.cells[m][2] for m in BASELINES],
        "zone success, " + ("test_course and variations" if not plan.courses else ", ".join(plan.scenarios())),
        target=TARGET,
    )
    return lines


def _efficiency_section(
    trained: Sequence[TrainedModel], runs: list[StudyRun], base: _Baselines, efficiency: _Efficiency, figs: Path
) -> list[str]:
    """Section 2: success against minutes of demonstration, as a table and curves."""
    from terrapref.plots import save_curves

    lines = [
        "## 2. Data efficiency",
        "",
        "The first N minutes of the same demonstrations.",
        "",
        "| minutes | " + " | ".join(METHOD_NAMES[m] for m in CURVES) + " |",
        "|---|" + "---|" * len(CURVES),
    ]
    for mins in efficiency.points:
        study = "baselines" if mins == ALL else "efficiency"
        samples = next(
            (
                t.samples
                for t in trained
                if t.job.study == study and t.job.minutes == (None if mins == ALL else mins) and t.job.method == "C"
            ),
            0,
        )
        label = f"all, {efficiency.full_minutes:.1f}" if mins == ALL else f"{mins:g}"
        texts = [_cell(base.runs[m] if mins == ALL else _select(runs, study="efficiency", method=m, minutes=mins))[0] for m in CURVES]
        lines.append(f"| {label} ({samples} frames) | " + " | ".join(texts) + " |")
    lines += ["", "![data efficiency](figures/data_efficiency.png)", ""]
    save_curves(
        figs / "data_efficiency.png",
        {METHOD_NAMES[m]: list(efficiency.curves[m]) for m in CURVES},
        "minutes of demonstration",
        "zone success",
        target=TARGET,
        logx=True,
    )
    return lines


def _profile_section(plan: StudyPlan, runs: list[StudyRun]) -> list[str]:
    """Section 3: the other profile, learned and scored both ways; the choices; the zones where the profiles disagree."""
    if plan.alt is None:
        return ["## 3. Another preference profile", "", _profile_answer(plan, runs)[2:], ""]
    p = _Profiles.of(runs)
    lines = [
        "## 3. Another preference profile",
        "",
        f"Demonstrations driven under {' > '.join(plan.alt)} (the default is {' > '.join(plan.default_order())}); "
        "`best` zones resolve under the profile the model carries.",
        "",
        "| model | scored under | zone success | collisions |",
        "|---|---|---|---|",
        f"| C trained on the other profile | its own | {_cell(p.alt)[0]} | {_collisions(p.alt)} |",
        f"| synthetic driver, other profile | its own | {_cell(p.alt_driver)[0]} | {_collisions(p.alt_driver)} |",
        f"| C trained on the other profile | default | {_cell(p.alt_as_default)[0]} | — |",
        f"| C trained on the default profile | other | {_cell(p.default_as_alt)[0]} | — |",
        "",
    ]
    return lines + _choice_table(plan, runs) + _disagreement_table(runs)


def _robustness_section(plan: StudyPlan, runs: list[StudyRun], figs: Path) -> list[str]:
    """Section 4: the default style's taught models under each perception preset, and each part of
    the sweep's base preset alone at rising levels; tables, and agreement against level per part."""
    from terrapref.plots import save_curves

    rob = _Robustness.of(plan, runs)
    lines = [
        "## 4. Robustness: what a real robot sees",
        "",
        f"The models of section 6 taught by the default-style driver of every order ({rob.models} models), driving the same "
        f"{len(plan.layouts)} layouts while they receive what a robot would instead of the truth (terrapref.perception; presets in "
        "docs/perception.md). The driver always sees the truth. "
        + (
            f"Then each part of `{plan.sweep_name()}` alone, at rising multiples of it, until agreement with the driver falls below 90%. "
            if plan.sweep_base is not None
            else "No perception model of this table was given (`--perception`): no sweep. "
        )
        + "Rates with 95% Wilson intervals over zones.",
        "",
        "| perception | agreement with the driver | zone success | collisions |",
        "|---|---|---|---|",
    ]
    for name, rr in rob.presets.items():
        ok, n = agreement(rr, rob.driver)
        lines.append(f"| {name} | {rate_text(ok, n)} | {_cell(rr)[0]} | {_collisions(rr)} |")
    if plan.sweep_base is None:
        return lines + [""]
    lines += ["", f"| part of `{plan.sweep_name()}` alone | x level | agreement with the driver | collisions |", "|---|---|---|---|"]
    curves = {}
    for part, levels in rob.sweep.items():
        pts = []
        for level, rr in levels.items():
            ok, n = agreement(rr, rob.driver)
            pts.append((level, ok / n if n else float("nan"), 0.0))
            lines.append(f"| {part} | {level:g} | {rate_text(ok, n)} | {_collisions(rr)} |")
        curves[part] = pts
    lines += ["", "![robustness](figures/robustness.png)", ""]
    save_curves(
        figs / "robustness.png", curves, f"level (multiples of {plan.sweep_name()}'s)", "agreement with the driver", target=0.9, logx=True
    )
    return lines


@dataclass(frozen=True)
class _Robustness:
    """Section 4's runs: per preset the default style's taught models (clean: the teaching runs), per
    part of the sweep and level its runs, the driver runs they are compared with, and how many models."""

    presets: dict[str, list[StudyRun]]
    sweep: dict[str, dict[float, list[StudyRun]]]
    driver: list[StudyRun]
    models: int

    @classmethod
    def of(cls, plan: StudyPlan, runs: list[StudyRun]) -> _Robustness:
        clean = _select(runs, study="teach", method="C", style="default")
        presets = {
            m.name: clean if not m.active else _select(runs, study="robustness", kind=m.name, level=None) for m in plan.perceptions()
        }
        sweep: dict[str, dict[float, list[StudyRun]]] = {}
        for r in runs:
            if r.tag.study == "robustness" and r.tag.level is not None:
                sweep.setdefault(r.tag.kind, {}).setdefault(r.tag.level, []).append(r)
        sweep = {part: dict(sorted(levels.items())) for part, levels in sweep.items()}
        models = len({(r.tag.order, r.tag.seed) for r in clean})
        return cls(presets, sweep, _select(runs, study="teach", method=EXPERT, style="default"), models)

    def answer(self) -> str:
        """One bullet: agreement under each preset, and how far each part holds 90%."""
        presets = ", ".join(
            f"{name} {rate_text(*agreement(rr, self.driver))} ({_collisions(rr)} collisions)" for name, rr in self.presets.items()
        )
        holds = []
        for part, levels in self.sweep.items():
            kept = [lv for lv, rr in levels.items() if _ratio(agreement(rr, self.driver)) >= 0.9]
            below = [lv for lv in levels if lv not in kept]
            holds.append(
                f"{part} {'to x' + format(max(kept), 'g') if kept else 'not at x' + format(min(levels), 'g')}"
                + (f", below at x{min(below):g}" if below else "")
            )
        held = (" 90% holds for " + "; ".join(holds) + ".") if holds else " No part was swept."
        return f"- **Under what a robot sees** (agreement with the driver): {presets}.{held}"


def _ratio(counts: tuple[int, int]) -> float:
    ok, n = counts
    return ok / n if n else float("nan")


def _ablation_section(runs: list[StudyRun], base: _Baselines) -> list[str]:
    """Section 5: C with one part taken away or changed at a time."""
    lines = [
        "## 5. Ablations",
        "",
        "| variant | zone success | collisions |",
        "|---|---|---|",
        f"| C (ours: compression, distance utility, n = 30, width 64) | {base.cells['C'][0]} | {_collisions(base.runs['C'])} |",
    ]
    variants = sorted({r.tag.variant for r in runs if r.tag.study == "ablation"}, key=str)
    for v in variants:
        rr = _select(runs, study="ablation", variant=v)
        lines.append(f"| {v} | {_cell(rr)[0]} | {_collisions(rr)} |")
    return lines + [""]


def agreement(planner: list[StudyRun], driver: list[StudyRun]) -> tuple[int, int]:
    """Zones (agreeing, compared) where the planner's runs made the choice of the driver's run of the
    same preference order on the same layout (those it reached: where it did not, it made no choice)."""
    by = {(r.tag.order, r.scenario, z.id): z for r in driver for z in r.metrics.zones if z.reached}
    pairs = [(z, by[(r.tag.order, r.scenario, z.id)]) for r in planner for z in r.metrics.zones if (r.tag.order, r.scenario, z.id) in by]
    return sum(zone_agrees(p, d) for p, d in pairs), len(pairs)


def _clearance_gap(planner: list[StudyRun], driver: list[StudyRun]) -> float:
    """Mean |planner's zone clearance - the driver's| over zones where both came near terrain they did not choose [m]."""
    by = {(r.scenario, z.id): z.clearance_m for r in driver for z in r.metrics.zones}
    gaps = [
        abs(z.clearance_m - by[(r.scenario, z.id)])
        for r in planner
        for z in r.metrics.zones
        if z.clearance_m is not None and by.get((r.scenario, z.id)) is not None
    ]
    return float(np.mean(gaps)) if gaps else float("nan")


def _mean_cross_track(runs: list[StudyRun]) -> float:
    """Mean over the runs of their RMS cross-track error [m]."""
    values = [r.metrics.rms_cross_track_m for r in runs]
    return float(np.mean(values)) if values else float("nan")


def _mean_clearance(runs: list[StudyRun]) -> float:
    values = [z.clearance_m for r in runs for z in r.metrics.zones if z.clearance_m is not None]
    return float(np.mean(values)) if values else float("nan")


def _taught(taught: list[StudyRun], method: str, order: Sequence[str], style: str | None) -> list[StudyRun]:
    """The teaching runs of ``method`` (C or the driver) for one order and driver style."""
    return _select(taught, method=method, order=tuple(order), style=style)


def teaching_section(plan: StudyPlan, runs: list[StudyRun], figs: Path) -> list[str]:
    """Section 6: one drive of the teaching course per order and per driver style; agreement with that driver on unseen layouts."""
    from terrapref.plots import RateRow, save_intervals

    taught = _select(runs, study="teach")
    if not taught:
        return []
    order_rows, order_points = _order_rows(plan, taught)
    style_rows, style_points = _style_rows(plan, taught)
    points = order_points + style_points
    course = course_name(plan.teach_course())
    follow = " and the follow-up course of what it left open" if plan.follow_up else ""
    lines = [
        f"## 6. Any order, any driver: one drive by recipe {plan.recipe}",
        "",
        f"Per training seed, the synthetic driver demonstrates on {course}{follow} (recipe {plan.recipe}, {plan.epochs} epochs) for each order "
        f"(default style) and each driver style (default order); every model then drives {len(plan.layouts)} generated layouts it "
        f"has never seen ({', '.join(plan.layouts)}), and so does the driver it learned from. **Agreement**: the planner's zone "
        f"choice equals that driver's in the same zone of the same layout (touching {plan.table.lethal_column or 'lethal terrain'} where the driver did not "
        "counts against). Brackets: 95% Wilson interval over all zones and seeds.",
        "",
        "| order | agreement with its driver | zone success | the driver's zone success | collisions |",
        "|---|---|---|---|---|",
        *order_rows,
        "",
        "Driver styles (order " + " > ".join(plan.orders[0]) + "): each style's planner against its own driver, and the "
        "planner taught by another style against the same driver. Clearance: how close the reference point came to terrain "
        "it did not choose, per zone; |Δ| is the mean gap to the driver's clearance in the same zone. Cross-track: RMS over "
        "the run.",
        "",
        "| driver style | agreement: own planner | agreement: planner of another style | clearance: driver | |Δ| own | |Δ| other | "
        "cross-track: driver | own | other | collisions (own) |",
        "|---|---|---|---|---|---|---|---|---|---|",
        *style_rows,
        "",
        *_imitation_table(plan, taught),
    ]
    rows = [RateRow(label, ok / n if n else float("nan"), wilson(ok, n)) for label, ok, n in points]
    save_intervals(
        figs / "teaching.png",
        rows,
        "agreement with its driver",
        target=0.95,
        title=f"one drive of {course}{' and its follow-up' if plan.follow_up else ''}: agreement on unseen layouts, by order and driver style",
    )
    return lines + ["", "![teaching](figures/teaching.png)", ""]


def _order_rows(plan: StudyPlan, taught: list[StudyRun]) -> tuple[list[str], list[tuple[str, int, int]]]:
    """One table row per order (default style), and each order's (label, agreeing zones, zones) for the figure."""
    rows, points = [], []
    for order in plan.orders:
        p, d = _taught(taught, "C", order, "default"), _taught(taught, EXPERT, order, "default")
        ok, n = agreement(p, d)
        succ = [z.success for r in p for z in r.metrics.zones]
        dsucc = [z.success for r in d for z in r.metrics.zones]
        rows.append(
            f"| {' > '.join(order)} | {rate_text(ok, n)} | {rate_text(int(sum(succ)), len(succ))} | "
            f"{rate_text(int(sum(dsucc)), len(dsucc))} | {_collisions(p)} |"
        )
        points.append((" > ".join(order[:3]), ok, n))
    return rows, points


def _style_rows(plan: StudyPlan, taught: list[StudyRun]) -> tuple[list[str], list[tuple[str, int, int]]]:
    """One table row per driver style (default order): its own planner and another style's against
    its driver; each style but the default's (label, agreeing zones, zones) for the figure."""
    from terrapref.demos.expert import STYLES

    rows, points = [], []
    for style in plan.styles:
        other, d, own, theirs = _style_runs(plan, taught, style)
        ok, n = agreement(own, d)
        ok2, n2 = agreement(theirs, d)
        rows.append(
            f"| {style} ({STYLES[style].description}) | {rate_text(ok, n)} | {rate_text(ok2, n2) + f' ({other})' if other else '—'} | "
            f"{_mean_clearance(d):.2f} m | {_clearance_gap(own, d):.2f} m | {_clearance_gap(theirs, d):.2f} m | "
            f"{_mean_cross_track(d):.2f} m | {_mean_cross_track(own):.2f} m | "
            f"{_mean_cross_track(theirs):.2f} m | {_collisions(own)} |"
        )
        if style != "default":
            points.append((f"style {style}", ok, n))
    return rows, points


def _imitation_table(plan: StudyPlan, taught: list[StudyRun]) -> list[str]:
    """Does each style's planner imitate its own driver better than another style's planner does?

    Paired on the same layout and training seed: agreement (own minus other), and how much
    closer the own planner's cross-track RMS and zone clearances come to the driver's than the
    other's (|other - driver| - |own - driver|). Positive favours the own planner; the interval
    resamples (layout, seed) runs."""
    rows = []
    for style in plan.styles:
        other, driver_runs, own_runs, other_runs = _style_runs(plan, taught, style)
        if other is None:
            continue
        driver = {r.scenario: r for r in driver_runs}
        theirs = {(r.scenario, r.tag.seed): r for r in other_runs}
        pairs = [
            (r, theirs[(r.scenario, r.tag.seed)], driver[r.scenario])
            for r in own_runs
            if (r.scenario, r.tag.seed) in theirs and r.scenario in driver
        ]
        agree, track, clear = [], [], []
        for own, oth, drv in pairs:
            d = {z.id: z for z in drv.metrics.zones}
            o = {z.id: z for z in oth.metrics.zones}
            zs = [(z, o[z.id], d[z.id]) for z in own.metrics.zones if z.id in o and z.id in d]
            agree.append([100.0 * (float(zone_agrees(a, c)) - float(zone_agrees(b, c))) for a, b, c in zs if c.reached])
            track.append(
                [
                    abs(oth.metrics.rms_cross_track_m - drv.metrics.rms_cross_track_m)
                    - abs(own.metrics.rms_cross_track_m - drv.metrics.rms_cross_track_m)
                ]
            )
            clear.append(
                [
                    abs(b.clearance_m - c.clearance_m) - abs(a.clearance_m - c.clearance_m)
                    for a, b, c in zs
                    if None not in (a.clearance_m, b.clearance_m, c.clearance_m)
                ]
            )
        cells = [
            _difference_text(cluster_bootstrap(g), unit, digits)
            for g, unit, digits in ((agree, " pts", 1), (track, " m", 2), (clear, " m", 2))
        ]
        rows.append(f"| {style} | {other} | {len(pairs)} | " + " | ".join(cells) + " |")
    if not rows:
        return []
    return [
        "Does each style's planner imitate its own driver better than the other style's planner? Paired on the same layout and "
        "training seed: agreement with the driver (own minus other, percentage points), and how much closer the own planner "
        "comes to the driver's cross-track RMS and zone clearances than the other does (|other - driver| - |own - driver|). "
        "Positive favours the own planner; brackets: 95% interval resampling (layout, seed) runs (2,000 draws); **own** or "
        "**other** where the interval as printed excludes 0, else not shown.",
        "",
        "| driver style | other planner | runs | agreement: own - other | cross-track: own closer by | clearance: own closer by |",
        "|---|---|---|---|---|---|",
        *rows,
    ]


def _style_runs(plan: StudyPlan, taught: list[StudyRun], style: str) -> tuple[str | None, list[StudyRun], list[StudyRun], list[StudyRun]]:
    """For one driver style in the default order: the style whose planner its own is compared with
    (the default's, or for the default the first other style; None if there is none), and the
    runs of its driver, of its own planner and of that other planner."""
    default = plan.orders[0]
    other = "default" if style != "default" else next((s for s in plan.styles if s != "default"), None)
    theirs = _taught(taught, "C", default, other) if other else []
    return other, _taught(taught, EXPERT, default, style), _taught(taught, "C", default, style), theirs


def _difference_text(estimate: tuple[float, float, float], unit: str, digits: int) -> str:
    """``"+0.12 m (+0.03 to +0.20), **own**"``: a paired difference, its interval (``digits``
    decimals) and which side it favours."""
    mean, lo, hi = estimate
    if math.isnan(mean):
        return "—"
    # judged on the interval as printed, so that no verdict rests on a bound that reads as 0
    lo, hi = round(lo, digits), round(hi, digits)
    verdict = ", **own**" if lo > 0 else (", **other**" if hi < 0 else ", not shown")
    return f"{mean:+.{digits}f}{unit} ({lo:+.{digits}f} to {hi:+.{digits}f}){verdict}"


def _demo_minutes(trained: Sequence[TrainedModel]) -> float:
    """Minutes of demonstration behind the full-data models (frames at 10 Hz)."""
    frames = [t.samples for t in trained if t.job.study == "baselines" and t.job.method == "C"]
    return float(np.mean(frames)) / 600.0 if frames else float("nan")


def _zone_success(runs: list[StudyRun], keep: set) -> tuple[int, int]:
    zs = [z.success for r in runs for z in r.metrics.zones if (r.scenario, z.id) in keep]
    return int(sum(zs)), len(zs)


def disagreement_zones(runs: list[StudyRun]) -> set:
    """(scenario, zone id) whose expected choice differs between the default and the other profile."""

    def expects(rr: list[StudyRun]) -> dict:
        return {(r.scenario, z.id): z.expect for r in rr for z in r.metrics.zones}

    default = expects(_select(runs, study="baselines", method=EXPERT, seed=0))
    other = expects(_select(runs, study="profile", method=EXPERT, seed=0))
    return {k for k in default if k in other and default[k] != other[k]}


def _disagreement_table(runs: list[StudyRun]) -> list[str]:
    keep = disagreement_zones(runs)
    if not keep:
        return []
    rows = [
        (label, *_zone_success(rr, keep))
        for label, rr in (
            ("C trained on the other profile, scored under the other profile", _select(runs, study="profile", method="C")),
            ("C trained on the default profile, scored under the other profile", _select(runs, study="profile_cross", method="C_default")),
            ("C trained on the default profile, scored under the default profile", _select(runs, study="baselines", method="C")),
            ("C trained on the other profile, scored under the default profile", _select(runs, study="profile_cross", method="C")),
        )
    ]
    out = [
        f"The zones where the two profiles expect different choices ({len(keep)}: "
        + ", ".join(f"{sc} {zid}" for sc, zid in sorted(keep))
        + "):",
        "",
        "| model and scoring | success in these zones |",
        "|---|---|",
    ]
    out += [f"| {label} | {rate_text(ok, n)} |" for label, ok, n in rows]
    return out + [""]


def _choice_table(plan: StudyPlan, runs: list[StudyRun]) -> list[str]:
    """How often each class was chosen in `best` zones, by which profile the model learned."""
    columns = (*plan.default_order(), "avoid")  # a lethal class's choice counts in the lethal column
    rows = ["| model | " + " | ".join(columns) + " |", "|---|" + "---|" * len(columns)]
    for label, rr in (
        ("default profile", _select(runs, study="baselines", method="C")),
        ("other profile", _select(runs, study="profile", method="C")),
    ):
        choices = [plan.table.column_of(z.choice) for r in rr for z in r.metrics.zones if z.expect != "avoid"]
        n = max(len(choices), 1)
        rows.append(f"| C, {label} | " + " | ".join(f"{choices.count(c) / n:.0%}" for c in columns) + " |")
    return ["Choices in the zones where a patch is expected (share of zones):", "", *rows, ""]
