"""The speed rule's check of the grades it read ahead against the body's pitch once there
(terrapref.rules.speed.calibration), in closed form."""

from __future__ import annotations

import math

import numpy as np
import pytest

from terrapref.rules.speed.calibration import FADE, PRIOR, GradeCheck


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
    assert (check.correction == 0).all()  # nothing checked: nothing taken off
    _drive_along(check, 2.0, 40)
    # Station s of decision i is checked at decision i + s (station 0 at once), once: 40 - s errors of 2 deg, faded.
    for s in range(4):
        n = 40 - s
        faded = sum(FADE**j for j in range(n))
        assert check.correction[s] == pytest.approx(2.0 * faded / (faded + PRIOR))
    check.reset()
    assert (check.correction == 0).all()


def test_a_station_is_checked_only_where_the_vehicle_stands_heading_along_it():
    check = GradeCheck(1)
    check.keep(np.array([[1.0, 0.0]]), np.zeros(1), np.array([3.0]))
    check.arrived(1.0, 0.3, 0.0, 0.0)  # beside it
    check.arrived(1.0, 0.0, math.radians(45.0), 0.0)  # there, turned away
    assert check.correction[0] == 0.0
    check.arrived(1.05, 0.0, 0.0, 1.0)  # there: 3 - 1 deg
    assert check.correction[0] == pytest.approx(2.0 / (1.0 + PRIOR))
    check.arrived(1.0, 0.0, 0.0, 1.0)  # checked once
    assert check.correction[0] == pytest.approx(2.0 / (1.0 + PRIOR))
