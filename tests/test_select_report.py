"""SELECT.md's intervals: Wilson over zones, and whole layouts resampled."""

from terrapref.evaluation.stats import cluster_bootstrap, wilson
from terrapref.report.select import layout_interval, write_selection_report

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
    saved = {
        "selection": {"recipes": ["teach"], "orders": [ORDER], "seeds": 5, "layouts": [f"gen:{i}" for i in range(4)], "style": "default"},
        "zones": rows,
        "runs": [{"recipe": "teach", "order": ORDER, "seed": 0, "scenario": "gen:0", "collisions": 0}],
        "engine": "local, 1 worker",
        "train_s": 1.0,
        "eval_s": 2.0,
    }
    text = write_selection_report(tmp_path, saved).read_text()
    rate, lo, hi = layout_interval(rows)
    row = next(line for line in text.splitlines() if line.startswith("| teach | mud > rock > water"))
    assert "96.2% (154/160, 95% CI" in row
    assert f"| {rate:.1%} (95% CI {lo:.1%}-{hi:.1%}) |" in row
    assert (tmp_path / "select.png").stat().st_size > 0


def test_the_figure_marks_each_row_with_its_own_target(tmp_path, monkeypatch):
    import terrapref.report.select as select_report

    rows = [dict(r, perception=name) for name in ("clean", "field") for r in _zones({"gen:0": 1, "gen:1": 0})]
    saved = {
        "selection": {
            "recipes": ["teach"],
            "orders": [ORDER],
            "seeds": 5,
            "layouts": ["gen:0", "gen:1"],
            "style": "default",
            "perceptions": [{"name": "clean"}, {"name": "field"}],
        },
        "zones": rows,
        "runs": [
            {"recipe": "teach", "order": ORDER, "seed": 0, "scenario": "gen:0", "collisions": 0, "perception": p}
            for p in ("clean", "field")
        ],
        "engine": "local, 1 worker",
        "train_s": 1.0,
        "eval_s": 2.0,
    }
    drawn = {}
    monkeypatch.setattr(
        select_report,
        "save_intervals",
        lambda path, rows, *args, target=None, **kw: drawn.update(labels=[r.label for r in rows], target=target),
    )
    write_selection_report(tmp_path, saved)
    assert drawn["labels"] == ["teach, all orders, clean", "teach, all orders, field"]
    assert drawn["target"] == [select_report.TARGET, select_report.PERCEIVED_TARGET]  # 95% on clean frames, 90% under errors
