"""A recording cut short (Ctrl-C) is used as far as it goes by every command that reads one, and
each says so in the same warning line: featurize, train and course --after."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from terrapref.cli import main
from terrapref.demos.recording import read_recording
from terrapref.errors import UserError


def _partial_copy(recording: Path, folder: Path) -> Path:
    """A copy of ``recording`` as a recorder stopped by Ctrl-C leaves it (meta.json's status partial)."""
    out = folder / "cut"
    shutil.copytree(recording, out)
    meta = json.loads((out / "meta.json").read_text())
    meta["status"] = "partial"
    meta.pop("frames", None)
    (out / "meta.json").write_text(json.dumps(meta))
    return out


@pytest.mark.parametrize("command", ["featurize", "train", "course --after"])
def test_every_command_reading_a_partial_recording_says_so(tiny_recording, tmp_path, capsys, monkeypatch, command):
    import terrapref.learning.pipeline as pipeline
    import terrapref.recipes as recipes
    from terrapref.learning.identify import FollowUp

    def trained(*args, **kwargs):
        raise UserError("train_and_save", "reached")  # the warning is what is asked, not a model

    monkeypatch.setattr(pipeline, "train_and_save", trained)
    monkeypatch.setattr(recipes, "follow_up_plan", lambda *args, **kwargs: FollowUp())  # nothing left open: nothing written
    rec = _partial_copy(tiny_recording, tmp_path)
    frames = len(read_recording(rec))
    argv = {
        "featurize": ["featurize", str(rec), "--out", str(tmp_path / "d.safetensors")],
        "train": ["train", str(rec), "--out", str(tmp_path / "m.safetensors")],
        "course --after": ["course", "--after", str(rec), "--out", str(tmp_path / "more.yaml")],
    }[command]
    main(argv)
    warnings = [line for line in capsys.readouterr().err.splitlines() if line.startswith("warning:")]
    assert warnings == [f"warning: {rec} is partial; using its {frames} frames"]
