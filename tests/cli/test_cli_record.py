"""`terrapref record --disturb`: the recording carries the pushes and stays labelled by the driver;
`--relief-style` on a flat course is said to show nothing."""

from __future__ import annotations

import json

import pytest

from helpers import TINY_COURSE, TINY_RELIEF
from terrapref.cli import main
from terrapref.demos.recording import read_recording


def test_record_with_disturbances(tmp_path, capsys):
    out = tmp_path / "rec"
    assert main(["record", str(TINY_COURSE), "--seed", "1", "--out", str(out), "--disturb", "1.0", "--quiet"]) == 0
    rec = read_recording(out)
    assert rec.complete
    assert rec.meta["driver"]["disturbance"]["rate_hz"] == 1.0
    lines = [json.loads(x) for x in (out / "frames.jsonl").read_text().splitlines()]
    assert any("executed" in x for x in lines) and not all("executed" in x for x in lines)
    assert "complete" in capsys.readouterr().out


def test_record_refuses_a_negative_rate(tmp_path, capsys):
    assert main(["record", "demo_course", "--out", str(tmp_path / "rec"), "--disturb", "-1"]) == 2
    err = capsys.readouterr().err
    assert "--disturb" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "rec").exists()


def test_disturb_help_names_the_rate_a_recording_stores_by_default():
    import argparse
    import re

    from terrapref.cli import build_parser
    from terrapref.cli.demos import _disturbance

    stored = _disturbance(None).rate_hz  # what a recording made without --disturb holds
    commands = next(a for a in build_parser(train_flags=False)._actions if isinstance(a, argparse._SubParsersAction)).choices
    for name in ("record", "drive"):
        help_text = next(a.help for a in commands[name]._actions if "--disturb" in a.option_strings)
        assert re.findall(r"default: the recommended protocol's ([0-9.]+)", help_text) == [f"{stored:g}"], (name, help_text)


@pytest.mark.parametrize("course,flat", [(TINY_COURSE, True), (TINY_RELIEF, False)])
def test_a_relief_style_on_a_flat_course_is_said_to_show_nothing(tmp_path, capsys, course, flat):
    out = tmp_path / "rec"
    assert main(["record", str(course), "--relief-style", "cautious", "--out", str(out), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert ("is flat: the relief style is kept with the recording but no frame shows it" in err) == flat, err
    assert read_recording(out).meta["driver"]["config"]["relief"]["roll_deg"] > 0  # kept either way
