"""Higher-level planning (terrapref.planner.route): a global route over a prior map, priced by
the learned costmap, and ``terrapref route``."""

from __future__ import annotations

import numpy as np
import pytest
from test_offset_rule import DRIVER_LIKE, _offset_meta, _scenario, _terrain

from helpers import model_meta, one_line_error, skip_path_weights
from terrapref.camera import PinholeCamera
from terrapref.cli import main
from terrapref.features import FeatureConfig
from terrapref.groundmap.costmap import LETHAL_COST
from terrapref.interop.robot import load_waypoints
from terrapref.learning.model_file import save_model
from terrapref.learning.network import ClassifierConfig
from terrapref.planner.model import Model
from terrapref.planner.route import RouteConfig, RouteError, plan_route, route_over
from terrapref.rules.offset.fit import OffsetUtility
from terrapref.rules.offset.rule import OffsetSteering
from terrapref.scenario import load_scenario, parse_scenario
from terrapref.scenario.path import ReferencePath
from terrapref.terrain import default_classes
from terrapref.world import rasterise

CONTROL = FeatureConfig().preference.control  # the default control set: 1 m/s

NAMES = default_classes().feature_names
PATH = ReferencePath(np.array([[2.0, 10.0], [38.0, 10.0]]))


def _route(patches: list[dict], config: RouteConfig | None = None):
    """The route along PATH over ``patches``, priced as DRIVER_LIKE prices them, and its costmap."""
    stage = OffsetSteering(OffsetUtility(DRIVER_LIKE, 5.0), PinholeCamera(), _terrain((0,), NAMES), CONTROL)
    prices = stage.route_prices()
    costmap = prices.prior(rasterise(_scenario(patches)))
    return plan_route(costmap, PATH, prices.detour_price, prices.span_m, config=config), costmap


def _band(cls: str, x: tuple[float, float], y: tuple[float, float]) -> dict:
    return {"class": cls, "rectangle": {"center": [sum(x) / 2, sum(y) / 2], "size": [x[1] - x[0], y[1] - y[0]]}}


def test_a_long_dear_patch_is_gone_round_on_its_near_side_and_the_route_agrees_with_the_costmap():
    # 16 m of water across the path, 2.5 m of it to the right and 4 m to the left: 0.068 per m^2
    # per metre for about 3 m off the path is far less than 1.9 per metre of water.
    route, costmap = _route([_band("water", (12.0, 28.0), (7.5, 14.0))])
    offsets = route.waypoints[:, 1] - 10.0
    assert offsets.min() < -3.0 and offsets.max() < 0.3  # round the right, the near side
    assert 3.0 < route.max_offset_m < 4.5
    cells = [costmap.at(x, y) for x, y in route.waypoints]
    assert max(cells) == 0  # the route keeps to the background the costmap prices at nothing ...
    assert route.cost < route.along_path_cost  # ... and costs less than the path through the water
    np.testing.assert_allclose(route.waypoints[[0, -1]], PATH.waypoints[[0, -1]])


def test_a_short_cheap_patch_is_crossed():
    route, _ = _route([_band("mud", (17.0, 23.0), (7.5, 14.0))])  # 6 m of mud: cheaper than going 3 m out
    assert route.max_offset_m < 1.0


def test_lethal_terrain_is_kept_clear_by_half_the_width_and_the_margin_or_refused():
    config = RouteConfig(half_width_m=0.6, lethal_margin_m=0.3)
    route, costmap = _route([_band("non_traversable", (18.0, 21.0), (8.5, 11.5))], config)
    assert LETHAL_COST not in [costmap.at(x, y) for x, y in route.waypoints]
    dense = ReferencePath(route.waypoints).resampled(0.05)[0]
    gap = np.hypot(np.maximum(np.abs(dense[:, 0] - 19.5) - 1.5, 0), np.maximum(np.abs(dense[:, 1] - 10.0) - 1.5, 0))
    assert gap.min() > 0.6  # 0.9 m kept from the block, less a search cell and the cut of a bend's chord
    with pytest.raises(RouteError, match="cuts the path's start from its end"):
        _route([_band("non_traversable", (18.0, 21.0), (0.0, 20.0))])


def test_terrapref_route_writes_a_scenario_that_follows_the_route(tmp_path, capsys):
    config = ClassifierConfig(hidden=8, skip=True)
    model = save_model(tmp_path / "m.safetensors", config, skip_path_weights(config), _offset_meta(DRIVER_LIKE))
    out = tmp_path / "route.yaml"
    assert main(["route", "fig7_rock_vs_non_traversable_left", "--model", str(model), "--out", str(out)]) == 0
    assert "meets lethal terrain" in capsys.readouterr().out  # the path itself clips the trees
    routed = load_scenario(out)
    world = rasterise(routed)
    row, col, inside = world.cells_of(routed.waypoints)
    assert inside.all() and not np.isin(world.raster[row, col], list(routed.classes.lethal_ids)).any()
    np.testing.assert_array_equal(load_waypoints(out, "test"), routed.waypoints)  # ros1 --path-file reads it
    assert (tmp_path / "route.png").stat().st_size > 10_000
    plain = save_model(tmp_path / "c.safetensors", config, skip_path_weights(config), model_meta())
    assert main(["route", "fig7_rock_vs_non_traversable_left", "--model", str(plain), "--out", str(tmp_path / "c.yaml")]) == 2
    one_line_error(capsys, "c.safetensors", "learned no prices")
    assert not (tmp_path / "c.yaml").exists()


def test_a_route_keeps_off_the_maps_edge_and_a_path_that_ends_where_it_starts_is_refused():
    edge = ReferencePath(np.array([[2.0, 1.5], [38.0, 1.5]]))  # 1.5 m from the map's southern edge, beside a strip of water
    stage = OffsetSteering(OffsetUtility(DRIVER_LIKE, 5.0), PinholeCamera(), _terrain((0,), NAMES), CONTROL)
    prices = stage.route_prices()
    costmap = prices.prior(rasterise(_scenario([_band("water", (15.0, 25.0), (1.0, 4.0))])))
    route = plan_route(costmap, edge, prices.detour_price, prices.span_m)
    assert ReferencePath(route.waypoints).resampled(0.05)[0][:, 1].min() > 0.8  # never within 0.9 m (less a cell) of the edge
    with pytest.raises(RouteError, match="ends in the search cell it starts in"):
        plan_route(costmap, ReferencePath(np.array([[10.0, 10.0], [10.1, 10.1]])), prices.detour_price, prices.span_m)


@pytest.mark.parametrize("resolution_m", [0.25, 0.7, 1.0, 2.0])
def test_coarse_search_cells_keep_the_clearance_from_lethal_terrain(resolution_m):
    # Trees across the path with a gap 1 m wide at y 12-13: narrower than the vehicle and its
    # clearance (2 x 0.9 m), refused at every cell size; a gap of 3.2 m (y 12-15.2) is taken, every
    # cell centre on the way at least 0.9 m from the trees.
    config = RouteConfig(resolution_m=resolution_m)
    narrow = [_band("non_traversable", (19.0, 21.0), (0.0, 12.0)), _band("non_traversable", (19.0, 21.0), (13.0, 20.0))]
    with pytest.raises(RouteError, match="cuts the path's start from its end"):
        _route(narrow, config)
    route, costmap = _route(
        [_band("non_traversable", (19.0, 21.0), (0.0, 12.0)), _band("non_traversable", (19.0, 21.0), (15.2, 20.0))], config
    )
    grid = route.cell_m
    centres = (np.floor((route.waypoints - costmap.origin) / grid) + 0.5) * grid + costmap.origin  # the cells the route passes
    across = np.maximum(np.abs(centres[:, 0] - 20.0) - 1.0, 0)
    above = np.hypot(across, np.maximum(15.2 - centres[:, 1], 0))  # to the trees at y 15.2-20 ...
    below = np.hypot(across, np.maximum(centres[:, 1] - 12.0, 0))  # ... and at y 0-12
    assert min(above.min(), below.min()) >= 0.9 - 1e-9


def test_no_diagonal_step_slips_between_lethal_cells_that_meet_at_a_corner():
    # A wall of 1 m trees, each touching the next at a corner only, across the path.
    wall = [_band("non_traversable", (15.0 + i, 16.0 + i), (i, i + 1.0)) for i in range(20)]
    for resolution_m in (0.25, 1.0, 2.0):
        with pytest.raises(RouteError, match="cuts the path's start from its end"):
            _route(wall, RouteConfig(resolution_m=resolution_m))


@pytest.mark.parametrize("height_m", [0.14, 0.16])
def test_a_ledge_the_vehicle_cannot_climb_is_gone_round_and_one_it_can_is_crossed(tmp_path, height_m):
    # A sill 0.5 m thick across the path (x 20-20.5, y 0-14: the path at y 10, the way round from
    # y 14 up); the default vehicle climbs 0.15 m. The prior map's heights are known, as its classes are.
    route = route_over(_sill(14.0, height_m), _driver_like(tmp_path))
    if height_m < 0.15:
        assert route.max_offset_m < 0.3  # straight over it
        return
    dense = ReferencePath(route.waypoints).resampled(0.05)[0]
    at_ledge = dense[np.abs(dense[:, 0] - 20.25) < 0.3]
    assert len(at_ledge) and (at_ledge[:, 1] >= 14.0 + 0.9 - 0.25).all()  # round its end, clear by the margin (less a cell)
    assert not np.isfinite(route.along_path_cost)  # the path itself meets the ledge


def test_a_ledge_across_the_whole_map_is_named_as_relief_not_as_lethal_terrain(tmp_path):
    """A course without lethal terrain whose ledge cuts the way: the error said only "lethal
    terrain", which the course has none of."""
    with pytest.raises(RouteError, match=r"ground past the vehicle's limits: a slope or a step it cannot cross\) cuts the path's start"):
        route_over(_sill(20.0, 0.4), _driver_like(tmp_path))


def _sill(y_top: float, height_m: float):
    """A 40 x 20 m course along y = 10 m with a sill 0.5 m thick across it (x 20-20.5, y 0 to ``y_top``), a vertical step."""
    sill = [[20.0, 0.0], [20.5, 0.0], [20.5, y_top], [20.0, y_top]]
    return parse_scenario(
        {
            "format": "terrapref-scenario/1",
            "name": "ledge",
            "world": {"size_m": [40.0, 20.0], "resolution_m": 0.05, "background": "grass"},
            "terrain": [],
            "path": {"waypoints": [[2.0, 10.0], [38.0, 10.0]]},
            "relief": [{"plateau": {"polygon": sill, "height_m": height_m, "edge_m": 0.0}}],
        }
    )


def _driver_like(tmp_path):
    """A model whose offset rule prices the classes as the default synthetic driver does."""
    config = ClassifierConfig(hidden=8, skip=True)
    return Model.load(save_model(tmp_path / "m.safetensors", config, skip_path_weights(config), _offset_meta(DRIVER_LIKE)))
