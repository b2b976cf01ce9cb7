"""The offset rule (terrapref.rules.offset): its offsets' features, ground map, fit and decision, on
tiny scenarios with closed-form answers."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cpu_settings import SETTINGS, CpuCheck
from helpers import TESTS, model_meta, skip_path_weights
from terrapref.camera import PinholeCamera, SegmentationRenderer, SegmentationView
from terrapref.dataset import FORMAT as DATASET_FORMAT
from terrapref.dataset import Dataset, load_dataset, save_dataset
from terrapref.errors import UserError
from terrapref.features import FeatureConfig, UtilityFeaturizer
from terrapref.groundmap.columns import TerrainColumns
from terrapref.groundmap.map import GroundMap
from terrapref.groundmap.settings import MapSettings
from terrapref.learning.model_file import load_model, save_model
from terrapref.learning.network import ClassifierConfig
from terrapref.planner import Planner
from terrapref.planner.registry import load_policy
from terrapref.rules.offset import fit as offset_fit
from terrapref.rules.offset.features import RELIEF_BANDS_DEG, OffsetFeatures, OffsetView, gated
from terrapref.rules.offset.fit import OffsetUtility, fit_offset_utility, fit_softmax, soft_labels
from terrapref.rules.offset.geometry import OffsetGeometry
from terrapref.rules.offset.rule import OffsetConfig, OffsetSteering, hidden_prices
from terrapref.rules.offset.steering import intent_offsets, steer
from terrapref.scenario import parse_scenario
from terrapref.scenario.path import ReferencePath
from terrapref.terrain import default_classes
from terrapref.vehicle import Command, integrate_unicycle

CONTROL = FeatureConfig().preference.control  # the default control set: 1 m/s

K = len(default_classes().feature_names)  # columns: non_traversable, water, rock, mud
# The synthetic driver's own costs relative to its detour price (per metre 1, 1.5, 2.25 by rank
# for mud > rock > water, 30 for non_traversable, 0.08 per m^2 per metre of detour), scaled.
DRIVER_LIKE = np.array([-25.5, -1.9125, -1.275, -0.85, 0.0, -0.068, -1.3])


def _scenario(terrain: list[dict]):
    return parse_scenario(
        {
            "format": "terrapref-scenario/1",
            "name": "corridor_test",
            "world": {"size_m": [40.0, 20.0], "resolution_m": 0.05, "background": "grass"},
            "terrain": terrain,
            "path": {"waypoints": [[2.0, 10.0], [38.0, 10.0]]},
        }
    )


MUD = {"class": "mud", "rectangle": {"center": [12.1, 10.0], "size": [3.0, 2.0]}}  # 8.6-11.6 m along the path, 1 m each side
TREES = {"class": "non_traversable", "rectangle": {"center": [14.1, 10.2], "size": [2.0, 2.2]}}


@pytest.fixture(scope="module")
def camera() -> PinholeCamera:
    return PinholeCamera()


def _columns() -> np.ndarray:
    return UtilityFeaturizer(FeatureConfig(), PinholeCamera()).class_columns


def _terrain(lethal: tuple[int, ...] = (), names: tuple[str, ...] = ()) -> TerrainColumns:
    return TerrainColumns(_columns(), K, lethal, names)


def _map_of(stage: OffsetSteering, camera: PinholeCamera) -> GroundMap:
    """The ground map a planner keeps for ``stage``: its settings, with its lethal columns."""
    return GroundMap(camera, _terrain(tuple(int(c) for c in np.flatnonzero(stage.lethal[:K]))), stage.map_settings)


def _steer(stage: OffsetSteering, gmap: GroundMap, view: SegmentationView, pose, path, s: float, speed_mps: float | None = None) -> float:
    """One frame as the planner gives it to ``stage``: ``gmap`` gathers ``view``, then the rule steers."""
    gmap.update(view, pose)
    return stage.yaw_rate(gmap, pose, path, s, speed_mps)


def _seen_from(scenario, camera: PinholeCamera, pose) -> SegmentationView:
    from terrapref.world import rasterise

    return SegmentationView.of(SegmentationRenderer(camera, rasterise(scenario)).render(pose))


def test_offsets_and_stations_are_symmetric_grids():
    c = OffsetGeometry()
    assert len(c.offsets) == 31 and c.offsets[15] == 0.0
    np.testing.assert_allclose(c.offsets, -c.offsets[::-1])
    assert c.stations[0] == -1.0 and c.stations[-1] == 11.0 and len(c.stations) == 49
    assert OffsetGeometry.from_dict(c.to_dict()) == c
    with pytest.raises(ValueError):
        OffsetGeometry(offset_step_m=0.0)
    with pytest.raises(ValueError):
        OffsetGeometry(stations_m=(5.0, 1.0))


def test_a_patch_ahead_on_the_path_is_metres_on_its_class_and_sets_the_near_distance(camera):
    scenario = _scenario([MUD])
    gmap = GroundMap(camera, _terrain())
    gmap.update(_seen_from(scenario, camera, (2.0, 10.0, 0.0)), (2.0, 10.0, 0.0))
    corridor = OffsetFeatures(OffsetGeometry(), K)
    view = corridor(gmap, ReferencePath(scenario.waypoints), 0.0)
    offsets = corridor.offsets
    mud = view.features[:, 3]
    centre = int(np.argmin(np.abs(offsets)))
    # Stations 8.75 ... 11.0 lie on the mud (the corridor ends 11 m ahead): 10 x 0.25 m.
    assert mud[centre] == pytest.approx(2.5, abs=0.3)
    assert view.near_m == pytest.approx(8.75, abs=0.3)
    # 1.4 m aside or more, the 1.2 m footprint is off the 2 m wide patch.
    assert (mud[np.abs(offsets) >= 1.6 + 1e-9] == 0).all()
    # The detour's price: d^2 * (on-path length + 5 m).
    on_path = view.features[centre + 5, 5] / offsets[centre + 5] ** 2 - 5.0
    assert on_path == pytest.approx(2.5, abs=0.3)
    # Behind the camera nothing has been seen: the first metres of every offset are unseen.
    assert (view.features[:, 4] >= 1.0).all()
    gate = gated(view, offsets, near_m=5.0)
    assert (gate[:, -1] == offsets**2).all()  # nothing on the path within 5 m
    assert (gated(view, offsets, near_m=10.0)[:, -1] == 0).all()


def test_the_ground_map_keeps_the_world_fixed_when_it_recentres(camera):
    scenario = _scenario([MUD])
    gmap = GroundMap(camera, _terrain())
    gmap.update(_seen_from(scenario, camera, (2.0, 10.0, 0.0)), (2.0, 10.0, 0.0))
    points = np.stack(np.meshgrid(np.arange(0.0, 20.0, 0.07), np.arange(5.0, 15.0, 0.07)), axis=-1)
    before = gmap.lookup(points)
    origin = gmap.origin.copy()
    gmap.update(SegmentationView.of(np.full(camera.shape, 255, np.uint8)), (20.0, 9.0, 0.0))  # far enough to recentre; sees nothing
    assert not np.allclose(gmap.origin, origin)
    after = gmap.lookup(points)
    kept = after != K + 1
    assert (after[kept] == before[kept]).all() and kept.sum() > 0.5 * (before != K + 1).sum()


def _noisy_views(scenario, camera: PinholeCamera, pose, errors, frames: int, seed: int = 0):
    """``frames`` views of ``scenario`` from ``pose``, each with its own draw of the label errors ``errors``."""
    from terrapref.perception import LabelErrors
    from terrapref.perception.labels import LabelledView, LabelNoise
    from terrapref.world import rasterise

    renderer = SegmentationRenderer(camera, rasterise(scenario))
    noise = LabelNoise(LabelErrors(**errors), camera, scenario.classes)
    rng = np.random.default_rng(seed)
    noise.reset(rng)
    return [LabelledView(SegmentationView(renderer, pose), noise.draw(rng, k)) for k in range(frames)]


def test_the_ground_map_outvotes_labels_a_few_frames_get_wrong(camera):
    """With 20% of pixels flipped in every frame (a fifth of them to trees), a map of the last view
    shows trees all over; the votes of thirty frames show the mud where it is and no tree at all."""
    scenario = _scenario([MUD])
    pose = (2.0, 10.0, 0.0)
    truth = GroundMap(camera, _terrain((0,)))
    truth.update(_seen_from(scenario, camera, pose), pose)
    voted = GroundMap(camera, _terrain((0,)))
    for view in _noisy_views(scenario, camera, pose, {"flip_rate": 0.2}, 30):
        voted.update(view, pose)
    last = GroundMap(camera, _terrain((0,)), MapSettings(map_fade=0.0))
    last.update(view, pose)
    seen = truth.cells != K + 1
    assert (voted.cells[seen] == truth.cells[seen]).mean() > 0.999
    assert (voted.cells == 0).sum() == 0  # not one cell of phantom trees
    assert (last.cells[seen] == 0).mean() > 0.02  # the last view alone: trees everywhere


def test_a_lethal_share_of_the_evidence_makes_a_cell_lethal(camera):
    """Trees seen in 40% of the frames are lethal at a lethal share of 0.35, not at 0.5; mud seen as
    often (and grass the rest) is terrain at a terrain share of 0.35, and grass at 0.5."""
    pose = (2.0, 10.0, 0.0)
    views = {
        c: _seen_from(_scenario([{"class": c, "rectangle": {"center": [12.1, 10.0], "size": [3.0, 2.0]}}]), camera, pose)
        for c in ("non_traversable", "mud")
    }
    plain = _seen_from(_scenario([]), camera, pose)
    centre = np.array([[12.1, 10.0]])
    for patch, share, expect in (
        ("non_traversable", dict(map_lethal_share=0.35), 0),
        ("non_traversable", dict(map_lethal_share=0.5), K),
        ("mud", dict(map_terrain_share=0.35), 3),
        ("mud", dict(map_terrain_share=0.5), K),
    ):
        gmap = GroundMap(camera, _terrain((0,)), MapSettings(map_fade=1.0, **share))
        for k in range(10):
            view = views[patch] if k % 5 in (1, 3) else plain
            gmap.update(view, pose)
        assert gmap.lookup(centre)[0] == expect, (patch, share)


def test_the_ground_map_waits_for_enough_evidence_before_a_cell_counts_as_seen(camera):
    scenario = _scenario([MUD])
    pose = (2.0, 10.0, 0.0)
    view = _seen_from(scenario, camera, pose)
    gmap = GroundMap(camera, _terrain(), MapSettings(map_min_evidence=0.5))
    gmap.update(view, pose)
    near, far = np.array([[4.0, 10.0]]), np.array([[14.5, 10.0]])  # 2 m ahead: a vote of 0.8; 12.5 m: 0.09
    assert gmap.lookup(near)[0] == K and gmap.lookup(far)[0] == K + 1
    for _ in range(6):
        gmap.update(view, pose)
    assert gmap.lookup(far)[0] == K


def test_steering_toward_an_offset_is_pure_pursuit():
    path = ReferencePath(np.array([[0.0, 0.0], [30.0, 0.0]]))
    w = steer(path, (0.0, 0.0, 0.0), 0.0, np.array([0.0, 1.0, -1.0]), 2.5, 1.0)
    # Target 2.5 m ahead, 1 m aside: w = 2 v sin(alpha) / L = 2 * 1 / L^2 with L^2 = 7.25.
    np.testing.assert_allclose(w, [0.0, 2.0 / 7.25, -2.0 / 7.25])


def test_the_intended_offset_inverts_pure_pursuit():
    path = ReferencePath(np.array([[0.0, 0.0], [30.0, 0.0]]))
    offsets = OffsetGeometry().offsets
    # Heading 0.2 rad to the left at 0.3 m: straight ahead, 2.5 m on, is 0.3 + 2.5 tan(0.2) = 0.807 m.
    poses = np.array([[5.0, 0.0, 0.0], [6.0, 0.3, 0.2], [7.0, 0.0, 0.0]])
    w = steer(path, tuple(poses[0]), 5.0, 1.2, 2.5, 1.0)
    later = np.array([[1.0, float(w)], [1.0, 0.0], [np.nan, np.nan]])
    intent = intent_offsets(poses, later, np.array([5.0, 6.0, 7.0]), path, offsets, 2.5)
    assert intent[0] == pytest.approx(1.2)
    assert intent[1] == pytest.approx(0.8)  # the stick at rest: the offset it is heading for, not where it is
    assert np.isnan(intent[2])


def test_the_softmax_fit_recovers_the_weights_that_made_the_labels():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(4000, 9, 3))
    truth = np.array([1.5, -0.7, 0.3])
    z = X @ truth
    Y = np.exp(z - z.max(axis=1, keepdims=True))
    Y /= Y.sum(axis=1, keepdims=True)
    theta, _ = fit_softmax(X, Y, l2=0.0)
    np.testing.assert_allclose(theta, truth, atol=1e-6)


def test_the_offset_fit_picks_the_near_distance_that_explains_the_labels():
    """Frames where the driver keeps to the path while a patch is far and swerves once it is near."""
    rng = np.random.default_rng(1)
    c = OffsetGeometry()
    offsets = c.offsets
    n = 600
    near = rng.uniform(1.0, 10.0, n)
    features = np.zeros((n, len(offsets), K + 2))
    features[:, :, 3] = np.where(np.abs(offsets) < 1.0, 2.0, 0.0)  # 2 m of mud near the path, on every frame
    features[:, :, 5] = offsets**2 * 7.0
    intent = np.where(near > 4.0, 0.0, 1.4 * rng.choice([-1.0, 1.0], n))
    fit = fit_offset_utility(features, near, intent, offsets)
    assert fit.near_m == 4.0 and fit.samples == n
    assert fit.weights[3] < 0 and fit.weights[-1] < 0  # mud costs; far from a patch, so does leaving the path
    assert soft_labels(np.array([0.0]), offsets, 0.3).sum() == pytest.approx(1.0)
    with pytest.raises(ValueError):
        fit_offset_utility(features, near, np.full(n, np.nan), offsets)


def test_on_relief_the_near_distance_is_chosen_on_frames_with_nothing_steep_on_the_path(monkeypatch):
    """A driver that leaves the path 4 m before a mud patch, and six times as many frames before
    slopes: in the frames a fit reads, ground past the first relief band is a patch on the path,
    and the near distance is measured to the slope's gentle foot, 2.5 m short of the part the
    driver goes round. Read on every frame, those frames say the driver reacts at 2.5 m."""
    rng = np.random.default_rng(1)
    offsets = OffsetGeometry().offsets
    n, m = 200, 6
    near = rng.uniform(1.0, 10.0, (m + 1) * n)
    features = np.zeros(((m + 1) * n, len(offsets), K + 2))
    features[:n, :, 3] = np.where(np.abs(offsets) < 1.0, 2.0, 0.0)  # mud near the path
    features[:, :, 5] = offsets**2 * 7.0
    swerve = 1.4 * rng.choice([-1.0, 1.0], (m + 1) * n)
    intent = np.where(near > np.repeat([4.0, 2.5], [n, m * n]), 0.0, swerve)
    bands = (4.0, 8.0)
    relief = np.zeros(((m + 1) * n, len(offsets), 2 * len(bands)))
    relief[n:, :, :2] = np.where(np.abs(offsets) < 1.0, 2.0, 0.0)[:, None]  # 2 m past 4 and 8 deg of side slope
    fit = fit_offset_utility(features, near, intent, offsets, relief=(relief, bands))
    assert fit.near_m == 4.0 and min(fit.losses, key=fit.losses.get) == 4.0 and fit.samples == (m + 1) * n
    assert fit.relief[0] + fit.relief[1] < 0  # the slope's price is still fitted on every frame
    # With fewer level frames than it takes to choose on, every frame is read, and the slopes' frames choose.
    monkeypatch.setattr(offset_fit, "LEVEL_FRAMES_LEAST", n + 1)
    assert fit_offset_utility(features, near, intent, offsets, relief=(relief, bands)).near_m == 2.5


def _relief_drive(rng: np.random.Generator, n: int) -> tuple[np.ndarray, ...]:
    """Frames of a driver that goes round mud near the path (the first ``n``, no relief in view)
    and, as many again, along a slope with mud at the footprint's edge: the features, near
    distances, intended offsets and relief columns (2 m past each of two bands near the path)."""
    offsets = OffsetGeometry().offsets
    near = rng.uniform(1.0, 10.0, 2 * n)
    features = np.zeros((2 * n, len(offsets), K + 2))
    features[:, :, 3] = np.where(np.abs(offsets) < 1.0, 2.0, 0.0)  # mud near the path
    features[:, :, 5] = offsets**2 * 7.0
    intent = np.where(near > 4.0, 0.0, 1.4 * rng.choice([-1.0, 1.0], 2 * n))
    relief = np.zeros((2 * n, len(offsets), 4))
    relief[n:, :, :2] = np.where(np.abs(offsets) < 1.5, 2.0, 0.0)[:, None]
    return features, near, intent, relief


def test_on_relief_the_terrain_is_priced_on_the_frames_with_no_relief_in_view(monkeypatch):
    """The frames with relief in view may show the terrain otherwise (a line held along a slope,
    the vehicle wandering onto the patch at its edge): the terrain's weights come from the other
    frames alone, the same whatever the driver did on the slopes; the relief's from every frame."""
    offsets, bands = OffsetGeometry().offsets, (4.0, 8.0)
    features, near, intent, relief = _relief_drive(np.random.default_rng(3), 300)
    fit = fit_offset_utility(features, near, intent, offsets, relief=(relief, bands))
    wandering = intent.copy()
    wandering[300:] = 0.4  # on the slopes, a few tenths of a metre onto the mud whatever is near
    moved = fit_offset_utility(features, near, wandering, offsets, relief=(relief, bands))
    terrain = [0, 1, 2, 3, 5, 6]  # the classes, the detour and the gate (4: ground never seen, priced with relief)
    assert fit.near_m == moved.near_m == 4.0
    np.testing.assert_array_equal(moved.weights[terrain], fit.weights[terrain])
    assert fit.weights[3] < 0 and not np.array_equal(moved.relief, fit.relief)
    assert fit.relief_interval is not None and (fit.relief_interval[:, 0] <= fit.relief_interval[:, 1]).all()
    # With fewer such frames than it takes, every weight is fitted on every frame, and the slopes' frames move the mud's price.
    monkeypatch.setattr(offset_fit, "FLAT_FRAMES_LEAST", 301)
    joint = fit_offset_utility(features, near, intent, offsets, relief=(relief, bands))
    joint_moved = fit_offset_utility(features, near, wandering, offsets, relief=(relief, bands))
    assert joint_moved.weights[3] / joint_moved.weights[5] < 0.9 * joint.weights[3] / joint.weights[5]


def test_on_relief_the_slopes_are_priced_on_the_frames_with_no_class_in_view(monkeypatch):
    """A driver that drives over a slope on the path when nothing else is near, and holds a line
    1.4 m off beside the same slope where a patch's edge is near the footprint: the second frames
    show the patch, not the slope. Relief is priced on the frames with no class in view, so the
    slope costs nothing; read on every frame, it would be priced for the patch's sake."""
    rng, n = np.random.default_rng(7), 300
    offsets, bands = OffsetGeometry().offsets, (4.0, 8.0)
    features, near, intent, relief = _relief_drive(rng, n)
    near = np.concatenate([near, rng.uniform(1.0, 10.0, n)])
    features = np.concatenate([features, np.zeros((n, len(offsets), K + 2))])
    features[:, :, 5] = offsets**2 * 7.0
    intent = np.concatenate([intent, np.full(n, 1.4)])
    relief = np.concatenate([relief, np.zeros((n, len(offsets), 4))])
    slope = np.where(np.abs(offsets) < 1.2, 2.0, 0.0)[:, None]
    features[n : 2 * n, :, 3] = 0.0  # the slope alone, driven over
    intent[n : 2 * n] = 0.0
    relief[n:, :, :2] = slope
    features[2 * n :, :, 3] = np.where((np.abs(offsets) > 0.6) & (np.abs(offsets) < 1.0), 0.5, 0.0)  # a patch's edge
    fit = fit_offset_utility(features, near, intent, offsets, relief=(relief, bands))
    assert fit.weights[3] < 0 and (fit.relief == 0.0).all()
    monkeypatch.setattr(offset_fit, "TERRAIN_FREE_FRAMES_LEAST", n + 1)  # too few such frames: relief read on every frame
    every = fit_offset_utility(features, near, intent, offsets, relief=(relief, bands))
    np.testing.assert_array_equal(every.weights[[0, 1, 2, 3, 5]], fit.weights[[0, 1, 2, 3, 5]])
    assert every.relief[0] + every.relief[1] < 0


def test_on_relief_ground_never_seen_is_priced_apart_on_the_paths_lanes_and_beside_them():
    """A driver who keeps off a bank's crest, past which it cannot see, yet drives over a mound
    into the ground the mound hides: one price for ground never seen would split the difference;
    the fit prices it dear beside the path and cheap on the path's own lanes, and the rule, on a
    map that reads depth, prices it so (:func:`hidden_prices`)."""
    rng, n = np.random.default_rng(5), 300
    offsets = OffsetGeometry().offsets
    features, near, intent, relief = _relief_drive(rng, n)
    intent[n:] = 0.0  # relief in view, nothing else near: on the path
    lanes = np.abs(offsets) <= offset_fit.HIDDEN_ON_PATH_M + 1e-9
    mound, bank = slice(n, n + n // 2), slice(n + n // 2, 2 * n)
    features[n:, :, 3] = 0.0
    features[mound, :, 4] = np.where(lanes, 3.0, 0.0)  # the ground a mound on the path hides
    features[bank, :, 4] = np.where(offsets > offset_fit.HIDDEN_ON_PATH_M, 4.0, 0.0)  # past a bank's crest on the right
    intent[bank] = -0.6  # kept to the left of the bank's foot
    fit = fit_offset_utility(features, near, intent, offsets, relief=(relief, (4.0, 8.0)))
    beside, on_path = hidden_prices(OffsetUtility(fit.weights, fit.near_m, relief=fit.relief, hidden_on_path=fit.hidden_on_path))
    assert fit.hidden_on_path > 0.0 and beside < on_path <= 0.0


def test_the_staged_fits_relief_intervals_cover_the_true_price_when_frames_come_in_runs():
    """As the intervals of a fit of every weight at once (test above): drives simulated from a
    known utility (a terrain column, ground never seen, the detour, two relief columns, the gate),
    half their frames with no relief in view, each frame repeated for 10 in a row; the terrain's
    weights fitted on those, the rest on every frame (terrapref.rules.offset.fit.fit_staged). The
    95% intervals, carrying the detour's spread from the first stage, cover both true prices at
    once in about 0.95^2 of drives (50 of these 60); taking each frame as independent evidence,
    in far fewer (11)."""
    from terrapref.rules.offset.fit import fit_staged, relief_price_intervals, relief_prices, staged_covariance

    rng = np.random.default_rng(11)
    truth = np.array([-1.0, -0.5, -2.0, -2.4, -1.6, 0.0])  # terrain, never seen, detour, side slope and grade past band 1, gate
    price = relief_prices(truth[3:5], truth[2])
    offsets, runs, repeat, drives = 7, 200, 10, 60
    second = np.array([1, 3, 4])
    covered = naive_covered = 0
    for _ in range(drives):
        X = rng.uniform(0.0, 1.0, size=(runs, offsets, 6))
        X[:, :, 2] = (np.linspace(-1.5, 1.5, offsets) ** 2)[None, :]  # the detour: the offset squared
        X[: runs // 2, :, 3:5] = 0.0  # no relief in view
        X[:, :, 5] = 0.0  # no gate
        X = np.repeat(X, repeat, axis=0)
        z = X @ truth
        p = np.exp(z - z.max(axis=1, keepdims=True))
        p /= p.sum(axis=1, keepdims=True)
        Y = np.eye(offsets)[np.repeat(np.array([rng.choice(offsets, p=row) for row in p[::repeat]]), repeat)]
        flat = ~X[:, :, 3:5].any(axis=(1, 2))
        theta, _, free, first = fit_staged(X, Y, (flat, None), 3, 1e-6)
        for block in (50, 1):
            covariance = staged_covariance(X, Y, (theta, free), ((flat, None), second, first), 1e-6, block)
            interval = relief_price_intervals(theta, covariance, 3, 2)
            inside = bool(((interval[:, 0] <= price) & (price <= interval[:, 1])).all())
            covered, naive_covered = (covered + inside, naive_covered) if block == 50 else (covered, naive_covered + inside)
    assert covered >= 0.75 * drives and naive_covered < 0.5 * covered


def _drive(stage: OffsetSteering, scenario, camera: PinholeCamera, seconds: float) -> np.ndarray:
    from terrapref.scenario.path import PathTracker
    from terrapref.world import rasterise

    renderer = SegmentationRenderer(camera, rasterise(scenario))
    path = ReferencePath(scenario.waypoints)
    tracker = PathTracker(path)
    pose = (2.0, 10.0, 0.0)
    poses = []
    gmap = _map_of(stage, camera)
    for _ in range(round(seconds * 10)):
        s = tracker.update(np.array(pose[:2]))
        w = _steer(stage, gmap, SegmentationView.of(renderer.render(pose)), pose, path, s)
        pose = integrate_unicycle(pose, Command(1.0, w), 0.1)
        poses.append(pose)
    return np.array(poses)


def test_the_offset_stage_goes_round_trees_on_the_path_and_comes_back(camera):
    scenario = _scenario([TREES])
    lethal = np.array([0])
    stage = OffsetSteering(OffsetUtility(DRIVER_LIKE, 5.0), camera, _terrain(tuple(int(c) for c in lethal)), CONTROL)
    poses = _drive(stage, scenario, camera, 30.0)
    # Clear of the 2 x 2.2 m trees (x 13.1-15.1, y 9.1-11.3) by the half-width 0.6 m at least.
    beside = (poses[:, 0] > 13.1 - 0.6) & (poses[:, 0] < 15.1 + 0.6)
    gap = np.minimum(np.abs(poses[beside, 1] - 9.1), np.abs(poses[beside, 1] - 11.3))
    outside = (poses[beside, 1] < 9.1) | (poses[beside, 1] > 11.3)
    assert outside.all() and gap.min() > 0.6
    assert abs(poses[-1, 1] - 10.0) < 0.3  # back on the path
    stage.reset()
    assert stage.held == 0.0


def _clearance(poses: np.ndarray, centre: tuple[float, float], size: tuple[float, float]) -> float:
    """Least distance [m] from the driven centre line to an axis-aligned rectangle."""
    dx = np.maximum(np.abs(poses[:, 0] - centre[0]) - size[0] / 2, 0.0)
    dy = np.maximum(np.abs(poses[:, 1] - centre[1]) - size[1] / 2, 0.0)
    return float(np.hypot(dx, dy).min())


def test_trees_wider_than_every_fitted_offset_are_escaped_beyond_them(camera):
    # 7 m across: the fitted offsets reach 3 m, getting round needs 3.5 + 0.6 + 0.3 = 4.4 m or more.
    wide = {"class": "non_traversable", "rectangle": {"center": [16.0, 10.0], "size": [2.5, 7.0]}}
    scenario = _scenario([wide])
    stage = OffsetSteering(OffsetUtility(DRIVER_LIKE, 5.0), camera, _terrain((0,)), CONTROL)
    poses = _drive(stage, scenario, camera, 34.0)
    assert _clearance(poses, (16.0, 10.0), (2.5, 7.0)) > 0.6 + 0.3
    assert abs(poses[-1, 1] - 10.0) < 0.3 and stage.held == 0.0  # back on the path
    stuck = OffsetSteering(OffsetUtility(DRIVER_LIKE, 5.0), camera, _terrain((0,)), CONTROL, OffsetConfig(escape_factor=1.0))
    assert _clearance(_drive(stuck, scenario, camera, 34.0), (16.0, 10.0), (2.5, 7.0)) == 0.0  # without escape it drives in


def test_trees_beside_the_vehicle_and_others_ahead_on_the_other_side_are_no_wall_to_escape(camera):
    # Trees 3 m wide along the right of the path (their edge on it), then trees on the left 1.4 m
    # from it: every fitted offset meets one or the other somewhere 11 m ahead, but no offset
    # meets both at once. The vehicle holds left of the first and comes back between; taken for
    # a wall across the way, it made for an escape 4.2 m right, across the first trees, and ran into them.
    right = {"class": "non_traversable", "rectangle": {"center": [11.5, 8.5], "size": [9.0, 3.0]}}
    left = {"class": "non_traversable", "rectangle": {"center": [21.5, 15.0], "size": [7.0, 7.2]}}
    poses = _drive(OffsetSteering(OffsetUtility(DRIVER_LIKE, 5.0), camera, _terrain((0,)), CONTROL), _scenario([right, left]), camera, 27.0)
    assert _clearance(poses, (11.5, 8.5), (9.0, 3.0)) > 0.6 and _clearance(poses, (21.5, 15.0), (7.0, 7.2)) > 0.6
    assert np.abs(poses[:, 1] - 10.0).max() < 3.0  # never out for an escape


def _taken(scenario, camera: PinholeCamera, pose, held: float, speed_mps: float | None = None, rule: tuple = (DRIVER_LIKE, None)) -> float:
    """The offset a fresh rule (``rule``: its utility's weights and its OffsetConfig) holds after one
    frame seen at ``pose`` (on the test path, which starts at x = 2 m), holding ``held`` before it,
    the vehicle going at ``speed_mps``."""
    stage = OffsetSteering(OffsetUtility(rule[0], 5.0), camera, _terrain((0,)), CONTROL, rule[1])
    stage.held = held
    _steer(
        stage, _map_of(stage, camera), _seen_from(scenario, camera, pose), pose, ReferencePath(scenario.waypoints), pose[0] - 2.0, speed_mps
    )
    return stage.held


def test_an_escape_is_taken_on_the_side_of_the_offset_held(camera):
    # Trees 7 m across, 0.4 m left of the path: the nearest escape clear of them is right of it
    # (4.2 m), the left one lies 0.6 m further out (4.8 m). Holding nothing, the vehicle takes the
    # nearest; holding an offset on the left, it stays on the left rather than cross in front of them.
    wall = {"class": "non_traversable", "rectangle": {"center": [16.0, 10.4], "size": [2.5, 7.0]}}
    taken = {held: _taken(_scenario([wall]), camera, (9.0, 10.0, 0.0), held) for held in (0.0, 2.0, -2.0)}
    reach = OffsetGeometry().max_offset_m
    assert taken[0.0] < -reach and taken[-2.0] == taken[0.0]  # the nearest, on the right
    assert taken[2.0] > reach  # held on the left: the escape on the left


def test_at_speed_an_offset_ruled_out_is_traded_for_one_on_the_same_side(camera):
    # A tree 2.2 m across on the path, 5 m ahead; the vehicle holds an offset right of the path
    # whose way meets it. The utility prefers the left side, by less than the switch margin. At
    # the control set's speed the rule takes the best, on the left; faster than that it keeps to the
    # right, where it was already going.
    tree = {"class": "non_traversable", "rectangle": {"center": [14.0, 10.0], "size": [2.0, 2.2]}}
    taken = {speed: _taken(_scenario([tree]), camera, (8.0, 10.0, 0.0), -1.0, speed) for speed in (None, 1.0, 1.5)}
    assert taken[None] == taken[1.0] > 2.0  # the best, across
    assert taken[1.5] < -2.0  # clear of the tree on the right


def test_between_two_classes_the_offset_nearest_the_path_of_those_nearly_as_good_is_taken():
    offsets = OffsetGeometry().offsets
    stage = OffsetSteering.__new__(OffsetSteering)  # the choice alone: the offsets, the columns and the tolerance
    stage.offsets, stage.k, stage.config = offsets, K, OffsetConfig(trade_tolerance=0.25)
    # A strip of rock on the path, mud beside it on the left: every offset crosses 7 m of terrain;
    # the utility rises by less than the tolerance from 0.6 m left to its best, 1.4 m left.
    features = np.zeros((len(offsets), K + 2))
    features[:, 2] = 7.0
    strip = OffsetView(features, 3.0)
    value = -np.abs(offsets - 1.4) * 0.2 - 1.0
    value[offsets < 0.6 - 1e-9] -= 1.0
    best = int(np.argmax(value))
    taken = stage.nearest_trade(value, best, strip)
    assert offsets[best] == pytest.approx(1.4) and offsets[taken] == pytest.approx(0.6)
    value_blocked = np.where(np.isclose(offsets, 0.6), -np.inf, value)
    assert offsets[stage.nearest_trade(value_blocked, best, strip)] == pytest.approx(0.8)  # a ruled-out offset is never taken
    # Moving in would cross more terrain (a lone patch gone round), or steeper ground (a mound's
    # flank): the best, however flat the utility.
    patch = features.copy()
    patch[np.abs(offsets) < 1.4 - 1e-9, 3] = 2.0
    assert stage.nearest_trade(value, best, OffsetView(patch, 3.0)) == best
    steep = np.zeros((len(offsets), 2 * len(RELIEF_BANDS_DEG)))
    steep[np.abs(offsets) < 1.4 - 1e-9, 3] = 1.5
    assert stage.nearest_trade(value, best, OffsetView(features, 3.0, steep)) == best
    # The best's own line on less than a metre of terrain (misread cells, not a strip): the best.
    assert stage.nearest_trade(value, best, OffsetView(features * (0.9 / 7.0), 3.0)) == best
    # No tolerance, or the best on the path: the best.
    stage.config = OffsetConfig()
    assert stage.nearest_trade(value, best, strip) == best
    stage.config = OffsetConfig(trade_tolerance=0.25)
    centre = int(np.argmin(np.abs(offsets)))
    assert stage.nearest_trade(np.where(np.arange(len(offsets)) == centre, 0.0, -5.0), centre, strip) == centre
    with pytest.raises(ValueError, match="trade_tolerance"):
        OffsetConfig(trade_tolerance=-0.1)


def test_a_strip_beside_a_better_class_is_left_no_further_than_the_utility_can_tell(camera):
    # A water strip on the path (2.8 m wide), mud beside it on the left, rock on the right: a utility
    # with the driver's prices, a quarter as sure of them as DRIVER_LIKE, holds 2 m left (wholly
    # on the mud), and 1.4 m left (astride the strip's edge) within 0.25 of that. With the
    # tolerance the rule holds there; a lone patch of mud on the path is gone round as far out.
    strip = {"class": "water", "rectangle": {"center": [16.0, 10.0], "size": [7.0, 2.8]}}
    better = {"class": "mud", "rectangle": {"center": [16.0, 12.9], "size": [7.0, 3.0]}}
    worse = {"class": "rock", "rectangle": {"center": [16.0, 7.1], "size": [7.0, 3.0]}}
    lone = {"class": "mud", "rectangle": {"center": [16.0, 10.0], "size": [3.0, 2.0]}}
    pose, unsure = (9.0, 10.0, 0.0), 0.25 * DRIVER_LIKE
    plain, traded = ((unsure, None), (unsure, OffsetConfig(trade_tolerance=0.25)))
    assert _taken(_scenario([strip, better, worse]), camera, pose, 0.0, rule=plain) == pytest.approx(2.0)
    assert _taken(_scenario([strip, better, worse]), camera, pose, 0.0, rule=traded) == pytest.approx(1.4)
    near = (11.0, 10.0, 0.0)  # the patch 3.5 m ahead, within the utility's near distance
    round_plain = _taken(_scenario([lone]), camera, near, 0.0, rule=plain)
    assert abs(round_plain) >= 1.0 and _taken(_scenario([lone]), camera, near, 0.0, rule=traded) == round_plain


def test_the_stage_goes_back_to_the_path_only_when_the_way_back_is_clear(camera):
    # A thin strip of trees 0.65-1.0 m right of the path: off the footprint of offset 0 (0.6 m
    # each side) but inside its clearance (0.9 m), so nothing lies on the path, yet the way
    # back from 1.4 m left is ruled out.
    strip = {"class": "non_traversable", "rectangle": {"center": [11.0, 9.175], "size": [4.0, 0.35]}}
    scenario = _scenario([strip])
    path = ReferencePath(scenario.waypoints)
    stage = OffsetSteering(OffsetUtility(DRIVER_LIKE, 5.0), camera, _terrain((0,)), CONTROL)
    pose = (9.0, 11.4, 0.0)
    stage.held = 1.4
    _steer(stage, _map_of(stage, camera), _seen_from(scenario, camera, pose), pose, path, 7.0)
    assert stage.held > 0.0
    free = _scenario([])
    stage.reset()
    stage.held = 1.4
    _steer(stage, _map_of(stage, camera), _seen_from(free, camera, pose), pose, path, 7.0)
    assert stage.held == 0.0  # with nothing there it goes back


def _driven_past(scenario, camera: PinholeCamera, pose, held: float, until_x: float, each=None) -> np.ndarray:
    """The poses a fresh rule drives at 1 m/s from ``pose`` on the test path (which starts at
    x = 2 m), holding ``held`` at first, until past ``until_x`` [m]; ``each`` is called with the
    rule after every step. Where it starts, the way to every fitted offset brushes the clearance
    (checked on the view from there)."""
    path = ReferencePath(scenario.waypoints)
    stage = OffsetSteering(OffsetUtility(DRIVER_LIKE, 5.0), camera, _terrain((0,)), CONTROL)
    gmap = _map_of(stage, camera)
    gmap.update(_seen_from(scenario, camera, pose), pose)
    assert (stage._swept(gmap, stage.offsets, pose, path, pose[0] - 2.0) < stage._steps).all()  # every way brushes the clearance
    gmap.reset()
    stage.held = held
    poses = []
    while pose[0] < until_x:
        s = path.project(np.array(pose[:2]))[0]
        w = _steer(stage, gmap, _seen_from(scenario, camera, pose), pose, path, s)
        pose = integrate_unicycle(pose, Command(1.0, w), 0.1)
        poses.append(pose)
        if each is not None:
            each(stage)
    return np.array(poses)


def test_a_side_only_the_margin_rules_out_is_kept_rather_than_a_way_across_lethal_terrain(camera):
    # Trees on the path, 2.5 m across (1.25 m each side), from 1.5 m ahead. The vehicle is 1.8 m
    # left of the path: its footprint (0.6 m each side) passes them, its clearance (0.9 m) does
    # not, so the way to every offset brushes the clearance. The ways to the right offsets touch
    # it later (only once they are across), which is no reason to cross the trees.
    trees = {"class": "non_traversable", "rectangle": {"center": [16.0, 10.0], "size": [8.0, 2.5]}}

    def never_across(stage: OffsetSteering) -> None:
        assert stage.held > 0.0  # never the way across

    poses = _driven_past(_scenario([trees]), camera, (10.5, 11.8, 0.0), 2.8, 20.0, never_across)
    assert _clearance(poses, (16.0, 10.0), (8.0, 2.5)) > 0.6


def test_where_every_fitted_way_brushes_the_clearance_a_wider_one_that_keeps_it_is_held(camera):
    # Trees 4.1 m across on the path, 2.3 m left of it and 1.8 m right, from 4 m ahead. The
    # vehicle holds the outermost fitted offset on the left, 3 m: its footprint (0.6 m each side)
    # passes 0.1 m from them, inside the clearance (0.3 m), and the way to every other fitted
    # offset brushes them too. Beyond the fitted offsets on the same side, 3.4 m keeps the
    # clearance: it is held until past, and the vehicle never comes nearer than the clearance.
    trees = {"class": "non_traversable", "rectangle": {"center": [18.0, 10.25], "size": [8.0, 4.1]}}
    poses = _driven_past(_scenario([trees]), camera, (10.0, 12.9, 0.0), 3.0, 23.0)
    assert _clearance(poses, (18.0, 10.25), (8.0, 4.1)) > 0.6 + 0.3 - 0.05  # the clearance, less a map cell


def test_when_lethal_terrain_lies_across_every_way_the_side_held_is_kept(camera):
    # A slanted non_traversable strip across the whole corridor, nearer on the left: the footprint
    # meets it on the way to every offset, and the ways to the right run farthest before it.
    # Holding a left offset, the stage keeps to the left rather than swinging across in front of
    # the strip (which way runs farthest turns on a step of pose noise); holding none, it takes
    # the farthest way.
    strip = {"class": "non_traversable", "polygon": [[14.5, 18.0], [15.1, 18.0], [16.9, 2.0], [16.3, 2.0]]}
    scenario = _scenario([strip])
    path = ReferencePath(scenario.waypoints)
    stage = OffsetSteering(OffsetUtility(DRIVER_LIKE, 5.0), camera, _terrain((0,)), CONTROL)
    pose = (10.5, 10.0, 0.0)
    gmap = _map_of(stage, camera)
    gmap.update(_seen_from(scenario, camera, pose), pose)
    reach = stage._swept(gmap, stage.offsets, pose, path, 8.5, stage._bare)
    assert (reach < stage._steps).all()  # even the footprint alone meets the strip on every way
    assert stage.offsets[np.argmax(reach)] < 0.0  # the farthest way is on the right
    for held, side in ((1.0, 1.0), (-1.0, -1.0), (0.0, -1.0)):
        stage.held = held
        kept = stage.offsets[~stage._ruled_out(gmap, stage.offsets, pose, path, 8.5)[0]]
        assert kept.size > 0 and (np.sign(kept) == side).all(), (held, kept)


def test_ground_never_seen_is_priced_at_the_mean_of_the_non_lethal_classes(camera):
    stage = OffsetSteering(OffsetUtility(DRIVER_LIKE, 5.0), camera, _terrain((0,)), CONTROL)
    assert stage.weights[K] == pytest.approx(DRIVER_LIKE[1:K].mean())
    with pytest.raises(ValueError):
        OffsetSteering(OffsetUtility(DRIVER_LIKE[:-1], 5.0), camera, _terrain((0,)), CONTROL)


def _oldest_offset_meta(weights, near_m=5.0) -> dict:
    """A model file's header as files before the ``stages`` list wrote it: the offset rule's
    utility as ``corridor``, its geometry in the features' ``corridor``."""
    meta = model_meta()
    meta["features"]["corridor"] = OffsetGeometry().to_dict()
    return {**meta, "corridor": {"weights": list(weights), "near_m": near_m}}


def _offset_meta(weights, near_m=5.0) -> dict:
    """A model file's header as this version writes it: the offset rule in ``rules``, driving."""
    block = {"type": "offset", **OffsetConfig().to_dict(), "weights": list(weights), "near_m": near_m}
    return {**model_meta(), "rules": [block], "drives": "offset"}


@pytest.mark.parametrize("make, key", [(_oldest_offset_meta, "rules"), (_offset_meta, "rules")])
def test_a_model_file_with_an_offset_utility_drives_by_the_offset_rule_old_or_new(tmp_path, make, key):
    config = ClassifierConfig(hidden=8, skip=True)
    path = save_model(tmp_path / "m.safetensors", config, skip_path_weights(config), make(DRIVER_LIKE))
    model = load_model(path)
    planner = Planner(model)
    assert planner.rule.type == "offset" and planner.rule.utility.near_m == 5.0 and planner.rule.config == OffsetConfig()
    assert planner.runner.keeps_ground_map
    assert not Planner(model, rule="argmax").runner.keeps_ground_map
    for weights, near, field in (
        (DRIVER_LIKE[:-1], 5.0, f"{key}[0].weights"),
        ([math.nan] * 7, 5.0, f"{key}[0].weights"),
        (DRIVER_LIKE, -1.0, f"{key}[0].near_m"),
    ):
        bad = save_model(tmp_path / "bad.safetensors", config, skip_path_weights(config), make(weights, near))
        with pytest.raises(UserError) as exc:
            load_policy(bad)
        assert exc.value.problems[0].field == field


def test_an_offset_utility_that_prices_relief_keeps_its_prices_in_the_file_and_bad_ones_are_refused(tmp_path):
    """A utility fitted on relief writes its relief block (the bands, a weight per column, the
    steepest band its drive showed); it reads back the same, a flat one writes none, and a block
    with a band, a weight or a shown band this version does not read is refused naming it."""
    from terrapref.rules.offset.features import RELIEF_BANDS_DEG
    from terrapref.rules.offset.rule import OffsetRule

    config = ClassifierConfig(hidden=8, skip=True)
    relief = -np.linspace(0.0, 0.5, 2 * len(RELIEF_BANDS_DEG))
    interval = np.stack([np.arange(20.0), np.arange(20.0) + 0.5], axis=1)
    interval[0] = 0.0  # a band held at 0
    rule = OffsetRule(
        OffsetConfig(), OffsetUtility(np.array(DRIVER_LIKE), 5.0, OffsetGeometry(), relief, (22.0, math.nan), interval, -0.25)
    )
    block = rule.header()
    assert block["relief"] == {
        "bands_deg": list(RELIEF_BANDS_DEG),
        "weights": relief.tolist(),
        "shown_deg": [22.0, None],
        "price_interval": interval.tolist(),
        "hidden_on_path": -0.25,
    }
    meta = {**model_meta(), "rules": [block], "drives": "offset"}
    back = Planner(load_model(save_model(tmp_path / "m.safetensors", config, skip_path_weights(config), meta))).rule
    np.testing.assert_array_equal(back.utility.relief, relief)
    np.testing.assert_array_equal(back.utility.relief_interval, interval)
    assert back.utility.hidden_on_path == -0.25
    assert back.utility.relief_shown[0] == 22.0 and math.isnan(back.utility.relief_shown[1])
    assert "(19.0 to 19.5)" in back.relief_lines()[1] and "with its 95% interval" in back.relief_lines()[0]
    assert ": 4 0.0 held, 6 " in back.relief_lines()[0]
    older = {
        **block,
        "relief": {k: v for k, v in block["relief"].items() if k not in ("price_interval", "hidden_on_path")},
    }  # a file before either
    older_meta = {**meta, "rules": [older]}
    before = Planner(load_model(save_model(tmp_path / "old.safetensors", config, skip_path_weights(config), older_meta))).rule
    assert before.utility.relief_interval is None and " to " not in before.relief_lines()[0]
    assert before.utility.hidden_on_path == 0.0
    assert "relief" not in OffsetRule(OffsetConfig(), OffsetUtility(np.array(DRIVER_LIKE), 5.0)).header()
    for change, field in (
        ({"bands_deg": [5.0, 10.0]}, "rules[0].relief.bands_deg"),
        ({"weights": [0.0] * 3}, "rules[0].relief.weights"),
        ({"weights": ["steep"] * (2 * len(RELIEF_BANDS_DEG))}, "rules[0].relief.weights"),
        ({"shown_deg": [13.0, None]}, "rules[0].relief.shown_deg"),
        ({"price_interval": [[1.0, 0.0]] * 20}, "rules[0].relief.price_interval"),
        ({"price_interval": [[0.0, math.nan]] * 20}, "rules[0].relief.price_interval"),
        ({"price_interval": [[-50.0, -40.0]] * 20}, "rules[0].relief.price_interval"),  # a price is never below 0
        ({"price_interval": [[0.0, 1.0]] * 3}, "rules[0].relief.price_interval"),
        ({"price_interval": [["0", "1"]] * 20}, "rules[0].relief.price_interval"),
        ({"price_interval": [[0, 10**400]] * 20}, "rules[0].relief.price_interval"),  # past what a float holds
        ({"weights": [10**400] * (2 * len(RELIEF_BANDS_DEG))}, "rules[0].relief.weights"),
        ({"weights": [True] * (2 * len(RELIEF_BANDS_DEG))}, "rules[0].relief.weights"),
        ({"extra": 1}, "rules[0].relief"),
        ({"hidden_on_path": math.nan}, "rules[0].relief.hidden_on_path"),
        ({"hidden_on_path": -1e308}, "rules[0].relief.hidden_on_path"),  # finite, but the utility's sums overflow
        ({"weights": [-1e308] * (2 * len(RELIEF_BANDS_DEG))}, "rules[0].relief.weights"),
        ({"hidden_on_path": "1"}, "rules[0].relief.hidden_on_path"),
        (
            {"weights": [0.0] * 9 + [5.0] + [0.0] * 10},
            "rules[0].relief.weights",
        ),  # a band that rewards steep ground: it rode a ridge's flank
    ):
        bad_block = {**block, "relief": {**block["relief"], **change}}
        bad = save_model(tmp_path / "bad.safetensors", config, skip_path_weights(config), {**meta, "rules": [bad_block]})
        with pytest.raises(UserError) as exc:
            load_policy(bad)
        assert exc.value.problems[0].field == field


def test_a_detour_that_does_not_cost_is_refused_in_a_file_and_from_a_fit(tmp_path, monkeypatch):
    """A detour's weight of 0 or more (holding off the path costs nothing, or pays): every price is
    read against it, and the rule steers away from the path. A short drive's fit gave +0.0045, and
    its prices were printed negative, outside their own intervals."""
    import terrapref.rules.offset.rule as offset_rule
    from terrapref.learning.train import FitData

    config = ClassifierConfig(hidden=8, skip=True)
    meta = _offset_meta(DRIVER_LIKE)
    for detour in (0.0, 0.0045):
        weights = [*DRIVER_LIKE[:-2], detour, DRIVER_LIKE[-1]]
        bad = {**meta, "rules": [{**meta["rules"][0], "weights": weights}]}
        with pytest.raises(UserError) as exc:
            load_policy(save_model(tmp_path / "bad.safetensors", config, skip_path_weights(config), bad))
        assert exc.value.problems[0].field == "rules[0].weights" and "must be below 0" in str(exc.value)
    fitted = offset_rule.OffsetFit(np.array([*DRIVER_LIKE[:-2], 0.0045, DRIVER_LIKE[-1]]), 5.0, 1.0, {}, 100)
    monkeypatch.setattr(offset_rule, "fit_offset_utility", lambda *a, **k: fitted)
    arrays = {"features": np.zeros((1, 1, 1)), "near_m": np.zeros(1), "intent_m": np.zeros(1)}

    class Data(FitData):
        def __init__(self):
            pass

        def rule_data(self, name):
            return {"geometry": offset_rule.OffsetGeometry().to_dict()}, arrays

    with pytest.raises(UserError, match=r"did not show what holding off the path costs \(its weight came out \+0.0045"):
        OffsetConfig().fit(Data())


def test_the_relief_prices_intervals_cover_the_true_price_when_frames_come_in_runs():
    """Drives simulated from a known utility (a terrain column, the detour, two relief columns, the
    gate), each frame repeated for 10 in a row as a drive's neighbouring frames are: the fit's 95%
    intervals of the printed relief prices (terrapref.rules.offset.fit.relief_price_intervals)
    cover the true prices in about 95% of drives, where intervals that took each frame as
    independent evidence (blocks of one frame) are about three times too narrow and miss far
    more often."""
    from terrapref.rules.offset.fit import (
        INTERVAL_BLOCK_FRAMES,
        fit_softmax,
        relief_price_intervals,
        relief_prices,
        weight_covariance,
    )

    rng = np.random.default_rng(7)
    truth = np.array([-1.0, -2.0, -0.8, -0.6, 0.0])  # terrain, detour, side slope past band 1, grade past band 1, gate
    price = relief_prices(truth[2:4], truth[1])
    offsets, runs, repeat = 7, 40, 10
    covered = naive_covered = 0
    widths, naive_widths = [], []
    drives = 60
    for _ in range(drives):
        X = rng.uniform(0.0, 1.0, size=(runs, offsets, 5))
        X[:, :, 1] = (np.linspace(-1.5, 1.5, offsets) ** 2)[None, :]  # the detour: the offset squared
        X[:, :, 4] = 0.0  # no gate
        X = np.repeat(X, repeat, axis=0)
        z = X @ truth
        p = np.exp(z - z.max(axis=1, keepdims=True))
        p /= p.sum(axis=1, keepdims=True)
        chosen = np.repeat(np.array([rng.choice(offsets, p=row) for row in p[::repeat]]), repeat)  # a choice held for its run
        Y = np.eye(offsets)[chosen]
        theta, _ = fit_softmax(X[:, :, :4], Y, 1e-6)
        theta = np.append(theta, 0.0)
        free = np.array([True, True, True, True, False])
        for block, tally in ((INTERVAL_BLOCK_FRAMES, "blocks"), (1, "frames")):
            covariance = weight_covariance(X, Y, theta, free, 1e-6, block)
            interval = relief_price_intervals(theta, covariance, 2, 2)
            inside = bool(((interval[:, 0] <= price) & (price <= interval[:, 1])).all())
            width = float(np.mean(interval[:, 1] - interval[:, 0]))
            if tally == "blocks":
                covered, widths = covered + inside, [*widths, width]
            else:
                naive_covered, naive_widths = naive_covered + inside, [*naive_widths, width]
    assert covered >= 0.8 * drives  # both prices at once: about 0.95^2 of the drives, with sampling error
    assert naive_covered < covered and np.median(widths) > 2.0 * np.median(naive_widths)
    no_detour = np.array([-1.0, 0.0, -0.8, -0.6, 0.0])  # nothing is on the scale of a detour priced at 0
    assert np.isnan(relief_price_intervals(no_detour, np.eye(5), 2, 2)).all()


def test_a_file_that_names_a_rule_it_does_not_list_to_drive_is_refused(tmp_path):
    config = ClassifierConfig(hidden=8, skip=True)
    bad = save_model(
        tmp_path / "bad.safetensors", config, skip_path_weights(config), {**_offset_meta(DRIVER_LIKE), "drives": "second_stage"}
    )
    with pytest.raises(UserError) as exc:
        Planner(load_model(bad))
    assert exc.value.problems[0].field == "drives" and "second_stage" in str(exc.value)


class _CountingFeaturizer:
    """A featurizer that counts its calls."""

    def __init__(self, inner: UtilityFeaturizer) -> None:
        self.inner, self.calls = inner, 0

    def __call__(self, *args, **kwargs):
        self.calls += 1
        return self.inner(*args, **kwargs)


def test_the_offset_stage_leaves_u_and_c_until_a_decision_reports_them(tmp_path, camera):
    config = ClassifierConfig(hidden=8, skip=True)
    model = load_model(save_model(tmp_path / "m.safetensors", config, skip_path_weights(config), _oldest_offset_meta(DRIVER_LIKE)))
    scenario = _scenario([MUD])
    image = _seen_from(scenario, camera, (5.0, 10.0, 0.0)).image
    planners = {how: Planner(model) for how in ("view", "array")} | {"argmax": Planner(model, rule="argmax")}
    for planner in planners.values():
        planner.set_path(scenario.waypoints)
        planner.featurizer = _CountingFeaturizer(planner.featurizer)
    lazy = planners["view"].decide(SegmentationView.of(image), (5.0, 10.0, 0.0))
    assert planners["view"].featurizer.calls == 0  # the offset rule steered without them
    now = planners["array"].decide(image, (5.0, 10.0, 0.0))  # an array the caller may reuse: read at once
    assert planners["array"].featurizer.calls == 1
    argmax = planners["argmax"].decide(SegmentationView.of(image), (5.0, 10.0, 0.0))  # a stage that steers by F_t
    assert planners["argmax"].featurizer.calls == 1
    assert lazy.command == now.command and lazy.index == now.index and lazy.progress_m == now.progress_m
    for a, b in ((lazy, now), (lazy, argmax)):
        np.testing.assert_array_equal(a.probs, b.probs)
        np.testing.assert_array_equal(a.U, b.U)
    assert lazy.U[:, :K].sum() > 0  # the mud is in view
    assert planners["view"].featurizer.calls == 1  # computed once, when first read


def _offset_dataset(n: int = 40) -> Dataset:
    rng = np.random.default_rng(2)
    rule = OffsetConfig()
    o = len(rule.geometry.offsets)
    arrays = {
        "features": rng.uniform(0, 3, (n, o, K + 2)).astype(np.float32),
        "near_m": np.full(n, np.inf, np.float32),
        "intent_m": np.append(rng.uniform(-1, 1, n - 2), [np.nan, np.nan]).astype(np.float32),
    }
    meta = {
        "format": DATASET_FORMAT,
        **model_meta(),
        "rules": {"offset": {"config": rule.data(), "arrays": {name: OffsetConfig.arrays[name] for name in arrays}}},
    }
    return Dataset(
        rng.uniform(0, 1, (n, 21, 5)).astype(np.float32),
        rng.integers(0, 21, n),
        np.zeros(n, np.float32),
        np.zeros(n, np.int64),
        meta,
        {"offset": arrays},
    )


def test_the_offset_rules_arrays_survive_a_dataset_file_and_bad_values_are_refused(tmp_path):
    data = _offset_dataset()
    back = load_dataset(save_dataset(data, tmp_path / "d.safetensors"))
    for name, a in data.rules["offset"].items():
        np.testing.assert_array_equal(a, back.rules["offset"][name])
    assert back.fingerprint == data.fingerprint and back.rule_data("offset")[0] == OffsetConfig().data()
    broken = data.rules["offset"]["features"].copy()
    broken[3, 4, 1] = np.nan
    bad = Dataset(data.U, data.labels, data.w, data.source, data.meta, {"offset": {**data.rules["offset"], "features": broken}})
    with pytest.raises(UserError) as exc:
        load_dataset(save_dataset(bad, tmp_path / "bad.safetensors"))
    assert exc.value.problems[0].field == "rules.offset.features"


def test_a_rule_fitted_on_relief_waits_for_a_near_views_evidence_and_its_planner_keeps_one_map(tmp_path):
    """Fitted on a drive whose frames carried depth (relief columns), the rule's map counts a cell
    once it holds RELIEF_MIN_EVIDENCE, and reads it as lethal once lethal classes hold
    RELIEF_LETHAL_SHARE of it, both written in its file; fitted on flat ground it keeps the
    geometry's own (0 and 0.35), as before. Neither takes a trade tolerance unless its config sets
    one, which the fit keeps and the file holds; a file written without it reads 0. The speed rule reads the steering rule's map, so a planner with
    both keeps one map whatever the offset rule's map settings."""
    from test_speed_rule import MODEL as SPEED_MODEL

    from terrapref.learning.train import FitData
    from terrapref.rules.offset.features import RELIEF_BANDS_DEG
    from terrapref.rules.offset.rule import RELIEF_LETHAL_SHARE, RELIEF_MIN_EVIDENCE
    from terrapref.rules.speed.rule import SpeedConfig, SpeedRule

    flat = _offset_dataset()
    arrays = flat.rules["offset"]
    n, o = arrays["features"].shape[:2]
    relief_m = np.zeros((n, o, 2 * len(RELIEF_BANDS_DEG)), np.float32)
    relief_m[::3, o // 2 :, 3] = 2.0  # steep ground on one side in some frames
    meta = {
        **flat.meta,
        "rules": {
            "offset": {**flat.meta["rules"]["offset"], "arrays": {**flat.meta["rules"]["offset"]["arrays"], "relief_m": "finite >= 0"}}
        },
    }
    on_relief = Dataset(flat.U, flat.labels, flat.w, flat.source, meta, {"offset": {**arrays, "relief_m": relief_m}})
    flat_rule = OffsetConfig().fit(FitData(flat, mirror=False))
    on_flat = flat_rule.config.geometry
    assert (on_flat.map_min_evidence, on_flat.map_lethal_share) == (0.0, 0.35)
    assert flat_rule.config.trade_tolerance == flat_rule.header()["trade_tolerance"] == 0.0
    set_rule = OffsetConfig(trade_tolerance=0.25).fit(FitData(flat, mirror=False))
    assert set_rule.config.trade_tolerance == set_rule.header()["trade_tolerance"] == 0.25
    rule = OffsetConfig().fit(FitData(on_relief, mirror=False))
    assert rule.config.trade_tolerance == 0.0
    assert RELIEF_MIN_EVIDENCE > 0 and rule.config.geometry.map_min_evidence == RELIEF_MIN_EVIDENCE
    assert RELIEF_LETHAL_SHARE > 0.35 and rule.config.geometry.map_lethal_share == RELIEF_LETHAL_SHARE
    assert rule.header()["geometry"]["map_min_evidence"] == RELIEF_MIN_EVIDENCE
    assert rule.header()["geometry"]["map_lethal_share"] == RELIEF_LETHAL_SHARE
    map_line = [
        line for line in rule.relief_lines() if line.startswith("map: a cell counts as seen, lethal or not, once it holds 1 of evidence")
    ]
    assert len(map_line) == 1 and map_line[0].endswith("reads as lethal once lethal classes hold 50% of it")
    meta = {**model_meta(), "rules": [rule.header(), SpeedRule(SpeedConfig(), SPEED_MODEL).header()], "drives": "offset"}
    config = ClassifierConfig(hidden=8, skip=True)
    planner = Planner(load_model(save_model(tmp_path / "m.safetensors", config, skip_path_weights(config), meta)))
    assert planner.ground_map.settings.map_min_evidence == RELIEF_MIN_EVIDENCE
    assert planner.ground_map.settings.map_lethal_share == RELIEF_LETHAL_SHARE
    assert planner.speed is not None and list(planner._maps.values()) == [planner.ground_map]  # offset, speed and stop: one map

    def tolerance_read(header: dict, name: str) -> float:
        meta = {**model_meta(), "rules": [header], "drives": "offset"}
        return Planner(load_model(save_model(tmp_path / name, config, skip_path_weights(config), meta))).rule.config.trade_tolerance

    assert tolerance_read(set_rule.header(), "set.safetensors") == 0.25
    assert tolerance_read({k: v for k, v in set_rule.header().items() if k != "trade_tolerance"}, "older.safetensors") == 0


def test_the_compiled_swept_check_is_the_numpy_form(camera):
    """The way to each offset, stepped by pure pursuit in NumPy, meets the trees at the step the kernel says."""
    scenario = _scenario([TREES])
    stage = OffsetSteering(OffsetUtility(DRIVER_LIKE, 5.0), camera, _terrain((0,)), CONTROL)
    path = ReferencePath(scenario.waypoints)
    gmap = _map_of(stage, camera)
    for pose, s in (((8.0, 10.0, 0.0), 6.0), ((9.0, 10.5, 0.2), 7.0), ((10.0, 9.3, -0.3), 8.0)):
        gmap.update(_seen_from(scenario, camera, pose), pose)
        n = len(stage.offsets)
        x, y, yaw = (np.full(n, v) for v in pose)
        first = np.full(n, 60)  # the step where each way first meets the trees
        for i in range(60):
            ahead = s + i * 0.1 + 2.5
            heading = float(path.heading_at(ahead))
            tx = path.point_at(ahead)[0] - stage.offsets * math.sin(heading) - x
            ty = path.point_at(ahead)[1] + stage.offsets * math.cos(heading) - y
            alpha = (np.arctan2(ty, tx) - yaw + math.pi) % (2 * math.pi) - math.pi
            w = np.clip(2.0 * np.sin(alpha) / np.maximum(np.hypot(tx, ty), 1e-6), -1.0, 1.0)
            yaw = yaw + w * 0.1
            x, y = x + np.cos(yaw) * 0.1, y + np.sin(yaw) * 0.1
            if i % 2 == 0:
                points = np.stack([x[:, None] - stage._clear * np.sin(yaw)[:, None], y[:, None] + stage._clear * np.cos(yaw)[:, None]], -1)
                hit = (gmap.lookup(points) == 0).any(axis=1)
                first = np.where(hit & (first == 60), i, first)
        assert (first < 60).any() and not (first < 60).all()
        np.testing.assert_array_equal(stage._swept(gmap, stage.offsets, pose, path, s), first)


_FIT = """
import sys, hashlib
import numpy as np
sys.path[:0] = {tests!r}
from test_offset_rule import _fit_case

print(hashlib.sha256(_fit_case().tobytes()).hexdigest())
"""


def _fit_case() -> np.ndarray:
    """Weights of a corridor fit to random frames, with labels from a known utility."""
    rng = np.random.default_rng(3)
    offsets = OffsetGeometry().offsets
    n = 800
    features = rng.uniform(0.0, 3.0, (n, len(offsets), K + 2)) * (rng.uniform(size=(n, 1, K + 2)) < 0.5)
    features[:, :, K + 1] = offsets**2 * rng.uniform(5.0, 12.0, (n, 1))
    near = rng.uniform(1.0, 12.0, n)
    value = np.concatenate([features, (offsets**2)[None, :, None] * (near > 5.0)[:, None, None]], axis=2) @ DRIVER_LIKE
    intent = offsets[np.argmax(value + rng.gumbel(size=value.shape), axis=1)]
    return fit_offset_utility(features, near, intent, offsets).weights


CPU_CHECK = CpuCheck.of("corridor fit", _FIT.format(tests=[str(TESTS), str(Path(__file__).resolve().parent)]), SETTINGS)


def test_the_offset_fit_gives_the_same_weights_under_an_older_blas_kernel(cpu_outputs):
    hashes = {out.strip() for _, out in cpu_outputs["corridor fit"]}
    assert len(cpu_outputs["corridor fit"]) >= 2 and len(hashes) == 1


@pytest.mark.slow
def test_the_offset_fit_gives_the_same_weights_under_every_cpu_setting(cpu_outputs_every):
    hashes = {out.strip() for _, out in cpu_outputs_every["corridor fit"]}
    assert len(hashes) == 1


def test_the_map_reads_every_voted_cell_as_decided_and_refuses_too_many_columns():
    """After votes, ``cells`` holds no undecided marker (it decides them) and is read-only; a
    class table with 254 terrain columns would need the marker as a column and is refused."""
    from terrapref.groundmap import map_compiled

    scenario = _scenario([MUD])
    camera = PinholeCamera()
    gmap = GroundMap(camera, _terrain())
    for pose in ((2.0, 10.0, 0.0), (4.0, 10.2, 0.05)):
        gmap.update(_seen_from(scenario, camera, pose), pose)
    assert (gmap._cells == map_compiled.UNSETTLED).any()  # the votes left cells to decide
    cells = gmap.cells
    assert not (cells == map_compiled.UNSETTLED).any() and (cells < gmap.k + 1).any()
    assert not cells.flags.writeable
    with pytest.raises(ValueError, match="terrain columns"):
        GroundMap(camera, TerrainColumns(np.zeros(256, np.uint8), 254))


@pytest.mark.parametrize("best", [-4.0, 4.0])
def test_the_held_offset_is_kept_within_the_margin_whatever_the_sign_of_the_best_utility(best):
    from terrapref.rules.offset.rule import keeps

    short = 0.1 * abs(best)  # within a margin of 0.15 of the best's magnitude
    assert keeps(best - short, best, 0.15) and not keeps(best - 2 * short, best, 0.15)
    assert keeps(best, best, 0.0) and not keeps(best - 1e-9, best, 0.0)


def test_a_driver_who_likes_a_patch_is_not_switched_off_a_held_offset_by_a_sliver(camera):
    # A utility that prices mud above the grass around it: every offset's utility on the patch is
    # positive, and one a step off the best is short of it by the detour's price alone.
    likes_mud = DRIVER_LIKE.copy()
    likes_mud[3] = 2.0
    scenario = _scenario([MUD])
    path = ReferencePath(scenario.waypoints)
    stage = OffsetSteering(OffsetUtility(likes_mud, 5.0), camera, _terrain((0,)), CONTROL)
    pose = (6.0, 10.2, 0.0)
    stage.held = 0.2
    _steer(stage, _map_of(stage, camera), _seen_from(scenario, camera, pose), pose, path, 4.0)
    assert stage.held == pytest.approx(0.2)  # kept: a margin of the best's magnitude, not of its signed value


def test_an_offset_block_written_before_the_pursuit_distances_were_renamed_reads_the_same(tmp_path):
    config = ClassifierConfig(hidden=8, skip=True)
    block = {"type": "offset", **OffsetConfig(pursuit_m=3.0).to_dict(), "weights": list(DRIVER_LIKE), "near_m": 5.0}
    block["pursuit_lookahead_m"] = block.pop("pursuit_m")
    block["geometry"]["intent_lookahead_m"] = block["geometry"].pop("intent_pursuit_m")
    path = save_model(
        tmp_path / "old.safetensors", config, skip_path_weights(config), {**model_meta(), "rules": [block], "drives": "offset"}
    )
    rule = Planner(load_model(path)).rule
    assert rule.config == OffsetConfig(pursuit_m=3.0)


def test_a_dataset_of_flat_and_relief_drives_reads_the_flat_ones_relief_columns_as_zero():
    """The offset rule's relief columns come only with a drive on relief; joined with a flat
    drive's arrays, the flat one's read 0 (no ground past any band), its other arrays as they were."""
    from terrapref.dataset import _joined

    flat = {"features": np.ones((2, 3, 4), np.float32), "near_m": np.full(2, 5.0, np.float32)}
    relief = {
        "features": np.full((3, 3, 4), 2.0, np.float32),
        "near_m": np.ones(3, np.float32),
        "relief_m": np.ones((3, 3, 20), np.float32),
    }
    joined = _joined([flat, relief])
    assert joined["features"].shape == (5, 3, 4) and joined["relief_m"].shape == (5, 3, 20) and joined["relief_m"].dtype == np.float32
    assert not joined["relief_m"][:2].any() and joined["relief_m"][2:].all()
    np.testing.assert_array_equal(joined["near_m"], [5.0, 5.0, 1.0, 1.0, 1.0])
    assert set(_joined([flat, flat])) == {"features", "near_m"}  # flat drives alone: no relief columns
