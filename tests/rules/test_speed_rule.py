"""The speed rule (terrapref.rules.speed, SPEC 18): its model's speed against closed-form answers,
its fit recovering a model that made the speeds it is given, its file block's checks, its runner
on a ground map a tiny scenario fills, the rule that drives beside it, and the comparison of a
planner's speeds with its driver's (terrapref.evaluation.speed).

The checks every registered rule shares (round trip, determinism, blank frames) are
tests/rules/test_rules.py's; these are the speed rule's own.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from helpers import model_meta, skip_path_weights
from terrapref.camera import PinholeCamera, SegmentationRenderer, SegmentationView
from terrapref.dataset import FORMAT as DATASET_FORMAT
from terrapref.dataset import Dataset, load_dataset, save_dataset
from terrapref.demos.expert import ExpertConfig
from terrapref.demos.meta import ExpertInfo, HumanInfo
from terrapref.errors import UserError
from terrapref.evaluation.speed import LATERAL_TOLERANCE, TIME_TOLERANCE, SpeedComparison, driver_lateral_limit, trained_driver
from terrapref.features import FeatureConfig, UtilityFeaturizer
from terrapref.groundmap.map import GroundMap
from terrapref.learning.model_file import load_model, save_model
from terrapref.learning.network import ClassifierConfig
from terrapref.learning.train import FitData
from terrapref.planner import Planner, PlannerDriver
from terrapref.rules import ArgmaxRule, HeaderContext, OffsetConfig, OffsetRule, RuleContext, chosen_rule, driving_rule, speed_rule
from terrapref.rules.base import SPEED, STEERING, Where
from terrapref.rules.offset.fit import OffsetUtility
from terrapref.rules.speed.model import MIN_SPEED_MPS, STATIONS, Drive, Rough, SpeedFit, SpeedModel, across, fit_speed
from terrapref.rules.speed.rule import LearnedSpeed, SpeedConfig, SpeedRule
from terrapref.scenario import AVOID, Scenario, parse_scenario
from terrapref.scenario.path import ReferencePath
from terrapref.sim import Simulation, run_episode
from terrapref.terrain import default_classes
from terrapref.vehicle.ground import Attitude
from terrapref.world import rasterise

SOURCE = "speed-under-test"
FEATURES = FeatureConfig()
K = FEATURES.n_terrain  # 4 terrain columns: non_traversable 0, water 1, rock 2, mud 3; column 4 the background
LETHAL, WATER, ROCK, MUD, BACKGROUND, NEVER = 0, 1, 2, 3, K, K + 1
assert FEATURES.feature_classes == ("non_traversable", "water", "rock", "mud")

# Cruising speeds [m/s] by column: the lethal column's as a fit leaves it (the slowest learned).
SPEEDS = (0.5, 0.5, 0.8, 0.9, 1.6)
MODEL = SpeedModel(SPEEDS, preview_m=1.5, lateral_accel_mps2=None, near_lethal_m=None, near_lethal_mps=None, lethal=(LETHAL,))
PREVIEW_STATIONS = 7  # 1.5 m at 0.25 m a station, the one under the vehicle included


def _way(*marks: tuple[int, int | slice, int]) -> np.ndarray:
    """One way (1, STATIONS, 9) all background but for ``(station, points, column)`` marks."""
    way = np.full((1, STATIONS, 9), BACKGROUND, dtype=np.uint8)
    for station, points, column in marks:
        way[0, station, points] = column
    return way


def _predict(model: SpeedModel, way: np.ndarray, curvature: float = 0.0) -> float:
    (v,) = model.predict(way, np.array([curvature]))
    return float(v)


# --- 1. the model's speed, in closed form ---------------------------------------------------------------


def test_the_points_across_are_the_footprint_then_the_rings():
    np.testing.assert_allclose(across(0.6), [-0.6, -0.3, 0.0, 0.3, 0.6, -1.6, -1.1, 1.1, 1.6])


def test_a_way_all_background_is_driven_at_the_background_speed():
    assert _predict(MODEL, _way()) == 1.6


def test_a_slower_class_counts_within_the_preview_and_not_beyond():
    last = PREVIEW_STATIONS - 1  # 1.5 m ahead
    assert _predict(MODEL, _way((last, 2, WATER))) == 0.5
    assert _predict(MODEL, _way((last + 1, slice(0, 5), WATER))) == 1.6
    assert _predict(MODEL, _way((0, 4, ROCK))) == 0.8  # one footprint point under the vehicle is enough (min_points 1)
    assert _predict(MODEL, _way((2, 5, WATER), (2, 8, WATER))) == 1.6  # the rings' points carry no cruising speed
    assert _predict(MODEL, _way((1, 0, MUD), (3, 2, ROCK))) == 0.8  # the slowest of those met
    ways = np.concatenate([_way(), _way((3, 1, WATER)), _way((PREVIEW_STATIONS, 1, WATER))])
    np.testing.assert_array_equal(MODEL.predict(ways, np.zeros(3)), [1.6, 0.5, 1.6])  # each way its own speed


def test_a_longer_preview_sees_further():
    way = _way((12, 2, WATER))  # 3 m ahead
    assert _predict(replace(MODEL, preview_m=2.75), way) == 1.6
    assert _predict(replace(MODEL, preview_m=3.0), way) == 0.5


def test_lethal_and_never_seen_columns_carry_no_cruising_speed():
    slow = replace(MODEL, speeds_mps=(0.2, 0.5, 0.8, 0.9, 1.6))  # a lethal column's own speed, slower than any, is not read either
    assert _predict(slow, _way((1, slice(0, 5), LETHAL))) == 1.6
    assert _predict(slow, _way((1, slice(0, 5), NEVER), (2, 2, 200))) == 1.6  # K + 1 and ids beyond it
    unseen = np.full((1, STATIONS, 9), NEVER, dtype=np.uint8)
    assert _predict(MODEL, unseen) == 0.5  # nothing seen: the slowest cruising speed
    assert _predict(MODEL, np.full((1, STATIONS, 9), LETHAL, dtype=np.uint8)) == 0.5


def test_min_points_ignores_a_class_on_fewer_of_a_stations_footprint_points():
    two = replace(MODEL, min_points=2)
    one_point, two_points = _way((3, 0, WATER)), _way((3, 0, WATER), (3, 4, WATER))
    assert _predict(MODEL, one_point) == 0.5
    assert _predict(two, one_point) == 1.6
    assert _predict(two, two_points) == 0.5
    assert _predict(two, _way((3, 0, WATER), (4, 0, WATER))) == 1.6  # points are counted within one station
    assert _predict(replace(MODEL, min_points=3), two_points) == 1.6


@pytest.mark.parametrize("curvature", [0.5, -0.5, 2.0])
def test_a_bend_is_driven_at_the_lateral_limits_speed(curvature: float):
    bends = replace(MODEL, lateral_accel_mps2=0.4)
    assert _predict(bends, _way(), curvature) == pytest.approx(math.sqrt(0.4 / abs(curvature)))
    assert _predict(bends, _way(), 0.0) == 1.6
    assert _predict(bends, _way(), 0.1) == 1.6  # sqrt(4) = 2 m/s: the cruising speed is slower
    assert _predict(MODEL, _way(), curvature) == 1.6  # no limit: bends are not slowed


@pytest.mark.parametrize(
    ("ring_m", "station", "point", "slows"),
    [
        (1.0, 2, 2, True),  # lethal under the footprint
        (0.5, 2, 0, True),
        (1.0, 2, 5, True),  # the outer ring, left
        (1.0, 2, 8, True),  # and right
        (0.5, 2, 5, False),  # a ring of 0.5 m: only the inner rings count
        (0.5, 2, 8, False),
        (0.5, 2, 6, True),
        (0.5, 2, 7, True),
        (1.0, PREVIEW_STATIONS - 1, 7, True),  # 1.5 m ahead: within the preview
        (1.0, PREVIEW_STATIONS, 7, False),  # beyond it
    ],
)
def test_near_lethal_terrain_slows_within_its_ring_and_the_preview(ring_m: float, station: int, point: int, slows: bool):
    near = replace(MODEL, near_lethal_m=ring_m, near_lethal_mps=0.7)
    assert _predict(near, _way((station, point, LETHAL))) == (0.7 if slows else 1.6)
    assert _predict(near, _way((station, point, WATER))) == (0.5 if point < 5 else 1.6)  # no lethal terrain: cruising speeds alone


GRADED = replace(MODEL, up_mps_per_deg=0.03, down_mps_per_deg=0.02)


def _graded(*marks: tuple[int, float]) -> np.ndarray:
    """One way's grades (1, STATIONS) [deg], level but for ``(station, grade)`` marks."""
    grade = np.zeros((1, STATIONS))
    for station, g in marks:
        grade[0, station] = g
    return grade


def test_grades_within_the_preview_shed_speed_per_degree_up_and_down():
    (up,) = GRADED.predict(_way(), np.zeros(1), _graded((2, 10.0)))
    (down,) = GRADED.predict(_way(), np.zeros(1), _graded((2, -10.0)))
    assert up == pytest.approx(1.6 - 0.3) and down == pytest.approx(1.6 - 0.2)
    (both,) = GRADED.predict(_way(), np.zeros(1), _graded((1, 5.0), (4, -12.0)))
    assert both == pytest.approx(1.6 - 0.24)  # the station that sheds most
    (beyond,) = GRADED.predict(_way(), np.zeros(1), _graded((PREVIEW_STATIONS, 20.0)))
    (unknown,) = GRADED.predict(_way(), np.zeros(1), _graded((2, math.nan)))
    assert beyond == unknown == 1.6 == GRADED.predict(_way(), np.zeros(1))[0]  # beyond the preview, unknown or not given: level
    (on_rock,) = GRADED.predict(_way((2, 1, ROCK)), np.zeros(1), _graded((5, 10.0)))
    assert on_rock == 0.8  # the rock on level ground is slower than the grass on the grade (1.3)
    assert GRADED.predict(_way((5, 1, ROCK)), np.zeros(1), _graded((5, 10.0)))[0] == pytest.approx(0.8 - 0.3)  # shed from the class's speed
    (flat,) = MODEL.predict(_way(), np.zeros(1), _graded((2, 10.0)))
    assert flat == 1.6 and not MODEL.sheds_on_grades  # a model from a flat drive sheds nothing
    assert GRADED.predict(_way(), np.zeros(1), _graded((2, 60.0)))[0] == MIN_SPEED_MPS


def test_grades_on_the_footprints_points_shed_from_the_steepest_of_them():
    """Read on each of a station's 5 footprint points, the grade that sheds most counts: a level
    centre line beside a flank that pitches one edge of the body 10 deg up sheds as the flank."""
    grade = np.zeros((1, STATIONS, 5))
    grade[0, 2, 4] = 10.0
    assert GRADED.predict(_way(), np.zeros(1), grade)[0] == pytest.approx(1.6 - 0.3)
    assert GRADED.predict(_way(), np.zeros(1), grade[:, :, 2])[0] == 1.6  # the centre line alone: level
    grade[0, 4, 0] = -12.0  # another station, another point: 0.24 shed down against 0.3 up
    assert GRADED.predict(_way(), np.zeros(1), grade)[0] == pytest.approx(1.6 - 0.3)
    grade[0, 4, 1] = -20.0
    assert GRADED.predict(_way(), np.zeros(1), grade)[0] == pytest.approx(1.6 - 0.4)
    # Each point sheds from its own class's speed: rock, level, on the other edge further on is slower.
    level_rock = np.zeros((1, STATIONS, 5))
    level_rock[0, 2, 4] = 10.0
    assert GRADED.predict(_way((5, 4, ROCK)), np.zeros(1), level_rock)[0] == pytest.approx(0.8)
    two = np.concatenate([level_rock, np.zeros((1, STATIONS, 5))])  # two ways at once, each its own grades
    np.testing.assert_allclose(GRADED.predict(np.concatenate([_way(), _way()]), np.zeros(2), two), [1.6 - 0.3, 1.6])


ROUGH = replace(MODEL, rough_m=0.02, rough_mps=0.8)


def test_rough_ground_within_the_first_metre_caps_the_speed():
    def rough_at(station: int, roughness: float) -> np.ndarray:
        rough = np.zeros((1, STATIONS))
        rough[0, station] = roughness
        return rough

    assert ROUGH.predict(_way(), np.zeros(1), None, rough_at(4, 0.03))[0] == 0.8  # a metre ahead: capped
    assert ROUGH.predict(_way(), np.zeros(1), None, rough_at(5, 0.03))[0] == 1.6  # beyond it: not yet
    assert ROUGH.predict(_way(), np.zeros(1), None, rough_at(0, 0.02))[0] == 1.6  # not past the band
    assert ROUGH.predict(_way(), np.zeros(1), None, rough_at(0, math.nan))[0] == 1.6  # unknown: smooth
    assert ROUGH.predict(_way((1, 2, WATER)), np.zeros(1), None, rough_at(0, 0.05))[0] == 0.5  # water is slower still
    assert MODEL.predict(_way(), np.zeros(1), None, rough_at(0, 0.05))[0] == 1.6 and not MODEL.slows_on_rough


def test_the_speed_is_never_below_the_rules_slowest():
    assert _predict(replace(MODEL, speeds_mps=(0.05,) * 5), _way()) == MIN_SPEED_MPS
    assert _predict(replace(MODEL, lateral_accel_mps2=0.01), _way(), 10.0) == MIN_SPEED_MPS  # sqrt(0.001) ~ 0.03 m/s
    assert _predict(replace(MODEL, near_lethal_m=1.0, near_lethal_mps=0.01), _way((1, 2, LETHAL))) == MIN_SPEED_MPS


# --- 2. the fit recovers the model that drove ------------------------------------------------------------

# A 1-D drive: stretches of one column each, one station (0.25 m) a frame. Water and rock are
# driven long enough to be seen steady, mud too briefly (fewer than 10 frames alone within any
# preview tried), the lethal column never.
STRETCHES = [
    (BACKGROUND, 30),
    (WATER, 30),
    (BACKGROUND, 50),
    (ROCK, 30),
    (WATER, 30),
    (MUD, 8),
    (BACKGROUND, 30),
    (ROCK, 30),
    (BACKGROUND, 30),
]
# What drove: mud as slow as water (a mud never shown steady is fitted at the slowest learned
# speed, and must still explain every frame exactly), the lethal column's speed never read.
DRIVER = SpeedModel((9.9, 0.5, 0.8, 0.5, 1.6), 1.5, None, None, None, (LETHAL,))
BEND = slice(65, 85)  # frames inside the long background stretch


def _track() -> np.ndarray:
    """The drive's columns (L, 9): each station's 9 points alike."""
    columns = np.concatenate([np.full(n, c, dtype=np.uint8) for c, n in STRETCHES])
    return np.repeat(columns[:, None], 9, axis=1)


def _drive(
    driver: SpeedModel, track: np.ndarray, curvature: np.ndarray | None = None, lag: int = 2
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The fit's arrays (way, curvature, v_mps, frame) of driving ``track``: frame i's way starts
    at station i (beyond the track: never seen), and the speed ``driver`` gives frame i's way is
    commanded ``lag`` frames later (the first frames hold the first speed)."""
    n = len(track)
    padded = np.concatenate([track, np.full((STATIONS, 9), NEVER, dtype=np.uint8)])
    way = np.stack([padded[i : i + STATIONS] for i in range(n)])
    curvature = np.zeros(n) if curvature is None else curvature
    target = driver.predict(way, curvature)
    v = np.concatenate([np.full(lag, target[0]), target[: n - lag]])
    return way, curvature, v, np.arange(n)


@pytest.mark.parametrize(("preview_m", "lag"), [(1.5, 2), (0.5, 0), (3.0, 1), (2.0, 3)])
def test_the_fit_recovers_the_speeds_preview_and_lag_that_drove(preview_m: float, lag: int):
    track = _track()
    fit = fit_speed(Drive(*_drive(replace(DRIVER, preview_m=preview_m), track, lag=lag)), K, (LETHAL,))
    assert fit is not None
    m = fit.model
    assert m.preview_m == preview_m and fit.lag_frames == lag
    np.testing.assert_allclose(m.speeds_mps[WATER : BACKGROUND + 1], [0.5, 0.8, 0.5, 1.6], atol=1e-6)
    assert fit.error_mps == pytest.approx(0.0, abs=1e-6) and fit.samples == len(track) - lag
    assert m.min_points == 1 and m.lateral_accel_mps2 is None and m.near_lethal_m is None and m.near_lethal_mps is None
    assert m.drive_lateral_mps2 is None  # never a bend: no lateral acceleration shown
    for column, speed in ((WATER, 0.5), (ROCK, 0.8), (BACKGROUND, 1.6)):
        low, high = fit.intervals[column]
        assert low - 1e-6 <= speed <= high + 1e-6
    assert fit.intervals[MUD] is None and fit.intervals[LETHAL] is None  # never shown at a steady speed
    slowest = min(m.speeds_mps[c] for c in (WATER, ROCK, BACKGROUND))
    assert m.speeds_mps[MUD] == slowest and m.speeds_mps[LETHAL] == slowest  # the slowest learned, to be safe


def test_a_class_never_shown_steady_is_driven_at_the_slowest_speed_the_drive_showed_and_warned_of():
    """A drive that shows only the background steady (1.6 m/s) and its mud too briefly, slowly: the
    mud is not driven at the background's speed, the one learned, but at the drive's slowest."""
    columns = np.concatenate([np.full(n, c, dtype=np.uint8) for c, n in ((BACKGROUND, 100), (MUD, 8), (BACKGROUND, 100))])
    fit = fit_speed(Drive(*_drive(DRIVER, np.repeat(columns[:, None], 9, axis=1))), K, (LETHAL,))
    assert fit is not None and fit.intervals[MUD] is None and fit.intervals[BACKGROUND] is not None
    speeds = fit.model.speeds_mps
    assert speeds[BACKGROUND] == pytest.approx(1.6) and speeds[MUD] == speeds[WATER] == speeds[ROCK] == pytest.approx(0.5)
    rule = SpeedRule(SpeedConfig(), fit.model, fit, "grass")
    names, lethal = FEATURES.feature_classes, frozenset({"non_traversable"})
    assert rule.warnings(names, lethal) == [
        "water, rock, mud: never shown at a steady speed; driven at 0.50 m/s, the slowest the drive showed "
        "(a lane of each, as teaching courses lay them, shows the speed kept on it)"
    ]
    assert "mud" not in rule.describe(names, lethal) and "grass 1.60 m/s" in rule.describe(names, lethal)
    assert rule.warnings(names, frozenset({"non_traversable", "water", "rock", "mud"})) == []


def test_the_fit_reads_a_class_wherever_one_footprint_point_meets_it():
    """A driver who never slowed for a patch one footprint point brushes is explained better by
    two points; the fit still reads one, as a driver who slows for such a patch elsewhere would
    be read (docs/design.md: two points passed at full speed the patches drivers brush)."""
    track = _track()
    for station in np.flatnonzero(track[:, 0] == BACKGROUND)[4::8][:16]:
        track[station, 0] = WATER  # the footprint's left edge only
    ignores = replace(DRIVER, min_points=2)
    way, curvature, v, frame = _drive(ignores, track)
    fit = fit_speed(Drive(way, curvature, v, frame), K, (LETHAL,))
    assert fit is not None and fit.model.min_points == 1
    lag = fit.lag_frames
    two = np.mean(np.abs(replace(fit.model, min_points=2).predict(way, curvature)[: len(v) - lag] - v[lag:]))
    assert two < 0.5 * fit.error_mps, "two points explain the drive far better"


def test_a_class_shown_mostly_at_its_edge_is_learned_at_its_own_speed_from_the_frames_well_inside_it():
    """The driver brushes water at the edge of the rock stretches (its footprint's right edge
    meets it) and drives the water's speed there, while the map puts that water just beyond the
    footprint, in the ring 0.5 m beside it: those frames read as rock alone. They are most of the
    rock frames; the fit learns rock from the frames well inside it (the ring rock too), not at
    the water's speed."""
    truth, seen = _track(), _track()
    for start in np.flatnonzero((truth[1:, 2] == ROCK) & (truth[:-1, 2] != ROCK)) + 1:
        edge = slice(start + 15, start + 30)  # the second half of each rock stretch
        truth[edge, 0] = WATER  # the footprint's right edge: the driver's speed there is water's
        seen[edge, 6] = WATER  # the ring's right point (model.across): the map's edge, 0.5 m further out
    v = _drive(DRIVER, truth)[2]
    way, curvature, _, frame = _drive(DRIVER, seen)
    fit = fit_speed(Drive(way, curvature, v, frame), K, (LETHAL,))
    assert fit is not None
    alone = (way[:, :6, :5] == ROCK).all(axis=(1, 2))
    assert np.median(v[alone]) == pytest.approx(0.5), "most frames of rock alone are at the water's speed"
    assert fit.model.speeds_mps[ROCK] == pytest.approx(0.8) and fit.model.speeds_mps[WATER] == pytest.approx(0.5)


def test_a_class_shown_well_inside_only_between_lethal_walls_is_learned_there_not_at_its_edges():
    """Rock shown well inside only as a lane between lethal walls (1.0 m beside the footprint),
    which the driver drives at rock's speed, and otherwise only at its edge, brushing water and
    driven at water's speed: the lane's frames give rock's speed, not the edge's."""
    truth, seen = _track(), _track()
    for start in np.flatnonzero((truth[1:, 2] == ROCK) & (truth[:-1, 2] != ROCK)) + 1:
        lane, edge = slice(start, start + 15), slice(start + 15, start + 30)
        truth[lane, 5], truth[lane, 8] = LETHAL, LETHAL  # the outer rings: walls 1 m beside the footprint
        seen[lane, 5], seen[lane, 8] = LETHAL, LETHAL
        truth[edge, 0] = WATER  # the footprint's right edge: the driver's speed there is water's
        seen[edge, 6] = WATER  # the map puts it in the ring's right point, just beyond the footprint
    v = _drive(DRIVER, truth)[2]
    way, curvature, _, frame = _drive(DRIVER, seen)
    fit = fit_speed(Drive(way, curvature, v, frame), K, (LETHAL,))
    assert fit is not None
    assert fit.model.near_lethal_mps is None  # the driver does not slow beside the walls
    assert fit.model.speeds_mps[ROCK] == pytest.approx(0.8) and fit.model.speeds_mps[WATER] == pytest.approx(0.5)


def test_a_lag_pairs_frames_only_within_one_recording():
    way, curvature, v, _ = _drive(DRIVER, _track())
    half = len(v) // 2
    frame = np.concatenate([np.arange(half), np.arange(len(v) - half)])  # two recordings, each numbered from 0
    fit = fit_speed(Drive(way, curvature, v, frame), K, (LETHAL,))
    assert fit is not None and fit.lag_frames == 2
    assert fit.samples == len(v) - 2 * 2  # each recording's last 2 frames have no speed 2 frames later


def test_the_fit_recovers_a_bend_limit_the_speeds_show():
    curvature = np.zeros(len(_track()))
    curvature[BEND] = 0.5
    data = _drive(replace(DRIVER, lateral_accel_mps2=0.4), _track(), curvature)
    fit = fit_speed(Drive(*data), K, (LETHAL,))
    assert fit is not None
    assert fit.model.lateral_accel_mps2 == pytest.approx(0.4, rel=1e-9)
    assert fit.error_mps == pytest.approx(0.0, abs=1e-6)
    np.testing.assert_allclose(fit.model.speeds_mps[WATER : BACKGROUND + 1], [0.5, 0.8, 0.5, 1.6], atol=1e-6)
    _, _, v, _ = data
    # The drive's largest v^2 |k|, frame by frame: entering the bend the speed is still the
    # straight's (the lag), 1.6^2 * 0.5 = 1.28, well above the limit kept through it.
    assert fit.model.drive_lateral_mps2 == pytest.approx(1.6**2 * 0.5) == pytest.approx(float(np.max(v**2 * curvature)))


def test_the_fit_invents_no_bend_limit_the_speeds_do_not_show():
    curvature = np.zeros(len(_track()))
    curvature[BEND] = 0.5  # as sharp a bend, driven at the cruising speed
    fit = fit_speed(Drive(*_drive(DRIVER, _track(), curvature)), K, (LETHAL,))
    assert fit is not None and fit.model.lateral_accel_mps2 is None
    assert fit.error_mps == pytest.approx(0.0, abs=1e-6)


def test_the_drives_lateral_acceleration_is_its_largest():
    """The drive's largest v^2 |k| (docs/lab/2026-11-28-driving-speed.md, step 5: taken at the
    largest rather than the 99th percentile, which would slow a steady driver in its tightest arcs)."""
    curvature = np.zeros(len(_track()))
    curvature[70:75] = 0.05  # gentle curves on the background at 1.6 m/s: 0.128 m/s^2
    curvature[90] = -0.08  # and one frame of 0.2048 m/s^2
    _, _, v, _ = data = _drive(DRIVER, _track(), curvature)
    fit = fit_speed(Drive(*data), K, (LETHAL,))
    assert fit is not None
    assert fit.model.drive_lateral_mps2 == pytest.approx(1.6**2 * 0.08, rel=1e-12)
    assert fit.model.drive_lateral_mps2 > np.percentile(v**2 * np.abs(curvature), 99)
    assert fit.model.lateral_accel_mps2 is None  # too gentle to be bends


@pytest.mark.parametrize(("point", "ring_m"), [(8, 1.0), (7, 0.5)])
def test_the_fit_recovers_the_speed_near_lethal_terrain_and_its_ring(point: int, ring_m: float):
    track = _track()
    track[70:100, point] = LETHAL  # beside the long background stretch
    fit = fit_speed(Drive(*_drive(replace(DRIVER, near_lethal_m=ring_m, near_lethal_mps=0.7), track)), K, (LETHAL,))
    assert fit is not None
    assert fit.model.near_lethal_m == ring_m and fit.model.near_lethal_mps == pytest.approx(0.7)
    assert fit.error_mps == pytest.approx(0.0, abs=1e-6)
    assert fit.model.speeds_mps[BACKGROUND] == pytest.approx(1.6)  # from the frames away from it


def _grades(track_grades: np.ndarray) -> np.ndarray:
    """Each frame's way's grades (L, STATIONS) [deg] of a drive whose station i has grade ``track_grades[i]``."""
    padded = np.concatenate([track_grades, np.full(STATIONS, np.nan)])
    return np.stack([padded[i : i + STATIONS] for i in range(len(track_grades))])


def test_cruising_speeds_are_read_net_of_what_gentle_grades_shed():
    """Ground never quite level: every frame the fit counts as level (within 3 deg) rises or falls
    1.5 deg, so a driver who sheds speed from the first degree drives its classes 0.03-0.045 m/s
    under their speeds there; the fit reads the class speeds net of that (not the level frames'
    median), what a degree sheds from the steep frames against them, and puts no limit in a bend
    taken on a steep grade, whose slowing the grade explains."""
    track = _track()
    track_grades = np.where(np.arange(len(track)) % 40 < 20, 1.5, -1.5)
    track_grades[62:78], track_grades[90:106] = 6.0, -8.0
    way, curvature, _, frame = _drive(DRIVER, track)
    curvature[BEND] = 0.2  # a gentle bend on the climb (62-78) and after it
    grade = _grades(track_grades)
    target = replace(DRIVER, up_mps_per_deg=0.03, down_mps_per_deg=0.02).predict(way, curvature, grade)
    v = np.concatenate([np.full(2, target[0]), target[:-2]])
    fit = fit_speed(Drive(way, curvature, v, frame, grade), K, (LETHAL,))
    assert fit is not None and fit.lag_frames == 2
    m = fit.model
    shown = [WATER, ROCK, BACKGROUND]  # mud, never shown steady, is driven at the slowest speed the drive showed
    np.testing.assert_allclose(np.array(m.speeds_mps)[shown], [0.5, 0.8, 1.6], atol=1e-3)
    assert m.up_mps_per_deg == pytest.approx(0.03, abs=1e-3) and m.down_mps_per_deg == pytest.approx(0.02, abs=1e-3)
    assert m.lateral_accel_mps2 is None


def test_the_fit_recovers_what_grades_shed_up_and_down():
    """The long background stretch (frames 60-110) climbs 6 deg, then descends 8 deg; the class
    speeds are read from the level frames, what a degree sheds from the frames on one grade."""
    track = _track()
    track_grades = np.zeros(len(track))
    track_grades[62:78], track_grades[90:106] = 6.0, -8.0
    assert (track[60:110, 0] == BACKGROUND).all()
    way, curvature, _, frame = _drive(DRIVER, track)
    grade = _grades(track_grades)
    target = replace(DRIVER, up_mps_per_deg=0.03, down_mps_per_deg=0.02).predict(way, curvature, grade)
    v = np.concatenate([np.full(2, target[0]), target[:-2]])
    fit = fit_speed(Drive(way, curvature, v, frame, grade), K, (LETHAL,))
    assert fit is not None and fit.lag_frames == 2 and fit.error_mps == pytest.approx(0.0, abs=1e-6)
    m = fit.model
    assert m.up_mps_per_deg == pytest.approx(0.03) and m.down_mps_per_deg == pytest.approx(0.02)
    np.testing.assert_allclose(m.speeds_mps[WATER : BACKGROUND + 1], [0.5, 0.8, 0.5, 1.6], atol=1e-6)
    (up_low, up_high), (down_low, down_high) = fit.grade_intervals
    assert up_low - 1e-9 <= 0.03 <= up_high + 1e-9 and down_low - 1e-9 <= 0.02 <= down_high + 1e-9
    assert all(n >= 10 for n in fit.grade_frames)
    # A driver who kept its speed on the same grades: nothing learned, the model a flat drive gives.
    kept = fit_speed(Drive(*_drive(DRIVER, track), grade), K, (LETHAL,))
    flat = fit_speed(Drive(*_drive(DRIVER, track)), K, (LETHAL,))
    assert kept is not None and flat is not None and not kept.model.sheds_on_grades and kept.model == flat.model
    assert kept.grade_intervals == (None, None) and kept.on_grades and kept.grade_frames[0] >= 10
    line = next(
        x for x in SpeedRule(SpeedConfig(), kept.model, kept).lines(FEATURES.feature_classes, frozenset()) if x.startswith("grades")
    )
    assert line.startswith(
        f"grades: nothing learned up ({kept.grade_frames[0]} frames on one class past 3 deg up faster than 0.15 m/s: slowing there explains"
    )


def test_what_a_degree_sheds_is_read_on_the_steepest_of_the_footprints_points():
    """A driver who sheds on the steepest ground under its footprint, on a climb and a descent
    whose edges pitch the body a third steeper than the centre line (the flank of a mound): read on
    the footprint's points the fit finds its 0.03 and 0.02 m/s a degree and says it read them so;
    read on the centre line alone (datasets featurised before) it finds a third more."""
    track = _track()
    centre_grades = np.zeros(len(track))
    centre_grades[62:78], centre_grades[90:106] = 6.0, -6.0
    grade = np.repeat(_grades(centre_grades)[:, :, None], 5, axis=2)
    grade[:, :, 0] *= 4.0 / 3.0
    way, curvature, _, frame = _drive(DRIVER, track)
    target = replace(DRIVER, up_mps_per_deg=0.03, down_mps_per_deg=0.02).predict(way, curvature, grade)
    v = np.concatenate([np.full(2, target[0]), target[:-2]])
    across_fit = fit_speed(Drive(way, curvature, v, frame, grade), K, (LETHAL,))
    assert across_fit is not None and across_fit.model.grades_across
    assert across_fit.model.up_mps_per_deg == pytest.approx(0.03) and across_fit.model.down_mps_per_deg == pytest.approx(0.02)
    centre_fit = fit_speed(Drive(way, curvature, v, frame, grade[:, :, 2]), K, (LETHAL,))
    assert centre_fit is not None and not centre_fit.model.grades_across
    assert centre_fit.model.up_mps_per_deg == pytest.approx(0.04) and centre_fit.model.down_mps_per_deg == pytest.approx(0.02 * 4 / 3)


def test_rough_bands_within_a_millimetre_per_second_of_the_best_are_alike_and_the_middle_one_is_kept():
    """As below, with the frames that see one spot a little rough (0.011 m) within a metre ahead a
    little slow: at 1.18 m/s the smoothest band explains them best by a hair (under 1 mm/s of mean
    error), so every band below 0.03 m still explains the drive alike and the middle one is kept,
    not the smoothest; at 1.15 m/s the bands below 0.011 m explain them better by more, and the
    middle of those is kept."""
    from terrapref.rules.speed.model import roughest

    track = _track()
    track_rough = np.zeros(len(track))
    track_rough[70:90], track_rough[64] = 0.03, 0.011
    way, curvature, _, frame = _drive(DRIVER, track)
    rough = _grades(track_rough)
    target = replace(DRIVER, rough_m=0.02, rough_mps=0.8).predict(way, curvature, None, rough)
    seeing = np.flatnonzero((roughest(rough) > 0.01) & (roughest(rough) < 0.02))
    assert len(seeing) >= 3
    kept = {}
    for slow in (1.18, 1.15):
        v = np.concatenate([np.full(2, target[0]), target[:-2]])
        v[seeing + 2] = slow  # two frames later: the driver's lag
        fit = fit_speed(Drive(way, curvature, v, frame, None, rough), K, (LETHAL,))
        assert fit is not None and fit.lag_frames == 2 and fit.rough is not None
        kept[slow] = (fit.rough.alike_m, fit.model.rough_m)
    assert kept[1.18] == ((0.005, 0.025), 0.015)
    assert kept[1.15] == ((0.005, 0.01), 0.0075)


def test_the_fit_recovers_a_top_speed_on_rough_ground_and_says_which_roughness_it_cannot_tell():
    """The long background stretch (frames 60-110) is rough (0.03 m) from frame 70 to 90; the
    driver keeps 0.8 m/s there past 0.02 m. The drive shows nothing between the smooth ground's 0
    and 0.03 m, so every band below 0.03 m explains it alike; one that kept its speed shows nothing."""
    track = _track()
    track_rough = np.zeros(len(track))
    track_rough[70:90] = 0.03
    way, curvature, _, frame = _drive(DRIVER, track)
    rough = _grades(track_rough)
    target = replace(DRIVER, rough_m=0.02, rough_mps=0.8).predict(way, curvature, None, rough)
    v = np.concatenate([np.full(2, target[0]), target[:-2]])
    fit = fit_speed(Drive(way, curvature, v, frame, None, rough), K, (LETHAL,))
    assert fit is not None and fit.lag_frames == 2 and fit.error_mps == pytest.approx(0.0, abs=1e-6)
    m, shown = fit.model, fit.rough
    assert m.rough_mps == pytest.approx(0.8) and m.slows_on_rough and shown is not None and shown.frames >= 10
    assert shown.alike_m == (0.005, 0.025) and m.rough_m == 0.015  # the eight bands below 0.03 m alike; the middle one kept
    low, high = shown.interval
    assert low - 1e-9 <= 0.8 <= high + 1e-9
    line = next(x for x in SpeedRule(SpeedConfig(), m, fit).lines(FEATURES.feature_classes, frozenset()) if x.startswith("rough"))
    assert line.startswith("rough ground: at most 0.80 m/s where the ground within 1 m ahead is rougher than 0.015 m (95% CI")
    assert line.endswith("the drive cannot tell a roughness of 0.005-0.025 m from it")
    kept = fit_speed(Drive(*_drive(DRIVER, track), None, rough), K, (LETHAL,))
    assert kept is not None and not kept.model.slows_on_rough and kept.rough is not None and kept.rough.interval is None
    line = next(x for x in SpeedRule(SpeedConfig(), kept.model, kept).lines(FEATURES.feature_classes, frozenset()) if x.startswith("rough"))
    assert (
        line == "rough ground: nothing learned (0 frames slower than terrain and grades ask, past 0.005 m within 1 m ahead: fewer than 10)"
    )


def test_the_fit_finds_nothing_without_a_steady_frame():
    assert fit_speed(Drive(*_drive(DRIVER, _track()[:9], lag=0)), K, (LETHAL,)) is None  # fewer than 10 frames
    way, curvature, v, frame = _drive(DRIVER, _track())
    assert fit_speed(Drive(way, np.full(len(v), 0.5), v, frame), K, (LETHAL,)) is None  # every frame in a bend


# --- 3. the file block -----------------------------------------------------------------------------------


def _block(**changes) -> dict:
    rule = SpeedRule(SpeedConfig(), replace(MODEL, lateral_accel_mps2=0.4, min_points=2, drive_lateral_mps2=0.6))
    return {**json.loads(json.dumps(rule.header())), **changes}


def _read(block: dict) -> SpeedRule:
    return SpeedRule.from_header(block, HeaderContext(FEATURES, FEATURES.to_dict()), Where(SOURCE, 0))


def test_a_block_reads_back_as_the_rule_that_wrote_it():
    rule = _read(_block())
    assert rule.model == replace(MODEL, lateral_accel_mps2=0.4, min_points=2, drive_lateral_mps2=0.6)
    assert rule.config == SpeedConfig() and rule.fit is None


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("speeds_mps", [0.5, 0.5, 0.8, 1.6]),  # K + 1 = 5 expected
        ("speeds_mps", [0.5, 0.5, 0.8, 0.9, 1.6, 1.0]),
        ("speeds_mps", [0.5, 0.0, 0.8, 0.9, 1.6]),
        ("speeds_mps", [0.5, -0.5, 0.8, 0.9, 1.6]),
        ("speeds_mps", [0.5, True, 0.8, 0.9, 1.6]),
        ("speeds_mps", None),
        ("min_points", 0),
        ("min_points", 6),
        ("min_points", True),
        ("min_points", 2.0),
        ("lethal", [K + 1]),
        ("lethal", [-1]),
        ("lethal", [True]),
        ("drive_lateral_mps2", -0.1),
        ("drive_lateral_mps2", 0.0),
        ("lateral_accel_mps2", -1.0),
        ("preview_m", 0.0),
    ],
)
def test_a_bad_block_is_a_user_error_naming_the_field(field: str, value):
    with pytest.raises(UserError) as raised:
        _read(_block(**{field: value}))
    assert raised.value.source == SOURCE
    assert [p.field for p in raised.value.problems] == [f"rules[0].{field}"]


def test_a_block_with_what_grades_shed_reads_back_and_a_flat_drives_block_holds_none():
    fit = SpeedFit(GRADED, (None,) * (K + 1), 2, 100, 0.01, ((0.025, 0.035), None), (40, 0), True)
    rule = SpeedRule(SpeedConfig(), GRADED, fit)
    back = _read(json.loads(json.dumps(rule.header())))
    assert back.model == GRADED and back.fit is not None
    assert back.fit.grade_intervals == ((0.025, 0.035), None) and back.fit.grade_frames == (40, 0)
    line = next(x for x in back.lines(FEATURES.feature_classes, frozenset({"non_traversable"})) if x.startswith("grades"))
    assert line.startswith("grades: 0.030 m/s per deg up (95% CI 0.025-0.035, 40 frames); 0.020 m/s per deg down")
    assert "up_mps_per_deg" not in SpeedRule(SpeedConfig(), MODEL).header()  # a flat drive's file is as before
    with pytest.raises(UserError) as raised:
        _read(_block(up_mps_per_deg=-0.01))
    assert [p.field for p in raised.value.problems] == ["rules[0].up_mps_per_deg"]
    across_rule = SpeedRule(SpeedConfig(), replace(GRADED, grades_across=True))
    assert _read(json.loads(json.dumps(across_rule.header()))).model.grades_across
    centre_line = "grades read on the way's centre line"
    assert any(x.startswith(centre_line) for x in back.lines(FEATURES.feature_classes, frozenset()))  # info says which
    assert not any(x.startswith(centre_line) for x in across_rule.lines(FEATURES.feature_classes, frozenset()))
    older = {k: v for k, v in SpeedRule(SpeedConfig(), GRADED).header().items() if k != "grades_across"}
    assert not _read(older).model.grades_across  # a file from before read its grades on the centre line
    with pytest.raises(UserError) as raised:
        _read({**across_rule.header(), "grades_across": "yes"})
    assert [p.field for p in raised.value.problems] == ["rules[0].grades_across"]


def test_a_block_with_a_top_speed_on_rough_ground_reads_back_and_a_half_one_is_refused():
    fit = SpeedFit(ROUGH, (None,) * (K + 1), 2, 100, 0.01, rough=Rough(30, (0.75, 0.82), (0.015, 0.025)))
    back = _read(json.loads(json.dumps(SpeedRule(SpeedConfig(), ROUGH, fit).header())))
    assert back.model == ROUGH and back.fit is not None and back.fit.rough == Rough(30, (0.75, 0.82), (0.015, 0.025))
    assert "rough_m" not in SpeedRule(SpeedConfig(), MODEL).header()  # a flat drive's file is as before
    bad = (
        ({"rough_m": 0.02}, "rough_m"),
        ({"rough_m": 0.02, "rough_mps": 0.01}, "rough_mps"),
        ({"rough_m": -1.0, "rough_mps": 0.8}, "rough_m"),
        # Past what any drive shows (a file written by hand was read and printed 300 digits long):
        ({"rough_m": 1e300, "rough_mps": 0.8}, "rough_m"),
        ({"rough_m": 0.02, "rough_mps": 1e300}, "rough_mps"),
        ({"up_mps_per_deg": 1e300, "down_mps_per_deg": 0.02}, "up_mps_per_deg"),
        ({"up_mps_per_deg": 0.02, "down_mps_per_deg": 5.0}, "down_mps_per_deg"),
    )
    for changes, field in bad:  # half of it; a top speed below the least; a roughness below 0; past any drive
        with pytest.raises(UserError) as raised:
            _read(_block(**changes))
        assert [p.field for p in raised.value.problems] == [f"rules[0].{field}"]


def test_an_older_block_without_min_points_or_the_drives_lateral_reads_with_their_defaults():
    block = _block()
    del block["min_points"], block["drive_lateral_mps2"]
    model = _read(block).model
    assert model.min_points == 1 and model.drive_lateral_mps2 is None
    assert model.speeds_mps == SPEEDS and model.lateral_accel_mps2 == 0.4


def test_the_ways_class_ids_survive_a_dataset_file_and_wider_integers_are_refused(tmp_path: Path):
    n = 12
    rng = np.random.default_rng(0)
    arrays = {
        "way": rng.integers(0, NEVER + 1, (n, STATIONS, 9)).astype(np.uint8),
        "curvature": np.zeros(n, np.float32),
        "v_mps": np.ones(n, np.float32),
        "frame": np.arange(n, dtype=np.float32),
        "grade": np.full((n, STATIONS), np.nan, np.float32),
        "rough": np.full((n, STATIONS), np.nan, np.float32),
    }
    rules = {"speed": {"config": SpeedConfig().data(), "arrays": dict(SpeedConfig.arrays)}}
    meta = {"format": DATASET_FORMAT, **model_meta(), "rules": rules}
    U, labels = rng.uniform(0, 1, (n, 21, 5)).astype(np.float32), rng.integers(0, 21, n)
    data = Dataset(U, labels, np.zeros(n, np.float32), np.zeros(n, np.int64), meta, {"speed": arrays})
    back = load_dataset(save_dataset(data, tmp_path / "d.safetensors")).rules["speed"]
    assert back["way"].dtype == np.uint8
    np.testing.assert_array_equal(back["way"], arrays["way"])
    wide = Dataset(U, labels, data.w, data.source, meta, {"speed": {**arrays, "way": arrays["way"].astype(np.int64) + 300}})
    with pytest.raises(UserError) as exc:  # beyond the 256 class ids a rule's tables read: refused, not an index error in the fit
        load_dataset(save_dataset(wide, tmp_path / "bad.safetensors"))
    assert exc.value.problems[0].field == "rules.speed.way"
    odd = {**arrays, "grade": np.zeros((n, STATIONS, 7), np.float32)}  # neither a grade a station nor one a footprint point
    with pytest.raises(UserError, match=r"grades of \(24, 7\) a sample; this version reads \(24, 5\)"):
        SpeedConfig().fit(FitData(Dataset(U, labels, data.w, data.source, meta, {"speed": odd}), mirror=False))


# --- 4. the runner on a ground map a tiny scenario fills ---------------------------------------------------

CLASSES = default_classes()


def _scenario(terrain: list[dict]) -> Scenario:
    return parse_scenario(
        {
            "format": "terrapref-scenario/1",
            "name": "speed_rule",
            "world": {"size_m": [40.0, 20.0], "resolution_m": 0.05, "background": "grass"},
            "terrain": terrain,
            "path": {"waypoints": [[2.0, 10.0], [38.0, 10.0]]},
        }
    )


ALL_MUD_TERRAIN = [{"class": "mud", "rectangle": {"center": [20.0, 10.0], "size": [40.0, 20.0]}}]
ALL_MUD = _scenario(ALL_MUD_TERRAIN)
MUD_LEFT = _scenario([{"class": "mud", "rectangle": {"center": [20.0, 14.0], "size": [40.0, 6.0]}}])  # y from 11 m
AT = (8.0, 10.0, 0.0)  # 6 m along the path


def _runner(model: SpeedModel, scenario: Scenario | None) -> tuple[LearnedSpeed, GroundMap]:
    """The rule's runner and the ground map a planner keeps for it, fed the views of ``scenario``
    from 2 m to 8 m along its path (every 0.5 m); ``None``: nothing seen."""
    camera = PinholeCamera()
    context = RuleContext(camera, UtilityFeaturizer(FEATURES, camera, CLASSES), FEATURES, CLASSES)
    runner = SpeedRule(SpeedConfig(), model).runner(context)
    assert isinstance(runner, LearnedSpeed)
    seen = GroundMap(camera, context.terrain, runner.map_settings)
    if scenario is not None:
        renderer = SegmentationRenderer(camera, rasterise(scenario))
        for x in np.arange(2.0, AT[0] + 1e-9, 0.5):
            pose = (float(x), 10.0, 0.0)
            seen.update(SegmentationView.of(renderer.render(pose)), pose)
    return runner, seen


def test_on_ground_of_one_class_the_runner_drives_at_its_speed():
    runner, seen = _runner(MODEL, ALL_MUD)
    assert runner.speed(seen, AT, 0.0, 1.0) == 0.9
    assert runner.speed(seen, AT, 0.2, 1.0) == 0.9 and runner.speed(seen, AT, -0.2, 1.0) == 0.9  # every way is on mud
    seen.reset()
    assert runner.speed(seen, AT, 0.0, 1.0) == 0.5  # forgotten: nothing seen, the slowest cruising speed
    blank, nothing = _runner(MODEL, None)
    assert blank.speed(nothing, AT, 0.0, 1.0) == 0.5


def test_the_runner_reads_the_way_of_the_arc_or_of_the_offset_held():
    runner, seen = _runner(MODEL, MUD_LEFT)
    path = ReferencePath(MUD_LEFT.waypoints)
    assert runner.speed(seen, AT, 0.0, 1.0) == 1.6  # straight on: the footprint stays below y = 10.6 m
    assert runner.speed(seen, AT, 0.5, 1.0) == 0.9  # the left arc reaches the mud within 1.5 m
    assert runner.speed(seen, AT, -0.5, 1.0) == 1.6
    assert runner.speed(seen, AT, 0.0, 1.0, (path, 6.0, 4.0)) == 0.9  # the path shifted 4 m left: on the mud
    assert runner.speed(seen, AT, 0.0, 1.0, (path, 6.0, 0.0)) == 1.6
    assert runner.speed(seen, AT, 0.0, 1.0, (path, 6.0, -4.0)) == 1.6


def test_a_runner_that_learned_its_grades_across_the_footprint_reads_them_there(monkeypatch: pytest.MonkeyPatch):
    """Ground that tilts across the way (here a grade rising 10 deg a metre to the left, read by
    the map's body_grades): a model fitted on the footprint's points sheds what its left edge
    (0.6 m) climbs, on the arc and on the offset held alike; one from an older file, on the centre
    line, what the centre line climbs; the checks against the body's pitch read the centre line."""
    runner, seen = _runner(replace(GRADED, grades_across=True), _scenario([]))
    centre_line, _ = _runner(GRADED, _scenario([]))
    path = ReferencePath(_scenario([]).waypoints)
    monkeypatch.setattr(seen, "body_grades", lambda centre, heading, chord: 10.0 * (np.asarray(centre)[:, 1] - 10.0))
    assert runner.speed(seen, AT, 0.0, 1.0) == pytest.approx(1.6 - 0.03 * 6.0)
    assert runner.speed(seen, AT, 0.0, 1.0, (path, 6.0, 1.0)) == pytest.approx(1.6 - 0.03 * 16.0)  # 1 m left: its edge 1.6 m
    assert centre_line.speed(seen, AT, 0.0, 1.0, (path, 6.0, 1.0)) == pytest.approx(1.6 - 0.03 * 10.0)
    runner.speed(seen, AT, 0.0, 1.0, None, Attitude(0.0, 0.0, 0.0))  # level body, level centre line: nothing to correct
    offset, slope = runner.grades.line
    assert not offset.any() and (slope == 1.0).all()


@pytest.mark.parametrize("curvature", [0.5, -0.5, 1.0])
def test_the_runner_keeps_to_the_largest_yaw_rate(curvature: float):
    runner, seen = _runner(MODEL, ALL_MUD)
    assert runner.speed(seen, AT, curvature, 0.3) == pytest.approx(0.3 / abs(curvature))  # below the mud's 0.9 m/s
    assert runner.speed(seen, AT, curvature, 5.0) == 0.9


@pytest.mark.parametrize("curvature", [0.5, -0.5, 1.0])
def test_the_runner_keeps_to_the_drives_lateral_acceleration(curvature: float):
    runner, seen = _runner(replace(MODEL, drive_lateral_mps2=0.2), ALL_MUD)
    v = runner.speed(seen, AT, curvature, 5.0)
    assert v == pytest.approx(math.sqrt(0.2 / abs(curvature)))  # below the mud's 0.9 m/s
    assert v**2 * abs(curvature) <= 0.2 + 1e-12
    assert runner.speed(seen, AT, 0.0, 5.0) == 0.9  # straight on: no sideways acceleration to keep to
    assert runner.speed(seen, AT, curvature, 0.1) == pytest.approx(0.1 / abs(curvature))  # the tighter of the two caps


@pytest.mark.parametrize("curvature", [0.5, -0.5, 2.0])
def test_the_yaw_rate_keeps_to_the_lateral_limit_at_the_vehicles_speed(curvature: float):
    runner, seen = _runner(replace(MODEL, drive_lateral_mps2=0.6), ALL_MUD)
    v = runner.speed(seen, AT, curvature, 5.0)
    assert runner.yaw_rate(curvature, v) == pytest.approx(curvature * v)  # at the speed it commands: within the limit
    assert runner.yaw_rate(curvature, v, speed_mps=v / 2) == pytest.approx(curvature * v)  # still speeding up: no faster than v
    braking = runner.yaw_rate(curvature, v, speed_mps=1.5)  # still faster than v: a wider arc for now
    assert braking == pytest.approx(math.copysign(0.6 / 1.5, curvature)) and abs(braking) * 1.5 == pytest.approx(0.6)
    assert runner.yaw_rate(0.0, v, speed_mps=1.5) == 0.0
    bends, _ = _runner(replace(MODEL, lateral_accel_mps2=0.3, drive_lateral_mps2=0.6), ALL_MUD)
    assert bends.rule.model.lateral_limit_mps2 == 0.3  # a bend limit shown is the tighter limit
    assert abs(bends.yaw_rate(curvature, 0.9, speed_mps=1.5)) * 1.5 == pytest.approx(min(0.3, abs(curvature) * 0.9 * 1.5))
    free, _ = _runner(MODEL, ALL_MUD)  # neither known: the arc asked for
    assert free.rule.model.lateral_limit_mps2 is None and free.yaw_rate(curvature, 0.9, speed_mps=2.0) == curvature * 0.9


def test_the_yaw_rate_keeps_to_the_lateral_limit_while_the_vehicle_may_still_speed_up_to_the_last_command():
    """A frame taken at 1.0 m/s while the vehicle sped up toward the 2.0 m/s commanded last: until
    the next decision it may reach 2.0 m/s, so the arc of a slower command keeps to the limit there."""
    runner, seen = _runner(replace(MODEL, drive_lateral_mps2=0.6), ALL_MUD)
    assert runner.yaw_rate(0.5, 0.9, speed_mps=1.0) == pytest.approx(0.45)  # nothing commanded yet: 0.45 m/s^2 at 1 m/s
    runner.commanded(2.0)
    assert runner.yaw_rate(0.5, 0.9, speed_mps=1.0) == pytest.approx(0.6 / 2.0)  # not 0.45: 0.9 m/s^2 at 2 m/s
    runner.commanded(0.9)
    assert runner.yaw_rate(0.5, 0.9, speed_mps=1.0) == pytest.approx(0.45)  # 0.9 commanded last, 1.0 measured: 0.45 m/s^2
    runner.commanded(0.0)  # the planner stopped
    assert runner.yaw_rate(0.5, 0.9, speed_mps=0.5) == pytest.approx(0.45)
    runner.commanded(2.0)
    runner.reset()  # a new path: no speed commanded yet
    assert runner.yaw_rate(0.5, 0.9, speed_mps=0.5) == pytest.approx(0.45)


def test_a_way_the_stop_rule_steers_onto_is_driven_no_harder_sideways_than_the_drive_went(tmp_path: Path):
    """A lethal block ahead covers the footprint's left 0.3 m: the stop rule steers the planner
    onto the nearest free way, which at the mud's 0.9 m/s would go harder sideways than the drive's
    0.05 m/s^2; it drives that way's arc slower instead, and touches nothing."""
    classifier = ClassifierConfig(hidden=8, skip=True)
    rule = SpeedRule(SpeedConfig(), replace(MODEL, drive_lateral_mps2=0.05))
    meta = {**model_meta(), "rules": [rule.header()], "drives": "argmax"}
    planner = Planner(load_model(save_model(tmp_path / "speed.safetensors", classifier, skip_path_weights(classifier), meta)))
    block = {"class": "non_traversable", "rectangle": {"center": [12.0, 10.8], "size": [2.0, 1.0]}}
    driver = PlannerDriver(planner, keep=True)
    log = run_episode(Simulation(_scenario([*ALL_MUD_TERRAIN, block])), driver, np.random.default_rng(0))
    assert log.collisions == 0
    sideways = [abs(d.command.v * d.command.w) for d in driver.decisions]
    assert max(sideways) <= 0.05 + 1e-9
    steered = [d.command for d in driver.decisions if d.stop is None and abs(d.command.w) > 0.05 / 0.9 + 1e-9]
    assert steered and all(c.v < 0.9 for c in steered)  # turned harder than the rule's own turns at 0.9 m/s, slower


def test_the_runner_never_exceeds_the_rules_top_speed():
    runner, seen = _runner(replace(MODEL, speeds_mps=(3.0,) * 5), ALL_MUD)
    assert runner.speed(seen, AT, 0.0, 1.0) == SpeedConfig().max_speed_mps


def test_the_planner_drives_the_steering_rules_curvature_at_the_speed_rules_speed(tmp_path: Path):
    """C's argmax steers (its trajectory's w at the control set's 1 m/s); the speed rule sets v on
    mud, and w follows so that the curvature is kept."""
    classifier = ClassifierConfig(hidden=8, skip=True)
    meta = {**model_meta(), "rules": [SpeedRule(SpeedConfig(), MODEL).header()], "drives": "argmax"}
    planner = Planner(load_model(save_model(tmp_path / "speed.safetensors", classifier, skip_path_weights(classifier), meta)))
    assert planner.speed is not None and planner.rule.type == "argmax"
    planner.set_path(ALL_MUD.waypoints)
    renderer = SegmentationRenderer(planner.camera, rasterise(ALL_MUD))
    start = (2.0, 10.0, 0.0)
    d = planner.decide(SegmentationView.of(renderer.render(start)), start)
    w_grid = np.asarray(FEATURES.preference.control.w_rps)
    assert d.stop is None and d.command.v == 0.9
    assert d.command.w == pytest.approx(w_grid[d.index] * 0.9)


def test_a_planner_told_its_speed_turns_no_harder_than_the_lateral_limit_allows_there(tmp_path: Path):
    """Still going 2 m/s while it commands the mud's 0.9, the planner widens its arc so that
    v * w stays within the drive's largest lateral acceleration; told nothing, it keeps the curvature."""
    classifier = ClassifierConfig(hidden=8, skip=True)
    rule = SpeedRule(SpeedConfig(), replace(MODEL, drive_lateral_mps2=0.05))
    meta = {**model_meta(), "rules": [rule.header()], "drives": "argmax"}
    planner = Planner(load_model(save_model(tmp_path / "speed.safetensors", classifier, skip_path_weights(classifier), meta)))
    planner.set_path(ALL_MUD.waypoints)
    renderer = SegmentationRenderer(planner.camera, rasterise(ALL_MUD))
    start = (2.0, 10.0, 0.3)  # turned off the path: the argmax turns back
    view = SegmentationView.of(renderer.render(start))
    told = planner.decide(view, start, speed_mps=2.0)
    planner.set_path(ALL_MUD.waypoints)
    untold = planner.decide(view, start)
    assert told.index == untold.index and told.command.v == untold.command.v
    assert abs(untold.command.w) * 2.0 > 0.05  # the arc chosen would be harder sideways at 2 m/s
    assert abs(told.command.w) * 2.0 == pytest.approx(0.05) and np.sign(told.command.w) == np.sign(untold.command.w)


def test_the_steering_rule_is_told_the_faster_of_the_odometrys_speed_and_the_last_command(tmp_path: Path):
    """RuleInput.speed_mps: nothing before a speed rule has commanded and nothing measured is 0;
    then the speed commanded last, or the odometry's where that is faster."""
    classifier = ClassifierConfig(hidden=8, skip=True)
    meta = {**model_meta(), "rules": [SpeedRule(SpeedConfig(), MODEL).header()], "drives": "argmax"}
    planner = Planner(load_model(save_model(tmp_path / "speed.safetensors", classifier, skip_path_weights(classifier), meta)))
    told = []
    decide = planner.runner.decide
    planner.runner.decide = lambda frame: told.append(frame.speed_mps) or decide(frame)
    planner.set_path(ALL_MUD.waypoints)
    view = SegmentationView.of(SegmentationRenderer(planner.camera, rasterise(ALL_MUD)).render((2.0, 10.0, 0.0)))
    for measured in (None, 0.5, 1.7):
        planner.decide(view, (2.0, 10.0, 0.0), speed_mps=measured)
    assert told == [0.0, 0.9, 1.7]  # the mud's 0.9 commanded at each frame


# --- 5. the rule that drives beside a speed rule -------------------------------------------------------------


def _offset_rule() -> OffsetRule:
    return OffsetRule(OffsetConfig(), OffsetUtility(np.zeros(K + 3), 2.0))


def test_a_speed_rule_sets_the_speed_but_never_drives():
    speed, offset = SpeedRule(SpeedConfig(), MODEL), _offset_rule()
    assert (speed.kind, offset.kind) == (SPEED, STEERING)
    assert driving_rule([offset, speed], None) is offset  # the last rule that steers, not the last listed
    assert driving_rule([speed, offset], None) is offset
    assert driving_rule([offset, speed], "offset") is offset
    assert isinstance(driving_rule([speed], None), ArgmaxRule)  # nothing else steers: C's argmax
    assert isinstance(driving_rule([speed], "argmax"), ArgmaxRule)
    with pytest.raises(UserError) as raised:
        driving_rule([offset, speed], "speed", SOURCE)
    assert raised.value.problems[0].field == "drives"
    assert speed_rule([offset, speed]) is speed and speed_rule([offset]) is None


def test_a_planner_cannot_be_asked_to_drive_by_the_speed_rule():
    speed, offset = SpeedRule(SpeedConfig(), MODEL), _offset_rule()
    assert chosen_rule([offset, speed], None, None, SOURCE) is offset
    assert chosen_rule([offset, speed], "offset", "offset", SOURCE) is offset
    assert isinstance(chosen_rule([speed], None, None, SOURCE), ArgmaxRule)
    with pytest.raises(ValueError, match="no 'speed' rule"):
        chosen_rule([offset, speed], None, "speed", SOURCE)


# --- 6. the planner's speeds against its driver's ------------------------------------------------------------


def _zone(scenario: str, choice: str, speed: float | None, driver: float | None, agrees: bool = True) -> dict:
    return {"scenario": scenario, "driver_choice": choice, "agrees": agrees, "speed_mps": speed, "driver_speed_mps": driver}


def _run(scenario: str, time_s: float, driver_time_s: float | None, lateral: float, driver_lateral: float | None, **flags) -> dict:
    return {
        "scenario": scenario,
        "completed": flags.get("completed", True),
        "driver_completed": flags.get("driver_completed", True),
        "time_s": time_s,
        "driver_time_s": driver_time_s,
        "max_lateral_accel_mps2": lateral,
        "driver_max_lateral_accel_mps2": driver_lateral,
        "driver_lateral_limit_mps2": flags.get("limit"),
    }


ZONES = [
    _zone("a", "mud", 0.6, 0.5),  # 0.1 off
    _zone("b", "mud", 0.3, 0.5),  # 0.2 off
    _zone("a", AVOID, 1.5, 1.6),  # 0.1 off: passed by, the background
    _zone("a", "rock", 0.9, 0.4, agrees=False),  # the planner took another class: left out
    _zone("b", "water", None, 0.5),  # the planner never reached it: left out
    _zone("b", "water", 0.5, None),  # nor the driver
]
RUNS = [
    _run("a", 10.4, 10.0, 1.09, 1.0, limit=1.0),  # 4% slower: within; lateral 9% above: not over
    _run("b", 9.0, 10.0, 1.2, 1.0, limit=1.5),  # 10% faster: not within; 20% above the driver's run: over; under its limit
    _run("b", 50.0, 10.0, 0.5, None, completed=False, limit=0.4),  # the planner did not finish: no time; no driver's lateral
    _run("a", 10.0, 10.0, 0.5, 0.0, driver_completed=False),  # nor did the driver; a driver's 0: no ratio; no limit known
]


def test_the_speed_error_per_class_is_over_the_zones_both_took():
    c = SpeedComparison.of(ZONES, RUNS, "grass")
    assert set(c.by_class) == {"mud", "grass"}  # the zones passed by: on the background, by its name (SPEC 18)
    assert c.by_class["mud"].mean == pytest.approx(0.15) and c.by_class["mud"].n == 2
    assert c.by_class["mud"].low == pytest.approx(0.1) and c.by_class["mud"].high == pytest.approx(0.2)  # resampling layouts a, b
    assert c.by_class["grass"].mean == pytest.approx(0.1) and c.by_class["grass"].n == 1


def test_the_time_and_lateral_acceleration_against_the_drivers():
    c = SpeedComparison.of(ZONES, RUNS, "grass")
    assert c.time_ratio is not None and c.time_ratio.n == 2 and c.time_ratio.mean == pytest.approx((1.04 + 0.9) / 2)
    assert c.time_within == (1, 2)
    assert c.lateral_over == (1, 2) and c.lateral_worst == pytest.approx(1.2)
    assert c.limit_over == (1, 3) and c.limit_worst == pytest.approx(0.5 / 0.4)  # runs whose driver's limit is known
    assert TIME_TOLERANCE == 0.05 and LATERAL_TOLERANCE == 0.10
    edge = SpeedComparison.of([], [_run("a", 10.49, 10.0, 1.0999, 1.0), _run("a", 10.51, 10.0, 1.1001, 1.0)], "grass")
    assert edge.time_within == (1, 2) and edge.lateral_over == (1, 2)
    none = SpeedComparison.of([], [], "grass")
    assert none.by_class == {} and none.time_ratio is None and none.time_within == (0, 0) and none.lateral_worst is None
    assert none.limit_over == (0, 0) and none.limit_worst is None


def test_a_comparison_reads_back_what_it_writes():
    for c in (SpeedComparison.of(ZONES, RUNS, "grass"), SpeedComparison.of([], [], "grass")):
        assert SpeedComparison.from_dict(json.loads(json.dumps(c.to_dict()))) == c
    lines = SpeedComparison.of(ZONES, RUNS, "grass").lines()
    assert len(lines) == 5  # a line per class, the time, the lateral acceleration against the limit and the driver's run
    assert "against the driver, grass (zones passed by): 0.100" in lines[0] and "mud: 0.150" in lines[1]
    assert "within 5% in 50.0% (1/2" in lines[2]
    assert "above the driver's limit: 33.3% (1/3" in lines[3] and "at most 1.25 times the limit" in lines[3]
    assert "on the same layout: 50.0% (1/2" in lines[4] and "at most 1.20 times it" in lines[4]
    old = {k: v for k, v in SpeedComparison.of(ZONES, RUNS, "grass").to_dict().items() if not k.startswith("limit")}
    assert SpeedComparison.from_dict(old).limit_over == (0, 0)  # a metrics.json from before the limit was compared
    older = {**old, "by_class": {AVOID if k == "grass" else k: v for k, v in old["by_class"].items()}}
    del older["background"]  # from before the background was named
    assert "against the driver, the background (zones passed by): 0.100" in SpeedComparison.from_dict(older).lines()[0]


def test_the_drivers_lateral_limit_is_its_styles_else_the_most_its_drive_showed():
    shown = SpeedRule(SpeedConfig(), replace(MODEL, drive_lateral_mps2=0.9))
    assert driver_lateral_limit("default", (), [_offset_rule(), shown]) == 0.9
    wide = ExpertConfig.styled("wide").lateral_accel_mps2
    assert wide is not None and driver_lateral_limit("wide", (), [_offset_rule(), shown]) == wide  # the style's own limit
    assert driver_lateral_limit("default", (("mud", 0.5),), [_offset_rule()]) is None  # no speed rule: not known


def _meta(*drivers: dict | None) -> dict:
    return {"data": {"recordings": [{"path": f"rec{i}", "driver": d} for i, d in enumerate(drivers)]}}


def test_the_trained_driver_is_the_one_synthetic_driver_of_every_recording():
    speeds = (("mud", 0.6), ("rock", 0.8))
    wide = ExpertInfo.of(0, "wide", ExpertConfig(speeds=speeds)).to_dict()
    assert trained_driver(_meta(wide, ExpertInfo.of(1, "wide", ExpertConfig(speeds=speeds)).to_dict())) == ("wide", speeds, ())
    assert trained_driver(_meta(ExpertInfo.of(0, "default", ExpertConfig()).to_dict())) == ("default", (), ())
    other = ExpertInfo.of(0, "wide", ExpertConfig(speeds=(("mud", 0.7),))).to_dict()
    assert trained_driver(_meta(wide, other)) is None  # two drivers' speeds
    assert trained_driver(_meta(wide, ExpertInfo.of(0, "default", ExpertConfig(speeds=speeds)).to_dict())) is None  # two styles
    assert trained_driver(_meta(wide, HumanInfo().to_dict())) is None  # a person drove one
    assert trained_driver(_meta(HumanInfo().to_dict())) is None
    assert trained_driver(_meta(wide, None)) is None  # a recording that names no driver
    assert trained_driver(_meta()) is None and trained_driver({}) is None and trained_driver({"data": None}) is None
