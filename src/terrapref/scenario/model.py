"""The typed scenario object (SPEC section 11)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from terrapref.scenario.relief import ReliefEntry
from terrapref.scenario.shapes import Shape
from terrapref.terrain import ClassTable, PreferenceProfile, default_classes

AVOID = "avoid"
BEST = "best"


@dataclass(frozen=True)
class TerrainPatch:
    class_name: str
    shape: Shape


@dataclass(frozen=True)
class Zone:
    """A scored situation: what a driver should do inside ``shape`` (SPEC 11, 12)."""

    id: str
    shape: Shape
    expect: str
    label: str = ""

    def resolve_expect(self, present: list[str], profile: PreferenceProfile, classes: ClassTable) -> str:
        """The expectation as a concrete choice: ``avoid`` or a class name.

        ``best`` becomes the most preferred non-background class in ``present`` (the classes
        painted inside the zone); with none present it is ``avoid``. The background class
        means ``avoid``.
        """
        if self.expect == BEST:
            return profile.best(present) or AVOID
        if self.expect == classes.background:
            return AVOID
        return self.expect


@dataclass(frozen=True, eq=False)
class Scenario:
    """A terrain layout, a reference path, a start pose and the zones to score.

    Attributes:
        size_m: map extent (x, y) [m]; the lower-left corner is (0, 0).
        resolution_m: raster cell size [m].
        waypoints: reference path, shape (N, 2) [m].
        start: start pose (x [m], y [m], yaw [rad]).
        relief: what raises and lowers the ground, added in order (SPEC 19); none: flat.
    """

    name: str
    size_m: tuple[float, float]
    resolution_m: float
    background: str
    terrain: tuple[TerrainPatch, ...]
    waypoints: np.ndarray
    start: tuple[float, float, float]
    zones: tuple[Zone, ...] = ()
    description: str = ""
    source: str = ""
    classes: ClassTable = field(default_factory=default_classes)
    relief: tuple[ReliefEntry, ...] = ()

    @property
    def has_relief(self) -> bool:
        """Whether the ground has relief (else it is the plane z = 0)."""
        return bool(self.relief)

    @property
    def grid_shape(self) -> tuple[int, int]:
        """Raster shape (rows along y, columns along x)."""
        return grid_shape(self.size_m, self.resolution_m)

    def path_length_m(self) -> float:
        return float(np.linalg.norm(np.diff(self.waypoints, axis=0), axis=1).sum())

    @property
    def has_terrain(self) -> bool:
        """Whether there is a map of the ground: an imported robot log's scenario has only its path
        (no patch, no zone), and its ground is not known."""
        return bool(self.terrain or self.zones)

    def to_dict(self) -> dict:
        """The scenario as a ``terrapref-scenario/1`` mapping (round-trips through the loader); a
        scenario of a class table other than the default carries it (``classes:``)."""
        out: dict = {
            "format": "terrapref-scenario/1",
            "name": self.name,
            "world": {"size_m": list(self.size_m), "resolution_m": self.resolution_m, "background": self.background},
            "terrain": [{"class": p.class_name, **p.shape.to_dict()} for p in self.terrain],
            "path": {"waypoints": self.waypoints.tolist()},
            "start": [self.start[0], self.start[1], math.degrees(self.start[2])],
            "zones": [{"id": z.id, **({"label": z.label} if z.label else {}), **z.shape.to_dict(), "expect": z.expect} for z in self.zones],
        }
        if self.relief:  # a flat scenario's mapping stays as it was
            out["relief"] = [entry.to_dict() for entry in self.relief]
        if self.description:
            out["description"] = self.description
        if self.classes != default_classes():
            out["classes"] = self.classes.to_dict()
        return out


def grid_shape(size_m: tuple[float, float], resolution_m: float) -> tuple[int, int]:
    # A tiny tolerance keeps 100 m / 0.05 m at exactly 2000 cells despite float rounding.
    nx = max(1, math.ceil(size_m[0] / resolution_m - 1e-9))
    ny = max(1, math.ceil(size_m[1] / resolution_m - 1e-9))
    return ny, nx
