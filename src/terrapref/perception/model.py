"""Perception models (``terrapref-perception/1``): what a real robot's planner gets instead of the truth.

A perception model says how the labels, the pose, the camera's attitude and the frames' timing
a planner receives differ from the simulator's truth (SPEC 16). Every field is optional and off
(0) by default, so ``clean`` is the empty model::

    format: terrapref-perception/1
    labels:
      flip_rate: 0.05          # share of pixels relabelled to a random class, per frame
      blobs_per_frame: 1.0     # mislabelled blobs (Poisson), whole regions painted one class
      blob_radius_px: [15, 60]
      boundary_px: 3           # pixels this close to a class border take the neighbour's class at random
      confusion:               # per true class: share of its pixels seen as another class, per frame
        water: {grass: 0.4, mud: 0.1}
      region_px: 16            # a confusion is decided alike over image tiles this size (a network
                               # mislabels regions, not scattered pixels)
      persist_frames: 1        # ... and alike for this many frames in a row
      max_range_m: 20          # ground farther than this is unknown (255)
    pose:
      noise_m: 0.3             # white noise on the pose the planner is told (std) [m]
      noise_deg: 3             # ... on its heading (std) [deg]
      drift_m_per_m: 0.02      # a random walk on the position: std after one metre driven [m];
                               # it grows with the square root of the distance
      drift_deg_per_m: 0.5     # ... on the heading [deg]
    camera:
      pitch_jitter_deg: 2      # the camera's attitude wanders (std) while the planner assumes the
      roll_jitter_deg: 2       # nominal mount
      jitter_time_s: 0.3       # the wander's correlation time [s]
    frames:
      delay: 1                 # every frame arrives this many camera periods late
      late_rate: 0.1           # ... and one period later still, this share of them
      drop_rate: 0.1           # share of frames lost
    depth:
      noise_m: 0.003           # the depth image's noise (std) at 1 m; it grows with the square of
                               # the depth, as a stereo camera's does (0.3 m at 10 m)
      dropout_rate: 0.05       # share of pixels with no return (NaN)
      max_range_m: 20          # farther returns are NaN

Presets by name (``terrapref perception`` lists them): ``clean``, ``rellis`` (label errors at the
rates of a segmentation network on RELLIS-3D; docs/perception.md derives them) and ``field``
(``rellis`` with pose noise and drift, camera jitter, a late or lost frame now and then, and a
stereo camera's depth errors).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field, fields, replace
from importlib import resources
from pathlib import Path
from typing import Any, NamedTuple

from terrapref.errors import ConfigError, Problem, UserError, described, finite_number
from terrapref.records import to_plain
from terrapref.terrain import ClassTable
from terrapref.yamlio import read_yaml_mapping

FORMAT = "terrapref-perception/1"
PRESETS = ("clean", "rellis", "field")


@dataclass(frozen=True)
class LabelErrors:
    """How the segmentation's labels differ from the truth, drawn afresh for every frame.

    Attributes:
        flip_rate: share of pixels relabelled to a class drawn uniformly from the class table.
        blobs_per_frame: expected mislabelled blobs per frame (Poisson): ellipses on the ground
            part of the image painted one class.
        blob_radius_px: (min, max) blob radius [px].
        boundary_px: each pixel takes the class of a pixel up to this far away [px], drawn at
            random, so pixels near a class border take the neighbour's class at random.
        confusion: per true class name, the share of its pixels seen as each other class.
        region_px: side of the image tiles over which a confusion is decided alike [px].
        persist_frames: frames in a row over which a confusion is decided alike.
        max_range_m: ground farther than this from the camera is unknown (None: the camera's own range).
    """

    flip_rate: float = 0.0
    blobs_per_frame: float = 0.0
    blob_radius_px: tuple[int, int] = (15, 60)
    boundary_px: int = 0
    confusion: tuple[tuple[str, tuple[tuple[str, float], ...]], ...] = ()
    region_px: int = 16
    persist_frames: int = 1
    max_range_m: float | None = None

    @property
    def active(self) -> bool:
        return bool(self.flip_rate or self.blobs_per_frame or self.boundary_px or self.confusion or self.max_range_m is not None)

    def confusion_dict(self) -> dict[str, dict[str, float]]:
        return {true: dict(row) for true, row in self.confusion}


@dataclass(frozen=True)
class PoseErrors:
    """How the pose the planner is told differs from the truth.

    Attributes:
        noise_m, noise_deg: white noise on the position [m] and heading [deg] (std), per frame.
        drift_m_per_m, drift_deg_per_m: random walks on the position [m] and heading [deg]:
            the std after one metre driven (it grows with the square root of the distance). The
            error is an offset that wanders slowly, as a localisation between corrections does.
    """

    noise_m: float = 0.0
    noise_deg: float = 0.0
    drift_m_per_m: float = 0.0
    drift_deg_per_m: float = 0.0

    @property
    def active(self) -> bool:
        return bool(self.noise_m or self.noise_deg or self.drift_m_per_m or self.drift_deg_per_m)


@dataclass(frozen=True)
class CameraJitter:
    """How the real camera's attitude moves while the planner assumes the nominal mount.

    Attributes:
        pitch_jitter_deg, roll_jitter_deg: std of the attitude's wander [deg].
        jitter_time_s: its correlation time [s] (an Ornstein-Uhlenbeck process).
    """

    pitch_jitter_deg: float = 0.0
    roll_jitter_deg: float = 0.0
    jitter_time_s: float = 0.3

    @property
    def active(self) -> bool:
        return bool(self.pitch_jitter_deg or self.roll_jitter_deg)


@dataclass(frozen=True)
class FrameTiming:
    """When frames reach the planner.

    Attributes:
        delay: every frame arrives this many camera periods after it was taken.
        late_rate: share of frames that arrive one period later still (after the next one,
            which makes them stale: the planner drops a frame older than one it decided on).
        drop_rate: share of frames lost.
    """

    delay: int = 0
    late_rate: float = 0.0
    drop_rate: float = 0.0

    @property
    def active(self) -> bool:
        return bool(self.delay or self.late_rate or self.drop_rate)


@dataclass(frozen=True)
class DepthErrors:
    """How the depth image differs from the truth, drawn afresh for every frame.

    Attributes:
        noise_m: the noise's std at 1 m of depth [m]; at depth d it is ``noise_m * d ** 2``, as a
            stereo camera's error grows (its disparity's error is constant).
        dropout_rate: share of pixels with no return (NaN), each drawn alone.
        max_range_m: returns farther than this along the optical axis are NaN; None: every one.
    """

    noise_m: float = 0.0
    dropout_rate: float = 0.0
    max_range_m: float | None = None

    @property
    def active(self) -> bool:
        return bool(self.noise_m or self.dropout_rate or self.max_range_m is not None)


@dataclass(frozen=True)
class PerceptionModel:
    """A perception model: what differs between the truth and what a planner receives.

    Attributes:
        name: the preset's name or the file it came from (for reports).
    """

    labels: LabelErrors = field(default_factory=LabelErrors)
    pose: PoseErrors = field(default_factory=PoseErrors)
    camera: CameraJitter = field(default_factory=CameraJitter)
    frames: FrameTiming = field(default_factory=FrameTiming)
    name: str = "clean"
    depth: DepthErrors = field(default_factory=DepthErrors)

    @property
    def active(self) -> bool:
        """Whether anything differs from the truth."""
        return self.labels.active or self.pose.active or self.camera.active or self.frames.active or self.depth.active

    def part(self, section: str) -> PerceptionModel:
        """This model with only ``section`` (labels, pose, camera, frames or depth) kept, named ``NAME:SECTION``."""
        if section not in _SECTIONS:
            raise ValueError(f"unknown section {section!r}")
        return replace(PerceptionModel(), **{section: getattr(self, section)}, name=f"{self.name}:{section}")

    def scaled(self, factor: float) -> PerceptionModel:
        """This model with every error ``factor`` times as large, named ``NAME x FACTOR``: rates and
        shares (capped at 1), blobs per frame, the border's width, noises, drifts and jitters, and
        the delay (rounded to whole periods); sizes (blob radii, regions), their persistence and
        the depth's range stay."""
        if not (math.isfinite(factor) and factor >= 0):
            raise ValueError("a scale factor must be finite and >= 0")
        lab, pose, cam, fr = self.labels, self.pose, self.camera, self.frames
        confusion = tuple((t, tuple((c, p * factor) for c, p in row)) for t, row in lab.confusion)
        confusion = tuple((t, tuple((c, p / max(1.0, sum(q for _, q in row))) for c, p in row)) for t, row in confusion)
        return PerceptionModel(
            replace(
                lab,
                flip_rate=min(1.0, lab.flip_rate * factor),
                blobs_per_frame=lab.blobs_per_frame * factor,
                boundary_px=round(lab.boundary_px * factor),
                confusion=tuple((t, row) for t, row in confusion if any(p > 0 for _, p in row)),
            ),
            PoseErrors(*(v * factor for v in (pose.noise_m, pose.noise_deg, pose.drift_m_per_m, pose.drift_deg_per_m))),
            replace(cam, pitch_jitter_deg=cam.pitch_jitter_deg * factor, roll_jitter_deg=cam.roll_jitter_deg * factor),
            FrameTiming(round(fr.delay * factor), min(1.0, fr.late_rate * factor), min(1.0, fr.drop_rate * factor)),
            name=f"{self.name} x {factor:g}",
            depth=replace(self.depth, noise_m=self.depth.noise_m * factor, dropout_rate=min(1.0, self.depth.dropout_rate * factor)),
        )

    def to_dict(self) -> dict[str, Any]:
        """As terrapref-perception/1 holds it (every field), with the name."""
        out: dict[str, Any] = {"format": FORMAT, "name": self.name}
        for section in _SECTIONS:
            values = to_plain(getattr(self, section))
            if section == "labels":
                values["confusion"] = self.labels.confusion_dict()
            out[section] = values
        return out

    def file_dict(self) -> dict[str, Any]:
        """As a ``terrapref-perception/1`` file holds it (every field), which ``--perception FILE`` reads
        back: :meth:`to_dict` less the name, which a file takes from its path."""
        return {k: v for k, v in self.to_dict().items() if k != "name"}

    def summary(self) -> str:
        """The fields that are on, one line (``clean`` when none is)."""
        parts = []
        for section in _SECTIONS:
            sub = getattr(self, section)
            if not sub.active:
                continue
            default = type(sub)()
            on = [f"{f.name}={_short(getattr(sub, f.name))}" for f in fields(sub) if getattr(sub, f.name) != getattr(default, f.name)]
            parts.append(f"{section}: {', '.join(on)}")
        return "; ".join(parts) or "clean (the truth)"


_SECTIONS = ("labels", "pose", "camera", "frames", "depth")


def _short(value: Any) -> str:
    if isinstance(value, tuple) and value and isinstance(value[0], tuple):  # the confusion
        return "{" + ", ".join(f"{t}->{'/'.join(f'{c} {p:g}' for c, p in row)}" for t, row in value) + "}"
    if isinstance(value, tuple):
        return "-".join(f"{v:g}" for v in value)
    return f"{value:g}" if isinstance(value, float) else str(value)


# -- reading files -----------------------------------------------------------------------------

# Each field: (kind, low, high); a number must lie in [low, high].
_NUMBER, _INT, _RANGE_PX, _CONFUSION, _OPTIONAL = "number", "integer", "radius range", "confusion", "number or null"
_SCHEMA: dict[str, dict[str, tuple[str, float, float]]] = {
    "labels": {
        "flip_rate": (_NUMBER, 0.0, 1.0),
        "blobs_per_frame": (_NUMBER, 0.0, 100.0),
        "blob_radius_px": (_RANGE_PX, 1, 10_000),
        "boundary_px": (_INT, 0, 100),
        "confusion": (_CONFUSION, 0.0, 1.0),
        "region_px": (_INT, 1, 10_000),
        "persist_frames": (_INT, 1, 10_000),
        "max_range_m": (_OPTIONAL, 0.1, 1e6),
    },
    "pose": {
        "noise_m": (_NUMBER, 0.0, 100.0),
        "noise_deg": (_NUMBER, 0.0, 180.0),
        "drift_m_per_m": (_NUMBER, 0.0, 10.0),
        "drift_deg_per_m": (_NUMBER, 0.0, 180.0),
    },
    "camera": {"pitch_jitter_deg": (_NUMBER, 0.0, 30.0), "roll_jitter_deg": (_NUMBER, 0.0, 30.0), "jitter_time_s": (_NUMBER, 0.0, 1e4)},
    "frames": {"delay": (_INT, 0, 100), "late_rate": (_NUMBER, 0.0, 1.0), "drop_rate": (_NUMBER, 0.0, 1.0)},
    # A depth camera that drops every return, or sees no farther than the ground nearest its mount
    # (about 1 m ahead), gives no depth at all: refused, not taken for flat ground.
    "depth": {"noise_m": (_NUMBER, 0.0, 10.0), "dropout_rate": (_NUMBER, 0.0, 0.99), "max_range_m": (_OPTIONAL, 1.0, 1e6)},
}
_TOP = {"format", "description", *_SCHEMA}


def parse_perception(data: dict[str, Any], source: str, classes: ClassTable, name: str | None = None) -> PerceptionModel:
    """A checked perception model from a parsed ``terrapref-perception/1`` mapping.

    Raises:
        ConfigError: every problem, each naming its field (``labels.flip_rate: must be in [0, 1]``).
    """
    problems = [Problem(str(k), f"unknown key; expected {', '.join(sorted(_TOP))}") for k in data if k not in _TOP]
    if "description" in data and not isinstance(data["description"], str):
        problems.append(Problem("description", "expected text"))
    sections: dict[str, dict[str, Any]] = {}
    for section, schema in _SCHEMA.items():
        raw = data.get(section, {})
        if raw is None:
            raw = {}
        if not isinstance(raw, dict):
            problems.append(Problem(section, "expected a mapping"))
            continue
        values: dict[str, Any] = {}
        for key, value in raw.items():
            where = f"{section}.{key}"
            if key not in schema:
                problems.append(Problem(where, f"unknown key; expected {', '.join(schema)}"))
                continue
            checked = _check(value, _Field(*schema[key]), where, classes, problems)
            if checked is not _BAD:
                values[key] = checked
        sections[section] = values
    if problems:
        raise ConfigError(source, problems)
    labels = LabelErrors(**sections["labels"])
    if labels.blob_radius_px[0] > labels.blob_radius_px[1]:
        raise ConfigError(source, "the smallest radius must not exceed the largest", field="labels.blob_radius_px")
    return PerceptionModel(
        labels,
        PoseErrors(**sections["pose"]),
        CameraJitter(**sections["camera"]),
        FrameTiming(**sections["frames"]),
        name=name or source,
        depth=DepthErrors(**sections["depth"]),
    )


_BAD = object()


class _Field(NamedTuple):
    """What a field of the schema holds: its kind and the range of its numbers."""

    kind: str
    low: float
    high: float


def _check(value: Any, spec: _Field, where: str, classes: ClassTable, problems: list[Problem]) -> Any:
    """``value`` converted to the type of the field ``spec`` describes, or _BAD (with the problem noted)."""
    kind, low, high = spec

    def number(v: Any, at: str) -> float | None:
        if not finite_number(v):
            problems.append(Problem(at, f"expected a finite number, got {described(v)}"))
            return None
        if not low <= v <= high:
            problems.append(Problem(at, f"must be in [{low:g}, {high:g}], got {v:g}"))
            return None
        return float(v)

    def integer(v: Any, at: str) -> int | None:
        if isinstance(v, bool) or not isinstance(v, int):
            problems.append(Problem(at, f"expected a whole number, got {described(v)}"))
            return None
        if not low <= v <= high:
            problems.append(Problem(at, f"must be in [{low:g}, {high:g}], got {described(v)}"))
            return None
        return int(v)

    if kind == _NUMBER:
        x = number(value, where)
        return _BAD if x is None else x
    if kind == _OPTIONAL:
        if value is None:
            return None
        x = number(value, where)
        return _BAD if x is None else x
    if kind == _INT:
        n = integer(value, where)
        return _BAD if n is None else n
    if kind == _RANGE_PX:
        if not isinstance(value, list) or len(value) != 2:
            problems.append(Problem(where, f"expected [min, max] in pixels, got {described(value)}"))
            return _BAD
        pair = [integer(v, f"{where}[{i}]") for i, v in enumerate(value)]
        return _BAD if None in pair else (pair[0], pair[1])
    return _confusion(value, where, classes, number, problems)


def _confusion(value: Any, where: str, classes: ClassTable, number, problems: list[Problem]) -> Any:
    """The confusion mapping {true: {seen: share}}, its rows summing to at most 1, as sorted tuples."""
    if not isinstance(value, dict):
        problems.append(Problem(where, "expected a mapping of class name to {class name: share}"))
        return _BAD
    rows = []
    before = len(problems)
    for true, row in value.items():
        at = f"{where}.{true}"
        if true not in classes.names:
            problems.append(
                Problem(at, f"unknown class {true!r}; classes: {', '.join(classes.names)} (your own class table? give its --classes FILE)")
            )
            continue
        if not isinstance(row, dict) or not row:
            problems.append(Problem(at, "expected a mapping of class name to share"))
            continue
        shares = []
        for seen, p in row.items():
            if seen not in classes.names or seen == true:
                problems.append(
                    Problem(f"{at}.{seen}", f"expected another class of the table ({', '.join(c for c in classes.names if c != true)})")
                )
                continue
            x = number(p, f"{at}.{seen}")
            if x is not None and x > 0:
                shares.append((seen, x))
        if sum(p for _, p in shares) > 1.0 + 1e-9:
            problems.append(Problem(at, f"the shares sum to {sum(p for _, p in shares):g}; at most 1"))
        elif shares:
            rows.append((true, tuple(sorted(shares, key=lambda s: classes.id_of(s[0])))))
    if len(problems) > before:
        return _BAD
    return tuple(sorted(rows, key=lambda r: classes.id_of(r[0])))


def check_classes(model: PerceptionModel, classes: ClassTable, source: str) -> None:
    """Refuse a model whose confusion names a class ``classes`` does not have (one line naming the field)."""
    for true, row in model.labels.confusion:
        for name in (true, *(c for c, _ in row)):
            if name not in classes.names:
                raise UserError(
                    source,
                    f"names class {name!r}, which this class table does not have ({', '.join(classes.names)})",
                    field=f"labels.confusion.{true}",
                )


@functools.cache
def preset(name: str) -> PerceptionModel:
    """A packaged preset by name (PRESETS)."""
    if name not in PRESETS:
        raise UserError("--perception", f"unknown preset {name!r}; presets: {', '.join(PRESETS)} (or a terrapref-perception/1 file)")
    from terrapref.terrain import default_classes

    ref = resources.files("terrapref") / "data" / "perception" / f"{name}.yaml"
    with resources.as_file(ref) as path:
        return parse_perception(read_yaml_mapping(path, FORMAT), str(path), default_classes(), name=name)


def load_perception(spec: str | Path | PerceptionModel | None, classes: ClassTable | None = None) -> PerceptionModel:
    """A perception model: a preset's name, a ``terrapref-perception/1`` file, a model as it is, or None (clean).

    ``SPEC:PART`` (``field:pose``) keeps only one part of it: labels, pose, camera, frames or depth.

    With ``classes``, a confusion that names a class the table lacks is refused.
    """
    from terrapref.terrain import default_classes

    if spec is None:
        return PerceptionModel()
    head, _, section = str(spec).rpartition(":")
    if head and section in _SECTIONS and not isinstance(spec, PerceptionModel):
        # A preset's part is checked alone: its pose, camera or frames suit any class table.
        model = load_perception(head, None if head in PRESETS else classes).part(section)
        if classes is not None:
            check_classes(model, classes, model.name)
        return model
    if isinstance(spec, PerceptionModel):
        model = spec
    elif str(spec) in PRESETS:
        model = preset(str(spec))
    else:
        path = Path(spec)
        if not path.exists() and not path.suffix:
            parts = f", each keeping one part as NAME:PART ({', '.join(_SECTIONS)})" if head else ""
            raise UserError("--perception", f"no preset or file {str(spec)!r}; presets: {', '.join(PRESETS)}{parts}")
        model = parse_perception(read_yaml_mapping(path, FORMAT), str(path), classes or default_classes())
    if classes is not None:
        check_classes(model, classes, model.name)
    return model


def from_dict(data: dict[str, Any], source: str, classes: ClassTable) -> PerceptionModel:
    """A model as :meth:`PerceptionModel.to_dict` wrote it (in a recording's or a report's metadata)."""
    body = {k: v for k, v in data.items() if k != "name"}
    return parse_perception(body, source, classes, name=str(data.get("name", source)))
