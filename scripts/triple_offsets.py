"""How far from the path the planner and its driver go in each triple zone of a selection run.

Reads a `terrapref select` output folder (select.json and the models under work/), drives every
model and the driver it learned from again on the same layouts, and for each triple zone takes
the largest distance of the reference point from the path within ``--window`` metres (along
the path) of the zone's centre. Prints the distribution separately for the zones where the
planner and the driver agree and where they do not (the lab book,
docs/lab/2026-11-25-offset-stage.md, "A closer look at the triples").

    python scripts/triple_offsets.py RUNS/selection [--recipe teach] [--window 3] [--workers 2]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from terrapref.evaluation.runner import EXPERT, PLANNER, RunSpec, run_many
from terrapref.grid import Engine
from terrapref.report.select import job_folder
from terrapref.scenario import resolve_scenario
from terrapref.scenario.generate import zone_kind
from terrapref.scenario.path import ReferencePath

STRADDLE_M = (0.5, 1.5)  # a distance from the path that leaves the footprint across a middle patch's edge


class Layout:
    """One layout's reference path and where along it each triple zone's centre lies."""

    def __init__(self, course: str) -> None:
        scenario = resolve_scenario(course)
        self.path = ReferencePath(scenario.waypoints)
        self.triples: dict[str, float] = {}  # zone id -> arc length of its centre [m]
        for zone in scenario.zones:
            if zone_kind(zone.label) == "triple":
                centre = zone.shape.vertices.mean(axis=0) if hasattr(zone.shape, "vertices") else np.asarray(zone.shape.center)
                self.triples[zone.id] = self.path.project(np.asarray(centre, dtype=float))[0]

    def largest_offsets(self, xy: np.ndarray, window_m: float) -> dict[str, float]:
        """Per triple zone: the largest |distance from the path| [m] of ``xy`` within ``window_m`` of the zone's centre."""
        along = np.array([self.path.project(p) for p in xy])  # (T, 2): arc length, signed distance
        out = {}
        for zone, s0 in self.triples.items():
            near = np.abs(along[:, 0] - s0) <= window_m
            out[zone] = float(np.abs(along[near, 1]).max()) if near.any() else float("nan")
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
    seed_of: dict[str, int] = {}  # model file -> its training seed
    specs = []
    for order in map(tuple, sel["orders"]):
        for seed in range(sel["seeds"]):
            model = str(job_folder(args.selection, order, seed) / args.recipe / "model.safetensors")
            seed_of[model] = seed
            specs += [RunSpec(c, 0, PLANNER, model, order) for c in layouts]
    specs += [RunSpec(c, 0, EXPERT, None, tuple(o), style=style) for o in sel["orders"] for c in layouts]
    results = run_many(specs, engine=Engine(workers=args.workers))
    courses = {c: Layout(c) for c in layouts}
    driver = {
        (s.profile, s.scenario): courses[s.scenario].largest_offsets(r.xy, args.window)
        for s, r in zip(specs, results, strict=True)
        if s.driver == EXPERT
    }
    groups: dict[bool, list[tuple[float, float]]] = {True: [], False: []}
    for spec, r in zip(specs, results, strict=True):
        if spec.driver != PLANNER:
            continue
        for zone, offset in courses[spec.scenario].largest_offsets(r.xy, args.window).items():
            groups[agrees[(spec.profile, seed_of[spec.model_path], spec.scenario, zone)]].append(
                (driver[(spec.profile, spec.scenario)][zone], offset)
            )
    lo, hi = STRADDLE_M
    print(f"| triple zones | driver: median (quartiles) | driver between {lo} and {hi} m | planner: median (quartiles) |")
    print("|---|---|---|---|")
    for agree, label in ((False, "disagree"), (True, "agree")):
        a = np.array(groups[agree]).reshape(-1, 2)
        if not len(a):
            continue
        d, p = np.percentile(a[:, 0], [50, 25, 75]), np.percentile(a[:, 1], [50, 25, 75])
        straddle = int(((a[:, 0] >= lo) & (a[:, 0] <= hi)).sum())
        print(
            f"| the {len(a)} where they {label} | {d[0]:.2f} m ({d[1]:.2f}-{d[2]:.2f}) | {straddle} of {len(a)} "
            f"| {p[0]:.2f} m ({p[1]:.2f}-{p[2]:.2f}) |"
        )


if __name__ == "__main__":
    main()
