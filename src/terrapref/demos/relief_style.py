"""A driver's relief style (SPEC 19): how much side slope and grade it takes before going round,
how much speed it sheds per degree up and down, and its speed on rough ground.

The synthetic driver (terrapref.demos.expert) reads the ground as a person sees it: the grade
of each point of a way along the way's heading, and its side slope across it, from the world's
height field; its roughness, the heights' standard deviation about their plane within
:data:`ROUGH_RADIUS_M`. A way over ground steeper than the style takes costs more than any terrain
class, so the driver goes round it where it can, weighed against the terrain it would cross to
do so; its speed is that of the terrain it drives on, less ``up_mps_per_deg`` for each degree of
grade up (``down_mps_per_deg`` down), and at most ``rough_mps`` where the ground is rougher than
``rough_m``. Its terrain order and its speeds per class are what they are without relief.

Named styles (:data:`RELIEF_STYLES`), and ``k=v`` pairs over one::

    terrapref record teach_relief --relief-style cautious --out rec
    terrapref record teach_relief --relief-style default,roll_deg=8,up_mps_per_deg=0.05 --out rec
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np
from numba import njit

from terrapref.errors import UserError
from terrapref.records import to_plain
from terrapref.registry import Registry

ROUGH_RADIUS_M = 0.3  # the disc a point's roughness is read over [m]: as the planner's height layer reads it


@dataclass(frozen=True)
class ReliefStyle:
    """How a driver takes relief.

    Attributes:
        roll_deg: the steepest side slope it drives along without going round [deg].
        grade_deg: the steepest grade, up or down, it takes without going round [deg].
        up_mps_per_deg: the speed it sheds per degree of grade up [m/s per deg] ...
        down_mps_per_deg: ... and down.
        rough_mps: its top speed where the ground is rougher than ``rough_m`` [m/s].
        rough_m: see ``rough_mps`` [m, the heights' standard deviation about their plane].
    """

    roll_deg: float = 12.0
    grade_deg: float = 15.0
    up_mps_per_deg: float = 0.03
    down_mps_per_deg: float = 0.02
    rough_mps: float = 0.8
    rough_m: float = 0.03

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)):
                raise ValueError(f"{f.name} must be a finite number, got {value!r}")
        if not (0.0 < self.roll_deg < 90.0 and 0.0 < self.grade_deg < 90.0):
            raise ValueError(f"roll_deg and grade_deg must lie in (0, 90) deg, got {self.roll_deg:g} and {self.grade_deg:g}")
        if min(self.up_mps_per_deg, self.down_mps_per_deg) < 0.0 or self.rough_mps <= 0.0 or self.rough_m <= 0.0:
            raise ValueError("up_mps_per_deg and down_mps_per_deg must be >= 0, rough_mps and rough_m > 0")

    def to_dict(self) -> dict[str, Any]:
        return to_plain(self)

    def speed(self, v_mps: float, grade_rad: float, rough_m: float, least_mps: float) -> float:
        """The speed [m/s] it drives at where its terrain's speed is ``v_mps``, on a grade of
        ``grade_rad`` along its heading (positive up) and ground of roughness ``rough_m``; never
        below ``least_mps`` (it crawls up a grade it takes rather than stands)."""
        degrees = math.degrees(grade_rad)
        v = v_mps - (self.up_mps_per_deg * degrees if degrees > 0.0 else -self.down_mps_per_deg * degrees)
        if rough_m > self.rough_m:
            v = min(v, self.rough_mps)
        return max(v, least_mps)


# Named relief styles: the fields that differ from the default's; `terrapref record --relief-style NAME`.
RELIEF_STYLES: Registry[dict[str, float]] = Registry("relief style", "relief styles")
RELIEF_STYLES.register("default", {}, doc="goes round side slopes past 12 deg and grades past 15 deg; sheds 0.03 m/s per deg up, 0.02 down")
RELIEF_STYLES.register(
    "bold",
    {"roll_deg": 20.0, "grade_deg": 22.0, "up_mps_per_deg": 0.01, "down_mps_per_deg": 0.01, "rough_mps": 1.2},
    doc="takes side slopes to 20 deg and grades to 22 deg; sheds 0.01 m/s per deg; 1.2 m/s on rough ground",
)
RELIEF_STYLES.register(
    "cautious",
    {"roll_deg": 7.0, "grade_deg": 9.0, "up_mps_per_deg": 0.05, "down_mps_per_deg": 0.05, "rough_mps": 0.5},
    doc="goes round side slopes past 7 deg and grades past 9 deg; sheds 0.05 m/s per deg; 0.5 m/s on rough ground",
)


def parse_relief_style(text: str, source: str = "--relief-style") -> tuple[str, ReliefStyle]:
    """``NAME``, ``NAME,k=v,...`` or ``k=v,...`` (over the default) as the style's name and the
    style; an unknown name or field, a bad value or one out of range is a UserError."""
    parts = [p.strip() for p in text.split(",")]
    name = "default"
    if parts and "=" not in parts[0]:
        name = parts.pop(0)
        if name not in RELIEF_STYLES.names():
            raise UserError(source, f"{name!r} is not a relief style ({', '.join(RELIEF_STYLES.names())})")
    changes: dict[str, float] = dict(RELIEF_STYLES[name])
    known = [f.name for f in fields(ReliefStyle)]
    given: set[str] = set()
    for item in parts:
        key, sep, value = (s.strip() for s in item.partition("="))
        if not sep or key not in known:
            raise UserError(source, f"expected NAME or k=v pairs with k one of {', '.join(known)}; got {item!r}")
        if key in given:
            raise UserError(source, f"{key} is given twice")
        try:
            number = float(value)
        except ValueError:
            number = math.nan
        if not math.isfinite(number):
            raise UserError(source, f"{key}: expected a number, got {value!r}")
        changes[key] = number
        given.add(key)
    try:
        return name, replace(ReliefStyle(), **changes)
    except ValueError as exc:
        raise UserError(source, str(exc)) from None


class ReliefSight:
    """The relief of a world as the driver reads it (module docstring): the height field's
    gradient (central differences) and, at points, the roughness.

    Args:
        heights: the world's height field (ny, nx) [m] at its cell centres.
        res: its cell size [m].
    """

    def __init__(self, heights: np.ndarray, res: float) -> None:
        z = np.asarray(heights, dtype=np.float64)
        gy, gx = np.gradient(z, res) if min(z.shape) > 1 else (np.zeros_like(z), np.zeros_like(z))
        self.heights = np.ascontiguousarray(heights, dtype=np.float32)
        self.gx, self.gy = gx.astype(np.float32), gy.astype(np.float32)
        self.res = float(res)
        self.reach = max(1, int(math.floor(ROUGH_RADIUS_M / res + 1e-9)))

    def steep(self, centre: np.ndarray, normal: np.ndarray, lat: np.ndarray, upto: int, style: ReliefStyle) -> np.ndarray:
        """Whether each point ``centre[s] + lat[o, f] * normal[s]`` (O, upto, F) lies on ground
        steeper than ``style`` takes, driven along the path (its tangent at ``s``, left of which
        ``normal`` points): a side slope past ``roll_deg`` or a grade past ``grade_deg``."""
        limits = (math.tan(math.radians(style.roll_deg)), math.tan(math.radians(style.grade_deg)))
        return _steep(centre, normal, lat, upto, self.gx, self.gy, self.res, limits)

    def along(self, xy: np.ndarray, heading: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The grade [rad, positive up] along ``heading`` (N,) [rad] and the roughness [m] at the
        points ``xy`` (N, 2); level and smooth off the map."""
        xy = np.ascontiguousarray(xy, dtype=np.float64)
        return _grade_and_roughness(xy, np.asarray(heading, dtype=np.float64), self.heights, self.gx, self.gy, self.res, self.reach)


@njit(cache=True, nogil=True)
def _steep(
    centre: np.ndarray,
    normal: np.ndarray,
    lat: np.ndarray,
    upto: int,
    gx: np.ndarray,
    gy: np.ndarray,
    res: float,
    limits: tuple[float, float],
) -> np.ndarray:
    """:meth:`ReliefSight.steep`: ``limits``, the tangents of the side slope and the grade taken."""
    n_rows, n_cols = gx.shape
    tan_roll, tan_grade = limits
    out = np.zeros((lat.shape[0], upto, lat.shape[1]), np.bool_)
    for o in range(lat.shape[0]):
        for k in range(upto):
            nx, ny = normal[k, 0], normal[k, 1]
            for f in range(lat.shape[1]):
                row = int(math.floor((centre[k, 1] + lat[o, f] * ny) / res))
                col = int(math.floor((centre[k, 0] + lat[o, f] * nx) / res))
                if not (0 <= row < n_rows and 0 <= col < n_cols):
                    continue
                side = gx[row, col] * nx + gy[row, col] * ny
                grade = gx[row, col] * ny - gy[row, col] * nx  # along the tangent (ny, -nx)
                out[o, k, f] = abs(side) > tan_roll or abs(grade) > tan_grade
    return out


@njit(cache=True, nogil=True)
def _grade_and_roughness(
    xy: np.ndarray, heading: np.ndarray, heights: np.ndarray, gx: np.ndarray, gy: np.ndarray, res: float, reach: int
) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`ReliefSight.along`: the roughness the standard deviation of the heights within
    ``reach`` cells (a disc) about their least-squares plane."""
    n_rows, n_cols = heights.shape
    grade, rough = np.zeros(xy.shape[0]), np.zeros(xy.shape[0])
    for i in range(xy.shape[0]):
        r0, c0 = int(math.floor(xy[i, 1] / res)), int(math.floor(xy[i, 0] / res))
        if not (0 <= r0 < n_rows and 0 <= c0 < n_cols):
            continue
        grade[i] = math.atan(gx[r0, c0] * math.cos(heading[i]) + gy[r0, c0] * math.sin(heading[i]))
        m = sx = sy = sz = sxx = syy = sxy = sxz = syz = szz = 0.0
        for dr in range(-reach, reach + 1):
            for dc in range(-reach, reach + 1):
                r, c = r0 + dr, c0 + dc
                if dr * dr + dc * dc > reach * reach or not (0 <= r < n_rows and 0 <= c < n_cols):
                    continue
                x, y, z = dc * res, dr * res, np.float64(heights[r, c])
                m, sx, sy, sz = m + 1.0, sx + x, sy + y, sz + z
                sxx, syy, sxy, sxz, syz, szz = sxx + x * x, syy + y * y, sxy + x * y, sxz + x * z, syz + y * z, szz + z * z
        cxx, cyy, cxy = sxx - sx * sx / m, syy - sy * sy / m, sxy - sx * sy / m
        cxz, cyz, czz = sxz - sx * sz / m, syz - sy * sz / m, szz - sz * sz / m
        det = cxx * cyy - cxy * cxy
        if det > 0.0:
            a, b = (cxz * cyy - cyz * cxy) / det, (cyz * cxx - cxz * cxy) / det
            rough[i] = math.sqrt(max(czz - a * cxz - b * cyz, 0.0) / m)
    return grade, rough
