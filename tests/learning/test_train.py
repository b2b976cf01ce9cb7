"""Training C: the paper's recipe and its budget, seeded determinism, ensembles, decisive frames,
class balance, proof that it learns, train-and-save with checkpoints, mirrored samples, and an
interrupted training."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from helpers import (
    W_TRUE,
    K,
    M,
    assert_weights_equal,
    dataset_of,
    linear_dataset,
    model_meta,
    random_dataset,
    random_weights,
    sparse_terrain_dataset,
    train_config,
    weights_differ,
)
from terrapref.dataset import FORMAT as DATASET_FORMAT
from terrapref.dataset import Dataset
from terrapref.learning.model_file import expected_shapes, load_model
from terrapref.learning.network import ClassifierConfig, numpy_forward, softmax
from terrapref.learning.pipeline import RunOptions, train_and_save
from terrapref.learning.train import MEMBER_SEED_STEP, TrainConfig, split_indices, train
from terrapref.rules import SecondStageConfig

# --- the paper's recipe ----------------------------------------------------------------------------


def test_defaults_are_the_papers_recipe():
    c = TrainConfig()
    assert (c.optimiser.epochs, c.optimiser.lr, c.optimiser.batch_size, c.optimiser.val_fraction) == (15, 1e-3, 256, 0.2)
    assert not c.data.class_balance and not c.classifier.skip and c.classifier.depth == 3


def test_paper_budget_is_an_80_20_split_and_135_adam_steps():
    """SPEC 15: 2726 samples, 80% for training, batch 256, 15 epochs is 135 steps."""
    tr, va = split_indices(2726, 0.2, np.random.default_rng(0))
    assert (len(tr), len(va)) == (2181, 545)
    assert len(np.intersect1d(tr, va)) == 0
    np.testing.assert_array_equal(np.union1d(tr, va), np.arange(2726))
    result = train(random_dataset(2726))
    assert result.steps == 15 * 9 == 135  # ceil(2181 / 256) = 9 batches per epoch
    assert [h.epoch for h in result.history] == list(range(1, 16))


def test_val_fraction_zero_holds_out_nothing():
    tr, va = split_indices(100, 0.0, np.random.default_rng(0))
    assert len(va) == 0 and len(tr) == 100


@pytest.mark.parametrize("bad", [dict(epochs=0), dict(batch_size=0), dict(lr=0.0), dict(val_fraction=1.0), dict(activation="sigmoid")])
def test_train_config_is_validated(bad: dict):
    with pytest.raises(ValueError):
        train_config(**bad)


def test_training_is_deterministic_per_seed():
    data = random_dataset(600)
    config = train_config(epochs=3, batch_size=64, hidden=16)
    a, b = train(data, config), train(data, config)
    assert_weights_equal(a.weights, b.weights)
    assert a.history == b.history and a.best_epoch == b.best_epoch and a.steps == b.steps
    for ca, cb in zip(a.checkpoints, b.checkpoints, strict=True):
        assert_weights_equal(ca, cb)
    c = train(data, replace(config, seed=1))
    assert weights_differ(a.weights, c.weights)
    assert a.history != c.history


def test_training_does_not_touch_torch():
    """C trains in NumPy: PyTorch's global settings (threads, determinism) are never read or set."""
    threads, deterministic = torch.get_num_threads(), torch.are_deterministic_algorithms_enabled()
    train(random_dataset(100), train_config(epochs=1))
    assert torch.get_num_threads() == threads and torch.are_deterministic_algorithms_enabled() == deterministic


def test_chosen_epoch_is_the_lowest_validation_loss():
    # Random labels and a high learning rate: the network memorises, so validation loss turns up.
    result = train(random_dataset(600), train_config(epochs=12, lr=1e-2, batch_size=32, hidden=64))
    losses = [h.val_loss for h in result.history]
    assert result.best_epoch == int(np.argmin(losses)) + 1
    assert result.best_epoch < len(losses)  # the interesting case: not simply the last epoch
    assert_weights_equal(result.weights, result.checkpoints[result.best_epoch - 1])


def test_one_checkpoint_per_epoch():
    result = train(random_dataset(300), train_config(epochs=4, batch_size=64))
    assert len(result.checkpoints) == len(result.history) == 4
    for a, b in zip(result.checkpoints, result.checkpoints[1:]):
        assert weights_differ(a, b)


# --- ensembles: members trained apart, F_t averaged -------------------------------------------------


def test_ensemble_forward_is_the_log_of_the_members_mean_softmax():
    one = ClassifierConfig(hidden=8, skip=True)
    members = [random_weights(one, seed) for seed in (0, 1, 2)]
    config = replace(one, members=3)
    weights = {f"members.{j}.{k}": v for j, w in enumerate(members) for k, v in w.items()}
    U = np.random.default_rng(2).uniform(0, 1, (4, M, K)).astype(np.float32)
    mean = np.mean([softmax(numpy_forward(one, w, U)) for w in members], axis=0)
    np.testing.assert_allclose(softmax(numpy_forward(config, weights, U)), mean, atol=1e-6)
    np.testing.assert_allclose(softmax(numpy_forward(config, weights, U[1])), mean[1], atol=1e-6)
    assert set(expected_shapes(config)) == set(weights)


def test_members_train_apart_from_their_own_seeds():
    data = random_dataset(400)
    config = train_config(epochs=2, batch_size=64, hidden=16, seed=5, members=2)
    result = train(data, config)
    assert result.classifier.members == 2 and len(result.members) == 2
    # Member j is exactly what training alone from seed + MEMBER_SEED_STEP * j gives.
    for j, member in enumerate(result.members):
        alone = train(data, train_config(config, members=1, seed=5 + MEMBER_SEED_STEP * j))
        assert_weights_equal(member.weights, alone.weights)
        assert_weights_equal(
            {k[len(f"members.{j}.") :]: v for k, v in result.weights.items() if k.startswith(f"members.{j}.")}, alone.weights
        )
    assert weights_differ(result.members[0].weights, result.members[1].weights)
    assert result.history == result.members[0].history and result.steps == sum(m.steps for m in result.members)
    assert len(result.checkpoints) == 2 and set(result.checkpoints[0]) == set(result.weights)


def test_an_ensemble_model_file_loads_and_records_its_members(tmp_path: Path):
    data = random_dataset(300)
    config = train_config(epochs=2, batch_size=64, hidden=8, seed=3, members=2)
    path = tmp_path / "ens.safetensors"
    result = train_and_save(data, path, config, options=RunOptions(checkpoints=False))
    model = load_model(path)
    assert model.classifier.members == 2 and model.meta["training"]["classifier"]["members"] == 2
    assert [m["seed"] for m in model.meta["members"]] == [3, 3 + MEMBER_SEED_STEP]
    assert [m["best_epoch"] for m in model.meta["members"]] == [r.best_epoch for r in result.members]
    U = data.U[:5]
    for b in range(5):
        mean = np.mean([softmax(numpy_forward(r.classifier, r.weights, U[b])) for r in result.members], axis=0)
        np.testing.assert_allclose(softmax(numpy_forward(model.classifier, model.weights, U[b])), mean, atol=1e-6)


@pytest.mark.parametrize("bad", [{"members": 0}])
def test_members_must_be_positive(bad: dict):
    with pytest.raises(ValueError, match="members"):
        train_config(**bad)
    with pytest.raises(ValueError, match="members"):
        ClassifierConfig(**bad)


@pytest.mark.parametrize("field", ["m", "n_features", "hidden", "depth", "members"])
@pytest.mark.parametrize("value", [2.0, True, "2"])
def test_classifier_sizes_must_be_integers(field: str, value):
    with pytest.raises(ValueError, match="integers"):
        ClassifierConfig(**{field: value})


def test_class_balance_changes_the_loss_only_when_asked():
    data = sparse_terrain_dataset(500)
    config = train_config(epochs=2, batch_size=64, hidden=16)
    a, b = train(data, config), train(data, train_config(config, class_balance=True))
    assert weights_differ(a.weights, b.weights)
    assert np.isfinite([h.train_loss for h in b.history]).all()


def test_a_linear_preference_is_learned():
    """Labels that are the argmax of a fixed linear utility of U are learnable by C (skip on):
    validation accuracy well above the majority class (about 1/21 here) proves learning works."""
    data = linear_dataset(4000)
    majority = np.bincount(data.labels).max() / len(data)
    assert majority < 0.2
    result = train(data, train_config(epochs=30, lr=3e-3, batch_size=64, skip=True))
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


# --- train and save ----------------------------------------------------------------------------------


def test_train_and_save_writes_the_model_and_every_checkpoint(tmp_path: Path):
    data = random_dataset(400)
    out = tmp_path / "models" / "pref.safetensors"
    result = train_and_save(data, out, train_config(epochs=3, batch_size=64, hidden=16))
    model = load_model(out)
    assert_weights_equal(model.weights, result.weights)
    assert model.classifier == result.classifier
    assert model.meta["best_epoch"] == model.meta["epoch"] == result.best_epoch
    assert model.meta["steps"] == result.steps
    assert model.meta["training"]["classifier"]["hidden"] == 16
    assert model.meta["data"]["samples"] == 400 and model.meta["data"]["fingerprint"] == data.fingerprint
    assert [h["val_loss"] for h in model.meta["history"]] == [h.val_loss for h in result.history]
    assert model.features == data.feature_config and model.camera == data.camera_config
    folder = tmp_path / "models" / "pref.checkpoints"
    assert sorted(p.name for p in folder.iterdir()) == ["epoch_001.safetensors", "epoch_002.safetensors", "epoch_003.safetensors"]
    for i, weights in enumerate(result.checkpoints, start=1):
        ck = load_model(folder / f"epoch_{i:03d}.safetensors")
        assert ck.meta["epoch"] == i
        assert_weights_equal(ck.weights, weights)


def test_a_diverged_fit_is_one_error_naming_the_model_and_leaves_nothing_behind(tmp_path: Path):
    """A learning rate that sends the weights to NaN in the first epoch: one error naming the
    model and --lr, and no checkpoints folder, no interrupted model of weights no command could read."""
    from terrapref.errors import UserError

    out = tmp_path / "pref.safetensors"
    with pytest.raises(UserError) as err:
        train_and_save(random_dataset(400), out, train_config(epochs=2, batch_size=64, hidden=16, lr=1e300))
    assert err.value.source == str(out) and "diverged" in str(err.value) and "--lr" in str(err.value)
    assert list(tmp_path.iterdir()) == []
    # One that diverges with weights still finite: its loss gives it away (it was written, at chance).
    with pytest.raises(UserError, match=r"diverged \(epoch \d's training loss is .*\); a smaller --lr may help") as err:
        train_and_save(random_dataset(400), out, train_config(epochs=2, batch_size=64, hidden=16, lr=1e10))
    assert list(tmp_path.iterdir()) == []


def test_train_and_save_without_checkpoints(tmp_path: Path):
    out = tmp_path / "pref.safetensors"
    train_and_save(random_dataset(100), out, train_config(epochs=1), options=RunOptions(checkpoints=False))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pref.safetensors"]


def test_mirror_learns_the_unseen_side():
    """A dataset whose preference is only ever shown with the better arcs on the left is learned
    for the right side too when mirrored copies are added (the preference has no side)."""
    data = linear_dataset(2000)
    left = data.labels >= 10  # keep only decisions toward w >= 0
    shown = dataset_of(data.U[left], data.labels[left])
    mirrored = dataset_of(data.U[~left], data.labels[~left])  # the other side, never shown
    cfg = dict(epochs=30, lr=3e-3, batch_size=64, skip=True)
    plain = train(shown, train_config(**cfg))
    mirror = train(shown, train_config(**cfg, mirror=True))

    def acc(result) -> float:
        pred = np.argmax(numpy_forward(result.classifier, result.weights, mirrored.U), axis=1)
        return float((pred == mirrored.labels).mean())

    assert acc(mirror) > 0.8 and acc(mirror) > acc(plain) + 0.2, (acc(plain), acc(mirror))


def test_mirror_needs_a_symmetric_control_set():
    from dataclasses import replace

    from terrapref.features import FeatureConfig
    from terrapref.vehicle import ControlSet

    data = linear_dataset(200)
    fc = FeatureConfig()
    skewed = replace(fc, preference=replace(fc.preference, control=ControlSet(1.0, tuple(np.linspace(-1.0, 0.6, 21).round(6)))))
    data = Dataset(data.U, data.labels, data.w, data.source, {**data.meta, "features": skewed.to_dict()})
    with pytest.raises(ValueError, match="symmetric"):
        train(data, train_config(epochs=1, mirror=True))


def test_an_interrupted_training_leaves_its_best_so_far_and_touches_nothing_else(tmp_path: Path):
    from terrapref.learning.pipeline import interrupted_path

    data = _interrupt_dataset()
    out = tmp_path / "model.safetensors"
    config = train_config(epochs=4, members=3, hidden=8, batch_size=64)
    train_and_save(data, out, train_config(config, members=1))  # an earlier model and its checkpoints
    before = out.read_bytes()
    old_checkpoints = sorted(p.name for p in (tmp_path / "model.checkpoints").iterdir())
    seen = []

    def stop(m) -> None:
        seen.append(m.epoch)
        if len(seen) == 6:  # member 2, epoch 2
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        train_and_save(data, out, config, options=RunOptions(progress=stop))
    assert out.read_bytes() == before  # the earlier model is untouched
    assert sorted(p.name for p in (tmp_path / "model.checkpoints").iterdir()) == old_checkpoints
    partial = load_model(interrupted_path(out))
    assert partial.meta["status"] == "interrupted" and partial.classifier.members == 2  # member 1 whole, member 2 so far
    assert partial.meta["interrupted"]["members_reached"] == 2
    assert sorted(p.name for p in (tmp_path / "model.checkpoints.interrupted").iterdir()) == ["member_1", "member_2"]
    assert len(list((tmp_path / "model.checkpoints.interrupted" / "member_2").iterdir())) == 2
    # A complete retrain replaces the old checkpoints wholly: none of another run is left beside.
    train_and_save(data, out, train_config(config, members=2, epochs=2))
    assert sorted(p.name for p in (tmp_path / "model.checkpoints").iterdir()) == ["member_1", "member_2"]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def _interrupt_dataset() -> Dataset:
    rng = np.random.default_rng(0)
    n = 200
    return Dataset(
        rng.uniform(0, 1, (n, 21, 5)).astype(np.float32),
        rng.integers(0, 21, n),
        np.zeros(n, np.float32),
        np.zeros(n, np.int64),
        {"format": DATASET_FORMAT, **model_meta()},
    )


def test_training_without_the_identifiability_report_trains_the_same_weights():
    ds = random_dataset(120, seed=3)
    config = train_config(epochs=3)
    full, bare = train(ds, config), train(ds, config, identify=False)
    assert full.identifiability is not None and bare.identifiability is None and not bare.rules
    assert_weights_equal(full.weights, bare.weights)
    # a second stage needs the fit: it is made whatever identify says
    staged = train(ds, train_config(epochs=3), identify=False, rules=[SecondStageConfig()])
    assert staged.rules[0].type == "second_stage" and staged.identifiability is not None


def test_a_rules_configuration_edited_in_a_dataset_is_refused_naming_the_field_not_failing_in_a_fit():
    from terrapref.errors import UserError
    from terrapref.learning.train import DATASET, FitData
    from terrapref.rules.second.rule import LookaheadConfig

    data = random_dataset(10)
    for lookahead, read in (({"after_s": 2.4, "stride": 2}, True), ({"after_s": 2.4, "stride": 0}, False), ("x", False)):
        meta = dict(data.meta) | {"rules": {"second_stage": {"config": {"lookahead": lookahead}, "arrays": {}}}}
        fit = FitData(Dataset(data.U, data.labels, data.w, data.source, meta, {"second_stage": {}}), mirror=False)
        if read:
            assert fit.rule_config("second_stage", lambda c: LookaheadConfig.from_dict(c["lookahead"]))[0].stride == 2
            continue
        with pytest.raises(UserError) as err:
            fit.rule_config("second_stage", lambda c: LookaheadConfig.from_dict(c["lookahead"]))
        assert err.value.source == DATASET and err.value.problems[0].field == "rules.second_stage.config"
