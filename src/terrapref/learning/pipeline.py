"""Train-and-save: the glue behind `terrapref train` and the reproduction."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from terrapref.dataset import Dataset
from terrapref.errors import UserError
from terrapref.fileio import holds_nothing, new_folder, release_folder, replace_dir
from terrapref.learning.header import CHECKPOINT, INTERRUPTED, DataSource, Interruption, MemberRun, ModelHeader
from terrapref.learning.model_file import write_model
from terrapref.learning.network import ClassifierConfig, member_prefix
from terrapref.learning.train import EpochMetrics, RuleFit, TrainConfig, TrainResult, train
from terrapref.terrain import ClassTable


@dataclass(frozen=True)
class RunOptions:
    """How :func:`train_and_save` runs, besides what it trains; none of it changes the model.

    Attributes:
        checkpoints: write every epoch as a checkpoint beside the model.
        progress: called with every epoch's scores as it ends.
        identify: also report what the demonstrations identify, as :func:`train`'s ``identify``.
    """

    checkpoints: bool = True
    progress: Callable[[EpochMetrics], None] | None = None
    identify: bool = True


def source_header(dataset: Dataset, config: TrainConfig, recipe: str | None = None) -> ModelHeader:
    """What every file of one training carries, known before it starts: the recipe, the
    configuration and the data (its classifier, the configured one, is each file's own)."""
    profile = dataset.meta["profile"]
    return ModelHeader(
        classifier=config.classifier,
        recipe=recipe or None,
        features=dataset.feature_config,
        camera=dataset.camera_config,
        classes=ClassTable.from_dict(dataset.meta["classes"], "dataset"),
        profile=tuple(profile) if profile is not None else None,
        training=config.to_dict(),
        data=DataSource(dataset.fingerprint, len(dataset), tuple(dataset.meta.get("recordings") or ())),
    )


def model_header(config: TrainConfig, result: TrainResult, source: ModelHeader) -> ModelHeader:
    """A model's header: ``source`` (:func:`source_header`) and what the training produced."""
    members = tuple(MemberRun(seed, r.best_epoch, tuple(r.history)) for seed, r in zip(config.member_seeds, result.members))
    return replace(
        source,
        classifier=result.classifier,
        history=tuple(result.history),
        best_epoch=result.best_epoch,
        steps=result.steps,
        identifiability=result.identifiability.to_dict() if result.identifiability is not None else None,
        steadying=result.steadying.to_dict() if result.steadying is not None else None,
        rules=tuple(rule.header() for rule in result.rules),
        drives=result.drives,
        sets_speed=result.sets_speed,
        members=members or None,
        epoch=result.best_epoch,
    )


def checkpoints_path(out: str | Path) -> Path:
    """The folder of a training's checkpoints, beside its model ``out``."""
    out = Path(out)
    return out.with_name(out.stem + ".checkpoints")


def loss_curve_path(out: str | Path) -> Path:
    """The figure of a training's losses, beside its model ``out``."""
    return Path(out).with_suffix(".loss.png")


def interrupted_path(out: str | Path) -> Path:
    """Where an interrupted training leaves its best model so far: beside ``out``, never over it."""
    out = Path(out)
    return out.with_name(f"{out.stem}.interrupted{out.suffix}")


# A training loss past this has diverged: a softmax over the 21 trajectories starts near ln 21 (3.0)
# and a fit that merely overfits stays within tens; --lr 1e10 took it to 7.5e52 with finite weights.
DIVERGED_LOSS = 1e3


class _Checkpoints:
    """Every epoch written as it is made, into a fresh folder beside the model's; swapped in for
    the old one only when training completes, so a retrain never mixes two runs' checkpoints.
    Also the best epoch so far of each member, for an interrupted run. ``header``: what every
    file of the run carries (:func:`source_header`, with the member count)."""

    def __init__(self, out: Path, header: ModelHeader, write: bool) -> None:
        self.out, self.final = out, checkpoints_path(out)
        self.header, self.write = header, write
        self.folder = new_folder(self.final, "") if write else None
        self.best: dict[int, tuple[float, int, ClassifierConfig, dict]] = {}  # member -> (loss, epoch, classifier, weights)

    def __call__(self, member: int, classifier: ClassifierConfig, weights: dict, m: EpochMetrics) -> None:
        finite = all(np.isfinite(v).all() for v in weights.values())
        if not finite or not m.train_loss <= DIVERGED_LOSS:  # diverged: nothing of it is worth keeping
            which = f"member {member + 1}'s epoch {m.epoch}" if self.header.member_count != 1 else f"epoch {m.epoch}"
            why = f"{which}'s weights are not finite" if not finite else f"{which}'s training loss is {m.train_loss:.3g}"
            raise UserError(str(self.out), f"not written: the fit diverged ({why}); a smaller --lr may help", field="--lr")
        loss = m.val_loss if not math.isnan(m.val_loss) else m.train_loss
        if member not in self.best or loss < self.best[member][0]:
            self.best[member] = (loss, m.epoch, classifier, weights)
        if self.write:
            name = (
                f"epoch_{m.epoch:03d}.safetensors"
                if self.header.member_count == 1
                else f"member_{member + 1}/epoch_{m.epoch:03d}.safetensors"
            )
            write_model(
                self.folder / name,
                replace(self.header, classifier=classifier, member=member + 1, epoch=m.epoch, status=CHECKPOINT),
                weights,
            )

    def finish(self) -> None:
        if self.folder is not None:
            replace_dir(self.folder, self.final)

    def discard(self) -> None:
        """A run that could not write its files leaves none of them."""
        if self.folder is not None:
            release_folder(self.folder)

    def keep_partial(self) -> None:
        """An interrupted run's checkpoints stay, beside the old ones, as ``.checkpoints.interrupted``
        (a run that wrote none leaves no folder)."""
        if self.folder is not None and self.folder.exists() and holds_nothing(self.folder):
            self.discard()
        elif self.folder is not None and self.folder.exists():
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
        header = replace(
            self.header,
            classifier=classifier,
            member_count=None,
            status=INTERRUPTED,
            interrupted=Interruption(len(members), tuple(e for _, e, _, _ in members)),
        )
        return write_model(interrupted_path(out), header, weights)


def train_and_save(
    dataset: Dataset,
    out: str | Path,
    config: TrainConfig,
    rules: Sequence[RuleFit] = (),
    recipe: str | None = None,
    options: RunOptions = RunOptions(),
) -> TrainResult:
    """Train C and fit the decision ``rules`` with it (as :func:`train`), write every epoch as a
    checkpoint as it is made and the chosen epoch as the model; ``recipe`` (its name) is recorded
    in the model's header.

    Interrupted (Ctrl-C, or any error but a failed write) after at least one epoch, the best
    epochs so far are written as ``NAME.interrupted.safetensors`` beside ``out`` (header
    ``status: interrupted``), its checkpoints as ``NAME.checkpoints.interrupted``; ``out`` and
    its old checkpoints are left as they were. A write that fails (a full disk) leaves nothing of
    this run behind.
    """
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    source = source_header(dataset, config, recipe)  # the data's fingerprint hashes every sample: once
    saver = _Checkpoints(out, replace(source, member_count=config.classifier.members), options.checkpoints)
    try:
        result = train(dataset, config, options.progress, on_epoch=saver, identify=options.identify, rules=rules)
        write_model(out, model_header(config, result, source), result.weights)
    except OSError as exc:  # a file could not be written (a full disk): nothing of this run is left to fill it further
        saver.discard()
        written = Path(exc.filename) if exc.filename else out
        raise OSError(
            exc.errno,
            f"{exc.strerror or exc} (writing {'a checkpoint' if written != out else 'the model'}; nothing of this run is kept)",
            str(out),
        ) from None
    except BaseException:
        saver.keep_partial()
        saver.interrupted_model(out)
        raise
    saver.finish()
    return result
