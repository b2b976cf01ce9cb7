"""What the driving window tells the driver about the course: progress, the next patch, the
terrain underneath, the label as a turn, and where the map ends. No drawing here."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from terrapref.features import PreferenceSet
from terrapref.scenario.path import ReferencePath
from terrapref.vehicle import Command, Pose, integrate_unicycle
from terrapref.world import WorldMap

SAMPLE_STEP_M = 0.5
"""Spacing of the path samples searched for patches [m]."""
PATCH_REACH_M = 3.0
"""Terrain this far beside the path counts as a patch on the way [m] (the vehicle is 1.2 m wide;
the preference set reaches about 3 m to each side over its first metres)."""
EDGE_MARGIN_M = 1.0
"""The vehicle stops when its next frame would bring its centre nearer the map's edge than this [m]."""


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
        radius_m: the label's turn radius at the control set's speed [m] (inf: straight).
        at_edge: the vehicle is held at the map's edge.
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

    def lines(self) -> list[str]:
        share = self.progress_m / self.length_m if self.length_m > 0 else 0.0
        if self.next_patch is None:
            patch = "next patch: none ahead"
        elif self.next_patch_m <= SAMPLE_STEP_M:
            patch = f"patch here: {self.next_patch}"
        else:
            patch = f"next patch: {self.next_patch} in {self.next_patch_m:.0f} m"
        side = "left" if self.turn_deg_s > 0.05 else "right" if self.turn_deg_s < -0.05 else ""
        turn = f"label {self.label}: {f'{side} {abs(self.turn_deg_s):.0f} deg/s, a {self.radius_m:.1f} m radius' if side else 'straight'}"
        return [f"path {self.progress_m:5.1f} / {self.length_m:.0f} m ({share:.0%})", patch, f"under the vehicle: {self.under}", turn]


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
        control = prefs.config.control
        w = np.asarray(control.w_rps, dtype=float)
        self.turn_deg_s = np.degrees(w)
        with np.errstate(divide="ignore"):
            self.radius_m = np.where(w != 0.0, control.v_mps / np.abs(w), np.inf)

    def readout(self, pose: Pose, progress_m: float, label: int, at_edge: bool = False) -> Readout:
        i = min(int(math.ceil(progress_m / SAMPLE_STEP_M - 1e-9)), len(self.s) - 1)
        # Beside a patch now, if the sample just passed has one.
        j = i - 1 if i > 0 and self.cls[i - 1] >= 0 else int(self.next_index[i])
        if j >= len(self.s):
            name, dist = None, 0.0
        else:
            name, dist = self.names.get(int(self.cls[j]), "?"), max(0.0, float(self.s[j]) - progress_m)
        under_id = int(self.world.class_at(np.array(pose[:2])))
        under = "off the map" if under_id == 255 else self.names.get(under_id, "?")
        return Readout(progress_m, self.path.length_m, under, name, dist, label, float(self.turn_deg_s[label]), float(self.radius_m[label]), at_edge)


def stays_on_map(world: WorldMap, pose: Pose, command: Command, period_s: float, margin_m: float = EDGE_MARGIN_M) -> bool:
    """Whether holding ``command`` for ``period_s`` keeps the vehicle's centre ``margin_m`` inside
    the map, or at least takes it no nearer the edge (a vehicle already within the margin may
    drive back in)."""
    w_m, h_m = world.size_m

    def clearance(x: float, y: float) -> float:
        return min(x, w_m - x, y, h_m - y)

    x, y, _ = integrate_unicycle(pose, command, period_s)
    after = clearance(x, y)
    return after >= margin_m or after >= clearance(pose[0], pose[1])
