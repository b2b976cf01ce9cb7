"""Recipes: how demonstrations become a model, end to end (demonstrate, correct, train).

``paper`` is the published recipe: one demonstration on the training course, 15 epochs of C.
Other recipes add what a real user could do with a human driver too: more demonstration runs,
correction sessions (the planner drives, the person shows what they would do), a residual path
in C, more training steps, and loss weights for the frames that carry the preference.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from terrapref.camera import CameraConfig
from terrapref.demos.corrections import record_corrections
from terrapref.demos.dataset import build_dataset
from terrapref.demos.expert import ExpertConfig, ExpertDriver
from terrapref.demos.recording import Recording, RecordingWriter, read_recording
from terrapref.demos.session import DisturbanceConfig, record_run, recording_meta
from terrapref.features import FeatureConfig
from terrapref.learning.model_file import load_model
from terrapref.learning.pipeline import train_and_save
from terrapref.learning.train import TrainConfig, TrainResult
from terrapref.planner import Planner, PlannerDriver
from terrapref.scenario import resolve_scenario
from terrapref.sim import SimConfig, Simulation
from terrapref.terrain import PreferenceProfile


@dataclass(frozen=True)
class Recipe:
    """One way of turning a person's driving into a model.

    Attributes:
        name: label in reports.
        demonstrations: demonstration runs of the training course.
        corrections: correction sessions after the first model (one run of the course each,
            the model retrained on everything after each).
        train: training hyperparameters.
        smoothing: the planner's averaging of F_t over frames.
        disturbance: pushes injected while demonstrating, so that recoveries are shown
            (None: the driver drives undisturbed).
    """

    name: str
    demonstrations: int = 1
    corrections: int = 0
    train: TrainConfig = field(default_factory=TrainConfig)
    smoothing: float = 0.0
    disturbance: DisturbanceConfig | None = None

    def to_dict(self) -> dict:
        return asdict(self)


PAPER = Recipe("paper")


@dataclass
class RecipeOutput:
    model: Path
    recordings: list[Path]
    result: TrainResult
    demo_minutes: float
    correction_minutes: float


def record_demonstrations(
    recipe: Recipe,
    workdir: str | Path,
    seed: int,
    profile: PreferenceProfile | None = None,
    course: str = "train_course",
    features: FeatureConfig | None = None,
    log: Callable[[str], None] | None = None,
) -> list[Path]:
    """The recipe's demonstration runs (synthetic driver, seeds ``seed * 100 + k``) in ``workdir``.

    They go to ``workdir/demo_K`` (``demo_K_disturbed`` with disturbances) and a complete one
    recorded under the same driver, profile, seed and disturbances is reused, so recipes sharing
    a seed share their demonstrations.
    """
    workdir = Path(workdir)
    scenario = resolve_scenario(course)
    profile = profile or PreferenceProfile.default(scenario.classes)
    features = features or FeatureConfig()
    camera, sim_cfg = CameraConfig(), SimConfig()
    expert_cfg = ExpertConfig(profile=profile.order)
    disturbance = recipe.disturbance.to_dict() if recipe.disturbance is not None else None
    sim = Simulation(scenario, camera, sim_cfg)
    paths: list[Path] = []
    for k in range(recipe.demonstrations):
        demo_seed = seed * 100 + k
        out = workdir / (f"demo_{k}" if disturbance is None else f"demo_{k}_disturbed")
        if (out / "meta.json").exists():
            existing = read_recording(out)
            driver = existing.meta["driver"]
            if (existing.complete and existing.meta.get("profile") == list(profile.order) and driver.get("seed") == demo_seed
                    and driver.get("disturbance") == disturbance and driver.get("config") == expert_cfg.to_dict()):
                paths.append(out)
                continue
        meta = recording_meta(scenario, camera, features.preference, sim_cfg,
                              {"kind": "expert", "seed": demo_seed, "config": expert_cfg.to_dict(), "disturbance": disturbance}, profile)
        writer = RecordingWriter(out, meta, scenario.to_dict(), overwrite=True)
        record_run(sim, ExpertDriver(expert_cfg), writer, features.preference, np.random.default_rng(demo_seed), disturbance=recipe.disturbance)
        paths.append(out)
        if log:
            log(f"demonstration {k + 1}/{recipe.demonstrations}: {len(read_recording(out))} frames")
    return paths


def run_recipe(
    recipe: Recipe,
    workdir: str | Path,
    seed: int,
    profile: PreferenceProfile | None = None,
    course: str = "train_course",
    features: FeatureConfig | None = None,
    log: Callable[[str], None] | None = None,
) -> RecipeOutput:
    """Demonstrate, correct, train; write into ``workdir``.

    Demonstrations come from :func:`record_demonstrations` (shared by recipes with the same
    seed and protocol); corrections and the model go to ``workdir/<recipe name>/``.
    """
    workdir = Path(workdir)
    own = workdir / recipe.name.replace(" ", "_")
    own.mkdir(parents=True, exist_ok=True)
    scenario = resolve_scenario(course)
    profile = profile or PreferenceProfile.default(scenario.classes)
    features = features or FeatureConfig()
    paths = record_demonstrations(recipe, workdir, seed, profile, course, features, log)
    recordings = [read_recording(p) for p in paths]
    demo_s = sum(r.duration_s for r in recordings)
    corr_s = 0.0
    train_cfg = replace(recipe.train, seed=seed)
    model = own / "model.safetensors"
    result = train_and_save(build_dataset(recordings, features), model, train_cfg, checkpoints=False)
    if recipe.corrections:  # the planner drives the course; only then is a simulation needed here
        camera, sim_cfg = CameraConfig(), SimConfig()
        expert_cfg = ExpertConfig(profile=profile.order)
        sim = Simulation(scenario, camera, sim_cfg)
    for r in range(recipe.corrections):
        out = own / f"corrections_{r}"
        meta = recording_meta(scenario, camera, features.preference, sim_cfg, {"kind": "corrections", "round": r, "seed": seed}, profile)
        writer = RecordingWriter(out, meta, scenario.to_dict(), overwrite=True)
        planner = PlannerDriver(Planner(load_model(model), smoothing=recipe.smoothing))
        run = record_corrections(sim, planner, ExpertDriver(expert_cfg), writer, features.preference, np.random.default_rng(seed * 100 + 50 + r))
        corr_s += run.duration_s
        recordings.append(read_recording(out))
        paths.append(out)
        result = train_and_save(build_dataset(recordings, features), model, train_cfg, checkpoints=False)
        if log:
            log(f"correction session {r + 1}/{recipe.corrections}: {len(recordings[-1])} frames, retrained")
    return RecipeOutput(model, paths, result, demo_s / 60.0, corr_s / 60.0)
