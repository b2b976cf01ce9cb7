"""The `train` command: model, loss curve and checkpoints written; ensembles, the second stage,
several datasets; bad data and hyperparameters refused in one line."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from helpers import dataset_file, linear_model, model_meta, one_line_error
from terrapref.cli import main
from terrapref.dataset import FORMAT as DATASET_FORMAT
from terrapref.dataset import Dataset, save_dataset
from terrapref.learning.model_file import load_model

PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def model_path(tmp_path_factory) -> Path:
    return linear_model(tmp_path_factory.mktemp("model") / "linear.safetensors")


def test_cli_train_writes_model_curve_and_checkpoints(tmp_path: Path, capsys):
    data = dataset_file(tmp_path / "data.safetensors")
    out = tmp_path / "models" / "pref.safetensors"
    rc = main(
        [
            "train",
            str(data),
            "--out",
            str(out),
            "--epochs",
            "3",
            "--skip",
            "--class-balance",
            "--hidden",
            "16",
            "--seed",
            "2",
            "--members",
            "1",
            "--no-mirror",
            "--stage-weight",
            "2.5",
        ]
    )
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    model = load_model(out)
    assert model.classifier.skip and model.classifier.hidden == 16
    training = model.meta["training"]
    assert training["optimiser"]["epochs"] == 3 and training["data"]["class_balance"] and training["seed"] == 2
    # Flags override the recipe's value field by field; the rest is the recipe's (teach: mirrored samples, the second stage;
    # its offset rule reads what this dataset lacks, and is left out with a warning).
    blocks = model.meta["rules"]
    assert not training["data"]["mirror"] and [s["type"] for s in blocks] == ["second_stage"] and blocks[0]["weight"] == 2.5
    assert model.meta["drives"] == "second_stage" and "carries no data for the offset rule" in captured.err
    assert "sets_speed" not in model.meta  # no speed rule: the control set's speed
    curve = tmp_path / "models" / "pref.loss.png"
    assert curve.read_bytes().startswith(PNG)
    folder = tmp_path / "models" / "pref.checkpoints"
    assert sorted(p.name for p in folder.iterdir()) == [f"epoch_{i:03d}.safetensors" for i in (1, 2, 3)]
    epoch_lines = [
        line for line in captured.out.splitlines() if re.fullmatch(r"\s*\d+(\s+\d+\.\d+){5}\s+\d.* s( left)?", line)
    ]  # with the time so far (and left)
    assert [int(line.split()[0]) for line in epoch_lines] == [1, 2, 3]
    # Each line is the history the model file records.
    for line, h in zip(epoch_lines, model.meta["history"], strict=True):
        assert float(line.split()[2]) == pytest.approx(h["val_loss"], abs=1e-4)
    last = captured.out.strip().splitlines()[-1]
    assert last.startswith(f"wrote {out}") and str(curve) in last and str(folder) in last
    assert f"epoch {model.meta['best_epoch']}" in last


def test_a_featurized_recording_trains_as_the_recording_does(tmp_path: Path, capsys):
    """featurize then train (the default recipe, its speed rule's class ids included) fits the rules that training on the recording fits."""
    course = tmp_path / "course.yaml"
    course.write_text(
        "format: terrapref-scenario/1\nname: mud_across\nworld: {size_m: [10.0, 6.0], resolution_m: 0.05, background: grass}\n"
        "terrain: [{class: mud, rectangle: {center: [6.0, 3.0], size: [1.5, 6.0]}}]\npath: {waypoints: [[1.0, 3.0], [9.0, 3.0]]}\n"
    )
    rec, data = tmp_path / "rec", tmp_path / "d.safetensors"
    assert main(["record", str(course), "--out", str(rec), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["featurize", str(rec), "--out", str(data)]) == 0
    progress = [line for line in capsys.readouterr().err.splitlines() if line.startswith("featurize: ")]
    assert len(progress) > 2 and "frames of 1 recording" in progress[1]  # frame by frame, not only once the recording is done
    for source, out in ((data, tmp_path / "from_data.safetensors"), (rec, tmp_path / "from_rec.safetensors")):
        rc = main(["train", str(source), "--out", str(out), "--epochs", "1", "--members", "1"])
        assert rc == 0, capsys.readouterr().err
    from_data, from_rec = load_model(tmp_path / "from_data.safetensors"), load_model(tmp_path / "from_rec.safetensors")
    assert [b["type"] for b in from_data.meta["rules"]] == ["second_stage", "offset", "speed"]
    assert from_data.meta["rules"] == from_rec.meta["rules"]
    # One drive under two names (the recording beside its dataset, or a copy of it) would count twice: refused.
    import shutil

    shutil.copytree(rec, tmp_path / "copy")
    capsys.readouterr()
    for inputs, second, first in ((data, rec, "(in "), (rec, tmp_path / "copy", str(rec))):
        assert main(["train", str(inputs), str(second), "--out", str(tmp_path / "twice.safetensors"), "--epochs", "1"]) == 2
        error = capsys.readouterr().err.strip().splitlines()[-1]  # after the featurising's progress
        assert error.startswith("error: ") and "holds the same drive as" in error and first in error and "Traceback" not in error
    assert main(["featurize", str(rec), str(tmp_path / "copy"), "--out", str(tmp_path / "d2.safetensors")]) == 2
    error = capsys.readouterr().err.strip().splitlines()[-1]
    assert error.startswith(f"error: {tmp_path / 'copy'}: frames: holds the same drive as {rec}")
    assert not (tmp_path / "twice.safetensors").exists() and not (tmp_path / "d2.safetensors").exists()


def test_cli_train_on_two_dataset_files(tmp_path: Path, capsys):
    a, b = dataset_file(tmp_path / "a.safetensors", 120, 0), dataset_file(tmp_path / "b.safetensors", 80, 1)
    out = tmp_path / "m.safetensors"
    assert main(["train", str(a), str(b), "--out", str(out), "--epochs", "1"]) == 0
    assert load_model(out).meta["data"]["samples"] == 200
    assert "training on 200 samples (2 input(s))" in capsys.readouterr().out


def test_cli_train_members_writes_an_ensemble(tmp_path: Path, capsys):
    data = dataset_file(tmp_path / "data.safetensors", 200)
    out = tmp_path / "ens.safetensors"
    assert main(["train", str(data), "--out", str(out), "--epochs", "2", "--hidden", "8", "--members", "2", "--seed", "4"]) == 0
    text = capsys.readouterr().out
    assert "2 members" in text and "member 1/2" in text and "member 2/2" in text
    model = load_model(out)
    assert model.classifier.members == 2 and [m["seed"] for m in model.meta["members"]] == [4, 1004]
    summary = next(line for line in text.splitlines() if line.startswith("wrote "))
    for j, member in enumerate(model.meta["members"], start=1):  # each member's own chosen epoch
        best = member["history"][member["best_epoch"] - 1]
        assert f"member {j} epoch {member['best_epoch']}: val loss {best['val_loss']:.4f}" in summary
    assert len(list((tmp_path / "ens.checkpoints").iterdir())) == 2


def test_cli_train_second_stage_stores_the_fitted_utility(tmp_path: Path, capsys):
    data = dataset_file(tmp_path / "data.safetensors", 200)
    out = tmp_path / "m.safetensors"
    assert main(["train", str(data), "--out", str(out), "--epochs", "1", "--mirror", "--second-stage"]) == 0
    model = load_model(out)
    (stage,) = [s for s in model.meta["rules"] if s["type"] == "second_stage"]
    assert stage["weight"] == 5.0 and len(stage["w"]) == 5 and len(stage["b"]) == 21


@pytest.mark.parametrize("features", [{"lane_m": 6.0, "lane_points": 12}, {"near_m": 2.0}], ids=["lanes", "near"])
def test_cli_train_refuses_a_dataset_with_columns_that_left_in_one_line(tmp_path: Path, capsys, features: dict):
    """Columns that lost their experiment (lanes, a near distance) left the code: a dataset featurised with them is refused."""
    rng = np.random.default_rng(0)
    meta = {"format": DATASET_FORMAT, **model_meta()}
    meta["features"] = {**meta["features"], **features}
    n = 50
    data = save_dataset(
        Dataset(
            rng.uniform(0, 1, (n, 21, 6)).astype(np.float32), rng.integers(0, 21, n), np.zeros(n, np.float32), np.zeros(n, np.int64), meta
        ),
        tmp_path / "old.safetensors",
    )
    out = tmp_path / "m.safetensors"
    assert main(["train", str(data), "--out", str(out), "--epochs", "1"]) == 2
    assert "no longer supported" in one_line_error(capsys, str(data))
    assert not out.exists()


def test_cli_train_missing_dataset(tmp_path: Path, capsys):
    missing = tmp_path / "absent.safetensors"
    assert main(["train", str(missing), "--out", str(tmp_path / "m.safetensors")]) == 2
    one_line_error(capsys, str(missing))
    assert not (tmp_path / "m.safetensors").exists()


def test_cli_train_refuses_a_model_file_as_data(model_path: Path, tmp_path: Path, capsys):
    assert main(["train", str(model_path), "--out", str(tmp_path / "m.safetensors")]) == 2
    one_line_error(capsys, str(model_path))


@pytest.mark.parametrize(
    "flag", [["--epochs", "0"], ["--batch-size", "0"], ["--hidden", "0"], ["--lr", "-1"], ["--members", "0"]], ids=lambda f: f[0]
)
def test_cli_train_bad_hyperparameter_is_a_user_error(tmp_path: Path, capsys, flag: list[str]):
    data = dataset_file(tmp_path / "data.safetensors", 50)
    assert main(["train", str(data), "--out", str(tmp_path / "m.safetensors"), *flag]) == 2
    line = one_line_error(capsys)
    assert re.search(flag[0].lstrip("-").replace("-", "[-_]"), line), line  # names the flag or the field


# --- errors raised in worker processes ------------------------------------------------------------


def test_train_prints_the_time_left_with_its_epochs(monkeypatch, capsys):
    import time
    from types import SimpleNamespace

    from terrapref.cli.train import _epoch_printer

    clock = iter(float(t) for t in range(0, 1000, 10))  # each reading of the clock 10 s after the last
    monkeypatch.setattr(time, "perf_counter", lambda: next(clock))
    config = SimpleNamespace(classifier=SimpleNamespace(members=2), optimiser=SimpleNamespace(epochs=10))
    show = _epoch_printer(config, verbose=False)
    for _member in range(2):
        for epoch in range(1, 11):
            show(SimpleNamespace(epoch=epoch, train_loss=1.0, val_loss=1.0, train_acc=0.5, val_acc=0.5, val_top3=0.8))
    rows = [line for line in capsys.readouterr().out.splitlines() if line.lstrip()[:1].isdigit()]
    assert rows[0].endswith("10 s, about 3 min 10 s left")  # 1 of 20 epochs in 10 s: 19 more at that pace
    assert rows[-1].endswith("3 min 20 s")  # done: no estimate
