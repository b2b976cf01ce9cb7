"""The planner (SPEC 9): one decision per frame from the image, the pose and the path; it never
reads the world map; it refuses a model trained for
another camera."""

from __future__ import annotations

import ast
import inspect
import math
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import torch

import terrapref.planner.planner as planner_module
from helpers import LINEAR_W, linear_model, model_meta, train_config
from terrapref.camera import CameraConfig, PinholeCamera, SegmentationRenderer, SegmentationView
from terrapref.dataset import build_dataset
from terrapref.demos.recording import read_recording
from terrapref.errors import UserError
from terrapref.features import FeatureConfig, UtilityFeaturizer
from terrapref.learning.model_file import LoadedModel, load_model, save_model
from terrapref.learning.network import ClassifierConfig, numpy_forward, softmax
from terrapref.learning.pipeline import RunOptions, train_and_save
from terrapref.planner import Decision, Planner, PlannerDriver
from terrapref.scenario import Scenario, resolve_scenario
from terrapref.scenario.path import PathTracker, ReferencePath
from terrapref.sim import Frame, Simulation, run_episode
from terrapref.vehicle import Command, Pose
from terrapref.world import WorldMap
from torch_net import UtilityClassifier


# Columns of U: non_traversable, water, rock, mud, distance. Avoid terrain, follow the path.
def _linear_model(path: Path, camera: CameraConfig | None = None) -> LoadedModel:
    return load_model(linear_model(path, camera))


def _random_model(path: Path) -> LoadedModel:
    config = ClassifierConfig(hidden=16, activation="elu")
    torch.manual_seed(5)
    weights = {k: v.detach().numpy().copy() for k, v in UtilityClassifier(config).state_dict().items()}
    return load_model(save_model(path, config, weights, model_meta()))


@pytest.fixture(scope="module")
def models(tmp_path_factory) -> SimpleNamespace:
    d = tmp_path_factory.mktemp("models")
    return SimpleNamespace(linear=_linear_model(d / "linear.safetensors"), random=_random_model(d / "random.safetensors"))


@pytest.fixture(scope="module")
def course() -> Scenario:
    return resolve_scenario("demo_course")


@pytest.fixture(scope="module")
def views(course: Scenario) -> SimpleNamespace:
    """Frames rendered before any planner exists: before the mud/rock pair, and at the start."""
    renderer = SegmentationRenderer(PinholeCamera(), Simulation(course).world)
    near = Pose(16.0, 10.0, 0.0)  # the pair spans x 18.5-25.5, both sides of the path
    start = Pose(*course.start)
    return SimpleNamespace(near=near, near_image=renderer.render(near), start=start, start_image=renderer.render(start))


def _planner(model: LoadedModel, course: Scenario, **kwargs) -> Planner:
    """A planner following the rest of the course from the ``near`` pose (x = 16 m on its first leg)."""
    planner = Planner(model, **kwargs)
    planner.set_path(_rest_of_course(course))
    return planner


def _rest_of_course(course: Scenario) -> np.ndarray:
    return np.vstack([[16.0, 10.0], course.waypoints[1:]])


# --- one decision ----------------------------------------------------------------------------------


@pytest.mark.parametrize("which", ["linear", "random"])
def test_decision_contract(models, course, views, which: str):
    model = getattr(models, which)
    planner = _planner(model, course)
    d = planner.decide(views.near_image, views.near)
    assert isinstance(d, Decision)
    m = model.classifier.m
    assert d.probs.shape == (m,) and np.all(d.probs >= 0)
    assert math.isclose(float(d.probs.sum()), 1.0, abs_tol=1e-6)
    assert d.index == int(np.argmax(d.probs))
    control = model.features.preference.control
    assert isinstance(d.command, Command) and tuple(d.command) == control.command(d.index)
    # U is the feature of this image, pose and path, as training computed it.
    path = ReferencePath(_rest_of_course(course))
    s = PathTracker(path).update(np.array(views.near[:2]))
    assert d.progress_m == pytest.approx(s) and d.progress_m == pytest.approx(0.0, abs=0.01)
    featurizer = UtilityFeaturizer(model.features, PinholeCamera(model.camera), model.classes)
    np.testing.assert_array_equal(d.U, featurizer(views.near_image, views.near, path, s))
    assert d.U.shape == (m, model.features.n_features)
    assert d.U[:, :-1].sum() > 0  # terrain is in view here


def test_linear_model_decides_by_the_linear_utility(models, course, views):
    d = _planner(models.linear, course).decide(views.near_image, views.near)
    np.testing.assert_allclose(d.probs, softmax(d.U.astype(np.float64) @ LINEAR_W), atol=1e-6)
    assert d.index == int(np.argmax(d.U.astype(np.float64) @ LINEAR_W))


def test_decide_needs_a_path(models, views):
    with pytest.raises(RuntimeError):
        Planner(models.linear).decide(views.start_image, views.start)


def test_warm_up_decides_once_and_forgets_it(models, course, views):
    cold = Planner(models.random)
    cold.warm_up()
    with pytest.raises(RuntimeError):  # no path was set, and the warm-up's is gone
        cold.decide(views.start_image, views.start)
    planner, fresh = _planner(models.random, course), _planner(models.random, course)
    first = planner.decide(views.near_image, views.near)
    planner.warm_up()  # mid-drive: the path and the progress along it are kept
    assert (
        planner.decide(views.near_image, views.near).probs.tolist()
        == fresh.decide(views.near_image, views.near).probs.tolist()
        == first.probs.tolist()
    )
    assert planner.tracker is not None and planner.path is not None


# --- memory -------------------------------------------------------------------------------------------


def test_memoryless_by_default(models, course, views):
    grass = np.zeros_like(views.near_image)  # nothing but grass: a different first frame
    fresh = _planner(models.random, course).decide(views.near_image, views.near)
    planner = _planner(models.random, course)
    first = planner.decide(grass, views.near)
    assert not np.allclose(first.probs, fresh.probs)  # the two frames do differ
    again = planner.decide(views.near_image, views.near)
    np.testing.assert_array_equal(again.probs, fresh.probs)
    assert again.index == fresh.index
    np.testing.assert_array_equal(planner.decide(views.near_image, views.near).probs, fresh.probs)


# --- the planner has no map -------------------------------------------------------------------------


def _reachable(root: object, depth: int = 6) -> list[object]:
    """Every object reachable from ``root`` through attributes and containers (arrays are leaves)."""
    seen: set[int] = set()
    out: list[object] = []
    stack = [(root, 0)]
    while stack:
        obj, d = stack.pop()
        if id(obj) in seen or d > depth or obj is None or isinstance(obj, (str, bytes, int, float, bool, type)):
            continue
        seen.add(id(obj))
        out.append(obj)
        if isinstance(obj, np.ndarray):
            continue
        if isinstance(obj, dict):
            children = list(obj.keys()) + list(obj.values())
        elif isinstance(obj, (list, tuple, set, frozenset)):
            children = list(obj)
        else:
            children = list(getattr(obj, "__dict__", {}).values())
            children += [getattr(obj, s) for s in getattr(type(obj), "__slots__", ()) if hasattr(obj, s)]
        stack.extend((c, d + 1) for c in children)
    return out


def test_planner_holds_no_world_map_after_driving(models, course):
    sim = Simulation(course)
    driver = PlannerDriver(Planner(models.linear), keep=True)
    log = run_episode(sim, driver, np.random.default_rng(0))
    assert len(driver.decisions) == len(log.commands) > 100
    np.testing.assert_array_equal(log.commands, [tuple(d.command) for d in driver.decisions])
    held = _reachable(driver)
    assert not [o for o in held if isinstance(o, (WorldMap, SegmentationRenderer, Simulation, Scenario))]
    assert not [o for o in held if isinstance(o, np.ndarray) and np.shares_memory(o, sim.world.raster)]
    assert not [o for o in held if isinstance(o, np.ndarray) and o.shape == sim.world.raster.shape]


def test_planner_module_does_not_import_the_world():
    for module in (planner_module, __import__("terrapref.planner", fromlist=["x"])):
        tree = ast.parse(inspect.getsource(module))
        imported: list[str] = []
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                imported += [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                imported += [node.module or ""] + [f"{node.module}.{a.name}" for a in node.names]
        assert not [n for n in imported if n.startswith("terrapref.world")], module.__name__
        assert not [n for n in imported if n.endswith(("rasterise", "WorldMap", "SegmentationRenderer")) or "camera.render" in n], (
            module.__name__
        )


def test_planner_decides_without_the_world_map(models, course, monkeypatch):
    """Replay a drive with every way to the map blocked: the decisions are the same."""

    class Recorder:
        def __init__(self, inner: PlannerDriver) -> None:
            self.inner, self.frames, self.commands = inner, [], []

        def reset(self, scenario, rng) -> None:
            self.inner.reset(scenario, rng)

        def act(self, frame: Frame) -> Command:
            self.commands.append(self.inner.act(frame))  # reads only the pixels it needs
            self.frames.append(replace(frame, view=SegmentationView.of(frame.image)))  # kept whole for the replay
            return self.commands[-1]

    sim = Simulation(course)
    sim.time_limit_s = 20.0  # the first 200 frames: the water, and into the mud/rock pair
    rec = Recorder(PlannerDriver(Planner(models.linear), keep=True))
    run_episode(sim, rec, np.random.default_rng(0))
    assert len(rec.frames) == 200
    assert any(rec.inner.decisions[i].U[:, :-1].sum() > 0 for i in range(len(rec.frames)))  # terrain was seen

    def no_map(*args, **kwargs):
        raise AssertionError("the planner read the world map")

    monkeypatch.setattr(WorldMap, "class_at", no_map)
    monkeypatch.setattr(WorldMap, "class_at_point", no_map)
    monkeypatch.setattr(WorldMap, "cells_of", no_map)
    monkeypatch.setattr(SegmentationRenderer, "render", no_map)
    monkeypatch.setattr(SegmentationRenderer, "pixels", no_map)
    for target in ("terrapref.world.rasterise", "terrapref.world.raster.rasterise", "terrapref.sim.loop.rasterise"):
        monkeypatch.setattr(target, no_map)

    driver = PlannerDriver(Planner(models.linear), keep=True)
    driver.reset(SimpleNamespace(waypoints=course.waypoints.copy()), np.random.default_rng(0))  # only the path
    replayed = [driver.act(f) for f in rec.frames]
    assert replayed == rec.commands  # and whole frames give what the pixels read alone gave
    for a, b in zip(driver.decisions, rec.inner.decisions, strict=True):
        np.testing.assert_array_equal(a.probs, b.probs)


def test_driving_is_deterministic(models, course):
    logs = []
    for seed in (0, 1):
        sim = Simulation(course)
        sim.time_limit_s = 15.0
        logs.append(run_episode(sim, PlannerDriver(Planner(models.random)), np.random.default_rng(seed)))
    assert len(logs[0].commands) == 150
    np.testing.assert_array_equal(logs[0].trace, logs[1].trace)  # the planner draws nothing from the rng


# --- camera compatibility ----------------------------------------------------------------------------


def test_model_for_another_camera_is_refused(tmp_path: Path, models):
    tilted = replace(CameraConfig(), pitch_deg=25.0)
    with pytest.raises(UserError) as err:
        Planner(models.linear, camera=tilted)
    assert err.value.source == models.linear.path and "pitch_deg" in str(err.value)
    other = _linear_model(tmp_path / "tilted.safetensors", camera=tilted)
    with pytest.raises(UserError) as err:
        Planner(other, camera=CameraConfig())
    assert str(tmp_path / "tilted.safetensors") in str(err.value) and "pitch_deg" in str(err.value)
    # With no camera given, the planner uses the one the model was trained for.
    assert Planner(other).camera.config == tilted
    assert Planner(other, camera=tilted).camera.config == tilted


# --- a model trained on a real demonstration -----------------------------------------------------------


@pytest.fixture(scope="module")
def demo(tmp_path_factory, demo_course_drive) -> SimpleNamespace:
    """The synthetic driver's demonstration of demo_course (tests/conftest.py), featurised, and a 3-epoch model."""
    d = tmp_path_factory.mktemp("demo")
    features = FeatureConfig()
    recording = read_recording(demo_course_drive.path)
    dataset = build_dataset([recording], features)
    result = train_and_save(dataset, d / "model.safetensors", train_config(epochs=3, skip=True), options=RunOptions(checkpoints=False))
    return SimpleNamespace(recording=recording, dataset=dataset, result=result, model=load_model(d / "model.safetensors"))


def test_planner_sees_what_training_saw(demo):
    """Replaying the demonstration through the planner reproduces the training features exactly,
    and its probabilities are the trained classifier's."""
    rec, data, model = demo.recording, demo.dataset, demo.model
    assert len(data) == len(rec) > 300 and data.U[:, :, :-1].sum() > 0
    planner = Planner(model)
    planner.set_path(np.asarray(rec.meta["path"]))
    for i in range(len(rec)):
        d = planner.decide(rec.image(i), Pose(*rec.poses[i]))
        np.testing.assert_array_equal(d.U, data.U[i], err_msg=f"frame {i}")
        if i % 25 == 0:
            np.testing.assert_allclose(d.probs, softmax(numpy_forward(model.classifier, demo.result.weights, data.U[i])), atol=1e-6)
            assert d.index == int(np.argmax(d.probs)) and tuple(d.command) == model.features.preference.control.command(d.index)
    assert model.meta["data"]["recordings"][0]["scenario"] == "demo_course"
