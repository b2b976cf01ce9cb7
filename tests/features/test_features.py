"""Preference set S and utility features U (SPEC 6-7) against closed forms and hand-made images."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from terrapref.camera import PinholeCamera
from terrapref.features import DistanceMode, FeatureConfig, PreferenceSet, PreferenceSetConfig, UtilityFeaturizer
from terrapref.features.preference_set import forward_simulate
from terrapref.scenario.path import PathTracker, ReferencePath
from terrapref.terrain import UNKNOWN, default_classes
from terrapref.vehicle import ControlSet, Pose

CLASSES = default_classes()
GRASS = CLASSES.id_of("grass")
MUD = CLASSES.id_of("mud")
H, W = 480, 640
CX = 320  # principal point column [px]; pixel centres at +0.5, so u = 320.0 is column 320's left edge
FEATURE_NAMES = ("non_traversable", "water", "rock", "mud")


@pytest.fixture(scope="module")
def camera() -> PinholeCamera:
    return PinholeCamera()


@pytest.fixture(scope="module")
def featurizer(camera: PinholeCamera) -> UtilityFeaturizer:
    return UtilityFeaturizer(FeatureConfig(), camera, CLASSES)


def _straight_path() -> ReferencePath:
    """Along the world x axis, from 5 m behind the origin: a vehicle at the origin has progress 5 m."""
    return ReferencePath(np.array([[-5.0, 0.0], [30.0, 0.0]]))


S_ORIGIN = 5.0  # progress [m] of the origin along _straight_path()


def _to_world(points_v: np.ndarray, pose: Pose) -> np.ndarray:
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    x, y = points_v[..., 0], points_v[..., 1]
    return np.stack([pose.x + c * x - s * y, pose.y + s * x + c * y], axis=-1)


# --- S: forward simulation and its pixels (SPEC 6) ---------------------------------------------


def test_forward_simulate_matches_the_euler_recursion():
    v = np.array([1.0, 0.5, 2.0, 1.0])
    w = np.array([0.0, 0.7, -1.3, 1.0])
    n, dt = 6, 0.25
    traj = forward_simulate(v, w, n, dt)
    assert traj.shape == (4, n, 3)
    for i in range(len(v)):
        x = y = theta = 0.0  # the first point is the origin
        for t in range(n):
            np.testing.assert_allclose(traj[i, t], [x, y, theta], atol=1e-12, err_msg=f"trajectory {i}, point {t}")
            x, y, theta = x + v[i] * dt * math.cos(theta), y + v[i] * dt * math.sin(theta), theta + w[i] * dt


def test_forward_simulate_first_steps_in_closed_form():
    # One command (v = 1, w = 0.5, dt = 0.2): the Euler points written out by hand.
    traj = forward_simulate(np.array([1.0]), np.array([0.5]), 4, 0.2)[0]
    expected = [
        (0.0, 0.0, 0.0),
        (0.2, 0.0, 0.1),
        (0.2 + 0.2 * math.cos(0.1), 0.2 * math.sin(0.1), 0.2),
        (0.2 + 0.2 * math.cos(0.1) + 0.2 * math.cos(0.2), 0.2 * math.sin(0.1) + 0.2 * math.sin(0.2), 0.3),
    ]
    np.testing.assert_allclose(traj, expected, atol=1e-12)


def test_straight_trajectory_points_are_v_dt_apart():
    cfg = PreferenceSetConfig()
    pset = PreferenceSet(cfg, PinholeCamera())
    straight = pset.trajectories[cfg.control.w_rps.index(0.0)]
    step = cfg.control.v_mps * cfg.dt_s
    np.testing.assert_allclose(straight[0], [0.0, 0.0, 0.0])
    np.testing.assert_allclose(np.diff(straight[:, 0]), step, atol=1e-12)
    np.testing.assert_array_equal(straight[:, 1], 0.0)
    np.testing.assert_array_equal(straight[:, 2], 0.0)


def test_preference_set_shapes_and_symmetry(camera: PinholeCamera):
    pset = PreferenceSet(PreferenceSetConfig(), camera)
    assert pset.trajectories.shape == (21, 30, 3)
    assert pset.pixel_index.shape == (21, 30)
    assert pset.endpoints.shape == (21, 2)
    # w and -w mirror each other across the vehicle's x axis.
    np.testing.assert_allclose(pset.trajectories[::-1, :, 0], pset.trajectories[:, :, 0], atol=1e-12)
    np.testing.assert_allclose(pset.trajectories[::-1, :, 1], -pset.trajectories[:, :, 1], atol=1e-12)


def test_pixel_indices_agree_with_the_camera(camera: PinholeCamera):
    pset = PreferenceSet(PreferenceSetConfig(), camera)
    np.testing.assert_array_equal(pset.pixel_index, camera.pixel_indices(pset.trajectories[..., :2]))
    assert pset.pixel_index.min() >= -1 and pset.pixel_index.max() < H * W


def test_straight_trajectory_pixels_in_closed_form(camera: PinholeCamera):
    # A ground point x metres straight ahead is seen atan(1/x) below the horizontal, i.e.
    # atan(1/x) - 30 deg below the optical axis: row cy + fy tan(that), on the centre column.
    cfg = PreferenceSetConfig()
    pset = PreferenceSet(cfg, camera)
    k = cfg.control.w_rps.index(0.0)
    for j, x in enumerate(pset.trajectories[k, :, 0]):
        row = 240.0 + 320.0 * math.tan(math.atan2(1.0, x) - math.radians(30.0)) if x > 0 else math.inf
        expected = int(math.floor(row)) * W + CX if row < H else -1
        assert pset.pixel_index[k, j] == expected, f"point {j} at x = {x:.2f} m"
    # The bottom edge sees the ground ~0.43 m ahead: the points at 0, 0.2 and 0.4 m are unseen.
    assert list(pset.pixel_index[k, :4] >= 0) == [False, False, False, True]


# --- terrain utilities (SPEC 7) -----------------------------------------------------------------


@pytest.mark.parametrize("name", [*FEATURE_NAMES, "grass", "unknown"])
def test_uniform_image_gives_the_visible_fraction_in_its_own_column_only(featurizer: UtilityFeaturizer, name: str):
    class_id = UNKNOWN if name == "unknown" else CLASSES.id_of(name)
    image = np.full((H, W), class_id, dtype=np.uint8)
    u = featurizer(image, Pose(0.0, 0.0, 0.0), _straight_path(), S_ORIGIN)
    visible = (featurizer.pset.pixel_index >= 0).mean(axis=1)
    for col, feature in enumerate(FEATURE_NAMES):
        want = visible if feature == name else np.zeros(21)
        np.testing.assert_allclose(u[:, col], want, atol=1e-6, err_msg=f"image of {name}, column {feature}")


def test_all_mud_shares_are_below_one_where_points_leave_the_image(featurizer: UtilityFeaturizer):
    image = np.full((H, W), MUD, dtype=np.uint8)
    mud = featurizer.terrain(image)[:, FEATURE_NAMES.index("mud")]
    # The first point (the origin) is under the camera, out of view, on every trajectory.
    assert np.all(mud < 1.0)
    assert np.all(featurizer.pset.pixel_index[:, 0] == -1)
    # The tightest arcs curl out of the view: most of their points count for no class.
    w = np.asarray(featurizer.config.preference.control.w_rps)
    straight, tight = mud[w == 0.0][0], mud[np.abs(w) == 1.0]
    assert np.all(tight < 0.5 * straight), (tight, straight)
    np.testing.assert_allclose(mud, featurizer.pset.visible_fraction())


def test_out_of_view_points_do_not_read_any_pixel(featurizer: UtilityFeaturizer):
    # Mud only in the first and the last pixel: an unseen point read as pixel 0 (or, by
    # negative indexing, as pixel -1) would count it.
    pix = featurizer.pset.pixel_index
    assert not np.isin(pix[pix >= 0], [0, H * W - 1]).any()  # no point really projects there
    image = np.full((H, W), GRASS, dtype=np.uint8)
    image[0, 0] = image[-1, -1] = MUD
    np.testing.assert_array_equal(featurizer.terrain(image), 0.0)


def test_mud_on_the_left_half_raises_mud_only_for_left_turns(featurizer: UtilityFeaturizer):
    image = np.full((H, W), GRASS, dtype=np.uint8)
    image[:, :CX] = MUD  # columns 0..319: everything left of the optical axis
    u = featurizer(image, Pose(0.0, 0.0, 0.0), _straight_path(), S_ORIGIN)
    mud = u[:, FEATURE_NAMES.index("mud")]
    pix = featurizer.pset.pixel_index
    visible = pix >= 0
    col = np.where(visible, pix % W, -1)
    w = np.asarray(featurizer.config.preference.control.w_rps)
    # Geometry: a left turn's points lie left of the vehicle (y > 0), so left of the image centre.
    assert np.all(col[w > 0][visible[w > 0]] < CX)
    assert np.all(col[w < 0][visible[w < 0]] >= CX)
    # The straight trajectory projects onto u = cx exactly, i.e. column 320 (not mud).
    straight = w == 0.0
    assert np.all(col[straight][visible[straight]] == CX)
    expected = (visible & (col < CX)).mean(axis=1)
    np.testing.assert_allclose(mud, expected, atol=1e-6)
    np.testing.assert_allclose(mud[w > 0], featurizer.pset.visible_fraction()[w > 0], atol=1e-6)
    np.testing.assert_array_equal(mud[w <= 0], 0.0)
    assert np.all(mud[w > 0] > 0)
    np.testing.assert_array_equal(u[:, :3], 0.0)


def test_features_are_float32_m_by_5(featurizer: UtilityFeaturizer):
    rng = np.random.default_rng(3)
    image = rng.choice(np.array([0, 1, 2, 3, 4, 255], dtype=np.uint8), size=(H, W))
    u = featurizer(image, Pose(2.0, -1.0, 0.3), _straight_path(), 1.0)
    assert u.shape == (21, 5)
    assert u.dtype == np.float32
    assert np.all((u >= 0) & (u <= 1))
    assert FeatureConfig().column_names == (*FEATURE_NAMES, "distance")
    assert np.all(u[:, :4].sum(axis=1) <= featurizer.pset.visible_fraction() + 1e-6)


# --- distance utility (SPEC 7) ------------------------------------------------------------------


def test_normalise_in_closed_form():
    np.testing.assert_allclose(UtilityFeaturizer.normalise(np.array([1.0, 2.0, 3.0, 1.5])), [1.0, 0.5, 0.0, 0.75])
    np.testing.assert_array_equal(UtilityFeaturizer.normalise(np.full(21, 2.7)), np.ones(21))
    np.testing.assert_array_equal(UtilityFeaturizer.normalise(np.array([4.0, 4.0 + 1e-12, 4.0])), np.ones(3))


@pytest.mark.parametrize("mode", list(DistanceMode))
def test_equal_distances_give_u5_all_ones(camera: PinholeCamera, mode: DistanceMode):
    # Two mirror-image arcs about a straight path through the vehicle end equally far from it.
    control = ControlSet(1.0, (-0.5, 0.5))
    feat = UtilityFeaturizer(FeatureConfig(PreferenceSetConfig(control), distance_mode=mode), camera, CLASSES)
    path = _straight_path()
    d = feat.distances(Pose(0.0, 0.0, 0.0), path, S_ORIGIN)
    assert d[0] == pytest.approx(d[1], abs=1e-12)
    assert d[0] > 0.5  # the arcs really are off the path: equal, not zero
    u = feat(np.zeros((H, W), np.uint8), Pose(0.0, 0.0, 0.0), path, S_ORIGIN)
    np.testing.assert_array_equal(u[:, -1], 1.0)


def test_u5_ranks_by_distance_from_1_to_0(featurizer: UtilityFeaturizer):
    u = featurizer(np.zeros((H, W), np.uint8), Pose(0.0, 0.0, 0.0), _straight_path(), S_ORIGIN)
    u5 = u[:, -1]
    w = np.asarray(featurizer.config.preference.control.w_rps)
    assert u5.max() == pytest.approx(1.0) and u5.min() == pytest.approx(0.0)
    assert int(np.argmax(u5)) == int(np.flatnonzero(w == 0.0)[0])  # on a straight path, straight on


# A loop course seen from its start: 3 m ahead the path turns right, runs a big loop, and its
# final leg comes back along the vehicle's x axis from behind, ending at the start.
LOOP_V = np.array([[0.0, 0.0], [3.0, 0.0], [3.0, -14.0], [-15.0, -14.0], [-15.0, 0.0], [0.0, 0.0]])
LOOP_POSE = Pose(10.0, 5.0, 0.7)  # anywhere: the features live in the vehicle frame


def _loop_featurizer(camera: PinholeCamera, mode: DistanceMode) -> UtilityFeaturizer:
    return UtilityFeaturizer(FeatureConfig(distance_mode=mode, path_spacing_m=0.05), camera, CLASSES)


def _loop_progress(path: ReferencePath) -> float:
    return PathTracker(path).update(np.array(LOOP_POSE[:2]))


def test_paper_distance_is_captured_by_the_returning_leg(camera: PinholeCamera):
    feat = _loop_featurizer(camera, DistanceMode.PAPER)
    path = ReferencePath(_to_world(LOOP_V, LOOP_POSE))
    d = feat.distances(LOOP_POSE, path, None)
    ends = feat.pset.endpoints
    # Closed form: distance from each endpoint to the whole polyline (up to the resampling).
    np.testing.assert_allclose(d, ReferencePath(LOOP_V).distance_to(ends), atol=0.025 + 1e-9)
    w = np.asarray(feat.config.preference.control.w_rps)
    tight = np.abs(w) == 1.0
    # The tight arcs end just behind the vehicle, 0.16 m from the final leg: they score best.
    np.testing.assert_allclose(d[tight], np.abs(ends[tight, 1]), atol=0.025 + 1e-9)
    u5 = feat(np.zeros((H, W), np.uint8), LOOP_POSE, path, None)[:, -1]
    assert set(np.flatnonzero(u5 >= u5.max() - 1e-6)) <= set(np.flatnonzero(tight))
    assert np.all(u5[tight] > u5[~tight].max())


def test_window_distance_ignores_the_returning_leg(camera: PinholeCamera):
    feat = _loop_featurizer(camera, DistanceMode.WINDOW)
    path = ReferencePath(_to_world(LOOP_V, LOOP_POSE))
    s = _loop_progress(path)
    assert s == pytest.approx(0.0, abs=1e-9)  # the tracker starts at the path's start, not its end
    d = feat.distances(LOOP_POSE, path, s)
    window = feat.config.effective_window_m
    assert window == pytest.approx(11.6)  # twice the 5.8 m travel to a trajectory's last point
    # Closed form: only the path from s to s + 11.6 m, i.e. 3 m ahead then 8.6 m to the right.
    ahead = ReferencePath(np.array([[0.0, 0.0], [3.0, 0.0], [3.0, -8.6]]))
    ends = feat.pset.endpoints
    np.testing.assert_allclose(d, ahead.distance_to(ends), atol=0.025 + 1e-9)
    w = np.asarray(feat.config.preference.control.w_rps)
    tight = np.abs(w) == 1.0
    np.testing.assert_allclose(d[tight], np.linalg.norm(ends[tight], axis=1), atol=1e-9)  # nearest: the start
    u5 = feat(np.zeros((H, W), np.uint8), LOOP_POSE, path, s)[:, -1]
    best = int(np.argmax(u5))
    assert w[best] < 0 and abs(w[best]) < 1.0, f"best w = {w[best]}: a right turn, not a tight curl"


def test_lookahead_distance_ignores_the_returning_leg(camera: PinholeCamera):
    feat = _loop_featurizer(camera, DistanceMode.PROGRESS)
    path = ReferencePath(_to_world(LOOP_V, LOOP_POSE))
    s = _loop_progress(path)
    d = feat.distances(LOOP_POSE, path, s)
    # Closed form: the look-ahead point 5.8 m along the path (29 steps of 0.2 m) is (3, -2.8).
    assert feat.config.preference.horizon_m == pytest.approx(5.8)
    ends = feat.pset.endpoints
    np.testing.assert_allclose(d, np.hypot(ends[:, 0] - 3.0, ends[:, 1] + 2.8), atol=1e-9)
    w = np.asarray(feat.config.preference.control.w_rps)
    u5 = feat(np.zeros((H, W), np.uint8), LOOP_POSE, path, s)[:, -1]
    best = int(np.argmax(u5))
    assert w[best] == pytest.approx(w[int(np.argmin(np.hypot(ends[:, 0] - 3.0, ends[:, 1] + 2.8)))])  # the endpoint nearest (3, -2.8)
    assert w[best] == pytest.approx(-0.3)
    assert np.all(u5[np.abs(w) == 1.0] < 0.5)


def test_window_and_lookahead_need_a_progress(camera: PinholeCamera):
    for mode in (DistanceMode.WINDOW, DistanceMode.PROGRESS):
        feat = UtilityFeaturizer(FeatureConfig(distance_mode=mode), camera, CLASSES)
        with pytest.raises(ValueError):
            feat.distances(Pose(0.0, 0.0, 0.0), _straight_path(), None)


def test_lookahead_point_is_where_a_perfect_follower_ends(featurizer: UtilityFeaturizer):
    cfg = featurizer.config.preference
    straight = featurizer.pset.trajectories[cfg.control.w_rps.index(0.0)]
    travelled = float(np.linalg.norm(np.diff(straight[:, :2], axis=0), axis=1).sum())
    assert cfg.horizon_m == pytest.approx(travelled)
    d = featurizer.distances(Pose(0.0, 0.0, 0.0), _straight_path(), 5.0)
    assert d[cfg.control.w_rps.index(0.0)] == pytest.approx(0.0, abs=1e-9)


# --- configuration ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    "config",
    [
        FeatureConfig(),
        FeatureConfig(
            PreferenceSetConfig(ControlSet.uniform(11, 0.8, 0.6), n_steps=45, dt_s=0.1),
            distance_mode=DistanceMode.WINDOW,
            window_m=9.5,
            path_spacing_m=0.1,
        ),
        FeatureConfig(distance_mode=DistanceMode.PAPER, feature_classes=("mud", "rock")),
    ],
)
def test_feature_config_round_trip(config: FeatureConfig):
    data = json.loads(json.dumps(config.to_dict()))  # it must survive a JSON file too
    back = FeatureConfig.from_dict(data)
    assert back == config
    assert back.to_dict() == config.to_dict()


def test_distance_mode_accepts_its_string_value():
    assert FeatureConfig(distance_mode="paper").distance_mode is DistanceMode.PAPER  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        FeatureConfig(distance_mode="nearest")  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        FeatureConfig(path_spacing_m=0.0)
    with pytest.raises(ValueError):
        PreferenceSetConfig(n_steps=0)


# --- lanes (removed) ----------------------------------------------------------------------------


def test_a_file_with_lane_columns_is_refused_and_one_without_loads():
    """Lanes beyond the trajectories' ends left the code; files that recorded lane_m 0 still load."""
    plain = FeatureConfig().to_dict()
    assert FeatureConfig.from_dict({**plain, "lane_m": 0.0, "lane_points": 12}) == FeatureConfig()
    with pytest.raises(ValueError, match="lane columns .* no longer supported"):
        FeatureConfig.from_dict({**plain, "lane_m": 6.0, "lane_points": 12})


# --- the compiled per-frame loops against their NumPy forms -------------------------------------


def test_compiled_features_give_the_numpy_forms_bits(featurizer: UtilityFeaturizer):
    """terrapref.features.utility_compiled: the same bits as the NumPy forms the featurizer used before."""
    rng = np.random.default_rng(4)
    pix = featurizer.pset.pixel_index
    m, n = pix.shape
    k = featurizer.config.n_terrain
    offset = np.where(pix.ravel() >= 0, np.repeat(np.arange(m), n), m) * (k + 1)
    path = ReferencePath(np.array([[0.0, 0.0], [30.0, 4.0], [60.0, -5.0]]))
    for _ in range(40):
        image = rng.integers(0, 6, (480, 640)).astype(np.uint8)
        image[rng.random((480, 640)) < 0.1] = UNKNOWN
        ids = image.reshape(-1)[featurizer._pix_flat]
        expected = np.bincount(featurizer.class_columns[ids] + offset, minlength=(m + 1) * (k + 1)).reshape(m + 1, k + 1)[:-1, :k] * (
            1.0 / n
        )
        np.testing.assert_array_equal(featurizer.terrain(image), expected)
        pose = Pose(rng.uniform(0, 60), rng.uniform(-5, 5), rng.uniform(-math.pi, math.pi))
        s = float(rng.uniform(0, 60))
        ends = featurizer.pset.endpoints
        c, sn = math.cos(pose.yaw), math.sin(pose.yaw)
        tx, ty = path.point_at(s + featurizer.config.preference.horizon_m)
        d = np.hypot(ends[:, 0] * c - ends[:, 1] * sn + (pose.x - tx), ends[:, 0] * sn + ends[:, 1] * c + (pose.y - ty))
        got = featurizer.distances(pose, path, s)
        assert np.array_equal(got.view(np.int64), d.view(np.int64))
        norm = (d.max() - d) * (1.0 / (d.max() - d.min()))
        assert np.array_equal(featurizer.normalise(d).view(np.int64), norm.view(np.int64))
        # The whole U in one call: the same float32 values as assembling it from the parts.
        U = np.empty((m, k + 1), np.float32)
        U[:, :-1], U[:, -1] = expected, norm
        assert np.array_equal(featurizer(image, pose, path, s).view(np.int32), U.view(np.int32))
    assert (featurizer.normalise(np.full((2, 3), 4.0)) == 1.0).all()


@pytest.mark.parametrize("n", [1, 5, 7, 8, 9, 15, 16, 30, 128])
def test_numpy_sum_adds_in_numpys_order(n: int):
    from terrapref.sums import numpy_sum

    rng = np.random.default_rng(n)
    # Terms over many magnitudes, so that another order would round differently somewhere.
    x = rng.standard_normal((3000, n)) * 10.0 ** rng.integers(-6, 6, (3000, n))
    got = np.array([numpy_sum(row) for row in x])
    assert np.array_equal(got.view(np.int64), x.sum(axis=1).view(np.int64))


def test_numpy_sum_refuses_more_terms_than_it_can_follow():
    from terrapref.sums import numpy_sum

    with pytest.raises(ValueError):
        numpy_sum(np.ones(129))


def test_the_progress_distance_mode_reads_its_older_name():
    """``lookahead``, the mode's name in files and flags before "look-ahead" was the second stage's alone."""
    assert FeatureConfig(distance_mode="lookahead").distance_mode is DistanceMode.PROGRESS  # type: ignore[arg-type]
    assert FeatureConfig.from_dict({**FeatureConfig().to_dict(), "distance_mode": "lookahead"}) == FeatureConfig()
