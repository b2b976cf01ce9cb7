"""Tests for ``terrapref validate``, ``render`` and ``show``: one line per problem, exit code 2,
never a traceback (STYLE convention 9)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from helpers import REPO
from terrapref.cli import main
from terrapref.pngio import DEPTH_KEY_WIDTH_PX, LEGEND_WIDTH_PX
from terrapref.scenario import packaged_scenarios, resolve_scenario
from terrapref.terrain import UNKNOWN
from terrapref.world import rasterise

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
  - {class: water, circle: {center: [15.0, 5.0], radius: 1.5}}
  - {class: mud, polygon: [[14.0, 1.0], [16.0, 1.0], [15.0, 3.0]]}
path:
  waypoints: [[1.0, 5.0], [19.0, 5.0]]
zones:
  - {id: "1", rectangle: {center: [5.0, 5.0], size: [4.0, 4.0]}, expect: best}
  - {id: "2", circle: {center: [15.0, 5.0], radius: 3.0}, expect: avoid}
"""


def edit(old: str, new: str) -> str:
    assert old in GOOD_YAML, old
    return GOOD_YAML.replace(old, new, 1)


def write(folder: Path, name: str, content: str | bytes) -> Path:
    path = folder / name
    if isinstance(content, str):
        path.write_text(content, encoding="utf-8")
    else:
        path.write_bytes(content)
    return path


def run_cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, list[str], list[str]]:
    """Run ``terrapref ARGV`` in-process: (exit code, stdout lines, stderr lines)."""
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out.splitlines(), err.splitlines()


def run_subprocess(cwd: Path, *argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "terrapref.cli", *argv], cwd=cwd, capture_output=True, text=True, check=False)


# --- validate: good files -------------------------------------------------------------------


def test_validate_good_file_prints_ok(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = write(tmp_path, "good.yaml", GOOD_YAML)
    assert run_cli(capsys, "validate", str(path)) == (0, [f"{path}: ok (scenario)"], [])


def test_validate_several_good_files_and_a_packaged_name(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    a = write(tmp_path, "a.yaml", GOOD_YAML)
    b = write(tmp_path, "b.yml", edit("name: tiny_course", "name: other"))
    code, out, err = run_cli(capsys, "validate", str(a), str(b), "demo_course")
    assert (code, out, err) == (0, [f"{a}: ok (scenario)", f"{b}: ok (scenario)", "demo_course: ok (scenario)"], [])


def test_validate_every_packaged_scenario(capsys: pytest.CaptureFixture[str]) -> None:
    names = packaged_scenarios()
    assert run_cli(capsys, "validate", *names) == (0, [f"{n}: ok (scenario)" for n in names], [])


def test_validate_generated_layouts_by_name(capsys: pytest.CaptureFixture[str]) -> None:
    """gen:SEED and genrelief:SEED, as every command that reads a scenario takes them."""
    assert run_cli(capsys, "validate", "gen:7", "genrelief:101") == (0, ["gen:7: ok (scenario)", "genrelief:101: ok (scenario)"], [])


def test_validate_a_relative_path(tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    write(tmp_path, "x.yaml", GOOD_YAML)
    monkeypatch.chdir(tmp_path)
    assert run_cli(capsys, "validate", "x.yaml") == (0, ["x.yaml: ok (scenario)"], [])


# --- validate: bad files, one problem each ------------------------------------------------------

# (test id, file content, the expected line after "FILE: ").  An entry ending in "..." is a prefix.
BAD_FILES: list[tuple[str, str | bytes, str]] = [
    ("empty", b"", "empty file"),
    (
        "binary-nul",
        bytes(np.random.default_rng(1).integers(0, 256, 2048, dtype=np.uint8)) + b"\x00",
        "binary data, expected a YAML text file",
    ),
    ("non-utf8", b"format: terrapref-scenario/1\nname: \xe9\xff\xfe\n", "not UTF-8 text, expected a YAML file"),
    ("malformed", "format: terrapref-scenario/1\nworld: {size_m: [1, 2}\n", "malformed YAML at line 2..."),
    ("bad-date", "format: terrapref-scenario/1\nname: 2020-13-45\n", "malformed YAML..."),
    ("top-level-list", "- format\n- name\n", "expected a mapping at the top level, got a list"),
    (
        "wrong-format",
        edit("terrapref-scenario/1", "terrapref-scenario/2"),
        "format: 'terrapref-scenario/2' is not supported; expected 'terrapref-scenario/1'",
    ),
    ("missing-format", edit("format: terrapref-scenario/1\n", ""), "format: missing; expected 'terrapref-scenario/1'"),
    ("missing-name", edit("name: tiny_course\n", ""), "name: missing"),
    ("missing-resolution", edit("  resolution_m: 0.1\n", ""), "world.resolution_m: missing"),
    ("missing-waypoints", edit("  waypoints: [[1.0, 5.0], [19.0, 5.0]]\n", "  {}\n"), "path.waypoints: missing"),
    ("unknown-top", GOOD_YAML + "colour: red\n", "colour: unknown key"),
    ("unknown-world", edit("  background: grass\n", "  background: grass\n  origin: [0, 0]\n"), "world.origin: unknown key"),
    ("unknown-terrain", edit("{class: rock,", "{class: rock, height: 1,"), "terrain[1].height: unknown key"),
    ("unknown-circle", edit("radius: 1.0}", "radius: 1.0, r: 2}"), "terrain[0].circle.r: unknown key"),
    ("unknown-rectangle", edit("yaw_deg: 30.0}", "yaw_deg: 30.0, pitch_deg: 1}"), "terrain[1].rectangle.pitch_deg: unknown key"),
    ("unknown-zone", edit('{id: "1",', '{id: "1", weight: 2,'), "zones[0].weight: unknown key"),
    ("string-number", edit("resolution_m: 0.1", "resolution_m: fine"), "world.resolution_m: expected a number, got string 'fine'"),
    ("bool-number", edit("radius: 1.0", "radius: true"), "terrain[0].circle.radius: expected a number, got boolean True"),
    ("yes-number", edit("radius: 1.0", "radius: yes"), "terrain[0].circle.radius: expected a number, got string 'yes'"),
    (
        "mapping-for-list",
        edit("size_m: [20.0, 10.0]", "size_m: {x: 20.0, y: 10.0}"),
        "world.size_m: expected a list of 2 numbers, got a mapping",
    ),
    ("nan", edit("radius: 1.0", "radius: .nan"), "terrain[0].circle.radius: must be finite (got NaN or infinity)"),
    ("inf", edit("resolution_m: 0.1", "resolution_m: .inf"), "world.resolution_m: must be finite (got NaN or infinity)"),
    ("minus-inf", edit("[19.0, 5.0]]", "[-.inf, 5.0]]"), "path.waypoints[1][0]: must be finite (got NaN or infinity)"),
    ("huge-int", edit("radius: 1.0", "radius: 1" + "0" * 400), "terrain[0].circle.radius: is too large"),
    ("unknown-class", edit("class: rock", "class: lava"), "terrain[1].class: unknown class 'lava'..."),
    ("unknown-background", edit("background: grass", "background: snow"), "world.background: unknown class 'snow'..."),
    (
        "polygon-2-distinct",
        edit("[[14.0, 1.0], [16.0, 1.0], [15.0, 3.0]]", "[[14.0, 1.0], [16.0, 1.0], [14.0, 1.0]]"),
        "terrain[3].polygon: needs at least 3 distinct vertices, got 2",
    ),
    (
        "polygon-2-vertices",
        edit("[[14.0, 1.0], [16.0, 1.0], [15.0, 3.0]]", "[[14.0, 1.0], [16.0, 1.0]]"),
        "terrain[3].polygon: expected a list of at least 3 [x, y] points, got a list of 2",
    ),
    (
        "polygon-collinear",
        edit("[[14.0, 1.0], [16.0, 1.0], [15.0, 3.0]]", "[[14.0, 1.0], [15.0, 2.0], [16.0, 3.0]]"),
        "terrain[3].polygon: has zero area (vertices are collinear)",
    ),
    (
        "shape-off-map",
        edit("center: [15.0, 5.0], radius: 1.5", "center: [35.0, 5.0], radius: 1.5"),
        "terrain[2].circle: lies wholly off the map...",
    ),
    ("waypoint-off-map", edit("[19.0, 5.0]]", "[19.0, 5.0], [25.0, 5.0]]"), "path.waypoints[2]: (25, 5) is off the map..."),
    ("path-same-points", edit("[[1.0, 5.0], [19.0, 5.0]]", "[[1.0, 1.0], [1.0, 1.0]]"), "path.waypoints: needs at least 2 distinct points"),
    (
        "path-one-point",
        edit("[[1.0, 5.0], [19.0, 5.0]]", "[[1.0, 1.0]]"),
        "path.waypoints: expected a list of at least 2 [x, y] points, got a list of 1",
    ),
    ("resolution-zero", edit("resolution_m: 0.1", "resolution_m: 0"), "world.resolution_m: must be > 0"),
    ("resolution-negative", edit("resolution_m: 0.1", "resolution_m: -0.1"), "world.resolution_m: must be > 0"),
    ("radius-zero", edit("radius: 1.0", "radius: 0"), "terrain[0].circle.radius: must be > 0"),
    (
        "too-many-cells",
        edit("size_m: [20.0, 10.0]", "size_m: [2000.0, 1000.0]").replace("resolution_m: 0.1", "resolution_m: 0.05"),
        "world: raster would have 40000 x 20000 = 800,000,000 cells...",
    ),
    ("astronomical-cells", edit("size_m: [20.0, 10.0]", "size_m: [1.0e+300, 1.0e+300]"), "world: raster would have about 10^602 cells..."),
    ("duplicate-zone", edit('{id: "2",', "{id: 1,"), "zones[1].id: duplicate zone id '1' (also zones[0])"),
    ("bad-expect", edit("expect: avoid", "expect: maybe"), "zones[1].expect: 'maybe' is neither 'avoid', 'best' nor a known class..."),
    (
        "lethal-expect",
        edit("expect: avoid", "expect: non_traversable"),
        "zones[1].expect: 'non_traversable' is lethal, and no zone expects lethal terrain (a zone the driver keeps off expects 'avoid')",
    ),
    ("bad-name", edit("name: tiny_course", "name: tiny course!"), "name: must match [A-Za-z0-9_-]+"),
    (
        "relief-radius",
        GOOD_YAML
        + "relief:\n  - {noise: {amplitude_m: 0.3, wavelength_m: 5.0, seed: 1}}\n  - {mound: {center: [5, 5], radius: -2, height_m: 1}}\n",
        "relief[1].mound.radius: must be > 0",
    ),
    (
        "start-in-trees",
        edit("path:", "  - {class: non_traversable, circle: {center: [1.0, 5.0], radius: 1.0}}\npath:"),
        "start: (1, 5) (the first waypoint, facing the second) puts the vehicle's footprint on lethal terrain (non_traversable)...",
    ),
]


@pytest.mark.parametrize(("content", "expected"), [c[1:] for c in BAD_FILES], ids=[c[0] for c in BAD_FILES])
def test_validate_bad_file_prints_one_line_and_exits_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], content: str | bytes, expected: str
) -> None:
    path = write(tmp_path, "x.yaml", content)
    code, out, err = run_cli(capsys, "validate", str(path))
    assert code == 2
    assert err == []
    assert len(out) == 1, out
    (line,) = out
    if expected.endswith("..."):
        assert line.startswith(f"error: {path}: {expected[:-3]}"), line
    else:
        assert line == f"error: {path}: {expected}"


def test_a_zone_expecting_lethal_terrain_is_refused_wherever_the_scenario_is_loaded(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Not only ``validate``: ``record`` and ``evaluate`` refuse the scenario too, and write nothing."""
    from helpers import linear_model

    path = write(tmp_path, "x.yaml", edit("expect: avoid", "expect: non_traversable"))
    said = f"error: {path}: zones[1].expect: 'non_traversable' is lethal, and no zone expects lethal terrain"
    model = linear_model(tmp_path / "m.safetensors")
    for argv in (["record", str(path), "--out", str(tmp_path / "rec")], ["evaluate", str(model), str(path), "--out", str(tmp_path / "ev")]):
        code, out, err = run_cli(capsys, *argv)
        assert code == 2 and out == [] and len(err) == 1 and err[0].startswith(said), (argv, out, err)
    assert not (tmp_path / "rec").exists() and not (tmp_path / "ev").exists()


def test_validate_example_from_the_spec(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = write(tmp_path, "x.yaml", edit("radius: 1.5", "radius: -1.5"))
    code, out, err = run_cli(capsys, "validate", str(path))
    assert (code, out, err) == (2, [f"error: {path}: terrain[2].circle.radius: must be > 0"], [])


def test_validate_nonexistent_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "missing.yaml"
    assert run_cli(capsys, "validate", str(path)) == (2, [f"error: {path}: no such file"], [])


def test_validate_unknown_name(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_cli(capsys, "validate", "no_such_course")
    assert code == 2 and err == []
    (line,) = out
    assert line.startswith("error: no_such_course: no such file and no packaged scenario of that name")


def test_validate_directory(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "folder.yaml"
    folder.mkdir()
    for arg in (str(folder), str(tmp_path)):
        assert run_cli(capsys, "validate", arg) == (2, [f"error: {arg}: is a directory, expected a file"], [])


def test_validate_name_too_long_for_the_os(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    name = "n" * 300
    code, out, err = run_cli(capsys, "validate", name, str(write(tmp_path, "good.yaml", GOOD_YAML)))
    assert code == 2 and err == []
    assert len(out) == 2
    assert out[0].startswith(f"error: {name}: ")
    assert out[1].endswith(": ok (scenario)")


def test_validate_reports_every_problem_in_a_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    text = (
        edit("name: tiny_course", "name: tiny course")
        .replace("resolution_m: 0.1", "resolution_m: 0")
        .replace("radius: 1.0", "radius: -1")
        .replace("class: rock", "class: lava")
        .replace("expect: avoid", "expect: never")
    )
    path = write(tmp_path, "many.yaml", text)
    code, out, err = run_cli(capsys, "validate", str(path))
    assert code == 2 and err == []
    assert sorted(line.split(": ")[2] for line in out) == [  # error: FILE: FIELD: ...
        "name",
        "terrain[0].circle.radius",
        "terrain[1].class",
        "world.resolution_m",
        "zones[1].expect",
    ]
    assert all(line.startswith(f"error: {path}: ") for line in out)
    assert f"error: {path}: terrain[0].circle.radius: must be > 0" in out


def test_validate_mixed_good_and_bad_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    good = write(tmp_path, "good.yaml", GOOD_YAML)
    bad = write(tmp_path, "bad.yaml", edit("radius: 1.0", "radius: 0"))
    empty = write(tmp_path, "empty.yaml", "")
    good2 = write(tmp_path, "good2.yaml", GOOD_YAML)
    code, out, err = run_cli(capsys, "validate", str(good), str(bad), str(empty), str(good2))
    assert code == 2
    assert err == []
    assert out == [
        f"{good}: ok (scenario)",
        f"error: {bad}: terrain[0].circle.radius: must be > 0",
        f"error: {empty}: empty file",
        f"{good2}: ok (scenario)",
    ]


def test_validate_needs_a_file(capsys: pytest.CaptureFixture[str]) -> None:
    code, out, err = run_cli(capsys, "validate")
    assert (code, out) == (2, []) and len(err) == 1 and "--template KIND" in err[0]
    # A template is of the default table's classes: --classes beside it was ignored without a word.
    code, out, err = run_cli(capsys, "validate", "--template", "labels", "--classes", str(REPO / "examples" / "classes" / "small.yaml"))
    assert (code, out) == (2, []) and len(err) == 1 and "of the default table's classes" in err[0]


# --- validate: every kind of file, and templates to start from ----------------------------------

KINDS = {
    "scenario": "scenario",
    "classes": "class table",
    "perception": "perception model",
    "robot": "robot file",
    "labels": "label map",
    "style": "driver style",
}


@pytest.mark.parametrize("kind", KINDS)
def test_each_template_is_a_file_of_its_kind_that_validate_accepts(tmp_path: Path, capsys: pytest.CaptureFixture[str], kind: str) -> None:
    code, out, err = run_cli(capsys, "validate", "--template", kind)
    assert code == 0 and err == [] and out[0].startswith("# ")  # commented
    path = write(tmp_path, f"{kind}.yaml", "\n".join(out) + "\n")  # terrapref validate --template KIND > FILE
    said = ["  note: background grass; feature classes mud, gravel; lethal tree"] if kind == "classes" else []  # a table in a line
    assert run_cli(capsys, "validate", str(path)) == (0, [f"{path}: ok ({KINDS[kind]})", *said], [])


@pytest.mark.parametrize(
    "kind,old,new,line",
    [
        ("classes", "id: 2, name: gravel", "id: 300, name: gravel", "classes[2].id: must be an integer in 0..254"),
        ("classes", "lethal: [tree]", "lethal: [rocks]", "lethal: must be a list of distinct known class names; unknown class 'rocks'"),
        (
            "classes",
            "id: 2, name: gravel",
            "id: 1, name: gravel",
            "classes: class names and ids must be unique; id 1 is given to more than one class",
        ),
        ("perception", "drop_rate: 0.05", "drop_rate: 2", "frames.drop_rate: must be in [0, 1], got 2"),
        ("robot", "height_m: 1.0", "height_m: -1.0", "camera.height_m: ..."),
        ("labels", "2: mud", "2: lava", "ids: class 'lava' is not in the class table ..."),
        ("style", "mud: 0.5", "mud: 5", "speeds.mud: a cruising speed of 5 m/s is above the vehicle's 2 m/s"),
        ("style", "base: default", "base: fast", "base: 'fast' is not a style ..."),
        ("style", "rock: 1.0", "lava: 1.0", "speeds: class 'lava' is not in the class table ..."),
        ("robot", "format: terrapref-robot/1\n", "", "format: missing; expected 'terrapref-robot/1'"),
    ],
)
def test_validate_names_the_file_and_field_of_each_kind(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], kind: str, old: str, new: str, line: str
) -> None:
    main(["validate", "--template", kind])
    text = capsys.readouterr().out
    assert old in text
    path = write(tmp_path, f"{kind}.yaml", text.replace(old, new, 1))
    code, out, err = run_cli(capsys, "validate", str(path))
    assert (code, err, len(out)) == (2, [], 1), out
    expected = f"error: {path}: {line}"
    assert out[0].startswith(expected[:-3]) if line.endswith("...") else out[0] == expected


def test_validate_reads_a_label_map_and_a_perception_file_with_the_given_table(capsys: pytest.CaptureFixture[str]) -> None:
    examples = REPO / "examples" / "classes"
    table, labels, field = (str(examples / n) for n in ("rellis3d.yaml", "rellis3d_labels.yaml", "rellis3d_field.yaml"))
    assert run_cli(capsys, "validate", table, labels, field, "--classes", table) == (
        0,
        [
            f"{table}: ok (class table)",
            "  note: background grass; feature classes dirt, gravel, mud, puddle, water, bush; lethal tree, log, fence, building, vehicle, person",
            f"{labels}: ok (label map)",
            f"{field}: ok (perception model)",
        ],
        [],
    )
    code, out, _ = run_cli(capsys, "validate", labels)  # the default table has no 'building'
    assert code == 2 and out[0].startswith(f"error: {labels}: ids: class ")


def test_validate_refuses_a_file_of_no_known_kind(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = write(tmp_path, "x.yaml", "format: terrapref-model/1\n")
    code, out, _ = run_cli(capsys, "validate", str(path))
    assert code == 2 and out == [
        f"error: {path}: format: 'terrapref-model/1' is not a file terrapref reads here; expected one of "
        "terrapref-scenario/1, terrapref-classes/1, terrapref-perception/1, terrapref-robot/1, terrapref-labels/1, "
        "terrapref-driver-style/1"
    ]
    assert run_cli(capsys, "validate", "--template", "robot", str(path))[0] == 2


def test_validate_as_a_subprocess_exit_code_and_no_traceback(tmp_path: Path) -> None:
    good = write(tmp_path, "good.yaml", GOOD_YAML)
    write(tmp_path, "bad.yaml", edit("radius: 1.0", "radius: .nan"))
    write(tmp_path, "garbage.yaml", bytes(range(256)) * 8)
    write(tmp_path, "date.yaml", "format: terrapref-scenario/1\nname: 2020-02-30\n")
    write(tmp_path, "huge.yaml", edit("size_m: [20.0, 10.0]", "size_m: [1.0e+200, 1.0e+200]"))
    (tmp_path / "dir.yaml").mkdir()
    files = [str(good), "bad.yaml", "garbage.yaml", "date.yaml", "huge.yaml", "dir.yaml", "missing.yaml", "demo_course"]
    result = run_subprocess(tmp_path, "validate", *files)
    assert result.returncode == 2
    assert "Traceback" not in result.stdout
    assert "Traceback" not in result.stderr
    assert result.stderr == ""
    lines = result.stdout.splitlines()
    assert lines == [
        f"{good}: ok (scenario)",
        "error: bad.yaml: terrain[0].circle.radius: must be finite (got NaN or infinity)",
        "error: garbage.yaml: binary data, expected a YAML text file",
        lines[3],
        lines[4],
        "error: dir.yaml: is a directory, expected a file",
        "error: missing.yaml: no such file",
        "demo_course: ok (scenario)",
    ]
    assert lines[3].startswith("error: date.yaml: malformed YAML")
    assert lines[4].startswith("error: huge.yaml: world: raster would have about 10^402 cells")


def test_validate_good_files_exit_0(tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    # In-process: the exit code and the streams of a real process are checked by the test above.
    write(tmp_path, "good.yaml", GOOD_YAML)
    monkeypatch.chdir(tmp_path)
    assert run_cli(capsys, "validate", "good.yaml", "demo_course") == (0, ["good.yaml: ok (scenario)", "demo_course: ok (scenario)"], [])


# --- render and show ----------------------------------------------------------------------------


def test_render_writes_class_id_png_and_preview(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    seg, col = tmp_path / "seg.png", tmp_path / "col.png"
    code, out, err = run_cli(capsys, "render", "demo_course", "--pose", "8", "10", "0", "--out", str(seg), "--preview", str(col))
    assert code == 0 and err == []
    assert len(out) == 2 and str(seg) in out[0] and str(col) in out[1]

    with Image.open(seg) as im:
        assert im.format == "PNG"
        assert im.mode == "L"
        assert im.size == (640, 480)
        labels = np.asarray(im)
    scenario = resolve_scenario("demo_course")
    in_map = set(np.unique(rasterise(scenario).raster).tolist())
    seen = set(np.unique(labels).tolist())
    assert seen <= in_map | {UNKNOWN}
    # At (8, 10) facing +x the water pond centred 4 m ahead fills part of the view.
    classes = scenario.classes
    assert {classes.id_of("grass"), classes.id_of("water")} <= seen

    with Image.open(col) as im:
        assert im.format == "PNG"
        assert im.mode == "RGB"
        assert im.size == (640 + LEGEND_WIDTH_PX, 480)
        rgb = np.asarray(im)
    np.testing.assert_array_equal(rgb[:, :640], classes.palette()[labels])  # the image, exactly
    band = rgb[:, 640:].reshape(-1, 3)
    for c in classes.classes:  # and a legend swatch of every class beside it
        assert (band == c.color).all(axis=1).sum() >= 100, c.name


def test_render_of_a_relief_course_writes_the_depth_image_and_shows_it_beside_the_segmentation(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """relief_demo from (8, 12) facing +x: the 0.6 m mound 8 m ahead hides part of the ground
    behind it; the depth PNG holds millimetres (0: no return) and the preview shows it."""
    seg, col, depth = tmp_path / "seg.png", tmp_path / "col.png", tmp_path / "depth.png"
    code, out, err = run_cli(
        capsys, "render", "relief_demo", "--pose", "8", "12", "0", "--out", str(seg), "--preview", str(col), "--depth", str(depth)
    )
    assert code == 0 and err == [] and out[0].startswith("on relief: the body at") and len(out) == 4
    with Image.open(depth) as im:
        mm = np.asarray(im)
    assert mm.dtype == np.uint16 and mm.shape == (480, 640)
    with Image.open(seg) as im:
        labels = np.asarray(im)
    assert (labels[mm == 0] == UNKNOWN).all()  # no return: nothing seen (ground off the map returns depth, unlabelled)
    assert (mm[labels != UNKNOWN] > 0).all()
    assert 300 < mm[mm > 0].min() and mm.max() <= 30_000
    with Image.open(col) as im:
        assert im.size == (640 + LEGEND_WIDTH_PX + 640 + DEPTH_KEY_WIDTH_PX, 480)
        bar = np.asarray(im.convert("L"))[30:250, -DEPTH_KEY_WIDTH_PX + 17]  # the depth key's shades, near at the top
    assert (np.diff(bar.astype(int)) <= 0).all() and int(bar[0]) - int(bar[-1]) > 150


def test_render_defaults_to_the_start_pose(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = write(tmp_path, "s.yaml", GOOD_YAML)
    seg = tmp_path / "seg.png"
    code, _, err = run_cli(capsys, "render", str(path), "--out", str(seg))
    assert code == 0 and err == []
    with Image.open(seg) as im:
        assert (im.mode, im.size) == ("L", (640, 480))


def test_show_writes_a_png(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out_png = tmp_path / "map.png"
    code, out, err = run_cli(capsys, "show", "demo_course", "--out", str(out_png))
    assert code == 0 and err == []
    (line,) = out
    assert str(out_png) in line
    with Image.open(out_png) as im:
        assert im.format == "PNG"
        assert im.size[0] > 0 and im.size[1] > 0


@pytest.mark.parametrize("command", ["render", "show"])
def test_bad_scenario_exits_2_with_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str) -> None:
    bad = write(tmp_path, "bad.yaml", edit("radius: 1.0", "radius: 0"))
    out_png = tmp_path / "out.png"
    code, out, err = run_cli(capsys, command, str(bad), "--out", str(out_png))
    assert code == 2
    assert out == []
    assert err == [f"error: {bad}: terrain[0].circle.radius: must be > 0"]
    assert not out_png.exists()


@pytest.mark.parametrize("command", ["render", "show"])
def test_unknown_scenario_name_exits_2_with_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str) -> None:
    code, out, err = run_cli(capsys, command, "no_such_course", "--out", str(tmp_path / "x.png"))
    assert code == 2 and out == []
    (line,) = err
    assert line.startswith("error: no_such_course: ")


def test_render_bad_scenario_as_a_subprocess(tmp_path: Path) -> None:
    write(tmp_path, "bad.yaml", b"\x00\x01\x02 not yaml")
    result = run_subprocess(tmp_path, "render", "bad.yaml", "--out", "seg.png")
    assert result.returncode == 2
    assert "Traceback" not in result.stdout + result.stderr
    assert result.stderr == "error: bad.yaml: binary data, expected a YAML text file\n"
    assert not (tmp_path / "seg.png").exists()


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
@pytest.mark.parametrize("pose", [("nan", "10", "0"), ("8", "10", "inf")], ids=["nan-x", "inf-yaw"])
def test_render_non_finite_pose_is_a_user_error(tmp_path: Path, capsys: pytest.CaptureFixture[str], pose: tuple[str, str, str]) -> None:
    with pytest.raises(SystemExit) as refused:  # the command line's parser refuses a number that is not finite
        main(["render", "demo_course", "--pose", *pose, "--out", str(tmp_path / "seg.png")])
    err = capsys.readouterr().err.splitlines()
    assert refused.value.code == 2
    assert len(err) == 1 and err[0].startswith("error: terrapref render: argument --pose: ") and "is not a finite number" in err[0]


@pytest.mark.parametrize(
    "change, note",
    [
        ("lethal: [tree]", "no lethal class: the planner may drive over every class"),
        ("color: [120, 120, 120]", "mud and gravel have the same colour [120, 120, 120]: no figure tells them apart"),
    ],
)
def test_validate_notes_what_a_table_is_that_is_no_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], change: str, note: str
) -> None:
    """A table whose lethal line was left out, or two classes of one colour, are valid tables a
    newcomer rarely means: validate says so beside the ok."""
    main(["validate", "--template", "classes"])
    text = capsys.readouterr().out
    if change.startswith("lethal"):
        text = text.replace(change, "lethal: []", 1)
    else:  # gravel given mud's colour
        mud = next(line for line in text.splitlines() if "name: mud" in line)
        gravel = next(line for line in text.splitlines() if "name: gravel" in line)
        colour = mud[mud.index("color:") :].rstrip("}").strip()
        text = text.replace(mud, mud.replace(colour, change), 1).replace(
            gravel, gravel.replace(gravel[gravel.index("color:") :].rstrip("}").strip(), change), 1
        )
    path = write(tmp_path, "table.yaml", text)
    code, out, _ = run_cli(capsys, "validate", str(path))
    assert code == 0 and out[0] == f"{path}: ok (class table)" and any(line.startswith(f"  note: {note}") for line in out[1:]), out


@pytest.mark.parametrize(
    "line, error",
    [
        (
            "rules: {speed: {class_max_mps: {mud: -1}}}",
            "rules.speed.class_max_mps.mud: expected at least 0.1 m/s, the least cruising speed, got -1",
        ),
        ("path_file: nowhere.yaml", "path_file: "),
        ("rules: {offset: {switch_margin: -5}}", "rules.offset.switch_margin: expected a value >= 0, got -5"),
        ("rules: {offset: {pursuit_m: 0}}", "rules.offset.pursuit_m: expected a distance > 0 [m], got 0"),
        ("stop: {decel_mps2: .nan}", "stop: the stop rule's settings must be finite numbers; decel_mps2 is nan"),
    ],
)
def test_validate_refuses_a_robot_file_the_node_would_refuse(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], line: str, error: str
) -> None:
    """What a node refuses as it starts, whatever the model: a top speed on a class below the
    least cruising speed, a path file that is not there (validate said ok to both)."""
    main(["validate", "--template", "robot"])
    path = write(tmp_path, "robot.yaml", capsys.readouterr().out + line + "\n")
    code, out, _ = run_cli(capsys, "validate", str(path))
    assert code == 2 and out[0].startswith(f"error: {path}: {error}"), out
