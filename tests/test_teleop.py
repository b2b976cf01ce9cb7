"""The teleop window driven headless: SDL's dummy video driver and scripted key events."""

from __future__ import annotations

import os
import subprocess
import sys

os.environ.setdefault("SDL_VIDEODRIVER", "dummy")
os.environ.setdefault("SDL_AUDIODRIVER", "dummy")

import pytest

pygame = pytest.importorskip("pygame")

from terrapref.demos.recording import read_recording  # noqa: E402
from terrapref.demos.teleop import run_teleop  # noqa: E402
from terrapref.errors import UserError  # noqa: E402
from terrapref.vehicle import ControlSet  # noqa: E402

CENTRE = 10  # index of w = 0 in the default control set


def key(kind: int, k: int) -> pygame.event.Event:
    return pygame.event.Event(kind, key=k, mod=0, unicode="", scancode=0)


def script_from(events: dict[int, list]) -> callable:
    return lambda i: events.get(i, [])


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
    result = run_teleop("demo_course", out, realtime=False, script=script_from(events), max_frames=200,
                        screenshot=tmp_path / "shot.png")
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
        30: [pygame.event.Event(pygame.QUIT)],
    }
    result = run_teleop("demo_course", out, realtime=False, script=script_from(events), max_frames=100)
    rec = read_recording(out)
    assert result.frames == len(rec) == 20  # iterations 10..19 were paused
    dt = rec.times[1:] - rec.times[:-1]
    assert dt.max() == pytest.approx(0.1, abs=1e-6), "time does not advance while paused"


def test_max_frames_stops_the_run(tmp_path):
    result = run_teleop("demo_course", tmp_path / "rec", realtime=False, max_frames=12)
    assert result.frames == 12 and not result.quit
    assert len(read_recording(tmp_path / "rec")) == 12


def test_driving_without_recording(tmp_path):
    result = run_teleop("demo_course", None, realtime=False, max_frames=5)
    assert result.record_dir is None and result.frames == 5


def test_refuses_to_overwrite_a_recording_unless_told(tmp_path):
    out = tmp_path / "rec"
    run_teleop("demo_course", out, realtime=False, max_frames=3)
    with pytest.raises(UserError):
        run_teleop("demo_course", out, realtime=False, max_frames=3)
    result = run_teleop("demo_course", out, realtime=False, max_frames=4, overwrite=True)
    assert len(read_recording(out)) == result.frames == 4


# --- added with the teleop module: closed forms, user errors, import isolation ------------------


def test_ramp_and_axis_closed_forms():
    from terrapref.demos.teleop import axis_to_w, ramp_toward

    assert ramp_toward(0.0, 1.0, 2.5, 0.1) == pytest.approx(0.25)  # 2.5 rad/s per s for one 10 Hz frame
    assert ramp_toward(0.9, 1.0, 2.5, 0.1) == 1.0  # lands exactly on the target
    assert ramp_toward(0.5, -1.0, 2.5, 0.1) == pytest.approx(0.25)
    assert axis_to_w(0.05, 1.0) == 0.0  # inside the deadzone
    assert axis_to_w(1.0, 1.0) == -1.0  # stick right turns right (w < 0)
    assert axis_to_w(-0.5, 1.0) == pytest.approx(0.5)


def test_keyboard_ramp_labels_and_screenshot(tmp_path):
    out = tmp_path / "rec"
    events = {2: [key(pygame.KEYDOWN, pygame.K_LEFT)], 8: [key(pygame.KEYUP, pygame.K_LEFT)], 10: [pygame.event.Event(pygame.QUIT)]}
    result = run_teleop("demo_course", out, realtime=False, script=script_from(events), max_frames=40, screenshot=tmp_path / "shot.png")
    assert result.frames == 10 and result.duration_s == pytest.approx(1.0)
    rec = read_recording(out)
    assert rec.meta["driver"] == {"kind": "human", "input": "keyboard/mouse/gamepad", "disturbance": None, "seed": 0}
    assert rec.meta["summary"]["quit"] is True
    # 0.1 rad/s per frame, one control-set bin a frame; released at frame 8, the stick stays at 0.6.
    assert rec.commands[2:10, 1] == pytest.approx([0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.6, 0.6])
    assert list(rec.labels[2:8]) == [11, 12, 13, 14, 15, 16]
    assert rec.poses[8, 2] > rec.poses[2, 2], "turning left raises the heading"
    assert pygame.image.load(str(tmp_path / "shot.png")).get_size() == (640 + 256, 480 + 26)


def test_bad_speed_is_a_user_error():
    with pytest.raises(UserError, match="speed"):
        run_teleop("demo_course", realtime=False, v_mps=0.0, max_frames=1)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="display detection by environment is Linux-specific")
def test_no_display_is_a_user_error(monkeypatch, tmp_path):
    for name in ("SDL_VIDEODRIVER", "DISPLAY", "WAYLAND_DISPLAY"):
        monkeypatch.delenv(name, raising=False)
    with pytest.raises(UserError, match="no display available"):
        run_teleop("demo_course", tmp_path / "rec", realtime=False, max_frames=1)
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
    run_teleop("demo_course", out, realtime=False, max_frames=120, disturbance=DisturbanceConfig(rate_hz=2.0), seed=3)
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
    run_teleop("demo_course", out, realtime=False, script=script_from(events), max_frames=100)
    rec = read_recording(out)
    w = rec.commands[:, 1]
    assert w[5] == pytest.approx(0.1) and rec.labels[5] == CENTRE + 1, "one frame of LEFT: the next bin, and it stays"
    assert (w[5:10] == w[5]).all()
    assert w[11] == pytest.approx(0.5) and w[15] == pytest.approx(-0.5), "pointer a quarter from the left: half left lock, and back"
    assert (w[18:22] == w[17]).all(), "released, the stick stays where the pointer left it"
