"""The planner for a robot's control loop, without the simulator: label images in, commands out.

A ROS 2 node (docs/robot.md, "A ROS 2 node") wraps :class:`PlannerRuntime`: it passes each label image
with its stamp and the robot's pose at that stamp, sends ``command_at(now)`` at its own rate,
and publishes the trajectory probabilities if it likes. Nothing here needs ROS.

Safety: the last decision's command is held for ``hold_s`` after its frame's stamp; past that
(the camera stopped, frames are late) the runtime commands a stop until a fresh frame arrives.
An image of the wrong size, a camera other than the model's, or labels outside the map are
refused with a ``ValueError`` rather than driven on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from terrapref.camera import CameraConfig
from terrapref.interop.labels import LabelMap
from terrapref.learning.model_file import LoadedModel, load_model
from terrapref.planner.costmap import Costmap
from terrapref.planner.planner import Planner
from terrapref.vehicle import Command, Pose

STOP = Command(0.0, 0.0)


@dataclass(frozen=True)
class RuntimeDecision:
    """One frame's decision.

    Attributes:
        stamp_s: the frame's stamp [s].
        command: (v [m/s], w [rad/s]) of the chosen trajectory.
        index: the chosen trajectory (0..m-1, the control set's order).
        probs: C's F_t over the m trajectories.
        progress_m: progress along the path [m].
        U: the frame's utility features (m, K + 1), as C saw them.
    """

    stamp_s: float
    command: Command
    index: int
    probs: np.ndarray
    progress_m: float
    U: np.ndarray


class PlannerRuntime:
    """A trained model driving from label images.

    Args:
        model: a model file (``terrapref train``) or a loaded model.
        camera: the robot's camera; a model trained for another one is refused (default: the
            model's own).
        labels: the segmentation network's label map; images then hold its ids (uint8 or
            uint16) and are mapped onto the model's classes. None: images hold terrapref class
            ids (uint8, 255 unknown).
        hold_s: how long a decision's command stays in force after its frame's stamp [s].
    """

    def __init__(self, model: str | Path | LoadedModel, camera: CameraConfig | None = None, labels: LabelMap | None = None, hold_s: float = 0.3) -> None:
        if not (math.isfinite(hold_s) and hold_s >= 0):
            raise ValueError("hold_s must be a finite number >= 0")
        self.model = model if isinstance(model, LoadedModel) else load_model(model)
        self.planner = Planner(self.model, camera)  # refuses a camera the model was not trained for
        self.planner.warm_up()  # the compiled loops ready before the first frame
        self.shape = self.planner.camera.shape
        self.lut = labels.lut(self.model.classes) if labels is not None else None
        self.hold_s = hold_s
        self.last: RuntimeDecision | None = None

    def set_path(self, waypoints: np.ndarray) -> None:
        """Follow a new reference path, (N, 2) [m] in the frame the poses are given in."""
        waypoints = np.asarray(waypoints, dtype=float)
        if waypoints.ndim != 2 or waypoints.shape[1] != 2 or len(waypoints) < 2 or not np.isfinite(waypoints).all():
            raise ValueError(f"a path is at least two finite (x, y) points, got shape {waypoints.shape}")
        self.planner.set_path(waypoints)
        self.last = None

    def decide(self, image: np.ndarray, stamp_s: float, pose: Pose | tuple[float, float, float]) -> RuntimeDecision | None:
        """Decide on one label image taken at ``stamp_s`` from ``pose`` (x [m], y [m], yaw [rad]).

        Returns None for a frame older than the last one decided on (out of order); such a frame
        changes nothing.
        """
        if self.planner.path is None:
            raise RuntimeError("call set_path() before decide()")
        image = np.asarray(image)
        if image.shape != self.shape:
            raise ValueError(f"label image of shape {image.shape}; the model's camera gives {self.shape}")
        if self.lut is not None:
            if image.dtype not in (np.uint8, np.uint16):
                raise ValueError(f"label image of dtype {image.dtype}; expected uint8 or uint16 label ids")
            image = self.lut[image]
        elif image.dtype != np.uint8:
            raise ValueError(f"label image of dtype {image.dtype}; expected uint8 class ids (or give a label map)")
        pose = Pose(*(float(v) for v in pose))
        if not (math.isfinite(stamp_s) and all(math.isfinite(v) for v in pose)):
            raise ValueError("stamp and pose must be finite")
        if self.last is not None and stamp_s <= self.last.stamp_s:
            return None
        d = self.planner.decide(image, pose)
        self.last = RuntimeDecision(float(stamp_s), d.command, d.index, d.probs, d.progress_s, d.U)
        return self.last

    def costmap(self) -> Costmap:
        """The learned preference over the ground seen so far, in the frame of the poses given
        (terrapref.planner.costmap): 0-99 by learned price, 100 lethal, -1 never seen.

        Raises:
            ValueError: the model's planner keeps no ground map (it has no offset stage).
        """
        costmap = self.planner.costmap()
        if costmap is None:
            raise ValueError("this model's planner keeps no ground map (no offset stage: recipe teach has one)")
        return costmap

    def command_at(self, now_s: float) -> Command:
        """The command to send at ``now_s``: the last decision's while it is fresh, else a stop."""
        if self.last is None or not now_s - self.last.stamp_s <= self.hold_s:
            return STOP
        return self.last.command
