"""The simulation loop: a vehicle ticking at 30 Hz and a camera frame, with its pose, at 10 Hz.

Each camera frame is one decision: a driver sees the :class:`Frame` and returns a command,
which the vehicle's controller holds until the next frame (SPEC section 4).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from terrapref.camera import CameraConfig, PinholeCamera, SegmentationRenderer, SegmentationView
from terrapref.scenario import Scenario
from terrapref.scenario.path import ReferencePath
from terrapref.stops import GOAL as GOAL_REASON
from terrapref.stops import UNSAID, stop_reason_of
from terrapref.vehicle import Command, Pose, Vehicle, VehicleConfig
from terrapref.vehicle.ground import LEVEL, Attitude
from terrapref.world import WorldMap, rasterise


@dataclass(frozen=True)
class SimConfig:
    """Loop timing and episode limits.

    Attributes:
        camera_rate_hz: segmentation frames (and decisions) per second [Hz]; must divide the
            vehicle's control rate.
        goal_radius_m: the run is complete within this distance of the last waypoint [m].
        time_limit_s: episode time limit [s]; None gives the time to drive the path twice at
            1 m/s, plus 60 s.
        stopped_limit_s: the run ends once the vehicle has stood still this long without a
            break (a stop whose reason does not clear in a world that does not change);
            None: only the goal or the time limit ends it [s].
        vehicle: the vehicle's controller rate and limits.
    """

    camera_rate_hz: float = 10.0
    goal_radius_m: float = 2.0
    time_limit_s: float | None = None
    stopped_limit_s: float | None = 20.0
    vehicle: VehicleConfig = field(default_factory=VehicleConfig)

    def time_limit(self, path_length_m: float) -> float:
        """The episode time limit [s] on a path this long."""
        return self.time_limit_s if self.time_limit_s is not None else 2.0 * path_length_m / 1.0 + 60.0

    @classmethod
    def driving(cls, vehicle: VehicleConfig | None) -> SimConfig:
        """The default simulation of ``vehicle`` (None: the default vehicle, a field UGV)."""
        return cls(vehicle=vehicle or VehicleConfig())

    @classmethod
    def paper(cls) -> SimConfig:
        """The paper's setting: its vehicle (:meth:`VehicleConfig.paper`), the rest as default."""
        return cls(vehicle=VehicleConfig.paper())

    def __post_init__(self) -> None:
        ratio = self.vehicle.control_rate_hz / self.camera_rate_hz
        if self.camera_rate_hz <= 0 or abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ValueError("camera_rate_hz must divide the vehicle's control rate")
        if self.stopped_limit_s is not None and not (math.isfinite(self.stopped_limit_s) and self.stopped_limit_s > 0):
            raise ValueError("stopped_limit_s must be None or a finite number > 0")

    @property
    def ticks_per_frame(self) -> int:
        return round(self.vehicle.control_rate_hz / self.camera_rate_hz)


@dataclass(frozen=True)
class Frame:
    """What a driver receives at each camera frame.

    Attributes:
        index: frame number since reset.
        time_s: simulation time [s].
        view: the segmentation image, rendered as far as a driver reads it (``image`` for the
            whole frame).
        pose: vehicle pose in the world frame.
        waypoints: the reference path, shape (N, 2) [m].
        speed_mps: the vehicle's forward speed, as its odometry gives it [m/s].
        attitude: the body's height, pitch and roll on the ground (level on flat ground).
    """

    index: int
    time_s: float
    view: SegmentationView
    pose: Pose
    waypoints: np.ndarray
    speed_mps: float = 0.0
    attitude: Attitude = LEVEL

    @property
    def image(self) -> np.ndarray:
        """The segmentation image, shape (H, W) uint8 class ids."""
        return self.view.image

    @property
    def depth(self) -> np.ndarray | None:
        """The depth image, shape (H, W) float32 [m along the optical axis, NaN where nothing is
        seen, REP 118]."""
        return self.view.depth


class Driver(Protocol):
    """Anything that turns frames into commands: the synthetic demonstrator, a human, a planner.

    A driver that stops for a reason (terrapref.planner.stop) says which in ``stop_reason``
    after :meth:`act` (None while it drives); the loop counts stops by it.
    """

    def reset(self, scenario: Scenario, rng: np.random.Generator) -> None: ...

    def act(self, frame: Frame) -> Command: ...


class Simulation:
    """The world, the vehicle and the camera of one scenario, stepped one camera frame at a time."""

    def __init__(
        self,
        scenario: Scenario,
        camera: CameraConfig | None = None,
        config: SimConfig | None = None,
        world: WorldMap | None = None,
    ) -> None:
        self.scenario = scenario
        self.config = config or SimConfig()
        self.world = world if world is not None else rasterise(scenario)
        self.camera = PinholeCamera(camera)
        self.renderer = SegmentationRenderer(self.camera, self.world)
        self.path = ReferencePath(scenario.waypoints)
        self._lethal = frozenset(int(i) for i in scenario.classes.lethal_ids)
        self._across = tuple(float(a) for a in self.config.vehicle.footprint_m)
        self.time_limit_s = self.config.time_limit(self.path.length_m)
        self.reset()

    def reset(self, pose: Pose | None = None) -> Frame:
        """Put the vehicle at ``pose`` (default: the scenario's start) and render the first frame."""
        ground = self.world if self.world.has_relief else None
        self.vehicle = Vehicle(Pose(*(self.scenario.start if pose is None else pose)), self.config.vehicle, ground=ground)
        self.tick = 0
        self.frame_index = 0
        self.progress_m = self.path.project(self.vehicle.pose[:2], 0.0, 5.0)[0]
        self._on_lethal = self._in_contact(self.vehicle.pose)
        self.started_in_contact = self._on_lethal
        self.collisions = int(self._on_lethal)  # a start in contact with lethal terrain is one
        self.contact_s = 0.0
        self.contact_m = 0.0
        self.tips = int(self.vehicle.tipped)  # entries past the roll or pitch limit (a start past one is one)
        self.stuck = 0  # times a step too high held the vehicle
        self.max_roll_deg = self.max_pitch_deg = 0.0  # the largest |roll| and |pitch| of any tick [deg]
        self._relief_tick()
        self.stops: dict[str, float] = {}  # seconds stood still, by the reason given
        self.stop_count = 0  # times the vehicle came to a stop
        self.stopped_s = 0.0  # how long it has stood still without a break
        self.trace: list[Pose] = [self.vehicle.pose]
        self.speeds: list[float] = [self.vehicle.speed_mps]  # the vehicle's speed at each tick [m/s]
        self.commands: list[Command] = []
        return self.frame()

    @property
    def time_s(self) -> float:
        return self.tick / self.config.vehicle.control_rate_hz

    def frame(self) -> Frame:
        pose = self.vehicle.pose
        return Frame(
            self.frame_index,
            self.time_s,
            SegmentationView(self.renderer, pose, attitude=self.vehicle.attitude),
            pose,
            self.scenario.waypoints,
            self.vehicle.speed_mps,
            self.vehicle.attitude,
        )

    def _in_contact(self, pose: Pose) -> bool:
        """Whether lethal terrain lies under any point of the footprint at ``pose``, in plain floats
        (asked at every tick: a few array calls would cost more than the vehicle's own tick)."""
        x, y, yaw = pose
        sin, cos, class_at = math.sin(yaw), math.cos(yaw), self.world.class_at_point
        return any(class_at(x - a * sin, y + a * cos) in self._lethal for a in self._across)

    def step(self, command: Command, stop_reason: str | None = None) -> Frame:
        """Hold ``command`` for one camera period (several controller ticks) and render the next frame.

        A command of v = 0 is a stop, counted under ``stop_reason`` (the driver's, :data:`UNSAID`
        when it gives none). Contact with lethal terrain is counted at every tick wherever the
        footprint is: each entry a collision, and the time and distance in contact.
        """
        self.vehicle.set_command(Command(*command))
        self.commands.append(self.vehicle.command)
        c = self.config
        period_s = c.ticks_per_frame * c.vehicle.dt_s
        if self.vehicle.command.v == 0.0:
            if self.stopped_s == 0.0:
                self.stop_count += 1
            reason = stop_reason or UNSAID
            self.stops[reason] = self.stops.get(reason, 0.0) + period_s
            self.stopped_s += period_s
        else:
            self.stopped_s = 0.0
        poses, steps_m = [], []
        for _ in range(c.ticks_per_frame):
            tipped, stuck = self.vehicle.tipped, self.vehicle.stuck
            pose = self.vehicle.tick()
            if self.vehicle.contact is not None:
                self.tips += self.vehicle.tipped and not tipped
                self.stuck += self.vehicle.stuck and not stuck
                self._relief_tick()
            self.tick += 1
            self.trace.append(pose)
            self.speeds.append(self.vehicle.speed_mps)
            poses.append(pose)
            steps_m.append(self.vehicle.step_m)
        for contact, step_m in zip(map(self._in_contact, poses), steps_m, strict=True):
            if contact:
                self.collisions += not self._on_lethal
                self.contact_s += c.vehicle.dt_s
                self.contact_m += step_m
            self._on_lethal = bool(contact)
        # Progress along the path, searched in a window so a path passing near itself cannot capture it.
        self.progress_m = max(self.progress_m, self.path.project(self.vehicle.pose[:2], self.progress_m - 2.0, self.progress_m + 10.0)[0])
        self.frame_index += 1
        return self.frame()

    def _relief_tick(self) -> None:
        """Keep the largest roll and pitch so far."""
        attitude = self.vehicle.attitude
        self.max_roll_deg = max(self.max_roll_deg, abs(math.degrees(attitude.roll_rad)))
        self.max_pitch_deg = max(self.max_pitch_deg, abs(math.degrees(attitude.pitch_rad)))

    @property
    def incidents(self) -> int:
        """Entries onto lethal terrain, tips and times stuck so far: what counts against a run's
        safety (as :attr:`terrapref.evaluation.scoring.RunMetrics.incidents` counts a run's)."""
        return self.collisions + self.tips + self.stuck

    @property
    def reached_goal(self) -> bool:
        end = self.path.waypoints[-1]
        x, y, _ = self.vehicle.pose
        near = math.hypot(x - end[0], y - end[1]) <= self.config.goal_radius_m
        return near and self.progress_m >= 0.5 * self.path.length_m

    @property
    def timed_out(self) -> bool:
        return self.time_s >= self.time_limit_s

    @property
    def gave_up(self) -> bool:
        """The vehicle has stood still for ``stopped_limit_s`` without a break."""
        limit = self.config.stopped_limit_s
        return limit is not None and self.stopped_s >= limit - 1e-9

    @property
    def done(self) -> bool:
        return self.reached_goal or self.timed_out or self.gave_up

    @property
    def ended(self) -> str:
        """How the run ended (:data:`ENDINGS`): at the goal, stopped for good, or at the time limit; ``running`` before."""
        return GOAL if self.reached_goal else STOPPED if self.gave_up else TIME_LIMIT if self.timed_out else "running"


GOAL, STOPPED, TIME_LIMIT = "goal", "stopped", "time limit"
ENDINGS = (GOAL, STOPPED, TIME_LIMIT)  # how a run ends (EpisodeLog.ended)


@dataclass(frozen=True)
class GoalStop:
    """How a driver that stops at its own goal (the planner's goal check) came to stand there,
    driven on past the point where the run was scored complete (:func:`settle`).

    Attributes:
        stopped: it stood still, saying ``goal``, within the time it was given.
        after_s: from the run's completion to standing still (or the time given) [s].
        from_end_m: how far from the path's last point it stood (or was when the time ran out) [m].
    """

    stopped: bool
    after_s: float
    from_end_m: float


@dataclass
class EpisodeLog:
    """A driven run: the 30 Hz pose trace and the per-frame commands.

    Attributes:
        trace: poses at every controller tick, shape (T, 3) [m, m, rad].
        commands: command held after each frame, shape (F, 2) [m/s, rad/s].
        completed: reached the last waypoint before the time limit.
        collisions: entries of the footprint onto lethal terrain (a start in contact is one).
        duration_s: simulated time [s].
        ended: how the run ended (:data:`ENDINGS`).
        contact_s: time with lethal terrain under the footprint [s].
        contact_m: distance driven with lethal terrain under the footprint [m].
        stops: seconds stood still, by the reason the driver gave.
        stop_count: times the vehicle came to a stop.
        progress_m: how far along the path the vehicle got [m].
        speeds: the vehicle's speed at every controller tick, shape (T,) [m/s]; None: not kept.
        goal_stop: how the driver came to stand at its goal after the run completed, for a
            driver watched for it (:func:`settle`); None otherwise.
        tips: entries past the vehicle's roll or pitch limit (terrapref.vehicle.ground).
        stuck: times a step higher than the vehicle climbs held it.
        max_roll_deg: the largest |roll| of any controller tick [deg].
        max_pitch_deg: the largest |pitch| of any controller tick [deg].
    """

    scenario: str
    trace: np.ndarray
    commands: np.ndarray
    completed: bool
    collisions: int
    duration_s: float
    ended: str = GOAL
    contact_s: float = 0.0
    contact_m: float = 0.0
    stops: dict[str, float] = field(default_factory=dict)
    stop_count: int = 0
    progress_m: float = 0.0
    speeds: np.ndarray | None = None
    goal_stop: GoalStop | None = None
    tips: int = 0
    stuck: int = 0
    max_roll_deg: float = 0.0
    max_pitch_deg: float = 0.0

    @classmethod
    def of(cls, sim: Simulation) -> EpisodeLog:
        """The log of the episode ``sim`` has driven since its last reset."""
        return cls(
            scenario=sim.scenario.name,
            trace=np.array(sim.trace, dtype=float),
            commands=np.array(sim.commands, dtype=float).reshape(-1, 2),
            completed=sim.reached_goal,
            collisions=sim.collisions,
            duration_s=sim.time_s,
            ended=sim.ended,
            contact_s=sim.contact_s,
            contact_m=sim.contact_m,
            stops=dict(sim.stops),
            stop_count=sim.stop_count,
            progress_m=float(sim.progress_m),
            speeds=np.array(sim.speeds, dtype=float),
            tips=sim.tips,
            stuck=sim.stuck,
            max_roll_deg=sim.max_roll_deg,
            max_pitch_deg=sim.max_pitch_deg,
        )

    def summary(self) -> dict:
        """What a recording's metadata keeps of the run (on relief, its tips, times stuck and
        largest roll and pitch too)."""
        summary = {
            "completed": self.completed,
            "collisions": self.collisions,
            "duration_s": round(self.duration_s, 3),
            "contact_s": round(self.contact_s, 3),
            "contact_m": round(self.contact_m, 3),
        }
        if self.tips or self.stuck or self.max_roll_deg or self.max_pitch_deg:
            summary.update(self.relief_summary())
        return summary

    def relief_summary(self) -> dict:
        """The run's tips, times stuck and largest roll and pitch [deg]."""
        return {
            "tips": self.tips,
            "stuck": self.stuck,
            "max_roll_deg": round(self.max_roll_deg, 2),
            "max_pitch_deg": round(self.max_pitch_deg, 2),
        }


def run_episode(sim: Simulation, driver: Driver, rng: np.random.Generator, start: Pose | None = None) -> EpisodeLog:
    """Drive one episode to the goal or the time limit."""
    frame = sim.reset(start)
    driver.reset(sim.scenario, rng)
    while not sim.done:
        command = driver.act(frame)
        frame = sim.step(command, stop_reason_of(driver))
    return EpisodeLog.of(sim)


def settle(sim: Simulation, driver: Driver, settle_s: float) -> GoalStop:
    """Drive ``sim`` on from where its episode ended for up to ``settle_s`` [s], until ``driver``
    stands still saying ``goal`` (a planner's goal check): how it came to stand at its goal, for a
    run that completed (:func:`run_episode`'s log holds the run up to its completion)."""
    start_s, end = sim.time_s, sim.path.waypoints[-1]

    def from_end_m() -> float:
        return round(math.hypot(sim.vehicle.pose.x - end[0], sim.vehicle.pose.y - end[1]), 3)

    frame = sim.frame()
    while sim.time_s - start_s < settle_s - 1e-9:
        command = driver.act(frame)
        reason = stop_reason_of(driver)
        if reason == GOAL_REASON and command[0] == 0.0 and sim.vehicle.speed_mps == 0.0:
            return GoalStop(True, round(sim.time_s - start_s, 3), from_end_m())
        frame = sim.step(command, reason)
    return GoalStop(False, round(sim.time_s - start_s, 3), from_end_m())
