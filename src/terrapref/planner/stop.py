"""When the planner stops: the one rule every decision passes through (SPEC 18).

A stop is a decision with a reason, not a failure to hide. After the driving rule has chosen
its command, the planner commands v = 0 instead when:

- ``no_free_way``: no way ahead keeps the footprint on ground that is seen and not lethal over
  the stopping distance. Where ground past the vehicle's limits by its geometry (a slope it would
  tip on, a step it cannot climb: terrapref.groundmap.height) is what closes them, the ways
  being free were that ground read by its class alone, the stop says so: ``no_free_way:geometry``. A vehicle whose footprint is on lethal terrain already stands there
  too: under pose noise, "on it" and "just short of it" cannot be told apart, and driving on
  from just short of it is what the rule exists to prevent. The ways are arcs of constant yaw rate across the stick's range, at
  the commanded speed; the stopping distance is what the vehicle covers before it stands
  (``reaction_s`` at that speed, then braking at ``decel_mps2``) plus ``margin_m``. Ground is
  read from the ground map the planner keeps (the steering rule's, or, for a rule that reads
  none, a small one of the stop rule's settings). Unknown ground (never seen, 255, beyond the camera's range) is never free where the
  camera looks from the pose it stands at; under and right beside the vehicle, where it cannot
  look, the rule goes by what the map remembers from earlier frames, and a vehicle that starts
  on ground it has never seen takes that ground as the ground it stands on.
- ``blind``: for ``blind_after_s`` or longer, each frame showed less than ``seen_share`` of the
  ground ahead (the footprint's width, from the camera's near edge to ``look_m``; with a depth
  image, ground with a return): a lens covered, a segmentation that failed, a range cut short, a
  depth camera that sees nothing.
- ``stale``: no fresh frame for longer than the command is held (the runtime's and the
  simulated robot's ``hold_s``), or, on a robot's node, no frame decided on for the watchdog's
  limit by the wall clock: they give the rule the time and the last frame's (:meth:`StopRule.stale`),
  as no frame arrives to check.

Where it does not stop, the command is driven on its own way if that is free, else on the free
way nearest to it (the same speed, the nearest yaw rate: :meth:`StopRule.way_rps`; the planner
drives it slower where it turns harder sideways than its speed rule's lateral limit: the same
arc): a vehicle never drives a way the rule reads as blocked because another was free.

The planner moves on by itself once the reason has cleared (a free way, for ``resume_after_s``). The reasons'
names are terrapref.stops'.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from terrapref.camera import PinholeCamera, PixelSet, SegmentationView
from terrapref.errors import finite_number
from terrapref.groundmap.columns import TerrainColumns
from terrapref.groundmap.map import GroundMap
from terrapref.groundmap.map_compiled import UNSETTLED, MapLayers, map_decide
from terrapref.groundmap.settings import MapSettings
from terrapref.records import to_plain
from terrapref.rules.base import StopRunner, Verdict
from terrapref.stops import BLIND, NO_FREE_WAY, NO_FREE_WAY_GEOMETRY, held_too_long
from terrapref.terrain import UNKNOWN
from terrapref.vehicle import Pose

# Past these a setting no longer means what it says: a way checked in steps longer than half a
# metre passes over a lethal strip between two of them; a look at ground 50 m ahead, a few hundred
# ways or an evidence past what the map's votes add up to are settings no robot means.
STOP_BOUNDS = {"step_m": 0.5, "look_m": 50.0, "arcs": 201, "decel_mps2": 20.0, "blind_after_s": 10.0, "lethal_evidence": 1e6}
STOP_BOUND_REASONS = {
    "step_m": "a longer step passes over a lethal strip between two points it checks",
    "look_m": "farther than a camera shows the ground",
    "arcs": "more ways than a frame's time allows",
    "decel_mps2": "about twice the braking of a wheeled vehicle",
    "blind_after_s": "blind that long, the vehicle has not stopped for it",
    "lethal_evidence": "more than the map's votes add up to",
}


@dataclass(frozen=True)
class StopConfig:
    """When the planner stops (module docstring).

    Attributes:
        reaction_s: from a frame to the brakes acting: a camera period and a controller tick,
            rounded up [s].
        decel_mps2: the braking the rule counts on [m/s^2].
        margin_m: kept between the stopped footprint and lethal or unseen ground [m].
        blind_after_s: how long frames may see too little of the ground ahead before a stop [s].
        resume_after_s: once stopped for want of a free way, how long a way must stay free
            before the planner moves on [s]: a way that flickers free for a frame (label noise)
            would otherwise let the vehicle creep, a frame's travel at a time, toward what
            stopped it.
        seen_share: a frame sees enough when at least this share of the ground ahead shows ground.
        look_m: the ground ahead a frame must show runs from the camera's near edge to this far [m].
        arcs: how many ways (arcs of constant yaw rate across the stick's range) are checked.
        step_m: spacing of the points checked along each way [m].
        lethal_evidence: a lethal cell where the camera cannot look from the pose (under the
            vehicle's nose) blocks a way once the map holds at least this much lethal evidence
            for it (a vote from 0 m weighs 1; a patch approached from afar gathers tens); with
            less it does not: a region mislabelled for a few frames while the vehicle stood
            would otherwise hold it for ever, as no later frame can see that ground again. Where
            the camera looks, every lethal cell blocks (the next frames confirm or clear it).
        goal_tolerance_m: the goal is reached within this distance of the path's last point (or
            once the vehicle has passed that point within this of the path's last segment's
            line) [m] (terrapref.planner.goal).
        goal_yaw_tolerance_deg: with a value, the goal also needs the heading within this many
            degrees of the path's last direction: the vehicle turns in place there until it is;
            None: the heading is not checked.
        off_path_m: farther than this from the path the planner stops (``off_path``) rather than
            drive on [m].
    """

    reaction_s: float = 0.2
    decel_mps2: float = 1.0
    margin_m: float = 0.3
    blind_after_s: float = 0.5
    resume_after_s: float = 0.3
    seen_share: float = 0.5
    look_m: float = 3.0
    arcs: int = 21
    step_m: float = 0.1
    lethal_evidence: float = 5.0
    goal_tolerance_m: float = 0.5
    goal_yaw_tolerance_deg: float | None = None
    off_path_m: float = 10.0

    def __post_init__(self) -> None:
        names = ("reaction_s", "decel_mps2", "margin_m", "blind_after_s", "resume_after_s", "seen_share", "look_m", "step_m")
        names += ("lethal_evidence", "goal_tolerance_m", "off_path_m")
        names += () if self.goal_yaw_tolerance_deg is None else ("goal_yaw_tolerance_deg",)
        bad = next((name for name in names if not finite_number(getattr(self, name))), None)
        if bad is not None:
            raise ValueError(f"the stop rule's settings must be finite numbers; {bad} is {getattr(self, bad)!r}")
        if self.goal_tolerance_m <= 0 or self.off_path_m <= self.goal_tolerance_m:
            raise ValueError("the stop rule needs goal_tolerance_m > 0 and off_path_m greater than it")
        if self.goal_yaw_tolerance_deg is not None and not 0 < self.goal_yaw_tolerance_deg <= 180:
            raise ValueError("goal_yaw_tolerance_deg must be in (0, 180], or null not to check the heading")
        if (
            self.reaction_s < 0
            or self.decel_mps2 <= 0
            or self.margin_m < 0
            or self.blind_after_s < 0
            or self.resume_after_s < 0
            or not 0 < self.seen_share <= 1
            or self.look_m <= 0
            or self.step_m <= 0
            or isinstance(self.arcs, bool)
            or not isinstance(self.arcs, int)
            or self.arcs < 1
            or self.lethal_evidence < 0
        ):
            raise ValueError(
                "the stop rule needs reaction_s, margin_m, blind_after_s, resume_after_s and lethal_evidence >= 0, decel_mps2, look_m and "
                "step_m > 0, seen_share in (0, 1] and at least one arc"
            )
        for name, most in STOP_BOUNDS.items():
            if getattr(self, name) > most:
                raise ValueError(f"{name} must be at most {most:g}, got {getattr(self, name):g}: {STOP_BOUND_REASONS[name]}")

    def stopping_distance_m(self, v_mps: float) -> float:
        """Distance [m] from a frame to standing still, at ``v_mps``, plus the margin."""
        v = abs(float(v_mps))
        return v * self.reaction_s + v * v / (2.0 * self.decel_mps2) + self.margin_m

    def to_dict(self) -> dict:
        return to_plain(self)

    @classmethod
    def from_dict(cls, data: dict) -> StopConfig:
        return cls(**data)


# The small ground map the stop rule reads where the steering rule reads none: 0.2 m cells, ground read every
# 0.2 m to 3.5 m ahead and 3 m each side (the ways' reach at 2 m/s), the last few frames
# counting (fade 0.8 a frame), placed with the mount's attitude, otherwise as the offset rule's
# map. It is much coarser than the offset rule's (a fortieth of the samples): it decides only
# whether to go, and the decision it guards (C's) costs 20 us.
_OWN_MAP = MapSettings(
    map_resolution_m=0.2,
    sample_step_m=0.2,
    map_half_size_m=5.0,
    sample_range_m=3.5,
    sample_half_width_m=3.0,
    map_fade=0.8,
    map_sky_attitude=False,
)


class StopRule(StopRunner):
    """The stop rule (module docstring) for one planner's camera and class table.

    Args:
        camera: the robot's camera.
        terrain: the class table's terrain columns (which are lethal).
        max_yaw_rate_rps: the stick's range of yaw rates; the ways checked span it [rad/s].
        half_width_m: half the vehicle's width; the footprint is 5 points across it [m].
        config: the rule's settings.

    The rule reads the ground map the planner keeps, handed to each check: the steering rule's,
    or where that rule reads none, the small one of :attr:`map_settings`.
    """

    map_settings: MapSettings = _OWN_MAP  # the map read where the steering rule reads none

    def __init__(
        self,
        camera: PinholeCamera,
        terrain: TerrainColumns,
        max_yaw_rate_rps: float = 1.0,
        half_width_m: float = 0.6,
        config: StopConfig | None = None,
    ) -> None:
        self.config = c = config or StopConfig()
        self.k = terrain.k
        self.lethal = np.zeros(self.k + 2, dtype=np.bool_)
        self.lethal[np.asarray(terrain.lethal, dtype=np.int64)] = True
        self.across = np.linspace(-half_width_m, half_width_m, 5)
        self.yaw_rates = np.linspace(-max_yaw_rate_rps, max_yaw_rate_rps, c.arcs) if c.arcs > 1 else np.zeros(1)
        # Where the camera on its mount looks, in the vehicle frame: a grid of 0.05 m cells.
        self._vis_origin = (-2.0, -6.0)
        self._vis_inv_res = 20.0
        xs = self._vis_origin[0] + (np.arange(int(12.0 * self._vis_inv_res)) + 0.5) / self._vis_inv_res
        ys = self._vis_origin[1] + (np.arange(int(12.0 * self._vis_inv_res)) + 0.5) / self._vis_inv_res
        grid = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1)
        self.visible = camera.pixel_indices(grid) >= 0  # (X, Y)
        self.near_m = _near_edge(camera, half_width_m)
        # The ground ahead a frame must show: the footprint's width from the near edge to look_m.
        ahead = np.arange(self.near_m, max(c.look_m, self.near_m + c.step_m), c.step_m)
        across = np.arange(-half_width_m, half_width_m + 1e-9, c.step_m)
        points = np.stack(np.meshgrid(ahead, across, indexing="ij"), axis=-1).reshape(-1, 2)
        pix = camera.pixel_indices(points)
        self._ahead = PixelSet(pix[pix >= 0])
        self._blind_since: float | None = None
        self._stopped: str | None = None  # the reason the last frame stopped with for want of a free way
        self._free_since: float | None = None  # since when a way has been free again, while so stopped
        self._frames = 0

    def reset(self) -> None:
        """Start a new run: forget how long frames were blind and any stop."""
        self._blind_since = None
        self._stopped, self._free_since = None, None
        self._frames = 0

    def seen_share(self, view: SegmentationView) -> float:
        """The share of the ground ahead (the footprint's width, near edge to ``look_m``) that ``view``
        shows as ground: with a depth image, where it has a return too (a pixel without one cannot
        be placed on the ground: a depth camera that sees nothing is blind)."""
        if self._ahead.shape[0] == 0:
            return 0.0
        seen = view.pixels(self._ahead) != UNKNOWN
        if view.carries_depth:
            depth = view.depth.reshape(-1)[self._ahead.flat]
            seen &= (depth > 0) & (depth < np.inf)  # NaN, 0 or inf: no return
        return float(np.count_nonzero(seen)) / seen.shape[0]

    def check(
        self, gmap: GroundMap, view: SegmentationView, pose: Pose, v_mps: float, w_rps: float, time_s: float | None = None
    ) -> Verdict:
        """The reason to stop at this frame (None: drive) and the yaw rate to drive the driving
        rule's command (``v_mps``, ``w_rps``) with: ``w_rps`` where its own way is free, else the
        nearest free way's (:meth:`way_rps`).

        Args:
            gmap: the ground map read (the planner's, updated with the frame).
            view: the frame's segmentation image.
            pose: the pose it was taken at.
            v_mps: the speed the driving rule commands: the stopping distance is worked out at it.
            w_rps: the yaw rate it commands: its arc is checked first.
            time_s: the frame's time [s]; None: frames are taken 0.1 s apart.
        """
        self._frames += 1
        now = time_s if time_s is not None else 0.1 * (self._frames - 1)
        if self.seen_share(view) < self.config.seen_share:
            if self._blind_since is None:
                self._blind_since = now
            if now - self._blind_since >= self.config.blind_after_s - 1e-9:
                return Verdict(BLIND, w_rps)
        else:
            self._blind_since = None
        way = self.way_rps(gmap, pose, v_mps, w_rps)
        if way is None:
            self._stopped, self._free_since = self.closed_by(gmap, pose, v_mps, self.yaw_rates), None
            return Verdict(self._stopped, w_rps)
        if self._stopped:  # free again: moves on once it has stayed free resume_after_s
            self._free_since = now if self._free_since is None else self._free_since
            if now - self._free_since < self.config.resume_after_s - 1e-9:
                return Verdict(self._stopped, w_rps)
            self._stopped, self._free_since = None, None
        return Verdict(None, way)

    def closed_by(self, gmap: GroundMap, pose: Pose, v_mps: float, yaw_rates: np.ndarray) -> str:
        """Why the ways of ``yaw_rates`` at ``v_mps``, none of them free on ``gmap``, are closed:
        ``no_free_way:geometry`` where one would be free were the ground past the vehicle's
        limits read by its class alone, else ``no_free_way``."""
        flat = gmap.layers_without_geometry()
        if flat is not None and self._first_free(gmap, pose, v_mps, yaw_rates, 0, flat) >= 0:
            return NO_FREE_WAY_GEOMETRY
        return NO_FREE_WAY

    def stale(self, now_s: float, frame_s: float | None, hold_s: float) -> bool:
        """Whether a command decided on a frame stamped ``frame_s`` (None: none yet) is stale at
        ``now_s``: held for longer than ``hold_s`` [s] (terrapref.stops.held_too_long)."""
        return held_too_long(now_s, frame_s, hold_s)

    def way_rps(self, gmap: GroundMap, pose: Pose, v_mps: float, w_rps: float) -> float | None:
        """The yaw rate [rad/s] to drive at ``v_mps``: ``w_rps`` where its own arc is free on
        ``gmap``, else that of the free way (of the ways checked) nearest to it, the lower on a
        tie; None where none is free."""
        if self.arc_free(gmap, pose, v_mps, w_rps):
            return float(w_rps)
        nearest = self.yaw_rates[np.argsort(np.abs(self.yaw_rates - w_rps), kind="stable")]
        a = self._first_free(gmap, pose, v_mps, nearest, 0)
        return None if a < 0 else float(nearest[a])

    def arc_free(self, gmap: GroundMap, pose: Pose, v_mps: float, w_rps: float) -> bool:
        """Whether the arc of ``w_rps`` [rad/s] at ``v_mps`` [m/s] itself keeps the footprint on
        seen, non-lethal ground of ``gmap`` over the stopping distance (no other way is tried)."""
        return self._first_free(gmap, pose, v_mps, np.array([float(w_rps)]), 0) >= 0

    def _first_free(
        self, gmap: GroundMap, pose: Pose, v_mps: float, yaw_rates: np.ndarray, first: int, layers: MapLayers | None = None
    ) -> int:
        """The first of ``yaw_rates`` (``first`` tried first) whose arc at ``v_mps`` is free over
        the stopping distance on ``gmap`` (read as ``layers``; None: as it is) (:func:`first_free_arc`);
        -1 when none is."""
        if gmap.origin is None:
            return -1
        c = self.config
        distance = c.stopping_distance_m(v_mps)
        steps = max(1, math.ceil(distance / c.step_m - 1e-9))
        v = max(abs(float(v_mps)), 1e-3)
        return first_free_arc(
            float(pose[0]),
            float(pose[1]),
            float(pose[2]),
            yaw_rates / v,
            first,
            c.step_m,
            steps,
            self.across,
            gmap.layers() if layers is None else layers,
            self.lethal,
            self.k + 1,
            np.float32(c.lethal_evidence),
            self.visible,
            *self._vis_origin,
            self._vis_inv_res,
        )


def _near_edge(camera: PinholeCamera, half_width_m: float) -> float:
    """The nearest distance ahead [m] at which the camera on its mount sees the footprint's whole width."""
    xs = np.arange(0.0, 5.0, 0.01)
    ys = np.array([-half_width_m, 0.0, half_width_m])
    points = np.stack(np.broadcast_arrays(xs[:, None], ys[None, :]), axis=-1)
    seen = (camera.pixel_indices(points) >= 0).all(axis=1)
    return float(xs[np.argmax(seen)]) if seen.any() else 5.0


@njit(cache=True, nogil=True)
def first_free_arc(
    x0: float,
    y0: float,
    yaw0: float,
    curvatures: np.ndarray,
    first: int,
    step_m: float,
    steps: int,
    across: np.ndarray,
    layers: MapLayers,
    lethal: np.ndarray,
    never: int,
    confirmed: np.float32,
    visible: np.ndarray,
    vx0: float,
    vy0: float,
    vis_inv_res: float,
) -> int:
    """An arc (``curvatures`` (A,) [1/m], ``first`` tried first, then the others in order) along
    which the footprint (``across`` (F,) [m], left positive) stays on seen, non-lethal ground of
    the map for ``steps`` steps of ``step_m`` from the pose; -1 when none does.

    A point is blocked where the camera looks from the pose (``visible``, a vehicle-frame grid
    from (``vx0``, ``vy0``) at ``vis_inv_res`` cells per metre) when its cell's column is lethal
    (``lethal`` by column) or never seen (``never``); where it does not look, when its cell is
    lethal on at least ``confirmed`` lethal evidence (``map_lethal``'s columns). A cell never seen
    whose 4-neighbours were seen reads as them (lethal if any is): the map's samples leave single
    cells unvoted between them, which are not unseen ground. A lethal cell none of whose
    4-neighbours is lethal does not block (a speckle: labels flipped in a few frames; the
    footprint's points, 0.3 m apart, do not resolve a 0.1 m obstacle either). The map's cells
    (``layers``) are read as :func:`terrapref.groundmap.map_compiled.map_decide` says.
    """
    for t in range(curvatures.shape[0]):
        a = first if t == 0 else (t - 1 if t <= first else t)
        if not _arc_blocked(
            x0, y0, yaw0, curvatures[a], step_m, steps, across, layers, lethal, never, confirmed, visible, vx0, vy0, vis_inv_res
        ):
            return a
    return -1


@njit(cache=True, nogil=True, inline="always")
def _arc_blocked(
    x0: float,
    y0: float,
    yaw0: float,
    kappa: float,
    step_m: float,
    steps: int,
    across: np.ndarray,
    layers: MapLayers,
    lethal: np.ndarray,
    never: int,
    confirmed: np.float32,
    visible: np.ndarray,
    vx0: float,
    vy0: float,
    vis_inv_res: float,
) -> bool:
    """Whether the arc of curvature ``kappa`` is blocked within ``steps`` steps of ``step_m``
    for the footprint's points ``across``: :func:`first_free_arc` says when."""
    ox, oy, inv_res = layers.ox, layers.oy, layers.inv_res
    vis_x, vis_y = visible.shape
    c0, s0 = math.cos(yaw0), math.sin(yaw0)
    for q in range(1, steps + 1):
        d = q * step_m
        heading = kappa * d
        if abs(kappa) < 1e-9:
            bx, by = d, 0.0
        else:
            bx, by = math.sin(heading) / kappa, (1.0 - math.cos(heading)) / kappa
        sh, ch = math.sin(heading), math.cos(heading)
        for f in range(across.shape[0]):
            px = bx - across[f] * sh  # vehicle frame
            py = by + across[f] * ch
            wx = x0 + px * c0 - py * s0
            wy = y0 + px * s0 + py * c0
            gi = math.floor((px - vx0) * vis_inv_res)
            gj = math.floor((py - vy0) * vis_inv_res)
            looks = 0 <= gi < vis_x and 0 <= gj < vis_y and visible[gi, gj]
            if _blocked(layers, lethal, never, confirmed, math.floor((wy - oy) * inv_res), math.floor((wx - ox) * inv_res), looks):
                return True
    return False


@njit(cache=True, nogil=True, inline="always")
def _blocked(layers: MapLayers, lethal: np.ndarray, never: int, confirmed: np.float32, j: int, i: int, looks: bool) -> bool:
    """Whether the footprint may not stand on cell (row ``j``, column ``i``): :func:`first_free_arc`
    says when (``looks``: the camera looks at the point from the pose)."""
    cells, evidence, map_lethal, shares = layers.cells, layers.evidence, layers.lethal, layers.shares
    n_rows, n_cols = cells.shape
    col = _column(cells, evidence, map_lethal, shares, j, i, never)
    if col == never and 0 <= i < n_cols and 0 <= j < n_rows:  # a cell between samples: read its neighbours
        seen, deadly = False, False
        for dj, di in ((0, 1), (0, -1), (1, 0), (-1, 0)):
            cn = _column(cells, evidence, map_lethal, shares, j + dj, i + di, never)
            if cn != never:
                seen = True
                deadly = deadly or (lethal[cn] and (looks or _lethal_evidence(evidence, map_lethal, j + dj, i + di) >= confirmed))
        if seen:
            return deadly
    if (
        lethal[col]
        and (looks or _lethal_evidence(evidence, map_lethal, j, i) >= confirmed)
        and _lethal_neighbour(cells, evidence, map_lethal, shares, lethal, j, i, never)
    ):
        return True
    return col == never and looks


@njit(cache=True, nogil=True, inline="always")
def _lethal_evidence(evidence: np.ndarray, map_lethal: np.ndarray, j: int, i: int) -> np.float32:
    """The evidence for lethal columns (``map_lethal``) map cell ``(j, i)`` holds, as of its last vote."""
    total = np.float32(0.0)
    for q in range(evidence.shape[2]):
        if map_lethal[q]:
            total += evidence[j, i, q]
    return total


@njit(cache=True, nogil=True, inline="always")
def _column(cells: np.ndarray, evidence: np.ndarray, map_lethal: np.ndarray, shares: np.ndarray, j: int, i: int, never: int) -> int:
    """The column of map cell ``(j, i)``, decided first if it is UNSETTLED (as
    :func:`terrapref.groundmap.map_compiled.map_decide` says); ``never`` outside the map."""
    if not (0 <= i < cells.shape[1] and 0 <= j < cells.shape[0]):
        return never
    col = cells[j, i]
    if col == UNSETTLED:
        col = cells[j, i] = map_decide(evidence, map_lethal, shares[0], shares[1], shares[2], j, i)
    return col


@njit(cache=True, nogil=True, inline="always")
def _lethal_neighbour(
    cells: np.ndarray, evidence: np.ndarray, map_lethal: np.ndarray, shares: np.ndarray, lethal: np.ndarray, j: int, i: int, never: int
) -> bool:
    """Whether a 4-neighbour of map cell ``(j, i)`` is lethal (``lethal`` by column)."""
    for dj, di in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        if lethal[_column(cells, evidence, map_lethal, shares, j + dj, i + di, never)]:
            return True
    return False
