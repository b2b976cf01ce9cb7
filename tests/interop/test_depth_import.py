"""Depth images in and out of robot logs (REP 118): a robot file's depth topic, 32FC1 metres or
16UC1 millimetres, imported with each label image into the recording, and exported again; every
depth the import cannot take is one line naming the bag and the field, and writes nothing."""

from __future__ import annotations

import json
import math
import shutil
from dataclasses import dataclass, replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from terrapref.camera import CameraConfig
from terrapref.cli import main
from terrapref.demos.recording import read_recording
from terrapref.errors import UserError
from terrapref.interop.bag_frames import DEPTH_PAIRING_S
from terrapref.interop.ros_decode import depth_metres
from terrapref.interop.ros_messages import (
    OPTICAL_FRAME,
    add_topics,
    camera_info,
    compressed_image,
    epoch_ns,
    header,
    odometry,
    path_message,
    png,
    pose,
    rpy_quaternion,
    twist,
    typestore,
)
from terrapref.pngio import millimetres_to_depth
from terrapref.vehicle.ground import Attitude

H, W = 48, 64  # a small camera: the tests are about the depth, not the picture
CAMERA = CameraConfig(width_px=W, height_px=H)
FRAMES = 12  # 0.1 s apart, at 1 m/s
KNOWN_MM = np.tile(np.array([0, 1, 1234, 30000], np.uint16), (H, W // 4))  # millimetres, 0: no return
TOPIC = {"labels": "/cam/labels", "info": "/cam/info", "odom": "/odom", "cmd": "/cmd", "path": "/plan", "depth": "/cam/depth"}
DEPTH_INFO = "/cam/depth_info"
TILT = Attitude(0.3, 0.1, -0.05)  # the odometry's height [m], pitch and roll [rad]


def _msg(encoding: str, data: np.ndarray, big: bool = False, pad: int = 0) -> SimpleNamespace:
    """A sensor_msgs/Image of ``data`` (H, W) in ``encoding``, each row padded by ``pad`` bytes."""
    raw = data.astype(data.dtype.newbyteorder(">" if big else "<"))
    rows = np.concatenate([raw.view(np.uint8).reshape(data.shape[0], -1), np.zeros((data.shape[0], pad), np.uint8)], axis=1)
    h, w = data.shape
    return SimpleNamespace(encoding=encoding, height=h, width=w, step=rows.shape[1], is_bigendian=int(big), data=rows.reshape(-1))


def _metres_with_no_returns() -> np.ndarray:
    """KNOWN_MM as 32FC1 metres, where it has no return each way REP 118 says none: NaN, +inf, and 0 or below."""
    metres = KNOWN_MM.astype(np.float32) / np.float32(1000.0)
    none = np.flatnonzero(KNOWN_MM.reshape(-1) == 0)
    metres.reshape(-1)[none] = np.resize(np.array([np.nan, np.inf, -1.0, 0.0], np.float32), len(none))
    return metres


def test_16uc1_millimetres_are_metres_and_0_is_no_return():
    expected = np.where(KNOWN_MM > 0, KNOWN_MM / 1000.0, np.nan)
    for big, pad in ((False, 0), (True, 6)):
        got = depth_metres(_msg("16UC1", KNOWN_MM, big, pad), "/d", "log.mcap")
        assert got.dtype == np.float32 and got.shape == (H, W)
        np.testing.assert_allclose(got, expected, rtol=1e-7)  # NaN where the image holds 0
    assert np.isnan(got[0, 0]) and got[0, 1] == np.float32(0.001) and got[0, 2] == np.float32(1.234) and got[0, 3] == 30.0


def test_32fc1_metres_read_as_the_same_depth_and_every_kind_of_no_return_is_nan():
    for big in (False, True):
        got = depth_metres(_msg("32FC1", _metres_with_no_returns(), big), "/d", "log.mcap")
        np.testing.assert_array_equal(got, millimetres_to_depth(KNOWN_MM))


def test_32fc1_depth_in_millimetres_is_refused_saying_so():
    """Millimetres in a 32FC1 image were taken as metres: the ground kilometres away, and the robot
    stopped with no free way, with no hint of the units."""
    millimetres = np.where(KNOWN_MM > 0, KNOWN_MM, 0).astype(np.float32)
    with pytest.raises(
        UserError, match=r"topics.depth: topic /cam/depth: depth of a median \d+ m, millimetres as it seems; 32FC1 is metres"
    ):
        depth_metres(_msg("32FC1", millimetres), "/cam/depth", "log.mcap")


@pytest.mark.parametrize("encoding", ["mono8", "mono16", "rgb8", "64FC1"])
def test_another_depth_encoding_is_refused_naming_the_log_the_topic_and_the_encoding(encoding: str):
    with pytest.raises(UserError) as err:
        depth_metres(_msg(encoding, KNOWN_MM), "/cam/depth", "log.mcap", 1.5)
    (line,) = err.value.lines()
    assert err.value.source == "log.mcap" and err.value.problems[0].field == "topics.depth"
    assert "/cam/depth" in line and repr(encoding) in line and "1.500 s into the log" in line and "32FC1" in line


def test_a_step_shorter_than_a_row_and_data_shorter_than_the_rows_are_each_named():
    short_step = _msg("16UC1", KNOWN_MM)
    short_step.step = KNOWN_MM.shape[1] * 2 - 4  # the data would hold its rows; the step is not a row's
    with pytest.raises(UserError, match=r"depth step of \d+ bytes is shorter than a row of \d+ pixels of 2 bytes"):
        depth_metres(short_step, "/cam/depth", "log.mcap")
    cut = _msg("16UC1", KNOWN_MM)
    cut.data = cut.data[:-1]
    with pytest.raises(UserError, match=r"depth data of \d+ bytes does not hold \d+ rows of \d+"):
        depth_metres(cut, "/cam/depth", "log.mcap")


# --- a small log with a depth topic -----------------------------------------------------------------


@dataclass(frozen=True)
class DepthLog:
    """A log of FRAMES label images (grass), odometry, commands, a path and a depth topic."""

    storage: str = "mcap"  # or rosbag1
    encoding: str = "16UC1"  # or 32FC1 (KNOWN_MM in metres), or any other to be refused
    shape: tuple[int, int] = (H, W)
    offset_s: float = 0.0  # each depth image's stamp minus its label image's [s]
    every: int = 1  # a depth image with every so many label images
    depth_info: CameraConfig | None = None  # a calibration of the depth images' own, on DEPTH_INFO
    empty: bool = False  # every depth image without a return (all 0)


def _robot(folder: Path, depth_info: bool = False) -> Path:
    topics = "".join(f"  {role}: {TOPIC[key]}\n" for role, key in (
        ("segmentation", "labels"), ("camera_info", "info"), ("odometry", "odom"), ("command", "cmd"), ("path", "path"), ("depth", "depth")
    ))  # fmt: skip
    info = f"  depth_info: {DEPTH_INFO}\n" if depth_info else ""
    robot = folder / "robot.yaml"
    robot.write_text(f"format: terrapref-robot/1\ntopics:\n{topics}{info}camera:\n  height_m: 1.0\n  pitch_deg: 30.0\nlabels: terrapref\n")
    return robot


def _depth_message(ts, stamped, log: DepthLog):
    data = KNOWN_MM if log.encoding != "32FC1" else _metres_with_no_returns()
    data = np.resize(data, log.shape) * (not log.empty)
    m = _msg(log.encoding, data)
    return ts.types["sensor_msgs/msg/Image"](
        header=stamped, height=m.height, width=m.width, encoding=m.encoding, is_bigendian=0, step=m.step, data=m.data
    )


def _messages(ts, log: DepthLog, ros1: bool) -> list[tuple[float, str, object]]:
    """(time [s], role, message) of the whole log, in time order."""
    out = [(0.0, "path", path_message(ts, [(1.0, 5.0), (12.0, 5.0)], ros1))]
    for i in range(FRAMES):
        t = 0.1 * i
        at = pose(ts, 1.0 + t, 5.0, rpy_quaternion(ts, TILT.roll_rad, TILT.pitch_rad, 0.0), TILT.z_m)
        optical = header(ts, t, OPTICAL_FRAME, ros1)
        out += [
            (t, "odom", odometry(ts, header(ts, t, "odom", ros1), at)),
            (t, "info", camera_info(ts, optical, CAMERA, ros1)),
            (t, "cmd", twist(ts, 1.0, 0.0)),
            (t, "labels", compressed_image(ts, optical, "mono8; png", png(np.zeros((H, W), np.uint8)))),
        ]
        if i % log.every == 0:
            out.append((t + log.offset_s, "depth", _depth_message(ts, header(ts, t + log.offset_s, OPTICAL_FRAME, ros1), log)))
        if log.depth_info is not None:
            out.append((t, "depth_info", camera_info(ts, optical, log.depth_info, ros1)))
    return sorted(out, key=lambda m: m[0])


def _write_log(path: Path, log: DepthLog) -> Path:
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2

    ros1 = log.storage == "rosbag1"
    ts = typestore(ros1)
    kinds = {
        "labels": "sensor_msgs/msg/CompressedImage",
        "info": "sensor_msgs/msg/CameraInfo",
        "odom": "nav_msgs/msg/Odometry",
        "cmd": "geometry_msgs/msg/Twist",
        "path": "nav_msgs/msg/Path",
        "depth": "sensor_msgs/msg/Image",
        "depth_info": "sensor_msgs/msg/CameraInfo",
    }
    names = {**TOPIC, "depth_info": DEPTH_INFO}
    roles = [role for role in kinds if role != "depth_info" or log.depth_info is not None]
    with Writer1(path) if ros1 else Writer2(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        topics = add_topics(writer, ts, {role: (names[role], kinds[role]) for role in roles}, ros1)
        for t, role, msg in _messages(ts, log, ros1):
            topics.write(role, epoch_ns(t), msg)
    return path


@pytest.mark.parametrize(("storage", "encoding"), [("mcap", "16UC1"), ("rosbag1", "16UC1"), ("mcap", "32FC1")])
def test_an_imported_depth_topic_holds_the_logs_metres_and_the_odometrys_attitude(tmp_path: Path, storage: str, encoding: str):
    bag = _write_log(tmp_path / ("log.bag" if storage == "rosbag1" else "log.mcap"), DepthLog(storage, encoding))
    assert main(["import", str(bag), "--robot", str(_robot(tmp_path)), "--out", str(tmp_path / "rec")]) == 0
    rec = read_recording(tmp_path / "rec")
    assert len(rec) == FRAMES and rec.has_depth
    for i in (0, FRAMES - 1):
        np.testing.assert_array_equal(rec.depth(i), millimetres_to_depth(KNOWN_MM))  # 1.234 m, 30 m, 1 mm; NaN where none
        np.testing.assert_allclose(rec.attitude(i), TILT, atol=1e-12)


def test_a_label_image_takes_the_depth_image_of_the_nearest_stamp_within_50_ms_and_is_skipped_without(tmp_path: Path, capsys):
    robot = _robot(tmp_path)
    near = _write_log(tmp_path / "near.mcap", DepthLog(offset_s=0.02))
    assert main(["import", str(near), "--robot", str(robot), "--out", str(tmp_path / "near")]) == 0
    assert len(read_recording(tmp_path / "near")) == FRAMES
    assert "at most 20 ms apart; 50 ms allowed" in capsys.readouterr().out
    half = _write_log(tmp_path / "half.mcap", DepthLog(every=2))  # the odd frames' nearest depth is 0.1 s off
    assert main(["import", str(half), "--robot", str(robot), "--out", str(tmp_path / "half")]) == 0
    assert f"skipped          {FRAMES // 2} images without a depth image within 50 ms" in capsys.readouterr().out
    rec = read_recording(tmp_path / "half")
    assert len(rec) == FRAMES // 2 and rec.has_depth
    np.testing.assert_allclose(rec.times, 0.2 * np.arange(FRAMES // 2), atol=1e-6)
    assert 0.1 > DEPTH_PAIRING_S


def test_a_depth_topic_without_a_single_return_is_imported_with_a_warning(tmp_path: Path, capsys):
    """A depth topic whose every image holds no return (a wrong encoding or unit, a covered lens)
    is not taken silently for depth: the import's report says so."""
    bag = _write_log(tmp_path / "empty.mcap", DepthLog(empty=True))
    assert main(["import", str(bag), "--robot", str(_robot(tmp_path)), "--out", str(tmp_path / "rec")]) == 0
    assert f"WARNING: {FRAMES} of them hold no return at all" in capsys.readouterr().out
    bag = _write_log(tmp_path / "full.mcap", DepthLog())
    assert main(["import", str(bag), "--robot", str(_robot(tmp_path)), "--out", str(tmp_path / "full")]) == 0
    assert "WARNING" not in capsys.readouterr().out


def _one_line(capsys, *words: str) -> str:
    text = capsys.readouterr().err
    lines = [line for line in text.splitlines() if line.startswith("error:")]  # besides progress lines
    assert len(lines) == 1 and all(w in lines[0] for w in words), text
    assert "Traceback" not in text and "internal error" not in text
    return lines[0]


@pytest.mark.parametrize(
    ("log", "words"),
    [
        (DepthLog(encoding="mono16"), ["topics.depth", TOPIC["depth"], "'mono16'", "32FC1", "16UC1"]),
        (DepthLog(shape=(H // 2, W // 2)), ["topics.depth", TOPIC["depth"], f"{W // 2} x {H // 2}", f"{W} x {H}"]),
        (DepthLog(depth_info=replace(CAMERA, hfov_deg=60.0)), ["topics.depth_info", DEPTH_INFO, "registered", "fx 32 "]),
    ],
)
def test_depth_the_import_cannot_take_is_one_line_naming_the_bag_and_the_field_and_writes_nothing(
    tmp_path: Path, capsys, log: DepthLog, words: list[str]
):
    bag = _write_log(tmp_path / "log.mcap", log)
    robot = _robot(tmp_path, depth_info=log.depth_info is not None)
    assert main(["import", str(bag), "--robot", str(robot), "--out", str(tmp_path / "rec")]) == 2
    _one_line(capsys, str(bag), *words)
    assert not (tmp_path / "rec").exists() and sorted(p.name for p in tmp_path.iterdir()) == sorted([bag.name, robot.name])


def test_a_depth_calibration_equal_to_the_label_cameras_is_taken(tmp_path: Path):
    bag = _write_log(tmp_path / "log.mcap", DepthLog(depth_info=CAMERA))
    assert main(["import", str(bag), "--robot", str(_robot(tmp_path, depth_info=True)), "--out", str(tmp_path / "rec")]) == 0
    assert read_recording(tmp_path / "rec").has_depth


# --- a recording with depth out and in again -------------------------------------------------------


def _first_frames(recording: Path, out: Path, n: int) -> Path:
    """A copy of ``recording`` cut to its first ``n`` frames, complete (a short drive exports and imports fast)."""
    shutil.copytree(recording, out)
    lines = (out / "frames.jsonl").read_text().splitlines(keepends=True)[:n]
    (out / "frames.jsonl").write_text("".join(lines))
    meta = json.loads((out / "meta.json").read_text())
    (out / "meta.json").write_text(json.dumps({**meta, "frames": n}))
    return out


@pytest.mark.parametrize("fmt", ["mcap", "rosbag1"])
def test_an_exported_relief_recording_imports_back_with_its_depth_and_attitude(tmp_path: Path, relief_recording: Path, fmt: str):
    from terrapref.dataset import build_dataset
    from terrapref.recipes import DEFAULT_RECIPE, recipe_named, rules_with

    short = _first_frames(relief_recording, tmp_path / "rec", 16)  # onto the mound: the body pitches
    out = tmp_path / f"run.{'mcap' if fmt == 'mcap' else 'bag'}"
    assert main(["export", str(short), "--format", fmt, "--out", str(out)]) == 0
    assert "depth: /terrapref/depth" in out.with_name(out.name + ".robot.yaml").read_text()
    assert main(["import", str(out), "--robot", f"{out}.robot.yaml", "--out", str(tmp_path / "back")]) == 0
    rec, back = read_recording(short), read_recording(tmp_path / "back")
    assert np.abs(rec.attitudes[:, 1]).max() > 0.05
    assert len(back) == len(rec) and back.has_depth
    for i in range(len(rec)):
        np.testing.assert_array_equal(back.depth(i), rec.depth(i))
    np.testing.assert_allclose(back.attitudes, rec.attitudes, atol=1e-12)
    np.testing.assert_allclose(back.poses, rec.poses, atol=1e-12)
    recipe = recipe_named(DEFAULT_RECIPE)
    a, b = (build_dataset([r], recipe.features(), rules=rules_with(recipe)) for r in (rec, back))
    np.testing.assert_array_equal(a.U, b.U)
    for name, arrays in a.rules.items():
        for key, array in arrays.items():
            np.testing.assert_allclose(b.rules[name][key], array, atol=1e-6, err_msg=f"{name}.{key}")


def test_export_refuses_a_depth_image_of_another_size_than_the_camera_as_featurize_does(tmp_path: Path, relief_recording: Path, capsys):
    from PIL import Image

    short = _first_frames(relief_recording, tmp_path / "rec", 8)
    name = read_recording(short).depth_files[5]
    Image.fromarray(np.asarray(Image.open(short / name))[::2, ::2].copy()).save(short / name)
    out = tmp_path / "run.mcap"
    assert main(["export", str(short), "--format", "mcap", "--out", str(out)]) == 2
    assert capsys.readouterr().err.strip().splitlines()[-1] == f"error: {short / name}: is 320 x 240, the camera's 640 x 480"
    assert not out.exists()


def test_replay_hands_each_frames_depth_and_attitude_to_the_runtime(tmp_path: Path, relief_recording: Path, monkeypatch):
    from helpers import linear_model
    from terrapref.interop.replay import replay
    from terrapref.interop.runtime import PlannerRuntime
    from terrapref.planner.model import Model

    given = []
    decide = PlannerRuntime.decide

    def spy(self, *args, depth=None, **options):
        given.append(depth)
        return decide(self, *args, depth=depth, **options)

    monkeypatch.setattr(PlannerRuntime, "decide", spy)
    rec = read_recording(relief_recording)
    replay(Model.load(linear_model(tmp_path / "m.safetensors")), rec)
    assert len(given) == len(rec) and all(d is not None for d in given)
    i = len(rec) // 2
    np.testing.assert_array_equal(given[i].image, rec.depth(i))
    assert given[i].attitude == rec.attitude(i) and not math.isclose(rec.attitude(i).pitch_rad, 0.0)
