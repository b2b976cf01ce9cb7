"""`terrapref reproduce`: demonstrations -> models -> closed-loop evaluation -> REPORT.md.

For each training seed, the synthetic driver demonstrates on each recipe's course
(``train_course`` for the paper's recipe and ``ours``, ``teach_course`` for the default recipe
``teach``) and a model is trained by each recipe; every model then drives ``train_course``,
``test_course`` and the figure variations, and so does the synthetic driver. The report gives
the paper's Table 1 and Table 2 with success over seeds (and the planner's agreement with the
driver), each rate with its 95% Wilson interval, the figures, and each stage's time.
"""

from __future__ import annotations

import functools
import json
import time
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path

import numpy as np

from terrapref.fileio import write_text_atomic
from terrapref.grid import Engine, run_grid
from terrapref.evaluation.runner import EXPERT, PLANNER, RunSpec, annotate_agreement, run_many, summarise
from terrapref.evaluation.stats import rate_text
from terrapref.recipes import OURS, PAPER, TEACH, Recipe, run_recipe
from terrapref.progress import every_tenth
from terrapref.scenario import packaged_scenarios, resolve_scenario
from terrapref.terrain import PreferenceProfile

TEST_SET = ("test_course",)
TRACK_COLOURS = ("orange", "red", "magenta", "limegreen")  # the planners' tracks, by recipe


def variations() -> list[str]:
    return [n for n in packaged_scenarios() if n.startswith("fig")]


def _train_job(args: tuple[tuple[Recipe, ...], str, int, tuple[str, ...]]) -> list[dict]:
    """Recipes of one seed that share demonstrations, in one process (they never record twice)."""
    recipes, workdir, seed, profile = args
    rows = []
    for recipe in recipes:
        t0 = time.perf_counter()
        out = run_recipe(recipe, workdir, seed, PreferenceProfile(profile))
        rows.append({
            "recipe": recipe.name, "seed": seed, "model": str(out.model),
            "history": [asdict(h) for h in out.result.history], "best_epoch": out.result.best_epoch,
            "demo_minutes": out.demo_minutes, "correction_minutes": out.correction_minutes,
            "seconds": time.perf_counter() - t0,
        })
    return rows


def reproduce(out_dir: str | Path, seeds: int = 5, eval_seeds: int = 1, recipes: tuple[Recipe, ...] = (PAPER, OURS, TEACH),
              profile: PreferenceProfile | None = None, engine: Engine | None = None, log: Callable[[str], None] = print) -> Path:
    """Run the whole reproduction into ``out_dir`` and return the path of REPORT.md; ``engine``
    runs its jobs (default: local processes, one per core)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    profile = profile or PreferenceProfile.default()
    engine = engine or Engine()
    timings: dict[str, float] = {}

    t0 = time.perf_counter()
    # One job per seed and demonstration protocol (recipes recording the same demonstrations stay
    # together), the costliest first, so that both cores stay busy to the end.
    groups: dict = {}
    for r in recipes:
        groups.setdefault((r.course, r.disturbance), []).append(r)
    cost = {key: max(r.demonstrations * (1 + r.train.members * r.train.epochs * (2 if r.train.mirror else 1) / 100) for r in g)
            for key, g in groups.items()}
    jobs = [(tuple(g), str(out / "work" / f"seed{s}"), s, profile.order)
            for key, g in sorted(groups.items(), key=lambda kv: -cost[kv[0]]) for s in range(seeds)]
    log(f"[1/3] demonstrations, corrections and training: {len(recipes) * seeds} models ({', '.join(r.name for r in recipes)} x {seeds} seeds) ...")
    done = run_grid(_train_job, jobs, engine, lambda k, n: log(f"      trained {k}/{n} job(s)"),
                    describe=lambda j: f"recipes {', '.join(r.name for r in j[0])}, seed {j[2]}")
    trained = [row for rows in done for row in rows]
    order = {r.name: i for i, r in enumerate(recipes)}
    trained.sort(key=lambda t: (t["seed"], order[t["recipe"]]))
    timings["demonstrate + correct + train"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    scenarios = ["train_course", *TEST_SET, *variations()]
    specs = [RunSpec(sc, e, PLANNER, t["model"], profile.order)
             for t in trained for sc in scenarios for e in range(eval_seeds)]
    specs += [RunSpec(sc, s, EXPERT, None, profile.order) for sc in scenarios for s in range(seeds)]
    specs.sort(key=lambda sp: -scenario_length(sp.scenario))  # longest first: no core idles at the end
    log(f"[2/3] closed-loop evaluation: {len(specs)} runs ...")
    results = run_many(specs, progress=every_tenth(log), engine=engine)
    annotate_agreement(results)
    for r, spec in zip(results, specs):
        r["recipe"] = next((t["recipe"] for t in trained if t["model"] == spec.model_path), "driver")
        r["train_seed"] = next((t["seed"] for t in trained if t["model"] == spec.model_path), r["seed"])
    timings["closed-loop evaluation"] = time.perf_counter() - t0

    log("[3/3] figures and REPORT.md ...")
    return _write_report(out, results, trained, recipes, seeds, eval_seeds, profile, scenarios, timings)


@functools.lru_cache(maxsize=64)
def scenario_length(scenario: str) -> float:
    """Length of a scenario's reference path [m] (to start the longest runs first)."""
    return resolve_scenario(scenario).path_length_m()


def _zone_rows(results: list[dict], scenario: str, recipes: tuple[Recipe, ...]) -> list[str]:
    s = resolve_scenario(scenario)
    rows = []
    for zone in s.zones:
        def choices(recipe: str) -> list[tuple[str, bool, str]]:
            out = []
            for r in results:
                if r["scenario"] == scenario and r["recipe"] == recipe:
                    z = next(z for z in r["metrics"]["zones"] if z["id"] == zone.id)
                    out.append((z["choice"], z["success"], z["expect"]))
            return out

        drv = choices("driver")
        expect = drv[0][2] if drv else zone.expect
        cells = [zone.id, zone.label or "", expect, _mode(drv)]
        for recipe in recipes:
            c = choices(recipe.name)
            lethal = sum(ch == ex and not ok for ch, ok, ex in c)
            note = f" ({lethal} touched non_traversable)" if lethal else ""
            cells += [_mode(c), f"{sum(ok for _, ok, _ in c)}/{len(c)}{note}"]
        rows.append("| " + " | ".join(cells) + " |")
    return rows


def _mode(choices: list[tuple[str, bool, str]]) -> str:
    if not choices:
        return "-"
    names = [c for c, _, _ in choices]
    top = max(set(names), key=names.count)
    return top if names.count(top) == len(names) else f"{top} ({names.count(top)}/{len(names)})"


def _write_report(out: Path, results, trained, recipes, seeds, eval_seeds, profile, scenarios, timings) -> Path:
    from terrapref.plots import save_loss_curve, save_map
    from terrapref.world import rasterise

    t_fig = time.perf_counter()
    figs = out / "figures"
    figs.mkdir(exist_ok=True)
    for sc in scenarios:
        scenario = resolve_scenario(sc)
        tracks = []
        for r in results:
            if r["scenario"] != sc or r["seed"] != 0:
                continue
            if r["recipe"] == "driver":
                tracks.append(("driver (seed 0)", r["xy"], "deepskyblue"))
            elif r["train_seed"] == 0:
                color = TRACK_COLOURS[[x.name for x in recipes].index(r["recipe"]) % len(TRACK_COLOURS)]
                tracks.append((f"planner, {r['recipe']} (seed 0)", r["xy"], color))
        save_map(figs / f"{sc}.png", scenario, rasterise(scenario), tracks, title=f"{sc}: reference, driver and planner paths")
    for t in trained:
        if t["seed"] == 0:
            save_loss_curve(figs / f"training_{t['recipe']}.png", t["history"], t["best_epoch"], title=f"training, recipe {t['recipe']}, seed 0")

    def set_summary(recipe: str, names: list[str]) -> dict:
        return summarise([r for r in results if r["recipe"] == recipe and r["scenario"] in names], PLANNER if recipe != "driver" else EXPERT)

    test_names = [*TEST_SET, *variations()]
    header = "| zone | terrains | expected | driver | " + " | ".join(f"{r.name} planner | {r.name} success" for r in recipes) + " |"
    sep = "|" + "---|" * (4 + 2 * len(recipes))
    lines = [
        "# terrapref: reproduction of the paper's Tables 1 and 2",
        "",
        f"Preference profile: {profile} (grass preferred over every patch). Synthetic driver as the human;",
        f"{seeds} training seeds per recipe (each seed: its own demonstrations and training initialisation),",
        f"{eval_seeds} evaluation run(s) per model and scenario. Every number below comes from driving the simulator.",
        "",
        "Recipes:",
    ]
    for r in recipes:
        pushes = (f"with disturbances ({r.disturbance.rate_hz:g} pushes/s of {r.disturbance.min_yaw_rate_rps:g}-{r.disturbance.max_yaw_rate_rps:g} rad/s)"
                  if r.disturbance is not None else "undisturbed")
        lines.append(f"- **{r.name}**: {r.demonstrations} demonstration run(s) of {r.course}, {pushes}, {r.corrections} correction session(s), "
                     f"{r.train.epochs} epochs, residual path {'on' if r.train.skip else 'off'}, class-balanced loss {'on' if r.train.class_balance else 'off'}, "
                     f"mirrored samples {'on' if r.train.mirror else 'off'}"
                     + (f", {r.train.members} ensemble members" if r.train.members > 1 else "")
                     + (", the planner scoring a second stage of trajectories beyond the first with the linear utility fitted to the same samples"
                        + (" through the look-ahead" if r.lookahead else "") if r.train.utility else "") + ".")
    lines += ["", "## Summary (test_course and the figure variations)", "",
              "Zone success against the zones' expectations; agreement: the planner's choice equals the synthetic driver's in the same "
              "zone of the same run (evaluation seed). 95% Wilson intervals over all zones of all training seeds.", "",
              "| who | zone success | agreement with the driver | collisions | completed | runs |", "|---|---|---|---|---|---|"]
    for name in [*(r.name for r in recipes), "driver"]:
        runs = [r for r in results if r["recipe"] == name and r["scenario"] in test_names]
        zones = [z for r in runs for z in r["metrics"]["zones"]]
        compared = [z for z in zones if "agrees" in z]
        s = set_summary(name, test_names)
        agreement = rate_text(sum(z["agrees"] for z in compared), len(compared)) if compared else "—"
        lines.append(f"| {name} | {rate_text(sum(z['success'] for z in zones), len(zones))} | {agreement} | {s['collision_count']} | "
                     f"{s['completed_rate']:.0%} | {s['runs']} |")
    for title, names in (("Table 1: training scenarios (train_course)", ["train_course"]), ("Table 2: test scenarios (test_course)", ["test_course"])):
        lines += ["", f"## {title}", "", header, sep]
        for sc in names:
            lines += _zone_rows(results, sc, recipes)
    lines += ["", "## Figure 7 and 8 variations", "", header.replace("| zone |", "| scenario |"), sep]
    for sc in variations():
        for row in _zone_rows(results, sc, recipes):
            lines.append(row.replace("| 1 |", f"| {sc} |", 1))
    lines += ["", "## Training", ""]
    for r in recipes:
        ts = [t for t in trained if t["recipe"] == r.name]
        lines.append(f"- {r.name}: chosen epochs {[t['best_epoch'] for t in ts]}; validation accuracy at the chosen epoch "
                     f"{[round(t['history'][t['best_epoch'] - 1]['val_acc'], 3) for t in ts]}; demonstration {np.mean([t['demo_minutes'] for t in ts]):.1f} min, "
                     f"corrections {np.mean([t['correction_minutes'] for t in ts]):.1f} min per seed. Curve: `figures/training_{r.name}.png`.")
    lines += ["", "## Figures", ""]
    for sc in scenarios:
        lines.append(f"- `figures/{sc}.png`")
    timings["figures"] = time.perf_counter() - t_fig
    lines += ["", "## Time per stage (wall clock)", "", "| stage | seconds |", "|---|---|"]
    for k, v in timings.items():
        lines.append(f"| {k} | {v:.1f} |")
    lines.append(f"| total | {sum(timings.values()):.1f} |")
    slim = [{k: v for k, v in r.items() if k not in ("xy", "frames")} for r in results]
    write_text_atomic(out / "results.json", json.dumps({"runs": slim, "timings": timings}, indent=1))
    return write_text_atomic(out / "REPORT.md", "\n".join(lines) + "\n")
