"""Camera files: terrapref's own (the fields of :class:`CameraConfig`) or a ROS ``camera_info``
YAML as ``camera_calibration`` writes it, with the mounting beside it.

A ROS file holds the intrinsics (``image_width``, ``image_height``, ``camera_matrix``,
``distortion_model``, ``distortion_coefficients``, ...) but not where the camera sits; add
``mount_height_m`` and ``pitch_deg`` (and optionally ``mount_forward_m``, ``yaw_deg``,
``max_range_m``) to the same file, or terrapref's defaults (1.0 m, 30 deg) are used.
"""

from __future__ import annotations

import math
from dataclasses import fields
from pathlib import Path

import numpy as np

from terrapref.camera.pinhole import CameraConfig
from terrapref.errors import ConfigError, Problem, finite_number
from terrapref.yamlio import read_yaml_mapping

_FIELDS = {f.name for f in fields(CameraConfig)}
_MOUNT = ("mount_height_m", "mount_forward_m", "pitch_deg", "yaw_deg", "max_range_m")
_ROS = {
    "image_width",
    "image_height",
    "camera_name",
    "camera_matrix",
    "distortion_model",
    "distortion_coefficients",
    "rectification_matrix",
    "projection_matrix",
}


def _matrix(data: dict, key: str, size: int, problems: list[Problem]) -> np.ndarray | None:
    m = data.get(key)
    values = m.get("data") if isinstance(m, dict) else None
    if not (isinstance(values, list) and len(values) == size and all(finite_number(v) for v in values)):
        problems.append(Problem(f"{key}.data", f"expected {size} finite numbers"))
        return None
    return np.asarray(values, dtype=float)


def camera_from_mapping(data: dict, source: str) -> CameraConfig:
    """A camera from a parsed file; every problem names the field."""
    problems: list[Problem] = []
    if "camera_matrix" in data or "image_width" in data:  # ROS camera_info YAML
        unknown = sorted(set(data) - _ROS - set(_MOUNT))
        problems += [Problem(k, "unknown key in a camera_info file (mounting: " + ", ".join(_MOUNT) + ")") for k in unknown]
        w, h = data.get("image_width"), data.get("image_height")
        for key, v in (("image_width", w), ("image_height", h)):
            if isinstance(v, bool) or not isinstance(v, int) or v <= 0:
                problems.append(Problem(key, "expected a positive integer"))
        k = _matrix(data, "camera_matrix", 9, problems)
        d = data.get("distortion_coefficients")
        if d is not None:
            coeffs = _matrix(
                data,
                "distortion_coefficients",
                len(d.get("data", [])) if isinstance(d, dict) and isinstance(d.get("data"), list) else -1,
                problems,
            )
            if coeffs is not None and np.any(coeffs):
                problems.append(
                    Problem("distortion_coefficients", "the renderer is a pinhole camera; give a rectified (undistorted) calibration")
                )
        mount = {key: data[key] for key in _MOUNT if key in data}
        for key, v in mount.items():
            if not finite_number(v):
                problems.append(Problem(key, "expected a finite number"))
        if problems:
            raise ConfigError(source, problems)
        fx, fy, cx, cy = k[0], k[4], k[2], k[5]
        try:
            return CameraConfig(
                width_px=w,
                height_px=h,
                hfov_deg=math.degrees(2 * math.atan(w / (2 * fx))) if fx > 0 else 90.0,
                fx=fx,
                fy=fy,
                cx=cx,
                cy=cy,
                **mount,
            )
        except ValueError as exc:
            raise ConfigError(source, str(exc)) from None
    unknown = sorted(set(data) - _FIELDS)
    problems += [Problem(k, f"unknown key; expected {', '.join(sorted(_FIELDS))} (or a ROS camera_info file)") for k in unknown]
    for key, v in data.items():
        if key in _FIELDS and not (v is None and key in ("fx", "fy", "cx", "cy")) and not finite_number(v):
            problems.append(Problem(key, "expected a finite number"))
    if problems:
        raise ConfigError(source, problems)
    try:
        return CameraConfig(**data)
    except (TypeError, ValueError) as exc:
        raise ConfigError(source, str(exc)) from None


def load_camera(path: str | Path) -> CameraConfig:
    """Read a camera file (terrapref's fields, or a ROS camera_info YAML)."""
    return camera_from_mapping(read_yaml_mapping(path), str(path))
