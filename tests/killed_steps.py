"""A folder replacement run in a child process that is killed with SIGKILL (as ``kill -9``) just
before its N-th change on disk, so that none of its own clean-up runs: for tests/test_fileio.py.

A process of its own, which imports little, so that forking it for every step is quick (a test
process that has loaded torch takes tens of milliseconds a fork). Reads ``CASE<TAB>WORK<TAB>STEP``
lines on stdin and answers each with ``killed`` (the kill came) or ``ended`` (the action ended
first).
"""

from __future__ import annotations

import os
import signal
import sys
from collections.abc import Callable
from pathlib import Path

from terrapref.fileio import output_folder, replace_dir

OLD = {"figs/a.png": "old", "metrics.json": "old"}
NEW = {"figs/a.png": "new", "metrics.json": "new"}
CHANGES = ("mkdir", "rmdir", "rename", "replace", "unlink")  # every change a replacement makes on disk is one of these


def write(folder: Path, run: dict[str, str]) -> None:
    """The files of ``run`` (name -> text) in ``folder``."""
    for name, text in run.items():
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text(text)


def _replacing(out: Path, fail: bool = False) -> None:
    """A command writing ``out`` with --force (ending with Ctrl-C when ``fail``)."""
    try:
        with output_folder(out, force=True):
            write(out, NEW)
            if fail:
                raise KeyboardInterrupt
    except KeyboardInterrupt:
        pass


ACTIONS: dict[str, Callable[[Path], None]] = {
    "replace": lambda work: _replacing(work / "ev"),
    "first run": lambda work: _replacing(work / "ev"),
    "replace, failing": lambda work: _replacing(work / "ev", fail=True),
    "swap": lambda work: (write(work / ".ev.new", NEW), replace_dir(work / ".ev.new", work / "ev")),
}


def killed_at(step: int, action: Callable[[], None]) -> bool:
    """Run ``action`` in a child killed just before its ``step``-th change on disk; whether it was."""
    pid = os.fork()
    if pid == 0:
        code = 1
        try:
            done = [0]

            def counted(real):
                def change(*args, **kwargs):
                    done[0] += 1
                    if done[0] == step:
                        os.kill(os.getpid(), signal.SIGKILL)
                    return real(*args, **kwargs)

                return change

            for name in CHANGES:
                setattr(os, name, counted(getattr(os, name)))
            action()
            code = 0
        finally:
            os._exit(code)
    _, status = os.waitpid(pid, 0)
    if not os.WIFSIGNALED(status) and os.WEXITSTATUS(status) != 0:
        raise RuntimeError(f"the action failed at step {step}")
    return os.WIFSIGNALED(status)


def main() -> None:
    for line in sys.stdin:
        case, work, step = line.rstrip("\n").split("\t")
        killed = killed_at(int(step), lambda: ACTIONS[case](Path(work)))
        print("killed" if killed else "ended", flush=True)


if __name__ == "__main__":
    main()
