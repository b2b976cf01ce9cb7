"""The ``speed`` rule: how fast to drive the way the steering chose, learned from the same drive.

It does not steer: the rule that steers picks the way (a trajectory's or an offset's curvature),
and this rule picks the speed along it (:class:`LearnedSpeed`), from what the ground map the
planner keeps for it (terrapref.groundmap) has gathered of the ground the camera has shown, under and
ahead of the vehicle. The model and its fit are :mod:`.model`. Its fit reads, for every frame of
a drive, the ground map around the vehicle as the camera had shown it by then, along the way the
driver then drove (:class:`SpeedReader`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from terrapref.camera import PinholeCamera, SegmentationView
from terrapref.errors import UserError, finite_number
from terrapref.features import UtilityFeaturizer
from terrapref.groundmap.columns import TerrainColumns
from terrapref.groundmap.height import DepthImage
from terrapref.groundmap.map import GroundMap
from terrapref.groundmap.settings import MapSettings
from terrapref.records import to_plain
from terrapref.rules.base import (
    MOST_NUMBER,
    SPEED,
    Choice,
    FrameReader,
    HeaderContext,
    Rule,
    RuleConfig,
    RuleContext,
    RuleInput,
    SpeedRunner,
    Where,
    number,
)
from terrapref.rules.settings import NUMBER, PER_CLASS
from terrapref.rules.speed.calibration import GradeCheck
from terrapref.rules.speed.model import (
    CHORD_M,
    CHORD_WEIGHTS,
    LEVEL_DEG,
    MIN_FRAMES,
    MIN_SPEED_MPS,
    ROUGH_BANDS_M,
    ROUGH_PREVIEW_M,
    STATION_STEP_M,
    STATIONS,
    Drive,
    Rough,
    SpeedFit,
    SpeedModel,
    across,
    body_grade,
    fit_speed,
    stations_within,
)
from terrapref.scenario.path import ReferencePath
from terrapref.terrain import ClassTable
from terrapref.vehicle import Command, Pose
from terrapref.vehicle.ground import Attitude

if TYPE_CHECKING:
    from terrapref.demos.recording import Recording
    from terrapref.learning.train import FitData

# The speed rule's ground map where the steering rule reads none, and the one its fit reads the
# drive with: the offset rule's default geometry (0.1 m cells gathered over the last seconds, placed
# with the camera's attitude from the sky line). Where the offset rule steers, the planner keeps its
# map for both, so that a robot's ragged labels are outvoted alike.
MAP = MapSettings()
# A cell split between two terrain classes (its class holding under half its evidence, another
# at least 0.15) reads as never seen: a robot's network takes a patch of one class for another in
# regions that last a few frames (rock for mud under the `field` preset, docs/perception.md), and one such cell in the few
# dozen the way ahead crosses would slow the vehicle to the other class's speed; the cells around
# it tell which class it is. The edge of a patch against the ground is not split (the ground is
# not a terrain class), so a footprint that touches a patch in passing still slows for it.
SPLIT = (0.5, 0.15)
# The ground around the vehicle each training frame keeps (the vehicle frame: x ahead, y left):
# SNAPSHOT_X x SNAPSHOT_Y cells of SNAPSHOT_STEP_M from (SNAPSHOT_X0, -SNAPSHOT_Y0).
SNAPSHOT_STEP_M = 0.2
SNAPSHOT_X0, SNAPSHOT_Y0 = -1.0, 2.8
SNAPSHOT_X, SNAPSHOT_Y = 40, 29
CENTRE = 2  # the footprint point on the way's centre line (model.across)
FOOT = 5  # the footprint's points (model.across): the grade is read on each


@dataclass(frozen=True)
class SpeedConfig(RuleConfig):
    """The speed rule before fitting.

    Attributes:
        half_width_m: half the vehicle's width: the footprint whose ground sets the speed [m].
        max_speed_mps: the fastest it commands [m/s].
    """

    type: ClassVar[str] = "speed"
    arrays: ClassVar[dict[str, str]] = {
        "way": "finite >= 0",
        "curvature": "no inf",
        "v_mps": "finite >= 0",
        "frame": "finite >= 0",
        "grade": "no inf",
        "rough": "no inf",
    }
    without_data: ClassVar[str] = "the model gets no speed rule and drives at the control set's speed"

    half_width_m: float = 0.6
    max_speed_mps: float = 2.0

    def __post_init__(self) -> None:
        if not (0 < self.half_width_m < 3 and math.isfinite(self.max_speed_mps) and self.max_speed_mps > 0):
            raise ValueError("the speed rule needs a half width in (0, 3) m and a top speed > 0")

    def to_dict(self) -> dict:
        return to_plain(self)

    def summary(self) -> str:
        return "the speed rule, a cruising speed per class, on grades, on rough ground, in bends and near lethal terrain, learned from the drive"

    def data(self) -> dict[str, Any]:
        return {"half_width_m": self.half_width_m}

    def reader(self, featurizer: UtilityFeaturizer, camera: PinholeCamera, classes: ClassTable, n: int) -> SpeedReader:
        return SpeedReader(self.half_width_m, featurizer, camera, classes, n)

    def fit(self, data: FitData) -> SpeedRule | None:
        """The speed model fitted to the speeds the driver drove; None without the rule's arrays or a steady speed."""
        found = data.rule_config(self.type, lambda recorded: replace(self, half_width_m=float(recorded["half_width_m"])))
        if found is None:
            return None
        config, arrays = found
        features = data.dataset.feature_config
        table = ClassTable.from_dict(data.dataset.meta["classes"])
        lethal = table.lethal_columns(features.feature_classes)
        frame = arrays["frame"].astype(np.int64)
        grade, rough = (arrays.get(name) for name in ("grade", "rough"))  # absent from datasets featurised before they were read: flat
        grade, rough = (None if a is None or not np.isfinite(a).any() else a for a in (grade, rough))  # a drive on flat ground
        if grade is not None and grade.shape[1:] not in ((STATIONS,), (STATIONS, FOOT)):
            raise UserError(
                "speed rule",
                f"grades of {grade.shape[1:]} a sample; this version reads ({STATIONS}, {FOOT}), or ({STATIONS},) as read before",
            )
        fitted = fit_speed(Drive(arrays["way"], arrays["curvature"], arrays["v_mps"], frame, grade, rough), features.n_terrain, lethal)
        return None if fitted is None else SpeedRule(config, fitted.model, fitted, table.background)


class SpeedReader(FrameReader):
    """Each frame's ground around the vehicle as its ground map then held, and, once the drive is
    read, the way the driver drove from each frame: the speed rule's training arrays.

    Arrays: ``way`` (N, STATIONS, 9) uint8 terrain columns along the way driven (module
    :mod:`.model`); ``curvature`` (N,) the command's curvature w / v (NaN where v = 0) [1/m];
    ``v_mps`` (N,) the speed commanded [m/s]; ``frame`` (N,) the frame's number in its recording;
    ``grade`` (N, STATIONS, 5) the grade of the way driven at each station's footprint points,
    heading along it, as the ground map's height layer then showed it [deg, positive up; NaN:
    unknown, all of it on flat ground; datasets featurised before read the centre line alone,
    (N, STATIONS)]; ``rough`` (N, STATIONS) the ground's roughness on the way's centre line, the
    same way [m]."""

    def __init__(self, half_width_m: float, featurizer: UtilityFeaturizer, camera: PinholeCamera, classes: ClassTable, n: int) -> None:
        terrain = TerrainColumns.of(featurizer.class_columns, featurizer.config.n_terrain, classes)
        self.map = GroundMap(camera, terrain, MAP)
        self.k = terrain.k
        self.across = across(half_width_m)
        xs = SNAPSHOT_X0 + SNAPSHOT_STEP_M * np.arange(SNAPSHOT_X)
        ys = -SNAPSHOT_Y0 + SNAPSHOT_STEP_M * np.arange(SNAPSHOT_Y)
        self._grid = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1)  # (X, Y, 2) vehicle frame
        self.snapshots = np.empty((n, SNAPSHOT_X, SNAPSHOT_Y), dtype=np.uint8)
        self.gradients: np.ndarray | None = None  # the ground's gradient there (n, X, Y, 2), from the first depth image
        self.roughness: np.ndarray | None = None  # and its roughness (n, X, Y) [m]

    def read(self, j: int, view: SegmentationView, pose: Pose, path: ReferencePath, progress_m: float) -> None:
        depth = DepthImage.of(view, self.map.camera, pose)
        self.map.update(view, pose, depth)
        grid = _to_world(self._grid, pose)
        self.snapshots[j] = self.map.lookup(grid, SPLIT)
        if depth is not None:
            if self.gradients is None:
                self.gradients = np.full((len(self.snapshots), SNAPSHOT_X, SNAPSHOT_Y, 2), np.nan, dtype=np.float32)
                self.roughness = np.full((len(self.snapshots), SNAPSHOT_X, SNAPSHOT_Y), np.nan, dtype=np.float32)
            self.gradients[j] = self.map.gradient_at(grid)
            self.roughness[j] = self.map.roughness_at(grid)

    def arrays(self, recording: Recording, keep: np.ndarray, path: ReferencePath) -> dict[str, np.ndarray]:
        poses = recording.poses[keep].astype(float)
        v, w = recording.commands[keep, 0].astype(float), recording.commands[keep, 1].astype(float)
        with np.errstate(divide="ignore", invalid="ignore"):
            curvature = np.where(v > 0, w / v, np.nan)
        way = np.full((len(keep), STATIONS, len(self.across)), self.k + 1, dtype=np.uint8)
        grade = np.full((len(keep), STATIONS, FOOT), np.nan, dtype=np.float32)
        rough = np.full((len(keep), STATIONS), np.nan, dtype=np.float32)
        step = np.hypot(*np.diff(poses[:, :2], axis=0).T)
        gap = np.diff(keep) != 1  # frames not next to each other (left out, or another session): the way ends there
        step[gap] = np.inf
        travelled = np.concatenate([[0.0], np.cumsum(step)])
        d = STATION_STEP_M * np.arange(STATIONS)
        for j in range(len(keep)):
            end = np.searchsorted(travelled, travelled[j] + d[-1] + STATION_STEP_M, side="right")
            ahead = travelled[j:end] - travelled[j]
            reach = d <= ahead[-1]
            if not reach.any() or not np.isfinite(ahead[-1]):
                reach = d <= 0.0
            x = np.interp(d[reach], ahead, poses[j:end, 0])
            y = np.interp(d[reach], ahead, poses[j:end, 1])
            yaw = np.interp(d[reach], ahead, np.unwrap(poses[j:end, 2]))
            points = (
                np.stack([x, y], axis=-1)[:, None, :]
                + self.across[None, :, None] * np.stack([-np.sin(yaw), np.cos(yaw)], axis=-1)[:, None, :]
            )
            i, k, inside = self._snapshot_cells(points, tuple(poses[j]))
            way[j, reach] = np.where(inside, self.snapshots[j, i, k], self.k + 1)
            # The body's pitch heading along the way on each footprint point, the roughness on its centre line.
            if self.gradients is not None:
                gradient_at = functools.partial(self._gradient_at, j, tuple(poses[j]))
                grade[j, reach] = body_grade(gradient_at, points[:, :FOOT].reshape(-1, 2), np.repeat(yaw, FOOT)).reshape(-1, FOOT)
                centre = (i[:, CENTRE], k[:, CENTRE])
                rough[j, reach] = np.where(inside[:, CENTRE], self.roughness[j][centre], np.nan)
        return {
            "way": way,
            "curvature": curvature.astype(np.float32),
            "v_mps": v.astype(np.float32),
            "frame": keep.astype(np.float32),
            "grade": grade,
            "rough": rough,
        }

    def _gradient_at(self, j: int, pose: tuple[float, float, float], points: np.ndarray) -> np.ndarray:
        """The ground's gradient in frame ``j``'s snapshot at world ``points`` (..., 2); NaN outside it."""
        i, k, inside = self._snapshot_cells(points, pose)
        return np.where(inside[..., None], self.gradients[j, i, k], np.nan)

    def _snapshot_cells(self, points: np.ndarray, pose: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The snapshot cells (row, column) under world ``points`` (..., 2) with the vehicle at
        ``pose``, clipped to the snapshot, and whether each point lies inside it."""
        x, y, yaw = pose
        dx, dy = points[..., 0] - x, points[..., 1] - y
        c, s = math.cos(yaw), math.sin(yaw)
        i = np.floor((dx * c + dy * s - SNAPSHOT_X0) / SNAPSHOT_STEP_M + 0.5).astype(np.int64)
        k = np.floor((-dx * s + dy * c + SNAPSHOT_Y0) / SNAPSHOT_STEP_M + 0.5).astype(np.int64)
        inside = (i >= 0) & (i < SNAPSHOT_X) & (k >= 0) & (k < SNAPSHOT_Y)
        return np.clip(i, 0, SNAPSHOT_X - 1), np.clip(k, 0, SNAPSHOT_Y - 1), inside


def _to_world(points: np.ndarray, pose: Pose) -> np.ndarray:
    """Vehicle-frame points (..., 2) in the world frame at ``pose``."""
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    return np.stack([x + points[..., 0] * c - points[..., 1] * s, y + points[..., 0] * s + points[..., 1] * c], axis=-1)


# The most a degree of grade may shed in a model file [m/s per deg]: a top speed of 2 m/s gone in 2 deg.
MAX_SHED_MPS_PER_DEG = 1.0
# The fastest a model file's speeds may be [m/s]: past what an imported log of the fastest robot a
# robot file allows can show (its top speed of 30 m/s, commands taken to 1.5 times it and 0.5).
MOST_MPS = 50.0


@dataclass(frozen=True)
class SpeedRule(Rule):
    """A fitted speed rule (``fit``: how the fit went, for a rule just fitted)."""

    type: ClassVar[str] = "speed"
    kind: ClassVar[str] = SPEED
    settable: ClassVar[dict[str, tuple[str, str]]] = {
        "max_speed_mps": (NUMBER, "the fastest it commands [m/s]"),
        "class_max_mps": (PER_CLASS, "the fastest it commands on a class, below the speed learned there [m/s]"),
    }

    config: SpeedConfig
    model: SpeedModel
    fit: SpeedFit | None = None
    # The class table's background class, by name (the last terrain column's); None: not named (a
    # file older than the field), printed as "background".
    background: str | None = None

    @classmethod
    def setting_problem(cls, name: str, value: float) -> str | None:
        """A top speed of 0 or less, or on a class one below the least cruising speed the rule commands."""
        if name == "max_speed_mps":
            return "expected a top speed > 0 [m/s]" if not value > 0 else None
        return f"expected at least {MIN_SPEED_MPS:g} m/s, the least cruising speed" if value < MIN_SPEED_MPS else None

    @property
    def reads_relief(self) -> bool:
        """Whether it learned speeds on grades or rough ground."""
        return self.model.sheds_on_grades or self.model.slows_on_rough

    def with_settings(self, values: Mapping[str, Any], names: tuple[str, ...], lethal: frozenset[str]) -> SpeedRule:
        """The rule no faster than ``values`` say: overall (``max_speed_mps``) and on each class
        named (``class_max_mps``: the cruising speed learned there, capped). A class it keeps no
        speed for (unknown, or lethal), or a cap below the least cruising speed, is a ValueError."""
        rule = self
        if "max_speed_mps" in values:
            rule = replace(rule, config=replace(rule.config, max_speed_mps=float(values["max_speed_mps"])))
        caps = values.get("class_max_mps", {})
        columns = {name: col for col, name in self._classes(names, lethal)}
        for name, cap in caps.items():
            if name not in columns:
                raise ValueError(f"no speed is kept for {name!r}; the classes: {', '.join(columns)}")
            problem = self.setting_problem("class_max_mps", cap)
            if problem is not None:
                raise ValueError(f"{name}: {problem}")
        speeds = list(rule.model.speeds_mps)
        for name, cap in caps.items():
            speeds[columns[name]] = min(speeds[columns[name]], float(cap))
        return replace(rule, model=replace(rule.model, speeds_mps=tuple(speeds)))

    def header(self) -> dict[str, Any]:
        m = self.model
        out = {
            "type": self.type,
            **self.config.to_dict(),
            "speeds_mps": list(m.speeds_mps),
            "preview_m": m.preview_m,
            "lateral_accel_mps2": m.lateral_accel_mps2,
            "near_lethal_m": m.near_lethal_m,
            "near_lethal_mps": m.near_lethal_mps,
            "lethal": list(m.lethal),
            "min_points": m.min_points,
            "drive_lateral_mps2": m.drive_lateral_mps2,
            **({"background": self.background} if self.background is not None else {}),
        }
        if m.sheds_on_grades:  # a flat drive's model file is as it was before grades were learned
            out |= {"up_mps_per_deg": m.up_mps_per_deg, "down_mps_per_deg": m.down_mps_per_deg, "grades_across": m.grades_across}
        if m.slows_on_rough:  # and before rough ground was
            out |= {"rough_m": m.rough_m, "rough_mps": m.rough_mps}
        if self.fit is not None:
            out |= {
                "intervals_mps": [list(i) if i is not None else None for i in self.fit.intervals],
                "lag_frames": self.fit.lag_frames,
                "samples": self.fit.samples,
                "error_mps": self.fit.error_mps,
            }
            if self.fit.on_grades:  # a drive on relief: what it showed of grades, learned or not
                out |= {
                    "grade_intervals": [list(i) if i is not None else None for i in self.fit.grade_intervals],
                    "grade_frames": list(self.fit.grade_frames),
                }
            if self.fit.rough is not None:  # what it showed of rough ground, learned or not
                shown = self.fit.rough
                out |= {
                    "rough_frames": shown.frames,
                    "rough_interval": list(shown.interval) if shown.interval is not None else None,
                    "rough_alike_m": list(shown.alike_m) if shown.alike_m is not None else None,
                }
        return out

    @classmethod
    def from_header(cls, block: Mapping[str, Any], context: HeaderContext, where: Where) -> SpeedRule:
        k = context.features.n_terrain
        speeds = block.get("speeds_mps")
        # Slower than the least cruising speed reads as it (a log's standing noise may fit so).
        if not (isinstance(speeds, list) and len(speeds) == k + 1 and all(finite_number(v) and 0 < v <= MOST_MPS for v in speeds)):
            raise where.error(
                "speeds_mps",
                f"expected {k + 1} cruising speeds > 0 and at most {MOST_MPS:g} m/s, one per terrain column and the background",
            )
        lethal = block.get("lethal", [])
        if not (isinstance(lethal, list) and all(isinstance(c, int) and not isinstance(c, bool) and 0 <= c < k for c in lethal)):
            raise where.error("lethal", f"expected terrain columns 0..{k - 1} (column {k} is the background, never lethal)")
        optional = _optional_fields(block, where)
        top = number(block, "max_speed_mps", where, 2.0)
        if not MIN_SPEED_MPS <= top <= MOST_MPS:
            raise where.error("max_speed_mps", f"expected {MIN_SPEED_MPS:g} to {MOST_MPS:g} m/s, got {top:g}")
        try:
            config = SpeedConfig(number(block, "half_width_m", where, 0.6), top)
        except ValueError as exc:
            raise where.error("", str(exc)) from None
        model = SpeedModel(
            tuple(float(v) for v in speeds),
            number(block, "preview_m", where, positive=True),
            optional["lateral_accel_mps2"],
            optional["near_lethal_m"],
            optional["near_lethal_mps"],
            tuple(lethal),
            _points(block, where),
            optional["drive_lateral_mps2"],
            optional["up_mps_per_deg"],
            optional["down_mps_per_deg"],
            optional["rough_m"],
            optional["rough_mps"],
            _grades_across(block, where),
        )
        _intervals_in_order(block, where)
        fit = None
        intervals = block.get("intervals_mps")
        if isinstance(intervals, list) and len(intervals) == k + 1:
            fit = SpeedFit(
                model,
                tuple(_interval_of(i) for i in intervals),
                int(number(block, "lag_frames", where, 0.0, low=0.0)),
                int(number(block, "samples", where, 0.0, low=0.0)),
                number(block, "error_mps", where, 0.0, low=0.0),
                _grade_intervals(block.get("grade_intervals")),
                _grade_frames(block.get("grade_frames")),
                "grade_frames" in block,
                _rough_shown(block),
            )
        background = block.get("background")
        if background is not None and (not isinstance(background, str) or not background):
            raise where.error("background", "expected the background class's name")
        return cls(config, model, fit, background)

    def runner(self, context: RuleContext) -> LearnedSpeed:
        """Bound to one planner."""
        return LearnedSpeed(self)

    def describe(self, names: tuple[str, ...], lethal: frozenset[str]) -> str:
        """The cruising speed per class with its interval, and the limits."""
        return "speed rule: " + "; ".join(self.lines(names, lethal))

    def warnings(self, names: tuple[str, ...], lethal: frozenset[str]) -> list[str]:
        """The classes the drive never showed at a steady speed, and the speed they are driven at:
        the slowest the drive showed (:func:`~terrapref.rules.speed.model.fit_speed`)."""
        unseen = [(name, col) for col, name in self._classes(names, lethal) if self.fit is not None and self.fit.intervals[col] is None]
        if not unseen:
            return []
        v = min(self.model.speeds_mps[col] for _, col in unseen)
        return [
            f"{', '.join(name for name, _ in unseen)}: never shown at a steady speed; driven at {v:.2f} m/s, the slowest the drive "
            f"showed (a lane of {'each' if len(unseen) > 1 else 'it'}, as teaching courses lay them, shows the speed kept on it)"
        ]

    def lines(self, names: tuple[str, ...], lethal: frozenset[str]) -> list[str]:
        """What was learned, a line each: the speed per class the drive showed at a steady speed (interval), then the limits."""
        m, fit = self.model, self.fit
        out = []
        for col, name in self._classes(names, lethal):
            interval = fit.intervals[col] if fit is not None else None
            if fit is not None and interval is None:  # never shown at a steady speed: :meth:`warnings`
                continue
            around = f" (95% CI {interval[0]:.2f}-{interval[1]:.2f})" if interval is not None else ""
            out.append(f"{name} {m.speeds_mps[col]:.2f} m/s{around}")
        points = f" on {m.min_points} of 5 footprint points" if m.min_points > 1 else ""
        out.append(f"slows {m.preview_m:g} m before a slower class{points}")
        if m.sheds_on_grades or (fit is not None and fit.on_grades):
            out.append(f"grades: {self._grade_line(0, m.up_mps_per_deg, 'up')}; {self._grade_line(1, m.down_mps_per_deg, 'down')}")
        if m.sheds_on_grades and not m.grades_across:
            out.append(
                "grades read on the way's centre line, as its drive was (a file from before they were read on the footprint's points)"
            )
        if m.slows_on_rough or (fit is not None and fit.rough is not None):
            out.append(f"rough ground: {self._rough_line()}")
        bends = f"at most {m.lateral_accel_mps2:.2f} m/s^2 sideways" if m.lateral_accel_mps2 is not None else "no limit shown"
        out.append(f"bends: {bends}")
        if m.drive_lateral_mps2 is not None:
            out.append(f"never more than {m.drive_lateral_mps2:.2f} m/s^2 sideways (the drive's most)")
        if m.near_lethal_m is not None and m.near_lethal_mps is not None:
            out.append(f"near lethal terrain (within {m.near_lethal_m:g} m): {m.near_lethal_mps:.2f} m/s")
        if fit is not None:
            out.append(f"fitted to {fit.samples} frames, mean error {fit.error_mps:.3f} m/s")
        return out

    def _grade_line(self, i: int, per_deg: float | None, way: str) -> str:
        """What a degree of grade ``way`` (index ``i``: up 0, down 1) sheds, with its interval and frames."""
        frames = self.fit.grade_frames[i] if self.fit is not None else 0
        if per_deg is None:
            # Frames at the least speed are not counted: the grade may have held the speed there, short of what it sheds.
            shown = f"{frames} frames on one class past {LEVEL_DEG:g} deg {way} faster than {MIN_SPEED_MPS + 0.05:g} m/s"
            why = f"fewer than {MIN_FRAMES}" if frames < MIN_FRAMES else "slowing there explains them no better"
            return f"nothing learned {way} ({shown}: {why})"
        interval = self.fit.grade_intervals[i] if self.fit is not None else None
        around = f" (95% CI {interval[0]:.3f}-{interval[1]:.3f}, {frames} frames)" if interval is not None else ""
        return f"{per_deg:.3f} m/s per deg {way}{around}"

    def _rough_line(self) -> str:
        """The top speed on rough ground, past which roughness, with its interval, its frames and
        the roughness the drive cannot tell from the one kept; or what the drive showed."""
        m, shown = self.model, self.fit.rough if self.fit is not None else None
        where = f"within {ROUGH_PREVIEW_M:g} m ahead"
        if not m.slows_on_rough:
            frames = shown.frames if shown is not None else 0
            why = f"fewer than {MIN_FRAMES}" if frames < MIN_FRAMES else "a top speed there explains them no better"
            return f"nothing learned ({frames} frames slower than terrain and grades ask, past {ROUGH_BANDS_M[0]:g} m {where}: {why})"
        line = f"at most {m.rough_mps:.2f} m/s where the ground {where} is rougher than {m.rough_m:g} m"
        if shown is not None and shown.interval is not None:
            line += f" (95% CI {shown.interval[0]:.2f}-{shown.interval[1]:.2f} m/s, {shown.frames} frames)"
        if shown is not None and shown.alike_m is not None and shown.alike_m[0] != shown.alike_m[1]:
            line += f"; the drive cannot tell a roughness of {shown.alike_m[0]:g}-{shown.alike_m[1]:g} m from it"
        return line

    def _classes(self, names: tuple[str, ...], lethal: frozenset[str]) -> list[tuple[int, str]]:
        """(column, class) of every terrain column a speed is kept for: ``names``, then the background; not the lethal ones."""
        return [(col, name) for col, name in enumerate((*names, self.background or "background")) if name not in lethal]


def _grades_across(block: Mapping[str, Any], where: Where) -> bool:
    """Whether a speed rule block's grades are read on each of the footprint's points (absent:
    on the centre line, as files written before read them)."""
    value = block.get("grades_across", False)
    if not isinstance(value, bool):
        raise where.error("grades_across", f"expected true or false, got {value!r}")
    return value


def _optional_fields(block: Mapping[str, Any], where: Where) -> dict[str, float | None]:
    """A speed rule block's fields a drive may not have fitted (None where absent), each checked
    against what a drive can show (a UserError naming the field)."""
    optional = {}
    for name in ("lateral_accel_mps2", "drive_lateral_mps2", "near_lethal_m", "near_lethal_mps"):
        optional[name] = None if block.get(name) is None else number(block, name, where, positive=True)
    if optional["near_lethal_mps"] is not None and optional["near_lethal_mps"] > MOST_MPS:
        raise where.error("near_lethal_mps", f"expected at most {MOST_MPS:g} m/s, got {optional['near_lethal_mps']:g}")
    for name in ("up_mps_per_deg", "down_mps_per_deg"):  # absent from a flat drive's file
        optional[name] = None if block.get(name) is None else number(block, name, where, low=0.0)
    for name in ("rough_m", "rough_mps"):  # likewise
        optional[name] = None if block.get(name) is None else number(block, name, where, positive=True)
    if (optional["rough_m"] is None) != (optional["rough_mps"] is None):
        raise where.error("rough_m", "rough_m and rough_mps come together: the roughness past which the top speed holds, and that speed")
    if optional["rough_mps"] is not None and optional["rough_mps"] < MIN_SPEED_MPS:
        raise where.error("rough_mps", f"expected at least {MIN_SPEED_MPS:g} m/s, the least cruising speed")
    # Past what any drive shows (a robot's log may be fast: MOST_MPS).
    bounds = (
        ("up_mps_per_deg", MAX_SHED_MPS_PER_DEG),
        ("down_mps_per_deg", MAX_SHED_MPS_PER_DEG),
        ("rough_m", 1.0),
        ("rough_mps", MOST_MPS),
    )
    for name, most in bounds:
        if optional[name] is not None and optional[name] > most:  # past what a drive shows: a file written by hand
            raise where.error(name, f"expected at most {most:g}, got {optional[name]:g}")
    return optional


def _interval_of(value: object) -> tuple[float, float] | None:
    """An interval a block keeps: two numbers, else None (not given, or not readable)."""
    return (
        (float(value[0]), float(value[1])) if isinstance(value, list) and len(value) == 2 and all(finite_number(x) for x in value) else None
    )


def _intervals_in_order(block: Mapping[str, Any], where: Where) -> None:
    """Every interval a speed rule block keeps reads low then high (a UserError naming the field)."""
    kept = {name: block.get(name) for name in ("intervals_mps", "grade_intervals")}
    for name, value in {**kept, "rough_interval": [block.get("rough_interval")], "rough_alike_m": [block.get("rough_alike_m")]}.items():
        for pair in value if isinstance(value, list) else []:
            interval = _interval_of(pair)
            if interval is not None and interval[0] > interval[1]:
                raise where.error(name, f"an interval reads high then low: {interval[0]:g} to {interval[1]:g}")


def _grade_intervals(value: object) -> tuple[tuple[float, float] | None, tuple[float, float] | None]:
    """A block's ``grade_intervals`` (up, down), each None where not given or not two numbers."""
    up, down = value if isinstance(value, list) and len(value) == 2 else (None, None)
    return _interval_of(up), _interval_of(down)


def _rough_shown(block: Mapping[str, Any]) -> Rough | None:
    """What a block says the drive showed of rough ground (None: a file without it)."""
    if "rough_frames" not in block:
        return None
    frames = block["rough_frames"]
    alike = _interval_of(block.get("rough_alike_m"))
    counted = finite_number(frames) and 0 <= frames <= MOST_NUMBER
    return Rough(int(frames) if counted else 0, _interval_of(block.get("rough_interval")), alike)


def _grade_frames(value: object) -> tuple[int, int]:
    """A block's ``grade_frames`` (up, down); 0 where not given."""
    ok = isinstance(value, list) and len(value) == 2 and all(isinstance(x, int) and not isinstance(x, bool) and x >= 0 for x in value)
    return (value[0], value[1]) if ok else (0, 0)


def _points(block: Mapping[str, Any], where: Where) -> int:
    """A block's ``min_points``: 1 to 5 (1 where a file does not say)."""
    points = block.get("min_points", 1)
    if isinstance(points, bool) or not isinstance(points, int) or not 1 <= points <= 5:
        raise where.error("min_points", "expected an integer from 1 to 5: the footprint points a class must hold to count")
    return points


class LearnedSpeed(SpeedRunner):
    """The speed rule bound to one planner: the speed along a chosen way, read from the ground map
    the planner keeps for the steering rule, or where that rule reads none, from one of
    :attr:`map_settings`."""

    map_settings: MapSettings = MAP

    def __init__(self, rule: SpeedRule) -> None:
        self.rule = rule
        self.across = across(rule.config.half_width_m)
        self._d = STATION_STEP_M * np.arange(STATIONS)
        self._rough_stations = stations_within(ROUGH_PREVIEW_M)
        self._last_v = 0.0  # the speed commanded last [m/s]
        self.grades = GradeCheck(STATIONS)  # the grades read ahead against the body's pitch once there

    def reset(self) -> None:
        """Forget the speed commanded last and the grades' errors (a new path)."""
        self._last_v = 0.0
        self.grades.reset()

    def commanded(self, v_mps: float) -> None:
        """The speed [m/s] the planner commanded (0 when it stopped), for the next :meth:`yaw_rate`."""
        self._last_v = float(v_mps)

    def going_mps(self, speed_mps: float | None) -> float:
        """How fast the vehicle may be going [m/s]: the faster of its odometry's ``speed_mps``
        (None: unknown) and the speed commanded last (:meth:`commanded`; 0 before the first),
        toward which it may still be speeding up."""
        return max(speed_mps or 0.0, self._last_v)

    def along(self, ground_map: GroundMap, frame: RuleInput, choice: Choice, set_v_mps: float, max_yaw_rate_rps: float) -> Choice:
        """``choice``, steered at the control set's ``set_v_mps``, at this rule's speed along its way
        (:meth:`speed`: along the path shifted by the choice's offset, or its arc) with the yaw rate
        of the same curvature (:meth:`yaw_rate`, at the vehicle's speed the frame gives)."""
        curvature = choice.command.w / set_v_mps
        way = (frame.path, frame.progress_m, choice.offset_m) if choice.offset_m is not None else None
        v = self.speed(ground_map, frame.pose, curvature, max_yaw_rate_rps, way, frame.view.attitude)
        return Choice(choice.index, Command(v, self.yaw_rate(curvature, v, frame.speed_mps)), choice.offset_m)

    def speed(
        self,
        gmap: GroundMap,
        pose: Pose,
        curvature: float,
        max_yaw_rate_rps: float,
        along: tuple[ReferencePath, float, float] | None = None,
        attitude: Attitude | None = None,
    ) -> float:
        """The speed [m/s] along the way chosen, as ``gmap`` (the ground map it reads, updated with
        the frame) shows it, within the rule's top speed and the speed at which an arc
        of ``curvature`` [1/m] needs no more than ``max_yaw_rate_rps``. With the body's ``attitude``
        (its odometry's; None: not known), a model that sheds speed on grades checks the grades it
        read ahead against the body's pitch once there, and takes what it reads as those checks say
        reads of that size turned out (terrapref.rules.speed.calibration).

        The way: with ``along`` (path, progress [m], offset [m]: a rule that holds an offset from
        the path), the footprint where the vehicle is, then the path shifted by the offset ahead
        of the progress, as the driver's way was read for the fit; else the arc of ``curvature``
        from ``pose``."""
        x, y, yaw = pose
        d, k = self._d, curvature
        if along is not None:
            path, progress_m, offset_m = along
            s = np.minimum(progress_m + d, path.length_m)
            heading = path.heading_at(s)
            centre = path.point_at(s) + offset_m * np.stack([-np.sin(heading), np.cos(heading)], axis=-1)
            centre[0], heading[0] = (x, y), yaw
            px, py = centre[:, 0], centre[:, 1]
        else:
            heading = yaw + k * d
            if abs(k) < 1e-9:
                px, py = x + d * math.cos(yaw), y + d * math.sin(yaw)
            else:
                px, py = x + (np.sin(heading) - math.sin(yaw)) / k, y - (np.cos(heading) - math.cos(yaw)) / k
        normal = np.stack([-np.sin(heading), np.cos(heading)], axis=-1)
        centre = np.stack([px, py], axis=-1)
        points = centre[:, None, :] + self.across[None, :, None] * normal[:, None, :]
        way = gmap.lookup(points, SPLIT)[None]
        grade = None
        if self.rule.model.sheds_on_grades:  # the body's pitch along the way, as the height layer shows the ground
            read = self._grades(gmap, points, heading)
            if attitude is not None:  # the centre line's grades checked against the body's pitch (station 0 at once)
                self.grades.keep(centre, np.broadcast_to(heading, (len(centre),)), read[:, read.shape[1] // 2])
                self.grades.arrived(x, y, yaw, math.degrees(attitude.grade_rad))
                read = self.grades.corrected(read)
            grade = read[None]
        rough = None
        if self.rule.model.slows_on_rough:  # the roughness on the way's first stations (model.roughest reads no further)
            near = self._rough_stations
            rough = np.full((1, STATIONS), np.nan)
            rough[0, :near] = gmap.roughness_at(centre[:near])
        v = float(self.rule.model.predict(way, np.array([k]), grade, rough)[0])
        top = self.rule.config.max_speed_mps
        if abs(k) > 1e-9:
            top = min(top, max_yaw_rate_rps / abs(k))
            if self.rule.model.drive_lateral_mps2 is not None:  # never harder sideways than the drive went
                top = min(top, math.sqrt(self.rule.model.drive_lateral_mps2 / abs(k)))
        return min(v, top)

    def _grades(self, gmap: GroundMap, points: np.ndarray, heading: np.ndarray) -> np.ndarray:
        """The body's pitch [deg] heading ``heading`` along the way, as ``gmap`` shows the ground, at
        the points across ``points`` (S, 9, 2) the model read its drive on: (S, 5), each footprint
        point, or (S, 1), the centre line alone (a model file from before)."""
        on = points[:, :FOOT] if self.rule.model.grades_across else points[:, CENTRE : CENTRE + 1]
        heading = np.repeat(np.broadcast_to(heading, (len(points),)), on.shape[1])
        return gmap.body_grades(on.reshape(-1, 2), heading, (CHORD_M, CHORD_WEIGHTS)).reshape(len(points), on.shape[1])

    def yaw_rate(self, curvature: float, v_mps: float, speed_mps: float | None = None) -> float:
        """The yaw rate [rad/s] that drives an arc of ``curvature`` [1/m] at the commanded ``v_mps``,
        turned no harder than the model's lateral limit (SpeedModel.lateral_limit_mps2) allows at
        the fastest the vehicle may go until the next decision: ``v_mps``, its speed ``speed_mps``
        [m/s] when the frame was taken (None: unknown), or the speed commanded last
        (:meth:`commanded`), toward which it may have gone on speeding up since. A vehicle still
        faster than ``v_mps`` (braking into a bend) widens its arc for a moment instead of going
        harder sideways than the driver did."""
        w = curvature * v_mps
        fastest = max(v_mps, self.going_mps(speed_mps))
        lateral = self.rule.model.lateral_limit_mps2
        if lateral is None or fastest <= 0 or abs(w) * fastest <= lateral:
            return w
        return math.copysign(lateral / fastest, w)
