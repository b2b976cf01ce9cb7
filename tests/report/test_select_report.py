"""SELECT.md's intervals: Wilson over zones, and whole layouts resampled; the size `select`
announces before any work, and the bound beyond which it needs --large."""

from pathlib import Path

import pytest

from terrapref.cli import main
from terrapref.errors import UserError
from terrapref.evaluation.scoring import ReliefZoneResult, RunMetrics, ZoneResult
from terrapref.evaluation.stats import cluster_bootstrap, wilson
from terrapref.report.select import SelectionSize, count_orders, layout_interval, parse_orders, write_selection_report
from terrapref.terrain import default_classes

ORDER = ["mud", "rock", "water", "non_traversable"]


def _zones(misses_by_layout: dict[str, int], zones_per_layout: int = 40) -> list[dict]:
    rows = []
    for layout, misses in misses_by_layout.items():
        for i in range(zones_per_layout):
            rows.append(
                {
                    "recipe": "teach",
                    "order": ORDER,
                    "seed": i % 5,
                    "scenario": layout,
                    "zone": str(i),
                    "kind": "lone",
                    "choice": "mud",
                    "driver_choice": "mud" if i >= misses else "avoid",
                    "agrees": i >= misses,
                    "success": True,
                    "driver_success": True,
                }
            )
    return rows


def _saved(rows: list[dict], runs: list[dict], layouts: list[str], seeds: int = 5, **selection) -> dict:
    """select.json's content for ``rows`` and ``runs`` of one recipe and order on ``layouts``."""
    sel = {"recipes": ["teach"], "orders": [ORDER], "seeds": seeds, "layouts": layouts, "style": "default", **selection}
    return {"selection": sel, "zones": rows, "runs": runs, "engine": "local, 1 worker", "train_s": 1.0, "eval_s": 2.0}


def test_misses_gathered_on_a_few_layouts_widen_the_layout_interval_beyond_wilsons():
    gathered = _zones({f"gen:{i}": (12 if i < 2 else 0) for i in range(20)})
    spread = _zones({f"gen:{i}": (2 if i < 4 else 1) for i in range(20)})  # the same 24 misses, on every layout
    for rows in (gathered, spread):
        rate, lo, hi = layout_interval(rows)
        assert rate == sum(r["agrees"] for r in rows) / len(rows)
        assert lo <= rate <= hi
    g_rate, g_lo, g_hi = layout_interval(gathered)
    w_lo, w_hi = wilson(sum(r["agrees"] for r in gathered), len(gathered))
    assert g_hi - g_lo > 1.5 * (w_hi - w_lo)  # 24 misses on 2 of 20 layouts: the set of layouts decides the rate
    s_rate, s_lo, s_hi = layout_interval(spread)
    assert s_hi - s_lo < g_hi - g_lo  # a miss or two on every layout: any set of layouts gives about the same rate


def test_the_layout_interval_resamples_layouts_not_zones():
    rows = _zones({"gen:1": 3, "gen:2": 0, "gen:3": 10})
    groups = [[r["agrees"] for r in rows if r["scenario"] == s] for s in ("gen:1", "gen:2", "gen:3")]
    assert layout_interval(rows) == cluster_bootstrap(groups)


def test_select_md_gives_both_intervals_per_order(tmp_path):
    rows = _zones({f"gen:{i}": (6 if i == 0 else 0) for i in range(4)})
    runs = [{"recipe": "teach", "order": ORDER, "seed": 0, "scenario": "gen:0", "collisions": 0}]
    saved = _saved(rows, runs, [f"gen:{i}" for i in range(4)])
    text = write_selection_report(tmp_path, saved).read_text()
    rate, lo, hi = layout_interval(rows)
    row = next(line for line in text.splitlines() if line.startswith("| teach | mud > rock > water"))
    assert "96.2% (154/160, 95% CI" in row
    assert f"| {rate:.1%} (95% CI {lo:.1%}-{hi:.1%}) |" in row
    assert (tmp_path / "select.png").stat().st_size > 0


def test_the_figure_marks_each_row_with_its_own_target(tmp_path, monkeypatch):
    import terrapref.report.select as select_report

    rows = [dict(r, perception=name) for name in ("clean", "field") for r in _zones({"gen:0": 1, "gen:1": 0})]
    runs = [
        {"recipe": "teach", "order": ORDER, "seed": 0, "scenario": "gen:0", "collisions": 0, "perception": p} for p in ("clean", "field")
    ]
    saved = _saved(rows, runs, ["gen:0", "gen:1"], perceptions=[{"name": "clean"}, {"name": "field"}])
    drawn = {}
    monkeypatch.setattr(
        select_report,
        "save_intervals",
        lambda path, rows, *args, target=None, **kw: drawn.update(labels=[r.label for r in rows], target=target),
    )
    write_selection_report(tmp_path, saved)
    assert drawn["labels"] == ["teach, all orders, clean", "teach, all orders, field"]
    assert drawn["target"] == [select_report.TARGET, select_report.PERCEIVED_TARGET]  # 95% on clean frames, 90% under errors


# --- the size, before any work -----------------------------------------------------------------


def _ten_classes(tmp_path: Path) -> Path:
    """A table of ten feature classes (the most a table may have): 3,628,800 orders."""
    names = ["grass", *(f"c{i}" for i in range(10)), "tree"]
    rows = "".join(f"  - {{id: {i}, name: {n}, color: [{i * 20}, {i * 5}, 0]}}\n" for i, n in enumerate(names))
    path = tmp_path / "ten.yaml"
    path.write_text(f"format: terrapref-classes/1\nbackground: grass\nlethal: [tree]\nclasses:\n{rows}profile: [{', '.join(names[1:])}]\n")
    return path


def test_the_orders_are_counted_as_parse_orders_makes_them():
    table = default_classes()
    for text in ("all", "random:4", "mud,rock,water;rock,mud,water"):
        assert count_orders(text, table) == len(parse_orders(text, table))
    with pytest.raises(ValueError, match="random:N"):
        count_orders("random:7", table)


def test_the_size_counts_every_model_and_run():
    size = SelectionSize.of(recipes=2, orders=6, seeds=1, courses=1, perceptions=2, random_speeds=True)
    assert (size.models, size.runs) == (12, 30)  # 12 models under 2 perception models, and a driver per order and seed
    assert SelectionSize.of(1, 6, 5, 32, 1, random_speeds=False).runs == (30 + 6) * 32  # a driver per order
    assert not SelectionSize.of(1, 200, 5, 1, 1, False).large and SelectionSize.of(1, 201, 5, 1, 1, False).large  # 1,000 models
    assert SelectionSize.of(1, 1, 1, 100_000, 1, False).large  # 200,000 runs
    assert (
        SelectionSize.of(1, 6, 5, 32, 1, False)
        .describe(2)
        .startswith("30 models (1 recipe x 6 orders x 5 seeds) and 1,152 closed-loop runs on 32 layouts: about ")
    )


@pytest.mark.parametrize("orders", ["random:3628800", "all"])
def test_select_says_at_once_how_much_it_would_make_and_refuses_an_absurd_size(tmp_path, capsys, monkeypatch, orders: str):
    def drawn(*args, **kwargs):
        raise AssertionError("the orders were drawn or listed before the size was announced")

    monkeypatch.setattr("terrapref.report.select._draw_orders", drawn)
    monkeypatch.setattr("terrapref.report.select.itertools.permutations", drawn)
    out = tmp_path / "sel"
    assert main(["select", "--classes", str(_ten_classes(tmp_path)), "--orders", orders, "--workers", "2", "--out", str(out)]) == 2
    captured = capsys.readouterr()
    assert captured.out.startswith(
        "select: 18,144,000 models (1 recipe x 3,628,800 orders x 5 seeds) and 696,729,600 closed-loop runs on 32 layouts: about "
    )
    assert "years on 2 workers" in captured.out
    (line,) = captured.err.strip().splitlines()
    assert line.startswith("error: --orders, --seeds, --courses: 18,144,000 models") and "--large" in line and "internal error" not in line
    assert not out.exists()


@pytest.mark.parametrize(
    ("flags", "needle"),
    [
        (["--orders", "mud,mud,water"], "--orders"),
        (["--orders", "lava,rock,water"], "'lava'"),
        (["--orders", "non_traversable,rock,mud,water"], "lethal column 'non_traversable' before rock, mud, water"),
        (["--orders", "rock,mud,water;mud,non_traversable,rock,water"], "lethal column 'non_traversable' before rock, water"),
        (["--orders", "rock,,mud"], "empty class"),
        (["--orders", "rock,mud,water;;mud,rock,water"], "empty order"),
        (["--orders", "rock,mud,water;"], "empty order"),
        (["--course", "nosuch_course"], "nosuch_course"),
    ],
)
def test_orders_and_a_course_that_cannot_be_read_are_refused_before_the_plan_is_said(tmp_path, capsys, flags, needle):
    """One line, the error's: no plan of a selection that will not run before it."""
    out = tmp_path / "sel"
    assert main(["select", *flags, "--out", str(out)]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.count("\n") == 1 and needle in captured.err and not out.exists()


def test_large_runs_a_selection_beyond_the_bound(tmp_path, capsys, monkeypatch):
    def started(*args, **kwargs):
        raise UserError("run_selection", "started")

    monkeypatch.setattr("terrapref.report.select.run_selection", started)
    argv = ["select", "--seeds", "200", "--courses", "1", "--out", str(tmp_path / "sel")]  # 6 orders x 200 seeds: 1,200 models
    assert main(argv) == 2 and "--large" in capsys.readouterr().err
    assert main([*argv, "--large"]) == 2
    assert "run_selection: started" in capsys.readouterr().err


# --- relief: the relief styles as one more dimension of the drivers ------------------------------


def _relief_run(choices: list[str], zone_choice: str = "mud") -> RunMetrics:
    zones = [ZoneResult("z0", "pair mud/rock", "mud", zone_choice, zone_choice == "mud", False, {}, speed_mps=0.8)]
    relief = [ReliefZoneResult(10.0 * k, 10.0 * k + 3.0, c, 0.0) for k, c in enumerate(choices)]
    return RunMetrics(True, 0, 10.0, 0.0, 0.0, 0.0, {}, zones=zones, relief_zones=relief)


def test_a_relief_run_gives_a_row_per_relief_zone_beside_its_terrain_zones():
    from terrapref.report.select import RELIEF_ZONE, _zone_rows

    who = {"recipe": "teach", "order": ORDER, "seed": 0, "scenario": "genrelief:101", "perception": "clean", "relief_style": "bold"}
    rows = _zone_rows(who, _relief_run(["over", "right", "left"]), _relief_run(["over", "left", "left"], "rock"))
    terrain, relief = rows[0], rows[1:]
    assert (terrain["kind"], terrain["choice"], terrain["driver_choice"], terrain["agrees"]) == ("pair", "mud", "rock", False)
    assert [(r["kind"], r["choice"], r["driver_choice"], r["agrees"]) for r in relief] == [
        (RELIEF_ZONE, "over", "over", True),
        (RELIEF_ZONE, "right", "left", False),
        (RELIEF_ZONE, "left", "left", True),
    ]
    assert all(r["success"] is None and r["relief_style"] == "bold" for r in relief)  # no zone success of their own
    flat = _zone_rows(who, _relief_run([]), _relief_run([]))
    assert [r["kind"] for r in flat] == ["pair"]


def test_select_md_gives_a_table_per_relief_style_with_the_relief_zones_apart(tmp_path, monkeypatch):
    import terrapref.report.select as select_report

    rows = []
    for style, misses in (("default", 0), ("bold", 2)):
        for i in range(8):
            kind = "relief" if i < 4 else "lone"
            rows.append(
                {
                    **_zones({f"genrelief:{i % 2}": 0}, 1)[0],
                    "scenario": f"genrelief:{i % 2}",
                    "relief_style": style,
                    "kind": kind,
                    "agrees": not (kind == "relief" and i < misses),
                    "success": None if kind == "relief" else True,
                    "driver_success": None if kind == "relief" else True,
                }
            )
    runs = [
        {"recipe": "teach", "order": ORDER, "seed": 0, "scenario": "genrelief:0", "collisions": 0, "relief_style": s}
        for s in ("default", "bold")
    ]
    saved = _saved(rows, runs, ["genrelief:0", "genrelief:1"], seeds=1, relief_styles=["default", "bold"])
    drawn = {}
    monkeypatch.setattr(select_report, "save_intervals", lambda path, rows, *a, **kw: drawn.update(bars={r.label: r.rate for r in rows}))
    text = write_selection_report(tmp_path, saved).read_text()
    assert "## Relief style `default`" in text and "## Relief style `bold`" in text
    bold = text[text.index("## Relief style `bold`") :]
    row = next(line for line in bold.splitlines() if line.startswith("| teach | mud > rock > water"))
    cells = [c.strip() for c in row.split("|")]
    assert cells[5].startswith("100.0% (4/4") and cells[6].startswith("50.0% (2/4")  # lone zones, then relief zones
    assert cells[7].startswith("100.0% (4/4")  # zone success: the terrain zones alone
    assert drawn["bars"] == {  # terrain zones and relief zones apart, each with its target
        "teach, all orders, terrain zones, relief default": 1.0,
        "teach, all orders, relief zones, relief default": 1.0,
        "teach, all orders, terrain zones, relief bold": 1.0,
        "teach, all orders, relief zones, relief bold": 0.5,
    }


def test_the_size_counts_each_relief_style_as_a_driver_of_its_own():
    size = SelectionSize.of(recipes=1, orders=3, seeds=1, courses=6, perceptions=2, random_speeds=False).with_relief(3)
    assert (size.models, size.drivers, size.runs) == (9, 9, (9 * 2 + 9) * 6)
    assert size.describe(2).startswith("9 models (1 recipe x 3 orders x 1 seed x 3 relief styles) and 162 closed-loop runs on 6 layouts")
    from terrapref.report.select import RELIEF_MODEL_CORE_S, RELIEF_RUN_CORE_S

    assert size.core_s == 9 * RELIEF_MODEL_CORE_S + 162 * RELIEF_RUN_CORE_S  # a relief drive is longer, a relief run renders depth


def test_the_layouts_have_relief_when_the_drivers_have_relief_styles():
    from terrapref.report.select import Selection, job_folder

    assert Selection(("teach",), (tuple(ORDER),), 1, 101, 2).layouts == ["gen:101", "gen:102"]
    assert Selection(("teach",), (tuple(ORDER),), 1, 101, 2, relief_styles=("bold",)).layouts == ["genrelief:101", "genrelief:102"]
    a, b = (job_folder(Path("out"), ORDER, 0, relief=s) for s in ("default", "default,roll_deg=10"))
    assert a.name == "mu_ro_wa_s0_relief-default" and b.name == "mu_ro_wa_s0_relief-default_roll_deg_10"


@pytest.mark.parametrize(
    "styles, word",
    [
        ("steep", "steep"),
        ("default;default", "distinct"),
        ("default;;bold", "distinct"),
        ("rough_mps=1e9", "rough_mps"),
        ("default;roll_deg=12", "'default' and 'roll_deg=12' are the same relief style"),  # the default's own roll: the models twice
        ("bold;default,roll_deg=12;default", "'default,roll_deg=12' and 'default' are the same"),
    ],
)
def test_select_refuses_a_bad_relief_style_before_any_work(tmp_path, capsys, styles: str, word: str):
    out = tmp_path / "sel"
    assert main(["select", "--relief-style", styles, "--orders", "mud,rock,water", "--seeds", "1", "--out", str(out)]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith("error: --relief-style") and word in line
    assert not out.exists()


def test_select_refuses_a_driver_style_file_saying_where_one_goes(tmp_path, capsys):
    style = tmp_path / "mine.yaml"
    style.write_text("format: terrapref-driver-style/1\nbase: wide\n")
    out = tmp_path / "sel"
    assert main(["select", "--style", str(style), "--orders", "mud,rock,water", "--seeds", "1", "--out", str(out)]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith("error: --style") and "select takes a preset" in line and "record and evaluate" in line
    assert not out.exists()


def test_select_with_relief_styles_teaches_on_the_relief_course_and_judges_relief_layouts(tmp_path, monkeypatch):
    """The default table's drivers demonstrate `teach_relief`; a table's own, its course with relief, written into OUT."""
    from terrapref.scenario import load_scenario

    seen = {}

    def started(out, selection, *args, **kwargs):
        seen["selection"] = selection
        if Path(selection.course).exists():  # a table's course, written into OUT (removed with it when the command fails)
            seen["has_relief"], seen["folder"] = load_scenario(selection.course).has_relief, Path(selection.course).parent
        raise UserError("run_selection", "started")

    monkeypatch.setattr("terrapref.report.select.run_selection", started)
    argv = ["select", "--orders", "mud,rock,water", "--seeds", "1", "--courses", "2", "--relief-style", "bold;default,roll_deg=10"]
    assert main([*argv, "--out", str(tmp_path / "a")]) == 2
    sel = seen["selection"]
    assert sel.course == "teach_relief" and sel.relief_styles == ("bold", "default,roll_deg=10")
    assert sel.layouts == ["genrelief:1000", "genrelief:1001"]
    table = Path(__file__).parents[2] / "examples" / "classes" / "rellis3d.yaml"
    order = "mud,water,dirt,gravel,puddle,bush"
    assert main([*argv[:2], order, *argv[3:], "--classes", str(table), "--out", str(tmp_path / "b")]) == 2
    assert seen["has_relief"] and seen["folder"].name == "b"


def test_a_kind_of_zone_no_layout_had_is_no_bar_at_nothing():
    """Relief layouts whose paths tilted the body nowhere past 4 deg have no relief zones: no bar, not one drawn at 0%."""
    from terrapref.report.select import _relief_bars

    rows = _zones({"genrelief:0": 1, "genrelief:1": 0}, 10)
    assert [label for label, _, _ in _relief_bars(["teach"], rows)] == ["teach, all orders, terrain zones"]
