"""Speed by grade band on relief (SPEC 19): each run's mean speed going up, going down and on the
level (the body's pitch past 3 deg), each zone's band, and ``evaluate``'s speed error against the
driver by band; and likewise by roughness band (rough past 0.015 m, smooth); flat runs' metrics as
they were."""

from __future__ import annotations

import math

import numpy as np
import pytest

from terrapref.demos.expert import ExpertConfig, ExpertDriver
from terrapref.demos.relief_style import ReliefStyle
from terrapref.evaluation import score_run
from terrapref.evaluation.scoring import GRADE_BAND_DEG, ROUGH_BAND_M, grade_band
from terrapref.evaluation.speed import SpeedComparison
from terrapref.scenario import parse_scenario
from terrapref.sim import Simulation, run_episode
from terrapref.terrain import PreferenceProfile

# A plateau 1 m up east of x = 20, its ramp 6 m wide (x = 14 to 20): 9.46 deg; a zone on the ramp.
RAMP = [{"plateau": {"polygon": [[20.0, -10.0], [60.0, -10.0], [60.0, 30.0], [20.0, 30.0]], "height_m": 1.0, "edge_m": 6.0}}]
ZONE = {"id": "1", "label": "on the ramp", "rectangle": {"center": [17.0, 10.0], "size": [4.0, 6.0]}, "expect": "best"}


def _run(relief: list[dict], waypoints: list[list[float]]):
    data = {
        "format": "terrapref-scenario/1",
        "name": "grades",
        "world": {"size_m": [40.0, 20.0], "resolution_m": 0.05, "background": "grass"},
        "terrain": [],
        "zones": [ZONE],
        "path": {"waypoints": waypoints},
    }
    if relief:
        data["relief"] = relief
    scenario = parse_scenario(data)
    sim = Simulation(scenario)
    log = run_episode(sim, ExpertDriver(ExpertConfig(relief=ReliefStyle())), np.random.default_rng(0))
    return score_run(log, scenario, sim.world, PreferenceProfile.default())


def test_the_bands_split_at_3_deg():
    assert GRADE_BAND_DEG == 3.0
    assert [grade_band(math.radians(d)) for d in (9.5, 3.1, 2.9, 0.0, -2.9, -3.1)] == ["up", "up", "level", "level", "level", "down"]


@pytest.mark.parametrize(
    ("waypoints", "band", "other"), [([[2.0, 10.0], [38.0, 10.0]], "up", "down"), ([[38.0, 10.0], [2.0, 10.0]], "down", "up")]
)
def test_a_ramp_driven_is_timed_in_its_band_and_its_zone_says_so(waypoints, band, other):
    """Up (or down) the 6 m ramp: the ground where the body pitches past 3 deg is the ramp and the
    third of a metre either end of it where the wheels straddle its edge (a 1 m wheelbase over a
    9.46 deg kink: past 3 deg from 0.32 m before it), so the band's metres are 6.0-7.0; the rest
    is level."""
    metrics = _run(RAMP, waypoints)
    bands = metrics.speed_by_grade_mps
    assert set(bands) == {band, "level"} and other not in bands
    assert 6.0 < bands[band]["mps"] * bands[band]["s"] < 7.0
    total = sum(v["mps"] * v["s"] for v in bands.values())
    assert total == pytest.approx(metrics.driven_m, rel=1e-3)
    assert bands[band]["mps"] < bands["level"]["mps"]  # the driver's relief style slows on it
    assert [z.grade_band for z in metrics.zones] == [band] and "grade_band" in metrics.zones[0].to_dict()


def test_on_flat_ground_there_are_no_bands_and_the_metrics_read_as_before():
    metrics = _run([], [[2.0, 10.0], [38.0, 10.0]])
    assert metrics.speed_by_grade_mps is None and metrics.zones[0].grade_band is None and metrics.speed_by_roughness_mps is None
    assert "speed_by_grade_mps" not in metrics.to_dict() and "grade_band" not in metrics.zones[0].to_dict()
    assert "speed_by_roughness_mps" not in metrics.to_dict()


def test_a_rough_patch_driven_is_timed_in_the_rough_band_at_the_drivers_speed_there():
    """A rough patch 10 m long (x = 15 to 25) across the way: the driver's relief style holds
    0.8 m/s past 0.015 m there and 1 m/s on the smooth ground before and after it."""
    assert ROUGH_BAND_M == ReliefStyle().rough_m == 0.015 and ReliefStyle().rough_mps == 0.8
    patch = [[15.0, 4.0], [25.0, 4.0], [25.0, 16.0], [15.0, 16.0]]
    metrics = _run([{"noise": {"amplitude_m": 0.07, "wavelength_m": 0.3, "seed": 1, "polygon": patch}}], [[2.0, 10.0], [38.0, 10.0]])
    bands = metrics.speed_by_roughness_mps
    assert set(bands) == {"rough", "smooth"} and 5.0 < bands["rough"]["mps"] * bands["rough"]["s"] < 10.0
    assert sum(v["mps"] * v["s"] for v in bands.values()) == pytest.approx(metrics.driven_m, rel=1e-3)
    assert bands["rough"]["mps"] < 0.82 and bands["smooth"]["mps"] > 0.9


def test_the_speed_error_by_band_compares_the_runs_on_the_same_layout():
    def row(scenario: str, mine: dict, theirs: dict) -> dict:
        return {"scenario": scenario, "speed_by_grade_mps": mine, "driver_speed_by_grade_mps": theirs}

    runs = [
        row(
            "a",
            {"up": {"mps": 0.7, "s": 9.0}, "level": {"mps": 1.0, "s": 30.0}},
            {"up": {"mps": 0.8, "s": 8.0}, "level": {"mps": 1.0, "s": 30.0}},
        ),
        row("b", {"up": {"mps": 0.9, "s": 5.0}}, {"up": {"mps": 0.8, "s": 5.0}, "down": {"mps": 0.9, "s": 4.0}}),
        row("c", {"up": {"mps": 0.5, "s": 0.5}}, {"up": {"mps": 0.8, "s": 5.0}}),  # under a second on it: not compared
        # A driver stuck against a ledge for 200 s: its level speed says how long it stood; not compared.
        {
            **row("d", {"level": {"mps": 1.1, "s": 40.0}}, {"level": {"mps": 0.07, "s": 226.0}}),
            "completed": True,
            "driver_completed": False,
        },
    ]
    comparison = SpeedComparison.of([], runs, "grass")
    assert set(comparison.by_grade) == {"up", "level"}
    assert comparison.by_grade["up"].mean == pytest.approx(0.1) and comparison.by_grade["up"].n == 2
    assert comparison.by_grade["level"].mean == 0.0
    again = SpeedComparison.from_dict(comparison.to_dict())
    assert again.by_grade == comparison.by_grade and any("going up" in line for line in comparison.lines())
    assert "by_grade" not in SpeedComparison.of([], [], "grass").to_dict()  # flat: as before
    rough = [
        {
            "scenario": "a",
            "speed_by_roughness_mps": {"rough": {"mps": 0.7, "s": 4.0}},
            "driver_speed_by_roughness_mps": {"rough": {"mps": 0.8, "s": 5.0}},
        }
    ]
    comparison = SpeedComparison.of([], rough, "grass")
    assert set(comparison.by_roughness) == {"rough"} and comparison.by_roughness["rough"].mean == pytest.approx(0.1)
    assert SpeedComparison.from_dict(comparison.to_dict()).by_roughness == comparison.by_roughness
    assert any(line.startswith("speed error against the driver, rough ground (roughness past 0.015 m)") for line in comparison.lines())
    assert "by_roughness" not in SpeedComparison.of([], [], "grass").to_dict()


def test_on_relief_the_speed_figure_has_a_panel_of_the_ground_height_under_each_run(tmp_path):
    """The driver's and the planner's runs up the ramp: speed above, the ground's height under
    each below (a taller figure than a flat course's, which has no height panel)."""
    from types import SimpleNamespace

    from matplotlib.image import imread
    from test_relief_zones import _scenario as scenario  # a straight path along y = 10 m, 40 x 20 m

    from terrapref.evaluation.runner import EXPERT, PLANNER
    from terrapref.evaluation.speed import RUN_XY_STEP_S, save_speed_along

    x = np.arange(2.0, 38.0, 1.0 * RUN_XY_STEP_S)
    runs = [
        SimpleNamespace(driver=who, scenario="grades", seed=0, xy=np.stack([x, np.full_like(x, 10.0)], axis=1)) for who in (EXPERT, PLANNER)
    ]
    hilly = save_speed_along(tmp_path / "hilly.png", runs, scenario(RAMP), "grades")
    flat = save_speed_along(tmp_path / "flat.png", runs, scenario([]), "grades")
    assert imread(hilly).shape[0] > 1.4 * imread(flat).shape[0]
