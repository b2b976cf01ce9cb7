"""teach_course, the demonstration course: what one drive must show (SPEC 13, docs/design.md) and
that the synthetic driver shows it within five and a half minutes at 1 m/s, and every class at a
steady speed within seven minutes at a person's speeds."""

from __future__ import annotations

import itertools
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from terrapref.evaluation.runner import EXPERT, RunSpec, run_one
from terrapref.scenario import resolve_scenario
from terrapref.terrain import PreferenceProfile, default_classes

ROOT = Path(__file__).resolve().parents[2]
CLASSES = default_classes().feature_names
LETHAL = "non_traversable"


@pytest.fixture(scope="module")
def labels() -> list[str]:
    return [z.label for z in resolve_scenario("teach_course").zones]


def _pairs(labels: list[str]) -> list[tuple[str, str]]:
    return [tuple(label.split(" vs ")) for label in labels if " vs " in label]


def _triples(labels: list[str]) -> list[tuple[str, str, str]]:
    """The strips: a class on the path between the trees and another class (lanes, between trees on both sides, apart)."""
    return [t for t in (tuple(label.split(" | ")) for label in labels if label.count(" | ") == 2) if not (t[0] == t[2] == LETHAL)]


def _lanes(labels: list[str]) -> list[str]:
    """The classes lying as a lane: between the trees on both sides, too wide to pass round."""
    return [t[1] for t in (label.split(" | ") for label in labels if label.count(" | ") == 2) if t[0] == t[2] == LETHAL]


def test_every_pair_meets_on_both_sides(labels):
    safe = [c for c in CLASSES if c != LETHAL]
    assert sorted(_pairs(labels)) == sorted(itertools.permutations(safe, 2))  # each ordered (left, right) once
    # Beside non_traversable: every class as the strip on the path, once with the trees on each
    # side, and every class on the other side once on each side too.
    triples = _triples(labels)
    assert all(LETHAL in (left, right) and middle != LETHAL for left, middle, right in triples)
    strips = Counter((middle, "left" if left == LETHAL else "right") for left, middle, right in triples)
    assert strips == {(c, side): 1 for c in safe for side in ("left", "right")}
    beside = Counter((right if left == LETHAL else left, "right" if left == LETHAL else "left") for left, middle, right in triples)
    assert beside == {(c, side): 1 for c in safe for side in ("left", "right")}
    # Each strip has each other class beside it once: every ordered (strip, other) pair.
    assert sorted((m, r if left == LETHAL else left) for left, m, r in triples) == sorted(itertools.permutations(safe, 2))


def test_every_class_lies_alone_and_every_feature_class_as_a_lane(labels):
    scenario = resolve_scenario("teach_course")
    lone = [z for z in scenario.zones if z.expect == "avoid"]
    assert Counter(z.label for z in lone) == {c: 1 if c != LETHAL else 2 for c in CLASSES}  # a lane stands for the second
    assert sorted(_lanes(labels)) == sorted(c for c in CLASSES if c != LETHAL)


@pytest.mark.slow  # a study of the course (a 7-minute drive featurised whole); the speed rule's fit is tested in test_speed_rule
def test_the_driver_shows_every_class_at_a_steady_speed_within_seven_minutes(tmp_path):
    from terrapref.dataset import build_dataset
    from terrapref.features import FeatureConfig
    from terrapref.learning.train import FitData
    from terrapref.recipes import RecipeSetup, demonstrate, recipe_named
    from terrapref.rules import SpeedConfig

    speeds = (("grass", 1.6), ("rock", 1.0), ("mud", 0.5), ("water", 0.3))
    setup = RecipeSetup(0, PreferenceProfile(("rock", "mud", "water", LETHAL)), speeds=speeds)
    (recording,) = demonstrate(recipe_named("teach"), tmp_path, setup, write=False)
    assert recording.duration_s < 420.0  # simulated time, not wall clock
    rule = SpeedConfig().fit(FitData(build_dataset([recording], FeatureConfig(), rules=(SpeedConfig(),)), mirror=False))
    names = (*FeatureConfig().feature_classes, "grass")
    learned = {name: (rule.model.speeds_mps[k], rule.fit.intervals[k]) for k, name in enumerate(names) if name != LETHAL}
    assert all(interval is not None for _, interval in learned.values()), learned  # every class shown steady
    assert {name: round(v, 2) for name, (v, _) in learned.items()} == dict(speeds)


@pytest.mark.slow  # a whole drive, course or training end to end; the default run keeps the test suite's time
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
    for left, middle, right in _triples(list(zones)):  # never the trees; the strip or the class beside it
        assert zones[f"{left} | {middle} | {right}"].choice in (middle, right if left == LETHAL else left)
    assert all(z.choice == "avoid" for z in m.zones if z.expect == "avoid")


def _strip_metres(scenario, world, zone, lateral_m: float) -> tuple[float, float]:
    """Metres of a strip zone's middle class, and of the class beside it that is not lethal, along
    the strip's 7 m on the line ``lateral_m`` left of the path (the zone's rectangle sits on the
    path, turned to its heading), read from ``world``, the scenario rasterised."""
    left, middle, right = zone.label.split(" | ")
    side = 1.0 if right in scenario.classes.lethal else -1.0  # the neighbour's side
    rect, along = zone.shape, np.arange(-3.45, 3.5, 0.05)
    c, s = np.cos(rect.yaw_rad), np.sin(rect.yaw_rad)
    lat = side * lateral_m
    xy = np.stack([rect.center[0] + c * along - s * lat, rect.center[1] + s * along + c * lat], axis=1)
    ids = world.class_at(xy)
    neighbour = left if side > 0 else right
    return 0.05 * float((ids == scenario.classes.id_of(middle)).sum()), 0.05 * float((ids == scenario.classes.id_of(neighbour)).sum())


@pytest.mark.parametrize("table", [None, "examples/classes/small.yaml"])  # a table of one's own: its strip beside the background
def test_a_strips_edge_beside_a_class_tapers_so_that_the_metres_on_it_change_steadily_with_the_offset(table):
    """Across the offsets at which a footprint point passes the strip's edge beside the better
    class, the metres it crosses on the strip shrink steadily (with straight edges they fell from
    7 m to none within one 0.2 m step of the offsets, so a held offset only bounded the price step)."""
    from terrapref.scenario.loader import parse_scenario
    from terrapref.scenario.teaching import designed_course
    from terrapref.terrain import load_classes
    from terrapref.world.raster import rasterise

    if table is None:
        scenario = resolve_scenario("teach_course")
    else:
        classes = load_classes(ROOT / table)
        scenario = parse_scenario(designed_course(classes, "full")[0].data(), table, classes)
    strips = [z for z in scenario.zones if z.label.count(" | ") == 2 and not _lane_label(z.label, scenario)]
    assert len(strips) == (6 if table is None else 2)
    world = rasterise(scenario)
    for zone in strips:
        metres = [_strip_metres(scenario, world, zone, y) for y in (1.1, 1.3, 1.5, 1.7)]
        on_strip = [m for m, _ in metres]
        assert all(a - b > 1.0 for a, b in zip(on_strip, on_strip[1:])), (zone.label, metres)
        assert all(abs(m + n - 6.95) < 0.2 for m, n in metres), (zone.label, metres)  # the rest is the neighbour's


def _lane_label(label: str, scenario) -> bool:
    left, _, right = label.split(" | ")
    return left == right and left in scenario.classes.lethal
