"""What drives on relief left unshown, for a follow-up course (``terrapref course --after``).

A relief lesson (terrapref.scenario.teaching.RELIEF_LESSONS) is unshown where the drives' frames,
as the default recipe's rules read them, hold too little of it:

- ``steep side slope`` / ``steep grade``: no way the drive could have taken (the offset rule's
  lattice) crosses ground past the steep bank's side slope / the steep mound's grade, so the
  steering prices nothing as steep as that;
- ``grades``: fewer than the speed rule's ``MIN_FRAMES`` frames climb, or descend, past
  ``LEVEL_DEG`` within :data:`GRADE_REACH_M`, so what a degree sheds is not read;
- ``rough ground``: fewer than that many frames find ground rougher than :data:`ROUGH_SHOWN_M`
  within the speed rule's roughness preview.

A drive on flat ground (no depth) has no relief lessons. As for pairs, a lesson unshown before
the last drive and still unshown after it is left: driving the same again would show the same.
"""

from __future__ import annotations

import numpy as np

from terrapref.dataset import Dataset
from terrapref.rules.offset.features import RELIEF_BANDS_DEG
from terrapref.rules.offset.fit import relief_shown
from terrapref.rules.speed.model import LEVEL_DEG, MIN_FRAMES, roughest, stations_within, steepest
from terrapref.scenario.teaching import RELIEF_DEG, RELIEF_LESSONS

GRADE_REACH_M = 2.0  # a frame climbs or descends where its way does within this [m]
ROUGH_SHOWN_M = 0.015  # ground this rough shows the speed kept on rough ground [m] (the default relief style's rough_m)


def relief_unshown(dataset: Dataset) -> tuple[str, ...] | None:
    """The relief lessons (:data:`RELIEF_LESSONS`, in its order) ``dataset``'s drives left unshown;
    None for drives on flat ground."""
    speed, offset = dataset.rules.get("speed", {}), dataset.rules.get("offset", {})
    grade, rough, relief = speed.get("grade"), speed.get("rough"), offset.get("relief_m")
    if grade is None or not np.isfinite(grade).any():
        return None
    unshown = set()
    if relief is not None and relief.size:
        roll, pitch = relief_shown(relief, RELIEF_BANDS_DEG)
        if not roll >= RELIEF_DEG["steep bank"]:  # NaN: none shown
            unshown.add("steep side slope")
        if not pitch >= RELIEF_DEG["steep mound"]:
            unshown.add("steep grade")
    climb, descent = steepest(grade, stations_within(GRADE_REACH_M), len(grade))  # as the speed rule's fit counts them
    if (
        min(np.count_nonzero((climb >= LEVEL_DEG) & (descent < LEVEL_DEG)), np.count_nonzero((descent >= LEVEL_DEG) & (climb < LEVEL_DEG)))
        < MIN_FRAMES
    ):
        unshown.add("grades")
    if rough is None or np.count_nonzero(roughest(rough) > ROUGH_SHOWN_M) < MIN_FRAMES:
        unshown.add("rough ground")
    return tuple(lesson for lesson in RELIEF_LESSONS if lesson in unshown)


def relief_plan(pooled: Dataset, earlier: Dataset | None, last: str) -> tuple[tuple[str, ...], tuple[str, ...], bool]:
    """The relief lessons the drives (``pooled``; ``earlier``: all but the ``last``, None for one
    drive) leave unshown that a follow-up can show, a line for each that none can, and whether
    the drives were on relief."""
    now = relief_unshown(pooled)
    if now is None:
        return (), (), False
    before = set(relief_unshown(earlier) or ()) if earlier is not None else set()
    show = tuple(lesson for lesson in now if lesson not in before)
    left = tuple(
        f"{lesson}: unshown before {last} and after it; driving it again would show the same" for lesson in now if lesson in before
    )
    return show, left, True
