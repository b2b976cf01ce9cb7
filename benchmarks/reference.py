"""A fixed reference workload, timed in the same run as every benchmark.

Machines differ (the same frame renders in 0.68 ms on one and 1.09 ms on another), so each
benchmark also reports its time as a multiple of this reference, measured in the same process
just before: a ratio holds across machines where a time does not. The reference is a naive
NumPy segmentation renderer: one ray per pixel through the camera's intrinsics and rotation
(float64, no precomputation), intersected with the ground and looked up in a 2000 x 2000 map.
It is deliberately frozen: change it and every ratio in docs/benchmarks.md changes with it.
"""

from __future__ import annotations

import math
import time

import numpy as np

from terrapref.camera import PinholeCamera
from terrapref.terrain import UNKNOWN, default_classes
from terrapref.world import WorldMap

REFERENCE_POSES = 200


def naive_render(camera: PinholeCamera, world: WorldMap, pose: tuple[float, float, float]) -> np.ndarray:
    """Class ids (H, W) at ``pose``, one ray per pixel."""
    c = camera.config
    cols, rows = np.meshgrid(np.arange(c.width_px) + 0.5, np.arange(c.height_px) + 0.5)
    rays_cam = np.stack([(cols - camera.cx) / camera.fx, (rows - camera.cy) / camera.fy, np.ones_like(cols)], axis=-1)
    rays = rays_cam @ camera.R  # camera-frame rays in the vehicle frame (rows of R are the camera axes)
    down = rays[..., 2] < -1e-12
    s = np.where(down, -camera.t[2] / np.where(down, rays[..., 2], -1.0), 0.0)
    ground = camera.t[:2] + s[..., None] * rays[..., :2]
    in_range = down & (s * np.linalg.norm(rays, axis=-1) <= c.max_range_m)
    x, y, yaw = pose
    cs, sn = math.cos(yaw), math.sin(yaw)
    wx = x + ground[..., 0] * cs - ground[..., 1] * sn
    wy = y + ground[..., 0] * sn + ground[..., 1] * cs
    ids = world.class_at(np.stack([wx, wy], axis=-1))
    return np.where(in_range, ids, UNKNOWN).astype(np.uint8)


def reference_ms(n_poses: int = REFERENCE_POSES, seed: int = 12345) -> float:
    """Median time [ms] of one naive frame on a random 100 m map at random poses."""
    rng = np.random.default_rng(seed)
    classes = default_classes()
    ids = np.array([k.id for k in classes.classes], dtype=np.uint8)
    world = WorldMap(rng.choice(ids, size=(2000, 2000)), 0.05, classes)
    camera = PinholeCamera()
    poses = list(zip(rng.uniform(0, 100, n_poses), rng.uniform(0, 100, n_poses), rng.uniform(-math.pi, math.pi, n_poses)))
    for pose in poses[:5]:
        naive_render(camera, world, pose)
    samples = []
    for pose in poses:
        t0 = time.perf_counter()
        naive_render(camera, world, pose)
        samples.append(time.perf_counter() - t0)
    return float(np.median(samples) * 1e3)
