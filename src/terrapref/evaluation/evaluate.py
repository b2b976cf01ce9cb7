"""`terrapref evaluate`: closed-loop runs of a model over scenarios and seeds, metrics.json and figures."""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from terrapref.camera import PinholeCamera
from terrapref.errors import UserError
from terrapref.fileio import write_text_atomic
from terrapref.grid import Engine
from terrapref.evaluation.runner import EXPERT, PLANNER, RunSpec, annotate_agreement, run_many, scenario_and_world, summarise
from terrapref.evaluation.scoring import classes_in_zone
from terrapref.learning.identify import GRASS, Identifiability
from terrapref.features import PreferenceSet
from terrapref.evaluation.policies import load_policy
from terrapref.scenario import AVOID, resolve_scenario
from terrapref.terrain import PreferenceProfile
from terrapref.vehicle import Pose
from terrapref.world import rasterise


def evaluate_model(
    model_path: str,
    scenarios: Sequence[str],
    seeds: int,
    out_dir: str | Path,
    profile: PreferenceProfile | None = None,
    with_driver: bool = True,
    frames: Sequence[int] = (),
    engine: Engine | None = None,
    progress: Callable[[int, int], None] | None = None,
    style: str = "default",
    mcap: bool = False,
) -> dict:
    """Drive every scenario with the planner (and the synthetic driver) for seeds 0..N-1.

    ``best`` zones resolve under the model's profile unless ``profile`` overrides it. Each
    planner zone gets the choice the driver (of ``style``) made in the same run and whether the
    planner agreed (SPEC 12), and, when the model's demonstrations left a pair of classes
    unidentified (terrapref.learning.identify), the pairs its expected choice rests on.
    Writes ``metrics.json``, one top-down figure per scenario and the decision pictures of
    ``frames`` (for seed 0) into ``out_dir``, and with ``mcap`` every planner run as ROS 2 MCAP
    (``runs/SCENARIO_seedN.mcap``: the camera, the pose, the 21 trajectories and the one chosen);
    returns the metrics. ``engine``: where the runs go (default: local processes, one per core).
    """
    model = load_policy(model_path)  # C, or a learned baseline (linear, CNN)
    for name in scenarios:
        resolve_scenario(name)  # fail early, with the file and field, before any run
    profile = profile or PreferenceProfile.parse(list(model.profile), model.classes, source=f"{model_path}: profile")
    specs = [RunSpec(name, seed, PLANNER, model_path, profile.order, tuple(frames) if seed == 0 else (), keep_run=mcap) for name in scenarios for seed in range(seeds)]
    if with_driver:
        specs += [RunSpec(name, seed, EXPERT, None, profile.order, style=style) for name in scenarios for seed in range(seeds)]
    results = run_many(specs, progress=progress, engine=engine)
    annotate_agreement(results)
    identified = _identifiability(model)
    if identified is not None:
        for name in scenarios:
            _mark_unidentified(results, name, identified)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    metrics: dict = {
        "model": str(model_path),
        "profile": list(profile.order),
        "seeds": seeds,
        "driver_style": style,
        "unidentified_pairs": [f"{p.first} vs {p.second}" for p in identified.unidentified()] if identified is not None else None,
        "scenarios": {},
        "summary": summarise(results, PLANNER),
    }
    if with_driver:
        metrics["driver_summary"] = summarise(results, EXPERT)
    for name in scenarios:
        entry: dict = {}
        for r in results:
            if r["scenario"] == name:
                entry.setdefault(r["driver"], {})[str(r["seed"])] = r["metrics"]
        metrics["scenarios"][name] = entry
    _figures(results, scenarios, out, model, profile)
    if mcap:
        _write_runs(results, out / "runs", model)
    write_text_atomic(out / "metrics.json", json.dumps(metrics, indent=2))
    return metrics


def _write_runs(results: list[dict], folder: Path, model) -> None:
    """Each planner run as an MCAP file, its camera frames rendered again at the poses driven."""
    from terrapref.camera import SegmentationRenderer
    from terrapref.interop.mcap_export import RunFrames, write_mcap

    camera = PinholeCamera(model.camera)
    for r in results:
        run = r.get("run")
        if r["driver"] != PLANNER or run is None:
            continue
        scenario, world = scenario_and_world(r["scenario"])  # cached: the runs of one course share a raster
        renderer = SegmentationRenderer(camera, world)
        poses = run["poses"]
        frames = RunFrames(times=0.1 * np.arange(len(poses)), poses=poses, commands=run["commands"],
                           image=lambda i, poses=poses, renderer=renderer: renderer.render(Pose(*poses[i])), chosen=run["index"],
                           path=scenario.waypoints, camera=model.camera, classes=model.classes, preference=model.features.preference, probs=run["probs"])
        write_mcap(folder / f"{r['scenario'].replace(':', '_')}_seed{r['seed']}.mcap", frames, robot_file=False)


def _identifiability(model) -> Identifiability | None:
    """What the model's demonstrations showed, if its file says (models trained before it was stored do not)."""
    data = getattr(getattr(model, "model", None), "meta", {}).get("identifiability")
    try:
        return Identifiability.from_dict(data) if data else None
    except (KeyError, TypeError, ValueError, IndexError):
        raise UserError(model.path, "malformed identifiability report", field="identifiability") from None


def rests_on(expect: str, present: Sequence[str], identified: Identifiability) -> list[str]:
    """The unidentified pairs a zone's expected choice depends on: the expected class against
    every other class present (or grass against them all, for ``avoid``)."""
    best = GRASS if expect == AVOID else expect
    pairs = [identified.pair(best, other) for other in present if other != best]
    if expect != AVOID:
        pairs.append(identified.pair(best, GRASS))
    return sorted({f"{p.first} vs {p.second}" for p in pairs if p is not None and not p.identified})


def _mark_unidentified(results: list[dict], name: str, identified: Identifiability) -> None:
    scenario = resolve_scenario(name)
    world = rasterise(scenario)
    present = {z.id: classes_in_zone(z, world) for z in scenario.zones}
    for r in results:
        if r["scenario"] == name and r["driver"] == PLANNER:
            for z in r["metrics"]["zones"]:
                z["rests_on_unidentified"] = rests_on(z["expect"], present[z["id"]], identified)


def _figures(results: list[dict], scenarios: Sequence[str], out: Path, model, profile: PreferenceProfile) -> None:
    from terrapref.plots import save_decision, save_evaluation

    pset = PreferenceSet(model.features.preference, PinholeCamera(model.camera))
    uv, visible = pset.camera.project_ground(pset.trajectories[..., :2])
    for name in scenarios:
        scenario, world = scenario_and_world(name)  # the raster the runs used, not a new one
        planner_runs = [r for r in results if r["scenario"] == name and r["driver"] == PLANNER]
        driver_runs = [r for r in results if r["scenario"] == name and r["driver"] == EXPERT]
        per_zone: dict[str, tuple[int, int]] = {}
        for r in planner_runs:
            for z in r["metrics"]["zones"]:
                ok, n = per_zone.get(z["id"], (0, 0))
                per_zone[z["id"]] = (ok + bool(z["success"]), n + 1)
        ok = sum(v[0] for v in per_zone.values())
        n = sum(v[1] for v in per_zone.values())
        save_evaluation(out / f"{name}.png", scenario, world, [r["xy"] for r in driver_runs], [r["xy"] for r in planner_runs], per_zone,
                        title=f"{name}: planner zone success {ok}/{n} over {len(planner_runs)} run(s), profile {profile}")
        for r in planner_runs:
            for i, f in r.get("frames", {}).items():
                rgb = model.classes.palette()[f["image"]]
                x, y, yaw = f["pose"]
                save_decision(out / f"{name}_frame{int(i):05d}.png", rgb, uv, visible, f["probs"], f["index"],
                              model.features.preference.control.w_rps, classes=model.classes,
                              title=f"{name}, frame {i}, pose ({x:.1f} m, {y:.1f} m, yaw {np.degrees(yaw):.0f} deg)")
