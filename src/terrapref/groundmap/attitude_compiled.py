"""The camera's pitch and roll off its mount from the sky line of a frame, compiled (Numba)
(terrapref.groundmap.attitude).

Each loop does, element by element, exactly the IEEE 754 operations of the NumPy form its
docstring gives, in the same order (compiled without fast-math: nothing is reassociated or
fused into a multiply-add), so the results, and every decision made from them, are the same
bits as the NumPy forms give.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def sky_line(ids: np.ndarray, rows: np.ndarray, n_cols: int, unknown: int) -> np.ndarray:
    """The first band row of each column below which ground is seen, (n_cols,) float; NaN where none.

    ``ids`` (len(rows) * n_cols,) are the class ids of the band, row by row. The NumPy form
    (tests/rules/test_offset_kernels.py keeps it): ``ground = ids != unknown``, the first row r with at
    least 3 of rows r..r+3 ground; all NaN when the band holds fewer than 4 rows.
    """
    out = np.full(n_cols, np.nan)
    if rows.shape[0] < 4:
        return out
    for c in range(n_cols):
        for r in range(rows.shape[0] - 3):
            seen = 0
            for q in range(4):
                if ids[(r + q) * n_cols + c] != unknown:
                    seen += 1
            if seen >= 3:
                out[c] = rows[r]
                break
    return out


@njit(cache=True, nogil=True)
def column_medians(history: np.ndarray, count: int, rows: np.ndarray) -> np.ndarray:
    """Median of each column of ``history[:count]`` (M, C) over its non-NaN entries, (C,); NaN
    where a column has none. Every entry is NaN or one of ``rows`` (increasing), so each column is
    counted into their bins. The NumPy form: ``np.nanmedian(history[:count], axis=0)`` (for an even
    count, the mean of the two middle values)."""
    n_cols, n_bins = history.shape[1], rows.shape[0]
    step = rows[1] - rows[0] if n_bins > 1 else 0.0
    out = np.empty(n_cols)
    counts = np.zeros(n_bins, np.int64)
    for c in range(n_cols):
        counts[:] = 0
        n = 0
        for m in range(count):
            v = history[m, c]
            if not np.isnan(v):
                # Evenly spaced rows (the band's) give the bin at once; a search otherwise.
                b = int((v - rows[0]) / step + 0.5) if step > 0.0 else -1
                if not (0 <= b < n_bins and rows[b] == v):
                    b = np.searchsorted(rows, v)
                    if b >= n_bins or rows[b] != v:
                        raise ValueError("a history entry is not one of the rows")
                counts[b] += 1
                n += 1
        if n == 0:
            out[c] = np.nan
            continue
        # The values of rank n // 2 (and n // 2 - 1, for an even n), counting from 0.
        low, high = np.nan, np.nan
        seen = 0
        for b in range(n_bins):
            seen += counts[b]
            if np.isnan(low) and seen > (n - 1) // 2:
                low = rows[b]
            if seen > n // 2:
                high = rows[b]
                break
        out[c] = high if n % 2 == 1 else (low + high) / 2.0
    return out


@njit(cache=True, nogil=True)
def exact_sum(values: np.ndarray) -> float:
    """The sum of finite ``values``, exactly rounded (to nearest, ties to even): ``math.fsum``'s
    result, by the same method (Shewchuk's non-overlapping partials), so the same bits on every CPU."""
    partials = np.empty(values.shape[0] + 1)
    n = 0
    for x in values:
        i = 0
        for j in range(n):
            y = partials[j]
            if abs(x) < abs(y):
                x, y = y, x
            hi = x + y
            lo = y - (hi - x)
            if lo != 0.0:
                partials[i] = lo
                i += 1
            x = hi
        n = i
        if x != 0.0:
            partials[n] = x
            n += 1
    if n == 0:
        return 0.0
    n -= 1
    hi = partials[n]
    lo = 0.0
    while n > 0:
        x = hi
        n -= 1
        y = partials[n]
        hi = x + y
        lo = y - (hi - x)
        if lo != 0.0:
            break
    # Half-even rounding across several partials.
    if n > 0 and ((lo < 0.0 and partials[n - 1] < 0.0) or (lo > 0.0 and partials[n - 1] > 0.0)):
        y = lo * 2.0
        x = hi + y
        if y == x - hi:
            hi = x
    return hi


@njit(cache=True, nogil=True)
def _interp(x: float, xp: np.ndarray, fp: np.ndarray) -> float:
    """``np.interp(x, xp, fp)`` for increasing ``xp`` (the ends held beyond it)."""
    n = xp.shape[0]
    if x <= xp[0]:
        return fp[0]
    if x >= xp[n - 1]:
        return fp[n - 1]
    j = np.searchsorted(xp, x, side="right") - 1
    if x == xp[j]:
        return fp[j]
    slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
    out = slope * (x - xp[j]) + fp[j]
    if np.isnan(out):
        out = slope * (x - xp[j + 1]) + fp[j + 1]
        if np.isnan(out) and fp[j] == fp[j + 1]:
            out = fp[j]
    return out


@njit(cache=True, nogil=True)
def _gradient(f: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``np.gradient(f, x)`` of 1-D ``f`` at coordinates ``x`` (at least 2): second-order central
    differences inside (numpy's uniform form when every step of ``x`` is equal), first-order at the ends."""
    n = f.shape[0]
    out = np.empty(n)
    dx = np.empty(n - 1)
    uniform = True
    for i in range(n - 1):
        dx[i] = x[i + 1] - x[i]
        if dx[i] != dx[0]:
            uniform = False
    if uniform:
        for i in range(1, n - 1):
            out[i] = (f[i + 1] - f[i - 1]) / (2.0 * dx[0])
        out[0] = (f[1] - f[0]) / dx[0]
        out[n - 1] = (f[n - 1] - f[n - 2]) / dx[0]
        return out
    for i in range(1, n - 1):
        dx1, dx2 = dx[i - 1], dx[i]
        a = -dx2 / (dx1 * (dx1 + dx2))
        b = (dx2 - dx1) / (dx1 * dx2)
        c = dx1 / (dx2 * (dx1 + dx2))
        out[i] = a * f[i - 1] + b * f[i] + c * f[i + 1]
    out[0] = (f[1] - f[0]) / dx[0]
    out[n - 1] = (f[n - 1] - f[n - 2]) / dx[n - 2]
    return out


@njit(cache=True, nogil=True)
def attitude_fit(departure: np.ndarray, reference: np.ndarray, u: np.ndarray, fy: float, cy: float, max_rad: float) -> tuple[float, float]:
    """(pitch, roll) [rad] off the mount from the sky line's ``departure`` (C,) [rows] from its
    ``reference`` (C,) at column offsets ``u`` (C,) [px]; (0, 0) when fewer than half the columns
    support it, or the estimate exceeds ``max_rad``. The least squares of
    terrapref.groundmap.attitude's module docstring, twice (the second time without the columns
    that miss the first fit by more than 3 rows), with exactly rounded sums (:func:`exact_sum`);
    tests/rules/test_offset_kernels.py keeps its NumPy form and compares."""
    n = departure.shape[0]
    if n < 2:  # no slope to read along a single column
        return 0.0, 0.0
    ok = np.empty(n, np.bool_)
    good = 0
    for i in range(n):
        ok[i] = np.isfinite(departure[i]) and np.isfinite(reference[i])
        good += ok[i]
    if good < n // 2:
        return 0.0, 0.0
    xp, fp = np.empty(good), np.empty(good)
    g = 0
    for i in range(n):
        if ok[i]:
            xp[g], fp[g] = u[i], reference[i]
            g += 1
    filled = np.empty(n)
    for i in range(n):
        filled[i] = reference[i] if ok[i] else _interp(u[i], xp, fp)
    slope = _gradient(filled, u)
    d0, d1 = np.empty(n), np.empty(n)
    for i in range(n):
        y = (reference[i] + 0.5 - cy) / fy
        d0[i] = -fy * (1.0 + y * y)
        d1[i] = -u[i] - slope[i] * (reference[i] + 0.5 - cy)
    keep = ok.copy()
    dp = dr = 0.0
    pp, pq, qq, pr, qr = np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    for _ in range(2):
        m = 0
        for i in range(n):
            if keep[i]:
                pp[m], pq[m], qq[m] = d0[i] * d0[i], d0[i] * d1[i], d1[i] * d1[i]
                pr[m], qr[m] = d0[i] * departure[i], d1[i] * departure[i]
                m += 1
        if m < n // 2:
            return 0.0, 0.0
        spp, spq, sqq = exact_sum(pp[:m]), exact_sum(pq[:m]), exact_sum(qq[:m])
        spr, sqr = exact_sum(pr[:m]), exact_sum(qr[:m])
        det = spp * sqq - spq * spq
        if not det > 1e-12 * max(spp * sqq, 1e-300):
            dp, dr = 0.0, 0.0
        else:
            dp, dr = (sqq * spr - spq * sqr) / det, (spp * sqr - spq * spr) / det
        for i in range(n):
            keep[i] = ok[i] and abs(d0[i] * dp + d1[i] * dr - (departure[i] if ok[i] else 0.0)) <= 3.0
    if not (abs(dp) <= max_rad and abs(dr) <= max_rad):
        return 0.0, 0.0
    return dp, dr
