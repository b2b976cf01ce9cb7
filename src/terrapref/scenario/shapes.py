"""Planar shapes used for terrain patches and scoring zones, with vectorised point tests."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class Polygon:
    """A simple or self-intersecting polygon (even-odd rule); ``vertices`` shape (k, 2) [m]."""

    vertices: np.ndarray

    def contains(self, points: np.ndarray) -> np.ndarray:
        """Boolean mask, shape (N,), of the points (N, 2) inside the polygon (even-odd rule)."""
        px, py = points[:, 0], points[:, 1]
        inside = np.zeros(len(points), dtype=bool)
        v = self.vertices
        for (x0, y0), (x1, y1) in zip(v, np.roll(v, -1, axis=0)):
            if y0 == y1:
                continue
            crosses = (py >= min(y0, y1)) & (py < max(y0, y1))
            x_at = x0 + (py - y0) * (x1 - x0) / (y1 - y0)
            inside ^= crosses & (px < x_at)
        return inside

    def bounds(self) -> tuple[float, float, float, float]:
        lo, hi = self.vertices.min(axis=0), self.vertices.max(axis=0)
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])

    def to_dict(self) -> dict:
        return {"polygon": self.vertices.tolist()}


@dataclass(frozen=True)
class Circle:
    center: tuple[float, float]
    radius_m: float

    def contains(self, points: np.ndarray) -> np.ndarray:
        d2 = (points[:, 0] - self.center[0]) ** 2 + (points[:, 1] - self.center[1]) ** 2
        return d2 <= self.radius_m**2

    def bounds(self) -> tuple[float, float, float, float]:
        (cx, cy), r = self.center, self.radius_m
        return cx - r, cy - r, cx + r, cy + r

    def to_dict(self) -> dict:
        return {"circle": {"center": list(self.center), "radius": self.radius_m}}


@dataclass(frozen=True)
class Rectangle:
    """A rectangle of ``size`` (length along its own x, width along its y) rotated by ``yaw_rad``."""

    center: tuple[float, float]
    size: tuple[float, float]
    yaw_rad: float = 0.0

    def contains(self, points: np.ndarray) -> np.ndarray:
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        dx, dy = points[:, 0] - self.center[0], points[:, 1] - self.center[1]
        lx, ly = c * dx + s * dy, -s * dx + c * dy
        return (np.abs(lx) <= self.size[0] / 2) & (np.abs(ly) <= self.size[1] / 2)

    def corners(self) -> np.ndarray:
        """Corner points, shape (4, 2), counter-clockwise."""
        hx, hy = self.size[0] / 2, self.size[1] / 2
        local = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        rot = np.array([[c, -s], [s, c]])
        return local @ rot.T + np.asarray(self.center)

    def bounds(self) -> tuple[float, float, float, float]:
        pts = self.corners()
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])

    def to_dict(self) -> dict:
        return {"rectangle": {"center": list(self.center), "size": list(self.size), "yaw_deg": math.degrees(self.yaw_rad)}}


Shape = Polygon | Circle | Rectangle


def outline(shape: Shape, segments: int = 64) -> np.ndarray:
    """Closed outline of a shape for drawing, shape (k, 2) [m]."""
    if isinstance(shape, Circle):
        t = np.linspace(0, 2 * np.pi, segments + 1)
        return np.stack([shape.center[0] + shape.radius_m * np.cos(t), shape.center[1] + shape.radius_m * np.sin(t)], axis=1)
    pts = shape.corners() if isinstance(shape, Rectangle) else shape.vertices
    return np.vstack([pts, pts[:1]])
