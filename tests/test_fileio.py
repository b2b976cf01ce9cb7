"""Atomic writes: unique temporary names, nothing half-written, modes that follow the umask."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import numpy as np
import pytest

from terrapref.fileio import atomic_path, new_folder, write_bytes_atomic, write_text_atomic
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
