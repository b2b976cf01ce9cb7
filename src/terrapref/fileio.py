"""Writing files so that a reader never sees half of one: a unique temporary name in the same
folder, then a rename. Every file terrapref writes goes through here, and every output a command
names is checked here before any work (:func:`check_output`, :func:`output_folder`).

The temporary name is unique (two writers of the same target cannot collide), keeps the
target's suffix (writers such as matplotlib choose the format by it), and the finished file's
mode follows the umask like any other new file (temporary files are created 0600).

A folder is replaced with a journal: a hidden folder beside it, ``.NAME.XXXXXXXX.replacing``
(a command writing NAME in place) or ``.NAME.XXXXXXXX.swapping`` (a finished folder being put at
NAME), which holds the old folder until the new one is complete and is locked by its command for
as long as that runs. A journal nobody holds was left by a command that was killed (``kill -9``,
out of memory): the next command that checks an output or an input in that folder, or replaces
a folder there, finishes what the journal says first (the old output back, or the finished swap)
and says so in one line. Every step is one rename, so a kill between any two leaves a state the
journal names.
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import stat
import sys
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
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
    it; with the permissions the umask gives any folder (a temporary folder's are 0700). It is
    marked as scratch and held (locked) by this process until :func:`release_folder` (or
    :func:`replace_dir`, which puts it in place) lets go of it: one that nobody holds was left by
    a killed command, and the next command that checks an output beside it removes it."""
    folder = Path(tempfile.mkdtemp(prefix=f".{beside.name}.", suffix=suffix, dir=beside.parent))
    os.chmod(folder, 0o777 & ~_umask())
    fd = _lock(folder)
    assert fd is not None  # made just now
    _HELD_SCRATCH[folder] = fd
    (folder / _SCRATCH_MARK).touch()
    return folder


def holds_nothing(folder: Path) -> bool:
    """Whether ``folder`` (one :func:`new_folder` made, or any) holds nothing written into it."""
    return all(p.name in (_SCRATCH_MARK, _KEEP_MARK) for p in folder.iterdir())


def keep_if_stopped(folder: Path) -> None:
    """Mark a folder :func:`new_folder` made as worth keeping: one a killed command left (a
    recording's frames, a person's driving among them) is moved to ``NAME.partial`` by the next
    command that checks an output beside it, not removed."""
    (Path(folder) / _KEEP_MARK).touch()


def free_partial(target: str | Path) -> Path:
    """Where an unfinished output of ``target`` is kept: ``TARGET.partial``, or, where an earlier
    one is there, ``TARGET.partial-2``, ``-3`` and so on (an earlier one is never replaced)."""
    target = Path(target)
    partial, n = target.with_name(target.name + ".partial"), 1
    while partial.exists() or partial.is_symlink():
        n += 1
        partial = target.with_name(f"{target.name}.partial-{n}")
    return partial


def release_folder(folder: Path, remove: bool = True) -> None:
    """Let go of a folder :func:`new_folder` made, removing it (and what it holds) unless not ``remove``."""
    if remove:
        shutil.rmtree(folder, ignore_errors=True)
    fd = _HELD_SCRATCH.pop(Path(folder), None)
    if fd is not None:
        os.close(fd)


def replace_dir(new: str | Path, target: str | Path) -> Path:
    """Put the finished folder ``new`` at ``target``, replacing what was there, through a journal
    beside ``target``: ``target`` is at every moment the old folder or the new one (or, after a
    kill between two renames, the next command puts the new one there), never half of either."""
    new, target = Path(new), Path(target)
    (new / _SCRATCH_MARK).unlink(missing_ok=True)  # a folder new_folder made is scratch no more
    (new / _KEEP_MARK).unlink(missing_ok=True)
    with _folder_held(target.parent):
        _recover(target.parent)
        _swap(new, target)
    release_folder(new, remove=False)
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


def check_tensor_file(out: str | Path, flag: str) -> None:
    """A model or dataset is a safetensors file, named so: never ``.onnx`` (every command reads a
    file of that suffix as ONNX, so the file would be refused where it is used), nor another suffix.

    Raises:
        UserError: ``out``'s suffix is not ``.safetensors`` (naming ``flag``).
    """
    from terrapref.errors import UserError

    suffix = Path(out).suffix.lower()
    if suffix == ".onnx":
        raise UserError(
            str(out),
            "a .onnx file is read as ONNX; name the file .safetensors (terrapref export --format onnx makes the ONNX file)",
            field=flag,
        )
    if suffix != ".safetensors" and not Path(out).is_dir():  # a folder: check_output says what it is
        raise UserError(str(out), "a model or dataset is a safetensors file: give it the suffix .safetensors", field=flag)


def check_distinct_outputs(outputs: Sequence[tuple[str, str | Path | None]]) -> None:
    """Refuse two output flags of one command that name the same file: the second written would
    replace the first. ``outputs``: (flag, path) pairs, a path None where the flag was not given.

    Raises:
        UserError: two paths resolve to the same file (naming the later flag, and the earlier).
    """
    from terrapref.errors import UserError

    seen: dict[Path, str] = {}
    for flag, path in outputs:
        if path is None:
            continue
        target = Path(path).resolve()
        if target in seen:
            raise UserError(str(path), f"is also {seen[target]}'s file; {flag} must name a file of its own", field=flag)
        seen[target] = flag


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
    for beside in {_existing_parent(out), *(p.parent for p in map(Path, inputs) if p.exists())}:
        if beside.is_dir() and (_journals(beside) or _scratch_folders(beside)):  # a command killed while it wrote here
            with _folder_held(beside):
                _recover(beside)
    target = out.resolve()
    for given in map(Path, inputs):
        if not given.exists():
            continue
        if target == given.resolve():
            raise UserError(str(out), f"is also an input; {flag} must name a new {'folder' if folder else 'file'}", field=flag)
        if given.is_dir() and target.is_relative_to(given.resolve()):
            raise UserError(str(out), f"lies inside the input {given}; {flag} must name a place outside it", field=flag)
        if folder and given.resolve().is_relative_to(target):  # replaced whole with --force: the input with it
            raise UserError(
                str(out), f"holds the input {given}, which a new output would replace; {flag} must name another folder", field=flag
            )
    if folder and out.exists() and _holds_cwd(target):  # a folder in use cannot be replaced
        raise UserError(str(out), f"is the current folder or holds it; {flag} must name a folder elsewhere", field=flag)
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
    parent = out if folder and out.exists() else _existing_parent(out)
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


def _holds_cwd(folder: Path) -> bool:
    """Whether the current folder is ``folder`` (resolved) or lies inside it (False where the
    current folder is gone)."""
    try:
        return Path.cwd().resolve().is_relative_to(folder)
    except OSError:
        return False


def _special_file(path: Path) -> str | None:
    """What ``path`` is when it exists and is neither a regular file nor a folder (links followed):
    writing over it would replace a device node or block on a pipe."""
    try:
        mode = path.stat().st_mode
    except OSError:
        return None
    kinds = ((stat.S_ISCHR, "character device"), (stat.S_ISBLK, "block device"), (stat.S_ISFIFO, "FIFO"), (stat.S_ISSOCK, "socket"))
    return next((name for test, name in kinds if test(mode)), None)


def _existing_parent(path: Path) -> Path:
    """The nearest folder above ``path`` that exists."""
    parent = path.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    return parent


@contextlib.contextmanager
def output_folder(out: str | Path, force: bool, flag: str = "--out") -> Iterator[Path]:
    """``out``, made fresh for one command to write all its outputs into, and held against every
    other command while it does: the one rule for a folder output.

    A folder that exists and holds anything is refused unless ``force``; with ``force`` it is moved
    into a journal beside ``out`` and removed only once the block ends without an exception.
    Otherwise the new, unfinished folder is moved to ``OUT.partial`` (one that holds nothing is
    removed) and the old one put back. A run never leaves two runs' files mixed in one folder, nor
    an unfinished run at ``out``'s name, and a replacement that fails loses nothing; a command
    killed half-way is undone the same way by the next command that checks an output beside
    ``out`` (see the module's docstring). Another command writing the same folder is refused,
    with or without ``force``.

    Raises:
        UserError: ``out`` exists and is not empty (without ``force``), or is being written.
    """
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with _folder_held(out.parent):
        running = _recover(out.parent)
        journal = _begin(out, force, flag, out.name in running)
    try:
        try:
            yield out
        except BaseException:
            with _folder_held(out.parent):
                _put_back(journal.path, out)
            raise
        journal.commit()
    except BaseException:
        journal.close(remove=not journal.holds_old())  # a failure to put back or commit leaves it for the next command
        raise
    journal.close()


# --- journals: a folder replaced so that a kill at any point loses nothing -------------------------

_REPLACING = ".replacing"  # a command writes NAME in place: holds old/ (what it replaces) or fresh/ (nothing was there)
_SWAPPING = ".swapping"  # a finished folder is put at NAME: holds new/ until it is there, and old/
_JOURNAL = re.compile(r"\.(?P<name>.+)\.[a-z0-9_]{8}(?P<kind>\.replacing|\.swapping)")  # tempfile.mkdtemp's 8 characters
_SCRATCH = re.compile(r"\.(?P<name>.+)\.[a-z0-9_]{8}(\.[a-z]+)?")  # new_folder's names (its mark inside says it is one)
_SCRATCH_MARK = ".terrapref-scratch"
_KEEP_MARK = ".terrapref-keep"  # a scratch folder a killed command left is kept as NAME.partial (keep_if_stopped)
_HELD_SCRATCH: dict[Path, int] = {}  # the scratch folders this process made and holds, and their locks


@dataclass
class _Journal:
    """A journal this process made and holds (its lock) until :meth:`close`."""

    path: Path
    fd: int

    @classmethod
    def start(cls, target: Path, kind: str) -> _Journal:
        """A new journal for ``target``, in its folder (held by the caller, so that no other
        command sees it before it is locked)."""
        path = Path(tempfile.mkdtemp(prefix=f".{target.name}.", suffix=kind, dir=target.parent))
        fd = _lock(path)
        assert fd is not None  # made just now, in a folder this process holds
        return cls(path, fd)

    def commit(self) -> None:
        """The new output is complete: one rename (or removal) says so, before the old one is removed."""
        if (self.path / "old").exists():
            os.replace(self.path / "old", self.path / "done")
        else:
            (self.path / "fresh").rmdir()

    def holds_old(self) -> bool:
        """Whether the old output is still in the journal (the new one not complete)."""
        return (self.path / "old").exists()

    def close(self, remove: bool = True) -> None:
        """Remove the journal (and the old output a completed replacement left in it), then let go of it."""
        if remove:
            shutil.rmtree(self.path, ignore_errors=True)
        os.close(self.fd)


def _journals(folder: Path) -> list[tuple[Path, str, str]]:
    """The journals in ``folder``: (path, the name of the output it concerns, its kind)."""
    found = []
    with os.scandir(folder) as entries:
        for entry in entries:
            m = _JOURNAL.fullmatch(entry.name)
            if m and entry.is_dir(follow_symlinks=False):
                found.append((Path(entry.path), m["name"], m["kind"]))
    return sorted(found, key=lambda j: (j[2] != _SWAPPING, j[0].name))  # swaps first: each stands alone


def _recover(folder: Path) -> set[str]:
    """Finish what every journal in ``folder`` (held by the caller) whose command was killed
    says, each in one line on stderr; the names of the outputs whose commands still run."""
    _remove_scratch(folder)
    running: set[str] = set()
    for path, name, kind in _journals(folder):
        try:
            fd = _lock(path)
        except FileNotFoundError:  # its command finished with it and removed it meanwhile
            continue
        if fd is None:  # its command is running
            running.add(name)
            continue
        journal = _Journal(path, fd)
        try:
            note = (_finish_swap if kind == _SWAPPING else _put_back)(path, folder / name)
        except BaseException:
            journal.close(remove=False)
            raise
        journal.close()
        if note:
            print(note, file=sys.stderr)
    return running


def _scratch_folders(folder: Path) -> list[Path]:
    """The scratch folders (:func:`new_folder`) in ``folder``, held or not."""
    with os.scandir(folder) as entries:
        found = [
            Path(e.path)
            for e in entries
            if _SCRATCH.fullmatch(e.name) and not _JOURNAL.fullmatch(e.name) and e.is_dir(follow_symlinks=False)
        ]
    return sorted(path for path in found if (path / _SCRATCH_MARK).is_file())


def _remove_scratch(folder: Path) -> None:
    """Remove the scratch folders (:func:`new_folder`) in ``folder`` that no command holds, each
    said in one line on stderr: a killed command's unfinished output; one marked to keep
    (:func:`keep_if_stopped`) is moved to ``NAME.partial`` (:func:`free_partial`) instead."""
    for path in _scratch_folders(folder):
        try:
            fd = _lock(path)
        except FileNotFoundError:  # its command let go of it and removed it meanwhile (a stopped record's)
            continue
        if fd is None:  # its command is running
            continue
        name = path.parent / _SCRATCH.fullmatch(path.name)["name"]
        try:
            if (path / _KEEP_MARK).is_file():  # a recording's frames: kept where a stopped one's are
                kept = free_partial(name)
                os.replace(path, kept)  # its name no scratch's from here on; then its marks go
                for mark in (_SCRATCH_MARK, _KEEP_MARK):
                    (kept / mark).unlink(missing_ok=True)
                said = f"kept what a stopped command left unfinished as {kept}"
            else:
                shutil.rmtree(path, ignore_errors=True)
                said = f"removed {path.name}, what a stopped command left unfinished"
        finally:
            os.close(fd)
        print(f"note: {name}: {said}", file=sys.stderr)


def _begin(out: Path, force: bool, flag: str, running: bool) -> _Journal:
    """The journal of a command about to write ``out`` in place (its folder held by the caller):
    the old output moved into it (one rename), or a mark that there was none.

    Raises:
        UserError: another command is writing ``out``, or it holds something and not ``force``.
    """
    from terrapref.errors import UserError

    if running:
        raise UserError(str(out), f"is being written by another terrapref command; choose another {flag} or wait for it to end", field=flag)
    occupied = out.is_dir() and any(out.iterdir())
    if occupied and not force:
        raise UserError(
            str(out),
            f"exists; choose another {flag}, or pass --force to replace it (the old folder stays until the new one is complete)",
            field=flag,
        )
    journal = _Journal.start(out, _REPLACING)
    try:
        if occupied:
            os.replace(out, journal.path / "old")
        else:
            (journal.path / "fresh").mkdir()
        out.mkdir(exist_ok=True)
    except BaseException:
        _put_back(journal.path, out)
        journal.close()
        raise
    return journal


def _put_back(journal: Path, target: Path) -> str | None:
    """Undo a replacement of ``target`` that did not complete (its folder held by the caller):
    the unfinished new output to ``TARGET.partial`` (one that holds nothing removed), the old one
    back at ``target``. What was done, as a note, or None if there was nothing to undo."""
    old, fresh = journal / "old", journal / "fresh"
    if not old.exists() and not fresh.exists():  # complete, or never begun
        return None
    partial = free_partial(target)
    kept = target.is_dir() and any(target.iterdir())
    if kept:
        _swap(target, partial)
    elif target.is_dir():
        target.rmdir()
    if old.exists():
        os.replace(old, target)
        return f"note: {target}: put back the output a stopped command was replacing" + (
            f"; its unfinished one is in {partial}" if kept else ""
        )
    return f"note: {target}: a stopped command left it unfinished; moved to {partial}" if kept else None


def _swap(new: Path, target: Path) -> None:
    """Put the finished folder ``new`` at ``target`` (its folder held by the caller): both moved
    into a journal, then the new one out to ``target``; the old one removed."""
    if not target.exists():
        os.replace(new, target)
        return
    journal = _Journal.start(target, _SWAPPING)
    try:
        os.replace(new, journal.path / "new")
        os.replace(target, journal.path / "old")
        os.replace(journal.path / "new", target)
    except BaseException:
        journal.close(remove=False)  # the next command finishes the swap from what the journal holds
        raise
    journal.close()


def _finish_swap(journal: Path, target: Path) -> str | None:
    """Finish a swap a killed command left half-way: its new folder, which was complete, at ``target``."""
    new = journal / "new"
    if not new.exists():  # done, the old one partly removed, or never begun
        return None
    if target.exists():
        os.replace(target, journal / "old")
    os.replace(new, target)
    return f"note: {target}: put in place the new one a stopped command had finished"


def _lock(path: Path) -> int | None:
    """A descriptor of ``path`` holding an exclusive lock on it, released when it is closed or
    the process ends, however it ends; None if another holds it."""
    import fcntl

    fd = os.open(path, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        return None
    except BaseException:
        os.close(fd)
        raise
    return fd


@contextlib.contextmanager
def _folder_held(folder: Path) -> Iterator[None]:
    """``folder`` held against every other command's journal work in it for the block (waiting
    for one that holds it: each holds it only for a few renames)."""
    import fcntl

    fd = os.open(folder, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)
