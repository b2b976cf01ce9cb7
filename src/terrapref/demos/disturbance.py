"""Disturbances while demonstrating: now and then the vehicle's yaw rate is pushed off what the
driver commands for a moment, the way a rut or a slip would, and the driver steers back.

A learner that has only seen a driver on its own line has never seen how to get back to it,
and a planner is never exactly on that line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from terrapref.records import to_plain
from terrapref.vehicle import Command


@dataclass(frozen=True)
class DisturbanceConfig:
    """Random yaw-rate pushes added to the executed command while demonstrating.

    Attributes:
        rate_hz: expected pushes per second (a Poisson process; 0 is off).
        min_yaw_rate_rps, max_yaw_rate_rps: magnitude range of a push [rad/s]; its sign is
            a coin toss.
        min_duration_s, max_duration_s: how long a push lasts [s].
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
        self.left_s, self.push = 0.0, 0.0

    def __call__(self, command: Command) -> Command:
        """The command the vehicle executes instead of ``command`` (often ``command`` itself)."""
        c = self.config
        if self.left_s <= 0.0 and self.rng.random() < -math.expm1(-c.rate_hz * self.dt):
            self.left_s = self.rng.uniform(c.min_duration_s, c.max_duration_s)
            self.push = float(self.rng.choice((-1.0, 1.0)) * self.rng.uniform(c.min_yaw_rate_rps, c.max_yaw_rate_rps))
        if self.left_s <= 0.0:
            return command
        self.left_s -= self.dt
        return Command(command[0], float(np.clip(command[1] + self.push, -c.max_command_rps, c.max_command_rps)))
