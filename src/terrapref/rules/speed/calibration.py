"""The grades the speed rule reads ahead, checked against the body's own pitch once it gets there.

The height layer reads the ground's shape through the depth camera, and a real one reads it with
a bias that grows with range: a stereo camera's noise along each ray (growing with the square of
the depth) and a mount that wanders by a degree or two make level ground ahead look as if it rose,
the more so the farther ahead (docs/lab/2026-11-29-relief-speed.md). A speed rule that sheds speed per degree then slows on level ground. The body's
pitch where it stands is known (its odometry's attitude), so each grade read ahead is kept with
where it was read for, and once the vehicle stands there, heading the same way, the difference
is that station's error; the mean error per station (shrunk toward none until enough are seen)
is taken off what is read there later. On clean frames it stays near zero.
"""

from __future__ import annotations

import math

import numpy as np

from terrapref.rules.speed.calibration_compiled import check_arrived

KEPT_DECISIONS = 100  # the decisions whose grades are kept until the vehicle gets there (10 s at 10 Hz)
REACH_M = 0.15  # a kept station counts once the vehicle stands this near it ...
HEADING_RAD = math.radians(20.0)  # ... heading within this of the way there
PRIOR = 10.0  # the errors a station's correction is shrunk toward none by (a station's own count below this halves it or more)
FADE = 0.995  # each error's weight against the next's (about 200 errors a station remembered)


class GradeCheck:
    """Errors of the grades read at each station of a way (module docstring).

    Args:
        stations: the stations a way is read at.
    """

    def __init__(self, stations: int) -> None:
        self.stations = stations
        self._points = np.full((KEPT_DECISIONS, stations, 2), np.nan)
        self._heading = np.zeros((KEPT_DECISIONS, stations))
        self._read = np.full((KEPT_DECISIONS, stations), np.nan)
        self._next = 0
        self._sum = np.zeros(stations)  # each station's errors, faded [deg]
        self._count = np.zeros(stations)  # and how many, faded

    def reset(self) -> None:
        """Forget the grades kept and the errors found (a new path, a new place)."""
        self.__init__(self.stations)

    @property
    def correction(self) -> np.ndarray:
        """What to take off the grade read at each station [deg] (stations,)."""
        return self._sum / (self._count + PRIOR)

    def arrived(self, x: float, y: float, yaw: float, grade_deg: float) -> None:
        """The vehicle stands at (``x``, ``y``) heading ``yaw`` [rad], its body pitched ``grade_deg``
        (positive up): each kept grade read for here is checked against it, once."""
        kept = (self._points, self._heading, self._read)
        check_arrived(kept, (x, y, yaw, grade_deg), (REACH_M, HEADING_RAD), FADE, (self._sum, self._count))

    def keep(self, points: np.ndarray, heading: np.ndarray, read_deg: np.ndarray) -> None:
        """Keep the grades ``read_deg`` (stations,) read for the body at ``points`` (stations, 2)
        heading ``heading`` (stations,) [rad], to be checked once the vehicle gets there."""
        i = self._next % KEPT_DECISIONS
        self._points[i], self._heading[i], self._read[i] = points, heading, read_deg
        self._next += 1
