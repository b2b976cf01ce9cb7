"""A depth camera's errors (the perception model's ``depth`` section): noise whose spread grows with
the square of the depth, dropouts, a maximum range; the same errors for the same seed, whether or
not the depth is read; and the ``field`` preset includes them."""

from __future__ import annotations

import numpy as np
import pytest

from terrapref.camera import PinholeCamera
from terrapref.camera.render import SegmentationRenderer
from terrapref.errors import ConfigError
from terrapref.perception.model import DepthErrors, PerceptionModel, load_perception, parse_perception
from terrapref.perception.perceiver import Perceiver
from terrapref.scenario import resolve_scenario
from terrapref.sim import Simulation
from terrapref.terrain import default_classes


def _frames(model: PerceptionModel, seed: int, count: int = 3):
    sim = Simulation(resolve_scenario("teach_course"))
    perceiver = Perceiver(model, SegmentationRenderer(PinholeCamera(), sim.world), sim.scenario.classes)
    perceiver.reset(np.random.default_rng(seed))
    frame, out = sim.reset(), []
    for _ in range(count):
        out.append((frame, perceiver.captured(frame)))
        frame = sim.step((1.0, 0.0))
    return out


def test_depth_noise_grows_with_the_square_of_the_depth_and_dropouts_and_range_leave_nan() -> None:
    model = PerceptionModel(depth=DepthErrors(noise_m=0.01, dropout_rate=0.1, max_range_m=10.0), name="stereo")
    truth, seen = _frames(model, 0, 1)[0]
    true, noisy = truth.depth, seen.depth
    assert noisy.dtype == np.float32 and noisy.shape == true.shape
    np.testing.assert_array_equal(seen.image, truth.image)  # depth errors leave the labels as they were
    assert np.isnan(noisy[~(true <= 10.0)]).all()
    near = true < 10.0
    assert np.isnan(noisy[near]).mean() == pytest.approx(0.1, abs=0.01)
    for low, high in ((1.0, 2.0), (6.0, 9.0)):
        band = (true >= low) & (true < high) & ~np.isnan(noisy)
        spread = np.std((noisy[band] - true[band]) / true[band] ** 2)
        assert spread == pytest.approx(0.01, rel=0.1), (low, high)


def test_the_same_seed_gives_the_same_depth_errors_whether_or_not_earlier_depth_was_read() -> None:
    model = PerceptionModel(depth=DepthErrors(noise_m=0.01, dropout_rate=0.1), name="stereo")
    read_all = [seen.depth for _, seen in _frames(model, 4)]
    skipped = _frames(model, 4)
    np.testing.assert_array_equal(skipped[2][1].depth, read_all[2])
    assert not np.array_equal(np.isnan(read_all[0]), np.isnan(read_all[1]))


def test_field_includes_depth_errors_and_a_bad_depth_field_is_refused_naming_it() -> None:
    field = load_perception("field", default_classes())
    assert field.depth.active and field.depth.max_range_m == 20.0 and "depth:" in field.summary()
    assert not load_perception("clean", default_classes()).depth.active
    with pytest.raises(ConfigError, match=r"depth\.dropout_rate"):
        parse_perception({"format": "terrapref-perception/1", "depth": {"dropout_rate": 1.5}}, "p.yaml", default_classes())
    assert field.part("depth").depth == field.depth and not field.part("depth").labels.active
