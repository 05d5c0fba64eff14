"""The one TOML writer (issue 20): every value it writes reads back as itself with the
standard library's tomllib — names with quotes, backslashes and control characters included,
which the machine's writer did not escape before."""
from __future__ import annotations

import math
import tomllib

import pytest

from mtwin.tomlwrite import dump_tables, inline_table, toml_key, toml_string, toml_value

AWKWARD = ['plain', 'say "hi"', 'back\\slash', 'tab\there', 'new\nline', 'bell\x07', 'del\x7f', 'ünï ✓', '']


@pytest.mark.parametrize("text", AWKWARD)
def test_strings_read_back(text):
    assert tomllib.loads(f"v = {toml_string(text)}")["v"] == text
    assert tomllib.loads(f"{toml_key(text or 'x')} = 1") == {text or "x": 1}


def test_values_read_back():
    values = [True, False, 0, -7, 1.5, 1e-300, 123456789.125, [1.0, 2.0], ["a", 'b"'], math.inf, -math.inf]
    for v in values:
        assert tomllib.loads(f"v = {toml_value(v)}")["v"] == v
    assert math.isnan(tomllib.loads(f"v = {toml_value(math.nan)}")["v"])
    with pytest.raises(TypeError):
        toml_value(object())
    got = tomllib.loads(f"t = {inline_table({'a b': 1.0, 'c': None})}")["t"]
    assert got["a b"] == 1.0 and math.isnan(got["c"])


def test_tables_read_back():
    doc = {"machine": {"name": 'the "big" one'}, "axes": {"x": {"servo": {"kpp": 30.0}, "mass": 200.0}},
           "odd key": {"v": [1, 2]}}
    assert tomllib.loads("\n".join(dump_tables(doc))) == doc


def test_the_machine_file_escapes_its_name():
    from dataclasses import replace

    from mtwin.twin.machine import Machine, machine_toml

    m = replace(Machine(), name='VMC "A"\\2')
    assert tomllib.loads(machine_toml(m))["machine"]["name"] == 'VMC "A"\\2'


def test_the_grind_cycle_file_reads_back():
    from mtwin.grind.cycle import Stage
    from mtwin.grind.io import cycle_toml
    from mtwin.grind.model import GrindTwin

    tw = GrindTwin()
    doc = tomllib.loads(cycle_toml(tw, [Stage(1.25, 0.05), Stage(0.3, 0.0)], "note"))
    assert doc["cycle"]["stages"] == [{"feed": 1.25, "switch_allowance": 0.05}, {"feed": 0.3, "switch_allowance": 0.0}]
