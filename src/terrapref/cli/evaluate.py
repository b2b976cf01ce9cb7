"""Commands that drive models and report: evaluate, reproduce, study, select, perception."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from terrapref.cli.common import (
    PERCEPTION_HELP,
    SCENARIO_HELP,
    add_classes_arg,
    add_engine_args,
    add_force_arg,
    add_live_args,
    check_table,
    class_table,
    grid_engine,
    live_view,
    perception_list,
    perception_model,
    teachable_table,
    watching,
)
from terrapref.errors import UserError
from terrapref.fileio import check_distinct, check_output, output_folder


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from terrapref.evaluation.evaluate import Evaluation, evaluate_model
    from terrapref.evaluation.runner import Summary
    from terrapref.planner.registry import load_policy
    from terrapref.progress import Progress
    from terrapref.terrain import PreferenceProfile

    if args.seeds < 1:
        raise UserError("--seeds", "must be >= 1")
    check_distinct(args.scenarios, "scenario")
    check_output(args.out, "--out", [args.model, *args.scenarios], folder=True)
    engine = grid_engine(args)
    if args.mcap:
        from terrapref.extras import check

        check("robot", "--mcap", "rosbags")  # before the runs, not after them
    try:
        frames = sorted({int(f) for f in args.frames.split(",") if f.strip()}) if args.frames else []
    except ValueError:
        raise UserError("--frames", f"expected comma-separated frame numbers, got {args.frames!r}") from None
    _check_frames(frames, args.scenarios, class_table(args))  # before the model is read
    model = load_policy(args.model)  # C, or a learned baseline's file (linear, CNN)
    if args.classes is not None:  # the model carries its table (the scenarios are read with it); --classes must be it
        check_table(args, model.classes, args.model)
    profile = PreferenceProfile.parse(args.profile, model.classes) if args.profile is not None else None
    perception = perception_model(args.perception, classes=model.classes)
    from terrapref.demos.expert import STYLES
    from terrapref.evaluation.stats import rate_text

    STYLES.get(args.style, "--style")
    with output_folder(args.out, args.force):
        bar = Progress("evaluate", len(args.scenarios) * args.seeds * (1 if args.no_driver else 2))
        view = live_view(args)
        try:
            evaluation = Evaluation(args.model, tuple(args.scenarios), args.seeds, profile=profile, with_driver=not args.no_driver, style=args.style,
                                    frames=tuple(frames), mcap=args.mcap, perception=perception)
            metrics = evaluate_model(evaluation, args.out, engine, progress=lambda k, n: bar.update(k, f"{k}/{n} runs"), watch=watching(view))
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


def evaluate_parser(sub: argparse._SubParsersAction) -> None:
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
    add_engine_args(p)
    p.add_argument("--mcap", action="store_true", help="also write each planner run as ROS 2 MCAP in OUT/runs (Foxglove, RViz)")
    p.add_argument("--perception", metavar="PRESET|FILE", help=PERCEPTION_HELP + " (default: clean); the driver always sees the truth")
    add_live_args(p, "the runs go one after another in this process", paced=True)
    add_classes_arg(p, check=True)  # the scenarios and gen:N are read with the model's table
    add_force_arg(p)
    p.set_defaults(func=_cmd_evaluate)


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
    perceptions = perception_list(args.perception)
    check_output(args.out, "--out", folder=True)
    with output_folder(args.out, args.force):
        engine = grid_engine(args)
        t0 = time.perf_counter()
        setup = Reproduction(recipes, args.seeds, args.eval_seeds, profile or PreferenceProfile.default(), args.write_recordings, perceptions)
        report = reproduce(args.out, setup, engine, log=lambda m: print(m, flush=True))
        print(f"wrote {report} ({time.perf_counter() - t0:.0f} s)")
        return 0


def reproduce_parser(sub: argparse._SubParsersAction) -> None:
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
    add_engine_args(p)
    add_force_arg(p)
    p.set_defaults(func=_cmd_reproduce)


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
    table = teachable_table(args)
    if table is not None and table.same_classes(default_classes()) and table.profile == default_classes().profile:
        table = None  # the packaged table, given by its file: the default plan
    perceptions = None
    if args.perception is not None:
        perceptions = perception_list(args.perception, table)
        if not perceptions:
            raise UserError("--perception", f"names no perception model: {args.perception!r}")
    if table is not None:
        plan = for_table(plan, table, perceptions=perceptions or (), follow_up=args.follow_up)
    else:
        plan = replace(plan, follow_up=args.follow_up)
        if perceptions is not None:
            plan = with_perception(plan, perceptions)
    check_output(args.out, "--out", folder=True)
    with output_folder(args.out, args.force):
        engine = grid_engine(args)
        t0 = time.perf_counter()
        path = run_study(args.out, plan, engine, log=lambda m: print(m, flush=True))
        print(f"wrote {path} ({time.perf_counter() - t0:.0f} s)")
        return 0


def study_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("study", help="baselines, data efficiency, profiles, robustness and ablations; write STUDY.md")
    p.add_argument("--out", required=True, type=Path, help="folder for STUDY.md, its figures and the work")
    p.add_argument("--quick", action="store_true", help="one seed and fewer levels (its time: docs/benchmarks.md)")
    p.add_argument("--seeds", type=int, help="training seeds (default: 3, or 1 with --quick)")
    p.add_argument("--recipe", metavar="NAME", help="the recipe section 6 teaches every order and style with (default: teach)")
    add_classes_arg(p)
    p.add_argument("--perception", metavar="LIST",
                   help="comma-separated perception presets or files the taught models also drive under; the last that perturbs anything is swept part by part "
                        "(default: clean,rellis,field, or clean,field with --quick; with --classes: clean, unless files for the table are given)")
    p.add_argument("--follow-up", action="store_true",
                   help="each teaching drive is followed by a drive of the course of what it left open, and the model learns from both")
    add_engine_args(p)
    add_force_arg(p)
    p.set_defaults(func=_cmd_study)


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
    table = teachable_table(args)
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
    check_output(args.out, "--out", folder=True)
    perceptions = perception_list(args.perception or "clean", table)
    if args.taught_under == "same" and len(perceptions) != 1:
        raise UserError("--taught-under", "'same' needs exactly one --perception model")
    taught_under = perceptions[0] if args.taught_under == "same" else perception_model(args.taught_under, "--taught-under", table)
    with output_folder(args.out, args.force):
        engine = grid_engine(args)
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


def select_parser(sub: argparse._SubParsersAction) -> None:
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
    add_classes_arg(p)
    add_engine_args(p)
    add_force_arg(p)
    p.set_defaults(func=_cmd_select)


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
        model = load_perception(spec, class_table(args))
        if i:
            print("---")
        print(f"# {model.name} as a terrapref-perception/1 file: save it, edit any field, give it to --perception FILE")
        print(yaml.safe_dump(model.file_dict(), sort_keys=False, default_flow_style=None).rstrip())
    return 0


def perception_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("perception", help="list the perception presets (what a robot's planner gets instead of the truth), or print one in full")
    p.add_argument("models", nargs="*", metavar="PRESET|FILE", help="print these in full (checked as --perception checks them)")
    add_classes_arg(p)
    p.set_defaults(func=_cmd_perception)
