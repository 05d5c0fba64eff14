"""The figures the README and the tutorial state are the ones the code gives (issue 19): the
README's sample table and in-position sentence are read from it and run (cycle times to the
millisecond, as printed; loads to 0.05 N and powers to 0.5 W, their last digit); the
tutorial is filled in by scripts/tutorial.py from runs of its own commands, and checked
here to be what they print."""
from __future__ import annotations

import json
import re
import subprocess
import sys

import pytest
from conftest import ROOT

README = (ROOT / "README.md").read_text(encoding="utf-8")
TUTORIAL = (ROOT / "docs" / "tutorial.md").read_text(encoding="utf-8")

# | `pocket.nc` | 73.402 s | 77.5 N (75) | 440 / 146 W |
ROW = re.compile(r"^\| `([a-z_]+\.nc)` \| ([0-9.]+) s \| (?:([0-9.]+) N \((\d+)\)|— \(plunges\)) \| (\d+) / (\d+) W \|$",
                 re.M)
ROWS = ROW.findall(README)


def _simulate(name: str) -> dict:
    r = subprocess.run([sys.executable, "-m", "mtwin", "simulate", str(ROOT / "samples" / name), "--json"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def test_the_readme_has_its_sample_table():
    assert [r[0] for r in ROWS] == ["pocket.nc", "contour.nc", "drilling.nc", "face_slot_inch.nc"]


@pytest.mark.parametrize("row", ROWS, ids=[r[0] for r in ROWS])
def test_the_readme_sample_table_is_what_simulate_gives(row):
    name, cycle, load, line, peak_w, mean_w = row
    s = _simulate(name)
    assert s["cycle_time"] == pytest.approx(float(cycle), abs=0.0005)
    if load:
        assert s["peak_load"] == pytest.approx(float(load), abs=0.05)
        assert s["peak_load_line"] == int(line)
    assert s["peak_power"] == pytest.approx(float(peak_w), abs=0.5)
    assert s["mean_cutting_power"] == pytest.approx(float(mean_w), abs=0.5)


def test_the_readme_drilling_waits_are_what_simulate_gives():
    m = re.search(r"`drilling\.nc` spends ([0-9.]+) s waiting for the axes to settle within ([0-9.]+) mm at (\d+) "
                  r"stops", README.replace("\n", " "))
    assert m, "the sentence about drilling.nc's in-position waits is gone from the README"
    s = _simulate("drilling.nc")
    assert s["in_position_wait"] == pytest.approx(float(m.group(1)), abs=0.05)


def test_the_tutorial_is_what_its_commands_print():
    """scripts/tutorial.py runs the tutorial's commands and fills in their output; --check
    says whether docs/tutorial.md is still what they print (about 30 s)."""
    r = subprocess.run([sys.executable, str(ROOT / "scripts" / "tutorial.py"), "--check"], capture_output=True,
                       text=True)
    assert r.returncode == 0, "docs/tutorial.md is stale (python scripts/tutorial.py rewrites it):\n" + r.stdout + r.stderr
