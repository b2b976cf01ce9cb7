"""A driver's speed style from the command line or a file (SPEC 18), checked against the class
table and the vehicle before anything is driven.

A style file (``terrapref-driver-style/1``, YAML) names a preset to start from and the fields it
changes; a flag given beside it wins::

    format: terrapref-driver-style/1
    base: default            # a preset of `terrapref record --style` (default: default)
    speeds: {grass: 1.6, rock: 1.0, mud: 0.5, water: 0.3}
    lateral_accel_mps2: 0.8  # the lateral acceleration kept in bends
    preview_m: 3.0           # how early it slows before a slower class
    near_lethal_mps: 0.6     # its speed while lethal terrain lies near its way ...
    near_lethal_m: 1.0       # ... within this distance of its footprint
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from terrapref.demos.expert import STYLES, ExpertConfig
from terrapref.demos.relief_style import ReliefStyle
from terrapref.errors import UserError, described, finite_number
from terrapref.terrain import ClassTable
from terrapref.vehicle import MIN_CRUISE_MPS as MIN_SPEED_MPS
from terrapref.yamlio import read_yaml_mapping

STYLE_FORMAT = "terrapref-driver-style/1"
_NUMBERS = ("speed_mps", "lateral_accel_mps2", "preview_m", "near_lethal_mps", "near_lethal_m")  # a file's plain numbers


def parse_speeds(text: str, source: str = "--speeds") -> tuple[tuple[str, float], ...]:
    """``CLASS=MPS,...`` as (class, speed) pairs; a malformed entry or a repeated class is a UserError."""
    pairs: list[tuple[str, float]] = []
    for item in (part.strip() for part in text.split(",")):
        name, sep, value = item.partition("=")
        name = name.strip()
        try:
            speed = float(value)
        except ValueError:
            speed = math.nan
        if sep and name and not math.isfinite(speed) and value.strip().lower().lstrip("+-") in ("nan", "inf", "infinity"):
            raise UserError(source, f"class {name!r}: a cruising speed is a finite number of m/s, got {value.strip()}")
        if not sep or not name or not math.isfinite(speed):
            raise UserError(source, f"expected CLASS=SPEED entries in m/s separated by commas, e.g. grass=1.6,mud=0.5; got {item!r}")
        if name in dict(pairs):
            raise UserError(source, f"class {name!r} is given twice")
        if speed <= 0:
            raise UserError(source, f"class {name!r}: a cruising speed is > 0 m/s, got {value.strip()}")
        pairs.append((name, speed))
    return tuple(pairs)


def names_style_file(style: str) -> bool:
    """Whether ``style`` (a --style value that is no preset) names a style file: a YAML name, or
    a file that exists."""
    return bool(style.strip()) and (style.endswith((".yaml", ".yml")) or Path(style).exists())  # "" is no file ('.' exists)


def read_style_file(path: str | Path) -> tuple[str, dict[str, Any]]:
    """The preset a style file starts from and the :class:`ExpertConfig` fields it changes."""
    source = str(path)
    data = read_yaml_mapping(path, STYLE_FORMAT)
    unknown = sorted(set(data) - {"format", "base", "speeds", "ranked_speeds_mps", *_NUMBERS})
    if unknown:
        raise UserError(source, f"unknown field; a style file has base, speeds, ranked_speeds_mps, {', '.join(_NUMBERS)}", field=unknown[0])
    base = data.get("base", "default")
    if base not in STYLES.names():
        raise UserError(source, f"{base!r} is not a style ({', '.join(STYLES.names())})", field="base")
    changes: dict[str, Any] = {name: _file_number(source, name, data[name]) for name in _NUMBERS if name in data}
    if "speeds" in data:
        speeds = data["speeds"]
        if not isinstance(speeds, dict) or not all(isinstance(k, str) for k in speeds):
            raise UserError(source, "expected a mapping of class names to speeds in m/s", field="speeds")
        changes["speeds"] = tuple((k, _file_number(source, f"speeds.{k}", v)) for k, v in speeds.items())
    if "ranked_speeds_mps" in data:
        ranked = data["ranked_speeds_mps"]
        if not (isinstance(ranked, list) and len(ranked) == 2):
            raise UserError(
                source, "expected [fastest, slowest]: the most and the least preferred class's speeds", field="ranked_speeds_mps"
            )
        changes["ranked_speeds_mps"] = tuple(_file_number(source, f"ranked_speeds_mps[{i}]", v) for i, v in enumerate(ranked))
    return base, changes


_AT_LEAST_0 = ("near_lethal_m",)  # a file's numbers that may be 0; the others must be > 0
_NULLABLE = ("lateral_accel_mps2", "near_lethal_mps")  # a file's numbers that may be null


def _file_number(source: str, field: str, value: Any) -> float | None:
    """A style file's number at ``field``, checked: finite, > 0 (>= 0 where 0 means something),
    null where null means something; anything else is a UserError naming the file and the field."""
    if value is None and field in _NULLABLE:
        return None
    if not finite_number(value):
        raise UserError(source, f"expected a finite number{' or null' if field in _NULLABLE else ''}, got {described(value)}", field=field)
    if float(value) < 0 or (float(value) == 0 and field not in _AT_LEAST_0):
        raise UserError(source, f"must be {'>= 0' if field in _AT_LEAST_0 else '> 0'}, got {float(value):g}", field=field)
    return float(value)


def driver_style(
    style: str,
    profile: tuple[str, ...],
    classes: ClassTable,
    max_speed_mps: float,
    changes: dict[str, Any] | None = None,
) -> ExpertConfig:
    """The synthetic driver of ``style`` (a preset name or a style file) for ``profile``, with
    ``changes`` (flags' fields) on top, checked against ``classes`` and the vehicle's top speed.

    Raises:
        UserError: an unknown preset, a bad file, a class the table lacks, a speed for a lethal
            class, a speed out of [MIN_SPEED_MPS, max].
    """
    source, file_changes = ("--style", {}) if style in STYLES.names() else (style, None)
    if file_changes is None:
        if not names_style_file(style):
            raise UserError("--style", f"{style!r} is neither a style ({', '.join(STYLES.names())}) nor a style file")
        style, file_changes = read_style_file(source)
    flags = changes or {}
    try:
        config = ExpertConfig.styled(style, profile, changes=file_changes)
    except ValueError as exc:
        raise UserError(source, str(exc)) from None
    for field, value in flags.items():
        try:  # speeds: the classes the flag names; the others keep the style's
            config = config.with_speeds(value) if field == "speeds" else replace(config, **{field: value})
        except ValueError as exc:
            raise UserError(FLAGS.get(field, source), str(exc)) from None
    blame = FLAGS["speeds"] if "speeds" in flags else source
    try:
        table = config.speed_table(classes)
    except ValueError as exc:
        raise UserError(blame, str(exc)) from None
    named = dict(flags.get("speeds", ()))
    _check_drivable(config, classes, table, lambda name: FLAGS["speeds"] if name in named else source)
    fastest = max(config.speed_mps, float(max((v for v in table if v == v), default=0.0)))
    if fastest > max_speed_mps + 1e-9:
        over = [c.name for c in classes.classes if table[c.id] == fastest and dict(config.speeds).get(c.name) == fastest]
        where = "" if not over else over[0] if "speeds" in flags else f"speeds.{over[0]}"  # the class it is given for
        where = where or ("speed_mps" if source != "--style" and config.speed_mps == fastest else "")
        raise UserError(blame, f"a cruising speed of {fastest:g} m/s is above the vehicle's {max_speed_mps:g} m/s", field=where)
    if config.near_lethal_mps is not None and config.near_lethal_mps > max_speed_mps + 1e-9:  # a cap it never reaches
        raise UserError(
            source, f"{config.near_lethal_mps:g} m/s is above the vehicle's top speed, {max_speed_mps:g} m/s", field="near_lethal_mps"
        )
    check_rough_speed(config.relief, max_speed_mps)
    return config


def check_rough_speed(relief: ReliefStyle | None, max_speed_mps: float) -> None:
    """Refuse a relief style whose top speed on rough ground is above the vehicle's top speed: a
    cap the driver never reaches, most likely a slip of the hand (``rough_mps=1e9``)."""
    if relief is not None and relief.rough_mps > max_speed_mps + 1e-9:
        raise UserError(FLAGS["relief"], f"rough_mps: {relief.rough_mps:g} m/s is above the vehicle's top speed, {max_speed_mps:g} m/s")


def _check_drivable(config: ExpertConfig, classes: ClassTable, table: np.ndarray, blame: Callable[[str], str]) -> None:
    """Refuse a speed for a lethal class (the driver never drives on one: the speed would be
    stored and never used) and a cruising speed below :data:`MIN_SPEED_MPS`, the least the
    planner's speed rule commands: a driver that slow never gets anywhere in a run's time, and a
    model learned from it could not follow it. ``blame(name)`` is the flag or file that set a class's speed.
    """

    def refuse(name: str, field: str, message: str) -> UserError:
        source = blame(name)
        return UserError(source, message, field="" if source.startswith("--") else field)

    lethal = [name for name, _ in config.speeds if name in classes.names and classes.id_of(name) in classes.lethal_ids]
    if lethal:
        raise refuse(lethal[0], "speeds", f"class {lethal[0]!r} is lethal: the driver never drives on it, so it takes no speed")
    slow = [(c.name, float(table[c.id])) for c in classes.classes if table[c.id] < MIN_SPEED_MPS]
    if slow:
        name, v = slow[0]
        ranked = config.ranked_speeds_mps is not None and name in classes.terrain_names
        field = "speeds" if name in dict(config.speeds) else "ranked_speeds_mps" if ranked else "speed_mps"
        raise refuse(name, field, f"class {name!r}: {v:g} m/s is below {MIN_SPEED_MPS:g} m/s, the least the planner commands")
    if config.near_lethal_mps is not None and config.near_lethal_mps < MIN_SPEED_MPS:
        v = config.near_lethal_mps
        raise refuse("", "near_lethal_mps", f"{v:g} m/s is below {MIN_SPEED_MPS:g} m/s, the least the planner commands")


FLAGS = {
    "speeds": "--speeds",
    "lateral_accel_mps2": "--lateral-accel",
    "preview_m": "--preview",
    "relief": "--relief-style",
}  # the fields flags set
