"""Shared test helpers (not collected: pytest only collects test_*.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from terrapref.camera import CameraConfig, PinholeCamera
from terrapref.dataset import FORMAT as DATASET_FORMAT
from terrapref.dataset import Dataset, save_dataset
from terrapref.features import FeatureConfig
from terrapref.learning.model_file import save_model
from terrapref.learning.network import ClassifierConfig
from terrapref.learning.train import TrainConfig
from terrapref.terrain import default_classes

TESTS = Path(__file__).resolve().parent  # the tests' folder: their data, and the modules they share
REPO = TESTS.parent  # the repository: examples/, docs/, scripts/
SHORT_COURSE = TESTS / "data" / "short_course.yaml"
"""demo_course's classes on a 32 m trail (about 320 frames at 1 m/s, demo_course's 575): a
course for tests that need a drive of every class, not a long one."""

TINY_COURSE = TESTS / "data" / "tiny_course.yaml"
"""A 12 m trail past a mud patch (about 106 frames): a course for tests that need a drive, not
what it shows."""

TINY_RELIEF = TESTS / "data" / "tiny_relief.yaml"
"""A 7 m trail over a low mound (about 56 frames, every one with a depth image): a course for
tests that need a drive on relief, not what it shows."""


def model_meta(features: FeatureConfig | None = None, camera: CameraConfig | None = None, profile: tuple[str, ...] | None = None) -> dict:
    """The configuration a model or dataset file carries, defaults unless given."""
    classes = default_classes()
    return {
        "features": (features or FeatureConfig()).to_dict(),
        "camera": (camera or CameraConfig()).to_dict(),
        "classes": classes.to_dict(),
        "profile": list(profile or classes.profile),
    }


LINEAR_W = np.array([-8.0, -4.0, -2.0, -1.0, 6.0], dtype=np.float32)
"""The skip path's weights of the linear test model: shy from each terrain class, follow the path."""


def skip_path_weights(config: ClassifierConfig, w: np.ndarray = LINEAR_W) -> dict[str, np.ndarray]:
    """C reduced to its skip path: logits = U @ w exactly (the hidden layers output zero)."""
    dims = [config.m] + [config.hidden] * config.depth + [config.m]
    weights = {"compress.weight": np.array(w, np.float32)[None], "compress.bias": np.zeros(1, np.float32)}  # a copy: callers may change it
    for i, (a, b) in enumerate(zip(dims[:-1], dims[1:])):
        weights[f"layers.{i}.weight"] = np.zeros((b, a), np.float32)
        weights[f"layers.{i}.bias"] = np.zeros(b, np.float32)
    return weights


def linear_model(path: Path, camera: CameraConfig | None = None) -> Path:
    """C reduced to its skip path, logits = U @ LINEAR_W: follows the path, shies from terrain;
    drives the demo course to the end in about a minute of simulated time."""
    config = ClassifierConfig(hidden=8, skip=True)
    return save_model(path, config, skip_path_weights(config), model_meta(camera=camera))


def dataset_file(path: Path, n: int = 300, seed: int = 0) -> Path:
    """A random dataset of ``n`` samples with the default configuration, saved at ``path``."""
    rng = np.random.default_rng(seed)
    meta = {"format": DATASET_FORMAT, **model_meta()}
    data = Dataset(
        rng.uniform(0, 1, (n, 21, 5)).astype(np.float32), rng.integers(0, 21, n), np.zeros(n, np.float32), np.zeros(n, np.int64), meta
    )
    return save_dataset(data, path)


def one_line_error(capsys, *words: str, progress: str | None = None) -> str:
    """The one line of a refusal on stderr, which names every one of ``words``; with ``progress``,
    after the lines of that progress bar (a command that failed part way)."""
    err = capsys.readouterr().err
    lines = [line for line in err.strip().splitlines() if progress is None or not line.startswith(f"{progress}: ")]
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert "Traceback" not in err and "internal error" not in err, err
    for word in words:
        assert word in lines[0], err
    return lines[0]


# --- training data and weights for the learning tests -------------------------------------------

M, K = 21, 5
W_TRUE = np.array([-3.0, -1.5, -0.5, 0.5, 2.0], dtype=np.float32)  # a fixed linear utility over U's columns


def dataset_of(U: np.ndarray, labels: np.ndarray) -> Dataset:
    """A dataset of utilities ``U`` (n, M, K) and labels, with the default configuration."""
    n = len(labels)
    meta = {"format": DATASET_FORMAT, **model_meta()}
    return Dataset(U.astype(np.float32), labels.astype(np.int64), np.zeros(n, np.float32), np.zeros(n, np.int64), meta)


def random_dataset(n: int, seed: int = 0) -> Dataset:
    """U uniform in [0, 1], labels uniform: nothing to learn, plenty to overfit."""
    rng = np.random.default_rng(seed)
    return dataset_of(rng.uniform(0, 1, (n, M, K)), rng.integers(0, M, n))


def linear_dataset(n: int, margin: float = 0.5, seed: int = 0) -> Dataset:
    """Labels = argmax over trajectories of U @ W_TRUE, keeping samples whose best score beats
    the runner-up by ``margin`` (so that the direction of W_TRUE, not its last digit, decides)."""
    rng = np.random.default_rng(seed)
    kept: list[np.ndarray] = []
    while sum(map(len, kept)) < n:
        U = rng.uniform(0, 1, (n, M, K)).astype(np.float32)
        top2 = np.sort(U @ W_TRUE, axis=1)[:, -2:]
        kept.append(U[top2[:, 1] - top2[:, 0] >= margin])
    U = np.concatenate(kept)[:n]
    return dataset_of(U, np.argmax(U @ W_TRUE, axis=1))


def sparse_terrain_dataset(n: int, seed: int = 0) -> Dataset:
    """Sparse terrain and a distance peak, labels sometimes away from the peak (where terrain is in view)."""
    rng = np.random.default_rng(seed)
    U = np.zeros((n, M, K), np.float32)
    peak = rng.integers(0, M, n)
    U[:, :, -1] = 1.0 - np.abs(np.arange(M)[None] - peak[:, None]) / (M - 1)
    terrain = rng.random(n) < 0.5
    U[terrain, rng.integers(0, M, terrain.sum()), rng.integers(0, K - 1, terrain.sum())] = 1.0
    labels = np.where(terrain & (rng.random(n) < 0.5), rng.integers(0, M, n), peak)
    return dataset_of(U, labels)


def assert_weights_equal(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> None:
    assert set(a) == set(b)
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)


def weights_differ(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> bool:
    return any(not np.array_equal(a[k], b[k]) for k in a)


def random_weights(config: ClassifierConfig, seed: int = 0) -> dict[str, np.ndarray]:
    """PyTorch's initial weights for ``config`` under ``seed``, as NumPy arrays."""
    import torch  # here, so that the programs the tests start in fresh interpreters do not pay for it

    from torch_net import UtilityClassifier

    torch.manual_seed(seed)
    return {k: v.detach().numpy().copy() for k, v in UtilityClassifier(config).state_dict().items()}


def train_config(base: TrainConfig | None = None, **options) -> TrainConfig:
    """A training configuration written the short way: each option goes to the part that has it
    (``epochs`` to the optimiser, ``hidden`` to the classifier, ``mirror`` to the data options)."""
    from dataclasses import fields, replace

    config = base or TrainConfig()
    parts: dict[str, dict] = {}
    for name, value in options.items():
        if name in ("seed",):
            config = replace(config, seed=value)
            continue
        part = next(p for p in ("optimiser", "classifier", "data") if name in {f.name for f in fields(getattr(config, p))})
        parts.setdefault(part, {})[name] = value
    return config.updated(parts)


def flat_depth(camera: PinholeCamera) -> tuple[np.ndarray, np.ndarray]:
    """Every pixel's depth along the optical axis on the plane z = 0 (NaN: no ground in range),
    and its ground distance ahead of the camera [m], from the pinhole model alone: the depth
    image of level ground, (H, W) each."""
    rows, cols = np.mgrid[0 : camera.config.height_px, 0 : camera.config.width_px]
    ground, ok = camera.back_project(np.stack([cols + 0.5, rows + 0.5], axis=-1))
    point = np.concatenate([ground, np.zeros(ground.shape[:-1] + (1,))], axis=-1) - camera.t
    return np.where(ok, point @ camera.R[2], np.nan), np.where(ok, ground[..., 0] - camera.t[0], np.nan)
