"""Correction sessions (DAgger): the planner drives, the demonstrator shows what it would do.

After the first model is trained from plain demonstrations, the planner drives the training
course itself; at every frame the demonstrator's intended command is recorded as the label,
while the vehicle executes the planner's choice. The planner thus gets labels in exactly the
situations its own mistakes lead to, which plain demonstrations never visit (SPEC 15: after the
first miss, the planner is off the data's distribution). With a person, this is a ride-along:
the operator holds the stick as if driving while the robot drives.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from terrapref.demos.expert import ExpertDriver
from terrapref.demos.recording import RecordingWriter
from terrapref.features import PreferenceSetConfig
from terrapref.planner import PlannerDriver
from terrapref.sim import EpisodeLog, Simulation
from terrapref.vehicle import Command


@dataclass(frozen=True)
class CorrectionDrivers:
    """Who drives a correction session and who labels it.

    Attributes:
        planner: drives the vehicle.
        expert: the demonstrator, whose intended command labels every frame.
        takeover: probability per frame that the demonstrator's command is executed instead
            of the planner's (0: pure DAgger).
    """

    planner: PlannerDriver
    expert: ExpertDriver
    takeover: float = 0.0


def record_corrections(
    sim: Simulation,
    drivers: CorrectionDrivers,
    writer: RecordingWriter,
    preference: PreferenceSetConfig,
    rng: np.random.Generator,
) -> EpisodeLog:
    """Drive with ``drivers.planner``, label every frame with ``drivers.expert``'s intent in
    ``preference``'s control set."""
    planner, expert, takeover = drivers.planner, drivers.expert, drivers.takeover
    frame = sim.reset()
    planner.reset(sim.scenario, rng)
    expert.reset(sim.scenario, rng, world=sim.world)
    control = preference.control
    v = control.v_mps
    while not sim.done:
        w_label = expert.intent(frame)
        executed = planner.act(frame)
        if takeover > 0 and rng.random() < takeover:
            executed = Command(v, w_label)
        writer.append(frame.time_s, frame.pose, frame.view, (v, w_label), control.label_of(w_label), executed=executed)
        frame = sim.step(executed)
    log = EpisodeLog.of(sim)
    writer.close({**log.summary(), "session": "corrections"})
    return log
