"""Driving a scenario into a recording: the loop shared by synthetic drivers and teleop.

Disturbances (optional) show the demonstrator's recoveries: now and then the vehicle's yaw
rate is pushed off what the driver commands for a moment, the way a rut or a slip would, and
the driver steers back. The label stays the driver's own command; the command the vehicle
actually executed is recorded beside it. A learner that has only seen a driver on its own
line has never seen how to get back to it, and a planner is never exactly on that line.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from terrapref.camera import CameraConfig
from terrapref.demos.recording import RecordingWriter
from terrapref.features import PreferenceSetConfig
from terrapref.scenario import Scenario
from terrapref.sim import Driver, EpisodeLog, SimConfig, Simulation
from terrapref.terrain import PreferenceProfile
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
        if not (self.rate_hz >= 0 and 0 <= self.min_yaw_rate_rps <= self.max_yaw_rate_rps
                and 0 < self.min_duration_s <= self.max_duration_s and self.max_command_rps > 0):
            raise ValueError("disturbance: rate >= 0, 0 <= min <= max yaw rate, 0 < min <= max duration")

    def to_dict(self) -> dict:
        return asdict(self)


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


def recording_meta(
    scenario: Scenario,
    camera: CameraConfig,
    preference: PreferenceSetConfig,
    sim: SimConfig,
    driver: dict[str, Any],
    profile: PreferenceProfile,
) -> dict[str, Any]:
    """Everything a recording must carry to be featurised again later (SPEC 10)."""
    return {
        "scenario": scenario.name,
        "camera": camera.to_dict(),
        "preference_set": preference.to_dict(),
        "sim": {"camera_rate_hz": sim.camera_rate_hz, "goal_radius_m": sim.goal_radius_m, "vehicle": asdict(sim.vehicle)},
        "classes": scenario.classes.to_dict(),
        "profile": list(profile.order),
        "driver": driver,
        "path": scenario.waypoints.tolist(),
    }


def record_run(
    sim: Simulation,
    driver: Driver,
    writer: RecordingWriter,
    preference: PreferenceSetConfig,
    rng: np.random.Generator,
    progress: Callable[[Simulation], None] | None = None,
    disturbance: DisturbanceConfig | None = None,
) -> EpisodeLog:
    """Drive ``sim`` with ``driver`` to the goal or the time limit, writing every frame.

    The recording is marked complete only when the loop ends normally; an exception or a kill
    leaves it partial with every frame written so far readable. With ``disturbance``, pushes
    drawn from a stream seeded by ``rng`` are added to what the vehicle executes (the label
    stays the driver's command).
    """
    frame = sim.reset()
    driver.reset(sim.scenario, rng)
    control = preference.control
    disturb = None
    if disturbance is not None and disturbance.active:
        disturb = Disturber(disturbance, np.random.default_rng(rng.integers(2**63)), 1.0 / sim.config.camera_rate_hz)
    while not sim.done:
        command = driver.act(frame)
        executed = disturb(command) if disturb is not None else command
        writer.append(frame.time_s, frame.pose, frame.image, command, control.label_of(command[1]),
                      executed=executed if executed != command else None)
        frame = sim.step(executed)
        if progress is not None:
            progress(sim)
    log = EpisodeLog.of(sim)
    writer.close(log.summary())
    return log
