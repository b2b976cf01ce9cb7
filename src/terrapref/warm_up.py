"""Compile the project's compiled loops once, at set-up, so that the first real job does not.

The loops (numba, ``cache=True``) are compiled on their first call and kept beside their
sources; a fresh checkout has none, and ``terrapref reproduce`` would otherwise spend about
ten seconds of its first run compiling them in every worker. ``python -m terrapref.warm_up``
(run by ``scripts/setup.sh``) drives the same code paths on a short course with tiny settings:
a demonstration with disturbances, featurising with and without the look-ahead, training each
named recipe for one epoch (both utility fits), one closed-loop run of each model and of the
synthetic driver, one run through the ``field`` perception model (label errors, a tilted
camera), and a few frames of the default recipe's model on a course with relief (its height
field and noise, the relief renderer with depth, the height layer's votes, geometry and grades), its
costmap, the ground's roughness an evaluation scores speed by, and of the synthetic driver with a relief style there, and a whole flat frame. What it writes goes to a temporary folder and is removed.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import replace
from pathlib import Path

from terrapref.evaluation.runner import EXPERT, PLANNER, RunSpec, run_one
from terrapref.perception import load_perception
from terrapref.recipes import RECIPES, RecipeSetup, run_recipe
from terrapref.scenario import resolve_scenario
from terrapref.terrain import PreferenceProfile

COURSE = "fig7_rock_vs_non_traversable_left"  # short: a few hundred frames


def warm_up(log=print) -> float:
    """Drive, train and evaluate once with tiny settings; returns the seconds it took."""
    t0 = time.perf_counter()
    profile = PreferenceProfile.default()
    with tempfile.TemporaryDirectory(prefix="terrapref-warm-up-") as tmp:
        for recipe in RECIPES.values():
            small = replace(
                recipe, demonstrations=1, corrections=0, train=replace(recipe.train, optimiser=replace(recipe.train.optimiser, epochs=1))
            )
            out = run_recipe(small, Path(tmp) / "work", RecipeSetup(0, profile, course=COURSE))
            run_one(RunSpec(COURSE, 1, PLANNER, str(out.model), profile.order))
            if recipe.name == "teach":
                _relief_frames(out.model)
        run_one(RunSpec(COURSE, 1, PLANNER, str(out.model), profile.order, perception=load_perception("field")))
        run_one(RunSpec(COURSE, 1, EXPERT, None, profile.order))
    seconds = time.perf_counter() - t0
    log(f"compiled loops ready ({seconds:.0f} s)")
    return seconds


def _relief_frames(model_path: Path, frames: int = 5) -> None:
    """A few frames of the model at ``model_path`` deciding on ``relief_demo`` with their depth,
    and of the synthetic driver with a relief style."""
    import numpy as np

    from terrapref.demos.expert import ExpertConfig, ExpertDriver
    from terrapref.demos.relief_style import ReliefStyle
    from terrapref.groundmap.height_compiled import near_blocked
    from terrapref.learning.model_file import load_model
    from terrapref.planner import Planner, PlannerDriver
    from terrapref.rules.offset.features import BANDS
    from terrapref.rules.offset.offsets_compiled import relief_metres
    from terrapref.sim import Simulation

    sim = Simulation(resolve_scenario("relief_demo"))
    driver = PlannerDriver(Planner(load_model(model_path)))
    driver.reset(sim.scenario, np.random.default_rng(0))
    frame = sim.reset()
    for _ in range(frames):
        frame = sim.step(driver.act(frame))
    driver.planner.costmap()  # the map's cells all decided at once
    from terrapref.rules.speed.calibration import GradeCheck
    from terrapref.rules.speed.model import CHORD_M, CHORD_WEIGHTS

    gmap = driver.planner.ground_map  # the grades a speed rule learned on relief reads, and its fit
    gmap.gradient_at(np.zeros((1, 2)))
    gmap.roughness_at(np.zeros((1, 2)))
    gmap.body_grades(np.zeros((1, 2)), np.zeros(1), (CHORD_M, CHORD_WEIGHTS))
    GradeCheck(1).arrived(0.0, 0.0, 0.0, 0.0)  # the grades read ahead, checked once there
    gmap.read_shape()  # the sums a re-centred map works out afresh
    gmap.beside_attitudes(np.zeros((1, 2)), np.array([[0.0, 1.0]]), np.zeros(1))  # the relief an offset rule learned prices
    relief_metres(np.zeros((1, 1, 2)), 1, BANDS, 0.25)  # ... counted in its bands
    sim.world.roughness_at(np.zeros((1, 2)))  # an evaluation's speed by roughness band on relief
    expert = ExpertDriver(ExpertConfig(relief=ReliefStyle()))
    expert.reset(sim.scenario, np.random.default_rng(0))
    for _ in range(frames):
        frame = sim.step(expert.act(frame))
    near_blocked(np.ones((2, 2), dtype=np.uint8), 1, np.zeros(4, dtype=np.uint8))  # blocked ground, which these frames have none of
    _frames_as_they_come(Simulation(resolve_scenario(COURSE)))


def _frames_as_they_come(sim) -> None:
    """A flat frame rendered whole, and frames read as robots' come: pixels as a PixelSet (its
    indices read-only) or as plain indices, of a frame not yet rendered and of an image in hand,
    writable or read-only (decoded from a message's buffer)."""
    import numpy as np

    from terrapref.camera import PixelSet, SegmentationView

    image = sim.reset().image  # a whole flat frame rendered
    frozen = image.copy()
    frozen.flags.writeable = False
    indices = np.arange(16, dtype=np.int64)
    for pixels in (indices, PixelSet(indices)):
        sim.reset().view.pixels(pixels)  # read before the frame is rendered: only these pixels
        for held in (image, frozen):
            SegmentationView.of(held).pixels(pixels)


if __name__ == "__main__":
    warm_up()
