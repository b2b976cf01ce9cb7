"""Inputs that once ended in an internal error, a traceback or a hang: each now gives a result or a
clear refusal."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import numpy as np
import pytest
import yaml

from helpers import linear_model, one_line_error
from terrapref.cli import main


def _scenario_with(tmp_path: Path, name: str, **changes) -> Path:
    data = yaml.safe_load(resources.files("terrapref.data").joinpath("scenarios/fig7a_non_traversable_longer.yaml").read_text())
    data.update(changes)
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def test_a_course_with_no_zones_is_evaluated(tmp_path: Path, capsys):
    course = _scenario_with(tmp_path, "no_zones.yaml", zones=[])
    model = linear_model(tmp_path / "m.safetensors")
    assert main(["evaluate", str(model), str(course), "--seeds", "1", "--workers", "1", "--out", str(tmp_path / "ev")]) == 0
    out = capsys.readouterr().out
    assert "planner: zone success - (0 zones)" in out and "driver:  zone success - over 0 zones" in out
    assert (tmp_path / "ev" / "metrics.json").is_file()


@pytest.mark.parametrize(
    "waypoints",
    [[[5.0, 15.0], [5.0, 15.0]], [[5.0, 15.0]], [[5.0, float("nan")], [30.0, 15.0]]],
    ids=["two identical points", "one point", "not finite"],
)
def test_a_path_of_no_length_is_refused_by_the_runtime_before_anything_changes(tmp_path: Path, waypoints):
    from terrapref.interop.runtime import PlannerRuntime
    from terrapref.scenario import resolve_scenario

    runtime = PlannerRuntime(linear_model(tmp_path / "m.safetensors"))
    with pytest.raises(ValueError, match="path"):
        runtime.set_path(np.array(waypoints))
    runtime.set_path(resolve_scenario("fig7a_non_traversable_longer").waypoints)
    with pytest.raises(ValueError, match="two distinct points"):
        runtime.set_path(np.array([[5.0, 15.0], [5.0, 15.0]]))
    assert runtime.planner.path is not None and runtime.planner.path.length_m > 50  # the good path stays


def test_the_node_skips_a_path_of_no_length_and_keeps_the_one_in_force(tmp_path: Path):
    from terrapref.interop.node_core import PlannerNodeCore
    from terrapref.interop.robot import load_robot
    from terrapref.interop.ros_messages import path_message, typestore
    from terrapref.learning.model_file import load_model

    robot = tmp_path / "robot.yaml"
    robot.write_text(
        "format: terrapref-robot/1\ntopics: {segmentation: /seg, camera_info: /info, odometry: /odom, command: /cmd, path: /path}\n"
        "camera: {height_m: 1.0, pitch_deg: 30.0}\nlabels: terrapref\n"
    )
    core = PlannerNodeCore(load_model(linear_model(tmp_path / "m.safetensors")), load_robot(robot))
    ts = typestore()
    said = core.on_path(path_message(ts, [(5.0, 15.0), (5.0, 15.0)]))  # what is wrong, for the node to say
    assert said == "a path of 2 pose(s), fewer than two distinct points; no path yet: nothing is commanded"
    assert core.path is None and core.skipped["paths of fewer than two distinct points"] == 1
    assert core.on_path(path_message(ts, [(5.0, 15.0), (30.0, 15.0)])) is None
    said = core.on_path(path_message(ts, [(7.0, 1.0), (7.0, 1.0), (7.0, 1.0)]))
    assert said == "a path of 3 pose(s), fewer than two distinct points; the path in force stays"
    assert (
        core.on_path(path_message(ts, [(7.0, 1.0), (float("nan"), 1.0)]))
        == "a path with a point that is not a number; the path in force stays"
    )
    assert core.path.tolist() == [[5.0, 15.0], [30.0, 15.0]] and core.skipped["paths of fewer than two distinct points"] == 3


def test_a_path_file_of_no_length_is_refused_naming_it(tmp_path: Path):
    from terrapref.errors import UserError
    from terrapref.interop.robot import load_waypoints

    path = tmp_path / "route.yaml"
    path.write_text("waypoints: [[1.0, 2.0], [1.0, 2.0]]\n")
    with pytest.raises(UserError, match="two distinct finite") as refused:
        load_waypoints(path, "robot.yaml")
    assert refused.value.lines()[0].startswith(f"robot.yaml: path_file: {path}: ")  # the robot file's field
    with pytest.raises(UserError) as refused:  # a node's parameter: the file's own error, named once
        load_waypoints(path, None)
    assert refused.value.lines()[0].startswith(f"{path}: path_file: expected at least two distinct finite")


@pytest.mark.parametrize(
    "command",
    [
        ["evaluate", "{model}", "fig7a_non_traversable_longer", "--seeds", "1", "--out", "{tmp}/ev"],
        ["export", "{model}", "--format", "onnx", "--out", "{tmp}/m.onnx"],
    ],
    ids=["evaluate", "export"],
)
def test_an_image_size_in_a_file_is_bounded_before_anything_is_allocated(tmp_path: Path, capsys, command):
    """A model header asking for a camera 10^9 pixels wide once exhausted the machine's memory."""
    from terrapref.learning.model_file import _write, read_model_file

    weights, meta = read_model_file(linear_model(tmp_path / "m.safetensors"))
    meta["camera"]["width_px"] = 10**9
    model = tmp_path / "big.safetensors"
    _write(model, weights, meta)
    assert main([part.format(model=model, tmp=tmp_path) for part in command]) == 2
    one_line_error(capsys, "big.safetensors", "1..4096 px", "1000000000")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["big.safetensors", "m.safetensors"]


@pytest.mark.parametrize("uri", ["localhost:11311", "http://host:abc", "http://[::1", "ftp://localhost:11311", "http://:11311"])
def test_a_malformed_ros_master_uri_is_refused_at_once(uri):
    from terrapref.errors import UserError
    from terrapref.interop.ros1 import check_master

    with pytest.raises(UserError, match="not a ROS master's URI; expected http://HOST:PORT"):
        check_master(uri)


def test_no_ros_master_is_said_within_seconds_not_waited_for():
    import socket

    from terrapref.errors import UserError
    from terrapref.interop.ros1 import check_master

    with socket.socket() as s:  # a port nothing listens on once it is closed
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(UserError, match=f"no ROS master at http://127.0.0.1:{port}"):
        check_master(f"http://127.0.0.1:{port}", timeout_s=1.0)
    with socket.socket() as listening:  # something answers: a master to rospy
        listening.bind(("127.0.0.1", 0))
        listening.listen()
        check_master(f"http://127.0.0.1:{listening.getsockname()[1]}")


@pytest.mark.parametrize(
    "block,key,value,words",
    [
        ("preference", "n_steps", 10**9, ["n_steps", "1..1000"]),
        ("geometry", "map_resolution_m", 1e-6, ["ground-map cells a side", "at most 4096"]),
        ("geometry", "offset_step_m", 1e-9, ["offsets", "at most 10000"]),
        ("geometry", "station_step_m", 1e-9, ["stations", "at most 10000"]),
        ("geometry", "sample_step_m", 1e-9, ["camera samples", "at most 10000"]),
    ],
    ids=["trajectory points", "map cells", "offsets", "stations", "samples"],
)
def test_every_size_a_model_file_gives_is_bounded(tmp_path: Path, capsys, block, key, value, words):
    """Sizes in a model's header once allocated gigabytes (or failed in a worker) before any check."""
    from test_offset_rule import DRIVER_LIKE, _offset_meta

    from helpers import skip_path_weights
    from terrapref.learning.model_file import _write, read_model_file, save_model
    from terrapref.learning.network import ClassifierConfig

    config = ClassifierConfig(hidden=8, skip=True)
    good = save_model(tmp_path / "good.safetensors", config, skip_path_weights(config), _offset_meta(DRIVER_LIKE))
    weights, meta = read_model_file(good)
    (meta["rules"][0] if block == "geometry" else meta["features"])[block][key] = value  # the offset rule's geometry, or C's preference set
    model = tmp_path / "big.safetensors"
    _write(model, weights, meta)
    assert main(["evaluate", str(model), "fig7a_non_traversable_longer", "--seeds", "1", "--no-driver", "--out", str(tmp_path / "ev")]) == 2
    one_line_error(capsys, "big.safetensors", *words)
    assert not (tmp_path / "ev").exists()


@pytest.mark.parametrize("command", ["ros1", "ros2", "play"])
def test_a_node_started_with_sigint_ignored_takes_ctrl_c_from_its_first_line(monkeypatch, command):
    """A script's background job inherits SIGINT ignored. A node's command (and `play`) took
    SIGINT only once it spun, so Ctrl-C in its first seconds (the model read, the middleware
    started) was lost and it ran on; now it is armed before the command's first line, and put
    back after it. Other commands keep what they inherit."""
    import signal

    from terrapref.cli import build_parser, robot

    seen = {}

    def command_body(args) -> int:
        seen[args.command] = signal.getsignal(signal.SIGINT)
        raise KeyboardInterrupt

    for name in ("_cmd_ros1", "_cmd_ros2", "_cmd_play", "_cmd_route"):
        monkeypatch.setattr(robot, name, command_body)
    argv = {
        "ros1": ["ros1", "--model", "m.safetensors", "--robot", "robot.yaml"],
        "ros2": ["ros2", "--model", "m.safetensors", "--robot", "robot.yaml"],
        "play": ["play", "log.mcap"],
    }[command]
    build_parser.cache_clear()  # built afresh with the stand-ins, and again after them
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        assert main(argv) == 130  # interrupted, not run on
        assert seen[command] is signal.default_int_handler and signal.getsignal(signal.SIGINT) is signal.SIG_IGN
        main(["route", "s.yaml", "--model", "m.safetensors", "--out", "r.yaml"])
        assert seen["route"] is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)
        build_parser.cache_clear()
