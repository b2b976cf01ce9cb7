"""Shapes, rasterisation and the reference path, checked against brute force and closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from terrapref.scenario import Circle, Polygon, Rectangle, parse_scenario
from terrapref.scenario.model import grid_shape
from terrapref.scenario.path import PathTracker, ReferencePath
from terrapref.terrain import UNKNOWN, default_classes
from terrapref.world import WorldMap, rasterise
from terrapref.world.raster import paint

RES = 0.1
MAP_W, MAP_H = 6.0, 5.0
CLASSES = default_classes()
GRASS, WATER, ROCK, MUD = (CLASSES.id_of(n) for n in ("grass", "water", "rock", "mud"))

# Concave (an arrow head pointing +x) with vertices in general position, so no cell centre
# lies exactly on an edge and the inside test has one right answer for every cell.
CONCAVE = [[0.53, 0.41], [4.87, 2.46], [0.61, 4.38], [2.07, 2.51]]
TRIANGLE = [[1.03, 0.52], [5.41, 1.07], [2.96, 4.13]]


def _inside_polygon(x: float, y: float, vertices: list[list[float]]) -> bool:
    """Independent point-in-polygon by winding number (plain Python, one point at a time)."""
    winding = 0
    n = len(vertices)
    for k in range(n):
        (x0, y0), (x1, y1) = vertices[k], vertices[(k + 1) % n]
        side = (x1 - x0) * (y - y0) - (x - x0) * (y1 - y0)
        if y0 <= y < y1 and side > 0:
            winding += 1
        elif y1 <= y < y0 and side < 0:
            winding -= 1
    return winding != 0


def _brute_force(shape_test, shape_hw: tuple[int, int] = grid_shape((MAP_W, MAP_H), RES), res: float = RES) -> np.ndarray:
    """Mask of cells whose centre passes ``shape_test(x, y)``, one cell at a time."""
    ny, nx = shape_hw
    mask = np.zeros((ny, nx), dtype=bool)
    for r in range(ny):
        for c in range(nx):
            mask[r, c] = shape_test((c + 0.5) * res, (r + 0.5) * res)
    return mask


def _painted(shape, class_id: int = MUD) -> np.ndarray:
    raster = np.full(grid_shape((MAP_W, MAP_H), RES), GRASS, dtype=np.uint8)
    paint(raster, shape, class_id, RES)
    return raster == class_id


def _rect_corners(center, size, yaw_rad) -> list[list[float]]:
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    hx, hy = size[0] / 2, size[1] / 2
    return [[center[0] + c * lx - s * ly, center[1] + s * lx + c * ly] for lx, ly in ((-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy))]


def _scenario(terrain: list[dict], size=(MAP_W, MAP_H), resolution=RES):
    return parse_scenario(
        {
            "format": "terrapref-scenario/1",
            "name": "tiny",
            "world": {"size_m": list(size), "resolution_m": resolution, "background": "grass"},
            "terrain": terrain,
            "path": {"waypoints": [[0.5, 0.5], [size[0] - 0.5, size[1] - 0.5]]},
        }
    )


# --- shapes -----------------------------------------------------------------------------------


@pytest.mark.parametrize("vertices", [TRIANGLE, CONCAVE], ids=["triangle", "concave"])
def test_polygon_paints_exactly_the_cells_whose_centres_are_inside(vertices):
    expected = _brute_force(lambda x, y: _inside_polygon(x, y, vertices))
    got = _painted(Polygon(np.array(vertices)))
    assert 50 < expected.sum() < expected.size - 50  # the case is not trivial
    np.testing.assert_array_equal(got, expected)


def test_concave_polygon_leaves_its_notch_unpainted():
    got = _painted(Polygon(np.array(CONCAVE)))
    # (1.2, 2.5) lies in the notch between the arrow's barbs: outside; (3.0, 2.5) is inside.
    assert not got[int(2.5 / RES), int(1.2 / RES)]
    assert got[int(2.5 / RES), int(3.0 / RES)]


def test_circle_paints_exactly_the_cells_whose_centres_are_inside():
    center, r = (2.93, 2.41), 1.57
    expected = _brute_force(lambda x, y: (x - center[0]) ** 2 + (y - center[1]) ** 2 <= r * r)
    np.testing.assert_array_equal(_painted(Circle(center, r)), expected)
    # Area check: the painted cells approximate pi r^2.
    assert abs(expected.sum() * RES**2 - math.pi * r * r) < 0.05 * math.pi * r * r


@pytest.mark.parametrize("yaw_deg", [0.0, 17.0, 45.0, -70.0, 123.0])
def test_rotated_rectangle_paints_exactly_the_cells_whose_centres_are_inside(yaw_deg):
    center, size = (3.04, 2.47), (3.3, 1.7)
    corners = _rect_corners(center, size, math.radians(yaw_deg))
    expected = _brute_force(lambda x, y: _inside_polygon(x, y, corners))
    got = _painted(Rectangle(center, size, math.radians(yaw_deg)))
    np.testing.assert_array_equal(got, expected)
    assert abs(expected.sum() * RES**2 - size[0] * size[1]) < 0.1 * size[0] * size[1]


def test_rectangle_corners_are_counter_clockwise_and_rotated():
    rect = Rectangle((1.0, 2.0), (4.0, 2.0), math.radians(90.0))
    np.testing.assert_allclose(rect.corners(), [[2.0, 0.0], [2.0, 4.0], [0.0, 4.0], [0.0, 0.0]], atol=1e-12)
    x0, y0, x1, y1 = rect.bounds()
    assert (x0, y0, x1, y1) == pytest.approx((0.0, 0.0, 2.0, 4.0))


def test_shape_contains_is_vectorised_over_points():
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [3.0, 0.0]])
    assert Circle((0.0, 0.0), 1.0).contains(pts).tolist() == [True, True, False]
    assert Rectangle((0.0, 0.0), (2.0, 1.0)).contains(pts).tolist() == [True, True, False]
    assert Polygon(np.array([[-1.0, -1.0], [2.0, -1.0], [2.0, 1.0], [-1.0, 1.0]])).contains(pts).tolist() == [True, True, False]


# --- rasterisation ----------------------------------------------------------------------------


def test_rasterise_paints_each_shape_type_from_a_scenario():
    scenario = _scenario(
        [
            {"class": "water", "polygon": CONCAVE},
            {"class": "rock", "circle": {"center": [4.63, 1.12], "radius": 0.77}},
            {"class": "mud", "rectangle": {"center": [4.42, 3.81], "size": [1.6, 0.9], "yaw_deg": 30.0}},
        ]
    )
    world = rasterise(scenario)
    assert world.raster.shape == (50, 60) and world.raster.dtype == np.uint8
    assert world.size_m == pytest.approx((MAP_W, MAP_H))
    corners = _rect_corners((4.42, 3.81), (1.6, 0.9), math.radians(30.0))

    def expected_class(x: float, y: float) -> int:
        cls = GRASS
        if _inside_polygon(x, y, CONCAVE):
            cls = WATER
        if (x - 4.63) ** 2 + (y - 1.12) ** 2 <= 0.77**2:
            cls = ROCK
        if _inside_polygon(x, y, corners):
            cls = MUD
        return cls

    expected = np.zeros(world.raster.shape, dtype=np.uint8)
    for r in range(expected.shape[0]):
        for c in range(expected.shape[1]):
            expected[r, c] = expected_class((c + 0.5) * RES, (r + 0.5) * RES)
    np.testing.assert_array_equal(world.raster, expected)
    assert {GRASS, WATER, ROCK, MUD} <= set(np.unique(world.raster).tolist())


def test_later_shapes_paint_over_earlier_ones():
    mud_square = {"class": "mud", "rectangle": {"center": [2.0, 2.5], "size": [2.0, 2.0]}}
    rock_disc = {"class": "rock", "circle": {"center": [3.0, 2.5], "radius": 1.0}}
    overlap = (int(2.5 / RES), int(2.75 / RES))  # inside both shapes
    mud_only, rock_only = (int(2.5 / RES), int(1.25 / RES)), (int(2.5 / RES), int(3.75 / RES))

    first = rasterise(_scenario([mud_square, rock_disc])).raster
    second = rasterise(_scenario([rock_disc, mud_square])).raster
    assert first[overlap] == ROCK and second[overlap] == MUD
    assert first[mud_only] == second[mud_only] == MUD
    assert first[rock_only] == second[rock_only] == ROCK


def test_cells_off_the_map_are_ignored():
    # A disc round the map's lower-left corner and a rectangle overhanging the top-right corner.
    scenario = _scenario(
        [
            {"class": "water", "circle": {"center": [0.21, 0.33], "radius": 1.13}},
            {"class": "rock", "rectangle": {"center": [5.8, 4.9], "size": [1.4, 1.0], "yaw_deg": 10.0}},
        ]
    )
    world = rasterise(scenario)
    corners = _rect_corners((5.8, 4.9), (1.4, 1.0), math.radians(10.0))
    np.testing.assert_array_equal(world.raster == WATER, _brute_force(lambda x, y: (x - 0.21) ** 2 + (y - 0.33) ** 2 <= 1.13**2))
    np.testing.assert_array_equal(world.raster == ROCK, _brute_force(lambda x, y: _inside_polygon(x, y, corners)))


def test_paint_of_a_shape_wholly_off_the_map_changes_nothing():
    raster = np.full((50, 60), GRASS, dtype=np.uint8)
    for shape in (Circle((-3.0, 2.0), 1.0), Rectangle((10.0, 2.0), (1.0, 1.0)), Polygon(np.array([[1.0, 7.0], [2.0, 7.0], [1.5, 8.0]]))):
        paint(raster, shape, MUD, RES)
    assert (raster == GRASS).all()


def test_world_map_class_at_and_off_map_unknown():
    raster = np.zeros((4, 6), dtype=np.uint8)
    raster[1, 2] = MUD  # covers x in [1.0, 1.5), y in [0.5, 1.0) at 0.5 m cells
    world = WorldMap(raster, 0.5, CLASSES)
    pts = np.array([[1.2, 0.7], [1.0, 0.5], [1.5, 0.7], [0.1, 0.1], [-0.01, 1.0], [3.0, 1.0], [1.0, 2.0], [1.0, -1e-9]])
    assert world.class_at(pts).tolist() == [MUD, MUD, GRASS, GRASS, UNKNOWN, UNKNOWN, UNKNOWN, UNKNOWN]
    assert world.class_at(np.array([1.2, 0.7])) == MUD  # a single point works too
    assert world.class_at(pts.reshape(2, 4, 2)).shape == (2, 4)
    odd = np.array([[math.nan, 1.0], [1.0, math.inf], [-math.inf, 0.7], [1e300, 0.7], [1.2, -1e300], [2.9999999, 1.9999999]])
    assert world.class_at(odd[:5]).tolist() == [UNKNOWN] * 5  # non-finite and huge: off the map on every CPU
    for x, y in np.concatenate([pts, odd]):  # the simulator's one point at a time: the same classes
        assert world.class_at_point(float(x), float(y)) == world.class_at(np.array([x, y]))


@settings(max_examples=300, derandomize=True, deadline=None, database=None)
@given(st.floats(-1.0, 4.0, allow_nan=False), st.floats(-1.0, 3.0, allow_nan=False), st.sampled_from([0.05, 0.1, 0.3, 0.5]))
def test_class_at_point_is_class_at(x, y, resolution):
    raster = np.arange(4 * 6, dtype=np.uint8).reshape(4, 6) * 7
    world = WorldMap(raster, resolution, CLASSES)
    assert world.class_at_point(x, y) == world.class_at(np.array([x, y]))
    x32, y32 = np.float32(x), np.float32(y)  # NumPy scalars: divided in float64, as class_at does
    assert world.class_at_point(x32, y32) == world.class_at(np.array([x32, y32]))


@settings(max_examples=300, derandomize=True, deadline=None, database=None)
@given(
    st.floats(-2.0, 6.0, allow_nan=False),
    st.floats(-2.0, 5.0, allow_nan=False),
    st.floats(0.0, 4.0, allow_nan=False),
    st.sampled_from([0.1, 0.25, 0.5]),
    st.integers(0, 2**32 - 1),
)
def test_lethal_within_is_any_lethal_cell_centre_within_the_radius(x, y, radius, resolution, seed):
    lethal = CLASSES.lethal_ids[0]
    raster = np.where(np.random.default_rng(seed).random((12, 10)) < 0.03, lethal, GRASS).astype(np.uint8)
    world = WorldMap(raster, resolution, CLASSES)
    rows, cols = np.nonzero(raster == lethal)
    centres = np.stack([(cols + 0.5) * resolution, (rows + 0.5) * resolution], axis=1)
    expected = bool(len(centres)) and bool((np.hypot(centres[:, 0] - x, centres[:, 1] - y) <= radius).any())
    if len(centres) and abs(np.hypot(centres[:, 0] - x, centres[:, 1] - y).min() - radius) < 1e-9:
        return  # a centre on the circle itself: either answer is the rounding's
    assert world.lethal_within(x, y, radius) == expected


def test_grid_shape_is_exact_for_decimal_resolutions():
    assert grid_shape((100.0, 100.0), 0.05) == (2000, 2000)
    assert grid_shape((120.0, 80.0), 0.05) == (1600, 2400)
    assert grid_shape((1.01, 0.3), 0.1) == (3, 11)  # a partial cell still gets a column


# --- reference path ---------------------------------------------------------------------------


def test_arc_length_and_point_at():
    path = ReferencePath(np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 4.0], [3.0, 10.0]]))  # a repeated point
    assert len(path.waypoints) == 3
    assert path.length_m == pytest.approx(11.0)
    np.testing.assert_allclose(path.s, [0.0, 5.0, 11.0])
    np.testing.assert_allclose(path.point_at(2.5), [1.5, 2.0])
    np.testing.assert_allclose(path.point_at(5.0), [3.0, 4.0])
    np.testing.assert_allclose(path.point_at(8.0), [3.0, 7.0])
    np.testing.assert_allclose(path.point_at(np.array([-1.0, 11.0, 99.0])), [[0.0, 0.0], [3.0, 10.0], [3.0, 10.0]])
    assert path.point_at(np.zeros((2, 3))).shape == (2, 3, 2)
    np.testing.assert_allclose(path.heading_at(np.array([1.0, 6.0])), [math.atan2(4.0, 3.0), math.pi / 2])


def test_straight_between_gives_the_segment_both_ends_share():
    path = ReferencePath(np.array([[0.0, 0.0], [3.0, 4.0], [3.0, 10.0]]))
    x, y, ux, uy = path.straight_between(1.0, 4.0)
    np.testing.assert_allclose([x, y, ux, uy], [0.6, 0.8, 0.6, 0.8])
    for s in (1.0, 2.5, 4.0):  # the same points as point_at along the segment
        np.testing.assert_allclose([x + (s - 1.0) * ux, y + (s - 1.0) * uy], path.point_at(s))
    assert path.straight_between(4.0, 6.0) is None  # across the corner at s = 5
    assert path.straight_between(10.0, 12.0) is None  # past the end
    assert path.straight_between(-1.0, 1.0) is None  # before the start


def test_project_gives_arc_length_and_signed_offset():
    path = ReferencePath(np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]]))
    assert path.project(np.array([4.0, 1.5])) == pytest.approx((4.0, 1.5))  # left of +x: positive
    assert path.project(np.array([4.0, -2.0])) == pytest.approx((4.0, -2.0))
    assert path.project(np.array([12.0, 6.0])) == pytest.approx((16.0, -2.0))  # right of +y: negative
    assert path.project(np.array([-3.0, 4.0])) == pytest.approx((0.0, 5.0))  # before the start: the end point
    s, off = path.project(np.array([11.0, -1.0]))  # outside the corner: the corner, sqrt(2) away
    assert s == pytest.approx(10.0) and abs(off) == pytest.approx(math.sqrt(2.0))


def test_project_window_stops_a_path_that_loops_back_from_capturing_it():
    # Out along y = 0, back along y = 2: a point at y = 1.2 is nearer the return leg.
    path = ReferencePath(np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 2.0], [0.0, 2.0]]))
    s_free, off_free = path.project(np.array([2.0, 1.2]))
    assert s_free == pytest.approx(20.0) and off_free == pytest.approx(0.8)  # captured by the return leg
    s_win, off_win = path.project(np.array([2.0, 1.2]), 0.0, 5.0)
    assert s_win == pytest.approx(2.0) and off_win == pytest.approx(1.2)
    # The window clips inside a segment too: the nearest allowed point is its end.
    assert path.project(np.array([8.0, 0.3]), 0.0, 5.0) == pytest.approx((5.0, math.hypot(3.0, 0.3)))
    # And on the way back, a window round s = 20 finds the return leg.
    assert path.project(np.array([2.0, 0.9]), 15.0, 25.0) == pytest.approx((20.0, 1.1))


def test_tracker_keeps_the_offset_of_its_last_fix():
    tracker = PathTracker(ReferencePath(np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]])))
    assert tracker.update(np.array([4.0, 1.5])) == pytest.approx(4.0) and tracker.lateral_m == pytest.approx(1.5)
    assert tracker.update(np.array([6.0, -0.5])) == pytest.approx(6.0) and tracker.lateral_m == pytest.approx(-0.5)
    # Progress never moves back; the offset is still that of the nearest point in the window.
    assert tracker.update(np.array([5.5, 2.0])) == pytest.approx(6.0) and tracker.lateral_m == pytest.approx(2.0)
    tracker.reset()
    assert tracker.s is None and tracker.lateral_m == 0.0


def test_project_in_plain_floats_and_in_numpy_agree_exactly(monkeypatch):
    # Short windows are searched in plain floats, long ones with NumPy: the same arithmetic,
    # so the same progress to the last bit (the closed loop's decisions depend on it).
    import terrapref.scenario.path as path_module

    rng = np.random.default_rng(3)
    path = ReferencePath(np.cumsum(rng.normal(size=(120, 2)), axis=0))  # winds and nears itself
    queries = []
    for _ in range(400):
        xy = rng.uniform(path.waypoints.min(0) - 2, path.waypoints.max(0) + 2)
        c = rng.uniform(-3, path.length_m + 3)
        lo, hi = [(-np.inf, np.inf), (c - 2.0, c + 8.0), (c, c), (path.length_m + 1, path.length_m + 5)][rng.integers(4)]
        queries.append((xy, lo, hi))
    scalar = [path.project(xy, lo, hi) for xy, lo, hi in queries]
    monkeypatch.setattr(path_module, "_SCALAR_SEGMENTS", 10**9)
    assert [path.project(xy, lo, hi) for xy, lo, hi in queries] == scalar  # every window in plain floats
    monkeypatch.setattr(path_module, "_SCALAR_SEGMENTS", 0)
    assert [path.project(xy, lo, hi) for xy, lo, hi in queries] == scalar  # every window in NumPy
    # A non-finite point or a NaN bound gives NumPy's answer (NaN progress), whatever the window.
    odd = [(np.array([np.nan, 1.0]), 5.0, 15.0), (np.array([np.inf, 1.0]), 5.0, 15.0), (np.array([1.0, 1.0]), np.nan, np.nan)]
    in_numpy = [repr(path.project(xy, lo, hi)) for xy, lo, hi in odd]
    monkeypatch.setattr(path_module, "_SCALAR_SEGMENTS", 10**9)
    assert [repr(path.project(xy, lo, hi)) for xy, lo, hi in odd] == in_numpy
    assert "nan" in in_numpy[0] and "nan" in in_numpy[2]
    assert any(0 < len([1 for k in range(119) if path.s[k + 1] >= lo and path.s[k] <= hi]) <= 24 for _, lo, hi in queries)


def test_distance_to_matches_brute_force():
    rng = np.random.default_rng(1)
    wp = np.array([[0.0, 0.0], [5.0, 1.0], [6.0, 6.0], [1.0, 4.0]])
    path = ReferencePath(wp)
    pts = rng.uniform(-3.0, 9.0, (300, 2))

    def seg_dist(p, a, b):
        t = min(1.0, max(0.0, float(np.dot(p - a, b - a) / np.dot(b - a, b - a))))
        return float(np.linalg.norm(p - (a + t * (b - a))))

    expected = [min(seg_dist(p, wp[k], wp[k + 1]) for k in range(len(wp) - 1)) for p in pts]
    np.testing.assert_allclose(path.distance_to(pts, chunk=64), expected, atol=1e-12)
    assert path.distance_to(np.array([5.0, 1.0])) == pytest.approx([0.0])
    # Consistent with project(): |offset| is the distance.
    for p in pts[:20]:
        assert abs(path.project(p)[1]) == pytest.approx(path.distance_to(p)[0])
