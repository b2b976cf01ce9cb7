"""Tests for reading and validating ``terrapref-scenario/1`` files (SPEC section 11).

Every bad input must become a :class:`ScenarioError` naming the file and the field path of each
problem; nothing else may escape the loader. The fixtures are tiny scenarios built here.
"""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Any, Callable

import numpy as np
import pytest
import yaml

from helpers import REPO
from terrapref.errors import ConfigError, Problem, ScenarioError, UserError
from terrapref.scenario import (
    AVOID,
    BEST,
    FORMAT,
    Circle,
    Polygon,
    Rectangle,
    load_scenario,
    packaged_scenarios,
    parse_scenario,
    resolve_scenario,
)
from terrapref.scenario.catalog import scenario_path
from terrapref.scenario.generate import generate_course
from terrapref.scenario.loader import MAX_CELLS
from terrapref.scenario.relief import Mound, Noise, Plateau, Ridge
from terrapref.scenario.teaching import designed_course
from terrapref.terrain import default_classes, load_classes

# A 20 m x 10 m map with one patch of each shape type and one zone. Indices used below:
# terrain[0] circle, terrain[1] rectangle, terrain[2] polygon; zones[0] rectangle.
GOOD: dict[str, Any] = {
    "format": FORMAT,
    "name": "tiny_course",
    "description": "three patches and a zone",
    "world": {"size_m": [20.0, 10.0], "resolution_m": 0.1, "background": "grass"},
    "terrain": [
        {"class": "mud", "circle": {"center": [5.0, 5.0], "radius": 1.0}},
        {"class": "rock", "rectangle": {"center": [10.0, 5.0], "size": [2.0, 1.0], "yaw_deg": 30.0}},
        {"class": "water", "polygon": [[14.0, 4.0], [16.0, 4.0], [15.0, 6.0]]},
    ],
    "path": {"waypoints": [[1.0, 5.0], [19.0, 5.0]]},
    "zones": [{"id": "1", "label": "mud", "rectangle": {"center": [5.0, 5.0], "size": [4.0, 4.0]}, "expect": "best"}],
}

# The same scenario as YAML text, for the cases that need YAML syntax (.nan, .inf, raw bytes).
GOOD_YAML = """\
format: terrapref-scenario/1
name: tiny_course
world:
  size_m: [20.0, 10.0]
  resolution_m: 0.1
  background: grass
terrain:
  - {class: mud, circle: {center: [5.0, 5.0], radius: 1.0}}
  - {class: rock, rectangle: {center: [10.0, 5.0], size: [2.0, 1.0], yaw_deg: 30.0}}
  - {class: water, polygon: [[14.0, 4.0], [16.0, 4.0], [15.0, 6.0]]}
path:
  waypoints: [[1.0, 5.0], [19.0, 5.0]]
start: [1.0, 5.0, 0.0]
zones:
  - {id: "1", rectangle: {center: [5.0, 5.0], size: [4.0, 4.0]}, expect: best}
"""


def scenario(**changes: Any) -> dict[str, Any]:
    """A deep copy of GOOD with top-level keys replaced."""
    data = copy.deepcopy(GOOD)
    data.update(changes)
    return data


def edited(edit: Callable[[dict[str, Any]], Any]) -> dict[str, Any]:
    """A deep copy of GOOD changed in place by ``edit``."""
    data = copy.deepcopy(GOOD)
    edit(data)
    return data


def problems_of(data: dict[str, Any]) -> list[Problem]:
    """The problems parse_scenario reports for ``data`` (failing the test if it accepts it)."""
    with pytest.raises(ScenarioError) as info:
        parse_scenario(data, "x.yaml")
    assert info.value.source == "x.yaml"
    assert info.value.problems, "a ScenarioError must carry at least one problem"
    return list(info.value.problems)


def only_problem(data: dict[str, Any]) -> Problem:
    found = problems_of(data)
    assert len(found) == 1, found
    return found[0]


def write(tmp_path: Path, content: str | bytes, name: str = "s.yaml") -> Path:
    path = tmp_path / name
    if isinstance(content, str):
        path.write_text(content, encoding="utf-8")
    else:
        path.write_bytes(content)
    return path


def load_problems(path: Path) -> list[Problem]:
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    assert info.value.source == str(path)
    for line in info.value.lines():
        assert line.startswith(f"{path}: ")
        assert "\n" not in line
    return list(info.value.problems)


def yaml_problem(tmp_path: Path, old: str, new: str) -> Problem:
    """The single problem reported after replacing ``old`` by ``new`` in GOOD_YAML."""
    assert old in GOOD_YAML, old
    found = load_problems(write(tmp_path, GOOD_YAML.replace(old, new, 1)))
    assert len(found) == 1, found
    return found[0]


# --- good files -----------------------------------------------------------------------------


def test_good_scenario_parses_into_typed_fields() -> None:
    s = parse_scenario(copy.deepcopy(GOOD), "x.yaml")
    assert s.name == "tiny_course"
    assert s.description == "three patches and a zone"
    assert s.size_m == (20.0, 10.0)
    assert s.resolution_m == 0.1
    assert s.background == "grass"
    assert s.source == "x.yaml"
    assert s.grid_shape == (100, 200)
    assert [p.class_name for p in s.terrain] == ["mud", "rock", "water"]
    circle, rect, poly = (p.shape for p in s.terrain)
    assert isinstance(circle, Circle) and circle.center == (5.0, 5.0) and circle.radius_m == 1.0
    assert isinstance(rect, Rectangle) and rect.size == (2.0, 1.0)
    assert rect.yaw_rad == pytest.approx(math.radians(30.0))
    assert isinstance(poly, Polygon)
    np.testing.assert_array_equal(poly.vertices, [[14.0, 4.0], [16.0, 4.0], [15.0, 6.0]])
    np.testing.assert_array_equal(s.waypoints, [[1.0, 5.0], [19.0, 5.0]])
    assert s.waypoints.shape == (2, 2) and s.waypoints.dtype == np.float64
    assert s.path_length_m() == pytest.approx(18.0)
    assert len(s.zones) == 1
    zone = s.zones[0]
    assert (zone.id, zone.label, zone.expect) == ("1", "mud", BEST)


def test_good_yaml_file_loads(tmp_path: Path) -> None:
    path = write(tmp_path, GOOD_YAML)
    s = load_scenario(path)
    assert s.name == "tiny_course"
    assert s.source == str(path)
    assert s.start == (1.0, 5.0, 0.0)


def test_yml_suffix_and_str_path_load(tmp_path: Path) -> None:
    path = write(tmp_path, GOOD_YAML, "course.yml")
    assert load_scenario(str(path)).name == "tiny_course"


@pytest.mark.parametrize(
    ("waypoints", "yaw_rad"),
    [
        ([[1.0, 5.0], [19.0, 5.0]], 0.0),
        ([[1.0, 1.0], [1.0, 9.0]], math.pi / 2),
        ([[10.0, 5.0], [2.0, 5.0]], math.pi),
        ([[1.0, 1.0], [4.0, 5.0], [19.0, 1.0]], math.atan2(4.0, 3.0)),
        # A repeated first point: face the next distinct waypoint, not the duplicate.
        ([[1.0, 1.0], [1.0, 1.0], [4.0, 5.0]], math.atan2(4.0, 3.0)),
    ],
)
def test_start_defaults_to_first_waypoint_facing_the_next(waypoints: list, yaw_rad: float) -> None:
    data = scenario(path={"waypoints": waypoints})
    s = parse_scenario(data)
    assert s.start[:2] == tuple(waypoints[0])
    assert s.start[2] == pytest.approx(yaw_rad)


def test_explicit_start_yaw_is_given_in_degrees() -> None:
    s = parse_scenario(scenario(start=[3.0, 4.0, 90]))
    assert s.start[:2] == (3.0, 4.0)
    assert s.start[2] == pytest.approx(math.pi / 2)


def test_rectangle_yaw_defaults_to_zero() -> None:
    data = edited(lambda d: d["terrain"][1]["rectangle"].pop("yaw_deg"))
    rect = parse_scenario(data).terrain[1].shape
    assert isinstance(rect, Rectangle)
    assert rect.yaw_rad == 0.0


@pytest.mark.parametrize("zones", ["absent", None, []])
def test_zones_are_optional(zones: Any) -> None:
    data = scenario(zones=zones)
    if zones == "absent":
        del data["zones"]
    assert parse_scenario(data).zones == ()


def test_description_is_optional() -> None:
    data = scenario()
    del data["description"]
    assert parse_scenario(data).description == ""


def test_integer_zone_ids_are_accepted_as_strings() -> None:
    data = edited(lambda d: d["zones"][0].update(id=5))
    zone = parse_scenario(data).zones[0]
    assert zone.id == "5"
    assert isinstance(zone.id, str)


def test_zone_label_defaults_to_empty_and_expect_accepts_avoid_best_and_classes() -> None:
    zones = [
        {"id": "a", "circle": {"center": [5.0, 5.0], "radius": 2.0}, "expect": "avoid"},
        {"id": "b", "polygon": [[8.0, 3.0], [12.0, 3.0], [10.0, 7.0]], "expect": "best"},
        {"id": "c", "rectangle": {"center": [15.0, 5.0], "size": [3.0, 3.0], "yaw_deg": 45}, "expect": "water"},
        {"id": "d", "circle": {"center": [18.0, 5.0], "radius": 1.0}, "expect": "grass"},
    ]
    s = parse_scenario(scenario(zones=zones))
    assert [(z.id, z.label, z.expect) for z in s.zones] == [("a", "", AVOID), ("b", "", BEST), ("c", "", "water"), ("d", "", "grass")]
    assert [type(z.shape) for z in s.zones] == [Circle, Polygon, Rectangle, Circle]


def test_integers_are_accepted_where_numbers_are_expected() -> None:
    data = edited(lambda d: d["world"].update(size_m=[20, 10], resolution_m=1))
    s = parse_scenario(data)
    assert s.size_m == (20.0, 10.0) and s.resolution_m == 1.0
    assert all(isinstance(v, float) for v in s.size_m)


def test_shape_partly_on_the_map_is_accepted() -> None:
    # The circle's centre is off the map but it overlaps the map's left edge.
    data = edited(lambda d: d["terrain"][0]["circle"].update(center=[-0.5, 5.0]))
    assert isinstance(parse_scenario(data).terrain[0].shape, Circle)


def test_waypoints_on_the_map_edges_are_accepted() -> None:
    data = scenario(path={"waypoints": [[0.0, 0.0], [20.0, 10.0]]})
    np.testing.assert_array_equal(parse_scenario(data).waypoints, [[0.0, 0.0], [20.0, 10.0]])


def test_raster_of_exactly_the_limit_is_accepted() -> None:
    # 500 m / 0.05 m = 10,000 cells a side: exactly MAX_CELLS = 10^8, which is allowed.
    data = edited(lambda d: d["world"].update(size_m=[500.0, 500.0], resolution_m=0.05))
    s = parse_scenario(data)
    assert s.grid_shape == (10_000, 10_000)
    assert s.grid_shape[0] * s.grid_shape[1] == MAX_CELLS


def test_to_dict_round_trips_through_the_loader() -> None:
    s = parse_scenario(scenario(start=[2.0, 3.0, 45.0]))
    d = s.to_dict()
    again = parse_scenario(copy.deepcopy(d), "again.yaml")
    assert again.to_dict() == d
    assert d["format"] == FORMAT
    assert d["name"] == "tiny_course"
    assert d["description"] == "three patches and a zone"


def test_to_dict_round_trips_through_yaml_text(tmp_path: Path) -> None:
    s = parse_scenario(copy.deepcopy(GOOD))
    path = write(tmp_path, yaml.safe_dump(s.to_dict(), sort_keys=False))
    assert load_scenario(path).to_dict() == s.to_dict()


def test_to_dict_round_trip_with_defaults_filled_in() -> None:
    # Defaults (start, yaw_deg, no zones, no description) come back explicit and stable.
    data = scenario()
    for key in ("description", "zones"):
        del data[key]
    data["terrain"][1]["rectangle"].pop("yaw_deg")
    d = parse_scenario(data).to_dict()
    assert d["start"] == [1.0, 5.0, 0.0]
    assert d["terrain"][1]["rectangle"]["yaw_deg"] == 0.0
    assert d["zones"] == []
    assert "description" not in d
    assert parse_scenario(copy.deepcopy(d)).to_dict() == d


# --- packaged scenarios -----------------------------------------------------------------------


def test_packaged_scenarios_are_listed_sorted() -> None:
    names = packaged_scenarios()
    assert "demo_course" in names
    assert names == sorted(names)


@pytest.mark.parametrize("name", packaged_scenarios())
def test_every_packaged_scenario_validates_and_round_trips(name: str) -> None:
    s = resolve_scenario(name)
    assert s.name == name
    assert len(s.waypoints) >= 2
    d = s.to_dict()
    assert parse_scenario(copy.deepcopy(d)).to_dict() == d


def test_packaged_name_resolves_to_its_file() -> None:
    path = scenario_path("demo_course")
    assert path.name == "demo_course.yaml"
    assert path.is_file()
    assert load_scenario(path).name == "demo_course"


def test_path_to_a_file_resolves_to_that_file(tmp_path: Path) -> None:
    path = write(tmp_path, GOOD_YAML)
    assert resolve_scenario(str(path)).name == "tiny_course"


@pytest.mark.parametrize("name", ["no_such_course", "demo-course", "DEMO_COURSE"])
def test_unknown_packaged_name_is_a_user_error_naming_the_input(name: str) -> None:
    with pytest.raises(ScenarioError) as info:
        resolve_scenario(name)
    assert isinstance(info.value, UserError)
    assert info.value.source == name
    (line,) = info.value.lines()
    assert line.startswith(f"{name}: ")
    assert "demo_course" in line  # lists what is packaged


def test_unknown_yaml_path_is_a_user_error_naming_the_input() -> None:
    with pytest.raises(ScenarioError) as info:
        resolve_scenario("missing_course.yaml")
    assert info.value.lines() == ["missing_course.yaml: no such file"]


def test_name_too_long_for_the_os_is_reported_not_raised() -> None:
    name = "a" * 300  # longer than any file name the OS accepts
    with pytest.raises(ScenarioError) as info:
        resolve_scenario(name)
    (line,) = info.value.lines()
    assert line.startswith(f"{name}: ")


# --- unreadable files -------------------------------------------------------------------------


def test_nonexistent_file(tmp_path: Path) -> None:
    path = tmp_path / "nope.yaml"
    assert load_problems(path) == [Problem("", "no such file")]


def test_directory_instead_of_file(tmp_path: Path) -> None:
    folder = tmp_path / "course.yaml"
    folder.mkdir()
    (problem,) = load_problems(folder)
    assert problem.field == ""
    assert "directory" in problem.message


@pytest.mark.parametrize("content", [b"", b"\n\n  \t\n"], ids=["empty", "whitespace"])
def test_empty_file(tmp_path: Path, content: bytes) -> None:
    assert load_problems(write(tmp_path, content)) == [Problem("", "empty file")]


def test_comment_only_file_is_not_a_mapping(tmp_path: Path) -> None:
    (problem,) = load_problems(write(tmp_path, "# nothing here\n"))
    assert problem.field == ""
    assert "expected a mapping" in problem.message


def test_binary_garbage_with_nul_bytes(tmp_path: Path) -> None:
    data = np.random.default_rng(0).integers(0, 256, 4096, dtype=np.uint8).tobytes()
    assert b"\x00" in data
    (problem,) = load_problems(write(tmp_path, data, "garbage.yaml"))
    assert problem.field == ""
    assert "binary" in problem.message


def test_utf16_text_counts_as_binary(tmp_path: Path) -> None:
    (problem,) = load_problems(write(tmp_path, GOOD_YAML.encode("utf-16")))
    assert "binary" in problem.message


@pytest.mark.parametrize(
    "content",
    [b"name: caf\xe9\n", b"\xff\xfe\xfd\xfc garbage \x80\x81", "name: na\xefve\n".encode("latin-1")],
    ids=["latin1", "high-bytes", "latin1-2"],
)
def test_non_utf8_bytes_without_nul(tmp_path: Path, content: bytes) -> None:
    assert b"\x00" not in content
    (problem,) = load_problems(write(tmp_path, content))
    assert problem.field == ""
    assert "not UTF-8" in problem.message


def test_utf8_byte_order_mark_is_accepted(tmp_path: Path) -> None:
    path = write(tmp_path, b"\xef\xbb\xbf" + GOOD_YAML.encode("utf-8"))
    assert load_scenario(path).name == "tiny_course"


@pytest.mark.parametrize(
    ("content", "where"),
    [
        ("format: terrapref-scenario/1\nworld: [1, 2\n", "line 3"),
        ("format: terrapref-scenario/1\nworld:\n\tsize_m: [1, 2]\n", "line 3"),
        ("format: terrapref-scenario/1\nname: a\n  bad: indent\n", "line 3"),
        ("format: terrapref-scenario/1\nname: 'unterminated\n", ""),
        ("a: *undefined_alias\n", "line 1"),
        ("? [a, b]\n: 1\n", "line 1"),
        ("format: terrapref-scenario/1\nname: a\x07b\n", ""),
    ],
    ids=["unclosed-list", "tab-indent", "bad-indent", "unterminated-quote", "undefined-alias", "unhashable-key", "control-char"],
)
def test_malformed_yaml(tmp_path: Path, content: str, where: str) -> None:
    (problem,) = load_problems(write(tmp_path, content))
    assert problem.field == ""
    assert problem.message.startswith("malformed YAML")
    assert where in problem.message


@pytest.mark.parametrize(
    "value",
    ["2020-13-45", "2020-02-30", "2020-01-01 25:61:61", "!!int abc", "!!float abc", "!!bool maybe", "!!timestamp never"],
)
def test_yaml_value_the_parser_cannot_build(tmp_path: Path, value: str) -> None:
    (problem,) = load_problems(write(tmp_path, f"format: terrapref-scenario/1\nname: {value}\n"))
    assert problem.field == ""
    assert problem.message.startswith("malformed YAML")


def test_python_tags_are_refused_not_executed(tmp_path: Path) -> None:
    marker = tmp_path / "pwned"
    content = f"format: terrapref-scenario/1\nname: !!python/object/apply:os.system ['touch {marker}']\n"
    (problem,) = load_problems(write(tmp_path, content))
    assert problem.message.startswith("malformed YAML")
    assert not marker.exists()


@pytest.mark.parametrize("depth", [201, 5_000, 200_000])  # the last is past what libyaml's composer's stack holds
def test_deeply_nested_yaml(tmp_path: Path, depth: int) -> None:
    content = "format: terrapref-scenario/1\nname: " + "[" * depth + "]" * depth + "\n"
    (problem,) = load_problems(write(tmp_path, content))
    assert problem.message == "malformed YAML at line 2, column 206: nested more than 200 levels deep"


def test_nesting_as_deep_as_allowed_reads() -> None:
    from terrapref.yamlio import MAX_DEPTH, load_yaml_text

    levels = MAX_DEPTH - 1  # mappings, the list the last one holds the last level
    block = "".join(f"{'  ' * i}k:\n" for i in range(levels - 1)) + "  " * (levels - 1) + "k: [1]\n"
    data = load_yaml_text(block)
    for _ in range(levels - 1):
        data = data["k"]
    assert data == {"k": [1]}


@pytest.mark.parametrize(("content", "kind"), [("- a\n- b\n", "a list"), ("just text\n", "a string"), ("42\n", "a number")])
def test_top_level_must_be_a_mapping(tmp_path: Path, content: str, kind: str) -> None:
    assert load_problems(write(tmp_path, content)) == [Problem("", f"expected a mapping at the top level, got {kind}")]


# --- format -----------------------------------------------------------------------------------


def test_missing_format() -> None:
    data = scenario()
    del data["format"]
    problem = only_problem(data)
    assert problem.field == "format"
    assert problem.message.startswith("missing")
    assert FORMAT in problem.message


@pytest.mark.parametrize("value", ["terrapref-scenario/2", "terrapref-classes/1", "", 1, ["terrapref-scenario/1"]])
def test_wrong_format(value: Any) -> None:
    problem = only_problem(scenario(format=value))
    assert problem.field == "format"
    assert "is not supported" in problem.message
    assert repr(value) in problem.message


def test_wrong_format_in_a_file(tmp_path: Path) -> None:
    path = write(tmp_path, GOOD_YAML.replace("terrapref-scenario/1", "terrapref-scenario/9"))
    (problem,) = load_problems(path)
    assert problem.field == "format"
    assert "'terrapref-scenario/9' is not supported" in problem.message


# --- missing and unknown keys -----------------------------------------------------------------


def _delete(*keys: str | int) -> Callable[[dict[str, Any]], None]:
    def edit(d: dict[str, Any]) -> None:
        target: Any = d
        for key in keys[:-1]:
            target = target[key]
        del target[keys[-1]]

    return edit


@pytest.mark.parametrize(
    ("keys", "field"),
    [
        (("name",), "name"),
        (("world",), "world"),
        (("path",), "path"),
        (("world", "size_m"), "world.size_m"),
        (("world", "resolution_m"), "world.resolution_m"),
        (("world", "background"), "world.background"),
        (("path", "waypoints"), "path.waypoints"),
        (("terrain", 0, "class"), "terrain[0].class"),
        (("terrain", 0, "circle", "radius"), "terrain[0].circle.radius"),
        (("terrain", 0, "circle", "center"), "terrain[0].circle.center"),
        (("terrain", 1, "rectangle", "size"), "terrain[1].rectangle.size"),
        (("terrain", 1, "rectangle", "center"), "terrain[1].rectangle.center"),
        (("zones", 0, "id"), "zones[0].id"),
        (("zones", 0, "expect"), "zones[0].expect"),
    ],
)
def test_missing_required_key(keys: tuple, field: str) -> None:
    assert only_problem(edited(_delete(*keys))) == Problem(field, "missing")


@pytest.mark.parametrize(
    ("keys", "field"),
    [(("terrain", 0, "circle"), "terrain[0]"), (("zones", 0, "rectangle"), "zones[0]")],
)
def test_missing_shape(keys: tuple, field: str) -> None:
    problem = only_problem(edited(_delete(*keys)))
    assert problem.field == field
    assert "expected exactly one of polygon, circle, rectangle, got 0" in problem.message


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (lambda d: d.update(colour="red"), "colour"),
        (lambda d: d.update(Name="x"), "Name"),
        (lambda d: d["world"].update(origin=[0, 0]), "world.origin"),
        (lambda d: d["path"].update(speed=1.0), "path.speed"),
        (lambda d: d["terrain"][0].update(height=2.0), "terrain[0].height"),
        (lambda d: d["terrain"][0]["circle"].update(yaw_deg=3.0), "terrain[0].circle.yaw_deg"),
        (lambda d: d["terrain"][1]["rectangle"].update(angle=3.0), "terrain[1].rectangle.angle"),
        (lambda d: d["zones"][0].update(weight=1), "zones[0].weight"),
        (lambda d: d["zones"][0]["rectangle"].update(radius=1), "zones[0].rectangle.radius"),
    ],
)
def test_unknown_key(edit: Callable, field: str) -> None:
    assert only_problem(edited(edit)) == Problem(field, "unknown key")


def test_unknown_non_string_keys_are_named() -> None:
    found = problems_of(edited(lambda d: d.update({1: "a", None: "b"})))
    assert sorted(p.field for p in found) == ["1", "None"]
    assert all(p.message == "unknown key" for p in found)


def test_unknown_key_with_a_newline_stays_on_one_line() -> None:
    problem = only_problem(edited(lambda d: d.update({"a\nb": 1})))
    assert problem.message == "unknown key"
    assert "\n" not in problem.format("x.yaml")
    assert "a\\nb" in problem.field


def test_two_shapes_in_one_item() -> None:
    data = edited(lambda d: d["terrain"][0].update(polygon=[[1.0, 1.0], [2.0, 1.0], [1.0, 2.0]]))
    problem = only_problem(data)
    assert problem.field == "terrain[0]"
    assert "got 2" in problem.message


# --- wrong types ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("edit", "field", "message"),
    [
        (lambda d: d["world"].update(resolution_m="fine"), "world.resolution_m", "expected a number, got string 'fine'"),
        (lambda d: d["world"].update(resolution_m=True), "world.resolution_m", "expected a number, got boolean True"),
        (lambda d: d["world"].update(resolution_m=None), "world.resolution_m", "expected a number, got nothing"),
        (lambda d: d["terrain"][0]["circle"].update(radius="1.5"), "terrain[0].circle.radius", "expected a number, got string '1.5'"),
        (lambda d: d["terrain"][0]["circle"].update(radius=False), "terrain[0].circle.radius", "expected a number, got boolean False"),
        (
            lambda d: d["terrain"][1]["rectangle"].update(yaw_deg="north"),
            "terrain[1].rectangle.yaw_deg",
            "expected a number, got string 'north'",
        ),
        (lambda d: d["world"].update(size_m=20.0), "world.size_m", "expected a list of 2 numbers, got number 20.0"),
        (lambda d: d["world"].update(size_m=[20.0, 10.0, 5.0]), "world.size_m", "expected a list of 2 numbers, got a list of 3"),
        (lambda d: d["world"].update(size_m={"x": 20, "y": 10}), "world.size_m", "expected a list of 2 numbers, got a mapping"),
        (lambda d: d["world"].update(size_m=[20.0, "ten"]), "world.size_m[1]", "expected a number, got string 'ten'"),
        (
            lambda d: d["terrain"][0]["circle"].update(center=[5.0, True]),
            "terrain[0].circle.center[1]",
            "expected a number, got boolean True",
        ),
        (lambda d: d.update(terrain={"class": "mud"}), "terrain", "expected a list, got a mapping"),
        (lambda d: d.update(terrain=None), "terrain", "expected a list, got nothing"),
        (lambda d: d.update(zones={"id": "1"}), "zones", "expected a list, got a mapping"),
        (
            lambda d: d["path"].update(waypoints={"a": [1, 2]}),
            "path.waypoints",
            "expected a list of at least 2 [x, y] points, got a mapping",
        ),
        (lambda d: d["path"].update(waypoints=[[1.0, 5.0], "end"]), "path.waypoints[1]", "expected a list of 2 numbers, got string 'end'"),
        (
            lambda d: d["path"].update(waypoints=[[1.0, 5.0], [19.0, 5.0, 0.0]]),
            "path.waypoints[1]",
            "expected a list of 2 numbers, got a list of 3",
        ),
        (lambda d: d.update(world=[20.0, 10.0]), "world", "expected a mapping, got a list of 2"),
        (lambda d: d.update(path=[[1.0, 5.0], [19.0, 5.0]]), "path", "expected a mapping, got a list of 2"),
        (lambda d: d["terrain"].__setitem__(0, "mud"), "terrain[0]", "expected a mapping, got string 'mud'"),
        (lambda d: d["terrain"][0].update(circle=[5.0, 5.0, 1.0]), "terrain[0].circle", "expected a mapping, got a list of 3"),
        (
            lambda d: d["terrain"][2].update(polygon={"a": 1}),
            "terrain[2].polygon",
            "expected a list of at least 3 [x, y] points, got a mapping",
        ),
        (
            lambda d: d["terrain"][2]["polygon"].__setitem__(1, [16.0]),
            "terrain[2].polygon[1]",
            "expected a list of 2 numbers, got a list of 1",
        ),
        (lambda d: d.update(name=5), "name", "expected a string, got number 5"),
        (lambda d: d.update(description=["a"]), "description", "expected a string, got a list of 1"),
        (lambda d: d.update(start=[1.0, 5.0]), "start", "expected a list of 3 numbers, got a list of 2"),
        (lambda d: d.update(start=[1.0, 5.0, "east"]), "start[2]", "expected a number, got string 'east'"),
        (lambda d: d["zones"][0].update(label=7), "zones[0].label", "expected a string, got number 7"),
        (lambda d: d["zones"][0].update(id=[1]), "zones[0].id", "expected a string, got a list of 1"),
        (lambda d: d["zones"][0].update(id=True), "zones[0].id", "expected a string, got boolean True"),
        (lambda d: d["zones"][0].update(id=1.5), "zones[0].id", "expected a string, got number 1.5"),
        (lambda d: d["zones"].__setitem__(0, ["1", "best"]), "zones[0]", "expected a mapping, got a list of 2"),
    ],
)
def test_wrong_type(edit: Callable, field: str, message: str) -> None:
    assert only_problem(edited(edit)) == Problem(field, message)


def test_huge_integer_is_too_large_not_a_crash() -> None:
    data = edited(lambda d: d["terrain"][0]["circle"].update(radius=10**400))
    assert only_problem(data) == Problem("terrain[0].circle.radius", "is too large")


def test_integers_too_long_to_print_are_reported(tmp_path: Path) -> None:
    # Python refuses to turn an int of more than 4300 digits into text; the messages must cope.
    big = "0x" + "f" * 5_000
    text = GOOD_YAML.replace('id: "1"', f"id: {big}").replace("expect: best", f"expect: {big}").replace("name: tiny_course", f"name: {big}")
    found = load_problems(write(tmp_path, text))
    assert {p.field for p in found} == {"name", "zones[0].expect"}


# --- NaN and infinity ---------------------------------------------------------------------------


@pytest.mark.parametrize("value", [".nan", ".NaN", ".inf", "-.inf", "+.inf", ".Inf", "1.0e+400"])
@pytest.mark.parametrize(
    ("old", "template", "field"),
    [
        ("radius: 1.0", "radius: {}", "terrain[0].circle.radius"),
        ("resolution_m: 0.1", "resolution_m: {}", "world.resolution_m"),
        ("size_m: [20.0, 10.0]", "size_m: [{}, 10.0]", "world.size_m[0]"),
        ("yaw_deg: 30.0", "yaw_deg: {}", "terrain[1].rectangle.yaw_deg"),
        ("[16.0, 4.0]", "[16.0, {}]", "terrain[2].polygon[1][1]"),
        ("[19.0, 5.0]]", "[{}, 5.0]]", "path.waypoints[1][0]"),
        ("start: [1.0, 5.0, 0.0]", "start: [1.0, 5.0, {}]", "start[2]"),
        ("center: [5.0, 5.0], size: [4.0, 4.0]", "center: [{}, 5.0], size: [4.0, 4.0]", "zones[0].rectangle.center[0]"),
    ],
)
def test_non_finite_numbers(tmp_path: Path, value: str, old: str, template: str, field: str) -> None:
    problem = yaml_problem(tmp_path, old, template.format(value))
    assert problem == Problem(field, "must be finite (got NaN or infinity)")


# --- classes and names ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("edit", "field", "shown"),
    [
        (lambda d: d["terrain"][0].update({"class": "lava"}), "terrain[0].class", "'lava'"),
        (lambda d: d["terrain"][0].update({"class": "Mud"}), "terrain[0].class", "'Mud'"),
        (lambda d: d["world"].update(background="snow"), "world.background", "'snow'"),
        (lambda d: d["world"].update(background="unknown"), "world.background", "'unknown'"),
    ],
)
def test_unknown_class_name(edit: Callable, field: str, shown: str) -> None:
    problem = only_problem(edited(edit))
    assert problem.field == field
    assert problem.message.startswith(f"unknown class {shown}")
    assert "grass, non_traversable, water, rock, mud" in problem.message  # lists the known ones


def test_class_given_as_a_number() -> None:
    data = edited(lambda d: d["terrain"][0].update({"class": 4}))
    assert only_problem(data) == Problem("terrain[0].class", "expected a string, got number 4")


@pytest.mark.parametrize("name", ["my course", "café", "a/b", "a.b", "", "course\n", "\ncourse", "x" * 3 + "!"])
def test_bad_name(name: str) -> None:
    assert only_problem(scenario(name=name)) == Problem("name", "must match [A-Za-z0-9_-]+")


@pytest.mark.parametrize("name", ["a", "A-b_9", "0", "demo_course"])
def test_good_name(name: str) -> None:
    assert parse_scenario(scenario(name=name)).name == name


# --- geometry ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("vertices", "message"),
    [
        ([[1.0, 1.0], [2.0, 1.0]], "expected a list of at least 3 [x, y] points, got a list of 2"),
        ([], "expected a list of at least 3 [x, y] points, got a list of 0"),
        ([[1.0, 1.0], [2.0, 1.0], [1.0, 1.0]], "needs at least 3 distinct vertices, got 2"),
        ([[1.0, 1.0], [1.0, 1.0], [1.0, 1.0], [1.0, 1.0]], "needs at least 3 distinct vertices, got 1"),
        ([[1.0, 1.0], [2.0, 2.0], [3.0, 3.0]], "has zero area (vertices are collinear)"),
        ([[1.0, 1.0], [5.0, 1.0], [3.0, 1.0], [2.0, 1.0]], "has zero area (vertices are collinear)"),
        ([[0.1, 0.3], [0.7, 2.1], [1.3, 3.9]], "has zero area (vertices are collinear)"),
        (
            [[1.0, 1.0], [3.0, 3.0], [3.0, 1.0], [1.0, 3.0]],  # a bow tie: its halves' areas cancel
            "has zero area: it crosses itself (its edge from vertex 0 crosses the one from vertex 2) and its parts cancel; "
            "give the vertices in order round it",
        ),
    ],
    ids=["two-vertices", "none", "duplicate", "all-same", "collinear", "collinear-4", "collinear-decimals", "bow-tie"],
)
def test_degenerate_polygon(vertices: list, message: str) -> None:
    data = edited(lambda d: d["terrain"][2].update(polygon=vertices))
    assert only_problem(data) == Problem("terrain[2].polygon", message)


def test_collinear_polygon_far_from_the_origin() -> None:
    # Exactly collinear in decimal, but the shoelace sum in floats leaves ~4e-9 m^2 at these
    # coordinates; an absolute tolerance alone lets this through.
    data = edited(lambda d: d["world"].update(size_m=[5000.0, 4000.0], resolution_m=1.0))
    data["terrain"][2]["polygon"] = [[4000.7, 3000.9], [4011.0, 3021.6], [4021.3, 3042.3]]
    assert only_problem(data) == Problem("terrain[2].polygon", "has zero area (vertices are collinear)")


def test_small_but_real_polygon_is_accepted() -> None:
    data = edited(lambda d: d["terrain"][2].update(polygon=[[1.0, 1.0], [1.001, 1.0], [1.0, 1.001]]))
    assert isinstance(parse_scenario(data).terrain[2].shape, Polygon)


def test_huge_polygon_covering_the_map_is_accepted() -> None:
    # Scaling the tolerance with the coordinates must not overflow for extreme (finite) values.
    data = edited(lambda d: d["terrain"][2].update(polygon=[[-1e200, -1e200], [1e200, -1e200], [0.0, 1e200]]))
    assert isinstance(parse_scenario(data).terrain[2].shape, Polygon)


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (lambda d: d["terrain"][0]["circle"].update(center=[30.0, 5.0]), "terrain[0].circle"),
        (lambda d: d["terrain"][0]["circle"].update(center=[-2.0, 5.0]), "terrain[0].circle"),
        (lambda d: d["terrain"][1]["rectangle"].update(center=[10.0, -5.0]), "terrain[1].rectangle"),
        (lambda d: d["terrain"][1]["rectangle"].update(center=[10.0, 12.0]), "terrain[1].rectangle"),
        (lambda d: d["terrain"][2].update(polygon=[[100.0, 1.0], [110.0, 1.0], [105.0, 9.0]]), "terrain[2].polygon"),
        (lambda d: d["zones"][0]["rectangle"].update(center=[50.0, 50.0]), "zones[0].rectangle"),
    ],
)
def test_shape_wholly_off_the_map(edit: Callable, field: str) -> None:
    problem = only_problem(edited(edit))
    assert problem.field == field
    assert problem.message.startswith("lies wholly off the map")
    assert "map 0..20 x 0..10" in problem.message


@pytest.mark.parametrize(
    ("waypoints", "field", "shown"),
    [
        ([[1.0, 5.0], [25.0, 5.0]], "path.waypoints[1]", "(25, 5)"),
        ([[-1.0, 5.0], [19.0, 5.0]], "path.waypoints[0]", "(-1, 5)"),
        ([[1.0, 5.0], [10.0, 10.5], [19.0, -3.0]], "path.waypoints[1]", "(10, 10.5)"),
    ],
)
def test_waypoints_off_the_map(waypoints: list, field: str, shown: str) -> None:
    data = scenario(path={"waypoints": waypoints})
    del data["zones"]
    problem = only_problem(data)
    assert problem.field == field
    assert problem.message.startswith(f"{shown} is off the map")


def test_start_off_the_map() -> None:
    problem = only_problem(scenario(start=[30.0, 5.0, 0.0]))
    assert problem.field == "start"
    assert "off the map" in problem.message


@pytest.mark.parametrize(("yaw_deg", "refused"), [(1e6, False), (-1e6, False), (1.0000001e6, True), (-1e308, True)])
def test_a_start_heading_past_a_million_degrees_is_refused(yaw_deg: float, refused: bool) -> None:
    data = scenario(start=[2.0, 5.0, yaw_deg])
    if not refused:
        assert parse_scenario(data, "x.yaml").start[2] == math.radians(yaw_deg)
        return
    problem = only_problem(data)
    assert (problem.field, problem.message) == ("start[2]", f"the heading must be within +-1,000,000 deg, got {yaw_deg:g}")


# Trees (lethal) over x 8-12 m, y 7-10 m; the footprint is the line 0.6 m either side of the start,
# and a point counts where its 0.1 m cell's centre is under the trees, as the simulator reads it.
TREES = {"class": "non_traversable", "rectangle": {"center": [10.0, 8.5], "size": [4.0, 3.0]}}


@pytest.mark.parametrize(
    ("start", "lethal"),
    [
        ([10.0, 8.5, 0.0], True),  # inside the trees
        ([10.0, 6.45, 0.0], True),  # the footprint's left end at y 7.05 m: under the trees
        ([10.0, 6.35, 0.0], False),  # its left end at y 6.95 m: its cell's centre below their edge
        ([10.0, 6.45, 90.0], False),  # facing them: the footprint lies along y = 6.45 m
        ([7.55, 8.5, 90.0], True),  # beside them, facing along them: its right end at x 8.15 m
        ([7.35, 8.5, 90.0], False),
    ],
)
def test_a_start_that_puts_the_footprint_on_lethal_terrain_is_refused(start: list, lethal: bool) -> None:
    data = scenario(terrain=[*GOOD["terrain"], TREES], start=start)
    if not lethal:
        assert parse_scenario(data).start[:2] == tuple(start[:2])
        return
    problem = only_problem(data)
    assert problem.field == "start"
    assert problem.message.startswith(
        f"({start[0]:g}, {start[1]:g}) (given) puts the vehicle's footprint on lethal terrain (non_traversable)"
    )


def test_the_default_start_on_lethal_terrain_is_refused_and_a_recordings_scenario_is_read() -> None:
    data = scenario(terrain=[*GOOD["terrain"], TREES], path={"waypoints": [[10.0, 8.5], [19.0, 5.0]]})
    problem = only_problem(data)
    assert problem.field == "start" and "(the first waypoint, facing the second)" in problem.message
    assert parse_scenario(data, driven=True).start[:2] == (10.0, 8.5)  # a drive already made from there stays readable


def test_generated_layouts_and_teaching_courses_start_clear_of_lethal_terrain() -> None:
    """Each is read as every command reads it, which refuses a start on lethal terrain (the
    packaged scenarios: test_every_packaged_scenario_validates_and_round_trips)."""
    rellis = load_classes(REPO / "examples" / "classes" / "rellis3d.yaml")
    for seed in range(0, 2048, 32):  # the layouts for choosing (gen:1000-) and for checking (gen:2000-) among them
        generate_course(seed)
    for seed in range(16):
        generate_course(seed, classes=rellis)
    for table in (default_classes(), rellis):
        for design in ("full", "compact"):
            parse_scenario(designed_course(table, design)[0].data(), "course", table)


def test_a_later_patch_over_the_trees_clears_the_start() -> None:
    grass = {"class": "grass", "rectangle": {"center": [10.0, 8.5], "size": [2.0, 2.0]}}  # painted last, as the raster is
    assert parse_scenario(scenario(terrain=[TREES, grass], start=[10.0, 8.5, 0.0])).start[:2] == (10.0, 8.5)


@pytest.mark.parametrize(
    ("waypoints", "message"),
    [
        ([[1.0, 1.0], [1.0, 1.0]], "needs at least 2 distinct points"),
        ([[3.0, 4.0], [3.0, 4.0], [3.0, 4.0]], "needs at least 2 distinct points"),
        ([[1.0, 1.0]], "expected a list of at least 2 [x, y] points, got a list of 1"),
        ([], "expected a list of at least 2 [x, y] points, got a list of 0"),
        (None, "expected a list of at least 2 [x, y] points, got nothing"),
    ],
    ids=["two-same", "three-same", "one", "empty", "null"],
)
def test_path_needs_two_distinct_points(waypoints: Any, message: str) -> None:
    assert only_problem(scenario(path={"waypoints": waypoints})) == Problem("path.waypoints", message)


@pytest.mark.parametrize("value", [0, 0.0, -0.05, -1])
def test_resolution_must_be_positive(value: float) -> None:
    data = edited(lambda d: d["world"].update(resolution_m=value))
    assert only_problem(data) == Problem("world.resolution_m", "must be > 0")


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (lambda d: d["world"].update(size_m=[0.0, 10.0]), "world.size_m[0]"),
        (lambda d: d["world"].update(size_m=[20.0, -10.0]), "world.size_m[1]"),
        (lambda d: d["terrain"][0]["circle"].update(radius=0.0), "terrain[0].circle.radius"),
        (lambda d: d["terrain"][0]["circle"].update(radius=-1.5), "terrain[0].circle.radius"),
        (lambda d: d["terrain"][1]["rectangle"].update(size=[2.0, 0]), "terrain[1].rectangle.size[1]"),
    ],
)
def test_sizes_must_be_positive(edit: Callable, field: str) -> None:
    assert only_problem(edited(edit)) == Problem(field, "must be > 0")


def test_raster_over_the_cell_limit_states_the_count() -> None:
    # 1000 m / 0.05 m = 20,000 cells a side: 4 * 10^8 cells, four times the limit.
    data = edited(lambda d: d["world"].update(size_m=[1000.0, 1000.0], resolution_m=0.05))
    problem = only_problem(data)
    assert problem.field == "world"
    assert "20000 x 20000 = 400,000,000 cells" in problem.message
    assert f"{MAX_CELLS:,}" in problem.message


def test_raster_one_column_over_the_limit() -> None:
    data = edited(lambda d: d["world"].update(size_m=[10_001.0, 10_000.0], resolution_m=1.0))
    problem = only_problem(data)
    assert problem.field == "world"
    assert "10001 x 10000 = 100,010,000 cells" in problem.message


@pytest.mark.parametrize(
    ("size", "resolution", "magnitude"),
    [(1e200, 1.0, "10^400"), (1e300, 1e-300, "10^1200"), (1.7e308, 5e-324, "10^1263"), (1e10, 1e-1, "10^22")],
)
def test_astronomical_raster_states_its_magnitude(size: float, resolution: float, magnitude: str) -> None:
    data = edited(lambda d: d["world"].update(size_m=[size, size], resolution_m=resolution))
    problem = only_problem(data)
    assert problem.field == "world"
    assert f"about {magnitude} cells" in problem.message


# --- zones ------------------------------------------------------------------------------------


def _two_zones(first_id: Any, second_id: Any) -> dict[str, Any]:
    zone = GOOD["zones"][0]
    return scenario(zones=[{**copy.deepcopy(zone), "id": first_id}, {**copy.deepcopy(zone), "id": second_id}])


@pytest.mark.parametrize(("first", "second"), [("5", "5"), ("5", 5), (5, 5), ("a", "a")])
def test_duplicate_zone_ids(first: Any, second: Any) -> None:
    problem = only_problem(_two_zones(first, second))
    assert problem.field == "zones[1].id"
    assert problem.message == f"duplicate zone id {str(second)!r} (also zones[0])"


@pytest.mark.parametrize("expect", ["maybe", "Best", "AVOID", "lava", 3, None, ["best"]])
def test_zone_expect_must_be_avoid_best_or_a_class(expect: Any) -> None:
    data = edited(lambda d: d["zones"][0].update(expect=expect))
    problem = only_problem(data)
    assert problem.field == "zones[0].expect"
    assert problem.message.startswith(f"{expect!r} is neither 'avoid', 'best' nor a known class")


def test_a_zone_expecting_lethal_terrain_is_refused() -> None:
    """No zone expects lethal terrain (docs/classes.md): a driver is never expected to drive onto it."""
    problem = only_problem(edited(lambda d: d["zones"][0].update(expect="non_traversable")))
    assert problem.field == "zones[0].expect"
    assert (
        problem.message == "'non_traversable' is lethal, and no zone expects lethal terrain (a zone the driver keeps off expects 'avoid')"
    )


# --- several problems ---------------------------------------------------------------------------


def test_every_problem_in_a_file_is_reported(tmp_path: Path) -> None:
    text = (
        GOOD_YAML.replace("name: tiny_course", "name: tiny course")
        .replace("resolution_m: 0.1", "resolution_m: -1")
        .replace("radius: 1.0", "radius: 0")
        .replace("class: rock", "class: lava")
        .replace("expect: best", "expect: maybe, extra: 1")
        .replace("[19.0, 5.0]]", "[19.0, .nan]]")
    )
    path = write(tmp_path, text)
    found = load_problems(path)
    assert {p.field for p in found} == {
        "name",
        "world.resolution_m",
        "terrain[0].circle.radius",
        "terrain[1].class",
        "zones[0].extra",
        "path.waypoints[1][1]",
    }
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    lines = str(info.value).split("\n")
    assert lines == info.value.lines()
    assert len(lines) == len(found)
    assert f"{path}: terrain[0].circle.radius: must be > 0" in lines


def test_problems_in_many_items_are_all_reported() -> None:
    data = scenario(terrain=[{"class": "mud", "circle": {"center": [5.0, 5.0], "radius": -float(i)}} for i in range(1, 4)])
    assert problems_of(data) == [Problem(f"terrain[{i}].circle.radius", "must be > 0") for i in range(3)]


# --- the error types ----------------------------------------------------------------------------


def test_problem_lines_name_file_and_field() -> None:
    err = ScenarioError("x.yaml", [Problem("terrain[2].circle.radius", "must be > 0"), Problem("", "empty file")])
    assert err.lines() == ["x.yaml: terrain[2].circle.radius: must be > 0", "x.yaml: empty file"]
    assert str(err) == "x.yaml: terrain[2].circle.radius: must be > 0\nx.yaml: empty file"


def test_user_error_from_a_single_message() -> None:
    err = UserError("cfg.yaml", "bad value", field="camera.fov_deg")
    assert err.problems == (Problem("camera.fov_deg", "bad value"),)
    assert err.lines() == ["cfg.yaml: camera.fov_deg: bad value"]
    assert UserError("", "no source").lines() == ["no source"]


def test_error_types_are_user_errors() -> None:
    assert issubclass(ScenarioError, UserError)
    assert issubclass(ConfigError, UserError)
    assert issubclass(UserError, Exception)


def test_parse_error_without_source_has_no_file_prefix() -> None:
    with pytest.raises(ScenarioError) as info:
        parse_scenario(scenario(name="bad name"))
    assert info.value.lines() == ["name: must match [A-Za-z0-9_-]+"]


def test_generated_courses_are_deterministic_valid_and_labelled_by_kind() -> None:
    from terrapref.scenario.generate import ZONE_KINDS, generate_course, zone_kind

    a, b = resolve_scenario("gen:1000"), resolve_scenario("gen:1000")
    assert a.name == "gen_1000" and a.to_dict() == b.to_dict()
    assert resolve_scenario("gen:1001").to_dict() != a.to_dict()
    for kinds in (("lone",), ("pair",), ("triple",)):
        course = generate_course(7, zones=6, kinds=kinds)
        assert len(course.zones) == 6
        assert {zone_kind(z.label) for z in course.zones} == set(kinds)
        assert {z.expect for z in course.zones} == ({AVOID} if kinds == ("lone",) else {BEST})
    mixed = {zone_kind(z.label) for s in range(1000, 1004) for z in resolve_scenario(f"gen:{s}").zones}
    assert mixed == set(ZONE_KINDS)
    for name in ("gen:abc", "gen: 3", "gen:3_0", "genrelief:3_0", "genrelief:+3", "gen:٣"):  # int() read the last five as seeds
        with pytest.raises(ScenarioError, match="SEED with an integer SEED"):
            resolve_scenario(name)


@pytest.mark.parametrize("data", [[1, 2], "x", None, 3])
def test_parse_scenario_refuses_what_is_not_a_mapping_in_one_line(data) -> None:
    """Parsed data that is not a mapping (a recording's scenario, an imported one) is a user error, not a crash."""
    with pytest.raises(ScenarioError) as caught:
        parse_scenario(data, "s.yaml")
    lines = caught.value.lines()
    assert len(lines) == 1 and lines[0].startswith("s.yaml: expected a mapping of scenario fields")


def test_the_start_clearance_is_the_default_vehicles_footprint() -> None:
    from terrapref.scenario.loader import START_HALF_WIDTH_M
    from terrapref.vehicle import VehicleConfig

    assert START_HALF_WIDTH_M * np.array([-1.0, -0.5, 0.0, 0.5, 1.0]) == pytest.approx(VehicleConfig().footprint_m)


# --- relief (SPEC 19) ---------------------------------------------------------------------------

RELIEF = [
    {"noise": {"amplitude_m": 0.6, "wavelength_m": 15.0, "seed": 3}},
    {"mound": {"center": [5.0, 5.0], "radius": 3.0, "height_m": -1.0}},
    {"ridge": {"polyline": [[10.0, 2.0], [10.0, 8.0], [12.0, 9.0]], "width_m": 2.0, "height_m": 0.8}},
    {"plateau": {"polygon": [[14, 2], [18, 2], [18, 8], [14, 8]], "height_m": 1.5, "edge_m": 0}},
]


def test_relief_parses_into_typed_entries_in_order_and_round_trips() -> None:
    s = parse_scenario(scenario(relief=copy.deepcopy(RELIEF)), "x.yaml")
    assert [type(e) for e in s.relief] == [Noise, Mound, Ridge, Plateau] and s.has_relief
    assert s.relief[0] == Noise(0.6, 15.0, 3) and s.relief[1] == Mound((5.0, 5.0), 3.0, -1.0)
    assert s.relief[2].polyline.tolist() == [[10.0, 2.0], [10.0, 8.0], [12.0, 9.0]] and s.relief[3].edge_m == 0.0
    assert s.to_dict()["relief"] == yaml.safe_load(yaml.safe_dump(RELIEF))
    assert parse_scenario(s.to_dict(), "y.yaml").to_dict() == s.to_dict()
    assert not parse_scenario(scenario(relief=None), "x.yaml").has_relief
    patch = [{"noise": {"amplitude_m": 0.1, "wavelength_m": 0.3, "seed": 1, "polygon": [[2.0, 2.0], [6.0, 2.0], [6.0, 6.0]]}}]
    rough = parse_scenario(scenario(relief=copy.deepcopy(patch)), "x.yaml")
    assert rough.relief[0].polygon.vertices.tolist() == patch[0]["noise"]["polygon"] and rough.to_dict()["relief"] == patch


def relief_with(i: int, kind: str, **fields: Any) -> dict[str, Any]:
    """GOOD with RELIEF, its entry ``i`` (of ``kind``) given ``fields`` (None: removed)."""
    relief = copy.deepcopy(RELIEF)
    for key, value in fields.items():
        if value is None:
            del relief[i][kind][key]
        else:
            relief[i][kind][key] = value
    return scenario(relief=relief)


@pytest.mark.parametrize(
    ("data", "field", "message"),
    [
        (scenario(relief={"mound": {}}), "relief", "expected a list, got a mapping"),
        (scenario(relief=["mound"]), "relief[0]", "expected a mapping, got string 'mound'"),
        (scenario(relief=[{}]), "relief[0]", "expected exactly one of noise, mound, ridge, plateau, got 0"),
        (scenario(relief=[{**RELIEF[1], **RELIEF[2]}]), "relief[0]", "expected exactly one of noise, mound, ridge, plateau, got 2"),
        (scenario(relief=[{"hill": {}}]), "relief[0].hill", "unknown kind of relief; the kinds are noise, mound, ridge, plateau"),
        (relief_with(1, "mound", slope=2), "relief[1].mound.slope", "unknown key"),
        (relief_with(1, "mound", radius=None), "relief[1].mound.radius", "missing"),
        (relief_with(1, "mound", radius=0), "relief[1].mound.radius", "must be > 0"),
        (relief_with(1, "mound", height_m="high"), "relief[1].mound.height_m", "expected a number, got string 'high'"),
        (relief_with(1, "mound", height_m=1e4), "relief[1].mound.height_m", "must be at most 1000 m either way"),
        (
            relief_with(1, "mound", height_m=5e-324),
            "relief[1].mound.height_m",
            "must be at least 1 mm either way: the ground would not change",
        ),  # was ok: flat ground called relief
        (
            relief_with(1, "mound", height_m=-0.0009),
            "relief[1].mound.height_m",
            "must be at least 1 mm either way: the ground would not change",
        ),
        (
            relief_with(1, "mound", center=[40.0, 5.0]),
            "relief[1].mound",
            "lies wholly off the map (bounds x 37..43, y 2..8; map 0..20 x 0..10)",
        ),
        (relief_with(1, "mound", center=[5.0, 1e300]), "relief[1].mound.center", "lies more than 1e+06 m from the map"),
        (relief_with(0, "noise", seed=-1), "relief[0].noise.seed", "expected an integer from 0 to 2^63 - 1, got number -1"),
        (relief_with(0, "noise", seed=1.5), "relief[0].noise.seed", "expected an integer from 0 to 2^63 - 1, got number 1.5"),
        (relief_with(0, "noise", seed=True), "relief[0].noise.seed", "expected an integer from 0 to 2^63 - 1, got boolean True"),
        (relief_with(0, "noise", amplitude_m=0), "relief[0].noise.amplitude_m", "must be > 0"),
        (
            relief_with(0, "noise", wavelength_m=0.15),
            "relief[0].noise.wavelength_m",
            "must be at least two cells (2 x world.resolution_m = 0.2 m)",
        ),
        (
            relief_with(2, "ridge", polyline=[[1.0, 1.0]]),
            "relief[2].ridge.polyline",
            "expected a list of at least 2 [x, y] points, got a list of 1",
        ),
        (relief_with(2, "ridge", polyline=[[1.0, 1.0], [1.0, 1.0]]), "relief[2].ridge.polyline", "needs at least 2 distinct points"),
        (
            relief_with(2, "ridge", polyline=[[1.0, 1.0], [1e300, 1.0]]),
            "relief[2].ridge.polyline",
            "has a point more than 1e+06 m from the map",
        ),
        (relief_with(2, "ridge", width_m=-2), "relief[2].ridge.width_m", "must be > 0"),
        (relief_with(3, "plateau", edge_m=-1), "relief[3].plateau.edge_m", "must be >= 0 (0: a vertical step)"),
        (
            relief_with(3, "plateau", edge_m=0.001),  # was ok: a step on the grid, called a slope
            "relief[3].plateau.edge_m",
            "must be at least one cell (0.1 m at world.resolution_m 0.1) or 0 (a vertical step): finer relief falls between the cells",
        ),
        (relief_with(3, "plateau", edge_m=None), "relief[3].plateau.edge_m", "missing"),
        (
            relief_with(3, "plateau", polygon=[[1, 1], [2, 2], [3, 3]]),
            "relief[3].plateau.polygon",
            "has zero area (vertices are collinear)",
        ),
        (relief_with(3, "plateau", edge_m=float("nan")), "relief[3].plateau.edge_m", "must be finite (got NaN or infinity)"),
        (
            relief_with(0, "noise", polygon=[[1, 1], [2, 2], [3, 3]]),
            "relief[0].noise.polygon",
            "has zero area (vertices are collinear)",
        ),
        (
            relief_with(0, "noise", polygon=[[1, 1], [2e6, 1], [2e6, 2e6]]),
            "relief[0].noise.polygon",
            "has a point more than 1e+06 m from the map",
        ),
        (
            relief_with(0, "noise", polygon=[[40, 1], [42, 1], [42, 3]]),
            "relief[0].noise",
            "lies wholly off the map (bounds x 40..42, y 1..3; map 0..20 x 0..10)",
        ),
    ],
)
def test_bad_relief_is_one_problem_naming_its_field(data: dict[str, Any], field: str, message: str) -> None:
    assert only_problem(data) == Problem(field, message)
