"""Nothing lost or mixed between the product's own files: what one command writes, the next reads
back whole (the driver's order through a bag, a recording replaced while it is read, reserved
class names), and every command treats an existing output the same way."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from helpers import REPO, TINY_COURSE, one_line_error
from terrapref.cli import main
from terrapref.demos.recording import read_recording
from terrapref.learning.identify import NO_DECLARED_ORDER
from terrapref.learning.model_file import load_model

ORDER = ["water", "rock", "mud", "non_traversable"]  # not the default order


@pytest.fixture(scope="module")
def ordered_recording(tmp_path_factory) -> Path:
    """A short undisturbed drive by a driver with a non-default order."""
    out = tmp_path_factory.mktemp("ordered") / "rec"
    assert main(["record", str(TINY_COURSE), "--out", str(out), "--quiet", "--disturb", "0", "--profile", ",".join(ORDER)]) == 0
    return out


@pytest.mark.parametrize("fmt", ["mcap", "rosbag1"])
def test_the_drivers_order_survives_an_export_and_an_import(tmp_path: Path, ordered_recording: Path, capsys, fmt: str):
    bag = tmp_path / ("run.mcap" if fmt == "mcap" else "run.bag")
    assert main(["export", str(ordered_recording), "--format", fmt, "--out", str(bag)]) == 0
    assert main(["import", str(bag), "--robot", f"{bag}.robot.yaml", "--out", str(tmp_path / "back")]) == 0
    assert "water > rock > mud > non_traversable (the robot file's profile)" in capsys.readouterr().out
    assert read_recording(tmp_path / "back").meta["profile"] == ORDER


def test_an_export_is_named_as_its_format_and_replaces_an_earlier_ones_label_map(tmp_path: Path, ordered_recording: Path, capsys):
    """Readers know a file's format by its name: a bag named .mcap (or the reverse) is refused, in
    one line naming --out, before anything is written. With --force, an earlier export's label map
    (of another class table) goes with it: the new bag of terrapref's own ids needs none."""
    for fmt, name in (("rosbag1", "run.mcap"), ("mcap", "run.bag"), ("mcap", "run.txt"), ("onnx", "m.safetensors")):
        assert main(["export", str(ordered_recording), "--format", fmt, "--out", str(tmp_path / name)]) == 2
        one_line_error(capsys, name, "--out", f"--format {fmt}")
    assert not list(tmp_path.iterdir())
    bag = tmp_path / "run.mcap"
    stale = Path(f"{bag}.labels.yaml")
    stale.write_text("format: terrapref-labels/1\nids: {0: dirt}\n")
    assert main(["export", str(ordered_recording), "--format", "mcap", "--out", str(bag), "--force"]) == 0
    assert bag.is_file() and Path(f"{bag}.robot.yaml").is_file() and not stale.exists()


def test_an_import_with_no_declared_order_says_so_and_its_model_names_none(tmp_path: Path, ordered_recording: Path, capsys):
    bag = tmp_path / "run.mcap"
    assert main(["export", str(ordered_recording), "--format", "mcap", "--out", str(bag)]) == 0
    robot = Path(f"{bag}.robot.yaml")
    robot.write_text("".join(line for line in robot.read_text().splitlines(keepends=True) if not line.startswith("profile:")))
    assert main(["import", str(bag), "--robot", str(robot), "--out", str(tmp_path / "none")]) == 0
    out = capsys.readouterr().out
    assert "none declared" in out and "default" not in out.split("order", 1)[1].splitlines()[0]
    assert read_recording(tmp_path / "none").meta.get("profile") is None
    assert main(["inspect", str(tmp_path / "none"), "--no-preference", "--out", str(tmp_path / "none.png")]) == 0
    assert "order      none declared" in capsys.readouterr().out
    # The model learns the drive and names no order (train says so); evaluate needs one to score zones and drive its driver by.
    assert main(["featurize", str(tmp_path / "none"), "--out", str(tmp_path / "ds.safetensors"), "--recipe", "paper"]) == 0
    model = tmp_path / "m.safetensors"
    assert main(["train", str(tmp_path / "ds.safetensors"), "--recipe", "paper", "--epochs", "1", "--out", str(model)]) == 0
    out = capsys.readouterr().out
    assert f"  {NO_DECLARED_ORDER}" in out and "the profile stored with the drive" not in out
    assert load_model(model).profile == ()
    assert main(["evaluate", str(model), "fig7a_non_traversable_longer", "--out", str(tmp_path / "eval")]) == 2
    one_line_error(capsys, str(model), "profile", "--profile ORDER")
    assert not (tmp_path / "eval").exists()
    # --profile declares it at the import
    assert (
        main(["import", str(bag), "--robot", str(robot), "--out", str(tmp_path / "given"), "--profile", "rock,mud,water,non_traversable"])
        == 0
    )
    assert "(--profile)" in capsys.readouterr().out
    assert read_recording(tmp_path / "given").meta["profile"] == ["rock", "mud", "water", "non_traversable"]


def test_a_recording_replaced_while_it_is_featurised_fails_clearly(
    tmp_path: Path, tiny_recording: Path, ordered_recording: Path, monkeypatch, capsys
):
    """`record --force --out REC` swapping a new drive in while `featurize REC` reads it: the
    reader would take one recording's frame list and the other's images; it must fail instead."""
    import shutil

    import terrapref.demos.recording as recording_module
    from terrapref.fileio import replace_dir

    rec, other = tmp_path / "rec", tmp_path / "other"
    shutil.copytree(tiny_recording, rec)
    shutil.copytree(ordered_recording, other)
    reads = []
    real = recording_module.read_label_png

    def read_then_replace(path):
        reads.append(path)
        if len(reads) == 5:  # as record --force does once its new drive is complete
            replace_dir(other, rec)
        return real(path)

    monkeypatch.setattr(recording_module, "read_label_png", read_then_replace)
    assert main(["featurize", str(rec), "--out", str(tmp_path / "ds.safetensors")]) == 2
    one_line_error(capsys, str(rec), "replaced", progress="featurize")
    assert not (tmp_path / "ds.safetensors").exists()
    assert len(read_recording(rec)) == len(read_recording(ordered_recording))  # the new one, whole, for the next reader


@pytest.mark.parametrize("value", ["inf", "nan", "-inf"])
def test_a_learning_rate_that_is_not_finite_is_refused(tmp_path: Path, capsys, value: str):
    from helpers import dataset_file

    data = dataset_file(tmp_path / "ds.safetensors")
    with pytest.raises(SystemExit) as refused:
        main(["train", str(data), "--out", str(tmp_path / "m.safetensors"), f"--lr={value}"])
    assert refused.value.code == 2
    one_line_error(capsys, "--lr", "not a finite number")
    assert list(tmp_path.iterdir()) == [data]


def test_weights_that_are_not_finite_are_never_written(tmp_path: Path):
    import numpy as np

    from helpers import model_meta, skip_path_weights
    from terrapref.errors import UserError
    from terrapref.learning.model_file import save_model
    from terrapref.learning.network import ClassifierConfig

    config = ClassifierConfig(hidden=8, skip=True)
    weights = {name: value.copy() for name, value in skip_path_weights(config).items()}  # (views of a shared array)
    weights["compress.weight"][0, 2] = np.nan
    with pytest.raises(UserError, match="compress.weight.*1 of its weights are not finite"):
        save_model(tmp_path / "m.safetensors", config, weights, model_meta())
    assert not (tmp_path / "m.safetensors").exists()


def test_a_drive_whose_every_frame_is_dropped_writes_no_recording(tmp_path: Path, tiny_recording: Path, capsys):
    import shutil

    drop_all = tmp_path / "drop.yaml"
    drop_all.write_text("format: terrapref-perception/1\nframes: {drop_rate: 1.0}\n")
    args = ["record", str(TINY_COURSE), "--quiet", "--disturb", "0", "--perception", str(drop_all)]
    assert main([*args, "--out", str(tmp_path / "new")]) == 2
    one_line_error(capsys, "new", "no frame")
    assert not (tmp_path / "new").exists()
    old = tmp_path / "old"
    shutil.copytree(tiny_recording, old)
    assert main([*args, "--out", str(old), "--force"]) == 2
    one_line_error(capsys, "old", "no frame")
    assert len(read_recording(old)) == len(read_recording(tiny_recording)) and read_recording(old).complete
    assert sorted(p.name for p in tmp_path.iterdir()) == ["drop.yaml", "old"]


# --- one rule for every command's output ----------------------------------------------------------


def _writers(tmp: Path, rec: Path) -> dict[str, tuple[list[str], Path]]:
    """Each command that writes, as a user runs it: its arguments and the output it makes."""
    from helpers import dataset_file, linear_model

    model, data = linear_model(tmp / "m.safetensors"), dataset_file(tmp / "ds.safetensors", n=64)
    return {
        "render": (["render", "demo_course", "--out", str(tmp / "seg.png")], tmp / "seg.png"),
        "show": (["show", "demo_course", "--out", str(tmp / "map.png")], tmp / "map.png"),
        "course": (["course", "--classes", "examples/classes/small.yaml", "--out", str(tmp / "c.yaml")], tmp / "c.yaml"),
        "inspect": (["inspect", str(rec), "--no-preference", "--out", str(tmp / "driven.png")], tmp / "driven.png"),
        "featurize": (["featurize", str(rec), "--out", str(tmp / "d.safetensors")], tmp / "d.safetensors"),
        "train": (["train", str(data), "--recipe", "paper", "--epochs", "1", "--out", str(tmp / "t.safetensors")], tmp / "t.safetensors"),
        "export onnx": (["export", str(model), "--format", "onnx", "--out", str(tmp / "m.onnx")], tmp / "m.onnx"),
        "export mcap": (["export", str(rec), "--format", "mcap", "--out", str(tmp / "r.mcap")], tmp / "r.mcap"),
        "evaluate": (
            [
                "evaluate",
                str(model),
                str(TINY_COURSE),
                "--seeds",
                "1",
                "--no-driver",
                "--workers",
                "1",
                "--out",
                str(tmp / "ev"),
            ],
            tmp / "ev",
        ),
    }


def _state(path: Path) -> dict[str, bytes]:
    files = sorted(path.rglob("*")) if path.is_dir() else [path]
    return {str(p): p.read_bytes() for p in files if p.is_file()}


@pytest.mark.parametrize("command", ["render", "show", "course", "inspect", "featurize", "train", "export onnx", "export mcap", "evaluate"])
def test_every_command_refuses_an_existing_output_without_force_and_replaces_it_with_force(
    tmp_path: Path, tiny_recording: Path, monkeypatch, capsys, command: str
):
    monkeypatch.chdir(REPO)  # examples/ as a user's clone has it
    argv, out = _writers(tmp_path, tiny_recording)[command]
    assert main(argv) == 0
    before = _state(out)
    capsys.readouterr()
    assert main(argv) == 2
    one_line_error(capsys, str(out), "exists", "--force")
    assert _state(out) == before  # untouched
    assert main([*argv, "--force"]) == 0


def test_inspects_default_figure_in_the_recording_is_refused_once_there_unless_forced(tmp_path: Path, tiny_recording: Path, capsys):
    """``DIR/driven_path.png`` is an output like any other: a second inspect asks for --force before any work."""
    rec = tmp_path / "rec"
    shutil.copytree(tiny_recording, rec)
    assert main(["inspect", str(rec), "--no-preference"]) == 0
    figure = rec / "driven_path.png"
    before = figure.read_bytes()
    capsys.readouterr()
    assert main(["inspect", str(rec), "--no-preference"]) == 2
    one_line_error(capsys, str(figure), "exists", "--force")
    assert figure.read_bytes() == before
    assert main(["inspect", str(rec), "--no-preference", "--force"]) == 0


def test_a_run_never_replaces_a_recording_even_with_force(tmp_path: Path, tiny_recording: Path, capsys):
    from helpers import linear_model

    rec = tmp_path / "rec"
    shutil.copytree(tiny_recording, rec)
    model = linear_model(tmp_path / "m.safetensors")
    assert main(["evaluate", str(model), str(TINY_COURSE), "--seeds", "1", "--no-driver", "--out", str(rec), "--force"]) == 2
    one_line_error(capsys, str(rec), "--out", "is a recording")
    assert len(read_recording(rec)) == len(read_recording(tiny_recording))


def test_two_evaluations_into_one_folder_leave_one_run_whole(tmp_path: Path, tiny_recording: Path, capsys):
    """A second evaluate while the first writes is refused, even with --force; one after another,
    the second (with --force) replaces the first whole: no figure of the first is left beside it."""
    from terrapref.fileio import output_folder

    argv, out = _writers(tmp_path, tiny_recording)["evaluate"]
    with output_folder(out, force=False):  # as a first evaluate holds it while it runs
        (out / "tiny_course_seed0.png").write_bytes(b"first")
        assert main([*argv, "--force"]) == 2
        one_line_error(capsys, str(out), "being written by another terrapref command")
    (out / "from_the_first_run.png").write_bytes(b"first")
    assert main([*argv, "--force"]) == 0
    assert not (out / "from_the_first_run.png").exists() and (out / "metrics.json").is_file()


@pytest.mark.parametrize(
    "argv",
    [["reproduce", "--seeds", "1"], ["select", "--seeds", "1", "--courses", "1"], ["study", "--quick"]],
    ids=["reproduce", "select", "study"],
)
def test_the_long_jobs_refuse_an_existing_folder_before_any_work(tmp_path: Path, capsys, argv):
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "REPORT.md").write_text("an earlier run")
    assert main([*argv, "--out", str(tmp_path / "out")]) == 2
    one_line_error(capsys, "out", "exists", "--force")
    assert (tmp_path / "out" / "REPORT.md").read_text() == "an earlier run"
