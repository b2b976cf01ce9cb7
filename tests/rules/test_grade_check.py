"""The speed rule's check of the grades it read ahead against the body's pitch once there
(terrapref.rules.speed.calibration), in closed form."""

from __future__ import annotations

import math

import numpy as np
import pytest

from terrapref.rules.speed.calibration import FADE, PRIOR, PRIOR_SPREAD_DEG2, GradeCheck


def _drive_along(check: GradeCheck, bias_deg: float, decisions: int, true_deg: float = 5.0) -> None:
    """A vehicle on a straight way along x, 0.25 m a decision (one station): it reads every station
    of its way ``bias_deg`` steeper than the ``true_deg`` its body then has there."""
    stations = check.stations
    for i in range(decisions):
        x = 0.25 * i
        points = np.stack([x + 0.25 * np.arange(stations), np.zeros(stations)], axis=1)
        check.keep(points, np.zeros(stations), np.full(stations, true_deg + bias_deg))
        check.arrived(x, 0.0, 0.0, true_deg)


def test_a_station_read_steeper_than_the_body_then_was_is_corrected_by_the_mean_error_shrunk():
    check = GradeCheck(4)
    np.testing.assert_array_equal(check.corrected(np.full((4, 5), 7.0)), 7.0)  # nothing checked: taken as read
    _drive_along(check, 2.0, 40)
    # Station s of decision i is checked at decision i + s (station 0 at once), once: 40 - s errors of 2 deg, faded.
    # The body's grade never varied (5 deg), so nothing tells a slope: only the mean error comes off.
    got = check.corrected(np.full((4, 5), 7.0))
    for s in range(4):
        n = 40 - s
        faded = sum(FADE**j for j in range(n))
        np.testing.assert_allclose(got[s], 7.0 - 2.0 * faded / (faded + PRIOR))
    check.reset()
    np.testing.assert_array_equal(check.corrected(np.full(4, 7.0)), 7.0)


def test_a_station_is_checked_only_where_the_vehicle_stands_heading_along_it():
    check = GradeCheck(1)
    check.keep(np.array([[1.0, 0.0]]), np.zeros(1), np.array([3.0]))
    check.arrived(1.0, 0.3, 0.0, 0.0)  # beside it
    check.arrived(1.0, 0.0, math.radians(45.0), 0.0)  # there, turned away
    assert check.corrected(np.array([3.0]))[0] == 3.0
    check.arrived(1.05, 0.0, 0.0, 1.0)  # there: 3 - 1 deg
    assert check.corrected(np.array([3.0]))[0] == pytest.approx(3.0 - 2.0 / (1.0 + PRIOR))
    check.arrived(1.0, 0.0, 0.0, 1.0)  # checked once
    assert check.corrected(np.array([3.0]))[0] == pytest.approx(3.0 - 2.0 / (1.0 + PRIOR))


def _check_pairs(check: GradeCheck, reads: np.ndarray, body: np.ndarray) -> None:
    """Check each read grade against the body's grade then, one station, one place after another along x."""
    for i, (r, b) in enumerate(zip(reads, body)):
        check.keep(np.array([[float(i), 0.0]]), np.zeros(1), np.array([r]))
        check.arrived(float(i), 0.0, 0.0, b)


def test_reads_twice_the_bodys_grade_are_taken_at_half_in_closed_form():
    body = np.array([-3.0, -1.0, 1.0, 3.0] * 50)  # a way that rises and falls, every read twice as steep
    check = GradeCheck(1)
    _check_pairs(check, 2.0 * body, body)
    w = FADE ** np.arange(len(body))[::-1]  # the last check weighs 1
    n, mean = w.sum(), np.sum(w * body) / w.sum()
    spread = np.sum(w * (body - mean) ** 2)  # of the body's grades; the reads' is four times it, their product twice
    prior = PRIOR * PRIOR_SPREAD_DEG2
    slope = (2.0 * spread + prior) / (4.0 * spread + prior)
    offset = n / (n + PRIOR) * (mean - slope * 2.0 * mean)
    assert check.line[1][0] == pytest.approx(slope, rel=1e-9) and 0.5 < slope < 0.52
    assert check.line[0][0] == pytest.approx(offset, abs=1e-9)
    assert check.corrected(np.array([6.0]))[0] == pytest.approx(offset + slope * 6.0)


def test_reads_scattered_about_the_truth_are_shrunk_toward_it_and_exact_ones_are_kept():
    rng = np.random.default_rng(3)
    body = rng.normal(0.0, 1.0, 600)  # gentle ground, a degree either way
    scattered, exact = GradeCheck(1), GradeCheck(1)
    _check_pairs(scattered, body + rng.normal(0.0, 2.0, len(body)), body)  # reads off by 2 deg (rms), unbiased
    _check_pairs(exact, body, body)
    offset, slope = scattered.line
    assert 0.15 < slope[0] < 0.35  # a read is worth a fifth of itself: the spread of the truth over that of the reads
    fresh = rng.normal(0.0, 1.0, 2000)
    reads = fresh + rng.normal(0.0, 2.0, len(fresh))
    taken = offset[0] + slope[0] * reads
    assert np.mean((taken - fresh) ** 2) < 0.5 * np.mean((reads - fresh) ** 2)  # nearer the truth than the reads
    assert exact.line[1][0] == pytest.approx(1.0) and exact.line[0][0] == pytest.approx(0.0, abs=1e-9)
