"""`terrapref info` and `terrapref --version`."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from helpers import dataset_file, linear_model, model_meta, skip_path_weights
from terrapref import __version__
from terrapref.cli import main
from terrapref.learning.header import FORMAT as MODEL_FORMAT
from terrapref.learning.model_file import save_model
from terrapref.learning.network import ClassifierConfig
from terrapref.tensorfile import write_tensor_file


def test_version(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0 and capsys.readouterr().out.strip() == f"terrapref {__version__}"


def test_info_on_a_model_a_dataset_an_onnx_file_and_a_recording(tmp_path: Path, capsys, tiny_recording):
    model = linear_model(tmp_path / "m.safetensors")
    data = dataset_file(tmp_path / "d.safetensors")
    assert main(["export", str(model), "--format", "onnx", "--out", str(tmp_path / "m.onnx")]) == 0
    capsys.readouterr()
    assert main(["info", str(model), str(data), str(tmp_path / "m.onnx"), str(tiny_recording)]) == 0
    out = capsys.readouterr().out
    assert "terrapref model" in out and "terrapref dataset" in out and "exported as ONNX" in out and "terrapref recording (complete)" in out
    assert out.count("camera          640x480") == 4 and "profile         mud > rock > water > non_traversable" in out
    assert "samples         300" in out and "driver          expert" in out
    # the linear model lists no rule: C's argmax drives, and the graph is that decision
    assert (
        out.count("steers          argmax\nsets the speed  none (the control set's speed)\n") == 2 and "the graph holds C alone" not in out
    )


@pytest.mark.parametrize("content", [b"", b"not safetensors at all", b"\x00" * 64])
def test_info_on_a_foreign_file_is_one_line(tmp_path: Path, capsys, content: bytes):
    path = tmp_path / "x.safetensors"
    path.write_bytes(content)
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0] and "internal error" not in err[0]


def test_info_and_evaluate_on_a_model_cut_short_say_it_is_truncated(tmp_path: Path, capsys):
    """A file that begins as a safetensors file but was cut short is said to be truncated, with
    the bytes its header promises, and the tensor lost named; a file that is none keeps the
    general line."""
    import struct

    model = linear_model(tmp_path / "m.safetensors")
    raw = model.read_bytes()
    n = struct.unpack("<Q", raw[:8])[0]
    cut = tmp_path / "cut.safetensors"
    cut.write_bytes(raw[:-4])
    said = f"{cut}: truncated: the header promises {len(raw)} bytes, the file has {len(raw) - 4}; tensor "
    for argv in (["info", str(cut)], ["evaluate", str(cut), "gen:7", "--seeds", "1", "--out", str(tmp_path / "ev")]):
        assert main(argv) == 2
        err = capsys.readouterr().err.splitlines()
        assert len(err) == 1 and err[0].startswith(f"error: {said}") and err[0].endswith(" is cut short"), err
    assert not (tmp_path / "ev").exists()
    half = tmp_path / "half.safetensors"
    half.write_bytes(raw[: 8 + n // 2])
    assert main(["info", str(half)]) == 2
    cut_header = f"truncated: the header promises at least {8 + n} bytes, the file has {8 + n // 2} (the header itself is cut short)"
    assert capsys.readouterr().err.splitlines() == [f"error: {half}: {cut_header}"]
    foreign = tmp_path / "x.safetensors"
    foreign.write_bytes(b"not safetensors at all")
    assert main(["info", str(foreign)]) == 2
    assert capsys.readouterr().err.splitlines() == [f"error: {foreign}: not a terrapref recording, dataset, model or ONNX file"]


def test_info_gives_every_ensemble_members_chosen_epoch(tmp_path: Path, capsys):
    data = dataset_file(tmp_path / "d.safetensors")
    model = tmp_path / "m.safetensors"
    assert main(["train", str(data), "--out", str(model), "--recipe", "paper", "--epochs", "2", "--members", "2"]) == 0
    capsys.readouterr()
    assert main(["info", str(model)]) == 0
    lines = capsys.readouterr().out.splitlines()
    first = next(i for i, line in enumerate(lines) if line.startswith("training "))
    assert lines[first].startswith("training        member 1: 2 epochs, chose epoch ")
    assert lines[first + 1].startswith("                member 2: 2 epochs, chose epoch ")


def test_info_reads_older_stage_blocks_and_shows_what_it_can_of_a_damaged_list(tmp_path: Path, capsys):
    config = ClassifierConfig(hidden=8, skip=True)
    old = save_model(
        tmp_path / "old.safetensors", config, skip_path_weights(config), {**model_meta(), "utility": {"w": [0.0] * 5, "b": [0.0] * 21}}
    )
    bad = save_model(tmp_path / "bad.safetensors", config, skip_path_weights(config), {**model_meta(), "stages": "offset"})
    assert main(["info", str(bad), str(old)]) == 2  # a file no command can use; the others are still shown
    out = capsys.readouterr().out
    # a utility block written before rules were listed: the second stage, which drives
    assert (
        "steers          second_stage\nsets the speed  none (the control set's speed)\n  second stage: weight 1.5, linear utility fitted frame by frame\n"
        in out
    )
    assert "rules           unreadable (stages: expected a list of rules)" in out and "profile         mud > rock" in out


def _diverged_model(path: Path) -> Path:
    """C's file with one NaN weight, as a diverged fit would have written it (training refuses to)."""
    config = ClassifierConfig(hidden=8, skip=True)
    weights = skip_path_weights(config)
    weights["compress.weight"][0, 3] = np.nan
    write_tensor_file(path, weights, {"format": MODEL_FORMAT, "kind": "classifier", "classifier": config.to_dict(), **model_meta()})
    return path


def test_info_on_a_model_of_nan_weights_shows_it_not_readable_and_exits_2(tmp_path: Path, capsys):
    path = _diverged_model(tmp_path / "diverged.safetensors")
    assert main(["info", str(path)]) == 2
    captured = capsys.readouterr()
    shown = f"{path}: terrapref model (classifier), NOT READABLE: weights.compress.weight: 1 of its 5 weights are NaN or infinite"
    assert shown in captured.out and "profile         mud > rock" in captured.out  # what its header still says
    assert captured.err.splitlines() == [f"error: {path}: weights.compress.weight: 1 of its 5 weights are NaN or infinite"]


@pytest.mark.parametrize(("profile", "shown"), [([1, 2], "(unreadable)"), (["mud", "mud", "water", "non_traversable"], "(unreadable)")])
def test_info_on_a_model_whose_profile_is_damaged_shows_it_not_readable_and_exits_2(tmp_path: Path, capsys, profile, shown):
    config = ClassifierConfig(hidden=8, skip=True)
    path = tmp_path / "m.safetensors"
    meta = {"format": MODEL_FORMAT, "kind": "classifier", "classifier": config.to_dict(), **model_meta(), "profile": profile}
    write_tensor_file(path, skip_path_weights(config), meta)
    assert main(["info", str(path)]) == 2
    captured = capsys.readouterr()
    assert f"{path}: terrapref model (classifier), NOT READABLE: profile: " in captured.out
    assert f"profile         {shown}" in captured.out and "internal error" not in captured.err


def test_info_flags_a_speed_rule_faster_than_the_vehicle(tmp_path: Path, capsys):
    from test_runtime import _model

    assert main(["info", str(_model(tmp_path, 8.0, top_mps=8.0))]) == 0
    out = capsys.readouterr().out
    assert "WARNING: its speed rule goes up to 8 m/s, above the default vehicle's 2 m/s" in out
    assert main(["info", str(_model(tmp_path, 1.6))]) == 0
    assert "WARNING" not in capsys.readouterr().out
