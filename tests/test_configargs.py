"""Command-line flags made from typed configurations (terrapref.configargs)."""

from __future__ import annotations

import argparse
import doctest
from dataclasses import dataclass, field

import pytest

import terrapref.configargs
from terrapref.configargs import add_arguments, apply_arguments, option
from terrapref.errors import UserError
from terrapref.learning.train import TrainConfig
from terrapref.recipes import RECIPES


def test_the_module_examples_run():
    assert doctest.testmod(terrapref.configargs, verbose=False).failed == 0


@dataclass(frozen=True)
class Inner:
    weight: float = option(1.5, "a weight", flag="inner-weight")


@dataclass(frozen=True)
class Part:
    scale: float = option(1.0, "a scale")


@dataclass(frozen=True)
class Outer:
    epochs: int = option(15, "passes")
    name: str = option("relu", "an activation", choices=("relu", "tanh"))
    hidden: int = 3  # no help text: not a flag
    inner: Inner | None = option(None, "turn the inner part on")
    always: Part = field(default_factory=Part)


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    add_arguments(parser, Outer)
    return parser.parse_args(argv)


def test_only_given_flags_change_the_base():
    base = Outer(epochs=300, inner=Inner(2.0))
    assert apply_arguments(_parse([]), base) == base
    assert apply_arguments(_parse(["--epochs", "4", "--name", "tanh"]), base) == Outer(4, "tanh", 3, Inner(2.0), Part())


def test_an_optional_part_is_a_switch_and_its_fields_apply_when_on():
    assert apply_arguments(_parse(["--inner"]), Outer()).inner == Inner()
    assert apply_arguments(_parse(["--inner", "--inner-weight", "4"]), Outer()).inner == Inner(4.0)
    assert apply_arguments(_parse(["--no-inner"]), Outer(inner=Inner(2.0))).inner is None
    with pytest.raises(ValueError, match="--inner-weight needs --inner"):
        apply_arguments(_parse(["--inner-weight", "4"]), Outer())  # off, so the weight would change nothing
    with pytest.raises(ValueError, match="--inner-weight needs --inner"):
        apply_arguments(_parse(["--no-inner", "--inner-weight", "4"]), Outer(inner=Inner(2.0)))
    # A nested part without a help text of its own is walked: its fields' flags set it.
    assert apply_arguments(_parse(["--scale", "4"]), Outer()).always == Part(4.0)


def test_a_percent_sign_in_help_and_a_float_field_with_an_int_default():
    @dataclass(frozen=True)
    class Odd:
        share: float = option(1, "share of the data in %")

    parser = argparse.ArgumentParser()
    add_arguments(parser, Odd)
    assert "share of the data in %" in parser.format_help()
    assert apply_arguments(parser.parse_args(["--share", "0.5"]), Odd()) == Odd(0.5)


def test_fields_without_help_and_bad_choices_are_not_flags():
    with pytest.raises(SystemExit):
        _parse(["--hidden", "4"])
    with pytest.raises(SystemExit):
        _parse(["--name", "sigmoid"])


def test_the_train_flags_cover_every_documented_training_field():
    parser = argparse.ArgumentParser()
    add_arguments(parser, TrainConfig)
    flags = {a.option_strings[0] for a in parser._actions if a.option_strings and a.option_strings[0] != "-h"}
    assert flags == {
        "--epochs",
        "--lr",
        "--batch-size",
        "--hidden",
        "--activation",
        "--skip",
        "--members",
        "--class-balance",
        "--mirror",
        "--steady-labels",
        "--seed",
    }
    args = parser.parse_args(["--members", "1"])
    config = apply_arguments(args, RECIPES["teach"].train)
    assert config.classifier.members == 1
    assert config.optimiser == RECIPES["teach"].train.optimiser and config.data == RECIPES["teach"].train.data


def test_the_stage_flags_change_the_recipes_stages():
    from terrapref.cli import build_parser
    from terrapref.recipes import rules_with
    from terrapref.rules import OffsetConfig, SecondStageConfig, SpeedConfig

    def stages(recipe: str, *flags: str) -> tuple:
        args = build_parser().parse_args(["train", "rec", "--out", "m.safetensors", *flags])
        return rules_with(RECIPES[recipe], args.second_stage, args.stage_weight)

    assert stages("teach") == RECIPES["teach"].rules
    assert stages("teach", "--no-second-stage") == (OffsetConfig(), SpeedConfig())
    assert stages("teach", "--stage-weight", "3") == (SecondStageConfig(weight=3.0, lookahead=True), OffsetConfig(), SpeedConfig())
    assert stages("paper", "--second-stage", "--stage-weight", "3") == (SecondStageConfig(weight=3.0),)
    with pytest.raises(UserError, match="--stage-weight"):
        stages("paper", "--stage-weight", "3")
    with pytest.raises(SystemExit):  # refused by the command line itself, in one line naming the flag (tests/cli/test_bad_inputs.py)
        stages("ours", "--stage-weight", "-1")


def test_a_configuration_changed_part_by_part():
    base = RECIPES["teach"].train
    changed = base.updated({"classifier": {"hidden": 16}, "seed": 4})
    assert changed.classifier.hidden == 16 and changed.classifier.members == base.classifier.members
    assert changed.seed == 4 and changed.optimiser == base.optimiser
    with pytest.raises(ValueError):
        base.updated({"optimiser": {"epochs": 0}})
