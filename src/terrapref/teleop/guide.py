"""What the driving window tells the driver about the course: progress, the next patch, the
terrain underneath, the label as a turn, where the route is, and where the map ends. No drawing
here."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from terrapref.features import PreferenceSet
from terrapref.scenario.path import ReferencePath
from terrapref.vehicle import Command, Pose, VehicleConfig, integrate_unicycle, wrap_angle
from terrapref.vehicle.ground import Attitude
from terrapref.world import WorldMap

SAMPLE_STEP_M = 0.5
"""Spacing of the path samples searched for patches [m]."""
PATCH_REACH_M = 3.0
"""Terrain this far beside the path counts as a patch on the way [m] (the vehicle is 1.2 m wide;
the preference set reaches about 3 m to each side over its first metres)."""
EDGE_MARGIN_M = 1.0
"""The vehicle stops when its next frame would bring its centre nearer the map's edge than this [m]."""
OFF_ROUTE_M = PATCH_REACH_M
"""Farther than this from the route the vehicle is off it [m]: the patches the display names
(those within :data:`PATCH_REACH_M` of the route) are no longer on its way."""
REJOIN_AHEAD_M = 3.0
"""The way back points at the route this far ahead of its nearest point [m], so that the driver
rejoins it heading along it rather than square to it."""
ON_LINE_M = 0.25
"""Nearer the route than this, the display says the vehicle is on it [m]."""
STANDING_MPS = 0.05
"""Slower than this the vehicle turns on the spot: the display gives no radius [m/s]."""


@dataclass(frozen=True)
class Readout:
    """One frame's heads-up display, in words and numbers.

    Attributes:
        progress_m, length_m: distance along the path so far and in all [m].
        under: the class under the vehicle's centre ("off the map" past the edge).
        next_patch: the class of the next patch on the way, or None past the last one.
        next_patch_m: distance along the path to it [m] (0 while beside it).
        label: the current label (the control set's index).
        turn_deg_s: the label's turn rate [deg/s], positive to the left.
        radius_m: the label's turn radius at the vehicle's speed [m] (inf: straight; 0: standing,
            turning on the spot).
        at_edge: the vehicle is held at the map's edge.
        offset_m: the vehicle's distance from the route [m] (the cross-track error, >= 0).
        foot_rad: the bearing of the route's nearest point from the vehicle's heading [rad],
            positive to the left (which side the route lies).
        rejoin_rad: the bearing of the way back onto the route (:data:`REJOIN_AHEAD_M` ahead
            of its nearest point) from the vehicle's heading [rad], positive to the left.
    """

    progress_m: float
    length_m: float
    under: str
    next_patch: str | None
    next_patch_m: float
    label: int
    turn_deg_s: float
    radius_m: float
    at_edge: bool = False
    offset_m: float = 0.0
    foot_rad: float = 0.0
    rejoin_rad: float = 0.0

    @property
    def off_route(self) -> bool:
        """The vehicle is farther from the route than :data:`OFF_ROUTE_M`."""
        return self.offset_m > OFF_ROUTE_M

    def warning(self) -> str | None:
        """What to do when off the route ("OFF ROUTE: 7 m away, turn left"); None on it."""
        if not self.off_route:
            return None
        degrees = math.degrees(self.rejoin_rad)
        way = "ahead" if abs(degrees) < 20.0 else f"turn {'left' if degrees > 0 else 'right'}"
        return f"OFF ROUTE: {self.offset_m:.0f} m away, {way}" + (" (it is behind you)" if abs(degrees) > 90.0 else "")

    def lines(self) -> list[str]:
        share = self.progress_m / self.length_m if self.length_m > 0 else 0.0
        if self.off_route:  # the patches are counted along the route, which the vehicle is not on
            patch = "next patch: back on the route first"
        elif self.next_patch is None:
            patch = "next patch: none ahead"
        elif self.next_patch_m <= SAMPLE_STEP_M:
            patch = f"patch here: {self.next_patch}"
        else:
            patch = f"next patch: {self.next_patch} in {self.next_patch_m:.0f} m"
        side = "left" if self.turn_deg_s > 0.05 else "right" if self.turn_deg_s < -0.05 else ""
        radius = f"a {self.radius_m:.1f} m radius" if self.radius_m > 0 else "on the spot"
        turn = f"label {self.label}: {f'{side} {abs(self.turn_deg_s):.0f} deg/s, {radius}' if side else 'straight'}"
        if self.offset_m < ON_LINE_M:
            route = "route: on it"
        else:
            route = f"route: {self.offset_m:.1f} m to your {'left' if self.foot_rad > 0 else 'right'}"
        return [
            f"path {self.progress_m:5.1f} / {self.length_m:.0f} m ({share:.0%})",
            patch,
            f"under the vehicle: {self.under}",
            turn,
            route,
        ]


class CourseGuide:
    """Computed once per course: the patches along the path and each label's turn."""

    def __init__(self, world: WorldMap, path: ReferencePath, prefs: PreferenceSet) -> None:
        self.world = world
        self.path = path
        self.names = {c.id: c.name for c in world.classes.classes}
        background = world.classes.background_id
        s = np.arange(0.0, path.length_m + 1e-9, SAMPLE_STEP_M)
        offsets = np.arange(-PATCH_REACH_M, PATCH_REACH_M + 1e-9, SAMPLE_STEP_M)
        heading = path.heading_at(s)
        normal = np.stack([-np.sin(heading), np.cos(heading)], axis=-1)  # (S, 2), to the left
        points = path.point_at(s)[:, None, :] + offsets[None, :, None] * normal[:, None, :]
        ids = world.class_at(points)  # (S, O); 255 off the map
        patch = (ids != background) & (ids != 255)
        # Per sample, the patch class nearest the centre line, or -1.
        order = np.argsort(np.abs(offsets), kind="stable")
        first = np.argmax(patch[:, order], axis=1)
        nearest = ids[np.arange(len(s)), order[first]].astype(int)
        self.s = s
        self.cls = np.where(patch.any(axis=1), nearest, -1)
        # For each sample, the index of the first patch sample at or after it (len(s): none).
        nxt = np.full(len(s) + 1, len(s))
        for i in range(len(s) - 1, -1, -1):
            nxt[i] = i if self.cls[i] >= 0 else nxt[i + 1]
        self.next_index = nxt[:-1]
        self.w_rps = np.asarray(prefs.config.control.w_rps, dtype=float)

    def readout(self, pose: Pose, progress_m: float, label: int, at_edge: bool = False, speed_mps: float = 1.0) -> Readout:
        """The display for the vehicle at ``pose`` having come ``progress_m`` [m] along the path
        (the simulation's progress) at ``speed_mps`` [m/s], its stick on ``label``."""
        i = min(int(math.ceil(progress_m / SAMPLE_STEP_M - 1e-9)), len(self.s) - 1)
        # Beside a patch now, if the sample just passed has one.
        j = i - 1 if i > 0 and self.cls[i - 1] >= 0 else int(self.next_index[i])
        if j >= len(self.s):
            name, dist = None, 0.0
        else:
            name, dist = self.names.get(int(self.cls[j]), "?"), max(0.0, float(self.s[j]) - progress_m)
        under_id = int(self.world.class_at(np.array(pose[:2])))
        under = "off the map" if under_id == 255 else self.names.get(under_id, "?")
        offset_m, foot_rad, rejoin_rad = self.where_the_route_is(pose, progress_m)
        return Readout(
            progress_m,
            self.path.length_m,
            under,
            name,
            dist,
            label,
            math.degrees(self.w_rps[label]),
            turn_radius_m(speed_mps, float(self.w_rps[label])),
            at_edge,
            offset_m,
            foot_rad,
            rejoin_rad,
        )

    def where_the_route_is(self, pose: Pose, progress_m: float) -> tuple[float, float, float]:
        """(distance [m], bearing of its nearest point [rad], bearing of the way back [rad]): the
        route seen from ``pose``, bearings from the heading and positive to the left.

        The nearest point is searched near ``progress_m`` (as the simulation tracks progress),
        so that a path passing near itself cannot pull the way back to a later stretch.
        """
        x, y, yaw = pose
        s, offset = self.path.project(np.array([x, y]), progress_m - 2.0, progress_m + 10.0)
        fx, fy = self.path.point_at(float(s))
        tx, ty = self.path.point_at(float(min(s + REJOIN_AHEAD_M, self.path.length_m)))
        return abs(float(offset)), _bearing(fx - x, fy - y, yaw), _bearing(tx - x, ty - y, yaw)


def turn_radius_m(speed_mps: float, w_rps: float) -> float:
    """The radius [m] a vehicle at ``speed_mps`` [m/s] turns at ``w_rps`` [rad/s]: v / |w|
    (inf: straight; 0: standing, below :data:`STANDING_MPS`, it turns on the spot)."""
    if w_rps == 0.0:
        return math.inf
    return abs(speed_mps) / abs(w_rps) if abs(speed_mps) >= STANDING_MPS else 0.0


def _bearing(dx: float, dy: float, yaw: float) -> float:
    """The direction of (dx, dy) [m] from heading ``yaw`` [rad], in [-pi, pi), positive to the left."""
    return wrap_angle(math.atan2(dy, dx) - yaw)


def stays_on_map(
    world: WorldMap, pose: Pose, command: Command, period_s: float, margin_m: float = EDGE_MARGIN_M, brake_m: float = 0.0
) -> bool:
    """Whether holding ``command`` for ``period_s``, then braking over ``brake_m`` along the heading
    reached, keeps the vehicle's centre ``margin_m`` inside the map, or at least takes it no nearer
    the edge (a vehicle already within the margin may drive back in)."""
    w_m, h_m = world.size_m

    def clearance(x: float, y: float) -> float:
        return min(x, w_m - x, y, h_m - y)

    x, y, yaw = integrate_unicycle(pose, command, period_s)
    x, y = x + brake_m * math.cos(yaw), y + brake_m * math.sin(yaw)
    after = clearance(x, y)
    return after >= margin_m or after >= clearance(pose[0], pose[1])


NEAR_TIPPING = 0.8  # the share of its roll or pitch limit at which the vehicle is said to be near tipping


def attitude_readout(attitude: Attitude, vehicle: VehicleConfig) -> tuple[str, str | None]:
    """On relief, the body's roll and pitch in words with the limits past which it tips (a line of
    the heads-up display), and a warning once either is within :data:`NEAR_TIPPING` of its limit
    (None before)."""
    roll, pitch = math.degrees(attitude.roll_rad), math.degrees(attitude.pitch_rad)
    side = "left side up" if roll > 0 else "right side up"
    nose = "nose down" if pitch > 0 else "nose up"
    line = f"roll {abs(roll):.0f} deg {side} (tips at {vehicle.max_roll_deg:g}), pitch {abs(pitch):.0f} deg {nose} (tips at {vehicle.max_pitch_deg:g})"
    if abs(roll) >= NEAR_TIPPING * vehicle.max_roll_deg:
        return line, f"NEAR TIPPING: roll {abs(roll):.0f} of {vehicle.max_roll_deg:g} deg, turn down the slope"
    if abs(pitch) >= NEAR_TIPPING * vehicle.max_pitch_deg:
        return line, f"NEAR TIPPING: pitch {abs(pitch):.0f} of {vehicle.max_pitch_deg:g} deg, take it at an angle or go round"
    return line, None
