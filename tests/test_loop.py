"""The loop end to end (issue 10): a 100 Hz measurement with 2 % noise and one hidden effect;
`diagnose` ranks the hidden effect first, `calibrate` recovers its parameters within 10 % and
the error falls by at least half, to within 1.5x the noise; an effect outside the catalogue
is "unexplained" until it is registered; the CLI writes a twin file with a journal."""
from __future__ import annotations

import json

import numpy as np
import pytest

import mtwin
from conftest import SAMPLES
from mtwin import effects as FX
from mtwin.loop.fit import diagnose, fit, target
from mtwin.loop.measurement import Measurement
from mtwin.loop.synth import synthesize
from test_cli import mtwin as run_cli

POCKET = str(SAMPLES / "pocket.nc")

# hidden effect, the parameters it is hidden with, the signals measured, the parameters that
# must come back within 10 % (the others are checked to stay near their hidden values)
CASES = [
    ("spindle-no-load", {"p0": 150.0, "b": 0.01}, ["spindle_power"], ["p0", "b"]),
    ("tool-wear", {"rate": 0.5}, ["spindle_power"], ["rate"]),
    ("coulomb-friction", {"fx": 150.0, "fy": 100.0}, ["x_torque", "y_torque"], ["fx", "fy"]),
    ("viscous-friction", {"bx": 3000.0}, ["x_torque"], ["bx"]),
    ("gravity", {"mass": 60.0}, ["z_torque"], ["mass"]),
    ("stribeck-friction", {"sx": 300.0}, ["x_torque"], ["sx"]),
]
CONTOUR = str(SAMPLES / "contour.nc")
HIDDEN = str(SAMPLES / "measurements" / "pocket_hidden.csv")


def _measure(twin, prog, hidden, signals, seed=1):
    cols = synthesize(twin.with_effects(*hidden), prog, rate=100, noise=0.02, seed=seed, signals=signals)
    return Measurement("hidden.csv", cols["t"], {s: cols[s] for s in signals}, cols["line"].astype(np.int64))


@pytest.fixture(scope="module")
def pocket():
    tw = mtwin.Twin()
    return tw, tw.load(POCKET)


@pytest.mark.parametrize("name,values,signals,exact", CASES, ids=[c[0] for c in CASES])
def test_a_hidden_effect_is_found_fitted_and_the_error_falls(pocket, name, values, signals, exact):
    tw, prog = pocket
    cls = FX.get(name)
    meas = _measure(tw, prog, [cls(**values)], signals)
    tg = target(tw, prog, meas)
    d = diagnose(tg)
    for s in signals:
        assert d[s]["verdict"] == "explained", (s, d[s])
        assert d[s]["candidates"][0]["effect"] == name, (s, [c["effect"] for c in d[s]["candidates"]])
        assert "explained" in d[s]["candidates"][0]["evidence"]
    res = fit(tg, [cls()], signals)
    for p in exact:
        assert res.params[f"effects.{name}.{p}"] == pytest.approx(values[p], rel=0.10), (p, res.params)
    for s in signals:
        assert res.rms_after[s] <= 0.5 * res.rms_before[s], (s, res.rms_before, res.rms_after)
        assert res.rms_after[s] <= 1.5 * res.noise[s], (s, res.rms_after, res.noise)


OUTSIDE = '''
import math
import numpy as np
from mtwin.effects import Effect
from mtwin.params import Param


class SupplyRipple(Effect):
    name = "supply-ripple"
    description = "a slow ripple on the measured spindle power from the shop's supply"
    params = (Param("amplitude", "W", 0.0, 0.0, 500.0, "ripple amplitude"),
              Param("period", "s", 7.0, 1.0, 60.0, "ripple period"))
    signals = ("spindle_power",)

    def observe(self, trace, p):
        t = np.asarray(trace.t, dtype=np.float64)
        trace.set_signal("spindle_power", trace.signal("spindle_power")
                         + p["amplitude"] * np.sin(2 * math.pi * t / p["period"]))
'''


def test_an_effect_outside_the_catalogue_is_unexplained_until_it_is_registered(pocket, effect_package):
    tw, prog = pocket
    # the effect exists only in this test: the measurement is made with it, unregistered
    namespace: dict = {}
    exec(compile(OUTSIDE, "supply_ripple.py", "exec"), namespace)  # noqa: S102 - the test's own code
    ripple = namespace["SupplyRipple"]
    meas = _measure(tw, prog, [ripple(amplitude=60.0, period=9.0)], ["spindle_power"])
    tg = target(tw, prog, meas)
    before = diagnose(tg)["spindle_power"]
    assert before["verdict"] == "unexplained", before
    # registered the way a package does it: a module and an entry point in a dist-info
    effect_package("ripple_fx", OUTSIDE, {"supply-ripple": "SupplyRipple"})
    after = diagnose(tg)["spindle_power"]
    assert after["verdict"] == "explained" and after["candidates"][0]["effect"] == "supply-ripple", after
    res = fit(tg, [FX.get("supply-ripple")(period=8.0)], ["spindle_power"])
    assert res.params["effects.supply-ripple.amplitude"] == pytest.approx(60.0, rel=0.1)
    assert res.rms_after["spindle_power"] <= 0.5 * res.rms_before["spindle_power"]


def test_calibrate_writes_the_twin_file_and_the_journal_shows_the_error_fall(tmp_path):
    meas = tmp_path / "m.csv"
    r = run_cli("synth", POCKET, "--effect", "spindle-no-load:p0=120", "--noise", "0.02", "--signals",
                "spindle_power", "-o", str(meas))
    assert r.returncode == 0, r.stderr.decode()
    r = run_cli("diagnose", POCKET, str(meas), "--json")
    d = json.loads(r.stdout)
    assert d["signals"]["spindle_power"]["candidates"][0]["effect"] == "spindle-no-load"
    for key in ("rms", "verdict", "candidates"):
        assert key in d["signals"]["spindle_power"]
    for key in ("effect", "explained_variance", "delta_bic", "params", "evidence"):
        assert key in d["signals"]["spindle_power"]["candidates"][0]
    out = tmp_path / "twin.toml"
    r = run_cli("calibrate", POCKET, str(meas), "--fit", "spindle-no-load", "-o", str(out), "--json")
    assert r.returncode == 0, r.stderr.decode()
    res = json.loads(r.stdout)
    assert res["params"]["effects.spindle-no-load.p0"] == pytest.approx(120, rel=0.1)
    tw = mtwin.Twin.from_toml(str(out))
    assert [e.name for e in tw.effects] == ["spindle-no-load"]
    # the calibrated twin fits: the residual is at the noise level
    r = run_cli("diagnose", POCKET, str(meas), "--twin", str(out), "--json")
    assert json.loads(r.stdout)["signals"]["spindle_power"]["verdict"] == "fits"
    r = run_cli("journal", str(out), "--json")
    j = json.loads(r.stdout)
    assert len(j) == 1 and j[0]["rms_after"]["spindle_power"] < 0.2 * j[0]["rms_before"]["spindle_power"]
    # a second calibration appends to the journal and keeps the effect
    out2 = tmp_path / "twin2.toml"
    r = run_cli("calibrate", POCKET, str(meas), "--twin", str(out), "--fit", "tool-wear", "-o", str(out2))
    assert r.returncode == 0, r.stderr.decode()
    j2 = json.loads(run_cli("journal", str(out2), "--json").stdout)
    assert [e["iteration"] for e in j2] == [1, 2]
    assert [e.name for e in mtwin.Twin.from_toml(str(out2)).effects] == ["spindle-no-load", "tool-wear"]
    r = run_cli("calibrate", POCKET, str(meas), "-o", str(tmp_path / "x.toml"))
    assert r.returncode == 2 and "nothing to fit" in r.stderr.decode()


def test_a_base_cutting_coefficient_is_calibrated_by_its_dotted_name(pocket, tmp_path):
    tw, prog = pocket
    true = tw.with_params({"cutting.al6061.ktc": 1500.0})
    cols = synthesize(true, prog, rate=100, noise=0.02, seed=2, signals=["spindle_power"])
    meas = Measurement("ktc.csv", cols["t"], {"spindle_power": cols["spindle_power"]}, cols["line"].astype(np.int64))
    res = fit(target(tw, prog, meas), [], ["spindle_power"], ("cutting.al6061.ktc",))
    assert res.params["cutting.al6061.ktc"] == pytest.approx(1500.0, rel=0.02)
    assert res.rms_after["spindle_power"] <= 1.5 * res.noise["spindle_power"]
    from mtwin.errors import ConfigError

    with pytest.raises(ConfigError, match="the twin cuts al6061"):
        tw.with_params({"cutting.steel1045.ktc": 2000.0})
    with pytest.raises(ConfigError, match="not in the twin file's tool table"):
        tw.with_params({"tools.1.diameter": 8.0})
    f = tmp_path / "t.toml"
    f.write_text("[tools.1]\ndiameter = 6.0\n")
    t2 = mtwin.Twin.from_toml(str(f)).with_params({"tools.1.diameter": 8.0})
    assert t2.cutting.tools[1].diameter == 8.0


def test_the_tutorial_s_bundled_measurement_gives_the_tutorial_s_numbers(tmp_path):
    meas = str(SAMPLES / "measurements" / "pocket_hidden.csv")
    d = json.loads(run_cli("diagnose", POCKET, meas, "--signals", "spindle_power", "--json").stdout)
    assert d["signals"]["spindle_power"]["candidates"][0]["effect"] == "spindle-no-load"
    one = tmp_path / "one.toml"
    two = tmp_path / "two.toml"
    assert run_cli("calibrate", POCKET, meas, "--fit", "spindle-no-load", "--signals", "spindle_power",
                   "-o", str(one)).returncode == 0
    r = run_cli("calibrate", POCKET, meas, "--twin", str(one), "--fit", "tool-wear", "--refit", "--signals",
                "spindle_power", "-o", str(two), "--json")
    assert r.returncode == 0, r.stderr.decode()
    res = json.loads(r.stdout)
    assert res["params"]["effects.spindle-no-load.p0"] == pytest.approx(180, rel=0.05)
    assert res["params"]["effects.tool-wear.rate"] == pytest.approx(0.35, rel=0.05)
    assert res["rms_after"]["spindle_power"] <= 1.1 * res["noise"]["spindle_power"]
    assert [e.name for e in mtwin.Twin.from_toml(str(two)).effects] == ["spindle-no-load", "tool-wear"]


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
