"""Any class table (terrapref.terrain.classes): the default table's terrain columns, a user's own
table (examples/classes/rellis3d.yaml) whose lethal classes share one column, what a table file
may not say, and what a table shapes: its teaching course (terrapref.scenario.teaching), the
generated layouts, the orders ``select`` compares, ``--classes`` on the command line, label maps
and the identifiability report's background."""

from __future__ import annotations

import hashlib
import itertools
import json
import math
import re
from collections import Counter
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from helpers import REPO
from terrapref.cli import main
from terrapref.errors import ConfigError
from terrapref.interop.labels import load_label_map
from terrapref.learning.identify import GRASS, Identifiability, PairEvidence, TableNames, identifiability
from terrapref.learning.linear import LinearUtility
from terrapref.report.select import parse_orders
from terrapref.scenario import parse_scenario, resolve_scenario
from terrapref.scenario.generate import generate_course, zone_kind
from terrapref.scenario.teaching import (
    BRACKET_SIZES_M,
    BUDGET_M,
    FOLLOW_UP_M,
    LADDER_HALF_M,
    LETHAL_LONE,
    LONE_OFFSET_M,
    Beside,
    Situation,
    balanced_pairs,
    build_course,
    course_length,
    description,
    designed_course,
    fits,
    follow_up,
    follow_up_after,
    ladder,
    ladder_follows,
    neighbours_within,
    situations,
    teaching_course,
)
from terrapref.terrain import ClassTable, PreferenceProfile, default_classes, load_classes
from terrapref.terrain.classes import LETHAL_COLUMN, MAX_TERRAIN_CLASSES, TerrainClass

EXAMPLES = REPO / "examples" / "classes"
EXAMPLE = EXAMPLES / "rellis3d.yaml"
EXAMPLE_LABELS = EXAMPLES / "rellis3d_labels.yaml"
EXAMPLE_TERRAIN = ("dirt", "gravel", "mud", "puddle", "water", "bush")
EXAMPLE_LETHAL = ("tree", "log", "fence", "building", "vehicle", "person")


@pytest.fixture(scope="module")
def example() -> ClassTable:
    return load_classes(EXAMPLE)


def _table_text(background: str, lethal: list[str], names: list[str], profile: list[str] | None = None) -> str:
    """A ``terrapref-classes/1`` file of ``names`` (ids 0, 1, ... in that order)."""
    lines = ["format: terrapref-classes/1", f"background: {background}", f"lethal: [{', '.join(lethal)}]", "classes:"]
    lines += [f"  - {{id: {i}, name: {n}, color: [{i}, {2 * i}, {3 * i}]}}" for i, n in enumerate(names)]
    if profile is not None:
        lines.append(f"profile: [{', '.join(profile)}]")
    return "\n".join(lines) + "\n"


def _write_table(folder: Path, *args, **kwargs) -> Path:
    path = folder / "classes.yaml"
    path.write_text(_table_text(*args, **kwargs))
    return path


def _table(background: str, lethal: list[str], names: list[str], profile: list[str] | None = None) -> ClassTable:
    data = yaml.safe_load(_table_text(background, lethal, names, profile))
    return ClassTable.from_dict(data, "test")


def _synthetic(k: int, lethal: int = 1) -> ClassTable:
    """grass, ``k`` feature classes c0.. and ``lethal`` lethal classes x0.."""
    walls = [f"x{i}" for i in range(lethal)]
    return _table("grass", walls, ["grass", *(f"c{i}" for i in range(k)), *walls])


def _one_error(capsys, *words: str) -> str:
    """The one ``error:`` line a refused command printed, naming every one of ``words`` (on stderr;
    ``validate`` reports on stdout, beside the files that are ok)."""
    captured = capsys.readouterr()
    text = captured.out + captured.err
    errors = [line for line in text.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, text
    assert "Traceback" not in text and "internal error" not in text
    assert all(w in errors[0] for w in words), errors[0]
    return errors[0]


# --- The default table: one lethal class, its column named after it ------------------------------


def _record_it(printed: str) -> tuple[str, list[str]]:
    """The course and the flags of the record command ``course --after`` printed ("record it: ...")."""
    found = re.search(r"\(record it: terrapref record (\S+)((?: --\S+ \S+)*?) --out DIR\)", printed)
    assert found, printed
    return found.group(1), found.group(2).split()


def test_the_default_table_keeps_its_columns():
    d = default_classes()
    assert d.names == ("grass", "non_traversable", "water", "rock", "mud")
    assert d.feature_names == ("non_traversable", "water", "rock", "mud")
    assert d.terrain_names == ("water", "rock", "mud")
    assert d.lethal_column == "non_traversable" and d.lethal == ("non_traversable",)
    assert [d.ids_of(c) for c in d.feature_names] == [(1,), (2,), (3,), (4,)]
    assert d.column_of("non_traversable") == "non_traversable" and d.column_of("mud") == "mud"
    assert d.profile == ("mud", "rock", "water", "non_traversable")


# --- The example table: six lethal classes pooled into the column `lethal` -----------------------


def test_the_example_table_pools_its_lethal_classes_at_the_first_ones_place(example):
    assert example.background == "grass" and example.lethal == EXAMPLE_LETHAL
    assert example.feature_names == (*EXAMPLE_TERRAIN, LETHAL_COLUMN)  # tree (id 7) comes after bush (id 6)
    assert example.terrain_names == EXAMPLE_TERRAIN
    assert example.lethal_column == LETHAL_COLUMN
    assert example.ids_of(LETHAL_COLUMN) == (7, 8, 9, 10, 11, 12) == example.lethal_ids
    assert [example.ids_of(c) for c in EXAMPLE_TERRAIN] == [(1,), (2,), (3,), (4,), (5,), (6,)]
    assert all(example.column_of(c) == LETHAL_COLUMN for c in EXAMPLE_LETHAL)
    assert example.column_of("gravel") == "gravel"
    assert example.profile == ("dirt", "gravel", "puddle", "mud", "bush", "water", LETHAL_COLUMN)


def test_a_profile_of_the_example_table_names_its_columns(example):
    text = "bush,water,dirt,gravel,puddle,mud,lethal"
    assert PreferenceProfile.parse(text, example).order == tuple(text.split(","))
    assert PreferenceProfile.default(example).order == example.profile
    for bad in (
        "bush,water,dirt,gravel,puddle,mud,tree",
        "bush,water,dirt,gravel,puddle,mud",
        "bush,water,dirt,gravel,puddle,mud,lethal,grass",
    ):
        with pytest.raises(ConfigError):
            PreferenceProfile.parse(bad, example)


# --- What a table file may not say ---------------------------------------------------------------

ELEVEN = ["grass", *(f"c{i}" for i in range(MAX_TERRAIN_CLASSES + 1)), "tree"]


@pytest.mark.parametrize(
    "table,field,words",
    [
        (("grass", ["tree"], ELEVEN), "classes", ["11 feature classes", f"at most {MAX_TERRAIN_CLASSES}"]),
        (("grass", ["grass", "tree"], ["grass", "mud", "tree"]), "lethal", ["background class 'grass'", "cannot be lethal"]),
        (("grass", ["grass"], ["grass", "mud"]), "lethal", ["background class 'grass'", "cannot be lethal"]),
        (
            ("grass", ["grass", "tree"], ["grass", "mud", "tree"], ["mud", "lethal"]),
            "lethal",
            ["background class 'grass'", "cannot be lethal"],
        ),
        (("grass", ["tree", "log"], ["grass", "lethal", "tree", "log"]), "classes", ["'lethal'", "clash", "2 lethal classes"]),
        (("grass", ["lethal", "log"], ["grass", "mud", "lethal", "log"]), "classes", ["'lethal'", "clash"]),
        (
            ("grass", ["tree", "log"], ["grass", "mud", "rock", "tree", "log"], ["mud", "lethal"]),
            "profile",
            ["mud, rock, lethal", "exactly once"],
        ),
        (("grass", ["tree", "log"], ["grass", "mud", "tree", "log"], ["mud", "lethal", "rock"]), "profile", ["mud, lethal"]),
        (("grass", ["tree", "log"], ["grass", "mud", "tree", "log"], ["mud", "tree"]), "profile", ["mud, lethal"]),
        (("grass", ["tree", "log"], ["grass", "mud", "tree", "log"], ["mud", "mud", "lethal"]), "profile", ["mud, lethal"]),
        (("sand", ["tree"], ["grass", "tree"]), "background", ["'sand'"]),
        (("grass", ["stone"], ["grass", "tree"]), "lethal", ["known class names"]),
        (("grass", ["tree"], ["grass", "unknown", "tree"]), "classes[1].name", ["'unknown'", "reserved"]),
        (("grass", ["tree"], ["grass", "avoid", "tree"]), "classes[1].name", ["'avoid'", "reserved", "zone"]),
        (("grass", ["tree"], ["grass", "best", "tree"]), "classes[1].name", ["'best'", "reserved", "zone"]),
        (("grass", ["tree"], ["grass", "'True'", "tree"], ["True", "tree"]), "profile", ["True, tree", "exactly once"]),
        (("grass", ["tree", "log"], ["grass", "mud", "tree", "log"], ["lethal", "mud"]), "profile", ["'lethal'", "last"]),
    ],
    ids=[
        "11 feature classes",
        "background lethal",
        "background the only lethal",
        "background lethal, with a profile",
        "class lethal, 2 lethal",
        "class lethal is lethal, 2 lethal",
        "profile misses a column",
        "profile names an unknown class",
        "profile names a lethal class",
        "profile names a column twice",
        "unknown background",
        "unknown lethal",
        "a class named unknown",
        "a class named avoid",
        "a class named best",
        "a boolean in the profile",
        "profile puts the lethal column first",
    ],
)
def test_a_bad_table_is_refused_naming_the_file_and_field(tmp_path, table, field, words):
    path = _write_table(tmp_path, *table)
    with pytest.raises(ConfigError) as caught:
        load_classes(path)
    lines = caught.value.lines()
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"{path}: {field}: "), lines[0]
    assert all(w in lines[0] for w in words), lines[0]


def test_a_table_without_a_background_line_says_it_is_missing(tmp_path):
    path = _write_table(tmp_path, "grass", ["tree"], ["grass", "mud", "tree"])
    path.write_text("".join(line for line in path.read_text().splitlines(keepends=True) if not line.startswith("background:")))
    with pytest.raises(ConfigError) as caught:
        load_classes(path)
    assert caught.value.lines() == [f"{path}: background: missing: name the class of the ground between patches (one of the table's)"]


def test_the_constructor_checks_what_from_dict_checks():
    classes = (TerrainClass(0, "grass", (0, 0, 0)), TerrainClass(1, "mud", (1, 1, 1)), TerrainClass(2, "tree", (2, 2, 2)))
    assert ClassTable(classes, "grass", ("tree",), ("mud", "tree")).feature_names == ("mud", "tree")
    for background, lethal, profile in (
        ("grass", ("grass",), ("mud", "tree")),
        ("grass", ("tree",), ("mud",)),
        ("grass", ("tree",), ("mud", "lethal")),
        ("grass", ("tree",), ("tree", "mud")),
    ):
        with pytest.raises(ValueError):
            ClassTable(classes, background, lethal, profile)


def test_ten_feature_classes_are_allowed(tmp_path):
    names = ["grass", *(f"c{i}" for i in range(MAX_TERRAIN_CLASSES)), "tree", "log"]
    table = load_classes(_write_table(tmp_path, "grass", ["tree", "log"], names))
    assert len(table.terrain_names) == MAX_TERRAIN_CLASSES
    assert table.feature_names[-1] == LETHAL_COLUMN


def test_a_class_named_lethal_is_allowed_beside_one_lethal_class(tmp_path):
    # A feature class called `lethal`: the one lethal class keeps its own name for its column.
    table = load_classes(_write_table(tmp_path, "grass", ["tree"], ["grass", "lethal", "tree"]))
    assert table.feature_names == ("lethal", "tree") and table.lethal_column == "tree"
    assert table.column_of("lethal") == "lethal" and table.ids_of("lethal") == (1,) and table.ids_of("tree") == (2,)
    # The one lethal class itself called `lethal`.
    table = load_classes(_write_table(tmp_path, "grass", ["lethal"], ["grass", "mud", "lethal"]))
    assert table.feature_names == ("mud", "lethal") and table.lethal_column == "lethal" and table.ids_of("lethal") == (2,)


def test_without_a_profile_the_columns_go_in_id_order_the_lethal_column_last(tmp_path):
    table = load_classes(_write_table(tmp_path, "grass", ["tree", "log"], ["grass", "tree", "mud", "log", "rock"]))
    assert table.feature_names == ("lethal", "mud", "rock")  # the pooled column at tree's place, id 1
    assert table.profile == ("mud", "rock", "lethal")
    table = load_classes(_write_table(tmp_path, "grass", [], ["grass", "rock", "mud"]))
    assert table.lethal_column is None and table.profile == table.feature_names == ("rock", "mud")


# --- The teaching course of any table ------------------------------------------------------------


@pytest.mark.parametrize("n", range(1, MAX_TERRAIN_CLASSES + 1))
def test_balanced_pairs_show_every_pair_once_each_name_left_as_often_as_right(n):
    names = [f"c{i}" for i in range(n)]
    pairs = balanced_pairs(names)
    assert Counter(frozenset(p) for p in pairs) == {frozenset(p): 1 for p in itertools.combinations(names, 2)}
    assert all(a != b for a, b in pairs)
    left, right = Counter(a for a, _ in pairs), Counter(b for _, b in pairs)
    assert all(abs(left[c] - right[c]) <= 1 for c in names), (left, right)


def _kinds(items: list[Situation]) -> tuple[list[tuple[str, ...]], list[tuple[str, ...]], list[Situation]]:
    return (
        [s.classes for s in items if s.kind == "pair"],
        [s.classes for s in items if s.kind == "strip"],
        [s for s in items if s.kind == "lone"],
    )


@pytest.mark.parametrize("table", [default_classes(), _synthetic(2, lethal=2), _synthetic(4, lethal=3)], ids=["default", "2+2", "4+3"])
def test_the_full_design_shows_everything_on_both_sides(table):
    terrain, lethal = table.terrain_names, table.lethal
    pairs, strips, lone = _kinds(situations(table, full=True))
    assert sorted(pairs) == sorted(itertools.permutations(terrain, 2))  # every ordered (left, right) once
    # Every class as the strip twice: lethal terrain once on its left, once on its right.
    assert all((left in lethal) != (right in lethal) for left, _, right in strips)
    sides = Counter((middle, "left" if left in lethal else "right") for left, middle, _ in strips)
    assert sides == {(c, side): 1 for c in terrain for side in ("left", "right")}
    assert all(
        middle in terrain and (left in terrain or right in terrain) and middle not in (left, right) for left, middle, right in strips
    )
    # Lethal terrain alone on both sides (the first lethal class: the lethal classes share one
    # column); each feature class alone once and as a lane once, between walls of one lethal class.
    assert Counter((s.classes[0], s.offset_m) for s in lone if s.classes[0] in lethal) == {
        (lethal[0], o): 1 for o in (LONE_OFFSET_M, -LONE_OFFSET_M)
    }
    assert Counter(s.classes[0] for s in lone if s.classes[0] in terrain) == {c: 1 for c in terrain}
    lanes = [s.classes for s in situations(table, full=True) if s.kind == "lane"]
    assert sorted(middle for _, middle, _ in lanes) == sorted(terrain)
    assert all(left == right and left in lethal for left, _, right in lanes)


def test_the_compact_design_shows_each_pair_once_balanced(example):
    pairs, strips, lone = _kinds(situations(example, full=False))
    assert Counter(frozenset(p) for p in pairs) == {frozenset(p): 1 for p in itertools.combinations(EXAMPLE_TERRAIN, 2)}
    left, right = Counter(a for a, _ in pairs), Counter(b for _, b in pairs)
    assert all(abs(left[c] - right[c]) <= 1 for c in EXAMPLE_TERRAIN)
    assert strips == []  # left to the follow-up's ladder
    # Each feature class alone once, and lethal terrain alone twice (LETHAL_LONE): its first two classes.
    assert Counter(s.classes[0] for s in lone) == {c: 1 for c in (*EXAMPLE_TERRAIN, *EXAMPLE_LETHAL[:LETHAL_LONE])}
    for kind in (EXAMPLE_TERRAIN, EXAMPLE_LETHAL):
        positive = sum(s.offset_m > 0 for s in lone if s.classes[0] in kind)
        assert abs(positive - (sum(s.classes[0] in kind for s in lone) - positive)) <= 1
    # Each kind spread over the whole drive: every third of it has pairs, lone patches and lanes.
    items = situations(example, full=False)
    thirds = [items[i * len(items) // 3 : (i + 1) * len(items) // 3] for i in range(3)]
    assert all({s.kind for s in third} == {"pair", "lone", "lane"} for third in thirds)
    assert sorted(s.classes[1] for s in items if s.kind == "lane") == sorted(EXAMPLE_TERRAIN)


def test_a_table_without_lethal_classes_puts_feature_classes_either_side_of_a_strip():
    table = _synthetic(3, lethal=0)
    _, strips, lone = _kinds(situations(table, full=True))
    assert Counter(middle for _, middle, _ in strips) == {c: 2 for c in table.terrain_names}
    assert all(middle not in (left, right) and {left, right} <= set(table.terrain_names) for left, middle, right in strips)
    assert Counter(s.classes[0] for s in lone) == {c: 1 for c in table.terrain_names}
    lanes = [s for s in situations(table, full=True) if s.kind == "lane"]  # without walls: each class across the whole way
    assert sorted(s.classes for s in lanes) == sorted((c,) for c in table.terrain_names)


@pytest.mark.parametrize(
    ("table", "full"),
    [(default_classes(), True), (_synthetic(2, lethal=2), True), (_synthetic(4, lethal=3), True), (load_classes(EXAMPLE), False)],
    ids=["default", "2+2 full", "4+3 full", "example compact"],
)
def test_the_description_names_the_lethal_classes_the_course_shows_alone(table, full):
    """What a course's description says is shown alone is what its situations show alone."""
    alone = list(dict.fromkeys(s.classes[0] for s in situations(table, full=full) if s.kind == "lone" and s.classes[0] in table.lethal))
    text = description(table, full)
    if alone == list(table.lethal):
        assert "every class alone on the path" in text
    else:
        assert f"every feature class alone on the path, and lethal terrain ({', '.join(alone)})" in text


def test_the_design_is_full_while_it_fits_the_budget(example):
    d = default_classes()
    assert situations(d) == situations(d, full=True) and course_length(situations(d)) <= BUDGET_M
    assert course_length(situations(example, full=True)) > BUDGET_M
    assert situations(example) == situations(example, full=False) and course_length(situations(example)) <= BUDGET_M
    # Up to four feature classes drive the full design within the budget (the module docstring).
    assert [course_length(situations(_synthetic(k), full=True)) <= BUDGET_M for k in range(1, 11)] == [k <= 4 for k in range(1, 11)]


@pytest.mark.parametrize(
    "table",
    [default_classes(), load_classes(EXAMPLE), _synthetic(1, lethal=0), _synthetic(1), _synthetic(10, lethal=3)],
    ids=["default", "example", "1+0", "1+1", "10+3"],
)
def test_a_teaching_course_reads_back_and_lies_on_its_map(table):
    items = situations(table)
    course = teaching_course(table)
    scenario = parse_scenario(course.data(), "teaching_course", table)
    assert scenario.name == "teaching_course" and scenario.background == table.background
    assert [z.label for z in scenario.zones] == [s.label for s in items]
    # A strip beside the background expects every driver to leave it for the background.
    beside_background = [s.kind == "lone" or table.background in s.classes for s in items]
    assert [z.expect for z in scenario.zones] == ["avoid" if b else "best" for b in beside_background]
    painted = {p.class_name for p in scenario.terrain}  # real classes, never a column
    assert {*table.terrain_names, *table.lethal} <= painted <= set(table.names)
    assert scenario.path_length_m() == pytest.approx(course_length(items), abs=0.01)
    w, h = scenario.size_m
    for shape in [z.shape for z in scenario.zones] + [p.shape for p in scenario.terrain]:
        x0, y0, x1, y1 = shape.bounds()
        assert 0.0 <= x0 and 0.0 <= y0 and x1 <= w and y1 <= h, (shape, scenario.size_m)
    assert np.all((scenario.waypoints >= 0) & (scenario.waypoints <= (w, h)))


def test_the_course_design_is_chosen_by_name(example):
    for design, full in (("auto", False), ("full", True), ("compact", False)):
        course, items = designed_course(example, design, "mine")
        assert items == situations(example, full) and course.name == "mine"
        assert course.data() == build_course(example, items, "mine", course.description).data()
    assert designed_course(example)[0].data() == teaching_course(example).data()


def test_a_follow_up_is_named_after_the_courses_driven(example):
    pairs = [("grass", "mud")]
    course, items = follow_up_after(example, pairs, ["courses/a.yaml", "b", "courses/a.yaml"])
    assert course.name == "a.yaml_more" and items == follow_up(example, pairs)
    assert "3 drives of courses/a.yaml and b together left open (grass vs mud)" in course.description
    assert follow_up_after(example, pairs, ["a"], "more")[0].name == "more"
    assert "the drive of a left open" in follow_up_after(example, pairs, ["a"])[0].description
    course, items = follow_up_after(example, [("dirt", "bush")], ["a"], beside=Beside(neighbours=[("water", "dirt")]))
    assert items == follow_up(example, [("dirt", "bush"), ("water", "dirt")])
    assert (
        "left open (dirt vs bush), beside their neighbours in the learned order (water vs dirt), each once, the sides" in course.description
    )


def test_a_compact_course_leaves_its_strips_to_the_ladder_and_a_fitting_table_keeps_them():
    """A table too large for the full design drives no strip; --design compact of a table whose
    full design fits, and a compact course with relief, keep each strip once."""
    large, fitting = _synthetic(6, lethal=2), _synthetic(3, lethal=1)
    unwalled = _synthetic(6, lethal=0)  # a ladder's strips would have the background beside them
    assert not fits(large) and fits(fitting) and not fits(unwalled)
    assert [ladder_follows(t) for t in (large, fitting, unwalled)] == [True, False, False]
    assert [s for s in situations(large, full=False) if s.kind == "strip"] == []
    assert "no strip (its follow-up shows the learned order's)" in description(large, False)
    for table, items in (
        (fitting, situations(fitting, full=False)),
        (large, situations(large, full=False, relief=True)),
        (unwalled, situations(unwalled, full=False)),
    ):
        assert Counter(s.classes[1] for s in items if s.kind == "strip") == {c: 1 for c in table.terrain_names}


def test_the_ladder_puts_each_class_beside_the_next_better_and_the_best_alone_at_two_sizes(example):
    order = ["mud", "lethal", "water", "gravel", "grass", "dirt"]  # other names than feature classes are passed over
    items = ladder(example, order)
    strips, lone = [s for s in items if s.kind == "strip"], [s for s in items if s.kind == "lone"]
    wall = example.lethal[0]
    assert [s.classes for s in strips] == [(wall, "water", "mud"), ("water", "gravel", wall), (wall, "dirt", "gravel")]
    assert [(s.classes, s.offset_m, s.size_m) for s in lone] == [
        (("mud",), LONE_OFFSET_M, BRACKET_SIZES_M[0]),
        (("mud",), -LONE_OFFSET_M, BRACKET_SIZES_M[1]),
    ]
    assert ladder(example, []) == [] and ladder(example, ["lethal"]) == []
    # One class: no step, its two sizes alone; no ladder: the trail as the open pairs' own.
    course, shown = follow_up_after(example, [("dirt", "bush")], ["a"], beside=Beside(order=["grass", "mud", "lethal"]))
    assert [s.kind for s in shown].count("strip") == 0 and [s.size_m for s in shown if s.kind == "lone"] == list(BRACKET_SIZES_M)
    assert "mud, the best class the drive of a learned, alone at two sizes" in course.description
    assert all(s.legs_m is None for s in follow_up_after(example, [("dirt", "bush")], ["a"], beside=Beside(order=["lethal"]))[1])
    # The brackets are rectangles of their sizes, scored as lone patches; the course says what it shows.
    course, shown = follow_up_after(example, [("dirt", "bush")], ["teaching_course"], beside=Beside(order=order))
    unshortened = [replace(s, legs_m=None) for s in shown]
    assert sorted(map(repr, unshortened)) == sorted(map(repr, [*follow_up(example, [("dirt", "bush")]), *items]))
    assert "the order the drive of teaching_course learned (mud > water > gravel > dirt) as strips" in course.description
    # With a ladder, each situation has the shorter trail; without one, its kind's.
    assert all(s.legs_m == (LADDER_HALF_M[s.kind],) * 2 for s in shown)
    assert all(s.legs_m is None for s in follow_up_after(example, [("dirt", "bush")], ["teaching_course"])[1])
    scenario = parse_scenario(course.data(), "more", example)
    assert [z.label for z in scenario.zones] == [s.label for s in shown]
    mud = [p for p in course.data()["terrain"] if p["class"] == "mud" and "rectangle" in p]
    assert set(BRACKET_SIZES_M) <= {tuple(p["rectangle"]["size"]) for p in mud}  # beside the strip mud is the better side of


def test_a_follow_up_shows_neighbours_within_its_length_and_every_open_pair(example):
    """The neighbours beside the open pairs stop where the course would pass FOLLOW_UP_M; the
    open pairs are all shown, however long."""
    pairs = list(itertools.combinations(EXAMPLE_TERRAIN, 2))
    few, many = pairs[:2], pairs[2:]
    shown = neighbours_within(example, few, many)
    assert shown == many[: len(shown)] and 0 < len(shown) < len(many)
    assert course_length(follow_up(example, [*few, *shown])) <= FOLLOW_UP_M
    assert course_length(follow_up(example, [*few, *many[: len(shown) + 1]])) > FOLLOW_UP_M
    assert neighbours_within(example, pairs, many) == []
    assert course_length(follow_up(example, pairs)) > FOLLOW_UP_M
    assert neighbours_within(example, few, many[:1]) == many[:1]


def test_a_table_without_feature_classes_has_no_teaching_course(tmp_path, capsys):
    table = _table("grass", ["tree"], ["grass", "tree"])
    with pytest.raises(ValueError):
        situations(table)
    path = _write_table(tmp_path, "grass", ["tree"], ["grass", "tree"])
    assert main(["course", "--classes", str(path), "--out", str(tmp_path / "c.yaml")]) == 2
    _one_error(capsys, str(path), "classes", "no feature class")
    assert not (tmp_path / "c.yaml").exists()


def test_a_follow_up_shows_each_open_pair_once_sides_alternating_and_the_background_as_lone_patches(example):
    items = follow_up(example, [("grass", "mud"), ("lethal", "grass"), ("mud", "lethal"), ("dirt", "gravel")])
    lone = [("lone", ("mud",), LONE_OFFSET_M), ("lone", ("tree",), -LONE_OFFSET_M)]
    pairs = [("pair", ("mud", "tree"), 0.0), ("pair", ("gravel", "dirt"), 0.0)]
    assert [(s.kind, s.classes, s.offset_m) for s in items] == lone + pairs  # the lethal column: its first class
    scenario = parse_scenario(build_course(example, items, "more", "follow-up").data(), "more", example)
    assert [z.label for z in scenario.zones] == [s.label for s in items]
    # The default table's lethal column is its own class.
    d = default_classes()
    items = follow_up(d, [("grass", "non_traversable"), ("water", "non_traversable")])
    assert [(s.classes, s.offset_m) for s in items] == [(("non_traversable",), LONE_OFFSET_M), (("non_traversable", "water"), 0.0)]


# --- Generated layouts ---------------------------------------------------------------------------


def _fingerprint(data: dict) -> str:
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()[:16]


# A regression guard: the fingerprints of two of the default table's generated layouts, computed
# by running generate_course. A class table other than the default must not move a default layout
# by one draw; a deliberate change to the generator updates these.
@pytest.mark.parametrize("name,fingerprint", [("gen:7", "ae6f83ba9c1e6a35"), ("gen:1000", "36b95a9dfa9e0fec")])
def test_the_default_tables_generated_layouts_are_unchanged(name, fingerprint):
    assert _fingerprint(resolve_scenario(name).to_dict()) == fingerprint


def test_generated_layouts_of_the_example_table_use_its_classes(example):
    lethal_seen: set[str] = set()
    for seed in range(5):
        scenario = generate_course(seed, classes=example)
        classes = {p.class_name for p in scenario.terrain}
        assert classes <= set(example.names) - {example.background}, classes  # never the column `lethal`
        for zone in scenario.zones:
            named = zone.label.removeprefix("lone ").split(" | ")
            assert set(named) <= classes
        lethal_seen |= classes & set(EXAMPLE_LETHAL)
    assert len(lethal_seen) >= 2  # the pooled column becomes one lethal class or another
    assert generate_course(3, classes=example).to_dict() == generate_course(3, classes=example).to_dict()
    assert resolve_scenario("gen:3", example).to_dict() == generate_course(3, classes=example).to_dict()


def test_a_small_table_gets_only_the_zones_it_can_fill():
    three = _table("grass", ["tree"], ["grass", "mud", "tree"])
    kinds = Counter(zone_kind(z.label) for seed in range(6) for z in generate_course(seed, classes=three).zones)
    assert set(kinds) == {"lone", "pair"}, kinds
    assert {zone_kind(z.label) for z in generate_course(0, kinds=("triple",), classes=three).zones} == {"lone"}
    two = _table("grass", [], ["grass", "mud"])
    assert {z.label for z in generate_course(0, classes=two).zones} == {"lone mud"}


# --- The orders `select` compares ----------------------------------------------------------------


def test_all_orders_of_the_default_table_are_the_six(example):
    orders = parse_orders("all")
    assert orders == tuple((*p, "non_traversable") for p in itertools.permutations(("mud", "rock", "water")))
    assert len(parse_orders("all", example)) == math.factorial(6)


def test_random_orders_are_distinct_drawn_the_same_each_time(example):
    orders = parse_orders("random:4", example)
    assert len(set(orders)) == 4
    assert all(o[-1] == LETHAL_COLUMN and sorted(o[:-1]) == sorted(EXAMPLE_TERRAIN) for o in orders)
    assert parse_orders("random:4", example) == orders
    assert set(parse_orders("random:720", example)) == set(parse_orders("all", example))


@pytest.mark.parametrize("n", [20_000, 40_320 // 2 + 1, 40_320])
def test_many_random_orders_are_drawn_at_once(n):
    """Of the 40,320 orders of 8 classes, thousands: each drawn once (a draw that checked each new
    order against a list of those drawn took minutes)."""
    table = _synthetic(8)
    orders = parse_orders(f"random:{n}", table)
    assert len(orders) == len(set(orders)) == n
    assert all(sorted(o[:-1]) == sorted(table.terrain_names) and o[-1] == table.lethal_column for o in orders)
    assert parse_orders(f"random:{n}", table) == orders


@pytest.mark.parametrize("text", ["random:0", "random:-1", "random:721", "random:x", "random:"])
def test_a_bad_random_count_is_refused(example, text):
    with pytest.raises(ValueError, match="random:N"):
        parse_orders(text, example)


def test_random_count_is_capped_by_the_tables_orders():
    assert len(parse_orders("random:6")) == 6
    with pytest.raises(ValueError, match="1 <= N <= 6"):
        parse_orders("random:7")


def test_an_explicit_order_gets_the_lethal_column_appended(example):
    assert parse_orders("mud,rock,water") == (("mud", "rock", "water", "non_traversable"),)
    assert parse_orders("bush,water,dirt,gravel,puddle,mud;dirt,gravel,mud,puddle,water,bush,lethal", example) == (
        ("bush", "water", "dirt", "gravel", "puddle", "mud", "lethal"),
        ("dirt", "gravel", "mud", "puddle", "water", "bush", "lethal"),
    )


# --- The command line ----------------------------------------------------------------------------


def test_course_writes_a_tables_teaching_course_that_carries_the_table(tmp_path, capsys):
    small = EXAMPLES / "small.yaml"  # a course of a few situations: its picture draws quickly
    table = load_classes(small)
    out = tmp_path / "c.yaml"
    assert main(["course", "--classes", str(small), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert out.is_file() and (tmp_path / "c.png").is_file()
    minutes = re.search(r"expected drive about ([0-9.]+) minutes", printed)
    assert minutes is not None, printed
    assert float(minutes.group(1)) == round(course_length(situations(table)) / 60, 1)
    assert f"{len(situations(table))} situations" in printed
    assert yaml.safe_load(out.read_text()) == yaml.safe_load(yaml.safe_dump(teaching_course(table).data()))
    # The course carries its table: it reads without --classes, with its table, and not with another.
    assert "(record it: terrapref record " + str(out) + " --out DIR)" in printed
    assert main(["validate", str(out)]) == 0
    assert main(["validate", str(out), "--classes", str(small)]) == 0
    assert main(["show", str(out), "--out", str(tmp_path / "map.png")]) == 0
    capsys.readouterr()
    default_file = REPO / "src" / "terrapref" / "data" / "classes.yaml"
    assert main(["show", str(out), "--classes", str(default_file), "--out", str(tmp_path / "map2.png")]) == 2
    line = _one_error(
        capsys,
        str(out),
        "classes: the scenario carries the class table of grass, mud, tree",
        "not the one it is read with (grass, non_traversable",
    )
    assert not (tmp_path / "map2.png").exists(), line


@pytest.mark.slow  # a whole drive, course or training end to end; the default run keeps the test suite's time
def test_course_design_and_name(tmp_path, capsys):
    out = tmp_path / "c.yaml"
    assert main(["course", "--out", str(out), "--design", "compact", "--name", "short"]) == 0  # the default table's is full
    assert f"{len(situations(default_classes(), full=False))} situations" in capsys.readouterr().out
    data = yaml.safe_load(out.read_text())
    assert data["name"] == "short" and len(data["zones"]) == 13  # 3 pairs, 3 strips, 4 lone patches, 3 lanes


def test_course_of_the_default_table_reads_without_classes(tmp_path, capsys):
    out = tmp_path / "c.yaml"
    assert main(["course", "--out", str(out)]) == 0
    assert main(["validate", str(out)]) == 0
    assert "20 situations" in capsys.readouterr().out


def test_course_needs_a_yaml_out(tmp_path, capsys):
    out = tmp_path / "x.txt"
    assert main(["course", "--out", str(out)]) == 2
    _one_error(capsys, str(out), "--out", ".yaml")
    assert not out.exists() and not (tmp_path / "x.png").exists()


@pytest.mark.parametrize("command", [["course", "--out", "c.yaml"], ["validate", "demo_course"], ["show", "demo_course", "--out", "m.png"]])
def test_a_malformed_classes_file_is_refused_in_one_line(tmp_path, capsys, monkeypatch, command):
    monkeypatch.chdir(tmp_path)
    text = EXAMPLE.read_text().replace("profile: [dirt, gravel, puddle, mud, bush, water, lethal]", "profile: [dirt, gravel, mud]")
    assert text != EXAMPLE.read_text()
    bad = tmp_path / "bad_classes.yaml"
    bad.write_text(text)
    assert main([*command, "--classes", str(bad)]) == 2
    _one_error(capsys, str(bad), "profile")
    assert not (tmp_path / "c.yaml").exists() and not (tmp_path / "m.png").exists()


def test_a_recording_of_another_table_is_refused_naming_both(tiny_recording, tmp_path, capsys):
    assert main(["inspect", str(tiny_recording), "--classes", str(EXAMPLE), "--no-preference", "--out", str(tmp_path / "p.png")]) == 2
    line = _one_error(capsys, str(tiny_recording), "non_traversable", str(EXAMPLE), "person")
    assert "classes" in line
    assert not (tmp_path / "p.png").exists()
    # The table the recording was made for is accepted.
    default_file = REPO / "src" / "terrapref" / "data" / "classes.yaml"
    assert main(["inspect", str(tiny_recording), "--classes", str(default_file), "--no-preference", "--out", str(tmp_path / "p.png")]) == 0


def test_evaluate_refuses_a_model_of_another_table(tmp_path, capsys):
    from helpers import linear_model

    course = tmp_path / "c.yaml"  # the example table's course, as `terrapref course --classes` writes it (without its picture)
    course.write_text(yaml.safe_dump(teaching_course(load_classes(EXAMPLE)).data(), sort_keys=False))
    model = linear_model(tmp_path / "m.safetensors")  # made for the default table
    capsys.readouterr()
    assert (
        main(["evaluate", str(model), str(course), "--classes", str(EXAMPLE), "--out", str(tmp_path / "ev"), "--seeds", "1", "--no-driver"])
        == 2
    )
    _one_error(capsys, str(model), "non_traversable", str(EXAMPLE), "person")
    assert not (tmp_path / "ev" / "metrics.json").exists()


# --- Label maps ----------------------------------------------------------------------------------


def test_the_example_label_map_maps_rellis_ids_onto_the_example_table(example):
    lut = load_label_map(str(EXAMPLE_LABELS), example).lut(example)
    assert lut[29] == lut[30] == example.id_of("grass")  # uphill, downhill
    assert lut[32] == example.id_of("water")  # deep water
    assert lut[31] == example.id_of("puddle")
    assert lut[4] == example.id_of("tree") and lut[19] == example.id_of("bush")
    with pytest.raises(ConfigError):
        load_label_map(str(EXAMPLE_LABELS), default_classes())  # its classes are not the default table's


def test_the_packaged_rellis_map_covers_uphill_downhill_and_deep_water():
    d = default_classes()
    lut = load_label_map("rellis3d", d).lut(d)
    assert lut[29] == lut[30] == d.id_of("grass")
    assert lut[32] == d.id_of("water")


# --- The identifiability report's background -----------------------------------------------------


def _evidence(first: str, second: str) -> PairEvidence:
    return PairEvidence(first, second, 12, 10, 2, (6, 6), 1.5, 0.3)


def test_identifiability_keeps_its_background_through_a_file():
    report = Identifiability(("sand", "mud", "lethal"), (_evidence("sand", "mud"), _evidence("mud", "lethal")), ("lethal",), "sand")
    data = report.to_dict()
    assert data["background"] == "sand"
    assert Identifiability.from_dict(json.loads(json.dumps(data))) == report
    # The default background stays out of the file, so that reports of the default table read as before.
    plain = Identifiability(("grass", "mud"), (_evidence("grass", "mud"),), ("non_traversable",))
    assert "background" not in plain.to_dict()
    assert Identifiability.from_dict(plain.to_dict()).background == GRASS


def test_identifiability_names_the_tables_background():
    rng = np.random.default_rng(0)
    n, m = 40, 5
    U = rng.uniform(0, 1, (n, m, 3))
    report = identifiability(
        U,
        rng.integers(0, m, n),
        ("mud", "lethal"),
        LinearUtility(np.array([-1.0, -3.0, 1.0]), np.zeros(m)),
        names=TableNames("sand", ("lethal",)),
    )
    assert report.order == ("sand", "mud", "lethal") and report.background == "sand"
    assert {frozenset((p.first, p.second)) for p in report.pairs} == {
        frozenset(p) for p in itertools.combinations(("sand", "mud", "lethal"), 2)
    }
    assert GRASS not in " ".join(report.lines())


def test_a_bad_colour_of_a_lethal_class_is_one_problem(tmp_path):
    path = _write_table(tmp_path, "grass", ["tree"], ["grass", "mud", "tree"])
    path.write_text(path.read_text().replace("name: tree, color: [2, 4, 6]", "name: tree, color: [2, 4]"))
    with pytest.raises(ConfigError) as caught:
        load_classes(path)
    lines = caught.value.lines()
    assert len(lines) == 1 and lines[0].startswith(f"{path}: classes[2].color: "), lines


def test_a_table_that_differs_only_in_colours_or_profile_is_the_same_table(tiny_recording, tmp_path, capsys):
    default_file = REPO / "src" / "terrapref" / "data" / "classes.yaml"
    text = (
        default_file.read_text()
        .replace("[92, 158, 70]", "[90, 160, 70]")
        .replace("profile: [mud, rock, water, non_traversable]", "profile: [rock, mud, water, non_traversable]")
    )
    recoloured = tmp_path / "recoloured.yaml"
    recoloured.write_text(text)
    table = load_classes(recoloured)
    assert table != default_classes() and table.same_classes(default_classes())
    assert main(["inspect", str(tiny_recording), "--classes", str(recoloured), "--no-preference", "--out", str(tmp_path / "p.png")]) == 0
    renamed = tmp_path / "renamed.yaml"
    renamed.write_text(default_file.read_text().replace("name: rock", "name: stone").replace("rock, water", "stone, water"))
    assert not load_classes(renamed).same_classes(default_classes())


def test_a_table_of_the_background_alone_is_refused(tmp_path):
    with pytest.raises(ConfigError) as caught:
        load_classes(_write_table(tmp_path, "grass", [], ["grass"]))
    assert "besides the background" in caught.value.lines()[0]


def test_a_presets_pose_camera_and_frames_suit_any_table(example):
    from terrapref.errors import UserError
    from terrapref.perception import load_perception

    for part in ("pose", "camera", "frames"):
        assert load_perception(f"field:{part}", example).active
    with pytest.raises(UserError):
        load_perception("field", example)  # its label errors name the default table's classes
    with pytest.raises(UserError):
        load_perception("field:labels", example)


def test_a_recording_whose_meta_names_no_class_table_is_one_line(tiny_recording, tmp_path, capsys):
    import json
    import shutil

    rec = tmp_path / "rec"
    shutil.copytree(tiny_recording, rec)
    meta = json.loads((rec / "meta.json").read_text())
    del meta["classes"]
    (rec / "meta.json").write_text(json.dumps(meta))
    for argv in (
        ["inspect", str(rec), "--no-preference", "--out", str(tmp_path / "p.png")],
        ["inspect", str(rec), "--classes", str(EXAMPLE), "--no-preference", "--out", str(tmp_path / "p.png")],
        ["export", str(rec), "--format", "mcap", "--out", str(tmp_path / "r.mcap")],
    ):
        assert main(argv) == 2
        _one_error(capsys, f"{rec / 'meta.json'}: classes: missing")


@pytest.mark.slow  # a whole drive or export end to end, its steps tested apart in the default run
def test_a_courses_table_goes_with_its_drive_to_the_follow_up_training_and_evaluation(tmp_path, capsys, tiny_recording):
    """The follow-up loop's steps on a 12 m course of the small table (the whole loop, two drives
    that together leave nothing open, is a slow test below): the course carries its table, so
    record, course --after, train and evaluate never need --classes; drives of two tables, or one
    drive twice, are refused in one line naming the file."""
    from helpers import TINY_COURSE
    from terrapref.scenario import resolve_scenario

    small = EXAMPLES / "small.yaml"
    course, me, more = tmp_path / "c.yaml", tmp_path / "me", tmp_path / "more.yaml"
    tiny = yaml.safe_load(TINY_COURSE.read_text())  # grass, mud and trees: the small table's, its trees called tree
    for patch in tiny["terrain"]:
        patch["class"] = {"non_traversable": "tree"}.get(patch["class"], patch["class"])
    course.write_text(yaml.safe_dump({**tiny, "classes": teaching_course(load_classes(small)).data()["classes"]}, sort_keys=False))
    assert main(["record", str(course), "--out", str(me), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["course", "--after", str(me), "--out", str(more)]) == 0
    printed, said = capsys.readouterr()
    assert "frames, then fitting them ..." in said.strip().splitlines()[-1]  # once featurised, the fit still to come is said
    left_open = "pairs open for a follow-up: "
    assert left_open in printed and "tree" in printed.split(left_open)[1].split(";")[0]  # no tree was driven beside
    assert _record_it(printed)[0] == str(more), "the command that works, not a --classes FILE placeholder"
    assert resolve_scenario(str(more)).classes == load_classes(small)
    assert main(["course", "--after", str(me), str(tiny_recording), "--out", str(tmp_path / "x.yaml")]) == 2
    _one_error(capsys, str(tiny_recording), "classes", "give drives of one table")
    assert main(["course", "--after", str(me), str(me), "--out", str(tmp_path / "x.yaml")]) == 2
    _one_error(capsys, str(me), "given twice")
    assert not (tmp_path / "x.yaml").exists()
    model = tmp_path / "m.safetensors"
    assert main(["train", str(me), "--recipe", "paper", "--epochs", "2", "--out", str(model)]) == 0
    assert main(["evaluate", str(model), str(course), "--seeds", "1", "--no-driver", "--out", str(tmp_path / "ev")]) == 0
    assert (tmp_path / "ev" / "metrics.json").is_file()
    capsys.readouterr()
    assert (
        main(
            ["evaluate", str(model), str(course), "--classes", str(EXAMPLE), "--seeds", "1", "--no-driver", "--out", str(tmp_path / "ev2")]
        )
        == 2
    )
    _one_error(capsys, str(model), "classes", str(EXAMPLE))
    assert not (tmp_path / "ev2").exists()


@pytest.mark.slow  # two drives of a teaching course and its follow-up; its steps run on a short course above
def test_the_follow_up_loop_runs_without_classes_and_asks_what_drives_leave_open_together(tmp_path, capsys, tiny_recording):
    """A course carries its table: record, course --after (of several drives), train and evaluate
    never need --classes again."""
    from terrapref.demos.recording import read_recording

    small = EXAMPLES / "small.yaml"
    course, me, more, me_more = tmp_path / "c.yaml", tmp_path / "me", tmp_path / "more.yaml", tmp_path / "me_more"
    assert main(["course", "--classes", str(small), "--out", str(course), "--design", "compact"]) == 0  # the shorter drive
    assert main(["record", str(course), "--out", str(me), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["course", "--after", str(me), "--out", str(more)]) == 0
    printed = capsys.readouterr().out
    assert (
        "the drive left 1 pair open for a follow-up: mud vs tree; beside them, their neighbours in the learned order: grass vs mud"
        in printed
    )
    course_named, flags = _record_it(printed)
    assert course_named == str(more), "the command that works, not a --classes FILE placeholder"
    assert main(["record", str(more), *flags, "--out", str(me_more), "--quiet"]) == 0  # as it says (the drive's order with it)
    assert read_recording(me_more).classes == load_classes(small)
    # Both drives together leave nothing open; nothing is written.
    assert main(["course", "--after", str(me), str(me_more), "--out", str(tmp_path / "more2.yaml")]) == 0
    assert "the drives together identified every pair of classes" in capsys.readouterr().out
    assert not (tmp_path / "more2.yaml").exists()
    # Drives of two tables, or one drive twice, are refused in one line naming the file.
    assert main(["course", "--after", str(me), str(tiny_recording), "--out", str(tmp_path / "x.yaml")]) == 2
    _one_error(capsys, str(tiny_recording), "classes", "give drives of one table")
    assert main(["course", "--after", str(me), str(me), "--out", str(tmp_path / "x.yaml")]) == 2
    _one_error(capsys, str(me), "given twice")
    assert not (tmp_path / "x.yaml").exists()
    # The model carries the table: evaluate reads the course with it, and a --classes of another table is refused.
    model = tmp_path / "m.safetensors"
    assert main(["train", str(me), str(me_more), "--recipe", "paper", "--epochs", "2", "--out", str(model)]) == 0
    assert main(["evaluate", str(model), str(more), "--seeds", "1", "--no-driver", "--out", str(tmp_path / "ev")]) == 0
    assert (tmp_path / "ev" / "metrics.json").is_file()
    capsys.readouterr()
    assert (
        main(["evaluate", str(model), str(more), "--classes", str(EXAMPLE), "--seeds", "1", "--no-driver", "--out", str(tmp_path / "ev2")])
        == 2
    )
    _one_error(capsys, str(model), "classes", str(EXAMPLE))
    assert not (tmp_path / "ev2").exists()


def test_course_after_names_what_no_further_course_settles_and_writes_nothing(tmp_path, capsys, monkeypatch, fig7_recording):
    """The loop ends when nothing is left that a course settles: the pairs left are named with their reasons."""
    import terrapref.recipes as recipes
    from terrapref.learning.identify import FollowUp

    why = "rock vs non_traversable: open before rec and after it (margin 0.10, 30 frames): driving it again would show the same"
    monkeypatch.setattr(recipes, "follow_up_plan", lambda *args, **kwargs: FollowUp(left=(why,)))
    assert main(["course", "--after", str(fig7_recording), "--out", str(tmp_path / "more.yaml")]) == 0
    assert capsys.readouterr().out.splitlines() == [
        f"note: {why}",
        "the drive left 1 pair open that a further drive of this loop would not settle (above); nothing written",
    ]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow  # whole drives of two courses; the ladder's own situations are tested apart in the default run
def test_the_ladder_follows_one_drive_of_a_table_too_large_for_the_full_design(tmp_path, capsys, monkeypatch, short_recording):
    """After one drive of a compact course (no strips) the follow-up shows the learned order's
    ladder instead of the open pairs' neighbours; after two drives, or of a table whose full design
    fits, it does not."""
    import terrapref.scenario.teaching as teaching
    from terrapref.demos.recording import read_recording
    from terrapref.recipes import DEFAULT_RECIPE, follow_up_plan, recipe_named

    rec, recipe, cache = read_recording(short_recording), recipe_named(DEFAULT_RECIPE), {}  # the drive featurised once
    as_drawn = follow_up_plan([rec], recipe, cache=cache)
    assert as_drawn.ladder == ()  # the default table's full design fits
    monkeypatch.setattr(teaching, "ladder_follows", lambda classes: True)  # as for a table of more classes (read when called)
    plan = follow_up_plan([rec], recipe, cache=cache)
    learned = list(plan.ladder)
    assert learned and set(learned) <= set(rec.classes.terrain_names) and plan.neighbours == () and plan.anything
    assert plan.open == as_drawn.open
    assert follow_up_plan([rec, rec], recipe, cache=cache).ladder == ()
    more = tmp_path / "more.yaml"
    assert main(["course", "--after", str(short_recording), "--out", str(more)]) == 0
    printed = capsys.readouterr().out
    assert f"its first follow-up shows the order the drive learned ({' > '.join(learned)}) as strips, and {learned[0]} alone" in printed
    labels = [z.label for z in resolve_scenario(str(more)).zones]
    assert f"{rec.classes.lethal[0]} | {learned[1]} | {learned[0]}" in labels  # the first step: the second class on the path


@pytest.mark.slow
def test_the_readmes_follow_up_loop_on_the_example_table_ends_after_one_follow_up(tmp_path, capsys):
    """README "Your own classes": the teaching drive, the follow-up course it asks for (its open
    pairs and the ladder), and then nothing a further course settles, as the README says; the two
    drives within 12 minutes."""
    from terrapref.demos.recording import read_recording

    profile = "mud,water,dirt,bush,puddle,gravel,lethal"
    course, me, more, me_more, more2 = (tmp_path / n for n in ("course.yaml", "me", "more.yaml", "me_more", "more2.yaml"))
    assert main(["course", "--classes", str(EXAMPLE), "--out", str(course)]) == 0
    assert main(["record", str(course), "--profile", profile, "--out", str(me), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["course", "--after", str(me), "--out", str(more)]) == 0
    assert "shows the order the drive learned (mud > water > dirt > bush > puddle > gravel) as strips" in capsys.readouterr().out
    assert main(["record", str(more), "--profile", profile, "--out", str(me_more), "--quiet"]) == 0
    assert main(["course", "--after", str(me), str(me_more), "--out", str(more2)]) == 0
    printed = capsys.readouterr().out
    assert "open that a further drive of this loop would not settle (above); nothing written" in printed and not more2.exists()
    assert sum(read_recording(r).duration_s for r in (me, me_more)) <= 12 * 60  # simulated time, not the test's


def test_a_scenario_carrying_a_bad_table_is_refused_naming_the_field(tmp_path, capsys):
    table = load_classes(EXAMPLES / "small.yaml")
    data = teaching_course(table).data()
    data["classes"]["background"] = "sand"
    bad = tmp_path / "c.yaml"
    bad.write_text(yaml.safe_dump(data, sort_keys=False))
    assert main(["record", str(bad), "--out", str(tmp_path / "rec")]) == 2
    _one_error(capsys, f"{bad}: classes.background: unknown class 'sand'")
    assert not (tmp_path / "rec").exists()
