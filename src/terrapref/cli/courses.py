"""Commands on scenarios and courses: validate, render, show, course, scenarios."""

from __future__ import annotations

import argparse
import math
import re
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from terrapref.cli.common import SCENARIO_HELP, add_classes_arg, add_force_arg, check_table, class_table, output_path, warn_partial
from terrapref.configargs import finite_float
from terrapref.errors import UserError
from terrapref.fileio import check_distinct, check_distinct_outputs, check_figure, check_output, write_text_atomic

if TYPE_CHECKING:  # for the hints only: the command line imports what a command needs when it runs
    from terrapref.learning.identify import FollowUp
    from terrapref.scenario import Scenario
    from terrapref.scenario.teaching import Situation


def _cmd_validate(args: argparse.Namespace) -> int:
    from terrapref.filekinds import KINDS, check_file, template
    from terrapref.scenario import resolve_scenario
    from terrapref.vehicle.ground import drivable

    if args.template is not None:
        if args.files or args.classes is not None:
            raise UserError("--template", "prints a template of the default table's classes; give it alone, or FILEs to check")
        print(template(args.template), end="")
        return 0
    if not args.files:
        raise UserError("validate", f"give the files to check, or --template KIND ({', '.join(KINDS)}) for one to start from")
    status = 0
    table = class_table(args)
    for name in args.files:
        try:
            notes = []
            if _is_file(name):
                found, notes = check_file(name, table)
                kind = found.title
            else:  # a packaged scenario's name, or a generated layout's (gen:SEED, genrelief:SEED)
                drivable(resolve_scenario(name, table))
                kind = KINDS["scenario"].title
        except UserError as exc:
            for line in exc.lines():
                print(f"error: {line}")  # in the report's order, beside the files that are ok
            status = 2
        else:
            print(f"{name}: ok ({kind})" + "".join(f"\n  note: {note}" for note in notes))
    return status


def _is_file(name: str) -> bool:
    try:
        return Path(name).is_file()
    except OSError:  # a name the OS refuses (too long): the scenario reader says so
        return False


def validate_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "validate", help="check scenarios, class tables, perception models, robot files, label maps and driver styles (each by its format)"
    )
    p.add_argument(
        "files",
        nargs="*",
        metavar="FILE",
        help="files to check, each read as its format: field says (terrapref-scenario/1, -classes/1, -perception/1, -robot/1, "
        "-labels/1, -driver-style/1), packaged scenarios' names, or generated layouts (gen:SEED, genrelief:SEED)",
    )
    p.add_argument(
        "--template",
        metavar="KIND",
        choices=("scenario", "classes", "perception", "robot", "labels", "style"),
        help="print a commented file of this kind to start from (scenario, classes, perception, robot, labels, style): "
        "terrapref validate --template robot > robot.yaml",
    )
    add_classes_arg(p)
    p.set_defaults(func=_cmd_validate)


# Why each image render writes is a PNG, whatever its name says.
PNG_ONLY = {
    "--out": "class ids need a lossless format",
    "--depth": "millimetres need a lossless 16-bit format",
    "--preview": "its one format for the colour preview",
}


def _cmd_render(args: argparse.Namespace) -> int:
    import numpy as np

    from terrapref.camera import PinholeCamera, SegmentationRenderer
    from terrapref.pngio import depth_key, depth_preview, depth_to_millimetres, preview_with_legend, write_png_atomic
    from terrapref.scenario import MAX_YAW_DEG, resolve_scenario
    from terrapref.vehicle import Pose, Vehicle
    from terrapref.world import rasterise

    if args.pose is not None and not all(math.isfinite(v) for v in args.pose):
        raise UserError("--pose", "X, Y and YAW_DEG must be finite numbers")
    check_distinct_outputs([("--out", args.out), ("--preview", args.preview), ("--depth", args.depth)])
    check_output(args.out, "--out", [args.scenario], force=args.force)
    if args.preview:
        check_output(args.preview, "--preview", [args.scenario, args.out], force=args.force)
    if args.depth:
        check_output(args.depth, "--depth", [args.scenario, args.out, *([args.preview] if args.preview else [])], force=args.force)
    for flag, path in (("--out", args.out), ("--preview", args.preview), ("--depth", args.depth)):
        if path is not None and Path(path).suffix.lower() != ".png":
            raise UserError(str(path), f"render writes PNG ({PNG_ONLY[flag]}): give it the suffix .png", field=flag)
    scenario = resolve_scenario(args.scenario, class_table(args))
    x, y, yaw_deg = args.pose if args.pose is not None else (scenario.start[0], scenario.start[1], math.degrees(scenario.start[2]))
    camera = PinholeCamera()
    (w, h), reach = scenario.size_m, camera.config.max_range_m
    if not (-reach <= x <= w + reach and -reach <= y <= h + reach and abs(yaw_deg) <= MAX_YAW_DEG):
        raise UserError(
            "--pose",
            f"({x:g}, {y:g}, {yaw_deg:g} deg) is not a pose the camera sees {scenario.name}'s {w:g} x {h:g} m world from "
            f"(x and y within {reach:g} m of it, |yaw| <= {MAX_YAW_DEG:,.0f} deg)",
        )
    world = rasterise(scenario)
    renderer = SegmentationRenderer(camera, world)
    vehicle = Vehicle(Pose(x, y, math.radians(yaw_deg)), ground=world if world.has_relief else None)
    image, depth = (
        renderer.render_with_depth(vehicle.pose, vehicle.attitude)
        if world.has_relief or args.depth
        else (renderer.render(vehicle.pose), None)
    )
    if world.has_relief:
        a = vehicle.attitude
        print(
            f"on relief: the body at {a.z_m:.2f} m, pitch {math.degrees(a.pitch_rad):.1f} deg (nose down positive), "
            f"roll {math.degrees(a.roll_rad):.1f} deg (left side up positive){'; past its limits (tipped)' if vehicle.tipped else ''}"
        )
    write_png_atomic(args.out, image)
    print(f"wrote {args.out} ({image.shape[1]}x{image.shape[0]} class ids)")
    if args.depth:
        write_png_atomic(args.depth, depth_to_millimetres(depth))
        print(f"wrote {args.depth} (16-bit depth in millimetres along the optical axis, 0 where nothing is seen; REP 118's 16UC1)")
    if args.preview:
        preview = preview_with_legend(image, scenario.classes)
        if depth is not None:
            h = preview.shape[0]
            preview = np.concatenate([preview, depth_preview(depth, h), depth_key(depth, h)], axis=1)
        write_png_atomic(args.preview, preview)
        shown = "the image, a legend" + (" and the depth image with its scale (near light, far dark)" if depth is not None else "")
        print(f"wrote {args.preview} (colour preview: {shown})")
    return 0


def render_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("render", help="render the segmentation camera image at a pose")
    p.add_argument("scenario", metavar="SCENARIO", help=SCENARIO_HELP)
    p.add_argument("--pose", nargs=3, type=finite_float, metavar=("X", "Y", "YAW_DEG"), help="vehicle pose [m, m, deg]; default: the start")
    p.add_argument("--out", required=True, type=output_path, help="single-channel PNG of class ids")
    p.add_argument(
        "--preview", type=Path, help="also write a colour preview PNG (with the depth image beside it on relief or with --depth)"
    )
    p.add_argument("--depth", type=Path, help="also write the depth image: a 16-bit PNG of millimetres, 0 where nothing is seen")
    add_classes_arg(p)
    add_force_arg(p)
    p.set_defaults(func=_cmd_render)


def _cmd_show(args: argparse.Namespace) -> int:
    from terrapref.plots import save_map
    from terrapref.scenario import resolve_scenario
    from terrapref.world import rasterise

    check_figure(args.out, "--out")
    check_output(args.out, "--out", [args.scenario], force=args.force)
    scenario = resolve_scenario(args.scenario, class_table(args))
    save_map(args.out, scenario, rasterise(scenario))
    print(
        f"wrote {args.out} ({scenario.name}: {len(scenario.terrain)} patches, {len(scenario.zones)} zones, path {scenario.path_length_m():.0f} m)"
    )
    return 0


def show_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("show", help="draw the map top-down with the path, the start and the zones")
    p.add_argument("scenario", metavar="SCENARIO", help=SCENARIO_HELP)
    p.add_argument("--out", required=True, type=output_path, help="figure file (.png, .pdf or .svg)")
    add_classes_arg(p)
    add_force_arg(p)
    p.set_defaults(func=_cmd_show)


def _cmd_course(args: argparse.Namespace) -> int:
    from terrapref.evaluation.speed import driver_flags
    from terrapref.plots import save_map
    from terrapref.scenario import parse_scenario
    from terrapref.scenario.relief_layout import relief_for
    from terrapref.scenario.teaching import Beside, designed_course, follow_up_after, relief_course
    from terrapref.terrain import default_classes
    from terrapref.world import rasterise

    out = Path(args.out)
    if out.suffix.lower() not in (".yaml", ".yml"):
        raise UserError(str(out), "a course is a scenario file: give it the suffix .yaml", field="--out")
    figure = out.with_suffix(".png")
    inputs = [p for p in (args.classes, *(args.after or ())) if p is not None]
    for path in (out, figure):
        check_output(path, "--out", inputs, force=args.force)
    if args.name is not None and not re.fullmatch(r"[A-Za-z0-9_-]+", args.name):  # a scenario's name, as validate holds it
        raise UserError("--name", f"a scenario's name is letters, digits, _ and -; got {args.name!r}")
    table = class_table(args)
    if args.relief is not None and not 0 <= args.relief < 2**63:
        raise UserError("--relief", f"expected a seed from 0 to 2^63 - 1, as genrelief:SEED takes, got {args.relief}")
    if args.after is not None:
        recs = _drives_of_one_table(args, args.after)
        table = recs[0].classes
        plan = _follow_up_plan(recs)
        if not _says_what_is_left(plan, args.after):
            return 0
        courses = [str(r.meta.get("scenario")) for r in recs]
        course, items = follow_up_after(table, plan.open, courses, args.name, Beside(plan.neighbours, plan.relief, plan.ladder))
    else:
        table = table or default_classes()
        try:
            if args.relief is not None:  # the relief situations, and relief between them (SPEC 19)
                course, items = relief_course(table, args.design, args.name or "teaching_course_relief", args.relief)
            else:
                course, items = designed_course(table, args.design, args.name or "teaching_course")
        except ValueError as exc:
            raise UserError(str(args.classes or "classes"), str(exc), field="classes") from None
    if args.relief is not None and args.after is not None:  # a follow-up's relief: between its situations, beside their own
        course.relief = [*course.relief, *relief_for(parse_scenario(course.data(), str(out), table), args.relief)]
    scenario = parse_scenario(course.data(), str(out), table)  # checked as every command will read it
    source = (
        f"--classes {args.classes}"
        if args.classes
        else ("--after " + " ".join(map(str, args.after)) if args.after else "the default class table")
    )
    write_text_atomic(
        out,
        f"# terrapref course ({source}); it carries its class table (classes:), so no command needs --classes for it.\n" + course.to_yaml(),
    )
    save_map(figure, scenario, rasterise(scenario))
    print(f"{scenario.name}: {scenario.description}")
    print(f"  {_drive_line(scenario, items)}")
    drives = [(r.meta.get("driver"), r.meta.get("profile")) for r in recs] if args.after is not None else []  # as they were driven
    flags = driver_flags([d for d, _ in drives], scenario.has_relief, [p for _, p in drives])
    print(f"wrote {out} and {figure} (record it: terrapref record {out}{flags} --out DIR)")
    return 0


def _drive_line(scenario: Scenario, items: Sequence[Situation]) -> str:
    """What a course shows and how long its drive is expected to take: at the teaching driver's
    speed, or on relief at the pace the default driver keeps there."""
    from collections import Counter

    from terrapref.scenario.teaching import DRIVER_SPEED_MPS, RELIEF_PACE_MPS

    kinds = Counter(item.kind for item in items)
    pace = RELIEF_PACE_MPS if scenario.has_relief else DRIVER_SPEED_MPS
    where = " on relief (the default driver's pace there)" if scenario.has_relief else ""
    length = scenario.path_length_m()
    return (
        f"{len(items)} situations ({', '.join(f'{n} {k}' for k, n in kinds.items())}); path {length:.0f} m; "
        f"expected drive about {length / pace / 60:.1f} minutes at {pace:g} m/s{where}"
    )


def _drives_of_one_table(args: argparse.Namespace, paths: Sequence[Path]) -> list:
    """The recordings ``course --after`` reads, each given once and all of one class table
    (``--classes``' when given, else the first's)."""
    from terrapref.demos.recording import read_recording

    check_distinct(paths, "recording")
    recs = [read_recording(p) for p in paths]
    for path, rec in zip(paths, recs, strict=True):
        if class_table(args) is not None:
            check_table(args, rec.classes, path)
        elif not rec.classes.same_classes(recs[0].classes):
            raise UserError(
                str(path),
                f"was made for the class table of {', '.join(rec.classes.names)}, not {paths[0]}'s "
                f"({', '.join(recs[0].classes.names)}): give drives of one table",
                field="classes",
            )
    for rec in recs:
        warn_partial(rec)
    return recs


def _follow_up_plan(recs: Sequence) -> FollowUp:
    """What recordings' drives together leave open and a follow-up course can settle (the report ``inspect`` prints)."""
    from terrapref.cli.common import counted
    from terrapref.progress import Progress
    from terrapref.recipes import DEFAULT_RECIPE, follow_up_plan, recipe_named

    for rec in recs:
        if len(rec) == 0:
            raise UserError(str(rec.path), "holds no frames: drive the teaching course first", field="frames")
    total = sum(len(r) for r in recs)
    bar = Progress(f"featurising the drive{'s' if len(recs) > 1 else ''} to find the pairs left open", total, unit="frames")
    plan = follow_up_plan(list(recs), recipe_named(DEFAULT_RECIPE), frames=counted(bar, "frames", f"{total} frames, then fitting them ..."))
    bar.close(f"{total} frames")  # (closed once all were featurised: the fit that follows takes a while too)
    return plan


def _says_what_is_left(plan: FollowUp, paths: Sequence[Path]) -> bool:
    """Print what the drives left open, what no further course settles and why; whether a follow-up course is to be written."""
    drives = "drives together" if len(paths) > 1 else "drive"
    left = len(plan.open) + len(plan.left) + len(plan.relief) + len(plan.relief_left) + len(plan.ladder)
    if not left:
        print(
            f"{', '.join(map(str, paths))}: the {drives} identified every pair of classes"
            f"{' and showed all the relief it teaches' if plan.on_relief else ''}; no follow-up course is needed (nothing written)"
        )
        return False
    for line in plan.reopened + plan.left + plan.relief_left:
        print(f"note: {line}")
    if not plan.anything:
        what = " and ".join(x for x in (_count(plan.left, "pair"), _count(plan.relief_left, "relief lesson")) if x)
        print(f"the {drives} left {what} open that a further drive of this loop would not settle (above); nothing written")
        return False
    if plan.open:
        neighbours = f"; beside them, their neighbours in the learned order: {_pairs(plan.neighbours)}" if plan.neighbours else ""
        print(f"the {drives} left {_count(plan.open, 'pair')} open for a follow-up: {_pairs(plan.open)}{neighbours}")
    if plan.ladder:
        if not plan.open:
            print(f"the {drives} identified every pair of classes")
        strips = f"as strips, and {plan.ladder[0]} " if len(plan.ladder) > 1 else ""
        print(
            f"the table has too many feature classes for the full design, so its first follow-up shows the order the {drives} "
            f"learned ({' > '.join(plan.ladder)}) {strips}alone at two sizes"
        )
    if plan.relief:
        print(f"the {drives} left relief unshown for a follow-up: {', '.join(plan.relief)}")
    elif plan.on_relief and not plan.relief_left:
        print(f"the {drives} showed all the relief it teaches: the follow-up shows terrain only")
    return True


def _count(items: Sequence, what: str) -> str:
    """``N what(s)``; empty for no items."""
    return f"{len(items)} {what}{'s' if len(items) > 1 else ''}" if items else ""


def _pairs(pairs: Sequence[tuple[str, str]]) -> str:
    return ", ".join(f"{a} vs {b}" for a, b in pairs)


def course_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("course", help="write the teaching course of a class table (or, with --after, a follow-up of what drives left open)")
    p.add_argument("--out", required=True, type=output_path, help="scenario file to write (.yaml); a top-down figure goes beside it (.png)")
    p.add_argument(
        "--after",
        type=Path,
        nargs="+",
        metavar="REC",
        help="recordings of the teaching course (and of the follow-ups since, in the order driven): write a short course "
        "of the pairs their drives together left unidentified, beside their neighbours in the learned order (after the first "
        "drive of a table too large for the full design, beside the ladder of that order instead), and of the "
        "relief drives on relief left unshown (a steep bank or mound, a ramp, a rough patch), or say what no further "
        "course settles (train on all the recordings after)",
    )
    p.add_argument(
        "--design",
        choices=("auto", "full", "compact"),
        default="auto",
        help="full: every pair once on each side; compact: every pair once, sides balanced; auto (default): full while "
        "the drive stays within 10 minutes at 1 m/s (with --relief: 7 minutes at 0.85 m/s, each pair and lethal lone "
        "patch once in either design, the full one still with every strip on both sides)",
    )
    p.add_argument("--name", help="the scenario's name (default teaching_course, or teaching_course_relief with --relief, or DRIVEN_more)")
    p.add_argument(
        "--relief",
        type=int,
        nargs="?",
        const=0,
        metavar="SEED",
        help="a course with relief, as teach_relief is: the relief situations (mounds on the path, banks beside it, a ramp, "
        "each class against a bank) among the others, and relief between the situations (bumps, dips, ramps, ditches and "
        "gently rolling ground, drawn from SEED, default 0; the terrain situations' own ground stays flat) (docs/cli.md, Relief)",
    )
    add_classes_arg(p)
    add_force_arg(p)
    p.set_defaults(func=_cmd_course)


def _cmd_list(args: argparse.Namespace) -> int:
    from terrapref.scenario import packaged_scenarios, resolve_scenario

    names = packaged_scenarios()
    width = max(map(len, names), default=0)
    for name in names:
        s = resolve_scenario(name)
        print(
            f"{name:{width}s} {s.size_m[0]:5.0f} x {s.size_m[1]:<4.0f} m  path {s.path_length_m():5.0f} m  {len(s.zones):2d} zones  {s.description}"
        )
    return 0


def scenarios_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("scenarios", help="list the packaged scenarios")
    p.set_defaults(func=_cmd_list)
