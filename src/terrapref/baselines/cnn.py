"""End-to-end behaviour cloning: a small CNN from the segmentation image to the 21-way label.

The baseline the paper argues against: no utility features, no preference set geometry. Its
input is the segmentation image, downsampled by ``stride`` (nearest pixel) and one-hot per
class, and the reference path's position in the vehicle frame (points 1..8 m ahead of the
vehicle's progress, the same ones :class:`terrapref.planner.Planner` computes). It is trained
on the same recordings and scored by the same evaluation as C.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from terrapref.camera import CameraConfig, SegmentationView
from terrapref.demos.recording import Recording
from terrapref.extras import needs
from terrapref.features import FeatureConfig
from terrapref.learning.model_file import FORMAT, model_context
from terrapref.learning.train import class_weights, split_indices
from terrapref.planner.planner import PATH_AHEAD_M, path_ahead
from terrapref.planner.policy import CNN, Observation, Policy
from terrapref.records import to_plain
from terrapref.scenario.path import PathTracker, ReferencePath
from terrapref.tensorfile import write_tensor_file
from terrapref.terrain import ClassTable

with needs("cnn", "the CNN baseline"):  # this module is imported only for it
    import torch
    from torch import nn


@dataclass(frozen=True)
class CnnConfig:
    """Shape and training of the CNN baseline.

    Attributes:
        stride: image downsampling factor (640x480 -> 40x30 at 16).
        channels: output channels of the three stride-2 convolutions.
        hidden: width of the fully connected layer.
        n_classes: one-hot channels (class ids 0 .. n_classes - 1; others are all-zero).
        epochs, lr, batch_size, val_fraction, class_balance, seed: training, as for C.
    """

    stride: int = 16
    channels: tuple[int, int, int] = (16, 32, 32)
    hidden: int = 64
    n_classes: int = 5
    epochs: int = 40
    lr: float = 1e-3
    batch_size: int = 256
    val_fraction: float = 0.2
    class_balance: bool = True
    seed: int = 0

    def to_dict(self) -> dict:
        return to_plain(self)

    @classmethod
    def from_dict(cls, data: dict) -> CnnConfig:
        return cls(**{**data, "channels": tuple(data["channels"])})


class CnnNet(nn.Module):
    """The network ``config`` describes, for images downsampled to ``image_hw`` (h, w) and ``m`` trajectories."""

    def __init__(self, config: CnnConfig, image_hw: tuple[int, int], m: int) -> None:
        super().__init__()
        self.config = config
        c1, c2, c3 = config.channels
        self.conv = nn.Sequential(
            nn.Conv2d(config.n_classes, c1, 3, stride=2, padding=1),
            nn.ReLU(),
            nn.Conv2d(c1, c2, 3, stride=2, padding=1),
            nn.ReLU(),
            nn.Conv2d(c2, c3, 3, stride=2, padding=1),
            nn.ReLU(),
        )
        with torch.no_grad():
            flat = self.conv(torch.zeros(1, config.n_classes, *image_hw)).numel()
        self.head = nn.Sequential(nn.Linear(flat + 2 * len(PATH_AHEAD_M), config.hidden), nn.ReLU(), nn.Linear(config.hidden, m))

    def forward(self, onehot: torch.Tensor, path: torch.Tensor) -> torch.Tensor:
        return self.head(torch.cat([self.conv(onehot).flatten(1), path], dim=1))


def downsample(images: np.ndarray, stride: int) -> np.ndarray:
    """(..., H, W) class ids -> (..., H / stride, W / stride), nearest pixel (centre of each block)."""
    o = stride // 2
    return np.ascontiguousarray(images[..., o::stride, o::stride])


def _grid(shape: tuple[int, int], stride: int) -> tuple[np.ndarray, tuple[int, int]]:
    """The flat pixel indices :func:`downsample` keeps of a (H, W) frame, and the downsampled shape."""
    h, w = shape
    rows, cols = np.arange(h)[stride // 2 :: stride], np.arange(w)[stride // 2 :: stride]
    return (rows[:, None] * w + cols[None, :]).ravel(), (len(rows), len(cols))


def _read_grid(view: SegmentationView, grid: tuple[np.ndarray, tuple[int, int]]) -> np.ndarray:
    """:func:`downsample` of a view's frame, reading only the pixels kept (``grid``: :func:`_grid`'s)."""
    flat, small = grid
    return view.pixels(flat).reshape(small)


def _onehot(small: np.ndarray, n_classes: int) -> torch.Tensor:
    """(B, h, w) uint8 -> (B, n_classes, h, w) float32."""
    ids = torch.from_numpy(small.astype(np.int64))
    out = torch.zeros((ids.shape[0], n_classes, *ids.shape[1:]), dtype=torch.float32)
    valid = ids < n_classes
    out.scatter_(1, torch.where(valid, ids, 0).unsqueeze(1), valid.unsqueeze(1).float())
    return out


PATH_SCALE_M = 8.0  # path coordinates are divided by this before entering the network


def cnn_samples(recordings: list[Recording], features: FeatureConfig, stride: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Downsampled images (N, h, w) uint8, path points (N, 2P) float32 and labels (N,)."""
    images, paths, labels = [], [], []
    control = features.preference.control
    for rec in recordings:
        path = ReferencePath(np.asarray(rec.meta["path"], dtype=float))
        tracker = PathTracker(path)
        # a recording kept in memory renders only the pixels kept (the same values)
        grid = _grid(rec.views[0].shape, stride) if rec.in_memory and len(rec) else None
        for i in range(len(rec)):
            pose = tuple(rec.poses[i])
            s = tracker.update(rec.poses[i, :2])
            images.append(_read_grid(rec.views[i], grid) if grid is not None else downsample(rec.image(i), stride))
            paths.append(path_ahead(path, pose, s).ravel() / PATH_SCALE_M)
        labels.append(np.asarray(control.label_of(rec.commands[:, 1]), dtype=np.int64).reshape(-1))
    return np.stack(images), np.asarray(paths, dtype=np.float32), np.concatenate(labels)


@dataclass
class CnnTrainResult:
    net: CnnNet
    best_epoch: int
    val_acc: float
    n_samples: int


def train_cnn(
    images: np.ndarray,
    paths: np.ndarray,
    labels: np.ndarray,
    m: int,
    config: CnnConfig,
    progress: Callable[[int, float], None] | None = None,
) -> CnnTrainResult:
    """Train on (downsampled images, path points, labels); the lowest-validation-loss epoch wins."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        with torch.random.fork_rng():
            return _train(images, paths, labels, m, config, progress)
    finally:
        torch.set_num_threads(threads)


def _train(images, paths, labels, m, config, progress) -> CnnTrainResult:
    rng = np.random.default_rng(config.seed)
    torch.manual_seed(config.seed)
    tr, va = split_indices(len(labels), config.val_fraction, rng)
    net = CnnNet(config, images.shape[1:], m)
    opt = torch.optim.Adam(net.parameters(), lr=config.lr)
    X, P, y = _onehot(images, config.n_classes), torch.from_numpy(paths), torch.from_numpy(labels)
    weight = torch.as_tensor(class_weights(labels[tr], m), dtype=torch.float32) if config.class_balance else None
    loss_fn, plain = nn.CrossEntropyLoss(weight=weight), nn.CrossEntropyLoss()
    best = (np.inf, 0, 0.0, None)
    for epoch in range(1, config.epochs + 1):
        net.train()
        order = tr[rng.permutation(len(tr))]
        for start in range(0, len(order), config.batch_size):
            b = order[start : start + config.batch_size]
            loss = loss_fn(net(X[b], P[b]), y[b])
            opt.zero_grad()
            loss.backward()
            opt.step()
        net.eval()
        idx = va if len(va) else tr
        with torch.no_grad():
            logits = net(X[idx], P[idx])
            vl, acc = float(plain(logits, y[idx])), float((logits.argmax(1) == y[idx]).float().mean())
        if vl < best[0]:
            best = (vl, epoch, acc, {k: v.clone() for k, v in net.state_dict().items()})
        if progress is not None:
            progress(epoch, vl)
    net.load_state_dict(best[3])
    return CnnTrainResult(net, best[1], best[2], len(labels))


def save_cnn(path: str | Path, result: CnnTrainResult, config: CnnConfig, image_hw: tuple[int, int], meta: dict) -> Path:
    """Write the CNN's weights (safetensors) and configuration; ``meta`` as for C."""
    tensors = {k: v.detach().numpy().astype(np.float32) for k, v in result.net.state_dict().items()}
    header = {
        "format": FORMAT,
        **meta,
        "kind": CNN,
        "cnn": config.to_dict(),
        "image_hw": list(image_hw),
        "best_epoch": result.best_epoch,
        "val_acc": result.val_acc,
        "samples": result.n_samples,
    }
    return write_tensor_file(path, tensors, header)


class CnnPolicy(Policy):
    """The trained CNN as a planner policy (PyTorch inference, one thread)."""

    name = CNN
    uses_path_ahead = True

    def __init__(
        self,
        net: CnnNet,
        features: FeatureConfig,
        camera: CameraConfig,
        classes: ClassTable,
        profile: tuple[str, ...] | None = None,
        path: str = "",
    ) -> None:
        super().__init__(features, camera, classes, profile, path)
        self.net, self.config = net.eval(), net.config
        # The pixels downsample() keeps (flat indices, and the downsampled shape): a frame is read only there.
        self._grid = _grid((self.camera.height_px, self.camera.width_px), self.config.stride)

    @classmethod
    def from_tensors(cls, tensors: dict[str, np.ndarray], meta: dict, source: str) -> CnnPolicy:
        """The CNN of a model file's ``tensors`` and ``meta`` (kind ``cnn``); ``source`` names the file in errors."""
        from terrapref.errors import UserError

        features, camera, classes, profile = model_context(meta, source)
        try:
            config = CnnConfig.from_dict(meta["cnn"])
            net = CnnNet(config, tuple(meta["image_hw"]), features.preference.m)
            net.load_state_dict({k: torch.from_numpy(np.array(v)) for k, v in tensors.items()})
        except (KeyError, TypeError, ValueError, RuntimeError) as exc:
            raise UserError(source, f"not a valid CNN model ({str(exc).splitlines()[0]})", field="cnn") from None
        return cls(net, features, camera, classes, profile, source)

    def logits(self, obs: Observation) -> np.ndarray:
        small = _read_grid(obs.view, self._grid)[None]  # downsample(obs.image, stride), not rendering the rest
        torch.set_num_threads(1)
        with torch.no_grad():
            out = self.net(
                _onehot(small, self.config.n_classes), torch.from_numpy((obs.path_ahead.ravel() / PATH_SCALE_M)[None].astype(np.float32))
            )
        return out[0].numpy().astype(np.float64)


def cnn_from_file(tensors: dict[str, np.ndarray], meta: dict, source: str) -> CnnPolicy:
    """The CNN of a model file (kind ``cnn``; registered in terrapref.planner.registry)."""
    return CnnPolicy.from_tensors(tensors, meta, source)
