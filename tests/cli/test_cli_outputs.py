"""Outputs are checked before any work: never an input, never the wrong kind, always writable."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from helpers import dataset_file, linear_model
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


def test_train_and_featurize_name_their_output_safetensors(tmp_path: Path, capsys):
    data = dataset_file(tmp_path / "train.safetensors")
    assert main(["train", str(data), "--out", str(tmp_path / "m.txt"), "--epochs", "1"]) == 2
    assert "m.txt: --out: a model or dataset is a safetensors file: give it the suffix .safetensors" in _error(capsys)
    assert main(["featurize", str(data), "--out", str(tmp_path / "d")]) == 2
    assert "give it the suffix .safetensors" in _error(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["train.safetensors"]


def test_train_says_an_input_is_missing_before_what_lies_where_it_would_write(tmp_path: Path, capsys):
    (tmp_path / "m.loss.png").write_bytes(b"an earlier curve")
    assert main(["train", str(tmp_path / "nosuch"), "--out", str(tmp_path / "m.safetensors")]) == 2
    assert "nosuch: no such file" in _error(capsys)


def test_a_training_beside_what_an_interrupted_one_left_keeps_it_and_says_so(tmp_path: Path, capsys):
    data = dataset_file(tmp_path / "train.safetensors", n=64)
    left = [tmp_path / "m.interrupted.safetensors", tmp_path / "m.checkpoints.interrupted"]
    left[0].write_bytes(b"the best epochs of a stopped run")
    left[1].mkdir()
    capsys.readouterr()
    assert main(["train", str(data), "--recipe", "paper", "--epochs", "1", "--out", str(tmp_path / "m.safetensors")]) == 0
    assert f"note: {left[0]} and {left[1]}: left by an earlier run that was interrupted; kept" in capsys.readouterr().out
    assert all(p.exists() for p in left)


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
    silent = [
        f"{name} {a.dest}" for name, sub in commands.items() for a in sub._actions if not isinstance(a, argparse._HelpAction) and not a.help
    ]
    assert not silent, silent


@pytest.mark.parametrize(
    ("flag", "why"),
    [
        ("--out", "class ids need a lossless format"),
        ("--preview", "its one format for the colour preview"),
        ("--depth", "millimetres need a lossless 16-bit format"),
    ],
)
def test_render_refuses_a_lossy_image_name_before_writing(tmp_path: Path, capsys, flag: str, why: str):
    outputs = {"--out": tmp_path / "seg.png", "--preview": tmp_path / "view.png", "--depth": tmp_path / "depth.png"}
    outputs[flag] = tmp_path / "seg.jpg"
    assert main(["render", "demo_course", *(a for f, p in outputs.items() for a in (f, str(p)))]) == 2
    assert _error(capsys) == f"error: {tmp_path / 'seg.jpg'}: {flag}: render writes PNG ({why}): give it the suffix .png"
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("flags", [("--out", "--depth"), ("--out", "--preview"), ("--preview", "--depth")])
def test_render_refuses_two_outputs_that_name_one_file_before_writing(tmp_path: Path, capsys, flags: tuple[str, str]):
    """Written one after the other, the second would replace the first: the class ids lost."""
    outputs = {"--out": tmp_path / "seg.png", "--preview": tmp_path / "view.png", "--depth": tmp_path / "depth.png"}
    outputs[flags[1]] = outputs[flags[0]]
    argv = [arg for flag, path in outputs.items() for arg in (flag, str(path))]
    assert main(["render", "relief_demo", *argv]) == 2
    same = outputs[flags[0]]
    assert _error(capsys) == f"error: {same}: {flags[1]}: is also {flags[0]}'s file; {flags[1]} must name a file of its own"
    assert list(tmp_path.iterdir()) == []


def test_export_onnx_of_a_recording_says_which_format_a_recording_takes(tmp_path: Path, capsys):
    (tmp_path / "rec").mkdir()
    assert main(["export", str(tmp_path / "rec"), "--format", "onnx", "--out", str(tmp_path / "m.onnx")]) == 2
    error = _error(capsys)
    assert error.startswith(f"error: {tmp_path / 'rec'}: --format: is a recording folder") and "--format mcap or rosbag1" in error


def test_every_flag_with_a_default_names_it_in_its_help():
    import argparse

    from terrapref.cli import build_parser

    parser = build_parser(train_flags=True)
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices
    unnamed = [
        f"{name} {a.option_strings[0]}={a.default!r}"
        for name, sub in commands.items()
        for a in sub._actions
        if a.option_strings and a.default not in (None, False, argparse.SUPPRESS) and "default" not in (a.help or "")
    ]
    assert not unnamed, unnamed  # select --help once gave none of its five


def test_time_left_is_estimated_from_the_pace_so_far():
    from terrapref.progress import duration_text, time_left

    assert time_left(10.0, 0.25) == "10 s, about 30 s left"
    assert time_left(90.0, 0.5) == "1 min 30 s, about 1 min 30 s left"
    assert time_left(0.5, 0.5) == "0 s" and time_left(30.0, 0.01) == "30 s"  # too early to tell
    assert time_left(12.0, 1.0) == "12 s" and duration_text(4000) == "1 h 6 min"


@pytest.mark.slow  # a whole drive or export end to end, its steps tested apart in the default run
def test_long_jobs_report_what_they_have_done_and_the_time_left(tiny_recording: Path, tmp_path: Path, capsys):
    assert main(["course", "--after", str(tiny_recording), "--out", str(tmp_path / "more.yaml")]) == 0
    lines = capsys.readouterr().err.splitlines()
    frames = len((tiny_recording / "frames.jsonl").read_text().splitlines())
    ticks = [line for line in lines if line.startswith("featurising the drive to find the pairs left open:") and "% " in line]
    assert len(ticks) >= 10 and f"{frames}/{frames} frames" in ticks[-1]  # a line per tenth of the frames, not one at the end
    assert all(line.rstrip().endswith(")") for line in ticks)  # each with the time so far (and what is left, once it can be told)
