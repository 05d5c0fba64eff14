"""`mtwin simulate` and `mtwin config`: JSON keys, trace files, reproducibility, clear errors."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

from conftest import SAMPLES
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
