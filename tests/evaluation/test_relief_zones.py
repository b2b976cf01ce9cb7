"""Relief zones (terrapref.evaluation.scoring.relief_zones): the stretches of a path whose own
ground would tilt the body past 4 deg, and how a run passed each (over it, or round it on one
side), against closed-form answers; ``evaluate``'s agreement with the driver on them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from terrapref.evaluation.runner import EXPERT, RunResult, annotate_agreement
from terrapref.evaluation.scoring import NOT_REACHED, RELIEF_SIDE_M, RELIEF_ZONE_DEG, ReliefZoneResult, relief_zones, score_relief_zones
from terrapref.scenario import parse_scenario
from terrapref.scenario.path import ReferencePath
from terrapref.world import rasterise

# A straight path along y = 10 m; a mound of radius 3 m on it at x = 20 m, its flanks pitching a
# body heading along the path by up to 12.5 deg (0.5 m high: atan(0.5 sin(pi/6) / 1)).
MOUND = {"mound": {"center": [20.0, 10.0], "radius": 3.0, "height_m": 0.5}}


def _scenario(relief: list[dict]):
    data = {
        "format": "terrapref-scenario/1",
        "name": "relief_zones",
        "world": {"size_m": [40.0, 20.0], "resolution_m": 0.05, "background": "grass"},
        "terrain": [],
        "path": {"waypoints": [[2.0, 10.0], [38.0, 10.0]]},
    }
    if relief:
        data["relief"] = relief
    return parse_scenario(data)


def test_a_mound_on_the_path_is_one_relief_zone_where_its_flanks_tilt_the_body_past_4_deg():
    """The cosine mound pitches a body of 1 m wheelbase heading through its centre by
    atan(0.25 (cos(pi (r - 0.5) / 3) - cos(pi (r + 0.5) / 3))) at r m from it: past 4 deg from
    r = 0.46 m to 2.73 m on either side; the flat top between is shorter than the 5 m that joins
    the two flanks into one zone."""
    scenario = _scenario([MOUND])
    path = ReferencePath(scenario.waypoints)
    zones = relief_zones(path, rasterise(scenario))
    r = np.linspace(0.0, 3.5, 3501)
    pitch = np.degrees(np.arctan(0.25 * (np.cos(np.pi * np.clip(r - 0.5, 0, 3) / 3) - np.cos(np.pi * np.clip(r + 0.5, 0, 3) / 3))))
    past = r[pitch > RELIEF_ZONE_DEG]
    assert len(zones) == 1
    (s0, s1) = zones[0]
    centre_s = 18.0  # the mound's centre along the path
    assert s0 == pytest.approx(centre_s - past.max(), abs=0.3) and s1 == pytest.approx(centre_s + past.max(), abs=0.3)
    assert relief_zones(path, rasterise(_scenario([]))) == []  # flat ground: none


def test_a_bump_under_one_side_that_tilts_the_body_past_4_deg_for_a_single_read_is_no_relief_zone():
    """A knob 0.2 m across and 0.15 m high under the left wheels' line rolls the body past 4 deg
    only while its centre line passes it (a tenth of a metre): one read of the path's, every
    0.25 m, a zone of no length that every run would pass alike. Zones are at least 1 m long
    (RELIEF_MIN_M); the same knob twice as wide, 0.25 m high, tilts it past 4 deg over a longer stretch and is one."""
    from terrapref.evaluation.scoring import RELIEF_MIN_M, RELIEF_STEP_M
    from terrapref.vehicle import VehicleConfig

    left = 10.0 + VehicleConfig().half_width_m
    knob = _scenario([{"mound": {"center": [20.0, left], "radius": 0.1, "height_m": 0.15}}])
    path = ReferencePath(knob.waypoints)
    assert relief_zones(path, rasterise(knob)) == [] and RELIEF_MIN_M >= 4 * RELIEF_STEP_M
    wider = _scenario([{"mound": {"center": [20.0, left], "radius": 1.0, "height_m": 0.25}}])
    ((s0, s1),) = relief_zones(path, rasterise(wider))
    assert s1 - s0 >= RELIEF_MIN_M and s0 < 18.0 < s1  # 18 m along: the knob's centre


@pytest.mark.parametrize(("lateral", "choice"), [(0.0, "over"), (0.4, "over"), (1.5, "left"), (-2.0, "right")])
def test_a_run_passes_a_relief_zone_over_it_or_round_it_by_its_mean_offset(lateral, choice):
    scenario = _scenario([MOUND])
    path = ReferencePath(scenario.waypoints)
    zones = relief_zones(path, rasterise(scenario))
    x = np.arange(2.0, 38.0, 0.05)
    # On the path, then held ``lateral`` left of it from 4 m before the zone to 4 m after it.
    s = x - 2.0
    held = (s > zones[0][0] - 4.0) & (s < zones[0][1] + 4.0)
    xy = np.stack([x, 10.0 + np.where(held, lateral, 0.0)], axis=1)
    (result,) = score_relief_zones(xy, path, zones, progress_m=path.length_m)
    assert result.choice == choice and result.offset_m == pytest.approx(lateral, abs=1e-6)
    assert abs(lateral) <= RELIEF_SIDE_M or choice != "over"
    (short,) = score_relief_zones(xy[x < 17.0], path, zones, progress_m=15.0)
    assert short.choice == NOT_REACHED and short.offset_m is None


def test_the_planner_agrees_on_a_relief_zone_when_it_made_the_drivers_choice():
    """``annotate_agreement`` compares each relief zone's choice with the driver's run of the same
    scenario and seed, and ``metrics.json`` carries both."""
    from dataclasses import replace

    from terrapref.evaluation.scoring import RunMetrics

    def run(driver: str, choices: list[str]) -> RunResult:
        zones = [
            ReliefZoneResult(10.0 * k, 10.0 * k + 3.0, c, 0.0 if c == "over" else math.copysign(1.0, k - 0.5))
            for k, c in enumerate(choices)
        ]
        metrics = RunMetrics(True, 0, 10.0, 0.0, 0.0, 0.0, {}, relief_zones=zones)
        return RunResult("s", 0, driver, metrics, np.zeros((0, 2), np.float32))

    driver, planner = run(EXPERT, ["over", "left"]), run("planner", ["over", "right"])
    planner = annotate_agreement([driver, planner])[1]
    assert [a.agrees for a in planner.relief_agreement] == [True, False]
    written = planner.metrics_dict()["relief_zones"]
    assert [(z["choice"], z["driver_choice"], z["agrees"]) for z in written] == [("over", "over", True), ("right", "left", False)]
    flat = replace(planner.metrics, relief_zones=None)
    assert "relief_zones" not in flat.to_dict()  # flat runs' metrics as they were
