"""Fixtures shared across test modules, built once per test run, and the run's BLAS threads."""

from __future__ import annotations

import gc
import json
import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from types import SimpleNamespace

import pytest

MACHINE_ENVIRON = dict(os.environ)
"""The environment the test run started with: the CPU-setting checks' setting ``{}`` runs in it."""

# OpenBLAS's threads wait for each other spinning. Where every core is busy (a small machine
# running several test runs at once) each of the small matrix products that training C makes
# then waits out a scheduler time slice, and a test that trains takes ten times as long or
# more. The tests, and the processes they start, use one BLAS thread unless the run was started
# with a count; the bits do not depend on it (test_exact trains in fresh interpreters under
# other thread counts, the machine's default among them).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before NumPy is first imported, which reads it

# The run's temporary folders in memory (a tmpfs), where the machine has one and the run was not
# given a TMPDIR: the tests write and remove tens of thousands of small files (a recording's
# frames, exports, models), which on a disk took a third of the run, most of it removing them.
SHM_FREE_B = 4 << 30  # the most a run keeps in its temporary folders, with room to spare


def _roomy_tmpfs(folder: str) -> bool:
    """Whether ``folder`` is writable with room for a run (a container's /dev/shm may hold 64 MiB)."""
    if not (os.path.isdir(folder) and os.access(folder, os.W_OK)):
        return False
    found = os.statvfs(folder)
    return found.f_bavail * found.f_frsize >= SHM_FREE_B


if "TMPDIR" not in os.environ and _roomy_tmpfs("/dev/shm"):
    os.environ["TMPDIR"] = "/dev/shm"  # for the processes the tests start too
    tempfile.tempdir = None  # tempfile reads TMPDIR again


def built_once(tmp_path_factory: pytest.TempPathFactory, name: str, build: Callable[[Path], object]) -> Path:
    """The folder ``name`` of this test run, made by ``build(folder)`` once for the whole run.

    pytest-xdist's workers each have a session of their own, so a session fixture is built once
    per worker; what this makes is built by the first worker that asks, under a file lock, and
    read by the others. ``build`` must make the same thing in any worker (seeded, no clock).
    """
    from filelock import FileLock

    base = tmp_path_factory.getbasetemp()
    run = base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base  # each worker's base lies in the run's
    out, done = run / "built_once" / name, run / "built_once" / f"{name}.done"
    out.parent.mkdir(exist_ok=True)
    with FileLock(str(out.parent / f"{name}.lock")):
        if not done.exists():
            shutil.rmtree(out, ignore_errors=True)  # what a build that failed left
            out.mkdir()
            build(out)
            done.touch()
    return out


def _record(out: Path, *argv: str) -> None:
    from terrapref.cli import main

    assert main(["record", *argv, "--out", str(out / "rec"), "--quiet"]) == 0


@pytest.fixture(scope="session")
def fig7_recording(tmp_path_factory) -> Path:
    """An undisturbed recording of the synthetic driver on fig7_rock_vs_non_traversable_left
    (about 600 frames, up to the rock and the trees). Shared: read it, never write into it."""
    return built_once(tmp_path_factory, "fig7", lambda out: _record(out, "fig7_rock_vs_non_traversable_left", "--disturb", "0")) / "rec"


@pytest.fixture(scope="session")
def short_recording(tmp_path_factory) -> Path:
    """An undisturbed recording of the synthetic driver on tests/data/short_course.yaml (about 320
    frames, every class of the default table): for a test that needs a drive, not a particular
    one. Shared: read it, never write into it (copy it first)."""
    from helpers import SHORT_COURSE

    return built_once(tmp_path_factory, "short", lambda out: _record(out, str(SHORT_COURSE), "--disturb", "0")) / "rec"


@pytest.fixture(scope="session")
def tiny_recording(tmp_path_factory) -> Path:
    """An undisturbed recording of the synthetic driver on tests/data/tiny_course.yaml (about 106
    frames, grass and mud): for a test that needs a recording, not what it shows. Shared: read it,
    never write into it (copy it first)."""
    from helpers import TINY_COURSE

    return built_once(tmp_path_factory, "tiny", lambda out: _record(out, str(TINY_COURSE), "--disturb", "0")) / "rec"


@pytest.fixture(scope="session")
def relief_recording(tmp_path_factory) -> Path:
    """An undisturbed recording of the synthetic driver on tests/data/tiny_relief.yaml (about 56
    frames over a low mound, each with its depth image and the body's attitude): for a test that
    needs a recording on relief. Shared: read it, never write into it (copy it first)."""
    from helpers import TINY_RELIEF

    return built_once(tmp_path_factory, "relief", lambda out: _record(out, str(TINY_RELIEF), "--disturb", "0")) / "rec"


@pytest.fixture(scope="session")
def demo_course_recording(tmp_path_factory) -> Path:
    """``terrapref record demo_course`` as a user runs it: the synthetic driver, seed 0, pushed at
    the default rate (about 575 frames). Shared: read it, never write into it (copy it first)."""
    return built_once(tmp_path_factory, "demo_course", lambda out: _record(out, "demo_course")) / "rec"


@pytest.fixture(scope="session")
def demo_course_drive(tmp_path_factory) -> SimpleNamespace:
    """The synthetic driver's undisturbed drive of demo_course (default style and profile, seed 0)
    through the session loop: its ``scenario``, the ``sim`` it ended in, the episode ``log`` and
    the recording's ``path``: the drive a recipe without pushes demonstrates first under seed 0.
    Shared: read it, never write into it or step its simulation."""
    import numpy as np

    from terrapref.demos.expert import ExpertDriver
    from terrapref.demos.meta import ExpertInfo, RecordingMeta, RecordingSetup
    from terrapref.demos.recording import RecordingWriter
    from terrapref.demos.session import RunSettings, record_run
    from terrapref.features import PreferenceSetConfig
    from terrapref.scenario import resolve_scenario
    from terrapref.sim import Simulation
    from terrapref.terrain import PreferenceProfile

    out = tmp_path_factory.mktemp("demo_course_drive") / "rec"
    scenario = resolve_scenario("demo_course")
    sim = Simulation(scenario)
    driver = ExpertDriver()
    preference = PreferenceSetConfig()
    meta = RecordingMeta.driven(
        scenario,
        RecordingSetup(sim.camera.config, preference, sim.config),
        ExpertInfo.of(0, "default", driver.config),
        PreferenceProfile.default(),
    )
    log = record_run(sim, driver, RecordingWriter(out, meta, scenario.to_dict()), RunSettings(preference), np.random.default_rng(0))
    return SimpleNamespace(scenario=scenario, sim=sim, log=log, path=out)


def _cpu_outputs(request, tmp_path_factory, fixture: str, every: bool) -> dict:
    """What each module's bit-for-bit check (its ``CPU_CHECK``, tests/cpu_settings.py) printed
    under its CPU settings (every one, or the quick ones), by check name: one fresh interpreter
    per setting runs the checks of every collected test that takes ``fixture``, once for the run
    (every worker collects the same tests, so each would ask for the same checks)."""
    from cpu_settings import run_checks

    checks = sorted(
        {item.module.CPU_CHECK for item in request.session.items if fixture in getattr(item, "fixturenames", ())},
        key=lambda c: c.name,
    )
    checks = checks if every else [c.quick() for c in checks]
    # The quick ones run with the tests' one BLAS thread (below): a machine's default threads spin
    # while they wait, which on a busy machine costs more than the check itself.
    environ = MACHINE_ENVIRON if every else dict(os.environ)

    def build(out: Path) -> None:
        (out / "outputs.json").write_text(json.dumps(run_checks(checks, environ)))

    outputs = json.loads((built_once(tmp_path_factory, fixture, build) / "outputs.json").read_text())
    return {name: [(setting, printed) for setting, printed in runs] for name, runs in outputs.items()}


@pytest.fixture(scope="session")
def cpu_outputs(request, tmp_path_factory) -> dict:
    """The checks under the quick settings (cpu_settings.QUICK), for the default run."""
    return _cpu_outputs(request, tmp_path_factory, "cpu_outputs", every=False)


@pytest.fixture(scope="session")
def cpu_outputs_every(request, tmp_path_factory) -> dict:
    """The checks under every one of their settings, for the slow tests."""
    return _cpu_outputs(request, tmp_path_factory, "cpu_outputs_every", every=True)


# Tests that spend most of their time waiting on other processes (ROS nodes starting, a log played
# in real time) run first: one worker waits on them while the others run the rest, rather than
# the run ending with one worker waiting alone.
WAITING_FIRST = ("tests/interop/test_ros2.py", "tests/interop/test_ros1.py")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    items.sort(key=lambda item: not item.nodeid.startswith(WAITING_FIRST))  # a stable sort: the rest keep their order


def pytest_collection_finish(session: pytest.Session) -> None:
    """Collected, the test modules and what they import (NumPy, PyTorch, Matplotlib, the package)
    are loaded for good: their objects are frozen out of the garbage collector's reach, so that
    each full collection during the run (and pytest's at its end) does not walk them again."""
    gc.collect()
    gc.freeze()
