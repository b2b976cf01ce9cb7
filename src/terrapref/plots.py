"""Figures drawn with matplotlib (Agg backend, files only)."""

from __future__ import annotations

import functools
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib import patheffects  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from terrapref.fileio import atomic_path  # noqa: E402
from terrapref.scenario import Scenario, Zone  # noqa: E402
from terrapref.scenario.shapes import outline  # noqa: E402
from terrapref.terrain import ClassTable, TerrainClass  # noqa: E402
from terrapref.world import WorldMap  # noqa: E402


def _save(fig: plt.Figure, path: str | Path, whole: bool = False) -> Path:
    """Write a figure (creating its folder) and release it; ``whole``: grown to hold everything
    drawn, a legend beside the axes included."""
    path = Path(path)
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, **({"bbox_inches": "tight", "pad_inches": 0.1} if whole else {}))
    finally:
        plt.close(fig)
    return path


PATH_ZORDER = 3.0  # the reference path's layer: tracks go beneath it, the start above
TRACK_LW = 3.5  # a track's width [pt], twice and more the dashed path's, so both are seen where they coincide
SEED_COLOURS = (
    "magenta",
    "yellow",
    "cyan",
    "white",
    "black",
    "darkviolet",
)  # one per run seed, clear of the terrain palette and the zones' lime and red
LONGEST_NAME = 24  # characters of a class name a figure shows; a longer one is cut with an ellipsis


@functools.cache
def _font() -> object:
    """The font figures are drawn in (matplotlib's default family's file)."""
    from matplotlib import font_manager

    return font_manager.get_font(font_manager.findfont(font_manager.FontProperties()))


def drawable(text: str) -> bool:
    """Whether the figures' font has a glyph for every character of ``text`` (else matplotlib
    draws boxes and warns)."""
    font = _font()
    return all(ch in "\n " or font.get_char_index(ord(ch)) != 0 for ch in text)


def class_label(c: TerrainClass) -> str:
    """A class's name as figures show it: ``class ID`` when the font cannot draw it, cut to
    :data:`LONGEST_NAME` characters when longer."""
    if not drawable(c.name):
        return f"class {c.id}"
    return c.name if len(c.name) <= LONGEST_NAME else c.name[: LONGEST_NAME - 1] + "\u2026"


def figure_text(text: str, classes: ClassTable) -> str:
    """``text`` (a zone's label, a title) with every class name in it as :func:`class_label`
    shows it, and any other character the font lacks as ``?``."""
    for c in sorted(classes.classes, key=lambda c: -len(c.name)):  # longest first: no name inside another is replaced early
        if c.name in text and class_label(c) != c.name:
            text = text.replace(c.name, class_label(c))
    return text if drawable(text) else "".join(ch if drawable(ch) else "?" for ch in text)


def class_handles(classes: ClassTable, present: Sequence[int] | None = None) -> list:
    """Legend entries of ``classes``, only those whose ids are in ``present`` when given."""
    keep = set(present) if present is not None else None
    return [Patch(color=np.array(c.color) / 255, label=class_label(c)) for c in classes.classes if keep is None or c.id in keep]


class GroundView(NamedTuple):
    """What of the ground a map draws: the picture of the whole world's ground
    (:func:`ground_picture`, made once where a figure draws it several times) and the window
    (x0, x1, y0, y1) [m] to show of it (None: all of it; a zone's inset shows a few metres)."""

    picture: np.ndarray
    window: tuple[float, float, float, float] | None = None


def draw_map(
    ax: plt.Axes,
    scenario: Scenario,
    world: WorldMap,
    zones: bool = True,
    marks: dict[str, str] | None = None,
    view: GroundView | None = None,
) -> list:
    """Top-down map with the reference path, the start and the labelled zones, each label placed
    clear of the others; ``marks`` (zone id -> text, a missed zone's expected and chosen) are
    added to their zones' labels in red. ``view``: the ground's picture and the window of it
    the axes show, only the cells within it drawn (None: the whole world, its picture made here).
    Returns the legend handles: the classes the map shows (none where it has no terrain,
    :attr:`Scenario.has_terrain`: the ground is left blank)."""
    classes = scenario.classes
    window = view.window if view is not None else None
    rows, cols, extent = _cells_within(world, window)
    handles: list = []
    if scenario.has_terrain:
        picture = view.picture if view is not None else ground_picture(scenario, world)
        ax.imshow(picture[rows, cols], origin="lower", extent=extent, interpolation="nearest")
        handles = class_handles(classes, np.unique(world.raster[rows, cols]).tolist())
    else:
        ax.set_facecolor("whitesmoke")
    if world.height is not None:
        handles.append(_draw_contours(ax, world, rows, cols))
    wp = scenario.waypoints
    ax.plot(
        wp[:, 0],
        wp[:, 1],
        color="white",
        lw=1.5,
        ls="--",
        label="reference path",
        zorder=PATH_ZORDER,
        path_effects=[patheffects.withStroke(linewidth=3, foreground="black")],
    )  # seen on any ground, and in the legend
    x, y, yaw = scenario.start
    ax.annotate(
        "", xy=(x + 2.5 * np.cos(yaw), y + 2.5 * np.sin(yaw)), xytext=(x, y), arrowprops={"arrowstyle": "-|>", "color": "black", "lw": 1.5}
    )
    ax.plot([x], [y], "o", color="black", ms=5, label="start", zorder=PATH_ZORDER + 0.5)
    x0, x1, y0, y1 = window if window is not None else extent
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    if zones:
        _label_zones(ax, scenario.zones, marks or {}, classes)
    return handles


RELIEF_EXAGGERATION = 3.0  # hillshade's vertical exaggeration: gentle slopes (a few degrees) still show
CONTOUR_LEVELS = 6  # about this many contour lines on a map with relief
CONTOUR_CELLS = 400  # contours are traced on at most this many cells a side (finer adds nothing at a figure's size)


def ground_picture(scenario: Scenario, world: WorldMap) -> np.ndarray:
    """The world's ground as :func:`draw_map` draws it: its classes' colours (ny, nx, 3) uint8,
    shaded by its relief where it has one ((ny, nx, 3) float in [0, 1]; the shading's contrast
    is set by the whole world, so a part of it cut out looks as it does on the whole map)."""
    colours = scenario.classes.palette()[world.raster]
    return hillshade(colours, world.height, world.resolution_m) if world.height is not None else colours


def _cells_within(world: WorldMap, window: tuple[float, float, float, float] | None) -> tuple[slice, slice, tuple[float, ...]]:
    """The rows and columns of ``world``'s cells within ``window`` (x0, x1, y0, y1) [m] and a cell
    beyond it, and their extent (x0, x1, y0, y1) [m]; the whole world where ``window`` is None."""
    ny, nx = world.raster.shape
    if window is None:
        sx, sy = world.size_m
        return slice(None), slice(None), (0.0, sx, 0.0, sy)
    res = world.resolution_m
    x0, x1, y0, y1 = window
    c0, c1 = int(np.clip(np.floor(x0 / res) - 1, 0, nx - 1)), int(np.clip(np.ceil(x1 / res) + 1, 1, nx))
    r0, r1 = int(np.clip(np.floor(y0 / res) - 1, 0, ny - 1)), int(np.clip(np.ceil(y1 / res) + 1, 1, ny))
    c1, r1 = max(c1, c0 + 1), max(r1, r0 + 1)
    return slice(r0, r1), slice(c0, c1), (c0 * res, c1 * res, r0 * res, r1 * res)


def hillshade(rgb: np.ndarray, height: np.ndarray, res_m: float) -> np.ndarray:
    """Colours ``rgb`` (ny, nx, 3) uint8 shaded by the heights ``height`` (ny, nx) [m] on cells of
    ``res_m`` [m] (row 0 the southern edge), lit from the north-west as maps are, with
    :data:`RELIEF_EXAGGERATION`: (ny, nx, 3) float in [0, 1]."""
    from matplotlib.colors import LightSource

    # LightSource reads row 0 as the top of the picture; the map's row 0 is its southern edge.
    shaded = LightSource(azdeg=315, altdeg=45).shade_rgb(
        rgb[::-1] / 255.0, height[::-1].astype(np.float64), blend_mode="soft", vert_exag=RELIEF_EXAGGERATION, dx=res_m, dy=res_m
    )
    return shaded[::-1]


def _draw_contours(ax: plt.Axes, world: WorldMap, rows: slice = slice(None), cols: slice = slice(None)) -> Line2D:
    """A few labelled contour lines of the world's height [m] (on a grid of at most
    CONTOUR_CELLS a side), traced over its cells ``rows`` x ``cols`` at the levels of the whole
    world; returns their legend entry."""
    from matplotlib.ticker import MaxNLocator

    assert world.height is not None
    step = max(1, -(-max(world.height.shape) // CONTOUR_CELLS))
    whole = world.height[::step, ::step]
    levels = MaxNLocator(CONTOUR_LEVELS).tick_values(float(whole.min()), float(whole.max()))
    row_ids, col_ids = np.arange(world.height.shape[0])[rows], np.arange(world.height.shape[1])[cols]
    row_ids, col_ids = row_ids[row_ids % step == 0], col_ids[col_ids % step == 0]
    z = world.height[np.ix_(row_ids, col_ids)].astype(np.float64)
    x, y = (col_ids + 0.5) * world.resolution_m, (row_ids + 0.5) * world.resolution_m
    levels = levels[(levels > whole.min()) & (levels < whole.max())]
    if min(z.shape) < 2:  # too few cells to trace a line through
        levels = levels[:0]
    else:  # the levels the cells shown cross
        levels = levels[(levels > z.min()) & (levels < z.max())]
    entry = Line2D([], [], color="black", lw=0.7, label="height contours [m]")
    if not len(levels):  # relief too slight for a contour between its lowest and highest cell
        return entry
    # Solid lines below zero too (monochrome contours are dashed there by default, and a label's
    # minus sign read as one more dash), and a true minus sign in the labels.
    lines = ax.contour(
        x, y, z, levels=levels, colors="black", linewidths=0.7, alpha=0.6, zorder=PATH_ZORDER - 1, negative_linestyles="solid"
    )
    ax.clabel(lines, fmt=lambda v: f"{v:g} m".replace("-", "\u2212"), fontsize=6, inline=True)
    return entry


def _label_zones(ax: plt.Axes, zones: Sequence[Zone], marks: dict[str, str], classes: ClassTable) -> None:
    """Each zone's outline and label; a label goes above its zone, else below, right or left,
    whichever first overlaps no label placed before it (else the least overlapping)."""
    renderer = ax.figure.canvas.get_renderer()
    frame = ax.get_window_extent(renderer)
    placed: list = []  # the labels' boxes in display coordinates
    for z in zones:
        o = outline(z.shape)
        ax.plot(o[:, 0], o[:, 1], color="yellow", lw=1.0)
        (x0, y0), (x1, y1) = o.min(axis=0), o.max(axis=0)
        text = _wrapped(figure_text(z.id + (f": {z.label}" if z.label else ""), classes))
        text += f"\n{_wrapped(figure_text(marks[z.id], classes))}" if z.id in marks else ""
        style = {
            "color": "red" if z.id in marks else "yellow",
            "fontsize": 7,
            "bbox": {"facecolor": "black", "alpha": 0.6, "pad": 1, "lw": 0},
        }
        best = None
        for x, y, ha, va in (
            ((x0 + x1) / 2, y1 + 0.5, "center", "bottom"),
            ((x0 + x1) / 2, y0 - 0.5, "center", "top"),
            (x1 + 0.5, (y0 + y1) / 2, "left", "center"),
            (x0 - 0.5, (y0 + y1) / 2, "right", "center"),
        ):
            label = ax.text(x, y, text, ha=ha, va=va, **style)
            box = label.get_window_extent(renderer).expanded(1.05, 1.1)
            inside = max(0.0, min(box.x1, frame.x1) - max(box.x0, frame.x0)) * max(0.0, min(box.y1, frame.y1) - max(box.y0, frame.y0))
            overlap = sum(max(0.0, min(box.x1, b.x1) - max(box.x0, b.x0)) * max(0.0, min(box.y1, b.y1) - max(box.y0, b.y0)) for b in placed)
            overlap += box.width * box.height - inside  # beyond the map counts as overlap too
            if best is None or overlap < best[0]:
                if best is not None:
                    best[1].remove()
                best = (overlap, label, box)
            else:
                label.remove()
            if overlap == 0.0:
                break
        placed.append(best[2])


LABEL_WIDTH = 26  # characters per line of a zone's label: a long one is wrapped, so that it stays beside its zone


def _wrapped(text: str) -> str:
    return _bars_at_ends(textwrap.wrap(text, LABEL_WIDTH, break_long_words=False, break_on_hyphens=False)) or text


def _bars_at_ends(lines: list[str]) -> str:
    """Wrapped ``lines`` joined, a zone label's ``|`` that a break left at a line's start moved to
    the end of the line before (so each line but the last ends with it)."""
    for k in range(1, len(lines)):
        if lines[k] == "|" or lines[k].startswith("| "):
            lines[k - 1], lines[k] = f"{lines[k - 1]} |", lines[k][2:]
    return "\n".join(line for line in lines if line)


def save_map(
    path: str | Path,
    scenario: Scenario,
    world: WorldMap,
    tracks: Sequence[tuple[str, np.ndarray, str]] = (),
    title: str | None = None,
    marks: dict[str, str] | None = None,
) -> Path:
    """Write a top-down PNG of the map; ``tracks`` are (label, xy (N, 2), colour) drawn on top,
    ``marks`` (zone id -> text) added to those zones' labels in red."""
    sx, sy = world.size_m
    width = 11.5
    fig, ax = plt.subplots(figsize=(width, max(3.0, (width - 1.5) * sy / sx * 0.95)), dpi=120)
    classes_shown = draw_map(ax, scenario, world, zones=False)  # the zones once the map has its final size
    for label, xy, color in tracks:  # wide and beneath the path: the dashed path stays seen along a track that follows it
        ax.plot(xy[:, 0], xy[:, 1], color=color, lw=TRACK_LW, alpha=0.85, label=label, zorder=PATH_ZORDER - 0.5, solid_capstyle="round")
    ax.legend(
        handles=classes_shown + ax.get_legend_handles_labels()[0],
        loc="upper left",
        bbox_to_anchor=(1.01, 1.0),
        fontsize=7,
        framealpha=0.8,
        borderaxespad=0.0,
    )  # beside the map: never over the start or a zone
    ax.set_title(figure_text(title or scenario.name, scenario.classes))
    fig.tight_layout()
    # Labelled after the layout: placed while the map was larger, labels clear of one another there
    # would run into one another once the legend and the title had shrunk it.
    _label_zones(ax, scenario.zones, marks or {}, scenario.classes)
    return _save(fig, path)


def save_loss_curve(path: str | Path, members: Sequence[tuple[Sequence[dict], int]], title: str = "training") -> Path:
    """Training and validation loss and accuracy per epoch (the paper's Fig. 4), every member of
    an ensemble in its own colour; ``members``: (history, chosen epoch) each."""
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 3.6), dpi=120)
    for j, (history, best_epoch) in enumerate(members):
        colour = f"C{j}"
        epochs = [h["epoch"] for h in history]
        ax1.plot(epochs, [h["train_loss"] for h in history], color=colour, lw=1.0, alpha=0.6)
        ax1.plot(epochs, [h["val_loss"] for h in history], color=colour, lw=1.6, ls="--")
        ax1.axvline(best_epoch, color=colour, ls=":", lw=1.0)
        ax2.plot(epochs, [h["train_acc"] for h in history], color=colour, lw=1.0, alpha=0.6)
        ax2.plot(epochs, [h["val_acc"] for h in history], color=colour, lw=1.6, ls="--")
        ax2.plot(epochs, [h["val_top3"] for h in history], color=colour, lw=1.6, ls=":")
    who = [
        Line2D([], [], color=f"C{j}", lw=3, label=f"member {j + 1}: epoch {best} chosen" if len(members) > 1 else f"epoch {best} chosen")
        for j, (_, best) in enumerate(members)
    ]
    key = [Line2D([], [], color="grey", lw=1.0, label="train"), Line2D([], [], color="grey", lw=1.6, ls="--", label="validation")]
    ax1.legend(handles=who + key + [Line2D([], [], color="grey", ls=":", label="chosen epoch")], fontsize=7, loc="upper right")
    ax1.set_xlabel("epoch")
    ax1.set_ylabel("cross-entropy loss")
    ax2.legend(
        handles=[
            Line2D([], [], color="grey", lw=1.0, label="train top-1"),
            Line2D([], [], color="grey", lw=1.6, ls="--", label="validation top-1"),
            Line2D([], [], color="grey", lw=1.6, ls=":", label="validation top-3"),
        ],
        fontsize=7,
        loc="lower right",
    )
    ax2.set_xlabel("epoch")
    ax2.set_ylabel("accuracy (chance 1 in 21)")
    ax2.set_ylim(0, 1)
    fig.suptitle(title)
    fig.tight_layout()
    return _save(fig, path)


@dataclass(frozen=True, eq=False)  # arrays inside
class Decision:
    """A planner decision, as drawn over the camera view.

    Attributes:
        uv: pixel coordinates of the trajectory points, (m, n, 2).
        visible: which of them the camera sees, (m, n).
        probs: F_t, (m,).
        chosen: the planner's choice (after the second stage, where there is one).
        w_rps: each trajectory's yaw rate [rad/s], (m,).
        stop: why the planner stood at this frame (None: it drove ``chosen``); the steering's
            choice is then drawn as what it was not let drive.
    """

    uv: np.ndarray
    visible: np.ndarray
    probs: np.ndarray
    chosen: int
    w_rps: Sequence[float]
    stop: str | None = None


def save_decision(path: str | Path, rgb: np.ndarray, decision: Decision, title: str = "", classes=None) -> Path:
    """The camera view ``rgb`` (H, W, 3) with every trajectory coloured by its predicted
    probability on an absolute 0-1 scale, C's own best and the planner's choice marked apart (they
    differ when the second stage overrules C), and a legend of the terrain classes (``classes``:
    the class table)."""
    uv, visible, probs, chosen, w_rps = decision.uv, decision.visible, decision.probs, decision.chosen, decision.w_rps
    h, w = rgb.shape[:2]
    fig, ax = plt.subplots(figsize=(8.6, 6.4), dpi=100)
    ax.imshow(rgb)
    cmap = plt.get_cmap("plasma")
    best = int(np.argmax(probs))
    for i in np.argsort(probs):
        pts = uv[i][visible[i]]
        if len(pts) < 2:
            continue
        lw = 4.0 if i == chosen else (2.5 if i == best else 1.5)
        ax.plot(pts[:, 0], pts[:, 1], color=cmap(float(probs[i])), lw=lw, alpha=0.95)
        if i == chosen:
            ax.plot(pts[:, 0], pts[:, 1], color="white", lw=1.0, ls="--")
            ax.text(
                pts[-1, 0],
                pts[-1, 1] - 8,
                (
                    f"steering's w={w_rps[i]:+.1f}\nstood: {decision.stop}"
                    if decision.stop
                    else f"chosen w={w_rps[i]:+.1f}\np={probs[i]:.2f}"
                ),
                color="white",
                fontsize=8,
                ha="center",
                bbox={"facecolor": "black", "alpha": 0.6, "pad": 1, "lw": 0},
            )
        elif i == best:
            ax.plot(pts[:, 0], pts[:, 1], color="cyan", lw=1.0, ls=":")
            ax.text(
                pts[-1, 0],
                pts[-1, 1] + 14,
                f"C's best w={w_rps[i]:+.1f}\np={probs[i]:.2f}",
                color="cyan",
                fontsize=8,
                ha="center",
                bbox={"facecolor": "black", "alpha": 0.6, "pad": 1, "lw": 0},
            )
    sm = plt.cm.ScalarMappable(cmap=cmap, norm=matplotlib.colors.Normalize(0.0, 1.0))
    fig.colorbar(sm, ax=ax, fraction=0.035, label="predicted probability F_t (absolute scale)")
    chosen_label = f"the steering's choice; the planner stood ({decision.stop})" if decision.stop else "planner's choice"
    handles = [Line2D([], [], color="white", lw=3, ls="--", label=chosen_label)]
    if best != chosen:
        handles.append(Line2D([], [], color="cyan", lw=2, ls=":", label="C's best (second stage overruled it)"))
    if classes is not None:  # the classes in view
        handles += class_handles(classes, [c.id for c in classes.classes if (rgb.reshape(-1, 3) == c.color).all(axis=1).any()])
    ax.legend(handles=handles, loc="lower left", fontsize=7, framealpha=0.8)
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.set_axis_off()
    ax.set_title(title, fontsize=9)
    fig.tight_layout()
    return _save(fig, path)


@dataclass(frozen=True, eq=False)  # arrays inside
class CourseRuns:
    """The runs of one course, as an evaluation figure shows them.

    Attributes:
        scenario: the course.
        world: its raster (the one the runs used).
        driver: the synthetic driver's tracks, each (T, 2) [m], by seed (the k-th is seed k's).
        planner: the planner's tracks, each (T, 2) [m], by seed.
        zone_success: zone id -> (planner runs that met it, runs scored in it).
    """

    scenario: Scenario
    world: WorldMap
    driver: Sequence[np.ndarray]
    planner: Sequence[np.ndarray]
    zone_success: dict[str, tuple[int, int]]


def save_evaluation(path: str | Path, runs: CourseRuns, title: str) -> Path:
    """An evaluation at a glance: the whole course with each zone numbered and outlined green
    (every planner run met it) or red (some run missed it), and below it one inset per zone at a
    legible scale; each seed's runs in a colour of their own (:data:`SEED_COLOURS`), the driver's
    dashed and the planner's solid. The legend stands beside the course, off the map."""
    scenario, world, driver, planner, zone_success = runs.scenario, runs.world, runs.driver, runs.planner, runs.zone_success
    zones = list(scenario.zones)
    cols = 4
    rows = (len(zones) + cols - 1) // cols
    sx, sy = world.size_m
    overview_h = max(2.6, min(7.0, 13.0 * sy / sx))
    fig = plt.figure(figsize=(13, overview_h + 3.3 * rows + 0.6), dpi=110)
    grid = fig.add_gridspec(1 + rows, cols, height_ratios=[overview_h] + [3.3] * rows)
    ax = fig.add_subplot(grid[0, :])
    ground = ground_picture(scenario, world)  # shaded once, for the course and each inset
    classes_shown = draw_map(ax, scenario, world, zones=False, view=GroundView(ground))
    _draw_runs(ax, runs, scale=1.0)
    for z in zones:
        ok, n = zone_success.get(z.id, (0, 0))
        o = outline(z.shape)
        colour = "lime" if n and ok == n else "red"
        ax.plot(o[:, 0], o[:, 1], color=colour, lw=1.4)
        c = o.mean(axis=0)
        ax.text(
            c[0],
            c[1],
            z.id,
            color="black",
            fontsize=7,
            ha="center",
            va="center",
            zorder=PATH_ZORDER + 1,
            bbox={"facecolor": colour, "alpha": 0.85, "pad": 1, "lw": 0},
        )
    seeds = max(len(driver), len(planner))
    key = _seed_colour(0) if seeds == 1 else "grey"  # one seed: the key in its colour; more: the style alone, each seed's colour below
    tracks = [Line2D([], [], color=key, ls="--", label="driver (dashed)")] if len(driver) else []  # none with --no-driver
    tracks += [Line2D([], [], color=key, label="planner (solid)")]
    tracks += [Line2D([], [], color=_seed_colour(k), lw=3, label=f"seed {k}") for k in range(seeds)] if seeds > 1 else []
    tracks += [
        Patch(facecolor="none", edgecolor="lime", label="zone met in every run"),
        Patch(facecolor="none", edgecolor="red", label="zone missed in some run"),
    ]
    ax.legend(
        handles=classes_shown + ax.get_legend_handles_labels()[0] + tracks,
        loc="upper left",
        bbox_to_anchor=(1.01, 1.0),
        fontsize=7,
        framealpha=0.8,
        borderaxespad=0.0,
    )  # beside the course: never over the start or a zone
    ax.set_title(figure_text(title, scenario.classes))
    for k, z in enumerate(zones):
        _draw_zone_inset(fig.add_subplot(grid[1 + k // cols, k % cols]), runs, z, ground)
    fig.tight_layout()
    return _save(fig, path, whole=True)


def _draw_zone_inset(zax: plt.Axes, runs: CourseRuns, z: Zone, ground: np.ndarray) -> None:
    """Zone ``z`` at a legible scale (4 m around it) on the ``ground`` picture of the course (:func:`draw_map`):
    its outline green when every planner run met it, and the driver's and the planner's tracks."""
    o = outline(z.shape)
    lo, hi = o.min(axis=0) - 4.0, o.max(axis=0) + 4.0
    half = max(hi - lo) / 2
    mid = (lo + hi) / 2
    window = (mid[0] - half, mid[0] + half, mid[1] - half, mid[1] + half)
    draw_map(zax, runs.scenario, runs.world, zones=False, view=GroundView(ground, window))
    success = runs.zone_success.get(z.id, (0, 0))
    ok, n = success
    colour = "lime" if n and ok == n else "red"
    zax.plot(o[:, 0], o[:, 1], color=colour, lw=1.2)
    _draw_runs(zax, runs, scale=1.3)
    zax.set_xlim(mid[0] - half, mid[0] + half)
    zax.set_ylim(mid[1] - half, mid[1] + half)
    zax.set_xlabel("")
    zax.set_ylabel("")
    zax.tick_params(labelsize=6)
    verdict = f"{ok}/{n} met" if n else "not scored"
    zax.set_title(
        figure_text(f"{z.id}: {z.label or z.expect} ({verdict})", runs.scenario.classes),
        fontsize=8,
        color="darkred" if colour == "red" else "black",
    )


def _seed_colour(seed: int) -> str:
    return SEED_COLOURS[seed % len(SEED_COLOURS)]


def _draw_runs(ax: plt.Axes, runs: CourseRuns, scale: float) -> None:
    """Every run's track, seed k's (the k-th of each list) in its colour: the driver's dashed, the
    planner's solid; widths times ``scale``."""
    for k, xy in enumerate(runs.driver):
        ax.plot(xy[:, 0], xy[:, 1], color=_seed_colour(k), lw=1.0 * scale, ls="--", zorder=PATH_ZORDER + 0.2)
    for k, xy in enumerate(runs.planner):
        ax.plot(xy[:, 0], xy[:, 1], color=_seed_colour(k), lw=1.0 * scale, alpha=0.9, zorder=PATH_ZORDER + 0.1)


def save_bars(
    path: str | Path, labels: Sequence[str], means: Sequence[float], stds: Sequence[float], ylabel: str, target: float | None = None
) -> Path:
    """One bar per method with its spread over seeds."""
    fig, ax = plt.subplots(figsize=(8, 3.8), dpi=120)
    x = np.arange(len(labels))
    ax.bar(x, means, yerr=stds, capsize=4, color="tab:blue")
    if target is not None:
        ax.axhline(target, color="grey", ls=":", label=f"{target:.0%}")
        ax.legend(fontsize=8)
    ax.set_xticks(x, labels, rotation=20, ha="right", fontsize=8)
    ax.set_ylim(0, 1.05)
    ax.set_ylabel(ylabel)
    fig.tight_layout()
    return _save(fig, path)


class RateRow(NamedTuple):
    """One row of :func:`save_intervals`: its label, its rate (0-1) and the rate's 95% interval (low, high)."""

    label: str
    rate: float
    interval: tuple[float, float]


def save_intervals(
    path: str | Path, rows: Sequence[RateRow], ylabel: str, target: float | Sequence[float] | None = None, title: str = ""
) -> Path:
    """One point per row with its 95% interval (asymmetric, e.g. Wilson) and the rate written beside it;
    ``target`` a line across, or one per row (a short line at each point, its value written where it
    changes; a line across when every row's is the same).

    Points rather than bars: the axis can then start near the data without bars that begin
    nowhere, and differences of a few points stay visible.
    """
    labels, intervals = [r.label for r in rows], [r.interval for r in rows]
    fig, ax = plt.subplots(figsize=(max(6.0, 1.1 * len(labels) + 2), 3.8), dpi=120)
    x = np.arange(len(labels))
    rates = np.array([r.rate for r in rows], dtype=float)
    lo, hi = (np.array(v, dtype=float) for v in zip(*intervals)) if len(intervals) else (np.zeros(0), np.zeros(0))
    bars = ax.errorbar(x, rates, yerr=np.stack([rates - lo, hi - rates]), fmt="o", color="tab:blue", capsize=5, lw=1.5)
    for artist in (bars.lines[0], *bars.lines[1], *bars.lines[2]):
        artist.set_clip_on(False)  # a point at 100% drawn whole on the axis's top edge, not cut in half
    for xi, r, h in zip(x, rates, hi):
        ax.text(xi + 0.08, r, f"{r:.1%}", ha="left", va="center", fontsize=8)
    bottom = float(np.nanmin(lo)) if len(lo) else 0.0
    if target is not None and not isinstance(target, (int, float)) and len(set(target)) == 1:
        target = float(target[0])
    if isinstance(target, (int, float)):
        ax.axhline(target, color="grey", ls=":")
        # Beside the axes, to the right, where no point's written rate can fall on it.
        ax.text(
            1.01, target, f"target\n{target:.0%}", transform=ax.get_yaxis_transform(), ha="left", va="center", fontsize=8, color="dimgrey"
        )
        bottom = min(bottom, target)
    elif target is not None:
        targets = [float(t) for t in target]
        for i, t in enumerate(targets):
            ax.hlines(t, i - 0.45, i + 0.45, color="grey", ls=":")
            if i == 0 or t != targets[i - 1]:
                ax.text(i - 0.45, t, f"target {t:.0%}", ha="left", va="bottom", fontsize=7, color="dimgrey")
        bottom = min([bottom, *targets])
    ax.set_xticks(x, labels, rotation=15, ha="right", fontsize=8)
    ax.set_xlim(-0.5, len(labels) - 0.5)
    ax.set_ylim(max(0.0, bottom - 0.05), 1.0)
    ax.yaxis.set_major_formatter(matplotlib.ticker.PercentFormatter(1.0))
    ax.set_ylabel(ylabel)
    width_chars = int(fig.get_figwidth() * 12)  # what a 9-point title holds across the figure
    ax.set_title("\n".join(textwrap.wrap(title, width_chars)) if title else "", fontsize=9)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    return _save(fig, path)


def save_curves(
    path: str | Path,
    series: dict[str, Sequence[tuple[float, float, float]]],
    xlabel: str,
    ylabel: str,
    target: float | None = None,
    logx: bool = False,
) -> Path:
    """Lines of (x, mean, std) per series, with the spread shaded."""
    fig, ax = plt.subplots(figsize=(6.5, 4), dpi=120)
    for name, pts in series.items():
        x, y, e = (np.array(v, dtype=float) for v in zip(*pts))
        ax.plot(x, y, marker="o", label=name)
        ax.fill_between(x, y - e, y + e, alpha=0.2)
    if target is not None:
        ax.axhline(target, color="grey", ls=":", label=f"{target:.0%}")
    if logx:
        ax.set_xscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_ylim(0, 1.05)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, path)


def save_speed_profile(
    path: str | Path,
    series: Sequence[tuple[str, np.ndarray, np.ndarray, str]],
    title: str,
    spans: Sequence[tuple[str, float, float]] = (),
    heights: Sequence[np.ndarray] | None = None,
) -> Path:
    """Speed [m/s] against progress along the path [m], one line per (label, progress, speed,
    colour), over the stretches ``spans`` (label, first and last progress [m]: the zones) shaded;
    with ``heights`` (one per series: the ground's height [m] under it at each progress), a
    panel below of height along the path, in the same colours."""
    panels = [2.7] + ([1.8] if heights is not None else [])  # [in]: speed, and height below it on relief
    strip = [1.1] if spans else []  # the zones' names [in], upright in a band of their own above the speeds
    fig, axes = plt.subplots(
        len(strip + panels),
        1,
        figsize=(9, sum(strip + panels) + 0.9),
        dpi=120,
        sharex=True,
        gridspec_kw={"height_ratios": strip + panels},
        squeeze=False,
        layout="constrained",
    )
    axes = list(axes[:, 0])
    if spans:
        _name_spans(axes.pop(0), spans)
    ax = axes[0]
    for a in axes:
        for label, s0, s1 in spans:
            a.axvspan(s0, s1, color="0.85", lw=0)
    for label, s, v, colour in series:
        ax.plot(s, v, color=colour, lw=1.2, label=label)
    ax.set_ylabel("speed [m/s]")
    top = max((float(np.max(v)) for _, _, v, _ in series if len(v)), default=0.0)
    ax.set_ylim(0, max(0.5, 1.15 * top))  # the speeds driven fill the panel, with room above the fastest
    fig.suptitle(title, fontsize=10)
    ax.legend(fontsize=8)
    if heights is not None:
        for (label, s, _, colour), z in zip(series, heights, strict=True):
            axes[1].plot(s, z, color=colour, lw=1.2, label=label)
        axes[1].set_ylabel("ground height [m]")
    for a in axes:
        a.grid(alpha=0.3)
    axes[-1].set_xlabel("progress along the path [m]")
    return _save(fig, path)


SPAN_NAME_WIDTH = 18  # characters per line of a zone's name over its stretch


def _name_spans(ax: plt.Axes, spans: Sequence[tuple[str, float, float]]) -> None:
    """The band above a speed panel: each zone's stretch shaded and its name upright over it,
    clear of the speeds drawn below."""
    for label, s0, s1 in spans:
        ax.axvspan(s0, s1, color="0.85", lw=0)
        name = _bars_at_ends(textwrap.wrap(label, SPAN_NAME_WIDTH, max_lines=2, placeholder=" ...")) or label
        ax.text((s0 + s1) / 2, 0.04, name, rotation=90, ha="center", va="bottom", fontsize=6.5, color="0.25", linespacing=1.0)
    ax.set_ylim(0, 1)
    ax.set_yticks([])
    for side in ("top", "right", "left"):
        ax.spines[side].set_visible(False)
    ax.tick_params(axis="x", bottom=False)
