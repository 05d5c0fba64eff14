"""Edge cases of the loop found by a review: each failed before its fix."""
from __future__ import annotations


import numpy as np
import pytest

import mtwin
from conftest import SAMPLES
from mtwin.loop.compare import compare
from mtwin.loop.measurement import Measurement, read_measurement
from mtwin.loop.synth import synthesize
from test_cli import mtwin as run_cli

POCKET = str(SAMPLES / "pocket.nc")
CONTOUR = str(SAMPLES / "contour.nc")
HIDDEN = str(SAMPLES / "measurements" / "pocket_hidden.csv")


def test_fitting_an_effect_the_twin_already_has_refits_it(tmp_path):
    one, two = tmp_path / "one.toml", tmp_path / "two.toml"
    assert run_cli("calibrate", POCKET, HIDDEN, "--fit", "spindle-no-load", "--signals", "spindle_power",
                   "-o", str(one)).returncode == 0
    r = run_cli("calibrate", POCKET, HIDDEN, "--twin", str(one), "--fit", "spindle-no-load", "--signals",
                "spindle_power", "-o", str(two), "--json")
    assert r.returncode == 0, r.stderr.decode()
    p0 = mtwin.Twin.from_toml(str(two)).effects[0].resolved()["p0"]
    assert p0 == pytest.approx(185.6, rel=0.02)  # not the increment over the first fit


def test_a_machine_parameter_is_fitted_by_its_dotted_name():
    tw = mtwin.Twin()
    prog = tw.load(CONTOUR)
    true = tw.with_params({"axes.x.friction.viscous": 3000.0})
    cols = synthesize(true, prog, rate=100, noise=0.02, seed=3, signals=["x_torque"])
    meas = Measurement("v.csv", cols["t"], {"x_torque": cols["x_torque"]}, cols["line"].astype(np.int64))
    from mtwin.loop.fit import fit, target

    res = fit(target(tw, prog, meas), [], ["x_torque"], ("axes.x.friction.viscous",))
    assert res.params["axes.x.friction.viscous"] == pytest.approx(3000.0, rel=0.1)


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


def test_the_journal_survives_odd_measurement_names_and_config_check_reads_effects(tmp_path):
    from mtwin.loop.journal import calibrated_text

    class Fit:
        effects, params, uncertainty = [], {"x": float("inf")}, {"x": None}
        rms_before, rms_after, noise = {"s": 1.0}, {"s": 0.5}, {"s": 0.1}

    from mtwin.loop.journal import journal_entry

    text = calibrated_text("", [], journal_entry(1, 'we"ird\\name\nwith newline.csv', Fit), [])
    f = tmp_path / "j.toml"
    f.write_text(text)
    assert run_cli("config", "check", str(f)).returncode == 0
    bad = tmp_path / "bad.toml"
    bad.write_text("[effects.tool-wear]\nrate = 99\n")
    r = run_cli("config", "check", str(bad))
    assert r.returncode == 2 and "must be within" in r.stderr.decode()


def test_synth_refuses_a_rate_the_servo_clock_cannot_give(tmp_path):
    r = run_cli("synth", CONTOUR, "--rate", "300", "-o", str(tmp_path / "m.csv"))
    assert r.returncode == 2 and "333.333" in r.stderr.decode()


def test_diagnose_names_missing_signals_and_xcorr_needs_values(tmp_path):
    r = run_cli("calibrate", POCKET, HIDDEN, "--fit", "spindle-no-load", "--signals", "spindle_power,fx",
                "-o", str(tmp_path / "x.toml"))
    assert r.returncode == 2 and "--signals fx" in r.stderr.decode()
    f = tmp_path / "empty_power.csv"
    f.write_text("t,x,spindle_power\n0,1,\n0.01,1,\n0.02,1,\n")
    r = run_cli("compare", CONTOUR, str(f), "--align", "xcorr", "--xcorr-signal", "spindle_power")
    assert r.returncode == 2 and "fewer than 3" in r.stderr.decode()


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


def test_fitted_base_parameters_are_written_into_the_twin_file(tmp_path):
    tw = mtwin.Twin()
    prog = tw.load(CONTOUR)
    true = tw.with_params({"axes.x.friction.viscous": 3000.0, "cutting.al6061.ktc": 1500.0})
    cols = synthesize(true, prog, rate=100, noise=0.01, seed=4, signals=["x_torque", "spindle_power"])
    meas = tmp_path / "m.csv"
    from mtwin.motion.trace import write_columns

    write_columns(meas, cols)
    src = tmp_path / "src.toml"
    src.write_text("[machine]\nname = 'shop VMC'\n\n[effects.spindle-no-load]\np0 = 0.0\n")
    out = tmp_path / "out.toml"
    r = run_cli("calibrate", CONTOUR, str(meas), "--twin", str(src), "--param", "axes.x.friction.viscous",
                "--param", "cutting.al6061.ktc", "-o", str(out))
    assert r.returncode == 0, r.stderr.decode()
    assert run_cli("config", "check", str(out)).returncode == 0
    t2 = mtwin.Twin.from_toml(str(out))
    assert t2.machine.name == "shop VMC" and [e.name for e in t2.effects] == ["spindle-no-load"]
    assert t2.machine.x.friction.viscous == pytest.approx(3000.0, rel=0.1)
    assert t2.cutting.material.ktc == pytest.approx(1500.0, rel=0.02)
    assert t2.cutting.material.krc == tw.cutting.material.krc  # the others kept
