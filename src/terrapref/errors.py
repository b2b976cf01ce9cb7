"""Errors a user can cause, carrying the file and the field they concern.

The CLI prints each :class:`UserError` as one line per problem and exits with code 2; anything
else reaching the user would be a bug.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass


def finite_number(value: object) -> bool:
    """Whether ``value`` is a number (an int or a float, not a bool) that is finite as a float: an
    integer beyond the float range (YAML and JSON read 1 followed by 400 zeros as one) is not."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def printed(value: object) -> str:
    """``repr(value)``, safe for integers too long to print (Python limits int-to-text conversion)."""
    try:
        return repr(value)
    except ValueError:
        return "a very large number"


def described(value: object) -> str:
    """A value from a file as an error message names it, in a few words whatever its size: a
    number or a short string as it is, a long string, a list or a mapping by its kind."""
    if value is None:
        return "nothing"
    if isinstance(value, bool):
        return f"boolean {value}"
    if isinstance(value, (int, float)):
        text = printed(value)
        return f"number {text}" if len(text) < 40 else "a very large number"
    if isinstance(value, str):
        return f"string {value!r}" if len(value) < 40 else "a string"
    if isinstance(value, list):
        return f"a list of {len(value)}"
    if isinstance(value, dict):
        return "a mapping"
    return type(value).__name__


@dataclass(frozen=True)
class Problem:
    """One thing wrong with an input: ``field`` is a dotted path such as ``terrain[2].circle.radius``."""

    field: str
    message: str

    def format(self, source: str) -> str:
        where = f"{source}: " if source else ""
        field = f"{self.field}: " if self.field else ""
        return f"{where}{field}{self.message}"


class UserError(Exception):
    """An error in user input (a file, a flag, a model that does not fit the configuration)."""

    def __init__(self, source: str, problems: Sequence[Problem] | str, field: str = "") -> None:
        if isinstance(problems, str):
            problems = [Problem(field, problems)]
        self.source = source
        self.problems: tuple[Problem, ...] = tuple(problems)
        super().__init__("\n".join(self.lines()))

    def lines(self) -> list[str]:
        """One printable line per problem, each naming the file and the field."""
        return [p.format(self.source) for p in self.problems]

    def __reduce__(self):
        # Rebuilt from its own arguments, so that an error raised in a worker process reaches
        # the parent intact (and is printed as one line there) instead of breaking the pool.
        return (type(self), (self.source, self.problems))


class ScenarioError(UserError):
    """A scenario file that does not follow ``terrapref-scenario/1``."""


class ConfigError(UserError):
    """A configuration file or value that is invalid."""


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the command was (terrapref.cli installs the handler), so that it
    cleans up as after Ctrl-C."""


def one_line(exc: BaseException, limit: int = 160) -> str:
    """An exception's text on one line (a reader's errors quote whole message definitions), without
    the memory addresses some quote (PIL's ``<_io.BytesIO object at 0x...>``), so that the same
    problem reads the same each time."""
    text = re.sub(r" at 0x[0-9a-fA-F]+", "", " ".join(str(exc).split()))
    return f"{type(exc).__name__}: {text[:limit]}{'...' if len(text) > limit else ''}"
