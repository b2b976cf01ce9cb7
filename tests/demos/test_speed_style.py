"""The synthetic driver's speed style (SPEC 18): a cruising speed per class, by name or by
preference rank; slowing over its preview distance before a slower class; its lateral-acceleration
limit in bends; its speed near lethal terrain; the steady default driver; and the style's
flags and files (terrapref.demos.speed_style, ``terrapref record --speeds``), each against a
closed-form or derivable answer on a tiny map."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from helpers import REPO, one_line_error
from terrapref.cli import main
from terrapref.demos.expert import STYLES, ExpertConfig, ExpertDriver
from terrapref.demos.recording import read_recording
from terrapref.demos.speed_style import driver_style, parse_speeds, read_style_file
from terrapref.errors import UserError
from terrapref.evaluation import score_run
from terrapref.scenario import Scenario, parse_scenario
from terrapref.sim import EpisodeLog, Simulation, run_episode
from terrapref.terrain import PreferenceProfile, default_classes, load_classes

CLASSES = default_classes()  # grass 0, non_traversable 1, water 2, rock 3, mud 4
GRASS, NON_TRAVERSABLE, WATER, ROCK, MUD = (CLASSES.id_of(n) for n in ("grass", "non_traversable", "water", "rock", "mud"))
RELLIS = REPO / "examples" / "classes" / "rellis3d.yaml"
TOP_SPEED_MPS = 2.0  # VehicleConfig's default
STYLE_FORMAT = "format: terrapref-driver-style/1\n"


def _scenario(terrain: list[dict], waypoints: list[list[float]], size_m: tuple[float, float] = (40.0, 20.0)) -> Scenario:
    return parse_scenario(
        {
            "format": "terrapref-scenario/1",
            "name": "speed_style",
            "world": {"size_m": list(size_m), "resolution_m": 0.05, "background": "grass"},
            "terrain": terrain,
            "path": {"waypoints": waypoints},
        }
    )


def _drive(scenario: Scenario, config: ExpertConfig, seed: int = 0) -> tuple[Simulation, EpisodeLog]:
    sim = Simulation(scenario)
    log = run_episode(sim, ExpertDriver(config), np.random.default_rng(seed))
    assert log.completed and log.collisions == 0
    return sim, log


def _speeds_where(log: EpisodeLog, mask: np.ndarray) -> np.ndarray:
    """The vehicle's speeds [m/s] at the controller ticks ``mask`` picks (a mask over ``log.trace``)."""
    assert log.speeds is not None and len(log.speeds) == len(log.trace)
    assert mask.any(), "no tick in the stretch asked about"
    return log.speeds[mask]


# A straight path along y = 10 from x = 2 to x = 38 over a 40 m x 20 m field of grass.
STRAIGHT = [[2.0, 10.0], [38.0, 10.0]]
# Mud from x = 23 to x = 27 across the whole map: every offset the driver weighs (up to 8 m
# either side) crosses it, so it drives straight over.
MUD_ACROSS = {"class": "mud", "rectangle": {"center": [25.0, 10.0], "size": [4.0, 20.0]}}


# --- the speed table ----------------------------------------------------------------------------


def test_speeds_by_name_the_rest_at_the_cruising_speed():
    table = ExpertConfig(speed_mps=1.3, speeds=(("grass", 1.6), ("mud", 0.5))).speed_table(CLASSES)
    assert table.shape == (256,)
    assert table[GRASS] == 1.6 and table[MUD] == 0.5
    assert table[ROCK] == table[WATER] == 1.3


def test_ranked_speeds_spread_evenly_from_the_most_to_the_least_preferred_class():
    # Three feature classes (the lethal column is not driven on): 1.2, 0.8, 0.4 by rank.
    config = ExpertConfig(profile=("water", "rock", "mud", "non_traversable"), speed_mps=1.5, ranked_speeds_mps=(1.2, 0.4))
    table = config.speed_table(CLASSES)
    assert table[WATER] == pytest.approx(1.2) and table[ROCK] == pytest.approx(0.8) and table[MUD] == pytest.approx(0.4)
    assert table[GRASS] == 1.5  # the background keeps the cruising speed
    # The default profile (mud, rock, water) reverses it.
    table = ExpertConfig(speed_mps=1.5, ranked_speeds_mps=(1.2, 0.4)).speed_table(CLASSES)
    assert table[MUD] == pytest.approx(1.2) and table[ROCK] == pytest.approx(0.8) and table[WATER] == pytest.approx(0.4)


def test_a_named_speed_wins_over_the_ranked_one_and_leaves_the_other_ranks_alone():
    table = ExpertConfig(ranked_speeds_mps=(1.2, 0.4), speeds=(("rock", 1.5),)).speed_table(CLASSES)
    assert table[ROCK] == 1.5
    assert table[MUD] == pytest.approx(1.2) and table[WATER] == pytest.approx(0.4)


def test_lethal_classes_and_ids_the_table_does_not_name_have_no_speed():
    table = ExpertConfig(speeds=(("non_traversable", 0.3),), ranked_speeds_mps=(1.0, 0.5)).speed_table(CLASSES)
    assert np.isnan(table[NON_TRAVERSABLE])  # even when named: it is never driven on
    named = [c.id for c in CLASSES.classes]
    assert np.isnan(np.delete(table, named)).all()  # 5..255, 255 (off the map) included
    assert np.isfinite(table[[GRASS, WATER, ROCK, MUD]]).all()


def test_a_class_the_table_lacks_is_a_value_error_naming_it():
    with pytest.raises(ValueError, match="'gravel'"):
        ExpertConfig(speeds=(("gravel", 1.0),)).speed_table(CLASSES)


def test_the_speed_table_of_a_custom_class_table():
    rellis = load_classes(RELLIS)  # profile: dirt, gravel, puddle, mud, bush, water, lethal
    config = ExpertConfig(profile=rellis.profile, speed_mps=1.6, ranked_speeds_mps=(1.0, 0.5), speeds=(("gravel", 1.4),))
    table = config.speed_table(rellis)
    by_name = {name: table[rellis.id_of(name)] for name in rellis.names}
    # Six feature classes, 0.1 m/s apart; gravel named.
    expected = {"dirt": 1.0, "gravel": 1.4, "puddle": 0.8, "mud": 0.7, "bush": 0.6, "water": 0.5, "grass": 1.6}
    assert {n: by_name[n] for n in expected} == pytest.approx(expected)
    assert all(np.isnan(by_name[n]) for n in rellis.lethal)
    assert np.isnan(table[len(rellis.names) :]).all()
    with pytest.raises(ValueError, match="'rock'"):  # the default table's class is not this one's
        ExpertConfig(profile=rellis.profile, speeds=(("rock", 1.0),)).speed_table(rellis)


def test_the_presets_speeds_fit_the_vehicle_and_only_the_default_is_steady():
    for name in STYLES.names():
        config = driver_style(name, CLASSES.profile, CLASSES, TOP_SPEED_MPS)
        assert config == ExpertConfig.styled(name, CLASSES.profile)
        assert config.steady == (name == "default"), name
    wide = ExpertConfig.styled("wide").speed_table(CLASSES)  # 1.2 on grass, 0.9 to 0.5 by preference
    np.testing.assert_allclose(wide[[GRASS, MUD, ROCK, WATER]], [1.2, 0.9, 0.7, 0.5])


# --- validation ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "changes",
    [
        {"speed_mps": 0.0},
        {"speed_mps": -1.0},
        {"speed_mps": math.inf},
        {"speed_mps": math.nan},
        {"speed_mps": True},
        {"speeds": (("mud", 0.0),)},
        {"speeds": (("mud", -0.5),)},
        {"speeds": (("mud", math.nan),)},
        {"speeds": (("mud", True),)},
        {"ranked_speeds_mps": (1.0, 0.0)},
        {"ranked_speeds_mps": (math.inf, 0.5)},
        {"near_lethal_mps": -0.5},
        {"near_lethal_mps": math.nan},
        {"lateral_accel_mps2": 0.0},
        {"lateral_accel_mps2": -1.0},
        {"lateral_accel_mps2": math.inf},
        {"lateral_accel_mps2": True},
        {"preview_m": 0.0},
        {"preview_m": -1.0},
        {"preview_m": math.nan},
        {"near_lethal_m": -0.1},
        {"near_lethal_m": math.inf},
    ],
    ids=lambda c: "-".join(f"{k}={v}" for k, v in c.items()),
)
def test_bad_speed_style_values_are_refused(changes):
    with pytest.raises(ValueError):
        ExpertConfig(**changes)


def test_the_edges_of_the_valid_ranges_are_accepted():
    config = ExpertConfig(near_lethal_m=0.0, lateral_accel_mps2=None, near_lethal_mps=None, preview_m=0.25, speed_mps=2)
    assert config.near_lethal_m == 0.0 and config.speed_mps == 2


def test_a_zero_speed_near_lethal_terrain_is_refused():
    with pytest.raises(ValueError):
        ExpertConfig(near_lethal_mps=0.0)


# --- driving ------------------------------------------------------------------------------------


def test_on_a_straight_the_vehicle_settles_at_its_speed_for_grass():
    scenario = _scenario([], STRAIGHT)
    sim, log = _drive(scenario, ExpertConfig(speeds=(("grass", 1.5),)))
    np.testing.assert_array_equal(log.commands[:, 0], 1.5)
    np.testing.assert_array_equal(sim.speeds, log.speeds)
    # 0 to 1.5 m/s at 1 m/s^2: 1.5 s (45 ticks at 30 Hz) over 1.5^2 / 2 = 1.125 m; then 1.5 m/s held.
    assert log.speeds[45] == pytest.approx(1.5) and log.speeds[44] < 1.5
    assert log.trace[45, 0] == pytest.approx(2.0 + 1.125)
    np.testing.assert_array_equal(log.speeds[45:], 1.5)
    # It ends at the first frame after the centre is 2 m from the goal: 1.5 s + (36 - 2 - 1.125) m / 1.5 m/s.
    metrics = score_run(log, scenario, sim.world, PreferenceProfile.default())
    arrive_s = 1.5 + (36.0 - 2.0 - 1.125) / 1.5
    assert arrive_s <= metrics.time_s < arrive_s + 0.1 + 1e-9
    assert metrics.speed_by_class_mps["grass"]["mps"] == pytest.approx((log.trace[-1, 0] - 2.0) / metrics.time_s, abs=1e-3)
    assert metrics.max_lateral_accel_mps2 == 0.0


@pytest.fixture(scope="module")
def over_mud() -> tuple[Scenario, Simulation, EpisodeLog]:
    """1.5 m/s on grass, 0.5 m/s on mud, over the mud across the straight (x 23 to 27)."""
    scenario = _scenario([MUD_ACROSS], STRAIGHT)
    sim, log = _drive(scenario, ExpertConfig(speeds=(("grass", 1.5), ("mud", 0.5))))
    np.testing.assert_array_equal(log.trace[:, 1], 10.0)  # straight over: nothing to swerve for
    return scenario, sim, log


def test_it_slows_for_mud_within_its_preview_and_crosses_at_the_mud_speed(over_mud):
    scenario, sim, log = over_mud
    x = log.trace[:, 0]
    # The way ahead reaches the mud once the centre is 3 m (preview_m) from it, at x = 20: before
    # that, after the ramp (x >= 3.125), it holds the grass speed.
    np.testing.assert_array_equal(_speeds_where(log, (x >= 3.2) & (x < 20.0)), 1.5)
    # Then 0.2 s of the hand's delay (0.3 m) plus 1.5 -> 0.5 m/s at 2 m/s^2 (0.5 s, 0.5 m), up to
    # one frame late (0.15 m): down to the mud speed by x = 20.95, 2 m before the edge.
    assert _speeds_where(log, (x >= 21.0) & (x < 23.0)).max() <= 0.5 + 1e-9
    on_mud = (x >= 23.0) & (x <= 27.0)
    np.testing.assert_allclose(_speeds_where(log, on_mud), 0.5, atol=1e-9)
    # Past the mud it speeds up again: 1 s at 1 m/s^2 after the hand's delay.
    np.testing.assert_array_equal(_speeds_where(log, x >= 29.0), 1.5)
    assert set(np.unique(log.commands[:, 0])) == {0.5, 1.5}
    metrics = score_run(log, scenario, sim.world, PreferenceProfile.default())
    assert metrics.speed_by_class_mps["mud"]["mps"] == pytest.approx(0.5, abs=1e-3)
    assert metrics.speed_by_class_mps["mud"]["s"] == pytest.approx(4.0 / 0.5, abs=0.1)


def test_a_longer_preview_slows_earlier():
    _, log = _drive(_scenario([MUD_ACROSS], STRAIGHT), ExpertConfig(speeds=(("grass", 1.5), ("mud", 0.5)), preview_m=6.0))
    x = log.trace[:, 0]
    np.testing.assert_array_equal(_speeds_where(log, (x >= 3.2) & (x < 17.0)), 1.5)
    assert _speeds_where(log, (x >= 18.0) & (x <= 27.0)).max() <= 0.5 + 1e-9


def _bend(radius_m: float) -> tuple[list[list[float]], tuple[float, float]]:
    """A straight along y = 2 from x = 2 to 14, a left half circle of ``radius_m`` (61 points)
    and a straight back: the waypoints and the circle's centre."""
    cx, cy = 14.0, 2.0 + radius_m
    arc = [[cx + radius_m * math.sin(t), cy - radius_m * math.cos(t)] for t in np.linspace(0.0, math.pi, 61)]
    return [[2.0, 2.0], *arc, [2.0, cy + radius_m]], (cx, cy)


@pytest.mark.parametrize(("radius_m", "accel_mps2"), [(4.0, 0.25), (5.0, 0.45)])
def test_in_a_bend_it_keeps_to_its_lateral_acceleration(radius_m: float, accel_mps2: float):
    waypoints, (cx, cy) = _bend(radius_m)
    # A hand without tremor, so that the bound is geometry's alone.
    config = ExpertConfig(speed_mps=1.8, lateral_accel_mps2=accel_mps2, stick_noise_rps=0.0)
    _, log = _drive(_scenario([], waypoints, size_m=(24.0, 2 * radius_m + 6.0)), config)
    x, y = log.trace[:, 0], log.trace[:, 1]
    limit_mps = math.sqrt(accel_mps2 * radius_m)  # v^2 / R = a
    # Along the bend, 0 at its start, pi at its end.
    turned = np.arctan2(x - cx, cy - y)
    # The middle half of the bend: it sees the bend through its pursuit point 2.5 m ahead, and it
    # takes the hand's delay and the brakes about 3 m (a quarter turn) into it to come down.
    middle = (x >= cx) & (turned >= math.pi / 4) & (turned <= 3 * math.pi / 4)
    in_bend = _speeds_where(log, middle)
    # The limit applies to the pure-pursuit curvature toward a point 2.5 m along the arc, which
    # is 1/R only with the vehicle on the arc, heading along it. Pure pursuit cuts slightly
    # inside the arc (a tighter circle: slower) and the 61-point polyline and the stick's 0.2 s
    # lag swing the heading by a little, measured at up to 0.2% over sqrt(a R): 1% allows for it.
    assert in_bend.max() <= 1.01 * limit_mps
    assert in_bend.min() >= 0.95 * limit_mps  # kept to the limit, not crawling
    straight = _speeds_where(log, (y < 3.0) & (x >= 4.0) & (x <= 11.0))
    np.testing.assert_array_equal(straight, 1.8)


def _beside_the_path(gap_m: float) -> dict:
    """A 1 m deep lethal strip from x = 15 to 25, ``gap_m`` left of the footprint's edge (y 10.6)."""
    return {"class": "non_traversable", "rectangle": {"center": [20.0, 10.6 + gap_m + 0.5], "size": [10.0, 1.0]}}


@pytest.mark.parametrize(
    ("near_lethal_m", "gap_m", "slows"),
    [(1.0, 0.7, True), (1.0, 1.3, False), (2.0, 1.3, True)],
)
def test_it_holds_its_near_lethal_speed_only_while_lethal_terrain_is_near(near_lethal_m: float, gap_m: float, slows: bool):
    # 0.7 m or more from the footprint: outside the driver's 0.4 m lethal margin, so no detour.
    config = ExpertConfig(speed_mps=1.5, near_lethal_mps=0.6, near_lethal_m=near_lethal_m)
    _, log = _drive(_scenario([_beside_the_path(gap_m)], [[2.0, 10.0], [34.0, 10.0]], size_m=(36.0, 20.0)), config)
    np.testing.assert_array_equal(log.trace[:, 1], 10.0)
    x = log.trace[:, 0]
    beside = _speeds_where(log, (x >= 15.0) & (x <= 25.0))
    np.testing.assert_array_equal(beside, 0.6 if slows else 1.5)
    # Elsewhere it keeps its speed: before its preview (3 m) reaches the strip, and once it has
    # sped up again (1 s at 1 m/s^2, after the hand's 0.2 s) past it.
    np.testing.assert_array_equal(_speeds_where(log, (x >= 3.2) & (x < 12.0)), 1.5)
    np.testing.assert_array_equal(_speeds_where(log, x >= 27.0), 1.5)


def test_the_default_driver_is_steady_at_1_mps(over_mud):
    scenario, _, _ = over_mud
    config = ExpertConfig()
    assert config.steady and ExpertConfig.styled("default") == config
    _, log = _drive(scenario, config)
    np.testing.assert_array_equal(log.commands[:, 0], 1.0)  # exactly: mud or grass
    after_ramp = log.trace[:, 0] >= 2.6  # 0 to 1 m/s at 1 m/s^2: 0.5 m
    np.testing.assert_array_equal(_speeds_where(log, after_ramp), 1.0)
    assert not ExpertConfig(speeds=(("grass", 1.0),)).steady
    assert not ExpertConfig(lateral_accel_mps2=1.0).steady and not ExpertConfig(near_lethal_mps=0.5).steady


# --- --speeds -----------------------------------------------------------------------------------


def test_speeds_text_is_read_into_pairs():
    assert parse_speeds("grass=1.6,mud=0.5") == (("grass", 1.6), ("mud", 0.5))
    assert parse_speeds(" grass = 1.6 , mud=.5 ") == (("grass", 1.6), ("mud", 0.5))
    assert parse_speeds("rock=1") == (("rock", 1.0),)


@pytest.mark.parametrize("text", ["", "grass", "grass=", "=1", "grass=fast", "grass=1,", "grass=1=2", "grass:1"])
def test_a_malformed_speeds_entry_is_a_user_error_naming_the_flag(text: str):
    with pytest.raises(UserError) as err:
        parse_speeds(text)
    assert err.value.source == "--speeds" and "CLASS=SPEED" in str(err.value)


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "+Infinity"])
def test_a_speed_that_is_not_finite_is_said_to_be_so(value: str):
    with pytest.raises(UserError) as err:
        parse_speeds(f"mud=0.5,grass={value}")
    assert err.value.source == "--speeds" and f"class 'grass': a cruising speed is a finite number of m/s, got {value}" in str(err.value)


def test_a_class_given_twice_is_a_user_error():
    with pytest.raises(UserError, match="'mud' is given twice") as err:
        parse_speeds("mud=0.5,grass=1,mud=0.6")
    assert err.value.source == "--speeds"


# --- style files and driver_style ---------------------------------------------------------------


def _style_file(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "style.yaml"
    path.write_text(STYLE_FORMAT + text)
    return path


def test_a_style_file_names_its_base_and_its_changes(tmp_path):
    path = _style_file(
        tmp_path,
        "base: wide\nspeeds: {grass: 1.6, mud: 0.5}\nlateral_accel_mps2: 0.8\npreview_m: 2\nnear_lethal_mps: null\n"
        "near_lethal_m: 1.5\nranked_speeds_mps: [1.0, 0.6]\nspeed_mps: 1.1\n",
    )
    base, changes = read_style_file(path)
    assert base == "wide"
    assert changes == {
        "speeds": (("grass", 1.6), ("mud", 0.5)),
        "lateral_accel_mps2": 0.8,
        "preview_m": 2.0,
        "near_lethal_mps": None,
        "near_lethal_m": 1.5,
        "ranked_speeds_mps": (1.0, 0.6),
        "speed_mps": 1.1,
    }
    config = driver_style(str(path), CLASSES.profile, CLASSES, TOP_SPEED_MPS)
    assert config.margin_m == ExpertConfig.styled("wide").margin_m  # the base's other fields
    assert (config.lateral_accel_mps2, config.preview_m, config.near_lethal_mps) == (0.8, 2.0, None)
    table = config.speed_table(CLASSES)  # mud named; rock, water by rank after mud
    np.testing.assert_allclose(table[[GRASS, MUD, ROCK, WATER]], [1.6, 0.5, 0.8, 0.6])


def test_a_style_file_without_a_base_starts_from_the_default_driver(tmp_path):
    base, changes = read_style_file(_style_file(tmp_path, "preview_m: 4.5\n"))
    assert (base, changes) == ("default", {"preview_m": 4.5})


@pytest.mark.parametrize(
    ("text", "field"),
    [
        ("top_speed: 1.0\n", "top_speed"),
        ("base: nosuch\n", "base"),
        ("speeds: [grass, 1.5]\n", "speeds"),
        ("speeds: {grass: fast}\n", "speeds.grass"),
        ("speeds: {grass: true}\n", "speeds.grass"),
        ("speeds: {grass: .nan}\n", "speeds.grass"),
        ("speeds: {grass: -1}\n", "speeds.grass"),
        ("lateral_accel_mps2: -1\n", "lateral_accel_mps2"),
        ("preview_m: -3\n", "preview_m"),
        ("near_lethal_m: -1\n", "near_lethal_m"),
        ("speeds: {1: 1.0}\n", "speeds"),
        ("preview_m: '3'\n", "preview_m"),
        ("preview_m: null\n", "preview_m"),
        ("near_lethal_m: yes\n", "near_lethal_m"),
        ("lateral_accel_mps2: [1]\n", "lateral_accel_mps2"),
        ("speed_mps: true\n", "speed_mps"),
        ("ranked_speeds_mps: [1.0]\n", "ranked_speeds_mps"),
        ("ranked_speeds_mps: [1.0, slow]\n", "ranked_speeds_mps[1]"),
        ("ranked_speeds_mps: {fast: 1.0, slow: 0.5}\n", "ranked_speeds_mps"),
        # past what a float holds, and not finite: named here, not an internal error or another field's message
        ("speeds: {grass: 1" + "0" * 400 + "}\n", "speeds.grass"),
        ("ranked_speeds_mps: [1" + "0" * 400 + ", 0.5]\n", "ranked_speeds_mps[0]"),
        ("preview_m: 1" + "0" * 400 + "\n", "preview_m"),
        ("near_lethal_mps: .nan\n", "near_lethal_mps"),
    ],
)
def test_a_bad_style_file_is_a_user_error_naming_the_file_and_field(tmp_path, text: str, field: str):
    path = _style_file(tmp_path, text)
    with pytest.raises(UserError) as err:
        read_style_file(path)
    assert err.value.source == str(path)
    assert [p.field for p in err.value.problems] == [field]
    with pytest.raises(UserError) as err:  # as the command line reaches it
        driver_style(str(path), CLASSES.profile, CLASSES, TOP_SPEED_MPS)
    assert err.value.source == str(path)


def test_a_style_file_of_another_format_is_refused(tmp_path):
    path = tmp_path / "style.yaml"
    path.write_text("format: terrapref-scenario/1\npreview_m: 2\n")
    with pytest.raises(UserError) as err:
        read_style_file(path)
    assert err.value.source == str(path) and "terrapref-driver-style/1" in str(err.value)


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("speeds: {mud: 0}\n", ["speeds.mud", "> 0"]),
        ("preview_m: 0\n", ["preview_m"]),
        ("speeds: {gravel: 1.0}\n", ["'gravel'"]),
        ("speeds: {grass: 2.5}\n", ["2.5 m/s", "2 m/s"]),
        ("speed_mps: 2.5\n", ["speed_mps:", "2.5 m/s"]),
        ("near_lethal_mps: 50\n", ["near_lethal_mps:", "50 m/s", "top speed"]),  # a cap it would never reach
        ("ranked_speeds_mps: [2.5, 1.0]\n", ["2.5 m/s"]),
        ("speeds: {non_traversable: 0.5}\n", ["speeds:", "'non_traversable'", "lethal"]),
        ("speeds: {mud: 0.05}\n", ["speeds:", "'mud'", "0.1 m/s"]),
        ("ranked_speeds_mps: [1.0, 0.05]\n", ["ranked_speeds_mps:", "0.05 m/s"]),
        ("speed_mps: 0.01\n", ["speed_mps:", "'grass'", "0.01 m/s"]),
        ("near_lethal_mps: 0.02\n", ["near_lethal_mps:", "0.02 m/s"]),
    ],
)
def test_a_style_file_the_driver_or_the_vehicle_cannot_take_is_refused_naming_the_file(tmp_path, text: str, words: list[str]):
    path = _style_file(tmp_path, text)
    with pytest.raises(UserError) as err:
        driver_style(str(path), CLASSES.profile, CLASSES, TOP_SPEED_MPS)
    assert err.value.source == str(path)
    assert all(w in str(err.value) for w in words), str(err.value)


@pytest.mark.parametrize(
    ("speeds", "words"),
    [
        ((("grass", 2.5),), ["2.5 m/s", "above the vehicle's 2 m/s"]),
        ((("mud", 2.01),), ["2.01 m/s"]),
        ((("nosuch", 1.0),), ["'nosuch'", "not in the class table"]),
        ((("grass", 0.0),), ["cruising speeds"]),
        ((("grass", 1e-9),), ["'grass'", "below 0.1 m/s"]),
        ((("non_traversable", 0.4),), ["'non_traversable'", "lethal"]),
    ],
)
def test_speeds_the_vehicle_or_the_table_cannot_take_blame_the_flag(tmp_path, speeds, words: list[str]):
    for style in ("default", str(_style_file(tmp_path, "lateral_accel_mps2: 0.8\n"))):
        with pytest.raises(UserError) as err:
            driver_style(style, CLASSES.profile, CLASSES, TOP_SPEED_MPS, {"speeds": speeds})
        assert err.value.source == "--speeds", style
        assert all(w in str(err.value) for w in words), str(err.value)


def test_the_top_speed_itself_is_allowed_and_flags_win_over_the_file(tmp_path):
    path = _style_file(tmp_path, "preview_m: 2\nlateral_accel_mps2: 0.8\n")
    config = driver_style(str(path), CLASSES.profile, CLASSES, TOP_SPEED_MPS, {"speeds": (("grass", 2.0),), "preview_m": 5.0})
    assert config.speeds == (("grass", 2.0),) and config.preview_m == 5.0 and config.lateral_accel_mps2 == 0.8
    with pytest.raises(UserError) as err:
        driver_style(str(path), CLASSES.profile, CLASSES, TOP_SPEED_MPS, {"lateral_accel_mps2": -1.0})
    assert err.value.source == "--lateral-accel"


def test_a_speeds_flag_keeps_the_style_files_speeds_for_other_classes(tmp_path):
    path = _style_file(tmp_path, "speeds: {mud: 0.5}\n")
    config = driver_style(str(path), CLASSES.profile, CLASSES, TOP_SPEED_MPS, {"speeds": (("grass", 1.2),)})
    table = config.speed_table(CLASSES)
    assert table[GRASS] == 1.2
    assert table[MUD] == 0.5


# --- terrapref record ---------------------------------------------------------------------------


@pytest.fixture
def tiny_scenario(tmp_path) -> Path:
    """12 m along y = 3 over grass, with 1.5 m of mud across the map at x = 7.25 to 8.75."""
    path = tmp_path / "tiny.yaml"
    data = {
        "format": "terrapref-scenario/1",
        "name": "tiny_speeds",
        "world": {"size_m": [14.0, 6.0], "resolution_m": 0.05, "background": "grass"},
        "terrain": [{"class": "mud", "rectangle": {"center": [8.0, 3.0], "size": [1.5, 6.0]}}],
        "path": {"waypoints": [[1.0, 3.0], [13.0, 3.0]]},
    }
    path.write_text(yaml.safe_dump(data))
    return path


def test_record_with_speeds_drives_at_them(tmp_path, tiny_scenario, capsys):
    out = tmp_path / "rec"
    assert main(["record", str(tiny_scenario), "--speeds", "grass=1.2", "--out", str(out), "--quiet", "--disturb", "0"]) == 0
    assert "wrote" in capsys.readouterr().out
    rec = read_recording(out)
    assert rec.complete
    assert rec.meta["driver"]["config"]["speeds"] == [["grass", 1.2]]
    v = rec.commands[:, 0]
    # 1.2 m/s on grass; the default style's 1 m/s for mud, from 3 m before it.
    assert v.max() == 1.2 and set(np.unique(v)) == {1.0, 1.2}
    x = rec.poses[:, 0]
    np.testing.assert_array_equal(v[x < 4.0], 1.2)
    np.testing.assert_array_equal(v[(x >= 7.25) & (x <= 8.5)], 1.0)


@pytest.mark.parametrize(
    ("flags", "words"),
    [
        (["--speeds", "nosuch=1"], ["--speeds", "'nosuch'"]),
        (["--speeds", "grass=3"], ["--speeds", "3 m/s", "2 m/s"]),
        (["--speeds", "grass"], ["--speeds", "CLASS=SPEED"]),
        (["--speeds", "grass=1,grass=2"], ["--speeds", "twice"]),
        (["--speeds", "grass=0"], ["--speeds"]),
        (["--speeds", "grass=1e-9"], ["--speeds", "'grass'", "1e-09 m/s", "0.1 m/s"]),  # a vehicle that never moves
        (["--speeds", "mud=0.05"], ["--speeds", "'mud'", "0.05 m/s", "0.1 m/s"]),
        (["--speeds", "non_traversable=0.5"], ["--speeds", "'non_traversable'", "lethal"]),
    ],
)
def test_record_refuses_bad_speed_flags_in_one_line(tmp_path, tiny_scenario, capsys, flags: list[str], words: list[str]):
    out = tmp_path / "rec"
    assert main(["record", str(tiny_scenario), *flags, "--out", str(out), "--quiet"]) == 2
    one_line_error(capsys, *words)
    assert not out.exists()


def test_record_refuses_a_bad_style_file_in_one_line(tmp_path, tiny_scenario, capsys):
    style = _style_file(tmp_path, "speeds: {grass: 1.2}\nturbo: true\n")
    out = tmp_path / "rec"
    assert main(["record", str(tiny_scenario), "--style", str(style), "--out", str(out), "--quiet"]) == 2
    one_line_error(capsys, str(style), "turbo")
    assert not out.exists()
