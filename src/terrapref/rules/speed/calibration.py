"""The grades the speed rule reads ahead, checked against the body's own pitch once it gets there.

The height layer reads the ground's shape through the depth camera, and a real one reads it with
errors: a stereo camera's noise along each ray (growing with the square of the depth) and a mount
that wanders by a degree or two make level ground ahead look as if it rose, the more so the
farther ahead (docs/lab/2026-11-29-relief-speed.md), and scatter every grade read about the true
one. A speed rule that sheds speed per degree up and down then slows on level ground, for the
bias and for the scatter alike (docs/lab/2026-12-06-grades-read-through-noise.md). The body's
pitch where it stands is known (its odometry's attitude), so each grade read ahead is kept with
where it was read for, and once the vehicle stands there, heading the same way, the pair (read,
body) is that station's check. Each station's checks give the body's grade as a line in the
read one (a least-squares fit, ``body = a + b * read``), shrunk toward the read taken as it is
(``a`` = 0, ``b`` = 1) until enough are seen; the line is what the station's reads are taken to
mean. Where reads scatter about the truth the slope comes out below one, and a read is taken
for as much of a grade as reads of its size turned out to be: the best linear guess of the body's
grade, not the read. Where the body's grade never varied (a robot that gives no attitude is
taken to be level) nothing tells the slope, and only the mean error is taken off. On clean
frames the line stays near the read.
"""

from __future__ import annotations

import math

import numpy as np

from terrapref.rules.speed.calibration_compiled import check_arrived

KEPT_DECISIONS = 100  # the decisions whose grades are kept until the vehicle gets there (10 s at 10 Hz)
REACH_M = 0.15  # a kept station counts once the vehicle stands this near it ...
HEADING_RAD = math.radians(20.0)  # ... heading within this of the way there
PRIOR = 10.0  # checks a station's line is shrunk toward the read as it is by (a station's own count below this halves its say or more)
PRIOR_SPREAD_DEG2 = 4.0  # the spread [deg^2] of reads the prior's checks stand for, all found right (how firmly the slope starts at one)
FADE = 0.995  # each check's weight against the next's (about 200 checks a station remembered)
STILL_DEG2 = 1e-6  # a body's grade that varied by less than this [deg^2] over a station's checks tells no slope


class GradeCheck:
    """Checks of the grades read at each station of a way (module docstring).

    Args:
        stations: the stations a way is read at.
    """

    def __init__(self, stations: int) -> None:
        self.stations = stations
        self._points = np.full((KEPT_DECISIONS, stations, 2), np.nan)
        self._heading = np.zeros((KEPT_DECISIONS, stations))
        self._read = np.full((KEPT_DECISIONS, stations), np.nan)
        self._next = 0
        self._sums = np.zeros((6, stations))  # each station's checks, faded: count, reads, body's, reads^2, reads * body's, body's^2

    def reset(self) -> None:
        """Forget the grades kept and the checks made (a new path, a new place)."""
        self.__init__(self.stations)

    @property
    def line(self) -> tuple[np.ndarray, np.ndarray]:
        """Each station's line (offset [deg], slope) (stations,) each: a grade read there is taken for
        offset + slope * read (module docstring)."""
        n, read, body, read2, cross, body2 = self._sums
        mean_read, mean_body = (np.divide(v, n, out=np.zeros_like(v), where=n > 0) for v in (read, body))
        spread = np.maximum(read2 - n * mean_read**2, 0.0)  # centred sums of squares and products, faded
        moved = np.maximum(body2 - n * mean_body**2, 0.0) > STILL_DEG2 * n
        together = np.where(moved, cross - n * mean_read * mean_body, spread)  # a still body: the slope stays at one
        prior = PRIOR * PRIOR_SPREAD_DEG2
        slope = (together + prior) / (spread + prior)
        return n / (n + PRIOR) * (mean_body - slope * mean_read), slope

    def corrected(self, read_deg: np.ndarray) -> np.ndarray:
        """The grades ``read_deg`` (stations, ...) [deg] read at each station, as that station's line takes them."""
        offset, slope = self.line
        shape = (self.stations,) + (1,) * (np.ndim(read_deg) - 1)
        return offset.reshape(shape) + slope.reshape(shape) * read_deg

    def arrived(self, x: float, y: float, yaw: float, grade_deg: float) -> None:
        """The vehicle stands at (``x``, ``y``) heading ``yaw`` [rad], its body pitched ``grade_deg``
        (positive up): each kept grade read for here is checked against it, once."""
        kept = (self._points, self._heading, self._read)
        check_arrived(kept, (x, y, yaw, grade_deg), (REACH_M, HEADING_RAD), FADE, self._sums)

    def keep(self, points: np.ndarray, heading: np.ndarray, read_deg: np.ndarray) -> None:
        """Keep the grades ``read_deg`` (stations,) read for the body at ``points`` (stations, 2)
        heading ``heading`` (stations,) [rad], to be checked once the vehicle gets there."""
        i = self._next % KEPT_DECISIONS
        self._points[i], self._heading[i], self._read[i] = points, heading, read_deg
        self._next += 1
