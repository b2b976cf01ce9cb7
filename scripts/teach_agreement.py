"""Agreement with the driver after one drive of teach_course, per preference order: does one
five-minute drive teach any driver's preference?

For every order and training seed, the synthetic driver of that order drives the demonstration
course once (recipe ``teach`` unless --recipe says otherwise), a model is trained, and the model
and the same driver drive every generated layout. A zone agrees when the planner's choice equals
the driver's in the same zone of the same layout (terrapref.evaluation.runner.zone_agrees).

    .venv/bin/python scripts/teach_agreement.py --out runs/agreement                # 6 orders x 5 seeds x gen:2000-2031
    .venv/bin/python scripts/teach_agreement.py --orders mud,rock,water --seeds 1 --first 1000 --courses 16 --out runs/sel

Writes AGREEMENT.md (per order and per zone kind, with 95% Wilson intervals), agreement.json
(every zone) and agreement.png. Layouts gen:1000-1999 are where recipes are chosen; the final
measurement uses gen:2000-2031, which no choice has seen.
"""

from __future__ import annotations

import argparse
import itertools
import json
import multiprocessing as mp
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

from terrapref.evaluation.runner import EXPERT, PLANNER, RunSpec, run_many, zone_agrees
from terrapref.evaluation.stats import rate_text, wilson
from terrapref.learning.recipe import DEFAULT_RECIPE, recipe_named, run_recipe
from terrapref.report.plots import save_intervals
from terrapref.scenario.generate import zone_kind
from terrapref.terrain import PreferenceProfile

LETHAL_LAST = "non_traversable"
ALL_ORDERS = [(*p, LETHAL_LAST) for p in itertools.permutations(("mud", "rock", "water"))]


def parse_orders(text: str) -> list[tuple[str, ...]]:
    if text == "all":
        return ALL_ORDERS
    orders = []
    for item in text.split(";"):
        names = tuple(n.strip() for n in item.split(",") if n.strip())
        orders.append(names if LETHAL_LAST in names else (*names, LETHAL_LAST))
    return orders


def _train(job: tuple[str, str, tuple[str, ...], int, str]) -> tuple[str, float]:
    recipe_name, workdir, order, seed, style = job
    t0 = time.perf_counter()
    out = run_recipe(recipe_named(recipe_name), workdir, seed, PreferenceProfile(order), style=style)
    return str(out.model), time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--recipe", default=DEFAULT_RECIPE)
    ap.add_argument("--orders", default="all", help="'all' (the six orders with non_traversable last) or 'a,b,c;d,e,f'")
    ap.add_argument("--style", default="default", help="the driver's style (terrapref.demos.expert.STYLES)")
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--first", type=int, default=2000, help="first generated layout")
    ap.add_argument("--courses", type=int, default=32)
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--report-only", action="store_true", help="rewrite AGREEMENT.md and the figure from OUT/agreement.json")
    args = ap.parse_args(argv)
    orders = parse_orders(args.orders)
    layouts = [f"gen:{args.first + i}" for i in range(args.courses)]
    if args.report_only:
        saved = json.loads((args.out / "agreement.json").read_text())
        rows = saved["zones"]
        collisions = {(tuple(r["order"]), r["model"], r["scenario"]): r["collisions"] for r in rows}
        order_list = list(dict.fromkeys(tuple(r["order"]) for r in rows))
        write_report(args, order_list, saved["layouts"], rows, collisions, saved.get("train_s", 0.0), saved.get("eval_s", 0.0))
        return 0
    args.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()

    jobs = [(args.recipe, str(args.out / "work" / f"{'_'.join(o[:2] for o in order[:3])}_s{s}"), order, s, args.style)
            for order in orders for s in range(args.seeds)]
    models: list[str] = [""] * len(jobs)
    with ProcessPoolExecutor(args.workers, mp_context=mp.get_context("fork")) as pool:
        futures = {pool.submit(_train, j): i for i, j in enumerate(jobs)}
        for k, fut in enumerate(as_completed(futures), start=1):
            models[futures[fut]], seconds = fut.result()
            print(f"trained {k}/{len(jobs)} ({seconds:.0f} s)", file=sys.stderr, flush=True)
    t_train = time.perf_counter() - t0

    specs = [RunSpec(c, 0, PLANNER, model, job[2]) for job, model in zip(jobs, models) for c in layouts]
    specs += [RunSpec(c, 0, EXPERT, None, order, style=args.style) for order in orders for c in layouts]
    results = run_many(specs, args.workers, lambda k, n: print(f"run {k}/{n}", file=sys.stderr, flush=True) if k % 50 == 0 or k == n else None)
    t_eval = time.perf_counter() - t0 - t_train

    driver = {(tuple(s.profile), r["scenario"], z["id"]): z for s, r in zip(specs, results) if r["driver"] == EXPERT for z in r["metrics"]["zones"]}
    rows = []
    for spec, r in zip(specs, results):
        if r["driver"] != PLANNER:
            continue
        for z in r["metrics"]["zones"]:
            d = driver[(tuple(spec.profile), r["scenario"], z["id"])]
            rows.append({"order": list(spec.profile), "model": spec.model_path, "scenario": r["scenario"], "zone": z["id"],
                         "kind": zone_kind(z["label"]), "label": z["label"], "choice": z["choice"], "driver_choice": d["choice"],
                         "agrees": zone_agrees(z, d), "success": z["success"], "driver_success": d["success"],
                         "collisions": r["metrics"]["collisions"]})
    collisions = {(tuple(s.profile), s.model_path, r["scenario"]): r["metrics"]["collisions"] for s, r in zip(specs, results) if r["driver"] == PLANNER}
    (args.out / "agreement.json").write_text(json.dumps({"recipe": args.recipe, "style": args.style, "layouts": layouts, "zones": rows,
                                                         "train_s": t_train, "eval_s": t_eval}, indent=0))
    write_report(args, orders, layouts, rows, collisions, t_train, t_eval)
    return 0


def _rate(rows: list[dict], key: str) -> str:
    return rate_text(sum(r[key] for r in rows), len(rows))


def write_report(args, orders, layouts, rows, collisions, t_train: float, t_eval: float) -> None:
    kinds = sorted({r["kind"] for r in rows})
    n_seeds = len({r["model"] for r in rows}) // max(1, len(orders))
    lines = [f"# Agreement with the driver: recipe {args.recipe}, one drive per order and seed", "",
             f"{len(orders)} order(s) x {n_seeds} training seed(s); every model and its driver (style {args.style}) drive "
             f"{len(layouts)} generated layouts ({layouts[0]} to {layouts[-1]}). Rates with 95% Wilson intervals over all zones.", "",
             "| order | agreement with the driver | " + " | ".join(f"agreement, {k} zones" for k in kinds)
             + " | zone success | the driver's zone success | collisions | per seed |",
             "|---|---|" + "---|" * len(kinds) + "---|---|---|---|"]
    labels, rates, intervals = [], [], []
    for order in [*orders, None]:
        sel = rows if order is None else [r for r in rows if tuple(r["order"]) == order]
        coll = sum(v for (o, _, _), v in collisions.items() if order is None or o == order)
        per_seed = {}
        for r in sel:
            per_seed.setdefault(r["model"], []).append(r["agrees"])
        seeds = ", ".join(f"{sum(v) / len(v):.0%}" for v in per_seed.values())
        name = "**all**" if order is None else " > ".join(order)
        lines.append(f"| {name} | {_rate(sel, 'agrees')} | " + " | ".join(_rate([r for r in sel if r["kind"] == k], "agrees") for k in kinds)
                     + f" | {_rate(sel, 'success')} | {_rate(sel, 'driver_success')} | {coll} | {seeds if order else '-'} |")
        if order is not None:
            ok = sum(r["agrees"] for r in sel)
            labels.append(" > ".join(order[:3]))
            rates.append(ok / len(sel))
            intervals.append(wilson(ok, len(sel)))
    misses: dict[tuple, int] = {}
    for r in rows:
        if not r["agrees"]:
            key = (r["kind"], r["choice"], r["driver_choice"])
            misses[key] = misses.get(key, 0) + 1
    lines += ["", "Disagreements (zone kind: planner's choice / driver's choice, count): "
              + "; ".join(f"{k}: {p} / {d}, {n}" for (k, p, d), n in sorted(misses.items(), key=lambda kv: -kv[1])), "",
              f"Training {t_train:.0f} s, evaluation {t_eval:.0f} s (wall, {args.workers} workers).", "", "![agreement](agreement.png)", ""]
    save_intervals(args.out / "agreement.png", labels, rates, intervals, "agreement with the driver", target=0.95,
                   title=f"recipe {args.recipe}: one drive per order and seed, {len(layouts)} unseen layouts x {n_seeds} seeds; 95% intervals")
    (args.out / "AGREEMENT.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    sys.exit(main())
