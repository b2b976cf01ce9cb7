"""`terrapref evaluate`: closed-loop runs of a model over scenarios and seeds, metrics.json and figures."""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from terrapref.camera import PinholeCamera, SegmentationView
from terrapref.demos.relief_style import ReliefStyle
from terrapref.errors import UserError
from terrapref.evaluation.runner import (
    EXPERT,
    PLANNER,
    RunResult,
    RunSpec,
    Watch,
    annotate_agreement,
    run_many,
    scenario_and_world,
    summarise,
)
from terrapref.evaluation.scoring import classes_in_zone
from terrapref.evaluation.speed import SpeedComparison, driver_lateral_limit, save_speed_along
from terrapref.features import PreferenceSet
from terrapref.fileio import write_text_atomic
from terrapref.grid import Engine
from terrapref.learning.identify import Identifiability
from terrapref.perception import PerceptionModel
from terrapref.planner.model import Model
from terrapref.rules import speed_rule
from terrapref.scenario import AVOID, resolve_scenario
from terrapref.sim import SimConfig
from terrapref.terrain import ClassTable, PreferenceProfile
from terrapref.vehicle import Pose, VehicleConfig
from terrapref.vehicle.ground import LEVEL, Attitude, GroundContact, drivable


@dataclass(frozen=True)
class Evaluation:
    """What an evaluation drives: a model over courses and seeds 0..N-1, and (``with_driver``)
    the synthetic driver on the same runs.

    Attributes:
        model_path: the model file (C, or a learned baseline: linear, CNN).
        scenarios: the courses.
        seeds: runs per course (seeds 0..N-1).
        profile: the order ``best`` zones resolve under; None: the model's.
        with_driver: also drive the synthetic driver, for the agreement with it.
        style: the synthetic driver's style.
        speeds: the synthetic driver's cruising speeds by class, over its style's [m/s].
        driver_changes: the synthetic driver's other :class:`ExpertConfig` fields over its
            style's (a style file's).
        relief: the synthetic driver's relief style (terrapref.demos.relief_style); None: it
            drives relief as if it were flat.
        frames: decision numbers of seed 0 to draw.
        mcap: write every planner run as ROS 2 MCAP.
        perception: what the planner receives instead of the truth; None: the truth.
    """

    model_path: str
    scenarios: tuple[str, ...]
    seeds: int
    profile: PreferenceProfile | None = None
    with_driver: bool = True
    style: str = "default"
    speeds: tuple[tuple[str, float], ...] = ()
    driver_changes: tuple[tuple[str, Any], ...] = ()
    frames: tuple[int, ...] = ()
    mcap: bool = False
    perception: PerceptionModel | None = None
    relief: ReliefStyle | None = None

    @property
    def perceived(self) -> PerceptionModel:
        """The perception model the planner's runs go through (a clean one: the truth)."""
        return self.perception or PerceptionModel()

    def specs(self, profile: PreferenceProfile, classes: ClassTable | None = None) -> list[RunSpec]:
        """The planner's runs (seed 0 keeping ``frames``; every run kept with ``mcap``), then the
        driver's; zones resolve under ``profile``, scenarios are read with ``classes``."""
        specs = [
            RunSpec(
                name,
                seed,
                PLANNER,
                self.model_path,
                profile.order,
                self.frames if seed == 0 else (),
                keep_run=self.mcap,
                perception=self.perceived,
                classes=classes,
            )
            for name in self.scenarios
            for seed in range(self.seeds)
        ]
        if self.with_driver:
            specs += [
                RunSpec(
                    name,
                    seed,
                    EXPERT,
                    None,
                    profile.order,
                    style=self.style,
                    classes=classes,
                    speeds=self.speeds,
                    relief=self.relief,
                    driver_changes=self.driver_changes,
                )
                for name in self.scenarios
                for seed in range(self.seeds)
            ]
        return specs


def scoring_profile(model, given: PreferenceProfile | None, source: str | Path) -> PreferenceProfile:
    """The order a run of ``model`` (a policy) is scored under and its synthetic driver drives by:
    ``given``, else the order the model's drives declared.

    Raises:
        UserError: neither: the model's drives declared no order (``drive`` without ``--profile``).
    """
    if given is not None:
        return given
    if not model.profile:
        raise UserError(
            str(source),
            "names no driver's order (its drives declared none): give --profile ORDER, the order `best` zones are scored "
            "under and the synthetic driver it is compared with drives by",
            field="profile",
        )
    return PreferenceProfile.parse(list(model.profile), model.classes, source=f"{source}: profile")


def evaluate_model(
    evaluation: Evaluation,
    out_dir: str | Path,
    engine: Engine | None = None,
    progress: Callable[[int, int], None] | None = None,
    watch: Watch | None = None,
) -> dict:
    """Drive every scenario of ``evaluation`` with the planner (and the synthetic driver) for seeds 0..N-1.

    ``best`` zones resolve under the model's profile unless the evaluation's ``profile``
    overrides it. Each planner zone gets the choice the driver (of ``style``) made in the same
    run and whether the planner agreed (SPEC 12), and, when the model's demonstrations left a
    pair of classes unidentified (terrapref.learning.identify), the pairs its expected choice
    rests on. Writes ``metrics.json``, one top-down figure per scenario and the decision
    pictures of ``frames`` (for seed 0) into ``out_dir``; for a model with a speed rule, one
    figure per scenario of the speed along its path (``SCENARIO_speed.png``: driver and planner,
    seed 0); and with ``mcap`` every planner run as ROS 2 MCAP (``runs/SCENARIO_seedN.mcap``: the
    camera, the pose, the 21 trajectories and the one chosen); returns the metrics. ``engine``: where the runs go (default: local processes,
    one per core). With ``perception``, the planner receives what a robot would
    (terrapref.perception) while the driver and the scoring see the truth; metrics.json names the
    model. With ``watch``, the runs go one after another in this process, each planner driving as
    ``watch`` wraps it (a live view).
    """
    ev = evaluation
    model = Model.load(ev.model_path).policy  # C, or a learned baseline (linear, CNN)
    for name in ev.scenarios:
        drivable(resolve_scenario(name, model.classes), seeds=ev.seeds)  # fail early, with the file and field, before any run
    profile = scoring_profile(model, ev.profile, ev.model_path)
    results = annotate_agreement(run_many(ev.specs(profile, model.classes), progress=progress, engine=engine, watch=watch))
    evidence = _evidence(model, ev.scenarios)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    limit = driver_lateral_limit(ev.style, ev.speeds, model.rules, ev.driver_changes)
    metrics = _metrics(ev, profile, results, evidence, limit, model.classes.background)
    beyond = {r.scenario: sorted(set(ev.frames) - {f.number for f in r.frames}) for r in results if r.driver == PLANNER and r.seed == 0}
    if any(beyond.values()):
        metrics["frames_beyond_the_run"] = {name: numbers for name, numbers in beyond.items() if numbers}
    _figures(results, ev.scenarios, out, model, profile, ev.perceived)
    if speed_rule(model.rules) is not None:  # a model that learned its driver's speed: where it went how fast
        _speed_figures(results, ev.scenarios, out, model.classes)
    if ev.mcap:
        _write_runs(results, out / "runs", model)
    write_text_atomic(out / "metrics.json", json.dumps(metrics, indent=2))
    return metrics


@dataclass(frozen=True)
class _Evidence:
    """What the model's demonstrations showed, and the classes present in every zone of the courses driven."""

    identified: Identifiability
    present: dict[str, dict[str, list[str]]]  # scenario -> zone id -> terrain columns of the classes in it
    classes: ClassTable

    def rests_on(self, scenario: str, zone: dict) -> list[str]:
        """The unidentified pairs a zone's expected choice rests on (:func:`rests_on`)."""
        expect = zone["expect"] if zone["expect"] == AVOID else self.classes.column_of(zone["expect"])
        return rests_on(expect, self.present[scenario][zone["id"]], self.identified)


def _evidence(model, scenarios: Sequence[str]) -> _Evidence | None:
    """The model's identifiability report and the classes of every zone; None for a model without one."""
    identified = _identifiability(model)
    if identified is None:
        return None
    present: dict[str, dict[str, list[str]]] = {}
    for name in scenarios:
        scenario, world = scenario_and_world(name, model.classes)
        columns = model.classes.column_of  # the report names the lethal classes' shared column
        present[name] = {z.id: list(dict.fromkeys(map(columns, classes_in_zone(z, world)))) for z in scenario.zones}
    return _Evidence(identified, present, model.classes)


def _metrics(
    ev: Evaluation,
    profile: PreferenceProfile,
    results: list[RunResult],
    evidence: _Evidence | None,
    lateral_limit_mps2: float | None,
    background: str,
) -> dict:
    """metrics.json: what was evaluated, every run's metrics by course, driver and seed, and the
    summaries (the speed's against the driver's lateral-acceleration limit, where known; by class,
    the ``background`` class's name for the zones passed by)."""
    metrics: dict = {
        "model": str(ev.model_path),
        "profile": list(profile.order),
        "seeds": ev.seeds,
        "driver_style": ev.style,
        "driver_speeds": {name: v for name, v in ev.speeds},
        **({"driver_changes": dict(ev.driver_changes)} if ev.driver_changes else {}),  # a style file's fields
        **({"driver_relief": ev.relief.to_dict()} if ev.relief is not None else {}),  # its relief style, where it has one
        "perception": ev.perceived.to_dict(),
        "unidentified_pairs": [f"{p.first} vs {p.second}" for p in evidence.identified.unidentified()] if evidence is not None else None,
        "scenarios": {name: _course_runs(results, name, evidence) for name in ev.scenarios},
        "summary": summarise(results, PLANNER).to_dict(),
    }
    if ev.with_driver:
        metrics["driver_summary"] = summarise(results, EXPERT).to_dict()
        metrics["driver_lateral_limit_mps2"] = lateral_limit_mps2
        metrics["speed"] = SpeedComparison.of_results(results, background, lateral_limit_mps2).to_dict()
    return metrics


def _course_runs(results: list[RunResult], name: str, evidence: _Evidence | None) -> dict:
    """One course's runs as metrics.json holds them: by driver, then by seed; a planner zone also
    names the unidentified pairs its expected choice rests on, where the model's file says."""
    entry: dict = {}
    for r in results:
        if r.scenario != name:
            continue
        metrics = r.metrics_dict()
        if evidence is not None and r.driver == PLANNER:
            for z in metrics["zones"]:
                z["rests_on_unidentified"] = evidence.rests_on(name, z)
        entry.setdefault(r.driver, {})[str(r.seed)] = metrics
    return entry


def _write_runs(results: list[RunResult], folder: Path, model) -> None:
    """Each planner run as an MCAP file, its camera frames rendered again at the poses driven (on
    relief with the body's attitude there, and their depth images); with an offset rule, the
    costmap of the ground those frames show, once a second."""
    from terrapref.camera import SegmentationRenderer
    from terrapref.interop.mcap_export import RunFrames, costmaps_of, write_mcap
    from terrapref.planner import Planner

    camera = PinholeCamera(model.camera)
    planner = Planner(model)  # its costmap only where its steering rule reads a ground map (the offset rule)
    for r in results:
        run = r.run
        if r.driver != PLANNER or run is None:
            continue
        scenario, world = scenario_and_world(r.scenario, model.classes)  # cached: the runs of one course share a raster
        seen = _RunView(SegmentationRenderer(camera, world), run.poses, SimConfig.driving(None).vehicle)  # the runs' vehicle
        depth, attitude = (seen.depth, seen.attitude) if world.has_relief else (None, None)
        frames = RunFrames(
            times=0.1 * np.arange(len(run.poses)),
            poses=run.poses,
            commands=run.commands,
            image=seen.image,
            chosen=run.index,
            path=scenario.waypoints,
            camera=model.camera,
            classes=model.classes,
            preference=model.features.preference,
            probs=run.probs,
            costmap=costmaps_of(planner, run.poses, depth, attitude) if planner.ground_map is not None else None,
            stops=run.stops or None,
            depth=depth,
            attitude=attitude,
        )
        write_mcap(folder / f"{file_stem(r.scenario)}_seed{r.seed}.mcap", frames, robot_file=False)


class _RunView:
    """A run's camera frames rendered again at its ``poses`` (F, 3) by ``renderer``: on relief
    with the body of ``vehicle`` resting on the ground at each pose, as it rode there, and with
    its depth image; each frame one view (rendered once however often it is read), asked for in order."""

    def __init__(self, renderer, poses: np.ndarray, vehicle: VehicleConfig) -> None:
        self._renderer, self._poses = renderer, poses
        self._contact = GroundContact(renderer.world, vehicle) if renderer.relief else None
        self._at, self._view = -1, None

    def attitude(self, i: int) -> Attitude:
        """The body's attitude at pose ``i`` (level on flat ground)."""
        return self._seen(i).attitude

    def image(self, i: int) -> np.ndarray:
        """Frame ``i``'s class ids (H, W) uint8."""
        return self._seen(i).image

    def depth(self, i: int) -> np.ndarray | None:
        """Frame ``i``'s depth image (H, W) float32 [m, NaN: none]."""
        return self._seen(i).depth

    def _seen(self, i: int) -> SegmentationView:
        """Frame ``i``'s view, made when first asked for."""
        if i != self._at:
            pose = Pose(*self._poses[i])
            attitude = self._contact.attitude(pose) if self._contact is not None else LEVEL
            self._view, self._at = SegmentationView(self._renderer, pose, attitude=attitude), i
        return self._view


def file_stem(scenario: str) -> str:
    """A scenario's name as a file name any file system takes, in the output folder itself:
    ``gen:7`` -> ``gen_7``, ``courses/my.yaml`` -> ``courses_my``."""
    name = re.sub(r"\.ya?ml$", "", scenario)
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("_.") or "scenario"


def _identifiability(model) -> Identifiability | None:
    """What the model's demonstrations showed, if its file says (None for a file without the report)."""
    data = getattr(getattr(model, "model", None), "meta", {}).get("identifiability")
    try:
        return Identifiability.from_dict(data) if data else None
    except (KeyError, TypeError, ValueError, IndexError):
        raise UserError(model.path, "malformed identifiability report", field="identifiability") from None


def rests_on(expect: str, present: Sequence[str], identified: Identifiability) -> list[str]:
    """The unidentified pairs a zone's expected choice depends on: the expected class against
    every other class present (or the background against them all, for ``avoid``)."""
    best = identified.background if expect == AVOID else expect
    pairs = [identified.pair(best, other) for other in present if other != best]
    if expect != AVOID:
        pairs.append(identified.pair(best, identified.background))
    return sorted({f"{p.first} vs {p.second}" for p in pairs if p is not None and not p.identified})


def _figures(
    results: list[RunResult], scenarios: Sequence[str], out: Path, model, profile: PreferenceProfile, perception: PerceptionModel
) -> None:
    """Per course, the top-down evaluation figure; per kept frame, its decision picture (the frame the planner received)."""
    from terrapref.plots import CourseRuns, Decision, save_decision, save_evaluation

    pset = PreferenceSet(model.features.preference, PinholeCamera(model.camera))
    uv, visible = pset.camera.project_ground(pset.trajectories[..., :2])
    for name in scenarios:
        scenario, world = scenario_and_world(name, model.classes)  # the raster the runs used, not a new one
        planner_runs = sorted((r for r in results if r.scenario == name and r.driver == PLANNER), key=lambda r: r.seed)
        driver_runs = sorted((r for r in results if r.scenario == name and r.driver == EXPERT), key=lambda r: r.seed)
        per_zone = _zone_successes(planner_runs)
        ok = sum(v[0] for v in per_zone.values())
        n = sum(v[1] for v in per_zone.values())
        course = CourseRuns(scenario, world, [r.xy for r in driver_runs], [r.xy for r in planner_runs], per_zone)
        save_evaluation(
            out / f"{file_stem(name)}.png",
            course,
            title=f"{name}: planner zone success {ok}/{n} over {len(planner_runs)} run(s), profile {profile}"
            + (f", perception {perception.name}" if perception.active else ""),
        )
        for r in planner_runs:
            for f in r.frames:
                rgb = model.classes.palette()[f.image]
                x, y, yaw = f.pose
                decision = Decision(uv, visible, f.probs, f.index, model.features.preference.control.w_rps, f.stop)
                save_decision(
                    out / f"{file_stem(name)}_frame{f.number:05d}.png",
                    rgb,
                    decision,
                    classes=model.classes,
                    title=f"{name}, frame {f.number}, pose ({x:.1f} m, {y:.1f} m, yaw {np.degrees(yaw):.0f} deg)"
                    + (f"; stood: {f.stop}" if f.stop else ""),
                )


def _speed_figures(results: list[RunResult], scenarios: Sequence[str], out: Path, classes: ClassTable) -> None:
    """Per course, the speed along its path of the driver's and the planner's run of seed 0, its zones shaded."""
    for name in scenarios:
        scenario, _ = scenario_and_world(name, classes)
        save_speed_along(out / f"{file_stem(name)}_speed.png", results, scenario, name, zones=True)


def _zone_successes(runs: list[RunResult]) -> dict[str, tuple[int, int]]:
    """Zone id -> (runs that met it, runs that were scored in it)."""
    per_zone: dict[str, tuple[int, int]] = {}
    for r in runs:
        for z in r.metrics.zones:
            ok, n = per_zone.get(z.id, (0, 0))
            per_zone[z.id] = (ok + bool(z.success), n + 1)
    return per_zone
