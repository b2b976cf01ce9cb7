"""The goal check (terrapref.planner.goal): the planner stops at the end of its path and far off
it, slows for its goal, and turns back to a path behind it, whatever drives it (the runtime a
robot runs, or a simulated run that `evaluate` scores)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_interop import speed_block
from test_offset_rule import DRIVER_LIKE, _offset_meta

from helpers import skip_path_weights
from terrapref.interop.runtime import PlannerRuntime
from terrapref.learning.model_file import save_model
from terrapref.learning.network import ClassifierConfig
from terrapref.planner.goal import TURN_MPS, GoalCheck
from terrapref.planner.stop import StopConfig
from terrapref.scenario.loader import parse_scenario
from terrapref.scenario.path import PathTracker, ReferencePath
from terrapref.sim import SimConfig, Simulation
from terrapref.sim.loop import run_episode, settle
from terrapref.vehicle import Pose

OPEN = {
    "format": "terrapref-scenario/1",
    "name": "open_ground",
    "world": {"size_m": [80.0, 40.0], "resolution_m": 0.05, "background": "grass"},
    "terrain": [],
    "path": {"waypoints": [[20.0, 20.0], [30.0, 20.0]]},  # 10 m east
}


@pytest.fixture(scope="module")
def fast_model(tmp_path_factory):
    """The offset rule at 1.6 m/s on every class (a speed rule's block): what drove 36 m past a 10 m path's end."""
    config = ClassifierConfig(hidden=8, skip=True)
    meta = _offset_meta(DRIVER_LIKE)
    meta["rules"] = [*meta["rules"], speed_block(1.6)]
    return save_model(tmp_path_factory.mktemp("goal") / "fast.safetensors", config, skip_path_weights(config), meta)


@pytest.fixture(scope="module")
def open_ground():
    return parse_scenario(OPEN)


def _drive(model, scenario, start, waypoints=None, frames=250, **runtime):
    """The runtime driving a simulated vehicle frame by frame (the simulator only moves the vehicle
    and renders: it never ends the run): the poses at each frame, the commands sent and the reasons."""
    sim = Simulation(scenario, config=SimConfig(stopped_limit_s=None))
    planner = PlannerRuntime(model, **runtime)
    planner.set_path(np.asarray(scenario.waypoints if waypoints is None else waypoints, dtype=float))
    frame = sim.reset(Pose(*start))
    poses, commands, reasons = [], [], []
    for _ in range(frames):
        planner.decide(frame.image, frame.time_s, frame.pose, frame.speed_mps)
        command, reason = planner.status_at(frame.time_s)
        poses.append(frame.pose)
        commands.append(command)
        reasons.append(reason)
        frame = sim.step(command, reason)
    return np.array(poses), np.array(commands), reasons, planner


def test_the_runtime_stops_at_the_end_of_a_10_m_path_and_stays(fast_model, open_ground):
    poses, commands, reasons, _ = _drive(fast_model, open_ground, (20.0, 20.0, 0.0))
    assert commands[:, 0].max() == pytest.approx(1.6)  # it cruised at its speed rule's speed on the way
    assert reasons[-1] == "goal" and tuple(commands[-1]) == (0.0, 0.0)
    first = reasons.index("goal")
    assert all(r == "goal" for r in reasons[first:])  # it stays stopped: the goal holds until a new path
    assert np.abs(poses[first:, 0] - poses[-1, 0]).max() < 1.0  # it stood within a metre of where it stopped
    assert abs(poses[-1, 0] - 30.0) < 0.5 and abs(poses[-1, 1] - 20.0) < 0.1  # at the path's end, not 36 m past it
    assert poses[:, 0].max() < 30.5


def test_the_approach_slows_so_that_the_stop_is_at_the_goal(fast_model, open_ground):
    poses, commands, _, _ = _drive(fast_model, open_ground, (20.0, 20.0, 0.0))
    to_go = 30.0 - poses[:, 0]
    near = (to_go > 0.5) & (to_go < 1.2)
    assert near.any() and np.all(commands[near, 0] <= np.sqrt(2.0 * 1.0 * to_go[near]) + 1e-9)  # sqrt(2 a d), a the stop rule's 1 m/s^2


@pytest.mark.parametrize(
    "start, waypoints, reason",
    [
        ((20.0, 20.0, 0.0), [[20.0, 20.0], [20.05, 20.0]], "goal"),  # a path of 5 cm: there already
        ((35.0, 20.0, 0.0), None, "goal"),  # started 5 m past the end of the path: nothing left to drive
        ((20.0, 35.0, 0.0), [[20.0, 5.0], [60.0, 5.0]], "off_path"),  # 30 m from the path
        ((1e300, 1e300, 0.0), None, "off_path"),  # a pose too far off to compute with
        ((5000.0, 20.0, 0.0), None, "off_path"),  # kilometres away
    ],
)
def test_the_runtime_never_moves_where_there_is_nothing_to_drive(fast_model, open_ground, start, waypoints, reason):
    _, commands, reasons, _ = _drive(fast_model, open_ground, start, waypoints, frames=5)
    assert set(reasons) == {reason} and not commands[:, 0].any()


def test_a_vehicle_facing_away_from_its_path_turns_back_and_reaches_the_goal(fast_model, open_ground):
    poses, commands, reasons, _ = _drive(fast_model, open_ground, (20.0, 20.0, math.pi))  # the path runs east, the vehicle faces west
    assert poses[:, 0].min() > 18.0  # it turned back within a couple of metres, not off to the map's edge
    assert reasons[-1] == "goal" and abs(poses[-1, 0] - 30.0) < 0.5
    turning = commands[np.abs((poses[:, 2] + math.pi) % (2 * math.pi) - math.pi) > math.pi / 2 + 0.3]  # while it faced away
    assert turning[:, 0].max() <= TURN_MPS and np.abs(turning[turning[:, 0] > 0, 1]).max() == pytest.approx(1.0)  # slowly, turning hard


def test_a_new_path_starts_again_after_the_goal(fast_model, open_ground):
    _, _, reasons, runtime = _drive(fast_model, open_ground, (20.0, 20.0, 0.0))
    assert reasons[-1] == "goal"
    runtime.set_path(np.array([[30.0, 20.0], [40.0, 20.0]]))
    image = np.zeros(runtime.shape, dtype=np.uint8)  # grass all round
    decision = runtime.decide(image, 1000.0, (30.0, 20.0, 0.0))
    assert decision.stop is None and decision.command.v > 0


def test_evaluate_sees_the_planner_stand_at_its_goal(fast_model, open_ground):
    """A run scored complete at 2 m from the end is driven on until the planner stands, saying `goal`."""
    from terrapref.planner import Planner, PlannerDriver
    from terrapref.planner.model import Model

    sim = Simulation(open_ground)
    driver = PlannerDriver(Planner(Model.load(fast_model).policy))
    log = run_episode(sim, driver, np.random.default_rng(0))
    assert log.completed and sim.vehicle.speed_mps > 1.0  # scored complete 2 m from the end, still going
    stood = settle(sim, driver, 10.0)
    assert stood.stopped and stood.from_end_m < 0.5 and 0 < stood.after_s < 10.0 and sim.vehicle.speed_mps == 0.0


def test_evaluate_of_a_start_facing_away_turns_back_and_completes(fast_model):
    """A course whose start faces away from its path: the planner turns back and drives it to its
    goal, where it used to arc away to the map's edge and end blind."""
    from terrapref.planner import Planner, PlannerDriver
    from terrapref.planner.model import Model

    backwards = parse_scenario({**OPEN, "path": {"waypoints": [[20.0, 20.0], [40.0, 20.0]]}, "start": [20.0, 20.0, 180.0]})
    log = run_episode(Simulation(backwards), PlannerDriver(Planner(Model.load(fast_model).policy)), np.random.default_rng(0))
    assert log.completed and log.ended == "goal" and log.trace[:, 0].min() > 18.0 and not log.stops


# --- the check itself -----------------------------------------------------------------------------


def _state(check, pose, path):
    tracker = PathTracker(path)
    s = tracker.update(np.array(pose[:2]))
    return check.check(Pose(*pose), path, s, tracker.lateral_m)


def test_a_path_that_ends_where_it_starts_is_not_done_at_its_start():
    loop = ReferencePath(np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0], [0.0, 0.0]]))
    state = _state(GoalCheck(StopConfig(), 1.0), (0.0, 0.0, 0.0), loop)
    assert state.stop is None and state.cap_mps == pytest.approx(math.sqrt(2.0 * 40.0))


def test_with_a_heading_tolerance_the_vehicle_turns_in_place_at_the_goal():
    path = ReferencePath(np.array([[0.0, 0.0], [10.0, 0.0]]))
    check = GoalCheck(StopConfig(goal_yaw_tolerance_deg=10.0), 1.0)
    state = _state(check, (9.9, 0.0, 0.5), path)  # at the end, 29 degrees left of the path's direction
    assert state.stop is None and state.turn_mps == 0.0 and state.turn_rps == pytest.approx(-1.0)
    state = _state(check, (9.9, 0.0, 0.1), path)  # within 10 degrees
    assert state.stop == "goal" and check.reached
    assert _state(GoalCheck(StopConfig(), 1.0), (9.9, 0.0, 0.5), path).stop == "goal"  # no heading checked by default


@pytest.mark.parametrize(
    "settings",
    [{"goal_tolerance_m": 0.0}, {"off_path_m": 0.4}, {"goal_yaw_tolerance_deg": 0.0}, {"goal_yaw_tolerance_deg": math.nan}],
)
def test_the_goal_settings_are_checked(settings):
    with pytest.raises(ValueError):
        StopConfig(**settings)


@pytest.mark.parametrize(
    "pose, stop",
    [
        ((10.1, 8.0, 0.0), None),  # past the end's line, 8 m beside it: not at its goal
        ((10.1, 0.6, 0.0), None),  # just past the tolerance beside it
        ((10.1, 0.4, 0.0), "goal"),  # within it
        ((15.0, 0.0, 0.0), "goal"),  # 5 m past the end, on the path's line: nothing left to drive
    ],
)
def test_a_vehicle_past_the_end_is_at_its_goal_only_near_the_path_s_line(pose, stop):
    path = ReferencePath(np.array([[0.0, 0.0], [10.0, 0.0]]))
    assert _state(GoalCheck(StopConfig(), 1.0), pose, path).stop == stop


def test_a_vehicle_that_passes_the_end_beside_it_comes_back_to_its_goal(fast_model, open_ground):
    """Past the path's end 2 m beside it, the planner turns back to the end's line and says `goal`
    there, where it used to say `goal` where it stood."""
    poses, _, reasons, _ = _drive(fast_model, open_ground, (30.5, 22.0, 0.0), waypoints=[[20.0, 20.0], [30.0, 20.0]], frames=120)
    assert reasons[0] is None  # it did not claim its goal 2 m beside it
    first = reasons.index("goal")
    assert abs(poses[first, 1] - 20.0) <= 0.5 + 0.1 and poses[first, 0] > 29.5  # on the end's line (a frame's travel), at or past the end
    assert all(r == "goal" for r in reasons[first:])


def test_a_patch_of_lethal_terrain_on_the_path_s_end_is_gone_round_and_the_goal_still_reached(fast_model):
    """A vehicle that goes round a lethal patch lying on the path's end passes the end beside it:
    no longer at its goal there, it must come back to it and stand, not circle."""
    patch = {"class": "non_traversable", "circle": {"center": [29.5, 20.0], "radius": 0.8}}
    poses, commands, reasons, _ = _drive(fast_model, parse_scenario({**OPEN, "terrain": [patch]}), (20.0, 20.0, 0.0), frames=300)
    first = reasons.index("goal")
    assert all(r == "goal" for r in reasons[first:]) and not commands[first:, 0].any()
    assert abs(poses[first, 1] - 20.0) <= 0.5 + 0.1 and poses[first, 0] > 29.5  # on the end's line, at or past the end


@pytest.mark.parametrize("waypoints", [[[0.0, 0.0], [1e308, 1e308], [-1e308, 5.0]], [[0.0, 0.0], [1e200, 0.0]], [[0.0, 0.0], [2e7, 0.0]]])
def test_a_path_whose_lengths_would_overflow_is_refused_before_it_is_driven(fast_model, waypoints):
    """Points past any place on Earth made the progress along the path NaN, and the runtime turned on it."""
    runtime = PlannerRuntime(fast_model)
    with pytest.raises(ValueError, match=r"a path's points lie within \+-1e\+07 m of the origin"):
        runtime.set_path(np.asarray(waypoints))
    assert ReferencePath(np.array([[0.0, 0.0], [9.9e6, 0.0]])).length_m == pytest.approx(9.9e6)  # UTM coordinates still fit
