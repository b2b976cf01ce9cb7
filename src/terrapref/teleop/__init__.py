"""The driving window in which a person records demonstrations and corrections (SPEC 10).

This package is the only part of terrapref that imports pygame, and nothing imports the package
at terrapref's import time: the CLI loads it when ``terrapref drive`` runs, so the rest of the
project works without pygame installed. pygame comes with the ``teleop`` extra
(``pip install 'terrapref[teleop]'``); without it, importing this package is a one-line error
naming the extra.

The window shows what the learner will see, the camera's segmentation image, with the preference
set S drawn on it and the trajectory of the current stick's label highlighted, so the driver
sees which discrete command each stick position is recorded as; a heads-up display with the
progress along the path, the next patch, the terrain under the vehicle, the label as a turn and
the distance to the route; alerts when a push turns the vehicle or it is off the route, with an
arrow back to the route; a top-down inset of the map with the reference path, the vehicle, its
trace and where the pushes began; a stick gauge, the terrain legend and the controls. The
status line under the view gives the vehicle's speed beside the throttle's set speed.

- ``stick``: keyboard, mouse and gamepad steering.
- ``throttle``: the set speed, from W/S, the mouse wheel and a gamepad axis.
- ``guide``: what the display says about the course, and where the map ends.
- ``window``: drawing, on a canvas scaled to the (resizable) window.
- ``loop``: the session (start, countdown, pause, riding along with a model, recording).
- ``keyboard``: a simulated person at a keyboard, for tests and the keyboard study.
"""

import os

from terrapref.extras import needs

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")  # before pygame is first imported
with needs("teleop", "terrapref drive"):  # here once, before the submodules import it
    import pygame  # noqa: F401

from terrapref.teleop.loop import COUNTDOWN_S, HANDBACK_S, TeleopOptions, TeleopResult, TeleopState, run_session, run_teleop  # noqa: E402
from terrapref.teleop.stick import AXIS_DEADZONE, KEY_RATE_RPS2, Stick, axis_to_w, ramp_toward  # noqa: E402
from terrapref.teleop.throttle import Throttle  # noqa: E402

__all__ = [
    "AXIS_DEADZONE",
    "COUNTDOWN_S",
    "HANDBACK_S",
    "KEY_RATE_RPS2",
    "Stick",
    "TeleopOptions",
    "TeleopResult",
    "TeleopState",
    "Throttle",
    "axis_to_w",
    "ramp_toward",
    "run_session",
    "run_teleop",
]
