"""mtwin optimize: the fast model against the full twin, segmentation, the objectives, the
limits on the re-simulated output, verification, determinism and bad input."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from conftest import SAMPLES

import mtwin
from mtwin.errors import MtwinError
from mtwin.gcode.verify import compare
from mtwin.optimize.run import InfeasibleError, OptimizeOptions, optimize
from mtwin.optimize.search import GAOptions

GA_SAMPLE = str(SAMPLES / "ga_reference.nc")
REF = dict(feed_range=(100.0, 500.0), spindle_range=(1000.0, 8000.0), force_limit=60.0)


def _run(path, **kw):
    tw = mtwin.Twin()
    prog = tw.load(path)
    return tw, prog, optimize(tw, prog, OptimizeOptions(**kw))


def test_fast_model_load_matches_a_closed_form_slot():
    # full slot, flat end mill, Kt, Ke of the reference (edge terms 0): the revolution-average
    # load is N a fz / 4 * sqrt(Ktc^2 + Krc^2) (docs/physics.md section 1)
    from mtwin.cutting.engagement import engagement_for
    from mtwin.motion.simulate import _program_cutting
    from mtwin.optimize.model import path_model

    tw = mtwin.Twin()
    prog = tw.load(b"G21 G90 G94 S5000 M3\nG0 X-10 Y0 Z5\nG0 Z-2\nG1 X40 F500\nG0 Z5\nM30\n"
                   b"(MTWIN STOCK 0,-10,-10,50,10,0)\n", path="slot.nc")
    plan = tw.plan(prog)
    eng = engagement_for(plan, prog, _program_cutting(tw, prog), cache=tw.engagement_cache)
    pm = path_model(tw, prog, plan, eng)
    fz = 0.04
    mid = (pm.pos > 0.5) & (pm.pos < 0.7) & pm.cutting
    expected = 2 * 2.0 * fz / 4 * math.hypot(1230.0, 615.0)
    assert np.median(pm.load(np.full(pm.steps, fz))[mid]) == pytest.approx(expected, rel=0.06)


def test_contour_comes_out_under_60_N_and_verified():
    tw, prog, r = _run(str(SAMPLES / "contour.nc"), force_limit=60.0)
    assert r.before.peak_load > 250.0
    assert r.after.peak_load <= 60.0
    assert r.trace_after.summary.cutting.peak_load <= 60.0
    assert compare(prog, tw.load(r.output, path="out.nc")) is None
    assert r.verified


def test_a_program_over_the_limit_at_the_lowest_feed_is_reported():
    with pytest.raises(InfeasibleError, match=r"contour\.nc:\d+: .*lowest feed 100 mm/min.*lines \d+-\d+: \d+ N"):
        _run(str(SAMPLES / "contour.nc"), force_limit=10.0, feed_range=(100.0, 500.0))


@pytest.mark.parametrize("objective", ["time", "cost", "smooth"])
def test_reference_sample_objectives(objective):
    tw, prog, r = _run(GA_SAMPLE, objective=objective, method="ga", **REF)
    assert r.trace_after.summary.cutting.peak_load <= 60.0
    assert compare(prog, tw.load(r.output, path="out.nc")) is None
    if objective == "time":
        assert r.after.cycle_time < r.before.cycle_time * 0.9
    elif objective == "cost":
        assert r.after.cost < r.before.cost
    else:
        assert r.after.power_cv < r.before.power_cv
    # the S words only where the program had them, and within the range
    new = tw.load(r.output, path="out.nc")
    s = new.records["spindle"][new.records["spindle"] > 0]
    assert s.min() >= 1000 and s.max() <= 8000
    assert r.output.count(b"S") == prog.data.count(b"S")


def test_ga_is_deterministic_for_a_seed():
    a = _run(GA_SAMPLE, method="ga", ga=GAOptions(seed=7), **REF)[2]
    b = _run(GA_SAMPLE, method="ga", ga=GAOptions(seed=7), **REF)[2]
    assert a.output == b.output


def test_feeds_stay_in_range_and_under_the_machine_maximum():
    tw, prog, r = _run(GA_SAMPLE, method="bisect", **REF)
    new = tw.load(r.output, path="out.nc")
    f = new.records["feed"][(new.records["kind"] == 1)]
    changed = ~np.isin(f, prog.records["feed"])
    assert (f[changed] >= 100).all() and (f[changed] <= 500).all()
    assert r.output != prog.data


def test_air_objective_raises_only_air_cuts_to_the_machine_maximum():
    tw = mtwin.Twin()
    prog = tw.load(str(SAMPLES / "pocket.nc"))
    r = optimize(tw, prog, OptimizeOptions(objective="air"))
    new = tw.load(r.output, path="out.nc")
    assert new.records["feed"].max() <= tw.machine.max_cutting_feed
    # nothing that cuts changed its feed
    assert all(s["feed_after"] == s["feed_before"] for s in r.segments if not s["air"])
    assert any(s["feed_after"] > s["feed_before"] for s in r.segments if s["air"])
    assert r.after.cycle_time < r.before.cycle_time


def test_a_program_at_the_optimum_comes_back_byte_identical():
    # every feed already at the top of the range and the load far under the limit
    text = (b"G21 G90 G94\nS8000 M3\nG0 X-10 Y0 Z5\nG0 Z-0.5\nG1 X40 F500.\nG1 Y5\nG1 X-10\nG0 Z5\nM30\n"
            b"(MTWIN STOCK 0,-10,-10,30,10,0)\n")
    tw = mtwin.Twin()
    prog = tw.load(text, path="opt.nc")
    r = optimize(tw, prog, OptimizeOptions(feed_range=(100.0, 500.0), force_limit=60.0))
    assert r.after.peak_load < 60.0
    assert r.output == text
    assert r.changed_lines == []


def test_engagement_is_computed_once_across_rounds_and_objectives():
    tw = mtwin.Twin()
    prog = tw.load(GA_SAMPLE)
    optimize(tw, prog, OptimizeOptions(method="bisect", **REF))
    n = tw.engagement_cache.computations
    optimize(tw, prog, OptimizeOptions(objective="smooth", method="bisect", **REF))
    # the written programs split moves (another path structure); the original's stays cached
    assert tw.engagement_cache.computations <= n + 2


def run_cli(*args):
    import subprocess
    import sys

    return subprocess.run([sys.executable, "-m", "mtwin", *args], capture_output=True, text=True)


def test_cli_optimize_json_and_bad_input(tmp_path):
    out = tmp_path / "o.nc"
    r = run_cli("optimize", str(SAMPLES / "contour.nc"), "-o", str(out), "--force-limit", "60", "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    for k in ("objective", "method", "before", "after", "changed_lines", "verified"):
        assert k in doc
    for k in ("cycle_time", "cost", "peak_load", "peak_power", "power_cv"):
        assert k in doc["before"] and k in doc["after"]
    assert doc["after"]["peak_load"] <= 60.0 and doc["verified"] is True
    assert run_cli("verify", str(SAMPLES / "contour.nc"), str(out)).returncode == 0
    bad = run_cli("optimize", str(SAMPLES / "contour.nc"), "-o", str(tmp_path / "x.nc"), "--feed-range", "500,100")
    assert bad.returncode == 2 and "--feed-range" in bad.stderr and not (tmp_path / "x.nc").exists()
    bad = run_cli("optimize", str(SAMPLES / "contour.nc"), "-o", str(tmp_path / "x.nc"), "--objective", "fast")
    assert bad.returncode == 2 and "--objective" in bad.stderr
    inf = run_cli("optimize", str(SAMPLES / "contour.nc"), "-o", str(tmp_path / "x.nc"), "--force-limit", "5")
    assert inf.returncode == 2 and "lowest feed" in inf.stderr and not (tmp_path / "x.nc").exists()


@pytest.mark.parametrize("k", range(4))
def test_property_randomly_perturbed_programs(k):
    # random feeds and speeds on the bundled samples: the optimiser's output parses, cuts the
    # same path and holds the limit on its own re-simulation
    rng = np.random.default_rng(100 + k)
    name = ("contour.nc", "ga_reference.nc", "pocket.nc", "ga_reference.nc")[k]
    tw = mtwin.Twin()
    prog = tw.load(str(SAMPLES / name))
    f = np.round(prog.records["feed"] * rng.uniform(0.6, 1.4, len(prog.records)))
    text = mtwin.rewrite(prog, feeds=np.where(prog.records["kind"] == 1, f, np.nan))
    prog = tw.load(text, path=name)
    limit = float(rng.uniform(60, 120))
    r = optimize(tw, prog, OptimizeOptions(objective=("time", "smooth")[k % 2], force_limit=limit,
                                           feed_range=(50.0, 3000.0)))
    new = tw.load(r.output, path="out.nc")
    assert compare(prog, new) is None
    assert mtwin.Twin().simulate(new).summary.cutting.peak_load <= limit
