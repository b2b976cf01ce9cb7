"""The offsets' features: what driving beside the path at a lateral offset would cross.

A person facing a patch on the trail does not pick a 6 m arc; they pick a side and how far out
to hold it until the patch is behind them. The offset features describe exactly that choice.
For each candidate offset d (left positive) from the reference path, the footprint is laid
along the path shifted by d, over stations from just behind the vehicle to ``stations_m[1]``
ahead, and the ground under it is read from a :class:`GroundMap`: the camera's views, gathered
over the last frames, so that a patch the vehicle is already beside still counts.

Features per offset (:class:`OffsetFeatures`, shape (O, K + 2)):

- metres driven on each of the K terrain classes (footprint points averaged);
- metres over ground never seen;
- d^2 * (on-path length + ``span_m``): the price of a detour that lasts as long as the patch on
  the path, plus the swerves in and out;

and one gated column (:func:`gated`): d^2 while nothing lies on the path within the near
distance, so that a utility can learn to keep to the path until a patch is close. Only the
first patch on the path (gaps under ``gap_m`` do not split it) and ``span_m / 2`` beyond it
are weighed; later patches wait for their own turn.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from terrapref.groundmap.map import GroundMap
from terrapref.rules.offset import offsets_compiled as kernels
from terrapref.rules.offset.geometry import OffsetGeometry
from terrapref.scenario.path import ReferencePath


@dataclass(frozen=True)
class OffsetView:
    """The offset features at one frame.

    Attributes:
        features: per offset, metres on each terrain class, metres never seen and the detour's
            price, shape (O, K + 2).
        near_m: distance along the path to the first terrain on it [m] (inf: none in reach).
    """

    features: np.ndarray
    near_m: float


class OffsetFeatures:
    """Offset features (module docstring) read from a ground map along a path."""

    def __init__(self, config: OffsetGeometry, k: int) -> None:
        self.config, self.k = config, k
        self.offsets = config.offsets
        self.stations = config.stations
        self._lat = self.offsets[:, None] + config.footprint[None, :]  # (O, F)
        self._centre = int(np.argmin(np.abs(self.offsets)))
        self._gap = round(config.gap_m / config.station_step_m)
        self._beyond = round(config.span_m / 2 / config.station_step_m)

    def columns(self, gmap: GroundMap, path: ReferencePath, progress_m: float) -> np.ndarray:
        """Terrain column under every footprint point, shape (O, S, F)."""
        return gmap.beside(path, np.minimum(progress_m + self.stations, path.length_m), self._lat)

    def __call__(self, gmap: GroundMap, path: ReferencePath, progress_m: float) -> OffsetView:
        c = self.config
        features, near_m = kernels.offset_features(
            self.columns(gmap, path, progress_m),
            self._centre,
            self.k,
            self._gap,
            self._beyond,
            c.station_step_m,
            self.stations,
            self.offsets,
            c.span_m,
        )
        return OffsetView(features, float(near_m))


def gated(view: OffsetView, offsets: np.ndarray, near_m: float) -> np.ndarray:
    """The offsets' features with the gate column: d^2 while nothing is on the path within ``near_m``, (O, K + 3)."""
    gate = offsets**2 * float(view.near_m > near_m)
    return np.concatenate([view.features, gate[:, None]], axis=1)
