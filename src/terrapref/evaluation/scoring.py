"""Score a driven run against a scenario (SPEC 12).

A zone's choice: inside the zone, sum the distance the vehicle's reference point travels on
each non-background class; the largest sum, if above a tolerance (0.3 m), is the choice,
otherwise ``avoid``. The zone succeeds when the choice equals the expectation (``best``
resolved under the profile being tested) and no lethal cell was driven on inside it (unless a
lethal class was expected). A zone's clearance is how close the reference point came to the
terrain it did not choose (every patch, when it avoided them): the margin a driver keeps.

Only what was driven counts: a zone the vehicle did not get past (it never entered it, or its
progress along the path stopped short of where the path leaves the zone) is
:data:`NOT_REACHED`, a failure, whatever it would have expected. Lethal terrain counts
under the whole footprint (the line across the vehicle), not only under its reference point.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, fields, replace

import numpy as np

from terrapref.records import from_plain, to_plain
from terrapref.scenario import AVOID, Scenario, Zone
from terrapref.scenario.path import ReferencePath
from terrapref.sim import EpisodeLog
from terrapref.terrain import PreferenceProfile
from terrapref.vehicle import VehicleConfig, wrap_angle
from terrapref.world import WorldMap

NOT_REACHED = "not reached"  # a zone's choice when the vehicle did not get past it
REACHED_TOLERANCE_M = 0.5  # progress this short of the zone's end along the path still counts as past it


@dataclass(frozen=True)
class ZoneScoring:
    """How zones are scored.

    Attributes:
        tolerance_m: a class is the zone's choice when more than this much was driven on it [m].
        footprint_m: the vehicle's footprint across (VehicleConfig.footprint_m): lethal
            terrain under any of its points touches it [m].
    """

    tolerance_m: float = 0.3
    footprint_m: tuple[float, ...] = (-0.6, -0.3, 0.0, 0.3, 0.6)


def segments(xy: np.ndarray, max_step_m: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Split a polyline (T, 2) into short pieces: their midpoints (K, 2) and lengths (K,) [m]."""
    xy = np.asarray(xy, dtype=float)
    if len(xy) < 2:
        return np.zeros((0, 2)), np.zeros(0)
    d = np.diff(xy, axis=0)
    length = np.linalg.norm(d, axis=1)
    parts = _parts(length, max_step_m)
    seg = np.repeat(np.arange(len(d)), parts)
    # Fraction along each segment of every piece's midpoint.
    first = np.concatenate([[0], np.cumsum(parts)[:-1]])
    k = np.arange(len(seg)) - np.repeat(first, parts)
    frac = (k + 0.5) / parts[seg]
    mid = xy[seg] + frac[:, None] * d[seg]
    return mid, length[seg] / parts[seg]


def piece_times(xy: np.ndarray, dt_s: float, max_step_m: float = 0.05) -> np.ndarray:
    """The time [s] spent on each piece :func:`segments` cuts the polyline ``xy`` (T, 2) into, its
    points ``dt_s`` apart: each step's time shared evenly between its pieces."""
    xy = np.asarray(xy, dtype=float)
    if len(xy) < 2:
        return np.zeros(0)
    parts = _parts(np.linalg.norm(np.diff(xy, axis=0), axis=1), max_step_m)
    return np.repeat(dt_s / parts, parts)


def _parts(length: np.ndarray, max_step_m: float) -> np.ndarray:
    """How many pieces of at most ``max_step_m`` each step of ``length`` [m] is cut into (at least one)."""
    return np.maximum(1, np.ceil(length / max_step_m).astype(int))


def classes_in_zone(zone: Zone, world: WorldMap) -> list[str]:
    """Non-background classes painted inside a zone (cells whose centres lie in it)."""
    res = world.resolution_m
    x0, y0, x1, y1 = zone.shape.bounds()
    ny, nx = world.raster.shape
    c0, c1 = max(0, int(x0 / res)), min(nx, int(np.ceil(x1 / res)) + 1)
    r0, r1 = max(0, int(y0 / res)), min(ny, int(np.ceil(y1 / res)) + 1)
    if c0 >= c1 or r0 >= r1:
        return []
    gx, gy = np.meshgrid((np.arange(c0, c1) + 0.5) * res, (np.arange(r0, r1) + 0.5) * res)
    inside = zone.shape.contains(np.stack([gx.ravel(), gy.ravel()], axis=1))
    ids = np.unique(world.raster[r0:r1, c0:c1].ravel()[inside])
    classes = world.classes
    return [classes.name_of(int(i)) for i in ids if int(i) != classes.background_id]


@dataclass(frozen=True)
class ZoneResult:
    id: str
    label: str
    expect: str  # as resolved: avoid or a class name
    choice: str
    success: bool
    touched_lethal: bool
    distance_m: dict[str, float]
    clearance_m: float | None = None  # closest approach to terrain not chosen; None: none in reach
    reached: bool = True  # the vehicle got past the zone (else its choice is NOT_REACHED)
    speed_mps: float | None = None  # the mean speed while the reference point was in the zone [m/s]; None: never in it, or not timed
    grade_band: str | None = None  # on relief, the zone's grade as driven (GRADE_BANDS: its mean over the time in it); None: flat

    def to_dict(self) -> dict:
        return to_plain(self, omit_none=("grade_band",))

    @classmethod
    def from_dict(cls, data: dict) -> ZoneResult:
        """A zone as :meth:`to_dict` wrote it; keys a report added (the driver's choice) are left out."""
        return cls(**{f.name: data[f.name] for f in fields(cls) if f.name in data})


def score_zones(
    trace: np.ndarray,
    scenario: Scenario,
    world: WorldMap,
    profile: PreferenceProfile,
    progress_m: float | None = None,
    rules: ZoneScoring = ZoneScoring(),
) -> list[ZoneResult]:
    """Score every zone of ``scenario`` for the driven path ``trace``.

    Args:
        trace: the reference point's path, (T, 2) [m]; or its poses, (T, 3) [m, m, rad], and then
            lethal terrain under any point of the footprint inside a zone is touching it.
        progress_m: how far along the path the run got [m]; a zone whose end along the path
            lies beyond it is not reached. None: the run is taken to have passed every zone
            it entered.
        rules: the zone rules (the choice's tolerance, the footprint).
    """
    trace = np.asarray(trace, dtype=float)
    xy, yaw = trace[:, :2], (trace[:, 2] if trace.ndim == 2 and trace.shape[1] == 3 else None)
    tolerance_m, footprint_m = rules.tolerance_m, rules.footprint_m
    mid, length = segments(xy)
    cls = world.class_at(mid)
    classes = world.classes
    lethal = np.zeros(256, dtype=bool)
    lethal[list(classes.lethal_ids)] = True
    under = _footprint_lethal(xy, yaw, world, lethal, footprint_m) if yaw is not None else None
    path = ReferencePath(scenario.waypoints)
    results = []
    for zone in scenario.zones:
        inside = zone.shape.contains(mid) if len(mid) else np.zeros(0, bool)
        dist: dict[str, float] = {}
        for cid in np.unique(cls[inside]):
            if int(cid) == classes.background_id or int(cid) == 255:
                continue
            dist[classes.name_of(int(cid))] = round(float(length[inside & (cls == cid)].sum()), 3)
        top = max(dist.items(), key=lambda kv: kv[1], default=(AVOID, 0.0))
        expect = zone.resolve_expect(classes_in_zone(zone, world), profile, classes)
        touched = bool(lethal[cls[inside]].any())
        if under is not None and len(xy):
            touched |= bool(under[zone.shape.contains(np.asarray(xy, dtype=float))].any())
        reached = _passed(zone, path, progress_m, bool(inside.any()))
        choice = (top[0] if top[1] > tolerance_m else AVOID) if reached else NOT_REACHED
        expected_lethal = expect in classes.lethal
        success = reached and choice == expect and (not touched or expected_lethal)
        clearance = _clearance(mid[inside], world, exclude=classes.id_of(choice) if choice in classes.names else None)
        results.append(ZoneResult(zone.id, zone.label, expect, choice, success, touched, dist, clearance, reached))
    return results


def zone_end_m(zone: Zone, path: ReferencePath, step_m: float = 0.1) -> float | None:
    """Where the path leaves ``zone`` for the last time, as arc length [m]; None when it never enters it."""
    s = np.arange(0.0, path.length_m + step_m / 2, step_m)
    inside = zone.shape.contains(path.point_at(s))
    return float(s[inside].max()) if inside.any() else None


def _passed(zone: Zone, path: ReferencePath, progress_m: float | None, entered: bool) -> bool:
    """Whether the run got past ``zone``: it entered the zone and, for a zone the path crosses,
    its progress along the path reached the zone's end (a vehicle that stands still inside a
    zone has not got past it; progress alone is not enough, as a vehicle driving beside the
    path far off it still makes progress along it)."""
    if not entered:
        return False
    end = zone_end_m(zone, path) if progress_m is not None else None
    return end is None or progress_m >= min(end, path.length_m) - REACHED_TOLERANCE_M


def _footprint_lethal(xy: np.ndarray, yaw: np.ndarray, world: WorldMap, lethal: np.ndarray, footprint_m: tuple[float, ...]) -> np.ndarray:
    """Whether lethal terrain lies under any footprint point at each pose (T,)."""
    xy = np.asarray(xy, dtype=float)
    across = np.asarray(footprint_m, dtype=float)
    yaw = np.asarray(yaw, dtype=float)[:, None]
    points = np.stack([xy[:, 0:1] - across * np.sin(yaw), xy[:, 1:2] + across * np.cos(yaw)], axis=-1)
    return lethal[world.class_at(points)].any(axis=1)


CLEARANCE_REACH_M = 3.0  # terrain farther than this from the path in a zone does not count
CLEARANCE_STEP_M = 0.1  # points of the path, this far apart, measured from


def _clearance(points: np.ndarray, world: WorldMap, exclude: int | None) -> float | None:
    """Distance [m] from ``points`` (the path inside a zone) to the nearest cell of a non-background
    class other than ``exclude``, within reach; 0 where the path crossed such terrain.

    Measured to the edge cells of that terrain only (a cell of it with a 4-neighbour outside it),
    in a window around the points, so that it costs a few thousand distances per zone.
    """
    if len(points) == 0:
        return None
    points = points[:: max(1, int(round(CLEARANCE_STEP_M / 0.05)))]
    res = world.resolution_m
    ny, nx = world.raster.shape
    lo, hi = points.min(axis=0) - CLEARANCE_REACH_M, points.max(axis=0) + CLEARANCE_REACH_M
    c0, r0 = max(0, int(lo[0] / res)), max(0, int(lo[1] / res))
    c1, r1 = min(nx, int(np.ceil(hi[0] / res))), min(ny, int(np.ceil(hi[1] / res)))
    if c0 >= c1 or r0 >= r1:
        return None
    window = world.raster[r0:r1, c0:c1]
    other = (window != world.classes.background_id) & (window != 255)
    if exclude is not None:
        other &= window != exclude
    if not other.any():
        return None
    padded = np.pad(other, 1, constant_values=False)
    interior = padded[:-2, 1:-1] & padded[2:, 1:-1] & padded[1:-1, :-2] & padded[1:-1, 2:]
    rows, cols = np.nonzero(other & ~interior)
    cells = np.stack([(cols + c0 + 0.5) * res, (rows + r0 + 0.5) * res], axis=1)
    d = np.sqrt(((points[:, None, :] - cells[None, :, :]) ** 2).sum(axis=2)).min()
    if d > CLEARANCE_REACH_M:
        return None
    inside = other[
        np.clip((points[:, 1] / res).astype(int) - r0, 0, r1 - r0 - 1), np.clip((points[:, 0] / res).astype(int) - c0, 0, c1 - c0 - 1)
    ]
    return 0.0 if inside.any() else round(float(d), 3)


@dataclass(frozen=True)
class RunMetrics:
    """What a run reports besides its zones (SPEC 12)."""

    completed: bool
    collisions: int
    duration_s: float
    rms_cross_track_m: float
    max_cross_track_m: float
    rms_cross_track_outside_zones_m: float
    distance_m: dict[str, float]
    zones: list[ZoneResult] = field(default_factory=list)
    ended: str | None = None  # how the run ended: goal, stopped (stood still for good) or time limit (None: not recorded)
    progress_m: float | None = None  # how far along the path it got [m]
    contact_s: float = 0.0  # time with lethal terrain under the footprint [s]
    contact_m: float = 0.0  # distance driven so [m]
    stop_count: int = 0  # times the vehicle came to a stop
    stops_s: dict[str, float] = field(default_factory=dict)  # seconds stood still, by reason
    # By class under the reference point: the mean speed there ("mps") and the seconds spent there ("s").
    speed_by_class_mps: dict[str, dict[str, float]] = field(default_factory=dict)
    time_s: float | None = None  # the time to the end of the path, or to the end of the run [s]
    max_lateral_accel_mps2: float = 0.0  # the largest |v w| over the run's controller ticks [m/s^2]
    # A planner's stop at its own goal, driven on past completion: {"stopped", "after_s", "from_end_m"} (None: not watched).
    goal_stop: dict[str, float | bool] | None = None
    tips: int = 0  # entries past the vehicle's roll or pitch limit (SPEC 19)
    stuck: int = 0  # times a step higher than the vehicle climbs held it
    max_roll_deg: float = 0.0  # the largest |roll| of any controller tick [deg]
    max_pitch_deg: float = 0.0  # the largest |pitch| [deg]
    # On relief, by grade band (GRADE_BANDS) of the ground driven: the mean speed ("mps") and the seconds ("s"); None: flat.
    speed_by_grade_mps: dict[str, dict[str, float]] | None = None
    # On relief, by roughness band (ROUGH_BANDS) of the ground driven, likewise; None: flat.
    speed_by_roughness_mps: dict[str, dict[str, float]] | None = None
    relief_zones: list[ReliefZoneResult] | None = None  # on relief, how it passed each relief zone (relief_zones); None: flat

    @property
    def incidents(self) -> int:
        """Collisions, tips and times stuck: what counts against the run's safety."""
        return self.collisions + self.tips + self.stuck

    @property
    def zone_successes(self) -> int:
        return sum(z.success for z in self.zones)

    @property
    def ending(self) -> str:
        """How the run ended; for metrics that did not record it, the goal or the time limit by ``completed``."""
        return self.ended or ("goal" if self.completed else "time limit")

    @property
    def driven_m(self) -> float:
        """The distance the reference point travelled [m]."""
        return float(sum(self.distance_m.values()))

    def to_dict(self) -> dict:
        return to_plain(self, omit_none=("speed_by_grade_mps", "speed_by_roughness_mps", "relief_zones"))

    @classmethod
    def from_dict(cls, data: dict) -> RunMetrics:
        """Metrics as :meth:`to_dict` wrote them."""
        return from_plain(cls, data)


def score_run(
    log: EpisodeLog, scenario: Scenario, world: WorldMap, profile: PreferenceProfile, rules: ZoneScoring = ZoneScoring()
) -> RunMetrics:
    """All metrics of the run ``log`` of ``scenario`` on ``world``: from its path (every controller
    tick's pose), whether it completed and how it ended, its collisions and contact, its stops
    and its duration; ``rules`` how its zones are scored."""
    xy = log.trace[:, :2]
    path = ReferencePath(scenario.waypoints)
    mid, length = segments(xy)
    err = path.distance_to(mid) if len(mid) else np.zeros(0)
    in_zone = np.zeros(len(mid), bool)
    for z in scenario.zones:
        in_zone |= z.shape.contains(mid) if len(mid) else in_zone
    out = ~in_zone

    def rms(mask: np.ndarray) -> float:
        w = length[mask]
        return float(np.sqrt((err[mask] ** 2 * w).sum() / w.sum())) if w.sum() > 0 else 0.0

    cls = world.class_at(mid)
    classes = world.classes
    dist = {c.name: round(float(length[cls == c.id].sum()), 3) for c in classes.classes}
    dt_s = log.duration_s / (len(xy) - 1) if len(xy) > 1 else 0.0  # the controller's tick
    time = piece_times(xy, dt_s)
    speeds = {
        c.name: {"mps": round(float(length[on].sum() / time[on].sum()), 4), "s": round(float(time[on].sum()), 3)}
        for c in classes.classes
        if (on := cls == c.id).any() and time[on].sum() > 0
    }
    grade = grade_along(log.trace, mid, world) if world.has_relief else None
    zones = _timed(score_zones(log.trace, scenario, world, profile, log.progress_m, rules), scenario, (mid, length, time, grade))
    return RunMetrics(
        completed=log.completed,
        collisions=log.collisions,
        duration_s=round(log.duration_s, 3),
        rms_cross_track_m=round(rms(np.ones(len(mid), bool)), 4),
        max_cross_track_m=round(float(err.max()) if len(err) else 0.0, 4),
        rms_cross_track_outside_zones_m=round(rms(out), 4),
        distance_m=dist,
        zones=zones,
        ended=log.ended,
        progress_m=round(log.progress_m, 3),
        contact_s=round(log.contact_s, 3),
        contact_m=round(log.contact_m, 3),
        stop_count=log.stop_count,
        stops_s={k: round(v, 3) for k, v in sorted(log.stops.items())},
        speed_by_class_mps=speeds,
        time_s=round(log.duration_s, 3),
        max_lateral_accel_mps2=round(_max_lateral_accel(log.trace, dt_s), 4),
        goal_stop=asdict(log.goal_stop) if log.goal_stop is not None else None,
        speed_by_grade_mps=_by_band(_grade_bands(grade), GRADE_BANDS, length, time) if grade is not None else None,
        speed_by_roughness_mps=_by_band(_rough_bands(world.roughness_at(mid)), ROUGH_BANDS, length, time) if world.has_relief else None,
        relief_zones=score_relief_zones(xy, path, relief_zones(path, world), log.progress_m) if world.has_relief else None,
        **log.relief_summary(),
    )


def _timed(zones: list[ZoneResult], scenario: Scenario, pieces: tuple[np.ndarray, ...]) -> list[ZoneResult]:
    """``zones`` (of ``scenario``'s) with the mean speed and, on relief, the grade band of the
    run's ``pieces`` in each (their midpoints, lengths, times and grades: None on flat ground)."""
    mid, length, time, grade = pieces
    out = []
    for z, zone in zip(zones, scenario.zones, strict=True):
        inside = zone.shape.contains(mid) if len(mid) else np.zeros(0, bool)
        timed = time[inside].sum() > 0
        speed = round(float(length[inside].sum() / time[inside].sum()), 4) if timed else None
        band = grade_band(float(np.average(grade[inside], weights=time[inside]))) if grade is not None and timed else None
        out.append(replace(z, speed_mps=speed, grade_band=band))
    return out


# A run's ground on relief, by the body's pitch along its heading as driven: up past this
# angle, down past it, level between [deg] (a grade of about 1:19, which the synthetic driver's
# default relief style slows for by 0.09 m/s).
GRADE_BAND_DEG = 3.0
GRADE_BANDS = ("up", "level", "down")
# And by the ground's roughness under its reference point (terrapref.world.WorldMap.roughness_at):
# rough past this [m] (the default relief style's rough_m), smooth up to it.
ROUGH_BAND_M = 0.015
ROUGH_BANDS = ("rough", "smooth")


def grade_band(grade_rad: float) -> str:
    """The band (:data:`GRADE_BANDS`) of a grade [rad, positive up]."""
    degrees = math.degrees(grade_rad)
    return "up" if degrees > GRADE_BAND_DEG else "down" if degrees < -GRADE_BAND_DEG else "level"


def grade_along(trace: np.ndarray, mid: np.ndarray, world: WorldMap, max_step_m: float = 0.05) -> np.ndarray:
    """The grade [rad, positive up] of each piece :func:`segments` cut the driven path ``trace``
    into (their midpoints ``mid``): the body's pitch there heading as it did at the piece's step
    (the heights under its wheels half the default vehicle's wheelbase ahead and behind, as
    terrapref.vehicle.ground sets its attitude)."""
    xy = np.asarray(trace[:, :2], dtype=float)
    if len(xy) < 2:
        return np.zeros(0)
    yaw = np.repeat(trace[:-1, 2], _parts(np.linalg.norm(np.diff(xy, axis=0), axis=1), max_step_m))
    half = 0.5 * VehicleConfig().wheelbase_m
    ahead = np.stack([np.cos(yaw), np.sin(yaw)], axis=1) * half
    return np.arctan((world.height_at(mid + ahead) - world.height_at(mid - ahead)) / (2.0 * half))


# A relief zone: a stretch of the path whose own ground would tilt the body, heading along the
# path, past this angle across or along [deg] (the gentlest band the offset rule prices), its
# stretches less than RELIEF_GAP_M apart joined, and at least RELIEF_MIN_M long (a crest or a
# dip of a single read past the angle is no stretch to go round or over, and every run passes
# it alike). Its choice: where the run's reference point held, on average over the stretch, more
# than RELIEF_SIDE_M off the path, the side it went round by (``left``, ``right``); else ``over``.
RELIEF_ZONE_DEG = 4.0
RELIEF_GAP_M = 5.0
RELIEF_MIN_M = 1.0
RELIEF_SIDE_M = 0.5
RELIEF_STEP_M = 0.25  # the path is read this often [m]
RELIEF_CHOICES = ("over", "left", "right")


@dataclass(frozen=True)
class ReliefZoneResult:
    """How a run passed one relief zone (:func:`relief_zones`).

    Attributes:
        from_m, to_m: the zone's stretch of the path [m of arc length].
        choice: ``over``, ``left`` or ``right`` (RELIEF_CHOICES), or :data:`NOT_REACHED`.
        offset_m: the reference point's mean offset from the path over the stretch [m, left
            positive]; None where not reached.
    """

    from_m: float
    to_m: float
    choice: str
    offset_m: float | None = None

    def to_dict(self) -> dict:
        return to_plain(self)


def relief_zones(path: ReferencePath, world: WorldMap) -> list[tuple[float, float]]:
    """The relief zones (module comment above) of ``path`` on ``world``: their stretches (from, to)
    [m of arc length]; none on flat ground. The body is the default vehicle's: its track across,
    its wheelbase along, the heights under its wheels as terrapref.vehicle.ground sets its attitude."""
    if not world.has_relief or path.length_m < RELIEF_STEP_M:
        return []
    vehicle = VehicleConfig()
    across, along = vehicle.half_width_m, 0.5 * vehicle.wheelbase_m
    s = np.arange(0.0, path.length_m, RELIEF_STEP_M)
    centre, direction = path.point_at(s), path.direction_at(s)
    normal = np.stack([-direction[:, 1], direction[:, 0]], axis=1)
    roll = np.abs(world.height_at(centre + across * normal) - world.height_at(centre - across * normal)) / (2.0 * across)
    pitch = np.abs(world.height_at(centre + along * direction) - world.height_at(centre - along * direction)) / (2.0 * along)
    steep = np.flatnonzero(np.degrees(np.arctan(np.maximum(roll, pitch))) > RELIEF_ZONE_DEG)
    out: list[tuple[float, float]] = []
    for i in steep:
        if out and s[i] - out[-1][1] < RELIEF_GAP_M:
            out[-1] = (out[-1][0], float(s[i]))
        else:
            out.append((float(s[i]), float(s[i])))
    return [(round(a, 3), round(b, 3)) for a, b in out if b - a >= RELIEF_MIN_M]


def score_relief_zones(
    xy: np.ndarray, path: ReferencePath, zones: list[tuple[float, float]], progress_m: float | None
) -> list[ReliefZoneResult]:
    """How the run whose reference point drove ``xy`` (T, 2) [m] passed each relief zone (from
    :func:`relief_zones`): its mean offset from the path over the zone's stretch (each station's
    from the points within half a step of its line across the path, up to 5 m off), and the side
    that makes (module comment above). A zone the run's progress did not get past, or whose
    stations no point passed, is :data:`NOT_REACHED`."""
    xy = np.asarray(xy, dtype=float)
    out = []
    for s0, s1 in zones:
        s = np.arange(s0, s1 + 1e-9, RELIEF_STEP_M)
        centre, direction = path.point_at(s), path.direction_at(s)
        rel = xy[None, :, :] - centre[:, None, :]  # (Q, T, 2)
        ahead = np.einsum("qtk,qk->qt", rel, direction)
        side = rel[..., 1] * direction[:, None, 0] - rel[..., 0] * direction[:, None, 1]  # left of the path positive
        near = (np.abs(ahead) <= RELIEF_STEP_M / 2) & (np.abs(side) <= 5.0)
        seen = near.any(axis=1)
        passed = progress_m is None or progress_m >= s1 - REACHED_TOLERANCE_M
        if not seen.any() or not passed:
            out.append(ReliefZoneResult(s0, s1, NOT_REACHED))
            continue
        per_station = np.where(near, side, 0.0).sum(axis=1)[seen] / near.sum(axis=1)[seen]
        offset = float(per_station.mean())
        choice = "left" if offset > RELIEF_SIDE_M else "right" if offset < -RELIEF_SIDE_M else "over"
        out.append(ReliefZoneResult(s0, s1, choice, round(offset, 3)))
    return out


def _grade_bands(grade: np.ndarray) -> np.ndarray:
    """The band (:data:`GRADE_BANDS`) of each grade [rad, positive up] of ``grade``."""
    degrees = np.degrees(grade)
    return np.where(degrees > GRADE_BAND_DEG, "up", np.where(degrees < -GRADE_BAND_DEG, "down", "level"))


def _rough_bands(roughness: np.ndarray) -> np.ndarray:
    """The band (:data:`ROUGH_BANDS`) of each roughness [m] of ``roughness``."""
    return np.where(roughness > ROUGH_BAND_M, "rough", "smooth")


def _by_band(bands: np.ndarray, names: tuple[str, ...], length: np.ndarray, time: np.ndarray) -> dict[str, dict[str, float]]:
    """The mean speed and the seconds of each band of ``names`` a run's pieces (their ``bands``,
    ``length`` and ``time``) fall in, the bands with time in them."""
    return {
        band: {"mps": round(float(length[on].sum() / time[on].sum()), 4), "s": round(float(time[on].sum()), 3)}
        for band in names
        if (on := bands == band).any() and time[on].sum() > 0
    }


def _max_lateral_accel(trace: np.ndarray, dt_s: float) -> float:
    """The largest |v w| [m/s^2] between consecutive controller ticks of ``trace`` (T, 3): v the
    step's length over ``dt_s``, w its turn (wrapped to +-pi) over ``dt_s``."""
    if len(trace) < 2 or dt_s <= 0:
        return 0.0
    step = np.diff(trace, axis=0)
    v = np.hypot(step[:, 0], step[:, 1]) / dt_s
    w = wrap_angle(step[:, 2])
    return float(np.max(np.abs(v * w / dt_s)))
