"""Label maps (``terrapref-labels/1``): a segmentation network's label ids onto terrapref's classes.

A map is keyed by id, never by colour (SPEC 14)::

    format: terrapref-labels/1
    name: my_network
    ids:
      0: unknown
      3: grass
      33: mud

An id the map does not list is an error where images come in (the runtime, the ROS node, the
importer), naming the id: a network that emits a class nobody mapped must not be driven on as
if it were ground. A map that means such ids to be unknown says so::

    unlisted: unknown    # default: error

A network that publishes colour images (rgb8) instead of ids adds its colour table, again
keyed by id::

    colors:
      3: [0, 102, 0]
      33: [255, 128, 0]

Pixels of a colour not in the table are unknown, and counted as ids the map does not list.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from terrapref.errors import ConfigError, Problem
from terrapref.terrain import ClassTable
from terrapref.terrain.classes import UNKNOWN
from terrapref.yamlio import read_yaml_mapping

LABELS_FORMAT = "terrapref-labels/1"
UNKNOWN_NAME = "unknown"
MAX_ID = 65535  # mono16 label images
_KEYS = {"format", "name", "description", "ids", "colors", "unlisted"}
UNLISTED = ("error", "unknown")  # what an id the map does not list is (LabelMap.unlisted)
NO_ID = MAX_ID  # what a colour missing from the table decodes to (never listed)


@dataclass(frozen=True)
class LabelMap:
    """Source label id -> terrapref class name (or ``unknown``)."""

    name: str
    ids: dict[int, str]
    source: str = ""
    colors: dict[int, tuple[int, int, int]] | None = None  # id -> (r, g, b), for rgb8 images
    unlisted: str = "error"  # an id the map does not list: an error, or unknown (UNLISTED)

    def decode_rgb(self, rgb: np.ndarray) -> np.ndarray:
        """Label ids (H, W) uint16 of an (H, W, 3) uint8 colour image, by the colour table."""
        if not self.colors:
            raise ValueError("this label map has no colour table (colors) to decode colour images with")
        keys = np.array([(r << 16) | (g << 8) | b for r, g, b in self.colors.values()], dtype=np.int64)
        ids = np.array(list(self.colors), dtype=np.uint16)
        order = np.argsort(keys)
        keys, ids = keys[order], ids[order]
        packed = (rgb[..., 0].astype(np.int64) << 16) | (rgb[..., 1].astype(np.int64) << 8) | rgb[..., 2]
        at = np.clip(np.searchsorted(keys, packed), 0, len(keys) - 1)
        return np.where(keys[at] == packed, ids[at], NO_ID).astype(np.uint16)

    def lut(self, classes: ClassTable, unlisted: int = UNKNOWN) -> np.ndarray:
        """Lookup table (65536,) uint8: source id -> class id of ``classes`` (255 unknown), and
        ``unlisted`` for the ids the map does not list."""
        missing = sorted({n for n in self.ids.values() if n != UNKNOWN_NAME} - set(classes.names))
        if missing:
            raise ConfigError(
                self.source or self.name, f"class {missing[0]!r} is not in the class table ({', '.join(classes.names)})", field="ids"
            )
        lut = np.full(MAX_ID + 1, unlisted, dtype=np.uint8)
        for source_id, name in self.ids.items():
            lut[source_id] = UNKNOWN if name == UNKNOWN_NAME else classes.id_of(name)
        return lut

    def unlisted_in(self, ids: np.ndarray) -> list[int]:
        """The ids in ``ids`` (label images) that the map does not list, sorted."""
        listed = self.listed()
        return sorted(int(i) for i in np.unique(ids[~listed[ids]]))

    def refuse_unlisted(self, ids: np.ndarray, where: str) -> None:
        """Raise a :class:`ConfigError` naming the ids in ``ids`` the map does not list, unless it maps them to unknown."""
        if self.unlisted == "unknown":
            return
        bad = self.unlisted_in(ids)
        if bad:
            raise ConfigError(self.source or self.name, unlisted_message(bad, where), field="ids")

    def listed(self) -> np.ndarray:
        """Mask (65536,) of the ids the map lists (``unknown`` included)."""
        mask = np.zeros(MAX_ID + 1, dtype=bool)
        mask[list(self.ids)] = True
        return mask


def parse_label_map(data: dict, source: str) -> LabelMap:
    """Check a parsed ``terrapref-labels/1`` mapping; every problem names its field."""
    problems = [Problem(k, f"unknown key; expected {', '.join(sorted(_KEYS))}") for k in data if k not in _KEYS]
    name = data.get("name", Path(source).stem)
    if not isinstance(name, str) or not name:
        problems.append(Problem("name", "expected a non-empty string"))
    ids = data.get("ids")
    out: dict[int, str] = {}
    if not isinstance(ids, dict) or not ids:
        problems.append(Problem("ids", "expected a mapping of label ids to class names"))
        ids = {}
    for key, value in ids.items():
        if isinstance(key, bool) or not isinstance(key, int) or not 0 <= key <= MAX_ID:
            problems.append(Problem(f"ids.{key}", f"a label id must be an integer in 0..{MAX_ID}"))
        elif not isinstance(value, str) or not value:
            problems.append(Problem(f"ids.{key}", "expected a class name (or unknown)"))
        else:
            out[key] = value
    colors = data.get("colors")
    out_colors: dict[int, tuple[int, int, int]] | None = None
    if colors is not None:
        out_colors = {}
        if not isinstance(colors, dict) or not colors:
            problems.append(Problem("colors", "expected a mapping of label ids to [r, g, b]"))
            colors = {}
        for key, value in colors.items():
            if isinstance(key, bool) or not isinstance(key, int) or not 0 <= key < MAX_ID:
                problems.append(Problem(f"colors.{key}", f"a label id must be an integer in 0..{MAX_ID - 1}"))
            elif not (
                isinstance(value, list)
                and len(value) == 3
                and all(isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= 255 for v in value)
            ):
                problems.append(Problem(f"colors.{key}", "expected [r, g, b] with integers 0..255"))
            elif tuple(value) in out_colors.values():
                problems.append(Problem(f"colors.{key}", f"colour {value} is already another id's"))
            else:
                out_colors[key] = (value[0], value[1], value[2])
    unlisted = data.get("unlisted", "error")
    if unlisted not in UNLISTED:
        problems.append(Problem("unlisted", f"expected one of {', '.join(UNLISTED)}"))
    if problems:
        raise ConfigError(source, problems)
    return LabelMap(name, out, source, out_colors, unlisted)


def unlisted_message(ids: list[int], where: str) -> str:
    """The error for label ids a map does not list, seen ``where``."""
    shown = ", ".join(str(i) for i in ids[:8]) + (" ..." if len(ids) > 8 else "")
    return (
        f"label id{'s' if len(ids) > 1 else ''} {shown} in {where} not listed: add {'them' if len(ids) > 1 else 'it'} "
        "(as a class or as unknown), or set unlisted: unknown"
    )


def packaged_label_maps() -> list[str]:
    """Names of the label maps that ship with terrapref."""
    return sorted(
        p.name.removesuffix(".yaml") for p in resources.files("terrapref.data").joinpath("labels").iterdir() if p.name.endswith(".yaml")
    )


def load_label_map(name_or_path: str | Path, classes: ClassTable | None = None, source: str = "labels") -> LabelMap:
    """A packaged map by name (``rellis3d``) or a ``terrapref-labels/1`` file; with ``classes``,
    every class it names is checked against that table."""
    text = str(name_or_path)
    if text in packaged_label_maps():
        path = Path(str(resources.files("terrapref.data").joinpath("labels").joinpath(f"{text}.yaml")))
    elif Path(text).suffix in (".yaml", ".yml") or Path(text).exists():
        path = Path(text)
    else:
        raise ConfigError(source, f"{text!r} is neither a packaged label map ({', '.join(packaged_label_maps())}) nor a file")
    labels = parse_label_map(read_yaml_mapping(path, LABELS_FORMAT), str(path))
    if classes is not None:
        labels.lut(classes)
    return labels
