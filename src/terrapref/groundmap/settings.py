"""The ground map's settings: its size and resolution, the ground read from each image, and how
the votes decide a cell (:class:`MapSettings`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

MAX_MAP_CELLS = 4096
"""The most ground-map cells a side (640 by default: 64 m at 0.1 m)."""
MAX_SAMPLES = 10_000
"""The most camera samples along one line of a ground map's read (``sample_range_m / sample_step_m``)."""


@dataclass(frozen=True)
class MapSettings:
    """How a ground map is laid out and how it gathers the camera's views.

    The fields keep the names of the file block they are read from (the offset rule's
    ``geometry``, terrapref.rules.offset.geometry.OffsetGeometry), so that a name in a model file
    is the name in the code.

    Attributes:
        map_resolution_m: cell size [m].
        map_half_size_m: the map covers this much around its centre, each way [m].
        sample_step_m: spacing of the ground points read from each image [m].
        sample_range_m: ground read up to this far ahead of the camera [m].
        sample_half_width_m: ground read this far each side of the vehicle [m].
        map_range_m: a ground sample's vote weighs 1 / (1 + (r / map_range_m)^2) at r metres
            from the vehicle: near ground is seen sharper and placed better [m].
        map_fade: each frame a cell is not voted on, its evidence fades by this factor, so that
            recent views count more than old ones (0: the last view alone).
        map_lethal_share: a cell is lethal when lethal classes hold at least this share of its
            evidence ...
        map_terrain_share: ... else terrain (its class with the most evidence) when the K
            terrain classes hold at least this share, else background: a segmentation network
            misses a patch into the ground around it far more often than it sees a patch in plain
            ground, and a patch blurred over frames must not vanish into the ground around it
            (0.4 rather than a majority: a patch's edge cells stay the patch under the `field`
            preset's misses, so a detour keeps its width; docs/perception.md).
        map_min_evidence: a cell counts as seen once its evidence totals this much (a vote at
            0 m weighs 1), lethal or not: a far glimpse of a lethal class waits for the views
            that confirm or outvote it, and the stop rule keeps the vehicle off ground not yet
            seen within its stopping distance.
        map_sky_attitude: place the ground samples with the camera's pitch and roll off its mount
            as the sky line of each frame shows them (terrapref.groundmap.attitude), not with the
            mount's.
    """

    map_resolution_m: float = 0.1
    map_half_size_m: float = 32.0
    sample_step_m: float = 0.1
    sample_range_m: float = 14.0
    sample_half_width_m: float = 8.0
    map_range_m: float = 4.0
    map_fade: float = 0.97
    map_lethal_share: float = 0.35
    map_terrain_share: float = 0.4
    map_min_evidence: float = 0.0
    map_sky_attitude: bool = True

    def __post_init__(self) -> None:
        sizes = (self.map_resolution_m, self.map_half_size_m, self.sample_step_m, self.sample_range_m, self.sample_half_width_m)
        if not all(math.isfinite(v) and v > 0 for v in sizes):
            raise ValueError("the ground map needs positive sizes and steps")
        if not self.map_half_size_m > self.sample_range_m + 1.0:
            raise ValueError("the ground map must reach past the camera's sample range by more than 1 m")
        if 2 * self.map_half_size_m / self.map_resolution_m > MAX_MAP_CELLS or self.sample_range_m / self.sample_step_m > MAX_SAMPLES:
            raise ValueError(f"the ground map may have at most {MAX_MAP_CELLS} cells a side and {MAX_SAMPLES} samples along a line")
        if not (
            math.isfinite(self.map_range_m)
            and self.map_range_m > 0
            and 0 <= self.map_fade <= 1
            and 0 < self.map_lethal_share <= 1
            and 0 < self.map_terrain_share <= 1
            and 0 <= self.map_min_evidence < 1e3
        ):
            raise ValueError(
                "the ground map needs map_range_m > 0, map_fade in [0, 1], map_lethal_share and map_terrain_share in (0, 1] "
                "and map_min_evidence >= 0"
            )
        if not isinstance(self.map_sky_attitude, bool):  # a file's "false" would read as true
            raise ValueError(f"the ground map's map_sky_attitude must be true or false, got {self.map_sky_attitude!r}")
