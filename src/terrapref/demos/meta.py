"""A recording's configuration (its ``meta.json`` beside the writer's format and status) and who
drove it, as typed records: written by :meth:`RecordingMeta.to_dict` and read back by
:meth:`RecordingMeta.from_dict`, here and nowhere else.

The file keeps its keys in the format's fixed order, so the same recording is the same file,
byte for byte, whichever code wrote it. Some recordings lack some entries (a driver entry
without a style, an import without a perception model): what a file does not hold is None
here, and the use that needs it says so (featurising: ``require_meta``).

A driver is one of four kinds, each with its own fields::

    expert       the synthetic demonstrator: seed, style, config, disturbance
    human        a person in the teleop window: input, disturbance, seed
    corrections  the planner drove and a driver corrected it: a person riding along in the
                 window (input, disturbance, seed, model), or the synthetic driver in a
                 recipe's correction round (round, seed)
    imported     a real robot's bag: bag, robot, labels

>>> ExpertInfo(seed=3).to_dict()
{'kind': 'expert', 'seed': 3, 'style': 'default', 'config': None, 'disturbance': None}
>>> driver_from_dict({"kind": "human", "input": "keyboard", "seed": 0}, "meta.json").describe()
'human, seed 0'
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from terrapref.camera import CameraConfig
from terrapref.demos.relief_style import ReliefStyle
from terrapref.errors import Problem, UserError
from terrapref.features import PreferenceSetConfig
from terrapref.perception import PerceptionModel
from terrapref.records import FieldError, to_plain
from terrapref.registry import Registry
from terrapref.sim import SimConfig
from terrapref.terrain import ClassTable, PreferenceProfile, default_classes
from terrapref.vehicle import VehicleConfig

if TYPE_CHECKING:
    from terrapref.demos.disturbance import DisturbanceConfig
    from terrapref.demos.expert import ExpertConfig
    from terrapref.scenario import Scenario

Settings = dict[str, Any]  # a configuration as the version that wrote it wrote it (see ExpertInfo)


def _settings(config: ExpertConfig | DisturbanceConfig | None) -> Settings | None:
    return config.to_dict() if config is not None else None


@dataclass(frozen=True)
class ExpertInfo:
    """The synthetic demonstrator (terrapref.demos.expert).

    ``config`` and ``disturbance`` are kept as written: a recording may name parameters that
    this code's :class:`ExpertConfig` does not have, and it must still load.

    Attributes:
        seed: the seed of its noise (and of the run's pushes).
        style: its style's name (terrapref.demos.expert.STYLES).
        config: its :class:`~terrapref.demos.expert.ExpertConfig`, as a mapping.
        disturbance: the run's pushes (:class:`~terrapref.demos.disturbance.DisturbanceConfig`), or None.
    """

    seed: int | None = None
    style: str = "default"
    config: Settings | None = None
    disturbance: Settings | None = None
    kind = "expert"

    @classmethod
    def of(cls, seed: int, style: str, config: ExpertConfig, disturbance: DisturbanceConfig | None = None) -> ExpertInfo:
        """The driver of ``config`` (of style ``style``), seeded with ``seed``, with ``disturbance``'s pushes."""
        return cls(seed, style, _settings(config), _settings(disturbance))

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, **to_plain(self)}

    def describe(self) -> str:
        text = _describe(self.kind, style=self.style, seed=self.seed)
        relief = (self.config or {}).get("relief")
        if isinstance(relief, Mapping):  # a relief style (terrapref.demos.relief_style), as written
            style = ReliefStyle.written(relief)
            text += f", relief: {style.describe() if style is not None else dict(relief)}"  # one this version does not read: as written
        return text


@dataclass(frozen=True)
class HumanInfo:
    """A person driving in the teleop window.

    Attributes:
        input: the devices offered (``keyboard/mouse/gamepad``).
        disturbance: the session's pushes, as written, or None.
        seed: the seed of the pushes.
    """

    input: str | None = None
    disturbance: Settings | None = None
    seed: int | None = None
    kind = "human"

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, **to_plain(self)}

    def describe(self) -> str:
        return _describe(self.kind, seed=self.seed)


@dataclass(frozen=True)
class RideAlongInfo:
    """A person correcting the planner from the teleop window (kind ``corrections``).

    Attributes:
        input, disturbance, seed: as :class:`HumanInfo`'s.
        model: the model file the planner drove with.
    """

    input: str | None = None
    disturbance: Settings | None = None
    seed: int | None = None
    model: str | None = None
    kind = "corrections"

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, **to_plain(self)}

    def describe(self) -> str:
        return _describe(self.kind, seed=self.seed, model=self.model)


@dataclass(frozen=True)
class CorrectionRoundInfo:
    """The synthetic driver correcting the planner in a recipe's correction round (kind ``corrections``).

    Attributes:
        round: the round's number, from 0.
        seed: the recipe's seed.
    """

    round: int
    seed: int | None = None
    kind = "corrections"

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, **to_plain(self)}

    def describe(self) -> str:
        return _describe(self.kind, seed=self.seed)


@dataclass(frozen=True)
class ImportedInfo:
    """A real robot's operator, imported from a bag (terrapref.interop.bag_import).

    Attributes:
        bag: the bag's file.
        robot: the robot description's file.
        labels: the name of the label map the segmentation went through.
    """

    bag: str
    robot: str | None = None
    labels: str | None = None
    kind = "imported"

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, **to_plain(self)}

    def describe(self) -> str:
        return _describe(self.kind, bag=self.bag)


DriverInfo = ExpertInfo | HumanInfo | RideAlongInfo | CorrectionRoundInfo | ImportedInfo


def _describe(kind: str, style: str | None = None, seed: int | None = None, bag: str | None = None, model: str | None = None) -> str:
    """Who drove, in words: the kind, then whichever of style, seed, source bag and ridden-along model it names."""
    return (
        kind
        + (f", style {style}" if style else "")
        + (f", seed {seed}" if seed is not None else "")
        + (f", from {bag}" if bag else "")
        + (f", riding along with {model}" if model else "")
    )


class _Fields:
    """Reads the fields of one mapping of a file, each checked; a wrong one is a UserError naming it."""

    def __init__(self, data: dict[str, Any], source: str, prefix: str) -> None:
        self.data, self.source, self.prefix = data, source, prefix

    def fail(self, key: str, message: str) -> UserError:
        return UserError(self.source, message, field=f"{self.prefix}{key}")

    def get(self, key: str, kind: type | tuple[type, ...], what: str, default: Any = None) -> Any:
        """``data[key]`` if it is a ``kind`` (bool is not a number here), ``default`` when absent or null."""
        value = self.data.get(key)
        if value is None:
            return default
        if not isinstance(value, kind) or (isinstance(value, bool) and bool not in (kind if isinstance(kind, tuple) else (kind,))):
            raise self.fail(key, f"expected {what}, got {type(value).__name__}")
        return value

    def number(self, key: str, default: float | None = None) -> float | None:
        value = self.get(key, (int, float), "a number", default)
        if value is not None and not math.isfinite(value):
            raise self.fail(key, "expected a finite number")
        return value


def _expert(f: _Fields) -> ExpertInfo:
    return ExpertInfo(
        f.get("seed", int, "an integer"),
        f.get("style", str, "a style name", "default"),
        f.get("config", dict, "a mapping"),
        f.get("disturbance", dict, "a mapping"),
    )


def _human(f: _Fields) -> HumanInfo:
    return HumanInfo(f.get("input", str, "text"), f.get("disturbance", dict, "a mapping"), f.get("seed", int, "an integer"))


def _corrections(f: _Fields) -> RideAlongInfo | CorrectionRoundInfo:
    if "round" in f.data:  # the synthetic driver's round in a recipe; a person's session has no rounds
        return CorrectionRoundInfo(f.get("round", int, "an integer", 0), f.get("seed", int, "an integer"))
    return RideAlongInfo(
        f.get("input", str, "text"),
        f.get("disturbance", dict, "a mapping"),
        f.get("seed", int, "an integer"),
        f.get("model", str, "a file name"),
    )


def _imported(f: _Fields) -> ImportedInfo:
    return ImportedInfo(f.get("bag", str, "a file name", ""), f.get("robot", str, "a file name"), f.get("labels", str, "a name"))


# How each kind of driver is read back, by the "kind" its meta.json entry names.
DRIVER_KINDS: Registry[Callable[[_Fields], DriverInfo]] = Registry("driver kind")
DRIVER_KINDS.register(ExpertInfo.kind, _expert, "the synthetic demonstrator")
DRIVER_KINDS.register(HumanInfo.kind, _human, "a person in the teleop window")
DRIVER_KINDS.register(RideAlongInfo.kind, _corrections, "the planner drove and a driver corrected it")
DRIVER_KINDS.register(ImportedInfo.kind, _imported, "a real robot's operator, from a bag")


def driver_from_dict(data: Any, source: str, field: str = "driver") -> DriverInfo:
    """A driver as its ``to_dict`` wrote it; ``source`` and ``field`` name it in errors.

    Raises:
        UserError: not a mapping, an unknown kind, or a field of the wrong type (named).
    """
    if not isinstance(data, dict):
        raise UserError(source, f"expected a mapping, got {type(data).__name__}", field=field)
    kind = data.get("kind")
    if not isinstance(kind, str):
        raise UserError(source, f"expected a driver kind ({', '.join(DRIVER_KINDS)})", field=f"{field}.kind")
    return DRIVER_KINDS.get(kind, f"{field}.kind", source)(_Fields(data, source, f"{field}."))


@dataclass(frozen=True)
class SimMeta:
    """The simulation settings a recording was made under (an import holds only the rate).

    Attributes:
        camera_rate_hz: frames per second [Hz].
        goal_radius_m: how close to the last waypoint the run ended [m]; None: not recorded.
        vehicle: the vehicle's limits; None: not recorded.
    """

    camera_rate_hz: float
    goal_radius_m: float | None = None
    vehicle: VehicleConfig | None = None

    @classmethod
    def of(cls, sim: SimConfig) -> SimMeta:
        return cls(sim.camera_rate_hz, sim.goal_radius_m, sim.vehicle)

    def to_dict(self) -> dict[str, Any]:
        """What is recorded; None is left out."""
        return to_plain(self, omit_none=True)

    @classmethod
    def from_dict(cls, data: Any, source: str) -> SimMeta:
        if not isinstance(data, dict):
            raise UserError(source, f"expected a mapping, got {type(data).__name__}", field="sim")
        f = _Fields(data, source, "sim.")
        rate = f.number("camera_rate_hz")
        if rate is None or rate <= 0:
            raise f.fail("camera_rate_hz", "expected a frame rate > 0 [Hz]")
        vehicle = f.get("vehicle", dict, "a mapping")
        try:
            parsed = VehicleConfig.from_dict(vehicle) if vehicle is not None else None
        except (TypeError, ValueError) as exc:
            raise f.fail("vehicle", f"invalid ({type(exc).__name__}: {exc})") from None
        return cls(rate, f.number("goal_radius_m"), parsed)


@dataclass(frozen=True)
class RecordingSetup:
    """The configuration a run is recorded under, besides its course: what the camera saw, the
    control and preference set its commands are labelled with, and the simulation's settings."""

    camera: CameraConfig
    preference: PreferenceSetConfig
    sim: SimConfig


Points = tuple[tuple[float, float], ...]


@dataclass(frozen=True)
class RecordingMeta:
    """Everything a recording carries to be featurised again later (SPEC 10), as its meta.json
    holds it; None where the file does not say (a recording without that entry, an import).

    Attributes:
        scenario: the course's name.
        camera: the camera the frames were rendered with.
        preference_set: the control and preference set the commands are labelled with.
        sim: the simulation's settings.
        classes: the class table of the frames' ids.
        profile: the driver's preference order.
        driver: who drove.
        path: the reference path's waypoints [m].
        perception: the perception model the frames went through (a clean one: the truth).
        origin_shift_m: how far an import moved the odometry frame onto the map [m].
    """

    scenario: str | None = None
    camera: CameraConfig | None = None
    preference_set: PreferenceSetConfig | None = None
    sim: SimMeta | None = None
    classes: ClassTable | None = None
    profile: tuple[str, ...] | None = None
    driver: DriverInfo | None = None
    path: Points | None = None
    perception: PerceptionModel | None = None
    origin_shift_m: tuple[float, float] | None = None

    @classmethod
    def driven(
        cls,
        scenario: Scenario,
        setup: RecordingSetup,
        driver: DriverInfo,
        profile: PreferenceProfile | None,
        perception: PerceptionModel | None = None,
    ) -> RecordingMeta:
        """The meta of a run of ``scenario`` driven by ``driver`` of the declared order ``profile``
        (None: none declared), whose frames went through ``perception`` (None: the truth)."""
        return cls(
            scenario.name,
            setup.camera,
            setup.preference,
            SimMeta.of(setup.sim),
            scenario.classes,
            tuple(profile.order) if profile is not None else None,
            driver,
            _points(scenario.waypoints),
            perception or PerceptionModel(),
        )

    def to_dict(self) -> dict[str, Any]:
        """The entries of meta.json, in the file's order (the fields'); what is None is left out."""
        return to_plain(self, omit_none=True)

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str) -> RecordingMeta:
        """The entries of a meta.json (other keys, the writer's format and status, are ignored),
        each checked once here so that every later use is safe; ``source`` names the file.

        Raises:
            UserError: an entry that is not what it should be, naming the file and the field.
        """
        camera = _parsed(data, "camera", CameraConfig.from_dict, source)
        preference = _parsed(data, "preference_set", PreferenceSetConfig.from_dict, source)
        classes = _parsed(data, "classes", lambda d: ClassTable.from_dict(d, source), source)
        profile = data.get("profile")
        if profile is not None and not (isinstance(profile, list) and all(isinstance(p, str) for p in profile)):
            raise UserError(source, "expected a list of class names", field="profile")
        if profile is not None:  # an order of the recording's own classes, each once
            try:
                PreferenceProfile.parse(profile, classes, source)
            except UserError as exc:
                raise UserError(source, exc.problems[0].message, field="profile") from None
        perception = _perception(data["perception"], source, classes) if "perception" in data else None
        path = _path(data["path"], source, "path", 2) if "path" in data else None
        f = _Fields(data, source, "")
        shift = _path([data["origin_shift_m"]], source, "origin_shift_m", 1)[0] if "origin_shift_m" in data else None
        return cls(
            f.get("scenario", str, "a scenario name"),
            camera,
            preference,
            SimMeta.from_dict(data["sim"], source) if "sim" in data else None,
            classes,
            tuple(profile) if profile is not None else None,
            driver_from_dict(data["driver"], source) if "driver" in data else None,
            path,
            perception,
            shift,
        )


def _points(points: np.ndarray) -> Points:
    return tuple((x, y) for x, y in points.tolist())


def _parsed(data: dict[str, Any], key: str, parse: Callable[[dict], Any], source: str) -> Any:
    """``parse(data[key])`` (None when absent); a value that is not a mapping, or that ``parse``
    refuses, is a UserError naming the field."""
    if key not in data:
        return None
    value = data[key]
    if not isinstance(value, dict):
        raise UserError(source, f"expected a mapping, got {type(value).__name__}", field=key)
    try:
        return parse(value)
    except UserError:
        raise
    except FieldError as exc:
        raise UserError(source, exc.message, field=f"{key}.{exc.field}") from None
    except (TypeError, ValueError, KeyError, AttributeError) as exc:
        raise UserError(source, f"invalid ({type(exc).__name__}: {exc})", field=key) from None


def _perception(value: Any, source: str, classes: ClassTable | None) -> PerceptionModel:
    """The perception model a recording's frames went through (terrapref.perception), as it was written."""
    from terrapref.perception.model import from_dict

    if not isinstance(value, dict):
        raise UserError(source, f"expected a mapping, got {type(value).__name__}", field="perception")
    try:
        return from_dict(value, source, classes or default_classes())
    except UserError as exc:
        raise UserError(source, [Problem(f"perception.{p.field}" if p.field else "perception", p.message) for p in exc.problems]) from None


def _path(value: Any, source: str, field: str, least: int) -> Points:
    """At least ``least`` finite [x, y] points."""
    try:
        points = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        points = np.zeros(0)
    if points.ndim != 2 or points.shape[1:] != (2,) or len(points) < least or not np.isfinite(points).all():
        raise UserError(
            source, "expected at least two finite [x, y] points" if least > 1 else "expected two finite numbers [m]", field=field
        )
    if least > 1 and len(np.unique(points, axis=0)) < 2:  # a path the vehicle could follow
        raise UserError(source, "expected at least two distinct [x, y] points", field=field)
    return _points(points)
