"""Compile the project's compiled loops once, at set-up, so that the first real job does not.

The loops (numba, ``cache=True``) are compiled on their first call and kept beside their
sources; a fresh checkout has none, and ``terrapref reproduce`` would otherwise spend about
ten seconds of its first run compiling them in every worker. ``python -m terrapref.warm_up``
(run by ``scripts/setup.sh``) drives the same code paths on a short course with tiny settings:
a demonstration with disturbances, featurising with and without the look-ahead, training each
named recipe for one epoch (both utility fits), one closed-loop run of each model and of the
synthetic driver, one run through the ``field`` perception model (label errors, a tilted
camera), and the height field of a course with relief (its noise is compiled too). What it writes goes to a temporary folder and is removed.
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
from terrapref.world import rasterise

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
        run_one(RunSpec(COURSE, 1, PLANNER, str(out.model), profile.order, perception=load_perception("field")))
        run_one(RunSpec(COURSE, 1, EXPERT, None, profile.order))
    rasterise(resolve_scenario("relief_demo"))
    seconds = time.perf_counter() - t0
    log(f"compiled loops ready ({seconds:.0f} s)")
    return seconds


if __name__ == "__main__":
    warm_up()
