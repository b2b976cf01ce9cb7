"""Unicycle kinematics (SPEC section 4), integrated exactly for a constant command."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

from terrapref.records import to_plain

if TYPE_CHECKING:
    import numpy as np


POSE_DIFFERENCE_HALF_S = 0.1  # a pose's motion: the poses this long before and after it, differenced (centred, over 0.2 s)
MIN_CRUISE_MPS = 0.1  # the slowest a driver cruises, or the planner's speed rule commands while it drives [m/s]; slower is standing


class Pose(NamedTuple):
    """Planar pose in the world frame: x [m] east, y [m] north, yaw [rad] CCW from +x."""

    x: float
    y: float
    yaw: float


class Command(NamedTuple):
    """Velocity command: v [m/s] forward, w [rad/s] counter-clockwise (left)."""

    v: float
    w: float


def wrap_angle(a: float | np.ndarray) -> float | np.ndarray:
    """Angle (or angles, element by element) wrapped to [-pi, pi)."""
    return (a + math.pi) % (2 * math.pi) - math.pi


def pose_velocities(t: np.ndarray, poses: np.ndarray, half_s: float = POSE_DIFFERENCE_HALF_S) -> np.ndarray:
    """(v [m/s], w [rad/s]) (N, 2) at each of ``poses`` (N, 3: x, y, unwrapped yaw) stamped ``t`` (N,) [s], sorted.

    A centred difference of the poses ``half_s`` before and after each one (interpolated;
    one-sided at the ends), over a window rather than between neighbours so that jitter in the
    stamps and positions averages out: v is the displacement along the heading (negative when
    reversing) over dt, w the yaw change, wrapped, over dt. NaN where dt is 0.
    """
    import numpy as np

    lo = np.maximum(t - half_s, t[0])
    hi = np.minimum(t + half_s, t[-1])
    before = np.stack([np.interp(lo, t, poses[:, k]) for k in range(3)], axis=1)
    after = np.stack([np.interp(hi, t, poses[:, k]) for k in range(3)], axis=1)
    step = after - before
    forward = step[:, 0] * np.cos(poses[:, 2]) + step[:, 1] * np.sin(poses[:, 2])
    turn = wrap_angle(step[:, 2])
    dt = np.where(hi > lo, hi - lo, math.nan)
    return np.stack([forward / dt, turn / dt], axis=1)


def pure_pursuit_yaw_rate(speed_mps: float, sin_alpha: float, distance_m: float) -> float:
    """Yaw rate [rad/s] that drives a unicycle at ``speed_mps`` along the circle through a target
    ``distance_m`` away, whose bearing from the heading has the sine ``sin_alpha``: 2 v sin(alpha) / L.

    >>> pure_pursuit_yaw_rate(1.0, 0.5, 2.0)  # 30 deg off, 2 m away: a circle of 2 m radius
    0.5
    """
    return 2.0 * speed_mps * sin_alpha / distance_m


def integrate_unicycle(pose: Pose, cmd: Command, dt: float) -> Pose:
    """Exact pose after holding ``cmd`` for ``dt`` [s]: a straight segment or a circular arc."""
    x, y, yaw = pose
    v, w = cmd
    if abs(w * dt) < 1e-9:
        return Pose(x + v * dt * math.cos(yaw), y + v * dt * math.sin(yaw), yaw + w * dt)
    yaw1 = yaw + w * dt
    r = v / w
    return Pose(x + r * (math.sin(yaw1) - math.sin(yaw)), y - r * (math.cos(yaw1) - math.cos(yaw)), yaw1)


@dataclass(frozen=True)
class VehicleConfig:
    """Vehicle limits and controller rate.

    The defaults are a field UGV's of about 1.2 m across (a Husky or Warthog class vehicle on
    loose ground): 2 m/s top speed; 1 m/s^2 of acceleration, which its drive gives on grass and
    mud without wheel spin (0 to 2 m/s in 2 s); 2 m/s^2 of braking, about 0.2 g, well inside the
    grip of wet grass (friction about 0.5), so that it stops from 2 m/s within 1 m without
    sliding. :meth:`paper` is the paper's vehicle: 1 m/s, every command applied at once.

    Attributes:
        control_rate_hz: rate of the internal controller that applies the held command [Hz].
        max_speed_mps: commands are clipped to v in [0, max_speed_mps] [m/s].
        max_yaw_rate_rps: commands are clipped to |w| <= max_yaw_rate_rps [rad/s].
        half_width_m: half the vehicle's width: its footprint is the line across it at the
            reference point, and lethal terrain under any part of that line is contact [m].
        max_accel_mps2: how fast the speed may rise toward the command [m/s^2]; None: at once.
        max_decel_mps2: how fast the speed may fall toward the command [m/s^2]; None: at once.
        wheelbase_m: from the rear wheels to the front ones, the reference point midway; on relief
            the body rests on the four wheels (terrapref.vehicle.ground) [m].
        max_roll_deg: past this roll the vehicle has tipped over [deg].
        max_pitch_deg: past this pitch, nose up or down, it has tipped over [deg].
        max_step_m: the highest step its wheels climb; a higher one stops it (stuck) [m].
        rolling_resistance: the ground's rolling resistance coefficient, which sets how much a
            grade slows it (:meth:`terrapref.vehicle.ground.GroundContact.top_speed_mps`).
    """

    control_rate_hz: float = 30.0
    max_speed_mps: float = 2.0
    max_yaw_rate_rps: float = 1.0
    half_width_m: float = 0.6
    max_accel_mps2: float | None = 1.0
    max_decel_mps2: float | None = 2.0
    wheelbase_m: float = 1.0
    max_roll_deg: float = 25.0
    max_pitch_deg: float = 30.0
    max_step_m: float = 0.15
    rolling_resistance: float = 0.15

    def __post_init__(self) -> None:
        values = (self.control_rate_hz, self.max_speed_mps, self.max_yaw_rate_rps, self.half_width_m, self.wheelbase_m, self.max_step_m)
        if not all(_positive(v) for v in values):
            raise ValueError("vehicle rates, limits, half width, wheelbase and step must be finite and > 0")
        if not all(_positive(a) and a < 90.0 for a in (self.max_roll_deg, self.max_pitch_deg)):
            raise ValueError(f"max_roll_deg and max_pitch_deg must be in (0, 90), got {self.max_roll_deg!r} and {self.max_pitch_deg!r}")
        if not (_positive(self.rolling_resistance) and self.rolling_resistance <= 1.0):
            raise ValueError(f"rolling_resistance must be in (0, 1], got {self.rolling_resistance!r}")
        if not all(a is None or _positive(a) for a in (self.max_accel_mps2, self.max_decel_mps2)):
            raise ValueError(
                f"max_accel_mps2 and max_decel_mps2 must be None (at once) or finite and > 0, got {self.max_accel_mps2!r} and {self.max_decel_mps2!r}"
            )

    @classmethod
    def paper(cls) -> VehicleConfig:
        """The paper's vehicle: 1 m/s top speed and every command applied at once."""
        return cls(max_speed_mps=1.0, max_accel_mps2=None, max_decel_mps2=None)

    @classmethod
    def from_dict(cls, data: dict) -> VehicleConfig:
        """The vehicle a recording's metadata names; one recorded before acceleration limits
        existed applied its commands at once."""
        return cls(**{"max_accel_mps2": None, "max_decel_mps2": None, **data})

    def to_dict(self) -> dict:
        return to_plain(self)

    @property
    def footprint_m(self) -> tuple[float, ...]:
        """Lateral positions of the footprint's 5 points, left positive [m]."""
        return tuple(self.half_width_m * k / 2 for k in (-2, -1, 0, 1, 2))

    @property
    def dt_s(self) -> float:
        return 1.0 / self.control_rate_hz

    def braking_distance_m(self, v_mps: float) -> float:
        """Distance [m] this vehicle needs to stop from ``v_mps`` (0 when it stops at once)."""
        return 0.0 if self.max_decel_mps2 is None else v_mps * v_mps / (2.0 * self.max_decel_mps2)

    def next_speed(self, speed_mps: float, target_mps: float) -> float:
        """The speed [m/s] one controller period after ``speed_mps``, moving toward ``target_mps``
        within the acceleration limits."""
        if target_mps > speed_mps:
            step = math.inf if self.max_accel_mps2 is None else self.max_accel_mps2 * self.dt_s
            return min(target_mps, speed_mps + step)
        step = math.inf if self.max_decel_mps2 is None else self.max_decel_mps2 * self.dt_s
        return max(target_mps, speed_mps - step)


def _positive(x: float) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) and x > 0
