"""Figures drawn with matplotlib (Agg backend, files only)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from terrapref.scenario import Scenario  # noqa: E402
from terrapref.scenario.shapes import outline  # noqa: E402
from terrapref.world import WorldMap  # noqa: E402


def draw_map(ax: plt.Axes, scenario: Scenario, world: WorldMap, zones: bool = True) -> list:
    """Top-down map with the reference path, the start and the labelled zones; returns legend handles."""
    classes = scenario.classes
    rgb = classes.palette()[world.raster]
    sx, sy = world.size_m
    ax.imshow(rgb, origin="lower", extent=(0, sx, 0, sy), interpolation="nearest")
    wp = scenario.waypoints
    ax.plot(wp[:, 0], wp[:, 1], color="white", lw=1.5, ls="--", label="reference path")
    x, y, yaw = scenario.start
    ax.annotate("", xy=(x + 2.5 * np.cos(yaw), y + 2.5 * np.sin(yaw)), xytext=(x, y), arrowprops={"arrowstyle": "-|>", "color": "black", "lw": 1.5})
    ax.plot([x], [y], "o", color="black", ms=5, label="start")
    if zones:
        for z in scenario.zones:
            o = outline(z.shape)
            ax.plot(o[:, 0], o[:, 1], color="yellow", lw=1.0)
            top = o[np.argmax(o[:, 1])]
            text = z.id + (f": {z.label}" if z.label else "")
            ax.text(top[0], top[1] + 0.5, text, color="yellow", fontsize=7, ha="center", va="bottom",
                    bbox={"facecolor": "black", "alpha": 0.5, "pad": 1, "lw": 0})
    ax.set_xlim(0, sx)
    ax.set_ylim(0, sy)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    return [Patch(color=np.array(c.color) / 255, label=c.name) for c in classes.classes]


def save_map(path: str | Path, scenario: Scenario, world: WorldMap,
             tracks: Sequence[tuple[str, np.ndarray, str]] = (), title: str | None = None) -> Path:
    """Write a top-down PNG of the map; ``tracks`` are (label, xy (N, 2), colour) drawn on top."""
    sx, sy = world.size_m
    width = 10.0
    fig, ax = plt.subplots(figsize=(width, max(3.0, width * sy / sx * 0.95)), dpi=120)
    class_handles = draw_map(ax, scenario, world)
    for label, xy, color in tracks:
        ax.plot(xy[:, 0], xy[:, 1], color=color, lw=1.6, label=label)
    ax.legend(handles=class_handles + ax.get_legend_handles_labels()[0], loc="upper left", fontsize=7, framealpha=0.8)
    ax.set_title(title or scenario.name)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path
