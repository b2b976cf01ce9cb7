"""The product's YAML files by kind: which reader checks a file (told by its ``format``), and a
commented template of each kind to start from (``terrapref validate FILE``, ``--template KIND``).
"""

from __future__ import annotations

from collections.abc import Callable
from importlib import resources
from pathlib import Path
from typing import NamedTuple

from terrapref.errors import UserError
from terrapref.terrain import ClassTable
from terrapref.yamlio import read_yaml_mapping


class FileKind(NamedTuple):
    """One kind of file: its ``format``, what it is called, the keys only it has at the top (which
    tell it when the format is missing), and its reader (which raises a :class:`UserError` naming the file and the field)."""

    format: str
    title: str
    keys: frozenset[str]
    check: Callable[[Path, ClassTable | None], object]


def _scenario(path: Path, classes: ClassTable | None) -> object:
    from terrapref.scenario import load_scenario
    from terrapref.vehicle.ground import drivable

    return drivable(load_scenario(path, classes))  # and where a run would begin: not past the vehicle's limits


def _classes(path: Path, classes: ClassTable | None) -> object:
    from terrapref.terrain import load_classes

    return load_classes(path)  # a table is read alone: --classes does not apply to it


def _perception(path: Path, classes: ClassTable | None) -> object:
    from terrapref.perception import load_perception

    return load_perception(path, classes)


def _robot(path: Path, classes: ClassTable | None) -> object:
    from terrapref.interop.robot import load_robot, load_waypoints

    robot = load_robot(path, classes)
    if robot.path_file:  # read as a node reads it when it starts
        load_waypoints(robot.path_file, robot.source)
    return robot


def _labels(path: Path, classes: ClassTable | None) -> object:
    from terrapref.interop.labels import load_label_map
    from terrapref.terrain import default_classes

    return load_label_map(path, classes or default_classes(), source=str(path))


def _style(path: Path, classes: ClassTable | None) -> object:
    from terrapref.demos.speed_style import driver_style
    from terrapref.terrain import default_classes
    from terrapref.vehicle import VehicleConfig

    table = classes or default_classes()  # its speeds checked against the table, for the table's own order
    return driver_style(str(path), table.profile, table, VehicleConfig().max_speed_mps)


KINDS: dict[str, FileKind] = {
    "scenario": FileKind("terrapref-scenario/1", "scenario", frozenset({"world", "path", "terrain", "zones"}), _scenario),
    "classes": FileKind("terrapref-classes/1", "class table", frozenset({"background", "lethal"}), _classes),
    "perception": FileKind("terrapref-perception/1", "perception model", frozenset({"pose", "frames"}), _perception),
    "robot": FileKind("terrapref-robot/1", "robot file", frozenset({"topics"}), _robot),
    "labels": FileKind("terrapref-labels/1", "label map", frozenset({"ids", "colors", "unlisted"}), _labels),
    "style": FileKind("terrapref-driver-style/1", "driver style", frozenset({"base", "speeds", "ranked_speeds_mps"}), _style),
}
"""Every kind ``validate`` reads, by the name ``--template`` takes."""


def kind_of(path: str | Path) -> FileKind:
    """The kind of a YAML file, by its ``format`` (a later version of a kind goes to that kind's
    reader, which names the version it reads); with no format, by its keys.

    Raises:
        UserError: the file cannot be read as YAML, or neither its format nor its keys tell a kind.
    """
    data = read_yaml_mapping(path)
    given = data.get("format")
    for kind in KINDS.values():
        if isinstance(given, str) and given.partition("/")[0] == kind.format.partition("/")[0]:
            return kind
    if given is None:
        by_keys = [k for k in KINDS.values() if k.keys & set(map(str, data))]
        if len(by_keys) == 1:
            return by_keys[0]  # its reader says the format is missing, and which one it expects
    got = "missing" if given is None else f"{given!r} is not a file terrapref reads here"
    raise UserError(str(path), f"{got}; expected one of {', '.join(k.format for k in KINDS.values())}", field="format")


def check_file(path: str | Path, classes: ClassTable | None = None) -> tuple[FileKind, list[str]]:
    """Read ``path`` as its kind's reader reads it (scenarios, perception models, robot files and
    label maps with ``classes``, the default table when None; a scenario's start checked as the
    commands that drive it check it); its kind when it is sound, and what a reader should know of
    it that is no error (a class table's: :meth:`ClassTable.notes`).

    Raises:
        UserError: every problem the reader finds, each naming the file and the field.
    """
    kind = kind_of(path)
    read = kind.check(Path(path), classes)
    return kind, (read.notes() if isinstance(read, ClassTable) else [])


def template(name: str) -> str:
    """The commented template of the kind ``name`` (a key of :data:`KINDS`), a file its reader accepts."""
    if name not in KINDS:
        raise UserError("--template", f"unknown kind {name!r}; kinds: {', '.join(KINDS)}")
    return (resources.files("terrapref") / "data" / "templates" / f"{name}.yaml").read_text(encoding="utf-8")
