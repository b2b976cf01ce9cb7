"""The camera on relief (SPEC 19) against closed-form answers: the depth of flat ground, a wall
that hides the ground behind it as far as its crest's shadow reaches, a ramp that tilts the body
and moves the horizon by its grade while the ground ahead looks as the flat ground does; and the
frames a simulation hands out."""

from __future__ import annotations

import copy
import math
from typing import Any

import numpy as np
import pytest

from helpers import flat_depth
from terrapref.camera import CameraConfig, PinholeCamera, relief_compiled
from terrapref.camera import render as render_module
from terrapref.camera.relief_compiled import step_lengths
from terrapref.camera.render import SegmentationRenderer
from terrapref.scenario import FORMAT, parse_scenario
from terrapref.sim import Simulation
from terrapref.terrain import UNKNOWN
from terrapref.vehicle import Pose, Vehicle
from terrapref.vehicle.ground import Attitude
from terrapref.world import WorldMap, rasterise

FLAT: dict[str, Any] = {
    "format": FORMAT,
    "name": "relief_render_test",
    "world": {"size_m": [60.0, 40.0], "resolution_m": 0.05, "background": "grass"},
    "terrain": [],
    "path": {"waypoints": [[1.0, 20.0], [59.0, 20.0]]},
}


def world(relief: list[dict] | None = None, terrain: list[dict] | None = None) -> WorldMap:
    data = copy.deepcopy(FLAT)
    data["terrain"] = terrain or []
    if relief:
        data["relief"] = relief
    return rasterise(parse_scenario(data, "relief_render_test.yaml"))


def test_on_flat_ground_every_depth_pixel_is_its_analytic_depth_and_the_classes_are_the_flat_renderers() -> None:
    flat = world(terrain=[{"class": "mud", "circle": {"center": [14.0, 21.0], "radius": 2.0}}])
    renderer = SegmentationRenderer(PinholeCamera(), flat)
    pose = Pose(10.0, 20.3, 0.1)
    ids, depth = renderer.render_with_depth(pose)
    expected, _ = flat_depth(renderer.camera)
    assert depth.dtype == np.float32 and ids.dtype == np.uint8
    np.testing.assert_array_equal(np.isnan(depth), np.isnan(expected))
    np.testing.assert_allclose(depth[~np.isnan(depth)], expected[~np.isnan(expected)], rtol=1e-6)
    np.testing.assert_array_equal(ids, renderer.render(pose))
    assert (ids == flat.classes.id_of("mud")).sum() > 1000


def test_a_wall_hides_the_ground_behind_it_as_far_as_its_crests_shadow() -> None:
    """A wall 0.5 m high from 3.0 to 3.2 m ahead of a camera 1 m up, pitched 30 deg down: its far
    top edge shades the ground out to 3.2 * 1 / (1 - 0.5) = 6.4 m. Rows whose flat-ground point
    lies in that shadow see the wall instead, its face or its top, at depths from
    3.0 cos 30 deg + 0.25 = 2.85 m to 3.0 cos 30 deg + 0.5 = 3.10 m (3.2 m ahead on its top:
    3.02 m); the rows of its top (flat points from 6.0 to 6.4 m) see rock; rows beyond the shadow
    see the grass at its own depth."""
    box = [[13.0, 0.0], [13.2, 0.0], [13.2, 40.0], [13.0, 40.0]]
    walled = world([{"plateau": {"polygon": box, "height_m": 0.5, "edge_m": 0.0}}], [{"class": "rock", "polygon": box}])
    renderer = SegmentationRenderer(PinholeCamera(), walled)
    vehicle = Vehicle(Pose(10.0, 20.0, 0.0), ground=walled)
    assert vehicle.attitude.z_m == 0.0 and vehicle.attitude.pitch_rad == 0.0  # its wheels are on the flat
    ids, depth = renderer.render_with_depth(vehicle.pose, vehicle.attitude)
    expected, ahead = flat_depth(renderer.camera)
    column = renderer.camera.config.width_px // 2
    rock, grass = walled.classes.id_of("rock"), walled.classes.id_of("grass")
    # Each edge of the wall is a slope over one 5 cm cell (bilinear heights): margins of a cell or two.
    shadow = (ahead[:, column] > 3.05) & (ahead[:, column] < 6.25)
    top = (ahead[:, column] > 6.05) & (ahead[:, column] < 6.25)
    beyond = ahead[:, column] > 6.5
    assert shadow.sum() > 40 and top.sum() >= 2 and beyond.sum() > 20
    assert ((depth[shadow, column] > 2.84) & (depth[shadow, column] < 3.11)).all()
    assert (ids[top, column] == rock).all()
    assert (ids[beyond, column] == grass).all()
    np.testing.assert_allclose(depth[beyond, column], expected[beyond, column], rtol=1e-5)
    near = ahead[:, column] < 2.9  # before the wall: the ground as it is
    np.testing.assert_allclose(depth[near, column], expected[near, column], rtol=1e-5)


@pytest.mark.parametrize("height_m", [2.0, 20.0, 1000.0])
def test_a_wall_taller_than_the_view_fills_every_row_above_its_foot_at_the_depth_of_its_plane(height_m: float) -> None:
    """A wall across the view 10 m ahead of a camera 1 m up, pitched 30 deg down: a pixel whose ray
    meets the plane x = 10 below the wall's top sees the wall, at depth 10 / r_x (r: the ray per
    metre of depth), within the march's step there: the face is taken as straight from the last
    sample before it to the first on its top, a pixel row's ground apart ((u^2 + 1) / 320 for u
    metres along the column's plane: 0.32 m, 3.2%, ahead; 0.63 m, 4.5%, at the frame's sides,
    each side of the face).
    A wall 20 m or 1 km high rises past the plane of the optical centre before its top, where no
    sample of the march is in front of the camera: its face still fills every row up to the top
    of the image, not the sky."""
    walled = world([{"plateau": {"polygon": [[20.0, 0.0], [60.0, 0.0], [60.0, 40.0], [20.0, 40.0]], "height_m": height_m, "edge_m": 0.0}}])
    renderer = SegmentationRenderer(PinholeCamera(), walled)
    vehicle = Vehicle(Pose(10.0, 20.0, 0.0), ground=walled)
    ids, depth = renderer.render_with_depth(vehicle.pose, vehicle.attitude)
    axes, centre = renderer.placement(vehicle.pose, vehicle.attitude)
    camera = renderer.camera
    cols, rows = np.meshgrid(np.arange(camera.config.width_px), np.arange(camera.config.height_px))
    a, b = (cols + 0.5 - camera.cx) / camera.fx, (rows + 0.5 - camera.cy) / camera.fy
    rays = a[..., None] * axes[0] + b[..., None] * axes[1] + axes[2]
    with np.errstate(divide="ignore"):
        at = np.where(rays[..., 0] > 0, (20.0 - centre[0]) / rays[..., 0], np.inf)  # depth at the plane x = 20
    hit_z = centre[2] + at * rays[..., 2]
    # The face, a cell clear of its foot and top (the field is bilinear: each edge a slope over a cell).
    face = (hit_z > 0.1) & (hit_z < height_m - 0.1) & (at * np.linalg.norm(rays, axis=-1) < camera.config.max_range_m - 0.5)
    assert face[0].all() == (height_m > 10.0) and face.sum() > 20_000
    assert (ids[face] == walled.classes.id_of("grass")).all()
    ahead = face & (np.abs(a) <= 0.25)  # within 14 deg of the optical axis
    np.testing.assert_allclose(depth[ahead], at[ahead], rtol=0.035)
    np.testing.assert_allclose(depth[face], at[face], rtol=0.09)


def test_on_a_ramp_the_horizon_moves_by_the_grade_and_the_ramp_ahead_looks_as_flat_ground_does() -> None:
    """A ramp of grade 0.2 from x = 5 to 55 m: the body pitches up by atan(0.2), so the level
    horizon drops in the image from cy - fy tan(30 deg) to cy - fy tan(30 deg - atan(0.2)); the
    camera rides the body, so the ramp ahead (within its 30 m range) is imaged as flat ground is."""
    ramp = world([{"plateau": {"polygon": [[55, -10], [80, -10], [80, 50], [55, 50]], "height_m": 10.0, "edge_m": 50.0}}])
    renderer = SegmentationRenderer(PinholeCamera(CameraConfig(max_range_m=20.0)), ramp)
    vehicle = Vehicle(Pose(15.0, 20.0, 0.0), ground=ramp)
    grade = math.atan(0.2)
    assert vehicle.attitude.grade_rad == pytest.approx(grade, abs=1e-6)
    axes, _ = renderer.placement(vehicle.pose, vehicle.attitude)
    level = np.array([1.0, 0.0, 0.0])  # a level ray straight ahead
    row = renderer.camera.cy + renderer.camera.fy * (axes[1] @ level) / (axes[2] @ level)
    assert row == pytest.approx(renderer.camera.cy - renderer.camera.fy * math.tan(math.radians(30.0) - grade), abs=1e-3)
    ids, depth = renderer.render_with_depth(vehicle.pose, vehicle.attitude)
    expected, _ = flat_depth(renderer.camera)
    both = ~np.isnan(depth) & ~np.isnan(expected)
    assert (np.isnan(depth) != np.isnan(expected)).sum() <= 10  # a few pixels at the range's edge, on either side of it
    np.testing.assert_allclose(depth[both], expected[both], rtol=1e-4)
    assert both.sum() > 200_000 and (ids[~np.isnan(depth)] != UNKNOWN).all()


def test_a_simulations_frames_carry_depth_and_on_relief_the_body_attitude() -> None:
    data = copy.deepcopy(FLAT)
    data["relief"] = [{"mound": {"center": [3.0, 20.0], "radius": 3.0, "height_m": 0.3}}]
    sim = Simulation(parse_scenario(data, "relief_render_test.yaml"))
    frame = sim.reset()
    assert frame.attitude.pitch_rad != 0.0  # the start is on the mound's flank
    assert frame.depth is not None and frame.depth.shape == frame.image.shape and np.isfinite(frame.depth).sum() > 1000
    flat_frame = Simulation(parse_scenario(copy.deepcopy(FLAT), "relief_render_test.yaml")).reset()
    expected, _ = flat_depth(PinholeCamera())
    np.testing.assert_allclose(flat_frame.depth, expected, rtol=1e-6)


def test_a_nearer_range_leaves_the_ground_beyond_it_unseen_and_the_rest_as_it_was() -> None:
    rolling = world([{"noise": {"amplitude_m": 0.5, "wavelength_m": 10.0, "seed": 1}}])
    renderer = SegmentationRenderer(PinholeCamera(), rolling)
    vehicle = Vehicle(Pose(20.0, 20.0, 0.4), ground=rolling)
    ids, depth = renderer.render_with_depth(vehicle.pose, vehicle.attitude)
    near_ids, near_depth = renderer.render_with_depth(vehicle.pose, vehicle.attitude, max_range_m=10.0)
    cam = renderer.camera
    rows, cols = np.mgrid[0 : cam.config.height_px, 0 : cam.config.width_px]
    per_depth = np.sqrt(1.0 + ((cols + 0.5 - cam.cx) / cam.fx) ** 2 + ((rows + 0.5 - cam.cy) / cam.fy) ** 2)  # range per metre of depth
    kept = ~np.isnan(near_depth)
    assert (near_depth[kept] * per_depth[kept] <= 10.0 + 1e-4).all() and (near_ids[~kept] == UNKNOWN).all()
    np.testing.assert_array_equal(near_ids[kept], ids[kept])
    np.testing.assert_array_equal(near_depth[kept], depth[kept])
    lost = ~kept & ~np.isnan(depth)  # seen only with the camera's own range: farther than 10 m
    assert lost.sum() > 1000 and (depth[lost] * per_depth[lost] > 10.0 - 1e-4).all()


def marched(
    renderer: SegmentationRenderer, pose: Pose, attitude: Attitude, pixels: np.ndarray, step_m: float = 0.02
) -> tuple[np.ndarray, np.ndarray]:
    """Class ids and depths [m along the optical axis, NaN: no ground] of the flat pixel indices
    ``pixels`` (n,), the slow and plain way: each pixel's ray walked out from the optical centre
    in steps of ``step_m`` until it first ends below the height field, the crossing then halved
    down to a micrometre; the class of the cell it meets, unknown past the camera's range."""
    camera, world = renderer.camera, renderer.world
    axes, centre = renderer.placement(pose, attitude)
    rows, cols = np.divmod(pixels, camera.config.width_px)
    a, b = (cols + 0.5 - camera.cx) / camera.fx, (rows + 0.5 - camera.cy) / camera.fy
    rays = a[:, None] * axes[0] + b[:, None] * axes[1] + axes[2]  # (n, 3): a metre of depth
    per_m = np.linalg.norm(rays, axis=1)  # metres of ray per metre of depth

    far = camera.config.max_range_m / per_m
    before, hit = np.zeros(len(pixels)), np.full(len(pixels), np.nan)
    for k in range(1, math.ceil(camera.config.max_range_m / step_m) + 1):
        depth = np.minimum(k * step_m / per_m, far)
        crossed = np.isnan(hit) & under_at(depth, rays, centre, world)
        hit[crossed] = depth[crossed]
        before = np.where(np.isnan(hit), depth, before)
    found = ~np.isnan(hit)
    low, high = before[found], hit[found]
    while (high - low).max(initial=0.0) > 1e-6:
        middle = 0.5 * (low + high)
        below = under_at(middle, rays[found], centre, world)
        low, high = np.where(below, low, middle), np.where(below, middle, high)
    depth = np.full(len(pixels), np.nan)
    depth[found] = high
    ids = np.full(len(pixels), UNKNOWN, dtype=np.uint8)
    ids[found] = world.class_at((centre + high[:, None] * rays[found])[:, :2])
    return ids, depth


def under_at(depth: np.ndarray, rays: np.ndarray, centre: np.ndarray, ground: WorldMap) -> np.ndarray:
    """Whether the points at ``depth`` along ``rays`` from ``centre`` lie on or under the ground."""
    point = centre + depth[:, None] * rays
    return point[:, 2] <= ground.height_at(point[:, :2])


@pytest.mark.parametrize("attitude", [Attitude(0.0, -0.05, 0.15), Attitude(0.0, 0.12, -0.2)], ids=["rolled-left", "pitched-rolled-right"])
def test_over_rolling_ground_and_a_mound_the_frame_agrees_with_each_rays_own_march(attitude: Attitude) -> None:
    """The march samples each column's ground and takes it as straight between samples; against
    every pixel's ray walked to the ground on its own (2,000 pixels of the full frame, the camera
    rolled and pitched off the ground's own attitude), 99.5% of them see the same class, and of
    the pixels both see ground at, 99.5% at depths within 1% or 2 cm (the rest lie on the
    silhouettes of crests, a row's breadth off)."""
    relief = [
        {"noise": {"amplitude_m": 0.5, "wavelength_m": 10.0, "seed": 1}},
        {"mound": {"center": [18.0, 21.0], "radius": 2.5, "height_m": 0.8}},
    ]
    terrain = [
        {"class": "mud", "circle": {"center": [16.0, 17.0], "radius": 2.0}},
        {"class": "rock", "polygon": [[20.0, 19.0], [24.0, 19.0], [24.0, 26.0], [20.0, 26.0]]},
        {"class": "water", "circle": {"center": [30.0, 24.0], "radius": 4.0}},
    ]
    ground = world(relief, terrain)
    renderer = SegmentationRenderer(PinholeCamera(), ground)
    pose = Pose(10.0, 20.0, 0.1)
    attitude = attitude._replace(z_m=Vehicle(pose, ground=ground).attitude.z_m)
    ids, depth = renderer.render_with_depth(pose, attitude)
    pixels = np.random.default_rng(0).choice(ids.size, 2000, replace=False)
    expected_ids, expected_depth = marched(renderer, pose, attitude, pixels)
    got_ids, got_depth = ids.reshape(-1)[pixels], depth.reshape(-1)[pixels]
    assert (expected_ids != UNKNOWN).sum() > 1000 and len(np.unique(expected_ids)) >= 4  # ground, mud, rock, water, sky
    assert (got_ids == expected_ids).mean() >= 0.995
    assert (np.isnan(got_depth) == np.isnan(expected_depth)).mean() >= 0.995
    both = ~np.isnan(got_depth) & ~np.isnan(expected_depth)
    close = np.abs(got_depth[both] - expected_depth[both]) <= np.maximum(0.01 * expected_depth[both], 0.02)
    assert close.mean() >= 0.995


def test_the_marchs_step_is_a_block_on_a_plane_and_on_a_parabola_the_step_that_keeps_its_chord_within_the_tolerance() -> None:
    """Ground taken as straight over a step L strays from ground of curvature c by c L^2 / 8: on
    z = x^2 / 2 (c = 1 /m) a tolerance of 5 mm allows L = sqrt(8 * 0.005) = 0.2 m; a plane
    allows any step, and gets the longest, a block (16 cells of 5 cm). Blocks within two of the
    field's edge are left aside: beyond it the ground goes on level, a crease."""
    res, tolerance = 0.05, 0.005
    x = (np.arange(160) + 0.5) * res
    # Row-major float32, as a world's height field is.
    plane = np.ascontiguousarray(np.broadcast_to(0.3 * x[None, :] - 0.1 * x[:, None] + 2.0, (160, 160)), dtype=np.float32)
    parabola = np.ascontiguousarray(np.broadcast_to(0.5 * x[None, :] ** 2, (160, 160)), dtype=np.float32)
    inner = (slice(2, -2), slice(2, -2))
    np.testing.assert_allclose(step_lengths(plane, res, 4, tolerance, 2 * res)[inner], 16 * res)
    np.testing.assert_allclose(step_lengths(parabola, res, 4, tolerance, 2 * res)[inner], 0.2, rtol=1e-3)
    assert step_lengths(parabola, res, 4, 1e-6, 2 * res).max() == pytest.approx(2 * res)  # never under two cells


def test_past_a_wall_no_column_shows_ground_above_its_own_silhouette() -> None:
    """A wall 0.4 m high and 0.5 m thick across the way, seen from a rolled camera: where a column's plane meets
    its wall, a Newton step from the level ground before it lands in the air, and the rows it
    would fill above the true silhouette show ground that is not there. In every fourth column,
    the ground the frame shows in the 40 rows under its top agrees with each ray's own march in
    all but two of them."""
    ledge = [{"plateau": {"polygon": [[25.0, 0.0], [25.5, 0.0], [25.5, 40.0], [25.0, 40.0]], "height_m": 0.4, "edge_m": 0.0}}]
    renderer = SegmentationRenderer(PinholeCamera(), world(ledge))
    pose, attitude = Pose(18.0, 20.0, 0.15), Attitude(0.0, 0.02, 0.12)
    depth = renderer.render_with_depth(pose, attitude)[1]
    height, width = depth.shape
    seen = ~np.isnan(depth)
    columns = np.arange(0, width, 4)
    top = seen[:, columns].argmax(axis=0)
    band = np.arange(-3, 40)
    rows = np.clip(top[:, None] + band[None, :], 0, height - 1)
    pixels = (rows * width + columns[:, None]).reshape(-1)
    expected = ~np.isnan(marched(renderer, pose, attitude, pixels)[1]).reshape(len(columns), len(band))
    wrong = (seen.reshape(-1)[pixels].reshape(len(columns), len(band)) != expected).sum(axis=1)
    assert seen[:, columns].any(axis=0).all() and wrong.max() <= 2, columns[wrong > 2]


def test_a_newton_step_that_overshoots_a_post_is_settled_on_its_near_face_not_the_ground_behind() -> None:
    """A post 1 m high and a cell wide, a column's plane leaning (0.15 m sideways per metre of
    drop) from a centre 1.2 m up: from a guess of 0.5 m (inside the post) one Newton step lands
    0.1 m above the centre, in the air. Settled, the drop is where the plane's point meets the
    post's near face (its gap closed; the post bilinear between cell centres), not 1.2 m, the
    ground behind it, which the far end of the field's heights also reaches."""
    from terrapref.camera.relief_compiled import SETTLE_M, settle_drops
    from terrapref.world.height_compiled import height_at

    res, cz, lean, x0 = 0.05, 1.2, 0.15, 4.95
    heights = np.zeros((4, 200), np.float32)
    heights[:, 100] = 1.0  # the cell centred at x = 5.025
    guess, stepped = 0.5, -0.1
    drop, moved = np.array([stepped]), np.array([stepped - guess])
    planes = np.zeros((9, 1))
    planes[0, 0], planes[2, 0] = 1.0, lean  # level direction +x; a metre of drop moves the point 0.15 m along x
    settle_drops(moved, drop, np.array([x0]), planes, np.array([0.0, 0.1, cz]), heights, 1.0 / res, (0.0, 1.0))
    face = x0 + drop[0] * lean
    assert 0.2 < drop[0] < 1.0 and 5.0 < face < 5.025
    assert abs(cz - drop[0] - height_at(heights, 1.0 / res, face, 0.1)) <= 0.01 * SETTLE_M


def test_a_frame_of_more_segments_than_the_march_first_makes_room_for_agrees_with_each_rays_own_march() -> None:
    """A tall, narrow frame over short bumps: each column's ground comes in more segments than the
    march first keeps room for (64 a column), so it grows its lists; the frame still agrees with
    every pixel's own ray as a frame of the usual size does."""
    relief = [{"noise": {"amplitude_m": 0.1, "wavelength_m": 0.8, "seed": 2}}]
    ground = world(relief)
    # fy = 1000 px: a row's ground is under the bumps' two-cell steps out to the 12 m range.
    camera = PinholeCamera(
        CameraConfig(width_px=8, height_px=1000, hfov_deg=math.degrees(2 * math.atan(4 / 1000)), pitch_deg=20.0, max_range_m=12.0)
    )
    renderer = SegmentationRenderer(camera, ground)
    pose = Pose(10.0, 20.0, 0.0)
    attitude = Vehicle(pose, ground=ground).attitude
    axes, centre = renderer.placement(pose, attitude)
    heights, steps, shift, span = render_module._march_ground(ground)
    planes = relief_compiled._planes(axes, renderer._ray_a)
    below = float(ground.height_at(centre[None, :2])[0]) - centre[2]
    march = (planes, -below, max(-below, 0.2), camera.fy, camera.cy, camera.config.max_range_m, centre, renderer._ray_b)
    _, segments, _ = relief_compiled._march(*march, (heights, 1.0 / ground.resolution_m, steps, shift, span), camera.shape)
    assert len(segments[0]) > 64 * camera.config.width_px
    ids, depth = renderer.render_with_depth(pose, attitude)
    pixels = np.random.default_rng(0).choice(ids.size, 2000, replace=False)
    expected_ids, expected_depth = marched(renderer, pose, attitude, pixels)
    got_ids, got_depth = ids.reshape(-1)[pixels], depth.reshape(-1)[pixels]
    assert (expected_ids != UNKNOWN).sum() > 1000
    assert (got_ids == expected_ids).mean() >= 0.995
    both = ~np.isnan(got_depth) & ~np.isnan(expected_depth)
    assert (np.isnan(got_depth) == np.isnan(expected_depth)).mean() >= 0.99
    close = np.abs(got_depth[both] - expected_depth[both]) <= np.maximum(0.01 * expected_depth[both], 0.02)
    assert close.mean() >= 0.995
