"""Timing calibration against a control's logged block times (loop/timing.py): the plan-only
evaluation against the full simulation, recovery of known timing effects from a log the twin
itself wrote, bad logs, and the NIST Hurco VMX24 plates where the workspace has them."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from conftest import REALDATA, ROOT

import mtwin
from mtwin.effects import get
from mtwin.loop import timing as T
from mtwin.loop.measurement import Measurement

# two tools, small arcs (r 1 mm), short lines, rapids, a drill-like plunge
PROGRAM = """\
G21 G90 G17 G94
T1 M6
S9000 M3
G0 X0 Y0 Z5
G1 Z-1 F300
G1 X20 F900
G2 X22 Y2 I0 J2 F3000
G2 X20 Y4 I-2 J0
G3 X18 Y6 I0 J2
G1 X18.5 Y6.5
G1 X19 Y6
G1 X19.5 Y6.5
G1 X40 Y6
G2 X42 Y8 I0 J2
G2 X40 Y10 I-2 J0
G0 Z5
G0 X80 Y40
G1 Z-1 F300
G1 X0 Y40 F1200
G0 Z5
M5
T2 M6
S12000 M3
G0 X10 Y10
G1 Z-1 F300
G2 X12 Y12 I0 J2 F3000
G2 X10 Y14 I-2 J0
G2 X8 Y12 I0 J-2
G2 X10 Y10 I2 J0
G1 X60 F1500
G0 Z5
M5
M30
"""


def _log_of(twin, prog, every=0.17, seed=0):
    """What a control logs of the twin's own run: the executing line every ~0.17 s (jittered),
    the path speed."""
    tr = twin.simulate(prog, cutting=False)
    t, line = np.asarray(tr.t), np.asarray(tr.line)
    rng = np.random.default_rng(seed)
    ts = np.cumsum(rng.uniform(0.8 * every, 1.2 * every, int(t[-1] / every) + 5))
    ts = ts[ts < t[-1]]
    k = np.searchsorted(t, ts)
    m = Measurement("log.txt", ts, {"feed": np.asarray(tr.signal("feed"))[k]}, line[k].astype(np.int64), {}, [])
    m.end_time = float(t[-1])
    return m


@pytest.fixture(scope="module")
def prog(tmp_path_factory):
    p = tmp_path_factory.mktemp("timing") / "part.nc"
    p.write_text(PROGRAM)
    return mtwin.Twin().load(str(p))


def test_plan_with_waits_is_the_simulation(prog):
    # the fit's evaluation (a plan plus the in-position waits of one simulation) puts every
    # line start where the full simulation does, and ends where it ends
    from mtwin.loop.blocks import simulated_starts

    tw = mtwin.Twin()
    case = T.timing_case(tw, prog, _log_of(tw, prog))
    plan = tw.plan(prog)
    lines, starts, end = T.plan_starts(plan, case.wait_line, T.case_waits(tw, case))
    tr = tw.simulate(prog, cutting=False)
    sl, ss = simulated_starts(np.asarray(tr.t), np.asarray(tr.line))
    assert list(lines) == list(sl)
    assert np.abs(starts - ss).max() < 3 * tw.machine.controller.servo_period
    assert end == pytest.approx(tr.summary.cycle_time, abs=3e-3)
    assert case.wait.sum() > 0.05  # there are waits to account for
    # at another in-position width the log-linear waits stay close to a simulation's
    wide = tw.with_params({"controller.in_position": 0.03})
    _, _, end_w = T.plan_starts(plan, case.wait_line, T.case_waits(wide, case))
    assert end_w == pytest.approx(wide.simulate(prog, cutting=False).summary.cycle_time, abs=0.05)


def test_fit_recovers_timing_effects_from_the_twins_own_log(prog):
    truth = mtwin.Twin().with_effects("toolchange-time:extra=2.5,first_extra=1.5", "arc-acceleration:acceleration=250")
    meas = _log_of(truth, prog)
    tw = mtwin.Twin()
    case = T.timing_case(tw, prog, meas)
    fr = T.fit_timing(tw, [case], [get("toolchange-time")(), get("arc-acceleration")()])
    assert fr.params["effects.toolchange-time.extra"] + fr.params["effects.toolchange-time.first_extra"] / 2 == \
        pytest.approx(2.5 + 1.5 / 2, abs=0.2)
    assert fr.params["effects.arc-acceleration.acceleration"] == pytest.approx(250, rel=0.15)
    # (0.54 % left on the default machine: its in-position waits under feed-forward are short and
    # steep in the width, which the fit's log-linear wait model follows less closely; the fit
    # also holds each block kind's sum, which the log's sampling blurs — 0.39 % on windows alone)
    assert abs(fr.after["cases"][0]["cycle_error"]) < 0.006 < abs(fr.before["cases"][0]["cycle_error"])
    assert fr.rms_after["window_time"] < 0.5 * fr.rms_before["window_time"]


def test_a_limit_no_logged_block_reaches_is_set_at_the_least_the_log_allows(tmp_path):
    # arcs of 5 mm at F3000 (50 mm/s): v²/r 500 mm/s², below the truth's arc limit of 2,000 —
    # the log shows no arc slowed, so any limit from ~500 up fits it; the fit says so and sets
    # the least (a program with tighter arcs would otherwise be predicted at whatever value the
    # search was left at, faster than the machine was ever seen to go)
    p = tmp_path / "arcs.nc"
    p.write_text("G21 G90 G17 G94\nG0 X0 Y0 Z5\nG1 Z-1 F300\nG1 X10 F3000\n"
                 + "".join(f"G2 X{10 + 10 * i + 5} Y5 I0 J5\nG3 X{10 + 10 * i + 10} Y0 I5 J0\n" for i in range(8))
                 + "G1 X100 Y0\nG0 Z5\nM30\n")
    truth = mtwin.Twin().with_effects("arc-acceleration:acceleration=2000")
    prog = truth.load(str(p))
    case = T.timing_case(mtwin.Twin(), prog, _log_of(truth, prog))
    fr = T.fit_timing(mtwin.Twin(), [case], [get("arc-acceleration")()])
    key = "effects.arc-acceleration.acceleration"
    assert key in fr.unreached and fr.uncertainty[key] is None
    least = fr.params[key]
    assert least == fr.unreached[key]["least"] <= fr.unreached[key]["fitted"]
    assert 450 < least < 650  # just above the arcs' 500 mm/s²
    assert abs(fr.after["cases"][0]["cycle_error"]) < 0.01
    # a limit the log does show is fitted as before (the test above: 250 recovered), not walked
    truth = mtwin.Twin().with_effects("arc-acceleration:acceleration=250")
    fr = T.fit_timing(mtwin.Twin(), [T.timing_case(mtwin.Twin(), prog, _log_of(truth, prog))],
                      [get("arc-acceleration")()])
    assert fr.unreached == {} and fr.params[key] == pytest.approx(250, rel=0.15)


def test_fit_finds_an_arc_jerk_limit_and_the_acceleration_limit_from_small_and_large_circles(tmp_path):
    # forty circles of 0.3 mm and six of 10 mm at F6000, on a machine whose arcs are held at
    # v²/r = 500 mm/s² and v³/r² = 8 m/s³ (the jerk is the tighter below a³/J² = 1.95 mm): the
    # small ones run at ∛(J·r²), 9.0 mm/s, the large at √(a·r), 70.7 mm/s (the jerk would allow
    # 92.8); asked for both (fit=acceleration+jerk), the fit finds both.  (Over logs of seeds 0-5:
    # 480-525 mm/s², 7.7-8.0 m/s³, the cycle within 0.9 %.  With radii close to a³/J², or a log
    # of a few seconds, the two trade, and the fit can leave one at a compromise.)  Not asked,
    # the jerk stays none: the effect's default fits the acceleration alone
    from mtwin.effects import parse_effect_spec

    p = tmp_path / "circles.nc"
    p.write_text("G21 G90 G17 G94\nG0 X0.3 Y0 Z5\nG1 Z-1 F300\n" + "G3 X0.3 Y0 I-0.3 J0 F6000\n" * 40
                 + "G1 X10\n" + "G3 X10 Y0 I-10 J0\n" * 6 + "G0 Z5\nM30\n")
    truth = mtwin.Twin().with_effects("arc-acceleration:acceleration=500,jerk=8000")
    prog = truth.load(str(p))
    case = T.timing_case(mtwin.Twin(), prog, _log_of(truth, prog))
    fr = T.fit_timing(mtwin.Twin(), [case], [parse_effect_spec("arc-acceleration:fit=acceleration+jerk")])
    assert fr.params["effects.arc-acceleration.acceleration"] == pytest.approx(500, rel=0.1)
    assert fr.params["effects.arc-acceleration.jerk"] == pytest.approx(8000, rel=0.1)
    assert fr.unreached == {}
    assert abs(fr.after["cases"][0]["cycle_error"]) < 0.01 < 0.2 < abs(fr.before["cases"][0]["cycle_error"])
    fr = T.fit_timing(mtwin.Twin(), [case], [get("arc-acceleration")()])
    assert "effects.arc-acceleration.jerk" not in fr.params


def test_the_walk_down_an_unreached_limit_by_its_branches():
    # a synthetic cost: ten residuals of 1 wherever the limit does not bind (x >= 500), rising
    # as it binds below — the least value the data allow is where the cost has risen by one
    # variance per degree of freedom (10/9): 10 (1 + d/50)² = 10 + 10/9 at d = 2.70, 497.30,
    # wherever the search left it (from 4,000 the walk's grid holds 500 and 450, from 3,000 it
    # holds 546.75 and 492.08: the least value within the bound on the grid was 500 or 546.75);
    # flat everywhere: nothing bounds it; a dip at 300 below the flat part: a better fit there
    x = np.array([4000.0])
    binds = lambda y: np.full(10, 1.0 + max(0.0, 500.0 - y[0]) / 50.0)
    crossing = 500.0 - 50.0 * (np.sqrt(1.0 + 1.0 / 9.0) - 1.0)
    for left in (4000.0, 3000.0, 5300.0, 510.0):
        how, v = T._least_unreached(binds, np.array([left]), 0, 0.0, 1)
        assert how == "least" and v == pytest.approx(crossing, rel=5e-4), left
    how, v = T._least_unreached(lambda y: np.ones(10), x, 0, 0.0, 1)
    assert how == "unbounded" and np.isnan(v)
    dip = lambda y: np.full(10, 1.0 + min(abs(y[0] - 300.0), 200.0) / 100.0)
    how, v = T._least_unreached(dip, x, 0, 0.0, 1)
    assert how == "better" and abs(v - 300.0) < 20.0
    assert x[0] == 4000.0  # (the fit's vector is left as it was)


def test_diagnose_ranks_the_missing_timing_effect_first(prog):
    truth = mtwin.Twin().with_effects("toolchange-time:extra=4")
    d = T.diagnose_timing(mtwin.Twin(), [T.timing_case(mtwin.Twin(), prog, _log_of(truth, prog))])
    assert d["candidates"][0]["effect"] == "toolchange-time"
    assert d["candidates"][0]["explained_variance"] > 0.8
    assert d["verdict"] == "explained"


def test_rapid_rate_is_read_off_the_logged_rapids(tmp_path):
    p = tmp_path / "r.nc"
    p.write_text("G21 G90\nG0 X0 Y0 Z0\n" + "".join(f"G0 X{100 * (i % 2)} Y{40 * (i % 3)}\nG0 Y{60 + 5 * i}\n"
                                                      for i in range(6)) + "M30\n")
    truth = mtwin.Twin().with_params({"axes.x.max_velocity": 9000.0, "axes.y.max_velocity": 7000.0})
    prog = truth.load(str(p))
    case = T.timing_case(mtwin.Twin(), prog, _log_of(truth, prog, every=0.05))
    r = T.rapid_rates([case])
    assert r["axes.x.max_velocity"][0] == pytest.approx(9000, rel=0.02)
    assert r["axes.y.max_velocity"][0] == pytest.approx(7000, rel=0.02)


def test_a_timing_fit_refuses_what_it_cannot_fit(prog):
    tw = mtwin.Twin()
    case = T.timing_case(tw, prog, _log_of(tw, prog))
    with pytest.raises(mtwin.errors.MtwinError, match="not a timing effect"):
        T.fit_timing(tw, [case], [get("coulomb-friction")()])
    with pytest.raises(mtwin.errors.MtwinError, match="axes"):
        T.fit_timing(tw, [case], [], ["cutting.al6061.ktc"])


# ------------------------------------------------------------------ bad logs, exit 2

GOOD = ("2020-01-01T00:00:00.0Z|Program_Name_Running|PART.NC\n2020-01-01T00:00:00.1Z|Program_Status|ACTIVE\n"
        "2020-01-01T00:00:00.2Z|Block_Number|3\n2020-01-01T00:00:01.0Z|Block_Number|5\n"
        "2020-01-01T00:00:02.0Z|Program_Status|PROGRAM_COMPLETED\n")


@pytest.mark.parametrize("log,where,what", [
    (GOOD.replace("|Block_Number|5", "|Blok_Numbr|5"), ":4:24:", "unknown data item 'Blok_Numbr'"),
    (GOOD.replace("2020-01-01T00:00:01.0Z", "2019-12-31T23:59:00.0Z"), ":4:1:", "records are out of order"),
    (GOOD.replace("|Block_Number|5", "|Block_Number|500"), ":4:1:", "beyond the end of PART.NC"),
    (GOOD.replace("|PART.NC", "|OTHER.NC"), "", "the log ran OTHER.NC, not PART.NC"),
])
def test_malformed_logs_are_clear_errors(tmp_path, log, where, what):
    (tmp_path / "PART.NC").write_text("G21 G90\nG0 X0 Y0 Z5\nG1 X10 F600\nG1 Y10\nG1 X0\nG1 Y0\nM30\n")
    (tmp_path / "log.txt").write_text(log)
    for cmd in ("compare", "diagnose"):
        r = subprocess.run([sys.executable, "-m", "mtwin", cmd, "PART.NC", "log.txt"], capture_output=True, text=True,
                           cwd=tmp_path)
        assert r.returncode == 2, (cmd, r.stderr)
        assert "log.txt" + where in r.stderr and what in r.stderr, r.stderr
    if "OTHER" in log:  # a renamed file is accepted on request
        r = subprocess.run([sys.executable, "-m", "mtwin", "compare", "PART.NC", "log.txt", "--any-program"],
                           capture_output=True, text=True, cwd=tmp_path)
        assert r.returncode == 0, r.stderr


def test_overrides_and_holds(tmp_path):
    # a feed hold is taken out of its group's time; so is the time the feed override stood at
    # 0 % with the machine standing (the replay makes it a hold: one judge of "held"), and
    # that group is kept; a group that ran at 0 % while the machine moved is left out and listed
    # (any other override the twin replays: tests/test_logs_as_run.py)
    from mtwin.loop.asrun import as_run
    from mtwin.loop.blocks import measurement_groups
    from mtwin.loop.mtconnect import read_mtconnect

    (tmp_path / "PART.NC").write_text("G21 G90\nG0 X0 Y0 Z5\nG1 X10 F600\nG1 Y10\nG1 X0\nG1 Y0\nM30\n")
    (tmp_path / "log.txt").write_text(
        "2020-01-01T00:00:00.0Z|Program_Name_Running|PART.NC|Program_Status|ACTIVE|Feed_Override|100\n"
        "2020-01-01T00:00:00.2Z|Block_Number|3\n2020-01-01T00:00:01.0Z|Execution|FEED_HOLD\n"
        "2020-01-01T00:00:04.0Z|Execution|ACTIVE\n2020-01-01T00:00:04.5Z|Block_Number|4\n"
        "2020-01-01T00:00:05.5Z|Block_Number|5|Feed_Override|0\n2020-01-01T00:00:07.0Z|Feed_Override|100\n"
        "2020-01-01T00:00:07.5Z|Block_Number|6\n2020-01-01T00:00:08.5Z|Program_Status|PROGRAM_COMPLETED\n")
    prog = mtwin.Twin().load(str(tmp_path / "PART.NC"))
    m = as_run(prog, read_mtconnect(str(tmp_path / "log.txt"))).measurement
    g = measurement_groups(prog, m)
    assert g.hold_time == pytest.approx(3.0 + 1.5)
    assert list(g.first_line) == [3, 4, 5, 6] and not g.excluded
    assert g.measured[0] == pytest.approx(4.3 - 3.0)
    assert g.measured[2] == pytest.approx(2.0 - 1.5)
    # the same log with the feed logged at 0.5 s and 6.5 s: the machine moved at 0 %
    moved = (tmp_path / "log.txt").read_text().replace(
        "|Feed_Override|0\n", "|Feed_Override|0|Feed_Rate|10\n").replace(
        "2020-01-01T00:00:07.0Z|", "2020-01-01T00:00:06.5Z|Feed_Rate|12\n2020-01-01T00:00:07.0Z|")
    (tmp_path / "moved.txt").write_text(moved)
    m = as_run(prog, read_mtconnect(str(tmp_path / "moved.txt"))).measurement
    g = measurement_groups(prog, m)
    assert g.hold_time == pytest.approx(3.0) and list(g.first_line) == [3, 4, 6]
    assert [x["first_line"] for x in g.excluded] == [5]
    assert g.excluded[0]["reason"] == "it ran at a feed override of 0 % for 1.5 s while the machine moved"


STOPPED_AT_0 = (
    "2020-01-01T00:00:00.0Z|Program_Name_Running|PART.NC|Program_Status|ACTIVE|Feed_Override|100|Feed_Rate|10\n"
    "2020-01-01T00:00:00.2Z|Block_Number|3\n2020-01-01T00:00:01.2Z|Block_Number|4\n"
    "2020-01-01T00:00:02.2Z|Block_Number|5\n2020-01-01T00:00:02.5Z|Feed_Override|0|Feed_Rate|0\n"
    "2020-01-01T00:00:03.0Z|Execution|STOPPED\n2020-01-01T00:00:20.0Z|Execution|ACTIVE\n"
    "2020-01-01T00:00:20.5Z|Feed_Override|100|Feed_Rate|10\n2020-01-01T00:00:21.2Z|Block_Number|6\n"
    "2020-01-01T00:00:22.2Z|Program_Status|PROGRAM_COMPLETED\n")


def test_an_override_at_0_through_a_logged_stop_is_time_the_machine_stood(tmp_path):
    # the operator turns the feed override to 0 and then stops the program: 0.5 s held before
    # the stop, 17 s stopped, 0.5 s held after — the machine stood 18 s, counted once, in the
    # header's cycle time, the groups and compare's measured cycle alike; the group is kept (it
    # did not move at 0 %), and the override it ran at is 100 %, not a mean with the stop's 0
    import json

    from mtwin.loop.asrun import as_run
    from mtwin.loop.blocks import measurement_groups
    from mtwin.loop.mtconnect import read_mtconnect

    (tmp_path / "PART.NC").write_text("G21 G90\nG0 X0 Y0 Z5\nG1 X10 F600\nG1 Y10\nG1 X0\nG1 Y0\nM30\n")
    (tmp_path / "log.txt").write_text(STOPPED_AT_0)
    prog = mtwin.Twin().load(str(tmp_path / "PART.NC"))
    m = read_mtconnect(str(tmp_path / "log.txt"))
    assert float(m.meta["cycle_time_s"]) == pytest.approx(22.2 - 18.0) and m.end_time == pytest.approx(22.2)
    run = as_run(prog, m)
    for meas in (m, run.measurement):  # (read as it is, or through the replay: the same)
        g = measurement_groups(prog, meas)
        assert list(g.first_line) == [3, 4, 5, 6] and not g.excluded
        assert g.hold_time + g.stop_time == pytest.approx(18.0)
        assert g.measured[2] == pytest.approx(21.2 - 2.2 - 18.0)
    r = subprocess.run([sys.executable, "-m", "mtwin", "compare", str(tmp_path / "PART.NC"), str(tmp_path / "log.txt"),
                        "--json"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["cycle_time"]["measured"] == pytest.approx(4.2)
    assert "feed override 100 % applied" in r.stderr


def test_overlapping_logged_stops_are_counted_once_and_a_stand_to_the_end_keeps_the_override_in_force(tmp_path):
    from mtwin.loop.asrun import _time_mean
    from mtwin.loop.blocks import measured_groups

    (tmp_path / "PART.NC").write_text("G21 G90\nG0 X0 Y0 Z5\nG1 X10 F600\nG1 Y10\nG1 X0\nG1 Y0\nM30\n")
    prog = mtwin.Twin().load(str(tmp_path / "PART.NC"))
    g = measured_groups(prog, np.array([0.0, 1.0, 9.0]), np.array([3, 4, 5]), 10.0,
                        stops=[(2.0, 6.0, "STOPPED"), (5.0, 8.0, "RESTART"), (6.5, 7.0, "STOPPED")])
    assert g.stop_time == pytest.approx(6.0) and g.measured[1] == pytest.approx(8.0 - 6.0)
    # a group wholly inside a stand that runs to the log's end ran at the value in force before it
    t, v = np.array([0.0, 1.0, 2.0, 3.0]), np.array([50.0, 80.0, 90.0, 90.0])
    assert _time_mean(t, v, np.array([4.0]), np.array([5.0]), [(2.5, 10.0)])[0] == pytest.approx(90.0)
    t, v = np.array([0.0, 1.0, 2.0, 3.0]), np.array([50.0, 80.0, 0.0, 0.0])  # (held from the sample at 2)
    assert _time_mean(t, v, np.array([4.0]), np.array([5.0]), [(2.0, 10.0)])[0] == pytest.approx(80.0)


def test_time_the_machine_stood_is_counted_once_where_spans_overlap():
    from mtwin.loop.blocks import _overridden
    from mtwin.loop.measurement import coverage, covered, merged

    assert merged([(1, 2), (0.5, 1.5, "STOPPED"), (3, 3), (2, 2.5)]) == [(0.5, 2.5)]
    assert covered([(1, 2), (1, 2)], 0, 10) == pytest.approx(1.0)
    assert covered([(0.5, 1.8), (1.2, 2.0)], 1.0, 1.5) == pytest.approx(0.5)
    t = np.arange(6.0)
    v = {"feed_override": np.array([100, 0, 100, 0, 50, 100.0])}  # at 0 % over 1–2 s and 3–4 s
    assert _overridden(t, v, 0.5, 4.5, coverage([(1, 2), (1, 2)])) == \
        "it ran at a feed override of 0 % for 1.0 s while the machine moved"
    assert "for 1.0 s" in _overridden(t, v, 0.5, 4.5, coverage([(0.5, 1.8), (1.2, 2.0)]))
    assert _overridden(t, v, 0.5, 4.5, coverage([(1, 2), (2.9, 4.1)])) == ""
    # where the time at 0 % lies inside the holds, its value is not what is told
    v2 = {"feed_override": np.array([100, 0, 0.5, 100, 100, 100.0])}
    assert _overridden(t, v2, 0.5, 4.5, coverage([(1, 2)])) == \
        "it ran at a feed override of 0.5 % for 1.0 s while the machine moved"


# ------------------------------------------------------------------ the NIST Hurco VMX24

HURCO = REALDATA / "nist_smstestbed_mtc_hurco"
PROFILE = ROOT / "samples" / "machines" / "hurco-vmx24.toml"
need_hurco = pytest.mark.skipif(not HURCO.is_dir(), reason=f"{HURCO} not present (the workspace's real logs)")


def _case(twin, plate):
    from mtwin.loop.measurement import read_measurement

    prog = twin.load(str(HURCO / "NC-Code" / f"NIST_MTC_CRADA_PLATE-{plate}.NC"))
    return T.timing_case(twin, prog, read_measurement(str(HURCO / "Split" / f"Plate-Op1-Hurco04-{plate}of20.txt")),
                         f"plate {plate}")


@need_hurco
def test_the_profile_predicts_each_plates_cycle_time_within_2_percent():
    tw = mtwin.Twin.from_toml(str(PROFILE))
    for plate in (12, 13, 14):
        # the full simulation (cutting included), as mtwin compare runs it
        case = _case(tw, plate)
        cyc = tw.simulate(case.program, every=50).summary.cycle_time
        assert abs(cyc - case.cycle_measured) / case.cycle_measured < 0.02, (plate, cyc, case.cycle_measured)


def test_the_start_twin_is_the_profile_scripts_hand_set_base():
    # the leave-one-out, the validation and the fleet recipe start from this file; the script
    # writes the same values ahead of its first step
    import re
    import tomllib

    script = (ROOT / "scripts" / "hurco-vmx24.sh").read_text()
    base = re.search(r'cat >> "\$work/0.toml" <<\'TOML\'\n(.*?)\nTOML\n', script, re.S).group(1)
    start = (ROOT / "samples" / "machines" / "hurco-vmx24-start.toml").read_text()
    assert tomllib.loads(base) == tomllib.loads(start)


@need_hurco
def test_leave_one_out_predicts_plate_12_from_plates_13_and_14():
    # the profile's recipe step by step from its hand-set base (scripts/hurco-vmx24.sh), on
    # plates 13 and 14; plate 12 predicted.  Plate 12 is the hard fold: only it runs S12000
    # (the spindle's power range must come from S750-S9000 starts and stops) and only its helices
    # run below both v²/r limits: the time a spiral block takes beyond its path comes from plates
    # 13 and 14's spirals below the spiral limit (it grows with v²/r: spiral-acceleration's
    # normal_time; a constant time per block fitted there came out twice plate 12's, and none left
    # plate 12's small arcs 2.8 s short).  Before the spindle overlapped motion its tool changes
    # came out 8.5 s short here
    base = mtwin.Twin.from_toml(str(ROOT / "samples" / "machines" / "hurco-vmx24-start.toml"))
    profile = [e.name for e in mtwin.Twin.from_toml(str(PROFILE)).effects]
    assert profile == ["spindle-runup", "toolchange-time", "rapid-acceleration", "arc-acceleration",
                       "spiral-acceleration", "block-time", "feed-rapid-wait"]
    effects = [get(n)() for n in profile]
    fr = T.fit_timing_steps(base, [_case(base, 13), _case(base, 14)], effects,
                            ["axes.x.max_velocity", "axes.y.max_velocity", "axes.x.max_acceleration",
                             "axes.y.max_acceleration", "axes.z.max_acceleration", "controller.bell_time"])
    fitted = base.with_params({k: v for k, v in fr.params.items() if not k.startswith("effects.")}) \
        .with_effects(*fr.effects)
    case = _case(fitted, 12)
    _, _, by_kind, cycle = T._errors(fitted, case)
    assert abs(cycle / case.cycle_measured - 1) < 0.01, cycle / case.cycle_measured - 1
    worst = dict(zip(case.kinds, by_kind))
    assert max(abs(v) for v in worst.values()) < 3.5, worst
    assert abs(worst["small arc"]) < 2.0, worst  # the spirals' extra time, learnt from plates 13 and 14


@need_hurco
def test_the_hurco_stands_at_a_straight_feed_lines_end_before_a_rapid_and_the_profile_does_too():
    # plate 12's straight feed lines, timed against logs of the twin's own run: those a rapid
    # follows run ~70 ms short of the log on the profile without its wait, beyond four standard
    # errors, while those a feed line follows run alike — and so do the profile's, with the wait
    # it fitted to the block times of whole kinds and windows (which want less than these ends
    # alone: they are still short, by less than half)
    from mtwin.loop.asrun import feed_line_ends
    from mtwin.loop.measurement import read_measurement

    profile = mtwin.Twin.from_toml(str(PROFILE))
    bare = profile.replace(effects=[e for e in profile.effects if e.name != "feed-rapid-wait"])
    meas = read_measurement(str(HURCO / "Split" / "Plate-Op1-Hurco04-12of20.txt"))
    ends = {}
    for name, tw in (("bare", bare), ("profile", profile)):
        prog = tw.load(str(HURCO / "NC-Code" / "NIST_MTC_CRADA_PLATE-12.NC"))
        ends[name] = feed_line_ends(prog, meas, tw.simulate(prog, cutting=False))
    n, before_rapid, se = ends["bare"][("line", "rapid")]
    assert n >= 50 and before_rapid < -0.04 and before_rapid < -4 * se, ends["bare"]
    _, before_feed, se = ends["bare"][("line", "feed")]
    assert abs(before_feed) < 3 * se, ends["bare"]
    _, after_feed, se = ends["profile"][("line", "feed")]
    assert abs(after_feed) < 3 * se, ends["profile"]
    _, with_wait, se = ends["profile"][("line", "rapid")]
    assert before_rapid / 2 < with_wait < 0, ends["profile"]


@need_hurco
def test_diagnose_names_the_timing_effects_the_profile_adds_in_order():
    # from the machine the profile was made from: the default twin, its first five steps
    start = mtwin.Twin()
    d = T.diagnose_timing(start, [_case(start, 13)])
    names = [c["effect"] for c in d["candidates"]]
    profile = [e.name for e in mtwin.Twin.from_toml(str(PROFILE)).effects]
    assert names[:5] == profile[:5], (names, profile)
    # the others remove less than the fifth (on plate 13: 25 % for spiral-acceleration); far less
    # but for feed-rapid-wait, which on a twin 15 % short stands in for missing time at every
    # pass end (0.35 s each, 16 %): the profile adds it seventh, on the line ends' evidence
    # (test_the_hurco_stands_at_a_straight_feed_lines_end_before_a_rapid…); corner-slowdown and
    # block-time 7 % each
    weakest = d["candidates"][4]["explained_variance"]
    assert all(c["explained_variance"] < weakest for c in d["candidates"][5:])
    assert all(c["explained_variance"] < 0.5 * weakest for c in d["candidates"][5:]
               if c["effect"] != "feed-rapid-wait")
    # with those five in the profile's twin, block-time is what it ranks next (the sixth step),
    # well ahead of corner-slowdown
    profile_twin = mtwin.Twin.from_toml(str(PROFILE))
    five = profile_twin.replace(effects=[e for e in profile_twin.effects if e.name != "block-time"])
    d = T.diagnose_timing(five, [_case(five, 13)])
    assert profile[5] == "block-time" and d["candidates"][0]["effect"] == "block-time", d["candidates"]
    rest = [c["explained_variance"] for c in d["candidates"][1:]]
    assert all(v < 0.5 * d["candidates"][0]["explained_variance"] for v in rest)


def test_block_times_by_kind_as_logged_take_out_the_reporting_delay():
    # the twin's own run logged by sampling its executing line every ~0.17 s: a short line is
    # reported late by about half its own length, a long one by half the interval, so summed by
    # kind the log itself moves ~1.7 s from the feed lines to the short ones; the simulation as
    # logged moves the same (an independent route: the sampling done, against the formula)
    from mtwin.loop.blocks import measurement_block_timing, report_period

    lines, x = ["G21 G90 G94", "G0 X0 Y0 Z0", "G1 F600"], 0.0
    for i in range(40):
        x += 0.6
        lines.append(f"G1 X{x:.1f}")  # 0.06 s: shorter than the sampling interval
        x += 8.0
        lines += [f"G1 X{x:.1f}", f"G1 Y{(i % 2) * 1.0:.1f}"]
    tw = mtwin.Twin()
    prog = tw.load(("\n".join(lines) + "\nM30\n").encode(), path="s.nc")
    tr = tw.simulate(prog, cutting=False)
    raw, logged = [], []
    for seed in range(4):
        m = _log_of(tw, prog, seed=seed)
        assert report_period(m.t, m.line) == pytest.approx(0.17, rel=0.06)
        b = {k["kind"]: k for k in measurement_block_timing(prog, m, tr).by_kind()}
        raw.append(b["short line"]["error"])
        logged.append(b["short line"]["error_as_logged"])
        # the shifts cancel over the run, but for the first report's own delay
        assert sum(k["error"] for k in b.values()) == pytest.approx(sum(k["error_as_logged"] for k in b.values()),
                                                                    abs=0.5 * 0.17 * 1.2)
    assert np.mean(np.abs(raw)) > 1.0
    assert np.mean(np.abs(logged)) < 0.25 * np.mean(np.abs(raw))


def test_the_logging_bias_is_what_logs_of_the_twins_own_run_show():
    # feed lines, small arcs and runs of short lines: which lines a log reports decides how the
    # groups are cut and which kind each takes, a bias the first-order delays leave (-0.5 s on
    # the short lines, +0.6 s on the arcs, averaged over six logs of the twin's own run, where
    # the true error is zero).  Taking off what the twin's run logged the same way shows
    # (logging_bias) leaves under half of it.
    from mtwin.loop.blocks import measurement_block_timing

    lines, x = ["G21 G90 G94 S1000 M3", "G0 X0 Y0 Z0", "G1 F900"], 0.0
    for i in range(60):
        x += 12.0
        lines.append(f"G1 X{x:.1f}")
        lines.append(f"G2 X{x + 1.0:.1f} Y-1.0 R1.0" if i % 2 == 0 else f"G3 X{x + 1.0:.1f} Y0 R1.0")
        x += 1.0
        for _ in range(3):
            x += 0.8
            lines.append(f"G1 X{x:.1f}")
    tw = mtwin.Twin()
    prog = tw.load(("\n".join(lines) + "\nM30\n").encode(), path="s.nc")
    tr = tw.simulate(prog, cutting=False)
    first, corrected = {"short line": [], "small arc": []}, {"short line": [], "small arc": []}
    for seed in range(100, 106):
        b = {k["kind"]: k for k in measurement_block_timing(prog, _log_of(tw, prog, every=0.19, seed=seed), tr).by_kind()}
        for k in first:
            corrected[k].append(b[k]["error_as_logged"])
            first[k].append(b[k]["error_as_logged"] + b[k]["logging_bias"])
    for k in first:
        assert abs(np.mean(first[k])) > 0.4, (k, first[k])
        assert abs(np.mean(corrected[k])) < 0.5 * abs(np.mean(first[k])), (k, first[k], corrected[k])
