"""The terrain class table (SPEC section 3), loaded from YAML so that users can add classes."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from terrapref.errors import ConfigError, Problem
from terrapref.records import to_plain
from terrapref.yamlio import read_yaml_mapping

UNKNOWN = 255
"""Class id for pixels that see no ground: sky, beyond range, outside the map."""


@dataclass(frozen=True)
class TerrainClass:
    id: int
    name: str
    color: tuple[int, int, int]


@dataclass(frozen=True)
class ClassTable:
    """An ordered set of terrain classes.

    Attributes:
        classes: the classes in id order.
        background: name of the class that carries no utility feature (grass).
        lethal: names of classes whose entry is a collision (non_traversable).
        profile: default preference order of the feature classes, most preferred first.
    """

    classes: tuple[TerrainClass, ...]
    background: str
    lethal: tuple[str, ...]
    profile: tuple[str, ...]

    def __post_init__(self) -> None:
        names = [c.name for c in self.classes]
        ids = [c.id for c in self.classes]
        if len(set(names)) != len(names) or len(set(ids)) != len(ids):
            raise ValueError("class names and ids must be unique")
        for name in (self.background, *self.lethal, *self.profile):
            if name not in names:
                raise ValueError(f"unknown class {name!r}")

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.classes)

    def id_of(self, name: str) -> int:
        for c in self.classes:
            if c.name == name:
                return c.id
        raise KeyError(name)

    def name_of(self, class_id: int) -> str:
        for c in self.classes:
            if c.id == class_id:
                return c.name
        return "unknown" if class_id == UNKNOWN else f"id{class_id}"

    @property
    def background_id(self) -> int:
        return self.id_of(self.background)

    @property
    def lethal_ids(self) -> tuple[int, ...]:
        return tuple(self.id_of(n) for n in self.lethal)

    @property
    def feature_classes(self) -> tuple[TerrainClass, ...]:
        """The non-background classes in id order: one terrain utility feature each (SPEC 3, 7)."""
        return tuple(c for c in self.classes if c.name != self.background)

    @property
    def feature_ids(self) -> tuple[int, ...]:
        return tuple(c.id for c in self.feature_classes)

    @property
    def feature_names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.feature_classes)

    def palette(self) -> np.ndarray:
        """RGB lookup table, shape (256, 3) uint8; unknown (255) and unused ids are near-black/sky."""
        lut = np.zeros((256, 3), dtype=np.uint8)
        lut[:] = (30, 30, 30)
        lut[UNKNOWN] = (176, 206, 236)
        for c in self.classes:
            lut[c.id] = c.color
        return lut

    def to_dict(self) -> dict:
        return {
            "background": self.background,
            "lethal": list(self.lethal),
            "profile": list(self.profile),
            "classes": [to_plain(c) for c in self.classes],
        }

    @classmethod
    def from_dict(cls, data: object, source: str = "") -> ClassTable:
        """Build a table from parsed YAML/JSON, raising :class:`ConfigError` naming each bad field."""
        problems: list[Problem] = []
        if not isinstance(data, dict):
            raise ConfigError(source, "expected a mapping")
        rows = data.get("classes")
        classes: list[TerrainClass] = []
        if not isinstance(rows, list) or not rows:
            problems.append(Problem("classes", "expected a non-empty list"))
            rows = []
        for i, row in enumerate(rows):
            f = f"classes[{i}]"
            if not isinstance(row, dict) or set(row) != {"id", "name", "color"}:
                problems.append(Problem(f, "expected keys id, name, color"))
                continue
            cid, name, color = row["id"], row["name"], row["color"]
            if not isinstance(cid, int) or isinstance(cid, bool) or not 0 <= cid < UNKNOWN:
                problems.append(Problem(f"{f}.id", "must be an integer in 0..254"))
                continue
            if not isinstance(name, str) or not name.isidentifier():
                problems.append(Problem(f"{f}.name", "must be an identifier-like string"))
                continue
            if (
                not isinstance(color, list)
                or len(color) != 3
                or not all(isinstance(v, int) and 0 <= v <= 255 for v in color)
            ):
                problems.append(Problem(f"{f}.color", "must be [r, g, b] with integers 0..255"))
                continue
            classes.append(TerrainClass(cid, name, (color[0], color[1], color[2])))
        names = {c.name for c in classes}
        background = data.get("background")
        if not isinstance(background, str) or background not in names:
            problems.append(Problem("background", f"unknown class {background!r}"))
        lethal = data.get("lethal", [])
        profile = data.get("profile", [])
        for key, value in (("lethal", lethal), ("profile", profile)):
            if not isinstance(value, list) or any(not isinstance(v, str) or v not in names for v in value):
                problems.append(Problem(key, "must be a list of known class names"))
        if problems:
            raise ConfigError(source, problems)
        try:
            return cls(tuple(sorted(classes, key=lambda c: c.id)), background, tuple(lethal), tuple(profile))
        except ValueError as exc:
            raise ConfigError(source, str(exc), field="classes") from None


def load_classes(path: str | Path) -> ClassTable:
    """Load a class table from a YAML file."""
    return ClassTable.from_dict(read_yaml_mapping(path, "terrapref-classes/1"), str(path))


@functools.cache
def default_classes() -> ClassTable:
    """The packaged default table (grass, non_traversable, water, rock, mud)."""
    ref = resources.files("terrapref") / "data" / "classes.yaml"
    with resources.as_file(ref) as path:
        return load_classes(path)
