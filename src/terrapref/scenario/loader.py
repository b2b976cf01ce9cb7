"""Load and validate ``terrapref-scenario/1`` files, reporting every problem with its field path."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from terrapref.errors import Problem, ScenarioError, UserError
from terrapref.scenario.model import AVOID, BEST, Scenario, TerrainPatch, Zone, grid_shape
from terrapref.scenario.shapes import Circle, Polygon, Rectangle, Shape
from terrapref.terrain import ClassTable, default_classes
from terrapref.yamlio import read_yaml_mapping

FORMAT = "terrapref-scenario/1"
MAX_CELLS = 100_000_000
_NAME = re.compile(r"[A-Za-z0-9_-]+")
_TOP_KEYS = {"format", "name", "description", "world", "terrain", "path", "start", "zones"}
_SHAPE_KEYS = ("polygon", "circle", "rectangle")


class _Checker:
    """Collects problems while converting untyped YAML values into typed ones."""

    def __init__(self) -> None:
        self.problems: list[Problem] = []

    def fail(self, field: str, message: str) -> None:
        self.problems.append(Problem(field, message))

    def mapping(self, value: Any, field: str, required: set[str], optional: set[str] = frozenset()) -> dict | None:
        if not isinstance(value, dict):
            self.fail(field, f"expected a mapping, got {_describe(value)}")
            return None
        ok = True
        for key in sorted(required - set(value), key=str):
            self.fail(_join(field, key), "missing")
            ok = False
        for key in sorted(set(value) - required - set(optional), key=_key_text):
            self.fail(_join(field, _key_text(key)), "unknown key")
            ok = False
        return value if ok else None

    def number(self, value: Any, field: str, *, positive: bool = False) -> float | None:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            self.fail(field, f"expected a number, got {_describe(value)}")
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
            self.fail(field, f"expected a list of {length} numbers, got {_describe(value)}")
            return None
        items = [self.number(v, f"{field}[{i}]", positive=positive) for i, v in enumerate(value)]
        return None if any(v is None for v in items) else tuple(items)  # type: ignore[arg-type]

    def points(self, value: Any, field: str, minimum: int) -> np.ndarray | None:
        if not isinstance(value, list) or len(value) < minimum:
            self.fail(field, f"expected a list of at least {minimum} [x, y] points, got {_describe(value)}")
            return None
        pts = [self.vector(p, f"{field}[{i}]", 2) for i, p in enumerate(value)]
        return None if any(p is None for p in pts) else np.array(pts, dtype=float)

    def text(self, value: Any, field: str) -> str | None:
        if not isinstance(value, str):
            self.fail(field, f"expected a string, got {_describe(value)}")
            return None
        return value

    def class_name(self, value: Any, field: str, classes: ClassTable) -> str | None:
        name = self.text(value, field)
        if name is not None and name not in classes.names:
            self.fail(field, f"unknown class {name!r}; known: {', '.join(classes.names)}")
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
                area = 0.5 * abs(float(np.dot(q[:, 0], np.roll(q[:, 1], -1)) - np.dot(q[:, 1], np.roll(q[:, 0], -1))))
                if len(distinct) < 3:
                    self.fail(f, f"needs at least 3 distinct vertices, got {len(distinct)}")
                elif area <= max(1e-12, 1e-9 / scale / scale):
                    self.fail(f, "has zero area (vertices are collinear)")
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
                self.fail(f, f"lies wholly off the map (bounds x {x0:g}..{x1:g}, y {y0:g}..{y1:g}; map 0..{size_m[0]:g} x 0..{size_m[1]:g})")
                return None
        return shape


def _join(field: str, key: str) -> str:
    return f"{field}.{key}" if field else key


def _repr(value: Any) -> str:
    """``repr(value)``, safe for integers too long to print (Python limits int-to-text conversion)."""
    try:
        return repr(value)
    except ValueError:
        return "a very large number"


def _key_text(key: Any) -> str:
    """A mapping key as it appears in a field path, kept on one printable line."""
    text = key if isinstance(key, str) else _repr(key)
    return text if text.isprintable() else repr(text)


def _describe(value: Any) -> str:
    if value is None:
        return "nothing"
    if isinstance(value, bool):
        return f"boolean {value}"
    if isinstance(value, (int, float)):
        text = _repr(value)
        return f"number {text}" if len(text) < 40 else "a very large number"
    if isinstance(value, str):
        return f"string {value!r}" if len(value) < 40 else "a string"
    if isinstance(value, list):
        return f"a list of {len(value)}"
    if isinstance(value, dict):
        return "a mapping"
    return type(value).__name__


def _on_map(p: np.ndarray, size_m: tuple[float, float]) -> np.ndarray:
    return (p[..., 0] >= 0) & (p[..., 0] <= size_m[0]) & (p[..., 1] >= 0) & (p[..., 1] <= size_m[1])


def parse_scenario(data: dict[str, Any], source: str = "", classes: ClassTable | None = None) -> Scenario:
    """Validate a parsed mapping and build a :class:`Scenario`.

    Raises:
        ScenarioError: listing every problem found, each with its field path.
    """
    classes = classes or default_classes()
    c = _Checker()
    if data.get("format") != FORMAT:
        got = data.get("format")
        c.fail("format", f"{'missing' if got is None else _repr(got) + ' is not supported'}; expected {FORMAT!r}")
        raise ScenarioError(source, c.problems)
    top = c.mapping(data, "", {"format", "name", "world", "path"}, _TOP_KEYS - {"format", "name", "world", "path"})
    data = data if top is None else top

    name = c.text(data.get("name"), "name") if "name" in data else None
    if name is not None and not _NAME.fullmatch(name):
        c.fail("name", "must match [A-Za-z0-9_-]+")
    description = data.get("description", "")
    if not isinstance(description, str):
        c.fail("description", f"expected a string, got {_describe(description)}")

    size_m: tuple[float, float] | None = None
    resolution = background = None
    world = c.mapping(data["world"], "world", {"size_m", "resolution_m", "background"}) if "world" in data else None
    if world is not None:
        size = c.vector(world["size_m"], "world.size_m", 2, positive=True)
        resolution = c.number(world["resolution_m"], "world.resolution_m", positive=True)
        background = c.class_name(world["background"], "world.background", classes)
        if size is not None and resolution is not None:
            if size[0] / resolution * (size[1] / resolution) > 1e18:
                # Past 10^18 an exact count is unreadable (and past ~10^308 it overflows); give the magnitude.
                digits = math.log10(size[0]) + math.log10(size[1]) - 2 * math.log10(resolution)
                c.fail("world", f"raster would have about 10^{digits:.0f} cells, more than the limit of {MAX_CELLS:,}; use a coarser resolution_m or a smaller size_m")
            else:
                ny, nx = grid_shape((size[0], size[1]), resolution)
                if nx * ny > MAX_CELLS:
                    c.fail(
                        "world",
                        f"raster would have {nx} x {ny} = {nx * ny:,} cells ({nx * ny / 1e9:.1f} GB), more than the limit of {MAX_CELLS:,}; use a coarser resolution_m or a smaller size_m",
                    )
                else:
                    size_m = (size[0], size[1])

    terrain: list[TerrainPatch] = []
    raw_terrain = data.get("terrain", [])
    if not isinstance(raw_terrain, list):
        c.fail("terrain", f"expected a list, got {_describe(raw_terrain)}")
        raw_terrain = []
    for i, item in enumerate(raw_terrain):
        f = f"terrain[{i}]"
        item = c.mapping(item, f, {"class"}, set(_SHAPE_KEYS))
        if item is None:
            continue
        cls_name = c.class_name(item["class"], f"{f}.class", classes)
        shape = c.shape(item, f, size_m)
        if cls_name is not None and shape is not None:
            terrain.append(TerrainPatch(cls_name, shape))

    waypoints = None
    path = c.mapping(data["path"], "path", {"waypoints"}) if "path" in data else None
    if path is not None:
        waypoints = c.points(path["waypoints"], "path.waypoints", 2)
        if waypoints is not None:
            if len(np.unique(waypoints, axis=0)) < 2:
                c.fail("path.waypoints", "needs at least 2 distinct points")
                waypoints = None
            elif size_m is not None:
                off = np.flatnonzero(~_on_map(waypoints, size_m))
                if len(off):
                    i = int(off[0])
                    c.fail(f"path.waypoints[{i}]", f"({waypoints[i, 0]:g}, {waypoints[i, 1]:g}) is off the map (0..{size_m[0]:g} x 0..{size_m[1]:g}); {len(off)} waypoint(s) off the map")
                    waypoints = None

    start: tuple[float, float, float] | None = None
    if "start" in data:
        s = c.vector(data["start"], "start", 3)
        if s is not None:
            if size_m is not None and not _on_map(np.array(s[:2]), size_m):
                c.fail("start", f"({s[0]:g}, {s[1]:g}) is off the map")
            else:
                start = (s[0], s[1], math.radians(s[2]))
    elif waypoints is not None:
        # Default: the first waypoint, facing the next distinct one.
        first = waypoints[0]
        nxt = next(p for p in waypoints[1:] if not np.array_equal(p, first))
        start = (float(first[0]), float(first[1]), math.atan2(nxt[1] - first[1], nxt[0] - first[0]))

    zones: list[Zone] = []
    raw_zones = data.get("zones", [])
    if raw_zones is None:
        raw_zones = []
    if not isinstance(raw_zones, list):
        c.fail("zones", f"expected a list, got {_describe(raw_zones)}")
        raw_zones = []
    seen: dict[str, int] = {}
    expect_ok = {AVOID, BEST, *classes.names}
    for i, item in enumerate(raw_zones):
        f = f"zones[{i}]"
        item = c.mapping(item, f, {"id", "expect"}, {"label", *_SHAPE_KEYS})
        if item is None:
            continue
        zid = item["id"]
        if isinstance(zid, bool) or not isinstance(zid, (str, int)):
            c.fail(f"{f}.id", f"expected a string, got {_describe(zid)}")
            continue
        zid = zid if isinstance(zid, str) else _repr(zid)
        if zid in seen:
            c.fail(f"{f}.id", f"duplicate zone id {zid!r} (also zones[{seen[zid]}])")
            continue
        seen[zid] = i
        label = item.get("label", "")
        if not isinstance(label, str):
            c.fail(f"{f}.label", f"expected a string, got {_describe(label)}")
        expect = item["expect"]
        if not isinstance(expect, str) or expect not in expect_ok:
            c.fail(f"{f}.expect", f"{_repr(expect)} is neither 'avoid', 'best' nor a known class ({', '.join(classes.names)})")
            expect = None
        shape = c.shape(item, f, size_m)
        if shape is not None and expect is not None and isinstance(label, str):
            zones.append(Zone(zid, shape, expect, label))

    if c.problems:
        raise ScenarioError(source, c.problems)
    assert name is not None and size_m is not None and resolution is not None and background is not None
    assert waypoints is not None and start is not None
    return Scenario(
        name=name,
        size_m=size_m,
        resolution_m=resolution,
        background=background,
        terrain=tuple(terrain),
        waypoints=waypoints,
        start=start,
        zones=tuple(zones),
        description=description,
        source=source,
        classes=classes,
    )


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
