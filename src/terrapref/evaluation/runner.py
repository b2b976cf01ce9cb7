"""Closed-loop evaluation: drive scenarios with the planner (and the synthetic driver for
comparison) over seeds, score every zone (SPEC 12), and collect the paths for figures.

Each (scenario, seed, driver) run is independent, so runs are spread over worker processes
or a Ray cluster (terrapref.grid).
Seed 0 starts exactly at the scenario's start; other seeds start up to 0.3 m to the side and
3 degrees off (terrapref.vehicle.ground.start_pose, where a start is checked against them), and
seed the synthetic driver's noise.
"""

from __future__ import annotations

import functools
import os
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from terrapref.demos.expert import ExpertConfig, ExpertDriver
from terrapref.demos.relief_style import ReliefStyle
from terrapref.evaluation.scoring import NOT_REACHED, ReliefZoneResult, RunMetrics, ZoneResult, ZoneScoring, score_run
from terrapref.evaluation.stats import wilson
from terrapref.grid import Engine, run_grid
from terrapref.perception import PerceivedDriver, Perceiver, PerceptionModel
from terrapref.planner import Planner, PlannerDriver
from terrapref.planner.model import Model
from terrapref.planner.planner import Decision
from terrapref.planner.policy import CostPolicy, Policy, PurePursuitPolicy
from terrapref.planner.registry import make as make_policy
from terrapref.registry import Registry
from terrapref.scenario import Scenario, resolve_scenario
from terrapref.sim import EpisodeLog, SimConfig, Simulation, run_episode
from terrapref.sim.loop import settle
from terrapref.terrain import ClassTable, PreferenceProfile
from terrapref.vehicle import VehicleConfig
from terrapref.vehicle.ground import start_pose
from terrapref.world import WorldMap, rasterise

PLANNER = "planner"  # a model file: C, or a learned baseline (linear, CNN)
EXPERT = "driver"  # the synthetic demonstrator, for comparison
PURE_PURSUIT = PurePursuitPolicy.name  # baselines that need no model file (policies registered in terrapref.planner.registry)
HAND_COST = CostPolicy.name
GOAL_SETTLE_S = 10.0  # a planner run that completed is driven on this long at most, to see it stand at its own goal [s]


@dataclass(frozen=True)
class RunSpec:
    scenario: str
    seed: int
    driver: str  # a registered driver kind (drivers()): PLANNER, EXPERT, or a baseline that needs no file
    model_path: str | None
    profile: tuple[str, ...]
    keep_frames: tuple[int, ...] = ()
    perception: PerceptionModel | None = None  # what the planner receives instead of the truth (the driver sees the truth)
    style: str = "default"  # the synthetic driver's style (terrapref.demos.expert.STYLES), for EXPERT runs
    keep_run: bool = False  # keep every decision (pose, choice, F_t) of a planner run, for an MCAP of it
    classes: ClassTable | None = None  # the class table the scenario is read with (None: the default)
    vehicle: VehicleConfig | None = None  # the vehicle driven (None: the default field UGV; VehicleConfig.paper(): the paper's)
    speeds: tuple[tuple[str, float], ...] = ()  # the synthetic driver's cruising speeds by class, over its style's (EXPERT runs)
    perception_draw: int = 0  # which draw of the perception model's errors (terrapref.perception.run_stream)
    relief: ReliefStyle | None = None  # the synthetic driver's relief style (EXPERT runs; None: it drives relief as if flat)
    driver_changes: tuple[tuple[str, Any], ...] = ()  # the synthetic driver's other ExpertConfig fields over its style's (EXPERT runs)

    @property
    def perceived_as(self) -> str:
        """The name of the perception model the planner receives ('clean' when none is given: the truth)."""
        return self.perception.name if self.perception is not None else "clean"


@dataclass(frozen=True, eq=False)  # arrays inside: compared field by field where needed
class KeptFrame:
    """One planner decision kept for a picture (``RunSpec.keep_frames``)."""

    number: int  # the decision's place in the run (frames at the camera's rate)
    pose: tuple[float, float, float]  # x [m], y [m], yaw [rad] when it was taken
    probs: np.ndarray  # F_t, (m,)
    index: int  # the trajectory chosen
    image: np.ndarray  # the class image the camera saw, (H, W)
    stop: str | None = None  # why the planner stood at it (None: it drove the trajectory chosen)


@dataclass(frozen=True, eq=False)  # arrays inside: compared field by field where needed
class KeptRun:
    """Every decision of a planner run (``RunSpec.keep_run``), for an MCAP of it."""

    poses: np.ndarray  # (n, 3): x [m], y [m], yaw [rad] at each decision
    index: np.ndarray  # (n,): the trajectories chosen
    probs: np.ndarray  # (n, m) float32: F_t
    commands: np.ndarray  # (n, 2): v [m/s], w [rad/s] sent
    stops: tuple[str | None, ...] = ()  # (n,): why the planner stopped at each (None: it drove)


@dataclass(frozen=True)
class ZoneAgreement:
    """The synthetic driver's choice in a zone of the same run, and whether the planner made it
    (SPEC 12); a zone the driver did not reach shows no choice to make, and is not compared."""

    driver_choice: str
    agrees: bool

    @property
    def compared(self) -> bool:
        """Whether the driver made a choice here (it reached the zone) for the planner's to be compared with."""
        return self.driver_choice != NOT_REACHED

    def to_dict(self) -> dict:
        """As JSON: the driver's choice, and the agreement where compared."""
        return {"driver_choice": self.driver_choice, **({"agrees": self.agrees} if self.compared else {})}


@dataclass(frozen=True, eq=False)  # arrays inside: compared field by field where needed
class RunResult:
    """One run's outcome: which run it was, its scores, its path and what was kept of its decisions.

    Plain arrays and frozen records, so that it travels between processes (terrapref.grid).
    """

    scenario: str
    seed: int
    driver: str
    metrics: RunMetrics
    xy: np.ndarray  # (T, 2) float32: the reference point at every third controller tick [m]
    frames: tuple[KeptFrame, ...] = ()
    run: KeptRun | None = None
    agreement: tuple[ZoneAgreement, ...] | None = None  # per zone of ``metrics.zones``; see annotate_agreement
    relief_agreement: tuple[ZoneAgreement, ...] | None = None  # per relief zone of ``metrics.relief_zones``, likewise

    def zone_dicts(self) -> list[dict]:
        """The zones as JSON, each with the driver's choice and the agreement where they were compared."""
        zones = [z.to_dict() for z in self.metrics.zones]
        if self.agreement is None:
            return zones
        return [z | a.to_dict() for z, a in zip(zones, self.agreement, strict=True)]

    def metrics_dict(self) -> dict:
        """The metrics as JSON, the zones as :meth:`zone_dicts` writes them, the relief zones
        (on relief) likewise with the driver's choice and the agreement where compared."""
        out = self.metrics.to_dict() | {"zones": self.zone_dicts()}
        if self.relief_agreement is not None:
            out["relief_zones"] = [z | a.to_dict() for z, a in zip(out["relief_zones"], self.relief_agreement, strict=True)]
        return out

    def to_dict(self) -> dict:
        """Which run and its metrics, as JSON (the path and the kept decisions are arrays, not written)."""
        return {"scenario": self.scenario, "seed": self.seed, "driver": self.driver, "metrics": self.metrics_dict()}


@dataclass(frozen=True)
class Summary:
    """One driver's runs summed up (SPEC 12); rates rounded to 4 places, None where nothing was counted."""

    runs: int
    zones: int
    zone_success_rate: float | None
    zone_success_ci95: tuple[float, float]
    collision_count: int
    completed_rate: float | None
    mean_rms_cross_track_m: float | None
    agreement_zones: int = 0  # zones compared with the driver's; the agreement fields are None without any
    agreement_rate: float | None = None
    agreement_ci95: tuple[float, float] | None = None
    relief_agreement_zones: int = 0  # on relief, relief zones compared with the driver's (SPEC 19); the fields are None without any
    relief_agreement_rate: float | None = None
    relief_agreement_ci95: tuple[float, float] | None = None
    completed_ci95: tuple[float, float] = (0.0, 1.0)
    not_reached: int = 0  # zones the vehicle did not get past (each a failure)
    ended: dict[str, int] = field(default_factory=dict)  # runs by how they ended (goal, stopped, time limit)
    contact_s: float = 0.0  # time with lethal terrain under the footprint, all runs [s]
    driven_m: float = 0.0  # distance driven, all runs [m]
    stop_count: int = 0  # stops, all runs
    stops_s: dict[str, float] = field(default_factory=dict)  # seconds stood still by reason, all runs
    goal_watched: int = 0  # completed runs driven on to see the planner stand at its goal
    goal_stops: int = 0  # those in which it stood still saying `goal`
    goal_from_end_m: float | None = None  # the farthest from the path's end it stood (or was when the time ran out) [m]
    tip_count: int = 0  # entries past the vehicle's roll or pitch limit, all runs (SPEC 19)
    stuck_count: int = 0  # times a step too high held the vehicle, all runs
    max_roll_deg: float = 0.0  # the largest |roll| of any run [deg]
    max_pitch_deg: float = 0.0  # the largest |pitch| of any run [deg]

    @property
    def stops_per_100m(self) -> float | None:
        """Stops per 100 m driven; None where nothing was driven."""
        return round(100.0 * self.stop_count / self.driven_m, 3) if self.driven_m > 0 else None

    @classmethod
    def from_dict(cls, data: dict) -> Summary:
        """A summary as :meth:`to_dict` wrote it."""
        known = {f.name for f in fields(cls)}
        values = {k: (tuple(v) if k.endswith("_ci95") and v is not None else v) for k, v in data.items() if k in known}
        return cls(**values)

    def driving_lines(self) -> list[str]:
        """What a summary says of how the runs were driven, beside their scores: completion,
        how runs ended, zones not reached, contact with lethal terrain and stops by reason."""
        if not self.runs:
            return []
        lo, hi = self.completed_ci95
        ended = ", ".join(f"{why} {n}" for why, n in self.ended.items())
        lines = [f"completed {self.completed_rate:.0%} of {self.runs} runs (95% CI {lo:.0%}-{hi:.0%}); ended: {ended}"]
        if self.not_reached:
            lines.append(f"{self.not_reached} of {self.zones} zones not reached (each a failure)")
        if self.contact_s:
            lines.append(f"lethal terrain under the vehicle for {self.contact_s:.1f} s")
        if self.max_roll_deg or self.max_pitch_deg:
            lines.append(
                f"on relief: {self.tip_count} tips, {self.stuck_count} times stuck; "
                f"roll at most {self.max_roll_deg:.1f} deg, pitch {self.max_pitch_deg:.1f} deg"
            )
        if self.stop_count:
            reasons = ", ".join(f"{why} {seconds:.1f} s" for why, seconds in self.stops_s.items())
            per = f", {self.stops_per_100m:.2f} per 100 m driven" if self.stops_per_100m is not None else ", nothing driven"
            lines.append(f"{self.stop_count} stop{'' if self.stop_count == 1 else 's'}{per}; stood still: {reasons}")
        else:
            lines.append("no stop")
        if self.goal_watched:
            lines.append(
                f"stood at its goal (stop `goal`) in {self.goal_stops} of {self.goal_watched} completed runs, "
                f"at most {self.goal_from_end_m:.2f} m from the path's end"
            )
        return lines

    def to_dict(self) -> dict:
        """As JSON; the agreement only where zones were compared."""
        agreement = (
            {
                "agreement_rate": self.agreement_rate,
                "agreement_ci95": list(self.agreement_ci95 or ()),
                "agreement_zones": self.agreement_zones,
            }
            if self.agreement_zones
            else {}
        )
        if self.relief_agreement_zones:
            agreement |= {
                "relief_agreement_rate": self.relief_agreement_rate,
                "relief_agreement_ci95": list(self.relief_agreement_ci95 or ()),
                "relief_agreement_zones": self.relief_agreement_zones,
            }
        return {
            "runs": self.runs,
            "zones": self.zones,
            "zone_success_rate": self.zone_success_rate,
            "zone_success_ci95": list(self.zone_success_ci95),
            **agreement,
            "not_reached": self.not_reached,
            "collision_count": self.collision_count,
            "tip_count": self.tip_count,
            "stuck_count": self.stuck_count,
            "max_roll_deg": self.max_roll_deg,
            "max_pitch_deg": self.max_pitch_deg,
            "contact_s": self.contact_s,
            "completed_rate": self.completed_rate,
            "completed_ci95": list(self.completed_ci95),
            "ended": self.ended,
            "mean_rms_cross_track_m": self.mean_rms_cross_track_m,
            "driven_m": self.driven_m,
            "stop_count": self.stop_count,
            "stops_per_100m": self.stops_per_100m,
            "stops_s": self.stops_s,
            **(
                {"goal_watched": self.goal_watched, "goal_stops": self.goal_stops, "goal_from_end_m": self.goal_from_end_m}
                if self.goal_watched
                else {}
            ),
        }


@functools.lru_cache(maxsize=16)
def scenario_and_world(name: str, classes: ClassTable | None = None) -> tuple:
    """Scenarios and rasters, cached per worker process: many runs share a handful of maps."""
    scenario = resolve_scenario(name, classes)
    return scenario, rasterise(scenario)


@functools.lru_cache(maxsize=8)
def _policy_file(path: str) -> Policy:
    return Model.load(path).policy


Driver = ExpertDriver | PlannerDriver
DriverFactory = Callable[[RunSpec, Scenario, WorldMap, PreferenceProfile], tuple[Simulation, Driver]]
DRIVERS: Registry[DriverFactory] = Registry("driver")  # who can drive a run (RunSpec.driver)


def register_driver(kind: str, factory: DriverFactory, doc: str = "") -> None:
    """Name who can drive a run (``RunSpec.driver``): ``factory(spec, scenario, world, profile)``
    gives the run's simulation and its driver."""
    DRIVERS.register(kind, factory, doc)


def drivers() -> list[str]:
    """The registered driver kinds, in the order registered."""
    return DRIVERS.names()


def _expert(spec: RunSpec, scenario: Scenario, world: WorldMap, profile: PreferenceProfile) -> tuple[Simulation, Driver]:
    """The synthetic driver of the run's profile and style, on the cached raster (not a new one)."""
    return Simulation(scenario, config=SimConfig.driving(spec.vehicle), world=world), ExpertDriver(
        replace(ExpertConfig.styled(spec.style, profile.order, spec.speeds, spec.driver_changes), relief=spec.relief), world=world
    )


def _through_planner(policy: Policy, spec: RunSpec, scenario: Scenario, world: WorldMap) -> tuple[Simulation, Driver]:
    """The planner driving with ``policy``, seeing through the camera the policy was built for."""
    sim = Simulation(scenario, policy.camera, SimConfig.driving(spec.vehicle), world=world)
    planner = Planner(policy, vehicle=sim.config.vehicle)
    return sim, PlannerDriver(planner, keep=bool(spec.keep_frames) or spec.keep_run, images=spec.keep_frames)


def _model_file(spec: RunSpec, scenario: Scenario, world: WorldMap, profile: PreferenceProfile) -> tuple[Simulation, Driver]:
    """The planner with the policy of the run's model file (C, or a learned baseline)."""
    if spec.model_path is None:
        raise ValueError("a planner run needs a model file")
    return _through_planner(_policy_file(spec.model_path), spec, scenario, world)


def _baseline(kind: str) -> DriverFactory:
    """The planner with a registered policy that needs no file (terrapref.planner.registry), for
    the scenario's class table."""

    def factory(spec: RunSpec, scenario: Scenario, world: WorldMap, profile: PreferenceProfile) -> tuple[Simulation, Driver]:
        return _through_planner(make_policy(kind, classes=scenario.classes), spec, scenario, world)

    return factory


register_driver(EXPERT, _expert, "the synthetic demonstrator of the run's profile and style")
register_driver(PLANNER, _model_file, "the planner with a model file's policy")
register_driver(PURE_PURSUIT, _baseline(PURE_PURSUIT), "the planner with the pure pursuit policy (no model file)")
register_driver(HAND_COST, _baseline(HAND_COST), "the planner with the hand-tuned cost policy (no model file)")


# Puts a planner driver where it can be watched (terrapref.interop.live); the driver it gives can be
# muted (``mute()``), as it is once the run is scored and only its stop at the goal is awaited.
Watch = Callable[[PlannerDriver], Driver]


def run_one(spec: RunSpec, watch: Watch | None = None) -> RunResult:
    """Drive one run and return its scores, its path and any kept decisions; with ``watch``, the
    planner (of a planner run) drives as ``watch`` wraps it."""
    scenario, world = scenario_and_world(spec.scenario, spec.classes)
    profile = PreferenceProfile.parse(list(spec.profile), scenario.classes, source="--profile")
    sim, driver = _sim_and_driver(spec, scenario, world, profile)
    perceived = spec.perception is not None and spec.perception.active and spec.driver != EXPERT
    watched = watch(driver) if watch is not None and isinstance(driver, PlannerDriver) else driver
    runner = (
        PerceivedDriver(
            watched, Perceiver(spec.perception, sim.renderer, scenario.classes, sim.config.camera_rate_hz), draw=spec.perception_draw
        )
        if perceived
        else watched
    )
    log = run_episode(sim, runner, np.random.default_rng(spec.seed), start_pose(scenario.start, spec.seed))
    if isinstance(driver, PlannerDriver) and log.completed:  # driven on, unwatched, to see it stand at its goal
        if watched is not driver:
            watched.mute()
        log = replace(log, goal_stop=settle(sim, runner, GOAL_SETTLE_S))
    metrics = score_run(log, scenario, sim.world, profile, ZoneScoring(footprint_m=sim.config.vehicle.footprint_m))
    planner = driver if isinstance(driver, PlannerDriver) else None
    return RunResult(
        spec.scenario,
        spec.seed,
        spec.driver,
        metrics,
        log.trace[::3, :2].astype(np.float32),
        frames=_kept_frames(planner, log),
        run=_kept_run(spec, planner, log),
    )


def _sim_and_driver(spec: RunSpec, scenario: Scenario, world: WorldMap, profile: PreferenceProfile) -> tuple[Simulation, Driver]:
    """The simulation of a run and who drives it, by the run's registered driver kind."""
    return DRIVERS[spec.driver](spec, scenario, world, profile)


def _kept_frames(planner: PlannerDriver | None, log: EpisodeLog) -> tuple[KeptFrame, ...]:
    """The decisions the run's spec asked to keep (by frame number) that it reached, each with
    the class image it was decided on (what the planner received, under a perception model)."""
    if planner is None:
        return ()
    frames = [
        KeptFrame(number, tuple(log.trace[3 * number]), d.probs, d.index, planner.image_of[number], d.stop)
        for number, d in _scored(planner, log)
        if number in planner.image_of
    ]
    return tuple(sorted(frames, key=lambda f: f.number))


def _kept_run(spec: RunSpec, planner: PlannerDriver | None, log: EpisodeLog) -> KeptRun | None:
    """Every decision of a planner run, where ``spec.keep_run`` asks for them and it made any: the
    pose at its frame, the trajectory chosen, F_t, and the command the vehicle held after that frame."""
    kept = _scored(planner, log) if planner is not None else []
    if not spec.keep_run or not kept:
        return None
    numbers = np.array([number for number, _ in kept], dtype=np.int64)
    decisions = [d for _, d in kept]
    return KeptRun(
        log.trace[3 * numbers].copy(),
        np.array([d.index for d in decisions]),
        np.stack([d.probs for d in decisions]).astype(np.float32),
        log.commands[numbers].copy(),
        tuple(d.stop for d in decisions),
    )


def _scored(planner: PlannerDriver, log: EpisodeLog) -> list[tuple[int, Decision]]:
    """The planner's kept decisions, with their frame numbers, in the run as scored (not those
    made while it was driven on to stand at its goal)."""
    return [(number, d) for number, d in zip(planner.frames, planner.decisions, strict=True) if number < len(log.commands)]


def run_many(
    specs: list[RunSpec],
    workers: int | None = None,
    progress: Callable[[int, int], None] | None = None,
    engine: Engine | None = None,
    watch: Watch | None = None,
) -> list[RunResult]:
    """Run specs on ``engine`` (default: local processes, ``workers`` of them); results in the order
    given. With ``watch`` (:func:`run_one`), one after another in this process instead."""
    if watch is not None:
        results = []
        for spec in specs:
            results.append(run_one(spec, watch))
            if progress is not None:
                progress(len(results), len(specs))
        return results
    engine = engine or Engine(workers=workers if workers is not None else min(len(specs), os.cpu_count() or 1) or 1)
    return run_grid(run_one, specs, engine, progress, describe=describe_spec)


def describe_spec(spec: RunSpec) -> str:
    """A run's inputs, for a report that it failed."""
    who = f"model {spec.model_path}" if spec.model_path else spec.driver
    return f"{who} on {spec.scenario}, seed {spec.seed}"


def zone_agrees(planner_zone: ZoneResult, driver_zone: ZoneResult) -> bool:
    """The planner made the driver's choice in a zone (SPEC 12): the same class (or ``avoid``), and
    no lethal terrain touched where the driver touched none."""
    return planner_zone.choice == driver_zone.choice and not (planner_zone.touched_lethal and not driver_zone.touched_lethal)


def relief_agreement(mine: Sequence[ReliefZoneResult] | None, theirs: Sequence[ReliefZoneResult] | None) -> tuple[bool, ...] | None:
    """Per relief zone, whether the planner's run (``mine``) passed it as the driver's run of the same
    course (``theirs``) did: over it, or round it on the same side; None where either run has no
    relief zones or they differ in number (not the same course)."""
    if mine is None or theirs is None or len(mine) != len(theirs):
        return None
    return tuple(m.choice == t.choice for m, t in zip(mine, theirs, strict=True))


def annotate_agreement(results: list[RunResult]) -> list[RunResult]:
    """The results, every planner run given the choice the synthetic driver made in each zone of the
    same run (scenario and seed: the same start) and whether it agreed; runs without a driver run,
    and the driver's own, come back as they were."""
    driver = {(r.scenario, r.seed): r for r in results if r.driver == EXPERT}
    return [r if r.driver == EXPERT else _with_agreement(r, driver.get((r.scenario, r.seed))) for r in results]


def _with_agreement(run: RunResult, ref: RunResult | None) -> RunResult:
    """``run`` with its agreement with the driver's run ``ref`` (None: nothing to compare with)."""
    if ref is None:
        return run
    by_id = {z.id: z for z in ref.metrics.zones}
    agreement = tuple(ZoneAgreement(by_id[z.id].choice, zone_agrees(z, by_id[z.id])) for z in run.metrics.zones)
    agrees = relief_agreement(run.metrics.relief_zones, ref.metrics.relief_zones)
    relief = None if agrees is None else tuple(ZoneAgreement(t.choice, a) for t, a in zip(ref.metrics.relief_zones, agrees, strict=True))
    return replace(run, agreement=agreement, relief_agreement=relief)


def compared_zones(runs: Sequence[RunResult], relief: bool = False) -> list[ZoneAgreement]:
    """The zones (``relief``: the relief zones) of ``runs`` compared with the driver's run: those
    annotated, less those the driver did not reach."""
    found = (r.relief_agreement if relief else r.agreement for r in runs)
    return [a for agreement in found if agreement is not None for a in agreement if a.compared]


def summarise(results: list[RunResult], driver: str) -> Summary:
    """Zone success, agreement (where annotated), collisions, completion and cross-track error of ``driver``'s runs."""
    runs = [r for r in results if r.driver == driver]
    zones = [z for r in runs for z in r.metrics.zones]
    n = len(zones)
    ok = sum(z.success for z in zones)
    compared = compared_zones(runs)
    agree = sum(a.agrees for a in compared)
    relief = compared_zones(runs, relief=True)
    relief_agree = sum(a.agrees for a in relief)
    completed = sum(r.metrics.completed for r in runs)
    stops: dict[str, float] = {}
    for r in runs:
        for reason, seconds in r.metrics.stops_s.items():
            stops[reason] = round(stops.get(reason, 0.0) + seconds, 3)
    return Summary(
        runs=len(runs),
        zones=n,
        zone_success_rate=round(ok / n, 4) if n else None,
        zone_success_ci95=_rounded(wilson(ok, n)),
        collision_count=int(sum(r.metrics.collisions for r in runs)),
        completed_rate=round(completed / len(runs), 4) if runs else None,
        mean_rms_cross_track_m=round(float(np.mean([r.metrics.rms_cross_track_m for r in runs])), 4) if runs else None,
        agreement_zones=len(compared),
        agreement_rate=round(agree / len(compared), 4) if compared else None,
        agreement_ci95=_rounded(wilson(agree, len(compared))) if compared else None,
        relief_agreement_zones=len(relief),
        relief_agreement_rate=round(relief_agree / len(relief), 4) if relief else None,
        relief_agreement_ci95=_rounded(wilson(relief_agree, len(relief))) if relief else None,
        completed_ci95=_rounded(wilson(completed, len(runs))),
        not_reached=sum(not z.reached for z in zones),
        ended=dict(sorted(Counter(r.metrics.ending for r in runs).items())),
        contact_s=round(sum(r.metrics.contact_s for r in runs), 3),
        tip_count=sum(r.metrics.tips for r in runs),
        stuck_count=sum(r.metrics.stuck for r in runs),
        max_roll_deg=max((r.metrics.max_roll_deg for r in runs), default=0.0),
        max_pitch_deg=max((r.metrics.max_pitch_deg for r in runs), default=0.0),
        driven_m=round(sum(r.metrics.driven_m for r in runs), 3),
        stop_count=sum(r.metrics.stop_count for r in runs),
        stops_s=dict(sorted(stops.items())),
        **_goal_counts(runs),
    )


def _goal_counts(runs: list[RunResult]) -> dict:
    """Summary's goal fields: the runs watched at their goal, those that stood there saying ``goal``, and the farthest from the end."""
    watched = [r.metrics.goal_stop for r in runs if r.metrics.goal_stop is not None]
    return {
        "goal_watched": len(watched),
        "goal_stops": sum(bool(g["stopped"]) for g in watched),
        "goal_from_end_m": round(max(float(g["from_end_m"]) for g in watched), 3) if watched else None,
    }


def _rounded(interval: tuple[float, float]) -> tuple[float, float]:
    lo, hi = interval
    return round(lo, 4), round(hi, 4)
