"""The grade check's per-frame loop, compiled (Numba) for the planner's control loop
(terrapref.rules.speed.calibration): element by element, without fast-math, in the order the
NumPy form its docstring gives would take them."""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def check_arrived(
    kept: tuple[np.ndarray, np.ndarray, np.ndarray],
    here: tuple[float, float, float, float],
    within: tuple[float, float],
    fade: float,
    errors: tuple[np.ndarray, np.ndarray],
) -> None:
    """Each kept grade (``kept``: the points (D, S, 2) [m], headings (D, S) [rad] and grades read
    (D, S) [deg, NaN: none or checked already]) read for a body standing within ``within``'s
    reach [m] of ``here``'s (x, y), heading within its angle [rad] of ``here``'s yaw, is checked
    against ``here``'s grade [deg]: its error (read less the grade) is folded into its station's
    ``errors`` (sums and counts (S,), each faded by ``fade`` first), decision by decision and
    station by station in order, and the grade is set to NaN (checked once). As

        d2 = (px - x)**2 + (py - y)**2;  turn = |(heading - yaw + pi) % 2 pi - pi|
        for each (i, s) with d2 < reach**2, turn < angle and read finite, row by row:
            total[s] = fade * total[s] + (read[i, s] - grade); count[s] = fade * count[s] + 1
    """
    points, heading, read = kept
    x, y, yaw, grade = here
    reach, angle = within
    total, count = errors
    for i in range(read.shape[0]):
        for s in range(read.shape[1]):
            if not math.isfinite(read[i, s]):
                continue
            d2 = (points[i, s, 0] - x) ** 2 + (points[i, s, 1] - y) ** 2
            turn = abs((heading[i, s] - yaw + math.pi) % (2.0 * math.pi) - math.pi)
            if d2 < reach * reach and turn < angle:
                total[s] = fade * total[s] + (read[i, s] - grade)
                count[s] = fade * count[s] + 1.0
                read[i, s] = np.nan
