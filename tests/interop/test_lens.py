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


def test_a_centred_cameras_info_in_ros_pixel_coordinates_is_the_simulators_camera(tmp_path):
    """ROS (as OpenCV) puts a pixel's centre at its index, terrapref at index + 0.5: a centred
    640 x 480 camera's CameraInfo says 319.5, 239.5, and is the camera the simulator's models are
    trained for; the calibration export writes reads back as the same camera."""
    from types import SimpleNamespace

    from synthetic_bag import robot_yaml, write_robot
    from terrapref.camera import CameraConfig
    from terrapref.interop.robot import load_robot
    from terrapref.interop.ros_decode import camera_from_info
    from terrapref.interop.ros_messages import camera_info, header, typestore

    robot = load_robot(write_robot(tmp_path / "robot.yaml", robot_yaml()))
    sim = CameraConfig(mount_height_m=robot.camera["height_m"], pitch_deg=robot.camera["pitch_deg"])

    def read(k: list[float]) -> CameraConfig:
        info = SimpleNamespace(width=640, height=480, k=k, d=[0.0] * 5, distortion_model="plumb_bob")
        return camera_from_info(info, robot, "log.mcap")[0]

    assert read([320.0, 0, 319.5, 0, 320.0, 239.5, 0, 0, 1]).same_geometry(sim)
    assert not read([320.0, 0, 320.0, 0, 320.0, 240.0, 0, 0, 1]).same_geometry(sim)  # half a pixel off: another camera
    ts = typestore()
    written = camera_info(ts, header(ts, 0.0, "camera_optical"), sim)
    assert (written.k[2], written.k[5]) == (319.5, 239.5)
    assert read(list(written.k)).same_geometry(sim)
