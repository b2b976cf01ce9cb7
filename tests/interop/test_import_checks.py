"""What an import refuses or puts right in a log's odometry, commands and stamps, and the rate it keeps."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from synthetic_bag import robot_yaml, write_robot, write_synthetic_bag
from terrapref.demos.recording import read_recording
from terrapref.errors import UserError
from terrapref.interop.bag_frames import _SmallTopics
from terrapref.interop.bag_import import ImportOptions, _check_command_speeds, import_bag
from terrapref.interop.robot import load_robot

ODOMETRY = SimpleNamespace(msgtype="nav_msgs/msg/Odometry")
TWIST = SimpleNamespace(msgtype="geometry_msgs/msg/Twist")


def _odometry(stamp_s: float, x: float, quaternion=(0.0, 0.0, 0.0, 1.0), z: float = 0.0):
    qx, qy, qz, qw = quaternion
    sec = int(stamp_s)
    pose = SimpleNamespace(position=SimpleNamespace(x=x, y=0.0, z=z), orientation=SimpleNamespace(x=qx, y=qy, z=qz, w=qw))
    return SimpleNamespace(
        header=SimpleNamespace(stamp=SimpleNamespace(sec=sec, nanosec=round((stamp_s - sec) * 1e9))),
        pose=SimpleNamespace(pose=pose),
        twist=SimpleNamespace(twist=SimpleNamespace(linear=SimpleNamespace(x=1.0), angular=SimpleNamespace(z=0.0))),
    )


def _read(poses: list, receive_s: list[float] | None = None) -> _SmallTopics:
    read = _SmallTopics()
    for i, msg in enumerate(poses):
        t = receive_s[i] if receive_s is not None else 100.0 + 0.1 * i
        read.take("odometry", ODOMETRY, round(t * 1e9), msg)
    return read


def test_a_quaternion_not_of_unit_length_turns_the_body_as_its_unit_one_and_is_said():
    half = math.sin(0.3), math.cos(0.3)  # a turn of 0.6 rad about z
    unit = _read([_odometry(100.0 + 0.1 * i, 0.1 * i, (0.0, 0.0, *half)) for i in range(3)]).checked("log.mcap", "/odom")
    scaled = _read([_odometry(100.0 + 0.1 * i, 0.1 * i, (0.0, 0.0, 5 * half[0], 5 * half[1])) for i in range(3)]).checked(
        "log.mcap", "/odom"
    )
    np.testing.assert_allclose(scaled.odom, unit.odom)
    np.testing.assert_allclose(unit.odom[:, 2], 0.6)
    assert not unit.notes and scaled.notes == ["normalised 3 quaternion(s) of /odom that were not of unit length"]


def test_a_pose_whose_quaternion_is_zero_or_not_finite_is_left_out_and_said():
    poses = [_odometry(100.0 + 0.1 * i, 0.1 * i) for i in range(4)]
    poses[1] = _odometry(100.1, 0.1, (0.0, 0.0, 0.0, 0.0))
    poses[2] = _odometry(100.2, 0.2, (0.0, 0.0, math.nan, 1.0))
    streams = _read(poses).checked("log.mcap", "/odom")
    np.testing.assert_allclose(streams.odom_t, [100.0, 100.3])
    assert streams.notes == ["left out 2 pose(s) of /odom whose orientation is a zero or non-finite quaternion"]


def test_a_pose_higher_than_any_robot_goes_is_refused_naming_the_topic():
    poses = [_odometry(100.0 + 0.1 * i, 0.1 * i, z=1e30 if i == 2 else 1500.0) for i in range(4)]
    with pytest.raises(UserError, match=r"log.mcap: topics.odometry: topic /odom: a pose 1e\+30 m high"):
        _read(poses).checked("log.mcap", "/odom")
    assert _read(poses[:2]).checked("log.mcap", "/odom").odom_attitude[:, 0].tolist() == [1500.0, 1500.0]  # an altitude is fine


def test_stamps_that_jump_against_the_logs_clock_are_refused():
    stamps = [1000.0 + 0.1 * i for i in range(6)]
    stamps[3:] = [s - 1000.0 for s in stamps[3:]]  # a simulator's clock reset halfway
    with pytest.raises(UserError, match=r"topics.odometry: topic /odom: header stamps jump by -999.9 s"):
        _read([_odometry(s, 0.1 * i) for i, s in enumerate(stamps)]).checked("log.mcap", "/odom")
    # Stamps on another clock throughout (simulated time recorded by wall clock) are not a jump,
    # nor a simulator paused for 30 s while the log went on recording.
    _read([_odometry(5.0 + 0.1 * i, 0.1 * i) for i in range(6)]).checked("log.mcap", "/odom")
    paused = [100.0 + 0.1 * i + (30.0 if i >= 3 else 0.0) for i in range(6)]
    _read([_odometry(5.0 + 0.1 * i, 0.1 * i) for i in range(6)], receive_s=paused).checked("log.mcap", "/odom")
    ahead = [1000.0 + 0.1 * i + (60.0 if i >= 3 else 0.0) for i in range(6)]  # a clock set forward
    with pytest.raises(UserError, match=r"header stamps jump by \+60.0 s"):
        _read([_odometry(s, 0.1 * i) for i, s in enumerate(ahead)]).checked("log.mcap", "/odom")


def test_a_command_faster_than_any_this_robot_drives_is_refused(tmp_path: Path):
    robot = load_robot(write_robot(tmp_path / "robot.yaml", robot_yaml()))
    read = _read([_odometry(100.0 + 0.1 * i, 0.1 * i) for i in range(3)])
    for v in (1.0, 1e6):
        read.take("command", TWIST, round(100.05e9), SimpleNamespace(linear=SimpleNamespace(x=v), angular=SimpleNamespace(z=0.1)))
    with pytest.raises(UserError, match=r"topics.command: topic .*: a command of 1e\+06 m/s is past any this robot drives"):
        _check_command_speeds(read.checked("log.mcap", "/odom"), robot, "log.mcap")


@pytest.mark.parametrize("rate_hz", [1.0, 4.0, 7.0])
def test_frames_are_kept_at_the_rate_asked_for(tmp_path: Path, rate_hz: float):
    robot = load_robot(write_robot(tmp_path / "robot.yaml", robot_yaml()))
    bag = write_synthetic_bag(tmp_path / "log.mcap", "mcap", quirks=False, max_seconds=6.0)
    report = import_bag(bag, robot, tmp_path / "rec", ImportOptions(rate_hz=rate_hz), show_progress=False)
    times = read_recording(tmp_path / "rec").times
    kept = (len(times) - 1) / (times[-1] - times[0])  # frames a second between the first and the last
    assert abs(kept - rate_hz) <= 0.1 * rate_hz, (kept, np.diff(times))
    assert report.duration_s == pytest.approx(len(times) * np.median(np.diff(times)), rel=1e-3)


@pytest.mark.parametrize("field", ["labels", "path_file"])
def test_a_device_that_never_ends_named_in_a_robot_file_is_refused_without_reading_it_whole(tmp_path: Path, monkeypatch, field: str):
    """``/dev/zero`` as the label map or the path file was read into memory whole (a MemoryError
    under a memory limit, all the memory without one); a file is read no further than its cap."""
    import terrapref.yamlio as yamlio
    from terrapref.interop.robot import load_waypoints

    monkeypatch.setattr(yamlio, "MAX_FILE_BYTES", 1_000_000)  # the cap, smaller: the test reads 1 MB of zeros, not 50
    if field == "path_file":
        with pytest.raises(UserError, match=r"path_file: /dev/zero: unreadable \(file too large"):
            load_waypoints(Path("/dev/zero"), "robot.yaml")
        return
    text = robot_yaml(labels="/dev/zero")
    with pytest.raises(UserError, match="labels.*file too large"):
        load_robot(write_robot(tmp_path / "robot.yaml", text))
