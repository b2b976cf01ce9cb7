"""Safe reading of YAML files, turning every parse failure into a one-line :class:`UserError`."""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import yaml

from terrapref.errors import UserError

MAX_FILE_BYTES = 50_000_000
MAX_DEPTH = 200  # mappings and lists inside one another; no terrapref file needs more than a handful
MAX_ALIASED = 1_000_000  # values that aliases may repeat in one file


# libyaml's parser where PyYAML was built with it (its wheels are): the same documents read about
# ten times faster than by the pure-Python one, which stands in where it is missing.
_SafeLoader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


class _UniqueKeyLoader(_SafeLoader):
    """PyYAML's safe loader, refusing a mapping that gives a key twice (PyYAML keeps the last)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        first: dict[Any, int] = {}
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue
            key = self.construct_object(key_node, deep=True)
            try:
                line = first.get(key)
            except TypeError:  # an unhashable key: the base loader says so
                continue
            if line is not None:  # on another line or the same one (a flow mapping: {a: 1, a: 2})
                raise yaml.constructor.ConstructorError(None, None, f"key {key!r} given twice (first at line {line})", key_node.start_mark)
            first[key] = key_node.start_mark.line + 1
        return super().construct_mapping(node, deep)


class _Dumper(yaml.SafeDumper):
    """PyYAML's safe dumper, quoting what the loader would read as a number (:data:`_FLOAT`)."""


# Numbers as YAML 1.2's core schema reads them: PyYAML follows YAML 1.1, which wants a dot in an
# exponent's mantissa (it reads 5e-2 and 2.5e1 as strings, so that a file written by another tool
# would be refused field by field) and reads 1:30 as 90, 2_0 as 20 and 010 as 8. The dumper knows
# the same forms, so that a string such as "1e5" is written quoted and read back a string.
_INT = re.compile(r"^(?:[-+]?[0-9]+|0o[0-7]+|0x[0-9a-fA-F]+)$")
_FLOAT = re.compile(r"^(?:[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)(?:[eE][-+]?[0-9]+)?|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$")


def _int(loader: yaml.BaseLoader, node: yaml.ScalarNode) -> int:
    text = loader.construct_scalar(node)
    if text.startswith(("0o", "0x")):
        return int(text[2:], 8 if text[1] == "o" else 16)
    try:
        return int(text, 10)
    except ValueError:  # past the digits Python turns into a number from text
        raise yaml.constructor.ConstructorError(None, None, f"a whole number of {len(text):,} digits", node.start_mark) from None


def _float(loader: yaml.BaseLoader, node: yaml.ScalarNode) -> float:
    text = loader.construct_scalar(node).lower()
    if text.endswith(".inf"):
        return -math.inf if text.startswith("-") else math.inf
    return math.nan if text == ".nan" else float(text)


# Booleans too, for the loader: YAML 1.1 reads yes, no, on, off, y and n as booleans, so that a
# class named `on` or a profile listing `no` would be refused as "a boolean"; YAML 1.2 reads them
# as the words they are. The dumper still quotes them, for the readers of YAML 1.1.
_BOOL = re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$")
_READ_AS_1_2 = {
    "tag:yaml.org,2002:int": (_INT, "-+0123456789"),
    "tag:yaml.org,2002:float": (_FLOAT, "-+.0123456789"),
    "tag:yaml.org,2002:bool": (_BOOL, "tTfF"),
}
for _cls, _tags in ((_UniqueKeyLoader, tuple(_READ_AS_1_2)), (_Dumper, ("tag:yaml.org,2002:int", "tag:yaml.org,2002:float"))):
    _cls.yaml_implicit_resolvers = {
        first: [(tag, rx) for tag, rx in resolvers if tag not in _tags] for first, resolvers in _cls.yaml_implicit_resolvers.items()
    }
    for _tag in _tags:
        _cls.add_implicit_resolver(_tag, _READ_AS_1_2[_tag][0], list(_READ_AS_1_2[_tag][1]))
_UniqueKeyLoader.add_constructor("tag:yaml.org,2002:int", _int)
_UniqueKeyLoader.add_constructor("tag:yaml.org,2002:float", _float)


def dump_yaml(data: Any, **options: Any) -> str:
    """``yaml.safe_dump(data, **options)``, with strings that :func:`load_yaml_text` would read as
    numbers quoted."""
    return yaml.dump(data, Dumper=_Dumper, **options)


_OPEN = (yaml.MappingStartEvent, yaml.SequenceStartEvent)
_CLOSE = (yaml.MappingEndEvent, yaml.SequenceEndEvent)


def load_yaml_text(text: str) -> Any:
    """``yaml.safe_load``, except that a mapping with a key given twice, or collections nested more
    than :data:`MAX_DEPTH` deep, is a YAMLError."""
    _check_depth(text)
    return yaml.load(text, Loader=_UniqueKeyLoader)  # noqa: S506 - a SafeLoader subclass


def _check_depth(text: str) -> None:
    """Refuse nesting deeper than :data:`MAX_DEPTH` before anything is built from it: the parser's
    events come one by one, while building the nested objects recurses (in libyaml's composer, in
    C, past what its stack holds). Refuse aliases that repeat more than :data:`MAX_ALIASED`
    values in all, too (a few hundred bytes of aliases of aliases stand for billions of values,
    which whatever reads them, a message quoting one included, would expand)."""
    depth = aliased = values = 0
    opened: list[tuple[str | None, int]] = []  # each open collection's anchor and the values before it
    sizes: dict[str, int] = {}  # each anchor's values, its own nested ones included
    for event in yaml.parse(text, Loader=_SafeLoader):
        if isinstance(event, yaml.AliasEvent):
            aliased += sizes.get(event.anchor, 1)
            values += sizes.get(event.anchor, 1)
            if aliased > MAX_ALIASED:
                raise yaml.composer.ComposerError(None, None, f"aliases repeat more than {MAX_ALIASED:,} values", event.start_mark)
        elif isinstance(event, yaml.ScalarEvent):
            values += 1
            if event.anchor is not None:
                sizes[event.anchor] = 1
        elif isinstance(event, _OPEN):
            depth += 1
            if depth > MAX_DEPTH:
                raise yaml.parser.ParserError(None, None, f"nested more than {MAX_DEPTH} levels deep", event.start_mark)
            opened.append((event.anchor, values))
            values += 1
        elif isinstance(event, _CLOSE):
            depth -= 1
            anchor, before = opened.pop()
            if anchor is not None:
                sizes[anchor] = values - before


def read_capped(path: str | Path) -> bytes:
    """The bytes of the file ``path``, refused (ValueError) past :data:`MAX_FILE_BYTES`, read no
    further than that: a device that never ends (``/dev/zero``) is not read into memory whole."""
    with open(path, "rb") as f:
        raw = f.read(MAX_FILE_BYTES + 1)
    if len(raw) > MAX_FILE_BYTES:
        raise ValueError(f"file too large (more than {MAX_FILE_BYTES:,} bytes)")
    return raw


def read_yaml_mapping(path: str | Path, expected_format: str | None = None) -> dict[str, Any]:
    """Read a YAML file whose top level is a mapping, optionally checking its ``format`` key.

    Raises:
        UserError: unreadable, empty, not UTF-8 text, malformed YAML, not a mapping, wrong format.
    """
    source = str(path)
    try:
        raw = read_capped(path)
    except FileNotFoundError:
        raise UserError(source, "no such file") from None
    except IsADirectoryError:
        raise UserError(source, "is a directory, expected a file") from None
    except OSError as exc:
        raise UserError(source, f"cannot read: {exc.strerror}") from None
    except ValueError as exc:
        raise UserError(source, str(exc)) from None
    if not raw.strip():
        raise UserError(source, "empty file")
    if b"\x00" in raw:
        raise UserError(source, "binary data, expected a YAML text file")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise UserError(source, "not UTF-8 text, expected a YAML file") from None
    try:
        data = load_yaml_text(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or "invalid syntax"
        raise UserError(source, f"malformed YAML{where}: {problem}") from None
    except RecursionError:
        raise UserError(source, "malformed YAML: nested too deeply") from None
    except (ValueError, TypeError, KeyError, AttributeError) as exc:
        # PyYAML's constructors raise these for bad scalars such as `2020-13-45` or `!!int abc`.
        raise UserError(source, f"malformed YAML: a value cannot be read ({type(exc).__name__}: {exc})") from None
    if not isinstance(data, dict):
        raise UserError(source, f"expected a mapping at the top level, got {_type_name(data)}")
    if expected_format is not None and data.get("format") != expected_format:
        got = data.get("format")
        msg = "missing" if got is None else f"{got!r} is not supported"
        raise UserError(source, f"{msg}; expected {expected_format!r}", field="format")
    return data


def _type_name(value: object) -> str:
    return {type(None): "nothing", list: "a list", str: "a string", int: "a number", float: "a number", bool: "a boolean"}.get(
        type(value), type(value).__name__
    )
