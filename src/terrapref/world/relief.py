"""The height field of a scenario's relief (SPEC 19): z [m], up, on the world's grid.

Each entry of the ``relief:`` block adds its height at every cell centre, in the block's order,
in float64; the sum is kept as float32. An entry is evaluated only over the cells it reaches
(its bounds), so a mound costs its own area, not the map's. Noise is OpenSimplex noise
(``opensimplex``), evaluated at every cell centre in float64: the same bits on any machine for
one seed (a 2000 x 2000 grid takes a few tenths of a second).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from terrapref.scenario.relief import Mound, Noise, Plateau, ReliefEntry, Ridge


def height_field(
    relief: Sequence[ReliefEntry], grid_shape: tuple[int, int], resolution_m: float, part: tuple[slice, slice] | None = None
) -> np.ndarray:
    """The ground's height at every cell centre, shape ``grid_shape`` (ny, nx) float32 [m]:
    the entries of ``relief`` added in order to flat ground (z = 0). ``part``: only the cells of
    these rows and columns (slices within the grid), each the same value as in the whole field."""
    ny, nx = grid_shape
    rows_in, cols_in = part if part is not None else (slice(0, ny), slice(0, nx))
    z = np.zeros((rows_in.stop - rows_in.start, cols_in.stop - cols_in.start), dtype=np.float64)
    for entry in relief:
        if isinstance(entry, Noise) and entry.polygon is None:
            x, y = (
                (np.arange(cols_in.start, cols_in.stop) + 0.5) * resolution_m,
                (np.arange(rows_in.start, rows_in.stop) + 0.5) * resolution_m,
            )
            z += noise_height(entry, x, y)
            continue
        window = _window(entry.bounds(), grid_shape, resolution_m)
        if window is None:
            continue
        rows = slice(max(window[0].start, rows_in.start), min(window[0].stop, rows_in.stop))
        cols = slice(max(window[1].start, cols_in.start), min(window[1].stop, cols_in.stop))
        if rows.start >= rows.stop or cols.start >= cols.stop:
            continue
        x = ((np.arange(cols.start, cols.stop) + 0.5) * resolution_m)[None, :]
        y = ((np.arange(rows.start, rows.stop) + 0.5) * resolution_m)[:, None]
        with np.errstate(over="ignore", invalid="ignore"):  # far-off vertices: distances beyond the float range are simply far
            z[rows.start - rows_in.start : rows.stop - rows_in.start, cols.start - cols_in.start : cols.stop - cols_in.start] += (
                _entry_height(entry, x, y)
            )
    return z.astype(np.float32)


def _entry_height(entry: Noise | Mound | Ridge | Plateau, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The height one entry adds at the cell centres ``x`` (1, n) and ``y`` (m, 1) [m], shape (m, n)."""
    if isinstance(entry, Noise):  # on a patch: faded in over one wavelength inside the polygon's edge
        gx, gy = np.broadcast_arrays(x, y)
        inside = entry.polygon.contains(np.stack([gx.ravel(), gy.ravel()], axis=1)).reshape(gx.shape)
        fade = np.clip(_polyline_distance(entry.polygon.vertices, x, y, closed=True) / entry.wavelength_m, 0.0, 1.0)
        return np.where(inside, fade, 0.0) * noise_height(entry, x[0], y[:, 0])
    if isinstance(entry, Mound):
        d = np.hypot(x - entry.center[0], y - entry.center[1])
        return _cosine(d, entry.radius_m, entry.height_m)
    if isinstance(entry, Ridge):
        d = _polyline_distance(entry.polyline, x, y, closed=False)
        return _cosine(d, entry.width_m / 2, entry.height_m)
    gx, gy = np.broadcast_arrays(x, y)
    inside = entry.polygon.contains(np.stack([gx.ravel(), gy.ravel()], axis=1)).reshape(gx.shape)
    if entry.edge_m <= 0:  # a ledge: the polygon's cells raised, no others
        return np.where(inside, entry.height_m, 0.0)
    d = _polyline_distance(entry.polygon.vertices, x, y, closed=True)
    ramp = entry.height_m * np.clip(1.0 - d / entry.edge_m, 0.0, 1.0)  # straight down over edge_m outside
    return np.where(inside, entry.height_m, ramp)


def _cosine(d: np.ndarray, reach_m: float, height_m: float) -> np.ndarray:
    """``height_m`` at distance 0, half of it at ``reach_m / 2``, 0 from ``reach_m`` on (a raised
    cosine: its slope is 0 at the top and at the foot, so the ground has no crease)."""
    return np.where(d < reach_m, height_m * 0.5 * (1.0 + np.cos(np.pi * np.minimum(d / reach_m, 1.0))), 0.0)


def _polyline_distance(vertices: np.ndarray, x: np.ndarray, y: np.ndarray, closed: bool) -> np.ndarray:
    """The distance [m] from the points (x (1, n), y (m, 1)) to a polyline's segments (``closed``:
    the last vertex joined to the first), shape (m, n)."""
    ends = np.roll(vertices, -1, axis=0) if closed else vertices[1:]
    best = np.full(np.broadcast_shapes(x.shape, y.shape), np.inf)
    for (ax, ay), (bx, by) in zip(vertices, ends):
        dx, dy = bx - ax, by - ay
        length2 = dx * dx + dy * dy
        t = 0.0 if length2 == 0 else np.clip(((x - ax) * dx + (y - ay) * dy) / length2, 0.0, 1.0)
        np.minimum(best, (x - ax - t * dx) ** 2 + (y - ay - t * dy) ** 2, out=best)
    return np.sqrt(best)


def noise_height(noise: Noise, x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
    """The height [m] ``noise`` adds at the grid of points ``x_m`` (n,) by ``y_m`` (m,), shape
    (m, n) float64; a point's value does not depend on the other points asked."""
    import numba
    from opensimplex import OpenSimplex  # only a scenario with noise needs it

    # opensimplex's arrays are compiled parallel loops; Numba's default threading layer there is
    # GNU OpenMP, after which a forked worker (the local grid's) aborts. Numba's own work queue is
    # fork safe, and the noise is the same bits whichever layer computes it.
    if numba.config.THREADING_LAYER == "default":
        numba.config.THREADING_LAYER = "workqueue"
    grid = OpenSimplex(noise.seed).noise2array(
        np.asarray(x_m, dtype=np.float64) / noise.wavelength_m, np.asarray(y_m, dtype=np.float64) / noise.wavelength_m
    )
    return noise.amplitude_m * grid


def _window(bounds: tuple[float, float, float, float], grid_shape: tuple[int, int], resolution_m: float) -> tuple[slice, slice] | None:
    """The rows and columns of the cells whose centres may lie within ``bounds`` (x0, y0, x1, y1)
    [m], or None where none do."""
    ny, nx = grid_shape
    x0, y0, x1, y1 = (
        float(np.clip(v, -resolution_m, lim + resolution_m)) for v, lim in zip(bounds, (nx * resolution_m, ny * resolution_m) * 2)
    )
    c0, c1 = max(0, math.floor(x0 / resolution_m)), min(nx, math.ceil(x1 / resolution_m) + 1)
    r0, r1 = max(0, math.floor(y0 / resolution_m)), min(ny, math.ceil(y1 / resolution_m) + 1)
    if c0 >= c1 or r0 >= r1:
        return None
    return slice(r0, r1), slice(c0, c1)
