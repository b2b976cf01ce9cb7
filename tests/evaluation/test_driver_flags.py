"""The synthetic driver a model's recordings name, as record's flags and as evaluate compares with it."""

from __future__ import annotations

from terrapref.demos.relief_style import parse_relief_style
from terrapref.evaluation.speed import driver_flags, relief_styles_differ


def _driver(style: str = "default", speeds=(), relief: str | None = None) -> dict:
    config = {"speeds": [list(p) for p in speeds], "relief": parse_relief_style(relief)[1].to_dict() if relief else None}
    return {"kind": "expert", "style": style, "config": config}


def test_the_flags_drive_a_follow_up_as_the_drives_were_driven():
    assert driver_flags([_driver()], relief=False) == ""
    assert driver_flags([_driver()], relief=True) == " --relief-style default"  # else relief is driven as if flat
    assert driver_flags([_driver("shaky", relief="cautious")] * 2, relief=False) == " --style shaky --relief-style cautious"
    own = parse_relief_style("default,roll_deg=8")[1].as_flag()
    assert driver_flags([_driver(speeds=[("grass", 1.2)], relief="default,roll_deg=8")], relief=True) == (
        f" --speeds grass=1.2 --relief-style {own}"
    )
    assert driver_flags([{"kind": "human"}], relief=False) == ""  # a person's drive: no synthetic driver to name
    # The order the drives declared: recorded in another, the follow-up could not be trained with them.
    order = ["puddle", "mud", "gravel", "boulders"]
    assert driver_flags([_driver()] * 2, relief=False, profiles=[order, None]) == " --profile puddle,mud,gravel,boulders"
    assert driver_flags([_driver()] * 2, relief=False, profiles=[order, order[::-1]]) == ""  # two orders: none to name


def test_a_mix_of_drivers_with_and_without_a_relief_style_is_told():
    def meta(*drivers):
        return {"data": {"recordings": [{"driver": d} for d in drivers]}}

    assert relief_styles_differ(meta(_driver(relief="default"), _driver()))
    assert relief_styles_differ(meta(_driver(relief="bold"), _driver(relief="cautious")))  # two styles: compared as if flat, unsaid
    assert not relief_styles_differ(meta(_driver(relief="bold"), _driver(relief="bold")))
    assert not relief_styles_differ(meta(_driver(), _driver()))


def test_a_relief_style_is_told_by_the_flag_that_gives_it_and_every_way_it_drives():
    for text in ("default", "cautious", "default,roll_deg=8,up_mps_per_deg=0.05", "bold,rough_mps=1.0"):
        style = parse_relief_style(text)[1]
        assert parse_relief_style(style.as_flag())[1] == style
    assert parse_relief_style("default,up_mps_per_deg=0.05")[1].describe() == (
        "up_mps_per_deg=0.05 (round side slopes past 12 deg and grades past 15 deg; 0.05 m/s less a deg up, 0.02 down; "
        "0.8 m/s on ground rougher than 0.015 m)"
    )
