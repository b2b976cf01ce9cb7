"""Pinhole geometry against closed forms, and the fast renderer against per-pixel ray casting."""

from __future__ import annotations

import math

import numpy as np
import pytest

from terrapref.camera import CameraConfig, PinholeCamera, PixelSet, SegmentationRenderer, SegmentationView
from terrapref.terrain import UNKNOWN, default_classes
from terrapref.vehicle import Pose
from terrapref.world import WorldMap

CLASSES = default_classes()
GRASS, MUD = CLASSES.id_of("grass"), CLASSES.id_of("mud")
TAN30 = math.tan(math.radians(30.0))


def _world(raster: np.ndarray, res: float) -> WorldMap:
    return WorldMap(raster, res, CLASSES)


def _grass_with_mud_square(center: tuple[float, float], half_m: float, size_m: float = 30.0, res: float = 0.05) -> WorldMap:
    n = round(size_m / res)
    raster = np.full((n, n), GRASS, dtype=np.uint8)
    c0, c1 = round((center[0] - half_m) / res), round((center[0] + half_m) / res)
    r0, r1 = round((center[1] - half_m) / res), round((center[1] + half_m) / res)
    raster[r0:r1, c0:c1] = MUD
    return _world(raster, res)


def _blocks_world(
    rng: np.random.Generator, size_m: tuple[float, float] = (40.0, 25.0), res: float = 0.05, block_m: float = 0.5
) -> WorldMap:
    """Random classes in square blocks; a non-square map, so rows and columns cannot be swapped."""
    k = round(block_m / res)
    blocks = rng.integers(0, 5, (round(size_m[1] / block_m), round(size_m[0] / block_m))).astype(np.uint8)
    return _world(np.kron(blocks, np.ones((k, k), dtype=np.uint8)), res)


def _to_world(points_v: np.ndarray, pose: Pose) -> np.ndarray:
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    x, y = points_v[..., 0], points_v[..., 1]
    return np.stack([pose.x + c * x - s * y, pose.y + s * x + c * y], axis=-1)


# --- closed-form facts (SPEC section 5) -------------------------------------------------------


def test_default_intrinsics():
    cam = PinholeCamera()
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == pytest.approx((320.0, 320.0, 320.0, 240.0))
    assert cam.shape == (480, 640)


def test_ground_point_on_the_optical_axis_projects_to_the_principal_point():
    cam = PinholeCamera()
    uv, visible = cam.project_ground(np.array([1.0 / TAN30, 0.0]))
    np.testing.assert_allclose(uv, [320.0, 240.0], atol=1e-9)
    assert visible
    assert cam.pixel_indices(np.array([1.0 / TAN30, 0.0])) == 240 * 640 + 320


def test_bottom_edge_sees_the_ground_about_0_43_m_ahead():
    cam = PinholeCamera()
    ground, ok = cam.back_project(np.array([320.0, 480.0]))
    expected = 1.0 / math.tan(math.radians(30.0) + math.atan(240.0 / 320.0))
    assert ok
    np.testing.assert_allclose(ground, [expected, 0.0], atol=1e-12)
    assert ground[0] == pytest.approx(0.43, abs=0.005)


def test_horizon_row():
    cam = PinholeCamera()
    assert cam.horizon_row() == pytest.approx(240.0 - 320.0 * TAN30)
    assert cam.horizon_row() == pytest.approx(55.2, abs=0.05)


def test_rows_above_the_horizon_render_unknown():
    # A 1 km map at 1 m cells and a 10 km range, so that rows just below the horizon do see
    # ground and the 255 above it comes from the geometry, not from the range or the map's edge.
    world = _world(np.full((1000, 1000), GRASS, dtype=np.uint8), 1.0)
    for max_range in (30.0, 1e4):
        cam = PinholeCamera(CameraConfig(max_range_m=max_range))
        image = SegmentationRenderer(cam, world).render(Pose(500.0, 500.0, 0.3))
        horizon = cam.horizon_row()
        assert (image[: math.floor(horizon)] == UNKNOWN).all()
        assert (image[-1] == GRASS).all()
        if max_range > 1e3:
            assert (image[60:] == GRASS).all()  # 5 rows below the horizon: ground about 80 m ahead


def test_rendered_default_frame_matches_the_range_limit():
    world = _world(np.full((2000, 2000), GRASS, dtype=np.uint8), 0.05)
    cam = PinholeCamera()
    image = SegmentationRenderer(cam, world).render(Pose(50.0, 50.0, 0.0))
    # Centre column: the ray at row r hits ground at distance h / tan(angle below horizontal).
    rows = np.arange(480)
    angle = math.radians(30.0) + np.arctan((rows + 0.5 - 240.0) / 320.0)
    with np.errstate(divide="ignore"):
        ray_len = np.where(angle > 0, 1.0 / np.sin(np.maximum(angle, 1e-300)), np.inf)
    # Stay away from the exact range boundary (a measure-zero tie).
    clear = np.abs(ray_len - 30.0) > 1e-6
    expected = np.where(ray_len <= 30.0, GRASS, UNKNOWN)
    col = image[:, 320]
    np.testing.assert_array_equal(col[clear], expected[clear])


def test_points_behind_beyond_range_or_outside_the_image_are_not_visible():
    cam = PinholeCamera()
    pts = np.array(
        [
            [2.0, 0.0],  # visible
            [-2.0, 0.0],  # behind the camera
            [0.0, 0.0],  # straight below: outside the image (below its bottom edge)
            [0.3, 0.0],  # ahead, but nearer than the bottom edge's 0.43 m
            [40.0, 0.0],  # beyond max range
            [29.0, 0.0],  # within range, above the bottom, but is it inside the image?
            [2.0, 5.0],  # far to the left: outside the image's left edge
            [2.0, -5.0],  # far to the right
        ]
    )
    uv, visible = cam.project_ground(pts)
    # 29 m ahead: ray length sqrt(29^2 + 1) < 30, and the row is below the horizon: visible.
    assert visible.tolist() == [True, False, False, False, False, True, False, False]
    assert cam.pixel_indices(pts).tolist()[1:5] == [-1, -1, -1, -1]
    assert uv[6, 0] < 0 and uv[7, 0] >= 640


def test_left_of_the_vehicle_is_left_in_the_image():
    cam = PinholeCamera()
    uv, visible = cam.project_ground(np.array([[3.0, 1.0], [3.0, -1.0]]))
    assert visible.all()
    assert uv[0, 0] < 320 < uv[1, 0]
    assert uv[0, 1] == pytest.approx(uv[1, 1])


def test_back_project_inverts_project_ground():
    cam = PinholeCamera()
    rng = np.random.default_rng(3)
    uv = np.stack([rng.uniform(0, 640, 200), rng.uniform(120, 480, 200)], axis=-1)
    ground, ok = cam.back_project(uv)
    uv2, visible = cam.project_ground(ground[ok])
    assert ok.sum() > 100
    np.testing.assert_allclose(uv2, uv[ok], atol=1e-7)
    assert visible.all()


def test_back_project_misses_above_the_horizon():
    cam = PinholeCamera()
    _, ok = cam.back_project(np.array([[320.0, 10.0], [0.5, 50.0], [320.0, 56.0]]))
    assert ok.tolist() == [False, False, False]  # sky, sky, and ground beyond 30 m


@pytest.mark.parametrize(
    "config",
    [
        CameraConfig(pitch_deg=20.0, hfov_deg=70.0, mount_height_m=1.5),
        CameraConfig(pitch_deg=45.0, hfov_deg=60.0, mount_height_m=0.8, width_px=320, height_px=200),
        CameraConfig(pitch_deg=25.0, mount_forward_m=0.4),
    ],
    ids=["p20-h70-1.5m", "p45-small", "forward-mount"],
)
def test_principal_point_fact_for_other_configs(config):
    cam = PinholeCamera(config)
    fx = (config.width_px / 2) / math.tan(math.radians(config.hfov_deg) / 2)
    assert cam.fx == pytest.approx(fx) and cam.fy == pytest.approx(fx)
    ahead = config.mount_forward_m + config.mount_height_m / math.tan(math.radians(config.pitch_deg))
    uv, visible = cam.project_ground(np.array([ahead, 0.0]))
    np.testing.assert_allclose(uv, [config.width_px / 2, config.height_px / 2], atol=1e-9)
    assert visible
    ground, ok = cam.back_project(np.array([config.width_px / 2, config.height_px]))
    bottom = config.mount_forward_m + config.mount_height_m / math.tan(
        math.radians(config.pitch_deg) + math.atan((config.height_px / 2) / fx)
    )
    assert ok and ground == pytest.approx([bottom, 0.0], abs=1e-12)
    assert cam.horizon_row() == pytest.approx(config.height_px / 2 - fx * math.tan(math.radians(config.pitch_deg)))


def test_camera_yaw_turns_the_view():
    cam = PinholeCamera(CameraConfig(yaw_deg=30.0))
    d = 1.0 / TAN30
    uv, visible = cam.project_ground(np.array([d * math.cos(math.radians(30.0)), d * math.sin(math.radians(30.0))]))
    np.testing.assert_allclose(uv, [320.0, 240.0], atol=1e-9)
    assert visible


def test_camera_config_validation_and_round_trip():
    for bad in ({"hfov_deg": 180.0}, {"mount_height_m": 0.0}, {"pitch_deg": 90.0}, {"width_px": 0}, {"max_range_m": -1.0}):
        with pytest.raises(ValueError):
            CameraConfig(**bad)
    config = CameraConfig(pitch_deg=20.0, fx=300.0)
    assert CameraConfig.from_dict(config.to_dict()) == config
    assert PinholeCamera(config).fy == 300.0


# --- the renderer against the geometry --------------------------------------------------------


def _check_render_consistency(cam: PinholeCamera, world: WorldMap, rng: np.random.Generator, n_poses: int, n_pixels: int) -> int:
    """Render at random poses and compare sampled pixels with a ray cast through their centres.

    Returns the number of pixels that saw the map (so callers can check the test had teeth).
    """
    renderer = SegmentationRenderer(cam, world)
    h, w = cam.shape
    size = np.array(world.size_m)
    on_map_pixels = 0
    for _ in range(n_poses):
        # Some poses near or beyond the edge, so off-map pixels are sampled too.
        xy = rng.uniform(-2.0, size + 2.0)
        pose = Pose(float(xy[0]), float(xy[1]), float(rng.uniform(-math.pi, math.pi)))
        image = renderer.render(pose)
        assert image.shape == (h, w) and image.dtype == np.uint8
        rows = rng.integers(0, h, n_pixels)
        cols = rng.integers(0, w, n_pixels)
        centres = np.stack([cols + 0.5, rows + 0.5], axis=-1)
        ground_v, ok = cam.back_project(centres)
        ground_w = _to_world(ground_v, pose)
        expected = np.where(ok, world.class_at(ground_w), UNKNOWN)
        # Only points within 1e-3 cells of a cell boundary may differ (float32 in the renderer).
        cell = ground_w / world.resolution_m
        frac = cell - np.floor(cell)
        near_edge = ok & (np.minimum(frac, 1.0 - frac) < 1e-3).any(axis=-1)
        keep = ~near_edge
        assert keep.mean() > 0.95
        np.testing.assert_array_equal(image[rows[keep], cols[keep]], expected[keep])
        on_map_pixels += int((expected[keep] != UNKNOWN).sum())
        # And the ground point projects back into the same pixel.
        uv, visible = cam.project_ground(ground_v[ok])
        assert visible.all()
        np.testing.assert_array_equal(np.floor(uv).astype(int), np.stack([cols[ok], rows[ok]], axis=-1))
    return on_map_pixels


def test_render_matches_ray_casting_at_random_poses():
    rng = np.random.default_rng(0)
    world = _blocks_world(rng)
    assert world.raster.shape == (500, 800)
    seen = _check_render_consistency(PinholeCamera(), world, rng, n_poses=30, n_pixels=400)
    assert seen > 30 * 400 * 0.2


def test_render_matches_ray_casting_on_a_large_map():
    # 100 m x 60 m at 0.05 m: cell coordinates up to 2000, where float32 rounding is largest.
    rng = np.random.default_rng(11)
    world = _blocks_world(rng, size_m=(100.0, 60.0))
    assert _check_render_consistency(PinholeCamera(), world, rng, n_poses=8, n_pixels=1000) > 8 * 1000 * 0.2


@pytest.mark.parametrize(
    "config",
    [
        CameraConfig(pitch_deg=20.0, hfov_deg=70.0, mount_height_m=1.5),
        CameraConfig(
            pitch_deg=35.0,
            hfov_deg=100.0,
            mount_height_m=0.7,
            yaw_deg=15.0,
            mount_forward_m=0.3,
            max_range_m=12.0,
            width_px=160,
            height_px=90,
        ),
    ],
    ids=["p20-h70-1.5m", "yawed-forward-small"],
)
def test_render_matches_ray_casting_for_other_configs(config):
    rng = np.random.default_rng(7)
    world = _blocks_world(rng, size_m=(30.0, 18.0))
    assert _check_render_consistency(PinholeCamera(config), world, rng, n_poses=15, n_pixels=400) > 0


def test_known_patch_appears_where_geometry_says():
    # Vehicle at (10, 15) facing +x; a 2 m mud square 4..6 m ahead, centred on the heading.
    world = _grass_with_mud_square((15.0, 15.0), 1.0)
    cam = PinholeCamera()
    image = SegmentationRenderer(cam, world).render(Pose(10.0, 15.0, 0.0))
    centre = np.floor(cam.project_ground(np.array([5.0, 0.0]))[0]).astype(int)
    assert image[centre[1], centre[0]] == MUD
    outside = np.floor(cam.project_ground(np.array([5.0, 2.0]))[0]).astype(int)  # 2 m left: grass
    assert image[outside[1], outside[0]] == GRASS
    near = np.floor(cam.project_ground(np.array([3.0, 0.0]))[0]).astype(int)  # before the square
    assert image[near[1], near[0]] == GRASS
    # The square is centred, so its pixels straddle the centre column.
    cols = np.flatnonzero((image == MUD).any(axis=0))
    assert cols.min() < 320 < cols.max()
    assert abs((cols.min() + cols.max()) / 2 - 319.5) <= 1.0


def test_known_patch_with_the_vehicle_turned():
    # Facing north (+y); the patch 5 m north of the vehicle must be straight ahead.
    world = _grass_with_mud_square((15.0, 20.0), 1.0)
    cam = PinholeCamera()
    image = SegmentationRenderer(cam, world).render(Pose(15.0, 15.0, math.pi / 2))
    centre = np.floor(cam.project_ground(np.array([5.0, 0.0]))[0]).astype(int)
    assert image[centre[1], centre[0]] == MUD
    # Facing east instead, the patch is at a bearing of 90 deg, outside the +-45 deg view.
    image_east = SegmentationRenderer(cam, world).render(Pose(15.0, 15.0, 0.0))
    assert not (image_east == MUD).any()


def test_patch_on_the_left_appears_in_the_left_half():
    # A square 5 m ahead and 2 m to the vehicle's left, with the vehicle facing south-west.
    pose = Pose(15.0, 15.0, math.radians(-135.0))
    center = _to_world(np.array([5.0, 2.0]), pose)
    world = _grass_with_mud_square((float(center[0]), float(center[1])), 0.75)
    image = SegmentationRenderer(PinholeCamera(), world).render(pose)
    mud_cols = np.flatnonzero((image == MUD).any(axis=0))
    assert len(mud_cols) > 10
    assert mud_cols.max() < 320
    mirrored = _to_world(np.array([5.0, -2.0]), pose)
    world_r = _grass_with_mud_square((float(mirrored[0]), float(mirrored[1])), 0.75)
    image_r = SegmentationRenderer(PinholeCamera(), world_r).render(pose)
    mud_cols_r = np.flatnonzero((image_r == MUD).any(axis=0))
    assert mud_cols_r.min() >= 320
    # Mirror symmetry: the right patch's columns are the left patch's reflected about the centre.
    assert sorted(639 - mud_cols_r) == mud_cols.tolist()


def test_off_map_is_unknown():
    world = _world(np.full((400, 400), GRASS, dtype=np.uint8), 0.05)  # 20 m x 20 m
    cam = PinholeCamera()
    pose = Pose(1.0, 10.0, math.pi)  # 1 m from the western edge, facing west
    image = SegmentationRenderer(cam, world).render(pose)
    for ahead, expected in ((0.5, GRASS), (0.9, GRASS), (1.2, UNKNOWN), (3.0, UNKNOWN), (10.0, UNKNOWN)):
        col, row = np.floor(cam.project_ground(np.array([ahead, 0.0]))[0]).astype(int)
        assert image[row, col] == expected, ahead
    # Entirely off the map, looking away from it: nothing but unknown.
    assert (SegmentationRenderer(cam, world).render(Pose(-5.0, 10.0, math.pi)) == UNKNOWN).all()
    assert (SegmentationRenderer(cam, world).render(Pose(50.0, -40.0, 0.0)) == UNKNOWN).all()


def test_render_does_not_reuse_a_returned_frame():
    world = _grass_with_mud_square((15.0, 15.0), 1.0)
    renderer = SegmentationRenderer(PinholeCamera(), world)
    first = renderer.render(Pose(10.0, 15.0, 0.0))
    kept = first.copy()
    renderer.render(Pose(10.0, 15.0, math.pi))
    np.testing.assert_array_equal(first, kept)


# --- the compiled loops against the vectorised NumPy form ----------------------------------------


def _numpy_render(renderer: SegmentationRenderer, pose: Pose) -> np.ndarray:
    """The renderer's formula as a dozen vectorised NumPy passes (how it rendered before its loops
    were compiled): the compiled kernels must give these class ids, pixel for pixel."""
    # Each visible row's padded-raster cell of column offset 0 and its change per column: the
    # ground points rotated by the yaw into the world frame, then to cells (+1 for the border).
    x, y, yaw = pose
    res = renderer.world.resolution_m
    c, s = math.cos(yaw), math.sin(yaw)
    P, Q = renderer._P, renderer._Q
    A = np.empty(P.shape, np.float32)
    B = np.empty(Q.shape, np.float32)
    A[:, 0] = (x + (P[:, 0] * c - P[:, 1] * s)) / res + 1.0
    A[:, 1] = (y + (P[:, 0] * s + P[:, 1] * c)) / res + 1.0
    B[:, 0] = (Q[:, 0] * c - Q[:, 1] * s) / res
    B[:, 1] = (Q[:, 0] * s + Q[:, 1] * c) / res
    ny, nx = renderer.world.raster.shape
    u = renderer._u
    gx = np.clip(np.multiply.outer(B[:, 0], u) + A[:, 0:1], 0.0, nx + 2 - 1e-2)
    gy = np.clip(np.multiply.outer(B[:, 1], u) + A[:, 1:2], 0.0, ny + 2 - 1e-2)
    assert gx.dtype == np.float32 and gy.dtype == np.float32
    out = np.full(renderer.shape, UNKNOWN, dtype=np.uint8)
    block = renderer._flat[gy.astype(np.int32) * (nx + 2) + gx.astype(np.int32)]
    row0 = renderer._row0
    out[row0:] = np.where(renderer._valid_flat.reshape(renderer.shape)[row0:], block, UNKNOWN)
    return out


@pytest.mark.parametrize(
    "config",
    [CameraConfig(), CameraConfig(pitch_deg=45.0, hfov_deg=60.0, mount_height_m=0.8, width_px=320, height_px=200)],
    ids=["default", "p45-small"],
)
def test_compiled_render_equals_the_numpy_form_pixel_for_pixel(config):
    rng = np.random.default_rng(23)
    # Every cell its own random class, so a pixel read from a neighbouring cell would show.
    world = _world(rng.integers(0, 5, (500, 700)).astype(np.uint8), 0.05)
    renderer = SegmentationRenderer(PinholeCamera(config), world)
    every = np.arange(config.width_px * config.height_px)
    on_map = 0
    for _ in range(60):
        pose = Pose(rng.uniform(-8.0, 43.0), rng.uniform(-8.0, 33.0), rng.uniform(-math.pi, math.pi))
        expected = _numpy_render(renderer, pose)
        np.testing.assert_array_equal(renderer.render(pose), expected)
        np.testing.assert_array_equal(renderer.pixels(pose, every), expected.reshape(-1))
        on_map += int(np.count_nonzero(expected != UNKNOWN))
    assert on_map > 60 * every.size * 0.2  # most poses saw the map


def test_render_and_pixels_refuse_a_pose_that_is_not_finite_or_a_pixel_off_the_image():
    renderer = SegmentationRenderer(PinholeCamera(), _grass_with_mud_square((15.0, 15.0), 1.0))
    for pose in (Pose(math.nan, 1.0, 0.0), Pose(1.0, math.inf, 0.0), Pose(1.0, 1.0, math.nan)):
        with pytest.raises(ValueError, match="finite"):
            renderer.render(pose)
        with pytest.raises(ValueError, match="finite"):
            renderer.pixels(pose, np.array([0]))
    for bad in (-1, 640 * 480):
        with pytest.raises(IndexError):
            renderer.pixels(Pose(10.0, 15.0, 0.0), np.array([5, bad]))


# --- rendering only the pixels a driver reads ------------------------------------------------


@pytest.mark.parametrize(
    "config",
    [CameraConfig(), CameraConfig(pitch_deg=45.0, hfov_deg=60.0, mount_height_m=0.8, width_px=320, height_px=200)],
    ids=["default", "p45-small"],
)
def test_pixels_equal_the_full_frame_at_random_poses(config):
    rng = np.random.default_rng(11)
    world = _blocks_world(rng)
    renderer = SegmentationRenderer(PinholeCamera(config), world)
    every = np.arange(config.width_px * config.height_px)
    for _ in range(20):
        # Poses on, near and off the map, so that clipping at the border is exercised too.
        pose = Pose(rng.uniform(-8.0, 48.0), rng.uniform(-8.0, 33.0), rng.uniform(-math.pi, math.pi))
        image = renderer.render(pose)
        np.testing.assert_array_equal(renderer.pixels(pose, every), image.reshape(-1))
        some = rng.integers(0, every.size, 700)
        np.testing.assert_array_equal(renderer.pixels(pose, some), image.reshape(-1)[some])


def test_view_renders_the_whole_frame_only_when_asked():
    world = _grass_with_mud_square((15.0, 15.0), 1.0)
    renderer = SegmentationRenderer(PinholeCamera(), world)
    pose = Pose(12.0, 15.0, 0.0)
    view = SegmentationView(renderer, pose)
    idx = np.array([0, 240 * 640 + 320, 479 * 640 + 639])
    assert view.pixels(idx)[0] == UNKNOWN and not view.rendered
    full = renderer.render(pose)
    np.testing.assert_array_equal(view.image, full)
    assert view.rendered and view.image is view.image  # rendered once, then kept
    np.testing.assert_array_equal(view.pixels(idx), full.reshape(-1)[idx])
    np.testing.assert_array_equal(SegmentationView.of(full).pixels(idx), full.reshape(-1)[idx])
    with pytest.raises(ValueError):
        SegmentationView(renderer)


def test_a_pixel_set_reads_as_its_indices_on_every_camera_and_view():
    """A PixelSet keeps its pixels' rows and columns for the camera it was first read with; read
    with another camera, it works them out again. Every view reads it as its index array."""
    rng = np.random.default_rng(8)
    world = _blocks_world(rng)
    small = CameraConfig(pitch_deg=45.0, hfov_deg=60.0, mount_height_m=0.8, width_px=320, height_px=200)
    index = rng.integers(0, 320 * 200, 900)  # pixels of both cameras, some above the horizon
    pixels = PixelSet(index)
    index[:] = 0  # the set keeps its own copy
    for config in (CameraConfig(), small, CameraConfig()):
        renderer = SegmentationRenderer(PinholeCamera(config), world)
        for _ in range(5):
            pose = Pose(rng.uniform(-8.0, 48.0), rng.uniform(-8.0, 33.0), rng.uniform(-math.pi, math.pi))
            full = renderer.render(pose).reshape(-1)
            want = full[pixels.flat]
            np.testing.assert_array_equal(renderer.pixels(pose, pixels), want)
            np.testing.assert_array_equal(SegmentationView(renderer, pose).pixels(pixels), want)
            np.testing.assert_array_equal(SegmentationView.of(full.reshape(renderer.shape)).pixels(pixels), want)
    assert pixels.shape == (900,) and not pixels.flat.flags.writeable
    renderer = SegmentationRenderer(PinholeCamera(small), world)
    with pytest.raises(IndexError):
        renderer.pixels(Pose(10.0, 15.0, 0.0), PixelSet(np.array([5, 320 * 200])))


def test_pixels_reads_a_changed_index_array_afresh():
    """An index array is read anew on every call (only a PixelSet keeps what it works out), so
    changing it between calls changes the answer, read-only or not."""
    rng = np.random.default_rng(5)
    renderer = SegmentationRenderer(PinholeCamera(), _blocks_world(rng))
    pose = Pose(20.0, 12.0, 0.4)
    full = renderer.render(pose).reshape(-1)
    idx = rng.integers(300 * 640, full.size, 400)
    np.testing.assert_array_equal(renderer.pixels(pose, idx), full[idx])
    idx[:] = rng.integers(300 * 640, full.size, 400)
    np.testing.assert_array_equal(renderer.pixels(pose, idx), full[idx])
    frozen = idx.copy()
    frozen.flags.writeable = False
    view = frozen[:200]  # read-only but not its own data
    np.testing.assert_array_equal(renderer.pixels(pose, frozen), full[frozen])
    np.testing.assert_array_equal(renderer.pixels(pose, view), full[view])
    np.testing.assert_array_equal(renderer.pixels(pose, frozen), full[frozen])


def test_camera_files_terrapref_and_ros_camera_info(tmp_path):
    from terrapref.camera.files import load_camera
    from terrapref.errors import UserError

    (tmp_path / "cam.yaml").write_text("width_px: 320\nheight_px: 240\nhfov_deg: 80\npitch_deg: 25\n")
    cam = load_camera(tmp_path / "cam.yaml")
    assert (cam.width_px, cam.pitch_deg, cam.hfov_deg) == (320, 25, 80)
    ros = """image_width: 640
image_height: 480
camera_name: front
camera_matrix: {rows: 3, cols: 3, data: [320.0, 0.0, 320.0, 0.0, 320.0, 240.0, 0.0, 0.0, 1.0]}
distortion_model: plumb_bob
distortion_coefficients: {rows: 1, cols: 5, data: [0.0, 0.0, 0.0, 0.0, 0.0]}
rectification_matrix: {rows: 3, cols: 3, data: [1, 0, 0, 0, 1, 0, 0, 0, 1]}
projection_matrix: {rows: 3, cols: 4, data: [320.0, 0.0, 320.0, 0.0, 0.0, 320.0, 240.0, 0.0, 0.0, 0.0, 1.0, 0.0]}
mount_height_m: 1.2
pitch_deg: 20.0
"""
    (tmp_path / "ros.yaml").write_text(ros)
    cam = load_camera(tmp_path / "ros.yaml")
    assert cam.intrinsics == (320.0, 320.0, 320.0, 240.0) and cam.mount_height_m == 1.2 and cam.pitch_deg == 20.0
    for text, field in (
        (ros.replace("data: [0.0, 0.0, 0.0, 0.0, 0.0]", "data: [0.1, 0.0, 0.0, 0.0, 0.0]"), "distortion_coefficients"),
        (ros.replace("image_width: 640", "image_width: -4"), "image_width"),
        (ros + "lens: wide\n", "lens"),
        ("width_px: 320\nzoom: 2\n", "zoom"),
        ("pitch_deg: .nan\n", "pitch_deg"),
    ):
        (tmp_path / "bad.yaml").write_text(text)
        with pytest.raises(UserError) as info:
            load_camera(tmp_path / "bad.yaml")
        assert any(str(tmp_path / "bad.yaml") in line and f"{field}:" in line for line in info.value.lines()), info.value.lines()
