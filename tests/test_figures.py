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


@pytest.mark.parametrize("name", ["teach_course", "train_course", "demo_course"])
def test_zone_labels_do_not_overlap_and_the_legend_stays_off_the_map(name):
    scenario = resolve_scenario(name)
    fig, ax = plt.subplots(figsize=(11.5, 6), dpi=120)
    handles = draw_map(ax, scenario, rasterise(scenario))
    legend = ax.legend(handles=handles + ax.get_legend_handles_labels()[0], loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    boxes = [t.get_window_extent(renderer) for t in ax.texts if t.get_text()]  # the start arrow is an empty annotation
    assert len(boxes) == len(scenario.zones)
    crowded = [(i, j) for i in range(len(boxes)) for j in range(i) if _overlap(boxes[i], boxes[j]) > 0.1 * min(boxes[i].width * boxes[i].height,
                                                                                                                 boxes[j].width * boxes[j].height)]
    assert not crowded, crowded
    assert _overlap(legend.get_window_extent(renderer), ax.get_window_extent(renderer)) == 0.0
    assert "reference path" in [t.get_text() for t in legend.get_texts()]
    plt.close(fig)


def test_a_missed_zone_is_marked_with_what_was_expected_and_chosen():
    scenario = resolve_scenario("demo_course")
    fig, ax = plt.subplots()
    zone = scenario.zones[0]
    draw_map(ax, scenario, rasterise(scenario), marks={zone.id: "missed: expected avoid, drove water"})
    marked = [t for t in ax.texts if "missed: expected avoid, drove water" in t.get_text()]
    assert len(marked) == 1 and marked[0].get_text().startswith(zone.id) and marked[0].get_color() == "red"
    plt.close(fig)


def test_the_loss_plot_draws_every_member(tmp_path):
    history = [{"epoch": e, "train_loss": 2.0 / e, "val_loss": 2.1 / e, "train_acc": 0.1 * e, "val_acc": 0.09 * e, "val_top3": 0.2 * e} for e in (1, 2, 3)]
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
    assert [t.get_text() for t in loss_ax.get_legend().get_texts()][:3] == [f"member {j}: epoch {e} chosen" for j, e in ((1, 3), (2, 2), (3, 1))]
    assert (tmp_path / "loss.png").stat().st_size > 10_000
