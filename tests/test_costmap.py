"""The learned preference as a costmap (terrapref.planner.costmap)."""

from __future__ import annotations

import numpy as np
import pytest
from test_corridor import DRIVER_LIKE, K, _columns, _corridor_meta, _scenario, _seen_from

from helpers import skip_path_weights
from terrapref.camera import PinholeCamera
from terrapref.interop.runtime import PlannerRuntime
from terrapref.learning.corridor import CorridorUtility
from terrapref.learning.model_file import save_model
from terrapref.learning.network import ClassifierConfig
from terrapref.planner.costmap import LETHAL_COST, UNKNOWN_COST, class_costs
from terrapref.planner.offset import OffsetStage
from terrapref.terrain import default_classes

PATCHES = [  # 4 m wide, 3 m deep, 6-9 m ahead of a vehicle at (10, 10) looking along +x
    {"class": "mud", "rectangle": {"center": [17.5, 14.0], "size": [3.0, 3.0]}},
    {"class": "rock", "rectangle": {"center": [17.5, 10.0], "size": [3.0, 3.0]}},
    {"class": "water", "rectangle": {"center": [17.5, 6.0], "size": [3.0, 3.0]}},
    {"class": "non_traversable", "rectangle": {"center": [23.0, 10.0], "size": [2.0, 2.0]}},
]


@pytest.fixture(scope="module")
def seen():
    camera = PinholeCamera()
    scenario = _scenario(PATCHES)
    stage = OffsetStage(CorridorUtility(DRIVER_LIKE, 5.0), camera, _columns(), K, np.array([0]), 1.0)
    pose = (10.0, 10.0, 0.0)
    for _ in range(3):
        stage.map.update(_seen_from(scenario, camera, pose), pose)
    return stage.costmap(default_classes().feature_names)


def test_the_cells_of_each_patch_are_priced_in_the_learned_order(seen):
    # DRIVER_LIKE: water dearer than rock, rock dearer than mud; grass costs nothing.
    mud, rock, water, grass = seen.at(17.5, 14.0), seen.at(17.5, 10.0), seen.at(17.5, 6.0), seen.at(13.0, 10.0)
    assert grass == 0 < mud < rock < water == 99
    assert seen.prices["water"] > seen.prices["rock"] > seen.prices["mud"] > 0


def test_lethal_cells_are_lethal_and_ground_never_seen_is_unknown(seen):
    assert seen.at(23.0, 10.0) == LETHAL_COST
    assert seen.at(5.0, 10.0) == UNKNOWN_COST  # behind the camera
    assert seen.at(1e6, 0.0) == UNKNOWN_COST  # off the grid
    assert set(np.unique(seen.cost).tolist()) <= {UNKNOWN_COST, LETHAL_COST, *range(0, 100)}
    assert seen.cost.dtype == np.int8


def test_a_class_liked_better_than_the_background_costs_nothing():
    weights = np.array([-25.5, 0.4, -1.0, -0.5, 0.0, -0.07, -1.3])  # water liked above grass
    lethal = np.array([True, False, False, False, False, False])
    costs, prices = class_costs(weights, lethal, 4)
    assert costs.tolist() == [LETHAL_COST, 0, 99, 50, 0, UNKNOWN_COST] and prices[1] < 0


def test_the_runtime_gives_the_costmap_of_the_ground_it_has_seen(tmp_path):
    config = ClassifierConfig(hidden=8, skip=True)
    path = save_model(tmp_path / "m.safetensors", config, skip_path_weights(config), _corridor_meta(DRIVER_LIKE))
    runtime = PlannerRuntime(path)
    runtime.set_path(np.array([[2.0, 10.0], [38.0, 10.0]]))
    assert (runtime.costmap().cost == UNKNOWN_COST).all()  # nothing seen yet
    scenario = _scenario(PATCHES)
    view = _seen_from(scenario, PinholeCamera(), (10.0, 10.0, 0.0))
    runtime.decide(view.image, 0.0, (10.0, 10.0, 0.0))
    grid = runtime.costmap()
    assert grid.at(23.0, 10.0) == LETHAL_COST and 0 < grid.at(17.5, 14.0) < grid.at(17.5, 6.0)


def test_a_planner_without_a_ground_map_says_so(tmp_path):
    from helpers import model_meta

    config = ClassifierConfig(hidden=8, skip=True)
    runtime = PlannerRuntime(save_model(tmp_path / "c.safetensors", config, skip_path_weights(config), model_meta()))
    with pytest.raises(ValueError, match="keeps no ground map"):
        runtime.costmap()


def test_an_evaluated_run_carries_its_costmap_as_an_occupancy_grid(tmp_path):
    from rosbags.highlevel import AnyReader

    from terrapref.cli import main

    config = ClassifierConfig(hidden=8, skip=True)
    model = save_model(tmp_path / "m.safetensors", config, skip_path_weights(config), _corridor_meta(DRIVER_LIKE))
    out = tmp_path / "ev"
    assert main(["evaluate", str(model), "fig7_rock_vs_non_traversable_left", "--seeds", "1", "--no-driver", "--workers", "1",
                 "--out", str(out), "--mcap"]) == 0
    with AnyReader([out / "runs" / "fig7_rock_vs_non_traversable_left_seed0.mcap"]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        grids = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages() if c.topic == "/terrapref/costmap"]
    assert counts["/terrapref/costmap"] == -(-counts["/terrapref/labels"] // 10)  # once a second
    last = grids[-1]
    cost = np.asarray(last.data, dtype=np.int8).reshape(last.info.height, last.info.width)
    assert last.header.frame_id == "odom" and last.info.resolution > 0
    assert (cost == LETHAL_COST).any() and (cost == UNKNOWN_COST).any() and ((cost > 0) & (cost < LETHAL_COST)).any()  # trees, unseen, rock
