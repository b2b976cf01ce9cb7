"""`terrapref study --classes FILE`: the study's plan for a class table of one's own (its teaching
course, orders, other profile, evaluation layouts and perception), the report in the table's
names, the command's refusals, and one tiny study of a 3-class table end to end (slow)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest

from terrapref.cli import main
from terrapref.evaluation.runner import EXPERT, HAND_COST, PURE_PURSUIT
from terrapref.grid import Engine
from terrapref.perception import load_perception
from terrapref.planner.policy import hand_costs
from terrapref.report.study import run_study
from terrapref.report.study_plan import FULL, QUICK, StudyPlan, for_table, reversed_order, with_perception
from terrapref.report.study_report import StudyRun, _select, write_study
from terrapref.terrain import PreferenceProfile, load_classes

from test_study import _fabricated

EXAMPLES = Path(__file__).resolve().parent.parent / "examples" / "classes"


@pytest.fixture(scope="module")
def example():
    return load_classes(EXAMPLES / "rellis3d.yaml")


@pytest.fixture(scope="module")
def small():
    return load_classes(EXAMPLES / "small.yaml")


def test_the_default_plans_other_profile_is_the_papers_swap():
    assert FULL.alt == QUICK.alt == ("rock", "mud", "water", "non_traversable")
    assert FULL.classes is None and FULL.course is None and FULL.demo_course() == "train_course"


def test_a_tables_plan_orders_layouts_and_other_profile(example):
    plan = for_table(FULL, example)
    default = PreferenceProfile.default(example).order
    assert plan.classes is example and plan.course is None  # run_study writes the table's teaching course
    assert len(plan.orders) == len(FULL.orders) and len(set(plan.orders)) == len(plan.orders)
    assert plan.orders[0] == default
    for order in plan.orders:
        assert order[-1] == "lethal" and sorted(order) == sorted(example.feature_names)
    assert plan.alt == (*reversed(default[:-1]), "lethal")  # every pair the other way round
    # the evaluation courses are the table's generated layouts, apart from the teaching section's
    assert plan.scenarios() == [f"gen:{6000 + i}" for i in range(len(FULL.layouts))]
    assert not set(plan.scenarios()) & set(plan.layouts)
    assert plan.presets == ("clean",) and plan.sweep_base is None  # no perception given: no sweep
    assert for_table(FULL, example) == plan  # the orders are drawn the same each time


def test_a_tables_plan_sweeps_the_last_perception_given(example):
    field = load_perception(EXAMPLES / "rellis3d_field.yaml", example)
    plan = for_table(QUICK, example, perceptions=(load_perception("clean"), field), follow_up=True)
    assert [p.name for p in plan.perceptions()] == ["clean", field.name]
    assert plan.sweep_base is field and plan.sweep_name() == field.name and plan.follow_up


def test_perception_given_for_the_default_table_replaces_the_presets():
    field = load_perception("field")
    plan = with_perception(FULL, (load_perception("clean"), load_perception("rellis"), field))
    assert [p.name for p in plan.perceptions()] == ["clean", "rellis", "field"] and plan.sweep_name() == "field"
    clean_only = with_perception(QUICK, (load_perception("clean"),))
    assert clean_only.presets == ("clean",) and clean_only.sweep_base is None and clean_only.classes is None


def test_a_table_of_one_class_has_one_order_and_no_other_profile(small):
    plan = for_table(FULL, small)
    assert plan.orders == (PreferenceProfile.default(small).order,)
    assert plan.alt is None and reversed_order(small) is None


def test_reversed_order_of_the_default_table():
    from terrapref.terrain import default_classes

    assert reversed_order(default_classes()) == ("water", "rock", "mud", "non_traversable")


def _table_plan(table, **extra) -> StudyPlan:
    """The fabricated study's plan, its names those of ``table``."""
    plan = StudyPlan(seeds=2, minutes=(0.5, 2.0), presets=("clean",), sweep_base=None, sweep=(1.0,), horizons=(), widths=(16,),
                     courses=("sc",), styles=("default", "wide"), layouts=("L",))
    return for_table(plan, table, **extra)


def test_the_report_of_a_table_speaks_its_names(example, tmp_path):
    plan = _table_plan(example, course="teaching_course.yaml")
    runs, trained = _fabricated(replace(plan, orders=plan.orders[:2]))
    # the fabricated runs name the default table's classes: the report's columns come from the plan
    text = write_study(tmp_path, plan, trained, [r for r in runs if r.tag.study != "teach" and r.tag.study != "robustness"],
                       {"all": 1.0}).read_text()
    assert "The class table: background grass; terrain columns dirt, gravel, mud, puddle, water, bush; lethal tree, log" in text
    assert "2 runs of teaching_course.yaml with disturbances" in text
    costs = ", ".join(f"{k} {v:g}" for k, v in hand_costs(example).items())
    assert f"Hand-tuned costs per unit share: {costs};" in text and "lethal 128" in text
    assert "| model | " + " | ".join(plan.orders[0]) + " | avoid |" in text
    assert f"Demonstrations driven under {' > '.join(plan.alt)} (the default is {' > '.join(plan.orders[0])})" in text
    assert "No perception model of this table was given (`--perception`): no sweep." in text
    assert "No part was swept." in text
    assert "non_traversable" not in text and "mud > rock" not in text


def test_the_report_of_a_one_class_table_says_there_is_no_other_profile(small, tmp_path):
    plan = _table_plan(small)
    runs, trained = _fabricated(replace(plan, orders=plan.orders * 2))
    kept = [r for r in runs if r.tag.study in ("baselines", "efficiency", "ablation")]
    text = write_study(tmp_path, plan, trained, kept, {"all": 1.0}).read_text()
    assert "- **Another profile:** none; the table has one class besides tree." in text  # the answer
    assert "## 3. Another preference profile\n\n**Another profile:** none; the table has one class besides tree.\n" in text


def test_cli_study_refuses_a_perception_of_another_table_before_writing(tmp_path, capsys):
    out = tmp_path / "study"
    assert main(["study", "--quick", "--out", str(out), "--classes", str(EXAMPLES / "rellis3d.yaml"), "--perception", "rellis"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "non_traversable" in err[0] and "does not have" in err[0]
    assert not out.exists()


def test_cli_study_refuses_a_missing_table(tmp_path, capsys):
    out = tmp_path / "study"
    assert main(["study", "--quick", "--out", str(out), "--classes", str(tmp_path / "nope.yaml")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nope.yaml" in err[0]
    assert not out.exists()


def test_cli_study_refuses_a_perception_named_twice(tmp_path, capsys):
    assert main(["study", "--quick", "--out", str(tmp_path / "s"), "--perception", "field,field"]) == 2
    assert "--perception" in capsys.readouterr().err


# --- one tiny study of a 3-class table, end to end -------------------------------------------------


@pytest.fixture(scope="module")
def tiny_table_study(tmp_path_factory, small):
    plan = for_table(StudyPlan(seeds=1, minutes=(0.5,), epochs=2, cnn_epochs=1, sweep=(1.0,), horizons=(), widths=(16,), styles=("default",),
                               layouts=("gen:5000",)), small, perceptions=(load_perception("field:pose", small),))
    out = tmp_path_factory.mktemp("table_study")
    lines: list[str] = []
    path = run_study(out, plan, Engine(workers=2), log=lines.append)
    return path, lines, small


@pytest.mark.slow
def test_a_tables_study_drives_its_own_course_and_layouts(tiny_table_study):
    path, lines, small = tiny_table_study
    data = json.loads((path.parent / "study.json").read_text())
    assert data["plan"]["classes"] == small.to_dict() and data["plan"]["alt"] is None
    assert data["plan"]["course"] == str(path.parent.resolve() / "teaching_course.yaml")
    assert (path.parent / "teaching_course.yaml").is_file()
    runs = [StudyRun.from_dict(r) for r in data["runs"]]
    assert {r.scenario for r in runs} == {"gen:6000", "gen:5000"}
    assert not _select(runs, study="profile") and not _select(runs, study="profile_cross")
    # every baseline drove the table's layout, and its zones name the table's classes
    assert {r.tag.method for r in _select(runs, study="baselines")} == {"C", "linear", "cnn", HAND_COST, PURE_PURSUIT, EXPERT}
    names = set(small.names) | {"avoid", "lethal", "none", "mixed"}
    assert all(z.expect in names for r in runs for z in r.metrics.zones)
    # the sweep varies only what field:pose has: the pose
    assert {r.tag.kind for r in _select(runs, study="robustness", level=1.0)} == {"pose"}
    assert lines[0].startswith("[1/5] demonstrations and featurisation: 1 seed(s) x 1 profile(s) x 2 runs of teaching_course.yaml")
    text = path.read_text()
    assert "terrain columns mud; lethal tree" in text and "**Another profile:** none" in text
    taught = _select(runs, study="teach", method="C")
    assert len(taught) == 1 and taught[0].scenario == "gen:5000" and taught[0].metrics.zones
