"""The vehicle on relief (SPEC 19): a rigid body on four wheels, without suspension.

Each controller tick the body takes its height, pitch and roll from the ground under its four
wheels (at +-``wheelbase_m / 2`` along it and +-``half_width_m`` across it, about the reference
point): the height is the mean of the four, the pitch the rise of the rear axle's mean over the
front's along the wheelbase, the roll the rise of the left side's mean over the right's across
the track. On a plane that is the plane's own attitude; on curved ground it is the attitude of
the plane fitted to the four contacts.

Angles follow REP 103 (body x forward, y left, z up): pitch is positive nose down, roll positive
with the left side up. Driving up a grade of ``g`` rad, the pitch is ``-g``.

Limits (:class:`~terrapref.vehicle.kinematics.VehicleConfig`): past ``max_roll_deg`` or
``max_pitch_deg`` the vehicle has tipped; ground rising by more than ``max_step_m`` just ahead of
a front wheel stops it where it stands (stuck): it can still turn in place. No wheel climbs more
than ``max_step_m`` on its way either, whichever way it moves (a wall thinner than a tick's
distance, a ledge under the rear wheels, a turn into a bank): ground read every half cell along
each wheel's way, and a cell past it, so that nothing is stepped over between two ticks or
climbed a little at a time. Up a grade its top speed is that of a drive of constant power
(:meth:`GroundContact.top_speed_mps`).
"""

from __future__ import annotations

import math
from typing import NamedTuple, Protocol

import numpy as np

from terrapref.vehicle.kinematics import Pose, VehicleConfig


class Attitude(NamedTuple):
    """The body's height and orientation on the ground.

    Attributes:
        z_m: the reference point's height: the mean of the ground under the four wheels [m].
        pitch_rad: about the body's left axis, positive nose down (REP 103) [rad].
        roll_rad: about the body's forward axis, positive with the left side up [rad].
    """

    z_m: float
    pitch_rad: float
    roll_rad: float

    @property
    def grade_rad(self) -> float:
        """The grade along the heading, positive uphill [rad]: ``-pitch_rad``."""
        return -self.pitch_rad


LEVEL = Attitude(0.0, 0.0, 0.0)  # the attitude on flat ground


class Ground(Protocol):
    """Anything that gives the ground's height at a point (a world map with relief)."""

    resolution_m: float  # the side of its grid's cells [m]

    def height_at_point(self, x: float, y: float) -> float: ...


class GroundContact:
    """The ground under one vehicle's wheels: its attitude, the step ahead of it and its top speed
    up a grade, in plain floats (asked at every controller tick).

    Args:
        ground: the ground's heights.
        config: the vehicle's geometry and limits.
    """

    def __init__(self, ground: Ground, config: VehicleConfig) -> None:
        self.height_at = ground.height_at_point
        self.config = config
        self.half_length_m = 0.5 * config.wheelbase_m
        self.half_width_m = config.half_width_m
        # Long enough that a ledge one grid cell wide (a rasterised vertical step) is seen whole
        # from some tick: the distance of one tick at top speed, and a cell.
        self.probe_m = config.max_speed_mps * config.dt_s + ground.resolution_m
        self.resolution_m = ground.resolution_m

    def _wheel_points(self, pose: Pose) -> tuple[tuple[float, float], ...]:
        """Where the front-left, front-right, rear-left and rear-right wheels touch the ground (x, y) [m]."""
        x, y, yaw = pose
        cos, sin = math.cos(yaw), math.sin(yaw)
        ax, ay = self.half_length_m * cos, self.half_length_m * sin  # half the wheelbase, along
        cx, cy = -self.half_width_m * sin, self.half_width_m * cos  # half the track, to the left
        return (x + ax + cx, y + ay + cy), (x + ax - cx, y + ay - cy), (x - ax + cx, y - ay + cy), (x - ax - cx, y - ay - cy)

    def _wheels(self, pose: Pose) -> tuple[float, float, float, float]:
        """The ground's height [m] under the front-left, front-right, rear-left and rear-right wheels."""
        z = self.height_at
        (a, b), (c, d), (e, f), (g, h) = self._wheel_points(pose)
        return z(a, b), z(c, d), z(e, f), z(g, h)

    def _rise_along(self, x: float, y: float, dx: float, dy: float) -> float:
        """The largest rise of the ground [m] from (x, y) along the way (dx, dy) from it, read every
        half cell to the way's end (inclusive)."""
        z, n = self.height_at, max(1, math.ceil(2.0 * math.hypot(dx, dy) / self.resolution_m))
        return max(z(x + dx * k / n, y + dy * k / n) for k in range(1, n + 1)) - z(x, y)

    def climbs(self, before: Pose, after: Pose) -> bool:
        """Whether a wheel, moving from ``before`` to ``after``, would climb more than the step the
        vehicle climbs: the ground along each wheel's way and a cell past it, over the ground
        under the wheel at ``before``."""
        limit, cell = self.config.max_step_m, self.resolution_m
        for (x0, y0), (x1, y1) in zip(self._wheel_points(before), self._wheel_points(after), strict=True):
            dx, dy = x1 - x0, y1 - y0
            way = math.hypot(dx, dy)
            if way > 0.0 and self._rise_along(x0, y0, dx * (1.0 + cell / way), dy * (1.0 + cell / way)) > limit:
                return True
        return False

    def step_under(self, pose: Pose) -> float:
        """The highest step [m] under the body at ``pose`` that its rear wheels would have to climb
        to follow its front ones: along each side from the rear wheel to the front one, the
        largest rise of the ground over a cell (read every half cell; 0 on smooth ground)."""
        fl, fr, rl, rr = self._wheel_points(pose)
        step = 0.0
        for (x0, y0), (x1, y1) in ((rl, fl), (rr, fr)):
            n = max(2, math.ceil(2.0 * math.hypot(x1 - x0, y1 - y0) / self.resolution_m))
            z = [self.height_at(x0 + (x1 - x0) * k / n, y0 + (y1 - y0) * k / n) for k in range(n + 1)]
            step = max(step, *(z[k + 2] - z[k] for k in range(n - 1)))
        return step

    def attitude(self, pose: Pose) -> Attitude:
        """The body's height and orientation at ``pose``."""
        fl, fr, rl, rr = self._wheels(pose)
        pitch = math.atan2(0.5 * (rl + rr) - 0.5 * (fl + fr), 2.0 * self.half_length_m)
        roll = math.atan2(0.5 * (fl + rl) - 0.5 * (fr + rr), 2.0 * self.half_width_m)
        return Attitude(0.25 * (fl + fr + rl + rr), pitch, roll)

    def rise_ahead_m(self, pose: Pose) -> float:
        """The largest rise of the ground [m] from a front wheel (or the middle of the front axle)
        within ``probe_m`` ahead of it: the step the vehicle is about to climb."""
        x, y, yaw = pose
        cos, sin = math.cos(yaw), math.sin(yaw)
        ax, ay = self.half_length_m * cos, self.half_length_m * sin
        px, py = self.probe_m * cos, self.probe_m * sin
        rise = -math.inf
        for side in (-1.0, 0.0, 1.0):
            wx, wy = x + ax - side * self.half_width_m * sin, y + ay + side * self.half_width_m * cos
            rise = max(rise, self._rise_along(wx, wy, px, py))
        return rise

    def blocked(self, pose: Pose) -> bool:
        """Whether the step ahead at ``pose`` is higher than the vehicle climbs."""
        return self.rise_ahead_m(pose) > self.config.max_step_m

    def tipped(self, attitude: Attitude) -> bool:
        """Whether ``attitude`` is past the vehicle's roll or pitch limit."""
        return self.past_limits(attitude, self.config)

    @staticmethod
    def past_limits(attitude: Attitude, config: VehicleConfig) -> bool:
        """Whether ``attitude`` is past ``config``'s roll or pitch limit."""
        return abs(attitude.roll_rad) > math.radians(config.max_roll_deg) or abs(attitude.pitch_rad) > math.radians(config.max_pitch_deg)

    def top_speed_mps(self, attitude: Attitude) -> float:
        """The fastest the vehicle goes [m/s] at ``attitude``: up a grade, a drive of constant power
        that reaches ``max_speed_mps`` on the level against rolling resistance ``c`` climbs at
        ``max_speed_mps * c / (c cos g + sin g)`` (level and downhill: ``max_speed_mps``)."""
        g, c = attitude.grade_rad, self.config.rolling_resistance
        if g <= 0.0:
            return self.config.max_speed_mps
        return self.config.max_speed_mps * c / (c * math.cos(g) + math.sin(g))


START_REACH_M = 3.0  # the ground read round a start for the attitude there: past the wheels of any vehicle of ours [m]
START_SHIFT_M = 0.3  # an evaluation's seeds after the first begin up to this far to the side of the start [m]
START_SHIFT_DEG = 3.0  # and up to this far off its heading [deg]


def start_pose(start: tuple[float, float, float], seed: int) -> Pose:
    """Where an evaluation's run of ``seed`` begins: seed 0 at ``start``, each later one up to
    :data:`START_SHIFT_M` to its side and :data:`START_SHIFT_DEG` off its heading."""
    if seed == 0:
        return Pose(*start)
    rng = np.random.default_rng([seed, 7919])
    return _shifted(start, rng.uniform(-START_SHIFT_M, START_SHIFT_M), math.radians(rng.uniform(-START_SHIFT_DEG, START_SHIFT_DEG)))


def _shifted(start: tuple[float, float, float], lateral_m: float, turn_rad: float) -> Pose:
    """``start`` moved ``lateral_m`` to its left (negative: right) and turned ``turn_rad``."""
    x, y, yaw = start
    return Pose(x - lateral_m * math.sin(yaw), y + lateral_m * math.cos(yaw), yaw + turn_rad)


def start_poses(start: tuple[float, float, float], seeds: int = 0) -> tuple[Pose, ...]:
    """The start, then poses round it where a run may begin: every centimetre to either side of it
    within :data:`START_SHIFT_M`, each on the start's heading and :data:`START_SHIFT_DEG` off it;
    then where ``seeds`` runs of an evaluation begin (:func:`start_pose`)."""
    steps = round(START_SHIFT_M / 0.01)
    shifts = [START_SHIFT_M * k / steps for k in range(-steps, steps + 1)]
    turns = (0.0, -math.radians(START_SHIFT_DEG), math.radians(START_SHIFT_DEG))
    around = (_shifted(start, lat, turn) for lat in shifts for turn in turns)
    return (Pose(*start), *around, *(start_pose(start, seed) for seed in range(1, seeds)))


def start_attitude(scenario, config: VehicleConfig | None = None) -> Attitude:
    """The body's attitude at ``scenario``'s start (a :class:`terrapref.scenario.Scenario`), as the
    simulator's vehicle of ``config`` (default: the default vehicle) would stand there: from the
    height field's cells round the start, each the value the whole field gives it (read from them,
    the attitude is the simulator's to rounding), so a large map need not be built to check where
    a run would begin. Level on a scenario without relief."""
    return start_attitudes(scenario, (Pose(*scenario.start),), config)[0]


def start_attitudes(scenario, poses: tuple[Pose, ...], config: VehicleConfig | None = None) -> tuple[Attitude, ...]:
    """:func:`start_attitude` at each of ``poses`` (within :data:`START_SHIFT_M` of the start), in their order."""
    return _attitudes_on(_start_contact(scenario, config), poses)


def _attitudes_on(contact: GroundContact | None, poses: tuple[Pose, ...]) -> tuple[Attitude, ...]:
    """The body's attitude at each of ``poses`` on ``contact``'s ground (None: level ground)."""
    return tuple(LEVEL for _ in poses) if contact is None else tuple(contact.attitude(pose) for pose in poses)


def _start_contact(scenario, config: VehicleConfig | None) -> GroundContact | None:
    """The ground round ``scenario``'s start under the vehicle of ``config``: the height field's
    cells within :data:`START_REACH_M` of it, each read as the whole field gives it (None: no relief)."""
    from terrapref.world.height_compiled import height_at
    from terrapref.world.relief import height_field

    if not scenario.has_relief:
        return None
    config = config or VehicleConfig()
    res, (ny, nx) = scenario.resolution_m, scenario.grid_shape
    reach = math.ceil(START_REACH_M / res)
    col, row = math.floor(scenario.start[0] / res), math.floor(scenario.start[1] / res)
    rows, cols = slice(max(0, row - reach), min(ny, row + reach + 1)), slice(max(0, col - reach), min(nx, col + reach + 1))
    part = height_field(scenario.relief, (ny, nx), res, (rows, cols))
    x0, y0 = cols.start * res, rows.start * res

    class Part:  # the field's cells round the start, read as the whole field's (the map's edge where it is one)
        resolution_m = res

        def height_at_point(self, x: float, y: float) -> float:
            return height_at(part, 1.0 / res, x - x0, y - y0)

    return GroundContact(Part(), config)


def _past_by(attitude: Attitude, config: VehicleConfig) -> float:
    """How far ``attitude`` is toward the nearer of ``config``'s limits: 1 at a limit."""
    return max(abs(attitude.roll_rad) / math.radians(config.max_roll_deg), abs(attitude.pitch_rad) / math.radians(config.max_pitch_deg))


def drivable(scenario, config: VehicleConfig | None = None, seeds: int = 0):
    """``scenario`` (a :class:`terrapref.scenario.Scenario`), where a run may begin at its start: a
    start whose ground tips the vehicle of ``config`` (default: the default vehicle) past its roll
    or pitch limit is refused, as one on lethal terrain is (a run would count a tip before it moved);
    so is one where it would tip begun a little to the side or off the heading, as an evaluation's
    seeds after the first begin (:func:`start_poses`; with ``seeds``, where each of that many does),
    and one astride a step higher than it climbs (its rear wheels could not follow: a run would
    count it stuck before it got anywhere).

    Raises:
        ScenarioError: naming the scenario's ``start``.
    """
    from terrapref.errors import ScenarioError

    config = config or VehicleConfig()
    poses = start_poses(scenario.start, seeds)
    contact = _start_contact(scenario, config)
    step = max(contact.step_under(pose) for pose in poses) if contact is not None else 0.0  # where any seed begins
    if step > config.max_step_m:
        raise ScenarioError(
            scenario.source or scenario.name,
            f"({scenario.start[0]:g}, {scenario.start[1]:g}) stands the vehicle astride a step of {step:.2f} m (there, or begun "
            f"a little to its side as an evaluation's later seeds may be), higher than it climbs ({config.max_step_m:g} m): its "
            "rear wheels could not follow its front ones; start it off the step",
            field="start",
        )
    attitudes = _attitudes_on(contact, poses)  # the ground round the start read once, for the step and the tilt
    tipped = [(pose, attitude) for pose, attitude in zip(poses, attitudes, strict=True) if GroundContact.past_limits(attitude, config)]
    if not tipped:
        return scenario
    at_start = tipped[0][0] is poses[0]  # the start itself tips it: said as it is, whatever tips more beside it
    (px, py, pyaw), attitude = tipped[0] if at_start else max(tipped, key=lambda t: _past_by(t[1], config))
    x, y, yaw = scenario.start
    where = (
        ""
        if at_start
        else f" begun {math.hypot(px - x, py - y):.2f} m to its side, {math.degrees(abs(pyaw - yaw)):g} deg off its heading (as an evaluation's later seeds may be),"
    )
    raise ScenarioError(
        scenario.source or scenario.name,
        f"({x:g}, {y:g}){where} stands the vehicle at roll {math.degrees(abs(attitude.roll_rad)):.1f} deg, pitch "
        f"{math.degrees(abs(attitude.pitch_rad)):.1f} deg, past the vehicle's limits ({config.max_roll_deg:g} deg of roll, "
        f"{config.max_pitch_deg:g} of pitch); start it on gentler ground",
        field="start",
    )
