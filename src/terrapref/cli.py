"""The ``terrapref`` command: thin wrappers over the library.

Every user error (bad file, bad flag value, mismatched model) is printed as one line per
problem, naming the file and the field, and exits with code 2.
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import signal
import stat
import sys
import tempfile
import threading
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

from terrapref.configargs import finite_float
from terrapref.errors import Terminated, UserError
from terrapref.fileio import output_folder
from terrapref.grid import ENGINES, Engine, GridError

if TYPE_CHECKING:  # for the hints only: the command line imports what a command needs when it runs
    from terrapref.dataset import Dataset
    from terrapref.learning.train import EpochMetrics, TrainConfig, TrainResult
    from terrapref.recipes import Recipe


def _cmd_validate(args: argparse.Namespace) -> int:
    from terrapref.filekinds import KINDS, check_file, template
    from terrapref.scenario import load_scenario
    from terrapref.scenario.catalog import scenario_path

    if args.template is not None:
        if args.files:
            raise UserError("--template", "prints a template to start from; give it alone, or FILEs to check without it")
        print(template(args.template), end="")
        return 0
    if not args.files:
        raise UserError("validate", f"give the files to check, or --template KIND ({', '.join(KINDS)}) for one to start from")
    status = 0
    table = _class_table(args)
    for name in args.files:
        try:
            if _is_file(name):
                kind = check_file(name, table).title
            else:  # a packaged scenario's name
                load_scenario(scenario_path(name), table)
                kind = KINDS["scenario"].title
        except UserError as exc:
            for line in exc.lines():
                print(f"error: {line}")  # in the report's order, beside the files that are ok
            status = 2
        else:
            print(f"{name}: ok ({kind})")
    return status


def _is_file(name: str) -> bool:
    try:
        return Path(name).is_file()
    except OSError:  # a name the OS refuses (too long): the scenario reader says so
        return False


def _cmd_render(args: argparse.Namespace) -> int:
    from terrapref.camera import PinholeCamera, SegmentationRenderer
    from terrapref.pngio import preview_with_legend, write_png_atomic
    from terrapref.scenario import resolve_scenario
    from terrapref.vehicle import Pose
    from terrapref.world import rasterise

    if args.pose is not None and not all(math.isfinite(v) for v in args.pose):
        raise UserError("--pose", "X, Y and YAW_DEG must be finite numbers")
    _check_output(args.out, "--out", [args.scenario], force=args.force)
    if args.preview:
        _check_output(args.preview, "--preview", [args.scenario, args.out], force=args.force)
    for flag, path in (("--out", args.out), ("--preview", args.preview)):
        if path is not None and Path(path).suffix.lower() != ".png":  # a lossy format would change the class ids
            raise UserError(str(path), "render writes PNG (class ids need a lossless format): give it the suffix .png", field=flag)
    scenario = resolve_scenario(args.scenario, _class_table(args))
    x, y, yaw_deg = args.pose if args.pose is not None else (scenario.start[0], scenario.start[1], math.degrees(scenario.start[2]))
    camera = PinholeCamera()
    (w, h), reach = scenario.size_m, camera.config.max_range_m
    if not (-reach <= x <= w + reach and -reach <= y <= h + reach and abs(yaw_deg) <= 1e6):
        raise UserError("--pose", f"({x:g}, {y:g}, {yaw_deg:g} deg) is not a pose the camera sees {scenario.name}'s {w:g} x {h:g} m world from "
                        f"(x and y within {reach:g} m of it, |yaw| <= 1e6 deg)")
    renderer = SegmentationRenderer(camera, rasterise(scenario))
    image = renderer.render(Pose(x, y, math.radians(yaw_deg)))
    write_png_atomic(args.out, image)
    print(f"wrote {args.out} ({image.shape[1]}x{image.shape[0]} class ids)")
    if args.preview:
        write_png_atomic(args.preview, preview_with_legend(image, scenario.classes))
        print(f"wrote {args.preview} (colour preview, the image and a legend beside it)")
    return 0


def _cmd_show(args: argparse.Namespace) -> int:
    from terrapref.plots import save_map
    from terrapref.scenario import resolve_scenario
    from terrapref.world import rasterise

    _check_figure(args.out, "--out")
    _check_output(args.out, "--out", [args.scenario], force=args.force)
    scenario = resolve_scenario(args.scenario, _class_table(args))
    save_map(args.out, scenario, rasterise(scenario))
    print(f"wrote {args.out} ({scenario.name}: {len(scenario.terrain)} patches, {len(scenario.zones)} zones, path {scenario.path_length_m():.0f} m)")
    return 0


def _cmd_course(args: argparse.Namespace) -> int:
    from collections import Counter

    from terrapref.fileio import write_text_atomic
    from terrapref.plots import save_map
    from terrapref.scenario import parse_scenario
    from terrapref.scenario.teaching import DRIVER_SPEED_MPS, build_course, description, fits, follow_up, follow_up_course, situations
    from terrapref.terrain import default_classes
    from terrapref.world import rasterise

    out = Path(args.out)
    if out.suffix.lower() not in (".yaml", ".yml"):
        raise UserError(str(out), "a course is a scenario file: give it the suffix .yaml", field="--out")
    figure = out.with_suffix(".png")
    inputs = [p for p in (args.classes, *(args.after or ())) if p is not None]
    for path in (out, figure):
        _check_output(path, "--out", inputs, force=args.force)
    table = _class_table(args)
    if args.after is not None:
        recs = _drives_of_one_table(args, args.after)
        table = recs[0].classes
        open_pairs = _open_pairs(recs)
        drives = "drives together" if len(recs) > 1 else "drive"
        if not open_pairs:
            print(f"{', '.join(map(str, args.after))}: the {drives} identified every pair of classes; no follow-up course is needed (nothing written)")
            return 0
        items = follow_up(table, open_pairs)
        driven = list(dict.fromkeys(str(r.meta.get("scenario")) for r in recs))
        course = follow_up_course(table, open_pairs, args.name or f"{Path(driven[0]).name}_more", " and ".join(driven), drives=len(recs))
        print(f"the {drives} left {len(open_pairs)} pairs open: {', '.join(f'{a} vs {b}' for a, b in open_pairs)}")
    else:
        table = table or default_classes()
        try:
            full = fits(table) if args.design == "auto" else args.design == "full"
            items = situations(table, full)
        except ValueError as exc:
            raise UserError(str(args.classes or "classes"), str(exc), field="classes") from None
        course = build_course(table, items, args.name or "teaching_course", description(table, full))
    scenario = parse_scenario(course.data(), str(out), table)  # checked as every command will read it
    source = f"--classes {args.classes}" if args.classes else ("--after " + " ".join(map(str, args.after)) if args.after else "the default class table")
    write_text_atomic(out, f"# terrapref course ({source}); it carries its class table (classes:), so no command needs --classes for it.\n"
                      + course.to_yaml())
    save_map(figure, scenario, rasterise(scenario))
    length = scenario.path_length_m()
    kinds = Counter(item.kind for item in items)
    print(f"{scenario.name}: {scenario.description}")
    print(f"  {len(items)} situations ({', '.join(f'{n} {k}' for k, n in kinds.items())}); path {length:.0f} m; "
          f"expected drive about {length / DRIVER_SPEED_MPS / 60:.1f} minutes at {DRIVER_SPEED_MPS:g} m/s")
    print(f"wrote {out} and {figure} (record it: terrapref record {out} --out DIR)")
    return 0


def _drives_of_one_table(args: argparse.Namespace, paths: Sequence[Path]) -> list:
    """The recordings ``course --after`` reads, each given once and all of one class table
    (``--classes``' when given, else the first's)."""
    from terrapref.demos.recording import read_recording

    _check_distinct(paths, "recording")
    recs = [read_recording(p) for p in paths]
    for path, rec in zip(paths, recs, strict=True):
        if _class_table(args) is not None:
            _check_table(args, rec.classes, path)
        elif not rec.classes.same_classes(recs[0].classes):
            raise UserError(str(path), f"was made for the class table of {', '.join(rec.classes.names)}, not {paths[0]}'s "
                                       f"({', '.join(recs[0].classes.names)}): give drives of one table", field="classes")
    return recs


def _open_pairs(recs: Sequence) -> list[tuple[str, str]]:
    """The pairs of classes that recordings' drives together leave unidentified (the report ``inspect`` prints)."""
    from terrapref.recipes import DEFAULT_RECIPE, open_pairs, recipe_named

    for rec in recs:
        if len(rec) == 0:
            raise UserError(str(rec.path), "holds no frames: drive the teaching course first", field="frames")
    from terrapref.progress import Progress

    total = sum(len(r) for r in recs)
    bar = Progress(f"featurising the drive{'s' if len(recs) > 1 else ''} to find the pairs left open", total, unit="frames")
    pairs = open_pairs(list(recs), recipe_named(DEFAULT_RECIPE), frames=lambda done, n: bar.update(done, f"{done}/{n} frames"))
    bar.close(f"{total} frames")
    return pairs


def _cmd_list(args: argparse.Namespace) -> int:
    from terrapref.scenario import packaged_scenarios, resolve_scenario

    names = packaged_scenarios()
    width = max(map(len, names), default=0)
    for name in names:
        s = resolve_scenario(name)
        print(f"{name:{width}s} {s.size_m[0]:5.0f} x {s.size_m[1]:<4.0f} m  path {s.path_length_m():5.0f} m  {len(s.zones):2d} zones  {s.description}")
    return 0


def _disturbance(rate_hz: float | None):
    """--disturb RATE: pushes per second while demonstrating (0: none; not given: the recommended
    protocol's, that of the default recipe)."""
    from dataclasses import replace

    from terrapref.recipes import DEFAULT_RECIPE, RECIPES

    protocol = RECIPES[DEFAULT_RECIPE].disturbance
    if rate_hz is None:
        return protocol
    if not (math.isfinite(rate_hz) and rate_hz >= 0):
        raise UserError("--disturb", "must be a number >= 0 (pushes per second)")
    return replace(protocol, rate_hz=rate_hz) if rate_hz > 0 else None


def _cmd_record(args: argparse.Namespace) -> int:
    import numpy as np

    from terrapref.camera import CameraConfig
    from terrapref.demos.expert import ExpertConfig, ExpertDriver
    from terrapref.demos.recording import RecordingWriter
    from terrapref.demos.meta import ExpertInfo, RecordingMeta, RecordingSetup
    from terrapref.demos.session import RunSettings, record_run
    from terrapref.features import PreferenceSetConfig
    from terrapref.progress import Progress
    from terrapref.scenario import resolve_scenario
    from terrapref.sim import SimConfig, Simulation
    from terrapref.terrain import PreferenceProfile

    if args.seed < 0:
        raise UserError("--seed", f"must be an integer >= 0, got {args.seed}")
    _check_output(args.out, "--out", [args.scenario], folder=True)
    scenario = resolve_scenario(args.scenario, _class_table(args))
    profile = PreferenceProfile.parse(args.profile, scenario.classes) if args.profile is not None else PreferenceProfile.default(scenario.classes)
    try:
        expert = ExpertConfig.styled(args.style, profile.order)
    except ValueError as exc:
        raise UserError("--style", str(exc)) from None
    disturbance = _disturbance(args.disturb)
    perception = _perception(args.perception, classes=scenario.classes)
    camera, preference, sim_config = CameraConfig(), PreferenceSetConfig(), SimConfig()
    meta = RecordingMeta.driven(scenario, RecordingSetup(camera, preference, sim_config), ExpertInfo.of(args.seed, args.style, expert, disturbance),
                                profile, perception)
    sim = Simulation(scenario, camera, sim_config)
    writer = RecordingWriter(args.out, meta, scenario.to_dict(), overwrite=args.force)
    bar = Progress(f"record {scenario.name}", sim.path.length_m, enabled=not args.quiet)
    try:
        log = record_run(sim, ExpertDriver(expert, sim_config.camera_rate_hz), writer, RunSettings(preference, disturbance, perception),
                         np.random.default_rng(args.seed), progress=lambda s: bar.update(s.progress_m, f"t={s.time_s:6.1f}s frames={writer.count}"))
    except BaseException as exc:
        writer.abort()
        if writer.partial_dir is not None and isinstance(exc, OSError):  # a full disk: the unfinished replacement goes
            shutil.rmtree(writer.partial_dir, ignore_errors=True)
            print(f"note: {args.out} keeps the recording it held", file=sys.stderr)
        elif writer.partial_dir is not None:
            print(f"note: {args.out} keeps the recording it held; the unfinished new one is in {writer.partial_dir}", file=sys.stderr)
        elif isinstance(exc, OSError):
            print(f"note: {args.out} keeps the {writer.count} frames recorded before the write failed (partial)", file=sys.stderr)
        raise
    bar.close("done")
    state = "reached the goal" if log.completed else "timed out"
    seen = f"; the frames are what the robot received under perception {perception.name}" if perception is not None and perception.active else ""
    contact = f" ({log.contact_s:.1f} s, {log.contact_m:.1f} m with lethal terrain under the vehicle)" if log.contact_s else ""
    print(f"wrote {args.out}: {writer.count} frames, {log.duration_s:.1f} s, {state}, {log.collisions} collisions{contact} (complete){seen}")
    return 0


def _cmd_drive(args: argparse.Namespace) -> int:
    from terrapref.scenario import resolve_scenario
    from terrapref.teleop import TeleopOptions, run_session
    from terrapref.terrain import PreferenceProfile

    if args.seed < 0:
        raise UserError("--seed", f"must be an integer >= 0, got {args.seed}")
    riding = None  # the table of the model riding along: the scenario is read with it
    if args.model is not None:
        from terrapref.learning.model_file import load_model

        riding = load_model(args.model).classes
        if args.classes is not None:
            _check_table(args, riding, args.model)
    scenario = resolve_scenario(args.scenario, _class_table(args) or riding)
    profile = PreferenceProfile.parse(args.profile, scenario.classes) if args.profile is not None else None
    if args.record is not None:
        _check_output(args.record, "--record", [args.scenario, *([args.model] if args.model else [])], folder=True)
    perception = _perception(args.perception, classes=scenario.classes)
    view = _live_view(args)
    try:
        result = run_session(scenario, TeleopOptions(record_dir=args.record, overwrite=args.force, v_mps=args.speed, disturbance=_disturbance(args.disturb),
                                                     seed=args.seed, profile=profile, model=args.model, perception=perception, live=view))
    finally:
        if view is not None:
            view.stop()
    where = f", recorded to {result.record_dir}" if result.record_dir else ""
    state = "reached the goal" if result.completed else ("quit" if result.quit else "stopped")
    edge = f", {result.edge_frames} frames held at the map's edge (not recorded)" if result.edge_frames else ""
    edge += f", {result.pushes} push{'es' if result.pushes != 1 else ''} (--disturb 0: none)" if result.pushes else ""
    if args.model is not None:
        print(f"rode along: the planner drove {result.planner_frames} frames, you {result.frames} (corrections){where}; "
              f"{state}, {result.collisions} collisions{edge}")
    else:
        print(f"drove {result.frames} frames, {state}, {result.collisions} collisions{where}{edge}")
    return 0


def _cmd_inspect(args: argparse.Namespace) -> int:
    from terrapref.report.inspect import save_driven_path, summarise
    from terrapref.demos.recording import read_recording

    if args.out is not None:
        _check_figure(args.out, "--out")
        _check_output(args.out, "--out", [args.recording], force=args.force)
    rec = read_recording(args.recording)
    if getattr(args, "classes", None) is not None:
        _check_table(args, rec.classes, args.recording)
    summary = summarise(rec)
    for line in summary.lines():
        print(line)
    out = args.out or rec.path / "driven_path.png"
    _check_figure(out, "--out")
    save_driven_path(summary, rec, out)
    print(f"wrote {out}")
    if not args.no_preference:
        _print_what_the_drive_shows(rec)
    return 0


def _print_what_the_drive_shows(rec) -> None:
    """The identifiability report of a recording (featurised as the default recipe would), before any training."""
    from terrapref.dataset import build_dataset
    from terrapref.recipes import DEFAULT_RECIPE, recipe_named
    from terrapref.learning.train import identify
    from terrapref.progress import Progress

    if len(rec) == 0:
        print("what the drive shows: nothing (no frames)")
        return
    recipe = recipe_named(DEFAULT_RECIPE)
    bar = Progress("featurize", len(rec), unit="frames")
    dataset = build_dataset([rec], recipe.features(), rules=recipe.rules, progress=lambda p: bar.update(p.frames_done, f"{p.frames_done}/{p.frames} frames"))
    bar.close()
    print(f"what the drive shows (recipe {DEFAULT_RECIPE}'s features, {len(dataset)} frames):")
    for line in identify(dataset, steady=recipe.train.data.steady_labels).lines(rec.meta.get("profile")):
        print(f"  {line}")


def _cmd_featurize(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from terrapref.dataset import build_dataset, save_dataset
    from terrapref.demos.recording import read_recording
    from terrapref.progress import Progress

    _check_distinct(args.recordings, "recording")
    _check_output(args.out, "--out", [*args.recordings, *([args.camera] if args.camera else [])], force=args.force)
    recordings = [read_recording(p) for p in args.recordings]
    for r in recordings:
        if args.classes is not None:
            _check_table(args, r.classes, r.path)
        if not r.complete:
            print(f"warning: {r.path} is partial; using its {len(r)} frames", file=sys.stderr)
    from terrapref.recipes import DEFAULT_RECIPE, recipe_named

    recipe = recipe_named(args.recipe or DEFAULT_RECIPE)
    features = replace(recipe.features(), distance_mode=args.distance_mode)
    pref = features.preference
    if args.n_steps is not None or args.dt is not None:
        if args.n_steps is not None and args.n_steps < 1:
            raise UserError("--n-steps", f"must be an integer >= 1, got {args.n_steps}")
        if args.dt is not None and not (math.isfinite(args.dt) and args.dt > 0):
            raise UserError("--dt", f"must be a finite number of seconds > 0, got {args.dt}")
        pref = replace(pref, n_steps=args.n_steps if args.n_steps is not None else pref.n_steps, dt_s=args.dt if args.dt is not None else pref.dt_s)
        features = replace(features, preference=pref)
    camera = None
    if args.camera:
        from terrapref.camera.files import load_camera

        camera = load_camera(args.camera)
    bar = Progress("featurize", len(recordings))
    dataset = build_dataset(recordings, features, camera, recipe.rules, progress=_by_recording(bar))
    bar.close()
    save_dataset(dataset, args.out)
    print(f"wrote {args.out}: {len(dataset)} samples from {len(recordings)} recordings (fingerprint {dataset.fingerprint})")
    return 0


def _by_recording(bar):
    """A featurising progress (terrapref.dataset.Featuring) that moves ``bar`` a whole recording at a time."""
    return lambda p: bar.update(p.recordings_done, f"{p.recordings_done}/{p.recordings} recordings") if p.recordings_done else None


def _stages(args: argparse.Namespace, recipe: Recipe) -> tuple:
    """The recipe's rules with ``--second-stage`` / ``--no-second-stage`` and ``--stage-weight`` on top."""
    from terrapref.rules import SecondStageConfig

    stages = list(recipe.rules)
    second = next((i for i, s in enumerate(stages) if isinstance(s, SecondStageConfig)), None)
    on, weight = getattr(args, "second_stage", None), getattr(args, "stage_weight", None)
    if on is False and second is not None:
        del stages[second]
        second = None
    elif on and second is None:
        stages.insert(0, SecondStageConfig())
        second = 0
    if weight is not None:
        if second is None:
            raise UserError("--stage-weight", f"recipe {recipe.name} has no second stage here (add --second-stage)")
        try:
            stages[second] = replace(stages[second], weight=weight)
        except ValueError as exc:
            raise UserError("--stage-weight", str(exc)) from None
    return tuple(stages)


def _train_config(args: argparse.Namespace, recipe: Recipe) -> TrainConfig:
    """The recipe's training configuration with the flags given on the command line on top."""
    from terrapref.configargs import apply_arguments

    try:
        return apply_arguments(args, recipe.train)
    except ValueError as exc:
        # Name the flag where the configuration's check names a field that has one.
        head, _, rest = str(exc).partition(" ")
        flag = head if head.startswith("--") else f"--{head.replace('_', '-')}" if getattr(args, head, None) is not None else None
        raise UserError(flag or "train", rest if flag else str(exc)) from None


FIGURE_FORMATS = (".png", ".pdf", ".svg", ".jpg", ".jpeg", ".tif", ".tiff", ".webp", ".eps", ".ps")


def _check_figure(out: str | Path, flag: str) -> None:
    """A figure's file name must say a format the plotting library writes."""
    if Path(out).suffix.lower() not in FIGURE_FORMATS:
        raise UserError(str(out), f"a figure needs one of the suffixes {', '.join(FIGURE_FORMATS)}", field=flag)


def _check_output(out: str | Path, flag: str, inputs: Sequence[str | Path] = (), folder: bool = False, force: bool | None = None) -> None:
    """Refuse an output before any work: one that is an input or lies inside one, a device, FIFO
    or socket, a file where a folder goes (or the reverse), a place that cannot be written, and,
    given ``force`` (the command's --force), a file that exists unless it is True: the one rule
    of every command (a folder output's is :func:`terrapref.fileio.output_folder`)."""
    out = Path(out)
    target = out.resolve()
    for given in map(Path, inputs):
        if not given.exists():
            continue
        if target == given.resolve():
            raise UserError(str(out), f"is also an input; {flag} must name a new {'folder' if folder else 'file'}", field=flag)
        if given.is_dir() and target.is_relative_to(given.resolve()):
            raise UserError(str(out), f"lies inside the input {given}; {flag} must name a place outside it", field=flag)
    special = _special_file(out)
    if special:
        raise UserError(str(out), f"is a {special}; {flag} must name a {'folder' if folder else 'regular file'}", field=flag)
    if out.exists() and out.is_dir() != folder:
        raise UserError(str(out), "exists and is a " + ("file; expected a folder" if folder else "folder; expected a file name"), field=flag)
    if force is False and not folder and out.exists():
        raise UserError(str(out), f"exists; choose another {flag}, or pass --force to replace it (only once the new one is complete)", field=flag)
    parent = out if folder and out.exists() else out.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    try:  # a file made and removed at once: permissions alone miss read-only and virtual file systems
        with tempfile.TemporaryFile(dir=parent):
            pass
    except OSError as exc:
        raise UserError(str(out), f"cannot be written (no file can be made in {parent}: {exc.strerror or exc})", field=flag) from None


def _add_force_arg(p: argparse.ArgumentParser) -> None:
    """--force, the same for every command that writes: an output that exists is refused without it."""
    p.add_argument("--force", action="store_true",
                   help="replace an output that exists (only once the new one is complete; a folder is replaced whole)")


def _check_distinct(inputs: Sequence[str | Path], what: str) -> None:
    """Refuse an input given twice (by the same name, or two names of one file): its frames would
    count twice, or land in training and validation both."""
    seen: dict[object, str] = {}
    for given in map(str, inputs):
        key = Path(given).resolve() if Path(given).exists() else given
        if key in seen:
            same = "" if seen[key] == given else f" (the same as {seen[key]})"
            raise UserError(given, f"is given twice{same}; give each {what} once")
        seen[key] = given


def _class_table(args: argparse.Namespace):
    """The class table ``--classes FILE`` gives (read once per command), or None (the packaged default)."""
    if getattr(args, "classes", None) is None:
        return None
    if not hasattr(args, "class_table"):
        from terrapref.terrain import load_classes

        args.class_table = load_classes(args.classes)
    return args.class_table


def _teachable_table(args: argparse.Namespace):
    """``--classes``' table for a command that teaches it (None: the default), refused when it has
    no feature class to choose between."""
    table = _class_table(args)
    if table is not None and not table.terrain_names:
        raise UserError(str(args.classes), "the class table has no feature class (neither background nor lethal) to teach", field="classes")
    return table


def _check_table(args: argparse.Namespace, found, source: str | Path) -> None:
    """Refuse a file made for another class table than ``--classes`` gives (the default table
    when the flag is not given), naming both."""
    from terrapref.terrain import default_classes

    table = _class_table(args) or default_classes()
    if not found.same_classes(table):
        given = f"{args.classes}'s" if getattr(args, "classes", None) is not None else "the default table's (give --classes FILE for another)"
        raise UserError(str(source), f"was made for the class table of {', '.join(found.names)}, not {given} ({', '.join(table.names)})",
                        field="classes")


def _special_file(path: Path) -> str | None:
    """What ``path`` is when it exists and is neither a regular file nor a folder (links followed):
    writing over it would replace a device node or block on a pipe."""
    try:
        mode = path.stat().st_mode
    except OSError:
        return None
    kinds = ((stat.S_ISCHR, "character device"), (stat.S_ISBLK, "block device"), (stat.S_ISFIFO, "FIFO"), (stat.S_ISSOCK, "socket"))
    return next((name for test, name in kinds if test(mode)), None)


def _training_data(args: argparse.Namespace, recipe: Recipe) -> Dataset:
    """The samples to train on: recordings featurised as the recipe needs, and datasets; refused when
    there is nothing to learn."""
    import numpy as np

    from terrapref.dataset import training_data
    from terrapref.progress import Progress

    recordings = [p for p in args.data if p.is_dir()]
    _warn_lethal_contact(recordings)
    bar = Progress("featurize", len(recordings), enabled=bool(recordings))
    data = training_data(args.data, recipe.features(), recipe.rules, progress=_by_recording(bar))
    bar.close()
    if len(data) == 0:
        raise UserError(str(args.data[0]), "holds no samples to train on", field="frames")
    if len(np.unique(data.labels)) < 2:
        raise UserError(str(args.data[0]), f"every sample has the same label ({int(data.labels[0])}): the drive never steered, there is no choice to learn", field="labels")
    return data


def _warn_lethal_contact(recordings: list[Path]) -> None:
    """A warning for each recording whose drive had lethal terrain under the footprint."""
    from terrapref.demos.recording import read_recording

    for path in recordings:
        contact = read_recording(path).lethal_contact()
        if contact is not None:
            print(f"warning: {path}: the drive had lethal terrain under the vehicle ({contact}); the model learns from it as driven",
                  file=sys.stderr)


def _epoch_printer(config: TrainConfig, verbose: bool) -> Callable[[EpochMetrics], None]:
    """Prints a table of epochs (every tenth, the last, or all when ``verbose``), one per ensemble
    member, each row with the time so far and the time the remaining epochs will take at the pace so far."""
    import time

    from terrapref.progress import time_left

    header = f"{'epoch':>5s} {'train loss':>10s} {'val loss':>9s} {'train acc':>9s} {'val acc':>8s} {'val top3':>8s}  time"
    members, epochs = config.classifier.members, config.optimiser.epochs
    member = 0
    start = time.perf_counter()

    def show(m) -> None:
        nonlocal member
        if m.epoch == 1:
            member += 1
            print(f"member {member}/{members}\n{header}" if members > 1 else header)
        if verbose or m.epoch == epochs or m.epoch % max(1, epochs // 10) == 0:
            done = ((member - 1) * epochs + m.epoch) / (members * epochs)
            print(f"{m.epoch:5d} {m.train_loss:10.4f} {m.val_loss:9.4f} {m.train_acc:9.3f} {m.val_acc:8.3f} {m.val_top3:8.3f}  "
                  f"{time_left(time.perf_counter() - start, done)}", flush=True)

    return show


def _report_training(args: argparse.Namespace, config: TrainConfig, data: Dataset, result: TrainResult) -> None:
    """The loss curve beside the model, the chosen epochs and what the demonstrations show."""
    from dataclasses import asdict

    from terrapref.plots import save_loss_curve
    from terrapref.terrain import ClassTable

    members = config.classifier.members
    curve = Path(args.out).with_suffix(".loss.png")
    save_loss_curve(curve, [([asdict(h) for h in r.history], r.best_epoch) for r in result.members or [result]],
                    title=f"{Path(args.out).name}: {len(data)} samples{f', {members} members' if members > 1 else ''}")
    chosen = []
    for j, r in enumerate(result.members or [result]):
        best = r.history[r.best_epoch - 1]
        label = f"member {j + 1} " if members > 1 else ""
        chosen.append(f"{label}epoch {r.best_epoch}: val loss {best.val_loss:.4f}, val acc {best.val_acc:.3f}")
    if result.steadying is not None:
        print(result.steadying.line())
    table = ClassTable.from_dict(data.meta["classes"], str(args.data[0]))
    lethal = frozenset({table.lethal_column} if table.lethal else ())  # the terrain column the lethal classes share
    for rule in result.rules:
        print(rule.describe(data.feature_config.feature_classes, lethal))
    if result.identifiability is not None:
        print("what the demonstrations show (stored in the model):")
        for line in result.identifiability.lines(data.meta.get("profile")):
            print(f"  {line}")
    m = len(data.feature_config.preference.control.w_rps)
    print(f"val acc: the share of held-out frames ({config.optimiser.val_fraction:.0%}) whose driven trajectory C ranks first of {m} "
          f"(chance {1 / m:.3f}); neighbours differ by one step of steering, so val top3 and, for the planner, the agreement "
          "`terrapref evaluate` measures say more (one synthetic drive of teach_course: val acc about 0.45, val top3 about 0.84)")
    print(f"wrote {args.out} ({'; '.join(chosen)}), {curve}, checkpoints in {Path(args.out).with_name(Path(args.out).stem + '.checkpoints')}")


def _cmd_train(args: argparse.Namespace) -> int:
    from terrapref.learning.pipeline import RunOptions, interrupted_path, train_and_save
    from terrapref.recipes import DEFAULT_RECIPE, recipe_named

    recipe = recipe_named(args.recipe or DEFAULT_RECIPE)
    config = _train_config(args, recipe)
    recipe = replace(recipe, rules=_stages(args, recipe))
    _check_distinct(args.data, "recording or dataset")
    _check_output(args.out, "--out", args.data, force=args.force)
    if args.classes is not None:  # recordings before they are featurised
        from terrapref.demos.recording import read_recording

        for path in (p for p in args.data if p.is_dir()):
            _check_table(args, read_recording(path).classes, path)
    data = _training_data(args, recipe)
    if args.classes is not None:
        from terrapref.terrain import ClassTable

        _check_table(args, ClassTable.from_dict(data.meta["classes"], str(args.data[0])), args.data[0])
    for rule in recipe.rules:
        if rule.data() is not None and data.rule_data(rule.type) is None:
            print(f"warning: {args.data[0]} carries no data for the {rule.type} rule; {rule.without_data} "
                  f"(train from the recordings, or featurize them with --recipe {recipe.name})", file=sys.stderr)
    opt, members = config.optimiser, config.classifier.members
    print(f"recipe {recipe.name}: training on {len(data)} samples ({len(args.data)} input(s)), {opt.epochs} epochs, "
          f"batch {opt.batch_size}, lr {opt.lr}{f', {members} members' if members > 1 else ''}")
    try:
        result = train_and_save(data, args.out, config, rules=recipe.rules, recipe=recipe.name,
                                options=RunOptions(progress=_epoch_printer(config, args.verbose)))
    except KeyboardInterrupt:
        if interrupted_path(args.out).exists():
            print(f"note: the best epochs so far are in {interrupted_path(args.out)} (marked interrupted: no decision rules); "
                  f"{args.out} is untouched", file=sys.stderr)
        raise
    _report_training(args, config, data, result)
    return 0


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from terrapref.evaluation.evaluate import Evaluation, evaluate_model
    from terrapref.evaluation.runner import Summary
    from terrapref.planner.registry import load_policy
    from terrapref.progress import Progress
    from terrapref.terrain import PreferenceProfile

    if args.seeds < 1:
        raise UserError("--seeds", "must be >= 1")
    _check_distinct(args.scenarios, "scenario")
    _check_output(args.out, "--out", [args.model, *args.scenarios], folder=True)
    engine = _engine(args)
    if args.mcap:
        from terrapref.extras import check

        check("robot", "--mcap", "rosbags")  # before the runs, not after them
    try:
        frames = sorted({int(f) for f in args.frames.split(",") if f.strip()}) if args.frames else []
    except ValueError:
        raise UserError("--frames", f"expected comma-separated frame numbers, got {args.frames!r}") from None
    _check_frames(frames, args.scenarios, _class_table(args))  # before the model is read
    model = load_policy(args.model)  # C, or a learned baseline's file (linear, CNN)
    if args.classes is not None:  # the model carries its table (the scenarios are read with it); --classes must be it
        _check_table(args, model.classes, args.model)
    profile = PreferenceProfile.parse(args.profile, model.classes) if args.profile is not None else None
    perception = _perception(args.perception, classes=model.classes)
    from terrapref.demos.expert import STYLES
    from terrapref.evaluation.stats import rate_text

    STYLES.get(args.style, "--style")
    with output_folder(args.out, args.force):
        bar = Progress("evaluate", len(args.scenarios) * args.seeds * (1 if args.no_driver else 2))
        view = _live_view(args)
        try:
            evaluation = Evaluation(args.model, tuple(args.scenarios), args.seeds, profile=profile, with_driver=not args.no_driver, style=args.style,
                                    frames=tuple(frames), mcap=args.mcap, perception=perception)
            metrics = evaluate_model(evaluation, args.out, engine, progress=lambda k, n: bar.update(k, f"{k}/{n} runs"), watch=_watching(view))
        finally:
            if view is not None:
                view.stop()
        bar.close()
        if perception is not None and perception.active:
            print(f"perception: {perception.name} ({perception.summary()}); the driver sees the truth")
        zones = [z for sc in metrics["scenarios"].values() for run in sc.get("planner", {}).values() for z in run["zones"]]
        s = metrics["summary"]
        print(f"planner: zone success {rate_text(sum(z['success'] for z in zones), len(zones))}, {s['collision_count']} collisions")
        for line in Summary.from_dict(s).driving_lines():
            print(f"planner: {line}")
        compared = [z for z in zones if "agrees" in z]
        if compared:
            print(f"planner: agreement with the driver ({args.style}) {rate_text(sum(z['agrees'] for z in compared), len(compared))}")
        if "driver_summary" in metrics:
            d = metrics["driver_summary"]
            success = f"{d['zone_success_rate']:.1%}" if d["zones"] else "-"
            print(f"driver:  zone success {success} over {d['zones']} zones, {d['collision_count']} collisions")
        for name, numbers in metrics.get("frames_beyond_the_run", {}).items():
            print(f"note: --frames {','.join(map(str, numbers))}: {name}'s run (seed 0) ended before them; no picture", file=sys.stderr)
        guesses = [z for z in zones if z.get("rests_on_unidentified")]
        if metrics.get("unidentified_pairs"):
            print(f"note: the model's demonstrations did not identify {', '.join(metrics['unidentified_pairs'])}; "
                  f"{len(guesses)} of {len(zones)} zone runs rest on them (marked in metrics.json)")
        print(f"wrote {Path(args.out) / 'metrics.json'} and figures in {args.out}" + (f"; runs as MCAP in {Path(args.out) / 'runs'}" if args.mcap else ""))
        return 0


def _check_frames(frames: Sequence[int], scenarios: Sequence[str], classes) -> None:
    """Refuse a frame number no run of these scenarios can reach: the shortest's time limit caps its frames."""
    from terrapref.errors import ScenarioError
    from terrapref.scenario import resolve_scenario
    from terrapref.scenario.path import ReferencePath
    from terrapref.sim import SimConfig

    if not frames:
        return
    if frames[0] < 0:
        raise UserError("--frames", f"frame numbers start at 0, got {frames[0]}")
    config = SimConfig()
    for name in scenarios:
        try:  # only the path counts here, which gen:N draws alike for every table
            scenario = resolve_scenario(name, classes)
        except ScenarioError:
            if classes is not None:
                raise
            continue  # a file of the model's table that does not carry it: read with the model's, and its end noted after the run
        last = int(config.time_limit(ReferencePath(scenario.waypoints).length_m) * config.camera_rate_hz)
        if frames[-1] > last:
            raise UserError("--frames", f"frame {frames[-1]} lies beyond any run of {scenario.name} (its time limit ends at frame {last})")


def _cmd_import(args: argparse.Namespace) -> int:
    from terrapref.interop.bag_import import ImportOptions, import_bag
    from terrapref.interop.robot import load_robot
    from terrapref.terrain import PreferenceProfile, default_classes

    _check_output(args.out, "--out", [args.bag, args.robot], folder=True)
    table = _class_table(args)
    robot = load_robot(args.robot, table)
    profile = PreferenceProfile.parse(args.profile, table or default_classes()) if args.profile is not None else None
    report = import_bag(args.bag, robot, args.out, ImportOptions(rate_hz=args.rate, force=args.force, classes=table, profile=profile))
    for line in report.lines():
        print(line)
    print(f"wrote {args.out} (terrapref inspect / featurize / train accept it)")
    return 0


def _cmd_replay(args: argparse.Namespace) -> int:
    from terrapref.interop.robot import load_robot
    from terrapref.learning.model_file import load_model

    model = load_model(args.model)
    robot = load_robot(args.robot, model.classes)
    out = Path(args.out)
    _check_output(out, "--out", [args.bag, args.model, args.robot], folder=True)
    with output_folder(out, args.force):  # refused (another camera) or stopped: nothing of a new OUT is left
        return _replay_into(args, model, robot, out)


def _replay_into(args: argparse.Namespace, model, robot, out: Path) -> int:
    from terrapref.demos.recording import read_recording
    from terrapref.interop.bag_import import ImportOptions, import_bag
    from terrapref.interop.replay import replay, write_replay
    from terrapref.learning.model_file import check_compatible
    from terrapref.progress import Progress

    rec_dir = out / "recording"
    options = ImportOptions(rate_hz=args.rate, force=True, classes=model.classes, check_camera=lambda camera: check_compatible(model, camera))
    report = import_bag(args.bag, robot, rec_dir, options)
    print(f"imported {report.frames} frames ({report.duration_s:.0f} s) into {rec_dir}")
    rec = read_recording(rec_dir)
    bar = Progress("replay", len(rec))
    result = replay(model, rec, progress=lambda k, n: bar.update(k, f"{k}/{n} frames"))
    bar.close()
    write_replay(result, out, f"{Path(args.model).name} on {Path(args.bag).name}")
    for name, key in (("planner, all frames", "overall"), ("planner, terrain", "terrain_in_view"), ("C alone, all", "classifier_overall"),
                      ("C alone, terrain", "classifier_terrain_in_view")):
        r = result[key]
        if r["frames"]:
            top3 = f", top-3 {r['top3']:.1%}" if r["top3"] is not None else ""
            print(f"{name:20s} top-1 {r['top1']:.1%}{top3}, mean |w| error {r['mean_abs_w_error_rps']:.3f} rad/s over {r['frames']} frames")
        else:
            print(f"{name:20s} no frames")
    print("top-3: how often the operator's trajectory is among the three C ranks most probable (F_t); the planner's stages "
          "choose one trajectory and rank none, so only C has a top-3")
    print(f"wrote {out / 'replay.json'} and {out / 'replay.png'}")
    return 0


def _cmd_ros1(args: argparse.Namespace) -> int:
    from terrapref.interop.ros1 import NodeOptions, run_node

    options = NodeOptions(stamped=True if args.stamped else None, rate=args.rate, path_file=args.path_file, cmd_topic=args.cmd_topic)
    options.resolved(lambda name, default: default)  # what the command line gives is checked before ROS starts
    view = _live_view(args)
    try:
        run_node(args.model, args.robot, options, live=view)
    finally:
        if view is not None:
            view.stop()
    return 0


def _cmd_ros2(args: argparse.Namespace) -> int:
    from terrapref.extras import check

    check("ros2", "terrapref ros2")  # before the model is read
    from terrapref.interop.node_core import NodeOptions
    from terrapref.interop.ros2 import run_node

    options = NodeOptions(stamped=True if args.stamped else None, rate=args.rate, path_file=args.path_file, cmd_topic=args.cmd_topic)
    options.resolved(lambda name, default: default)  # what the command line gives is checked before DDS starts
    view = _live_view(args)
    try:
        run_node(args.model, args.robot, options, ros_args=args.ros_args or (), live=view)
    except KeyboardInterrupt as exc:  # Ctrl-C ends a node as ROS 2's do (its summary printed); SIGTERM as every command
        if isinstance(exc, Terminated):
            raise
    finally:
        if view is not None:
            view.stop()
    return 0


def _cmd_play(args: argparse.Namespace) -> int:
    from terrapref.extras import check

    check("ros2", "terrapref play")
    from terrapref.interop.dds import domain_id
    from terrapref.interop.play import BagPlayer
    from terrapref.interop.robot import load_robot_topics
    from terrapref.progress import Progress

    if not 0.01 <= args.rate <= 100:
        raise UserError("--rate", f"expected a factor in [0.01, 100], got {args.rate:g}")
    if not 1 <= args.clock <= 1000:
        raise UserError("--clock", f"expected a rate in [1, 1000] Hz, got {args.clock:g}")
    if not 0 <= args.delay <= 60:
        raise UserError("--delay", f"expected [0, 60] s, got {args.delay:g}")
    domain = domain_id()
    topics = set(args.topics) if args.topics else None
    if args.robot:  # what the node reads, and the transforms that place it; the log's commands and markers stay out
        roles = load_robot_topics(args.robot)
        topics = (topics or set()) | {t for role, t in roles.items() if role != "command"}
    player = BagPlayer(args.bag, domain, topics, optional={"/tf", "/tf_static"} if args.robot else ())
    first, last = player.span_ns
    span_s = (last - first) * 1e-9
    print(f"playing {args.bag} in ROS_DOMAIN_ID {domain}: {', '.join(sorted({t for t, _ in player.writers}))} and /clock, "
          f"{span_s:.1f} s of log at {args.rate:g}x", flush=True)
    bar = Progress("play", span_s, "s")
    count = 0
    try:
        count = player.play(rate=args.rate, clock_hz=args.clock, delay_s=args.delay, progress=lambda ns: bar.update(ns * 1e-9))
    finally:
        bar.close(f"{count} messages")
        player.close()
    print(f"played {count} messages on {len(player.writers)} topics and /clock: {span_s:.1f} s of {args.bag}")
    return 0


def _add_live_args(p: argparse.ArgumentParser, note: str, paced: bool = False) -> None:
    """--live and its address; with ``paced`` (simulated runs), --live-pace and --live-wait too."""
    p.add_argument("--live", action="store_true",
                   help=f"serve the planner's channels live (those of the MCAP export) on Foxglove's WebSocket protocol "
                        f"(subprotocol foxglove.sdk.v1, or foxglove.websocket.v1 for older viewers); {note}")
    p.add_argument("--live-host", default="127.0.0.1", help="address the live view listens on (default 127.0.0.1; 0.0.0.0: every interface)")
    p.add_argument("--live-port", type=int, default=8765, help="port of the live view (default 8765, Foxglove's; 0: a free one)")
    if paced:
        p.add_argument("--live-pace", type=finite_float, default=None, metavar="FACTOR",
                       help="send each run's frames at FACTOR times real time (1: as driven; 2: twice as fast); default: as fast as "
                            "they are computed")
        p.add_argument("--live-wait", action="store_true", help="wait for a viewer to connect before the first run starts")


def _live_view(args: argparse.Namespace):
    """The live view that --live asks for (its address printed), or None."""
    pace, wait = getattr(args, "live_pace", None), getattr(args, "live_wait", False)
    if not args.live:
        if pace is not None or wait:
            raise UserError("--live-pace" if pace is not None else "--live-wait", "goes with --live")
        return None
    if not 0 <= args.live_port <= 65535:
        raise UserError("--live-port", f"expected a port in [0, 65535], got {args.live_port}")
    if pace is not None and not pace > 0:
        raise UserError("--live-pace", f"expected a factor of real time > 0 (1: as driven), got {pace:g}")
    from terrapref.interop.live import LiveView

    view = LiveView(args.live_host, args.live_port, pace=pace or 0.0, wait=wait)
    paced = f"; frames at {pace:g}x real time" if pace else ""
    waiting = "; waiting for a viewer before the first run" if wait else ""
    print(f"live view: {view.url} (Foxglove: Open connection, Foxglove WebSocket{paced}){waiting}", flush=True)
    return view


def _watching(view):
    from terrapref.interop.live import watching

    return watching(view)


def _cmd_route(args: argparse.Namespace) -> int:
    import yaml

    from terrapref.fileio import write_text_atomic
    from terrapref.learning.model_file import load_model
    from terrapref.planner.route import RouteConfig, RouteError, route_over, routed_scenario
    from terrapref.plots import save_map
    from terrapref.scenario import resolve_scenario
    from terrapref.world import rasterise

    out, figure = Path(args.out), Path(args.out).with_suffix(".png")
    for path in (out, figure):
        _check_output(path, "--out", [args.scenario, args.model], force=args.force)
    if out.suffix.lower() not in (".yaml", ".yml"):
        raise UserError(str(out), "the route is written as a scenario file: give it the suffix .yaml", field="--out")
    if not (math.isfinite(args.resolution) and 0.1 <= args.resolution <= 2.0):
        raise UserError("--resolution", f"expected a cell size in [0.1, 2] m, got {args.resolution}")
    model = load_model(args.model)
    if args.classes is not None:  # the model carries its table; --classes, when given, must be it
        _check_table(args, model.classes, args.model)
    scenario = resolve_scenario(args.scenario, model.classes)
    world = rasterise(scenario)
    try:
        route = route_over(scenario, model, RouteConfig(resolution_m=args.resolution), world)
    except RouteError as exc:
        raise UserError(args.scenario, str(exc), field="path") from None
    except ValueError as exc:
        raise UserError(args.model, str(exc), field="--model") from None
    text = yaml.safe_dump(routed_scenario(scenario, route, Path(args.model).name), sort_keys=False, default_flow_style=None, width=120)
    write_text_atomic(out, "# terrapref route: a scenario whose path is the route; every command that takes a scenario takes it,\n"
                           "# and terrapref ros1 --path-file reads its waypoints.\n" + text)
    save_map(figure, scenario, world, tracks=[("route", route.waypoints, "tab:blue")],
             title=f"{scenario.name}: route priced by {Path(args.model).name}")
    along = "meets lethal terrain" if not math.isfinite(route.along_path_cost) else f"{route.along_path_cost:.1f}"
    print(f"route: {route.length_m:.1f} m (path {scenario.path_length_m():.1f} m), up to {route.max_offset_m:.1f} m from the path; "
          f"price {route.cost:.1f} (the path itself: {along}); searched in {route.cell_m:g} m cells")
    flag = f" --classes {args.classes}" if args.classes else ""
    print(f"wrote {out} (the scenario with the route as its path: terrapref evaluate {args.model} {out}{flag}) and {figure}")
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    from terrapref.report.info import info_lines

    for i, path in enumerate(args.files):
        if i:
            print()
        for line in info_lines(path):
            print(line)
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    out = Path(args.out)
    inputs = [args.input] + ([args.model] if args.model else [])
    _check_output(out, "--out", inputs, force=args.force)
    if args.format in ("mcap", "rosbag1"):
        _check_output(Path(f"{out}.robot.yaml"), "--out", inputs, force=args.force)
        _check_output(Path(f"{out}.labels.yaml"), "--out", inputs, force=args.force)
        from dataclasses import replace

        from terrapref.demos.recording import read_recording
        from terrapref.extras import check
        from terrapref.interop.mcap_export import recording_frames, write_bag
        from terrapref.progress import Progress

        check("robot", f"terrapref export --format {args.format}", "rosbags")  # before the frames are read

        rec = read_recording(args.input)
        if args.classes is not None:
            _check_table(args, rec.classes, args.input)
        if len(rec) == 0:
            raise UserError(args.input, "holds no frames", field="frames.jsonl")
        frames = recording_frames(rec)
        if args.model:
            frames = replace(frames, costmap=_model_costmaps(args.model, frames))
        bar = Progress("export", len(rec))
        write_bag(out, frames, ros1=args.format == "rosbag1", progress=lambda done, total: bar.update(done, f"{done}/{total} frames"))
        bar.close(f"{len(rec)} frames")
        what = "ROS 1 bag; rosbag play it" if args.format == "rosbag1" else "ROS 2 MCAP; open it in Foxglove"
        from terrapref.terrain import default_classes

        if not frames.classes.same_classes(default_classes()):
            print(f"wrote {out} ({what}), {out.name}.robot.yaml and its label map {out.name}.labels.yaml "
                  f"(terrapref import {out} --robot {out}.robot.yaml --classes FILE, the recording's class table)")
        else:
            print(f"wrote {out} ({what}) and {out.name}.robot.yaml (terrapref import {out} --robot {out}.robot.yaml)")
        return 0
    if args.model:
        raise UserError(args.model, "--model goes with --format mcap or rosbag1 (a recording's costmap); for onnx the model is the input", field="--model")
    from terrapref.interop.onnx_export import export_onnx
    from terrapref.learning.model_file import load_model

    if Path(args.input).is_dir():
        raise UserError(args.input, "is a recording folder; --format onnx exports a model file (.safetensors), a recording exports "
                                    "as --format mcap or rosbag1", field="--format")
    model = load_model(args.input)
    if args.classes is not None:
        _check_table(args, model.classes, args.input)
    export_onnx(model, out)
    print(f"wrote {out} (ONNX: input utilities float32 [N, {model.classifier.m}, {model.classifier.n_features}], output logits float32 [N, {model.classifier.m}])")
    return 0


def _model_costmaps(model_path: str, frames):
    from terrapref.interop.mcap_export import model_costmaps
    from terrapref.learning.model_file import load_model

    try:
        return model_costmaps(load_model(model_path), frames)
    except ValueError as exc:
        raise UserError(model_path, str(exc), field="--model") from None


def _cmd_perception(args: argparse.Namespace) -> int:
    import yaml

    from terrapref.perception import PRESETS, load_perception

    if not args.models:
        for name in PRESETS:
            model = load_perception(name)
            print(f"{name}: {model.summary()}")
        print("(terrapref perception NAME|FILE prints one in full; --perception takes a preset, a file, or NAME:PART "
              "for one part alone: labels, pose, camera or frames)")
        return 0
    for i, spec in enumerate(args.models):
        model = load_perception(spec, _class_table(args))
        if i:
            print("---")
        print(f"# {model.name} as a terrapref-perception/1 file: save it, edit any field, give it to --perception FILE")
        print(yaml.safe_dump(model.file_dict(), sort_keys=False, default_flow_style=None).rstrip())
    return 0


def _cmd_recipes(args: argparse.Namespace) -> int:
    from terrapref.recipes import DEFAULT_RECIPE, RECIPES

    for name, r in RECIPES.items():
        tag = " (default)" if name == DEFAULT_RECIPE else ""
        drives = f"{r.demonstrations} drive{'s' if r.demonstrations > 1 else ''} of {r.course}"
        stages = ", then ".join(s.type for s in r.rules) or "none"
        print(f"{name}{tag}: {drives}, {r.train.optimiser.epochs} epochs{f', {r.train.classifier.members} members' if r.train.classifier.members > 1 else ''}; "
              f"rules: {stages} (the last drives; none: C's argmax)")
        print(f"    {r.summary}")
    return 0


def _cmd_reproduce(args: argparse.Namespace) -> int:
    import time

    from terrapref.recipes import recipe_named
    from terrapref.report.reproduce import Reproduction, reproduce
    from terrapref.terrain import PreferenceProfile

    if args.seeds < 1:
        raise UserError("--seeds", "must be >= 1")
    if args.eval_seeds < 1:
        raise UserError("--eval-seeds", "must be >= 1")
    profile = PreferenceProfile.parse(args.profile) if args.profile is not None else None
    names = [n.strip() for n in args.recipes.split(",") if n.strip()]
    if not names or len(set(names)) != len(names):
        raise UserError("--recipes", f"expected distinct recipe names separated by commas, got {args.recipes!r}")
    recipes = tuple(recipe_named(n, "--recipes") for n in names)
    perceptions = _perception_list(args.perception)
    _check_output(args.out, "--out", folder=True)
    with output_folder(args.out, args.force):
        engine = _engine(args)
        t0 = time.perf_counter()
        setup = Reproduction(recipes, args.seeds, args.eval_seeds, profile or PreferenceProfile.default(), args.write_recordings, perceptions)
        report = reproduce(args.out, setup, engine, log=lambda m: print(m, flush=True))
        print(f"wrote {report} ({time.perf_counter() - t0:.0f} s)")
        return 0


def _cmd_study(args: argparse.Namespace) -> int:
    import time
    from dataclasses import replace

    from terrapref.extras import check
    from terrapref.report.study import run_study
    from terrapref.report.study_plan import FULL, QUICK, for_table, with_perception
    from terrapref.terrain import default_classes

    check("cnn", "terrapref study (its end-to-end CNN baseline)")  # before the stages that come before the CNN's
    plan = QUICK if args.quick else FULL
    if args.seeds is not None:
        if args.seeds < 1:
            raise UserError("--seeds", "must be >= 1")
        plan = replace(plan, seeds=args.seeds)
    if args.recipe is not None:
        from terrapref.recipes import recipe_named

        plan = replace(plan, recipe=recipe_named(args.recipe).name)
    table = _teachable_table(args)
    if table is not None and table.same_classes(default_classes()) and table.profile == default_classes().profile:
        table = None  # the packaged table, given by its file: the default plan
    perceptions = None
    if args.perception is not None:
        perceptions = _perception_list(args.perception, table)
        if not perceptions:
            raise UserError("--perception", f"names no perception model: {args.perception!r}")
    if table is not None:
        plan = for_table(plan, table, perceptions=perceptions or (), follow_up=args.follow_up)
    else:
        plan = replace(plan, follow_up=args.follow_up)
        if perceptions is not None:
            plan = with_perception(plan, perceptions)
    _check_output(args.out, "--out", folder=True)
    with output_folder(args.out, args.force):
        engine = _engine(args)
        t0 = time.perf_counter()
        path = run_study(args.out, plan, engine, log=lambda m: print(m, flush=True))
        print(f"wrote {path} ({time.perf_counter() - t0:.0f} s)")
        return 0


def _cmd_select(args: argparse.Namespace) -> int:
    import time

    from terrapref.demos.expert import STYLES
    from terrapref.recipes import recipe_named
    from terrapref.report.select import Selection, parse_orders, run_selection
    from terrapref.terrain import PreferenceProfile

    names = [n.strip() for n in args.recipes.split(",") if n.strip()]
    if not names or len(set(names)) != len(names):
        raise UserError("--recipes", f"expected distinct recipe names separated by commas, got {args.recipes!r}")
    for n in names:
        recipe_named(n, "--recipes")
    table = _teachable_table(args)
    try:
        orders = parse_orders(args.orders, table)
    except ValueError as exc:
        raise UserError("--orders", str(exc)) from None
    for o in orders:
        PreferenceProfile.parse(list(o), table, source="--orders")
    if len(set(orders)) != len(orders):
        raise UserError("--orders", f"names an order twice: {args.orders!r}")
    STYLES.get(args.style, "--style")
    for flag, value, low in (("--seeds", args.seeds, 1), ("--courses", args.courses, 1), ("--first", args.first, 0)):
        if value < low:
            raise UserError(flag, f"must be an integer >= {low}, got {value}")
    _check_output(args.out, "--out", folder=True)
    perceptions = _perception_list(args.perception or "clean", table)
    if args.taught_under == "same" and len(perceptions) != 1:
        raise UserError("--taught-under", "'same' needs exactly one --perception model")
    taught_under = perceptions[0] if args.taught_under == "same" else _perception(args.taught_under, "--taught-under", table)
    with output_folder(args.out, args.force):
        engine = _engine(args)
        course = _selection_course(args, table)
        t0 = time.perf_counter()
        selection = Selection(tuple(names), orders, args.seeds, args.first, args.courses, args.style, perceptions, taught_under, table, course,
                              args.follow_up)
        path = run_selection(args.out, selection, engine, log=lambda m: print(m, flush=True))
        print(f"done ({time.perf_counter() - t0:.0f} s): {path}")
        return 0


def _selection_course(args: argparse.Namespace, table) -> str | None:
    """The course every recipe demonstrates in ``select``: ``--course``, or with ``--classes`` the
    table's teaching course (written into OUT); None: each recipe's own."""
    if args.course is not None:
        from terrapref.scenario import resolve_scenario

        resolve_scenario(args.course, table)  # checked before any work
        return str(Path(args.course).resolve()) if Path(args.course).exists() else args.course
    if table is None:
        return None
    from terrapref.scenario.teaching import write_teaching_course

    return str(write_teaching_course(args.out, table))


def _perception(spec: str | None, flag: str = "--perception", classes=None):
    """The perception model of ``--perception PRESET|FILE`` (None when not given), checked before any work."""
    if spec is None:
        return None
    from terrapref.perception import load_perception

    try:
        return load_perception(spec, classes)
    except UserError as exc:
        if exc.source == "--perception" and flag != "--perception":
            raise UserError(flag, exc.problems) from None
        raise


def _perception_list(text: str, classes=None) -> tuple:
    """The perception models of a comma-separated ``--perception`` list (blank items skipped),
    each checked before any work; one named twice is refused."""
    models = tuple(_perception(n, classes=classes) for n in (x.strip() for x in text.split(",")) if n)
    if len({p.name for p in models}) != len(models):
        raise UserError("--perception", f"names a perception model twice: {text!r}")
    return models


SCENARIO_HELP = "a packaged scenario's name (terrapref scenarios lists them), gen:N for generated layout N, or a scenario file"
PERCEPTION_HELP = ("what the planner receives instead of the truth: a preset (clean, rellis, field; terrapref perception lists them) "
                   "or a terrapref-perception/1 file")


def _engine(args: argparse.Namespace) -> Engine:
    """The grid engine of ``--engine``, ``--workers`` and ``--address``, checked before any work."""
    if args.workers is not None and args.workers < 1:
        raise UserError("--workers", f"must be an integer >= 1, got {args.workers}")
    if args.address is not None and args.engine != "ray":
        raise UserError("--address", "is the address of a Ray cluster; add --engine ray")
    if args.engine == "ray":
        from terrapref.extras import check

        check("ray", "--engine ray")
        if args.address not in (None, "auto"):
            _check_ray_address(args.address)
    if args.engine == "ray":
        # Jobs pass files by path; a cluster's workers do not start in this folder.
        for name in ("out", "model"):
            value = getattr(args, name, None)
            if isinstance(value, (str, Path)) and str(value):
                setattr(args, name, type(value)(Path(value).resolve()))
    return Engine(args.engine, args.workers, args.address)


def _check_ray_address(address: str) -> None:
    """Refuse, in a few seconds, an address where no Ray head answers (Ray itself retries for minutes)."""
    import socket

    host, _, port = address.removeprefix("ray://").rpartition(":")
    if not host or not port.isdigit():
        raise UserError("--address", f"expected HOST:PORT of a Ray head (ray start --head), got {address!r}")
    try:
        with socket.create_connection((host, int(port)), timeout=5.0):
            pass
    except OSError as exc:
        raise UserError("--address", f"no Ray head answers at {address} ({exc.strerror or exc}); start one with ray start --head") from None


def _add_engine_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--workers", type=int, help="parallel jobs on this machine (default: one per core)")
    p.add_argument("--engine", choices=ENGINES.names(), default="local",
                   help="where the jobs run: local processes (default) or Ray (a local instance, or the cluster at --address)")
    p.add_argument("--address", metavar="HOST:PORT", help="a Ray cluster to run the jobs on (ray start --head on one machine); with --engine ray")


CLASSES_HELP = ("your own class table (a terrapref-classes/1 file, e.g. examples/classes/rellis3d.yaml): the classes scenarios, "
                "generated layouts (gen:N) and label maps are read with; default: the packaged grass, mud, rock, water, non_traversable")
CLASSES_CHECK_HELP = ("the class table the files must have been made for (a terrapref-classes/1 file); a file made for another is refused. "
                      "Files carry their own table, so this is a check, not a setting")


def _add_classes_arg(p: argparse.ArgumentParser, check: bool = False) -> None:
    p.add_argument("--classes", metavar="FILE", help=CLASSES_CHECK_HELP if check else CLASSES_HELP)


def _course_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("course", help="write the teaching course of a class table (or, with --after, a follow-up of what drives left open)")
    p.add_argument("--out", required=True, type=Path, help="scenario file to write (.yaml); a top-down figure goes beside it (.png)")
    p.add_argument("--after", type=Path, nargs="+", metavar="REC",
                   help="recordings of the teaching course (and of earlier follow-ups): write a short course of only the pairs "
                        "their drives together left unidentified (train on all the recordings after)")
    p.add_argument("--design", choices=("auto", "full", "compact"), default="auto",
                   help="full: every pair once on each side; compact: every pair once, sides balanced; auto (default): full while "
                        "the drive stays within 10 minutes at 1 m/s")
    p.add_argument("--name", help="the scenario's name (default: teaching_course, or the course driven + _more)")
    _add_classes_arg(p)
    _add_force_arg(p)
    p.set_defaults(func=_cmd_course)


def _validate_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("validate", help="check scenarios, class tables, perception models, robot files and label maps (each by its format)")
    p.add_argument("files", nargs="*", metavar="FILE",
                   help="files to check, each read as its format: field says (terrapref-scenario/1, -classes/1, -perception/1, -robot/1, "
                        "-labels/1), or packaged scenarios' names")
    p.add_argument("--template", metavar="KIND", choices=("scenario", "classes", "perception", "robot", "labels"),
                   help="print a commented file of this kind to start from (scenario, classes, perception, robot, labels): "
                        "terrapref validate --template robot > robot.yaml")
    _add_classes_arg(p)
    p.set_defaults(func=_cmd_validate)


def _render_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("render", help="render the segmentation camera image at a pose")
    p.add_argument("scenario", metavar="SCENARIO", help="packaged scenario name or file")
    p.add_argument("--pose", nargs=3, type=finite_float, metavar=("X", "Y", "YAW_DEG"), help="vehicle pose [m, m, deg]; default: the start")
    p.add_argument("--out", required=True, type=Path, help="single-channel PNG of class ids")
    p.add_argument("--preview", type=Path, help="also write a colour preview PNG")
    _add_classes_arg(p)
    _add_force_arg(p)
    p.set_defaults(func=_cmd_render)


def _show_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("show", help="draw the map top-down with the path, the start and the zones")
    p.add_argument("scenario", metavar="SCENARIO", help=SCENARIO_HELP)
    p.add_argument("--out", required=True, type=Path, help="figure file (.png, .pdf or .svg)")
    _add_classes_arg(p)
    _add_force_arg(p)
    p.set_defaults(func=_cmd_show)


def _record_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("record", help="record a demonstration with the synthetic driver")
    p.add_argument("scenario", metavar="SCENARIO", help=SCENARIO_HELP)
    p.add_argument("--profile", help="preference order, best first, e.g. rock,mud,water,non_traversable (default: the class table's)")
    p.add_argument("--style", default="default", help="the driver's style: default, wide (wider margins), late (reacts later), shaky (a shakier hand), "
                        "reluctant (leaves the path reluctantly)")
    p.add_argument("--seed", type=int, default=0, help="seeds the driver's hand and the pushes (default 0)")
    p.add_argument("--out", required=True, type=Path, help="recording directory to create")
    p.add_argument("--force", action="store_true", help="replace an existing recording at --out")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.add_argument("--disturb", type=finite_float, default=None, metavar="RATE",
                   help="push the executed yaw rate off the driver's command RATE times per second, so recoveries are shown "
                        "(default: the recommended protocol's 0.3; 0: none)")
    p.add_argument("--perception", metavar="PRESET|FILE",
                   help="the driver sees the truth; the recording holds what the robot's camera and localisation gave through this "
                        "perception model (a preset: clean, rellis, field; or a terrapref-perception/1 file)")
    _add_classes_arg(p)
    p.set_defaults(func=_cmd_record)


def _drive_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("drive", help="drive a scenario yourself (keyboard, mouse or gamepad), optionally recording, or ride along with a model (--model)")
    p.add_argument("scenario", metavar="SCENARIO", help=SCENARIO_HELP)
    p.add_argument("--record", type=Path, metavar="DIR", help="record the drive into DIR")
    p.add_argument("--force", action="store_true", help="replace an existing recording at DIR")
    p.add_argument("--speed", type=finite_float, default=1.0, help="forward speed [m/s] (default 1)")
    p.add_argument("--disturb", type=finite_float, default=None, metavar="RATE",
                   help="pushes per second on the executed yaw rate, each shown in the window as it happens "
                        "(default: the recommended protocol's 0.3; 0: none)")
    p.add_argument("--seed", type=int, default=0, help="seeds the pushes")
    p.add_argument("--profile", help="your preference order, best first, stored with the recording (default: the class table's)")
    p.add_argument("--model", type=Path, metavar="MODEL",
                   help="ride along: MODEL drives, any stick input takes over, and the frames you steer are recorded as "
                        "corrections that train accepts beside demonstrations")
    p.add_argument("--perception", metavar="PRESET|FILE",
                   help="you see the truth; the recording (and a riding-along model) gets what the robot's camera and localisation "
                        "gave through this perception model")
    _add_live_args(p, "every driven frame, riding along with the planner's F_t and costmap")
    _add_classes_arg(p)
    p.set_defaults(func=_cmd_drive)


def _inspect_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("inspect", help="summarise a recording and draw its driven path")
    p.add_argument("recording", metavar="DIR", type=Path, help="a recording folder (from record, drive or import)")
    p.add_argument("--out", type=Path, help="top-down PNG (default: DIR/driven_path.png)")
    p.add_argument("--no-preference", action="store_true",
                   help="skip what the drive shows of the driver's preference (it featurises every frame: seconds)")
    _add_classes_arg(p, check=True)
    _add_force_arg(p)
    p.set_defaults(func=_cmd_inspect)


def _featurize_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("featurize", help="turn recordings into a training set (U, label)")
    p.add_argument("recordings", nargs="+", metavar="DIR", type=Path, help="recording folders (from record, drive or import)")
    p.add_argument("--out", required=True, type=Path, help="dataset file (.safetensors)")
    p.add_argument("--distance-mode", choices=["lookahead", "window", "paper"], default="lookahead",
                   help="how each trajectory's distance to the path is measured: lookahead (default) to the path ahead of the vehicle, "
                        "window to the nearest path point within a window, paper as the paper writes it")
    p.add_argument("--n-steps", type=int, help="trajectory points n (default 30)")
    p.add_argument("--dt", type=finite_float, help="trajectory time step [s] (default 0.2)")
    p.add_argument("--camera", help="camera file to re-render the frames with: CameraConfig's fields, or a ROS camera_info YAML (with mount_height_m, pitch_deg)")
    p.add_argument("--recipe", metavar="NAME", help="featurise as this recipe trains (default: teach, with the look-ahead utilities)")
    _add_classes_arg(p, check=True)
    _add_force_arg(p)
    p.set_defaults(func=_cmd_featurize)


def _train_parser(sub: argparse._SubParsersAction, flags: bool = True) -> None:
    """``train``; its training flags come from TrainConfig's fields (``flags``: built only when
    the command line is a training, since they need the recipes and NumPy)."""
    p = sub.add_parser("train", help="train a planner from recordings or featurised datasets (recipe teach by default)")
    p.add_argument("data", nargs="+", metavar="DATA", type=Path,
                   help="recording directories (featurised as the recipe needs) or dataset files from `terrapref featurize`")
    p.add_argument("--out", required=True, type=Path, help="model file (.safetensors)")
    p.add_argument("--recipe", default=None, metavar="NAME", help="a named recipe (`terrapref recipes`; default: teach)")
    p.add_argument("--verbose", action="store_true", help="print every epoch (default: every tenth)")
    _add_classes_arg(p, check=True)
    _add_force_arg(p)
    p.set_defaults(func=_cmd_train)
    if flags:
        from terrapref.configargs import add_arguments
        from terrapref.learning.train import TrainConfig
        from terrapref.recipes import DEFAULT_RECIPE, recipe_named

        group = p.add_argument_group("training (defaults shown: recipe teach's; each flag overrides the chosen recipe's value)")
        add_arguments(group, TrainConfig, recipe_named(DEFAULT_RECIPE).train)
        stages = p.add_argument_group("decision stages (terrapref recipes lists each recipe's; the last one fitted drives)")
        stages.add_argument("--second-stage", action=argparse.BooleanOptionalAction, default=None,
                            help="also fit the second stage's linear utility (or, with --no-, leave the recipe's out)")
        stages.add_argument("--stage-weight", type=finite_float, default=None,
                            help="the second stage's weight against log F_t in the decision (recipe teach: 5.0)")


def _evaluate_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("evaluate", help="drive scenarios with a model, score every zone, write metrics.json and figures")
    p.add_argument("model", metavar="MODEL", help="a model file from train (or a learned baseline's)")
    p.add_argument("scenarios", nargs="+", metavar="SCENARIO", help=SCENARIO_HELP)
    p.add_argument("--seeds", type=int, default=3, help="runs per scenario (default 3): seed 0 starts at the scenario's start, "
                        "the others up to 0.3 m and 3 degrees off it")
    p.add_argument("--out", required=True, type=Path, help="folder for metrics.json and the figures")
    p.add_argument("--profile", help="resolve `best` zones under this profile instead of the model's")
    p.add_argument("--frames", help="comma-separated frame numbers of seed 0 to draw as decision pictures")
    p.add_argument("--no-driver", action="store_true", help="skip the synthetic driver's comparison runs")
    p.add_argument("--style", default="default", help="the synthetic driver's style for the comparison runs (agreement; default: default)")
    _add_engine_args(p)
    p.add_argument("--mcap", action="store_true", help="also write each planner run as ROS 2 MCAP in OUT/runs (Foxglove, RViz)")
    p.add_argument("--perception", metavar="PRESET|FILE", help=PERCEPTION_HELP + " (default: clean); the driver always sees the truth")
    _add_live_args(p, "the runs go one after another in this process", paced=True)
    _add_classes_arg(p, check=True)  # the scenarios and gen:N are read with the model's table
    _add_force_arg(p)
    p.set_defaults(func=_cmd_evaluate)


def _reproduce_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("reproduce", help="demonstrate, train and evaluate end to end; write REPORT.md with Tables 1 and 2")
    p.add_argument("--out", required=True, type=Path, help="folder for REPORT.md, its figures and the work")
    p.add_argument("--seeds", type=int, default=5, help="training seeds per recipe (default 5)")
    p.add_argument("--eval-seeds", type=int, default=1, help="evaluation runs per model and scenario (default 1)")
    p.add_argument("--recipes", default="paper,ours,teach",
                   help="recipes to compare, by name, separated by commas (default: paper,ours,teach; see `terrapref recipes`)")
    p.add_argument("--profile", help="preference order for the demonstrations, best first")
    p.add_argument("--write-recordings", action="store_true",
                   help="also write the synthetic driver's demonstrations as recordings in OUT/work (they are featurised as they are driven)")
    p.add_argument("--perception", default="clean,rellis,field", metavar="P1,P2,...",
                   help="perception models (presets or files, separated by commas) every recipe's models drive the test courses under, "
                        "for the report's table of what a robot sees (default: clean,rellis,field)")
    _add_engine_args(p)
    _add_force_arg(p)
    p.set_defaults(func=_cmd_reproduce)


def _study_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("study", help="baselines, data efficiency, profiles, robustness and ablations; write STUDY.md")
    p.add_argument("--out", required=True, type=Path, help="folder for STUDY.md, its figures and the work")
    p.add_argument("--quick", action="store_true", help="one seed and fewer levels (about a minute on 2 cores)")
    p.add_argument("--seeds", type=int, help="training seeds (default: 3, or 1 with --quick)")
    p.add_argument("--recipe", metavar="NAME", help="the recipe section 6 teaches every order and style with (default: teach)")
    _add_classes_arg(p)
    p.add_argument("--perception", metavar="LIST",
                   help="comma-separated perception presets or files the taught models also drive under; the last that perturbs anything is swept part by part "
                        "(default: clean,rellis,field, or clean,field with --quick; with --classes: clean, unless files for the table are given)")
    p.add_argument("--follow-up", action="store_true",
                   help="each teaching drive is followed by a drive of the course of what it left open, and the model learns from both")
    _add_engine_args(p)
    _add_force_arg(p)
    p.set_defaults(func=_cmd_study)


def _import_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("import", help="turn a ROS 1 bag, ROS 2 bag (sqlite3 or MCAP) of a drive into a recording")
    p.add_argument("bag", help="a .bag file, a ROS 2 bag folder, or a .mcap / .db3 file")
    p.add_argument("--robot", required=True, help="terrapref-robot/1 file: topics, camera mounting, label map")
    p.add_argument("--out", required=True, help="recording folder to create")
    p.add_argument("--rate", type=finite_float, default=10.0, help="frames per second to keep (default 10, the planner's rate)")
    p.add_argument("--force", action="store_true", help="replace an existing recording at --out (only once the import succeeds)")
    p.add_argument("--profile", help="the driver's preference order, best first, stored with the recording (default: the robot file's "
                                     "profile; with neither, the recording declares none and training refuses it)")
    _add_classes_arg(p)
    p.set_defaults(func=_cmd_import)


def _replay_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("replay", help="run a model open-loop over a held-out bag: how often it makes the operator's choice")
    p.add_argument("bag", help="a .bag file, a ROS 2 bag folder, or a .mcap / .db3 file")
    p.add_argument("--robot", required=True, help="terrapref-robot/1 file")
    p.add_argument("--model", required=True, help="model file (terrapref train)")
    p.add_argument("--out", required=True, help="folder for replay.json, replay.png and the imported recording")
    p.add_argument("--rate", type=finite_float, default=10.0, help="frames per second to replay (default 10)")
    _add_force_arg(p)
    p.set_defaults(func=_cmd_replay)


def _export_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("export", help="export a model as ONNX, or a recording as ROS 2 MCAP (Foxglove, RViz) or a ROS 1 bag")
    p.add_argument("input", help="model file (--format onnx) or recording folder (--format mcap or rosbag1)")
    p.add_argument("--format", choices=["onnx", "mcap", "rosbag1"], required=True,
                   help="onnx: the classifier C; mcap: the recording's frames as ROS 2 messages; rosbag1: the same as a ROS 1 bag (rosbag play)")
    p.add_argument("--out", required=True, help="output file")
    p.add_argument("--model", help="with --format mcap or rosbag1: also write the costmap this model (with an offset stage) prices the recording's ground with, "
                                   "as nav_msgs/OccupancyGrid and foxglove_msgs/Grid, once a second")
    _add_classes_arg(p, check=True)
    _add_force_arg(p)
    p.set_defaults(func=_cmd_export)


def _ros1_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("ros1", help="run the planner as a ROS 1 node (rospy; Debian's ros-core and python3-rospy)")
    p.add_argument("--model", required=True, help="a model file from train")
    p.add_argument("--robot", required=True, help="the robot file: topics, camera mounting, label map (terrapref-robot/1)")
    p.add_argument("--stamped", action="store_true",
                   help="publish geometry_msgs/TwistStamped (stamped with the frame decided on) instead of Twist (ROS parameter ~stamped)")
    p.add_argument("--rate", type=finite_float, help="commands per second between decisions (ROS parameter ~rate; default 20)")
    p.add_argument("--path-file", help="waypoints (YAML: a list, a mapping with waypoints, or a scenario such as terrapref route writes) of "
                                       "the reference path in the odometry frame, instead of the path topic (ROS parameter ~path_file)")
    p.add_argument("--cmd-topic", help="where to publish the command (ROS parameter ~cmd_topic; default: the robot file's command topic)")
    _add_live_args(p, "stamped with the frames' ROS times")
    p.set_defaults(func=_cmd_ros1)


def _ros2_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("ros2", help="run the planner as a ROS 2 node over DDS (no rclpy; the ros2 extra: cyclonedds)")
    p.add_argument("--model", required=True, help="a model file from train")
    p.add_argument("--robot", required=True, help="the robot file: topics, camera mounting, label map (terrapref-robot/1)")
    p.add_argument("--stamped", action="store_true",
                   help="publish geometry_msgs/TwistStamped (stamped with the frame decided on; Jazzy's Nav2 default) instead of Twist "
                        "(ROS parameter stamped)")
    p.add_argument("--rate", type=finite_float, help="commands per second between decisions (ROS parameter rate; default 20)")
    p.add_argument("--path-file", help="waypoints (YAML: a list, a mapping with waypoints, or a scenario such as terrapref route writes) of "
                                       "the reference path in the odometry frame, instead of the path topic (ROS parameter path_file)")
    p.add_argument("--cmd-topic", help="where to publish the command (ROS parameter cmd_topic; default: the robot file's command topic)")
    _add_live_args(p, "stamped with the frames' ROS times")
    p.add_argument("--ros-args", nargs=argparse.REMAINDER, metavar="ARG",
                   help="ROS 2's arguments, last: -p NAME:=VALUE (stamped, rate, path_file, cmd_topic, hold_s, use_sim_time) and "
                        "-r FROM:=TO (topics; __node, __ns); ROS_DOMAIN_ID picks the domain")
    p.set_defaults(func=_cmd_ros2)


def _play_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("play", help="publish a ROS 2 bag or MCAP on ROS 2 topics with /clock, as ros2 bag play --clock (the ros2 extra)")
    p.add_argument("bag", help="a ROS 2 bag folder or .mcap file (terrapref export --format mcap writes one)")
    p.add_argument("--robot", help="play only what this robot file's node reads (image, camera_info, odometry, path) and /tf, /tf_static, "
                                   "so that the log's own commands and markers stay off the node's topics")
    p.add_argument("--topics", nargs="+", metavar="TOPIC", help="play only these topics (with --robot: these as well)")
    p.add_argument("--rate", type=finite_float, default=1.0, help="speed factor over the log's own pace (default 1)")
    p.add_argument("--clock", type=finite_float, default=40.0, help="/clock messages per second (default 40, as ros2 bag play --clock)")
    p.add_argument("--delay", type=finite_float, default=1.0,
                   help="seconds between joining the domain and the first message, for subscribers to discover the topics (default 1)")
    p.set_defaults(func=_cmd_play)


def _route_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("route", help="plan a global route over a scenario's map, priced with a model's learned preference, as waypoints the planner follows")
    p.add_argument("scenario", help="the course (packaged name, file or gen:N): its terrain stands in for a prior map such as labelled aerial imagery")
    p.add_argument("--model", required=True, help="a model with an offset stage (recipe teach): its class prices and price of leaving the path")
    p.add_argument("--out", required=True, help="the scenario with the route as its path (.yaml); a figure is written beside it (.png)")
    p.add_argument("--resolution", type=finite_float, default=0.25,
                   help="search cell size [m], 0.1-2, taken as the nearest whole multiple of the map's cells (default 0.25)")
    _add_classes_arg(p, check=True)  # the scenario is read with the model's table
    _add_force_arg(p)
    p.set_defaults(func=_cmd_route)


def _info_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("info", help="what a recording, dataset, model or ONNX file holds (camera, profile, data, history, identifiability)")
    p.add_argument("files", nargs="+", metavar="FILE", help="recording folders, dataset or model files (.safetensors), ONNX files")
    p.set_defaults(func=_cmd_info)


def _select_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("select", help="compare recipes: train each for every order and seed, drive generated layouts, report agreement with the driver")
    p.add_argument("--out", required=True, type=Path, help="folder for SELECT.md, select.json, select.png and the work")
    p.add_argument("--recipes", default="teach", help="recipe names separated by commas (terrapref recipes; default: teach)")
    p.add_argument("--orders", default="all",
                   help="'all' (every order of the feature classes, the lethal ones last: six for the default table), 'random:N' (N of them "
                        "drawn at random, the same N every time) or orders separated by ';', e.g. 'rock,mud,water;water,mud,rock' (default: all)")
    p.add_argument("--style", default="default", help="the synthetic driver's style (default: default; terrapref record --help lists them)")
    p.add_argument("--seeds", type=int, default=5, help="training seeds per recipe and order (default: 5)")
    p.add_argument("--first", type=int, default=1000, help="first generated layout (1000-1999: for choosing; 2000 on: for confirming; default: 1000)")
    p.add_argument("--courses", type=int, default=32, help="generated layouts (default: 32)")
    p.add_argument("--perception", metavar="P1,P2,...",
                   help="perception models (presets, files or NAME:PART, separated by commas) the models drive the layouts under, each "
                        "in turn, for a table each (default: clean): " + PERCEPTION_HELP)
    p.add_argument("--taught-under", metavar="PRESET|FILE|same", default=None,
                   help="record the demonstrations through this perception model instead of the truth ('same': --perception's)")
    p.add_argument("--course", metavar="SCENARIO", help="the course every recipe demonstrates (default: each recipe's own; with --classes, "
                                                        "the table's teaching course, as terrapref course writes it)")
    p.add_argument("--follow-up", action="store_true",
                   help="after each demonstration, the driver also drives a follow-up course of the pairs it left unidentified "
                        "(terrapref course --after), and the model trains on both")
    _add_classes_arg(p)
    _add_engine_args(p)
    _add_force_arg(p)
    p.set_defaults(func=_cmd_select)


def _perception_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("perception", help="list the perception presets (what a robot's planner gets instead of the truth), or print one in full")
    p.add_argument("models", nargs="*", metavar="PRESET|FILE", help="print these in full (checked as --perception checks them)")
    _add_classes_arg(p)
    p.set_defaults(func=_cmd_perception)


def _recipes_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("recipes", help="list the named training recipes (--recipe NAME in train, --recipes in reproduce and select)")
    p.set_defaults(func=_cmd_recipes)


def _scenarios_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("scenarios", help="list the packaged scenarios")
    p.set_defaults(func=_cmd_list)


COMMANDS = (
    _course_parser,
    _validate_parser,
    _render_parser,
    _show_parser,
    _record_parser,
    _drive_parser,
    _inspect_parser,
    _featurize_parser,
    _train_parser,
    _evaluate_parser,
    _reproduce_parser,
    _study_parser,
    _import_parser,
    _replay_parser,
    _export_parser,
    _ros1_parser,
    _ros2_parser,
    _play_parser,
    _route_parser,
    _info_parser,
    _select_parser,
    _perception_parser,
    _recipes_parser,
    _scenarios_parser,
)
"""Each command's parser, in the order `terrapref --help` lists them."""


class _Parser(argparse.ArgumentParser):
    """argparse, with its refusals (a missing argument, a value of the wrong type, an unknown
    choice) as one line on stderr and exit code 2, like every other error of the command line."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"error: {self.prog}: {message} (see {self.prog} --help)\n")


def build_parser(train_flags: bool = True) -> argparse.ArgumentParser:
    """The ``terrapref`` command line (``train_flags``: with train's training flags)."""
    from terrapref import __version__

    parser = _Parser(prog="terrapref", description="Learn off-road terrain preferences from a few minutes of driving.")
    parser.add_argument("--version", action="version", version=f"terrapref {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add in COMMANDS:
        add(sub, flags=train_flags) if add is _train_parser else add(sub)
    return parser


def _on_sigterm(pid: int) -> Callable[[int, object], None]:
    def handler(signum: int, frame: object) -> None:
        if os.getpid() != pid:  # a forked worker: end as SIGTERM ends a process, the command cleans up
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)
            return
        raise Terminated()
    return handler


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    command = next((a for a in argv if not a.startswith("-")), None)
    parser = build_parser(train_flags=command == "train")
    args = parser.parse_args(argv)
    func: Callable[[argparse.Namespace], int] = args.func
    on_main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _on_sigterm(os.getpid())) if on_main_thread else None
    try:
        return func(args)
    except UserError as exc:
        for line in exc.lines():
            print(f"error: {line}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        if isinstance(exc, Terminated):  # cleaned up on the way here; end now, before libraries' exit handlers (SDL's can wait)
            print("terminated", file=sys.stderr, flush=True)
            sys.stdout.flush()
            os._exit(143)
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into `head` and the like: stop quietly
        sys.stderr.close()
        return 0
    except OSError as exc:
        print(f"error: {exc.filename or ''}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    except GridError as exc:  # jobs of a grid failed: each named by its inputs
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except Exception as exc:  # a bug, not a user error: one line unless asked for the traceback
        if os.environ.get("TERRAPREF_DEBUG"):
            raise
        print(f"error: internal error ({type(exc).__name__}: {exc}); set TERRAPREF_DEBUG=1 for the traceback", file=sys.stderr)
        return 1
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    sys.exit(main())
