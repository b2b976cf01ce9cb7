"""Typed records as plain mappings and back (terrapref.records)."""

from __future__ import annotations

import doctest
import json
from dataclasses import dataclass

import pytest

import terrapref.records
from terrapref.features import FeatureConfig
from terrapref.features.utility import DistanceMode
from terrapref.records import from_plain, to_plain
from terrapref.rules.second.lookahead import LookaheadConfig


def test_the_module_examples_run():
    assert doctest.testmod(terrapref.records, verbose=False).failed == 0


@dataclass(frozen=True)
class Inner:
    sides: tuple[int, int]
    names: tuple[str, ...] = ()


@dataclass(frozen=True)
class Outer:
    inner: Inner
    inners: tuple[Inner, ...]
    look: LookaheadConfig | None = None
    mode: DistanceMode = DistanceMode.PAPER
    note: str | None = None


def test_a_record_becomes_json_and_comes_back_equal():
    record = Outer(Inner((1, 2), ("a", "b")), (Inner((3, 4)),), LookaheadConfig(1.8, 3))
    plain = to_plain(record)
    assert plain == {
        "inner": {"sides": [1, 2], "names": ["a", "b"]},
        "inners": [{"sides": [3, 4], "names": []}],
        "look": {"after_s": 1.8, "stride": 3},
        "mode": "paper",
        "note": None,
    }
    assert from_plain(Outer, json.loads(json.dumps(plain))) == record


def test_none_is_left_out_where_asked():
    record = Outer(Inner((1, 2)), ())
    assert list(to_plain(record, omit_none=("look",))) == ["inner", "inners", "mode", "note"]
    assert list(to_plain(record, omit_none=True)) == ["inner", "inners", "mode"]


def test_a_nested_record_writes_and_reads_itself_where_it_has_its_own_conversion():
    features = FeatureConfig(path_spacing_m=0.5)
    assert from_plain(FeatureConfig, json.loads(json.dumps(to_plain(features)))) == features
    assert to_plain(features) == features.to_dict()


def test_the_constructor_refuses_what_it_would_refuse_from_a_caller():
    with pytest.raises(TypeError, match="unexpected keyword argument 'colour'"):
        from_plain(Inner, {"sides": [1, 2], "colour": "red"})
    with pytest.raises(TypeError, match="missing 1 required positional argument: 'sides'"):
        from_plain(Inner, {})
    with pytest.raises(TypeError, match="must be a mapping"):
        from_plain(Inner, [1, 2])  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="stride"):
        from_plain(LookaheadConfig, {"after_s": 1.0, "stride": 0})
