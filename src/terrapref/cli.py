"""The ``terrapref`` command: thin wrappers over the library.

Every user error (bad file, bad flag value, mismatched model) is printed as one line per
problem, naming the file and the field, and exits with code 2.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from terrapref.errors import UserError


def _cmd_validate(args: argparse.Namespace) -> int:
    from terrapref.scenario import load_scenario
    from terrapref.scenario.catalog import scenario_path

    status = 0
    for name in args.files:
        try:
            load_scenario(scenario_path(name))
        except UserError as exc:
            for line in exc.lines():
                print(line)
            status = 2
        else:
            print(f"{name}: ok")
    return status


def _cmd_render(args: argparse.Namespace) -> int:
    from terrapref.camera import PinholeCamera, SegmentationRenderer
    from terrapref.report.images import colorise, write_png_atomic
    from terrapref.scenario import resolve_scenario
    from terrapref.vehicle import Pose
    from terrapref.world import rasterise

    if args.pose is not None and not all(math.isfinite(v) for v in args.pose):
        raise UserError("--pose", "X, Y and YAW_DEG must be finite numbers")
    scenario = resolve_scenario(args.scenario)
    x, y, yaw_deg = args.pose if args.pose is not None else (scenario.start[0], scenario.start[1], math.degrees(scenario.start[2]))
    renderer = SegmentationRenderer(PinholeCamera(), rasterise(scenario))
    image = renderer.render(Pose(x, y, math.radians(yaw_deg)))
    write_png_atomic(args.out, image)
    print(f"wrote {args.out} ({image.shape[1]}x{image.shape[0]} class ids)")
    if args.preview:
        write_png_atomic(args.preview, colorise(image, scenario.classes))
        print(f"wrote {args.preview} (colour preview)")
    return 0


def _cmd_show(args: argparse.Namespace) -> int:
    from terrapref.report.plots import save_map
    from terrapref.scenario import resolve_scenario
    from terrapref.world import rasterise

    scenario = resolve_scenario(args.scenario)
    save_map(args.out, scenario, rasterise(scenario))
    print(f"wrote {args.out} ({scenario.name}: {len(scenario.terrain)} patches, {len(scenario.zones)} zones, path {scenario.path_length_m():.0f} m)")
    return 0


def _cmd_list(args: argparse.Namespace) -> int:
    from terrapref.scenario import packaged_scenarios, resolve_scenario

    for name in packaged_scenarios():
        s = resolve_scenario(name)
        print(f"{name:28s} {s.size_m[0]:5.0f} x {s.size_m[1]:<4.0f} m  path {s.path_length_m():5.0f} m  {len(s.zones):2d} zones  {s.description}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="terrapref", description="Learn off-road terrain preferences from a few minutes of driving.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("validate", help="check scenario files against terrapref-scenario/1")
    p.add_argument("files", nargs="+", metavar="FILE")
    p.set_defaults(func=_cmd_validate)

    p = sub.add_parser("render", help="render the segmentation camera image at a pose")
    p.add_argument("scenario", metavar="SCENARIO", help="packaged scenario name or file")
    p.add_argument("--pose", nargs=3, type=float, metavar=("X", "Y", "YAW_DEG"), help="vehicle pose [m, m, deg]; default: the start")
    p.add_argument("--out", required=True, type=Path, help="single-channel PNG of class ids")
    p.add_argument("--preview", type=Path, help="also write a colour preview PNG")
    p.set_defaults(func=_cmd_render)

    p = sub.add_parser("show", help="draw the map top-down with the path, the start and the zones")
    p.add_argument("scenario", metavar="SCENARIO")
    p.add_argument("--out", required=True, type=Path)
    p.set_defaults(func=_cmd_show)

    p = sub.add_parser("scenarios", help="list the packaged scenarios")
    p.set_defaults(func=_cmd_list)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    func: Callable[[argparse.Namespace], int] = args.func
    try:
        return func(args)
    except UserError as exc:
        for line in exc.lines():
            print(f"error: {line}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except OSError as exc:
        print(f"error: {exc.filename or ''}: {exc.strerror or exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
