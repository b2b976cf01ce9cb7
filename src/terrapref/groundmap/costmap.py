"""The learned preference as a costmap: what other planners (Nav2, MPPI, move_base) read.

The offset rule keeps a ground map of what the camera has shown (terrapref.rules.offset,
``GroundMap``): each cell holds a terrain class, ground that is none of them, or ground never
seen. The costmap prices every cell with the offset utility the model learned from the drive:
a class's price is what driving a metre on it costs against driving a metre on the background
(the weight the utility gives it, negated), so the cells keep the driver's order. Lethal classes
are lethal, ground never seen is unknown. Costs follow ``nav_msgs/OccupancyGrid``: 0 (the
background, or a class liked at least as well) to 99 (the dearest class), 100 lethal, -1
unknown.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from terrapref.groundmap.height import trusted_elevation

if TYPE_CHECKING:
    from terrapref.groundmap.map import GroundMap

LETHAL_COST = 100
UNKNOWN_COST = -1
MAX_COST = 99  # the dearest non-lethal class


@dataclass(frozen=True)
class Costmap:
    """A grid of costs in the frame the poses are given in (the odometry frame on a robot).

    Attributes:
        cost: (H, W) int8, row i at y = origin[1] + (i + 0.5) * resolution_m, column j at
            x = origin[0] + (j + 0.5) * resolution_m: 0-99 by learned price, 100 lethal, -1 never seen.
        resolution_m: the side of a cell [m].
        origin: the corner of cell (0, 0) [m].
        prices: each class's learned price per metre (against the background), by name; the
            costs are these scaled to 0-99.
        lethal: the classes among ``prices`` that are lethal (cost 100 whatever their price).
        layers: more layers over the same cells, (H, W) float32 each, NaN where unknown
            (:func:`with_layers`: ``speed`` [m/s], ``elevation`` [m], ``slope`` [rad],
            ``roughness`` [m], ``step`` [m]).
        top_speed_mps: the fastest the ``speed`` layer may say, the robot's top speed (Nav2's
            speed filter gives speeds in percent of it) [m/s]; None without a speed layer.
    """

    cost: np.ndarray
    resolution_m: float
    origin: tuple[float, float]
    prices: dict[str, float]
    lethal: frozenset[str] = frozenset()
    layers: Mapping[str, np.ndarray] = field(default_factory=dict)
    top_speed_mps: float | None = None

    def grid_layers(self) -> dict[str, np.ndarray]:
        """Every layer as float32 (H, W), NaN where unknown: ``cost`` (-1 unknown becomes NaN) and :attr:`layers`."""
        return {"cost": np.where(self.cost == UNKNOWN_COST, np.nan, self.cost).astype(np.float32), **self.layers}

    @property
    def price_per_cost(self) -> float:
        """The price per metre that one unit of cost stands for (the dearest non-lethal class's
        price over 99; 0 when no class is dearer than the background)."""
        top = max([p for name, p in self.prices.items() if name not in self.lethal and p > 0] or [0.0])
        return top / MAX_COST

    def cell_of(self, x: float, y: float) -> tuple[int, int] | None:
        """(row, column) of the cell holding (x, y) [m], or None off the grid."""
        j = int(np.floor((x - self.origin[0]) / self.resolution_m))
        i = int(np.floor((y - self.origin[1]) / self.resolution_m))
        h, w = self.cost.shape
        return (i, j) if 0 <= i < h and 0 <= j < w else None

    def at(self, x: float, y: float) -> int:
        """The cost at (x, y) [m]; unknown off the grid."""
        cell = self.cell_of(x, y)
        return UNKNOWN_COST if cell is None else int(self.cost[cell])


def class_costs(weights: np.ndarray, lethal: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The cost (K + 2,) int8 of each map cell value (K terrain columns, K: the background,
    K + 1: never seen) and the price per metre (K,) of each terrain column, from the offset
    utility's ``weights`` (K + 3,; the first K price a metre on each class, as utilities) and the
    ``lethal`` columns (K + 2,)."""
    prices = -np.asarray(weights[:k], dtype=float)
    costs = np.zeros(k + 2, dtype=np.int8)
    safe = ~lethal[:k]
    top = prices[safe].max() if safe.any() else 0.0
    if top > 0:
        costs[:k] = np.clip(np.round(MAX_COST * prices / top), 0, MAX_COST).astype(np.int8)
    costs[:k][lethal[:k]] = LETHAL_COST
    costs[k] = 0
    costs[k + 1] = UNKNOWN_COST
    return costs, prices


def costmap_of(
    cells: np.ndarray, origin: np.ndarray | None, resolution_m: float, weights: np.ndarray, lethal: np.ndarray, names: tuple[str, ...]
) -> Costmap:
    """The costmap of a ground map's ``cells`` (values 0..K + 1, rows along y) whose cell (0, 0)
    has its corner at ``origin`` (None: nothing seen yet, every cell unknown), cropped to the
    rectangle of cells seen; ``names``, the K terrain columns' classes."""
    k = len(names)
    costs, prices = class_costs(weights, lethal, k)
    grid = costs[cells] if origin is not None else np.full(cells.shape, UNKNOWN_COST, dtype=np.int8)
    corner = (float(origin[0]), float(origin[1])) if origin is not None else (0.0, 0.0)
    seen_rows, seen_cols = np.flatnonzero((grid != UNKNOWN_COST).any(axis=1)), np.flatnonzero((grid != UNKNOWN_COST).any(axis=0))
    if len(seen_rows):  # cropped to the ground seen: a map is mostly ground never seen, and a grid's size is what a message carries
        r0, r1, c0, c1 = seen_rows[0], seen_rows[-1] + 1, seen_cols[0], seen_cols[-1] + 1
        grid = grid[r0:r1, c0:c1]
        corner = (corner[0] + c0 * resolution_m, corner[1] + r0 * resolution_m)
    return Costmap(
        grid,
        float(resolution_m),
        corner,
        {n: float(p) for n, p in zip(names, prices, strict=True)},
        frozenset(n for n, is_lethal in zip(names, lethal[:k]) if is_lethal),
    )


GEOMETRY_LAYERS = ("elevation", "slope", "roughness", "step")


def with_layers(
    costmap: Costmap, ground_map: GroundMap, speeds_mps: np.ndarray | None, top_mps: float, shed: tuple[float, float] = (0.0, 0.0)
) -> Costmap:
    """``costmap`` (of ``ground_map``'s cells) with its other layers over the same cells: the
    ``speed`` [m/s] a speed rule drives each cell's column at (``speeds_mps``, (K + 2,): the K
    terrain columns, the background, NaN for ground never seen; 0 on lethal ground; None: no
    speed rule, no layer) up to the robot's ``top_mps``, and the height layer's ``elevation`` where trusted (terrapref.groundmap.height.trusted_elevation) with the ``slope``, ``roughness``
    and ``step`` read from it as the map's height settings say (terrapref.groundmap.height), NaN
    where unknown. ``shed``: the speed a speed rule sheds per degree of grade [m/s per deg], the
    more of up and down, and the least it slows to [m/s]; a cell's speed is then its column's
    less that for each degree of its slope (a limit whichever way the cell is crossed, as a speed
    filter reads its mask), down to the least."""
    h, w = costmap.cost.shape
    layers: dict[str, np.ndarray] = {}
    if ground_map.origin is None:
        for name in (("speed",) if speeds_mps is not None else ()) + GEOMETRY_LAYERS:
            layers[name] = np.full((h, w), np.nan, dtype=np.float32)
        return replace(costmap, layers=layers, top_speed_mps=top_mps if speeds_mps is not None else None)
    res = ground_map.settings.map_resolution_m
    r0 = int(round((costmap.origin[1] - float(ground_map.origin[1])) / res))
    c0 = int(round((costmap.origin[0] - float(ground_map.origin[0])) / res))
    rows, cols = np.mgrid[r0 : r0 + h, c0 : c0 + w]
    if speeds_mps is not None:
        layers["speed"] = np.asarray(speeds_mps, dtype=np.float32)[ground_map.cells[r0 : r0 + h, c0 : c0 + w]]
    layers["elevation"] = trusted_elevation(ground_map.heights, ground_map.height_settings, (slice(r0, r0 + h), slice(c0, c0 + w)))
    if np.isfinite(layers["elevation"]).any():
        geometry = ground_map.geometry_of(rows.ravel(), cols.ravel()).reshape(h, w, 3)
    else:
        geometry = np.full((h, w, 3), np.nan)
    for i, name in enumerate(GEOMETRY_LAYERS[1:]):
        layers[name] = geometry[..., i].astype(np.float32)
    per_deg, least_mps = shed
    if speeds_mps is not None and per_deg > 0.0:
        speed, slope = layers["speed"], np.degrees(geometry[..., 0])
        slowed = np.isfinite(slope) & (speed > 0)  # never-seen (NaN) and lethal (0) ground as they are
        shed = np.maximum(speed - per_deg * np.where(slowed, slope, 0.0), least_mps)  # down to the least, never above the column's
        layers["speed"] = np.where(slowed, np.minimum(speed, shed), speed).astype(np.float32)
    return replace(costmap, layers=layers, top_speed_mps=top_mps if speeds_mps is not None else None)


_CHEAP, _DEAR, _LETHAL = np.array([40, 200, 60]), np.array([230, 40, 30]), np.array([20, 20, 20])


def cost_colours(cost: np.ndarray) -> np.ndarray:
    """RGBA (..., 4) uint8 of costs, for a viewer: green (0) to red (99), lethal near-black,
    unknown transparent."""
    cost = np.asarray(cost)
    share = np.clip(cost, 0, MAX_COST)[..., None] / MAX_COST
    rgba = np.empty(cost.shape + (4,), dtype=np.uint8)
    rgba[..., :3] = np.round(_CHEAP + share * (_DEAR - _CHEAP)).astype(np.uint8)
    rgba[..., 3] = 160
    rgba[cost == LETHAL_COST] = (*_LETHAL, 230)
    rgba[cost == UNKNOWN_COST] = 0
    return rgba
