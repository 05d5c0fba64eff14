"""`mtwin simulate` and `mtwin config`: JSON keys, trace files, reproducibility, clear errors;
outputs that mean what they say (a feed over the machine's maximum, the guessed stock, shares
that add up, the tools listed)."""
from __future__ import annotations

import json
import re
import subprocess
import sys

import numpy as np
import pytest

import mtwin as mtwin_api  # (the package: `mtwin` here is the command runner)
from conftest import ROOT, SAMPLES
from test_cli import mtwin

SAMPLE_PROGRAMS = sorted(p.name for p in SAMPLES.glob("*.nc"))
MEASUREMENT_COLUMNS = ["t", "line", "x", "y", "z", "x_cmd", "y_cmd", "z_cmd", "x_err", "y_err", "z_err",
                       "x_vel", "y_vel", "z_vel", "feed", "x_torque", "y_torque", "z_torque",
                       "x_current", "y_current", "z_current", "spindle_speed", "spindle_torque", "spindle_power",
                       "fx", "fy", "fz", "ae", "ap", "mrr", "h_max"]


@pytest.mark.parametrize("name", SAMPLE_PROGRAMS)
def test_simulate_json_is_complete_and_reproducible(name):
    runs = [mtwin("simulate", str(SAMPLES / name), "--json") for _ in range(2)]
    for r in runs:
        assert r.returncode == 0, r.stderr.decode()
    a, b = (json.loads(r.stdout) for r in runs)
    for key in ("cycle_time", "cutting_time", "rapid_time", "dwell_time"):
        assert isinstance(a[key], float) and a[key] >= 0
    for key in ("max_following_error", "max_torque"):
        assert set(a[key]) == {"x", "y", "z"}
    assert round(a["cycle_time"], 3) == round(b["cycle_time"], 3)
    parts = a["cutting_time"] + a["rapid_time"] + a["dwell_time"] + a["tool_change_time"] + a["spindle_wait_time"]
    assert parts == pytest.approx(a["cycle_time"], rel=1e-9)
    print(f"{name}: cycle time {a['cycle_time']:.3f} s")


def test_simulate_table_on_stderr():
    r = mtwin("simulate", str(SAMPLES / "contour.nc"))
    assert r.returncode == 0
    assert r.stdout == b""
    text = r.stderr.decode()
    assert "cycle time" in text and "max following error" in text and "tool T2" in text


def test_trace_csv_follows_the_measurement_format(tmp_path):
    out = tmp_path / "trace.csv"
    r = mtwin("simulate", str(SAMPLES / "contour.nc"), "-o", str(out), "--every", "10")
    assert r.returncode == 0, r.stderr.decode()
    lines = out.read_text().splitlines()
    meta = [ln for ln in lines if ln.startswith("#")]
    assert meta[0] == "# format: mtwin-measurement 1"
    header = lines[len(meta)].split(",")
    assert header == MEASUREMENT_COLUMNS + ["record"]  # the record index: kept, ignored by readers
    data = np.loadtxt(out, delimiter=",", comments="#", skiprows=len(meta) + 1)
    assert np.all(np.diff(data[:-1, 0]) == pytest.approx(0.01))  # the last sample is always kept
    col = {n: data[:, i] for i, n in enumerate(header)}
    for a in "xyz":
        assert np.allclose(col[f"{a}_cmd"] - col[a], col[f"{a}_err"], atol=2e-5)
    j = json.loads(mtwin("simulate", str(SAMPLES / "contour.nc"), "--json").stdout)
    n = j["samples"]
    assert len(data) == (n - 1) // 10 + 1 + (1 if (n - 1) % 10 else 0)
    # --decimate 100 Hz is the same as --every 10 at a 1 ms servo period
    out2 = tmp_path / "trace2.csv"
    assert mtwin("simulate", str(SAMPLES / "contour.nc"), "-o", str(out2), "--decimate", "100").returncode == 0
    assert out2.read_text() == out.read_text()


def test_config_show_round_trips_and_checks(tmp_path):
    r = mtwin("config", "show")
    assert r.returncode == 0
    f = tmp_path / "m.toml"
    f.write_bytes(r.stdout)
    assert mtwin("config", "check", str(f)).returncode == 0
    # the printed file reproduces the default machine exactly
    a = json.loads(mtwin("simulate", str(SAMPLES / "pocket.nc"), "--json").stdout)
    b = json.loads(mtwin("simulate", str(SAMPLES / "pocket.nc"), "--json", "--twin", str(f)).stdout)
    assert a["cycle_time"] == b["cycle_time"]


@pytest.mark.parametrize("edit,key", [
    (("mass             = 300.0", "mass = -5.0"), "axes.x.mass"),
    (("max_acceleration = 3000.0", "max_acceleration = 0.0"), "axes.x.max_acceleration"),
    (("max_acceleration = 3000.0", 'max_acceleration = "3 m/s"'), "axes.x.max_acceleration"),
    (("max_acceleration = 3000.0", 'max_acceleration = "3 furlongs"'), "axes.x.max_acceleration"),
    (("kpp                = 40.0", "kpp = 40.0\nkp_typo = 1.0"), "axes.x.servo.kp_typo"),
    (('style                 = "fanuc"', 'style = "haas"'), "controller.style"),
    (("servo_period          = 0.001", "servo_period = 0.5"), "controller.servo_period"),
])
def test_bad_configuration_names_the_key(tmp_path, edit, key):
    text = mtwin("config", "show").stdout.decode()
    old, new = edit
    assert old in text
    f = tmp_path / "bad.toml"
    f.write_text(text.replace(old, new, 1))
    for args in (("config", "check", str(f)), ("simulate", str(SAMPLES / "pocket.nc"), "--twin", str(f))):
        r = mtwin(*args)
        assert r.returncode == 2
        assert key in r.stderr.decode()


def test_feed_zero_is_an_error_with_its_line(tmp_path):
    f = tmp_path / "f0.nc"
    f.write_text("G21 G90 G94\nG0 X10\nG1 X20 F0\nM30\n")
    r = mtwin("simulate", str(f))
    assert r.returncode == 2
    assert re.search(r"f0\.nc:3:\d+: .*feed", r.stderr.decode())


def test_move_beyond_travel_is_an_error_naming_axis_and_line(tmp_path):
    # a twin file describes a real machine: its travel limits are hard, as on its control
    twin = tmp_path / "m.toml"
    twin.write_text("[machine]\nname = 'shop VMC'\n")
    f = tmp_path / "far.nc"
    f.write_text("G21 G90 G94\nG0 X10\nG1 Y300 F1000\nM30\n")
    r = mtwin("simulate", str(f), "--twin", str(twin), "--no-cutting")
    assert r.returncode == 2
    msg = r.stderr.decode()
    assert "far.nc:3:" in msg and "axis Y" in msg and "axes.y.max_travel" in msg
    # an arc whose bulge leaves the travel, though its end points do not
    f.write_text("G21 G90 G94\nG0 X390 Y0\nG2 X390 Y0 I6 J0 F1000\nM30\n")
    r = mtwin("simulate", str(f), "--twin", str(twin), "--no-cutting")
    assert r.returncode == 2 and "far.nc:3:" in r.stderr.decode()


def test_the_default_machine_warns_beyond_its_travel_and_simulates(tmp_path):
    # the embedded default machine is nobody's machine: a NIST plate's G58 park move (Y 508 mm)
    # must not stop a first simulation
    f = tmp_path / "far.nc"
    f.write_text("G21 G90 G94\nG0 X10\nG1 Y300 F1000\nM30\n")
    r = mtwin("simulate", str(f), "--no-cutting", "--json")
    assert r.returncode == 0, r.stderr.decode()
    msg = r.stderr.decode()
    assert "far.nc:3:1: warning: move reaches Y = 300.000 mm" in msg and "default machine" in msg
    assert json.loads(r.stdout)["cycle_time"] > 300 / (1000 / 60)


def test_planner_override_and_bad_options():
    ok = mtwin("simulate", str(SAMPLES / "pocket.nc"), "--planner", "grbl", "--json")
    assert ok.returncode == 0 and json.loads(ok.stdout)["style"] == "grbl"
    for args in (("--planner", "haas"), ("--every", "0"), ("--decimate", "-5"), ("--every", "2", "--decimate", "5")):
        r = mtwin("simulate", str(SAMPLES / "pocket.nc"), *args)
        assert r.returncode == 2, args


def test_simulate_reads_stdin():
    data = (SAMPLES / "contour.nc").read_bytes()
    r = mtwin("simulate", "-", "--json", stdin=data)
    assert r.returncode == 0 and json.loads(r.stdout)["cycle_time"] > 0


def test_configuration_doc_shows_the_current_default_machine():
    from conftest import ROOT
    from mtwin.twin.machine import machine_toml

    assert machine_toml().rstrip() in (ROOT / "docs" / "configuration.md").read_text()


def test_trace_parquet_when_pyarrow_is_installed(tmp_path):
    pq = pytest.importorskip("pyarrow.parquet")
    out = tmp_path / "trace.parquet"
    r = mtwin("simulate", str(SAMPLES / "contour.nc"), "-o", str(out), "--every", "50")
    assert r.returncode == 0, r.stderr.decode()
    table = pq.read_table(out)
    assert table.column_names == MEASUREMENT_COLUMNS + ["record"]
    assert table.num_rows > 100


def test_simulate_cutting_keys_plot_and_defaults(tmp_path):
    svg = tmp_path / "power.svg"
    r = mtwin("simulate", str(SAMPLES / "pocket.nc"), "--json", "--plot", str(svg))
    assert r.returncode == 0, r.stderr.decode()
    d = json.loads(r.stdout)
    for key in ("peak_load", "peak_power", "mean_cutting_power", "peak_spindle_torque", "peak_load_line"):
        assert key in d
    assert d["peak_load"] > 0 and d["peak_power"] >= d["mean_cutting_power"] > 0
    assert 1 <= d["peak_load_line"] <= len((SAMPLES / "pocket.nc").read_bytes().splitlines())
    text = svg.read_text()
    assert text.startswith("<?xml") and "spindle power" in text and "program line" in text
    table = mtwin("simulate", str(SAMPLES / "pocket.nc")).stderr.decode()
    # pocket.nc declares its tool (line 4) and its material (line 3: "Al 6061")
    assert "al6061" in table and "comment line 4" in table and "comment line 3" in table
    bare = (SAMPLES / "pocket.nc").read_bytes().replace(b"(T1 D=6. CR=0. - FLAT END MILL, 2 FLUTES, CARBIDE)", b"")
    (tmp_path / "bare.nc").write_bytes(bare)
    table = mtwin("simulate", str(tmp_path / "bare.nc")).stderr.decode()
    assert "no description in the program" in table
    # without its material line the material is the default, said so
    (tmp_path / "nomat.nc").write_bytes(bare.replace(b", Al 6061", b""))
    table = mtwin("simulate", str(tmp_path / "nomat.nc")).stderr.decode()
    assert "default used" in table and "material: al6061 with the reference" in table


def test_simulate_stock_option_and_errors(tmp_path):
    f = tmp_path / "slot.nc"
    f.write_text("G21 G90 G94 S8000 M3\nG0 X-10 Y0 Z5\nG0 Z-2\nG1 X30 F600\nG0 Z5\nM30\n")
    ok = mtwin("simulate", str(f), "--json", "--stock", "0,-10,-10,40,10,0")
    assert ok.returncode == 0 and json.loads(ok.stdout)["peak_load"] > 10
    air = mtwin("simulate", str(f), "--json", "--stock", "0,20,-10,40,30,0")
    assert air.returncode == 0 and json.loads(air.stdout)["peak_load"] == 0
    bad = mtwin("simulate", str(f), "--stock", "0,-10,-1,40,10,0")
    assert bad.returncode == 2 and "slot.nc:4:" in bad.stderr.decode() and "stock bottom" in bad.stderr.decode()
    assert mtwin("simulate", str(f), "--stock", "1,2,3").returncode == 2
    inst = mtwin("simulate", str(f), "--json", "--stock", "0,-10,-10,40,10,0", "--tooth-resolution")
    assert inst.returncode == 0 and json.loads(inst.stdout)["peak_load"] > json.loads(ok.stdout)["peak_load"]


def test_machine_parameters_by_dotted_name():
    from mtwin.errors import MtwinError
    from mtwin.twin.machine import Machine, get_param, param_names, with_params

    names = param_names()
    assert "axes.x.servo.kpp" in names and "controller.bell_time" in names and "spindle.base_speed" in names
    m = with_params(Machine(), {"axes.z.friction.coulomb_pos": "0.2 kN", "controller.bell_time": 0.016})
    assert get_param(m, "axes.z.friction.coulomb_pos") == 200.0 and get_param(m, "controller.bell_time") == 0.016
    assert get_param(m, "axes.x.friction.coulomb_pos") == 150.0
    for bad in ({"axes.q.mass": 1.0}, {"axes.x.servo.nope": 1.0}, {"axes.x.mass": -3.0}, {"axes.x.servo": 1.0}):
        with pytest.raises(MtwinError):
            with_params(Machine(), bad)


def _cli(*args, **kw):
    """The command in a process of its own, text out (the outputs a user sees)."""
    return subprocess.run([sys.executable, "-m", "mtwin", *args], capture_output=True, text=True, **kw)


def test_a_feed_above_the_machines_maximum_is_a_warning_and_runs_at_the_maximum(tmp_path):
    (tmp_path / "f.nc").write_text("G21 G90 G94\nG0 X0 Y0 Z5\nG1 X100 F1000000000\nG1 X0 F30000\nM30\n")
    r = _cli("simulate", str(tmp_path / "f.nc"), "--no-cutting", "--json")
    assert r.returncode == 0, r.stderr
    # no maximum cutting feed in the twin: a feed no path can reach runs at the axes' limits
    assert ("f.nc:3:1: warning: the feed of this line, 1e+09 mm/min, is above what the axes can run together "
            "(59,093 mm/min)") in r.stderr
    tw = mtwin_api.Twin()
    a = tw.plan(tw.load(str(tmp_path / "f.nc")))
    b = tw.plan(tw.load(b"G21 G90 G94\nG0 X0 Y0 Z5\nG1 X100 F36000\nG1 X0 F30000\nM30\n", path="g.nc"))
    assert a.total_time == pytest.approx(b.total_time, rel=1e-12)  # X at its 36 m/min
    # the control's maximum cutting feed: clamped to it, as the control does
    (tmp_path / "m.toml").write_text("[controller]\nmax_cutting_feed = 20000.0\n")
    r = _cli("simulate", str(tmp_path / "f.nc"), "--no-cutting", "--twin", str(tmp_path / "m.toml"))
    assert "1e+09 mm/min, is above the machine's maximum cutting feed 20000 mm/min: feeds are clamped to it" in r.stderr
    tw2 = mtwin_api.Twin.from_toml(str(tmp_path / "m.toml"))
    c = tw2.plan(tw2.load(str(tmp_path / "f.nc")))
    d = tw2.plan(tw2.load(b"G21 G90 G94\nG0 X0 Y0 Z5\nG1 X100 F20000\nG1 X0 F30000\nM30\n", path="g.nc"))
    assert c.total_time == pytest.approx(d.total_time, rel=1e-12)
    # a feed within it says nothing
    ok = _cli("simulate", str(ROOT / "samples" / "contour.nc"), "--no-cutting")
    assert "cutting feed" not in ok.stderr and "can run together" not in ok.stderr


def test_the_default_stock_spans_the_arcs_own_sweep(tmp_path):
    # a quarter arc of radius 100: its circle's box would be 200 x 200 mm
    src = ("G21 G90 G17 G94\n(T1 D=6. CR=0. - FLAT END MILL)\nT1 M6\nS8000 M3\nG0 X0 Y0 Z5\nG1 Z-1 F300\n"
           "G2 X100 Y100 I100 J0 F1000\nG0 Z5\nM30\n")
    tw = mtwin_api.Twin()
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
    tw = mtwin_api.Twin()
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
