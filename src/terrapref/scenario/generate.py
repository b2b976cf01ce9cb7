"""Procedurally generated courses: layouts never packaged, for choosing and checking recipes.

Each course is a gently bending trail with a zone every ~26 m, each zone one of:
- ``lone``: one patch of a random class and shape (circle, rotated rectangle or irregular
  polygon, at most ~3.4 m across) on or near the path; expected ``avoid``;
- ``pair``: two patches of different classes meeting near the path, each 5-6.5 m wide and
  7-10 m long, on random sides; expected ``best``;
- ``triple``: a 2.4-3.2 m wide patch on the path between two wide ones; expected ``best``.
Sizes follow the packaged courses' rules (lone patches passable on grass, wide patches not),
but shapes, sizes, sides, offsets, classes and the trail's bends are all drawn at random.
"""

from __future__ import annotations

import math

import numpy as np

from terrapref.scenario.loader import parse_scenario
from terrapref.scenario.model import Scenario
from terrapref.terrain import ClassTable, default_classes

ZONE_KINDS = ("lone", "pair", "triple")
ZONE_CLASSES = {"lone": 1, "pair": 2, "triple": 3}  # the classes each kind needs


def _frame(wp: np.ndarray, s: float) -> tuple[np.ndarray, float]:
    seg = np.linalg.norm(np.diff(wp, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    i = min(int(np.searchsorted(cum, s, side="right")) - 1, len(seg) - 1)
    d = wp[i + 1] - wp[i]
    return wp[i] + (s - cum[i]) / seg[i] * d, math.atan2(d[1], d[0])


def _to_world(wp: np.ndarray, s: float, pts: np.ndarray) -> list[list[float]]:
    p, h = _frame(wp, s)
    c, sn = math.cos(h), math.sin(h)
    return [[round(float(p[0] + a * c - lat * sn), 3), round(float(p[1] + a * sn + lat * c), 3)] for a, lat in pts]


def _blob(rng: np.random.Generator, radius: float, k: int) -> np.ndarray:
    """An irregular convex-ish polygon (k vertices) of about ``radius`` round the origin."""
    t = np.sort(rng.uniform(0, 2 * math.pi, k))
    r = radius * rng.uniform(0.75, 1.1, k)
    return np.stack([r * np.cos(t), r * np.sin(t)], axis=1)


def _patch(rng: np.random.Generator, wp: np.ndarray, s: float, cls: str, centre: tuple[float, float], size: tuple[float, float]) -> dict:
    """A patch of about ``size`` (along, across) centred at path coordinates ``centre``."""
    a0, l0 = centre
    kind = rng.choice(["rect", "polygon", "circle"]) if max(size) < 3.6 else rng.choice(["rect", "polygon"])
    if kind == "circle":
        ((cx, cy),) = _to_world(wp, s, np.array([[a0, l0]]))
        return {"class": cls, "circle": {"center": [cx, cy], "radius": round(float(min(size)) / 2, 3)}}
    if kind == "rect":
        yaw = rng.uniform(-12, 12)
        local = np.array(
            [[-size[0] / 2, -size[1] / 2], [size[0] / 2, -size[1] / 2], [size[0] / 2, size[1] / 2], [-size[0] / 2, size[1] / 2]]
        )
        c, sn = math.cos(math.radians(yaw)), math.sin(math.radians(yaw))
        local = local @ np.array([[c, sn], [-sn, c]]) + (a0, l0)
        return {"class": cls, "polygon": _to_world(wp, s, local)}
    blob = _blob(rng, 0.5, int(rng.integers(6, 10))) * np.array(size) + (a0, l0)
    return {"class": cls, "polygon": _to_world(wp, s, blob)}


def zone_kind(label: str) -> str:
    """The kind (``lone``, ``pair`` or ``triple``) of a generated zone, read from its label."""
    return "lone" if label.startswith("lone ") else ("triple" if label.count("|") == 2 else "pair")


def generate_course(seed: int, zones: int = 8, kinds: tuple[str, ...] = ZONE_KINDS, classes: ClassTable | None = None) -> Scenario:
    """A random course named ``gen_<seed>`` with ``zones`` scored situations."""
    classes = classes or default_classes()
    rng = np.random.default_rng([seed, 4242])
    spacing = 26.0
    wp, size = _trail(rng, spacing * (zones + 1))
    names = list(classes.feature_names)
    # A small table may have too few classes for pairs or triples.
    kinds = tuple(k for k in kinds if ZONE_CLASSES[k] <= len(names)) or ("lone",)

    def concrete(name: str) -> str:
        """A class of a terrain column: lethal classes sharing one column take turns at random."""
        return name if name in classes.names else str(rng.choice(classes.lethal))

    terrain, zone_list = [], []
    for z in range(zones):
        s = spacing * (z + 1)
        kind = kinds[int(rng.integers(len(kinds)))]
        if kind == "lone":
            cls = concrete(names[int(rng.integers(len(names)))])
            terrain.append(_patch(rng, wp, s, cls, (0.0, rng.uniform(-0.4, 0.4)), (rng.uniform(2.2, 3.4), rng.uniform(2.2, 3.0))))
            expect, label, half = "avoid", f"lone {cls}", (6.0, 5.0)
        else:
            picked = [concrete(str(n)) for n in rng.choice(names, ZONE_CLASSES[kind], replace=False)]
            patches, half = (_pair if kind == "pair" else _triple)(rng, wp, s, picked)
            terrain += patches
            expect, label = "best", " | ".join(picked)
        box = np.array([[-half[0], -half[1]], [half[0], -half[1]], [half[0], half[1]], [-half[0], half[1]]])
        zone_list.append({"id": str(z + 1), "label": label, "polygon": _to_world(wp, s, box), "expect": expect})
    data = {
        "format": "terrapref-scenario/1",
        "name": f"gen_{seed}",
        "description": f"generated course, seed {seed}",
        "world": {"size_m": [round(size[0], 1), round(size[1], 1)], "resolution_m": 0.05, "background": classes.background},
        "terrain": terrain,
        "path": {"waypoints": wp.round(3).tolist()},
        "zones": zone_list,
    }
    return parse_scenario(data, f"gen_{seed}", classes)


def _trail(rng: np.random.Generator, length_m: float) -> tuple[np.ndarray, tuple[float, float]]:
    """A trail at least ``length_m`` long of 30 m legs, each turning by up to 20 degrees, its
    heading kept within 0.6 rad of the x axis; its waypoints, moved 20 m inside a world of the
    size returned (x, y) [m]."""
    heading, pts = 0.0, [np.array([10.0, 0.0])]
    while sum(np.linalg.norm(np.diff(np.array(pts), axis=0), axis=1)) < length_m:
        heading = float(np.clip(heading + math.radians(rng.uniform(-20, 20)), -0.6, 0.6))
        pts.append(pts[-1] + 30.0 * np.array([math.cos(heading), math.sin(heading)]))
    wp = np.array(pts)
    lo, hi = wp.min(axis=0), wp.max(axis=0)
    return wp - lo + 20.0, (float(hi[0] - lo[0] + 40.0), float(hi[1] - lo[1] + 40.0))


def _pair(rng: np.random.Generator, wp: np.ndarray, s: float, picked: list[str]) -> tuple[list[dict], tuple[float, float]]:
    """Two patches side by side across the path at arc length ``s``, the first on the left; and
    the half length and half width of their zone [m]."""
    length_m, edge = rng.uniform(7.0, 10.0), rng.uniform(-0.3, 0.3)
    patches = []
    for cls, side in zip(picked, (1.0, -1.0)):
        width = rng.uniform(5.0, 6.5)
        corners = [[-length_m / 2, edge], [length_m / 2, edge], [length_m / 2, edge + side * width], [-length_m / 2, edge + side * width]]
        patches.append({"class": str(cls), "polygon": _to_world(wp, s, np.array(corners))})
    return patches, (length_m / 2 + 2.0, 8.5)


def _triple(rng: np.random.Generator, wp: np.ndarray, s: float, picked: list[str]) -> tuple[list[dict], tuple[float, float]]:
    """Three patches across the path at arc length ``s`` (left, on it, right); and the half
    length and half width of their zone [m]."""
    length_m, mid = rng.uniform(6.0, 8.0), rng.uniform(2.4, 3.2)
    patches = []
    for cls, l0, l1 in zip(picked, (mid / 2, -mid / 2, -mid / 2 - 4.5), (mid / 2 + 4.5, mid / 2, -mid / 2)):
        corners = [[-length_m / 2, l0], [length_m / 2, l0], [length_m / 2, l1], [-length_m / 2, l1]]
        patches.append({"class": str(cls), "polygon": _to_world(wp, s, np.array(corners))})
    return patches, (length_m / 2 + 2.0, 8.5)
