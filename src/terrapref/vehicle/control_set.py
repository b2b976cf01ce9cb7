"""The control set A (SPEC section 6): m discrete (v, w) commands sharing one index with S."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from terrapref.records import to_plain

MOST_V_MPS = 30.0  # the fastest a control set's commands may be [m/s]: a robot file's top speed at most


@dataclass(frozen=True)
class ControlSet:
    """Discrete commands: one forward speed and a grid of yaw rates.

    Attributes:
        v_mps: forward speed of every command [m/s] (paper: 1 m/s).
        w_rps: yaw rates [rad/s], ascending (paper: -1.0, -0.9, ..., 1.0).
    """

    v_mps: float = 1.0
    w_rps: tuple[float, ...] = tuple(round(-1.0 + 0.1 * i, 10) for i in range(21))

    def __post_init__(self) -> None:
        w = np.asarray(self.w_rps)
        if len(w) < 2 or not np.all(np.isfinite(w)) or not np.all(np.diff(w) > 0):
            raise ValueError("w_rps must have at least 2 finite, strictly ascending values")
        if not (math.isfinite(self.v_mps) and 0 < self.v_mps <= MOST_V_MPS):
            raise ValueError(f"v_mps must be > 0 and at most {MOST_V_MPS:g} m/s")
        object.__setattr__(self, "_grid", np.asarray(self.w_rps, dtype=float))  # label_of's, made once

    @classmethod
    def uniform(cls, m: int = 21, v_mps: float = 1.0, w_max_rps: float = 1.0) -> ControlSet:
        """m yaw rates evenly spaced over [-w_max, w_max]."""
        return cls(v_mps, tuple(float(x) for x in np.round(np.linspace(-w_max_rps, w_max_rps, m), 10)))

    @property
    def m(self) -> int:
        return len(self.w_rps)

    @property
    def symmetric(self) -> bool:
        """Whether the w grid is symmetric about zero (so left and right can be mirrored)."""
        w = np.asarray(self.w_rps, dtype=float)
        return bool(np.allclose(w, -w[::-1]))

    def command(self, index: int) -> tuple[float, float]:
        """(v [m/s], w [rad/s]) of one index."""
        return self.v_mps, self.w_rps[index]

    def label_of(self, w: float | np.ndarray) -> int | np.ndarray:
        """Index of the nearest yaw rate to a continuous ``w``; ties go toward w = 0."""
        if isinstance(w, (float, int)):  # one command, as the control loop labels it: the same arithmetic, compiled
            return int(_nearest_label(float(w), self._grid))
        grid = self._grid
        w_arr = np.asarray(w, dtype=float)
        d = np.abs(w_arr[..., None] - grid)
        # Among equally near grid values prefer the one with the smaller |w| (SPEC 6).
        key = np.round(d, 9) * 1e3 + np.abs(grid) * 1e-3
        idx = np.argmin(key, axis=-1)
        return int(idx) if np.ndim(w) == 0 else idx

    def to_dict(self) -> dict:
        return to_plain(self)

    @classmethod
    def from_dict(cls, data: dict) -> ControlSet:
        return cls(float(data["v_mps"]), tuple(float(w) for w in data["w_rps"]))


@njit(cache=True, nogil=True)
def _nearest_label(w: float, grid: np.ndarray) -> int:
    """:meth:`ControlSet.label_of` of one yaw rate: per grid value the NumPy form's ``key = round(|w
    - grid|, 9) * 1e3 + |grid| * 1e-3`` (NumPy rounds to 9 decimals as ``rint(d * 1e9) / 1e9``),
    and the first smallest key, as ``argmin`` takes it (the first NaN if any)."""
    best, best_key = 0, math.inf
    for j in range(grid.shape[0]):
        key = np.rint(abs(w - grid[j]) * 1e9) / 1e9 * 1e3 + abs(grid[j]) * 1e-3
        if j == 0 or key < best_key or (key != key and best_key == best_key):
            best, best_key = j, key
    return best
