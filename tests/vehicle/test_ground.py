"""The vehicle on relief (SPEC 19) against closed-form answers: its pitch and roll on a ramp of
known grade, its height, its speed up a grade, a ledge just under and just over the step it
climbs, a side slope past its roll limit, a wall thinner than a tick's distance, a ledge under
the rear wheels, a turn into a bank; and the run's counts of tips and times stuck."""

from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np
import pytest

from terrapref.scenario import FORMAT, parse_scenario
from terrapref.sim import SimConfig, Simulation
from terrapref.vehicle import Command, Pose, Vehicle, VehicleConfig
from terrapref.vehicle.ground import LEVEL
from terrapref.world import WorldMap, rasterise

FLAT: dict[str, Any] = {
    "format": FORMAT,
    "name": "ground_test",
    "world": {"size_m": [30.0, 20.0], "resolution_m": 0.1, "background": "grass"},
    "terrain": [],
    "path": {"waypoints": [[1.0, 10.0], [29.0, 10.0]]},
}
# A ramp up 1 m over x = 5 .. 10 m (grade 0.2) onto a plateau from x = 10 m, level across (y).
RAMP = {"plateau": {"polygon": [[10, -5], [40, -5], [40, 25], [10, 25]], "height_m": 1.0, "edge_m": 5.0}}


def world(*relief: dict) -> WorldMap:
    data = copy.deepcopy(FLAT)
    if relief:
        data["relief"] = list(relief)
    return rasterise(parse_scenario(data, "ground_test.yaml"))


def ledge(height_m: float) -> dict:
    """A vertical step of ``height_m`` at x = 12 m, across the whole map."""
    return {"plateau": {"polygon": [[12, -5], [40, -5], [40, 25], [12, 25]], "height_m": height_m, "edge_m": 0.0}}


def test_on_a_ramp_the_pitch_is_minus_the_grade_going_up_the_roll_is_it_across_and_the_height_its_mid_point() -> None:
    ramp = world(RAMP)
    up = Vehicle(Pose(7.5, 10.0, 0.0), ground=ramp)
    assert up.attitude.pitch_rad == pytest.approx(-math.atan(0.2), abs=1e-6)  # REP 103: nose up is negative
    assert up.attitude.grade_rad == pytest.approx(math.atan(0.2), abs=1e-6)
    assert up.attitude.roll_rad == pytest.approx(0.0, abs=1e-12)
    assert up.attitude.z_m == pytest.approx(0.5, abs=1e-6)
    down = Vehicle(Pose(7.5, 10.0, math.pi), ground=ramp)
    assert down.attitude.pitch_rad == pytest.approx(math.atan(0.2), abs=1e-6)
    # Facing north, the ramp rises to the right (east): the left side is the lower one.
    across = Vehicle(Pose(7.5, 10.0, math.pi / 2), ground=ramp)
    assert across.attitude.roll_rad == pytest.approx(-math.atan(0.2), abs=1e-6)
    assert across.attitude.pitch_rad == pytest.approx(0.0, abs=1e-12)


def test_on_flat_ground_the_vehicle_is_level_and_asks_nothing_of_the_ground() -> None:
    flat = Vehicle(Pose(7.5, 10.0, 0.3), ground=None)
    assert flat.contact is None and flat.attitude == LEVEL and not flat.tipped
    assert world().height_at_point(7.5, 10.0) == 0.0


def _drive(vehicle: Vehicle, command: Command, seconds: float) -> list[float]:
    """Hold ``command`` for ``seconds``; the speed at every tick [m/s]."""
    vehicle.set_command(command)
    speeds = []
    for _ in range(round(seconds * vehicle.config.control_rate_hz)):
        vehicle.tick()
        speeds.append(vehicle.speed_mps)
    return speeds


def test_up_a_grade_the_speed_is_a_constant_power_drives_and_down_it_is_not_capped() -> None:
    config = VehicleConfig()
    g, c = math.atan(0.2), config.rolling_resistance
    climbing = config.max_speed_mps * c / (c * math.cos(g) + math.sin(g))
    up = Vehicle(Pose(5.6, 10.0, 0.0), ground=world(RAMP), speed_mps=2.0)
    _drive(up, Command(2.0, 0.0), 1.5)
    assert 6.5 < up.pose.x < 9.4  # on the ramp, the whole wheelbase on it
    assert up.speed_mps == pytest.approx(climbing, abs=1e-6) and climbing == pytest.approx(0.874, abs=1e-3)
    down = Vehicle(Pose(9.4, 10.0, math.pi), ground=world(RAMP), speed_mps=2.0)
    _drive(down, Command(2.0, 0.0), 1.0)
    assert down.speed_mps == 2.0 and down.pose.x < 8.0


@pytest.mark.parametrize(("height_m", "stuck"), [(0.14, False), (0.16, True)])
def test_a_ledge_under_the_step_it_climbs_is_climbed_and_one_over_it_holds_the_vehicle(height_m: float, stuck: bool) -> None:
    vehicle = Vehicle(Pose(8.0, 10.0, 0.0), ground=world(ledge(height_m)))
    assert vehicle.config.max_step_m == 0.15
    speeds = _drive(vehicle, Command(1.0, 0.0), 8.0)
    if stuck:
        assert vehicle.stuck and vehicle.speed_mps == 0.0 and speeds[-1] == 0.0
        assert 11.2 < vehicle.pose.x + 0.5 < 12.0  # the front wheels stopped short of the ledge
        _drive(vehicle, Command(0.0, 1.0), 1.0)  # it can still turn in place
        assert vehicle.pose.yaw == pytest.approx(1.0) and not vehicle.stuck
    else:
        assert not vehicle.stuck and vehicle.pose.x > 14.0 and vehicle.attitude.z_m == pytest.approx(height_m, abs=1e-6)


def wall(x_m: float, width_m: float, height_m: float = 2.0) -> dict:
    """A wall ``width_m`` thick from x = ``x_m``, ``height_m`` high, across the whole map."""
    return {"plateau": {"polygon": [[x_m, -5], [x_m + width_m, -5], [x_m + width_m, 25], [x_m, 25]], "height_m": height_m, "edge_m": 0.0}}


def thin_wall_world() -> WorldMap:
    """A wall 2 m high and one 5 cm cell thick from x = 12 m, across the whole map."""
    data = copy.deepcopy(FLAT)
    data["world"]["resolution_m"] = 0.05
    data["relief"] = [wall(12.0, 0.05)]
    return rasterise(parse_scenario(data, "ground_test.yaml"))


@pytest.mark.parametrize("start_x", [8.0, 8.03, 8.07])
def test_a_wall_one_cell_thick_is_not_driven_through_straight_on(start_x: float) -> None:
    vehicle = Vehicle(Pose(start_x, 10.0, 0.0), ground=thin_wall_world(), speed_mps=2.0)
    _drive(vehicle, Command(2.0, 0.0), 4.0)
    assert vehicle.stuck and vehicle.pose.x + 0.5 < 12.0 and vehicle.attitude.z_m == 0.0


@pytest.mark.parametrize(("yaw", "v"), [(0.0, 0.2), (0.2, 0.5), (0.2, 1.0)])
def test_a_wall_one_cell_thick_is_not_climbed_turning_slowly_beside_it(yaw: float, v: float) -> None:
    # Stopped with the front wheels 16 cm short of the wall and turning while creeping on, a front
    # wheel's way runs sideways into the wall, where a probe straight ahead of it does not look:
    # no wheel ever stands on it.
    vehicle = Vehicle(Pose(11.33, 10.0, yaw), ground=thin_wall_world())
    vehicle.set_command(Command(v, 0.6))
    heights = []
    for _ in range(90):
        vehicle.tick()
        heights.append(max(vehicle.contact._wheels(vehicle.pose)))
    assert max(heights) <= vehicle.config.max_step_m and vehicle.stuck and not vehicle.tipped


def test_a_ledge_under_the_rear_wheels_holds_the_vehicle_the_front_wheels_stand_on() -> None:
    # Started with the front wheels up a 0.5 m ledge (26.6 deg of pitch, within its limit), the
    # rear wheels cannot climb it: the vehicle is held with them at its foot.
    vehicle = Vehicle(Pose(11.8, 10.0, 0.0), ground=world(ledge(0.5)))
    assert vehicle.attitude.pitch_rad == pytest.approx(-math.atan(0.5), abs=1e-6) and not vehicle.tipped
    _drive(vehicle, Command(1.0, 0.0), 4.0)
    assert vehicle.stuck and 11.8 < vehicle.pose.x - 0.5 < 12.0
    assert vehicle.attitude.pitch_rad == pytest.approx(-math.atan(0.5), abs=1e-6)


def test_a_turn_in_place_that_would_swing_a_wheel_onto_a_wall_is_held() -> None:
    # Alongside a wall 10 cm beside its left wheels, a turn either way swings a left corner (the
    # front one turning left, the rear one turning right) 18 cm out, onto the wall: the vehicle
    # does not turn. Along the wall it drives freely.
    beside = {"plateau": {"polygon": [[-5, 10.7], [40, 10.7], [40, 11.2], [-5, 11.2]], "height_m": 2.0, "edge_m": 0.0}}
    for w in (1.0, -1.0):
        turning = Vehicle(Pose(10.0, 10.0, 0.0), ground=world(beside))
        assert not turning.tipped and turning.attitude.z_m == 0.0
        _drive(turning, Command(0.0, w), 1.0)
        assert turning.stuck and abs(turning.pose.yaw) < 0.1 and turning.attitude.z_m < 0.15
    along = Vehicle(Pose(10.0, 10.0, 0.0), ground=world(beside))
    _drive(along, Command(1.0, 0.0), 2.0)
    assert not along.stuck and along.pose.x > 11.0 and along.attitude.z_m == 0.0


def test_a_side_slope_past_the_roll_limit_tips_the_vehicle_and_one_within_it_does_not() -> None:
    steep = {"plateau": {"polygon": [[10, -5], [40, -5], [40, 25], [10, 25]], "height_m": 3.0, "edge_m": 5.0}}  # 31 deg
    gentle = {"plateau": {"polygon": [[10, -5], [40, -5], [40, 25], [10, 25]], "height_m": 2.0, "edge_m": 5.0}}  # 21.8 deg
    tipped = Vehicle(Pose(7.5, 10.0, math.pi / 2), ground=world(steep))
    assert tipped.tipped and math.degrees(abs(tipped.attitude.roll_rad)) == pytest.approx(math.degrees(math.atan(0.6)), abs=1e-4)
    assert not Vehicle(Pose(7.5, 10.0, math.pi / 2), ground=world(gentle)).tipped
    assert not Vehicle(Pose(7.5, 10.0, 0.0), ground=world(gentle)).tipped  # 21.8 deg of pitch is within 30


class Straight:
    """A driver that holds one command."""

    def __init__(self, command: Command) -> None:
        self.command = command

    def reset(self, scenario, rng) -> None:
        pass

    def act(self, frame) -> Command:
        return self.command


def test_a_run_counts_its_tips_and_times_stuck_and_keeps_its_largest_roll_and_pitch() -> None:
    from terrapref.cli.demos import incidents
    from terrapref.evaluation.scoring import score_run
    from terrapref.sim import run_episode

    data = copy.deepcopy(FLAT)
    data["relief"] = [RAMP, ledge(0.2)]
    scenario = parse_scenario(data, "ground_test.yaml")
    sim = Simulation(scenario, config=SimConfig(time_limit_s=12.0, stopped_limit_s=None))
    log = run_episode(sim, Straight(Command(1.0, 0.0)), np.random.default_rng(0))
    assert log.stuck == 1 and log.tips == 0  # held at the ledge on the plateau, once: it kept being held
    assert log.max_pitch_deg == pytest.approx(math.degrees(math.atan(0.2)), abs=1e-4) and log.max_roll_deg == pytest.approx(0.0, abs=1e-6)
    assert log.summary()["stuck"] == 1
    metrics = score_run(log, scenario, sim.world, scenario.classes.profile)
    assert (metrics.stuck, metrics.tips, metrics.incidents) == (1, 0, 1)
    assert metrics.to_dict()["max_pitch_deg"] == pytest.approx(11.31, abs=0.01)
    flat = Simulation(parse_scenario(copy.deepcopy(FLAT), "ground_test.yaml"), config=SimConfig(time_limit_s=3.0))
    flat_log = run_episode(flat, Straight(Command(1.0, 0.0)), np.random.default_rng(0))
    assert (flat_log.tips, flat_log.stuck, flat_log.max_pitch_deg) == (0, 0, 0.0) and "tips" not in flat_log.summary()
    # What record prints of the drive: the time stuck beside the collisions, as it counts; a drive without, as before.
    assert incidents(log) == "0 collisions, 0 tips, 1 times stuck (roll at most 0 deg, pitch 11.31 deg)"
    assert incidents(flat_log) == "0 collisions"
