"""What a real robot's planner gets instead of the truth: perception models (SPEC 16).

A :class:`PerceptionModel` (``terrapref-perception/1``, or a preset by name) says how labels,
pose, camera attitude and frame timing differ from the simulator's truth; a :class:`Perceiver`
applies it to a run's frames, and :class:`PerceivedDriver` puts a planner behind one.
"""

from terrapref.perception.model import (
    FORMAT,
    PRESETS,
    CameraJitter,
    FrameTiming,
    LabelErrors,
    PerceptionModel,
    PoseErrors,
    load_perception,
    preset,
)
from terrapref.perception.perceiver import COMMAND_HOLD_S, PerceivedDriver, Perceiver, run_stream

__all__ = [
    "COMMAND_HOLD_S",
    "FORMAT",
    "PRESETS",
    "CameraJitter",
    "FrameTiming",
    "LabelErrors",
    "PerceivedDriver",
    "PerceptionModel",
    "Perceiver",
    "PoseErrors",
    "load_perception",
    "preset",
    "run_stream",
]
