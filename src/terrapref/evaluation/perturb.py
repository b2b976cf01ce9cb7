"""What a real robot's planner gets instead of clean frames: the robustness study's perturbations.

- Segmentation noise: independent label flips (a share of pixels gets a random class), and
  blob-shaped mislabels, the way a segmentation network errs (whole regions of the ground
  painted with a wrong class for one frame).
- Pose noise: Gaussian error on the position and heading the planner is told.
- Dropped frames: a frame does not arrive; the planner holds its last command for up to
  ``hold_s`` and then stops the vehicle until frames return (it never drives blind for long).
- Delayed frames: every frame arrives ``delay_frames`` camera periods late, with its pose.
"""

from __future__ import annotations

from collections import deque
from dataclasses import asdict, dataclass, replace

import numpy as np

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


def corrupt_image(image: np.ndarray, p: Perturbation, rng: np.random.Generator) -> np.ndarray:
    """A copy of ``image`` with flips and blobs (the input is left alone)."""
    if not p.corrupts_image:
        return image
    out = image.copy()
    h, w = out.shape
    if p.flip_rate:
        n = rng.binomial(out.size, p.flip_rate)
        idx = rng.choice(out.size, size=n, replace=False)
        out.reshape(-1)[idx] = rng.integers(0, p.n_classes, size=n, dtype=out.dtype)
    for _ in range(rng.poisson(p.blobs) if p.blobs else 0):
        r = int(rng.integers(p.blob_radius_px[0], p.blob_radius_px[1] + 1))
        cy, cx = int(rng.integers(h // 2, h)), int(rng.integers(0, w))  # on the ground part of the view
        ry, rx = max(1, int(r * rng.uniform(0.4, 1.0))), r
        y0, y1, x0, x1 = max(0, cy - ry), min(h, cy + ry + 1), max(0, cx - rx), min(w, cx + rx + 1)
        yy, xx = np.ogrid[y0:y1, x0:x1]
        mask = ((yy - cy) / ry) ** 2 + ((xx - cx) / rx) ** 2 <= 1.0
        out[y0:y1, x0:x1][mask] = rng.integers(0, p.n_classes)
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
        view = SegmentationView.of(corrupt_image(seen.image, p, self.rng)) if p.corrupts_image else seen.view
        self.last = self.inner.act(replace(seen, view=view, pose=pose))
        return self.last

    def _no_frame(self) -> Command:
        self.blind_s += self.dt
        if self.last is not None and self.blind_s <= self.p.hold_s + 1e-9:
            return self.last
        self.stops += 1
        return Command(0.0, 0.0)
