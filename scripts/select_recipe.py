"""Choose a recipe on generated layouts (never on the packaged test course).

For each recipe and each training seed: demonstrate on train_course, correct, train (see
terrapref.recipes); then drive generated validation courses (gen:1000...) and count
zone success over the zones the synthetic driver itself gets right (a generated zone the
driver misses is ambiguous under its own costs, and is left out).

    python scripts/select_recipe.py --seeds 2 --courses 4
    python scripts/select_recipe.py --seeds 3 --courses 16 --only 19 29   # the docs/notebook.md runs
    python scripts/select_recipe.py --seeds 5 --courses 32 --only 19 34   # + 2 practice courses, 5 seeds
    python scripts/select_recipe.py --seeds 5 --courses 32 --first-course 1032 --only 34   # confirm a choice on fresh courses
    python scripts/select_recipe.py --seeds 5 --courses 32 --only 39 40 41 42   # counter-pushes while demonstrating
    python scripts/select_recipe.py --seeds 5 --courses 32 --only 43   # the planner's second stage (now `ours`)

With closed-loop runs cheap, 16 courses (117 zones the driver meets) cost little more than 8;
training is most of the time (about a minute per recipe and seed).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from terrapref.demos.session import DisturbanceConfig
from terrapref.evaluation.runner import EXPERT, PLANNER, RunSpec, run_many
from terrapref.recipes import PAPER, Recipe
from terrapref.learning.train import TrainConfig
from terrapref.scenario import resolve_scenario
from terrapref.scenario.generate import ZONE_KINDS, zone_kind

RECIPES = [
    PAPER,
    Recipe("long+skip+balanced, 2 demos", 2, 0, TrainConfig(epochs=100, skip=True, class_balance=True)),
    Recipe("long+skip+balanced, 2 demos + 2 corrections", 2, 2, TrainConfig(epochs=100, skip=True, class_balance=True)),
    Recipe("long+skip, decisive x3, 2 demos", 2, 0, TrainConfig(epochs=100, skip=True, decisive_weight=3.0)),
    Recipe("long+skip, decisive x3, 2 demos + 2 corrections", 2, 2, TrainConfig(epochs=100, skip=True, decisive_weight=3.0)),
    Recipe("long+skip+balanced, 1 demo + 2 corrections", 1, 2, TrainConfig(epochs=100, skip=True, class_balance=True)),
    Recipe("long+skip+balanced, 1 demo", 1, 0, TrainConfig(epochs=100, skip=True, class_balance=True)),
    Recipe("long+skip+balanced, 2 demos, smoothing 0.5", 2, 0, TrainConfig(epochs=100, skip=True, class_balance=True), smoothing=0.5),
    Recipe("long+skip+balanced, 2 demos, 300 epochs", 2, 0, TrainConfig(epochs=300, skip=True, class_balance=True)),
    Recipe("long+skip+balanced, 2 demos, 300 epochs, smoothing 0.5", 2, 0, TrainConfig(epochs=300, skip=True, class_balance=True), smoothing=0.5),
    Recipe("long+skip+balanced, 2 demos, 300 epochs, lr 3e-3", 2, 0, TrainConfig(epochs=300, lr=3e-3, skip=True, class_balance=True)),
    Recipe("long+skip+balanced, 2 demos, 300 epochs, lr 3e-3, smoothing 0.5", 2, 0,
           TrainConfig(epochs=300, lr=3e-3, skip=True, class_balance=True), smoothing=0.5),
    Recipe("long+skip+balanced, 2 demos, 300 epochs, mirrored", 2, 0, TrainConfig(epochs=300, skip=True, class_balance=True, mirror=True)),
    Recipe("long+skip+balanced, 1 demo, 300 epochs, mirrored", 1, 0, TrainConfig(epochs=300, skip=True, class_balance=True, mirror=True)),
    Recipe("long+skip+balanced, 2 disturbed demos, 300 epochs", 2, 0, TrainConfig(epochs=300, skip=True, class_balance=True),
           disturbance=DisturbanceConfig()),
    Recipe("long+skip+balanced, 2 demos disturbed x2, 300 epochs", 2, 0, TrainConfig(epochs=300, skip=True, class_balance=True),
           disturbance=DisturbanceConfig(rate_hz=0.3)),
    Recipe("long+skip+balanced, 1 disturbed demo, 300 epochs", 1, 0, TrainConfig(epochs=300, skip=True, class_balance=True),
           disturbance=DisturbanceConfig()),
    Recipe("long+skip+balanced, 2 demos disturbed x3, 300 epochs", 2, 0, TrainConfig(epochs=300, skip=True, class_balance=True),
           disturbance=DisturbanceConfig(rate_hz=0.5)),
    Recipe("long+skip+balanced, 2 demos disturbed x2 up to 0.8, 300 epochs", 2, 0, TrainConfig(epochs=300, skip=True, class_balance=True),
           disturbance=DisturbanceConfig(rate_hz=0.3, max_yaw_rate_rps=0.8)),
    Recipe("long+skip+balanced, 2 demos disturbed x2, 300 epochs, mirrored", 2, 0,
           TrainConfig(epochs=300, skip=True, class_balance=True, mirror=True), disturbance=DisturbanceConfig(rate_hz=0.3)),
    Recipe("long+skip+balanced, 2 demos disturbed x2, 500 epochs", 2, 0, TrainConfig(epochs=500, skip=True, class_balance=True),
           disturbance=DisturbanceConfig(rate_hz=0.3)),
    Recipe("long+skip+balanced, 2 demos disturbed x2, 100 epochs, mirrored", 2, 0,
           TrainConfig(epochs=100, skip=True, class_balance=True, mirror=True), disturbance=DisturbanceConfig(rate_hz=0.3)),
    Recipe("long+skip+balanced, 2 demos disturbed x2, 150 epochs, mirrored", 2, 0,
           TrainConfig(epochs=150, skip=True, class_balance=True, mirror=True), disturbance=DisturbanceConfig(rate_hz=0.3)),
    Recipe("ours, hidden width 16", 2, 0, TrainConfig(epochs=300, skip=True, class_balance=True, mirror=True, hidden=16),
           disturbance=DisturbanceConfig(rate_hz=0.3)),
    Recipe("ours, hidden width 256", 2, 0, TrainConfig(epochs=300, skip=True, class_balance=True, mirror=True, hidden=256),
           disturbance=DisturbanceConfig(rate_hz=0.3)),
    Recipe("ours, 3 demos", 3, 0, TrainConfig(epochs=300, skip=True, class_balance=True, mirror=True),
           disturbance=DisturbanceConfig(rate_hz=0.3)),
    Recipe("ours, 4 demos, 150 epochs", 4, 0, TrainConfig(epochs=150, skip=True, class_balance=True, mirror=True),
           disturbance=DisturbanceConfig(rate_hz=0.3)),
    Recipe("ours + 1 correction", 2, 1, TrainConfig(epochs=300, skip=True, class_balance=True, mirror=True),
           disturbance=DisturbanceConfig(rate_hz=0.3)),
    Recipe("ours + 2 corrections", 2, 2, TrainConfig(epochs=300, skip=True, class_balance=True, mirror=True),
           disturbance=DisturbanceConfig(rate_hz=0.3)),
    Recipe("ours, 2 channels per trajectory", 2, 0, TrainConfig(epochs=300, skip=True, class_balance=True, mirror=True, channels=2),
           disturbance=DisturbanceConfig(rate_hz=0.3)),
    Recipe("ours, 4 channels per trajectory", 2, 0, TrainConfig(epochs=300, skip=True, class_balance=True, mirror=True, channels=4),
           disturbance=DisturbanceConfig(rate_hz=0.3)),
    Recipe("ours, decisive x3", 2, 0, TrainConfig(epochs=300, skip=True, class_balance=True, mirror=True, decisive_weight=3.0),
           disturbance=DisturbanceConfig(rate_hz=0.3)),
    Recipe("ours, weight decay 1e-4", 2, 0, TrainConfig(epochs=300, skip=True, class_balance=True, mirror=True, weight_decay=1e-4),
           disturbance=DisturbanceConfig(rate_hz=0.3)),
    Recipe("ours + 1 practice course", 2, 0, TrainConfig(epochs=300, skip=True, class_balance=True, mirror=True),
           disturbance=DisturbanceConfig(rate_hz=0.3), practice=1),
    Recipe("ours + 2 practice courses", 2, 0, TrainConfig(epochs=300, skip=True, class_balance=True, mirror=True),
           disturbance=DisturbanceConfig(rate_hz=0.3), practice=2),
    Recipe("ours + 2 practice courses, 150 epochs", 2, 0, TrainConfig(epochs=150, skip=True, class_balance=True, mirror=True),
           disturbance=DisturbanceConfig(rate_hz=0.3), practice=2),
    Recipe("ours + 2 practice courses + lanes", 2, 0, TrainConfig(epochs=300, skip=True, class_balance=True, mirror=True),
           disturbance=DisturbanceConfig(rate_hz=0.3), practice=2, lane_m=6.0),
    Recipe("ours + 2 practice + lanes, 2 members", 2, 0, TrainConfig(epochs=300, skip=True, class_balance=True, mirror=True, members=2),
           disturbance=DisturbanceConfig(rate_hz=0.3), practice=2, lane_m=6.0),
    Recipe("ours + 2 practice + lanes, 2 members x 150 epochs", 2, 0,
           TrainConfig(epochs=150, skip=True, class_balance=True, mirror=True, members=2),
           disturbance=DisturbanceConfig(rate_hz=0.3), practice=2, lane_m=6.0),
    Recipe("ours, pushed the other way at half the detours, driver follows its side within 10%", 2, 0,
           TrainConfig(epochs=300, skip=True, class_balance=True, mirror=True),
           disturbance=DisturbanceConfig(rate_hz=0.3, counter_share=0.5), follow_margin=0.1),
    Recipe("ours + 2 practice, pushed the other way at half the detours, driver follows its side within 10%", 2, 0,
           TrainConfig(epochs=300, skip=True, class_balance=True, mirror=True),
           disturbance=DisturbanceConfig(rate_hz=0.3, counter_share=0.5), practice=2, follow_margin=0.1),
    Recipe("ours + 2 practice, pushed the other way at half the detours, driver follows its side within 30%", 2, 0,
           TrainConfig(epochs=300, skip=True, class_balance=True, mirror=True),
           disturbance=DisturbanceConfig(rate_hz=0.3, counter_share=0.5), practice=2, follow_margin=0.3),
    Recipe("ours + 2 practice, pushed the other way at a quarter of the detours, driver follows its side within 10%", 2, 0,
           TrainConfig(epochs=300, skip=True, class_balance=True, mirror=True),
           disturbance=DisturbanceConfig(rate_hz=0.3, counter_share=0.25), practice=2, follow_margin=0.1),
    Recipe("ours + second stage (scored by the linear utility fitted with C)", 2, 0,
           TrainConfig(epochs=300, skip=True, class_balance=True, mirror=True, utility=True), disturbance=DisturbanceConfig(rate_hz=0.3)),
]


def main() -> int:
    from terrapref.recipes import run_recipe

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--courses", type=int, default=4)
    parser.add_argument("--only", type=int, nargs="*", help="indices of RECIPES to run")
    parser.add_argument("--first-course", type=int, default=1000,
                        help="seed of the first generated course (1000: selection; 1032: the confirmation courses)")
    args = parser.parse_args()
    courses = [f"gen:{args.first_course + i}" for i in range(args.courses)]
    profile = ("mud", "rock", "water", "non_traversable")
    driver = run_many([RunSpec(c, 0, EXPERT, None, profile) for c in courses])
    fair = {(r["scenario"], z["id"]) for r in driver for z in r["metrics"]["zones"] if z["success"]}
    kind = {(c, z.id): zone_kind(z.label) for c in courses for z in resolve_scenario(c).zones}
    total = sum(len(r["metrics"]["zones"]) for r in driver)
    print(f"validation: {len(courses)} generated courses, {len(fair)}/{total} zones the driver meets")
    for i, recipe in enumerate(RECIPES):
        if args.only and i not in args.only:
            continue
        t0 = time.perf_counter()
        ok = n = collisions = 0
        by_kind = {k: [0, 0] for k in ZONE_KINDS}
        with tempfile.TemporaryDirectory() as tmp:
            for seed in range(args.seeds):
                out = run_recipe(recipe, Path(tmp) / f"s{seed}", seed)
                res = run_many([RunSpec(c, 0, PLANNER, str(out.model), profile, smoothing=recipe.smoothing) for c in courses])
                for r in res:
                    collisions += r["metrics"]["collisions"]
                    for z in r["metrics"]["zones"]:
                        key = (r["scenario"], z["id"])
                        if key in fair:
                            n += 1
                            ok += z["success"]
                            by_kind[kind[key]][0] += z["success"]
                            by_kind[kind[key]][1] += 1
        kinds = ", ".join(f"{k} {a}/{b}" for k, (a, b) in by_kind.items())
        print(f"[{i}] {recipe.name:52s} zone success {ok}/{n} = {ok / max(n, 1):.1%}, collisions {collisions} ({kinds})  ({time.perf_counter() - t0:.0f} s)",
              flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
