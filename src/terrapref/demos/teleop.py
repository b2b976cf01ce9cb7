"""A keyboard/gamepad driving window in which a person records demonstrations (SPEC 10).

This is the only module in terrapref that imports pygame, and nothing imports it at package
import time: the CLI loads it when ``terrapref drive`` runs, so the rest of the project works
without pygame installed (``pip install terrapref[teleop]`` adds it).

The window shows what the learner will see, the camera's segmentation image, with the preference
set S drawn on it and the trajectory of the current stick's label highlighted, so the driver
sees which discrete command each stick position is recorded as. A top-down inset of the map
shows the reference path, the vehicle and its trace, and a status line shows time, w, label,
frames recorded, pause and collisions.

Controls: Left/Right move the stick (holding an arrow moves w toward +w_max / -w_max at
KEY_RATE_RPS2; releasing leaves it where it is, so a keyboard can hold a gentle curve), Down or C
centres it (exactly 0), holding the left mouse button over the camera view sets w by the
pointer's horizontal position (centre: straight; edges: full lock), gamepad axis 0 sets w
continuously, Space or P pauses, Esc or Q quits. The input last used drives. The stick is
sampled once per camera frame, as the simulated vehicle is.
"""

from __future__ import annotations

import math
import os
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
import pygame  # noqa: E402  (the prompt variable must be set before the import)

from terrapref.camera import CameraConfig  # noqa: E402
from terrapref.demos.recording import RecordingWriter  # noqa: E402
from terrapref.demos.session import DisturbanceConfig, Disturber, recording_meta  # noqa: E402
from terrapref.errors import UserError  # noqa: E402
from terrapref.features import PreferenceSet, PreferenceSetConfig  # noqa: E402
from terrapref.scenario import Scenario, resolve_scenario  # noqa: E402
from terrapref.sim import SimConfig, Simulation  # noqa: E402
from terrapref.terrain import PreferenceProfile  # noqa: E402
from terrapref.vehicle import Command, ControlSet  # noqa: E402

SOURCE = "terrapref drive"
NO_DISPLAY = "no display available; set SDL_VIDEODRIVER=dummy for a headless run or run on a desktop"

KEY_RATE_RPS2 = 1.0
"""How fast a held arrow key moves w [rad/s per s]: one control-set step (0.1 rad/s) per frame,
full lock (1 rad/s) in 1 s; released, the stick stays where it was left."""
AXIS_DEADZONE = 0.08
"""Gamepad axis values within this of 0 read as a centred stick (worn sticks rest slightly off 0)."""

INSET_WIDTH_PX = 240
PANEL_MARGIN_PX = 8
STATUS_HEIGHT_PX = 26

# Drawing colours (RGB). Trajectories are light on every terrain colour; the highlight is a
# saturated yellow with a dark outline so it stays distinct over sky blue, grass and mud alike.
TRAJ_COLOR = (236, 236, 236)
HIGHLIGHT_COLOR = (255, 226, 0)
OUTLINE_COLOR = (20, 20, 20)
PANEL_BG = (28, 30, 34)
TEXT_COLOR = (230, 230, 230)
DIM_TEXT = (150, 154, 160)
PATH_COLOR = (255, 255, 255)
TRACE_COLOR = (232, 40, 200)
VEHICLE_COLOR = (255, 226, 0)
PAUSE_COLOR = (255, 90, 70)


@dataclass(frozen=True)
class TeleopResult:
    """How a driving session ended.

    Attributes:
        frames: camera frames driven (and recorded, when recording); paused frames excluded.
        completed: the vehicle reached the goal.
        collisions: entries onto lethal terrain.
        quit: the driver quit (Esc, Q or the window's close button) before the run ended.
        record_dir: the recording's directory, or None when not recording.
        duration_s: simulated time driven [s].
    """

    frames: int
    completed: bool
    collisions: int
    quit: bool
    record_dir: Path | None
    duration_s: float = 0.0


def ramp_toward(w: float, target: float, rate_rps2: float, dt_s: float) -> float:
    """Move ``w`` [rad/s] toward ``target`` by at most ``rate_rps2 * dt_s``; exact once there."""
    step = rate_rps2 * dt_s
    if abs(target - w) <= step:
        return target
    return w + math.copysign(step, target - w)


def axis_to_w(axis: float, w_max_rps: float, deadzone: float = AXIS_DEADZONE) -> float:
    """Yaw rate [rad/s] of a gamepad axis in [-1, 1] (right is positive, w left is positive)."""
    if abs(axis) <= deadzone:
        return 0.0
    return float(np.clip(-axis * w_max_rps, -w_max_rps, w_max_rps))


class _Stick:
    """The driver's input: arrow keys (a stick that holds where it is left), the mouse over the
    camera view, and the first gamepad axis; the one used last drives."""

    def __init__(self, w_max_rps: float, rate_rps2: float = KEY_RATE_RPS2, view_width_px: int = 640) -> None:
        self.w_max = w_max_rps
        self.rate = rate_rps2
        self.view_width = view_width_px
        self.w = 0.0
        self.left = False
        self.right = False
        self.mouse_x: float | None = None  # pointer x while the left button is held over the view
        self.source = "keys"
        self.joystick: Any = None
        self._open_joystick()

    def _open_joystick(self) -> None:
        if self.joystick is None and pygame.joystick.get_count() > 0:
            self.joystick = pygame.joystick.Joystick(0)
            self.joystick.init()

    def handle(self, event: Any) -> None:
        if event.type in (pygame.KEYDOWN, pygame.KEYUP):
            down = event.type == pygame.KEYDOWN
            if event.key == pygame.K_LEFT:
                self.left, self.source = down, "keys"
            elif event.key == pygame.K_RIGHT:
                self.right, self.source = down, "keys"
            elif down and event.key in (pygame.K_DOWN, pygame.K_c):
                self.w, self.source = 0.0, "keys"
        elif event.type == pygame.MOUSEBUTTONDOWN and event.button == 1 and event.pos[0] < self.view_width:
            self.mouse_x, self.source = float(event.pos[0]), "mouse"
        elif event.type == pygame.MOUSEMOTION and self.mouse_x is not None:
            self.mouse_x = float(min(max(event.pos[0], 0), self.view_width))
        elif event.type == pygame.MOUSEBUTTONUP and event.button == 1:
            self.mouse_x = None  # the stick stays where the pointer left it
        elif event.type == pygame.WINDOWFOCUSLOST:
            # A key released while another window has focus never sends KEYUP here.
            self.left = self.right = False
            self.mouse_x = None
        elif event.type == pygame.JOYDEVICEADDED:
            self._open_joystick()
        elif event.type == pygame.JOYDEVICEREMOVED:
            self.joystick = None

    def update(self, dt_s: float) -> float:
        """Sample the stick for one frame of ``dt_s`` [s]; returns w [rad/s]."""
        pad = self.joystick.get_axis(0) if self.joystick is not None and self.joystick.get_numaxes() > 0 else 0.0
        if abs(pad) > AXIS_DEADZONE:
            self.source = "pad"
        if self.left != self.right:
            target = self.w_max if self.left else -self.w_max
            self.w = ramp_toward(self.w, target, self.rate, dt_s)
        elif self.source == "mouse" and self.mouse_x is not None:
            centre = self.view_width / 2
            self.w = float(np.clip((centre - self.mouse_x) / centre * self.w_max, -self.w_max, self.w_max))
        elif self.source == "pad":
            self.w = axis_to_w(pad, self.w_max)
        return self.w


class _Window:
    """Drawing only: the camera view with S, the map inset and the status line."""

    def __init__(self, sim: Simulation, prefs: PreferenceSet, title: str) -> None:
        self.sim = sim
        self.palette = sim.world.classes.palette()
        rows, cols = sim.camera.shape
        self.view_size = (cols, rows)
        self.panel_x = cols
        panel_w = INSET_WIDTH_PX + 2 * PANEL_MARGIN_PX
        self.size = (cols + panel_w, rows + STATUS_HEIGHT_PX)
        pygame.display.set_caption(title)
        self.screen = pygame.display.set_mode(self.size)
        self.font = pygame.font.Font(None, 20)
        self.big_font = pygame.font.Font(None, 56)
        self.segments = self._trajectory_segments(prefs)
        self.control = prefs.config.control
        self._build_inset()

    # --- computed once ------------------------------------------------------------------------

    def _trajectory_segments(self, prefs: PreferenceSet) -> list[list[list[tuple[float, float]]]]:
        """Per trajectory, its runs of consecutive visible points as pixel polylines.

        A tight arc can leave the image and come back (w = 1 rad/s over 6 m is almost a full
        circle), so each visible run is drawn on its own rather than joined across the gap.
        """
        uv, visible = self.sim.camera.project_ground(prefs.trajectories[..., :2])
        out = []
        for i in range(prefs.m):
            runs: list[list[tuple[float, float]]] = []
            current: list[tuple[float, float]] = []
            for (u, v), ok in zip(uv[i], visible[i], strict=True):
                if ok:
                    current.append((float(u), float(v)))
                elif current:
                    runs.append(current)
                    current = []
            if current:
                runs.append(current)
            out.append(runs)
        return out

    def _build_inset(self) -> None:
        """The map, north up, coloured by class and downsampled by plain slicing."""
        world = self.sim.world
        ny, nx = world.raster.shape
        w_m, h_m = world.size_m
        max_h = self.view_size[1] - 160  # leave room below for the stick gauge and legend
        scale = min(INSET_WIDTH_PX / w_m, max_h / h_m)  # [px/m]
        self.inset_scale = scale
        self.inset_size = (max(1, round(w_m * scale)), max(1, round(h_m * scale)))
        step = max(1, int(min(nx / self.inset_size[0], ny / self.inset_size[1])))
        small = world.raster[::step, ::step][::-1]  # row 0 is south in the raster; north up here
        rgb = np.ascontiguousarray(self.palette[small])
        surf = pygame.image.frombuffer(rgb.tobytes(), (rgb.shape[1], rgb.shape[0]), "RGB")
        self.inset = pygame.transform.smoothscale(surf, self.inset_size)
        self.inset_origin = (self.panel_x + PANEL_MARGIN_PX, PANEL_MARGIN_PX + 18)
        self.inset_h_m = h_m
        self.path_px = [self.to_inset(x, y) for x, y in self.sim.path.waypoints]

    def to_inset(self, x: float, y: float) -> tuple[float, float]:
        """Screen pixel of world point (x, y) [m] in the inset."""
        ox, oy = self.inset_origin
        return ox + x * self.inset_scale, oy + (self.inset_h_m - y) * self.inset_scale

    # --- per frame ----------------------------------------------------------------------------

    def draw(self, image: np.ndarray, w: float, label: int, trace_px: Sequence[tuple[float, float]], status: str, paused: bool, banner: str = "") -> None:
        screen = self.screen
        screen.fill(PANEL_BG)
        rgb = np.ascontiguousarray(self.palette[image])
        screen.blit(pygame.image.frombuffer(rgb.tobytes(), self.view_size, "RGB"), (0, 0))
        self._draw_trajectories(label)
        self._draw_inset(trace_px)
        self._draw_gauge(w, label)
        self._draw_legend()
        screen.blit(self.font.render(status, True, TEXT_COLOR), (8, self.view_size[1] + 6))
        if paused or banner:
            text = self.big_font.render(banner or "PAUSED", True, PAUSE_COLOR if paused else HIGHLIGHT_COLOR)
            box = text.get_rect(center=(self.view_size[0] // 2, self.view_size[1] // 3))
            pygame.draw.rect(screen, OUTLINE_COLOR, box.inflate(24, 12))
            screen.blit(text, box)
        pygame.display.flip()

    def _draw_trajectories(self, label: int) -> None:
        for i, runs in enumerate(self.segments):
            if i == label:
                continue
            for run in runs:
                if len(run) > 1:
                    pygame.draw.aalines(self.screen, TRAJ_COLOR, False, run)
        for run in self.segments[label]:
            if len(run) > 1:
                pygame.draw.lines(self.screen, OUTLINE_COLOR, False, run, 7)
                pygame.draw.lines(self.screen, HIGHLIGHT_COLOR, False, run, 4)
            for u, v in (run[0], run[-1]):
                pygame.draw.circle(self.screen, OUTLINE_COLOR, (u, v), 5)
                pygame.draw.circle(self.screen, HIGHLIGHT_COLOR, (u, v), 3)

    def _draw_inset(self, trace_px: Sequence[tuple[float, float]]) -> None:
        screen = self.screen
        ox, oy = self.inset_origin
        screen.blit(self.font.render("map (north up)", True, DIM_TEXT), (ox, PANEL_MARGIN_PX))
        screen.blit(self.inset, (ox, oy))
        pygame.draw.rect(screen, DIM_TEXT, pygame.Rect(ox - 1, oy - 1, self.inset_size[0] + 2, self.inset_size[1] + 2), 1)
        clip = screen.get_clip()
        screen.set_clip(pygame.Rect(ox, oy, *self.inset_size))
        if len(self.path_px) > 1:
            pygame.draw.lines(screen, OUTLINE_COLOR, False, self.path_px, 3)
            pygame.draw.lines(screen, PATH_COLOR, False, self.path_px, 1)
        pygame.draw.circle(screen, PATH_COLOR, self.path_px[-1], 4, 1)
        if len(trace_px) > 1:
            pygame.draw.lines(screen, TRACE_COLOR, False, trace_px, 2)
        x, y, yaw = self.sim.vehicle.pose
        cx, cy = self.to_inset(x, y)
        c, s = math.cos(yaw), math.sin(yaw)
        r = 7.0
        # A triangle pointing along the heading (screen y grows southward, hence -sin).
        tip = (cx + r * c, cy - r * s)
        left = (cx - 0.6 * r * c - 0.5 * r * s, cy + 0.6 * r * s - 0.5 * r * c)
        right = (cx - 0.6 * r * c + 0.5 * r * s, cy + 0.6 * r * s + 0.5 * r * c)
        pygame.draw.polygon(screen, VEHICLE_COLOR, (tip, left, right))
        pygame.draw.polygon(screen, OUTLINE_COLOR, (tip, left, right), 1)
        screen.set_clip(clip)

    def _draw_gauge(self, w: float, label: int) -> None:
        """A horizontal stick gauge: one tick per command in A, the label's tick and w's marker."""
        screen = self.screen
        x0 = self.inset_origin[0]
        y0 = self.inset_origin[1] + self.inset_size[1] + 18
        width = INSET_WIDTH_PX
        screen.blit(self.font.render("stick w [rad/s]   left <  > right", True, DIM_TEXT), (x0, y0))
        y = y0 + 28
        grid = np.asarray(self.control.w_rps, dtype=float)
        w_max = float(np.abs(grid).max())

        def gx(value: float) -> float:  # w = +w_max (left) is drawn at the left end
            return x0 + (w_max - value) / (2 * w_max) * width

        pygame.draw.line(screen, DIM_TEXT, (x0, y), (x0 + width, y), 1)
        for i, wi in enumerate(grid):
            h = 9 if i == label else 4
            pygame.draw.line(screen, HIGHLIGHT_COLOR if i == label else DIM_TEXT, (gx(wi), y - h), (gx(wi), y + h), 3 if i == label else 1)
        pygame.draw.circle(screen, TRACE_COLOR, (gx(float(np.clip(w, -w_max, w_max))), y), 5)

    def _draw_legend(self) -> None:
        screen = self.screen
        x0 = self.inset_origin[0]
        y = self.inset_origin[1] + self.inset_size[1] + 64
        for c in self.sim.world.classes.classes:
            pygame.draw.rect(screen, c.color, pygame.Rect(x0, y + 2, 12, 12))
            screen.blit(self.font.render(c.name, True, TEXT_COLOR), (x0 + 18, y))
            y += 18
        y += 8
        for line in ("Left/Right  move the stick", "Down / C    centre it", "mouse drag  steer", "Space / P   pause", "Esc / Q     quit"):
            screen.blit(self.font.render(line, True, DIM_TEXT), (x0, y))
            y += 18


def _check_display() -> None:
    """Refuse to open a window nobody can see: SDL would silently fall back to an offscreen one."""
    if os.environ.get("SDL_VIDEODRIVER"):
        return
    if sys.platform.startswith(("linux", "freebsd", "openbsd", "netbsd")) and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
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


def run_teleop(
    scenario: Scenario | str,
    record_dir: str | Path | None = None,
    *,
    overwrite: bool = False,
    camera: CameraConfig | None = None,
    preference: PreferenceSetConfig | None = None,
    sim_config: SimConfig | None = None,
    v_mps: float = 1.0,
    realtime: bool = True,
    script: Callable[[int], Sequence[Any]] | None = None,
    max_frames: int | None = None,
    screenshot: str | Path | None = None,
    disturbance: DisturbanceConfig | None = None,
    seed: int = 0,
    profile: PreferenceProfile | None = None,
) -> TeleopResult:
    """Drive ``scenario`` by keyboard or gamepad in a window, optionally recording every frame.

    Each loop iteration is one camera frame: handle input, sample the stick, draw, then (unless
    paused) record the frame with the command (v, w) and its label, and step the simulation by
    one camera period. The run ends at the goal, at the time limit, on quit, or after
    ``max_frames`` iterations. The recording is closed complete in all those cases (its
    summary says which), and left partial if an exception escapes.

    Args:
        scenario: a Scenario, or a packaged scenario name or a path.
        record_dir: directory for the recording; None drives without recording.
        overwrite: replace an existing recording in ``record_dir``.
        camera: camera configuration (default: SPEC 5).
        preference: preference/control set configuration; its control set labels w.
        sim_config: loop timing and limits.
        v_mps: forward speed held throughout [m/s], in (0, vehicle max speed].
        realtime: pace the loop at the camera rate for a person; False runs as fast as it can.
        script: ``frame_index -> events`` posted before that iteration's events are handled
            (tests inject KEYDOWN/KEYUP/QUIT this way).
        max_frames: stop after this many loop iterations (paused ones included, so a paused
            scripted run still ends).
        screenshot: save the last drawn window image to this file (PNG by extension).
        disturbance: pushes added to the executed yaw rate now and then, so that the recording
            shows the driver's recoveries (the stick stays the label); drawn from ``seed``.
        profile: the driver's declared preference order, stored with the recording (default:
            the class table's).

    Returns:
        How the run ended.

    Raises:
        UserError: no display, a bad speed, or a recording that already exists (without
            ``overwrite``).
    """
    scenario = resolve_scenario(scenario) if isinstance(scenario, str) else scenario
    camera_cfg = camera or CameraConfig()
    preference_cfg = preference or PreferenceSetConfig()
    sim_cfg = sim_config or SimConfig()
    if not 0.0 < v_mps <= sim_cfg.vehicle.max_speed_mps:
        raise UserError(SOURCE, f"speed must be in (0, {sim_cfg.vehicle.max_speed_mps:g}] m/s, got {v_mps:g}", field="v_mps")
    if max_frames is not None and max_frames < 0:
        raise UserError(SOURCE, "max_frames must be >= 0", field="max_frames")
    control: ControlSet = preference_cfg.control
    frame_dt = 1.0 / sim_cfg.camera_rate_hz

    _open_display()
    writer: RecordingWriter | None = None
    try:
        sim = Simulation(scenario, camera_cfg, sim_cfg)
        prefs = PreferenceSet(preference_cfg, sim.camera)
        window = _Window(sim, prefs, f"terrapref drive - {scenario.name}" + (f" -> {record_dir}" if record_dir else ""))
        if record_dir is not None:
            meta = recording_meta(
                scenario, camera_cfg, preference_cfg, sim_cfg,
                {"kind": "human", "input": "keyboard/mouse/gamepad", "disturbance": disturbance.to_dict() if disturbance else None, "seed": seed},
                profile or PreferenceProfile.default(scenario.classes),
            )
            writer = RecordingWriter(record_dir, meta, scenario.to_dict(), overwrite=overwrite)
        stick = _Stick(w_max_rps=float(np.abs(control.w_rps).max()), view_width_px=window.view_size[0])
        disturb = Disturber(disturbance, np.random.default_rng(seed), frame_dt) if disturbance and disturbance.active else None
        clock = pygame.time.Clock()
        frame = sim.reset()
        trace_px = [window.to_inset(frame.pose.x, frame.pose.y)]
        paused = quit_ = False
        recorded = 0
        i = 0
        while not sim.done and (max_frames is None or i < max_frames):
            if script is not None:
                for event in script(i):
                    pygame.event.post(event)
            for event in pygame.event.get():
                if event.type == pygame.QUIT or (event.type == pygame.KEYDOWN and event.key in (pygame.K_ESCAPE, pygame.K_q)):
                    quit_ = True
                elif event.type == pygame.KEYDOWN and event.key in (pygame.K_SPACE, pygame.K_p):
                    paused = not paused
                else:
                    stick.handle(event)
            if quit_:
                break
            w = stick.update(frame_dt)
            label = int(control.label_of(w))
            status = _status(sim.time_s, v_mps, w, label, control.m, recorded, sim.collisions, writer is not None, paused)
            window.draw(frame.image, w, label, trace_px, status, paused)
            if not paused:
                command = Command(v_mps, w)
                executed = disturb(command) if disturb is not None else command
                if writer is not None:
                    writer.append(frame.time_s, frame.pose, frame.image, command, label,
                                  executed=executed if executed != command else None)
                frame = sim.step(executed)
                recorded += 1
                trace_px.append(window.to_inset(frame.pose.x, frame.pose.y))
            i += 1
            if realtime:
                clock.tick(sim_cfg.camera_rate_hz)
        banner = "GOAL" if sim.reached_goal else "TIME UP" if sim.timed_out else ""
        status = _status(sim.time_s, v_mps, stick.w, int(control.label_of(stick.w)), control.m, recorded, sim.collisions, writer is not None, False)
        window.draw(frame.image, stick.w, int(control.label_of(stick.w)), trace_px, status + ("   quit" if quit_ else "   done"), False, banner)
        if screenshot is not None:
            pygame.image.save(window.screen, str(screenshot))
        result = TeleopResult(
            frames=recorded,
            completed=sim.reached_goal,
            collisions=sim.collisions,
            quit=quit_,
            record_dir=Path(record_dir) if record_dir is not None else None,
            duration_s=sim.time_s,
        )
        if writer is not None:
            writer.close({"completed": result.completed, "collisions": result.collisions, "duration_s": round(result.duration_s, 3), "quit": result.quit})
            writer = None
        if realtime and banner:
            pygame.time.wait(1000)  # let the driver see how the run ended before the window closes
        return result
    except BaseException:
        if writer is not None:
            writer.abort()
            if writer.partial_dir is not None:
                print(f"note: {writer.target} keeps the recording it held; the unfinished new one is in {writer.partial_dir}", file=sys.stderr)
        raise
    finally:
        pygame.quit()


def _status(time_s: float, v: float, w: float, label: int, m: int, frames: int, collisions: int, recording: bool, paused: bool) -> str:
    parts = [
        f"t {time_s:6.1f} s",
        f"v {v:.2f} m/s",
        f"w {w:+.2f} rad/s",
        f"label {label:2d}/{m - 1}",
        f"{'rec' if recording else 'frames'} {frames}",
        f"collisions {collisions}",
    ]
    if paused:
        parts.append("PAUSED")
    return "   ".join(parts)
