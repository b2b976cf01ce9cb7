"""Broken inputs a user can give: each is one error line naming the file or flag, exit 2,
never an internal error."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from terrapref.cli import main


@pytest.fixture(scope="module")
def recording(tiny_recording) -> Path:
    """An undisturbed recording of the tiny course (tests/conftest.py): copy it before changing it."""
    return tiny_recording


def _one_error(capsys, *needles: str) -> str:
    text = capsys.readouterr().err
    errors = [line for line in text.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, text
    assert "internal error" not in text and "Traceback" not in text
    assert all(n in errors[0] for n in needles), errors[0]
    return errors[0]


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["show", "gen:-1", "--out", "m.png"], "gen:-1"),
        (["record", "demo_course", "--seed", "-1", "--out", "r1"], "--seed"),
        (["show", "demo_course", "--out", "map.xyz"], "--out"),
        (["record", "demo_course", "--profile", "mud,rock,water", "--out", "r1"], "exactly once; 'non_traversable' is missing"),
        (["record", "gen:7", "--profile", "sand,mud,rock,water", "--out", "r1"], "(your own class table? give its --classes FILE)"),
    ],
)
def test_bad_flags(tmp_path: Path, capsys, monkeypatch, argv, needle):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    _one_error(capsys, needle)


@pytest.mark.parametrize(
    "flags,needle",
    [
        (["--n-steps", "-5"], "--n-steps"),
        (["--dt", "nan"], "--dt"),
        (["--n-steps", "5"], "--n-steps: the look-ahead starts 2.4 s"),  # the second stage's look-ahead past the trajectories
        (["--n-steps", "100000"], "--n-steps"),
        (["--dt", "0.01"], "--dt: the look-ahead"),
        (["--dt", "1e9"], "--dt: the look-ahead"),
    ],
)
def test_bad_featurize_flags(tmp_path: Path, capsys, recording, flags, needle):
    try:
        code = main(["featurize", str(recording), "--out", str(tmp_path / "d.safetensors"), *flags])
    except SystemExit as refused:  # the command line's parser refuses a number that is not finite
        code = refused.code
    assert code == 2
    _one_error(capsys, needle)
    assert not (tmp_path / "d.safetensors").exists()


def _damage(rec: Path, how: str) -> None:
    frames = rec / "frames.jsonl"
    lines = frames.read_text().splitlines()
    if how == "truncated":
        frames.write_text("\n".join(lines[:20]) + "\n")
    elif how == "reversed":
        frames.write_text("\n".join(reversed(lines)) + "\n")
    elif how == "nan pose":
        row = json.loads(lines[5])
        row["pose"][0] = float("nan")
        lines[5] = json.dumps(row)
        frames.write_text("\n".join(lines) + "\n")
    elif how == "empty":
        frames.write_text("")
        meta = json.loads((rec / "meta.json").read_text())
        meta.pop("frames", None)
        (rec / "meta.json").write_text(json.dumps(meta))
    elif how == "scenario list":
        (rec / "scenario.yaml").write_text("- a\n- b\n")
    elif how == "camera str":
        meta = json.loads((rec / "meta.json").read_text())
        meta["camera"] = "x"
        (rec / "meta.json").write_text(json.dumps(meta))
    elif how == "far pose":
        row = json.loads(lines[5])
        row["pose"] = [1e300, 1e300, 0.0]
        lines[5] = json.dumps(row)
        frames.write_text("\n".join(lines) + "\n")
    elif how == "unknown class in profile":
        meta = json.loads((rec / "meta.json").read_text())
        meta["profile"] = ["lava", *meta["profile"][1:]]
        (rec / "meta.json").write_text(json.dumps(meta))
    elif how == "nan steering grid":
        meta = json.loads((rec / "meta.json").read_text())
        meta["preference_set"]["control"]["w_rps"] = [float("nan")] * len(meta["preference_set"]["control"]["w_rps"])
        (rec / "meta.json").write_text(json.dumps(meta))
    elif how == "no profile":
        meta = json.loads((rec / "meta.json").read_text())
        meta.pop("profile")
        (rec / "meta.json").write_text(json.dumps(meta))
    elif how == "class 200":
        path = rec / "images" / "000003.png"
        image = np.asarray(Image.open(path)).copy()
        image[0, 0] = 200
        Image.fromarray(image).save(path)
    elif how == "rgb frame":
        Image.fromarray(np.zeros((480, 640, 3), np.uint8)).save(rec / "images" / "000003.png")
    elif how == "label 99":  # past the preference set's 21 trajectories: inspect's histogram would drop it unseen
        row = json.loads(lines[5])
        row["label"] = 99
        lines[5] = json.dumps(row)
        frames.write_text("\n".join(lines) + "\n")
    elif how == "small frame":
        Image.fromarray(np.zeros((48, 64), np.uint8)).save(rec / "images" / "000003.png")


@pytest.mark.parametrize(
    "how,needle",
    [
        ("truncated", "frames.jsonl"),
        ("reversed", "frames.jsonl"),
        ("nan pose", "line 6.pose"),
        ("far pose", "line 6.pose: expected x and y [m] and a heading [rad] within"),
        ("label 99", "line 6.label: 99 is not one of the preference set's 21 trajectories (0-20)"),
        ("unknown class in profile", "meta.json: profile: unknown or background class 'lava'"),
        ("nan steering grid", "preference_set"),
        ("empty", "frames.jsonl"),
        ("scenario list", "scenario.yaml"),
        ("camera str", "camera"),
        ("class 200", "000003.png"),
        ("rgb frame", "000003.png"),
        ("small frame", "000003.png"),
    ],
)
def test_a_broken_recording_is_refused_by_featurize(tmp_path: Path, capsys, recording, how, needle):
    rec = tmp_path / "rec"
    shutil.copytree(recording, rec)
    _damage(rec, how)
    assert main(["featurize", str(rec), "--out", str(tmp_path / "d.safetensors")]) == 2
    _one_error(capsys, needle)
    assert not (tmp_path / "d.safetensors").exists()


def test_inspect_finds_a_damaged_frame_before_it_replaces_the_figure(tmp_path: Path, capsys, recording):
    """``inspect --out F --force`` reads every frame for what the drive shows: a damaged one is one
    error line, and the figure already at F is left as it was."""
    rec = tmp_path / "rec"
    shutil.copytree(recording, rec)
    _damage(rec, "class 200")
    figure = tmp_path / "driven.png"
    figure.write_bytes(b"an earlier figure")
    assert main(["inspect", str(rec), "--out", str(figure), "--force"]) == 2
    _one_error(capsys, "000003.png")
    assert figure.read_bytes() == b"an earlier figure"


def test_a_recording_that_declares_no_order_is_featurized(tmp_path: Path, recording):
    """No ``profile`` in its metadata: a drive whose order nobody declared (a person's, a robot's log), not a broken file."""
    rec = tmp_path / "rec"
    shutil.copytree(recording, rec)
    _damage(rec, "no profile")
    assert main(["featurize", str(rec), "--out", str(tmp_path / "d.safetensors")]) == 0


def _dataset_with(tmp_path: Path, **change) -> Path:
    from helpers import model_meta
    from terrapref.dataset import FORMAT
    from terrapref.tensorfile import write_tensor_file

    rng = np.random.default_rng(0)
    n = 50
    tensors = {
        "U": rng.uniform(0, 1, (n, 21, 5)).astype(np.float32),
        "labels": rng.integers(0, 21, n),
        "w": np.zeros(n, np.float32),
        "source": np.zeros(n, np.int64),
    }
    tensors.update(change)
    return write_tensor_file(tmp_path / "d.safetensors", tensors, {"format": FORMAT, **model_meta()})


@pytest.mark.parametrize(
    "change,needle",
    [
        ({"U": np.full((50, 21, 5), np.nan, np.float32)}, "U:"),
        ({"U": np.zeros((50, 105), np.float32)}, "U:"),
        ({"labels": np.full(50, 30)}, "labels:"),
        ({"labels": np.zeros(49, np.int64)}, "labels:"),
        ({"w": np.full(50, np.inf, np.float32)}, "w:"),
        ({"labels": np.full(50, 10)}, "same label"),
        ({"U": np.full((50, 21, 3), 0.5, np.float32)}, "U: expected 21 trajectories x 5 features"),  # not what its features say
    ],
)
def test_a_broken_or_degenerate_dataset_is_refused_before_training(tmp_path: Path, capsys, change, needle):
    data = _dataset_with(tmp_path, **change)
    assert main(["train", str(data), "--out", str(tmp_path / "m.safetensors"), "--epochs", "1"]) == 2
    _one_error(capsys, str(data), needle)
    assert not (tmp_path / "m.safetensors").exists()


def test_a_model_with_nan_weights_is_refused(tmp_path: Path, capsys):
    from helpers import model_meta
    from terrapref.learning import ClassifierConfig
    from terrapref.learning.mlp import init_weights
    from terrapref.learning.model_file import CLASSIFIER, FORMAT
    from terrapref.tensorfile import write_tensor_file as _write

    weights = init_weights(ClassifierConfig(), np.random.default_rng(0))
    weights["layers.1.weight"][0, 0] = np.nan
    path = tmp_path / "m.safetensors"
    # save_model refuses such weights (a fit that diverged is never written); a file made elsewhere is refused where it is read
    _write(
        path,
        {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in weights.items()},
        {"format": FORMAT, "kind": CLASSIFIER, "classifier": ClassifierConfig().to_dict(), **model_meta()},
    )
    assert main(["evaluate", str(path), "demo_course", "--seeds", "1", "--out", str(tmp_path / "e")]) == 2
    _one_error(capsys, str(path), "weights.layers.1.weight")


@pytest.mark.parametrize(
    "kind,needle", [("recording", "a recording folder, not a model file; `terrapref train`"), ("checkpoints", "epoch_NNN")]
)
def test_a_folder_given_as_a_model_says_what_it_is(tmp_path: Path, capsys, recording, kind, needle):
    folder = recording if kind == "recording" else tmp_path / "m.checkpoints"
    folder.mkdir(exist_ok=True)
    assert main(["evaluate", str(folder), "demo_course", "--seeds", "1", "--out", str(tmp_path / "e")]) == 2
    _one_error(capsys, str(folder), needle)
    assert not (tmp_path / "e").exists()


def _contents(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.mark.parametrize(
    "argv",
    [
        ["featurize", "REC", "--out", "REC/frames.jsonl"],
        ["featurize", "REC", "--out", "REC/new.safetensors"],
        ["train", "REC", "--out", "REC/meta.json"],
        ["export", "REC", "--format", "mcap", "--out", "REC/frames.jsonl"],
        ["inspect", "REC", "--out", "REC/images/000000.png"],
        ["import", "REC", "--robot", "robot.yaml", "--out", "REC/imported"],
    ],
)
def test_an_output_inside_an_input_is_refused_before_any_work(tmp_path: Path, capsys, recording, argv):
    rec = shutil.copytree(recording, tmp_path / "rec")
    before = _contents(rec)
    argv = [a.replace("REC", str(rec)) for a in argv]
    assert main(argv) == 2
    _one_error(capsys, "--out", str(rec))
    assert _contents(rec) == before


def test_an_output_that_is_a_device_or_a_fifo_is_refused_and_left_as_it_was(tmp_path: Path, capsys, recording):
    import os
    import stat

    os.mkfifo(tmp_path / "fifo.png")
    (tmp_path / "dev.safetensors").symlink_to("/dev/null")
    for argv, kind in (
        (["show", "demo_course", "--out", str(tmp_path / "fifo.png")], "FIFO"),
        (["train", str(recording), "--out", str(tmp_path / "dev.safetensors")], "character device"),
        (["export", str(recording), "--format", "mcap", "--out", str(tmp_path / "fifo.png")], "FIFO"),
        (["render", "demo_course", "--out", str(tmp_path / "dev.safetensors")], "character device"),
    ):
        assert main(argv) == 2
        _one_error(capsys, "--out", kind)
    assert stat.S_ISFIFO((tmp_path / "fifo.png").stat().st_mode)
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode) and (tmp_path / "dev.safetensors").is_symlink()


_ROBOT = (
    "format: terrapref-robot/1\ntopics: {segmentation: /seg, camera_info: /info, odometry: /odom, command: /cmd}\n"
    "camera: {height_m: 1.0, pitch_deg: 30.0}\n"
)


_HUGE = "1" + "0" * 400  # a whole number past the float range, as YAML reads it
_SCENARIO = (
    "format: terrapref-scenario/1\nname: r\nworld: {size_m: [20, 10], resolution_m: 0.1, background: grass}\n"
    "path: {waypoints: [[1, 5], [19, 5]]}\n"
)


@pytest.mark.parametrize(
    ("name", "text", "needles"),
    [
        ("p.yaml", f"format: terrapref-perception/1\ndepth: {{noise_m: {_HUGE}}}\n", ("depth.noise_m", "a very large number")),
        ("p.yaml", f"format: terrapref-perception/1\nlabels: {{boundary_px: {_HUGE}}}\n", ("labels.boundary_px", "a very large number")),
        ("p.yaml", "format: terrapref-perception/1\ndepth: {dropout_rate: 1.0}\n", ("depth.dropout_rate", "[0, 0.99]")),
        ("p.yaml", "format: terrapref-perception/1\ndepth: {max_range_m: 0.5}\n", ("depth.max_range_m", "[1, ")),
        ("r.yaml", _ROBOT.replace("height_m: 1.0", f"height_m: {_HUGE}") + "labels: rellis3d\n", ("camera.height_m",)),
        ("r.yaml", _ROBOT + f"labels: rellis3d\nlimits: {{max_speed_mps: {_HUGE}}}\n", ("limits.max_speed_mps",)),
        ("r.yaml", _ROBOT.replace("command: /cmd", "command: /odom") + "labels: rellis3d\n", ("topics.command", "topics.odometry")),
        ("r.yaml", _ROBOT.replace("command: /cmd", "command: /c md") + "labels: rellis3d\n", ("topics.command", "topic name")),
        ("r.yaml", _ROBOT + "labels: rellis3d\nstop: {step_m: 5}\n", ("stop", "step_m must be at most 0.5")),
        (
            "s.yaml",
            _SCENARIO + "relief: [{mound: {center: [8, 5], radius: 2, height_m: 0}}]\n",
            ("relief[0].mound.height_m", "at least 1 mm"),
        ),
        ("s.yaml", _SCENARIO + "relief: [{noise: {amplitude_m: 0.5, wavelength_m: 1e308, seed: 1}}]\n", ("wavelength_m", "at most")),
    ],
)
def test_a_number_no_file_could_mean_is_refused_naming_the_file_and_the_field(tmp_path: Path, capsys, name, text, needles):
    """A whole number past what a float holds, relief that changes nothing, depth with no return,
    a topic two roles share: refused in one line naming the file and the field, exit 2."""
    path = tmp_path / name
    path.write_text(text)
    assert main(["validate", str(path)]) == 2
    said = capsys.readouterr()
    errors = [line for line in (said.out + said.err).splitlines() if line.startswith("error:")]  # validate reports on stdout
    assert len(errors) == 1 and all(n in errors[0] for n in (str(path), *needles)), said
    assert "internal error" not in said.err and "Traceback" not in said.err


@pytest.mark.parametrize("kind", ["scenario", "perception", "robot", "label map", "class table"])
def test_a_yaml_file_with_a_key_given_twice_is_refused_naming_the_key_and_its_lines(tmp_path: Path, capsys, kind):
    # PyYAML keeps the last of two equal keys; RELLIS grass (3) would be imported as mud.
    files = {
        "scenario": ("s.yaml", "format: terrapref-scenario/1\nname: a\nname: b\n", ["validate", "s.yaml"]),
        "perception": ("p.yaml", "format: terrapref-perception/1\nlabels:\n  flip_rate: 0.1\n  flip_rate: 0.0\n", ["perception", "p.yaml"]),
        "robot": ("r.yaml", _ROBOT + "labels: rellis3d\nlabels: terrapref\n", ["import", "x.bag", "--robot", "r.yaml", "--out", "o"]),
        "label map": (
            "l.yaml",
            "format: terrapref-labels/1\nids:\n  3: grass\n  0x3: mud\n",
            ["import", "x.bag", "--robot", "r.yaml", "--out", "o"],
        ),
        "class table": ("c.yaml", "format: terrapref-classes/1\nclasses: []\nclasses: []\n", None),
    }
    name, text, argv = files[kind]
    (tmp_path / name).write_text(text)
    if not (tmp_path / "r.yaml").exists():
        (tmp_path / "r.yaml").write_text(_ROBOT + "labels: l.yaml\n")
    if argv is None:
        from terrapref.errors import UserError
        from terrapref.terrain.classes import load_classes

        with pytest.raises(UserError, match="given twice"):
            load_classes(tmp_path / name)
        return
    argv = [str(tmp_path / a) if a.endswith(".yaml") else a for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr()
    assert "given twice (first at line" in err.err + err.out and "Traceback" not in err.err


@pytest.mark.parametrize(
    "text",
    [
        "fx: 0.0\n",
        "fx: -300.0\nfy: 300.0\n",
        "image_width: 640\nimage_height: 480\ncamera_matrix: {rows: 3, cols: 3, data: [-300, 0, 320, 0, 300, 240, 0, 0, 1]}\n",
    ],
)
def test_a_camera_file_with_a_focal_length_that_is_not_positive_is_refused(tmp_path: Path, capsys, recording, text):
    (tmp_path / "cam.yaml").write_text(text)
    assert main(["featurize", str(recording), "--camera", str(tmp_path / "cam.yaml"), "--out", str(tmp_path / "d.safetensors")]) == 2
    _one_error(capsys, "cam.yaml", "fx must be a focal length > 0")
    assert not (tmp_path / "d.safetensors").exists()


def test_a_recording_whose_camera_has_no_focal_length_is_refused(tmp_path: Path, capsys, recording):
    rec = shutil.copytree(recording, tmp_path / "rec")
    meta = json.loads((rec / "meta.json").read_text())
    meta["camera"]["fy"] = 0.0
    (rec / "meta.json").write_text(json.dumps(meta))
    assert main(["featurize", str(rec), "--out", str(tmp_path / "d.safetensors")]) == 2
    _one_error(capsys, "meta.json", "camera", "fy must be a focal length > 0")


@pytest.mark.parametrize(
    "argv, needles",
    [
        (["record", "demo_course", "--profile", "", "--out", "OUT/r"], ("--profile", "exactly once")),
        (["record", "demo_course", "--profile", "non_traversable,rock,mud,water", "--out", "OUT/r"], ("--profile", "lethal", "last")),
        (["record", "demo_course", "--profile", "rock,non_traversable,mud,water", "--out", "OUT/r"], ("--profile", "before mud, water")),
        (["record", "demo_course", "--profile", "rock,,mud,water,non_traversable", "--out", "OUT/r"], ("--profile", "empty item")),
        (["train", "REC", "--hidden", "100000000", "--out", "OUT/m.safetensors"], ("--hidden", "weights", "at most")),
        (["render", "demo_course", "--pose", "1e308", "0", "0", "--out", "OUT/s.png"], ("--pose", "within 30 m")),
        (["evaluate", "M", "demo_course", "--frames", "5,99999", "--out", "OUT/e"], ("--frames", "99999", "time limit")),
        (["train", "REC", "REC", "--out", "OUT/m.safetensors"], ("REC", "given twice")),
        (["featurize", "REC", "REC/", "--out", "OUT/d.safetensors"], ("REC", "given twice")),
        (["evaluate", "M", "demo_course", "demo_course", "--out", "OUT/e"], ("demo_course", "given twice")),
        (
            ["evaluate", "M", "demo_course", "--no-driver", "--relief-style", "cautious", "--out", "OUT/e"],
            ("--relief-style", "--no-driver"),
        ),
        (["evaluate", "M", "demo_course", "--no-driver", "--style", "shaky", "--out", "OUT/e"], ("--style", "--no-driver")),
        (["render", "demo_course", "--pose", "-1e9", "0", "0", "--out", "OUT/s.png"], ("--pose", "within 30 m")),
        (["course", "--name", "", "--out", "OUT/c.yaml"], ("--name", "letters, digits")),  # not a silent teaching_course
        (["select", "--perception", "", "--out", "OUT/s"], ("--perception", "empty item")),  # not a silent clean
        (["select", "--perception", "clean,,field", "--out", "OUT/s"], ("--perception", "empty item")),
        (["select", "--taught-under", "", "--out", "OUT/s"], ("--taught-under", "a preset")),
        (["reproduce", "--perception", "clean,", "--out", "OUT/r"], ("--perception", "empty item")),
        (["train", "REC", "--out", "OUT/m.onnx"], ("--out", "read as ONNX", ".safetensors")),  # info would then refuse it
        (["featurize", "REC", "--out", "OUT/d.onnx"], ("--out", "read as ONNX", ".safetensors")),
    ],
)
def test_values_that_cannot_be_right_and_inputs_given_twice_are_refused_before_any_work(tmp_path: Path, capsys, recording, argv, needles):
    out = tmp_path / "out"
    out.mkdir()
    model = tmp_path / "m.safetensors"
    model.write_bytes(b"")  # refused before the model is read
    swap = {"REC": str(recording), "REC/": f"{recording}/", "OUT": str(out), "M": str(model)}
    argv = [swap.get(a, a).replace("OUT", str(out)) for a in argv]
    assert main(argv) == 2
    _one_error(capsys, *(swap.get(n, n) for n in needles))
    assert not any(out.iterdir())


def _commands_with(flag: str) -> list[str]:
    """Every command of the command line that takes ``flag``."""
    import argparse

    from terrapref.cli import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return sorted(name for name, parser in sub.choices.items() if flag in parser._option_string_actions)


def test_an_empty_output_path_is_refused_by_every_command_that_writes_one(tmp_path: Path, capsys, monkeypatch):
    """``--out ""`` is not the current folder: every command refuses it in one line naming the flag."""
    commands = _commands_with("--out")
    assert {"record", "train", "evaluate", "select", "study", "reproduce", "import", "export", "route"} <= set(commands)
    monkeypatch.chdir(tmp_path)
    for command in commands:
        with pytest.raises(SystemExit) as refused:  # argparse's refusal (terrapref.cli._Parser): one line
            main([command, "--out", ""])
        assert refused.value.code == 2, command
        _one_error(capsys, f"terrapref {command}: argument --out", "expected a path")
    assert list(tmp_path.iterdir()) == []


def _full_disk_after(writes: int):
    """A stand-in for a writer that fills the disk: ``writes`` calls succeed, the next fail as a
    full file system does (safetensors reports it in its own exception's text)."""
    from safetensors import SafetensorError
    from safetensors.numpy import save_file

    calls = []

    def write(tensors, filename, metadata=None):
        calls.append(filename)
        if len(calls) > writes:
            raise SafetensorError("Error while serializing: I/O error: No space left on device (os error 28)")
        save_file(tensors, filename, metadata=metadata)

    return write


@pytest.mark.parametrize("command, writes", [("train", 0), ("train", 2), ("featurize", 0)])
def test_a_full_disk_is_one_error_naming_the_output_and_leaves_nothing_behind(
    tmp_path: Path, capsys, monkeypatch, recording, command, writes
):
    monkeypatch.setattr("terrapref.tensorfile.save_file", _full_disk_after(writes))
    out = tmp_path / "out"
    out.mkdir()
    name = "m.safetensors" if command == "train" else "d.safetensors"
    assert (
        main([command, str(recording), "--out", str(out / name), *(["--epochs", "3", "--members", "1"] if command == "train" else [])]) == 2
    )
    _one_error(capsys, str(out / name), "No space left on device")
    assert not any(out.iterdir()), list(out.iterdir())  # no model, checkpoints or .interrupted


def test_record_onto_a_full_disk_keeps_the_recording_it_replaces_and_no_hidden_folder(tmp_path: Path, capsys, monkeypatch, recording):
    import errno

    from terrapref.demos import recording as recording_module

    rec = shutil.copytree(recording, tmp_path / "rec")
    before = _contents(rec)
    real, calls = recording_module.write_png_atomic, []

    def write(path, image, **kwargs):
        calls.append(path)
        if len(calls) > 10:
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, image, **kwargs)

    monkeypatch.setattr(recording_module, "write_png_atomic", write)
    assert main(["record", "demo_course", "--out", str(rec), "--force", "--quiet"]) == 2
    _one_error(capsys, "No space left on device")
    assert _contents(rec) == before and sorted(p.name for p in tmp_path.iterdir()) == ["rec"]


@pytest.mark.parametrize(
    "argv, needles",
    [
        (["evaluate", "m.safetensors", "demo_course", "--seeds", "abc", "--out", "e"], ("terrapref evaluate", "--seeds", "'abc'")),
        (["render", "demo_course", "--pose", "8", "10", "--out", "s.png"], ("terrapref render", "--pose", "expected 3 arguments")),
        (["record", "teach_course"], ("terrapref record", "--out")),
        (["drive-it"], ("terrapref", "invalid choice", "'drive-it'")),
        (["record", "teach_course", "--preview", "-1", "--out", "r"], ("terrapref record", "--preview", "'-1' is not > 0")),
        (["record", "teach_course", "--lateral-accel", "0", "--out", "r"], ("terrapref record", "--lateral-accel", "'0' is not > 0")),
        (
            ["train", "rec", "--stage-weight", "-5", "--out", "m.safetensors"],
            ("terrapref train", "--stage-weight", "'-5' is not between 0"),
        ),
    ],
)
def test_the_command_lines_own_refusals_are_one_line(capsys, argv: list[str], needles: tuple[str, ...]):
    with pytest.raises(SystemExit) as info:
        main(argv)
    assert info.value.code == 2
    text = capsys.readouterr().err
    assert text.count("\n") == 1 and text.startswith("error: ") and "usage:" not in text, text
    assert all(n in text for n in needles) and "--help)" in text, text


@pytest.mark.parametrize("how", ["unknown class in profile", "far pose", "label 99"])
def test_a_recording_refused_by_featurize_is_refused_by_train_inspect_and_course_after(tmp_path: Path, capsys, recording, how):
    rec = tmp_path / "rec"
    shutil.copytree(recording, rec)
    _damage(rec, how)
    for argv in (
        ["train", str(rec), "--out", str(tmp_path / "m.safetensors"), "--epochs", "1"],
        ["inspect", str(rec), "--out", str(tmp_path / "i.png")],
        ["course", "--after", str(rec), "--out", str(tmp_path / "c.yaml")],
    ):
        assert main(argv) == 2
        _one_error(capsys, str(rec))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec"]


@pytest.fixture(scope="module")
def featurized(recording, tmp_path_factory) -> Path:
    """The tiny recording featurised for the default recipe (its rules' arrays with it)."""
    out = tmp_path_factory.mktemp("featurized") / "d.safetensors"
    assert main(["featurize", str(recording), "--out", str(out)]) == 0
    return out


def test_samples_with_no_intended_offset_are_refused_before_training(tmp_path: Path, capsys, featurized):
    from terrapref.dataset import FORMAT
    from terrapref.tensorfile import read_tensor_file, write_tensor_file

    tensors, meta = read_tensor_file(featurized, FORMAT, "no such file", "not a dataset")
    tensors["rules.offset.intent_m"] = np.full_like(
        tensors["rules.offset.intent_m"], np.nan
    )  # NaN is allowed: a frame whose intent is unknown
    data = write_tensor_file(tmp_path / "nan_intent.safetensors", tensors, meta)
    assert main(["train", str(data), "--out", str(tmp_path / "m.safetensors"), "--epochs", "1"]) == 2
    _one_error(capsys, str(data), "rules.offset.intent_m: no sample holds an intended offset")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["nan_intent.safetensors"]


def test_samples_whose_trajectories_end_before_the_look_ahead_are_refused_by_a_recipe_with_one(tmp_path: Path, capsys, recording):
    data = tmp_path / "short.safetensors"
    assert main(["featurize", str(recording), "--out", str(data), "--recipe", "paper", "--n-steps", "1"]) == 0  # the paper's has none
    assert main(["train", str(data), "--out", str(tmp_path / "m.safetensors"), "--epochs", "1"]) == 2
    _one_error(capsys, str(data), "features.preference: the look-ahead starts 2.4 s", "past trajectories of 1 steps")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["short.safetensors"]


@pytest.mark.parametrize("beside", ["m.loss.png", "m.checkpoints"])
def test_train_keeps_what_lies_where_it_writes_beside_the_model_unless_forced(tmp_path: Path, capsys, beside):
    from helpers import dataset_file

    data = dataset_file(tmp_path / "d.safetensors", n=60)
    kept = tmp_path / beside
    if beside.endswith(".png"):
        kept.write_text("mine")
    else:
        kept.mkdir()
        (kept / "notes.txt").write_text("mine")
    argv = ["train", str(data), "--out", str(tmp_path / "m.safetensors"), "--epochs", "1"]
    assert main(argv) == 2
    _one_error(capsys, str(kept), "--out", "pass --force")
    assert not (tmp_path / "m.safetensors").exists()
    assert (kept.read_text() if kept.is_file() else (kept / "notes.txt").read_text()) == "mine"
    assert main([*argv, "--force"]) == 0
    assert (tmp_path / "m.safetensors").exists() and not (kept / "notes.txt").exists()


def test_export_refuses_a_frame_with_a_class_id_its_table_does_not_have(tmp_path: Path, capsys, recording):
    rec = tmp_path / "rec"
    shutil.copytree(recording, rec)
    _damage(rec, "class 200")
    assert main(["export", str(rec), "--format", "mcap", "--out", str(tmp_path / "r.mcap")]) == 2
    _one_error(capsys, "000003.png", "class ids [200]")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec"]


def test_a_damaged_header_is_refused_in_a_line_of_readable_length(tmp_path: Path, capsys):
    from helpers import dataset_file

    data = dataset_file(tmp_path / "d.safetensors", n=60)
    raw = bytearray(data.read_bytes())
    raw[20:30] = b"@" * 10  # inside the JSON header: the parser's reason quotes the header whole
    data.write_bytes(bytes(raw))
    assert main(["train", str(data), "--out", str(tmp_path / "m.safetensors"), "--epochs", "1"]) == 2
    line = _one_error(capsys, str(data))
    assert len(line) < 400, line


def test_drives_of_two_orders_are_refused_naming_both_and_what_to_do(tmp_path: Path, capsys, recording):
    """A follow-up recorded without the first drive's --profile declares another order: the refusal
    names both orders and says to record with the same --profile (it once said to featurise them
    separately, which teaches neither drive's lesson together)."""
    other = tmp_path / "other"
    shutil.copytree(recording, other)
    meta = json.loads((other / "meta.json").read_text())
    first = list(meta["profile"])
    meta["profile"] = [*first[:-1][::-1], first[-1]]
    (other / "meta.json").write_text(json.dumps(meta))
    assert main(["featurize", str(recording), str(other), "--out", str(tmp_path / "d.safetensors")]) == 2
    _one_error(capsys, "profile", " > ".join(meta["profile"]), " > ".join(first), "record the drives with the same --profile")


def test_drives_of_two_class_tables_are_refused_naming_both(tmp_path: Path, capsys, recording):
    from helpers import REPO
    from terrapref.terrain import load_classes

    other = tmp_path / "other"
    shutil.copytree(recording, other)
    meta = json.loads((other / "meta.json").read_text())
    small = load_classes(REPO / "examples" / "classes" / "small.yaml")
    meta["classes"], meta["profile"] = small.to_dict(), list(small.profile)
    (other / "meta.json").write_text(json.dumps(meta))
    assert main(["featurize", str(recording), str(other), "--out", str(tmp_path / "d.safetensors")]) == 2
    _one_error(
        capsys, "classes", "another class table (grass, mud, tree)", "(grass, non_traversable, water, rock, mud)", "train them apart"
    )
