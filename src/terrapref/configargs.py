"""Command-line options made from typed configurations, so that a flag and the field it sets
are written once (on the field) and cannot drift apart.

A field becomes a flag when its metadata carries a ``help`` text (:func:`option`); nested
configuration dataclasses are walked, so ``TrainConfig.optimiser.epochs`` gives ``--epochs``.
Every generated flag defaults to "not given", and :func:`apply_arguments` replaces only the
fields whose flag was given, on top of a base configuration (a recipe's):

>>> import argparse
>>> from dataclasses import dataclass
>>> @dataclass(frozen=True)
... class Fit:
...     epochs: int = option(15, "passes over the data")
...     mirror: bool = option(False, "add mirrored samples")
>>> parser = argparse.ArgumentParser()
>>> add_arguments(parser, Fit)
>>> apply_arguments(parser.parse_args(["--epochs", "3", "--mirror"]), Fit(epochs=300))
Fit(epochs=3, mirror=True)
>>> apply_arguments(parser.parse_args([]), Fit(epochs=300))
Fit(epochs=300, mirror=False)

A field whose value is an optional configuration (``SecondStageConfig | None``) becomes an
on/off switch (``--second-stage`` / ``--no-second-stage``); its own fields' flags apply
when it is on, and are refused (``ValueError``) when it is off.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import typing
from collections.abc import Callable, Iterator
from typing import Any

HELP, FLAG, CHOICES = "help", "flag", "choices"


def option(default: Any, help: str, flag: str | None = None, choices: tuple | None = None) -> Any:
    """A dataclass field with ``default`` that the command line may set (``--name``, or ``--flag``)."""
    meta = {HELP: help, **({FLAG: flag} if flag else {}), **({CHOICES: choices} if choices else {})}
    return dataclasses.field(default=default, metadata=meta)


def _flag(f: dataclasses.Field) -> str:
    return f.metadata.get(FLAG, f.name.replace("_", "-"))


def _dest(f: dataclasses.Field) -> str:
    return _flag(f).replace("-", "_")


def _nested(cls: type, f: dataclasses.Field) -> type | None:
    """The configuration dataclass a field holds (also inside ``X | None``), or None."""
    hint = typing.get_type_hints(cls)[f.name]
    for arg in (hint, *typing.get_args(hint)):
        if dataclasses.is_dataclass(arg):
            return arg
    return None


def _scalar(cls: type, f: dataclasses.Field) -> Callable[[str], Any]:
    """How a flag's value is parsed: as the field's type (``X | None`` gives X); a float must be finite."""
    hint = typing.get_type_hints(cls)[f.name]
    kinds = [a for a in (hint, *typing.get_args(hint)) if a in (int, float, str)]
    if not kinds:
        raise TypeError(f"{cls.__name__}.{f.name}: a flag needs an int, float or str field")
    return finite_float if kinds[0] is float else kinds[0]


def finite_float(text: str) -> float:
    """A flag's number, refused (by argparse, naming the flag) when it is not finite: inf or nan."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return value


def positive_float(text: str) -> float:
    """A flag's number, refused (by argparse, naming the flag) unless finite and > 0."""
    value = finite_float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not > 0")
    return value


def _fields(cls: type) -> Iterator[tuple[dataclasses.Field, type | None]]:
    for f in dataclasses.fields(cls):
        yield f, _nested(cls, f)


def add_arguments(parser: argparse.ArgumentParser, cls: type, defaults: Any = None) -> None:
    """Add a flag for every field of ``cls`` (and its nested configurations) that has a help
    text; ``defaults`` (an instance) is named in the help as the value the flag overrides."""
    for f, nested in _fields(cls):
        current = getattr(defaults, f.name) if defaults is not None else f.default
        if nested is not None and HELP not in f.metadata:
            add_arguments(parser, nested, current if dataclasses.is_dataclass(current) else None)
            continue
        if HELP not in f.metadata:
            continue
        shown = ("on" if current else "off") if nested is not None or isinstance(f.default, bool) else current
        text = f"{f.metadata[HELP]} (default: {shown})".replace("%", "%%")
        if nested is not None or isinstance(f.default, bool):
            parser.add_argument(f"--{_flag(f)}", dest=_dest(f), action=argparse.BooleanOptionalAction, default=None, help=text)
        else:
            parser.add_argument(
                f"--{_flag(f)}", dest=_dest(f), type=_scalar(cls, f), default=None, choices=f.metadata.get(CHOICES), help=text
            )
        if nested is not None:
            add_arguments(parser, nested, current if dataclasses.is_dataclass(current) else None)


def apply_arguments(args: argparse.Namespace, base: Any) -> Any:
    """``base`` with every field whose flag was given set from ``args`` (nested ones included).

    Raises:
        ValueError: from the configuration's own checks.
    """
    changes = {}
    for f, nested in _fields(type(base)):
        value = getattr(base, f.name)
        given = getattr(args, _dest(f), None) if HELP in f.metadata else None
        if nested is None:
            if given is not None:
                changes[f.name] = given
            continue
        inner = None if given is False else value if value is not None else (nested() if given else None)
        if inner is not None:
            changes[f.name] = apply_arguments(args, inner)
        elif value is not None or given is False:
            changes[f.name] = None
        if inner is None:
            _refuse_given(args, nested, f)
    return dataclasses.replace(base, **changes)


def _refuse_given(args: argparse.Namespace, cls: type, switch: dataclasses.Field) -> None:
    """A flag of an optional part that is off would change nothing: say so rather than drop it."""
    for f, _ in _fields(cls):
        if HELP in f.metadata and getattr(args, _dest(f), None) is not None:
            raise ValueError(f"--{_flag(f)} needs --{_flag(switch)} (the configuration trains without it)")
