"""The size `study` and `reproduce` announce before any work, as `select` does, counted as their
jobs are listed, and the bound beyond which they need --large."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from terrapref.cli import main
from terrapref.errors import UserError
from terrapref.perception import load_perception
from terrapref.report.reproduce import RecipeModel, Reproduction, evaluation_specs, reproduction_workload
from terrapref.report.reproduce_relief import ReliefPart
from terrapref.report.study import PARTS, TaughtModel, _evaluation_runs, _train_jobs, study_workload, teach_jobs
from terrapref.report.study_plan import FULL, QUICK, TrainedModel
from terrapref.report.workload import Workload

ABSURD = "99999999999999999999"


def test_the_study_workload_counts_the_jobs_and_runs_the_study_lists(tmp_path):
    for plan in (replace(QUICK, seeds=2), FULL):
        size = study_workload(plan)
        trained = [TrainedModel(job, 1, 0.0) for job in _train_jobs(plan, tmp_path)]
        taught = [TaughtModel(job, f"{job.workdir}.safetensors", 1.0, 0.0) for job in teach_jobs(plan, tmp_path)]
        assert size.models == len(trained) + len(taught)
        base = load_perception(plan.sweep_base, plan.classes)
        default_style = sum(t.job.style == "default" for t in taught)
        swept = len(plan.sweep) * sum(base.part(p).active for p in PARTS) * len(plan.layouts) * default_style  # no part dropping out
        assert size.runs == len(_evaluation_runs(plan, trained, taught)) + swept and size.up_to


def test_the_reproduction_workload_counts_the_models_and_runs_it_lists():
    setup = Reproduction(seeds=3, eval_seeds=2, perceptions=(load_perception("clean"), load_perception("field")), speed_seeds=2)
    size = reproduction_workload(setup)
    trained = [RecipeModel(r.name, s, f"{r.name}_{s}.safetensors", (), 0, 1.0, 0.0, 0.0) for s in range(3) for r in setup.recipes]
    relief = ReliefPart(1, setup.profile.order)
    parts = 2 * 2 * (len(setup.scenarios) - 1) + 2 * len(relief.courses)  # the speed part drives the test courses, the relief part its own
    assert size.models == len(trained) + 2 + 1
    assert size.runs == len(evaluation_specs(setup, trained)) + parts and not size.up_to


def test_a_workload_beyond_the_bound_is_large_and_says_so_in_one_line(monkeypatch):
    monkeypatch.setattr("os.cpu_count", lambda: 4)
    assert not Workload(1_000, "", 100_000, 1.0, "").large
    assert Workload(1_001, "", 1, 1.0, "").large and Workload(1, "", 100_001, 1.0, "").large
    huge = Workload(10**400, "x", 10**401, float("inf"), "1 course")
    assert huge.describe(2).endswith(": more than a billion years on 2 workers (more than a billion years of one core)")
    assert "\n" not in huge.refusal()


def test_workers_beyond_the_machines_cores_make_it_no_faster(monkeypatch):
    monkeypatch.setattr("os.cpu_count", lambda: 2)
    work = Workload(1, "1 recipe", 10, 600.0, "2 layouts")
    assert work.describe(2).endswith(": about 5 min 0 s on 2 workers (about 10 min 0 s of one core)")
    assert work.describe(1000).endswith(": about 5 min 0 s on 1000 workers, 2 cores here (about 10 min 0 s of one core)")


@pytest.mark.parametrize("command", ["study", "reproduce"])
def test_study_and_reproduce_say_at_once_how_much_they_would_make_and_refuse_an_absurd_size(tmp_path, capsys, monkeypatch, command):
    def started(*args, **kwargs):
        raise AssertionError("the work started")

    monkeypatch.setattr("terrapref.report.study.run_study", started)
    monkeypatch.setattr("terrapref.report.reproduce.reproduce", started)
    out = tmp_path / "out"
    assert main([command, "--seeds", ABSURD, "--workers", "2", "--out", str(out)]) == 2
    captured = capsys.readouterr()
    assert captured.out.startswith(f"{command}: ") and f"{ABSURD[:2]},{ABSURD[2:5]}," in captured.out
    assert "closed-loop runs" in captured.out and "on 2 workers" in captured.out
    (line,) = captured.err.strip().splitlines()
    assert line.startswith("error: --seeds") and "are more than 1,000 models or 100,000 runs" in line and "--large" in line
    assert not out.exists()


@pytest.mark.parametrize(
    ("command", "runs"), [("study", "terrapref.report.study.run_study"), ("reproduce", "terrapref.report.reproduce.reproduce")]
)
def test_large_runs_a_study_or_reproduction_beyond_the_bound(tmp_path: Path, capsys, monkeypatch, command: str, runs: str):
    def started(*args, **kwargs):
        raise UserError(command, "started")

    monkeypatch.setattr(runs, started)
    argv = [command, "--seeds", "400", "--out", str(tmp_path / "out")]  # 400 seeds: more than 1,000 models either way
    assert main(argv) == 2 and "--large" in capsys.readouterr().err
    assert main([*argv, "--large"]) == 2
    captured = capsys.readouterr()
    assert captured.out.startswith(f"{command}: ") and f"{command}: started" in captured.err
