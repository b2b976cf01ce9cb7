"""Model and dataset files: safetensors without pickle, round trips, and refusals of anything
they cannot vouch for (damage, missing or wrong metadata, weights of the wrong shape, a model
for another camera or preference set)."""

from __future__ import annotations

import json
import math
import pickle
import struct
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from safetensors.numpy import save_file

from helpers import assert_weights_equal, model_meta, random_dataset, random_weights, sparse_terrain_dataset
from terrapref.camera import CameraConfig
from terrapref.dataset import Dataset, load_dataset, save_dataset
from terrapref.errors import UserError
from terrapref.features import FeatureConfig, PreferenceSetConfig
from terrapref.learning.header import DataSource, Interruption, MemberRun, ModelHeader, rule_blocks
from terrapref.learning.model_file import FORMAT, check_compatible, load_model, read_model_file, save_model, write_model
from terrapref.learning.network import ClassifierConfig
from terrapref.learning.train import EpochMetrics, TrainConfig
from terrapref.tensorfile import write_tensor_file
from terrapref.terrain import PreferenceProfile, default_classes

# --- model files -------------------------------------------------------------------------------------


ODD_FEATURES = FeatureConfig(PreferenceSetConfig(n_steps=20, dt_s=0.25), distance_mode="window", window_m=9.0, path_spacing_m=0.5)
ODD_CAMERA = CameraConfig(pitch_deg=25.0, max_range_m=20.0, mount_height_m=1.2)
ODD_PROFILE = ("mud", "rock", "water", "non_traversable")


@pytest.fixture
def model_file(tmp_path: Path) -> tuple[Path, ClassifierConfig, dict[str, np.ndarray]]:
    config = ClassifierConfig(hidden=16, activation="tanh", depth=2, skip=True)
    weights = random_weights(config)
    path = save_model(
        tmp_path / "sub" / "model.safetensors", config, weights, {**model_meta(ODD_FEATURES, ODD_CAMERA, ODD_PROFILE), "note": "kept"}
    )
    return path, config, weights


def test_model_file_round_trip(model_file):
    path, config, weights = model_file
    model = load_model(path)
    assert model.path == str(path)
    assert model.classifier == config
    assert_weights_equal(model.weights, weights)
    assert model.features == ODD_FEATURES
    assert model.camera == ODD_CAMERA
    assert model.classes.to_dict() == default_classes().to_dict()
    assert model.profile == ODD_PROFILE
    assert model.meta["format"] == FORMAT and model.meta["note"] == "kept"
    assert not any(p.name.endswith(".tmp") for p in path.parent.iterdir())  # written atomically


def test_model_file_is_safetensors_without_pickle(model_file, monkeypatch):
    path, _, weights = model_file
    raw = path.read_bytes()
    (n,) = struct.unpack("<Q", raw[:8])
    assert raw[8:9] == b"{"
    header = json.loads(raw[8 : 8 + n])
    assert json.loads(header["__metadata__"]["terrapref"])["format"] == FORMAT
    tensors = {k: v for k, v in header.items() if k != "__metadata__"}
    assert set(tensors) == set(weights)
    assert len(raw) == 8 + n + max(v["data_offsets"][1] for v in tensors.values())  # nothing else in the file

    def refuse(*args, **kwargs):
        raise AssertionError("loading a model must not unpickle")

    for name in ("load", "loads", "Unpickler"):
        monkeypatch.setattr(pickle, name, refuse)
    monkeypatch.setattr(torch, "load", refuse)
    assert load_model(path).classifier.skip


def _expect_user_error(path: Path, *words: str) -> UserError:
    with pytest.raises(UserError) as err:
        load_model(path)
    assert err.value.source == str(path)
    text = str(err.value)
    assert str(path) in text and "\n" not in text
    for word in words:
        assert word in text, text
    return err.value


def test_missing_file_and_directory_are_refused(tmp_path: Path):
    _expect_user_error(tmp_path / "absent.safetensors")
    _expect_user_error(tmp_path)


@pytest.mark.parametrize("damage", ["truncated", "garbage", "empty", "header_too_long", "pickle"])
def test_corrupted_model_file_is_refused(model_file, damage: str):
    path = model_file[0]
    raw = path.read_bytes()
    if damage == "truncated":
        path.write_bytes(raw[: len(raw) - 100])
    elif damage == "garbage":
        path.write_bytes(np.random.default_rng(0).integers(0, 256, 4000, dtype=np.uint8).tobytes())
    elif damage == "empty":
        path.write_bytes(b"")
    elif damage == "header_too_long":
        path.write_bytes(struct.pack("<Q", 10**9) + raw[8:])
    else:
        path.write_bytes(pickle.dumps({"compress.weight": np.zeros((1, 5))}))
    _expect_user_error(path)


def _header_of(raw: bytes) -> tuple[int, dict]:
    """The length of a safetensors file's header and the header."""
    n = struct.unpack("<Q", raw[:8])[0]
    return n, json.loads(raw[8 : 8 + n])


def _with_header(header: dict, data: bytes) -> bytes:
    text = json.dumps(header).encode()
    text += b" " * (-len(text) % 8)
    return struct.pack("<Q", len(text)) + text + data


@pytest.mark.parametrize("how", ["header cut", "tensor cut", "tensor missing", "entry removed", "bytes added"])
def test_a_model_file_cut_short_or_missing_a_tensor_says_so_and_names_the_tensor(model_file, how: str):
    """A safetensors file cut short (a copy or a download that stopped) says so and which tensors
    it lost, not that it is no model file; so does one whose header lacks a tensor's entry."""
    path = model_file[0]
    raw = path.read_bytes()
    n, header = _header_of(raw)
    spans = sorted((entry["data_offsets"], name) for name, entry in header.items() if name != "__metadata__")
    (first, end), last = spans[-1]
    data = raw[8 + n :]
    if how == "header cut":
        path.write_bytes(raw[: 8 + n // 2])
        said = f"truncated: the header promises at least {8 + n} bytes, the file has {8 + n // 2} (the header itself is cut short)"
    elif how == "tensor cut":
        path.write_bytes(raw[:-4])
        said = f"truncated: the header promises {len(raw)} bytes, the file has {len(raw) - 4}; tensor {last!r} is cut short"
    elif how == "tensor missing":
        path.write_bytes(raw[: 8 + n + first])
        said = f"truncated: the header promises {len(raw)} bytes, the file has {8 + n + first}; tensor {last!r} is missing"
    elif how == "entry removed":
        (_, gap_end), removed = spans[0]
        path.write_bytes(_with_header({k: v for k, v in header.items() if k != removed}, data))
        said = (
            f"bytes 0-{gap_end} of its data belong to no tensor of its header (before tensor {spans[1][1]!r}): a tensor's entry is missing"
        )
    else:
        path.write_bytes(raw + b"\0" * 8)
        said = f"the header accounts for {len(raw)} bytes, the file has {len(raw) + 8}: a tensor's entry is missing, or bytes were added"
    assert _expect_user_error(path).lines() == [f"{path}: {said}"]


def test_non_model_safetensors_is_refused(tmp_path: Path):
    path = tmp_path / "weights.safetensors"
    save_file({"x": np.zeros(3, np.float32)}, str(path))
    err = _expect_user_error(path, "metadata")
    assert err.problems[0].field == "metadata"


def test_dataset_file_round_trip(tmp_path: Path):
    data = sparse_terrain_dataset(50)
    back = load_dataset(save_dataset(data, tmp_path / "d.safetensors"))
    for name in ("U", "labels", "w", "source"):
        np.testing.assert_array_equal(getattr(back, name), getattr(data, name))
    assert back.fingerprint == data.fingerprint and back.meta["samples"] == 50
    assert back.feature_config == data.feature_config and back.camera_config == data.camera_config


def test_dataset_without_format_in_meta_round_trips(tmp_path: Path):
    data = random_dataset(20)
    data = Dataset(data.U, data.labels, data.w, data.source, {k: v for k, v in data.meta.items() if k != "format"})
    back = load_dataset(save_dataset(data, tmp_path / "d.safetensors"))
    np.testing.assert_array_equal(back.U, data.U)


@pytest.mark.parametrize(
    ("edit", "field", "said"),
    [
        (lambda meta: meta | {"profile": ["lava", "mud"]}, "profile", "unknown or background class 'lava'"),
        (lambda meta: meta | {"profile": [1, 2]}, "profile", "expected a list of class names"),
        (
            lambda meta: meta | {"features": {**meta["features"], "feature_classes": ["mud", "water", "rock", "mud"]}},
            "features.feature_classes",
            "names mud, water, rock, mud where its class table's feature classes are",
        ),
        (lambda meta: meta | {"rules": {"speed": {"config": "x", "arrays": {}}}}, "rules", "each with its config and arrays"),
        (lambda meta: meta | {"recordings": ["x"]}, "recordings", "expected a list of the recordings it was made from"),
    ],
    ids=["unknown-class", "not-names", "columns", "rule-config", "recordings"],
)
def test_a_dataset_whose_order_or_columns_are_not_of_its_table_is_refused(tmp_path: Path, edit, field: str, said: str):
    """Training such a dataset wrote a model that no command could read."""
    data = random_dataset(10)
    path = save_dataset(Dataset(data.U, data.labels, data.w, data.source, edit(dict(data.meta))), tmp_path / "d.safetensors")
    with pytest.raises(UserError) as err:
        load_dataset(path)
    assert err.value.problems[0].field == field and said in err.value.lines()[0]


def test_dataset_file_is_not_a_model(tmp_path: Path):
    path = save_dataset(random_dataset(10), tmp_path / "data.safetensors")
    err = _expect_user_error(path, FORMAT)
    assert err.problems[0].field == "format"


@pytest.mark.parametrize("metadata", [{"other": "x"}, {"terrapref": "{not json"}], ids=["no-terrapref-key", "bad-json"])
def test_missing_metadata_is_refused(model_file, metadata: dict):
    path, _, weights = model_file
    save_file(weights, str(path), metadata=metadata)
    assert _expect_user_error(path, "metadata").problems[0].field == "metadata"


@pytest.mark.parametrize(
    ("text", "said"),
    [
        ("[" * 5000 + "]" * 5000, "not JSON that can be read (maximum recursion depth"),  # beyond the parser's recursion
        ('{"format": "terrapref-model/1", "deep": ' + "[" * 40 + "]" * 40 + "}", "nested more than 32 deep"),  # beyond the readers'
        ('{"format": "terrapref-model/1", "steps": 1' + "0" * 5000 + "}", "an integer of thousands of digits"),
        ('{"format": "terrapref-model/1", "format": "terrapref-model/1"}', "names 'format' twice in one mapping"),
    ],
    ids=["parser-depth", "reader-depth", "huge-integer", "key-twice"],
)
def test_metadata_json_the_readers_cannot_take_is_refused_in_one_line(model_file, text: str, said: str):
    path, _, weights = model_file
    save_file(weights, str(path), metadata={"terrapref": text})
    assert _expect_user_error(path, said).problems[0].field == "metadata"


@pytest.mark.parametrize(
    ("key", "value", "field", "said"),
    [
        ("kind", [1], "kind", "expected the name of a kind of model, got a list of 1"),
        ("profile", "mud", "profile", "expected a list of class names, most preferred first, got string 'mud'"),
        ("profile", [1, 2], "profile", "expected a list of class names"),
        ("profile", ["mud", "mud", "water", "non_traversable"], "profile", "'rock' is missing"),
        ("profile", ["lava", "rock", "water", "non_traversable"], "profile", "unknown or background class 'lava'"),
    ],
)
def test_a_kind_or_profile_the_file_cannot_mean_is_refused(model_file, key: str, value, field: str, said: str):
    path, config, weights = model_file
    header = {"format": FORMAT, "classifier": config.to_dict(), **model_meta(ODD_FEATURES, ODD_CAMERA, ODD_PROFILE), key: value}
    save_file(weights, str(path), metadata={"terrapref": json.dumps(header)})
    assert _expect_user_error(path, said).problems[0].field == field


def test_an_older_files_profile_with_the_lethal_column_before_others_reads_as_written(model_file):
    path, config, weights = model_file
    older = ["water", "non_traversable", "rock", "mud"]  # written before the lethal column had to come last
    header = {"format": FORMAT, "classifier": config.to_dict(), **model_meta(ODD_FEATURES, ODD_CAMERA, ODD_PROFILE), "profile": older}
    save_file(weights, str(path), metadata={"terrapref": json.dumps(header)})
    assert load_model(path).profile == tuple(older)


def test_terrain_columns_not_the_tables_feature_classes_are_refused(model_file):
    path, config, weights = model_file
    header = {"format": FORMAT, "classifier": config.to_dict(), **model_meta(ODD_FEATURES, ODD_CAMERA, ODD_PROFILE)}
    columns = header["features"]["feature_classes"]
    header["features"]["feature_classes"] = [*columns[:-1], "lava"]
    save_file(weights, str(path), metadata={"terrapref": json.dumps(header)})
    err = _expect_user_error(path, f"names {', '.join([*columns[:-1], 'lava'])} where its class table's feature classes are")
    assert err.problems[0].field == "features.feature_classes"


def test_wrong_format_is_refused(model_file):
    path, config, weights = model_file
    header = {"format": "terrapref-model/99", "classifier": config.to_dict(), **model_meta()}
    save_file(weights, str(path), metadata={"terrapref": json.dumps(header)})
    assert _expect_user_error(path, "terrapref-model/99").problems[0].field == "format"


@pytest.mark.parametrize("key", ["camera", "features", "classes", "profile", "classifier"])
def test_missing_configuration_is_refused(model_file, key: str):
    path, config, weights = model_file
    header = {"format": FORMAT, "classifier": config.to_dict(), **model_meta()}
    del header[key]
    save_file(weights, str(path), metadata={"terrapref": json.dumps(header)})
    assert _expect_user_error(path, key).problems[0].field == key


@pytest.mark.parametrize("key", ["camera", "features", "classes"])
def test_a_configuration_that_is_not_a_mapping_is_refused(model_file, key: str):
    path, config, weights = model_file
    header = {"format": FORMAT, "classifier": config.to_dict(), **model_meta(), key: None}
    save_file(weights, str(path), metadata={"terrapref": json.dumps(header)})
    assert _expect_user_error(path, "expected a mapping").problems[0].field == key


def test_invalid_configuration_is_refused(model_file):
    path, config, weights = model_file
    header = {"format": FORMAT, "classifier": {**config.to_dict(), "activation": "sigmoid"}, **model_meta()}
    save_file(weights, str(path), metadata={"terrapref": json.dumps(header)})
    _expect_user_error(path, "activation")


@pytest.mark.parametrize("v_mps", [1e9, math.inf, 0.0])
def test_a_control_set_faster_than_any_robot_is_refused(model_file, v_mps: float):
    path, config, weights = model_file
    header = {"format": FORMAT, "classifier": config.to_dict(), **model_meta(ODD_FEATURES, ODD_CAMERA, ODD_PROFILE)}
    header["features"]["preference"]["control"]["v_mps"] = v_mps
    save_file(weights, str(path), metadata={"terrapref": json.dumps(header)})
    assert _expect_user_error(path, "v_mps must be > 0 and at most 30 m/s").problems[0].field == "metadata"


@pytest.mark.parametrize("change", ["missing", "extra"])
def test_weights_not_matching_the_classifier_are_refused(model_file, change: str):
    path, config, weights = model_file
    weights = dict(weights)
    if change == "missing":
        del weights[f"layers.{config.depth}.bias"]
    else:
        weights["layers.9.weight"] = np.zeros((2, 2), np.float32)
    save_model(path, config, weights, model_meta(ODD_FEATURES, ODD_CAMERA, ODD_PROFILE))
    err = _expect_user_error(path, "layers.")
    assert err.problems[0].field == "weights"


@pytest.mark.parametrize("name", ["compress.weight", "layers.0.weight", "layers.2.bias"])
def test_weights_of_the_wrong_shape_are_refused(model_file, name: str):
    path, config, weights = model_file
    weights = {**weights, name: np.zeros(tuple(d + 1 for d in weights[name].shape), np.float32)}
    save_model(path, config, weights, model_meta(ODD_FEATURES, ODD_CAMERA, ODD_PROFILE))
    err = _expect_user_error(path, name)
    assert err.problems[0].field == f"weights.{name}"


def test_classifier_not_matching_the_features_is_refused(tmp_path: Path):
    config = ClassifierConfig(m=11)
    path = save_model(tmp_path / "m.safetensors", config, random_weights(config), model_meta())
    assert _expect_user_error(path).problems[0].field == "classifier"


def test_check_compatible_refuses_another_camera(model_file):
    model = load_model(model_file[0])
    check_compatible(model, ODD_CAMERA, ODD_FEATURES)  # its own configuration passes
    with pytest.raises(UserError) as err:
        check_compatible(model, replace(ODD_CAMERA, pitch_deg=30.0))
    assert err.value.source == model.path and err.value.problems[0].field == "camera"
    assert "pitch_deg" in str(err.value) and "mount_height_m" not in str(err.value)


def test_check_compatible_takes_a_calibrated_camera_equal_to_the_one_trained_for(model_file):
    model = load_model(model_file[0])
    fx, fy, cx, cy = ODD_CAMERA.intrinsics
    calibrated = replace(ODD_CAMERA, fx=round(fx, 6), fy=round(fy, 6), cx=cx, cy=cy)  # as a camera_info file gives it
    assert calibrated != ODD_CAMERA and calibrated.same_geometry(ODD_CAMERA)
    check_compatible(model, calibrated, ODD_FEATURES)
    with pytest.raises(UserError, match="another camera"):
        check_compatible(model, replace(calibrated, fx=fx * 1.001))


def test_check_compatible_refuses_a_default_model_under_pitch_25(tmp_path: Path):
    config = ClassifierConfig()
    model = load_model(save_model(tmp_path / "m.safetensors", config, random_weights(config), model_meta()))
    with pytest.raises(UserError) as err:
        check_compatible(model, CameraConfig(pitch_deg=25.0))
    assert str(tmp_path / "m.safetensors") in str(err.value) and "pitch_deg" in str(err.value)


def test_check_compatible_refuses_another_preference_set(tmp_path: Path):
    config = ClassifierConfig()
    model = load_model(save_model(tmp_path / "m.safetensors", config, random_weights(config), model_meta()))
    check_compatible(model, CameraConfig(), FeatureConfig())
    with pytest.raises(UserError) as err:
        check_compatible(model, CameraConfig(), FeatureConfig(PreferenceSetConfig(n_steps=20)))
    assert err.value.source == model.path and err.value.problems[0].field == "features"
    assert "preference" in str(err.value)


def test_check_compatible_names_the_differing_preference_field(tmp_path: Path):
    config = ClassifierConfig()
    model = load_model(save_model(tmp_path / "m.safetensors", config, random_weights(config), model_meta()))
    with pytest.raises(UserError) as err:
        check_compatible(model, CameraConfig(), FeatureConfig(PreferenceSetConfig(n_steps=20)))
    assert "n_steps" in str(err.value)


# --- the header as one record ----------------------------------------------------------------------


def _header(**changes) -> ModelHeader:
    """A finished ensemble's header with every entry training writes."""
    epochs = tuple(EpochMetrics(e, 2.0 / e, 2.5 / e, 0.3, 0.25, 0.6) for e in (1, 2))
    classes = default_classes()
    values = dict(
        classifier=ClassifierConfig(hidden=8, members=2),
        recipe="teach",
        features=ODD_FEATURES,
        camera=ODD_CAMERA,
        classes=classes,
        profile=ODD_PROFILE,
        training=TrainConfig().to_dict(),
        data=DataSource("0123456789abcdef", 40, ({"path": "rec", "frames": 40},)),
        history=epochs,
        best_epoch=2,
        steps=8,
        identifiability={"order": ["mud"], "pairs": [], "min_frames": 20, "lethal": []},
        steadying={"tremor_rps": None, "spacing_rps": 0.1, "window": 1, "changed": 0.0},
        rules=({"type": "second_stage", "weight": 5.0},),
        drives="second_stage",
        members=(MemberRun(0, 2, epochs), MemberRun(1000, 1, epochs)),
        epoch=2,
    )
    return ModelHeader(**{**values, **changes})


def test_a_header_is_written_in_the_files_order_and_read_back_equal(tmp_path: Path):
    header = _header()
    assert list(header.to_dict()) == [
        "format",
        "kind",
        "classifier",
        "recipe",
        "features",
        "camera",
        "classes",
        "profile",
        "training",
        "data",
        "history",
        "best_epoch",
        "steps",
        "identifiability",
        "steadying",
        "rules",
        "drives",
        "members",
        "epoch",
    ]
    config = header.classifier
    weights = {f"members.{j}.{k}": v for j in range(2) for k, v in random_weights(replace(config, members=1), j).items()}
    model = load_model(write_model(tmp_path / "m.safetensors", header, weights))
    assert model.header == header and model.meta == json.loads(json.dumps(header.to_dict()))
    assert model.classifier == config and model.features == ODD_FEATURES and model.header.rules == header.rules


def test_a_checkpoints_member_count_and_an_interrupted_runs_progress_are_its_own_entries():
    checkpoint = _header(
        history=None,
        best_epoch=None,
        steps=None,
        identifiability=None,
        steadying=None,
        rules=None,
        drives=None,
        members=None,
        member_count=2,
        member=1,
        epoch=3,
        status="checkpoint",
    )
    written = checkpoint.to_dict()
    assert list(written)[-4:] == ["member_count", "member", "epoch", "status"] and written["member_count"] == 2
    older = {**{k: v for k, v in written.items() if k != "member_count"}, "members": 2}  # a checkpoint before the count had its own name
    assert ModelHeader.from_dict(older, "old.safetensors") == checkpoint
    assert ModelHeader.from_dict(written, "c.safetensors") == checkpoint
    interrupted = replace(checkpoint, member_count=None, member=None, epoch=None, status="interrupted", interrupted=Interruption(2, (3, 1)))
    written = interrupted.to_dict()
    assert list(written)[-3:] == ["data", "status", "interrupted"] and written["interrupted"]["best_epochs"] == [3, 1]
    assert ModelHeader.from_dict(written, "i.safetensors") == interrupted


@pytest.mark.parametrize(
    "key, value", [("history", [{"epoch": 1}]), ("data", ["rec"]), ("members", "two"), ("best_epoch", 1.5), ("recipe", 3), ("training", [])]
)
def test_a_damaged_training_record_is_refused_naming_its_entry(tmp_path: Path, key: str, value):
    header = _header()
    config = header.classifier
    weights = {f"members.{j}.{k}": v for j in range(2) for k, v in random_weights(replace(config, members=1), j).items()}
    path = write_tensor_file(tmp_path / "m.safetensors", weights, {**header.to_dict(), key: value})
    assert _expect_user_error(path).problems[0].field == key


def test_rules_are_read_without_a_feature_configuration_and_older_files_keys_by_each_rule():
    from terrapref.rules import legacy_blocks

    legacy = {"utility": {"w": [0.0], "b": [0.0]}, "corridor": {"weights": [1.0], "near_m": 2.0}}
    assert legacy_blocks(legacy, "old.safetensors") == (
        {"type": "second_stage", "weight": 1.5, "w": [0.0], "b": [0.0]},
        {"type": "offset", "weights": [1.0], "near_m": 2.0},
    )
    with_lookahead = legacy_blocks({**legacy, "features": {"lookahead": {"after_s": 1.8, "stride": 3}}}, "old.safetensors")
    assert with_lookahead[0] == {"type": "second_stage", "weight": 1.5, "after_s": 1.8, "stride": 3, "w": [0.0], "b": [0.0]}
    assert rule_blocks({"rules": []}, "rules", "new.safetensors") == () and rule_blocks({}, "rules", "checkpoint.safetensors") is None
    assert rule_blocks({"stages": [{"type": "offset"}]}, "stages", "older.safetensors") == ({"type": "offset"},)
    with pytest.raises(UserError) as err:
        rule_blocks({"stages": [{"weight": 1.0}]}, "stages", "bad.safetensors")
    assert err.value.lines() == ["bad.safetensors: stages[0]: expected a mapping with a type"]
    with pytest.raises(UserError) as err:
        legacy_blocks({"corridor": [1.0]}, "bad.safetensors")
    assert err.value.lines() == ["bad.safetensors: corridor: expected a mapping"]


# --- ensembles and sizes in a model file -----------------------------------------------------------


@pytest.mark.parametrize("claimed, held", [(2, 1), (3, 2), (3_000_000, 2), (1, 2)])
def test_an_ensemble_whose_header_disagrees_with_its_members_is_refused(tmp_path: Path, claimed: int, held: int):
    # Checked before any shape is built from the header, so a huge claimed count fails at once.
    one = ClassifierConfig(hidden=8)
    weights = {f"members.{j}.{k}": v for j in range(held) for k, v in random_weights(one, j).items()}
    path = save_model(tmp_path / "m.safetensors", replace(one, members=claimed), weights, model_meta())
    err = _expect_user_error(path, f"header says {claimed} member(s), the weights hold {held}")
    assert err.problems[0].field == "classifier.members"


def test_an_ensemble_whose_members_are_numbered_otherwise_is_refused_saying_so(tmp_path: Path):
    one = ClassifierConfig(hidden=8)
    weights = {f"members.{j}.{k}": v for j in (0, 1, 3) for k, v in random_weights(one, j).items()}
    path = save_model(tmp_path / "m.safetensors", replace(one, members=3), weights, model_meta())
    _expect_user_error(path, "classifier.members: header says 3 member(s), numbered 0 to 2; the weights hold members 0, 1, 3")


def test_a_member_missing_a_weight_is_refused(tmp_path: Path):
    one = ClassifierConfig(hidden=8)
    weights = {f"members.{j}.{k}": v for j in range(2) for k, v in random_weights(one, j).items()}
    del weights["members.1.layers.2.bias"]
    path = save_model(tmp_path / "m.safetensors", replace(one, members=2), weights, model_meta())
    err = _expect_user_error(path, "members.1.layers.2.bias")
    assert err.problems[0].field == "weights"


def test_a_model_header_with_a_fractional_size_is_refused(tmp_path: Path):
    one = ClassifierConfig(hidden=8)
    weights = {f"members.{j}.{k}": v for j in range(2) for k, v in random_weights(one, j).items()}
    path = save_model(tmp_path / "m.safetensors", replace(one, members=2), weights, model_meta())
    weights, meta = read_model_file(path)
    meta["classifier"]["members"] = 2.0
    write_tensor_file(path, weights, meta)
    err = _expect_user_error(path, "integers")
    assert err.problems[0].field == "classifier"


def test_profile_of_the_model_parses(model_file):
    model = load_model(model_file[0])
    assert PreferenceProfile.parse(list(model.profile), model.classes).order == ODD_PROFILE


# --- mirror augmentation ---------------------------------------------------------------------------------


@pytest.mark.parametrize("channels", [1, 2])
def test_a_header_from_before_channels_left_loads_with_one_and_is_refused_with_more(tmp_path: Path, channels: int):
    """Model files written while the compression had a ``channels`` option say ``channels: 1``
    (what C is) and load as they are; a file with more is refused in one line naming the field."""
    config = ClassifierConfig(hidden=8, skip=True)
    weights = random_weights(config)
    header = {"format": FORMAT, "kind": "classifier", "classifier": {**config.to_dict(), "channels": channels}, **model_meta()}
    path = write_tensor_file(tmp_path / "old.safetensors", {k: np.asarray(v, np.float32) for k, v in weights.items()}, header)
    if channels == 1:
        assert load_model(path).classifier == config
        return
    with pytest.raises(UserError) as caught:
        load_model(path)
    lines = caught.value.lines()
    assert len(lines) == 1 and "classifier.channels" in lines[0] and "train the model again" in lines[0], lines
