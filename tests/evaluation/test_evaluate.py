"""Closed-loop evaluation (SPEC 12) and the `evaluate` command: metrics.json holds every run's
scores, figures are written, `best` zones follow the profile, user errors are one line."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from helpers import SHORT_COURSE, linear_model, model_meta, one_line_error, skip_path_weights
from terrapref.cli import main
from terrapref.demos.expert import ExpertConfig
from terrapref.demos.meta import ExpertInfo
from terrapref.errors import UserError
from terrapref.evaluation.evaluate import Evaluation, evaluate_model, file_stem
from terrapref.grid import Engine
from terrapref.learning.model_file import FORMAT as MODEL_FORMAT
from terrapref.learning.model_file import save_model
from terrapref.learning.network import ClassifierConfig
from terrapref.scenario import resolve_scenario
from terrapref.tensorfile import write_tensor_file
from terrapref.terrain import PreferenceProfile, default_classes

PNG = b"\x89PNG\r\n\x1a\n"
RUN_KEYS = {"completed", "collisions", "duration_s", "rms_cross_track_m", "max_cross_track_m", "distance_m", "zones"}
ZONE_KEYS = {"id", "expect", "choice", "success"}
ROCK_FIRST = "rock,mud,water,non_traversable"
COURSE = str(SHORT_COURSE)  # demo_course's zones (lone water, mud vs rock, lone non_traversable) on a shorter trail
STEM = file_stem(COURSE)  # its figures' names


@pytest.fixture(scope="module")
def model_path(tmp_path_factory) -> Path:
    return linear_model(tmp_path_factory.mktemp("model") / "linear.safetensors")


@pytest.fixture(scope="module")
def evaluated(model_path: Path, tmp_path_factory) -> SimpleNamespace:
    out = tmp_path_factory.mktemp("eval") / "ev"
    metrics = evaluate_model(Evaluation(str(model_path), (COURSE,), seeds=2, frames=(5,)), out, engine=Engine(workers=1))
    return SimpleNamespace(out=out, metrics=metrics)


# --- evaluate_model ------------------------------------------------------------------------------------


def test_metrics_file_is_what_was_returned(evaluated):
    on_disk = json.loads((evaluated.out / "metrics.json").read_text())
    assert on_disk == json.loads(json.dumps(evaluated.metrics))
    assert on_disk["seeds"] == 2
    assert on_disk["profile"] == list(default_classes().profile)
    assert not [p.name for p in evaluated.out.iterdir() if p.name.endswith(".tmp")]


@pytest.mark.parametrize("driver", ["planner", "driver"])
def test_every_run_is_scored(evaluated, driver: str):
    scenario = resolve_scenario(COURSE)
    runs = evaluated.metrics["scenarios"][COURSE][driver]
    assert sorted(runs) == ["0", "1"]
    goal = scenario.waypoints[-1]
    for seed, run in runs.items():
        assert RUN_KEYS <= set(run), seed
        assert isinstance(run["completed"], bool) and isinstance(run["collisions"], int) and run["collisions"] >= 0
        assert 0 < run["duration_s"]
        assert 0 <= run["rms_cross_track_m"] <= run["max_cross_track_m"]
        assert set(run["distance_m"]) == set(default_classes().names)
        assert all(v >= 0 for v in run["distance_m"].values())
        driven = sum(run["distance_m"].values())
        if run["completed"]:
            # From the start to within the goal radius (2 m) of the last waypoint, at <= 1 m/s.
            assert driven >= math.dist(scenario.start[:2], goal) - 2.0 - 0.5
            assert driven <= run["duration_s"] * 1.0 + 0.5
        assert [z["id"] for z in run["zones"]] == [z.id for z in scenario.zones]
        for z in run["zones"]:
            assert ZONE_KEYS <= set(z)
            assert z["expect"] in ("avoid", *default_classes().feature_names)
            assert z["choice"] in ("avoid", "not reached", *default_classes().feature_names)
            assert isinstance(z["success"], bool)
            assert (z["choice"] == "not reached") is (not z["reached"]) and z["success"] <= z["reached"]
            if z["choice"] != z["expect"]:
                assert not z["success"]


def test_the_synthetic_driver_drives_the_course(evaluated):
    for run in evaluated.metrics["scenarios"][COURSE]["driver"].values():
        assert run["completed"] and run["collisions"] == 0


def test_best_zone_resolves_under_the_models_profile(evaluated):
    for driver in ("planner", "driver"):
        for run in evaluated.metrics["scenarios"][COURSE][driver].values():
            expect = {z["id"]: z["expect"] for z in run["zones"]}
            assert expect == {"1": "avoid", "2": "mud", "3": "avoid"}


@pytest.mark.parametrize("key, driver", [("summary", "planner"), ("driver_summary", "driver")])
def test_summary_counts_the_runs(evaluated, key: str, driver: str):
    summary = evaluated.metrics[key]
    runs = list(evaluated.metrics["scenarios"][COURSE][driver].values())
    zones = [z for r in runs for z in r["zones"]]
    assert summary["runs"] == 2 and summary["zones"] == len(zones) == 6
    assert summary["zone_success_rate"] == pytest.approx(sum(z["success"] for z in zones) / len(zones), abs=1e-4)
    assert summary["collision_count"] == sum(r["collisions"] for r in runs)
    assert summary["completed_rate"] == pytest.approx(sum(r["completed"] for r in runs) / len(runs))


def test_the_speed_against_the_driver_names_the_background_by_its_class(evaluated):
    """The zones both passed by count for the background, named as SPEC 18 keys classes (not `avoid`;
    the keying itself: tests/rules/test_speed_rule.py)."""
    speed = evaluated.metrics["speed"]
    assert speed["background"] == "grass" and set(speed["by_class"]) <= set(default_classes().names)


def test_figures_are_written(evaluated):
    for name in (f"{STEM}.png", f"{STEM}_frame00005.png"):
        data = (evaluated.out / name).read_bytes()
        assert data.startswith(PNG) and len(data) > 1000, name
    assert sorted(p.name for p in evaluated.out.glob("*.png")) == [f"{STEM}.png", f"{STEM}_frame00005.png"]


@pytest.mark.slow  # a whole drive or export end to end, its steps tested apart in the default run
def test_a_model_with_a_speed_rule_gets_a_figure_of_speed_along_each_path(tmp_path: Path):
    """The skip-path model with a speed rule: its runs' speed along the short course, driver and planner (seed 0)."""
    from terrapref.rules.speed.model import SpeedModel
    from terrapref.rules.speed.rule import SpeedConfig, SpeedRule

    speeds = SpeedModel((0.5, 0.5, 0.8, 0.9, 1.6), 1.5, None, None, None, (0,))
    classifier = ClassifierConfig(hidden=8, skip=True)
    meta = {**model_meta(), "rules": [SpeedRule(SpeedConfig(), speeds).header()], "drives": "argmax"}
    model = save_model(tmp_path / "speed.safetensors", classifier, skip_path_weights(classifier), meta)
    evaluate_model(Evaluation(str(model), (COURSE,), seeds=1), tmp_path / "ev", engine=Engine(workers=1))
    figure = (tmp_path / "ev" / f"{STEM}_speed.png").read_bytes()
    assert figure.startswith(PNG) and len(figure) > 1000


def test_evaluation_is_deterministic(model_path: Path, evaluated, tmp_path: Path):
    again = evaluate_model(Evaluation(str(model_path), (COURSE,), seeds=2, with_driver=False), tmp_path, engine=Engine(workers=1))

    def without_agreement(runs: dict) -> dict:  # the driver's run adds its choices to the planner's zones
        return {
            seed: {**run, "zones": [{k: v for k, v in z.items() if k not in ("driver_choice", "agrees")} for z in run["zones"]]}
            for seed, run in runs.items()
        }

    assert again["scenarios"][COURSE]["planner"] == without_agreement(evaluated.metrics["scenarios"][COURSE]["planner"])
    summary = {k: v for k, v in evaluated.metrics["summary"].items() if not k.startswith("agreement")}
    assert again["summary"] == summary


def test_without_the_driver(model_path: Path, tmp_path: Path):
    metrics = evaluate_model(Evaluation(str(model_path), (COURSE,), seeds=1, with_driver=False), tmp_path, engine=Engine(workers=1))
    assert list(metrics["scenarios"][COURSE]) == ["planner"]
    assert "driver_summary" not in metrics
    assert json.loads((tmp_path / "metrics.json").read_text()) == json.loads(json.dumps(metrics))
    assert (tmp_path / f"{STEM}.png").is_file() and not list(tmp_path.glob("*_frame*.png"))


def test_profile_changes_how_best_resolves(model_path: Path, tmp_path: Path):
    profile = PreferenceProfile.parse(ROCK_FIRST)
    metrics = evaluate_model(
        Evaluation(str(model_path), (COURSE,), seeds=1, profile=profile, with_driver=False), tmp_path, engine=Engine(workers=1)
    )
    assert metrics["profile"] == ROCK_FIRST.split(",")
    zones = {z["id"]: z for z in metrics["scenarios"][COURSE]["planner"]["0"]["zones"]}
    assert zones["2"]["expect"] == "rock"
    assert zones["1"]["expect"] == zones["3"]["expect"] == "avoid"  # expect: avoid does not depend on the profile


# --- terrapref evaluate ----------------------------------------------------------------------------------


def test_cli_evaluate_with_a_profile(model_path: Path, tmp_path: Path, capsys):
    out = tmp_path / "ev"
    rc = main(
        [
            "evaluate",
            str(model_path),
            COURSE,
            "--seeds",
            "1",
            "--out",
            str(out),
            "--no-driver",
            "--workers",
            "1",
            "--profile",
            ROCK_FIRST,
        ]
    )
    captured = capsys.readouterr()
    assert rc == 0, captured.err
    metrics = json.loads((out / "metrics.json").read_text())
    assert {z["id"]: z["expect"] for z in metrics["scenarios"][COURSE]["planner"]["0"]["zones"]} == {
        "1": "avoid",
        "2": "rock",
        "3": "avoid",
    }
    assert "driver" not in metrics["scenarios"][COURSE]
    assert "planner: zone success" in captured.out and str(out / "metrics.json") in captured.out
    # Once the runs are done it says what it does next (the figures take a few seconds a course), after the bar.
    said = captured.err.strip().splitlines()
    assert re.fullmatch(r"evaluate: 1 run done; scoring and drawing the figures of 1 course \.\.\. \(\d+\.\d s\)", said[-1])
    assert "100% 1/1 runs" in said[-2]


def test_cli_evaluate_missing_model(tmp_path: Path, capsys):
    missing = tmp_path / "absent.safetensors"
    rc = main(["evaluate", str(missing), "demo_course", "--seeds", "1", "--out", str(tmp_path / "ev"), "--workers", "1"])
    assert rc == 2
    one_line_error(capsys, str(missing))
    assert not (tmp_path / "ev").exists()


def test_cli_evaluate_unknown_scenario(model_path: Path, tmp_path: Path, capsys):
    rc = main(["evaluate", str(model_path), "no_such_course", "--seeds", "1", "--out", str(tmp_path / "ev"), "--workers", "1"])
    assert rc == 2
    one_line_error(capsys, "no_such_course")
    assert not (tmp_path / "ev").exists()


def test_cli_evaluate_refuses_a_scenario_that_starts_on_lethal_terrain(model_path: Path, tmp_path: Path, capsys):
    course = tmp_path / "in_the_trees.yaml"
    course.write_text(
        "format: terrapref-scenario/1\nname: in_the_trees\nworld: {size_m: [20.0, 10.0], resolution_m: 0.05, background: grass}\n"
        "terrain: [{class: non_traversable, circle: {center: [2.0, 5.0], radius: 1.0}}]\npath: {waypoints: [[2.0, 5.0], [18.0, 5.0]]}\n"
    )
    rc = main(["evaluate", str(model_path), str(course), "--seeds", "1", "--out", str(tmp_path / "ev"), "--workers", "1"])
    assert rc == 2  # not a run that stands still and is charged a collision
    one_line_error(capsys, str(course), "start:", "lethal terrain")
    assert not (tmp_path / "ev").exists()


def test_cli_evaluate_refuses_a_model_of_nan_weights_before_any_run(tmp_path: Path, capsys):
    header = {"format": MODEL_FORMAT, "kind": "linear", **model_meta()}
    model = write_tensor_file(tmp_path / "nan.safetensors", {"w": np.full(5, np.nan, np.float32), "b": np.zeros(21, np.float32)}, header)
    rc = main(["evaluate", str(model), "demo_course", "--seeds", "1", "--out", str(tmp_path / "ev"), "--workers", "1"])
    assert rc == 2  # not runs of a planner that stands still, reported as blind
    one_line_error(capsys, str(model), "weights.w", "NaN")
    assert not (tmp_path / "ev").exists()


def test_cli_evaluate_bad_profile(model_path: Path, tmp_path: Path, capsys):
    rc = main(["evaluate", str(model_path), "demo_course", "--seeds", "1", "--out", str(tmp_path / "ev"), "--profile", "rock,mud"])
    assert rc == 2
    one_line_error(capsys, "--profile")


@pytest.mark.parametrize("speeds", ["nosuch=1", "grass=3", "grass", "grass=0", "grass=0.05", "non_traversable=0.4"])
def test_cli_evaluate_bad_driver_speeds_are_refused_before_any_run(model_path: Path, tmp_path: Path, capsys, speeds: str):
    rc = main(["evaluate", str(model_path), "demo_course", "--seeds", "1", "--out", str(tmp_path / "ev"), "--speeds", speeds])
    assert rc == 2
    one_line_error(capsys, "--speeds")
    assert not (tmp_path / "ev").exists()


def _model_of_driver(tmp_path: Path, monkeypatch, driver: dict) -> tuple[Path, list[Evaluation]]:
    """A model whose one recording was driven by ``driver`` (an ExpertInfo's dict), and the list
    each evaluation of it lands in: evaluate_model is replaced by one that records the evaluation
    (the driver is all these tests ask about) and drives no run."""
    config = ClassifierConfig(hidden=8, skip=True)
    meta = {**model_meta(), "data": {"fingerprint": "0" * 16, "samples": 1, "recordings": [{"path": "rec0", "driver": driver}]}}
    model = save_model(tmp_path / "m.safetensors", config, skip_path_weights(config), meta)
    compared: list[Evaluation] = []

    def read_driver(evaluation: Evaluation, *args, **kwargs) -> dict:  # the driver is all this test asks about: no runs
        compared.append(evaluation)
        raise UserError("runs", "not driven here")

    monkeypatch.setattr("terrapref.evaluation.evaluate.evaluate_model", read_driver)
    return model, compared


def test_cli_evaluate_speeds_change_only_the_classes_they_name_of_the_models_driver(tmp_path: Path, capsys, monkeypatch):
    speeds = (("grass", 1.6), ("mud", 0.5), ("water", 0.3))
    driver = ExpertInfo.of(0, "wide", ExpertConfig(speeds=speeds)).to_dict()
    model, compared = _model_of_driver(tmp_path, monkeypatch, driver)
    for flags, style, expected in [
        (["--speeds", "grass=1.2"], "wide", {"grass": 1.2, "mud": 0.5, "water": 0.3}),
        ([], "wide", dict(speeds)),
        (["--style", "default", "--speeds", "grass=1.2"], "default", {"grass": 1.2}),  # another style: the speeds given alone
    ]:
        assert main(["evaluate", str(model), "demo_course", "--seeds", "1", "--out", str(tmp_path / "ev"), *flags]) == 2
        assert (compared[-1].style, dict(compared[-1].speeds)) == (style, expected), flags


def test_cli_evaluate_compares_with_a_style_files_driver_given_or_trained(tmp_path: Path, capsys, monkeypatch):
    """A style file given to --style, or the one the model's recordings were driven with (its
    name recorded, the file perhaps gone), is the comparison driver: its preset, speeds and fields."""
    style = tmp_path / "mine.yaml"
    style.write_text("format: terrapref-driver-style/1\nbase: wide\nspeeds: {grass: 1.6, mud: 0.5}\nlateral_accel_mps2: 0.8\n")
    driver = ExpertInfo.of(0, "gone.yaml", ExpertConfig(speeds=(("grass", 1.2),), lateral_accel_mps2=0.7, preview_m=2.0)).to_dict()
    model, compared = _model_of_driver(tmp_path, monkeypatch, driver)
    for flags, expected in [
        (["--style", str(style), "--speeds", "mud=0.4"], ("wide", {"grass": 1.6, "mud": 0.4}, 0.8, 4.0)),
        ([], ("default", {"grass": 1.2}, 0.7, 2.0)),
    ]:
        assert main(["evaluate", str(model), "demo_course", "--seeds", "1", "--out", str(tmp_path / "ev"), *flags]) == 2
        one_line_error(capsys, "not driven here")
        ev = compared[-1]
        spec = ev.specs(PreferenceProfile.parse(ROCK_FIRST.split(","), default_classes()))[-1]
        driven = ExpertConfig.styled(spec.style, None, spec.speeds, spec.driver_changes)
        assert (ev.style, dict(ev.speeds), driven.lateral_accel_mps2, driven.preview_m) == expected, flags


def test_cli_evaluate_zero_seeds_is_a_user_error(model_path: Path, tmp_path: Path, capsys):
    rc = main(["evaluate", str(model_path), "demo_course", "--seeds", "0", "--out", str(tmp_path / "ev"), "--workers", "1"])
    assert rc == 2
    one_line_error(capsys, "--seeds")


def test_cli_evaluate_refuses_an_absurd_number_of_seeds_before_any_run(model_path: Path, tmp_path: Path, capsys):
    out = tmp_path / "ev"
    rc = main(["evaluate", str(model_path), "demo_course", "--seeds", "10000000", "--out", str(out), "--workers", "1"])
    assert rc == 2
    assert "20,000,000 runs" in one_line_error(capsys, "--seeds")
    assert not out.exists()


def test_cli_evaluate_bad_frames_is_a_user_error(model_path: Path, tmp_path: Path, capsys):
    rc = main(
        ["evaluate", str(model_path), "demo_course", "--seeds", "1", "--out", str(tmp_path / "ev"), "--frames", "5,x", "--workers", "1"]
    )
    assert rc == 2
    one_line_error(capsys, "--frames")


# --- terrapref train --------------------------------------------------------------------------------------


def test_user_error_survives_the_trip_between_processes():
    import pickle

    from terrapref.errors import Problem, ScenarioError, UserError

    for err in (
        UserError("model.safetensors", "not a model", field="format"),
        ScenarioError("s.yaml", [Problem("terrain[0].circle.radius", "must be > 0"), Problem("path", "too short")]),
    ):
        back = pickle.loads(pickle.dumps(err))
        assert type(back) is type(err) and back.lines() == err.lines() and str(back) == str(err)


def test_a_bad_model_in_a_worker_is_a_user_error_not_a_broken_pool(tmp_path: Path):
    from terrapref.errors import UserError
    from terrapref.evaluation.runner import PLANNER, RunSpec, run_many

    bad = tmp_path / "model.safetensors"
    bad.write_bytes(b"not a model at all")
    specs = [RunSpec("demo_course", seed, PLANNER, str(bad), ("mud", "rock", "water", "non_traversable")) for seed in (0, 1)]
    with pytest.raises(UserError) as info:
        run_many(specs, workers=2)
    assert str(bad) in str(info.value)


@pytest.mark.parametrize(
    "scenario, stem",
    [
        ("demo_course", "demo_course"),
        ("gen:7", "gen_7"),
        ("courses/my.yaml", "courses_my"),
        ("/abs/path/x.yml", "abs_path_x"),
        ("C:\\runs\\a b.yaml", "C_runs_a_b"),
    ],
)
def test_figures_are_named_for_any_file_system(scenario: str, stem: str):
    assert file_stem(scenario) == stem


def test_speed_by_class_seconds_there_and_lateral_acceleration_are_closed_form():
    """A hand-made log at 30 Hz: 10 m straight at 1.5 m/s across a mud strip (x 4-6 m), then a
    quarter circle of radius 2 m at 1 m/s: mean speeds, seconds per class, a zone's speed and
    v^2 / r = 0.5 m/s^2."""
    from terrapref.evaluation.scoring import score_run
    from terrapref.scenario import parse_scenario
    from terrapref.sim.loop import EpisodeLog
    from terrapref.world import rasterise

    scenario = parse_scenario(
        {
            "format": "terrapref-scenario/1",
            "name": "speeds",
            "world": {"size_m": [20.0, 20.0], "resolution_m": 0.05, "background": "grass"},
            "terrain": [{"class": "mud", "rectangle": {"center": [5.0, 5.0], "size": [2.0, 4.0]}}],
            "path": {"waypoints": [[0.0, 5.0], [10.0, 5.0], [12.0, 7.0]]},
            "zones": [{"id": "mud", "expect": "mud", "rectangle": {"center": [5.0, 5.0], "size": [2.0, 4.0]}}],
        }
    )
    dt = 1.0 / 30.0
    x = np.arange(0.0, 10.0 + 1e-9, 1.5 * dt)
    straight = np.stack([x, np.full_like(x, 5.0), np.zeros_like(x)], axis=1)
    a = np.arange(1, round((math.pi / 2) / (dt / 2.0)) + 1) * (dt / 2.0)  # 1 m/s on a 2 m circle: w = 0.5 rad/s
    arc = np.stack([straight[-1, 0] + 2.0 * np.sin(a), 7.0 - 2.0 * np.cos(a), a], axis=1)
    trace = np.vstack([straight, arc])
    log = EpisodeLog("speeds", trace, np.zeros((0, 2)), True, 0, (len(trace) - 1) * dt)
    m = score_run(log, scenario, rasterise(scenario), PreferenceProfile.default())
    assert m.speed_by_class_mps["mud"]["mps"] == pytest.approx(1.5, abs=1e-3)
    assert m.speed_by_class_mps["mud"]["s"] == pytest.approx(2.0 / 1.5, abs=dt)
    grass = m.speed_by_class_mps["grass"]
    assert grass["s"] == pytest.approx(8.0 / 1.5 + math.pi, abs=2 * dt)  # the rest of the straight, then the quarter circle
    assert grass["mps"] == pytest.approx((8.0 + math.pi) / grass["s"], abs=2e-3)
    assert m.max_lateral_accel_mps2 == pytest.approx(0.5, abs=1e-3)
    (zone,) = m.zones
    assert zone.speed_mps == pytest.approx(1.5, abs=1e-3) and "speed_mps" in zone.to_dict()
    assert {"speed_by_class_mps", "max_lateral_accel_mps2"} <= set(m.to_dict()) and m.time_s == pytest.approx(log.duration_s)
