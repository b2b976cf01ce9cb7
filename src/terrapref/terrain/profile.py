"""Preference profiles: an ordered list of terrain classes, most preferred first."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from terrapref.errors import ConfigError, UserError, described
from terrapref.terrain.classes import ClassTable, default_classes


@dataclass(frozen=True)
class PreferenceProfile:
    """Ordered feature classes, most preferred first; the background class beats them all (SPEC 3)."""

    order: tuple[str, ...]

    @classmethod
    def parse(cls, text: str | Sequence[str], classes: ClassTable | None = None, source: str = "--profile") -> PreferenceProfile:
        """Parse ``"mud,rock,water,non_traversable"`` (or a list) and check it against the class table.

        The profile must name every feature class exactly once, so that any zone's ``best``
        resolves to one class, and the lethal column last (it is lethal to every driver: no zone
        expects it), as the table's own profile has it; an empty item is refused, not skipped.
        """
        classes = classes or default_classes()
        names = ([s.strip() for s in text.split(",")] if text.strip() else []) if isinstance(text, str) else list(text)
        if not all(names):
            raise ConfigError(source, f"has an empty item: {text!r}; expected the classes separated by commas, most preferred first")
        unknown = [n for n in names if n not in classes.feature_names]
        if unknown:
            raise ConfigError(
                source,
                f"unknown or background class {unknown[0]!r}; expected a permutation of {', '.join(classes.feature_names)}"
                + (" (your own class table? give its --classes FILE)" if unknown[0] not in classes.names else ""),
            )
        if sorted(names) != sorted(classes.feature_names):
            left = [n for n in classes.feature_names if n not in names]
            which = f"{left[0]!r} is missing" if left else f"{next(n for n in names if names.count(n) > 1)!r} is named twice"
            raise ConfigError(source, f"must list each of {', '.join(classes.feature_names)} exactly once; {which}")
        lethal = classes.lethal_column
        if lethal is not None and names[-1] != lethal:
            after = ", ".join(names[names.index(lethal) + 1 :])
            raise ConfigError(source, f"puts the lethal column {lethal!r} before {after}: it is lethal to every driver and comes last")
        return cls(tuple(names))

    @classmethod
    def default(cls, classes: ClassTable | None = None) -> PreferenceProfile:
        classes = classes or default_classes()
        return cls(classes.profile)

    def rank(self, name: str) -> int:
        """0 for the most preferred class; lower is better."""
        return self.order.index(name)

    def best(self, present: Iterable[str]) -> str | None:
        """The most preferred of ``present`` (feature classes), or None if none is present."""
        candidates = [n for n in present if n in self.order]
        return min(candidates, key=self.rank) if candidates else None

    def __str__(self) -> str:
        return ",".join(self.order)


def declared_order(value: object, classes: ClassTable, source: str) -> tuple[str, ...]:
    """A file's declared preference order (a model's or a dataset's ``profile``): each of its class
    table's terrain columns once, as ``--profile`` is checked; a UserError naming ``source`` and
    ``profile`` otherwise. Where the lethal column stands is left to the commands that score by the
    order (files written before it had to come last read as written)."""
    if not isinstance(value, list) or not all(isinstance(name, str) for name in value):
        raise UserError(source, f"expected a list of class names, most preferred first, got {described(value)}", field="profile")
    lethal = classes.lethal_column
    try:
        PreferenceProfile.parse([n for n in value if n != lethal] + [n for n in value if n == lethal], classes, source=source)
    except ConfigError as exc:
        raise UserError(source, exc.problems[0].message, field="profile") from None
    return tuple(value)


def check_columns(columns: Sequence[str], classes: ClassTable, source: str) -> None:
    """Refuse a file's terrain columns (its ``features.feature_classes``) that are not its class
    table's feature classes, naming ``source`` and the field."""
    if tuple(columns) != classes.feature_names:
        raise UserError(
            source,
            f"names {', '.join(map(str, columns))} where its class table's feature classes are {', '.join(classes.feature_names)}",
            field="features.feature_classes",
        )
