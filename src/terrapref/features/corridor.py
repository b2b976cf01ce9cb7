"""The offset corridor: what driving beside the path at a lateral offset would cross.

A person facing a patch on the trail does not pick a 6 m arc; they pick a side and how far out
to hold it until the patch is behind them. The corridor features describe exactly that choice.
For each candidate offset d (left positive) from the reference path, the footprint is laid
along the path shifted by d, over stations from just behind the vehicle to ``stations_m[1]``
ahead, and the ground under it is read from a :class:`GroundMap`: the camera's views, gathered
over the last frames, so that a patch the vehicle is already beside still counts.

Features per offset (:meth:`CorridorFeatures.base`, shape (O, K + 2)):

- metres driven on each of the K terrain classes (footprint points averaged);
- metres over ground never seen;
- d^2 * (on-path length + ``span_m``): the price of a detour that lasts as long as the patch on
  the path, plus the swerves in and out;

and one gated column (:func:`gated`): d^2 while nothing lies on the path within the near
distance, so that a utility can learn to keep to the path until a patch is close. Only the
first patch on the path (gaps under ``gap_m`` do not split it) and ``span_m / 2`` beyond it
are weighed; later patches wait for their own turn.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from terrapref.camera import PinholeCamera, PixelSet, SegmentationView
from terrapref.features import kernels
from terrapref.features.attitude import HorizonAttitude
from terrapref.records import to_plain
from terrapref.scenario.path import ReferencePath
from terrapref.terrain import UNKNOWN, ClassTable
from terrapref.vehicle import Pose, pure_pursuit_yaw_rate


MAX_COUNT = 10_000
"""The most offsets, stations or camera samples a corridor may have."""
MAX_MAP_CELLS = 4096
"""The most ground-map cells a side (640 by default: 64 m at 0.1 m)."""


@dataclass(frozen=True)
class CorridorConfig:
    """Geometry of the offset corridor and of the ground map behind it.

    Attributes:
        max_offset_m: candidate offsets run from -max to +max [m].
        offset_step_m: spacing of the candidate offsets [m].
        stations_m: first and last station read along the path, from the vehicle's progress [m].
        station_step_m: spacing of the stations [m].
        half_width_m: half the footprint's width; 5 points across it [m].
        span_m: metres added to the on-path length in the detour's price (swerving in and out) [m].
        gap_m: gaps along the path shorter than this do not split a patch [m].
        map_resolution_m: cell size of the ground map [m].
        map_half_size_m: the ground map covers this much around its centre, each way [m].
        sample_step_m: spacing of the ground points read from each image [m].
        sample_range_m: ground read up to this far ahead of the camera [m].
        intent_delay_s: a demonstrator's command is read as what it meant this long before (its
            reaction time) [s] ...
        intent_lookahead_m: ... and inverted through pure pursuit this far ahead along the path
            into the offset it was steering for [m] (terrapref.learning.corridor).
        map_range_m: a ground sample's vote in the map weighs 1 / (1 + (r / map_range_m)^2) at r
            metres from the vehicle: near ground is seen sharper and placed better [m].
        map_fade: each frame a cell is not voted on, its evidence fades by this factor, so that
            recent views count more than old ones (0: the last view alone).
        map_lethal_share: a cell is lethal when lethal classes hold at least this share of its
            evidence ...
        map_terrain_share: ... else terrain (its class with the most evidence) when the K
            terrain classes hold at least this share, else background: a segmentation network
            misses a patch into the ground around it far more often than it sees a patch in plain
            ground, and a patch blurred over frames must not vanish into the ground around it
            (0.4 rather than a majority: a patch's edge cells stay the patch under the `field`
            preset's misses, so a detour keeps its width; docs/perception.md).
        map_min_evidence: a cell counts as seen once its evidence totals this much (a vote at
            0 m weighs 1).
        map_sky_attitude: place the ground samples with the camera's pitch and roll off its mount
            as the sky line of each frame shows them (terrapref.features.attitude), not with the
            mount's.
    """

    max_offset_m: float = 3.0
    offset_step_m: float = 0.2
    stations_m: tuple[float, float] = (-1.0, 11.0)
    station_step_m: float = 0.25
    half_width_m: float = 0.6
    span_m: float = 5.0
    gap_m: float = 1.0
    map_resolution_m: float = 0.1
    map_half_size_m: float = 32.0
    sample_step_m: float = 0.1
    sample_range_m: float = 14.0
    intent_delay_s: float = 0.2
    intent_lookahead_m: float = 2.5
    map_range_m: float = 4.0
    map_fade: float = 0.97
    map_lethal_share: float = 0.35
    map_terrain_share: float = 0.4
    map_min_evidence: float = 0.0
    map_sky_attitude: bool = True

    def __post_init__(self) -> None:
        positive = (self.max_offset_m, self.offset_step_m, self.station_step_m, self.half_width_m, self.map_resolution_m,
                    self.map_half_size_m, self.sample_step_m, self.sample_range_m, self.intent_lookahead_m)
        if not all(math.isfinite(v) and v > 0 for v in positive) or not (self.span_m >= 0 and self.gap_m >= 0 and self.intent_delay_s >= 0):
            raise ValueError("the corridor needs positive sizes and steps, and span_m, gap_m and intent_delay_s >= 0")
        if not self.map_half_size_m > self.sample_range_m + 1.0 or not self.stations_m[1] < self.sample_range_m:
            raise ValueError("the ground map must reach past the camera's sample range by more than 1 m, and that past the corridor")
        if not self.stations_m[0] < self.stations_m[1]:
            raise ValueError("the corridor's stations_m must run forward")
        counts = {"offsets": (self.max_offset_m / self.offset_step_m, MAX_COUNT),
                  "stations": ((self.stations_m[1] - self.stations_m[0]) / self.station_step_m, MAX_COUNT),
                  "camera samples": (self.sample_range_m / self.sample_step_m, MAX_COUNT),
                  "ground-map cells a side": (2 * self.map_half_size_m / self.map_resolution_m, MAX_MAP_CELLS)}
        for what, (count, most) in counts.items():  # a size read from a file is bounded before anything is allocated by it
            if count > most:
                raise ValueError(f"the corridor's steps give {count:.3g} {what}; at most {most}")
        if not (math.isfinite(self.map_range_m) and self.map_range_m > 0 and 0 <= self.map_fade <= 1 and 0 < self.map_lethal_share <= 1
                and 0 < self.map_terrain_share <= 1 and 0 <= self.map_min_evidence < 1e3):
            raise ValueError("the ground map needs map_range_m > 0, map_fade in [0, 1], map_lethal_share and map_terrain_share in (0, 1] "
                             "and map_min_evidence >= 0")

    @property
    def offsets(self) -> np.ndarray:
        """Candidate lateral offsets (O,) [m], left positive, symmetric about 0."""
        n = round(self.max_offset_m / self.offset_step_m)
        return np.arange(-n, n + 1) * self.offset_step_m

    @property
    def stations(self) -> np.ndarray:
        """Stations (S,) [m] along the path from the vehicle's progress."""
        n = round((self.stations_m[1] - self.stations_m[0]) / self.station_step_m)
        return self.stations_m[0] + np.arange(n + 1) * self.station_step_m

    @property
    def footprint(self) -> np.ndarray:
        """Lateral positions (5,) [m] of the footprint's points about its centre line."""
        return np.linspace(-self.half_width_m, self.half_width_m, 5)

    def to_dict(self) -> dict:
        return to_plain(self)

    @classmethod
    def from_dict(cls, data: dict) -> CorridorConfig:
        data = dict(data)
        if "stations_m" in data:
            data["stations_m"] = tuple(data["stations_m"])
        return cls(**data)


@dataclass(frozen=True, eq=False)
class TerrainColumns:
    """How a class table's classes fall into the terrain columns that the ground map holds.

    Attributes:
        of_class: terrain column of each class id (256,), as :attr:`UtilityFeaturizer.class_columns`.
        k: the number of terrain classes K (column K: ground that is none of them).
        lethal: the terrain columns of lethal classes.
        names: the classes of the K columns, for a costmap's legend.
    """

    of_class: np.ndarray
    k: int
    lethal: tuple[int, ...] = ()
    names: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if np.shape(self.of_class) != (256,) or self.k < 0 or not all(0 <= c <= self.k + 1 for c in self.lethal):
            raise ValueError("terrain columns need a column for each of the 256 class ids, K >= 0 and lethal columns up to K + 1")

    @classmethod
    def of(cls, of_class: np.ndarray, k: int, classes: ClassTable, names: tuple[str, ...] = ()) -> TerrainColumns:
        """The columns ``of_class`` gives the class ids, with the columns of ``classes``' lethal classes."""
        return cls(of_class, k, tuple(sorted({int(of_class[i]) for i in classes.lethal_ids})), names)


class GroundMap:
    """What the camera has shown of the ground around the vehicle, gathered over frames.

    A square of ``2 * map_half_size_m`` in the world frame, re-centred on the vehicle before
    the ground the camera sees (``sample_range_m`` ahead) could leave it; cells that leave it
    are forgotten. Every frame, each ground sample the camera sees votes for its terrain column
    in its cell, weighted by how near it is (``map_range_m``), and a cell's older votes fade
    (``map_fade``); the cell holds the column with the most evidence, or a lethal one where
    lethal classes hold ``map_lethal_share`` of it. So a label that a few frames get wrong (a
    segmentation network's flips, a blob, a region mislabelled for a moment, a pose or a camera
    attitude a little off) is outvoted by the frames that got it right, and lethal terrain is
    neither entered nor seen where it is not because of a few frames.

    Cells hold a terrain column (0..K-1), K for ground that is none of the K classes, K + 1 for
    ground never seen.

    Args:
        camera: the camera whose images update the map.
        terrain: the class table's terrain columns.
        config: the corridor's configuration (map resolution, size and voting, image sampling).
        sample_half_width_m: ground is read this far each side of the vehicle [m].
    """

    def __init__(self, camera: PinholeCamera, terrain: TerrainColumns, config: CorridorConfig | None = None,
                 sample_half_width_m: float = 8.0) -> None:
        self.config = c = config or CorridorConfig()
        self.k = k = terrain.k
        self.columns = np.asarray(terrain.of_class, dtype=np.uint8).copy()
        self.columns[UNKNOWN] = k + 1  # a pixel that sees no ground casts no vote
        if k + 1 >= kernels.UNSETTLED:
            raise ValueError(f"a ground map holds at most {kernels.UNSETTLED - 2} terrain columns, got {k}")
        self.lethal = np.zeros(k + 2, dtype=np.bool_)
        self.lethal[np.asarray(terrain.lethal, dtype=np.int64)] = True
        # How a cell's evidence decides its column (kernels.map_decide): lethal share, terrain share, least evidence.
        self._shares = np.array([c.map_lethal_share, c.map_terrain_share, c.map_min_evidence], dtype=np.float32)
        # The ground points read from each image: a vehicle-frame grid, those the camera sees.
        xs = np.arange(0.2, c.sample_range_m, c.sample_step_m)
        ys = np.arange(-sample_half_width_m, sample_half_width_m, c.sample_step_m)
        grid = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 2)
        pix = camera.pixel_indices(grid)
        seen = pix >= 0
        self._pix = pix[seen]
        # Far samples share pixels: each distinct pixel is read once, and each sample reads its own.
        distinct, self._sample_pix = np.unique(self._pix, return_inverse=True)
        self._pixels = PixelSet(distinct)  # read every frame: their rows and columns worked out once
        self._vx, self._vy = grid[seen, 0].copy(), grid[seen, 1].copy()
        self.camera = camera
        self.attitude = HorizonAttitude(camera) if c.map_sky_attitude else None
        # The ray through each sample's pixel centre (camera frame, z = 1), and where the mount's
        # camera sees it meet the ground: a tilted camera moves each sample by where its ray lands.
        cols, rows = self._pix % camera.config.width_px, self._pix // camera.config.width_px
        self._ray = np.stack([(cols + 0.5 - camera.cx) / camera.fx, (rows + 0.5 - camera.cy) / camera.fy], axis=1)
        self._ground0 = _ground(self._ray, camera.R, camera.t)
        self._weight = (1.0 / (1.0 + (self._vx**2 + self._vy**2) / c.map_range_m**2)).astype(np.float32)
        fade = np.ones(64, dtype=np.float32)
        for g in range(1, len(fade)):  # by repeated products: the same bits on every CPU
            fade[g] = fade[g - 1] * np.float32(c.map_fade)
        self._fade = fade
        self._n = int(round(2 * c.map_half_size_m / c.map_resolution_m))
        # Each cell's column (row: y, col: x), kernels.UNSETTLED where voted on since last decided.
        self._cells = np.full((self._n, self._n), k + 1, dtype=np.uint8)
        self.evidence = np.zeros((self._n, self._n, k + 1), dtype=np.float32)
        self.stamp = np.zeros((self._n, self._n), dtype=np.int64)
        self.frame = 0
        self.origin: np.ndarray | None = None  # world position of cell (0, 0)'s corner [m]
        self._origin_xy: tuple[float, float] | None = None  # the same, in plain floats

    def reset(self) -> None:
        """Forget everything seen."""
        self._cells.fill(self.k + 1)
        self.evidence.fill(0.0)
        self.stamp.fill(0)
        self.frame = 0
        self.origin = self._origin_xy = None
        if self.attitude is not None:
            self.attitude.reset()

    def _recentre(self, x: float, y: float) -> None:
        c = self.config
        # Re-centred while all the camera writes and the corridor reads stays inside (checked in
        # plain floats: the same arithmetic as NumPy's on the two coordinates; a NaN re-centres).
        if self._origin_xy is not None:
            reach = c.map_half_size_m - c.sample_range_m - 1.0
            if abs(self._origin_xy[0] - (x - c.map_half_size_m)) < reach and abs(self._origin_xy[1] - (y - c.map_half_size_m)) < reach:
                return
        centre = np.array([x, y]) - c.map_half_size_m
        new = np.floor(centre / c.map_resolution_m).astype(np.int64)
        if self.origin is not None:  # keep what the old square and the new one share
            old = np.round(self.origin / c.map_resolution_m).astype(np.int64)
            dx, dy = int(new[0] - old[0]), int(new[1] - old[1])
            self._cells = _shifted(self._cells, dx, dy, self.k + 1)
            self.evidence = _shifted(self.evidence, dx, dy, 0.0)
            self.stamp = _shifted(self.stamp, dx, dy, 0)
        self.origin = new * c.map_resolution_m
        self._origin_xy = (float(self.origin[0]), float(self.origin[1]))

    def update(self, view: SegmentationView, pose: Pose) -> None:
        """Add what ``view``, taken at ``pose``, shows of the ground."""
        x, y, yaw = pose
        c = self.config
        self._recentre(float(x), float(y))
        self.frame += 1
        ids = view.pixels(self._pixels)
        dpitch, droll = self.attitude(view) if self.attitude is not None else (0.0, 0.0)
        tilted = bool(dpitch or droll)
        axes = self.camera.tilted(dpitch, droll) if tilted else self.camera.R
        kernels.map_vote(self.evidence, self.stamp, self._cells,  # the map
                         *self._origin_xy, 1.0 / c.map_resolution_m,  # its corner and cells per metre
                         float(x), float(y), math.cos(yaw), math.sin(yaw),  # the pose
                         self._vx, self._vy, self._weight, ids, self._sample_pix, self.columns,  # the samples and what they saw
                         self.frame, self._fade,  # the votes' fading
                         tilted, self._ray, self._ground0, axes, self.camera.t)  # the camera off its mount

    @property
    def cells(self) -> np.ndarray:
        """Terrain column of every cell (rows y, columns x), each decided from its evidence: a
        read-only view, valid until the next :meth:`update` (which leaves the cells it votes on
        to be decided again)."""
        kernels.map_settle(self._cells, self.evidence, self.lethal, self._shares)
        view = self._cells.view()
        view.flags.writeable = False
        return view

    def layers(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float, float, float]:
        """What a compiled read of the map takes (kernels.map_decide): the cells' columns, some
        still undecided, their evidence, the lethal columns and the shares that decide a column;
        then where the map lies, its corner's x and y [m] and its cells per metre. Read once the map
        has been placed (its first update: ``origin`` is not None)."""
        ox, oy = self._origin_xy
        return self._cells, self.evidence, self.lethal, self._shares, ox, oy, 1.0 / self.config.map_resolution_m

    def beside(self, path: ReferencePath, s: np.ndarray, lat: np.ndarray) -> np.ndarray:
        """Terrain column (O, S, F) at the points ``lat`` (O, F) [m] left of the path at arc lengths ``s`` (S,)."""
        if self.origin is None:
            return np.full((lat.shape[0], len(s), lat.shape[1]), self.k + 1, dtype=np.uint8)
        a, d, length = path.segments
        return kernels.map_read_beside(*self.layers(), path.s, a, d, length, np.asarray(s, dtype=np.float64),
                                       np.ascontiguousarray(lat, dtype=np.float64), self.k + 1)

    def lookup(self, points: np.ndarray) -> np.ndarray:
        """Terrain column at each world point (..., 2); K + 1 (never seen) outside the map."""
        if self.origin is None:
            return np.full(points.shape[:-1], self.k + 1, dtype=np.uint8)
        px = np.ascontiguousarray(points[..., 0], dtype=np.float64).reshape(-1)
        py = np.ascontiguousarray(points[..., 1], dtype=np.float64).reshape(-1)
        out = kernels.map_read(*self.layers(), px, py, self.k + 1)
        return out.reshape(points.shape[:-1])


@dataclass(frozen=True)
class CorridorView:
    """The corridor at one frame.

    Attributes:
        features: per offset, metres on each terrain class, metres never seen and the detour's
            price, shape (O, K + 2).
        near_m: distance along the path to the first terrain on it [m] (inf: none in reach).
    """

    features: np.ndarray
    near_m: float


class CorridorFeatures:
    """Corridor features (module docstring) read from a ground map along a path."""

    def __init__(self, config: CorridorConfig, k: int) -> None:
        self.config, self.k = config, k
        self.offsets = config.offsets
        self.stations = config.stations
        self._lat = self.offsets[:, None] + config.footprint[None, :]  # (O, F)
        self._centre = int(np.argmin(np.abs(self.offsets)))
        self._gap = round(config.gap_m / config.station_step_m)
        self._beyond = round(config.span_m / 2 / config.station_step_m)

    def columns(self, gmap: GroundMap, path: ReferencePath, progress_m: float) -> np.ndarray:
        """Terrain column under every footprint point, shape (O, S, F)."""
        return gmap.beside(path, np.minimum(progress_m + self.stations, path.length_m), self._lat)

    def __call__(self, gmap: GroundMap, path: ReferencePath, progress_m: float) -> CorridorView:
        c = self.config
        features, near_m = kernels.corridor_features(self.columns(gmap, path, progress_m), self._centre, self.k, self._gap, self._beyond,
                                                     c.station_step_m, self.stations, self.offsets, c.span_m)
        return CorridorView(features, float(near_m))


def _ground(ray: np.ndarray, axes: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Where rays (N, 2) of a camera at ``t`` with ``axes`` (rows right, down, forward in the vehicle
    frame) meet the ground, (N, 2) in the vehicle frame [m]; NaN for rays that do not.

    Elementwise products and sums in a fixed order (no matrix product): the same bits on every CPU."""
    d = [ray[:, 0] * axes[0, i] + ray[:, 1] * axes[1, i] + axes[2, i] for i in range(3)]
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(d[2] < -1e-12, -t[2] / d[2], np.nan)
    return np.stack([t[0] + scale * d[0], t[1] + scale * d[1]], axis=1)


def _shifted(a: np.ndarray, dx: int, dy: int, fill: float) -> np.ndarray:
    """``a`` (rows y, columns x, ...) moved so that what was at cell (i + dx, j + dy) is at (i, j); ``fill`` where nothing was."""
    out = np.full_like(a, fill)
    n = a.shape[0]
    if abs(dx) < n and abs(dy) < n:
        out[max(0, -dy):n - max(0, dy), max(0, -dx):n - max(0, dx)] = a[max(0, dy):n - max(0, -dy), max(0, dx):n - max(0, -dx)]
    return out


def gated(view: CorridorView, offsets: np.ndarray, near_m: float) -> np.ndarray:
    """The corridor's features with the gate column: d^2 while nothing is on the path within ``near_m``, (O, K + 3)."""
    gate = offsets**2 * float(view.near_m > near_m)
    return np.concatenate([view.features, gate[:, None]], axis=1)


def steer(path: ReferencePath, pose: Pose, progress_m: float, offset_m: np.ndarray | float, lookahead_m: float, v_mps: float) -> np.ndarray:
    """:func:`pursuit_yaw_rates` clipped to the stick's +-1 rad/s."""
    return np.asarray(np.clip(pursuit_yaw_rates(path, pose, progress_m, offset_m, lookahead_m, v_mps), -1.0, 1.0))


def pursuit_yaw_rates(path: ReferencePath, pose: Pose, progress_m: float, offset_m: np.ndarray | float, lookahead_m: float,
                      v_mps: float) -> np.ndarray:
    """Pure-pursuit yaw rate [rad/s] toward the path shifted by ``offset_m`` (left positive), ``lookahead_m`` ahead
    of ``progress_m``. One value per offset, ``offset_m``'s shape.

    Scalar ``math`` throughout (NumPy's vectorised trigonometry may pick CPU-specific code whose
    last bits differ, and ``math.hypot`` rounds more exactly than C's), so that the command, and
    the run it steers, is the same on every machine.
    """
    tx0, ty0, cos_h, sin_h = path.frame_at(min(progress_m + lookahead_m, path.length_m))
    x, y, yaw = (float(v) for v in pose)
    offsets = np.asarray(offset_m, dtype=float)
    out = np.empty(offsets.shape)
    for k, d in enumerate(offsets.flat):
        tx, ty = tx0 - d * sin_h - x, ty0 + d * cos_h - y
        alpha = (math.atan2(ty, tx) - yaw + math.pi) % (2 * math.pi) - math.pi
        out.flat[k] = pure_pursuit_yaw_rate(v_mps, math.sin(alpha), max(math.hypot(tx, ty), 1e-6))
    return out


def intent_offsets(poses: np.ndarray, later: np.ndarray, progress_m: np.ndarray, path: ReferencePath, offsets: np.ndarray,
                   lookahead_m: float) -> np.ndarray:
    """The offset [m] each frame's driver was steering for, (F,); NaN where ``later`` is NaN.

    The offset whose pure-pursuit yaw rate is nearest the command. A stick at rest (w = 0) is
    read the same way, as steering for the offset straight ahead: a driver converging on the
    offset it holds, with the heading already right, leaves the stick at rest, and reading that
    as "where the vehicle is" put 43% of such frames more than 0.3 m from the offset the
    synthetic driver held (docs/learning.md).

    Args:
        poses: (F, 3) the vehicle's poses.
        later: (F, 2) the command (v [m/s], w [rad/s]) recorded one reaction time after each frame.
        progress_m: (F,) the vehicle's progress along the path [m].
        path: the reference path.
        offsets: the candidate offsets (O,) [m].
        lookahead_m: the driver's pure-pursuit look-ahead [m].
    """
    out = np.full(len(poses), np.nan)
    for i, (v, w) in enumerate(later):
        if not (math.isfinite(v) and math.isfinite(w)):
            continue
        yaw_rate = pursuit_yaw_rates(path, tuple(poses[i]), progress_m[i], offsets, lookahead_m, v)
        out[i] = offsets[int(np.argmin(np.abs(yaw_rate - w)))]
    return out
