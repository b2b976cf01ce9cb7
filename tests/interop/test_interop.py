"""Models out (ONNX), label maps in, and the runtime a robot's node wraps."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnxruntime as ort
import pytest

from helpers import linear_model, model_meta, one_line_error
from terrapref.camera import CameraConfig
from terrapref.cli import main
from terrapref.errors import UserError
from terrapref.interop.labels import load_label_map, packaged_label_maps
from terrapref.interop.onnx_export import export_onnx, read_onnx_metadata
from terrapref.learning import ClassifierConfig, load_model, numpy_forward, save_model
from terrapref.learning.mlp import init_weights
from terrapref.learning.network import member_prefix
from terrapref.planner.planner import Planner
from terrapref.rules import rules_in, speed_rule
from terrapref.runtime import STOP, PlannerRuntime, RobotSettings
from terrapref.scenario import resolve_scenario
from terrapref.sim import Simulation
from terrapref.terrain import default_classes
from terrapref.vehicle import Command, VehicleConfig

CONFIGS = [
    ClassifierConfig(),  # the paper's C
    ClassifierConfig(skip=True, members=3),  # recipe teach: residual path, an ensemble of 3
    ClassifierConfig(activation="tanh", skip=True, depth=2),
    ClassifierConfig(compress=False, activation="elu", ignore=(1,)),
]


UNSMOOTHED = RobotSettings(
    limits=VehicleConfig(max_accel_mps2=None)
)  # a base that ramps its speed itself: the command sent is the decision's


def speed_block(v_mps: float) -> dict:
    """A speed rule's block in a model file: every terrain column and the background at ``v_mps`` [m/s]."""
    return {"type": "speed", "half_width_m": 0.6, "max_speed_mps": 2.0, "speeds_mps": [v_mps] * 5, "preview_m": 1.0, "lethal": []}


def _model(path: Path, config: ClassifierConfig, seed: int = 0, utility: bool = False, speed_mps: float | None = None) -> Path:
    rng = np.random.default_rng(seed)
    if config.members == 1:
        weights = init_weights(config, rng)
    else:
        weights = {member_prefix(j) + k: v for j in range(config.members) for k, v in init_weights(config, rng).items()}
    meta = model_meta()
    if utility:
        meta["rules"] = [{"type": "second_stage", "weight": 5.0, "w": [-1.0, -2.0, -3.0, -9.0, 4.0], "b": [0.0] * 21, "fit": "frames"}]
        meta["drives"] = "second_stage"
    if speed_mps is not None:
        meta["rules"] = [*meta.get("rules", []), speed_block(speed_mps)]
    return save_model(path, config, weights, meta)


# --- ONNX ------------------------------------------------------------------------------------


def test_an_onnx_export_given_where_a_model_file_is_wanted_is_named_as_one(tmp_path: Path, capsys):
    onnx = export_onnx(load_model(_model(tmp_path / "m.safetensors", CONFIGS[0])), tmp_path / "m.onnx")
    for argv in (["export", str(onnx), "--format", "onnx", "--out", str(tmp_path / "again.onnx")], ["info", str(onnx)]):
        code = main(argv)
        if argv[0] == "info":  # info reads an ONNX file as what it is
            assert code == 0 and "C exported as ONNX" in capsys.readouterr().out
            continue
        assert code == 2
        one_line_error(capsys, "m.onnx", "an ONNX file (as `terrapref export` writes); give the .safetensors file it was exported from")
    assert not (tmp_path / "again.onnx").exists()


@pytest.mark.parametrize("config", CONFIGS, ids=["paper", "teach", "tanh-skip", "flat-elu-ignore"])
def test_onnxruntime_gives_numpy_forwards_logits(tmp_path: Path, config: ClassifierConfig):
    model = load_model(_model(tmp_path / "m.safetensors", config))
    out = export_onnx(model, tmp_path / "m.onnx")
    session = ort.InferenceSession(str(out), providers=["CPUExecutionProvider"])
    assert [(i.name, i.shape) for i in session.get_inputs()] == [("utilities", ["N", 21, 5])]
    assert [(o.name, o.shape) for o in session.get_outputs()] == [("logits", ["N", 21])]
    U = np.random.default_rng(1).uniform(0.0, 1.0, (256, 21, 5)).astype(np.float32)
    logits = session.run(["logits"], {"utilities": U})[0]
    assert logits.dtype == np.float32 and logits.shape == (256, 21)
    np.testing.assert_allclose(logits, numpy_forward(model.classifier, model.weights, U.astype(np.float64)), atol=1e-5, rtol=0)
    single = session.run(["logits"], {"utilities": U[:1]})[0]
    np.testing.assert_allclose(single[0], logits[0], atol=1e-6)


def test_onnx_parity_holds_for_the_tiny_probabilities_of_a_trained_ensemble(tmp_path: Path):
    """A trained model's rare trajectories have logits near log(1e-30) = -69, where float32
    arithmetic alone would be off by 1e-5; the graph computes in float64."""
    config = CONFIGS[1]
    path = _model(tmp_path / "m.safetensors", config)
    model = load_model(path)
    sharp = {k: (v * 600.0 if k.endswith(f"layers.{config.depth}.weight") else v) for k, v in model.weights.items()}
    model = load_model(save_model(tmp_path / "sharp.safetensors", config, sharp, model_meta()))
    session = ort.InferenceSession(str(export_onnx(model, tmp_path / "m.onnx")), providers=["CPUExecutionProvider"])
    U = np.random.default_rng(2).uniform(0.0, 1.0, (512, 21, 5)).astype(np.float32)
    expected = numpy_forward(model.classifier, model.weights, U.astype(np.float64))
    assert expected.min() < -60.0  # rare trajectories, as in trained models
    np.testing.assert_allclose(session.run(["logits"], {"utilities": U})[0], expected, atol=1e-5, rtol=0)


def test_onnx_metadata_carries_the_configuration(tmp_path: Path):
    model = load_model(_model(tmp_path / "m.safetensors", CONFIGS[1], utility=True))
    meta = read_onnx_metadata(export_onnx(model, tmp_path / "m.onnx"))
    assert meta["format"] == "terrapref-onnx/1"
    assert meta["camera"] == model.camera.to_dict() and meta["features"] == model.features.to_dict()
    assert meta["classes"] == model.classes.to_dict() and meta["profile"] == list(model.profile)
    assert meta["classifier"] == model.classifier.to_dict()
    assert meta["preference_set"]["w_rps"] == list(model.features.preference.control.w_rps) and len(meta["preference_set"]["w_rps"]) == 21
    (stage,) = meta["rules"]
    assert stage["type"] == "second_stage" and stage["weight"] == 5.0 and stage["w"] == [-1.0, -2.0, -3.0, -9.0, 4.0]
    assert meta["drives"] == "second_stage"


def test_onnx_metadata_says_the_speed_runs_in_the_planner_and_reads_back_the_speed_rule(tmp_path: Path):
    model = load_model(_model(tmp_path / "m.safetensors", CONFIGS[1], utility=True, speed_mps=1.5))
    meta = read_onnx_metadata(export_onnx(model, tmp_path / "m.onnx"))
    assert [r["type"] for r in meta["rules"]] == ["second_stage", "speed"] and meta["drives"] == "second_stage"
    speed = meta["speed"]
    assert speed["rule"] == 1 and speed["type"] == "speed" and speed["decided_in"] == "planner"
    assert "runs in terrapref's planner" in speed["note"] and "not in this graph" in speed["note"]
    rules, driving = rules_in(meta, "m.onnx")  # as a runtime reading the exported metadata finds them
    assert driving.type == "second_stage"
    assert speed_rule(rules).model.speeds_mps == (1.5,) * 5
    plain = read_onnx_metadata(export_onnx(load_model(_model(tmp_path / "p.safetensors", CONFIGS[0])), tmp_path / "p.onnx"))
    assert plain["speed"]["rule"] is None and "the control set's speed, 1 m/s" in plain["speed"]["note"]


def test_an_onnx_export_of_a_file_that_names_no_driving_rule_names_the_one_that_steers(tmp_path: Path):
    """A speed rule listed last drives no way: the export names the last rule that steers."""
    path = _model(tmp_path / "m.safetensors", CONFIGS[1], utility=True, speed_mps=1.5)
    model = load_model(path)
    meta = dict(model.meta)
    del meta["drives"]
    model = load_model(save_model(tmp_path / "undriven.safetensors", model.classifier, model.weights, meta))
    exported = read_onnx_metadata(export_onnx(model, tmp_path / "m.onnx"))
    assert exported["drives"] == "second_stage"
    assert rules_in(exported, "m.onnx")[1].type == "second_stage"


def test_cli_export_onnx(tmp_path: Path, capsys):
    src = _model(tmp_path / "m.safetensors", CONFIGS[0])
    assert main(["export", str(src), "--format", "onnx", "--out", str(tmp_path / "out" / "m.onnx")]) == 0
    assert "wrote" in capsys.readouterr().out and (tmp_path / "out" / "m.onnx").is_file()
    assert not list((tmp_path / "out").glob(".*tmp"))  # no temporary file left behind
    assert main(["export", str(src), "--format", "onnx", "--out", str(src)]) == 2
    assert "is also an input" in capsys.readouterr().err
    (tmp_path / "junk.safetensors").write_bytes(b"not a model")
    assert main(["export", str(tmp_path / "junk.safetensors"), "--format", "onnx", "--out", str(tmp_path / "j.onnx")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "junk.safetensors" in err[0] and not (tmp_path / "j.onnx").exists()


# --- label maps ------------------------------------------------------------------------------


def test_rellis3d_maps_as_the_spec_says():
    classes = default_classes()
    assert "rellis3d" in packaged_label_maps()
    lut = load_label_map("rellis3d", classes).lut(classes)
    spec = {
        "water": [6, 31],
        "rock": [34],
        "mud": [33],
        "non_traversable": [4, 5, 8, 9, 12, 15, 17, 18, 19, 27],
        "grass": [1, 3, 10, 23],
    }
    for name, ids in spec.items():
        assert (lut[ids] == classes.id_of(name)).all(), name
    assert (lut[[0, 7]] == 255).all()  # void and sky: unknown
    assert lut[2] == 255 and lut[1000] == 255  # ids the map does not list


@pytest.mark.parametrize(
    "text,field",
    [
        ("format: terrapref-labels/1\nids: {3: grass}\ncolours: {}\n", "colours"),
        ("format: terrapref-labels/1\nids: {3: gravel}\n", "ids"),
        ("format: terrapref-labels/1\nids: {-1: grass}\n", "ids.-1"),
        ("format: terrapref-labels/1\nids: {70000: grass}\n", "ids.70000"),
        ("format: terrapref-labels/1\nids: []\n", "ids"),
        ("format: terrapref-labels/2\nids: {3: grass}\n", "format"),
        ("ids: {3: grass}\n", "format"),
        ("format: terrapref-labels/1\nids: {3: grass}\ncolors: {3: [0, 300, 0]}\n", "colors.3"),
        ("format: terrapref-labels/1\nids: {3: grass, 4: mud}\ncolors: {3: [1, 2, 3], 4: [1, 2, 3]}\n", "colors.4"),
    ],
)
def test_a_bad_label_map_is_one_line_naming_file_and_field(tmp_path: Path, text: str, field: str):
    path = tmp_path / "labels.yaml"
    path.write_text(text)
    with pytest.raises(UserError) as info:
        load_label_map(path, default_classes())
    lines = info.value.lines()
    assert len(lines) == 1 and str(path) in lines[0] and f"{field}:" in lines[0]


def test_a_user_label_map(tmp_path: Path):
    path = tmp_path / "mine.yaml"
    path.write_text("format: terrapref-labels/1\nname: mine\nids:\n  0: unknown\n  7: mud\n  300: rock\n")
    labels = load_label_map(path, default_classes())
    assert labels.name == "mine" and labels.lut(default_classes())[[7, 300, 0, 5]].tolist() == [4, 3, 255, 255]
    with pytest.raises(UserError, match="neither a packaged label map"):
        load_label_map("no_such_map")


# --- the runtime -----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def linear_model_file(tmp_path_factory) -> Path:
    return linear_model(tmp_path_factory.mktemp("runtime") / "linear.safetensors")


def test_runtime_drives_as_the_planner_decides(linear_model_file: Path):
    scenario = resolve_scenario("demo_course")
    sim = Simulation(scenario)
    runtime = PlannerRuntime(linear_model_file, robot=UNSMOOTHED)
    runtime.set_path(scenario.waypoints)
    planner = Planner(load_model(linear_model_file))
    planner.set_path(scenario.waypoints)
    frame = sim.reset()
    indices = set()
    for _ in range(400):
        decision = runtime.decide(frame.image, frame.time_s, frame.pose)
        expected = planner.decide(frame.image, frame.pose)
        assert decision.index == expected.index and decision.command == expected.command
        np.testing.assert_array_equal(decision.probs, expected.probs)
        assert runtime.command_at(frame.time_s + 0.1) == decision.command
        indices.add(decision.index)
        frame = sim.step(runtime.command_at(frame.time_s + 0.1))
    assert len(indices) > 1  # it steered


def test_runtime_commands_the_speed_rules_speed_along_the_way_chosen(tmp_path: Path, linear_model_file: Path):
    """A model whose speed rule cruises at 1.5 m/s commands 1.5 m/s on open ground, at the chosen
    way's curvature; without a speed rule the control set's 1 m/s."""
    linear = load_model(linear_model_file)
    meta = {**linear.meta, "rules": [speed_block(1.5)]}
    fast = save_model(tmp_path / "fast.safetensors", linear.classifier, linear.weights, meta)
    scenario = resolve_scenario("demo_course")
    image = Simulation(scenario).reset().image
    w_grid = np.asarray(linear.features.preference.control.w_rps)
    for model, v in ((fast, 1.5), (linear_model_file, 1.0)):
        runtime = PlannerRuntime(model, robot=UNSMOOTHED)
        runtime.set_path(scenario.waypoints)
        d = runtime.decide(image, 10.0, scenario.start)
        assert d.stop is None and d.command.v == pytest.approx(v)
        assert d.command.w == pytest.approx(w_grid[d.index] * v)  # the chosen trajectory's curvature (at 1 m/s), at v
        assert runtime.command_at(10.1) == d.command


def test_runtime_holds_then_stops(linear_model_file: Path):
    runtime = PlannerRuntime(linear_model_file, robot=RobotSettings(hold_s=0.3))
    scenario = resolve_scenario("demo_course")
    runtime.set_path(scenario.waypoints)
    assert runtime.command_at(0.0) == STOP  # nothing decided yet
    image = Simulation(scenario).reset().image
    d = runtime.decide(image, 10.0, scenario.start)
    assert d.command != STOP
    assert runtime.command_at(10.2) == d.command and runtime.command_at(10.29) == d.command
    assert runtime.command_at(10.31) == STOP  # the camera went quiet: stop
    assert runtime.decide(image, 9.9, scenario.start) is None  # out of order: ignored
    assert runtime.last is d
    assert runtime.command_at(float("nan")) == STOP


def test_runtime_refuses_what_it_cannot_drive_on(linear_model_file: Path):
    runtime = PlannerRuntime(linear_model_file)
    with pytest.raises(RuntimeError, match="set_path"):
        runtime.decide(np.zeros((480, 640), np.uint8), 0.0, (0.0, 0.0, 0.0))
    runtime.set_path(np.array([[0.0, 0.0], [10.0, 0.0]]))
    with pytest.raises(ValueError, match="shape"):
        runtime.decide(np.zeros((240, 320), np.uint8), 0.0, (0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="dtype"):
        runtime.decide(np.zeros((480, 640), np.uint16), 0.0, (0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="finite"):
        runtime.decide(np.zeros((480, 640), np.uint8), 0.0, (0.0, float("nan"), 0.0))
    with pytest.raises(ValueError, match="path"):
        runtime.set_path(np.array([[0.0, 0.0]]))
    with pytest.raises(UserError, match="another camera"):
        PlannerRuntime(linear_model_file, camera=CameraConfig(pitch_deg=20.0))


def test_runtime_maps_a_networks_label_ids(linear_model_file: Path):
    classes = default_classes()
    labels = load_label_map("rellis3d", classes)
    runtime = PlannerRuntime(linear_model_file, labels=labels, robot=UNSMOOTHED)
    plain = PlannerRuntime(linear_model_file)
    scenario = resolve_scenario("demo_course")
    for r in (runtime, plain):
        r.set_path(scenario.waypoints)
    image = Simulation(scenario).reset(scenario.start).image
    # The same scene as RELLIS-3D ids: grass -> 3, mud -> 33, rock -> 34, water -> 6, lethal -> 19, unknown -> 7.
    to_rellis = np.full(256, 7, np.uint16)
    for name, rid in (("grass", 3), ("mud", 33), ("rock", 34), ("water", 6), ("non_traversable", 19)):
        to_rellis[classes.id_of(name)] = rid
    a = runtime.decide(to_rellis[image], 0.0, scenario.start)
    b = plain.decide(image, 0.0, scenario.start)
    assert a.index == b.index and np.array_equal(a.probs, b.probs)
    assert runtime.command_at(0.1) == Command(*b.command)
