"""The typed entries of a scenario's ``relief:`` block (SPEC 19): what raises or lowers the ground.

Each entry adds a height [m] to the ground, in the order the file lists them; the height field
they make is built by :func:`terrapref.world.relief.height_field`. A scenario without entries is
flat (z = 0 everywhere).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from terrapref.scenario.shapes import Polygon


@dataclass(frozen=True)
class Noise:
    """Smooth OpenSimplex noise: ``amplitude_m`` times a value in about [-1, 1], its features
    about ``wavelength_m`` across, the same on any machine for one ``seed``; over the whole map,
    or only inside ``polygon`` (rough ground: short noise on a patch), faded in over one
    wavelength inside its edge so that the patch has no step at its border."""

    amplitude_m: float
    wavelength_m: float
    seed: int
    polygon: Polygon | None = None

    def bounds(self) -> tuple[float, float, float, float] | None:
        """The polygon's box (x0, y0, x1, y1) [m] outside which the noise adds nothing; None: the whole map."""
        return None if self.polygon is None else self.polygon.bounds()

    def to_dict(self) -> dict:
        spec: dict = {"amplitude_m": self.amplitude_m, "wavelength_m": self.wavelength_m, "seed": self.seed}
        if self.polygon is not None:
            spec["polygon"] = self.polygon.vertices.tolist()
        return {"noise": spec}


@dataclass(frozen=True)
class Mound:
    """A round hill (``height_m`` < 0: a pit) of cosine profile: ``height_m`` at its centre,
    half of it at half its radius, nothing from ``radius_m`` outwards."""

    center: tuple[float, float]
    radius_m: float
    height_m: float

    def bounds(self) -> tuple[float, float, float, float]:
        """The box (x0, y0, x1, y1) [m] outside which the mound adds nothing."""
        (cx, cy), r = self.center, self.radius_m
        return cx - r, cy - r, cx + r, cy + r

    def to_dict(self) -> dict:
        return {"mound": {"center": list(self.center), "radius": self.radius_m, "height_m": self.height_m}}


@dataclass(frozen=True, eq=False)
class Ridge:
    """A bank along a polyline (``height_m`` < 0: a ditch) of cosine cross-section: ``height_m``
    on the line, nothing from ``width_m / 2`` off it (its ends rounded).

    Attributes:
        polyline: the ridge's line, shape (k, 2) [m], k >= 2.
    """

    polyline: np.ndarray
    width_m: float
    height_m: float

    def bounds(self) -> tuple[float, float, float, float]:
        """The box (x0, y0, x1, y1) [m] outside which the ridge adds nothing."""
        half = self.width_m / 2
        lo, hi = self.polyline.min(axis=0), self.polyline.max(axis=0)
        return float(lo[0]) - half, float(lo[1]) - half, float(hi[0]) + half, float(hi[1]) + half

    def to_dict(self) -> dict:
        return {"ridge": {"polyline": self.polyline.tolist(), "width_m": self.width_m, "height_m": self.height_m}}


@dataclass(frozen=True, eq=False)
class Plateau:
    """Ground raised by ``height_m`` inside a polygon (< 0: a sunken floor), its sides sloping
    straight down over ``edge_m`` outside it (a ramp of grade ``height_m / edge_m``); ``edge_m``
    0 makes its edge a vertical step (a ledge)."""

    polygon: Polygon
    height_m: float
    edge_m: float

    def bounds(self) -> tuple[float, float, float, float]:
        """The box (x0, y0, x1, y1) [m] outside which the plateau adds nothing."""
        x0, y0, x1, y1 = self.polygon.bounds()
        return x0 - self.edge_m, y0 - self.edge_m, x1 + self.edge_m, y1 + self.edge_m

    def to_dict(self) -> dict:
        return {"plateau": {"polygon": self.polygon.vertices.tolist(), "height_m": self.height_m, "edge_m": self.edge_m}}


ReliefEntry = Noise | Mound | Ridge | Plateau
RELIEF_KINDS = ("noise", "mound", "ridge", "plateau")
