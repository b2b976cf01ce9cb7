"""Writing files so that a reader never sees half of one: a unique temporary name in the same
folder, then a rename. Every file terrapref writes goes through here.

The temporary name is unique (two writers of the same target cannot collide), keeps the
target's suffix (writers such as matplotlib choose the format by it), and the finished file's
mode follows the umask like any other new file (temporary files are created 0600).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_path(path: str | Path, fsync: bool = False) -> Iterator[Path]:
    """A temporary path to write ``path``'s content to; renamed to ``path`` when the block ends
    without an exception, removed otherwise.

    Raises:
        IsADirectoryError: ``path`` is a folder.
    """
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(21, "is a directory, expected a file name", str(path))
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=f".tmp{path.suffix}")
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        if fsync:
            with open(tmp, "rb") as fh:
                os.fsync(fh.fileno())
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except OSError as exc:  # a full disk, most often: said of the file asked for, not the temporary one
        tmp.unlink(missing_ok=True)
        if exc.filename not in (None, str(tmp), name):
            raise
        raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def new_folder(beside: Path, suffix: str) -> Path:
    """A new hidden folder in ``beside``'s folder, named after it, for writing what will replace
    it; with the permissions the umask gives any folder (a temporary folder's are 0700)."""
    folder = Path(tempfile.mkdtemp(prefix=f".{beside.name}.", suffix=suffix, dir=beside.parent))
    os.chmod(folder, 0o777 & ~_umask())
    return folder


def replace_dir(new: str | Path, target: str | Path) -> Path:
    """Put the folder ``new`` at ``target``, replacing what was there: the old folder is first
    moved aside under a unique temporary name, so ``target`` is never missing half-way through a
    delete, and removed once the new one is in place."""
    new, target = Path(new), Path(target)
    if target.exists():
        aside = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=".old", dir=target.parent))
        os.replace(target, aside / "old")
        os.replace(new, target)
        shutil.rmtree(aside, ignore_errors=True)
    else:
        os.replace(new, target)
    return target


def write_bytes_atomic(path: str | Path, data: bytes, fsync: bool = False) -> Path:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_path`)."""
    with atomic_path(path, fsync) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text_atomic(path: str | Path, text: str, fsync: bool = False) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically."""
    return write_bytes_atomic(path, text.encode("utf-8"), fsync)
