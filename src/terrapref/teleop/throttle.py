"""The driver's throttle: the forward speed the vehicle is told to hold, set by W and S, the mouse
wheel or a gamepad axis.

The throttle is a set-point, as a cruise control's is: left alone it holds, so that a person can
drive a long stretch at one speed without holding anything. The vehicle itself reaches the set
speed within its acceleration limits (terrapref.vehicle), so its actual speed may lag behind.
"""

from __future__ import annotations

from typing import Any

import pygame

FASTER_KEYS = (pygame.K_w,)
SLOWER_KEYS = (pygame.K_s,)
"""W and S, under the left hand while the right steers with the arrows (Down centres the stick)."""
KEY_STEP_MPS = 0.1
"""How far one press of W or S moves the set speed at once [m/s]."""
KEY_RATE_MPS2 = 0.5
"""How fast W or S held goes on moving it after the press's step [m/s per s]: 0.55 m/s after 1 s."""
WHEEL_STEP_MPS = 0.1
"""How far one notch of the mouse wheel moves it [m/s]; up is faster."""
PAD_AXIS = 1
"""The gamepad axis that moves it: the left stick's vertical axis on common pads (up is negative)."""
PAD_DEADZONE = 0.3
"""Throttle axis values within this of 0 leave the set speed alone: wider than the steering
deadzone, since a stick pushed hard to one side is rarely pushed exactly sideways."""
PAD_RATE_MPS2 = KEY_RATE_MPS2
"""How fast the axis pushed fully up (or down) moves the set speed [m/s per s]; less when pushed less."""


class Throttle:
    """The set speed v [m/s], held in [0, ``v_max_mps``] until the driver moves it.

    A press of W (S) raises (lowers) it by :data:`KEY_STEP_MPS` at once, and held on by
    :data:`KEY_RATE_MPS2`; a notch of the mouse wheel moves it by :data:`WHEEL_STEP_MPS`; the
    gamepad axis :data:`PAD_AXIS` pushed off centre moves it at a rate that grows with the push.

    ``touched`` records that the driver used the throttle since it was last cleared (a tap or a
    notch counts), ``active`` that they are using it now (a key held, the axis pushed): riding
    along with a model, either takes the vehicle over, as the stick does.
    """

    def __init__(self, v_mps: float, v_max_mps: float) -> None:
        self.v_max = v_max_mps
        self.v = min(max(float(v_mps), 0.0), v_max_mps)
        self.faster = False
        self.slower = False
        self.pressed = False  # a key went down since the last update: that frame moves by the press's step only
        self.pad = 0.0
        self.touched = False

    @property
    def active(self) -> bool:
        return self.faster or self.slower or abs(self.pad) > PAD_DEADZONE

    def set(self, v_mps: float) -> None:
        """Move the set speed to ``v_mps`` [m/s], clipped to [0, v_max]."""
        self.v = min(max(round(float(v_mps), 9), 0.0), self.v_max)  # rounded: steps of 0.1 add up to 1.2, not 1.2000000000000002

    def follow(self, v_mps: float) -> None:
        """Rest the set speed at the planner's command ``v_mps`` [m/s] while it drives, so that a
        takeover starts from it; a planner's stop (0) leaves it where it was, so that taking over
        from a stopped planner drives on."""
        if v_mps > 0.0:
            self.set(v_mps)

    def handle(self, event: Any) -> None:
        """Take one input event (keys, the mouse wheel, focus)."""
        if event.type in (pygame.KEYDOWN, pygame.KEYUP) and event.key in FASTER_KEYS + SLOWER_KEYS:
            down = event.type == pygame.KEYDOWN
            faster = event.key in FASTER_KEYS
            if faster:
                self.faster = down
            else:
                self.slower = down
            if down:
                self.set(self.v + (KEY_STEP_MPS if faster else -KEY_STEP_MPS))
                self.pressed = self.touched = True
        elif event.type == pygame.MOUSEWHEEL and event.y != 0:
            notches = -event.y if event.dict.get("flipped", False) else event.y  # flipped: the system reverses the wheel for scrolling
            self.set(self.v + notches * WHEEL_STEP_MPS)
            self.touched = True
        elif event.type == pygame.WINDOWFOCUSLOST:
            self.faster = self.slower = False  # a key released while another window has focus never sends KEYUP here

    def update(self, dt_s: float, pad_axis: float = 0.0) -> float:
        """Sample the throttle for one frame of ``dt_s`` [s], the gamepad's throttle axis at
        ``pad_axis`` (in [-1, 1], up negative; 0 without a pad); returns the set speed [m/s]."""
        self.pad = pad_axis
        if abs(pad_axis) > PAD_DEADZONE:
            self.set(self.v - pad_axis * PAD_RATE_MPS2 * dt_s)
            self.touched = True
        if self.faster != self.slower and not self.pressed:
            self.set(self.v + (KEY_RATE_MPS2 if self.faster else -KEY_RATE_MPS2) * dt_s)
        self.pressed = False
        return self.v
