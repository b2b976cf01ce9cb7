"""Gymnasium environment over the simulation loop.

Registered as ``terrapref/OffRoadNav-v0`` (discrete actions: an index into the control set)
and ``terrapref/OffRoadNavContinuous-v0`` (actions (v [m/s], w [rad/s])). One step is one camera
frame (0.1 s at the default 10 Hz).

Example:
    >>> import gymnasium as gym
    >>> import terrapref.sim.env  # registers the ids
    >>> env = gym.make("terrapref/OffRoadNav-v0", scenario="demo_course")
    >>> obs, info = env.reset(seed=0)
    >>> obs["image"].shape, obs["image"].dtype.name
    ((480, 640), 'uint8')
    >>> obs, reward, terminated, truncated, info = env.step(10)  # straight ahead
"""

from __future__ import annotations

import math
from typing import Any, Literal

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from terrapref.camera import CameraConfig
from terrapref.scenario import Scenario, resolve_scenario
from terrapref.sim.loop import Frame, SimConfig, Simulation
from terrapref.vehicle import Command, ControlSet, Pose

ENV_ID = "terrapref/OffRoadNav-v0"
ENV_ID_CONTINUOUS = "terrapref/OffRoadNavContinuous-v0"


class OffRoadNavEnv(gym.Env):
    """Follow a reference path across terrain, seeing only a segmentation camera.

    Observation (dict):
        image: segmentation image, (H, W) uint8 class ids (255 unknown).
        pose: (x [m], y [m], yaw [rad]) in the world frame, float32.
        waypoints: the next ``n_waypoints`` path points ahead of the vehicle's progress,
            (n_waypoints, 2) [m] world frame, float32 (the last one repeated near the end).
    Reward: metres of progress along the path, minus ``collision_penalty`` per entry onto
    lethal terrain and ``cross_track_weight`` x |cross-track error| [m] per step.
    Terminated at the goal; truncated at the time limit.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        scenario: str | Scenario = "demo_course",
        action_type: Literal["discrete", "continuous"] = "discrete",
        control_set: ControlSet | None = None,
        camera: CameraConfig | None = None,
        sim: SimConfig | None = None,
        n_waypoints: int = 10,
        waypoint_spacing_m: float = 2.0,
        collision_penalty: float = 10.0,
        cross_track_weight: float = 0.01,
        start_jitter_m: float = 0.0,
        render_mode: str | None = None,
    ) -> None:
        self.scenario = resolve_scenario(scenario) if isinstance(scenario, str) else scenario
        self.sim = Simulation(self.scenario, camera, sim)
        self.control_set = control_set or ControlSet()
        self.action_type = action_type
        self.n_waypoints = n_waypoints
        self.waypoint_spacing_m = waypoint_spacing_m
        self.collision_penalty = collision_penalty
        self.cross_track_weight = cross_track_weight
        self.start_jitter_m = start_jitter_m
        self.render_mode = render_mode
        h, w = self.sim.camera.shape
        sx, sy = self.scenario.size_m
        reach = 1e3  # poses may leave the map; keep the space finite but generous
        self.observation_space = spaces.Dict(
            {
                "image": spaces.Box(0, 255, (h, w), np.uint8),
                "pose": spaces.Box(
                    np.array([-reach, -reach, -math.pi], np.float32),
                    np.array([sx + reach, sy + reach, math.pi], np.float32),
                    dtype=np.float32,
                ),
                "waypoints": spaces.Box(np.float32(-reach), np.float32(max(sx, sy) + reach), (n_waypoints, 2), np.float32),
            }
        )
        if action_type == "discrete":
            self.action_space: spaces.Space = spaces.Discrete(self.control_set.m)
        elif action_type == "continuous":
            vc = self.sim.config.vehicle
            self.action_space = spaces.Box(
                np.array([0.0, -vc.max_yaw_rate_rps], np.float32), np.array([vc.max_speed_mps, vc.max_yaw_rate_rps], np.float32), dtype=np.float32
            )
        else:
            raise ValueError(f"action_type must be 'discrete' or 'continuous', got {action_type!r}")
        self._frame: Frame | None = None

    def _observation(self, frame: Frame) -> dict[str, np.ndarray]:
        s = self.sim.progress_s + self.waypoint_spacing_m * np.arange(1, self.n_waypoints + 1)
        x, y, yaw = frame.pose
        yaw = (yaw + math.pi) % (2 * math.pi) - math.pi
        return {
            "image": frame.image,
            "pose": np.array([x, y, yaw], np.float32),
            "waypoints": self.sim.path.point_at(s).astype(np.float32),
        }

    def _info(self) -> dict[str, Any]:
        return {"collisions": self.sim.collisions, "progress_m": self.sim.progress_s, "time_s": self.sim.time_s}

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple[dict, dict]:
        super().reset(seed=seed)
        x, y, yaw = self.scenario.start
        if self.start_jitter_m > 0:
            dx, dy = self.np_random.uniform(-self.start_jitter_m, self.start_jitter_m, 2)
            x, y = x + dx, y + dy
        self._frame = self.sim.reset(Pose(x, y, yaw))
        return self._observation(self._frame), self._info()

    def step(self, action: Any) -> tuple[dict, float, bool, bool, dict]:
        if self._frame is None:
            raise RuntimeError("call reset() before step()")
        if self.action_type == "discrete":
            cmd = Command(*self.control_set.command(int(action)))
        else:
            a = np.asarray(action, dtype=float)
            cmd = Command(float(a[0]), float(a[1]))
        progress0, collisions0 = self.sim.progress_s, self.sim.collisions
        self._frame = self.sim.step(cmd)
        _, offset = self.sim.path.project(self._frame.pose[:2], self.sim.progress_s - 2.0, self.sim.progress_s + 2.0)
        reward = (
            (self.sim.progress_s - progress0)
            - self.collision_penalty * (self.sim.collisions - collisions0)
            - self.cross_track_weight * abs(offset)
        )
        return self._observation(self._frame), float(reward), self.sim.reached_goal, self.sim.timed_out and not self.sim.reached_goal, self._info()

    def render(self) -> np.ndarray | None:
        if self.render_mode != "rgb_array" or self._frame is None:
            return None
        return self.scenario.classes.palette()[self._frame.image]


def register_envs() -> None:
    """Register the environment ids with Gymnasium (idempotent)."""
    for env_id, action_type in ((ENV_ID, "discrete"), (ENV_ID_CONTINUOUS, "continuous")):
        if env_id not in gym.registry:
            gym.register(id=env_id, entry_point="terrapref.sim.env:OffRoadNavEnv", kwargs={"action_type": action_type})


register_envs()
