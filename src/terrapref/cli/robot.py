"""Commands for a robot: ros1, ros2, play, route."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from terrapref.cli.common import add_classes_arg, add_force_arg, add_live_args, check_table, live_view, output_path
from terrapref.configargs import finite_float
from terrapref.errors import Terminated, UserError
from terrapref.fileio import check_output, write_text_atomic


def _node_options(args: argparse.Namespace):
    """The options a node's flags give (terrapref.interop.node_core.NodeOptions), checked before
    the node joins ROS: a flag not given is left to the node's parameter or default."""
    from terrapref.interop.node_core import NodeOptions

    options = NodeOptions(stamped=True if args.stamped else None, rate=args.rate, path_file=args.path_file, cmd_topic=args.cmd_topic)
    options.resolved(lambda name, default: default)
    return options


def _cmd_ros1(args: argparse.Namespace) -> int:
    from terrapref.interop.ros1 import run_node

    options = _node_options(args)
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
    p.add_argument(
        "--stamped",
        action="store_true",
        help="publish geometry_msgs/TwistStamped (stamped with the frame decided on) instead of Twist (ROS parameter ~stamped)",
    )
    p.add_argument("--rate", type=finite_float, help="commands per second between decisions (ROS parameter ~rate; default 20)")
    p.add_argument(
        "--path-file",
        help="waypoints (YAML: a list, a mapping with waypoints, or a scenario such as terrapref route writes) of "
        "the reference path in the odometry frame, instead of the path topic (ROS parameter ~path_file)",
    )
    p.add_argument("--cmd-topic", help="where to publish the command (ROS parameter ~cmd_topic; default: the robot file's command topic)")
    add_live_args(p, "stamped with the frames' ROS times")
    p.set_defaults(func=_cmd_ros1)


def _cmd_ros2(args: argparse.Namespace) -> int:
    from terrapref.extras import check

    check("ros2", "terrapref ros2")  # before the model is read
    from terrapref.interop.ros2 import run_node

    options = _node_options(args)
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
    p.add_argument(
        "--stamped",
        action="store_true",
        help="publish geometry_msgs/TwistStamped (stamped with the frame decided on; Jazzy's Nav2 default) instead of Twist "
        "(ROS parameter stamped)",
    )
    p.add_argument("--rate", type=finite_float, help="commands per second between decisions (ROS parameter rate; default 20)")
    p.add_argument(
        "--path-file",
        help="waypoints (YAML: a list, a mapping with waypoints, or a scenario such as terrapref route writes) of "
        "the reference path in the odometry frame, instead of the path topic (ROS parameter path_file)",
    )
    p.add_argument("--cmd-topic", help="where to publish the command (ROS parameter cmd_topic; default: the robot file's command topic)")
    add_live_args(p, "stamped with the frames' ROS times")
    p.add_argument(
        "--ros-args",
        nargs=argparse.REMAINDER,
        metavar="ARG",
        help="ROS 2's arguments, last: -p NAME:=VALUE (stamped, rate, path_file, cmd_topic, hold_s, watchdog_s, use_sim_time, silent_s; the robot's "
        "limits; the rules' settings as RULE.NAME, e.g. offset.switch_margin, docs/robot.md) and "
        "-r FROM:=TO (topics; __node, __ns); ROS_DOMAIN_ID picks the domain",
    )
    p.set_defaults(func=_cmd_ros2)


def _cmd_play(args: argparse.Namespace) -> int:
    from terrapref.extras import check

    check("ros2", "terrapref play")
    from terrapref.interop.dds import domain_id
    from terrapref.interop.play import BagPlayer, RobotTopics
    from terrapref.interop.robot import load_robot_topics
    from terrapref.interop.ros2 import interruptible
    from terrapref.progress import Progress

    if not 0.01 <= args.rate <= 100:
        raise UserError("--rate", f"expected a factor in [0.01, 100], got {args.rate:g}")
    if not 1 <= args.clock <= 1000:
        raise UserError("--clock", f"expected a rate in [1, 1000] Hz, got {args.clock:g}")
    if not 0 <= args.delay <= 60:
        raise UserError("--delay", f"expected [0, 60] s, got {args.delay:g}")
    if not 1 <= args.max_gap <= 1e9:
        raise UserError("--max-gap", f"expected [1, 1e9] s of log, got {args.max_gap:g}")
    domain = domain_id()
    robot = RobotTopics(args.robot, load_robot_topics(args.robot)) if args.robot else None  # what the node reads, and the transforms
    player = BagPlayer(args.bag, domain, set(args.topics) if args.topics else None, robot)
    first, last = player.span_ns
    span_s = (last - first) * 1e-9
    print(
        f"playing {args.bag} in ROS_DOMAIN_ID {domain}: {', '.join(sorted({t for t, _ in player.writers}))} and /clock, "
        f"{span_s:.1f} s of log at {args.rate:g}x",
        flush=True,
    )
    bar = Progress("play", span_s, "s")
    ended = False
    try:
        with interruptible():  # Ctrl-C ends it even where it was started with SIGINT ignored (a script's background job)
            player.play(
                rate=args.rate,
                clock_hz=args.clock,
                delay_s=args.delay,
                progress=lambda ns: bar.update(ns * 1e-9, f"{ns * 1e-9:.1f} of {span_s:.1f} s"),
                max_gap_s=args.max_gap,
                log=lambda line: print(f"play: {line}", flush=True),
            )
        ended = True
    finally:  # stopped (Ctrl-C, a damaged log) or not: what was published
        bar.close(f"{player.published} messages published" + ("" if ended else ", then stopped"))
        player.close()
    skipped = f" ({player.skipped_s:.1f} s of gaps longer than --max-gap skipped)" if player.skipped_s else ""
    print(f"played {player.published} messages on {len(player.writers)} topics and /clock: {span_s:.1f} s of {args.bag}{skipped}")
    return 0


def play_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("play", help="publish a ROS 2 bag or MCAP on ROS 2 topics with /clock, as ros2 bag play --clock (the ros2 extra)")
    p.add_argument("bag", help="a ROS 2 bag folder or .mcap file (terrapref export --format mcap writes one)")
    p.add_argument(
        "--robot",
        help="play only what this robot file's node reads (image, camera_info, odometry, path, depth) and /tf, /tf_static, "
        "so that the log's own commands and markers stay off the node's topics",
    )
    p.add_argument("--topics", nargs="+", metavar="TOPIC", help="play only these topics (with --robot: these as well)")
    p.add_argument("--rate", type=finite_float, default=1.0, help="speed factor over the log's own pace (default 1)")
    p.add_argument("--clock", type=finite_float, default=40.0, help="/clock messages per second (default 40, as ros2 bag play --clock)")
    p.add_argument(
        "--delay",
        type=finite_float,
        default=1.0,
        help="seconds between joining the domain and the first message, for subscribers to discover the topics (default 1)",
    )
    p.add_argument(
        "--max-gap",
        type=finite_float,
        default=5.0,
        help="a stretch of the log without a message longer than this many seconds is played as this long, the clock "
        "jumping over the rest, as rosbag play --skip-empty does (default 5)",
    )
    p.set_defaults(func=_cmd_play)


def _cmd_route(args: argparse.Namespace) -> int:
    from terrapref.planner.model import Model
    from terrapref.planner.route import RouteConfig, RouteError, route_over, routed_scenario
    from terrapref.plots import save_map
    from terrapref.scenario import resolve_scenario
    from terrapref.world import rasterise
    from terrapref.yamlio import dump_yaml

    out, figure = Path(args.out), Path(args.out).with_suffix(".png")
    for path in (out, figure):
        check_output(path, "--out", [args.scenario, args.model], force=args.force)
    if out.suffix.lower() not in (".yaml", ".yml"):
        raise UserError(str(out), "the route is written as a scenario file: give it the suffix .yaml", field="--out")
    if not (math.isfinite(args.resolution) and 0.1 <= args.resolution <= 2.0):
        raise UserError("--resolution", f"expected a cell size in [0.1, 2] m, got {args.resolution}")
    model = Model.load(args.model)
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
    text = dump_yaml(routed_scenario(scenario, route, Path(args.model).name), sort_keys=False, default_flow_style=None, width=120)
    write_text_atomic(
        out,
        "# terrapref route: a scenario whose path is the route; every command that takes a scenario takes it,\n"
        "# and terrapref ros1 --path-file reads its waypoints.\n" + text,
    )
    save_map(
        figure,
        scenario,
        world,
        tracks=[("route", route.waypoints, "tab:blue")],
        title=f"{scenario.name}: route priced by {Path(args.model).name}",
    )
    blocked = "lethal terrain or ground past the vehicle's limits" if world.has_relief else "lethal terrain"
    along = f"meets {blocked}" if not math.isfinite(route.along_path_cost) else f"{route.along_path_cost:.1f}"
    print(
        f"route: {route.length_m:.1f} m (path {scenario.path_length_m():.1f} m), up to {route.max_offset_m:.1f} m from the path; "
        f"price {route.cost:.1f} (the path itself: {along}); searched in {route.cell_m:g} m cells"
    )
    flag = f" --classes {args.classes}" if args.classes else ""
    print(f"wrote {out} (the scenario with the route as its path: terrapref evaluate {args.model} {out}{flag}) and {figure}")
    return 0


def route_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "route",
        help="plan a global route over a scenario's map, priced with a model's learned preference, as waypoints the planner follows",
    )
    p.add_argument(
        "scenario",
        help="the course (packaged name, file, gen:N or genrelief:N): its terrain (and relief) stands in for a prior map such as "
        "labelled aerial imagery",
    )
    p.add_argument(
        "--model", required=True, help="a model with an offset rule (recipe teach): its class prices and price of leaving the path"
    )
    p.add_argument(
        "--out",
        type=output_path,
        required=True,
        help="the scenario with the route as its path (.yaml); a figure is written beside it (.png)",
    )
    p.add_argument(
        "--resolution",
        type=finite_float,
        default=0.25,
        help="search cell size [m], 0.1-2, taken as the nearest whole multiple of the map's cells (default 0.25)",
    )
    add_classes_arg(p, check=True)  # the scenario is read with the model's table
    add_force_arg(p)
    p.set_defaults(func=_cmd_route)
