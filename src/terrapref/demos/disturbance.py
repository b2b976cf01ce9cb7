"""Disturbances while demonstrating: now and then the vehicle's yaw rate is pushed off what the
driver commands for a moment, the way a rut or a slip would, and the driver steers back.

A learner that has only seen a driver on its own line has never seen how to get back to it,
and a planner is never exactly on that line.

A push's numbers are given as at 1 m/s (:data:`REFERENCE_SPEED_MPS`). Slower, a push is the
same stretch of ground as at 1 m/s (a rut, a slip): at the commanded speed v it comes v times as
often per second, lasts 1/v times as long and turns v times as fast, so it bends the path by the
same curvature over the same distance. A driver creeping over rock is not spun round by a push
sized for 1 m/s, and a stopped vehicle is not pushed. Faster, a push stays as at 1 m/s in time:
grown with the speed as well, it would carry the vehicle farther than the driver's reaction
delay lets it catch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from terrapref.records import to_plain
from terrapref.vehicle import Command

REFERENCE_SPEED_MPS = 1.0  # a push's rate, yaw rate and duration are given as at this speed


@dataclass(frozen=True)
class DisturbanceConfig:
    """Random yaw-rate pushes added to the executed command while demonstrating, each as at
    :data:`REFERENCE_SPEED_MPS` and faster (module docstring: slower, the same stretch of ground).

    Attributes:
        rate_hz: expected pushes per second at 1 m/s (a Poisson process; 0 is off).
        min_yaw_rate_rps, max_yaw_rate_rps: magnitude range of a push at 1 m/s [rad/s]; its sign
            is a coin toss.
        min_duration_s, max_duration_s: how long a push lasts at 1 m/s [s].
        max_command_rps: the vehicle's yaw-rate limit; the pushed command is clipped to it.
    """

    rate_hz: float = 0.15
    min_yaw_rate_rps: float = 0.3
    max_yaw_rate_rps: float = 0.6
    min_duration_s: float = 0.3
    max_duration_s: float = 1.5
    max_command_rps: float = 1.0

    @property
    def active(self) -> bool:
        return self.rate_hz > 0

    def __post_init__(self) -> None:
        if not (
            self.rate_hz >= 0
            and 0 <= self.min_yaw_rate_rps <= self.max_yaw_rate_rps
            and 0 < self.min_duration_s <= self.max_duration_s
            and self.max_command_rps > 0
        ):
            raise ValueError("disturbance: rate >= 0, 0 <= min <= max yaw rate, 0 < min <= max duration")

    def to_dict(self) -> dict:
        return to_plain(self)


class Disturber:
    """Draws the pushes of one run from its own seeded stream."""

    def __init__(self, config: DisturbanceConfig, rng: np.random.Generator, dt: float) -> None:
        self.config, self.rng, self.dt = config, rng, dt
        self.left_m, self.push = 0.0, 0.0  # the push's time left, as metres at 1 m/s; its yaw rate at 1 m/s [rad/s]

    def __call__(self, command: Command) -> Command:
        """The command the vehicle executes instead of ``command`` (often ``command`` itself), the
        push scaled to a commanded speed under 1 m/s (module docstring)."""
        c = self.config
        scale = min(max(float(command[0]), 0.0) / REFERENCE_SPEED_MPS, 1.0)  # 1 at 1 m/s and faster: pushes exactly as configured
        if self.left_m <= 0.0 and self.rng.random() < -math.expm1(-c.rate_hz * scale * self.dt):
            self.left_m = self.rng.uniform(c.min_duration_s, c.max_duration_s) * REFERENCE_SPEED_MPS
            self.push = float(self.rng.choice((-1.0, 1.0)) * self.rng.uniform(c.min_yaw_rate_rps, c.max_yaw_rate_rps))
        if self.left_m <= 0.0:
            return command
        self.left_m -= scale * REFERENCE_SPEED_MPS * self.dt
        return Command(command[0], float(np.clip(command[1] + self.push * scale, -c.max_command_rps, c.max_command_rps)))
