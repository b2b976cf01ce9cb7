"""The planner's speed against its own driver's (SPEC 18): per class over zones, time to the end of
the path, lateral acceleration; shared by ``evaluate`` (metrics.json) and ``select`` (SELECT.md);
and the figure of speed along a course's path, driver and planner (``evaluate``, ``reproduce``).

Rows are plain mappings, as select.json keeps them: a zone row has ``scenario``,
``driver_choice``, ``agrees``, ``speed_mps`` and ``driver_speed_mps``; a run row has
``scenario``, ``completed``, ``driver_completed``, ``time_s``, ``driver_time_s``,
``max_lateral_accel_mps2``, ``driver_max_lateral_accel_mps2`` and ``driver_lateral_limit_mps2``
(None where the driver's limit is not known).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from terrapref.demos.expert import STYLES, ExpertConfig
from terrapref.demos.relief_style import ReliefStyle
from terrapref.errors import UserError
from terrapref.evaluation.runner import EXPERT, PLANNER, RunResult
from terrapref.evaluation.scoring import GRADE_BAND_DEG, GRADE_BANDS, ROUGH_BAND_M, ROUGH_BANDS, RunMetrics
from terrapref.evaluation.stats import cluster_bootstrap, rate_text
from terrapref.rules import Rule, speed_rule
from terrapref.rules.speed.rule import SpeedRule
from terrapref.scenario import AVOID, Scenario
from terrapref.scenario.path import ReferencePath

SPEED_TARGET_MPS = 0.08  # the planner's speed error per class against its driver must stay within this [m/s]
GRADE_SPEED_TARGET_MPS = 0.10  # and per grade band (up, level, down) on relief within this [m/s]
TIME_TOLERANCE = 0.05  # and its time to the end of the path within this share of the driver's
LATERAL_TOLERANCE = 0.10  # and its lateral acceleration no more than this share above the driver's limit
GRADE_MIN_S = 1.0  # a run's speed on a grade band is compared where both runs spent at least this long on it [s]


@dataclass(frozen=True)
class Estimate:
    """A mean with its 95% interval resampling layouts, over ``n`` values."""

    mean: float
    low: float
    high: float
    n: int

    def text(self, digits: int = 3) -> str:
        return f"{self.mean:.{digits}f} (95% CI {self.low:.{digits}f}-{self.high:.{digits}f}, {self.n})"


@dataclass(frozen=True)
class SpeedComparison:
    """The planner's speed against its driver's.

    Attributes:
        by_class: per class the driver took, by name (the background, ``background``, where it
            passed a zone by), the mean absolute error of the mean speed through a zone [m/s],
            over the zones where the planner took that class too.
        time_ratio: the planner's time to the end of the path over the driver's, over runs both completed.
        time_within: runs whose time is within :data:`TIME_TOLERANCE` of the driver's, and runs compared.
        limit_over: runs whose largest lateral acceleration is more than :data:`LATERAL_TOLERANCE`
            above the driver's limit (:func:`driver_lateral_limit`), and runs compared.
        limit_worst: the largest ratio of the two.
        lateral_over: runs whose largest lateral acceleration is more than :data:`LATERAL_TOLERANCE`
            above the largest of the driver's own run on the same layout, and runs compared.
        lateral_worst: the largest ratio of the two.
        background: the class table's background class (None in a file written before it was named:
            its zones passed by are keyed ``avoid`` there).
        by_grade: on relief, per grade band (terrapref.evaluation.scoring.GRADE_BANDS), the
            absolute error of a run's mean speed on ground of that band [m/s], over the runs
            where both it and the driver's run on the same layout spent :data:`GRADE_MIN_S` there,
            both completed.
        by_roughness: likewise per roughness band (terrapref.evaluation.scoring.ROUGH_BANDS).
    """

    by_class: dict[str, Estimate]
    time_ratio: Estimate | None
    time_within: tuple[int, int]
    lateral_over: tuple[int, int]
    lateral_worst: float | None
    limit_over: tuple[int, int] = (0, 0)
    limit_worst: float | None = None
    background: str | None = None
    by_grade: dict[str, Estimate] = field(default_factory=dict)
    by_roughness: dict[str, Estimate] = field(default_factory=dict)

    @classmethod
    def of(cls, zones: Sequence[Mapping[str, Any]], runs: Sequence[Mapping[str, Any]], background: str) -> SpeedComparison:
        """The comparison of zone and run rows (module docstring), a zone the driver passed by
        counted for the ``background`` class."""
        errors: dict[str, dict[str, list[float]]] = {}
        for z in zones:
            if z.get("speed_mps") is None or z.get("driver_speed_mps") is None or not z.get("agrees"):
                continue
            name = background if z["driver_choice"] == AVOID else z["driver_choice"]  # passed by: on the background
            errors.setdefault(name, {}).setdefault(z["scenario"], []).append(abs(z["speed_mps"] - z["driver_speed_mps"]))
        by_class = {name: _estimate(groups) for name, groups in sorted(errors.items())}
        ratios: dict[str, list[float]] = {}
        for r in runs:
            if r.get("completed") and r.get("driver_completed") and r.get("driver_time_s"):
                ratios.setdefault(r["scenario"], []).append(r["time_s"] / r["driver_time_s"])
        compared = [x for v in ratios.values() for x in v]
        within = sum(abs(x - 1) <= TIME_TOLERANCE for x in compared)
        grades, roughness = _band_errors(runs, "speed_by_grade_mps", GRADE_BANDS), _band_errors(runs, "speed_by_roughness_mps", ROUGH_BANDS)
        same = [r["max_lateral_accel_mps2"] / r["driver_max_lateral_accel_mps2"] for r in runs if r.get("driver_max_lateral_accel_mps2")]
        limit = [r["max_lateral_accel_mps2"] / r["driver_lateral_limit_mps2"] for r in runs if r.get("driver_lateral_limit_mps2")]
        return cls(
            by_class,
            _estimate(ratios) if compared else None,
            (within, len(compared)),
            (sum(x > 1 + LATERAL_TOLERANCE for x in same), len(same)),
            max(same) if same else None,
            (sum(x > 1 + LATERAL_TOLERANCE for x in limit), len(limit)),
            max(limit) if limit else None,
            background,
            {band: _estimate(grades[band]) for band in GRADE_BANDS if band in grades},
            {band: _estimate(roughness[band]) for band in ROUGH_BANDS if band in roughness},
        )

    @classmethod
    def of_results(cls, results: Sequence[RunResult], background: str, lateral_limit_mps2: float | None = None) -> SpeedComparison:
        """The planner's runs against the driver's of the same course and seed (zones annotated with
        agreement; those passed by counted for the ``background`` class), and against the driver's
        lateral-acceleration limit where it is known."""
        driver = {(r.scenario, r.seed): r for r in results if r.driver == EXPERT}
        zones, runs = [], []
        for r in results:
            d = driver.get((r.scenario, r.seed))
            if r.driver != PLANNER or d is None:
                continue
            runs.append({"scenario": r.scenario, **run_fields(r.metrics, d.metrics, lateral_limit_mps2)})
            theirs = {z.id: z for z in d.metrics.zones}
            for z, a in zip(r.metrics.zones, r.agreement or (), strict=False):
                if z.id in theirs:
                    zones.append(
                        {
                            "scenario": r.scenario,
                            "driver_choice": a.driver_choice,
                            "agrees": a.agrees,
                            "speed_mps": z.speed_mps,
                            "driver_speed_mps": theirs[z.id].speed_mps,
                        }
                    )
        return cls.of(zones, runs, background)

    def to_dict(self) -> dict:
        out = asdict(self)
        for name in ("by_grade", "by_roughness"):
            if not out[name]:  # flat ground: no bands
                del out[name]
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SpeedComparison:
        def estimate(e: Mapping[str, Any] | None) -> Estimate | None:
            return Estimate(**e) if e is not None else None

        return cls(
            {name: Estimate(**e) for name, e in data["by_class"].items()},
            estimate(data["time_ratio"]),
            tuple(data["time_within"]),
            tuple(data["lateral_over"]),
            data["lateral_worst"],
            tuple(data.get("limit_over", (0, 0))),
            data.get("limit_worst"),
            data.get("background"),
            {band: Estimate(**e) for band, e in (data.get("by_grade") or {}).items()},
            {band: Estimate(**e) for band, e in (data.get("by_roughness") or {}).items()},
        )

    def lines(self) -> list[str]:
        """What it says, a line each."""
        passed_by = {self.background: f"{self.background} (zones passed by)", AVOID: "the background (zones passed by)"}
        out = [
            f"speed error against the driver, {passed_by.get(name, name)}: {e.text()} m/s over zones (target <= {SPEED_TARGET_MPS})"
            for name, e in self.by_class.items()
        ]
        out += [
            f"speed error against the driver, "
            f"{f'level ground (grade within {GRADE_BAND_DEG:g} deg)' if band == 'level' else f'going {band} (grade past {GRADE_BAND_DEG:g} deg)'}"
            f": {e.text()} m/s over runs (target <= {GRADE_SPEED_TARGET_MPS})"
            for band, e in self.by_grade.items()
        ]
        out += [
            f"speed error against the driver, {band} ground (roughness {'past' if band == 'rough' else 'up to'} {ROUGH_BAND_M:g} m)"
            f": {e.text()} m/s over runs (target <= {GRADE_SPEED_TARGET_MPS})"
            for band, e in self.by_roughness.items()
        ]
        if self.time_ratio is not None:
            out.append(
                f"time to the end of the path over the driver's: {self.time_ratio.text()}; within {TIME_TOLERANCE:.0%} in "
                f"{rate_text(*self.time_within)} of the runs"
            )
        if self.limit_worst is not None:
            out.append(
                f"lateral acceleration more than {LATERAL_TOLERANCE:.0%} above the driver's limit: {rate_text(*self.limit_over)} "
                f"of the runs; at most {self.limit_worst:.2f} times the limit"
            )
        if self.lateral_worst is not None:
            out.append(
                f"lateral acceleration more than {LATERAL_TOLERANCE:.0%} above the most of the driver's run on the same layout: "
                f"{rate_text(*self.lateral_over)} of the runs; at most {self.lateral_worst:.2f} times it"
            )
        return out


def driver_lateral_limit(
    style: str, speeds: tuple[tuple[str, float], ...], rules: Sequence[Rule], changes: tuple[tuple[str, Any], ...] = ()
) -> float | None:
    """The lateral acceleration [m/s^2] a driver keeps: its style's limit in bends (``changes``:
    :class:`ExpertConfig` fields over the style's, a style file's), else (a style without one)
    the largest its teaching drive showed, which a model's speed rule keeps; None where neither
    is known (a model without a speed rule)."""
    own = ExpertConfig.styled(style, None, speeds, changes).lateral_accel_mps2
    if own is not None:
        return own
    rule = speed_rule(rules)
    return rule.model.drive_lateral_mps2 if isinstance(rule, SpeedRule) else None


def run_fields(metrics: RunMetrics, driver: RunMetrics, lateral_limit_mps2: float | None = None) -> dict[str, Any]:
    """A planner run's fields that :meth:`SpeedComparison.of` reads, beside its driver's run on the
    same course and the driver's lateral-acceleration limit (None: not known)."""
    return {
        "completed": metrics.completed,
        "driver_completed": driver.completed,
        "time_s": metrics.time_s,
        "driver_time_s": driver.time_s,
        "max_lateral_accel_mps2": metrics.max_lateral_accel_mps2,
        "driver_max_lateral_accel_mps2": driver.max_lateral_accel_mps2,
        "driver_lateral_limit_mps2": lateral_limit_mps2,
        **(
            {"speed_by_grade_mps": metrics.speed_by_grade_mps, "driver_speed_by_grade_mps": driver.speed_by_grade_mps}
            if metrics.speed_by_grade_mps is not None and driver.speed_by_grade_mps is not None
            else {}
        ),  # on relief: the speed by grade band of both runs ...
        **(
            {"speed_by_roughness_mps": metrics.speed_by_roughness_mps, "driver_speed_by_roughness_mps": driver.speed_by_roughness_mps}
            if metrics.speed_by_roughness_mps is not None and driver.speed_by_roughness_mps is not None
            else {}
        ),  # ... and by roughness band
    }


def _band_errors(runs: Sequence[Mapping[str, Any]], key: str, bands: tuple[str, ...]) -> dict[str, dict[str, list[float]]]:
    """Per band of ``bands``, per layout, the absolute errors of the runs' mean speed there
    against their driver's (``key`` and ``driver_`` + ``key``), where both spent :data:`GRADE_MIN_S` there,
    over the runs both completed: one that stood stuck against a ledge, or stopped short, shows
    how long it stood, not the speeds it drives at."""
    errors: dict[str, dict[str, list[float]]] = {}
    for r in runs:
        if not (r.get("completed", True) and r.get("driver_completed", True)):
            continue
        mine, theirs = r.get(key) or {}, r.get(f"driver_{key}") or {}
        for band in (b for b in bands if b in mine and b in theirs):
            if min(mine[band]["s"], theirs[band]["s"]) >= GRADE_MIN_S:
                errors.setdefault(band, {}).setdefault(r["scenario"], []).append(abs(mine[band]["mps"] - theirs[band]["mps"]))
    return errors


def _estimate(groups: Mapping[str, list[float]]) -> Estimate:
    mean, low, high = cluster_bootstrap(list(groups.values()))
    return Estimate(mean, low, high, sum(len(v) for v in groups.values()))


TrainedDriver = tuple[str, tuple[tuple[str, float], ...], tuple[tuple[str, Any], ...]]  # style, speeds by class, other fields


def trained_driver(meta: Mapping[str, Any]) -> TrainedDriver | None:
    """The synthetic driver a model's recordings were driven by, when every recording names the
    same: its style (a preset), its cruising speeds by class and the :class:`ExpertConfig`
    fields it changed over the preset's (a driver of a style file: every field its recording
    holds, over the default preset's); None for a person's drives, a mix, or a driver unreadable."""
    return _common_driver(_recorded_drivers(meta))


def _common_driver(drivers: Sequence[Any]) -> TrainedDriver | None:
    """:func:`trained_driver` of recordings whose driver entries are ``drivers``."""
    if not drivers or not all(isinstance(d, Mapping) and d.get("kind") == "expert" for d in drivers):
        return None
    found = {(d.get("style", "default"), tuple(tuple(p) for p in (d.get("config") or {}).get("speeds") or ())) for d in drivers}
    if len(found) != 1:
        return None
    style, speeds = next(iter(found))
    if not isinstance(style, str) or not all(len(p) == 2 and isinstance(p[0], str) and isinstance(p[1], (int, float)) for p in speeds):
        return None
    speeds = tuple((str(n), float(v)) for n, v in speeds)
    if style in STYLES.names():
        return style, speeds, ()
    changes = {_recorded_changes(d.get("config") or {}) for d in drivers}  # a style file's: it may be gone; its recordings hold it
    return ("default", speeds, changes.pop()) if len(changes) == 1 and None not in changes else None


def driver_flags(drivers: Sequence[Any], relief: bool, profiles: Sequence[Any] = ()) -> str:
    """The flags of ``terrapref record`` (`` --profile P --style S --speeds ... --relief-style R``,
    each where it is not the default) that drive another course as the synthetic driver of
    recordings whose driver entries are ``drivers`` drove theirs, where they all name the same;
    the order their ``profiles`` (each recording's declared order, None: none) declare, where
    one is (a follow-up recorded in another order cannot be trained with them); on a course with
    ``relief``, a relief style always (the default's where they name none): a driver without one
    drives relief as if it were flat. Empty for a person's drives or a mix."""
    driver = _common_driver(drivers)
    declared = {tuple(p) for p in profiles if isinstance(p, (list, tuple)) and p}
    flags = f" --profile {','.join(next(iter(declared)))}" if len(declared) == 1 else ""
    if driver is not None:
        style, speeds, _ = driver
        flags += f" --style {style}" if style != "default" else ""
        if speeds and speeds != tuple(ExpertConfig.styled(style, ()).speeds):
            flags += " --speeds " + ",".join(f"{name}={v:g}" for name, v in speeds)
    try:
        named = _common_relief(drivers)
    except UserError:
        named = None
    if relief or named is not None:
        flags += f" --relief-style {named.as_flag() if named is not None else 'default'}"
    return flags


def _recorded_changes(config: Mapping[str, Any]) -> tuple[tuple[str, Any], ...] | None:
    """A recorded driver's fields but its profile, speeds and relief, as :class:`ExpertConfig`
    takes them; None where they do not make one."""
    if not isinstance(config, Mapping):
        return None
    kept = {f.name for f in fields(ExpertConfig)} - {"profile", "speeds", "relief"}
    changes = tuple((k, tuple(v) if isinstance(v, list) else v) for k, v in config.items() if k in kept)
    if not all(v is None or isinstance(v, (int, float)) or all(isinstance(x, (int, float)) for x in v) for _, v in changes):
        return None  # hand-edited: not fields a driver takes
    try:
        ExpertConfig(**dict(changes))
    except (TypeError, ValueError):
        return None
    return changes


def _recorded_drivers(meta: Mapping[str, Any]) -> list[Any]:
    """The driver entry of each recording a model was trained on, as its file names them (None
    for a recording that is not a mapping; none where the file lists no recordings)."""
    data = meta.get("data")
    recordings = data.get("recordings") if isinstance(data, Mapping) else None
    if not isinstance(recordings, (list, tuple)):
        return []
    return [r.get("driver") if isinstance(r, Mapping) else None for r in recordings]


def trained_relief(meta: Mapping[str, Any], source: str = "") -> ReliefStyle | None:
    """The relief style of the synthetic driver a model's recordings were driven by, when every
    recording names the same one (terrapref.demos.relief_style); None where none names one (it
    drove relief as if it were flat), for a person's drives or a mix. A style named that this
    code cannot read (a damaged file, another version's) is a UserError naming ``source``: a
    driver that drove relief as if flat is not what the model learned from."""
    return _common_relief(_recorded_drivers(meta), source)


def _recorded_reliefs(drivers: Sequence[Any]) -> list[Any]:
    """The relief style each synthetic driver of ``drivers`` (recordings' driver entries) names, as
    written (None: none, it drove relief as if flat, or a person drove)."""
    configs = [d.get("config") if isinstance(d, Mapping) and d.get("kind") == "expert" else None for d in drivers]
    return [c.get("relief") if isinstance(c, Mapping) else None for c in configs]


def _common_relief(drivers: Sequence[Any], source: str = "") -> ReliefStyle | None:
    """:func:`trained_relief` of recordings whose driver entries are ``drivers``."""
    found = _recorded_reliefs(drivers)
    if not found or any(f != found[0] for f in found) or found[0] is None:
        return None
    style = ReliefStyle.written(found[0])
    if style is None:
        raise UserError(
            source,
            "the relief style of the driver its recordings were driven by cannot be read; give the driver's with --relief-style",
            field="data.recordings[].driver.config.relief",
        )
    return style


def relief_styles_differ(meta: Mapping[str, Any]) -> bool:
    """Whether a model's recordings' synthetic drivers took relief differently: some by a relief
    style and some as if flat, or by two styles (no one driver to compare the model with)."""
    found = _recorded_reliefs(_recorded_drivers(meta))
    return any(f is not None for f in found) and any(f != found[0] for f in found)


RUN_XY_STEP_S = 0.1  # a run's kept path (RunResult.xy): its reference point every third 30 Hz tick [s]


def speed_along(xy: np.ndarray, path: ReferencePath) -> tuple[np.ndarray, np.ndarray]:
    """Progress along ``path`` [m] and speed [m/s] of a run's kept reference points ``xy`` (T, 2)
    (:data:`RUN_XY_STEP_S` apart), both (T - 1,)."""
    xy = np.asarray(xy, dtype=float)
    speed = np.hypot(*np.diff(xy, axis=0).T) / RUN_XY_STEP_S
    s, progress = [], 0.0
    for point in xy[1:]:
        progress = max(progress, path.project(point, progress - 2.0, progress + 10.0)[0])
        s.append(progress)
    return np.array(s), speed


def zone_spans(scenario: Scenario, step_m: float = 0.25) -> list[tuple[str, float, float]]:
    """(zone id and label, first and last progress [m]) of the stretch of the path inside each zone the path crosses."""
    path = ReferencePath(scenario.waypoints)
    s = np.arange(0.0, path.length_m + 1e-9, step_m)
    points = path.point_at(s)
    spans = []
    for zone in scenario.zones:
        inside = zone.shape.contains(points)
        if inside.any():
            spans.append((f"{zone.id}: {zone.label}" if zone.label else zone.id, float(s[inside].min()), float(s[inside].max())))
    return spans


def save_speed_along(
    out: str | Path, results: Sequence[RunResult], scenario: Scenario, name: str, zones: bool = False, seed: int = 0
) -> Path | None:
    """The figure of speed along ``scenario``'s path (run as ``name``), the driver's and the
    planner's run of ``seed`` (each where it ran), with the zones shaded (``zones``); on relief,
    with the ground's height under each run below; None when neither ran."""
    from terrapref.plots import save_speed_profile
    from terrapref.world import rasterise

    reference = ReferencePath(scenario.waypoints)
    series, tracks = [], []
    for who, colour in ((EXPERT, "black"), (PLANNER, "red")):
        run = next((r for r in results if r.driver == who and r.scenario == name and r.seed == seed), None)
        if run is not None:
            series.append((who, *speed_along(run.xy, reference), colour))
            tracks.append(np.asarray(run.xy, dtype=float)[1:])
    if not series:
        return None
    drivers = " and ".join(label for label, *_ in series)
    spans = zone_spans(scenario) if zones else ()
    if not scenario.has_relief:
        return save_speed_profile(out, series, f"{name}: speed along the path, {drivers} (seed {seed})", spans)
    world = rasterise(scenario)
    heights = [world.height_at(xy) for xy in tracks]
    return save_speed_profile(out, series, f"{name}: speed and ground height along the path, {drivers} (seed {seed})", spans, heights)
