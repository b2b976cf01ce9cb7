"""The planner: at each camera frame, U from the image and the path, C, and the argmax command.

It sees only what a real robot has: the segmentation image, its own pose and the waypoints.
It never reads the world map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from terrapref.camera import CameraConfig, PinholeCamera, SegmentationView, as_view
from terrapref.features import UtilityFeaturizer
from terrapref.learning.model_file import LoadedModel, check_compatible
from terrapref.learning import exact
from terrapref.planner.offset import OffsetConfig, OffsetStage
from terrapref.planner.second_stage import SecondStage, SecondStageConfig
from terrapref.planner.policy import ClassifierPolicy, Observation, Policy
from terrapref.scenario import Scenario
from terrapref.scenario.path import PathTracker, ReferencePath
from terrapref.sim.loop import Frame
from terrapref.terrain import UNKNOWN
from terrapref.vehicle import Command, Pose


@dataclass(frozen=True)
class Decision:
    """One planning step.

    Attributes:
        index: chosen trajectory (argmax of ``probs``, or of the second stage's scores).
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


MODEL = "model"  # Planner(second_stage=MODEL): the second stage as the model was trained for it
PATH_AHEAD_M = np.arange(1.0, 9.0)  # where Observation.path_ahead samples the path [m]


class Planner:
    """A policy (the trained classifier C, or a baseline) driving by the preference set.

    Args:
        model: a loaded model file (C) or any :class:`Policy`.
        camera: the robot's camera; a model trained for another camera is refused.
        second_stage: the second stage beyond the trajectories (terrapref.planner.second_stage),
            used when the model file carries the linear utility it scores with (``terrapref
            train --second-stage``); ``MODEL`` (the default): the weight the model was trained
            with and the look-ahead its data were featurised with; None never looks beyond the
            trajectories.
        offset: the offset stage (terrapref.planner.offset), used when the model file carries
            the corridor utility it scores offsets with: the planner then steers toward the
            offset it holds, and C's distribution is still computed for every frame. ``MODEL``
            (the default): with the default :class:`OffsetConfig`; None: drive C's trajectories.
    """

    def __init__(self, model: LoadedModel | Policy, camera: CameraConfig | None = None,
                 second_stage: SecondStageConfig | str | None = "model", offset: OffsetConfig | str | None = "model") -> None:
        policy = model if isinstance(model, Policy) else ClassifierPolicy(model)
        camera = camera or policy.camera
        if isinstance(model, LoadedModel):
            check_compatible(model, camera)
        elif not policy.camera.same_geometry(camera):
            raise ValueError(f"{policy.name}: built for another camera")
        self.policy = policy
        self.camera = PinholeCamera(camera)
        self.featurizer = UtilityFeaturizer(policy.features, self.camera, policy.classes)
        self.control = policy.features.preference.control
        stage = policy.stage_utility()
        if second_stage == MODEL and stage is not None:
            look = policy.features.lookahead
            second_stage = SecondStageConfig(weight=stage.weight, **({"after_s": look.after_s, "stride": look.stride} if look else {}))
        self.second_stage = SecondStage(second_stage, self.featurizer, self.camera, stage.utility) if second_stage is not None and stage is not None else None
        corridor = policy.corridor_utility()
        self.offset_stage = None
        if offset is not None and corridor is not None:
            lethal = np.array(sorted({int(self.featurizer.class_columns[i]) for i in policy.classes.lethal_ids}), dtype=np.int64)
            self.offset_stage = OffsetStage(corridor, self.camera, self.featurizer.class_columns, policy.features.n_terrain, lethal,
                                            self.control.v_mps, None if offset == MODEL else offset)
        self.path: ReferencePath | None = None
        self.tracker: PathTracker | None = None

    def set_path(self, waypoints: np.ndarray) -> None:
        """Start following a new reference path (the offset stage forgets the ground it has seen)."""
        self.path = ReferencePath(np.asarray(waypoints, dtype=float))
        self.tracker = PathTracker(self.path)
        if self.offset_stage is not None:
            self.offset_stage.reset()

    def warm_up(self) -> None:
        """Decide once on a blank frame along a straight path, then forget that path.

        The compiled loops (docs/design.md) are loaded now, or compiled if this machine has no
        cached copy yet, instead of in the first step of a control loop.
        """
        path, tracker = self.path, self.tracker
        self.set_path(np.array([[0.0, 0.0], [20.0, 0.0]]))
        self.decide(np.full(self.camera.shape, UNKNOWN, dtype=np.uint8), Pose(0.0, 0.0, 0.0))
        self.path, self.tracker = path, tracker
        if self.offset_stage is not None:  # the blank frame is not ground seen
            self.offset_stage.reset()

    def decide(self, image: np.ndarray | SegmentationView, pose: Pose) -> Decision:
        """Choose a trajectory for one segmentation frame (H, W) uint8 at ``pose``.

        ``image`` may be a :class:`SegmentationView`, of which only the pixels the policy reads
        are rendered (the preference set's, for C).
        """
        if self.path is None or self.tracker is None:
            raise RuntimeError("call set_path() first")
        view = as_view(image)
        s = self.tracker.update(np.array(pose[:2]))
        U = self.featurizer(view, pose, self.path, s)
        ahead = path_ahead(self.path, pose, s) if self.policy.uses_path_ahead else _NO_POINTS
        probs = self.policy.probabilities(Observation(U, view, ahead))
        if self.offset_stage is not None:
            # Steered continuously within the stick's range; the index names the nearest trajectory.
            w = float(np.clip(self.offset_stage.decide(view, pose, self.path, s), self.control.w_rps[0], self.control.w_rps[-1]))
            return Decision(int(self.control.label_of(w)), Command(self.control.v_mps, w), probs, U, s)
        if self.second_stage is None:
            i = int(np.argmax(probs))
        else:  # a probability of exactly 0 is -inf, never chosen
            i = int(np.argmax(self.second_stage.scores(exact.log(probs), view, pose, self.path, s)))
        return Decision(i, Command(*self.control.command(i)), probs, U, s)


def path_ahead(path: ReferencePath, pose: Pose, progress_s: float) -> np.ndarray:
    """The path 1, 2, ... m (PATH_AHEAD_M) ahead of ``progress_s`` in the vehicle frame (P, 2) [m]."""
    x, y, yaw = pose
    c, s = math.cos(yaw), math.sin(yaw)
    d = path.point_at(progress_s + PATH_AHEAD_M) - (x, y)
    return np.stack([d[:, 0] * c + d[:, 1] * s, -d[:, 0] * s + d[:, 1] * c], axis=1)


_NO_POINTS = np.zeros((0, 2))


class PlannerDriver:
    """The planner as a :class:`terrapref.sim.Driver`; with ``keep``, keeps its decisions for later
    pictures with the number of the frame each was made on (``frames``), and the image decided on
    for the frame numbers in ``images`` (``image_of``)."""

    def __init__(self, planner: Planner, keep: bool = False, images: tuple[int, ...] = ()) -> None:
        self.planner = planner
        self.keep = keep
        self.images = frozenset(images)
        self.decisions: list[Decision] = []
        self.frames: list[int] = []
        self.image_of: dict[int, np.ndarray] = {}
        self.last: Decision | None = None  # the latest decision

    def reset(self, scenario: Scenario, rng: np.random.Generator) -> None:
        self.planner.set_path(scenario.waypoints)
        self.decisions, self.frames, self.image_of, self.last = [], [], {}, None

    def act(self, frame: Frame) -> Command:
        d = self.last = self.planner.decide(frame.view, frame.pose)
        if self.keep:
            self.decisions.append(d)
            self.frames.append(frame.index)
            if frame.index in self.images:
                self.image_of[frame.index] = frame.view.image.copy()
        return d.command
