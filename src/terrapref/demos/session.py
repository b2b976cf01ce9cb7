"""Driving a scenario into a recording: the loop shared by synthetic drivers and teleop.

Disturbances (optional, terrapref.demos.disturbance) show the demonstrator's recoveries; the
label stays the driver's own command, and the command the vehicle actually executed is
recorded beside it.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from terrapref.camera import CameraConfig
from terrapref.demos.disturbance import DisturbanceConfig, Disturber  # DisturbanceConfig: imported from here by callers too
from terrapref.demos.meta import DriverInfo, RecordingMeta, RecordingSetup
from terrapref.demos.recording import MemoryRecordingWriter, RecordingWriter
from terrapref.features import PreferenceSetConfig
from terrapref.perception import Perceiver, PerceptionModel, run_stream
from terrapref.scenario import Scenario
from terrapref.sim import Driver, EpisodeLog, Frame, SimConfig, Simulation
from terrapref.terrain import PreferenceProfile
from terrapref.vehicle import Command, ControlSet, VehicleConfig


@dataclass(frozen=True)
class DriveSetup:
    """A drive that records, whoever drives it (``record``'s synthetic driver, a person in
    ``drive``'s window, a recipe's demonstrations): the course, the camera, the simulation of the
    vehicle and the preference set whose indices label the frames. The one place a drive is set up.

    Attributes:
        scenario: the course.
        camera: the camera the frames are taken with.
        sim: the simulation (its vehicle, the camera rate, when a run ends).
        preference: the control and preference set its commands are labelled with.
    """

    scenario: Scenario
    camera: CameraConfig = field(default_factory=CameraConfig)
    sim: SimConfig = field(default_factory=SimConfig)
    preference: PreferenceSetConfig = field(default_factory=PreferenceSetConfig)

    @classmethod
    def of(
        cls,
        scenario: Scenario,
        vehicle: VehicleConfig | None = None,
        camera: CameraConfig | None = None,
        preference: PreferenceSetConfig | None = None,
        person: bool = False,
    ) -> DriveSetup:
        """The drive of ``scenario`` with ``vehicle`` (None: the default field UGV), the camera and
        preference set given (None: the defaults); a ``person``'s drive never ends for standing
        still (they may stop as long as they like)."""
        sim = SimConfig.driving(vehicle)
        if person:
            sim = replace(sim, stopped_limit_s=None)
        return cls(scenario, camera or CameraConfig(), sim, preference or PreferenceSetConfig())

    def simulation(self) -> Simulation:
        """The simulation the drive runs in, reset to the course's start."""
        return Simulation(self.scenario, self.camera, self.sim)

    def meta(self, driver: DriverInfo, profile: PreferenceProfile | None, perception: PerceptionModel | None = None) -> RecordingMeta:
        """The recording's metadata: who drove (``driver``), the order they declared (None: none), what the robot received."""
        return RecordingMeta.driven(self.scenario, RecordingSetup(self.camera, self.preference, self.sim), driver, profile, perception)


@dataclass(frozen=True)
class RunSettings:
    """How a run is recorded, besides who drives it and where it is written.

    Attributes:
        preference: the control and preference set whose indices label the frames.
        disturbance: pushes added to what the vehicle executes (None: none).
        perception: what the robot receives instead of the truth (None: the truth).
    """

    preference: PreferenceSetConfig
    disturbance: DisturbanceConfig | None = None
    perception: PerceptionModel | None = None


class RecordLoop:
    """The per-frame recording every driver shares: push, write, step; and the closing summary.

    A driver (the synthetic one in :func:`record_run`, a person in the teleop window) decides a
    command on each camera frame; :meth:`executed` adds the run's pushes to it,
    :meth:`record_step` writes the frame with the command and its label and steps the
    simulation by one camera period, and :meth:`close` marks the recording complete.

    With a perceiver (terrapref.perception), the driver still sees the truth and the recording
    holds what the robot would have logged: each period, the frame that reached the robot then
    (:meth:`perceive`: its labels, its pose as the robot's localisation gave it, taken that period
    or earlier), with the driver's command of that period; a period in which no frame arrived
    writes nothing.

    Args:
        sim: the simulation driven, already reset.
        writer: the recording (on disk, or kept in memory), or None to drive without one.
        control: the control set whose indices label the frames.
        disturb: the run's pushes, or None for none.
        perceiver: what the robot receives instead of the truth, already reset; None: the truth.
    """

    def __init__(
        self,
        sim: Simulation,
        writer: RecordingWriter | MemoryRecordingWriter | None,
        control: ControlSet,
        disturb: Disturber | None = None,
        perceiver: Perceiver | None = None,
    ) -> None:
        self.sim, self.writer, self.control, self.disturb, self.perceiver = sim, writer, control, disturb, perceiver
        self._perceived: tuple[int, Frame | None] | None = None  # (the period, what reached the robot in it)

    def executed(self, command: Command) -> Command:
        """What the vehicle executes this frame instead of ``command`` (often ``command`` itself)."""
        if self.disturb is None:
            return command
        x, y, _ = self.sim.vehicle.pose
        return self.disturb(command, self.sim.vehicle.speed_mps, lambda r: self._hazard_within(x, y, r))

    def _hazard_within(self, x: float, y: float, radius_m: float) -> bool:
        """Whether lethal terrain, or ground that would tilt the vehicle past its roll or pitch
        limit, lies within ``radius_m`` of (``x``, ``y``) [m]: a push begins only clear of both."""
        world, vehicle = self.sim.world, self.sim.vehicle.config
        if world.lethal_within(x, y, radius_m):
            return True
        return world.steep_within(x, y, radius_m, min(vehicle.max_roll_deg, vehicle.max_pitch_deg), vehicle.half_width_m)

    def perceive(self, frame: Frame) -> Frame | None:
        """What reaches the robot in ``frame``'s period (``frame`` itself without a perceiver; None
        when no frame arrives); asked again in the same period, the same answer."""
        if self._perceived is None or self._perceived[0] != frame.index:
            self._perceived = (frame.index, self.perceiver(frame) if self.perceiver is not None else frame)
        return self._perceived[1]

    def record_step(self, frame: Frame, command: Command, executed: Command, record: bool = True) -> Frame:
        """Write what reached the robot in ``frame``'s period with the driver's ``command`` and its
        label, then drive ``executed`` for one camera period; returns the next frame.

        ``record`` False (or no recording) only steps: frames a recording must not hold.
        """
        got = self.perceive(frame)
        if record and self.writer is not None and got is not None:
            self.writer.append(
                frame.time_s,
                got.pose,
                got.view,
                command,
                self.control.label_of(command[1]),
                executed=executed if executed != command else None,
            )
        return self.sim.step(executed)

    def close(self, summary: dict[str, Any]) -> None:
        """Mark the recording complete with the run's ``summary`` (nothing without a recording)."""
        if self.writer is not None:
            self.writer.close(summary)


def abort_recording(writer: RecordingWriter) -> None:
    """Leave ``writer``'s recording partial after a run that ended in an exception, and say where
    an unfinished replacement of an older recording was kept."""
    writer.abort()
    if writer.partial_dir is not None:
        print(f"note: {writer.target} keeps the recording it held; the unfinished new one is in {writer.partial_dir}", file=sys.stderr)
    elif writer.count and writer.dir.exists():  # a first recording: what was recorded stays, marked partial
        print(f"note: {writer.target} keeps the {writer.count} frames recorded before it was stopped (partial)", file=sys.stderr)


def record_run(
    sim: Simulation,
    driver: Driver,
    writer: RecordingWriter | MemoryRecordingWriter,
    settings: RunSettings,
    rng: np.random.Generator,
    progress: Callable[[Simulation], None] | None = None,
) -> EpisodeLog:
    """Drive ``sim`` with ``driver`` to the goal or the time limit, writing every frame labelled
    in ``settings.preference``'s control set.

    The recording is marked complete only when the loop ends normally; an exception or a kill
    leaves it partial with every frame written so far readable. With ``settings.disturbance``,
    pushes drawn from a stream seeded by ``rng`` are added to what the vehicle executes (the
    label stays the driver's command). With ``settings.perception``, the recording holds what
    the robot would have logged (:class:`RecordLoop`), drawn from a stream spawned from ``rng``.
    """
    frame = sim.reset()
    driver.reset(sim.scenario, rng)
    disturber = _run_disturber(settings.disturbance, rng, sim)
    loop = RecordLoop(sim, writer, settings.preference.control, disturber, run_perceiver(settings.perception, sim, rng))
    while not sim.done:
        command = driver.act(frame)
        frame = loop.record_step(frame, command, loop.executed(command))
        if progress is not None:
            progress(sim)
    log = EpisodeLog.of(sim)
    loop.close(log.summary())
    return log


def run_perceiver(perception: PerceptionModel | None, sim: Simulation, rng: np.random.Generator) -> Perceiver | None:
    """A run's perceiver, on a stream spawned from ``rng`` (which leaves ``rng``'s own draws as they
    were: the driver drives the same run with or without perception); None for the truth."""
    if perception is None or not perception.active:
        return None
    perceiver = Perceiver(perception, sim.renderer, sim.scenario.classes, sim.config.camera_rate_hz)
    perceiver.reset(run_stream(rng.spawn(1)[0], sim.scenario.name))
    return perceiver


def _run_disturber(disturbance: DisturbanceConfig | None, rng: np.random.Generator, sim: Simulation) -> Disturber | None:
    """The run's pushes on their own stream, seeded from ``rng`` (drawn from only when pushes are on,
    so that a run without them leaves the driver's stream untouched)."""
    if disturbance is None or not disturbance.active:
        return None
    return Disturber(disturbance, np.random.default_rng(rng.integers(2**63)), 1.0 / sim.config.camera_rate_hz)
