"""Pinhole camera fixed to the vehicle, looking at the ground plane z = 0 (SPEC section 5).

Frames: vehicle (x forward, y left, z up) and camera (OpenCV: x right, y down, z forward).
Pixel (col, row) covers [col, col + 1) x [row, row + 1); its centre is at +0.5.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from terrapref.records import from_plain, to_plain

ROS_PIXEL_CENTRE_PX = 0.5
"""ROS's CameraInfo, as OpenCV, puts pixel (col, row)'s centre at (col, row): its principal point is
this camera's less this much on each axis (an image 640 px wide centred at 319.5, here at 320)."""

MAX_IMAGE_PX = 4096
"""The largest image side a camera may have [px]: a 4K segmentation; the planner's per-pixel tables
of a larger one would not fit a robot's memory, and a size read from a file is bounded by it."""


@dataclass(frozen=True)
class CameraConfig:
    """Camera intrinsics and mounting.

    Attributes:
        width_px, height_px: image size [px].
        hfov_deg: horizontal field of view [deg]; gives fx when ``fx`` is None.
        fx, fy, cx, cy: intrinsics [px]; None derives them (fx = fy from hfov, principal
            point at the image centre).
        mount_height_m: height of the optical centre above the ground [m].
        mount_forward_m: optical centre ahead of the vehicle origin [m].
        pitch_deg: downward tilt of the optical axis [deg].
        yaw_deg: optical axis yaw relative to the vehicle's heading, CCW [deg].
        max_range_m: rays longer than this (from the optical centre) see nothing (255) [m].
    """

    width_px: int = 640
    height_px: int = 480
    hfov_deg: float = 90.0
    fx: float | None = None
    fy: float | None = None
    cx: float | None = None
    cy: float | None = None
    mount_height_m: float = 1.0
    mount_forward_m: float = 0.0
    pitch_deg: float = 30.0
    yaw_deg: float = 0.0
    max_range_m: float = 30.0

    def __post_init__(self) -> None:
        if not (0 < self.width_px <= MAX_IMAGE_PX and 0 < self.height_px <= MAX_IMAGE_PX):
            raise ValueError(f"image size must be 1..{MAX_IMAGE_PX} px a side, got {self.width_px} x {self.height_px}")
        if not 0 < self.hfov_deg < 180:
            raise ValueError("hfov_deg must be in (0, 180)")
        if self.mount_height_m <= 0 or self.max_range_m <= 0:
            raise ValueError("mount_height_m and max_range_m must be > 0")
        if not -90 < self.pitch_deg < 90:
            raise ValueError("pitch_deg must be in (-90, 90)")
        for name in ("fx", "fy"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a focal length > 0 [px], got {value}")
        for name in ("cx", "cy"):
            value = getattr(self, name)
            if value is not None and not math.isfinite(value):
                raise ValueError(f"{name} must be a finite number [px], got {value}")

    @property
    def intrinsics(self) -> tuple[float, float, float, float]:
        """(fx, fy, cx, cy) [px]."""
        fx = self.fx if self.fx is not None else (self.width_px / 2) / math.tan(math.radians(self.hfov_deg) / 2)
        fy = self.fy if self.fy is not None else fx
        cx = self.cx if self.cx is not None else self.width_px / 2
        cy = self.cy if self.cy is not None else self.height_px / 2
        return fx, fy, cx, cy

    def same_geometry(self, other: CameraConfig, rel_tol: float = 1e-6) -> bool:
        """Whether ``other`` projects the ground as this camera does: the same image size, and
        intrinsics, mount and range equal within ``rel_tol`` (a calibration file's fx = 320.0
        and one derived from a 90 deg field of view, 320.00000000000006, are the same camera)."""
        if (self.width_px, self.height_px) != (other.width_px, other.height_px):
            return False
        mine, theirs = self._geometry(), other._geometry()
        return all(math.isclose(a, b, rel_tol=rel_tol, abs_tol=1e-9) for a, b in zip(mine, theirs))

    def _geometry(self) -> tuple[float, ...]:
        return (*self.intrinsics, self.mount_height_m, self.mount_forward_m, self.pitch_deg, self.yaw_deg, self.max_range_m)

    def to_dict(self) -> dict:
        return to_plain(self)

    @classmethod
    def from_dict(cls, data: dict) -> CameraConfig:
        return from_plain(cls, data)


class PinholeCamera:
    """Projection between vehicle-frame ground points and pixels."""

    def __init__(self, config: CameraConfig | None = None) -> None:
        self.config = c = config or CameraConfig()
        self.fx, self.fy, self.cx, self.cy = c.intrinsics
        p, y = math.radians(c.pitch_deg), math.radians(c.yaw_deg)
        forward = np.array([math.cos(p) * math.cos(y), math.cos(p) * math.sin(y), -math.sin(p)])
        right = np.array([math.sin(y), -math.cos(y), 0.0])
        down = np.cross(forward, right)
        # Rows: the camera's axes in the vehicle frame, so p_cam = R @ (p_vehicle - t).
        self.R = np.stack([right, down, forward])
        self.t = np.array([c.mount_forward_m, 0.0, c.mount_height_m])

    def tilted(self, dpitch_rad: float, droll_rad: float) -> np.ndarray:
        """The camera's axes (rows: right, down, forward in the vehicle frame, as :attr:`R`) when
        its attitude is off the mount by ``dpitch_rad`` (more downward) and ``droll_rad`` (about the
        optical axis, clockwise as the camera looks), shape (3, 3)."""
        c = self.config
        p, y = math.radians(c.pitch_deg) + dpitch_rad, math.radians(c.yaw_deg)
        cp, sp, cy, sy = math.cos(p), math.sin(p), math.cos(y), math.sin(y)
        forward = (cp * cy, cp * sy, -sp)
        right = (sy, -cy, 0.0)
        down = (
            forward[1] * right[2] - forward[2] * right[1],
            forward[2] * right[0] - forward[0] * right[2],
            forward[0] * right[1] - forward[1] * right[0],
        )  # forward x right, as the mount's axes are made
        cr, sr = math.cos(droll_rad), math.sin(droll_rad)
        return np.array([[cr * r + sr * d for r, d in zip(right, down)], [-sr * r + cr * d for r, d in zip(right, down)], forward])

    def placement(
        self, pose: tuple[float, float, float], attitude: tuple[float, float, float] = (0.0, 0.0, 0.0)
    ) -> tuple[np.ndarray, np.ndarray]:
        """The camera's axes (3, 3; rows right, down, forward) and optical centre (3,) [m] in the
        world frame, for the vehicle at ``pose`` (x, y, yaw) with ``attitude`` (its height [m],
        pitch and roll [rad]: yaw, pitch and roll applied in that order, REP 103)."""
        x, y, yaw = pose
        z, pitch, roll = attitude
        cz, sz = math.cos(yaw), math.sin(yaw)
        cp, sp = math.cos(pitch), math.sin(pitch)
        cr, sr = math.cos(roll), math.sin(roll)
        body = np.array(
            [
                [cz * cp, cz * sp * sr - sz * cr, cz * sp * cr + sz * sr],
                [sz * cp, sz * sp * sr + cz * cr, sz * sp * cr - cz * sr],
                [-sp, cp * sr, cp * cr],
            ]
        )  # world from body: Rz(yaw) Ry(pitch) Rx(roll)
        return self.R @ body.T, np.array([x, y, z]) + body @ self.t

    @property
    def shape(self) -> tuple[int, int]:
        """Image shape (rows, cols)."""
        return self.config.height_px, self.config.width_px

    def project_ground(self, points_v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project vehicle-frame ground points to pixel coordinates.

        Args:
            points_v: ground points (x forward, y left) [m], shape (..., 2).

        Returns:
            uv: continuous pixel coordinates (col, row), shape (..., 2); pixel (i, j) is
                ``floor(uv)``.
            visible: shape (...,), True where the point is in front of the camera, inside
                the image and within ``max_range_m`` of the optical centre.
        """
        pts = np.asarray(points_v, dtype=float)
        p3 = np.concatenate([pts, np.zeros(pts.shape[:-1] + (1,))], axis=-1) - self.t
        cam = p3 @ self.R.T
        z = cam[..., 2]
        in_front = z > 1e-9
        zs = np.where(in_front, z, 1.0)
        u = self.fx * cam[..., 0] / zs + self.cx
        v = self.fy * cam[..., 1] / zs + self.cy
        c = self.config
        visible = in_front & (u >= 0) & (u < c.width_px) & (v >= 0) & (v < c.height_px) & (np.linalg.norm(p3, axis=-1) <= c.max_range_m)
        return np.stack([u, v], axis=-1), visible

    def pixel_indices(self, points_v: np.ndarray) -> np.ndarray:
        """Flat pixel index (row * width + col) of each ground point, -1 where not visible; shape (...,)."""
        uv, visible = self.project_ground(points_v)
        col = np.floor(uv[..., 0]).astype(np.int64)
        row = np.floor(uv[..., 1]).astype(np.int64)
        return np.where(visible, row * self.config.width_px + col, -1)

    def rays(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Vehicle-frame ray directions through pixel coordinates (u, v), shape (..., 3), unnormalised."""
        d = np.stack([(u - self.cx) / self.fx, (v - self.cy) / self.fy, np.ones(np.broadcast(u, v).shape)], axis=-1)
        return d @ self.R

    def back_project(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Ground points (vehicle frame, shape (..., 2)) seen at pixel coordinates ``uv`` (..., 2).

        Returns the points and a mask of rays that hit the ground within range.
        """
        uv = np.asarray(uv, dtype=float)
        d = self.rays(uv[..., 0], uv[..., 1])
        down = d[..., 2] < -1e-12
        s = np.where(down, -self.t[2] / np.where(down, d[..., 2], -1.0), 0.0)
        ground = self.t + s[..., None] * d
        ok = down & (s * np.linalg.norm(d, axis=-1) <= self.config.max_range_m)
        return ground[..., :2], ok

    def horizon_row(self) -> float:
        """Image row of the horizon (meaningful for a level camera, yaw and roll aside)."""
        return self.cy - self.fy * math.tan(math.radians(self.config.pitch_deg))
