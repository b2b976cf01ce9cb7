"""The simulation loop: timing, determinism, collisions, goal (the Gymnasium environments: test_gym_env.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from terrapref.scenario import Scenario, parse_scenario
from terrapref.sim import Frame, SimConfig, Simulation, run_episode
from terrapref.vehicle import Command, Pose, VehicleConfig

AT_ONCE = SimConfig.paper()  # commands applied at once: the loop's timing and counting alone


def _scenario(terrain: list[dict] | None = None, waypoints: list[list[float]] | None = None, start: list[float] | None = None) -> Scenario:
    data = {
        "format": "terrapref-scenario/1",
        "name": "tiny_sim",
        "world": {"size_m": [20.0, 10.0], "resolution_m": 0.05, "background": "grass"},
        "terrain": terrain or [],
        "path": {"waypoints": waypoints or [[2.0, 5.0], [15.0, 5.0]]},
    }
    if start is not None:
        data["start"] = start
    return parse_scenario(data)


class PursuitDriver:
    """Steers toward the next unreached waypoint, with a little seeded stick noise."""

    def __init__(self, noise_rps: float = 0.05) -> None:
        self.noise_rps = noise_rps

    def reset(self, scenario: Scenario, rng: np.random.Generator) -> None:
        self.rng = rng
        self.target = 1

    def act(self, frame: Frame) -> Command:
        x, y, yaw = frame.pose
        wp = frame.waypoints
        while self.target < len(wp) - 1 and math.hypot(wp[self.target, 0] - x, wp[self.target, 1] - y) < 1.0:
            self.target += 1
        tx, ty = wp[self.target]
        error = (math.atan2(ty - y, tx - x) - yaw + math.pi) % (2 * math.pi) - math.pi
        return Command(1.0, float(np.clip(2.0 * error + self.rng.normal(0.0, self.noise_rps), -1.0, 1.0)))


# --- timing -----------------------------------------------------------------------------------


def test_frames_at_10hz_ticks_at_30hz():
    sim = Simulation(_scenario(), config=AT_ONCE)
    frame = sim.reset()
    assert frame.index == 0 and frame.time_s == 0.0 and len(sim.trace) == 1
    for k in range(1, 6):
        frame = sim.step(Command(1.0, 0.0))
        assert frame.index == k
        assert frame.time_s == pytest.approx(0.1 * k)
        assert len(sim.trace) == 1 + 3 * k
        assert len(sim.commands) == k
    steps = np.diff(np.array(sim.trace)[:, :2], axis=0)
    np.testing.assert_allclose(np.linalg.norm(steps, axis=1), 1.0 / 30.0, atol=1e-12)  # 1 m/s for 1/30 s
    assert frame.pose.x == pytest.approx(2.5, abs=1e-12)
    assert frame.image.shape == (480, 640)


def test_camera_rate_must_divide_the_control_rate():
    assert SimConfig().ticks_per_frame == 3
    assert SimConfig(camera_rate_hz=5.0).ticks_per_frame == 6
    with pytest.raises(ValueError):
        SimConfig(camera_rate_hz=7.0)
    with pytest.raises(ValueError):
        SimConfig(camera_rate_hz=60.0, vehicle=VehicleConfig(control_rate_hz=30.0))


def test_other_rates_keep_the_tick_count():
    sim = Simulation(_scenario(), config=SimConfig(camera_rate_hz=5.0, vehicle=VehicleConfig(control_rate_hz=40.0, max_accel_mps2=None)))
    sim.step(Command(1.0, 0.0))
    assert len(sim.trace) == 1 + 8 and sim.time_s == pytest.approx(0.2)
    assert sim.vehicle.pose.x == pytest.approx(2.2, abs=1e-12)


# --- determinism ------------------------------------------------------------------------------


def test_seeded_run_episode_is_identical():
    scenario = _scenario(
        terrain=[{"class": "mud", "rectangle": {"center": [8.0, 5.0], "size": [2.0, 3.0]}}],
        waypoints=[[2.0, 5.0], [10.0, 5.0], [16.0, 8.0]],
    )
    logs = [run_episode(Simulation(scenario), PursuitDriver(), np.random.default_rng(5)) for _ in range(2)]
    a, b = logs
    assert a.completed and b.completed
    np.testing.assert_array_equal(a.trace, b.trace)
    np.testing.assert_array_equal(a.commands, b.commands)
    assert (a.collisions, a.duration_s) == (b.collisions, b.duration_s)
    assert len(a.trace) == 1 + 3 * len(a.commands)
    # A different seed changes the stick noise, and so the trace.
    c = run_episode(Simulation(scenario), PursuitDriver(), np.random.default_rng(6))
    assert not np.array_equal(c.trace[: len(a.trace)], a.trace[: len(c.trace)])


def test_simulation_reset_starts_over():
    sim = Simulation(_scenario(), config=AT_ONCE)
    first = sim.reset()
    for _ in range(5):
        sim.step(Command(1.0, 0.3))
    again = sim.reset()
    assert again.pose == first.pose and sim.tick == 0 and sim.collisions == 0 and len(sim.trace) == 1
    np.testing.assert_array_equal(again.image, first.image)


# --- collisions and the goal ------------------------------------------------------------------

LETHAL_STRIP = {"class": "non_traversable", "rectangle": {"center": [6.0, 5.0], "size": [1.0, 4.0]}}
SECOND_STRIP = {"class": "non_traversable", "rectangle": {"center": [10.0, 5.0], "size": [0.5, 4.0]}}


def test_a_collision_counts_once_per_entry():
    sim = Simulation(_scenario(terrain=[LETHAL_STRIP]), config=AT_ONCE)
    for _ in range(40):  # 4 m: from x = 2 into the strip (5.5..6.5) and stopped inside it
        sim.step(Command(1.0, 0.0))
    assert 5.5 < sim.vehicle.pose.x < 6.5
    assert sim.collisions == 1
    for _ in range(10):  # standing still on it is no new entry
        sim.step(Command(0.0, 0.0))
    assert sim.collisions == 1
    for _ in range(20):  # drive out of it
        sim.step(Command(1.0, 0.0))
    assert sim.vehicle.pose.x > 6.5 and sim.collisions == 1


def test_each_entry_is_a_new_collision():
    sim = Simulation(_scenario(terrain=[LETHAL_STRIP, SECOND_STRIP]), config=AT_ONCE)
    for _ in range(100):
        sim.step(Command(1.0, 0.0))
    assert sim.vehicle.pose.x == pytest.approx(12.0, abs=1e-9)
    assert sim.collisions == 2
    # Started again facing west beyond the second strip: driving back over it is one entry.
    sim.reset(Pose(12.0, 5.0, math.pi))
    for _ in range(30):
        sim.step(Command(1.0, 0.0))
    assert sim.collisions == 1


def test_non_lethal_terrain_is_no_collision():
    sim = Simulation(_scenario(terrain=[{"class": "water", "rectangle": {"center": [6.0, 5.0], "size": [1.0, 4.0]}}]))
    for _ in range(60):
        sim.step(Command(1.0, 0.0))
    assert sim.collisions == 0


def test_run_episode_reaches_the_goal_and_stops():
    sim = Simulation(_scenario(), config=AT_ONCE)
    log = run_episode(sim, PursuitDriver(noise_rps=0.0), np.random.default_rng(0))
    assert log.completed and log.collisions == 0
    assert log.duration_s == pytest.approx(len(log.commands) * 0.1)
    assert math.hypot(log.trace[-1, 0] - 15.0, log.trace[-1, 1] - 5.0) <= 2.0
    assert log.trace.shape == (1 + 3 * len(log.commands), 3)


def test_being_near_the_end_too_early_is_not_the_goal():
    # A loop whose end lies beside its start: arriving there first is no finish.
    waypoints = [[2.0, 5.0], [16.0, 5.0], [16.0, 8.0], [2.0, 8.0], [2.0, 6.5]]
    sim = Simulation(_scenario(waypoints=waypoints, start=[2.0, 5.0, 0.0]))
    assert not sim.reached_goal
    assert math.hypot(2.0 - 2.0, 6.5 - 5.0) <= sim.config.goal_radius_m


def test_default_time_limit():
    assert Simulation(_scenario()).time_limit_s == pytest.approx(2 * 13.0 / 1.0 + 60.0)
    sim = Simulation(_scenario(), config=SimConfig(time_limit_s=1.0))
    for _ in range(9):
        sim.step(Command(0.0, 0.0))
    assert not sim.timed_out
    sim.step(Command(0.0, 0.0))
    assert sim.timed_out and sim.done


def test_reset_accepts_a_numpy_pose():
    import numpy as np

    from terrapref.scenario import resolve_scenario
    from terrapref.sim import Simulation

    sim = Simulation(resolve_scenario("demo_course"))
    frame = sim.reset(np.array([5.0, 10.0, 0.25]))
    assert tuple(frame.pose) == (5.0, 10.0, 0.25)


def test_the_default_vehicle_starts_from_rest_and_counts_the_distance_it_ramps_over():
    sim = Simulation(_scenario(terrain=[LETHAL_STRIP]))  # the field UGV: 1 m/s^2 up, 2 m/s^2 down
    for _ in range(10):
        sim.step(Command(2.0, 0.0))
    assert sim.vehicle.speed_mps == pytest.approx(1.0, abs=1e-12)  # 1 s of 1 m/s^2
    assert sim.vehicle.pose.x == pytest.approx(2.0 + 0.5, abs=1e-9)
    np.testing.assert_allclose(sim.speeds[:4], [0.0, 1 / 30, 2 / 30, 3 / 30], atol=1e-12)
    while sim.vehicle.pose.x < 5.9:  # into the strip (5.5..6.5)
        sim.step(Command(1.0, 0.0))
    for _ in range(6):  # braking from 1 m/s at 2 m/s^2: 0.5 s and 0.25 m, all of it in contact
        sim.step(Command(0.0, 0.0))
    driven_in = sim.vehicle.pose.x - 5.5
    assert sim.collisions == 1 and sim.vehicle.speed_mps == 0.0
    assert sim.contact_m == pytest.approx(driven_in, abs=1 / 30 + 1e-9)  # counted per tick, at the ramped speed
