"""Featurisation: recordings -> training sets of (U, label), saved without pickle (safetensors).

A dataset carries the configuration that produced it (features, camera, classes, profile,
source recordings) and a fingerprint of its contents, so a model trained on it can be checked
against the planner's configuration later. A recording can be featurised under another camera
(frames are re-rendered from its stored scenario at its stored poses) or another preference
set (labels are re-derived from the recorded continuous w) without driving again.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import NamedTuple

import numpy as np

from terrapref.camera import CameraConfig, PinholeCamera, SegmentationRenderer, SegmentationView
from terrapref.demos.recording import Recording, read_recording, require_meta
from terrapref.errors import UserError
from terrapref.features import FeatureConfig, UtilityFeaturizer
from terrapref.features.corridor import CorridorFeatures, GroundMap, TerrainColumns, intent_offsets
from terrapref.features.lookahead import Lookahead
from terrapref.scenario import Scenario, parse_scenario
from terrapref.scenario.path import PathTracker, ReferencePath
from terrapref.tensorfile import read_tensor_file, write_tensor_file
from terrapref.terrain import ClassTable
from terrapref.world import rasterise

FORMAT = "terrapref-dataset/1"


class CorridorData(NamedTuple):
    """Each frame's offset corridor (terrapref.features.corridor) and what the driver steered for.

    Attributes:
        features: metres per terrain class, never seen, and the detour's price, per candidate
            offset, shape (N, O, K + 2) float32.
        near_m: distance along the path to the first terrain on it, shape (N,) float32 [m]
            (inf: none within the corridor).
        intent_m: the offset the driver was steering for, shape (N,) float32 [m] (NaN: the
            recording ends before its reaction time has passed).
    """

    features: np.ndarray
    near_m: np.ndarray
    intent_m: np.ndarray


@dataclass(frozen=True)
class Dataset:
    """Training samples and the configuration that produced them.

    Attributes:
        U: utility features, shape (N, m, K + 1) float32.
        labels: demonstrated control-set index, shape (N,) int64.
        w: demonstrated continuous yaw rate [rad/s], shape (N,) float32.
        source: index of the recording each sample came from, shape (N,) int64.
        meta: features, camera, classes, profile, recordings (JSON-serialisable).
        U2: the look-ahead utilities of every frame, shape (N, m, m, K + 1) float16, when the
            feature configuration asks for them (``FeatureConfig.lookahead``); else None.
        corridor: every frame's offset corridor and intended offset, when the feature
            configuration asks for them (``FeatureConfig.corridor``); else None.
    """

    U: np.ndarray
    labels: np.ndarray
    w: np.ndarray
    source: np.ndarray
    meta: dict
    U2: np.ndarray | None = None
    corridor: CorridorData | None = None

    def __len__(self) -> int:
        return len(self.labels)

    @property
    def feature_config(self) -> FeatureConfig:
        return FeatureConfig.from_dict(self.meta["features"])

    @property
    def camera_config(self) -> CameraConfig:
        return CameraConfig.from_dict(self.meta["camera"])

    @property
    def fingerprint(self) -> str:
        h = hashlib.sha256()
        extra = (() if self.U2 is None else (self.U2,)) + (() if self.corridor is None else tuple(self.corridor))
        for a in (self.U, self.labels, *extra):
            h.update(np.ascontiguousarray(a).tobytes())
        return h.hexdigest()[:16]


class Featurised(NamedTuple):
    """One recording's samples (:class:`Dataset`'s arrays, without ``source``)."""

    U: np.ndarray
    labels: np.ndarray
    w: np.ndarray
    U2: np.ndarray | None
    corridor: CorridorData | None


def featurize_recording(recording: Recording, features: FeatureConfig, camera: CameraConfig | None = None,
                        on_frame: Callable[[int], None] | None = None) -> Featurised:
    """U (F, m, K + 1), labels (F,), w (F,) and, when ``features.lookahead`` asks, U2 (F, m, m, K + 1)
    float16, and when ``features.corridor`` asks, the corridor data, for every frame of a
    recording taken on the map (frames off it are left out).

    Args:
        camera: None uses the recorded frames; another configuration re-renders each frame from
            the recording's scenario at its recorded pose.
        on_frame: called after each frame with the frames done so far (a long recording takes a minute).
    """
    require_meta(recording, "classes", "camera")
    classes = recording.classes
    rec_camera = CameraConfig.from_dict(recording.meta["camera"])
    camera = camera or rec_camera
    scenario = parse_scenario(recording.scenario, str(recording.path / "scenario.yaml"), classes)
    featurizer = UtilityFeaturizer(features, PinholeCamera(camera), classes)
    path = ReferencePath(np.asarray(recording.meta.get("path", scenario.waypoints), dtype=float))
    tracker = PathTracker(path)
    perceived = recording.perception
    if not camera.same_geometry(rec_camera) and perceived != "clean":
        raise UserError(str(recording.path / "meta.json"), f"its frames are what the robot received under perception {perceived!r}; "
                        "rendering them again under another camera would give the simulator's truth instead", field="perception")
    renderer = None if camera.same_geometry(rec_camera) else SegmentationRenderer(PinholeCamera(camera), rasterise(scenario))
    lookahead = Lookahead(features.lookahead, featurizer, PinholeCamera(camera)) if features.lookahead is not None else None
    if len(recording) == 0:
        raise UserError(str(recording.path / "frames.jsonl"), "holds no frames to featurise", field="frames")
    keep = np.flatnonzero(on_map(recording.poses, scenario))  # frames taken off the map are not training data
    if len(keep) == 0:
        raise UserError(str(recording.path / "frames.jsonl"), f"every frame was taken off the {scenario.size_m[0]:g} x {scenario.size_m[1]:g} m map", field="pose")
    n, m = len(keep), featurizer.m
    known = np.zeros(256, dtype=bool)
    known[[c.id for c in classes.classes]] = True
    known[255] = True
    shape = (rec_camera.height_px, rec_camera.width_px)
    U = np.empty((n, m, features.n_features), dtype=np.float32)
    U2 = np.empty((n, m, m, features.n_terrain + 1), dtype=np.float16) if lookahead is not None else None
    # Between frames that are not consecutive (a ride-along's corrections, frames left out off
    # the map) the vehicle may have gone further than the tracker's window: widen it by what
    # the vehicle could have driven in the gap.
    period = recording.frame_period_s
    v_max = _max_speed(recording.meta)
    corridor = _CorridorReader(features, featurizer, PinholeCamera(camera), classes, n) if features.corridor is not None else None
    for j, i in enumerate(keep):
        pose = tuple(recording.poses[i])
        view = _frame_view(recording, i, renderer, pose, shape, known)
        gap_s = recording.times[i] - recording.times[keep[j - 1]] if j > 0 else 0.0
        s = tracker.update(recording.poses[i, :2], ahead_m=v_max * gap_s + 2.0 if gap_s > 1.5 * period else None)
        U[j] = featurizer(view, pose, path, s)
        if lookahead is not None:
            U2[j] = lookahead.utilities(view, pose, path, s)
        if corridor is not None:
            corridor.read(j, view, pose, path, s)
        if on_frame is not None:
            on_frame(j + 1)
    w = recording.commands[keep, 1].astype(np.float32)
    labels = np.asarray(features.preference.control.label_of(w), dtype=np.int64).reshape(n)
    return Featurised(U, labels, w, U2, corridor.data(recording, keep, path) if corridor is not None else None)


class _CorridorReader:
    """The corridor of each frame of one recording, read in order (the ground map gathers them)."""

    def __init__(self, features: FeatureConfig, featurizer: UtilityFeaturizer, camera: PinholeCamera, classes: ClassTable, n: int) -> None:
        config, k = features.corridor, features.n_terrain
        self.config = config
        self.map = GroundMap(camera, TerrainColumns.of(featurizer.class_columns, k, classes), config)
        self.corridor = CorridorFeatures(config, k)
        self.features = np.empty((n, len(self.corridor.offsets), k + 2), dtype=np.float32)
        self.near = np.empty(n, dtype=np.float32)
        self.progress = np.empty(n)

    def read(self, j: int, view: SegmentationView, pose: tuple, path: ReferencePath, s: float) -> None:
        self.map.update(view, pose)
        frame = self.corridor(self.map, path, s)
        self.features[j], self.near[j] = frame.features, frame.near_m
        self.progress[j] = s

    def data(self, recording: Recording, keep: np.ndarray, path: ReferencePath) -> CorridorData:
        """The corridor data, with each frame's intended offset read from the command one reaction time later."""
        delay = round(self.config.intent_delay_s / recording.frame_period_s)
        later = np.full((len(keep), 2), np.nan)
        ahead = keep + delay
        ok = ahead < len(recording)
        # Only where the frame that much later is the next ones' in time (not across a gap).
        ok[ok] &= np.abs(recording.times[ahead[ok]] - recording.times[keep[ok]] - delay * recording.frame_period_s) < 0.5 * recording.frame_period_s
        later[ok] = recording.commands[ahead[ok]]
        intent = intent_offsets(recording.poses[keep], later, self.progress, path, self.corridor.offsets,
                                self.config.intent_lookahead_m)
        return CorridorData(self.features, self.near, intent.astype(np.float32))


def _frame_view(recording: Recording, i: int, renderer: SegmentationRenderer | None, pose: tuple, shape: tuple[int, int],
                known: np.ndarray) -> SegmentationView:
    """Frame ``i`` as the featurizer reads it: re-rendered under another camera, the simulation's
    own view for a recording kept in memory (only the pixels read are rendered), or the recorded
    image, refused when its size or class ids do not fit the recording's camera and classes."""
    if renderer is not None:
        return SegmentationView.of(renderer.render(pose))
    if recording.views is not None:
        return recording.views[i]
    image = recording.image(i)
    if image.shape != shape or not known[image].all():
        what = f"is {image.shape[1]} x {image.shape[0]}, the camera's {shape[1]} x {shape[0]}" if image.shape != shape else \
            f"holds class ids {sorted(set(np.unique(image).tolist()) - set(np.flatnonzero(known).tolist()))[:5]} that the class table does not have"
        raise UserError(str(recording.path / recording.image_files[i]), what)
    return SegmentationView.of(image)


def _max_speed(meta: dict) -> float:
    """The recorded vehicle's top speed [m/s] (1 when the recording does not say)."""
    sim = meta.get("sim")
    vehicle = sim.get("vehicle") if isinstance(sim, dict) else None
    v = vehicle.get("max_speed_mps") if isinstance(vehicle, dict) else None
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0 else 1.0


def on_map(poses: np.ndarray, scenario: Scenario) -> np.ndarray:
    """Which poses (F, 3) lie on the scenario's map, (F,) bool."""
    w_m, h_m = scenario.size_m
    x, y = poses[:, 0], poses[:, 1]
    return (x >= 0) & (x <= w_m) & (y >= 0) & (y <= h_m)


def build_dataset(recordings: list[Recording], features: FeatureConfig, camera: CameraConfig | None = None, progress=None,
                  cache: dict | None = None, frames: Callable[[int, int], None] | None = None) -> Dataset:
    """Featurise several recordings into one dataset (they must share classes and profile).

    ``progress(k, n)`` is called after each of the ``n`` recordings, ``frames(done, total)`` after
    each frame of them all.

    ``cache`` keeps each recording's features (keyed by the recording object, the features and
    the camera), so that a later dataset of some of the same recordings featurises only the
    others: the same arrays, computed once.
    """
    if not recordings:
        raise UserError("featurize", "no recordings given")
    first = recordings[0]
    if first.meta.get("profile") is None:
        raise UserError(str(first.path / "meta.json"), "names no preference order; a model needs the order its driver had "
                        "(an imported drive: import it again with --profile, or add profile: to its robot file)", field="profile")
    for rec in recordings[1:]:
        for key in ("classes", "profile"):
            if rec.meta.get(key) != first.meta.get(key):
                raise UserError(str(rec.path / "meta.json"), f"differs from {first.path} in {key}; featurise them separately", field=key)
    # The terrain columns are the recordings' class table's.
    require_meta(first, "classes")
    features = replace(features, feature_classes=first.classes.feature_names)
    parts = []
    total, before = sum(len(r) for r in recordings), 0
    for k, rec in enumerate(recordings):
        key = (id(rec), features, camera)
        if cache is None or key not in cache:
            part = featurize_recording(rec, features, camera, None if frames is None else (lambda j, b=before: frames(b + j, total)))
            if cache is not None:
                cache[key] = (rec, part)  # the recording held with its features: its id is not reused while the cache lives
        parts.append(part if cache is None else cache[key][1])
        before += len(rec)
        if progress is not None:
            progress(k + 1, len(recordings))
    U = np.concatenate([p[0] for p in parts])
    labels = np.concatenate([p[1] for p in parts])
    w = np.concatenate([p[2] for p in parts])
    U2 = np.concatenate([p.U2 for p in parts]) if features.lookahead is not None else None
    corridor = CorridorData(*(np.concatenate(a) for a in zip(*(p.corridor for p in parts)))) if features.corridor is not None else None
    source = np.concatenate([np.full(len(p[1]), k, dtype=np.int64) for k, p in enumerate(parts)])
    meta = {
        "format": FORMAT,
        "features": features.to_dict(),
        "camera": (camera or CameraConfig.from_dict(first.meta["camera"])).to_dict(),
        "classes": first.meta["classes"],
        "profile": first.meta.get("profile"),
        "recordings": [
            {"path": str(r.path), "scenario": r.meta.get("scenario"), "frames": len(r), "frames_used": len(p[1]), "complete": r.complete,
             "driver": r.meta.get("driver"), "perception": r.perception,
             **({"written": False} if r.in_memory else {})}
            for r, p in zip(recordings, parts, strict=True)
        ],
    }
    return Dataset(U, labels, w.astype(np.float32), source, meta, U2, corridor)


def save_dataset(dataset: Dataset, path: str | Path) -> Path:
    """Write a dataset as safetensors (tensors plus JSON metadata), atomically."""
    meta = {**dataset.meta, "format": FORMAT, "fingerprint": dataset.fingerprint, "samples": len(dataset)}
    tensors = {"U": dataset.U, "labels": dataset.labels, "w": dataset.w, "source": dataset.source}
    if dataset.U2 is not None:
        tensors["U2"] = dataset.U2
    if dataset.corridor is not None:
        tensors |= {f"corridor.{name}": a for name, a in zip(CorridorData._fields, dataset.corridor)}
    return write_tensor_file(path, tensors, meta)


def load_dataset(path: str | Path) -> Dataset:
    """Read a dataset written by :func:`save_dataset` (no code is executed on load)."""
    tensors, meta = read_tensor_file(path, FORMAT, "no such file", "not a terrapref dataset")
    for key in ("U", "labels", "w", "source"):
        if key not in tensors:
            raise UserError(str(path), "missing tensor", field=key)
    _check_tensors(tensors, str(path))
    try:
        FeatureConfig.from_dict(meta["features"])
        CameraConfig.from_dict(meta["camera"])
        ClassTable.from_dict(meta["classes"], str(path))
    except KeyError as exc:
        raise UserError(str(path), "missing", field=str(exc.args[0])) from None
    except (TypeError, ValueError, AttributeError) as exc:
        raise UserError(str(path), f"invalid configuration ({type(exc).__name__}: {exc})", field="metadata") from None
    if not isinstance(meta.get("profile"), list):
        raise UserError(str(path), "expected a list of class names", field="profile")
    corridor = CorridorData(*(tensors[f"corridor.{name}"] for name in CorridorData._fields)) if "corridor.features" in tensors else None
    return Dataset(tensors["U"], tensors["labels"], tensors["w"], tensors["source"], meta, tensors.get("U2"), corridor)


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
            raise UserError(source, f"expected {n} {'integers' if kinds == 'iu' else 'floats'}, got {t[key].dtype} {t[key].shape}", field=key)
    if n and (t["labels"].min() < 0 or t["labels"].max() >= m):
        raise UserError(source, f"labels must index the {m} trajectories", field="labels")
    if not np.isfinite(t["w"]).all():
        raise UserError(source, "holds NaN or infinite yaw rates", field="w")
    if n and t["source"].min() < 0:
        raise UserError(source, "recording numbers must be >= 0", field="source")
    U2 = t.get("U2")
    if U2 is not None and (U2.ndim != 4 or U2.shape[:3] != (n, m, m) or U2.dtype.kind != "f" or not np.isfinite(U2).all()):
        raise UserError(source, f"expected finite floats of shape ({n}, {m}, {m}, k), got {U2.dtype} {U2.shape}", field="U2")
    names = [f"corridor.{name}" for name in CorridorData._fields]
    present = [name in t for name in names]
    if any(present) and not all(present):
        raise UserError(source, "missing tensor", field=names[present.index(False)])
    if all(present):
        features, near, intent = (t[name] for name in names)
        if features.ndim != 3 or len(features) != n or features.dtype.kind != "f" or not np.isfinite(features).all() or (features < 0).any():
            raise UserError(source, f"expected finite metres >= 0 of shape ({n}, offsets, k + 2), got {features.dtype} {features.shape}", field=names[0])
        if near.shape != (n,) or near.dtype.kind != "f" or np.isnan(near).any():
            raise UserError(source, f"expected {n} distances (inf allowed, NaN not), got {near.dtype} {near.shape}", field=names[1])
        if intent.shape != (n,) or intent.dtype.kind != "f" or np.isinf(intent).any():
            raise UserError(source, f"expected {n} offsets (NaN allowed, inf not), got {intent.dtype} {intent.shape}", field=names[2])


def merge_datasets(sets: list[tuple[str, Dataset]]) -> Dataset:
    """One dataset from several (named by their files), which must share features, camera, classes
    and profile; samples keep their order, and ``source`` numbers the recordings across all."""
    if not sets:
        raise UserError("train", "no training data given")
    first_name, first = sets[0]
    for name, d in sets[1:]:
        for key in ("features", "camera", "classes", "profile"):
            if d.meta.get(key) != first.meta.get(key):
                raise UserError(name, f"differs from {first_name} in {key}; featurise all recordings the same way", field=key)
        if (d.U2 is None) != (first.U2 is None):
            raise UserError(name, f"carries look-ahead utilities and {first_name} does not, or the other way round", field="U2")
        if (d.corridor is None) != (first.corridor is None):
            raise UserError(name, f"carries corridor data and {first_name} does not, or the other way round", field="corridor")
    if len(sets) == 1:
        return first
    # Each dataset's recordings are numbered after those of the datasets before it: by the
    # recordings it lists (a recording may have left no samples), else by its highest source.
    counts = [len(d.meta.get("recordings") or []) or (int(d.source.max()) + 1 if len(d) else 0) for _, d in sets[:-1]]
    offsets = np.cumsum([0] + counts)
    return Dataset(
        np.concatenate([d.U for _, d in sets]), np.concatenate([d.labels for _, d in sets]), np.concatenate([d.w for _, d in sets]),
        np.concatenate([d.source + off for off, (_, d) in zip(offsets, sets)]),
        {**first.meta, "recordings": [r for _, d in sets for r in d.meta.get("recordings", [])]},
        None if first.U2 is None else np.concatenate([d.U2 for _, d in sets]),
        None if first.corridor is None else CorridorData(*(np.concatenate(a) for a in zip(*(d.corridor for _, d in sets)))),
    )


def training_data(paths: list[Path], features: FeatureConfig, progress=None) -> Dataset:
    """The samples of ``paths``: recording directories, featurised under ``features``, and dataset
    files (from ``terrapref featurize``), loaded as they are; merged into one dataset."""
    recordings = [read_recording(p) for p in paths if Path(p).is_dir()]
    sets: list[tuple[str, Dataset]] = []
    if recordings:
        sets.append((str(recordings[0].path), build_dataset(recordings, features, progress=progress)))
    sets += [(str(p), load_dataset(p)) for p in paths if not Path(p).is_dir()]
    return merge_datasets(sets)


def check_learnable(data: Dataset, source: str | Path) -> None:
    """Refuse samples with nothing to learn from: none at all, or every one with the same label
    (the drive never steered, so there is no choice between trajectories).

    Raises:
        UserError: naming ``source`` (the first input the samples came from).
    """
    if len(data) == 0:
        raise UserError(str(source), "holds no samples to train on", field="frames")
    if len(np.unique(data.labels)) < 2:
        raise UserError(str(source), f"every sample has the same label ({int(data.labels[0])}): the drive never steered, there is no choice to learn", field="labels")
