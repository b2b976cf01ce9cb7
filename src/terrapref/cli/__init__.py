"""The ``terrapref`` command: thin wrappers over the library.

Every user error (bad file, bad flag value, mismatched model) is printed as one line per
problem, naming the file and the field, and exits with code 2.

One module per group of commands, each holding its commands and their parsers side by side:
:mod:`~terrapref.cli.courses` (validate, render, show, course, scenarios),
:mod:`~terrapref.cli.demos` (record, drive, inspect, featurize), :mod:`~terrapref.cli.train`
(train, recipes), :mod:`~terrapref.cli.evaluate` (evaluate, perception),
:mod:`~terrapref.cli.studies` (reproduce, study, select), :mod:`~terrapref.cli.files` (import,
replay, export, info) and :mod:`~terrapref.cli.robot` (ros1, ros2, play, route); the flags
several share are in :mod:`~terrapref.cli.common`.
"""

from __future__ import annotations

import argparse
import functools
import os
import re
import signal
import sys
import threading
from collections.abc import Callable, Sequence
from typing import NoReturn

from terrapref.cli.courses import course_parser, render_parser, scenarios_parser, show_parser, validate_parser
from terrapref.cli.demos import drive_parser, featurize_parser, inspect_parser, record_parser
from terrapref.cli.evaluate import evaluate_parser, perception_parser
from terrapref.cli.files import export_parser, import_parser, info_parser, replay_parser
from terrapref.cli.robot import play_parser, ros1_parser, ros2_parser, route_parser
from terrapref.cli.studies import reproduce_parser, select_parser, study_parser
from terrapref.cli.train import recipes_parser, train_parser
from terrapref.errors import Terminated, UserError
from terrapref.grid import GridError

COMMANDS = (
    course_parser,
    validate_parser,
    render_parser,
    show_parser,
    record_parser,
    drive_parser,
    inspect_parser,
    featurize_parser,
    train_parser,
    evaluate_parser,
    reproduce_parser,
    study_parser,
    import_parser,
    replay_parser,
    export_parser,
    ros1_parser,
    ros2_parser,
    play_parser,
    route_parser,
    info_parser,
    select_parser,
    perception_parser,
    recipes_parser,
    scenarios_parser,
)
"""Each command's parser, in the order `terrapref --help` lists them."""

_NEGATIVE_NUMBER = re.compile(r"^-(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?$")


class _Parser(argparse.ArgumentParser):
    """argparse, with its refusals (a missing argument, a value of the wrong type, an unknown
    choice) as one line on stderr and exit code 2, like every other error of the command line;
    a negative number with an exponent (``--pose -1e3 5 0``) is a number, not an option."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE_NUMBER

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"error: {self.prog}: {message} (see {self.prog} --help)\n")


@functools.cache
def build_parser(train_flags: bool = True) -> argparse.ArgumentParser:
    """The ``terrapref`` command line (``train_flags``: with train's training flags), built once a
    process: parsing leaves it as it was, and a program calling :func:`main` again reuses it."""
    from terrapref import __version__

    parser = _Parser(prog="terrapref", description="Learn off-road terrain preferences from a few minutes of driving.")
    parser.add_argument("--version", action="version", version=f"terrapref {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add in COMMANDS:
        add(sub, flags=train_flags) if add is train_parser else add(sub)
    return parser


def _on_sigterm(pid: int) -> Callable[[int, object], None]:
    def handler(signum: int, frame: object) -> None:
        if os.getpid() != pid:  # a forked worker: end as SIGTERM ends a process, the command cleans up
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)
            return
        raise Terminated()

    return handler


# Commands a launcher or a supervisor ends with SIGINT, as it ends rclpy's and rospy's nodes:
# started by a script in the background they inherit SIGINT ignored, so they arm it themselves,
# from their first line (the model's loading and the middleware's start take seconds).
ENDED_BY_SIGINT = ("ros1", "ros2", "play")


def _arm_signals(command: str) -> dict[int, object]:
    """SIGTERM ends the command as Ctrl-C does, cleaning up on the way; a node's command
    (:data:`ENDED_BY_SIGINT`) takes SIGINT whatever it inherited. The handlers replaced."""
    previous = {signal.SIGTERM: signal.signal(signal.SIGTERM, _on_sigterm(os.getpid()))}
    if command in ENDED_BY_SIGINT:
        previous[signal.SIGINT] = signal.signal(signal.SIGINT, signal.default_int_handler)
    return previous


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    command = next((a for a in argv if not a.startswith("-")), None)
    parser = build_parser(train_flags=command == "train")
    args = parser.parse_args(argv)
    func: Callable[[argparse.Namespace], int] = args.func
    previous = _arm_signals(args.command) if threading.current_thread() is threading.main_thread() else None
    try:
        return func(args)
    except UserError as exc:
        for line in exc.lines():
            print(f"error: {line}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        if isinstance(exc, Terminated):  # cleaned up on the way here; end now, before libraries' exit handlers (SDL's can wait)
            print("terminated", file=sys.stderr, flush=True)
            sys.stdout.flush()
            os._exit(143)
        print("interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into `head` and the like: stop quietly
        sys.stderr.close()
        return 0
    except OSError as exc:
        print(f"error: {exc.filename or ''}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    except GridError as exc:  # jobs of a grid failed: each named by its inputs
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except Exception as exc:  # a bug, not a user error: one line unless asked for the traceback
        if os.environ.get("TERRAPREF_DEBUG"):
            raise
        print(f"error: internal error ({type(exc).__name__}: {exc}); set TERRAPREF_DEBUG=1 for the traceback", file=sys.stderr)
        return 1
    finally:
        for signum, handler in (previous or {}).items():
            signal.signal(signum, handler)
