"""A robot log of a class table of one's own: a log whose segmentation publishes RELLIS-3D ids,
imported with the example table's label map, trains a model for that table."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from helpers import REPO
from synthetic_bag import RELLIS_OF_EXAMPLE, TOPICS, write_synthetic_bag
from terrapref.cli import main
from terrapref.demos.recording import read_recording
from terrapref.learning.model_file import load_model
from terrapref.scenario.teaching import Situation, build_course
from terrapref.terrain import ClassTable, load_classes

EXAMPLES = REPO / "examples" / "classes"
TABLE = EXAMPLES / "rellis3d.yaml"
LABELS = EXAMPLES / "rellis3d_labels.yaml"


@pytest.fixture(scope="module")
def table() -> ClassTable:
    return load_classes(TABLE)


@pytest.fixture(scope="module")
def log(tmp_path_factory, table) -> dict:
    """A short course of the example table (grass, puddle beside water, mud beside a tree), driven
    and written as an MCAP log in RELLIS-3D ids, and a robot file naming the example label map."""
    root = tmp_path_factory.mktemp("rellis_table")
    items = [Situation("pair", ("puddle", "water")), Situation("strip", ("tree", "mud", "dirt"))]
    course = root / "course.yaml"
    course.write_text(yaml.safe_dump(build_course(table, items, "short", "three situations").data(), sort_keys=False))
    bag = write_synthetic_bag(root / "drive.mcapbag", "mcap", scenario=str(course), profile=table.profile, quirks=False, classes=table)
    topics = "\n".join(f"  {k}: {v}" for k, v in TOPICS.items())
    robot = root / "robot.yaml"
    robot.write_text(
        f"format: terrapref-robot/1\ntopics:\n{topics}\ncamera:\n  height_m: 1.0\n  pitch_deg: 30.0\nlabels: {LABELS}\n"
        f"profile: [{', '.join(table.profile)}]\n"
    )
    return {"root": root, "bag": bag, "robot": robot, "course": course}


@pytest.fixture(scope="module")
def rec_dir(log) -> Path:
    rec_dir = log["root"] / "rec"
    assert main(["import", str(log["bag"]), "--robot", str(log["robot"]), "--classes", str(TABLE), "--out", str(rec_dir)]) == 0
    return rec_dir


def test_the_label_map_brings_every_rellis_id_of_the_log_to_the_table(rec_dir, table):
    rec = read_recording(rec_dir)
    assert ClassTable.from_dict(rec.meta["classes"]) == table
    seen = np.unique(np.concatenate([np.unique(rec.image(i)) for i in range(0, len(rec), 25)]))
    # Grass came as "downhill" (30) and water as "deep water" (32): both arrive as the table's classes.
    assert {table.id_of("grass"), table.id_of("water"), table.id_of("puddle")} <= set(seen.tolist())
    assert set(seen.tolist()) <= {c.id for c in table.classes} | {255}
    assert RELLIS_OF_EXAMPLE["grass"] == 30 and RELLIS_OF_EXAMPLE["water"] == 32


def test_the_imported_log_trains_a_model_for_the_table(log, rec_dir, table, capsys):
    model_path = log["root"] / "m.safetensors"
    # The paper's recipe: the quickest to train; the default recipe reads the same table (tests/scenario/test_class_tables.py).
    assert main(["train", str(rec_dir), "--out", str(model_path), "--recipe", "paper", "--epochs", "2", "--classes", str(TABLE)]) == 0
    model = load_model(model_path)
    assert model.classes == table
    assert model.features.feature_classes == table.feature_names == ("dirt", "gravel", "mud", "puddle", "water", "bush", "lethal")
    # A model of this table is refused where the default table is given, in one line naming both tables.
    default_file = REPO / "src" / "terrapref" / "data" / "classes.yaml"
    assert main(["evaluate", str(model_path), "gen:3", "--classes", str(default_file), "--out", str(log["root"] / "e")]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error:")]
    assert len(err) == 1 and "dirt" in err[0] and "non_traversable" in err[0]


@pytest.mark.slow  # a whole drive or export end to end, its steps tested apart in the default run
def test_an_export_of_the_tables_recording_imports_back_only_with_its_table(log, rec_dir, capsys):
    out = log["root"] / "back.mcap"
    assert main(["export", str(rec_dir), "--format", "mcap", "--out", str(out)]) == 0
    assert "--classes FILE" in capsys.readouterr().out
    assert "tree" in (log["root"] / "back.mcap.labels.yaml").read_text()
    robot = log["root"] / "back.mcap.robot.yaml"
    # Read with the default table, the ids would be other classes: refused, naming a class it lacks.
    assert main(["import", str(out), "--robot", str(robot), "--out", str(log["root"] / "wrong")]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error:")]
    assert len(err) == 1 and "not in the class table" in err[0]
    assert main(["import", str(out), "--robot", str(robot), "--classes", str(TABLE), "--out", str(log["root"] / "back")]) == 0
    a, b = read_recording(rec_dir), read_recording(log["root"] / "back")
    assert len(a) == len(b) and all(np.array_equal(a.image(i), b.image(i)) for i in range(0, len(a), 10))


def test_a_robot_files_label_map_of_another_table_than_the_models_names_the_model(tmp_path, table):
    """A log of terrapref's own ids replayed, or a node run, with a model of the example table: the
    robot file's label map names classes the model's table lacks, and the refusal says whose table
    it was read with, not only that the robot file is at fault."""
    from synthetic_bag import robot_yaml, write_robot
    from terrapref.errors import UserError
    from terrapref.interop.robot import load_robot

    robot = write_robot(tmp_path / "robot.yaml", robot_yaml(labels="terrapref"))
    with pytest.raises(UserError) as err:
        load_robot(robot, table, "--model m.safetensors")
    (line,) = str(err.value).splitlines()
    assert line.startswith(f"{robot}: labels: ") and "is not in the class table" in line and "of --model m.safetensors" in line
