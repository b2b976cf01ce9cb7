"""The named recipes, the synthetic driver's styles, and merging training data: what each recipe
holds, what each style changes, and which datasets can be trained on together."""

from __future__ import annotations

import json
from dataclasses import fields, replace

import numpy as np
import pytest

from helpers import TINY_COURSE, model_meta, train_config
from terrapref.camera import CameraConfig
from terrapref.dataset import FORMAT as DATASET_FORMAT
from terrapref.dataset import Dataset, build_dataset, check_learnable, merge_datasets, save_dataset, training_data
from terrapref.demos.expert import STYLES, ExpertConfig, ExpertDriver
from terrapref.demos.session import DisturbanceConfig
from terrapref.errors import UserError
from terrapref.features import FeatureConfig
from terrapref.learning.train import TrainConfig
from terrapref.recipes import DEFAULT_RECIPE, RECIPES, Recipe, recipe_named, rules_with
from terrapref.rules import OffsetConfig, SecondStageConfig, SpeedConfig
from terrapref.rules.offset.geometry import OffsetGeometry
from terrapref.rules.second.lookahead import LookaheadConfig
from terrapref.rules.speed.model import STATIONS
from terrapref.scenario import parse_scenario
from terrapref.terrain import default_classes

# --- the named recipes -------------------------------------------------------------------------------


def test_the_recipes_and_the_default():
    assert list(RECIPES) == ["teach", "ours", "paper"]
    assert DEFAULT_RECIPE == "teach"
    assert all(recipe.name == name and recipe.summary for name, recipe in RECIPES.items())


def test_recipe_named():
    assert recipe_named("paper") is RECIPES["paper"]
    assert recipe_named(DEFAULT_RECIPE).course == "teach_course"


@pytest.mark.parametrize("flag", ["--recipe", "--recipes"])
def test_an_unknown_recipe_is_a_user_error_naming_the_flag_and_the_recipes(flag: str):
    with pytest.raises(UserError) as caught:
        recipe_named("bogus", flag)
    assert not isinstance(caught.value, ValueError)  # a UserError, not a ValueError
    assert caught.value.lines() == [f"{flag}: unknown recipe 'bogus'; recipes: teach, ours, paper"]


def test_the_paper_recipe_is_the_published_one():
    paper = RECIPES["paper"]
    assert paper.train == TrainConfig()
    opt = paper.train.optimiser
    assert (opt.epochs, opt.lr, opt.batch_size, opt.val_fraction) == (15, 1e-3, 256, 0.2)
    assert not (paper.train.classifier.skip or paper.train.data.class_balance or paper.train.data.mirror)
    assert paper.rules == () and paper.train.classifier.members == 1
    assert (paper.demonstrations, paper.corrections, paper.course) == (1, 0, "train_course")
    assert paper.disturbance is None
    assert paper.features() == FeatureConfig()  # the paper's U


def test_ours_drives_train_course_twice_with_pushes():
    ours = RECIPES["ours"]
    assert (ours.demonstrations, ours.course, ours.disturbance) == (2, "train_course", DisturbanceConfig(rate_hz=0.3))
    assert (ours.train.optimiser.epochs, ours.train.optimiser.lr, ours.train.classifier.members) == (100, 3e-3, 1)
    assert ours.train.classifier.skip and ours.train.data.class_balance and ours.train.data.mirror and ours.rules == (SecondStageConfig(),)
    assert ours.rules[0].data() is None  # fitted frame by frame: it reads nothing of the frames


def test_teach_drives_teach_course_once_and_fits_through_the_lookahead():
    teach = RECIPES["teach"]
    assert (teach.demonstrations, teach.course, teach.disturbance) == (
        1,
        "teach_course",
        DisturbanceConfig(rate_hz=0.6, clear_m=3.0, clear_s=2.0),
    )
    assert (teach.train.optimiser.epochs, teach.train.optimiser.lr, teach.train.classifier.members) == (100, 3e-3, 3)
    assert teach.train.classifier.skip and teach.train.data.class_balance and teach.train.data.mirror
    # the offset rule, the last that steers, drives; the speed rule sets its speed
    assert teach.rules == (SecondStageConfig(weight=5.0, lookahead=True), OffsetConfig(), SpeedConfig())
    assert teach.features() == FeatureConfig()
    assert [r.data() for r in teach.rules] == [
        {"lookahead": LookaheadConfig().to_dict()},
        {"geometry": OffsetGeometry().to_dict()},
        {"half_width_m": SpeedConfig().half_width_m},
    ]


def test_features_are_the_base_given():
    base = FeatureConfig(path_spacing_m=0.5)
    assert RECIPES["teach"].features(base) == base == RECIPES["paper"].features(base)


@pytest.mark.parametrize("bad", [dict(demonstrations=0), dict(corrections=-1)])
def test_recipes_are_validated(bad: dict):
    with pytest.raises(ValueError):
        Recipe("bad", **bad)


def test_to_dict_is_plain_data():
    data = RECIPES["teach"].to_dict()
    assert data["name"] == "teach" and data["train"]["optimiser"]["epochs"] == 100 and data["disturbance"]["rate_hz"] == 0.6


# --- the driver's styles -------------------------------------------------------------------------------

PROFILE = ("water", "rock", "mud", "non_traversable")

# What each style is meant to change, and which way: +1 more than the default, -1 less, SET where
# the default has none (its speed style: the default driver keeps 1 m/s everywhere).
SET = "set"
MEANT = {
    "default": {},
    "wide": {"margin_m": +1, "lethal_margin_m": +1, "speed_mps": +1, "ranked_speeds_mps": SET, "lateral_accel_mps2": SET}
    | {"near_lethal_mps": SET, "preview_m": +1},
    "late": {"reaction_distance_m": -1, "reaction_delay_s": +1, "speed_mps": +1, "ranked_speeds_mps": SET, "lateral_accel_mps2": SET}
    | {"preview_m": -1},
    "shaky": {"stick_noise_rps": +1, "deadzone_rps": +1, "speed_mps": +1, "ranked_speeds_mps": SET, "lateral_accel_mps2": SET},
    "reluctant": {"deviation_cost": +1, "speed_mps": +1, "ranked_speeds_mps": SET, "lateral_accel_mps2": SET, "near_lethal_mps": SET},
}


def test_every_style_is_described_and_listed_here():
    assert set(STYLES) == set(MEANT)
    assert all(style.description for _, style in STYLES.items())


@pytest.mark.parametrize("style", list(STYLES))
def test_a_style_is_the_default_driver_with_its_own_changes(style: str):
    default, styled = ExpertConfig(profile=PROFILE), ExpertConfig.styled(style, PROFILE)
    assert styled.profile == PROFILE
    changed = {
        f.name: (getattr(default, f.name), getattr(styled, f.name))
        for f in fields(ExpertConfig)
        if getattr(default, f.name) != getattr(styled, f.name)
    }
    assert set(changed) == set(MEANT[style])
    for name, (before, after) in changed.items():
        if MEANT[style][name] == SET:
            assert before is None and after is not None, (name, before, after)
        else:
            assert (after - before) * MEANT[style][name] > 0, (name, before, after)
    if style != "default":  # a speed style: slower on the least preferred patch than on the most, both below open ground
        fast, slow = styled.ranked_speeds_mps
        assert styled.speed_mps > fast > slow > 0
    ExpertDriver(styled)  # builds its footprint and offsets from the config


def test_the_style_without_a_profile_keeps_the_default_profile():
    assert ExpertConfig.styled("late").profile == ExpertConfig().profile
    assert ExpertConfig.styled() == ExpertConfig()


def test_the_numbers_in_the_descriptions_are_the_configs():
    default, wide, late = ExpertConfig(), ExpertConfig.styled("wide"), ExpertConfig.styled("late")
    assert f"reacts {default.reaction_distance_m:g} m ahead, {default.half_width_m:g} m half-width" in STYLES["default"].description
    assert f"terrain within {wide.margin_m:g} m beside it costs half" in STYLES["wide"].description
    assert f"{wide.lethal_margin_m:g} m extra from lethal terrain" in STYLES["wide"].description
    assert f"{late.reaction_distance_m:g} m ahead, not {default.reaction_distance_m:g} m" in STYLES["late"].description
    assert f"{ExpertConfig.styled('shaky').stick_noise_rps:g} rad/s of tremor" in STYLES["shaky"].description
    assert ExpertConfig.styled("reluctant").deviation_cost == 2 * default.deviation_cost  # "twice the cost"


def test_an_unknown_style_is_refused_naming_the_styles():
    with pytest.raises(ValueError, match=r"unknown driver style 'sleepy'; styles: default, wide, late, shaky, reluctant"):
        ExpertConfig.styled("sleepy")


def _patch(cls: str, radius_m: float = 1.6):
    """A straight trail along y = 10 from x = 2 with one circular patch at x = 15."""
    return parse_scenario(
        {
            "format": "terrapref-scenario/1",
            "name": "one_patch",
            "world": {"size_m": [30.0, 20.0], "resolution_m": 0.05, "background": "grass"},
            "terrain": [{"class": cls, "circle": {"center": [15.0, 10.0], "radius": radius_m}}],
            "path": {"waypoints": [[2.0, 10.0], [28.0, 10.0]]},
        }
    )


def _offset(style: str, scenario, s_m: float) -> float:
    driver = ExpertDriver(ExpertConfig.styled(style))
    driver.reset(scenario, np.random.default_rng(0))
    return driver.choose_offset(s_m)


def test_the_late_driver_reacts_nearer_the_patch():
    water = _patch("water")  # its near edge at s = 11.4
    assert _offset("default", water, 7.0) > 0.0 == _offset("late", water, 7.0)  # 4.4 m ahead
    assert _offset("late", water, 8.5) == _offset("default", water, 8.5) > 0.0  # 2.9 m ahead


def test_the_reluctant_driver_swerves_less():
    water = _patch("water")
    assert 0.0 < _offset("reluctant", water, 9.0) < _offset("default", water, 9.0)


def test_the_wide_driver_keeps_further_from_lethal_terrain():
    wall = _patch("non_traversable")
    assert _offset("wide", wall, 9.0) >= _offset("default", wall, 9.0) + 0.2


@pytest.mark.parametrize("cls, radius_m", [("water", 0.8), ("water", 1.6), ("rock", 1.4)])
def test_the_wide_driver_passes_a_patch_further_out(cls: str, radius_m: float):
    patch = _patch(cls, radius_m)
    assert abs(_offset("wide", patch, 9.0)) >= abs(_offset("default", patch, 9.0)) + 0.2 > 0.2


# --- merging training data -------------------------------------------------------------------------------


def _dataset(n: int, recordings: int, seed: int, lookahead: bool = False, **meta) -> Dataset:
    """``n`` random samples from ``recordings`` recordings (source 0, 1, ... in turn)."""
    rng = np.random.default_rng(seed)
    m, k = 21, 5
    source = np.sort(np.arange(n) % recordings).astype(np.int64)
    meta = {"format": DATASET_FORMAT, **model_meta(), "recordings": [{"path": f"rec{seed}_{i}"} for i in range(recordings)], **meta}
    rules = {"second_stage": {"U2": rng.uniform(0, 1, (n, m, m, k)).astype(np.float16)}} if lookahead else {}
    if lookahead:
        meta["rules"] = {"second_stage": {"config": SecondStageConfig(lookahead=True).data(), "arrays": {"U2": "finite"}}}
    return Dataset(
        rng.uniform(0, 1, (n, m, k)).astype(np.float32),
        rng.integers(0, m, n),
        rng.uniform(-1, 1, n).astype(np.float32),
        source,
        meta,
        rules,
    )


def test_merging_concatenates_and_numbers_the_recordings_across_all():
    a, b, c = _dataset(4, 2, 0), _dataset(3, 1, 1), _dataset(2, 2, 2)
    merged = merge_datasets([("a.safetensors", a), ("b.safetensors", b), ("c.safetensors", c)])
    assert len(merged) == 9
    np.testing.assert_array_equal(merged.U, np.concatenate([a.U, b.U, c.U]))
    np.testing.assert_array_equal(merged.labels, np.concatenate([a.labels, b.labels, c.labels]))
    np.testing.assert_array_equal(merged.w, np.concatenate([a.w, b.w, c.w]))
    np.testing.assert_array_equal(merged.source, [0, 0, 1, 1, 2, 2, 2, 3, 4])
    assert [r["path"] for r in merged.meta["recordings"]] == ["rec0_0", "rec0_1", "rec1_0", "rec2_0", "rec2_1"]
    assert merged.U2 is None
    assert merged.meta["profile"] == a.meta["profile"]


def test_merging_numbers_by_the_recordings_listed_even_without_samples():
    a, b = _dataset(4, 2, 0), _dataset(3, 1, 1)
    a = Dataset(a.U, a.labels, a.w, np.zeros(4, np.int64), a.meta)  # its second recording left no samples
    merged = merge_datasets([("a.safetensors", a), ("b.safetensors", b)])
    np.testing.assert_array_equal(merged.source, [0, 0, 0, 0, 2, 2, 2])
    assert merged.meta["recordings"][2]["path"] == "rec1_0"


def test_merging_keeps_the_lookahead_utilities():
    a, b = _dataset(3, 1, 0, lookahead=True), _dataset(2, 1, 1, lookahead=True)
    merged = merge_datasets([("a", a), ("b", b)])
    assert merged.U2.shape == (5, 21, 21, 5) and merged.U2.dtype == np.float16
    np.testing.assert_array_equal(merged.U2, np.concatenate([a.U2, b.U2]))


def test_one_dataset_is_returned_as_it_is():
    a = _dataset(3, 1, 0)
    assert merge_datasets([("a", a)]) is a


def test_no_datasets_is_a_user_error():
    with pytest.raises(UserError, match="no training data given"):
        merge_datasets([])


@pytest.mark.parametrize(
    "field, value",
    [
        ("profile", ["water", "rock", "mud", "non_traversable"]),
        ("features", FeatureConfig(path_spacing_m=0.5).to_dict()),
        ("camera", CameraConfig(hfov_deg=60.0).to_dict()),
        ("classes", {**default_classes().to_dict(), "background": "mud"}),
    ],
)
def test_datasets_made_differently_are_refused_naming_the_file_and_field(field: str, value):
    a, b = _dataset(3, 1, 0), _dataset(3, 1, 1, **{field: value})
    with pytest.raises(UserError) as caught:
        merge_datasets([("first.safetensors", a), ("second.safetensors", b)])
    error = caught.value
    assert error.source == "second.safetensors" and [p.field for p in error.problems] == [field]
    if field == "profile":  # two drivers' orders: both named
        expected = (
            "second.safetensors: profile: declares the order water > rock > mud > non_traversable, first.safetensors "
            "mud > rock > water > non_traversable: one model learns one driver's order; featurise drives of one order together"
        )
    else:
        expected = f"second.safetensors: {field}: differs from first.safetensors in {field}; featurise all recordings the same way"
    assert error.lines() == [expected]


def test_a_dataset_that_declares_no_order_joins_one_that_does():
    """A drive without --profile declares none: it contradicts no order, and the merge takes the one declared."""
    order = ["water", "rock", "mud", "non_traversable"]
    none, declared = _dataset(3, 1, 0, profile=None), _dataset(3, 1, 1, profile=order)
    assert merge_datasets([("a", none), ("b", declared)]).meta["profile"] == order
    assert merge_datasets([("a", none), ("b", _dataset(2, 1, 2, profile=None))]).meta["profile"] is None


@pytest.mark.parametrize("first, second", [(False, True), (True, False)])
def test_datasets_with_and_without_lookahead_are_refused(first: bool, second: bool):
    a, b = _dataset(3, 1, 0, lookahead=first), _dataset(3, 1, 1, lookahead=second)
    with pytest.raises(UserError) as caught:
        merge_datasets([("first.safetensors", a), ("second.safetensors", b)])
    assert caught.value.source == "second.safetensors" and [p.field for p in caught.value.problems] == ["rules"]
    assert "first.safetensors" in str(caught.value)


def test_training_data_merges_dataset_files(tmp_path):
    a, b = _dataset(4, 2, 0), _dataset(3, 1, 1)
    paths = [save_dataset(a, tmp_path / "a.safetensors"), save_dataset(b, tmp_path / "b.safetensors")]
    merged = training_data(paths, FeatureConfig())
    np.testing.assert_array_equal(merged.U, np.concatenate([a.U, b.U]))
    np.testing.assert_array_equal(merged.labels, np.concatenate([a.labels, b.labels]))
    np.testing.assert_array_equal(merged.source, [0, 0, 1, 1, 2, 2, 2])


def test_training_data_names_the_file_that_differs(tmp_path):
    a, b = _dataset(4, 2, 0), _dataset(3, 1, 1, profile=["water", "rock", "mud", "non_traversable"])
    paths = [save_dataset(a, tmp_path / "a.safetensors"), save_dataset(b, tmp_path / "b.safetensors")]
    with pytest.raises(UserError) as caught:
        training_data(paths, FeatureConfig())
    assert caught.value.source == str(paths[1]) and caught.value.problems[0].field == "profile"
    assert str(paths[0]) in caught.value.problems[0].message


def test_samples_with_nothing_to_learn_are_refused():
    data = _dataset(6, 2, 0)
    check_learnable(data, "a.safetensors")
    for empty, field in (
        (replace(data, U=data.U[:0], labels=data.labels[:0]), "frames"),
        (replace(data, labels=np.full_like(data.labels, 7)), "labels"),
    ):
        with pytest.raises(UserError) as caught:
            check_learnable(empty, "a.safetensors")
        assert caught.value.source == "a.safetensors" and caught.value.problems[0].field == field


def test_the_second_stage_is_added_left_out_or_weighted():
    teach, paper = RECIPES["teach"], RECIPES["paper"]
    assert rules_with(teach) == teach.rules and rules_with(teach, True) == teach.rules
    assert rules_with(teach, False) == (OffsetConfig(), SpeedConfig())
    assert rules_with(paper, True, 2.0) == (SecondStageConfig(weight=2.0),)
    with pytest.raises(UserError, match="recipe paper has no second stage here"):
        rules_with(paper, stage_weight=2.0)
    with pytest.raises(UserError, match="recipe teach has no second stage here"):
        rules_with(teach, False, 2.0)


def test_run_recipe_demonstrates_corrects_and_reuses_demonstrations(tmp_path):
    from terrapref.recipes import Recipe, RecipeSetup, run_recipe

    # The skip path: a planner that drives the course to the goal, so that the correction session
    # is one drive of the course rather than one until the time limit.
    recipe = Recipe("tiny", demonstrations=1, corrections=1, train=train_config(epochs=2, skip=True))
    setup = RecipeSetup(0, course=str(TINY_COURSE))
    out = run_recipe(recipe, tmp_path, setup, write_recordings=True)
    assert out.model.exists()
    assert [p.name for p in out.recordings] == ["tiny_course_0", "corrections_0"]
    assert out.demo_minutes > 0 and out.correction_minutes > 0
    stamp = (tmp_path / "tiny_course_0" / "meta.json").stat().st_mtime_ns
    again = run_recipe(Recipe("plain", demonstrations=1, train=train_config(epochs=2)), tmp_path, setup)
    assert again.recordings == [tmp_path / "tiny_course_0"] and again.correction_minutes == 0
    assert (tmp_path / "tiny_course_0" / "meta.json").stat().st_mtime_ns == stamp  # reused, not recorded again


def test_demonstrations_kept_in_memory_train_what_their_recordings_train(tmp_path):
    """A demonstration kept in memory is featurised from the simulation's own views: the same
    samples, look-ahead and fingerprint as the same run written to disk and read back."""
    from terrapref.learning.model_file import read_model_file
    from terrapref.recipes import TEACH, RecipeSetup, demonstrate, run_recipe

    features = TEACH.features()
    setup = RecipeSetup(3, course=str(TINY_COURSE), features=features)
    kept = demonstrate(TEACH, tmp_path / "mem", setup, write=False)
    written = demonstrate(TEACH, tmp_path / "disk", setup, write=True)
    assert kept[0].in_memory and not written[0].in_memory and not (tmp_path / "mem").exists()
    a, b = build_dataset(kept, features), build_dataset(written, features)
    assert a.fingerprint == b.fingerprint and len(a) == len(written[0]) > 100
    np.testing.assert_array_equal(a.w, b.w)
    np.testing.assert_array_equal(kept[0].poses, written[0].poses)
    assert a.meta["recordings"][0]["written"] is False and "written" not in b.meta["recordings"][0]
    out = run_recipe(replace(TEACH, train=train_config(epochs=1)), tmp_path / "job", RecipeSetup(3, course=str(TINY_COURSE)))
    assert out.recordings == [] and out.model.exists() and not (tmp_path / "job" / "tiny_course_0_disturbed").exists()
    header = read_model_file(out.model)[1]  # the model file says which rule steers and which sets the speed
    assert (header["drives"], header["sets_speed"]) == ("offset", "speed")


def test_a_cache_featurises_each_recording_once_into_the_same_dataset(tmp_path, monkeypatch):
    """build_dataset's cache (the follow-up's question and then training): each recording is
    featurised once per features, and the dataset is the one built without it."""
    import terrapref.dataset as dataset_module
    from terrapref.recipes import TEACH, RecipeSetup, demonstrate

    features, rules = TEACH.features(), TEACH.rules
    recordings = demonstrate(Recipe("two", demonstrations=2), tmp_path, RecipeSetup(3, course=str(TINY_COURSE)), write=False)
    plain, one = build_dataset(recordings, features, rules=rules), build_dataset(recordings[:1], features, rules=rules)
    calls: list[int] = []
    featurise = dataset_module.featurize_recording
    monkeypatch.setattr(dataset_module, "featurize_recording", lambda rec, *a: calls.append(id(rec)) or featurise(rec, *a))
    cache: dict = {}
    first = build_dataset(recordings[:1], features, rules=rules, cache=cache)
    both = build_dataset(recordings, features, rules=rules, cache=cache)
    assert calls == [id(recordings[0]), id(recordings[1])]  # the first recording was not featurised again
    assert both.fingerprint == plain.fingerprint and first.fingerprint == one.fingerprint
    for a, b in ((both.U, plain.U), (both.labels, plain.labels), (both.w, plain.w), (both.source, plain.source), (both.U2, plain.U2)):
        np.testing.assert_array_equal(a, b)
    assert both.meta == plain.meta
    build_dataset(recordings, features, rules=rules[1:], cache=cache)  # other rules' data: featurised anew
    assert len(calls) == 4


def test_a_recorded_demonstration_of_another_course_is_recorded_again(tmp_path):
    from terrapref.demos.recording import read_recording
    from terrapref.recipes import RecipeSetup, record_demonstrations

    recipe = Recipe("one", demonstrations=2)
    logged: list[str] = []
    setup = RecipeSetup(0, course=str(TINY_COURSE))
    record_demonstrations(recipe, tmp_path, setup, log=logged.append)
    assert len(logged) == 2
    meta_path = tmp_path / "tiny_course_1" / "meta.json"
    meta_path.write_text(json.dumps({**json.loads(meta_path.read_text()), "scenario": "another_course"}))
    logged.clear()
    record_demonstrations(recipe, tmp_path, setup, log=logged.append)
    assert read_recording(tmp_path / "tiny_course_1").meta["scenario"] == "tiny_course"
    assert len(logged) == 1 and logged[0].startswith(f"demonstration 2/2 ({TINY_COURSE})"), "run 0 reused, run 1 recorded again"


def test_datasets_whose_rule_arrays_were_read_another_way_are_refused_naming_the_array():
    """A relief drive featurised before the speed rule read its grades on the footprint's 5 points
    holds a grade a station; one featurised now, five: they do not mix."""
    a, b = _dataset(3, 1, 0), _dataset(3, 1, 1)
    a.rules["speed"] = {"grade": np.zeros((3, STATIONS, 5), np.float32)}
    b.rules["speed"] = {"grade": np.zeros((3, STATIONS), np.float32)}
    with pytest.raises(UserError) as caught:
        merge_datasets([("first.safetensors", a), ("second.safetensors", b)])
    assert caught.value.lines() == [
        "second.safetensors: rules.speed.grade: holds (24,) a sample where first.safetensors holds (24, 5); "
        "featurise all recordings the same way"
    ]


def test_a_flat_drives_grades_merge_whichever_way_they_were_read():
    """On flat ground the grade is unknown everywhere (NaN), read one a station or one a footprint
    point: a flat drive featurised before joins one featurised now, its grades taken as unknown."""
    a, b = _dataset(3, 1, 0), _dataset(2, 1, 1)
    a.rules["speed"] = {"grade": np.ones((3, STATIONS, 5), np.float32)}
    b.rules["speed"] = {"grade": np.full((2, STATIONS), np.nan, np.float32)}
    merged = merge_datasets([("now.safetensors", a), ("before.safetensors", b)])
    grade = merged.rules["speed"]["grade"]
    assert grade.shape == (5, STATIONS, 5) and (grade[:3] == 1).all() and np.isnan(grade[3:]).all()
