"""The end-to-end CNN baseline (terrapref.baselines.cnn): nearest-pixel downsampling, one-hot
input, and training that runs (class-balanced or not) and keeps its best epoch."""

from __future__ import annotations

import numpy as np
import pytest

from terrapref.baselines.cnn import PATH_AHEAD_M, CnnConfig, _onehot, downsample, train_cnn

M = 21


def _samples(n: int = 64, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Images whose left or right half is mud (class 4): the label turns away from it."""
    rng = np.random.default_rng(seed)
    images = np.zeros((n, 6, 8), np.uint8)
    side = rng.integers(0, 2, n)
    images[side == 0, :, :4] = 4
    images[side == 1, :, 4:] = 4
    labels = np.where(side == 0, 14, 6)  # mud on the left: turn right of straight (index 10), and back
    return images, rng.normal(0, 0.1, (n, 2 * len(PATH_AHEAD_M))).astype(np.float32), labels.astype(np.int64)


@pytest.mark.slow  # a whole drive, course or training end to end; the default run keeps the test suite's time
@pytest.mark.parametrize("class_balance", [True, False])
def test_training_runs_and_keeps_the_best_epoch(class_balance: bool):
    images, paths, labels = _samples()
    config = CnnConfig(channels=(4, 4, 4), hidden=8, epochs=3, batch_size=16, class_balance=class_balance)
    result = train_cnn(images, paths, labels, M, config)
    assert 1 <= result.best_epoch <= 3 and result.n_samples == len(labels)
    assert 0.0 <= result.val_acc <= 1.0


def test_downsampling_takes_the_centre_pixel_of_each_block():
    image = np.arange(64, dtype=np.uint8).reshape(8, 8)
    np.testing.assert_array_equal(downsample(image, 4), [[18, 22], [50, 54]])


def test_onehot_leaves_unknown_ids_all_zero():
    out = _onehot(np.array([[[0, 4, 255]]], np.uint8), 5).numpy()
    assert out.shape == (1, 5, 1, 3)
    np.testing.assert_array_equal(out[0, :, 0, 0], [1, 0, 0, 0, 0])
    np.testing.assert_array_equal(out[0, :, 0, 1], [0, 0, 0, 0, 1])
    np.testing.assert_array_equal(out[0, :, 0, 2], [0, 0, 0, 0, 0])


def test_samples_of_a_drive_kept_in_memory_are_those_of_the_same_drive_on_disk(tmp_path):
    """A recording kept in memory reads only the pixels the downsampling keeps: the same samples."""
    from dataclasses import replace

    from helpers import TINY_COURSE
    from terrapref.baselines.cnn import cnn_samples
    from terrapref.features import FeatureConfig
    from terrapref.recipes import OURS, RecipeSetup, demonstrate

    first = replace(OURS, demonstrations=1)  # its first demonstration, the one compared
    setup = RecipeSetup(2, course=str(TINY_COURSE))
    kept = demonstrate(first, tmp_path / "mem", setup, write=False)
    written = demonstrate(first, tmp_path / "disk", setup, write=True)
    a, b = cnn_samples(kept, FeatureConfig(), 16), cnn_samples(written, FeatureConfig(), 16)
    assert a[0].shape == (len(kept[0]), 30, 40)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)
