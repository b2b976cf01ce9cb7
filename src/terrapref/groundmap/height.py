"""The ground map's height layer (SPEC 19): elevation per cell from depth images and the camera's
pose, and the ground's geometry read from it as grid_map's traversability filters read theirs.

Each frame's depth image, read at the pixels the map reads its classes at (the ground every
0.1 m ahead, as a level camera over flat ground sees it: about one return a cell), gives returns
in the world: the optical centre plus the depth times the pixel's ray (the camera placed by the
robot's pose, its height, pitch and roll). Each cell keeps the mean height of the returns that fell in it and how many did
(the ``elevation`` and ``returns`` layers, terrapref.groundmap.layers). A cell's geometry comes
from the cells with an elevation within ``radius_m`` of it: the slope of the least-squares plane
through them and the roughness (their heights' standard deviation about that plane), unknown
(NaN) where fewer than three are known; and the step, the height range over the cell and its
eight neighbours, unknown where fewer than two of them are.

Ground the vehicle cannot cross within its limits is lethal, from its config and never learned
(:class:`GeometryLimits`): a slope past its roll or its pitch limit, whichever is smaller (a
slope may have to be driven across as well as up), or a step higher than it climbs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from terrapref.groundmap import height_compiled as kernels

if TYPE_CHECKING:
    from terrapref.camera import PinholeCamera
    from terrapref.vehicle import VehicleConfig


@dataclass(frozen=True)
class HeightSettings:
    """How the height layer is read from depth and its geometry from the layer.

    Attributes:
        radius_m: the disc round a cell its plane is fitted in [m] (0.3 m: half the vehicle's
            width, as grid_map's slope filter is set for a robot of this size).
    """

    radius_m: float = 0.3

    def __post_init__(self) -> None:
        if not (math.isfinite(self.radius_m) and self.radius_m > 0):
            raise ValueError(f"radius_m must be finite and > 0, got {self.radius_m!r}")


@dataclass(frozen=True)
class GeometryLimits:
    """The ground a vehicle cannot cross: a slope past ``max_slope_rad``, a step over ``max_step_m``."""

    max_slope_rad: float
    max_step_m: float

    @classmethod
    def of(cls, vehicle: VehicleConfig) -> GeometryLimits:
        """The limits of ``vehicle``: its smaller tilt limit (roll or pitch) and its step."""
        return cls(math.radians(min(vehicle.max_roll_deg, vehicle.max_pitch_deg)), vehicle.max_step_m)

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

    def points(self, depth: np.ndarray, axes: np.ndarray, centre: np.ndarray) -> np.ndarray:
        """The returns (N, 3) in the world [m] of ``depth`` (H, W) [m along the optical axis, NaN:
        none] seen by a camera with ``axes`` (3, 3; rows right, down, forward in the world) at
        ``centre`` (3,); NaN rows for pixels without a return."""
        d = depth[self.rows, self.cols].astype(np.float64)
        return centre + (d[:, None] * self.ray) @ axes


def vote_heights(elevation: np.ndarray, returns: np.ndarray, corner: tuple[float, float], res_m: float, points: np.ndarray) -> None:
    """Fold the returns ``points`` (N, 3) [m] into the layers of a map whose corner is ``corner``."""
    kernels.height_vote(elevation, returns, corner[0], corner[1], 1.0 / res_m, np.ascontiguousarray(points, dtype=np.float64))


def geometry_of_cells(elevation: np.ndarray, rows: np.ndarray, cols: np.ndarray, res_m: float, radius_m: float) -> np.ndarray:
    """Slope [rad], roughness [m] and step [m] of the cells (``rows``, ``cols``), (N, 3); NaN where unknown."""
    out = np.empty((len(rows), 3))
    reach = max(1, int(math.floor(radius_m / res_m + 1e-9)))
    kernels.cell_geometry(elevation, np.asarray(rows, dtype=np.int64), np.asarray(cols, dtype=np.int64), reach, res_m, out)
    return out
