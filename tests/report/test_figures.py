"""Figures a person reads at a glance: the map's zone labels, its legend and marks."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402

from terrapref.plots import draw_map, save_loss_curve  # noqa: E402
from terrapref.scenario import resolve_scenario  # noqa: E402
from terrapref.world import rasterise  # noqa: E402


def _overlap(a, b) -> float:
    return max(0.0, min(a.x1, b.x1) - max(a.x0, b.x0)) * max(0.0, min(a.y1, b.y1) - max(a.y0, b.y0))


@pytest.mark.parametrize(
    "name", [pytest.param("teach_course", marks=pytest.mark.slow), "train_course", "demo_course"]
)  # the teaching course's many zones take the longest; the two others run by default
def test_zone_labels_do_not_overlap_and_the_legend_stays_off_the_map(name):
    scenario = resolve_scenario(name)
    fig, ax = plt.subplots(figsize=(11.5, 6), dpi=120)
    handles = draw_map(ax, scenario, rasterise(scenario))
    legend = ax.legend(handles=handles + ax.get_legend_handles_labels()[0], loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    boxes = [t.get_window_extent(renderer) for t in ax.texts if t.get_text()]  # the start arrow is an empty annotation
    assert len(boxes) == len(scenario.zones)
    crowded = [
        (i, j)
        for i in range(len(boxes))
        for j in range(i)
        if _overlap(boxes[i], boxes[j]) > 0.1 * min(boxes[i].width * boxes[i].height, boxes[j].width * boxes[j].height)
    ]
    assert not crowded, crowded
    assert _overlap(legend.get_window_extent(renderer), ax.get_window_extent(renderer)) == 0.0
    assert "reference path" in [t.get_text() for t in legend.get_texts()]
    plt.close(fig)


def test_a_missed_zone_is_marked_with_what_was_expected_and_chosen():
    scenario = resolve_scenario("demo_course")
    fig, ax = plt.subplots()
    zone = scenario.zones[0]
    draw_map(ax, scenario, rasterise(scenario), marks={zone.id: "missed: expected avoid, drove water"})
    marked = [t for t in ax.texts if "missed: expected avoid, drove water" in t.get_text().replace("\n", " ")]  # wrapped beside its zone
    assert len(marked) == 1 and marked[0].get_text().startswith(zone.id) and marked[0].get_color() == "red"
    plt.close(fig)


def test_the_loss_plot_draws_every_member(tmp_path):
    history = [
        {"epoch": e, "train_loss": 2.0 / e, "val_loss": 2.1 / e, "train_acc": 0.1 * e, "val_acc": 0.09 * e, "val_top3": 0.2 * e}
        for e in (1, 2, 3)
    ]
    captured = {}
    real_close = plt.close

    def keep(fig):
        captured["fig"] = fig
        return real_close(fig)

    plt.close = keep
    try:
        save_loss_curve(tmp_path / "loss.png", [(history, 3), (history, 2), (history, 1)], title="t")
    finally:
        plt.close = real_close
    loss_ax = captured["fig"].axes[0]
    assert len(loss_ax.lines) == 3 * 3  # train, validation and the chosen epoch of each member
    assert [t.get_text() for t in loss_ax.get_legend().get_texts()][:3] == [
        f"member {j}: epoch {e} chosen" for j, e in ((1, 3), (2, 2), (3, 1))
    ]
    assert (tmp_path / "loss.png").stat().st_size > 10_000


def _kept_figure(monkeypatch) -> dict:
    """The next figure a save_* function draws, kept for the test when the function closes it."""
    captured: dict = {}
    real_close = plt.close

    def keep(fig):
        captured["fig"] = fig
        return real_close(fig)

    monkeypatch.setattr(plt, "close", keep)
    return captured


def test_a_zone_label_stays_beside_its_zone_however_long():
    from terrapref.scenario.shapes import outline

    scenario = resolve_scenario("teach_course")  # labels such as "rock | mud | water" beside small zones
    fig, ax = plt.subplots(figsize=(11.5, 6), dpi=120)
    draw_map(ax, scenario, rasterise(scenario))
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    for text, zone in zip([t for t in ax.texts if t.get_text()], scenario.zones, strict=True):
        box = text.get_window_extent(renderer)
        (x0, y0), (x1, y1) = (
            ax.transData.transform(outline(zone.shape)).min(axis=0),
            ax.transData.transform(outline(zone.shape)).max(axis=0),
        )
        farthest = max(
            max(abs(x - min(max(x, x0), x1)) for x in (box.x0, box.x1)), max(abs(y - min(max(y, y0), y1)) for y in (box.y0, box.y1))
        )
        assert farthest < 120, (zone.id, text.get_text(), farthest)  # pixels: a wrapped label's width, not a line across the map
    plt.close(fig)


def test_the_legend_lists_only_the_classes_on_the_map():
    scenario = resolve_scenario("fig7_rock_vs_non_traversable_left")  # rock and trees on grass: no water, no mud
    fig, ax = plt.subplots()
    names = [h.get_label() for h in draw_map(ax, scenario, rasterise(scenario))]
    assert names == ["grass", "non_traversable", "rock"]
    plt.close(fig)


def test_non_latin_and_very_long_class_names_draw_without_warnings_or_boxes(tmp_path, recwarn):
    import warnings

    from terrapref.plots import LONGEST_NAME, save_map
    from terrapref.scenario import parse_scenario
    from terrapref.terrain import ClassTable

    long_name = "a_very_long_class_name_that_goes_on_and_on"
    table = ClassTable.from_dict(
        {
            "format": "terrapref-classes/1",
            "background": "grass",
            "lethal": ["tree"],
            "profile": ["泥地", long_name, "tree"],
            "classes": [
                {"id": 0, "name": "grass", "color": [92, 158, 70]},
                {"id": 1, "name": "泥地", "color": [112, 72, 36]},
                {"id": 2, "name": long_name, "color": [150, 150, 150]},
                {"id": 3, "name": "tree", "color": [20, 70, 20]},
            ],
        },
        "table.yaml",
    )
    scenario = parse_scenario(
        {
            "format": "terrapref-scenario/1",
            "name": "t",
            "world": {"size_m": [20, 10], "resolution_m": 0.1, "background": "grass"},
            "terrain": [
                {"class": "泥地", "circle": {"center": [6, 5], "radius": 1}},
                {"class": long_name, "circle": {"center": [12, 5], "radius": 1}},
            ],
            "path": {"waypoints": [[1, 5], [19, 5]]},
            "zones": [{"id": "1", "label": f"泥地 vs {long_name}", "circle": {"center": [9, 5], "radius": 4}, "expect": "best"}],
        },
        "t.yaml",
        table,
    )
    warnings.simplefilter("always")
    kept = {}
    real_close = plt.close
    plt.close = lambda fig: (kept.setdefault("fig", fig), real_close(fig))
    try:
        save_map(tmp_path / "map.png", scenario, rasterise(scenario))
    finally:
        plt.close = real_close
    assert [str(w.message) for w in recwarn] == []  # matplotlib's "Glyph ... missing from font(s)" names its source files
    ax = kept["fig"].axes[0]
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "class 1" in legend and long_name[: LONGEST_NAME - 1] + "\u2026" in legend
    assert all(len(line) <= 30 for t in ax.texts for line in t.get_text().splitlines())
    assert "class 1" in " ".join(t.get_text() for t in ax.texts)


def test_the_route_is_drawn_wide_beneath_the_dashed_path(tmp_path, monkeypatch):
    import numpy as np

    from terrapref.plots import save_map

    scenario = resolve_scenario("demo_course")
    kept = _kept_figure(monkeypatch)
    save_map(
        tmp_path / "route.png", scenario, rasterise(scenario), tracks=[("route", scenario.waypoints + np.array([0.0, 0.1]), "tab:blue")]
    )
    lines = {line.get_label(): line for line in kept["fig"].axes[0].lines}
    path, route = lines["reference path"], lines["route"]
    assert route.get_linewidth() >= 2 * path.get_linewidth() and route.get_zorder() < path.get_zorder()


def test_the_evaluation_figure_gives_each_seed_its_colour_and_keeps_its_legend_off_the_map(tmp_path, monkeypatch):
    import numpy as np

    from terrapref.plots import CourseRuns, save_evaluation

    scenario = resolve_scenario("demo_course")
    tracks = [scenario.waypoints + np.array([0.0, dy]) for dy in (0.0, 0.5)]
    kept = _kept_figure(monkeypatch)
    save_evaluation(tmp_path / "ev.png", CourseRuns(scenario, rasterise(scenario), tracks, tracks, {"1": (1, 2)}), "t")
    fig = kept["fig"]
    overview = fig.axes[0]
    planner = [line for line in overview.lines if line.get_linestyle() == "-" and len(line.get_xdata()) == len(scenario.waypoints)]
    assert len({matplotlib.colors.to_hex(line.get_color()) for line in planner}) == 2  # seed 0 and seed 1 apart
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = FigureCanvasAgg(fig)  # the closed figure, drawn again as it was saved
    canvas.draw()
    renderer = canvas.get_renderer()
    legend = overview.get_legend()
    assert _overlap(legend.get_window_extent(renderer), overview.get_window_extent(renderer)) == 0.0
    assert {"seed 0", "seed 1"} <= {t.get_text() for t in legend.get_texts()}


def test_with_one_seed_the_evaluation_legend_shows_the_tracks_in_the_colour_they_are_drawn(tmp_path, monkeypatch):
    from matplotlib.lines import Line2D

    from terrapref.plots import CourseRuns, save_evaluation

    scenario = resolve_scenario("demo_course")
    track = [scenario.waypoints]
    kept = _kept_figure(monkeypatch)
    save_evaluation(tmp_path / "ev.png", CourseRuns(scenario, rasterise(scenario), track, track, {"1": (1, 1)}), "t")
    overview = kept["fig"].axes[0]
    runs = [line for line in overview.lines if line.get_label().startswith("_") and len(line.get_xdata()) == len(track[0])]
    drawn = {line.get_linestyle(): matplotlib.colors.to_hex(line.get_color()) for line in runs}
    handles = [h for h in overview.get_legend().legend_handles if isinstance(h, Line2D)]
    key = {h.get_label(): (h.get_linestyle(), matplotlib.colors.to_hex(h.get_color())) for h in handles}
    assert len(runs) == 2 and key["driver (dashed)"] == ("--", drawn["--"]) and key["planner (solid)"] == ("-", drawn["-"])
    assert not any(label.startswith("seed ") for label in key)


def test_relief_is_drawn_as_hillshade_and_labelled_contours_and_a_flat_map_as_before():
    import numpy as np
    from matplotlib.contour import ContourSet

    flat = resolve_scenario("demo_course")
    hilly = resolve_scenario("relief_demo")
    for scenario, has_relief in ((flat, False), (hilly, True)):
        world = rasterise(scenario)
        fig, ax = plt.subplots()
        names = [h.get_label() for h in draw_map(ax, scenario, world)]
        (image,) = ax.get_images()
        shown = np.asarray(image.get_array())
        contours = [c for c in ax.collections if isinstance(c, ContourSet)]
        if has_relief:
            assert "height contours [m]" in names and len(contours) == 1 and len(contours[0].levels) >= 3
            assert any(t.get_text().endswith(" m") for t in ax.texts)  # the contours' heights
            below = [t.get_text() for t in ax.texts if t.get_text().startswith("\u2212")]
            assert below and not any("-" in t.get_text() for t in ax.texts)  # below zero: a true minus, not a dash
            assert all(dashes is None for _, dashes in contours[0].get_linestyle())  # solid lines below zero too
            flat_colours = scenario.classes.palette()[world.raster] / 255.0
            assert shown.shape == flat_colours.shape and np.abs(shown - flat_colours).max() > 0.1  # shaded
        else:
            assert "height contours [m]" not in names and not contours
            np.testing.assert_array_equal(shown, scenario.classes.palette()[world.raster])  # the class colours, as always
        plt.close(fig)


def test_a_zones_inset_draws_the_ground_within_its_window_alone_as_the_whole_map_draws_it_there():
    """An inset shows the ground within its window alone (12 m of a 70 m world), its pixels those
    the whole map shows there (the relief's shading set by the whole world), and the contours at
    the whole map's levels."""
    import numpy as np
    from matplotlib.contour import ContourSet

    from terrapref.plots import GroundView, ground_picture

    scenario = resolve_scenario("relief_demo")
    world = rasterise(scenario)
    fig, (whole_ax, inset_ax) = plt.subplots(1, 2)
    draw_map(whole_ax, scenario, world, zones=False)
    window = (20.0, 32.0, 10.0, 22.0)
    draw_map(inset_ax, scenario, world, zones=False, view=GroundView(ground_picture(scenario, world), window))
    whole, inset = (np.asarray(ax.get_images()[0].get_array()) for ax in (whole_ax, inset_ax))
    x0, x1, y0, y1 = inset_ax.get_images()[0].get_extent()
    assert x0 <= window[0] and y0 <= window[2] and x1 >= window[1] and y1 >= window[3]
    assert inset.shape[0] * inset.shape[1] < whole.shape[0] * whole.shape[1] / 10
    assert inset_ax.get_xlim() == window[:2] and inset_ax.get_ylim() == window[2:]
    res = world.resolution_m
    r0, c0 = round(y0 / res), round(x0 / res)
    np.testing.assert_array_equal(inset, whole[r0 : r0 + inset.shape[0], c0 : c0 + inset.shape[1]])
    levels = [tuple(c.levels) for ax in (whole_ax, inset_ax) for c in ax.collections if isinstance(c, ContourSet)]
    assert len(levels) == 2 and set(levels[1]) <= set(levels[0])
    plt.close(fig)


def test_the_speed_figure_is_scaled_to_the_speeds_driven(tmp_path, monkeypatch):
    """Speeds under 1 m/s fill the panel (an axis to the vehicle's 2 m/s had squeezed them into its lower half)."""
    import numpy as np

    from terrapref.plots import save_speed_profile

    kept = _kept_figure(monkeypatch)
    s = np.linspace(0.0, 40.0, 50)
    series = [("driver", s, 0.6 + 0.3 * np.sin(s / 5.0), "k"), ("planner", s, np.full(50, 0.7), "tab:red")]
    save_speed_profile(tmp_path / "speed.png", series, "speed", [("mud", 10.0, 15.0)])
    speed = next(a for a in kept["fig"].axes if a.get_ylabel() == "speed [m/s]")
    low, high = speed.get_ylim()
    assert low == 0.0 and 0.9 < high <= 1.1


def test_the_speed_figures_zone_names_stand_above_the_speeds_never_over_them(tmp_path, monkeypatch):
    """Each zone's name, however long, is upright over its stretch in a band of its own: none
    crosses the panels the speeds and heights are drawn in."""
    import numpy as np

    from terrapref.plots import save_speed_profile

    kept = _kept_figure(monkeypatch)
    s = np.linspace(0.0, 200.0, 400)
    series = [("driver", s, 1.0 + 0.3 * np.sin(s / 9.0), "k"), ("planner", s, np.full(400, 1.2), "tab:red")]
    spans = [(f"{k}: mud vs rock on a bank too steep to drive along, with a long label", 15.0 * k, 15.0 * k + 6.0) for k in range(1, 13)]
    save_speed_profile(tmp_path / "speed.png", series, "speed", spans, [np.sin(s / 30.0), np.sin(s / 31.0)])
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = kept["fig"]
    renderer = FigureCanvasAgg(fig).get_renderer()  # closed once saved: drawn again as it was saved
    fig.draw(renderer)
    panels = [a for a in fig.axes if a.get_ylabel()]
    names = [t for a in fig.axes for t in a.texts if t.get_text()]
    assert [a.get_ylabel() for a in panels] == ["speed [m/s]", "ground height [m]"] and len(names) == len(spans)
    for name in names:
        box = name.get_window_extent(renderer)
        assert all(not box.overlaps(a.get_window_extent(renderer)) for a in panels), name.get_text()
        assert box.y0 >= panels[0].get_window_extent(renderer).y1


def test_a_wrapped_zone_label_ends_its_lines_with_the_bar_between_classes():
    """A label of classes broken across lines keeps each `|` at the end of a line, on the map and
    over the speed figure's zone stretches, never at the start of the next."""
    import textwrap

    from terrapref import plots

    label = "3: non_traversable | water | mud"
    assert plots._wrapped(label) == "3: non_traversable | water |\nmud"
    assert plots._bars_at_ends(textwrap.wrap(label, plots.SPAN_NAME_WIDTH)) == "3: non_traversable |\nwater | mud"
    assert plots._bars_at_ends(["a | b"]) == "a | b" and plots._bars_at_ends([]) == ""
    assert plots._bars_at_ends(["1: " + "x" * 23, "|", "y" * 25]) == "1: " + "x" * 23 + " |\n" + "y" * 25  # a bar alone on its line
