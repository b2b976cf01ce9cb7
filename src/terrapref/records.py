"""Typed records as plain mappings and back: the one conversion behind the ``to_dict`` and
``from_dict`` of the package's frozen dataclasses (configurations, file headers, reports).

:func:`to_plain` writes a record's fields in their order: tuples as lists, nested records as
mappings (through their own ``to_dict`` where they define one), enums as their values.
:func:`from_plain` builds a record from such a mapping: a list becomes a tuple where the field
holds a tuple, a mapping becomes the record its field names (through that record's own
``from_dict`` where it defines one). Keys that name no field reach the record's constructor as
they are, so that it refuses them as it would refuse them from a caller.

A record whose file format differs from its fields (renamed or computed keys, a fixed order of
its own, checks that name the file and the field) keeps a ``to_dict``/``from_dict`` of its own.

>>> from dataclasses import dataclass
>>> @dataclass(frozen=True)
... class Point:
...     xy: tuple[float, float]
...     name: str | None = None
>>> to_plain(Point((1.0, 2.0)))
{'xy': [1.0, 2.0], 'name': None}
>>> to_plain(Point((1.0, 2.0)), omit_none=True)
{'xy': [1.0, 2.0]}
>>> from_plain(Point, {"xy": [1.0, 2.0]})
Point(xy=(1.0, 2.0), name=None)
"""

from __future__ import annotations

import functools
import types
from collections.abc import Collection, Mapping
from dataclasses import fields, is_dataclass
from enum import Enum
from typing import Any, TypeVar, Union, get_args, get_origin, get_type_hints

from terrapref.errors import described

R = TypeVar("R")


def to_plain(record: Any, omit_none: bool | Collection[str] = False) -> dict[str, Any]:
    """The fields of the dataclass ``record`` as a JSON-ready mapping, in field order.

    Args:
        omit_none: leave out the fields that are None: every one (True) or the ones named.
    """
    out = {}
    for f in fields(record):
        value = getattr(record, f.name)
        if value is None and (omit_none is True or (not isinstance(omit_none, bool) and f.name in omit_none)):
            continue
        out[f.name] = _plain(value)
    return out


def _plain(value: Any) -> Any:
    if is_dataclass(value) and not isinstance(value, type):
        return value.to_dict() if hasattr(value, "to_dict") else to_plain(value)
    if isinstance(value, Enum):
        return value.value
    if isinstance(value, (tuple, list)):
        return [_plain(v) for v in value]
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value


def from_plain(cls: type[R], data: Mapping[str, Any]) -> R:
    """The record ``cls`` of a mapping :func:`to_plain` wrote; its constructor checks the values.

    Raises:
        TypeError, ValueError: as ``cls(**data)`` raises them (not a mapping, an unknown or
            missing key, a value the record refuses).
    """
    if not isinstance(data, Mapping):
        return cls(**data)  # the constructor's own TypeError, as for any caller
    hints = _hints(cls)
    for key, value in data.items():  # a number field given another kind of value, named (the constructor's comparisons would not)
        if hints.get(key) in (int, float) and (isinstance(value, bool) or not isinstance(value, (int, float))):
            raise FieldError(key, f"expected a number, got {described(value)}")
    return cls(**{key: _typed(hints[key], value) if key in hints else value for key, value in data.items()})


class FieldError(TypeError):
    """A field of a record's mapping that holds another kind of value than the record's."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(f"{field}: {message}")
        self.field, self.message = field, message


@functools.cache
def _hints(cls: type) -> dict[str, Any]:
    """The resolved type of each field ``cls`` takes in its constructor."""
    hints = get_type_hints(cls)
    return {f.name: hints[f.name] for f in fields(cls) if f.init}


def _typed(hint: Any, value: Any) -> Any:
    """``value`` as the field of type ``hint`` holds it: tuples for lists, records for mappings."""
    if value is None:
        return None
    origin, args = get_origin(hint), get_args(hint)
    if origin in (Union, types.UnionType):
        kinds = [a for a in args if a is not type(None)]
        return _typed(kinds[0], value) if len(kinds) == 1 else value
    if isinstance(hint, type) and is_dataclass(hint) and isinstance(value, Mapping):
        return hint.from_dict(value) if hasattr(hint, "from_dict") else from_plain(hint, value)
    if origin is tuple and isinstance(value, list):
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_typed(args[0], v) for v in value)
        if len(args) == len(value):
            return tuple(_typed(a, v) for a, v in zip(args, value))
        return tuple(value)
    if origin is list and isinstance(value, list) and args:
        return [_typed(args[0], v) for v in value]
    return value
