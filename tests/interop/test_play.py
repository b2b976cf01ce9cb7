"""`terrapref play` (terrapref.interop.play) without a DDS network: the log read, paced and
published to a participant that keeps what it is given, on a clock that moves only when the
player sleeps (so no test waits for the log's pace)."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from helpers import one_line_error
from terrapref.cli import main

TOPIC = "/robot/seg/labels"


class _Clock:
    """time.monotonic and time.sleep, on a clock that moves only when slept on."""

    def __init__(self) -> None:
        self.t = 0.0

    def monotonic(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        self.t += max(0.0, seconds)
        assert self.t < 1000.0, "the player waited over 1000 s"


class _Participant:
    """A DDS participant whose writers keep (topic, message) in ``sent`` instead of sending."""

    def __init__(self, types, sent: list) -> None:
        self.types, self.sent = types, sent

    def writer(self, topic: str, msgtype: str, profile, types=None) -> SimpleNamespace:
        return SimpleNamespace(types=types or self.types, publish=lambda msg: self.sent.append((topic, msg)), matched=lambda: 1)

    def close(self) -> None:
        pass


@pytest.fixture
def offline(monkeypatch) -> SimpleNamespace:
    """The player on :class:`_Clock`, publishing to :class:`_Participant`: ``clock``, ``sent``."""
    import terrapref.interop.play as play

    found = SimpleNamespace(clock=_Clock(), sent=[])
    monkeypatch.setattr(play, "time", found.clock)
    monkeypatch.setattr(play, "Participant", lambda domain, types: _Participant(types, found.sent))
    return found


def _log(folder: Path, times_s: list[float], payload: int = 16) -> Path:
    """A ROS 2 MCAP log in zstd chunks of at most about 1 MiB (as ros2 bag record writes it) of
    one CompressedImage topic: a message of ``payload`` bytes at each of ``times_s``; its file."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

    from terrapref.interop.ros_messages import typestore

    ts = typestore()
    T = ts.types
    writer = Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    with writer:
        conn = writer.add_connection(TOPIC, "sensor_msgs/msg/CompressedImage", typestore=ts)
        for t_s in times_s:
            stamp = T["builtin_interfaces/msg/Time"](sec=int(t_s), nanosec=int(round(t_s % 1 * 1e9)))
            msg = T["sensor_msgs/msg/CompressedImage"](
                header=T["std_msgs/msg/Header"](stamp=stamp, frame_id="camera"), format="png", data=np.zeros(payload, np.uint8)
            )
            writer.write(conn, int(round(t_s * 1e9)), ts.serialize_cdr(msg, "sensor_msgs/msg/CompressedImage"))
    return next(folder.glob("*.mcap"))


def _played(sent: list) -> list:
    return [msg for topic, msg in sent if topic == TOPIC]


def test_a_damaged_chunk_stops_the_play_in_one_line_and_the_count_is_what_was_published(tmp_path: Path, offline, capsys):
    bag = _log(tmp_path / "log", [0.1 * i for i in range(9)], payload=400_000)  # three chunks of three messages
    data = bytearray(bag.read_bytes())
    second = data.index(b"\x04\x00\x00\x00zstd", data.index(b"\x04\x00\x00\x00zstd") + 1)  # the second chunk's compression
    data[second + 16 : second + 32] = bytes(16)  # its compressed data's first bytes
    bag.write_bytes(bytes(data))
    assert main(["play", str(bag), "--delay", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(_played(offline.sent)) == 3
    assert err[-2].startswith("play: 3 messages published, then stopped")
    assert err[-1].startswith(f"error: {bag}: damaged: message 4 of the read (0.200 s into the log) cannot be read (ZstdError: ")
    assert "internal error" not in "\n".join(err) and "Traceback" not in "\n".join(err)


def test_a_log_without_messages_is_one_line_and_plays_nothing(tmp_path: Path, offline, capsys):
    bag = _log(tmp_path / "empty", [])
    assert main(["play", str(bag), "--delay", "0"]) == 2
    one_line_error(capsys, str(bag), "holds no messages to play")
    assert offline.sent == []


def test_a_long_gap_is_played_as_max_gap_and_said(tmp_path: Path, offline, capsys):
    """A recording paused for 1e6 s: played as --max-gap (5 s), the clock ticking on through
    them and then jumping, never back; every message published."""
    bag = _log(tmp_path / "gap", [0.0, 1.0, 1e6 + 1.0, 1e6 + 2.0])
    assert main(["play", str(bag), "--delay", "0"]) == 0
    out = capsys.readouterr().out
    assert "play: 1000000.0 s without a message after 1.0 s of log: played as 5 s (--max-gap), the clock jumping 999995.0 s\n" in out
    assert "played 4 messages" in out and "(999995.0 s of gaps longer than --max-gap skipped)" in out
    assert offline.clock.t == pytest.approx(1.0 + 5.0 + 1.0)  # the seconds the play took
    assert [m.header.stamp.sec for m in _played(offline.sent)] == [0, 1, 1_000_001, 1_000_002]
    clock_ns = [m.clock.sec * 10**9 + m.clock.nanosec for topic, m in offline.sent if topic == "/clock"]
    assert clock_ns == sorted(clock_ns) and clock_ns[-1] == int((1e6 + 2.0) * 1e9)


def test_max_gap_is_checked(tmp_path: Path, offline, capsys):
    bag = _log(tmp_path / "log", [0.0])
    assert main(["play", str(bag), "--max-gap", "0.5"]) == 2
    one_line_error(capsys, "--max-gap", "[1, 1e9]")


# --- play --robot: what the node reads, checked as import checks it, and the transforms ---------------

ROBOT_TOPICS = {
    "segmentation": ("/robot/seg/labels", "sensor_msgs/msg/Image"),
    "camera_info": ("/robot/camera/camera_info", "sensor_msgs/msg/CameraInfo"),
    "odometry": ("/robot/odom", "nav_msgs/msg/Odometry"),
    "command": ("/robot/cmd_vel", "geometry_msgs/msg/Twist"),
}
TF = {"/tf": "tf2_msgs/msg/TFMessage", "/tf_static": "tf2_msgs/msg/TFMessage", "/robot/markers": "std_msgs/msg/String"}


def _robot_log(folder: Path, types: dict[str, str], counts: dict[str, int] | None = None) -> Path:
    """A ROS 2 MCAP log of zeroed messages of ``types`` (topic -> type), ``counts`` of each (default
    3), at 0.1 s apart; its file."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    from terrapref.interop.ros_messages import typestore, zeroed

    ts = typestore()
    with Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        for topic, msgtype in types.items():
            conn = writer.add_connection(topic, msgtype, typestore=ts)
            for i in range((counts or {}).get(topic, 3)):
                writer.write(conn, 10**9 + i * 10**8, ts.serialize_cdr(zeroed(ts, msgtype), msgtype))
    return next(folder.glob("*.mcap"))


def _robot_file(folder: Path) -> Path:
    """A robot file naming :data:`ROBOT_TOPICS` (play reads only its topics)."""
    path = folder / "robot.yaml"
    topics = "".join(f"  {role}: {topic}\n" for role, (topic, _) in ROBOT_TOPICS.items())
    path.write_text(f"format: terrapref-robot/1\ntopics:\n{topics}")
    return path


def test_play_robot_plays_what_the_node_reads_and_the_transforms_not_the_commands_or_markers(tmp_path: Path, offline, capsys):
    bag = _robot_log(tmp_path / "log", {**{t: m for t, m in ROBOT_TOPICS.values()}, **TF})
    assert main(["play", str(bag), "--robot", str(_robot_file(tmp_path)), "--delay", "0"]) == 0
    played = {topic for topic, _ in offline.sent} - {"/clock"}
    assert played == {"/robot/seg/labels", "/robot/camera/camera_info", "/robot/odom", "/tf", "/tf_static"}
    assert "played 15 messages on 5 topics" in capsys.readouterr().out


def test_play_robot_plays_a_log_without_transforms(tmp_path: Path, offline, capsys):
    bag = _robot_log(tmp_path / "log", {t: m for t, m in ROBOT_TOPICS.values()})
    assert main(["play", str(bag), "--robot", str(_robot_file(tmp_path)), "--delay", "0"]) == 0
    assert {topic for topic, _ in offline.sent} - {"/clock"} == {"/robot/seg/labels", "/robot/camera/camera_info", "/robot/odom"}


@pytest.mark.parametrize(
    ("types", "counts", "words"),
    [
        ({"/robot/seg/labels": "std_msgs/msg/String"}, {}, ("topics.segmentation /robot/seg/labels has type std_msgs/msg/String",)),
        ({}, {"/robot/seg/labels": 0}, ("topics.segmentation /robot/seg/labels has no messages",)),
        ({}, {"/robot/odom": 0, "/robot/camera/camera_info": 0}, ("topics.camera_info", "has no messages; topics.odometry")),
    ],
    ids=["an image topic of another type", "an image topic without messages", "two topics without messages"],
)
def test_play_robot_refuses_the_topics_import_refuses_in_import_s_words(tmp_path: Path, offline, capsys, types, counts, words):
    from synthetic_bag import robot_yaml, write_robot

    bag = _robot_log(tmp_path / "log", {**{t: m for t, m in ROBOT_TOPICS.values()}, **types}, counts)
    assert main(["play", str(bag), "--robot", str(_robot_file(tmp_path)), "--delay", "0"]) == 2
    line = one_line_error(capsys, str(bag), "topics", *words)
    assert offline.sent == []
    (tmp_path / "full").mkdir()
    robot = write_robot(tmp_path / "full" / "robot.yaml", robot_yaml(path_topic=False))  # the same topics, a file import reads whole
    assert main(["import", str(bag), "--robot", str(robot), "--out", str(tmp_path / "rec")]) == 2
    assert one_line_error(capsys, str(bag)).split(" (topics in ")[0] == line.split(" (topics in ")[0]


@pytest.mark.parametrize("content", [b"\x89MCAP0\r\n", b"12345678", b""], ids=["the magic alone", "garbage", "empty"])
def test_a_log_that_is_no_log_is_refused_by_play_as_import_refuses_it(tmp_path: Path, offline, capsys, content: bytes):
    from synthetic_bag import robot_yaml, write_robot

    bag = tmp_path / "broken.mcap"
    bag.write_bytes(content)
    assert main(["play", str(bag), "--delay", "0"]) == 2
    played = one_line_error(capsys, str(bag))
    robot = write_robot(tmp_path / "robot.yaml", robot_yaml())
    assert main(["import", str(bag), "--robot", str(robot), "--out", str(tmp_path / "rec")]) == 2
    assert one_line_error(capsys, str(bag)) == played
    assert offline.sent == []


def test_play_robot_plays_every_topic_of_an_exported_recording_its_robot_file_names(tmp_path: Path, offline, capsys, tiny_recording):
    """`export --format mcap` writes a log and the robot file of its node: played with it, every
    topic the node reads and the transforms go out, the log's commands do not."""
    from terrapref.interop.robot import load_robot_topics

    bag = tmp_path / "drive.mcap"
    assert main(["export", str(tiny_recording), "--format", "mcap", "--out", str(bag)]) == 0
    robot = Path(f"{bag}.robot.yaml")
    capsys.readouterr()
    assert main(["play", str(bag), "--robot", str(robot), "--delay", "0"]) == 0
    topics = load_robot_topics(robot)
    played = {topic for topic, _ in offline.sent} - {"/clock"}
    assert played == {t for role, t in topics.items() if role != "command"} | {"/tf", "/tf_static"}


def test_ctrl_c_ends_a_play_started_with_sigint_ignored(tmp_path: Path, offline, monkeypatch, capsys):
    """A script's background job inherits SIGINT ignored: play went on to the log's end on Ctrl-C
    (kill -INT), where the node ends; it now ends there too, saying what it published."""
    import os
    import signal

    bag = _log(tmp_path / "log", [0.1 * i for i in range(50)])
    sleep = offline.clock.sleep

    def interrupted(seconds: float) -> None:
        sleep(seconds)
        if offline.clock.t > 1.0:
            os.kill(os.getpid(), signal.SIGINT)

    monkeypatch.setattr(offline.clock, "sleep", interrupted)
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        code = main(["play", str(bag), "--delay", "0"])
    finally:
        signal.signal(signal.SIGINT, previous)
    assert code != 0 and 0 < len(_played(offline.sent)) < 50
    assert "then stopped" in capsys.readouterr().err
