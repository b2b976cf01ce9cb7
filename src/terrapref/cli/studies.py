"""Commands that train and drive many models: reproduce, study, select."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from terrapref.cli.common import (
    PERCEPTION_HELP,
    add_classes_arg,
    add_engine_args,
    add_force_arg,
    add_large_arg,
    announce_workload,
    check_run_folder,
    check_table,
    given_files,
    grid_engine,
    output_path,
    perception_list,
    perception_model,
    teachable_table,
)
from terrapref.errors import UserError
from terrapref.fileio import output_folder

if TYPE_CHECKING:
    from terrapref.grid import Engine
    from terrapref.terrain import ClassTable


def _cmd_reproduce(args: argparse.Namespace) -> int:
    import time

    from terrapref.recipes import recipe_named
    from terrapref.report.reproduce import Reproduction, reproduce, reproduction_workload
    from terrapref.terrain import PreferenceProfile

    if args.seeds < 1:
        raise UserError("--seeds", "must be >= 1")
    if args.eval_seeds < 1:
        raise UserError("--eval-seeds", "must be >= 1")
    profile = PreferenceProfile.parse(args.profile) if args.profile is not None else None
    names = [n.strip() for n in args.recipes.split(",")]
    if not all(names) or len(set(names)) != len(names):  # an empty item, as --orders and --perception refuse one
        raise UserError("--recipes", f"expected distinct recipe names separated by commas, got {args.recipes!r}")
    recipes = tuple(recipe_named(n, "--recipes") for n in names)
    perceptions = perception_list(args.perception)
    check_run_folder(args.out, given_files(args, "classes", "perception", "taught_under", "course"))
    engine = grid_engine(args)
    setup = Reproduction(
        recipes,
        args.seeds,
        args.eval_seeds,
        profile or PreferenceProfile.default(),
        args.write_recordings,
        perceptions,
        speed_seeds=min(2, args.seeds),
        relief_seeds=1,
    )
    announce_workload(
        "reproduce",
        reproduction_workload(setup),
        engine,
        args.large,
        "--seeds, --eval-seeds, --recipes",
        "seeds, evaluation seeds or recipes",
    )
    with output_folder(args.out, args.force):
        t0 = time.perf_counter()
        report = reproduce(args.out, setup, engine, log=lambda m: print(m, flush=True))
        print(f"wrote {report} ({time.perf_counter() - t0:.0f} s)")
        return 0


def reproduce_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("reproduce", help="demonstrate, train and evaluate end to end; write REPORT.md with Tables 1 and 2")
    p.add_argument("--out", required=True, type=output_path, help="folder for REPORT.md, its figures and the work")
    p.add_argument("--seeds", type=int, default=5, help="training seeds per recipe (default 5)")
    p.add_argument("--eval-seeds", type=int, default=1, help="evaluation runs per model and scenario (default 1)")
    p.add_argument(
        "--recipes",
        default="paper,ours,teach",
        help="recipes to compare, by name, separated by commas (default: paper,ours,teach; see `terrapref recipes`)",
    )
    p.add_argument("--profile", help="preference order for the demonstrations, best first")
    p.add_argument(
        "--write-recordings",
        action="store_true",
        help="also write the synthetic driver's demonstrations as recordings in OUT/work (they are featurised as they are driven)",
    )
    p.add_argument(
        "--perception",
        default="clean,rellis,field",
        metavar="P1,P2,...",
        help="perception models (presets or files, separated by commas) every recipe's models drive the test courses under, "
        "for the report's table of what a robot sees (default: clean,rellis,field)",
    )
    add_large_arg(p, "reproduce")
    add_engine_args(p)
    add_force_arg(p)
    p.set_defaults(func=_cmd_reproduce)


def _cmd_study(args: argparse.Namespace) -> int:
    import time
    from dataclasses import replace

    from terrapref.extras import check
    from terrapref.report.study import run_study, study_workload
    from terrapref.report.study_plan import FULL, QUICK, for_table, with_perception
    from terrapref.terrain import default_classes

    check("cnn", "terrapref study (its end-to-end CNN baseline)")  # before the steps that come before the CNN's
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
    check_run_folder(args.out, given_files(args, "classes", "perception", "taught_under", "course"))
    engine = grid_engine(args)
    announce_workload("study", study_workload(plan), engine, args.large, "--seeds", "seeds")
    with output_folder(args.out, args.force):
        t0 = time.perf_counter()
        path = run_study(args.out, plan, engine, log=lambda m: print(m, flush=True))
        print(f"wrote {path} ({time.perf_counter() - t0:.0f} s)")
        return 0


def study_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("study", help="baselines, data efficiency, profiles, robustness and ablations; write STUDY.md")
    p.add_argument("--out", required=True, type=output_path, help="folder for STUDY.md, its figures and the work")
    p.add_argument("--quick", action="store_true", help="one seed and fewer levels (its time: docs/benchmarks.md)")
    p.add_argument("--seeds", type=int, help="training seeds (default: 3, or 1 with --quick)")
    p.add_argument("--recipe", metavar="NAME", help="the recipe section 6 teaches every order and style with (default: teach)")
    add_classes_arg(p)
    p.add_argument(
        "--perception",
        metavar="LIST",
        help="comma-separated perception presets or files the taught models also drive under; the last that perturbs anything is swept part by part "
        "(default: clean,rellis,field, or clean,field with --quick; with --classes: clean, unless files for the table are given)",
    )
    p.add_argument(
        "--follow-up",
        action="store_true",
        help="each teaching drive is followed by a drive of the course of what it left open, and the model learns from both",
    )
    add_large_arg(p, "study")
    add_engine_args(p)
    add_force_arg(p)
    p.set_defaults(func=_cmd_study)


def _select_speeds(text: str | None, table) -> str | None:
    """``--speeds`` checked before any work: ``random``, or cruising speeds by class of the table."""
    if text is None or text == "random":
        return text
    from terrapref.demos.speed_style import driver_style, parse_speeds
    from terrapref.terrain import default_classes
    from terrapref.vehicle import VehicleConfig

    classes = table or default_classes()
    driver_style("default", classes.profile, classes, VehicleConfig().max_speed_mps, {"speeds": parse_speeds(text)})
    return text


def _cmd_select(args: argparse.Namespace) -> int:
    import time

    from terrapref.demos.expert import STYLES
    from terrapref.demos.speed_style import names_style_file
    from terrapref.recipes import recipe_named
    from terrapref.report.select import Selection, run_selection

    names = [n.strip() for n in args.recipes.split(",")]
    if not all(names) or len(set(names)) != len(names):  # an empty item, as --orders and --perception refuse one
        raise UserError("--recipes", f"expected distinct recipe names separated by commas, got {args.recipes!r}")
    for n in names:
        recipe_named(n, "--recipes")
    table = teachable_table(args)
    if args.style not in STYLES and names_style_file(args.style):
        raise UserError(
            "--style", f"{args.style}: select takes a preset ({', '.join(STYLES.names())}); a style file is for record and evaluate"
        )
    STYLES.get(args.style, "--style")
    _check_select_sizes(args)
    check_run_folder(args.out, given_files(args, "classes", "perception", "taught_under", "course"))
    perceptions = perception_list("clean" if args.perception is None else args.perception, table)
    if args.taught_under == "same" and len(perceptions) != 1:
        raise UserError("--taught-under", "'same' needs exactly one --perception model")
    taught_under = perceptions[0] if args.taught_under == "same" else perception_model(args.taught_under, "--taught-under", table)
    speeds = _select_speeds(args.speeds, table)
    relief_styles = _select_relief_styles(args.relief_style)
    engine = grid_engine(args)
    named = args.orders != "all" and not args.orders.startswith("random:")  # orders named one by one: read before the plan is said
    orders = _orders(args.orders, table) if named else None
    if args.course is not None:  # checked before any work, and before the plan is said: one of another table too
        from terrapref.scenario import resolve_scenario

        check_table(args, resolve_scenario(args.course, table).classes, args.course)
    _announce_size(args, len(names), table, len(perceptions), engine, len(relief_styles))
    orders = orders or _orders(args.orders, table)  # all or random:N, counted before they are drawn
    with output_folder(args.out, args.force):
        course = _selection_course(args, table, bool(relief_styles))
        t0 = time.perf_counter()
        selection = Selection(
            tuple(names),
            orders,
            args.seeds,
            args.first,
            args.courses,
            args.style,
            perceptions,
            taught_under,
            table,
            course,
            args.follow_up,
            speeds,
            relief_styles,
        )
        path = run_selection(args.out, selection, engine, log=lambda m: print(m, flush=True))
        print(f"done ({time.perf_counter() - t0:.0f} s): {path}")
        return 0


def _check_select_sizes(args: argparse.Namespace) -> None:
    """``--seeds``, ``--courses`` and ``--first`` checked before any work, the last layout's seed among them."""
    for flag, value, low in (("--seeds", args.seeds, 1), ("--courses", args.courses, 1), ("--first", args.first, 0)):
        if value < low:
            raise UserError(flag, f"must be an integer >= {low}, got {value}")
    if args.first + args.courses > 2**63:  # a generated layout's seed
        raise UserError("--first", f"the last layout would be gen:{args.first + args.courses - 1}; a layout's seed is at most 2^63 - 1")


def _select_relief_styles(text: str | None) -> tuple[str, ...]:
    """``--relief-style`` checked before any work: relief styles as record takes them, separated by ';'
    (none given: flat), no two of them the same style (``default`` and ``roll_deg=12``: the default's roll)."""
    if text is None:
        return ()
    from terrapref.demos.relief_style import parse_relief_style
    from terrapref.demos.speed_style import check_rough_speed
    from terrapref.vehicle import VehicleConfig

    styles = tuple(t.strip() for t in text.split(";"))
    if not all(styles) or len(set(styles)) != len(styles):
        raise UserError("--relief-style", f"expected distinct relief styles separated by ';', got {text!r}")
    seen: dict[object, str] = {}
    for style in styles:
        parsed = parse_relief_style(style)[1]
        check_rough_speed(parsed, VehicleConfig().max_speed_mps)
        if parsed in seen:
            raise UserError(
                "--relief-style", f"{seen[parsed]!r} and {style!r} are the same relief style: each would teach the same models twice"
            )
        seen[parsed] = style
    return styles


def _orders(text: str, table: ClassTable | None) -> tuple[tuple[str, ...], ...]:
    """The orders ``--orders`` names (terrapref.report.select.parse_orders), each a preference
    order of the table's classes, none twice; a UserError naming the flag."""
    from terrapref.report.select import parse_orders
    from terrapref.terrain import PreferenceProfile

    try:
        orders = parse_orders(text, table)
    except ValueError as exc:
        raise UserError("--orders", str(exc)) from None
    for o in orders:
        PreferenceProfile.parse(list(o), table, source="--orders")
    if len(set(orders)) != len(orders):
        raise UserError("--orders", f"names an order twice: {text!r}")
    return orders


def _announce_size(
    args: argparse.Namespace, recipes: int, table: ClassTable | None, perceptions: int, engine: Engine, relief_styles: int = 0
) -> None:
    """Print at once how many models and runs the selection makes and about how long they take,
    counted without drawing or listing the orders; refuse one beyond the bound unless --large."""
    from terrapref.report.select import SelectionSize, count_orders

    try:
        orders = count_orders(args.orders, table)
    except ValueError as exc:
        raise UserError("--orders", str(exc)) from None
    size = SelectionSize.of(recipes, orders, args.seeds, args.courses, perceptions, args.speeds == "random").with_relief(relief_styles)
    announce_workload("select", size.workload, engine, args.large, "--orders, --seeds, --courses", "orders (random:N), seeds or layouts")


def _selection_course(args: argparse.Namespace, table, relief: bool = False) -> str | None:
    """The course every recipe demonstrates in ``select``: ``--course``, or with ``--classes`` the
    table's teaching course (written into OUT); None: each recipe's own. With ``relief``, the
    teaching course with relief: ``teach_relief``, or the table's (as ``course --relief 0`` writes it)."""
    if args.course is not None:  # read before the plan was said
        return str(Path(args.course).resolve()) if Path(args.course).exists() else args.course
    if table is None:
        return "teach_relief" if relief else None
    from terrapref.scenario.teaching import write_teaching_course

    return str(write_teaching_course(args.out, table, relief))


def select_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "select", help="compare recipes: train each for every order and seed, drive generated layouts, report agreement with the driver"
    )
    p.add_argument("--out", required=True, type=output_path, help="folder for SELECT.md, select.json, select.png and the work")
    p.add_argument("--recipes", default="teach", help="recipe names separated by commas (terrapref recipes; default: teach)")
    p.add_argument(
        "--orders",
        default="all",
        help="'all' (every order of the feature classes, the lethal ones last: six for the default table), 'random:N' (N of them "
        "drawn at random, the same N every time) or orders separated by ';', e.g. 'rock,mud,water;water,mud,rock' (default: all)",
    )
    _add_select_driver_args(p)
    p.add_argument("--seeds", type=int, default=5, help="training seeds per recipe and order (default: 5)")
    p.add_argument(
        "--first", type=int, default=1000, help="first generated layout (1000-1999: for choosing; 2000 on: for confirming; default: 1000)"
    )
    p.add_argument("--courses", type=int, default=32, help="generated layouts (default: 32)")
    p.add_argument(
        "--perception",
        metavar="P1,P2,...",
        help="perception models (presets, files or NAME:PART, separated by commas) the models drive the layouts under, each "
        "in turn, for a table each (default: clean): " + PERCEPTION_HELP,
    )
    p.add_argument(
        "--taught-under",
        metavar="PRESET|FILE|same",
        default=None,
        help="record the demonstrations through this perception model instead of the truth ('same': --perception's)",
    )
    p.add_argument(
        "--course",
        metavar="SCENARIO",
        help="the course every recipe demonstrates (default: each recipe's own; with --classes, "
        "the table's teaching course, as terrapref course writes it)",
    )
    p.add_argument(
        "--follow-up",
        action="store_true",
        help="after each demonstration, the driver also drives a follow-up course of the pairs it left unidentified "
        "(terrapref course --after), and the model trains on both",
    )
    add_large_arg(p, "select")
    add_classes_arg(p)
    add_engine_args(p)
    add_force_arg(p)
    p.set_defaults(func=_cmd_select)


def _add_select_driver_args(p: argparse.ArgumentParser) -> None:
    """``select``'s flags of the synthetic drivers: their style, speeds and relief styles."""
    p.add_argument("--style", default="default", help="the synthetic driver's style (default: default; terrapref record --help lists them)")
    p.add_argument(
        "--speeds",
        metavar="random|CLASS=MPS,...",
        help="the driver's cruising speeds: drawn for each order and seed (random), or given by class; SELECT.md then "
        "reports the planner's speed against its driver's",
    )
    p.add_argument(
        "--relief-style",
        metavar="STYLE;STYLE...",
        help="relief styles, as record takes them, separated by ';' (e.g. 'default;bold;cautious'): each order and seed's driver "
        "drives with each in turn, demonstrating the relief teaching course (teach_relief, or the table's with relief), and the "
        "models and drivers drive the same layouts with relief (genrelief:N); SELECT.md adds the relief zones and the speed by "
        "grade band and by roughness band (default: none, flat layouts)",
    )
