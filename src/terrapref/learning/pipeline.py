"""Train-and-save: the glue behind `terrapref train` and the reproduction."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path

from terrapref.demos.dataset import Dataset
from terrapref.learning.model_file import save_model
from terrapref.learning.train import EpochMetrics, TrainConfig, TrainResult, train


def model_meta(dataset: Dataset, config: TrainConfig, result: TrainResult, recipe: str | None = None) -> dict:
    return {
        **({"recipe": recipe} if recipe else {}),
        "features": dataset.meta["features"],
        "camera": dataset.meta["camera"],
        "classes": dataset.meta["classes"],
        "profile": dataset.meta["profile"],
        "training": config.to_dict(),
        "data": {"fingerprint": dataset.fingerprint, "samples": len(dataset), "recordings": dataset.meta.get("recordings", [])},
        "history": [asdict(h) for h in result.history],
        "best_epoch": result.best_epoch,
        "steps": result.steps,
        **({"identifiability": result.identifiability.to_dict()} if result.identifiability is not None else {}),
        **({"utility": {"w": result.utility.w.tolist(), "b": result.utility.b.tolist(), "weight": config.stage_weight,
                        "fit": "lookahead" if dataset.U2 is not None else "frames"}} if result.utility is not None else {}),
        **({"members": [{"seed": seed, "best_epoch": r.best_epoch, "history": [asdict(h) for h in r.history]}
                        for seed, r in zip(config.member_seeds, result.members)]} if result.members else {}),
    }


def train_and_save(dataset: Dataset, out: str | Path, config: TrainConfig, checkpoints: bool = True,
                   progress: Callable[[EpochMetrics], None] | None = None, recipe: str | None = None) -> TrainResult:
    """Train, write the chosen epoch as the model, every epoch as a checkpoint beside it;
    ``recipe`` (its name) is recorded in the model's metadata."""
    result = train(dataset, config, progress)
    meta = model_meta(dataset, config, result, recipe)
    out = Path(out)
    if checkpoints:
        folder = out.with_name(out.stem + ".checkpoints")
        for i, weights in enumerate(result.checkpoints, start=1):
            save_model(folder / f"epoch_{i:03d}.safetensors", result.classifier, weights, {**meta, "epoch": i})
    save_model(out, result.classifier, result.weights, {**meta, "epoch": result.best_epoch})
    return result
