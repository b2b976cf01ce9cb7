"""The teleop window driven headless: SDL's dummy video driver and scripted key events."""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("SDL_AUDIODRIVER", "dummy")

import pytest

pygame = pytest.importorskip("pygame")

from helpers import REPO  # noqa: E402
from terrapref.demos.recording import read_recording  # noqa: E402
from terrapref.errors import UserError  # noqa: E402
from terrapref.teleop import COUNTDOWN_S, run_teleop  # noqa: E402
from terrapref.vehicle import ControlSet  # noqa: E402

CENTRE = 10  # index of w = 0 in the default control set


def key(kind: int, k: int) -> pygame.event.Event:
    return pygame.event.Event(kind, key=k, mod=0, unicode="", scancode=0)


def script_from(events: dict[int, list]) -> callable:
    return lambda state: events.get(state.index, [])


def ride_along(out, model, events: dict[int, list], **options):
    """A ride-along run of ``model`` with ``events`` by frame (200 frames at most); its result, and
    who drove and the stick's w as seen before each frame."""
    drivers: list[str] = []
    stick: list[float] = []

    def script(state):
        drivers.append(state.driver)
        stick.append(state.w)
        return events.get(state.index, [])

    result = run_teleop("demo_course", out, realtime=False, wait_for_start=False, script=script, max_frames=200, model=model, **options)
    return result, drivers, stick


def test_left_then_release_then_right_is_recorded_and_labelled(tmp_path):
    out = tmp_path / "rec"
    events = {
        5: [key(pygame.KEYDOWN, pygame.K_LEFT)],
        15: [key(pygame.KEYUP, pygame.K_LEFT)],
        20: [key(pygame.KEYDOWN, pygame.K_DOWN)],
        25: [key(pygame.KEYDOWN, pygame.K_RIGHT)],
        32: [key(pygame.KEYUP, pygame.K_RIGHT)],
        40: [pygame.event.Event(pygame.QUIT)],
    }
    result = run_teleop(
        "demo_course",
        out,
        realtime=False,
        wait_for_start=False,
        script=script_from(events),
        max_frames=200,
        screenshot=tmp_path / "shot.png",
    )
    assert result.quit and not result.completed
    rec = read_recording(out)
    assert rec.complete, "a session the driver quit cleanly is a complete recording"
    assert len(rec) == result.frames == 40
    w = rec.commands[:, 1]
    assert (w[:5] == 0.0).all() and (rec.labels[:5] == CENTRE).all()
    held_left = w[6:15]
    assert (held_left > 0).all() and (held_left[1:] >= held_left[:-1]).all(), "holding LEFT moves w up"
    assert (rec.labels[8:15] > CENTRE).all()
    assert (w[15:20] == w[14]).all() and w[14] > 0, "a released key leaves the stick where it was: a gentle curve held"
    assert (rec.labels[20:25] == CENTRE).all() and (w[20:25] == 0.0).all(), "Down centres the stick at exactly zero"
    assert (w[27:32] < 0).all() and (rec.labels[27:32] < CENTRE).all()
    assert (rec.labels == ControlSet().label_of(w)).all(), "labels are the nearest control-set bins of w"
    assert (rec.commands[:, 0] == 1.0).all()
    assert (tmp_path / "shot.png").stat().st_size > 0


def test_pause_records_nothing_and_stops_time(tmp_path):
    out = tmp_path / "rec"
    events = {
        10: [key(pygame.KEYDOWN, pygame.K_SPACE)],
        20: [key(pygame.KEYDOWN, pygame.K_SPACE)],
        60: [pygame.event.Event(pygame.QUIT)],
    }
    result = run_teleop("demo_course", out, realtime=False, wait_for_start=False, script=script_from(events), max_frames=100)
    rec = read_recording(out)
    countdown = round(COUNTDOWN_S * 10)
    assert countdown == 30
    # Iterations 10..19 were paused and 20..49 counted down before driving resumed.
    assert result.frames == len(rec) == 10 + (60 - 20 - countdown)
    dt = rec.times[1:] - rec.times[:-1]
    assert dt.max() == pytest.approx(0.1, abs=1e-6), "time does not advance while paused"


def test_max_frames_stops_the_run(tmp_path):
    result = run_teleop("demo_course", tmp_path / "rec", realtime=False, wait_for_start=False, max_frames=12)
    assert result.frames == 12 and not result.quit
    assert len(read_recording(tmp_path / "rec")) == 12


def test_a_drive_declares_the_order_given_and_none_without_one(tmp_path):
    from terrapref.terrain import PreferenceProfile

    run_teleop("demo_course", tmp_path / "none", realtime=False, wait_for_start=False, max_frames=3)
    assert "profile" not in read_recording(tmp_path / "none").meta  # not the class table's order, as if declared
    order = PreferenceProfile(("water", "rock", "mud", "non_traversable"))
    run_teleop("demo_course", tmp_path / "given", realtime=False, wait_for_start=False, max_frames=3, profile=order)
    assert read_recording(tmp_path / "given").meta["profile"] == list(order.order)


def test_driving_without_recording(tmp_path):
    result = run_teleop("demo_course", None, realtime=False, wait_for_start=False, max_frames=5)
    assert result.record_dir is None and result.frames == 5


def test_refuses_to_overwrite_a_recording_unless_told(tmp_path):
    out = tmp_path / "rec"
    run_teleop("demo_course", out, realtime=False, wait_for_start=False, max_frames=3)
    with pytest.raises(UserError):
        run_teleop("demo_course", out, realtime=False, wait_for_start=False, max_frames=3)
    result = run_teleop("demo_course", out, realtime=False, wait_for_start=False, max_frames=4, overwrite=True)
    assert len(read_recording(out)) == result.frames == 4


# --- added with the teleop module: closed forms, user errors, import isolation ------------------


def test_ramp_and_axis_closed_forms():
    from terrapref.teleop import axis_to_w, ramp_toward

    assert ramp_toward(0.0, 1.0, 2.5, 0.1) == pytest.approx(0.25)  # 2.5 rad/s per s for one 10 Hz frame
    assert ramp_toward(0.9, 1.0, 2.5, 0.1) == 1.0  # lands exactly on the target
    assert ramp_toward(0.5, -1.0, 2.5, 0.1) == pytest.approx(0.25)
    assert axis_to_w(0.05, 1.0) == 0.0  # inside the deadzone
    assert axis_to_w(1.0, 1.0) == -1.0  # stick right turns right (w < 0)
    assert axis_to_w(-0.5, 1.0) == pytest.approx(0.5)


def test_keyboard_ramp_labels_and_screenshot(tmp_path):
    out = tmp_path / "rec"
    events = {2: [key(pygame.KEYDOWN, pygame.K_LEFT)], 8: [key(pygame.KEYUP, pygame.K_LEFT)], 10: [pygame.event.Event(pygame.QUIT)]}
    result = run_teleop(
        "demo_course",
        out,
        realtime=False,
        wait_for_start=False,
        script=script_from(events),
        max_frames=40,
        screenshot=tmp_path / "shot.png",
    )
    assert result.frames == 10 and result.duration_s == pytest.approx(1.0)
    rec = read_recording(out)
    assert rec.meta["driver"] == {"kind": "human", "input": "keyboard/mouse/gamepad", "disturbance": None, "seed": 0}
    assert rec.meta["summary"]["quit"] is True
    # The press moves one control-set step, the hold 0.05 rad/s a frame; released at frame 8, the stick stays at 0.35.
    assert rec.commands[2:10, 1] == pytest.approx([0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.35, 0.35])
    assert rec.labels[2] == 11 and rec.labels[4] == 12 and rec.labels[6] == 13
    assert rec.poses[8, 2] > rec.poses[2, 2], "turning left raises the heading"
    assert pygame.image.load(str(tmp_path / "shot.png")).get_size() == (640 + 256, 480 + 26)


def test_an_arrow_held_for_a_second_makes_a_gentle_curve_not_full_lock():
    from terrapref.teleop import Stick

    pygame.init()
    stick = Stick(1.0)
    stick.handle(key(pygame.KEYDOWN, pygame.K_LEFT))
    w = [stick.update(0.1) for _ in range(20)]
    assert w[0] == pytest.approx(0.1)  # the press: one step
    assert 0.4 < w[9] < 0.6  # held 1 s
    assert w[15] == pytest.approx(1.0)  # full lock after about 1.5 s
    stick.handle(key(pygame.KEYUP, pygame.K_LEFT))
    stick.handle(key(pygame.KEYDOWN, pygame.K_RIGHT))
    assert stick.update(0.1) == pytest.approx(0.9)  # a new press starts gently again


def test_bad_speed_is_a_user_error():
    with pytest.raises(UserError, match="speed"):
        run_teleop("demo_course", realtime=False, wait_for_start=False, v_mps=0.0, max_frames=1)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="display detection by environment is Linux-specific")
def test_no_display_is_a_user_error(monkeypatch, tmp_path):
    for name in ("SDL_VIDEODRIVER", "DISPLAY", "WAYLAND_DISPLAY"):
        monkeypatch.delenv(name, raising=False)
    with pytest.raises(UserError, match="no display available"):
        run_teleop("demo_course", tmp_path / "rec", realtime=False, wait_for_start=False, max_frames=1)
    assert not (tmp_path / "rec").exists(), "no recording is started without a window"


def test_package_import_does_not_import_pygame():
    code = (
        "import sys, terrapref, terrapref.demos, terrapref.demos.recording, terrapref.demos.session, terrapref.cli; "
        "sys.exit('pygame' in sys.modules)"
    )
    assert subprocess.run([sys.executable, "-c", code], check=False).returncode == 0


def test_disturbances_push_the_executed_command_not_the_label(tmp_path):
    from terrapref.demos.session import DisturbanceConfig

    out = tmp_path / "rec"
    run_teleop("demo_course", out, realtime=False, wait_for_start=False, max_frames=120, disturbance=DisturbanceConfig(rate_hz=2.0), seed=3)
    rec = read_recording(out)
    lines = [__import__("json").loads(x) for x in (out / "frames.jsonl").read_text().splitlines()]
    pushed = [x for x in lines if "executed" in x]
    assert 0 < len(pushed) < len(lines)
    # The stick rests at zero (no keys pressed): every label is the centre, whatever was executed.
    assert set(rec.labels.tolist()) == {CENTRE}
    assert all(x["executed"][1] != 0.0 for x in pushed)
    assert rec.meta["driver"]["disturbance"]["rate_hz"] == 2.0
    # Undisturbed, the vehicle drives straight; pushed, it does not.
    assert abs(rec.poses[-1, 1] - rec.poses[0, 1]) > 1e-3


def test_the_keyboard_shows_a_gentle_curve_and_the_mouse_steers(tmp_path):
    """A tap of LEFT is one control-set step; the mouse sets w by the pointer's position."""
    out = tmp_path / "rec"
    events = {
        3: [key(pygame.KEYDOWN, pygame.K_LEFT)],
        4: [key(pygame.KEYUP, pygame.K_LEFT)],
        10: [pygame.event.Event(pygame.MOUSEBUTTONDOWN, pos=(160, 240), button=1)],
        14: [pygame.event.Event(pygame.MOUSEMOTION, pos=(480, 240), rel=(320, 0), buttons=(1, 0, 0))],
        18: [pygame.event.Event(pygame.MOUSEBUTTONUP, pos=(480, 240), button=1)],
        22: [pygame.event.Event(pygame.QUIT)],
    }
    run_teleop("demo_course", out, realtime=False, wait_for_start=False, script=script_from(events), max_frames=100)
    rec = read_recording(out)
    w = rec.commands[:, 1]
    assert w[5] == pytest.approx(0.1) and rec.labels[5] == CENTRE + 1, "one frame of LEFT: the next bin, and it stays"
    assert (w[5:10] == w[5]).all()
    assert w[11] == pytest.approx(0.5) and w[15] == pytest.approx(-0.5), "pointer a quarter from the left: half left lock, and back"
    assert (w[18:22] == w[17]).all(), "released, the stick stays where the pointer left it"


def _tiny(terrain: list[dict] | None = None, start: list[float] | None = None):
    from terrapref.scenario import parse_scenario

    data = {
        "format": "terrapref-scenario/1",
        "name": "tiny_drive",
        "world": {"size_m": [30.0, 12.0], "resolution_m": 0.05, "background": "grass"},
        "terrain": terrain or [],
        "path": {"waypoints": [[2.0, 6.0], [28.0, 6.0]]},
    }
    if start is not None:
        data["start"] = start
    return parse_scenario(data)


def test_the_window_opens_waiting_and_records_only_after_the_countdown(tmp_path):
    out = tmp_path / "rec"
    events = {
        4: [key(pygame.KEYDOWN, pygame.K_LEFT)],  # the stick may be set before the start
        6: [key(pygame.KEYUP, pygame.K_LEFT)],
        10: [key(pygame.KEYDOWN, pygame.K_SPACE)],
        50: [pygame.event.Event(pygame.QUIT)],
    }
    phases: list[str] = []

    def script(state):
        phases.append(state.phase)
        return events.get(state.index, [])

    result = run_teleop("demo_course", out, realtime=False, script=script, max_frames=200, screenshot=tmp_path / "shot.png")
    rec = read_recording(out)
    countdown = round(COUNTDOWN_S * 10)
    # The key's frame is the countdown's first; the vehicle moves on frame 10 + countdown.
    assert phases[:11] == ["waiting"] * 11 and phases[11 : 10 + countdown] == ["countdown"] * (countdown - 1)
    assert phases[10 + countdown] == "driving"
    assert result.frames == len(rec) == 50 - 10 - countdown
    assert rec.times[0] == 0.0, "nothing moved before the countdown ended"
    assert rec.commands[0, 1] == pytest.approx(0.15), "the stick set while waiting holds"


def test_the_map_edge_stops_the_vehicle_and_is_not_recorded(tmp_path):
    from terrapref.teleop.guide import EDGE_MARGIN_M

    out = tmp_path / "rec"
    # Start 3 m from the west edge, heading west (at it; the start yaw is in degrees).
    events = {45: [key(pygame.KEYDOWN, pygame.K_LEFT)], 120: [pygame.event.Event(pygame.QUIT)]}
    result = run_teleop(
        _tiny(start=[3.0, 6.0, 180.0]), out, realtime=False, wait_for_start=False, script=script_from(events), max_frames=200
    )
    rec = read_recording(out)
    assert result.edge_frames > 0
    assert len(rec) == result.frames == 120 - result.edge_frames
    assert (rec.poses[:, 0] >= EDGE_MARGIN_M).all(), "no frame at or beyond the edge is recorded"
    frames = (out / "frames.jsonl").read_text().splitlines()
    assert len(frames) == len(rec)
    # Held at the edge, it turned on the spot with the stick and drove away once facing inward.
    assert rec.poses[-1, 0] > rec.poses[:, 0].min() + 0.3
    assert rec.meta["summary"]["edge_frames"] == result.edge_frames


def test_a_resized_window_scales_the_view_and_the_mouse_follows(tmp_path):
    out = tmp_path / "rec"
    # Twice the canvas size (896 x 506): the pointer at window x = 320 is canvas x = 160, a
    # quarter from the left of the camera view: half left lock.
    events = {
        2: [pygame.event.Event(pygame.VIDEORESIZE, size=(1792, 1012), w=1792, h=1012)],
        4: [pygame.event.Event(pygame.MOUSEBUTTONDOWN, pos=(320, 480), button=1)],
        8: [pygame.event.Event(pygame.QUIT)],
    }
    run_teleop(
        "demo_course",
        out,
        realtime=False,
        wait_for_start=False,
        script=script_from(events),
        max_frames=20,
        screenshot=tmp_path / "shot.png",
    )
    rec = read_recording(out)
    assert rec.commands[5, 1] == pytest.approx(0.5)
    shot = pygame.image.load(str(tmp_path / "shot.png"))
    assert shot.get_size() == (1792, 1012)


def test_the_guide_reads_progress_the_next_patch_and_the_terrain_underneath():
    from terrapref.features import PreferenceSet, PreferenceSetConfig
    from terrapref.sim import Simulation
    from terrapref.teleop.guide import CourseGuide
    from terrapref.vehicle import Pose

    scenario = _tiny(
        [
            {"class": "mud", "rectangle": {"center": [13.5, 6.0], "size": [3.0, 2.0]}},
            {"class": "water", "rectangle": {"center": [21.0, 8.75], "size": [2.0, 1.5]}},
        ]
    )
    sim = Simulation(scenario)
    prefs = PreferenceSet(PreferenceSetConfig(), sim.camera)
    guide = CourseGuide(sim.world, sim.path, prefs)
    r = guide.readout(Pose(4.0, 6.0, 0.0), 2.0, label=10)
    assert (r.next_patch, r.under, r.turn_deg_s) == ("mud", "grass", 0.0) and r.lines()[3] == "label 10: straight"
    assert r.next_patch_m == pytest.approx(8.0, abs=0.5)  # the mud begins at x = 12 m, s = 10 m
    assert r.lines()[0].startswith("path   2.0 / 26 m")
    on_mud = guide.readout(Pose(13.0, 6.0, 0.0), 11.0, label=10)
    assert (on_mud.under, on_mud.next_patch, on_mud.next_patch_m) == ("mud", "mud", 0.0)
    assert "patch here: mud" in on_mud.lines()
    # Water 2-3.5 m beside the path counts; nothing after it.
    after_mud = guide.readout(Pose(16.0, 6.0, 0.0), 14.0, label=10)
    assert after_mud.next_patch == "water" and after_mud.next_patch_m == pytest.approx(4.0, abs=0.5)
    assert guide.readout(Pose(25.0, 6.0, 0.0), 23.0, label=10).next_patch is None
    left, right = guide.readout(Pose(4.0, 6.0, 0.0), 2.0, label=15), guide.readout(Pose(4.0, 6.0, 0.0), 2.0, label=5)
    assert left.turn_deg_s > 0 > right.turn_deg_s and left.turn_deg_s == pytest.approx(-right.turn_deg_s)
    assert left.lines()[3] == "label 15: left 29 deg/s, a 2.0 m radius" and right.lines()[3].startswith("label 5: right 29 deg/s")
    assert guide.readout(Pose(4.0, 6.0, 0.0), 2.0, label=20).lines()[3] == "label 20: left 57 deg/s, a 1.0 m radius"  # was 332 deg left


def test_the_guide_gives_the_turn_radius_at_the_vehicle_speed():
    """The radius is v / |w| at the speed the vehicle goes, not at the control set's 1 m/s."""
    from terrapref.features import PreferenceSet, PreferenceSetConfig
    from terrapref.sim import Simulation
    from terrapref.teleop.guide import CourseGuide, turn_radius_m
    from terrapref.vehicle import Pose

    sim = Simulation(_tiny([]))
    guide = CourseGuide(sim.world, sim.path, PreferenceSet(PreferenceSetConfig(), sim.camera))
    at = (Pose(4.0, 6.0, 0.0), 2.0)
    assert guide.readout(*at, label=15, speed_mps=1.6).lines()[3] == "label 15: left 29 deg/s, a 3.2 m radius"  # 1.6 m/s / 0.5 rad/s
    assert guide.readout(*at, label=5, speed_mps=0.5).radius_m == pytest.approx(1.0)
    assert guide.readout(*at, label=20, speed_mps=0.0).lines()[3] == "label 20: left 57 deg/s, on the spot"
    assert guide.readout(*at, label=10, speed_mps=2.0).lines()[3] == "label 10: straight"
    assert turn_radius_m(2.0, -0.25) == pytest.approx(8.0) and turn_radius_m(2.0, 0.0) == math.inf


def test_riding_along_records_only_the_takeover_and_train_accepts_it(tmp_path):
    """The planner drives; Left takes over from the planner's command; 1.5 s untouched hands back."""
    from helpers import linear_model
    from terrapref.cli import main
    from terrapref.learning.model_file import load_model
    from terrapref.teleop import HANDBACK_S

    model = linear_model(tmp_path / "m.safetensors")
    out = tmp_path / "corrections"
    events = {20: [key(pygame.KEYDOWN, pygame.K_LEFT)], 23: [key(pygame.KEYUP, pygame.K_LEFT)], 80: [pygame.event.Event(pygame.QUIT)]}
    result, drivers, stick = ride_along(out, model, events)
    handback = round(HANDBACK_S * 10)
    # State is seen before each frame: the driver steers frames 20-22 (Left held) and 15 more untouched.
    assert drivers[:21] == ["planner"] * 21 and drivers[21 : 24 + handback] == ["you"] * (3 + handback)
    assert drivers[24 + handback] == "planner"
    rec = read_recording(out)
    assert result.frames == len(rec) == 3 + handback and result.planner_frames == 80 - len(rec)
    assert rec.meta["driver"]["kind"] == "corrections" and rec.meta["driver"]["model"] == str(model)
    assert rec.meta["profile"] == list(load_model(model).profile)  # riding along, the driver is the one the model learned
    w = rec.commands[:, 1]
    assert w[0] == pytest.approx(stick[20] + 0.1), "the takeover starts from the planner's command, one step left"
    assert (w[3:] == w[2]).all(), "released, the stick holds until it hands back"
    assert (rec.labels == ControlSet().label_of(w)).all()
    assert rec.times[0] == pytest.approx(2.0) and (rec.times[1:] - rec.times[:-1]).max() == pytest.approx(0.1)
    # A demonstration and the corrections train together.
    demo = tmp_path / "demo"
    run_teleop(
        "demo_course",
        demo,
        realtime=False,
        wait_for_start=False,
        max_frames=60,
        script=script_from({10: [key(pygame.KEYDOWN, pygame.K_RIGHT)], 14: [key(pygame.KEYUP, pygame.K_RIGHT)]}),
    )
    # Six seconds of driving show the offset rule no price of holding off the path (refused, as
    # train refuses it): the paper's recipe, whose C alone drives, trains on them.
    assert main(["train", str(demo), str(out), "--out", str(tmp_path / "m2.safetensors"), "--epochs", "1", "--recipe", "paper"]) == 0


def test_riding_along_without_taking_over_records_nothing_and_says_so(tmp_path):
    """The planner drove the whole run: no correction, so no recording (it used to end in a
    refusal that blamed a perception file or a drive ended before its first frame)."""
    from helpers import linear_model

    model = linear_model(tmp_path / "m.safetensors")
    out = tmp_path / "corrections"
    result, drivers, _ = ride_along(out, model, {40: [pygame.event.Event(pygame.QUIT)]})
    assert set(drivers) == {"planner"} and result.frames == 0 and result.planner_frames == 40
    assert result.record_dir is None and not out.exists()


def test_riding_along_with_a_missing_model_is_one_line(tmp_path, capsys):
    from terrapref.cli import main

    assert main(["drive", "demo_course", "--model", str(tmp_path / "none.safetensors"), "--record", str(tmp_path / "rec")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "none.safetensors" in err[0]
    assert not (tmp_path / "rec").exists()


def test_a_negative_seed_for_the_pushes_is_one_line(tmp_path, capsys):
    from terrapref.cli import main

    assert main(["drive", "demo_course", "--seed", "-1", "--disturb", "0.3", "--record", str(tmp_path / "rec")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["error: --seed: must be an integer >= 0, got -1"]
    assert not (tmp_path / "rec").exists()


def test_frames_taken_off_the_map_are_not_training_data(tmp_path):
    """A recording made before the edge stopped the vehicle (or imported) keeps its off-map frames; featurising leaves them out."""
    import json

    from terrapref.dataset import build_dataset
    from terrapref.features import FeatureConfig

    out = tmp_path / "rec"
    run_teleop("demo_course", out, realtime=False, wait_for_start=False, max_frames=10)
    lines = [json.loads(x) for x in (out / "frames.jsonl").read_text().splitlines()]
    for row in lines[6:]:
        row["pose"][1] = -3.0  # south of the map
    (out / "frames.jsonl").write_text("".join(json.dumps(x) + "\n" for x in lines))
    data = build_dataset([read_recording(out)], FeatureConfig())
    assert len(data) == 6 and data.meta["recordings"][0]["frames_used"] == 6
    for row in lines:
        row["pose"][1] = -3.0
    (out / "frames.jsonl").write_text("".join(json.dumps(x) + "\n" for x in lines))
    with pytest.raises(UserError, match="off the"):
        build_dataset([read_recording(out)], FeatureConfig())


@pytest.mark.slow  # the whole of demo_course; a press's step and a hold's ramp are tested above, the person on the short course below
def test_a_simulated_keyboard_person_drives_the_course_through_the_window(tmp_path):
    """Key presses from the synthetic driver's intent, 0.3 s late: the course driven with gentle curves, no collision."""
    import numpy as np

    from terrapref.demos.expert import ExpertConfig, ExpertDriver
    from terrapref.scenario import resolve_scenario
    from terrapref.teleop.keyboard import START_AFTER_FRAMES, KeyboardPerson

    scenario = resolve_scenario("demo_course")
    person = KeyboardPerson(ExpertDriver(ExpertConfig()), scenario, np.random.default_rng(0))
    out = tmp_path / "rec"
    result = run_teleop(scenario, out, realtime=False, script=person, max_frames=2000)
    rec = read_recording(out)
    assert result.completed and result.collisions == 0 and not result.quit
    assert len(rec) == result.frames and rec.times[0] == 0.0
    assert result.frames + START_AFTER_FRAMES + round(COUNTDOWN_S * 10) <= 2000
    w = rec.commands[:, 1]
    steps = np.round(np.abs(np.diff(w)), 6)
    assert ((steps == 0.0) | (steps == 0.05) | (steps == 0.1) | (w[1:] == 0.0)).all(), (
        "a press moves a step, a hold less at first, or Down centres it"
    )
    assert len(set(rec.labels.tolist())) >= 5 and 0.2 < np.mean(w == 0.0) < 0.9, "curves of several widths, and straight stretches"
    assert person.presses > 10
    assert person.throttle_presses == 0 and (rec.commands[:, 0] == 1.0).all(), "a driver of one speed leaves the throttle at it"


@pytest.mark.slow  # a whole drive, course or training end to end; the default run keeps the test suite's time
def test_a_simulated_keyboard_person_works_the_throttle_toward_the_speeds_it_wants(tmp_path):
    """W and S through the window's own events: the set speed moves by a tap's step or a held key's
    ramp, and settles at each cruising speed the driver wants (within half a step)."""
    import numpy as np

    from helpers import SHORT_COURSE
    from terrapref.demos.expert import ExpertConfig, ExpertDriver
    from terrapref.scenario import resolve_scenario
    from terrapref.teleop.keyboard import KeyboardPerson
    from terrapref.teleop.throttle import KEY_RATE_MPS2, KEY_STEP_MPS

    scenario = resolve_scenario(str(SHORT_COURSE))
    order = ("rock", "mud", "water", "non_traversable")
    speeds = (("grass", 1.3), ("rock", 0.8), ("mud", 0.5), ("water", 0.3))
    person = KeyboardPerson(ExpertDriver(ExpertConfig.styled("default", order, speeds)), scenario, np.random.default_rng(0))
    out = tmp_path / "rec"
    result = run_teleop(scenario, out, realtime=False, script=person, max_frames=3000)
    rec = read_recording(out)
    assert result.completed and result.collisions == 0
    v = rec.commands[:, 0]
    steps = np.round(np.abs(np.diff(v)), 6)
    ramp = round(KEY_RATE_MPS2 / 10.0, 6)  # a held key, per camera frame
    assert set(steps.tolist()) <= {0.0, KEY_STEP_MPS, ramp}, "a tap moves a step, a held key the ramp"
    held = np.round(v, 2)
    for _, mps in speeds:
        assert np.count_nonzero(np.abs(held - mps) <= 0.5 * KEY_STEP_MPS + 1e-9) >= 20, f"held near {mps} m/s for 2 s or more"
    assert person.throttle_presses > 5 and v.min() >= 0.3 - 1e-9 and v.max() <= 1.3 + 1e-9


@pytest.mark.slow
def test_a_keyboard_demonstration_teaches_beside_a_stick(tmp_path, monkeypatch):
    """The keyboard study on one seed and a few unseen layouts (scripts/keyboard_demo.py; docs/teleop.md has the full run)."""
    import importlib.util
    import json

    spec = importlib.util.spec_from_file_location("keyboard_demo", REPO / "scripts" / "keyboard_demo.py")
    study = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, "keyboard_demo", study)  # its forked workers find their job function by module name
    spec.loader.exec_module(study)
    assert study.main(["--seeds", "1", "--courses", "4", "--out", str(tmp_path / "kb"), "--workers", "2"]) == 0
    saved = json.loads((tmp_path / "kb" / "keyboard.json").read_text())
    by_input = {k: [z for z in saved["zones"] if z["input"] == k] for k in ("stick", "keyboard")}
    assert all(len(v) >= 16 for v in by_input.values())
    success = {k: sum(z["success"] for z in v) / len(v) for k, v in by_input.items()}
    assert success["keyboard"] >= 0.8, f"a keyboard demonstration teaches: {success}"
    assert saved["drives"]["keyboard_s0"]["frames"] > 3000
    assert (tmp_path / "kb" / "keyboard.png").stat().st_size > 0 and "keyboard" in (tmp_path / "kb" / "KEYBOARD.md").read_text()


def test_the_gamepad_stick_springs_back_and_takes_over_from_the_keys():
    from terrapref.teleop import AXIS_DEADZONE, Stick

    class Pad:
        axis = 0.0

        def get_numaxes(self) -> int:
            return 2

        def get_axis(self, i: int) -> float:
            return self.axis if i == 0 else 0.0

    pygame.init()
    stick = Stick(w_max_rps=1.0)
    stick.joystick = pad = Pad()
    stick.follow(0.3)  # the planner's command while it drives
    assert stick.update(0.1) == 0.3 and not stick.touched and not stick.active
    pad.axis = 0.5  # pushed half right
    assert stick.update(0.1) == pytest.approx(-0.5) and stick.source == "pad" and stick.touched and stick.active
    pad.axis = AXIS_DEADZONE / 2  # released: a spring stick returns to straight
    assert stick.update(0.1) == 0.0 and not stick.active
    stick.handle(key(pygame.KEYDOWN, pygame.K_LEFT))
    assert stick.update(0.1) == pytest.approx(0.1) and stick.source == "keys", "the input used last drives"


def test_frames_after_a_gap_get_the_features_of_a_recording_without_one(tmp_path, short_recording):
    """A ride-along records only the takeovers: the path progress must jump the gap, so that
    the frames after it are featurised as they would be in one continuous recording."""
    import json
    import shutil

    import numpy as np

    from terrapref.dataset import featurize_recording
    from terrapref.features import FeatureConfig

    full = short_recording  # the synthetic driver, along the path
    gappy = tmp_path / "gappy"
    shutil.copytree(full, gappy)
    lines = (gappy / "frames.jsonl").read_text().splitlines()
    kept = list(range(20)) + list(range(200, 230))  # 18 s (about 18 m) of path missing
    (gappy / "frames.jsonl").write_text("".join(lines[i] + "\n" for i in kept))
    meta = json.loads((gappy / "meta.json").read_text())
    (gappy / "meta.json").write_text(json.dumps({**meta, "frames": len(kept)}))
    U_full = featurize_recording(read_recording(full), FeatureConfig())[0]
    U_gap = featurize_recording(read_recording(gappy), FeatureConfig())[0]
    np.testing.assert_array_equal(U_gap, U_full[kept])


def test_a_window_resized_in_one_direction_is_letterboxed_and_the_mouse_follows(tmp_path):
    """896 x 506 canvas in a 1000 x 506 window: scale 1, the picture centred with 52 px either side."""
    out = tmp_path / "rec"
    events = {
        2: [pygame.event.Event(pygame.VIDEORESIZE, size=(1000, 506), w=1000, h=506)],
        4: [pygame.event.Event(pygame.MOUSEBUTTONDOWN, pos=(52 + 160, 240), button=1)],
        6: [pygame.event.Event(pygame.MOUSEBUTTONUP, pos=(52 + 160, 240), button=1)],
        7: [pygame.event.Event(pygame.MOUSEBUTTONDOWN, pos=(52 + 600, 495), button=1)],  # the status bar: not the view
        9: [pygame.event.Event(pygame.QUIT)],
    }
    run_teleop(
        "demo_course",
        out,
        realtime=False,
        wait_for_start=False,
        script=script_from(events),
        max_frames=20,
        screenshot=tmp_path / "shot.png",
    )
    w = read_recording(out).commands[:, 1]
    assert w[5] == pytest.approx(0.5), "a quarter from the left of the view as the driver sees it"
    assert w[8] == pytest.approx(0.5), "a click below the camera view does not steer"
    shot = pygame.image.load(str(tmp_path / "shot.png"))
    assert shot.get_size() == (1000, 506)
    assert tuple(shot.get_at((10, 200)))[:3] == (0, 0, 0) and tuple(shot.get_at((990, 200)))[:3] == (0, 0, 0), "dark margins"
    assert tuple(shot.get_at((60, 300)))[:3] != (0, 0, 0), "the camera view starts after the margin"


def test_a_vehicle_within_the_edge_margin_may_drive_back_in():
    from terrapref.teleop.guide import stays_on_map
    from terrapref.vehicle import Command, Pose
    from terrapref.world import rasterise

    world = rasterise(_tiny())
    assert not stays_on_map(world, Pose(0.5, 6.0, math.pi), Command(1.0, 0.0), 0.1), "further out: held"
    assert stays_on_map(world, Pose(0.5, 6.0, 0.0), Command(1.0, 0.0), 0.1), "back toward the map: allowed"
    assert not stays_on_map(world, Pose(1.05, 6.0, math.pi), Command(1.0, 0.0), 0.1), "into the margin: held"


@pytest.mark.slow  # once in a full default run the drive process did not exit after SIGTERM (its SDL timer thread waiting): under investigation
def test_sigterm_before_the_first_frame_of_drive_leaves_no_recording(tmp_path):
    # SDL turns SIGTERM into a quit event when no handler is set, which closed a 0-frame recording
    # as complete; terrapref's handler ends the command as Ctrl-C does, and an empty one is removed.
    import signal
    import time

    out = tmp_path / "rec"
    command = [
        sys.executable,
        "-c",
        "import sys; from terrapref.cli import main; sys.exit(main())",
        "drive",
        "demo_course",
        "--record",
        str(out),
    ]
    child = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        while not (out / "meta.json").exists():  # no time limit: the window opens its recording or the child exits
            if child.poll() is not None:
                pytest.fail(f"drive exited ({child.returncode}) before opening its recording: {child.stderr.read()}")
            time.sleep(0.01)
        child.send_signal(signal.SIGTERM)
        _, err = child.communicate(timeout=120)  # a guard against the hang seen once, not a speed check
    finally:
        child.kill()
        child.wait()
    assert child.returncode == 143 and "terminated" in err, err
    assert not out.exists()


def test_the_route_is_drawn_on_the_ground_in_the_camera_view(tmp_path):
    # The 21 arcs are the turns on offer; the route to follow is drawn in its own colour.
    import numpy as np

    from terrapref.teleop.window import PATH_COLOR

    events = {5: [pygame.event.Event(pygame.QUIT)]}
    run_teleop(
        "demo_course",
        None,
        realtime=False,
        wait_for_start=False,
        script=script_from(events),
        max_frames=20,
        screenshot=tmp_path / "shot.png",
    )
    shot = pygame.surfarray.array3d(pygame.image.load(str(tmp_path / "shot.png"))).transpose(1, 0, 2)  # (H, W, 3)
    view = shot[:480, :640].astype(int)
    on_route = np.abs(view - np.array(PATH_COLOR)).sum(axis=2) < 30
    assert on_route.sum() > 150 and on_route[:, 300:340].sum() > 0.8 * on_route.sum()  # straight ahead, down the middle


class _Collecting:
    """Stands in for a live view (terrapref.interop.live.LiveView): keeps each message by role,
    serialised as it is sent (the trajectory markers are restyled in place frame after frame)."""

    def __init__(self) -> None:
        from terrapref.interop.ros_messages import typestore

        self.ts, self.got = typestore(), {}

    def write(self, role: str, t_ns: int, msg) -> None:
        from terrapref.interop.mcap_export import TOPICS

        msgtype = TOPICS[role][1]
        self.got.setdefault(role, []).append((t_ns, self.ts.deserialize_cdr(self.ts.serialize_cdr(msg, msgtype), msgtype)))


def test_drive_live_sends_every_driven_frame_and_riding_along_the_planners_costmap(tmp_path):
    from test_offset_rule import DRIVER_LIKE, _offset_meta

    from helpers import skip_path_weights
    from terrapref.learning.model_file import save_model
    from terrapref.learning.network import ClassifierConfig

    config = ClassifierConfig(hidden=8, skip=True)
    model = save_model(tmp_path / "m.safetensors", config, skip_path_weights(config), _offset_meta(DRIVER_LIKE))
    view = _Collecting()
    result = run_teleop(
        "demo_course",
        None,
        realtime=False,
        wait_for_start=False,
        max_frames=40,
        model=model,
        live=view,
        script=script_from({25: [key(pygame.KEYDOWN, pygame.K_LEFT)], 28: [key(pygame.KEYUP, pygame.K_LEFT)]}),
    )
    odom, markers = view.got["odom"], view.got["trajectories"]
    assert len(odom) == len(markers) == result.frames + result.planner_frames == 40
    assert [ns for ns, _ in odom] == sorted(ns for ns, _ in odom)
    assert len(view.got["costmap"]) == 4 and view.got["path"] and view.got["tf_static"]  # once a second; the path and mounting resent
    # F_t shades the trajectories while the planner drives; the driver's own frames show only its choice.
    shaded = [len({round(m.color.a, 3) for m in msg.markers}) > 2 for _, msg in markers]
    assert shaded[:25] == [True] * 25 and not any(shaded[26:29])


def test_a_course_of_ones_own_class_table_drives_in_the_window(tmp_path):

    from terrapref.scenario import parse_scenario
    from terrapref.scenario.teaching import teaching_course
    from terrapref.terrain import ClassTable, load_classes

    table = load_classes(REPO / "examples" / "classes" / "rellis3d.yaml")
    scenario = parse_scenario(teaching_course(table).data(), "course.yaml", table)
    out = tmp_path / "rec"
    events = {3: [key(pygame.KEYDOWN, pygame.K_LEFT)], 6: [key(pygame.KEYUP, pygame.K_LEFT)], 12: [pygame.event.Event(pygame.QUIT)]}
    result = run_teleop(
        scenario, out, realtime=False, wait_for_start=False, script=script_from(events), max_frames=40, screenshot=tmp_path / "shot.png"
    )
    assert result.frames == 12
    rec = read_recording(out)
    assert ClassTable.from_dict(rec.meta["classes"]) == table and "profile" not in rec.meta  # no --profile: none declared
    shot = pygame.image.load(str(tmp_path / "shot.png"))
    # The camera view is drawn in the table's colours: grass just ahead, at the view's bottom left.
    assert tuple(shot.get_at((20, 470)))[:3] == table.classes[0].color


def _overlays(monkeypatch) -> list:
    """Every overlay the window draws, in order (the window still draws them)."""
    from terrapref.teleop.window import Window

    drawn = []
    draw = Window.draw

    def keep(self, image, w, label, trace_px, overlay):
        drawn.append(overlay)
        draw(self, image, w, label, trace_px, overlay)

    monkeypatch.setattr(Window, "draw", keep)
    return drawn


def test_each_push_is_shown_as_it_happens_and_marked_on_the_map(tmp_path, monkeypatch):
    import json

    from terrapref.demos.session import DisturbanceConfig

    drawn = _overlays(monkeypatch)
    out = tmp_path / "rec"
    events = {3: [key(pygame.KEYDOWN, pygame.K_SPACE)], 3 + 30 + 120: [pygame.event.Event(pygame.QUIT)]}
    result = run_teleop(
        "demo_course",
        out,
        realtime=False,
        script=script_from(events),
        max_frames=400,
        disturbance=DisturbanceConfig(rate_hz=1.0),
        seed=3,
        screenshot=tmp_path / "shot.png",
    )
    start = drawn[0].banner
    assert start is not None and any("never near lethal terrain) turn the" in line for line in start.lines)
    assert any("--disturb 0" in line for line in start.lines), "the start screen says how to turn them off"
    frames = [json.loads(x) for x in (out / "frames.jsonl").read_text().splitlines()]
    pushed = [("executed" in f) for f in frames]
    starts = sum(1 for i, p in enumerate(pushed) if p and (i == 0 or not pushed[i - 1]))
    assert result.pushes >= starts > 0
    # The frame after each pushed frame is drawn with the alert, naming the push's direction.
    driving = [o for o in drawn if o.banner is None][: len(frames)]
    for i, f in enumerate(frames[:-1]):
        if "executed" in f:
            side = "LEFT" if f["executed"][1] > f["cmd"][1] else "RIGHT"
            assert any(a.startswith(f"PUSHED {side}") for a in driving[i + 1].alerts)
    assert len(drawn[-1].pushes_px) == result.pushes and f"pushes {result.pushes}" in drawn[-1].status


def test_the_display_gives_the_turn_radius_at_the_speed_driven(monkeypatch):
    drawn = _overlays(monkeypatch)
    events = {5: [key(pygame.KEYDOWN, pygame.K_LEFT)] * 3}
    run_teleop("demo_course", None, realtime=False, wait_for_start=False, script=script_from(events), max_frames=90, v_mps=2.0)
    last = drawn[-1]
    speed_mps = float(re.search(r"v (\d+\.\d+) m/s", last.status)[1])
    turn = next(line for line in last.hud if line.startswith("label "))
    deg_s, radius_m = (float(x) for x in re.search(r"left (\d+) deg/s, a (\d+\.\d) m radius", turn).groups())
    assert speed_mps > 1.5 and radius_m == pytest.approx(speed_mps / math.radians(deg_s), abs=0.1)  # not the 1 m/s radius


def test_without_pushes_the_start_screen_says_so_and_nothing_is_pushed(tmp_path, monkeypatch):
    drawn = _overlays(monkeypatch)
    events = {2: [key(pygame.KEYDOWN, pygame.K_SPACE)], 80: [pygame.event.Event(pygame.QUIT)]}
    result = run_teleop("demo_course", None, realtime=False, script=script_from(events), max_frames=100, disturbance=None)
    assert "No pushes: the vehicle goes where you steer." in drawn[0].banner.lines
    assert result.pushes == 0 and not any(o.alerts for o in drawn) and "pushes" not in drawn[-1].status


def test_drive_disturb_0_turns_the_pushes_off(tmp_path, monkeypatch, capsys):
    from terrapref.cli import main

    drawn = _overlays(monkeypatch)
    import terrapref.teleop as teleop

    run = teleop.run_session

    def scripted(scenario, options):
        from dataclasses import replace

        return run(scenario, replace(options, realtime=False, wait_for_start=False, max_frames=60))

    monkeypatch.setattr(teleop, "run_session", scripted)
    assert main(["drive", "demo_course", "--disturb", "0", "--record", str(tmp_path / "rec")]) == 0
    assert read_recording(tmp_path / "rec").meta["driver"]["disturbance"] is None
    assert main(["drive", "demo_course", "--disturb", "0", "--record", str(tmp_path / "rec")]) == 2  # its refusal names the flag given
    assert "choose another --record or pass --force" in capsys.readouterr().err
    assert drawn and not any(o.alerts for o in drawn) and "push" not in capsys.readouterr().out
    assert main(["drive", "demo_course", "--disturb", "2", "--seed", "3"]) == 0
    assert re.search(
        r"drove 60 frames, stopped, 0 collisions, [1-9][0-9]* push(es)? \(--disturb 0: none\)$", capsys.readouterr().out.strip()
    )


def test_off_the_route_the_display_points_back_and_stops_counting_patches_along_it():
    from terrapref.features import PreferenceSet, PreferenceSetConfig
    from terrapref.sim import Simulation
    from terrapref.teleop.guide import CourseGuide
    from terrapref.vehicle import Pose

    scenario = _tiny([{"class": "mud", "rectangle": {"center": [20.0, 6.0], "size": [3.0, 2.0]}}])
    sim = Simulation(scenario)
    guide = CourseGuide(sim.world, sim.path, PreferenceSet(PreferenceSetConfig(), sim.camera))
    near = guide.readout(Pose(8.0, 7.0, 0.0), 6.0, label=10)
    assert not near.off_route and near.warning() is None
    assert near.lines()[1] == "next patch: mud in 10 m" and near.lines()[4] == "route: 1.0 m to your right"
    # 5 m north of the route, heading away from it (north-east): the route is behind, to the right.
    away = guide.readout(Pose(12.0, 11.0, math.radians(60.0)), 10.0, label=10)
    assert away.off_route and away.offset_m == pytest.approx(5.0)
    assert away.lines()[1] == "next patch: back on the route first", "no distance counted along a route the vehicle is not on"
    assert away.warning() == "OFF ROUTE: 5 m away, turn right (it is behind you)"
    # The way back: the route 3 m ahead of its nearest point, (15, 6) from (12, 11): 59 deg right of east, 119 deg right of the heading.
    assert math.degrees(away.rejoin_rad) == pytest.approx(-60.0 - math.degrees(math.atan2(5.0, 3.0)), abs=0.1)
    facing = guide.readout(Pose(12.0, 11.0, math.radians(-70.0)), 10.0, label=10)  # the way back 11 deg to the left
    assert facing.warning() == "OFF ROUTE: 5 m away, ahead"


def test_driving_away_from_the_route_raises_the_alert_and_draws_the_arrow(tmp_path, monkeypatch):
    import numpy as np

    from terrapref.scenario import parse_scenario
    from terrapref.teleop.window import ALERT_COLOR

    drawn = _overlays(monkeypatch)
    data = {
        "format": "terrapref-scenario/1",
        "name": "wide",
        "world": {"size_m": [40.0, 30.0], "resolution_m": 0.05, "background": "grass"},
        "terrain": [{"class": "mud", "rectangle": {"center": [30.0, 6.0], "size": [3.0, 2.0]}}],
        "path": {"waypoints": [[2.0, 6.0], [38.0, 6.0]]},
        "start": [4.0, 6.0, 60.0],
    }
    run_teleop(
        parse_scenario(data), None, realtime=False, wait_for_start=False, max_frames=80, disturbance=None, screenshot=tmp_path / "shot.png"
    )
    first, last = drawn[0], drawn[-1]
    assert not first.off_route and not first.alerts and first.hud[1].startswith("next patch: mud in")
    assert last.off_route and last.alerts[0].startswith("OFF ROUTE: 6 m away, turn right")  # 8 s, the first 1 s of it speeding up
    assert last.hud[1] == "next patch: back on the route first" and last.route_rad < 0
    shot = pygame.surfarray.array3d(pygame.image.load(str(tmp_path / "shot.png"))).transpose(1, 0, 2)[:480, :640].astype(int)
    red = np.abs(shot - np.array(ALERT_COLOR)).sum(axis=2) < 30
    assert red[140:230, 280:360].sum() > 200, "the arrow under the alert"


# --- the throttle: the set speed from W/S, the mouse wheel and a gamepad axis ------------------


def test_the_throttle_keys_step_at_a_press_then_ramp_gently_within_zero_and_top_speed():
    from terrapref.teleop import Throttle

    throttle = Throttle(1.0, v_max_mps=2.0)
    throttle.handle(key(pygame.KEYDOWN, pygame.K_w))
    v = [throttle.update(0.1) for _ in range(10)]
    assert v[0] == pytest.approx(1.1) and v[1] == pytest.approx(1.15), "the press: one 0.1 m/s step; held: 0.5 m/s per s"
    assert v[9] == pytest.approx(1.55)
    assert max(throttle.update(0.1) for _ in range(20)) == 2.0 and throttle.v == 2.0, "held on: the top speed, no more"
    throttle.handle(key(pygame.KEYUP, pygame.K_w))
    assert throttle.update(0.1) == 2.0 and not throttle.active, "released, the set speed holds"
    throttle.handle(key(pygame.KEYDOWN, pygame.K_s))
    assert [throttle.update(0.1) for _ in range(3)] == pytest.approx([1.9, 1.85, 1.8])
    assert min(throttle.update(0.1) for _ in range(50)) == 0.0 and throttle.v == 0.0, "held on: a stop, never below"
    throttle.handle(key(pygame.KEYUP, pygame.K_s))
    throttle.handle(key(pygame.KEYDOWN, pygame.K_w))  # a tap within one frame
    throttle.handle(key(pygame.KEYUP, pygame.K_w))
    assert throttle.update(0.1) == pytest.approx(0.1) and throttle.update(0.1) == pytest.approx(0.1)


def test_the_mouse_wheel_and_the_pads_throttle_axis_move_the_set_speed():
    from terrapref.teleop import Stick, Throttle
    from terrapref.teleop.throttle import PAD_AXIS, PAD_DEADZONE

    throttle = Throttle(1.0, v_max_mps=2.0)
    throttle.handle(pygame.event.Event(pygame.MOUSEWHEEL, x=0, y=3, flipped=False))
    assert throttle.update(0.1) == pytest.approx(1.3) and throttle.touched
    throttle.handle(pygame.event.Event(pygame.MOUSEWHEEL, x=0, y=-1, flipped=False))
    throttle.handle(pygame.event.Event(pygame.MOUSEWHEEL, x=0, y=1, flipped=True))  # reversed by the system: the wheel went down
    assert throttle.update(0.1) == pytest.approx(1.1)

    class Pad:
        def __init__(self, axes: int) -> None:
            self.axes, self.values = axes, [0.0] * axes

        def get_numaxes(self) -> int:
            return self.axes

        def get_axis(self, i: int) -> float:
            return self.values[i]

    pygame.init()
    stick = Stick(w_max_rps=1.0)
    stick.joystick = pad = Pad(2)
    pad.values[PAD_AXIS] = -1.0  # pushed fully up: 0.5 m/s per s
    throttle = Throttle(1.0, v_max_mps=2.0)
    assert [throttle.update(0.1, stick.axis(PAD_AXIS)) for _ in range(2)] == pytest.approx([1.05, 1.1])
    assert throttle.touched and throttle.active
    pad.values[PAD_AXIS] = PAD_DEADZONE / 2  # let go: the set speed holds
    throttle.touched = False
    assert throttle.update(0.1, stick.axis(PAD_AXIS)) == pytest.approx(1.1) and not throttle.touched and not throttle.active
    pad.values[PAD_AXIS] = 0.5  # half down
    assert throttle.update(0.1, stick.axis(PAD_AXIS)) == pytest.approx(1.075)
    stick.joystick = Pad(1)  # a pad without the axis: the throttle is the keys' and the wheel's
    assert stick.axis(PAD_AXIS) == 0.0 and throttle.update(0.1, stick.axis(PAD_AXIS)) == pytest.approx(1.075)
    assert stick.update(0.1) == 0.0


def test_a_recording_holds_the_set_speed_of_each_frame_and_leaves_out_standing_frames(tmp_path):
    import numpy as np

    out = tmp_path / "rec"
    events = {
        5: [key(pygame.KEYDOWN, pygame.K_w)],
        9: [key(pygame.KEYUP, pygame.K_w)],
        12: [pygame.event.Event(pygame.MOUSEWHEEL, x=0, y=-3, flipped=False)],
        15: [key(pygame.KEYDOWN, pygame.K_s)],
        40: [key(pygame.KEYUP, pygame.K_s)],
        45: [key(pygame.KEYDOWN, pygame.K_w), key(pygame.KEYUP, pygame.K_w)],
        50: [pygame.event.Event(pygame.QUIT)],
    }
    set_v: list[float] = []

    def script(state):
        set_v.append(state.v)
        return events.get(state.index, [])

    result = run_teleop("demo_course", out, realtime=False, wait_for_start=False, script=script, max_frames=100)
    # W: a step at 5, then 0.05 m/s a frame until released at 9; the wheel 3 notches down at 12;
    # S from 15: a step, then 0.05 m/s a frame, a stop at 32 held until W is tapped at 45.
    expected = [1.0] * 5 + [1.1, 1.15, 1.2] + [1.25] * 4 + [0.95] * 3 + [0.85 - 0.05 * k for k in range(17)] + [0.0] * 13 + [0.1] * 5
    assert set_v[1:51] == pytest.approx(expected), "scripts see the set speed after each frame"
    rec = read_recording(out)
    standing = [i for i, v in enumerate(expected) if v == 0.0]
    assert result.standing_frames == len(standing) == 13 and rec.meta["summary"]["standing_frames"] == 13
    assert len(rec) == result.frames == 50 - 13
    np.testing.assert_allclose(rec.commands[:, 0], [v for v in expected if v > 0.0], atol=1e-9)
    assert rec.times[32] - rec.times[31] == pytest.approx(0.1 * (1 + 13)), "the stop is a gap in the recording"
    assert (rec.commands[:, 1] == 0.0).all() and (rec.labels == CENTRE).all()


def test_the_status_line_shows_the_vehicles_speed_and_the_set_speed(monkeypatch):
    drawn = _overlays(monkeypatch)
    events = {3: [key(pygame.KEYDOWN, pygame.K_w), key(pygame.KEYUP, pygame.K_w)], 20: [pygame.event.Event(pygame.QUIT)]}
    run_teleop("demo_course", None, realtime=False, wait_for_start=False, script=script_from(events), max_frames=40)
    # From standstill at 1 m/s^2: 0.1 m/s more each 0.1 s frame, up to the set speed.
    assert "v 0.00 m/s (set 1.00)" in drawn[0].status
    assert "v 0.30 m/s (set 1.10)" in drawn[3].status, "the set speed at once, the vehicle's own a while later"
    assert "v 1.10 m/s (set 1.10)" in drawn[15].status


def test_the_throttle_takes_over_from_the_planner_and_is_recorded_as_a_correction(tmp_path):
    """The planner drives; W takes over from the planner's command (its v one step faster, its w
    kept on the stick); 1.5 s untouched hands back."""
    from helpers import linear_model
    from terrapref.teleop import HANDBACK_S

    model = linear_model(tmp_path / "m.safetensors")
    out = tmp_path / "corrections"
    events = {20: [key(pygame.KEYDOWN, pygame.K_w), key(pygame.KEYUP, pygame.K_w)], 80: [pygame.event.Event(pygame.QUIT)]}
    result, drivers, stick = ride_along(out, model, events, v_mps=0.5)  # the driver's own starting speed is not the planner's
    handback = round(HANDBACK_S * 10)
    assert drivers[:21] == ["planner"] * 21 and drivers[21 : 21 + handback + 1] == ["you"] * (1 + handback)
    assert drivers[21 + handback + 1] == "planner"
    rec = read_recording(out)
    assert result.frames == len(rec) == 1 + handback and result.planner_frames == 80 - len(rec)
    assert rec.meta["driver"]["kind"] == "corrections"
    assert rec.commands[:, 0] == pytest.approx([ControlSet().v_mps + 0.1] * len(rec)), "the planner's speed, one step faster"
    assert (rec.commands[:, 1] == stick[21]).all(), "the stick holds the planner's w from the takeover on"
    assert (rec.labels == ControlSet().label_of(rec.commands[:, 1])).all()


def test_a_starting_speed_above_the_vehicles_top_speed_is_a_user_error():
    with pytest.raises(UserError, match=r"speed must be in \(0, 2\] m/s, got 2.5"):
        run_teleop("demo_course", realtime=False, wait_for_start=False, v_mps=2.5, max_frames=1)


# --- relief: the map hillshaded, the body's roll and pitch, a warning near its limits --------------


def test_the_attitude_readout_names_the_limits_and_warns_within_a_fifth_of_them():
    from terrapref.teleop.guide import attitude_readout
    from terrapref.vehicle import VehicleConfig
    from terrapref.vehicle.ground import Attitude

    ugv = VehicleConfig()  # tips past 25 deg of roll, 30 of pitch
    line, warning = attitude_readout(Attitude(0.0, math.radians(-6.0), math.radians(12.0)), ugv)
    assert line == "roll 12 deg left side up (tips at 25), pitch 6 deg nose up (tips at 30)" and warning is None
    assert attitude_readout(Attitude(0.0, 0.0, math.radians(-20.5)), ugv)[1] == "NEAR TIPPING: roll 20 of 25 deg, turn down the slope"
    assert attitude_readout(Attitude(0.0, math.radians(19.9), 0.0), ugv)[1] is None  # under 20 deg: not yet
    assert attitude_readout(Attitude(0.0, math.radians(24.0), 0.0), ugv)[1].startswith("NEAR TIPPING: pitch 24 of 30 deg")


def test_on_relief_the_window_shows_the_bodys_attitude_and_warns_on_a_steep_bank(tmp_path, monkeypatch):
    """Along a bank of 22 deg (a plateau's ramp beside the path): the display gives the roll and,
    past 20 deg of it, the warning; the map in the panel is hillshaded (its grass is not all one colour)."""
    import numpy as np

    from terrapref.scenario import parse_scenario
    from terrapref.teleop.window import Window

    drawn, insets = _overlays(monkeypatch), []
    build = Window._build_inset

    def keep_inset(self):
        build(self)
        insets.append(pygame.surfarray.array3d(self.inset).reshape(-1, 3))

    monkeypatch.setattr(Window, "_build_inset", keep_inset)
    data = {
        "format": "terrapref-scenario/1",
        "name": "bank",
        "world": {"size_m": [30.0, 20.0], "resolution_m": 0.05, "background": "grass"},
        "terrain": [],
        "relief": [{"plateau": {"polygon": [[10.0, 11.0], [30.0, 11.0], [30.0, 20.0], [10.0, 20.0]], "height_m": 1.0, "edge_m": 2.5}}],
        "path": {"waypoints": [[2.0, 9.75], [28.0, 9.75]]},
    }
    result = run_teleop(
        parse_scenario(data), None, realtime=False, wait_for_start=False, max_frames=160, disturbance=None, screenshot=tmp_path / "shot.png"
    )
    # The drive keeps its attitude as a simulated run does (its recording's summary, drive's line).
    summary = result.relief_summary()
    assert (summary["tips"], summary["stuck"]) == (0, 0) and 20.0 < summary["max_roll_deg"] < 25.0
    first, last = drawn[0], drawn[-1]
    assert first.hud[-1] == "roll 0 deg right side up (tips at 25), pitch 0 deg nose up (tips at 30)" and not first.alerts
    # The bank rises to the left of the way (north): the left wheels ride higher.
    assert re.fullmatch(r"roll 2[0-2] deg left side up \(tips at 25\), pitch \d deg nose (up|down) \(tips at 30\)", last.hud[-1])
    assert last.alerts[0].startswith("NEAR TIPPING: roll 2")
    assert len(np.unique(insets[-1], axis=0)) > 5  # grass lit, in shadow and flat: not the one colour of a flat map


def test_a_set_speed_past_the_vehicles_is_refused_naming_the_flag(tmp_path, capsys):
    from helpers import one_line_error
    from terrapref.cli import main

    for speed in ("0", "-1", "9"):
        assert main(["drive", "demo_course", "--speed", speed, "--record", str(tmp_path / "rec")]) == 2
        one_line_error(capsys, "--speed", "(0, 2] m/s")
    assert not (tmp_path / "rec").exists()


def test_riding_along_on_relief_the_planner_reads_the_depth_and_stops_short_of_the_ledge(tmp_path):
    """Riding along, the planner was given the frames without their depth images: on
    `relief_hazards` it drove into the 0.4 m ledge and stood stuck against it, commanding its
    cruising speed, where evaluate's runs of the same model go round it."""
    from test_offset_rule import DRIVER_LIKE, _offset_meta

    from helpers import skip_path_weights
    from terrapref.learning.model_file import save_model
    from terrapref.learning.network import ClassifierConfig

    config = ClassifierConfig(hidden=8, skip=True)
    model = save_model(tmp_path / "m.safetensors", config, skip_path_weights(config), _offset_meta(DRIVER_LIKE))
    result = run_teleop("relief_hazards", None, realtime=False, wait_for_start=False, max_frames=450, model=model, script=lambda _: [])
    assert result.planner_frames == 450 and result.max_pitch_deg > 10.0  # it drove the course's relief
    assert (result.stuck, result.tips, result.collisions) == (0, 0, 0)
