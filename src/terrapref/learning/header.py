"""A model file's header: what a file of C holds besides its weights, as one typed record,
written by :meth:`ModelHeader.to_dict` and read back by :meth:`ModelHeader.from_dict`, here and
nowhere else (training writes it, loading and ``terrapref info`` read it).

The header is the file's JSON metadata. Its entries keep a fixed order, so that the same
training writes the same file, byte for byte::

    format, kind, classifier         what the file is, and C's shape
    recipe                           the recipe that made it (absent: none named)
    features, camera, classes,       the configuration C was trained under; a planner must
    profile                          run under the same
    training, data                   how it was trained, and on which data
    history, best_epoch, steps,      what a completed training produced
    identifiability, steadying
    rules, drives                    the decision rules fitted with C, one block each under its
                                     ``type`` (terrapref.rules reads them), and the one that drives
    members, member_count            an ensemble's members' runs; in a checkpoint, how many there are
    member, epoch                    a checkpoint's member and epoch; a model's chosen epoch
    status, interrupted              ``checkpoint`` or ``interrupted`` (absent: a finished model),
                                     and what an interrupted training reached

A header made by hand (tests, tools) may hold only the configuration. Files written before the
rules named the one that drives list them as ``stages`` (the last one drives), and older files
still carry the second stage's linear utility as ``utility`` and the offset rule's as
``corridor`` (each rule reads its own: terrapref.rules.legacy_blocks).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields
from typing import Any

from terrapref.camera import CameraConfig
from terrapref.errors import UserError
from terrapref.features import FeatureConfig
from terrapref.learning.network import ClassifierConfig
from terrapref.learning.train import EpochMetrics
from terrapref.records import from_plain, to_plain
from terrapref.terrain import ClassTable
from terrapref.terrain.profile import check_columns, declared_order

FORMAT = "terrapref-model/1"
CLASSIFIER = "classifier"  # the header's "kind" of C; baselines write their own kinds
CHECKPOINT = "checkpoint"  # the status of an epoch written as it was made
INTERRUPTED = "interrupted"  # the status of the best epochs so far of a training that was stopped
Block = dict[str, Any]  # a decision rule's block, under its "type"
Section = dict[str, Any]  # a section kept as the version that wrote it wrote it


@dataclass(frozen=True)
class DataSource:
    """The data a model was trained on.

    Attributes:
        fingerprint: the dataset's fingerprint (terrapref.demos.dataset).
        samples: how many samples it holds.
        recordings: the recordings it was featurised from, as the dataset lists them.
    """

    fingerprint: str
    samples: int
    recordings: tuple[Section, ...] = ()


@dataclass(frozen=True)
class MemberRun:
    """One member of an ensemble: the seed it trained from, its chosen epoch and its history."""

    seed: int
    best_epoch: int
    history: tuple[EpochMetrics, ...]


@dataclass(frozen=True)
class Interruption:
    """What an interrupted training reached: the members it started and each one's best epoch so far."""

    members_reached: int
    best_epochs: tuple[int, ...]
    note: str = "training was interrupted: the best epochs so far, without the decision rules or the identifiability report"


@dataclass(frozen=True, kw_only=True)
class ModelHeader:
    """The header of a model file of C, its fields in the file's order (after ``format`` and
    ``kind``); None: the file does not hold the entry.

    Attributes:
        classifier: C's shape.
        recipe: the name of the recipe that made the model.
        features, camera, classes: the configuration C was trained under.
        profile: the demonstrating driver's declared preference order (None: the drives declared
            none; ``evaluate`` then needs the order to score under).
        training: the training's configuration (``TrainConfig.to_dict``), as written.
        data: the data it was trained on.
        history, best_epoch, steps: every epoch's scores, the epoch chosen and the optimiser's steps
            (for an ensemble, member 0's).
        identifiability, steadying: what the demonstrations identify and what steadying the labels
            did, as written (terrapref.learning.identify, .steady).
        rules: the decision rules' blocks, in order; None: the file lists none (a checkpoint).
        drives: the type of the rule that steers (one of ``rules``, or ``argmax``).
        sets_speed: the type of the rule that sets the speed (one of ``rules``; None: none does,
            the control set's speed).
        stages: an older file's list of rules (the last one drove); never written.
        members: an ensemble's members.
        member_count: a checkpoint's number of members (``members`` in older files, which held
            either this count or the members' runs).
        member: the member a checkpoint holds, from 1.
        epoch: a checkpoint's epoch, or the epoch a model holds.
        status: :data:`CHECKPOINT` or :data:`INTERRUPTED`; None: a finished model.
        interrupted: what an interrupted training reached.
    """

    classifier: ClassifierConfig
    recipe: str | None = None
    features: FeatureConfig
    camera: CameraConfig
    classes: ClassTable
    profile: tuple[str, ...] | None
    training: Section | None = None
    data: DataSource | None = None
    history: tuple[EpochMetrics, ...] | None = None
    best_epoch: int | None = None
    steps: int | None = None
    identifiability: Section | None = None
    steadying: Section | None = None
    rules: tuple[Block, ...] | None = None
    drives: str | None = None
    sets_speed: str | None = None
    stages: tuple[Block, ...] | None = None
    members: tuple[MemberRun, ...] | None = None
    member_count: int | None = None
    member: int | None = None
    epoch: int | None = None
    status: str | None = None
    interrupted: Interruption | None = None

    def to_dict(self) -> dict[str, Any]:
        """The header as the file holds it: ``format`` and ``kind``, then the fields in order,
        what is None left out (the profile is always written); a checkpoint's member count is
        its ``members``."""
        entries = to_plain(self, omit_none=[f.name for f in fields(self) if f.name != "profile"])
        return {"format": FORMAT, "kind": CLASSIFIER, **entries}

    @classmethod
    def from_dict(cls, meta: Mapping[str, Any], source: str) -> ModelHeader:
        """The header of a model file of C (``meta``: its metadata, any kind), each entry checked
        once here; ``source`` names the file.

        Raises:
            UserError: another kind of model, or an entry that is missing where it is needed or
                is not what it should be, naming the file and the field.
        """
        kind = meta.get("kind", CLASSIFIER)
        if kind != CLASSIFIER:
            raise UserError(source, f"holds a {kind!r} model, not the classifier C", field="kind")
        features, camera, classes, profile = model_context(meta, source)
        try:
            classifier = ClassifierConfig.from_dict(meta["classifier"])
        except KeyError as exc:
            raise UserError(source, "missing", field=str(exc.args[0])) from None
        except (TypeError, ValueError) as exc:
            field = "classifier.channels" if "channels" in str(exc) else "classifier"
            raise UserError(source, f"invalid configuration: {exc}", field=field) from None
        members = _entry(meta, "members", _members, source)
        return cls(
            classifier=classifier,
            recipe=_entry(meta, "recipe", _text, source),
            features=features,
            camera=camera,
            classes=classes,
            profile=profile,
            training=_entry(meta, "training", _section, source),
            data=_entry(meta, "data", _record(DataSource), source),
            history=_entry(meta, "history", _history, source),
            best_epoch=_entry(meta, "best_epoch", _integer, source),
            steps=_entry(meta, "steps", _integer, source),
            identifiability=_entry(meta, "identifiability", _section, source),
            steadying=_entry(meta, "steadying", _section, source),
            rules=rule_blocks(meta, "rules", source),
            drives=_entry(meta, "drives", _text, source),
            sets_speed=_entry(meta, "sets_speed", _text, source),
            stages=rule_blocks(meta, "stages", source),
            members=members if isinstance(members, tuple) else None,
            member_count=members if isinstance(members, int) else _entry(meta, "member_count", _integer, source),
            member=_entry(meta, "member", _integer, source),
            epoch=_entry(meta, "epoch", _integer, source),
            status=_entry(meta, "status", _text, source),
            interrupted=_entry(meta, "interrupted", _record(Interruption), source),
        )


def model_context(meta: Mapping[str, Any], source: str) -> tuple[FeatureConfig, CameraConfig, ClassTable, tuple[str, ...] | None]:
    """The configuration every model file carries (C's and the baselines'): features, camera,
    classes, profile (None: its drives declared none); a missing or invalid one is a UserError
    naming the file and the field."""
    for key in ("features", "camera", "classes"):
        if key in meta and not isinstance(meta[key], dict):
            raise UserError(source, "expected a mapping", field=key)
    try:
        features = FeatureConfig.from_dict(meta["features"])
        camera = CameraConfig.from_dict(meta["camera"])
        classes = ClassTable.from_dict(meta["classes"], source)
        profile = None if meta["profile"] is None else declared_order(meta["profile"], classes, source)
    except KeyError as exc:
        raise UserError(source, "missing", field=str(exc.args[0])) from None
    except (TypeError, ValueError) as exc:
        raise UserError(source, f"invalid configuration: {exc}", field="metadata") from None
    check_columns(features.feature_classes, classes, source)
    return features, camera, classes, profile


def rule_blocks(meta: Mapping[str, Any], key: str, source: str) -> tuple[Block, ...] | None:
    """The decision rules a header lists under ``key`` (``rules``; ``stages`` in older files), in
    order; None when it lists none. Only the blocks' shape is checked here; each rule checks its
    own fields when it is read (terrapref.rules.read_rules).

    Raises:
        UserError: the list is not a list of mappings with a type, naming the file and the field.
    """
    if key not in meta:
        return None
    blocks = meta[key]
    if not isinstance(blocks, list):
        raise UserError(source, "expected a list of rules", field=key)
    for i, block in enumerate(blocks):
        if not isinstance(block, dict) or not isinstance(block.get("type"), str):
            raise UserError(source, "expected a mapping with a type", field=f"{key}[{i}]")
    return tuple(blocks)


# --- the provenance entries, each read once: a wrong one is a UserError naming it ---------------------


def _entry(meta: Mapping[str, Any], key: str, parse: Callable[[Any], Any], source: str) -> Any:
    """``parse(meta[key])``; None where the entry is absent or null."""
    value = meta.get(key)
    if value is None:
        return None
    try:
        return parse(value)
    except (TypeError, ValueError, KeyError, AttributeError) as exc:
        raise UserError(source, f"unreadable ({type(exc).__name__}: {exc})", field=key) from None


def _text(value: Any) -> str:
    if not isinstance(value, str):
        raise TypeError(f"expected text, got {type(value).__name__}")
    return value


def _integer(value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise TypeError(f"expected an integer, got {type(value).__name__}")
    return value


def _section(value: Any) -> Section:
    if not isinstance(value, dict):
        raise TypeError(f"expected a mapping, got {type(value).__name__}")
    return value


def _record(cls: type) -> Callable[[Any], Any]:
    return lambda value: from_plain(cls, _section(value))


def _history(value: Any) -> tuple[EpochMetrics, ...]:
    if not isinstance(value, list):
        raise TypeError(f"expected a list of epochs, got {type(value).__name__}")
    return tuple(from_plain(EpochMetrics, _section(h)) for h in value)


def _members(value: Any) -> tuple[MemberRun, ...] | int:
    """An ensemble's members, or a checkpoint's number of them."""
    if not isinstance(value, list):
        return _integer(value)
    return tuple(from_plain(MemberRun, _section(m)) for m in value)
