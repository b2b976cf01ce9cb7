"""The teaching course of any class table: one drive that shows every choice a driver makes.

A driver's preference is an order of the table's feature classes. One drive identifies it
when the course shows

- every **pair** of feature classes side by side, meeting on the path (the driver takes the
  better side);
- every feature class as a **strip** on the path between lethal terrain and another class (the
  driver keeps to the strip or moves over: how much worse one class is than another against a
  2 m detour, and every class beside lethal terrain); the compact course of a table with lethal
  classes (below) leaves its strips to the follow-up, which shows them along the order its drive
  learned;
- every feature class **alone** on the path (driven through or passed on the background), and
  lethal terrain alone (passed on the background) at most :data:`LETHAL_LONE` times;
- every feature class as a **lane**: on the path between lethal walls too wide to pass round
  (or, in a table without lethal classes, across the whole way), so that every driver drives
  along it at its own speed on that class (SPEC 18).

With relief (``terrapref course --relief``, the packaged ``teach_relief``) it also shows each
relief situation alone and relief against terrain (:func:`relief_situations`): a mound on the
path of a gentle and of a steep grade (and, last on the course, one of a grade between them: the
three with no class in view, where the relief prices are fitted), a bank beside the path (the
path on its flank) of a gentle and of a steep side slope, a ramp up and down across the way, a
rough patch across the way (short noise: rocks and ruts), rough at first and smoother step by step, and each feature class as a flat patch beside the path against the path's
own ground sloping across the way as a bank of the background. Which of them a driver goes
round, and how it slows on them, is its relief style. So that all of it fits in a drive of about
7 minutes (:data:`RELIEF_BUDGET_M`: up to 3 feature classes and one lethal class), a course with
relief shows each pair and each lethal class alone once (two at most), the sides balanced, in either design,
and gives the terrain situations a little less trail where they do not meet a relief situation
(:data:`RELIEF_HALF_M`); its full design still shows every strip on both sides, each class on the
path beside each other one (a larger table gets the compact design, and a longer drive). The
strips, not the pairs, tell how much worse one class is than another, on which a layout's
triples turn: with each strip once and each pair twice, relief drives priced their last class
at 1.45-1.77 times their first, where their driver's costs are 2.25 times.

Pairs grow as K(K-1)/2. The course shows each pair once on each side, each strip with the
lethal terrain once on each side, the first lethal class alone twice (once a little left of the
path, once a little right) and each feature class alone once and as a lane once, while that drive stays
within :data:`BUDGET_M` (10 minutes at the driver's 1 m/s: up to 4 feature classes). Beyond it
the course is *compact*: each pair once, with every class on the left as often as on the right
(to within one), each feature class alone, each lane and the first two lethal classes alone once,
the sides alternating, and no strip (the lengths of both designs: docs/classes.md). Its follow-up
shows the strips instead, where they tell most: the **ladder** of the order its drive learned
(:func:`ladder`), each class on the path beside the next better one, and the best class alone at
two sizes that bracket its price (:func:`ladder_follows`: a table with a lethal class for the
strips' wall). A compact course with relief, and the compact design of any other table
(``--design compact`` of one whose full design fits, or one without lethal classes), keep each
strip once. The lethal
classes share one column of the features, and each is a strip's wall and a lane's walls.

Situations sit on straight legs; the trail bends a little between them (keeping to the path is
part of the lesson) and turns round every :data:`LANE` situations, so that a long course folds
into a compact map.

:func:`follow_up` makes a short course of the pairs a drive left open and their neighbours in
the learned order (``terrapref course --after REC``), each once, the neighbours as many as keep it
within :data:`FOLLOW_UP_M`; after the first drive of a table whose compact course leaves its
strips to it, the pairs it left open and the ladder instead (the ladder shows every neighbour's
step), whatever course that drive was of.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from terrapref.scenario.builder import CourseBuilder, trail
from terrapref.terrain import ClassTable

DRIVER_SPEED_MPS = 1.0  # the speed a teaching drive is timed at (the synthetic driver's)
BUDGET_M = 600.0  # the longest full design [m]: 10 minutes at 1 m/s
# A course with relief is driven slower: the default driver and relief style average about 0.85 m/s
# on one (grades, bumps and the situations' detours; teach_relief's 355 m in 410-416 s) [m/s].
RELIEF_PACE_MPS = 0.85
RELIEF_BUDGET_M = 7 * 60 * RELIEF_PACE_MPS  # the longest full design with relief [m]: 7 minutes at that pace
LANE = 8  # situations between two turns round
# Lethal terrain alone on the path: at most this many patches (the first lethal classes, the sides
# alternating; one class on both sides in the full design). The lethal classes share one column of
# the features, and each is still shown as a strip's wall and a lane's walls.
LETHAL_LONE = 2
# The longest follow-up course the neighbours of its open pairs may make it [m]: 2.25 minutes at
# the driver's 1 m/s, so that a table of six feature classes is taught in 12 minutes with its
# follow-up (the open pairs themselves are always shown).
FOLLOW_UP_M = 135.0
HALF_M = {
    "lone": 6.0,
    "lane": 6.0,
    "pair": 8.5,
    "strip": 8.5,
    "mound": 5.0,
    "bank": 6.5,
    "ramp": 6.5,
    "slope": 6.5,
    "rough": 6.5,
}  # half a leg [m]
# Half a leg of a course with relief [m]: a pair or strip has 1 m less trail before and after it than
# on the flat course, a lone patch or lane 1 m (a pair's patches, 8 m long at most, still clear
# their leg's ends by 3.5 m, a lane's 6 m by 2 m), except on a side that faces a relief
# situation, which keeps the flat course's, as the relief situations keep theirs: with less, the
# driver moves over for the next terrain situation while still on the relief, and the fit reads
# that as going round the relief (a drive priced 8 deg grades it drove over).
RELIEF_HALF_M = {**HALF_M, "lone": 5.0, "lane": 5.0, "pair": 7.5, "strip": 7.5}
# Half a leg of a follow-up that shows the ladder [m]: the same 1 m less trail round each pair,
# strip and lone patch (it comes after a compact teaching course, so that the two drives of a
# table of six feature classes stay within 12 minutes).
LADDER_HALF_M = {**HALF_M, "lone": 5.0, "pair": 7.5, "strip": 7.5}
RELIEF_KINDS = ("mound", "bank", "ramp", "rough", "slope")  # the situations of relief (module docstring)
MOUND_RADIUS_M = 3.0  # a mound on the path: its radius; its height sets its steepest grade [m]
BANK_WIDTH_M, BANK_LENGTH_M = 5.0, 9.0  # a bank beside the path: its full width and length; the path on its flank [m]
RAMP_TOP_M, RAMP_EDGE_M, RAMP_ACROSS_M = 3.0, 4.0, 14.0  # a ramp across the way: its top, each ramp, across [m]
# A rough patch across the way: (length, width) [m], and its noise's wavelength [m] and amplitude
# [m] on each of its steps, in the order driven, each a quarter of its length: from about 0.019 m
# rough (the heights' deviation about their plane within 0.3 m, the roughness the planner reads),
# past the default relief style's 0.015 m, down to about 0.008 m. A driver slows on the roughest
# and speeds up on the first step smooth enough for it, so the drive shows the roughness it slows
# for, not only that it slows (with the roughest step alone, any roughness between it and smooth
# ground explained the drive alike, and the planner slowed on rough patches less than its driver).
# Its height steps (the height range over 0.3 m, as the planner's height layer reads a step) at most
# 0.09 m, well under the 0.15 m the vehicle climbs: rougher patches read past that step where
# bumps hide the ground behind them, and stop the planner.
ROUGH_PATCH_M = (8.0, 8.0)
ROUGH_WAVELENGTH_M = 0.3
ROUGH_LADDER_M = (0.07, 0.057, 0.043, 0.03)
SLOPE_PATCH_M = (8.0, 4.0)  # relief against terrain: the flat patch beside the path, (length, width) [m]
# ... and the slope it leaves between itself and the footprint on the path [m]: a map cell and a
# hand's wander, so that a footprint holding the path is on the slope alone (with none, the map's
# cell at the patch's edge put 1-1.5 m of the patch under a footprint that held the path).
SLOPE_GAP_M = 0.3
# The default vehicle's half track and wheelbase [m], the body the relief situations are as steep
# for (terrapref.vehicle.VehicleConfig's; the scenario sits below the vehicle, and
# tests/scenario/test_relief.py holds the two equal).
BODY_M = (0.6, 1.0)
RELIEF_DEG = {
    "gentle mound": 8.0,
    "steep mound": 16.0,
    "middle mound": 12.0,
    "gentle bank": 10.0,
    "steep bank": 16.0,
    "ramp": 7.0,
    "slope": 14.0,
}
START_M, END_M = 8.0, 5.0  # trail before the first situation and after the last [m]
PAIR_SIZES = ((8.0, 5.0), (7.0, 5.5), (7.5, 5.0), (8.0, 5.5))  # (length, width) of a pair's patches [m]
STRIP_M, STRIP_LENGTH_M = 2.8, 7.0  # a strip on the path: its mean width and its length [m]
# A strip's edge beside a feature class runs this much nearer the path at one end and as much
# further at the other, so that its width goes 2.4-3.2 m along it, as a generated layout's middle
# patches' do [m]. With straight edges, the metres a footprint point crosses on the strip change all
# at once where the point passes an edge, so the offset a driver holds only bounds how much worse
# the strip's class is than its neighbour's, and where the edges fall among the offsets (0.2 m
# apart) set the fitted step between the two by up to half again the driver's. Tapered, the metres
# change steadily with the offset, and the offset it holds tells where its trade balances.
STRIP_TAPER_M = 0.4
# ... and on a course with relief: straight edges. Tapered by 0.4 m, teach_relief's nine drives
# (three orders, three relief styles) agreed with their drivers as often on clean frames, and on
# 6 fewer triples of 126 under `field` (docs/lab/2026-12-07-where-the-step-comes-from.md) [m].
RELIEF_TAPER_M = 0.0
LONE_OFFSET_M = 0.3  # a lone patch lies this far left or right of the path [m]
# The ladder's best class alone, (length, width) [m]: wider than the teaching course's lone patch
# (3.0 by 2.6 m, gone round by a driver pricing the class above about 6.8 on the detour's scale),
# gone round above about 10.7 and 17.3 (the synthetic driver goes round a patch L m long when its
# price times L exceeds d^2 (L + 5), d = W / 2 - 0.3 + 0.6 the least offset that clears it).
BRACKET_SIZES_M = ((3.0, 3.4), (2.5, 4.2))
LANE_M, LANE_WIDTH_M = 6.0, 4.0  # a lane's length and width: lethal walls more than 1 m from a 1.2 m vehicle on its middle [m]
LANE_WALL_M = 9.0  # each wall's width: no driver leaves the path that far (8 m at most) [m]
BAND_WIDTH_M = 20.0  # a lane without lethal walls: the class across the whole way [m]
BEND_DEG, TURN_DEG = 12.0, 36.0  # the bend between two situations; each of a turn round's five


@dataclass(frozen=True)
class Situation:
    """One scored situation of a teaching course.

    Attributes:
        kind: ``pair`` (classes[0] left, classes[1] right), ``strip`` (left, middle, right),
            ``lone`` (one class) or ``lane`` (wall, class, wall; or the class alone without lethal classes).
        classes: the classes, left to right.
        offset_m: a lone patch's lateral offset, left positive [m].
        deg: a relief situation's steepest grade or side slope [deg].
        legs_m: the trail before and after its centre [m]; None: its kind's half leg on the flat
            course (:data:`HALF_M`) each.
        size_m: a lone patch's (length, width) as a rectangle [m]; None: the class's lone shape.
    """

    kind: str
    classes: tuple[str, ...]
    offset_m: float = 0.0
    deg: float = 0.0
    legs_m: tuple[float, float] | None = None
    size_m: tuple[float, float] | None = None

    @property
    def before_m(self) -> float:
        return HALF_M[self.kind] if self.legs_m is None else self.legs_m[0]

    @property
    def after_m(self) -> float:
        return HALF_M[self.kind] if self.legs_m is None else self.legs_m[1]

    @property
    def length_m(self) -> float:
        return self.before_m + self.after_m

    @property
    def label(self) -> str:
        side = "left" if self.offset_m > 0 else "right"
        if self.kind == "mound" or self.kind == "ramp":
            return f"{self.kind} {self.deg:g} deg"
        if self.kind == "bank":
            return f"bank {self.deg:g} deg {side}"
        if self.kind == "slope":
            return f"{self.classes[0]} {side} vs bank {self.deg:g} deg"
        if self.kind == "rough":
            return "rough patch"
        return {"pair": " vs ", "strip": " | ", "lone": "", "lane": " | "}[self.kind].join(self.classes)


def balanced_pairs(names: Sequence[str]) -> list[tuple[str, str]]:
    """Every pair of ``names`` once, as (left, right), each name on the left as often as on the
    right to within one; in rounds in which no name comes twice (the circle method)."""
    n = len(names)
    odd = n if n % 2 else n - 1  # names[:odd] form a regular tournament; an even n's last name alternates
    left_of = {}
    for i in range(odd):
        for j in range(odd):
            if i != j and 1 <= (j - i) % odd <= (odd - 1) // 2:
                left_of[frozenset((i, j))] = i
    for i in range(odd, n):
        for j in range(odd):
            left_of[frozenset((i, j))] = j if j % 2 == 0 else i
    # Rounds: fix the last slot, rotate the others (a bye stands in for a missing name).
    slots = list(range(n)) + ([-1] if n % 2 else [])
    pairs = []
    for _ in range(len(slots) - 1):
        for a, b in zip(slots[: len(slots) // 2], reversed(slots[len(slots) // 2 :])):
            if a >= 0 and b >= 0:
                first = left_of[frozenset((a, b))]
                pairs.append((names[first], names[b if first == a else a]))
        slots = [slots[0], slots[-1], *slots[1:-1]]
    return pairs


def situations(classes: ClassTable, full: bool | None = None, relief: bool = False) -> list[Situation]:
    """The situations of ``classes``' teaching course, in driving order.

    ``full``: each pair and strip on both sides (True), once (False; no strip where the
    follow-up shows the :func:`ladder`, :func:`ladder_follows`), or whichever fits the budget
    (None); ``relief``: with the relief situations (:func:`relief_situations`), each pair and each
    lethal class alone once (as in the compact design), and last a mound between the gentle and
    the steep one, on the legs of a course with relief (:func:`_relief_legs`)."""
    terrain, lethal = list(classes.terrain_names), list(classes.lethal)
    if not terrain:
        raise ValueError("the class table has no feature class (neither background nor lethal) to teach")
    full = fits(classes, relief) if full is None else full
    both_sides = full and not relief  # pairs and lethal lone patches on each side, or once with relief
    pairs = balanced_pairs(terrain)
    if both_sides:
        pairs += [(b, a) for a, b in pairs]
    strips = []
    for k, middle in enumerate(terrain if shows_strips(classes, full, relief) else ()):
        others = [t for t in terrain if t != middle] or [classes.background]
        for side in (1, -1) if full else ((1, -1)[k % 2],):
            neighbour = others[(k + (side < 0)) % len(others)]
            if lethal:
                wall = lethal[len(strips) % len(lethal)]
                strips.append(Situation("strip", (wall, middle, neighbour) if side > 0 else (neighbour, middle, wall)))
            else:
                strips.append(Situation("strip", (neighbour, middle, others[(k + 1 + (side < 0)) % len(others)])))
    lone = []
    for k, name in enumerate(terrain):
        lone.append(Situation("lone", (name,), (1, -1)[k % 2] * LONE_OFFSET_M))
    lone += [Situation("lone", (name,), side * LONE_OFFSET_M) for name, side in _lethal_alone(lethal, len(terrain), both_sides)]
    lanes = [
        Situation("lane", (lethal[k % len(lethal)], name, lethal[k % len(lethal)]) if lethal else (name,)) for k, name in enumerate(terrain)
    ]
    items = _interleave([[Situation("pair", p) for p in pairs], strips, lone, lanes, relief_situations(classes) if relief else []])
    if not relief:
        return items
    return _relief_legs([*items, LAST_MOUND])


def _relief_legs(items: Sequence[Situation]) -> list[Situation]:
    """``items`` on the legs of a course with relief: a terrain situation's trail
    (:data:`RELIEF_HALF_M`) as long as the flat course's on a side that faces a relief situation."""

    def half(k: int, side: int) -> float:
        kind, beside = items[k].kind, items[k + side].kind if 0 <= k + side < len(items) else None
        return HALF_M[kind] if beside in RELIEF_KINDS else RELIEF_HALF_M[kind]

    return [replace(s, legs_m=(half(k, -1), half(k, 1))) for k, s in enumerate(items)]


def relief_situations(classes: ClassTable) -> list[Situation]:
    """The relief situations (module docstring) of ``classes``' teaching course: two mounds, two
    banks (one on each side), a ramp, a rough patch, and each feature class against a bank, sides
    alternating; each shows the steepest grade or side slope :data:`RELIEF_DEG` gives it. The
    course ends with one more, after every other situation (:data:`LAST_MOUND`)."""
    d = RELIEF_DEG
    items = [
        Situation("mound", (), 0.0, d["gentle mound"]),
        Situation("bank", (), 1.0, d["gentle bank"]),
        Situation("ramp", (), 0.0, d["ramp"]),
        Situation("mound", (), 0.0, d["steep mound"]),
        Situation("bank", (), -1.0, d["steep bank"]),
        Situation("rough", (), 0.0, 0.0),
    ]
    return items + [Situation("slope", (name,), (1.0, -1.0)[k % 2], d["slope"]) for k, name in enumerate(classes.terrain_names)]


LAST_MOUND = Situation("mound", (), 0.0, RELIEF_DEG["middle mound"])
"""The last situation of a course with relief (:func:`situations`): a mound between the gentle and
the steep one, so that the drive shows grades at three steepnesses with no class in view; last,
so that nothing before it moves."""


def place_relief(c: CourseBuilder, item: Situation, s: float) -> None:
    """The relief situation ``item`` (module docstring) centred at arc length ``s`` of ``c``'s path:
    its relief entries, and a slope's flat patch. Each is as steep as ``item.deg`` for the default
    vehicle's body (its wheels ``a`` = half its wheelbase ahead and behind, or half its track to
    each side): a mound's cosine profile of height h and radius R pitches it most, by
    ``atan(h sin(pi a / R) / (2 a))``, halfway out; a bank's (a ridge of width w) rolls it by
    ``atan(h sin(2 pi a / w) / (2 a))`` a quarter of its width from its line, where the path runs;
    a ramp rises its height over its edge. A rough patch is level, its steps' noise each from a seed of its own (:data:`ROUGH_LADDER_M`)."""
    half_track, wheelbase = BODY_M
    tan = math.tan(math.radians(item.deg))
    if item.kind == "mound":
        a = 0.5 * wheelbase
        height = tan * 2.0 * a / math.sin(math.pi * a / MOUND_RADIUS_M)
        c.relief.append({"mound": {"center": c.to_world(s, [(0.0, 0.0)])[0], "radius": MOUND_RADIUS_M, "height_m": round(height, 3)}})
    elif item.kind == "ramp":
        a, b = RAMP_TOP_M / 2, RAMP_ACROSS_M / 2
        corners = c.to_world(s, [(-a, -b), (a, -b), (a, b), (-a, b)])
        c.relief.append({"plateau": {"polygon": corners, "height_m": round(tan * RAMP_EDGE_M, 3), "edge_m": RAMP_EDGE_M}})
    elif item.kind == "rough":
        (length, width), steps = ROUGH_PATCH_M, len(ROUGH_LADDER_M)
        b = width / 2
        for k, amplitude in enumerate(ROUGH_LADDER_M):
            a0, a1 = length * (k / steps - 0.5), length * ((k + 1) / steps - 0.5)
            corners = c.to_world(s, [(a0, -b), (a1, -b), (a1, b), (a0, b)])
            c.relief.append({"noise": {"amplitude_m": amplitude, "wavelength_m": ROUGH_WAVELENGTH_M, "seed": 1 + k, "polygon": corners}})
    else:  # a bank with the path on its flank: rising on the side of the offset, or across from a slope's patch
        side = math.copysign(1.0, item.offset_m) * (1.0 if item.kind == "bank" else -1.0)
        line = c.to_world(s, [(-BANK_LENGTH_M / 2, side * BANK_WIDTH_M / 4), (BANK_LENGTH_M / 2, side * BANK_WIDTH_M / 4)])
        a = half_track
        height = tan * 2.0 * a / math.sin(2.0 * math.pi * a / BANK_WIDTH_M)
        c.relief.append({"ridge": {"polyline": line, "width_m": BANK_WIDTH_M, "height_m": round(height, 3)}})
        if item.kind == "slope":
            length, width = SLOPE_PATCH_M
            c.rect(item.classes[0], s, math.copysign(half_track + SLOPE_GAP_M + width / 2, item.offset_m), length, width)


# What a drive on relief may leave unshown, and the situation that shows it (``course --after``):
# ground past the steep bank's side slope or the steep mound's grade among the ways it could have
# taken (the steering prices nothing steeper than it saw); enough frames climbing, descending, and
# on rough ground for the speed rule to read what each sheds.
RELIEF_LESSONS = {
    "steep side slope": Situation("bank", (), 1.0, RELIEF_DEG["steep bank"]),
    "steep grade": Situation("mound", (), 0.0, RELIEF_DEG["steep mound"]),
    "grades": Situation("ramp", (), 0.0, RELIEF_DEG["ramp"]),
    "rough ground": Situation("rough", (), 0.0, 0.0),
}


def _lethal_alone(lethal: Sequence[str], first: int, both_sides: bool) -> list[tuple[str, int]]:
    """The lethal classes a teaching course shows alone on the path, each with its side (+1 or
    -1), at most :data:`LETHAL_LONE`: the first on both sides (``both_sides``), or each once, the
    sides alternating on from the feature classes' lone patches (``first`` of them)."""
    sides = [(name, side) for k, name in enumerate(lethal, first) for side in ((1, -1) if both_sides else ((1, -1)[k % 2],))]
    return sides[:LETHAL_LONE]


def ladder_follows(classes: ClassTable) -> bool:
    """Whether ``classes``' compact teaching course leaves its strips to the follow-up's
    :func:`ladder`: a table too large for the full design, with a lethal class for the ladder's
    wall (without one, a strip's other side would be the background, which most drivers take over
    any class, and the strip would show no step of the order)."""
    return bool(classes.lethal) and not fits(classes)


def shows_strips(classes: ClassTable, full: bool, relief: bool) -> bool:
    """Whether ``classes``' teaching course of the ``full`` design or not, with ``relief`` or not,
    shows its strips: all but the compact course whose follow-up shows the :func:`ladder`."""
    return full or relief or not ladder_follows(classes)


def fits(classes: ClassTable, relief: bool = False) -> bool:
    """Whether the full design of ``classes``' course stays within :data:`BUDGET_M`, or with
    ``relief`` (its relief situations) within :data:`RELIEF_BUDGET_M`."""
    return course_length(situations(classes, True, relief)) <= (RELIEF_BUDGET_M if relief else BUDGET_M)


def neighbours_within(
    classes: ClassTable, open_pairs: Sequence[tuple[str, str]], neighbours: Sequence[tuple[str, str]], relief: Sequence[str] = ()
) -> list[tuple[str, str]]:
    """The first of ``neighbours`` that a follow-up course of ``open_pairs`` and the ``relief``
    lessons can show within :data:`FOLLOW_UP_M` (the open pairs and the lessons are shown whatever
    their length: a pair left unshown would read as one a drive could not settle)."""
    shown = list(neighbours)
    while shown and course_length(_follow_up_items(classes, open_pairs, Beside(shown, relief))) > FOLLOW_UP_M:
        shown.pop()
    return shown


@dataclass(frozen=True)
class Beside:
    """What a follow-up course shows beside the open pairs.

    Attributes:
        neighbours: the pairs' neighbours in the learned order
            (:func:`~terrapref.learning.identify.bracketed`), which keep what is identified so.
        relief: the relief lessons (:data:`RELIEF_LESSONS`) the drives left unshown.
        order: the learned order (best first), whose :func:`ladder` the course shows; empty: none.
    """

    neighbours: Sequence[tuple[str, str]] = ()
    relief: Sequence[str] = ()
    order: Sequence[str] = ()


def follow_up_course(
    classes: ClassTable, open_pairs: Sequence[tuple[str, str]], name: str, courses: Sequence[str], beside: Beside = Beside()
) -> CourseBuilder:
    """The follow-up course of ``open_pairs``, which the drives of ``courses`` (each drive's
    course, by name) left open together, and of what it shows ``beside`` them."""
    neighbours, relief, order = beside.neighbours, beside.relief, beside.order
    driven = " and ".join(dict.fromkeys(courses))
    what = f"the drive of {driven}" if len(courses) == 1 else f"{len(courses)} drives of {driven} together"
    parts = []
    if open_pairs:
        listed = "; ".join(f"{a} vs {b}" for a, b in open_pairs)
        with_them = (
            f", beside their neighbours in the learned order ({'; '.join(f'{a} vs {b}' for a, b in neighbours)})" if neighbours else ""
        )
        parts.append(f"the pairs {what} left open ({listed}){with_them}, each once, the sides alternating")
    if relief:
        parts.append(f"the relief {'left' if open_pairs else what + ' left'} unshown ({', '.join(relief)})")
    steps = [c for c in order if c in classes.terrain_names]
    if len(steps) > 1:
        parts.append(
            f"the order {what} learned ({' > '.join(steps)}) as strips, each class on the path between the next better one "
            f"and {_ladder_wall(classes)}, and {steps[0]} alone at two sizes"
        )
    elif steps:
        parts.append(f"{steps[0]}, the best class {what} learned, alone at two sizes")
    items = _follow_up_items(classes, open_pairs, beside)
    return build_course(classes, items, name, f"Follow-up course: {'; and '.join(parts)}.")


def ladder(classes: ClassTable, order: Sequence[str]) -> list[Situation]:
    """The ladder of ``order`` (feature classes, best first; other names are passed over): each
    class as a strip on the path beside the next better one, lethal terrain (or, in a table
    without lethal classes, the background) on its other side, the sides alternating; then the
    best class alone at the two sizes of :data:`BRACKET_SIZES_M`, left and right of the path.

    A compact teaching course's pairs say which class of two a driver takes, not by how much; the
    strips say how much worse each step of the order is against a 2 m detour, on which a layout's
    triples turn, and the two lone patches bound the best class's price from above as well as
    from below (nothing else on either course does: too wide to go round, a pair tells only the
    order)."""
    steps = [c for c in order if c in classes.terrain_names]
    wall = _ladder_wall(classes)
    out = []
    for k, (better, worse) in enumerate(zip(steps, steps[1:])):
        out.append(Situation("strip", (wall, worse, better) if k % 2 == 0 else (better, worse, wall)))
    for side, size in zip((1, -1), BRACKET_SIZES_M if steps else ()):
        out.append(Situation("lone", (steps[0],), side * LONE_OFFSET_M, size_m=size))
    return out


def follow_up(classes: ClassTable, open_pairs: Sequence[tuple[str, str]]) -> list[Situation]:
    """A short course of only ``open_pairs`` (class names; the background means "alone on the
    path"): each pair once, the sides alternating from pair to pair (the first as given), a class
    against the background as a lone patch."""
    out = []
    for k, (a, b) in enumerate(open_pairs):
        side = (1, -1)[k % 2]
        if classes.background in (a, b):
            name = b if a == classes.background else a
            out.append(Situation("lone", (_concrete(classes, name),), side * LONE_OFFSET_M))
        else:
            a, b = (_concrete(classes, n) for n in (a, b))
            out.append(Situation("pair", (a, b) if side > 0 else (b, a)))
    return out


def _concrete(classes: ClassTable, name: str) -> str:
    """A class for a terrain column (the lethal column: the first lethal class)."""
    return classes.lethal[0] if name == classes.lethal_column and name not in classes.names else name


def _interleave(lists: Sequence[Sequence[Situation]]) -> list[Situation]:
    """The situations of every list, each list spread evenly over the course."""
    keyed = [((i + 0.5) / len(items), k, s) for k, items in enumerate(lists) for i, s in enumerate(items)]
    return [s for _, _, s in sorted(keyed, key=lambda t: (t[0], t[1]))]


def course_length(items: Sequence[Situation]) -> float:
    """The trail's length [m]: every situation's leg, and the trail before and after them."""
    return START_M + sum(s.length_m for s in items) + END_M


def _turns(count: int) -> list[float]:
    """Heading changes [deg] after each of ``count`` situations: gentle bends either way, and
    every :data:`LANE` situations a turn round (five 36 degree bends), left and right in turn."""
    turns, lane, k = [], 0, 0
    while len(turns) < count - 1:
        if k == LANE:
            sign = 1.0 if lane % 2 == 0 else -1.0
            turns += [sign * TURN_DEG] * 5
            lane, k = lane + 1, 0
        else:
            turns.append(BEND_DEG if len(turns) % 2 == 0 else -BEND_DEG)
            k += 1
    return turns[: count - 1]


def build_course(
    classes: ClassTable, items: Sequence[Situation], name: str, description: str, taper_m: float = STRIP_TAPER_M
) -> CourseBuilder:
    """The course of ``items`` in driving order, on a trail folded into a compact map; its strips'
    edges beside a class tapered by ``taper_m`` (:func:`place_strip`), the first strip's
    narrower at its start and the next one's wider, in turn."""
    lengths = [s.length_m for s in items]
    legs = [START_M + lengths[0], *lengths[1:]]
    legs[-1] += END_M
    wp, size = trail(legs, _turns(len(items)))
    c = CourseBuilder(name, description, size, [tuple(p) for p in wp], classes.background, classes)
    order = {n: k for k, n in enumerate(classes.names)}
    s, pairs, strips = START_M, 0, 0
    for k, item in enumerate(items):
        s += item.before_m
        zid = str(k + 1)
        if item.kind in RELIEF_KINDS:  # no zone: evaluate finds relief zones by the ground's own tilt
            place_relief(c, item, s)
        elif item.kind == "lone":
            name_ = item.classes[0]
            if item.size_m is None:
                _lone(c, name_, order[name_], s, item.offset_m)
            else:
                c.rect(name_, s, item.offset_m, *item.size_m)
            c.zone(zid, item.label, s, (9.0, 9.0), "avoid")
        elif item.kind == "lane":
            _lane(c, item.classes, s)
            c.zone(zid, item.label, s, (LANE_M + 4.0, LANE_WIDTH_M + 2.0), "best")
        elif item.kind == "pair":
            c.pair(zid, item.classes[0], item.classes[1], s, PAIR_SIZES[pairs % len(PAIR_SIZES)])
            pairs += 1
        else:
            place_strip(c, item.classes, s, (1, -1)[strips % 2] * taper_m, classes.lethal)
            strips += 1
            # Beside the background, leaving the strip for it is every driver's choice.
            c.zone(zid, item.label, s, (11.0, 17.0), "avoid" if classes.background in item.classes else "best")
        s += item.after_m
    return c


def place_strip(c: CourseBuilder, classes: Sequence[str], s: float, taper_m: float, walls: Sequence[str] = ()) -> None:
    """A strip (left, middle, right ``classes``) centred at arc length ``s`` of ``c``'s path: the
    middle class :data:`STRIP_M` wide on average and :data:`STRIP_LENGTH_M` long on the path, 4.5 m
    of the others beside it. Each edge beside a class not among ``walls`` (lethal classes) runs
    ``taper_m`` nearer the path at the strip's start and as much further at its end (a negative
    ``taper_m``: the other way round; :data:`STRIP_TAPER_M`)."""
    left, middle, right = classes
    a, h = STRIP_LENGTH_M / 2, STRIP_M / 2
    if taper_m == 0.0:  # straight edges: rectangles, as courses were written before the taper
        for name, lat, width in ((left, h + 2.25, 4.5), (middle, 0.0, STRIP_M), (right, -h - 2.25, 4.5)):
            c.rect(name, s, lat, STRIP_LENGTH_M, width)
        return
    tl, tr = (0.0 if name in walls else taper_m for name in (left, right))
    edge_l, edge_r = [(-a, h - tl), (a, h + tl)], [(-a, -h + tr), (a, -h - tr)]
    c.polygon(left, s, [*edge_l, (a, h + 4.5), (-a, h + 4.5)])
    c.polygon(middle, s, [*edge_r, *reversed(edge_l)])
    c.polygon(right, s, [(-a, -h - 4.5), (a, -h - 4.5), *reversed(edge_r)])


def _lane(c: CourseBuilder, classes: tuple[str, ...], s: float) -> None:
    """A class on the path between lethal walls no driver passes round (wall, class, wall), or across
    the whole way (the class alone)."""
    if len(classes) == 1:
        c.rect(classes[0], s, 0.0, LANE_M, BAND_WIDTH_M)
        return
    wall, name, _ = classes
    c.rect(name, s, 0.0, LANE_M, LANE_WIDTH_M)
    for side in (1.0, -1.0):
        c.rect(wall, s, side * (LANE_WIDTH_M + LANE_WALL_M) / 2, LANE_M, LANE_WALL_M)


def _lone(c: CourseBuilder, name: str, index: int, s: float, lat: float) -> None:
    """A patch under 3 m across on the path (a driver passes it on the background): a rectangle,
    an irregular quadrilateral or a disc, by the class's place in the table."""
    shape = index % 3
    if shape == 0:
        c.rect(name, s, lat, 3.0, 2.6)
    elif shape == 1:
        c.polygon(name, s, [(-1.6, lat - 1.2), (1.4, lat - 1.4), (1.6, lat + 1.1), (-1.2, lat + 1.4)])
    else:
        c.circle(name, s, lat, 1.4)


def teaching_course(classes: ClassTable, name: str = "teaching_course", full: bool | None = None) -> CourseBuilder:
    """The teaching course of ``classes`` (see the module docstring)."""
    full = fits(classes) if full is None else full
    return build_course(classes, situations(classes, full), name, description(classes, full))


def designed_course(
    classes: ClassTable, design: str = "auto", name: str = "teaching_course", relief: bool = False
) -> tuple[CourseBuilder, list[Situation]]:
    """The teaching course of ``classes`` in ``design`` (``terrapref course --design``): ``full``
    (every pair and strip once on each side), ``compact`` (every pair and strip once, sides
    balanced) or ``auto`` (full while it stays within :data:`BUDGET_M`, or with relief
    :data:`RELIEF_BUDGET_M`); with the relief situations where ``relief`` (each pair and lethal
    lone patch then once in either design); with its situations in driving order.

    Raises:
        ValueError: the table has no feature class to teach.
    """
    full = fits(classes, relief) if design == "auto" else design == "full"
    items = situations(classes, full, relief)
    text = description(classes, full, relief) + (f" {RELIEF_DESCRIPTION}" if relief else "")
    return build_course(classes, items, name, text, RELIEF_TAPER_M if relief else STRIP_TAPER_M), items


def relief_course(
    classes: ClassTable, design: str = "auto", name: str = "teaching_course_relief", seed: int = 0
) -> tuple[CourseBuilder, list[Situation]]:
    """The teaching course of ``classes`` with relief (``terrapref course --relief SEED``, and the
    packaged ``teach_relief`` of the default table with seed 0): :func:`designed_course` with the
    relief situations, and the relief of ``seed`` between the situations
    (terrapref.scenario.relief_layout)."""
    from terrapref.scenario.loader import parse_scenario
    from terrapref.scenario.relief_layout import relief_for

    course, items = designed_course(classes, design, name, relief=True)
    course.relief = [*course.relief, *relief_for(parse_scenario(course.data(), name, classes), seed)]
    return course, items


def follow_up_after(
    classes: ClassTable, open_pairs: Sequence[tuple[str, str]], courses: Sequence[str], name: str | None = None, beside: Beside = Beside()
) -> tuple[CourseBuilder, list[Situation]]:
    """The follow-up course of ``open_pairs``, which drives of ``courses`` (each drive's course, by
    name) left open together (``terrapref course --after``), and of what it shows ``beside`` them
    (:func:`follow_up_course`), with its situations in driving order; named ``name``, by default
    the first course's name followed by ``_more``."""
    course = follow_up_course(classes, open_pairs, name or f"{Path(courses[0]).name}_more", courses, beside)
    return course, _follow_up_items(classes, open_pairs, beside)


def _follow_up_items(classes: ClassTable, open_pairs: Sequence[tuple[str, str]], beside: Beside = Beside()) -> list[Situation]:
    """A follow-up course's situations in driving order: ``open_pairs``' and the neighbours'
    (:func:`follow_up`), the relief lessons' (:data:`RELIEF_LESSONS`) and the :func:`ladder`
    of the learned order, each spread over the course; with a ladder, on the shorter trail of
    :data:`LADDER_HALF_M`."""
    pairs, rungs = follow_up(classes, [*open_pairs, *beside.neighbours]), ladder(classes, beside.order)
    items = _interleave([pairs, [RELIEF_LESSONS[r] for r in beside.relief], rungs])
    if not rungs:
        return items
    return [replace(s, legs_m=(LADDER_HALF_M[s.kind],) * 2) for s in items]


def _ladder_wall(classes: ClassTable) -> str:
    """The class on a ladder strip's outer side: the first lethal class (the background for a
    table without one, which :func:`ladder_follows` gives no ladder)."""
    return classes.lethal[0] if classes.lethal else classes.background


def write_teaching_course(folder: str | Path, classes: ClassTable, relief: bool = False) -> Path:
    """The teaching course of ``classes`` written as ``folder/teaching_course.yaml`` (the folder
    made if need be), for the commands that demonstrate it; its absolute path. ``relief``: the
    course with relief (:func:`relief_course`, seed 0, as ``teach_relief`` is the default table's)."""
    from terrapref.fileio import write_text_atomic

    path = Path(folder).resolve() / "teaching_course.yaml"
    path.parent.mkdir(parents=True, exist_ok=True)
    course = relief_course(classes)[0] if relief else teaching_course(classes)
    write_text_atomic(path, course.to_yaml())
    return path


RELIEF_DESCRIPTION = (
    "With relief: a gentle, a steep and, last, a middle mound on the path, a gentle and a steep bank beside it, a ramp up and down, a rough patch in steps, "
    "each feature class flat beside the path against a bank of the background, and bumps and dips between the situations."
)


def description(classes: ClassTable, full: bool, relief: bool = False) -> str:
    """What the teaching course of ``classes`` shows, in the full or the compact design (with
    ``relief``, the terrain situations of a course with relief)."""
    n = len(classes.terrain_names)
    design = (
        "no pairs (one feature class)"
        if n < 2
        else "every pair once on each side"
        if full and not relief
        else "every pair once, each class left as often as right"
    )
    beside = "each other class" if full and relief and n > 1 else "another class"  # a full course with relief: up to 3 classes
    strip = f"between lethal terrain and {beside}" if classes.lethal else "between two other classes"  # a table without lethal classes
    strips = (
        f"every class as a strip on the path {strip}"
        if shows_strips(classes, full, relief)
        else "no strip (its follow-up shows the learned order's)"
    )
    alone = "every class alone on the path"
    shown = list(dict.fromkeys(name for name, _ in _lethal_alone(classes.lethal, n, full and not relief)))
    if shown != list(classes.lethal):  # the others shown as walls
        alone = f"every feature class alone on the path, and lethal terrain ({', '.join(shown)})"
    return (
        f"Teaching course for {n} feature class{'es' if n != 1 else ''} ({', '.join(classes.terrain_names)}): {design}; "
        f"{strips}; {alone}; "
        f"every feature class as a lane, driven along at the driver's speed on it."
    )
