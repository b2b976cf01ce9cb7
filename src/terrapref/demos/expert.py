"""The synthetic demonstrator: a stand-in for a human driver (SPEC 10).

It drives the way a person with a gamepad does, not the way an optimal planner does:

- It looks along the reference path only ``reaction_distance_m`` ahead (a person reacts to a
  patch a few seconds away, not to the whole map), so that when it starts to turn, the reason
  is already on the planner's trajectories (SPEC 15: a clairvoyant driver teaches nothing).
- Within that window it picks one lateral offset from the path ("I'll pass left of the
  puddle"), trading the terrain its 1.2 m wide footprint would cross, costed by its preference
  profile, against a quadratic cost of leaving the path. It never re-plans into a circle: it
  always commits to a side and drives forward. An offset whose way there, as its own hand
  would steer it from where it is now, runs over lethal terrain costs as much as lethal
  terrain on the offset's line: late in front of a patch it keeps to the side it is on rather
  than cut across the patch to the other.
- It steers toward the offset path by pure pursuit, through a stick that rests at exactly zero
  when no correction is needed, moves at a limited rate, lags by a reaction delay, and shakes a
  little only while it is deflected.
- Its speed style (SPEC 18) sets the throttle: a cruising speed per class, the slowest of the
  classes its footprint meets on its way over the next ``preview_m``; no faster in a bend than
  its lateral-acceleration limit allows; slower still while lethal terrain lies near that way.
  The throttle lags by the same reaction delay as the stick. The default driver keeps 1 m/s
  everywhere (the paper's).
- Its relief style (SPEC 19, terrapref.demos.relief_style), when it has one, prices ground
  steeper than it takes above any terrain class, so it goes round a bank or a steep ramp where
  it can, and slows on grades and rough ground; without one it drives relief as if it were flat.

It reads the map (privileged knowledge) and never uses the planner's feature pipeline.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from terrapref.demos.relief_style import ReliefSight, ReliefStyle
from terrapref.records import to_plain
from terrapref.registry import Registry
from terrapref.scenario import Scenario
from terrapref.scenario.path import PathTracker, ReferencePath
from terrapref.sim.loop import Frame
from terrapref.sums import numpy_sum
from terrapref.terrain import UNKNOWN, ClassTable, PreferenceProfile
from terrapref.vehicle import MIN_CRUISE_MPS, Command, VehicleConfig, pure_pursuit_yaw_rate, wrap_angle
from terrapref.world import WorldMap, rasterise


@dataclass(frozen=True)
class ExpertConfig:
    """Parameters of the synthetic driver.

    Attributes:
        profile: preferred feature classes, best first (the background class beats all).
        speed_mps: cruising speed on the background class and on every class given no speed of
            its own [m/s].
        speeds: cruising speed per class, by class name [m/s].
        ranked_speeds_mps: the feature classes' cruising speeds from the most preferred class to
            the least, evenly between (a style that names no classes, for any class table);
            ``speeds`` wins for a class it names [m/s].
        lateral_accel_mps2: the lateral acceleration it keeps to in bends, v^2 * curvature;
            None: no limit [m/s^2].
        preview_m: how far ahead on its way it slows for a slower class [m].
        near_lethal_mps: its speed while lethal terrain lies within ``near_lethal_m`` of its
            footprint on the way ahead; None: it does not slow for it [m/s].
        near_lethal_m: see ``near_lethal_mps`` [m].
        reaction_distance_m: terrain on the path closer than this ahead triggers a detour [m].
        decision_extent_m: once triggered, the detour is planned over terrain this much
            further ahead too, so that the whole patch, not its near edge, is weighed [m].
        lookbehind_m: terrain this far behind the vehicle still holds the detour (the body) [m].
        half_width_m: half the vehicle's footprint width [m].
        margin_m: terrain this close beside the footprint costs as if half of it were driven on,
            so that the driver gives patches a wider berth (0: off) [m].
        lethal_margin_m: extra clearance kept from lethal terrain [m].
        max_offset_m: largest lateral offset considered [m].
        offset_step_m: resolution of the candidate offsets [m].
        deviation_cost: cost per metre of detour per square metre of offset [1/m^2].
        rank_cost: terrain cost per metre of the most preferred class; each later class in
            the profile costs ``rank_growth`` times more; lethal classes cost ``lethal_cost``.
        switch_margin: a new offset must be this much cheaper (relative) to replace the held one.
        pursuit_m: pure pursuit's pursuit distance: how far along the path it aims [m].
        max_yaw_rate_rps: stick range [rad/s].
        stick_rate_rps2: how fast the stick can move [rad/s per s].
        deadzone_rps: corrections below this leave the stick at zero [rad/s].
        reaction_delay_s: delay between seeing and the stick moving [s].
        stick_noise_rps: std of the hand's tremor while the stick is deflected [rad/s].
        relief: how it takes relief (terrapref.demos.relief_style); None: it drives as if the
            ground were flat, as the paper's driver does.
    """

    profile: tuple[str, ...] = ("mud", "rock", "water", "non_traversable")
    speed_mps: float = 1.0
    speeds: tuple[tuple[str, float], ...] = ()
    ranked_speeds_mps: tuple[float, float] | None = None
    lateral_accel_mps2: float | None = None
    preview_m: float = 3.0
    near_lethal_mps: float | None = None
    near_lethal_m: float = 1.0
    reaction_distance_m: float = 5.0
    decision_extent_m: float = 6.0
    lookbehind_m: float = 1.0
    half_width_m: float = 0.6
    margin_m: float = 0.0
    lethal_margin_m: float = 0.4
    max_offset_m: float = 8.0
    offset_step_m: float = 0.2
    deviation_cost: float = 0.08
    rank_cost: float = 1.0
    rank_growth: float = 1.5
    lethal_cost: float = 1000.0
    switch_margin: float = 0.15
    pursuit_m: float = 2.5
    max_yaw_rate_rps: float = 1.0
    stick_rate_rps2: float = 4.0
    deadzone_rps: float = 0.06
    reaction_delay_s: float = 0.2
    stick_noise_rps: float = 0.02
    relief: ReliefStyle | None = None

    def __post_init__(self) -> None:
        speeds = [self.speed_mps, *(v for _, v in self.speeds), *(self.ranked_speeds_mps or ())]
        speeds += [self.near_lethal_mps] if self.near_lethal_mps is not None else []
        if not all(_positive(v) for v in speeds):
            raise ValueError(f"cruising speeds must be finite and > 0 m/s, got {speeds}")
        if self.lateral_accel_mps2 is not None and not _positive(self.lateral_accel_mps2):
            raise ValueError(f"lateral_accel_mps2 must be None or finite and > 0, got {self.lateral_accel_mps2!r}")
        if not (_positive(self.preview_m) and math.isfinite(self.near_lethal_m) and self.near_lethal_m >= 0):
            raise ValueError(f"preview_m must be > 0 and near_lethal_m >= 0, got {self.preview_m!r} and {self.near_lethal_m!r}")

    def to_dict(self) -> dict:
        return to_plain(self, omit_none=("relief",))

    @property
    def steady(self) -> bool:
        """Whether it keeps ``speed_mps`` everywhere (no speed style)."""
        return not self.speeds and self.ranked_speeds_mps is None and self.lateral_accel_mps2 is None and self.near_lethal_mps is None

    @classmethod
    def styled(
        cls,
        style: str = "default",
        profile: tuple[str, ...] | None = None,
        speeds: tuple[tuple[str, float], ...] = (),
        changes: Mapping[str, Any] | Sequence[tuple[str, Any]] = (),
    ) -> ExpertConfig:
        """The driver of a named style (:data:`STYLES`) with a preference ``profile``, other fields
        over its style's (``changes``: a style file's) and ``speeds`` by class over those; an
        unknown style is a ValueError listing the styles."""
        base = cls() if profile is None else cls(profile=tuple(profile))
        return replace(base, **{**STYLES[style].changes, **dict(changes)}).with_speeds(speeds)

    def with_speeds(self, speeds: tuple[tuple[str, float], ...]) -> ExpertConfig:
        """This driver with ``speeds`` by class over its own (the classes not named keep theirs)."""
        return replace(self, speeds=tuple({**dict(self.speeds), **dict(speeds)}.items())) if speeds else self

    def speed_table(self, classes: ClassTable) -> np.ndarray:
        """Cruising speed [m/s] per class id (256,): NaN for lethal classes and ids the table does
        not name (the driver does not slow for what it never drives on); a ValueError for a
        class in ``speeds`` the table does not have."""
        table = np.full(256, np.nan)
        for c in classes.classes:
            table[c.id] = self.speed_mps
        order = PreferenceProfile.parse(list(self.profile), classes, source="expert.profile").order
        ranked = [name for name in order if name in classes.terrain_names]
        if self.ranked_speeds_mps is not None and ranked:
            fast, slow = self.ranked_speeds_mps
            for rank, name in enumerate(ranked):
                table[classes.id_of(name)] = fast + (slow - fast) * (rank / max(len(ranked) - 1, 1))
        for name, v in self.speeds:
            if name not in classes.names:
                raise ValueError(f"speeds: class {name!r} is not in the class table ({', '.join(classes.names)})")
            table[classes.id_of(name)] = v
        table[list(classes.lethal_ids)] = np.nan
        return table


def _positive(x: object) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) and x > 0


class Style(NamedTuple):
    """A driver style: the default driver with a few parameters changed.

    Attributes:
        description: what sets this driver apart, in words.
        changes: the :class:`ExpertConfig` fields that differ from the default driver's.
    """

    description: str
    changes: dict[str, Any]


def _style(name: str, description: str, **changes: Any) -> None:
    STYLES.register(name, Style(description, changes), doc=description)


# Driver styles: different people, not only different orders; `terrapref record --style NAME`.
STYLES: Registry[Style] = Registry("driver style", "styles")
_style("default", "reacts 5 m ahead, 0.6 m half-width, 0.4 m extra from lethal terrain; 1 m/s everywhere (the paper's driver)")
_style(
    "wide",
    "keeps wider margins: terrain within 0.5 m beside it costs half as if driven on, 0.8 m extra from lethal terrain; "
    "cautious: 1.2 m/s on open ground, 0.9 to 0.5 m/s on patches by preference, 0.6 m/s^2 in bends, 0.6 m/s near lethal terrain",
    margin_m=0.5,
    lethal_margin_m=0.8,
    speed_mps=1.2,
    ranked_speeds_mps=(0.9, 0.5),
    lateral_accel_mps2=0.6,
    near_lethal_mps=0.6,
    preview_m=4.0,
)
_style(
    "late",
    "reacts later: terrain on the path 3.5 m ahead, not 5 m; a slower hand (0.35 s); "
    "brisk: 1.8 m/s on open ground, 1.3 to 0.7 m/s on patches, 1.2 m/s^2 in bends, slows 2 m before a patch",
    reaction_distance_m=3.5,
    reaction_delay_s=0.35,
    speed_mps=1.8,
    ranked_speeds_mps=(1.3, 0.7),
    lateral_accel_mps2=1.2,
    preview_m=2.0,
)
_style(
    "shaky",
    "a shakier hand: 0.08 rad/s of tremor while the stick is deflected, a wider deadzone; "
    "1.4 m/s on open ground, 1.0 to 0.5 m/s on patches, 0.8 m/s^2 in bends",
    stick_noise_rps=0.08,
    deadzone_rps=0.1,
    speed_mps=1.4,
    ranked_speeds_mps=(1.0, 0.5),
    lateral_accel_mps2=0.8,
)
_style(
    "reluctant",
    "leaves the path reluctantly: twice the cost per metre of detour; "
    "1.6 m/s on open ground, 1.2 to 0.4 m/s on patches, 1.0 m/s^2 in bends, 0.8 m/s near lethal terrain",
    deviation_cost=0.16,
    speed_mps=1.6,
    ranked_speeds_mps=(1.2, 0.4),
    lateral_accel_mps2=1.0,
    near_lethal_mps=0.8,
)


class ExpertDriver:
    """A seeded, human-like driver that follows the path and its terrain preference."""

    sample_step_m = 0.25

    def __init__(self, config: ExpertConfig | None = None, camera_rate_hz: float = 10.0, world: WorldMap | None = None) -> None:
        self.config = config or ExpertConfig()
        self._given_world = world  # the scenario's raster, when the caller already has it
        self.dt = 1.0 / camera_rate_hz
        self._vehicle_steps = max(1, round(VehicleConfig().control_rate_hz * self.dt))  # the vehicle's steps a camera period
        c = self.config
        self.offsets = np.round(np.arange(-c.max_offset_m, c.max_offset_m + 1e-9, c.offset_step_m), 6)
        foot = np.linspace(-c.half_width_m, c.half_width_m, 5)
        lethal_foot = np.linspace(-c.half_width_m - c.lethal_margin_m, c.half_width_m + c.lethal_margin_m, 7)
        self._foot = foot
        edge = c.half_width_m + c.margin_m * np.array([0.5, 1.0])
        margin_foot = np.concatenate([-edge[::-1], edge]) if c.margin_m > 0 else None
        # Each candidate offset's footprint points, its berth and its lethal clearance (O, F) [m].
        self._lat = self.offsets[:, None] + foot[None, :]
        self._margin_lat = self.offsets[:, None] + margin_foot[None, :] if margin_foot is not None else None
        self._lethal_lat = self.offsets[:, None] + lethal_foot[None, :]
        self._way_s = np.arange(0.0, c.preview_m + 1e-9, self.sample_step_m)  # the way ahead its speed looks over
        self._near_lat = np.linspace(-c.half_width_m - c.near_lethal_m, c.half_width_m + c.near_lethal_m, 9)
        self._s_rel = np.arange(-c.lookbehind_m, c.reaction_distance_m + c.decision_extent_m + 1e-9, self.sample_step_m)
        self._in_reach = self._s_rel <= c.reaction_distance_m

    # -- episode ---------------------------------------------------------------------------

    def reset(self, scenario: Scenario, rng: np.random.Generator, world: WorldMap | None = None) -> None:
        c = self.config
        self.rng = rng
        world = world if world is not None else self._given_world
        self.world = world if world is not None and world.raster.shape == scenario.grid_shape else rasterise(scenario)
        self.path = ReferencePath(scenario.waypoints)
        self.tracker = PathTracker(self.path, back_m=2.0, ahead_m=6.0)
        classes = scenario.classes
        profile = PreferenceProfile.parse(list(c.profile), classes, source="expert.profile")
        cost = np.zeros(256)
        cost[255] = c.lethal_cost  # off the map: never go there
        for rank, name in enumerate(profile.order):
            cost[list(classes.ids_of(name))] = c.rank_cost * c.rank_growth**rank
        lethal = np.zeros(256, dtype=bool)
        lethal[list(classes.lethal_ids)] = True
        lethal[255] = True
        cost[lethal] = c.lethal_cost
        self._cost, self._lethal = cost, lethal
        self.offset = 0.0
        self.stick = 0.0
        self._queue: deque[float] = deque([0.0] * max(0, round(c.reaction_delay_s / self.dt)))
        self._throttle: deque[float] | None = None  # the speeds wanted, as the reaction delay holds them
        self._speed = c.speed_table(classes)
        self.wanted_mps = c.speed_mps
        # Relief: what it reads of the ground, and what a way over ground steeper than it takes costs
        # a metre (more than any terrain class, less than lethal terrain: it goes round where it can).
        height = self.world.height
        body = (c.half_width_m, VehicleConfig().wheelbase_m)
        self._sight = ReliefSight(height, self.world.resolution_m, *body) if c.relief is not None and height is not None else None
        self._steep_cost = 2.0 * float(cost[np.isfinite(cost) & ~lethal].max(initial=c.rank_cost))

    # -- decision --------------------------------------------------------------------------

    def choose_offset(self, s_now: float, pose: tuple[float, float, float] | None = None, v_mps: float | None = None) -> float:
        """The lateral offset [m] (left positive) to hold over the terrain ahead; with the vehicle's
        ``pose`` and speed ``v_mps``, an offset it cannot reach from there without running over
        lethal terrain costs as lethal terrain on its line does (:func:`_way_totals`)."""
        c = self.config
        s = s_now + self._s_rel  # (S,)
        valid = s <= self.path.length_m
        s, in_reach = s[valid], self._in_reach[valid]
        centre = self.path.point_at(s)  # (S, 2)
        heading = self.path.heading_at(s)
        normal = np.stack([-np.sin(heading), np.cos(heading)], axis=1)  # left of the path
        # A detour lasts as long as the obstacle ahead lies on the path itself (gaps under 1 m
        # do not split it), plus the swerves in and out; later patches wait for their own turn.
        on_path = (self._cost[self._classes(centre, normal, self._foot[None, :], len(s))[0]] > 0).any(axis=1)
        if self._sight is not None:  # ground steeper than it takes is a reason to leave the path too
            on_path |= self._sight.steep(centre, normal, np.zeros(1), len(s), c.relief)[0]
        reach = np.flatnonzero(on_path & in_reach)
        if len(reach) == 0:
            return 0.0
        first = last = int(reach[0])
        gap = round(1.0 / self.sample_step_m)
        for i in np.flatnonzero(on_path[first:]) + first:
            if i - last > gap:
                break
            last = int(i)
        upto = min(len(s), last + 1 + round(c.pursuit_m / self.sample_step_m))
        terrain = self._costs(centre, normal, self._lat, upto) * self.sample_step_m  # (O,)
        if self._margin_lat is not None:  # the berth beside the footprint: half the cost of driving on it
            terrain = terrain + 0.5 * self._costs(centre, normal, self._margin_lat, upto) * self.sample_step_m
        if self._sight is not None:
            steep = self._sight.steep(centre, normal, self.offsets, upto, c.relief)
            terrain = terrain + steep.sum(axis=1) * self._steep_cost * self.sample_step_m
        # Lethal terrain within the whole window is kept clear of while steep ground sets the detour:
        # a bump across the way must not leave the next lethal patch to be seen too late.
        near = len(s) if self._sight is not None else upto
        hits_lethal = _offset_hits(centre, normal, self._lethal_lat, near, self.world.raster, self.world.resolution_m, self._lethal)
        terrain = terrain + hits_lethal * c.lethal_cost
        span = (last - first + 1) * self.sample_step_m + 2.0 * c.pursuit_m
        detour = c.deviation_cost * self.offsets**2 * span
        held = int(np.argmin(np.abs(self.offsets - self.offset)))
        can_hold = self.offset != 0.0 and not hits_lethal[held]
        if pose is None:
            total = terrain + detour
        else:  # the ways there, of the offsets that can decide
            stations = (s - s_now, near, centre, heading)
            total = self._way_totals(terrain, detour, (held, can_hold), stations, pose, v_mps or c.speed_mps)
        best = float(total.min())
        # Hold the current side unless another is clearly cheaper (no dithering); among equal
        # candidates prefer the smaller offset, then a coin toss between left and right.
        if can_hold and total[held] <= best * (1 + c.switch_margin) + 1e-6:
            return float(self.offsets[held])
        ties = np.flatnonzero(total <= best + 1e-6)
        mags = np.abs(self.offsets[ties])
        ties = ties[mags <= mags.min() + 1e-9]
        same_side = ties[np.sign(self.offsets[ties]) == np.sign(self.offset)]
        if self.offset != 0.0 and len(same_side):
            ties = same_side  # keep to the side already taken
        return float(self.offsets[ties[self.rng.integers(len(ties))]] if len(ties) > 1 else self.offsets[ties[0]])

    def _way_totals(
        self,
        terrain: np.ndarray,
        detour: np.ndarray,
        held: tuple[int, bool],
        stations: tuple,
        pose: tuple[float, float, float],
        v_mps: float,
    ) -> np.ndarray:
        """``terrain + detour`` (O,), with the lethal cost added to the terrain of each offset whose
        way there from ``pose`` at ``v_mps`` runs over lethal terrain, where it can decide
        (:func:`_way_totals`). ``held``: the held offset's index, and whether it may be held.
        ``stations``: the path's stations' distances from the vehicle's [m], how many of them the
        line's check reads, their points and headings."""
        costs = (terrain, detour, held[0], held[1], self.config.switch_margin, self.config.lethal_cost)
        return _way_totals(costs, self.offsets, self._way(stations, pose, v_mps))

    def _way_hits(self, stations: tuple, pose: tuple[float, float, float], v_mps: float) -> np.ndarray:
        """(O,): whether the way to each candidate offset runs over lethal terrain (:func:`_way_hit`)."""
        return _way_hits(self.offsets, self._way(stations, pose, v_mps))

    def _way(self, stations: tuple, pose: tuple[float, float, float], v_mps: float) -> tuple:
        """The way's start, hand and ground (:func:`_way_hit`) for the driver as it is now."""
        s_rel, upto, centre, heading = stations
        c = self.config
        hand = (c.pursuit_m, c.max_yaw_rate_rps, c.stick_rate_rps2 * self.dt, c.deadzone_rps, self.stick)
        pending = np.array(self._queue, dtype=np.float64)
        start = (float(pose[0]), float(pose[1]), float(pose[2]))  # a plain tuple: one compiled form for a Pose and any other
        ground = (self._foot, self.world.raster, self.world.resolution_m, self._lethal)
        return start, float(v_mps), (self.dt, self._vehicle_steps, hand, pending), (s_rel, centre, heading), float(s_rel[upto - 1]), ground

    def _costs(self, centre: np.ndarray, normal: np.ndarray, lat: np.ndarray, upto: int) -> np.ndarray:
        """``cost[_classes(centre, normal, lat, upto)].mean(axis=2).sum(axis=1)`` (O,): each offset's
        cost per point summed along the path, with NumPy's sums (compiled, up to 128 stations)."""
        if upto > 128 or lat.shape[1] > 128:  # past the sums terrapref.sums follows
            return self._cost[self._classes(centre, normal, lat, upto)].mean(axis=2).sum(axis=1)
        return _offset_costs(centre, normal, lat, upto, self.world.raster, self.world.resolution_m, self._cost)

    def _classes(self, centre: np.ndarray, normal: np.ndarray, lat: np.ndarray, upto: int) -> np.ndarray:
        """Class ids (O, upto, F) of the points ``centre + lat * normal`` for the first ``upto`` samples along the path.

        ``lat`` (O, F) are lateral offsets [m] (left positive) of the footprint's points; the
        same arithmetic as ``world.class_at(centre[None, :upto, None] + lat[:, None, :, None] *
        normal[None, :upto, None])``, point by point in one compiled pass.
        """
        return _offset_classes(centre, normal, lat, upto, self.world.raster, self.world.resolution_m)

    def pursuit(self, pose: tuple[float, float, float], s_now: float, offset: float) -> tuple[float, float]:
        """Pure pursuit toward the path shifted sideways by ``offset``: the sine of the target's
        bearing from the heading and its distance [m] (curvature 2 sin / distance)."""
        c = self.config
        s_t = s_now + c.pursuit_m
        heading = float(self.path.heading_at(s_t))
        target = self.path.point_at(s_t) + offset * np.array([-math.sin(heading), math.cos(heading)])
        x, y, yaw = pose
        alpha = math.atan2(target[1] - y, target[0] - x) - yaw
        alpha = wrap_angle(alpha)
        return math.sin(alpha), max(math.hypot(target[0] - x, target[1] - y), 1e-6)

    def steer(self, pose: tuple[float, float, float], s_now: float, offset: float, v_mps: float | None = None) -> float:
        """Pure-pursuit yaw rate [rad/s] toward the path shifted sideways by ``offset``, at
        ``v_mps`` (None: the cruising speed)."""
        return pure_pursuit_yaw_rate(self.config.speed_mps if v_mps is None else v_mps, *self.pursuit(pose, s_now, offset))

    def wanted_speed(self, pose: tuple[float, float, float], s_now: float, curvature: float) -> float:
        """The speed [m/s] the driver's style asks for now (before its hand's delay): the slowest
        cruising speed of the classes its footprint meets now and on its way over the next
        ``preview_m``, no more than its lateral-acceleration limit allows at ``curvature``
        [1/m], nor than ``near_lethal_mps`` while lethal terrain lies near that way. With a
        relief style, each point's speed is its class's less what its grade along the way and
        its roughness take off (terrapref.demos.relief_style)."""
        c = self.config
        if c.steady and self._sight is None:
            return c.speed_mps
        s = s_now + self._way_s
        s = s[s <= self.path.length_m]
        x, y, yaw = pose
        across = np.array([(x - a * math.sin(yaw), y + a * math.cos(yaw)) for a in self._foot])
        ids = [self.world.class_at_point(px, py) for px, py in across]
        headings = [yaw] * len(ids)
        near_lethal = False
        if len(s):
            centre, heading = self.path.point_at(s), self.path.heading_at(s)
            normal = np.stack([-np.sin(heading), np.cos(heading)], axis=1)
            raster, res = self.world.raster, self.world.resolution_m
            ids += _offset_classes(centre, normal, self.offset + self._foot[None, :], len(s), raster, res).ravel().tolist()
            if self._sight is not None:
                lat = self.offset + self._foot
                across = np.concatenate([across, (centre[:, None, :] + lat[None, :, None] * normal[:, None, :]).reshape(-1, 2)])
                headings += np.repeat(heading, len(lat)).tolist()
            if c.near_lethal_mps is not None:
                near_lethal = bool(
                    _offset_hits(centre, normal, self.offset + self._near_lat[None, :], len(s), raster, res, self._lethal)[0]
                )
        speeds = self._speed[np.asarray(ids, dtype=np.intp)]
        if self._sight is not None:  # each point's speed less what its grade and roughness take off
            grade, rough = self._sight.along(across, np.asarray(headings))
            speeds = np.array([c.relief.speed(v, g, r, MIN_CRUISE_MPS) if v == v else v for v, g, r in zip(speeds, grade, rough)])
        v = float(np.nanmin(speeds)) if np.isfinite(speeds).any() else c.speed_mps
        if near_lethal:
            v = min(v, c.near_lethal_mps)
        if c.lateral_accel_mps2 is not None and curvature != 0.0:
            v = min(v, math.sqrt(c.lateral_accel_mps2 / abs(curvature)))
        return v

    def intent(self, frame: Frame) -> float:
        """The yaw rate [rad/s] the driver wants now, before its hand's delay, rate limit and tremor,
        at the faster of the vehicle's speed and the speed it wants (``wanted_mps`` after the call);
        with a relief style, at no less than :data:`RELIEF_STEER_MPS`.

        Used alone when the driver corrects another driver (the planner) rather than driving.
        """
        c = self.config
        s_now = self.tracker.update(np.array(frame.pose[:2]))
        self.offset = self.choose_offset(s_now, frame.pose, max(frame.speed_mps, self.wanted_mps))
        sin_alpha, distance = self.pursuit(frame.pose, s_now, self.offset)
        self.wanted_mps = self.wanted_speed(frame.pose, s_now, 2.0 * sin_alpha / distance)
        v = max(frame.speed_mps, self.wanted_mps)
        if self._sight is not None:  # slowed by relief, it still turns to where it is going
            v = max(v, RELIEF_STEER_MPS)
        w = pure_pursuit_yaw_rate(v, sin_alpha, distance)
        w = 0.0 if abs(w) < c.deadzone_rps else w
        return float(np.clip(w, -c.max_yaw_rate_rps, c.max_yaw_rate_rps))

    def act(self, frame: Frame) -> Command:
        c = self.config
        w = self.intent(frame)
        if self._throttle is None:  # the hand holds the first speed it wants from the start
            self._throttle = deque([self.wanted_mps] * len(self._queue))
        self._throttle.append(self.wanted_mps)
        v = self._throttle.popleft()
        self._queue.append(w)
        wanted = self._queue.popleft()
        step = c.stick_rate_rps2 * self.dt
        self.stick = min(max(wanted, self.stick - step, -c.max_yaw_rate_rps), self.stick + step, c.max_yaw_rate_rps)
        if wanted == 0.0 and abs(self.stick) <= step:
            self.stick = 0.0  # a released stick springs back to exactly zero
        out = self.stick
        if out != 0.0 and c.stick_noise_rps > 0:
            out = float(np.clip(out + self.rng.normal(0.0, c.stick_noise_rps), -c.max_yaw_rate_rps, c.max_yaw_rate_rps))
        return Command(v, out)


# A driver slowed by relief (a steep grade sheds its speed down to MIN_CRUISE_MPS) steers as at
# this speed at least. Pure pursuit's yaw rate is the speed times the curvature: at 0.1 m/s a
# target half a radian off asks for less than the hand's deadzone, so a cautious driver on a ridge's
# flank held its stick at zero and crept along the flank, turned by each push, where a person
# crawling up a bank still turns the vehicle towards where they are going.
RELIEF_STEER_MPS = 0.3


@njit(cache=True, nogil=True, inline="always")
def _cell_beside(x: float, y: float, lat: float, nx: float, ny: float, res: float) -> tuple[int, int]:
    """(row, col) of the raster cell under ``(x, y) + lat * (nx, ny)``, floor to a cell as
    :meth:`WorldMap.class_at` (numbers only: an inlined helper that takes an array costs each
    point more than the point)."""
    return np.int64(math.floor((y + lat * ny) / res)), np.int64(math.floor((x + lat * nx) / res))


@njit(cache=True, nogil=True)
def _offset_costs(
    centre: np.ndarray, normal: np.ndarray, lat: np.ndarray, upto: int, raster: np.ndarray, res: float, cost: np.ndarray
) -> np.ndarray:
    """(O,): ``cost[_offset_classes(...)].mean(axis=2).sum(axis=1)``, each mean and sum as NumPy
    adds it (terrapref.sums.numpy_sum; ``upto`` and the points across, ``lat.shape[1]``, <= 128)."""
    n_rows, n_cols = raster.shape
    n_f = lat.shape[1]
    points, stations = np.empty(n_f), np.empty(upto)
    out = np.empty(lat.shape[0])
    for o in range(lat.shape[0]):
        for k in range(upto):
            total = 0.0  # numpy_sum's order for fewer than 8 terms, written out: a call per station cost more than its sum
            for f in range(n_f):
                row, col = _cell_beside(centre[k, 0], centre[k, 1], lat[o, f], normal[k, 0], normal[k, 1], res)
                points[f] = cost[raster[row, col] if 0 <= col < n_cols and 0 <= row < n_rows else UNKNOWN]
                total += points[f]
            stations[k] = (0.0 + total if n_f < 8 else numpy_sum(points)) / n_f
        out[o] = numpy_sum(stations)
    return out


@njit(cache=True, nogil=True)
def _offset_hits(
    centre: np.ndarray, normal: np.ndarray, lat: np.ndarray, upto: int, raster: np.ndarray, res: float, lethal: np.ndarray
) -> np.ndarray:
    """(O,): ``lethal[_offset_classes(...)].any(axis=(1, 2))``, each offset's search stopped at its first hit."""
    n_rows, n_cols = raster.shape
    out = np.zeros(lat.shape[0], np.bool_)
    for o in range(lat.shape[0]):
        for k in range(upto):
            for f in range(lat.shape[1]):
                row, col = _cell_beside(centre[k, 0], centre[k, 1], lat[o, f], normal[k, 0], normal[k, 1], res)
                if lethal[raster[row, col] if 0 <= col < n_cols and 0 <= row < n_rows else UNKNOWN]:
                    out[o] = True
                    break
            if out[o]:
                break
    return out


@njit(cache=True, nogil=True, inline="always")
def _along(s: float, s_rel: np.ndarray, centre: np.ndarray, heading: np.ndarray) -> tuple[float, float, float]:
    """The path's point (x, y) and heading at ``s`` [m] (relative, as ``s_rel``), between the
    stations ``s_rel`` (evenly spaced), held at the first and last."""
    n = s_rel.shape[0]
    t = (s - s_rel[0]) / (s_rel[1] - s_rel[0]) if n > 1 else 0.0
    if t <= 0.0:
        return centre[0, 0], centre[0, 1], heading[0]
    if t >= n - 1:
        return centre[n - 1, 0], centre[n - 1, 1], heading[n - 1]
    k = np.int64(t)
    f = t - k
    turn = (heading[k + 1] - heading[k] + math.pi) % (2.0 * math.pi) - math.pi
    return centre[k, 0] + f * (centre[k + 1, 0] - centre[k, 0]), centre[k, 1] + f * (centre[k + 1, 1] - centre[k, 1]), heading[k] + f * turn


@njit(cache=True, nogil=True)
def _way_totals(
    costs: tuple[np.ndarray, np.ndarray, int, bool, float, float],
    offsets: np.ndarray,
    way: tuple,
) -> np.ndarray:
    """The offsets' totals, ``terrain + detour``, with ``lethal_cost`` added to the terrain of each
    offset whose way there runs over lethal terrain (:func:`_way_hit`; ``costs``: terrain,
    detour, the held offset's index and whether it may be held, the switch margin, the lethal
    cost).

    Only the ways that can decide are followed: the held offset's; if it is then held whatever
    the others' ways (within the margin of the least total without them), no other; else the
    others' from the cheapest up, until the next one's total is past the best so far by more
    than the margin. Those not followed cost more than the best by the margin whatever their
    way, so the best, the hold and the ties are the same as with every way followed.
    """
    terrain, detour, held, can_hold, margin, lethal_cost = costs
    total = terrain + detour
    order = np.argsort(total)
    least = total[order[0]]
    if _way_hit(offsets[held], way):
        total[held] = (terrain[held] + lethal_cost) + detour[held]
    best = total[held]
    if can_hold and best <= least * (1.0 + margin) + 1e-6:
        return total
    for i in order:
        if i == held:
            continue
        if total[i] > best * (1.0 + margin) + 1e-6:
            break
        if _way_hit(offsets[i], way):
            total[i] = (terrain[i] + lethal_cost) + detour[i]
        best = min(best, total[i])
    return total


@njit(cache=True, nogil=True)
def _way_hits(
    offsets: np.ndarray,
    way: tuple,
) -> np.ndarray:
    """(O,): :func:`_way_hit` of each offset in ``offsets``."""
    out = np.zeros(offsets.shape[0], np.bool_)
    for o in range(offsets.shape[0]):
        out[o] = _way_hit(offsets[o], way)
    return out


@njit(cache=True, nogil=True)
def _way_hit(off: float, way: tuple) -> bool:
    """Whether the driver's way to the offset ``off`` [m] runs the points across its axle over
    lethal terrain. ``way``: ``pose``, ``v``, ``hand``, ``stations``, ``reach`` and ``ground``
    (those points [m], the class raster, its cell size [m], the lethal classes) as below.

    The way is the driver's own steering imagined without its tremor: from ``pose`` at a steady
    ``v`` [m/s], each camera period a pure-pursuit yaw rate toward the offset's line, through its
    reaction delay and its stick, held over the vehicle's ticks (``hand``: the period [s], the
    ticks in it, the stick's pursuit distance [m], largest yaw rate [rad/s], largest move a
    period, deadzone and where it is now, and the yaw rates already pending). ``stations``: the
    path's stations, their distances from the vehicle's along the path [m], points (S, 2) and
    headings (S,) (the pursuit's target is held at the last). It ends past ``reach`` [m] along
    the path, or once on the line, straight and with nothing pending (the line's own check
    takes over there), or after 400 periods.
    """
    pose, v, hand, stations, reach, ground = way
    dt, ticks, stick_hand, pending = hand
    pursuit_m, max_w, stick_step, deadzone, stick = stick_hand
    delay = pending.shape[0]
    queue = np.empty(delay + 1)
    queue[:delay] = pending
    h = dt / ticks
    x, y, yaw = pose
    s = 0.0
    for _ in range(400):
        if s > reach or _settled(x, y, yaw, s, off, stick, queue[:delay], stations):
            return False
        w = _pursuit_rate(x, y, yaw, s + pursuit_m, off, v, stations)
        queue[delay] = 0.0 if abs(w) < deadzone else min(max(w, -max_w), max_w)
        wanted = queue[0]
        queue[:delay] = queue[1:]
        stick = min(max(wanted, stick - stick_step, -max_w), stick + stick_step, max_w)
        if wanted == 0.0 and abs(stick) <= stick_step:
            stick = 0.0
        x, y, yaw, s, hit = _ticks(x, y, yaw, s, v * h, stick * h, ticks, stations, ground)
        if hit:
            return True
    return False


@njit(cache=True, nogil=True, inline="always")
def _settled(
    x: float,
    y: float,
    yaw: float,
    s: float,
    off: float,
    stick: float,
    pending: np.ndarray,
    stations: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> bool:
    """Whether the vehicle at ``(x, y, yaw)``, ``s`` along the path, is on the offset ``off``'s line
    (within 5 cm), straight along it, its stick at rest and no yaw rate ``pending``."""
    px, py, ph = _along(s, stations[0], stations[1], stations[2])
    if stick != 0.0 or abs((y - py) * math.cos(ph) - (x - px) * math.sin(ph) - off) >= 0.05 or abs(math.sin(yaw - ph)) >= 0.02:
        return False
    for k in range(pending.shape[0]):
        if pending[k] != 0.0:
            return False
    return True


@njit(cache=True, nogil=True, inline="always")
def _pursuit_rate(
    x: float, y: float, yaw: float, s_target: float, off: float, v: float, stations: tuple[np.ndarray, np.ndarray, np.ndarray]
) -> float:
    """Pure pursuit's yaw rate [rad/s] at ``v`` toward the point ``off`` [m] beside the path at
    ``s_target`` along it."""
    tx, ty, th = _along(s_target, stations[0], stations[1], stations[2])
    tx, ty = tx - off * math.sin(th), ty + off * math.cos(th)
    return 2.0 * v * math.sin(math.atan2(ty - y, tx - x) - yaw) / max(math.hypot(tx - x, ty - y), 1e-6)


@njit(cache=True, nogil=True, inline="always")
def _ticks(
    x: float,
    y: float,
    yaw: float,
    s: float,
    step_m: float,
    turn: float,
    ticks: int,
    stations: tuple[np.ndarray, np.ndarray, np.ndarray],
    ground: tuple[np.ndarray, np.ndarray, float, np.ndarray],
) -> tuple[float, float, float, float, bool]:
    """``ticks`` steps of ``step_m`` [m] turning ``turn`` [rad] each, the pose's distance along
    the path ``s`` following; and whether the points ``foot`` across the axle met lethal terrain
    (``ground``: foot, raster, cell size, lethal classes) after any step."""
    foot, raster, res, lethal = ground
    n_rows, n_cols = raster.shape
    hit = False
    for _ in range(ticks):
        x, y, yaw = x + step_m * math.cos(yaw + 0.5 * turn), y + step_m * math.sin(yaw + 0.5 * turn), yaw + turn
        sin, cos = math.sin(yaw), math.cos(yaw)
        for f in range(foot.shape[0]):
            row, col = _cell_beside(x, y, foot[f], -sin, cos, res)
            hit |= lethal[raster[row, col] if 0 <= col < n_cols and 0 <= row < n_rows else UNKNOWN]
        px, py, ph = _along(s, stations[0], stations[1], stations[2])
        s += (x - px) * math.cos(ph) + (y - py) * math.sin(ph)  # the pose's projection, a step at a time
    return x, y, yaw, s, hit


@njit(cache=True, nogil=True)
def _offset_classes(centre: np.ndarray, normal: np.ndarray, lat: np.ndarray, upto: int, raster: np.ndarray, res: float) -> np.ndarray:
    """Class id (O, upto, F) uint8 of every point ``centre[s] + lat[o, f] * normal[s]`` (255 off the
    map): per point the NumPy form of :meth:`WorldMap.class_at`, ``floor(x / res)`` to a cell."""
    n_rows, n_cols = raster.shape
    out = np.empty((lat.shape[0], upto, lat.shape[1]), np.uint8)
    for o in range(lat.shape[0]):
        for k in range(upto):
            for f in range(lat.shape[1]):
                row, col = _cell_beside(centre[k, 0], centre[k, 1], lat[o, f], normal[k, 0], normal[k, 1], res)
                out[o, k, f] = raster[row, col] if 0 <= col < n_cols and 0 <= row < n_rows else UNKNOWN
    return out
