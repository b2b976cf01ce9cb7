"""teach_course, the demonstration course: what one drive must show (SPEC 13, docs/design.md) and
that the synthetic driver shows it within five and a half minutes."""

from __future__ import annotations

import itertools
from collections import Counter

import pytest

from terrapref.evaluation.runner import EXPERT, RunSpec, run_one
from terrapref.scenario import resolve_scenario
from terrapref.terrain import PreferenceProfile, default_classes

CLASSES = default_classes().feature_names
LETHAL = "non_traversable"


@pytest.fixture(scope="module")
def labels() -> list[str]:
    return [z.label for z in resolve_scenario("teach_course").zones]


def _pairs(labels: list[str]) -> list[tuple[str, str]]:
    return [tuple(label.split(" vs ")) for label in labels if " vs " in label]


def test_every_pair_meets_on_both_sides(labels):
    pairs = _pairs(labels)
    assert sorted(pairs) == sorted(itertools.permutations(CLASSES, 2))  # each ordered (left, right) once
    for x in CLASSES:
        if x != LETHAL:
            assert (x, LETHAL) in pairs and (LETHAL, x) in pairs


def test_every_class_lies_alone_twice():
    scenario = resolve_scenario("teach_course")
    lone = [z for z in scenario.zones if z.expect == "avoid"]
    assert Counter(z.label for z in lone) == {c: 2 for c in CLASSES}


@pytest.mark.parametrize("order", [("mud", "rock", "water", LETHAL), ("water", "rock", "mud", LETHAL)])
def test_the_synthetic_driver_shows_it_in_at_most_five_and_a_half_minutes(order):
    run = run_one(RunSpec("teach_course", 0, EXPERT, None, order))
    m = run.metrics
    assert m.completed and m.collisions == 0
    assert m.duration_s <= 330.0  # simulated time at 1 m/s, not wall clock
    zones = {z.label: z for z in m.zones}
    best = PreferenceProfile(order).order
    for left, right in _pairs(list(zones)):
        assert zones[f"{left} vs {right}"].choice == min((left, right), key=best.index)
    assert all(z.choice == "avoid" for z in m.zones if z.expect == "avoid")
