"""``terrapref recipes`` and the recipe flags of ``reproduce``: names, the default, one-line errors."""

from __future__ import annotations

import pytest

from terrapref.cli import main
from terrapref.recipes import DEFAULT_RECIPE, RECIPES


def test_recipes_lists_every_recipe_with_what_it_is_for(capsys):
    assert main(["recipes"]) == 0
    out = capsys.readouterr().out.splitlines()
    heads = [line for line in out if not line.startswith(" ")]
    assert [h.split(":")[0].replace(" (default)", "") for h in heads] == list(RECIPES)
    assert f"{DEFAULT_RECIPE} (default): 1 drive of teach_course" in heads[0]
    for name, recipe in RECIPES.items():
        assert recipe.summary and f"    {recipe.summary}" in out, name


@pytest.mark.parametrize(
    "value, message",
    [
        ("bogus", "unknown recipe 'bogus'"),
        ("paper,paper", "expected distinct recipe names"),
        (",", "expected distinct recipe names"),
    ],
)
def test_reproduce_refuses_bad_recipe_lists_before_any_work(tmp_path, capsys, value: str, message: str):
    out = tmp_path / "rep"
    assert main(["reproduce", "--out", str(out), "--recipes", value]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--recipes" in err[0] and message in err[0], err
    assert not out.exists()


def test_reproduce_names_the_flag_it_refuses(tmp_path, capsys):
    assert main(["reproduce", "--out", str(tmp_path / "rep"), "--eval-seeds", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert "--eval-seeds" in err and "--seeds:" not in err


def test_study_refuses_an_unknown_recipe_before_any_work(tmp_path, capsys):
    out = tmp_path / "study"
    assert main(["study", "--out", str(out), "--quick", "--recipe", "bogus"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--recipe" in err[0] and "unknown recipe 'bogus'" in err[0], err
    assert not out.exists()
