"""Crash-safe recordings (SPEC 10): round trip, refusals, cut and unfinished files, a real kill,
and the size of a five-minute demonstration."""

from __future__ import annotations

import json
import re
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pytest

from terrapref.demos.meta import (
    CorrectionRoundInfo,
    ExpertInfo,
    HumanInfo,
    ImportedInfo,
    RecordingMeta,
    RecordingSetup,
    RideAlongInfo,
    driver_from_dict,
)
from terrapref.demos.recording import FRAMES, META, Recording, RecordingWriter, read_recording
from terrapref.errors import UserError
from terrapref.features import PreferenceSetConfig
from terrapref.scenario import Scenario, resolve_scenario
from terrapref.sim import EpisodeLog, Simulation
from terrapref.terrain import PreferenceProfile

H, W = 480, 640
META_IN = {
    "scenario": "hand_made",
    "camera": {"width_px": W, "height_px": H},
    "driver": {"kind": "human", "input": "test", "disturbance": None, "seed": 0},
}
SCENARIO_IN = {"format": "terrapref-scenario/1", "name": "hand_made", "path": {"waypoints": [[0.0, 0.0], [5.0, 0.0]]}}


def _frames(n: int, seed: int = 0) -> list[tuple[float, tuple[float, float, float], np.ndarray, tuple[float, float], int]]:
    rng = np.random.default_rng(seed)
    ids = np.array([0, 1, 2, 3, 4, 255], dtype=np.uint8)
    out = []
    for i in range(n):
        pose = (float(rng.uniform(0, 50)), float(rng.uniform(0, 30)), float(rng.uniform(-np.pi, np.pi)))
        cmd = (1.0, float(rng.uniform(-1, 1)))
        out.append((0.1 * i, pose, rng.choice(ids, size=(H, W)), cmd, int(rng.integers(0, 21))))
    return out


def _write(out: Path, frames: list, close: bool = True, **kwargs) -> RecordingWriter:
    writer = RecordingWriter(out, META_IN, SCENARIO_IN, **kwargs)
    for t, pose, image, cmd, label in frames:
        writer.append(t, pose, image, cmd, label)
    if close:
        writer.close({"completed": True})
    return writer


def _assert_frames_equal(rec: Recording, frames: list) -> None:
    assert len(rec) == len(frames)
    np.testing.assert_allclose(rec.times, [f[0] for f in frames], atol=1e-6)
    np.testing.assert_array_equal(rec.poses, np.array([f[1] for f in frames]))
    np.testing.assert_array_equal(rec.commands, np.array([f[3] for f in frames]))
    np.testing.assert_array_equal(rec.labels, [f[4] for f in frames])
    for i, f in enumerate(frames):
        np.testing.assert_array_equal(rec.image(i), f[2], err_msg=f"frame {i}")


# --- round trip and refusals --------------------------------------------------------------------


def test_round_trip(tmp_path: Path):
    frames = _frames(5)
    _write(tmp_path / "rec", frames)
    rec = read_recording(tmp_path / "rec")
    _assert_frames_equal(rec, frames)
    assert rec.complete
    assert rec.meta["status"] == "complete" and rec.meta["frames"] == 5
    assert rec.meta["summary"] == {"completed": True}
    assert {k: rec.meta[k] for k in META_IN} == META_IN
    assert rec.scenario == SCENARIO_IN
    images = rec.images()
    assert images.shape == (5, H, W) and images.dtype == np.uint8


def test_frames_file_is_plain_json_lines(tmp_path: Path):
    _write(tmp_path / "rec", _frames(3))
    lines = (tmp_path / "rec" / FRAMES).read_text().splitlines()
    assert [json.loads(line)["i"] for line in lines] == [0, 1, 2]
    assert all((tmp_path / "rec" / json.loads(line)["image"]).is_file() for line in lines)


def test_existing_recording_is_refused_unless_overwrite(tmp_path: Path):
    out = tmp_path / "rec"
    _write(out, _frames(3))
    with pytest.raises(UserError) as err:
        RecordingWriter(out, META_IN, SCENARIO_IN)
    assert str(out) in str(err.value)
    assert len(read_recording(out)) == 3  # untouched
    frames = _frames(2, seed=1)
    _write(out, frames, overwrite=True)
    rec = read_recording(out)
    _assert_frames_equal(rec, frames)
    assert sorted(p.name for p in (out / "images").iterdir()) == ["000000.png", "000001.png"]


def test_partial_recording_is_also_refused_unless_overwrite(tmp_path: Path):
    out = tmp_path / "rec"
    _write(out, _frames(2), close=False)
    with pytest.raises(UserError):
        RecordingWriter(out, META_IN, SCENARIO_IN)


@pytest.mark.parametrize("overwrite", [False, True])
def test_non_empty_directory_that_is_no_recording_is_refused(tmp_path: Path, overwrite: bool):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("keep me")
    with pytest.raises(UserError) as err:
        RecordingWriter(out, META_IN, SCENARIO_IN, overwrite=overwrite)
    assert str(out) in str(err.value)
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]
    assert (out / "notes.txt").read_text() == "keep me"


def test_empty_directory_is_accepted(tmp_path: Path):
    out = tmp_path / "empty"
    out.mkdir()
    _write(out, _frames(1))
    assert read_recording(out).complete


def test_reading_something_that_is_no_recording_is_a_user_error(tmp_path: Path):
    with pytest.raises(UserError):
        read_recording(tmp_path / "missing")
    with pytest.raises(UserError):
        read_recording(tmp_path)  # a directory without meta.json


# --- cut and unfinished recordings ----------------------------------------------------------------


def test_cut_last_line_is_dropped_and_reads_as_partial(tmp_path: Path):
    out = tmp_path / "rec"
    frames = _frames(4)
    _write(out, frames)
    path = out / FRAMES
    text = path.read_text()
    last_start = text.rstrip("\n").rfind("\n") + 1
    path.write_text(text[: last_start + (len(text) - last_start) // 2])  # half of the last line
    with pytest.raises(UserError, match="a cut last line; meta.json says the complete run has 4 frames"):
        read_recording(out)  # a finished run's file cut afterwards: not taken for a shorter run
    _mark_partial(out)  # as a recorder killed before it finished leaves it
    rec = read_recording(out)
    assert not rec.complete
    _assert_frames_equal(rec, frames[:3])


def _mark_partial(folder: Path) -> None:
    """``folder``'s meta.json as a recorder killed before it finished leaves it."""
    meta = json.loads((folder / META).read_text())
    meta["status"] = "partial"
    meta.pop("frames", None)
    (folder / META).write_text(json.dumps(meta))


def test_recording_never_closed_reads_as_partial(tmp_path: Path):
    out = tmp_path / "rec"
    frames = _frames(3)
    writer = _write(out, frames, close=False)
    rec = read_recording(out)  # while the writer is still open
    assert not rec.complete and rec.meta["status"] == "partial"
    _assert_frames_equal(rec, frames)
    writer.abort()
    assert not read_recording(out).complete


def test_exception_inside_the_writer_context_leaves_it_partial(tmp_path: Path):
    out = tmp_path / "rec"
    frames = _frames(2)
    with pytest.raises(RuntimeError):
        with RecordingWriter(out, META_IN, SCENARIO_IN) as writer:
            for t, pose, image, cmd, label in frames:
                writer.append(t, pose, image, cmd, label)
            raise RuntimeError("driver crashed")
    rec = read_recording(out)
    assert not rec.complete
    _assert_frames_equal(rec, frames)


def test_broken_line_in_the_middle_is_a_user_error_naming_it(tmp_path: Path):
    out = tmp_path / "rec"
    _write(out, _frames(3))
    lines = (out / FRAMES).read_text().splitlines(keepends=True)
    lines[1] = "{not json\n"
    (out / FRAMES).write_text("".join(lines))
    with pytest.raises(UserError) as err:
        read_recording(out)
    assert "line 2" in str(err.value) and FRAMES in str(err.value)


CRASH_CHILD = """
import sys
import numpy as np
from terrapref.demos.expert import ExpertDriver
from terrapref.demos.recording import RecordingWriter
from terrapref.demos.meta import ExpertInfo, RecordingMeta, RecordingSetup
from terrapref.demos.session import RunSettings, record_run
from terrapref.features import PreferenceSetConfig
from terrapref.scenario import resolve_scenario
from terrapref.sim import Simulation
from terrapref.terrain import PreferenceProfile

scenario = resolve_scenario("demo_course")
sim = Simulation(scenario)
driver = ExpertDriver()
preference = PreferenceSetConfig()
meta = RecordingMeta.driven(scenario, RecordingSetup(sim.camera.config, preference, sim.config), ExpertInfo.of(0, "default", driver.config), PreferenceProfile.default())
writer = RecordingWriter(sys.argv[1], meta, scenario.to_dict())
record_run(sim, driver, writer, RunSettings(preference), np.random.default_rng(0))
"""


def test_recording_survives_sigkill(tmp_path: Path):
    out = tmp_path / "rec"
    frames_path = out / FRAMES
    with open(tmp_path / "child.log", "wb") as log:
        child = subprocess.Popen([sys.executable, "-c", CRASH_CHILD, str(out)], stdout=log, stderr=subprocess.STDOUT)
        try:
            # Wait (no time limit: the child either writes 30 frames or exits) until 30 lines are out.
            while not (frames_path.exists() and frames_path.read_bytes().count(b"\n") >= 30):
                if child.poll() is not None:
                    pytest.fail(f"the recorder exited ({child.returncode}) before 30 frames: {(tmp_path / 'child.log').read_text()}")
                time.sleep(0.002)
            child.send_signal(signal.SIGKILL)
        finally:
            child.kill()
            child.wait()
    assert child.returncode == -signal.SIGKILL, "the recorder finished before it could be killed"
    rec = read_recording(out)
    assert len(rec) >= 30
    assert not rec.complete and rec.meta["status"] == "partial"
    for i in range(len(rec)):
        image = rec.image(i)
        assert image.shape == (H, W) and image.dtype == np.uint8
    np.testing.assert_allclose(rec.times, 0.1 * np.arange(len(rec)), atol=1e-6)
    assert rec.meta["scenario"] == "demo_course"


# --- a full recording made by the session loop -------------------------------------------------


@dataclass
class FullRecording:
    scenario: Scenario
    sim: Simulation
    log: EpisodeLog
    rec: Recording


@pytest.fixture(scope="module")
def demo_recording(demo_course_drive) -> FullRecording:
    """The synthetic driver's drive of demo_course through the session loop (tests/conftest.py)."""
    drive = demo_course_drive
    return FullRecording(drive.scenario, drive.sim, drive.log, read_recording(drive.path))


def test_recorded_run_matches_the_episode(demo_recording: FullRecording):
    log, rec, sim = demo_recording.log, demo_recording.rec, demo_recording.sim
    assert log.completed and rec.complete
    assert len(rec) == len(log.commands) == rec.meta["frames"]
    np.testing.assert_array_equal(rec.poses, log.trace[:: sim.config.ticks_per_frame][: len(rec)])
    np.testing.assert_array_equal(rec.commands, log.commands)
    np.testing.assert_array_equal(rec.labels, PreferenceSetConfig().control.label_of(rec.commands[:, 1]))
    np.testing.assert_array_equal(rec.image(0), Simulation(demo_recording.scenario).reset().image)


def test_recording_carries_what_featurising_again_needs(demo_recording: FullRecording):
    meta, scenario = demo_recording.rec.meta, demo_recording.scenario
    assert PreferenceSetConfig.from_dict(meta["preference_set"]) == PreferenceSetConfig()
    assert meta["camera"] == demo_recording.sim.camera.config.to_dict()
    assert np.array_equal(np.array(meta["path"]), scenario.waypoints)
    assert meta["profile"] == list(PreferenceProfile.default().order)
    assert demo_recording.rec.scenario == scenario.to_dict()


def test_five_minutes_fit_in_100_mb(demo_recording: FullRecording):
    rec = demo_recording.rec
    total = sum(p.stat().st_size for p in rec.path.rglob("*") if p.is_file())
    per_frame = total / len(rec)
    estimate = per_frame * 3000  # 5 minutes at 10 Hz
    assert estimate < 100e6, f"{per_frame / 1e3:.1f} kB per frame: 5 minutes (3000 frames) ~ {estimate / 1e6:.1f} MB"
    assert (rec.path / META).is_file()


@pytest.mark.slow  # a whole drive or export end to end, its steps tested apart in the default run
def test_inspect_tells_what_the_drive_shows_of_the_preference(demo_recording: FullRecording, tmp_path: Path, capsys):
    from terrapref.cli import main

    rec = demo_recording.rec
    assert main(["inspect", str(rec.path), "--out", str(tmp_path / "a.png")]) == 0
    out = capsys.readouterr().out
    assert f"what the drive shows (recipe teach's features, {len(rec)} frames):" in out
    learned = next(line for line in out.splitlines() if "learned order:" in line)
    assert learned.split(": ", 1)[1].split(" > ")[0] == "grass"  # the driver keeps to grass where it can
    # demo_course never puts rock beside water: that pair is a guess, and the report says so
    assert re.search(r"warning: (rock vs water|water vs rock): never compared; the planner's choice between them is a guess", out)
    assert re.search(r"mud > rock: margin [0-9.]+, standard error [0-9.]+, compared in [1-9][0-9]* frames", out)
    assert main(["inspect", str(rec.path), "--out", str(tmp_path / "b.png"), "--no-preference"]) == 0
    assert "what the drive shows" not in capsys.readouterr().out


def test_force_keeps_the_old_recording_until_the_new_one_is_complete(tmp_path: Path):
    from terrapref.demos.recording import RecordingWriter, read_recording

    out = tmp_path / "rec"
    first = RecordingWriter(out, {"scenario": "a"}, {"name": "a"})
    first.append(0.0, (1.0, 2.0, 0.0), np.zeros((4, 4), np.uint8), (1.0, 0.0), 10)
    first.close()
    # A replacement that ends early: the old recording is untouched, the new one is kept beside it.
    second = RecordingWriter(out, {"scenario": "b"}, {"name": "b"}, overwrite=True)
    for i in range(3):
        second.append(0.1 * i, (0.0, 0.0, 0.0), np.ones((4, 4), np.uint8), (1.0, 0.1), 11)
    second.abort()
    old = read_recording(out)
    assert old.complete and len(old) == 1 and old.meta["scenario"] == "a"
    partial = read_recording(second.partial_dir)
    assert second.partial_dir == tmp_path / "rec.partial" and not partial.complete and len(partial) == 3
    # A replacement that finishes is swapped in whole, with nothing left beside it.
    third = RecordingWriter(out, {"scenario": "c"}, {"name": "c"}, overwrite=True)
    third.append(0.0, (0.0, 0.0, 0.0), np.ones((4, 4), np.uint8), (1.0, 0.0), 10)
    assert read_recording(out).meta["scenario"] == "a"  # still the old one while the new one is written
    third.close()
    new = read_recording(out)
    assert new.complete and new.meta["scenario"] == "c" and len(new) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec", "rec.partial"]
    # Another that ends early is kept beside the first one, which it never replaces.
    fourth = RecordingWriter(out, {"scenario": "d"}, {"name": "d"}, overwrite=True)
    fourth.append(0.0, (0.0, 0.0, 0.0), np.ones((4, 4), np.uint8), (1.0, 0.0), 10)
    fourth.abort()
    assert fourth.partial_dir == tmp_path / "rec.partial-2" and len(read_recording(tmp_path / "rec.partial")) == 3


def test_a_replacement_killed_outright_is_kept_as_a_partial_recording(tmp_path, capsys):
    """`kill -9` of `record --force` or `drive --record --force` leaves its frames in a hidden
    folder; the next command that writes beside it keeps them as OUT.partial, as a stopped
    recording's are (they used to be removed: a person's driving among them)."""
    from terrapref.demos.recording import RecordingWriter, read_recording
    from terrapref.fileio import check_output

    out = tmp_path / "rec"
    first = RecordingWriter(out, {"scenario": "a"}, {"name": "a"})
    first.append(0.0, (1.0, 2.0, 0.0), np.zeros((4, 4), np.uint8), (1.0, 0.0), 10)
    first.close()
    killed = (
        "import os, sys, numpy as np; from terrapref.demos.recording import RecordingWriter\n"
        f"w = RecordingWriter({str(out)!r}, {{'scenario': 'b'}}, {{'name': 'b'}}, overwrite=True)\n"
        "for i in range(3): w.append(0.1 * i, (0.0, 0.0, 0.0), np.ones((4, 4), np.uint8), (1.0, 0.1), 11)\n"
        "os._exit(9)  # killed: nothing of its own clean-up runs\n"
    )
    assert subprocess.run([sys.executable, "-c", killed]).returncode == 9
    assert any(p.name.startswith(".rec.") for p in tmp_path.iterdir())
    check_output(tmp_path / "other.safetensors", "--out")  # any command writing beside it
    assert f"note: {out}: kept what a stopped command left unfinished as {out}.partial" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec", "rec.partial"]
    kept = read_recording(tmp_path / "rec.partial")
    assert not kept.complete and len(kept) == 3 and read_recording(out).meta["scenario"] == "a"
    assert [p.name for p in (tmp_path / "rec.partial").iterdir() if p.name.startswith(".")] == []  # a plain recording


def test_inspect_says_quit_and_not_reached(tmp_path: Path):
    from terrapref.camera import CameraConfig
    from terrapref.features import PreferenceSetConfig
    from terrapref.report.inspect import summarise
    from terrapref.sim import SimConfig, Simulation
    from terrapref.terrain import PreferenceProfile

    scenario = resolve_scenario("demo_course")
    meta = RecordingMeta.driven(
        scenario, RecordingSetup(CameraConfig(), PreferenceSetConfig(), SimConfig()), HumanInfo("keyboard"), PreferenceProfile.default()
    )
    writer = RecordingWriter(tmp_path / "rec", meta, scenario.to_dict())
    sim = Simulation(scenario)
    frame = sim.reset()
    for _ in range(20):  # 2 m: the person pressed Esc long before the first zone
        writer.append(frame.time_s, frame.pose, frame.image, (1.0, 0.0), 10)
        frame = sim.step((1.0, 0.0))
    writer.close({"completed": False, "quit": True, "tips": 0, "stuck": 23, "max_roll_deg": 0.0, "max_pitch_deg": 26.57})
    summary = summarise(read_recording(tmp_path / "rec"))
    lines = summary.lines()
    assert lines[0].endswith("quit by the driver")
    # How the drive ended, on relief with its tips, times stuck and attitude (inspect said "complete" alone).
    assert "drive      did not reach the goal; 0 tips, 23 times stuck; roll at most 0.0 deg, pitch 26.6 deg" in lines
    assert (
        lines.index("scenario   demo_course")
        == lines.index("drive      did not reach the goal; 0 tips, 23 times stuck; roll at most 0.0 deg, pitch 26.6 deg") + 1
    )
    zone_lines = [line for line in lines if line.endswith("not reached")]
    assert zone_lines and all(" -> -" in line for line in zone_lines)
    # A long label (a triple of long class names) keeps the table in line: every arrow in one column.
    long = replace(summary.zones[0][0], label="non_traversable | water | non_traversable", choice="water", success=True)
    lines = replace(summary, zones=[(long, True), *summary.zones]).lines()
    table = lines[lines.index("zones      (id, label: expected -> choice)") + 1 : -1]
    assert len(table) == len(summary.zones) + 1 and len({line.index(" -> ") for line in table}) == 1


def _record_terminated(out: Path, ready: Callable[[], bool], *flags: str) -> tuple[int, str]:
    """``terrapref record demo_course --out OUT FLAGS`` in a fresh interpreter, sent SIGTERM once
    ``ready()`` (no time limit: the recorder gets there or exits, which fails the test); its exit
    code and its stderr."""
    command = [sys.executable, "-c", "import sys; from terrapref.cli import main; sys.exit(main())", "record", "demo_course"]
    child = subprocess.Popen([*command, "--out", str(out), *flags, "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        while not ready():
            if child.poll() is not None:
                pytest.fail(f"the recorder exited ({child.returncode}) before it was ready: {child.stderr.read()}")
            time.sleep(0.005)
        child.send_signal(signal.SIGTERM)
        _, err = child.communicate()
    finally:
        child.kill()
        child.wait()
    return child.returncode, err


def test_sigterm_during_record_force_says_so_and_keeps_the_old_recording(tmp_path, tiny_recording):
    # As after Ctrl-C: the old recording stays as it was, the unfinished one is OUT.partial (not
    # a hidden folder beside it), and the command says it was terminated.

    out = shutil.copytree(tiny_recording, tmp_path / "rec")
    before = (out / "frames.jsonl").read_bytes()

    def twenty_new_frames() -> bool:  # the replacement's, in its hidden folder
        return any(p.name.endswith(".new") and len(list((p / "images").glob("*.png"))) >= 20 for p in tmp_path.iterdir())

    code, err = _record_terminated(out, twenty_new_frames, "--force")
    assert code == 143 and "terminated" in err and "Traceback" not in err, err
    assert (out / "frames.jsonl").read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rec", "rec.partial"]
    assert read_recording(tmp_path / "rec.partial").complete is False


def test_a_first_recording_stopped_says_where_its_frames_are(tmp_path):
    """Stopped (SIGTERM, as Ctrl-C), a first recording keeps its frames at OUT, marked partial,
    and says so: it said only "terminated"."""
    out = tmp_path / "rec"
    frames = out / "frames.jsonl"  # an image is written before its line: 20 lines are 20 frames
    code, err = _record_terminated(out, lambda: frames.is_file() and frames.read_text().count("\n") >= 20)
    kept = read_recording(out)
    assert code == 143 and not kept.complete and len(kept) >= 20
    assert re.search(rf"note: {re.escape(str(out))} keeps the \d+ frames recorded before it was stopped \(partial\)", err), err


def test_a_run_stopped_before_its_first_frame_leaves_no_recording(tmp_path):
    out = tmp_path / "rec"
    writer = RecordingWriter(out, {"camera": {}}, {"format": "terrapref-scenario/1"})
    writer.abort()
    assert not out.exists()


# --- the typed meta.json (terrapref.demos.meta) ----------------------------------------------------------

DRIVERS = [
    ExpertInfo(3, "wide", {"reaction_distance_m": 5.0}, {"rate_hz": 0.15}),
    HumanInfo("keyboard/mouse/gamepad", None, 0),
    RideAlongInfo("keyboard/mouse/gamepad", {"rate_hz": 1.0}, 2, "model.safetensors"),
    CorrectionRoundInfo(1, 7),
    ImportedInfo("drive.mcap", "robot.yaml", "rellis"),
]


@pytest.mark.parametrize("driver", DRIVERS, ids=lambda d: type(d).__name__)
def test_every_kind_of_driver_reads_back_as_written(driver):
    data = json.loads(json.dumps(driver.to_dict()))
    assert next(iter(data)) == "kind"
    assert driver_from_dict(data, "meta.json") == driver


def test_the_meta_reads_back_as_written_with_its_keys_in_the_files_order(demo_recording: FullRecording):
    meta = demo_recording.rec.header
    entries = {
        k: v for k, v in demo_recording.rec.meta.items() if k not in ("format", "status", "created", "frames", "summary", "finished")
    }
    assert json.dumps(meta.to_dict()) == json.dumps(entries)
    assert RecordingMeta.from_dict(meta.to_dict(), "meta.json") == meta
    assert list(entries) == ["scenario", "camera", "preference_set", "sim", "classes", "profile", "driver", "path", "perception"]


@pytest.mark.parametrize(
    ("key", "value", "field", "message"),
    [
        ("driver", {"kind": "robot"}, "driver.kind", "unknown driver kind 'robot'; driver kinds: expert, human, corrections, imported"),
        ("driver", {"kind": "expert", "seed": "3"}, "driver.seed", "expected an integer, got str"),
        ("driver", [1], "driver", "expected a mapping, got list"),
        ("sim", {"camera_rate_hz": 0}, "sim.camera_rate_hz", "expected a frame rate > 0 [Hz]"),
        ("sim", {"camera_rate_hz": 10.0, "vehicle": {"wheels": 4}}, "sim.vehicle", "invalid (TypeError"),
        ("origin_shift_m", [1.0], "origin_shift_m", "expected two finite numbers [m]"),
        ("path", [[12.0, 12.0], [12.0, 12.0], [12.0, 12.0]], "path", "expected at least two distinct [x, y] points"),
    ],
)
def test_a_wrong_meta_entry_is_one_line_naming_the_file_and_field(tmp_path: Path, key, value, field, message):
    rec = tmp_path / "rec"
    with RecordingWriter(rec, {**META_IN, key: value}, {}) as w:
        w.append(0.0, (1.0, 2.0, 0.0), np.zeros((4, 4), np.uint8), (1.0, 0.0), 10)
        w.close()
    with pytest.raises(UserError) as err:
        read_recording(rec)
    assert len(err.value.lines()) == 1 and err.value.problems[0].field == field and message in err.value.problems[0].message
    assert err.value.source.endswith("meta.json")


def _written(tmp_path: Path) -> Path:
    rec = tmp_path / "rec"
    with RecordingWriter(rec, META_IN, {}) as w:
        for i in range(3):
            w.append(0.1 * i, (1.0 + 0.1 * i, 2.0, 0.0), np.zeros((4, 4), np.uint8), (1.0, 0.0), 10)
        w.close()
    return rec


@pytest.mark.parametrize(
    ("edit", "said"),
    [
        (lambda text: text[:-1] + ', "deep": ' + "[" * 5000 + "]" * 5000 + "}", "not JSON that can be read (maximum recursion depth"),
        (lambda text: text[:-1] + ', "seed": 1' + "0" * 5000 + "}", "not JSON that can be read (an integer of thousands of digits)"),
        (lambda text: text[:-1] + ', "format": "terrapref-recording/1"}', "names 'format' twice in one mapping"),
    ],
    ids=["nested-deep", "huge-integer", "key-twice"],
)
def test_a_meta_json_the_reader_cannot_take_is_one_line_naming_it(tmp_path: Path, edit, said: str):
    rec = _written(tmp_path)
    meta = rec / "meta.json"
    meta.write_text(edit(meta.read_text().rstrip()))
    with pytest.raises(UserError) as err:
        read_recording(rec)
    assert len(err.value.lines()) == 1 and err.value.source == str(meta) and said in err.value.lines()[0]


def test_a_frame_line_of_a_huge_integer_or_nested_past_the_parser_is_a_malformed_line(tmp_path: Path):
    rec = _written(tmp_path)
    frames = rec / FRAMES
    lines = frames.read_text().splitlines()
    for bad in ('{"t": 1' + "0" * 5000 + "}", "[" * 5000 + "]" * 5000):
        frames.write_text("\n".join([lines[0], bad, *lines[2:]]) + "\n")
        with pytest.raises(UserError, match="line 2 is not a frame record"):
            read_recording(rec)


def test_a_class_id_image_past_pillows_pixel_limit_is_refused_before_it_is_decoded(tmp_path: Path, monkeypatch):
    from PIL import Image

    rec = _written(tmp_path)
    read_recording(rec).image(0)
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 4)  # the 4 x 4 frames, past twice a limit of 4 pixels: a bomb
    with pytest.raises(UserError, match="exceeds limit"):
        read_recording(rec).image(0)


def test_a_summary_that_is_not_counts_is_refused_where_it_is_read(tmp_path: Path):
    """``inspect`` and ``train`` say what a drive touched from its summary; "abc" seconds there
    was an internal error."""
    rec = _written(tmp_path)
    meta = json.loads((rec / "meta.json").read_text())
    meta["summary"] = {**meta.get("summary", {}), "collisions": 1, "contact_s": "abc"}
    (rec / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(UserError) as err:
        read_recording(rec).lethal_contact()
    assert err.value.lines() == [f"{rec / 'meta.json'}: summary.contact_s: expected a number >= 0, got string 'abc'"]


def test_inspect_reads_a_recording_without_its_preference_set_as_train_does(demo_recording: FullRecording, tmp_path: Path):
    from terrapref.report.inspect import summarise

    copy = tmp_path / "rec"
    shutil.copytree(demo_recording.rec.path, copy)
    meta = json.loads((copy / "meta.json").read_text())
    del meta["preference_set"]
    (copy / "meta.json").write_text(json.dumps(meta))
    assert summarise(read_recording(copy)).frames == len(demo_recording.rec)  # the default control set, as train takes it


def test_the_meta_module_examples_run():
    import doctest

    import terrapref.demos.meta

    assert doctest.testmod(terrapref.demos.meta, verbose=False).failed == 0


# --- depth images (relief) ------------------------------------------------------------------------


DROP = object()  # an entry taken out of a frame record


def _lines(rec: Path) -> list[dict]:
    return [json.loads(line) for line in (rec / FRAMES).read_text().splitlines()]


def test_a_relief_frames_depth_is_stored_to_the_millimetre_with_the_bodys_attitude(relief_recording: Path):
    from terrapref.camera import CameraConfig, PinholeCamera, SegmentationRenderer
    from terrapref.scenario import parse_scenario
    from terrapref.world import rasterise

    rec = read_recording(relief_recording)
    lines = _lines(relief_recording)
    assert rec.has_depth and all(line["depth"] == f"depth/{line['i']:06d}.png" and len(line["attitude"]) == 3 for line in lines)
    assert np.abs(rec.attitudes[:, 1]).max() > 0.05  # the mound pitches the body
    scenario = parse_scenario(rec.scenario, "scenario.yaml", rec.classes, driven=True)
    renderer = SegmentationRenderer(PinholeCamera(CameraConfig.from_dict(rec.meta["camera"])), rasterise(scenario))
    for i in (0, len(rec) // 2, len(rec) - 1):
        ids, depth = renderer.render_with_depth(tuple(rec.poses[i]), rec.attitude(i))
        stored = rec.depth(i)
        assert stored.dtype == np.float32 and np.array_equal(np.isnan(stored), np.isnan(depth)) and np.isnan(depth).any()
        assert np.nanmax(np.abs(stored - depth)) <= 0.001  # whole millimetres
        np.testing.assert_array_equal(rec.image(i), ids)
        view = rec.view(i)
        assert view.carries_depth and view.attitude == rec.attitude(i) and view.depth is not None


def test_a_flat_recording_holds_no_depth_and_reads_as_before(tiny_recording: Path):
    from terrapref.vehicle.ground import LEVEL

    rec = read_recording(tiny_recording)
    assert not (tiny_recording / "depth").exists()
    assert all(set(line) == {"i", "t", "pose", "cmd", "label", "image"} for line in _lines(tiny_recording))
    assert not rec.has_depth and rec.depth_files == () and rec.attitudes is None
    assert rec.depth(0) is None and rec.attitude(0) == LEVEL and not rec.view(0).carries_depth


def test_a_relief_recording_made_before_depth_was_kept_reads_level_and_its_depth_changes_only_the_ground_maps(
    tmp_path: Path, relief_recording: Path
):
    from terrapref.dataset import build_dataset
    from terrapref.recipes import DEFAULT_RECIPE, recipe_named, rules_with

    old = tmp_path / "old"
    shutil.copytree(relief_recording, old)
    shutil.rmtree(old / "depth")
    lines = [{k: v for k, v in line.items() if k not in ("depth", "attitude")} for line in _lines(old)]
    (old / FRAMES).write_text("".join(json.dumps(line) + "\n" for line in lines))
    before, now = read_recording(old), read_recording(relief_recording)
    assert not before.has_depth and before.attitudes is None and before.complete
    recipe = recipe_named(DEFAULT_RECIPE)
    a, b = (build_dataset([r], recipe.features(), rules=rules_with(recipe)) for r in (before, now))
    np.testing.assert_array_equal(a.U, b.U)  # C's features read the image's pixels: depth does not change them
    np.testing.assert_array_equal(a.rules["second_stage"]["U2"], b.rules["second_stage"]["U2"])
    assert not np.array_equal(a.rules["offset"]["features"], b.rules["offset"]["features"])  # the ground maps place what depth shows


def test_a_missing_depth_image_is_named_and_at_the_end_is_a_cut_frame(tmp_path: Path, relief_recording: Path):
    rec = tmp_path / "rec"
    shutil.copytree(relief_recording, rec)
    n = len(_lines(rec))
    (rec / "depth" / f"{n - 1:06d}.png").unlink()  # killed between the depth image and its line
    _mark_partial(rec)
    cut = read_recording(rec)
    assert len(cut) == n - 1 and not cut.complete
    (rec / "depth" / "000003.png").unlink()
    with pytest.raises(UserError) as err:
        read_recording(rec)
    assert err.value.problems[0].field == "line 4.depth" and "depth/000003.png is missing" in err.value.problems[0].message


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("depth", "images/000001.png", "expected a file name under depth/"),
        ("depth", "depth/../meta.json", "expected a file name under depth/"),
        ("attitude", [0.0, 0.1], "expected 3 finite numbers"),
        ("attitude", [0.0, None, 0.1], "expected 3 finite numbers"),
        ("attitude", [0.0, 100.0, 0.0], "expected each within +-pi/2"),
        ("attitude", [0.0, 0.0, -1.6], "expected each within +-pi/2"),
        ("attitude", [1e9, 0.0, 0.0], "expected a height z within +-1e+07 m, got 1e+09"),
        ("cmd", [1e9, 0.5], "expected a speed within +-50 m/s and a yaw rate within +-1e+06 rad/s"),
        ("cmd", [1.0, 1e300], "expected a speed within +-50 m/s and a yaw rate within +-1e+06 rad/s"),
        ("attitude", DROP, "missing: a frame on relief carries its depth image and its attitude together"),
        ("depth", DROP, "missing: a frame on relief carries its depth image and its attitude together"),
        (("depth", "attitude"), DROP, "has no depth image where the frame before it had one"),
    ],
)
def test_a_wrong_depth_or_attitude_entry_is_one_line_naming_the_field(tmp_path: Path, relief_recording: Path, key, value, message):
    rec = tmp_path / "rec"
    shutil.copytree(relief_recording, rec)
    lines = _lines(rec)
    for k in key if isinstance(key, tuple) else (key,):
        if value is DROP:
            del lines[1][k]
        else:
            lines[1][k] = value
    key = key[0] if isinstance(key, tuple) else key
    (rec / FRAMES).write_text("".join(json.dumps(line) + "\n" for line in lines))
    with pytest.raises(UserError) as err:
        read_recording(rec)
    assert len(err.value.lines()) == 1 and err.value.problems[0].field == f"line 2.{key}" and message in err.value.problems[0].message


def test_a_relief_recording_whose_frames_all_lost_their_attitude_is_refused_at_its_first_line(tmp_path: Path, relief_recording: Path):
    # Kept, the depth images would be placed in the ground maps as seen from a level body: each
    # relief frame's attitude is what places them.
    rec = tmp_path / "rec"
    shutil.copytree(relief_recording, rec)
    lines = [{k: v for k, v in line.items() if k != "attitude"} for line in _lines(rec)]
    (rec / FRAMES).write_text("".join(json.dumps(line) + "\n" for line in lines))
    with pytest.raises(UserError) as err:
        read_recording(rec)
    assert err.value.lines() == [
        f"{rec / FRAMES}: line 1.attitude: missing: a frame on relief carries its depth image and its attitude together"
    ]


def test_a_depth_file_that_is_not_16_bit_millimetres_is_named_when_read(tmp_path: Path, relief_recording: Path):
    from terrapref.pngio import write_png_atomic

    rec = tmp_path / "rec"
    shutil.copytree(relief_recording, rec)
    write_png_atomic(rec / "depth" / "000002.png", np.zeros((H, W), np.uint8))
    with pytest.raises(UserError) as err:
        read_recording(rec).depth(2)
    assert err.value.source == str(rec / "depth" / "000002.png") and "16-bit depth PNG" in err.value.lines()[0]


def test_a_relief_drive_kept_in_memory_featurises_as_written(tmp_path: Path):
    from helpers import TINY_RELIEF
    from terrapref.dataset import build_dataset
    from terrapref.demos.expert import ExpertDriver
    from terrapref.demos.recording import MemoryRecordingWriter
    from terrapref.demos.session import DriveSetup, RunSettings, record_run
    from terrapref.recipes import DEFAULT_RECIPE, recipe_named, rules_with
    from terrapref.scenario import load_scenario

    setup = DriveSetup.of(load_scenario(TINY_RELIEF))
    setup = replace(setup, sim=replace(setup.sim, time_limit_s=2.5))  # up onto the mound, no further
    meta = setup.meta(ExpertInfo.of(0, "default", ExpertDriver().config), PreferenceProfile.default())
    kept = MemoryRecordingWriter(tmp_path / "mem", meta, setup.scenario.to_dict())
    written = RecordingWriter(tmp_path / "disk", meta, setup.scenario.to_dict())
    for writer in (kept, written):
        record_run(setup.simulation(), ExpertDriver(), writer, RunSettings(setup.preference), np.random.default_rng(0))
    a, b = kept.recording(), read_recording(tmp_path / "disk")
    assert a.has_depth and b.has_depth and len(a) == len(b) == 25
    i = len(a) - 1
    np.testing.assert_array_equal(a.depth(i), b.depth(i))  # the memory's depth as the file holds it: whole millimetres
    assert a.attitude(i) == b.attitude(i) and abs(a.attitude(i).pitch_rad) > 0.05
    # Kept as the files keep them: a byte of class id and two of millimetres a pixel (a float32 depth image had made a
    # relief drive of 4,000 frames 6 GB in memory).
    h, w = a.views[0].shape
    assert sum(v.image.nbytes for v in a.views) + sum(d.nbytes for d in a.kept_depths) == len(a) * h * w * 3
    recipe = recipe_named(DEFAULT_RECIPE)
    assert build_dataset([a], recipe.features(), rules=rules_with(recipe)).fingerprint == (
        build_dataset([b], recipe.features(), rules=rules_with(recipe)).fingerprint
    )


def test_inspect_of_a_file_says_it_is_not_a_recording_and_where_a_model_goes(tmp_path: Path, capsys):
    """A model file handed to `inspect` (which reads recordings) is refused in one line that says
    what a recording is and that `info` shows a model; a missing folder is said to be missing."""
    from helpers import linear_model, one_line_error
    from terrapref.cli import main

    model = linear_model(tmp_path / "m.safetensors")
    assert main(["inspect", str(model)]) == 2
    one_line_error(capsys, "m.safetensors", "a file, not a recording")
    assert main(["inspect", str(tmp_path / "nothing")]) == 2
    one_line_error(capsys, "nothing", "no such recording directory")


@pytest.mark.parametrize("declared", ["many", -1, 2.5, True])
def test_a_complete_recordings_frame_count_that_is_not_a_count_is_refused(tmp_path: Path, declared):
    """A count meta.json cannot mean turned the check of a finished run's frames off."""
    out = tmp_path / "rec"
    _write(out, _frames(3))
    meta = json.loads((out / META).read_text())
    (out / META).write_text(json.dumps({**meta, "frames": declared}))
    with pytest.raises(UserError, match="expected the number of frames") as err:
        read_recording(out)
    assert err.value.problems[0].field == "frames" and err.value.source.endswith(META)


@pytest.mark.parametrize(
    ("status", "said"),
    [("weird", "expected 'partial' or 'complete', got string 'weird'"), (None, "missing; expected 'partial' or 'complete'")],
    ids=["unknown", "missing"],
)
def test_a_status_neither_partial_nor_complete_is_refused_naming_it(tmp_path: Path, tiny_recording: Path, capsys, status, said: str):
    """A finished run edited to some other status was read as a partial one, which skips the check
    that a finished run holds all its frames; it is refused, and nothing is written."""
    from helpers import one_line_error
    from terrapref.cli import main

    rec = tmp_path / "copy"
    shutil.copytree(tiny_recording, rec)
    meta = {k: v for k, v in json.loads((rec / META).read_text()).items() if k != "status"}
    (rec / META).write_text(json.dumps(meta | ({"status": status} if status is not None else {})))
    out = tmp_path / "d.safetensors"
    assert main(["featurize", str(rec), "--out", str(out)]) == 2
    assert one_line_error(capsys) == f"error: {rec / META}: status: {said}"
    assert not out.exists()


@pytest.mark.parametrize(
    ("line", "index", "said"),
    [
        (51, 49, "line 51.i: frame index 49 does not follow the previous frame's 49; each frame has its own index, in order"),
        (60, 12, "line 60.i: frame index 12 does not follow the previous frame's 58; each frame has its own index, in order"),
        (2, "1", "line 2.i: expected the frame's index, an integer >= 0, got string '1'"),
    ],
    ids=["repeats-the-previous", "repeats-an-earlier", "not-an-integer"],
)
def test_a_frame_index_out_of_order_or_not_a_number_is_refused_naming_the_line(
    tmp_path: Path, tiny_recording: Path, capsys, line, index, said
):
    """frames.jsonl numbers its frames in order; a line repeating an earlier index is an edit or
    two recordings run together, refused as a time out of order is. Frames without an index (a
    recording another tool wrote) read as before."""
    from helpers import one_line_error
    from terrapref.cli import main

    rec = tmp_path / "copy"
    shutil.copytree(tiny_recording, rec)
    lines = _lines(rec)
    (rec / FRAMES).write_text("".join(json.dumps({k: v for k, v in row.items() if k != "i"}) + "\n" for row in lines))
    assert len(read_recording(rec)) == len(lines)
    lines[line - 1]["i"] = index
    (rec / FRAMES).write_text("".join(json.dumps(row) + "\n" for row in lines))
    out = tmp_path / "d.safetensors"
    assert main(["featurize", str(rec), "--out", str(out)]) == 2
    assert one_line_error(capsys) == f"error: {rec / FRAMES}: {said}"
    assert not out.exists()


def test_a_camera_number_written_as_text_is_named_field_by_field(tmp_path: Path):
    """meta.json's camera.width_px as "640": named, not a comparison's TypeError about camera."""
    out = tmp_path / "rec"
    _write(out, _frames(2))
    meta = json.loads((out / META).read_text())
    meta["camera"]["width_px"] = "640"
    (out / META).write_text(json.dumps(meta))
    with pytest.raises(UserError) as err:
        read_recording(out).camera  # noqa: B018
    problem = err.value.problems[0]
    assert problem.field == "camera.width_px" and problem.message == "expected a number, got string '640'"
