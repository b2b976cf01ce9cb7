"""The driving session: input, the vehicle, the planner when riding along, and the recording.

One loop iteration is one camera frame: handle input, sample the stick, draw, then (while
driving) record the frame with the command (v, w) and its label and step the simulation by one
camera period, through the record loop the synthetic driver uses too
(:class:`~terrapref.demos.session.RecordLoop`). A session goes through these phases:

- ``waiting``: the window is open and nothing moves; the instructions are on screen. Space,
  Enter, P or a gamepad button starts the countdown.
- ``countdown``: three seconds in which the driver can already set the stick and the throttle;
  nothing moves.
- ``driving``: the vehicle moves and frames are recorded. Space/P (or a gamepad button) pauses.
- ``paused``: nothing moves; resuming counts down again.

The command is (v, w): the throttle's set speed (terrapref.teleop.throttle) and the stick's yaw
rate. A set speed of 0 stands the vehicle (it may still turn on the spot); those frames are not
recorded, since a label names one of the control set's arcs, which a standing vehicle does not
follow, and a long stop would fill the recording with one view.

The map's edge is a boundary: when the next frame would bring the vehicle within
:data:`~terrapref.teleop.guide.EDGE_MARGIN_M` of it, the vehicle stops (it may still turn
on the spot, v = 0) and the frame is not recorded, so a recording never holds frames taken off or
at the edge of the map.

Pushes (the session's disturbances, on unless turned off): while one turns the vehicle, an alert
says which way, and the map marks where it began; the start screen says they will come.

Riding along with a model: the planner drives; any stick input (an arrow, Down/C, the mouse
button over the view, the pad off centre) or throttle input (W/S, the mouse wheel, the pad's
throttle axis) takes over from the planner's current command (v and w), and the driver's frames
are recorded as corrections (label: the driver's command); after :data:`HANDBACK_S` without
stick or throttle input the planner drives again. Only the driver's frames are recorded:
those are the situations in which the planner did what the driver would not.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import pygame

from terrapref.camera import CameraConfig
from terrapref.demos.meta import HumanInfo, RideAlongInfo
from terrapref.demos.recording import RecordingWriter
from terrapref.demos.session import DisturbanceConfig, Disturber, DriveSetup, RecordLoop, abort_recording, run_perceiver
from terrapref.errors import Terminated, UserError
from terrapref.features import PreferenceSet, PreferenceSetConfig
from terrapref.perception import PerceptionModel
from terrapref.scenario import Scenario, resolve_scenario
from terrapref.sim import Frame, SimConfig, Simulation
from terrapref.teleop.guide import CourseGuide, attitude_readout, stays_on_map
from terrapref.teleop.stick import Stick
from terrapref.teleop.throttle import PAD_AXIS, Throttle
from terrapref.teleop.window import ALERT_COLOR, HIGHLIGHT_COLOR, PLANNER_COLOR, Banner, Overlay, Window
from terrapref.terrain import PreferenceProfile
from terrapref.vehicle import Command

SOURCE = "terrapref drive"
NO_DISPLAY = "no display available; set SDL_VIDEODRIVER=dummy for a headless run or run on a desktop"

INPUT = "keyboard/mouse/gamepad"  # the devices a person drives with (recorded as the driver's input)
COUNTDOWN_S = 3.0
"""From the start key to the first recorded frame, and again when resuming from a pause [s]."""
HANDBACK_S = 1.5
"""Riding along, the planner drives again after this long without stick or throttle input [s]."""
PUSH_SHOWN_S = 1.0
"""A push's alert stays this long after the push ends, so that a short one is seen too [s]."""

START_KEYS = (pygame.K_SPACE, pygame.K_RETURN, pygame.K_KP_ENTER, pygame.K_p)
QUIT_KEYS = (pygame.K_ESCAPE, pygame.K_q)

INSTRUCTIONS = (
    "Space/Enter  start, pause",
    "Left/Right   move the stick",
    "Down / C     centre it",
    "W / S, wheel faster, slower",
    "mouse drag   steer",
    "Esc / Q      quit",
)
RIDE_ALONG_INSTRUCTIONS = ("stick or throttle takes over", f"{HANDBACK_S:g} s untouched: hands back")


@dataclass(frozen=True)
class TeleopResult:
    """How a driving session ended.

    Attributes:
        frames: frames recorded (when recording) or driven by the person: paused, waiting,
            edge, standing and (riding along) planner frames excluded.
        completed: the vehicle reached the goal.
        collisions: entries of the footprint onto lethal terrain.
        quit: the driver quit (Esc, Q or the window's close button) before the run ended.
        record_dir: the recording's directory, or None when not recording.
        duration_s: simulated time driven [s].
        edge_frames: frames the vehicle was held at the map's edge.
        planner_frames: frames the planner drove (riding along).
        standing_frames: frames the person drove at a set speed of 0.
        contact_s: time with lethal terrain under the footprint [s].
        contact_m: distance driven so [m].
        pushes: pushes that turned the vehicle.
        tips, stuck: on relief, entries past the vehicle's roll or pitch limit, and times a step
            too high held it (terrapref.vehicle.ground).
        max_roll_deg, max_pitch_deg: on relief, the largest roll and pitch of the drive [deg].
    """

    frames: int
    completed: bool
    collisions: int
    quit: bool
    record_dir: Path | None
    duration_s: float = 0.0
    edge_frames: int = 0
    planner_frames: int = 0
    standing_frames: int = 0
    contact_s: float = 0.0
    contact_m: float = 0.0
    pushes: int = 0
    tips: int = 0
    stuck: int = 0
    max_roll_deg: float = 0.0
    max_pitch_deg: float = 0.0

    def relief_summary(self) -> dict[str, Any]:
        """The drive's tips, times stuck and largest roll and pitch [deg], as a simulated run's
        (terrapref.sim.EpisodeLog.relief_summary)."""
        return {
            "tips": self.tips,
            "stuck": self.stuck,
            "max_roll_deg": round(self.max_roll_deg, 2),
            "max_pitch_deg": round(self.max_pitch_deg, 2),
        }


@dataclass(frozen=True)
class TeleopState:
    """What a scripted input (tests, the simulated keyboard driver) sees before a frame.

    Attributes:
        index: loop iteration (0-based).
        frame: the camera frame on screen.
        w: the stick [rad/s] after the last frame.
        v: the throttle's set speed [m/s] after the last frame.
        phase: ``waiting``, ``countdown``, ``driving`` or ``paused``.
        driver: ``you`` or (riding along) ``planner``.
    """

    index: int
    frame: Frame
    w: float
    v: float
    phase: str
    driver: str


Script = Callable[[TeleopState], Sequence[Any]]


@dataclass(frozen=True)
class TeleopOptions:
    """How a driving session runs (:func:`run_session`; by name in :func:`run_teleop`).

    Attributes:
        record_dir: directory for the recording; None drives without recording.
        overwrite: replace an existing recording in ``record_dir`` (only once this one is complete).
        camera: camera configuration (default: the model's when riding along, else SPEC 5).
        preference: preference/control set configuration; its control set labels w (default:
            the model's when riding along).
        sim_config: loop timing and limits.
        v_mps: the throttle's set speed at the start [m/s], in (0, vehicle max speed]; the
            driver moves it in [0, vehicle max speed] while driving.
        realtime: pace the loop at the camera rate for a person; False runs as fast as it can.
        script: ``TeleopState -> events`` posted before each iteration's events are handled
            (tests and the simulated keyboard driver inject key and mouse events this way).
        max_frames: stop after this many loop iterations.
        screenshot: save the last drawn window image to this file (PNG by extension).
        disturbance: pushes added to the executed yaw rate now and then, so that the recording
            shows the driver's recoveries (the stick stays the label); drawn from ``seed``.
        seed: seeds the pushes' stream.
        profile: the driver's declared preference order, stored with the recording (default:
            riding along, the model's; else none: the recording declares no order).
        model: ride along with this model file: the planner drives, the driver's takeovers are
            recorded as corrections.
        wait_for_start: open paused and start after a key and a countdown (False: drive from
            the first frame, as scripted tests do).
        perception: the driver sees the truth; the recording, and a model riding along, get what
            the robot's camera and localisation gave through this model (terrapref.perception).
        live: a live view (terrapref.interop.live.LiveView) every driven frame is sent to.
    """

    record_dir: str | Path | None = None
    overwrite: bool = False
    camera: CameraConfig | None = None
    preference: PreferenceSetConfig | None = None
    sim_config: SimConfig | None = None
    v_mps: float = 1.0
    realtime: bool = True
    script: Script | None = None
    max_frames: int | None = None
    screenshot: str | Path | None = None
    disturbance: DisturbanceConfig | None = None
    seed: int = 0
    profile: PreferenceProfile | None = None
    model: str | Path | None = None
    perception: PerceptionModel | None = None
    wait_for_start: bool = True
    live: Any = None


@dataclass(frozen=True)
class _Setup:
    """A session's drive with its defaults filled in, and the planner riding along (or None)."""

    drive: DriveSetup
    planner: Any
    profile: PreferenceProfile | None = None  # the order the recording declares (None: none)

    @property
    def scenario(self) -> Scenario:
        return self.drive.scenario

    @property
    def sim(self) -> SimConfig:
        return self.drive.sim


def _check_display() -> None:
    """Refuse to open a window nobody can see: SDL would silently fall back to an offscreen one."""
    if os.environ.get("SDL_VIDEODRIVER"):
        return
    if sys.platform.startswith(("linux", "freebsd", "openbsd", "netbsd")) and not (
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    ):
        raise UserError(SOURCE, NO_DISPLAY)


def _open_display() -> None:
    _check_display()
    try:
        pygame.display.init()
    except pygame.error:
        raise UserError(SOURCE, NO_DISPLAY) from None
    if not os.environ.get("SDL_VIDEODRIVER") and pygame.display.get_driver() in ("offscreen", "dummy"):
        pygame.display.quit()
        raise UserError(SOURCE, NO_DISPLAY)
    pygame.font.init()
    pygame.joystick.init()


@dataclass(frozen=True)
class _Held:
    """What a riding-along planner commands before its first frame has reached it: a stop."""

    command: Command = Command(0.0, 0.0)


_NOTHING_YET = _Held()


class _Session:
    """One driving session's state: what a person adds to the record loop (phases, window
    events, the stick and the throttle, riding along, the map's edge). :func:`run_session`
    builds it and runs :meth:`run`."""

    def __init__(self, recorder: RecordLoop, prefs: PreferenceSet, window: Window, planner: Any, options: TeleopOptions) -> None:
        sim = recorder.sim
        self.recorder, self.sim, self.window = recorder, sim, window
        self.control = prefs.config.control
        self.frame_dt = 1.0 / sim.config.camera_rate_hz
        self.guide = CourseGuide(sim.world, sim.path, prefs)
        self.stick = Stick(
            w_max_rps=float(np.abs(self.control.w_rps).max()), view_width_px=window.view_size[0], view_height_px=window.view_size[1]
        )
        self.throttle = Throttle(options.v_mps, sim.config.vehicle.max_speed_mps)
        self.command = Command(self.throttle.v, 0.0)  # the command of the last frame drawn
        self.planner = planner
        self.driver = "planner" if planner is not None else "you"
        self.idle_s = 0.0
        self.phase = "waiting" if options.wait_for_start else "driving"
        self.countdown_left = 0
        self.quit = False
        self.at_edge = False
        self.recorded = self.edge_frames = self.planner_frames = self.standing_frames = 0
        self.disturbance = options.disturbance if options.disturbance is not None and options.disturbance.active else None
        self.pushing = False  # the last driven frame was pushed
        self.push_rps = 0.0  # the last push [rad/s]
        self.push_shown_s = 0.0  # how much longer the last push's alert stays [s]
        self.pushes = 0
        self.pushes_px: list[tuple[float, float]] = []
        self.frame = sim.reset()
        if planner is not None:
            planner.set_path(sim.scenario.waypoints)
        self.decision: Any = _NOTHING_YET
        self.decision = self._decide()
        self.trace_px = [window.to_inset(self.frame.pose.x, self.frame.pose.y)]
        self.live = None
        if options.live is not None:
            from terrapref.interop.live import LiveRun

            self.live = LiveRun.start(options.live, sim.scenario.waypoints, sim.camera.config, sim.scenario.classes, prefs.config)

    def _decide(self) -> Any:
        """The planner's decision on the frame that reached the robot in this period (once per
        period, so its path tracker keeps up); the last one while none arrives."""
        if self.planner is None:
            return None
        got = self.recorder.perceive(self.frame)
        return self.planner.decide_frame(got) if got is not None else self.decision  # on relief with its depth, as evaluate's

    # --- input --------------------------------------------------------------------------------

    def _toggle(self) -> None:
        if self.phase in ("waiting", "paused"):
            self.phase, self.countdown_left = "countdown", round(COUNTDOWN_S / self.frame_dt)
        elif self.phase == "driving":
            self.phase = "paused"

    def _follow_planner(self) -> None:
        """Rest the stick and the throttle at the planner's command, so that a takeover starts from it."""
        v, w = self.decision.command
        self.stick.follow(float(w))
        self.throttle.follow(float(v))

    def handle_events(self) -> None:
        if self.driver == "planner":
            self._follow_planner()
        for event in pygame.event.get():
            if event.type == pygame.QUIT or (event.type == pygame.KEYDOWN and event.key in QUIT_KEYS):
                self.quit = True
            elif event.type == pygame.VIDEORESIZE:
                self.window.resize(event.size)
            elif (event.type == pygame.KEYDOWN and event.key in START_KEYS) or event.type == pygame.JOYBUTTONDOWN:
                self._toggle()
            elif event.type in (pygame.MOUSEBUTTONDOWN, pygame.MOUSEBUTTONUP, pygame.MOUSEMOTION):
                self.stick.handle(pygame.event.Event(event.type, {**event.dict, "pos": self.window.to_canvas(event.pos)}))
            else:
                self.stick.handle(event)
                self.throttle.handle(event)

    def _who_drives(self) -> None:
        """Riding along: stick or throttle input takes the vehicle over; both left alone hand it back."""
        if self.planner is None:
            return
        used = self.stick.touched or self.stick.active or self.throttle.touched or self.throttle.active
        self.stick.touched = self.throttle.touched = False
        if self.phase != "driving":
            return
        if self.driver == "planner" and used:
            self.driver, self.idle_s = "you", 0.0
        elif self.driver == "you":
            if used:
                self.idle_s = 0.0
            elif self.idle_s >= HANDBACK_S - 0.5 * self.frame_dt:  # the driver's last HANDBACK_S were untouched
                self.driver = "planner"
                self._follow_planner()
            else:
                self.idle_s += self.frame_dt

    # --- one frame ----------------------------------------------------------------------------

    def tick(self) -> None:
        self.handle_events()
        if self.quit:
            return
        w = self.stick.update(self.frame_dt)
        v = self.throttle.update(self.frame_dt, self.stick.axis(PAD_AXIS))
        self._who_drives()
        self.command = Command(v, w) if self.driver == "you" else Command(*(float(c) for c in self.decision.command))
        label = int(self.control.label_of(self.command.w))
        self.draw(self.command, label)
        if self.phase == "countdown":
            self.countdown_left -= 1
            if self.countdown_left <= 0:
                self.phase = "driving"
        elif self.phase == "driving":
            self.drive(self.command)

    def drive(self, command: Command) -> None:
        """One driven frame of ``command``, the driver's (the throttle's v [m/s] and the stick's w
        [rad/s]) or the planner's: held at the map's edge where it must be, recorded only where
        the person drove at a set speed above 0."""
        executed = self.recorder.executed(command)
        self._note_push(float(executed[1]) - float(command[1]))
        vehicle = self.sim.vehicle
        brake_m = vehicle.config.braking_distance_m(max(vehicle.speed_mps, float(executed[0])))
        self.at_edge = not stays_on_map(self.sim.world, self.frame.pose, executed, self.frame_dt, brake_m=brake_m)
        kept = self.driver == "you" and not self.at_edge and command.v > 0.0
        if self.at_edge:
            executed = Command(0.0, executed[1])  # held at the edge: it may turn on the spot
            self.edge_frames += 1
        elif kept:
            self.recorded += 1
        elif self.driver == "you":
            self.standing_frames += 1
        else:
            self.planner_frames += 1
        if self.live is not None:
            self._send(executed, label_w=command.w)
        self.frame = self.recorder.record_step(self.frame, command, executed, record=kept)
        self.decision = self._decide()
        self.trace_px.append(self.window.to_inset(self.frame.pose.x, self.frame.pose.y))

    def _note_push(self, push_rps: float) -> None:
        """Keep what the display shows of the pushes: the one turning the vehicle now (``push_rps``
        [rad/s], 0 for none), how many there were, and where each began."""
        if push_rps != 0.0:
            if not self.pushing or (push_rps > 0) != (self.push_rps > 0):
                self.pushes += 1
                self.pushes_px.append(self.window.to_inset(self.frame.pose.x, self.frame.pose.y))
            self.push_rps, self.push_shown_s = push_rps, PUSH_SHOWN_S
        else:
            self.push_shown_s -= self.frame_dt
        self.pushing = push_rps != 0.0

    def push_alert(self) -> str | None:
        """The alert of the push turning the vehicle now or a moment ago ("PUSHED LEFT ..."); None without one."""
        if self.push_shown_s <= 0.0 or self.push_rps == 0.0:
            return None
        return f"PUSHED {'LEFT' if self.push_rps > 0 else 'RIGHT'} ({abs(self.push_rps):.2f} rad/s): steer back"

    def _send(self, executed: Command, label_w: float) -> None:
        """The frame just driven to the live view: what the camera shows, the pose, the command;
        riding along, the planner's F_t and once a second its costmap."""
        from terrapref.interop.live import planner_costmap
        from terrapref.interop.mcap_export import FrameData

        riding = self.planner is not None and self.decision is not _NOTHING_YET
        pose = self.frame.pose
        self.live.frame(
            FrameData(
                self.frame.time_s,
                (pose.x, pose.y, pose.yaw),
                (float(executed[0]), float(executed[1])),
                self.frame.view.image,
                int(self.control.label_of(label_w)),
                self.decision.probs if riding and self.driver == "planner" else None,
            ),
            planner_costmap(self.planner) if riding else None,
        )

    # --- drawing ----------------------------------------------------------------------------

    def banner(self) -> Banner | None:
        if self.phase == "waiting":
            what = (
                "The planner drives; steer to correct it."
                if self.planner is not None
                else "Drive along the magenta path the way you like to drive."
            )
            if self.disturbance is not None:
                every_s = 1.0 / self.disturbance.rate_hz
                pushes = (
                    f"Pushes (about every {every_s:.0f} s, never near lethal terrain) turn the",
                    "vehicle off its line, as a rut would: steer back (red alert).",
                    "(terrapref drive --disturb 0: no pushes)",
                )
            else:
                pushes = ("No pushes: the vehicle goes where you steer.",)
            return Banner(
                "Press Space to start",
                HIGHLIGHT_COLOR,
                (
                    what,
                    "The white arcs are the turns you can take; yours is yellow.",
                    "Left/Right move the stick, which stays where you leave it;",
                    "Down or C centres it. Or hold the left mouse button over",
                    "this view (the pointer's position steers), or use a gamepad.",
                    f"W / S or the mouse wheel set the speed (at first {self.throttle.v:g} m/s),",
                    "which holds until you change it; at 0 the vehicle stands.",
                    "Recording starts after a 3 s countdown. Space pauses.",
                    *pushes,
                ),
            )
        if self.phase == "countdown":
            return Banner(str(max(1, math.ceil(self.countdown_left * self.frame_dt))), HIGHLIGHT_COLOR)
        if self.phase == "paused":
            return Banner("PAUSED", ALERT_COLOR, ("Space to resume (after a countdown)",))
        if self.at_edge:
            return Banner("MAP EDGE", ALERT_COLOR, ("The vehicle stopped: turn back onto the map.", "Frames here are not recorded."))
        return None

    def draw(self, command: Command, label: int, end_banner: Banner | None = None, note: str = "") -> None:
        readout = self.guide.readout(self.frame.pose, self.sim.progress_m, label, self.at_edge, self.sim.vehicle.speed_mps)
        mode = None
        if self.planner is not None:
            mode = ("PLANNER DRIVING", PLANNER_COLOR) if self.driver == "planner" else ("YOU DRIVE: recording corrections", HIGHLIGHT_COLOR)
            if self.driver == "planner" and self.decision is not None and self.decision.stop is not None:
                mode = (f"PLANNER STOPPED: {self.decision.stop}", ALERT_COLOR)
        hud, tipping = readout.lines(), None
        if self.sim.world.has_relief:  # the body's roll and pitch, and a warning near its limits
            line, tipping = attitude_readout(self.sim.vehicle.attitude, self.sim.vehicle.config)
            hud = [*hud, line]
        alerts = tuple(a for a in (tipping, self.push_alert(), readout.warning()) if a is not None)
        overlay = Overlay(
            self.status(command, label) + note,
            hud,
            end_banner or self.banner(),
            mode,
            alerts=alerts,
            route_rad=readout.rejoin_rad,
            off_route=readout.off_route,
            pushes_px=self.pushes_px,
        )
        self.window.draw(self.frame.image, command.w, label, self.trace_px, overlay)

    def status(self, command: Command, label: int) -> str:
        """The line under the view: time, the vehicle's speed and the set one (``command``'s v
        [m/s]), ``command``'s w [rad/s] and its label, frames, collisions, and the phase unless driving."""
        parts = [
            f"t {self.sim.time_s:6.1f} s",
            f"v {self.sim.vehicle.speed_mps:.2f} m/s (set {command.v:.2f})",
            f"w {command.w:+.2f} rad/s",
            f"label {label:2d}/{self.control.m - 1}",
            f"{'rec' if self.recorder.writer is not None else 'frames'} {self.recorded}",
            f"collisions {self.sim.collisions}",
        ]
        if self.disturbance is not None:
            parts.append(f"pushes {self.pushes}")
        if self.phase != "driving":
            parts.append(self.phase.upper())
        return "   ".join(parts)

    def run(self, max_frames: int | None, script: Script | None, realtime: bool) -> None:
        """Loop over camera frames until the run ends, the driver quits or ``max_frames`` iterations have passed."""
        clock = pygame.time.Clock()
        i = 0
        while not self.sim.done and (max_frames is None or i < max_frames):
            if script is not None:
                for event in script(TeleopState(i, self.frame, self.stick.w, self.throttle.v, self.phase, self.driver)):
                    pygame.event.post(event)
            self.tick()
            if self.quit:
                break
            i += 1
            if realtime:
                clock.tick(self.sim.config.camera_rate_hz)

    def show_end(self, screenshot: str | Path | None) -> Banner | None:
        """Draw how the run ended and save the window to ``screenshot``; returns the end banner (None: neither goal nor time up)."""
        end = Banner("GOAL") if self.sim.reached_goal else Banner("TIME UP", ALERT_COLOR) if self.sim.timed_out else None
        self.draw(self.command, int(self.control.label_of(self.command.w)), end, "   quit" if self.quit else "   done")
        if screenshot is not None:
            self.window.save(str(screenshot))
        return end

    def result(self, record_dir: str | Path | None) -> TeleopResult:
        """How the session ended."""
        return TeleopResult(
            frames=self.recorded,
            completed=self.sim.reached_goal,
            collisions=self.sim.collisions,
            quit=self.quit,
            record_dir=Path(record_dir) if record_dir is not None else None,
            duration_s=self.sim.time_s,
            edge_frames=self.edge_frames,
            planner_frames=self.planner_frames,
            standing_frames=self.standing_frames,
            contact_s=self.sim.contact_s,
            contact_m=self.sim.contact_m,
            pushes=self.pushes,
            tips=self.sim.tips,
            stuck=self.sim.stuck,
            max_roll_deg=self.sim.max_roll_deg,
            max_pitch_deg=self.sim.max_pitch_deg,
        )


def _summary(result: TeleopResult) -> dict[str, Any]:
    """What the recording's metadata keeps of the session (on relief, its tips, times stuck and
    largest roll and pitch too, as a simulated run's)."""
    summary = {
        "completed": result.completed,
        "collisions": result.collisions,
        "duration_s": round(result.duration_s, 3),
        "contact_s": round(result.contact_s, 3),
        "contact_m": round(result.contact_m, 3),
        "quit": result.quit,
        "edge_frames": result.edge_frames,
        "planner_frames": result.planner_frames,
        "standing_frames": result.standing_frames,
    }
    if result.tips or result.stuck or result.max_roll_deg or result.max_pitch_deg:
        summary.update(result.relief_summary())
    return summary


def run_teleop(scenario: Scenario | str, record_dir: str | Path | None = None, **options: Any) -> TeleopResult:
    """Drive ``scenario`` by keyboard, mouse or gamepad in a window, recording into ``record_dir``
    if given; ``options`` are :class:`TeleopOptions`' other fields, by name (a shorthand for
    :func:`run_session`, which says when the run ends and what it raises).
    """
    return run_session(scenario, TeleopOptions(record_dir=record_dir, **options))


def run_session(scenario: Scenario | str, options: TeleopOptions) -> TeleopResult:
    """Drive ``scenario`` in a window as ``options`` say, recording to ``options.record_dir`` if set.

    The run ends at the goal, at the time limit, on quit, or after ``options.max_frames`` loop
    iterations (waiting, countdown and paused ones included, so a scripted run always ends). The
    recording is closed complete in all those cases (its summary says which); an exception
    leaves the old recording in place and the unfinished one beside it (``RecordingWriter``).

    Raises:
        UserError: no display, a bad speed, an unreadable model, or a recording that already
            exists (without ``options.overwrite``).
    """
    setup = _resolve(scenario, options)
    _open_display()
    writer: RecordingWriter | None = None
    ending = False
    try:
        sim, prefs, window = _open_window(setup, options.record_dir)
        writer = _open_recording(setup, options)
        recorder = RecordLoop(
            sim,
            writer,
            prefs.config.control,
            _disturber(options, 1.0 / setup.sim.camera_rate_hz),
            run_perceiver(options.perception, sim, np.random.default_rng([options.seed, 1])),
        )
        session = _Session(recorder, prefs, window, setup.planner, options)
        session.run(options.max_frames, options.script, options.realtime)
        end = session.show_end(options.screenshot)
        result = session.result(options.record_dir)
        if setup.planner is not None and writer is not None and writer.count == 0:  # rode along, never took over
            writer.abort()  # no correction: no recording (an old one at the folder stays)
            result = replace(result, record_dir=None)
        else:
            recorder.close(_summary(result))
        writer = None
        if options.realtime and end is not None:
            pygame.time.wait(1000)  # let the driver see how the run ended before the window closes
        return result
    except BaseException as exc:
        if writer is not None:
            abort_recording(writer)
        ending = isinstance(exc, Terminated)  # SIGTERM: the process is ending; SDL's teardown can wait on its timer thread
        raise
    finally:
        if not ending:
            pygame.quit()


def _resolve(scenario: Scenario | str, options: TeleopOptions) -> _Setup:
    """The scenario and configurations the session drives with, checked, and the planner riding along."""
    scenario = resolve_scenario(scenario) if isinstance(scenario, str) else scenario
    sim_cfg = options.sim_config or DriveSetup.of(scenario, person=True).sim  # a person may stand still as long as they like
    if not 0.0 < options.v_mps <= sim_cfg.vehicle.max_speed_mps:
        raise UserError(SOURCE, f"speed must be in (0, {sim_cfg.vehicle.max_speed_mps:g}] m/s, got {options.v_mps:g}", field="--speed")
    if options.max_frames is not None and options.max_frames < 0:
        raise UserError(SOURCE, "max_frames must be >= 0", field="max_frames")
    camera, preference, planner, profile = options.camera, options.preference, None, options.profile
    if options.model is not None:
        camera, preference, planner, learned_from = _load_planner(options.model, camera, preference)
        # The person riding along is the driver the model learned from: their drive's order, unless told another.
        profile = profile or learned_from
    return _Setup(DriveSetup(scenario, camera or CameraConfig(), sim_cfg, preference or PreferenceSetConfig()), planner, profile)


def _load_planner(
    model: str | Path, camera: CameraConfig | None, preference: PreferenceSetConfig | None
) -> tuple[CameraConfig, PreferenceSetConfig, Any, PreferenceProfile | None]:
    """The planner of the model file ``model``, with the camera and preference set it needs where not
    given, and the order the model's drive declared (None: none)."""
    from terrapref.learning.model_file import load_model
    from terrapref.planner import Planner

    loaded = load_model(model)
    camera = camera or loaded.camera
    preference = preference or loaded.features.preference
    declared = PreferenceProfile(loaded.profile) if loaded.profile else None
    try:
        return camera, preference, Planner(loaded, camera), declared
    except ValueError as exc:
        raise UserError(str(model), str(exc), field="camera") from None


def _open_window(setup: _Setup, record_dir: str | Path | None) -> tuple[Simulation, PreferenceSet, Window]:
    """The simulation, its preference set and the window that shows them."""
    sim = setup.drive.simulation()
    prefs = PreferenceSet(setup.drive.preference, sim.camera)
    instructions = INSTRUCTIONS + (RIDE_ALONG_INSTRUCTIONS if setup.planner is not None else ())
    title = f"terrapref drive - {setup.scenario.name}" + (f" -> {record_dir}" if record_dir else "")
    return sim, prefs, Window(sim, prefs, title, instructions)


def _open_recording(setup: _Setup, options: TeleopOptions) -> RecordingWriter | None:
    """The recording the session writes, with who drove and how in its metadata; None when not recording."""
    if options.record_dir is None:
        return None
    pushes = options.disturbance.to_dict() if options.disturbance else None
    driver = (
        HumanInfo(INPUT, pushes, options.seed) if setup.planner is None else RideAlongInfo(INPUT, pushes, options.seed, str(options.model))
    )
    meta = setup.drive.meta(driver, setup.profile, options.perception)
    return RecordingWriter(options.record_dir, meta, setup.scenario.to_dict(), overwrite=options.overwrite, flag="--record")


def _disturber(options: TeleopOptions, frame_dt_s: float) -> Disturber | None:
    """The session's pushes, drawn from ``options.seed``; None when off."""
    disturbance = options.disturbance
    return Disturber(disturbance, np.random.default_rng(options.seed), frame_dt_s) if disturbance and disturbance.active else None
