"""One way to name things that can be chosen by name: policies, decision rules, drivers, recipes,
driving styles and grid engines all live in a :class:`Registry`, as Gymnasium keeps its
environments' specs.

An entry is registered once under its name, with the value itself or a ``"module:attribute"``
string imported on first use (so that an entry defined above a registry's layer, or one that
needs an optional dependency, registers without importing it):

>>> colours = Registry("colour")
>>> colours.register("red", (255, 0, 0))
>>> colours.register("grey", "terrapref.terrain:UNKNOWN", doc="resolved on first use")
>>> colours["red"], colours.names()
((255, 0, 0), ['red', 'grey'])
>>> colours["blue"]
Traceback (most recent call last):
...
ValueError: unknown colour 'blue'; colours: red, grey
"""

from __future__ import annotations

import importlib
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

from terrapref.errors import UserError

T = TypeVar("T")


@dataclass(frozen=True)
class Entry(Generic[T]):
    """One registered name.

    Attributes:
        name: what users and files call it.
        target: the value, or ``"module:attribute"`` naming it (imported on first use).
        doc: one line on what it is (listed by the commands that offer the names).
    """

    name: str
    target: T | str
    doc: str = ""

    def load(self) -> T:
        """The value, importing it the first time if it was named as ``"module:attribute"``."""
        if isinstance(self.target, str) and ":" in self.target:
            module, _, attribute = self.target.partition(":")
            return getattr(importlib.import_module(module), attribute)
        return self.target  # type: ignore[return-value]


class Registry(Generic[T]):
    """Named entries of one kind (``what``: "policy", "rule", "recipe", ...), in the order registered.

    Args:
        what: the kind's name, singular, for messages.
        plural: its plural, if not ``what + "s"``.
    """

    def __init__(self, what: str, plural: str | None = None) -> None:
        self.what, self.plural = what, plural or f"{what}s"
        self._entries: dict[str, Entry[T]] = {}

    def register(self, name: str, target: T | str, doc: str = "") -> None:
        """Name ``target``; a name is registered once."""
        if name in self._entries:
            raise ValueError(f"{self.what} {name!r} is already registered")
        self._entries[name] = Entry(name, target, doc)

    def names(self) -> list[str]:
        """The registered names, in the order registered."""
        return list(self._entries)

    def entry(self, name: str) -> Entry[T]:
        """The entry of ``name``; an unknown name is a ValueError listing the known ones."""
        if name not in self._entries:
            raise ValueError(f"unknown {self.what} {name!r}; {self.plural}: {', '.join(self._entries)}")
        return self._entries[name]

    def __getitem__(self, name: str) -> T:
        return self.entry(name).load()

    def get(self, name: str, flag: str, source: str = "") -> T:
        """The value of ``name``, chosen by a user through ``flag`` (a command-line option, or a
        field of the file ``source``): an unknown name is a :class:`UserError` naming both."""
        if name not in self._entries:
            raise UserError(
                source or flag, f"unknown {self.what} {name!r}; {self.plural}: {', '.join(self._entries)}", field=flag if source else ""
            )
        return self[name]

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def values(self) -> Iterator[Any]:
        """The values, loading each, in the order registered."""
        return (entry.load() for entry in self._entries.values())

    def items(self) -> Iterator[tuple[str, Any]]:
        """(name, value) pairs, loading each value."""
        return ((name, entry.load()) for name, entry in self._entries.items())
