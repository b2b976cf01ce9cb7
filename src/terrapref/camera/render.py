"""Full-frame segmentation rendering from the class raster at any vehicle pose.

The camera has no roll, so every image row sees a straight line on the ground, and the ground
point of pixel (col, row) is affine in col: ``g = P[row] + Q[row] * (col + 0.5 - cx)`` in the
vehicle frame. P and Q are precomputed once per camera; per frame they are rotated into map
cells, and each pixel's cell is one float32 multiply-add away, with no trigonometry per pixel.
The per-pixel loops are compiled (:mod:`terrapref.camera.render_compiled`); a frame is one pass.

A planner reads only the few hundred pixels its trajectories project to, so
``SegmentationRenderer.pixels`` computes any set of pixels alone, with the same float32
arithmetic as the full frame (so the same class ids), and :class:`SegmentationView` hands a
driver a frame that renders in full only if something asks for the whole image.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np

from terrapref.camera.pinhole import CameraConfig, PinholeCamera
from terrapref.camera.relief_compiled import render_relief, step_lengths
from terrapref.camera.render_compiled import pixels_at, pixels_of_rows, ray_pixels, render_frame, rows_and_columns, take
from terrapref.terrain import UNKNOWN
from terrapref.vehicle import Pose
from terrapref.vehicle.ground import LEVEL, Attitude
from terrapref.world import WorldMap

RELIEF_TOLERANCE_M = 0.005
"""How far the ground, taken as straight between two samples of the relief renderer's march,
may stray from the height field [m] (:func:`~terrapref.camera.relief_compiled.step_lengths`)."""
RELIEF_LONGEST_STEP_M = 0.8
"""The longest step of that march where the ground is smooth [m], rounded down to a power of two
of cells (the blocks its step lengths are kept for; far out a step is a pixel row's ground)."""


class _GroundRows(NamedTuple):
    """What a camera's pixels see of level ground, the same for every world (:func:`_ground_rows`)."""

    row0: int  # the first row that sees ground in range
    valid_flat: np.ndarray  # (H W,) bool: pixels that see ground in range
    first: np.ndarray  # (rows,) int64: each row's first column in range, from row0 on
    last: np.ndarray  # (rows,) int64: one past its last
    P: np.ndarray  # (rows, 2): each row's ground point at the principal column [m]
    Q: np.ndarray  # (rows, 2): and its change per column [m per px]
    u: np.ndarray  # (W,) float32: the columns' offsets from the principal point [px]
    ray_a: np.ndarray  # (W,): each column's ray offset through the pixel centres
    ray_b: np.ndarray  # (H,): each row's


@functools.lru_cache(maxsize=8)
def _ground_rows(config: CameraConfig) -> _GroundRows:
    """The rows and columns of level ground a camera of ``config`` sees, worked out once a process
    for each camera (every simulation of a run has the same); the arrays are read-only."""
    camera = PinholeCamera(config)
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
    row0 = int(any_valid[0]) if len(any_valid) else height
    # Along a row the ray length is convex in the column, so the columns in range are one run.
    block = valid[row0:]
    first = np.where(block.any(axis=1), block.argmax(axis=1), 0).astype(np.int64)
    last = first + block.sum(axis=1)
    if not all(block[r, first[r] : last[r]].all() for r in range(len(block))):  # pragma: no cover
        raise ValueError("the renderer needs the visible columns of each row to be one run")
    rows = _GroundRows(
        row0,
        valid.ravel(),
        first,
        last,
        (camera.t[:2] + s[:, None] * b[:, :2])[row0:],
        (s[:, None] * a[:2])[row0:],
        u.astype(np.float32),
        # Each column's and row's ray offsets through the pixel centres, for a camera off its mount (kernels.ray_pixels).
        (np.arange(width) + 0.5 - camera.cx) / camera.fx,
        (np.arange(height) + 0.5 - camera.cy) / camera.fy,
    )
    for array in rows[1:]:
        array.flags.writeable = False
    return rows


class SegmentationRenderer:
    """Renders the segmentation image (class ids, 255 where no ground is seen) of a world map."""

    def __init__(self, camera: PinholeCamera, world: WorldMap) -> None:
        self.camera = camera
        self.world = world
        rows = _ground_rows(camera.config)
        self._row0, self._valid_flat, self._first, self._last = rows.row0, rows.valid_flat, rows.first, rows.last
        self._P, self._Q, self._u, self._ray_a, self._ray_b = rows.P, rows.Q, rows.u, rows.ray_a, rows.ray_b

        # A one-cell border of 255 round the raster: clipped indices off the map read "unknown".
        ny, nx = world.raster.shape
        if (ny + 2) * (nx + 2) >= 2**31:  # the frame's cells are 32-bit indices (a scenario holds at most 10^8)
            raise ValueError(f"a {nx} x {ny} raster is too large for the renderer (at most 2^31 cells)")
        padded = np.full((ny + 2, nx + 2), UNKNOWN, dtype=np.uint8)
        padded[1:-1, 1:-1] = world.raster
        self._flat = padded.ravel()
        self._nx_pad = nx + 2
        # Cell coordinates are clipped to just inside the padded raster (in float32, as NumPy's
        # clip of a float32 array by a Python float).
        self._x_max, self._y_max = np.float32(nx + 2 - 1e-2), np.float32(ny + 2 - 1e-2)
        self._ground: tuple[np.ndarray, np.ndarray, int, tuple[float, float]] | None = (
            None  # the relief march's ground, made when first asked
        )

    @property
    def shape(self) -> tuple[int, int]:
        return self.camera.shape

    @property
    def relief(self) -> bool:
        """Whether the world's ground has relief (frames are then rendered by following each ray
        to the height field, with the body's attitude)."""
        return self.world.has_relief

    def placement(self, pose: Pose, attitude: Attitude = LEVEL) -> tuple[np.ndarray, np.ndarray]:
        """The camera's axes and optical centre in the world (:meth:`PinholeCamera.placement`)."""
        return self.camera.placement(_finite(pose), attitude)

    def render_with_depth(self, pose: Pose, attitude: Attitude = LEVEL, max_range_m: float | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Class ids (H, W) uint8 and depth (H, W) float32 [m along the optical axis, NaN where no
        ground is seen, REP 118] of the frame at ``pose`` with ``attitude``, every ray followed to
        the height field (:mod:`terrapref.camera.relief_compiled`; the plane z = 0 on flat ground),
        up to ``max_range_m`` from the optical centre or the camera's range if that is nearer."""
        axes, centre = self.placement(pose, attitude)
        c = self.camera.config
        reach = c.max_range_m if max_range_m is None else min(c.max_range_m, max_range_m)
        ids = np.empty(self.camera.shape, dtype=np.uint8)
        depth = np.empty(self.camera.shape, dtype=np.float32)
        if self._ground is None:
            self._ground = _march_ground(self.world)
        heights, steps, shift, span = self._ground
        render_relief(
            axes,
            centre,
            self._ray_a,
            self._ray_b,
            reach,
            self.camera.fy,
            self.camera.cy,
            heights,
            self.world.resolution_m,
            steps,
            shift,
            span,
            self._flat,
            self._nx_pad,
            float(self._x_max),
            float(self._y_max),
            UNKNOWN,
            ids,
            depth,
        )
        return ids, depth

    def render(self, pose: Pose, attitude: Attitude = LEVEL) -> np.ndarray:
        """Segmentation image at ``pose``: class ids, shape (height, width) uint8 (on relief, with
        the body's ``attitude``)."""
        if self.relief:
            return self.render_with_depth(pose, attitude)[0]
        x, y, yaw = _finite(pose)
        out = np.empty(self.camera.shape, dtype=np.uint8)
        render_frame(
            self._P,
            self._Q,
            self._u,
            self._first,
            self._last,
            float(x),
            float(y),
            math.cos(yaw),
            math.sin(yaw),
            self.world.resolution_m,
            self._flat,
            self._nx_pad,
            self._x_max,
            self._y_max,
            UNKNOWN,
            out,
        )
        return out

    def pixels(self, pose: Pose, flat_index: np.ndarray | PixelSet) -> np.ndarray:
        """Class ids of the pixels ``flat_index`` (row * width + col) of the image at ``pose``.

        Equal to ``render(pose).reshape(-1)[flat_index]``: the same float32 operations, on
        those pixels only. A :class:`PixelSet` keeps each pixel's visible row and column from
        its first frame, so later frames skip working them out.
        """
        x, y, yaw = _finite(pose)
        if isinstance(flat_index, PixelSet):
            rows, cols = flat_index.rows_and_columns(self)
            return pixels_of_rows(
                rows,
                cols,
                self._P,
                self._Q,
                self._u,
                float(x),
                float(y),
                math.cos(yaw),
                math.sin(yaw),
                self.world.resolution_m,
                self._flat,
                self._nx_pad,
                self._x_max,
                self._y_max,
                UNKNOWN,
            )
        flat = np.asarray(flat_index, dtype=np.int64).reshape(-1)
        ids = pixels_at(
            flat,
            self.camera.config.width_px,
            self._row0,
            self._valid_flat,
            self._P,
            self._Q,
            self._u,
            float(x),
            float(y),
            math.cos(yaw),
            math.sin(yaw),
            self.world.resolution_m,
            self._flat,
            self._nx_pad,
            self._x_max,
            self._y_max,
            UNKNOWN,
        )
        return ids.reshape(np.shape(flat_index))

    def pixels_tilted(
        self, pose: Pose, flat_index: np.ndarray | PixelSet, dpitch_rad: float, droll_rad: float, max_range_m: float | None = None
    ) -> np.ndarray:
        """Class ids of the pixels ``flat_index`` that the camera sees when its attitude is off the
        mount by ``dpitch_rad`` and ``droll_rad`` (:meth:`PinholeCamera.tilted`); each pixel's ray is
        followed to the ground (kernels.ray_pixels), up to ``max_range_m`` or the camera's range
        if that is nearer."""
        x, y, yaw = _finite(pose)
        cam, c = self.camera, self.camera.config
        flat = read_only(np.asarray(flat_of(flat_index), dtype=np.int64).reshape(-1))
        if flat.size and (flat.min() < 0 or flat.max() >= c.width_px * c.height_px):
            raise IndexError("a pixel index is outside the image")
        reach = c.max_range_m if max_range_m is None else min(c.max_range_m, max_range_m)
        ids = ray_pixels(
            flat,
            c.width_px,
            self._ray_a,
            self._ray_b,
            cam.tilted(dpitch_rad, droll_rad),
            cam.t,
            reach,
            float(x),
            float(y),
            math.cos(yaw),
            math.sin(yaw),
            self.world.resolution_m,
            self._flat,
            self._nx_pad,
            self._x_max,
            self._y_max,
            UNKNOWN,
        )
        return ids.reshape(np.shape(flat_index))


class PixelSet:
    """A fixed set of pixels (row * width + col) that a reader takes from every frame, such as
    the ground map's samples or the sky line's band: what a renderer works out of each pixel
    alone (its row among the rows that see the ground, -1 for none, and its column) is kept from
    the first frame, for the renderer's camera. Every view reads it as it reads ``flat``."""

    __slots__ = ("flat", "_camera", "_rows", "_cols")

    def __init__(self, flat_index: np.ndarray) -> None:
        self.flat = np.array(flat_index, dtype=np.int64).reshape(-1)  # its own copy, read-only
        self.flat.flags.writeable = False
        self._camera = None  # the camera the rows and columns below were worked out for
        self._rows = self._cols = np.empty(0, dtype=np.int64)

    @property
    def shape(self) -> tuple[int]:
        """(number of pixels,): the shape of what a view's ``pixels`` returns for it."""
        return self.flat.shape

    def rows_and_columns(self, renderer: SegmentationRenderer) -> tuple[np.ndarray, np.ndarray]:
        """Each pixel's row among ``renderer``'s rows that see the ground (-1 where the pixel sees
        none in range) and its column; worked out again only for another camera."""
        config = renderer.camera.config
        if self._camera is not config and self._camera != config:
            self._rows, self._cols = rows_and_columns(self.flat, config.width_px, renderer._row0, renderer._valid_flat)
            self._camera = config
        return self._rows, self._cols


def read_only(a: np.ndarray) -> np.ndarray:
    """A read-only view of ``a``: a compiled loop then sees one type of array, whichever the
    caller passed (a kept pixel set's or a fresh one), and is compiled once."""
    view = a.view()
    view.setflags(write=False)
    return view


def flat_of(flat_index: np.ndarray | PixelSet) -> np.ndarray:
    """The pixel indices of ``flat_index``: an array as given, a :class:`PixelSet`'s ``flat``."""
    return flat_index.flat if isinstance(flat_index, PixelSet) else flat_index


def _march_ground(world: WorldMap) -> tuple[np.ndarray, np.ndarray, int, tuple[float, float]]:
    """The relief march's ground for ``world``: its height field (the plane z = 0 on flat ground;
    a one-cell side repeated, so that every cell has four corners), the longest step from each
    block of cells, the blocks' size as a power of two of cells (:func:`step_lengths`), and the
    field's lowest and highest heights [m]."""
    heights = world.height if world.height is not None else np.zeros((2, 2), dtype=np.float32)
    if min(heights.shape) < 2:
        heights = np.pad(heights, ((0, heights.shape[0] < 2), (0, heights.shape[1] < 2)), mode="edge")
    res = world.resolution_m
    shift = max(0, min(8, math.floor(math.log2(RELIEF_LONGEST_STEP_M / res)))) if res < RELIEF_LONGEST_STEP_M else 0
    span = (float(heights.min()), float(heights.max()))
    return heights, step_lengths(heights, res, shift, RELIEF_TOLERANCE_M, 2.0 * res), shift, span


def _finite(pose: Pose) -> Pose:
    """``pose``, refused if any part is not finite (a cell index is computed from it)."""
    if not all(math.isfinite(v) for v in pose):
        raise ValueError(f"a pose must be finite, got {tuple(pose)}")
    return pose


class SegmentationView:
    """One camera frame's segmentation, rendered only as far as it is read.

    ``image`` is the whole frame (rendered on first use, then kept); ``pixels`` reads a few
    pixels, from the kept image if there is one, else by rendering just those (on relief the
    whole frame is rendered: a ray's pixel depends on the ground before it). ``depth`` is the
    frame's depth image, rendered on first use, and ``attitude`` the body's when the frame was
    taken: with the pose, what places the depth image's returns in the world.
    """

    __slots__ = ("_image", "_renderer", "_pose", "_attitude", "_depth")

    def __init__(
        self,
        renderer: SegmentationRenderer | None = None,
        pose: Pose | None = None,
        image: np.ndarray | None = None,
        attitude: Attitude = LEVEL,
        depth: np.ndarray | None = None,
    ) -> None:
        if image is None and (renderer is None or pose is None):
            raise ValueError("a SegmentationView needs an image, or a renderer and a pose")
        self._image, self._renderer, self._pose, self._attitude, self._depth = image, renderer, pose, attitude, depth

    @classmethod
    def of(cls, image: np.ndarray, depth: np.ndarray | None = None, attitude: Attitude = LEVEL) -> SegmentationView:
        """A view of an image (and its depth image, if any, taken with the body at ``attitude``) already in hand."""
        return cls(image=image, depth=depth, attitude=attitude)

    @property
    def image(self) -> np.ndarray:
        """The segmentation image, shape (height, width) uint8."""
        if self._image is None:
            if self._renderer.relief:
                self._image, self._depth = self._with_depth()
            else:
                self._image = self._renderer.render(self._pose)
        return self._image

    @property
    def depth(self) -> np.ndarray | None:
        """The depth image, shape (height, width) float32 [m along the optical axis, NaN where
        nothing is seen, REP 118]; None for a view of an image that came without one."""
        if self._depth is None and self._renderer is not None:
            if self._renderer.relief and self._image is None:
                self._image, self._depth = self._with_depth()
            else:
                self._depth = self._with_depth()[1]
        return self._depth

    def _with_depth(self) -> tuple[np.ndarray, np.ndarray]:
        """The whole frame and its depth image, every ray followed to the ground."""
        return self._renderer.render_with_depth(self._pose, self._attitude)

    @property
    def attitude(self) -> Attitude:
        """The body's height, pitch and roll when the frame was taken (the camera rides the body;
        a camera's own wander off its mount is not in it): what, with the pose, places the
        depth image's returns in the world. Level on flat ground, and for an image in hand
        whose attitude was not given."""
        return self._attitude

    @property
    def carries_depth(self) -> bool:
        """Whether the frame comes with a depth image: given with it, or rendered over relief (a
        view of flat ground can render one too, but a planner need not ask: the height layer of
        a plane blocks nothing)."""
        return self._depth is not None or (self._renderer is not None and self._renderer.relief)

    @property
    def rendered(self) -> bool:
        """Whether the whole image exists yet."""
        return self._image is not None

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width) of the frame, without rendering it."""
        return self._image.shape if self._image is not None else self._renderer.shape

    def pixels(self, flat_index: np.ndarray | PixelSet) -> np.ndarray:
        """Class ids at ``flat_index`` (row * width + col; or a :class:`PixelSet`)."""
        if self._image is not None:
            image = self._image
            flat_index = flat_of(flat_index)
            if image.dtype == np.uint8 and image.ndim == 2 and image.flags.c_contiguous and flat_index.dtype.kind == "i":
                return take(image, flat_index).reshape(np.shape(flat_index))  # NumPy's fancy indexing, without its overhead
            return image.reshape(-1)[flat_index]
        if self._renderer.relief:
            self.image  # noqa: B018 - rendered whole on relief, then read as any kept image
            return self.pixels(flat_index)
        return self._renderer.pixels(self._pose, flat_index)


def as_view(image: np.ndarray | SegmentationView) -> SegmentationView:
    """``image`` as a view (an array is wrapped, a view passed through)."""
    return image if isinstance(image, SegmentationView) else SegmentationView.of(image)
