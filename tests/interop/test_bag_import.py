"""Robot logs in: ROS 1 bags, ROS 2 sqlite3 and MCAP bags made from simulator drives, imported
into recordings that inspect, featurize and train accept; every bad bag or robot file is one line."""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from helpers import REPO
from synthetic_bag import LENIENT_LABELS, TOPICS, UNLISTED_ID, robot_yaml, write_robot, write_synthetic_bag
from terrapref.cli import main
from terrapref.dataset import featurize_recording
from terrapref.demos.recording import read_recording
from terrapref.errors import UserError
from terrapref.features import FeatureConfig
from terrapref.interop.bag_import import import_bag, smooth_path
from terrapref.interop.robot import load_robot
from terrapref.report.inspect import summarise
from terrapref.scenario import resolve_scenario
from terrapref.sim import Simulation

SECONDS = 10.0  # of demo_course: past its quirks' odometry gap (8-9 s)
FORMATS = [("mcap", "mono8", "drive.mcapbag"), ("rosbag1", "mono16", "drive.bag"), ("sqlite3", "png", "drive.db3bag")]


@pytest.fixture(scope="module")
def logs(tmp_path_factory) -> dict:
    root = tmp_path_factory.mktemp("bags")
    write_robot(root / "robot.yaml", robot_yaml())
    bags = {
        storage: write_synthetic_bag(root / name, storage, encoding=encoding, max_seconds=SECONDS) for storage, encoding, name in FORMATS
    }
    return {"root": root, "robot": root / "robot.yaml", "bags": bags}


@pytest.fixture(scope="module")
def imported(logs) -> dict:
    robot = load_robot(logs["robot"])
    out = {}
    for storage, bag in logs["bags"].items():
        dest = logs["root"] / f"rec_{storage}"
        out[storage] = (import_bag(bag, robot, dest, show_progress=False), read_recording(dest))
    return out


def test_every_format_imports_to_the_same_recording(imported):
    (report, rec), *others = imported.values()
    assert rec.complete and len(rec) == report.frames > 0.8 * SECONDS * 10
    for other_report, other in others:
        assert other_report.frames == report.frames
        np.testing.assert_allclose(other.poses, rec.poses, atol=1e-9)
        np.testing.assert_array_equal(other.labels, rec.labels)
        np.testing.assert_array_equal(other.image(len(rec) // 2), rec.image(len(rec) // 2))


def test_an_id_the_label_map_does_not_list_is_refused_unless_the_map_makes_it_unknown(tmp_path: Path, logs):
    robot = write_robot(tmp_path / "robot.yaml", robot_yaml(labels="rellis3d"))  # the packaged map: unlisted ids are errors
    dest = tmp_path / "rec"
    with pytest.raises(UserError) as info:
        import_bag(logs["bags"]["mcap"], load_robot(robot), dest, show_progress=False)
    (line,) = info.value.lines()
    assert "rellis3d.yaml" in line and "ids:" in line and f"label id {UNLISTED_ID} " in line and "unlisted: unknown" in line, line
    assert not dest.exists() and not dest.with_name("rec.partial").exists()  # nothing half-written
    (tmp_path / "lenient").mkdir()
    lenient = write_robot(tmp_path / "lenient" / "robot.yaml")  # the same map with unlisted: unknown
    report = import_bag(logs["bags"]["mcap"], load_robot(lenient), dest, show_progress=False)
    assert report.frames > 0 and 0.0 < report.unmapped_share < 0.01


def test_the_quirks_are_handled_and_reported(imported):
    report, rec = imported["mcap"]
    assert report.skipped["images in an odometry gap"] > 0  # the synthetic log loses a second of odometry
    assert 0.0 < report.unmapped_share < 0.01  # a few pixels carry an id the label map does not list
    assert report.path_source.startswith(TOPICS["path"])
    assert np.all(np.diff(rec.times) > 0.07)  # out-of-order stamps put right, thinned to 10 Hz
    assert rec.meta["driver"]["kind"] == "imported" and rec.meta["origin_shift_m"]
    assert (rec.poses[:, :2] > 0).all()  # the odometry frame started at the robot; the map starts at 0
    assert set(np.unique(rec.image(len(rec) - 1))) <= {0, 1, 2, 3, 4, 255}
    text = "\n".join(report.lines())
    assert "odometry gap" in text and "not in the label map" in text


def test_an_undisturbed_clean_log_reproduces_the_simulator_run(tmp_path: Path, logs):
    bag = write_synthetic_bag(tmp_path / "clean.mcap", "mcap", quirks=False, max_seconds=6.0)
    rec = read_recording(tmp_path / "rec") if import_bag(bag, load_robot(logs["robot"]), tmp_path / "rec", show_progress=False) else None
    # The same drive in the simulator: the driver, its pushes and the camera, frame by frame.
    sim = Simulation(resolve_scenario("demo_course"))
    shift = np.array(rec.meta["origin_shift_m"])
    for i in (0, len(rec) // 2, len(rec) - 1):
        pose = rec.poses[i] - (*shift, 0.0)
        np.testing.assert_array_equal(rec.image(i), sim.renderer.render(tuple(pose)))
    assert len(rec) >= 55
    features = FeatureConfig()
    U, labels = featurize_recording(rec, features)[:2]
    assert U.shape == (len(rec), 21, 5) and np.isfinite(U).all() and len(set(labels.tolist())) > 1


def test_inspect_and_featurize_accept_an_imported_recording(imported, capsys):
    _, rec = imported["rosbag1"]
    summary = summarise(rec)
    assert summary.frames == len(rec) and summary.zones == []
    assert main(["inspect", str(rec.path), "--no-preference"]) == 0
    assert (rec.path / "driven_path.png").is_file()
    out = rec.path.parent / "ds.safetensors"
    assert main(["featurize", str(rec.path), "--out", str(out)]) == 0 and out.is_file()


def test_inspect_of_an_imported_log_says_it_has_no_map_and_draws_none(imported, tmp_path: Path, capsys):
    import matplotlib.pyplot as plt

    from terrapref.plots import draw_map

    _, rec = imported["mcap"]
    assert main(["inspect", str(rec.path), "--no-preference", "--out", str(tmp_path / "path.png")]) == 0
    out = capsys.readouterr().out
    assert "map        none: the log holds the path and the driven poses, not the ground" in out
    summary = summarise(rec)
    fig, ax = plt.subplots()
    assert draw_map(ax, summary.scenario, summary.world) == [] and len(ax.images) == 0  # no legend of classes, no painted ground
    plt.close(fig)


def test_without_a_path_the_driven_odometry_is_smoothed(tmp_path: Path, logs):
    robot = tmp_path / "robot.yaml"
    write_robot(robot, robot_yaml(path_topic=False))
    report = import_bag(logs["bags"]["mcap"], load_robot(robot), tmp_path / "rec", show_progress=False)
    assert report.path_source.startswith("the driven odometry")
    straight = smooth_path(np.stack([np.linspace(0, 30, 301), 0.2 * np.sin(np.linspace(0, 30, 301) * 5)], axis=1))
    interior = (straight[:, 0] > 5.0) & (straight[:, 0] < 25.0)
    assert np.abs(straight[interior, 1]).max() < 0.02  # a 0.2 m weave averaged away
    assert straight[0] == pytest.approx([0.0, 0.0], abs=1e-9) and straight[-1, 0] == pytest.approx(30.0, abs=0.3)


def test_cli_import(tmp_path: Path, logs, capsys):
    out = tmp_path / "rec"
    assert main(["import", str(logs["bags"]["mcap"]), "--robot", str(logs["robot"]), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "frames kept" in text and "wrote" in text and read_recording(out).complete
    assert main(["import", str(logs["bags"]["mcap"]), "--robot", str(logs["robot"]), "--out", str(out)]) == 2  # exists
    assert "--force" in capsys.readouterr().err
    assert main(["import", str(logs["bags"]["rosbag1"]), "--robot", str(logs["robot"]), "--out", str(out), "--force"]) == 0
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary folder left


# --- refusals -------------------------------------------------------------------------------


def _one_line(capsys, *names: str) -> str:
    text = capsys.readouterr().err
    err = [line for line in text.splitlines() if line.startswith("error:")]  # besides progress lines
    assert len(err) == 1 and all(n in err[0] for n in names), err
    assert "internal error" not in text and "Traceback" not in text
    return err[0]


def test_a_missing_topic_or_a_wrong_type_names_the_bag_and_the_field(tmp_path: Path, logs, capsys):
    bag = str(logs["bags"]["mcap"])
    robot = tmp_path / "robot.yaml"
    write_robot(robot, robot_yaml().replace(TOPICS["odometry"], "/warthog/odom"))
    assert main(["import", bag, "--robot", str(robot), "--out", str(tmp_path / "a")]) == 2
    _one_line(capsys, bag, "topics.odometry", "/warthog/odom", "is not in the bag")
    write_robot(robot, robot_yaml(command=False).replace(f"odometry: {TOPICS['odometry']}", f"odometry: {TOPICS['command']}"))
    assert main(["import", bag, "--robot", str(robot), "--out", str(tmp_path / "b")]) == 2
    _one_line(capsys, bag, "topics.odometry", "geometry_msgs/msg/Twist")
    write_robot(robot, robot_yaml().replace(f"odometry: {TOPICS['odometry']}", f"odometry: {TOPICS['command']}"))
    assert main(["import", bag, "--robot", str(robot), "--out", str(tmp_path / "c")]) == 2  # two roles, one topic: the file says
    _one_line(capsys, str(robot), "topics.", "each role comes on a topic of its own")
    write_robot(robot, robot_yaml().replace(f"odometry: {TOPICS['odometry']}", "odometry: /warthog/odom pose"))
    assert main(["import", bag, "--robot", str(robot), "--out", str(tmp_path / "d")]) == 2  # not a ROS name
    _one_line(capsys, str(robot), "topics.odometry", "expected a topic name")
    assert not any((tmp_path / d).exists() for d in "abcd")


def test_every_missing_or_mistyped_topic_is_named_in_one_message(tmp_path: Path, logs, capsys):
    bag = str(logs["bags"]["mcap"])
    robot = tmp_path / "robot.yaml"
    write_robot(
        robot,
        robot_yaml(path_topic=False)  # the path's topic named as the command's alone (two roles on one topic are the file's own error)
        .replace(TOPICS["odometry"], "/warthog/odom")
        .replace(f"command: {TOPICS['command']}", f"command: {TOPICS['path']}"),
    )
    assert main(["import", bag, "--robot", str(robot), "--out", str(tmp_path / "a")]) == 2
    _one_line(capsys, bag, "topics.odometry /warthog/odom is not in the bag", f"topics.command {TOPICS['path']} has type nav_msgs/msg/Path")


def _rewritten(mcap: Path, out: Path, service_events: bool = False, receive_shift_s: float = 0.0) -> Path:
    """``mcap`` written again, with a service-event channel as ``ros2 bag record -a`` writes it
    (its schema holds the raw service definition, which no message parser reads as the event
    type), or with every message received ``receive_shift_s`` later than its header stamp says
    (simulated time stamped, wall time received)."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    shift_ns = int(round(receive_shift_s * 1e9))
    with open(mcap, "rb") as source, open(out, "wb") as sink:
        reader, writer = make_reader(source), Writer(sink)
        writer.start(profile="ros2", library="terrapref tests")
        summary = reader.get_summary()
        schemas = {i: writer.register_schema(s.name, s.encoding, s.data) for i, s in summary.schemas.items()}
        channels = {
            i: writer.register_channel(c.topic, c.message_encoding, schemas[c.schema_id], c.metadata) for i, c in summary.channels.items()
        }
        raw = b"=" * 80 + b"\nSRV: example_interfaces/srv/AddTwoInts\nint64 a\nint64 b\n---\nint64 sum\n"
        event = writer.register_channel(
            "/add_two_ints/_service_event", "cdr", writer.register_schema("example_interfaces/srv/AddTwoInts_Event", "ros2msg", raw), {}
        )
        for i, (_, channel, message) in enumerate(reader.iter_messages()):
            writer.add_message(channels[channel.id], message.log_time + shift_ns, message.data, message.publish_time + shift_ns)
            if service_events and i % 50 == 0:
                writer.add_message(event, message.log_time, bytes(48), message.publish_time)
        writer.finish()
    return out


def test_a_log_with_service_events_imports_and_says_what_it_left_out(tmp_path: Path, logs, imported, capsys):
    bag = _rewritten(_mcap_file(logs["bags"]["mcap"]), tmp_path / "with_services.mcap", service_events=True)
    assert main(["import", str(bag), "--robot", str(logs["robot"]), "--out", str(tmp_path / "rec")]) == 0
    out = capsys.readouterr().out
    assert "left out 1 topic(s) whose message definition in the log cannot be read: /add_two_ints/_service_event" in out
    assert len(read_recording(tmp_path / "rec")) == len(imported["mcap"][1])
    # Asked for as a topic the planner needs, it is one line naming the topic and its type.
    robot = tmp_path / "robot.yaml"
    write_robot(robot, robot_yaml().replace(TOPICS["command"], "/add_two_ints/_service_event"))
    assert main(["import", str(bag), "--robot", str(robot), "--out", str(tmp_path / "b")]) == 2
    _one_line(capsys, "/add_two_ints/_service_event", "AddTwoInts_Event", "cannot be read")


def test_stamps_in_simulated_time_and_unstamped_commands_in_wall_time_are_paired_on_one_clock(tmp_path: Path, logs, imported, capsys):
    # Header stamps from a simulator's clock, receive times from the wall clock 1000 s on: the
    # Twist commands (no stamp) are timed by receive time, and are moved onto the stamps' clock.
    bag = _rewritten(_mcap_file(logs["bags"]["mcap"]), tmp_path / "sim_time.mcap", receive_shift_s=1000.0)
    assert main(["import", str(bag), "--robot", str(logs["robot"]), "--out", str(tmp_path / "rec")]) == 0
    assert "header stamps run -1000.0 s from when the log received the messages" in capsys.readouterr().out
    rec, plain = read_recording(tmp_path / "rec"), imported["mcap"][1]
    assert len(rec) == len(plain)
    # The clocks' offset is measured on the odometry, whose receive times lag its stamps by the
    # log's latency: a command near a change may land one frame off.
    assert np.mean(rec.labels == plain.labels) >= 0.9 and np.abs(rec.labels - plain.labels).max() <= 1


def _mcap_file(folder: Path) -> Path:
    return next(folder.glob("*.mcap"))


@pytest.mark.parametrize("damage", ["garbage", "truncated", "empty", "missing", "truncated mcap", "garbage mcap", "truncated sqlite3"])
def test_a_damaged_bag_is_one_line_and_leaves_nothing(tmp_path: Path, logs, capsys, damage: str):
    source = logs["bags"]["rosbag1"]
    bag = tmp_path / "broken.bag"
    if damage == "garbage":
        bag.write_bytes(b"#ROSBAG V2.0\n" + bytes(range(256)) * 40)
    elif damage == "truncated":
        bag.write_bytes(source.read_bytes()[: source.stat().st_size // 3])
    elif damage == "empty":
        bag.write_bytes(b"")
    elif damage.endswith("mcap"):
        mcap = _mcap_file(logs["bags"]["mcap"])
        bag = tmp_path / "broken.mcap"
        data = mcap.read_bytes()
        bag.write_bytes(data[: len(data) // 2] if damage.startswith("truncated") else data[:64] + bytes(range(256)) * 100)
    elif damage == "truncated sqlite3":
        bag = tmp_path / "broken_sqlite3"
        shutil.copytree(logs["bags"]["sqlite3"], bag)
        db = next(bag.glob("*.db3"))
        db.write_bytes(db.read_bytes()[: db.stat().st_size // 2])
    out = tmp_path / "rec"
    assert main(["import", str(bag), "--robot", str(logs["robot"]), "--out", str(out)]) == 2
    _one_line(capsys, str(bag))
    assert not out.exists() and not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_a_failed_force_import_keeps_the_old_recording(tmp_path: Path, logs, imported, capsys):
    out = tmp_path / "rec"
    shutil.copytree(logs["root"] / "rec_mcap", out)
    before = (out / "frames.jsonl").read_bytes()
    (tmp_path / "broken.bag").write_bytes(b"not a bag")
    assert main(["import", str(tmp_path / "broken.bag"), "--robot", str(logs["robot"]), "--out", str(out), "--force"]) == 2
    assert (out / "frames.jsonl").read_bytes() == before and read_recording(out).complete


@pytest.mark.parametrize(
    "edit,field",
    [
        (lambda t: t + "speed: 3\n", "speed"),
        (lambda t: t.replace("  pitch_deg: 30.0\n", ""), "camera.pitch_deg"),
        (lambda t: t.replace("height_m: 1.0", "height_m: -1"), "camera.height_m"),
        (lambda t: t.replace(f"command: {TOPICS['command']}", "command: cmd_vel"), "topics.command"),
        (lambda t: t.replace(f"  odometry: {TOPICS['odometry']}\n", ""), "topics.odometry"),
        (lambda t: t.replace(TOPICS["segmentation"], "seg"), "topics.segmentation"),
        (lambda t: t.replace(f"labels: {LENIENT_LABELS}", "labels: cityscapes"), "labels"),
        (lambda t: t.replace("terrapref-robot/1", "terrapref-robot/9"), "format"),
        (lambda t: t.replace("topics:\n", "topics:\n  depth: depth\n"), "topics.depth"),
        (lambda t: t.replace("topics:\n", f"topics:\n  depth: {TOPICS['segmentation']}\n"), "topics.depth"),
        (lambda t: t.replace("topics:\n", "topics:\n  depth_info: /cam/depth_info\n"), "topics.depth_info"),
    ],
)
def test_a_bad_robot_file_is_one_line_naming_file_and_field(tmp_path: Path, edit, field: str):
    robot = tmp_path / "robot.yaml"
    robot.write_text(edit(robot_yaml()))
    with pytest.raises(UserError) as info:
        load_robot(robot)
    lines = info.value.lines()
    assert len(lines) == 1 and str(robot) in lines[0] and f"{field}:" in lines[0], lines


def test_the_issue_example_robot_file_is_accepted(tmp_path: Path):
    robot = tmp_path / "warthog.yaml"
    robot.write_text("""format: terrapref-robot/1
topics:
  segmentation: /warthog/seg/labels        # sensor_msgs/Image
  camera_info: /warthog/camera/camera_info # sensor_msgs/CameraInfo
  odometry: /warthog/odom                  # nav_msgs/Odometry
  command: /warthog/cmd_vel                # geometry_msgs/Twist
  path: /route/plan                        # nav_msgs/Path
camera:
  height_m: 1.0
  pitch_deg: 30.0
labels: rellis3d
""")
    config = load_robot(robot)
    assert config.topics["odometry"] == "/warthog/odom" and config.path_topic == "/route/plan"
    assert config.camera["height_m"] == 1.0 and config.labels.name == "rellis3d"


# --- recordings and runs out, as MCAP ----------------------------------------------------------


def _topics(path: Path) -> dict[str, tuple[str, int]]:
    from rosbags.highlevel import AnyReader

    with AnyReader([path]) as reader:
        return {c.topic: (c.msgtype, c.msgcount) for c in reader.connections}


def _check_with_the_reference_mcap_reader(path: Path, frames: int) -> None:
    """What Foxglove needs: the ros2 profile, every schema a ros2msg definition, CDR messages,
    a summary whose counts match, and every message readable."""
    from mcap.reader import make_reader

    with open(path, "rb") as fh:
        reader = make_reader(fh)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert summary is not None and all(sc.encoding == "ros2msg" and sc.data for sc in summary.schemas.values())
        assert all(ch.message_encoding == "cdr" for ch in summary.channels.values())
        counts = {ch.topic: summary.statistics.channel_message_counts[ch.id] for ch in summary.channels.values()}
        assert counts["/terrapref/labels"] == counts["/terrapref/trajectories"] == frames
        assert sum(1 for _ in reader.iter_messages()) == sum(counts.values())


def test_a_run_is_written_as_mcap_beside_its_output_not_in_the_systems_tmp(tmp_path: Path, fig7_recording: Path, monkeypatch):
    """`evaluate --mcap` writes runs/NAME.mcap into a folder that does not exist yet: the file is
    made beside it, so its rename never crosses file systems (the system's tmp is often another:
    a rename across is refused with EXDEV)."""
    import errno
    import os
    import tempfile
    from dataclasses import replace

    from terrapref.interop.mcap_export import recording_frames, write_mcap

    system_tmp = tmp_path / "system_tmp"  # another file system, as far as renames go
    system_tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(system_tmp))
    real_replace, real_rename = os.replace, os.rename

    def across(real):
        def move(src, dst, *args, **kwargs):
            if Path(src).is_relative_to(system_tmp) != Path(dst).is_relative_to(system_tmp):
                raise OSError(errno.EXDEV, "Invalid cross-device link", str(src), None, str(dst))
            return real(src, dst, *args, **kwargs)

        return move

    monkeypatch.setattr(os, "replace", across(real_replace))
    monkeypatch.setattr(os, "rename", across(real_rename))
    rec = read_recording(fig7_recording)
    frames = recording_frames(rec)
    frames = replace(frames, times=frames.times[:3], poses=frames.poses[:3], commands=frames.commands[:3], chosen=frames.chosen[:3])
    out = tmp_path / "ev" / "runs" / "fig7_seed0.mcap"
    write_mcap(out, frames, robot_file=False)
    assert _topics(out)["/terrapref/labels"] == ("sensor_msgs/msg/CompressedImage", 3)
    assert [p.name for p in out.parent.iterdir()] == [out.name] and not any(system_tmp.iterdir())


@pytest.mark.parametrize("fmt", ["mcap", "rosbag1"])
def test_an_exported_recording_imports_to_the_same_dataset(tmp_path: Path, imported, capsys, fmt: str):
    from terrapref.dataset import build_dataset
    from terrapref.recipes import DEFAULT_RECIPE, recipe_named

    _, rec = imported["mcap"]
    out = tmp_path / f"run.{'mcap' if fmt == 'mcap' else 'bag'}"
    assert main(["export", str(rec.path), "--format", fmt, "--out", str(out)]) == 0
    topics = _topics(out)
    assert topics["/terrapref/labels"] == ("sensor_msgs/msg/CompressedImage", len(rec))
    assert topics["/terrapref/trajectories"] == ("visualization_msgs/msg/MarkerArray", len(rec))
    assert {
        "/tf",
        "/tf_static",
        "/terrapref/odom",
        "/terrapref/cmd_vel",
        "/terrapref/path",
        "/terrapref/camera_info",
        "/terrapref/labels_color",
    } <= set(topics)
    if fmt == "mcap":
        _check_with_the_reference_mcap_reader(out, len(rec))
    assert _chunk_compression(out) == {"mcap": {"zstd"}, "rosbag1": {"lz4"}}[fmt]  # each format's own, which its players read
    progress = [line for line in capsys.readouterr().err.splitlines() if line.startswith("export:") and "%" in line]
    assert progress and all(f"/{len(rec)} frames (" in line for line in progress)  # what is done and the time, not a bare percentage
    assert main(["import", str(out), "--robot", f"{out}.robot.yaml", "--out", str(tmp_path / "back")]) == 0
    back = read_recording(tmp_path / "back")
    features = recipe_named(DEFAULT_RECIPE).features()
    assert build_dataset([back], features).fingerprint == build_dataset([rec], features).fingerprint


def _chunk_compression(path: Path) -> set[str]:
    """The compressions of a bag's chunks ('' for none): an MCAP file's by the reference reader, a ROS 1 bag's by rosbags'."""
    if path.suffix == ".mcap":
        from mcap.reader import make_reader

        with path.open("rb") as f:
            return {c.compression for c in make_reader(f).get_summary().chunk_indexes}
    from rosbags.rosbag1 import Reader

    with Reader(path) as reader:  # each chunk keeps the function that decompresses it: lz4's, bz2's, or none
        return {(c.decompressor.__module__ or "").split(".")[0] if c.decompressor else "" for c in reader.chunks.values()}


def test_evaluate_writes_each_run_as_mcap(tmp_path: Path, capsys):
    from helpers import TINY_COURSE, linear_model

    model = linear_model(tmp_path / "linear.safetensors")
    out = tmp_path / "ev"
    assert (
        main(
            [
                "evaluate",
                str(model),
                str(TINY_COURSE),
                "--seeds",
                "1",
                "--no-driver",
                "--workers",
                "1",
                "--out",
                str(out),
                "--mcap",
            ]
        )
        == 0
    )
    (run,) = (out / "runs").glob("*tiny_course_seed0.mcap")  # named after the course file's path
    topics = _topics(run)
    frames = topics["/terrapref/labels"][1]
    assert frames > 50 and topics["/terrapref/trajectories"][1] == frames and topics["/terrapref/odom"][1] == frames
    _check_with_the_reference_mcap_reader(run, frames)


def test_replay_reports_agreement_with_the_operator(tmp_path: Path, logs, capsys):
    from helpers import linear_model

    model = linear_model(tmp_path / "linear.safetensors")
    out = tmp_path / "replay"
    assert main(["replay", str(logs["bags"]["sqlite3"]), "--robot", str(logs["robot"]), "--model", str(model), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "planner, all frames" in text and "C alone" in text
    import json

    result = json.loads((out / "replay.json").read_text())
    o = result["overall"]
    assert o["frames"] == len(read_recording(out / "recording")) and 0.0 <= o["top1"] <= 1.0
    c = result["classifier_overall"]
    assert 0.0 <= c["top1"] <= c["top3"] <= 1.0 and o["top3"] is None  # the planner ranks nothing: only C has a top-3
    assert o["mean_abs_v_error_mps"] == 0.0  # the operator drove at 1 m/s, the model (no speed rule) commands 1 m/s
    assert "planner, all frames" in text and "top-3" not in text.split("planner, all frames")[1].splitlines()[0]
    assert "the planner's rules choose one trajectory and rank none, so only C has a top-3" in text
    assert result["terrain_in_view"]["frames"] < o["frames"] and (out / "replay.png").stat().st_size > 10_000
    # A model for another camera is refused in one line.
    from helpers import model_meta
    from terrapref.camera import CameraConfig
    from terrapref.learning import load_model, save_model

    other = load_model(model)
    meta = model_meta(camera=CameraConfig(pitch_deg=20.0))
    save_model(tmp_path / "other.safetensors", other.classifier, other.weights, meta)
    assert (
        main(
            [
                "replay",
                str(logs["bags"]["sqlite3"]),
                "--robot",
                str(logs["robot"]),
                "--model",
                str(tmp_path / "other.safetensors"),
                "--out",
                str(tmp_path / "r2"),
            ]
        )
        == 2
    )
    _one_line(capsys, "other.safetensors", "another camera")
    assert not (tmp_path / "r2").exists()  # refused as soon as the log's camera is known, nothing left half-made


# --- speed: the recorded speed kept, learned, commanded and compared --------------------------

FAST_MPS = 1.5  # the operator of the fast log drives at this speed, not the control set's 1 m/s


@pytest.fixture(scope="module")
def fast(tmp_path_factory) -> dict:
    """A drive at FAST_MPS as a quirky MCAP log, imported, and a model taught by it (recipe teach)."""
    root = tmp_path_factory.mktemp("fast")
    robot = write_robot(root / "robot.yaml", robot_yaml())
    bag = write_synthetic_bag(root / "fast.mcap", "mcap", max_seconds=10.0, speed_mps=FAST_MPS)
    report = import_bag(bag, load_robot(robot), root / "rec", show_progress=False)
    # C's epochs cut short: what is read of the model is its speed rule, fitted to the drive's speeds.
    assert main(["train", str(root / "rec"), "--out", str(root / "taught.safetensors"), "--epochs", "5"]) == 0
    return {"bag": bag, "report": report, "rec": read_recording(root / "rec"), "model": root / "taught.safetensors"}


def _logged_commands(bag: Path) -> set[tuple[float, float]]:
    """Every (v, w) the log's command topic holds, as published."""
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as reader:
        conns = [c for c in reader.connections if c.topic == TOPICS["command"]]
        msgs = (reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages(connections=conns))
        return {(float(m.linear.x), float(m.angular.z)) for m in msgs}


def test_an_imported_log_keeps_the_speed_driven_and_labels_each_frame_by_its_curvature(fast):
    from terrapref.vehicle import ControlSet

    rec, report = fast["rec"], fast["report"]
    assert rec.commands[:, 0] == pytest.approx([FAST_MPS] * len(rec)), "the speed the operator drove, not the control set's"
    logged = _logged_commands(fast["bag"])
    assert all((v, w) in logged for v, w in rec.commands.tolist()), "each frame's command as the log holds it"
    control = ControlSet()
    # The label is the trajectory of the same curvature at the control set's 1 m/s: w x 1 / 1.5.
    at_set = np.clip(rec.commands[:, 1] * control.v_mps / FAST_MPS, min(control.w_rps), max(control.w_rps))
    np.testing.assert_array_equal(rec.labels, control.label_of(at_set))
    assert len(set(rec.labels.tolist())) > 1  # it steered
    assert report.speed_mps == pytest.approx((FAST_MPS, FAST_MPS, FAST_MPS))
    assert "speed            1.50 m/s on average (1.50-1.50)" in "\n".join(report.lines())


def test_a_model_taught_by_a_log_driven_at_1_5_mps_commands_1_5_mps_on_open_ground(fast):
    from test_interop import UNSMOOTHED

    from terrapref.learning.model_file import load_model
    from terrapref.rules import rules_of, speed_rule
    from terrapref.runtime import PlannerRuntime

    rules, _ = rules_of(load_model(fast["model"]))
    assert speed_rule(rules) is not None
    scenario = resolve_scenario("demo_course")
    runtime = PlannerRuntime(fast["model"], robot=UNSMOOTHED)
    runtime.set_path(scenario.waypoints)
    frame = Simulation(scenario).reset()
    decision = runtime.decide(frame.image, frame.time_s, frame.pose)
    assert decision.stop is None and decision.command.v == pytest.approx(FAST_MPS)
    assert runtime.command_at(frame.time_s + 0.1) == decision.command  # what a node sends: the learned speed


def test_replay_compares_the_models_speed_with_the_operators(tmp_path: Path, fast):
    from helpers import linear_model
    from terrapref.interop.replay import replay, summary_lines
    from terrapref.planner.model import Model

    rec = fast["rec"]
    plain = replay(Model.load(linear_model(tmp_path / "linear.safetensors")), rec)  # no speed rule: the control set's 1 m/s
    series = plain["series"]
    assert series["v_operator"] == pytest.approx([FAST_MPS] * len(rec)) and series["v_model"] == pytest.approx([1.0] * len(rec))
    assert plain["overall"]["mean_abs_v_error_mps"] == pytest.approx(FAST_MPS - 1.0)
    # The ways compared like with like: the operator's w brought to the control set's speed, as the label is.
    np.testing.assert_allclose(series["w_operator"], rec.commands[:, 1] / FAST_MPS)
    w_error = np.abs(np.asarray(series["w_model"]) - np.asarray(series["w_operator"])).mean()
    assert plain["overall"]["mean_abs_w_error_rps"] == pytest.approx(w_error)
    assert plain["classifier_overall"]["mean_abs_v_error_mps"] is None  # C alone picks no speed
    taught = replay(Model.load(fast["model"]), rec)
    v_error = np.abs(np.asarray(taught["series"]["v_model"]) - FAST_MPS).mean()
    assert taught["overall"]["mean_abs_v_error_mps"] == pytest.approx(v_error)
    assert v_error < 0.2  # it learned the operator's speed (slowing where its speed rule says so), not 1 m/s
    lines = summary_lines(taught)
    assert f"mean |v| error {v_error:.3f} m/s over {len(rec)} frames" in lines[0] and "|v|" not in lines[2]
    # On a robot whose limits hold it to 0.3 m/s (its robot file's, as its node takes them), the replay's planner too.
    from terrapref.interop.runtime import RobotSettings
    from terrapref.vehicle import VehicleConfig

    slow = replay(Model.load(fast["model"]), rec, robot=RobotSettings(limits=replace(VehicleConfig(), max_speed_mps=0.8)))
    assert max(slow["series"]["v_model"]) <= 0.8 + 1e-9 < max(taught["series"]["v_model"])


# --- speed without commands: the odometry's twist, or differences of its poses ----------------


@pytest.fixture(scope="module")
def measured(tmp_path_factory) -> dict:
    """The drive of ``fast`` (FAST_MPS) logged without commands, its odometry an Odometry with its
    twist filled, a PoseStamped, and an Odometry whose twist is zero; each imported by a robot
    file without a command topic, and a model taught by the first."""
    root = tmp_path_factory.mktemp("measured")
    robot = write_robot(root / "robot.yaml", robot_yaml(command=False))
    kinds = {
        "twist": {"twist": True},
        "poses": {"odometry_type": "geometry_msgs/msg/PoseStamped"},
        "zero_twist": {},
    }
    out: dict = {"robot": robot}
    for name, kind in kinds.items():
        # 20 s: labelled by the odometry's motion, 10 s did not show the offset rule what holding off the path costs.
        bag = write_synthetic_bag(root / f"{name}.mcap", "mcap", max_seconds=20.0, speed_mps=FAST_MPS, commands=False, **kind)
        rec = root / f"rec_{name}"
        out[name] = {"bag": bag, "report": import_bag(bag, load_robot(robot), rec, show_progress=False), "rec": read_recording(rec)}
    assert main(["train", str(root / "rec_twist"), "--out", str(root / "taught.safetensors"), "--epochs", "5"]) == 0  # as fast's
    out["model"] = root / "taught.safetensors"
    return out


def _same_frames(a, b) -> tuple[np.ndarray, np.ndarray]:
    """The indices in recordings ``a`` and ``b`` of the frames both kept (of one drive: the same poses)."""
    where = {tuple(np.round(p[:2], 6)): i for i, p in enumerate(b.poses)}
    pairs = [(i, where[key]) for i, p in enumerate(a.poses) if (key := tuple(np.round(p[:2], 6))) in where]
    assert len(pairs) > 0.9 * min(len(a), len(b))
    return np.array([i for i, _ in pairs]), np.array([j for _, j in pairs])


def test_without_a_command_topic_each_frame_is_labelled_by_the_odometrys_twist(measured):
    from terrapref.interop.bag_frames import MIN_SPEED_MPS
    from terrapref.vehicle import ControlSet

    assert load_robot(measured["robot"]).command_topic is None
    report, rec = measured["twist"]["report"], measured["twist"]["rec"]
    assert report.speed_source == "twist"
    assert "measured by the odometry's twist (no command topic)" in "\n".join(report.lines())
    v, w = rec.commands.T
    # Driven at 1.5 m/s once it has sped up from rest at 1 m/s^2: the measured speed, not a command's.
    assert np.median(v) == pytest.approx(FAST_MPS, abs=0.01) and np.mean(np.abs(v - FAST_MPS) < 0.05) > 0.8
    assert v.min() >= MIN_SPEED_MPS and v.max() <= FAST_MPS + 1e-9 and v[0] < 0.5 * FAST_MPS
    assert report.skipped["images while stopped or reversing"] >= 1  # at rest before the drive: the same reason as a stop command
    control = ControlSet()
    np.testing.assert_array_equal(rec.labels, control.label_of(np.clip(w * control.v_mps / v, min(control.w_rps), max(control.w_rps))))
    assert len(set(rec.labels.tolist())) > 1  # it steered


def test_without_twist_the_speed_is_measured_by_differences_of_odometry_poses(measured):
    twist, poses = measured["twist"]["rec"], measured["poses"]["rec"]
    report = measured["poses"]["report"]
    assert report.speed_source == "poses" and not report.notes
    assert "measured by differences of odometry poses over 0.2 s (no command topic)" in "\n".join(report.lines())
    assert np.median(poses.commands[:, 0]) == pytest.approx(FAST_MPS, abs=0.01)
    # Two measurements of one drive: the twist and the poses' differences agree frame by frame.
    a, b = _same_frames(twist, poses)
    np.testing.assert_allclose(poses.commands[b, 0], twist.commands[a, 0], atol=0.05)
    assert np.median(np.abs(poses.commands[b, 1] - twist.commands[a, 1])) < 0.05  # yaw rate (smoothed where it steps)


def test_an_odometry_twist_that_is_zero_throughout_falls_back_to_pose_differences_and_says_so(measured):
    report, rec = measured["zero_twist"]["report"], measured["zero_twist"]["rec"]
    assert report.speed_source == "poses"
    assert len(rec) > 0.8 * 10.0 * 10 and np.median(rec.commands[:, 0]) == pytest.approx(FAST_MPS, abs=0.01)  # not 0 m/s
    np.testing.assert_array_equal(rec.commands, measured["poses"]["rec"].commands)  # the same poses, the same differences
    lines = "\n".join(report.lines())
    assert f"note             the twist of {TOPICS['odometry']} is zero throughout while its pose moves" in lines
    assert "measured by differences of odometry poses" in lines


def test_a_command_topic_the_robot_file_names_but_the_bag_lacks_is_an_error_not_a_fallback(tmp_path: Path, measured, capsys):
    bag = str(measured["twist"]["bag"])
    robot = write_robot(tmp_path / "robot.yaml", robot_yaml())  # names /robot/cmd_vel, which this log lacks
    assert main(["import", bag, "--robot", str(robot), "--out", str(tmp_path / "rec")]) == 2
    _one_line(capsys, bag, "topics.command", TOPICS["command"], "is not in the bag")
    assert not (tmp_path / "rec").exists()


def test_a_model_taught_by_a_log_without_commands_commands_the_speed_driven(measured):
    from terrapref.runtime import PlannerRuntime

    scenario = resolve_scenario("demo_course")
    runtime = PlannerRuntime(measured["model"])
    runtime.set_path(scenario.waypoints)
    frame = Simulation(scenario).reset()
    decision = runtime.decide(frame.image, frame.time_s, frame.pose)
    assert decision.stop is None and decision.command.v == pytest.approx(FAST_MPS, abs=0.05)


@pytest.mark.slow  # a whole drive or export end to end, its steps tested apart in the default run
def test_colour_segmentation_through_the_label_maps_colour_table(tmp_path: Path, imported):
    from synthetic_bag import colour_label_map

    (tmp_path / "colours.yaml").write_text(colour_label_map())
    write_robot(tmp_path / "robot.yaml", robot_yaml(labels="colours.yaml"))
    bag = write_synthetic_bag(tmp_path / "rgb.mcap", "mcap", encoding="rgb8", max_seconds=SECONDS)
    report = import_bag(bag, load_robot(tmp_path / "robot.yaml"), tmp_path / "rec", show_progress=False)
    rec = read_recording(tmp_path / "rec")
    _, ids_rec = imported["mcap"]
    assert len(rec) == len(ids_rec)
    np.testing.assert_array_equal(rec.image(len(rec) // 2), ids_rec.image(len(rec) // 2))  # the same classes as from ids
    assert 0.0 < report.unmapped_share < 0.01  # the unlisted id has no colour: unknown, and counted
    write_robot(tmp_path / "robot.yaml", robot_yaml())  # rellis3d has no colour table
    with pytest.raises(UserError, match="colour table"):
        import_bag(bag, load_robot(tmp_path / "robot.yaml"), tmp_path / "rec2", show_progress=False)


def test_the_camera_mounting_from_tf_static(tmp_path: Path, logs, imported):
    robot = tmp_path / "robot.yaml"
    write_robot(robot, robot_yaml().replace("  height_m: 1.0\n  pitch_deg: 30.0\n", "  tf: base_link\n"))
    import_bag(logs["bags"]["rosbag1"], load_robot(robot), tmp_path / "rec", show_progress=False)
    rec, given = read_recording(tmp_path / "rec"), imported["rosbag1"][1]
    for key in ("mount_height_m", "mount_forward_m", "pitch_deg", "yaw_deg", "hfov_deg"):
        assert rec.meta["camera"][key] == pytest.approx(given.meta["camera"][key], abs=1e-9), key
    write_robot(robot, robot_yaml().replace("  height_m: 1.0\n  pitch_deg: 30.0\n", "  tf: chassis\n"))
    with pytest.raises(UserError, match="no static transform chain from chassis"):
        import_bag(logs["bags"]["rosbag1"], load_robot(robot), tmp_path / "rec2", show_progress=False)
    write_robot(robot, robot_yaml().replace("  pitch_deg: 30.0\n", "  tf: base_link\n"))
    with pytest.raises(UserError, match="either tf or height_m"):
        load_robot(robot)


def test_an_export_stamps_its_images_in_the_optical_frame_and_latches_its_static_transforms(tmp_path: Path, logs, imported):
    """REP 103's optical frame (z forward, x right, y down) carries the images and calibration,
    /tf_static reaches it from base_link, and the bag offers /tf_static transient-local (ROS 2)
    or latched (ROS 1), as a player needs to hand it to late subscribers."""
    from rosbags.highlevel import AnyReader
    from rosbags.interfaces import QosDurability

    from terrapref.camera import CameraConfig, PinholeCamera
    from terrapref.interop.ros_decode import camera_mount_from_tf, static_transforms

    _, rec = imported["mcap"]
    out = tmp_path / "run.mcap"
    assert main(["export", str(rec.path), "--format", "mcap", "--out", str(out)]) == 0
    with AnyReader([out]) as reader:
        conns = {c.topic: c for c in reader.connections}
        assert [q.durability for q in conns["/tf_static"].ext.offered_qos_profiles] == [QosDurability.TRANSIENT_LOCAL]
        assert conns["/tf"].ext.offered_qos_profiles == []
        assert "/terrapref/status" not in conns  # a recording: no planner's status to say
        info = reader.deserialize(next(reader.messages(connections=[conns["/terrapref/camera_info"]]))[2], "sensor_msgs/msg/CameraInfo")
        frames = {
            topic: reader.deserialize(raw, conns[topic].msgtype).header.frame_id
            for topic in ("/terrapref/labels", "/terrapref/camera_info")
            for _, _, raw in [next(reader.messages(connections=[conns[topic]]))]
        }
        static = next(reader.messages(connections=[conns["/tf_static"]]))
        tf_message = reader.deserialize(static[2], "tf2_msgs/msg/TFMessage")
    assert set(frames.values()) == {"camera_optical"}
    # K in ROS's pixel coordinates, a pixel's centre at its index: the centred camera's centre at 319.5, 239.5.
    fx, fy, cx, cy = CameraConfig.from_dict(rec.meta["camera"]).intrinsics
    assert (info.k[2], info.k[5], info.p[2], info.p[6]) == (cx - 0.5, cy - 0.5, cx - 0.5, cy - 0.5) and info.k[0] == fx
    # The optical axes, carried to base_link through the chain, are the camera model's.
    static = static_transforms(tf_message)
    assert static["camera_link"][0] == "base_link" and static["camera_optical"][0] == "camera_link"
    camera = PinholeCamera(CameraConfig.from_dict(rec.meta["camera"]))
    np.testing.assert_allclose(
        (static["camera_link"][2] @ static["camera_optical"][2]).T, camera.R, atol=1e-12
    )  # rows: right, down, forward
    mount = camera_mount_from_tf(static, "base_link", "camera_optical", str(out), [])
    assert mount["pitch_deg"] == pytest.approx(camera.config.pitch_deg) and mount["yaw_deg"] == pytest.approx(
        camera.config.yaw_deg, abs=1e-9
    )
    assert mount["height_m"] == pytest.approx(camera.config.mount_height_m) and mount["forward_m"] == pytest.approx(
        camera.config.mount_forward_m
    )
    with AnyReader([logs["bags"]["rosbag1"]]) as reader:
        assert [c.ext.latching for c in reader.connections if c.topic == "/tf_static"] == [1]


@pytest.mark.slow
def test_a_model_taught_by_an_imported_log_drives_like_one_taught_by_the_simulator_recording(tmp_path: Path):
    """One drive of teach_course, as a quirky MCAP log and as the simulator recorded it: both
    taught with the default recipe, both scored on generated layouts against the same driver."""
    import json

    write_robot(tmp_path / "robot.yaml", robot_yaml())
    bag = write_synthetic_bag(tmp_path / "teach.mcap", "mcap", scenario="teach_course", seed=0, encoding="png")
    assert main(["import", str(bag), "--robot", str(tmp_path / "robot.yaml"), "--out", str(tmp_path / "rec_bag")]) == 0
    assert main(["record", "teach_course", "--seed", "0", "--out", str(tmp_path / "rec_sim")]) == 0
    agreement = {}
    layouts = ["gen:2000", "gen:2001", "gen:2002", "gen:2003"]
    for name in ("bag", "sim"):
        model = tmp_path / f"{name}.safetensors"
        assert main(["train", str(tmp_path / f"rec_{name}"), "--out", str(model)]) == 0
        assert main(["evaluate", str(model), *layouts, "--seeds", "1", "--out", str(tmp_path / f"ev_{name}")]) == 0
        metrics = json.loads((tmp_path / f"ev_{name}" / "metrics.json").read_text())
        zones = [z for sc in metrics["scenarios"].values() for run in sc["planner"].values() for z in run["zones"] if "agrees" in z]
        agreement[name] = sum(z["agrees"] for z in zones) / len(zones)
        assert metrics["summary"]["collision_count"] == 0
    assert agreement["bag"] >= 0.8 and abs(agreement["bag"] - agreement["sim"]) <= 0.15, agreement


def _compressed(fmt: str, data: bytes):
    from types import SimpleNamespace

    return SimpleNamespace(topic="/seg", msgtype="sensor_msgs/msg/CompressedImage"), SimpleNamespace(format=fmt, data=data)


def test_a_png_that_cannot_be_decoded_names_the_log_the_topic_and_the_time(tmp_path: Path):
    from terrapref.errors import UserError
    from terrapref.interop.ros_decode import label_ids

    conn, msg = _compressed("mono8; png compressed", b"\x89PNG\r\n\x1a\n" + bytes(100))
    with pytest.raises(UserError) as err:
        label_ids(msg, conn.msgtype, conn.topic, "drive.bag", t_s=12.3)
    line = err.value.lines()[0]
    assert "drive.bag" in line and "/seg" in line and "12.300 s into the log" in line and "not a decodable png" in line


def test_compressed_depth_png_of_label_ids_is_read_and_of_depth_refused_by_name():
    import io

    from PIL import Image

    from terrapref.errors import UserError
    from terrapref.interop.ros_decode import COMPRESSED_DEPTH_HEADER, label_ids

    ids = (np.arange(12 * 16).reshape(12, 16) % 40).astype(np.uint16)
    png = io.BytesIO()
    Image.fromarray(ids).save(png, format="PNG")
    header = bytes(COMPRESSED_DEPTH_HEADER)  # format enum and two quantisation floats
    conn, msg = _compressed("16UC1; compressedDepth png", header + png.getvalue())
    np.testing.assert_array_equal(label_ids(msg, conn.msgtype, conn.topic, "drive.bag", t_s=1.0), ids)
    conn, msg = _compressed("32FC1; compressedDepth png", header + png.getvalue())
    with pytest.raises(UserError, match="compressedDepth of '32FC1' holds depth"):
        label_ids(msg, conn.msgtype, conn.topic, "drive.bag", t_s=1.0)


def test_the_sample_logs_robot_file_reads_with_the_label_map_written_beside_it(tmp_path: Path, monkeypatch, capsys):
    """docs/robot-logs.md's flow starts with examples/robot_logs.py: its robot file must import (the bags themselves are the tests')."""
    import runpy
    import sys

    import synthetic_bag

    monkeypatch.setattr(synthetic_bag, "write_synthetic_bag", lambda path, *a, **k: Path(path).mkdir())
    monkeypatch.setattr(sys, "argv", ["robot_logs.py", "--out", str(tmp_path / "logs")])
    runpy.run_path(str(REPO / "examples" / "robot_logs.py"), run_name="__main__")
    assert main(["validate", str(tmp_path / "logs" / "robot.yaml")]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == f"{tmp_path / 'logs' / 'robot.yaml'}: ok (robot file)"


def test_replay_reads_the_robots_speed_as_a_node_reads_it_from_odometry():
    """Frames 0.1 s apart driven at 1.5 m/s: 1.5 m/s from the third frame on (0.2 s of log behind
    it), none before, whichever way the robot faces or goes."""
    from terrapref.interop.replay import frame_speeds

    t = 0.1 * np.arange(8)
    for yaw, sign in ((0.0, 1.0), (2.0, 1.0), (0.5, -1.0)):
        poses = np.stack([sign * 1.5 * t * np.cos(yaw), sign * 1.5 * t * np.sin(yaw), np.full_like(t, yaw)], axis=1)
        speeds = frame_speeds(t, poses)
        assert np.isnan(speeds[:2]).all() and speeds[2:] == pytest.approx(1.5)


def test_info_of_an_imported_log_says_its_frames_are_the_robots_own(imported, capsys):
    _, rec = imported["mcap"]
    capsys.readouterr()
    assert main(["info", str(rec.path)]) == 0
    assert "perception      the robot's own (the log's label images and odometry, as imported)" in capsys.readouterr().out
