"""C's compiled forward pass (terrapref.learning.forward): what the planner decides with.

It must agree with the readable NumPy form (numpy_forward) to float32 rounding, give the same
bits whatever the CPU offers, and leave the planner's decisions exactly as they were before it
replaced the NumPy form: tests/data/planner_decisions.json holds closed-loop decisions made then
(tests/data/make_planner_decisions.py, commit 7a92879), of models trained here.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from cpu_settings import CpuCheck
from helpers import TESTS
from terrapref.dataset import build_dataset
from terrapref.demos.expert import ExpertDriver
from terrapref.learning.forward import PackedNetwork, probabilities
from terrapref.learning.mlp import init_weights
from terrapref.learning.model_file import load_model
from terrapref.learning.network import ClassifierConfig, numpy_forward, softmax
from terrapref.learning.pipeline import RunOptions, train_and_save
from terrapref.planner import Planner, PlannerDriver
from terrapref.recipes import PAPER, TEACH, RecipeSetup, demonstrate
from terrapref.scenario import resolve_scenario
from terrapref.sim import SimConfig, Simulation, run_episode
from terrapref.vehicle import VehicleConfig

DATA = TESTS / "data"

CONFIGS = [
    ClassifierConfig(skip=True, members=3),
    ClassifierConfig(),
    ClassifierConfig(hidden=16, activation="tanh", depth=2),
    ClassifierConfig(hidden=16, activation="elu", skip=True, members=2),
    ClassifierConfig(hidden=8, compress=False),
    ClassifierConfig(m=7, n_features=3, hidden=5, depth=4, skip=True, ignore=(1,)),
]


def _ensemble_weights(config: ClassifierConfig, rng: np.random.Generator) -> dict[str, np.ndarray]:
    one = replace(config, members=1)
    if config.members == 1:
        return {k: v.astype(np.float32) for k, v in init_weights(one, rng).items()}
    return {f"members.{j}.{k}": v.astype(np.float32) for j in range(config.members) for k, v in init_weights(one, rng).items()}


@pytest.mark.parametrize("config", CONFIGS, ids=lambda c: f"{c.activation}-h{c.hidden}-m{c.members}-skip{c.skip}-compress{c.compress}")
def test_compiled_forward_agrees_with_the_numpy_form(config: ClassifierConfig):
    rng = np.random.default_rng(5)
    weights = _ensemble_weights(config, rng)
    net = PackedNetwork.of(config, weights)
    for _ in range(20):
        U = (rng.random((config.m, config.n_features)) * (rng.random((config.m, config.n_features)) < 0.4)).astype(np.float32)
        got = probabilities(net, U)
        want = softmax(numpy_forward(config, weights, U).astype(np.float64))
        assert got.dtype == np.float64 and abs(got.sum() - 1.0) < 1e-12
        np.testing.assert_allclose(got, want, rtol=2e-5, atol=1e-7)


_BITS = """
import hashlib, numpy as np
from terrapref.learning.forward import PackedNetwork, probabilities
from terrapref.learning.mlp import init_weights
from terrapref.learning.network import ClassifierConfig
config = ClassifierConfig(skip=True, members=3)
rng = np.random.default_rng(1)
w = {f"members.{j}.{k}": v.astype(np.float32) for j in range(3) for k, v in init_weights(ClassifierConfig(skip=True), rng).items()}
net = PackedNetwork.of(config, w)
h = hashlib.sha256()
for _ in range(50):
    h.update(probabilities(net, rng.random((21, 5)).astype(np.float32)).tobytes())
print(h.hexdigest())
"""


CPU_CHECK = CpuCheck.of(
    "compiled forward",
    _BITS,
    [{}, {"NPY_DISABLE_CPU_FEATURES": "X86_V4,AVX512_ICL,AVX512_SPR"}, {"OPENBLAS_CORETYPE": "Prescott"}, {"NUMBA_CPU_NAME": "generic"}],
)


def test_compiled_forward_gives_the_same_bits_for_a_generic_cpu(cpu_outputs):
    hashes = {out.strip() for _, out in cpu_outputs["compiled forward"]}
    assert len(cpu_outputs["compiled forward"]) >= 2 and len(hashes) == 1


@pytest.mark.slow
def test_compiled_forward_gives_the_same_bits_under_other_cpu_settings(cpu_outputs_every):
    hashes = {out.strip() for _, out in cpu_outputs_every["compiled forward"]}
    assert len(hashes) == 1


# (recipe, epochs, demonstration course, courses driven): as make_planner_decisions.py made them,
# teach_course as it was then (its non_traversable situations were pairs until 2026-11-25).
# Recipe teach's run (three members and the second stage; about 15 s) is among the slow tests:
# the paper's run checks the decisions in the default run, and the ensemble's forward pass is
# checked against the NumPy form and under every CPU setting above.
GOLDEN_RUNS = [
    pytest.param(
        TEACH,
        40,
        str(DATA / "teach_course_pairs.yaml"),
        ("test_course", "fig8_water_mud_rock_mud_left"),
        id="teach",
        marks=pytest.mark.slow,
    ),
    pytest.param(PAPER, 15, "train_course", ("test_course",), id="paper"),
]


@pytest.mark.parametrize(("recipe", "epochs", "course", "driven"), GOLDEN_RUNS)
def test_the_planner_makes_the_decisions_it_made_before_the_forward_pass_was_compiled(
    tmp_path, monkeypatch, recipe, epochs, course, driven
):
    # the synthetic driver as it chose then: no check of the way to an offset (ExpertDriver.choose_offset without the pose)
    choose = ExpertDriver.choose_offset
    monkeypatch.setattr(ExpertDriver, "choose_offset", lambda self, s_now, pose=None, v_mps=None: choose(self, s_now))
    golden = json.loads((DATA / "planner_decisions.json").read_text())
    # the training schedule pinned as it was when the file was made (teach trained at lr 1e-3 then)
    recipe = replace(recipe, train=replace(recipe.train, optimiser=replace(recipe.train.optimiser, epochs=epochs, lr=1e-3)))
    if recipe.disturbance is not None:  # and the pushes as they were then: 0.3 a second, beginning anywhere
        recipe = replace(recipe, disturbance=replace(recipe.disturbance, rate_hz=0.3, clear_m=0.0, clear_s=0.0))
    features = recipe.features()
    rules = tuple(r for r in recipe.rules if r.type != "offset")  # C and its second stage drive, as when the file was made
    recordings = demonstrate(
        recipe, tmp_path / recipe.name, RecipeSetup(7, course=course, features=features, vehicle=VehicleConfig.paper()), write=False
    )
    model = tmp_path / f"{recipe.name}.safetensors"
    train_and_save(
        build_dataset(recordings, features, rules=rules),
        model,
        replace(recipe.train, seed=7),
        rules=rules,
        options=RunOptions(checkpoints=False),
    )
    for name in driven:
        driver = PlannerDriver(Planner(load_model(model)), keep=True)  # C and its second stage (if any) drive, as when the file was made
        log = run_episode(
            Simulation(resolve_scenario(name), config=SimConfig.paper()), driver, np.random.default_rng(0)
        )  # the vehicle of then
        made = [d.index for d in driver.decisions]
        want = golden[f"{recipe.name}/{name}"]
        # The stop rule and the goal check came after the file: up to the first stop, the same
        # decisions; from there on the run differs (the paper's planner, lost far off the path,
        # stops there, where it drove on to the map's edge then).
        stopped = next((i for i, d in enumerate(driver.decisions) if d.stop is not None), None)
        if stopped is not None:
            reason = driver.decisions[stopped].stop
            made, want = made[:stopped], want[:stopped]  # a stop's own decision is the stop's
            if reason == "off_path":
                where = log.trace[3 * driver.frames[stopped], :2]
                lost = float(driver.planner.path.distance_to(where)[0])
                assert lost > 10.0, f"{recipe.name} on {name}: off the path by only {lost:.1f} m at decision {stopped}"
            else:
                assert stopped > 1000, f"{recipe.name} on {name}: stopped at decision {stopped} ({reason})"
        first = next((i for i, (a, b) in enumerate(zip(made, want)) if a != b), None)
        if first is not None and _turning_back(driver, log, first):  # the goal check turned a planner lost facing away from its path
            made, want = made[:first], want[:first]
        assert made == want, f"{recipe.name} on {name}: {len(made)} decisions against {len(want)}, first difference at {first}"


def _turning_back(driver: PlannerDriver, log, decision: int) -> bool:
    """Whether the goal check (terrapref.planner.goal) turned the planner back to its path at ``decision``:
    the path ahead of its progress lay behind it."""
    from terrapref.planner.goal import GoalCheck
    from terrapref.planner.stop import StopConfig
    from terrapref.scenario.path import PathTracker
    from terrapref.vehicle import Pose

    path = driver.planner.path
    tracker, check = PathTracker(path), GoalCheck(StopConfig(), 1.0)
    for i in range(decision + 1):
        pose = Pose(*log.trace[3 * driver.frames[i]])
        s = tracker.update(np.array(pose[:2]))
    return check.check(pose, path, s, tracker.lateral_m).turn_rps is not None
