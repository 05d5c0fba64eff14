"""mtwin optimize: the fast model against the full twin, segmentation, the objectives, the
limits on the re-simulated output, verification, determinism and bad input."""
from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from conftest import SAMPLES

import mtwin
from mtwin.gcode.verify import compare
from mtwin.optimize.run import InfeasibleError, OptimizeOptions, optimize
from mtwin.optimize.search import GAOptions

GA_SAMPLE = str(SAMPLES / "ga_reference.nc")
REF = dict(feed_range=(100.0, 500.0), spindle_range=(1000.0, 8000.0), force_limit=60.0)


def _opt(text: bytes, path: str, **kw):
    # the inline programs declare no tool: T1 is the default 6 mm two-flute flat end mill, told
    # to the twin as --tool would (an undescribed tool keeps its feeds)
    tw = mtwin.Twin().with_tools({1: "flat:6:2"})
    prog = tw.load(text, path=path)
    # (a load limit given to raise feeds: the learned chip-thickness limit is lifted as --chip-limit none does)
    if kw.get("force_limit") is not None:
        kw.setdefault("chip_limit", "none")
    return tw, prog, optimize(tw, prog, OptimizeOptions(**kw))


def _run(path, **kw):
    tw = mtwin.Twin()
    prog = tw.load(path)
    # (a load limit given to raise feeds: the learned chip-thickness limit is lifted as --chip-limit none does)
    if kw.get("force_limit") is not None:
        kw.setdefault("chip_limit", "none")
    return tw, prog, optimize(tw, prog, OptimizeOptions(**kw))


def test_fast_model_load_matches_a_closed_form_slot():
    # full slot, flat end mill, Kt, Ke of the reference (edge terms 0): the revolution-average
    # load is N a fz / 4 * sqrt(Ktc^2 + Krc^2) (docs/physics.md section 1)
    from mtwin.cutting.engagement import engagement_for
    from mtwin.motion.simulate import program_cutting
    from mtwin.optimize.model import path_model

    tw = mtwin.Twin()
    prog = tw.load(b"G21 G90 G94 S5000 M3\nG0 X-10 Y0 Z5\nG0 Z-2\nG1 X40 F500\nG0 Z5\nM30\n"
                   b"(MTWIN STOCK 0,-10,-10,50,10,0)\n", path="slot.nc")
    plan = tw.plan(prog)
    eng = engagement_for(plan, prog, program_cutting(tw, prog), cache=tw.engagement_cache)
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
    with pytest.raises(InfeasibleError, match=r"contour\.nc:\d+: .*lowest feed 100 mm/min.*lines \d+-\d+, T2\): load [\d.]+ N over its limit 10\.0 N by \d+ %"):
        _run(str(SAMPLES / "contour.nc"), force_limit=10.0, feed_range=(100.0, 500.0))


@pytest.mark.parametrize("objective", ["time", "cost", "smooth"])
def test_reference_sample_objectives(objective):
    tw, prog, r = _run(GA_SAMPLE, objective=objective, method="ga", chip_limit="learned", **REF)  # (as the README runs it)
    assert r.trace_after.summary.cutting.peak_load <= 60.0
    assert compare(prog, tw.load(r.output, path="out.nc")) is None
    if objective == "time":
        # the README's reference experiment: at least the reference's own −16.9 %
        assert r.after.cycle_time <= r.before.cycle_time * (1 - 0.169)
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
    assert new.records["feed"].max() <= tw.machine.max_cutting_feed
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
    # nothing that meets material runs at another feed: compare record by record
    # the only changes are raised feeds, and only on moves that meet no material in the
    # program's own simulation; the one split is a plunge's air (air_entries), whose lower
    # piece keeps the plunge's feed
    nr = new.records
    split = [e for e in r.air_entries if e["air_to_z"] > e["to_z"]]
    air_piece = np.zeros(len(nr), bool)
    for e in split:
        air_piece |= np.isclose(nr["z"], e["air_to_z"]) & np.isclose(nr["sz"], e["from_z"]) & (nr["feed"] == e["air_feed"])
    assert air_piece.sum() == len(split) and len(nr) == len(prog.records) + len(split)
    nr = nr[~air_piece]
    changed = nr["feed"] != prog.records["feed"]
    assert changed.any() and (nr["feed"][changed] > prog.records["feed"][changed]).all()
    engaged = np.zeros(len(prog.records), bool)
    load = np.hypot(r.trace_before.signal("fx"), r.trace_before.signal("fy"))
    engaged[np.asarray(r.trace_before.record)[load > 0]] = True
    assert not (changed & engaged).any()
    assert r.after.cycle_time < r.before.cycle_time
    assert r.after.peak_power <= r.before.peak_power * 1.01  # the plunges keep how they are entered
    assert r.output.count(b"F30000.") >= 1


def test_air_and_smooth_keep_each_moves_own_feed():
    # one segment, four moves with slightly different feeds: a kept segment keeps all four
    text = (b"G21 G90 G17 G94\nT1 M6\nS5000 M3\nG0 X-10 Y0 Z5\nG0 Z-2\nG1 X10 F400.\nG1 X20 F404.\n"
            b"G1 X30 F396.\nG1 X40 F398.\nG1 X60 F398.\nG0 Z5\nM5\nM30\n(MTWIN STOCK 0,-10,-10,40,10,0)\n")
    tw, prog, r = _opt(text, "mixed.nc", objective="air", force_limit=60.0)
    new = tw.load(r.output, path="out.nc")
    cut = prog.records["x"] <= 40.0 + 1e-9
    np.testing.assert_array_equal(new.records["feed"][cut[: len(new.records)]][:5], prog.records["feed"][cut][:5])
    assert b"F404." in r.output and b"F396." in r.output


def test_several_speeds_for_one_tool_are_each_estimated_at_their_own_speed():
    # the same tool at S8000 then S3000: with S fixed, each segment is estimated (and limited)
    # at its own speed, so the re-simulation agrees in the first round
    text = (b"G21 G90 G17 G94\nT1 M6\nS8000 M3\nG0 X-10 Y0 Z5\nG0 Z-2\nG1 X40 F600.\nG0 Z5\nS3000\n"
            b"G0 X-10 Y5\nG0 Z-2\nG1 X40 F200.\nG0 Z5\nM5\nM30\n(MTWIN STOCK 0,-10,-10,30,10,0)\n")
    tw, prog, r = _opt(text, "twos.nc", force_limit=60.0, feed_range=(50.0, 2000.0))
    assert r.rounds == 1
    assert r.after.peak_load <= 60.0
    speeds = {s["spindle_after"] for s in r.segments if not s["air"]}
    assert speeds == {8000.0, 3000.0}
    assert r.output.count(b"S8000") == 1 and r.output.count(b"S3000") == 1


def test_speed_per_segment_is_written_as_chosen():
    tw = mtwin.Twin()
    prog = tw.load(GA_SAMPLE)
    r = optimize(tw, prog, OptimizeOptions(method="ga", spindle_per="segment", allow_s_changes=True,
                                           ga=GAOptions(generations=40), **REF))
    new = tw.load(r.output, path="out.nc")
    chosen = sorted({s["spindle_after"] for s in r.segments if not s["air"]})
    written = sorted(set(new.records["spindle"][new.records["kind"] != 0].tolist()))
    assert set(chosen) <= set(written), (chosen, written)
    assert r.trace_after.summary.cutting.peak_load <= 60.0


def test_canned_cycles_and_macro_feeds_stay_and_the_rest_is_optimised():
    g85 = (b"G21 G90 G17 G94\nT1 M6\nS3000 M3\nG0 X-10 Y0 Z5\nG0 Z-1\nG1 X40 F200.\nG0 Z5\n"
           b"G99 G85 X0 Y0 Z-5 R2 F100.\nX15\nG80\nG0 Z25\nM5\nM30\n(MTWIN STOCK -10,-10,-15,40,10,0)\n")
    tw, prog, r = _opt(g85, "g85.nc", force_limit=60.0, feed_range=(50.0, 1000.0))
    assert b"G99 G85 X0 Y0 Z-5 R2 F100." in r.output
    assert r.output != g85
    macro = (b"G21 G90 G17 G94\nT1 M6\nS5000 M3\n#<_f> = 300\nG0 X-10 Y0 Z5\nG0 Z-1\nG1 X40 F#<_f>\nG0 Z5\n"
             b"G0 X-10 Y5\nG0 Z-1\nG1 X40 F250\nG0 Z5\nM5\nM2\n(MTWIN STOCK 0,-10,-10,50,10,0)\n")
    tw, prog, r = _opt(macro, "m.ngc", force_limit=60.0, feed_range=(50.0, 1000.0))
    assert b"G1 X40 F#<_f>" in r.output
    assert b"G1 X40 F250\n" not in r.output


def test_a_speed_on_its_own_line_is_replaced_not_followed():
    text = (b"G21 G90 G17 G94\nT1 M6\nS5000 M3\nG0 X-10 Y0 Z5\nG0 Z-1\nG1 X40 F300.\nG0 Z5\nM5\nM30\n"
            b"(MTWIN STOCK 0,-10,-10,30,10,0)\n")
    tw, prog, r = _opt(text, "s.nc", feed_range=(100.0, 500.0), spindle_range=(1000.0, 8000.0), force_limit=60.0,
                       method="ga", ga=GAOptions(generations=30))
    lines = r.output.decode().splitlines()
    assert lines[2].startswith("S") and lines[2].endswith(" M3") and lines[2] != "S5000 M3"
    import re

    assert sum(len(re.findall(r"S\d", ln)) for ln in lines) == 1


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
    extra = {} if k < 2 else dict(method="ga", spindle_range=(2000.0, 8000.0), ga=GAOptions(generations=25, seed=k),
                                  spindle_per=("tool", "segment")[k % 2], allow_s_changes=True)
    r = optimize(tw, prog, OptimizeOptions(objective=("time", "smooth")[k % 2], force_limit=limit,
                                           feed_range=(50.0, 3000.0), **extra))
    new = tw.load(r.output, path="out.nc")
    assert compare(prog, new) is None
    tr = mtwin.Twin().simulate(new)
    c = tr.summary.cutting
    assert c.peak_load <= limit
    sp = tw.machine.spindle
    assert c.peak_power <= sp.rated_power
    n = np.maximum(np.abs(tr.signal("spindle_speed")), sp.base_speed)
    assert (tr.signal("spindle_torque") <= sp.rated_power / (2 * math.pi * n / 60) + 1e-9).all()
    changed = new.records["feed"][new.records["kind"] == 1]
    assert changed.max() <= tw.machine.max_cutting_feed


def test_a_tools_new_speed_may_carry_over_the_next_tools_rapids():
    """Issue 22 (found on NIST OP1): with --spindle-range, T1's new S stays modal over the tool
    change into the rapids of T2 (a drill: no segment of its own) until T2's own S word — the
    writer's check held those rapids to the old S and refused to write.  Every cutting move
    still runs at the speed asked."""
    from mtwin.optimize.run import OptimizeOptions, optimize
    from mtwin.twin import Twin

    text = ("(T1 D=6. CR=0. - FLAT END MILL)\n(T2 D=6. CR=0. - FLAT END MILL)\n(MTWIN STOCK 0,0,-5,60,40,0)\n"
            "G21 G90 G17 G94\nT1 M6\nG0 X-5. Y10. S8000 M3\nG0 Z2.\nG1 Z-1. F500.\nG1 X65. F800.\nG0 Z5.\n"
            "T2 M6\nG0 X10. Y30.\nG0 Z2. S5000 M3\nG81 X10. Y30. Z-3. R1. F300.\nX20.\nG80\nG0 Z5.\nM30\n")
    tw = Twin()
    prog = tw.load(text.encode(), path="carry.nc")
    res = optimize(tw, prog, OptimizeOptions(spindle_range=(3000.0, 6000.0), force_limit=500.0))
    new = tw.load(res.output, path="out.nc")
    r = new.records
    t1_cut = (r["tool"] == 1) & (r["kind"] != 0)
    assert set(np.round(r["spindle"][t1_cut])) == {6000.0}  # T1 moved into the range
    t2_cut = (r["tool"] == 2) & (r["kind"] != 0)
    assert set(np.round(r["spindle"][t2_cut])) == {5000.0}  # the drill's own S word, unchanged


def test_spindle_range_on_a_machine_that_does_not_wait_for_the_spindle(tmp_path):
    """linuxcnc-sim has wait_for_speed = false: no run-up pauses to reprice — the optimiser
    chose S without them (it crashed with an AttributeError before)."""
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-m", "mtwin", "optimize", str(SAMPLES / "contour.nc"), "--twin",
                        str(SAMPLES / "machines" / "linuxcnc-sim.toml"), "--spindle-range", "6000,10000", "-o",
                        str(tmp_path / "o.nc"), "--json"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    import json

    assert json.loads(r.stdout)["spindle"]


def _cli(*args, **kw):
    """The command in a process of its own, text out (the outputs a user sees)."""
    return subprocess.run([sys.executable, "-m", "mtwin", *args], capture_output=True, text=True, **kw)


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


def test_bisection_with_a_spindle_range_chooses_the_speed_that_pays():
    """Issue 32: a chip held to its limit carries the same chip at a higher feed when the spindle
    runs faster.  With --spindle-range the bisection tries speeds over the range (it kept the
    program's S before, so a range changed nothing unless the GA was asked): slots.nc (S3000,
    its slot held by the learned chip thickness) runs at the range's top, is faster on
    re-simulation than without the range, and its chip stays at the program's own level."""
    tw = mtwin.Twin()
    prog = tw.load(str(SAMPLES / "slots.nc"))
    plain = optimize(tw, prog, OptimizeOptions())
    ranged = optimize(tw, prog, OptimizeOptions(spindle_range=(1000.0, 8000.0)))
    assert ranged.spindle == {1: 8000.0}
    assert ranged.after.cycle_time < plain.after.cycle_time * 0.8
    cut = [s for s in ranged.segments if not s["air"]]
    assert cut and all(s["limited_by"] in ("chip thickness", "load") for s in cut)
    # the same feed per tooth where the chip binds: F rises with S (8000/3000) or less
    for a, b in zip(plain.segments, ranged.segments):
        if not a["air"]:
            assert b["feed_after"] <= a["feed_after"] * 8000.0 / 3000.0 + 2.0  # (F words are rounded)


def test_a_power_limit_stops_the_speed_where_it_binds():
    """The speed choice never buys time with a broken limit: on a spindle of 300 W the power
    binds (at a fixed chip, power grows with the speed), and every re-simulated segment of the
    answer stays within it."""
    tw = mtwin.Twin().with_params({"spindle.rated_power": 300.0})
    prog = tw.load(str(SAMPLES / "slots.nc"))
    res = optimize(tw, prog, OptimizeOptions(spindle_range=(1000.0, 8000.0)))
    assert res.after.peak_power <= 300.0 * 1.0001


SHARED_SUB = b"""(T1 D=6. CR=0. - FLAT END MILL)
(T2 D=6. CR=0. - FLAT END MILL)
(MTWIN STOCK -10,-10,-10,70,50,0)
G21 G90 G17 G94
o100 sub
G0 Z2.
G1 Z-1. F300.
G1 X#1 F600.
G0 Z5.
o100 endsub
T1 M6
S3000 M3
G0 X0 Y10.
o100 call [50.]
T2 M6
S3000 M3
G0 X0 Y30.
o100 call [50.]
M30
"""


def test_a_speed_that_cannot_be_written_stays_and_says_so():
    """Found on LinuxCNC's mmount.ngc: with --spindle-range, a tool whose moves run in a
    subprogram other tools call too got a new S written into the subprogram, the writer's
    own check refused it, and the run failed ("internal check failed").  Such a tool keeps
    its programmed speed, with a warning, and the answer is written."""
    tw = mtwin.Twin()
    prog = tw.load(SHARED_SUB, path="shared.ngc")
    res = optimize(tw, prog, OptimizeOptions(spindle_range=(1000.0, 8000.0)))
    assert res.spindle == {1: 3000.0, 2: 3000.0}
    assert any("keep the programmed speed" in w for w in res.warnings)
    assert compare(prog, tw.load(res.output, path="o.ngc")) is None


def test_a_locked_tool_keeps_every_s_word_as_written():
    """The review of the change above: T1 runs the shared subprogram at S3000 and again at
    S4000, T2 at S5000.  A locked tool was written at one speed (its lowest) over its S4000
    run, and the writer's check failed again; now a locked tool's S words stay as written."""
    text = SHARED_SUB.replace(b"o100 call [50.]\nT2 M6\nS3000 M3",
                              b"o100 call [50.]\nS4000 M3\nG0 X0 Y20.\no100 call [50.]\nT2 M6\nS5000 M3")
    tw = mtwin.Twin()
    prog = tw.load(text, path="shared4.ngc")
    res = optimize(tw, prog, OptimizeOptions(spindle_range=(1000.0, 8000.0)))
    new = tw.load(res.output, path="o.ngc")
    assert (new.records["spindle"] == prog.records["spindle"]).all()
    assert any("keep the programmed speed" in w for w in res.warnings)


def test_a_spindle_range_never_costs_more_than_none():
    """The review again: under the cost objective the speed choice counted a segment's own
    overshoot of its learned level (which the rounds allow) as a violation, and took a dearer
    speed that cured it — then a lower one than the program's, which the learned levels
    forbid.  With a range the answer is at most as dear as without one."""
    tw = mtwin.Twin().with_params({"cost.taylor_c": 300.0, "cost.tool_price": 500.0})
    prog = tw.load(str(SAMPLES / "slots.nc"))
    ranged = optimize(tw, prog, OptimizeOptions(objective="cost", spindle_range=(1000.0, 8000.0)))
    plain = optimize(tw, prog, OptimizeOptions(objective="cost"))
    assert ranged.after.cost <= plain.after.cost * 1.001
    assert all(v >= 3000.0 for v in ranged.spindle.values())  # (never below the program's own)
