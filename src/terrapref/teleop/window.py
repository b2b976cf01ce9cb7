"""Drawing the driving window: the camera view with S, the heads-up display, the alerts (a push,
off the route) and the arrow back to the route, the map inset with the pushes marked, the stick
gauge, the legend and the instructions, on a fixed-size canvas scaled to the window.

The window is resizable: everything is drawn at the canvas's own size and scaled to fit the
window, keeping its aspect ratio (the margins are left dark); pointer positions are mapped back
to canvas pixels with :meth:`Window.to_canvas`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pygame

from terrapref.features import PreferenceSet
from terrapref.sim import Simulation

INSET_WIDTH_PX = 240
PANEL_MARGIN_PX = 8
STATUS_HEIGHT_PX = 26
PANEL_BELOW_INSET_PX = 250  # the gauge, the legend and the instructions under the map inset

# Drawing colours (RGB). Trajectories are light on every terrain colour; the highlight is a
# saturated yellow with a dark outline so it stays distinct over sky blue, grass and mud alike.
TRAJ_COLOR = (236, 236, 236)
HIGHLIGHT_COLOR = (255, 226, 0)
OUTLINE_COLOR = (20, 20, 20)
PANEL_BG = (28, 30, 34)
TEXT_COLOR = (230, 230, 230)
DIM_TEXT = (150, 154, 160)
PATH_COLOR = (240, 40, 210)  # the route to follow, on the ground in the view and on the map
PATH_AHEAD_M = (-1.0, 25.0)  # the stretch of the route drawn in the camera view, from the vehicle's place on it [m]
TRACE_COLOR = (255, 255, 255)
VEHICLE_COLOR = (255, 226, 0)
ALERT_COLOR = (255, 90, 70)
PLANNER_COLOR = (90, 200, 255)


@dataclass(frozen=True)
class Banner:
    """Large text over the camera view (start screen, countdown, pause, edge, end), with smaller lines below."""

    text: str
    color: tuple[int, int, int] = HIGHLIGHT_COLOR
    lines: tuple[str, ...] = ()


@dataclass(frozen=True)
class Overlay:
    """The text drawn around and over the camera view in one frame.

    Attributes:
        status: the line under the view (time, the vehicle's speed and the set one, w, label, frames, collisions).
        hud: the guide's readout, top left of the view.
        banner: large text over the view, or None.
        mode: who drives (ride-along) and in what colour, top right of the view; None: nobody but you.
        alerts: what just happened to the vehicle or where it is (a push, off the route), in
            the alert colour at the top centre of the view.
        route_rad: the bearing of the way back onto the route from the heading [rad], positive
            to the left; an arrow points it out when ``off_route`` or when the route is out of
            the camera's sight. None: no arrow.
        off_route: the vehicle is off the route.
        pushes_px: where the pushes began, in inset pixels (:meth:`Window.to_inset`).
    """

    status: str
    hud: Sequence[str] = ()
    banner: Banner | None = None
    mode: tuple[str, tuple[int, int, int]] | None = None
    alerts: Sequence[str] = ()
    route_rad: float | None = None
    off_route: bool = False
    pushes_px: Sequence[tuple[float, float]] = ()


class Window:
    """The driving window of one simulation."""

    def __init__(self, sim: Simulation, prefs: PreferenceSet, title: str, instructions: Sequence[str]) -> None:
        self.sim = sim
        self.palette = sim.world.classes.palette()
        self.palette_list = [tuple(int(v) for v in rgb) for rgb in self.palette]
        rows, cols = sim.camera.shape
        self.view_size = (cols, rows)
        self.panel_x = cols
        panel_w = INSET_WIDTH_PX + 2 * PANEL_MARGIN_PX
        self.size = (cols + panel_w, rows + STATUS_HEIGHT_PX)
        self.instructions = tuple(instructions)
        pygame.display.set_caption(title)
        self.screen = pygame.display.set_mode(self.size, pygame.RESIZABLE)
        self.canvas = pygame.Surface(self.size)
        self.font = pygame.font.Font(None, 20)
        self.hud_font = pygame.font.Font(None, 22)
        self.big_font = pygame.font.Font(None, 56)
        self.segments = self._trajectory_segments(prefs)
        self.control = prefs.config.control
        self._build_inset()

    # --- the window and its scale ----------------------------------------------------------------

    def resize(self, size: tuple[int, int]) -> None:
        """Follow the window to a new size (a VIDEORESIZE event)."""
        w, h = (max(64, int(v)) for v in size)
        self.screen = pygame.display.set_mode((w, h), pygame.RESIZABLE)

    def _fit(self) -> tuple[float, int, int]:
        """Scale and offset [px] of the canvas in the window, aspect kept, centred."""
        win_w, win_h = self.screen.get_size()
        scale = min(win_w / self.size[0], win_h / self.size[1])
        return scale, (win_w - round(self.size[0] * scale)) // 2, (win_h - round(self.size[1] * scale)) // 2

    def to_canvas(self, pos: tuple[float, float]) -> tuple[float, float]:
        """Canvas pixel of a window pixel (pointer events)."""
        scale, ox, oy = self._fit()
        return (pos[0] - ox) / scale, (pos[1] - oy) / scale

    def _present(self) -> None:
        if self.screen.get_size() == self.size:
            self.screen.blit(self.canvas, (0, 0))
        else:
            scale, ox, oy = self._fit()
            self.screen.fill((0, 0, 0))  # the margins of a window of another shape
            size = (max(1, round(self.size[0] * scale)), max(1, round(self.size[1] * scale)))
            self.screen.blit(self.canvas if size == self.size else pygame.transform.smoothscale(self.canvas, size), (ox, oy))
        pygame.display.flip()

    # --- computed once -----------------------------------------------------------------------------

    def _trajectory_segments(self, prefs: PreferenceSet) -> list[list[list[tuple[float, float]]]]:
        """Per trajectory, its runs of consecutive visible points as pixel polylines.

        A tight arc can leave the image and come back (w = 1 rad/s over 6 m is almost a full
        circle), so each visible run is drawn on its own rather than joined across the gap.
        """
        uv, visible = self.sim.camera.project_ground(prefs.trajectories[..., :2])
        out = []
        for i in range(prefs.m):
            runs: list[list[tuple[float, float]]] = []
            current: list[tuple[float, float]] = []
            for (u, v), ok in zip(uv[i], visible[i], strict=True):
                if ok:
                    current.append((float(u), float(v)))
                elif current:
                    runs.append(current)
                    current = []
            if current:
                runs.append(current)
            out.append(runs)
        return out

    def _build_inset(self) -> None:
        """The map, north up, coloured by class (hillshaded on relief) and downsampled by plain slicing."""
        world = self.sim.world
        ny, nx = world.raster.shape
        w_m, h_m = world.size_m
        max_h = self.view_size[1] - PANEL_BELOW_INSET_PX
        scale = min(INSET_WIDTH_PX / w_m, max_h / h_m)  # [px/m]
        self.inset_scale = scale
        self.inset_size = (max(1, round(w_m * scale)), max(1, round(h_m * scale)))
        step = max(1, int(min(nx / self.inset_size[0], ny / self.inset_size[1])))
        rgb = self.palette[world.raster[::step, ::step]]
        if world.height is not None:  # relief: the classes hillshaded, as the figures show it
            from terrapref.plots import hillshade

            rgb = np.round(255.0 * hillshade(rgb, world.height[::step, ::step], world.resolution_m * step)).astype(np.uint8)
        rgb = np.ascontiguousarray(rgb[::-1])  # row 0 is south in the raster; north up here
        surf = pygame.image.frombuffer(rgb.tobytes(), (rgb.shape[1], rgb.shape[0]), "RGB")
        self.inset = pygame.transform.smoothscale(surf, self.inset_size)
        self.inset_origin = (self.panel_x + PANEL_MARGIN_PX, PANEL_MARGIN_PX + 18)
        self.inset_h_m = h_m
        self.path_px = [self.to_inset(x, y) for x, y in self.sim.path.waypoints]

    def to_inset(self, x: float, y: float) -> tuple[float, float]:
        """Canvas pixel of world point (x, y) [m] in the inset."""
        ox, oy = self.inset_origin
        return ox + x * self.inset_scale, oy + (self.inset_h_m - y) * self.inset_scale

    # --- per frame -----------------------------------------------------------------------------------

    def draw(self, image: np.ndarray, w: float, label: int, trace_px: Sequence[tuple[float, float]], overlay: Overlay) -> None:
        """Draw one frame and show it: the camera ``image`` (class ids), the stick's ``w`` [rad/s]
        and its ``label``, the driven trace in the inset, and the ``overlay``'s text."""
        canvas = self.canvas
        canvas.fill(PANEL_BG)
        view = pygame.image.frombuffer(np.ascontiguousarray(image, dtype=np.uint8), self.view_size, "P")  # class ids, 8-bit
        view.set_palette(self.palette_list)  # SDL colours it while blitting: no (H, W, 3) array per frame
        canvas.blit(view, (0, 0))
        in_sight = self._draw_route()
        self._draw_trajectories(label)
        below_hud = self._draw_hud(overlay.hud)
        if overlay.mode is not None:
            self._draw_box(self.hud_font.render(overlay.mode[0], True, overlay.mode[1]), anchor="topright")
        bottom = self._draw_alerts(overlay.alerts, below_hud)
        if overlay.route_rad is not None and (overlay.off_route or not in_sight):
            self._draw_arrow(overlay.route_rad, bottom)
        self._draw_inset(trace_px, overlay.pushes_px)
        self._draw_gauge(w, label)
        self._draw_legend()
        canvas.blit(self.font.render(overlay.status, True, TEXT_COLOR), (8, self.view_size[1] + 6))
        if overlay.banner is not None:
            self._draw_banner(overlay.banner)
        self._present()

    def save(self, path: str) -> None:
        """The window as the driver sees it, at its current size."""
        pygame.image.save(self.screen, path)

    def _shade(self, rect: pygame.Rect, rgba: tuple[int, int, int, int] = (0, 0, 0, 170)) -> None:
        """Darken ``rect`` of the canvas, so that text over the camera view stays readable."""
        shade = pygame.Surface(rect.size, pygame.SRCALPHA)
        shade.fill(rgba)
        self.canvas.blit(shade, rect)

    def _draw_box(self, text: pygame.Surface, anchor: str) -> None:
        box = text.get_rect(topright=(self.view_size[0] - 10, 10)) if anchor == "topright" else text.get_rect(topleft=(10, 10))
        self._shade(box.inflate(12, 8))
        self.canvas.blit(text, box)

    def _draw_hud(self, hud: Sequence[str]) -> int:
        """The guide's lines, top left of the view; returns the canvas row below them."""
        if not hud:
            return 4
        lines = [self.hud_font.render(line, True, TEXT_COLOR) for line in hud]
        width = max(s.get_width() for s in lines) + 16
        height = sum(s.get_height() + 3 for s in lines) + 10
        self._shade(pygame.Rect(4, 4, width, height))
        y = 9
        for s in lines:
            self.canvas.blit(s, (12, y))
            y += s.get_height() + 3
        return 4 + height

    def _draw_alerts(self, alerts: Sequence[str], top: int) -> int:
        """The alerts, one under another at the centre of the view below ``top`` [px] (the HUD);
        returns the canvas row below them."""
        y = top + 10
        for line in alerts:
            text = self.hud_font.render(line, True, ALERT_COLOR)
            box = text.get_rect(midtop=(self.view_size[0] // 2, y))
            self._shade(box.inflate(14, 8), (10, 10, 10, 215))
            self.canvas.blit(text, box)
            y = box.bottom + 10
        return y

    def _draw_arrow(self, bearing_rad: float, top: int) -> None:
        """An arrow below ``top`` [px], at the view's centre, pointing the way back onto the
        route: straight up is straight ahead, left is to the vehicle's left."""
        cx, cy, r = self.view_size[0] / 2, top + 34.0, 26.0
        ux, uy = -math.sin(bearing_rad), -math.cos(bearing_rad)  # the arrow's direction on the canvas (y grows downward)
        nx, ny = -uy, ux
        tip = (cx + r * ux, cy + r * uy)
        wings = [(cx - 0.2 * r * ux + s * 0.75 * r * nx, cy - 0.2 * r * uy + s * 0.75 * r * ny) for s in (1, -1)]
        stem = [(cx - 0.2 * r * ux + s * 0.3 * r * nx, cy - 0.2 * r * uy + s * 0.3 * r * ny) for s in (1, -1)]
        tail = [(cx - r * ux + s * 0.3 * r * nx, cy - r * uy + s * 0.3 * r * ny) for s in (1, -1)]
        outline = [tip, wings[0], stem[0], tail[0], tail[1], stem[1], wings[1]]
        pygame.draw.polygon(self.canvas, ALERT_COLOR, outline)
        pygame.draw.polygon(self.canvas, OUTLINE_COLOR, outline, 2)

    def _draw_banner(self, banner: Banner) -> None:
        text = self.big_font.render(banner.text, True, banner.color)
        small = [self.hud_font.render(line, True, TEXT_COLOR) for line in banner.lines]
        width = max([text.get_width(), *(s.get_width() for s in small)]) + 32
        height = text.get_height() + sum(s.get_height() + 4 for s in small) + 24
        box = pygame.Rect(0, 0, width, height)
        box.center = (self.view_size[0] // 2, self.view_size[1] // 2 if small else self.view_size[1] // 3)
        self._shade(box, (10, 10, 10, 215))
        self.canvas.blit(text, text.get_rect(midtop=(box.centerx, box.top + 10)))
        y = box.top + 16 + text.get_height()
        for s in small:
            self.canvas.blit(s, (box.left + 16, y))
            y += s.get_height() + 4

    def _draw_route(self) -> bool:
        """The reference path on the ground in the camera view, where it is in sight; whether any of it is."""
        sim = self.sim
        x, y, yaw = sim.vehicle.pose
        s0, _ = sim.path.project(np.array([x, y]))
        s = np.clip(np.arange(s0 + PATH_AHEAD_M[0], s0 + PATH_AHEAD_M[1], 0.25), 0.0, sim.path.length_m)
        d = sim.path.point_at(s) - (x, y)
        c, sn = math.cos(yaw), math.sin(yaw)
        local = np.stack([c * d[:, 0] + sn * d[:, 1], -sn * d[:, 0] + c * d[:, 1]], axis=1)
        uv, visible = sim.camera.project_ground(local)
        in_sight = False
        for run in np.split(np.arange(len(s)), np.flatnonzero(np.diff(visible.astype(int))) + 1):
            if visible[run[0]] and len(run) > 1:
                points = [(float(u), float(v)) for u, v in uv[run]]
                pygame.draw.lines(self.canvas, OUTLINE_COLOR, False, points, 6)
                pygame.draw.lines(self.canvas, PATH_COLOR, False, points, 3)
                in_sight = True
        return in_sight

    def _draw_trajectories(self, label: int) -> None:
        for i, runs in enumerate(self.segments):
            if i == label:
                continue
            for run in runs:
                if len(run) > 1:
                    pygame.draw.aalines(self.canvas, TRAJ_COLOR, False, run)
        for run in self.segments[label]:
            if len(run) > 1:
                pygame.draw.lines(self.canvas, OUTLINE_COLOR, False, run, 7)
                pygame.draw.lines(self.canvas, HIGHLIGHT_COLOR, False, run, 4)
            for u, v in (run[0], run[-1]):
                pygame.draw.circle(self.canvas, OUTLINE_COLOR, (u, v), 5)
                pygame.draw.circle(self.canvas, HIGHLIGHT_COLOR, (u, v), 3)

    def _draw_inset(self, trace_px: Sequence[tuple[float, float]], pushes_px: Sequence[tuple[float, float]] = ()) -> None:
        canvas = self.canvas
        ox, oy = self.inset_origin
        canvas.blit(
            self.font.render("map (north up; red dots: pushes)" if pushes_px else "map (north up)", True, DIM_TEXT), (ox, PANEL_MARGIN_PX)
        )
        canvas.blit(self.inset, (ox, oy))
        pygame.draw.rect(canvas, DIM_TEXT, pygame.Rect(ox - 1, oy - 1, self.inset_size[0] + 2, self.inset_size[1] + 2), 1)
        clip = canvas.get_clip()
        canvas.set_clip(pygame.Rect(ox, oy, *self.inset_size))
        if len(self.path_px) > 1:
            pygame.draw.lines(canvas, OUTLINE_COLOR, False, self.path_px, 3)
            pygame.draw.lines(canvas, PATH_COLOR, False, self.path_px, 2)
        pygame.draw.circle(canvas, PATH_COLOR, self.path_px[-1], 4, 1)
        if len(trace_px) > 1:
            pygame.draw.lines(canvas, TRACE_COLOR, False, trace_px, 2)
        for point in pushes_px:
            pygame.draw.circle(canvas, ALERT_COLOR, point, 3)
        x, y, yaw = self.sim.vehicle.pose
        cx, cy = self.to_inset(x, y)
        c, s = math.cos(yaw), math.sin(yaw)
        r = 7.0
        # A triangle pointing along the heading (canvas y grows southward, hence -sin).
        tip = (cx + r * c, cy - r * s)
        left = (cx - 0.6 * r * c - 0.5 * r * s, cy + 0.6 * r * s - 0.5 * r * c)
        right = (cx - 0.6 * r * c + 0.5 * r * s, cy + 0.6 * r * s + 0.5 * r * c)
        pygame.draw.polygon(canvas, VEHICLE_COLOR, (tip, left, right))
        pygame.draw.polygon(canvas, OUTLINE_COLOR, (tip, left, right), 1)
        canvas.set_clip(clip)

    def _draw_gauge(self, w: float, label: int) -> None:
        """A horizontal stick gauge: one tick per command in A, the label's tick and w's marker."""
        canvas = self.canvas
        x0 = self.inset_origin[0]
        y0 = self.inset_origin[1] + self.inset_size[1] + 12
        width = INSET_WIDTH_PX
        canvas.blit(self.font.render("stick w [rad/s]   left <  > right", True, DIM_TEXT), (x0, y0))
        y = y0 + 26
        grid = np.asarray(self.control.w_rps, dtype=float)
        w_max = float(np.abs(grid).max())

        def gx(value: float) -> float:  # w = +w_max (left) is drawn at the left end
            return x0 + (w_max - value) / (2 * w_max) * width

        pygame.draw.line(canvas, DIM_TEXT, (x0, y), (x0 + width, y), 1)
        for i, wi in enumerate(grid):
            h = 9 if i == label else 4
            pygame.draw.line(canvas, HIGHLIGHT_COLOR if i == label else DIM_TEXT, (gx(wi), y - h), (gx(wi), y + h), 3 if i == label else 1)
        pygame.draw.circle(canvas, TRACE_COLOR, (gx(float(np.clip(w, -w_max, w_max))), y), 5)

    def _draw_legend(self) -> None:
        """The terrain colours in two columns, then the instructions."""
        canvas = self.canvas
        x0 = self.inset_origin[0]
        y0 = self.inset_origin[1] + self.inset_size[1] + 52
        classes = self.sim.world.classes.classes
        half = (len(classes) + 1) // 2
        column = 18 + max(self.font.size(c.name)[0] for c in classes[:half]) + 12  # the second column's offset [px]
        for i, c in enumerate(classes):
            x, y = x0 + (i // half) * column, y0 + (i % half) * 18
            pygame.draw.rect(canvas, c.color, pygame.Rect(x, y + 2, 12, 12))
            canvas.blit(self.font.render(c.name, True, TEXT_COLOR), (x + 18, y))
        y = y0 + half * 18
        for colour, name, x in ((PATH_COLOR, "route to follow", x0), (TRACE_COLOR, "your trace", x0 + column)):
            pygame.draw.line(canvas, colour, (x, y + 8), (x + 12, y + 8), 3)
            canvas.blit(self.font.render(name, True, TEXT_COLOR), (x + 18, y))
        y += 18 + 8
        for line in self.instructions:
            canvas.blit(self.font.render(line, True, DIM_TEXT), (x0, y))
            y += 17
