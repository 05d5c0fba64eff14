"""Per-cut summary measurements through the whole loop (issue 21, its first part): diagnose,
calibrate and --validate read rows of statistics by line range as compare does — each row's
statistic of the simulated signal over its lines is the model's prediction, the noise comes
from the rows — and malformed rows are refused with file:line:col."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from conftest import SAMPLES

POCKET = str(SAMPLES / "pocket.nc")
RATE = 0.35  # the hidden tool wear, /m of cut


def _mtwin(*args, code=0):
    r = subprocess.run([sys.executable, "-m", "mtwin", *args], capture_output=True, text=True)
    assert r.returncode == code, r.stderr[-2000:]
    return r


@pytest.fixture(scope="module")
def cutters(tmp_path_factory):
    d = tmp_path_factory.mktemp("cutters")
    out = {}
    for name, rate, seed in (("a", RATE, 1), ("b", 0.42, 2)):
        out[name] = str(d / f"{name}.csv")
        _mtwin("synth", POCKET, "-o", out[name], "--summary", "line", "--effect", f"tool-wear:rate={rate}",
               "--noise", "0.03", "--seed", str(seed), "--signals", "fx,fy")
    return out


def test_synth_writes_one_row_per_line_the_tool_cuts(cutters):
    from mtwin.loop.measurement import read_measurement

    m = read_measurement(cutters["a"])
    assert m.is_summary and len(m.rows) > 50
    assert all(first == last for first, last, _ in m.rows)
    assert {"fx_rms", "fy_mean", "fy_max"} <= set(m.rows[0][2])


def test_diagnose_ranks_tool_wear_first_on_the_statistics(cutters):
    d = json.loads(_mtwin("diagnose", POCKET, cutters["a"], "--signals", "fx_rms,fy_rms", "--json").stdout)["signals"]
    for s in ("fx_rms", "fy_rms"):
        v = d[s]
        assert v["verdict"] == "explained" and v["candidates"][0]["effect"] == "tool-wear"
        assert v["candidates"][0]["params"]["rate"] == pytest.approx(RATE, rel=0.05)
        assert [x["effect"] for x in v["selected"]] == ["tool-wear"]
        assert v["rms_after"] <= 1.5 * v["noise"]


def test_the_noise_comes_from_the_rows(cutters):
    import mtwin

    d = mtwin.diagnose(None, POCKET, cutters["a"], signals=["fx_rms"], candidates=["tool-wear"])
    from mtwin.loop.measurement import read_measurement

    m = read_measurement(cutters["a"])
    v = np.array([st["fx_rms"] for _, _, st in m.rows])
    true = 0.03 * float(np.sqrt(np.mean(v * v)))  # the noise synth added: 3 % of the column's RMS
    assert d.signals["fx_rms"]["noise"] == pytest.approx(true, rel=0.25)


def test_calibrate_recovers_the_rate_and_validates_on_another_cutter(cutters, tmp_path):
    twin = str(tmp_path / "worn.toml")
    cal = json.loads(_mtwin("calibrate", POCKET, cutters["a"], "--fit", "tool-wear", "--signals", "fx_rms,fy_rms",
                            "-o", twin, "--validate", cutters["b"], "--json").stdout)
    assert cal["params"]["effects.tool-wear.rate"] == pytest.approx(RATE, rel=0.05)
    assert cal["uncertainty"]["effects.tool-wear.rate"] < 0.05 * RATE
    for s in ("fx_rms", "fy_rms"):
        assert cal["rms_after"][s] <= 1.5 * cal["noise"][s]
    # the second cutter wears 20 % faster: the calibrated twin is much nearer it than the as-built one
    before = json.loads(_mtwin("compare", POCKET, cutters["b"], "--json").stdout)["signals"]
    after = json.loads(_mtwin("compare", POCKET, cutters["b"], "--twin", twin, "--json").stdout)["signals"]
    for s in ("fx_rms", "fy_rms"):
        assert after[s]["rms"] < 0.5 * before[s]["rms"]
        assert cal["validation"][s] == pytest.approx(after[s]["rms"], rel=1e-6)


@pytest.mark.parametrize("body,where,what", [
    ("first_line,last_line,fx_rms\n12,10,3.0\n", ":2:1:", "not a range of program lines"),
    ("first_line,last_line,fx_rms\n12,12,3.0\n9999,9999,2.0\n", ":3:2:", "beyond the end"),
    ("first_line,last_line,fx_rmsx\n12,12,3.0\n", ":1:3:", "not a statistic"),
    ("first_line,last_line,fx_rms\n12,12,\n", ":2:3:", "no value"),
])
@pytest.mark.parametrize("command", ["diagnose", "calibrate", "compare"])
def test_malformed_rows_are_refused_with_their_place(tmp_path, body, where, what, command):
    f = tmp_path / "bad.csv"
    f.write_text(body)
    extra = ["--fit", "tool-wear", "-o", str(tmp_path / "t.toml")] if command == "calibrate" else []
    r = _mtwin(command, POCKET, str(f), *extra, code=2)
    assert f"bad.csv{where}" in r.stderr and what in r.stderr
    assert not (tmp_path / "t.toml").exists()
