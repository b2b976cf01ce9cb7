"""Score a driven run against a scenario (SPEC 12).

A zone's choice: inside the zone, sum the distance the vehicle's reference point travels on
each non-background class; the largest sum, if above a tolerance (0.3 m), is the choice,
otherwise ``avoid``. The zone succeeds when the choice equals the expectation (``best``
resolved under the profile being tested) and no lethal cell was driven on inside it (unless a
lethal class was expected). A zone's clearance is how close the reference point came to the
terrain it did not choose (every patch, when it avoided them): the margin a driver keeps.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

from terrapref.records import from_plain, to_plain
from terrapref.scenario import AVOID, Scenario, Zone
from terrapref.scenario.path import ReferencePath
from terrapref.sim import EpisodeLog
from terrapref.terrain import PreferenceProfile
from terrapref.world import WorldMap


def segments(xy: np.ndarray, max_step_m: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Split a polyline (T, 2) into short pieces: their midpoints (K, 2) and lengths (K,) [m]."""
    xy = np.asarray(xy, dtype=float)
    if len(xy) < 2:
        return np.zeros((0, 2)), np.zeros(0)
    d = np.diff(xy, axis=0)
    length = np.linalg.norm(d, axis=1)
    parts = np.maximum(1, np.ceil(length / max_step_m).astype(int))
    seg = np.repeat(np.arange(len(d)), parts)
    # Fraction along each segment of every piece's midpoint.
    first = np.concatenate([[0], np.cumsum(parts)[:-1]])
    k = np.arange(len(seg)) - np.repeat(first, parts)
    frac = (k + 0.5) / parts[seg]
    mid = xy[seg] + frac[:, None] * d[seg]
    return mid, length[seg] / parts[seg]


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


    def to_dict(self) -> dict:
        return to_plain(self)

    @classmethod
    def from_dict(cls, data: dict) -> ZoneResult:
        """A zone as :meth:`to_dict` wrote it; keys a report added (the driver's choice) are left out."""
        return cls(**{f.name: data[f.name] for f in fields(cls) if f.name in data})


def score_zones(xy: np.ndarray, scenario: Scenario, world: WorldMap, profile: PreferenceProfile, tolerance_m: float = 0.3) -> list[ZoneResult]:
    """Score every zone of ``scenario`` for the driven reference-point path ``xy`` (T, 2)."""
    mid, length = segments(xy)
    cls = world.class_at(mid)
    classes = world.classes
    lethal = set(classes.lethal_ids)
    results = []
    for zone in scenario.zones:
        inside = zone.shape.contains(mid) if len(mid) else np.zeros(0, bool)
        dist: dict[str, float] = {}
        for cid in np.unique(cls[inside]):
            if int(cid) == classes.background_id or int(cid) == 255:
                continue
            dist[classes.name_of(int(cid))] = round(float(length[inside & (cls == cid)].sum()), 3)
        top = max(dist.items(), key=lambda kv: kv[1], default=(AVOID, 0.0))
        choice = top[0] if top[1] > tolerance_m else AVOID
        expect = zone.resolve_expect(classes_in_zone(zone, world), profile, classes)
        touched = bool(np.isin(cls[inside], list(lethal)).any())
        expected_lethal = expect in classes.lethal
        success = choice == expect and (not touched or expected_lethal)
        clearance = _clearance(mid[inside], world, exclude=classes.id_of(choice) if choice != AVOID else None)
        results.append(ZoneResult(zone.id, zone.label, expect, choice, success, touched, dist, clearance))
    return results


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
    inside = other[np.clip((points[:, 1] / res).astype(int) - r0, 0, r1 - r0 - 1), np.clip((points[:, 0] / res).astype(int) - c0, 0, c1 - c0 - 1)]
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

    @property
    def zone_successes(self) -> int:
        return sum(z.success for z in self.zones)

    def to_dict(self) -> dict:
        return to_plain(self)

    @classmethod
    def from_dict(cls, data: dict) -> RunMetrics:
        """Metrics as :meth:`to_dict` wrote them."""
        return from_plain(cls, data)


def score_run(log: EpisodeLog, scenario: Scenario, world: WorldMap, profile: PreferenceProfile, tolerance_m: float = 0.3) -> RunMetrics:
    """All metrics of the run ``log`` of ``scenario`` on ``world``: from its reference-point path
    (every controller tick's x, y), whether it completed, its collisions and its duration."""
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
    return RunMetrics(
        completed=log.completed,
        collisions=log.collisions,
        duration_s=round(log.duration_s, 3),
        rms_cross_track_m=round(rms(np.ones(len(mid), bool)), 4),
        max_cross_track_m=round(float(err.max()) if len(err) else 0.0, 4),
        rms_cross_track_outside_zones_m=round(rms(out), 4),
        distance_m=dist,
        zones=score_zones(xy, scenario, world, profile, tolerance_m),
    )
