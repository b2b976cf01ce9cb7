"""What a demonstration shows about a preference, and what it leaves open (identifiability).

A demonstration teaches "mud rather than water" only if the driver was, at some moment, offered
both and took one. This module reads that from the data the planner learns from, not from the
course layout, so it works for any recording (a person's drive on any course, an imported log):

- **Comparisons.** A frame *compares* class A with class B when, among the trajectories that
  stay near the path (distance utility >= ``NEAR``), one runs mostly over A (share >= ``SHARE``,
  less than half as much B) and another mostly over B, and the driver's trajectory is one of
  them, or is clean of both. The frame is evidence for whichever the driver's trajectory holds
  more of; a clean choice is evidence for grass over both. Grass against A is compared the same
  way, with a trajectory clear of terrain in place of B. Each comparison is counted on the side
  the chosen class lay (left: the trajectories turning left).
- **The learned order.** The linear utility fitted to the same frames (terrapref.learning.linear)
  gives each class a weight; the order of the weights is the order learned, and the difference of
  two weights is the margin, with a standard error from the fit's Fisher information (a Wald
  interval: the data's own uncertainty about the difference).

A pair is *identified* when it was compared in at least ``MIN_FRAMES`` frames and its margin
is more than twice its standard error; otherwise the planner's choice between the two is a
guess, and :meth:`Identifiability.warnings` says so.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from terrapref.learning.linear import LinearUtility
from terrapref.records import to_plain
from terrapref.terrain.classes import LETHAL_COLUMN

GRASS = "grass"  # the default table's background, compared like a class
SHARE = 0.2  # a trajectory "runs over" a class when at least this share of its points do
NEAR = 0.5  # trajectories whose distance utility is below this have left the path: not an option
MIN_FRAMES = 10  # fewer comparing frames than this leave a pair unidentified
NO_DECLARED_ORDER = "no order was declared with the drive (--profile): the learned order is compared with none"


@dataclass(frozen=True)
class PairEvidence:
    """What the data say about one pair of classes (``first`` before ``second`` in the learned order).

    Attributes:
        first, second: class names (``grass`` for the background).
        frames: frames that compared the two.
        for_first, for_second: of those, the frames whose choice favoured each.
        sides: comparing frames with ``first`` on the left and on the right (left, right).
        margin: learned weight of ``first`` minus that of ``second`` (>= 0), in utility units
            (grass has weight 0 by construction).
        stderr: standard error of ``margin`` (Wald), None if unknown.
    """

    first: str
    second: str
    frames: int
    for_first: int
    for_second: int
    sides: tuple[int, int]
    margin: float
    stderr: float | None

    @property
    def identified(self) -> bool:
        return self.frames >= MIN_FRAMES and self.stderr is not None and self.margin > 2.0 * self.stderr

    def describe(self) -> str:
        # the standard error itself, the unit of the identification rule (margin > 2 standard errors)
        interval = f", standard error {self.stderr:.2f}" if self.stderr is not None else ""
        seen = (
            f"compared in {self.frames} frames ({self.for_first} for {self.first}, {self.for_second} for {self.second}; "
            f"{self.first} on the left {self.sides[0]}, on the right {self.sides[1]})"
            if self.frames
            else "never compared"
        )
        return f"{self.first} > {self.second}: margin {self.margin:.2f}{interval}, {seen}"

    def to_dict(self) -> dict:
        return {**to_plain(self), "identified": self.identified}


@dataclass(frozen=True)
class Identifiability:
    """The learned order of the classes (grass included) and the evidence for every pair."""

    order: tuple[str, ...]  # best first
    pairs: tuple[PairEvidence, ...]
    lethal: tuple[str, ...] = ()  # the class table's lethal column, which the offset rule never drives onto
    background: str = GRASS  # the class table's background (the class of clean trajectories)

    def pair(self, a: str, b: str) -> PairEvidence | None:
        return next((p for p in self.pairs if {p.first, p.second} == {a, b}), None)

    def unidentified(self) -> list[PairEvidence]:
        return [p for p in self.pairs if not p.identified]

    def warnings(self) -> list[str]:
        out = []
        for p in self.unidentified():
            why = (
                "never compared"
                if p.frames == 0
                else (
                    f"compared in only {p.frames} frames" if p.frames < MIN_FRAMES else "compared, but the margin is within its uncertainty"
                )
            )
            lethal = next((c for c in (p.first, p.second) if c in self.lethal), None)
            if lethal is not None:  # the class table, not the drive, keeps the offset rule off it
                pooled = lethal == LETHAL_COLUMN  # several lethal classes, one column
                what, verb, it = ("the lethal classes", "are", "them") if pooled else (lethal, "is", "it")
                out.append(
                    f"{p.first} vs {p.second}: {why}; {what} {verb} lethal, so the offset rule never drives onto {it} "
                    f"whatever the drive shows, but C's ranking of the two is a guess"
                )
            else:
                out.append(f"{p.first} vs {p.second}: {why}; the planner's choice between them is a guess")
        return out

    def lines(self, profile: Sequence[str] | None = None) -> list[str]:
        """The report; with ``profile`` (the order stored with the data, best first), also how the
        learned order compares with it (:meth:`against`)."""
        if not any(p.margin > 0 for p in self.pairs):
            out = ["learned order: none (the drive sets no class above another)"]
        else:
            out = [f"learned order: {' > '.join(self.order)}"]
            out += [f"  {p.describe()}{'' if p.identified else '  <- not identified'}" for p in self.pairs]
        out += [f"warning: {w}" for w in self.warnings()]
        return out + (self.against(profile) if profile else [])

    def lines_with_order(self, declared: Sequence[str] | None) -> list[str]:
        """The report (:meth:`lines`) of data whose drives declared the order ``declared``, and
        how the learned order compares with it; with none declared, that there is nothing to
        compare it with (an order nobody declared is not made up)."""
        return self.lines(declared) if declared else [*self.lines(), NO_DECLARED_ORDER]

    def against(self, profile: Sequence[str]) -> list[str]:
        """How the learned order compares with ``profile``, pair by pair of the classes both name:
        the pairs learned the other way round, each with its margin and whether the data identify
        it; or that every pair agrees, and how many of them the data identify."""
        named = [c for c in profile if c in self.order]
        head = f"the profile stored with the drive: {' > '.join(named)}"
        pairs = [self.pair(a, b) for i, a in enumerate(named) for b in named[i + 1 :]]  # a before b in the profile
        evidence = [p for p in pairs if p.margin > 0]  # a tie (no weight learned between them) orders nothing
        unseen = f"; {len(pairs) - len(evidence)} tied" if len(evidence) < len(pairs) else ""
        reversed_ = [p for p in evidence if named.index(p.first) > named.index(p.second)]
        if not evidence:
            return [f"{head}: the drive orders none of its {len(pairs)} pairs"]
        if not reversed_:
            identified = sum(p.identified for p in evidence)
            return [f"{head}: the drive agrees on all {len(evidence)} pairs it orders ({identified} identified){unseen}"]
        return [
            f"{head}: the drive orders {len(reversed_)} of {len(evidence)} pairs the other way round{unseen}",
            *(
                f"  {p.second} > {p.first} in the profile, {p.first} > {p.second} in the drive (margin {p.margin:.2f}, "
                f"{'identified' if p.identified else 'not identified'})"
                for p in reversed_
            ),
        ]

    def to_dict(self) -> dict:
        out = {"order": list(self.order), "pairs": [p.to_dict() for p in self.pairs], "min_frames": MIN_FRAMES, "lethal": list(self.lethal)}
        return out | ({"background": self.background} if self.background != GRASS else {})

    @classmethod
    def from_dict(cls, data: dict) -> Identifiability:
        pairs = tuple(
            PairEvidence(
                p["first"],
                p["second"],
                int(p["frames"]),
                int(p["for_first"]),
                int(p["for_second"]),
                (int(p["sides"][0]), int(p["sides"][1])),
                float(p["margin"]),
                None if p["stderr"] is None else float(p["stderr"]),
            )
            for p in data["pairs"]
        )
        return cls(tuple(data["order"]), pairs, tuple(data.get("lethal", ())), str(data.get("background", GRASS)))


def count_comparisons(
    U: np.ndarray, labels: np.ndarray, classes: tuple[str, ...], background: str = GRASS
) -> dict[tuple[str, str], np.ndarray]:
    """Per ordered pair (a, b): counts [a chosen with a on the left, a chosen on the right,
    b chosen with b on the left, b chosen on the right] over the frames comparing them.

    Args:
        U: (N, m, K + 1) utilities: K terrain shares in ``classes`` order, the distance utility last.
        labels: (N,) chosen trajectory per frame.
        classes: the K terrain classes; ``background`` is added as the class of clean trajectories.
    """
    n, m, _ = U.shape
    k = len(classes)
    terrain = U[:, :, :k]
    clean = terrain.sum(axis=2) < 0.05  # (N, m): (almost) no terrain on the trajectory
    near = U[:, :, -1] >= NEAR
    shares = np.concatenate([terrain, clean[..., None].astype(float)], axis=2)  # grass as column k
    names = (*classes, background)
    left = np.arange(m) > (m - 1) / 2  # trajectories turning left (w > 0)
    chosen = shares[np.arange(n), labels]  # (N, K + 1)
    out: dict[tuple[str, str], np.ndarray] = {}
    for a, b in itertools.combinations(range(k + 1), 2):
        over_a = near & (shares[:, :, a] >= SHARE) & (shares[:, :, b] < 0.5 * shares[:, :, a])
        over_b = near & (shares[:, :, b] >= SHARE) & (shares[:, :, a] < 0.5 * shares[:, :, b])
        offered = over_a.any(axis=1) & over_b.any(axis=1)
        # Which side each lies on: the mean turn of the trajectories that run over it.
        a_left = (over_a * left).sum(axis=1) * over_b.sum(axis=1) > (over_b * left).sum(axis=1) * over_a.sum(axis=1)
        took_a = offered & (chosen[:, a] > chosen[:, b]) & (chosen[:, a] >= SHARE / 2)
        took_b = offered & (chosen[:, b] > chosen[:, a]) & (chosen[:, b] >= SHARE / 2)
        if b == k:  # against grass, a clean choice is grass (between two patches it favours neither)
            took_b = offered & clean[np.arange(n), labels]
        out[(names[a], names[b])] = np.array(
            [(took_a & a_left).sum(), (took_a & ~a_left).sum(), (took_b & ~a_left).sum(), (took_b & a_left).sum()]
        )
    return out


def fisher_covariance(
    U: np.ndarray, labels: np.ndarray, utility: LinearUtility, U2: np.ndarray | None = None, gamma: float = 1.0
) -> np.ndarray:
    """Covariance of the linear utility's parameters (w, b[, gamma]) at the fit, from the Fisher
    information of the softmax over trajectories (the pseudo-inverse where it is singular).

    With look-ahead utilities ``U2`` (N, m, m, K + 1), trajectory i scores
    ``f(U_i) + gamma * max_j f(U2_ij)`` (terrapref.learning.linear.fit_lookahead_utility); with
    the best continuation j held fixed, that is linear in (w, b, gamma), which gives its design.
    """
    n, m, k = U.shape
    X = np.concatenate([U, np.broadcast_to(np.eye(m), (n, m, m))], axis=2)  # (N, m, K + m)
    if U2 is not None:
        f2 = U2.astype(np.float64) @ utility.w + utility.b  # (N, m, m)
        best = np.argmax(f2, axis=2)
        value = np.take_along_axis(f2, best[..., None], axis=2)[..., 0]
        cont = np.take_along_axis(U2.astype(np.float64), best[..., None, None], axis=2)[:, :, 0]  # (N, m, K)
        X = X + gamma * np.concatenate([cont, np.eye(m)[best]], axis=2)
        X = np.concatenate([X, value[..., None]], axis=2)
        logits = U @ utility.w + utility.b + gamma * value
    else:
        logits = U @ utility.w + utility.b
    p = np.exp(logits - logits.max(axis=1, keepdims=True))
    p /= p.sum(axis=1, keepdims=True)
    centred = X - np.einsum("nm,nmd->nd", p, X)[:, None, :]
    info = np.einsum("nm,nmd,nme->de", p, centred, centred)
    return np.linalg.pinv(info)


@dataclass(frozen=True)
class TableNames:
    """What the report needs of the class table besides the terrain columns.

    Attributes:
        background: the background class (the class of clean trajectories, weight 0).
        lethal: the lethal column (its pairs are warned about differently).
    """

    background: str = GRASS
    lethal: tuple[str, ...] = ()


@dataclass(frozen=True)
class FittedLookahead:
    """The look-ahead a linear utility was fitted through (terrapref.learning.linear.fit_lookahead_utility).

    Attributes:
        U2: (N, m, m, K + 1) look-ahead utilities of the frames.
        gamma: the weight the best continuation's value got in the fit.
    """

    U2: np.ndarray
    gamma: float


def identifiability(
    U: np.ndarray,
    labels: np.ndarray,
    classes: tuple[str, ...],
    utility: LinearUtility,
    lookahead: FittedLookahead | None = None,
    names: TableNames = TableNames(),
) -> Identifiability:
    """The evidence and learned order for every pair of ``classes`` and the background.

    Args:
        U: (N, m, K + 1) utilities of the demonstrated frames (not mirrored): terrain shares, distance.
        labels: (N,) the demonstrated trajectories.
        classes: the K terrain classes, in U's column order.
        utility: the linear utility fitted to these frames (or to them and their mirror images).
        lookahead: the look-ahead ``utility`` was fitted through, if it was.
        names: the background's name and the lethal column's.
    """
    background = names.background
    counts = count_comparisons(U, labels, classes, background)
    cov = (
        fisher_covariance(U, labels, utility) if lookahead is None else fisher_covariance(U, labels, utility, lookahead.U2, lookahead.gamma)
    )
    weight = {name: float(utility.w[i]) for i, name in enumerate(classes)} | {background: 0.0}
    order = tuple(sorted(weight, key=lambda c: -weight[c]))
    pairs = []
    for a, b in itertools.combinations(order, 2):  # a before b in the learned order
        key, flip = ((a, b), False) if (a, b) in counts else ((b, a), True)
        c = counts[key]
        for_a, for_b = (c[2] + c[3], c[0] + c[1]) if flip else (c[0] + c[1], c[2] + c[3])
        a_left, a_right = (c[2] + c[1], c[3] + c[0]) if flip else (c[0] + c[3], c[1] + c[2])
        grad = np.zeros(len(cov))
        if a != background:
            grad[classes.index(a)] += 1.0
        if b != background:
            grad[classes.index(b)] -= 1.0
        var = float(grad @ cov @ grad)
        stderr = math.sqrt(var) if var > 0 and math.isfinite(var) else None
        pairs.append(
            PairEvidence(a, b, int(for_a + for_b), int(for_a), int(for_b), (int(a_left), int(a_right)), weight[a] - weight[b], stderr)
        )
    return Identifiability(order, tuple(pairs), names.lethal, background)


Comparisons = Mapping[tuple[str, str], np.ndarray]
"""One drive's comparisons, as :func:`count_comparisons` counts them."""


def favoured(comparisons: Comparisons, a: str, b: str) -> tuple[int, int]:
    """How many of one drive's frames comparing ``a`` with ``b`` favoured each: (for a, for b)."""
    if (a, b) in comparisons:
        c = comparisons[(a, b)]
        return int(c[0] + c[1]), int(c[2] + c[3])
    c = comparisons.get((b, a), np.zeros(4))
    return int(c[2] + c[3]), int(c[0] + c[1])


def bracketed(order: Sequence[str], pairs: Sequence[tuple[str, str]]) -> list[tuple[str, str]]:
    """The neighbours a follow-up shows beside ``pairs``: for each pair, the class just above its
    better class in the learned ``order`` (best first) with that class, and its worse class with
    the class just below it; each once, and none of ``pairs`` themselves.

    Frames of a pair alone move its two classes' weights, and can move one past a neighbour it
    was identified against (the neighbour's margin is often the next smallest); frames of the
    neighbours as well hold both ends in place.
    """
    shown = {frozenset(p) for p in pairs}
    out = []
    for a, b in pairs:
        i, j = sorted((order.index(a), order.index(b)))
        for k in (i - 1, j):  # (the class above, the better one) and (the worse one, the class below)
            if k >= 0 and k + 1 < len(order) and frozenset(order[k : k + 2]) not in shown:
                shown.add(frozenset(order[k : k + 2]))
                out.append((order[k], order[k + 1]))
    return out


@dataclass(frozen=True)
class FollowUp:
    """What a follow-up course after some drives shows (``terrapref course --after``).

    Attributes:
        open: the pairs the drives leave unidentified that a further drive can still settle.
        neighbours: their neighbours in the learned order (:func:`bracketed`), shown beside them.
        left: one line per pair left open that no further course settles, saying why.
        reopened: one line per pair the drives before the last identified and the last reopened,
            shown again, saying how.
        relief: the relief lessons (terrapref.scenario.teaching.RELIEF_LESSONS) drives on relief
            left unshown that a further drive can still show.
        relief_left: one line per relief lesson left unshown that no further course shows, saying why.
        on_relief: whether the drives were on relief (their frames carry depth).
        ladder: the learned order's feature classes, best first, whose ladder the course shows
            (terrapref.scenario.teaching.ladder): after the first drive of a table whose compact
            course leaves its strips to it (terrapref.scenario.teaching.ladder_follows); empty
            otherwise.
    """

    open: tuple[tuple[str, str], ...] = ()
    neighbours: tuple[tuple[str, str], ...] = ()
    left: tuple[str, ...] = ()
    reopened: tuple[str, ...] = ()
    relief: tuple[str, ...] = ()
    relief_left: tuple[str, ...] = ()
    on_relief: bool = False
    ladder: tuple[str, ...] = ()

    @property
    def anything(self) -> bool:
        """Whether a follow-up course has something to show."""
        return bool(self.open or self.relief or self.ladder)


def plan_follow_up(
    pooled: Identifiability, drives: Sequence[Comparisons], earlier: Identifiability | None = None, last: str = "the last drive"
) -> FollowUp:
    """Which pairs the drives together (``pooled``, as ``train`` sees them) leave open, and which of
    them a follow-up course can still settle.

    The follow-up loop (drive, ``course --after`` every drive so far, drive what it writes) ends:
    a pair open before the last drive and still open after it is left, since driving it again
    gives the same; so is a pair the last drive reopened by choosing against the order the
    drives before it identified (the drives contradict each other), or that two drives have
    compared in ``MIN_FRAMES`` frames or more each. A pair the last drive reopened without
    contradicting it (its frames moved the weights) is shown again, beside its neighbours.

    Args:
        pooled: what all the drives show together.
        drives: each drive's comparisons, in the order driven (:func:`count_comparisons`).
        earlier: what the drives before the last show together (None: a single drive).
        last: the last drive's name, for the lines.
    """
    show, left, reopened = [], [], []
    for p in pooled.unidentified():
        now = f"margin {p.margin:.2f}" + (f", standard error {p.stderr:.2f}" if p.stderr is not None else "")
        before = earlier.pair(p.first, p.second) if earlier is not None else None
        compared = sum(sum(favoured(d, p.first, p.second)) >= MIN_FRAMES for d in drives)
        if before is None:
            show.append((p.first, p.second))
        elif not before.identified:
            never = not sum(favoured(drives[-1], p.first, p.second))  # the last drive was no course that shows them
            left.append(
                f"{p.first} vs {p.second}: open before {last} and after it ({now}, {p.frames} frames): driving it again "
                + (
                    f"would show the same ({last} never compared them: `course --after` of the drives before it shows them)"
                    if never
                    else "would show the same; the planner's choice between them stays a guess"
                )
            )
        else:
            x, y = before.first, before.second  # the order identified before the last drive
            for_x, for_y = favoured(drives[-1], x, y)
            was = f"the drives before {last} identified {x} > {y} (margin {before.margin:.2f})"
            if for_y > for_x:
                left.append(
                    f"{p.first} vs {p.second}: {was}, but in {last} the driver took {y} over {x} in {for_y} of {for_x + for_y} frames: the drives contradict each other"
                )
            elif compared >= 2:
                left.append(
                    f"{p.first} vs {p.second}: {was}; with {last} ({now}) it is open again after {compared} drives compared it: their choices do not settle it"
                )
            else:
                show.append((p.first, p.second))
                reopened.append(
                    f"{p.first} vs {p.second}: {was}; {last} did not choose against it, but its frames moved the weights ({now}): shown again"
                )
    return FollowUp(tuple(show), tuple(bracketed(pooled.order, show)), tuple(left), tuple(reopened))
