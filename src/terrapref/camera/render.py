"""Full-frame segmentation rendering from the class raster at any vehicle pose.

The camera has no roll, so every image row sees a straight line on the ground, and the ground
point of pixel (col, row) is affine in col: ``g = P[row] + Q[row] * (col + 0.5 - cx)`` in the
vehicle frame. P and Q are precomputed once per camera; per frame they are rotated into map
cells and expanded with one outer product per axis, so a frame costs about a dozen vectorised
passes over the visible rows and no trigonometry per pixel.
"""

from __future__ import annotations

import math

import numpy as np

from terrapref.camera.pinhole import PinholeCamera
from terrapref.terrain import UNKNOWN
from terrapref.vehicle import Pose
from terrapref.world import WorldMap


class SegmentationRenderer:
    """Renders the segmentation image (class ids, 255 where no ground is seen) of a world map."""

    def __init__(self, camera: PinholeCamera, world: WorldMap) -> None:
        self.camera = camera
        self.world = world
        c = camera.config
        width, height = c.width_px, c.height_px
        right = camera.R[0]
        if abs(right[2]) > 1e-12:  # pragma: no cover - CameraConfig has no roll
            raise ValueError("the row-affine renderer needs a camera without roll")

        rows = np.arange(height) + 0.5
        b = np.outer((rows - camera.cy) / camera.fy, camera.R[1]) + camera.R[2]  # (H, 3)
        a = right / camera.fx  # ray change per pixel column, (3,)
        sees_ground = b[:, 2] < -1e-12
        s = np.where(sees_ground, -camera.t[2] / np.where(sees_ground, b[:, 2], -1.0), 0.0)  # (H,)
        u = np.arange(width) + 0.5 - camera.cx  # (W,)
        ray_len = s[:, None] * np.linalg.norm(b[:, None, :] + u[None, :, None] * a, axis=-1)
        valid = sees_ground[:, None] & (ray_len <= c.max_range_m)  # (H, W)

        any_valid = np.flatnonzero(valid.any(axis=1))
        self._row0 = int(any_valid[0]) if len(any_valid) else height
        block_valid = valid[self._row0 :]
        self._invalid_in_block = np.flatnonzero(~block_valid.ravel())
        self._P = (camera.t[:2] + s[:, None] * b[:, :2])[self._row0 :]  # (rows, 2) [m]
        self._Q = (s[:, None] * a[:2])[self._row0 :]  # (rows, 2) [m per px]
        self._u = u.astype(np.float32)

        # A one-cell border of 255 round the raster: clipped indices off the map read "unknown".
        ny, nx = world.raster.shape
        padded = np.full((ny + 2, nx + 2), UNKNOWN, dtype=np.uint8)
        padded[1:-1, 1:-1] = world.raster
        self._flat = padded.ravel()
        self._nx_pad, self._ny_pad = nx + 2, ny + 2
        n = height - self._row0
        self._gx = np.empty((n, width), np.float32)
        self._gy = np.empty((n, width), np.float32)
        self._ix = np.empty((n, width), np.int32)
        self._iy = np.empty((n, width), np.int32)

    @property
    def shape(self) -> tuple[int, int]:
        return self.camera.shape

    def render(self, pose: Pose) -> np.ndarray:
        """Segmentation image at ``pose``: class ids, shape (height, width) uint8."""
        x, y, yaw = pose
        res = self.world.resolution_m
        cy_, sy_ = math.cos(yaw), math.sin(yaw)
        rot_t = np.array([[cy_, sy_], [-sy_, cy_]])  # transpose of the yaw rotation
        # Cell coordinates in the padded raster (+1 for the border).
        A = ((np.array([x, y]) + self._P @ rot_t) / res + 1.0).astype(np.float32)
        B = (self._Q @ rot_t / res).astype(np.float32)
        out = np.empty(self.camera.shape, dtype=np.uint8)
        out[: self._row0] = UNKNOWN
        block = out[self._row0 :]
        if block.size:
            gx, gy, ix, iy = self._gx, self._gy, self._ix, self._iy
            np.multiply.outer(B[:, 0], self._u, out=gx)
            gx += A[:, 0:1]
            np.clip(gx, 0.0, self._nx_pad - 1e-2, out=gx)
            np.multiply.outer(B[:, 1], self._u, out=gy)
            gy += A[:, 1:2]
            np.clip(gy, 0.0, self._ny_pad - 1e-2, out=gy)
            np.copyto(ix, gx, casting="unsafe")  # truncation == floor: all values are >= 0
            np.copyto(iy, gy, casting="unsafe")
            iy *= self._nx_pad
            iy += ix
            np.take(self._flat, iy, out=block)
            block.reshape(-1)[self._invalid_in_block] = UNKNOWN
        return out
