"""What a real robot's planner gets instead of clean frames: the robustness study's perturbations.

- Segmentation noise: independent label flips (a share of pixels gets a random class), and
  blob-shaped mislabels, the way a segmentation network errs (whole regions of the ground
  painted with a wrong class for one frame); drawn per frame and applied to the pixels a
  policy reads (:class:`NoisyView`), so a planner's run does not corrupt whole frames.
- Pose noise: Gaussian error on the position and heading the planner is told.
- Dropped frames: a frame does not arrive; the planner holds its last command for up to
  ``hold_s`` and then stops the vehicle until frames return (it never drives blind for long).
- Delayed frames: every frame arrives ``delay_frames`` camera periods late, with its pose.
"""

from __future__ import annotations

from collections import deque
from dataclasses import asdict, dataclass, replace

import numpy as np
from numba import njit

from terrapref.camera import SegmentationView
from terrapref.scenario import Scenario
from terrapref.sim.loop import Frame
from terrapref.vehicle import Command, Pose


@dataclass(frozen=True)
class Perturbation:
    """Attributes:
        flip_rate: share of pixels relabelled to a random class, per frame.
        blobs: expected number of mislabelled blobs per frame (Poisson).
        blob_radius_px: (min, max) blob radius [px].
        pose_noise_m: std of the position error [m]; pose_noise_deg: of the heading [deg].
        drop_rate: probability that a frame is lost.
        hold_s: how long the last command is held when frames stop arriving [s].
        delay_frames: latency of every frame, in camera periods.
        n_classes: class ids drawn for mislabels are 0 .. n_classes - 1.
    """

    flip_rate: float = 0.0
    blobs: float = 0.0
    blob_radius_px: tuple[int, int] = (15, 60)
    pose_noise_m: float = 0.0
    pose_noise_deg: float = 0.0
    drop_rate: float = 0.0
    hold_s: float = 0.5
    delay_frames: int = 0
    n_classes: int = 5

    def __post_init__(self) -> None:
        if not (0 <= self.flip_rate <= 1 and 0 <= self.drop_rate <= 1 and self.blobs >= 0 and self.delay_frames >= 0
                and self.pose_noise_m >= 0 and self.pose_noise_deg >= 0 and self.hold_s >= 0):
            raise ValueError("perturbation rates must be in [0, 1] and the rest >= 0")

    @property
    def corrupts_image(self) -> bool:
        return bool(self.flip_rate or self.blobs)

    @property
    def active(self) -> bool:
        return bool(self.flip_rate or self.blobs or self.pose_noise_m or self.pose_noise_deg or self.drop_rate or self.delay_frames)

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True, eq=False)
class FrameNoise:
    """One frame's segmentation noise, drawn once and applied to any pixel on demand.

    Flips are independent per pixel (each relabelled with probability ``flip_rate`` to a class
    drawn uniformly from 0 .. n_classes - 1), drawn from a counter-based hash of the frame's
    ``seed`` and the pixel's index, so a pixel gets the same draw whether the whole frame or only
    the planner's few thousand pixels are read, in any order. Blobs then paint over: ``blobs``
    (B, 5) holds each one's centre row and column, radii (rows, columns) [px] and class, a later
    blob over an earlier one.
    """

    seed: int
    flip_rate: float
    n_classes: int
    blobs: np.ndarray

    @classmethod
    def draw(cls, p: Perturbation, rng: np.random.Generator, shape: tuple[int, int]) -> FrameNoise:
        h, w = shape
        seed = int(rng.integers(2**63)) if p.flip_rate else 0
        blobs = []
        for _ in range(rng.poisson(p.blobs) if p.blobs else 0):
            r = int(rng.integers(p.blob_radius_px[0], p.blob_radius_px[1] + 1))
            cy, cx = int(rng.integers(h // 2, h)), int(rng.integers(0, w))  # on the ground part of the view
            ry, rx = max(1, int(r * rng.uniform(0.4, 1.0))), r
            blobs.append((cy, cx, ry, rx, int(rng.integers(0, p.n_classes))))
        return cls(seed, p.flip_rate, p.n_classes, np.array(blobs, dtype=np.float64).reshape(-1, 5))

    def apply(self, ids: np.ndarray, flat_index: np.ndarray, width: int) -> np.ndarray:
        """The class ids ``ids`` of the pixels ``flat_index`` (row * width + col) with this noise."""
        return _noisy(np.ascontiguousarray(ids, dtype=np.uint8).reshape(-1), np.asarray(flat_index, dtype=np.int64).reshape(-1), width,
                      np.uint64(self.seed), self.flip_rate, self.n_classes, self.blobs).reshape(np.shape(ids))


def corrupt_image(image: np.ndarray, p: Perturbation, rng: np.random.Generator) -> np.ndarray:
    """A copy of ``image`` with flips and blobs (the input is left alone)."""
    if not p.corrupts_image:
        return image
    noise = FrameNoise.draw(p, rng, image.shape)
    return noise.apply(image, np.arange(image.size), image.shape[1]).reshape(image.shape)


class NoisyView(SegmentationView):
    """A frame's segmentation with a :class:`FrameNoise`, rendered as far as it is read: the
    planner's pixels alone, or the whole frame for a policy that reads it (the same values)."""

    __slots__ = ("_base", "_noise")

    def __init__(self, base: SegmentationView, noise: FrameNoise) -> None:
        self._image, self._renderer, self._pose = None, None, None
        self._base, self._noise = base, noise

    @property
    def shape(self) -> tuple[int, int]:
        return self._base.shape

    @property
    def image(self) -> np.ndarray:
        if self._image is None:
            clean = self._base.image
            self._image = self._noise.apply(clean, np.arange(clean.size), clean.shape[1]).reshape(clean.shape)
        return self._image

    def pixels(self, flat_index: np.ndarray) -> np.ndarray:
        if self._image is not None:
            return super().pixels(flat_index)
        return self._noise.apply(self._base.pixels(flat_index), flat_index, self.shape[1])


@njit(cache=True, nogil=True)
def _mix(z: np.uint64) -> np.uint64:
    """splitmix64's finaliser: a well-mixed 64-bit value of ``z``."""
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


@njit(cache=True, nogil=True)
def _noisy(ids: np.ndarray, flat_index: np.ndarray, width: int, seed: np.uint64, flip_rate: float, n_classes: int,
           blobs: np.ndarray) -> np.ndarray:
    """Per pixel: a flip with probability ``flip_rate`` (to a uniform class), then the blobs in order."""
    out = ids.copy()
    golden = np.uint64(0x9E3779B97F4A7C15)
    for i in range(flat_index.shape[0]):
        k = flat_index[i]
        if flip_rate > 0.0:
            z = _mix(seed + np.uint64(k + 1) * golden)
            if np.float64(z >> np.uint64(11)) * 2.0**-53 < flip_rate:
                out[i] = np.uint8((_mix(z) >> np.uint64(32)) * np.uint64(n_classes) >> np.uint64(32))
        if blobs.shape[0]:
            y, x = k // width, k % width
            for b in range(blobs.shape[0]):
                dy, dx = (y - blobs[b, 0]) / blobs[b, 2], (x - blobs[b, 1]) / blobs[b, 3]
                if dy * dy + dx * dx <= 1.0:
                    out[i] = np.uint8(blobs[b, 4])
    return out


class PerturbedDriver:
    """Wraps a planner's driver and hands it perturbed frames (a :class:`terrapref.sim.Driver`)."""

    def __init__(self, inner, perturbation: Perturbation, camera_rate_hz: float = 10.0) -> None:
        self.inner, self.p, self.dt = inner, perturbation, 1.0 / camera_rate_hz
        self.stops = 0  # frames on which the vehicle was stopped for want of frames

    def reset(self, scenario: Scenario, rng: np.random.Generator) -> None:
        self.inner.reset(scenario, rng)
        self.rng = np.random.default_rng(rng.integers(2**63))
        self.queue: deque[Frame] = deque()
        self.last: Command | None = None
        self.blind_s = 0.0
        self.stops = 0

    def act(self, frame: Frame) -> Command:
        p = self.p
        self.queue.append(frame)
        while len(self.queue) > p.delay_frames + 1:  # frames older than the latency are gone
            self.queue.popleft()
        if len(self.queue) <= p.delay_frames or self.rng.random() < p.drop_rate:
            return self._no_frame()
        seen = self.queue.popleft()  # the frame taken delay_frames periods ago
        pose = seen.pose
        if p.pose_noise_m or p.pose_noise_deg:
            dx, dy = self.rng.normal(0.0, p.pose_noise_m, 2) if p.pose_noise_m else (0.0, 0.0)
            dyaw = np.radians(self.rng.normal(0.0, p.pose_noise_deg)) if p.pose_noise_deg else 0.0
            pose = Pose(pose[0] + dx, pose[1] + dy, pose[2] + dyaw)
        self.blind_s = 0.0
        view = NoisyView(seen.view, FrameNoise.draw(p, self.rng, seen.view.shape)) if p.corrupts_image else seen.view
        self.last = self.inner.act(replace(seen, view=view, pose=pose))
        return self.last

    def _no_frame(self) -> Command:
        self.blind_s += self.dt
        if self.last is not None and self.blind_s <= self.p.hold_s + 1e-9:
            return self.last
        self.stops += 1
        return Command(0.0, 0.0)
