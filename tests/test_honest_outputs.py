"""Warnings a careful user expects and outputs that mean what they say (issue 19): a feed above
the machine's maximum, the default stock from the arcs' own extent, one message about a
guessed stock, shares that add up, units, full-width tables when piped, config check
describing the file's machine, the structured tool list, Ctrl-C, --lenient's hint."""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from conftest import ROOT

import mtwin


def _cli(*args, **kw):
    return subprocess.run([sys.executable, "-m", "mtwin", *args], capture_output=True, text=True, **kw)


def test_a_feed_above_the_machines_maximum_is_a_warning_and_runs_at_the_maximum(tmp_path):
    (tmp_path / "f.nc").write_text("G21 G90 G94\nG0 X0 Y0 Z5\nG1 X100 F1000000000\nG1 X0 F30000\nM30\n")
    r = _cli("simulate", str(tmp_path / "f.nc"), "--no-cutting", "--json")
    assert r.returncode == 0, r.stderr
    # no maximum cutting feed in the twin: a feed no path can reach runs at the axes' limits
    assert ("f.nc:3:1: warning: the feed of this line, 1e+09 mm/min, is above what the axes can run together "
            "(59,093 mm/min)") in r.stderr
    tw = mtwin.Twin()
    a = tw.plan(tw.load(str(tmp_path / "f.nc")))
    b = tw.plan(tw.load(b"G21 G90 G94\nG0 X0 Y0 Z5\nG1 X100 F36000\nG1 X0 F30000\nM30\n", path="g.nc"))
    assert a.total_time == pytest.approx(b.total_time, rel=1e-12)  # X at its 36 m/min
    # the control's maximum cutting feed: clamped to it, as the control does
    (tmp_path / "m.toml").write_text("[controller]\nmax_cutting_feed = 20000.0\n")
    r = _cli("simulate", str(tmp_path / "f.nc"), "--no-cutting", "--twin", str(tmp_path / "m.toml"))
    assert "1e+09 mm/min, is above the machine's maximum cutting feed 20000 mm/min: feeds are clamped to it" in r.stderr
    tw2 = mtwin.Twin.from_toml(str(tmp_path / "m.toml"))
    c = tw2.plan(tw2.load(str(tmp_path / "f.nc")))
    d = tw2.plan(tw2.load(b"G21 G90 G94\nG0 X0 Y0 Z5\nG1 X100 F20000\nG1 X0 F30000\nM30\n", path="g.nc"))
    assert c.total_time == pytest.approx(d.total_time, rel=1e-12)
    # a feed within it says nothing
    ok = _cli("simulate", str(ROOT / "samples" / "contour.nc"), "--no-cutting")
    assert "cutting feed" not in ok.stderr and "can run together" not in ok.stderr


def test_optimize_refusal_uses_the_machines_bounds(tmp_path):
    (tmp_path / "p.nc").write_text("G21 G90 G94\n(T1 D=6. CR=0. - FLAT END MILL)\nT1 M6\nS8000 M3\nG0 X0 Y0 Z5\n"
                                   "G1 Z-3 F300\nG1 X50 F1000000000\nM30\n")
    r = _cli("optimize", str(tmp_path / "p.nc"), "-o", str(tmp_path / "o.nc"), "--force-limit", "1", "--json")
    assert r.returncode == 2
    doc = json.loads(r.stdout)
    assert doc["written"] is False
    low = min(x["at_feed"] for x in doc["reasons"])
    assert low <= 30000.0 * 0.1  # the range is the machine's, not 10 % of F1e9
    assert "1e+08" not in r.stderr


def test_the_default_stock_spans_the_arcs_own_sweep(tmp_path):
    # a quarter arc of radius 100: its circle's box would be 200 x 200 mm
    src = ("G21 G90 G17 G94\n(T1 D=6. CR=0. - FLAT END MILL)\nT1 M6\nS8000 M3\nG0 X0 Y0 Z5\nG1 Z-1 F300\n"
           "G2 X100 Y100 I100 J0 F1000\nG0 Z5\nM30\n")
    tw = mtwin.Twin()
    tr = tw.simulate(tw.load(src.encode(), path="a.nc"))
    box = tr.summary.cutting.stock
    assert box == pytest.approx([-3.0, -3.0, -2.0, 103.0, 103.0, 0.0])  # the sweep, the tool radius, Z0 top
    # a G18 arc too (its sweep in X and Z)
    pl = tw.plan(tw.load(b"G21 G90 G18\nG0 X10 Y0 Z0\nG1 Y-1 F300\nG2 X0 Z10 I-10 K0 F1000\nM30\n", path="b.nc"))
    np.testing.assert_allclose(pl.feed_box, [[0.0, -1.0, 0.0], [10.0, 0.0, 10.0]], atol=1e-9)


def test_one_message_about_the_stock_when_the_spindle_is_stopped(tmp_path):
    (tmp_path / "s.nc").write_text("G21 G90 G94\nG0 X0 Y0 Z5\nG1 Z-1 F300\nG1 X10\nM30\n")
    r = _cli("simulate", str(tmp_path / "s.nc"))
    assert "spindle stopped" in r.stderr and "no feed move meets the stock" not in r.stderr
    assert "not modelled: the feed moves cut the stock with the spindle stopped (line 3" in r.stderr
    # the one wording of a guessed stock, in simulate and in optimize's warning
    (tmp_path / "g.nc").write_text("G21 G90 G94\nS8000 M3\nG0 X0 Y0 Z5\nG1 Z-1 F300\nG1 X10\nG1 Z2\n"
                                   "G1 Z5 X30\nM30\n")
    r = _cli("simulate", str(tmp_path / "g.nc"))
    assert "guessed from the feed moves (their extent and the tool radius, top at Z0)" in r.stderr


def test_summary_shares_add_up_and_tables_carry_units(tmp_path):
    tw = mtwin.Twin()
    prog_path = ROOT / "samples" / "pocket.nc"
    tr = tw.simulate(tw.load(str(prog_path)))
    line, p = np.asarray(tr.line), np.asarray(tr.signal("spindle_power"))
    rows = []
    for k, ln in enumerate(sorted(set(line[line > 0].tolist()))[:12]):
        v = float(np.mean(p[line == ln])) * (1.0 + 0.3 * (k % 3))  # some rows far off
        rows.append(f"{ln},{ln},{v:.6g}")
    (tmp_path / "s.csv").write_text("first_line,last_line,spindle_power_mean\n" + "\n".join(rows) + "\n")
    r = _cli("compare", str(prog_path), str(tmp_path / "s.csv"), "--json")
    assert r.returncode == 0, r.stderr
    shares = [w["share"] for w in json.loads(r.stdout)["worst_regions"]]
    assert shares and max(shares) <= 1.0 and sum(shares) <= 1.0 + 1e-9
    r = _cli("compare", str(prog_path), str(tmp_path / "s.csv"))
    assert "unit" in r.stderr and "│ W " in r.stderr.replace("┃", "│")


def test_tables_are_not_cut_when_piped(tmp_path):
    d = tmp_path / "a_rather_long_directory_name_for_the_shop_floor_programs" / "and_one_more_level_of_them"
    d.mkdir(parents=True)
    (d / "pocket_with_a_long_name.nc").write_bytes((ROOT / "samples" / "pocket.nc").read_bytes())
    r = _cli("simulate", str(d / "pocket_with_a_long_name.nc"), env={**__import__("os").environ, "COLUMNS": ""})
    assert r.returncode == 0, r.stderr
    assert str(d / "pocket_with_a_long_name.nc") in r.stderr  # not broken mid-word at 80 columns
    assert max(len(x) for x in r.stderr.splitlines()) > 80


def test_config_check_describes_the_files_machine(tmp_path):
    (tmp_path / "my.toml").write_text("[spindle]\nmax_speed = 42000.0\nrated_power = 15000.0\n")
    r = _cli("config", "check", str(tmp_path / "my.toml"))
    assert r.returncode == 0, r.stderr
    assert "15 kW / 42,000 rpm" in r.stderr and "11 kW" not in r.stderr and "mtwin default" not in r.stderr
    named = tmp_path / "named.toml"
    named.write_text('[machine]\nname = "Haas VF-2"\n')
    assert "Haas VF-2" in _cli("config", "check", str(named)).stderr


def test_simulate_and_optimize_json_list_the_tools(tmp_path):
    r = _cli("simulate", str(ROOT / "samples" / "pocket.nc"), "--json", "--tool", "7=ball:8:3")
    tools = json.loads(r.stdout)["tools"]
    assert tools == [{"number": 1, "type": "flat", "diameter": 6.0, "flutes": 2, "corner_radius": 0.0,
                      "source": "program comment", "line": 4, "form": "Fusion 360"}]
    r = _cli("optimize", str(ROOT / "samples" / "pocket.nc"), "-o", str(tmp_path / "o.nc"), "--json",
             "--tool", "1=ball:8:3")
    (t,) = json.loads(r.stdout)["tools"]
    assert (t["number"], t["type"], t["diameter"], t["flutes"], t["corner_radius"], t["source"]) == \
        (1, "ball", 8.0, 3, 4.0, "--tool")


def test_ctrl_c_says_so_and_writes_nothing(tmp_path):
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_motion import make_program

    (tmp_path / "big.nc").write_bytes(make_program(60000))
    # (SIGINT restored for the child: a test run started in the background ignores it, and a
    # process that starts with SIGINT ignored keeps ignoring it)
    p = subprocess.Popen([sys.executable, "-m", "mtwin", "optimize", str(tmp_path / "big.nc"), "-o",
                          str(tmp_path / "o.nc")], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         start_new_session=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    time.sleep(4.0)  # (past start-up: the run is simulating or searching)
    if p.poll() is not None:
        pytest.skip("the run finished before the signal")
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=60)
    assert p.returncode == 130, err[-500:]
    assert "interrupted (Ctrl-C): no output is left half-written" in err
    assert not (tmp_path / "o.nc").exists() and not list(tmp_path.glob("*.tmp*"))


def test_lenient_is_offered_only_where_it_helps(tmp_path):
    (tmp_path / "a.nc").write_text("G21 G90\nG0 X0 Y0\nG1 X5 Y5 F100 G13.7\nM30\n")
    (tmp_path / "b.nc").write_text("G21 G90\nG0 X0 Y0\nG13.7\nM30\n")
    a = _cli("parse", str(tmp_path / "a.nc"))
    assert a.returncode == 2 and "--lenient does not pass over it" in a.stderr
    b = _cli("parse", str(tmp_path / "b.nc"))
    assert b.returncode == 2 and "--lenient passes over codes that do not move the tool" in b.stderr
    assert _cli("parse", str(tmp_path / "b.nc"), "--lenient").returncode == 0
    c = _cli("parse", str(tmp_path / "a.nc"), "--lenient")
    assert c.returncode == 2 and "even with --lenient" in c.stderr
