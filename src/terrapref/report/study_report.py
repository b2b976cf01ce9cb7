"""STUDY.md and its figures, from the study's runs (terrapref.report.study)."""

from __future__ import annotations

import time
from collections import defaultdict
from pathlib import Path

import numpy as np

from terrapref.fileio import write_text_atomic
from terrapref.evaluation.runner import EXPERT, HAND_COST, PURE_PURSUIT, zone_agrees
from terrapref.evaluation.stats import rate_text, wilson

TARGET = 0.9  # the success level the data-efficiency question asks about
ALT_PROFILE = ("rock", "mud", "water", "non_traversable")  # the study's other preference profile
ALL = "all"  # the data-efficiency point that uses every demonstrated minute: the baselines' runs
METHOD_NAMES = {
    "C": "C (ours)",
    "linear": "linear utility (learned)",
    "cnn": "end-to-end CNN",
    HAND_COST: "hand-tuned cost",
    PURE_PURSUIT: "pure pursuit",
    EXPERT: "synthetic driver",
}


def _rate(runs: list[dict]) -> float:
    zones = [z["success"] for r in runs for z in r["metrics"]["zones"]]
    return float(np.mean(zones)) if zones else float("nan")


def _per_seed(runs: list[dict]) -> list[float]:
    by: dict[int, list[dict]] = defaultdict(list)
    for r in runs:
        by[r["seed"]].append(r)
    return [_rate(v) for _, v in sorted(by.items())]


def _cell(runs: list[dict]) -> tuple[str, float, float]:
    """'mean ± std [lo-hi]': the mean and std of the per-seed zone success, and the 95% Wilson
    interval of the success rate pooled over every zone of the runs."""
    rates = _per_seed(runs)
    if not rates:
        return "—", float("nan"), float("nan")
    m, s = float(np.mean(rates)), float(np.std(rates))
    zones = [z["success"] for r in runs for z in r["metrics"]["zones"]]
    lo, hi = wilson(int(sum(zones)), len(zones))
    return (f"{m:.1%} ± {s:.1%}" if len(rates) > 1 else f"{m:.1%}") + f" [{lo:.0%}-{hi:.0%}]", m, s


def _collisions(runs: list[dict]) -> int:
    return int(sum(r["metrics"]["collisions"] for r in runs))


def _select(runs: list[dict], **keys) -> list[dict]:
    return [r for r in runs if all(r.get(k) == v for k, v in keys.items())]


def write_study(out: Path, plan, trained: list[dict], runs: list[dict], timings: dict[str, float],
                report_started: float | None = None) -> Path:
    """Write STUDY.md and the figures; ``report_started`` (perf_counter) times this stage in the table."""
    from terrapref.plots import save_bars, save_curves

    figs = out / "figures"
    figs.mkdir(exist_ok=True)
    n_seeds = plan.seeds
    lines = ["# terrapref study: baselines, data efficiency, preference profiles, robustness, ablations", ""]
    zones_per_pass = sum(len(r["metrics"]["zones"]) for r in _select(runs, study="baselines", method=EXPERT, seed=0))
    lines += [f"Every number comes from closed-loop runs in the simulator on {', '.join(plan.scenarios())} "
              f"({zones_per_pass} zones per pass), "
              f"{n_seeds} training seed(s): each seed has its own demonstrations (2 runs of train_course with disturbances, "
              "about 11 minutes) and its own initialisation. Zone success is given as the mean over seeds ± its standard deviation; "
              "collisions are summed over all runs; brackets give the 95% Wilson interval of the rate pooled over all zones. One zone is "
              f"{1 / max(zones_per_pass, 1):.1%} of a seed's score, so differences of a few points are within the spread between seeds.", ""]

    # -- baselines
    order = ["C", "linear", "cnn", HAND_COST, PURE_PURSUIT, EXPERT]
    base = {m: _select(runs, study="baselines", method=m) for m in order}
    cells = {m: _cell(base[m]) for m in order}
    # -- data efficiency
    full_minutes = _demo_minutes(trained)
    points = [*plan.minutes, ALL]
    eff: dict[str, list[tuple[float, float, float]]] = {}
    for m in ("C", "linear", "cnn"):
        eff[m] = [(full_minutes, *_cell(base[m])[1:]) if mins == ALL else (mins, *_cell(_select(runs, study="efficiency", method=m, minutes=mins))[1:])
                  for mins in points]
    reach = {m: next((mins for mins, mean, _ in eff[m] if mean >= TARGET), None) for m in eff}
    # -- profiles
    alt_runs = _select(runs, study="profile", method="C")
    alt_cell = _cell(alt_runs)
    alt_driver = _cell(_select(runs, study="profile", method=EXPERT))
    cross_alt_default = _cell(_select(runs, study="profile_cross", method="C"))
    cross_default_alt = _cell(_select(runs, study="profile_cross", method="C_default"))
    # -- robustness
    clean = cells["C"]

    def answer_minutes(m: str) -> str:
        if reach[m] is not None:
            return f"{reach[m]:.3g} min"
        return f"not reached with all {full_minutes:.1f} min (best {max(e[1] for e in eff[m]):.0%})"

    lines += ["## Answers", ""]
    lines.append(f"- **Minutes of demonstration to reach {TARGET:.0%} zone success:** C {answer_minutes('C')}; "
                 f"linear utility {answer_minutes('linear')}; end-to-end CNN {answer_minutes('cnn')}.")
    lines.append(f"- **Learned planner against hand-tuned and linear:** C {cells['C'][0]}, hand-tuned cost {cells[HAND_COST][0]} "
                 f"({(cells['C'][1] - cells[HAND_COST][1]) * 100:+.1f} points), learned linear utility {cells['linear'][0]} "
                 f"({(cells['C'][1] - cells['linear'][1]) * 100:+.1f} points); the end-to-end CNN {cells['cnn'][0]} "
                 f"({(cells['C'][1] - cells['cnn'][1]) * 100:+.1f} points).")
    keep = disagreement_zones(runs)
    a_ok, a_n = _zone_success(alt_runs, keep)
    d_ok, d_n = _zone_success(_select(runs, study="profile_cross", method="C_default"), keep)
    lines.append(f"- **Another profile ({' > '.join(ALT_PROFILE)}) is learned:** C trained on demonstrations driven under it reaches "
                 f"{alt_cell[0]} scored under that profile (the driver: {alt_driver[0]}). In the {len(keep)} test zones where the two "
                 f"profiles expect different choices, it makes the other profile's choice in {a_ok}/{a_n} runs; the model trained "
                 f"on the default profile does so in {d_ok}/{d_n}. (All zones: the other-profile model scored under the default "
                 f"profile {cross_alt_default[0]}, the default model under the other profile {cross_default_alt[0]}.)")
    falls = []
    for kind, levels in plan.noise.items():
        pts = [(lv, _cell(_select(runs, study="robustness", kind=kind, level=lv))[1]) for lv in levels]
        falls.append(f"{_kind_label(kind)}: " + ", ".join(f"{lv:g} -> {m:.0%}" for lv, m in pts))
    lines.append(f"- **How fast success falls with noise** (clean: {clean[0]}): " + "; ".join(falls) + ".")
    lines.append("")

    lines += ["## 1. Baselines", "", "Each is a driver under the same planner interface, scored by the same code.", "",
              "| method | zone success | collisions | completed |", "|---|---|---|---|"]
    for m in order:
        done = np.mean([r["metrics"]["completed"] for r in base[m]]) if base[m] else float("nan")
        lines.append(f"| {METHOD_NAMES[m]} | {cells[m][0]} | {_collisions(base[m])} | {done:.0%} |")
    from terrapref.planner.policy import HAND_COSTS, HAND_DISTANCE_WEIGHT

    lines += ["", f"Hand-tuned costs per unit share: {', '.join(f'{k} {v:g}' for k, v in HAND_COSTS.items())}; distance utility weight "
              f"{HAND_DISTANCE_WEIGHT:g}. Pure pursuit: 2.5 m look-ahead, nearest trajectory. For the deterministic baselines, "
              "'seeds' are the evaluation seeds (start offset and heading).", "", "![baselines](figures/baselines.png)", ""]
    save_bars(figs / "baselines.png", [METHOD_NAMES[m] for m in order], [cells[m][1] for m in order], [cells[m][2] for m in order],
              "zone success, test_course and variations", target=TARGET)

    lines += ["## 2. Data efficiency", "", "The first N minutes of the same demonstrations.", "",
              "| minutes | " + " | ".join(METHOD_NAMES[m] for m in eff) + " |", "|---|" + "---|" * len(eff)]
    for i, mins in enumerate(points):
        study = "baselines" if mins == ALL else "efficiency"
        samples = next((t["samples"] for t in trained if t["study"] == study and t.get("minutes") == (None if mins == ALL else mins) and t["method"] == "C"), 0)
        label = f"all, {full_minutes:.1f}" if mins == ALL else f"{mins:g}"
        texts = [_cell(base[m] if mins == ALL else _select(runs, study="efficiency", method=m, minutes=mins))[0] for m in eff]
        lines.append(f"| {label} ({samples} frames) | " + " | ".join(texts) + " |")
    lines += ["", "![data efficiency](figures/data_efficiency.png)", ""]
    save_curves(figs / "data_efficiency.png", {METHOD_NAMES[m]: [(x, y, e) for x, y, e in eff[m]] for m in eff},
                "minutes of demonstration", "zone success", target=TARGET, logx=True)

    lines += ["## 3. Another preference profile", "",
              f"Demonstrations driven under {' > '.join(ALT_PROFILE)} (the default is mud > rock > water > non_traversable); "
              "`best` zones resolve under the profile the model carries.", "",
              "| model | scored under | zone success | collisions |", "|---|---|---|---|",
              f"| C trained on the other profile | its own | {alt_cell[0]} | {_collisions(alt_runs)} |",
              f"| synthetic driver, other profile | its own | {alt_driver[0]} | {_collisions(_select(runs, study='profile', method=EXPERT))} |",
              f"| C trained on the other profile | default | {cross_alt_default[0]} | — |",
              f"| C trained on the default profile | other | {cross_default_alt[0]} | — |", ""]
    lines += _choice_table(runs)
    lines += _disagreement_table(runs)

    lines += ["## 4. Robustness", "", "C (recipe ours) under perturbations of what the planner receives. Dropped frames: the planner "
              "holds its last command for up to 0.5 s, then stops until frames return.", ""]
    curves = {}
    for kind, levels in plan.noise.items():
        lines += [f"| {_kind_label(kind)} | zone success | collisions | completed |", "|---|---|---|---|",
                  f"| 0 | {clean[0]} | {_collisions(base['C'])} | {np.mean([r['metrics']['completed'] for r in base['C']]):.0%} |"]
        pts = [(0.0, clean[1], clean[2])]
        for lv in levels:
            rr = _select(runs, study="robustness", kind=kind, level=lv)
            c = _cell(rr)
            pts.append((lv, c[1], c[2]))
            lines.append(f"| {lv:g} | {c[0]} | {_collisions(rr)} | {np.mean([r['metrics']['completed'] for r in rr]):.0%} |")
        curves[kind] = pts
        lines.append("")
    from terrapref.plots import save_panels

    save_panels(figs / "robustness.png", {_kind_label(k): v for k, v in curves.items()}, "zone success")
    lines += ["![robustness](figures/robustness.png)", ""]

    lines += ["## 5. Ablations", "", "| variant | zone success | collisions |", "|---|---|---|",
              f"| C (ours: compression, distance utility, n = 30, width 64) | {cells['C'][0]} | {_collisions(base['C'])} |"]
    variants = sorted({r["variant"] for r in runs if r.get("study") == "ablation"}, key=str)
    for v in variants:
        rr = _select(runs, study="ablation", variant=v)
        lines.append(f"| {v} | {_cell(rr)[0]} | {_collisions(rr)} |")
    lines += teaching_section(plan, runs, figs)
    if report_started is not None:
        timings = {**timings, "tables and figures": time.perf_counter() - report_started}
    lines += ["", "## Time per stage (wall clock)", "", "| stage | seconds |", "|---|---|"]
    lines += [f"| {k} | {v:.1f} |" for k, v in timings.items()] + [f"| total | {sum(timings.values()):.1f} |", ""]
    return write_text_atomic(out / "STUDY.md", "\n".join(lines))


def _agreement(planner: list[dict], driver: list[dict]) -> tuple[int, int]:
    """Zones (agreeing, compared) where the planner's runs made the choice of the driver's run on the same layout."""
    by = {(r["scenario"], z["id"]): z for r in driver for z in r["metrics"]["zones"]}
    pairs = [(z, by[(r["scenario"], z["id"])]) for r in planner for z in r["metrics"]["zones"] if (r["scenario"], z["id"]) in by]
    return sum(zone_agrees(p, d) for p, d in pairs), len(pairs)


def _clearance_gap(planner: list[dict], driver: list[dict]) -> float:
    """Mean |planner's zone clearance - the driver's| over zones where both came near terrain they did not choose [m]."""
    by = {(r["scenario"], z["id"]): z.get("clearance_m") for r in driver for z in r["metrics"]["zones"]}
    gaps = [abs(z["clearance_m"] - by[(r["scenario"], z["id"])]) for r in planner for z in r["metrics"]["zones"]
            if z.get("clearance_m") is not None and by.get((r["scenario"], z["id"])) is not None]
    return float(np.mean(gaps)) if gaps else float("nan")


def _mean_metric(runs: list[dict], key: str) -> float:
    values = [r["metrics"][key] for r in runs if key in r["metrics"]]
    return float(np.mean(values)) if values else float("nan")


def _mean_clearance(runs: list[dict]) -> float:
    values = [z["clearance_m"] for r in runs for z in r["metrics"]["zones"] if z.get("clearance_m") is not None]
    return float(np.mean(values)) if values else float("nan")


def teaching_section(plan, runs: list[dict], figs: Path) -> list[str]:
    """Section 6: one drive of teach_course per order and per driver style; agreement with that driver on unseen layouts."""
    from terrapref.plots import save_intervals

    taught = _select(runs, study="teach")
    if not taught:
        return []
    default = list(plan.orders[0])

    def planner(order, style):
        return _select(taught, method="C", order=list(order), style=style)

    def driver(order, style):
        return _select(taught, method=EXPERT, order=list(order), style=style)

    lines = [f"## 6. Any order, any driver: one drive by recipe {plan.recipe}", "",
             f"Per training seed, the synthetic driver demonstrates (recipe {plan.recipe}, {plan.epochs} epochs) for each order "
             f"(default style) and each driver style (default order); every model then drives {len(plan.layouts)} generated layouts it "
             f"has never seen ({', '.join(plan.layouts)}), and so does the driver it learned from. **Agreement**: the planner's zone "
             "choice equals that driver's in the same zone of the same layout (touching non_traversable where the driver did not "
             "counts against). Brackets: 95% Wilson interval over all zones and seeds.", "",
             "| order | agreement with its driver | zone success | the driver's zone success | collisions |", "|---|---|---|---|---|"]
    labels, rates, intervals = [], [], []
    for order in plan.orders:
        p, d = planner(order, "default"), driver(order, "default")
        ok, n = _agreement(p, d)
        succ = [z["success"] for r in p for z in r["metrics"]["zones"]]
        dsucc = [z["success"] for r in d for z in r["metrics"]["zones"]]
        lines.append(f"| {' > '.join(order)} | {rate_text(ok, n)} | {rate_text(int(sum(succ)), len(succ))} | "
                     f"{rate_text(int(sum(dsucc)), len(dsucc))} | {_collisions(p)} |")
        labels.append(" > ".join(order[:3]))
        rates.append(ok / n if n else float("nan"))
        intervals.append(wilson(ok, n))
    lines += ["", "Driver styles (order " + " > ".join(default) + "): each style's planner against its own driver, and the "
              "planner taught by another style against the same driver. Clearance: how close the reference point came to terrain "
              "it did not choose, per zone; |Δ| is the mean gap to the driver's clearance in the same zone. Cross-track: RMS over "
              "the run.", "",
              "| driver style | agreement: own planner | agreement: planner of another style | clearance: driver | |Δ| own | |Δ| other | "
              "cross-track: driver | own | other | collisions (own) |", "|---|---|---|---|---|---|---|---|---|---|"]
    from terrapref.demos.expert import STYLES

    for style in plan.styles:
        other = "default" if style != "default" else next((s for s in plan.styles if s != "default"), None)
        d, own = driver(default, style), planner(default, style)
        theirs = planner(default, other) if other else []
        ok, n = _agreement(own, d)
        ok2, n2 = _agreement(theirs, d)
        lines.append(f"| {style} ({STYLES[style][0]}) | {rate_text(ok, n)} | {rate_text(ok2, n2) + f' ({other})' if other else '—'} | "
                     f"{_mean_clearance(d):.2f} m | {_clearance_gap(own, d):.2f} m | {_clearance_gap(theirs, d):.2f} m | "
                     f"{_mean_metric(d, 'rms_cross_track_m'):.2f} m | {_mean_metric(own, 'rms_cross_track_m'):.2f} m | "
                     f"{_mean_metric(theirs, 'rms_cross_track_m'):.2f} m | {_collisions(own)} |")
        if style != "default":
            labels.append(f"style {style}")
            rates.append(ok / n if n else float("nan"))
            intervals.append(wilson(ok, n))
    save_intervals(figs / "teaching.png", labels, rates, intervals, "agreement with its driver", target=0.95,
                   title="one drive of teach_course: agreement on unseen layouts, by order and driver style")
    return lines + ["", "![teaching](figures/teaching.png)", ""]


def _demo_minutes(trained: list[dict]) -> float:
    """Minutes of demonstration behind the full-data models (frames at 10 Hz)."""
    frames = [t["samples"] for t in trained if t["study"] == "baselines" and t["method"] == "C"]
    return float(np.mean(frames)) / 600.0 if frames else float("nan")


def _kind_label(kind: str) -> str:
    return {"flip_rate": "label flips (share of pixels)", "blobs": "mislabelled blobs per frame", "pose_noise_m": "pose noise (m; 10 deg per m)",
            "drop_rate": "dropped frames (share)", "delay_frames": "frame delay (frames of 0.1 s)"}.get(kind, kind)


def _zone_success(runs: list[dict], keep: set) -> tuple[int, int]:
    zs = [z["success"] for r in runs for z in r["metrics"]["zones"] if (r["scenario"], z["id"]) in keep]
    return int(sum(zs)), len(zs)


def disagreement_zones(runs: list[dict]) -> set:
    """(scenario, zone id) whose expected choice differs between the default and the other profile."""
    def expects(rr: list[dict]) -> dict:
        return {(r["scenario"], z["id"]): z["expect"] for r in rr for z in r["metrics"]["zones"]}

    default = expects(_select(runs, study="baselines", method=EXPERT, seed=0))
    other = expects(_select(runs, study="profile", method=EXPERT, seed=0))
    return {k for k in default if k in other and default[k] != other[k]}


def _disagreement_table(runs: list[dict]) -> list[str]:
    keep = disagreement_zones(runs)
    if not keep:
        return []
    rows = [(label, *_zone_success(rr, keep)) for label, rr in (
        ("C trained on the other profile, scored under the other profile", _select(runs, study="profile", method="C")),
        ("C trained on the default profile, scored under the other profile", _select(runs, study="profile_cross", method="C_default")),
        ("C trained on the default profile, scored under the default profile", _select(runs, study="baselines", method="C")),
        ("C trained on the other profile, scored under the default profile", _select(runs, study="profile_cross", method="C")),
    )]
    out = [f"The zones where the two profiles expect different choices ({len(keep)}: "
           + ", ".join(f"{sc} {zid}" for sc, zid in sorted(keep)) + "):", "",
           "| model and scoring | success in these zones |", "|---|---|"]
    out += [f"| {label} | {rate_text(ok, n)} |" for label, ok, n in rows]
    return out + [""]


def _choice_table(runs: list[dict]) -> list[str]:
    """How often each class was chosen in `best` zones, by which profile the model learned."""
    rows = ["| model | " + " | ".join(("mud", "rock", "water", "non_traversable", "avoid")) + " |", "|---|---|---|---|---|---|"]
    for label, rr in (("default profile", _select(runs, study="baselines", method="C")), ("other profile", _select(runs, study="profile", method="C"))):
        choices = [z["choice"] for r in rr for z in r["metrics"]["zones"] if z["expect"] != "avoid"]
        n = max(len(choices), 1)
        rows.append(f"| C, {label} | " + " | ".join(f"{choices.count(c) / n:.0%}" for c in ("mud", "rock", "water", "non_traversable", "avoid")) + " |")
    return ["Choices in the zones where a patch is expected (share of zones):", "", *rows, ""]
