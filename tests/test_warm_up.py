"""The set-up's warm-up drives every named recipe end to end with tiny settings and leaves nothing behind."""

import tempfile
from pathlib import Path

from terrapref.warm_up import warm_up


def test_warm_up_runs_every_recipe_and_cleans_up():
    before = set(Path(tempfile.gettempdir()).glob("terrapref-warm-up-*"))
    lines: list[str] = []
    seconds = warm_up(log=lines.append)
    assert seconds > 0
    assert len(lines) == 1 and lines[0].startswith("compiled loops ready")
    assert set(Path(tempfile.gettempdir()).glob("terrapref-warm-up-*")) == before
