"""The preference set S: one constant-command trajectory per entry of the control set A.

Trajectories live in the vehicle frame and the camera is fixed to the vehicle, so every
trajectory point's pixel is computed once per camera (SPEC 6).

Default horizon, chosen by experiment (docs/design.md, "Trajectory horizon"): n = 30 steps of
dt = 0.2 s, i.e. points out to 5.8 m at 1 m/s. Shorter arcs (3 m) end before the point where a driver who must
clear a 2-4 m patch with a 1.2 m wide vehicle starts to turn, so the features would not show the
reason for the turn; much longer ones run past the camera's useful range on the tight arcs and
blur neighbouring situations together.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from terrapref.camera import PinholeCamera
from terrapref.records import to_plain
from terrapref.vehicle import ControlSet

MAX_STEPS = 1000
"""The most points a trajectory may have (a horizon of n_steps x dt_s; 30 x 0.2 s by default)."""


@dataclass(frozen=True)
class PreferenceSetConfig:
    """Configuration of S and A.

    Attributes:
        control: the control set A (v [m/s], the w grid [rad/s]); paper: 21 x 1 m/s, -1..1.
        n_steps: trajectory points per trajectory (n).
        dt_s: time step of the forward simulation [s].
    """

    control: ControlSet = field(default_factory=ControlSet)
    n_steps: int = 30
    dt_s: float = 0.2

    def __post_init__(self) -> None:
        if not 1 <= self.n_steps <= MAX_STEPS or not (math.isfinite(self.dt_s) and self.dt_s > 0):
            raise ValueError(f"n_steps must be in 1..{MAX_STEPS} and dt_s a number > 0")

    @property
    def m(self) -> int:
        return self.control.m

    @property
    def horizon_m(self) -> float:
        """Travel distance to each trajectory's last point [m]: point 1 is the origin, so n - 1 steps."""
        return self.control.v_mps * self.dt_s * (self.n_steps - 1)

    def to_dict(self) -> dict:
        return to_plain(self)

    @classmethod
    def from_dict(cls, data: dict) -> PreferenceSetConfig:
        return cls(ControlSet.from_dict(data["control"]), int(data["n_steps"]), float(data["dt_s"]))


def forward_simulate(v: np.ndarray, w: np.ndarray, n: int, dt: float) -> np.ndarray:
    """Euler rollouts of constant commands from (0, 0, 0), per SPEC 6.

    Args:
        v, w: speeds [m/s] and yaw rates [rad/s], shape (m,).

    Returns:
        Poses (x, y, theta) of points t = 1..n, shape (m, n, 3); point 1 is the origin.
    """
    v, w = np.asarray(v, float), np.asarray(w, float)
    theta = np.outer(w, np.arange(n) * dt)  # theta_t for t = 1..n, (m, n)
    step = (v * dt)[:, None]
    # x_t = x_{t-1} + v dt cos(theta_{t-1}): the first point is the origin, then cumulative sums.
    dx = np.concatenate([np.zeros((len(v), 1)), step * np.cos(theta[:, :-1])], axis=1)
    dy = np.concatenate([np.zeros((len(v), 1)), step * np.sin(theta[:, :-1])], axis=1)
    return np.stack([np.cumsum(dx, axis=1), np.cumsum(dy, axis=1), theta], axis=-1)


class PreferenceSet:
    """S for one camera: trajectories (m, n, 3) and each point's flat pixel index (m, n), -1 if unseen."""

    def __init__(self, config: PreferenceSetConfig, camera: PinholeCamera) -> None:
        self.config = config
        self.camera = camera
        c = config.control
        self.trajectories = forward_simulate(np.full(c.m, c.v_mps), np.asarray(c.w_rps), config.n_steps, config.dt_s)
        self.pixel_index = camera.pixel_indices(self.trajectories[..., :2])
        self.endpoints = self.trajectories[:, -1, :2]  # (m, 2) vehicle frame [m]

    @property
    def m(self) -> int:
        return self.config.m

    def visible_fraction(self) -> np.ndarray:
        """Share of each trajectory's points that land inside the image, shape (m,)."""
        return (self.pixel_index >= 0).mean(axis=1)
