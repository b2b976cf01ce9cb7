"""Tensor files: safetensors weights or arrays plus terrapref's JSON metadata in the header.

Reading parses a JSON header and raw tensors only; nothing in a file is ever executed.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np
from safetensors import SafetensorError, safe_open
from safetensors.numpy import save_file

from terrapref.errors import UserError, described
from terrapref.fileio import atomic_path

META_KEY = "terrapref"
REASON_CHARS = 160  # the most of a parser's reason an error line quotes
# The deepest that mappings and lists may lie within one another in a file's metadata: a model's
# lie 7 deep; far deeper ones would exhaust the readers' recursion.
MAX_META_DEPTH = 32


class _KeyTwice(ValueError):
    """A mapping of a file's metadata names a key twice (JSON reads the last silently)."""


def _no_key_twice(pairs: list[tuple[str, object]]) -> dict:
    keys = [k for k, _ in pairs]
    if len(set(keys)) != len(keys):
        raise _KeyTwice(next(k for k in keys if keys.count(k) > 1))
    return dict(pairs)


def parse_metadata(text: str, source: str, field: str = "metadata") -> object:
    """A file's JSON metadata, read as written or refused: not JSON (or an integer longer than
    Python reads), a key named twice in one mapping, or mappings and lists more than
    :data:`MAX_META_DEPTH` deep. Raises a UserError naming ``source`` and ``field``."""
    try:
        meta = json.loads(text, object_pairs_hook=_no_key_twice)
    except _KeyTwice as exc:
        raise UserError(source, f"names {exc.args[0]!r} twice in one mapping", field=field) from None
    except (ValueError, RecursionError) as exc:
        reason = "an integer of thousands of digits" if "integer string conversion" in str(exc) else str(exc)
        reason = reason if len(reason) <= REASON_CHARS else reason[: REASON_CHARS - 3] + "..."
        raise UserError(source, f"not JSON that can be read ({reason})", field=field) from None
    within = [(meta, 1)]
    while within:
        value, depth = within.pop()
        if isinstance(value, (dict, list)):
            if depth > MAX_META_DEPTH:
                raise UserError(source, f"mappings and lists nested more than {MAX_META_DEPTH} deep", field=field)
            within.extend((v, depth + 1) for v in (value.values() if isinstance(value, dict) else value))
    return meta


def write_tensor_file(path: str | Path, tensors: dict[str, np.ndarray], meta: dict) -> Path:
    """Write tensors and ``meta`` atomically (temporary file, then rename)."""
    with atomic_path(path) as tmp:
        try:
            save_file(tensors, str(tmp), metadata={META_KEY: json.dumps(meta)})
        except SafetensorError as exc:  # the library's I/O errors carry the OS error's number in their text
            code = re.search(r"os error (\d+)", str(exc))
            if code is None:
                raise
            raise OSError(int(code.group(1)), os.strerror(int(code.group(1))), str(tmp)) from None
    return Path(path)


def read_tensor_file(path: str | Path, fmt: str, missing: str, unreadable: str) -> tuple[dict[str, np.ndarray], dict]:
    """Tensors and metadata of a file whose metadata declares ``format: fmt``.

    Args:
        missing, unreadable: the messages for an absent file and for one that is not
            safetensors (the parser's reason is appended).

    Raises:
        UserError: naming the file, and the field where one is at fault.
    """
    source = str(path)
    if Path(path).is_dir():
        raise UserError(source, "a folder, not a file")
    if not Path(path).is_file():
        raise UserError(source, missing)
    try:
        with safe_open(source, framework="numpy") as fh:
            header = fh.metadata() or {}
            tensors = {k: fh.get_tensor(k) for k in fh.keys()}
    except (SafetensorError, OSError, ValueError) as exc:
        if Path(path).suffix.lower() == ".onnx":
            raise UserError(
                source, f"{unreadable}: an ONNX file (as `terrapref export` writes); give the .safetensors file it was exported from"
            ) from None
        reason = str(exc)  # a damaged header's reason quotes the header, kilobytes of it
        reason = reason if len(reason) <= REASON_CHARS else reason[: REASON_CHARS - 3] + "..."
        raise UserError(source, f"{unreadable} ({reason})") from None
    if META_KEY not in header:
        raise UserError(source, "missing terrapref metadata", field="metadata")
    meta = parse_metadata(header[META_KEY], source)
    if not isinstance(meta, dict) or meta.get("format") != fmt:
        got = meta.get("format") if isinstance(meta, dict) else None
        raise UserError(source, f"expected {fmt!r}, got {described(got)}", field="format")
    return tensors, meta
