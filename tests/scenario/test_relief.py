"""The height field of a scenario's relief (SPEC 19) against closed-form answers: cosine mounds and
ridges, plateaus with ramps and ledges, entries adding up in order, seeded noise, bilinear
sampling between cell centres; and a flat scenario's world as it always was."""

from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np
import pytest

from terrapref.errors import ScenarioError
from terrapref.scenario import FORMAT, parse_scenario
from terrapref.scenario.relief import Noise
from terrapref.sim import Simulation
from terrapref.terrain import default_classes
from terrapref.vehicle.ground import drivable, start_attitude, start_pose
from terrapref.world import WorldMap, rasterise
from terrapref.world.relief import height_field, noise_height

# A 20 m x 10 m map of 0.1 m cells: cell (row r, column c) has its centre at (0.1 c + 0.05, 0.1 r + 0.05).
FLAT: dict[str, Any] = {
    "format": FORMAT,
    "name": "relief_test",
    "world": {"size_m": [20.0, 10.0], "resolution_m": 0.1, "background": "grass"},
    "terrain": [{"class": "mud", "circle": {"center": [5.0, 5.0], "radius": 1.0}}],
    "path": {"waypoints": [[1.0, 5.0], [19.0, 5.0]]},
}


def height_of(*relief: dict) -> np.ndarray:
    """The height layer (10 m / 0.1 rows, 20 m / 0.1 columns) of FLAT with ``relief``."""
    world = rasterise(parse_scenario({**copy.deepcopy(FLAT), "relief": list(relief)}, "relief_test.yaml"))
    assert world.height is not None and world.height.dtype == np.float32 and world.height.shape == (100, 200)
    return world.height


def at(z: np.ndarray, x_m: float, y_m: float) -> float:
    """The height of the cell whose centre is (x_m, y_m)."""
    return float(z[round((y_m - 0.05) / 0.1), round((x_m - 0.05) / 0.1)])


MOUND = {"mound": {"center": [5.05, 5.05], "radius": 2.0, "height_m": 1.0}}


def test_a_mound_is_its_height_at_the_centre_half_of_it_at_half_its_radius_and_nothing_beyond() -> None:
    z = height_of(MOUND)
    assert at(z, 5.05, 5.05) == 1.0
    assert at(z, 6.05, 5.05) == pytest.approx(0.5, abs=1e-6)  # 1 m: half the radius
    assert at(z, 5.05, 6.45) == pytest.approx(0.5 * (1 + np.cos(np.pi * 1.4 / 2.0)), abs=1e-6)
    assert at(z, 7.05, 5.05) == 0.0 and at(z, 5.05, 7.15) == 0.0  # at and beyond the radius
    pit = height_of({"mound": {**MOUND["mound"], "height_m": -0.4}})
    assert at(pit, 5.05, 5.05) == pytest.approx(-0.4) and at(pit, 6.05, 5.05) == pytest.approx(-0.2, abs=1e-6)


def test_a_ridge_is_its_height_on_its_polyline_and_falls_off_as_a_cosine_across_it() -> None:
    line = [[2.05, 1.05], [2.05, 8.05], [12.05, 8.05]]
    z = height_of({"ridge": {"polyline": line, "width_m": 2.0, "height_m": -0.8}})
    for x, y in [(2.05, 1.05), (2.05, 4.05), (2.05, 8.05), (7.05, 8.05), (12.05, 8.05)]:
        assert at(z, x, y) == pytest.approx(-0.8), (x, y)
    assert at(z, 2.55, 4.05) == pytest.approx(-0.4, abs=1e-6)  # a quarter of the width off the line: half the depth
    assert at(z, 7.05, 7.55) == pytest.approx(-0.4, abs=1e-6)
    assert at(z, 3.05, 4.05) == 0.0 and at(z, 7.05, 9.15) == 0.0  # half the width off the line, and beyond
    assert at(z, 13.05, 8.05) == 0.0  # beyond the end by half the width: the end is rounded


def test_a_plateau_is_raised_inside_and_ramps_down_over_its_edge() -> None:
    square = [[10.0, 2.0], [14.0, 2.0], [14.0, 8.0], [10.0, 8.0]]
    z = height_of({"plateau": {"polygon": square, "height_m": 1.5, "edge_m": 2.1}})
    assert at(z, 12.05, 5.05) == pytest.approx(1.5) and at(z, 13.95, 2.05) == pytest.approx(1.5)
    assert at(z, 15.05, 5.05) == pytest.approx(0.75, abs=1e-6)  # edge_m / 2 out: half the height
    assert at(z, 12.05, 9.05) == pytest.approx(0.75, abs=1e-6)
    assert at(z, 14.55, 5.05) == pytest.approx(1.5 * (1 - 0.55 / 2.1), abs=1e-6)  # a straight ramp
    assert at(z, 16.15, 5.05) == 0.0
    ledge = height_of({"plateau": {"polygon": square, "height_m": 0.3, "edge_m": 0.0}})
    assert at(ledge, 13.95, 5.05) == pytest.approx(0.3) and at(ledge, 14.05, 5.05) == 0.0  # a vertical step at x = 14


def test_noise_on_a_polygon_stays_inside_it_fading_in_over_a_wavelength() -> None:
    square = [[2.0, 2.0], [9.0, 2.0], [9.0, 8.0], [2.0, 8.0]]
    noise = {"amplitude_m": 0.1, "wavelength_m": 0.5, "seed": 4}
    z = height_of({"noise": {**noise, "polygon": square}}).astype(np.float64)
    everywhere = height_of({"noise": noise}).astype(np.float64)
    x, y = (np.arange(z.shape[1]) + 0.5) * 0.1, (np.arange(z.shape[0]) + 0.5) * 0.1
    inner = (x[None, :] > 2.5) & (x[None, :] < 8.5) & (y[:, None] > 2.5) & (y[:, None] < 7.5)
    outside = (x[None, :] < 2.0) | (x[None, :] > 9.0) | (y[:, None] < 2.0) | (y[:, None] > 8.0)
    np.testing.assert_allclose(z[inner], everywhere[inner], atol=1e-7)  # a wavelength in: the noise itself
    assert not z[outside].any() and np.abs(z[inner]).max() > 0.03
    edge = (np.abs(x[None, :] - 5.5) < 0.5) & (y[:, None] > 2.0) & (y[:, None] < 2.5)  # within a wavelength of the edge
    depth = (y[:, None] - 2.0) / 0.5 * np.ones_like(z)
    np.testing.assert_allclose(z[edge], (depth * everywhere)[edge], atol=1e-7)  # faded in: no step at the border


def test_the_worlds_roughness_is_the_heights_deviation_about_their_plane() -> None:
    """On a tilted plane it is 0; on the plane plus a checkerboard of +-2 cm (symmetric about each
    cell, so the plane fitted through the disc is the tilted one raised by the disc's mean), it is
    the checkerboard's standard deviation over the disc's cells (terrapref.world.raster.ROUGH_RADIUS_M: 3 cells)."""
    flat = rasterise(parse_scenario(copy.deepcopy(FLAT), "relief_test.yaml"))
    rows, cols = np.indices(flat.raster.shape)
    tilted = 0.3 * (cols + 0.5) * 0.1 + 0.1 * (rows + 0.5) * 0.1
    checker = 0.02 * np.where((rows + cols) % 2 == 0, 1.0, -1.0)
    points = np.array([[5.05, 5.05], [12.05, 4.05]])  # cells (50, 50) and (40, 120): even, so +2 cm at the centre
    plane = WorldMap(flat.raster, flat.resolution_m, flat.classes, tilted.astype(np.float32))
    assert plane.roughness_at(points) == pytest.approx([0.0, 0.0], abs=1e-5)
    dr, dc = np.indices((7, 7)) - 3
    disc = 0.02 * np.where((dr + dc) % 2 == 0, 1.0, -1.0)[dr**2 + dc**2 <= 9]
    rough = WorldMap(flat.raster, flat.resolution_m, flat.classes, (tilted + checker).astype(np.float32))
    assert rough.roughness_at(points) == pytest.approx([disc.std()] * 2, rel=1e-4)
    assert not flat.roughness_at(points).any()  # flat ground


def test_entries_add_up_in_order() -> None:
    plateau = {"plateau": {"polygon": [[3.0, 2.0], [9.0, 2.0], [9.0, 8.0], [3.0, 8.0]], "height_m": 1.5, "edge_m": 1.0}}
    ditch = {"ridge": {"polyline": [[15.05, 0.0], [15.05, 10.0]], "width_m": 2.0, "height_m": -0.5}}
    z = height_of(plateau, MOUND, ditch)
    assert at(z, 5.05, 5.05) == pytest.approx(2.5)  # the mound stands on the plateau
    assert at(z, 6.05, 5.05) == pytest.approx(2.0, abs=1e-6)
    assert at(z, 15.05, 5.05) == pytest.approx(-0.5)
    alone = [height_of(e).astype(np.float64) for e in (plateau, MOUND, ditch)]
    np.testing.assert_allclose(z, alone[0] + alone[1] + alone[2], atol=1e-6)  # each alone was rounded to float32


def test_a_part_of_the_height_field_holds_the_whole_fields_values_there() -> None:
    """What the scenario reader reads round a start: the same cells, bit for bit, as the whole field."""
    scenario = parse_scenario(
        {
            **copy.deepcopy(FLAT),
            "relief": [
                {"noise": {"amplitude_m": 0.3, "wavelength_m": 4.0, "seed": 7}},
                MOUND,
                {"plateau": {"polygon": [[12.0, 1.0], [18.0, 1.0], [15.0, 9.0]], "height_m": 0.4, "edge_m": 0.5}},
            ],
        },
        "relief_test.yaml",
    )
    whole = height_field(scenario.relief, scenario.grid_shape, scenario.resolution_m)
    for rows, cols in ((slice(0, 100), slice(0, 200)), (slice(30, 71), slice(20, 61)), (slice(0, 12), slice(150, 200))):
        part = height_field(scenario.relief, scenario.grid_shape, scenario.resolution_m, (rows, cols))
        assert np.array_equal(part, whole[rows, cols])


@pytest.mark.parametrize(("height_m", "refused"), [(2.0, True), (0.2, False)])
def test_a_start_that_would_tip_the_vehicle_is_refused(height_m: float, refused: bool) -> None:
    """A bank rising beside the start: 2 m over 1.6 m rolls the default vehicle past 25 deg (a run
    would count a tip before it moved), 0.2 m does not; the attitude read from the cells round the
    start is the simulator's, to rounding."""
    bank = {"plateau": {"polygon": [[0.0, 5.8], [20.0, 5.8], [20.0, 10.0], [0.0, 10.0]], "height_m": height_m, "edge_m": 1.6}}
    scenario = parse_scenario({**copy.deepcopy(FLAT), "relief": [bank]}, "bank.yaml")
    assert start_attitude(scenario) == pytest.approx(Simulation(scenario).reset().attitude, rel=1e-12, abs=1e-15)
    _drivable_or_refused(
        scenario,
        refused,
        "bank.yaml: start: (1, 5) stands the vehicle at roll 51.3 deg, pitch 0.0 deg, "
        "past the vehicle's limits (25 deg of roll, 30 of pitch); start it on gentler ground",
    )


def _drivable_or_refused(scenario, refused: bool, line: str) -> None:
    """``scenario`` taken as it is where it is not ``refused``, else refused in the one ``line``."""
    if not refused:
        assert drivable(scenario) is scenario
        return
    with pytest.raises(ScenarioError) as err:
        drivable(scenario)
    assert err.value.lines() == [line]


@pytest.mark.parametrize(("height_m", "refused"), [(0.5, True), (0.14, False)])
def test_a_start_astride_a_step_higher_than_the_vehicle_climbs_is_refused(height_m: float, refused: bool) -> None:
    """A ledge between the axles at the start (the front wheels on top, the rear ones below): 0.5 m
    left the vehicle stuck for a whole recording, validated as "ok" (its pitch, 26.6 deg, is
    within the limit); 0.14 m it climbs."""
    ledge = {"plateau": {"polygon": [[1.2, 0.0], [20.0, 0.0], [20.0, 10.0], [1.2, 10.0]], "height_m": height_m, "edge_m": 0.0}}
    scenario = parse_scenario({**copy.deepcopy(FLAT), "relief": [ledge]}, "ledge.yaml")
    sim = Simulation(scenario)
    sim.reset()
    for _ in range(30):  # 1 s at 1 m/s: the rear wheels reach the ledge
        sim.step((1.0, 0.0))
    assert (sim.stuck > 0) is refused
    _drivable_or_refused(
        scenario,
        refused,
        "ledge.yaml: start: (1, 5) stands the vehicle astride a step of 0.50 m (there, or begun a little to its side as "
        "an evaluation's later seeds may be), higher than it climbs (0.15 m): its rear wheels could not follow its front "
        "ones; start it off the step",
    )


@pytest.mark.parametrize(("height_m", "refused"), [(0.6, True), (0.58, False)])
def test_a_start_that_would_tip_the_vehicle_begun_as_a_later_seed_begins_is_refused(height_m: float, refused: bool) -> None:
    """A ridge along the path beside the start: 0.6 m rolls the vehicle 22.6 deg at the start but
    past 25 deg 0.25 m toward the ridge, where an evaluation's later seeds may begin; 0.58 m stays
    within the limit wherever they begin, and no seed's run begins tipped."""
    ridge = {"ridge": {"polyline": [[0.0, 6.0], [20.0, 6.0]], "width_m": 3.0, "height_m": height_m}}
    scenario = parse_scenario({**copy.deepcopy(FLAT), "relief": [ridge]}, "ridge.yaml")
    assert math.degrees(start_attitude(scenario).roll_rad) < 23.0
    if refused:
        with pytest.raises(ScenarioError) as err:
            drivable(scenario)
        (line,) = err.value.lines()
        assert line.startswith(
            "ridge.yaml: start: (1, 5) begun 0.25 m to its side, 0 deg off its heading (as an evaluation's later seeds may be)"
        )
        assert "roll 25.4 deg" in line
        return
    assert drivable(scenario, seeds=40) is scenario
    sim = Simulation(scenario)
    for seed in range(40):
        sim.reset(start_pose(scenario.start, seed))
        assert not sim.vehicle.tipped and sim.tips == 0


@pytest.mark.parametrize(
    ("entry", "problem"),
    [
        ({"mound": {"center": [12.03, 5.03], "radius": 0.02, "height_m": 1.0}}, "relief[0].mound.radius: must be at least one cell (0.1 m"),
        (
            {"ridge": {"polyline": [[12.03, 0.0], [12.03, 9.0]], "width_m": 0.05, "height_m": 1.0}},
            "relief[0].ridge.width_m: must be at least 2 cells (0.2 m",
        ),
        (
            {"plateau": {"polygon": [[12.0, 5.0], [12.03, 5.0], [12.0, 5.03]], "height_m": 1.0, "edge_m": 0.0}},
            "relief[0].plateau.polygon: is smaller than one cell of the map (0.1 m square)",
        ),
        (
            {"noise": {"amplitude_m": 0.2, "wavelength_m": 1.0, "seed": 1, "polygon": [[12.0, 5.0], [12.03, 5.0], [12.0, 5.03]]}},
            "relief[0].noise.polygon: is smaller than one cell of the map (0.1 m square)",
        ),
    ],
    ids=["mound", "ridge", "plateau", "noise"],
)
def test_relief_finer_than_the_grid_is_refused_rather_than_lost_between_the_cells(entry: dict, problem: str) -> None:
    with pytest.raises(ScenarioError) as err:
        parse_scenario({**copy.deepcopy(FLAT), "relief": [entry]}, "fine.yaml")
    assert len(err.value.lines()) == 1 and err.value.lines()[0].startswith(f"fine.yaml: {problem}")
    smallest = {"mound": ("radius", 0.1), "ridge": ("width_m", 0.2)}.get(next(iter(entry)))
    if smallest is not None:  # at the least size, the ground changes
        kind = next(iter(entry))
        z = height_of({kind: {**entry[kind], smallest[0]: smallest[1]}})
        assert z.max() > 0.0


@pytest.mark.parametrize(
    ("entry", "field"),
    [
        ({"mound": {"center": [12.0, 5.0], "radius": 1e308, "height_m": 1.0}}, "mound.radius"),
        ({"ridge": {"polyline": [[12.0, 0.0], [12.0, 9.0]], "width_m": 2e6, "height_m": 1.0}}, "ridge.width_m"),
        ({"plateau": {"polygon": [[10.0, 2.0], [14.0, 2.0], [14.0, 8.0]], "height_m": 1.0, "edge_m": 1e308}}, "plateau.edge_m"),
    ],
    ids=["mound", "ridge", "plateau"],
)
def test_relief_wider_than_it_may_lie_from_the_map_is_refused_rather_than_left_flat(entry: dict, field: str) -> None:
    with pytest.raises(ScenarioError) as err:
        parse_scenario({**copy.deepcopy(FLAT), "relief": [entry]}, "wide.yaml")
    assert err.value.lines() == [f"wide.yaml: relief[0].{field}: must be at most 1e+06 m, as far as relief may lie from the map"]
    kind, key = field.split(".")
    z = height_of({kind: {**entry[kind], key: 1e6}})  # at the widest, still read
    assert np.isfinite(z).all()


def test_noise_of_a_known_seed_has_known_values_and_is_the_same_on_every_build() -> None:
    noise = Noise(amplitude_m=1.0, wavelength_m=15.0, seed=3)
    grid = noise_height(noise, np.array([7.5, 20.0]), np.array([15.0, 3.3]))
    assert grid.shape == (2, 2) and grid.dtype == np.float64
    assert abs(grid[1, 1] - -0.2560099749419541) < 1e-12
    assert abs(noise_height(Noise(0.6, 15.0, 12345), np.array([20.0]), np.array([3.3]))[0, 0] - 0.12850726309672128) < 1e-12
    assert noise_height(noise, np.array([20.0]), np.array([3.3]))[0, 0] == grid[1, 1]  # a point does not depend on the others
    entry = {"noise": {"amplitude_m": 0.6, "wavelength_m": 4.0, "seed": 7}}
    z = height_of(entry)
    np.testing.assert_array_equal(z, height_of(entry))
    assert 0.1 < float(np.abs(z).max()) <= 0.6 and not np.array_equal(z, height_of({"noise": {**entry["noise"], "seed": 8}}))


def test_heights_are_sampled_bilinearly_between_cell_centres_and_level_beyond_the_edge() -> None:
    z = np.array([[0.0, 1.0], [2.0, 3.0]], dtype=np.float32)  # centres (0.5, 0.5) (1.5, 0.5) (0.5, 1.5) (1.5, 1.5)
    world = WorldMap(np.zeros((2, 2), np.uint8), 1.0, default_classes(), z)
    points = np.array([[0.5, 0.5], [1.5, 1.5], [1.0, 1.0], [1.25, 0.5], [0.5, 1.25], [-3.0, 0.5], [9.0, 9.0], [np.nan, 1.0]])
    np.testing.assert_allclose(world.height_at(points), [0.0, 3.0, 1.5, 0.75, 1.5, 0.0, 3.0, np.nan])
    plane = np.add.outer(0.3 * np.arange(5), 0.2 * np.arange(7)).astype(np.float32)  # z = 0.2 x + 0.3 y at centres, 1 m cells
    world = WorldMap(np.zeros((5, 7), np.uint8), 1.0, default_classes(), plane)
    xy = np.random.default_rng(0).uniform(0.5, 4.5, (3, 4, 2))
    np.testing.assert_allclose(world.height_at(xy), 0.2 * (xy[..., 0] - 0.5) + 0.3 * (xy[..., 1] - 0.5), atol=1e-6)


def test_a_flat_scenario_has_no_height_layer_and_relief_leaves_the_classes_alone() -> None:
    flat = parse_scenario(copy.deepcopy(FLAT), "flat.yaml")
    world = rasterise(flat)
    assert not flat.has_relief and world.height is None and not world.has_relief and "relief" not in flat.to_dict()
    np.testing.assert_array_equal(world.height_at(np.array([[3.0, 4.0], [50.0, -1.0]])), [0.0, 0.0])
    for empty in ([], None):
        same = rasterise(parse_scenario({**copy.deepcopy(FLAT), "relief": empty}, "flat.yaml"))
        assert same.height is None
        np.testing.assert_array_equal(same.raster, world.raster)
    hilly = rasterise(parse_scenario({**copy.deepcopy(FLAT), "relief": [MOUND]}, "hilly.yaml"))
    np.testing.assert_array_equal(hilly.raster, world.raster)


# --- relief for a course that has none (genrelief:N, teach_relief) ------------------------------


def _layout(data: dict) -> dict:
    """A scenario mapping without its name, description and relief: the layout alone."""
    return {k: v for k, v in data.items() if k not in ("name", "description", "relief")}


def test_genrelief_is_gen_with_seeded_relief_clear_of_its_zones() -> None:
    from terrapref.scenario import resolve_scenario

    gen, hilly = resolve_scenario("gen:7"), resolve_scenario("genrelief:7")
    assert hilly.name == "genrelief_7" and not gen.has_relief and "relief" not in gen.to_dict()
    assert _layout(hilly.to_dict()) == _layout(gen.to_dict())
    assert hilly.to_dict() == resolve_scenario("genrelief:7").to_dict()  # the same bits for one seed
    assert hilly.to_dict()["relief"] != resolve_scenario("genrelief:8").to_dict()["relief"]
    kinds = [next(iter(e.to_dict())) for e in hilly.relief]
    assert kinds[0] == "noise" and len(kinds) >= 6 and set(kinds[1:]) == {"mound", "ridge", "plateau", "noise"}
    assert hilly.relief[0].polygon is None and all(e.polygon is not None for e in hilly.relief[1:] if isinstance(e, Noise))  # rough patches
    features = parse_scenario({**hilly.to_dict(), "relief": hilly.to_dict()["relief"][1:]}, "features.yaml")  # no noise
    world = rasterise(features)
    s = np.arange(0.0, 240.0, 0.25)
    from terrapref.scenario.path import ReferencePath

    points = ReferencePath(hilly.waypoints).point_at(s)
    in_zones = np.any([z.shape.contains(points) for z in hilly.zones], axis=0)
    assert in_zones.sum() > 100 and not world.height_at(points[in_zones]).any()  # a zone's ground is as gen's
    assert world.height_at(points[~in_zones]).any()


def _tilt_along(scenario) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stations (S,) [m] of ``scenario``'s path every 0.1 m, and the ground's grade and side slope
    there [deg, >= 0] over the default vehicle's wheelbase and track (as evaluate's relief zones read them)."""
    from terrapref.scenario.path import ReferencePath

    world, path = rasterise(scenario), ReferencePath(scenario.waypoints)
    s = np.arange(0.0, path.length_m, 0.1)
    centre, d = path.point_at(s), path.direction_at(s)
    n = np.stack([-d[:, 1], d[:, 0]], axis=1)
    grade = np.abs(world.height_at(centre + 0.5 * d) - world.height_at(centre - 0.5 * d)) / 1.0
    side = np.abs(world.height_at(centre + 0.6 * n) - world.height_at(centre - 0.6 * n)) / 1.2
    return s, np.degrees(np.arctan(grade)), np.degrees(np.arctan(side))


def test_teach_relief_shows_each_relief_situation_on_its_own_leg() -> None:
    """teach_relief is the default table's teaching course with relief (`course --relief`): every
    terrain lesson of the flat course (each pair and lone patch once), and each relief situation
    alone on its own leg: mounds on the path whose steepest grade is the one designed, banks whose
    side slope under the path is, a ramp, and each class flat beside a bank, clear of the footprint
    on the path; a terrain situation's trail shorter only where it does not meet relief, all of it
    within the relief budget (about 7 minutes at the default driver's pace there)."""
    from dataclasses import replace

    from terrapref.demos.relief_style import ReliefStyle
    from terrapref.scenario import resolve_scenario
    from terrapref.scenario.path import ReferencePath
    from terrapref.scenario.teaching import (
        BODY_M,
        HALF_M,
        RELIEF_BUDGET_M,
        RELIEF_DEG,
        RELIEF_HALF_M,
        RELIEF_KINDS,
        ROUGH_LADDER_M,
        ROUGH_PATCH_M,
        SLOPE_GAP_M,
        START_M,
        course_length,
        designed_course,
        relief_course,
    )
    from terrapref.vehicle import VehicleConfig

    assert BODY_M == (VehicleConfig().half_width_m, VehicleConfig().wheelbase_m)  # the body the situations are built for

    classes = default_classes()
    hilly = resolve_scenario("teach_relief")
    course, items = relief_course(classes, name="teach_relief")
    assert hilly.to_dict() == parse_scenario(course.data(), "teach_relief.yaml", classes).to_dict()  # as make_courses writes it
    flat_items = designed_course(classes)[1]
    terrain = [replace(i, legs_m=None) for i in items if i.kind not in RELIEF_KINDS]
    compact = designed_course(classes, "compact")[1]  # the compact design's pairs and lone patches: each once
    # Every terrain lesson: each strip (every class on the path beside each other class and beside
    # lethal terrain) and each lane, as on the flat course; each pair and each lone patch once, as
    # in its compact design.
    assert [i for i in terrain if i.kind in ("strip", "lane")] == [i for i in flat_items if i.kind in ("strip", "lane")]
    assert [i for i in terrain if i.kind in ("pair", "lone")] == [i for i in compact if i.kind in ("pair", "lone")]
    beside = {(i.classes[1], n) for i in terrain if i.kind == "strip" for n in (i.classes[0], i.classes[2]) if n not in classes.lethal}
    assert beside == {(a, b) for a in classes.terrain_names for b in classes.terrain_names if a != b}
    for k, item in enumerate(items):  # a side that meets a relief situation keeps the flat course's trail
        meets = [k + d in range(len(items)) and items[k + d].kind in RELIEF_KINDS for d in (-1, 1)]
        assert item.legs_m == tuple(HALF_M[item.kind] if m or item.kind in RELIEF_KINDS else RELIEF_HALF_M[item.kind] for m in meets)
    assert course_length(items) == pytest.approx(hilly.path_length_m(), abs=0.01) and course_length(items) <= RELIEF_BUDGET_M
    kinds = [i.kind for i in items]
    assert kinds.count("mound") == 3 and kinds.count("bank") == 2 and kinds.count("ramp") == 1 and kinds.count("rough") == 1
    assert sorted(i.classes[0] for i in items if i.kind == "slope") == sorted(classes.terrain_names)
    s, grade, side = _tilt_along(hilly)
    path = ReferencePath(hilly.waypoints)
    world, centre = rasterise(hilly), path.point_at(s)
    rough, step = world.roughness_at(centre), np.abs(np.diff(world.height_at(centre), append=0.0))  # a step: the rise over 0.1 m
    at = START_M
    for item in items:
        mid = at + item.before_m
        leg = (s > at + 0.5) & (s < at + item.length_m - 0.5)
        if item.kind == "mound":  # the steepest grade on the path, on its flank, is the one designed
            assert grade[leg].max() == pytest.approx(item.deg, abs=0.6)
        elif item.kind in ("bank", "slope"):  # the path runs on the flank: its side slope there is the one designed
            middle = np.abs(s - mid) < 1.0
            assert side[middle].mean() == pytest.approx(item.deg, abs=0.8)
        if item.kind == "slope":  # its flat patch lies beside the footprint on the path, a gap of the slope between
            along = np.abs(s - mid) < 3.0
            normal = np.stack([-path.direction_at(s[along])[:, 1], path.direction_at(s[along])[:, 0]], axis=1)
            toward = np.sign(item.offset_m) * normal
            for lateral in (0.0, BODY_M[0], BODY_M[0] + 0.2):  # the footprint, and a map cell and a hand's wander past it
                assert (world.class_at(centre[along] + lateral * toward) == classes.background_id).all(), (item.classes, lateral)
            assert (world.class_at(centre[along] + (BODY_M[0] + SLOPE_GAP_M + 0.1) * toward) == classes.id_of(item.classes[0])).all()
        elif item.kind == "ramp":  # the seed's gentle noise (0.1 m over 15 m) tilts it by up to a degree
            assert grade[leg].max() == pytest.approx(item.deg, abs=1.0)
        elif item.kind == "rough":  # in steps from past the default style's roughness to half of it; no step too high
            length, steps = ROUGH_PATCH_M[0], len(ROUGH_LADDER_M)
            centres = mid - length / 2 + length / steps * (np.arange(steps) + 0.5)
            medians = [np.median(rough[np.abs(s - c) < 0.5 * length / steps - 0.4]) for c in centres]
            assert medians[0] > ReliefStyle().rough_m > 1.5 * medians[-1] and all(np.diff(medians) < 0), medians
            assert step[leg].max() < 0.5 * VehicleConfig().max_step_m
        at += item.length_m
    # Three mounds, the gentle and the steep among the relief situations and one between them last,
    # each alone on its leg: grades at three steepnesses with no class in view.
    assert [i.deg for i in items if i.kind == "mound"] == [RELIEF_DEG[k] for k in ("gentle mound", "steep mound", "middle mound")]
    assert items[-1].kind == "mound" and items[-1].deg == RELIEF_DEG["middle mound"]


@pytest.mark.slow  # a whole drive, course or training end to end; the default run keeps the test suite's time
def test_course_relief_gives_a_tables_teaching_course_its_relief_situations_and_relief_between(tmp_path, capsys) -> None:
    """`terrapref course --relief [SEED]`: the table's course with its relief situations (each
    class against a bank), their own relief, and the relief of the seed between the situations
    (teach_relief's way), and the command that records it with a relief style; a seed
    genrelief:SEED would refuse is refused in one line."""
    from helpers import REPO
    from terrapref.cli import main
    from terrapref.scenario import load_scenario
    from terrapref.scenario.relief_layout import relief_for
    from terrapref.scenario.teaching import RELIEF_PACE_MPS, designed_course

    small = str(REPO / "examples" / "classes" / "small.yaml")
    assert main(["course", "--classes", small, "--relief", "3", "--out", str(tmp_path / "hilly.yaml")]) == 0
    hilly = load_scenario(tmp_path / "hilly.yaml")
    assert hilly.name == "teaching_course_relief"  # named apart from the flat course `course` writes
    minutes = hilly.path_length_m() / RELIEF_PACE_MPS / 60  # timed at the pace a driver keeps on relief, not the flat 1 m/s
    printed = capsys.readouterr().out
    assert f"expected drive about {minutes:.1f} minutes at {RELIEF_PACE_MPS:g} m/s on relief" in printed
    # The command it prints records a driver with a relief style (one without drives relief as if flat).
    assert f"(record it: terrapref record {tmp_path / 'hilly.yaml'} --relief-style default --out DIR)" in printed
    flat = parse_scenario(designed_course(hilly.classes)[0].data(), "flat.yaml", hilly.classes)  # `course` without --relief
    designed = designed_course(hilly.classes, relief=True)[0]
    situations = parse_scenario(designed.data(), "situations.yaml", hilly.classes)
    labels = [z.label for z in hilly.zones]  # the terrain lessons of `course` without relief's seed, each one the flat course shows
    assert not flat.has_relief and labels == [z.label for z in situations.zones] and set(labels) <= {z.label for z in flat.zones}
    own = [e.to_dict() for e in situations.relief]
    assert hilly.to_dict()["relief"] == own + relief_for(situations, 3)
    assert len(own) == 7 + len(hilly.classes.terrain_names)  # three mounds, two banks, a ramp, a rough patch, a bank beside each class
    capsys.readouterr()
    for seed in ("-1", str(2**63)):  # the seeds genrelief:SEED takes
        assert main(["course", "--relief", seed, "--out", str(tmp_path / "bad.yaml")]) == 2
        assert (
            capsys.readouterr().err.strip() == f"error: --relief: expected a seed from 0 to 2^63 - 1, as genrelief:SEED takes, got {seed}"
        )
    assert not (tmp_path / "bad.yaml").exists()
