"""Commands for robots and their logs: import, replay, export, ros1, ros2, play, route, info."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from terrapref.cli.common import add_classes_arg, add_force_arg, add_live_args, check_table, class_table, live_view
from terrapref.configargs import finite_float
from terrapref.errors import Terminated, UserError
from terrapref.fileio import check_output, output_folder, write_text_atomic


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
    p.add_argument("--out", required=True, help="recording folder to create")
    p.add_argument("--rate", type=finite_float, default=10.0, help="frames per second to keep (default 10, the planner's rate)")
    p.add_argument("--force", action="store_true", help="replace an existing recording at --out (only once the import succeeds)")
    p.add_argument("--profile", help="the driver's preference order, best first, stored with the recording (default: the robot file's "
                                     "profile; with neither, the recording declares none and training refuses it)")
    add_classes_arg(p)
    p.set_defaults(func=_cmd_import)


def _cmd_replay(args: argparse.Namespace) -> int:
    from terrapref.interop.robot import load_robot
    from terrapref.learning.model_file import load_model

    model = load_model(args.model)
    robot = load_robot(args.robot, model.classes)
    out = Path(args.out)
    check_output(out, "--out", [args.bag, args.model, args.robot], folder=True)
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
    print("top-3: how often the operator's trajectory is among the three C ranks most probable (F_t); the planner's rules "
          "choose one trajectory and rank none, so only C has a top-3")
    print(f"wrote {out / 'replay.json'} and {out / 'replay.png'}")
    return 0


def replay_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("replay", help="run a model open-loop over a held-out bag: how often it makes the operator's choice")
    p.add_argument("bag", help="a .bag file, a ROS 2 bag folder, or a .mcap / .db3 file")
    p.add_argument("--robot", required=True, help="terrapref-robot/1 file")
    p.add_argument("--model", required=True, help="model file (terrapref train)")
    p.add_argument("--out", required=True, help="folder for replay.json, replay.png and the imported recording")
    p.add_argument("--rate", type=finite_float, default=10.0, help="frames per second to replay (default 10)")
    add_force_arg(p)
    p.set_defaults(func=_cmd_replay)


def _cmd_export(args: argparse.Namespace) -> int:
    out = Path(args.out)
    inputs = [args.input] + ([args.model] if args.model else [])
    check_output(out, "--out", inputs, force=args.force)
    if args.format in ("mcap", "rosbag1"):
        check_output(Path(f"{out}.robot.yaml"), "--out", inputs, force=args.force)
        check_output(Path(f"{out}.labels.yaml"), "--out", inputs, force=args.force)
        from dataclasses import replace

        from terrapref.demos.recording import read_recording
        from terrapref.extras import check
        from terrapref.interop.mcap_export import recording_frames, write_bag
        from terrapref.progress import Progress

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
        check_table(args, model.classes, args.input)
    from terrapref.rules import driving_rule, rules_of

    rules, drives = rules_of(model)
    driving = driving_rule(rules, drives, args.input)
    export_onnx(model, out)
    print(f"wrote {out} (ONNX: input utilities float32 [N, {model.classifier.m}, {model.classifier.n_features}], output logits float32 [N, {model.classifier.m}])")
    if not driving.graph:
        print(f"note: {args.input} drives by the {driving.type} rule, which is not a network: the graph holds C, the classifier the model "
              "also carries, and the rule's block is in its metadata; the deployable planner is terrapref.runtime.PlannerRuntime "
              "(or terrapref ros1 / ros2), docs/robot.md", file=sys.stderr)
    return 0


def _model_costmaps(model_path: str, frames):
    from terrapref.interop.mcap_export import model_costmaps
    from terrapref.learning.model_file import load_model

    try:
        return model_costmaps(load_model(model_path), frames)
    except ValueError as exc:
        raise UserError(model_path, str(exc), field="--model") from None


def export_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("export", help="export a model as ONNX, or a recording as ROS 2 MCAP (Foxglove, RViz) or a ROS 1 bag")
    p.add_argument("input", help="model file (--format onnx) or recording folder (--format mcap or rosbag1)")
    p.add_argument("--format", choices=["onnx", "mcap", "rosbag1"], required=True,
                   help="onnx: the classifier C; mcap: the recording's frames as ROS 2 messages; rosbag1: the same as a ROS 1 bag (rosbag play)")
    p.add_argument("--out", required=True, help="output file")
    p.add_argument("--model", help="with --format mcap or rosbag1: also write the costmap this model (with an offset rule) prices the recording's ground with, "
                                   "as nav_msgs/OccupancyGrid and foxglove_msgs/Grid, once a second")
    add_classes_arg(p, check=True)
    add_force_arg(p)
    p.set_defaults(func=_cmd_export)


def _cmd_ros1(args: argparse.Namespace) -> int:
    from terrapref.interop.ros1 import NodeOptions, run_node

    options = NodeOptions(stamped=True if args.stamped else None, rate=args.rate, path_file=args.path_file, cmd_topic=args.cmd_topic)
    options.resolved(lambda name, default: default)  # what the command line gives is checked before ROS starts
    view = live_view(args)
    try:
        run_node(args.model, args.robot, options, live=view)
    finally:
        if view is not None:
            view.stop()
    return 0


def ros1_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("ros1", help="run the planner as a ROS 1 node (rospy; Debian's ros-core and python3-rospy)")
    p.add_argument("--model", required=True, help="a model file from train")
    p.add_argument("--robot", required=True, help="the robot file: topics, camera mounting, label map (terrapref-robot/1)")
    p.add_argument("--stamped", action="store_true",
                   help="publish geometry_msgs/TwistStamped (stamped with the frame decided on) instead of Twist (ROS parameter ~stamped)")
    p.add_argument("--rate", type=finite_float, help="commands per second between decisions (ROS parameter ~rate; default 20)")
    p.add_argument("--path-file", help="waypoints (YAML: a list, a mapping with waypoints, or a scenario such as terrapref route writes) of "
                                       "the reference path in the odometry frame, instead of the path topic (ROS parameter ~path_file)")
    p.add_argument("--cmd-topic", help="where to publish the command (ROS parameter ~cmd_topic; default: the robot file's command topic)")
    add_live_args(p, "stamped with the frames' ROS times")
    p.set_defaults(func=_cmd_ros1)


def _cmd_ros2(args: argparse.Namespace) -> int:
    from terrapref.extras import check

    check("ros2", "terrapref ros2")  # before the model is read
    from terrapref.interop.node_core import NodeOptions
    from terrapref.interop.ros2 import run_node

    options = NodeOptions(stamped=True if args.stamped else None, rate=args.rate, path_file=args.path_file, cmd_topic=args.cmd_topic)
    options.resolved(lambda name, default: default)  # what the command line gives is checked before DDS starts
    view = live_view(args)
    try:
        run_node(args.model, args.robot, options, ros_args=args.ros_args or (), live=view)
    except KeyboardInterrupt as exc:  # Ctrl-C ends a node as ROS 2's do (its summary printed); SIGTERM as every command
        if isinstance(exc, Terminated):
            raise
    finally:
        if view is not None:
            view.stop()
    return 0


def ros2_parser(sub: argparse._SubParsersAction) -> None:
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
    add_live_args(p, "stamped with the frames' ROS times")
    p.add_argument("--ros-args", nargs=argparse.REMAINDER, metavar="ARG",
                   help="ROS 2's arguments, last: -p NAME:=VALUE (stamped, rate, path_file, cmd_topic, hold_s, use_sim_time) and "
                        "-r FROM:=TO (topics; __node, __ns); ROS_DOMAIN_ID picks the domain")
    p.set_defaults(func=_cmd_ros2)


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


def play_parser(sub: argparse._SubParsersAction) -> None:
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


def _cmd_route(args: argparse.Namespace) -> int:
    import yaml

    from terrapref.learning.model_file import load_model
    from terrapref.planner.route import RouteConfig, RouteError, route_over, routed_scenario
    from terrapref.plots import save_map
    from terrapref.scenario import resolve_scenario
    from terrapref.world import rasterise

    out, figure = Path(args.out), Path(args.out).with_suffix(".png")
    for path in (out, figure):
        check_output(path, "--out", [args.scenario, args.model], force=args.force)
    if out.suffix.lower() not in (".yaml", ".yml"):
        raise UserError(str(out), "the route is written as a scenario file: give it the suffix .yaml", field="--out")
    if not (math.isfinite(args.resolution) and 0.1 <= args.resolution <= 2.0):
        raise UserError("--resolution", f"expected a cell size in [0.1, 2] m, got {args.resolution}")
    model = load_model(args.model)
    if args.classes is not None:  # the model carries its table; --classes, when given, must be it
        check_table(args, model.classes, args.model)
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


def route_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("route", help="plan a global route over a scenario's map, priced with a model's learned preference, as waypoints the planner follows")
    p.add_argument("scenario", help="the course (packaged name, file or gen:N): its terrain stands in for a prior map such as labelled aerial imagery")
    p.add_argument("--model", required=True, help="a model with an offset rule (recipe teach): its class prices and price of leaving the path")
    p.add_argument("--out", required=True, help="the scenario with the route as its path (.yaml); a figure is written beside it (.png)")
    p.add_argument("--resolution", type=finite_float, default=0.25,
                   help="search cell size [m], 0.1-2, taken as the nearest whole multiple of the map's cells (default 0.25)")
    add_classes_arg(p, check=True)  # the scenario is read with the model's table
    add_force_arg(p)
    p.set_defaults(func=_cmd_route)


def _cmd_info(args: argparse.Namespace) -> int:
    from terrapref.report.info import info_lines

    for i, path in enumerate(args.files):
        if i:
            print()
        for line in info_lines(path):
            print(line)
    return 0


def info_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("info", help="what a recording, dataset, model or ONNX file holds (camera, profile, data, history, identifiability)")
    p.add_argument("files", nargs="+", metavar="FILE", help="recording folders, dataset or model files (.safetensors), ONNX files")
    p.set_defaults(func=_cmd_info)
