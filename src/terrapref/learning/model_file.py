"""Model files: weights in safetensors, configuration and provenance in its JSON metadata.

Loading reads tensors and a JSON header only; no code from the file is ever executed.

The header's ``stages`` lists the decision stages fitted with C, one block each under its
``type`` (terrapref.planner.stages reads them). Files written before stages were listed carry
the second stage's linear utility as ``utility`` and the offset stage's as ``corridor``; they are
read as the same stages (:func:`stage_blocks`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from terrapref.camera import CameraConfig
from terrapref.errors import UserError
from terrapref.features import FeatureConfig
from terrapref.learning.network import MEMBERS, ClassifierConfig, member_prefix
from terrapref.tensorfile import read_tensor_file, write_tensor_file
from terrapref.terrain import ClassTable

FORMAT = "terrapref-model/1"
CLASSIFIER = "classifier"  # the metadata's "kind" of C; baselines write their own kinds


@dataclass(frozen=True)
class LoadedModel:
    """A trained classifier and everything it was trained under."""

    path: str
    classifier: ClassifierConfig
    weights: dict[str, np.ndarray]
    features: FeatureConfig
    camera: CameraConfig
    classes: ClassTable
    profile: tuple[str, ...]
    meta: dict
    stages: tuple[dict, ...] = ()  # the decision stages' blocks, in order (terrapref.planner.stages reads them)


def save_model(path: str | Path, classifier: ClassifierConfig, weights: dict[str, np.ndarray], meta: dict) -> Path:
    """Write weights and metadata atomically. ``meta`` must hold features, camera, classes, profile."""
    header = {"format": FORMAT, "kind": CLASSIFIER, "classifier": classifier.to_dict(), **meta}
    return write_tensor_file(path, {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in weights.items()}, header)


def read_model_file(path: str | Path) -> tuple[dict[str, np.ndarray], dict]:
    """Tensors and metadata of any model file (C or a baseline); ``meta["kind"]`` says which."""
    weights, meta = read_tensor_file(path, FORMAT, "no such model file", "not a safetensors model file")
    meta.setdefault("kind", CLASSIFIER)
    return weights, meta


def load_model(path: str | Path) -> LoadedModel:
    """Read a model file of C; every problem is a :class:`UserError` naming the file and the field."""
    weights, meta = read_model_file(path)
    return classifier_from(weights, meta, str(path))


def classifier_from(weights: dict[str, np.ndarray], meta: dict, source: str) -> LoadedModel:
    """Check and assemble C from a model file's tensors and metadata (see :func:`read_model_file`)."""
    if meta["kind"] != CLASSIFIER:
        raise UserError(source, f"holds a {meta['kind']!r} model, not the classifier C", field="kind")
    features, camera, classes, profile = model_context(meta, source)
    try:
        classifier = ClassifierConfig.from_dict(meta["classifier"])
    except KeyError as exc:
        raise UserError(source, "missing", field=str(exc.args[0])) from None
    except (TypeError, ValueError) as exc:
        field = "classifier.channels" if "channels" in str(exc) else "classifier"
        raise UserError(source, f"invalid configuration: {exc}", field=field) from None
    # The header's member count is checked against the weights before shapes are built from it.
    members = {name.split(".")[1] for name in weights if name.startswith(f"{MEMBERS}.")}
    if members != ({str(j) for j in range(classifier.members)} if classifier.members > 1 else set()):
        raise UserError(source, f"header says {classifier.members} member(s), the weights hold {len(members) or 1}", field="classifier.members")
    expected = expected_shapes(classifier)
    if set(weights) != set(expected):
        raise UserError(source, f"weights do not match the classifier (missing {sorted(set(expected) - set(weights))}, extra {sorted(set(weights) - set(expected))})", field="weights")
    for name, shape in expected.items():
        if tuple(weights[name].shape) != shape:
            raise UserError(source, f"has shape {tuple(weights[name].shape)}, expected {shape}", field=f"weights.{name}")
        if weights[name].dtype.kind != "f" or not np.isfinite(weights[name]).all():
            raise UserError(source, f"expected finite floats, got {weights[name].dtype}" + (" with NaN or infinite values" if weights[name].dtype.kind == "f" else ""), field=f"weights.{name}")
    if classifier.m != features.preference.m or classifier.n_features != features.n_features:
        raise UserError(source, "classifier shape does not match its feature configuration", field="classifier")
    return LoadedModel(source, classifier, weights, features, camera, classes, profile, meta, stage_blocks(meta, features, source))


def stage_blocks(meta: dict, features: FeatureConfig, source: str) -> tuple[dict, ...]:
    """The header's ``stages`` (a list of mappings, each with a ``type``), or, in a file written
    before stages were listed, its ``utility`` (the second stage; fitted through the look-ahead's
    ``after_s`` and ``stride`` when the features carry one) and ``corridor`` (the offset stage,
    which drove), in that order."""
    if "stages" in meta:
        blocks = meta["stages"]
        if not isinstance(blocks, list):
            raise UserError(source, "expected a list of stages", field="stages")
        for i, block in enumerate(blocks):
            if not isinstance(block, dict) or not isinstance(block.get("type"), str):
                raise UserError(source, "expected a mapping with a type", field=f"stages[{i}]")
        return tuple(blocks)
    blocks = []
    for key, kind in (("utility", "second_stage"), ("corridor", "offset")):
        data = meta.get(key)
        if data is None:
            continue
        if not isinstance(data, dict):
            raise UserError(source, "expected a mapping", field=key)
        look = features.lookahead if key == "utility" and features.lookahead is not None else None
        defaults = {"weight": 1.5, **({"after_s": look.after_s, "stride": look.stride} if look else {})} if key == "utility" else {}
        blocks.append({"type": kind, **defaults, **data})
    return tuple(blocks)


def model_context(meta: dict, source: str) -> tuple[FeatureConfig, CameraConfig, ClassTable, tuple[str, ...]]:
    """The configuration every model file carries: features, camera, classes, profile."""
    for key in ("features", "camera", "classes"):
        if key in meta and not isinstance(meta[key], dict):
            raise UserError(source, "expected a mapping", field=key)
    try:
        features = FeatureConfig.from_dict(meta["features"])
        camera = CameraConfig.from_dict(meta["camera"])
        classes = ClassTable.from_dict(meta["classes"], source)
        profile = tuple(meta["profile"])
    except KeyError as exc:
        raise UserError(source, "missing", field=str(exc.args[0])) from None
    except (TypeError, ValueError) as exc:
        raise UserError(source, f"invalid configuration: {exc}", field="metadata") from None
    return features, camera, classes, profile


def expected_shapes(c: ClassifierConfig) -> dict[str, tuple[int, ...]]:
    """Weight names and shapes of a classifier (PyTorch state-dict names, per member in an ensemble)."""
    if c.members > 1:
        one = expected_shapes(replace(c, members=1))
        return {member_prefix(j) + name: shape for j in range(c.members) for name, shape in one.items()}
    shapes: dict[str, tuple[int, ...]] = {}
    if c.compress:
        shapes |= {"compress.weight": (1, c.n_features), "compress.bias": (1,)}
    dims = [c.width_in] + [c.hidden] * c.depth + [c.m]
    for i, (a, b) in enumerate(zip(dims[:-1], dims[1:])):
        shapes |= {f"layers.{i}.weight": (b, a), f"layers.{i}.bias": (b,)}
    return shapes


def _differences(a: dict, b: dict, prefix: str = "") -> list[str]:
    """Dotted names of the leaves that differ between two nested mappings."""
    out = []
    for key in sorted(set(a) | set(b)):
        va, vb = a.get(key), b.get(key)
        if isinstance(va, dict) and isinstance(vb, dict):
            out += _differences(va, vb, f"{prefix}{key}.")
        elif va != vb:
            out.append(f"{prefix}{key}")
    return out


def check_compatible(model: LoadedModel, camera: CameraConfig, features: FeatureConfig | None = None) -> None:
    """Refuse a model trained under another camera or preference set than the planner's."""
    if not model.camera.same_geometry(camera):
        diff = _differences(model.camera.to_dict(), camera.to_dict())
        raise UserError(model.path, f"trained for another camera ({', '.join(diff)} differ); re-featurise the recordings with this camera and retrain", field="camera")
    if features is not None and model.features != features:
        diff = _differences(model.features.to_dict(), features.to_dict())
        raise UserError(model.path, f"trained with another preference set or feature configuration ({', '.join(diff)} differ)", field="features")
