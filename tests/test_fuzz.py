"""Property-based fuzzing of every reader: recordings, datasets, model files, scenarios, camera
files, robot files, label maps, perception files and class tables, mutated byte by byte and field by field. Whatever the input, a reader returns a
result or raises a UserError that names the file; nothing else escapes.

The default run uses a fast, derandomised profile (a couple of hundred cases per reader); the
slow tests run each reader on 2,000 random cases.
"""

from __future__ import annotations

import json
import shutil
from importlib import resources
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from helpers import model_meta
from synthetic_bag import robot_yaml, write_robot
from terrapref.camera.files import load_camera
from terrapref.dataset import FORMAT as DATASET_FORMAT
from terrapref.dataset import featurize_recording, load_dataset
from terrapref.demos.recording import RecordingWriter, read_recording
from terrapref.errors import UserError
from terrapref.features import FeatureConfig
from terrapref.interop.labels import load_label_map
from terrapref.interop.robot import load_robot
from terrapref.learning import ClassifierConfig, load_model, save_model
from terrapref.learning.mlp import init_weights
from terrapref.perception import load_perception
from terrapref.scenario import load_scenario, resolve_scenario
from terrapref.sim import Simulation
from terrapref.tensorfile import write_tensor_file
from terrapref.terrain.classes import load_classes
from terrapref.world import rasterise

TINY_COURSE = Path(__file__).parent / "data" / "tiny_course.yaml"
RELIEF = [  # one entry of each kind (SPEC 19), on the tiny course's map
    {"noise": {"amplitude_m": 0.3, "wavelength_m": 4.0, "seed": 3}},
    {"mound": {"center": [6.0, 3.0], "radius": 2.0, "height_m": -0.5}},
    {"ridge": {"polyline": [[2.0, 1.0], [2.0, 5.0], [8.0, 6.0]], "width_m": 1.5, "height_m": 0.4}},
    {"plateau": {"polygon": [[10.0, 1.0], [14.0, 1.0], [14.0, 5.0]], "height_m": 0.8, "edge_m": 2.0}},
]
COMMON = dict(deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
FAST = settings(max_examples=60, derandomize=True, **COMMON)  # the default run; THOROUGH is the slow tests'
THOROUGH = settings(max_examples=2000, **COMMON)

json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**40), 2**40) | st.floats(allow_nan=True, allow_infinity=True) | st.text(max_size=12),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
    max_leaves=10,
)


@st.composite
def mutated_bytes(draw, data: bytes) -> bytes:
    """``data`` with a few bytes flipped, inserted or deleted, or cut short."""
    out = bytearray(data)
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(["flip", "insert", "delete", "truncate"]))
        i = draw(st.integers(0, max(len(out) - 1, 0)))
        if op == "flip" and out:
            out[i] ^= draw(st.integers(1, 255))
        elif op == "insert":
            out[i:i] = draw(st.binary(min_size=1, max_size=8))
        elif op == "delete" and out:
            del out[i : i + draw(st.integers(1, 16))]
        elif op == "truncate":
            del out[i:]
    return bytes(out)


def _reads_or_refuses(read, source: Path) -> None:
    try:
        read()
    except UserError as exc:
        assert exc.lines() and all(str(source) in line or source.name in line for line in exc.lines()), exc.lines()


# --- fixtures: one small valid file of each kind -------------------------------------------------


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> dict:
    root = tmp_path_factory.mktemp("fuzz")
    scenario = resolve_scenario("demo_course")
    sim = Simulation(scenario)
    from terrapref.camera import CameraConfig
    from terrapref.features import PreferenceSetConfig
    from terrapref.terrain import default_classes

    meta = {
        "scenario": scenario.name,
        "camera": CameraConfig().to_dict(),
        "preference_set": PreferenceSetConfig().to_dict(),
        "classes": default_classes().to_dict(),
        "profile": list(default_classes().profile),
        "path": scenario.waypoints.tolist(),
    }
    writer = RecordingWriter(root / "rec", meta, scenario.to_dict())
    frame = sim.reset()
    for _ in range(3):
        writer.append(frame.time_s, frame.pose, frame.image, (1.0, 0.1), 11)
        frame = sim.step((1.0, 0.1))
    writer.close({"completed": False})
    rng = np.random.default_rng(0)
    n = 20
    write_tensor_file(
        root / "data.safetensors",
        {
            "U": rng.uniform(0, 1, (n, 21, 5)).astype(np.float32),
            "labels": rng.integers(0, 21, n),
            "w": np.zeros(n, np.float32),
            "source": np.zeros(n, np.int64),
        },
        {"format": DATASET_FORMAT, **model_meta()},
    )
    save_model(root / "model.safetensors", ClassifierConfig(hidden=4), init_weights(ClassifierConfig(hidden=4), rng), model_meta())
    (root / "scenario.yaml").write_text(yaml.safe_dump(resolve_scenario("fig7_rock_vs_non_traversable_left").to_dict(), sort_keys=False))
    (root / "relief.yaml").write_text(yaml.safe_dump({**load_scenario(TINY_COURSE).to_dict(), "relief": RELIEF}, sort_keys=False))
    write_robot(root / "robot.yaml", robot_yaml())
    (root / "camera.yaml").write_text(
        "image_width: 640\nimage_height: 480\ncamera_matrix: {rows: 3, cols: 3, data: [320.0, 0.0, 320.0, 0.0, 320.0, 240.0, 0.0, 0.0, 1.0]}\n"
        "distortion_model: plumb_bob\ndistortion_coefficients: {rows: 1, cols: 5, data: [0.0, 0.0, 0.0, 0.0, 0.0]}\n"
        "mount_height_m: 1.0\npitch_deg: 30.0\n"
    )
    (root / "labels.yaml").write_text(
        "format: terrapref-labels/1\nname: mine\nids:\n  0: unknown\n  3: grass\n  33: mud\ncolors:\n  3: [0, 102, 0]\n"
    )
    data = resources.files("terrapref.data")
    (root / "perception.yaml").write_text(data.joinpath("perception").joinpath("field.yaml").read_text())
    (root / "classes.yaml").write_text(data.joinpath("classes.yaml").read_text())
    return {"root": root}


def _fresh(base: dict, tmp: Path, name: str) -> Path:
    dst = tmp / name
    if dst.exists():
        shutil.rmtree(dst) if dst.is_dir() else dst.unlink()
    src = base["root"] / name
    shutil.copytree(src, dst) if src.is_dir() else shutil.copy(src, dst)
    return dst


def _finite_relief(path: Path) -> None:
    """Load a scenario and build its world: relief it accepts is a finite height everywhere."""
    world = rasterise(load_scenario(path))
    assert world.height is None or np.isfinite(world.height).all()


def _featurize(path: Path) -> None:
    rec = read_recording(path)
    if len(rec):
        featurize_recording(rec, FeatureConfig())


# --- the properties, each run fast by default and thoroughly as a slow test ------------------------


def recording_bytes(base, tmp_path_factory, which: str):
    tmp = tmp_path_factory.mktemp("rec_bytes")
    original = (base["root"] / "rec" / which).read_bytes()

    @given(st.data())
    def run(data):
        rec = _fresh(base, tmp, "rec")
        (rec / which).write_bytes(data.draw(mutated_bytes(original)))
        _reads_or_refuses(lambda: _featurize(rec), rec)

    return run


def recording_fields(base, tmp_path_factory):
    tmp = tmp_path_factory.mktemp("rec_fields")
    lines = (base["root"] / "rec" / "frames.jsonl").read_text().splitlines()
    meta = json.loads((base["root"] / "rec" / "meta.json").read_text())

    @given(
        st.sampled_from(["frame", "meta"]),
        st.integers(0, 2),
        st.sampled_from(
            ["t", "pose", "cmd", "label", "image", "i", "camera", "classes", "preference_set", "profile", "path", "frames", "status"]
        ),
        json_values,
    )
    def run(where, k, key, value):
        rec = _fresh(base, tmp, "rec")
        if where == "frame":
            row = json.loads(lines[k])
            row[key] = value
            (rec / "frames.jsonl").write_text("\n".join([*lines[:k], json.dumps(row), *lines[k + 1 :]]) + "\n")
        else:
            (rec / "meta.json").write_text(json.dumps({**meta, key: value}))
        _reads_or_refuses(lambda: _featurize(rec), rec)

    return run


def file_bytes(base, tmp_path_factory, name: str, read):
    tmp = tmp_path_factory.mktemp(f"bytes_{name.split('.')[0]}")
    original = (base["root"] / name).read_bytes()

    @given(st.data())
    def run(data):
        path = tmp / name
        path.write_bytes(data.draw(mutated_bytes(original)))
        _reads_or_refuses(lambda: read(path), path)

    return run


def tensor_fields(base, tmp_path_factory, kind: str):
    tmp = tmp_path_factory.mktemp(f"fields_{kind}")
    dtypes = st.sampled_from([np.float32, np.float64, np.float16, np.int64, np.int32, np.uint8, np.bool_])
    shapes = st.lists(st.integers(0, 6), min_size=0, max_size=4).map(tuple)

    @given(st.data())
    def run(data):
        if kind == "dataset":
            from terrapref.tensorfile import read_tensor_file

            tensors, meta = read_tensor_file(base["root"] / "data.safetensors", DATASET_FORMAT, "", "")
        else:
            from terrapref.learning.model_file import read_model_file

            tensors, meta = read_model_file(base["root"] / "model.safetensors")
        name = data.draw(st.sampled_from(sorted(tensors) + ["extra"]))
        if data.draw(st.booleans()):
            shape, dtype = data.draw(shapes), data.draw(dtypes)
            fill = data.draw(st.sampled_from([0.0, 1.0, -3.0, 40.0, float("nan"), float("inf")]))
            if np.dtype(dtype).kind != "f":  # integers and booleans: a value their type can hold
                fill = int(abs(fill)) if np.isfinite(fill) and abs(fill) < 100 else 0
            tensors[name] = np.full(shape, fill, dtype=dtype)
        else:
            key = data.draw(st.sampled_from(sorted(meta) + ["extra"]))
            meta[key] = data.draw(json_values)
        path = tmp / f"{kind}.safetensors"
        write_tensor_file(path, tensors, meta)
        _reads_or_refuses(lambda: load_dataset(path) if kind == "dataset" else load_model(path), path)

    return run


def yaml_fields(base, tmp_path_factory, name: str, read, under: str | None = None, depth: int = 2):
    """Fields of the YAML file ``name`` replaced by random values, a few levels down from the top
    (or from its block ``under``)."""
    tmp = tmp_path_factory.mktemp(f"yaml_{name.split('.')[0]}")
    original = yaml.safe_load((base["root"] / name).read_text())

    @given(st.data())
    def run(data):
        doc = json.loads(json.dumps(original))
        node = doc if under is None else doc[under]
        for _ in range(data.draw(st.integers(0, depth))):  # walk down a little, then replace a value
            if isinstance(node, dict) and node:
                child = node[data.draw(st.sampled_from(sorted(node, key=str)))]
                if isinstance(child, (dict, list)) and child:
                    node = child
            elif isinstance(node, list) and node:
                child = node[data.draw(st.integers(0, len(node) - 1))]
                if isinstance(child, (dict, list)) and child:
                    node = child
        if isinstance(node, dict):
            node[data.draw(st.sampled_from(sorted(node, key=str) + ["extra"]))] = data.draw(json_values)
        elif node:
            node[data.draw(st.integers(0, len(node) - 1))] = data.draw(json_values)
        path = tmp / name
        try:
            path.write_text(yaml.safe_dump(doc, sort_keys=False, allow_unicode=True))
        except (yaml.YAMLError, UnicodeEncodeError):
            return
        _reads_or_refuses(lambda: read(path), path)

    return run


READERS = {
    "recording frames.jsonl bytes": lambda b, f: recording_bytes(b, f, "frames.jsonl"),
    "recording meta.json bytes": lambda b, f: recording_bytes(b, f, "meta.json"),
    "recording scenario.yaml bytes": lambda b, f: recording_bytes(b, f, "scenario.yaml"),
    "recording fields": recording_fields,
    "dataset bytes": lambda b, f: file_bytes(b, f, "data.safetensors", load_dataset),
    "dataset fields": lambda b, f: tensor_fields(b, f, "dataset"),
    "model bytes": lambda b, f: file_bytes(b, f, "model.safetensors", load_model),
    "model fields": lambda b, f: tensor_fields(b, f, "model"),
    "scenario bytes": lambda b, f: file_bytes(b, f, "scenario.yaml", load_scenario),
    "scenario fields": lambda b, f: yaml_fields(b, f, "scenario.yaml", load_scenario),
    "scenario relief fields": lambda b, f: yaml_fields(b, f, "relief.yaml", _finite_relief, under="relief", depth=3),
    "robot file bytes": lambda b, f: file_bytes(b, f, "robot.yaml", load_robot),
    "robot file fields": lambda b, f: yaml_fields(b, f, "robot.yaml", load_robot),
    "camera file bytes": lambda b, f: file_bytes(b, f, "camera.yaml", load_camera),
    "camera file fields": lambda b, f: yaml_fields(b, f, "camera.yaml", load_camera),
    "label map bytes": lambda b, f: file_bytes(b, f, "labels.yaml", load_label_map),
    "label map fields": lambda b, f: yaml_fields(b, f, "labels.yaml", load_label_map),
    "perception file bytes": lambda b, f: file_bytes(b, f, "perception.yaml", load_perception),
    "perception file fields": lambda b, f: yaml_fields(b, f, "perception.yaml", load_perception),
    "class table bytes": lambda b, f: file_bytes(b, f, "classes.yaml", load_classes),
    "class table fields": lambda b, f: yaml_fields(b, f, "classes.yaml", load_classes),
}


@pytest.mark.parametrize("reader", sorted(READERS))
def test_fuzz_fast(reader, base, tmp_path_factory):
    FAST(READERS[reader](base, tmp_path_factory))()


@pytest.mark.slow
@pytest.mark.parametrize("reader", sorted(READERS))
def test_fuzz_thorough(reader, base, tmp_path_factory):
    THOROUGH(READERS[reader](base, tmp_path_factory))()
