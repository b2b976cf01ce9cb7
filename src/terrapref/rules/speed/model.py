"""The speed model the speed rule learns, and its fit (SPEC 18).

What a person's speed depends on, written as a few numbers that one drive can pin down: a
cruising speed per terrain column (the background included), taken as the slowest of the columns
the footprint meets on its way over the next ``preview_m``; on relief, less ``up_mps_per_deg`` for
each degree of grade up at each station of that way (``down_mps_per_deg`` down); no more than
``rough_mps`` where the ground within :data:`ROUGH_PREVIEW_M` of the vehicle on that way is
rougher than ``rough_m``; no more than ``lateral_accel_mps2`` allows in a bend of the way's
curvature; and no more than ``near_lethal_mps`` while lethal terrain lies within ``near_lethal_m``
beside the footprint on that way.

A frame's way is read as terrain columns at stations ``STATION_STEP_M`` apart (the first under
the vehicle) and at the footprint's points across (:data:`ACROSS`: the footprint's 5, then the
lethal rings' 4), the grade the body would be pitched at on each of the footprint's points
there, heading along the way [deg, positive up, NaN where the ground map does not know it: a
driver slows for the steepest ground under its footprint, not only for the centre line's] and
the roughness on the centre line [m, the same]. The fit reads the way the driver drove; the planner reads the way it chose.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from terrapref.vehicle import MIN_CRUISE_MPS

STATION_STEP_M = 0.25
STATIONS = 24  # the way is read to 6 m ahead
PREVIEWS_M = tuple(0.5 * k for k in range(1, 9))  # the previews the fit tries [m]
RINGS_M = (0.5, 1.0)  # lethal terrain this far beside the footprint is near, for the fit to choose [m]
LAGS = (0, 1, 2, 3)  # frames between what a frame shows and the speed commanded for it, for the fit to choose
STEADY_CURVATURE = 0.25  # a way of less curvature counts for a cruising speed (the median keeps out the few bends that slowed) [1/m]
BEND_CURVATURE = 0.1  # a way of more curvature may be slowed by the bend [1/m]
MIN_FRAMES = 10  # frames a cruising speed, a bend or a lethal neighbour needs to be fitted
MIN_SPEED_MPS = MIN_CRUISE_MPS  # the slowest the rule commands while it drives [m/s]
SLOWEST_PERCENTILE = 5  # the slowest speed a drive showed: this percentile of its speeds while moving (not a moment's)
LEVEL_DEG = 3.0  # a way whose grade stays within this of level shows its class's cruising speed; steeper, what a grade sheds [deg]
# Roughness is read on the way's first metre: a depth camera's far returns scatter (under
# `field`, smooth ground 2-3 m ahead reads as rough as a patch of 0.01-0.02 m does at the vehicle),
# while ground under the footprint has been seen from close by.
ROUGH_PREVIEW_M = 1.0
# The roughness past which the fit tries a top speed [m].
ROUGH_BANDS_M = (0.005, 0.0075, 0.01, 0.0125, 0.015, 0.0175, 0.02, 0.025, 0.03, 0.035, 0.04)
# Rough-ground bands whose speeds' mean error is within this of the best's explain a drive alike [m/s]:
# the drive showed no ground between them, and the fit keeps the middle one, not the smoothest (which
# slows on roughness the drive never showed, as a noisy map reads smooth ground) nor the roughest.
ROUGH_ALIKE_MPS = 0.001
# The cruising speeds read net of what grades shed are read again with what that gives, until no
# speed moves by more than NET_SETTLED_MPS, at most NET_ROUNDS times (each round takes a share of
# the bias equal to how gentle the level frames' grades are against the steep ones').
NET_ROUNDS = 8
NET_SETTLED_MPS = 1e-4


# The body's pitch at a station: the ground's gradient along the heading, averaged over a chord of
# the field UGV's wheelbase centred there (trapezoid weights): the rise from its rear axle to its
# front one, as a rigid body feels a grade, rather than the gradient of the ground under one point
# (over a mound's flank the two differ; docs/design.md).
CHORD_M = np.array([-0.5, -0.25, 0.0, 0.25, 0.5])
CHORD_WEIGHTS = np.array([0.5, 1.0, 1.0, 1.0, 0.5]) / 4.0


def body_grade(gradient_at: Callable[[np.ndarray], np.ndarray], centre: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """The grade [deg, positive up] (S,) the body would be pitched at, centred at the points
    ``centre`` (S, 2) heading ``heading`` (S,) [rad], from ``gradient_at`` (world points (..., 2)
    to the ground's gradient there (..., 2), NaN where unknown); NaN where the gradient is known
    under less than half the chord's weight."""
    tangent = np.stack([np.cos(heading), np.sin(heading)], axis=-1)
    points = centre[:, None, :] + CHORD_M[None, :, None] * tangent[:, None, :]
    g = gradient_at(points)
    rise = g[..., 0] * tangent[:, None, 0] + g[..., 1] * tangent[:, None, 1]
    known = np.isfinite(rise)
    weight = np.where(known, CHORD_WEIGHTS[None, :], 0.0).sum(axis=1)
    total = np.where(known, rise, 0.0) @ CHORD_WEIGHTS
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(weight >= 0.5, np.degrees(np.arctan(total / weight)), np.nan)


def across(half_width_m: float) -> np.ndarray:
    """The points across the way [m], left positive: the footprint's 5, then the rings' 4 (:data:`RINGS_M`)."""
    foot = np.linspace(-half_width_m, half_width_m, 5)
    rings = np.array([-(half_width_m + RINGS_M[1]), -(half_width_m + RINGS_M[0]), half_width_m + RINGS_M[0], half_width_m + RINGS_M[1]])
    return np.concatenate([foot, rings])


@dataclass(frozen=True)
class SpeedModel:
    """A fitted speed model (module docstring).

    Attributes:
        speeds_mps: cruising speed per terrain column, K + 1 of them (column K: the background) [m/s].
        preview_m: how far ahead on its way the slowest column counts [m].
        lateral_accel_mps2: the lateral acceleration kept in bends; None: no limit [m/s^2].
        near_lethal_m: lethal terrain this far beside the footprint is near; None: it does not slow for it [m].
        near_lethal_mps: the speed kept while lethal terrain is near [m/s].
        lethal: the lethal terrain columns.
        min_points: a column counts at a station where it holds at least this many of the
            footprint's 5 points there. The fit keeps 1 (:func:`fit_speed`); a model file may ask
            for more, for a map whose patch edges are too ragged to trust one point.
        drive_lateral_mps2: the largest lateral acceleration the drive showed, which the
            planner never asks for more than, bend limit or none [m/s^2].
        up_mps_per_deg: the speed shed per degree of grade up [m/s per deg]; None: not learned
            (a drive on flat ground) ...
        down_mps_per_deg: ... and down.
        rough_m: the roughness past which ``rough_mps`` holds [m]; None: not learned ...
        rough_mps: ... the top speed there [m/s].
        grades_across: whether the grades were read on each of the footprint's points (False:
            on the way's centre line alone, as model files written before read them).
    """

    speeds_mps: tuple[float, ...]
    preview_m: float
    lateral_accel_mps2: float | None
    near_lethal_m: float | None
    near_lethal_mps: float | None
    lethal: tuple[int, ...]
    min_points: int = 1
    drive_lateral_mps2: float | None = None
    up_mps_per_deg: float | None = None
    down_mps_per_deg: float | None = None
    rough_m: float | None = None
    rough_mps: float | None = None
    grades_across: bool = False

    @property
    def slows_on_rough(self) -> bool:
        """Whether the model keeps a top speed on rough ground (a drive on relief showed it)."""
        return self.rough_m is not None and self.rough_mps is not None

    @property
    def sheds_on_grades(self) -> bool:
        """Whether the model slows on grades (a drive on relief showed it)."""
        return self.up_mps_per_deg is not None or self.down_mps_per_deg is not None

    def predict(
        self, way: np.ndarray, curvature: np.ndarray, grade: np.ndarray | None = None, rough: np.ndarray | None = None
    ) -> np.ndarray:
        """The speed [m/s] (N,) for ways (N, STATIONS, 9) of terrain columns, their curvatures (N,)
        [1/m], their grades (N, STATIONS) on the centre line or (N, STATIONS, 5) on each of the
        footprint's points [deg, positive up; NaN: unknown, taken as level; None: all unknown]
        and their roughness (N, STATIONS) [m; NaN or None: unknown, taken as smooth]."""
        upto = stations_within(self.preview_m)
        foot = way[:, :upto, :5]
        at = self._speeds[foot]
        if self.min_points > 1:  # the points whose column too few of their station's points share
            shared = (foot[..., :, None] == foot[..., None, :]).sum(axis=-1)
            at = np.where(shared >= self.min_points, at, np.nan)
        if grade is not None and self.sheds_on_grades:
            g = grade[:, :upto]
            at = at - self.shed(g if g.ndim == 3 else g[:, :, None])
        v = np.nanmin(at.reshape(len(way), -1), axis=1, initial=np.inf)
        v = np.where(np.isfinite(v), v, float(np.nanmin(self.speeds_mps)))  # nothing seen: the slowest cruising speed
        if rough is not None and self.slows_on_rough:
            v = np.where(roughest(rough) > self.rough_m, np.minimum(v, self.rough_mps), v)
        if self.lateral_accel_mps2 is not None:
            k = np.abs(curvature)
            with np.errstate(divide="ignore"):
                v = np.minimum(v, np.where(k > 0, np.sqrt(self.lateral_accel_mps2 / np.where(k > 0, k, 1.0)), np.inf))
        if self.near_lethal_m is not None and self.near_lethal_mps is not None:
            v = np.where(_near(way, upto, self._is_lethal, self.near_lethal_m), np.minimum(v, self.near_lethal_mps), v)
        return np.maximum(v, MIN_SPEED_MPS)

    def shed(self, grade: np.ndarray) -> np.ndarray:
        """The speed [m/s] shed on grades ``grade`` [deg, positive up; NaN: level], of the same shape."""
        g = np.asarray(grade, dtype=np.float64)
        return (self.up_mps_per_deg or 0.0) * np.fmax(g, 0.0) + (self.down_mps_per_deg or 0.0) * np.fmax(-g, 0.0)  # fmax: NaN is 0

    @property
    def lateral_limit_mps2(self) -> float | None:
        """The most lateral acceleration the planner asks for: the bend limit where the drive showed
        one, else the largest the drive showed; None: neither known [m/s^2]."""
        known = [a for a in (self.lateral_accel_mps2, self.drive_lateral_mps2) if a is not None]
        return min(known) if known else None

    @functools.cached_property
    def _speeds(self) -> np.ndarray:
        """Cruising speed per column value (256,): NaN for lethal and never-seen ground (made once per model)."""
        table = np.full(256, np.nan)
        table[: len(self.speeds_mps)] = self.speeds_mps
        table[list(self.lethal)] = np.nan
        return table

    @functools.cached_property
    def _is_lethal(self) -> np.ndarray:
        return lethal_mask(self.lethal)


def roughest(rough: np.ndarray) -> np.ndarray:
    """The roughest ground [m] (N,) within :data:`ROUGH_PREVIEW_M` on each way of ``rough`` (N, STATIONS) (0 where unknown)."""
    return np.fmax.reduce(rough[:, : stations_within(ROUGH_PREVIEW_M)].astype(np.float64), axis=1, initial=0.0)  # fmax: NaN is 0


def stations_within(preview_m: float) -> int:
    """Stations of a way within ``preview_m`` (the one under the vehicle included)."""
    return min(STATIONS, round(preview_m / STATION_STEP_M) + 1)


def lethal_mask(lethal: tuple[int, ...]) -> np.ndarray:
    """Which column values (256,) are lethal."""
    is_lethal = np.zeros(256, dtype=bool)
    is_lethal[list(lethal)] = True
    return is_lethal


INSIDE = [0, 1, 2, 3, 4, 6, 7]  # the footprint's points and the nearer ring's (:func:`across`)


def _near(way: np.ndarray, upto: int, is_lethal: np.ndarray, ring_m: float) -> np.ndarray:
    """Whether lethal terrain (``is_lethal``, by column value) lies on the footprint or within ``ring_m`` beside it on each way (N,)."""
    points = INSIDE if ring_m <= RINGS_M[0] else list(range(9))
    return is_lethal[way[:, :upto, points]].any(axis=(1, 2))


@dataclass(frozen=True)
class SpeedFit:
    """How the fit went: the model, each column's cruising speed's 95% interval (None: never
    shown at a steady speed), the lag chosen, frames fitted and the mean absolute error on them;
    and, for a drive on relief (``on_grades``), the 95% intervals of what grades shed, up and down
    (None: not learned), and the frames on one grade each was read from (or would have been);
    and what rough ground showed (:class:`Rough`)."""

    model: SpeedModel
    intervals: tuple[tuple[float, float] | None, ...]
    lag_frames: int
    samples: int
    error_mps: float
    grade_intervals: tuple[tuple[float, float] | None, tuple[float, float] | None] = (None, None)
    grade_frames: tuple[int, int] = (0, 0)
    on_grades: bool = False
    rough: Rough | None = None


class Rough(NamedTuple):
    """What a drive on relief showed of rough ground: the frames on one class, away from lethal
    terrain and slower than the terrain and grades ask, on ground past the roughness learned
    (or past the smoothest band tried, where nothing was learned); the top speed's 95% interval
    (None: not learned); and the roughness bands [m] that explain the drive alike (within
    :data:`ROUGH_ALIKE_MPS`; the drive cannot tell them apart), the middle one kept."""

    frames: int = 0
    interval: tuple[float, float] | None = None
    alike_m: tuple[float, float] | None = None


class _Grades(NamedTuple):
    """What grades shed, as :func:`_fit_grades` found it: per degree up and down (None: not
    learned), their intervals and the frames each was read from."""

    up: float | None = None
    down: float | None = None
    intervals: tuple[tuple[float, float] | None, tuple[float, float] | None] = (None, None)
    frames: tuple[int, int] = (0, 0)


class Drive(NamedTuple):
    """The frames of a drive as the fit reads them (terrapref.rules.speed.rule.SpeedReader's arrays):
    the ways driven (N, STATIONS, 9), their curvatures (N, NaN where the vehicle stood), the speeds
    commanded (N) [m/s], the frames' numbers in their recordings (N; a lag pairs frames only within
    one recording), the ways' grades (N, STATIONS, 5) on the footprint's points, or (N, STATIONS)
    on the centre line as datasets featurised before read them [deg, positive up, NaN where
    unknown; None: a drive on flat ground] and their roughness (N, STATIONS) [m, the same]."""

    way: np.ndarray
    curvature: np.ndarray
    v_mps: np.ndarray
    frame: np.ndarray
    grade: np.ndarray | None = None
    rough: np.ndarray | None = None


def fit_speed(drive: Drive, k: int, lethal: tuple[int, ...]) -> SpeedFit | None:
    """The speed model that best explains the speeds a ``drive`` commanded, with K terrain columns
    ``k`` of which ``lethal`` are lethal; None without a frame at a steady speed on any column.

    For each preview and lag: a column's cruising speed is the median speed of the frames whose
    way within the preview is that column alone, level (within :data:`LEVEL_DEG`) and nearly
    straight, with no lethal terrain near, well inside the column where the drive shows enough
    such frames (:func:`_cruising`; where it shows too few, at its edges too, then not level
    too, then beside lethal terrain too); the bend's limit the median ``v^2 * curvature`` of the
    frames slower than their terrain allows in bends; the lethal neighbour's speed the median of
    the frames slower than both near lethal terrain (the ring that explains them best). The preview and lag that explain all frames best
    (mean absolute error) are kept. A class the drive never showed at a steady speed is driven at
    the slowest speed the drive showed: the slowest cruising speed learned, or the
    :data:`SLOWEST_PERCENTILE` th percentile of its speeds while moving where that is slower.
    What a degree of grade up sheds is the median, over the frames whose way is one column alone and
    nearly straight, climbing past :data:`LEVEL_DEG` and nowhere going down past it, of the speed
    they fall short of that column's cruising speed by per degree of their steepest grade up under
    the footprint (down likewise); each is kept where it explains the frames better than none; on
    relief the cruising speeds are read net of it (:func:`_net_of_grades`) before bends and lethal
    neighbours are fitted. On rough ground: for each band of :data:`ROUGH_BANDS_M`, the median speed
    of the frames on one column alone, nearly straight, away from lethal terrain, slower than the
    terrain and grades ask and past the band within :data:`ROUGH_PREVIEW_M`; where any explains the
    frames better than none, the middle one of those that explain them as well as the best
    (:data:`ROUGH_ALIKE_MPS`) is kept. A
    class counts where it meets any one of the footprint's points (``min_points`` 1), as the
    driver reads its footprint: a model that asked for two passed at full speed the patches its
    driver brushes, on clean frames and under label errors alike, even where two points explained
    its drive better.
    """

    way, curvature, v_mps, frame, grade, rough = drive

    def fitted(lag: int, preview: float, intervals: bool = False) -> SpeedFit | None:
        later = _shifted(v_mps, frame, lag)
        ok = np.isfinite(later) & (later > 0) & np.isfinite(curvature)
        if np.count_nonzero(ok) < MIN_FRAMES:
            return None
        w, c, v = way[ok], curvature[ok], later[ok]
        g = None if grade is None else grade[ok]
        r = None if rough is None else rough[ok]
        found = _fit_at(_Frames(w, c, v, k, lethal, g, intervals, r), preview)
        if found is None:
            return None
        model, intervals, grades, shown = found
        error = float(np.mean(np.abs(model.predict(w, c, g, r) - v)))
        return SpeedFit(model, intervals, lag, int(len(v)), error, grades.intervals, grades.frames, g is not None, shown)

    best: SpeedFit | None = None
    for lag in LAGS:
        for preview in PREVIEWS_M:
            trial = fitted(lag, preview)
            if best is None or (trial is not None and trial.error_mps < best.error_mps - 1e-9):
                best = trial
    if best is not None:  # the intervals, for the fit kept alone (their resampling is most of a fit's time)
        best = fitted(best.lag_frames, best.model.preview_m, intervals=True)
        moving = np.isfinite(curvature) & (v_mps > 0)
        lateral = float(np.max(v_mps[moving] ** 2 * np.abs(curvature[moving]), initial=0.0))
        on_points = grade is not None and grade.ndim == 3 and best.model.sheds_on_grades
        best = replace(best, model=replace(best.model, drive_lateral_mps2=lateral if lateral > 0 else None, grades_across=on_points))
    return best


def _shifted(v: np.ndarray, frame: np.ndarray, lag: int) -> np.ndarray:
    """``v`` ``lag`` frames later within the same recording (NaN where there is no such frame)."""
    out = np.full(len(v), np.nan)
    if lag == 0:
        return v.astype(float)
    same = frame[lag:] == frame[:-lag] + lag
    out[:-lag][same] = v[lag:][same]
    return out


class _Frames(NamedTuple):
    """The frames one fit reads: ways, curvatures, speeds (lagged), the terrain columns K, the
    lethal ones, the ways' grades (None: flat ground), whether to find the intervals, and the
    ways' roughness (None: flat ground)."""

    way: np.ndarray
    curvature: np.ndarray
    v: np.ndarray
    k: int
    lethal: tuple[int, ...]
    grade: np.ndarray | None = None
    intervals: bool = True
    rough: np.ndarray | None = None


def _fit_at(frames: _Frames, preview_m: float) -> tuple[SpeedModel, tuple[tuple[float, float] | None, ...], _Grades, Rough | None] | None:
    way, curvature, v, k, lethal, grade, _, rough = frames
    upto = stations_within(preview_m)
    foot = way[:, :upto, :5].reshape(len(way), -1)
    seen = foot <= k  # K + 1: never seen
    first = np.where(seen.any(axis=1), foot[np.arange(len(foot)), np.argmax(seen, axis=1)], k + 1)
    alone = seen.any(axis=1) & np.all((foot == first[:, None]) | ~seen, axis=1)
    is_lethal = lethal_mask(lethal)
    near = _near(way, upto, is_lethal, RINGS_M[1])
    steady = alone & (np.abs(curvature) < STEADY_CURVATURE)
    # The way's column alone across the footprint and the ring nearer it: well inside a patch.
    wide = way[:, :upto, INSIDE].reshape(len(way), -1)
    inside = steady & np.all((wide == first[:, None]) | (wide > k), axis=1)
    climb, descent = steepest(grade, upto, len(way))
    on = (first[:, None] == np.arange(k + 1)).T
    level = (climb < LEVEL_DEG) & (descent < LEVEL_DEG)
    speeds, intervals = _cruising(frames, (steady & on, inside & on), near, level)
    if all(math.isnan(s) for s in speeds):
        return None
    base = SpeedModel(_filled(speeds, v, lethal), preview_m, None, None, None, lethal)
    if grade is not None:  # what the level frames' own grades shed taken off their cruising speeds first
        base, intervals = _net_of_grades(frames, (base, intervals), (steady & on, inside & on, near, level, steady), (climb, descent))
    terrain_v = base.predict(way, curvature, grade)
    bend = (terrain_v > 1.1 * v) & (np.abs(curvature) >= BEND_CURVATURE) & ~near
    best, best_error = base, float(np.mean(np.abs(terrain_v - v)))
    if np.count_nonzero(bend) >= MIN_FRAMES:  # a limit in bends, kept only where it explains the frames better than none
        for a_lat in np.percentile(v[bend] ** 2 * np.abs(curvature[bend]), (25, 50, 75)):
            trial = replace(base, lateral_accel_mps2=float(a_lat))
            error = float(np.mean(np.abs(trial.predict(way, curvature, grade) - v)))
            if error < best_error - 1e-9:
                best, best_error = trial, error
    allowed = best.predict(way, curvature, grade)
    for ring in RINGS_M:
        slowed = _near(way, upto, is_lethal, ring) & (allowed > 1.1 * v)
        if np.count_nonzero(slowed) < MIN_FRAMES:
            continue
        trial = replace(best, near_lethal_m=ring, near_lethal_mps=float(np.median(v[slowed])))
        error = float(np.mean(np.abs(trial.predict(way, curvature, grade) - v)))
        if error < best_error - 1e-9:
            best, best_error = trial, error
    grades = _Grades()
    if grade is not None:  # the grades fitted again, with their intervals, on the model the bends and lethal terrain left
        best = replace(best, up_mps_per_deg=None, down_mps_per_deg=None)
        best_error = float(np.mean(np.abs(best.predict(way, curvature) - v)))
        best, grades = _fit_grades(best, best_error, frames, steady & ~near, (climb, descent))
    shown = None
    if rough is not None:
        best, shown = _fit_rough(best, frames, steady & ~near)
    return best, tuple(intervals), grades, shown


def _filled(speeds: list[float], v: np.ndarray, lethal: tuple[int, ...]) -> tuple[float, ...]:
    """The cruising speeds with each column the drive never showed steady (NaN) filled in: a class
    is driven at the slowest speed the drive showed (``v``), not at a class's it may be far faster
    than (a drive that showed only its grass steady). A lethal column's speed is never read; it
    stays the slowest known, so that a drive that showed every other class steady fits the model
    it always did."""
    slowest = min(s for s in speeds if not math.isnan(s))
    unseen_mps = min(slowest, float(np.percentile(v, SLOWEST_PERCENTILE)))
    return tuple((slowest if col in lethal else unseen_mps) if math.isnan(s) else s for col, s in enumerate(speeds))


def _net_of_grades(
    frames: _Frames, found: tuple[SpeedModel, list], masks: tuple[np.ndarray, ...], steepest: tuple[np.ndarray, np.ndarray]
) -> tuple[SpeedModel, list[tuple[float, float] | None]]:
    """The model of ``found`` (its cruising speeds read on level frames, and their intervals) with
    what grades shed and its cruising speeds read net of it, in turn until they settle
    (:data:`NET_ROUNDS`, :data:`NET_SETTLED_MPS`): a level frame's way is within :data:`LEVEL_DEG`
    of level, not level, and a driver who sheds speed from the first degree drives it slower than
    its class's speed (a drive on gentle relief put the cautious style's grass 0.06 m/s low).
    ``masks``: each column's frames steady on it alone and well inside it, the frames near lethal
    terrain, the level frames, the steady ones. ``found`` as it was where the steep frames are too
    few, or where speeds and grades together explain the frames no better than it."""
    alone, inside, near, level, steady = masks
    way, curvature, v, grade = frames.way, frames.curvature, frames.v, frames.grade
    model = found[0]
    climb, descent = steepest
    quick = frames._replace(intervals=False)
    for _ in range(NET_ROUNDS):
        plain = replace(model, up_mps_per_deg=None, down_mps_per_deg=None)
        shedding, _ = _fit_grades(plain, math.inf, quick, steady & ~near, steepest)  # what the steep frames shed, kept or not
        if not shedding.sheds_on_grades:
            return found
        # What it would take off each frame: its steepest station's shed (climb and descent as the model reads them).
        shed = np.maximum(shedding.shed(climb), shedding.shed(-descent))
        net = frames._replace(v=v + shed)
        speeds, _ = _cruising(net._replace(intervals=False), (alone, inside), near, level)
        again = replace(shedding, speeds_mps=_filled(speeds, v, frames.lethal))
        settled = np.allclose(again.speeds_mps, model.speeds_mps, rtol=0.0, atol=NET_SETTLED_MPS)
        model = again
        if settled:
            break
    # Kept where speeds and grades together explain the frames better than the speeds read on level frames alone.
    if np.mean(np.abs(model.predict(way, curvature, grade) - v)) >= np.mean(np.abs(found[0].predict(way, curvature) - v)) - 1e-9:
        return found
    return model, (_cruising(net, (alone, inside), near, level)[1] if frames.intervals else found[1])


def _cruising(
    frames: _Frames, on: tuple[np.ndarray, np.ndarray], near: np.ndarray, level: np.ndarray
) -> tuple[list[float], list[tuple[float, float] | None]]:
    """Each column's cruising speed (NaN: not shown, or lethal) and its interval, from the frames
    ``on`` it alone, steady, and of those the frames well inside it (its column alone within the
    nearer ring too), each (K + 1, N): well inside it, level and away from lethal terrain
    (``near``) where the drive shows enough such frames; else well inside it and level, beside
    lethal terrain too (a lane between lethal walls); else anywhere on it alone, level and away
    from lethal terrain; else on grades; else beside lethal terrain too. A frame at a patch's
    edge is the driver's or not by a few centimetres of where the map puts the edge: the driver,
    brushing the next patch, drives at that patch's speed there, and a class the drive shows
    mostly at its edges was learned at its neighbour's (a strip's detour onto it, driven at the
    strip's speed, was most of a class's frames away from lethal terrain on a course that shows
    each pair once)."""
    alone, inside = on
    speeds: list[float] = []
    intervals: list[tuple[float, float] | None] = []
    tries = ((inside, ~near & level), (inside, level), (alone, ~near & level), (alone, ~near), (alone, level), (alone, None))
    for col in range(frames.k + 1):
        for rows_on, where in tries:
            rows = np.flatnonzero(rows_on[col] & (True if where is None else where))
            if len(rows) >= MIN_FRAMES:
                break
        if col in frames.lethal or len(rows) < MIN_FRAMES:
            speeds.append(math.nan)
            intervals.append(None)
            continue
        speeds.append(float(np.median(frames.v[rows])))
        intervals.append(_interval(frames.v[rows], rows) if frames.intervals else None)
    return speeds, intervals


def steepest(grade: np.ndarray | None, upto: int, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The steepest grade up and down [deg, >= 0] (N,) on each way's first ``upto`` stations,
    on any of the points ``grade`` holds there (0 where unknown)."""
    if grade is None:
        return np.zeros(n), np.zeros(n)
    g = grade[:, :upto].astype(np.float64)
    g = np.nan_to_num(g.reshape(len(g), int(np.prod(g.shape[1:]))))
    return np.maximum(g.max(axis=1, initial=0.0), 0.0), np.maximum(-g.min(axis=1, initial=0.0), 0.0)


def _fit_grades(
    model: SpeedModel, error: float, frames: _Frames, steady: np.ndarray, steepest: tuple[np.ndarray, np.ndarray]
) -> tuple[SpeedModel, _Grades]:
    """``model`` with what grades shed, up and down, each kept where it explains ``frames`` better
    than none (:func:`fit_speed`); ``steady``: the frames on one column alone, nearly straight,
    with no lethal terrain near; ``steepest``: each way's steepest grade up and down [deg]."""
    way, curvature, v, grade = frames.way, frames.curvature, frames.v, frames.grade
    level_v = model.predict(way, curvature)  # what the terrain alone asks for
    intervals: list[tuple[float, float] | None] = [None, None]
    counts = [0, 0]
    for i, (name, along, against) in enumerate((("up_mps_per_deg", *steepest), ("down_mps_per_deg", *steepest[::-1]))):
        # Frames at the least speed may have been held there, short of what the grade sheds.
        rows = np.flatnonzero(steady & (along >= LEVEL_DEG) & (against < LEVEL_DEG) & (v > MIN_SPEED_MPS + 0.05))
        counts[i] = len(rows)
        if len(rows) < MIN_FRAMES:
            continue
        per_deg = np.maximum((level_v[rows] - v[rows]) / along[rows], 0.0)
        trial = replace(model, **{name: float(np.median(per_deg))})
        trial_error = float(np.mean(np.abs(trial.predict(way, curvature, grade) - v)))
        if trial_error < error - 1e-9:
            model, error = trial, trial_error
            intervals[i] = _interval(per_deg, rows) if frames.intervals else None
    return model, _Grades(model.up_mps_per_deg, model.down_mps_per_deg, (intervals[0], intervals[1]), (counts[0], counts[1]))


def _fit_rough(model: SpeedModel, frames: _Frames, steady: np.ndarray) -> tuple[SpeedModel, Rough]:
    """``model`` with a top speed on rough ground where one explains ``frames`` better than none
    (:func:`fit_speed`), and what the drive showed of it; ``steady``: the frames on one column
    alone, nearly straight, with no lethal terrain near."""
    way, curvature, v, grade, rough = frames.way, frames.curvature, frames.v, frames.grade, frames.rough
    asked = model.predict(way, curvature, grade)  # what terrain and grades alone ask for
    error = float(np.mean(np.abs(asked - v)))
    roughness = roughest(rough)
    slowed = steady & (asked > 1.05 * v)
    tried: list[tuple[float, SpeedModel, np.ndarray]] = []
    for band in ROUGH_BANDS_M:
        rows = np.flatnonzero(slowed & (roughness > band))
        if len(rows) < MIN_FRAMES:
            continue
        trial = replace(model, rough_m=band, rough_mps=max(float(np.median(v[rows])), MIN_SPEED_MPS))
        tried.append((float(np.mean(np.abs(trial.predict(way, curvature, grade, rough) - v))), trial, rows))
    better = [t for t in tried if t[0] < error - 1e-9]
    if not better:
        return model, Rough(int(np.count_nonzero(slowed & (roughness > ROUGH_BANDS_M[0]))))
    best_error = min(t[0] for t in better)
    alike = [t for t in better if t[0] <= best_error + ROUGH_ALIKE_MPS]
    _, kept, rows = alike[len(alike) // 2]  # the middle band of those that explain the drive as well as the best
    interval = _interval(v[rows], rows) if frames.intervals else None
    return kept, Rough(len(rows), interval, (alike[0][1].rough_m, alike[-1][1].rough_m))


def _interval(v: np.ndarray, rows: np.ndarray, resamples: int = 200) -> tuple[float, float]:
    """95% interval of the median of ``v`` by a bootstrap over blocks of 10 consecutive frames
    (neighbouring frames are not independent), seeded: the same interval on every run."""
    blocks = np.split(v, np.flatnonzero(np.diff(rows) > 1) + 1)
    blocks = [b[i : i + 10] for b in blocks for i in range(0, len(b), 10)]
    rng = np.random.default_rng(len(v))
    medians = [float(np.median(np.concatenate([blocks[i] for i in rng.integers(len(blocks), size=len(blocks))]))) for _ in range(resamples)]
    return float(np.percentile(medians, 2.5)), float(np.percentile(medians, 97.5))
