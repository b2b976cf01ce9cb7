"""Commands on robot logs and the product's files: import, replay, export, info."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from terrapref.cli.common import add_classes_arg, add_force_arg, check_run_folder, check_table, class_table, output_path
from terrapref.configargs import finite_float
from terrapref.errors import UserError
from terrapref.fileio import check_output, output_folder


def _cmd_import(args: argparse.Namespace) -> int:
    from terrapref.interop.bag_import import ImportOptions, import_bag
    from terrapref.interop.robot import load_robot
    from terrapref.terrain import PreferenceProfile, default_classes

    check_output(args.out, "--out", [args.bag, args.robot], folder=True)
    table = class_table(args)
    robot = load_robot(args.robot, table)
    profile = PreferenceProfile.parse(args.profile, table or default_classes()) if args.profile is not None else None
    report = import_bag(args.bag, robot, args.out, ImportOptions(rate_hz=args.rate, force=args.force, classes=table, profile=profile))
    for line in report.lines():
        print(line)
    print(f"wrote {args.out} (terrapref inspect / featurize / train accept it)")
    return 0


def import_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("import", help="turn a ROS 1 bag, ROS 2 bag (sqlite3 or MCAP) of a drive into a recording")
    p.add_argument("bag", help="a .bag file, a ROS 2 bag folder, or a .mcap / .db3 file")
    p.add_argument("--robot", required=True, help="terrapref-robot/1 file: topics, camera mounting, label map")
    p.add_argument("--out", type=output_path, required=True, help="recording folder to create")
    p.add_argument("--rate", type=finite_float, default=10.0, help="frames per second to keep (default 10, the planner's rate)")
    p.add_argument("--force", action="store_true", help="replace an existing recording at --out (only once the import succeeds)")
    p.add_argument(
        "--profile",
        help="the driver's preference order, best first, stored with the recording (default: the robot file's "
        "profile; with neither, the recording declares none: a model trains from it and names no order, and "
        "evaluate asks for one)",
    )
    add_classes_arg(p)
    p.set_defaults(func=_cmd_import)


def _cmd_replay(args: argparse.Namespace) -> int:
    from terrapref.interop.robot import load_robot
    from terrapref.planner.model import Model

    model = Model.load(args.model)
    robot = load_robot(args.robot, model.classes, f"--model {args.model}")
    out = Path(args.out)
    check_run_folder(out, [args.bag, args.model, args.robot])
    with output_folder(out, args.force):  # refused (another camera) or stopped: nothing unfinished is left at OUT
        return _replay_into(args, model, robot, out)


def _replay_into(args: argparse.Namespace, model, robot, out: Path) -> int:
    from terrapref.demos.recording import read_recording
    from terrapref.interop.bag_import import ImportOptions, import_bag
    from terrapref.interop.replay import replay, summary_lines, write_replay
    from terrapref.interop.runtime import RobotSettings
    from terrapref.learning.model_file import check_compatible
    from terrapref.progress import Progress

    rec_dir = out / "recording"
    options = ImportOptions(
        rate_hz=args.rate, force=True, classes=model.classes, check_camera=lambda camera: check_compatible(model, camera)
    )
    report = import_bag(args.bag, robot, rec_dir, options)
    print(f"imported {report.frames} frames ({report.duration_s:.0f} s) into {rec_dir}")
    rec = read_recording(rec_dir)
    bar = Progress("replay", len(rec))
    settings = RobotSettings(robot.stop, robot.limits, rules=robot.rules)  # the robot file's, as its node takes them
    result = replay(model, rec, progress=lambda k, n: bar.update(k, f"{k}/{n} frames"), robot=settings)
    bar.close()
    write_replay(result, out, f"{Path(args.model).name} on {Path(args.bag).name}")
    for line in summary_lines(result):
        print(line)
    print(
        "top-3: how often the operator's trajectory is among the three C ranks most probable (F_t); the planner's rules "
        "choose one trajectory and rank none, so only C has a top-3"
    )
    print(f"wrote {out / 'replay.json'} and {out / 'replay.png'}")
    return 0


def replay_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("replay", help="run a model open-loop over a held-out bag: how often it makes the operator's choice")
    p.add_argument("bag", help="a .bag file, a ROS 2 bag folder, or a .mcap / .db3 file")
    p.add_argument("--robot", required=True, help="terrapref-robot/1 file")
    p.add_argument("--model", required=True, help="model file (terrapref train)")
    p.add_argument("--out", type=output_path, required=True, help="folder for replay.json, replay.png and the imported recording")
    p.add_argument("--rate", type=finite_float, default=10.0, help="frames per second to replay (default 10)")
    add_force_arg(p)
    p.set_defaults(func=_cmd_replay)


EXPORT_SUFFIXES = {"onnx": ".onnx", "mcap": ".mcap", "rosbag1": ".bag"}  # what each format's readers know its files by


def _cmd_export(args: argparse.Namespace) -> int:
    out = Path(args.out)
    inputs = [args.input] + ([args.model] if args.model else [])
    check_output(out, "--out", inputs, force=args.force)
    suffix = EXPORT_SUFFIXES[args.format]
    if out.suffix.lower() != suffix:  # import, replay and play know a file's format by its name
        raise UserError(str(out), f"--format {args.format} writes a {suffix} file, which its readers know by that name", field="--out")
    if args.format in ("mcap", "rosbag1"):
        check_output(Path(f"{out}.robot.yaml"), "--out", inputs, force=args.force)
        check_output(Path(f"{out}.labels.yaml"), "--out", inputs, force=args.force)
        _export_bag(args, out)
    else:
        _export_onnx(args, out)
    return 0


def _export_bag(args: argparse.Namespace, out: Path) -> None:
    """A recording as a ROS 2 MCAP or a ROS 1 bag, with the robot file and label map that import it again."""
    from dataclasses import replace

    from terrapref.demos.recording import read_recording
    from terrapref.extras import check
    from terrapref.interop.mcap_export import recording_frames, write_bag
    from terrapref.progress import Progress
    from terrapref.terrain import default_classes

    check("robot", f"terrapref export --format {args.format}", "rosbags")  # before the frames are read
    rec = read_recording(args.input)
    if args.classes is not None:
        check_table(args, rec.classes, args.input)
    if len(rec) == 0:
        raise UserError(args.input, "holds no frames", field="frames.jsonl")
    frames = recording_frames(rec)
    if args.model:
        frames = replace(frames, costmap=_model_costmaps(args.model, frames))
    bar = Progress("export", len(rec))
    write_bag(out, frames, ros1=args.format == "rosbag1", progress=lambda done, total: bar.update(done, f"{done}/{total} frames"))
    bar.close(f"{len(rec)} frames")
    what = "ROS 1 bag; rosbag play it" if args.format == "rosbag1" else "ROS 2 MCAP; open it in Foxglove"
    if not frames.classes.same_classes(default_classes()):
        print(
            f"wrote {out} ({what}), {out}.robot.yaml and its label map {out}.labels.yaml "
            f"(terrapref import {out} --robot {out}.robot.yaml --classes FILE, the recording's class table)"
        )
    else:
        print(f"wrote {out} ({what}) and {out}.robot.yaml (terrapref import {out} --robot {out}.robot.yaml)")


def _export_onnx(args: argparse.Namespace, out: Path) -> None:
    """A model's classifier C as ONNX; a rule that is not a network is said to stay out of the graph."""
    from terrapref.interop.onnx_export import export_onnx
    from terrapref.planner.model import Model

    if args.model:
        raise UserError(
            args.model,
            "--model goes with --format mcap or rosbag1 (a recording's costmap); for onnx the model is the input",
            field="--model",
        )
    if Path(args.input).is_dir():
        raise UserError(
            args.input,
            "is a recording folder; --format onnx exports a model file (.safetensors), a recording exports as --format mcap or rosbag1",
            field="--format",
        )
    model = Model.load(args.input)
    if model.classifier is None:
        raise UserError(args.input, f"holds a {model.kind!r} model, not the classifier C: --format onnx exports C", field="kind")
    if args.classes is not None:
        check_table(args, model.classes, args.input)
    driving = model.driving
    export_onnx(model.classifier, out)
    c = model.classifier.classifier
    print(f"wrote {out} (ONNX: input utilities float32 [N, {c.m}, {c.n_features}], output logits float32 [N, {c.m}])")
    if not driving.graph:
        print(
            f"note: {args.input} drives by the {driving.type} rule, which is not a network: the graph holds C, the classifier the model "
            "also carries, and the rule's block is in its metadata; the deployable planner is terrapref.runtime.PlannerRuntime "
            "(or terrapref ros1 / ros2), docs/robot.md",
            file=sys.stderr,
        )


def _model_costmaps(model_path: str, frames):
    from terrapref.interop.mcap_export import model_costmaps
    from terrapref.planner.model import Model

    try:
        return model_costmaps(Model.load(model_path), frames)
    except ValueError as exc:
        raise UserError(model_path, str(exc), field="--model") from None


def export_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("export", help="export a model as ONNX, or a recording as ROS 2 MCAP (Foxglove, RViz) or a ROS 1 bag")
    p.add_argument("input", help="model file (--format onnx) or recording folder (--format mcap or rosbag1)")
    p.add_argument(
        "--format",
        choices=["onnx", "mcap", "rosbag1"],
        required=True,
        help="onnx: the classifier C; mcap: the recording's frames as ROS 2 messages; rosbag1: the same as a ROS 1 bag (rosbag play)",
    )
    p.add_argument("--out", type=output_path, required=True, help="output file")
    p.add_argument(
        "--model",
        help="with --format mcap or rosbag1: also write the costmap this model (with an offset rule) prices the recording's ground with, "
        "as nav_msgs/OccupancyGrid, foxglove_msgs/Grid and grid_map_msgs/GridMap (with its learned speed and, on relief, "
        "the ground's height, slope, roughness and step), once a second; with a speed rule, also the speed as Nav2's "
        "speed filter (nav2_msgs/CostmapFilterInfo and its mask)",
    )
    add_classes_arg(p, check=True)
    add_force_arg(p)
    p.set_defaults(func=_cmd_export)


def _cmd_info(args: argparse.Namespace) -> int:
    """Each file's summary; a model file no command can use is shown as far as its header goes,
    its refusal on stderr, and the exit code is 2 (the others are still shown)."""
    from terrapref.report.info import NotReadable, info_lines

    status = 0
    for i, path in enumerate(args.files):
        if i:
            print()
        try:
            lines = info_lines(path)
        except NotReadable as exc:
            lines, status = exc.shown, 2
            for line in exc.lines():
                print(f"error: {line}", file=sys.stderr)
        for line in lines:
            print(line)
    return status


def info_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("info", help="what a recording, dataset, model or ONNX file holds (camera, profile, data, history, identifiability)")
    p.add_argument("files", nargs="+", metavar="FILE", help="recording folders, dataset or model files (.safetensors), ONNX files")
    p.set_defaults(func=_cmd_info)
