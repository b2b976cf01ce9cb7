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
    sums: np.ndarray,
) -> None:
    """Each kept grade (``kept``: the points (D, S, 2) [m], headings (D, S) [rad] and grades read
    (D, S) [deg, NaN: none or checked already]) read for a body standing within ``within``'s
    reach [m] of ``here``'s (x, y), heading within its angle [rad] of ``here``'s yaw, is checked
    against ``here``'s grade [deg]: the pair (read, body) is folded into its station's ``sums``
    (6, S: how many, the reads, the body's grades, the reads squared, the reads times the body's,
    the body's squared; each faded by ``fade`` first), decision by decision and station by station
    in order, and the grade is set to NaN (checked once). As

        d2 = (px - x)**2 + (py - y)**2;  turn = |(heading - yaw + pi) % 2 pi - pi|
        for each (i, s) with d2 < reach**2, turn < angle and read finite, row by row, with r = read[i, s], b = grade:
            sums[:, s] = fade * sums[:, s] + (1, r, b, r * r, r * b, b * b)
    """
    points, heading, read = kept
    x, y, yaw, grade = here
    reach, angle = within
    for i in range(read.shape[0]):
        for s in range(read.shape[1]):
            r = read[i, s]
            if not math.isfinite(r):
                continue
            d2 = (points[i, s, 0] - x) ** 2 + (points[i, s, 1] - y) ** 2
            turn = abs((heading[i, s] - yaw + math.pi) % (2.0 * math.pi) - math.pi)
            if d2 < reach * reach and turn < angle:
                sums[0, s] = fade * sums[0, s] + 1.0
                sums[1, s] = fade * sums[1, s] + r
                sums[2, s] = fade * sums[2, s] + grade
                sums[3, s] = fade * sums[3, s] + r * r
                sums[4, s] = fade * sums[4, s] + r * grade
                sums[5, s] = fade * sums[5, s] + grade * grade
                read[i, s] = np.nan
