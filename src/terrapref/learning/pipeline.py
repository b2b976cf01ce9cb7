"""Train-and-save: the glue behind `terrapref train` and the reproduction."""

from __future__ import annotations

import math
import shutil
from collections.abc import Callable, Sequence
from dataclasses import asdict, replace
from pathlib import Path

from terrapref.dataset import Dataset
from terrapref.fileio import new_folder, replace_dir
from terrapref.learning.model_file import save_model
from terrapref.learning.network import ClassifierConfig, member_prefix
from terrapref.learning.train import EpochMetrics, StageFit, TrainConfig, TrainResult, train


def _source_meta(dataset: Dataset, config: TrainConfig, recipe: str | None) -> dict:
    """What every file of one training carries, known before it starts: recipe, configuration, data."""
    return {
        **({"recipe": recipe} if recipe else {}),
        "features": dataset.meta["features"],
        "camera": dataset.meta["camera"],
        "classes": dataset.meta["classes"],
        "profile": dataset.meta["profile"],
        "training": config.to_dict(),
        "data": {"fingerprint": dataset.fingerprint, "samples": len(dataset), "recordings": dataset.meta.get("recordings", [])},
    }


def model_meta(dataset: Dataset, config: TrainConfig, result: TrainResult, source: dict) -> dict:
    """A model's metadata: ``source`` (:func:`_source_meta`) and what the training produced."""
    return {
        **source,
        "history": [asdict(h) for h in result.history],
        "best_epoch": result.best_epoch,
        "steps": result.steps,
        **({"identifiability": result.identifiability.to_dict()} if result.identifiability is not None else {}),
        **({"steadying": result.steadying.to_dict()} if result.steadying is not None else {}),
        "stages": [stage.header() for stage in result.stages],
        **({"members": [{"seed": seed, "best_epoch": r.best_epoch, "history": [asdict(h) for h in r.history]}
                        for seed, r in zip(config.member_seeds, result.members)]} if result.members else {}),
    }


def interrupted_path(out: str | Path) -> Path:
    """Where an interrupted training leaves its best model so far: beside ``out``, never over it."""
    out = Path(out)
    return out.with_name(f"{out.stem}.interrupted{out.suffix}")


class _Checkpoints:
    """Every epoch written as it is made, into a fresh folder beside the model's; swapped in for
    the old one only when training completes, so a retrain never mixes two runs' checkpoints.
    Also the best epoch so far of each member, for an interrupted run."""

    def __init__(self, out: Path, meta: dict, write: bool) -> None:
        self.final = out.with_name(out.stem + ".checkpoints")
        self.meta, self.write = meta, write
        self.folder = new_folder(self.final, "") if write else None
        self.best: dict[int, tuple[float, int, ClassifierConfig, dict]] = {}  # member -> (loss, epoch, classifier, weights)

    def __call__(self, member: int, classifier: ClassifierConfig, weights: dict, m: EpochMetrics) -> None:
        loss = m.val_loss if not math.isnan(m.val_loss) else m.train_loss
        if member not in self.best or loss < self.best[member][0]:
            self.best[member] = (loss, m.epoch, classifier, weights)
        if self.write:
            name = f"epoch_{m.epoch:03d}.safetensors" if self.meta["members"] == 1 else f"member_{member + 1}/epoch_{m.epoch:03d}.safetensors"
            save_model(self.folder / name, classifier, weights, {**self.meta, "member": member + 1, "epoch": m.epoch, "status": "checkpoint"})

    def finish(self) -> None:
        if self.folder is not None:
            replace_dir(self.folder, self.final)

    def discard(self) -> None:
        """A run that could not write its files leaves none of them."""
        if self.folder is not None:
            shutil.rmtree(self.folder, ignore_errors=True)

    def keep_partial(self) -> None:
        """An interrupted run's checkpoints stay, beside the old ones, as ``.checkpoints.interrupted``."""
        if self.folder is not None and self.folder.exists():
            replace_dir(self.folder, self.final.with_name(self.final.name + ".interrupted"))

    def interrupted_model(self, out: Path) -> Path | None:
        """The best epochs so far (every member reached) as one model, clearly marked."""
        if not self.best:
            return None
        members = [self.best[j] for j in sorted(self.best)]
        classifier = members[0][2]
        if len(members) == 1:
            weights = members[0][3]
        else:
            classifier = replace(classifier, members=len(members))
            weights = {member_prefix(j) + k: v for j, (_, _, _, w) in enumerate(members) for k, v in w.items()}
        meta = {**self.meta, "status": "interrupted",
                "interrupted": {"members_reached": len(members), "best_epochs": [e for _, e, _, _ in members],
                                "note": "training was interrupted: the best epochs so far, without the decision stages or the identifiability report"}}
        meta.pop("members", None)
        return save_model(interrupted_path(out), classifier, weights, meta)


def train_and_save(dataset: Dataset, out: str | Path, config: TrainConfig, checkpoints: bool = True,
                   progress: Callable[[EpochMetrics], None] | None = None, recipe: str | None = None, identify: bool = True,
                   stages: Sequence[StageFit] = ()) -> TrainResult:
    """Train, write every epoch as a checkpoint as it is made and the chosen epoch as the model;
    ``recipe`` (its name) is recorded in the model's metadata; ``identify`` and ``stages`` (the
    decision stages to fit with C) as :func:`train`'s.

    Interrupted (Ctrl-C, or any error but a failed write) after at least one epoch, the best
    epochs so far are written as ``NAME.interrupted.safetensors`` beside ``out`` (metadata
    ``status: interrupted``), its checkpoints as ``NAME.checkpoints.interrupted``; ``out`` and
    its old checkpoints are left as they were. A write that fails (a full disk) leaves nothing of
    this run behind.
    """
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    source = _source_meta(dataset, config, recipe)  # the data's fingerprint hashes every sample: once
    saver = _Checkpoints(out, {**source, "members": config.classifier.members}, checkpoints)
    try:
        result = train(dataset, config, progress, on_epoch=saver, identify=identify, stages=stages)
        meta = model_meta(dataset, config, result, source)
        save_model(out, result.classifier, result.weights, {**meta, "epoch": result.best_epoch})
    except OSError as exc:  # a file could not be written (a full disk): nothing of this run is left to fill it further
        saver.discard()
        written = Path(exc.filename) if exc.filename else out
        raise OSError(exc.errno, f"{exc.strerror or exc} (writing {'a checkpoint' if written != out else 'the model'}; nothing of this run is kept)",
                      str(out)) from None
    except BaseException:
        saver.keep_partial()
        saver.interrupted_model(out)
        raise
    saver.finish()
    return result
