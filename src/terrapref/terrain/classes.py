"""The terrain class table (SPEC section 3), loaded from YAML so that users can add classes."""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from terrapref.errors import ConfigError, Problem
from terrapref.records import to_plain
from terrapref.yamlio import read_yaml_mapping

UNKNOWN = 255
"""Class id for pixels that see no ground: sky, beyond range, outside the map."""

MAX_TERRAIN_CLASSES = 10
"""Feature classes (neither background nor lethal) a table may have: a drive that shows every
pair of them grows as K(K-1)/2."""

LETHAL_COLUMN = "lethal"
"""The terrain column that several lethal classes share (one lethal class keeps its own name)."""
RESERVED_NAMES = {
    "unknown": "label maps and exports name id 255 so",
    "avoid": "a zone expects avoid when the driver keeps off it",
    "best": "a zone expects best when the driver takes the class it likes best",
}
"""Words the product's files give their own meaning; no class may be named so."""


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
        twice = [n for n in names if names.count(n) > 1] + [f"id {i}" for i in ids if ids.count(i) > 1]
        if twice:
            raise ValueError(f"class names and ids must be unique; {twice[0]} is given to more than one class")
        for name in (self.background, *self.lethal):
            if name not in names:
                raise ValueError(f"unknown class {name!r}")
        if len(names) < 2:
            raise ValueError("a table needs a class besides the background")
        if self.background in self.lethal:
            raise ValueError(f"the background class {self.background!r} cannot be lethal")
        if len(self.lethal) > 1 and LETHAL_COLUMN in names:
            raise ValueError(f"a class named {LETHAL_COLUMN!r} would clash with the column the {len(self.lethal)} lethal classes share")
        if len(self.terrain_names) > MAX_TERRAIN_CLASSES:
            raise ValueError(f"{len(self.terrain_names)} feature classes (neither background nor lethal); at most {MAX_TERRAIN_CLASSES}")
        if sorted(self.profile) != sorted(self.feature_names):
            raise ValueError(f"profile must list each of {', '.join(self.feature_names)} exactly once")
        if self.lethal_column is not None and self.profile[-1] != self.lethal_column:
            raise ValueError(f"profile must put the lethal column {self.lethal_column!r} last (it is lethal to every driver)")

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.classes)

    def notes(self) -> list[str]:
        """What the table's author should know that is no error: its background and its feature and
        lethal classes in one line, then a table with nothing lethal (every class may be driven
        over, at a price the drive teaches), one with no class to teach an order of (the teaching
        course has nothing to show), and classes drawn in the same colour (no figure tells them apart)."""
        said = [
            f"background {self.background}; feature classes {', '.join(self.terrain_names) or 'none'}; "
            f"lethal {', '.join(self.lethal) or 'none'}"
        ]
        if not self.lethal:
            said.append("no lethal class: the planner may drive over every class, at the price a drive teaches it")
        if not self.terrain_names:
            said.append("no feature class besides the background: a drive has no order of classes to teach (course refuses it)")
        colours: dict[tuple[int, int, int], str] = {}
        for c in self.classes:
            if c.color in colours:
                said.append(f"{colours[c.color]} and {c.name} have the same colour {list(c.color)}: no figure tells them apart")
            colours.setdefault(c.color, c.name)
        return said

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
    def terrain_names(self) -> tuple[str, ...]:
        """The feature classes a driver chooses between: neither background nor lethal, in id order."""
        return tuple(c.name for c in self.classes if c.name != self.background and c.name not in self.lethal)

    @property
    def lethal_column(self) -> str | None:
        """The name of the one terrain column all lethal classes share: the class's own name when
        the table has one lethal class, ``lethal`` when it has several, None when it has none."""
        return _lethal_column(self.lethal)

    def lethal_columns(self, columns: Sequence[str]) -> tuple[int, ...]:
        """Where the lethal column stands among terrain ``columns`` (a file's feature classes): its
        index, or none when the table has no lethal class (or the columns do not name it)."""
        return (list(columns).index(self.lethal_column),) if self.lethal_column in columns else ()

    @property
    def feature_names(self) -> tuple[str, ...]:
        """The terrain columns of the utility features (SPEC 3, 7): the non-background classes in
        id order, the lethal ones pooled into one column at the place of the first of them."""
        return _columns(self.classes, self.background, self.lethal)

    def ids_of(self, column: str) -> tuple[int, ...]:
        """The class ids a terrain column (a name of :attr:`feature_names`) or a class counts."""
        if column == self.lethal_column:
            return self.lethal_ids
        return (self.id_of(column),)

    def column_of(self, name: str) -> str:
        """The terrain column a class falls into (lethal classes share one)."""
        return LETHAL_COLUMN if len(self.lethal) > 1 and name in self.lethal else name

    def same_classes(self, other: ClassTable) -> bool:
        """Whether ``other`` means the same by every id: the same classes (ids and names), background
        and lethal classes; colours and the default profile may differ."""
        return (tuple((c.id, c.name) for c in self.classes), self.background, frozenset(self.lethal)) == (
            tuple((c.id, c.name) for c in other.classes),
            other.background,
            frozenset(other.lethal),
        )

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
            if name in RESERVED_NAMES:
                problems.append(Problem(f"{f}.name", f"{name!r} is a reserved word ({RESERVED_NAMES[name]}); choose another name"))
                continue
            if not isinstance(color, list) or len(color) != 3 or not all(isinstance(v, int) and 0 <= v <= 255 for v in color):
                problems.append(Problem(f"{f}.color", "must be [r, g, b] with integers 0..255"))
                continue
            classes.append(TerrainClass(cid, name, (color[0], color[1], color[2])))
        # Names are checked against every row that names a class, so that a bad colour is not
        # also reported as an unknown background or lethal class.
        names = {row["name"] for row in rows if isinstance(row, dict) and isinstance(row.get("name"), str)}
        background = data.get("background")
        if background is None:
            problems.append(Problem("background", "missing: name the class of the ground between patches (one of the table's)"))
        elif not isinstance(background, str) or background not in names:
            problems.append(Problem("background", f"unknown class {background!r}"))
        lethal = data.get("lethal", [])
        problems += _lethal_problems(lethal, names, background)
        if problems:
            raise ConfigError(source, problems)
        ordered = tuple(sorted(classes, key=lambda c: c.id))
        columns = _columns(ordered, background, tuple(lethal))
        last = _lethal_column(tuple(lethal))
        in_id_order = sorted(columns, key=lambda n: n == last)  # the columns in id order, the lethal one last
        try:  # the table's own checks first, with its columns as a stand-in profile
            cls(ordered, background, tuple(lethal), tuple(in_id_order))
        except ValueError as exc:
            raise ConfigError(source, str(exc), field="classes") from None
        profile = data.get("profile", in_id_order)
        if not isinstance(profile, list) or not all(isinstance(p, str) for p in profile) or sorted(profile) != sorted(columns):
            left = [c for c in columns if not isinstance(profile, list) or c not in profile]
            which = f" ({left[0]!r} is missing)" if isinstance(profile, list) and left else ""
            raise ConfigError(source, f"must list each of {', '.join(columns)} exactly once, most preferred first{which}", field="profile")
        if last is not None and profile[-1] != last:
            raise ConfigError(source, f"must put the lethal column {last!r} last (it is lethal to every driver)", field="profile")
        return cls(ordered, background, tuple(lethal), tuple(profile))


def _lethal_problems(lethal: object, names: set[str], background: object) -> list[Problem]:
    """What is wrong with a table's ``lethal`` entry, the table's class ``names`` and ``background`` given."""
    odd = [v for v in lethal if not isinstance(v, str) or v not in names] if isinstance(lethal, list) else []
    if not isinstance(lethal, list) or odd or len(set(lethal)) != len(lethal):
        which = f"; unknown class {odd[0]!r}" if odd else ("; a class named twice" if isinstance(lethal, list) else "")
        return [Problem("lethal", f"must be a list of distinct known class names{which}")]
    if background in lethal:
        return [Problem("lethal", f"names the background class {background!r}, which cannot be lethal")]
    return []


def _lethal_column(lethal: tuple[str, ...]) -> str | None:
    if not lethal:
        return None
    return lethal[0] if len(lethal) == 1 else LETHAL_COLUMN


def _columns(classes: tuple[TerrainClass, ...], background: str, lethal: tuple[str, ...]) -> tuple[str, ...]:
    """The terrain columns of ``classes`` (in id order): :attr:`ClassTable.feature_names`."""
    first_lethal = next((c.name for c in classes if c.name in lethal), None)
    names = []
    for c in classes:
        if c.name == background or (c.name in lethal and c.name != first_lethal):
            continue
        names.append(_lethal_column(lethal) if c.name == first_lethal else c.name)
    return tuple(names)


def load_classes(path: str | Path) -> ClassTable:
    """Load a class table from a YAML file."""
    return ClassTable.from_dict(read_yaml_mapping(path, "terrapref-classes/1"), str(path))


@functools.cache
def default_classes() -> ClassTable:
    """The packaged default table (grass, non_traversable, water, rock, mud)."""
    ref = resources.files("terrapref") / "data" / "classes.yaml"
    with resources.as_file(ref) as path:
        return load_classes(path)


class ForeignIds:
    """Finds class ids that a class table does not name (255, unknown, is always allowed) in
    label images, fast enough for every frame of a control loop.

    The ids outside the table form a few runs of consecutive ids; an image holds one of a run
    ``[a, b]`` when the least of its pixels' ``id - a`` (in uint8, wrapping) is at most ``b - a``:
    two passes of vectorised byte arithmetic per run (about 10 us on a 640 x 480 frame, against
    250 us for a table lookup of every pixel).
    """

    def __init__(self, classes: ClassTable) -> None:
        allowed = np.zeros(256, dtype=bool)
        allowed[[c.id for c in classes.classes]] = True
        allowed[UNKNOWN] = True
        self.allowed = allowed
        self.unnamed = int(np.flatnonzero(~allowed)[0])  # an id the table does not name (a label map's unlisted ids, to be refused)
        edges = np.flatnonzero(np.diff(np.concatenate([[False], ~allowed, [False]]).astype(np.int8)))
        self._runs = [(np.uint8(a), np.uint8(b - 1 - a)) for a, b in zip(edges[::2], edges[1::2])]

    def __call__(self, image: np.ndarray) -> list[int]:
        """The ids in ``image`` (uint8) that the table does not name, sorted; [] for none."""
        if image.size == 0 or not any((image - a).min() <= span for a, span in self._runs):
            return []
        return sorted(int(i) for i in np.unique(image[~self.allowed[image]]))
