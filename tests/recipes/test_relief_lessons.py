"""What drives on relief leave unshown (terrapref.recipes.lessons), and the follow-up course that
shows it (``terrapref course --after``)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from terrapref.recipes.lessons import relief_plan, relief_unshown
from terrapref.rules.offset.features import RELIEF_BANDS_DEG
from terrapref.rules.speed.model import STATIONS
from terrapref.scenario import parse_scenario
from terrapref.scenario.relief import Mound, Noise, Plateau, Ridge
from terrapref.scenario.teaching import RELIEF_LESSONS, Beside, follow_up_after
from terrapref.terrain import default_classes

N, B = 40, len(RELIEF_BANDS_DEG)


def _drive(roll_deg: float | None, pitch_deg: float | None, climbing: int, descending: int, rough: int) -> SimpleNamespace:
    """A drive's rule arrays as the lessons read them: ground past ``roll_deg`` and ``pitch_deg``
    (the offset rule's relief columns; None: none past any band), ``climbing`` frames up 5 deg
    and ``descending`` down, ``rough`` frames on 0.03 m of roughness, the rest level and smooth."""
    relief = np.zeros((N, 3, 2 * B))
    for k, deg in enumerate((roll_deg, pitch_deg)):
        if deg is not None:
            relief[0, 1, k * B : k * B + RELIEF_BANDS_DEG.index(deg) + 1] = 1.0
    grade, roughness = np.zeros((N, STATIONS)), np.zeros((N, STATIONS))
    grade[:climbing, 2] = 5.0
    grade[climbing : climbing + descending, 2] = -5.0
    roughness[:rough, 1] = 0.03
    return SimpleNamespace(rules={"speed": {"grade": grade, "rough": roughness}, "offset": {"relief_m": relief}})


def test_a_drive_that_showed_every_lesson_leaves_none_and_a_flat_drive_has_none():
    assert relief_unshown(_drive(16.0, 18.0, 12, 10, 10)) == ()
    flat = _drive(None, None, 0, 0, 0)
    flat.rules["speed"]["grade"][:] = np.nan
    assert relief_unshown(flat) is None and relief_plan(flat, None, "rec") == ((), (), False)


@pytest.mark.parametrize(
    ("drive", "unshown"),
    [
        (_drive(14.0, 18.0, 12, 10, 10), ("steep side slope",)),  # side slopes to 14 deg only: the steep bank's 16 unshown
        (_drive(None, 14.0, 12, 10, 10), ("steep side slope", "steep grade")),
        (_drive(16.0, 16.0, 12, 9, 10), ("grades",)),  # 9 frames descending: too few
        (_drive(16.0, 16.0, 12, 10, 9), ("rough ground",)),
    ],
)
def test_each_lesson_is_unshown_where_the_drive_holds_too_little_of_it(drive, unshown):
    assert relief_unshown(drive) == unshown
    assert relief_plan(drive, None, "rec") == (unshown, (), True)


def test_a_lesson_unshown_before_the_last_drive_and_after_it_is_left():
    before, now = _drive(None, 18.0, 12, 10, 0), _drive(16.0, 18.0, 12, 10, 0)
    show, left, _ = relief_plan(now, before, "rec2")
    assert show == () and left == ("rough ground: unshown before rec2 and after it; driving it again would show the same",)


def test_a_follow_up_of_relief_alone_places_each_lessons_situation():
    classes = default_classes()
    course, items = follow_up_after(classes, [], ["teach_relief"], beside=Beside(relief=tuple(RELIEF_LESSONS)))
    assert items == list(RELIEF_LESSONS.values())
    scenario = parse_scenario(course.data(), "more.yaml", classes)
    # a bank, a mound, a ramp, a rough patch in steps
    assert [type(e) for e in scenario.relief] == [Ridge, Mound, Plateau, Noise, Noise, Noise, Noise]
    assert scenario.description.startswith(
        "Follow-up course: the relief the drive of teach_relief left unshown (steep side slope, steep grade, grades, rough ground)"
    )


HILL = {
    "format": "terrapref-scenario/1",
    "name": "hill",
    "world": {"size_m": [40.0, 20.0], "resolution_m": 0.05, "background": "grass"},
    "terrain": [],
    "relief": [{"plateau": {"polygon": [[16.0, -10.0], [24.0, -10.0], [24.0, 30.0], [16.0, 30.0]], "height_m": 1.0, "edge_m": 6.0}}],
    "path": {"waypoints": [[5.0, 10.0], [35.0, 10.0]]},
}


@pytest.mark.slow  # a whole drive of a relief course, then its follow-up
def test_a_follow_up_with_relief_between_its_situations_keeps_its_lessons_relief(tmp_path, capsys):
    """`course --after REC --relief` adds relief between the follow-up's situations; the bank, the
    mound and the rough patch the drive left unshown stay (they were replaced by it)."""
    import yaml

    from terrapref.cli import main

    course, rec, more = (tmp_path / n for n in ("hill.yaml", "rec", "more.yaml"))
    course.write_text(yaml.safe_dump(HILL))
    assert main(["record", str(course), "--relief-style", "cautious", "--style", "shaky", "--out", str(rec), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["course", "--after", str(rec), "--relief", "5", "--out", str(more)]) == 0
    kinds = [next(iter(e)) for e in yaml.safe_load(more.read_text())["relief"]]
    assert kinds[:3] == ["ridge", "mound", "noise"] and len(kinds) > 3, kinds
    # The record line it prints drives the follow-up as the drive was driven.
    printed = capsys.readouterr().out  # and in the order it was driven in: recorded in another, it could not be trained with it
    assert (
        f"record it: terrapref record {more} --profile mud,rock,water,non_traversable --style shaky --relief-style cautious --out DIR"
        in printed
    )


@pytest.mark.slow
def test_course_after_a_drive_of_a_hill_shows_the_relief_it_left_unshown_and_the_loop_ends(tmp_path, capsys):
    """A drive over one ramp up and down shows grades and nothing else of relief: `course --after`
    writes the steep bank, the steep mound and a rough patch; after a drive of that, nothing is unshown."""
    import yaml

    from terrapref.cli import main

    course, rec, more, rec_more, more2 = (tmp_path / n for n in ("hill.yaml", "rec", "more.yaml", "rec_more", "more2.yaml"))
    course.write_text(yaml.safe_dump(HILL))
    assert main(["record", str(course), "--relief-style", "default", "--out", str(rec), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["course", "--after", str(rec), "--out", str(more)]) == 0
    out = capsys.readouterr().out
    assert "left relief unshown for a follow-up: steep side slope, steep grade, rough ground" in out
    written = yaml.safe_load(more.read_text())
    assert [next(iter(e)) for e in written["relief"]] == ["ridge", "mound", "noise"]
    assert main(["record", str(more), "--relief-style", "default", "--out", str(rec_more), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["course", "--after", str(rec), str(rec_more), "--out", str(more2)]) == 0
    out = capsys.readouterr().out
    # Every relief lesson shown: none unshown, none written (the hill leaves pairs of classes open, said apart).
    assert "unshown" not in out and "relief lesson" not in out and "nothing written" in out and not more2.exists()
