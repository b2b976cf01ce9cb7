"""Outputs are checked before any work: never an input, never the wrong kind, always writable."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from helpers import linear_model
from helpers import dataset_file

from terrapref.cli import main


def _error(capsys) -> str:
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error:")]
    assert len(err) == 1, err
    return err[0]


def test_train_refuses_to_overwrite_its_own_input(tmp_path: Path, capsys):
    data = dataset_file(tmp_path / "train.safetensors")
    before = data.read_bytes()
    assert main(["train", str(data), "--out", str(data), "--epochs", "1"]) == 2
    assert "is also an input" in _error(capsys) and data.read_bytes() == before


def test_train_refuses_a_folder_as_its_model_file(tmp_path: Path, capsys):
    data = dataset_file(tmp_path / "train.safetensors")
    (tmp_path / "models").mkdir()
    assert main(["train", str(data), "--out", str(tmp_path / "models"), "--epochs", "1"]) == 2
    assert "expected a file name" in _error(capsys)


def test_evaluate_refuses_a_file_as_its_folder_before_driving(tmp_path: Path, capsys):
    model = linear_model(tmp_path / "m.safetensors")
    (tmp_path / "eval").write_text("not a folder")
    assert main(["evaluate", str(model), "demo_course", "--seeds", "1", "--out", str(tmp_path / "eval")]) == 2
    assert "expected a folder" in _error(capsys) and (tmp_path / "eval").read_text() == "not a folder"
    assert main(["evaluate", str(model), "demo_course", "--seeds", "1", "--out", str(model)]) == 2
    assert "is also an input" in _error(capsys)


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write anywhere")
def test_an_unwritable_output_is_refused_before_training(tmp_path: Path, capsys):
    data = dataset_file(tmp_path / "train.safetensors")
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        assert main(["train", str(data), "--out", str(locked / "m.safetensors"), "--epochs", "1"]) == 2
        assert "cannot be written" in _error(capsys)
    finally:
        locked.chmod(0o755)


def test_an_output_that_no_file_can_be_made_beside_is_refused_before_training(tmp_path: Path, capsys):
    # Checked by making a file there, not from permission bits, so it holds for root too.
    data = dataset_file(tmp_path / "train.safetensors")
    (tmp_path / "notes.txt").write_text("a file where a folder would be")
    assert main(["train", str(data), "--out", str(tmp_path / "notes.txt" / "m.safetensors"), "--epochs", "1"]) == 2
    error = _error(capsys)
    assert "cannot be written (no file can be made in" in error and "notes.txt" in error
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt", "train.safetensors"]


def test_every_argument_of_every_command_says_what_it_is():
    import argparse

    from terrapref.cli import build_parser

    parser = build_parser(train_flags=True)
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices
    silent = [f"{name} {a.dest}" for name, sub in commands.items() for a in sub._actions
              if not isinstance(a, argparse._HelpAction) and not a.help]
    assert not silent, silent
