"""Labels from a shaky hand (terrapref.learning.steady): the tremor read from the drive, and
labels averaged only when it is large."""

import math
from dataclasses import replace

import numpy as np
import pytest

from helpers import assert_weights_equal, linear_dataset, train_config
from terrapref.learning.steady import WINDOW, hand_tremor, moving_average, steady_labels, window_for
from terrapref.learning.train import train

GRID = np.round(np.linspace(-1.0, 1.0, 21), 10)


def _hand(n: int, tremor: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A hand's commands: deliberate yaw rates held for 10-40 frames (a third of the time at
    rest, exactly zero), plus Gaussian tremor while deflected; two recordings."""
    rng = np.random.default_rng(seed)
    intent = []
    while len(intent) < n:
        value = 0.0 if rng.random() < 1 / 3 else float(rng.choice(GRID[GRID != 0]) * 0.6)
        intent += [value] * int(rng.integers(10, 41))
    intent = np.array(intent[:n])
    w = np.where(intent != 0, intent + rng.normal(0.0, tremor, n), 0.0)
    return w, (np.arange(n) >= n // 2).astype(np.int64)


@pytest.mark.parametrize("tremor", [0.02, 0.05, 0.08, 0.12])
def test_the_tremor_is_read_from_the_commands(tremor):
    w, source = _hand(4000, tremor)
    assert hand_tremor(w, source) == pytest.approx(tremor, rel=0.15)


def test_too_few_deflected_frames_give_no_estimate():
    assert math.isnan(hand_tremor(np.zeros(500), np.zeros(500, np.int64)))
    assert window_for(math.nan, 0.1) == 1


def test_the_window_is_one_for_a_steady_hand_and_half_a_second_for_a_shaky_one():
    assert window_for(0.05, 0.1) == 1  # half the spacing: labels as recorded
    assert window_for(0.02, 0.1) == 1
    assert window_for(0.0501, 0.1) == WINDOW == 5
    assert window_for(0.08, 0.2) == 1  # a coarser grid tolerates more tremor


def test_the_moving_average_stays_inside_each_recording():
    w = np.r_[np.full(10, 1.0), np.full(10, -1.0)]
    source = np.r_[np.zeros(10, np.int64), np.ones(10, np.int64)]
    out = moving_average(w, source, 5)
    assert np.array_equal(out, w)  # each recording is constant: nothing leaks across the boundary
    ramp = moving_average(np.arange(7.0), np.zeros(7, np.int64), 3)
    assert np.allclose(ramp, [1 / 3, 1, 2, 3, 4, 5, 6 - 1 / 3])


def _with_hand(tremor: float):
    data = linear_dataset(600)
    w, source = _hand(len(data), tremor, seed=1)
    labels = np.asarray(data.feature_config.preference.control.label_of(w), dtype=np.int64)
    return replace(data, w=w.astype(np.float32), source=source, labels=labels)


def test_a_steady_hand_keeps_its_labels_and_its_model_bit_for_bit():
    data = _with_hand(0.02)
    same, report = steady_labels(data)
    assert same is data and report.window == 1 and report.changed == 0.0
    assert "labels as recorded" in report.line()
    plain = train(data, train_config(epochs=2, steady_labels=False), identify=False)
    steadied = train(data, train_config(epochs=2, steady_labels=True), identify=False)
    assert_weights_equal(plain.weights, steadied.weights)
    assert plain.steadying is None and steadied.steadying.window == 1


def test_a_shaky_hands_labels_come_from_its_intent():
    data = _with_hand(0.08)
    as_recorded = moving_average(data.w, data.source, 1)  # a 1-frame average is w itself
    steadied, report = steady_labels(data)
    assert report.window > 1 and 0.0 < report.changed < 1.0
    assert report.tremor_rps == pytest.approx(0.08, rel=0.2)
    assert f"{report.window}-frame moving average" in report.line()
    assert np.array_equal(steadied.U, data.U) and not np.array_equal(steadied.labels, data.labels)
    # Averaging removes label noise: fewer frame-to-frame label changes than recorded.
    assert np.count_nonzero(np.diff(steadied.labels)) < np.count_nonzero(np.diff(data.labels))
    assert np.array_equal(as_recorded, data.w.astype(np.float64))
    result = train(data, train_config(epochs=1, steady_labels=True), identify=False)
    assert result.steadying == report
