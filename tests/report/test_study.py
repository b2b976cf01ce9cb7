"""`terrapref study`: the report's arithmetic over seeds (zone success per seed, mean ± std), the
zones where two preference profiles disagree, the perception model of each robustness sweep, the
report written from fabricated runs, one tiny end-to-end study (slow) and the command's flags."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import pytest

from terrapref.cli import main
from terrapref.evaluation.runner import EXPERT, HAND_COST, PURE_PURSUIT
from terrapref.evaluation.scoring import RunMetrics, ZoneResult
from terrapref.grid import Engine
from terrapref.perception import load_perception
from terrapref.report.study import LEARNED, PARTS, run_study, swept
from terrapref.report.study_plan import FULL, QUICK, TEACH_ORDERS, StudyPlan, TrainedModel, TrainJob
from terrapref.report.study_report import (
    ALL,
    METHOD_NAMES,
    ModelVariant,
    RunTag,
    StudyRun,
    _cell,
    _per_seed,
    _rate,
    _select,
    _zone_success,
    disagreement_zones,
    write_study,
)

PNG = b"\x89PNG\r\n\x1a\n"
METHODS = ("C", "linear", "cnn", HAND_COST, PURE_PURSUIT, EXPERT)
SECTIONS = (
    "## Answers",
    "## 1. Baselines",
    "## 2. Data efficiency",
    "## 3. Another preference profile",
    "## 4. Robustness",
    "## 5. Ablations",
    "## 6. Any order, any driver",
)


def _zone(zid: str, expect: str, choice: str, success: bool | None = None) -> ZoneResult:
    return ZoneResult(zid, f"zone {zid}", expect, choice, expect == choice if success is None else success, False, {})


def _run(
    study: str,
    method: str,
    seed: int,
    zones: list[ZoneResult],
    scenario: str = "sc",
    collisions: int = 0,
    completed: bool = True,
    rms: float = 0.0,
    minutes=None,
    variant: str | None = None,
    order=None,
    **tag,
) -> StudyRun:
    """A run as run_study tags it; ``minutes`` or ``variant`` make it a trained model's own run."""
    model = ModelVariant(minutes, variant) if minutes is not None or variant is not None else None
    run_tag = RunTag(study, method, seed, model, order=tuple(order) if order is not None else None, **tag)
    return StudyRun(run_tag, scenario, RunMetrics(completed, collisions, 60.0, rms, rms, rms, {}, zones))


def _trained(study: str, method: str, seed: int, samples: int, minutes: float | None = None) -> TrainedModel:
    """A trained model's record as run_study keeps it; only the fields the report reads matter."""
    return TrainedModel(
        TrainJob(study, method, seed, "U.safetensors", f"{method}_s{seed}.safetensors", 1, 1, method, minutes=minutes), samples, 1.0
    )


def _successes(seed: int, flags: list[bool], study: str = "baselines", method: str = "C", **tag) -> StudyRun:
    return _run(study, method, seed, [_zone(str(i + 1), "mud", "mud", ok) for i, ok in enumerate(flags)], **tag)


# --- zone success per seed, mean and spread ---------------------------------------------------------


def test_rate_pools_zones_over_runs():
    # run means would be 1/3 and 1 (mean 2/3); pooled over zones it is 2/4
    runs = [_successes(0, [True, False, False]), _successes(0, [True])]
    assert _rate(runs) == pytest.approx(0.5)
    assert math.isnan(_rate([])) and math.isnan(_rate([_successes(0, [])]))


def test_per_seed_groups_by_seed_in_seed_order():
    runs = [_successes(1, [False, False]), _successes(0, [True, False, False]), _successes(2, [True, True]), _successes(0, [True])]
    assert _per_seed(runs) == pytest.approx([0.5, 0.0, 1.0])
    assert _per_seed([]) == []


def test_cell_mean_and_population_std_over_seeds():
    runs = [_successes(1, [False, False]), _successes(0, [True, False, False]), _successes(0, [True])]
    text, mean, std = _cell(runs)  # per seed: 0.5, 0.0
    assert mean == pytest.approx(0.25)
    assert std == pytest.approx(0.25)  # np.std: over the seeds themselves (ddof 0)
    assert text == "25.0% ± 25.0% [10%-70%]"  # 2 of 6 zones pooled: Wilson


def test_cell_three_seeds():
    runs = [_successes(0, [True, True, False]), _successes(1, [True, False, False]), _successes(2, [True, True, True])]
    text, mean, std = _cell(runs)
    assert mean == pytest.approx(2 / 3)
    assert std == pytest.approx(math.sqrt(((2 / 3 - 2 / 3) ** 2 + (1 / 3 - 2 / 3) ** 2 + (1 - 2 / 3) ** 2) / 3))
    assert text == "66.7% ± 27.2% [35%-88%]"


def test_cell_one_seed_has_no_spread_in_its_text():
    text, mean, std = _cell([_successes(0, [True, False, True, True]), _successes(0, [True, True, True, True])])
    assert (mean, std) == (pytest.approx(0.875), 0.0)
    assert text == "87.5% [53%-98%]"
    assert "±" not in text


def test_cell_of_nothing():
    text, mean, std = _cell([])
    assert text == "—"
    assert math.isnan(mean) and math.isnan(std)


def test_select_matches_every_key():
    runs = [
        _successes(0, [True], study="efficiency", minutes=0.5),
        _successes(0, [True], study="efficiency", minutes=ALL),
        _successes(1, [True], study="efficiency", minutes=0.5),
        _successes(0, [True], study="efficiency", method="cnn", minutes=0.5),
    ]
    assert _select(runs, study="efficiency", method="C", minutes=0.5) == [runs[0], runs[2]]
    assert _select(runs, study="efficiency", minutes=ALL) == [runs[1]]
    assert _select(runs, study="baselines") == []


# --- the zones where the two profiles disagree -------------------------------------------------------


def _profile_runs() -> list[StudyRun]:
    """The default-profile and other-profile driver runs over two scenarios, and distractors."""
    return [
        _run("baselines", EXPERT, 0, [_zone("1", "avoid", "avoid"), _zone("2", "mud", "mud"), _zone("3", "water", "water")], scenario="a"),
        _run("baselines", EXPERT, 0, [_zone("1", "mud", "mud"), _zone("2", "avoid", "avoid"), _zone("9", "mud", "mud")], scenario="b"),
        _run("profile", EXPERT, 0, [_zone("1", "avoid", "avoid"), _zone("2", "rock", "rock"), _zone("3", "water", "water")], scenario="a"),
        _run("profile", EXPERT, 0, [_zone("1", "rock", "rock"), _zone("2", "avoid", "avoid")], scenario="b"),  # no zone 9
        # not the seed-0 driver runs: ignored even though their expectations differ
        _run("profile", EXPERT, 1, [_zone("3", "rock", "rock")], scenario="a"),
        _run("baselines", EXPERT, 1, [_zone("2", "water", "water")], scenario="b"),
        _run("profile", "C", 0, [_zone("3", "rock", "mud")], scenario="a"),
        _run("baselines", "C", 0, [_zone("2", "rock", "rock")], scenario="b"),
    ]


def test_disagreement_zones_are_keyed_by_scenario_and_zone():
    assert disagreement_zones(_profile_runs()) == {("a", "2"), ("b", "1")}


def test_disagreement_zones_empty_without_both_driver_passes():
    runs = _profile_runs()
    assert disagreement_zones([r for r in runs if r.tag.study != "profile"]) == set()
    assert disagreement_zones([r for r in runs if r.tag.study != "baselines"]) == set()
    assert disagreement_zones([]) == set()


def test_disagreement_zones_empty_when_profiles_agree():
    same = [_zone("1", "avoid", "avoid"), _zone("2", "mud", "mud")]
    runs = [_run("baselines", EXPERT, 0, same), _run("profile", EXPERT, 0, list(same))]
    assert disagreement_zones(runs) == set()


def test_zone_success_counts_only_kept_zones():
    runs = [
        _run("profile", "C", 0, [_zone("1", "avoid", "water"), _zone("2", "rock", "rock"), _zone("3", "mud", "rock")], scenario="a"),
        _run("profile", "C", 0, [_zone("1", "rock", "mud"), _zone("2", "avoid", "avoid")], scenario="b"),
        _run("profile", "C", 1, [_zone("2", "rock", "rock")], scenario="a"),
    ]
    keep = {("a", "2"), ("b", "1")}
    assert _zone_success(runs, keep) == (2, 3)  # a/2 twice (both right), b/1 once (wrong); b/2 and a/3 left out
    assert _zone_success(runs, {("b", "2")}) == (1, 1)
    assert _zone_success(runs, set()) == (0, 0)
    assert _zone_success([], keep) == (0, 0)
    ok, n = _zone_success(runs, keep)
    assert isinstance(ok, int) and isinstance(n, int)


# --- the robustness sweep's perception models ---------------------------------------------------------


def test_a_swept_model_is_one_part_of_the_base_preset_scaled():
    field = load_perception("field")
    for part in PARTS:
        once = swept(FULL, part, 1.0)
        assert getattr(once, part) == getattr(field, part)
        assert [getattr(once, other).active for other in PARTS if other != part] == [False, False, False]
    twice = swept(FULL, "pose", 2.0)
    assert twice.pose.noise_m == 2 * field.pose.noise_m and twice.pose.drift_deg_per_m == 2 * field.pose.drift_deg_per_m
    assert swept(FULL, "frames", 4.0).frames.delay == 4 * field.frames.delay


def test_every_plan_sweeps_rising_levels_of_a_preset():
    for plan in (FULL, QUICK):
        assert list(plan.sweep) == sorted(plan.sweep) and plan.sweep[0] >= 1.0
        assert "clean" in plan.presets
        for name in plan.presets:
            load_perception(name)


# --- STUDY.md from fabricated runs (no simulation) ---------------------------------------------------


def _fabricated(plan: StudyPlan) -> tuple[list[StudyRun], list[TrainedModel]]:
    """Runs and trained-model records shaped like run_study's, on one scenario with three zones.

    Per seed (0, 1): C 3/3 and 1/3, linear 1/3 and 1/3, the CNN 0/3, the driver 3/3, the others 2/3.
    Zone 2 is the one where the profiles disagree (mud under the default, rock under the other)."""

    def zones(ok: int, expect2: str = "mud") -> list[ZoneResult]:
        exp = ["avoid", expect2, "avoid"]
        return [_zone(str(i + 1), e, e if i < ok else "water") for i, e in enumerate(exp)]

    rates = {"C": (3, 1), "linear": (1, 1), "cnn": (0, 0), HAND_COST: (2, 2), PURE_PURSUIT: (2, 2), EXPERT: (3, 3)}
    runs: list[StudyRun] = []
    trained: list[TrainedModel] = []
    for s in range(plan.seeds):
        for m in METHODS:
            runs.append(_run("baselines", m, s, zones(rates[m][s]), collisions=1 if m == PURE_PURSUIT else 0))
        for m in LEARNED:
            trained.append(_trained("baselines", m, s, 6600))
            for mins in plan.minutes:
                trained.append(_trained("efficiency", m, s, int(mins * 600), minutes=mins))
                runs.append(_run("efficiency", m, s, zones(1), minutes=mins))
        runs.append(_run("profile", EXPERT, s, zones(3, "rock")))
        runs.append(_run("profile", "C", s, zones(3, "rock")))
        runs.append(_run("profile_cross", "C", s, zones(1)))
        runs.append(_run("profile_cross", "C_default", s, zones(1, "rock")))
        for w in plan.widths:
            runs.append(_run("ablation", "C", s, zones(0), variant=f"hidden width {w}", collisions=2))
        runs += _taught(plan, s)
    return runs, trained


def _taught(plan: StudyPlan, seed: int) -> list[StudyRun]:
    """Section 6's runs on one layout "L" with two zones (a pair, then a lone patch to avoid).

    The paper's order: the driver and its planner both take mud, then pass the patch (clearance
    1.0 and 0.8 m). Rock first: the driver takes rock, its planner mud (half the zones agree).
    The wide driver passes at 1.5 m, its planner at 1.4 m (the default style's planner at 0.8 m)."""

    def run(method: str, order, style: str, first: str, clearance: float, xtrack: float) -> StudyRun:
        zs = [replace(_zone("1", first, first), clearance_m=0.5), replace(_zone("2", "avoid", "avoid"), clearance_m=clearance)]
        return _run("teach", method, seed if method == "C" else 0, zs, scenario="L", rms=xtrack, order=order, style=style)

    paper, rock_first = plan.orders
    runs = [
        run("C", paper, "default", "mud", 0.8, 0.4),
        run("C", rock_first, "default", "mud", 0.8, 0.4),
        run("C", paper, "wide", "mud", 1.4, 0.6),
    ]
    # Section 4: under field the paper's order's planner takes water in the pair zone (half its zones
    # agree; rock first: none); the pose sweep agrees in every zone at x1 and in half at x2.
    for order, first in ((paper, "water"), (rock_first, "water")):
        zs = [_zone("1", first, first), _zone("2", "avoid", "avoid")]
        runs.append(_run("robustness", "C", seed, zs, scenario="L", order=order, style="default", kind="field", collisions=1))
        for level, first2 in ((1.0, "mud" if order == paper else "rock"), (2.0, "water")):
            zs = [_zone("1", first2, first2), _zone("2", "avoid", "avoid")]
            runs.append(_run("robustness", "C", seed, zs, scenario="L", order=order, style="default", kind="pose", level=level))
    if seed == 0:
        runs += [
            run(EXPERT, paper, "default", "mud", 1.0, 0.5),
            run(EXPERT, rock_first, "default", "rock", 1.0, 0.5),
            run(EXPERT, paper, "wide", "mud", 1.5, 0.7),
        ]
    return runs


@pytest.fixture(scope="module")
def fabricated_study(tmp_path_factory) -> tuple[Path, list[StudyRun]]:
    plan = StudyPlan(
        seeds=2,
        minutes=(0.5, 2.0),
        presets=("clean", "field"),
        sweep=(1.0, 2.0),
        horizons=(),
        widths=(16,),
        courses=("sc",),
        orders=TEACH_ORDERS[:2],
        styles=("default", "wide"),
        layouts=("L",),
    )
    runs, trained = _fabricated(plan)
    out = tmp_path_factory.mktemp("fabricated")
    path = write_study(out, plan, trained, runs, {"demonstrations": 1.0, "training": 2.5})
    return path, runs


def test_write_study_sections_and_figures(fabricated_study):
    path, _ = fabricated_study
    assert path.name == "STUDY.md"
    text = path.read_text()
    positions = [text.index(h) for h in SECTIONS]
    assert positions == sorted(positions)
    for name in ("baselines", "data_efficiency", "robustness", "teaching"):
        png = path.parent / "figures" / f"{name}.png"
        assert png.read_bytes()[:8] == PNG
        assert f"(figures/{name}.png)" in text


def test_write_study_baseline_table_is_mean_and_std_over_seeds(fabricated_study):
    text = fabricated_study[0].read_text()
    assert "| C (ours) | 66.7% ± 33.3% [30%-90%] | 0 | 100% |" in text
    assert "| linear utility (learned) | 33.3% ± 0.0% [10%-70%] | 0 | 100% |" in text
    assert "| end-to-end CNN | 0.0% ± 0.0% [0%-39%] | 0 | 100% |" in text
    assert "| pure pursuit | 66.7% ± 0.0% [30%-90%] | 2 | 100% |" in text  # collisions summed over both seeds
    assert "| synthetic driver | 100.0% ± 0.0% [61%-100%] | 0 | 100% |" in text
    assert "(3 zones per pass)" in text


def test_write_study_data_efficiency_rows(fabricated_study):
    text = fabricated_study[0].read_text()
    assert "| 0.5 (300 frames) | 33.3% ± 0.0% [10%-70%] | 33.3% ± 0.0% [10%-70%] | 33.3% ± 0.0% [10%-70%] |" in text
    assert "| 2 (1200 frames) |" in text
    assert (
        "| all, 11.0 (6600 frames) | 66.7% ± 33.3% [30%-90%] | 33.3% ± 0.0% [10%-70%] | 0.0% ± 0.0% [0%-39%] |" in text
    )  # 6600 frames at 10 Hz
    assert "C not reached with all 11.0 min (best 67%)" in text


def test_write_study_profile_disagreement(fabricated_study):
    text = fabricated_study[0].read_text()
    assert " > ".join(FULL.alt) in text
    assert "The zones where the two profiles expect different choices (1: sc 2)" in text
    assert "| C trained on the other profile, scored under the other profile | 100.0% (2/2, 95% CI 34.2%-100.0%) |" in text
    assert "| C trained on the default profile, scored under the other profile | 0.0% (0/2, 95% CI 0.0%-65.8%) |" in text
    assert "In the 1 test zones where the two profiles expect different choices, it makes the other profile's choice in 2/2 runs" in text


def test_write_study_robustness_and_ablations(fabricated_study):
    text = fabricated_study[0].read_text()
    # clean: the teaching runs (paper 2 x 2 zones agree, rock first 2 of 4); field: the lone patch's zone of every run
    assert "| clean | 75.0% (6/8, 95% CI 40.9%-92.9%) | 100.0% ± 0.0% [68%-100%] | 0 |" in text
    assert "| field | 50.0% (4/8, 95% CI 21.5%-78.5%) | 100.0% ± 0.0% [68%-100%] | 4 |" in text
    assert "| pose | 1 | 100.0% (8/8, 95% CI 67.6%-100.0%) | 0 |" in text
    assert "| pose | 2 | 50.0% (4/8, 95% CI 21.5%-78.5%) | 0 |" in text
    assert "90% holds for pose to x1, below at x2" in text
    assert "| hidden width 16 | 0.0% ± 0.0% [0%-39%] | 4 |" in text
    assert "| total | 3.5 |" in text


def test_write_study_teaching_agreement_per_order_and_style(fabricated_study):
    text = fabricated_study[0].read_text()
    # two seeds' planners against the one driver run per order: 4 zones each
    assert "| mud > rock > water > non_traversable | 100.0% (4/4, 95% CI 51.0%-100.0%) |" in text
    assert "| rock > mud > water > non_traversable | 50.0% (2/4, 95% CI 15.0%-85.0%) |" in text
    wide = next(line for line in text.splitlines() if line.startswith("| wide ("))
    # clearance: the driver 1.0 m on average; in the lone zone its own planner 0.1 m from it, the default style's 0.7 m
    # (0 in the pair zone: means 0.05 and 0.35 m); cross-track 0.7 / 0.6 / 0.4 m
    assert "| 1.00 m | 0.05 m | 0.35 m | 0.70 m | 0.60 m | 0.40 m |" in wide
    assert "100.0% (4/4, 95% CI 51.0%-100.0%) (default)" in wide


def test_write_study_teaching_imitation_is_paired_per_layout_and_seed(fabricated_study):
    text = fabricated_study[0].read_text()
    wide = next(line for line in text.splitlines() if line.startswith("| wide | default |"))
    # both seeds alike: agreement 0 (both planners take mud, as the wide driver does); cross-track
    # |0.4 - 0.7| - |0.6 - 0.7| = 0.2 m; clearance (0 in the pair zone, 0.7 - 0.1 in the lone one) 0.3 m
    assert wide == (
        "| wide | default | 2 | +0.0 pts (+0.0 to +0.0), not shown | +0.20 m (+0.20 to +0.20), **own** | "
        "+0.30 m (+0.30 to +0.30), **own** |"
    )
    default = next(line for line in text.splitlines() if line.startswith("| default | wide |"))
    # against the default driver (cross-track 0.5 m, lone-patch clearance 1.0 m): its own planner
    # 0.4 m and 0.8 m, the wide style's 0.6 m and 1.4 m: as close in cross-track, 0.2 m closer in clearance
    assert default == (
        "| default | wide | 2 | +0.0 pts (+0.0 to +0.0), not shown | +0.00 m (+0.00 to +0.00), not shown | "
        "+0.10 m (+0.10 to +0.10), **own** |"
    )


# --- one tiny study, end to end -------------------------------------------------------------------


TINY = StudyPlan(
    seeds=1,
    minutes=(0.5,),
    epochs=2,
    cnn_epochs=1,
    presets=("clean", "field"),
    sweep=(1.0,),
    horizons=(),
    widths=(16,),
    courses=("demo_course",),
    orders=TEACH_ORDERS[:1],
    styles=("default",),
    layouts=("demo_course",),
)


@pytest.fixture(scope="module")
def tiny_study(tmp_path_factory) -> tuple[Path, list[str]]:
    out = tmp_path_factory.mktemp("study")
    lines: list[str] = []
    path = run_study(out, TINY, Engine(workers=2), log=lines.append)
    return path, lines


def _runs(path: Path) -> list[StudyRun]:
    return [StudyRun.from_dict(r) for r in json.loads((path.parent / "study.json").read_text())["runs"]]


def _by(runs: list[StudyRun], **keys) -> StudyRun:
    found = _select(runs, **keys)
    assert len(found) == 1, keys
    return found[0]


@pytest.mark.slow
def test_the_study_on_ray_gives_the_local_engines_results(tiny_study, tmp_path):
    """The tiny study again on a local Ray instance with 2 CPUs: every run and model the same."""
    path, _ = tiny_study
    ray_path = run_study(tmp_path / "ray", TINY, Engine("ray", workers=2), log=lambda _: None)
    local, on_ray = (json.loads((p.parent / "study.json").read_text()) for p in (path, ray_path))
    assert len(local["runs"]) > 10 and local["runs"] == on_ray["runs"]
    kept = ("study", "method", "seed", "tag", "samples", "epochs", "order", "style")
    assert [{k: t.get(k) for k in kept} for t in local["trained"]] == [{k: t.get(k) for k in kept} for t in on_ray["trained"]]


@pytest.mark.slow
def test_study_writes_report_and_figures(tiny_study):
    path, _ = tiny_study
    assert path == path.parent / "STUDY.md"
    text = path.read_text()
    for heading in SECTIONS:
        assert heading in text, heading
    for name in ("baselines", "data_efficiency", "robustness", "teaching"):
        assert (path.parent / "figures" / f"{name}.png").read_bytes()[:8] == PNG


@pytest.mark.slow
def test_study_json_has_every_part(tiny_study):
    path, _ = tiny_study
    data = json.loads((path.parent / "study.json").read_text())
    assert data["plan"]["scenarios"] == ["demo_course"]
    runs = [StudyRun.from_dict(r) for r in data["runs"]]
    assert [r.to_dict() for r in runs] == data["runs"]
    assert {r.tag.method for r in _select(runs, study="baselines")} == set(METHODS)
    assert all(r.scenario == "demo_course" for r in runs)
    assert _select(runs, study="efficiency", minutes=0.5)
    assert not _select(runs, study="efficiency", minutes=ALL)  # the last point reuses the baselines' runs
    assert {r.tag.method for r in _select(runs, study="efficiency", minutes=0.5)} == set(LEARNED)
    assert _select(runs, study="robustness", kind="field", level=None)
    assert {r.tag.kind for r in _select(runs, study="robustness", level=1.0)} == set(PARTS)
    ablations = {r.tag.variant for r in _select(runs, study="ablation")}
    assert ablations == {"without the distance utility", "without the row-wise compression (flat MLP)", "hidden width 16"}
    assert {r.tag.method for r in _select(runs, study="profile")} == {"C", EXPERT}
    assert {r.tag.method for r in _select(runs, study="profile_cross")} == {"C", "C_default"}
    for r in data["runs"]:
        assert r["metrics"]["zones"], r
        assert {"id", "expect", "choice", "success"} <= set(r["metrics"]["zones"][0])


@pytest.mark.slow
def test_study_trains_on_the_planned_minutes(tiny_study):
    path, _ = tiny_study
    trained = json.loads((path.parent / "study.json").read_text())["trained"]
    short = [t for t in trained if t["study"] == "efficiency"]
    assert {t["method"] for t in short} == set(LEARNED)
    assert all(t["minutes"] == 0.5 and t["samples"] == 300 for t in short)  # 0.5 min at 10 Hz
    full = [t for t in trained if t["study"] == "baselines"]
    assert {t["method"] for t in full} == set(LEARNED)
    assert all(t["samples"] > 300 for t in full)
    assert all(Path(t["out"]).is_file() for t in trained)


@pytest.mark.slow
def test_study_runs_agree_with_each_other(tiny_study):
    """The profile-cross runs are the same drives scored under the other profile; the report's
    cells come from these runs."""
    path, _ = tiny_study
    runs = _runs(path)

    def choices(r: StudyRun) -> list[str]:
        return [z.choice for z in r.metrics.zones]

    def expects(r: StudyRun) -> list[str]:
        return [z.expect for z in r.metrics.zones]

    alt, alt_cross = _by(runs, study="profile", method="C"), _by(runs, study="profile_cross", method="C")
    default, default_cross = _by(runs, study="baselines", method="C"), _by(runs, study="profile_cross", method="C_default")
    assert choices(alt) == choices(alt_cross)
    assert choices(default) == choices(default_cross)
    assert expects(alt_cross) == expects(_by(runs, study="baselines", method=EXPERT))
    assert expects(default_cross) == expects(_by(runs, study="profile", method=EXPERT))
    assert disagreement_zones(runs)  # demo_course has a zone whose best patch depends on the profile

    text = path.read_text()
    for m in METHODS:
        assert f"| {METHOD_NAMES[m]} | {_cell(_select(runs, study='baselines', method=m))[0]} |" in text


@pytest.mark.slow
def test_study_logs_five_stages_in_order(tiny_study):
    _, lines = tiny_study
    stages = [next(i for i, line in enumerate(lines) if line.startswith(f"[{k}/5]")) for k in range(1, 6)]
    assert stages == sorted(stages)
    assert sum(line.startswith("[") for line in lines) == 5  # the sweep's one level
    assert lines[stages[0]].startswith("[1/5] demonstrations and featurisation: 1 seed(s) x 2 profile(s) x 2 runs of train_course")
    # 3 learned + 3 at 0.5 min + profile + 3 ablations, and the one drive of the teaching recipe
    assert lines[stages[1]].startswith("[2/5] training and teaching: 10 models, and 1 drives of teach_course")
    # 17 as before, and the taught model and its driver on the one layout
    assert lines[stages[2]] == "[3/5] closed-loop evaluation: 19 runs over 2 scenarios ..."
    assert lines[stages[3]].startswith("[4/5] robustness sweep at 1 x field's")


# --- the command --------------------------------------------------------------------------------------


@pytest.mark.parametrize("flag", ["--seeds", "--workers"])
@pytest.mark.parametrize("value", ["0", "-1"])
def test_cli_study_refuses_non_positive_counts(tmp_path: Path, capsys, flag: str, value: str):
    out = tmp_path / "study"
    assert main(["study", "--out", str(out), flag, value]) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("error: ") and flag in lines[0] and ">= 1" in lines[0]
    assert captured.out == ""
    assert not out.exists()  # refused before anything is written
