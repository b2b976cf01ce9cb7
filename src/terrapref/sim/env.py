"""Gymnasium environments over the simulation loop.

Registered as ``terrapref/OffRoadNav-v1`` (discrete actions: an index into the control set)
and ``terrapref/OffRoadNavContinuous-v1`` (actions in [-1, 1]^2 scaled to (v, w)). One step is
one camera frame (0.1 s at the default 10 Hz). The spaces do not depend on the course, so one
policy and one vector env serve every course (docs/gymnasium.md).

Example:
    >>> import gymnasium as gym
    >>> import terrapref.sim.env  # registers the ids
    >>> env = gym.make("terrapref/OffRoadNav-v1", scenario="demo_course")
    >>> obs, info = env.reset(seed=0)
    >>> obs["image"].shape, obs["image"].dtype.name
    ((120, 160, 1), 'uint8')
    >>> obs, reward, terminated, truncated, info = env.step(10)  # straight ahead
    >>> sorted(info["reward_terms"])
    ['collision', 'contact', 'cross_track', 'goal', 'off_map', 'progress', 'terrain']
    >>> OffRoadNavEnv("demo_course", EnvConfig(image_size=(60, 80)), n_waypoints=4).observation_space["waypoints"].shape
    (8,)
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Literal

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.error import InvalidAction, ResetNeeded

from terrapref.camera import CameraConfig
from terrapref.errors import UserError, one_line
from terrapref.perception import Perceiver, PerceptionModel, load_perception
from terrapref.scenario import Scenario, resolve_scenario
from terrapref.sim.loop import Frame, SimConfig, Simulation
from terrapref.terrain import ClassTable, load_classes
from terrapref.terrain.profile import PreferenceProfile
from terrapref.vehicle import Command, ControlSet, Pose, wrap_angle

ENV_ID = "terrapref/OffRoadNav-v1"
ENV_ID_CONTINUOUS = "terrapref/OffRoadNavContinuous-v1"
MAX_EPISODE_STEPS = 7200  # 12 simulated minutes at 10 Hz: twice the longest packaged course at 1 m/s, plus a minute
RANDOM_COURSE = "gen:*"  # a freshly generated course at every reset
RANDOM_COURSE_SEEDS = (1_000_000, 2_000_000)  # far from the layouts the docs choose and measure on (below 10,000)
START_DRAWS = 20  # jittered starts drawn at a reset before the start unjittered is taken
WAYPOINT_RANGE_M = 50.0  # waypoints and offsets are clipped to this, so the spaces are course-independent
TOP_DOWN_SPAN_M = 30.0  # side of the square around the vehicle that the top-down view shows
_SIM_CACHE = 4  # simulations kept for courses seen recently (rasterising one costs 50-130 ms)


@dataclass(frozen=True)
class RewardConfig:
    """The reward, term by term; each step's terms are in ``info["reward_terms"]``.

    Attributes:
        progress_weight: per metre that the vehicle's projection on the path advanced this step.
            The advance is bounded by the distance the vehicle drove, counts backwards as well
            as forwards, and is zero unless the vehicle was within ``path_band_m`` of the path and
            on the map before and after the step (the projection follows it everywhere, so a
            detour earns nothing for the stretch it skipped).
        path_band_m: half-width of the band around the path in which progress is credited [m].
        cross_track_weight: per metre of distance from the path, every step.
        collision_penalty: per entry of the footprint onto lethal terrain; on relief, per tip past
            the vehicle's roll or pitch limit and per time a step too high holds it, as every
            summary counts them.
        contact_penalty: per second with lethal terrain under the footprint (when the episode
            goes on after an entry: ``terminate_on_lethal`` False).
        off_map_penalty: each time the vehicle leaves the map.
        goal_reward: once, on reaching the goal.
        terrain_weight: per unit of terrain cost: each metre driven on the class ranked ``r``
            (0 = most preferred) in the env's profile costs ``terrain_growth ** r``; the
            background and lethal classes cost nothing here (lethal terrain is a collision).
            0 (the default) leaves terrain preference out of the reward.
        terrain_growth: how much each later class in the profile costs per metre, relative to
            the one before (the synthetic driver's default, 1.5).
    """

    progress_weight: float = 1.0
    path_band_m: float = 5.0
    cross_track_weight: float = 0.01
    collision_penalty: float = 10.0
    contact_penalty: float = 10.0
    off_map_penalty: float = 10.0
    goal_reward: float = 10.0
    terrain_weight: float = 0.0
    terrain_growth: float = 1.5

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if not math.isfinite(value):
                raise ValueError(f"RewardConfig.{name} must be finite, got {value!r}")
        if self.path_band_m <= 0 or self.terrain_growth <= 0:
            raise ValueError("RewardConfig.path_band_m and terrain_growth must be positive")


@dataclass(frozen=True)
class EnvConfig:
    """How an :class:`OffRoadNavEnv` observes, acts and is rewarded, whatever the course (each
    field is also a keyword of the env and of ``gym.make``).

    Attributes:
        action_type: ``discrete`` (an index into the control set) or ``continuous`` ((a_v, a_w) in [-1, 1]^2).
        image_size: the observed image's (h, w) [px], sampled from the camera's; None: the camera's own.
        image_encoding: ``ids`` (one channel of class ids) or ``onehot`` (one channel per class).
        n_waypoints: path points observed ahead.
        waypoint_spacing_m: their spacing along the path [m].
        reward: the reward's terms; None: :class:`RewardConfig`'s defaults.
        profile: the preference order the terrain reward follows (names, text, or a profile); None: the table's default.
        terminate_on_lethal: end the episode on entering lethal terrain (on relief, on a tip or a time stuck too).
        terminate_off_map: end the episode on leaving the map.
        start_jitter_m: the start is moved up to this far in x and y at each reset [m].
        start_yaw_jitter_rad: and turned up to this much [rad].
        control_set: the discrete actions; None: the default control set.
        camera: the camera; None: the default camera.
        sim: the simulation's settings; None: the defaults.
        perception: what a robot's segmentation and localisation would give (a model, a preset's
            name or a file); None: the truth.
        classes: the class table course names (packaged, ``gen:N`` or files) and the perception
            file are read with (a table or a ``terrapref-classes/1`` file); None: the default.
            A :class:`Scenario` given as it is carries its own table.
    """

    action_type: Literal["discrete", "continuous"] = "discrete"
    image_size: tuple[int, int] | None = (120, 160)
    image_encoding: Literal["ids", "onehot"] = "ids"
    n_waypoints: int = 10
    waypoint_spacing_m: float = 2.0
    reward: RewardConfig | None = None
    profile: str | Sequence[str] | PreferenceProfile | None = None
    terminate_on_lethal: bool = True
    terminate_off_map: bool = True
    start_jitter_m: float = 0.5
    start_yaw_jitter_rad: float = 0.1
    control_set: ControlSet | None = None
    camera: CameraConfig | None = None
    sim: SimConfig | None = None
    perception: PerceptionModel | str | None = None
    classes: ClassTable | str | Path | None = None

    def __post_init__(self) -> None:
        if self.action_type not in ("discrete", "continuous"):
            raise ValueError(f"action_type must be 'discrete' or 'continuous', got {self.action_type!r}")
        if self.image_encoding not in ("ids", "onehot"):
            raise ValueError(f"image_encoding must be 'ids' or 'onehot', got {self.image_encoding!r}")
        if self.n_waypoints < 1 or not self.waypoint_spacing_m > 0:
            raise ValueError("n_waypoints must be >= 1 and waypoint_spacing_m > 0")
        if not (self.start_jitter_m >= 0 and self.start_yaw_jitter_rad >= 0):
            raise ValueError("start_jitter_m and start_yaw_jitter_rad must be >= 0")
        size = self.image_size
        whole = (
            isinstance(size, (tuple, list))
            and len(size) == 2
            and all(isinstance(n, (int, np.integer)) and not isinstance(n, bool) for n in size)
        )
        if size is not None and not (whole and min(size) >= 1):
            raise ValueError(f"image_size must be None or two whole numbers (height, width) [px], got {size!r}")

    def with_options(self, **options: Any) -> EnvConfig:
        """This config with the fields named in ``options`` changed (as an env's keywords change it)."""
        return replace(self, **options) if options else self


class OffRoadNavEnv(gym.Env):
    """Follow a reference path across terrain, seeing only a segmentation camera.

    Observation (dict; the same spaces on every course):
        image: the segmentation image sampled to ``image_size`` by nearest pixel (class ids are
            never interpolated), channels last, uint8. ``image_encoding="ids"``: one channel of
            class ids (255 unknown). ``"onehot"``: one channel per class of the class table (in
            table order), 255 where the pixel is of that class, else 0.
        pose: (signed distance from the path [m], left positive; heading relative to the
            path's direction [rad]; share of the path done, 0-1), float32.
        waypoints: the next ``n_waypoints`` path points, ``waypoint_spacing_m`` apart ahead of
            the vehicle's progress, in the vehicle frame (x forward, y left) [m], flattened to
            (x0, y0, x1, y1, ...), float32. Distances are clipped to +-50 m.
    Action: discrete, an index 0..20 into the control set; continuous, (a_v, a_w) in [-1, 1],
        v = (a_v + 1) / 2 x max speed, w = a_w x max yaw rate.
    Info: ``progress_m``, the progress the reward credits, summed from the start's place on the
        path (it grows by at most the distance driven in a step, and not at all outside the
        path band); ``path_position_m``, where the vehicle projects onto the path now (it follows
        the vehicle out of the band and may jump where the path passes near itself);
        ``reward_terms``, ``is_success``, ``collisions``, ``off_map``, ``time_s``, ``scenario``.
    Reward: :class:`RewardConfig`. Terminated at the goal (``info["is_success"]``), on entering
    lethal terrain and on leaving the map (each configurable); truncated only by the
    registered ``max_episode_steps`` (Gymnasium's TimeLimit).
    Reset: ``scenario`` may name several courses (one is drawn per reset) or ``"gen:*"`` (a new
    generated course per reset); the start is jittered by up to ``start_jitter_m`` and
    ``start_yaw_jitter_rad``. ``reset(options={"scenario": ..., "start": (x, y, yaw)})``
    overrides both for one episode.
    Construction: ``OffRoadNavEnv(scenario, config, render_mode, **options)``: every field of
    :class:`EnvConfig` is also a keyword, which overrides ``config`` (as ``gym.make(ENV_ID,
    scenario=..., image_size=...)`` passes them).
    Perception: ``perception`` (a terrapref.perception model, a preset's name or a file) makes
    the image and the pose-derived observations what a robot's segmentation and localisation
    would give; a step in which no frame arrives (late or lost) observes the last one again. The
    reward, the termination and ``info`` stay the truth's.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        scenario: str | Scenario | Sequence[str | Scenario] = "demo_course",
        config: EnvConfig | None = None,
        render_mode: str | None = None,
        **options: Any,
    ) -> None:
        config = config.with_options(**options) if config is not None else EnvConfig(**options)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.config = config
        self.courses = _courses(scenario)
        self.action_type = config.action_type
        self.control_set = config.control_set or ControlSet()
        self.reward_config = config.reward or RewardConfig()
        self.terminate_on_lethal, self.terminate_off_map = config.terminate_on_lethal, config.terminate_off_map
        self.start_jitter_m, self.start_yaw_jitter_rad = config.start_jitter_m, config.start_yaw_jitter_rad
        self.n_waypoints, self.waypoint_spacing_m = config.n_waypoints, config.waypoint_spacing_m
        self.image_encoding = config.image_encoding
        self.render_mode = render_mode
        self._camera_config, self._sim_config = config.camera, config.sim
        self._sims: OrderedDict[Any, Simulation] = OrderedDict()
        self._table = load_classes(config.classes) if isinstance(config.classes, (str, Path)) else config.classes
        self.perception = load_perception(config.perception, self._table)
        self._perceiver: Perceiver | None = None
        self._last_obs: dict[str, np.ndarray] | None = None

        # The first course fixes the class table and the camera; every later course must share them.
        first = self._simulation(self.courses[0] if self.courses[0] != RANDOM_COURSE else "gen:0")
        self.sim = first
        self._course = self.courses[0] if isinstance(self.courses[0], str) else first.scenario.name
        self.classes = first.scenario.classes
        self.profile = _profile(config.profile, self.classes)
        self._terrain_cost = self._terrain_costs()
        self._class_ids = np.array([c.id for c in self.classes.classes], dtype=np.uint8)
        self._image_hw, self._pixel_index = _image_sampling(first.camera.shape, config.image_size)
        self._full_image = self._image_hw == first.camera.shape
        self.observation_space = self._observation_space()
        self.action_space: spaces.Space = self._action_space()
        self._progress_m = 0.0
        self._credited_m = 0.0  # progress the reward credited this episode, from the start's place on the path [m]
        self._in_band = True  # within the reward's path band (RewardConfig.path_band_m)
        self._off_map = False
        self._started = False
        self._ended = False

    # --- construction -------------------------------------------------------------------------

    def _terrain_costs(self) -> np.ndarray:
        """Cost per metre driven on each class id, shape (256,): ``terrain_growth ** rank`` in the
        profile; 0 for the background, lethal classes and ids of no class."""
        cost = np.zeros(256)
        for rank, name in enumerate(self.profile.order):
            if name != self.classes.lethal_column:
                cost[list(self.classes.ids_of(name))] = self.reward_config.terrain_growth**rank
        return cost

    def _observation_space(self) -> spaces.Dict:
        """The observation's spaces, the same on every course (see the class docstring)."""
        h, w = self._image_hw
        channels = 1 if self.image_encoding == "ids" else len(self._class_ids)
        r = WAYPOINT_RANGE_M
        return spaces.Dict(
            {
                "image": spaces.Box(0, 255, (h, w, channels), np.uint8),
                "pose": spaces.Box(np.array([-r, -math.pi, 0.0], np.float32), np.array([r, math.pi, 1.0], np.float32), dtype=np.float32),
                "waypoints": spaces.Box(np.float32(-r), np.float32(r), (2 * self.n_waypoints,), np.float32),
            }
        )

    def _action_space(self) -> spaces.Space:
        """An index into the control set, or (a_v, a_w) in [-1, 1]^2."""
        if self.action_type == "discrete":
            return spaces.Discrete(self.control_set.m)
        return spaces.Box(np.float32(-1.0), np.float32(1.0), (2,), np.float32)

    # --- courses ------------------------------------------------------------------------------

    def _simulation(self, course: str | Scenario) -> Simulation:
        """The simulation of ``course``, from the cache of recent ones when it is there."""
        key = course if isinstance(course, str) else ("scenario", id(course))
        if key in self._sims:
            self._sims.move_to_end(key)
            return self._sims[key]
        try:
            scenario = resolve_scenario(course, self._table) if isinstance(course, str) else course
        except UserError as error:  # a course name or file that is not one: refused as any bad argument is
            raise ValueError(one_line(error)) from error
        table, which = (self.classes, "the first course's") if hasattr(self, "classes") else (self._table, "classes=")
        if table is not None and not scenario.classes.same_classes(table):
            raise ValueError(f"scenario {scenario.name!r}: its class table differs from {which}; one env needs one table")
        sim = Simulation(scenario, self._camera_config, self._sim_config)
        self._sims[key] = sim
        while len(self._sims) > _SIM_CACHE:
            self._sims.popitem(last=False)
        return sim

    def _draw_course(self) -> str | Scenario:
        course = self.courses[int(self.np_random.integers(len(self.courses)))] if len(self.courses) > 1 else self.courses[0]
        if course == RANDOM_COURSE:
            return f"gen:{int(self.np_random.integers(*RANDOM_COURSE_SEEDS))}"
        return course

    # --- Gymnasium API ------------------------------------------------------------------------

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        super().reset(seed=seed)
        self._started = False  # a reset refused below leaves no episode to step on, not the last one
        if options is not None and not isinstance(options, Mapping):
            raise ValueError(f"reset options: expected a dict with 'scenario' and/or 'start', got {type(options).__name__}")
        options = dict(options or {})
        unknown = set(options) - {"scenario", "start"}
        if unknown:
            raise ValueError(f"reset options: unknown key {sorted(unknown)[0]!r}; expected 'scenario' and/or 'start'")
        course = options.get("scenario")
        if course is not None and not isinstance(course, (str, Scenario)):
            raise ValueError(f"reset options: 'scenario' must be a course name or a Scenario, got {type(course).__name__}")
        if course == RANDOM_COURSE:
            course = f"gen:{int(self.np_random.integers(*RANDOM_COURSE_SEEDS))}"
        course = course if course is not None else self._draw_course()
        self.sim = self._simulation(course)
        self._course = course if isinstance(course, str) else self.sim.scenario.name  # as info names it (gym.make takes it back)
        path = self.sim.path
        frame, pose = self._start(options.get("start"))
        if self.perception.active:
            # The first observation is the first frame as the robot's camera and localisation give
            # it; its timing applies from the first step on.
            self._perceiver = Perceiver(self.perception, self.sim.renderer, self.classes, self.sim.config.camera_rate_hz)
            self._perceiver.reset(np.random.default_rng(self.np_random.integers(2**63)))
            frame = self._perceiver.captured(frame)
        self._started, self._ended, self._off_map = True, False, False
        self._in_band = (
            abs(path.project(np.array(pose[:2]), self._progress_m - 2.0, self._progress_m + 2.0)[1]) <= self.reward_config.path_band_m
        )
        self._credited_m = self._progress_m
        terms = dict.fromkeys(("progress", "cross_track", "collision", "contact", "off_map", "goal", "terrain"), 0.0)
        self._last_obs = self._observation(frame.view, frame.pose)
        return self._last_obs, self._info(terms, success=False, off_map=False)

    def _start(self, given: Any) -> tuple[Frame, Pose]:
        """The simulation reset at the start ``given`` in reset's options (None: the scenario's own
        start, jittered): its first frame and the pose. A jittered start is drawn again, up to
        :data:`START_DRAWS` times, where it falls off the map or puts the footprint on lethal
        terrain (the scenario's file vouches for its own start alone), else the start unjittered."""
        path = self.sim.path
        if given is not None:
            try:
                start = np.asarray(given, dtype=float)
            except (TypeError, ValueError):
                start = np.zeros(0)
            if start.shape != (3,) or not np.isfinite(start).all():
                raise ValueError(f"reset options: 'start' must be three finite numbers (x [m], y [m], yaw [rad]), got {given!r}")
            if not self._on_map(start[0], start[1]):
                sx, sy = self.sim.scenario.size_m
                raise ValueError(f"reset options: 'start' ({start[0]:g}, {start[1]:g}) is off the {sx:g} x {sy:g} m map")
            pose = Pose(*map(float, start))
            self._progress_m = path.project(start[:2])[0]  # anywhere along the path
            frame = self.sim.reset(pose)
        else:
            x, y, yaw = self.sim.scenario.start
            for _ in range(START_DRAWS):
                dx, dy = self.np_random.uniform(-1.0, 1.0, 2) * self.start_jitter_m
                dyaw = self.np_random.uniform(-1.0, 1.0) * self.start_yaw_jitter_rad
                pose = Pose(x + dx, y + dy, yaw + dyaw)
                if self._on_map(pose.x, pose.y):
                    frame = self.sim.reset(pose)
                    if not (self.sim.started_in_contact or self.sim.tips):
                        break
            else:
                pose = Pose(x, y, yaw)
                frame = self.sim.reset(pose)
            self._progress_m = path.project(np.array(pose[:2]), 0.0, 5.0)[0]
        if self.sim.started_in_contact or self.sim.tips:
            where = "'start'" if given is not None else f"the start of {self.sim.scenario.name!r}"
            self._started = False
            what = (
                "the vehicle's footprint on lethal terrain" if self.sim.started_in_contact else "the vehicle past its roll or pitch limit"
            )
            raise ValueError(f"reset: {where} ({pose[0]:.2f}, {pose[1]:.2f}) puts {what}; start it clear of it")
        return frame, pose

    def _on_map(self, x: float, y: float) -> bool:
        sx, sy = self.sim.scenario.size_m
        return 0.0 <= x <= sx and 0.0 <= y <= sy

    def step(self, action: Any) -> tuple[dict, float, bool, bool, dict]:
        if not self._started:
            raise ResetNeeded("call reset() before step()")
        if self._ended:
            raise ResetNeeded(
                "the episode has ended (goal, lethal terrain, a tip or a time stuck, or off the map); call reset() before step()"
            )
        command = self._command(action)  # checked before anything changes, so a bad action leaves the env as it was
        sim, cfg = self.sim, self.reward_config
        tick0, incidents0, contact0 = len(sim.trace) - 1, sim.incidents, sim.contact_s
        frame = sim.step(command)
        trace = np.array(sim.trace[tick0:], dtype=float)
        hops = np.hypot(*np.diff(trace[:, :2], axis=0).T)
        travelled = float(hops.sum())
        sx, sy = sim.scenario.size_m
        xy = trace[1:, :2]
        off_map = bool(((xy < 0.0) | (xy > (sx, sy))).any())

        # Where the vehicle is along the path, followed even out of the path band (so observations
        # stay true); credit is the advance of that point, bounded by the distance driven, and only
        # while the vehicle stays in the band and on the map.
        s_before, in_before = self._progress_m, self._in_band
        self._progress_m, offset = sim.path.project(trace[-1, :2], s_before - 2.0 - travelled, s_before + 10.0 + travelled)
        self._in_band = abs(offset) <= cfg.path_band_m and not off_map
        advance = min(max(self._progress_m - s_before, -travelled), travelled) if (in_before and self._in_band) else 0.0
        self._credited_m += advance
        left_map = off_map and not self._off_map
        self._off_map = off_map
        collided = sim.incidents - incidents0  # on relief a tip or a time stuck counts as an entry
        end = sim.path.waypoints[-1]
        success = (
            math.hypot(trace[-1, 0] - end[0], trace[-1, 1] - end[1]) <= sim.config.goal_radius_m
            and self._progress_m >= 0.5 * sim.path.length_m
        )
        terrain_cost = float((self._terrain_cost[sim.world.class_at(xy)] * hops).sum())
        terms = {
            "progress": cfg.progress_weight * advance,
            "cross_track": -cfg.cross_track_weight * abs(offset),
            "collision": -cfg.collision_penalty * collided,
            "contact": -cfg.contact_penalty * (sim.contact_s - contact0),
            "off_map": -cfg.off_map_penalty * left_map,
            "goal": cfg.goal_reward * success,
            "terrain": -cfg.terrain_weight * terrain_cost,
        }
        terminated = bool(success or (self.terminate_on_lethal and collided > 0) or (self.terminate_off_map and off_map))
        self._ended = terminated
        return self._observe(frame), float(sum(terms.values())), terminated, False, self._info(terms, success, off_map)

    def render(self) -> np.ndarray | None:
        """``rgb_array``: a top-down view around the vehicle (path white, vehicle black with a red
        heading) beside the camera's segmentation in the class colours, (480, 1120, 3) uint8."""
        if self.render_mode != "rgb_array" or not self._started:
            return None
        palette = self.classes.palette()
        camera = palette[self.sim.frame().image]
        return np.concatenate([self._top_down(camera.shape[0]), camera], axis=1)

    # --- pieces -------------------------------------------------------------------------------

    def _command(self, action: Any) -> Command:
        a = np.asarray(action)
        if self.action_type == "discrete":
            n = self.control_set.m
            if a.shape != () or a.dtype.kind not in "iu":
                raise InvalidAction(f"a discrete action is one integer in 0..{n - 1}, got {action!r}")
            index = int(a)
            if not 0 <= index < n:
                raise InvalidAction(f"a discrete action is one integer in 0..{n - 1}, got {index}")
            return Command(*self.control_set.command(index))
        if a.shape != (2,) or a.dtype.kind not in "iuf":
            raise InvalidAction(f"a continuous action is two numbers (a_v, a_w) in [-1, 1], got {action!r}")
        a = a.astype(float)
        if not np.isfinite(a).all():
            raise InvalidAction(f"a continuous action must be finite, got {action!r}")
        a = np.clip(a, -1.0, 1.0)
        vc = self.sim.config.vehicle
        return Command(0.5 * (a[0] + 1.0) * vc.max_speed_mps, a[1] * vc.max_yaw_rate_rps)

    def _observe(self, frame) -> dict[str, np.ndarray]:
        """The observation of the frame that reached the agent this step; under a perception model
        whose frames come late or not at all, the last one again when none did."""
        got = self._perceiver(frame) if self._perceiver is not None and self.perception.active else frame
        if got is not None:
            self._last_obs = self._observation(got.view, got.pose)
        return {k: v.copy() for k, v in self._last_obs.items()}

    def _observation(self, view, pose: Pose) -> dict[str, np.ndarray]:
        ids = view.image.reshape(-1) if self._full_image else view.pixels(self._pixel_index)
        ids = ids.reshape(self._image_hw)
        if self.image_encoding == "ids":
            image = ids[:, :, None].copy()
        else:
            image = (ids[:, :, None] == self._class_ids).astype(np.uint8) * np.uint8(255)
        x, y, yaw = pose
        path, r = self.sim.path, WAYPOINT_RANGE_M
        _, offset = path.project(np.array([x, y]), self._progress_m - 2.0, self._progress_m + 10.0)
        heading = wrap_angle(yaw - float(path.heading_at(self._progress_m)))
        s = self._progress_m + self.waypoint_spacing_m * np.arange(1, self.n_waypoints + 1)
        d = path.point_at(s) - (x, y)
        c, sn = math.cos(yaw), math.sin(yaw)
        local = np.stack([c * d[:, 0] + sn * d[:, 1], -sn * d[:, 0] + c * d[:, 1]], axis=1)
        return {
            "image": image,
            "pose": np.array(
                [np.clip(offset, -r, r), np.clip(heading, -math.pi, math.pi), min(max(self._progress_m / path.length_m, 0.0), 1.0)],
                np.float32,
            ),
            "waypoints": np.clip(local, -r, r).reshape(-1).astype(np.float32),
        }

    def _info(self, terms: dict[str, float], success: bool, off_map: bool) -> dict[str, Any]:
        return {
            "scenario": self._course,
            "is_success": bool(success),
            "collisions": self.sim.collisions,
            "tips": self.sim.tips,  # on relief: entries past the roll or pitch limit
            "stuck": self.sim.stuck,  # and times a step too high held the vehicle
            "off_map": off_map,
            "progress_m": self._credited_m,
            "path_position_m": self._progress_m,
            "time_s": self.sim.time_s,
            "reward_terms": terms,
        }

    def _top_down(self, size: int) -> np.ndarray:
        sim = self.sim
        x, y, yaw = sim.vehicle.pose
        step = TOP_DOWN_SPAN_M / size
        u = (np.arange(size) + 0.5) * step - TOP_DOWN_SPAN_M / 2
        grid = np.stack(np.meshgrid(x + u, y - u), axis=-1)  # rows run north to south
        view = self.classes.palette()[sim.world.class_at(grid)]

        def to_pixels(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            col = np.floor((pts[:, 0] - x + TOP_DOWN_SPAN_M / 2) / step).astype(np.int64)
            row = np.floor((y + TOP_DOWN_SPAN_M / 2 - pts[:, 1]) / step).astype(np.int64)
            keep = (col >= 0) & (col < size) & (row >= 0) & (row < size)
            return row[keep], col[keep]

        path = sim.path.point_at(np.arange(0.0, sim.path.length_m, step))
        view[to_pixels(path)] = (255, 255, 255)
        ang = np.linspace(0.0, 2 * math.pi, 64)
        body = np.concatenate([np.stack([x + r * np.cos(ang), y + r * np.sin(ang)], axis=1) for r in np.arange(0.0, 0.6, step / 2)])
        view[to_pixels(body)] = (0, 0, 0)
        reach = np.arange(0.0, 1.5, step / 2)
        view[to_pixels(np.stack([x + reach * math.cos(yaw), y + reach * math.sin(yaw)], axis=1))] = (220, 30, 30)
        return view


def _courses(scenario: str | Scenario | Sequence[str | Scenario]) -> tuple[str | Scenario, ...]:
    """The courses a reset draws from: one, or several; never none."""
    if not isinstance(scenario, (str, Scenario, Sequence)):
        raise ValueError(f"scenario: expected a course name, a Scenario or a list of them, got {type(scenario).__name__}")
    courses = (scenario,) if isinstance(scenario, (str, Scenario)) else tuple(scenario)
    if not courses:
        raise ValueError("scenario: name at least one course")
    odd = next((c for c in courses if not isinstance(c, (str, Scenario))), None)
    if odd is not None:
        raise ValueError(f"scenario: expected course names or Scenarios, got {type(odd).__name__}")
    return courses


def _profile(profile: str | Sequence[str] | PreferenceProfile | None, classes: ClassTable) -> PreferenceProfile:
    """The preference profile the terrain reward follows: as given, parsed, or the table's default."""
    if isinstance(profile, PreferenceProfile):
        return profile
    return PreferenceProfile.parse(profile, classes, "profile") if profile is not None else PreferenceProfile.default(classes)


def _image_sampling(camera_hw: tuple[int, int], image_size: tuple[int, int] | None) -> tuple[tuple[int, int], np.ndarray]:
    """The observed image's (h, w) and, for each of its pixels, the flat index of the nearest
    camera pixel, shape (h * w,); ``image_size`` None keeps the camera's size."""
    cam_h, cam_w = camera_hw
    h, w = (cam_h, cam_w) if image_size is None else (int(image_size[0]), int(image_size[1]))
    if not (1 <= h <= cam_h and 1 <= w <= cam_w):
        raise ValueError(f"image_size must be within the camera's {cam_h} x {cam_w}, got {image_size!r}")
    rows = ((np.arange(h) + 0.5) * cam_h / h).astype(np.int64)
    cols = ((np.arange(w) + 0.5) * cam_w / w).astype(np.int64)
    return (h, w), (rows[:, None] * cam_w + cols[None, :]).reshape(-1)


def register_envs() -> None:
    """Register the environment ids with Gymnasium (idempotent)."""
    for env_id, action_type in ((ENV_ID, "discrete"), (ENV_ID_CONTINUOUS, "continuous")):
        if env_id not in gym.registry:
            gym.register(
                id=env_id,
                entry_point="terrapref.sim.env:OffRoadNavEnv",
                kwargs={"action_type": action_type},
                max_episode_steps=MAX_EPISODE_STEPS,
            )


register_envs()
