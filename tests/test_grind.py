"""Plunge grinding: the removal twin against its closed forms, the DP against brute force, the
robustness loop, parameter fitting and the CLI."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from mtwin.errors import ConfigError
from mtwin.grind.cycle import Stage, run_cycle, run_cycles
from mtwin.grind.dp import _rep, design
from mtwin.grind.io import fit, read_cycle, trace_columns
from mtwin.grind.model import Batch, GrindTwin, removal_step
from mtwin.grind.robust import robust_design

TW = GrindTwin()


def test_removal_step_solves_the_compliance_quadratic():
    rhs = np.array([0.0, 1e-5, 1e-3, 0.05])
    a1, a2, g = 1848.6, 3938.9, 0.0002
    f, p = removal_step(rhs, a1, a2, g)
    assert f[0] == 0 and p[0] == 0
    np.testing.assert_allclose(f + g * (a1 * f + a2 * np.sqrt(f)), rhs, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(p, a1 * f + a2 * np.sqrt(f))


def test_without_compliance_the_actual_feed_is_the_programmed_feed():
    tw = TW.with_params({"system.compliance": 0.0, "work.runout": 0.0})
    c = trace_columns(tw, [Stage(1.2, 0.0)])
    grinding = c["feed_cmd"] > 0
    # each position meets the wheel once a revolution, so in the first revolution after contact
    # the removal ramps up with the infeed each position has seen; from the second on, every
    # gauge interval removes exactly what was fed
    first = np.flatnonzero(grinding & (c["feed"] > 0))[0]
    after = first + int(tw["gauge.reads_per_rev"])
    np.testing.assert_allclose(c["feed"][after:][grinding[after:]], 1.2, rtol=1e-9)
    assert c["feed"][first] < 1.2


def test_compliance_makes_the_feed_lag_and_spark_out_removes_the_deflection():
    stiff = trace_columns(TW.with_params({"system.compliance": 0.0001, "work.runout": 0.0}), [Stage(1.0, 0.0)])
    soft = trace_columns(TW.with_params({"system.compliance": 0.0004, "work.runout": 0.0}), [Stage(1.0, 0.0)])
    t = 3.0  # s after the start: both in contact, neither at steady state
    assert np.interp(t, soft["t"], soft["feed"]) < np.interp(t, stiff["t"], stiff["feed"]) < 1.0
    # spark-out at zero feed: the force (the stored deflection γ·P) falls towards zero; with a
    # sharp wheel (η = 0, no rubbing term) it is ground away geometrically
    sharp = TW.with_params({"wheel.bluntness": 0.0, "work.runout": 0.0, "cycle.sparkout": 30,
                            "cycle.sparkout_max": 30, "gauge.error": 0.01})
    c = trace_columns(sharp, [Stage(1.0, 0.0)])
    spark = c["feed_cmd"] == 0
    force = c["fx"][spark]
    assert force[0] > 5 and force[-1] < 1e-3 * force[0]
    assert (np.diff(force) <= 1e-9).all()


def test_dp_beats_every_one_and_two_stage_cycle_of_a_coarse_grid_and_holds_its_limits():
    d = design(TW, 40, 40)
    assert d.stages and d.seconds < 10
    _, q, _ = run_cycle(TW, Batch.nominal(TW), d.stages)
    assert not q.defects(TW)[0]
    # the DP's own time (its table plus the spark-out it simulated) is the re-simulation's
    assert d.predicted == pytest.approx(q.cycle_time[0], rel=1e-9)
    feeds = np.geomspace(TW["machine.feed_min"], TW["machine.feed_max"], 8)
    allow = TW["work.allowance"] * np.array([0.9, 0.6, 0.4, 0.25, 0.15, 0.1, 0.05, 0.02])
    F = [[f, f] for f in feeds for _ in allow]
    W = [[a, a] for _ in feeds for a in allow]
    for f1 in feeds:
        for f2 in feeds[feeds < f1]:
            for a1 in allow:
                for a2 in allow[allow < a1]:
                    F.append([f1, f2])
                    W.append([a1, a2])
    F, W = np.array(F), np.array(W)
    _, qb, _ = run_cycles(TW, _rep(Batch.nominal(TW), len(F)), F, W)
    ok = ~qb.defects(TW)
    assert ok.sum() > 20  # the brute force finds feasible cycles to compare with
    assert d.cycle_time <= qb.cycle_time[ok].min() + 1e-9


@pytest.mark.parametrize("seed", [0, 2])
def test_robustness_loop_removes_the_defects_on_a_fresh_sample(seed):
    r = robust_design(TW, 40, 40, cases=300, seed=seed, validate=1000)
    assert r.iterations[0].defects >= 1
    assert r.feasible and r.iterations[-1].defects == 0
    assert r.validation is not None and r.validation.cases == 1000 and r.validation.defects == 0
    assert r.iterations[-1].cycle_time > r.iterations[0].cycle_time  # robustness costs time


def test_spark_out_is_counted_alike_by_the_dp_and_the_cycle():
    # no minimum spark-out: the DP's end and the re-simulation stop at the same gauge reading
    tw = TW.with_params({"cycle.sparkout": 0, "limits.roundness": 0.05, "limits.roughness_feed": 0.015,
                         "limits.burn_qw": 100, "wheel.force_limit": 1e5, "limits.size": 0.0444})
    d = design(tw, 20, 20)
    _, q, _ = run_cycle(tw, Batch.nominal(tw), d.stages)
    assert not q.defects(tw)[0]
    assert d.predicted == pytest.approx(q.cycle_time[0], rel=1e-9)


def test_gcode_stage_distances_cover_the_infeed_the_twin_needs():
    from mtwin.grind.io import cycle_gcode

    d = design(TW, 20, 20)
    g = cycle_gcode(TW, d.stages, 3.0)
    import re

    dist = [float(x) for x in re.findall(r"G31 X-([0-9.]+)", g)]
    need = [float(x) for x in re.findall(r"NOMINAL INFEED ([0-9.]+)", g)]
    assert len(dist) == len(d.stages) == len(need)
    # each skip move is longer than what the stage needs (the gauge ends it) but bounded
    assert all(n < x <= 1.5 * n + 0.0101 for x, n in zip(dist, need))
    # together they are the allowance, the run-out gap and the deflection the stages build up
    assert sum(need) > TW["work.allowance"] - d.stages[-1].switch_allowance


def test_compliance_and_stress_intensity_are_fitted_back_from_a_recording():
    stages = [Stage(1.2, 0.05), Stage(0.4, 0.01)]
    hidden = TW.with_params({"system.compliance": 0.00028, "work.sigma": 2400.0})
    rec = trace_columns(hidden, stages)
    rng = np.random.default_rng(3)
    feed = rec["feed"] * (1 + 0.01 * rng.standard_normal(len(rec["t"])))
    force = rec["fx"] * (1 + 0.01 * rng.standard_normal(len(rec["t"])))
    out = fit(TW, stages, rec["t"], feed, force)
    assert out["values"]["system.compliance"] == pytest.approx(0.00028, rel=0.02)
    assert out["values"]["work.sigma"] == pytest.approx(2400.0, rel=0.02)
    assert out["rms_after"] < 0.1 * out["rms_before"]


def test_parameters_are_declared_and_checked_by_dotted_name(tmp_path):
    assert TW.with_params({"system.compliance": 0.0003})["system.compliance"] == 0.0003
    with pytest.raises(ConfigError, match="within"):
        TW.with_params({"system.compliance": -1})
    with pytest.raises(ConfigError, match="unknown grinding parameter"):
        TW.with_params({"system.stiffness": 1})
    p = tmp_path / "g.toml"
    p.write_text("[system]\ncompliance = 0.0003\n[cycle]\nstages = [{feed = 1.0, switch_allowance = 0.02}]\n")
    assert GrindTwin.from_toml(str(p))["system.compliance"] == 0.0003
    assert read_cycle(str(p)) == [Stage(1.0, 0.02)]
    p.write_text("[cycle]\nstages = [{feed = 1.0}]\n")
    with pytest.raises(ConfigError, match="stage 1"):
        read_cycle(str(p))


def _mtwin(*args):
    return subprocess.run([sys.executable, "-m", "mtwin", *args], capture_output=True, text=True)


def test_cli_design_json_gcode_report_and_simulate(tmp_path):
    r = _mtwin("grind", "design", "--json", "--validate", "200", "-o", str(tmp_path / "c.nc"),
               "--cycle-out", str(tmp_path / "c.toml"), "--report", str(tmp_path / "c.html"))
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["cycle_time"] > 0 and doc["stages"]
    for s in doc["stages"]:
        assert {"feed", "switch_allowance", "time"} <= set(s)
    assert doc["robustness"] and all({"defects", "cases"} <= set(it) for it in doc["robustness"])
    assert doc["robust"] and doc["robustness"][-1]["defects"] == 0 and doc["validation"]["defects"] == 0
    gcode = (tmp_path / "c.nc").read_text()
    assert gcode.count("G31 X-") == len(doc["stages"]) and "G04" in gcode
    page = (tmp_path / "c.html").read_text()
    assert page.count("<svg") >= 2 and "radial force" in page and "Defect map" in page
    # the set-up the cycle was designed for (issue 19): every parameter with its value and unit
    assert "<h2>Set-up</h2>" in page and "<td>wheel.diameter</td><td>600</td><td>mm</td>" in page
    s = _mtwin("grind", "simulate", str(tmp_path / "c.toml"), "--json", "-o", str(tmp_path / "t.csv"))
    assert s.returncode == 0, s.stderr
    sim = json.loads(s.stdout)
    assert sim["cycle_time"] == pytest.approx(doc["cycle_time"], rel=1e-6)
    assert all(v <= 1.0 for v in sim["limit_ratios"].values())
    head = (tmp_path / "t.csv").read_text().splitlines()
    assert head[0] == "# format: mtwin-measurement 1" and "t,feed,feed_cmd,fx,radius,runout" in head
    bad = _mtwin("grind", "design", "--grid", "40by40")
    assert bad.returncode == 2 and "--grid" in bad.stderr
    bad = _mtwin("grind", "simulate", str(tmp_path / "missing.toml"))
    assert bad.returncode == 2 and "cannot read" in bad.stderr
    (tmp_path / "fast.toml").write_text("[cycle]\nstages = [{feed = 500.0, switch_allowance = 0.0}]\n")
    bad = _mtwin("grind", "simulate", str(tmp_path / "fast.toml"))
    assert bad.returncode == 2 and "outside the machine's range" in bad.stderr
    bad = _mtwin("grind", "design", "-o", str(tmp_path))
    assert bad.returncode == 2 and "is a directory" in bad.stderr


def test_cli_calibrate_fits_a_recorded_cycle(tmp_path):
    from mtwin.grind.io import cycle_toml
    from mtwin.motion.trace import write_columns

    stages = [Stage(1.2, 0.05), Stage(0.4, 0.01)]
    (tmp_path / "c.toml").write_text(cycle_toml(TW, stages))
    rec = trace_columns(TW.with_params({"system.compliance": 0.00025, "work.sigma": 1800.0}), stages)
    write_columns(tmp_path / "rec.csv", rec)
    r = _mtwin("grind", "calibrate", str(tmp_path / "c.toml"), str(tmp_path / "rec.csv"), "--json",
               "-o", str(tmp_path / "fitted.toml"))
    assert r.returncode == 0, r.stderr
    v = json.loads(r.stdout)["values"]
    assert v["system.compliance"] == pytest.approx(0.00025, rel=0.01)
    assert v["work.sigma"] == pytest.approx(1800.0, rel=0.01)
    assert GrindTwin.from_toml(str(tmp_path / "fitted.toml"))["work.sigma"] == pytest.approx(1800.0, rel=0.01)
    bad = _mtwin("grind", "calibrate", str(tmp_path / "c.toml"), str(tmp_path / "rec.csv"), "--param", "x.y")
    assert bad.returncode == 2 and "not a grinding parameter" in bad.stderr
