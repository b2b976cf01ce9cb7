"""Label errors on a frame, rendered only as far as the frame is read.

One frame's errors (:class:`FrameLabelErrors`) are drawn once and then apply to any pixel on
demand, the same value whichever pixels are read and in what order: every random choice is a
counter-based hash of the frame's seed and the pixel (or image tile) it concerns. So a planner
that reads a few thousand pixels pays for those alone, and a policy that reads the whole frame
sees the same values there.

Per pixel, in order (terrapref.perception.model.LabelErrors):

1. boundary: the pixel reads the true class of a pixel up to ``boundary_px`` away, drawn at
   random, so pixels near a class border take the neighbour's class at random;
2. range: ground farther than ``max_range_m`` from the camera is unknown (255) (a tilted camera's
   view applies it itself, along its own rays: terrapref.perception.perceiver.TiltedView);
3. confusion: within each image tile of ``region_px`` (and for ``persist_frames`` frames in a
   row), all pixels of a true class are seen as the same class, drawn from its confusion row;
4. blobs: ellipses on the ground part of the image painted one class;
5. flips: independent pixels relabelled to a class drawn uniformly from the class table.
"""

from __future__ import annotations

import functools

import numpy as np
from numba import njit

from terrapref.camera import CameraConfig, PinholeCamera, PixelSet, SegmentationView, flat_of
from terrapref.camera.render import read_only
from terrapref.camera.render_compiled import row_col
from terrapref.perception.model import LabelErrors
from terrapref.terrain import ClassTable
from terrapref.vehicle.ground import Attitude

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


class LabelNoise:
    """The label errors of one model, camera and class table; draws each frame's errors.

    Args:
        errors: the perception model's label errors.
        camera: the robot's camera (image size, and the range of each pixel).
        classes: the class table (flips and blobs draw from its ids; the confusion names its classes).
        range_in_view: the views these errors apply to have cut the ground at ``max_range_m``
            already (a tilted camera's do, along their own rays), so the nominal camera's cut is
            not applied again.
    """

    def __init__(self, errors: LabelErrors, camera: PinholeCamera, classes: ClassTable, range_in_view: bool = False) -> None:
        self.errors = errors
        self.height, self.width = camera.shape
        self.ids = np.array([c.id for c in classes.classes], dtype=np.uint8)
        rows = errors.confusion
        widest = max((len(row) for _, row in rows), default=0)
        self.conf_n = np.zeros(256, dtype=np.int64)
        self.conf_cum = np.zeros((256, max(widest, 1)), dtype=np.float64)
        self.conf_to = np.zeros((256, max(widest, 1)), dtype=np.uint8)
        for true, row in rows:
            t = classes.id_of(true)
            self.conf_n[t] = len(row)
            self.conf_cum[t, : len(row)] = np.cumsum([p for _, p in row])
            self.conf_to[t, : len(row)] = [classes.id_of(seen) for seen, _ in row]
        cut = errors.max_range_m is not None and not range_in_view
        # Read-only either way, as the kept masks are: the compiled loop takes one form of it.
        self.far = far_pixels(camera.config, errors.max_range_m) if cut else read_only(np.zeros(0, dtype=np.bool_))
        # The confusion tile of each pixel: row // region * tiles across + col // region, from two
        # tables (an integer division per pixel cost more than the rest of its errors).
        region = errors.region_px
        self.tile_of_col = np.arange(self.width, dtype=np.int64) // region
        self.tile_of_row = np.arange(self.height, dtype=np.int64) // region * ((self.width + region - 1) // region)
        self._conf_base = 0

    def reset(self, rng: np.random.Generator) -> None:
        """Start a run: draw the seed the run's persisting confusions derive from."""
        self._conf_base = int(rng.integers(2**63))

    def draw(self, rng: np.random.Generator, frame_index: int) -> FrameLabelErrors:
        """The errors of frame ``frame_index`` of the run, drawn from ``rng``."""
        e = self.errors
        boundary_seed = int(rng.integers(2**63)) if e.boundary_px else 0
        flip_seed = int(rng.integers(2**63)) if e.flip_rate else 0
        blobs = []
        for _ in range(rng.poisson(e.blobs_per_frame) if e.blobs_per_frame else 0):
            r = int(rng.integers(e.blob_radius_px[0], e.blob_radius_px[1] + 1))
            cy, cx = int(rng.integers(self.height // 2, self.height)), int(rng.integers(0, self.width))  # on the ground part of the view
            ry, rx = max(1, int(r * rng.uniform(0.4, 1.0))), r
            blobs.append((cy, cx, ry, rx, int(self.ids[rng.integers(len(self.ids))])))
        epoch = frame_index // e.persist_frames
        conf_seed = int(_mix_py(self._conf_base + (epoch + 1) * int(_GOLDEN))) if len(e.confusion) else 0
        return FrameLabelErrors(self, boundary_seed, conf_seed, flip_seed, np.array(blobs, dtype=np.float64).reshape(-1, 5))


def _mix_py(z: int) -> int:
    """splitmix64's finaliser on a Python integer (the compiled form is :func:`_mix`)."""
    mask = (1 << 64) - 1
    z &= mask
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & mask
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & mask
    return z ^ (z >> 31)


class FrameLabelErrors:
    """One frame's label errors, applied to any pixels on demand."""

    __slots__ = ("noise", "boundary_seed", "conf_seed", "flip_seed", "blobs")

    def __init__(self, noise: LabelNoise, boundary_seed: int, conf_seed: int, flip_seed: int, blobs: np.ndarray) -> None:
        self.noise, self.boundary_seed, self.conf_seed, self.flip_seed, self.blobs = noise, boundary_seed, conf_seed, flip_seed, blobs

    def apply(self, base: SegmentationView, flat_index: np.ndarray | PixelSet) -> np.ndarray:
        """The class ids the robot's segmentation gives at pixels ``flat_index`` (row * width + col) of ``base``."""
        n, e = self.noise, self.noise.errors
        flat = read_only(np.ascontiguousarray(flat_of(flat_index), dtype=np.int64).reshape(-1))
        source = _displaced(flat, n.width, n.height, np.uint64(self.boundary_seed), e.boundary_px) if e.boundary_px else flat
        ids = np.ascontiguousarray(base.pixels(source), dtype=np.uint8).reshape(-1)
        out = _errors(
            ids,
            flat,
            n.width,
            n.far,
            np.uint64(self.conf_seed),
            n.tile_of_row,
            n.tile_of_col,
            n.conf_n,
            n.conf_cum,
            n.conf_to,
            self.blobs,
            np.uint64(self.flip_seed),
            e.flip_rate,
            n.ids,
        )
        return out.reshape(np.shape(flat_index))


class LabelledView(SegmentationView):
    """A frame as the robot's segmentation labels it: ``base`` (the truth, or what a jittered
    camera saw of it) with one frame's :class:`FrameLabelErrors`, rendered as far as it is read."""

    __slots__ = ("_base", "_errors")

    def __init__(self, base: SegmentationView, errors: FrameLabelErrors) -> None:
        self._image, self._renderer, self._pose = None, None, None
        self._base, self._errors = base, errors

    @property
    def shape(self) -> tuple[int, int]:
        return self._base.shape

    @property
    def image(self) -> np.ndarray:
        if self._image is None:
            h, w = self.shape
            self._image = self._errors.apply(self._base, np.arange(h * w, dtype=np.int64)).reshape(h, w)
        return self._image

    def pixels(self, flat_index: np.ndarray | PixelSet) -> np.ndarray:
        if self._image is not None:
            return super().pixels(flat_index)
        return self._errors.apply(self._base, flat_index)

    @property
    def depth(self) -> np.ndarray | None:
        """The base's depth image: label errors leave the depth as it was."""
        return self._base.depth

    @property
    def carries_depth(self) -> bool:
        return self._base.carries_depth

    @property
    def attitude(self) -> Attitude:
        return self._base.attitude


@functools.lru_cache(maxsize=8)
def far_pixels(camera: CameraConfig, max_range_m: float) -> np.ndarray:
    """Which pixels (H * W,) see ground farther than ``max_range_m`` from the camera (or none at all)."""
    cam = PinholeCamera(camera)
    h, w = cam.shape
    v, u = np.mgrid[0:h, 0:w]
    ground, ok = cam.back_project(np.stack([u + 0.5, v + 0.5], axis=-1))
    rel = np.concatenate([ground, np.zeros(ground.shape[:-1] + (1,))], axis=-1) - cam.t
    far = ~ok | (np.linalg.norm(rel, axis=-1) > max_range_m)
    far.setflags(write=False)
    return far.reshape(-1)


@njit(cache=True, nogil=True)
def _mix(z: np.uint64) -> np.uint64:
    """splitmix64's finaliser: a well-mixed 64-bit value of ``z``."""
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


@njit(cache=True, nogil=True)
def _uniform(z: np.uint64) -> float:
    """A uniform number in [0, 1) from the top 53 bits of ``z``."""
    return np.float64(z >> np.uint64(11)) * 2.0**-53


@njit(cache=True, nogil=True)
def _below(z: np.uint64, n: int) -> int:
    """An integer uniform in 0 .. n - 1 from the top 32 bits of ``z``."""
    return int(((z >> np.uint64(32)) * np.uint64(n)) >> np.uint64(32))


@njit(cache=True, nogil=True)
def _displaced(flat: np.ndarray, width: int, height: int, seed: np.uint64, radius: int) -> np.ndarray:
    """Each pixel's source: a pixel up to ``radius`` away in each direction, drawn per pixel (itself
    where the draw leaves the image)."""
    out = flat.copy()
    golden = np.uint64(0x9E3779B97F4A7C15)
    span = 2 * radius + 1
    per_row = 1.0 / width
    for i in range(flat.shape[0]):
        k = flat[i]
        z = _mix(seed + np.uint64(k + 1) * golden)
        dx = _below(z, span) - radius
        dy = _below(_mix(z), span) - radius
        row, col = row_col(k, width, per_row)
        x, y = col + dx, row + dy
        if 0 <= x < width and 0 <= y < height:
            out[i] = y * width + x
    return out


@njit(cache=True, nogil=True)
def _errors(
    ids: np.ndarray,
    flat: np.ndarray,
    width: int,
    far: np.ndarray,
    conf_seed: np.uint64,
    tile_of_row: np.ndarray,
    tile_of_col: np.ndarray,
    conf_n: np.ndarray,
    conf_cum: np.ndarray,
    conf_to: np.ndarray,
    blobs: np.ndarray,
    flip_seed: np.uint64,
    flip_rate: float,
    table_ids: np.ndarray,
) -> np.ndarray:
    """Range, confusion, blobs and flips (the module docstring's steps 2-5) on the classes ``ids``
    read for the pixels ``flat``; a pixel's confusion tile is ``tile_of_row[row] + tile_of_col[col]``
    (``row // region * tiles across + col // region``)."""
    out = ids.copy()
    golden = np.uint64(0x9E3779B97F4A7C15)
    per_row = 1.0 / width
    last_key, last_u = -1, 0.0  # the confusion draw of the last (tile, class): neighbouring pixels share it
    for i in range(flat.shape[0]):
        k = flat[i]
        c = out[i]
        if far.shape[0] and far[k]:
            c = np.uint8(255)
        y, x = row_col(k, width, per_row)
        if c != 255 and conf_n[c] > 0:
            key = (tile_of_row[y] + tile_of_col[x]) * 256 + c
            if key != last_key:
                last_key, last_u = key, _uniform(_mix(conf_seed + np.uint64(key + 1) * golden))
            u = last_u
            for j in range(conf_n[c]):
                if u < conf_cum[c, j]:
                    c = conf_to[c, j]
                    break
        for b in range(blobs.shape[0]):
            dy, dx = (y - blobs[b, 0]) / blobs[b, 2], (x - blobs[b, 1]) / blobs[b, 3]
            if dy * dy + dx * dx <= 1.0:
                c = np.uint8(blobs[b, 4])
        if flip_rate > 0.0:
            z = _mix(flip_seed + np.uint64(k + 1) * golden)
            if _uniform(z) < flip_rate:
                c = table_ids[_below(_mix(z), table_ids.shape[0])]
        out[i] = c
    return out
