"""The offset rule's compiled loops give the bits of the NumPy and Python forms they stand for.

Each ``_*_numpy`` or ``_*_python`` function below is such a form, kept here as the reference:
the sky line, the reference line's median, the attitude's least squares (``math.fsum``), the
ground map's vote (the camera's tilt included) and its reads beside the path, the corridor's
features and gated value, the lethal lines, and the path's frame that pure pursuit steers by.
Every check is exact (``_same``: equal values, the same signs of zero, NaN where NaN), on
random inputs drawn by ``hypothesis`` (derandomised, so the default run is the same every time)
or by a seeded generator.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from terrapref.camera import PinholeCamera
from terrapref.groundmap import attitude_compiled, map_compiled
from terrapref.groundmap.map_compiled import MapLayers
from terrapref.rules.offset import offsets_compiled
from terrapref.rules.offset.features import RELIEF_BANDS_DEG
from terrapref.rules.offset.geometry import OffsetGeometry
from terrapref.rules.offset.reach_compiled import lethal_hits, swept_reach
from terrapref.rules.offset.steering import pursuit_yaw_rates, steer
from terrapref.scenario.path import ReferencePath
from terrapref.terrain import UNKNOWN
from terrapref.vehicle import pure_pursuit_yaw_rate

FAST = settings(max_examples=25, derandomize=True, deadline=None, database=None)


def _same(a, b) -> bool:
    """``a`` and ``b`` (arrays or numbers) hold the same dtype, shape and values, bit for bit but
    for NaN's payload: equal values, the same signs of zero, NaN where NaN."""
    a, b = np.asarray(a), np.asarray(b)
    if a.dtype != b.dtype or a.shape != b.shape:
        return False
    if a.dtype.kind != "f":
        return bool(np.array_equal(a, b))
    nan = np.isnan(a)
    return bool(
        np.array_equal(nan, np.isnan(b)) and np.array_equal(a[~nan], b[~nan]) and np.array_equal(np.signbit(a[~nan]), np.signbit(b[~nan]))
    )


def _path(rng: np.random.Generator, n: int | None = None) -> ReferencePath:
    """A random polyline of 2 to 7 waypoints, segments 0.3 to 4 m long turning up to 90 deg."""
    n = int(rng.integers(2, 8)) if n is None else n
    heading = rng.uniform(-math.pi, math.pi) + np.cumsum(rng.uniform(-1.5, 1.5, n - 1))
    steps = rng.uniform(0.3, 4.0, n - 1)[:, None] * np.stack([np.cos(heading), np.sin(heading)], axis=1)
    return ReferencePath(np.concatenate([rng.uniform(-2.0, 2.0, (1, 2)), rng.uniform(-2.0, 2.0, (1, 2)) + np.cumsum(steps, axis=0)]))


def _arc_lengths(rng: np.random.Generator, path: ReferencePath, n: int) -> np.ndarray:
    """``n`` arc lengths [m]: the waypoints' own (where the segment changes), and random ones from
    before the path's start to beyond its end."""
    s = np.concatenate([path.s, rng.uniform(-1.5, path.length_m + 1.5, n)])
    return rng.permutation(s)[:n].copy() if n < len(s) else s


# --- the sky line and its reference -------------------------------------------------------------


def _sky_line_numpy(ids: np.ndarray, rows: np.ndarray, n_cols: int, unknown: int) -> np.ndarray:
    """The NumPy form of attitude_compiled.sky_line (HorizonAttitude.line): the first row of each column with
    ground in at least 3 of it and the next 3 rows read, (C,) float; NaN where none."""
    ground = (ids.reshape(len(rows), n_cols) != unknown).astype(np.int8)
    if len(rows) < 4:
        return np.full(n_cols, np.nan)
    run = ground[:-3] + ground[1:-2] + ground[2:-1] + ground[3:]
    starts = run >= 3
    found = starts.any(axis=0)
    return np.where(found, rows[np.argmax(starts, axis=0)].astype(float), np.nan)


@FAST
@given(seed=st.integers(0, 2**32 - 1), n_rows=st.integers(1, 14), n_cols=st.integers(1, 12), ground=st.floats(0.0, 1.0))
def test_sky_line_gives_the_numpy_forms_rows(seed: int, n_rows: int, n_cols: int, ground: float):
    rng = np.random.default_rng(seed)
    step = int(rng.integers(1, 4))
    rows = np.arange(0, n_rows * step, step) + int(rng.integers(0, 200))
    ids = np.where(rng.random(n_rows * n_cols) < ground, rng.integers(0, UNKNOWN, n_rows * n_cols), UNKNOWN).astype(np.uint8)
    assert _same(attitude_compiled.sky_line(ids, rows, n_cols, UNKNOWN), _sky_line_numpy(ids, rows, n_cols, UNKNOWN))


def _column_medians_numpy(history: np.ndarray, count: int) -> np.ndarray:
    """The NumPy form of attitude_compiled.column_medians: ``np.nanmedian`` of the first ``count`` lines."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an all-NaN column's median is NaN
        return np.nanmedian(history[:count], axis=0)


@FAST
@given(
    seed=st.integers(0, 2**32 - 1),
    memory=st.integers(1, 12),
    n_cols=st.integers(1, 8),
    missing=st.floats(0.0, 1.0),
    integer_rows=st.booleans(),
)
def test_column_medians_are_numpys_nanmedians(seed: int, memory: int, n_cols: int, missing: float, integer_rows: bool):
    rng = np.random.default_rng(seed)
    if integer_rows:  # the band's rows, as HorizonAttitude reads them
        rows = np.arange(int(rng.integers(0, 100)), int(rng.integers(100, 200)), int(rng.integers(1, 4))).astype(np.float64)
    else:
        rows = np.unique(rng.uniform(-480.0, 480.0, int(rng.integers(1, 30))))  # negative ones too
    history = np.where(rng.random((memory, n_cols)) < missing, np.nan, rng.choice(rows, (memory, n_cols)))
    for count in range(1, memory + 1):  # the lines past ``count`` are not read
        assert _same(attitude_compiled.column_medians(history, count, rows), _column_medians_numpy(history, count))


# --- exactly rounded sums ------------------------------------------------------------------------


FSUM_CASES = [
    [],
    [0.0],
    [-0.0],
    [-0.0, -0.0],
    [1.0, -1.0],
    [1e16, 1.0, 1e-16],
    [1e16, 1.0, 1e-16][::-1],
    [1e100, 1.0, -1e100, 1e-100, 1e50, -1.0, -1e50],
    [2.0**53, -0.5, -(2.0**-54)],
    [2.0**53, 1.0, 2.0**-100],
    [2.0**53 + 10.0, 1.0, 2.0**-100],
    [2.0**53 - 4.0, 0.5, 2.0**-54],
    [1e16 - 2.0, 1.0 - 2.0**-53, -(1e16 - 2.0), -(1.0 - 2.0**-53)],
    [1.0, 2.0**-53],  # a tie, to even: 1
    [1.0, 2.0**-53, 2.0**-106],  # just past the tie: up
    [1.0 + 2.0**-52, 2.0**-53],  # a tie, to even: up
    [1.0, -(2.0**-54), -(2.0**-54)],
    [5e-324, 5e-324, -5e-324, 2.2250738585072014e-308],
    [1e300, 1e300, -1e300, -1e300, 1e-300],
    [0.1] * 10,
    [1.0 / n for n in range(1, 1001)],
    [(-1.0) ** n / n for n in range(1, 1001)],
    [2.0**n - 2.0 ** (n + 50) + 2.0 ** (n + 52) for n in range(-1074, 972, 2)] + [-(2.0**1022)],  # many partials
]


@pytest.mark.parametrize("values", FSUM_CASES, ids=range(len(FSUM_CASES)))
def test_exact_sum_is_fsum_on_the_hard_cases(values: list[float]):
    assert _same(attitude_compiled.exact_sum(np.array(values, dtype=np.float64)), math.fsum(values))


@FAST
@given(st.lists(st.floats(-1e300, 1e300, allow_subnormal=True), max_size=24))
def test_exact_sum_is_fsum(values: list[float]):
    assert _same(attitude_compiled.exact_sum(np.array(values, dtype=np.float64)), math.fsum(values))


def test_exact_sum_is_fsum_on_sums_that_cancel():
    rng = np.random.default_rng(7)
    for _ in range(300):
        n = int(rng.integers(1, 20))
        v = rng.standard_normal(n) * 10.0 ** rng.integers(-300, 300, n).astype(float)
        v = np.concatenate([v, -v[: int(rng.integers(0, n + 1))] * rng.choice([1.0, 1.0 + 2.0**-52, 1.0 - 2.0**-53])])
        v = rng.permutation(v)
        assert _same(attitude_compiled.exact_sum(v), math.fsum(v.tolist()))


# --- the attitude's fit --------------------------------------------------------------------------


def _least_squares_python(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """The Python form of attitude_compiled.attitude_fit's least squares: the two coefficients x minimising
    |a x - b| for a (N, 2), by the normal equations with exactly rounded sums (math.fsum)."""
    p, q = a[:, 0].tolist(), a[:, 1].tolist()
    r = b.tolist()
    pp, pq, qq = math.fsum(x * x for x in p), math.fsum(x * y for x, y in zip(p, q)), math.fsum(y * y for y in q)
    pr, qr = math.fsum(x * z for x, z in zip(p, r)), math.fsum(y * z for y, z in zip(q, r))
    det = pp * qq - pq * pq
    if not det > 1e-12 * max(pp * qq, 1e-300):
        return 0.0, 0.0
    return (qq * pr - pq * qr) / det, (pp * qr - pq * pr) / det


def _attitude_fit_numpy(
    departure: np.ndarray, reference: np.ndarray, u: np.ndarray, fy: float, cy: float, max_rad: float
) -> tuple[float, float]:
    """The NumPy form of attitude_compiled.attitude_fit: least squares of the columns'
    departures against a small pitch's and roll's image motion at the reference line, twice, the
    second time without the columns that miss the first fit by more than 3 rows."""
    n = len(u)
    ok = np.isfinite(departure) & np.isfinite(reference)
    if ok.sum() < n // 2:
        return 0.0, 0.0
    y = (reference + 0.5 - cy) / fy
    slope = np.gradient(np.where(ok, reference, np.interp(u, u[ok], reference[ok])), u)
    design = np.stack([-fy * (1.0 + y**2), -u - slope * (reference + 0.5 - cy)], axis=1)
    keep = ok.copy()
    for _ in range(2):
        if keep.sum() < n // 2:
            return 0.0, 0.0
        dp, dr = _least_squares_python(design[keep], departure[keep])
        keep = ok & (np.abs(design[:, 0] * dp + design[:, 1] * dr - np.where(ok, departure, 0.0)) <= 3.0)
    if not (abs(dp) <= max_rad and abs(dr) <= max_rad):
        return 0.0, 0.0
    return dp, dr


def _column_offsets(rng: np.random.Generator, n: int, spacing: str) -> np.ndarray:
    """``n`` column offsets u [px] of every 16th column: the camera's (cx = 320), off centre
    (cx = 319.7: inexact offsets, equal steps still), centred at the image's edge (cx = 0.3:
    steps that differ in their last bits), or random increasing steps."""
    cols = np.arange(8, 8 + 16 * n, 16)
    if spacing == "random":
        return -300.0 + np.cumsum(rng.uniform(0.5, 40.0, n))
    return cols + 0.5 - {"camera": 320.0, "off-centre": 319.7, "edge": 0.3}[spacing]


def _attitude_case(rng: np.random.Generator, n: int, spacing: str, missing: float) -> tuple[np.ndarray, ...]:
    """A reference line and a departure from it: a pitch and a roll (some beyond 6 deg) on a
    sloping line, rows rounded to the band's, some columns off by many rows, some NaN."""
    u = _column_offsets(rng, n, spacing)
    fy, cy = 320.00000000000006, 240.0
    reference = np.round((55.0 + rng.uniform(-20, 20) + u * rng.uniform(-0.2, 0.2) + rng.normal(0, 1.5, n)) / 2.0) * 2.0
    reference = np.where(rng.random(n) < rng.uniform(0.0, 0.5), reference + 1.0, reference)  # medians of an even count
    dp, dr = rng.uniform(-0.13, 0.13), rng.uniform(-0.13, 0.13)
    y = (reference + 0.5 - cy) / fy
    departure = np.round(-fy * (1.0 + y**2) * dp - u * dr + rng.normal(0.0, 1.0, n))
    departure = np.where(rng.random(n) < 0.1, departure + rng.choice([-1.0, 1.0], n) * rng.uniform(5.0, 40.0, n), departure)
    departure[rng.random(n) < missing] = np.nan
    reference[rng.random(n) < missing / 2] = np.nan
    return departure, reference, u, fy, cy


SPACINGS = ["camera", "off-centre", "edge", "random"]


@pytest.mark.parametrize("spacing", SPACINGS)
def test_attitude_fit_gives_the_python_forms_pitch_and_roll(spacing: str):
    rng = np.random.default_rng(SPACINGS.index(spacing))
    max_rad = math.radians(6.0)
    fitted = rejected = interpolated = 0
    for trial in range(150):
        n = int(rng.integers(2, 41))
        departure, reference, u, fy, cy = _attitude_case(rng, n, spacing, missing=rng.choice([0.0, 0.2, 0.6]))
        got = attitude_compiled.attitude_fit(departure, reference, u, fy, cy, max_rad)
        want = _attitude_fit_numpy(departure, reference, u, fy, cy, max_rad)
        assert _same(got[0], want[0]) and _same(got[1], want[1]), (trial, departure, reference, u)
        fitted += want != (0.0, 0.0)
        rejected += want == (0.0, 0.0)
        ok = np.isfinite(departure) & np.isfinite(reference)
        interpolated += bool(want != (0.0, 0.0) and not ok.all())
    assert fitted > 30 and rejected > 10 and interpolated > 10  # both outcomes, and the NaN columns filled in
    steps = np.diff(_column_offsets(rng, 40, spacing))
    assert (steps == steps[0]).all() == (spacing in ("camera", "off-centre"))  # np.gradient's uniform and non-uniform forms


@FAST
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(2, 40), spacing=st.sampled_from(SPACINGS), missing=st.floats(0.0, 0.8))
def test_attitude_fit_gives_the_python_forms_pitch_and_roll_on_drawn_lines(seed: int, n: int, spacing: str, missing: float):
    departure, reference, u, fy, cy = _attitude_case(np.random.default_rng(seed), n, spacing, missing)
    max_rad = math.radians(6.0)
    got = attitude_compiled.attitude_fit(departure, reference, u, fy, cy, max_rad)
    want = _attitude_fit_numpy(departure, reference, u, fy, cy, max_rad)
    assert _same(got[0], want[0]) and _same(got[1], want[1])


def test_attitude_fit_rejects_what_the_python_form_rejects():
    u = _column_offsets(np.random.default_rng(0), 10, "camera")
    fy, cy, max_rad = 320.0, 240.0, math.radians(6.0)
    reference = np.full(10, 56.0)
    cases = {
        "too few columns": (np.where(np.arange(10) < 6, np.nan, 1.0), reference),
        "too few reference columns": (np.ones(10), np.where(np.arange(10) < 6, np.nan, reference)),
        "beyond max_deg": (-fy * (1.0 + ((reference + 0.5 - cy) / fy) ** 2) * 0.2, reference),
        "one column of two": (np.array([3.0, np.nan]), np.array([56.0, 56.0])),
        "all outliers after the first fit": (np.array([0.0, 0.0, 0.0, 0.0, 0.0, 400.0, -400.0, 300.0, -300.0, 500.0]), reference),
    }
    for name, (departure, ref) in cases.items():
        uu = u[: len(departure)]
        want = _attitude_fit_numpy(departure, ref, uu, fy, cy, max_rad)
        got = attitude_compiled.attitude_fit(departure, ref, uu, fy, cy, max_rad)
        assert _same(got[0], want[0]) and _same(got[1], want[1]), name


# --- the ground map's vote -----------------------------------------------------------------------


def _ground_numpy(ray: np.ndarray, axes: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The NumPy form of where rays (N, 2) of a camera at ``t`` with ``axes`` meet the ground,
    (N, 2) in the vehicle frame [m]; NaN for rays that do not (terrapref.groundmap.map._ground)."""
    d = [ray[:, 0] * axes[0, i] + ray[:, 1] * axes[1, i] + axes[2, i] for i in range(3)]
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(d[2] < -1e-12, -t[2] / d[2], np.nan)
    return np.stack([t[0] + scale * d[0], t[1] + scale * d[1]], axis=1)


def _map_vote_python(
    evidence,
    stamp,
    cells,
    ox,
    oy,
    inv_res,
    x,
    y,
    c,
    s,
    vx,
    vy,
    weight,
    cols,
    frame,
    fade,
    lethal,
    lethal_share,
    terrain_share,
    min_evidence,
) -> None:
    """The Python form of map_compiled.map_vote's votes, sample by sample, with each sample's column
    ``cols`` given and placed at (vx, vy): float32 evidence, faded by the frames since a cell's
    last vote; a cell's column the lethal one, else the terrain one, else K (K + 1: too little)."""
    n_rows, n_cols = cells.shape
    k = evidence.shape[2] - 1
    for p in range(vx.shape[0]):
        col = cols[p]
        if col > k:
            continue
        i = math.floor((x - ox + vx[p] * c - vy[p] * s) * inv_res)
        j = math.floor((y - oy + vx[p] * s + vy[p] * c) * inv_res)
        if not (0 <= i < n_cols and 0 <= j < n_rows):
            continue
        gap = frame - stamp[j, i]
        if gap != 0:
            f = fade[min(gap, fade.shape[0] - 1)]
            for q in range(k + 1):
                evidence[j, i, q] *= f
            stamp[j, i] = frame
        evidence[j, i, col] += weight[p]
        cells[j, i] = _column_python(evidence[j, i], lethal, lethal_share, terrain_share, min_evidence)


def _column_python(e: np.ndarray, lethal: np.ndarray, lethal_share, terrain_share, min_evidence) -> int:
    """A cell's column from its evidence ``e`` (K + 1,) float32: K + 1 below ``min_evidence`` in all;
    else the lethal column with the most (the first of equals) if the lethal ones hold
    ``lethal_share``; else the terrain one if those hold ``terrain_share``; else K. Sums in float32,
    column by column."""
    k = e.shape[0] - 1
    total, deadly, terrain = e[k], np.float32(0.0), np.float32(0.0)
    best_lethal, best_terrain = -1, -1
    for q in range(k):
        total += e[q]
        if lethal[q]:
            deadly += e[q]
            if best_lethal < 0 or e[q] > e[best_lethal]:
                best_lethal = q
        else:
            terrain += e[q]
            if best_terrain < 0 or e[q] > e[best_terrain]:
                best_terrain = q
    if total < min_evidence:
        return k + 1
    if best_lethal >= 0 and deadly >= lethal_share * total:
        return best_lethal
    if best_terrain >= 0 and terrain >= terrain_share * total:
        return best_terrain
    return k


def _update_numpy(
    evidence, stamp, cells, ox, oy, inv_res, x, y, c, s, vx, vy, weight, ids, columns, frame, fade, lethal, shares, tilt, ray, ground0, t
) -> None:
    """The NumPy form of GroundMap.update's samples ahead of the vote: each pixel's column; with a
    tilt (the camera's axes off its mount), each sample moved by where its ray now meets the
    ground less where the mount's camera saw it meet it, no vote from a ray that misses it."""
    k = evidence.shape[2] - 1
    cols = columns[ids]
    if tilt is not None:
        moved = _ground_numpy(ray, tilt, t) - ground0
        vx, vy = vx + moved[:, 0], vy + moved[:, 1]
        cols = np.where(np.isfinite(vx) & np.isfinite(vy), cols, k + 1)
        vx, vy = np.nan_to_num(vx), np.nan_to_num(vy)
    _map_vote_python(evidence, stamp, cells, ox, oy, inv_res, x, y, c, s, vx, vy, weight, cols, frame, fade, lethal, *shares)


@pytest.mark.parametrize("tilted", [False, True])
def test_map_vote_gives_the_numpy_forms_map(tilted: bool):
    camera = PinholeCamera()
    for seed in range(3):
        rng = np.random.default_rng(seed + 10 * tilted)
        k, n, res = int(rng.integers(1, 5)), 64, 0.25
        columns = rng.integers(0, k + 1, 256).astype(np.uint8)
        columns[UNKNOWN] = k + 1
        lethal = np.zeros(k + 2, dtype=np.bool_)
        lethal[:k] = rng.random(k) < 0.4
        fade = np.ones(64, dtype=np.float32)
        for g in range(1, len(fade)):
            fade[g] = fade[g - 1] * np.float32(rng.uniform(0.0, 1.0))
        shares = (np.float32(0.35), np.float32(0.5), np.float32(rng.choice([0.0, 0.3, 1.5])))
        # The samples: pixels of the camera (some above the horizon) and their ground points on
        # the mount's camera, a grid where the ray misses the ground.
        rows, cols = rng.integers(0, 480, 600), rng.integers(0, 640, 600)
        ray = np.stack([(cols + 0.5 - camera.cx) / camera.fx, (rows + 0.5 - camera.cy) / camera.fy], axis=1)
        ground0 = _ground_numpy(ray, camera.R, camera.t)
        grid = np.round(rng.uniform([0.2, -4.0], [9.0, 4.0], (600, 2)) / 0.1) * 0.1
        vx, vy = np.where(np.isfinite(ground0), ground0, grid).T.copy()
        weight = (1.0 / (1.0 + (vx**2 + vy**2) / 16.0)).astype(np.float32)
        distinct = np.where(rng.random(400) < 0.1, UNKNOWN, rng.integers(0, 12, 400)).astype(np.uint8)  # the pixels read
        pixel_of = rng.integers(0, 400, 600)  # each sample's pixel: some share one
        ids = distinct[pixel_of]
        origin = np.round(rng.uniform(-5.0, 5.0, 2) / res) * res
        maps = [(np.zeros((n, n, k + 1), np.float32), np.zeros((n, n), np.int64), np.full((n, n), k + 1, np.uint8)) for _ in range(2)]
        frame = 0
        for _ in range(6):
            frame += int(rng.choice([1, 1, 2, 5, 70]))  # gaps beyond the fade table too
            x, y = origin + n * res / 2 + rng.uniform(-3.0, 3.0, 2)
            yaw = rng.uniform(-math.pi, math.pi)
            axes = camera.tilted(rng.uniform(-0.06, 0.06), rng.uniform(-0.06, 0.06)) if tilted else camera.R
            pose = (float(origin[0]), float(origin[1]), 1.0 / res, float(x), float(y), math.cos(yaw), math.sin(yaw), vx, vy, weight)
            map_compiled.map_vote(*maps[0], *pose, distinct, pixel_of, columns, frame, fade, tilted, ray, ground0, axes, camera.t)
            _update_numpy(*maps[1], *pose, ids, columns, frame, fade, lethal, shares, axes if tilted else None, ray, ground0, camera.t)
            (evidence, stamp, cells), (want_evidence, want_stamp, want_cells) = maps
            assert _same(evidence, want_evidence) and _same(stamp, want_stamp), (seed, frame)
            # The votes leave their cells undecided; a read decides each as deciding after every vote did.
            voted = cells == map_compiled.UNSETTLED
            assert voted.any() and np.array_equal(cells[~voted], want_cells[~voted]), (seed, frame)
            centres = (np.arange(n) + 0.5) * res
            px, py = np.meshgrid(origin[0] + centres, origin[1] + centres)
            layers = map_compiled.MapLayers(cells.copy(), evidence, lethal, np.array(shares), float(origin[0]), float(origin[1]), 1.0 / res)
            read = map_compiled.map_read(layers, px.ravel(), py.ravel(), k + 1)
            assert np.array_equal(read.reshape(n, n), want_cells), (seed, frame)
            if rng.random() < 0.5:  # some frames' cells decided before the next votes, some not
                map_compiled.map_settle(cells, evidence, lethal, np.array(shares))
                assert _same(cells, want_cells), (seed, frame)
        evidence, _, cells = maps[1]
        assert (cells < k + 1).sum() > 50 and (evidence > 0).sum(axis=2).max() > 1  # cells voted on, some by several columns


# --- reads beside the path -----------------------------------------------------------------------


def _map_read_numpy(cells: np.ndarray, ox: float, oy: float, inv_res: float, px: np.ndarray, py: np.ndarray, never: int) -> np.ndarray:
    """The NumPy form of map_compiled.map_read: ``cells[floor((py - oy) * inv_res), floor((px - ox) *
    inv_res)]`` where inside, ``never`` elsewhere."""
    n_rows, n_cols = cells.shape
    i, j = np.floor((px - ox) * inv_res), np.floor((py - oy) * inv_res)
    inside = (i >= 0) & (i < n_cols) & (j >= 0) & (j < n_rows)
    out = np.full(px.shape, never, dtype=np.uint8)
    out[inside] = cells[j[inside].astype(np.int64), i[inside].astype(np.int64)]
    return out


def _map_read_beside_numpy(
    cells: np.ndarray, ox: float, oy: float, inv_res: float, path: ReferencePath, s: np.ndarray, lat: np.ndarray, never: int
) -> np.ndarray:
    """The NumPy form of map_compiled.map_read_beside: the map's column (O, S, F) at ``centre + lat *
    normal``, ``centre = path.point_at(s)``, ``normal`` the path's direction there turned left."""
    u = path.direction_at(s)
    normal = np.stack([-u[:, 1], u[:, 0]], axis=-1)
    centre = path.point_at(s)
    points = centre[None, :, None, :] + lat[:, None, :, None] * normal[None, :, None, :]
    return _map_read_numpy(cells, ox, oy, inv_res, points[..., 0], points[..., 1], never)


def _random_map(rng: np.random.Generator, path: ReferencePath, k: int) -> tuple[np.ndarray, float, float, float]:
    """Cells (64, 64) of random columns 0..K+1 at 0.25 m, over part of ``path`` (some of it outside)."""
    res = 0.25
    ox, oy = np.round((path.waypoints.min(axis=0) - rng.uniform(-4.0, 6.0, 2)) / res) * res
    return rng.integers(0, k + 2, (64, 64)).astype(np.uint8), float(ox), float(oy), 1.0 / res


def _undecided(rng: np.random.Generator, cells: np.ndarray, k: int) -> tuple[np.ndarray, tuple, np.ndarray]:
    """``cells`` with about a third of them voted on since decided (map_compiled.UNSETTLED), the map's
    layers a compiled read takes (cells, evidence, lethal columns, shares), and every cell as a
    read decides it (_column_python where undecided)."""
    evidence = (rng.random((*cells.shape, k + 1)) * (rng.random((*cells.shape, k + 1)) < 0.5)).astype(np.float32)
    lethal = rng.random(k + 2) < 0.4
    shares = np.array([0.35, 0.5, rng.choice([0.0, 0.3])], dtype=np.float32)
    undecided = rng.random(cells.shape) < 0.3
    decided = cells.copy()
    for j, i in zip(*np.nonzero(undecided)):
        decided[j, i] = _column_python(evidence[j, i], lethal, *shares)
    return np.where(undecided, map_compiled.UNSETTLED, cells).astype(np.uint8), (evidence, lethal, shares), decided


@FAST
@given(seed=st.integers(0, 2**32 - 1), n_st=st.integers(1, 20), n_off=st.integers(1, 8), n_f=st.integers(1, 6))
def test_map_read_beside_gives_the_numpy_forms_columns(seed: int, n_st: int, n_off: int, n_f: int):
    rng = np.random.default_rng(seed)
    path = _path(rng)
    k = int(rng.integers(1, 6))
    cells, ox, oy, inv_res = _random_map(rng, path, k)
    s = _arc_lengths(rng, path, n_st)
    lat = rng.uniform(-4.0, 4.0, (n_off, n_f))
    a, d, length = path.segments
    lazy, layers, cells = _undecided(rng, cells, k)
    got = map_compiled.map_read_beside(MapLayers(lazy, *layers, ox, oy, inv_res), path.s, a, d, length, s, lat, k + 1)
    assert _same(got, _map_read_beside_numpy(cells, ox, oy, inv_res, path, s, lat, k + 1))
    read = lazy != map_compiled.UNSETTLED
    assert np.array_equal(lazy[read], cells[read])  # the cells it decided are kept as decided


def _map_read_split_numpy(cells, evidence, lethal, ox, oy, inv_res, px, py, never, lead, second) -> np.ndarray:
    """The NumPy form of map_compiled.map_read_split: the map's column, never where the cell's
    terrain column (not lethal) holds under ``lead`` of its evidence and another such column at
    least ``second``."""
    out = _map_read_numpy(cells, ox, oy, inv_res, px, py, never)
    k = evidence.shape[2] - 1
    for p in np.flatnonzero((out < k) & ~lethal[np.minimum(out, k + 1)]):
        e = evidence[int(math.floor((py[p] - oy) * inv_res)), int(math.floor((px[p] - ox) * inv_res))]
        total = np.float32(e[k])
        for q in range(k):  # float32, in column order
            total = np.float32(total + e[q])
        others = [e[q] for q in range(k) if q != out[p] and not lethal[q]]
        if e[out[p]] < np.float32(lead) * total and max(others, default=-1.0) >= np.float32(second) * total:
            out[p] = never
    return out


@FAST
@given(
    seed=st.integers(0, 2**32 - 1), n=st.integers(1, 300), lead=st.sampled_from([0.5, 0.6, 1.1]), second=st.sampled_from([0.0, 0.15, 0.3])
)
def test_map_read_split_gives_the_numpy_forms_columns(seed: int, n: int, lead: float, second: float):
    rng = np.random.default_rng(seed)
    k = int(rng.integers(1, 6))
    cells, ox, oy, inv_res = _random_map(rng, _path(rng), k)
    lazy, (evidence, lethal, shares), cells = _undecided(rng, cells, k)
    px, py = ox + rng.uniform(-2.0, 18.0, n), oy + rng.uniform(-2.0, 18.0, n)
    layers = MapLayers(lazy, evidence, lethal, shares, ox, oy, inv_res)
    got = map_compiled.map_read_split(layers, px, py, k + 1, np.float32(lead), np.float32(second))
    want = _map_read_split_numpy(cells, evidence, lethal, ox, oy, inv_res, px, py, k + 1, lead, second)
    assert _same(got, want)
    plain = _map_read_numpy(cells, ox, oy, inv_res, px, py, k + 1)
    assert np.all((got == plain) | (got == k + 1))  # a split cell reads as never seen; no other cell changes


def _lethal_hits_numpy(
    cells: np.ndarray,
    ox: float,
    oy: float,
    inv_res: float,
    path: ReferencePath,
    progress_m: float,
    stations: np.ndarray,
    offsets: np.ndarray,
    across: np.ndarray,
    lethal: np.ndarray,
    never: int,
) -> np.ndarray:
    """The NumPy form of terrapref.rules.offset.reach_compiled.lethal_hits (OffsetSteering's lethal
    lines): whether any point across each offset's line at each station lies on a lethal column."""
    s = np.minimum(progress_m + stations, path.length_m)
    return lethal[_map_read_beside_numpy(cells, ox, oy, inv_res, path, s, offsets[:, None] + across[None, :], never)].any(axis=2)


@FAST
@given(seed=st.integers(0, 2**32 - 1), n_off=st.integers(1, 10), n_across=st.integers(1, 7))
def test_lethal_hits_gives_the_numpy_forms_lines(seed: int, n_off: int, n_across: int):
    rng = np.random.default_rng(seed)
    path = _path(rng)
    k = int(rng.integers(1, 6))
    cells, ox, oy, inv_res = _random_map(rng, path, k)
    cells = np.where(rng.random(cells.shape) < 0.97, k, cells).astype(np.uint8)  # lethal here and there
    lethal = rng.random(k + 2) < 0.5
    stations = -1.0 + np.arange(int(rng.integers(1, 40))) * 0.25
    offsets = np.sort(rng.uniform(-3.5, 3.5, n_off))
    across = np.sort(rng.uniform(-0.9, 0.9, n_across))
    progress_m = float(rng.uniform(-1.0, path.length_m + 1.0))
    a, d, length = path.segments
    lazy, layers, cells = _undecided(rng, cells, k)
    got = lethal_hits(MapLayers(lazy, *layers, ox, oy, inv_res), path.s, a, d, length, progress_m, stations, offsets, across, lethal, k + 1)
    assert _same(got, _lethal_hits_numpy(cells, ox, oy, inv_res, path, progress_m, stations, offsets, across, lethal, k + 1))
    read = lazy != map_compiled.UNSETTLED
    assert np.array_equal(lazy[read], cells[read])


@FAST
@given(seed=st.integers(0, 2**32 - 1), n_off=st.integers(1, 10))
def test_swept_reach_reads_undecided_cells_as_decided(seed: int, n_off: int):
    rng = np.random.default_rng(seed)
    path = _path(rng)
    k = int(rng.integers(1, 6))
    cells, ox, oy, inv_res = _random_map(rng, path, k)
    cells = np.where(rng.random(cells.shape) < 0.97, k, cells).astype(np.uint8)
    lazy, layers, cells = _undecided(rng, cells, k)
    lethal = rng.random(k + 2) < 0.5
    offsets = np.sort(rng.uniform(-3.5, 3.5, n_off))
    clear = np.sort(rng.uniform(-0.9, 0.9, 5))
    progress_m = float(rng.uniform(0.0, path.length_m))
    x, y = path.point_at(progress_m)
    a, d, length = path.segments
    args = (float(x), float(y), float(path.heading_at(progress_m)), offsets, progress_m, 2.0, 0.1, 30, 2.5, path.s, a, d, length, clear)
    got = swept_reach(*args, MapLayers(lazy, *layers, ox, oy, inv_res), lethal, k + 1)
    want = swept_reach(*args, MapLayers(cells, *layers, ox, oy, inv_res), lethal, k + 1)  # no cell left to decide
    assert _same(got, want)
    read = lazy != map_compiled.UNSETTLED
    assert np.array_equal(lazy[read], cells[read])


# --- the corridor's features and value -----------------------------------------------------------


def _corridor_features_numpy(
    col: np.ndarray,
    steep: np.ndarray,
    centre: int,
    k: int,
    gap: int,
    beyond: int,
    step: float,
    stations: np.ndarray,
    offsets: np.ndarray,
    span: float,
) -> tuple[np.ndarray, float, int]:
    """The NumPy form of offsets_compiled.offset_features (OffsetFeatures.__call__): metres on each
    column up to ``beyond`` stations past the first patch on the path (terrain or steep ground),
    the detour's price, and the stations counted."""
    on = (col[centre] < k).any(axis=1) | steep  # (S,): terrain or steep ground on the path itself
    upto, on_path_m, near_m = len(stations), 0.0, math.inf
    if on.any():
        idx = np.flatnonzero(on)
        first = last = int(idx[0])
        for i in idx[1:]:
            if i - last > gap:
                break
            last = int(i)
        upto = min(len(stations), last + 1 + beyond)
        on_path_m = (last - first + 1) * step
        near_m = float(stations[first])
    n_off = len(offsets)
    flat = col[:, :upto].reshape(n_off, -1).astype(np.int64)
    counts = np.bincount((np.arange(n_off)[:, None] * (k + 2) + flat).ravel(), minlength=n_off * (k + 2)).reshape(n_off, k + 2)
    metres = counts * (step / col.shape[2])
    detour = offsets**2 * (on_path_m + span)
    return np.concatenate([metres[:, :k], metres[:, k + 1 :], detour[:, None]], axis=1), near_m, upto


@FAST
@given(
    seed=st.integers(0, 2**32 - 1),
    k=st.integers(1, 6),
    gap=st.integers(0, 5),
    beyond=st.integers(0, 12),
    on_path=st.sampled_from([0.0, 0.05, 0.3, 1.0]),
    steep_share=st.sampled_from([0.0, 0.05, 0.3]),
)
def test_offset_rule_features_give_the_numpy_forms_features(seed: int, k: int, gap: int, beyond: int, on_path: float, steep_share: float):
    rng = np.random.default_rng(seed)
    config = OffsetGeometry(station_step_m=float(rng.choice([0.25, 0.1, 0.3])), span_m=float(rng.uniform(0.0, 8.0)))
    stations, offsets = config.stations, config.offsets
    n_off, n_st, n_f = len(offsets), len(stations), int(rng.integers(1, 6))
    centre = int(np.argmin(np.abs(offsets)))
    col = rng.integers(0, k + 2, (n_off, n_st, n_f)).astype(np.uint8)
    # On the path: terrain at a share ``on_path`` of the stations (none, scattered with gaps, all).
    terrain = rng.random(n_st) < on_path
    col[centre] = np.where(
        terrain[:, None] & (rng.random((n_st, n_f)) < 0.5), rng.integers(0, k, (n_st, n_f)), rng.integers(k, k + 2, (n_st, n_f))
    )
    steep = rng.random(n_st) < steep_share  # steep ground on the path (relief), alone or beside terrain
    args = (centre, k, gap, beyond, config.station_step_m, stations, offsets, config.span_m)
    got, near_m, upto = offsets_compiled.offset_features(col, steep, *args)
    want, want_near_m, want_upto = _corridor_features_numpy(col, steep, *args)
    assert _same(got, want) and _same(near_m, want_near_m) and upto == want_upto


def _gated_numpy(features: np.ndarray, view_near_m: float, offsets: np.ndarray, near_m: float) -> np.ndarray:
    """The NumPy form of terrapref.rules.offset.features.gated: the gate column d^2 while nothing is
    on the path within ``near_m``, after the corridor's features, (O, K + 3)."""
    gate = offsets**2 * float(view_near_m > near_m)
    return np.concatenate([features, gate[:, None]], axis=1)


def _weighted_numpy(features: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """The NumPy form of ``features @ weights`` (O,) in offsets_compiled.gated_value: column by column in order."""
    value = features[:, 0] * weights[0]
    for j in range(1, len(weights)):
        value = value + features[:, j] * weights[j]
    return value


@FAST
@given(
    seed=st.integers(0, 2**32 - 1),
    n_off=st.integers(1, 31),
    k=st.integers(1, 6),
    view_near_m=st.sampled_from([0.0, 1.5, 4.0, math.inf]),
    near_m=st.sampled_from([0.0, 2.0, 4.0, 100.0]),
)
def test_gated_value_gives_the_numpy_forms_value(seed: int, n_off: int, k: int, view_near_m: float, near_m: float):
    rng = np.random.default_rng(seed)
    features = rng.uniform(0.0, 12.0, (n_off, k + 2)) * 10.0 ** rng.integers(-3, 4, (n_off, k + 2))
    features[rng.random(features.shape) < 0.3] = 0.0
    offsets = rng.uniform(-3.0, 3.0, n_off)
    weights = rng.normal(0.0, 1.0, k + 3) * 10.0 ** rng.integers(-2, 3, k + 3)
    got = offsets_compiled.gated_value(features, offsets, view_near_m > near_m, weights)
    assert _same(got, _weighted_numpy(_gated_numpy(features, view_near_m, offsets, near_m), weights))


@FAST
@given(
    seed=st.integers(0, 2**32 - 1),
    n_off=st.integers(1, 31),
    n_st=st.integers(1, 60),
    upto_share=st.floats(0.0, 1.0),
    missing=st.floats(0.0, 0.6),
)
def test_relief_metres_give_the_numpy_forms_columns(seed: int, n_off: int, n_st: int, upto_share: float, missing: float):
    rng = np.random.default_rng(seed)
    bands = np.asarray(RELIEF_BANDS_DEG)
    attitudes = rng.uniform(0.0, 30.0, (n_off, n_st, 2))
    on_band = rng.random(attitudes.shape) < 0.2  # exactly on a band: not past it
    attitudes[on_band] = rng.choice(bands, int(on_band.sum()))
    attitudes[rng.random(attitudes.shape) < missing] = np.nan  # unknown: past none
    upto = int(round(upto_share * n_st))
    got = offsets_compiled.relief_metres(attitudes, upto, bands, 0.25)
    assert _same(got, (attitudes[:, :upto, :, None] > bands).sum(axis=1).reshape(n_off, -1) * 0.25)


# --- the path's frame and pure pursuit -----------------------------------------------------------


@FAST
@given(seed=st.integers(0, 2**32 - 1))
def test_frame_at_gives_point_at_and_direction_at(seed: int):
    rng = np.random.default_rng(seed)
    path = _path(rng)
    for s in _arc_lengths(rng, path, 12).tolist():
        x, y, ux, uy = path.frame_at(s)
        point, direction = path.point_at(s), path.direction_at(s)
        assert _same(np.array([x, y]), point) and _same(np.array([ux, uy]), direction), s
        assert _same(np.array([x, y]), path.point_at(np.array([s]))[0]), s  # the vectorised form too


def _steer_python(path: ReferencePath, pose, progress_m: float, offset_m, pursuit_m: float, v_mps: float, clip: bool = True) -> np.ndarray:
    """The Python form of pursuit_yaw_rates (``clip=False``) and steer: the pure-pursuit yaw rate
    toward the path shifted by ``offset_m``, the target read by ``point_at`` and ``direction_at``."""
    s = min(progress_m + pursuit_m, path.length_m)
    cos_h, sin_h = (float(v) for v in path.direction_at(s))
    tx0, ty0 = (float(v) for v in path.point_at(s))
    x, y, yaw = (float(v) for v in pose)
    offsets = np.asarray(offset_m, dtype=float)
    out = np.empty(offsets.shape)
    for k, d in enumerate(offsets.flat):
        tx, ty = tx0 - d * sin_h - x, ty0 + d * cos_h - y
        alpha = (math.atan2(ty, tx) - yaw + math.pi) % (2 * math.pi) - math.pi
        w = pure_pursuit_yaw_rate(v_mps, math.sin(alpha), max(math.hypot(tx, ty), 1e-6))
        out.flat[k] = min(max(w, -1.0), 1.0) if clip else w
    return out


@FAST
@given(seed=st.integers(0, 2**32 - 1), scalar=st.booleans())
def test_pursuit_yaw_rates_and_steer_give_the_python_forms_rates(seed: int, scalar: bool):
    rng = np.random.default_rng(seed)
    path = _path(rng)
    for _ in range(4):
        progress_m = float(rng.choice([rng.uniform(-0.5, path.length_m + 0.5), *path.s]))
        x, y = path.point_at(min(max(progress_m, 0.0), path.length_m)) + rng.normal(0.0, 1.0, 2)
        pose = (float(x), float(y), float(rng.uniform(-math.pi, math.pi)))
        offsets = float(rng.uniform(-3.0, 3.0)) if scalar else np.arange(-15, 16) * 0.2
        pursuit_m, v_mps = float(rng.uniform(0.5, 4.0)), float(rng.uniform(0.5, 3.0))
        rates = pursuit_yaw_rates(path, pose, progress_m, offsets, pursuit_m, v_mps)
        assert _same(rates, _steer_python(path, pose, progress_m, offsets, pursuit_m, v_mps, clip=False))
        assert _same(
            steer(path, pose, progress_m, offsets, pursuit_m, v_mps),
            _steer_python(path, pose, progress_m, offsets, pursuit_m, v_mps, clip=True),
        )
