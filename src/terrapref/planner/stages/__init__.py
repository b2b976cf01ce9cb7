"""Decision stages: what turns a frame's F_t into the command the planner drives.

A policy (:mod:`terrapref.planner.policy`) scores the m trajectories; a stage decides what to
drive. Every stage is one registered component (:data:`STAGES`) that owns, in its own module:

- its configuration: a typed record a recipe names (``SecondStageConfig``, ``OffsetConfig``),
  with the features its data must carry (:meth:`StageConfig.features`) and its fit
  (:meth:`StageConfig.fit`, on the samples C was trained on);
- the fitted stage (:class:`Stage`): written to the model file's ``stages`` list as one block
  under its ``type`` (:meth:`Stage.header`) and read back with checks (:meth:`Stage.from_header`);
- its decision (:meth:`Stage.runner`, a :class:`StageRunner` bound to one planner's camera and
  features, holding whatever the stage keeps from frame to frame).

The stages:

- ``argmax`` (:mod:`.argmax`): the trajectory C ranks first (the paper's planner);
- ``second_stage`` (:mod:`.second`): C's best trajectories scored again with the second pieces
  beyond them, by a linear utility fitted with C;
- ``offset`` (:mod:`.offset`): a lateral offset from the path, priced by the corridor utility,
  held and steered to.

A model file lists the stages fitted with it, and the planner drives with the last one
(:func:`driving_stage`); a file that lists none drives C's argmax.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from terrapref.features import FeatureConfig
from terrapref.planner.stages.argmax import ArgmaxStage
from terrapref.planner.stages.base import Choice, Stage, StageConfig, StageContext, StageInput, StageRunner, Where
from terrapref.planner.stages.offset import OffsetConfig, OffsetStage
from terrapref.planner.stages.second import SecondStage, SecondStageConfig
from terrapref.registry import Registry

__all__ = ["STAGES", "ArgmaxStage", "Choice", "OffsetConfig", "OffsetStage", "SecondStage", "SecondStageConfig", "Stage", "StageConfig",
           "StageContext", "StageInput", "StageRunner", "driving_stage", "read_stages"]

STAGES: Registry[type[Stage]] = Registry("stage")


def register_stage(cls: type[Stage], doc: str) -> type[Stage]:
    """Register a stage class under its ``type``."""
    STAGES.register(cls.type, cls, doc)
    return cls


def read_stages(blocks: Sequence[Mapping[str, Any]], features: FeatureConfig, source: str) -> tuple[Stage, ...]:
    """The stages a model file lists (``LoadedModel.stages``), each checked by its own type."""
    stages = []
    for i, block in enumerate(blocks):
        where = Where(source, i)
        stages.append(STAGES.get(str(block["type"]), where.field("type"), source).from_header(block, features, where))
    return tuple(stages)


def driving_stage(stages: Sequence[Stage]) -> Stage:
    """The stage that drives: the last one listed; C's argmax when none is."""
    return stages[-1] if stages else ArgmaxStage()


register_stage(ArgmaxStage, "the trajectory C ranks first (the paper's planner)")
register_stage(SecondStage, "C's best trajectories scored again with the second pieces beyond them (a linear utility)")
register_stage(OffsetStage, "a lateral offset from the path priced by the corridor utility, held and steered to")
