"""Model files: weights in safetensors, configuration and provenance in its JSON metadata (the
header, :class:`~terrapref.learning.header.ModelHeader`).

Loading reads tensors and a JSON header only; no code from the file is ever executed.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from terrapref.camera import CameraConfig
from terrapref.errors import UserError, described
from terrapref.features import FeatureConfig
from terrapref.learning.header import CLASSIFIER, FORMAT, ModelHeader, model_context, rule_blocks
from terrapref.learning.network import MEMBERS, ClassifierConfig, member_prefix
from terrapref.tensorfile import read_tensor_file, write_tensor_file
from terrapref.terrain import ClassTable

__all__ = [
    "CLASSIFIER",
    "FORMAT",
    "LoadedModel",
    "check_compatible",
    "classifier_from",
    "expected_shapes",
    "load_model",
    "model_context",
    "read_model_file",
    "rule_blocks",
    "save_model",
    "write_model",
]


@dataclass(frozen=True)
class LoadedModel:
    """A trained classifier and everything it was trained under.

    Attributes:
        path: the file it was read from.
        header: its header, checked.
        weights: C's weights, by PyTorch state-dict name.
        meta: the header as the file holds it (entries this version does not read included).
    """

    path: str
    header: ModelHeader
    weights: dict[str, np.ndarray]
    meta: dict

    @property
    def classifier(self) -> ClassifierConfig:
        return self.header.classifier

    @property
    def features(self) -> FeatureConfig:
        return self.header.features

    @property
    def camera(self) -> CameraConfig:
        return self.header.camera

    @property
    def classes(self) -> ClassTable:
        return self.header.classes

    @property
    def profile(self) -> tuple[str, ...]:
        return self.header.profile or ()


def write_model(path: str | Path, header: ModelHeader, weights: dict[str, np.ndarray]) -> Path:
    """Write C's weights under ``header``, atomically."""
    return _write(path, weights, header.to_dict())


def save_model(path: str | Path, classifier: ClassifierConfig, weights: dict[str, np.ndarray], meta: Mapping[str, Any]) -> Path:
    """Write C's weights under a header given as a mapping (made by hand: tests, tools), atomically;
    ``meta`` holds the entries after ``format``, ``kind`` and ``classifier``, at least features,
    camera, classes and profile. Training writes a :class:`ModelHeader` (:func:`write_model`)."""
    return _write(path, weights, {"format": FORMAT, "kind": CLASSIFIER, "classifier": classifier.to_dict(), **meta})


def write_model_file(path: str | Path, weights: dict[str, np.ndarray], header: Mapping[str, Any]) -> Path:
    """Write a model file of any kind, its tensors and its header as given, atomically (weights
    that are not finite are refused, nothing written)."""
    return _write(path, weights, dict(header))


def _write(path: str | Path, weights: dict[str, np.ndarray], header: dict[str, Any]) -> Path:
    """Write a model file; weights that are not finite (a diverged fit) are refused, nothing written."""
    for name, value in weights.items():
        if not np.isfinite(value).all():
            raise UserError(
                str(path),
                f"not written: {int(np.size(value) - np.isfinite(value).sum())} of its weights are not finite "
                "(NaN or inf: the fit diverged; a smaller --lr may help)",
                field=name,
            )
    return write_tensor_file(path, {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in weights.items()}, header)


def read_model_file(path: str | Path) -> tuple[dict[str, np.ndarray], dict]:
    """Tensors and metadata of any model file (C or a baseline); ``meta["kind"]`` says which.

    Raises:
        UserError: besides the file's own problems, a weight that is NaN or infinite, naming the
            tensor: a policy of such weights scores every trajectory NaN and drives nowhere.
    """
    if Path(path).is_dir():
        raise UserError(str(path), _folder_problem(Path(path)))
    weights, meta = read_tensor_file(path, FORMAT, "no such model file", "not a safetensors model file")
    for name, value in weights.items():
        if value.dtype.kind == "f" and not np.isfinite(value).all():
            bad = int(value.size - np.isfinite(value).sum())
            raise UserError(str(path), f"{bad} of its {value.size} weights are NaN or infinite", field=f"weights.{name}")
    meta.setdefault("kind", CLASSIFIER)
    if not isinstance(meta["kind"], str):
        raise UserError(str(path), f"expected the name of a kind of model, got {described(meta['kind'])}", field="kind")
    return weights, meta


def _folder_problem(path: Path) -> str:
    """What to say of a folder given as a model: a recording is taught into one by ``train``; a
    training's checkpoints are model files inside it."""
    from terrapref.demos.recording import is_recording

    if is_recording(path):
        return "a recording folder, not a model file; `terrapref train` makes a model of a recording"
    if path.name.endswith(".checkpoints"):
        return "a folder of a training's checkpoints, not a model file; name one of them (epoch_NNN.safetensors)"
    return "a folder, not a model file"


def load_model(path: str | Path) -> LoadedModel:
    """Read a model file of C; every problem is a :class:`UserError` naming the file and the field."""
    weights, meta = read_model_file(path)
    return classifier_from(weights, meta, str(path))


def classifier_from(weights: dict[str, np.ndarray], meta: dict, source: str) -> LoadedModel:
    """Check and assemble C from a model file's tensors and metadata (see :func:`read_model_file`)."""
    header = ModelHeader.from_dict(meta, source)
    classifier, features = header.classifier, header.features
    # The header's member count is checked against the weights before shapes are built from it.
    members = {name.split(".")[1] for name in weights if name.startswith(f"{MEMBERS}.")}
    claimed = classifier.members if classifier.members > 1 else 0  # counted first: a huge claim is refused at once
    if len(members) != claimed or members != {str(j) for j in range(claimed)}:
        said = f"header says {classifier.members} member(s), the weights hold {len(members) or 1}"
        if len(members) == claimed:  # as many, numbered otherwise
            held = ", ".join(sorted(members, key=lambda m: (len(m), m)))
            said = f"header says {claimed} member(s), numbered 0 to {claimed - 1}; the weights hold members {held}"
        raise UserError(source, said, field="classifier.members")
    expected = expected_shapes(classifier)
    if set(weights) != set(expected):
        raise UserError(
            source,
            f"weights do not match the classifier (missing {sorted(set(expected) - set(weights))}, extra {sorted(set(weights) - set(expected))})",
            field="weights",
        )
    for name, shape in expected.items():
        if tuple(weights[name].shape) != shape:
            raise UserError(source, f"has shape {tuple(weights[name].shape)}, expected {shape}", field=f"weights.{name}")
        if weights[name].dtype.kind != "f" or not np.isfinite(weights[name]).all():
            raise UserError(
                source,
                f"expected finite floats, got {weights[name].dtype}"
                + (" with NaN or infinite values" if weights[name].dtype.kind == "f" else ""),
                field=f"weights.{name}",
            )
    if classifier.m != features.preference.m or classifier.n_features != features.n_features:
        raise UserError(source, "classifier shape does not match its feature configuration", field="classifier")
    return LoadedModel(source, header, weights, meta)


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
        raise UserError(
            model.path,
            f"trained for another camera ({', '.join(diff)} differ); re-featurise the recordings with this camera and retrain",
            field="camera",
        )
    if features is not None and model.features != features:
        diff = _differences(model.features.to_dict(), features.to_dict())
        raise UserError(
            model.path, f"trained with another preference set or feature configuration ({', '.join(diff)} differ)", field="features"
        )
