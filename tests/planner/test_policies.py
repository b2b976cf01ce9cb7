"""Policies behind the planner (classifier, linear, hand cost, pure pursuit), the linear utility
fit, policy files, and the classifier's ignored-column ablation."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from helpers import model_meta
from terrapref.camera import CameraConfig, PinholeCamera, SegmentationRenderer, SegmentationView
from terrapref.errors import UserError
from terrapref.features import FeatureConfig
from terrapref.learning.linear import LinearUtility, fit_linear_utility
from terrapref.learning.model_file import FORMAT, load_model, save_model
from terrapref.learning.network import ClassifierConfig, numpy_forward, softmax
from terrapref.planner import Planner
from terrapref.planner.policy import (
    HAND_DISTANCE_WEIGHT,
    ClassifierPolicy,
    CostPolicy,
    LinearPolicy,
    Observation,
    Policy,
    PurePursuitPolicy,
    hand_costs,
    save_linear,
)
from terrapref.planner.registry import load_policy
from terrapref.scenario import resolve_scenario
from terrapref.sim import Simulation
from terrapref.tensorfile import write_tensor_file
from terrapref.terrain import default_classes
from terrapref.vehicle import Pose
from torch_net import UtilityClassifier

M, K = 21, 5  # trajectories; utility columns (non_traversable, water, rock, mud, distance)
NO_IMAGE = SegmentationView.of(np.zeros((4, 4), np.uint8))
NO_POINTS = np.zeros((0, 2))


def _torch_weights(config: ClassifierConfig, seed: int = 3) -> dict[str, np.ndarray]:
    torch.manual_seed(seed)
    return {k: v.detach().numpy().copy() for k, v in UtilityClassifier(config).state_dict().items()}


def _obs(U: np.ndarray, path_ahead: np.ndarray = NO_POINTS) -> Observation:
    return Observation(U, NO_IMAGE, path_ahead)


# --- the linear utility fit ----------------------------------------------------------------------


def test_fit_linear_utility_recovers_the_ranking():
    rng = np.random.default_rng(0)
    n = 1500
    w_true = np.array([-3.0, -2.0, -1.0, -0.4, 1.5])
    U = rng.uniform(0.0, 1.0, size=(n, M, K))
    labels = np.argmax(U @ w_true + 0.05 * rng.standard_normal((n, M)), axis=1)
    fit = fit_linear_utility(U, labels)
    assert isinstance(fit, LinearUtility)
    assert fit.w.shape == (K,) and fit.b.shape == (M,)
    np.testing.assert_array_equal(np.sign(fit.w), np.sign(w_true))
    np.testing.assert_array_equal(np.argsort(fit.w), np.argsort(w_true))
    # The scale is free (the data nearly separate), the direction is not.
    cos = fit.w @ w_true / (np.linalg.norm(fit.w) * np.linalg.norm(w_true))
    assert cos > 0.98
    accuracy = float(np.mean(np.argmax(fit.logits(U), axis=1) == labels))
    assert accuracy > 0.85
    # The per-trajectory biases carry nothing here (no trajectory is favoured).
    assert np.abs(fit.b).max() < 0.2 * np.abs(fit.w).max()


def test_fit_linear_utility_sample_weight_zero_ignores_samples():
    """Samples with weight 0 do not move the fit: appending contradictory ones changes nothing."""
    rng = np.random.default_rng(1)
    w_true = np.array([-2.0, -1.0, -0.5, -0.2, 1.0])
    U = rng.uniform(size=(300, M, K))
    labels = np.argmax(U @ w_true, axis=1)
    base = fit_linear_utility(U, labels, steps=300)
    bad = np.argmin(U @ w_true, axis=1)  # the worst trajectory each time
    both = fit_linear_utility(
        np.concatenate([U, U]), np.concatenate([labels, bad]), steps=300, sample_weight=np.concatenate([np.ones(300), np.zeros(300)])
    )
    # Equal up to the fixed-point rounding of the exact products (twice the terms: one bit fewer).
    np.testing.assert_allclose(both.w, base.w, rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(both.b, base.b, rtol=1e-4, atol=1e-6)


# --- linear and hand-cost policies -------------------------------------------------------------


def test_linear_policy_logits_are_w_dot_u_plus_b():
    rng = np.random.default_rng(2)
    w, b = rng.normal(size=K), rng.normal(size=M)
    policy = LinearPolicy(LinearUtility(w, b))
    assert isinstance(policy, Policy) and not policy.uses_path_ahead
    U = rng.uniform(size=(M, K))
    np.testing.assert_allclose(policy.logits(_obs(U)), U @ w + b, rtol=1e-12)


def test_linear_policy_refuses_wrong_shapes():
    with pytest.raises(ValueError):
        LinearPolicy(LinearUtility(np.zeros(K - 1), np.zeros(M)))
    with pytest.raises(ValueError):
        LinearPolicy(LinearUtility(np.zeros(K), np.zeros(M + 1)))


def test_cost_policy_weights_follow_the_feature_columns():
    features = FeatureConfig()
    policy = CostPolicy()
    costs = {"mud": 2.0, "rock": 4.0, "water": 8.0, "non_traversable": 50.0}  # the default profile's, by rank
    assert hand_costs() == costs
    expected = [-costs[name] for name in features.feature_classes] + [HAND_DISTANCE_WEIGHT]
    np.testing.assert_array_equal(policy.utility.w, expected)
    np.testing.assert_array_equal(policy.utility.b, np.zeros(M))
    # Custom costs: missing classes cost nothing, the distance weight comes last.
    custom = CostPolicy({"rock": 3.0, "non_traversable": 10.0}, distance_weight=0.5)
    cols = list(features.column_names)
    w = dict(zip(cols, custom.utility.w))
    assert w == {"non_traversable": -10.0, "water": 0.0, "rock": -3.0, "mud": 0.0, "distance": 0.5}
    # The policy ranks trajectories by the cost: a trajectory on mud beats one on water.
    U = np.zeros((M, K))
    U[:, cols.index("distance")] = 0.5
    U[3, cols.index("water")] = 1.0
    U[4, cols.index("mud")] = 1.0
    logits = policy.logits(_obs(U))
    assert logits[4] > logits[3]
    assert logits[0] > logits[4]


def test_hand_costs_of_another_table_follow_its_profile():
    from terrapref.terrain import load_classes

    table = load_classes("examples/classes/rellis3d.yaml")  # profile dirt > gravel > puddle > mud > bush > water > lethal
    assert hand_costs(table) == {"dirt": 2.0, "gravel": 4.0, "puddle": 8.0, "mud": 16.0, "bush": 32.0, "water": 64.0, "lethal": 128.0}
    policy = CostPolicy(classes=table)
    assert policy.features.feature_classes == table.feature_names
    w = dict(zip(policy.features.column_names, policy.utility.w))
    assert w["water"] == -64.0 and w["lethal"] == -128.0 and w["distance"] == HAND_DISTANCE_WEIGHT


def test_cost_policy_rejects_an_unknown_class():
    with pytest.raises(ValueError, match="lava"):
        CostPolicy({"mud": 1.0, "lava": 5.0})


# --- pure pursuit ----------------------------------------------------------------------------------


def _path(curve: float) -> np.ndarray:
    x = np.arange(1.0, 9.0)
    return np.stack([x, curve * x**2], axis=1)


def test_pure_pursuit_straight_path_drives_straight():
    policy = PurePursuitPolicy()
    assert policy.uses_path_ahead
    U = np.random.default_rng(3).uniform(size=(M, K))  # terrain is ignored
    logits = policy.logits(_obs(U, _path(0.0)))
    assert logits.shape == (M,)
    assert int(np.argmax(logits)) == 10
    assert policy.features.preference.control.w_rps[10] == 0.0


@pytest.mark.parametrize("curve", [0.05, 0.1, 0.2])
def test_pure_pursuit_turns_toward_the_path_and_mirrors(curve: float):
    policy = PurePursuitPolicy()
    left = int(np.argmax(policy.logits(_obs(np.zeros((M, K)), _path(curve)))))
    right = int(np.argmax(policy.logits(_obs(np.zeros((M, K)), _path(-curve)))))
    assert left > 10
    assert right == 20 - left
    # A sharper curve is never a gentler turn.
    sharper = int(np.argmax(policy.logits(_obs(np.zeros((M, K)), _path(2 * curve)))))
    assert sharper >= left


def test_pure_pursuit_ignores_terrain():
    policy = PurePursuitPolicy()
    rng = np.random.default_rng(4)
    a = policy.logits(_obs(rng.uniform(size=(M, K)), _path(0.1)))
    b = policy.logits(_obs(rng.uniform(size=(M, K)), _path(0.1)))
    np.testing.assert_array_equal(a, b)


# --- policy files ------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def classifier_file(tmp_path_factory) -> SimpleNamespace:
    d = tmp_path_factory.mktemp("models")
    config = ClassifierConfig(hidden=8, activation="tanh")
    weights = _torch_weights(config)
    path = save_model(d / "c.safetensors", config, weights, model_meta())
    return SimpleNamespace(path=path, config=config, weights=weights, model=load_model(path))


def test_save_linear_load_policy_round_trip(tmp_path: Path):
    rng = np.random.default_rng(5)
    utility = LinearUtility(rng.normal(size=K), rng.normal(size=M))
    path = save_linear(tmp_path / "lin.safetensors", utility, model_meta())
    assert path.is_file()
    policy = load_policy(path)
    assert type(policy) is LinearPolicy
    assert policy.path == str(path) and policy.profile == tuple(default_classes().profile)
    assert policy.camera == CameraConfig() and policy.features == FeatureConfig()
    # Stored as float32: the logits match the float32-rounded weights exactly.
    U = rng.uniform(size=(M, K))
    expected = LinearPolicy(LinearUtility(utility.w.astype(np.float32).astype(float), utility.b.astype(np.float32).astype(float)))
    np.testing.assert_array_equal(policy.logits(_obs(U)), expected.logits(_obs(U)))
    np.testing.assert_allclose(policy.logits(_obs(U)), utility.logits(U), atol=1e-5)


def test_load_policy_of_a_classifier_file(classifier_file):
    policy = load_policy(classifier_file.path)
    assert isinstance(policy, ClassifierPolicy)
    assert policy.path == str(classifier_file.path)
    U = np.random.default_rng(6).uniform(size=(M, K))
    expected = softmax(numpy_forward(classifier_file.config, classifier_file.weights, U))
    np.testing.assert_allclose(policy.probabilities(_obs(U)), expected, atol=1e-6)
    # logits are log F_t: the same scores up to a constant, so the same argmax and softmax
    np.testing.assert_allclose(softmax(policy.logits(_obs(U))), expected, atol=1e-6)


def test_load_model_refuses_a_linear_file(tmp_path: Path):
    path = save_linear(tmp_path / "lin.safetensors", LinearUtility(np.zeros(K), np.zeros(M)), model_meta())
    with pytest.raises(UserError) as err:
        load_model(path)
    assert "linear" in str(err.value) and str(path) in str(err.value)
    assert err.value.problems[0].field == "kind"


def test_load_policy_refuses_an_unknown_kind(tmp_path: Path, classifier_file):
    meta = classifier_file.model.meta
    header = {"format": FORMAT, "kind": "bogus", **{k: meta[k] for k in ("features", "camera", "classes", "profile")}}
    path = write_tensor_file(tmp_path / "bogus.safetensors", {"w": np.zeros(K, np.float32)}, header)
    with pytest.raises(UserError) as err:
        load_policy(path)
    assert "bogus" in str(err.value) and str(path) in str(err.value)
    with pytest.raises(UserError):
        load_model(path)


def test_load_policy_refuses_a_linear_file_with_wrong_shapes(tmp_path: Path):
    path = write_tensor_file(
        tmp_path / "lin.safetensors",
        {"w": np.zeros(K + 1, np.float32), "b": np.zeros(M, np.float32)},
        {"format": FORMAT, "kind": "linear", **model_meta()},
    )
    with pytest.raises(UserError) as err:
        load_policy(path)
    assert err.value.problems[0].field == "weights.w"


@pytest.mark.parametrize("value", [np.nan, -np.inf])
def test_load_policy_refuses_a_linear_file_of_weights_that_are_not_finite(tmp_path: Path, value: float):
    w = np.zeros(K, np.float32)
    w[2] = value
    header = {"format": FORMAT, "kind": "linear", **model_meta()}
    path = write_tensor_file(tmp_path / "lin.safetensors", {"w": w, "b": np.zeros(M, np.float32)}, header)
    with pytest.raises(UserError) as err:  # not a policy that scores every trajectory NaN
        load_policy(path)
    assert err.value.source == str(path) and [p.field for p in err.value.problems] == ["weights.w"]
    assert "1 of its 5 weights are NaN or infinite" in str(err.value)


# --- the planner takes any policy -------------------------------------------------------------------


@pytest.fixture(scope="module")
def view() -> SimpleNamespace:
    course = resolve_scenario("demo_course")
    pose = Pose(16.0, 10.0, 0.0)  # before the mud/rock pair
    image = SegmentationRenderer(PinholeCamera(), Simulation(course).world).render(pose)
    return SimpleNamespace(course=course, pose=pose, image=image, path=np.vstack([[16.0, 10.0], course.waypoints[1:]]))


def test_planner_accepts_a_policy_and_a_model(view, classifier_file):
    policy = CostPolicy()
    planner = Planner(policy)
    assert planner.policy is policy
    planner.set_path(view.path)
    d = planner.decide(view.image, view.pose)
    assert d.U[:, :-1].sum() > 0  # terrain is in view
    np.testing.assert_allclose(d.probs, softmax(d.U.astype(float) @ policy.utility.w), atol=1e-6)
    assert d.index == int(np.argmax(d.U.astype(float) @ policy.utility.w))

    model_planner = Planner(classifier_file.model)
    assert isinstance(model_planner.policy, ClassifierPolicy)
    model_planner.set_path(view.path)
    dm = model_planner.decide(view.image, view.pose)
    np.testing.assert_array_equal(dm.U, d.U)
    np.testing.assert_allclose(dm.probs, softmax(numpy_forward(classifier_file.config, classifier_file.weights, dm.U)), atol=1e-6)


def test_planner_with_pure_pursuit_follows_the_path(view):
    planner = Planner(PurePursuitPolicy())
    planner.set_path(view.path)
    d = planner.decide(view.image, view.pose)
    assert d.index == 10  # on the straight first leg, heading along it
    planner.set_path(view.path)
    d = planner.decide(view.image, Pose(16.0, 10.0, -0.3))  # turned right of the path: steer left
    assert d.index > 10


def test_planner_refuses_a_policy_for_another_camera():
    tilted = replace(CameraConfig(), pitch_deg=25.0)
    with pytest.raises(ValueError, match="camera"):
        Planner(CostPolicy(camera=tilted), camera=CameraConfig())
    with pytest.raises(ValueError):
        Planner(PurePursuitPolicy(), camera=tilted)
    # With no camera given, the planner uses the policy's.
    assert Planner(CostPolicy(camera=tilted)).camera.config == tilted


# --- ignored columns ----------------------------------------------------------------------------------


def test_ignored_column_does_not_change_the_output():
    config = ClassifierConfig(hidden=16, ignore=(4,))
    weights = _torch_weights(config, seed=7)
    rng = np.random.default_rng(8)
    U = rng.uniform(size=(6, M, K)).astype(np.float32)
    U2 = U.copy()
    U2[..., 4] = rng.uniform(size=(6, M))
    out = numpy_forward(config, weights, U)
    np.testing.assert_array_equal(out, numpy_forward(config, weights, U2))
    U3 = U.copy()
    U3[..., 0] += 1.0  # a seen column does matter
    assert not np.allclose(out, numpy_forward(config, weights, U3))
    # numpy_forward does not write into its input.
    U_before = U.copy()
    numpy_forward(config, weights, U)
    np.testing.assert_array_equal(U, U_before)


def test_ignore_out_of_range_is_refused():
    with pytest.raises(ValueError):
        ClassifierConfig(n_features=5, ignore=(7,))
    with pytest.raises(ValueError):
        ClassifierConfig(n_features=5, ignore=(-1,))


def test_ignore_survives_to_dict_from_dict(tmp_path: Path):
    config = ClassifierConfig(hidden=8, ignore=(4, 1))
    d = config.to_dict()
    assert d["ignore"] == [4, 1]
    back = ClassifierConfig.from_dict(d)
    assert back == config and back.ignore == (4, 1)
    # And through a model file.
    path = save_model(tmp_path / "c.safetensors", config, _torch_weights(config), model_meta())
    assert load_model(path).classifier.ignore == (4, 1)


@pytest.mark.parametrize("kw", [{}, {"skip": True}, {"compress": False}])
def test_torch_and_numpy_agree_with_ignore(kw: dict):
    config = ClassifierConfig(hidden=16, activation="elu", ignore=(4,), **kw)
    torch.manual_seed(9)
    net = UtilityClassifier(config).eval()
    weights = {k: v.detach().numpy().copy() for k, v in net.state_dict().items()}
    U = np.random.default_rng(10).uniform(size=(5, M, K)).astype(np.float32)
    with torch.no_grad():
        t = net(torch.from_numpy(U.copy())).numpy()
        t2 = net(torch.from_numpy(np.concatenate([U[..., :4], np.full_like(U[..., 4:], 9.0)], axis=-1))).numpy()
    np.testing.assert_allclose(numpy_forward(config, weights, U), t, atol=1e-5)
    np.testing.assert_allclose(t2, t, atol=1e-6)  # torch ignores the column too


@pytest.mark.slow  # a whole drive or export end to end, its steps tested apart in the default run
def test_evaluate_command_drives_a_linear_model_file(tmp_path, capsys):
    """`terrapref evaluate` takes a baseline's model file as well as C's."""
    from terrapref.cli import main
    from terrapref.planner.policy import save_linear

    features = FeatureConfig()
    w = np.array([-50.0, -8.0, -4.0, -2.0, 2.0])
    path = save_linear(tmp_path / "linear.safetensors", LinearUtility(w, np.zeros(features.preference.m)), model_meta())
    out = tmp_path / "eval"
    assert main(["evaluate", str(path), "demo_course", "--seeds", "1", "--out", str(out), "--no-driver", "--workers", "1"]) == 0
    import json

    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["summary"]["runs"] == 1 and metrics["summary"]["zones"] > 0
    assert (out / "demo_course.png").exists()
    assert "zone success" in capsys.readouterr().out


# --- the registry of policies --------------------------------------------------------------------


def test_policies_are_registered_by_name_and_built_or_loaded_by_it(tmp_path: Path):
    import doctest

    import terrapref.planner.registry as registry
    from terrapref.planner.policy import Policy, PurePursuitPolicy

    assert doctest.testmod(registry, verbose=False).failed == 0
    assert registry.kinds(from_file=True) == ["classifier", "linear", "cnn"]
    assert registry.kinds(from_file=False) == ["pure_pursuit", "hand_cost"]
    assert isinstance(registry.make("pure_pursuit"), PurePursuitPolicy)
    with pytest.raises(ValueError, match="unknown policy 'linear'"):
        registry.make("linear")  # a file kind is loaded, not made
    with pytest.raises(ValueError, match="already registered"):
        registry.register("pure_pursuit", PurePursuitPolicy)
    with pytest.raises(TypeError):
        Policy()  # the interface is abstract: a policy must score trajectories


def test_only_a_policy_trained_with_a_second_stage_brings_one(classifier_file):
    from terrapref.planner.policy import ClassifierPolicy, CostPolicy

    assert CostPolicy().rules == ()
    assert ClassifierPolicy(classifier_file.model).rules == ()  # trained without one
    block = {"type": "second_stage", "weight": 5.0, "w": [0.0, 1.0, 2.0, 3.0, 4.0], "b": [0.0] * 21, "fit": "frames"}
    model = classifier_file.model
    with_stage = replace(model, header=replace(model.header, rules=(block,)))
    (stage,) = ClassifierPolicy(with_stage).rules
    assert stage.type == "second_stage" and stage.config.weight == 5.0 and list(stage.utility.w) == block["w"]
    assert stage.header() == {**block, "after_s": 2.4, "stride": 2, "candidates": 7}


def test_drivers_are_registered_by_name_like_policies():
    from terrapref.evaluation.runner import RunSpec, drivers, register_driver, run_one

    assert drivers() == ["driver", "planner", "pure_pursuit", "hand_cost"]
    with pytest.raises(ValueError, match="already registered"):
        register_driver("driver", lambda *a: None)
    with pytest.raises(ValueError, match="unknown driver 'bogus'; drivers: driver, planner, pure_pursuit, hand_cost"):
        run_one(RunSpec("demo_course", 0, "bogus", None, ("mud", "rock", "water", "non_traversable")))


def test_one_model_type_loads_saves_and_plans_with_every_kind_of_file(tmp_path: Path):
    """Model: C's file (with its rules) and a baseline's, read, written back as read, and planned
    with; only C's is exported as a graph."""
    from helpers import linear_model
    from terrapref.cli import main
    from terrapref.planner.model import Model
    from terrapref.tensorfile import read_tensor_file

    rng = np.random.default_rng(6)
    files = {
        "classifier": linear_model(tmp_path / "c.safetensors"),
        "linear": save_linear(tmp_path / "lin.safetensors", LinearUtility(rng.normal(size=K), rng.normal(size=M)), model_meta()),
    }
    for kind, path in files.items():
        model = Model.load(path)
        assert model.kind == kind and model.path == str(path) and model.classes == default_classes() and model.rules == ()
        assert model.driving.type == "argmax" and (model.classifier is not None) == (kind == "classifier")
        again = model.save(tmp_path / f"again_{kind}.safetensors")
        (t1, m1), (t2, m2) = read_tensor_file(path, FORMAT, "", ""), read_tensor_file(again, FORMAT, "", "")
        assert m1 == m2 and t1.keys() == t2.keys() and all(np.array_equal(t1[k], t2[k]) for k in t1)
        planner = model.planner()
        planner.set_path(np.array([[0.0, 0.0], [20.0, 0.0]]))
        assert np.isfinite(planner.decide(np.full(planner.camera.shape, 0, np.uint8), (0.0, 0.0, 0.0)).command.w)
    assert main(["export", str(files["linear"]), "--format", "onnx", "--out", str(tmp_path / "l.onnx")]) == 2
    assert not (tmp_path / "l.onnx").exists()
