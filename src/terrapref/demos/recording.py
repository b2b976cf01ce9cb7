"""Crash-safe recordings of driven runs (SPEC 10), readable with standard tools.

Layout of a recording directory::

    meta.json        configuration: scenario, camera, control/preference set, classes, driver;
                     "status" is "partial" until the run finishes, then "complete"
    scenario.yaml    the scenario as driven (terrapref-scenario/1)
    frames.jsonl     one JSON object per camera frame, appended and flushed as it happens:
                     {"i", "t", "pose": [x, y, yaw_rad], "cmd": [v, w], "label", "image"}
                     (+ "executed": [v, w] in correction sessions, where the planner drove
                     and "cmd" is the demonstrator's correction)
                     (+ "depth" and "attitude": [z_m, pitch_rad, roll_rad] for a frame that
                     carries a depth image: on relief, or imported from a log with a depth topic)
    images/NNNNNN.png  the segmentation frame, single-channel class ids
    depth/NNNNNN.png   the frame's depth image, if it carries one: 16-bit millimetres along the
                     optical axis, 0 where nothing is seen (REP 118's 16UC1)

A frame's image and depth image are written (atomically, via rename) before its line is
appended, so if the process is killed, every line in ``frames.jsonl`` refers to complete images
and at most the last line is cut short; the reader drops a cut line and reports the recording as
partial.

A depth image is placed in the world by the frame's pose and the body's ``attitude`` (its
height, pitch and roll, REP 103: terrapref.vehicle.ground.Attitude), written with it. Frames
without a depth image (flat ground, a log without a depth topic, recordings made before depth
was kept) have neither key and read as before: no depth, the body level. A frame with a depth
image but no attitude (written by another tool) is taken as level at height 0. The format stays
``terrapref-recording/1``: the keys are optional, and a reader that does not know them reads the
recording's frames as they were.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from datetime import datetime, timezone
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import yaml

from terrapref.camera import SegmentationView, as_view
from terrapref.errors import UserError, described, finite_number
from terrapref.fileio import free_partial, keep_if_stopped, new_folder, release_folder, replace_dir, write_text_atomic
from terrapref.pngio import depth_to_millimetres, millimetres_to_depth, read_depth_png, read_label_png, write_png_atomic
from terrapref.tensorfile import parse_metadata
from terrapref.vehicle.ground import LEVEL, Attitude
from terrapref.yamlio import dump_yaml, load_yaml_text

if TYPE_CHECKING:
    from terrapref.demos.meta import RecordingMeta
    from terrapref.terrain import ClassTable

FORMAT = "terrapref-recording/1"
META = "meta.json"
STATUSES = ("partial", "complete")  # meta.json's status: until the run finishes, and after
FRAMES = "frames.jsonl"
SCENARIO = "scenario.yaml"
IMAGES = "images"
DEPTH = "depth"


def write_json_atomic(path: Path, data: Any) -> None:
    """Write JSON through a temporary file and a rename: readers see the old or the new file."""
    write_text_atomic(path, json.dumps(data, indent=2, sort_keys=False), fsync=True)


def _entries(meta: RecordingMeta | dict[str, Any]) -> dict[str, Any]:
    """A recording's configuration as meta.json holds it."""
    return meta if isinstance(meta, dict) else meta.to_dict()


def is_recording(path: Path) -> bool:
    """Whether the folder ``path`` holds a recording (complete or not)."""
    return (path / META).exists() or (path / FRAMES).exists()


class RecordingWriter:
    """Appends frames to a new recording directory.

    Args:
        out_dir: directory to create; an existing recording there is refused unless
            ``overwrite``; a non-empty directory that is not a recording is always refused.
            With ``overwrite`` the old recording stays untouched until the new one is
            complete: the new one is written beside it and swapped in by :meth:`close`; if the
            run ends early (:meth:`abort`) it is kept as ``OUT.partial`` and the old one stays.
        meta: configuration to store (camera, control set, scenario name, driver...): a
            :class:`~terrapref.demos.meta.RecordingMeta`, or the entries its ``to_dict`` gives.
        scenario: the scenario mapping (``Scenario.to_dict()``) to store beside it.
        flag: the command's option that named ``out_dir``, as its refusal names it.
    """

    def __init__(
        self,
        out_dir: str | Path,
        meta: RecordingMeta | dict[str, Any],
        scenario: dict[str, Any],
        overwrite: bool = False,
        flag: str = "--out",
    ) -> None:
        self.target = Path(out_dir)
        self.dir = self.target
        self.partial_dir: Path | None = None  # where an aborted replacement was left
        if self.target.exists():
            if not self.target.is_dir():
                raise UserError(str(self.target), "exists and is not a directory")
            if is_recording(self.target):
                if not overwrite:
                    raise UserError(
                        str(self.target), f"a recording already exists here; choose another {flag} or pass --force to replace it"
                    )
                self.dir = new_folder(self.target, ".new")
            elif any(self.target.iterdir()):
                raise UserError(str(self.target), "directory is not empty and holds no recording; refusing to write into it")
        self.meta = {
            "format": FORMAT,
            "status": "partial",
            "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            **_entries(meta),
        }
        made = not self.dir.exists() or self.dir != self.target
        try:
            (self.dir / IMAGES).mkdir(parents=True, exist_ok=True)
            write_text_atomic(self.dir / SCENARIO, dump_yaml(scenario, sort_keys=False))
            write_json_atomic(self.dir / META, self.meta)
            self._frames = open(self.dir / FRAMES, "a", buffering=1)
        except OSError as exc:  # a full disk before the first frame: nothing is left behind
            if made:
                release_folder(self.dir)
            raise OSError(exc.errno, exc.strerror or str(exc), str(self.target)) from None
        self.count = 0
        self._made = made

    def append(
        self,
        time_s: float,
        pose: tuple[float, float, float],
        image: np.ndarray | SegmentationView,
        command: tuple[float, float],
        label: int,
        executed: tuple[float, float] | None = None,
    ) -> None:
        """Store one frame: its images first, then its line (flushed), so a kill never orphans a line.

        ``image`` is the frame's class ids, or its view: a view that carries a depth image
        (:attr:`SegmentationView.carries_depth`) has it stored too, with the body's attitude
        (:attr:`SegmentationView.attitude`). ``command`` is the demonstrated command (the
        label's source); ``executed``, when given, is what the vehicle actually did instead (a
        correction session: the planner drove).
        """
        view = as_view(image)
        name = f"{IMAGES}/{self.count:06d}.png"
        write_png_atomic(self.dir / name, view.image, compress_level=3)
        line = {
            "i": self.count,
            "t": round(float(time_s), 6),
            "pose": [float(pose[0]), float(pose[1]), float(pose[2])],
            "cmd": [float(command[0]), float(command[1])],
            "label": int(label),
            "image": name,
        }
        if executed is not None:
            line["executed"] = [float(executed[0]), float(executed[1])]
        if view.carries_depth:
            line.update(self._depth(view))
        try:
            self._frames.write(json.dumps(line) + "\n")
            self._frames.flush()
        except OSError as exc:
            raise OSError(exc.errno, exc.strerror or str(exc), str(self.dir / FRAMES)) from None
        self.count += 1
        if self.count == 1 and self.dir != self.target:  # a replacement with a frame: kept if the command is killed
            keep_if_stopped(self.dir)

    def _depth(self, view: SegmentationView) -> dict[str, Any]:
        """Write ``view``'s depth image (as whole millimetres) for the next frame; its line's entries."""
        name = f"{DEPTH}/{self.count:06d}.png"  # its folder made with the first
        write_png_atomic(self.dir / name, depth_to_millimetres(view.depth), compress_level=3)
        return {"depth": name, "attitude": [float(a) for a in view.attitude]}

    def close(self, summary: dict[str, Any] | None = None) -> None:
        """Mark the recording complete (atomically) with an optional summary. A run that kept no
        frame is no recording: it is removed (an old one it was to replace stays) and refused."""
        if self.count == 0:
            self.abort()
            raise UserError(
                str(self.target),
                "not written: no frame reached the recording (a perception file that drops every frame, "
                "or a drive ended before its first frame)",
            )
        self._frames.close()
        self.meta.update(status="complete", frames=self.count, finished=datetime.now(timezone.utc).isoformat(timespec="seconds"))
        if summary:
            self.meta["summary"] = summary
        write_json_atomic(self.dir / META, self.meta)
        if self.dir != self.target:  # the replacement is complete: swap it in
            self.dir = replace_dir(self.dir, self.target)

    def abort(self) -> None:
        """Stop writing and leave the recording marked partial (a replacement beside the old
        recording, as ``OUT.partial``); one that holds no frame yet is removed, when this
        writer made its folder."""
        self._frames.close()
        if self.count == 0 and self._made:
            release_folder(self.dir)
            return
        if self.dir != self.target:
            self.dir = self.partial_dir = replace_dir(self.dir, free_partial(self.target))

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None and not self._frames.closed:
            self.abort()


class MemoryRecordingWriter:
    """A :class:`RecordingWriter` that keeps the run in memory: the same frames, labels and
    metadata, with each frame's segmentation as the simulation's view (rendered only as far as
    it is read), and no files. For the synthetic driver's demonstrations inside a job that only
    featurises them: :meth:`recording` gives the :class:`Recording` to featurise. A frame that
    carries a depth image (on relief: rendered whole) is kept as a file would keep it: its class
    ids, its depth in whole millimetres (16 bits a pixel, 0.6 MB a 640x480 frame, not float32's
    1.2 MB) and the body's attitude.

    Args:
        target: where the recording would have been written (its name in datasets and models).
        meta, scenario: as :class:`RecordingWriter`'s.
    """

    def __init__(self, target: str | Path, meta: RecordingMeta | dict[str, Any], scenario: dict[str, Any]) -> None:
        self.target = Path(target)
        self.partial_dir: Path | None = None
        self.meta = {"format": FORMAT, "status": "partial", **_entries(meta)}
        self.scenario = scenario
        self._rows: list[tuple[float, tuple[float, float, float], tuple[float, float], int]] = []
        self._views: list[SegmentationView] = []
        self._depths: list[np.ndarray | None] = []  # each frame's depth image [mm, 0: no return], None: none

    @property
    def count(self) -> int:
        return len(self._rows)

    def append(
        self,
        time_s: float,
        pose: tuple[float, float, float],
        image: np.ndarray | SegmentationView,
        command: tuple[float, float],
        label: int,
        executed: tuple[float, float] | None = None,
    ) -> None:
        """Keep one frame as :meth:`RecordingWriter.append` writes it (time rounded to the
        microsecond); ``executed``, which a recording read back does not hold either, is not kept."""
        self._rows.append(
            (round(float(time_s), 6), (float(pose[0]), float(pose[1]), float(pose[2])), (float(command[0]), float(command[1])), int(label))
        )
        view = as_view(image)
        if view.carries_depth:  # kept as the file keeps it: the class ids, whole millimetres, the attitude
            self._depths.append(depth_to_millimetres(view.depth))
            view = SegmentationView.of(view.image, None, view.attitude)
        else:
            self._depths.append(None)
        self._views.append(view)

    def close(self, summary: dict[str, Any] | None = None) -> None:
        self.meta.update(status="complete", frames=self.count)
        if summary:
            self.meta["summary"] = summary

    def abort(self) -> None:
        """Nothing was written: nothing to keep."""

    def recording(self) -> Recording:
        """The run as a recording (complete once :meth:`close` ran)."""
        f = self.count
        return Recording(
            path=self.target,
            meta=self.meta,
            scenario=self.scenario,
            times=np.array([r[0] for r in self._rows], dtype=float),
            poses=np.array([r[1] for r in self._rows], dtype=float).reshape(f, 3),
            commands=np.array([r[2] for r in self._rows], dtype=float).reshape(f, 2),
            labels=np.array([r[3] for r in self._rows], dtype=np.int64),
            image_files=(),
            complete=self.meta["status"] == "complete",
            views=tuple(self._views),
            kept_depths=tuple(self._depths) if any(d is not None for d in self._depths) else (),
        )


@dataclass(frozen=True)
class Recording:
    """A recording read back from disk.

    Attributes:
        times: frame times [s], shape (F,).
        poses: poses (x, y, yaw) [m, m, rad], shape (F, 3).
        commands: commands (v, w) held after each frame, shape (F, 2).
        labels: control-set index of each command at record time, shape (F,).
        complete: False if the run did not finish (crash, kill, interruption).
        views: for a recording kept in memory (:class:`MemoryRecordingWriter`), each frame's
            segmentation as the simulation rendered it; None for one read from disk.
        kept_depths: for a recording kept in memory, each frame's depth image in whole
            millimetres (uint16, 0: no return; None: the frame carries none); empty when no frame does.
        folder: the identity (device, inode) of the folder it was read from: a recording
            replaced while it is read (``record --force`` into it) is another folder, and each
            image read checks it, so a reader sees one whole recording or fails clearly.
        depth_files: each frame's depth image file (None: the frame carries none); empty when
            no frame does (read from disk; a recording kept in memory has its views' depths).
        attitudes: the body's attitude (z [m], pitch, roll [rad]) at each frame, shape (F, 3);
            None where no frame carries one (level: flat ground).
    """

    path: Path
    meta: dict[str, Any]
    scenario: dict[str, Any]
    times: np.ndarray
    poses: np.ndarray
    commands: np.ndarray
    labels: np.ndarray
    image_files: tuple[str, ...]
    complete: bool
    views: tuple[SegmentationView, ...] | None = None
    folder: tuple[int, int] | None = None
    depth_files: tuple[str | None, ...] = ()
    attitudes: np.ndarray | None = None
    kept_depths: tuple[np.ndarray | None, ...] = ()

    def __len__(self) -> int:
        return len(self.times)

    def lethal_contact(self) -> str | None:
        """What the drive's summary says of lethal terrain under the footprint ("2 entries, 3.4 s,
        2.9 m"), None when it touched none (or, recorded before contact was counted, entered none)."""
        run = self.meta.get("summary") if isinstance(self.meta.get("summary"), dict) else {}
        for key in ("collisions", "contact_s", "contact_m"):
            if run.get(key) is not None and not (finite_number(run[key]) and run[key] >= 0):
                raise UserError(str(self.path / META), f"expected a number >= 0, got {described(run[key])}", field=f"summary.{key}")
        entries, seconds, metres = run.get("collisions") or 0, run.get("contact_s") or 0.0, run.get("contact_m")
        if not entries and not seconds:
            return None
        parts = (
            [f"{entries} entr{'y' if entries == 1 else 'ies'}"]
            + ([f"{seconds:.1f} s"] if seconds else [])
            + ([f"{metres:.1f} m"] if metres else [])
        )
        return ", ".join(parts)

    @property
    def frame_period_s(self) -> float:
        """The usual time between frames [s]: the median step (0.1, the camera's 10 Hz, with fewer than two frames)."""
        return float(np.median(np.diff(self.times))) if len(self.times) > 1 else 0.1

    @property
    def duration_s(self) -> float:
        """Time the frames cover [s]: frames x the frame period (gaps, as between a ride-along's
        corrections, do not count)."""
        return len(self.times) * self.frame_period_s

    @cached_property
    def header(self) -> RecordingMeta:
        """The configuration in :attr:`meta` as a typed record (read once, checked when the recording was read)."""
        from terrapref.demos.meta import RecordingMeta

        return RecordingMeta.from_dict(self.meta, str(self.path / META))

    @property
    def classes(self) -> ClassTable:
        """The class table of the frames' ids (checked when the recording was read); a recording
        whose meta.json names none is refused, naming the field."""
        table = self.header.classes
        if table is None:
            raise UserError(str(self.path / META), "missing; the class table of the frames' ids is needed here", field="classes")
        return table

    @property
    def perception(self) -> str:
        """The name of the perception model the frames went through ('clean': the simulator's truth)."""
        model = self.meta.get("perception")
        return str(model.get("name", "clean")) if isinstance(model, dict) else "clean"

    @property
    def in_memory(self) -> bool:
        """Whether the frames are the simulation's own (:class:`MemoryRecordingWriter`), not files."""
        return self.views is not None

    def image(self, i: int) -> np.ndarray:
        """Frame ``i``'s class ids (H, W) uint8; an unreadable or foreign image is a UserError."""
        if self.views is not None:
            return self.views[i].image
        path = self.path / self.image_files[i]
        try:
            image = read_label_png(path)
        except (OSError, ValueError, SyntaxError) as exc:  # Pillow's errors on damaged or foreign files
            self._check_same_folder()  # a missing image of a replaced recording is said as such
            raise UserError(str(path), f"not a single-channel 8-bit class-id PNG ({exc})") from None
        self._check_same_folder()  # after the read: an image of a recording swapped in meanwhile is never used
        return image

    @property
    def has_depth(self) -> bool:
        """Whether any frame carries a depth image (a drive on relief, a log with a depth topic)."""
        if self.views is not None:
            return bool(self.kept_depths)
        return any(name is not None for name in self.depth_files)

    def depth(self, i: int) -> np.ndarray | None:
        """Frame ``i``'s depth image (H, W) float32 [m along the optical axis, NaN: no return], in
        whole millimetres as the file holds it (a recording kept in memory gives its view's
        depth so rounded too: the same frames either way); None for a frame without one. An
        unreadable or foreign file is a UserError."""
        if self.views is not None:
            kept = self.kept_depths[i] if self.kept_depths else None
            return millimetres_to_depth(kept) if kept is not None else None
        name = self.depth_files[i] if self.depth_files else None
        if name is None:
            return None
        path = self.path / name
        try:
            depth = read_depth_png(path)
        except (OSError, ValueError, SyntaxError) as exc:  # Pillow's errors on damaged or foreign files
            self._check_same_folder()
            raise UserError(str(path), f"not a single-channel 16-bit depth PNG of millimetres ({exc})") from None
        self._check_same_folder()
        return depth

    def attitude(self, i: int) -> Attitude:
        """The body's height, pitch and roll at frame ``i`` (level where the recording holds none)."""
        if self.views is not None:
            return self.views[i].attitude
        return LEVEL if self.attitudes is None else Attitude(*(float(a) for a in self.attitudes[i]))

    def view(self, i: int) -> SegmentationView:
        """Frame ``i`` as a view: its class ids, its depth image if it carries one, and the body's attitude."""
        depth = self.depth(i)
        if self.views is not None and depth is None:
            return self.views[i]
        return SegmentationView.of(self.image(i), depth, self.attitude(i))

    def _check_same_folder(self) -> None:
        if self.folder is not None and _folder_identity(self.path) != self.folder:
            raise UserError(str(self.path), "was replaced or removed while it was being read (another command wrote it); run this again")

    def images(self) -> np.ndarray:
        """All frames, shape (F, H, W) uint8."""
        return np.stack([self.image(i) for i in range(len(self))]) if len(self) else np.zeros((0, 0, 0), np.uint8)


MAX_POSE = 1e7  # a frame's pose: x and y [m] and heading [rad] within this of 0 (UTM coordinates fit)
# The largest command a frame may record, either way: a speed [m/s] past what an import takes from a
# log of a robot file's fastest robot (30 m/s, commands to 1.5 times it and 0.5), and a yaw rate
# [rad/s] no wheel turns at (a log's, in whatever units, comes nowhere near it).
MAX_CMD = (50.0, 1e6)


def _frame_problem(row: dict) -> tuple[str, str] | None:
    """(field, message) of the first thing wrong with one frame record, or None."""

    if not finite_number(row["t"]):
        return "t", "expected a finite time [s]"
    for key, size in (("pose", 3), ("cmd", 2)):
        v = row[key]
        if not (isinstance(v, list) and len(v) == size and all(finite_number(x) for x in v)):
            return key, f"expected {size} finite numbers"
    if not all(abs(x) <= MAX_POSE for x in row["pose"]):
        return "pose", f"expected x and y [m] and a heading [rad] within +-{MAX_POSE:g} (a place on Earth), got {row['pose']}"
    if not (abs(row["cmd"][0]) <= MAX_CMD[0] and abs(row["cmd"][1]) <= MAX_CMD[1]):
        return "cmd", f"expected a speed within +-{MAX_CMD[0]:g} m/s and a yaw rate within +-{MAX_CMD[1]:g} rad/s, got {row['cmd']}"
    if isinstance(row["label"], bool) or not isinstance(row["label"], int) or row["label"] < 0:
        return "label", "expected an integer >= 0"
    index = row.get("i")  # optional: a recording another tool wrote may not number its frames
    if index is not None and (isinstance(index, bool) or not isinstance(index, int) or index < 0):
        return "i", f"expected the frame's index, an integer >= 0, got {described(index)}"
    image = row["image"]
    if not isinstance(image, str) or not image.startswith(f"{IMAGES}/") or ".." in image:
        return "image", f"expected a file name under {IMAGES}/"
    depth = row.get("depth")
    if depth is not None and (not isinstance(depth, str) or not depth.startswith(f"{DEPTH}/") or ".." in depth):
        return "depth", f"expected a file name under {DEPTH}/"
    attitude = row.get("attitude")
    if attitude is not None and not (isinstance(attitude, list) and len(attitude) == 3 and all(finite_number(x) for x in attitude)):
        return "attitude", "expected 3 finite numbers: z [m], pitch and roll [rad]"
    if attitude is not None and abs(attitude[0]) > MAX_POSE:
        return "attitude", f"expected a height z within +-{MAX_POSE:g} m, got {attitude[0]:g}"
    if attitude is not None and not all(abs(a) < 0.5 * math.pi for a in attitude[1:]):
        return "attitude", f"pitch {attitude[1]:g} and roll {attitude[2]:g} rad: expected each within +-pi/2 (a body on its wheels)"
    if (depth is None) != (attitude is None):
        return ("attitude" if attitude is None else "depth"), "missing: a frame on relief carries its depth image and its attitude together"
    return None


def _check_meta(meta: dict, path: Path) -> int | None:
    """The configuration a recording must carry, parsed once here so every later use is safe;
    the number of trajectories its labels index (None: it names no preference set)."""
    from terrapref.demos.meta import RecordingMeta

    parsed = RecordingMeta.from_dict(meta, str(path))
    return parsed.preference_set.m if parsed.preference_set is not None else None


def require_meta(recording: Recording, *keys: str) -> None:
    """Refuse a recording whose meta.json lacks what a use of it needs."""
    for key in keys:
        if key not in recording.meta:
            raise UserError(str(recording.path / META), "missing; the recording cannot be featurised without it", field=key)


def read_recording(path: str | Path) -> Recording:
    """Read a recording; a cut final line (the process was killed) is dropped.

    Raises:
        UserError: not a recording, unknown format, or a malformed line/field (named).
    """
    root = Path(path)
    folder = _folder_identity(root)
    meta = _read_meta(root)
    scenario = _read_scenario(root)
    trajectories = _check_meta(meta, root / META)
    frames = _read_frames(root, trajectories)
    complete = _is_complete(meta, frames, root / FRAMES)
    if _folder_identity(root) != folder:  # what was read may be of two recordings
        raise UserError(str(root), "was replaced or removed while it was being read (another command wrote it); run this again")
    rows, f = frames.rows, len(frames.rows)
    tilted = any(r.get("attitude") is not None for r in rows)
    return Recording(
        path=root,
        meta=meta,
        scenario=scenario,
        times=np.array([r["t"] for r in rows], dtype=float),
        poses=np.array([r["pose"] for r in rows], dtype=float).reshape(f, 3),
        commands=np.array([r["cmd"] for r in rows], dtype=float).reshape(f, 2),
        labels=np.array([r["label"] for r in rows], dtype=np.int64),
        image_files=tuple(r["image"] for r in rows),
        complete=complete,
        folder=folder,
        depth_files=tuple(r.get("depth") for r in rows) if any(r.get("depth") is not None for r in rows) else (),
        attitudes=np.array([r.get("attitude") or LEVEL for r in rows], dtype=float).reshape(f, 3) if tilted else None,
    )


def _folder_identity(root: Path) -> tuple[int, int] | None:
    """The folder's (device, inode), None if it is gone."""
    try:
        st = os.stat(root)
    except OSError:
        return None
    return st.st_dev, st.st_ino


@dataclass(frozen=True)
class _Frames:
    """The frame records read from frames.jsonl, in order.

    Attributes:
        rows: one parsed, checked record per frame whose image is on disk.
        cut: True if reading stopped at a last line (or image) that a kill left incomplete.
    """

    rows: tuple[dict, ...]
    cut: bool


def _read_meta(root: Path) -> dict:
    """The recording's meta.json, which must declare this format."""
    meta_path = root / META
    if root.is_file():  # a model, a dataset, a log: say what a recording is, and where the file goes
        raise UserError(
            str(root),
            "a file, not a recording (a recording is the folder `terrapref record` or `drive` writes; "
            "`terrapref info FILE` shows a model or a dataset)",
        )
    if not root.is_dir():
        raise UserError(str(root), "no such recording directory")
    try:
        text = meta_path.read_text()
    except FileNotFoundError:
        raise UserError(str(meta_path), "missing; not a terrapref recording") from None
    except UnicodeDecodeError as exc:
        raise UserError(str(meta_path), f"not valid JSON ({exc})") from None
    meta = parse_metadata(text, str(meta_path), field="")
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise UserError(str(meta_path), f"expected {FORMAT!r}", field="format")
    return meta


def _read_scenario(root: Path) -> dict:
    """The scenario mapping stored beside the frames (checked when it is parsed, not here)."""
    try:
        scenario = load_yaml_text((root / SCENARIO).read_text())
    except (OSError, UnicodeDecodeError):
        raise UserError(str(root / SCENARIO), "missing or unreadable") from None
    except yaml.YAMLError as exc:
        problem = getattr(exc, "problem", None) or "invalid syntax"
        raise UserError(str(root / SCENARIO), f"malformed YAML: {problem}") from None
    if not isinstance(scenario, dict):
        raise UserError(str(root / SCENARIO), f"expected a terrapref-scenario/1 mapping, got {type(scenario).__name__}")
    return scenario


def _frames_text(frames_path: Path) -> str:
    """The text of frames.jsonl ("" if there is none yet: the run stopped before its first frame)."""
    try:
        return frames_path.read_bytes().decode("utf-8") if frames_path.exists() else ""
    except UnicodeDecodeError as exc:
        raise UserError(str(frames_path), f"not UTF-8 text (byte {exc.start}); expected one JSON object per line") from None
    except OSError as exc:
        raise UserError(str(frames_path), f"unreadable ({exc.strerror or exc})") from None


def _read_frames(root: Path, trajectories: int | None = None) -> _Frames:
    """Every frame record, checked (a label among ``trajectories``, where known), up to the first
    one a kill cut short (which is dropped)."""
    frames_path = root / FRAMES
    lines = _frames_text(frames_path).split("\n")
    rows: list[dict] = []
    for n, line in enumerate(lines):
        if not line.strip():
            continue
        row = _frame_record(line)
        if row is None:
            if n == len(lines) - 1:  # a final line without its newline: cut by a kill
                return _Frames(tuple(rows), cut=True)
            raise UserError(str(frames_path), f"line {n + 1} is not a frame record", field=f"line {n + 1}")
        _check_frame(row, rows[-1] if rows else None, frames_path, n + 1)
        if trajectories is not None and row["label"] >= trajectories:
            raise UserError(
                str(frames_path),
                f"{row['label']} is not one of the preference set's {trajectories} trajectories (0-{trajectories - 1})",
                field=f"line {n + 1}.label",
            )
        for key in ("image", "depth"):
            if row.get(key) is not None and not (root / row[key]).exists():
                if n >= len(lines) - 2:
                    return _Frames(tuple(rows), cut=True)
                raise UserError(str(frames_path), f"line {n + 1}: {key} {row[key]} is missing", field=f"line {n + 1}.{key}")
        rows.append(row)
    return _Frames(tuple(rows), cut=False)


def _frame_record(line: str) -> dict | None:
    """One line parsed as a frame record with every key present, or None."""
    try:
        row = json.loads(line)
    except (ValueError, RecursionError):  # not JSON, an integer of thousands of digits, nested past the parser's reach
        return None
    return row if isinstance(row, dict) and all(k in row for k in ("t", "pose", "cmd", "label", "image")) else None


def _check_frame(row: dict, previous: dict | None, frames_path: Path, line_no: int) -> None:
    """Refuse a malformed record, or one whose time does not follow the ``previous`` record's."""
    problem = _frame_problem(row)
    if problem:
        raise UserError(str(frames_path), problem[1], field=f"line {line_no}.{problem[0]}")
    lost = row.get("depth") is None
    if previous is not None and lost != (previous.get("depth") is None):
        raise UserError(
            str(frames_path),
            f"{'has no' if lost else 'has a'} depth image where the frame before it {'had one' if lost else 'had none'}; "
            "a recording's frames all carry depth, or none does",
            field=f"line {line_no}.depth",
        )
    if previous is not None and not row["t"] > previous["t"]:
        raise UserError(
            str(frames_path), f"time {row['t']} does not follow {previous['t']}; frames must be in time order", field=f"line {line_no}.t"
        )
    if previous is not None and row.get("i") is not None and previous.get("i") is not None and not row["i"] > previous["i"]:
        raise UserError(
            str(frames_path),
            f"frame index {row['i']} does not follow the previous frame's {previous['i']}; each frame has its own index, in order",
            field=f"line {line_no}.i",
        )


def _is_complete(meta: dict, frames: _Frames, frames_path: Path) -> bool:
    """Whether the run finished; a finished run must hold the frames its meta.json declares, and
    no cut last line (which only a recorder killed before it finished leaves). A status that is
    neither is refused: a partial run read as one would lose the check of a finished run's frames."""
    status = meta.get("status")
    if status not in STATUSES:
        allowed = " or ".join(map(repr, STATUSES))
        said = f"expected {allowed}, got {described(status)}" if "status" in meta else f"missing; expected {allowed}"
        raise UserError(str(frames_path.parent / META), said, field="status")
    if status != "complete":
        return False
    f = len(frames.rows)
    declared = meta.get("frames")
    if declared is not None and (isinstance(declared, bool) or not isinstance(declared, int) or declared < 0):
        raise UserError(str(frames_path.parent / META), f"expected the number of frames, got {described(declared)}", field="frames")
    if frames.cut or (declared is not None and declared != f):
        said = f"{declared} frames" if declared is not None else "it finished"
        raise UserError(
            str(frames_path),
            f"holds {f} frames{' and a cut last line' if frames.cut else ''}; meta.json says the complete run has {said} (truncated or edited?)",
            field="frames",
        )
    return True
