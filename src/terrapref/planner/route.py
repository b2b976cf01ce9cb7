"""A global route over a prior map, priced as the model learned: higher-level planning.

The local planner keeps within a few metres of its reference path; a wide patch the driver would
go round, the way round lying farther out than the offsets it weighs, it can only cross. A
route planned over a prior map of the course (the scenario's terrain here, standing in for
labelled aerial imagery on a robot) moves the reference path itself.

The route is the least-cost way from the path's start to its end through the costmap of that
map (:mod:`terrapref.groundmap.costmap`: the learned per-class prices, lethal classes lethal) with
the price the model learned for leaving the path: the offset utility prices a metre on class
k at ``-w_k`` and an offset of d metres held for L metres of path at ``-w_detour * d^2 * (L +
span)``, the span standing for swerving out and back. So a metre of route at distance d from
the reference path costs ``price(cell) - w_detour * d^2``, and a step from distance d1 to d2
costs ``-w_detour * span / 2 * |d2^2 - d1^2|`` more (out to d and back: the span's share).
A cell's price is the mean over the vehicle's footprint across it; a cell whose centre lies
within half the vehicle's width plus a margin of lethal terrain, or of the map's edge, is not
entered, at any cell size. On a map with relief, ground past the vehicle's limits (a slope it
may not tilt to, a step it does not climb: :func:`past_limits`) is lethal terrain too. The search
is Dijkstra's over the 8-connected grid (networkx).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from terrapref.groundmap.costmap import LETHAL_COST, MAX_COST, UNKNOWN_COST, Costmap
from terrapref.groundmap.height import GeometryLimits, HeightSettings
from terrapref.groundmap.settings import MapSettings
from terrapref.scenario.path import ReferencePath
from terrapref.vehicle import VehicleConfig

if TYPE_CHECKING:
    from terrapref.planner.model import Model
    from terrapref.scenario import Scenario
    from terrapref.world import WorldMap

_LENGTH_PRICE = 0.01  # per metre of route on the cheapest ground: among equal routes, the shortest


@dataclass(frozen=True)
class RouteConfig:
    """How the route is searched.

    Attributes:
        resolution_m: the side of a search cell [m].
        half_width_m: half the vehicle's width; a cell's price is the mean across it [m].
        lethal_margin_m: clearance kept from lethal terrain beyond the half width [m].
        band_m: the search keeps within this distance of the reference path [m].
        spacing_m: spacing of the waypoints written [m].
    """

    resolution_m: float = 0.25
    half_width_m: float = 0.6
    lethal_margin_m: float = 0.3
    band_m: float = 12.0
    spacing_m: float = 1.0

    def __post_init__(self) -> None:
        values = (self.resolution_m, self.half_width_m, self.lethal_margin_m, self.band_m, self.spacing_m)
        if (
            not all(math.isfinite(v) for v in values)
            or min(self.resolution_m, self.band_m, self.spacing_m) <= 0
            or min(self.half_width_m, self.lethal_margin_m) < 0
        ):
            raise ValueError("a route needs resolution_m, band_m and spacing_m > 0, half_width_m and lethal_margin_m >= 0")


@dataclass(frozen=True)
class Route:
    """A route and what it costs.

    Attributes:
        waypoints: (N, 2) [m], ``spacing_m`` apart, from the path's start to its end.
        cost: its price in the learned utility's units (a metre on the background at the
            path costs about ``_LENGTH_PRICE``).
        along_path_cost: the price of driving the reference path itself (inf: it meets lethal
            terrain or leaves the map).
        max_offset_m: the farthest the route runs from the reference path [m].
        cell_m: the side of the search cells [m] (the resolution asked for, as a whole
            multiple of the map's).
    """

    waypoints: np.ndarray
    cost: float
    along_path_cost: float
    max_offset_m: float
    cell_m: float = 0.0

    @property
    def length_m(self) -> float:
        return float(np.linalg.norm(np.diff(self.waypoints, axis=0), axis=1).sum())


class RouteError(ValueError):
    """No route: the path's start or end cannot be entered, or lethal terrain cuts them apart."""


def route_over(scenario: Scenario, model: Model, config: RouteConfig | None = None, world: WorldMap | None = None) -> Route:
    """The route along ``scenario``'s path over its map (the prior; ``world``, its raster, when
    the caller has it), priced as ``model``'s driving rule learned: its class prices and price of
    leaving the path (:meth:`terrapref.rules.SteeringRunner.route_prices`).

    Raises:
        ValueError: the model's driving rule learned no prices to route with.
        RouteError: no route (module docstring).
    """
    from terrapref.world import rasterise

    planner = model.planner()
    prices = planner.runner.route_prices()
    if prices is None:
        raise ValueError(
            f"drives by rule {planner.rule.type}, which learned no prices of the ground to route with (train with recipe teach)"
        )
    world = world if world is not None else rasterise(scenario)
    costmap = prices.prior(world)
    if world.height is not None:  # ground past the vehicle's limits is lethal, as the planner's map blocks it
        limits = GeometryLimits.of(VehicleConfig())
        past = past_limits(world.height, world.resolution_m, limits)
        costmap = replace(costmap, cost=np.where(past, np.int8(LETHAL_COST), costmap.cost))
    return plan_route(costmap, ReferencePath(scenario.waypoints), prices.detour_price, prices.span_m, config=config)


def past_limits(height: np.ndarray, resolution_m: float, limits: GeometryLimits) -> np.ndarray:
    """Which cells of a prior map's ``height`` (H, W) [m, cells ``resolution_m`` wide] are past
    the vehicle's ``limits``, read as the planner's height layer reads the ground, in cells of
    its map's size (the prior's heights averaged within each): a slope steeper than the vehicle
    may tilt (the chords across the cell over the height layer's radius each way, along x and
    along y: it may cross the cell in any heading), or a step higher than it climbs (the height's
    range over the cell and its eight neighbours)."""
    factor = max(1, round(MapSettings().map_resolution_m / resolution_m))
    h, w = (n // factor * factor for n in height.shape)
    cell = resolution_m * factor
    blocks = height[:h, :w].astype(np.float64).reshape(h // factor, factor, w // factor, factor).mean(axis=(1, 3))
    k = max(1, round(HeightSettings().radius_m / cell))
    edge = np.pad(blocks, k, mode="edge")
    bh, bw = blocks.shape
    gx = (edge[k : k + bh, 2 * k :] - edge[k : k + bh, :bw]) / (2 * k * cell)
    gy = (edge[2 * k :, k : k + bw] - edge[:bh, k : k + bw]) / (2 * k * cell)
    near = np.lib.stride_tricks.sliding_window_view(edge[k - 1 : k + bh + 1, k - 1 : k + bw + 1], (3, 3))  # (bh, bw, 3, 3)
    past = (np.arctan(np.hypot(gx, gy)) > limits.max_slope_rad) | (near.max(axis=(2, 3)) - near.min(axis=(2, 3)) > limits.max_step_m)
    out = np.zeros(height.shape, dtype=bool)
    out[:h, :w] = np.repeat(np.repeat(past, factor, axis=0), factor, axis=1)
    return out


def routed_scenario(scenario: Scenario, route: Route, by: str) -> dict:
    """``scenario`` as a terrapref-scenario/1 mapping whose path is ``route``, planned with the
    model named ``by``."""
    data = scenario.to_dict()
    data["name"] = f"{scenario.name}_route"
    data["description"] = f"{scenario.name} with its path replaced by the route {by} prices lowest"
    data["path"] = {"waypoints": np.round(route.waypoints, 3).tolist()}
    return data


def coarsened(costmap: Costmap, resolution_m: float) -> Costmap:
    """``costmap`` in cells of the whole multiple of its own nearest ``resolution_m``: each the
    mean of the costs within, lethal (or unknown) when any cell within is."""
    factor = max(1, round(resolution_m / costmap.resolution_m))
    if factor == 1:
        return costmap
    h, w = (n // factor for n in costmap.cost.shape)
    blocks = costmap.cost[: h * factor, : w * factor].reshape(h, factor, w, factor).astype(np.int16)
    cost = np.round(blocks.clip(0, MAX_COST).mean(axis=(1, 3))).astype(np.int8)
    cost[(blocks == UNKNOWN_COST).any(axis=(1, 3))] = UNKNOWN_COST
    cost[(blocks == LETHAL_COST).any(axis=(1, 3))] = LETHAL_COST
    return Costmap(cost, costmap.resolution_m * factor, costmap.origin, costmap.prices, costmap.lethal)


def plan_route(costmap: Costmap, path: ReferencePath, detour_price: float, span_m: float = 0.0, config: RouteConfig | None = None) -> Route:
    """The least-cost route along ``path`` through ``costmap`` (module docstring); ``detour_price``
    the price of a metre held d metres off the path, per d^2 (the model's ``-w_detour``), and
    ``span_m`` the metres of path a swerve out and back adds to a detour's length."""
    import networkx as nx

    config = config or RouteConfig()
    grid = coarsened(costmap, config.resolution_m)
    res = grid.resolution_m
    h, w = grid.cost.shape
    centres = np.stack(np.meshgrid(grid.origin[0] + (np.arange(w) + 0.5) * res, grid.origin[1] + (np.arange(h) + 0.5) * res), axis=-1)
    d = path.distance_to(centres.reshape(-1, 2)).reshape(h, w)
    alpha = max(detour_price, 0.0)
    price = _footprint_price(grid, config) + alpha * d**2 + _LENGTH_PRICE
    price[(d > config.band_m) | _blocked(grid, config)] = np.inf
    start, goal = (grid.cell_of(*path.point_at(s)) for s in (0.0, path.length_m))
    for name, cell in (("start", start), ("end", goal)):
        if cell is None or not np.isfinite(price[cell]):
            raise RouteError(
                f"the path's {name} is off the map or within {config.half_width_m + config.lethal_margin_m:.1f} m "
                "of lethal terrain (on relief, or of ground past the vehicle's limits) or of the map's edge"
            )
    if start == goal:
        raise RouteError(f"the path ends in the search cell it starts in ({res:g} m): there is no way to plan between them")
    graph = nx.Graph()
    graph.add_weighted_edges_from(_edges(price, alpha * span_m / 2 * d**2, res))
    try:
        cells = nx.dijkstra_path(graph, start[0] * w + start[1], goal[0] * w + goal[1])
    except (nx.NetworkXNoPath, nx.NodeNotFound):
        raise RouteError(
            "lethal terrain (on relief, or ground past the vehicle's limits: a slope or a step it cannot cross) "
            "cuts the path's start from its end on this map"
        ) from None
    rows, cols = np.divmod(np.asarray(cells), w)
    points = centres[rows, cols]
    points[0], points[-1] = path.point_at(0.0), path.point_at(path.length_m)
    waypoints = ReferencePath(points).resampled(config.spacing_m)[0]
    along = path.resampled(res)[0]
    return Route(waypoints, _cost_of(points, price, grid), _cost_of(along, price, grid), float(d[rows, cols].max()), res)


def _footprint_price(grid: Costmap, config: RouteConfig) -> np.ndarray:
    """Each cell's price per metre: the costs' prices averaged over a disc of the half width."""
    price = np.where((grid.cost >= 0) & (grid.cost <= MAX_COST), grid.cost, 0).astype(float) * grid.price_per_cost
    return _disc_mean(price, config.half_width_m / grid.resolution_m)


def _blocked(grid: Costmap, config: RouteConfig) -> np.ndarray:
    """Cells the vehicle's centre may not enter: those whose centre lies within the half width
    and margin of any point of a cell of lethal terrain, of ground the map does not hold, or
    beyond the map's edge. Measured to the nearest point of such a cell, not to its centre, so
    that the clearance holds at any cell size: a search cell is lethal when any of the map's
    cells within it is (:func:`coarsened`), and the lethal cell may lie at its near side."""
    bad = (grid.cost == LETHAL_COST) | (grid.cost == UNKNOWN_COST)
    reach = (config.half_width_m + config.lethal_margin_m) / grid.resolution_m  # in cells
    r = math.ceil(reach + 0.5)
    h, w = bad.shape
    padded = np.pad(bad, r, mode="constant", constant_values=True)
    out = bad.copy()
    for i in range(-r, r + 1):
        for j in range(-r, r + 1):
            if math.hypot(max(abs(i) - 0.5, 0.0), max(abs(j) - 0.5, 0.0)) < reach:
                out |= padded[r + i : r + i + h, r + j : r + j + w]
    return out


def _disc_mean(a: np.ndarray, radius_cells: float) -> np.ndarray:
    """The mean of ``a`` over a disc of ``radius_cells`` around each cell; beyond the edges, the nearest cell's value."""
    r = int(math.floor(radius_cells))
    if r == 0:
        return a.copy()
    offsets = [(i, j) for i in range(-r, r + 1) for j in range(-r, r + 1) if i * i + j * j <= radius_cells**2 + 1e-9]
    padded = np.pad(a, r, mode="edge")
    h, w = a.shape
    return sum(padded[r + i : r + i + h, r + j : r + j + w] for i, j in offsets) / len(offsets)


def _edges(price: np.ndarray, potential: np.ndarray, res: float):
    """(node, node, weight) of every step between neighbouring enterable cells (8-connected):
    the step's length times the mean price of its two cells, plus the change of ``potential``
    between them (the swerve's price)."""
    h, w = price.shape
    ids = np.arange(h * w).reshape(h, w)
    for di, dj in ((0, 1), (1, 0), (1, 1), (1, -1)):
        a = (slice(0, h - di), slice(max(0, -dj), w - max(0, dj)))
        b = (slice(di, h), slice(max(0, dj), w + min(0, dj)))
        weight = res * math.hypot(di, dj) * 0.5 * (price[a] + price[b]) + np.abs(potential[a] - potential[b])
        ok = np.isfinite(weight)
        yield from zip(ids[a][ok].tolist(), ids[b][ok].tolist(), weight[ok].tolist())


def _cost_of(points: np.ndarray, price: np.ndarray, grid: Costmap) -> float:
    """The price of driving through ``points`` (N, 2) [m]: each step's length times the price
    of the cell it starts in (inf where that cell cannot be entered)."""
    cells = [grid.cell_of(float(x), float(y)) for x, y in points[:-1]]
    steps = np.linalg.norm(np.diff(points, axis=0), axis=1)
    return float(sum(step * (price[c] if c is not None else np.inf) for c, step in zip(cells, steps)))
