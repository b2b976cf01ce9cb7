"""Writing files so that a reader never sees half of one: a unique temporary name in the same
folder, then a rename. Every file terrapref writes goes through here, and every output a command
names is checked here before any work (:func:`check_output`, :func:`output_folder`).

The temporary name is unique (two writers of the same target cannot collide), keeps the
target's suffix (writers such as matplotlib choose the format by it), and the finished file's
mode follows the umask like any other new file (temporary files are created 0600).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import stat
import tempfile
from collections.abc import Iterator, Sequence
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


FIGURE_FORMATS = (".png", ".pdf", ".svg", ".jpg", ".jpeg", ".tif", ".tiff", ".webp", ".eps", ".ps")


def check_figure(out: str | Path, flag: str) -> None:
    """A figure's file name must say a format the plotting library writes.

    Raises:
        UserError: ``out``'s suffix is none of :data:`FIGURE_FORMATS` (naming ``flag``).
    """
    from terrapref.errors import UserError

    if Path(out).suffix.lower() not in FIGURE_FORMATS:
        raise UserError(str(out), f"a figure needs one of the suffixes {', '.join(FIGURE_FORMATS)}", field=flag)


def check_output(out: str | Path, flag: str, inputs: Sequence[str | Path] = (), folder: bool = False, force: bool | None = None) -> None:
    """Refuse an output before any work: one that is an input or lies inside one, a device, FIFO
    or socket, a file where a folder goes (or the reverse), a place that cannot be written, and,
    given ``force`` (the command's --force), a file that exists unless it is True: the one rule
    of every command (a folder output's is :func:`output_folder`).

    Raises:
        UserError: ``out`` is refused (naming ``flag``).
    """
    from terrapref.errors import UserError

    out = Path(out)
    target = out.resolve()
    for given in map(Path, inputs):
        if not given.exists():
            continue
        if target == given.resolve():
            raise UserError(str(out), f"is also an input; {flag} must name a new {'folder' if folder else 'file'}", field=flag)
        if given.is_dir() and target.is_relative_to(given.resolve()):
            raise UserError(str(out), f"lies inside the input {given}; {flag} must name a place outside it", field=flag)
    special = _special_file(out)
    if special:
        raise UserError(str(out), f"is a {special}; {flag} must name a {'folder' if folder else 'regular file'}", field=flag)
    if out.exists() and out.is_dir() != folder:
        raise UserError(
            str(out), "exists and is a " + ("file; expected a folder" if folder else "folder; expected a file name"), field=flag
        )
    if force is False and not folder and out.exists():
        raise UserError(
            str(out), f"exists; choose another {flag}, or pass --force to replace it (only once the new one is complete)", field=flag
        )
    parent = out if folder and out.exists() else out.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    try:  # a file made and removed at once: permissions alone miss read-only and virtual file systems
        with tempfile.TemporaryFile(dir=parent):
            pass
    except OSError as exc:
        raise UserError(str(out), f"cannot be written (no file can be made in {parent}: {exc.strerror or exc})", field=flag) from None


def check_distinct(inputs: Sequence[str | Path], what: str) -> None:
    """Refuse an input given twice (by the same name, or two names of one file): its frames would
    count twice, or land in training and validation both.

    Raises:
        UserError: an input is given twice (``what``: the kind of input, in the message).
    """
    from terrapref.errors import UserError

    seen: dict[object, str] = {}
    for given in map(str, inputs):
        key = Path(given).resolve() if Path(given).exists() else given
        if key in seen:
            same = "" if seen[key] == given else f" (the same as {seen[key]})"
            raise UserError(given, f"is given twice{same}; give each {what} once")
        seen[key] = given


def _special_file(path: Path) -> str | None:
    """What ``path`` is when it exists and is neither a regular file nor a folder (links followed):
    writing over it would replace a device node or block on a pipe."""
    try:
        mode = path.stat().st_mode
    except OSError:
        return None
    kinds = ((stat.S_ISCHR, "character device"), (stat.S_ISBLK, "block device"), (stat.S_ISFIFO, "FIFO"), (stat.S_ISSOCK, "socket"))
    return next((name for test, name in kinds if test(mode)), None)


@contextlib.contextmanager
def output_folder(out: str | Path, force: bool, flag: str = "--out") -> Iterator[Path]:
    """``out``, made fresh for one command to write all its outputs into, and held against every
    other command while it does: the one rule for a folder output.

    A folder that exists and holds anything is refused unless ``force``; with ``force`` it is moved
    aside, and removed only once the block ends without an exception. Otherwise the new, unfinished
    folder is kept as ``OUT.partial`` (unless it is empty) and the old one put back; a new folder
    that fails empty is removed. A run never leaves two runs' files
    mixed in one folder, and a replacement that fails loses nothing. Another command writing the
    same folder (a lock on it) is refused, with or without ``force``.

    Raises:
        UserError: ``out`` exists and is not empty (without ``force``), or is being written.
    """
    from terrapref.errors import UserError

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    aside: Path | None = None
    if out.is_dir() and any(out.iterdir()):
        with _locked(out, flag):  # held while it is moved: refused if another command is writing it
            if not force:
                raise UserError(
                    str(out),
                    f"exists; choose another {flag}, or pass --force to replace it (the old folder stays until the new one is complete)",
                    field=flag,
                )
            aside = new_folder(out, ".old")
            os.replace(out, aside / "old")
    out.mkdir(exist_ok=True)
    with _locked(out, flag):  # (another command that made the folder first in the meantime: the old one stays aside, hidden)
        try:
            yield out
        except BaseException:
            empty = not out.is_dir() or not any(out.iterdir())
            if empty:  # refused before it wrote anything: nothing of it is kept
                shutil.rmtree(out, ignore_errors=True)
            if aside is not None:
                if not empty:
                    replace_dir(out, out.with_name(out.name + ".partial"))
                os.replace(aside / "old", out)
                shutil.rmtree(aside, ignore_errors=True)
            raise
    if aside is not None:
        shutil.rmtree(aside, ignore_errors=True)


@contextlib.contextmanager
def _locked(folder: Path, flag: str) -> Iterator[None]:
    """An exclusive lock on ``folder`` for the block; refused (UserError) if another process holds it."""
    import fcntl

    from terrapref.errors import UserError

    fd = os.open(folder, os.O_RDONLY)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise UserError(
                str(folder), f"is being written by another terrapref command; choose another {flag} or wait for it to end", field=flag
            ) from None
        yield
    finally:
        os.close(fd)  # releases the lock
