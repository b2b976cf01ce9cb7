"""Rates with intervals (SPEC 12) and the planner's agreement with the synthetic driver: the Wilson
interval against its closed form, and zone agreement and summaries over hand-built run results."""

from __future__ import annotations

import math

import numpy as np
import pytest

from terrapref.evaluation.runner import EXPERT, PLANNER, PURE_PURSUIT, RunResult, annotate_agreement, summarise, zone_agrees
from terrapref.evaluation.scoring import RunMetrics, ZoneResult
from terrapref.evaluation.stats import cluster_bootstrap, rate_text, wilson

Z = 1.96


def _wilson_by_hand(k: int, n: int) -> tuple[float, float]:
    """The textbook form: (p + z^2/2n -+ z sqrt(p(1 - p)/n + z^2/4n^2)) / (1 + z^2/n)."""
    p = k / n
    root = Z * math.sqrt(p * (1 - p) / n + Z**2 / (4 * n**2))
    return (p + Z**2 / (2 * n) - root) / (1 + Z**2 / n), (p + Z**2 / (2 * n) + root) / (1 + Z**2 / n)


# --- the Wilson interval ---------------------------------------------------------------------------


def test_wilson_72_of_75():
    lo, hi = wilson(72, 75)
    assert (lo, hi) == pytest.approx(_wilson_by_hand(72, 75), abs=1e-12)
    assert (round(lo, 4), round(hi, 4)) == (0.8889, 0.9863)
    assert lo < 72 / 75 < hi


@pytest.mark.parametrize("k, n", [(1, 2), (3, 10), (50, 100), (99, 100), (7, 1000)])
def test_wilson_is_the_closed_form(k: int, n: int):
    assert wilson(k, n) == pytest.approx(_wilson_by_hand(k, n), abs=1e-12)


@pytest.mark.parametrize("n", [1, 5, 10, 75, 1000])
def test_wilson_at_none_and_all_stays_inside_zero_one(n: int):
    """At 0/n the interval is [0, z^2/(n + z^2)]; at n/n it is [n/(n + z^2), 1]."""
    lo, hi = wilson(0, n)
    assert lo == pytest.approx(0.0, abs=1e-15) and lo >= 0.0
    assert hi == pytest.approx(Z**2 / (n + Z**2), abs=1e-12)
    lo, hi = wilson(n, n)
    assert hi == pytest.approx(1.0, abs=1e-15) and hi <= 1.0
    assert lo == pytest.approx(n / (n + Z**2), abs=1e-12)


@pytest.mark.parametrize("n", [0, -3])
def test_wilson_without_trials_is_the_whole_range(n: int):
    assert wilson(0, n) == (0.0, 1.0)


def test_wilson_narrows_as_trials_grow_at_the_same_rate():
    intervals = [wilson(8 * n, 10 * n) for n in (1, 10, 100, 1000)]
    widths = [hi - lo for lo, hi in intervals]
    assert widths == sorted(widths, reverse=True) and len(set(widths)) == 4
    assert all(lo < 0.8 < hi for lo, hi in intervals)
    assert widths[-1] < 0.05 < 0.4 < widths[0]


def test_wilson_z_sets_the_confidence():
    assert wilson(3, 4, z=0.0) == (0.75, 0.75)
    lo90, hi90 = wilson(30, 40, z=1.645)
    lo95, hi95 = wilson(30, 40)
    assert lo95 < lo90 < 0.75 < hi90 < hi95


def test_rate_text():
    # Both bounds carry a percent sign (the docstring's example writes "88.9-98.6%").
    assert rate_text(72, 75) == "96.0% (72/75, 95% CI 88.9%-98.6%)"
    assert rate_text(5, 5) == "100.0% (5/5, 95% CI 56.6%-100.0%)"  # 5 / (5 + 1.96^2) = 56.55%
    assert rate_text(0, 4) == "0.0% (0/4, 95% CI 0.0%-49.0%)"  # 1.96^2 / (4 + 1.96^2) = 48.99%
    assert rate_text(0, 0) == "- (0 zones)"


# --- agreement with the synthetic driver -------------------------------------------------------------


def _zone(id: str, choice: str, success: bool = True, touched_lethal: bool = False) -> ZoneResult:
    """A scored zone, expected ``choice`` when it succeeded and ``avoid`` otherwise."""
    return ZoneResult(id, id, choice if success else "avoid", choice, success, touched_lethal, {})


def _run(
    scenario: str, seed: int, driver: str, zones: list[ZoneResult], collisions: int = 0, completed: bool = True, rms: float = 0.1
) -> RunResult:
    """A result as ``run_one`` returns it, with an empty path."""
    metrics = RunMetrics(completed, collisions, 60.0, rms, 2 * rms, rms, {}, zones)
    return RunResult(scenario, seed, driver, metrics, np.zeros((0, 2), np.float32))


@pytest.mark.parametrize(
    "planner, driver, agrees",
    [
        (("mud", False), ("mud", False), True),
        (("mud", False), ("rock", False), False),
        (("avoid", False), ("avoid", False), True),
        (("avoid", False), ("mud", False), False),
        (("mud", True), ("mud", False), False),  # the same choice, but the planner touched lethal terrain
        (("mud", True), ("mud", True), True),  # so did the driver
        (("mud", False), ("mud", True), True),  # only the driver did
    ],
)
def test_zone_agrees(planner: tuple[str, bool], driver: tuple[str, bool], agrees: bool):
    assert zone_agrees(_zone("z", *planner[:1], touched_lethal=planner[1]), _zone("z", *driver[:1], touched_lethal=driver[1])) is agrees


@pytest.fixture
def results() -> list[RunResult]:
    return [
        _run("course", 0, EXPERT, [_zone("a", "mud"), _zone("b", "rock"), _zone("c", "avoid")]),
        # The driver's zones in another order: matched by id.
        _run(
            "course",
            0,
            PLANNER,
            [_zone("c", "avoid"), _zone("a", "mud", success=False, touched_lethal=True), _zone("b", "water", success=False)],
            collisions=1,
            rms=0.3,
        ),
        _run("course", 1, PLANNER, [_zone("a", "mud"), _zone("b", "rock"), _zone("c", "avoid")], rms=0.5),  # no driver run
        _run("other", 0, PLANNER, [_zone("x", "mud", success=False)], completed=False, rms=0.7),  # no driver run
        _run("course", 0, PURE_PURSUIT, [_zone("a", "avoid", success=False), _zone("b", "rock"), _zone("c", "avoid")]),
    ]


def _agreement(r: RunResult) -> dict[str, tuple[str, bool]]:
    """Zone id -> (the driver's choice, agreed)."""
    assert r.agreement is not None
    return {z.id: (a.driver_choice, a.agrees) for z, a in zip(r.metrics.zones, r.agreement, strict=True)}


def test_annotate_agreement_gives_planner_zones_the_drivers_choice(results: list[RunResult]):
    annotated = annotate_agreement(results)
    assert _agreement(annotated[1]) == {
        "a": ("mud", False),  # the same choice, but lethal terrain touched where the driver touched none
        "b": ("rock", False),
        "c": ("avoid", True),
    }
    assert list(_agreement(annotated[4]).values()) == [("mud", False), ("rock", True), ("avoid", True)]
    assert all(r.agreement is None for r in results)  # the results given are left as they were


def test_annotate_agreement_leaves_runs_without_a_driver_run_and_the_driver_alone(results: list[RunResult]):
    annotated = annotate_agreement(results)
    for before, r in zip(results, annotated, strict=True):
        if r.driver == EXPERT or r.seed == 1 or r.scenario == "other":
            assert r is before and r.agreement is None, (r.scenario, r.seed, r.driver)
            assert "driver_choice" not in r.zone_dicts()[0] and "agrees" not in r.zone_dicts()[0]


def test_annotated_zones_are_written_with_the_drivers_choice(results: list[RunResult]):
    zones = annotate_agreement(results)[1].to_dict()["metrics"]["zones"]
    assert list(zones[1]) == [
        "id",
        "label",
        "expect",
        "choice",
        "success",
        "touched_lethal",
        "distance_m",
        "clearance_m",
        "reached",
        "speed_mps",
        "driver_choice",
        "agrees",
    ]
    assert (zones[1]["driver_choice"], zones[1]["agrees"]) == ("mud", False)


def test_summarise_the_planner(results: list[RunResult]):
    s = summarise(annotate_agreement(results), PLANNER).to_dict()
    assert s == {
        "runs": 3,
        "zones": 7,
        "zone_success_rate": round(4 / 7, 4),
        "zone_success_ci95": [round(v, 4) for v in _wilson_by_hand(4, 7)],
        "agreement_rate": round(1 / 3, 4),  # only the run with a driver run is compared
        "agreement_ci95": [round(v, 4) for v in _wilson_by_hand(1, 3)],
        "agreement_zones": 3,
        "collision_count": 1,
        "tip_count": 0,
        "stuck_count": 0,
        "max_roll_deg": 0.0,
        "max_pitch_deg": 0.0,
        "completed_rate": round(2 / 3, 4),
        "completed_ci95": [round(v, 4) for v in _wilson_by_hand(2, 3)],
        "ended": {"goal": 2, "time limit": 1},
        "not_reached": 0,
        "contact_s": 0.0,
        "driven_m": 0.0,
        "stop_count": 0,
        "stops_per_100m": None,
        "stops_s": {},
        "mean_rms_cross_track_m": 0.5,
    }


def test_summarise_the_driver_has_no_agreement(results: list[RunResult]):
    s = summarise(annotate_agreement(results), EXPERT).to_dict()
    assert (s["runs"], s["zones"], s["zone_success_rate"], s["collision_count"], s["completed_rate"]) == (1, 3, 1.0, 0, 1.0)
    assert s["zone_success_ci95"] == [round(_wilson_by_hand(3, 3)[0], 4), 1.0]
    assert not {"agreement_rate", "agreement_ci95", "agreement_zones"} & set(s)


def test_summarise_without_annotation_has_no_agreement(results: list[RunResult]):
    assert "agreement_rate" not in summarise(results, PLANNER).to_dict()


def test_summarise_a_driver_with_no_runs():
    s = summarise([_run("course", 0, EXPERT, [_zone("a", "mud")])], PLANNER).to_dict()
    assert s == {
        "runs": 0,
        "zones": 0,
        "zone_success_rate": None,
        "zone_success_ci95": [0.0, 1.0],
        "collision_count": 0,
        "tip_count": 0,
        "stuck_count": 0,
        "max_roll_deg": 0.0,
        "max_pitch_deg": 0.0,
        "completed_rate": None,
        "completed_ci95": [0.0, 1.0],
        "ended": {},
        "not_reached": 0,
        "contact_s": 0,
        "driven_m": 0,
        "stop_count": 0,
        "stops_per_100m": None,
        "stops_s": {},
        "mean_rms_cross_track_m": None,
    }


# --- the cluster bootstrap of a mean -------------------------------------------------------------


def test_cluster_bootstrap_of_identical_groups_is_exact():
    mean, lo, hi = cluster_bootstrap([[0.2], [0.2, 0.2], [0.2]])
    assert (mean, lo, hi) == pytest.approx((0.2, 0.2, 0.2))


def test_cluster_bootstrap_pools_values_and_brackets_the_mean():
    groups = [[1.0, 1.0], [0.0], [2.0, 0.0, 1.0], [3.0]]
    mean, lo, hi = cluster_bootstrap(groups)
    assert mean == pytest.approx(8.0 / 7.0)  # every value counts once, not every group
    assert 0.0 <= lo < mean < hi <= 3.0


def test_cluster_bootstrap_resamples_groups_not_values():
    """Ten groups of alike values: the interval is as wide as ten draws allow, not as narrow as 1,000 values would make it."""
    groups = [[float(k % 2)] * 100 for k in range(10)]
    _, lo, hi = cluster_bootstrap(groups)
    assert hi - lo > 0.4
    _, lo1, hi1 = cluster_bootstrap([[v] for g in groups for v in g])
    assert hi1 - lo1 < 0.1


def test_cluster_bootstrap_is_repeatable_and_seeded():
    groups = [[float(k)] for k in range(12)]
    assert cluster_bootstrap(groups) == cluster_bootstrap(groups)
    assert cluster_bootstrap(groups, seed=1) != cluster_bootstrap(groups)


def test_cluster_bootstrap_of_nothing_is_nan():
    assert all(math.isnan(v) for v in cluster_bootstrap([[], []]))


def test_a_zone_the_driver_did_not_reach_is_not_compared():
    """The driver stuck short of two zones: the planner's choices there were counted as
    disagreements (or, where it did not reach them either, agreements), in the summary, the zones
    written and select's rows."""
    from dataclasses import replace

    from terrapref.evaluation.scoring import NOT_REACHED
    from terrapref.report.select import layout_interval

    def short(id: str) -> ZoneResult:
        return replace(_zone(id, NOT_REACHED, success=False), choice=NOT_REACHED, reached=False)

    driver = _run("course", 0, EXPERT, [_zone("a", "mud"), short("b"), short("c")])
    planner = _run("course", 0, PLANNER, [_zone("a", "mud"), _zone("b", "rock"), short("c")])
    annotated = annotate_agreement([driver, planner])
    s = summarise(annotated, PLANNER)
    assert (s.agreement_zones, s.agreement_rate) == (1, 1.0)
    zones = annotated[1].to_dict()["metrics"]["zones"]
    assert ["agrees" in z for z in zones] == [True, False, False] and zones[1]["driver_choice"] == NOT_REACHED
    rows = [{"scenario": "course", "agrees": a} for a in (True, None, None)]
    assert layout_interval(rows)[0] == 1.0
