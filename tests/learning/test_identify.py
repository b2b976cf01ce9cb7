"""What demonstrations show about a preference (terrapref.learning.identify): which pairs of classes
a drive compared, the order and margins a linear utility learns from it, and the pairs it leaves
a guess. The drives are simulated: a chooser picks trajectories by a known linear utility."""

from __future__ import annotations

import json

import numpy as np
import pytest

from terrapref.learning.identify import (
    GRASS,
    MIN_FRAMES,
    FollowUp,
    Identifiability,
    PairEvidence,
    bracketed,
    count_comparisons,
    fisher_covariance,
    identifiability,
    plan_follow_up,
)
from terrapref.learning.linear import LinearUtility, fit_linear_utility

CLASSES = ("mud", "rock", "water")
M = 7  # trajectories, right (0) to left (6)
DISTANCE = 1.0 - 0.05 * np.abs(np.arange(M) - M // 2)  # all near the path (>= NEAR), the centre best
W_TRUE = np.array([-1.5, -3.0, -4.5, 2.0])  # mud, rock, water, distance: grass > mud > rock > water


def _frame(over: dict[str, list[int]], share: float = 0.8, distance: np.ndarray = DISTANCE) -> np.ndarray:
    """U (m, K + 1) of one frame: ``share`` of each listed trajectory's points on that class."""
    u = np.zeros((M, len(CLASSES) + 1))
    for name, trajectories in over.items():
        u[trajectories, CLASSES.index(name)] = share
    u[:, -1] = distance
    return u


def _drive(counts: dict[tuple[str, ...], int], seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """U (N, m, K + 1) and labels (N,) of a simulated drive.

    ``counts`` maps a frame kind to its number of frames: ``(a, b)`` splits the trajectories
    between two classes at a random point (every option runs over one of them, in a random
    order), ``(a,)`` puts a band of one to three trajectories over ``a`` and leaves the rest clean.
    The chooser takes the argmax of ``U @ W_TRUE`` plus Gumbel noise: a logit model, so the
    maximum-likelihood weights are finite.
    """
    rng = np.random.default_rng(seed)
    frames = []
    for kind, n in counts.items():
        for _ in range(n):
            share = rng.uniform(0.5, 1.0)
            if len(kind) == 2:
                cut = int(rng.integers(1, M))
                right, left = kind if rng.random() < 0.5 else kind[::-1]
                frames.append(_frame({right: list(range(cut)), left: list(range(cut, M))}, share))
            else:
                start, width = int(rng.integers(0, M)), int(rng.integers(1, 4))
                frames.append(_frame({kind[0]: list(range(start, min(M, start + width)))}, share))
    U = np.stack(frames)
    labels = np.argmax(U @ W_TRUE + rng.gumbel(size=U.shape[:2]), axis=1)
    return U, labels


# Mud and water are never offered together.
DRIVE = {("mud", "rock"): 150, ("rock", "water"): 150, ("mud",): 100, ("rock",): 100, ("water",): 100}


@pytest.fixture(scope="module")
def drive() -> tuple[np.ndarray, np.ndarray, LinearUtility]:
    U, labels = _drive(DRIVE)
    return U, labels, fit_linear_utility(U, labels)


@pytest.fixture(scope="module")
def report(drive) -> Identifiability:
    U, labels, utility = drive
    return identifiability(U, labels, CLASSES, utility)


# --- counting comparisons ------------------------------------------------------------------------


def test_a_frame_compares_the_two_classes_and_counts_the_choice_on_its_side():
    """Mud on the right (trajectory 0), water on the left (6), a clean centre; the driver takes water."""
    U = _frame({"mud": [0], "water": [6]})[None]
    counts = count_comparisons(U, np.array([6]), CLASSES)
    # [a chosen on the left, a chosen on the right, b chosen on the left, b chosen on the right]
    np.testing.assert_array_equal(counts[("mud", "water")], [0, 0, 1, 0])
    np.testing.assert_array_equal(counts[("water", GRASS)], [1, 0, 0, 0])  # water taken over the clean centre
    np.testing.assert_array_equal(counts[("mud", GRASS)], [0, 0, 0, 0])  # took neither mud nor a clean one
    np.testing.assert_array_equal(counts[("mud", "rock")], [0, 0, 0, 0])  # no rock: not offered
    assert set(counts) == {("mud", "rock"), ("mud", "water"), ("rock", "water"), ("mud", GRASS), ("rock", GRASS), ("water", GRASS)}


def test_the_mirrored_frame_counts_on_the_other_side():
    U = _frame({"mud": [6], "water": [0]})[None]
    counts = count_comparisons(U, np.array([6]), CLASSES)
    np.testing.assert_array_equal(counts[("mud", "water")], [1, 0, 0, 0])


def test_a_clean_choice_is_evidence_for_grass_and_for_neither_class():
    U = _frame({"mud": [0], "water": [6]})[None]
    counts = count_comparisons(U, np.array([3]), CLASSES)
    np.testing.assert_array_equal(counts[("mud", "water")], [0, 0, 0, 0])
    assert counts[("mud", GRASS)][2:].sum() == 1 and counts[("water", GRASS)][2:].sum() == 1
    assert counts[("mud", GRASS)][:2].sum() == 0 and counts[("water", GRASS)][:2].sum() == 0


def test_a_trajectory_that_leaves_the_path_is_no_option():
    distance = DISTANCE.copy()
    distance[6] = 0.4  # below NEAR: the water trajectory is off the path
    U = _frame({"mud": [0], "water": [6]}, distance=distance)[None]
    counts = count_comparisons(U, np.array([0]), CLASSES)
    np.testing.assert_array_equal(counts[("mud", "water")], [0, 0, 0, 0])
    np.testing.assert_array_equal(counts[("water", GRASS)], [0, 0, 0, 0])
    np.testing.assert_array_equal(counts[("mud", GRASS)], [0, 1, 0, 0])  # mud, on the right, over grass


def test_a_light_touch_is_not_running_over_a_class():
    U = _frame({"mud": [0], "water": [6]}, share=0.1)[None]  # below SHARE
    counts = count_comparisons(U, np.array([6]), CLASSES)
    assert all(c.sum() == 0 for c in counts.values())


def test_the_simulated_drive_compares_exactly_the_pairs_it_offered(drive):
    U, labels, _ = drive
    counts = count_comparisons(U, labels, CLASSES)
    assert counts[("mud", "water")].sum() == 0
    for pair in [("mud", "rock"), ("rock", "water"), ("mud", GRASS), ("rock", GRASS), ("water", GRASS)]:
        assert counts[pair].sum() >= MIN_FRAMES, pair
    # The chooser prefers the first of each pair (a lower cost), so most frames favour it.
    for pair in [("mud", "rock"), ("rock", "water")]:
        c = counts[pair]
        assert c[0] + c[1] > c[2] + c[3], (pair, c)
    # Against grass the clean trajectory wins.
    for name in CLASSES:
        c = counts[(name, GRASS)]
        assert c[2] + c[3] > 2 * (c[0] + c[1]), (name, c)


# --- the Fisher information of the fit ------------------------------------------------------------


def test_fisher_covariance_is_the_pseudo_inverse_of_the_softmax_information():
    """Two trajectories, one utility column, w = b = 0 (p = 1/2): each frame adds
    p (1 - p) d d^T with d = (u_0 - u_1, 1, -1), the difference of the two rows of the design."""
    U = np.array([[[0.2], [0.9]], [[0.5], [0.1]], [[1.0], [0.0]]])
    utility = LinearUtility(np.zeros(1), np.zeros(2))
    d = np.stack([U[:, 0, 0] - U[:, 1, 0], np.ones(3), -np.ones(3)], axis=1)
    info = 0.25 * d.T @ d
    cov = fisher_covariance(U, np.zeros(3, int), utility)
    assert cov.shape == (3, 3)
    np.testing.assert_allclose(cov, np.linalg.pinv(info), atol=1e-12)


def test_twice_the_frames_halve_the_covariance(drive):
    U, labels, utility = drive
    once = fisher_covariance(U, labels, utility)
    twice = fisher_covariance(np.concatenate([U, U]), np.concatenate([labels, labels]), utility)
    assert once.shape == (len(CLASSES) + 1 + M,) * 2
    np.testing.assert_allclose(twice, once / 2, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(once, once.T, atol=1e-12)
    assert np.all(np.diag(once)[: len(CLASSES)] > 0)


def test_a_lookahead_that_changes_nothing_adds_nothing_but_gamma(drive):
    """Continuations all worth 0: every trajectory's best one is the first, so the look-ahead adds
    the same bias to every option (centred away) and a value column that is always 0."""
    U, labels, utility = drive
    U2 = np.zeros((*U.shape[:2], M, U.shape[2]))
    cov = fisher_covariance(U, labels, LinearUtility(utility.w, np.zeros(M)), U2, gamma=0.7)
    plain = fisher_covariance(U, labels, LinearUtility(utility.w, np.zeros(M)))
    n = len(plain)
    assert cov.shape == (n + 1, n + 1)
    np.testing.assert_allclose(cov[:n, :n], plain, rtol=1e-6, atol=1e-10)
    np.testing.assert_array_equal(cov[n], 0.0)


def test_fisher_covariance_through_the_lookahead_adds_gamma():
    rng = np.random.default_rng(0)
    U, U2 = rng.uniform(0, 1, (40, M, 4)), rng.uniform(0, 1, (40, M, M, 4))
    utility = LinearUtility(np.array([-1.0, -2.0, -3.0, 1.0]), np.zeros(M))
    cov = fisher_covariance(U, rng.integers(0, M, 40), utility, U2, gamma=0.5)
    assert cov.shape == (4 + M + 1,) * 2  # w, b and gamma
    np.testing.assert_allclose(cov, cov.T, atol=1e-9)
    assert np.all(np.linalg.eigvalsh(cov) > -1e-9)


# --- the report -------------------------------------------------------------------------------------


def test_the_learned_order_is_the_choosers(report: Identifiability):
    assert report.order == (GRASS, "mud", "rock", "water")
    assert len(report.pairs) == 6  # every pair of four


@pytest.mark.parametrize("first, second", [("mud", "rock"), ("rock", "water"), (GRASS, "mud"), (GRASS, "rock"), (GRASS, "water")])
def test_compared_pairs_are_identified_in_the_right_order(report: Identifiability, first: str, second: str):
    p = report.pair(second, first)  # either way round
    assert (p.first, p.second) == (first, second)
    assert p.identified
    assert p.frames >= MIN_FRAMES and p.frames == p.for_first + p.for_second
    assert p.for_first > p.for_second
    assert p.stderr is not None and p.margin > 2 * p.stderr > 0
    assert sum(p.sides) == p.frames


def test_margins_are_differences_of_the_learned_weights(drive, report: Identifiability):
    w = dict(zip(CLASSES, drive[2].w)) | {GRASS: 0.0}
    for p in report.pairs:
        assert p.margin == pytest.approx(w[p.first] - w[p.second], abs=1e-12)
        assert p.margin >= 0
    # The fit recovers the chooser's gaps (1.5 per unit share) roughly.
    assert report.pair("mud", "rock").margin == pytest.approx(1.5, abs=0.75)
    assert report.pair("rock", "water").margin == pytest.approx(1.5, abs=0.75)


def test_a_pair_never_offered_together_is_a_guess(report: Identifiability):
    p = report.pair("water", "mud")
    assert (p.first, p.second) == ("mud", "water")  # ordered through rock, but never compared
    assert p.frames == p.for_first == p.for_second == 0 and p.sides == (0, 0)
    assert not p.identified
    assert report.unidentified() == [p]
    assert report.warnings() == ["mud vs water: never compared; the planner's choice between them is a guess"]


def test_lines_give_the_order_every_pair_and_the_warnings(report: Identifiability):
    lines = report.lines()
    assert lines[0] == "learned order: grass > mud > rock > water"
    assert len(lines) == 1 + 6 + 1
    flagged = [line for line in lines[1:7] if line.endswith("<- not identified")]
    assert len(flagged) == 1 and flagged[0].startswith("  mud > water: margin ") and "never compared" in flagged[0]
    mud_rock = next(line for line in lines if line.startswith("  mud > rock:"))
    p = report.pair("mud", "rock")
    assert f"margin {p.margin:.2f}, standard error {p.stderr:.2f}, compared in {p.frames} frames" in mud_rock
    assert f"({p.for_first} for mud, {p.for_second} for rock;" in mud_rock
    assert lines[-1] == "warning: mud vs water: never compared; the planner's choice between them is a guess"


def test_a_profile_the_drive_agrees_with_is_said_to_agree(report: Identifiability):
    line = "the profile stored with the drive: mud > rock > water: the drive agrees on all 3 pairs it orders (2 identified)"
    assert report.against(["mud", "rock", "water"]) == [line]
    assert report.lines(["mud", "rock", "water"]) == [*report.lines(), line]
    assert report.lines(None) == report.lines()


def test_a_profile_the_drive_contradicts_names_each_reversed_pair(report: Identifiability):
    # Declared water first: the drive put water last, identified against rock and a guess against mud.
    lines = report.against(["water", "mud", "rock", "non_traversable"])  # a class the report lacks is left out
    mw, rw = report.pair("mud", "water"), report.pair("rock", "water")
    assert lines == [
        "the profile stored with the drive: water > mud > rock: the drive orders 2 of 3 pairs the other way round",
        f"  water > mud in the profile, mud > water in the drive (margin {mw.margin:.2f}, not identified)",
        f"  water > rock in the profile, rock > water in the drive (margin {rw.margin:.2f}, identified)",
    ]


def test_a_drive_that_orders_nothing_states_no_order():
    # One frame, no choice between two classes: every weight 0, no learned order, no pair "the other way round".
    order = ("non_traversable", "water", "rock", "mud", "grass")
    empty = Identifiability(
        order, tuple(PairEvidence(a, b, 0, 0, 0, (0, 0), 0.0, None) for i, a in enumerate(order) for b in order[i + 1 :])
    )
    assert empty.lines()[0] == "learned order: none (the drive sets no class above another)"
    assert empty.against(["rock", "mud", "water"]) == [
        "the profile stored with the drive: rock > mud > water: the drive orders none of its 3 pairs"
    ]


def test_the_report_counts_each_choice_for_its_class_and_each_frame_on_its_side():
    """Hand-counted frames; grass comes first in the learned order, so its pair with mud is
    read the other way round from the counts (mud, grass)."""
    mud_right, mud_left = _frame({"mud": [0]}), _frame({"mud": [6]})
    mud_left_rock_right = _frame({"mud": [5, 6], "rock": [0, 1]})
    frames = (
        [(mud_right, 3)] * 12 + [(mud_right, 0)] * 3 + [(mud_left, 3)] * 5 + [(mud_left_rock_right, 6)] * 4 + [(mud_left_rock_right, 1)] * 2
    )
    U, labels = np.stack([f for f, _ in frames]), np.array([label for _, label in frames])
    report = identifiability(U, labels, CLASSES, LinearUtility(W_TRUE, np.zeros(M)))
    grass_mud = report.pair("mud", GRASS)
    assert (grass_mud.first, grass_mud.second) == (GRASS, "mud")
    # The mud-rock frames offer a clean middle too: the four that took mud count against grass.
    assert (grass_mud.frames, grass_mud.for_first, grass_mud.for_second) == (20 + 4, 17, 3 + 4)
    assert grass_mud.sides == (12 + 3, 5 + 4)  # grass lay left of mud on the right, right of mud on the left
    mud_rock = report.pair("rock", "mud")
    assert (mud_rock.first, mud_rock.second, mud_rock.frames, mud_rock.for_first, mud_rock.for_second) == ("mud", "rock", 6, 4, 2)
    assert mud_rock.sides == (6, 0)
    assert report.pair("mud", "water").frames == report.pair("rock", "water").frames == 0


def test_few_comparisons_leave_a_pair_unidentified():
    U, labels = _drive({**DRIVE, ("rock", "water"): 4}, seed=1)
    report = identifiability(U, labels, CLASSES, LinearUtility(W_TRUE, np.zeros(M)))
    p = report.pair("rock", "water")
    assert 0 < p.frames < MIN_FRAMES and not p.identified
    assert f"rock vs water: compared in only {p.frames} frames; the planner's choice between them is a guess" in report.warnings()


def test_a_margin_within_its_uncertainty_leaves_a_pair_unidentified(drive):
    """Plenty of mud-rock frames, but a utility that weighs the two the same: no margin."""
    U, labels, _ = drive
    even = LinearUtility(np.array([-2.0, -2.0, -4.5, 2.0]), np.zeros(M))
    report = identifiability(U, labels, CLASSES, even)
    p = report.pair("mud", "rock")
    assert p.frames >= MIN_FRAMES and p.margin == 0.0 and p.stderr > 0
    assert not p.identified
    assert (
        "mud vs rock: compared, but the margin is within its uncertainty; the planner's choice between them is a guess" in report.warnings()
    )


def test_an_unknown_stderr_is_never_identified():
    p = PairEvidence("mud", "rock", 50, 40, 10, (25, 25), 3.0, None)
    assert not p.identified
    assert p.describe() == "mud > rock: margin 3.00, compared in 50 frames (40 for mud, 10 for rock; mud on the left 25, on the right 25)"


# --- storing the report with a model ---------------------------------------------------------------


def test_to_dict_and_back_is_the_same_report():
    report = Identifiability(
        (GRASS, "mud", "water"),
        (
            PairEvidence(GRASS, "mud", 40, 35, 5, (22, 18), 1.25, 0.3125),
            PairEvidence(GRASS, "water", 12, 12, 0, (6, 6), 4.5, None),
            PairEvidence("mud", "water", 0, 0, 0, (0, 0), 3.25, 0.5),
        ),
    )
    data = json.loads(json.dumps(report.to_dict()))  # as stored in a model file's JSON
    assert data["min_frames"] == MIN_FRAMES
    assert [p["identified"] for p in data["pairs"]] == [True, False, False]
    assert Identifiability.from_dict(data) == report


def test_a_fitted_report_survives_a_model_files_json_exactly(report: Identifiability):
    back = Identifiability.from_dict(json.loads(json.dumps(report.to_dict())))
    assert back == report  # margins and standard errors stored unrounded: no pair changes status on loading
    assert back.unidentified() == [back.pair("mud", "water")]


def test_an_unordered_pair_with_a_lethal_class_is_left_to_the_class_table():
    pairs = (PairEvidence("water", "non_traversable", 7, 2, 5, (7, 0), 3.4, 2.4), PairEvidence("mud", "water", 0, 0, 0, (0, 0), 0.1, None))
    report = Identifiability(("mud", "water", "non_traversable"), pairs, ("non_traversable",))
    lethal, plain = report.warnings()
    assert "non_traversable is lethal" in lethal and "offset rule never drives onto it" in lethal
    assert plain == "mud vs water: never compared; the planner's choice between them is a guess"
    assert Identifiability.from_dict(report.to_dict()) == report


# --- the follow-up loop: what a further course shows, and what it leaves -------------------------

ORDER = ("grass", "mud", "water", "dirt", "bush", "puddle", "lethal")


def _report(margins: dict[tuple[str, str], tuple[float, int]], order: tuple[str, ...] = ORDER) -> Identifiability:
    """A report of ``order`` in which each pair has margin 1.0 over 20 frames (identified), but
    those ``margins`` names: (margin, frames), with standard error 0.1."""
    pairs = []
    for i, a in enumerate(order):
        for b in order[i + 1 :]:
            margin, frames = margins.get((a, b), (1.0, 20))
            pairs.append(PairEvidence(a, b, frames, frames, 0, (frames, 0), margin, 0.1))
    return Identifiability(order, tuple(pairs))


def _took(counts: dict[tuple[str, str], tuple[int, int]]) -> dict[tuple[str, str], np.ndarray]:
    """One drive's comparisons: (frames for a, frames for b) of each pair (a, b), all on the left."""
    return {pair: np.array([for_a, 0, for_b, 0]) for pair, (for_a, for_b) in counts.items()}


def test_a_follow_up_shows_each_open_pair_beside_its_neighbours_in_the_learned_order():
    assert bracketed(ORDER, [("dirt", "bush")]) == [("water", "dirt"), ("bush", "puddle")]
    assert bracketed(ORDER, [("grass", "mud")]) == [("mud", "water")]  # nothing above the best
    # Neighbours shared or open themselves are shown once, as the open pair they are.
    assert bracketed(ORDER, [("dirt", "bush"), ("puddle", "lethal"), ("water", "dirt")]) == [("bush", "puddle"), ("mud", "water")]


def test_one_drive_leaves_every_open_pair_to_a_follow_up():
    plan = plan_follow_up(_report({("dirt", "bush"): (0.02, 79)}), [_took({("dirt", "bush"): (67, 12)})])
    assert plan == FollowUp(open=(("dirt", "bush"),), neighbours=(("water", "dirt"), ("bush", "puddle")))


def test_a_pair_open_before_the_last_drive_and_after_it_is_left_saying_why():
    earlier = _report({("dirt", "bush"): (0.02, 79)})
    plan = plan_follow_up(_report({("dirt", "bush"): (0.05, 184)}), [_took({}), _took({("dirt", "bush"): (92, 13)})], earlier, "me_more")
    assert plan.open == () and plan.neighbours == () and plan.reopened == ()
    assert plan.left == (
        "dirt vs bush: open before me_more and after it (margin 0.05, standard error 0.10, 184 frames): driving it again "
        "would show the same; the planner's choice between them stays a guess",
    )


def test_a_pair_the_last_drive_never_compared_is_left_saying_which_course_shows_it():
    """The last drive was no course of the pair (another drive, not a follow-up): "driving it again
    would show the same" was said of it as of a follow-up that showed the pair in vain."""
    earlier = _report({("dirt", "bush"): (0.02, 79)})
    plan = plan_follow_up(_report({("dirt", "bush"): (0.02, 79)}), [_took({("dirt", "bush"): (67, 12)}), _took({})], earlier, "other")
    assert plan.left == (
        "dirt vs bush: open before other and after it (margin 0.02, standard error 0.10, 79 frames): driving it again "
        "would show the same (other never compared them: `course --after` of the drives before it shows them)",
    )


def test_a_pair_the_last_drive_reopened_without_choosing_against_it_is_shown_again():
    """The last drive never compared water with dirt, but its frames moved dirt's weight."""
    earlier = _report({("water", "dirt"): (0.28, 29)})
    pooled = _report({("water", "dirt"): (0.03, 29)})
    plan = plan_follow_up(pooled, [_took({("water", "dirt"): (29, 0)}), _took({("dirt", "bush"): (92, 13)})], earlier, "me_more")
    assert plan.open == (("water", "dirt"),) and plan.neighbours == (("mud", "water"), ("dirt", "bush")) and plan.left == ()
    assert plan.reopened == (
        "water vs dirt: the drives before me_more identified water > dirt (margin 0.28); me_more did not choose against it, "
        "but its frames moved the weights (margin 0.03, standard error 0.10): shown again",
    )


def test_a_pair_the_last_drive_contradicts_is_left_naming_the_choices():
    earlier = _report({("water", "dirt"): (0.28, 29)})
    pooled = _report({("water", "dirt"): (0.05, 45)})
    plan = plan_follow_up(pooled, [_took({("water", "dirt"): (29, 0)}), _took({("water", "dirt"): (2, 14)})], earlier, "me_more")
    assert plan.open == () and plan.left == (
        "water vs dirt: the drives before me_more identified water > dirt (margin 0.28), but in me_more the driver took "
        "dirt over water in 14 of 16 frames: the drives contradict each other",
    )


def test_a_pair_two_drives_compared_and_the_last_reopened_is_left():
    """Shown by the teaching drive and a follow-up already: a third showing would not settle it."""
    earlier = _report({("water", "dirt"): (0.28, 60)})
    pooled = _report({("water", "dirt"): (0.03, 75)})
    drives = [_took({("water", "dirt"): (29, 0)}), _took({("water", "dirt"): (31, 0)}), _took({("water", "dirt"): (15, 0)})]
    plan = plan_follow_up(pooled, drives, earlier, "me_more2")
    assert plan.open == () and plan.left[0].startswith("water vs dirt: the drives before me_more2 identified water > dirt")
    assert plan.left[0].endswith("it is open again after 3 drives compared it: their choices do not settle it")
