"""Which depth image goes with a label image, for ``import`` and the ROS nodes alike.

A label image takes the depth image of the nearest header stamp within :data:`DEPTH_PAIRING_S`
(an RGB-D camera's depth and colour frames share a stamp, or lie a few milliseconds apart). One
with none that near has no depth image: ``import`` skips it, and so does a node, for a frame
whose ground cannot be placed is not to be read as if the ground were flat.
"""

from __future__ import annotations

import bisect
from typing import Generic, TypeVar

DEPTH_PAIRING_S = 0.05  # a label image takes the depth image of the nearest stamp within this [s]; half a frame at 10 Hz

Image = TypeVar("Image")


class DepthPairing(Generic[Image]):
    """Depth images held by stamp until the label images near their stamps have come.

    Label images come in stamp order (``import`` puts them in order; a node's runtime ignores a
    frame older than the last), so each pairing lets go of the depth images too old for any
    label image still to come.

    Args:
        held_max: how many depth images are held at most (the newest by stamp).
    """

    def __init__(self, held_max: int) -> None:
        self.held_max = held_max
        self.held: list[tuple[float, Image]] = []  # (stamp [s], image), by stamp
        self.newest_s: float | None = None  # the newest stamp put so far [s]

    def put(self, t: float, image: Image) -> None:
        """Hold ``image``, stamped ``t`` [s]; the oldest goes when more than ``held_max`` are held."""
        k = bisect.bisect_right([s for s, _ in self.held], t)
        self.held.insert(k, (t, image))
        del self.held[: -self.held_max]
        self.newest_s = t if self.newest_s is None else max(self.newest_s, t)

    def nearest(self, t: float) -> tuple[float, Image] | None:
        """(|stamp - ``t``| [s], image) of the depth image of the stamp nearest ``t`` [s] within
        :data:`DEPTH_PAIRING_S`, or None; those older than that window are let go."""
        self.held = [(s, d) for s, d in self.held if s >= t - DEPTH_PAIRING_S]
        if not self.held:
            return None
        offset, image = min(((abs(s - t), d) for s, d in self.held), key=lambda pair: pair[0])
        return None if offset > DEPTH_PAIRING_S else (offset, image)

    def settled(self, t: float) -> bool:
        """Whether no depth image still to come can be nearer ``t`` [s] than those held: one
        stamped at or after ``t`` has come (a depth camera's images come in stamp order)."""
        return self.newest_s is not None and self.newest_s >= t
