"""Policies: what scores the m trajectories at each frame, behind one planner interface.

A policy sees what the planner sees (the utility features U, the segmentation image, and the
reference path ahead in the vehicle frame) and returns one score per trajectory; the planner's
driving rule (terrapref.rules: C's argmax for a policy without rules) turns them into
a command. The learned classifier C is one policy; the study's baselines are others:

- ``ClassifierPolicy``: C (SPEC 8), the paper's method.
- ``PurePursuitPolicy``: follows the path and ignores terrain.
- ``CostPolicy``: a hand-tuned cost over the same features (a weight per terrain class and
  one for the distance utility), the classic costmap approach.
- ``LinearPolicy``: the same form with weights learned from demonstrations.
- ``CnnPolicy`` (terrapref.baselines.cnn): end-to-end behaviour cloning from the image.

Kinds are registered by name and built or loaded by ``terrapref.planner.registry`` (``make``,
``load_policy``).
"""

from __future__ import annotations

import abc
import math
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from terrapref.camera import CameraConfig, SegmentationView
from terrapref.features import FeatureConfig
from terrapref.learning import exact
from terrapref.learning.forward import PackedNetwork
from terrapref.learning.forward import probabilities as forward_probabilities
from terrapref.learning.linear import LinearUtility
from terrapref.learning.model_file import FORMAT, LoadedModel
from terrapref.learning.network import softmax
from terrapref.rules import Rule, rules_of
from terrapref.tensorfile import write_tensor_file
from terrapref.terrain import ClassTable, default_classes
from terrapref.vehicle import pure_pursuit_yaw_rate


@dataclass(frozen=True)
class Observation:
    """What a policy may look at in one frame.

    Attributes:
        U: utility features (m, K + 1).
        view: the segmentation image (``image`` renders it whole, for policies that read all
            of it).
        path_ahead: reference-path points 1, 2, ..., P m ahead of the vehicle's progress, in
            the vehicle frame (P, 2) [m] (x forward, y left); empty unless the policy asks.
    """

    U: np.ndarray
    view: SegmentationView
    path_ahead: np.ndarray

    @property
    def image(self) -> np.ndarray:
        """The segmentation image (H, W) uint8."""
        return self.view.image


class Policy(abc.ABC):
    """Scores the m trajectories of a frame; the planner drives the best.

    A policy is built for one feature configuration, camera and class table (the planner
    refuses a camera it was not built for), and may name the preference order it learned
    (``profile``) and the file it came from (``path``). Kinds are registered by name in
    :mod:`terrapref.planner.registry`.

    Args:
        features: the utility features U it reads (and the preference set).
        camera: the camera it was built for.
        classes: the class table of the images it reads.
        profile: the preference order it was trained under, best first, if any.
        path: the model file it was loaded from ("" for none).

    Attributes:
        rules: the decision rules fitted with it, in order (the planner drives with the one the file names;
            none: the argmax of its scores).
    """

    name: ClassVar[str] = "policy"
    uses_path_ahead: ClassVar[bool] = False  # the planner computes Observation.path_ahead only when asked

    def __init__(
        self,
        features: FeatureConfig | None = None,
        camera: CameraConfig | None = None,
        classes: ClassTable | None = None,
        profile: tuple[str, ...] | None = None,
        path: str = "",
    ) -> None:
        self.classes = classes or default_classes()
        self.features = features or FeatureConfig(feature_classes=self.classes.feature_names)
        self.camera = camera or CameraConfig()
        self.profile, self.path = profile, path
        self.rules: tuple[Rule, ...] = ()  # the decision rules the model file lists
        self.drives: str | None = None  # the one it names to drive

    @abc.abstractmethod
    def logits(self, obs: Observation) -> np.ndarray:
        """One score per trajectory, shape (m,); the planner drives the argmax."""

    def probabilities(self, obs: Observation) -> np.ndarray:
        """F_t, shape (m,): the softmax of :meth:`logits` (what the planner reads)."""
        return softmax(self.logits(obs))


class ClassifierPolicy(Policy):
    """The learned classifier C from a model file."""

    name = "classifier"

    def __init__(self, model: LoadedModel) -> None:
        super().__init__(model.features, model.camera, model.classes, model.profile, model.path)
        self.model = model
        self._packed = PackedNetwork.of(model.classifier, model.weights)
        self.rules, self.drives = rules_of(model)

    def logits(self, obs: Observation) -> np.ndarray:
        """log F_t (-inf where a probability is exactly 0)."""
        return exact.log(self.probabilities(obs))

    def probabilities(self, obs: Observation) -> np.ndarray:
        """F_t of C (the mean of an ensemble's members' softmaxes) in one compiled call, the same
        bits on every CPU (:mod:`terrapref.learning.forward`)."""
        return forward_probabilities(self._packed, obs.U)


class LinearPolicy(Policy):
    """Scores ``w . U_i + b_i``: the multi-criteria decision function (weights given or fitted)."""

    name = "linear"

    def __init__(
        self,
        utility: LinearUtility,
        features: FeatureConfig | None = None,
        camera: CameraConfig | None = None,
        classes: ClassTable | None = None,
        profile: tuple[str, ...] | None = None,
        path: str = "",
    ) -> None:
        super().__init__(features, camera, classes, profile, path)
        self.utility = utility
        if len(utility.w) != self.features.n_features or len(utility.b) != self.features.preference.m:
            raise ValueError("linear utility does not match the feature configuration")

    def logits(self, obs: Observation) -> np.ndarray:
        return obs.U @ self.utility.w + self.utility.b


# Hand-set costs of the classic approach: a cost per metre-share on each class against a pull
# back to the path. For the default profile (mud < rock < water << non_traversable) they are
# mud 2, rock 4, water 8, non_traversable 50, the result of a few minutes of trial on
# train_course only; another table's classes cost the same by rank in its default profile.
HAND_BASE_COST = 2.0  # the most preferred class's; each next class in the profile costs twice the one before
HAND_LETHAL_COST = 50.0  # the lethal column's, or twice the costliest class's where that is more
HAND_DISTANCE_WEIGHT = 2.0


def hand_costs(classes: ClassTable | None = None) -> dict[str, float]:
    """The hand-tuned cost of each terrain column of ``classes`` (default: the packaged table):
    by rank in the table's default profile, doubling from HAND_BASE_COST; the lethal column
    HAND_LETHAL_COST, or twice the costliest class's where that is more."""
    classes = classes or default_classes()
    ranked = [name for name in classes.profile if name != classes.lethal_column]
    costs = {name: HAND_BASE_COST * 2.0**rank for rank, name in enumerate(ranked)}
    lethal = max(HAND_LETHAL_COST, 2.0 * max(costs.values(), default=0.0))
    return costs | ({classes.lethal_column: lethal} if classes.lethal_column else {})


class CostPolicy(LinearPolicy):
    """The hand-tuned cost planner: -sum_k cost_k u^k + weight * u^(K+1) (:func:`hand_costs` of the table by default)."""

    name = "hand_cost"

    def __init__(
        self,
        costs: dict[str, float] | None = None,
        distance_weight: float = HAND_DISTANCE_WEIGHT,
        features: FeatureConfig | None = None,
        camera: CameraConfig | None = None,
        classes: ClassTable | None = None,
    ) -> None:
        classes = classes or default_classes()
        features = features or FeatureConfig(feature_classes=classes.feature_names)
        costs = dict(hand_costs(classes) if costs is None else costs)
        unknown = set(costs) - set(features.feature_classes)
        if unknown:
            raise ValueError(f"no feature column for {sorted(unknown)}")
        w = np.array([-costs.get(name, 0.0) for name in features.feature_classes] + [distance_weight])
        super().__init__(LinearUtility(w, np.zeros(features.preference.m)), features, camera, classes)
        self.costs, self.distance_weight = costs, distance_weight


class PurePursuitPolicy(Policy):
    """A path follower that ignores terrain: pure pursuit to the path point ``pursuit_m`` ahead,
    then the trajectory whose yaw rate is nearest the pursuit command."""

    name = "pure_pursuit"
    uses_path_ahead = True

    def __init__(
        self,
        pursuit_m: float = 2.5,
        features: FeatureConfig | None = None,
        camera: CameraConfig | None = None,
        classes: ClassTable | None = None,
    ) -> None:
        super().__init__(features, camera, classes)
        self.pursuit_m = pursuit_m
        control = self.features.preference.control
        self._w = np.asarray(control.w_rps, dtype=float)
        self._v = float(control.v_mps)

    def logits(self, obs: Observation) -> np.ndarray:
        # The path point (1 m apart) nearest the pursuit distance.
        d = np.hypot(obs.path_ahead[:, 0], obs.path_ahead[:, 1])
        j = int(np.clip(np.searchsorted(d, self.pursuit_m), 0, len(d) - 1))
        x, y = obs.path_ahead[j]
        dist = max(math.hypot(x, y), 1e-6)
        w = pure_pursuit_yaw_rate(self._v, y / dist, dist)
        return -np.abs(self._w - w)


LINEAR = "linear"
CNN = "cnn"


def save_linear(path: str | Path, utility: LinearUtility, meta: dict) -> Path:
    """Write a fitted linear utility model; ``meta`` holds features, camera, classes, profile."""
    tensors = {"w": utility.w.astype(np.float32), "b": utility.b.astype(np.float32)}
    return write_tensor_file(path, tensors, {"format": FORMAT, **meta, "kind": LINEAR})
