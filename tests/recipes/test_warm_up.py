"""The set-up's warm-up drives every named recipe end to end with tiny settings and leaves nothing behind."""

import tempfile
from pathlib import Path

import pytest

import terrapref.warm_up
from terrapref.recipes import PAPER
from terrapref.warm_up import warm_up


def _warm_up_leaves_nothing() -> None:
    before = set(Path(tempfile.gettempdir()).glob("terrapref-warm-up-*"))
    lines: list[str] = []
    seconds = warm_up(log=lines.append)
    assert seconds > 0
    assert len(lines) == 1 and lines[0].startswith("compiled loops ready")
    assert set(Path(tempfile.gettempdir()).glob("terrapref-warm-up-*")) == before


def test_warm_up_of_one_recipe_runs_and_cleans_up(monkeypatch):
    """The warm-up's every step (a demonstration, training, closed-loop runs of the model, under a
    perception model and of the synthetic driver, clean-up) with the quickest recipe only: the fast
    twin of the test below."""
    monkeypatch.setattr(terrapref.warm_up, "RECIPES", {PAPER.name: PAPER})
    _warm_up_leaves_nothing()


@pytest.mark.slow
def test_warm_up_runs_every_recipe_and_cleans_up():
    """Every recipe, as scripts/setup.sh runs it (the fast twin above drives the quickest one)."""
    _warm_up_leaves_nothing()
