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

On relief (a map that holds the ground's shape, read from depth), and for a utility that prices
it, each offset also has its relief columns (:meth:`OffsetFeatures.attitudes`): the metres over
which the body, heading along the path, would be rolled more than each of
:data:`RELIEF_BANDS_DEG` (the ground's slope across the way over the footprint's width), then
the metres over which it would be pitched more than each of them (its slope along the way over
the wheelbase). Weighed beside the terrain classes, the bands price each side slope and grade
the way a driver goes round them or not. Ground on the path steeper than the first band is a
patch on the path as terrain is, for the frames a fit reads; a fitted utility reads as a patch
only ground past the first band it prices (:attr:`OffsetSteering.steep_deg`): ground it prices
at nothing is no reason to leave the path, and counted as a patch it would lift the detour's
price there and leave the way to small differences between the terrain either side.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from terrapref.groundmap.map import GroundMap
from terrapref.rules.offset import offsets_compiled as kernels
from terrapref.rules.offset.geometry import OffsetGeometry
from terrapref.scenario.path import ReferencePath
from terrapref.vehicle import VehicleConfig

RELIEF_BANDS_DEG = (4.0, 6.0, 8.0, 10.0, 12.0, 14.0, 16.0, 18.0, 20.0, 22.0)
"""The side slopes and grades [deg] past which the relief columns count the metres of the way."""
BANDS = np.asarray(RELIEF_BANDS_DEG)
"""The same bands as an array, as the compiled count of the relief columns reads them."""
FIRST_BAND = (RELIEF_BANDS_DEG[0], RELIEF_BANDS_DEG[0])
"""Side slope and grade [deg] past which ground on the path is a patch on it, in the frames a fit reads."""
WHEELBASE_M = VehicleConfig.wheelbase_m
"""The body's wheelbase the relief columns read its pitch over [m] (the default vehicle's)."""


@dataclass(frozen=True)
class OffsetView:
    """The offset features at one frame.

    Attributes:
        features: per offset, metres on each terrain class, metres never seen and the detour's
            price, shape (O, K + 2).
        near_m: distance along the path to the first terrain (or steep ground) on it [m] (inf:
            none in reach).
        relief: per offset, the metres sloping across the way past each band, then along it
            (O, 2 * len(RELIEF_BANDS_DEG)); None where relief was not read.
    """

    features: np.ndarray
    near_m: float
    relief: np.ndarray | None = None


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
        # The body's chord along (half the wheelbase) and across (half the footprint), in stations and offsets,
        # and the lattice its attitude is read on: the stations and offsets, that many more at each end.
        along, across = self._chord = (round(WHEELBASE_M / 2 / config.station_step_m), round(config.half_width_m / config.offset_step_m))
        step = config.station_step_m
        behind_and_at = np.concatenate([self.stations[0] - step * np.arange(along, 0, -1), self.stations])
        self._lattice_stations = np.concatenate([behind_and_at, behind_and_at[-1] + step * np.arange(1, along + 1)])
        beyond = config.offset_step_m * np.arange(1, across + 1)
        self._lattice_offsets = np.concatenate([self.offsets[0] - beyond[::-1], self.offsets, self.offsets[-1] + beyond])
        self._level = np.zeros(len(self.stations), dtype=np.bool_)  # no steep ground: flat, or relief not read

    def columns(self, gmap: GroundMap, path: ReferencePath, progress_m: float) -> np.ndarray:
        """Terrain column under every footprint point, shape (O, S, F)."""
        return gmap.beside(path, np.minimum(progress_m + self.stations, path.length_m), self._lat)

    def attitudes(self, gmap: GroundMap, path: ReferencePath, progress_m: float) -> np.ndarray:
        """The side slope and the grade [deg] (O, S, 2) of the ground under the body at every
        offset and station, heading along the path: the ground's gradient across the way averaged
        over the footprint's width, along it over the wheelbase (:data:`WHEELBASE_M`), as the
        heights under its wheels would tilt it; NaN where the map does not know them."""
        centre, direction = path.frames_at(progress_m + self._lattice_stations)
        normal = np.stack([-direction[:, 1], direction[:, 0]], axis=1)
        return gmap.beside_attitudes(centre, normal, self._lattice_offsets, self._chord)

    def __call__(
        self, gmap: GroundMap, path: ReferencePath, progress_m: float, relief: bool = False, steep_deg: tuple[float, float] = FIRST_BAND
    ) -> OffsetView:
        """The features at ``progress_m`` [m] along ``path``, with the relief columns when ``relief``;
        ground on the path sloping across it past ``steep_deg[0]`` or along it past ``steep_deg[1]``
        [deg] is a patch on it (``near_m``)."""
        c = self.config
        attitudes = self.attitudes(gmap, path, progress_m) if relief else None
        steep = self._level if attitudes is None else (attitudes[self._centre] > np.asarray(steep_deg)).any(axis=1)
        features, near_m, upto = kernels.offset_features(
            self.columns(gmap, path, progress_m),
            steep,
            self._centre,
            self.k,
            self._gap,
            self._beyond,
            c.station_step_m,
            self.stations,
            self.offsets,
            c.span_m,
        )
        if attitudes is None:
            return OffsetView(features, float(near_m))
        return OffsetView(features, float(near_m), kernels.relief_metres(attitudes, upto, BANDS, c.station_step_m))


def gated(view: OffsetView, offsets: np.ndarray, near_m: float) -> np.ndarray:
    """The offsets' features with the gate column: d^2 while nothing is on the path within ``near_m``, (O, K + 3)."""
    gate = offsets**2 * float(view.near_m > near_m)
    return np.concatenate([view.features, gate[:, None]], axis=1)
