"""Route + local planner against the driver, on layouts where a wide patch blocks the path.

Each layout lays one patch of mud, rock or water across a straight path, reaching 2.2-4 m to
one side of it (beyond the offsets the local planner weighs, 2.4 m less half the vehicle's
width) and 5-8 m to the other, 6-16 m long; on some, trees stand beyond the near edge, closing
that way round. The synthetic driver, whose offsets reach 8 m, drives each layout with each
preference order: it crosses the patch or goes round it, on one side. Each model of a selection
(`terrapref select --out SELECTION`, recipe teach) then drives the layout twice: along the
path, and along the route `terrapref route` plans over the layout with that model. A run goes
round when its footprint clears the patch along the middle third of the patch's length.

Prints, for the planner with and without the route, how often it does as the driver did
(through, round left, round right), with Wilson 95% intervals, the same split by the driver's
choice, and writes route_study.json and route_study.png in --out.

    python scripts/route_study.py SELECTION --out runs/route_study [--first 3000] [--layouts 16] [--seeds 5] [--workers 2]
"""

from __future__ import annotations

import argparse
import json
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import matplotlib
import numpy as np
import yaml

from terrapref.evaluation.runner import EXPERT, PLANNER, RunSpec, run_many
from terrapref.evaluation.stats import wilson
from terrapref.grid import Engine
from terrapref.report.select import job_folder

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

Y_PATH, LENGTH = 15.0, 80.0
OUTCOMES = ("through", "round left", "round right")


def layout(seed: int) -> dict:
    """The scenario mapping of detour layout ``seed`` (module docstring), and its patch as
    (x0, x1, y0, y1) under ``"patch"``."""
    rng = np.random.default_rng(seed)
    cls = str(rng.choice(["mud", "rock", "water"]))
    depth, near, far = rng.uniform(6.0, 16.0), rng.uniform(2.2, 4.0), rng.uniform(5.0, 8.0)
    side = 1.0 if rng.random() < 0.5 else -1.0  # the near edge's side: +1 left of the path
    x0 = 30.0
    edges = sorted((Y_PATH + side * near, Y_PATH - side * far))
    terrain = [{"class": cls, "rectangle": {"center": [x0 + depth / 2, sum(edges) / 2], "size": [depth, edges[1] - edges[0]]}}]
    if rng.random() < 0.3:  # trees beyond the near edge: that way round is closed
        y = Y_PATH + side * (near + 1.0 + 1.5)
        terrain.append({"class": "non_traversable", "rectangle": {"center": [x0 + depth / 2, y], "size": [depth + 4.0, 3.0]}})
    return {
        "format": "terrapref-scenario/1",
        "name": f"detour_{seed}",
        "description": f"{cls} {depth:.1f} m long across the path, {near:.1f} m to one side and {far:.1f} m to the other",
        "world": {"size_m": [LENGTH, 2 * Y_PATH], "resolution_m": 0.05, "background": "grass"},
        "terrain": terrain,
        "path": {"waypoints": [[5.0, Y_PATH], [LENGTH - 5.0, Y_PATH]]},
        "patch": [x0, x0 + depth, edges[0], edges[1]],
    }


HALF_WIDTH_M = 0.6  # the vehicle's footprint: a run goes round only when all of it clears the patch


def outcome(xy: np.ndarray, patch: list[float]) -> str:
    """Through the patch, or round it on the left or the right of the path: where the reference
    point runs along the middle third of the patch's length (a driver that decides late clips
    the near corner on its way round). Round only when the footprint clears the patch there;
    a vehicle with a wheel in the patch crossed it."""
    x0, x1, y0, y1 = patch
    third = (x1 - x0) / 3
    middle = (xy[:, 0] >= x0 + third) & (xy[:, 0] <= x1 - third)
    if not middle.any():
        return "through"  # the run ended before the patch: counted as not going round
    y = float(np.median(xy[middle, 1]))
    if y0 - HALF_WIDTH_M < y < y1 + HALF_WIDTH_M:
        return "through"
    return "round left" if y > Y_PATH else "round right"


def _route(job: tuple[str, str, str]) -> str:
    """Plan the route of one (model, layout file, route file) as `terrapref route` does; the route file's name."""
    import contextlib
    import io

    from terrapref.cli import main as terrapref

    model, scenario, out = job
    with contextlib.redirect_stdout(io.StringIO()):
        if terrapref(["route", scenario, "--model", model, "--out", out]) != 0:
            raise RuntimeError(f"terrapref route {scenario} --model {model} failed")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("selection", type=Path, help="a terrapref select --out folder with recipe teach")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--first", type=int, default=3000, help="first layout seed")
    ap.add_argument("--layouts", type=int, default=16)
    ap.add_argument("--seeds", type=int, default=5, help="training seeds per order to use from the selection")
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()

    sel = json.loads((args.selection / "select.json").read_text())["selection"]
    orders = [tuple(o) for o in sel["orders"]]
    (args.out / "layouts").mkdir(parents=True, exist_ok=True)
    (args.out / "routes").mkdir(exist_ok=True)
    patches = {}
    for seed in range(args.first, args.first + args.layouts):
        data = layout(seed)
        patches[seed] = data.pop("patch")
        (args.out / "layouts" / f"detour_{seed}.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    models = {(o, s): str(job_folder(args.selection, o, s) / "teach" / "model.safetensors") for o in orders for s in range(args.seeds)}
    jobs = [
        (
            models[o, s],
            str(args.out / "layouts" / f"detour_{n}.yaml"),
            str(args.out / "routes" / f"{'_'.join(c[:2] for c in o[:3])}_s{s}_{n}.yaml"),
        )
        for (o, s) in models
        for n in patches
    ]
    todo = [j for j in jobs if not Path(j[2]).exists()]  # routes planned by an earlier run of the study are kept
    with ProcessPoolExecutor(args.workers) as pool:
        for i, _ in enumerate(pool.map(_route, todo), 1):
            if i % 20 == 0 or i == len(todo):
                print(f"routes {i}/{len(todo)}", flush=True)
    specs, keys = [], []
    for o in orders:
        for n in patches:
            specs.append(RunSpec(str(args.out / "layouts" / f"detour_{n}.yaml"), 0, EXPERT, None, o))
            keys.append(("driver", o, None, n))
    for (o, s), model in models.items():
        for n in patches:
            job = next(j for j in jobs if j[0] == model and j[1].endswith(f"detour_{n}.yaml"))
            specs += [RunSpec(job[1], 0, PLANNER, model, o), RunSpec(job[2], 0, PLANNER, model, o)]
            keys += [("path", o, s, n), ("route", o, s, n)]
    results = run_many(
        specs,
        engine=Engine(workers=args.workers),
        progress=lambda d, t: print(f"runs {d}/{t}", flush=True) if d % 50 == 0 or d == t else None,
    )
    got = {k: outcome(r.xy, patches[k[3]]) for k, r in zip(keys, results, strict=True)}
    rows = [
        {
            "order": list(o),
            "seed": s,
            "layout": n,
            "driver": got["driver", o, None, n],
            "path": got["path", o, s, n],
            "route": got["route", o, s, n],
        }
        for (o, s) in models
        for n in patches
    ]
    summary = {}
    for way in ("path", "route"):
        for label, subset in (
            ("all", rows),
            ("driver went round", [r for r in rows if r["driver"] != "through"]),
            ("driver went through", [r for r in rows if r["driver"] == "through"]),
        ):
            agree = sum(r[way] == r["driver"] for r in subset)
            lo, hi = wilson(agree, len(subset)) if subset else (float("nan"), float("nan"))
            summary[f"{way}: {label}"] = {"agree": agree, "of": len(subset), "ci": [lo, hi]}
            print(
                f"planner along the {way:5s} | {label:20s} | {agree}/{len(subset)} = {100 * agree / max(len(subset), 1):.1f}% "
                f"(95% CI {100 * lo:.1f}-{100 * hi:.1f}%)"
            )
    (args.out / "route_study.json").write_text(json.dumps({"summary": summary, "runs": rows}, indent=1))
    _figure(args.out / "route_study.png", summary)
    print(f"wrote {args.out / 'route_study.json'} and {args.out / 'route_study.png'}")


def _figure(path: Path, summary: dict) -> None:
    """Agreement with the driver, with and without the route, by what the driver did."""
    labels = ("all", "driver went round", "driver went through")
    fig, ax = plt.subplots(figsize=(7.5, 3.4), dpi=120)
    for k, (way, colour) in enumerate((("path", "tab:grey"), ("route", "tab:blue"))):
        vals = [summary[f"{way}: {lab}"] for lab in labels]
        share = np.array([100 * v["agree"] / max(v["of"], 1) for v in vals])
        err = np.array([[share[i] - 100 * v["ci"][0], 100 * v["ci"][1] - share[i]] for i, v in enumerate(vals)]).T
        x = np.arange(len(labels)) + (k - 0.5) * 0.38
        ax.bar(x, share, 0.36, yerr=err, capsize=3, color=colour, label=f"planner along the {way}")
        for xi, v, sh in zip(x, vals, share):
            ax.text(xi, 2, f"{sh:.0f}%\n{v['agree']}/{v['of']}", ha="center", va="bottom", fontsize=7, color="white")
    ax.set_xticks(np.arange(len(labels)), labels)
    ax.set_ylabel("does as the driver did (%)")
    ax.set_ylim(0, 122)
    ax.set_yticks(range(0, 101, 20))
    ax.legend(fontsize=8, loc="upper center", ncol=2, frameon=False)
    ax.set_title("a wide patch across the path: through it, or round it on the driver's side")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


if __name__ == "__main__":
    main()
