"""The teleop window driven headless: SDL's dummy video driver and scripted key events."""

from __future__ import annotations

import os

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
    assert (rec.labels[18:25] == CENTRE).all() and (w[18:25] == 0.0).all(), "a released stick rests at exactly zero"
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
