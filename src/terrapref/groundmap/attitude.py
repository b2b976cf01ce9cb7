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

import numpy as np

from terrapref.camera import PinholeCamera, PixelSet, SegmentationView
from terrapref.groundmap import attitude_compiled as kernels
from terrapref.terrain import UNKNOWN

REFERENCE_EVERY = 4  # frames between updates of the reference line (it moves slowly)


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

    def __init__(
        self,
        camera: PinholeCamera,
        column_step_px: int = 16,
        row_step_px: int = 2,
        band_deg: float = 10.0,
        memory: int = 200,
        max_deg: float = 6.0,
    ) -> None:
        c = camera.config
        self.fy, self.cx, self.cy = camera.fy, camera.cx, camera.cy
        horizon = camera.horizon_row()
        reach = self.fy * math.tan(math.radians(band_deg)) * 2.0
        top, bottom = max(0, int(horizon - reach)), min(c.height_px, int(horizon + reach) + 1)
        self.rows = np.arange(top, bottom, row_step_px)
        self._row_values = self.rows.astype(np.float64)
        self.cols = np.arange(column_step_px // 2, c.width_px, column_step_px)
        # The band's pixels, row by row, read every frame: their rows and columns worked out once.
        self._band = PixelSet((self.rows[:, None] * c.width_px + self.cols[None, :]).reshape(-1))
        self.memory = memory
        self.max_rad = math.radians(max_deg)
        self._u = self.cols + 0.5 - self.cx
        self._history = np.full((memory, len(self.cols)), np.nan)  # the last ``memory`` lines, a ring
        self._reference: np.ndarray | None = None
        self._frames = 0

    def reset(self) -> None:
        """Start a new run: forget the reference line."""
        self._history.fill(np.nan)
        self._reference = None
        self._frames = 0

    def line(self, view: SegmentationView) -> np.ndarray:
        """The first row of each column read below which the camera sees ground (at least 3 of it and
        the next 3 rows read are ground), (C,) float; NaN where the band holds none."""
        return kernels.sky_line(view.pixels(self._band), self.rows, len(self.cols), UNKNOWN)

    def __call__(self, view: SegmentationView) -> tuple[float, float]:
        """(pitch [rad], more downward positive; roll [rad], as :meth:`PinholeCamera.tilted` takes it)
        of ``view``'s camera off its mount; (0, 0) until the reference holds five frames, and when
        the fit is not supported."""
        now = self.line(view)
        self._history[self._frames % self.memory] = now
        self._frames += 1
        if self._frames < 5:
            return 0.0, 0.0
        if self._reference is None or self._frames % REFERENCE_EVERY == 0 or self._frames < 2 * REFERENCE_EVERY:
            self._reference = kernels.column_medians(self._history, min(self._frames, self.memory), self._row_values)
        return kernels.attitude_fit(now - self._reference, self._reference, self._u, self.fy, self.cy, self.max_rad)
