"""The classifier C and its training (SPEC 8): the NumPy forward pass against PyTorch, seeded
determinism, the paper's recipe, proof that it learns, and safe model files that refuse
anything they cannot vouch for."""

from __future__ import annotations

import json
import pickle
import struct
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch
from safetensors.numpy import save_file

from terrapref.camera import CameraConfig
from terrapref.demos.dataset import FORMAT as DATASET_FORMAT
from terrapref.demos.dataset import Dataset, load_dataset, save_dataset
from terrapref.errors import UserError
from terrapref.features import FeatureConfig, PreferenceSetConfig
from terrapref.learning.model_file import FORMAT, check_compatible, expected_shapes, load_model, read_model_file, save_model
from terrapref.learning.network import ClassifierConfig, numpy_forward, softmax
from terrapref.learning.pipeline import train_and_save
from terrapref.learning.torch_net import UtilityClassifier
from terrapref.learning.train import MEMBER_SEED_STEP, TrainConfig, decisive_frames, split_indices, train
from terrapref.tensorfile import write_tensor_file
from terrapref.terrain import PreferenceProfile, default_classes

from helpers import model_meta

M, K = 21, 5
W_TRUE = np.array([-3.0, -1.5, -0.5, 0.5, 2.0], dtype=np.float32)  # a fixed linear utility over U's columns


def _dataset(U: np.ndarray, labels: np.ndarray) -> Dataset:
    n = len(labels)
    meta = {"format": DATASET_FORMAT, **model_meta()}
    return Dataset(U.astype(np.float32), labels.astype(np.int64), np.zeros(n, np.float32), np.zeros(n, np.int64), meta)


def _random_dataset(n: int, seed: int = 0) -> Dataset:
    """U uniform in [0, 1], labels uniform: nothing to learn, plenty to overfit."""
    rng = np.random.default_rng(seed)
    return _dataset(rng.uniform(0, 1, (n, M, K)), rng.integers(0, M, n))


def _linear_dataset(n: int, margin: float = 0.5, seed: int = 0) -> Dataset:
    """Labels = argmax over trajectories of U @ W_TRUE, keeping samples whose best score beats
    the runner-up by ``margin`` (so that the direction of W_TRUE, not its last digit, decides)."""
    rng = np.random.default_rng(seed)
    kept: list[np.ndarray] = []
    while sum(map(len, kept)) < n:
        U = rng.uniform(0, 1, (n, M, K)).astype(np.float32)
        top2 = np.sort(U @ W_TRUE, axis=1)[:, -2:]
        kept.append(U[top2[:, 1] - top2[:, 0] >= margin])
    U = np.concatenate(kept)[:n]
    return _dataset(U, np.argmax(U @ W_TRUE, axis=1))


def _decisive_dataset(n: int, seed: int = 0) -> Dataset:
    """Sparse terrain and a distance peak, labels sometimes away from the peak: has decisive frames."""
    rng = np.random.default_rng(seed)
    U = np.zeros((n, M, K), np.float32)
    peak = rng.integers(0, M, n)
    U[:, :, -1] = 1.0 - np.abs(np.arange(M)[None] - peak[:, None]) / (M - 1)
    terrain = rng.random(n) < 0.5
    U[terrain, rng.integers(0, M, terrain.sum()), rng.integers(0, K - 1, terrain.sum())] = 1.0
    labels = np.where(terrain & (rng.random(n) < 0.5), rng.integers(0, M, n), peak)
    return _dataset(U, labels)


def _assert_weights_equal(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> None:
    assert set(a) == set(b)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)


def _weights_differ(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> bool:
    return any(not np.array_equal(a[k], b[k]) for k in a)


# --- the NumPy forward pass is the PyTorch network ------------------------------------------------


CONFIGS = [
    ClassifierConfig(),
    ClassifierConfig(activation="tanh"),
    ClassifierConfig(activation="elu"),
    ClassifierConfig(skip=True),
    ClassifierConfig(activation="tanh", skip=True),
    ClassifierConfig(activation="elu", skip=True, hidden=17, depth=2),
    ClassifierConfig(compress=False),
    ClassifierConfig(activation="elu", compress=False, depth=1),
    ClassifierConfig(m=7, n_features=3, hidden=5, depth=4, activation="tanh", skip=True),
    ClassifierConfig(channels=3),
    ClassifierConfig(channels=2, skip=True, activation="elu"),
]


@pytest.mark.parametrize("config", CONFIGS, ids=lambda c: f"{c.activation}-d{c.depth}-h{c.hidden}-m{c.m}k{c.n_features}c{c.channels}{'-skip' if c.skip else ''}{'' if c.compress else '-flat'}")
def test_numpy_forward_equals_torch(config: ClassifierConfig):
    torch.manual_seed(3)
    net = UtilityClassifier(config).eval()
    weights = {k: v.detach().numpy().copy() for k, v in net.state_dict().items()}
    # Wider than [0, 1] so that every activation's negative side is exercised.
    U = np.random.default_rng(1).uniform(-2, 2, (9, config.m, config.n_features)).astype(np.float32)
    U_before, w_before = U.copy(), {k: v.copy() for k, v in weights.items()}
    with torch.no_grad():
        expected = net(torch.from_numpy(U)).numpy()
    batch = numpy_forward(config, weights, U)
    assert batch.shape == (9, config.m)
    np.testing.assert_allclose(batch, expected, atol=1e-5, rtol=0)
    for b in range(len(U)):
        single = numpy_forward(config, weights, U[b])
        assert single.shape == (config.m,)
        np.testing.assert_allclose(single, expected[b], atol=1e-5, rtol=0)
    # The forward pass works in place on its own buffers, never on the caller's.
    np.testing.assert_array_equal(U, U_before)
    _assert_weights_equal(weights, w_before)


def test_skip_adds_the_compressed_scores_to_the_logits():
    config = ClassifierConfig(skip=True, hidden=4)
    torch.manual_seed(0)
    weights = {k: v.detach().numpy().copy() for k, v in UtilityClassifier(config).state_dict().items()}
    U = np.random.default_rng(0).uniform(0, 1, (M, K)).astype(np.float32)
    plain = numpy_forward(replace(config, skip=False), weights, U)
    scores = U @ weights["compress.weight"][0] + weights["compress.bias"][0]
    np.testing.assert_allclose(numpy_forward(config, weights, U), plain + scores, atol=1e-6)


def test_channels_compress_each_row_to_several_scores():
    """Each trajectory's row becomes ``channels`` numbers, laid out trajectory by trajectory;
    the residual path adds the first channel."""
    config = ClassifierConfig(channels=2, skip=True, hidden=4, depth=1)
    torch.manual_seed(0)
    weights = {k: v.detach().numpy().copy() for k, v in UtilityClassifier(config).state_dict().items()}
    assert weights["compress.weight"].shape == (2, K) and weights["layers.0.weight"].shape == (4, 2 * M)
    U = np.random.default_rng(0).uniform(0, 1, (M, K)).astype(np.float32)
    per_row = U @ weights["compress.weight"].T + weights["compress.bias"]  # (m, 2)
    h = np.maximum(per_row.reshape(-1) @ weights["layers.0.weight"].T + weights["layers.0.bias"], 0.0)
    expected = h @ weights["layers.1.weight"].T + weights["layers.1.bias"] + per_row[:, 0]
    np.testing.assert_allclose(numpy_forward(config, weights, U), expected, atol=1e-5)


def test_softmax_is_a_distribution_over_the_last_axis():
    logits = np.array([[1000.0, 1000.0, 0.0], [-5.0, 0.0, 5.0]])
    p = softmax(logits)
    assert np.all(np.isfinite(p))  # no overflow for huge logits
    np.testing.assert_allclose(p.sum(axis=-1), 1.0)
    np.testing.assert_allclose(p[0], [0.5, 0.5, 0.0], atol=1e-12)
    np.testing.assert_array_equal(np.argmax(p, axis=-1), np.argmax(logits, axis=-1))


@pytest.mark.parametrize("bad", [dict(activation="sigmoid"), dict(m=1), dict(hidden=0), dict(depth=0), dict(skip=True, compress=False), dict(channels=0)])
def test_classifier_config_is_validated(bad: dict):
    with pytest.raises(ValueError):
        ClassifierConfig(**bad)


# --- the paper's recipe ----------------------------------------------------------------------------


def test_defaults_are_the_papers_recipe():
    c = TrainConfig()
    assert (c.epochs, c.lr, c.batch_size, c.val_fraction) == (15, 1e-3, 256, 0.2)
    assert c.decisive_weight == 1.0 and not c.class_balance and not c.skip and c.depth == 3


def test_paper_budget_is_an_80_20_split_and_135_adam_steps():
    """SPEC 15: 2726 samples, 80% for training, batch 256, 15 epochs is 135 steps."""
    tr, va = split_indices(2726, 0.2, np.random.default_rng(0))
    assert (len(tr), len(va)) == (2181, 545)
    assert len(np.intersect1d(tr, va)) == 0
    np.testing.assert_array_equal(np.union1d(tr, va), np.arange(2726))
    result = train(_random_dataset(2726))
    assert result.steps == 15 * 9 == 135  # ceil(2181 / 256) = 9 batches per epoch
    assert [h.epoch for h in result.history] == list(range(1, 16))


def test_val_fraction_zero_holds_out_nothing():
    tr, va = split_indices(100, 0.0, np.random.default_rng(0))
    assert len(va) == 0 and len(tr) == 100


@pytest.mark.parametrize("bad", [dict(epochs=0), dict(batch_size=0), dict(lr=0.0), dict(val_fraction=1.0), dict(activation="sigmoid")])
def test_train_config_is_validated(bad: dict):
    with pytest.raises(ValueError):
        TrainConfig(**bad)


def test_training_is_deterministic_per_seed():
    data = _random_dataset(600)
    config = TrainConfig(epochs=3, batch_size=64, hidden=16)
    a, b = train(data, config), train(data, config)
    _assert_weights_equal(a.weights, b.weights)
    assert a.history == b.history and a.best_epoch == b.best_epoch and a.steps == b.steps
    for ca, cb in zip(a.checkpoints, b.checkpoints, strict=True):
        _assert_weights_equal(ca, cb)
    c = train(data, replace(config, seed=1))
    assert _weights_differ(a.weights, c.weights)
    assert a.history != c.history


def test_training_does_not_touch_torch():
    """C trains in NumPy: PyTorch's global settings (threads, determinism) are never read or set."""
    threads, deterministic = torch.get_num_threads(), torch.are_deterministic_algorithms_enabled()
    train(_random_dataset(100), TrainConfig(epochs=1))
    assert torch.get_num_threads() == threads and torch.are_deterministic_algorithms_enabled() == deterministic


def test_chosen_epoch_is_the_lowest_validation_loss():
    # Random labels and a high learning rate: the network memorises, so validation loss turns up.
    result = train(_random_dataset(600), TrainConfig(epochs=12, lr=1e-2, batch_size=32, hidden=64))
    losses = [h.val_loss for h in result.history]
    assert result.best_epoch == int(np.argmin(losses)) + 1
    assert result.best_epoch < len(losses)  # the interesting case: not simply the last epoch
    _assert_weights_equal(result.weights, result.checkpoints[result.best_epoch - 1])


def test_one_checkpoint_per_epoch():
    result = train(_random_dataset(300), TrainConfig(epochs=4, batch_size=64))
    assert len(result.checkpoints) == len(result.history) == 4
    for a, b in zip(result.checkpoints, result.checkpoints[1:]):
        assert _weights_differ(a, b)


# --- ensembles: members trained apart, F_t averaged -------------------------------------------------


def test_ensemble_forward_is_the_log_of_the_members_mean_softmax():
    one = ClassifierConfig(hidden=8, skip=True)
    members = [_random_weights(one, seed) for seed in (0, 1, 2)]
    config = replace(one, members=3)
    weights = {f"members.{j}.{k}": v for j, w in enumerate(members) for k, v in w.items()}
    U = np.random.default_rng(2).uniform(0, 1, (4, M, K)).astype(np.float32)
    mean = np.mean([softmax(numpy_forward(one, w, U)) for w in members], axis=0)
    np.testing.assert_allclose(softmax(numpy_forward(config, weights, U)), mean, atol=1e-6)
    np.testing.assert_allclose(softmax(numpy_forward(config, weights, U[1])), mean[1], atol=1e-6)
    assert set(expected_shapes(config)) == set(weights)


def test_members_train_apart_from_their_own_seeds():
    data = _random_dataset(400)
    config = TrainConfig(epochs=2, batch_size=64, hidden=16, seed=5, members=2)
    result = train(data, config)
    assert result.classifier.members == 2 and len(result.members) == 2
    # Member j is exactly what training alone from seed + MEMBER_SEED_STEP * j gives.
    for j, member in enumerate(result.members):
        alone = train(data, replace(config, members=1, seed=5 + MEMBER_SEED_STEP * j))
        _assert_weights_equal(member.weights, alone.weights)
        _assert_weights_equal({k[len(f"members.{j}."):]: v for k, v in result.weights.items() if k.startswith(f"members.{j}.")}, alone.weights)
    assert _weights_differ(result.members[0].weights, result.members[1].weights)
    assert result.history == result.members[0].history and result.steps == sum(m.steps for m in result.members)
    assert len(result.checkpoints) == 2 and set(result.checkpoints[0]) == set(result.weights)


def test_an_ensemble_model_file_loads_and_records_its_members(tmp_path: Path):
    data = _random_dataset(300)
    config = TrainConfig(epochs=2, batch_size=64, hidden=8, seed=3, members=2)
    path = tmp_path / "ens.safetensors"
    result = train_and_save(data, path, config, checkpoints=False)
    model = load_model(path)
    assert model.classifier.members == 2 and model.meta["training"]["members"] == 2
    assert [m["seed"] for m in model.meta["members"]] == [3, 3 + MEMBER_SEED_STEP]
    assert [m["best_epoch"] for m in model.meta["members"]] == [r.best_epoch for r in result.members]
    U = data.U[:5]
    for b in range(5):
        mean = np.mean([softmax(numpy_forward(r.classifier, r.weights, U[b])) for r in result.members], axis=0)
        np.testing.assert_allclose(softmax(numpy_forward(model.classifier, model.weights, U[b])), mean, atol=1e-6)


@pytest.mark.parametrize("claimed, held", [(2, 1), (3, 2), (3_000_000, 2), (1, 2)])
def test_an_ensemble_whose_header_disagrees_with_its_members_is_refused(tmp_path: Path, claimed: int, held: int):
    # Checked before any shape is built from the header, so a huge claimed count fails at once.
    one = ClassifierConfig(hidden=8)
    weights = {f"members.{j}.{k}": v for j in range(held) for k, v in _random_weights(one, j).items()}
    path = save_model(tmp_path / "m.safetensors", replace(one, members=claimed), weights, model_meta())
    err = _expect_user_error(path, f"header says {claimed} member(s), the weights hold {held}")
    assert err.problems[0].field == "classifier.members"


def test_a_member_missing_a_weight_is_refused(tmp_path: Path):
    one = ClassifierConfig(hidden=8)
    weights = {f"members.{j}.{k}": v for j in range(2) for k, v in _random_weights(one, j).items()}
    del weights["members.1.layers.2.bias"]
    path = save_model(tmp_path / "m.safetensors", replace(one, members=2), weights, model_meta())
    err = _expect_user_error(path, "members.1.layers.2.bias")
    assert err.problems[0].field == "weights"


@pytest.mark.parametrize("bad", [{"members": 0}])
def test_members_must_be_positive(bad: dict):
    with pytest.raises(ValueError, match="members"):
        TrainConfig(**bad)
    with pytest.raises(ValueError, match="members"):
        ClassifierConfig(**bad)


@pytest.mark.parametrize("field", ["m", "n_features", "hidden", "depth", "channels", "members"])
@pytest.mark.parametrize("value", [2.0, True, "2"])
def test_classifier_sizes_must_be_integers(field: str, value):
    with pytest.raises(ValueError, match="integers"):
        ClassifierConfig(**{field: value})


def test_a_model_header_with_a_fractional_size_is_refused(tmp_path: Path):
    one = ClassifierConfig(hidden=8)
    weights = {f"members.{j}.{k}": v for j in range(2) for k, v in _random_weights(one, j).items()}
    path = save_model(tmp_path / "m.safetensors", replace(one, members=2), weights, model_meta())
    weights, meta = read_model_file(path)
    meta["classifier"]["members"] = 2.0
    write_tensor_file(path, weights, meta)
    err = _expect_user_error(path, "integers")
    assert err.problems[0].field == "classifier"


def test_decisive_frames_closed_form():
    U = np.zeros((3, M, K), np.float32)
    U[:, :, -1] = np.linspace(0, 1, M)  # the path follower's choice is the last trajectory
    U[1:, 4, 2] = 0.5  # terrain in view in frames 1 and 2
    labels = np.array([3, M - 1, 3])
    # frame 0: no terrain; frame 1: terrain, but the label is the path follower's; frame 2: decisive
    np.testing.assert_array_equal(decisive_frames(U, labels), [False, False, True])


def test_terrain_seen_only_on_the_lanes_does_not_make_a_frame_decisive():
    k = K - 1
    U = np.zeros((2, M, 2 * k + 1), np.float32)
    U[:, :, -1] = np.linspace(0, 1, M)
    U[0, 4, k + 1] = 0.5  # frame 0: mud on a lane only
    U[1, 4, 1] = 0.5  # frame 1: mud on a trajectory
    labels = np.array([3, 3])
    np.testing.assert_array_equal(decisive_frames(U, labels, n_terrain=k), [False, True])
    np.testing.assert_array_equal(decisive_frames(U, labels), [True, True])  # counted as terrain without n_terrain


def test_decisive_weight_one_is_the_default():
    data = _decisive_dataset(500)
    assert decisive_frames(data.U, data.labels).sum() > 20
    config = TrainConfig(epochs=3, batch_size=64, hidden=16)
    a, b = train(data, config), train(data, replace(config, decisive_weight=1.0))
    _assert_weights_equal(a.weights, b.weights)
    assert a.history == b.history
    # ... and the knob is connected: another weight changes the result on this data.
    c = train(data, replace(config, decisive_weight=5.0))
    assert _weights_differ(a.weights, c.weights)


def test_class_balance_changes_the_loss_only_when_asked():
    data = _decisive_dataset(500)
    config = TrainConfig(epochs=2, batch_size=64, hidden=16)
    a, b = train(data, config), train(data, replace(config, class_balance=True))
    assert _weights_differ(a.weights, b.weights)
    assert np.isfinite([h.train_loss for h in b.history]).all()


def test_a_linear_preference_is_learned():
    """Labels that are the argmax of a fixed linear utility of U are learnable by C (skip on):
    validation accuracy well above the majority class (about 1/21 here) proves learning works."""
    data = _linear_dataset(4000)
    majority = np.bincount(data.labels).max() / len(data)
    assert majority < 0.2
    result = train(data, TrainConfig(epochs=30, lr=3e-3, batch_size=64, skip=True))
    best = result.history[result.best_epoch - 1]
    assert best.val_acc > 0.9, [round(h.val_acc, 3) for h in result.history]
    assert best.val_top3 > best.val_acc
    # The learned compression ranks the utilities as W_TRUE does.
    w = result.weights["compress.weight"][0]
    assert list(np.argsort(w)) == list(np.argsort(W_TRUE)), w
    # The deployed NumPy classifier agrees with the training-time validation accuracy.
    tr, va = split_indices(len(data), 0.2, np.random.default_rng(0))
    pred = np.argmax(numpy_forward(result.classifier, result.weights, data.U[va]), axis=1)
    assert abs(float((pred == data.labels[va]).mean()) - best.val_acc) < 1e-6


# --- model files -------------------------------------------------------------------------------------


def _random_weights(config: ClassifierConfig, seed: int = 0) -> dict[str, np.ndarray]:
    torch.manual_seed(seed)
    return {k: v.detach().numpy().copy() for k, v in UtilityClassifier(config).state_dict().items()}


ODD_FEATURES = FeatureConfig(PreferenceSetConfig(n_steps=20, dt_s=0.25), distance_mode="window", window_m=9.0, path_spacing_m=0.5)
ODD_CAMERA = CameraConfig(pitch_deg=25.0, max_range_m=20.0, mount_height_m=1.2)
ODD_PROFILE = ("mud", "rock", "water", "non_traversable")


@pytest.fixture
def model_file(tmp_path: Path) -> tuple[Path, ClassifierConfig, dict[str, np.ndarray]]:
    config = ClassifierConfig(hidden=16, activation="tanh", depth=2, skip=True, channels=2)
    weights = _random_weights(config)
    path = save_model(tmp_path / "sub" / "model.safetensors", config, weights, {**model_meta(ODD_FEATURES, ODD_CAMERA, ODD_PROFILE), "note": "kept"})
    return path, config, weights


def test_model_file_round_trip(model_file):
    path, config, weights = model_file
    model = load_model(path)
    assert model.path == str(path)
    assert model.classifier == config
    _assert_weights_equal(model.weights, weights)
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


def test_non_model_safetensors_is_refused(tmp_path: Path):
    path = tmp_path / "weights.safetensors"
    save_file({"x": np.zeros(3, np.float32)}, str(path))
    err = _expect_user_error(path, "metadata")
    assert err.problems[0].field == "metadata"


def test_dataset_file_round_trip(tmp_path: Path):
    data = _decisive_dataset(50)
    back = load_dataset(save_dataset(data, tmp_path / "d.safetensors"))
    for name in ("U", "labels", "w", "source"):
        np.testing.assert_array_equal(getattr(back, name), getattr(data, name))
    assert back.fingerprint == data.fingerprint and back.meta["samples"] == 50
    assert back.feature_config == data.feature_config and back.camera_config == data.camera_config


def test_dataset_without_format_in_meta_round_trips(tmp_path: Path):
    data = _random_dataset(20)
    data = Dataset(data.U, data.labels, data.w, data.source, {k: v for k, v in data.meta.items() if k != "format"})
    back = load_dataset(save_dataset(data, tmp_path / "d.safetensors"))
    np.testing.assert_array_equal(back.U, data.U)


def test_dataset_file_is_not_a_model(tmp_path: Path):
    path = save_dataset(_random_dataset(10), tmp_path / "data.safetensors")
    err = _expect_user_error(path, FORMAT)
    assert err.problems[0].field == "format"


@pytest.mark.parametrize("metadata", [{"other": "x"}, {"terrapref": "{not json"}], ids=["no-terrapref-key", "bad-json"])
def test_missing_metadata_is_refused(model_file, metadata: dict):
    path, _, weights = model_file
    save_file(weights, str(path), metadata=metadata)
    assert _expect_user_error(path, "metadata").problems[0].field == "metadata"


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


def test_invalid_configuration_is_refused(model_file):
    path, config, weights = model_file
    header = {"format": FORMAT, "classifier": {**config.to_dict(), "activation": "sigmoid"}, **model_meta()}
    save_file(weights, str(path), metadata={"terrapref": json.dumps(header)})
    _expect_user_error(path, "activation")


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
    path = save_model(tmp_path / "m.safetensors", config, _random_weights(config), model_meta())
    assert _expect_user_error(path).problems[0].field == "classifier"


def test_check_compatible_refuses_another_camera(model_file):
    model = load_model(model_file[0])
    check_compatible(model, ODD_CAMERA, ODD_FEATURES)  # its own configuration passes
    with pytest.raises(UserError) as err:
        check_compatible(model, replace(ODD_CAMERA, pitch_deg=30.0))
    assert err.value.source == model.path and err.value.problems[0].field == "camera"
    assert "pitch_deg" in str(err.value) and "mount_height_m" not in str(err.value)


def test_check_compatible_refuses_a_default_model_under_pitch_25(tmp_path: Path):
    config = ClassifierConfig()
    model = load_model(save_model(tmp_path / "m.safetensors", config, _random_weights(config), model_meta()))
    with pytest.raises(UserError) as err:
        check_compatible(model, CameraConfig(pitch_deg=25.0))
    assert str(tmp_path / "m.safetensors") in str(err.value) and "pitch_deg" in str(err.value)


def test_check_compatible_refuses_another_preference_set(tmp_path: Path):
    config = ClassifierConfig()
    model = load_model(save_model(tmp_path / "m.safetensors", config, _random_weights(config), model_meta()))
    check_compatible(model, CameraConfig(), FeatureConfig())
    with pytest.raises(UserError) as err:
        check_compatible(model, CameraConfig(), FeatureConfig(PreferenceSetConfig(n_steps=20)))
    assert err.value.source == model.path and err.value.problems[0].field == "features"
    assert "preference" in str(err.value)


def test_check_compatible_names_the_differing_preference_field(tmp_path: Path):
    config = ClassifierConfig()
    model = load_model(save_model(tmp_path / "m.safetensors", config, _random_weights(config), model_meta()))
    with pytest.raises(UserError) as err:
        check_compatible(model, CameraConfig(), FeatureConfig(PreferenceSetConfig(n_steps=20)))
    assert "n_steps" in str(err.value)


# --- train and save ----------------------------------------------------------------------------------


def test_train_and_save_writes_the_model_and_every_checkpoint(tmp_path: Path):
    data = _random_dataset(400)
    out = tmp_path / "models" / "pref.safetensors"
    result = train_and_save(data, out, TrainConfig(epochs=3, batch_size=64, hidden=16))
    model = load_model(out)
    _assert_weights_equal(model.weights, result.weights)
    assert model.classifier == result.classifier
    assert model.meta["best_epoch"] == model.meta["epoch"] == result.best_epoch
    assert model.meta["steps"] == result.steps
    assert model.meta["training"]["hidden"] == 16
    assert model.meta["data"]["samples"] == 400 and model.meta["data"]["fingerprint"] == data.fingerprint
    assert [h["val_loss"] for h in model.meta["history"]] == [h.val_loss for h in result.history]
    assert model.features == data.feature_config and model.camera == data.camera_config
    folder = tmp_path / "models" / "pref.checkpoints"
    assert sorted(p.name for p in folder.iterdir()) == ["epoch_001.safetensors", "epoch_002.safetensors", "epoch_003.safetensors"]
    for i, weights in enumerate(result.checkpoints, start=1):
        ck = load_model(folder / f"epoch_{i:03d}.safetensors")
        assert ck.meta["epoch"] == i
        _assert_weights_equal(ck.weights, weights)


def test_train_and_save_without_checkpoints(tmp_path: Path):
    out = tmp_path / "pref.safetensors"
    train_and_save(_random_dataset(100), out, TrainConfig(epochs=1), checkpoints=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pref.safetensors"]


def test_profile_of_the_model_parses(model_file):
    model = load_model(model_file[0])
    assert PreferenceProfile.parse(list(model.profile), model.classes).order == ODD_PROFILE


# --- mirror augmentation ---------------------------------------------------------------------------------


def test_mirror_learns_the_unseen_side():
    """A dataset whose preference is only ever shown with the better arcs on the left is learned
    for the right side too when mirrored copies are added (the preference has no side)."""
    data = _linear_dataset(4000)
    left = data.labels >= 10  # keep only decisions toward w >= 0
    shown = _dataset(data.U[left], data.labels[left])
    mirrored = _dataset(data.U[~left], data.labels[~left])  # the other side, never shown
    cfg = dict(epochs=30, lr=3e-3, batch_size=64, skip=True)
    plain = train(shown, TrainConfig(**cfg))
    mirror = train(shown, TrainConfig(**cfg, mirror=True))

    def acc(result) -> float:
        pred = np.argmax(numpy_forward(result.classifier, result.weights, mirrored.U), axis=1)
        return float((pred == mirrored.labels).mean())

    assert acc(mirror) > 0.8 and acc(mirror) > acc(plain) + 0.2, (acc(plain), acc(mirror))


def test_mirror_needs_a_symmetric_control_set():
    from dataclasses import replace

    from terrapref.features import FeatureConfig
    from terrapref.vehicle import ControlSet

    data = _linear_dataset(200)
    fc = FeatureConfig()
    skewed = replace(fc, preference=replace(fc.preference, control=ControlSet(1.0, tuple(np.linspace(-1.0, 0.6, 21).round(6)))))
    data = Dataset(data.U, data.labels, data.w, data.source, {**data.meta, "features": skewed.to_dict()})
    with pytest.raises(ValueError, match="symmetric"):
        train(data, TrainConfig(epochs=1, mirror=True))


def test_run_recipe_demonstrates_corrects_and_reuses_demonstrations(tmp_path):
    from terrapref.recipes import Recipe, run_recipe
    from terrapref.learning.train import TrainConfig

    recipe = Recipe("tiny", demonstrations=1, corrections=1, train=TrainConfig(epochs=2))
    out = run_recipe(recipe, tmp_path, 0, course="demo_course")
    assert out.model.exists()
    assert [p.name for p in out.recordings] == ["demo_0", "corrections_0"]
    assert out.demo_minutes > 0 and out.correction_minutes > 0
    stamp = (tmp_path / "demo_0" / "meta.json").stat().st_mtime_ns
    again = run_recipe(Recipe("plain", demonstrations=1, train=TrainConfig(epochs=2)), tmp_path, 0, course="demo_course")
    assert again.recordings == [tmp_path / "demo_0"] and again.correction_minutes == 0
    assert (tmp_path / "demo_0" / "meta.json").stat().st_mtime_ns == stamp  # reused, not recorded again


def test_practice_courses_are_generated_per_training_seed_outside_the_selection_range():
    from terrapref.recipes import Recipe, practice_courses
    from terrapref.scenario import resolve_scenario

    recipe = Recipe("p", demonstrations=1, practice=2)
    assert practice_courses(recipe, 0) == ["gen:3000", "gen:5000"]
    assert practice_courses(recipe, 4) == ["gen:43000", "gen:45000"]
    assert practice_courses(Recipe("none"), 3) == []
    names = {c for s in range(5) for c in practice_courses(recipe, s)}
    assert len(names) == 10 and not any(1000 <= int(c[4:]) < 2000 for c in names)
    assert len(resolve_scenario("gen:3000").zones) > 0
    with pytest.raises(ValueError, match="practice"):
        Recipe("bad", practice=-1)


def test_run_recipe_demonstrates_the_practice_courses_and_rerecords_a_course_mismatch(tmp_path, monkeypatch):
    import terrapref.recipes as recipe_mod
    from terrapref.demos.recording import read_recording
    from terrapref.recipes import Recipe, record_demonstrations, run_recipe

    monkeypatch.setattr(recipe_mod, "practice_courses", lambda recipe, seed: ["demo_course"] * recipe.practice)
    recipe = Recipe("practised", demonstrations=1, practice=1, train=TrainConfig(epochs=2))
    out = run_recipe(recipe, tmp_path, 0, course="demo_course")
    assert [p.name for p in out.recordings] == ["demo_0", "practice_0"]
    practice = read_recording(tmp_path / "practice_0")
    assert practice.complete and practice.meta["driver"]["seed"] == 20  # its own seed, not demo_0's
    assert out.demo_minutes > 0
    # A recording of another course in the practice slot is not taken for the practice run.
    meta_path = tmp_path / "practice_0" / "meta.json"
    meta_path.write_text(json.dumps({**json.loads(meta_path.read_text()), "scenario": "another_course"}))
    logged: list[str] = []
    record_demonstrations(Recipe("p", demonstrations=1, practice=1), tmp_path, 0, course="demo_course", log=logged.append)
    assert read_recording(tmp_path / "practice_0").meta["scenario"] == "demo_course"
    assert len(logged) == 1 and "(demo_course)" in logged[0] and logged[0].startswith("demonstration 2/2")  # demo_0 reused


def test_an_interrupted_training_leaves_its_best_so_far_and_touches_nothing_else(tmp_path: Path):
    from terrapref.learning.pipeline import interrupted_path

    data = _interrupt_dataset()
    out = tmp_path / "model.safetensors"
    config = TrainConfig(epochs=4, members=3, hidden=8, batch_size=64)
    train_and_save(data, out, replace(config, members=1))  # an earlier model and its checkpoints
    before = out.read_bytes()
    old_checkpoints = sorted(p.name for p in (tmp_path / "model.checkpoints").iterdir())
    seen = []

    def stop(m) -> None:
        seen.append(m.epoch)
        if len(seen) == 6:  # member 2, epoch 2
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        train_and_save(data, out, config, progress=stop)
    assert out.read_bytes() == before  # the earlier model is untouched
    assert sorted(p.name for p in (tmp_path / "model.checkpoints").iterdir()) == old_checkpoints
    partial = load_model(interrupted_path(out))
    assert partial.meta["status"] == "interrupted" and partial.classifier.members == 2  # member 1 whole, member 2 so far
    assert partial.meta["interrupted"]["members_reached"] == 2
    assert sorted(p.name for p in (tmp_path / "model.checkpoints.interrupted").iterdir()) == ["member_1", "member_2"]
    assert len(list((tmp_path / "model.checkpoints.interrupted" / "member_2").iterdir())) == 2
    # A complete retrain replaces the old checkpoints wholly: none of another run is left beside.
    train_and_save(data, out, replace(config, members=2, epochs=2))
    assert sorted(p.name for p in (tmp_path / "model.checkpoints").iterdir()) == ["member_1", "member_2"]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def _interrupt_dataset() -> Dataset:
    rng = np.random.default_rng(0)
    n = 200
    return Dataset(rng.uniform(0, 1, (n, 21, 5)).astype(np.float32), rng.integers(0, 21, n), np.zeros(n, np.float32), np.zeros(n, np.int64),
                   {"format": DATASET_FORMAT, **model_meta()})
