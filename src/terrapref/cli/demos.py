"""Commands that make and read demonstrations: record, drive, inspect, featurize."""

from __future__ import annotations

import argparse
import math
import shutil
import sys
from pathlib import Path

from terrapref.cli.common import (
    SCENARIO_HELP,
    add_classes_arg,
    add_force_arg,
    add_live_args,
    by_recording,
    check_table,
    class_table,
    featurize_features,
    incidents,
    live_view,
    output_path,
    perception_model,
    warn_partial,
)
from terrapref.configargs import finite_float, positive_float
from terrapref.errors import UserError
from terrapref.fileio import check_distinct, check_figure, check_output, check_tensor_file


def _cmd_record(args: argparse.Namespace) -> int:
    import numpy as np

    from terrapref.demos.expert import ExpertDriver
    from terrapref.demos.meta import ExpertInfo
    from terrapref.demos.recording import RecordingWriter
    from terrapref.demos.session import DriveSetup, RunSettings, record_run
    from terrapref.demos.speed_style import driver_style
    from terrapref.progress import Progress
    from terrapref.scenario import resolve_scenario
    from terrapref.terrain import PreferenceProfile
    from terrapref.vehicle.ground import drivable

    if args.seed < 0:
        raise UserError("--seed", f"must be an integer >= 0, got {args.seed}")
    check_output(args.out, "--out", [args.scenario], folder=True)
    scenario = drivable(resolve_scenario(args.scenario, class_table(args)))
    profile = (
        PreferenceProfile.parse(args.profile, scenario.classes) if args.profile is not None else PreferenceProfile.default(scenario.classes)
    )
    if args.relief_style is not None and not scenario.has_relief:
        print(f"note: {args.scenario} is flat: the relief style is kept with the recording but no frame shows it", file=sys.stderr)
    drive = DriveSetup.of(scenario)
    expert = driver_style(args.style, profile.order, scenario.classes, drive.sim.vehicle.max_speed_mps, _style_flags(args))
    disturbance = _disturbance(args.disturb)
    perception = perception_model(args.perception, classes=scenario.classes)
    meta = drive.meta(ExpertInfo.of(args.seed, args.style, expert, disturbance), profile, perception)
    sim = drive.simulation()
    writer = RecordingWriter(args.out, meta, scenario.to_dict(), overwrite=args.force)
    bar = Progress(f"record {scenario.name}", sim.path.length_m, enabled=not args.quiet)
    try:
        log = record_run(
            sim,
            ExpertDriver(expert, drive.sim.camera_rate_hz),
            writer,
            RunSettings(drive.preference, disturbance, perception),
            np.random.default_rng(args.seed),
            progress=lambda s: bar.update(s.progress_m, f"t={s.time_s:6.1f}s frames={writer.count}"),
        )
    except BaseException as exc:
        writer.abort()
        if writer.partial_dir is not None and isinstance(exc, OSError):  # a full disk: the unfinished replacement goes
            shutil.rmtree(writer.partial_dir, ignore_errors=True)
            print(f"note: {args.out} keeps the recording it held", file=sys.stderr)
        elif writer.partial_dir is not None:
            print(f"note: {args.out} keeps the recording it held; the unfinished new one is in {writer.partial_dir}", file=sys.stderr)
        elif writer.count:  # a first recording: what was recorded stays, marked partial
            why = "the write failed" if isinstance(exc, OSError) else "it was stopped"
            print(f"note: {args.out} keeps the {writer.count} frames recorded before {why} (partial)", file=sys.stderr)
        raise
    bar.close("done")
    state = "reached the goal" if log.completed else "timed out"
    seen = (
        f"; the frames are what the robot received under perception {perception.name}"
        if perception is not None and perception.active
        else ""
    )
    print(f"wrote {args.out}: {writer.count} frames, {log.duration_s:.1f} s, {state}, {incidents(log)} (complete){seen}")
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


def _style_flags(args: argparse.Namespace) -> dict:
    """The driver's fields the speed and relief flags set (none given: none)."""
    from terrapref.demos.relief_style import parse_relief_style
    from terrapref.demos.speed_style import parse_speeds

    flags: dict = {}
    if args.relief_style is not None:
        flags["relief"] = parse_relief_style(args.relief_style)[1]
    if args.speeds is not None:
        flags["speeds"] = parse_speeds(args.speeds)
    if args.lateral_accel is not None:
        flags["lateral_accel_mps2"] = args.lateral_accel
    if args.preview is not None:
        flags["preview_m"] = args.preview
    return flags


def record_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("record", help="record a demonstration with the synthetic driver")
    p.add_argument("scenario", metavar="SCENARIO", help=SCENARIO_HELP)
    p.add_argument("--profile", help="preference order, best first, e.g. rock,mud,water,non_traversable (default: the class table's)")
    p.add_argument(
        "--style",
        default="default",
        metavar="NAME|FILE",
        help="the driver's style: default (1 m/s everywhere), wide (wider margins, cautious), late (reacts later, brisk), "
        "shaky (a shakier hand), reluctant (leaves the path reluctantly), or a terrapref-driver-style/1 file",
    )
    p.add_argument(
        "--speeds",
        metavar="CLASS=MPS,...",
        help="cruising speed per class [m/s], the background class included, e.g. grass=1.6,mud=0.5 (classes not named keep the style's)",
    )
    p.add_argument("--lateral-accel", type=positive_float, metavar="MPS2", help="lateral acceleration the driver keeps to in bends [m/s^2]")
    p.add_argument("--preview", type=positive_float, metavar="M", help="how early the driver slows before a slower class [m]")
    p.add_argument(
        "--relief-style",
        metavar="NAME[,K=V,...]",
        help="how the driver takes relief: default (round side slopes past 12 deg and grades past 15 deg, 0.03 m/s less per deg up), "
        "bold, cautious, each with K=V changes (roll_deg, grade_deg, up_mps_per_deg, down_mps_per_deg, rough_mps, rough_m); "
        "none, or not given: it drives relief as if it were flat (docs/cli.md, Relief)",
    )
    p.add_argument("--seed", type=int, default=0, help="seeds the driver's hand and the pushes (default 0)")
    p.add_argument("--out", required=True, type=output_path, help="recording directory to create")
    p.add_argument("--force", action="store_true", help="replace an existing recording at --out")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.add_argument(
        "--disturb",
        type=finite_float,
        default=None,
        metavar="RATE",
        help="push the executed yaw rate off the driver's command RATE times per second, so recoveries are shown "
        "(default: the recommended protocol's 0.6, recipe teach's; 0: none)",
    )
    p.add_argument(
        "--perception",
        metavar="PRESET|FILE",
        help="the driver sees the truth; the recording holds what the robot's camera and localisation gave through this "
        "perception model (a preset: clean, rellis, field; or a terrapref-perception/1 file)",
    )
    add_classes_arg(p)
    p.set_defaults(func=_cmd_record)


def _cmd_drive(args: argparse.Namespace) -> int:
    from terrapref.scenario import resolve_scenario
    from terrapref.teleop import TeleopOptions, run_session
    from terrapref.terrain import PreferenceProfile
    from terrapref.vehicle.ground import drivable

    if args.seed < 0:
        raise UserError("--seed", f"must be an integer >= 0, got {args.seed}")
    riding = None  # the table of the model riding along: the scenario is read with it
    if args.model is not None:
        from terrapref.learning.model_file import load_model

        riding = load_model(args.model).classes
        if args.classes is not None:
            check_table(args, riding, args.model)
    scenario = drivable(resolve_scenario(args.scenario, class_table(args) or riding))
    profile = PreferenceProfile.parse(args.profile, scenario.classes) if args.profile is not None else None
    if args.record is not None:
        check_output(args.record, "--record", [args.scenario, *([args.model] if args.model else [])], folder=True)
    perception = perception_model(args.perception, classes=scenario.classes)
    view = live_view(args)
    try:
        result = run_session(
            scenario,
            TeleopOptions(
                record_dir=args.record,
                overwrite=args.force,
                v_mps=args.speed,
                disturbance=_disturbance(args.disturb),
                seed=args.seed,
                profile=profile,
                model=args.model,
                perception=perception,
                live=view,
            ),
        )
    finally:
        if view is not None:
            view.stop()
    where = f", recorded to {result.record_dir}" if result.record_dir else ""
    state = "reached the goal" if result.completed else ("quit" if result.quit else "stopped")
    edge = f", {result.edge_frames} frames held at the map's edge (not recorded)" if result.edge_frames else ""
    edge += f", {result.pushes} push{'es' if result.pushes != 1 else ''} (--disturb 0: none)" if result.pushes else ""
    if args.model is not None:
        where = where or (", so nothing was recorded" if args.record is not None else "")
        print(
            f"rode along: the planner drove {result.planner_frames} frames, you {result.frames} (corrections){where}; "
            f"{state}, {incidents(result)}{edge}"
        )
    else:
        print(f"drove {result.frames} frames, {state}, {incidents(result)}{where}{edge}")
    return 0


def drive_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "drive", help="drive a scenario yourself (keyboard, mouse or gamepad), optionally recording, or ride along with a model (--model)"
    )
    p.add_argument("scenario", metavar="SCENARIO", help=SCENARIO_HELP)
    p.add_argument("--record", type=Path, metavar="DIR", help="record the drive into DIR")
    p.add_argument("--force", action="store_true", help="replace an existing recording at DIR")
    p.add_argument(
        "--speed",
        type=finite_float,
        default=1.0,
        help="the set speed at the start [m/s], up to the vehicle's top speed; W/S, the mouse wheel or a gamepad change it (default 1)",
    )
    p.add_argument(
        "--disturb",
        type=finite_float,
        default=None,
        metavar="RATE",
        help="pushes per second on the executed yaw rate, each shown in the window as it happens "
        "(default: the recommended protocol's 0.6, recipe teach's; 0: none)",
    )
    p.add_argument("--seed", type=int, default=0, help="seeds the pushes")
    p.add_argument(
        "--profile",
        help="your preference order, best first, stored with the recording and compared with the order your drive shows "
        "(default: riding along, the model's; else none is declared)",
    )
    p.add_argument(
        "--model",
        type=Path,
        metavar="MODEL",
        help="ride along: MODEL drives, any stick or throttle input takes over, and the frames you drive are recorded as "
        "corrections that train accepts beside demonstrations",
    )
    p.add_argument(
        "--perception",
        metavar="PRESET|FILE",
        help="you see the truth; the recording (and a riding-along model) gets what the robot's camera and localisation "
        "gave through this perception model",
    )
    add_live_args(p, "every driven frame, riding along with the planner's F_t and costmap")
    add_classes_arg(p)
    p.set_defaults(func=_cmd_drive)


def _cmd_inspect(args: argparse.Namespace) -> int:
    from terrapref.demos.recording import read_recording
    from terrapref.report.inspect import save_driven_path, summarise

    if args.out is not None:
        check_figure(args.out, "--out")
        check_output(args.out, "--out", [args.recording], force=args.force)
    rec = read_recording(args.recording)
    if getattr(args, "classes", None) is not None:
        check_table(args, rec.classes, args.recording)
    out = args.out or rec.path / "driven_path.png"
    if args.out is None:  # the default figure, in the recording: refused before any work as any output is
        check_output(out, "--out", force=args.force)
    summary = summarise(rec)
    # Every frame is read before the figure is written: a damaged one leaves the old figure as it was.
    shows = [] if args.no_preference else _what_the_drive_shows(rec)
    for line in summary.lines():
        print(line)
    save_driven_path(summary, rec, out)
    print(f"wrote {out}")
    for line in shows:
        print(line)
    return 0


def _what_the_drive_shows(rec) -> list[str]:
    """The lines of the identifiability report of a recording (featurised as the default recipe would), before any training."""
    from terrapref.dataset import build_dataset
    from terrapref.learning.train import FitData, identify
    from terrapref.progress import Progress
    from terrapref.recipes import DEFAULT_RECIPE, recipe_named
    from terrapref.rules import SpeedConfig
    from terrapref.rules.offset.rule import OffsetConfig

    if len(rec) == 0:
        return ["what the drive shows: nothing (no frames)"]
    recipe = recipe_named(DEFAULT_RECIPE)
    bar = Progress("featurize", len(rec), unit="frames")
    dataset = build_dataset(
        [rec], recipe.features(), rules=recipe.rules, progress=lambda p: bar.update(p.frames_done, f"{p.frames_done}/{p.frames} frames")
    )
    bar.close()
    lines = [f"what the drive shows (recipe {DEFAULT_RECIPE}'s features, {len(dataset)} frames):"]
    lines += [f"  {line}" for line in identify(dataset, steady=recipe.train.data.steady_labels).lines_with_order(rec.meta.get("profile"))]
    speed = next((rule for rule in recipe.rules if isinstance(rule, SpeedConfig)), None)
    fitted = speed.fit(FitData(dataset, mirror=False)) if speed is not None else None
    if fitted is not None:
        lethal = frozenset({rec.classes.lethal_column} if rec.classes.lethal else ())
        lines.append("  the speed it shows: " + "; ".join(fitted.lines(dataset.feature_config.feature_classes, lethal)))
        lines += [f"  warning: {warning}" for warning in fitted.warnings(dataset.feature_config.feature_classes, lethal)]
    offset = next((rule for rule in recipe.rules if isinstance(rule, OffsetConfig)), None)
    found = dataset.rule_data(offset.type) if offset is not None else None
    if found is not None and "relief_m" in found[1]:  # a drive on relief: the steering's prices of it
        steering = offset.fit(FitData(dataset, mirror=False))
        lines += [f"  {line}" for line in (steering.relief_lines() if steering is not None else ())]
    return lines


def inspect_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("inspect", help="summarise a recording and draw its driven path")
    p.add_argument("recording", metavar="DIR", type=Path, help="a recording folder (from record, drive or import)")
    p.add_argument("--out", type=output_path, help="top-down PNG (default: DIR/driven_path.png)")
    p.add_argument(
        "--no-preference",
        action="store_true",
        help="skip what the drive shows of the driver's preference (it featurises every frame: seconds)",
    )
    add_classes_arg(p, check=True)
    add_force_arg(p)
    p.set_defaults(func=_cmd_inspect)


def _cmd_featurize(args: argparse.Namespace) -> int:
    from terrapref.dataset import build_dataset, check_distinct_drives, save_dataset
    from terrapref.demos.recording import read_recording
    from terrapref.progress import Progress

    check_distinct(args.recordings, "recording")
    check_tensor_file(args.out, "--out")
    check_output(args.out, "--out", [*args.recordings, *([args.camera] if args.camera else [])], force=args.force)
    recordings = [read_recording(p) for p in args.recordings]
    for r in recordings:
        if args.classes is not None:
            check_table(args, r.classes, r.path)
        warn_partial(r)
    from terrapref.recipes import DEFAULT_RECIPE, recipe_named

    recipe = recipe_named(args.recipe or DEFAULT_RECIPE)
    features = featurize_features(args, recipe)
    camera = None
    if args.camera:
        from terrapref.camera.files import load_camera

        camera = load_camera(args.camera)
    bar = Progress("featurize", len(recordings))
    dataset = build_dataset(recordings, features, camera, recipe.rules, progress=by_recording(bar))
    bar.close()
    check_distinct_drives(dataset)
    save_dataset(dataset, args.out)
    print(f"wrote {args.out}: {len(dataset)} samples from {len(recordings)} recordings (fingerprint {dataset.fingerprint})")
    return 0


def featurize_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("featurize", help="turn recordings into a training set (U, label)")
    p.add_argument("recordings", nargs="+", metavar="DIR", type=Path, help="recording folders (from record, drive or import)")
    p.add_argument("--out", required=True, type=output_path, help="dataset file (.safetensors)")
    p.add_argument(
        "--distance-mode",
        choices=["progress", "window", "paper"],
        type=lambda v: "progress" if v == "lookahead" else v,  # its name before "look-ahead" was the second stage's alone
        default="progress",
        help="how each trajectory's distance to the path is measured: progress (default) to the path point the vehicle's progress reaches, "
        "window to the nearest path point within a window, paper as the paper writes it",
    )
    p.add_argument("--n-steps", type=int, help="trajectory points n (default 30)")
    p.add_argument("--dt", type=finite_float, help="trajectory time step [s] (default 0.2)")
    p.add_argument(
        "--camera",
        help="camera file to re-render the frames with: CameraConfig's fields, or a ROS camera_info YAML (with mount_height_m, pitch_deg)",
    )
    p.add_argument("--recipe", metavar="NAME", help="featurise as this recipe trains (default: teach, with the look-ahead utilities)")
    add_classes_arg(p, check=True)
    add_force_arg(p)
    p.set_defaults(func=_cmd_featurize)
