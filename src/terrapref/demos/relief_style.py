"""A driver's relief style (SPEC 19): how much side slope and grade it takes before going round,
how much speed it sheds per degree up and down, and its speed on rough ground.

The synthetic driver (terrapref.demos.expert) reads the ground as a person feels it: how its
body would roll and pitch at each point of a way, heading along it, its wheels on the world's
height field (:class:`ReliefSight`); and the ground's roughness, the heights' standard deviation
about their plane within 0.3 m (terrapref.world.raster.ROUGH_RADIUS_M). A way over ground steeper than the style takes costs more than any terrain
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
import re
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from typing import Any

import numpy as np
from numba import njit

from terrapref.errors import UserError, described, finite_number
from terrapref.records import to_plain
from terrapref.registry import Registry
from terrapref.world.height_compiled import height_at, roughness
from terrapref.world.raster import rough_reach

NO_RELIEF_STYLE = "none"  # --relief-style none: a driver that drives relief as if it were flat
MAX_ROUGH_M = 1.0  # the roughest ground a relief style may call smooth [m]: a metre's spread of heights about their plane
_NUMBER = re.compile(r"^[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?$")  # a k=v pair's number
MAX_SHED_MPS_PER_DEG = 0.2  # the most speed a relief style sheds per degree of grade [m/s per deg]: 2 m/s over 10 deg


@dataclass(frozen=True)
class ReliefStyle:
    """How a driver takes relief.

    Attributes:
        roll_deg: the steepest side slope it drives along without going round (its body's roll
            there) [deg].
        grade_deg: the steepest grade, up or down, it takes without going round (its body's
            pitch there) [deg].
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
    rough_m: float = 0.015

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not finite_number(value):
                raise ValueError(f"{f.name} must be a finite number, got {described(value)}")
        for name in ("roll_deg", "grade_deg"):
            if not 0.0 < getattr(self, name) < 90.0:
                raise ValueError(f"{name} must lie in (0, 90) deg, got {getattr(self, name):g}")
        for name in ("up_mps_per_deg", "down_mps_per_deg"):
            if not 0.0 <= getattr(self, name) <= MAX_SHED_MPS_PER_DEG:
                raise ValueError(
                    f"{name} must lie in [0, {MAX_SHED_MPS_PER_DEG:g}] (at most a vehicle's whole top speed shed over 10 deg), "
                    f"got {getattr(self, name):g}"
                )
        for name in ("rough_mps", "rough_m"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name):g}")
        if self.rough_m > MAX_ROUGH_M:
            raise ValueError(f"rough_m must be at most {MAX_ROUGH_M:g} m, got {self.rough_m:g}")

    def to_dict(self) -> dict[str, Any]:
        return to_plain(self)

    @classmethod
    def written(cls, raw: Any) -> ReliefStyle | None:
        """The style a file wrote (:meth:`to_dict`); None for anything else, or one this version does not read."""
        if not isinstance(raw, Mapping):
            return None
        try:
            return cls(**raw)
        except (TypeError, ValueError):
            return None

    def describe(self) -> str:
        """The style as ``--relief-style`` takes it, then where it goes round and how it slows, in words."""
        return (
            f"{self.as_flag()} (round side slopes past {self.roll_deg:g} deg and grades past {self.grade_deg:g} deg; "
            f"{self.up_mps_per_deg:g} m/s less a deg up, {self.down_mps_per_deg:g} down; {self.rough_mps:g} m/s on ground "
            f"rougher than {self.rough_m:g} m)"
        )

    def as_flag(self) -> str:
        """The style as ``--relief-style`` takes it: the named style it is, else its fields that
        differ from the default's as ``k=v`` pairs."""
        for name in RELIEF_STYLES.names():
            if replace(ReliefStyle(), **RELIEF_STYLES[name]) == self:
                return name
        base = ReliefStyle()
        return ",".join(f"{f.name}={getattr(self, f.name)!r}" for f in fields(self) if getattr(self, f.name) != getattr(base, f.name))

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


def parse_relief_style(text: str, source: str = "--relief-style") -> tuple[str, ReliefStyle | None]:
    """``NAME``, ``NAME,k=v,...`` or ``k=v,...`` (over the default) as the style's name and the
    style, or ``none`` (a driver that drives relief as if it were flat: None); an unknown name or
    field, a bad value or one out of range is a UserError."""
    if text.strip() == NO_RELIEF_STYLE:
        return NO_RELIEF_STYLE, None
    parts = [p.strip() for p in text.split(",")]
    if parts[0] == NO_RELIEF_STYLE:
        raise UserError(source, f"{NO_RELIEF_STYLE} (relief driven as if it were flat) takes no k=v changes; got {text.strip()!r}")
    name = "default"
    if parts and "=" not in parts[0]:
        name = parts.pop(0)
        if name not in RELIEF_STYLES.names():
            raise UserError(source, f"{name!r} is not a relief style ({', '.join(RELIEF_STYLES.names())}, or {NO_RELIEF_STYLE})")
    changes: dict[str, float] = dict(RELIEF_STYLES[name])
    known = [f.name for f in fields(ReliefStyle)]
    given: set[str] = set()
    for item in parts:
        key, sep, value = (s.strip() for s in item.partition("="))
        if not sep or key not in known:
            raise UserError(source, f"expected NAME or k=v pairs with k one of {', '.join(known)}; got {item!r}")
        if key in given:
            raise UserError(source, f"{key} is given twice")
        number = float(value) if _NUMBER.match(value) else math.nan  # a number as a file writes one (float() takes 1_0 too)
        if not math.isfinite(number):
            raise UserError(source, f"{key}: expected a number, got {value!r}")
        changes[key] = number
        given.add(key)
    try:
        return name, replace(ReliefStyle(), **changes)
    except ValueError as exc:
        raise UserError(source, str(exc)) from None


class ReliefSight:
    """The relief of a world as the driver reads it (module docstring): where its body would sit,
    its roll across the way and its pitch along it, as its wheels would set them (the heights
    under its wheels, a track of ``2 * half_width_m`` and a wheelbase of ``wheelbase_m``, as
    terrapref.vehicle.ground sets the vehicle's), and the ground's roughness at points.

    Args:
        heights: the world's height field (ny, nx) [m] at its cell centres.
        res: its cell size [m].
        half_width_m, wheelbase_m: the body's.
    """

    def __init__(self, heights: np.ndarray, res: float, half_width_m: float, wheelbase_m: float) -> None:
        self.heights = np.ascontiguousarray(heights, dtype=np.float32)
        self.res = float(res)
        self.body = (float(half_width_m), 0.5 * float(wheelbase_m))
        self.reach = rough_reach(res)

    def steep(self, centre: np.ndarray, normal: np.ndarray, offsets: np.ndarray, upto: int, style: ReliefStyle) -> np.ndarray:
        """Whether the body, centred ``offsets[o]`` left of the path at its first ``upto`` points
        ``centre`` (``normal`` pointing left) and heading along it, would roll past ``style``'s
        ``roll_deg`` or pitch past its ``grade_deg``: (O, upto) bool."""
        limits = (math.tan(math.radians(style.roll_deg)), math.tan(math.radians(style.grade_deg)))
        return _steep(centre, normal, np.asarray(offsets, dtype=np.float64), upto, self.heights, 1.0 / self.res, self.body, limits)

    def along(self, xy: np.ndarray, heading: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The body's pitch [rad, positive nose up] heading ``heading`` (N,) [rad] at the points
        ``xy`` (N, 2), and the roughness [m] there; smooth off the map."""
        xy = np.ascontiguousarray(xy, dtype=np.float64)
        heading = np.asarray(heading, dtype=np.float64)
        return _pitch_and_roughness(xy, heading, self.heights, self.res, self.body[1], self.reach)


@njit(cache=True, nogil=True)
def _steep(
    centre: np.ndarray,
    normal: np.ndarray,
    offsets: np.ndarray,
    upto: int,
    heights: np.ndarray,
    per_m: float,
    body: tuple[float, float],
    limits: tuple[float, float],
) -> np.ndarray:
    """:meth:`ReliefSight.steep`: ``limits``, the tangents of the roll and the pitch taken."""
    half_width, half_length = body
    tan_roll, tan_grade = limits
    out = np.zeros((offsets.shape[0], upto), np.bool_)
    for o in range(offsets.shape[0]):
        for k in range(upto):
            nx, ny = normal[k, 0], normal[k, 1]
            x, y = centre[k, 0] + offsets[o] * nx, centre[k, 1] + offsets[o] * ny
            left = height_at(heights, per_m, x + half_width * nx, y + half_width * ny)
            right = height_at(heights, per_m, x - half_width * nx, y - half_width * ny)
            front = height_at(heights, per_m, x + half_length * ny, y - half_length * nx)  # along the tangent (ny, -nx)
            back = height_at(heights, per_m, x - half_length * ny, y + half_length * nx)
            out[o, k] = abs(left - right) > 2.0 * half_width * tan_roll or abs(front - back) > 2.0 * half_length * tan_grade
    return out


@njit(cache=True, nogil=True)
def _pitch_and_roughness(
    xy: np.ndarray, heading: np.ndarray, heights: np.ndarray, res: float, half_length: float, reach: int
) -> tuple[np.ndarray, np.ndarray]:
    """:meth:`ReliefSight.along`: the roughness the standard deviation of the heights within
    ``reach`` cells (a disc) about their least-squares plane."""
    n_rows, n_cols = heights.shape
    pitch, rough = np.zeros(xy.shape[0]), np.zeros(xy.shape[0])
    for i in range(xy.shape[0]):
        x, y, c, s = xy[i, 0], xy[i, 1], math.cos(heading[i]), math.sin(heading[i])
        rise = height_at(heights, 1.0 / res, x + half_length * c, y + half_length * s)
        rise -= height_at(heights, 1.0 / res, x - half_length * c, y - half_length * s)
        pitch[i] = math.atan(rise / (2.0 * half_length))
        r0, c0 = int(math.floor(y / res)), int(math.floor(x / res))
        if 0 <= r0 < n_rows and 0 <= c0 < n_cols:
            rough[i] = roughness(heights, r0, c0, res, reach)
    return pitch, rough
