"""Does a keyboard demonstration teach as well as a stick? One drive of teach_course each way.

For every training seed, the same synthetic driver (default style, the paper's order unless
--profile says otherwise) demonstrates teach_course twice, with the recommended pushes of the
default recipe:

- *stick*: its own continuous stick (``terrapref record``);
- *keyboard*: through the teleop window's own event handling (SDL's dummy video driver), as a
  person at a keyboard would: it wants what the driver wants (its intent), reacts 0.3 s later,
  and can only hold Left/Right (a step at the press, then gently on) or tap Down
  (terrapref.teleop.keyboard); with ``--speeds`` it also works the throttle (W/S) toward the
  speed the driver wants.

A model is trained from each drive with the default recipe, and every model and the driver drive
the generated layouts. Reported per input: zone success and agreement with the driver, with 95%
Wilson intervals over all zones, and collisions; with ``--speeds`` (a driver of cruising speeds
by class, as ``terrapref record --speeds`` takes them), also each input's speed against the
driver's (``terrapref evaluate``'s speed error per class and time to the end of the path).

    .venv/bin/python scripts/keyboard_demo.py --out runs/keyboard                  # 5 seeds x gen:2000-2031
    .venv/bin/python scripts/keyboard_demo.py --seeds 1 --courses 4 --out runs/kb_smoke
    .venv/bin/python scripts/keyboard_demo.py --profile rock,mud,water,non_traversable \
        --speeds grass=1.6,rock=1.0,mud=0.5,water=0.3 --out runs/kb_speed       # the throttle too

Writes KEYBOARD.md, keyboard.json (every zone) and keyboard.png.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("SDL_AUDIODRIVER", "dummy")

import numpy as np  # noqa: E402

from terrapref.dataset import build_dataset  # noqa: E402
from terrapref.demos.recording import read_recording  # noqa: E402
from terrapref.demos.speed_style import parse_speeds  # noqa: E402
from terrapref.errors import UserError  # noqa: E402
from terrapref.evaluation.runner import EXPERT, PLANNER, RunResult, RunSpec, run_many, zone_agrees  # noqa: E402
from terrapref.evaluation.speed import SpeedComparison, run_fields  # noqa: E402
from terrapref.evaluation.stats import rate_text, wilson  # noqa: E402
from terrapref.grid import Engine, run_grid  # noqa: E402
from terrapref.learning.pipeline import RunOptions, train_and_save  # noqa: E402
from terrapref.plots import RateRow, save_intervals  # noqa: E402
from terrapref.recipes import DEFAULT_RECIPE, RecipeSetup, recipe_named, record_demonstrations  # noqa: E402
from terrapref.scenario import resolve_scenario  # noqa: E402
from terrapref.terrain import PreferenceProfile, default_classes  # noqa: E402

INPUTS = ("stick", "keyboard")
BACKGROUND = default_classes().background  # the zones passed by count for it in the speed comparison


Speeds = tuple[tuple[str, float], ...]


def _demonstrate(job: tuple[str, str, int, tuple[str, ...], Speeds]) -> tuple[str, str, int, float, str]:
    """One drive and its model: (input, model path, seed, seconds, recording folder)."""
    kind, workdir, seed, order, speeds = job
    t0 = time.perf_counter()
    recipe = recipe_named(DEFAULT_RECIPE)
    profile = PreferenceProfile(order)
    work = Path(workdir)
    if kind == "stick":
        rec = record_demonstrations(recipe, work, RecipeSetup(seed, profile, speeds=speeds))[0]
    else:
        from terrapref.demos.expert import ExpertConfig, ExpertDriver
        from terrapref.teleop import run_teleop
        from terrapref.teleop.keyboard import KeyboardPerson

        scenario = resolve_scenario(recipe.course)
        rec = work / "demo_keyboard"
        person = KeyboardPerson(ExpertDriver(ExpertConfig.styled("default", order, speeds)), scenario, np.random.default_rng(seed * 100))
        # Pushes with the default recipe's protocol (recipe.disturbance), drawn from their own
        # stream: the same kind of pushes as the stick's drive, not at the same moments.
        run_teleop(
            scenario, rec, overwrite=True, realtime=False, script=person, disturbance=recipe.disturbance, seed=seed * 100, profile=profile
        )
    model = work / f"model_{kind}.safetensors"
    train_and_save(
        build_dataset([read_recording(rec)], recipe.features(), rules=recipe.rules),
        model,
        replace(recipe.train, seed=seed),
        rules=recipe.rules,
        recipe=recipe.name,
        options=RunOptions(checkpoints=False),
    )
    return kind, str(model), seed, time.perf_counter() - t0, str(rec)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--profile", default="mud,rock,water,non_traversable")
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--first", type=int, default=2000, help="first generated layout")
    ap.add_argument("--courses", type=int, default=32)
    ap.add_argument("--speeds", help="the driver's cruising speeds by class, e.g. grass=1.6,rock=1.0,mud=0.5,water=0.3 (default: 1 m/s)")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    args = ap.parse_args(argv)
    order = tuple(args.profile.split(","))
    try:
        speeds = parse_speeds(args.speeds) if args.speeds else ()
    except UserError as e:
        ap.error(str(e))
    layouts = [f"gen:{args.first + i}" for i in range(args.courses)]
    args.out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    jobs = [(kind, str(args.out / "work" / f"{kind}_s{s}"), s, order, speeds) for s in range(args.seeds) for kind in INPUTS]
    done = run_grid(
        _demonstrate,
        jobs,
        Engine(workers=args.workers),
        lambda k, n: print(f"demonstrated and trained {k}/{n}", file=sys.stderr, flush=True),
        describe=lambda j: f"{j[0]} drive, seed {j[2]}",
    )
    models = {(kind, seed): model for kind, model, seed, _, _ in done}
    recordings = {(kind, seed): rec for kind, _, seed, _, rec in done}
    t_train = time.perf_counter() - t0

    keys = sorted(models)
    specs = [RunSpec(c, 0, PLANNER, models[key], order) for key in keys for c in layouts]
    specs += [RunSpec(c, 0, EXPERT, None, order, speeds=speeds) for c in layouts]
    results = run_many(
        specs, args.workers, lambda k, n: print(f"run {k}/{n}", file=sys.stderr, flush=True) if k % 20 == 0 or k == n else None
    )
    t_eval = time.perf_counter() - t0 - t_train

    rows, collisions, runs = _zone_rows(specs, results, {models[key]: key for key in keys})
    drives = _drives(recordings)
    speed = (
        {
            kind: SpeedComparison.of([r for r in rows if r["input"] == kind], [r for r in runs if r["input"] == kind], BACKGROUND)
            for kind in INPUTS
        }
        if speeds
        else None
    )
    (args.out / "keyboard.json").write_text(
        json.dumps(
            {
                "profile": order,
                "layouts": layouts,
                "zones": rows,
                "collisions": collisions,
                "drives": drives,
                "speeds": dict(speeds),
                "speed": None if speed is None else {kind: c.to_dict() for kind, c in speed.items()},
                "train_s": t_train,
                "eval_s": t_eval,
            },
            indent=0,
        )
    )
    write_report(args.out, order, layouts, rows, collisions, drives, t_train, t_eval, args.workers, speed, speeds)
    return 0


def _zone_rows(
    specs: list[RunSpec], results: list[RunResult], kind_of: dict[str, tuple[str, int]]
) -> tuple[list[dict], dict[str, int], list[dict]]:
    """Every planner zone beside the driver's choice in the same zone (keyboard.json's rows), each
    input's collisions, and every planner run beside the driver's (what SpeedComparison reads)."""
    driver_runs = {r.scenario: r for r in results if r.driver == EXPERT}
    driver = {(r.scenario, z.id): z for r in driver_runs.values() for z in r.metrics.zones}
    rows, runs = [], []
    collisions = dict.fromkeys(INPUTS, 0)
    for spec, r in zip(specs, results, strict=True):
        if r.driver != PLANNER:
            continue
        kind, seed = kind_of[spec.model_path]
        collisions[kind] += r.metrics.collisions
        runs.append({"input": kind, "scenario": r.scenario, **run_fields(r.metrics, driver_runs[r.scenario].metrics)})
        for z in r.metrics.zones:
            d = driver[(r.scenario, z.id)]
            rows.append(
                {
                    "input": kind,
                    "seed": seed,
                    "scenario": r.scenario,
                    "zone": z.id,
                    "choice": z.choice,
                    "driver_choice": d.choice,
                    "agrees": zone_agrees(z, d),
                    "success": z.success,
                    "speed_mps": z.speed_mps,
                    "driver_speed_mps": d.speed_mps,
                }
            )
    return rows, collisions, runs


def _drives(recordings: dict[tuple[str, int], str]) -> dict[str, dict]:
    """Each demonstration drive: its frames, minutes, share of frames driven straight (w = 0) and collisions."""
    drives = {}
    for key in sorted(recordings):
        kind, seed = key
        rec = read_recording(recordings[key])
        v, w = rec.commands[:, 0], rec.commands[:, 1]
        drives[f"{kind}_s{seed}"] = {
            "frames": len(rec),
            "minutes": rec.duration_s / 60,
            "straight_share": float(np.mean(w == 0.0)),
            "speeds_mps": [float(np.min(v)), float(np.max(v))],
            "collisions": rec.meta.get("summary", {}).get("collisions"),
        }
    return drives


def write_report(
    out: Path,
    order,
    layouts,
    rows,
    collisions,
    drives,
    t_train: float,
    t_eval: float,
    workers: int,
    speed: dict[str, SpeedComparison] | None = None,
    speeds: Speeds = (),
) -> None:
    seeds = sorted({r["seed"] for r in rows})
    at = f", cruising at {', '.join(f'{name} {mps:g}' for name, mps in speeds)} m/s" if speeds else ""
    lines = [
        "# A keyboard demonstration against a stick: one drive of teach_course each",
        "",
        f"Driver: the synthetic driver, default style{at}, order {' > '.join(order)}; {len(seeds)} training seed(s); every model "
        f"drives {len(layouts)} generated layouts ({layouts[0]} to {layouts[-1]}). Rates with 95% Wilson intervals over all zones.",
        "",
        "| demonstration | zone success | agreement with the driver | collisions | drive: frames at w = 0 | drive: collisions | per seed (agreement) |",
        "|---|---|---|---|---|---|---|",
    ]
    points = []
    for kind in INPUTS:
        sel = [r for r in rows if r["input"] == kind]
        if not sel:
            continue
        ds = [d for k, d in drives.items() if k.startswith(kind + "_")]
        per_seed = ", ".join(f"{np.mean([r['agrees'] for r in sel if r['seed'] == s]):.0%}" for s in seeds)
        lines.append(
            f"| {kind} | {rate_text(sum(r['success'] for r in sel), len(sel))} | {rate_text(sum(r['agrees'] for r in sel), len(sel))} | "
            f"{collisions[kind]} | {np.mean([d['straight_share'] for d in ds]):.0%} | "
            f"{sum(d['collisions'] or 0 for d in ds)} | {per_seed} |"
        )
        for key, name in (("success", "zone success"), ("agrees", "agreement")):
            ok = sum(r[key] for r in sel)
            points.append(RateRow(f"{kind}: {name}", ok / len(sel), wilson(ok, len(sel))))
    if speed is not None:
        lines += ["", "Speed against the driver's (95% intervals resampling layouts):", ""]
        for kind, comparison in speed.items():
            lines += [f"- {kind}: {line}" for line in comparison.lines()]
    lines += [
        "",
        f"Demonstrating and training {t_train:.0f} s, evaluation {t_eval:.0f} s (wall, {workers} workers).",
        "",
        "![keyboard](keyboard.png)",
        "",
    ]
    save_intervals(
        out / "keyboard.png",
        points,
        "share of zones",
        target=0.95,
        title=f"stick or keyboard, one drive each: {len(layouts)} layouts x {len(seeds)} seeds, 95% CI",
    )
    (out / "KEYBOARD.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    sys.exit(main())
