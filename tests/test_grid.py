"""Grids of jobs on local processes and on Ray: the same results in the jobs' order, progress as
they finish, and failures reported with their inputs."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from helpers import TINY_COURSE, linear_model
from terrapref.cli import main
from terrapref.errors import UserError
from terrapref.grid import Engine, GridError, run_grid


def square(x: int) -> int:
    return x * x


def fails_on_three(x: int) -> int:
    if x == 3:
        raise ZeroDivisionError("three is not allowed")
    return x


def bad_input(x: int) -> int:
    raise UserError(f"input_{x}.yaml", "not a scenario", field="format")


@pytest.mark.parametrize("workers", [1, 2])
def test_local_grids_keep_the_jobs_order_and_report_progress(workers):
    seen = []
    assert run_grid(square, range(7), Engine(workers=workers), progress=lambda k, n: seen.append((k, n))) == [x * x for x in range(7)]
    assert seen == [(k, 7) for k in range(1, 8)]


@pytest.mark.parametrize("workers", [1, 2])
def test_a_failed_job_is_reported_with_its_inputs_after_the_others_ran(workers):
    done = []
    with pytest.raises(GridError) as info:
        run_grid(fails_on_three, range(6), Engine(workers=workers), progress=lambda k, n: done.append(k), describe=lambda x: f"job x={x}")
    assert done[-1] == 6, "every job ran"
    assert info.value.failures == [("job x=3", "ZeroDivisionError: three is not allowed")]
    assert str(info.value).startswith("1 of 6 jobs failed: job x=3: ZeroDivisionError")


def test_workers_fork_after_this_process_made_a_relief_noise(tmp_path):
    """A relief's noise is computed in compiled parallel loops; the local grid's workers, forked
    after it (`reproduce` rasterises teach_relief, then drives), still run (a fresh interpreter:
    the threading layer is chosen once per process)."""
    import subprocess
    import sys

    script = (
        "import numpy as np\n"
        "from terrapref.grid import Engine, run_grid\n"
        "from terrapref.scenario.relief import Noise\n"
        "from terrapref.world.relief import noise_height\n"
        "def heights(seed):\n"
        "    return round(float(noise_height(Noise(0.1, 0.3, seed), np.arange(200) * 0.05, np.arange(200) * 0.05).sum()), 6)\n"
        "here = [heights(s) for s in (1, 2, 3)]\n"
        "print(run_grid(heights, [1, 2, 3], Engine(workers=2)) == here)\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert done.returncode == 0 and done.stdout.strip() == "True", done.stderr[-2000:]


def stopped_inside_compiled_code(job: int) -> int:
    """A job whose stop (Ctrl-C) arrives while compiled code runs: numba hands it back as a
    SystemError raised while the KeyboardInterrupt is being handled."""
    try:
        raise KeyboardInterrupt
    except KeyboardInterrupt:
        raise SystemError("CPUDispatcher(<function f>) returned a result with an exception set") from None


def test_a_stop_inside_compiled_code_stops_the_grid_rather_than_failing_a_job():
    with pytest.raises(KeyboardInterrupt):
        run_grid(stopped_inside_compiled_code, [0], Engine(workers=1))


def test_a_bad_input_in_a_job_is_the_users_error_naming_the_file():
    with pytest.raises(UserError, match="input_0.yaml"):
        run_grid(bad_input, [0, 1], Engine(workers=2))


def test_engines_are_validated():
    with pytest.raises(ValueError, match="unknown engine"):
        Engine("spark")
    with pytest.raises(ValueError, match="address"):
        Engine("local", address="10.0.0.1:6379")
    with pytest.raises(ValueError, match="workers"):
        Engine(workers=0)


def test_cli_engine_flags_are_checked_before_any_work(tmp_path, capsys):
    model = linear_model(tmp_path / "m.safetensors")
    out = tmp_path / "eval"
    assert main(["evaluate", str(model), "demo_course", "--out", str(out), "--address", "10.0.0.1:6379"]) == 2
    assert "--engine ray" in capsys.readouterr().err
    assert main(["study", "--out", str(tmp_path / "s"), "--workers", "0"]) == 2
    assert "--workers" in capsys.readouterr().err
    with pytest.raises(SystemExit) as info:  # argparse's own refusal of an unknown choice
        main(["reproduce", "--out", str(tmp_path / "r"), "--engine", "spark"])
    assert info.value.code == 2
    assert not out.exists()


@pytest.fixture(scope="module")
def ray_instance():
    """A local Ray instance with 2 CPUs for the module's grids (starting one takes seconds): a grid
    on the ray engine uses the instance this process is connected to, and leaves it running."""
    import ray

    from terrapref.grid import start_ray

    assert start_ray(Engine("ray", workers=2))
    yield
    ray.shutdown()


@pytest.mark.slow  # a Ray instance takes seconds to start and to stop; the local engine's grids are tested above
def test_ray_reports_a_failed_job_with_its_inputs(ray_instance):
    import math

    with pytest.raises(GridError) as info:
        run_grid(math.sqrt, [4.0, -1.0, 9.0], Engine("ray", workers=2), describe=lambda x: f"sqrt({x})")
    assert info.value.failures == [("sqrt(-1.0)", "ValueError: math domain error")]


@pytest.mark.slow  # as above
def test_cli_evaluate_on_ray_gives_the_local_engines_results(tmp_path, capsys, ray_instance):
    """The planner and the driver on a local Ray instance with 2 CPUs: the same runs, the same numbers."""
    model, course = str(linear_model(tmp_path / "m.safetensors")), str(TINY_COURSE)
    assert main(["evaluate", model, course, "--seeds", "2", "--out", str(tmp_path / "local"), "--workers", "2"]) == 0
    assert main(["evaluate", model, course, "--seeds", "2", "--out", str(tmp_path / "ray"), "--engine", "ray", "--workers", "2"]) == 0
    a, b = (json.loads(Path(tmp_path / d / "metrics.json").read_text()) for d in ("local", "ray"))
    assert a["summary"]["zones"] > 0 and a == b


def test_select_refuses_bad_flags_before_any_work(tmp_path, capsys):
    out = tmp_path / "sel"
    for argv, flag in (
        (["--recipes", "teach,nope"], "--recipes"),
        (["--recipes", "teach,"], "--recipes"),
        (["--orders", "mud,lava"], "--orders"),
        (["--seeds", "0"], "--seeds"),
        (["--orders", "mud,rock,water;mud,rock,water,non_traversable"], "--orders"),
        (["--style", "sleepy"], "--style"),
        (["--style", ""], "unknown driver style ''"),
        (["--first", "-1"], "--first"),
        (["--address", "h:1"], "--address"),
        (["--speeds", "nosuch=1"], "--speeds"),
        (["--speeds", "grass=3"], "--speeds"),
        (["--speeds", "fast"], "--speeds"),
        (["--speeds", "mud=0"], "class 'mud'"),
        (["--engine", "ray", "--address", "127.0.0.1:99999"], "expected HOST:PORT"),
        (["--perception", "field:foo"], "NAME:PART (labels, pose"),
        (["--first", str(2**63 - 1), "--courses", "2"], "--first"),  # the second layout's seed would be past 2^63 - 1
    ):
        assert main(["select", "--out", str(out), *argv]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and flag in err[0]
    assert not out.exists()


def test_select_refuses_an_output_that_holds_an_input_or_a_course_of_another_table(tmp_path, capsys, monkeypatch):
    """With --force an output folder is replaced whole: one holding an input file would take it
    with it, and the current folder cannot be replaced. A course of another class table than
    the selection's is refused before any training."""
    from terrapref.terrain import load_classes

    out = tmp_path / "sel"
    out.mkdir()
    (out / "p.yaml").write_text("format: terrapref-perception/1\nframes: {drop_rate: 0.1}\n")
    assert main(["select", "--out", str(out), "--perception", str(out / "p.yaml"), "--force"]) == 2
    one_line = capsys.readouterr().err.strip().splitlines()
    assert len(one_line) == 1 and "--out" in one_line[0] and "holds the input" in one_line[0] and (out / "p.yaml").exists()
    monkeypatch.chdir(out)
    assert main(["select", "--out", ".", "--force"]) == 2
    assert "is the current folder" in capsys.readouterr().err
    table = tmp_path / "t.yaml"
    table.write_text(
        "format: terrapref-classes/1\nclasses:\n  - {id: 0, name: grass, color: [0, 160, 0]}\n  - {id: 1, name: mud, color: [120, 80, 40]}\n  - {id: 2, name: tree, color: [0, 60, 0]}\nbackground: grass\nlethal: [tree]\n"
    )
    load_classes(table)  # a table of its own
    course = tmp_path / "c.yaml"
    assert main(["course", "--classes", str(table), "--out", str(course)]) == 0
    capsys.readouterr()
    assert main(["select", "--course", str(course), "--out", str(tmp_path / "s2")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(course) in err[0] and "class table" in err[0] and not (tmp_path / "s2").exists()


@pytest.mark.slow
def test_select_on_ray_gives_the_local_engines_table(tmp_path):
    """The paper's recipe (quick to train), one order, one seed, two layouts, on both engines."""
    argv = ["select", "--recipes", "paper", "--orders", "rock,mud,water", "--seeds", "1", "--courses", "2", "--workers", "2"]
    assert main([*argv, "--out", str(tmp_path / "local")]) == 0
    assert main([*argv, "--out", str(tmp_path / "ray"), "--engine", "ray"]) == 0
    a, b = (json.loads((tmp_path / d / "select.json").read_text()) for d in ("local", "ray"))
    assert len(a["zones"]) >= 8 and a["zones"] == b["zones"] and a["runs"] == b["runs"]
    assert "| paper | rock > mud > water > non_traversable |" in (tmp_path / "ray" / "SELECT.md").read_text()


def test_a_ray_address_where_nothing_answers_is_refused_in_one_line(tmp_path, capsys):
    import socket

    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    model = linear_model(tmp_path / "m.safetensors")
    for address, words in ((f"127.0.0.1:{port}", "no Ray head answers"), ("nonsense", "HOST:PORT")):
        assert main(["evaluate", str(model), "demo_course", "--out", str(tmp_path / "e"), "--engine", "ray", "--address", address]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--address" in err[0] and words in err[0], err
    assert not (tmp_path / "e").exists()


def slow_mark(path: str) -> int:
    """A job that writes ``path`` after a second and a half."""
    import time

    time.sleep(1.5)
    Path(path).write_text("done")
    return 0


def test_a_killed_commands_workers_end_with_it(tmp_path):
    """`kill -9` of a command with workers: they end with it, and write nothing more into its
    output (they used to finish their jobs there, and hold its lock, for ever)."""
    import signal
    import subprocess
    import sys
    import time

    marks = [str(tmp_path / f"mark{i}") for i in range(2)]
    script = (
        "import sys; sys.path.insert(0, 'tests'); import test_grid as t; from terrapref.grid import Engine, run_grid; "
        f"run_grid(t.slow_mark, {marks!r}, Engine('local', 2))"
    )
    with subprocess.Popen([sys.executable, "-c", script], cwd=Path(__file__).parent.parent) as proc:
        workers: list[int] = []
        while len(workers) < 2:  # no time limit: both workers fork, or the command ends, which fails the test
            assert proc.poll() is None, "the command ended before its workers were seen"
            workers = [int(pid) for pid in subprocess.run(["pgrep", "-P", str(proc.pid)], capture_output=True, text=True).stdout.split()]
            time.sleep(0.05)
        proc.send_signal(signal.SIGKILL)
    assert len(workers) == 2
    for _ in range(200):  # ended, they write nothing more: waited for up to 10 s, past the jobs' end had they gone on
        if not any(_running(pid) for pid in workers):
            break
        time.sleep(0.05)
    assert not any(_running(pid) for pid in workers)
    assert not any(Path(mark).exists() for mark in marks)


def _running(pid: int) -> bool:
    """Whether process ``pid`` runs (an ended one not yet reaped, a zombie, does not)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError):
        return False
