"""The ground map's height layer (SPEC 19): elevation per cell from depth images and the camera's
pose, and the ground's geometry read from it as grid_map's traversability filters read theirs.

Each frame's depth image, read at the pixels the map reads its classes at (the ground every
0.1 m ahead, as a level camera over flat ground sees it: about one return a cell), gives returns
in the world: the optical centre plus the depth times the pixel's ray (the camera placed by the
robot's pose, its height, pitch and roll). Each return weighs the inverse of its variance
(:class:`HeightSettings`: a stereo camera's error growing with the square of the depth, the
camera's attitude known to a degree or so). Each cell keeps the weighted mean height of the
returns that fell in it, how many did, their spread and their weights (the ``elevation``,
``returns``, ``spread`` and ``weight`` layers, terrapref.groundmap.layers); its height is trusted
once its standard error, by the sensor's errors and by the spread alike, is small enough.

The ground's geometry is read from its shape rather than from those heights. A camera whose
attitude errs by a degree or two (its mount's play and vibration, unknown to the planner) puts
every return of a frame off by one plane through the camera: 0.17-0.35 m at 5-10 m. Ground seen
in different frames (at the edge of the view, behind a mound, as the vehicle turns) then gets
heights that disagree by as much, and a step or a slope read across them is a ghost. Within one
frame there is none: so each frame's returns give each cell its gradient (the plane through its
own mean return and its two neighbours' along x and y), and the gradients, weighed by their
variance, are fused over frames (the ``shape`` layer). Where a frame moves a cell's
difference by more than :data:`CHECK_TOLERANCE_M` (or first makes it known), near the vehicle,
the difference is read again, and the sums over the disc round each cell of the differences as
read are moved with it (the ``checked`` and ``disc`` layers). A cell's slope is that of the mean
gradient read within ``radius_m`` of it (a least-squares plane's, on a regular grid: two
quotients of those sums), unknown where fewer than three gradients are known; its step is the height range over the cell and its
eight neighbours, their heights summed from the differences between them, unknown where fewer
than two of them are. The roughness (the heights' standard deviation about the plane fitted
through them within ``radius_m``) is read within each frame too, from the frame's own mean
returns of the cells round a cell, less the share of the depth's noise in it, and fused over the
frames that saw the cell within ``rough_range_m``, the least noisy weighing most (the ``rough``
layers): a pose off by a decimetre from frame to frame shifts each frame's returns by a third of
a rough patch's bumps, and heights fused over such frames read it half as rough as it is. The
speed rule and the costmap read it.

Ground the vehicle cannot cross within its limits is lethal, from its config and never learned
(:class:`GeometryLimits`): a slope past its roll or its pitch limit, whichever is smaller (a
slope may have to be driven across as well as up), or a step higher than it climbs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from terrapref.groundmap import height_compiled as kernels

if TYPE_CHECKING:
    from terrapref.camera import PinholeCamera, SegmentationView
    from terrapref.vehicle import Pose, VehicleConfig


# A cell's difference to a neighbour is read again when it has moved by more than this since it
# was last read [m], or has come to be known: ground whose shape has settled is not read again
# every frame. A slope is read from the differences as last read, so each axis of its gradient
# is within this over the cell's size (0.01, 0.6 deg, at 0.1 m cells) of what the differences
# now say; 5 mm let the relief the offset rule reads stray by up to 2 deg.
CHECK_TOLERANCE_M = 0.001


@dataclass(frozen=True)
class HeightSettings:
    """How the height layer is read from depth and its geometry from the layer.

    Attributes:
        radius_m: the disc round a cell its slope (and its plane, for the roughness) is read
            over [m] (0.3 m: half the vehicle's width, as grid_map's slope filter is set for a
            robot of this size).
        min_returns: a cell's elevation is trusted once this many returns fell in it...
        max_error_m: ... and once the standard error of their mean is at most this [m], both as
            their spread shows it and as the sensor's errors below put it: a noisy depth
            camera's far returns count once enough of them agree, as an elevation map's variance
            gates its cells. A gradient of the ground's shape counts once its difference over
            a cell is known so well.
        base_error_m, depth_error_per_m2, attitude_error_deg: a return's height error (one
            standard deviation) as the map takes it: ``base_error_m``, a stereo camera's depth
            error of ``depth_error_per_m2`` times the depth squared, and the camera's attitude
            known to ``attitude_error_deg`` (its mount's play and vibration: a height off by the
            return's distance times its tangent), added in quadrature. Each return weighs the
            inverse of its variance, so the near returns of ground the vehicle comes to outweigh
            the far ones it first saw it by (as elevation mapping fuses its measurements). The
            gradients of one frame leave the attitude's error out: it tilts the whole frame.
        max_range_m: returns deeper than this [m along the optical axis] are not gathered: a
            difference between cells read from returns 10 m deep weighs about 1/200 of what it
            needs to count (at 0.003 per m^2 of depth, 0.3 m a return), and far heights are
            off by as much as the camera's attitude is (0.17 m at 10 m for a degree); the ground
            there is gathered as the vehicle nears it.
        block_range_m: the ground this near the vehicle has its shape read, and its geometry
            checked against the limits, as returns fall in it [m]; farther ground is read as the
            vehicle nears it.
        rough_range_m: each frame reads the roughness of the ground within this distance [m]
            across the ground from the camera (farther, one return a cell is too noisy to tell
            rough ground from smooth: 0.075 m at 5 m against roughness of 0.01-0.02 m).
    """

    radius_m: float = 0.3
    min_returns: int = 2
    max_error_m: float = 0.03
    base_error_m: float = 0.01
    depth_error_per_m2: float = 0.003
    attitude_error_deg: float = 1.0
    max_range_m: float = 10.0
    block_range_m: float = 10.0
    rough_range_m: float = 5.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.radius_m) and self.radius_m > 0):
            raise ValueError(f"radius_m must be finite and > 0, got {self.radius_m!r}")
        errors = (self.base_error_m, self.depth_error_per_m2, self.attitude_error_deg)
        if not all(math.isfinite(e) and e >= 0 for e in errors) or self.base_error_m <= 0 or self.attitude_error_deg >= 45:
            raise ValueError("a return's errors must be finite and >= 0, base_error_m > 0 and attitude_error_deg < 45")

    @property
    def least_weight(self) -> float:
        """The weight [1 / m^2] from which a difference between cells counts (its standard error
        at most ``max_error_m``), as the ground's shape is read."""
        return 1.0 / self.max_error_m**2

    @property
    def errors(self) -> tuple[float, float, float]:
        """A return's errors as the height layer's kernels take them: the base [m], per m^2 of
        depth, and the tangent of the attitude's."""
        return self.base_error_m, self.depth_error_per_m2, math.tan(math.radians(self.attitude_error_deg))


class DepthImage(NamedTuple):
    """A frame's depth image and where its camera was.

    Attributes:
        image: (H, W) float32 [m along the optical axis, NaN: no return].
        axes: (3, 3) the camera's axes in the world (rows right, down, forward).
        centre: (3,) its optical centre in the world [m].
    """

    image: np.ndarray
    axes: np.ndarray
    centre: np.ndarray

    @classmethod
    def of(cls, view: SegmentationView, camera: PinholeCamera, pose: Pose) -> DepthImage | None:
        """``view``'s depth image with ``camera`` placed by ``pose`` and the view's attitude
        (:attr:`SegmentationView.attitude`); None when the view carries none (flat ground)."""
        return cls(view.depth, *camera.placement(pose, view.attitude)) if view.carries_depth else None


@dataclass(frozen=True)
class GeometryLimits:
    """The ground a vehicle cannot cross: a slope past ``max_slope_rad``, a step over ``max_step_m``;
    kept ``reach_m`` further off than lethal terrain is, since the planner's footprint is the line
    across the vehicle at its reference point, and its wheels reach half the wheelbase ahead of it."""

    max_slope_rad: float
    max_step_m: float
    reach_m: float = 0.0

    @classmethod
    def of(cls, vehicle: VehicleConfig) -> GeometryLimits:
        """The limits of ``vehicle``: its smaller tilt limit (roll or pitch), its step, half its wheelbase."""
        return cls(math.radians(min(vehicle.max_roll_deg, vehicle.max_pitch_deg)), vehicle.max_step_m, 0.5 * vehicle.wheelbase_m)

    def lethal(self, geometry: np.ndarray) -> np.ndarray:
        """Which cells of ``geometry`` (..., 3: slope, roughness, step) are past the limits;
        unknown geometry (NaN) is not."""
        slope, step = geometry[..., 0], geometry[..., 2]
        return (slope > self.max_slope_rad) | (step > self.max_step_m)


class DepthRays:
    """The pixels of a camera's depth image the height layer reads, and their rays.

    Args:
        camera: the camera.
        flat_index: the pixels (row * width + col).
    """

    def __init__(self, camera: PinholeCamera, flat_index: np.ndarray) -> None:
        self.rows, self.cols = np.divmod(np.asarray(flat_index, dtype=np.int64), camera.config.width_px)
        # Each pixel's ray in the camera frame (right, down, forward = 1): depth times it is the point.
        self.ray = np.stack(
            [(self.cols + 0.5 - camera.cx) / camera.fx, (self.rows + 0.5 - camera.cy) / camera.fy, np.ones(len(self.rows))], axis=1
        )

    @property
    def pixels(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The pixels' rows, columns and rays, as terrapref.groundmap.height_compiled.depth_frame takes them."""
        return self.rows, self.cols, self.ray


class Heights(NamedTuple):
    """A ground map's height layers: ``elevation`` (n, n) float32 [m, NaN: none], the returns'
    mean weighted by the inverse of their variance, ``returns`` (n, n) uint32, how many, ``spread``
    (n, n) float32, their weighted sum of squared deviations from the mean [m^2 / m^2], and
    ``weight`` (n, n) float32, their weights' sum [1 / m^2] (None: returns of equal weight whose
    errors are not known)."""

    elevation: np.ndarray
    returns: np.ndarray
    spread: np.ndarray
    weight: np.ndarray | None = None


def trusted_elevation(heights: Heights, settings: HeightSettings, window: tuple[slice, slice] | None = None) -> np.ndarray:
    """Each cell's elevation where it is trusted, else NaN: (n, n) float32, or over ``window``
    (rows, columns: slices of steps of one within the layers) alone. Trusted: at least
    ``min_returns`` returns (and 2), and the standard error of their mean at most
    ``max_error_m``, both as the sensor's errors put it (the inverse of the weights' sum) and
    as their spread shows it (the weighted variance over one less than their count)
    (terrapref.groundmap.height_compiled.trusted_window)."""
    rows, cols = window if window is not None else (slice(None), slice(None))
    n_rows, n_cols = heights.elevation.shape
    return kernels.trusted_window(*_trust(heights, settings), rows.indices(n_rows)[:2], cols.indices(n_cols)[:2])


def _trust(heights: Heights, settings: HeightSettings) -> tuple[tuple[np.ndarray, ...], tuple[float, float, bool]]:
    """The height layers and the trust test's terms as the kernels take them (height_compiled.trusted_window)."""
    weighed = heights.weight is not None
    layers = (heights.elevation, heights.returns, heights.spread, heights.weight if weighed else heights.elevation)
    return layers, (float(max(settings.min_returns, 2)), settings.max_error_m**2, weighed)


def disc_reach(settings: HeightSettings, res_m: float) -> int:
    """The radius, in cells of ``res_m``, of the disc a cell's plane is fitted in."""
    return max(1, int(math.floor(settings.radius_m / res_m + 1e-9)))
