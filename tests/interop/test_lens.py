"""A log's lens calibration (sensor_msgs/CameraInfo's distortion), as import and the nodes undo it."""

from __future__ import annotations

import numpy as np
import pytest

from terrapref.errors import UserError
from terrapref.interop.ros_decode import _undistortion

K = np.array([[320.0, 0.0, 320.0], [0.0, 320.0, 240.0], [0.0, 0.0, 1.0]])
SHAPE = (480, 640)


def _lens(d: list[float], model: str = "rational_polynomial") -> np.ndarray:
    return _undistortion(K, np.asarray(d, dtype=float), model, SHAPE, "log.mcap")


def test_a_rational_polynomial_lens_without_its_divisor_is_plumb_bob():
    d = [0.1, 0.01, 0.001, -0.002, 0.003]
    np.testing.assert_array_equal(_lens(d + [0.0, 0.0, 0.0]), _lens(d, "plumb_bob"))


def test_a_rational_polynomial_lens_divides_the_radial_factor_by_k4_k5_k6():
    d = [0.1, 0.01, 0.0, 0.0, 0.0, 0.5, 0.2, 0.1]
    undo = _lens(d)
    assert not np.array_equal(undo, _lens(d[:5] + [0.0, 0.0, 0.0]))
    # A pixel 200 px right of the centre: r^2 = (200 / 320)^2, the lens moves it by its radial factor.
    r2 = (200 / 320) ** 2
    radial = (1 + 0.1 * r2 + 0.01 * r2**2) / (1 + 0.5 * r2 + 0.2 * r2**2 + 0.1 * r2**3)
    assert undo[240, 520] == 240 * 640 + round(320 + 200 * radial)


@pytest.mark.parametrize("d", [[float("nan"), 0.0, 0.0, 0.0, 0.0], [0.0, float("inf"), 0.0, 0.0]])
def test_a_coefficient_that_is_not_a_number_is_refused_naming_the_camera_info(d):
    with pytest.raises(UserError, match="expected at least 4 finite coefficients") as err:
        _lens(d, "plumb_bob")
    assert str(err.value).startswith("log.mcap: topics.camera_info: ")


def test_a_lens_that_would_show_less_than_half_the_image_is_refused():
    with pytest.raises(UserError, match="outside the lens's own image: not a calibration"):
        _lens([1e6, 1e6, 0.0, 0.0, 1e6], "plumb_bob")


def test_too_few_coefficients_are_named_as_such():
    with pytest.raises(UserError, match=r"plumb_bob distortion \[0.1, 0.0\]: expected at least 4"):
        _lens([0.1, 0.0], "plumb_bob")
