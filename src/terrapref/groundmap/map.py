"""The ground map: what the camera has shown of the ground around the vehicle, gathered over
frames (:class:`GroundMap`), in the terrain columns of a class table (:class:`TerrainColumns`)."""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np

from terrapref.camera import PinholeCamera, PixelSet, SegmentationView
from terrapref.groundmap import height_compiled as height_kernels
from terrapref.groundmap import map_compiled as kernels
from terrapref.groundmap.attitude import HorizonAttitude
from terrapref.groundmap.columns import TerrainColumns
from terrapref.groundmap.height import (
    CHECK_TOLERANCE_M,
    DepthImage,
    DepthRays,
    GeometryLimits,
    Heights,
    HeightSettings,
    disc_reach,
)
from terrapref.groundmap.layers import LAYERS, Layer
from terrapref.groundmap.settings import MapSettings
from terrapref.scenario.path import ReferencePath
from terrapref.vehicle import Pose


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
    ground never seen. The map's arrays are the layers of :attr:`LAYERS` over one grid
    (terrapref.groundmap.layers), moved and emptied together; :meth:`layer` gives one by name.

    Args:
        camera: the camera whose images update the map.
        terrain: the class table's terrain columns.
        settings: its resolution, size and voting, and the ground read from each image.
    """

    LAYERS: ClassVar[tuple[Layer, ...]] = LAYERS

    def __init__(self, camera: PinholeCamera, terrain: TerrainColumns, settings: MapSettings | None = None) -> None:
        self.settings = c = settings or MapSettings()
        self.k = k = terrain.k
        self.columns = terrain.map_columns  # a pixel that sees no ground casts no vote
        if k + 1 >= kernels.UNSETTLED:
            raise ValueError(f"a ground map holds at most {kernels.UNSETTLED - 2} terrain columns, got {k}")
        self.lethal = np.zeros(k + 2, dtype=np.bool_)
        self.lethal[np.asarray(terrain.lethal, dtype=np.int64)] = True
        # How a cell's evidence decides its column (kernels.map_decide): lethal share, terrain share, least evidence.
        self._shares = np.array([c.map_lethal_share, c.map_terrain_share, c.map_min_evidence], dtype=np.float32)
        # The ground points read from each image: a vehicle-frame grid, those the camera sees.
        xs = np.arange(0.2, c.sample_range_m, c.sample_step_m)
        ys = np.arange(-c.sample_half_width_m, c.sample_half_width_m, c.sample_step_m)
        grid = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 2)
        pix = camera.pixel_indices(grid)
        seen = pix >= 0
        self._pix = pix[seen]
        # Far samples share pixels: each distinct pixel is read once, and each sample reads its own.
        distinct, self._sample_pix = np.unique(self._pix, return_inverse=True)
        self._pixels = PixelSet(distinct)  # read every frame: their rows and columns worked out once
        self._vx, self._vy = grid[seen, 0].copy(), grid[seen, 1].copy()
        self.camera = camera
        self._depth_rays: DepthRays | None = None  # made on the first depth image
        self._mark: np.ndarray | None = None  # scratch for the height layer's kernels (made with the rays, as the others below)
        self._slot: np.ndarray | None = None
        # Ground past these limits reads as lethal (update with a depth image); None: not blocked.
        self.limits: GeometryLimits | None = None
        self.height_settings = HeightSettings()
        lethal_columns = np.flatnonzero(self.lethal[:k])
        self.geometry_column = int(lethal_columns[0]) if len(lethal_columns) else None  # what blocked ground reads as
        self._blocking = False  # whether any cell is blocked
        self._lethal_by_geometry = np.empty(0, dtype=np.int64)  # the cells that read as lethal for it (flat indices)
        self._moved = False  # the blocked cells changed since those were found
        self._read_depth = False  # whether a depth image updated the map since it was made or reset
        self._depth_held = False  # whether its depth layers may hold anything: read from depth, or handed out (Layer.from_depth)
        self._from_depth = frozenset(layer.name for layer in self.LAYERS if layer.from_depth)
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
        self._layers = {layer.name: layer.empty(self._n, k) for layer in self.LAYERS}
        self.frame = 0
        self.origin: np.ndarray | None = None  # world position of cell (0, 0)'s corner [m]
        self._origin_xy: tuple[float, float] | None = None  # the same, in plain floats

    def _update_at_depth(self, ids: np.ndarray, depth: DepthImage, at_xy: tuple[float, float]) -> None:
        """:meth:`update` with a depth image, the vehicle at ``at_xy``: the votes at the returns,
        the heights, the ground's shape read (within the height settings' block range) and the
        blocks."""
        c = self.settings
        if self._depth_rays is None:
            self._depth_rays = DepthRays(self.camera, self._pixels.flat)
            self._mark = np.zeros(self._n * self._n, dtype=np.uint8)
            # Scratch for the frame's returns summed per cell (height_compiled.depth_frame).
            self._slot = np.full(self._n * self._n, -1, dtype=np.int32)
            self._sums = np.empty((len(self._pixels.flat), height_kernels.FRAME_SUMS))
            # Each distinct pixel's vote: where and for what, and the weight of its samples together.
            self._vote_cell = np.empty(len(self._pixels.flat), dtype=np.int64)
            self._vote_column = np.empty(len(self._pixels.flat), dtype=np.int64)
            self._pixel_weight = np.bincount(self._sample_pix, weights=self._weight, minlength=len(self._pixels.flat)).astype(np.float32)
        self._read_depth = self._depth_held = True
        h, res = self.height_settings, c.map_resolution_m
        touched = height_kernels.depth_frame(
            depth.image,
            self._depth_rays.pixels,
            np.asarray(depth.axes, dtype=np.float64),
            np.asarray(depth.centre, dtype=np.float64),
            (*self._origin_xy, 1.0 / res),
            h.max_range_m,
            h.errors,
            (ids, self.columns, self.k, self._vote_cell, self._vote_column),
            tuple(self.heights),
            self._shape,
            (self._slot, self._sums),
            (self._layers["rough"], self._layers["rough_weight"], disc_reach(h, res), h.rough_range_m),
        )
        kernels.map_vote_cells(
            self.evidence, self.stamp, self._cells, self._vote_cell, self._vote_column, self._pixel_weight, self.frame, self._fade
        )
        near = (*self._origin_xy, res, *at_xy, h.block_range_m)
        changed = height_kernels.shape_to_check(
            touched, self._shape, h.least_weight, self._checked, self._disc, CHECK_TOLERANCE_M, near, disc_reach(h, res), self._mark
        )
        if self.limits is not None and self.geometry_column is not None:
            self._block(changed)

    def _block(self, cells: np.ndarray) -> None:
        """Cells (flat indices ``cells``) whose geometry is past :attr:`limits` are blocked until
        their geometry no longer is (the ``blocked`` layer); the cells within the limits' reach
        of a blocked one read as the first lethal column (:meth:`_reblock`)."""
        blocked, limits = self._layers["blocked"], (self.limits.max_slope_rad, self.limits.max_step_m)
        if height_kernels.block_cells(self._shape, self._reading, self._disc, cells, limits, blocked):
            self._moved = True
        self._blocking = bool(blocked.any()) if self._moved else self._blocking
        self._reblock()

    def _reblock(self) -> None:
        """The cells within the limits' reach of a blocked cell (one of a cluster: a lone one is
        noise, terrapref.groundmap.height_compiled.near_blocked) set to read as lethal, again after
        each frame's votes (which leave the cells they fall in to be decided from their evidence);
        those no longer within reach of one decided from their evidence again."""
        if not self._blocking and not len(self._lethal_by_geometry):
            self._moved = False  # none blocked, none read as lethal for it: as finding them again would leave it
            return
        cells = self._cells.reshape(-1)
        if self._moved:  # the blocked cells changed (or the map moved): the cells near them found again
            reach = round(self.limits.reach_m / self.settings.map_resolution_m) if self.limits is not None else 0
            near = height_kernels.near_blocked(self._layers["blocked"], reach, self._mark)
            cells[np.setdiff1d(self._lethal_by_geometry, near, assume_unique=True)] = kernels.UNSETTLED
            self._lethal_by_geometry, self._moved = near, False
        cells[self._lethal_by_geometry] = self.geometry_column

    @property
    def reads_depth(self) -> bool:
        """Whether depth images have updated the map (on relief): its votes fall where the returns
        lie, and its heights and the ground's shape are read."""
        return self._read_depth

    @property
    def heights(self) -> Heights:
        """The height layers (terrapref.groundmap.height), valid until the map is next re-centred."""
        self._depth_held = True  # handed out: the caller may write them
        return Heights(self._layers["elevation"], self._layers["returns"], self._layers["spread"], self._layers["weight"])

    def geometry_at(self, points: np.ndarray) -> np.ndarray:
        """Slope [rad], roughness [m] and step [m] (..., 3) of the cells under the world points
        (..., 2), from the height layer (terrapref.groundmap.height); NaN where unknown or off the map."""
        if self.origin is None:
            return np.full((*np.shape(points)[:-1], 3), np.nan)
        out = self.geometry_of(*self._cells_under(points))
        return out.reshape(*np.shape(points)[:-1], 3)

    def roughness_at(self, points: np.ndarray) -> np.ndarray:
        """The roughness [m] (...) of the cells under the world points (..., 2), as :meth:`geometry_at`
        reads it (as the frames read it, each alone); NaN where unknown or off the map."""
        if self.origin is None:
            return np.full(np.shape(points)[:-1], np.nan)
        return self._roughness_of(*self._cells_under(points)).reshape(np.shape(points)[:-1])

    def gradient_at(self, points: np.ndarray) -> np.ndarray:
        """The ground's gradient (rise per metre along x, along y) (..., 2) under the world points
        (..., 2), from its shape as the slope is read (:meth:`geometry_of`); NaN where unknown or off the map."""
        if self.origin is None:
            return np.full(np.shape(points), np.nan)
        rows, cols = self._cells_under(points)
        out = np.empty((len(rows), 2))
        height_kernels.shape_gradient(self._disc, rows, cols, out)
        return out.reshape(np.shape(points))

    def body_grades(self, centre: np.ndarray, heading: np.ndarray, chord: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
        """The grade [deg, positive up] (S,) a body centred at ``centre`` (S, 2) heading ``heading``
        (S,) [rad] would be pitched at: the ground's gradient (:meth:`gradient_at`) along the heading,
        averaged over the ``chord`` (offsets along the heading [m], their weights); NaN where the
        gradient is known under less than half the chord's weight (in one compiled pass,
        terrapref.groundmap.height_compiled.chord_grades)."""
        out = np.full(len(centre), np.nan)
        if self.origin is None:
            return out
        grid = (*self._origin_xy, self.settings.map_resolution_m)
        centre = np.ascontiguousarray(centre, dtype=np.float64)
        heading = np.ascontiguousarray(np.broadcast_to(heading, (len(centre),)), dtype=np.float64)
        height_kernels.chord_grades(self._disc, grid, centre, heading, chord, out)
        return out

    def beside_attitudes(self, centre: np.ndarray, normal: np.ndarray, offsets: np.ndarray, chord: tuple[int, int] = (0, 0)) -> np.ndarray:
        """The side slope and the grade [deg, both >= 0] (O - 2c, S - 2a, 2) of the ground under a
        body heading along a path, on the lattice of the points ``offsets`` (O,) [m, evenly spaced]
        left of the path's points ``centre`` (S, 2, evenly spaced; ``normal`` (S, 2) pointing left):
        the ground's gradient (:meth:`gradient_at`) across the way averaged over ``2c + 1`` points
        across, along it over ``2a + 1`` points along (``chord`` = (a, c); (0, 0): the gradient at
        each point alone), body (o, q) at lattice point (o + c, q + a); NaN where unknown or off
        the map (in one compiled pass, terrapref.groundmap.height_compiled.beside_attitudes)."""
        along, across = chord
        out = np.full((len(offsets) - 2 * across, len(centre) - 2 * along, 2), np.nan)
        if self.origin is None:
            return out
        height_kernels.beside_attitudes(
            self._disc,
            (*self._origin_xy, self.settings.map_resolution_m),
            np.ascontiguousarray(centre, dtype=np.float64),
            np.ascontiguousarray(normal, dtype=np.float64),
            np.ascontiguousarray(offsets, dtype=np.float64),
            (int(along), int(across)),
            out,
        )
        return out

    def _cells_under(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The rows and columns (N,) of the cells under the world points (..., 2); -1 for a point not a number."""
        flat = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        res = self.settings.map_resolution_m
        with np.errstate(invalid="ignore"):
            cols = np.floor((flat[:, 0] - self._origin_xy[0]) / res)
            rows = np.floor((flat[:, 1] - self._origin_xy[1]) / res)
        inside = np.isfinite(cols) & np.isfinite(rows)
        return np.where(inside, rows, -1).astype(np.int64), np.where(inside, cols, -1).astype(np.int64)

    def geometry_of(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Slope [rad], roughness [m] and step [m] (N, 3) of the cells (``rows``, ``cols``): the
        slope and the step from the ground's shape (the height differences the frames show,
        :func:`terrapref.groundmap.height_compiled.shape_geometry`), what the limits are checked
        against; the roughness as the frames read it (terrapref.groundmap.height_compiled.depth_frame).
        NaN where unknown."""
        out = self._shape_geometry(rows, cols)
        out[:, 1] = self._roughness_of(rows, cols)
        return out

    def _roughness_of(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """The roughness [m] (N,) of the cells (``rows``, ``cols``) as the frames read it; NaN where unknown."""
        out = np.empty(len(rows))
        rows, cols = np.asarray(rows, dtype=np.int64), np.asarray(cols, dtype=np.int64)
        height_kernels.read_roughness((self._layers["rough"], self._layers["rough_weight"]), rows, cols, out)
        return out

    def _shape_geometry(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Slope [rad], NaN and step [m] (N, 3) of the cells (``rows``, ``cols``) from the ground's shape."""
        out = np.empty((len(rows), 3))
        rows, cols = np.asarray(rows, dtype=np.int64), np.asarray(cols, dtype=np.int64)
        height_kernels.shape_geometry(self._shape, self._reading, self._disc, rows, cols, out)
        return out

    @property
    def _checked(self) -> tuple[np.ndarray, ...]:
        """The differences and their runs as they were last read (terrapref.groundmap.height_compiled.shape_to_check)."""
        return tuple(self._layers[name] for name in ("checked_dx", "checked_dx_run", "checked_dy", "checked_dy_run"))

    @property
    def _reading(self) -> tuple[float, float]:
        """The weight from which a difference counts, and the cell [m] (height_compiled.shape_geometry)."""
        return self.height_settings.least_weight, self.settings.map_resolution_m

    @property
    def _disc(self) -> np.ndarray:
        """The sums over each cell's disc of the differences as they were last read (height_compiled.disc_sums)."""
        return self._layers["disc"]

    @property
    def _shape(self) -> np.ndarray:
        """The ground's shape as the kernels take it (terrapref.groundmap.height_compiled.depth_frame)."""
        return self._layers["shape"]

    def read_shape(self) -> None:
        """Read the ground's shape afresh over the whole map as its ``shape`` layer now holds it
        (each frame's depth image reads it where the frame changed it): for code that writes that
        layer itself. The slope and the gradients are read from what was read."""
        self._depth_held = True
        least, shape = self.height_settings.least_weight, self._shape
        for axis, first in (("x", height_kernels.SHAPE_X), ("y", height_kernels.SHAPE_Y)):
            rise, run, weight = (shape[..., first + k] for k in (height_kernels.RISE, height_kernels.RUN, height_kernels.WEIGHT))
            known = weight.astype(np.float64) >= least  # as the kernels compare them
            self._layers[f"checked_d{axis}"][...] = np.where(known, rise, np.float32(np.nan))
            self._layers[f"checked_d{axis}_run"][...] = run
        reach = disc_reach(self.height_settings, self.settings.map_resolution_m)
        height_kernels.disc_sums(self._checked, reach, np.arange(self._n * self._n), self._disc)

    def layer(self, name: str) -> np.ndarray:
        """The layer ``name`` of :attr:`LAYERS`, (n, n) or (n, n, K + 1) (rows y, columns x): the
        map's own array, for the code that writes it; valid until the map is next re-centred."""
        self._depth_held |= name in self._from_depth
        return self._layers[name]

    @property
    def _cells(self) -> np.ndarray:
        return self._layers["column"]

    @property
    def evidence(self) -> np.ndarray:
        """Each cell's votes per column (n, n, K + 1) float32 (the ``evidence`` layer)."""
        return self._layers["evidence"]

    @property
    def stamp(self) -> np.ndarray:
        """The frame of each cell's last vote (n, n) int64 (the ``stamp`` layer)."""
        return self._layers["stamp"]

    def reset(self) -> None:
        """Forget everything seen."""
        for layer in self.LAYERS:
            self._layers[layer.name].fill(layer.fill_value(self.k))
        self._blocking, self._moved, self._read_depth, self._depth_held = False, False, False, False
        self._lethal_by_geometry = np.empty(0, dtype=np.int64)
        self.frame = 0
        self.origin = self._origin_xy = None
        if self.attitude is not None:
            self.attitude.reset()

    def _recentre(self, x: float, y: float) -> None:
        c = self.settings
        # Re-centred while all the camera writes and the offset features read stays inside (checked in
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
            for layer in self.LAYERS:
                if self._depth_held or not layer.from_depth:  # empty depth layers read the same moved (most of a flat map's)
                    self._layers[layer.name] = _shifted(self._layers[layer.name], dx, dy, layer.fill_value(self.k))
            self._lethal_by_geometry, self._moved = np.empty(0, dtype=np.int64), True  # moved with the cells; found again
            if self._depth_held:  # the discs that reached past the old square, or now reach into it from outside, summed afresh
                reach = disc_reach(self.height_settings, c.map_resolution_m)
                height_kernels.disc_sums(self._checked, reach, _across_the_edge(self._n, dx, dy, reach), self._disc)
        self.origin = new * c.map_resolution_m
        self._origin_xy = (float(self.origin[0]), float(self.origin[1]))

    def update(self, view: SegmentationView, pose: Pose, depth: DepthImage | None = None) -> None:
        """Add what ``view``, taken at ``pose``, shows of the ground.

        With the frame's ``depth`` image (on relief, where a plane would put the ground a pixel
        sees in the wrong place), each sample votes where its pixel's depth return lies, the
        returns go into the height layer, and the ground they show past :attr:`limits` is
        blocked (terrapref.groundmap.height)."""
        x, y, yaw = pose
        c = self.settings
        self._recentre(float(x), float(y))
        self.frame += 1
        ids = view.pixels(self._pixels)
        if depth is not None:
            self._update_at_depth(ids, depth, (float(x), float(y)))
            return
        dpitch, droll = self.attitude(view) if self.attitude is not None else (0.0, 0.0)
        tilted = bool(dpitch or droll)
        axes = self.camera.tilted(dpitch, droll) if tilted else self.camera.R
        kernels.map_vote(
            self.evidence,
            self.stamp,
            self._cells,  # the map
            *self._origin_xy,
            1.0 / c.map_resolution_m,  # its corner and cells per metre
            float(x),
            float(y),
            math.cos(yaw),
            math.sin(yaw),  # the pose
            self._vx,
            self._vy,
            self._weight,
            ids,
            self._sample_pix,
            self.columns,  # the samples and what they saw
            self.frame,
            self._fade,  # the votes' fading
            tilted,
            self._ray,
            self._ground0,
            axes,
            self.camera.t,
        )  # the camera off its mount
        self._reblock()

    @property
    def cells(self) -> np.ndarray:
        """Terrain column of every cell (rows y, columns x), each decided from its evidence: a
        read-only view, valid until the next :meth:`update` (which leaves the cells it votes on
        to be decided again)."""
        kernels.map_settle(self._cells, self.evidence, self.lethal, self._shares)
        view = self._cells.view()
        view.flags.writeable = False
        return view

    def layers(self) -> kernels.MapLayers:
        """The map as a compiled read takes it (its cells, some still undecided, their evidence,
        the lethal columns, the shares that decide a column, its corner and cells per metre).
        Read once the map has been placed (its first update: ``origin`` is not None)."""
        ox, oy = self._origin_xy
        return kernels.MapLayers(self._cells, self.evidence, self.lethal, self._shares, ox, oy, 1.0 / self.settings.map_resolution_m)

    def layers_without_geometry(self) -> kernels.MapLayers | None:
        """The map as :meth:`layers` gives it, but with the ground that reads as lethal for its
        geometry alone (past :attr:`limits`) decided from its class evidence instead: what the
        way would be if the ground were flat. None while no ground reads so."""
        if not len(self._lethal_by_geometry):
            return None
        cells = self._cells.copy()
        cells.reshape(-1)[self._lethal_by_geometry] = kernels.UNSETTLED
        ox, oy = self._origin_xy
        return kernels.MapLayers(cells, self.evidence, self.lethal, self._shares, ox, oy, 1.0 / self.settings.map_resolution_m)

    def beside(self, path: ReferencePath, s: np.ndarray, lat: np.ndarray) -> np.ndarray:
        """Terrain column (O, S, F) at the points ``lat`` (O, F) [m] left of the path at arc lengths ``s`` (S,)."""
        if self.origin is None:
            return np.full((lat.shape[0], len(s), lat.shape[1]), self.k + 1, dtype=np.uint8)
        a, d, length = path.segments
        return kernels.map_read_beside(
            self.layers(), path.s, a, d, length, np.asarray(s, dtype=np.float64), np.ascontiguousarray(lat, dtype=np.float64), self.k + 1
        )

    def lookup(self, points: np.ndarray, split: tuple[float, float] | None = None) -> np.ndarray:
        """Terrain column at each world point (..., 2); K + 1 (never seen) outside the map.

        ``split`` (lead, second): a cell split between two terrain classes reads as never seen too,
        its terrain class (not lethal) holding less than ``lead`` of its evidence while another
        such class holds at least ``second`` (kernels.map_read_split): a reader for which the
        two classes differ, and the neighbouring cells tell which it is."""
        if self.origin is None:
            return np.full(points.shape[:-1], self.k + 1, dtype=np.uint8)
        px = np.ascontiguousarray(points[..., 0], dtype=np.float64).reshape(-1)
        py = np.ascontiguousarray(points[..., 1], dtype=np.float64).reshape(-1)
        if split is None:
            out = kernels.map_read(self.layers(), px, py, self.k + 1)
        else:
            out = kernels.map_read_split(self.layers(), px, py, self.k + 1, np.float32(split[0]), np.float32(split[1]))
        return out.reshape(points.shape[:-1])


def _ground(ray: np.ndarray, axes: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Where rays (N, 2) of a camera at ``t`` with ``axes`` (rows right, down, forward in the vehicle
    frame) meet the ground, (N, 2) in the vehicle frame [m]; NaN for rays that do not.

    Elementwise products and sums in a fixed order (no matrix product): the same bits on every CPU."""
    d = [ray[:, 0] * axes[0, i] + ray[:, 1] * axes[1, i] + axes[2, i] for i in range(3)]
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(d[2] < -1e-12, -t[2] / d[2], np.nan)
    return np.stack([t[0] + scale * d[0], t[1] + scale * d[1]], axis=1)


def _across_the_edge(n: int, dx: int, dy: int, reach: int) -> np.ndarray:
    """The cells (flat indices) of an n by n map moved as :func:`_shifted` moves it whose disc of
    ``reach`` cells crosses the edge of what the old map and the new one share, along each axis
    it moved along: their discs held cells the move dropped (the kept cells at the map's edge it
    moved towards), or now hold cells it kept (the new cells beside the kept ones)."""
    r0, r1, c0, c1 = max(0, -dy), n - max(0, dy), max(0, -dx), n - max(0, dx)  # the kept rows, then columns
    if r0 >= r1 or c0 >= c1:
        return np.empty(0, dtype=np.int64)
    crossing = np.zeros((n, n), dtype=np.bool_)
    crossing[max(r0 - reach, 0) : r1 + reach, max(c0 - reach, 0) : c1 + reach] = True
    inner_rows = (r0 + reach, r1 - reach) if dy else (0, n)
    inner_cols = (c0 + reach, c1 - reach) if dx else (0, n)
    crossing[inner_rows[0] : max(inner_rows), inner_cols[0] : max(inner_cols)] = False
    return np.flatnonzero(crossing)


def _shifted(a: np.ndarray, dx: int, dy: int, fill: float) -> np.ndarray:
    """``a`` (rows y, columns x, ...) moved so that what was at cell (i + dx, j + dy) is at (i, j); ``fill`` where nothing was."""
    out = np.full_like(a, fill)
    n = a.shape[0]
    if abs(dx) < n and abs(dy) < n:
        out[max(0, -dy) : n - max(0, dy), max(0, -dx) : n - max(0, dx)] = a[max(0, dy) : n - max(0, -dy), max(0, dx) : n - max(0, -dx)]
    return out
