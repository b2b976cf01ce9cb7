"""Relief for a course that has none: features placed by the course's own geometry, from a seed.

The path is cut into the stretches between its zones and the relief it has (the path through a
zone's situation, and through a teaching course's relief situation, gets no feature; a feature
beside the path or at a bend may still reach into a zone's ground), each at most
:data:`STRETCH_M` long, the first :data:`CLEAR_M` of the path (the start) and its last metres
left out. Each stretch gets one feature drawn at random among
those that fit in it, a bump or a dip only where no larger one fits:

- ``mound``: a round hill on the path, 0.3-0.5 m high, 2.5-4 m in radius;
- ``ramp``: a plateau across the path, 0.3-0.6 m high, its ramps 4-5 m long (a grade of at most
  0.15) up to a 3-5 m top;
- ``ditch``: a ditch 0.3-0.5 m deep and 2.5-3.5 m wide beside the path, 3.5-5 m off it;
- ``bank``: the same, raised;
- ``rough``: a rough patch across the path, 5-9 m long and 8 m across: short noise (0.3 m
  across) of 0.04-0.07 m, rough from about 0.011 to 0.019 m (the heights' deviation about their
  plane within 0.3 m), on both sides of the default relief style's 0.015 m, its steps under 0.1 m;
- ``bump``: a low ridge across the path, 0.1-0.2 m high and 1.5-2.5 m wide;
- ``dip``: the same, sunken (a swale);

and the whole map gentle noise (0.1 m, 15 m across). The same course and seed give the same
relief. ``genrelief:SEED`` is ``gen:SEED``'s layout with the relief of seed SEED; the packaged
``teach_relief`` is the default table's teaching course with relief situations
(terrapref.scenario.teaching) with the relief of seed 0 between them.
"""

from __future__ import annotations

import math

import numpy as np

from terrapref.scenario.loader import parse_scenario
from terrapref.scenario.model import Scenario
from terrapref.scenario.path import ReferencePath

STRETCH_M = 20.0  # the longest stretch of path one feature is placed in [m]
CLEAR_M = 8.0  # the path's first and last metres stay flat (the start and the goal) [m]
STEP_M = 0.5  # the path is sampled this often when finding what its zones cover [m]
NEEDS_M = {"mound": 7.0, "ramp": 13.0, "ditch": 8.0, "bank": 8.0, "rough": 8.0}  # the shortest stretch each kind fits in [m]
SMALL_NEEDS_M = {"bump": 3.0, "dip": 3.0}  # the same, of the kinds for a stretch too short for the others [m]
NOISE = {"amplitude_m": 0.1, "wavelength_m": 15.0}


def with_relief(scenario: Scenario, seed: int, name: str | None = None) -> Scenario:
    """``scenario`` with the relief of ``seed`` added after any it has, named ``name`` (default:
    its own name)."""
    data = scenario.to_dict()
    data["name"] = name or scenario.name
    data["relief"] = [*data.get("relief", []), *relief_for(scenario, seed)]
    return parse_scenario(data, data["name"], scenario.classes)


def relief_for(scenario: Scenario, seed: int) -> list[dict]:
    """The ``relief:`` entries (as the file writes them) of ``seed`` for ``scenario``'s path and zones."""
    rng = np.random.default_rng([seed, 7919])
    path = ReferencePath(scenario.waypoints)
    entries: list[dict] = [{"noise": {**NOISE, "seed": int(rng.integers(2**31))}}]
    for s0, s1 in _stretches(scenario, path):
        fits = [kind for kind, needs in NEEDS_M.items() if s1 - s0 >= needs]
        fits = fits or [kind for kind, needs in SMALL_NEEDS_M.items() if s1 - s0 >= needs]
        if fits:
            kind = str(fits[int(rng.integers(len(fits)))])
            entries.append(_feature(rng, kind, path, s0, s1))
    return entries


def _stretches(scenario: Scenario, path: ReferencePath) -> list[tuple[float, float]]:
    """The stretches (s0, s1) [m] of arc length between the zones, each at most STRETCH_M long."""
    s = np.arange(CLEAR_M, path.length_m - CLEAR_M, STEP_M)
    free = np.ones(len(s), dtype=bool)
    points = path.point_at(s)
    for zone in scenario.zones:
        free &= ~zone.shape.contains(points)
    for entry in scenario.relief:  # relief the course has (its relief situations) keeps its own ground
        box = entry.bounds()
        if box is not None:
            x0, y0, x1, y1 = box
            free &= ~((points[:, 0] >= x0 - 1.0) & (points[:, 0] <= x1 + 1.0) & (points[:, 1] >= y0 - 1.0) & (points[:, 1] <= y1 + 1.0))
    out: list[tuple[float, float]] = []
    edges = np.flatnonzero(np.diff(np.concatenate([[0], free.astype(np.int8), [0]])))
    for start, stop in zip(edges[::2], edges[1::2]):
        lo, hi = float(s[start]), float(s[stop - 1])
        pieces = max(1, math.ceil((hi - lo) / STRETCH_M))
        out += [(lo + (hi - lo) * k / pieces, lo + (hi - lo) * (k + 1) / pieces) for k in range(pieces)]
    return out


def _feature(rng: np.random.Generator, kind: str, path: ReferencePath, s0: float, s1: float) -> dict:
    """One ``kind`` of feature that fits in the stretch s0..s1 [m] of the path."""
    mid, room = (s0 + s1) / 2, s1 - s0 - 2.0  # a metre clear at each end
    x, y, ux, uy = path.frame_at(mid)
    if kind == "mound":
        radius, lateral = min(rng.uniform(2.5, 4.0), room / 2), rng.uniform(-0.5, 0.5)
        center = [x - uy * lateral, y + ux * lateral]
        return {"mound": {"center": _rounded(center), "radius": round(radius, 3), "height_m": round(rng.uniform(0.3, 0.5), 3)}}
    if kind == "ramp":
        top, ramp, half_across = rng.uniform(3.0, 5.0), rng.uniform(4.0, 5.0), 7.0
        top = min(top, room - 2 * ramp)
        corners = [(-top / 2, -half_across), (top / 2, -half_across), (top / 2, half_across), (-top / 2, half_across)]
        polygon = [[x + a * ux - b * uy, y + a * uy + b * ux] for a, b in corners]
        return {"plateau": {"polygon": _rounded(polygon), "height_m": round(rng.uniform(0.3, 0.6), 3), "edge_m": round(ramp, 3)}}
    if kind == "rough":
        length, half_across = min(rng.uniform(5.0, 9.0), room), 4.0
        corners = [(-length / 2, -half_across), (length / 2, -half_across), (length / 2, half_across), (-length / 2, half_across)]
        polygon = [[x + a * ux - b * uy, y + a * uy + b * ux] for a, b in corners]
        noise = {"amplitude_m": round(rng.uniform(0.04, 0.07), 3), "wavelength_m": 0.3, "seed": int(rng.integers(2**31))}
        return {"noise": {**noise, "polygon": _rounded(polygon)}}
    if kind in ("bump", "dip"):
        width, half_across = min(rng.uniform(1.5, 2.5), room), 6.0
        line = [[x + uy * half_across, y - ux * half_across], [x - uy * half_across, y + ux * half_across]]
        height = rng.uniform(0.1, 0.2) * (1.0 if kind == "bump" else -1.0)
        return {"ridge": {"polyline": _rounded(line), "width_m": round(width, 3), "height_m": round(height, 3)}}
    side, length = (1.0 if rng.uniform() < 0.5 else -1.0), min(12.0, room)
    offset, width = side * rng.uniform(3.5, 5.0), rng.uniform(2.5, 3.5)
    along = np.linspace(mid - length / 2, mid + length / 2, 5)
    line = path.point_at(along) + offset * np.stack([-path.direction_at(along)[:, 1], path.direction_at(along)[:, 0]], axis=1)
    depth = rng.uniform(0.3, 0.5) * (-1.0 if kind == "ditch" else 1.0)
    return {"ridge": {"polyline": _rounded(line.tolist()), "width_m": round(width, 3), "height_m": round(depth, 3)}}


def _rounded(value: list) -> list:
    """Coordinates [m] rounded to the millimetre, as a file keeps them."""
    if isinstance(value[0], list | tuple | np.ndarray):
        return [_rounded(list(v)) for v in value]
    return [round(float(v), 3) for v in value]
