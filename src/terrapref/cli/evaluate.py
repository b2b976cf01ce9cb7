"""Commands that score a model: evaluate, perception."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from terrapref.cli.common import (
    PERCEPTION_HELP,
    SCENARIO_HELP,
    add_classes_arg,
    add_engine_args,
    add_force_arg,
    add_live_args,
    check_run_folder,
    check_table,
    class_table,
    counted,
    grid_engine,
    live_view,
    output_path,
    perception_model,
    watching,
)
from terrapref.errors import UserError
from terrapref.fileio import check_distinct, output_folder

if TYPE_CHECKING:
    from terrapref.evaluation.evaluate import Evaluation
    from terrapref.evaluation.speed import TrainedDriver


def _checked_runs(args: argparse.Namespace) -> int:
    """The closed-loop runs ``evaluate`` makes (each scenario and seed once, twice with the
    driver); more than a command runs unasked (:data:`LARGE_RUNS`, as ``select`` and ``study``
    bound theirs) are refused, before anything is read or written."""
    from terrapref.report.workload import LARGE_RUNS

    runs = len(args.scenarios) * args.seeds * (1 if args.no_driver else 2)
    if runs > LARGE_RUNS:
        raise UserError("--seeds", f"{args.seeds:,} seeds make {runs:,} runs, more than {LARGE_RUNS:,}: name fewer seeds or scenarios")
    return runs


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from terrapref.evaluation.evaluate import evaluate_model
    from terrapref.progress import Progress

    if args.seeds < 1:
        raise UserError("--seeds", "must be >= 1")
    runs = _checked_runs(args)
    check_distinct(args.scenarios, "scenario")
    check_run_folder(args.out, [args.model, *args.scenarios])
    engine = grid_engine(args)
    if args.mcap:
        from terrapref.extras import check

        check("robot", "--mcap", "rosbags")  # before the runs, not after them
    evaluation = _evaluation(args)  # every input checked before the first run
    with output_folder(args.out, args.force):
        bar = Progress("evaluate", runs)
        courses = f"{len(args.scenarios)} course{'s' if len(args.scenarios) > 1 else ''}"
        # Once the runs are done the bar says what follows: the figures take a few seconds a course.
        ran = counted(bar, "runs", f"{runs} run{'s' if runs > 1 else ''} done; scoring and drawing the figures of {courses} ...")
        view = live_view(args)
        try:
            metrics = evaluate_model(evaluation, args.out, engine, progress=ran, watch=watching(view))
        finally:
            if view is not None:
                view.stop()
        bar.close()
        _print_results(evaluation, metrics, args)
        return 0


def _evaluation(args: argparse.Namespace) -> Evaluation:
    """What ``evaluate`` runs, from its flags, each checked (the frames before the model is read;
    the driver's speeds against the model's table and the vehicle)."""
    from terrapref.demos.expert import STYLES
    from terrapref.demos.relief_style import parse_relief_style
    from terrapref.demos.speed_style import check_rough_speed, driver_style, parse_speeds
    from terrapref.evaluation.evaluate import Evaluation, scoring_profile
    from terrapref.evaluation.speed import relief_styles_differ, trained_driver, trained_relief
    from terrapref.planner.model import Model
    from terrapref.terrain import PreferenceProfile
    from terrapref.vehicle import VehicleConfig

    if args.no_driver:  # the flags that set the comparison driver set nothing without one
        for flag, value in (("--style", args.style), ("--speeds", args.speeds), ("--relief-style", args.relief_style)):
            if value is not None:
                raise UserError(flag, "sets the driver the planner is compared with, which --no-driver leaves out")
    try:
        frames = sorted({int(f) for f in args.frames.split(",") if f.strip()}) if args.frames else []
    except ValueError:
        raise UserError("--frames", f"expected comma-separated frame numbers, got {args.frames!r}") from None
    _check_frames(frames, args.scenarios, class_table(args))  # before the model is read
    model = Model.load(args.model).policy  # C, or a learned baseline's file (linear, CNN)
    if args.classes is not None:  # the model carries its table (the scenarios are read with it); --classes must be it
        check_table(args, model.classes, args.model)
    profile = PreferenceProfile.parse(args.profile, model.classes) if args.profile is not None else None
    scored = scoring_profile(model, profile, args.model)  # a model whose drives declared no order needs one, before any run
    perception = perception_model(args.perception, classes=model.classes)
    given = parse_speeds(args.speeds) if args.speeds is not None else ()
    meta = getattr(getattr(model, "model", None), "meta", {})
    style, speeds, changes = _driver_of(args.style, given, trained_driver(meta))
    relief = parse_relief_style(args.relief_style)[1] if args.relief_style is not None else trained_relief(meta, args.model)
    if args.relief_style is not None and relief is not None:
        _note_flat(args.scenarios, model.classes)
    if args.relief_style is None and relief is None and relief_styles_differ(meta):
        print(
            f"note: {args.model}: its recordings' drivers took relief by different styles (or some as if flat); the comparison "
            "driver takes it as if flat: give --relief-style",
            file=sys.stderr,
        )
    top_mps = VehicleConfig().max_speed_mps  # the vehicle the runs drive
    if args.relief_style is not None:
        check_rough_speed(relief, top_mps)
    STYLES.get(style, "--style")
    # Checked against the model's table and the vehicle before any run (the trained driver's were when it drove).
    if given or args.style is not None:
        driver_style(args.style or style, scored.order, model.classes, top_mps, {"speeds": given} if given else None)
    return Evaluation(
        args.model,
        tuple(args.scenarios),
        args.seeds,
        profile=profile,
        with_driver=not args.no_driver,
        style=style,
        speeds=speeds,
        driver_changes=changes,
        frames=tuple(frames),
        mcap=args.mcap,
        perception=perception,
        relief=relief,
    )


def _print_results(evaluation: Evaluation, metrics: dict, args: argparse.Namespace) -> None:
    """What ``evaluate`` prints of its metrics: the planner's zones, driving and agreement, the
    speed against the driver, the driver's zones, and notes."""
    from terrapref.evaluation.runner import Summary
    from terrapref.evaluation.speed import SpeedComparison
    from terrapref.evaluation.stats import rate_text

    perception = evaluation.perception
    if perception is not None and perception.active:
        print(f"perception: {perception.name} ({perception.summary()}); the driver sees the truth")
    zones = [z for sc in metrics["scenarios"].values() for run in sc.get("planner", {}).values() for z in run["zones"]]
    s = metrics["summary"]
    incidents = f", {s['tip_count']} tips, {s['stuck_count']} stuck" if s.get("tip_count") or s.get("stuck_count") else ""
    print(f"planner: zone success {rate_text(sum(z['success'] for z in zones), len(zones))}, {s['collision_count']} collisions{incidents}")
    for line in Summary.from_dict(s).driving_lines():
        print(f"planner: {line}")
    compared = [z for z in zones if "agrees" in z]
    if compared:
        driver = evaluation.style + "".join(f", {name} {v:g} m/s" for name, v in evaluation.speeds)
        if evaluation.relief is not None:
            driver += f", relief: {evaluation.relief.describe()}"
        print(f"planner: agreement with the driver ({driver}) {rate_text(sum(z['agrees'] for z in compared), len(compared))}")
    relief = [z for sc in metrics["scenarios"].values() for run in sc.get("planner", {}).values() for z in run.get("relief_zones", ())]
    relief = [z for z in relief if "agrees" in z]
    if relief:
        both = [z["agrees"] for z in compared] + [z["agrees"] for z in relief]
        print(
            f"planner: agreement with the driver on relief zones (over, or round on the same side) "
            f"{rate_text(sum(z['agrees'] for z in relief), len(relief))}; on terrain and relief zones {rate_text(sum(both), len(both))}"
        )
    if "speed" in metrics:
        for line in SpeedComparison.from_dict(metrics["speed"]).lines():
            print(f"planner: {line}")
    if "driver_summary" in metrics:
        d = metrics["driver_summary"]
        success = f"{d['zone_success_rate']:.1%}" if d["zones"] else "-"
        incidents = f", {d['tip_count']} tips, {d['stuck_count']} stuck" if d.get("tip_count") or d.get("stuck_count") else ""
        print(f"driver:  zone success {success} over {d['zones']} zones, {d['collision_count']} collisions{incidents}")
    for name, numbers in metrics.get("frames_beyond_the_run", {}).items():
        print(f"note: --frames {','.join(map(str, numbers))}: {name}'s run (seed 0) ended before them; no picture", file=sys.stderr)
    guesses = [z for z in zones if z.get("rests_on_unidentified")]
    if metrics.get("unidentified_pairs") and guesses:  # a pair no zone here turns on changes nothing of these runs
        print(
            f"note: the model's demonstrations did not identify {', '.join(metrics['unidentified_pairs'])}; "
            f"{len(guesses)} of {len(zones)} zone runs rest on them (marked in metrics.json)"
        )
    print(
        f"wrote {Path(args.out) / 'metrics.json'} and figures in {args.out}"
        + (f"; runs as MCAP in {Path(args.out) / 'runs'}" if args.mcap else "")
    )


def _driver_of(
    style: str | None, given: tuple[tuple[str, float], ...], trained: TrainedDriver | None
) -> tuple[str, tuple[tuple[str, float], ...], tuple[tuple[str, Any], ...]]:
    """The comparison driver's style (a preset), speeds by class and other fields over the
    style's: without ``--style``, the model's own synthetic driver (``trained``) where it has
    one, the classes ``--speeds`` names (``given``) changed and the others kept; else the style
    given (or the default; a style file: its preset and what it changes) with the speeds given."""
    from terrapref.demos.expert import STYLES
    from terrapref.demos.speed_style import names_style_file, read_style_file

    if style is None and trained is not None:
        return trained[0], tuple({**dict(trained[1]), **dict(given)}.items()), trained[2]
    if style is None or style in STYLES.names():
        return style or "default", given, ()
    if not names_style_file(style):
        STYLES.get(style, "--style")  # neither a preset nor a file: refused, naming the presets
    base, changes = read_style_file(style)
    speeds = tuple({**dict(changes.pop("speeds", ())), **dict(given)}.items())
    return base, speeds, tuple(changes.items())


def _note_flat(scenarios: Sequence[str], classes) -> None:
    """Say so where ``--relief-style`` is given for courses that are all flat (as record does)."""
    from terrapref.scenario import resolve_scenario

    for name in scenarios:
        try:
            if resolve_scenario(name, classes).has_relief:
                return
        except UserError:  # read with the runs, which say what is wrong with it
            return
    print(f"note: {', '.join(scenarios)}: flat, so the driver's relief style changes no run", file=sys.stderr)


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


def evaluate_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("evaluate", help="drive scenarios with a model, score every zone, write metrics.json and figures")
    p.add_argument("model", metavar="MODEL", help="a model file from train (or a learned baseline's)")
    p.add_argument("scenarios", nargs="+", metavar="SCENARIO", help=SCENARIO_HELP)
    p.add_argument(
        "--seeds",
        type=int,
        default=3,
        help="runs per scenario (default 3): seed 0 starts at the scenario's start, the others up to 0.3 m and 3 degrees off it",
    )
    p.add_argument("--out", required=True, type=output_path, help="folder for metrics.json and the figures")
    p.add_argument(
        "--profile",
        help="resolve `best` zones, and drive the synthetic driver, under this order instead of the model's "
        "(needed for a model whose drives declared none)",
    )
    p.add_argument("--frames", help="comma-separated frame numbers of seed 0 to draw as decision pictures")
    p.add_argument("--no-driver", action="store_true", help="skip the synthetic driver's comparison runs")
    p.add_argument(
        "--style",
        help="the synthetic driver's style for the comparison runs (agreement, speed; default: the style and speeds of the "
        "synthetic driver the model was trained from, else default), or a terrapref-driver-style/1 file",
    )
    p.add_argument(
        "--speeds",
        metavar="CLASS=MPS,...",
        help="cruising speeds by class, e.g. grass=1.2: the comparison driver's classes named change, the others keep its speeds",
    )
    p.add_argument(
        "--relief-style",
        metavar="NAME[,K=V,...]",
        help="the comparison driver's relief style, as record takes it, or none: relief driven as if it were flat (default: that "
        "of the synthetic driver the model was trained from, none where it had none)",
    )
    add_engine_args(p)
    p.add_argument("--mcap", action="store_true", help="also write each planner run as ROS 2 MCAP in OUT/runs (Foxglove, RViz)")
    p.add_argument("--perception", metavar="PRESET|FILE", help=PERCEPTION_HELP + " (default: clean); the driver always sees the truth")
    add_live_args(p, "the runs go one after another in this process", paced=True)
    add_classes_arg(p, check=True)  # the scenarios and gen:N are read with the model's table
    add_force_arg(p)
    p.set_defaults(func=_cmd_evaluate)


def _cmd_perception(args: argparse.Namespace) -> int:
    from terrapref.perception import PRESETS, load_perception
    from terrapref.yamlio import dump_yaml

    if not args.models:
        for name in PRESETS:
            model = load_perception(name)
            print(f"{name}: {model.summary()}")
        print(
            "(terrapref perception NAME|FILE prints one in full; --perception takes a preset, a file, or NAME:PART "
            "for one part alone: labels, pose, camera, frames or depth)"
        )
        return 0
    for i, spec in enumerate(args.models):
        model = load_perception(spec, class_table(args))
        if i:
            print("---")
        print(f"# {model.name} as a terrapref-perception/1 file: save it, edit any field, give it to --perception FILE")
        print(dump_yaml(model.file_dict(), sort_keys=False, default_flow_style=None).rstrip())
    return 0


def perception_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "perception", help="list the perception presets (what a robot's planner gets instead of the truth), or print one in full"
    )
    p.add_argument("models", nargs="*", metavar="PRESET|FILE", help="print these in full (checked as --perception checks them)")
    add_classes_arg(p)
    p.set_defaults(func=_cmd_perception)
