"""Driving a scenario into a recording: the loop shared by synthetic drivers and teleop."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict
from typing import Any

import numpy as np

from terrapref.camera import CameraConfig
from terrapref.demos.recording import RecordingWriter
from terrapref.features import PreferenceSetConfig
from terrapref.scenario import Scenario
from terrapref.sim import Driver, EpisodeLog, SimConfig, Simulation
from terrapref.terrain import PreferenceProfile


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
) -> EpisodeLog:
    """Drive ``sim`` with ``driver`` to the goal or the time limit, writing every frame.

    The recording is marked complete only when the loop ends normally; an exception or a kill
    leaves it partial with every frame written so far readable.
    """
    frame = sim.reset()
    driver.reset(sim.scenario, rng)
    control = preference.control
    while not sim.done:
        command = driver.act(frame)
        writer.append(frame.time_s, frame.pose, frame.image, command, control.label_of(command[1]))
        frame = sim.step(command)
        if progress is not None:
            progress(sim)
    log = EpisodeLog.of(sim)
    writer.close(log.summary())
    return log
