"""Write tests/data/planner_decisions.json: the planner's decisions in closed-loop runs of two models
trained here (training is the same on every CPU, so the models are too).

The file was made before the classifier's forward pass and the second stage's distances were
compiled (commit 7a92879); tests/learning/test_forward.py checks that the planner still makes exactly
these decisions. Run from the repository root: ``.venv/bin/python tests/data/make_planner_decisions.py``.
"""

from __future__ import annotations

import json
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

from terrapref.dataset import build_dataset
from terrapref.demos.recording import read_recording
from terrapref.learning.model_file import load_model
from terrapref.learning.pipeline import RunOptions, train_and_save
from terrapref.planner import Planner, PlannerDriver
from terrapref.recipes import PAPER, TEACH, RecipeSetup, record_demonstrations
from terrapref.scenario import resolve_scenario
from terrapref.sim import Simulation, run_episode

# (recipe, epochs, demonstration course, courses driven); teach_course as it was when the file was made
CASES = [
    (TEACH, 40, str(Path(__file__).with_name("teach_course_pairs.yaml")), ("test_course", "fig8_water_mud_rock_mud_left")),
    (PAPER, 15, "train_course", ("test_course",)),
]


def decisions(work: Path) -> dict:
    out = {}
    for recipe, epochs, course, driven in CASES:
        # the training schedule pinned as it was when the file was made (teach trained at lr 1e-3 then)
        recipe = replace(recipe, train=replace(recipe.train, optimiser=replace(recipe.train.optimiser, epochs=epochs, lr=1e-3)))
        features = recipe.features()
        rules = tuple(r for r in recipe.rules if r.type != "offset")
        paths = record_demonstrations(recipe, work / recipe.name, RecipeSetup(7, course=course, features=features))
        model = work / f"{recipe.name}.safetensors"
        train_and_save(
            build_dataset([read_recording(p) for p in paths], features, rules=rules),
            model,
            replace(recipe.train, seed=7),
            rules=rules,
            options=RunOptions(checkpoints=False),
        )
        for name in driven:
            driver = PlannerDriver(Planner(load_model(model)), keep=True)
            run_episode(Simulation(resolve_scenario(name)), driver, np.random.default_rng(0))
            out[f"{recipe.name}/{name}"] = [d.index for d in driver.decisions]
    return out


if __name__ == "__main__":
    with tempfile.TemporaryDirectory() as tmp:
        found = decisions(Path(tmp))
    target = Path(__file__).with_name("planner_decisions.json")
    target.write_text(json.dumps(found) + "\n")
    print(f"wrote {target}: " + ", ".join(f"{k} {len(v)} decisions" for k, v in found.items()), file=sys.stderr)
