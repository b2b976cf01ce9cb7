"""A simulated person at a keyboard: the synthetic driver's intent, typed through the window.

The window is driven through its own event handling (a :data:`~terrapref.teleop.loop.Script`):
the person sees the scene, wants what the synthetic driver wants (its intended yaw rate, before
that driver's own hand), reacts ``reaction_s`` later, and can only hold Left or Right (the stick
moves one control-set step at the press, then gently on, terrapref.teleop.stick) or tap Down (centre). What a keyboard loses against a
stick (steps instead of a continuous w, a late and coarse return to straight) is therefore in the
recording, as it would be with a person.

The same person works the throttle with W and S (terrapref.teleop.throttle) toward the speed the
driver wants (its cruising speed for the ground ahead, its bends, its lethal neighbours), as late:
far from it they hold the key (a step at the press, then :data:`~terrapref.teleop.throttle.KEY_RATE_MPS2`),
near it they tap, no faster than :data:`TAP_EVERY_FRAMES` allows, and within half a step they leave it
(where taps cannot land nearer).
A driver of one speed (the paper's setting) never touches the throttle when the window starts at that speed.
"""

from __future__ import annotations

from collections import deque

import numpy as np
import pygame

from terrapref.demos.expert import ExpertDriver
from terrapref.scenario import Scenario
from terrapref.teleop.loop import TeleopState
from terrapref.teleop.stick import KEY_STEP_RPS
from terrapref.teleop.throttle import FASTER_KEYS, KEY_STEP_MPS, SLOWER_KEYS
from terrapref.world import WorldMap

REACTION_S = 0.3
"""A person's reaction time from seeing to pressing [s]."""
START_AFTER_FRAMES = 5
"""The person presses Space this many frames after the window opens."""
HOLD_FROM_MPS = 0.25
"""The person holds W or S while the speed they want is at least this far from the set speed [m/s], and taps nearer."""
TAP_EVERY_FRAMES = 2
"""The person taps W or S at most once in this many camera frames (5 taps a second at 10 Hz)."""


def _key(kind: int, key: int) -> pygame.event.Event:
    return pygame.event.Event(kind, key=key, mod=0, unicode="", scancode=0)


class KeyboardPerson:
    """Key presses from the synthetic driver's intent, at a person's reaction time.

    Args:
        expert: the driver whose intent the person has (its preference and style).
        scenario: the course driven; ``world`` its raster when the caller already has it.
        rng: seeds the expert's tie-breaks.
        camera_rate_hz: the window's frame rate.
        reaction_s: the delay from a frame to the key press it causes [s].
    """

    def __init__(
        self,
        expert: ExpertDriver,
        scenario: Scenario,
        rng: np.random.Generator,
        camera_rate_hz: float = 10.0,
        reaction_s: float = REACTION_S,
        world: WorldMap | None = None,
    ) -> None:
        self.expert = expert
        self.expert.reset(scenario, rng, world=world)
        self.step = KEY_STEP_RPS  # how far a press moves the stick [rad/s]; holding it, less per frame at first
        # The yaw rate and the speed wanted, reaction_s late (a speed of None: not yet seen).
        self.queue: deque[tuple[float, float | None]] = deque([(0.0, None)] * max(0, round(reaction_s * camera_rate_hz)))
        self.held: int | None = None  # the arrow held down, if any
        self.throttle_held: int | None = None  # W or S held down, if any
        self.last_tap = -TAP_EVERY_FRAMES
        self.presses = 0
        self.throttle_presses = 0

    def __call__(self, state: TeleopState) -> list[pygame.event.Event]:
        if state.phase == "waiting":
            return [_key(pygame.KEYDOWN, pygame.K_SPACE)] if state.index >= START_AFTER_FRAMES else []
        if state.phase != "driving":
            return []
        self.queue.append((self.expert.intent(state.frame), self.expert.wanted_mps))
        target, wanted = self.queue.popleft()
        events = self._throttle(state, wanted)
        want: int | None = None
        centre = False
        if abs(target - state.w) > 0.5 * self.step:
            if target == 0.0 and abs(state.w) <= 1.5 * self.step:
                centre = True  # nearly straight and straight is wanted: one tap of Down
            else:
                want = pygame.K_LEFT if target > state.w else pygame.K_RIGHT
        if self.held is not None and self.held != want:
            events.append(_key(pygame.KEYUP, self.held))
            self.held = None
        if want is not None and self.held is None:
            events.append(_key(pygame.KEYDOWN, want))
            self.held = want
            self.presses += 1
        if centre:
            events += [_key(pygame.KEYDOWN, pygame.K_DOWN), _key(pygame.KEYUP, pygame.K_DOWN)]
            self.presses += 1
        return events

    def _throttle(self, state: TeleopState, wanted: float | None) -> list[pygame.event.Event]:
        """W and S toward the speed ``wanted`` [m/s] (None: nothing seen yet, leave the throttle)."""
        gap = 0.0 if wanted is None else wanted - state.v
        key = FASTER_KEYS[0] if gap > 0 else SLOWER_KEYS[0]
        hold = abs(gap) >= HOLD_FROM_MPS
        events = []
        if self.throttle_held is not None and (not hold or self.throttle_held != key):
            events.append(_key(pygame.KEYUP, self.throttle_held))
            self.throttle_held = None
        if hold and self.throttle_held is None:
            events.append(_key(pygame.KEYDOWN, key))
            self.throttle_held = key
            self.throttle_presses += 1
        elif not hold and abs(gap) > 0.5 * KEY_STEP_MPS + 1e-9 and state.index - self.last_tap >= TAP_EVERY_FRAMES:
            events += [_key(pygame.KEYDOWN, key), _key(pygame.KEYUP, key)]
            self.last_tap = state.index
            self.throttle_presses += 1
        return events
