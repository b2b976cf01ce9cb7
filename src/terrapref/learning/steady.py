"""Labels from a shaky hand: separate the hand's tremor from its choices (``DataOptions.steady_labels``).

A demonstrated label is the trajectory whose yaw rate is nearest the recorded command w
(SPEC 6). A hand that trembles moves w by about its tremor every frame; once the tremor is
comparable to half the spacing of the control set's yaw rates, a large share of frames is
labelled with a neighbouring trajectory, and a swerve around a patch with a straight one, and
the planner learns the tremor as much as the choices.

The tremor is read from the drive itself: while the stick is deflected, frame-to-frame
changes of w are the hand's noise plus the rare deliberate moves, so a robust spread (the
median absolute deviation) of those changes, divided by sqrt(2), estimates the tremor's
standard deviation. When it exceeds half the grid's spacing, each label comes from a centred
moving average of w over :data:`WINDOW` frames (0.5 s at 10 Hz) within its recording: on
generated layouts this brought a shaky driver's planner from 79.1% to 85.9% agreement with
that driver, where 0.5 s averaging of a steady hand's labels cost a point (docs/learning.md).
A steadier hand keeps its labels as recorded, bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from terrapref.dataset import Dataset

_MAD_TO_STD = 1.4826  # a normal distribution's standard deviation per median absolute deviation
WINDOW = 5  # frames averaged for a shaky hand (0.5 s at 10 Hz: shorter than a deliberate swerve)


@dataclass(frozen=True)
class Steadying:
    """What :func:`steady_labels` found and did.

    Attributes:
        tremor_rps: the hand's estimated tremor, a standard deviation [rad/s] (NaN: too few
            deflected frames to tell).
        spacing_rps: the spacing of the control set's yaw rates [rad/s].
        window: frames in the moving average the labels came from (1: the recorded labels).
        changed: the share of labels that moved.
    """

    tremor_rps: float
    spacing_rps: float
    window: int
    changed: float

    def to_dict(self) -> dict:
        return {
            "tremor_rps": None if math.isnan(self.tremor_rps) else round(self.tremor_rps, 5),
            "spacing_rps": self.spacing_rps,
            "window": self.window,
            "changed": round(self.changed, 4),
        }

    def line(self) -> str:
        """One line for ``terrapref train``."""
        if math.isnan(self.tremor_rps):
            return "hand: too few deflected frames to estimate a tremor; labels as recorded"
        head = f"hand: tremor {self.tremor_rps:.3f} rad/s against a {self.spacing_rps:g} rad/s grid"
        if self.window == 1:
            return head + "; labels as recorded"
        return head + f"; labels from a {self.window}-frame moving average of w ({100 * self.changed:.0f}% of them moved)"


def hand_tremor(w: np.ndarray, source: np.ndarray) -> float:
    """The tremor's standard deviation [rad/s] from consecutive frames of the same recording
    where the stick is deflected (w != 0 in both); NaN with fewer than 20 such pairs."""
    w = np.asarray(w, dtype=np.float64)
    source = np.asarray(source)
    pairs = (source[1:] == source[:-1]) & (w[1:] != 0.0) & (w[:-1] != 0.0)
    if pairs.sum() < 20:
        return math.nan
    d = np.diff(w)[pairs]
    return float(_MAD_TO_STD * np.median(np.abs(d - np.median(d))) / math.sqrt(2.0))


def window_for(tremor: float, spacing: float) -> int:
    """Frames to average: 1 while the tremor is at most half the spacing (or unknown), else :data:`WINDOW`."""
    return 1 if math.isnan(tremor) or tremor <= spacing / 2 else WINDOW


def moving_average(w: np.ndarray, source: np.ndarray, window: int) -> np.ndarray:
    """Centred ``window``-frame average of ``w`` within each recording (runs of equal ``source``),
    its ends padded with their first and last values."""
    w = np.asarray(w, dtype=np.float64)
    out = w.copy()
    source = np.asarray(source)
    starts = np.flatnonzero(np.r_[True, source[1:] != source[:-1]])
    ends = np.r_[starts[1:], len(w)]
    half = window // 2
    for a, b in zip(starts, ends):
        run = w[a:b]
        padded = np.r_[np.repeat(run[0], half), run, np.repeat(run[-1], half)]
        out[a:b] = np.convolve(padded, np.full(window, 1.0 / window), mode="valid")
    return out


def steady_labels(dataset: Dataset) -> tuple[Dataset, Steadying]:
    """``dataset`` with labels from the hand's intent when its tremor is large (module doc); the
    dataset itself, unchanged, otherwise."""
    control = dataset.feature_config.preference.control
    grid = np.sort(np.asarray(control.w_rps, dtype=np.float64))
    spacing = float(np.min(np.diff(grid)))  # a control set has at least two yaw rates
    tremor = hand_tremor(dataset.w, dataset.source)
    window = window_for(tremor, spacing)
    if window == 1:  # includes an empty dataset (no tremor to read)
        return dataset, Steadying(tremor, spacing, 1, 0.0)
    labels = np.asarray(control.label_of(moving_average(dataset.w, dataset.source, window)), dtype=np.int64).reshape(len(dataset))
    changed = float(np.mean(labels != dataset.labels))
    return replace(dataset, labels=labels), Steadying(tremor, spacing, window, changed)
