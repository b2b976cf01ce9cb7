"""The driver's stick: arrow keys, the mouse over the camera view, or a gamepad axis."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pygame

KEY_STEP_RPS = 0.1
"""How far one press of an arrow key moves w at once [rad/s]: one control-set step."""
KEY_RATE_RPS2 = 0.5
"""How fast an arrow key held for up to ``KEY_SLOW_S`` goes on moving w [rad/s per s]: after
the press's step, a gentle curve builds (0.55 rad/s after 1 s) rather than full lock."""
KEY_SLOW_S = 1.0
KEY_FAST_RPS2 = 1.0
"""How fast it moves w once held longer than ``KEY_SLOW_S`` (full lock, 1 rad/s, after about
1.5 s); released, the stick stays where it was left."""
AXIS_DEADZONE = 0.08
"""Gamepad axis values within this of 0 read as a centred stick (worn sticks rest slightly off 0)."""


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


class Stick:
    """The driver's input; the one used last drives.

    Arrow keys move a stick that holds where it is left (a keyboard can hold a gentle curve),
    Down or C centres it, the left mouse button held over the camera view sets w by the
    pointer's horizontal position, and the first gamepad axis sets w as a spring stick does.

    ``touched`` records that the driver used the stick since it was last cleared (a tap counts),
    ``active`` that they are using it now (a key or the button held, the pad off centre): riding
    along with a model, either takes the vehicle over, and a stick left alone hands it back.
    """

    def __init__(self, w_max_rps: float, rate_rps2: float = KEY_RATE_RPS2, view_width_px: int = 640, view_height_px: int = 480) -> None:
        self.w_max = w_max_rps
        self.rate = rate_rps2
        self.held_s: float | None = None  # how long the arrow now down has been held (None: pressed, not yet moved)
        self.view_width = view_width_px
        self.view_height = view_height_px
        self.w = 0.0
        self.left = False
        self.right = False
        self.mouse_x: float | None = None  # pointer x [canvas px] while the left button is held over the view
        self.pad = 0.0
        self.source = "keys"
        self.touched = False
        self.joystick: Any = None
        self._open_joystick()

    def _open_joystick(self) -> None:
        if self.joystick is None and pygame.joystick.get_count() > 0:
            self.joystick = pygame.joystick.Joystick(0)
            self.joystick.init()

    @property
    def active(self) -> bool:
        return self.left or self.right or self.mouse_x is not None or abs(self.pad) > AXIS_DEADZONE

    def axis(self, index: int) -> float:
        """The gamepad's axis ``index`` in [-1, 1]; 0 without a pad or on a pad without that axis."""
        return float(self.joystick.get_axis(index)) if self.joystick is not None and self.joystick.get_numaxes() > index else 0.0

    def follow(self, w: float) -> None:
        """Rest the stick at ``w`` (the planner's command while it drives): arrows then move it from there."""
        self.w, self.source = float(w), "keys"

    def handle(self, event: Any) -> None:
        """Take one input event; mouse positions are in canvas pixels (see ``Window.to_canvas``)."""
        if event.type in (pygame.KEYDOWN, pygame.KEYUP):
            down = event.type == pygame.KEYDOWN
            if event.key in (pygame.K_LEFT, pygame.K_RIGHT):
                if event.key == pygame.K_LEFT:
                    self.left = down
                else:
                    self.right = down
                self.source = "keys"
                self.touched |= down
                if down:
                    self.held_s = None  # the next frame moves one step, then the hold ramps
            elif down and event.key in (pygame.K_DOWN, pygame.K_c):
                self.w, self.source, self.touched = 0.0, "keys", True
        elif (
            event.type == pygame.MOUSEBUTTONDOWN
            and event.button == 1
            and 0 <= event.pos[0] < self.view_width
            and 0 <= event.pos[1] < self.view_height
        ):
            self.mouse_x, self.source, self.touched = float(event.pos[0]), "mouse", True
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
        self.pad = self.axis(0)
        if abs(self.pad) > AXIS_DEADZONE:
            self.source, self.touched = "pad", True
        if self.left != self.right:
            target = self.w_max if self.left else -self.w_max
            if self.held_s is None:  # the press itself: one step
                self.w, self.held_s = ramp_toward(self.w, target, KEY_STEP_RPS, 1.0), 0.0
            else:
                self.held_s += dt_s
                self.w = ramp_toward(self.w, target, self.rate if self.held_s <= KEY_SLOW_S else KEY_FAST_RPS2, dt_s)
        elif self.source == "mouse" and self.mouse_x is not None:
            centre = self.view_width / 2
            self.w = float(np.clip((centre - self.mouse_x) / centre * self.w_max, -self.w_max, self.w_max))
        elif self.source == "pad":
            self.w = axis_to_w(self.pad, self.w_max)
        return self.w
