"""`terrapref study --classes FILE`: the study's plan for a class table of one's own (its teaching
course, orders, other profile, evaluation layouts and perception), the report in the table's
names, the command's refusals, and one tiny study of a 3-class table end to end (slow)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest
from test_study import _fabricated

from helpers import REPO
from terrapref.cli import main
from terrapref.evaluation.runner import EXPERT, HAND_COST, PURE_PURSUIT
from terrapref.grid import Engine
from terrapref.perception import load_perception
from terrapref.planner.policy import hand_costs
from terrapref.report.study import run_study
from terrapref.report.study_plan import FULL, QUICK, StudyPlan, for_table, reversed_order, with_perception
from terrapref.report.study_report import StudyRun, _select, write_study
from terrapref.terrain import PreferenceProfile, load_classes

EXAMPLES = REPO / "examples" / "classes"


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
    plan = StudyPlan(
        seeds=2,
        minutes=(0.5, 2.0),
        presets=("clean",),
        sweep_base=None,
        sweep=(1.0,),
        horizons=(),
        widths=(16,),
        courses=("sc",),
        styles=("default", "wide"),
        layouts=("L",),
    )
    return for_table(plan, table, **extra)


def test_the_report_of_a_table_speaks_its_names(example, tmp_path):
    plan = _table_plan(example, course="teaching_course.yaml")
    runs, trained = _fabricated(replace(plan, orders=plan.orders[:2]))
    # the fabricated runs name the default table's classes: the report's columns come from the plan
    text = write_study(
        tmp_path, plan, trained, [r for r in runs if r.tag.study != "teach" and r.tag.study != "robustness"], {"all": 1.0}
    ).read_text()
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


@pytest.mark.parametrize("value", ["field,field", ","])
def test_cli_study_refuses_a_perception_named_twice_or_none(tmp_path, capsys, value):
    out = tmp_path / "s"
    assert main(["study", "--quick", "--out", str(out), "--perception", value]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: --perception")
    assert not out.exists()


def test_cli_study_refuses_a_table_with_nothing_to_choose_between(tmp_path, capsys):
    table = tmp_path / "trees.yaml"
    table.write_text(
        "format: terrapref-classes/1\nbackground: grass\nlethal: [tree]\nclasses:\n"
        "  - {id: 0, name: grass, color: [0, 100, 0]}\n  - {id: 1, name: tree, color: [0, 50, 0]}\n"
    )
    out = tmp_path / "s"
    for command in (["study", "--quick"], ["select"]):
        assert main([*command, "--out", str(out), "--classes", str(table)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [f"error: {table}: classes: the class table has no feature class (neither background nor lethal) to teach"]
        assert not out.exists()


@pytest.fixture
def planned(monkeypatch):
    """The plan ``terrapref study`` would run (run_study replaced by a recorder)."""
    import terrapref.report.study as study

    seen: list[StudyPlan] = []

    def record(out, plan, engine=None, log=print):
        seen.append(plan)
        return Path(out) / "STUDY.md"

    monkeypatch.setattr(study, "run_study", record)
    return seen


def test_cli_study_builds_the_tables_plan_from_its_flags(planned, tmp_path, example):
    field = EXAMPLES / "rellis3d_field.yaml"
    assert (
        main(
            [
                "study",
                "--quick",
                "--out",
                str(tmp_path / "s"),
                "--classes",
                str(EXAMPLES / "rellis3d.yaml"),
                "--perception",
                f"clean,{field}",
                "--follow-up",
                "--seeds",
                "2",
            ]
        )
        == 0
    )
    plan = planned[0]
    assert plan.classes.same_classes(example) and plan.follow_up and plan.seeds == 2
    assert plan.orders == for_table(QUICK, example).orders and plan.alt == reversed_order(example)
    assert [p.name for p in plan.perceptions()] == ["clean", str(field)] and plan.sweep_name() == str(field)


def test_cli_study_of_the_packaged_table_file_is_the_default_study(planned, tmp_path):
    from terrapref.terrain.classes import default_classes

    packaged = REPO / "src" / "terrapref" / "data" / "classes.yaml"
    assert load_classes(packaged) == default_classes()
    assert main(["study", "--quick", "--out", str(tmp_path / "a"), "--classes", str(packaged)]) == 0
    assert main(["study", "--quick", "--out", str(tmp_path / "b"), "--perception", "clean"]) == 0
    assert planned[0] == QUICK
    assert planned[1] == replace(QUICK, presets=("clean",), sweep_base=None)


def test_each_taught_order_has_a_work_folder_of_its_own(example, tmp_path):
    from terrapref.report.study import teach_jobs

    plan = for_table(QUICK, example)
    first = plan.orders[0]
    same_start = (*first[:3], *reversed(first[3:-1]), first[-1])  # the same three classes first
    jobs = teach_jobs(replace(plan, orders=(first, same_start)), tmp_path)
    assert len({j.workdir for j in jobs}) == len(jobs) == 3  # two orders, and the other style of the first
    assert {Path(j.workdir).name for j in teach_jobs(QUICK, tmp_path)} == {"mu_ro_wa_default_s0", "mu_ro_wa_wide_s0", "ro_mu_wa_default_s0"}


def test_a_plan_of_another_tables_orders_is_refused(example):
    with pytest.raises(ValueError, match="for_table"):
        StudyPlan(classes=example)  # the default table's orders


def test_a_table_without_lethal_classes_has_a_plan(tmp_path):
    table_file = tmp_path / "soft.yaml"
    table_file.write_text(
        "format: terrapref-classes/1\nbackground: grass\nlethal: []\nclasses:\n"
        "  - {id: 0, name: grass, color: [0, 100, 0]}\n  - {id: 1, name: mud, color: [90, 60, 30]}\n"
        "  - {id: 2, name: sand, color: [200, 190, 120]}\n"
    )
    table = load_classes(table_file)
    plan = for_table(QUICK, table)
    assert plan.alt == tuple(reversed(PreferenceProfile.default(table).order)) and len(plan.orders) == 2
    assert hand_costs(table) == dict(zip(PreferenceProfile.default(table).order, (2.0, 4.0)))


def test_the_choice_table_counts_a_lethal_class_in_the_lethal_column(example, tmp_path):
    from test_study import _run, _zone

    plan = _table_plan(example)
    best = plan.orders[0][0]
    runs, trained = _fabricated(replace(plan, orders=plan.orders[:2]))
    runs = [r for r in runs if r.tag.study in ("baselines", "efficiency") and not (r.tag.study == "baselines" and r.tag.method == "C")]
    runs.append(_run("baselines", "C", 0, [_zone("1", best, "tree"), _zone("2", best, best), _zone("3", "avoid", "avoid")]))
    text = write_study(tmp_path, plan, trained, runs, {"all": 1.0}).read_text()
    row = next(line for line in text.splitlines() if line.startswith("| C, default profile |"))
    cells = dict(zip((*plan.orders[0], "avoid"), row.strip("|").split("|")[1:]))
    assert cells["lethal"].strip() == "50%" and cells[best].strip() == "50%"


def test_data_budgets_beyond_the_demonstrations_are_not_reported(example, tmp_path):

    plan = replace(_table_plan(example), minutes=(0.5, 2.0, 5.0))
    runs, trained = _fabricated(replace(plan, orders=plan.orders[:2]))
    trained = [replace(t, samples=1800) if t.job.study == "baselines" else t for t in trained]  # 3 minutes of demonstrations
    text = write_study(tmp_path, plan, trained, [r for r in runs if r.tag.study in ("baselines", "efficiency")], {"all": 1.0}).read_text()
    assert "| 2 (1200 frames) |" in text and "| all, 3.0 (1800 frames) |" in text
    assert "| 5 (" not in text


# --- one tiny study of a 3-class table, end to end -------------------------------------------------


@pytest.fixture(scope="module")
def tiny_table_study(tmp_path_factory, small):
    plan = for_table(
        StudyPlan(
            seeds=1,
            minutes=(0.5,),
            epochs=2,
            cnn_epochs=1,
            sweep=(1.0,),
            horizons=(),
            widths=(16,),
            styles=("default",),
            layouts=("gen:5000",),
        ),
        small,
        perceptions=(load_perception("field:pose", small),),
    )
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
    names = set(small.names) | {"avoid"}
    assert all(z.expect in names for r in runs for z in r.metrics.zones)
    # the sweep varies only what field:pose has: the pose
    assert {r.tag.kind for r in _select(runs, study="robustness", level=1.0)} == {"pose"}
    assert lines[0].startswith("[1/5] demonstrations and featurisation: 1 seed(s) x 1 profile(s) x 2 runs of teaching_course.yaml")
    text = path.read_text()
    assert "terrain columns mud; lethal tree" in text and "**Another profile:** none" in text
    taught = _select(runs, study="teach", method="C")
    assert len(taught) == 1 and taught[0].scenario == "gen:5000" and taught[0].metrics.zones
