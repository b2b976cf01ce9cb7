"""Fitting the offset utility (terrapref.rules.offset.rule) to the offsets a demonstrator steered for.

Each frame's label is the offset the driver was steering for, read when the recording is
featurised (:func:`terrapref.rules.offset.steering.intent_offsets`). A softmax over the candidate
offsets, ``p(d) ~ exp(weights . gated(features)(d))``, is fitted to Gaussian soft labels
(``sigma_m``) around that offset by Newton's method with a small ridge, once for each candidate
near distance; the near distance of the lowest loss is kept. On relief the losses compared are
those of the frames with nothing steep on the path ahead (:func:`level_frames`): in the frames a
fit reads, ground past the first relief band is a patch on the path as terrain is, but driving,
only ground past the first band the fit prices is (``OffsetSteering.steep_deg``), and a driver
who keeps to the path over slopes it takes would read as one who leaves the path only once a
patch is near.

On relief the weights are then fitted in two stages, where enough frames have no relief in view
(:func:`flat_frames`): the terrain's (each class, the detour, the gate) on those frames alone,
then the relief bands' and the never-seen ground's, with the terrain's held, on the frames with
no class in view (:func:`terrain_free_frames`; every frame where too few have none). A driver's
terrain order and its prices are what they are without relief (SPEC 19); fitted on every frame
at once, the frames where a drive holds a line along a slope with a patch's edge beside it (the
vehicle wandering a few tenths of a metre onto it) read as a driver for whom the classes are
cheap, and priced them at a third to a half of its own. The same frames, read for relief, price
slopes a driver takes without a second look: a line held a few tenths of a metre off a patch's
edge reads as one held off the slope beyond it, and a bold driver's grades came out priced as
dearly as a careful one's.

The relief prices come with 95% intervals: the fitted weights' covariance by the sandwich of
an M-estimator, its meat summed over blocks of :data:`INTERVAL_BLOCK_FRAMES` consecutive frames
(a drive's frames follow one another, so neighbours are not independent evidence), carried to
each printed price (a band's weight and those below it, over the detour's) by the delta method;
for a staged fit, the sandwich of the two stages' estimating equations stacked
(:func:`staged_covariance`), so that the detour's own spread, from the first stage, is carried.

Float64 NumPy throughout, and the problem is convex: NumPy's exp, its sums and BLAS's matrix
products may differ in their last bits between CPUs and thread counts, the Newton steps do not
amplify that, and the weights are kept to 12 decimals, so the same data give the same weights
on any machine (tests/rules/test_offset_rule.py runs the fit under NumPy's and OpenBLAS's CPU settings).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from terrapref.rules.offset.geometry import OffsetGeometry

WEIGHT_DECIMALS = 12  # fitted weights are kept to this many decimals
INTERVAL_BLOCK_FRAMES = 50  # the frames a relief price's interval takes as one piece of evidence (5 s at 10 Hz)
INTERVAL_DECIMALS = 6  # its ends are kept to this many decimals
NEAR_CANDIDATES_M = (2.0, 2.5, 3.0, 3.5, 4.0, 4.5, 5.0, 6.0, 7.0, 8.0)
HIDDEN_ON_PATH_M = 0.6  # offsets within this of the path (the body's half width) price ground never seen apart, on relief


@dataclass(frozen=True)
class OffsetUtility:
    """A fitted offset utility: ``weights . gated(features)`` per offset.

    Attributes:
        weights: one per column of :func:`terrapref.rules.offset.features.gated`, shape (K + 3,):
            K terrain classes, never seen, the detour's price, the gate.
        near_m: the gate's near distance [m].
        config: the offset rule's geometry.
        relief: one weight per relief column (terrapref.rules.offset.features.OffsetView.relief):
            side slope past each band, then grade past each; None: a utility that prices no
            relief (fitted on flat ground).
        relief_shown: the steepest band the drive showed ground past, of side slope and of
            grade [deg] (NaN: none): past it, its fit could not tell the price; None without relief.
        relief_interval: the 95% interval (R, 2) of each band's price as it is printed (its
            weight and those of the bands below it, over the detour's price: :func:`relief_prices`);
            None: not known (a utility without relief, or a file written before intervals).
        hidden_on_path: what a metre never seen weighs on the offsets within
            :data:`HIDDEN_ON_PATH_M` of the path beyond its weight elsewhere (``weights``'
            never-seen column): a mound hides ground on the path that a driver drives into, a
            bank's crest ground beside it that the same driver keeps off; 0 without relief.
    """

    weights: np.ndarray
    near_m: float
    config: OffsetGeometry = field(default_factory=OffsetGeometry)
    relief: np.ndarray | None = None
    relief_shown: tuple[float, float] | None = None
    relief_interval: np.ndarray | None = None
    hidden_on_path: float = 0.0


@dataclass(frozen=True)
class OffsetFit:
    """A fitted offset utility and how well it fitted.

    Attributes:
        weights: (K + 3,), the columns of :func:`terrapref.rules.offset.features.gated`.
        near_m: the chosen near distance [m].
        loss: mean cross-entropy of the soft labels at that near distance (to 12 decimals, as
            the weights).
        losses: the loss at every candidate near distance, the one compared: on relief, that
            of the frames with nothing steep on the path ahead (:func:`level_frames`), without the ridge.
        samples: frames fitted.
        relief: the relief columns' weights, for frames read with them; else None.
        relief_shown: the steepest bands the frames showed (OffsetUtility.relief_shown).
        relief_interval: the 95% intervals of the relief prices (OffsetUtility.relief_interval).
        hidden_on_path: ground never seen on the path's lanes (OffsetUtility.hidden_on_path).
    """

    weights: np.ndarray
    near_m: float
    loss: float
    losses: dict[float, float]
    samples: int
    relief: np.ndarray | None = None
    relief_shown: tuple[float, float] | None = None
    relief_interval: np.ndarray | None = None
    hidden_on_path: float = 0.0


def soft_labels(intent: np.ndarray, offsets: np.ndarray, sigma_m: float) -> np.ndarray:
    """Gaussian weights (F, O) over the offsets around each frame's intended offset, rows summing to 1."""
    y = np.exp(-0.5 * ((offsets[None, :] - intent[:, None]) / sigma_m) ** 2)
    return y / y.sum(axis=1, keepdims=True)


def fit_softmax(
    X: np.ndarray, Y: np.ndarray, l2: float = 1e-3, iterations: int = 50, base: np.ndarray | None = None
) -> tuple[np.ndarray, float]:
    """Weights (P,) maximising the soft-label log-likelihood of ``softmax(base + X @ weights)`` less ``l2 |weights|^2``.

    ``X`` (N, O, P) features, ``Y`` (N, O) soft labels, ``base`` (N, O) the utility of weights
    held (None: none). Newton steps with a backtracking line search; the problem is convex, so
    the result does not depend on where it starts.
    """
    n, o, p = X.shape
    rows = X.reshape(n * o, p)  # every (frame, offset) row: the sums over both as matrix products

    def evaluate(theta: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        logp, prob = _log_softmax(X, theta, base)
        loss = -(Y * logp).sum() / n + l2 * theta @ theta
        grad = (prob - Y).reshape(-1) @ rows / n + 2 * l2 * theta
        return loss, grad, _hessian(X, prob, l2)

    theta = np.zeros(p)
    loss = math.inf
    for _ in range(iterations):
        loss, grad, hess = evaluate(theta)
        if np.abs(grad).max() < 1e-7:
            break
        step = np.linalg.solve(hess, grad)
        t = 1.0
        while t > 1e-4:
            trial = evaluate(theta - t * step)[0]
            if trial <= loss - 1e-4 * t * grad @ step:
                break
            t /= 2
        theta = theta - t * step
    return theta, float(evaluate(theta)[0])


def _log_softmax(X: np.ndarray, theta: np.ndarray, base: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The log-probabilities and probabilities (N, O) of ``softmax(base + X @ theta)`` over the offsets (``base`` None: 0)."""
    z = X @ theta if base is None else base + X @ theta
    z = z - z.max(axis=1, keepdims=True)
    logp = z - np.log(np.exp(z).sum(axis=1, keepdims=True))
    return logp, np.exp(logp)


def _hessian(X: np.ndarray, prob: np.ndarray, l2: float) -> np.ndarray:
    """The Hessian (P, P) of :func:`fit_softmax`'s objective at the probabilities ``prob`` (N, O)."""
    n, o, p = X.shape
    rows = X.reshape(n * o, p)
    mean = np.matmul(prob[:, None, :], X)[:, 0, :]  # (N, P): each frame's expected features
    return ((rows * prob.reshape(-1, 1)).T @ rows - mean.T @ mean) / n + 2 * l2 * np.eye(p)


def _fit_steeper_costs_more(
    X: np.ndarray, Y: np.ndarray, l2: float, relief: range, base: np.ndarray | None = None
) -> tuple[np.ndarray, float, np.ndarray]:
    """:func:`fit_softmax` (over ``base``) with the relief columns' weights (``relief``) at most 0: each band past
    the one below it adds a price, never takes one off, so steeper ground never costs less than
    gentler (a drive that shows no reason to go round some relief says nothing for driving onto it).
    The columns whose weight comes out positive are held at 0 and the rest fitted again, until
    none does. The weights, the loss, and which columns were fitted (not held)."""
    free = np.ones(X.shape[2], dtype=bool)
    while True:
        fitted, loss = fit_softmax(X[:, :, free], Y, l2, base=base)
        theta = np.zeros(X.shape[2])
        theta[free] = fitted
        positive = [j for j in relief if free[j] and theta[j] > 0.0]
        if not positive:
            return theta, loss, free
        free[positive] = False


@dataclass(frozen=True)
class OffsetFitConfig:
    """How the offset utility is fitted.

    Attributes:
        sigma_m: the width of the Gaussian soft labels around each intended offset [m].
        l2: the ridge on the weights.
        near_candidates: the near distances tried [m]; the one of the lowest loss is kept.
    """

    sigma_m: float = 0.3
    l2: float = 1e-3
    near_candidates: tuple[float, ...] = NEAR_CANDIDATES_M


def fit_offset_utility(
    features: np.ndarray,
    near_m: np.ndarray,
    intent: np.ndarray,
    offsets: np.ndarray,
    config: OffsetFitConfig | None = None,
    relief: tuple[np.ndarray, tuple[float, ...]] | None = None,
) -> OffsetFit:
    """Fit the offset utility to frames' offset features (N, O, K + 2), near distances (N,)
    and intended offsets (N,) over the candidate ``offsets`` (O,) [m], with their relief columns
    when given (``relief``: the columns (N, O, R) and the bands [deg] they count past, side slope
    then grade; with them, the metres never seen on the offsets within :data:`HIDDEN_ON_PATH_M`
    get a column of their own, after the relief columns); frames without an intended offset (NaN) are left out; ``config`` None: the
    default fit."""
    config = config or OffsetFitConfig()
    keep = np.isfinite(intent)
    if not keep.any():
        raise ValueError("no frame has an intended offset to fit")
    X, near, Y = features[keep].astype(np.float64), near_m[keep], soft_labels(intent[keep], offsets, config.sigma_m)
    columns = X.shape[2]
    kept = None if relief is None else relief[0][keep]  # the fitted frames' relief columns
    R = 0 if kept is None else kept.shape[2]
    if kept is not None:
        on_path = (np.abs(offsets) <= HIDDEN_ON_PATH_M + 1e-9)[None, :, None]
        X = np.concatenate([X, kept.astype(np.float64), X[:, :, columns - 2 : columns - 1] * on_path], axis=2)
    judged = None if kept is None else level_frames(kept, offsets, len(relief[1]))
    best: tuple[np.ndarray, float, float, np.ndarray, np.ndarray] | None = None
    losses = {}
    for candidate in config.near_candidates:
        gated_x = np.concatenate([X, (offsets**2)[None, :, None] * (near > candidate)[:, None, None]], axis=2)
        if relief is None:
            theta, loss = fit_softmax(gated_x, Y, config.l2)
            free = np.ones(len(theta), dtype=bool)
        else:
            theta, loss, free = _fit_steeper_costs_more(gated_x, Y, config.l2, range(columns, columns + R))
        losses[candidate] = loss if judged is None else _data_loss(gated_x[judged], Y[judged], theta)
        if best is None or losses[candidate] < losses[best[2]] - 1e-9:
            best = (theta, loss, candidate, free, gated_x)
    theta, loss, chosen, free, gated_x = best
    flat = None if kept is None else flat_frames(kept)
    first = plain = None
    if flat is not None:
        plain = terrain_free_frames(X, columns - 2)
        theta, loss, free, first = fit_staged(gated_x, Y, (flat, plain), columns, config.l2)
    interval = None if relief is None else _relief_interval(gated_x, Y, (theta, free), ((flat, plain), first), (columns, R), config.l2)
    # NumPy's exp, sums and matrix products may differ in the last bits between CPUs; the convex
    # fit does not amplify them, and rounding leaves the same weights (and losses) everywhere but
    # at a rounding boundary.
    losses = {near: round(value, WEIGHT_DECIMALS) for near, value in losses.items()}
    theta = np.round(theta, WEIGHT_DECIMALS)
    weights = np.concatenate([theta[:columns], theta[-1:]])  # the relief columns' weights stand between those and the gate
    priced = theta[columns : columns + R] if relief is not None else None
    shown = relief_shown(kept, relief[1]) if kept is not None else None
    hidden_on_path = float(theta[-2]) if relief is not None else 0.0  # the lanes' own never-seen column stands just before the gate
    return OffsetFit(weights, chosen, round(loss, WEIGHT_DECIMALS), losses, int(keep.sum()), priced, shown, interval, hidden_on_path)


LEVEL_FRAMES_LEAST = 200  # the fewest frames with nothing steep ahead that the near distance is chosen on; fewer: on all
FLAT_FRAMES_LEAST = 200  # the fewest frames with no relief in view that the terrain's prices are fitted on; fewer: on all
TERRAIN_FREE_FRAMES_LEAST = 200  # the fewest frames with no class in view that relief's prices are fitted on; fewer: on all


def flat_frames(columns: np.ndarray) -> np.ndarray | None:
    """The frames (N,) bool whose relief ``columns`` (N, O, R) count nothing at any offset: no
    ground past the first band anywhere in the way ahead; None where fewer than
    :data:`FLAT_FRAMES_LEAST` are."""
    flat = ~columns.any(axis=(1, 2))
    return flat if flat.sum() >= FLAT_FRAMES_LEAST else None


def terrain_free_frames(X: np.ndarray, classes: int) -> np.ndarray | None:
    """The frames (N,) bool whose columns ``X`` (N, O, P), the first ``classes`` of them the
    terrain classes', count no class at any offset: nothing but relief and ground never seen to
    choose a way by; None where fewer than :data:`TERRAIN_FREE_FRAMES_LEAST` are."""
    free = ~X[:, :, :classes].any(axis=(1, 2))
    return free if free.sum() >= TERRAIN_FREE_FRAMES_LEAST else None


def _staged_columns(width: int, columns: int) -> np.ndarray:
    """The columns of a gated relief fit's ``width`` that its second stage fits (:func:`fit_staged`):
    the ground never seen (the ``columns``' last but one), then the relief columns and the ground
    never seen on the path's lanes (all between the ``columns`` and the gate)."""
    return np.r_[columns - 2, columns : width - 1]


def fit_staged(
    X: np.ndarray, Y: np.ndarray, frames: tuple[np.ndarray, np.ndarray | None], columns: int, l2: float
) -> tuple[np.ndarray, float, np.ndarray, np.ndarray]:
    """The weights of a fit on relief in two stages (module docstring): those of the terrain (the
    classes, the detour, the gate) fitted to the ``frames``' first (N,) bool, those with no relief
    in view, alone, with the ground never seen there, then those of the ground never seen and of
    relief (:func:`_staged_columns`) with the terrain's held, to the ``frames``' second (those
    with no class in view; None: every frame). ``X`` (N, O, P): the gated columns, ``columns`` of
    them the terrain's and never seen's. The weights (P,), the loss over every frame, which
    weights were fitted (not held at 0 by the second stage), and the first stage's weights (P; 0
    for relief)."""
    flat, plain = frames
    second = _staged_columns(X.shape[2], columns)
    first_columns = np.setdiff1d(np.arange(X.shape[2]), second[1:])
    first = np.zeros(X.shape[2])
    first[first_columns], _ = fit_softmax(X[flat][:, :, first_columns], Y[flat], l2)
    theta = first.copy()
    theta[second[0]] = 0.0
    Xp, Yp = (X, Y) if plain is None else (X[plain], Y[plain])
    theta[second], _, fitted = _fit_steeper_costs_more(Xp[:, :, second], Yp, l2, range(1, len(second) - 1), Xp @ theta)
    free = np.ones(X.shape[2], dtype=bool)
    free[second] = fitted
    return theta, _data_loss(X, Y, theta) + l2 * float(theta @ theta), free, first


def _relief_interval(
    X: np.ndarray,
    Y: np.ndarray,
    fitted: tuple[np.ndarray, np.ndarray],
    staged: tuple[tuple[np.ndarray | None, np.ndarray | None], np.ndarray | None],
    widths: tuple[int, int],
    l2: float,
) -> np.ndarray | None:
    """The 95% intervals (R, 2) of the relief prices of the weights and which were ``fitted``
    (:func:`fit_offset_utility`) to the gated ``X`` and ``Y`` (``widths``: its terrain's columns,
    the detour's last, and how many relief columns follow them): by :func:`staged_covariance` where
    the fit was ``staged`` (its flat frames and first stage's weights; None: not staged), else
    by :func:`weight_covariance`; None where the detour is priced at 0 (prices on its scale are
    not told)."""
    theta, free = fitted
    (flat, plain), first = staged
    columns, count = widths
    if flat is None or first is None:
        covariance = weight_covariance(X, Y, theta, free, l2, INTERVAL_BLOCK_FRAMES)
    else:
        stages = ((flat, plain), _staged_columns(X.shape[2], columns), first)
        covariance = staged_covariance(X, Y, fitted, stages, l2, INTERVAL_BLOCK_FRAMES)
    interval = np.round(relief_price_intervals(theta, covariance, columns, count), INTERVAL_DECIMALS)
    return interval if np.isfinite(interval).all() else None


def level_frames(columns: np.ndarray, offsets: np.ndarray, bands: int) -> np.ndarray | None:
    """The frames (N,) bool whose relief ``columns`` (N, O, 2 * ``bands``: side slope past each
    band, then grade) count no ground past the first band on the path itself (the offset nearest
    0 of ``offsets``); None where fewer than :data:`LEVEL_FRAMES_LEAST` do."""
    centre = int(np.argmin(np.abs(offsets)))
    level = (columns[:, centre, 0] == 0) & (columns[:, centre, bands] == 0)
    return level if level.sum() >= LEVEL_FRAMES_LEAST else None


def _data_loss(X: np.ndarray, Y: np.ndarray, theta: np.ndarray) -> float:
    """The mean cross-entropy of the soft labels ``Y`` (N, O) under ``softmax(X @ theta)``, without the ridge."""
    return float(-(Y * _log_softmax(X, theta)[0]).sum() / len(Y))


def weight_covariance(X: np.ndarray, Y: np.ndarray, theta: np.ndarray, free: np.ndarray, l2: float, block_frames: int) -> np.ndarray:
    """The covariance (P, P) of the weights ``theta`` (P,) :func:`fit_softmax` fitted to ``X`` (N, O,
    P) and ``Y`` (N, O) with ridge ``l2``, those of ``free`` (P,) bool fitted and the others held (no
    variance): the sandwich H^-1 M H^-1 / N^2 of the objective's Hessian H (as the fit's) and the
    frames' scores (each frame's gradient of its loss) summed over blocks of ``block_frames``
    consecutive frames, M the sum of those sums' outer products."""
    n = X.shape[0]
    Xf = X[:, :, free]
    _, prob = _log_softmax(Xf, theta[free])
    inverse = np.linalg.inv(_hessian(Xf, prob, l2))
    out = np.zeros((len(theta), len(theta)))
    out[np.ix_(free, free)] = inverse @ _block_meat(_scores(Xf, Y, prob), block_frames) @ inverse / n**2
    return out


def _scores(X: np.ndarray, Y: np.ndarray, prob: np.ndarray) -> np.ndarray:
    """Each frame's gradient of its loss (N, P): the soft labels ``Y`` (N, O) against the
    probabilities ``prob`` (N, O) over the columns ``X`` (N, O, P)."""
    return np.matmul((prob - Y)[:, None, :], X)[:, 0, :]


def _block_meat(scores: np.ndarray, block_frames: int) -> np.ndarray:
    """The sandwich's meat (P, P): the frames' ``scores`` (N, P) summed over blocks of
    ``block_frames`` consecutive frames, and those sums' outer products summed."""
    blocks = np.zeros((-(-scores.shape[0] // block_frames), scores.shape[1]))
    np.add.at(blocks, np.arange(scores.shape[0]) // block_frames, scores)
    return blocks.T @ blocks


def staged_covariance(
    X: np.ndarray,
    Y: np.ndarray,
    fitted: tuple[np.ndarray, np.ndarray],
    stages: tuple[tuple[np.ndarray, np.ndarray | None], np.ndarray, np.ndarray],
    l2: float,
    block_frames: int,
) -> np.ndarray:
    """The covariance (P, P) of the weights a staged fit (:func:`fit_staged`) ``fitted`` (theta,
    and which were fitted) to ``X`` (N, O, P) and ``Y`` (N, O), ``stages`` the frames of each
    stage (None: every frame), the columns of its second stage and its first stage's weights: the
    sandwich J^-1 M J^-T of the two stages' estimating equations stacked. The first stage's are
    the scores of its weights on its frames under its own utility (the ground never seen's there
    a weight of its own), the second's those of its columns on its frames under the whole utility; J is their
    Jacobian, block triangular (the second stage's equations move with the terrain's weights,
    not the reverse), and M sums the outer products of the scores summed over blocks of
    ``block_frames`` consecutive frames, as :func:`weight_covariance` does. Weights held have no variance."""
    theta, free = fitted
    (flat, plain), second, first = stages
    plain = np.ones(X.shape[0], dtype=bool) if plain is None else plain
    ones = np.setdiff1d(np.arange(X.shape[2]), second[1:])  # the first stage's columns; never seen among them
    twos = second[free[second]]
    _, alone = _log_softmax(X, first)  # on the flat frames, the first stage's utility (their relief columns are 0)
    _, whole = _log_softmax(X, theta)
    scores = np.concatenate([_scores(X[:, :, ones], Y, alone) * flat[:, None], _scores(X[:, :, twos], Y, whole) * plain[:, None]], axis=1)
    t = len(ones)
    jacobian = plain.sum() * _hessian(X[plain][:, :, np.r_[ones, twos]], whole[plain], l2)
    jacobian[:t, t:] = 0.0
    jacobian[t:, np.flatnonzero(ones == second[0])] = 0.0  # the second stage's equations hold no first-stage weight of never seen
    jacobian[:t, :t] = flat.sum() * _hessian(X[flat][:, :, ones], alone[flat], l2)
    inverse = np.linalg.inv(jacobian)
    stacked = inverse @ _block_meat(scores, block_frames) @ inverse.T
    kept = np.flatnonzero(np.r_[ones != second[0], np.ones(len(twos), dtype=bool)])  # never seen's first-stage weight dropped
    both = np.r_[ones[ones != second[0]], twos]
    out = np.zeros((len(theta), len(theta)))
    out[np.ix_(both, both)] = stacked[np.ix_(kept, kept)]
    return out


def relief_prices(relief: np.ndarray, detour: float) -> np.ndarray:
    """Each band's price as printed (R,): side slope then grade, a band's weight and those of the
    bands below it (a metre past it is past them too), over the detour's price."""
    half = len(relief) // 2
    return np.concatenate([np.cumsum(relief[:half]), np.cumsum(relief[half:])]) / detour


def relief_price_intervals(theta: np.ndarray, covariance: np.ndarray, columns: int, count: int, z: float = 1.96) -> np.ndarray:
    """The 95% intervals (R, 2) of :func:`relief_prices` of the fitted ``theta`` (the terrain
    ``columns``, the detour's price last among them, then ``count`` relief columns, then the
    gate) with its ``covariance``, by the delta method: each price a sum of relief weights over
    the detour's, and never below 0, as the fit holds every price (a band's weight is at least 0:
    steeper ground costs no less); NaN where the detour is priced at 0 (nothing is on its scale)."""
    detour, half = columns - 1, count // 2
    out = np.full((count, 2), np.nan)
    if theta[detour] == 0.0:
        return out
    prices = relief_prices(theta[columns : columns + count], theta[detour])
    for k, price in enumerate(prices):
        first = columns + (0 if k < half else half)
        picked = np.zeros(len(theta))  # the weights the price sums
        picked[first : columns + k + 1] = 1.0
        gradient = picked / theta[detour]
        gradient[detour] -= price / theta[detour]
        spread = z * math.sqrt(max(gradient @ covariance @ gradient, 0.0))
        out[k] = max(price - spread, 0.0), price + spread
    return out


def relief_shown(relief: np.ndarray, bands: tuple[float, ...]) -> tuple[float, float]:
    """The steepest of ``bands`` [deg] any frame's relief columns (N, O, 2B) count ground past, of
    side slope and of grade (NaN: none)."""
    seen = (relief > 0).any(axis=(0, 1)).reshape(2, len(bands))
    roll, grade = (float(bands[np.flatnonzero(row)[-1]]) if row.any() else math.nan for row in seen)
    return roll, grade
