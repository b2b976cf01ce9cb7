"""Unicycle kinematics (SPEC section 4), integrated exactly for a constant command."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple


class Pose(NamedTuple):
    """Planar pose in the world frame: x [m] east, y [m] north, yaw [rad] CCW from +x."""

    x: float
    y: float
    yaw: float


class Command(NamedTuple):
    """Velocity command: v [m/s] forward, w [rad/s] counter-clockwise (left)."""

    v: float
    w: float


def wrap_angle(a: float) -> float:
    """Angle wrapped to [-pi, pi)."""
    return (a + math.pi) % (2 * math.pi) - math.pi


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

    Attributes:
        control_rate_hz: rate of the internal controller that applies the held command [Hz].
        max_speed_mps: commands are clipped to v in [0, max_speed_mps] [m/s].
        max_yaw_rate_rps: commands are clipped to |w| <= max_yaw_rate_rps [rad/s].
        half_width_m: half the vehicle's width: its footprint is the line across it at the
            reference point, and lethal terrain under any part of that line is contact [m].
    """

    control_rate_hz: float = 30.0
    max_speed_mps: float = 1.0
    max_yaw_rate_rps: float = 1.0
    half_width_m: float = 0.6

    def __post_init__(self) -> None:
        values = (self.control_rate_hz, self.max_speed_mps, self.max_yaw_rate_rps, self.half_width_m)
        if not all(math.isfinite(v) and v > 0 for v in values):
            raise ValueError("vehicle rates, limits and half width must be finite and > 0")

    @property
    def footprint_m(self) -> tuple[float, ...]:
        """Lateral positions of the footprint's 5 points, left positive [m]."""
        return tuple(self.half_width_m * k / 2 for k in (-2, -1, 0, 1, 2))

    @property
    def dt_s(self) -> float:
        return 1.0 / self.control_rate_hz


class Vehicle:
    """A differential-drive vehicle whose controller holds the last command between ticks."""

    def __init__(self, pose: Pose, config: VehicleConfig | None = None) -> None:
        self.config = config or VehicleConfig()
        self.pose = Pose(*pose)
        self.command = Command(0.0, 0.0)

    def set_command(self, cmd: Command) -> None:
        """Latch a new command, clipped to the vehicle's limits; it is held until the next one."""
        c = self.config
        v = min(max(float(cmd.v), 0.0), c.max_speed_mps)
        w = min(max(float(cmd.w), -c.max_yaw_rate_rps), c.max_yaw_rate_rps)
        self.command = Command(v, w)

    def tick(self) -> Pose:
        """Advance one controller period (1 / control_rate_hz) with the held command."""
        x, y, yaw = integrate_unicycle(self.pose, self.command, self.config.dt_s)
        self.pose = Pose(x, y, wrap_angle(yaw))
        return self.pose
