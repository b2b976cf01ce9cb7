"""Unicycle kinematics, the 30 Hz controller and the control set, against closed-form answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from terrapref.vehicle import Command, ControlSet, Pose, Vehicle, VehicleConfig, integrate_unicycle, wrap_angle

AT_ONCE = VehicleConfig.paper()  # every command applied at once: the kinematics alone


def _angle_diff(a: float, b: float) -> float:
    return abs(wrap_angle(a - b))


def test_straight_drive_1mps_for_2s_is_2m():
    vehicle = Vehicle(Pose(3.0, -1.0, 0.0), AT_ONCE)
    vehicle.set_command(Command(1.0, 0.0))
    for _ in range(60):  # 2 s at 30 Hz
        vehicle.tick()
    assert vehicle.pose.x == pytest.approx(5.0, abs=1e-12)
    assert vehicle.pose.y == pytest.approx(-1.0, abs=1e-12)
    assert vehicle.pose.yaw == 0.0


def test_straight_drive_follows_the_heading():
    yaw = math.radians(120.0)
    vehicle = Vehicle(Pose(0.0, 0.0, yaw), AT_ONCE)
    vehicle.set_command(Command(0.5, 0.0))
    for _ in range(90):  # 3 s
        vehicle.tick()
    np.testing.assert_allclose(vehicle.pose[:2], [1.5 * math.cos(yaw), 1.5 * math.sin(yaw)], atol=1e-12)


def test_full_circle_returns_to_the_start_pose():
    v, w = 1.0, 0.5
    period_s = 2 * math.pi / w
    n = 377  # ticks in one period: the rate is chosen so the period is a whole number of ticks
    vehicle = Vehicle(Pose(2.0, 3.0, 0.7), VehicleConfig(control_rate_hz=n / period_s, max_accel_mps2=None))
    vehicle.set_command(Command(v, w))
    radius = v / w
    far = 0.0
    for _ in range(n):
        x, y, _ = vehicle.tick()
        far = max(far, math.hypot(x - 2.0, y - 3.0))
    assert far == pytest.approx(2 * radius, abs=1e-3)  # it did drive the circle, diameter 4 m
    assert vehicle.pose.x == pytest.approx(2.0, abs=1e-9)
    assert vehicle.pose.y == pytest.approx(3.0, abs=1e-9)
    assert _angle_diff(vehicle.pose.yaw, 0.7) < 1e-9


def test_full_circle_at_30hz_by_integrate_unicycle():
    period_s = 2 * math.pi / 0.5
    pose = Pose(0.0, 0.0, 0.0)
    n = 30 * 13
    for _ in range(n):
        pose = integrate_unicycle(pose, Command(1.0, 0.5), period_s / n)
    assert math.hypot(pose.x, pose.y) < 1e-9
    assert _angle_diff(pose.yaw, 0.0) < 1e-9


@pytest.mark.parametrize("v,w,dt,yaw0", [(1.0, 0.5, 1.3, 0.0), (0.7, -1.0, 2.0, 1.1), (1.0, 1.0, math.pi, -2.5), (0.3, 0.2, 0.1, 3.0)])
def test_integrate_unicycle_matches_the_arc_closed_form(v, w, dt, yaw0):
    x0, y0 = 1.5, -0.5
    pose = integrate_unicycle(Pose(x0, y0, yaw0), Command(v, w), dt)
    r = v / w
    # Centre of the turning circle lies r to the left of the start; the pose sweeps w*dt round it.
    cx, cy = x0 - r * math.sin(yaw0), y0 + r * math.cos(yaw0)
    yaw1 = yaw0 + w * dt
    assert pose.x == pytest.approx(cx + r * math.sin(yaw1), abs=1e-12)
    assert pose.y == pytest.approx(cy - r * math.cos(yaw1), abs=1e-12)
    assert pose.yaw == pytest.approx(yaw1, abs=1e-12)
    assert math.hypot(pose.x - cx, pose.y - cy) == pytest.approx(abs(r), abs=1e-12)


def test_integrate_unicycle_is_continuous_at_zero_yaw_rate():
    straight = integrate_unicycle(Pose(0.0, 0.0, 0.3), Command(1.0, 0.0), 1.0)
    tiny = integrate_unicycle(Pose(0.0, 0.0, 0.3), Command(1.0, 1e-7), 1.0)
    np.testing.assert_allclose(tiny, straight, atol=1e-6)


def test_half_turn_at_unit_rate_ends_one_diameter_to_the_left():
    pose = integrate_unicycle(Pose(0.0, 0.0, 0.0), Command(1.0, 1.0), math.pi)
    np.testing.assert_allclose(pose, [0.0, 2.0, math.pi], atol=1e-12)


def test_controller_holds_the_last_command():
    vehicle = Vehicle(Pose(0.0, 0.0, 0.0), AT_ONCE)
    assert vehicle.command == Command(0.0, 0.0)
    vehicle.tick()
    assert vehicle.pose == Pose(0.0, 0.0, 0.0)  # at rest until commanded
    vehicle.set_command(Command(1.0, 0.0))
    for _ in range(30):
        vehicle.tick()
    vehicle.set_command(Command(0.5, 0.0))
    for _ in range(30):
        vehicle.tick()
    assert vehicle.command == Command(0.5, 0.0)
    assert vehicle.pose.x == pytest.approx(1.5, abs=1e-12)


def test_commands_are_clipped_to_the_limits():
    vehicle = Vehicle(Pose(0.0, 0.0, 0.0), VehicleConfig(max_speed_mps=1.0, max_yaw_rate_rps=1.0))
    vehicle.set_command(Command(3.0, -5.0))
    assert vehicle.command == Command(1.0, -1.0)
    vehicle.set_command(Command(-2.0, 0.25))
    assert vehicle.command == Command(0.0, 0.25)
    vehicle.set_command(Command(0.4, 2.0))
    assert vehicle.command == Command(0.4, 1.0)
    fast = Vehicle(Pose(0.0, 0.0, 0.0), VehicleConfig(max_speed_mps=2.0, max_accel_mps2=None))
    fast.set_command(Command(5.0, 0.0))
    for _ in range(30):
        fast.tick()
    assert fast.pose.x == pytest.approx(2.0, abs=1e-12)


def test_tick_wraps_yaw():
    vehicle = Vehicle(Pose(0.0, 0.0, 3.0))
    vehicle.set_command(Command(0.0, 1.0))
    for _ in range(30):
        yaw = vehicle.tick().yaw
        assert -math.pi <= yaw < math.pi
    assert _angle_diff(vehicle.pose.yaw, 4.0) < 1e-12


def test_vehicle_config_rejects_bad_values():
    assert VehicleConfig().dt_s == pytest.approx(1 / 30)
    for bad in ({"control_rate_hz": 0.0}, {"max_speed_mps": -1.0}, {"max_yaw_rate_rps": 0.0}):
        with pytest.raises(ValueError):
            VehicleConfig(**bad)


def test_wrap_angle():
    assert wrap_angle(0.0) == 0.0
    assert wrap_angle(math.pi) == pytest.approx(-math.pi)
    assert wrap_angle(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert wrap_angle(-7.0) == pytest.approx(-7.0 + 2 * math.pi)


# --- control set ------------------------------------------------------------------------------


def test_default_control_set_is_the_papers():
    cs = ControlSet()
    assert cs.m == 21 and cs.v_mps == 1.0
    np.testing.assert_allclose(cs.w_rps, np.arange(-10, 11) / 10, atol=1e-12)
    assert cs.w_rps[10] == 0.0 and cs.w_rps[0] == -1.0 and cs.w_rps[-1] == 1.0
    assert cs.command(10) == (1.0, 0.0)
    assert cs.command(13) == (1.0, pytest.approx(0.3))
    assert ControlSet.uniform() == cs


@pytest.mark.parametrize(
    "w,label",
    [
        (0.0, 10),
        (0.05, 10),
        (-0.05, 10),
        (0.049, 10),
        (0.051, 11),
        (0.15, 11),
        (-0.15, 9),
        (0.25, 12),
        (-0.95, 1),
        (0.95, 19),
        (0.12, 11),
        (-0.33, 7),
        (1.0, 20),
        (2.0, 20),
        (-1.0, 0),
        (-7.0, 0),
    ],
)
def test_label_of_maps_w_to_the_nearest_bin_ties_toward_zero(w, label):
    assert ControlSet().label_of(w) == label


def test_label_of_is_vectorised():
    labels = ControlSet().label_of(np.array([-0.05, 0.05, 0.15, -0.15, 2.0]))
    assert labels.tolist() == [10, 10, 11, 9, 20]


def test_label_of_on_a_grid_without_zero():
    cs = ControlSet(1.0, (-0.6, -0.2, 0.2, 0.6))
    assert cs.label_of(0.0) in (1, 2)  # equidistant from +-0.2 with equal |w|: either is nearest to zero
    assert cs.label_of(0.4) == 2 and cs.label_of(-0.4) == 1


def test_control_set_validation_and_round_trip():
    with pytest.raises(ValueError):
        ControlSet(1.0, (0.5, 0.1))
    with pytest.raises(ValueError):
        ControlSet(0.0)
    cs = ControlSet.uniform(m=11, v_mps=0.8, w_max_rps=0.5)
    assert ControlSet.from_dict(cs.to_dict()) == cs


def test_label_of_one_command_is_the_vectorised_label():
    """One yaw rate takes a compiled path; it must give the label the NumPy form gives, on random
    rates, rates at and halfway between grid values (ties), and non-finite ones."""
    rng = np.random.default_rng(2)
    for control in (ControlSet(), ControlSet.uniform(7, w_max_rps=0.6), ControlSet(1.0, (-0.5, -0.2, 0.2, 0.5))):
        grid = np.asarray(control.w_rps)
        w = np.concatenate(
            [
                rng.uniform(-1.5, 1.5, 2000),
                grid,
                (grid[1:] + grid[:-1]) / 2,
                grid + 1e-12,
                grid - 1e-12,
                [0.0, -0.0, math.inf, -math.inf, math.nan],
            ]
        )
        want = control.label_of(w)
        got = np.array([control.label_of(float(x)) for x in w])
        np.testing.assert_array_equal(got, want)
        assert isinstance(control.label_of(0.3), int) and control.label_of(1) == control.label_of(np.array([1.0]))[0]


def test_from_rest_the_speed_ramps_at_the_acceleration_limit_and_the_distance_is_its_integral():
    vehicle = Vehicle(Pose(0.0, 0.0, 0.0), VehicleConfig(max_accel_mps2=1.0))  # 2 m/s top speed
    vehicle.set_command(Command(2.0, 0.0))
    speeds = []
    for _ in range(90):  # 3 s at 30 Hz: 2 s of ramp, then 1 s at 2 m/s
        vehicle.tick()
        speeds.append(vehicle.speed_mps)
    assert speeds[29] == pytest.approx(1.0, abs=1e-12)  # 1 m/s after 1 s
    assert speeds[59] == pytest.approx(2.0, abs=1e-12) and speeds[-1] == 2.0
    assert vehicle.pose.x == pytest.approx(0.5 * 1.0 * 2.0**2 + 2.0 * 1.0, abs=1e-9)  # a t^2 / 2, then v t


def test_braking_from_full_speed_stops_within_the_braking_distance():
    config = VehicleConfig(max_decel_mps2=2.0)
    vehicle = Vehicle(Pose(0.0, 0.0, 0.0), config, speed_mps=2.0)
    vehicle.set_command(Command(0.0, 0.0))
    for _ in range(60):
        vehicle.tick()
    assert vehicle.speed_mps == 0.0
    assert vehicle.pose.x == pytest.approx(config.braking_distance_m(2.0), abs=1e-9)
    assert config.braking_distance_m(2.0) == pytest.approx(1.0)
    assert VehicleConfig.paper().braking_distance_m(1.0) == 0.0


def test_the_yaw_rate_follows_at_once_while_the_speed_ramps():
    vehicle = Vehicle(Pose(0.0, 0.0, 0.0))
    vehicle.set_command(Command(1.0, 0.5))
    vehicle.tick()
    assert vehicle.pose.yaw == pytest.approx(0.5 / 30, abs=1e-12)
    assert vehicle.speed_mps == pytest.approx(1.0 / 30, abs=1e-12)


@pytest.mark.parametrize("field", ["max_accel_mps2", "max_decel_mps2"])
@pytest.mark.parametrize("value", [0.0, -1.0, math.inf, math.nan, True])
def test_acceleration_limits_are_validated(field, value):
    with pytest.raises(ValueError, match=field):
        VehicleConfig(**{field: value})


def test_a_vehicle_recorded_before_acceleration_limits_applied_commands_at_once():
    old = {"control_rate_hz": 30.0, "max_speed_mps": 1.0, "max_yaw_rate_rps": 1.0, "half_width_m": 0.6}
    assert VehicleConfig.from_dict(old) == VehicleConfig.paper()
    assert VehicleConfig.from_dict(VehicleConfig().to_dict()) == VehicleConfig()
