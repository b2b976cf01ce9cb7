"""Atomic writes: unique temporary names, nothing half-written, modes that follow the umask."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import numpy as np
import pytest

from terrapref.errors import UserError
from terrapref.fileio import (
    FIGURE_FORMATS,
    atomic_path,
    check_distinct,
    check_figure,
    check_output,
    new_folder,
    output_folder,
    write_bytes_atomic,
    write_text_atomic,
)
from terrapref.pngio import write_png_atomic
from terrapref.tensorfile import write_tensor_file


@pytest.fixture
def umask_022():
    old = os.umask(0o022)
    yield
    os.umask(old)


def _mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def test_every_writer_leaves_a_readable_file_and_no_temporary(tmp_path: Path, umask_022):
    write_bytes_atomic(tmp_path / "a.bin", b"abc")
    write_text_atomic(tmp_path / "b.json", "{}", fsync=True)
    write_png_atomic(tmp_path / "c.png", np.zeros((4, 5), np.uint8))
    write_tensor_file(tmp_path / "d.safetensors", {"x": np.zeros(3, np.float32)}, {"format": "test"})
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from terrapref.plots import _save

    fig, _ = plt.subplots()
    _save(fig, tmp_path / "e.png")
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["a.bin", "b.json", "c.png", "d.safetensors", "e.png"]  # no .tmp left behind
    assert all(_mode(tmp_path / n) == 0o644 for n in names)  # a robot's service account can read them
    assert (tmp_path / "e.png").read_bytes()[:4] == b"\x89PNG"  # the format chosen by the real suffix


def test_a_failed_write_keeps_the_old_file(tmp_path: Path):
    target = tmp_path / "model.safetensors"
    target.write_bytes(b"old")
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_bytes(b"half")
            raise RuntimeError("killed half-way")
    assert target.read_bytes() == b"old" and [p.name for p in tmp_path.iterdir()] == ["model.safetensors"]


def test_two_writers_of_one_target_do_not_share_a_temporary(tmp_path: Path):
    target = tmp_path / "out.json"
    with atomic_path(target) as first, atomic_path(target) as second:
        assert first != second
        first.write_text("1")
        second.write_text("2")
    assert target.read_text() == "1"  # the outer block finishes last: its content stays


def test_a_folder_is_not_a_file_name(tmp_path: Path):
    with pytest.raises(IsADirectoryError):
        write_bytes_atomic(tmp_path, b"x")


def test_folders_written_to_replace_others_follow_the_umask(tmp_path):
    # A temporary folder is 0700; a recording replaced with --force, a .partial one and a model's
    # checkpoints are folders a user keeps, with the permissions any other folder gets.
    from terrapref.demos.recording import RecordingWriter
    from terrapref.learning.pipeline import _Checkpoints

    old = os.umask(0o022)
    try:
        assert stat.S_IMODE(new_folder(tmp_path / "x", ".new").stat().st_mode) == 0o755
        out = tmp_path / "rec"
        for _ in range(2):  # the second replaces the first through a new folder beside it
            writer = RecordingWriter(out, {}, {"format": "terrapref-scenario/1"}, overwrite=True)
            writer.append(0.0, (0.0, 0.0, 0.0), np.zeros((4, 4), np.uint8), (1.0, 0.0), 10)
            writer.close()
        assert stat.S_IMODE(out.stat().st_mode) == 0o755
        checkpoints = _Checkpoints(tmp_path / "m.safetensors", {"members": 1}, True)
        checkpoints.finish()
        assert stat.S_IMODE((tmp_path / "m.checkpoints").stat().st_mode) == 0o755
    finally:
        os.umask(old)


# --- a command's output folder: one rule for every command -----------------------------------------


def _files(folder: Path) -> dict[str, str]:
    return {str(p.relative_to(folder)): p.read_text() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_an_output_folder_is_made_and_written(tmp_path: Path):
    with output_folder(tmp_path / "a" / "out", force=False) as out:
        (out / "metrics.json").write_text("{}")
    assert _files(tmp_path / "a" / "out") == {"metrics.json": "{}"}
    (tmp_path / "empty").mkdir()
    with output_folder(tmp_path / "empty", force=False) as out:  # an empty folder holds nothing to lose
        (out / "x").write_text("1")


def test_an_existing_output_folder_is_refused_without_force_and_kept(tmp_path: Path):
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "old.png").write_text("old")
    with pytest.raises(UserError, match="exists; choose another --out, or pass --force"):
        with output_folder(tmp_path / "out", force=False):
            pytest.fail("the block ran")
    assert _files(tmp_path / "out") == {"old.png": "old"}


def test_force_replaces_the_whole_folder_so_no_two_runs_mix(tmp_path: Path):
    for run in ("first", "second"):
        with output_folder(tmp_path / "out", force=True) as out:
            (out / f"{run}.png").write_text(run)
            (out / "metrics.json").write_text(run)
    assert _files(tmp_path / "out") == {"second.png": "second", "metrics.json": "second"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # nothing left aside


def test_a_replacement_that_fails_puts_the_old_folder_back_and_keeps_the_new_one_apart(tmp_path: Path):
    with output_folder(tmp_path / "out", force=False) as out:
        (out / "metrics.json").write_text("old")
    with pytest.raises(KeyboardInterrupt):
        with output_folder(tmp_path / "out", force=True) as out:
            (out / "half.png").write_text("new")
            raise KeyboardInterrupt
    assert _files(tmp_path / "out") == {"metrics.json": "old"}
    assert _files(tmp_path / "out.partial") == {"half.png": "new"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "out.partial"]


def test_a_first_run_that_fails_is_kept_as_partial_never_at_the_outputs_name(tmp_path: Path):
    # (evaluate --mcap failing on its last file left a half-made folder at --out)
    with pytest.raises(OSError):
        with output_folder(tmp_path / "ev", force=False) as out:
            (out / "metrics.json").write_text("half")
            raise OSError(18, "Invalid cross-device link")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ev.partial"]
    assert _files(tmp_path / "ev.partial") == {"metrics.json": "half"}


def test_a_folder_another_command_is_writing_is_refused_even_with_force(tmp_path: Path):
    with output_folder(tmp_path / "out", force=False) as out:
        (out / "metrics.json").write_text("running")
        for force in (False, True):
            with pytest.raises(UserError, match="is being written by another terrapref command"):
                with output_folder(tmp_path / "out", force=force):
                    pytest.fail("the block ran")
        assert _files(out) == {"metrics.json": "running"}


def test_a_command_refused_before_it_wrote_anything_leaves_nothing(tmp_path: Path):
    with pytest.raises(UserError):
        with output_folder(tmp_path / "new", force=False):
            raise UserError("--frames", "bad")
    assert not (tmp_path / "new").exists()
    with output_folder(tmp_path / "out", force=False) as out:
        (out / "metrics.json").write_text("old")
    with pytest.raises(UserError):
        with output_folder(tmp_path / "out", force=True):
            raise UserError("--frames", "bad")
    assert _files(tmp_path / "out") == {"metrics.json": "old"} and sorted(p.name for p in tmp_path.iterdir()) == ["out"]


# --- the outputs a command names, checked before any work ----------------------------------------


def _refusal(call, *args, **kwargs) -> str:
    with pytest.raises(UserError) as caught:
        call(*args, **kwargs)
    (line,) = caught.value.lines()
    return line


def test_an_output_that_is_an_input_or_lies_inside_one_is_refused(tmp_path: Path):
    rec = tmp_path / "rec"
    rec.mkdir()
    assert _refusal(check_output, rec, "--out", [rec], folder=True) == f"{rec}: --out: is also an input; --out must name a new folder"
    inside = rec / "model.safetensors"
    assert (
        _refusal(check_output, inside, "--out", [rec])
        == f"{inside}: --out: lies inside the input {rec}; --out must name a place outside it"
    )
    check_output(tmp_path / "model.safetensors", "--out", [rec, tmp_path / "not_there"])  # beside it, and an input that does not exist


def test_an_output_of_the_wrong_kind_or_one_that_exists_without_force_is_refused(tmp_path: Path):
    file, folder = tmp_path / "a.png", tmp_path / "dir"
    file.write_bytes(b"x")
    folder.mkdir()
    assert "exists and is a file; expected a folder" in _refusal(check_output, file, "--out", folder=True)
    assert "exists and is a folder; expected a file name" in _refusal(check_output, folder, "--out")
    assert "exists; choose another --preview, or pass --force" in _refusal(check_output, file, "--preview", force=False)
    check_output(file, "--out", force=True)
    check_output(file, "--out")  # force not given: the command replaces the file by its own rule
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    assert _refusal(check_output, fifo, "--out") == f"{fifo}: --out: is a FIFO; --out must name a regular file"


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux's /proc")
def test_an_output_where_no_file_can_be_made_is_refused():
    # /proc takes no new file, not even root's: permissions alone would not say so.
    out = Path("/proc/terrapref-not-a-process/a.png")
    assert _refusal(check_output, out, "--out").startswith(f"{out}: --out: cannot be written (no file can be made in /proc: ")


def test_a_figure_needs_a_suffix_the_plotting_library_writes():
    for suffix in FIGURE_FORMATS:
        check_figure(f"map{suffix.upper()}", "--out")
    assert _refusal(check_figure, "map.txt", "--out") == f"map.txt: --out: a figure needs one of the suffixes {', '.join(FIGURE_FORMATS)}"


def test_an_input_given_twice_is_refused_by_either_name(tmp_path: Path):
    rec = tmp_path / "rec"
    rec.mkdir()
    check_distinct([rec, tmp_path / "other", "gen:1"], "recording")
    assert _refusal(check_distinct, [rec, rec], "recording") == f"{rec}: is given twice; give each recording once"
    alias = tmp_path / "link"
    alias.symlink_to(rec)
    assert _refusal(check_distinct, [rec, alias], "recording") == f"{alias}: is given twice (the same as {rec}); give each recording once"


# --- a command killed (kill -9) at any step of a replacement, then the next command -----------------


@pytest.fixture(scope="module")
def killer():
    """tests/killed_steps.py as a process of its own: ``killer(case, work, step)`` runs ``case``
    in ``work``, killed before its ``step``-th change on disk; whether the kill came."""
    import subprocess
    import sys

    import terrapref

    src = str(Path(terrapref.__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([src, os.environ.get("PYTHONPATH", "")])}
    driver = subprocess.Popen(
        [sys.executable, str(Path(__file__).with_name("killed_steps.py"))],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env=env,
    )

    def run(case: str, work: Path, step: int) -> bool:
        driver.stdin.write(f"{case}\t{work}\t{step}\n")
        driver.stdin.flush()
        answer = driver.stdout.readline().strip()
        assert answer in ("killed", "ended"), f"the driver said {answer!r}"
        return answer == "killed"

    yield run
    driver.stdin.close()
    driver.wait()


def _visible(work: Path) -> dict[str, dict[str, str]]:
    """What a user sees in ``work``: each folder that is not hidden and holds files, with its files."""
    return {p.name: _files(p) for p in sorted(work.iterdir()) if not p.name.startswith(".") and _files(p)}


@pytest.mark.parametrize("case", ["replace", "first run", "replace, failing", "swap"])
def test_a_command_killed_at_any_step_loses_nothing_and_the_next_one_puts_it_right(tmp_path: Path, capsys, killer, case: str):
    """`kill -9` at each change on disk of a command replacing a folder (writing it in place with
    --force, the first run into it, undoing a run stopped by Ctrl-C, swapping a finished one in),
    then the next command's check of an output beside it: the output is whole (the old one, or the
    new one once complete), an unfinished run is only ever OUT.partial, and what was put right is
    said in one line."""
    from killed_steps import NEW, OLD, write

    seen = set()
    for step in range(1, 100):
        work = tmp_path / str(step)
        work.mkdir()
        out = work / "ev"
        if case != "first run":
            write(out, OLD)
        killed = killer(case, work, step)
        before = _visible(work)
        check_output(work / "map.png", "--out")  # the first step of any command writing beside it
        notes = capsys.readouterr().err.splitlines()
        after = _visible(work)
        assert set(after) <= {"ev", "ev.partial"}, after
        assert [p.name for p in work.iterdir() if p.name.startswith(".")] in ([], [".ev.new"])  # (the swap not begun)
        assert after.get("ev") in ((OLD, NEW) if case != "first run" else (None, NEW)), (step, after)
        assert after.get("ev.partial", {}).items() <= NEW.items()
        assert len(notes) == (before != after) and all(str(out) in n for n in notes), (step, notes)
        if case == "replace, failing":
            assert after["ev"] == OLD
        seen.add("new" if after.get("ev") == NEW else "old")
        if not killed:
            break
    assert step > 5 and seen == ({"old"} if case == "replace, failing" else {"old", "new"})


def test_any_command_writing_beside_a_killed_replacement_first_puts_the_old_output_back(tmp_path: Path, capsys):
    """What `kill -9` leaves in the middle of `evaluate --out ev --force`: the unfinished run at ev,
    the old one in its journal. The next command writing beside it (an import that is then
    refused) puts the old one back first, says so, and keeps the unfinished one as ev.partial."""
    from killed_steps import OLD, write
    from terrapref.cli import main

    write(tmp_path / ".ev.k1ll3d00.replacing" / "old", OLD)
    write(tmp_path / "ev", {"metrics.json": "new"})
    assert main(["import", str(tmp_path / "drive.bag"), "--robot", str(tmp_path / "robot.yaml"), "--out", str(tmp_path / "rec")]) == 2
    note, error = capsys.readouterr().err.splitlines()
    ev = tmp_path / "ev"
    assert note == f"note: {ev}: put back the output a stopped command was replacing; its unfinished one is in {ev}.partial"
    assert error.startswith(f"error: {tmp_path / 'robot.yaml'}")
    assert _visible(tmp_path) == {"ev": OLD, "ev.partial": {"metrics.json": "new"}}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ev", "ev.partial"]


def test_a_killed_commands_scratch_folder_is_removed_by_the_next_command_and_a_held_one_is_not(tmp_path, capsys):
    from terrapref.fileio import release_folder

    left = new_folder(tmp_path / "run.mcap", ".writing")
    (left / "run.bag").write_bytes(b"x" * 1000)
    release_folder(left, remove=False)  # as a kill leaves it: nobody holds it
    held = new_folder(tmp_path / "rec", ".importing")  # a command still writing it
    mine = tmp_path / ".cache.abcdefgh"  # a user's own folder of the same shape, without the mark
    mine.mkdir()
    check_output(tmp_path / "other.mcap", "--out")
    assert not left.exists() and held.is_dir() and mine.is_dir()
    assert f"note: {tmp_path / 'run.mcap'}: removed {left.name}, what a stopped command left unfinished" in capsys.readouterr().err
    release_folder(held)
    assert not held.exists()


def test_a_scratch_folder_its_command_removes_while_the_next_looks_is_passed_over(tmp_path, monkeypatch, capsys):
    """A stopped ``record --force`` removes its own folder as it lets go of it; the next command,
    listing the folders beside its output at that moment, finds it gone when it goes to lock it:
    that is no error (it once ended a ``record --force`` with "No such file or directory")."""
    import terrapref.fileio as fileio

    going = new_folder(tmp_path / "rec", ".new")
    lock = fileio._lock

    def removed_first(path):
        if path == going:  # its command's rmtree wins the race
            fileio.release_folder(going)
        return lock(path)

    monkeypatch.setattr(fileio, "_lock", removed_first)
    check_output(tmp_path / "rec", "--out", folder=True)
    assert not going.exists() and "error" not in capsys.readouterr().err
