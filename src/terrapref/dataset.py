"""Featurisation: recordings -> training sets of (U, label), saved without pickle (safetensors).

A dataset carries the configuration that produced it (features, camera, classes, profile,
source recordings) and a fingerprint of its contents, so a model trained on it can be checked
against the planner's configuration later. A recording can be featurised under another camera
(frames are re-rendered from its stored scenario at its stored poses) or another preference
set (labels are re-derived from the recorded continuous w) without driving again.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, NamedTuple, Protocol

import numpy as np

from terrapref.camera import CameraConfig, PinholeCamera, SegmentationRenderer, SegmentationView
from terrapref.demos.recording import Recording, read_recording, require_meta
from terrapref.errors import UserError, finite_number
from terrapref.features import FeatureConfig, UtilityFeaturizer
from terrapref.scenario import Scenario, parse_scenario
from terrapref.scenario.path import PathTracker, ReferencePath
from terrapref.tensorfile import read_tensor_file, write_tensor_file
from terrapref.terrain import ClassTable
from terrapref.terrain.classes import ForeignIds
from terrapref.terrain.profile import check_columns, declared_order
from terrapref.world import rasterise

FORMAT = "terrapref-dataset/2"
OLD_FORMATS = ("terrapref-dataset/1",)  # before the decision rules kept their own arrays: featurised again, not read

# What a rule's array may hold besides finite numbers, as a dataset declares it for each array (checked on load).
ARRAY_KINDS = {
    "finite": "finite numbers",
    "finite >= 0": "finite numbers >= 0",
    "no NaN": "numbers (inf allowed, NaN not)",
    "no inf": "numbers (NaN allowed, inf not)",
}


class FrameReader(Protocol):
    """What a decision rule reads of each frame while a recording is featurised (terrapref.rules.base.FrameReader)."""

    def read(self, j: int, view: SegmentationView, pose: tuple, path: ReferencePath, progress_m: float) -> None: ...

    def arrays(self, recording: Recording, keep: np.ndarray, path: ReferencePath) -> dict[str, np.ndarray]: ...


class RuleData(Protocol):
    """A decision rule's configuration as featurisation sees it (terrapref.rules.base.RuleConfig):
    its name, the configuration of the arrays it reads (None: none), how each array is checked,
    and a reader of them."""

    type: str
    arrays: dict[str, str]

    def data(self) -> dict[str, Any] | None: ...

    def reader(self, featurizer: UtilityFeaturizer, camera: PinholeCamera, classes: ClassTable, n: int) -> FrameReader: ...


@dataclass(frozen=True)
class Dataset:
    """Training samples and the configuration that produced them.

    Attributes:
        U: utility features, shape (N, m, K + 1) float32.
        labels: demonstrated control-set index, shape (N,) int64.
        w: demonstrated continuous yaw rate [rad/s], shape (N,) float32.
        source: index of the recording each sample came from, shape (N,) int64.
        meta: features, camera, classes, profile, recordings (JSON-serialisable).
        rules: what the decision rules' fits read of each frame, by rule (its ``type``) and
            array name, one row per sample; ``meta["rules"]`` holds, by rule, the configuration
            they were read with and how each array is checked.
    """

    U: np.ndarray
    labels: np.ndarray
    w: np.ndarray
    source: np.ndarray
    meta: dict
    rules: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.labels)

    @property
    def feature_config(self) -> FeatureConfig:
        return FeatureConfig.from_dict(self.meta["features"])

    @property
    def camera_config(self) -> CameraConfig:
        return CameraConfig.from_dict(self.meta["camera"])

    @property
    def U2(self) -> np.ndarray | None:
        """The look-ahead utilities of every frame, (N, m, m, K + 1) float16, when a rule's arrays
        hold them (the second stage's, ``U2``); else None."""
        return next((arrays["U2"] for arrays in self.rules.values() if "U2" in arrays), None)

    def rule_data(self, rule: str) -> tuple[dict[str, Any], dict[str, np.ndarray]] | None:
        """The configuration ``rule``'s arrays were read with, and the arrays; None when the dataset holds none for it."""
        if rule not in self.rules:
            return None
        return self.meta["rules"][rule]["config"], self.rules[rule]

    @property
    def fingerprint(self) -> str:
        h = hashlib.sha256()
        extra = [a for arrays in self.rules.values() for a in arrays.values()]
        for a in (self.U, self.labels, *extra):
            h.update(np.ascontiguousarray(a).tobytes())
        return h.hexdigest()[:16]


class Featurised(NamedTuple):
    """One recording's samples (:class:`Dataset`'s arrays, without ``source``)."""

    U: np.ndarray
    labels: np.ndarray
    w: np.ndarray
    rules: dict[str, dict[str, np.ndarray]]


def featurize_recording(
    recording: Recording,
    features: FeatureConfig,
    camera: CameraConfig | None = None,
    on_frame: Callable[[int], None] | None = None,
    rules: tuple[RuleData, ...] = (),
) -> Featurised:
    """U (F, m, K + 1), labels (F,), w (F,) and what each of ``rules`` reads for its fit, for every
    frame of a recording taken on the map (frames off it are left out).

    Args:
        camera: None uses the recorded frames; another configuration re-renders each frame from
            the recording's scenario at its recorded pose.
        on_frame: called after each frame with the frames done so far (a long recording takes a minute).
    """
    require_meta(recording, "classes", "camera")
    classes = recording.classes
    rec_camera = CameraConfig.from_dict(recording.meta["camera"])
    camera = camera or rec_camera
    scenario, renderer, keep = _to_featurise(recording, camera, rec_camera)
    featurizer = UtilityFeaturizer(features, PinholeCamera(camera), classes)
    path = ReferencePath(np.asarray(recording.meta.get("path", scenario.waypoints), dtype=float))
    readers = {rule.type: rule.reader(featurizer, PinholeCamera(camera), classes, len(keep)) for rule in rules if rule.data() is not None}
    U = np.empty((len(keep), featurizer.m, features.n_features), dtype=np.float32)
    for j, frame_u in _read_frames(recording, keep, featurizer, path, renderer, list(readers.values())):
        U[j] = frame_u
        if on_frame is not None:
            on_frame(j + 1)
    w = at_set_speed(recording.commands[keep], features.preference.control.v_mps)
    labels = np.asarray(features.preference.control.label_of(w), dtype=np.int64).reshape(len(keep))
    return Featurised(U, labels, w, {name: reader.arrays(recording, keep, path) for name, reader in readers.items()})


def _to_featurise(
    recording: Recording, camera: CameraConfig, rec_camera: CameraConfig
) -> tuple[Scenario, SegmentationRenderer | None, np.ndarray]:
    """The recording's scenario, the renderer of its frames under ``camera`` (None: its own
    frames are read), and the frames taken on the map; a recording that cannot be featurised so
    is a UserError naming its file and field."""
    scenario = parse_scenario(recording.scenario, str(recording.path / "scenario.yaml"), recording.classes, driven=True)
    perceived = recording.perception
    if not camera.same_geometry(rec_camera) and perceived != "clean":
        raise UserError(
            str(recording.path / "meta.json"),
            f"its frames are what the robot received under perception {perceived!r}; "
            "rendering them again under another camera would give the simulator's truth instead",
            field="perception",
        )
    renderer = None if camera.same_geometry(rec_camera) else SegmentationRenderer(PinholeCamera(camera), rasterise(scenario))
    if len(recording) == 0:
        raise UserError(str(recording.path / "frames.jsonl"), "holds no frames to featurise", field="frames")
    keep = np.flatnonzero(on_map(recording.poses, scenario))  # frames taken off the map are not training data
    if len(keep) == 0:
        raise UserError(
            str(recording.path / "frames.jsonl"),
            f"every frame was taken off the {scenario.size_m[0]:g} x {scenario.size_m[1]:g} m map",
            field="pose",
        )
    return scenario, renderer, keep


def _read_frames(
    recording: Recording,
    keep: np.ndarray,
    featurizer: UtilityFeaturizer,
    path: ReferencePath,
    renderer: SegmentationRenderer | None,
    readers: list,
) -> Iterator[tuple[int, np.ndarray]]:
    """(j, U of the j-th of the ``keep`` frames), in order, each frame also given to the rules' ``readers``."""
    foreign = ForeignIds(recording.classes)
    rec_camera = CameraConfig.from_dict(recording.meta["camera"])
    shape = (rec_camera.height_px, rec_camera.width_px)
    tracker = PathTracker(path)
    # Between frames that are not consecutive (a ride-along's corrections, frames left out off
    # the map) the vehicle may have gone further than the tracker's window: widen it by what
    # the vehicle could have driven in the gap.
    period = recording.frame_period_s
    v_max = _max_speed(recording.meta)
    for j, i in enumerate(keep):
        pose = tuple(recording.poses[i])
        view = _frame_view(recording, i, renderer, pose, shape, foreign)
        gap_s = recording.times[i] - recording.times[keep[j - 1]] if j > 0 else 0.0
        s = tracker.update(recording.poses[i, :2], ahead_m=v_max * gap_s + 2.0 if gap_s > 1.5 * period else None)
        frame_u = featurizer(view, pose, path, s)
        for reader in readers:
            reader.read(j, view, pose, path, s)
        yield j, frame_u


def _frame_view(
    recording: Recording, i: int, renderer: SegmentationRenderer | None, pose: tuple, shape: tuple[int, int], foreign: ForeignIds
) -> SegmentationView:
    """Frame ``i`` as the featurizer reads it, with its depth image and the body's attitude where
    it carries one (a recording without an attitude is taken as level): re-rendered under
    another camera (on relief with its depth, at the recorded attitude), the simulation's own
    view for a recording kept in memory (only the pixels read are rendered), or the recorded
    images, refused when their size or class ids do not fit the recording's camera and classes."""
    if renderer is not None:
        attitude = recording.attitude(i)
        return (
            SegmentationView.of(*renderer.render_with_depth(pose, attitude), attitude)
            if renderer.relief
            else SegmentationView.of(renderer.render(pose))
        )
    if recording.views is not None:
        return recording.view(i)
    image = recording.image(i)
    unknown = foreign(image) if image.shape == shape else []
    if image.shape != shape or unknown:
        what = (
            f"is {image.shape[1]} x {image.shape[0]}, the camera's {shape[1]} x {shape[0]}"
            if image.shape != shape
            else f"holds class ids {unknown[:5]} that the class table does not have"
        )
        raise UserError(str(recording.path / recording.image_files[i]), what)
    depth = recording.depth(i)
    if depth is not None and depth.shape != shape:
        raise UserError(
            str(recording.path / recording.depth_files[i]), f"is {depth.shape[1]} x {depth.shape[0]}, the camera's {shape[1]} x {shape[0]}"
        )
    return SegmentationView.of(image, depth, recording.attitude(i))


def at_set_speed(commands: np.ndarray, v_set: float) -> np.ndarray:
    """The yaw rates (F,) float32 of commands (F, 2) at the control set's speed ``v_set``: the same
    curvature w / v, the trajectory it drives (a command at v = 0 keeps its w)."""
    v, w = commands[:, 0].astype(float), commands[:, 1].astype(float)
    moving = v > 0
    out = w.copy()
    out[moving] = w[moving] * v_set / v[moving]
    return out.astype(np.float32)


def _max_speed(meta: dict) -> float:
    """The recorded vehicle's top speed [m/s] (1 when the recording does not say)."""
    sim = meta.get("sim")
    vehicle = sim.get("vehicle") if isinstance(sim, dict) else None
    v = vehicle.get("max_speed_mps") if isinstance(vehicle, dict) else None
    return float(v) if finite_number(v) and v > 0 else 1.0


def on_map(poses: np.ndarray, scenario: Scenario) -> np.ndarray:
    """Which poses (F, 3) lie on the scenario's map, (F,) bool."""
    w_m, h_m = scenario.size_m
    x, y = poses[:, 0], poses[:, 1]
    return (x >= 0) & (x <= w_m) & (y >= 0) & (y <= h_m)


class Featuring(NamedTuple):
    """How far featurising several recordings has come (:func:`build_dataset`'s progress)."""

    recordings_done: int
    recordings: int
    frames_done: int
    frames: int


def build_dataset(
    recordings: list[Recording],
    features: FeatureConfig,
    camera: CameraConfig | None = None,
    rules: tuple[RuleData, ...] = (),
    cache: dict | None = None,
    progress: Callable[[Featuring], None] | None = None,
) -> Dataset:
    """Featurise several recordings into one dataset (they must share classes, and the
    preference order those that declare one declare), with the arrays each of the decision
    ``rules`` (a recipe's) reads for its fit.

    ``progress`` is called after each frame and after each recording.

    ``cache`` keeps each recording's features (keyed by the recording object, the features, the
    camera and the rules' data), so that a later dataset of some of the same recordings featurises only the
    others: the same arrays, computed once.
    """
    if not recordings:
        raise UserError("featurize", "no recordings given")
    first = recordings[0]
    for rec in recordings[1:]:
        if rec.meta.get("classes") != first.meta.get("classes"):
            raise UserError(
                str(rec.path / "meta.json"),
                f"a drive of another class table ({', '.join(rec.classes.names)}) than {first.path}'s "
                f"({', '.join(first.classes.names)}); one model learns one table: featurise and train them apart",
                field="classes",
            )
    profile = _declared_order(
        [(str(r.path / "meta.json"), str(r.path), r.meta) for r in recordings], "record the drives with the same --profile"
    )
    # The terrain columns are the recordings' class table's.
    require_meta(first, "classes")
    features = replace(features, feature_classes=first.classes.feature_names)
    rules = tuple(rule for rule in rules if rule.data() is not None)
    parts = _featurized(recordings, features, camera, rules, cache, progress)
    U = np.concatenate([p[0] for p in parts])
    labels = np.concatenate([p[1] for p in parts])
    w = np.concatenate([p[2] for p in parts])
    arrays = {rule.type: _joined([p.rules[rule.type] for p in parts]) for rule in rules}
    source = np.concatenate([np.full(len(p[1]), k, dtype=np.int64) for k, p in enumerate(parts)])
    meta = {
        "format": FORMAT,
        "features": features.to_dict(),
        "camera": (camera or CameraConfig.from_dict(first.meta["camera"])).to_dict(),
        "classes": first.meta["classes"],
        "profile": profile,
        "rules": {rule.type: {"config": rule.data(), "arrays": {name: rule.arrays[name] for name in arrays[rule.type]}} for rule in rules},
        "recordings": [_recording_entry(r, len(p[1])) for r, p in zip(recordings, parts, strict=True)],
    }
    return Dataset(U, labels, w.astype(np.float32), source, meta, arrays)


def _joined(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """One rule's arrays of several recordings, joined; an array only some recordings have (the
    offset rule's relief columns, for drives on relief) is zeros for the others."""
    names = list(dict.fromkeys(name for part in parts for name in part))
    example = {name: next(part[name] for part in parts if name in part) for name in names}  # a row's shape and type
    rows = [len(next(iter(part.values()))) for part in parts]
    return {
        name: np.concatenate(
            [
                part[name] if name in part else np.zeros((n, *example[name].shape[1:]), example[name].dtype)
                for part, n in zip(parts, rows, strict=True)
            ]
        )
        for name in names
    }


def _featurized(
    recordings: list[Recording],
    features: FeatureConfig,
    camera: CameraConfig | None,
    rules: tuple[RuleData, ...],
    cache: dict | None,
    progress: Callable[[Featuring], None] | None,
) -> list:
    """Each recording's features (:func:`featurize_recording`), from ``cache`` where it holds them
    (:func:`build_dataset`), ``progress`` told after each frame and each recording."""
    reads = tuple((rule.type, repr(rule.data())) for rule in rules)
    parts = []
    total, before, n = sum(len(r) for r in recordings), 0, len(recordings)
    for k, rec in enumerate(recordings):
        key = (id(rec), features, camera, reads)
        if cache is None or key not in cache:
            on_frame = None if progress is None else (lambda j, b=before, k=k: progress(Featuring(k, n, b + j, total)))
            part = featurize_recording(rec, features, camera, on_frame, rules)
            if cache is not None:
                cache[key] = (rec, part)  # the recording held with its features: its id is not reused while the cache lives
        parts.append(part if cache is None else cache[key][1])
        before += len(rec)
        if progress is not None:
            progress(Featuring(k + 1, n, before, total))
    return parts


def _recording_entry(rec: Recording, used: int) -> dict[str, Any]:
    """What a dataset's ``recordings`` list says of one recording, ``used`` of its frames kept."""
    return {
        "path": str(rec.path),
        "scenario": rec.meta.get("scenario"),
        "frames": len(rec),
        "frames_used": used,
        "complete": rec.complete,
        "driver": rec.meta.get("driver"),
        "perception": rec.perception,
        **({"written": False} if rec.in_memory else {}),
    }


def _declared_order(files: Sequence[tuple[str, str, dict]], advice: str) -> list[str] | None:
    """The preference order the drives of ``files`` (each: the file to name in an error, the name
    to name it by to another, its meta) declared: one order, which a drive that declares none
    does not contradict (a drive without ``--profile``); None where none declares one.

    Raises:
        UserError: two declare different orders (two drivers, or one driver's two orders), with ``advice``.
    """
    declared = [(source, name, meta["profile"]) for source, name, meta in files if meta.get("profile") is not None]
    for source, _, order in declared[1:]:
        if order != declared[0][2]:
            raise UserError(
                source,
                f"declares the order {' > '.join(order)}, {declared[0][1]} {' > '.join(declared[0][2])}: one model learns one "
                f"driver's order; {advice}",
                field="profile",
            )
    return declared[0][2] if declared else None


def save_dataset(dataset: Dataset, path: str | Path) -> Path:
    """Write a dataset as safetensors (tensors plus JSON metadata), atomically."""
    meta = {**dataset.meta, "format": FORMAT, "fingerprint": dataset.fingerprint, "samples": len(dataset)}
    tensors = {"U": dataset.U, "labels": dataset.labels, "w": dataset.w, "source": dataset.source}
    tensors |= {f"rules.{rule}.{name}": a for rule, arrays in dataset.rules.items() for name, a in arrays.items()}
    return write_tensor_file(path, tensors, meta)


def load_dataset(path: str | Path) -> Dataset:
    """Read a dataset written by :func:`save_dataset` (no code is executed on load)."""
    try:
        tensors, meta = read_tensor_file(path, FORMAT, "no such file", "not a terrapref dataset")
    except UserError as exc:
        old = next((f for f in OLD_FORMATS if f in exc.problems[0].message), None)
        if old is None:
            raise
        raise UserError(str(path), f"a dataset of an earlier version ({old}); featurize its recordings again", field="format") from None
    for key in ("U", "labels", "w", "source"):
        if key not in tensors:
            raise UserError(str(path), "missing tensor", field=key)
    _check_tensors(tensors, str(path))
    try:
        features = FeatureConfig.from_dict(meta["features"])
        CameraConfig.from_dict(meta["camera"])
        classes = ClassTable.from_dict(meta["classes"], str(path))
    except KeyError as exc:
        raise UserError(str(path), "missing", field=str(exc.args[0])) from None
    except (TypeError, ValueError, AttributeError) as exc:
        raise UserError(str(path), f"invalid configuration ({type(exc).__name__}: {exc})", field="metadata") from None
    shape = (features.preference.m, features.n_features)
    if tensors["U"].shape[1:] != shape:
        raise UserError(
            str(path),
            f"expected {shape[0]} trajectories x {shape[1]} features ({', '.join(features.column_names)}) per sample, "
            f"as its features say; got {tensors['U'].shape[1]} x {tensors['U'].shape[2]}",
            field="U",
        )
    check_columns(features.feature_classes, classes, str(path))
    if meta.get("profile") is not None:  # None: the drives declared none
        declared_order(meta["profile"], classes, str(path))
    drives = meta.get("recordings")
    if drives is not None and not (isinstance(drives, list) and all(isinstance(d, dict) for d in drives)):
        raise UserError(str(path), "expected a list of the recordings it was made from, each a mapping", field="recordings")
    rules = _rule_arrays(tensors, meta, str(path))
    return Dataset(tensors["U"], tensors["labels"], tensors["w"], tensors["source"], meta, rules)


def _rule_arrays(tensors: dict[str, np.ndarray], meta: dict, source: str) -> dict[str, dict[str, np.ndarray]]:
    """The rules' arrays of a dataset file, each as ``meta["rules"]`` declares it: one row per
    sample, floats or uint8 class ids, and only the values its kind allows (:data:`ARRAY_KINDS`)."""
    declared = meta.get("rules", {})
    if not isinstance(declared, dict) or not all(
        isinstance(d, dict) and isinstance(d.get("arrays"), dict) and isinstance(d.get("config"), dict) for d in declared.values()
    ):
        raise UserError(source, "expected a mapping of rules, each with its config and arrays", field="rules")
    n = len(tensors["labels"])
    out: dict[str, dict[str, np.ndarray]] = {}
    for rule, d in declared.items():
        out[rule] = {}
        for name, kind in d["arrays"].items():
            key = f"rules.{rule}.{name}"
            a = tensors.get(key)
            if a is None:
                raise UserError(source, "missing tensor", field=key)
            if kind not in ARRAY_KINDS:
                raise UserError(
                    source, f"unknown kind {kind!r}; expected one of {', '.join(ARRAY_KINDS)}", field=f"rules.{rule}.arrays.{name}"
                )
            if a.dtype.kind == "f":
                bad = {"finite": ~np.isfinite(a), "finite >= 0": ~(np.isfinite(a) & (a >= 0)), "no NaN": np.isnan(a), "no inf": np.isinf(a)}
            else:  # class ids (the speed rule's way): one byte each, so every kind holds and every 256-entry table reads them
                bad = {}
            if len(a) != n or (a.dtype.kind != "f" and a.dtype != np.uint8) or np.any(bad.get(kind, False)):
                raise UserError(
                    source,
                    f"expected {ARRAY_KINDS[kind]} (floats, or uint8 class ids), a row for each of the {n} samples; got {a.dtype} {a.shape}",
                    field=key,
                )
            out[rule][name] = a
    stray = sorted(k for k in tensors if k.startswith("rules.") and k.split(".")[1] not in out)
    if stray:
        raise UserError(source, "a rule's array that meta.rules does not declare", field=stray[0])
    return out


def _check_tensors(t: dict[str, np.ndarray], source: str) -> None:
    """Shapes, dtypes and finiteness of a dataset's tensors; every problem names the tensor."""
    U = t["U"]
    if U.ndim != 3 or U.dtype.kind != "f":
        raise UserError(source, f"expected floats of shape (N, m, k), got {U.dtype} {U.shape}", field="U")
    n, m = U.shape[:2]
    if not np.isfinite(U).all():
        raise UserError(source, "holds NaN or infinite utilities", field="U")
    for key, kinds in (("labels", "iu"), ("w", "f"), ("source", "iu")):
        if t[key].shape != (n,) or t[key].dtype.kind not in kinds:
            raise UserError(
                source, f"expected {n} {'integers' if kinds == 'iu' else 'floats'}, got {t[key].dtype} {t[key].shape}", field=key
            )
    if n and (t["labels"].min() < 0 or t["labels"].max() >= m):
        raise UserError(source, f"labels must index the {m} trajectories", field="labels")
    if not np.isfinite(t["w"]).all():
        raise UserError(source, "holds NaN or infinite yaw rates", field="w")
    if n and t["source"].min() < 0:
        raise UserError(source, "recording numbers must be >= 0", field="source")


def _check_shapes(first: tuple[str, Dataset], other: tuple[str, Dataset]) -> None:
    """A UserError naming ``other``'s file and array where a rule's array holds samples of
    another shape than ``first``'s (read another way before: the speed rule's grade, once one a
    station, now one a footprint point), unless either holds nothing known (all NaN: flat ground)."""
    (first_name, a_set), (name, b_set) = first, other
    for rule, arrays in a_set.rules.items():
        for array, a in arrays.items():
            b = b_set.rules.get(rule, {}).get(array)
            if b is None or b.shape[1:] == a.shape[1:] or _unknown(a) or _unknown(b):
                continue
            raise UserError(
                name,
                f"holds {b.shape[1:]} a sample where {first_name} holds {a.shape[1:]}; featurise all recordings the same way",
                field=f"rules.{rule}.{array}",
            )


def _unknown(a: np.ndarray) -> bool:
    """Whether a floating array holds nothing known (all NaN)."""
    return a.dtype.kind == "f" and not np.isfinite(a).any()


def _widen_unknowns(sets: list[tuple[str, Dataset]]) -> list[tuple[str, Dataset]]:
    """``sets`` with each rule array that holds nothing known (all NaN) in the shape the others
    hold their samples in (:func:`_check_shapes` let them through), so that they concatenate."""
    out = []
    for name, d in sets:
        rules = {}
        for rule, arrays in d.rules.items():
            rules[rule] = dict(arrays)
            for array, a in arrays.items():
                others = (o.rules.get(rule, {}).get(array) for _, o in sets)
                known = [o for o in others if o is not None and not _unknown(o)]
                if known and _unknown(a) and a.shape[1:] != known[0].shape[1:]:
                    rules[rule][array] = np.full((len(a), *known[0].shape[1:]), np.nan, dtype=a.dtype)
        out.append((name, replace(d, rules=rules)))
    return out


def merge_datasets(sets: list[tuple[str, Dataset]]) -> Dataset:
    """One dataset from several (named by their files), which must share features, camera, classes
    and the order those that declare one declare; samples keep their order, and ``source`` numbers
    the recordings across all."""
    if not sets:
        raise UserError("train", "no training data given")
    first_name, first = sets[0]
    for name, d in sets[1:]:
        for key in ("features", "camera", "classes", "rules"):
            if d.meta.get(key) != first.meta.get(key):
                raise UserError(name, f"differs from {first_name} in {key}; featurise all recordings the same way", field=key)
        _check_shapes((first_name, first), (name, d))
    profile = _declared_order([(name, name, d.meta) for name, d in sets], "featurise drives of one order together")
    if len(sets) == 1:
        return first
    sets = _widen_unknowns(sets)
    # Each dataset's recordings are numbered after those of the datasets before it: by the
    # recordings it lists (a recording may have left no samples), else by its highest source.
    counts = [len(d.meta.get("recordings") or []) or (int(d.source.max()) + 1 if len(d) else 0) for _, d in sets[:-1]]
    offsets = np.cumsum([0] + counts)
    return Dataset(
        np.concatenate([d.U for _, d in sets]),
        np.concatenate([d.labels for _, d in sets]),
        np.concatenate([d.w for _, d in sets]),
        np.concatenate([d.source + off for off, (_, d) in zip(offsets, sets)]),
        {**first.meta, "profile": profile, "recordings": [r for _, d in sets for r in d.meta.get("recordings", [])]},
        {rule: {name: np.concatenate([d.rules[rule][name] for _, d in sets]) for name in arrays} for rule, arrays in first.rules.items()},
    )


def training_data(
    paths: list[Path], features: FeatureConfig, rules: tuple[RuleData, ...] = (), progress: Callable[[Featuring], None] | None = None
) -> Dataset:
    """The samples of ``paths``: recording directories, featurised under ``features`` with the
    arrays ``rules`` read, and dataset files (from ``terrapref featurize``), loaded as they are;
    merged into one dataset."""
    recordings = [read_recording(p) for p in paths if Path(p).is_dir()]
    sets: list[tuple[str, Dataset]] = []
    if recordings:
        sets.append((str(recordings[0].path), build_dataset(recordings, features, rules=rules, progress=progress)))
    files = [(str(p), load_dataset(p)) for p in paths if not Path(p).is_dir()]
    merged = merge_datasets(sets + files)
    names = [str(r.path) for r in recordings]  # each drive by the input it came from
    names += [f"{entry.get('path', 'a drive')} (in {name})" for name, d in files for entry in d.meta.get("recordings") or []]
    check_distinct_drives(merged, names)
    return merged


def check_distinct_drives(data: Dataset, names: Sequence[str] = ()) -> None:
    """Refuse one drive given twice under two names (a copy of a recording, or a recording beside
    a dataset featurised from it): its samples would count twice, its intervals read twice as
    tight, and its frames land in training and validation both. A drive is known by its samples;
    ``names`` name the drives by their sources (default: the paths the dataset lists).

    Raises:
        UserError: naming the second of the two and the first.
    """
    names = list(names) or [str(r.get("path", "")) for r in data.meta.get("recordings") or []]

    def name(i: int) -> str:
        return names[i] if i < len(names) and names[i] else f"recording {i + 1}"

    seen: dict[str, int] = {}
    order = np.argsort(data.source, kind="stable")
    for chunk in np.split(order, np.flatnonzero(np.diff(data.source[order])) + 1):
        if not len(chunk):
            continue
        drive = hashlib.sha256(np.ascontiguousarray(data.U[chunk]).tobytes() + np.ascontiguousarray(data.labels[chunk]).tobytes())
        i, key = int(data.source[chunk[0]]), drive.hexdigest()
        if key in seen:
            raise UserError(
                name(i), f"holds the same drive as {name(seen[key])}: its frames would count twice; give each drive once", field="frames"
            )
        seen[key] = i


def check_learnable(data: Dataset, source: str | Path) -> None:
    """Refuse samples with nothing to learn from: none at all, or every one with the same label
    (the drive never steered, so there is no choice between trajectories).

    Raises:
        UserError: naming ``source`` (the first input the samples came from).
    """
    if len(data) == 0:
        raise UserError(str(source), "holds no samples to train on", field="frames")
    if len(np.unique(data.labels)) < 2:
        raise UserError(
            str(source),
            f"every sample has the same label ({int(data.labels[0])}): the drive never steered, there is no choice to learn",
            field="labels",
        )
