"""Decision rules: what turns a frame into the command the planner drives.

A policy (:mod:`terrapref.planner.policy`) scores the m trajectories; a rule decides what to
drive. Every rule is one registered package (:data:`RULES`) that owns its configuration, what
its fit reads of each frame (the dataset keeps it under the rule's name), its fit, its block in
the model file (older files' too), its decision and what it offers (a costmap, a route's prices);
the interface is :mod:`.base`.

The rules:

- ``argmax`` (:mod:`.argmax`): the trajectory C ranks first (the paper's planner);
- ``second_stage`` (:mod:`.second`): C's best trajectories scored again with the second pieces
  beyond them, by a linear utility fitted with C;
- ``offset`` (:mod:`.offset`): a lateral offset from the path, priced by a utility learned from
  the offsets the driver held, kept and steered to (the default planner's);
- ``speed`` (:mod:`.speed`): not a way but the speed along the way the steering rule chose, a
  cruising speed per class, in bends and near lethal terrain, learned from the drive.

A model file lists the rules fitted with it (``rules``) and names the one that drives
(``drives``); the others were fitted to be reported, and a planner may be asked to drive by one
of them instead. A file that lists none drives C's argmax. A speed rule listed sets the speed
whichever rule steers; without one the planner drives at the control set's speed.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from terrapref.errors import UserError
from terrapref.features import FeatureConfig
from terrapref.learning.header import rule_blocks
from terrapref.registry import Registry
from terrapref.rules.argmax import ArgmaxRule
from terrapref.rules.base import (
    RULE_KINDS,
    SPEED,
    STEERING,
    STOP,
    Choice,
    HeaderContext,
    Rule,
    RuleConfig,
    RuleContext,
    RuleInput,
    SpeedRunner,
    SteeringRunner,
    StopRunner,
    Verdict,
    Where,
)
from terrapref.rules.offset.rule import OffsetConfig, OffsetRule
from terrapref.rules.second.rule import SecondStageConfig, SecondStageRule
from terrapref.rules.speed.rule import SpeedConfig, SpeedRule

if TYPE_CHECKING:
    from terrapref.learning.model_file import LoadedModel

__all__ = [
    "RULES",
    "RULE_KINDS",
    "SPEED",
    "STEERING",
    "STOP",
    "SpeedRunner",
    "StopRunner",
    "Verdict",
    "ArgmaxRule",
    "Choice",
    "HeaderContext",
    "OffsetConfig",
    "OffsetRule",
    "Rule",
    "RuleConfig",
    "RuleContext",
    "RuleInput",
    "SteeringRunner",
    "SecondStageConfig",
    "SecondStageRule",
    "SpeedConfig",
    "SpeedRule",
    "chosen_rule",
    "driving_rule",
    "legacy_blocks",
    "read_rules",
    "rules_in",
    "rule_roles",
    "rules_of",
    "speed_rule",
]

RULES: Registry[type[Rule]] = Registry("rule")


def register_rule(cls: type[Rule], doc: str) -> type[Rule]:
    """Register a rule class under its ``type``."""
    RULES.register(cls.type, cls, doc)
    return cls


def legacy_blocks(meta: Mapping[str, Any], source: str) -> tuple[dict[str, Any], ...]:
    """The rules of a file written before the ``stages`` list, each from its own key of the header
    (:meth:`Rule.legacy_block`), in the order they were listed then (the second stage first)."""
    return tuple(block for cls in RULES.values() if (block := cls.legacy_block(meta, source)) is not None)


def read_rules(
    blocks: Sequence[Mapping[str, Any]], features: FeatureConfig, raw_features: Mapping[str, Any], source: str, key: str = "rules"
) -> tuple[Rule, ...]:
    """The rules a model file lists, each checked by its own type (``raw_features``: the file's
    ``features`` section, where older files kept a rule's geometry; ``key``: the list's name in
    the file, for errors)."""
    context = HeaderContext(features, raw_features)
    rules = []
    for i, block in enumerate(blocks):
        where = Where(source, i, key)
        rule = RULES.get(str(block["type"]), where.field("type"), source).from_header(block, context, where)
        first = next((j for j, r in enumerate(rules) if r.type == rule.type), None)
        if first is not None:  # which of two would drive would depend on who reads the file
            raise where.error("type", f"a second {rule.type!r} rule ({key}[{first}] is one); a file holds one rule of each type")
        rules.append(rule)
    return tuple(rules)


def _listed(rules: Sequence | None, stages: Sequence | None, meta: Mapping[str, Any], source: str) -> tuple[Sequence, str]:
    """The rules' blocks a file lists, and the name of their list for errors: its ``rules``, an
    older file's ``stages``, or else the oldest files' own keys of ``meta`` (:func:`legacy_blocks`)."""
    if rules is not None:
        return rules, "rules"
    if stages is not None:
        return stages, "stages"
    return legacy_blocks(meta, source), "rules"


def rules_of(model: LoadedModel) -> tuple[tuple[Rule, ...], str | None]:
    """The rules a model file of C lists, read, and the type of the one it names to drive (None: not named)."""
    blocks, key = _listed(model.header.rules, model.header.stages, model.meta, model.path)
    raw = model.meta.get("features")
    read = read_rules(blocks, model.features, raw if isinstance(raw, Mapping) else {}, model.path, key)
    _check_sets_speed(read, model.header.sets_speed, model.path)
    _check_class_table(read, model, key)
    return read, model.header.drives


def _check_class_table(rules: Sequence[Rule], model: LoadedModel, key: str) -> None:
    """What a speed rule says of the file's classes must be what its class table says: the columns
    it keeps off are lethal there (a file older than lethal columns lists none), and the class it
    names as the background (a file older than that field names none) is the table's background."""
    lethal = set(model.classes.lethal_columns(model.features.feature_classes))
    background = model.classes.background
    for i, rule in enumerate(rules):
        if not isinstance(rule, SpeedRule):
            continue
        if not set(rule.model.lethal) <= lethal:
            named = ", ".join(str(c) for c in sorted(set(rule.model.lethal) - lethal))
            raise UserError(model.path, f"column {named} is not lethal in the file's class table", field=f"{key}[{i}].lethal")
        if rule.background is not None and rule.background != background:
            said = "unknown class" if rule.background not in model.classes.names else "not the background class"
            message = f"{said} {rule.background!r}; the file's class table's background is {background!r}"
            raise UserError(model.path, message, field=f"{key}[{i}].background")


def rules_in(meta: Mapping[str, Any], source: str) -> tuple[tuple[Rule, ...], Rule]:
    """The rules a file's metadata lists (a model file's header, or an exported graph's
    metadata), read against its features, and the one that drives; a problem is a
    :class:`UserError` naming ``source`` and the field."""
    raw = meta.get("features")
    try:
        features = FeatureConfig.from_dict(dict(raw))
    except (KeyError, TypeError, ValueError) as exc:
        raise UserError(source, f"invalid configuration ({exc})", field="features") from None
    blocks, key = _listed(rule_blocks(meta, "rules", source), rule_blocks(meta, "stages", source), meta, source)
    read = read_rules(blocks, features, raw, source, key)
    drives, sets_speed = meta.get("drives"), meta.get("sets_speed")
    for name, value in (("drives", drives), ("sets_speed", sets_speed)):
        if value is not None and not isinstance(value, str):
            raise UserError(source, "expected a rule's type", field=name)
    _check_sets_speed(read, sets_speed, source)
    return read, driving_rule(read, drives, source)


def _check_sets_speed(rules: Sequence[Rule], sets_speed: str | None, source: str) -> None:
    """A file's ``sets_speed`` (None: older files, or no speed rule) must name the speed rule it lists."""
    speed = speed_rule(rules)
    if sets_speed is not None and (speed is None or speed.type != sets_speed):
        listed = speed.type if speed is not None else "none"
        raise UserError(source, f"names rule {sets_speed!r} to set the speed, but the speed rule it lists is {listed}", field="sets_speed")


def rule_roles(types: Sequence[str]) -> str:
    """What rules of ``types`` (a recipe's, in order) do, in words: which steers (the last
    steering rule; C's argmax where none is), which sets the speed, and which are fitted to be
    reported."""
    steering = [t for t in types if RULES[t].kind == STEERING]
    speed = [t for t in types if RULES[t].kind == SPEED]
    steers = steering[-1] if steering else "C's argmax"
    sets = speed[0] if speed else "none (the control set's speed)"
    reported = f"; fitted to be reported: {', '.join(steering[:-1])}" if len(steering) > 1 else ""
    return f"steers: {steers}; sets the speed: {sets}{reported}"


def speed_rule(rules: Sequence[Rule]) -> Rule | None:
    """The rule that sets the speed (one that does not steer), or None: the control set's speed."""
    return next((r for r in rules if r.kind == SPEED), None)


def driving_rule(rules: Sequence[Rule], drives: str | None, source: str = "model") -> Rule:
    """The rule that drives: the one ``drives`` names (a file's ``drives``), else the last one
    listed that steers (older files); C's argmax when none is listed."""
    rules = [r for r in rules if r.kind == STEERING]
    if drives is None:
        return rules[-1] if rules else ArgmaxRule()
    if drives == ArgmaxRule.type:
        return next((r for r in rules if r.type == drives), ArgmaxRule())
    found = next((r for r in rules if r.type == drives), None)
    if found is None:
        raise UserError(source, f"names rule {drives!r} to drive, but lists {', '.join(r.type for r in rules) or 'none'}", field="drives")
    return found


def chosen_rule(rules: Sequence[Rule], drives: str | None, wanted: str | None, source: str) -> Rule:
    """The rule that drives a planner: the one the file names (``wanted`` None), or the one of the
    file's of type ``wanted`` (``argmax``, C's, every model has).

    Raises:
        ValueError: the file lists no rule of type ``wanted``.
    """
    if wanted is None:
        return driving_rule(rules, drives, source)
    if wanted == ArgmaxRule.type:
        return ArgmaxRule()
    found = [r for r in rules if r.type == wanted and r.kind == STEERING]
    if not found:
        have = ", ".join([ArgmaxRule.type, *(r.type for r in rules)])
        raise ValueError(f"{source}: no {wanted!r} rule (rules: {', '.join(RULES.names())}); it has {have}")
    return found[-1]


register_rule(ArgmaxRule, "the trajectory C ranks first (the paper's planner)")
register_rule(SecondStageRule, "C's best trajectories scored again with the second pieces beyond them (a linear utility)")
register_rule(OffsetRule, "a lateral offset from the path priced by a learned utility, held and steered to")
register_rule(SpeedRule, "the speed along the way another rule steers: a cruising speed per class, in bends and near lethal terrain")
