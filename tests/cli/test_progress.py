"""The progress a command shows while it works (terrapref.progress, and the callbacks the commands build on it)."""

from __future__ import annotations


def test_a_counted_progress_says_what_follows_once_all_are_done_and_its_bar_closes_once(capsys):
    """`course --after` featurises its drives, then fits them: the bar says so when the frames are
    done, not only when the fit is; a second close (the command's own, after the fit) adds nothing."""
    from terrapref.cli.common import counted
    from terrapref.progress import Progress

    bar = Progress("featurising", 3, unit="frames")
    tick = counted(bar, "frames", "3 frames, then fitting them ...")
    for done in range(1, 4):
        tick(done, 3)
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines[-2].startswith("featurising: 100% 3/3 frames") and lines[-1].startswith("featurising: 3 frames, then fitting them ... (")
    bar.close("3 frames")
    bar.update(3)
    assert capsys.readouterr().err == ""
