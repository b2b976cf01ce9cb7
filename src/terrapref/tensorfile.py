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
# The largest header the safetensors format allows [bytes]: a length past it is no safetensors file's.
MAX_HEADER_BYTES = 100_000_000
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
        found = damage(path)
        if found is not None:
            raise UserError(source, found) from None
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


def damage(path: str | Path) -> str | None:
    """What is wrong with a file that begins as a safetensors file (the length of its header, then
    a JSON header) but that the reader refuses: cut short (and which tensors that loses), or data
    that no tensor of its header accounts for. None for a file that does not begin so (no
    safetensors file at all) or whose damage is another."""
    try:
        with open(path, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            head = fh.read(8)
            n = int.from_bytes(head, "little") if len(head) == 8 else 0
            if not 0 < n <= MAX_HEADER_BYTES or fh.read(1) != b"{":
                return None
            if 8 + n > size:
                return f"truncated: the header promises at least {8 + n} bytes, the file has {size} (the header itself is cut short)"
            fh.seek(8)
            text = fh.read(n)
    except OSError:
        return None
    try:
        header = json.loads(text)
    except (ValueError, RecursionError):
        return None
    spans = _spans(header)
    return None if spans is None else _lost(spans, 8 + n, size - 8 - n)


def _spans(header: object) -> list[tuple[str, int, int]] | None:
    """(name, first byte, end) of each tensor a safetensors header lists, in the order of their
    data; None where the header is not one."""
    if not isinstance(header, dict):
        return None
    spans = []
    for name, entry in header.items():
        if name == "__metadata__":
            continue
        offsets = entry.get("data_offsets") if isinstance(entry, dict) else None
        if not (isinstance(offsets, list) and len(offsets) == 2 and all(isinstance(v, int) and v >= 0 for v in offsets)):
            return None
        spans.append((name, offsets[0], offsets[1]))
    return sorted(spans, key=lambda span: span[1:])


def _lost(spans: list[tuple[str, int, int]], start: int, held: int) -> str | None:
    """What of the tensors ``spans`` a file whose data begins at byte ``start`` and holds ``held``
    bytes of it lacks, or holds besides them; None where neither."""
    end = max((e for _, _, e in spans), default=0)
    if held < end:
        cut = [name for name, b, e in spans if b < held < e]
        missing = [name for name, b, e in spans if b >= held and e > b]
        lost = [f"tensor {cut[0]!r} is cut short"] if cut else []
        if missing:
            names = ", ".join(map(repr, missing[:3])) + (f" and {len(missing) - 3} more" if len(missing) > 3 else "")
            lost.append(f"tensor {names} is missing" if len(missing) == 1 else f"tensors {names} are missing")
        return f"truncated: the header promises {start + end} bytes, the file has {start + held}; {' and '.join(lost)}"
    at = 0
    for name, b, e in spans:
        if b > at:
            return f"bytes {at}-{b} of its data belong to no tensor of its header (before tensor {name!r}): a tensor's entry is missing"
        at = max(at, e)
    if held > end:
        return f"the header accounts for {start + end} bytes, the file has {start + held}: a tensor's entry is missing, or bytes were added"
    return None
