"""The reproduction's speed part: recipe ``teach`` taught by a driver with speed preferences on the
field UGV (SPEC 18), beside the paper's setting at 1 m/s; a table of speed by class (driver,
planner, error) and a figure of speed along one course, driver against planner."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from terrapref.demos.relief_style import ReliefStyle
from terrapref.evaluation.runner import EXPERT, PLANNER, RunResult, RunSpec, annotate_agreement, run_many
from terrapref.evaluation.speed import SpeedComparison, save_speed_along
from terrapref.evaluation.stats import rate_text
from terrapref.grid import Engine, run_grid
from terrapref.recipes import TEACH, RecipeSetup, run_recipe
from terrapref.scenario import resolve_scenario
from terrapref.terrain import PreferenceProfile, default_classes

SPEEDS = (("grass", 1.6), ("rock", 1.0), ("mud", 0.5), ("water", 0.3))  # the driver's cruising speeds [m/s]
FIGURE_COURSE = "test_course"  # the course of the speed-along-the-path figure


@dataclass(frozen=True)
class SpeedPart:
    """What the speed part runs: recipe ``teach`` for ``seeds`` seeds, taught by the driver of
    ``speeds`` (and of the relief style ``relief``; None: it drives relief as if flat) on
    ``course`` (None: the recipe's own), on ``courses``; ``name`` names its work folders and its
    log line (the relief part runs as one: terrapref.report.reproduce_relief)."""

    seeds: int
    profile: tuple[str, ...]
    courses: tuple[str, ...]
    speeds: tuple[tuple[str, float], ...] = SPEEDS
    course: str | None = None
    relief: ReliefStyle | None = None
    name: str = "speed"


def _train(job: tuple[str, int, SpeedPart]) -> str:
    workdir, seed, part = job
    setup = RecipeSetup(seed, PreferenceProfile(part.profile), course=part.course, speeds=part.speeds, relief=part.relief)
    return str(run_recipe(TEACH, workdir, setup).model)


def run_speed_part(part: SpeedPart, out: Path, engine: Engine, log: Callable[[str], None]) -> list[RunResult]:
    """Train, then drive every course with each model and with the driver (the field UGV); the runs, annotated with agreement."""
    jobs = [(str(out / "work" / f"{part.name}_seed{s}"), s, part) for s in range(part.seeds)]
    taught = f" on {part.course}" if part.course is not None else ""
    log(f"      {part.name}: recipe teach x {part.seeds} seeds{taught}, the driver at {speeds_text(part.speeds)} ...")
    models = run_grid(_train, jobs, engine, describe=lambda j: f"{part.name}, seed {j[1]}")
    specs = [RunSpec(c, s, PLANNER, m, part.profile) for s, m in enumerate(models) for c in part.courses]
    specs += [
        RunSpec(c, s, EXPERT, None, part.profile, speeds=part.speeds, relief=part.relief) for s in range(part.seeds) for c in part.courses
    ]
    return annotate_agreement(run_many(specs, engine=engine))


def speeds_text(speeds: Sequence[tuple[str, float]]) -> str:
    return ", ".join(f"{name} {v:g} m/s" for name, v in speeds)


def speed_lines(part: SpeedPart, results: list[RunResult], figure: str) -> list[str]:
    """REPORT.md's speed section: the setting, speed by class (driver, planner, error), time to the end of the path, the figure."""
    comparison = SpeedComparison.of_results(results, default_classes().background)
    lines = [
        "## Speed (recipe teach, a driver with speed preferences)",
        "",
        f"Recipe teach taught by the synthetic driver of the same order at {speeds_text(part.speeds)}, on the field UGV "
        "(0-2 m/s, 1 m/s^2 up, 2 m/s^2 down) instead of the paper's 1 m/s; "
        f"{part.seeds} training seed(s); planner and driver each drive the test course and the figure variations once per seed. "
        "Speed on a class: the mean speed while the vehicle's centre is on it, over all runs; error: the mean absolute "
        "difference of the mean speed through a zone, over the zones where both took the class (95% intervals resampling courses).",
        "",
        "| class | driver [m/s] | planner [m/s] | error [m/s] |",
        "|---|---|---|---|",
    ]
    driver, planner = _by_class(results, EXPERT), _by_class(results, PLANNER)
    for name in sorted(set(driver) | set(planner)):
        error = comparison.by_class.get(name)
        lines.append(f"| {name} | {_mean(driver.get(name))} | {_mean(planner.get(name))} | {error.text() if error else '-'} |")
    if comparison.time_ratio is not None:
        lines += [
            "",
            f"Time to the end of the path, the planner's over the driver's: {comparison.time_ratio.text()}; within 5% in "
            f"{rate_text(*comparison.time_within)} of the runs.",
        ]
    return lines + ["", f"![speed along {FIGURE_COURSE}]({figure})", ""]


def _by_class(results: list[RunResult], driver: str) -> dict[str, tuple[float, float]]:
    """Per class, (seconds, metres) on it over the runs of ``driver``."""
    out: dict[str, tuple[float, float]] = {}
    for r in results:
        if r.driver != driver:
            continue
        for name, entry in r.metrics.speed_by_class_mps.items():
            s, m = out.get(name, (0.0, 0.0))
            out[name] = (s + entry["s"], m + entry["s"] * entry["mps"])
    return out


def _mean(entry: tuple[float, float] | None) -> str:
    return f"{entry[1] / entry[0]:.2f}" if entry and entry[0] > 0 else "-"


def speed_figure(path: Path, results: list[RunResult], course: str = FIGURE_COURSE) -> Path | None:
    """Speed along ``course``'s path, the driver's against the planner's (seed 0); None when neither ran it."""
    return save_speed_along(path, results, resolve_scenario(course), course)
