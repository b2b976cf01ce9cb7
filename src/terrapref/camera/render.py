"""Full-frame segmentation rendering from the class raster at any vehicle pose.

The camera has no roll, so every image row sees a straight line on the ground, and the ground
point of pixel (col, row) is affine in col: ``g = P[row] + Q[row] * (col + 0.5 - cx)`` in the
vehicle frame. P and Q are precomputed once per camera; per frame they are rotated into map
cells and expanded with one outer product per axis, so a frame costs about a dozen vectorised
passes over the visible rows and no trigonometry per pixel.

A planner reads only the few hundred pixels its trajectories project to, so
``SegmentationRenderer.pixels`` computes any set of pixels alone, with the same float32
arithmetic as the full frame (so the same class ids), and :class:`SegmentationView` hands a
driver a frame that renders in full only if something asks for the whole image.
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
        self._valid_flat = valid.ravel()
        self._prepared_for: tuple[np.ndarray, tuple] | None = None
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

    def _cells(self, pose: Pose, rows: np.ndarray | slice = slice(None)) -> tuple[np.ndarray, np.ndarray]:
        """For ``rows`` (of the visible block), the padded-raster cell of column offset 0 and the
        change per column, (n, 2) float32 each; elementwise, so a subset of rows gives exactly
        the values of the whole block."""
        x, y, yaw = pose
        res = self.world.resolution_m
        c, s = math.cos(yaw), math.sin(yaw)
        P, Q = self._P[rows], self._Q[rows]
        A = np.empty(P.shape, np.float32)
        B = np.empty(Q.shape, np.float32)
        # Rotate by the yaw into the world frame, then to cells (+1 for the border).
        A[:, 0] = (x + (P[:, 0] * c - P[:, 1] * s)) / res + 1.0
        A[:, 1] = (y + (P[:, 0] * s + P[:, 1] * c)) / res + 1.0
        B[:, 0] = (Q[:, 0] * c - Q[:, 1] * s) / res
        B[:, 1] = (Q[:, 0] * s + Q[:, 1] * c) / res
        return A, B

    def render(self, pose: Pose) -> np.ndarray:
        """Segmentation image at ``pose``: class ids, shape (height, width) uint8."""
        A, B = self._cells(pose)
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

    def pixels(self, pose: Pose, flat_index: np.ndarray) -> np.ndarray:
        """Class ids of the pixels ``flat_index`` (row * width + col) of the image at ``pose``.

        Equal to ``render(pose).reshape(-1)[flat_index]``: the same float32 operations, on
        those pixels only. An index array that owns its data and is read-only (a preference
        set's, asked for every frame) is prepared once and kept.
        """
        rows, u, seen = self._prepared(flat_index)
        A, B = self._cells(pose, rows)
        gx = B[:, 0] * u
        gx += A[:, 0]
        np.clip(gx, 0.0, self._nx_pad - 1e-2, out=gx)
        gy = B[:, 1] * u
        gy += A[:, 1]
        np.clip(gy, 0.0, self._ny_pad - 1e-2, out=gy)
        out = np.full(seen.shape, UNKNOWN, dtype=np.uint8)
        out[seen] = self._flat[gy.astype(np.int32) * self._nx_pad + gx.astype(np.int32)]
        return out

    def _prepared(self, flat_index: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Block row and column offset of each seen pixel, and which pixels are seen."""
        cached = self._prepared_for
        if cached is not None and cached[0] is flat_index:
            return cached[1]
        flat = np.asarray(flat_index, dtype=np.intp)
        rows, cols = np.divmod(flat, self.camera.config.width_px)
        seen = self._valid_flat[flat]
        prepared = (rows[seen] - self._row0, self._u[cols[seen]], seen)
        if isinstance(flat_index, np.ndarray) and flat_index.base is None and not flat_index.flags.writeable:
            self._prepared_for = (flat_index, prepared)
        return prepared


class SegmentationView:
    """One camera frame's segmentation, rendered only as far as it is read.

    ``image`` is the whole frame (rendered on first use, then kept); ``pixels`` reads a few
    pixels, from the kept image if there is one, else by rendering just those.
    """

    __slots__ = ("_image", "_renderer", "_pose")

    def __init__(self, renderer: SegmentationRenderer | None = None, pose: Pose | None = None, image: np.ndarray | None = None) -> None:
        if image is None and (renderer is None or pose is None):
            raise ValueError("a SegmentationView needs an image, or a renderer and a pose")
        self._image, self._renderer, self._pose = image, renderer, pose

    @classmethod
    def of(cls, image: np.ndarray) -> SegmentationView:
        """A view of an image already in hand."""
        return cls(image=image)

    @property
    def image(self) -> np.ndarray:
        """The segmentation image, shape (height, width) uint8."""
        if self._image is None:
            self._image = self._renderer.render(self._pose)
        return self._image

    @property
    def rendered(self) -> bool:
        """Whether the whole image exists yet."""
        return self._image is not None

    def pixels(self, flat_index: np.ndarray) -> np.ndarray:
        """Class ids at ``flat_index`` (row * width + col)."""
        if self._image is not None:
            return self._image.reshape(-1)[flat_index]
        return self._renderer.pixels(self._pose, flat_index)


def as_view(image: np.ndarray | SegmentationView) -> SegmentationView:
    """``image`` as a view (an array is wrapped, a view passed through)."""
    return image if isinstance(image, SegmentationView) else SegmentationView.of(image)
