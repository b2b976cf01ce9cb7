"""Where the vehicle stands on its path: at its goal, off the path, or facing away from it.

Every decision passes through this check before the stop rule (terrapref.planner.stop), whatever
rule steers, the way a goal checker sits beside Nav2's controllers rather than inside them:

- ``goal``: the vehicle is within ``goal_tolerance_m`` of the path's last point with no more
  than that left of the path to drive, or has passed the last point (its progress is at the end
  of the path and it stands beyond the line through the last point square to the last segment,
  within ``goal_tolerance_m`` of the last segment's line: a vehicle that went round something at
  the end is not at its goal metres beside it). It commands v = 0 with the reason ``goal`` from then on, until it
  is given a new path. With ``goal_yaw_tolerance_deg`` it first turns in place there until its
  heading is within that of the last segment's direction.
- the approach: near the last point the speed is capped at sqrt(2 a d), d the distance to it
  (straight, or along the path where more is left to drive) and a the braking the stop rule
  counts on (``decel_mps2``), so that the vehicle comes to its goal at a speed it can stop
  from. The cap does not act farther than v^2 / 2a from the goal (2 m at 2 m/s for the default
  braking).
- ``off_path``: farther than ``off_path_m`` from the path (a pose kilometres away, a path given in
  another frame) it commands v = 0 with the reason ``off_path`` until it is back within.
- facing away: where the path a few metres ahead of the vehicle's progress lies behind it (a path
  behind the vehicle, or a start facing the wrong way), pure pursuit toward that point would
  drive straight away from it; the vehicle instead turns toward it at the largest yaw rate, at
  :data:`TURN_MPS`, on an arc the stop rule finds free (else it stops, ``no_free_way``).

The settings are the stop rule's (:class:`terrapref.planner.stop.StopConfig`): they belong to
the robot (its file's ``stop`` block, a node's parameters), not to a learned model.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from terrapref.planner.stop import StopConfig
from terrapref.scenario.path import ReferencePath
from terrapref.stops import GOAL, OFF_PATH
from terrapref.vehicle import Pose, wrap_angle

TURN_LOOK_M = 2.5  # the point of the path ahead of the progress that must lie in front of the vehicle [m]
TURN_MPS = 0.5  # the speed at which a vehicle facing away from its path turns back to it [m/s]
TURN_GAIN = 2.0  # turning in place at the goal: yaw rate per radian of heading error [1/s]


class PathState(NamedTuple):
    """What the check says of one frame.

    Attributes:
        stop: ``goal`` or ``off_path`` when the vehicle must stand (None: it may drive).
        cap_mps: the fastest the vehicle may go toward its goal [m/s] (inf far from it).
        turn_rps: a yaw rate to drive instead of the steering rule's (turning back to a path
            behind, or turning in place at the goal) [rad/s]; None: the steering rule's.
        turn_mps: the speed with ``turn_rps`` [m/s] (0: in place).
        to_goal_m: the distance from the vehicle to the path's last point [m].
    """

    stop: str | None
    cap_mps: float
    turn_rps: float | None
    turn_mps: float
    to_goal_m: float


class GoalCheck:
    """The check (module docstring) for one planner.

    Args:
        config: the stop rule's settings (goal tolerance, heading tolerance, off-path distance,
            the braking counted on).
        max_yaw_rate_rps: the largest yaw rate a turn may use [rad/s].
    """

    def __init__(self, config: StopConfig, max_yaw_rate_rps: float) -> None:
        self.config = config
        self.max_yaw_rate_rps = float(max_yaw_rate_rps)
        self.reached = False

    def reset(self) -> None:
        """A new path: its goal is not reached yet."""
        self.reached = False

    def check(self, pose: Pose, path: ReferencePath, progress_m: float, lateral_m: float) -> PathState:
        """The state of the vehicle at ``pose`` on ``path``, its progress ``progress_m`` [m] and its
        signed distance from the path there ``lateral_m`` [m] (terrapref.scenario.path.PathTracker)."""
        c = self.config
        x, y, yaw = (float(v) for v in pose)
        ex, ey, ux, uy = path.frame_at(path.length_m)
        to_goal = math.hypot(x - ex, y - ey)
        if self.reached:
            return PathState(GOAL, 0.0, None, 0.0, to_goal)
        if not abs(lateral_m) <= c.off_path_m:  # NaN or inf (a pose too far off to compute) is off the path too
            return PathState(OFF_PATH, 0.0, None, 0.0, to_goal)
        left_m = path.length_m - progress_m  # the path still to drive (a path that ends where it starts is not done at its start)
        beside = abs((y - ey) * ux - (x - ex) * uy)  # from the last segment's line, past its end
        passed = left_m <= 1e-9 and (x - ex) * ux + (y - ey) * uy >= 0.0 and beside <= c.goal_tolerance_m
        if (to_goal <= c.goal_tolerance_m and left_m <= c.goal_tolerance_m) or passed:
            turn = self._turn_at_goal(yaw, math.atan2(uy, ux))
            if turn is not None:
                return PathState(None, 0.0, turn, 0.0, to_goal)
            self.reached = True
            return PathState(GOAL, 0.0, None, 0.0, to_goal)
        cap = math.sqrt(2.0 * c.decel_mps2 * max(to_goal, left_m))
        tx, ty, _, _ = path.frame_at(min(progress_m + TURN_LOOK_M, path.length_m))
        ahead = (tx - x) * math.cos(yaw) + (ty - y) * math.sin(yaw)
        if ahead < 0.0:  # the path ahead lies behind: turn toward it
            left = -(tx - x) * math.sin(yaw) + (ty - y) * math.cos(yaw)
            return PathState(None, cap, math.copysign(self.max_yaw_rate_rps, left), TURN_MPS, to_goal)
        return PathState(None, cap, None, 0.0, to_goal)

    def _turn_at_goal(self, yaw: float, heading: float) -> float | None:
        """The yaw rate that turns the vehicle in place toward ``heading`` [rad] at the goal; None
        when the heading is not checked or is within its tolerance."""
        tolerance = self.config.goal_yaw_tolerance_deg
        if tolerance is None:
            return None
        error = float(wrap_angle(heading - yaw))
        if abs(error) <= math.radians(tolerance):
            return None
        return math.copysign(min(self.max_yaw_rate_rps, TURN_GAIN * abs(error)), error)
