"""The YAML reader and writer every terrapref file goes through."""

from __future__ import annotations

import pytest
import yaml

from terrapref.scenario import FORMAT, parse_scenario
from terrapref.yamlio import dump_yaml, load_yaml_text


def test_numbers_with_an_exponent_and_no_dot_are_numbers_as_yaml_1_2_reads_them():
    """PyYAML alone reads 5e-2 as a string: a file another tool wrote would be refused field by field."""
    read = load_yaml_text("a: 5e-2\nb: 1E3\nc: -2e+1\nd: 5.0e-2\ne: '5e-2'\nf: e5\ng: 12\n")
    assert read == {"a": 0.05, "b": 1000.0, "c": -20.0, "d": 0.05, "e": "5e-2", "f": "e5", "g": 12}


def test_numbers_are_what_yaml_1_2_reads_as_numbers_and_nothing_else():
    """YAML 1.1's forms (PyYAML's) are strings: 1:30 is not 90, 2_0 not 20, 010 not 8; a dot
    with an exponent is a number (2.5e1)."""
    read = load_yaml_text("a: 2.5e1\nb: 1:30\nc: 2_0\nd: 010\ne: 0x1f\nf: 0o17\ng: .inf\nh: -.Inf\ni: .5\nj: 0b11\nk: 1.\n")
    assert read == {"a": 25.0, "b": "1:30", "c": "2_0", "d": 10, "e": 31, "f": 15, "g": float("inf"), "h": float("-inf")} | {
        "i": 0.5,
        "j": "0b11",
        "k": 1.0,
    }
    assert load_yaml_text("a: .nan")["a"] != load_yaml_text("a: .nan")["a"]  # NaN


def test_booleans_are_true_and_false_as_yaml_1_2_reads_them_and_yes_no_on_off_are_words():
    """YAML 1.1 (PyYAML's) reads `on` as True: a class table naming a class `on` was refused
    ("must be an identifier-like string") and a scenario's `class: on` read "got boolean True"."""
    read = load_yaml_text("a: [true, True, TRUE, false, False, FALSE]\nb: [yes, no, on, off, y, n, Yes, OFF]\nc: ~\n")
    assert read == {"a": [True, True, True, False, False, False], "b": ["yes", "no", "on", "off", "y", "n", "Yes", "OFF"], "c": None}
    assert load_yaml_text(dump_yaml({"b": ["on", "yes", "no", "off"], "t": True})) == {"b": ["on", "yes", "no", "off"], "t": True}
    assert "'on'" in dump_yaml({"class": "on"})  # quoted still, for the readers of YAML 1.1


def test_a_string_that_reads_as_a_number_is_written_quoted_and_read_back_a_string():
    data = {"name": "1e5", "id": "12", "x": 0.05, "y": 1e-7, "z": 1e20, "w": "2.5e1", "v": ".5"}
    assert load_yaml_text(dump_yaml(data)) == data


def test_aliases_that_repeat_a_million_values_are_refused_before_anything_is_built():
    """A few hundred bytes of aliases of aliases stand for billions of values, which a message
    quoting one of them would expand; a few aliases are read as YAML reads them."""
    levels = ["a0: &l0 [x, x, x, x, x, x, x, x, x, x]"]
    levels += [f"a{i}: &l{i} [{', '.join([f'*l{i - 1}'] * 10)}]" for i in range(1, 7)]
    with pytest.raises(yaml.YAMLError, match="aliases repeat more than 1,000,000 values"):
        load_yaml_text("\n".join(levels) + "\nnoise_m: *l6\n")
    assert load_yaml_text("a: &p [1, 2]\nb: *p\nc: {d: *p}\n") == {"a": [1, 2], "b": [1, 2], "c": {"d": [1, 2]}}


def test_a_whole_number_too_long_to_read_is_refused_at_its_line():
    with pytest.raises(yaml.YAMLError, match="a whole number of 5,001 digits"):
        load_yaml_text("a: 1\nb: " + "1" * 5001 + "\n")


def test_a_scenario_with_exponents_reads_as_with_decimals():
    text = (
        f"format: {FORMAT}\nname: e\nworld: {{size_m: [2e1, 1e1], resolution_m: 1e-1, background: grass}}\n"
        "path: {waypoints: [[1, 5], [19, 5]]}\n"
    )
    decimals = text.replace("2e1", "20.0").replace("1e1", "10.0").replace("1e-1", "0.1")
    read, expected = parse_scenario(load_yaml_text(text), "e.yaml"), parse_scenario(load_yaml_text(decimals), "e.yaml")
    assert (read.size_m, read.resolution_m) == (expected.size_m, expected.resolution_m) == ((20.0, 10.0), 0.1)


@pytest.mark.parametrize(
    "text",
    [
        "a: 1\nb: 2\na: 3\n",  # block style, another line
        "relief: [{mound: {height_m: 0.4, height_m: 900}}]\n",  # flow style, the same line
        "{a: 1, b: {c: 2, c: 2}}\n",  # the same value twice is still a key given twice
    ],
)
def test_a_key_given_twice_in_one_mapping_is_refused_on_one_line_as_on_two(text: str):
    with pytest.raises(yaml.YAMLError, match=r"given twice \(first at line 1\)"):
        load_yaml_text(text)


def test_the_same_key_in_two_mappings_on_one_line_is_not_a_key_given_twice():
    assert load_yaml_text("a: [{x: 1}, {x: 2}]\n") == {"a": [{"x": 1}, {"x": 2}]}
