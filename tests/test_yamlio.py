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


def test_a_string_that_reads_as_a_number_is_written_quoted_and_read_back_a_string():
    data = {"name": "1e5", "id": "12", "x": 0.05, "y": 1e-7, "z": 1e20}
    assert load_yaml_text(dump_yaml(data)) == data


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
