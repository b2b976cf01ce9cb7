"""Closed-loop evaluation: drive scenarios with the planner (and the synthetic driver for
comparison) over seeds, score every zone (SPEC 12), and collect the paths for figures.

Each (scenario, seed, driver) run is independent, so runs are spread over worker processes
or a Ray cluster (terrapref.grid).
Seed 0 starts exactly at the scenario's start; other seeds start up to 0.3 m to the side and
3 degrees off, and seed the synthetic driver's noise.
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from terrapref.demos.expert import ExpertConfig, ExpertDriver
from terrapref.evaluation.scoring import score_run
from terrapref.evaluation.stats import wilson
from terrapref.evaluation.perturb import PerturbedDriver, Perturbation
from terrapref.grid import Engine, run_grid
from terrapref.planner import Planner, PlannerDriver
from terrapref.evaluation.policies import load_policy
from terrapref.planner.policy import CostPolicy, Policy, PurePursuitPolicy
from terrapref.scenario import resolve_scenario
from terrapref.sim import Simulation, run_episode
from terrapref.terrain import PreferenceProfile
from terrapref.vehicle import Pose
from terrapref.world import rasterise

PLANNER = "planner"  # a model file: C, or a learned baseline (linear, CNN)
EXPERT = "driver"  # the synthetic demonstrator, for comparison
PURE_PURSUIT = "pure_pursuit"  # baselines that need no model file
HAND_COST = "hand_cost"


@dataclass(frozen=True)
class RunSpec:
    scenario: str
    seed: int
    driver: str  # PLANNER or EXPERT
    model_path: str | None
    profile: tuple[str, ...]
    keep_frames: tuple[int, ...] = ()
    perturb: Perturbation | None = None
    style: str = "default"  # the synthetic driver's style (terrapref.demos.expert.STYLES), for EXPERT runs
    keep_run: bool = False  # keep every decision (pose, choice, F_t) of a planner run, for an MCAP of it


def start_pose(start: tuple[float, float, float], seed: int) -> Pose:
    if seed == 0:
        return Pose(*start)
    rng = np.random.default_rng([seed, 7919])
    x, y, yaw = start
    lat, dyaw = rng.uniform(-0.3, 0.3), math.radians(rng.uniform(-3.0, 3.0))
    return Pose(x - lat * math.sin(yaw), y + lat * math.cos(yaw), yaw + dyaw)


@functools.lru_cache(maxsize=16)
def scenario_and_world(name: str) -> tuple:
    """Scenarios and rasters, cached per worker process: many runs share a handful of maps."""
    scenario = resolve_scenario(name)
    return scenario, rasterise(scenario)


@functools.lru_cache(maxsize=8)
def _policy_file(path: str) -> Policy:
    return load_policy(path)


def _model_policy(spec: RunSpec) -> Policy:
    if spec.model_path is None:
        raise ValueError("a planner run needs a model file")
    return _policy_file(spec.model_path)


POLICY_DRIVERS: dict[str, Callable[[RunSpec], Policy]] = {
    PLANNER: _model_policy,
    PURE_PURSUIT: lambda spec: PurePursuitPolicy(),
    HAND_COST: lambda spec: CostPolicy(),
}
"""Driver kinds that drive through the planner -> the policy a run of that kind drives with
(``EXPERT``, the synthetic driver, drives itself)."""


def make_policy(spec: RunSpec) -> Policy:
    """The policy a run drives with: a model file's, or a baseline that needs none."""
    if spec.driver not in POLICY_DRIVERS:
        raise ValueError(f"unknown driver {spec.driver!r}; drivers: {', '.join([EXPERT, *POLICY_DRIVERS])}")
    return POLICY_DRIVERS[spec.driver](spec)


def run_one(spec: RunSpec) -> dict:
    """Drive one run and return its metrics (JSON-ready), its path and any kept decisions."""
    scenario, world = scenario_and_world(spec.scenario)
    profile = PreferenceProfile.parse(list(spec.profile), scenario.classes, source="--profile")
    if spec.driver == EXPERT:
        sim = Simulation(scenario, world=world)
        driver = ExpertDriver(ExpertConfig.styled(spec.style, profile.order), world=world)  # the cached raster, not a new one
    else:
        policy = make_policy(spec)
        sim = Simulation(scenario, policy.camera, world=world)
        driver = PlannerDriver(Planner(policy), keep=bool(spec.keep_frames) or spec.keep_run)
    runner = PerturbedDriver(driver, spec.perturb, sim.config.camera_rate_hz) if spec.perturb is not None and spec.perturb.active else driver
    log = run_episode(sim, runner, np.random.default_rng(spec.seed), start_pose(scenario.start, spec.seed))
    metrics = score_run(log.trace[:, :2], scenario, sim.world, profile, completed=log.completed, collisions=log.collisions, duration_s=log.duration_s)
    out = {"scenario": spec.scenario, "seed": spec.seed, "driver": spec.driver, "metrics": metrics.to_dict(), "xy": log.trace[::3, :2].astype(np.float32)}
    if spec.keep_frames and isinstance(driver, PlannerDriver):
        frames = {}
        for i in spec.keep_frames:
            if 0 <= i < len(driver.decisions):
                d = driver.decisions[i]
                pose = tuple(log.trace[3 * i])
                frames[i] = {"pose": pose, "probs": d.probs, "index": d.index, "image": sim.renderer.render(Pose(*pose))}
        out["frames"] = frames
    if spec.keep_run and isinstance(driver, PlannerDriver) and driver.decisions:
        n = len(driver.decisions)
        out["run"] = {"poses": log.trace[: 3 * n : 3].copy(), "index": np.array([d.index for d in driver.decisions]),
                      "probs": np.stack([d.probs for d in driver.decisions]).astype(np.float32), "commands": log.commands[:n].copy()}
    return out


def run_many(specs: list[RunSpec], workers: int | None = None, progress: Callable[[int, int], None] | None = None,
             engine: Engine | None = None) -> list[dict]:
    """Run specs on ``engine`` (default: local processes, ``workers`` of them); results in the order given."""
    engine = engine or Engine(workers=workers if workers is not None else min(len(specs), os.cpu_count() or 1) or 1)
    return run_grid(run_one, specs, engine, progress, describe=describe_spec)


def describe_spec(spec: RunSpec) -> str:
    """A run's inputs, for a report that it failed."""
    who = f"model {spec.model_path}" if spec.model_path else spec.driver
    return f"{who} on {spec.scenario}, seed {spec.seed}"


def zone_agrees(planner_zone: dict, driver_zone: dict) -> bool:
    """The planner made the driver's choice in a zone (SPEC 12): the same class (or ``avoid``), and
    no lethal terrain touched where the driver touched none."""
    return planner_zone["choice"] == driver_zone["choice"] and not (planner_zone["touched_lethal"] and not driver_zone["touched_lethal"])


def annotate_agreement(results: list[dict]) -> None:
    """Give every planner zone the choice the synthetic driver made in the same run (scenario and
    seed: the same start) as ``driver_choice`` and ``agrees``; zones without a driver run are left as they are."""
    driver = {(r["scenario"], r["seed"]): r for r in results if r["driver"] == EXPERT}
    for r in results:
        ref = driver.get((r["scenario"], r["seed"]))
        if r["driver"] == EXPERT or ref is None:
            continue
        by_id = {z["id"]: z for z in ref["metrics"]["zones"]}
        for z in r["metrics"]["zones"]:
            z["driver_choice"] = by_id[z["id"]]["choice"]
            z["agrees"] = zone_agrees(z, by_id[z["id"]])


def summarise(results: list[dict], driver: str) -> dict:
    runs = [r for r in results if r["driver"] == driver]
    zones = [z for r in runs for z in r["metrics"]["zones"]]
    n = len(zones)
    ok = sum(z["success"] for z in zones)
    compared = [z for z in zones if "agrees" in z]
    agree = sum(z["agrees"] for z in compared)
    return {
        "runs": len(runs),
        "zones": n,
        "zone_success_rate": round(ok / n, 4) if n else None,
        "zone_success_ci95": [round(v, 4) for v in wilson(ok, n)],
        **({"agreement_rate": round(agree / len(compared), 4), "agreement_ci95": [round(v, 4) for v in wilson(agree, len(compared))],
            "agreement_zones": len(compared)} if compared else {}),
        "collision_count": int(sum(r["metrics"]["collisions"] for r in runs)),
        "completed_rate": round(sum(r["metrics"]["completed"] for r in runs) / len(runs), 4) if runs else None,
        "mean_rms_cross_track_m": round(float(np.mean([r["metrics"]["rms_cross_track_m"] for r in runs])), 4) if runs else None,
    }
