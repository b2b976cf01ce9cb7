"""The synthetic driver's relief style (SPEC 19): the named styles and ``k=v`` pairs of
``terrapref record --relief-style``, the speed it sheds on grades and rough ground (closed form),
and, driven on small relief courses, going round a side slope steeper than it takes and keeping
to one it takes, and its speed up and down a ramp of known grade; and what the speed rule and
the offset rule learn of it from one drive."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from helpers import one_line_error
from terrapref.cli import main
from terrapref.demos.expert import ExpertConfig, ExpertDriver
from terrapref.demos.recording import read_recording
from terrapref.demos.relief_style import RELIEF_STYLES, ReliefStyle, parse_relief_style
from terrapref.errors import UserError
from terrapref.scenario import Scenario, parse_scenario
from terrapref.sim import EpisodeLog, Simulation, run_episode
from terrapref.vehicle import VehicleConfig


def _scenario(relief: list[dict], waypoints: list[list[float]]) -> Scenario:
    return parse_scenario(
        {
            "format": "terrapref-scenario/1",
            "name": "relief_style",
            "world": {"size_m": [40.0, 20.0], "resolution_m": 0.05, "background": "grass"},
            "terrain": [],
            "relief": relief,
            "path": {"waypoints": waypoints},
        }
    )


def _drive(scenario: Scenario, config: ExpertConfig) -> tuple[Simulation, EpisodeLog]:
    sim = Simulation(scenario)
    log = run_episode(sim, ExpertDriver(config), np.random.default_rng(0))
    assert log.completed and log.collisions == 0
    return sim, log


# --- the style -------------------------------------------------------------------------------------


def test_named_styles_and_pairs_over_them_are_read():
    assert parse_relief_style("default") == ("default", ReliefStyle())
    name, cautious = parse_relief_style("cautious")
    assert name == "cautious" and (cautious.roll_deg, cautious.grade_deg) == (7.0, 9.0)
    assert parse_relief_style("bold,roll_deg=18, up_mps_per_deg=0")[1] == ReliefStyle(
        roll_deg=18.0, grade_deg=22.0, up_mps_per_deg=0.0, down_mps_per_deg=0.01, rough_mps=1.2
    )
    assert parse_relief_style("grade_deg=10")[1] == ReliefStyle(grade_deg=10.0)  # pairs over the default
    assert parse_relief_style("none") == ("none", None)  # relief driven as if it were flat
    assert RELIEF_STYLES.names() == ["default", "bold", "cautious"]


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("steep", "'steep' is not a relief style"),
        ("roll=8", "expected NAME or k=v pairs"),
        ("roll_deg=eight", "roll_deg: expected a number"),
        ("roll_deg=nan", "roll_deg: expected a number"),
        ("roll_deg=95", "roll_deg must lie in (0, 90) deg, got 95"),  # each message names the field it is about
        ("grade_deg=0", "grade_deg must lie in (0, 90) deg, got 0"),
        ("rough_mps=0", "rough_mps must be > 0, got 0"),
        ("default,rough_m=0", "rough_m must be > 0, got 0"),
        ("up_mps_per_deg=-0.1", "up_mps_per_deg must lie in [0, 0.2]"),
        ("roll_deg=8,roll_deg=9", "roll_deg is given twice"),
        ("default,down_mps_per_deg=10", "down_mps_per_deg must lie in [0, 0.2]"),  # a driver that crawls down any grade
        ("none,roll_deg=8", "none (relief driven as if it were flat) takes no k=v changes"),
        ("roll_deg=1_0", "roll_deg: expected a number"),  # Python's float() reads 1_0 as 10; a file's number does not
        ("default,rough_m=1e308", "rough_m must be at most 1 m"),  # no ground would ever be rough
    ],
)
def test_a_bad_relief_style_is_refused_naming_the_flag(text: str, says: str):
    with pytest.raises(UserError) as caught:
        parse_relief_style(text)
    assert caught.value.source == "--relief-style" and says in str(caught.value)


def test_its_speed_sheds_per_degree_up_and_down_and_is_capped_on_rough_ground():
    style = ReliefStyle()  # 0.03 m/s per deg up, 0.02 down, 0.8 m/s where rougher than 0.015 m
    assert style.speed(1.6, math.radians(10.0), 0.0, 0.1) == pytest.approx(1.3)
    assert style.speed(1.6, math.radians(-10.0), 0.0, 0.1) == pytest.approx(1.4)
    assert style.speed(1.6, 0.0, 0.05, 0.1) == 0.8 and style.speed(1.6, 0.0, 0.015, 0.1) == 1.6
    assert style.speed(0.5, math.radians(20.0), 0.0, 0.1) == 0.1  # it crawls up a grade it takes


# --- driven -------------------------------------------------------------------------------------

# A plateau 1 m up north of y = 12 between x = 14 and 26, its side a ramp 3.5 m wide outside it: a
# side slope of atan(1 / 3.5) = 15.9 deg under a path along y = 10.25, the middle of the ramp.
BANK = [{"plateau": {"polygon": [[14.0, 12.0], [26.0, 12.0], [26.0, 30.0], [14.0, 30.0]], "height_m": 1.0, "edge_m": 3.5}}]
ALONG_BANK = [[2.0, 10.25], [38.0, 10.25]]


def _roll_deg(sim: Simulation, xy: np.ndarray) -> np.ndarray:
    """The body's roll [deg] heading along x at the points ``xy``: the heights under its wheels
    0.6 m either side (the vehicle's track, as its attitude is set)."""
    dy = np.array([0.0, 0.6])
    rise = sim.world.height_at(xy + dy) - sim.world.height_at(xy - dy)
    return np.degrees(np.arctan(np.abs(rise) / 1.2))


@pytest.mark.parametrize(("style", "goes_round"), [("default", True), ("bold", False)])
def test_a_side_slope_steeper_than_it_takes_is_gone_round_and_one_it_takes_is_kept_to(style: str, goes_round: bool):
    sim, log = _drive(_scenario(BANK, ALONG_BANK), ExpertConfig(relief=parse_relief_style(style)[1]))
    stretch = (log.trace[:, 0] > 17.0) & (log.trace[:, 0] < 23.0)
    roll = _roll_deg(sim, log.trace[stretch, :2])
    if goes_round:  # the default takes 12 deg: down off the bank, its wheels on the flat ground below it
        assert roll.max() < 12.0 and (log.trace[stretch, 1] < 9.0).all()
    else:  # the bold driver takes 20 deg: along the path, on the bank
        assert np.abs(log.trace[stretch, 1] - 10.25).max() < 0.3 and roll.min() > 15.0


def test_without_a_relief_style_it_drives_along_the_bank_as_if_it_were_flat():
    sim, log = _drive(_scenario(BANK, ALONG_BANK), ExpertConfig())
    stretch = (log.trace[:, 0] > 17.0) & (log.trace[:, 0] < 23.0)
    assert np.abs(log.trace[stretch, 1] - 10.25).max() < 0.3


# A plateau 1 m up east of x = 20, its ramp 6 m wide (x = 14 to 20): a grade of atan(1 / 6) = 9.46 deg.
RAMP = [{"plateau": {"polygon": [[20.0, -10.0], [60.0, -10.0], [60.0, 30.0], [20.0, 30.0]], "height_m": 1.0, "edge_m": 6.0}}]


@pytest.mark.parametrize(("waypoints", "shed_per_deg"), [([[2.0, 10.0], [38.0, 10.0]], 0.03), ([[38.0, 10.0], [2.0, 10.0]], 0.02)])
def test_on_a_ramp_it_asks_for_its_speed_less_what_the_grade_takes(waypoints: list[list[float]], shed_per_deg: float):
    """Up (0.03 m/s per deg) and down (0.02): 1 m/s less 9.46 deg's worth, asked for while its
    footprint and its way over the next 3 m lie on the ramp; 1 m/s on the level."""
    sim, log = _drive(_scenario(RAMP, waypoints), ExpertConfig(relief=ReliefStyle()))
    x = log.trace[np.minimum(3 * np.arange(len(log.commands)), len(log.trace) - 1), 0]  # each frame's (3 ticks of 30 Hz)
    on_ramp = (x > 14.5 + 3.5) & (x < 19.5) if waypoints[0][0] < 20 else (x < 19.5 - 3.5) & (x > 14.5)
    wanted = 1.0 - shed_per_deg * math.degrees(math.atan(1.0 / 6.0))
    # The command lags the wish by the hand's 0.2 s (2 frames), well inside the stretch.
    assert on_ramp.sum() > 10 and np.abs(log.commands[on_ramp, 0] - wanted).max() < 0.01
    level = (x < 8.0) if waypoints[0][0] < 20 else (x > 28.0)
    assert np.abs(log.commands[level & (log.commands[:, 0] > 0.5), 0] - 1.0).max() < 1e-9


def test_slowed_to_a_crawl_by_a_grade_it_still_turns_towards_its_line():
    """Shedding 0.2 m/s a degree, the ramp's 9.5 deg slows it to 0.1 m/s. Heading 0.5 rad off the
    path there, pure pursuit at 0.1 m/s asks for less than the hand's 0.06 rad/s deadzone, and the
    stick stayed at zero: it crept off its line, turned by whatever pushed it. A person crawling
    up a bank still turns the vehicle towards where they go."""
    from terrapref.camera import SegmentationView
    from terrapref.sim import Frame
    from terrapref.vehicle import Pose

    scenario = _scenario(RAMP, [[2.0, 10.0], [38.0, 10.0]])
    driver = ExpertDriver(ExpertConfig(relief=parse_relief_style("default,up_mps_per_deg=0.2")[1]))
    driver.reset(scenario, np.random.default_rng(0))
    view = SegmentationView.of(np.zeros((4, 4), np.uint8))
    w = driver.intent(Frame(0, 0.0, view, Pose(17.0, 10.0, 0.5), np.asarray(scenario.waypoints), 0.1))
    assert driver.wanted_mps < 0.2 and w < -driver.config.deadzone_rps  # right, back towards the path


def test_a_push_begins_only_clear_of_ground_that_would_tilt_the_vehicle_past_its_limits():
    """What a push keeps clear of besides lethal terrain (terrapref.demos.disturbance): the flank of
    a bank 1 m high over 1.5 m (34 deg) is past the vehicle's 25 deg of roll from within the
    clearance of it and not from farther; the bank over 3.5 m (16 deg) is within the limits, and a
    flat world has nothing steep."""
    from terrapref.world import rasterise

    steep = [{"plateau": {"polygon": [[14.0, 12.0], [26.0, 12.0], [26.0, 30.0], [14.0, 30.0]], "height_m": 1.0, "edge_m": 1.5}}]
    limit = VehicleConfig().max_roll_deg
    world = rasterise(_scenario(steep, ALONG_BANK))
    assert world.steep_within(20.0, 10.25, 3.0, limit, 0.6) and not world.steep_within(20.0, 6.0, 3.0, limit, 0.6)
    gentle = rasterise(_scenario(BANK, ALONG_BANK))
    assert not gentle.steep_within(20.0, 10.25, 3.0, limit, 0.6) and gentle.steep_within(20.0, 10.25, 3.0, 12.0, 0.6)
    assert not rasterise(_scenario([], ALONG_BANK)).steep_within(20.0, 10.25, 3.0, 1.0, 0.6)


@pytest.mark.slow  # a whole drive, course or training end to end; the default run keeps the test suite's time
def test_record_stores_the_relief_style_and_refuses_a_bad_one(tmp_path, capsys):
    course, out = tmp_path / "bank.yaml", tmp_path / "rec"
    course.write_text(yaml.safe_dump(_scenario(BANK, [[8.0, 10.25], [20.0, 10.25]]).to_dict()))
    assert main(["record", str(course), "--relief-style", "cautious,rough_mps=0.6", "--out", str(out), "--quiet"]) == 0
    relief = read_recording(out).meta["driver"]["config"]["relief"]
    assert relief == {**ReliefStyle(roll_deg=7.0, grade_deg=9.0, up_mps_per_deg=0.05, down_mps_per_deg=0.05, rough_mps=0.6).to_dict()}
    capsys.readouterr()
    assert main(["record", str(course), "--relief-style", "roll_deg=91", "--out", str(tmp_path / "bad"), "--quiet"]) == 2
    one_line_error(capsys, "--relief-style", "roll_deg")
    assert main(["record", str(course), "--relief-style", "default,rough_mps=1e9", "--out", str(tmp_path / "bad"), "--quiet"]) == 2
    one_line_error(capsys, "--relief-style", "rough_mps: 1e+09 m/s is above the vehicle's top speed, 2 m/s")  # a cap never reached
    assert not (tmp_path / "bad").exists()


def test_a_models_relief_style_is_that_of_its_recordings_driver_and_the_comparison_runs_carry_it():
    from terrapref.evaluation.evaluate import Evaluation
    from terrapref.evaluation.runner import EXPERT
    from terrapref.evaluation.speed import trained_relief
    from terrapref.terrain import PreferenceProfile

    cautious = parse_relief_style("cautious")[1]

    def meta(*reliefs: dict | None) -> dict:
        configs = [{"speeds": []} if r is None else {"speeds": [], "relief": r} for r in reliefs]
        return {"data": {"recordings": [{"driver": {"kind": "expert", "style": "default", "config": c}} for c in configs]}}

    assert trained_relief(meta(cautious.to_dict(), cautious.to_dict())) == cautious
    assert trained_relief(meta(None)) is None  # a driver that drove relief as if flat
    assert trained_relief(meta(cautious.to_dict(), ReliefStyle().to_dict())) is None  # a mix
    with pytest.raises(
        UserError, match=r"^m.safetensors: data.recordings\[\].driver.config.relief: .* cannot be read; give .*--relief-style"
    ):
        trained_relief(meta({**cautious.to_dict(), "roll_deg": "steep"}), "m.safetensors")  # not readable: said, never a flat driver
    specs = Evaluation("m.safetensors", ("relief_hazards",), 1, relief=cautious).specs(PreferenceProfile.default())
    assert [s.relief for s in specs if s.driver == EXPERT] == [cautious] and all(s.relief is None for s in specs if s.driver != EXPERT)


# A plateau 1 m high between x = 16 and 24 m, its sides ramps of 6 m: up from x = 10, down to x = 30.
HILL = [{"plateau": {"polygon": [[16.0, -10.0], [24.0, -10.0], [24.0, 30.0], [16.0, 30.0]], "height_m": 1.0, "edge_m": 6.0}}]


# Its level top rough (0.019 m of roughness, past the default relief style's 0.015 m).
ROUGH_TOP = [
    {"noise": {"amplitude_m": 0.07, "wavelength_m": 0.3, "seed": 1, "polygon": [[16.5, 5.0], [23.5, 5.0], [23.5, 15.0], [16.5, 15.0]]}}
]


@pytest.mark.slow  # a whole drive, course or training end to end; the default run keeps the test suite's time
def test_the_speed_rule_learns_what_the_drivers_grades_shed_from_its_drive(tmp_path):
    """The driver (0.03 m/s per deg up, 0.02 down, 0.8 m/s on rough ground) drives over the hill
    once, through the depth camera; the speed rule fitted to that drive sheds what it sheds, to
    within a tenth, with intervals, keeps its speed on the rough top, and its level speed is the
    driver's 1 m/s."""
    from terrapref.dataset import build_dataset
    from terrapref.demos.meta import ExpertInfo
    from terrapref.demos.recording import MemoryRecordingWriter
    from terrapref.demos.session import DriveSetup, RunSettings, record_run
    from terrapref.learning.train import FitData
    from terrapref.recipes import DEFAULT_RECIPE, recipe_named, rules_with
    from terrapref.rules.speed.rule import SpeedConfig
    from terrapref.terrain import PreferenceProfile

    setup = DriveSetup.of(_scenario(HILL + ROUGH_TOP, [[5.0, 10.0], [35.0, 10.0]]))
    config = ExpertConfig(relief=ReliefStyle())
    writer = MemoryRecordingWriter(
        tmp_path / "mem", setup.meta(ExpertInfo.of(0, "default", config), PreferenceProfile.default()), setup.scenario.to_dict()
    )
    record_run(setup.simulation(), ExpertDriver(config), writer, RunSettings(setup.preference), np.random.default_rng(0))
    recipe = recipe_named(DEFAULT_RECIPE)
    data = build_dataset([writer.recording()], recipe.features(), rules=rules_with(recipe))
    rule = SpeedConfig().fit(FitData(data, mirror=False))
    assert rule is not None and rule.fit is not None and rule.fit.on_grades
    m = rule.model
    assert m.up_mps_per_deg == pytest.approx(0.03, rel=0.1) and m.down_mps_per_deg == pytest.approx(0.02, rel=0.1)
    (up_low, up_high), (down_low, down_high) = rule.fit.grade_intervals
    assert up_low <= m.up_mps_per_deg <= up_high and down_low <= m.down_mps_per_deg <= down_high
    assert m.speeds_mps[-1] == pytest.approx(1.0, abs=0.02)
    assert m.rough_mps == pytest.approx(ReliefStyle().rough_mps, abs=0.03) and rule.fit.rough.frames >= 10
    low, high = rule.fit.rough.interval
    assert low <= m.rough_mps <= high and 0.0 < m.rough_m < 0.03
    # The rule bound to a planner, on the ground map its frames fill: the rough top's cap where the
    # first metre ahead is rough, the level speed beyond the hill.
    from terrapref.camera import CameraConfig, PinholeCamera
    from terrapref.features import UtilityFeaturizer
    from terrapref.groundmap.height import DepthImage
    from terrapref.groundmap.map import GroundMap
    from terrapref.rules.base import RuleContext

    rec = writer.recording()
    camera = PinholeCamera(CameraConfig.from_dict(rec.meta["camera"]))
    context = RuleContext(camera, UtilityFeaturizer(recipe.features(), camera, rec.classes), recipe.features(), rec.classes)
    runner = rule.runner(context)
    ground = GroundMap(camera, context.terrain, runner.map_settings)
    level, rough = [], []
    for i in np.flatnonzero((rec.poses[:, 0] > 13.0) & (rec.poses[:, 0] < 33.0)):  # from the top's first sight
        view, pose = rec.view(i), tuple(float(v) for v in rec.poses[i])
        ground.update(view, pose, DepthImage.of(view, camera, pose))
        (level if 30.5 < pose[0] < 33.0 else rough if 17.5 < pose[0] < 22.5 else []).append(runner.speed(ground, pose, 0.0, 1.0))
    assert np.median(level) == pytest.approx(m.speeds_mps[-1], abs=0.01) and np.median(rough) == pytest.approx(m.rough_mps, abs=0.01)


# A bank beside the path along y = 10 m: a ridge 5 m wide along y = 11.25 m from x = 12 to 28 m, the
# path on its flank, rolling a body of 1.2 m track heading along it by 16 deg (SPEC 19 ridge, cosine).
RIDGE_BANK = [{"ridge": {"polyline": [[12.0, 11.25], [28.0, 11.25]], "width_m": 5.0, "height_m": 0.503}}]


def _relief_prices(tmp_path, style: str) -> tuple[np.ndarray, float]:
    """The offset rule fitted to one drive of the bank by the driver of relief style ``style``:
    the price of a metre of side slope past each band (the cumulative weights, less is dearer),
    and the detour's weight."""
    from terrapref.dataset import build_dataset
    from terrapref.demos.meta import ExpertInfo
    from terrapref.demos.recording import MemoryRecordingWriter
    from terrapref.demos.session import DriveSetup, RunSettings, record_run
    from terrapref.learning.train import FitData
    from terrapref.recipes import DEFAULT_RECIPE, recipe_named, rules_with
    from terrapref.rules.offset.features import RELIEF_BANDS_DEG
    from terrapref.rules.offset.rule import OffsetConfig
    from terrapref.terrain import PreferenceProfile

    setup = DriveSetup.of(_scenario(RIDGE_BANK, [[6.0, 10.0], [34.0, 10.0]]))
    config = ExpertConfig(relief=parse_relief_style(style)[1])
    writer = MemoryRecordingWriter(
        tmp_path / style, setup.meta(ExpertInfo.of(0, "default", config), PreferenceProfile.default()), setup.scenario.to_dict()
    )
    record_run(setup.simulation(), ExpertDriver(config), writer, RunSettings(setup.preference), np.random.default_rng(0))
    recipe = recipe_named(DEFAULT_RECIPE)
    data = build_dataset([writer.recording()], recipe.features(), rules=rules_with(recipe))
    rule = OffsetConfig().fit(FitData(data, mirror=False))
    assert rule is not None and rule.utility.relief is not None
    relief, bands = rule.utility.relief, len(RELIEF_BANDS_DEG)
    assert (relief <= 0).all()  # steeper never costs less
    return np.cumsum(relief[:bands]), float(rule.utility.weights[-2])


@pytest.mark.slow  # two whole drives recorded and fitted; the fit's parts are tested apart in the default run
def test_the_offset_rule_learns_the_side_slope_a_driver_goes_round_from_its_drive(tmp_path):
    """The cautious driver (round side slopes past 7 deg) leaves the path beside the 16 deg bank;
    the bold one (20 deg) keeps to it. The offset rule fitted to each drive prices a metre along
    the bank as each drove it, on the scale of the detour's price: the cautious driver's dearer
    than holding 1.5 m off the path for it (1.5^2), the bold one's under a third of that, and the
    cautious driver's ten times the bold one's."""
    from terrapref.rules.offset.features import RELIEF_BANDS_DEG

    at = RELIEF_BANDS_DEG.index(14.0)
    prices, detour = _relief_prices(tmp_path, "cautious")
    cautious = prices[at] / detour
    prices, detour = _relief_prices(tmp_path, "bold")
    bold = prices[at] / detour
    assert cautious > 1.5**2 > 3 * bold and cautious > 10 * bold


def test_evaluate_says_so_when_a_relief_style_is_given_for_flat_courses_alone(capsys):
    from terrapref.cli.evaluate import _note_flat

    _note_flat(["demo_course"], None)
    assert "note: demo_course: flat, so the driver's relief style changes no run" in capsys.readouterr().err
    _note_flat(["demo_course", "relief_demo"], None)
    assert capsys.readouterr().err == ""
