"""The reproduction's relief part (SPEC 19): recipe ``teach`` taught by a driver with a relief
style on the relief teaching course (``teach_relief``), judged on a packaged relief course and on
generated relief layouts; agreement with the driver on terrain and relief zones, speed error by
grade and roughness band, tips, time stuck and contact, and a figure of speed and height along
one relief course, driver against planner."""

from __future__ import annotations

from dataclasses import dataclass

from terrapref.demos.relief_style import RELIEF_STYLES, ReliefStyle
from terrapref.evaluation.runner import PLANNER, RunResult, summarise
from terrapref.evaluation.scoring import RELIEF_MIN_M, RELIEF_ZONE_DEG
from terrapref.evaluation.speed import SpeedComparison
from terrapref.evaluation.stats import rate_text
from terrapref.report.reproduce_speed import SPEEDS, SpeedPart, speeds_text
from terrapref.terrain import default_classes

COURSE = "teach_relief"  # the course the driver teaches on
JUDGED = ("relief_demo", "genrelief:101", "genrelief:102")  # the courses driven: a packaged relief course, generated relief layouts
FIGURE_COURSE = "relief_demo"  # the course of the speed-and-height figure
STYLE = "default"  # the driver's relief style (terrapref.demos.relief_style.RELIEF_STYLES)


@dataclass(frozen=True)
class ReliefPart:
    """What the relief part runs: recipe ``teach`` for ``seeds`` seeds, taught on :data:`COURSE` by
    the driver of ``speeds`` and the relief style named ``style``, on ``courses``."""

    seeds: int
    profile: tuple[str, ...]
    courses: tuple[str, ...] = JUDGED
    speeds: tuple[tuple[str, float], ...] = SPEEDS
    style: str = STYLE

    @property
    def relief(self) -> ReliefStyle:
        return ReliefStyle(**RELIEF_STYLES[self.style])

    @property
    def drives(self) -> SpeedPart:
        """The teaching drives, the training and the runs, as the speed part runs its own."""
        return SpeedPart(self.seeds, self.profile, self.courses, self.speeds, COURSE, self.relief, "relief")


def relief_lines(part: ReliefPart, results: list[RunResult], figure: str) -> list[str]:
    """REPORT.md's relief section: the setting, agreement on terrain and relief zones, speed error
    by grade and roughness band, safety, the time to the end, the figure."""
    planner = summarise(results, PLANNER)
    comparison = SpeedComparison.of_results(results, default_classes().background)
    lines = [
        "## Relief (recipe teach, a driver with a relief style)",
        "",
        f"Recipe teach taught by one drive of `{COURSE}` by the synthetic driver of the same order at {speeds_text(part.speeds)} "
        f"and relief style `{part.style}` ({RELIEF_STYLES.entry(part.style).doc}); {part.seeds} training seed(s); planner and driver "
        f"each drive {', '.join(f'`{c}`' for c in part.courses)} once per seed, clean frames. Relief zones: stretches of the "
        f"path, {RELIEF_MIN_M:g} m or more, whose ground tilts the body past {RELIEF_ZONE_DEG:g} deg, passed over or round on one side.",
        "",
        "| measure | planner against its driver |",
        "|---|---|",
        f"| agreement on terrain zones | {_rate(planner.agreement_rate, planner.agreement_ci95, planner.agreement_zones)} |",
        f"| agreement on relief zones | {_rate(planner.relief_agreement_rate, planner.relief_agreement_ci95, planner.relief_agreement_zones)} |",
    ]
    lines += [f"| speed error going {band} [m/s] | {e.text()} |" for band, e in comparison.by_grade.items() if band != "level"]
    lines += [f"| speed error on level ground [m/s] | {e.text()} |" for band, e in comparison.by_grade.items() if band == "level"]
    lines += [f"| speed error on {band} ground [m/s] | {e.text()} |" for band, e in comparison.by_roughness.items()]
    if comparison.time_ratio is not None:
        lines.append(
            f"| time to the end over the driver's | {comparison.time_ratio.text()}; within 5% in {rate_text(*comparison.time_within)} |"
        )
    lines += [
        f"| completed | {rate_text(round(planner.completed_rate * planner.runs), planner.runs) if planner.completed_rate is not None else '-'} |",
        f"| tips, times stuck, contact with lethal terrain | {planner.tip_count}, {planner.stuck_count}, {planner.contact_s:.1f} s |",
        f"| stops per 100 m | {100 * planner.stop_count / planner.driven_m:.2f} |" if planner.driven_m > 0 else "| stops per 100 m | - |",
    ]
    return lines + ["", f"![speed and height along {FIGURE_COURSE}]({figure})", ""]


def _rate(rate: float | None, ci: tuple[float, float] | None, n: int) -> str:
    if rate is None or ci is None:
        return "-"
    return f"{100 * rate:.1f}% (95% CI {100 * ci[0]:.1f}-{100 * ci[1]:.1f}%, {n} zones)"
