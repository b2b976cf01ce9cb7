"""The ground map's height layer (terrapref.groundmap.height) against closed-form answers: the
heights of a ramp seen through the depth camera, its slope equal to its grade and no roughness;
a step one centimetre over the vehicle's limit is lethal and one under it is not; unseen ground
is unknown, never lethal."""

from __future__ import annotations

import copy
import math
from dataclasses import replace

import numpy as np
import pytest
from test_offset_rule import _terrain

from terrapref.camera import PinholeCamera, SegmentationView
from terrapref.camera.render import SegmentationRenderer
from terrapref.groundmap.height import DepthImage, GeometryLimits, Heights, HeightSettings, trusted_elevation
from terrapref.groundmap.map import GroundMap
from terrapref.rules.speed.model import CHORD_M, CHORD_WEIGHTS, SpeedModel, body_grade
from terrapref.rules.speed.rule import LearnedSpeed, SpeedConfig, SpeedRule
from terrapref.scenario import FORMAT, parse_scenario
from terrapref.vehicle import Pose, Vehicle, VehicleConfig
from terrapref.world import rasterise

# A ramp of grade 0.2 from x = 10 m to 40 m, level across (y).
RAMP = {
    "format": FORMAT,
    "name": "height_test",
    "world": {"size_m": [60.0, 30.0], "resolution_m": 0.05, "background": "grass"},
    "terrain": [],
    "path": {"waypoints": [[1.0, 15.0], [59.0, 15.0]]},
    "relief": [{"plateau": {"polygon": [[40, -10], [80, -10], [80, 40], [40, 40]], "height_m": 6.0, "edge_m": 30.0}}],
}


def _seen_ramp() -> tuple[GroundMap, object]:
    """A ground map that gathered three frames of the ramp, from 15, 16 and 17 m up it, through a
    depth camera it knows to be exact (1 cm of error, at any range and attitude)."""
    world = rasterise(parse_scenario(copy.deepcopy(RAMP), "height_test.yaml"))
    camera = PinholeCamera()
    renderer, gmap = SegmentationRenderer(camera, world), GroundMap(camera, _terrain(()))
    gmap.height_settings = HeightSettings(depth_error_per_m2=0.0, attitude_error_deg=0.0)
    for x in (15.0, 16.0, 17.0):
        vehicle = Vehicle(Pose(x, 15.0, 0.0), ground=world)
        ids, depth = renderer.render_with_depth(vehicle.pose, vehicle.attitude)
        gmap.update(SegmentationView.of(ids), vehicle.pose, DepthImage(depth, *renderer.placement(vehicle.pose, vehicle.attitude)))
    return gmap, world


def test_the_height_layer_holds_the_ramps_heights_and_its_slope_is_the_grade() -> None:
    gmap, world = _seen_ramp()
    elevation, returns = gmap.layer("elevation"), gmap.layer("returns")
    seen = returns > 0
    assert seen.sum() > 2000 and np.isnan(elevation[~seen]).all()
    rows, cols = np.nonzero(seen)
    res = gmap.settings.map_resolution_m
    centres = np.stack([gmap.origin[0] + (cols + 0.5) * res, gmap.origin[1] + (rows + 0.5) * res], axis=1)
    on_ramp = (centres[:, 0] > 11.0) & (centres[:, 0] < 39.0)
    truth = world.height_at(centres[on_ramp])
    assert np.abs(elevation[rows[on_ramp], cols[on_ramp]] - truth).max() < 0.02  # a return anywhere in its 0.1 m cell
    ahead = np.array([[x, y] for x in np.arange(19.0, 24.0, 0.5) for y in (14.0, 15.0, 16.0)])
    geometry = gmap.geometry_at(ahead)
    assert np.degrees(geometry[:, 0]) == pytest.approx(np.full(len(ahead), math.degrees(math.atan(0.2))), abs=1.0)
    rough = geometry[:, 1]  # read by the frames within 5 m of the camera: a plane, no roughness
    assert np.isfinite(rough[ahead[:, 0] <= 21.0]).all() and (rough[np.isfinite(rough)] < 0.01).all()
    step = geometry[:, 2]  # across a cell's neighbours: the grade's rise over two cells, where the frames show the gradients round it
    # Differences between the mean returns of neighbouring cells, each referred to a cell's run (0.1 m).
    known = step[np.isfinite(step)]
    assert len(known) >= 25 and np.median(known) == pytest.approx(0.04, abs=0.001) and (known < 0.046).all()
    assert not GeometryLimits.of(VehicleConfig()).lethal(geometry).any()


def test_rough_ground_reads_as_rough_as_it_is_though_each_frame_is_placed_a_decimetre_off() -> None:
    """A rough patch (short noise, 0.3 m across) driven up to in frames whose poses err by 0.1 m
    each (as a robot's localisation does from frame to frame): the heights fused over the frames
    are blurred into smoother ground than there is, but each frame alone is not moved against
    itself, so the roughness the frames read is the patch's, within a fifth, on the ground the
    frames saw within their range; smooth ground beside it reads smooth."""
    scenario = copy.deepcopy(RAMP)
    patch = [[18.0, 11.0], [26.0, 11.0], [26.0, 19.0], [18.0, 19.0]]
    scenario["relief"] = [{"noise": {"amplitude_m": 0.06, "wavelength_m": 0.3, "seed": 3, "polygon": patch}}]
    world = rasterise(parse_scenario(scenario, "height_test.yaml"))
    camera = PinholeCamera()
    renderer, gmap = SegmentationRenderer(camera, world), GroundMap(camera, _terrain(()))
    gmap.height_settings = HeightSettings(depth_error_per_m2=0.0, attitude_error_deg=0.0)
    rng = np.random.default_rng(0)
    for x in np.arange(12.0, 19.0, 0.2):
        vehicle = Vehicle(Pose(x, 15.0, 0.0), ground=world)
        ids, depth = renderer.render_with_depth(vehicle.pose, vehicle.attitude)
        dx, dy = rng.normal(0.0, 0.1, 2)
        believed = Pose(x + dx, 15.0 + dy, 0.0)
        gmap.update(SegmentationView.of(ids), believed, DepthImage(depth, *renderer.placement(believed, vehicle.attitude)))
    on_patch = np.array([[x, y] for x in np.arange(19.0, 22.0, 0.25) for y in np.arange(13.5, 16.6, 0.25)])
    truth, read = world.roughness_at(on_patch), gmap.roughness_at(on_patch)
    assert np.median(truth) > 0.01 and np.isfinite(read).all()
    assert np.median(read) == pytest.approx(np.median(truth), rel=0.2)
    smooth = gmap.roughness_at(np.array([[15.0, y] for y in np.arange(13.5, 16.6, 0.25)]) + [2.5, 0.0])
    assert np.isfinite(smooth).all() and (smooth < 0.003).all()


def test_the_sums_over_each_cells_disc_are_those_of_the_differences_read_as_the_map_moves() -> None:
    """The sums a cell's slope is read from (its disc's differences as last read), kept up to date
    frame by frame and moved with the map, equal the sums worked out afresh from the differences
    read: over a drive up the ramp and back that re-centres a small map each way."""
    from terrapref.groundmap import height_compiled as kernels
    from terrapref.groundmap.settings import MapSettings

    world = rasterise(parse_scenario(copy.deepcopy(RAMP), "height_test.yaml"))
    camera = PinholeCamera()
    settings = MapSettings(map_half_size_m=5.0, sample_range_m=3.5, sample_half_width_m=3.0)
    renderer, gmap = SegmentationRenderer(camera, world), GroundMap(camera, _terrain(()), settings)
    reach, moves, origin = 3, 0, None
    drive = [(x, 15.0 + 2.0 * math.sin(x), 0.3 * math.cos(x)) for x in np.arange(12.0, 26.0, 0.5)]
    drive += [(x, 15.0 - 2.0 * math.sin(x), math.pi) for x in np.arange(26.0, 14.0, -0.5)]
    for pose in drive:
        vehicle = Vehicle(Pose(*pose), ground=world)
        ids, depth = renderer.render_with_depth(vehicle.pose, vehicle.attitude)
        gmap.update(SegmentationView.of(ids), vehicle.pose, DepthImage(depth, *renderer.placement(vehicle.pose, vehicle.attitude)))
        moves += origin is not None and not np.array_equal(origin, gmap.origin)
        origin = gmap.origin.copy()
        checked = tuple(gmap.layer(name) for name in ("checked_dx", "checked_dx_run", "checked_dy", "checked_dy_run"))
        afresh = np.empty_like(gmap.layer("disc"))
        kernels.disc_sums(checked, reach, np.arange(afresh.shape[0] * afresh.shape[1]), afresh)
        np.testing.assert_allclose(gmap.layer("disc"), afresh, rtol=0, atol=1e-5)  # float32 sums, moved as they are
    assert moves >= 4 and (gmap.layer("disc")[..., kernels.DISC_KNOWN_X] >= 3).sum() > 500


def test_the_gradient_and_the_bodys_grade_on_the_ramp_are_its_grade_heading_along_it() -> None:
    """The ramp rises 0.2 a metre along x: the gradient there is (0.2, 0); a body heading up it is
    pitched atan(0.2) up, heading down it as much down, heading across it not at all; and the speed
    rule, which sheds 0.03 m/s a degree up and 0.02 down, slows by as much there."""
    gmap, _ = _seen_ramp()
    ahead = np.array([[x, y] for x in np.arange(19.0, 24.0, 0.5) for y in (14.0, 15.0, 16.0)])
    np.testing.assert_allclose(gmap.gradient_at(ahead), np.tile([0.2, 0.0], (len(ahead), 1)), atol=0.02)
    assert np.isnan(gmap.gradient_at(np.array([[2.0, 15.0], [np.nan, 15.0]]))).all()  # never seen; not a point
    grade = math.degrees(math.atan(0.2))
    centre, n = np.array([[21.0, 15.0]] * 3), np.array([0.0, math.pi, math.pi / 2])
    np.testing.assert_allclose(body_grade(gmap.gradient_at, centre, n), [grade, -grade, 0.0], atol=1.0)
    assert np.isnan(body_grade(gmap.gradient_at, np.array([[2.0, 15.0]]), np.zeros(1))).all()
    # The map's own compiled pass reads the same grades (the planner's; the fit's reads body_grade).
    anywhere = np.array([[x, y] for x in np.arange(1.0, 30.0, 0.7) for y in (12.0, 15.0, 18.0)])
    turns = np.linspace(-math.pi, math.pi, len(anywhere))
    np.testing.assert_allclose(
        gmap.body_grades(anywhere, turns, (CHORD_M, CHORD_WEIGHTS)), body_grade(gmap.gradient_at, anywhere, turns), atol=1e-9
    )
    model = SpeedModel((1.0,) * 5, 1.5, None, None, None, (0,), up_mps_per_deg=0.03, down_mps_per_deg=0.02)
    runner = LearnedSpeed(SpeedRule(SpeedConfig(), model))
    assert runner.speed(gmap, (21.0, 15.0, 0.0), 0.0, 1.0) == pytest.approx(1.0 - 0.03 * grade, abs=0.03)
    assert runner.speed(gmap, (23.0, 15.0, math.pi), 0.0, 1.0) == pytest.approx(1.0 - 0.02 * grade, abs=0.02)
    flat = LearnedSpeed(SpeedRule(SpeedConfig(), replace(model, up_mps_per_deg=None, down_mps_per_deg=None)))
    assert flat.speed(gmap, (21.0, 15.0, 0.0), 0.0, 1.0) == 1.0


def test_a_cell_counts_once_enough_returns_agree() -> None:
    """A ledge of 0.5 m seen through returns that disagree by 0.2 m (a far, noisy return each)
    is not yet trusted; with agreeing returns it is; with one return a cell it is not yet."""
    elevation = np.zeros((20, 20), dtype=np.float32)
    elevation[:, 10:] = 0.5
    returns = np.full(elevation.shape, 3, dtype=np.uint32)
    noisy = Heights(elevation, returns, np.full(elevation.shape, 2 * 0.2**2, dtype=np.float32))  # std 0.2 m, error 0.115 m
    agreeing = Heights(elevation, returns, np.full(elevation.shape, 2 * 0.01**2, dtype=np.float32))  # error 0.006 m
    assert np.isnan(trusted_elevation(noisy, HeightSettings())).all()
    np.testing.assert_array_equal(trusted_elevation(agreeing, HeightSettings()), elevation)
    single = Heights(elevation, np.ones(elevation.shape, dtype=np.uint32), np.zeros(elevation.shape, dtype=np.float32))
    assert np.isnan(trusted_elevation(single, HeightSettings())).all()


@pytest.mark.parametrize(("height_m", "lethal"), [(0.14, False), (0.16, True)])
def test_a_step_one_centimetre_over_the_limit_is_lethal_and_one_under_is_not(height_m: float, lethal: bool) -> None:
    elevation = np.zeros((20, 20), dtype=np.float32)
    elevation[:, 10:] = height_m  # a ledge between columns 9 and 10 of 0.1 m cells
    limits = GeometryLimits.of(VehicleConfig())
    assert limits.max_step_m == 0.15 and limits.max_slope_rad == pytest.approx(math.radians(25.0))
    # The ground as the frames' differences between neighbours give it, which the ground map blocks by:
    # at the ledge (columns 9 and 10) and away from it (3 and 16).
    shaped = _shape_geometry(elevation, np.array([10, 10, 10, 10]), np.array([9, 10, 3, 16]))
    assert shaped[:2, 2] == pytest.approx([height_m, height_m], abs=1e-6)
    assert (shaped[:2, 0] < limits.max_slope_rad).all()  # the slope over the ledge is not what decides
    assert limits.lethal(shaped).tolist() == [lethal, lethal, False, False] and (shaped[2:, 2] == 0).all()


def _shape_geometry(elevation: np.ndarray, rows: np.ndarray, cols: np.ndarray, res: float = 0.1, run_m: float = 0.1) -> np.ndarray:
    """Slope, NaN and step (terrapref.groundmap.height_compiled.shape_geometry) of the cells (``rows``,
    ``cols``) of ground of heights ``elevation`` (NaN: never seen) on 0.1 m cells, as the differences
    between its neighbours, each known to 1 mm (weighing 1 / 0.001^2) where both are seen, give them,
    each read over a run of ``run_m`` (the distance between the two cells' mean returns)."""
    from terrapref.groundmap import height_compiled as kernels

    dx, dy = np.full_like(elevation, np.nan), np.full_like(elevation, np.nan)
    dx[:, :-1], dy[:-1, :] = np.diff(elevation, axis=1), np.diff(elevation, axis=0)
    known_x, known_y = (np.where(np.isnan(d), 0.0, 1e6).astype(np.float32) for d in (dx, dy))
    run = np.full(elevation.shape, run_m, dtype=np.float32)
    disc = np.empty((*elevation.shape, kernels.DISC_SUMS), np.float32)  # as the map keeps its sums
    kernels.disc_sums((dx, run, dy, run), 3, np.arange(elevation.size), disc)  # every difference read
    shape = np.empty((*elevation.shape, kernels.SHAPE_VALUES), np.float32)  # as the map's shape layer holds them
    for first, values in ((kernels.SHAPE_X, (dx, run, known_x)), (kernels.SHAPE_Y, (dy, run, known_y))):
        for k, value in zip((kernels.RISE, kernels.RUN, kernels.WEIGHT), values, strict=True):
            shape[..., first + k] = value
    out = np.empty((len(rows), 3))
    kernels.shape_geometry(shape, (1.0 / 0.03**2, res), disc, rows, cols, out)
    return out


@pytest.mark.parametrize("run_m", [0.05, 0.2])
def test_a_slope_read_between_returns_far_apart_or_close_is_not_a_step_and_a_ledge_still_is(run_m: float) -> None:
    """Where a frame's returns bunch at one edge of their cells (the far side of a mound, seen at a
    graze), the rise between two cells' mean returns is read over up to twice a cell, or a fraction of
    one. A plane rising 0.4 a metre (21.8 deg, under the 25 deg limit) then reads its height range
    over a cell and its neighbours as 0.08 m, as over cells' centres; a ledge of 0.16 m is still
    past the vehicle's step and one of 0.14 m is not, however far apart the returns across it."""
    x = np.arange(20) * 0.1
    limits = GeometryLimits.of(VehicleConfig())
    plane = np.tile((0.4 * x).astype(np.float32), (20, 1))
    rise = 0.4 * run_m  # each difference, read between returns run_m apart
    shaped = _shape_geometry((plane / 0.1 * run_m).astype(np.float32), np.array([10, 5]), np.array([10, 14]), run_m=run_m)
    assert rise == pytest.approx(float(np.diff(plane / 0.1 * run_m, axis=1)[0, 0]), abs=1e-6)
    assert shaped[:, 2] == pytest.approx([0.08, 0.08], abs=1e-5) and not limits.lethal(shaped).any()
    for height_m, lethal in ((0.16, True), (0.14, False)):
        ledge = np.zeros((20, 20), dtype=np.float32)
        ledge[:, 10:] = height_m
        shaped = _shape_geometry(ledge, np.array([10, 10]), np.array([9, 10]), run_m=run_m)
        assert shaped[:, 2] == pytest.approx([height_m, height_m], abs=1e-6)
        assert (shaped[:, 2] > limits.max_step_m).tolist() == [lethal, lethal]


def test_unseen_ground_has_no_geometry_and_is_not_lethal() -> None:
    elevation = np.full((20, 20), np.nan, dtype=np.float32)
    elevation[5, 5] = 0.0  # one cell: no plane, no step
    geometry = _shape_geometry(elevation, np.array([5, 15, 0]), np.array([5, 15, 3]))
    assert np.isnan(geometry).all() and not GeometryLimits.of(VehicleConfig()).lethal(geometry).any()
    elevation[5, 6] = 0.5  # two: a step between them, still too few differences for a slope
    pair = _shape_geometry(elevation, np.array([5]), np.array([5]))
    assert np.isnan(pair[0, :2]).all() and pair[0, 2] == pytest.approx(0.5)


def test_a_near_return_outweighs_a_far_one_by_the_inverse_of_their_variances() -> None:
    """Returns seen from a camera 0.8 m up, each weighing 1 / (0.01^2 + (0.003 d^2)^2 + (r tan 1 deg)^2),
    d its depth and r its distance across the ground from the camera: a cell's height is their
    weighted mean; two agreeing returns 10 m off (each 0.17 m uncertain) are not trusted at 3 cm,
    and two 2 m off (0.037 m each) are."""
    from terrapref.groundmap import height_compiled as kernels

    settings = HeightSettings()
    n, res = 40, 0.1
    layers = Heights(
        np.full((n, n), np.nan, np.float32), np.zeros((n, n), np.uint32), np.zeros((n, n), np.float32), np.zeros((n, n), np.float32)
    )
    slot, sums = np.full(n * n, -1, np.int32), np.empty((1, kernels.FRAME_SUMS))
    shape = np.zeros((n, n, kernels.SHAPE_VALUES), np.float32)

    def vote(x: float, y: float, z: float, across_m: float) -> None:
        """One frame of one return at (x, y, z) seen from ``across_m`` behind it, 0.8 m up (a camera
        whose optical axis points at it: the return's depth is its distance)."""
        centre = np.array([x - across_m, y, 0.8])
        offset = np.array([x, y, z]) - centre
        depth = np.float64(np.linalg.norm(offset))
        votes = (np.zeros(1, np.uint8), np.zeros(1, np.uint8), 0, np.empty(1, np.int64), np.empty(1, np.int64))  # as a map's
        pixels = (np.zeros(1, np.int64), np.zeros(1, np.int64), (offset / depth)[None, :])
        image = np.full((1, 1), depth, np.float32)
        kernels.depth_frame(
            image,
            pixels,
            np.eye(3),
            centre,
            (0.0, 0.0, 1.0 / res),
            30.0,
            settings.errors,
            votes,
            tuple(layers),
            shape,
            (slot, sums),
            (np.zeros((n, n), np.float32), np.zeros((n, n), np.float32), 3, settings.rough_range_m),
        )

    def weight(across_m: float, z: float) -> float:
        depth_m = math.hypot(across_m, 0.8 - z)
        return 1.0 / (0.01**2 + (0.003 * depth_m**2) ** 2 + (across_m * math.tan(math.radians(1.0))) ** 2)

    vote(2.05, 2.05, 0.0, 2.0)
    vote(2.05, 2.05, 0.3, 10.0)
    near, far = weight(2.0, 0.0), weight(10.0, 0.3)
    assert layers.elevation[20, 20] == pytest.approx(0.3 * far / (near + far), rel=1e-5)
    assert layers.weight[20, 20] == pytest.approx(near + far, rel=1e-5)
    for _ in range(2):
        vote(1.05, 1.05, 0.2, 10.0)  # far: 1 / W = 0.015 m^2 > 0.03^2
        vote(3.05, 3.05, 0.2, 2.0)  # near: 1 / W = 0.00066 m^2 <= 0.03^2
    trusted = trusted_elevation(layers, settings)
    assert np.isnan(trusted[10, 10]) and trusted[30, 30] == pytest.approx(0.2)
    assert 1.0 / (2 * weight(10.0, 0.2)) > settings.max_error_m**2 >= 1.0 / (2 * weight(2.0, 0.2))


@pytest.mark.parametrize(("height_m", "lethal"), [(0.3, True), (0.1, False)])
def test_a_ledge_seen_through_the_depth_camera_is_blocked_twice_the_step_high_and_not_two_thirds_of_it(height_m, lethal) -> None:
    """A ledge across the way at x = 20 m, seen in four frames from 15-16.5 m through a depth
    camera the map knows to be exact: its cells are blocked when it is 0.3 m high (the vehicle
    climbs 0.15 m) and not when it is 0.1 m. Through the camera a ledge's height is spread over
    two or three 0.1 m cells (its edge lies anywhere in a cell, and the world's heights are
    bilinear between its 0.05 m cells), so a ledge within a centimetre of the limit is not told
    from one under it there: that is told above, from the differences between cells."""
    data = copy.deepcopy(RAMP)
    data["relief"] = [{"plateau": {"polygon": [[20, -10], [80, -10], [80, 40], [20, 40]], "height_m": height_m, "edge_m": 0.0}}]
    world = rasterise(parse_scenario(data, "ledge_test.yaml"))
    camera = PinholeCamera()
    renderer, gmap = SegmentationRenderer(camera, world), GroundMap(camera, _terrain((1,)))
    gmap.height_settings = HeightSettings(depth_error_per_m2=0.0, attitude_error_deg=0.0)
    gmap.limits = GeometryLimits.of(VehicleConfig())
    for x in (15.0, 15.5, 16.0, 16.5):
        vehicle = Vehicle(Pose(x, 15.0, 0.0), ground=world)
        ids, depth = renderer.render_with_depth(vehicle.pose, vehicle.attitude)
        gmap.update(SegmentationView.of(ids), vehicle.pose, DepthImage(depth, *renderer.placement(vehicle.pose, vehicle.attitude)))
    rows, cols = np.nonzero(gmap.layer("blocked"))
    res = gmap.settings.map_resolution_m
    x, y = gmap.origin[0] + (cols + 0.5) * res, gmap.origin[1] + (rows + 0.5) * res
    if lethal:  # cells along the ledge ahead, within the 0.3 m its slope is read over, and nothing else
        assert ((np.abs(y - 15.0) < 2.0) & (np.abs(x - 20.0) < 0.4)).sum() >= 10 and (np.abs(x - 20.0) < 0.4).all()
    else:
        assert len(x) == 0


def test_the_ground_under_a_body_beside_a_path_up_the_ramp_tilts_it_by_the_grade_along_and_not_across() -> None:
    """The offset rule's relief (terrapref.groundmap.map.GroundMap.beside_attitudes): a body heading
    up the ramp at any offset is pitched by its grade, atan(0.2), and not rolled; heading across
    it, rolled by as much and not pitched; where the map saw nothing, both are unknown. Its relief
    columns then count every station read past each band below the grade, and none above it."""
    from terrapref.rules.offset.features import RELIEF_BANDS_DEG, OffsetFeatures
    from terrapref.rules.offset.geometry import OffsetGeometry
    from terrapref.scenario.path import ReferencePath

    gmap, _ = _seen_ramp()
    grade = math.degrees(math.atan(0.2))
    offsets = np.array([-1.0, 0.0, 1.0])
    centre = np.array([[x, 15.0] for x in np.arange(19.0, 24.0, 0.5)])
    up = gmap.beside_attitudes(centre, np.tile([0.0, 1.0], (len(centre), 1)), offsets)  # heading +x: left is +y
    np.testing.assert_allclose(up[..., 1], grade, atol=1.0)
    np.testing.assert_allclose(up[..., 0], 0.0, atol=1.0)
    across = gmap.beside_attitudes(np.array([[21.0, 15.0]]), np.array([[-1.0, 0.0]]), offsets)  # heading +y: left is -x
    np.testing.assert_allclose(across[..., 0], grade, atol=1.0)
    np.testing.assert_allclose(across[..., 1], 0.0, atol=1.0)
    assert np.isnan(gmap.beside_attitudes(np.array([[2.0, 15.0]]), np.array([[0.0, 1.0]]), offsets)).all()
    # The offset features of a path up the ramp, read from 20 m: every offset over the ramp's grade.
    geometry = OffsetGeometry(max_offset_m=1.0, stations_m=(0.0, 2.0))
    features = OffsetFeatures(geometry, 0)
    view = features(gmap, ReferencePath(np.array([[1.0, 15.0], [59.0, 15.0]])), 19.0, relief=True)
    bands = len(RELIEF_BANDS_DEG)
    metres = len(geometry.stations) * geometry.station_step_m
    past = np.array(RELIEF_BANDS_DEG) < grade
    assert view.near_m == 0.0  # steep ground on the path from the first station: a patch on the path
    np.testing.assert_array_equal(view.relief[:, :bands], 0.0)  # not rolled
    np.testing.assert_array_equal(view.relief[:, bands:], np.where(past, metres, 0.0)[None, :].repeat(len(geometry.offsets), 0))
    flat = features(gmap, ReferencePath(np.array([[1.0, 15.0], [59.0, 15.0]])), 19.0)
    assert flat.relief is None and flat.near_m == math.inf  # without relief: the classes alone, as on flat ground


def test_ground_past_no_band_the_utility_prices_is_no_patch_on_the_path() -> None:
    """A fitted offset utility reads as a patch on the path only ground past the first band it
    prices (terrapref.rules.offset.rule.steep_from): the ramp's grade, atan(0.2) = 11.3 deg, is one
    for a utility that prices grades from 10 deg and none for one that prices them from 12 deg or
    prices side slopes alone; there, with nothing else on the path, the detour keeps its price."""
    from test_offset_rule import DRIVER_LIKE

    from terrapref.rules.offset.features import FIRST_BAND, RELIEF_BANDS_DEG, OffsetFeatures
    from terrapref.rules.offset.fit import OffsetUtility
    from terrapref.rules.offset.geometry import OffsetGeometry
    from terrapref.rules.offset.rule import steep_from
    from terrapref.scenario.path import ReferencePath

    gmap, _ = _seen_ramp()
    geometry = OffsetGeometry(max_offset_m=1.0, stations_m=(0.0, 2.0))
    features, path = OffsetFeatures(geometry, 0), ReferencePath(np.array([[1.0, 15.0], [59.0, 15.0]]))
    bands = len(RELIEF_BANDS_DEG)

    def priced_from(side_deg: float | None, grade_deg: float | None) -> tuple[float, float]:
        relief = np.zeros(2 * bands)
        for axis, deg in enumerate((side_deg, grade_deg)):
            if deg is not None:
                relief[axis * bands + RELIEF_BANDS_DEG.index(deg)] = -0.5
        return steep_from(OffsetUtility(np.array(DRIVER_LIKE), 5.0, geometry, relief, (22.0, 22.0)))

    assert priced_from(10.0, 12.0) == (10.0, 12.0) and priced_from(None, None) == (math.inf, math.inf)
    assert steep_from(OffsetUtility(np.array(DRIVER_LIKE), 5.0, geometry)) == FIRST_BAND  # prices no relief: as a fit reads
    for steep, patch in (((22.0, 10.0), True), ((22.0, 12.0), False), ((4.0, None), False), ((None, None), False)):
        view = features(gmap, path, 19.0, relief=True, steep_deg=priced_from(*steep))
        assert view.near_m == (0.0 if patch else math.inf), steep
        np.testing.assert_array_equal(view.relief, features(gmap, path, 19.0, relief=True).relief)  # the same columns either way


def test_ground_a_depth_reading_map_has_not_seen_is_priced_as_the_relief_drive_priced_it() -> None:
    """On a map that reads depth (relief), ground never seen (behind a crest, as a rule) is priced
    as a utility fitted on relief priced it, at most 0. With a speck of the cheapest class on the
    path 3 m ahead and 3 m of unseen ground past it: a relief utility whose drive priced unseen
    ground at nothing or above holds the offset it holds when that ground is seen background,
    and one whose drive priced it high goes round it. A utility fitted on flat ground prices it as
    an average class, on either map, and goes round it. One whose drive priced it dear beside the
    path but not on the path's own lanes (a mound's hidden ground, driven over) holds its offset."""
    from test_offset_rule import CONTROL, DRIVER_LIKE, K

    from terrapref.rules.offset.features import RELIEF_BANDS_DEG
    from terrapref.rules.offset.fit import OffsetUtility
    from terrapref.rules.offset.rule import OffsetSteering, hidden_price, hidden_prices
    from terrapref.scenario.path import ReferencePath

    camera, path, pose = PinholeCamera(), ReferencePath(np.array([[1.0, 15.0], [59.0, 15.0]])), Pose(17.0, 15.0, 0.0)
    flat = GroundMap(camera, _terrain(()))
    flat.update(SegmentationView.of(np.zeros((camera.config.height_px, camera.config.width_px), dtype=np.uint8)), pose)

    def relief_utility(unseen_weight: float, on_path: float = 0.0) -> OffsetUtility:
        weights = np.array(DRIVER_LIKE)
        weights[K] = unseen_weight
        return OffsetUtility(weights, 5.0, relief=np.zeros(2 * len(RELIEF_BANDS_DEG)), relief_shown=(22.0, 22.0), hidden_on_path=on_path)

    def held(gmap: GroundMap, unseen: bool, utility: OffsetUtility | None = None) -> float:
        """The offset held after one frame on ``gmap``, its cells seen background but for the speck
        and (``unseen``) the ground past it on the path."""
        res, cells = gmap.settings.map_resolution_m, gmap.layer("column")
        x = gmap.origin[0] + (np.arange(cells.shape[1]) + 0.5) * res
        y = gmap.origin[1] + (np.arange(cells.shape[0]) + 0.5) * res
        on_path = np.abs(y[:, None] - 15.0) < 0.6
        cells[...] = K  # seen, none of the classes: the background
        cells[on_path & (x[None, :] > 20.4) & (x[None, :] < 23.5)] = K + 1 if unseen else K
        cells[(np.abs(y[:, None] - 15.0) < 0.06) & (x[None, :] > 20.0) & (x[None, :] < 20.2)] = K - 1  # the cheapest class
        stage = OffsetSteering(utility or OffsetUtility(DRIVER_LIKE, 5.0), camera, _terrain(()), CONTROL)
        stage.yaw_rate(gmap, pose, path, 16.0)
        return stage.held

    relief, _ = _seen_ramp()
    assert relief.reads_depth and not flat.reads_depth
    assert abs(held(relief, unseen=True)) > abs(held(relief, unseen=False)) + 0.5  # a flat utility: as on flat ground
    assert hidden_price(OffsetUtility(DRIVER_LIKE, 5.0)) is None
    assert hidden_price(relief_utility(0.5)) == 0.0 and hidden_price(relief_utility(-2.0)) == -2.0
    assert held(relief, True, relief_utility(0.5)) == held(relief, False, relief_utility(0.5))
    assert abs(held(relief, True, relief_utility(-2.0))) > abs(held(relief, False, relief_utility(-2.0))) + 0.5
    # Priced dear beside the path but not on its own lanes (a mound's hidden ground, driven over).
    assert hidden_prices(relief_utility(-2.0, 2.5)) == (-2.0, 0.0) and hidden_prices(relief_utility(-2.0, 0.5)) == (-2.0, -1.5)
    assert held(relief, True, relief_utility(-2.0, 2.5)) == held(relief, False, relief_utility(-2.0, 2.5))
    assert abs(held(flat, unseen=True)) > abs(held(flat, unseen=False)) + 0.5
    relief.reset()
    assert not relief.reads_depth  # a new run starts as a map that has read no depth
