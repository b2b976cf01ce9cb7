"""The one registry every named choice uses (terrapref.registry)."""

from __future__ import annotations

import doctest

import pytest

import terrapref.registry
from terrapref.errors import UserError
from terrapref.registry import Registry


def test_the_module_examples_run():
    assert doctest.testmod(terrapref.registry, verbose=False).failed == 0


def test_a_name_is_registered_once_and_unknown_names_are_listed():
    r: Registry[int] = Registry("policy", plural="policies")
    r.register("a", 1, doc="the first")
    r.register("b", 2)
    with pytest.raises(ValueError, match="already registered"):
        r.register("a", 3)
    assert list(r) == ["a", "b"] and len(r) == 2 and "a" in r and "c" not in r
    assert r.entry("a").doc == "the first"
    with pytest.raises(ValueError, match="unknown policy 'c'; policies: a, b"):
        r["c"]


def test_a_user_choice_names_the_flag_or_the_file_and_field():
    r: Registry[int] = Registry("recipe")
    r.register("teach", 1)
    assert r.get("teach", "--recipe") == 1
    with pytest.raises(UserError) as flag:
        r.get("nope", "--recipe")
    assert flag.value.lines() == ["--recipe: unknown recipe 'nope'; recipes: teach"]
    with pytest.raises(UserError) as file:
        r.get("nope", "stages[0].type", source="model.safetensors")
    assert file.value.lines() == ["model.safetensors: stages[0].type: unknown recipe 'nope'; recipes: teach"]


def test_an_entry_point_is_imported_on_first_use():
    r: Registry[object] = Registry("thing")
    r.register("unknown_id", "terrapref.terrain:UNKNOWN")
    from terrapref.terrain import UNKNOWN

    assert r["unknown_id"] == UNKNOWN
    assert dict(r.items()) == {"unknown_id": UNKNOWN}
