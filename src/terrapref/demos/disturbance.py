"""Disturbances while demonstrating: now and then the vehicle's yaw rate is pushed off what the
driver commands for a moment, the way a rut or a slip would, and the driver steers back.

A learner that has only seen a driver on its own line has never seen how to get back to it,
and a planner is never exactly on that line. A push shows a recovery, not a crash: with a
clearance set, a push begins only where no lethal terrain lies within reach of it (farther at
speed, as a push of the same yaw rate carries a faster vehicle farther before the driver has
steered back).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from terrapref.records import to_plain
from terrapref.vehicle import Command

# A push is what the ground does to a rolling vehicle (a rut, a slip): where the command's speed
# [m/s] is slower than this, it turns the vehicle in proportion to that speed, and with none not
# at all (the command's speed rather than the vehicle's, so that a push at a drive's start is
# whole). Pure pursuit's own correction is the speed times a curvature, so a whole push at a
# crawl up a grade (0.1 m/s) would turn the vehicle round within centimetres, faster than the
# driver's steering turns it back. No speed style cruises slower (water's 0.3 m/s is the
# slowest), nor does the cautious relief style up the teaching course's grades (0.24 m/s).
FULL_PUSH_MPS = 0.2


@dataclass(frozen=True)
class DisturbanceConfig:
    """Random yaw-rate pushes added to the executed command while demonstrating.

    Attributes:
        rate_hz: expected pushes per second (a Poisson process; 0 is off).
        min_yaw_rate_rps, max_yaw_rate_rps: magnitude range of a push [rad/s]; its sign is
            a coin toss.
        min_duration_s, max_duration_s: how long a push lasts [s].
        max_command_rps: the vehicle's yaw-rate limit; the pushed command is clipped to it.
        clear_m, clear_s: a push begins only where no lethal terrain, nor ground that would tilt
            the vehicle past its roll or pitch limit, lies within ``clear_m + clear_s * speed`` of
            the vehicle's centre [m, s]; both 0: anywhere. A push that
            would begin nearer is left out (its time passes without a push, so that the pushes
            after it are drawn as they would have been).
    """

    rate_hz: float = 0.15
    min_yaw_rate_rps: float = 0.3
    max_yaw_rate_rps: float = 0.6
    min_duration_s: float = 0.3
    max_duration_s: float = 1.5
    max_command_rps: float = 1.0
    clear_m: float = 0.0
    clear_s: float = 0.0

    @property
    def active(self) -> bool:
        return self.rate_hz > 0

    def __post_init__(self) -> None:
        if not (
            self.rate_hz >= 0
            and 0 <= self.min_yaw_rate_rps <= self.max_yaw_rate_rps
            and 0 < self.min_duration_s <= self.max_duration_s
            and self.max_command_rps > 0
            and 0 <= self.clear_m < math.inf
            and 0 <= self.clear_s < math.inf
        ):
            raise ValueError("disturbance: rate >= 0, 0 <= min <= max yaw rate, 0 < min <= max duration, clearances >= 0")

    def clearance_m(self, speed_mps: float) -> float:
        """How far from lethal terrain a push may begin at ``speed_mps`` [m] (0: anywhere)."""
        return self.clear_m + self.clear_s * max(speed_mps, 0.0)

    def to_dict(self) -> dict:
        return to_plain(self)


class Disturber:
    """Draws the pushes of one run from its own seeded stream."""

    def __init__(self, config: DisturbanceConfig, rng: np.random.Generator, dt: float) -> None:
        self.config, self.rng, self.dt = config, rng, dt
        self.left_s, self.push = 0.0, 0.0
        self.left_out = False  # the push now running was left out: lethal terrain lay within reach as it began

    def __call__(self, command: Command, speed_mps: float = 0.0, lethal_within: Callable[[float], bool] | None = None) -> Command:
        """The command the vehicle executes instead of ``command`` (often ``command`` itself), at
        the vehicle's ``speed_mps``; ``lethal_within(r)`` says whether lethal terrain lies within
        ``r`` [m] of the vehicle (None: the clearance is not checked)."""
        c = self.config
        if self.left_s <= 0.0 and self.rng.random() < -math.expm1(-c.rate_hz * self.dt):
            self.left_s = self.rng.uniform(c.min_duration_s, c.max_duration_s)
            self.push = float(self.rng.choice((-1.0, 1.0)) * self.rng.uniform(c.min_yaw_rate_rps, c.max_yaw_rate_rps))
            reach = c.clearance_m(speed_mps)
            self.left_out = reach > 0.0 and lethal_within is not None and lethal_within(reach)
        if self.left_s <= 0.0:
            return command
        self.left_s -= self.dt
        if self.left_out:  # its time passes without a push, so that the pushes after it are drawn as before
            return command
        push = self.push * min(1.0, max(float(command[0]), 0.0) / FULL_PUSH_MPS)  # a rut or a slip turns the vehicle as it rolls
        return Command(command[0], float(np.clip(command[1] + push, -c.max_command_rps, c.max_command_rps)))
