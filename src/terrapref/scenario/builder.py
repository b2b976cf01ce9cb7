"""Laying out a course in path coordinates: patches and zones placed along a trail of waypoints.

Every patch and zone is placed at an arc length ``s`` along the reference path and a lateral
offset ``l`` to its left, so a layout reads as "a 3 m mud patch on the path at s = 70". The
result is the mapping a ``terrapref-scenario/1`` file holds (:meth:`CourseBuilder.data`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from terrapref.scenario.loader import FORMAT
from terrapref.terrain import ClassTable
from terrapref.yamlio import dump_yaml


class CourseBuilder:
    """A course under construction: its trail, and the patches and zones placed along it.

    With ``classes`` the course carries that class table (the file's ``classes:``), so that every
    command reads it with its own table; without, it is read with the default table or ``--classes``.
    """

    def __init__(
        self,
        name: str,
        description: str,
        size_m: tuple[float, float],
        waypoints: Sequence[Sequence[float]],
        background: str = "grass",
        classes: ClassTable | None = None,
    ):
        self.name, self.description, self.size_m, self.background, self.classes = name, description, size_m, background, classes
        self.wp = np.array(waypoints, dtype=float)
        self.seg_len = np.linalg.norm(np.diff(self.wp, axis=0), axis=1)
        self.s = np.concatenate([[0], np.cumsum(self.seg_len)])
        self.terrain: list[dict] = []
        self.zones: list[dict] = []
        self.relief: list[dict] = []  # the file's relief: entries (SPEC 19); none: flat

    def frame(self, s: float) -> tuple[np.ndarray, float]:
        """The path's point and heading [rad] at arc length ``s``."""
        i = min(int(np.searchsorted(self.s, s, side="right")) - 1, len(self.seg_len) - 1)
        d = self.wp[i + 1] - self.wp[i]
        return self.wp[i] + (s - self.s[i]) / self.seg_len[i] * d, math.atan2(d[1], d[0])

    def to_world(self, s: float, pts: Sequence[tuple[float, float]]) -> list[list[float]]:
        """Local (along, left) points round arc length ``s``, in world coordinates (mm rounded)."""
        p, h = self.frame(s)
        c, sn = math.cos(h), math.sin(h)
        return [[round(float(p[0] + a * c - lat * sn), 3), round(float(p[1] + a * sn + lat * c), 3)] for a, lat in pts]

    def rect(self, cls: str, s: float, lat: float, length: float, width: float, yaw_deg: float = 0.0) -> None:
        """A rectangle of class ``cls``, ``length`` x ``width`` [m], centred at arc length ``s`` and
        ``lat`` [m] left of the path, turned ``yaw_deg`` [deg] from the path's heading there."""
        ((cx, cy),) = self.to_world(s, [(0.0, lat)])
        h = math.degrees(self.frame(s)[1])
        self.terrain.append({"class": cls, "rectangle": {"center": [cx, cy], "size": [length, width], "yaw_deg": round(h + yaw_deg, 3)}})

    def circle(self, cls: str, s: float, lat: float, radius: float) -> None:
        """A disc of class ``cls`` and ``radius`` [m] centred at arc length ``s``, ``lat`` [m] left of the path."""
        ((cx, cy),) = self.to_world(s, [(0.0, lat)])
        self.terrain.append({"class": cls, "circle": {"center": [cx, cy], "radius": radius}})

    def polygon(self, cls: str, s: float, pts: Sequence[tuple[float, float]]) -> None:
        """A polygon of class ``cls`` through the (along, left) points ``pts`` [m] round arc length ``s``."""
        self.terrain.append({"class": cls, "polygon": self.to_world(s, pts)})

    def zone(self, zid: str, label: str, s: float, size: tuple[float, float], expect: str) -> None:
        """A scored zone: a rectangle of ``size`` (along, across) centred on the path at ``s``."""
        ((cx, cy),) = self.to_world(s, [(0.0, 0.0)])
        h = math.degrees(self.frame(s)[1])
        self.zones.append(
            {"id": zid, "label": label, "rectangle": {"center": [cx, cy], "size": list(size), "yaw_deg": round(h, 3)}, "expect": expect}
        )

    def pair(self, zid: str, left: str, right: str, s: float, size: tuple[float, float] = (8.0, 5.0)) -> None:
        """Two patches of ``size`` (length, width) meeting on the path: ``left`` on its left, ``right`` on its right."""
        length, width = size
        self.rect(left, s, width / 2, length, width)
        self.rect(right, s, -width / 2, length, width)
        self.zone(zid, f"{left} vs {right}", s, (length + 4.0, 2 * width + 4.0), "best")

    def data(self) -> dict:
        """The course as a ``terrapref-scenario/1`` mapping."""
        return {
            "format": FORMAT,
            "name": self.name,
            "description": self.description,
            "world": {"size_m": list(self.size_m), "resolution_m": 0.05, "background": self.background},
            "terrain": self.terrain,
            "path": {"waypoints": [[round(float(x), 3), round(float(y), 3)] for x, y in self.wp]},
            "zones": self.zones,
            **({"classes": self.classes.to_dict()} if self.classes is not None else {}),
            **({"relief": self.relief} if self.relief else {}),
        }

    def to_yaml(self) -> str:
        """The course as the text of a ``terrapref-scenario/1`` file."""
        return dump_yaml(self.data(), sort_keys=False, default_flow_style=None, width=120)


def trail(legs: Sequence[float], turns_deg: Sequence[float], margin_m: float = 12.0) -> tuple[np.ndarray, tuple[float, float]]:
    """Waypoints of a trail of straight ``legs`` [m] with a heading change of ``turns_deg[k]`` after
    leg k, shifted ``margin_m`` inside a world whose size (x, y) [m] comes with it."""
    heading, point = 0.0, np.zeros(2)
    points = [point]
    for k, length in enumerate(legs):
        point = point + length * np.array([math.cos(heading), math.sin(heading)])
        points.append(point)
        if k < len(turns_deg):
            heading += math.radians(turns_deg[k])
    wp = np.array(points)
    wp = wp - wp.min(axis=0) + margin_m
    size = (float(math.ceil(wp[:, 0].max() + margin_m)), float(math.ceil(wp[:, 1].max() + margin_m)))
    return wp, size
