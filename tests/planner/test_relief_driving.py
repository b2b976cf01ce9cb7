"""The planner on relief, in closed loop on clean frames: a wall higher than the vehicle climbs,
across its whole way, is seen through the depth camera and stopped short of (no_free_way, for its geometry),
never run into; without the height layer's limits the same planner drives into it and is held
there; a sill under the step it climbs is driven over."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_offset_rule import DRIVER_LIKE, _offset_meta

from helpers import skip_path_weights
from terrapref.learning.model_file import load_model, save_model
from terrapref.learning.network import ClassifierConfig
from terrapref.planner import Planner, PlannerDriver
from terrapref.scenario import FORMAT, parse_scenario
from terrapref.sim import SimConfig, Simulation, run_episode
from terrapref.stops import NO_FREE_WAY, NO_FREE_WAY_GEOMETRY

TRAIL: dict[str, Any] = {
    "format": FORMAT,
    "name": "relief_trail",
    "world": {"size_m": [20.0, 12.0], "resolution_m": 0.05, "background": "grass"},
    "terrain": [],
    "path": {"waypoints": [[1.0, 6.0], [17.0, 6.0]]},
}


def _across(height_m: float) -> dict:
    """A ledge of ``height_m`` up at x = 8 m, across the whole map, and down again 0.5 m on."""
    return {"plateau": {"polygon": [[8.0, -5.0], [8.5, -5.0], [8.5, 20.0], [8.0, 20.0]], "height_m": height_m, "edge_m": 0.0}}


@pytest.fixture(scope="module")
def model(tmp_path_factory: pytest.TempPathFactory):
    config = ClassifierConfig(hidden=8, skip=True)
    folder: Path = tmp_path_factory.mktemp("relief")
    return load_model(save_model(folder / "m.safetensors", config, skip_path_weights(config), _offset_meta(DRIVER_LIKE)))


def _drive(model, height_m: float, limits: bool = True, seconds: float = 20.0):
    data = copy.deepcopy(TRAIL)
    data["relief"] = [_across(height_m)]
    sim = Simulation(parse_scenario(data, "relief_trail.yaml"), config=SimConfig(time_limit_s=seconds, stopped_limit_s=3.0))
    planner = Planner(model)
    if not limits:
        for ground_map in planner._maps.values():
            ground_map.limits = None
    return run_episode(sim, PlannerDriver(planner), np.random.default_rng(0))


def test_a_wall_across_the_way_is_stopped_short_of_and_never_run_into(model) -> None:
    log = _drive(model, 0.4)
    assert log.stuck == 0 and log.tips == 0 and log.collisions == 0
    assert log.ended == "stopped" and set(log.stops) == {NO_FREE_WAY_GEOMETRY}
    front = log.trace[-1, 0] + 0.5  # the front wheels, half the wheelbase ahead
    assert 6.5 < front < 8.0 - 0.1  # short of the wall, and not far short


def test_without_the_height_layers_limits_the_planner_drives_into_the_wall(model) -> None:
    log = _drive(model, 0.4, limits=False, seconds=8.0)
    assert log.stuck >= 1 and not {NO_FREE_WAY, NO_FREE_WAY_GEOMETRY} & set(log.stops)


def test_a_sill_under_the_step_the_vehicle_climbs_is_driven_over(model) -> None:
    log = _drive(model, 0.1)
    assert log.completed and log.stuck == 0 and log.tips == 0 and not log.stops
