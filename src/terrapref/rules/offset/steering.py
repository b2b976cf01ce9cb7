"""Steering toward an offset by pure pursuit, and its inverse: the offset a driver's command was
steering for (the offset rule's training labels)."""

from __future__ import annotations

import math

import numpy as np

from terrapref.scenario.path import ReferencePath
from terrapref.vehicle import Pose, pure_pursuit_yaw_rate


def steer(path: ReferencePath, pose: Pose, progress_m: float, offset_m: np.ndarray | float, pursuit_m: float, v_mps: float) -> np.ndarray:
    """:func:`pursuit_yaw_rates` clipped to the stick's +-1 rad/s."""
    return np.asarray(np.clip(pursuit_yaw_rates(path, pose, progress_m, offset_m, pursuit_m, v_mps), -1.0, 1.0))


def pursuit_yaw_rates(
    path: ReferencePath, pose: Pose, progress_m: float, offset_m: np.ndarray | float, pursuit_m: float, v_mps: float
) -> np.ndarray:
    """Pure-pursuit yaw rate [rad/s] toward the path shifted by ``offset_m`` (left positive), ``pursuit_m`` ahead
    of ``progress_m``. One value per offset, ``offset_m``'s shape.

    Scalar ``math`` throughout (NumPy's vectorised trigonometry may pick CPU-specific code whose
    last bits differ, and ``math.hypot`` rounds more exactly than C's), so that the command, and
    the run it steers, is the same on every machine.
    """
    tx0, ty0, cos_h, sin_h = path.frame_at(min(progress_m + pursuit_m, path.length_m))
    x, y, yaw = (float(v) for v in pose)
    offsets = np.asarray(offset_m, dtype=float)
    out = np.empty(offsets.shape)
    for k, d in enumerate(offsets.flat):
        tx, ty = tx0 - d * sin_h - x, ty0 + d * cos_h - y
        alpha = (math.atan2(ty, tx) - yaw + math.pi) % (2 * math.pi) - math.pi
        out.flat[k] = pure_pursuit_yaw_rate(v_mps, math.sin(alpha), max(math.hypot(tx, ty), 1e-6))
    return out


def intent_offsets(
    poses: np.ndarray, later: np.ndarray, progress_m: np.ndarray, path: ReferencePath, offsets: np.ndarray, pursuit_m: float
) -> np.ndarray:
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
        pursuit_m: the driver's pursuit distance: how far along the path it aimed [m].
    """
    out = np.full(len(poses), np.nan)
    for i, (v, w) in enumerate(later):
        if not (math.isfinite(v) and math.isfinite(w)):
            continue
        yaw_rate = pursuit_yaw_rates(path, tuple(poses[i]), progress_m[i], offsets, pursuit_m, v)
        out[i] = offsets[int(np.argmin(np.abs(yaw_rate - w)))]
    return out
