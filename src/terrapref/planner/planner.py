"""The planner: at each camera frame, U from the image and the path, C, and the argmax command.

It sees only what a real robot has: the segmentation image, its own pose and the waypoints.
It never reads the world map.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from terrapref.camera import CameraConfig, PinholeCamera
from terrapref.features import UtilityFeaturizer
from terrapref.learning.model_file import LoadedModel, check_compatible
from terrapref.learning.network import numpy_forward, softmax
from terrapref.scenario import Scenario
from terrapref.scenario.path import PathTracker, ReferencePath
from terrapref.sim.loop import Frame
from terrapref.vehicle import Command, Pose


@dataclass(frozen=True)
class Decision:
    """One planning step.

    Attributes:
        index: chosen trajectory (argmax of ``probs``).
        command: its (v [m/s], w [rad/s]).
        probs: F_t, shape (m,).
        U: utility features, shape (m, K + 1).
        progress_s: the vehicle's progress along the path [m].
    """

    index: int
    command: Command
    probs: np.ndarray
    U: np.ndarray
    progress_s: float


class Planner:
    """A trained classifier driving by the preference set.

    Args:
        model: a loaded model file.
        camera: the robot's camera; a model trained for another camera is refused.
        smoothing: weight of the previous frames in an exponential average of F_t before the
            argmax (0: the paper's memoryless planner). When the classifier is unsure between
            passing a patch left or right, a memoryless argmax can flip sides every frame and
            average out to driving straight into it; the average lets it commit.
    """

    def __init__(self, model: LoadedModel, camera: CameraConfig | None = None, smoothing: float = 0.0) -> None:
        if not 0.0 <= smoothing < 1.0:
            raise ValueError("smoothing must be in [0, 1)")
        self.smoothing = smoothing
        self._avg: np.ndarray | None = None
        camera = camera or model.camera
        check_compatible(model, camera)
        self.model = model
        self.camera = PinholeCamera(camera)
        self.featurizer = UtilityFeaturizer(model.features, self.camera, model.classes)
        self.control = model.features.preference.control
        self._weights = model.weights
        self.path: ReferencePath | None = None
        self.tracker: PathTracker | None = None

    def set_path(self, waypoints: np.ndarray) -> None:
        """Start following a new reference path."""
        self.path = ReferencePath(np.asarray(waypoints, dtype=float))
        self.tracker = PathTracker(self.path)
        self._avg = None

    def decide(self, image: np.ndarray, pose: Pose) -> Decision:
        """Choose a trajectory for one segmentation frame (H, W) uint8 at ``pose``."""
        if self.path is None or self.tracker is None:
            raise RuntimeError("call set_path() first")
        s = self.tracker.update(np.array(pose[:2]))
        U = self.featurizer(image, pose, self.path, s)
        probs = softmax(numpy_forward(self.model.classifier, self._weights, U))
        if self.smoothing > 0:
            self._avg = probs if self._avg is None else self.smoothing * self._avg + (1 - self.smoothing) * probs
            probs = self._avg
        i = int(np.argmax(probs))
        return Decision(i, Command(*self.control.command(i)), probs, U, s)


class PlannerDriver:
    """The planner as a :class:`terrapref.sim.Driver`; keeps its decisions for later pictures."""

    def __init__(self, planner: Planner, keep: bool = False) -> None:
        self.planner = planner
        self.keep = keep
        self.decisions: list[Decision] = []

    def reset(self, scenario: Scenario, rng: np.random.Generator) -> None:
        self.planner.set_path(scenario.waypoints)
        self.decisions = []

    def act(self, frame: Frame) -> Command:
        d = self.planner.decide(frame.image, frame.pose)
        if self.keep:
            self.decisions.append(d)
        return d.command
