"""Running a grid of independent jobs: local worker processes, or a Ray cluster.

Every command that runs many independent jobs (evaluation runs, the reproduction's and the
study's demonstrations and trainings) maps one function over a list of jobs through
:func:`run_grid`. The engine decides where the jobs run:

- ``local`` (the default): forked worker processes on this machine, one per core unless
  ``workers`` says otherwise; one worker runs the jobs in this process.
- ``ray``: Ray tasks (the ``ray`` extra). With no ``address`` a Ray instance is started on this
  machine with ``workers`` CPUs; with ``address`` (``ray start --head`` on one machine, ``ray
  start --address HEAD:6379`` on the others) the jobs go to that cluster. Jobs pass files by path, so on a
  cluster the output folder must be on storage every node sees, and terrapref must be installed
  on every node.

Results come back in the jobs' order whatever order they finish in, so a grid gives the same
results on either engine and any number of workers. Progress is reported as jobs finish. A job
that fails does not stop the others; once all have run, a bad input is raised as the
:class:`UserError` it is, and any other failure as a :class:`GridError` naming every failed job
by its inputs (``TERRAPREF_DEBUG=1`` prints their tracebacks).
"""

from __future__ import annotations

import os
import sys
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

from terrapref.errors import UserError
from terrapref.extras import needs
from terrapref.registry import Registry

J = TypeVar("J")
R = TypeVar("R")

Outcome = tuple[bool, Any]  # (True, the job's result) or (False, what went wrong): see _guarded
Runner = Callable[[Callable, list, "Engine", "Callable[[int, int], None] | None"], list[Outcome]]

# Where a grid's jobs can run; each runner gives every job's outcome in the jobs' order. The
# runners are named as "module:attribute" because they are defined below (and Ray is optional).
ENGINES: Registry[Runner] = Registry("engine")
ENGINES.register("local", "terrapref.grid:_run_here", doc="worker processes on this machine")
ENGINES.register("ray", "terrapref.grid:_run_ray", doc="Ray tasks: a local instance, or a cluster")


class GridError(RuntimeError):
    """Some jobs of a grid failed; ``failures`` holds (job description, error text) for each."""

    def __init__(self, failures: list[tuple[str, str]], total: int) -> None:
        self.failures = failures
        shown = "; ".join(f"{what}: {error}" for what, error in failures[:3])
        more = f" (and {len(failures) - 3} more)" if len(failures) > 3 else ""
        super().__init__(f"{len(failures)} of {total} jobs failed: {shown}{more}")


@dataclass(frozen=True)
class Engine:
    """Where a grid's jobs run.

    Attributes:
        kind: ``local`` or ``ray``.
        workers: parallel jobs on this machine (local processes, or the CPUs of a Ray instance
            started here); None is one per core. Ignored with ``address`` (the cluster's CPUs).
        address: a Ray cluster's address (``HOST:6379`` or ``auto``); None starts one here.
    """

    kind: str = "local"
    workers: int | None = None
    address: str | None = None

    def __post_init__(self) -> None:
        ENGINES.entry(self.kind)  # an unknown kind is a ValueError listing the engines
        if self.workers is not None and self.workers < 1:
            raise ValueError("workers must be >= 1")
        if self.address is not None and self.kind != "ray":
            raise ValueError("an address is for the ray engine")

    @property
    def n_workers(self) -> int:
        return self.workers if self.workers is not None else os.cpu_count() or 1

    def describe(self) -> str:
        if self.kind == "local":
            return f"local, {self.n_workers} worker{'s' if self.n_workers > 1 else ''}"
        return f"ray, cluster at {self.address}" if self.address else f"ray, a local instance with {self.n_workers} CPUs"


LOCAL = Engine()


def _guarded(fn: Callable[[J], R], job: J) -> tuple[bool, Any]:
    """Run one job; an exception comes back as a value rather than ending the grid: a
    :class:`UserError` as itself (it names the file at fault), any other as its text and traceback."""
    try:
        return True, fn(job)
    except UserError as exc:
        return False, exc
    except Exception as exc:  # noqa: BLE001 - reported with the job's inputs by run_grid
        stop = _stop_within(exc)
        if stop is not None:  # a stop (Ctrl-C, SIGTERM) that arrived inside compiled code comes back wrapped
            raise stop from None
        return False, (f"{type(exc).__name__}: {exc}", traceback.format_exc())


def _stop_within(exc: BaseException) -> BaseException | None:
    """The stop (an exception that is not an :class:`Exception`, as KeyboardInterrupt) in ``exc``'s
    chain of causes and contexts, if any: a signal handled while compiled code runs surfaces as
    a SystemError whose context is the stop."""
    seen: set[int] = set()
    link: BaseException | None = exc
    while link is not None and id(link) not in seen:
        seen.add(id(link))
        if not isinstance(link, Exception):
            return link
        link = link.__cause__ or link.__context__
    return None


def run_grid(
    fn: Callable[[J], R],
    jobs: Sequence[J],
    engine: Engine = LOCAL,
    progress: Callable[[int, int], None] | None = None,
    describe: Callable[[J], str] = repr,
) -> list[R]:
    """``[fn(job) for job in jobs]`` on ``engine``; ``progress(done, total)`` as jobs finish.

    ``fn`` must be a module-level function (it is sent to other processes); ``describe(job)``
    names a failed job in the error.

    Raises:
        GridError: after every job has run, when any failed.
    """
    jobs = list(jobs)
    if not jobs:
        return []
    outcomes = ENGINES[engine.kind](fn, jobs, engine, progress)
    failed = [(job, value) for job, (ok, value) in zip(jobs, outcomes, strict=True) if not ok]
    for _, value in failed:
        if isinstance(value, UserError):
            raise value  # bad input: the user's to fix, and the error says where
    if failed:
        if os.environ.get("TERRAPREF_DEBUG"):
            for job, (_, trace) in failed:
                print(f"--- {describe(job)}\n{trace}", file=sys.stderr)
        raise GridError([(describe(job), text) for job, (text, _) in failed], len(jobs))
    return [value for _, value in outcomes]


def _run_here(fn: Callable, jobs: list, engine: Engine, progress: Callable[[int, int], None] | None) -> list[Outcome]:
    """The ``local`` engine: the jobs in this process with one worker (or one job), else in worker processes."""
    if engine.n_workers > 1 and len(jobs) > 1:
        return _run_local(fn, jobs, engine.n_workers, progress)
    outcomes = []
    for i, job in enumerate(jobs):
        outcomes.append(_guarded(fn, job))
        if progress:
            progress(i + 1, len(jobs))
    return outcomes


def _run_local(fn: Callable, jobs: list, workers: int, progress: Callable[[int, int], None] | None) -> list[Outcome]:
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from functools import partial

    outcomes: list[tuple[bool, Any] | None] = [None] * len(jobs)
    with ProcessPoolExecutor(
        max_workers=min(workers, len(jobs)), mp_context=mp.get_context("fork"), initializer=die_with_parent, initargs=(os.getpid(),)
    ) as pool:
        futures = {pool.submit(partial(_guarded, fn), job): i for i, job in enumerate(jobs)}
        for done, fut in enumerate(as_completed(futures), start=1):
            outcomes[futures[fut]] = fut.result()
            if progress:
                progress(done, len(jobs))
    return outcomes  # type: ignore[return-value]


PARENT_WATCH_S = 0.5  # how often a worker without Linux's parent-death signal looks for its parent


def die_with_parent(parent: int) -> None:
    """End this worker when the process ``parent`` that started it ends: a command killed outright
    (``kill -9``, the out-of-memory killer) would otherwise leave its workers finishing their jobs
    into its output and holding its output's lock, so that nothing could take its place. Linux's
    parent-death signal where there is one (SIGKILL: the worker's jobs are the command's, and
    nothing of theirs is kept); elsewhere a thread that looks for the parent twice a second."""
    import signal

    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        armed = libc.prctl(1, int(signal.SIGKILL), 0, 0, 0) == 0  # 1: PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # not Linux
        armed = False
    if os.getppid() != parent:  # gone before the signal was armed
        os._exit(1)
    if not armed:
        import threading

        threading.Thread(target=_watch_parent, args=(parent,), name="parent-watch", daemon=True).start()


def _watch_parent(parent: int) -> None:
    import time

    while os.getppid() == parent:
        time.sleep(PARENT_WATCH_S)
    os._exit(1)


def start_ray(engine: Engine) -> bool:
    """Connect to ``engine``'s Ray (start a local instance, or join the cluster at its address)
    unless this process already is; True when this call started the connection."""
    with needs("ray", "--engine ray"):
        import ray

    if ray.is_initialized():
        return False
    os.environ.setdefault("RAY_AUTH_MODE", "disabled")  # a local instance, or a cluster the user set up
    # Ray runs its workers at nice 15 unless told otherwise: on a busy machine they would then
    # wait behind everything else. These jobs are the work asked for.
    os.environ.setdefault("RAY_worker_niceness", "0")
    kwargs: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False, "configure_logging": False}
    if engine.address is None:
        kwargs["num_cpus"] = engine.n_workers
    try:
        ray.init(address=engine.address, **kwargs)
    except (ConnectionError, RuntimeError, ValueError) as exc:
        raise UserError("--address" if engine.address else "--engine", f"Ray did not start: {str(exc).splitlines()[0]}") from None
    return True


def _run_ray(fn: Callable, jobs: list, engine: Engine, progress: Callable[[int, int], None] | None) -> list[Outcome]:
    """The ``ray`` engine: one Ray task per job, on ``engine``'s instance or cluster."""
    started_here = start_ray(engine)
    import ray  # start_ray has imported it, or said which extra brings it

    try:
        task = ray.remote(num_cpus=1)(_guarded)
        refs = [task.remote(fn, job) for job in jobs]
        index = {ref: i for i, ref in enumerate(refs)}
        outcomes: list[tuple[bool, Any] | None] = [None] * len(jobs)
        pending = list(refs)
        done = 0
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            for ref in ready:
                outcomes[index[ref]] = ray.get(ref)
                done += 1
                if progress:
                    progress(done, len(jobs))
        return outcomes  # type: ignore[return-value]
    finally:
        if started_here:
            ray.shutdown()
