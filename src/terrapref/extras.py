"""The optional parts of terrapref and the packages each needs.

``pip install terrapref`` installs the core: simulation, recording, featurising, training,
evaluation, reports and routes. The heavy parts are extras, installed by name:

- ``teleop``: the driving window (``terrapref drive``; pygame).
- ``robot``: ROS bags in and out, ONNX export and the live view (``import``, ``replay``,
  ``export``, ``evaluate --mcap``, ``--live``; rosbags, onnx, onnxruntime, foxglove-sdk).
- ``ray``: the Ray grid engine (``--engine ray``).
- ``cnn``: the end-to-end CNN baseline (``study``, a CNN model file; PyTorch).
- ``ros2``: the planner as a ROS 2 node over DDS, and playing ROS 2 logs onto a ROS 2 graph
  (``ros2``, ``play``; cyclonedds, rosbags).

Code that needs one imports its packages where the feature runs, inside :func:`needs`, so that
a missing extra is one line naming it instead of a traceback::

    with needs("teleop", "terrapref drive"):
        import pygame

    # without pygame: terrapref drive: needs the teleop extra: pip install 'terrapref[teleop]' (pygame is not installed)
"""

from __future__ import annotations

import importlib.util
from collections.abc import Iterator
from contextlib import contextmanager

from terrapref.errors import UserError

EXTRAS: dict[str, tuple[str, ...]] = {
    "teleop": ("pygame",),
    "robot": ("rosbags", "onnx", "onnxruntime", "foxglove"),
    "ray": ("ray",),
    "cnn": ("torch",),
    "ros2": ("cyclonedds", "rosbags"),
}
"""Each extra's importable packages (pyproject.toml's ``optional-dependencies`` name their distributions)."""


class MissingExtra(UserError):
    """A feature was asked for whose extra is not installed."""


def _missing(extra: str, feature: str, why: str) -> MissingExtra:
    return MissingExtra(feature, f"needs the {extra} extra: pip install 'terrapref[{extra}]' ({why})")


@contextmanager
def needs(extra: str, feature: str) -> Iterator[None]:
    """Imports of ``extra``'s packages for ``feature`` (what the user asked for, such as
    ``terrapref drive`` or ``--engine ray``): one that fails is a :class:`MissingExtra`.

    Put only those imports inside the block: any ImportError raised in it is taken to be the
    extra's.
    """
    if extra not in EXTRAS:
        raise ValueError(f"unknown extra {extra!r}; extras: {', '.join(EXTRAS)}")
    try:
        yield
    except ImportError as exc:
        package = (exc.name or EXTRAS[extra][0]).split(".")[0]
        if isinstance(exc, ModuleNotFoundError):
            why = f"{package} is not installed"
        else:  # installed, but broken: a missing shared library, a version that does not fit
            why = f"{package} does not import: {' '.join(str(exc).split())[:120]}"
        raise _missing(extra, feature, why) from None


def check(extra: str, feature: str, *packages: str) -> None:
    """Refuse ``feature`` now, before any work, when ``packages`` (default: all of ``extra``'s) are
    not all installed; for a command that would reach the extra's code only late. Nothing is imported."""
    for package in packages or EXTRAS[extra]:
        if importlib.util.find_spec(package) is None:  # None too where sys.modules holds None for it
            raise _missing(extra, feature, f"{package} is not installed")
