"""Load and validate ``terrapref-scenario/1`` files, reporting every problem with its field path."""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from collections.abc import Set as AbstractSet
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from terrapref.errors import ConfigError, Problem, ScenarioError, UserError, described, printed
from terrapref.scenario.model import AVOID, BEST, Scenario, TerrainPatch, Zone, grid_shape
from terrapref.scenario.relief import RELIEF_KINDS, Mound, Noise, Plateau, ReliefEntry, Ridge
from terrapref.scenario.shapes import Circle, Polygon, Rectangle, Shape
from terrapref.terrain import ClassTable, default_classes
from terrapref.yamlio import read_yaml_mapping

FORMAT = "terrapref-scenario/1"
MAX_CELLS = 100_000_000
# A start must leave clear of lethal terrain the footprint of the simulator's default vehicle (half
# its width, terrapref.vehicle.VehicleConfig, which lies in a layer above scenarios; a test keeps them equal) [m].
START_HALF_WIDTH_M = 0.6
_NAME = re.compile(r"[A-Za-z0-9_-]+")
_TOP_KEYS = frozenset({"format", "name", "description", "world", "terrain", "path", "start", "zones", "classes", "relief"})
_REQUIRED_KEYS = frozenset({"format", "name", "world", "path"})
_SHAPE_KEYS = ("polygon", "circle", "rectangle")
MAX_RELIEF_M = 1000.0  # the largest height or noise amplitude of one relief entry [m]
MIN_RELIEF_M = 0.001  # the least, either way: finer relief changes no height a vehicle or a depth camera tells [m]
MAX_RELIEF_REACH_M = 1e6  # relief's points lie within this distance of the map [m]
MAX_WAVELENGTH_M = 1e4  # the longest wavelength of noise [m]
# The widest a mound's radius, a ridge's width or a plateau's ramp may be [m]: as far as relief's
# points may lie from the map. A file giving 1e308 m raised the whole map by one constant.
MAX_RELIEF_SPAN_M = MAX_RELIEF_REACH_M
MAX_YAW_DEG = 1e6  # the largest start heading a file may give, either way [deg]


class _Checker:
    """Collects problems while converting untyped YAML values into typed ones."""

    def __init__(self) -> None:
        self.problems: list[Problem] = []
        self.unknown: dict[str, list[str]] = {}  # unknown class name -> the fields naming it

    def unknown_classes(self, classes: ClassTable) -> None:
        """One problem per unknown class name, at the first field naming it: a scenario made for
        another class table names its classes in many fields."""
        for name, fields in self.unknown.items():
            more = f" (and {len(fields) - 1} more fields)" if len(fields) > 1 else ""
            self.fail(
                fields[0],
                f"unknown class {name!r}{more}; known: {', '.join(classes.names)} "
                "(a scenario of another class table? give its --classes FILE)",
            )

    def fail(self, field: str, message: str) -> None:
        self.problems.append(Problem(field, message))

    def mapping(
        self, value: Any, field: str, required: AbstractSet[str], optional: AbstractSet[str] = frozenset(), *, unknown: str = "unknown key"
    ) -> dict | None:
        """``value`` as a mapping of the ``required`` and ``optional`` keys, each other key failed
        with the message ``unknown``; None after any failure."""
        if not isinstance(value, dict):
            self.fail(field, f"expected a mapping, got {described(value)}")
            return None
        ok = True
        for key in sorted(required - set(value), key=str):
            self.fail(_join(field, key), "missing")
            ok = False
        for key in sorted(set(value) - required - set(optional), key=_key_text):
            self.fail(_join(field, _key_text(key)), unknown)
            ok = False
        return value if ok else None

    def number(self, value: Any, field: str, *, positive: bool = False) -> float | None:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(field, f"expected a number, got {described(value)}")
            return None
        try:
            x = float(value)
        except OverflowError:  # an integer beyond the float range
            self.fail(field, "is too large")
            return None
        if not math.isfinite(x):
            self.fail(field, "must be finite (got NaN or infinity)")
            return None
        if positive and x <= 0:
            self.fail(field, "must be > 0")
            return None
        return x

    def vector(self, value: Any, field: str, length: int, *, positive: bool = False) -> tuple[float, ...] | None:
        if not isinstance(value, list) or len(value) != length:
            self.fail(field, f"expected a list of {length} numbers, got {described(value)}")
            return None
        items = [self.number(v, f"{field}[{i}]", positive=positive) for i, v in enumerate(value)]
        return None if any(v is None for v in items) else tuple(items)  # type: ignore[arg-type]

    def points(self, value: Any, field: str, minimum: int) -> np.ndarray | None:
        if not isinstance(value, list) or len(value) < minimum:
            self.fail(field, f"expected a list of at least {minimum} [x, y] points, got {described(value)}")
            return None
        pts = [self.vector(p, f"{field}[{i}]", 2) for i, p in enumerate(value)]
        return None if any(p is None for p in pts) else np.array(pts, dtype=float)

    def text(self, value: Any, field: str) -> str | None:
        if not isinstance(value, str):
            self.fail(field, f"expected a string, got {described(value)}")
            return None
        return value

    def class_name(self, value: Any, field: str, classes: ClassTable) -> str | None:
        name = self.text(value, field)
        if name is not None and name not in classes.names:
            self.unknown.setdefault(name, []).append(field)
            return None
        return name

    def shape(self, item: dict, field: str, size_m: tuple[float, float] | None) -> Shape | None:
        present = [k for k in _SHAPE_KEYS if k in item]
        if len(present) != 1:
            self.fail(field, f"expected exactly one of {', '.join(_SHAPE_KEYS)}, got {len(present)}")
            return None
        kind = present[0]
        f = f"{field}.{kind}"
        spec = item[kind]
        shape: Shape | None = None
        if kind == "polygon":
            pts = self.points(spec, f, 3)
            if pts is not None:
                distinct = np.unique(pts, axis=0)
                # Rounding in the shoelace sum grows with the coordinates squared, so collinear
                # vertices far from the origin leave a tiny area: judge it on scaled vertices.
                scale = max(1.0, float(np.abs(pts).max()))
                q = pts / scale
                area = _area(q)
                if len(distinct) < 3:
                    self.fail(f, f"needs at least 3 distinct vertices, got {len(distinct)}")
                elif area <= max(1e-12, 1e-9 / scale / scale):
                    crossing = _crossing_edges(q)  # a bow tie's halves cancel in the shoelace sum
                    self.fail(
                        f,
                        "has zero area (vertices are collinear)"
                        if crossing is None
                        else f"has zero area: it crosses itself (its edge from vertex {crossing[0]} crosses the one from vertex "
                        f"{crossing[1]}) and its parts cancel; give the vertices in order round it",
                    )
                else:
                    shape = Polygon(pts)
        elif kind == "circle":
            spec = self.mapping(spec, f, {"center", "radius"})
            if spec is not None:
                center = self.vector(spec["center"], f"{f}.center", 2)
                radius = self.number(spec["radius"], f"{f}.radius", positive=True)
                if center is not None and radius is not None:
                    shape = Circle((center[0], center[1]), radius)
        else:
            spec = self.mapping(spec, f, {"center", "size"}, {"yaw_deg"})
            if spec is not None:
                center = self.vector(spec["center"], f"{f}.center", 2)
                size = self.vector(spec["size"], f"{f}.size", 2, positive=True)
                yaw = self.number(spec.get("yaw_deg", 0.0), f"{f}.yaw_deg")
                if center is not None and size is not None and yaw is not None:
                    shape = Rectangle((center[0], center[1]), (size[0], size[1]), math.radians(yaw))
        if shape is not None and size_m is not None:
            x0, y0, x1, y1 = shape.bounds()
            if x1 <= 0 or y1 <= 0 or x0 >= size_m[0] or y0 >= size_m[1]:
                self.fail(
                    f, f"lies wholly off the map (bounds x {x0:g}..{x1:g}, y {y0:g}..{y1:g}; map 0..{size_m[0]:g} x 0..{size_m[1]:g})"
                )
                return None
        return shape


def _join(field: str, key: str) -> str:
    return f"{field}.{key}" if field else key


def _key_text(key: Any) -> str:
    """A mapping key as it appears in a field path, kept on one printable line."""
    text = key if isinstance(key, str) else printed(key)
    return text if text.isprintable() else repr(text)


def _on_map(p: np.ndarray, size_m: tuple[float, float]) -> np.ndarray:
    return (p[..., 0] >= 0) & (p[..., 0] <= size_m[0]) & (p[..., 1] >= 0) & (p[..., 1] <= size_m[1])


def parse_scenario(data: dict[str, Any], source: str = "", classes: ClassTable | None = None, driven: bool = False) -> Scenario:
    """Validate a parsed mapping and build a :class:`Scenario`, its class names read with
    ``classes`` or the table the scenario carries (``classes:``; neither: the default table).
    ``driven``: the scenario of a recording, whose start is history; else a start that puts the
    vehicle's footprint on lethal terrain is refused.

    Raises:
        ScenarioError: listing every problem found, each with its field path; a carried table
            that is not ``classes`` (by :meth:`ClassTable.same_classes`) alone; a start on lethal terrain alone.
    """
    c = _Checker()
    data = _header(c, data, source)
    classes = _carried_table(c, data, source, classes)
    name = _name(c, data)
    description = _description(c, data)
    world = _world(c, data, classes)
    terrain = _terrain(c, data.get("terrain", []), world.size_m, classes)
    waypoints = _waypoints(c, data, world.size_m)
    start = _start(c, data, waypoints, world.size_m)
    zones = _zones(c, data.get("zones", []), world.size_m, classes)
    relief = _relief(c, data.get("relief", []), world)
    c.unknown_classes(classes)
    if c.problems:
        raise ScenarioError(source, c.problems)
    assert name is not None and world.size_m is not None and world.resolution_m is not None and world.background is not None
    assert waypoints is not None and start is not None
    lethal = None if driven else _lethal_under_start(start, world, terrain, classes)
    if lethal is not None:
        where = "given" if "start" in data else "the first waypoint, facing the second"
        raise ScenarioError(
            source,
            f"({start[0]:g}, {start[1]:g}) ({where}) puts the vehicle's footprint on lethal terrain ({lethal}); "
            "start it clear of lethal terrain",
            field="start",
        )
    return Scenario(
        name=name,
        size_m=world.size_m,
        resolution_m=world.resolution_m,
        background=world.background,
        terrain=tuple(terrain),
        waypoints=waypoints,
        start=start,
        zones=tuple(zones),
        description=description,
        source=source,
        classes=classes,
        relief=tuple(relief),
    )


@dataclass(frozen=True)
class _World:
    """The checked ``world`` block; a field is None where its value was invalid.

    Attributes:
        size_m: map size (x, y) [m]; also None when its raster would exceed ``MAX_CELLS``.
        resolution_m: raster cell side [m].
        background: class name of every cell no patch covers.
    """

    size_m: tuple[float, float] | None = None
    resolution_m: float | None = None
    background: str | None = None


def _header(c: _Checker, data: dict[str, Any], source: str) -> dict[str, Any]:
    """Check the format and the top-level keys; a foreign format is refused at once, alone."""
    if not isinstance(data, Mapping):
        c.fail("", f"expected a mapping of scenario fields, got {described(data)}")
        raise ScenarioError(source, c.problems)
    if data.get("format") != FORMAT:
        got = data.get("format")
        c.fail("format", f"{'missing' if got is None else printed(got) + ' is not supported'}; expected {FORMAT!r}")
        raise ScenarioError(source, c.problems)
    top = c.mapping(data, "", _REQUIRED_KEYS, _TOP_KEYS - _REQUIRED_KEYS)
    return data if top is None else top


def _carried_table(c: _Checker, data: dict[str, Any], source: str, given: ClassTable | None) -> ClassTable:
    """The table the scenario is read with: ``given``, else the one it carries, else the default.

    A course made for a class table of one's own carries it (``classes:``, the fields of a
    ``terrapref-classes/1`` file), so that it reads without ``--classes``; a table given as well
    must be the same table, or every class name would mean another class.
    """
    if "classes" not in data:
        return given or default_classes()
    try:
        carried = ClassTable.from_dict(data["classes"], source)
    except ConfigError as exc:
        for problem in exc.problems:
            c.fail(f"classes.{problem.field}" if problem.field else "classes", problem.message)
        raise ScenarioError(source, c.problems) from None
    if given is not None and not carried.same_classes(given):
        c.fail(
            "classes",
            f"the scenario carries the class table of {', '.join(carried.names)}, not the one it is read with "
            f"({', '.join(given.names)}: --classes, or the model's)",
        )
        raise ScenarioError(source, c.problems)
    return given or carried


def _name(c: _Checker, data: dict[str, Any]) -> str | None:
    """The scenario's name, which must be usable in file names."""
    name = c.text(data.get("name"), "name") if "name" in data else None
    if name is not None and not _NAME.fullmatch(name):
        c.fail("name", "must match [A-Za-z0-9_-]+")
    return name


def _description(c: _Checker, data: dict[str, Any]) -> Any:
    """The optional free-text description ("" when absent)."""
    description = data.get("description", "")
    if not isinstance(description, str):
        c.fail("description", f"expected a string, got {described(description)}")
    return description


def _world(c: _Checker, data: dict[str, Any], classes: ClassTable) -> _World:
    """The ``world`` block: map size, raster resolution and background class."""
    world = c.mapping(data["world"], "world", {"size_m", "resolution_m", "background"}) if "world" in data else None
    if world is None:
        return _World()
    size = c.vector(world["size_m"], "world.size_m", 2, positive=True)
    resolution = c.number(world["resolution_m"], "world.resolution_m", positive=True)
    background = c.class_name(world["background"], "world.background", classes)
    size_m = _raster_size(c, size, resolution) if size is not None and resolution is not None else None
    return _World(size_m, resolution, background)


def _raster_size(c: _Checker, size: tuple[float, ...], resolution_m: float) -> tuple[float, float] | None:
    """``size`` [m] as the map size, or None when its raster would exceed ``MAX_CELLS`` cells."""
    if size[0] / resolution_m * (size[1] / resolution_m) > 1e18:
        # Past 10^18 an exact count is unreadable (and past ~10^308 it overflows); give the magnitude.
        digits = math.log10(size[0]) + math.log10(size[1]) - 2 * math.log10(resolution_m)
        c.fail(
            "world",
            f"raster would have about 10^{digits:.0f} cells, more than the limit of {MAX_CELLS:,}; use a coarser resolution_m or a smaller size_m",
        )
        return None
    ny, nx = grid_shape((size[0], size[1]), resolution_m)
    if nx * ny > MAX_CELLS:
        c.fail(
            "world",
            f"raster would have {nx} x {ny} = {nx * ny:,} cells ({nx * ny / 1e9:.1f} GB), more than the limit of {MAX_CELLS:,}; use a coarser resolution_m or a smaller size_m",
        )
        return None
    return (size[0], size[1])


def _terrain(c: _Checker, raw: Any, size_m: tuple[float, float] | None, classes: ClassTable) -> list[TerrainPatch]:
    """The ``terrain`` list: one class and one shape per patch."""
    if not isinstance(raw, list):
        c.fail("terrain", f"expected a list, got {described(raw)}")
        return []
    patches: list[TerrainPatch] = []
    for i, item in enumerate(raw):
        f = f"terrain[{i}]"
        item = c.mapping(item, f, {"class"}, set(_SHAPE_KEYS))
        if item is None:
            continue
        cls_name = c.class_name(item["class"], f"{f}.class", classes)
        shape = c.shape(item, f, size_m)
        if cls_name is not None and shape is not None:
            patches.append(TerrainPatch(cls_name, shape))
    return patches


def _waypoints(c: _Checker, data: dict[str, Any], size_m: tuple[float, float] | None) -> np.ndarray | None:
    """The reference path's waypoints, shape (n, 2) [m]: at least two distinct, all on the map."""
    path = c.mapping(data["path"], "path", {"waypoints"}) if "path" in data else None
    if path is None:
        return None
    waypoints = c.points(path["waypoints"], "path.waypoints", 2)
    if waypoints is None:
        return None
    if len(np.unique(waypoints, axis=0)) < 2:
        c.fail("path.waypoints", "needs at least 2 distinct points")
        return None
    if size_m is not None:
        off = np.flatnonzero(~_on_map(waypoints, size_m))
        if len(off):
            i = int(off[0])
            c.fail(
                f"path.waypoints[{i}]",
                f"({waypoints[i, 0]:g}, {waypoints[i, 1]:g}) is off the map (0..{size_m[0]:g} x 0..{size_m[1]:g}); {len(off)} waypoint(s) off the map",
            )
            return None
    return waypoints


def _start(
    c: _Checker, data: dict[str, Any], waypoints: np.ndarray | None, size_m: tuple[float, float] | None
) -> tuple[float, float, float] | None:
    """The start pose (x [m], y [m], yaw [rad]); the file gives yaw in degrees."""
    if "start" not in data:
        if waypoints is None:
            return None
        # Default: the first waypoint, facing the next distinct one.
        first = waypoints[0]
        nxt = next(p for p in waypoints[1:] if not np.array_equal(p, first))
        return (float(first[0]), float(first[1]), math.atan2(nxt[1] - first[1], nxt[0] - first[0]))
    s = c.vector(data["start"], "start", 3)
    if s is None:
        return None
    if size_m is not None and not _on_map(np.array(s[:2]), size_m):
        c.fail("start", f"({s[0]:g}, {s[1]:g}) is off the map")
        return None
    if abs(s[2]) > MAX_YAW_DEG:
        c.fail("start[2]", f"the heading must be within +-{MAX_YAW_DEG:,.0f} deg, got {s[2]:g}")
        return None
    return (s[0], s[1], math.radians(s[2]))


def _lethal_under_start(start: tuple[float, float, float], world: _World, terrain: list[TerrainPatch], classes: ClassTable) -> str | None:
    """The lethal class under the vehicle's footprint at ``start`` as the simulator reads it (the
    class of the cell each footprint point falls in, painted as :func:`terrapref.world.rasterise`
    paints: the last patch holding the cell's centre, else the background); None where it is clear.
    A run started there would count a collision before it moved."""
    assert world.size_m is not None and world.resolution_m is not None and world.background is not None
    x, y, yaw = start
    across = START_HALF_WIDTH_M * np.array([-1.0, -0.5, 0.0, 0.5, 1.0])  # the footprint's 5 points, as the simulator's vehicle has them
    points = np.stack([x - across * math.sin(yaw), y + across * math.cos(yaw)], axis=1)
    res = world.resolution_m
    cells = np.floor(points / res)
    ny, nx = grid_shape(world.size_m, res)
    cells = cells[(cells[:, 0] >= 0) & (cells[:, 0] < nx) & (cells[:, 1] >= 0) & (cells[:, 1] < ny)]  # off the map: not lethal
    centres = (cells + 0.5) * res
    names = np.full(len(centres), world.background, dtype=object)
    with np.errstate(over="ignore", invalid="ignore"):  # a polygon of huge (finite) vertices, as the raster paints it
        for patch in terrain:
            names[patch.shape.contains(centres)] = patch.class_name
    return next((str(n) for n in names if n in classes.lethal), None)


def _crossing_edges(vertices: np.ndarray) -> tuple[int, int] | None:
    """The first two edges of the closed polygon ``vertices`` (N, 2) that cross (each passes strictly
    between the other's ends), by the vertices they start from; None for a simple polygon. Edges
    that only touch, or overlap along a line, are not counted."""
    a, b = vertices, np.roll(vertices, -1, axis=0)
    d = b - a

    def side(i: np.ndarray, p: np.ndarray) -> np.ndarray:  # which side of edge i each point p lies on: +1, -1 or 0
        return np.sign(d[i, 0] * (p[..., 1] - a[i, 1]) - d[i, 1] * (p[..., 0] - a[i, 0]))

    n = len(vertices)
    i, j = np.triu_indices(n, k=2)
    keep = ~((i == 0) & (j == n - 1))  # the last edge and the first share a vertex
    i, j = i[keep], j[keep]
    crosses = (side(i, a[j]) * side(i, b[j]) < 0) & (side(j, a[i]) * side(j, b[i]) < 0)
    if not crosses.any():
        return None
    k = int(np.argmax(crosses))
    return int(i[k]), int(j[k])


def _zones(c: _Checker, raw: Any, size_m: tuple[float, float] | None, classes: ClassTable) -> list[Zone]:
    """The ``zones`` list (``null`` is an empty one), each zone with an id unique in the file."""
    if raw is None:
        raw = []
    if not isinstance(raw, list):
        c.fail("zones", f"expected a list, got {described(raw)}")
        return []
    zones: list[Zone] = []
    seen: dict[str, int] = {}
    for i, item in enumerate(raw):
        f = f"zones[{i}]"
        item = c.mapping(item, f, {"id", "expect"}, {"label", *_SHAPE_KEYS})
        zid = _zone_id(c, item["id"], f, seen) if item is not None else None
        if zid is None:
            continue
        seen[zid] = i
        zone = _zone(c, item, f, zid, size_m, classes)
        if zone is not None:
            zones.append(zone)
    return zones


def _zone_id(c: _Checker, raw: Any, field: str, seen: dict[str, int]) -> str | None:
    """A zone's id as text (an integer id is accepted), or None if invalid or already in ``seen``."""
    if isinstance(raw, bool) or not isinstance(raw, (str, int)):
        c.fail(f"{field}.id", f"expected a string, got {described(raw)}")
        return None
    zid = raw if isinstance(raw, str) else printed(raw)
    if zid in seen:
        c.fail(f"{field}.id", f"duplicate zone id {zid!r} (also zones[{seen[zid]}])")
        return None
    return zid


def _zone(c: _Checker, item: dict, field: str, zid: str, size_m: tuple[float, float] | None, classes: ClassTable) -> Zone | None:
    """One zone with a checked id: its label, what the planner should do there, and its shape."""
    label = item.get("label", "")
    if not isinstance(label, str):
        c.fail(f"{field}.label", f"expected a string, got {described(label)}")
    expect = item["expect"]
    if not isinstance(expect, str) or expect not in {AVOID, BEST, *classes.names}:
        c.fail(f"{field}.expect", f"{printed(expect)} is neither 'avoid', 'best' nor a known class ({', '.join(classes.names)})")
        expect = None
    elif expect in classes.lethal:  # a driver is never expected onto it: every profile puts it last
        c.fail(f"{field}.expect", f"{expect!r} is lethal, and no zone expects lethal terrain (a zone the driver keeps off expects 'avoid')")
        expect = None
    shape = c.shape(item, field, size_m)
    if shape is not None and expect is not None and isinstance(label, str):
        return Zone(zid, shape, expect, label)
    return None


def _relief(c: _Checker, raw: Any, world: _World) -> list[ReliefEntry]:
    """The ``relief`` list (``null`` is an empty one: flat ground), each entry of one kind."""
    if raw is None:
        raw = []
    if not isinstance(raw, list):
        c.fail("relief", f"expected a list, got {described(raw)}")
        return []
    entries: list[ReliefEntry] = []
    for i, item in enumerate(raw):
        f = f"relief[{i}]"
        item = c.mapping(item, f, set(), set(RELIEF_KINDS), unknown=f"unknown kind of relief; the kinds are {', '.join(RELIEF_KINDS)}")
        if item is None:
            continue
        if len(item) != 1:
            c.fail(f, f"expected exactly one of {', '.join(RELIEF_KINDS)}, got {len(item)}")
            continue
        ((kind, spec),) = item.items()
        read = {"noise": _noise, "mound": _mound, "ridge": _ridge, "plateau": _plateau}[kind]
        entry = read(c, spec, f"{f}.{kind}", world)
        if entry is not None and world.size_m is not None and _relief_off_map(c, entry, f"{f}.{kind}", world.size_m):
            entry = None
        if entry is not None:
            entries.append(entry)
    return entries


def _relief_height(c: _Checker, value: Any, field: str, *, positive: bool = False) -> float | None:
    """A height [m] of at most :data:`MAX_RELIEF_M` either way, and at least :data:`MIN_RELIEF_M` (less leaves the ground as it was)."""
    x = c.number(value, field, positive=positive)
    if x is not None and abs(x) > MAX_RELIEF_M:
        c.fail(field, f"must be at most {MAX_RELIEF_M:g} m either way")
        return None
    if x is not None and abs(x) < MIN_RELIEF_M:
        c.fail(field, f"must be at least {1000 * MIN_RELIEF_M:g} mm either way: the ground would not change")
        return None
    return x


def _relief_points(c: _Checker, value: Any, field: str, minimum: int) -> np.ndarray | None:
    """Points (k, 2) [m], at least ``minimum`` of them distinct, none far beyond the map."""
    pts = c.points(value, field, minimum)
    if pts is None:
        return None
    if len(np.unique(pts, axis=0)) < minimum:
        c.fail(field, f"needs at least {minimum} distinct points")
        return None
    if np.abs(pts).max() > MAX_RELIEF_REACH_M:
        c.fail(field, f"has a point more than {MAX_RELIEF_REACH_M:g} m from the map")
        return None
    return pts


def _cell_sized(c: _Checker, polygon: Polygon | None, f: str, world: _World) -> Polygon | None:
    """``polygon`` (an entry's ``polygon``), refused (None) where it is smaller than one cell of the map."""
    if polygon is not None and world.resolution_m is not None and _area(polygon.vertices) < world.resolution_m**2:
        c.fail(f"{f}.polygon", f"is smaller than one cell of the map ({world.resolution_m:g} m square): the ground would not change")
        return None
    return polygon


def _noise(c: _Checker, spec: Any, f: str, world: _World) -> Noise | None:
    """A ``noise`` entry: amplitude [m], wavelength [m] of at least two cells, integer seed, and
    optionally the polygon it stays inside."""
    spec = c.mapping(spec, f, {"amplitude_m", "wavelength_m", "seed"}, {"polygon"})
    if spec is None:
        return None
    polygon = None
    if "polygon" in spec:
        polygon = _cell_sized(c, _relief_polygon(c, spec["polygon"], f), f, world)
        if polygon is None:
            return None
    amplitude = _relief_height(c, spec["amplitude_m"], f"{f}.amplitude_m", positive=True)
    wavelength = c.number(spec["wavelength_m"], f"{f}.wavelength_m", positive=True)
    if wavelength is not None and world.resolution_m is not None and wavelength < 2 * world.resolution_m:
        # Finer noise than two cells is aliased on the grid: the ground would not be what was asked.
        c.fail(f"{f}.wavelength_m", f"must be at least two cells (2 x world.resolution_m = {2 * world.resolution_m:g} m)")
        wavelength = None
    elif wavelength is not None and wavelength > MAX_WAVELENGTH_M:
        # Hills far wider than any map leave it flat to within the noise's rounding.
        c.fail(f"{f}.wavelength_m", f"must be at most {MAX_WAVELENGTH_M:g} m")
        wavelength = None
    seed = spec["seed"]
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < 2**63:
        c.fail(f"{f}.seed", f"expected an integer from 0 to 2^63 - 1, got {described(seed)}")
        seed = None
    if amplitude is None or wavelength is None or seed is None:
        return None
    return Noise(amplitude, wavelength, seed, polygon)


def _mound(c: _Checker, spec: Any, f: str, world: _World) -> Mound | None:
    """A ``mound`` entry: centre [m], radius [m] > 0, height [m] (< 0: a pit)."""
    spec = c.mapping(spec, f, {"center", "radius", "height_m"})
    if spec is None:
        return None
    center = c.vector(spec["center"], f"{f}.center", 2)
    if center is not None and max(abs(center[0]), abs(center[1])) > MAX_RELIEF_REACH_M:
        c.fail(f"{f}.center", f"lies more than {MAX_RELIEF_REACH_M:g} m from the map")
        center = None
    radius = _within_span(c, c.number(spec["radius"], f"{f}.radius", positive=True), f"{f}.radius")
    radius = _at_least_cells(c, radius, f"{f}.radius", 1, world)
    height = _relief_height(c, spec["height_m"], f"{f}.height_m")
    if center is None or radius is None or height is None:
        return None
    return Mound((center[0], center[1]), radius, height)


def _ridge(c: _Checker, spec: Any, f: str, world: _World) -> Ridge | None:
    """A ``ridge`` entry: a polyline of at least 2 distinct points, width [m] > 0, height [m] (< 0: a ditch)."""
    spec = c.mapping(spec, f, {"polyline", "width_m", "height_m"})
    if spec is None:
        return None
    polyline = _relief_points(c, spec["polyline"], f"{f}.polyline", 2)
    width = _within_span(c, c.number(spec["width_m"], f"{f}.width_m", positive=True), f"{f}.width_m")
    width = _at_least_cells(c, width, f"{f}.width_m", 2, world)
    height = _relief_height(c, spec["height_m"], f"{f}.height_m")
    if polyline is None or width is None or height is None:
        return None
    return Ridge(polyline, width, height)


def _plateau(c: _Checker, spec: Any, f: str, world: _World) -> Plateau | None:
    """A ``plateau`` entry: a polygon of non-zero area, height [m], its sides' run ``edge_m`` >= 0 (0: a ledge)."""
    spec = c.mapping(spec, f, {"polygon", "height_m", "edge_m"})
    if spec is None:
        return None
    polygon = _cell_sized(c, _relief_polygon(c, spec["polygon"], f), f, world)
    height = _relief_height(c, spec["height_m"], f"{f}.height_m")
    edge = c.number(spec["edge_m"], f"{f}.edge_m")
    if edge is not None and edge < 0:
        c.fail(f"{f}.edge_m", "must be >= 0 (0: a vertical step)")
        edge = None
    edge = _within_span(c, edge, f"{f}.edge_m")
    if edge:  # a slope finer than a cell is a step on the grid: 0 says so
        edge = _at_least_cells(c, edge, f"{f}.edge_m", 1, world, " or 0 (a vertical step)")
    if polygon is None or height is None or edge is None:
        return None
    return Plateau(polygon, height, edge)


def _within_span(c: _Checker, value: float | None, field: str) -> float | None:
    """``value`` [m] where it is at most :data:`MAX_RELIEF_SPAN_M`; else said and None."""
    if value is not None and value > MAX_RELIEF_SPAN_M:
        c.fail(field, f"must be at most {MAX_RELIEF_SPAN_M:g} m, as far as relief may lie from the map")
        return None
    return value


def _at_least_cells(c: _Checker, value: float | None, field: str, cells: int, world: _World, note: str = "") -> float | None:
    """``value`` [m] where it spans at least ``cells`` cells of the map; else said (a feature
    finer than the grid falls between the cells' centres, and the ground would not change) and None."""
    if value is None or world.resolution_m is None or value >= cells * world.resolution_m:
        return value
    span = "one cell" if cells == 1 else f"{cells} cells"
    c.fail(
        field,
        f"must be at least {span} ({cells * world.resolution_m:g} m at world.resolution_m {world.resolution_m:g}){note}: "
        "finer relief falls between the cells",
    )
    return None


def _area(vertices: np.ndarray) -> float:
    """The area [m^2] of the simple polygon ``vertices`` (N, 2) (the shoelace formula)."""
    x, y = vertices[:, 0], vertices[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def _relief_polygon(c: _Checker, value: Any, f: str) -> Polygon | None:
    """An entry's ``polygon``, checked as a terrain polygon is (at ``{f}.polygon``), none of its points far beyond the map."""
    polygon = c.shape({"polygon": value}, f, None)
    if not isinstance(polygon, Polygon):
        return None
    if np.abs(polygon.vertices).max() > MAX_RELIEF_REACH_M:
        c.fail(f"{f}.polygon", f"has a point more than {MAX_RELIEF_REACH_M:g} m from the map")
        return None
    return polygon


def _relief_off_map(c: _Checker, entry: ReliefEntry, f: str, size_m: tuple[float, float]) -> bool:
    """Whether ``entry`` reaches no point of the map (a mistake: it would change nothing); says so."""
    bounds = entry.bounds()
    if bounds is None:
        return False
    x0, y0, x1, y1 = bounds
    if x1 <= 0 or y1 <= 0 or x0 >= size_m[0] or y0 >= size_m[1]:
        c.fail(f, f"lies wholly off the map (bounds x {x0:g}..{x1:g}, y {y0:g}..{y1:g}; map 0..{size_m[0]:g} x 0..{size_m[1]:g})")
        return True
    return False


def load_scenario(path: str | Path, classes: ClassTable | None = None) -> Scenario:
    """Read and validate a scenario file.

    Raises:
        ScenarioError: one problem per bad field (or a single one for an unreadable file).
    """
    source = str(path)
    try:
        data = read_yaml_mapping(path)
    except ScenarioError:
        raise
    except UserError as exc:
        raise ScenarioError(exc.source, exc.problems) from None
    return parse_scenario(data, source, classes)
