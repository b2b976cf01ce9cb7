"""The vehicle: a controller that holds the last command between ticks, and its body on the
ground (flat, or on relief: terrapref.vehicle.ground)."""

from __future__ import annotations

from terrapref.vehicle.ground import LEVEL, Ground, GroundContact
from terrapref.vehicle.kinematics import Command, Pose, VehicleConfig, integrate_unicycle, wrap_angle


class Vehicle:
    """A differential-drive vehicle whose controller holds the last command between ticks.

    The yaw rate follows the command at once; the forward speed moves toward it within the
    acceleration limits, so ``speed_mps`` (what the vehicle does) may differ from
    ``command.v`` (what it was told). On ``ground`` with relief (terrapref.vehicle.ground) the
    body takes its attitude from the ground each tick, a grade caps its speed, a step too high
    ahead, or on any wheel's way, holds it where it stands (``stuck``: turning in place still
    possible where no wheel's way climbs one) and an attitude past its limits is ``tipped``;
    without it the ground is the plane z = 0.
    """

    def __init__(self, pose: Pose, config: VehicleConfig | None = None, speed_mps: float = 0.0, ground: Ground | None = None) -> None:
        self.config = config or VehicleConfig()
        self.pose = Pose(*pose)
        self.command = Command(0.0, 0.0)
        self.speed_mps = min(max(float(speed_mps), 0.0), self.config.max_speed_mps)
        self.step_m = 0.0  # the distance driven in the last tick [m]
        self.contact = GroundContact(ground, self.config) if ground is not None else None
        self.stuck = False  # a step too high ahead held it in the last tick
        self._settle()

    def set_command(self, cmd: Command) -> None:
        """Latch a new command, clipped to the vehicle's limits; it is held until the next one."""
        c = self.config
        v = min(max(float(cmd.v), 0.0), c.max_speed_mps)
        w = min(max(float(cmd.w), -c.max_yaw_rate_rps), c.max_yaw_rate_rps)
        self.command = Command(v, w)

    def tick(self) -> Pose:
        """Advance one controller period (1 / control_rate_hz) with the held command: the speed
        ramps within the limits (the distance of the period is its mean speed's) and the yaw rate
        is the command's."""
        c, v0, contact = self.config, self.speed_mps, self.contact
        v1 = c.next_speed(v0, self.command.v if contact is None else min(self.command.v, self.top_speed_mps))
        at_once = (c.max_accel_mps2 if v1 > v0 else c.max_decel_mps2) is None
        v = v1 if at_once or v0 == v1 else 0.5 * (v0 + v1)
        self.stuck = contact is not None and v > 0.0 and contact.blocked(self.pose)
        if self.stuck:
            v1 = v = 0.0
        pose = self._move(v)
        if contact is not None and contact.climbs(self.pose, pose):  # a wheel's way climbs a step: turn in place, or hold
            turn = self._move(0.0) if v > 0.0 else None
            pose = turn if turn is not None and not contact.climbs(self.pose, turn) else self.pose
            self.stuck, v1, v = True, 0.0, 0.0
        self.speed_mps = v1
        self.step_m = v * c.dt_s
        self.pose = pose
        self._settle()
        return self.pose

    def _move(self, v: float) -> Pose:
        """The pose one controller period on at forward speed ``v`` [m/s] and the held yaw rate."""
        x, y, yaw = integrate_unicycle(self.pose, Command(v, self.command.w), self.config.dt_s)
        return Pose(x, y, wrap_angle(yaw))

    def _settle(self) -> None:
        """The body's attitude on the ground at its pose, whether it has tipped, and its top speed there."""
        if self.contact is None:
            self.attitude, self.tipped, self.top_speed_mps = LEVEL, False, self.config.max_speed_mps
            return
        self.attitude = self.contact.attitude(self.pose)
        self.tipped = self.contact.tipped(self.attitude)
        self.top_speed_mps = self.contact.top_speed_mps(self.attitude)
