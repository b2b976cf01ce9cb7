"""The offset rule's geometry: the candidate offsets, the stations read along the path, the
footprint, and the settings of the ground map it reads (:class:`OffsetGeometry`; the map's own
settings: terrapref.groundmap.settings.MapSettings, :attr:`OffsetGeometry.map`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from terrapref.groundmap.settings import MAX_MAP_CELLS, MapSettings
from terrapref.records import to_plain

MAX_COUNT = 10_000
"""The most offsets, stations or camera samples an offset geometry may have."""
MAP_FIELDS = tuple(f.name for f in fields(MapSettings) if f.name != "sample_half_width_m")
"""The ground map's settings this block holds (the map reads 8 m each side, MapSettings' default)."""


@dataclass(frozen=True)
class OffsetGeometry:
    """Geometry of the candidate offsets, what is read along them, and of the ground map behind them.

    The ``map_*`` and ``sample_*`` fields are the ground map's settings (:attr:`map`), kept in
    this block of the model file, where files have always held them.

    Attributes:
        max_offset_m: candidate offsets run from -max to +max [m].
        offset_step_m: spacing of the candidate offsets [m].
        stations_m: first and last station read along the path, from the vehicle's progress [m].
        station_step_m: spacing of the stations [m].
        half_width_m: half the footprint's width; 5 points across it [m].
        span_m: metres added to the on-path length in the detour's price (swerving in and out) [m].
        gap_m: gaps along the path shorter than this do not split a patch [m].
        map_resolution_m, map_half_size_m, sample_step_m, sample_range_m, map_range_m, map_fade,
            map_lethal_share, map_terrain_share, map_min_evidence, map_sky_attitude: the ground
            map's settings, with its defaults (MapSettings says what each is).
        intent_delay_s: a demonstrator's command is read as what it meant this long before (its
            reaction time) [s] ...
        intent_pursuit_m: ... and inverted through pure pursuit this far ahead along the path
            into the offset it was steering for [m] (terrapref.rules.offset.fit).
    """

    max_offset_m: float = 3.0
    offset_step_m: float = 0.2
    stations_m: tuple[float, float] = (-1.0, 11.0)
    station_step_m: float = 0.25
    half_width_m: float = 0.6
    span_m: float = 5.0
    gap_m: float = 1.0
    map_resolution_m: float = MapSettings.map_resolution_m
    map_half_size_m: float = MapSettings.map_half_size_m
    sample_step_m: float = MapSettings.sample_step_m
    sample_range_m: float = MapSettings.sample_range_m
    intent_delay_s: float = 0.2
    intent_pursuit_m: float = 2.5
    map_range_m: float = MapSettings.map_range_m
    map_fade: float = MapSettings.map_fade
    map_lethal_share: float = MapSettings.map_lethal_share
    map_terrain_share: float = MapSettings.map_terrain_share
    map_min_evidence: float = MapSettings.map_min_evidence
    map_sky_attitude: bool = MapSettings.map_sky_attitude

    def __post_init__(self) -> None:
        stations = self.stations_m
        if not (
            isinstance(stations, tuple)
            and len(stations) == 2
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in stations)
        ):
            raise ValueError("the offset geometry's stations_m must be two numbers [m], the first and last station read")
        positive = (
            self.max_offset_m,
            self.offset_step_m,
            self.station_step_m,
            self.half_width_m,
            self.map_resolution_m,
            self.map_half_size_m,
            self.sample_step_m,
            self.sample_range_m,
            self.intent_pursuit_m,
        )
        if not all(math.isfinite(v) and v > 0 for v in positive) or not (self.span_m >= 0 and self.gap_m >= 0 and self.intent_delay_s >= 0):
            raise ValueError("the offset geometry needs positive sizes and steps, and span_m, gap_m and intent_delay_s >= 0")
        if not self.map_half_size_m > self.sample_range_m + 1.0 or not self.stations_m[1] < self.sample_range_m:
            raise ValueError("the ground map must reach past the camera's sample range by more than 1 m, and that past the stations read")
        if not self.stations_m[0] < self.stations_m[1]:
            raise ValueError("the offset geometry's stations_m must run forward")
        counts = {
            "offsets": (self.max_offset_m / self.offset_step_m, MAX_COUNT),
            "stations": ((self.stations_m[1] - self.stations_m[0]) / self.station_step_m, MAX_COUNT),
            "camera samples": (self.sample_range_m / self.sample_step_m, MAX_COUNT),
            "ground-map cells a side": (2 * self.map_half_size_m / self.map_resolution_m, MAX_MAP_CELLS),
        }
        for what, (count, most) in counts.items():  # a size read from a file is bounded before anything is allocated by it
            if count > most:
                raise ValueError(f"the offset geometry's steps give {count:.3g} {what}; at most {most}")
        self.map  # noqa: B018 (the ground map's settings, checked by their own rules: terrapref.groundmap.settings)

    @property
    def map(self) -> MapSettings:
        """The settings of the ground map the offsets are read from (ground read 8 m each side of the vehicle)."""
        return MapSettings(**{name: getattr(self, name) for name in MAP_FIELDS})

    @property
    def offsets(self) -> np.ndarray:
        """Candidate lateral offsets (O,) [m], left positive, symmetric about 0."""
        n = round(self.max_offset_m / self.offset_step_m)
        return np.arange(-n, n + 1) * self.offset_step_m

    @property
    def stations(self) -> np.ndarray:
        """Stations (S,) [m] along the path from the vehicle's progress."""
        n = round((self.stations_m[1] - self.stations_m[0]) / self.station_step_m)
        return self.stations_m[0] + np.arange(n + 1) * self.station_step_m

    @property
    def footprint(self) -> np.ndarray:
        """Lateral positions (5,) [m] of the footprint's points about its centre line."""
        return np.linspace(-self.half_width_m, self.half_width_m, 5)

    def to_dict(self) -> dict:
        return to_plain(self)

    @classmethod
    def from_dict(cls, data: dict) -> OffsetGeometry:
        data = dict(data)
        if "intent_lookahead_m" in data and "intent_pursuit_m" not in data:  # its name in files before it was intent_pursuit_m
            data["intent_pursuit_m"] = data.pop("intent_lookahead_m")
        if "stations_m" in data:
            data["stations_m"] = tuple(data["stations_m"])
        return cls(**data)
