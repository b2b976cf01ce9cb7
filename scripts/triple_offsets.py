"""How far from the path the planner and its driver go in each triple zone of a selection run.

Reads a `terrapref select` output folder (select.json and the models under work/), drives every
model and the driver it learned from again on the same layouts, and for each triple zone takes
the largest distance of the reference point from the path within ``--window`` metres (along
the path) of the zone's centre. Prints the distribution separately for the zones where the
planner and the driver agree and where they do not (docs/learning.md, "A closer look at the
triples").

    python scripts/triple_offsets.py RUNS/selection [--recipe teach] [--window 3] [--workers 2]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from terrapref.evaluation.runner import EXPERT, PLANNER, RunSpec, run_many
from terrapref.grid import Engine
from terrapref.scenario import resolve_scenario
from terrapref.scenario.generate import zone_kind
from terrapref.scenario.path import ReferencePath

STRADDLE_M = (0.5, 1.5)  # a distance from the path that leaves the footprint across a middle patch's edge


def largest_offsets(course: str, xy: np.ndarray, window_m: float) -> dict[str, float]:
    """Per triple zone of ``course``: the largest |distance from the path| [m] of ``xy`` within ``window_m`` of the zone's centre."""
    scenario = resolve_scenario(course)
    path = ReferencePath(scenario.waypoints)
    along = np.array([path.project(p) for p in xy])  # (T, 2): arc length, signed distance
    out = {}
    for zone in scenario.zones:
        if zone_kind(zone.label) != "triple":
            continue
        centre = zone.shape.vertices.mean(axis=0) if hasattr(zone.shape, "vertices") else np.asarray(zone.shape.center)
        s0, _ = path.project(np.asarray(centre, dtype=float))
        near = np.abs(along[:, 0] - s0) <= window_m
        out[zone.id] = float(np.abs(along[near, 1]).max()) if near.any() else float("nan")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("selection", type=Path, help="a terrapref select --out folder")
    ap.add_argument("--recipe", default="teach")
    ap.add_argument("--window", type=float, default=3.0, help="metres along the path on either side of a zone's centre")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()

    saved = json.loads((args.selection / "select.json").read_text())
    sel = saved["selection"]
    layouts, style = sel["layouts"], sel.get("style", "default")
    rows = [r for r in saved["zones"] if r["recipe"] == args.recipe and r["kind"] == "triple"]
    agrees = {(tuple(r["order"]), r["seed"], r["scenario"], r["zone"]): r["agrees"] for r in rows}
    specs = []
    for order in map(tuple, sel["orders"]):
        job = "_".join(c[:2] for c in order[:3])
        for seed in range(sel["seeds"]):
            model = args.selection / "work" / f"{job}_s{seed}" / args.recipe / "model.safetensors"
            specs += [RunSpec(c, 0, PLANNER, str(model), order) for c in layouts]
    specs += [RunSpec(c, 0, EXPERT, None, tuple(o), style=style) for o in sel["orders"] for c in layouts]
    results = run_many(specs, engine=Engine(workers=args.workers))
    driver = {(s.profile, s.scenario): largest_offsets(s.scenario, r.xy, args.window)
              for s, r in zip(specs, results, strict=True) if s.driver == EXPERT}
    groups: dict[bool, list[tuple[float, float]]] = {True: [], False: []}
    for spec, r in zip(specs, results, strict=True):
        if spec.driver != PLANNER:
            continue
        seed = int(Path(spec.model_path).parent.parent.name.rsplit("_s", 1)[1])
        for zone, offset in largest_offsets(spec.scenario, r.xy, args.window).items():
            groups[agrees[(spec.profile, seed, spec.scenario, zone)]].append((driver[(spec.profile, spec.scenario)][zone], offset))
    lo, hi = STRADDLE_M
    print(f"| triple zones | driver: median (quartiles) | driver between {lo} and {hi} m | planner: median (quartiles) |")
    print("|---|---|---|---|")
    for agree, label in ((False, "disagree"), (True, "agree")):
        a = np.array(groups[agree]).reshape(-1, 2)
        if not len(a):
            continue
        d, p = np.percentile(a[:, 0], [50, 25, 75]), np.percentile(a[:, 1], [50, 25, 75])
        straddle = int(((a[:, 0] >= lo) & (a[:, 0] <= hi)).sum())
        print(f"| the {len(a)} where they {label} | {d[0]:.2f} m ({d[1]:.2f}-{d[2]:.2f}) | {straddle} of {len(a)} "
              f"| {p[0]:.2f} m ({p[1]:.2f}-{p[2]:.2f}) |")


if __name__ == "__main__":
    main()
