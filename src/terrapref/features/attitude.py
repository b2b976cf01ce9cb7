"""The camera's attitude off its mount, read from where the label image's sky ends.

On rough ground the camera pitches and rolls, and a planner that projects every pixel with the
nominal mount places far ground metres off: at 6 m ahead, one degree of pitch moves the ground
seen by about 0.65 m. The segmentation shows where this happens: above a line across the image
the camera sees no ground (255: the sky, or ground beyond the network's range), and that line
moves with the camera's attitude, about 5.6 pixels per degree of pitch, and tilts with its roll.

:class:`HorizonAttitude` reads that line in a band of columns each frame, keeps a running
reference of where it lies (its median over recent frames: the mount's own line, whatever the
segmentation's range), and fits the frame's departure from it with the image motion of a small
pitch and roll (a rotation about the camera's x axis moves a pixel by -f (1 + y^2) rows per
radian; one about its optical axis by -(u - cx) rows and (v - cy) columns). A fit that fewer
than half the columns support (the map's edge, say, cutting the line short) gives no estimate.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from terrapref.camera import PinholeCamera, SegmentationView
from terrapref.terrain import UNKNOWN

REFERENCE_EVERY = 4  # frames between updates of the reference line (it moves slowly; its median is the costly part)


class HorizonAttitude:
    """Estimates a camera's pitch and roll off its mount from each label frame's sky line.

    Args:
        camera: the camera (its nominal mount).
        column_step_px: columns read, this far apart [px].
        row_step_px: rows read in the band, this far apart [px].
        band_deg: the band read reaches this far above and below the mount's horizon, measured
            as pitch [deg]; it holds the sky line at any attitude within it.
        memory: frames over which the reference line is the median.
        max_deg: estimates beyond this pitch or roll are not believed (0 instead) [deg].
    """

    def __init__(self, camera: PinholeCamera, column_step_px: int = 16, row_step_px: int = 2, band_deg: float = 10.0, memory: int = 200,
                 max_deg: float = 6.0) -> None:
        c = camera.config
        self.fx, self.fy, self.cx, self.cy = camera.fx, camera.fy, camera.cx, camera.cy
        horizon = camera.horizon_row()
        reach = self.fy * math.tan(math.radians(band_deg)) * 2.0
        top, bottom = max(0, int(horizon - reach)), min(c.height_px, int(horizon + reach) + 1)
        self.rows = np.arange(top, bottom, row_step_px)
        self.cols = np.arange(column_step_px // 2, c.width_px, column_step_px)
        self.index = (self.rows[:, None] * c.width_px + self.cols[None, :]).reshape(-1)
        self.index.flags.writeable = False
        self.memory = memory
        self.max_rad = math.radians(max_deg)
        self._u = self.cols + 0.5 - self.cx
        self._history: deque[np.ndarray] = deque(maxlen=memory)
        self._reference: np.ndarray | None = None
        self._frames = 0

    def reset(self) -> None:
        """Start a new run: forget the reference line."""
        self._history.clear()
        self._reference = None
        self._frames = 0

    def line(self, view: SegmentationView) -> np.ndarray:
        """The first row of each column read below which the camera sees ground (the next rows
        read mostly hold ground), (C,) float; NaN where the band holds none."""
        ground = (view.pixels(self.index).reshape(len(self.rows), len(self.cols)) != UNKNOWN).astype(np.int8)
        if len(self.rows) < 4:
            return np.full(len(self.cols), np.nan)
        run = ground[:-3] + ground[1:-2] + ground[2:-1] + ground[3:]  # ground among four rows read from here down
        starts = run >= 3
        found = starts.any(axis=0)
        first = np.where(found, self.rows[np.argmax(starts, axis=0)].astype(float), np.nan)
        return first

    def __call__(self, view: SegmentationView) -> tuple[float, float]:
        """(pitch [rad], more downward positive; roll [rad], as :meth:`PinholeCamera.tilted` takes it)
        of ``view``'s camera off its mount; (0, 0) until the reference holds five frames, and when
        the fit is not supported."""
        now = self.line(view)
        self._history.append(now)
        self._frames += 1
        if self._frames < 5:
            return 0.0, 0.0
        if self._reference is None or self._frames % REFERENCE_EVERY == 0 or self._frames < 2 * REFERENCE_EVERY:
            with np.errstate(all="ignore"):
                self._reference = np.nanmedian(np.stack(self._history), axis=0)
        return self._fit(now - self._reference, self._reference)

    def _fit(self, departure: np.ndarray, reference: np.ndarray) -> tuple[float, float]:
        """Least squares of the columns' departures [rows] against a small pitch's and roll's image
        motion at the reference line, twice: the second time without the columns that miss the
        first fit by more than 3 rows."""
        ok = np.isfinite(departure) & np.isfinite(reference)
        if ok.sum() < len(self.cols) // 2:
            return 0.0, 0.0
        y = (reference + 0.5 - self.cy) / self.fy
        slope = np.gradient(np.where(ok, reference, np.interp(self._u, self._u[ok], reference[ok])), self._u)
        # A pitch moves the line by -fy (1 + y^2) rows; a roll by -(u - cx) rows and (v - cy) columns,
        # which along a sloping line is a change of row of -(u - cx) - slope (v - cy).
        design = np.stack([-self.fy * (1.0 + y**2), -self._u - slope * (reference + 0.5 - self.cy)], axis=1)
        keep = ok.copy()
        for _ in range(2):
            if keep.sum() < len(self.cols) // 2:
                return 0.0, 0.0
            dp, dr = _least_squares(design[keep], departure[keep])
            keep = ok & (np.abs(design[:, 0] * dp + design[:, 1] * dr - np.where(ok, departure, 0.0)) <= 3.0)
        if not (abs(dp) <= self.max_rad and abs(dr) <= self.max_rad):
            return 0.0, 0.0
        return dp, dr


def _least_squares(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """The two coefficients x minimising |a x - b| for a (N, 2), by the normal equations with exactly
    rounded sums (math.fsum): the same bits on every CPU, where a LAPACK solver's may differ."""
    p, q = a[:, 0].tolist(), a[:, 1].tolist()
    r = b.tolist()
    pp, pq, qq = math.fsum(x * x for x in p), math.fsum(x * y for x, y in zip(p, q)), math.fsum(y * y for y in q)
    pr, qr = math.fsum(x * z for x, z in zip(p, r)), math.fsum(y * z for y, z in zip(q, r))
    det = pp * qq - pq * pq
    if not det > 1e-12 * max(pp * qq, 1e-300):
        return 0.0, 0.0
    return (qq * pr - pq * qr) / det, (pp * qr - pq * pr) / det
