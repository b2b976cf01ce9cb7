"""A run's frames as the robot receives them: through a perception model, in time or late or not at all.

:class:`Perceiver` turns each true frame of a run into what the robot's computer gets:

- the camera's attitude wanders (an Ornstein-Uhlenbeck process per axis), so the frame shows
  the ground a tilted camera sees, while the planner still assumes the nominal mount;
- the segmentation labels it with errors (terrapref.perception.labels);
- the pose it is told carries white noise and a slowly drifting offset;
- its depth image carries a depth camera's noise, dropouts and range;
- it arrives ``delay`` camera periods after it was taken (a share of frames one more), or never;
  a frame older than one already delivered is stale and dropped, as
  :class:`terrapref.interop.runtime.PlannerRuntime` drops it.

Each part draws from its own random stream, so switching one part on or off leaves the others'
draws as they were. :class:`PerceivedDriver` puts a planner behind a perceiver and holds its
last command for ``COMMAND_HOLD_S`` after the frame's stamp, then stops the vehicle, as the
runtime does; a demonstration is recorded through a perceiver by
terrapref.demos.session.RecordLoop.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import replace
from typing import Any, Protocol

import numpy as np

from terrapref.camera import PixelSet, SegmentationRenderer, SegmentationView
from terrapref.perception.labels import LabelledView, LabelNoise
from terrapref.perception.model import DepthErrors, PerceptionModel
from terrapref.stops import STALE, held_too_long, stop_reason_of
from terrapref.terrain import ClassTable
from terrapref.vehicle import Command, Pose
from terrapref.vehicle.ground import LEVEL, Attitude

COMMAND_HOLD_S = 0.3
"""How long a decision's command stays in force after its frame's stamp [s]; then the vehicle stops."""

STOP = Command(0.0, 0.0)


class Frame(Protocol):
    """A camera frame as the simulation hands it to a driver (:class:`terrapref.sim.Frame`, a dataclass)."""

    index: int  # frame number since the run began
    time_s: float  # when it was taken [s]
    view: SegmentationView
    pose: Pose
    attitude: Attitude  # the body's on the ground


class Driver(Protocol):
    """Anything that turns frames into commands (:class:`terrapref.sim.Driver`)."""

    def reset(self, scenario: Any, rng: np.random.Generator) -> None: ...

    def act(self, frame: Any) -> Command: ...


class TiltedView(SegmentationView):
    """The true ground through the camera at an attitude off its mount, up to ``max_range_m`` along
    each ray (None: the camera's own range), rendered as far as it is read. The depth image, and
    on relief the whole frame, is rendered with the wander added to the body's ``attitude``
    (pitch down, roll); the view's :attr:`attitude` stays the body's (the robot does not know
    the wander)."""

    __slots__ = ("_tilt",)

    def __init__(
        self,
        renderer: SegmentationRenderer,
        pose: Pose,
        dpitch_rad: float,
        droll_rad: float,
        max_range_m: float | None = None,
        attitude: Attitude = LEVEL,
    ) -> None:
        super().__init__(renderer, pose, attitude=attitude)
        self._tilt = (dpitch_rad, droll_rad, max_range_m)

    @property
    def image(self) -> np.ndarray:
        if self._image is None and not self._renderer.relief:
            h, w = self._renderer.shape
            self._image = self._renderer.pixels_tilted(self._pose, np.arange(h * w, dtype=np.int64), *self._tilt).reshape(h, w)
        return super().image

    def _with_depth(self) -> tuple[np.ndarray, np.ndarray]:
        a, (dpitch_rad, droll_rad, max_range_m) = self._attitude, self._tilt
        return self._renderer.render_with_depth(self._pose, Attitude(a.z_m, a.pitch_rad + dpitch_rad, a.roll_rad + droll_rad), max_range_m)

    def pixels(self, flat_index: np.ndarray | PixelSet) -> np.ndarray:
        if self._image is None and not self._renderer.relief:
            return self._renderer.pixels_tilted(self._pose, flat_index, *self._tilt)
        return super().pixels(flat_index)


class DepthErrorView(SegmentationView):
    """``base``'s labels, and its depth image with a depth camera's errors (:class:`DepthErrors`),
    drawn from ``seed`` when first read (so a frame's errors do not depend on whether, or when,
    its depth is read)."""

    __slots__ = ("_base", "_errors", "_seed")

    def __init__(self, base: SegmentationView, errors: DepthErrors, seed: int) -> None:
        self._image, self._renderer, self._pose, self._attitude, self._depth = None, None, None, LEVEL, None
        self._base, self._errors, self._seed = base, errors, seed

    @property
    def shape(self) -> tuple[int, int]:
        return self._base.shape

    @property
    def image(self) -> np.ndarray:
        return self._base.image

    def pixels(self, flat_index: np.ndarray | PixelSet) -> np.ndarray:
        return self._base.pixels(flat_index)

    @property
    def carries_depth(self) -> bool:
        return self._base.carries_depth

    @property
    def attitude(self) -> Attitude:
        return self._base.attitude

    @property
    def depth(self) -> np.ndarray | None:
        if self._depth is None:
            true = self._base.depth
            if true is None:
                return None
            e, rng = self._errors, np.random.default_rng(self._seed)
            noisy = true + (e.noise_m * true * true * rng.standard_normal(true.shape)).astype(np.float32)
            gone = rng.random(true.shape) < e.dropout_rate
            if e.max_range_m is not None:
                gone |= ~(true <= e.max_range_m)
            self._depth = np.where(gone | ~(noisy > 0), np.float32(np.nan), noisy).astype(np.float32)
        return self._depth


class Perceiver:
    """What the robot receives of one run's frames under ``model``.

    Args:
        model: the perception model.
        renderer: the run's renderer (the true world through the robot's camera).
        classes: the class table (label errors draw from it).
        camera_rate_hz: frames per second [Hz].
    """

    def __init__(self, model: PerceptionModel, renderer: SegmentationRenderer, classes: ClassTable, camera_rate_hz: float = 10.0) -> None:
        self.model, self.renderer = model, renderer
        self.labels = LabelNoise(model.labels, renderer.camera, classes, range_in_view=model.camera.active) if model.labels.active else None
        cam = model.camera
        self._rho = math.exp(-1.0 / (camera_rate_hz * cam.jitter_time_s)) if cam.jitter_time_s > 0 else 0.0
        self._sigma = np.radians([cam.pitch_jitter_deg, cam.roll_jitter_deg])
        self.reset(np.random.default_rng(0))

    def reset(self, rng: np.random.Generator) -> None:
        """Start a run: every part's random stream seeded from ``rng``, no drift, no frame pending."""
        self._rng_labels, self._rng_pose, self._rng_camera, self._rng_frames, self._rng_depth = (
            np.random.default_rng(rng.integers(2**63)) for _ in range(5)
        )
        if self.labels is not None:
            self.labels.reset(self._rng_labels)
        self._drift = np.zeros(3)  # x [m], y [m], yaw [rad]
        self._last_xy: tuple[float, float] | None = None
        self._attitude = self._rng_camera.normal(0.0, 1.0, 2) * self._sigma if self.model.camera.active else np.zeros(2)
        self._pending: list[tuple[int, Any]] = []  # (period it arrives in, the frame as captured)
        self._delivered = -1  # the index of the newest frame delivered

    def captured(self, frame: Frame) -> Any:
        """``frame`` as the robot's camera, segmentation and localisation give it (before its timing)."""
        m = self.model
        view = frame.view
        if m.camera.active:
            self._attitude = self._rho * self._attitude + math.sqrt(1.0 - self._rho**2) * self._sigma * self._rng_camera.normal(0.0, 1.0, 2)
            attitude = getattr(frame, "attitude", LEVEL)
            view = TiltedView(self.renderer, frame.pose, float(self._attitude[0]), float(self._attitude[1]), m.labels.max_range_m, attitude)
        if self.labels is not None:
            view = LabelledView(view, self.labels.draw(self._rng_labels, frame.index))
        if m.depth.active:
            view = DepthErrorView(view, m.depth, int(self._rng_depth.integers(2**63)))
        return replace(frame, view=view, pose=self._told(frame.pose))

    def _told(self, pose: Pose) -> Pose:
        """The pose the robot's localisation gives at ``pose``: the drift walked over the distance
        driven since the last frame, plus this frame's white noise."""
        p = self.model.pose
        if not p.active:
            return pose
        x, y, yaw = (float(v) for v in pose)
        if p.drift_m_per_m or p.drift_deg_per_m:
            driven = 0.0 if self._last_xy is None else math.hypot(x - self._last_xy[0], y - self._last_xy[1])
            scale = math.sqrt(driven)
            step = self._rng_pose.normal(0.0, 1.0, 3) * scale
            self._drift += step * (p.drift_m_per_m, p.drift_m_per_m, math.radians(p.drift_deg_per_m))
        self._last_xy = (x, y)
        noise = self._rng_pose.normal(0.0, 1.0, 3) * (p.noise_m, p.noise_m, math.radians(p.noise_deg))
        e = self._drift + noise
        return Pose(x + float(e[0]), y + float(e[1]), yaw + float(e[2]))

    def __call__(self, frame: Frame) -> Any:
        """The frame that reaches the robot in ``frame``'s period (the newest due, taken then or
        earlier), or None when none does."""
        timing = self.model.frames
        got = self.captured(frame)
        lost = timing.drop_rate > 0 and self._rng_frames.random() < timing.drop_rate
        late = timing.late_rate > 0 and self._rng_frames.random() < timing.late_rate
        if not lost:
            self._pending.append((frame.index + timing.delay + int(late), got))
        due = [f for when, f in self._pending if when <= frame.index]
        if not due:
            return None
        self._pending = [(when, f) for when, f in self._pending if when > frame.index]
        newest = max(due, key=lambda f: f.index)
        if newest.index <= self._delivered:  # stale: a newer frame was already delivered
            return None
        self._delivered = newest.index
        return newest


def run_stream(rng: np.random.Generator, scenario_name: str, draw: int = 0) -> np.random.Generator:
    """A run's perception stream: one draw from ``rng`` keyed by the scenario's name, so that runs
    with the same seed on different layouts see different errors (one drift, one set of
    mislabelled frames shared by every layout of a study would bias all of them alike), and by
    ``draw`` where it is not 0, so that several models driving the same layout with the same seed
    can each meet errors of their own."""
    keys = [int(rng.integers(2**63)), zlib.crc32(scenario_name.encode())]
    return np.random.default_rng(keys + [draw] if draw else keys)


class PerceivedDriver:
    """A driver (a planner) seeing through a :class:`Perceiver` (a :class:`terrapref.sim.Driver`).

    A frame that arrives is decided on; when none does, the last command is held while its
    frame is at most ``hold_s`` old, and the vehicle stops after that, until a frame arrives.
    """

    def __init__(self, inner: Driver, perceiver: Perceiver, hold_s: float = COMMAND_HOLD_S, draw: int = 0) -> None:
        self.inner, self.perceiver, self.hold_s, self.draw = inner, perceiver, hold_s, draw
        self.stops = 0  # periods the vehicle was stopped for want of a fresh frame
        self.stop_reason: str | None = None  # why the last command stops (the inner driver's, or stale)
        self._last: Command | None = None
        self._last_reason: str | None = None
        self._stamp_s = -math.inf

    def reset(self, scenario: Any, rng: np.random.Generator) -> None:
        self.inner.reset(scenario, rng)
        self.perceiver.reset(run_stream(rng, getattr(scenario, "name", ""), self.draw))
        self._last, self._last_reason, self._stamp_s, self.stops, self.stop_reason = None, None, -math.inf, 0, None

    def act(self, frame: Frame) -> Command:
        got = self.perceiver(frame)
        if got is not None:
            self._last, self._stamp_s = self.inner.act(got), got.time_s
            self._last_reason = stop_reason_of(self.inner)
        if self._last is not None and not self._stale(frame.time_s):
            self.stop_reason = self._last_reason
            return self._last
        self.stops += 1
        self.stop_reason = STALE
        return STOP

    def _stale(self, now_s: float) -> bool:
        """Whether the command held is stale at ``now_s``: as the inner driver's stop rule says
        (a planner's: terrapref.planner.stop), or for a driver without one, held over ``hold_s``."""
        stale = getattr(self.inner, "stale", held_too_long)
        return stale(now_s, self._stamp_s, self.hold_s)
