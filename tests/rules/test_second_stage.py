"""The planner's second stage (terrapref.rules.second.rule): trajectories laid out again from a
point along each candidate, read from the current frame, scored by a linear utility the model
file carries; off for models without one."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from helpers import model_meta, skip_path_weights, train_config
from terrapref.camera import PinholeCamera, SegmentationRenderer, SegmentationView
from terrapref.dataset import Dataset
from terrapref.errors import UserError
from terrapref.features import FeatureConfig, UtilityFeaturizer
from terrapref.learning.linear import LinearUtility
from terrapref.learning.model_file import load_model, save_model
from terrapref.learning.network import ClassifierConfig
from terrapref.learning.pipeline import RunOptions, train_and_save
from terrapref.planner import Planner
from terrapref.planner.registry import load_policy
from terrapref.rules import SecondStageConfig, SecondStageRule
from terrapref.rules.second.rule import SecondStageScores
from terrapref.scenario import resolve_scenario
from terrapref.scenario.path import PathTracker, ReferencePath
from terrapref.sim import Simulation
from terrapref.terrain import default_classes
from terrapref.vehicle import Pose

# Columns of U: non_traversable, water, rock, mud, distance.
UTILITY = LinearUtility(np.array([-12.0, -5.0, -3.0, -1.0, 5.0]), np.linspace(-1.0, 1.0, 21) ** 2 * -4.0 + 2.0)


@pytest.fixture(scope="module")
def setup():
    features = FeatureConfig()
    camera = PinholeCamera()
    featurizer = UtilityFeaturizer(features, camera)
    return featurizer, camera, SecondStageScores(SecondStageConfig(), featurizer, camera, UTILITY)


def _straight_path() -> ReferencePath:
    return ReferencePath(np.array([[0.0, 0.0], [40.0, 0.0]]))


def test_the_second_stage_starts_after_s_along_each_trajectory(setup):
    featurizer, _, la = setup
    step = round(SecondStageConfig().after_s / featurizer.config.preference.dt_s)
    np.testing.assert_allclose(la.starts, featurizer.pset.trajectories[:, step])
    straight = featurizer.m // 2
    np.testing.assert_allclose(la.starts[straight], [SecondStageConfig().after_s, 0.0, 0.0], atol=1e-12)
    # The straight continuation of the straight trajectory runs on along the x axis.
    np.testing.assert_allclose(
        la.ends[straight, straight], [SecondStageConfig().after_s + featurizer.config.preference.horizon_m, 0.0], atol=1e-9
    )


@pytest.mark.parametrize("stride", [1, 2, 3])
def test_second_stage_utilities_are_those_of_the_pose_it_starts_from(setup, stride: int):
    """U' equals U computed by hand at the start pose, with its points (every ``stride``-th,
    ending with the last) projected into this frame."""
    featurizer, camera, _ = setup
    la = SecondStageScores(SecondStageConfig(stride=stride), featurizer, camera, UTILITY)
    course = resolve_scenario("demo_course")
    pose = Pose(16.0, 10.0, 0.1)
    image = SegmentationRenderer(camera, Simulation(course).world).render(pose)
    path = ReferencePath(np.vstack([[16.0, 10.0], course.waypoints[1:]]))
    s = PathTracker(path).update(np.array(pose[:2]))
    rows = np.array([3, 10, 16])
    got = la.utilities(SegmentationView.of(image), pose, path, s, rows)
    k = featurizer.config.n_terrain
    ids = {name: default_classes().id_of(name) for name in featurizer.config.feature_classes}
    dists = []
    for r, i in enumerate(rows):
        x0, y0, th = la.starts[i]
        pts = featurizer.pset.trajectories[:, ::-1][:, ::stride][:, ::-1, :2]  # every stride-th, ending with the last
        here = np.stack(
            [x0 + pts[..., 0] * math.cos(th) - pts[..., 1] * math.sin(th), y0 + pts[..., 0] * math.sin(th) + pts[..., 1] * math.cos(th)],
            axis=-1,
        )
        pix = camera.pixel_indices(here)
        labels = np.where(pix >= 0, image.reshape(-1)[np.maximum(pix, 0)], 255)
        for j, name in enumerate(featurizer.config.feature_classes):
            np.testing.assert_allclose(got[r, :, j], (labels == ids[name]).mean(axis=1))
        c, sn = math.cos(pose[2]), math.sin(pose[2])
        start_world = Pose(pose[0] + x0 * c - y0 * sn, pose[1] + x0 * sn + y0 * c, pose[2] + th)
        dists.append(featurizer.distances(start_world, path, s + x0))
    # The distance utility is normalised over every second stage asked for, together.
    np.testing.assert_allclose(got[..., k], featurizer.normalise(np.array(dists)), atol=1e-9)
    assert got[..., :k].sum() > 0  # the pair ahead is on some second stage


def test_the_candidate_whose_second_stage_avoids_water_wins_a_tie(setup):
    featurizer, _, la = setup
    m = featurizer.m
    left, right = 14, 6  # w = +0.4 and -0.4: mirror images
    image = np.full(PinholeCamera().shape, default_classes().id_of("grass"), dtype=np.uint8)
    flat = image.reshape(-1)
    beyond = la.pixels_of(left)
    flat[beyond] = default_classes().id_of("water")
    log_probs = np.full(m, -5.0)
    log_probs[[left, right]] = -1.0
    scores = la.scores(log_probs, SegmentationView.of(image), Pose(0.0, 0.0, 0.0), _straight_path(), 0.0)
    assert int(np.argmax(scores)) == right
    assert np.isfinite(scores).sum() == SecondStageConfig().candidates  # only C's best few are looked beyond
    # Without water the two are mirror images on a straight path: a tie.
    grass = np.full_like(image, default_classes().id_of("grass"))
    tie = la.scores(log_probs, SegmentationView.of(grass), Pose(0.0, 0.0, 0.0), _straight_path(), 0.0)
    assert tie[left] == pytest.approx(tie[right])


@pytest.mark.parametrize("config", [dict(after_s=0.0), dict(weight=-1.0), dict(candidates=0), dict(after_s=math.nan), dict(stride=0)])
def test_invalid_second_stage_configs(config):
    with pytest.raises(ValueError):
        SecondStageConfig(**config)


def test_a_second_stage_beyond_the_trajectories_is_refused(setup):
    featurizer, camera, _ = setup
    with pytest.raises(ValueError, match="past trajectories of"):
        SecondStageScores(SecondStageConfig(after_s=10.0), featurizer, camera, UTILITY)


def _model_with_utility(path: Path, utility: dict | None):
    config = ClassifierConfig(hidden=8, skip=True)
    meta = model_meta() | ({"utility": utility} if utility is not None else {})
    return save_model(path, config, skip_path_weights(config), meta)


def test_the_planner_looks_ahead_only_with_a_utility(tmp_path: Path):
    plain = Planner(load_model(_model_with_utility(tmp_path / "plain.safetensors", None)))
    assert plain.rule.type == "argmax"
    with_utility = load_model(_model_with_utility(tmp_path / "la.safetensors", {"w": UTILITY.w.tolist(), "b": UTILITY.b.tolist()}))
    assert Planner(with_utility).rule.type == "second_stage"
    assert Planner(with_utility, rule="argmax").rule.type == "argmax"
    with pytest.raises(ValueError, match="no 'offset' rule"):
        Planner(with_utility, rule="offset")


def test_weight_zero_is_the_argmax_of_f(tmp_path: Path):
    model = load_model(_model_with_utility(tmp_path / "la.safetensors", {"w": UTILITY.w.tolist(), "b": UTILITY.b.tolist()}))
    course = resolve_scenario("demo_course")
    renderer = SegmentationRenderer(PinholeCamera(), Simulation(course).world)
    for x in (8.0, 12.0, 16.0):
        pose = Pose(x, 10.0, 0.0)
        image = renderer.render(pose)
        fitted = Planner(model).rule
        planner = Planner(model, rule=SecondStageRule(replace(fitted.config, weight=0.0), fitted.utility))
        planner.set_path(np.vstack([[x, 10.0], course.waypoints[1:]]))
        d = planner.decide(image, pose)
        assert d.index == int(np.argmax(d.probs))


@pytest.mark.parametrize(
    "utility, field",
    [
        ({"w": [1.0, 2.0], "b": [0.0] * 21}, "rules[0].w"),
        ({"w": [0.0] * 5}, "rules[0].b"),
        ({"w": [0.0] * 5, "b": [math.inf] * 21}, "rules[0].b"),
        ("not a table", "utility"),
        ({"w": [0.0] * 5, "b": [0.0] * 21, "weight": -1.0}, "rules[0].weight"),
        ({"w": [0.0] * 5, "b": [0.0] * 21, "weight": "heavy"}, "rules[0].weight"),
    ],
)
def test_a_broken_utility_is_refused_with_its_field(tmp_path: Path, utility, field: str):
    """A file written before stages were listed (its ``utility`` read as the second stage's block)."""
    path = _model_with_utility(tmp_path / "bad.safetensors", utility)
    with pytest.raises(UserError) as err:
        load_policy(path)
    assert err.value.problems[0].field == field and str(path) in str(err.value)


def test_training_keeps_the_fitted_utility_with_the_model(tmp_path: Path):
    """The fitted utility round-trips through the model file; mirrored training data gives
    mirrored trajectory biases; without ``utility`` the file carries none."""
    rng = np.random.default_rng(0)
    n, m = 200, 21
    dataset = Dataset(
        rng.uniform(0, 1, (n, m, 5)).astype(np.float32), rng.integers(0, m, n), np.zeros(n, np.float32), np.zeros(n, np.int64), model_meta()
    )
    out = tmp_path / "m.safetensors"
    result = train_and_save(
        dataset, out, train_config(epochs=1, mirror=True), rules=[SecondStageConfig()], options=RunOptions(checkpoints=False)
    )
    (stage,) = result.rules
    np.testing.assert_allclose(stage.utility.b, stage.utility.b[::-1], atol=0.02)  # random labels: asymmetric without mirror
    model = load_model(out)
    (block,) = model.meta["rules"]
    assert block["type"] == "second_stage" and block["fit"] == "frames" and block["weight"] == 1.5
    np.testing.assert_allclose(block["w"], stage.utility.w)
    assert Planner(model).rule.header() == stage.header()  # the file round-trips the fitted stage
    train_and_save(dataset, tmp_path / "p.safetensors", train_config(epochs=1), options=RunOptions(checkpoints=False))
    assert load_model(tmp_path / "p.safetensors").meta["rules"] == []


def test_the_planner_drives_the_best_second_stage_score(tmp_path: Path):
    """With a utility, the decision is the argmax of the second stage's scores; F_t is still C's."""
    model = load_model(_model_with_utility(tmp_path / "la.safetensors", {"w": UTILITY.w.tolist(), "b": UTILITY.b.tolist()}))
    course = resolve_scenario("demo_course")
    renderer = SegmentationRenderer(PinholeCamera(), Simulation(course).world)
    plain = Planner(model, rule="argmax")
    for x in (8.0, 12.0, 16.0):
        pose = Pose(x, 10.0, 0.0)
        image = renderer.render(pose)
        waypoints = np.vstack([[x, 10.0], course.waypoints[1:]])
        planner = Planner(model)
        planner.set_path(waypoints)
        plain.set_path(waypoints)
        d, d0 = planner.decide(image, pose), plain.decide(image, pose)
        np.testing.assert_array_equal(d.probs, d0.probs)
        expected = planner.runner.scores(np.log(d.probs), SegmentationView.of(image), pose, planner.path, d.progress_m)
        assert d.index == int(np.argmax(expected))


def test_scores_are_the_linear_utility_of_the_second_stage_utilities(setup):
    """scores() sums without building U'; it must equal log F + weight * max_j (U' @ w + b)."""
    featurizer, camera, la = setup
    course = resolve_scenario("demo_course")
    renderer = SegmentationRenderer(camera, Simulation(course).world)
    path = ReferencePath(np.vstack([[8.0, 10.0], course.waypoints[1:]]))
    rng = np.random.default_rng(3)
    for x in (8.0, 12.0, 16.0, 20.0):
        pose = Pose(x, 10.0 + rng.uniform(-0.5, 0.5), rng.uniform(-0.2, 0.2))
        view = SegmentationView.of(renderer.render(pose))
        s = PathTracker(path).update(np.array(pose[:2]))
        log_probs = np.log(rng.dirichlet(np.ones(featurizer.m)))
        got = la.scores(log_probs, view, pose, path, s)
        rows = np.argsort(-log_probs, kind="stable")[: la.config.candidates]
        value = (la.utilities(view, pose, path, s, rows) @ UTILITY.w + UTILITY.b).max(axis=1)
        np.testing.assert_allclose(got[rows], log_probs[rows] + la.config.weight * value, rtol=0, atol=1e-9)
        assert np.isneginf(np.delete(got, rows)).all()


def _numpy_scores(
    stage: SecondStageScores, log_probs: np.ndarray, image: np.ndarray, pose: Pose, path: ReferencePath, s: float
) -> np.ndarray:
    """SecondStageRule.scores as NumPy computed it before its loop was compiled."""
    rows = np.argsort(-log_probs, kind="stable")[: stage.config.candidates]
    r, m = len(rows), stage.m
    terrain = np.take(stage._point_weight, image.reshape(-1)[stage.pix[rows].ravel()])
    terrain *= stage.seen[rows].ravel()
    d = _distances(stage, pose, path, s, rows)
    lo, hi = d.min(), d.max()
    distance = np.ones_like(d) if hi - lo < 1e-9 else (hi - d) * (1.0 / (hi - lo))
    value = (terrain.reshape(r, m, stage.points).sum(axis=2) + stage.w[stage.k] * distance + stage.b).max(axis=1)
    out = np.full(log_probs.shape, -np.inf)
    out[rows] = log_probs[rows] + stage.config.weight * value
    return out


def _targets(stage: SecondStageScores, path: ReferencePath, s0: float, rows: np.ndarray) -> np.ndarray:
    """Each candidate's target, (r, 2): the path point at s0 plus its start's forward offset."""
    line = path.straight_between(s0 + stage._x_lo, s0 + stage._x_hi)
    if line is None:
        return path.point_at(s0 + stage.starts[rows, 0])
    x, y, ux, uy = line
    t = stage.starts[rows, 0] - stage._x_lo
    return np.stack([x + t * ux, y + t * uy], axis=1)


def _distances(stage: SecondStageScores, pose: Pose, path: ReferencePath, s: float, rows: np.ndarray) -> np.ndarray:
    """The second pieces' end distances (r, m) as written out: the complex product by its
    formula, hypot from the C library (NumPy's, and the compiled loop's; not NumPy's SIMD complex
    ``abs``, which rounds differently per CPU)."""
    x, y, yaw = pose
    c, sn = math.cos(yaw), math.sin(yaw)
    targets = _targets(stage, path, s + stage._horizon_m, rows)
    ex, ey = stage.ends[rows, :, 0], stage.ends[rows, :, 1]
    re = (ex * c - ey * sn) + (x - targets[:, 0])[:, None]
    im = (ex * sn + ey * c) + (y - targets[:, 1])[:, None]
    return np.hypot(re, im)


def test_the_distances_are_numpys_complex_ones_to_the_last_bits(setup):
    """The written-out distances differ from NumPy's complex arithmetic (whose SIMD versions
    round differently per CPU) by a few units in the last place at most."""
    _, _, stage = setup
    rng = np.random.default_rng(8)
    path = ReferencePath(np.array([[0.0, 0.0], [6.0, 3.0], [9.0, -4.0], [40.0, 2.0]]))
    for _ in range(40):
        pose = Pose(rng.uniform(0, 12), rng.uniform(-3, 3), rng.uniform(-math.pi, math.pi))
        s = float(rng.uniform(0, 12))
        rows = rng.permutation(21)[:7]
        targets = _targets(stage, path, s + stage._horizon_m, rows)
        numpy_form = np.abs(
            (stage.ends[rows] @ (1.0, 1j)) * complex(math.cos(pose.yaw), math.sin(pose.yaw))
            + (complex(pose.x, pose.y) - (targets @ (1.0, 1j))[:, None])
        )
        np.testing.assert_allclose(_distances(stage, pose, path, s, rows), numpy_form, rtol=4e-16 * 8, atol=1e-14)


def test_the_compiled_stage_gives_the_numpy_forms_bits(setup):
    featurizer, camera, stage = setup
    rng = np.random.default_rng(9)
    paths = [_straight_path(), ReferencePath(np.array([[0.0, 0.0], [6.0, 3.0], [9.0, -4.0], [40.0, 2.0]]))]
    for trial in range(60):
        image = rng.integers(0, 6, (480, 640)).astype(np.uint8)
        log_probs = np.log(rng.dirichlet(np.ones(21)))
        if trial % 3 == 0:
            log_probs[rng.integers(0, 21, 4)] = -np.inf  # probabilities of exactly 0
        if trial % 2:
            log_probs = log_probs.astype(np.float32)  # as the planner's, from C's float32 logits
        pose = Pose(rng.uniform(0, 12), rng.uniform(-3, 3), rng.uniform(-0.8, 0.8))
        path = paths[trial % 2]
        s = float(rng.uniform(0, 12))
        expected = _numpy_scores(stage, log_probs, image, pose, path, s)
        got = stage.scores(log_probs, SegmentationView.of(image), pose, path, s)
        assert np.array_equal(got.view(np.int64), expected.view(np.int64)), trial


def test_a_second_stage_weight_past_what_its_file_reads_back_is_refused():
    """``train --stage-weight 2e9`` wrote a file whose block was then refused as read."""
    SecondStageConfig(weight=1e9)
    with pytest.raises(ValueError, match=r"weight 0 to 1e\+09"):
        SecondStageConfig(weight=2e9)
