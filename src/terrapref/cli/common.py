"""What several commands share: the flags for class tables, perception, the grid engine, the live
view and --force, their help texts, and the checks of their values (each before any work)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path

from terrapref.configargs import finite_float
from terrapref.errors import UserError
from terrapref.grid import ENGINES, Engine

SCENARIO_HELP = (
    "a packaged scenario's name (terrapref scenarios lists them), gen:N for generated layout N, genrelief:N for "
    "generated layout N with relief, or a scenario file"
)
PERCEPTION_HELP = (
    "what the planner receives instead of the truth: a preset (clean, rellis, field; terrapref perception lists them) "
    "or a terrapref-perception/1 file"
)

CLASSES_HELP = (
    "your own class table (a terrapref-classes/1 file, e.g. examples/classes/rellis3d.yaml): the classes scenarios, "
    "generated layouts (gen:N) and label maps are read with; default: the packaged grass, mud, rock, water, non_traversable"
)
CLASSES_CHECK_HELP = (
    "the class table the files must have been made for (a terrapref-classes/1 file); a file made for another is refused. "
    "Files carry their own table, so this is a check, not a setting"
)


def output_path(text: str) -> Path:
    """An output flag's value (``--out``): a path, refused when empty (Path reads ``""`` as the
    current folder, which nobody writing ``--out ""`` means)."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"expected a path, got {text!r}")
    return Path(text)


def add_classes_arg(p: argparse.ArgumentParser, check: bool = False) -> None:
    """--classes FILE: the table files are read with, or (``check``) the one they must have been made for."""
    p.add_argument("--classes", metavar="FILE", help=CLASSES_CHECK_HELP if check else CLASSES_HELP)


def add_force_arg(p: argparse.ArgumentParser) -> None:
    """--force, the same for every command that writes: an output that exists is refused without it."""
    p.add_argument(
        "--force", action="store_true", help="replace an output that exists (only once the new one is complete; a folder is replaced whole)"
    )


def add_engine_args(p: argparse.ArgumentParser) -> None:
    """--workers, --engine and --address: where a command's grid of jobs runs (:func:`grid_engine` checks them)."""
    p.add_argument("--workers", type=int, help="parallel jobs on this machine (default: one per core)")
    p.add_argument(
        "--engine",
        choices=ENGINES.names(),
        default="local",
        help="where the jobs run: local processes (default) or Ray (a local instance, or the cluster at --address)",
    )
    p.add_argument(
        "--address", metavar="HOST:PORT", help="a Ray cluster to run the jobs on (ray start --head on one machine); with --engine ray"
    )


def add_large_arg(p: argparse.ArgumentParser, command: str) -> None:
    """--large, the same for every command that trains and drives many models (:func:`announce_workload`)."""
    p.add_argument(
        "--large",
        action="store_true",
        help=f"run more than 1,000 models or 100,000 runs ({command} first prints how many, and about how long)",
    )


def announce_workload(command: str, workload, engine: Engine, large: bool, flags: str, fewer: str) -> None:
    """Print at once how many models and closed-loop runs ``command`` makes and about how long
    they take on ``engine``'s workers (a terrapref.report.workload.Workload); refuse one beyond the
    bound unless ``large`` (--large), naming ``flags``, the flags that set its size, and what to
    name ``fewer`` of."""
    print(f"{command}: {workload.describe(engine.n_workers if engine.address is None else None)}", flush=True)
    if workload.large and not large:
        raise UserError(flags, f"{workload.refusal()}: name fewer {fewer}, or add --large to run them all")


LIVE_HOST, LIVE_PORT = "127.0.0.1", 8765  # where the live view listens unless told


def add_live_args(p: argparse.ArgumentParser, note: str, paced: bool = False) -> None:
    """--live and its address; with ``paced`` (simulated runs), --live-pace and --live-wait too."""
    p.add_argument(
        "--live",
        action="store_true",
        help=f"serve the planner's channels live (those of the MCAP export) on Foxglove's WebSocket protocol "
        f"(subprotocol foxglove.sdk.v1, or foxglove.websocket.v1 for older viewers); {note}",
    )
    p.add_argument("--live-host", default=None, help=f"address the live view listens on (default {LIVE_HOST}; 0.0.0.0: every interface)")
    p.add_argument("--live-port", type=int, default=None, help=f"port of the live view (default {LIVE_PORT}, Foxglove's; 0: a free one)")
    if paced:
        p.add_argument(
            "--live-pace",
            type=finite_float,
            default=None,
            metavar="FACTOR",
            help="send each run's frames at FACTOR times real time (1: as driven; 2: twice as fast); default: as fast as they are computed",
        )
        p.add_argument("--live-wait", action="store_true", help="wait for a viewer to connect before the first run starts")


def class_table(args: argparse.Namespace):
    """The class table ``--classes FILE`` gives (read once per command), or None (the packaged default)."""
    if getattr(args, "classes", None) is None:
        return None
    if not hasattr(args, "class_table"):
        from terrapref.terrain import load_classes

        args.class_table = load_classes(args.classes)
    return args.class_table


def teachable_table(args: argparse.Namespace):
    """``--classes``' table for a command that teaches it (None: the default), refused when it has
    no feature class to choose between."""
    table = class_table(args)
    if table is not None and not table.terrain_names:
        raise UserError(str(args.classes), "the class table has no feature class (neither background nor lethal) to teach", field="classes")
    return table


def check_table(args: argparse.Namespace, found, source: str | Path) -> None:
    """Refuse a file made for another class table than ``--classes`` gives (the default table
    when the flag is not given), naming both."""
    from terrapref.terrain import default_classes

    table = class_table(args) or default_classes()
    if not found.same_classes(table):
        given = (
            f"{args.classes}'s" if getattr(args, "classes", None) is not None else "the default table's (give --classes FILE for another)"
        )
        raise UserError(
            str(source),
            f"was made for the class table of {', '.join(found.names)}, not {given} ({', '.join(table.names)})",
            field="classes",
        )


def perception_model(spec: str | None, flag: str = "--perception", classes=None):
    """The perception model of ``--perception PRESET|FILE`` (None when not given), checked before any work."""
    if spec is None:
        return None
    if not spec.strip():
        raise UserError(flag, f"expected a preset ({', '.join(_presets())}) or a terrapref-perception/1 file, got {spec!r}")
    from terrapref.perception import load_perception

    try:
        return load_perception(spec, classes)
    except UserError as exc:
        if exc.source == "--perception" and flag != "--perception":
            raise UserError(flag, exc.problems) from None
        raise


def _presets() -> tuple[str, ...]:
    from terrapref.perception import PRESETS

    return tuple(PRESETS)


def perception_list(text: str, classes=None) -> tuple:
    """The perception models of a comma-separated ``--perception`` list, each checked before any
    work; an empty item and one named twice are refused."""
    names = [x.strip() for x in text.split(",")]
    if not all(names):
        raise UserError("--perception", f"has an empty item: {text!r}; expected perception models separated by commas")
    models = tuple(perception_model(n, classes=classes) for n in names)
    if len({p.name for p in models}) != len(models):
        raise UserError("--perception", f"names a perception model twice: {text!r}")
    return models


def given_files(args: argparse.Namespace, *flags: str) -> list[str]:
    """The files that the ``flags`` (attribute names of ``args``: a file, or a list of them and
    presets separated by commas, a file's part after ':') name and that exist: the inputs an
    output folder must not hold."""
    out = []
    for flag in flags:
        value = getattr(args, flag, None)
        for item in (value or "").split(",") if isinstance(value, str) else ():
            for name in (item.strip(), item.strip().rsplit(":", 1)[0]):
                if name and Path(name).exists():
                    out.append(name)
                    break
    return out


def grid_engine(args: argparse.Namespace) -> Engine:
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
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise UserError("--address", f"expected HOST:PORT of a Ray head (ray start --head), got {address!r}")
    try:
        with socket.create_connection((host, int(port)), timeout=5.0):
            pass
    except OSError as exc:
        raise UserError("--address", f"no Ray head answers at {address} ({exc.strerror or exc}); start one with ray start --head") from None


def live_view(args: argparse.Namespace):
    """The live view that --live asks for (its address printed), or None."""
    pace, wait = getattr(args, "live_pace", None), getattr(args, "live_wait", False)
    if not args.live:
        given = {
            "--live-pace": pace is not None,
            "--live-wait": wait,
            "--live-host": args.live_host is not None,
            "--live-port": args.live_port is not None,
        }
        flag = next((f for f, on in given.items() if on), None)
        if flag is not None:
            raise UserError(flag, "goes with --live")
        return None
    host, port = args.live_host or LIVE_HOST, LIVE_PORT if args.live_port is None else args.live_port
    if not 0 <= port <= 65535:
        raise UserError("--live-port", f"expected a port in [0, 65535], got {port}")
    if pace is not None and not pace > 0:
        raise UserError("--live-pace", f"expected a factor of real time > 0 (1: as driven), got {pace:g}")
    from terrapref.interop.live import LiveView

    view = LiveView(host, port, pace=pace or 0.0, wait=wait)
    paced = f"; frames at {pace:g}x real time" if pace else ""
    waiting = "; waiting for a viewer before the first run" if wait else ""
    print(f"live view: {view.url} (Foxglove: Open connection, Foxglove WebSocket{paced}){waiting}", flush=True)
    return view


def watching(view):
    """What a run shows the live view ``view`` (None: nothing), as terrapref.interop.live.watching gives it."""
    from terrapref.interop.live import watching

    return watching(view)


def warn_partial(recording) -> None:
    """A warning line for a recording cut short (Ctrl-C, a write that failed: terrapref.demos.recording),
    which the commands that read it use as far as it goes."""
    if not recording.complete:
        print(f"warning: {recording.path} is partial; using its {len(recording)} frames", file=sys.stderr)


def by_recording(bar):
    """A featurising progress (terrapref.dataset.Featuring) that moves ``bar`` (counting recordings)
    frame by frame: one recording of a five-minute drive takes half a minute."""
    return lambda p: bar.update(
        p.recordings * p.frames_done / max(p.frames, 1),
        f"{p.frames_done}/{p.frames} frames of {p.recordings} recording{'s' if p.recordings != 1 else ''}",
    )


def counted(bar, unit: str, then: str) -> Callable[[int, int], None]:
    """A ``(done, total)`` progress that moves ``bar`` and closes it with ``then`` once all are done
    (for a command whose work goes on after them)."""

    def tick(done: int, total: int) -> None:
        bar.update(done, f"{done}/{total} {unit}")
        if done == total:
            bar.close(then)

    return tick


def incidents(log) -> str:
    """What of a drive counts against its safety, in words: its collisions (and the time and
    distance with lethal terrain under the vehicle), and on relief its tips and times stuck, which
    count as they do."""
    line = f"{log.collisions} collisions"
    if log.contact_s:
        line += f" ({log.contact_s:.1f} s, {log.contact_m:.1f} m with lethal terrain under the vehicle)"
    relief = log.relief_summary()
    if relief["tips"] or relief["stuck"]:
        line += (
            f", {relief['tips']} tips, {relief['stuck']} times stuck "
            f"(roll at most {relief['max_roll_deg']:g} deg, pitch {relief['max_pitch_deg']:g} deg)"
        )
    return line


def featurize_features(args: argparse.Namespace, recipe):
    """The features ``featurize`` computes for ``recipe`` (a terrapref.recipes.Recipe): its own, with
    ``--distance-mode`` and the trajectories' ``--n-steps`` and ``--dt``, refused where the recipe's
    second stage would look ahead past them."""
    import math
    from dataclasses import replace

    from terrapref.rules.second.rule import check_lookahead

    features = replace(recipe.features(), distance_mode=args.distance_mode)
    if args.n_steps is None and args.dt is None:
        return features
    if args.n_steps is not None and args.n_steps < 1:
        raise UserError("--n-steps", f"must be an integer >= 1, got {args.n_steps}")
    if args.dt is not None and not (math.isfinite(args.dt) and args.dt > 0):
        raise UserError("--dt", f"must be a finite number of seconds > 0, got {args.dt}")
    pref = features.preference
    try:
        pref = replace(pref, n_steps=pref.n_steps if args.n_steps is None else args.n_steps, dt_s=pref.dt_s if args.dt is None else args.dt)
        check_lookahead(recipe.rules, pref.n_steps, pref.dt_s)
    except ValueError as exc:
        raise UserError("--n-steps" if args.n_steps is not None else "--dt", str(exc)) from None
    return replace(features, preference=pref)


def check_run_folder(out: str | Path, inputs: list) -> None:
    """The one rule for a run's folder (``--out`` of evaluate, replay, select, study and reproduce:
    terrapref.fileio.check_output), and never a recording: only record and import replace one."""
    from terrapref.demos.recording import is_recording
    from terrapref.fileio import check_output

    check_output(out, "--out", inputs, folder=True)
    if is_recording(Path(out)):
        raise UserError(str(out), "is a recording, which only record and import replace; name a run's folder", field="--out")
