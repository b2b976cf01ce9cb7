"""Reference-path geometry: arc length, projection with a progress window, cross-track error."""

from __future__ import annotations

import bisect
import math

import numpy as np

_SCALAR_SEGMENTS = 24  # project() windows up to this many segments in plain floats


FARTHEST_M = 1e7
"""The farthest a path's point may lie from the origin [m]: UTM coordinates fit, as recordings' poses do."""


class ReferencePath:
    """A polyline of waypoints (N, 2) [m] with arc-length parametrisation."""

    def __init__(self, waypoints: np.ndarray) -> None:
        wp = np.asarray(waypoints, dtype=float)
        if wp.ndim != 2 or wp.shape[1:] != (2,) or not np.isfinite(wp).all():
            raise ValueError(f"a path is a list of finite (x, y) points, got shape {wp.shape}")
        if np.abs(wp).max(initial=0.0) > FARTHEST_M:  # its lengths, and the progress along it, would overflow or lose every digit
            raise ValueError(f"a path's points lie within +-{FARTHEST_M:g} m of the origin (a place on Earth), got {np.abs(wp).max():g}")
        keep = np.ones(len(wp), dtype=bool)
        keep[1:] = np.any(np.diff(wp, axis=0) != 0, axis=1)  # drop repeated points
        self.waypoints = wp[keep]
        if len(self.waypoints) < 2:
            raise ValueError(
                f"a path needs at least two distinct points; its {len(wp)} point(s) are all {wp[0].tolist() if len(wp) else 'missing'}"
            )
        self._a = self.waypoints[:-1]
        self._d = np.diff(self.waypoints, axis=0)
        self._len = np.linalg.norm(self._d, axis=1)
        self.s = np.concatenate([[0.0], np.cumsum(self._len)])  # arc length at each waypoint, (N,)
        self._s_list, self._len_list = self.s.tolist(), self._len.tolist()
        self._a_list, self._d_list = self._a.tolist(), self._d.tolist()
        self._resampled: dict[float, tuple[np.ndarray, np.ndarray]] = {}

    @property
    def length_m(self) -> float:
        return float(self.s[-1])

    @property
    def segments(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each segment's start (N - 1, 2), vector (N - 1, 2) and length (N - 1,) [m]; with :attr:`s`,
        what a compiled loop needs to walk the path as :meth:`point_at` and :meth:`heading_at` do."""
        return self._a, self._d, self._len

    def point_at(self, s: float | np.ndarray) -> np.ndarray:
        """Points (..., 2) at arc lengths ``s`` (clamped to the path)."""
        if isinstance(s, (float, int)):  # scalar fast path: used once per frame in the control loop
            x, y, _, _ = self.frame_at(s)
            return np.array([x, y])
        s, i = self._segment_at(s)
        f = (s - self.s[i]) / self._len[i]
        return self._a[i] + f[..., None] * self._d[i]

    def frame_at(self, s: float) -> tuple[float, float, float, float]:
        """(x, y, ux, uy): the point at arc length ``s`` (clamped to the path) and the unit direction
        there, the values :meth:`point_at` and :meth:`direction_at` give, in plain floats."""
        sf = min(max(float(s), 0.0), self.length_m)
        i = min(max(bisect.bisect_right(self._s_list, sf) - 1, 0), len(self._len) - 1)
        ln = self._len_list[i]
        f = (sf - self._s_list[i]) / ln
        (ax, ay), (dx, dy) = self._a_list[i], self._d_list[i]
        return ax + f * dx, ay + f * dy, dx / ln, dy / ln

    def straight_between(self, s_lo: float, s_hi: float) -> tuple[float, float, float, float] | None:
        """(x, y, ux, uy): the point at ``s_lo`` and the unit direction there, when the path runs
        straight from ``s_lo`` to ``s_hi`` (one segment, both inside the path); else None."""
        if not 0.0 <= s_lo <= s_hi <= self.length_m:
            return None
        i = min(max(bisect.bisect_right(self._s_list, s_lo) - 1, 0), len(self._len) - 1)
        if s_hi > self._s_list[i + 1]:
            return None
        ln = self._len_list[i]
        (ax, ay), (dx, dy) = self._a_list[i], self._d_list[i]
        f = (s_lo - self._s_list[i]) / ln
        return ax + f * dx, ay + f * dy, dx / ln, dy / ln

    def resampled(self, spacing_m: float) -> tuple[np.ndarray, np.ndarray]:
        """Points every ``spacing_m`` along the path (and its end): (points (K, 2), arc lengths (K,)).

        Cached per spacing; nearest-waypoint searches use these rather than sparse waypoints.
        """
        if spacing_m not in self._resampled:
            s = np.append(np.arange(0.0, self.length_m, spacing_m), self.length_m)
            self._resampled[spacing_m] = (self.point_at(s), s)
        return self._resampled[spacing_m]

    def heading_at(self, s: float | np.ndarray) -> np.ndarray:
        """Path direction [rad] at arc lengths ``s``."""
        _, i = self._segment_at(s)
        return np.arctan2(self._d[i, 1], self._d[i, 0])

    def direction_at(self, s: float | np.ndarray) -> np.ndarray:
        """Unit path directions (..., 2) at arc lengths ``s`` (clamped): each segment's vector over
        its length, so the same bits on every CPU (no trigonometry)."""
        s, i = self._segment_at(s)
        return self._d[i] / self._len[i, None] if np.ndim(s) else self._d[i] / self._len[i]

    def frames_at(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The points (S, 2) and unit directions (S, 2) at arc lengths ``s`` (S,) (clamped), as
        :meth:`point_at` and :meth:`direction_at` give them, the segments found once."""
        s, i = self._segment_at(s)
        d, length = self._d[i], self._len[i]
        return self._a[i] + ((s - self.s[i]) / length)[:, None] * d, d / length[:, None]

    def _segment_at(self, s: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Arc lengths ``s`` clamped to the path, and the segment each lies on."""
        s = np.clip(np.asarray(s, dtype=float), 0.0, self.length_m)
        return s, np.clip(np.searchsorted(self.s, s, side="right") - 1, 0, len(self._len) - 1)

    def project(self, xy: np.ndarray, s_lo: float = -np.inf, s_hi: float = np.inf) -> tuple[float, float]:
        """Nearest point of the path to ``xy`` among arc lengths in [s_lo, s_hi].

        Returns:
            (s [m], signed lateral offset [m], positive to the left of the path direction).
        """
        p = np.asarray(xy, dtype=float)
        # The segments that meet [s_lo, s_hi] are contiguous (s only grows): segment i spans
        # [s[i], s[i + 1]], so they run from the first i with s[i + 1] >= s_lo to the last with
        # s[i] <= s_hi. Found by bisection, the window costs the same on a long path as a short one.
        n_seg = len(self._len_list)
        i0 = bisect.bisect_left(self._s_list, s_lo, 1, n_seg + 1) - 1
        i1 = bisect.bisect_right(self._s_list, s_hi, 0, n_seg)
        if i0 >= i1:  # no segment in the window: search them all
            i0, i1 = 0, n_seg
        px, py = float(p[0]), float(p[1])
        # Plain floats for a short window; NumPy for a long one, or for a non-finite point or a
        # NaN bound, whose NaN results only NumPy's argmin and clip give as they always have.
        if i1 - i0 <= _SCALAR_SEGMENTS and math.isfinite(px) and math.isfinite(py) and not (math.isnan(s_lo) or math.isnan(s_hi)):
            found = self._project_scalar(px, py, s_lo, s_hi, i0, i1)
            if found is not None:
                return found
        seg_lo, a, d, ln = self.s[i0:i1], self._a[i0:i1], self._d[i0:i1], self._len[i0:i1]
        with np.errstate(over="ignore", invalid="ignore"):  # a point too far off for float arithmetic: an infinite distance
            t = np.einsum("ij,ij->i", p - a, d) / ln**2
            t_lo = np.clip((s_lo - seg_lo) / ln, 0.0, 1.0)
            t_hi = np.clip((s_hi - seg_lo) / ln, 0.0, 1.0)
            t = np.clip(t, t_lo, t_hi)
            foot = a + t[:, None] * d
            dist = np.linalg.norm(p - foot, axis=1)
            k = int(np.argmin(dist))
            cross = d[k, 0] * (p[1] - a[k, 1]) - d[k, 1] * (p[0] - a[k, 0])
        return float(seg_lo[k] + t[k] * ln[k]), float(np.copysign(dist[k], cross))

    def _project_scalar(self, px: float, py: float, s_lo: float, s_hi: float, i0: int, i1: int) -> tuple[float, float] | None:
        """:meth:`project` over segments i0..i1-1 in plain floats, the same arithmetic in the
        same order (a control-loop window holds a few segments, where NumPy's per-call cost
        dominates); None where no distance is finite (a point so far off that the arithmetic
        overflows), which NumPy's form answers."""
        best, k = math.inf, -1
        for i in range(i0, i1):
            ax, ay = self._a_list[i]
            dx, dy = self._d_list[i]
            ln, lo = self._len_list[i], self._s_list[i]
            t = ((px - ax) * dx + (py - ay) * dy) / ln**2
            t_lo = min(max((s_lo - lo) / ln, 0.0), 1.0)
            t_hi = min(max((s_hi - lo) / ln, 0.0), 1.0)
            t = min(max(t, t_lo), t_hi)
            ex, ey = px - (ax + t * dx), py - (ay + t * dy)
            dist = math.sqrt(ex * ex + ey * ey)
            if dist < best:  # the first of equal distances, as argmin
                best, k, tk = dist, i, t
        if k < 0:
            return None
        ax, ay = self._a_list[k]
        dx, dy = self._d_list[k]
        cross = dx * (py - ay) - dy * (px - ax)
        return self._s_list[k] + tk * self._len_list[k], math.copysign(best, cross)

    def distance_to(self, points: np.ndarray, chunk: int = 4096) -> np.ndarray:
        """Unsigned distance [m] of each point (N, 2) to the whole polyline, shape (N,)."""
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        out = np.empty(len(pts))
        for i in range(0, len(pts), chunk):
            p = pts[i : i + chunk, None, :]
            t = np.clip(np.einsum("nmj,mj->nm", p - self._a, self._d) / self._len**2, 0.0, 1.0)
            foot = self._a + t[..., None] * self._d
            out[i : i + chunk] = np.linalg.norm(p - foot, axis=-1).min(axis=1)
        return out


class PathTracker:
    """Progress along a path for a moving vehicle: each update searches only a window round the
    previous progress, so a path that passes near itself, or behind the vehicle, cannot capture it.

    Args:
        path: the reference path.
        back_m, ahead_m: search window behind and ahead of the previous progress [m].
    """

    def __init__(self, path: ReferencePath, back_m: float = 2.0, ahead_m: float = 8.0) -> None:
        self.path = path
        self.back_m = back_m
        self.ahead_m = ahead_m
        self.s: float | None = None
        self.lateral_m = 0.0  # signed offset of the last update's point from the path, left positive [m]

    def reset(self) -> None:
        self.s = None
        self.lateral_m = 0.0

    def update(self, xy: np.ndarray, ahead_m: float | None = None) -> float:
        """New progress [m] for the vehicle at ``xy``; it never moves backwards.

        ``ahead_m`` widens the search ahead for this update (after a gap in the frames, when
        the vehicle may have gone further than ``self.ahead_m``).
        """
        if self.s is None:  # first fix: the nearest point of the whole path
            self.s, self.lateral_m = self.path.project(xy)
        else:
            ahead = self.ahead_m if ahead_m is None else max(self.ahead_m, ahead_m)
            s, self.lateral_m = self.path.project(xy, self.s - self.back_m, self.s + ahead)
            self.s = max(self.s, s)
        return self.s
