"""The measurement reader and `mtwin compare` (issue 10): a trace read back is the trace
under every alignment, malformed files are clear errors, units and maps convert, a twin
whose timing is off still aligns, and a hidden effect on some lines is found there."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

import mtwin
from conftest import SAMPLES
from mtwin.effects import Effect, register
from mtwin.loop.compare import compare
from mtwin.loop.measurement import Measurement, MeasurementError, read_measurement
from mtwin.params import Param
from test_cli import mtwin as run_cli

CONTOUR = str(SAMPLES / "contour.nc")


@pytest.fixture(scope="module")
def trace_csv(tmp_path_factory):
    out = tmp_path_factory.mktemp("trace") / "trace.csv"
    r = run_cli("simulate", CONTOUR, "-o", str(out), "--every", "10")
    assert r.returncode == 0, r.stderr.decode()
    return out


@pytest.mark.parametrize("align", ["line", "position", "xcorr"])
def test_a_simulated_trace_read_back_compares_to_zero(trace_csv, align):
    r = run_cli("compare", CONTOUR, str(trace_csv), "--align", align, "--json")
    assert r.returncode == 0, r.stderr.decode()
    d = json.loads(r.stdout)
    assert d["alignment"] == align and d["time_offset"] == pytest.approx(0.0, abs=1e-9)
    assert len(d["signals"]) >= 25
    for name, m in d["signals"].items():
        # zero to float precision: the trace's channels are float32 (7 digits)
        assert m["nrmse"] is None or m["nrmse"] < 1e-7, (name, m)
        assert m["correlation"] is None or m["correlation"] > 0.999999, (name, m)
    assert d["cycle_time"]["relative_error"] == pytest.approx(0.0, abs=1e-9)


MALFORMED = {
    "empty.csv": ("", "the file is empty"),
    "comments_only.csv": ("# format: mtwin-measurement 1\n", "the file is empty"),
    "header_only.csv": ("t,spindle_power\n", "no samples"),
    "no_time.csv": ("line,spindle_power\n1,2\n", "no time column"),
    "backwards.csv": ("t,spindle_power\n0.0,1\n0.2,1\n0.1,1\n", "time goes backwards"),
    "text.csv": ("t,spindle_power\n0.0,1\n0.1,lots\n", "'lots' in column 'spindle_power' is not a number"),
    "unit.csv": ("t,spindle_power[furlong]\n0.0,1\n", "unknown or wrong unit [furlong]"),
    "dimension.csv": ("t,spindle_power[mm]\n0.0,1\n", "unknown or wrong unit [mm]"),
    "cells.csv": ("t,spindle_power\n0.0,1,3\n", "3 cells where the header has 2"),
    "badline.csv": ("t,line,spindle_power\n0.0,2.5,1\n", "line 2.5 is not a line number"),
    "twice.csv": ("t,fx,fx\n0,1,1\n", "appear twice"),
}


@pytest.mark.parametrize("name", sorted(MALFORMED))
def test_malformed_measurements_are_clear_errors(tmp_path, name):
    text, message = MALFORMED[name]
    f = tmp_path / name
    f.write_text(text)
    with pytest.raises(MeasurementError, match=re.escape(message)):
        read_measurement(str(f))
    r = run_cli("compare", CONTOUR, str(f))
    assert r.returncode == 2 and message.split("'")[0] in r.stderr.decode() and name in r.stderr.decode()
    assert "Traceback" not in r.stderr.decode()


def test_units_in_headers_and_maps(tmp_path):
    f = tmp_path / "m.csv"
    f.write_text("time_ms,power[kW],x,junk\n0,1.5,0,a\n10,2.0,1,b\n")
    m = read_measurement(str(f), ["time_ms=t*0.001", "power=spindle_power"])
    np.testing.assert_allclose(m.t, [0.0, 0.01])
    np.testing.assert_allclose(m.signals["spindle_power"], [1500.0, 2000.0])
    r = run_cli("compare", CONTOUR, str(f), "--map", "power=warp_factor")
    assert r.returncode == 2 and "not a signal the twin produces" in r.stderr.decode()


def test_summary_measurements_are_read_row_by_row(tmp_path):
    f = tmp_path / "s.csv"
    f.write_text("first_line,last_line,fy_rms,spindle_power_mean\n10,17,35.5,300\n18,25,40,320\n")
    m = read_measurement(str(f))
    assert m.is_summary and m.rows[0] == (10, 17, {"fy_rms": 35.5, "spindle_power_mean": 300.0})
    f.write_text("first_line,last_line,fy_rms\n10,7,35.5\n")
    with pytest.raises(MeasurementError, match="not a range of program lines"):
        read_measurement(str(f))


def test_a_twin_whose_timing_is_off_still_aligns_by_line_and_position():
    # the "machine" accelerates more slowly than the twin: its cycle takes longer, yet each
    # sample is put at its place in the program
    tw = mtwin.Twin()
    machine = tw.with_params({"axes.x.max_acceleration": 400.0, "axes.y.max_acceleration": 400.0})
    prog = tw.load(CONTOUR)
    from mtwin.loop.synth import synthesize
    from mtwin.loop.measurement import Measurement

    cols = synthesize(machine, prog, rate=100, signals=["x", "y", "z", "spindle_power"])
    meas = Measurement("slow.csv", cols["t"], {k: cols[k] for k in ("x", "y", "z", "spindle_power")},
                       cols["line"].astype(np.int64))
    trace = tw.simulate(prog)
    assert abs(trace.summary.cycle_time - (cols["t"][-1] - cols["t"][0])) > 0.3  # timing really is off
    # measured here: line 1.0 % / 0.47 %, position 0.01 %, one constant offset (xcorr) 3.6 % / 2.9 %:
    # by line the samples land in their line (time inside it mapped linearly), by position
    # on their point of the path
    nrmse = {align: compare(trace, meas, align).signals for align in ("line", "position", "xcorr")}
    for a in ("x", "y"):
        assert nrmse["line"][a]["nrmse"] < 0.02
        assert nrmse["position"][a]["nrmse"] < 0.001
        assert nrmse["xcorr"][a]["nrmse"] > 2 * nrmse["line"][a]["nrmse"]
    # a plain time offset: cross-correlation finds it
    shifted = Measurement("late.csv", trace.t[::10] + 1.5, {"spindle_power": trace.signal("spindle_power")[::10]})
    c = compare(trace, shifted, "xcorr")
    assert c.time_offset == pytest.approx(-1.5, abs=0.011)


class HardInclusion(Effect):
    """Defined only here: a hard inclusion in the material along some lines."""

    name = "hard-inclusion"
    description = "a hard inclusion: the cutting coefficients rise on lines first..last"
    stage = "loop"
    params = (Param("first", "", 1.0, 1.0, 1e6, "first line"), Param("last", "", 1.0, 1.0, 1e6, "last line"),
              Param("factor", "", 1.0, 1.0, 5.0, "factor on the cutting coefficients there"))
    signals = ("spindle_power", "fx", "fy", "fz")

    def cutting_scale(self, steps, p):
        inside = (steps.line >= p["first"]) & (steps.line <= p["last"])
        return np.where(inside, p["factor"], 1.0)


def test_a_hidden_effect_on_some_lines_is_named_among_the_worst_regions():
    if "hard-inclusion" not in mtwin.effects.available():
        register(HardInclusion, "test")
    tw = mtwin.Twin()
    prog = tw.load(CONTOUR)
    from mtwin.loop.measurement import Measurement
    from mtwin.loop.synth import synthesize

    hidden = tw.with_effects("hard-inclusion:first=14,last=14,factor=1.6")  # the G2 arc X8 Y43
    cols = synthesize(hidden, prog, rate=100, noise=0.02, seed=1, signals=["spindle_power", "fy"])
    meas = Measurement("inclusion.csv", cols["t"], {"spindle_power": cols["spindle_power"], "fy": cols["fy"]},
                       cols["line"].astype(np.int64))
    c = compare(tw.simulate(prog), meas, "line")
    power = [r for r in c.worst_regions if r["signal"] == "spindle_power"][:3]
    assert any(r["first_line"] <= 14 <= r["last_line"] for r in power), power


def test_a_summary_measurement_is_compared_row_by_row(tmp_path):
    tw = mtwin.Twin()
    prog = tw.load(CONTOUR)
    trace = tw.simulate(prog)
    # rows made from the twin's own trace compare to zero; a row 20 % high is found
    rows = []
    for first, last in ((12, 19), (24, 27)):
        sel = (trace.line >= first) & (trace.line <= last)
        p = trace.signal("spindle_power")[sel]
        fy = trace.signal("fy")[sel]
        rows.append((first, last, float(p.mean()), float(np.sqrt(np.mean(fy * fy)))))
    f = tmp_path / "s.csv"
    f.write_text("first_line,last_line,spindle_power_mean,fy_rms\n"
                 + "".join(f"{a},{b},{c!r},{d!r}\n" for a, b, c, d in rows))
    c = compare(trace, read_measurement(str(f)))
    assert c.signals["spindle_power_mean"]["max_error"] < 1e-6 * rows[0][2]
    assert c.signals["fy_rms"]["max_error"] < 1e-6 * rows[0][3]
    a, b, p, fy = rows[1]
    f.write_text("first_line,last_line,spindle_power_mean\n"
                 f"{rows[0][0]},{rows[0][1]},{rows[0][2]!r}\n{a},{b},{p * 1.2!r}\n")
    r = run_cli("compare", CONTOUR, str(f), "--json")
    assert r.returncode == 0, r.stderr.decode()
    d = json.loads(r.stdout)
    assert d["worst_regions"][0]["first_line"] == a and d["worst_regions"][0]["last_line"] == b
    assert d["worst_regions"][0]["rms"] == pytest.approx(0.2 * p, rel=1e-6)


def test_the_compare_report_is_one_self_contained_html_file(tmp_path, trace_csv):
    out = tmp_path / "compare.html"
    r = run_cli("compare", CONTOUR, str(trace_csv), "--report", str(out))
    assert r.returncode == 0, r.stderr.decode()
    text = out.read_text()
    assert text.startswith("<!DOCTYPE html>") and text.count("<svg") >= 4
    assert "<script" not in text and "src=" not in text and "<link" not in text  # nothing fetched
    assert "spindle_power" in text and "Where it fails" in text
    r = run_cli("compare", CONTOUR, str(trace_csv), "--report", str(tmp_path / "r.pdf"))
    assert r.returncode == 2 and not (tmp_path / "r.pdf").exists()


def test_per_tooth_cycle_force_errors(tmp_path):
    # a dynamometer-rate recording of the twin itself: zero; with 10 % runout hidden: the
    # peak error per tooth cycle is at most the runout, its mean below it
    tooth = tmp_path / "tooth.csv"
    assert run_cli("simulate", CONTOUR, "--tooth-resolution", "-o", str(tooth)).returncode == 0
    d = json.loads(run_cli("compare", CONTOUR, str(tooth), "--tooth-resolution", "--json").stdout)
    for f in ("fx", "fy"):
        m = d["signals"][f]
        assert m["cycles"] > 1000 and m["peak_error_mean"] < 1e-6 and m["amplitude_error_mean"] < 1e-6
    ro = tmp_path / "runout.csv"
    assert run_cli("synth", CONTOUR, "--rate", "1000", "--signals", "fx,fy,spindle_speed", "--effect",
                   "runout:e=0.1", "-o", str(ro)).returncode == 0
    d = json.loads(run_cli("compare", CONTOUR, str(ro), "--json").stdout)
    m = d["signals"]["fy"]
    assert 0.05 < m["peak_error_mean"] < 0.1 and m["peak_error_max"] == pytest.approx(0.1, abs=1e-4)
    assert m["amplitude_error_mean"] is None  # revolution averages have no swing to compare


def test_a_parquet_trace_reads_back_as_the_csv_one(tmp_path):
    pytest.importorskip("pyarrow")
    out = tmp_path / "trace.parquet"
    assert run_cli("simulate", CONTOUR, "-o", str(out), "--every", "20").returncode == 0
    m = read_measurement(str(out))
    assert len(m.t) > 1000 and "spindle_power" in m.signals and m.line is not None
    d = json.loads(run_cli("compare", CONTOUR, str(out), "--json").stdout)
    assert max(v["nrmse"] or 0 for v in d["signals"].values()) < 1e-7


def test_a_file_with_only_unknown_columns_names_them(tmp_path):
    f = tmp_path / "u.csv"
    f.write_text("t,zz_torque\n0,1\n0.1,2\n")
    r = run_cli("compare", CONTOUR, str(f))
    assert r.returncode == 2 and "zz_torque" in r.stderr.decode() and "--map" in r.stderr.decode()


def test_a_spreadsheet_csv_with_a_bom_quoted_headers_and_odd_columns(tmp_path):
    f = tmp_path / "bom.csv"
    f.write_bytes('\ufeff"t [ms]",Spindle Power,"Feed Override (%)",\r\n0,100,100,\r\n10,120,100,\r\n'.encode())
    m = read_measurement(str(f), ["Spindle Power=spindle_power"])
    np.testing.assert_allclose(m.t, [0.0, 0.01])
    np.testing.assert_allclose(m.signals["spindle_power"], [100.0, 120.0])
    assert len(m.ignored) == 2  # the override and the empty header: kept out, noted


def test_blank_line_cells_do_not_break_line_alignment():
    tw = mtwin.Twin()
    prog = tw.load(CONTOUR)
    trace = tw.simulate(prog)
    t = trace.t[::10]
    line = np.asarray(trace.line[::10], dtype=np.int64).copy()
    line[1::97] = -1  # 1 % empty cells (between known ones)
    meas = Measurement("gaps.csv", t, {"x": trace.signal("x")[::10]}, line)
    c = compare(trace, meas, "line")
    assert c.signals["x"]["samples"] == len(t) and c.signals["x"]["max_error"] < 1e-6


def test_position_alignment_finds_a_logger_that_started_late():
    tw = mtwin.Twin()
    prog = tw.load(CONTOUR)
    trace = tw.simulate(prog)
    late = slice(12000, None, 10)  # the logger started 12 s into the program, in the contour cut
    meas = Measurement("late.csv", trace.t[late] - trace.t[12000],
                       {a: trace.signal(a)[late] for a in ("x", "y", "z")})
    c = compare(trace, meas, "position")
    assert c.time_offset == pytest.approx(12.0, abs=0.011)
    assert c.signals["x"]["max_error"] < 1e-6
