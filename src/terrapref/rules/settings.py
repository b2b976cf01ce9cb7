"""Settings a robot gives its model's rules at run time, over what the model file holds.

A model file freezes what was fitted and how each rule was configured. Some of a rule's
settings are the robot's to choose, not the driver's: how fast it may go (overall, or on one
class), how readily the offset rule switches sides, how far it keeps from lethal terrain. As
Nav2 gives each plugin its own parameter namespace, each rule names the settings a robot may
give it (:attr:`terrapref.rules.base.Rule.settable`), by rule type and name: ``offset.switch_margin``,
``speed.max_speed_mps``, ``speed.class_max_mps.mud``. They come from the robot file's ``rules``
block, or a node's parameters, and are checked twice: their names and kinds as they are read
(:meth:`RuleSettings.parse`), their ranges and classes against the model's rules when a planner
is built (:meth:`RuleSettings.applied`). Either check failing is a :class:`UserError` naming
where the setting came from.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from terrapref.errors import ConfigError, UserError, described, finite_number
from terrapref.registry import Registry
from terrapref.rules.base import Rule

PER_CLASS = "class"  # a setting's kind: a number per class, given as NAME.CLASS
NUMBER = "number"  # a setting's kind: one finite number


@dataclass(frozen=True)
class RuleSettings:
    """Settings of a model's rules, by rule type and name (empty: the model file's own).

    Attributes:
        values: rule type -> setting -> value: a number, or for a per-class setting a mapping of
            class name -> number.
        origin: where they came from (a robot file, ``--ros-args``, ``~offset``), for errors.
    """

    values: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    origin: str = "rule settings"

    def __bool__(self) -> bool:
        return any(self.values.values())

    @classmethod
    def parse(cls, flat: Mapping[str, Any], origin: str, registry: Registry[type[Rule]]) -> RuleSettings:
        """Settings given as ``RULE.NAME`` (``RULE.NAME.CLASS`` for a per-class one) -> value, as
        a node's parameters give them; ``registry``: the rule classes by type. An unknown rule or
        name, or a value of the wrong kind, is a UserError naming ``origin`` and the key."""
        values: dict[str, dict[str, Any]] = {}
        for key, value in flat.items():
            rule, _, rest = str(key).partition(".")
            name, _, cls_name = rest.partition(".")
            kind = _kind_of(registry, rule, name, origin, key)
            if (kind == PER_CLASS) != bool(cls_name):
                expected = f"{rule}.{name}.CLASS" if kind == PER_CLASS else f"{rule}.{name}"
                raise UserError(origin, f"expected {expected}", field=str(key))
            number = _number(value, origin, str(key))
            problem = registry[rule].setting_problem(name, number)
            if problem is not None:
                raise UserError(origin, f"{problem}, got {number:g}", field=str(key))
            named = values.setdefault(rule, {})
            if kind == PER_CLASS:
                named.setdefault(name, {})[cls_name] = number
            else:
                named[name] = number
        return cls(values, origin)

    @classmethod
    def from_block(cls, block: object, origin: str, registry: Registry[type[Rule]]) -> RuleSettings:
        """Settings from a robot file's ``rules`` block: ``{RULE: {NAME: number, or {CLASS: number}}}``;
        a problem is a ConfigError naming the file and the block's field."""
        if block is None:
            return cls({}, origin)
        if not isinstance(block, Mapping):
            raise ConfigError(origin, "expected a mapping of rule types to their settings", field="rules")
        flat: dict[str, Any] = {}
        for rule, named in block.items():
            if str(rule) not in registry or not registry[str(rule)].settable:
                known = ", ".join(t for t in registry if registry[t].settable)
                raise ConfigError(origin, f"no rule {rule!r} takes settings; the rules that do: {known}", field=f"rules.{rule}")
            if not isinstance(named, Mapping):
                raise ConfigError(origin, "expected a mapping of settings to values", field=f"rules.{rule}")
            for name, value in named.items():
                try:
                    kind = _kind_of(registry, str(rule), str(name), origin, f"rules.{rule}.{name}")
                except UserError as exc:
                    raise ConfigError(origin, exc.problems) from None
                if kind == PER_CLASS:
                    if not isinstance(value, Mapping) or not value:
                        raise ConfigError(origin, "expected a mapping of class names to numbers", field=f"rules.{rule}.{name}")
                    flat |= {f"{rule}.{name}.{c}": v for c, v in value.items()}
                else:
                    flat[f"{rule}.{name}"] = value
        try:
            return cls.parse(flat, origin, registry)
        except UserError as exc:  # the same key, as the file nests it
            (problem,) = exc.problems
            raise ConfigError(origin, problem.message, field=f"rules.{problem.field}") from None

    def over(self, base: RuleSettings) -> RuleSettings:
        """These settings given over ``base``'s (a node's parameters over its robot file's)."""
        merged = {rule: dict(named) for rule, named in base.values.items()}
        for rule, named in self.values.items():
            for name, value in named.items():
                old = merged.setdefault(rule, {}).get(name)
                merged[rule][name] = {**old, **value} if isinstance(value, Mapping) and isinstance(old, Mapping) else value
        return RuleSettings(merged, self.origin if not base else f"{base.origin} and {self.origin}")

    def applied(self, rules: Sequence[Rule], names: tuple[str, ...], lethal: frozenset[str]) -> tuple[Rule, ...]:
        """``rules`` with these settings in place of their own (``names``: the terrain columns'
        classes; ``lethal``: the lethal ones). A value out of the rule's range, or a class it keeps no
        speed for, is a UserError naming the origin and the setting; settings of a rule type the
        model does not list are left unused (:meth:`unused` says which)."""
        out = []
        for rule in rules:
            given = self.values.get(rule.type)
            if not given:
                out.append(rule)
                continue
            try:
                out.append(rule.with_settings(given, names, lethal))
            except ValueError as exc:
                raise UserError(self.origin, str(exc), field=f"{rule.type}.{', '.join(given)}") from None
        return tuple(out)

    def unused(self, rules: Sequence[Rule]) -> list[str]:
        """The rule types given settings that ``rules`` do not list."""
        listed = {r.type for r in rules}
        return [rule for rule, named in self.values.items() if named and rule not in listed]

    def lines(self) -> list[str]:
        """Each setting as ``RULE.NAME VALUE`` (a per-class one as ``RULE.NAME.CLASS VALUE``), for a log."""
        out = []
        for rule, named in self.values.items():
            for name, value in named.items():
                items = value.items() if isinstance(value, Mapping) else [(None, value)]
                out += [f"{rule}.{name}{'' if c is None else '.' + c} {v:g}" for c, v in items]
        return out


def _kind_of(registry: Registry[type[Rule]], rule: str, name: str, origin: str, key: str) -> str:
    """The kind of setting ``name`` of rule type ``rule`` (``NUMBER`` or ``PER_CLASS``); unknown: a UserError."""
    cls = registry[rule] if rule in registry else None
    if cls is None or not cls.settable:
        known = ", ".join(t for t in registry if registry[t].settable)
        raise UserError(origin, f"no rule {rule!r} takes settings; the rules that do: {known}", field=key)
    if name not in cls.settable:
        known = ", ".join(cls.settable) or "none"
        raise UserError(origin, f"the {rule} rule has no setting {name!r}; its settings: {known}", field=key)
    return cls.settable[name][0]


def _number(value: object, origin: str, key: str) -> float:
    ok = finite_number(value)
    if not ok:
        raise UserError(origin, f"expected a finite number, got {described(value)}", field=key)
    return float(value)
