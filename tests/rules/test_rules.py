"""The decision rules' checker: the same checks over every registered rule (terrapref.rules.RULES),
the way Gymnasium's env checker runs over every registered environment, so that a rule registered
later is checked without editing this file.

Each rule is fitted honestly: the recipe config that names it (an ``argmax`` rule is its own
config) fitted, as training fits it, to the samples featurised from a recording the fixtures
make (``short_recording``). Then, for each rule:

1. its file block is JSON and reads back as the same rule, alone and through a model file that
   lists it and names it to drive (a rule that does not steer, the speed rule, sets the speed of
   C's argmax there);
2. it describes itself in one line that names it;
3. two planners of the same file decide the same frames the same way, bit for bit, and so does a
   planner given the frames again after ``set_path``;
4. a blank frame (all unknown) and a frame all of a lethal class give finite commands;
5. a block with a number (or a list of numbers) replaced by a string is a UserError naming the
   block, not a traceback;
6. what its runner offers (ground map, costmap, route prices) is consistent.

And RULES lists every rule class the package defines.
"""

from __future__ import annotations

import importlib
import inspect
import json
import pkgutil
from collections.abc import Iterator, Mapping
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

import terrapref.rules
from helpers import model_meta, skip_path_weights
from terrapref.camera import CameraConfig
from terrapref.dataset import build_dataset
from terrapref.demos.recording import read_recording
from terrapref.errors import UserError
from terrapref.features import FeatureConfig
from terrapref.learning.model_file import load_model, save_model
from terrapref.learning.network import ClassifierConfig
from terrapref.learning.steady import steady_labels
from terrapref.learning.train import FitData
from terrapref.planner import Planner
from terrapref.recipes import RECIPES
from terrapref.rules import RULES, HeaderContext, Rule, RuleConfig, read_rules, rule_roles, rules_in
from terrapref.rules.base import SPEED, STEERING, SpeedRunner, SteeringRunner, StopRunner, Where
from terrapref.terrain import UNKNOWN, ClassTable
from terrapref.vehicle import Pose

SOURCE = "rules-under-test"
"""The file name a block read on its own is said to come from."""

FRAME_STEP = 6
"""Every how many frames of the recording the determinism check decides (about 100 frames)."""


class WrittenButNotRead(AssertionError):
    """A rule writes fields into its block that it does not read back: the one failure that the
    known bug below is expected to raise (any other failure of its checks still fails)."""


KNOWN_BUGS: dict[tuple[str, str], pytest.MarkDecorator] = {}
"""Known bugs, by (check, rule type): the one case each is expected to fail (strictly: fixed, it must be unmarked)."""


def rule_cases(check: str) -> list[Any]:
    """Every registered rule's type, with the mark of a known bug in ``check`` where it has one."""
    return [pytest.param(name, marks=KNOWN_BUGS[(check, name)]) if (check, name) in KNOWN_BUGS else name for name in RULES.names()]


# --- every rule, fitted to a recording the fixtures make -------------------------------------------


def _config_of(rule_type: str, rule_class: type[Rule]) -> RuleConfig:
    """The config a recipe names for ``rule_type`` (the first recipe that names one), or the rule
    itself when it is its own config (``argmax``)."""
    for recipe in RECIPES.values():
        for config in recipe.rules:
            if config.type == rule_type:
                return config
    if issubclass(rule_class, RuleConfig):
        return rule_class()
    pytest.fail(
        f"rule {rule_type!r}: no recipe names it and it is not its own config; name it in a recipe or teach tests/rules/test_rules.py to make one"
    )


@pytest.fixture(scope="module")
def fitted(short_recording, tmp_path_factory) -> SimpleNamespace:
    """Every registered rule fitted to the short recording's samples, as the teach recipe fits its
    rules after C (labels steadied and samples mirrored as its training says), and a model file
    per rule that lists it and names it to drive (C reduced to its skip path: tests/helpers.py)."""
    recording = read_recording(short_recording)
    configs = {name: _config_of(name, cls) for name, cls in RULES.items()}
    dataset = build_dataset([recording], FeatureConfig(), rules=tuple(configs.values()))
    options = RECIPES["teach"].train.data
    if options.steady_labels:
        dataset, _ = steady_labels(dataset)
    data = FitData(dataset, options.mirror)
    rules = {}
    for name, config in configs.items():
        rule = config.fit(data)
        assert rule is not None, f"{name}: the fit found nothing to fit in the dataset's arrays"
        assert rule.type == name and isinstance(rule, RULES[name])
        rules[name] = rule
    features = dataset.feature_config
    folder = tmp_path_factory.mktemp("rules")
    classifier = ClassifierConfig(hidden=8, skip=True)
    assert classifier.n_features == features.n_features, "the skip path's weights fit the recording's features"
    meta = {
        **model_meta(features=features, camera=CameraConfig.from_dict(recording.meta["camera"])),
        "classes": recording.meta["classes"],
        "profile": recording.meta["profile"],
    }
    files = {
        name: save_model(
            folder / f"{name}.safetensors",
            classifier,
            skip_path_weights(classifier),
            {
                **meta,
                "rules": [rule.header()],
                "drives": name if rule.kind == STEERING else "argmax",
            },  # a speed rule sets the speed of C's way
        )
        for name, rule in rules.items()
    }
    return SimpleNamespace(
        recording=recording,
        features=features,
        raw_features=dataset.meta["features"],
        rules=rules,
        files=files,
        classes=ClassTable.from_dict(recording.meta["classes"], SOURCE),
    )


def _planner(fitted: SimpleNamespace, rule_type: str) -> Planner:
    """A fresh planner of ``rule_type``'s model file, set on the recording's path."""
    planner = Planner(load_model(fitted.files[rule_type]))
    planner.set_path(np.asarray(fitted.recording.meta["path"]))
    return planner


def _read_back(block: Mapping[str, Any], fitted: SimpleNamespace, cls: type[Rule]) -> Rule:
    return cls.from_header(block, HeaderContext(fitted.features, fitted.raw_features), Where(SOURCE, 0))


def _same_block(written: Mapping[str, Any], read: Mapping[str, Any]) -> None:
    """``read`` (a block written again after reading ``written``) is ``written``: the same values
    for every field, no field added; fields lost are :class:`WrittenButNotRead`."""
    lost = sorted(written.keys() - read.keys())
    assert {k: v for k, v in written.items() if k not in lost} == dict(read)
    if lost:
        raise WrittenButNotRead(f"fields written but not read back: {lost}")


# --- 1. the file block -------------------------------------------------------------------------------


@pytest.mark.parametrize("rule_type", rule_cases("round_trip"))
def test_a_rule_reads_back_the_block_it_writes(fitted, rule_type):
    rule = fitted.rules[rule_type]
    header = rule.header()
    assert header["type"] == rule_type
    text = json.dumps(header, allow_nan=False)  # JSON values only
    back = _read_back(json.loads(text), fitted, type(rule))
    assert type(back) is type(rule)
    _same_block(header, back.header())
    planner = Planner(load_model(fitted.files[rule_type]))  # through a model file that names it to drive (or sets the speed)
    read = planner.rule if rule.kind == STEERING else planner.speed.rule
    assert read.type == rule_type
    _same_block(header, read.header())


# --- 2. the description ------------------------------------------------------------------------------


@pytest.mark.parametrize("rule_type", RULES.names())
def test_a_rule_describes_itself_in_one_line_that_names_it(fitted, rule_type):
    table = fitted.classes
    lethal = frozenset({table.lethal_column} if table.lethal else ())  # as terrapref train and info call it
    line = fitted.rules[rule_type].describe(fitted.features.feature_classes, lethal)
    assert isinstance(line, str) and line.strip() and "\n" not in line
    assert rule_type in line or rule_type.replace("_", " ") in line, line  # argmax: "argmax: ..."; second_stage: "second stage: ..."


# --- 3. determinism ----------------------------------------------------------------------------------


def _drive(planner: Planner, recording) -> list[tuple[int, bytes, str | None]]:
    """The planner's decisions on every FRAME_STEP-th frame of ``recording``: index, command (its
    bytes: bit for bit) and stop reason."""
    out = []
    for i in range(0, len(recording), FRAME_STEP):
        d = planner.decide(recording.image(i), Pose(*recording.poses[i]), float(recording.times[i]))
        out.append((d.index, np.asarray(d.command, dtype=np.float64).tobytes(), d.stop))
    return out


@pytest.mark.parametrize("rule_type", RULES.names())
def test_two_planners_of_one_rule_decide_the_same_frames_alike(fitted, rule_type):
    rec = fitted.recording
    first, second = _planner(fitted, rule_type), _planner(fitted, rule_type)
    decisions = _drive(first, rec)
    assert len({c for _, c, _ in decisions}) > 1, "the frames give more than one command (the check is not vacuous)"
    assert _drive(second, rec) == decisions
    lethal = np.full(first.camera.shape, fitted.classes.lethal_ids[0], dtype=np.uint8)
    for step in range(3):  # something to forget: lethal ground where the run starts
        first.decide(lethal, Pose(*rec.poses[0]), float(rec.times[-1]) + 0.1 * (step + 1))
    first.set_path(np.asarray(rec.meta["path"]))  # a new run: the runner forgets what it kept
    assert _drive(first, rec) == decisions


# --- 4. a blank frame, a lethal frame ----------------------------------------------------------------


@pytest.mark.parametrize("rule_type", RULES.names())
def test_a_blank_or_lethal_frame_gives_a_finite_command(fitted, rule_type):
    pose = Pose(*fitted.recording.poses[0])
    for class_id in (UNKNOWN, fitted.classes.lethal_ids[0]):
        planner = _planner(fitted, rule_type)
        frame = np.full(planner.camera.shape, class_id, dtype=np.uint8)
        for step in range(3):  # a rule that keeps what it saw sees the same again
            d = planner.decide(frame, pose, 0.1 * step)
            assert np.isfinite(d.command.v) and np.isfinite(d.command.w), (class_id, step, d.command)
            assert 0 <= d.index < fitted.features.preference.m


# --- 5. a damaged block ------------------------------------------------------------------------------


def _numeric_fields(block: Mapping[str, Any], prefix: tuple[str, ...] = ()) -> Iterator[tuple[str, ...]]:
    """The path of every number or list of numbers in ``block``, mappings within it included."""

    def is_number(v: object) -> bool:
        return isinstance(v, (int, float)) and not isinstance(v, bool)

    for key, value in block.items():
        if isinstance(value, Mapping):
            yield from _numeric_fields(value, (*prefix, key))
        elif is_number(value) or (isinstance(value, list) and value and all(is_number(v) for v in value)):
            yield (*prefix, key)


def _damaged(block: Mapping[str, Any], path: tuple[str, ...]) -> dict[str, Any]:
    """A copy of ``block`` with the value at ``path`` replaced by a string."""
    bad = json.loads(json.dumps(block))
    inner = bad
    for key in path[:-1]:
        inner = inner[key]
    inner[path[-1]] = "x"
    return bad


def _check_damage(fitted: SimpleNamespace, rule_type: str, nested: bool) -> None:
    """Each numeric field of the rule's block (top-level ones, or those inside a mapping of it)
    replaced by a string is a UserError whose field is the block's (``rules[0]...``)."""
    rule = fitted.rules[rule_type]
    header = rule.header()
    paths = [p for p in _numeric_fields(header) if (len(p) > 1) == nested]
    if not paths:
        pytest.skip(f"the {rule_type} block has no {'nested ' if nested else ''}numeric field")
    read_back = _read_back(header, fitted, type(rule)).header()
    unread = []
    for path in paths:
        try:
            read_rules([_damaged(header, path)], fitted.features, fitted.raw_features, SOURCE)
        except UserError as exc:
            assert exc.source == SOURCE and exc.problems[0].field.startswith("rules[0]"), (path, exc.problems)
            continue
        assert path[0] not in read_back, f"{'.'.join(path)}: a string accepted in a field the rule reads"
        unread.append(".".join(path))
    if unread:
        raise WrittenButNotRead(f"a string accepted in fields the rule writes but does not read: {unread}")


@pytest.mark.parametrize("rule_type", rule_cases("damaged_number"))
def test_a_block_with_a_damaged_number_is_refused(fitted, rule_type):
    _check_damage(fitted, rule_type, nested=False)


@pytest.mark.parametrize("rule_type", rule_cases("damaged_nested_number"))
def test_a_block_with_a_damaged_nested_number_is_refused(fitted, rule_type):
    _check_damage(fitted, rule_type, nested=True)


# --- 6. what a runner offers -------------------------------------------------------------------------


@pytest.mark.parametrize("rule_type", RULES.names())
def test_what_a_runner_offers_is_consistent(fitted, rule_type):
    rec = fitted.recording
    planner = _planner(fitted, rule_type)
    i = len(rec) // 2
    planner.decide(rec.image(i), Pose(*rec.poses[i]), float(rec.times[i]))
    runner = planner.runner
    assert runner.keeps_ground_map == (planner.ground_map is not None)
    assert planner.ground_map is None or planner.ground_map.settings == runner.map_settings
    assert (planner.ground_map is None or runner.costmap(planner.ground_map) is None) == (not runner.keeps_ground_map)
    assert (planner.costmap() is None) == (not runner.keeps_ground_map)
    prices = runner.route_prices()
    if prices is not None:
        assert np.isfinite(prices.detour_price) and np.isfinite(prices.span_m), prices
    assert runner.half_width_m is None or (np.isfinite(runner.half_width_m) and runner.half_width_m > 0)


@pytest.mark.parametrize("rule_type", RULES.names())
def test_each_rule_is_of_a_kind_and_runs_as_one(fitted, rule_type):
    """A steering rule runs as a SteeringRunner, the speed rule as a SpeedRunner, and the stop rule
    every planner has as a StopRunner; the planner hands the speed rule the steering rule's choice."""
    cls = RULES[rule_type]
    assert cls.kind in (STEERING, SPEED)
    planner = _planner(fitted, rule_type)
    runners = {STEERING: planner.runner, SPEED: planner.speed}
    assert isinstance(runners[cls.kind], {STEERING: SteeringRunner, SPEED: SpeedRunner}[cls.kind])
    assert isinstance(planner.stop_rule, StopRunner)
    assert planner.stop_rule.stale(1.0, None, 0.3) and planner.stop_rule.stale(1.31, 1.0, 0.3)
    assert not planner.stop_rule.stale(1.3, 1.0, 0.3)  # held exactly hold_s: fresh


def test_a_model_file_names_the_rule_that_steers_and_the_one_that_sets_the_speed():
    from test_interop import speed_block
    from test_offset_rule import DRIVER_LIKE, _offset_meta

    meta = _offset_meta(DRIVER_LIKE)
    meta |= {"rules": [*meta["rules"], speed_block(1.0)], "drives": "offset", "sets_speed": "speed"}
    rules, steering = rules_in(meta, "m.safetensors")
    assert steering.type == "offset" and [r.kind for r in rules] == [STEERING, SPEED]
    assert rule_roles(["second_stage", "offset", "speed"]) == "steers: offset; sets the speed: speed; fitted to be reported: second_stage"
    with pytest.raises(
        UserError, match="m.safetensors: sets_speed: names rule 'offset' to set the speed, but the speed rule it lists is speed"
    ):
        rules_in({**meta, "sets_speed": "offset"}, "m.safetensors")
    types = [block["type"] for block in meta["rules"]]
    for twice in ("offset", "speed"):  # which of two would drive would depend on who reads the file
        with pytest.raises(UserError) as err:
            rules_in({**meta, "rules": [*meta["rules"], meta["rules"][types.index(twice)]]}, "m.safetensors")
        said = f"a second {twice!r} rule (rules[{types.index(twice)}] is one); a file holds one rule of each type"
        assert err.value.lines() == [f"m.safetensors: rules[{len(types)}].type: {said}"]


def test_a_speed_rule_slowing_for_a_column_the_class_table_calls_safe_is_refused(tmp_path):
    """The speed rule keeps off its lethal columns; a file whose table has no lethal class but
    whose rule lists one would slow on that class everywhere. A rule listing none (files older
    than lethal columns) reads with any table."""
    from test_interop import speed_block
    from test_offset_rule import DRIVER_LIKE, _offset_meta

    from helpers import skip_path_weights

    config = ClassifierConfig(hidden=8, skip=True)
    meta = _offset_meta(DRIVER_LIKE)
    table = meta["classes"]
    rules = [*meta["rules"], {**speed_block(1.0), "lethal": [0]}]
    load_model(save_model(tmp_path / "ok.safetensors", config, skip_path_weights(config), {**meta, "rules": rules}))
    lethal_column = meta["features"]["feature_classes"][0]
    safe = {**table, "lethal": []}
    profile = [name for name in meta["profile"] if name != lethal_column] + [lethal_column]
    meta_safe = {**meta, "classes": safe, "rules": rules, "profile": profile}
    with pytest.raises(UserError) as err:
        Planner(load_model(save_model(tmp_path / "bad.safetensors", config, skip_path_weights(config), meta_safe)))
    assert err.value.lines()[0].endswith(f"rules[{len(rules) - 1}].lethal: column 0 is not lethal in the file's class table")


@pytest.mark.parametrize(
    ("background", "said"),
    [
        ("lava", "unknown class 'lava'; the file's class table's background is 'grass'"),
        ("mud", "not the background class 'mud'; the file's class table's background is 'grass'"),
    ],
)
def test_a_speed_rule_naming_a_background_its_class_table_does_not_is_refused_where_the_model_is_read(tmp_path, capsys, background, said):
    """A speed rule keeps a speed for the table's background under that class's name; a file edited
    to name another class there (one the table lacks, or one of its own columns) is refused by
    every command that reads it, and ``info`` shows it as not readable. A block naming none (a file
    older than the field) reads with any table."""
    from test_interop import speed_block
    from test_offset_rule import DRIVER_LIKE, _offset_meta

    from terrapref.cli import main

    config = ClassifierConfig(hidden=8, skip=True)
    meta = _offset_meta(DRIVER_LIKE)
    for name in (None, "grass"):
        block = speed_block(1.0) | ({"background": name} if name else {})
        Planner(
            load_model(
                save_model(tmp_path / "ok.safetensors", config, skip_path_weights(config), {**meta, "rules": [*meta["rules"], block]})
            )
        )
    rules = [*meta["rules"], {**speed_block(1.0), "background": background}]
    path = save_model(tmp_path / "bad.safetensors", config, skip_path_weights(config), {**meta, "rules": rules})
    with pytest.raises(UserError) as err:
        Planner(load_model(path))
    assert err.value.lines() == [f"{path}: rules[1].background: {said}"]
    assert main(["info", str(path)]) == 2
    captured = capsys.readouterr()
    assert f"{path}: terrapref model (classifier), NOT READABLE: rules[1].background: {said}" in captured.out
    assert captured.err.splitlines() == [f"error: {path}: rules[1].background: {said}"]
    assert main(["evaluate", str(path), "gen:7", "--seeds", "1", "--out", str(tmp_path / "ev")]) == 2
    assert capsys.readouterr().err.splitlines() == [f"error: {path}: rules[1].background: {said}"]
    assert not (tmp_path / "ev").exists()


SPEEDS_SAID = "expected 5 cruising speeds > 0 and at most 50 m/s, one per terrain column and the background"


@pytest.mark.parametrize(
    ("change", "field", "said"),
    [
        ({"speeds_mps": [0.0, 1.0, 1.0, 1.0, 1.0]}, "speeds_mps", SPEEDS_SAID),
        ({"speeds_mps": [1e9, 1.0, 1.0, 1.0, 1.0]}, "speeds_mps", SPEEDS_SAID),
        ({"lethal": [0, 4]}, "lethal", "expected terrain columns 0..3 (column 4 is the background, never lethal)"),
        ({"max_speed_mps": 1e-9}, "max_speed_mps", "expected 0.1 to 50 m/s, got 1e-09"),
        ({"lateral_accel_mps2": 1e300}, "lateral_accel_mps2", "expected a number within +-1e+09, got 1e+300"),
        ({"near_lethal_m": 1.0, "near_lethal_mps": 1e3}, "near_lethal_mps", "expected at most 50 m/s, got 1000"),
        ({"intervals_mps": [None, [9.0, -3.0], None, None, None]}, "intervals_mps", "an interval reads high then low: 9 to -3"),
        ({"preview_m": 1e308}, "preview_m", "expected a number within +-1e+09, got 1e+308"),
    ],
    ids=[
        "standing",
        "past-any-robot",
        "background-lethal",
        "top-crawl",
        "sideways-past",
        "near-lethal",
        "interval",
        "past-any-number",
    ],
)
def test_a_speed_block_past_what_a_drive_or_a_robot_shows_is_refused(change: dict, field: str, said: str):
    """A file edited to stand (a vehicle that never gets anywhere), to drive past any robot's
    speed, or to slow on its background everywhere is refused, naming the field. Slower than the
    least cruising speed reads (a log's standing noise may fit so; the rule drives it at that speed)."""
    from test_interop import speed_block
    from test_offset_rule import DRIVER_LIKE, _offset_meta

    meta = _offset_meta(DRIVER_LIKE)
    for v_mps in (1.0, 0.005):  # as written, read
        rules_in({**meta, "rules": [*meta["rules"], speed_block(v_mps)]}, "m.safetensors")
    with pytest.raises(UserError) as err:
        rules_in({**meta, "rules": [*meta["rules"], {**speed_block(1.0), **change}]}, "m.safetensors")
    assert err.value.lines() == [f"m.safetensors: rules[{len(meta['rules'])}].{field}: {said}"]


# --- 7. the registry ---------------------------------------------------------------------------------


def _subclasses(cls: type) -> Iterator[type]:
    for sub in cls.__subclasses__():
        yield sub
        yield from _subclasses(sub)


def test_rules_lists_every_rule_class_the_package_defines():
    for info in pkgutil.walk_packages(terrapref.rules.__path__, "terrapref.rules."):
        importlib.import_module(info.name)  # every module of the package, so that every rule class it defines exists
    defined = {cls for cls in _subclasses(Rule) if cls.__module__.startswith("terrapref.rules") and not inspect.isabstract(cls)}
    exported = {v for v in vars(terrapref.rules).values() if inspect.isclass(v) and issubclass(v, Rule) and v is not Rule}
    registered = dict(RULES.items())
    assert defined and exported <= defined
    outside = sorted(cls.__name__ for cls in defined - set(registered.values()))
    assert not outside, f"rule classes outside RULES: {outside}"
    assert set(registered.values()) <= defined
    assert all(cls.type == name for name, cls in registered.items())
