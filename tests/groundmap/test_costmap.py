"""The learned preference as a costmap (terrapref.groundmap.costmap)."""

from __future__ import annotations

import numpy as np
import pytest
from test_offset_rule import DRIVER_LIKE, _offset_meta, _scenario, _seen_from, _terrain

from helpers import skip_path_weights
from terrapref.camera import PinholeCamera
from terrapref.features import FeatureConfig
from terrapref.groundmap import height_compiled as kernels
from terrapref.groundmap.costmap import LETHAL_COST, UNKNOWN_COST, class_costs, with_layers
from terrapref.groundmap.map import GroundMap
from terrapref.interop.runtime import PlannerRuntime
from terrapref.learning.model_file import save_model
from terrapref.learning.network import ClassifierConfig
from terrapref.rules.offset.fit import OffsetUtility
from terrapref.rules.offset.geometry import OffsetGeometry
from terrapref.rules.offset.rule import OffsetSteering
from terrapref.terrain import default_classes

CONTROL = FeatureConfig().preference.control  # the default control set: 1 m/s

PATCHES = [  # 4 m wide, 3 m deep, 6-9 m ahead of a vehicle at (10, 10) looking along +x
    {"class": "mud", "rectangle": {"center": [17.5, 14.0], "size": [3.0, 3.0]}},
    {"class": "rock", "rectangle": {"center": [17.5, 10.0], "size": [3.0, 3.0]}},
    {"class": "water", "rectangle": {"center": [17.5, 6.0], "size": [3.0, 3.0]}},
    {"class": "non_traversable", "rectangle": {"center": [23.0, 10.0], "size": [2.0, 2.0]}},
]


def _seen_patches() -> tuple[OffsetSteering, GroundMap]:
    """An offset rule and its ground map after three frames of PATCHES from (10, 10) along +x."""
    camera = PinholeCamera()
    scenario = _scenario(PATCHES)
    stage = OffsetSteering(OffsetUtility(DRIVER_LIKE, 5.0), camera, _terrain((0,), default_classes().feature_names), CONTROL)
    pose = (10.0, 10.0, 0.0)
    gmap = GroundMap(camera, _terrain((0,), default_classes().feature_names), stage.map_settings)
    for _ in range(3):
        gmap.update(_seen_from(scenario, camera, pose), pose)
    return stage, gmap


@pytest.fixture(scope="module")
def seen():
    stage, gmap = _seen_patches()
    return stage.costmap(gmap)


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


def test_the_costmaps_layers_hold_each_cells_speed_and_the_height_layers_geometry():
    """The speed of each cell's column (lethal 0, never seen NaN), and the elevation written into
    the height layer where trusted with the slope of a plane through it and the roughness the frames read,
    over exactly the costmap's cells."""
    stage, gmap = _seen_patches()
    res = gmap.settings.map_resolution_m
    elevation = gmap.layer("elevation")
    rows, cols = np.mgrid[0 : elevation.shape[0], 0 : elevation.shape[1]]
    elevation[...] = (0.2 * res * cols).astype(np.float32)  # a ramp up along x of grade 0.2
    gmap.layer("returns")[...] = 3  # each cell's returns agreeing
    gmap.layer("weight")[...] = 3 / 0.01**2  # ... each known to 1 cm
    shape = gmap.layer("shape")
    for first, rise in ((kernels.SHAPE_X, 0.2 * res), (kernels.SHAPE_Y, 0.0)):  # and the differences between neighbours the frames showed
        shape[..., first + kernels.RISE], shape[..., first + kernels.RUN], shape[..., first + kernels.WEIGHT] = rise, res, 1e4
    gmap.read_shape()
    gmap.layer("rough")[...], gmap.layer("rough_weight")[...] = 0.02**2, 1.0  # the frames read 2 cm of roughness ...
    gmap.layer("rough_weight")[:, :5] = 0.0  # ... save in the first five columns
    costmap = stage.costmap(gmap)
    speeds = np.array([0.0, 0.4, 0.6, 0.8, 1.5, np.nan])  # K = 4 columns, the background, never seen
    full = with_layers(costmap, gmap, speeds, 2.0)
    assert full.top_speed_mps == 2.0 and set(full.layers) == {"speed", "elevation", "slope", "roughness", "step"}
    r0 = round((costmap.origin[1] - gmap.origin[1]) / res)
    c0 = round((costmap.origin[0] - gmap.origin[0]) / res)
    h, w = costmap.cost.shape
    cells = gmap.cells[r0 : r0 + h, c0 : c0 + w]
    np.testing.assert_array_equal(full.layers["speed"], speeds.astype(np.float32)[cells])
    assert (full.layers["speed"][costmap.cost == LETHAL_COST] == 0.0).all()
    assert np.isnan(full.layers["speed"][costmap.cost == UNKNOWN_COST]).all()
    np.testing.assert_array_equal(full.layers["elevation"], elevation[r0 : r0 + h, c0 : c0 + w])
    gmap.layer("returns")[:, : c0 + 4] = 1  # one return a cell is not yet trusted: the layer says nothing there
    once = with_layers(costmap, gmap, speeds, 2.0).layers["elevation"]
    assert np.isnan(once[:, :4]).all()
    np.testing.assert_array_equal(once[:, 4:], elevation[r0 : r0 + h, c0 + 4 : c0 + w])
    gmap.layer("returns")[...] = 3
    inner = full.layers["slope"][3:-3, 3:-3]
    np.testing.assert_allclose(inner, np.arctan(0.2), atol=1e-4)
    rough = gmap.layer("rough_weight")[r0 : r0 + h, c0 : c0 + w] > 0
    assert rough.any() and np.allclose(full.layers["roughness"][rough], 0.02) and np.isnan(full.layers["roughness"][~rough]).all()
    assert "speed" not in with_layers(costmap, gmap, None, 2.0).layers
    # A speed rule that sheds 0.03 m/s per degree of grade: each cell's speed less that for its
    # slope's degrees (11.3), down to the least; lethal and never-seen ground as they were.
    shed = with_layers(costmap, gmap, speeds, 2.0, (0.03, 0.3)).layers["speed"]
    known = np.isfinite(full.layers["slope"]) & (full.layers["speed"] > 0)
    expected = np.maximum(full.layers["speed"] - 0.03 * np.degrees(full.layers["slope"]), 0.3)
    np.testing.assert_allclose(shed[known], expected[known], rtol=1e-6)
    assert known[3:-3, 3:-3].any() and (shed[known] < full.layers["speed"][known]).all()
    np.testing.assert_array_equal(shed[~known], full.layers["speed"][~known])


def test_the_runtime_gives_the_costmap_of_the_ground_it_has_seen(tmp_path):
    config = ClassifierConfig(hidden=8, skip=True)
    path = save_model(tmp_path / "m.safetensors", config, skip_path_weights(config), _offset_meta(DRIVER_LIKE))
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


def _costmaps_in(mcap) -> tuple[dict[str, int], np.ndarray]:
    """The message count of each topic of an MCAP run and its last costmap's cells, read from
    the OccupancyGrid, after checking that the Foxglove Grid beside it holds the same costs, in
    the same place, in the colours of cost_colours, and that both cover the ground seen, not the
    whole map the planner keeps."""
    from rosbags.highlevel import AnyReader

    from terrapref.groundmap.costmap import cost_colours
    from terrapref.interop.ros_messages import grid_map_layer

    with AnyReader([mcap]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        wanted = ("/terrapref/costmap", "/terrapref/grid_map")
        last = {c.topic: reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages() if c.topic.startswith(wanted)}
    occupancy, grid = last["/terrapref/costmap"], last["/terrapref/costmap_grid"]
    cost = np.asarray(occupancy.data, dtype=np.int8).reshape(occupancy.info.height, occupancy.info.width)
    layers = last["/terrapref/grid_map"]  # the same cells' layers, as grid_map lays them out
    assert layers.layers == ["cost", "elevation", "slope", "roughness", "step"]  # no speed rule, no speed layer
    assert layers.info.length_x == pytest.approx(occupancy.info.width * occupancy.info.resolution)
    np.testing.assert_array_equal(grid_map_layer(layers, "cost"), np.where(cost == UNKNOWN_COST, np.nan, cost).astype(np.float32))
    assert np.isnan(grid_map_layer(layers, "elevation")).all()  # a recording carries no depth
    assert occupancy.header.frame_id == grid.frame_id == "odom" and occupancy.info.resolution > 0
    full = round(2 * OffsetGeometry().map_half_size_m / OffsetGeometry().map_resolution_m)
    assert occupancy.info.width * occupancy.info.height < full * full  # cropped to the ground seen
    assert (grid.timestamp.sec, grid.timestamp.nanosec) == (occupancy.header.stamp.sec, occupancy.header.stamp.nanosec)
    assert grid.column_count == occupancy.info.width and grid.cell_size.x == grid.cell_size.y == pytest.approx(occupancy.info.resolution)
    assert (grid.pose.position.x, grid.pose.position.y) == (occupancy.info.origin.position.x, occupancy.info.origin.position.y)
    assert [(f.name, f.offset, f.type) for f in grid.fields] == [
        ("cost", 0, 2),
        ("red", 1, 1),
        ("green", 2, 1),
        ("blue", 3, 1),
        ("alpha", 4, 1),
    ]
    cells = np.asarray(grid.data, dtype=np.uint8).reshape(-1, grid.column_count, grid.cell_stride)
    assert grid.row_stride == grid.column_count * grid.cell_stride and cells.shape[0] == occupancy.info.height
    np.testing.assert_array_equal(cells[..., 0].view(np.int8), cost)
    np.testing.assert_array_equal(cells[..., 1:], cost_colours(cost))
    return counts, cost


@pytest.mark.slow  # a whole drive or export end to end, its steps tested apart in the default run
def test_an_exported_recording_carries_the_costmap_a_model_sees_in_it(tmp_path, capsys, short_recording):
    from helpers import model_meta, one_line_error
    from terrapref.cli import main

    config = ClassifierConfig(hidden=8, skip=True)
    model = save_model(tmp_path / "m.safetensors", config, skip_path_weights(config), _offset_meta(DRIVER_LIKE))
    rec = short_recording
    assert main(["export", str(rec), "--format", "mcap", "--model", str(model), "--out", str(tmp_path / "run.mcap")]) == 0
    counts, cost = _costmaps_in(tmp_path / "run.mcap")
    assert counts["/terrapref/costmap"] == -(-counts["/terrapref/labels"] // 10)
    assert (cost == LETHAL_COST).any() and ((cost > 0) & (cost < LETHAL_COST)).any()
    capsys.readouterr()
    plain = save_model(tmp_path / "c.safetensors", config, skip_path_weights(config), model_meta())
    assert main(["export", str(rec), "--format", "mcap", "--model", str(plain), "--out", str(tmp_path / "c.mcap")]) == 2
    one_line_error(capsys, "c.safetensors", "no offset rule")
    assert not (tmp_path / "c.mcap").exists()


def test_an_evaluations_run_on_relief_carries_its_depth_and_the_heights_its_costmap_gathered(tmp_path, capsys):
    """`evaluate --mcap` renders each run's frames again at the poses driven: on relief with the
    body's attitude there and each frame's depth image (on /terrapref/depth), so that the GridMap's
    height layers hold what the planner's map gathered from them, as the planner saw them."""
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import QosDurability

    from helpers import TINY_RELIEF
    from terrapref.cli import main
    from terrapref.interop.mcap_export import COSTMAP_TOPICS
    from terrapref.interop.ros_messages import grid_map_layer

    config = ClassifierConfig(hidden=8, skip=True)
    model = save_model(tmp_path / "m.safetensors", config, skip_path_weights(config), _offset_meta(DRIVER_LIKE))
    out = tmp_path / "ev"
    argv = ["evaluate", str(model), str(TINY_RELIEF), "--seeds", "1", "--no-driver", "--workers", "1", "--out", str(out), "--mcap"]
    assert main(argv) == 0
    (run,) = (out / "runs").glob("*seed0.mcap")
    with AnyReader([run]) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
        grids = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages() if c.topic == "/terrapref/grid_map"]
        latched = {
            c.topic for c in reader.connections if [q.durability for q in c.ext.offered_qos_profiles] == [QosDurability.TRANSIENT_LOCAL]
        }
        odometry = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages() if c.topic == "/terrapref/odom"]
    assert counts["/terrapref/labels"] > 30 and counts.get("/terrapref/depth") == counts["/terrapref/labels"]
    # The maps are offered as a map server offers them: Nav2 and RViz subscribe transient-local.
    assert latched == {"/tf_static"} | {topic for topic, _ in COSTMAP_TOPICS.values()}
    # The odometry's twist is the body's motion between its poses (in base_link: forward and turning).
    xy = np.array([(m.pose.pose.position.x, m.pose.pose.position.y) for m in odometry])
    stamps = np.array([m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in odometry])
    speed = np.array([m.twist.twist.linear.x for m in odometry])
    travelled = np.linalg.norm(np.diff(xy, axis=0), axis=1).sum() / (stamps[-1] - stamps[0])
    assert np.mean(speed) == pytest.approx(travelled, rel=0.05) and travelled > 0.3
    assert all(m.twist.twist.linear.y == m.twist.twist.angular.x == 0.0 for m in odometry)
    elevation = grid_map_layer(grids[-1], "elevation")
    assert np.isfinite(elevation).sum() > 100 and np.nanmax(elevation) > 0.2  # the mound, 0.4 m high, seen
