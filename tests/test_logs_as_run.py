"""Real machine logs as they come (issue 19): overrides read in the Hurco and the MTConnect
standard's names and replayed by the twin, program stops (M01 waits, logged stop states)
found and taken out, a log that stops before the program's end refused or compared up to
where it got (--partial).  The logs are written here from the twin's own run of a program
with known overrides and waits, so the answers are known."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from dataclasses import replace
from datetime import datetime, timedelta, timezone

import numpy as np
import pytest

import mtwin
import mtwin.loop.journal
from mtwin.gcode import records as R
from mtwin.loop.asrun import as_run
from mtwin.loop.measurement import MeasurementError, read_measurement

PROGRAM = """\
%
O1000(PART)
G21 G90 G17 G94
T1 M6
S6000 M3
G0 X0 Y0 Z5
G1 Z-1 F300
G1 X40 F900
G0 Z5
G0 X400 Y300
G1 Z-1 F300
G1 X360 F900
G0 Z5
M01
G0 X0 Y0
G1 Z-1 F300
G1 Y40 F600
G0 Z5
M30
%
"""
RAPID_LINES = (10,)  # G0 X400 Y300: run at 50 % rapid override
STOP_LINE = 14  # M01: the operator waits
WAIT = 30.0
BASE = datetime(2017, 2, 6, 10, 22, 28, 750000, tzinfo=timezone.utc)


def _ts(t: float) -> str:
    d = BASE + timedelta(seconds=float(t))
    return d.strftime("%Y-%m-%dT%H:%M:%S.%f") + "0Z"  # 7 digits, as the Hurco logger writes


def _truth(tw, prog):
    """The run the log records: line 10's rapid at half speed (the program as it ran)."""
    rec = prog.records
    scale = np.where(np.isin(rec["line"], RAPID_LINES) & (rec["kind"] == R.RAPID), 0.5, 1.0)
    return tw.simulate(replace(prog, rapid_scale=scale), cutting=False)


def _log(tw, prog, names=("Block_Number", "Program_Status", "Rapid_Override", "Feed_Rate"), wait=WAIT,
         cut_at: float | None = None, status_stop: bool = False) -> str:
    """An SHDR log of the twin's run: every line change, the rapid override on change (50 %
    while line 10 runs), the operator's wait at the M01, the feed in mm/s."""
    block, status, rapid, feed = names
    tr = _truth(tw, prog)
    t, line = np.asarray(tr.t), np.asarray(tr.line)
    f = np.asarray(tr.signal("feed")) / 60.0
    out = [f"{_ts(-1.0)}|Program_Name_Running|PART.NC", f"{_ts(-0.5)}|{rapid}|100.000000",
           f"{_ts(0.0)}|{status}|ACTIVE"]
    shift = 0.0
    prev = None
    for k in np.flatnonzero(np.r_[True, line[1:] != line[:-1]]):
        ln = int(line[k])
        if ln <= 0 or ln == prev:
            continue
        tk = float(t[k]) + shift
        if cut_at is not None and tk > cut_at:
            return "\n".join(out) + "\n"
        if prev is not None and prev < STOP_LINE < ln:
            # the control shows the M01 line while it waits for the operator
            out.append(f"{_ts(tk)}|{block}|{STOP_LINE}")
            if wait and status_stop:
                out.append(f"{_ts(tk + 0.01)}|{status}|OPTIONAL_STOP")
                out.append(f"{_ts(tk + wait)}|{status}|ACTIVE")
            shift += wait
            tk += wait
        if prev in RAPID_LINES:
            out.append(f"{_ts(tk)}|{rapid}|100.000000")
        out.append(f"{_ts(tk)}|{block}|{ln}|{feed}|{f[k]:.6f}")
        if ln in RAPID_LINES:
            out.append(f"{_ts(tk)}|{rapid}|50.000000")
        prev = ln
    out.append(f"{_ts(float(t[-1]) + shift)}|{status}|PROGRAM_COMPLETED")
    return "\n".join(out) + "\n"


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    d = tmp_path_factory.mktemp("logs")
    (d / "PART.NC").write_text(PROGRAM)
    tw = mtwin.Twin()
    prog = tw.load(str(d / "PART.NC"))
    return d, tw, prog


def _cli(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "mtwin", *args], capture_output=True, text=True, cwd=cwd)


def test_a_rapid_override_of_50_percent_doubles_the_rapid_time_at_speed_in_the_twin(setup):
    d, tw, prog = setup
    (d / "log.txt").write_text(_log(tw, prog))
    m = read_measurement(str(d / "log.txt"))
    assert "rapid_override" in m.extra and m.meta["overrides"] == "feed, spindle not logged: 100 % assumed"
    run = as_run(prog, m)
    assert run.applied == {"rapid_override": (50.0, 100.0)}
    full, half = tw.plan(prog), tw.plan(run.program)
    on = np.isin(full.seg["line"], RAPID_LINES)
    t_full, t_half = full.dur[on].sum(), half.dur[np.isin(half.seg["line"], RAPID_LINES)].sum()
    # the same as a machine whose rapid speed is half its own (an independent route), and close
    # to twice the time: a 500 mm rapid is mostly at speed (the ramps do not double)
    slow = tw.with_params({f"axes.{a}.max_velocity": ax.max_velocity / 2 for a, ax in zip("xyz", tw.machine.axes)})
    slow_plan = slow.plan(prog)
    assert t_half == pytest.approx(slow_plan.dur[np.isin(slow_plan.seg["line"], RAPID_LINES)].sum(), rel=1e-9)
    # closed form: the rapid runs X 360 mm (its longest axis) on a trapezoid, D/v + v/a (plus
    # the bell filter and the in-position hold, the same at both speeds): at half the speed
    # the time at speed doubles and the ramps halve, t(v/2) - t(v) = D/v - v/(2a)
    x = tw.machine.x
    v, a = x.max_velocity / 60.0, x.max_acceleration
    assert t_half - t_full == pytest.approx(360.0 / v - v / (2 * a), abs=0.005)
    # the other blocks are as they were
    assert half.dur[~np.isin(half.seg["line"], RAPID_LINES)].sum() == pytest.approx(full.dur[~on].sum(), rel=1e-12)


def test_compare_replays_the_override_and_reports_the_m01_wait(setup):
    d, tw, prog = setup
    (d / "log.txt").write_text(_log(tw, prog))
    r = _cli("compare", str(d / "PART.NC"), str(d / "log.txt"), "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    b = doc["blocks"]
    # the M01 wait is a program stop, taken out; what is left is the twin's own run
    (stop,) = b["program_stops"]
    assert stop["line"] == STOP_LINE and stop["state"] == "M01" and stop["wait"] == pytest.approx(WAIT, abs=0.05)
    assert all(k["kind"] != "tool change" or abs(k["error"]) < 0.05 for k in b["by_kind"])
    assert b["rms"] < 0.02  # every logged line change, replayed at the logged override: ~exact
    assert doc["cycle_time"]["relative_error"] == pytest.approx(0.0, abs=0.002)
    assert "program stop at line 14 (M01): waited 30.0 s" in r.stderr
    assert "rapid override 50–100 % applied" in r.stderr
    # not replaying the override (the log without the item) leaves line 10 twice as slow in the log
    no = "\n".join(x for x in _log(tw, prog).splitlines() if "Rapid_Override" not in x) + "\n"
    (d / "plain.txt").write_text(no)
    r2 = _cli("compare", str(d / "PART.NC"), str(d / "plain.txt"), "--json")
    worst = json.loads(r2.stdout)["blocks"]["worst"][0]
    assert worst["first_line"] == 10 and worst["error"] < -0.3  # the twin too fast there
    assert "feed, rapid, spindle override not logged: 100 % assumed" in r2.stderr


def test_the_standard_names_and_a_logged_optional_stop(setup):
    d, tw, prog = setup
    text = _log(tw, prog, names=("Line", "Execution", "RapidOverride", "PathFeedrate"), status_stop=True)
    (d / "std.txt").write_text(text)
    m = read_measurement(str(d / "std.txt"))
    assert m.stops and m.stops[0][2] == "OPTIONAL_STOP" and m.stops[0][1] - m.stops[0][0] == pytest.approx(WAIT - 0.01)
    assert m.complete is True
    r = _cli("compare", str(d / "PART.NC"), str(d / "std.txt"), "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["cycle_time"]["relative_error"] == pytest.approx(0.0, abs=0.002)
    assert doc["blocks"]["program_stop_s"] == pytest.approx(WAIT, abs=0.1)
    # an agent's XML: PathFeedrateOverride told apart by its subType
    xml = ['<?xml version="1.0"?>', '<MTConnectStreams xmlns="urn:mtconnect.org:MTConnectStreams:1.3"><Streams>'
           '<DeviceStream name="m"><ComponentStream component="Path"><Samples>']
    for ln in text.splitlines():
        ts, item, *rest = ln.split("|")
        for k in range(0, len(rest), 2):
            name, value = ([item] + rest)[k], rest[k] if k == 0 else rest[k]
        pairs = [(item, rest[0])] + [(rest[k], rest[k + 1]) for k in range(1, len(rest) - 1, 2)]
        for name, value in pairs:
            tag = {"RapidOverride": 'PathFeedrateOverride subType="RAPID"', "Line": "Line", "Execution": "Execution",
                   "PathFeedrate": "PathFeedrate", "Program_Name_Running": "Program"}[name]
            xml.append(f'<{tag} dataItemId="d" timestamp="{ts}">{value}</{tag.split()[0]}>')
    xml.append("</Samples></ComponentStream></DeviceStream></Streams></MTConnectStreams>")
    (d / "std.xml").write_text("\n".join(xml))
    mx = read_measurement(str(d / "std.xml"))
    assert "rapid_override" in mx.extra and np.nanmin(mx.extra["rapid_override"]) == 50.0
    assert as_run(prog, mx).applied == {"rapid_override": (50.0, 100.0)}


def test_an_imported_log_replays_the_same_overrides(setup, tmp_path):
    d, tw, prog = setup
    (d / "log.txt").write_text(_log(tw, prog))
    r = _cli("import", "mtconnect", str(d / "log.txt"), "-o", str(tmp_path / "m.csv"))
    assert r.returncode == 0, r.stderr
    direct, imported = read_measurement(str(d / "log.txt")), read_measurement(str(tmp_path / "m.csv"))
    assert imported.ignored == [] and set(imported.extra) == set(direct.extra)
    a, b = as_run(prog, direct), as_run(prog, imported)
    assert a.applied == b.applied and a.not_logged == b.not_logged
    np.testing.assert_allclose(a.program.rapid_scale, b.program.rapid_scale, rtol=1e-9)  # (t to 1 ns in the CSV)
    r2 = _cli("compare", str(d / "PART.NC"), str(tmp_path / "m.csv"), "--json")
    r1 = _cli("compare", str(d / "PART.NC"), str(d / "log.txt"), "--json")
    c1, c2 = json.loads(r1.stdout), json.loads(r2.stdout)
    assert c1["cycle_time"]["simulated"] == pytest.approx(c2["cycle_time"]["simulated"], rel=1e-9)
    assert c2["blocks"]["program_stops"][0]["wait"] == pytest.approx(WAIT, abs=0.05)


def test_a_log_cut_short_is_refused_and_compared_up_to_its_end_with_partial(setup):
    d, tw, prog = setup
    tr = _truth(tw, prog)
    (d / "cut.txt").write_text(_log(tw, prog, wait=0.0, cut_at=float(tr.t[-1]) * 0.5))
    for cmd in (["compare"], ["diagnose"], ["calibrate", "--fit", "block-time", "-o", str(d / "x.toml")]):
        r = _cli(*cmd[:1], str(d / "PART.NC"), str(d / "cut.txt"), *cmd[1:])
        assert r.returncode == 2, (cmd, r.stderr)
        assert "incomplete" in r.stderr and "--partial" in r.stderr
        assert not (d / "x.toml").exists()
    r = _cli("compare", str(d / "PART.NC"), str(d / "cut.txt"), "--partial", "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    m = read_measurement(str(d / "cut.txt"))
    last = int(m.line[m.line > 0][-1])
    assert f"stopped at line {last}" in r.stderr
    # the simulated cycle is the time to the end of that line, not the whole program's
    assert doc["cycle_time"]["simulated"] < 0.75 * float(tr.t[-1])
    assert abs(doc["cycle_time"]["relative_error"]) < 0.1


def test_an_unknown_item_names_ignore_item_and_every_log_command_takes_it(setup):
    d, tw, prog = setup
    text = _log(tw, prog).replace("|Program_Status|ACTIVE", "|Program_Status|ACTIVE|Coffee_Level|3", 1)
    (d / "odd.txt").write_text(text)
    r = _cli("compare", str(d / "PART.NC"), str(d / "odd.txt"))
    assert r.returncode == 2 and "--ignore-item Coffee_Level" in r.stderr and "odd.txt:3:" in r.stderr
    for cmd in ("compare", "diagnose"):
        r = _cli(cmd, str(d / "PART.NC"), str(d / "odd.txt"), "--ignore-item", "Coffee_Level")
        assert r.returncode == 0, (cmd, r.stderr)
    with pytest.raises(MeasurementError):
        read_measurement(str(d / "odd.txt"))


def test_an_agents_block_text_and_incremental_line_numbers_are_not_lines(tmp_path):
    # the standard's Block is the executing block's text; LineNumber INCREMENTAL counts blocks
    # from the start of execution — neither is the program line
    xml = """<?xml version="1.0"?>
<MTConnectStreams xmlns="urn:mtconnect.org:MTConnectStreams:1.7"><Streams><DeviceStream name="m">
<ComponentStream component="Path"><Events>
<Execution dataItemId="e" timestamp="2020-01-01T00:00:00.0Z">ACTIVE</Execution>
<Program dataItemId="p" timestamp="2020-01-01T00:00:00.0Z">PART.NC</Program>
<LineNumber dataItemId="l" subType="ABSOLUTE" timestamp="2020-01-01T00:00:00.1Z">3</LineNumber>
<LineNumber dataItemId="li" subType="INCREMENTAL" timestamp="2020-01-01T00:00:00.1Z">1</LineNumber>
<Block dataItemId="b" timestamp="2020-01-01T00:00:00.1Z">G1 X10 F600</Block>
<LineNumber dataItemId="l" subType="ABSOLUTE" timestamp="2020-01-01T00:00:01.1Z">4</LineNumber>
<LineNumber dataItemId="li" subType="INCREMENTAL" timestamp="2020-01-01T00:00:01.1Z">2</LineNumber>
<Block dataItemId="b" timestamp="2020-01-01T00:00:01.1Z">G1 Y10</Block>
<Execution dataItemId="e" timestamp="2020-01-01T00:00:02.0Z">PROGRAM_COMPLETED</Execution>
</Events></ComponentStream></DeviceStream></Streams></MTConnectStreams>
"""
    (tmp_path / "a.xml").write_text(xml)
    m = read_measurement(str(tmp_path / "a.xml"))
    assert list(m.line) == [3, 4] and m.complete is True


# ------------------------------------------------ programs that do not run top to bottom

SUB = """\
O1000(PART)
G21 G90 G17 G94
G0 X0 Y0 Z5
M98 P100
G0 X0 Y0
M98 P100
G0 Z50
M30
O100
G0 X300 Y200
G1 Z-1 F300
G1 X250 F900
G0 Z5
M99
"""
SUB_RAPID = 10  # G0 X300 Y200 in the subprogram: run twice


def _sub_log(tw, prog, second_at=50.0, cut_in_second: bool = False) -> tuple[str, np.ndarray]:
    """A log of the subprogram program: every line change; the rapid override at 50 % only
    while the subprogram's rapid runs the second time."""
    rec = prog.records
    entry = np.flatnonzero((rec["line"] == SUB_RAPID) & (rec["kind"] == R.RAPID))
    scale = np.ones(len(rec))
    scale[entry[1]] = second_at / 100.0
    tr = tw.simulate(replace(prog, rapid_scale=scale), cutting=False)
    t, line = np.asarray(tr.t), np.asarray(tr.line)
    out = [f"{_ts(-1.0)}|Program_Name_Running|PART.NC", f"{_ts(0.0)}|Program_Status|ACTIVE",
           f"{_ts(0.0)}|Rapid_Override|100"]
    k_all = [k for k in np.flatnonzero(np.r_[True, line[1:] != line[:-1]]) if line[k] > 0]
    seen = 0
    for n, k in enumerate(k_all):
        ln = int(line[k])
        if ln == SUB_RAPID:
            seen += 1
            if cut_in_second and seen == 2:
                out.append(f"{_ts(t[k])}|Block_Number|{ln}")
                return "\n".join(out) + "\n", scale
            out.append(f"{_ts(t[k])}|Rapid_Override|{second_at if seen == 2 else 100}")
        elif seen == 2 and int(line[k_all[n - 1]]) == SUB_RAPID:
            out.append(f"{_ts(t[k])}|Rapid_Override|100")
        out.append(f"{_ts(t[k])}|Block_Number|{ln}")
    out.append(f"{_ts(float(t[-1]))}|Program_Status|PROGRAM_COMPLETED")
    return "\n".join(out) + "\n", scale


def test_overrides_follow_execution_order_through_a_subprogram(tmp_path):
    (tmp_path / "PART.NC").write_text(SUB)
    tw = mtwin.Twin()
    prog = tw.load(str(tmp_path / "PART.NC"))
    text, truth = _sub_log(tw, prog)
    (tmp_path / "log.txt").write_text(text)
    run = as_run(prog, read_measurement(str(tmp_path / "log.txt")))
    # the subprogram's rapid at 50 % on its second call only, every other rapid at 100 %
    np.testing.assert_allclose(run.program.rapid_scale, truth, atol=1e-9)
    r = _cli("compare", str(tmp_path / "PART.NC"), str(tmp_path / "log.txt"), "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["cycle_time"]["relative_error"] == pytest.approx(0.0, abs=0.002)


def test_partial_cuts_the_program_where_the_log_stopped_in_execution_order(tmp_path):
    (tmp_path / "PART.NC").write_text(SUB)
    tw = mtwin.Twin()
    prog = tw.load(str(tmp_path / "PART.NC"))
    text, _ = _sub_log(tw, prog, cut_in_second=True)
    (tmp_path / "cut.txt").write_text(text)
    m = read_measurement(str(tmp_path / "cut.txt"))
    assert m.complete is False
    run = as_run(prog, m, partial=True)
    rec = prog.records
    second = int(np.flatnonzero((rec["line"] == SUB_RAPID) & (rec["kind"] == R.RAPID))[1])
    assert len(run.program.records) == second  # everything before the subprogram's second rapid
    r = _cli("compare", str(tmp_path / "PART.NC"), str(tmp_path / "cut.txt"), "--partial", "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["cycle_time"]["relative_error"] == pytest.approx(0.0, abs=0.01)


def test_partial_without_line_numbers_is_a_clear_error_and_overrides_are_averaged(tmp_path):
    (tmp_path / "PART.NC").write_text(PROGRAM)
    prog = mtwin.Twin().load(str(tmp_path / "PART.NC"))
    log = (f"{_ts(0)}|Program_Status|ACTIVE\n{_ts(0)}|Feed_Override|50\n{_ts(5)}|Feed_Override|100\n"
           f"{_ts(10)}|Feed_Rate|10\n")
    (tmp_path / "nolines.txt").write_text(log)
    m = read_measurement(str(tmp_path / "nolines.txt"))
    with pytest.raises(MeasurementError, match="names no program line"):
        as_run(prog, m, partial=True)
    done = log + f"{_ts(10)}|Program_Status|PROGRAM_COMPLETED\n"
    (tmp_path / "done.txt").write_text(done)
    run = as_run(prog, read_measurement(str(tmp_path / "done.txt")))
    # 50 % for 5 s, then 100 % for 5 s: 75 % over the run, on every feed move
    assert run.applied["feed_override"] == (75.0, 75.0) and "mean over the whole run" in " ".join(run.notes)


def test_a_spindle_override_ramp_adds_no_run_up_pauses(tmp_path):
    (tmp_path / "PART.NC").write_text(PROGRAM)
    tw = mtwin.Twin()
    prog = tw.load(str(tmp_path / "PART.NC"))
    text = _log(tw, prog, wait=0.0)
    lines = text.splitlines()
    ramp = [ln.split("|")[0] + f"|Spindle_Override|{100 + 5 * k}" for k, ln in enumerate(lines[3:-1])]
    (tmp_path / "s.txt").write_text("\n".join(lines[:3] + [x for pair in zip(lines[3:-1], ramp) for x in pair]
                                              + lines[-1:]) + "\n")
    run = as_run(prog, read_measurement(str(tmp_path / "s.txt")))
    assert run.applied["spindle_override"][1] > 140.0
    a, b = tw.plan(prog), tw.plan(run.program)
    assert int((b.seg["kind"] == 2).sum()) == int((a.seg["kind"] == 2).sum())  # no pause added
    # the plan is the one of the rapid override alone (the log's other override): the spindle
    # override acts on the speed the spindle is driven to, not on the plan
    c = tw.plan(replace(prog, rapid_scale=run.program.rapid_scale))
    assert b.total_time == pytest.approx(c.total_time, rel=1e-12)
    sim = tw.simulate(run.program)
    plain = tw.simulate(replace(prog, rapid_scale=run.program.rapid_scale))
    assert np.max(np.abs(sim.signal("spindle_speed"))) > 1.3 * np.max(np.abs(plain.signal("spindle_speed")))


def test_runs_a_stop_after_a_hold_aborts_and_another_program_starts_a_new_run(tmp_path):
    from mtwin.loop.mtconnect import read_shdr, runs

    log = (f"{_ts(0)}|Program_Name_Running|A.NC\n{_ts(0)}|Execution|ACTIVE\n{_ts(1)}|Block_Number|5\n"
           f"{_ts(2)}|Execution|FEED_HOLD\n{_ts(3)}|Execution|STOPPED\n{_ts(4)}|Execution|READY\n"
           f"{_ts(5)}|Program_Name_Running|B.NC\n{_ts(5)}|Execution|ACTIVE\n{_ts(6)}|Block_Number|3\n"
           f"{_ts(7)}|Execution|STOPPED\n{_ts(8)}|Program_Name_Running|C.NC\n{_ts(9)}|Execution|ACTIVE\n"
           f"{_ts(10)}|Block_Number|4\n{_ts(11)}|Execution|PROGRAM_COMPLETED\n")
    (tmp_path / "r.txt").write_text(log)
    rs = runs(read_shdr(str(tmp_path / "r.txt")))
    assert [(r.program, r.complete) for r in rs] == [("A.NC", False), ("B.NC", False), ("C.NC", True)]
    # a reset from a feed hold aborts the run too (read without its program, where READY alone
    # could be a finish); the program completed after a hold whose resume the log missed did not
    for end, complete in (("READY", False), ("PROGRAM_COMPLETED", True)):
        (tmp_path / "h.txt").write_text(f"{_ts(0)}|Program_Name_Running|A.NC\n{_ts(0)}|Execution|ACTIVE\n"
                                        f"{_ts(1)}|Block_Number|5\n{_ts(2)}|Execution|FEED_HOLD\n"
                                        f"{_ts(4)}|Execution|{end}\n")
        r, = runs(read_shdr(str(tmp_path / "h.txt")))
        assert r.complete is complete
        assert complete or r.describe() == "A.NC, incomplete (FEED_HOLD at line 5 at 2 s, then reset to READY), reached line 5"


def test_values_calibrated_from_a_log_without_overrides_are_labelled_effective(setup, tmp_path):
    d, tw, prog = setup
    plain = "\n".join(x for x in _log(tw, prog).splitlines() if "Rapid_Override" not in x) + "\n"
    (d / "plain2.txt").write_text(plain)
    r = _cli("calibrate", str(d / "PART.NC"), str(d / "plain2.txt"), "--fit", "block-time", "-o",
             str(tmp_path / "t.toml"))
    assert r.returncode == 0, r.stderr
    (entry,) = mtwin.loop.journal.read_journal(str(tmp_path / "t.toml"))
    assert any("not logged" in n and "effective" in n for n in entry["notes"])


def test_a_twin_file_calibrated_from_the_default_machine_runs_its_own_program(setup, tmp_path):
    # the program goes to Y 300, beyond the default machine's 250: a warning, never a hard
    # limit of a twin file that gives no travel (calibrate's output: effects and a journal) —
    # the loop commands tell it as simulate does
    d, tw, prog = setup
    (d / "plain3.txt").write_text(_log(tw, prog))
    r = _cli("calibrate", str(d / "PART.NC"), str(d / "plain3.txt"), "--fit", "block-time", "-o",
             str(tmp_path / "t.toml"))
    assert r.returncode == 0, r.stderr
    assert "travel limit 250 mm of axis Y" in r.stderr and "warning" in r.stderr
    assert "[axes" not in (tmp_path / "t.toml").read_text()
    r = _cli("compare", str(d / "PART.NC"), str(d / "plain3.txt"), "--twin", str(tmp_path / "t.toml"))
    assert r.returncode == 0, r.stderr
    assert "travel limit 250 mm of axis Y" in r.stderr
    # a file that gives the travel makes it the machine's: hard
    (tmp_path / "m.toml").write_text("[axes.y]\nmin_travel = -250.0\nmax_travel = 250.0\n")
    r = _cli("compare", str(d / "PART.NC"), str(d / "plain3.txt"), "--twin", str(tmp_path / "m.toml"))
    assert r.returncode == 2 and "PART.NC:10:1:" in r.stderr and "axes.y.max_travel" in r.stderr


def test_a_log_copied_while_written_ends_in_a_record_cut_short_which_is_left_out(setup, tmp_path):
    d, tw, prog = setup
    text = _log(tw, prog)
    cut = text[:text.index("Block_Number|12")] + "Block_Nu"  # (no newline after it)
    (d / "copied.txt").write_text(cut)
    r = _cli("compare", str(d / "PART.NC"), str(d / "copied.txt"))
    assert r.returncode == 2 and "incomplete" in r.stderr and "--partial" in r.stderr
    r = _cli("compare", str(d / "PART.NC"), str(d / "copied.txt"), "--partial", "--json")
    assert r.returncode == 0, r.stderr
    assert "the last, is not a whole record" in r.stderr and "left out" in r.stderr
    # the same record cut short in the middle of a log is an error with its place
    (d / "broken.txt").write_text(cut + "\n" + text[text.index("Block_Number|12"):])
    r = _cli("compare", str(d / "PART.NC"), str(d / "broken.txt"), "--partial")
    n = cut.count("\n") + 1
    assert r.returncode == 2 and f"broken.txt:{n}:" in r.stderr and "unknown data item 'Block_Nu'" in r.stderr


def test_the_compare_report_of_a_log_holds_its_block_timing_and_units(setup, tmp_path):
    # what compare prints of a control's log — the error by block kind, the worst blocks with
    # their G-code, the notes — is in the report too, the signals with their units
    d, tw, prog = setup
    (d / "rep.txt").write_text(_sampled_log(tw, prog))
    out = tmp_path / "c.html"
    r = _cli("compare", str(d / "PART.NC"), str(d / "rep.txt"), "--report", str(out))
    assert r.returncode == 0, r.stderr
    page = out.read_text()
    assert "<h2>Block timing</h2>" in page and "<td>rapid</td>" in page and "Worst blocks" in page
    assert "G0 X400 Y300" in page  # (a worst block's own line)
    assert "<td>feed</td><td>mm/min</td>" in page and "[mm/min]" in page  # the table's unit, the plot's axis
    assert "override not logged" in page  # the notes


def _events(text: str) -> list:
    """The log's lines as (seconds since BASE, rest)."""
    out = []
    for ln in text.splitlines():
        ts, rest = ln.split("|", 1)
        t = (datetime.strptime(ts[:26], "%Y-%m-%dT%H:%M:%S.%f").replace(tzinfo=timezone.utc) - BASE).total_seconds()
        out.append((t, rest))
    return out


def _restarted(tw, prog, stop_after: float, wait: float, back_to: int | None = None) -> str:
    """The log of a run stopped at ``stop_after`` s and, ``wait`` s later, run again: from the
    start (``back_to`` None: the whole log again, the runtime reset) or from the first time it
    reached line ``back_to`` (a restart in the middle)."""
    ev = _events(_log(tw, prog))
    head = [(t, r) for t, r in ev if t <= stop_after and "PROGRAM_COMPLETED" not in r]
    t_stop = head[-1][0] + 0.01
    out = head + [(t_stop, "Program_Status|STOPPED"), (t_stop, "Program_Runtime_Seconds|" + f"{t_stop:.0f}")]
    t_go = t_stop + wait
    if back_to is None:
        again = [(t, r) for t, r in ev if t >= 0]
        shift = t_go - again[0][0]
        out += [(t_go, "Program_Runtime_Seconds|0")] + [(t + shift, r) for t, r in again]
    else:
        k = next(i for i, (t, r) in enumerate(ev) if r.startswith(f"Block_Number|{back_to}"))
        again = ev[k:]
        shift = t_go - again[0][0]
        out += [(t_go, "Program_Status|ACTIVE")] + [(t + shift, r) for t, r in again]
    return "\n".join(f"{_ts(t)}|{r}" for t, r in out) + "\n"


def test_a_restart_from_the_start_is_an_aborted_run_and_a_complete_one(setup, tmp_path):
    d, tw, prog = setup
    truth = _truth(tw, prog).summary.cycle_time + WAIT  # (the M01 wait is in the log, and taken out)
    (d / "restart.txt").write_text(_restarted(tw, prog, stop_after=20.0, wait=963.0))
    m = read_measurement(str(d / "restart.txt"))
    assert len(m.runs) == 2 and [r.complete for r in m.runs] == [False, True]
    aborted = m.runs[0]
    assert 0 < aborted.reached < 19 and "started again from the program's start" in aborted.ended
    assert m.meta["run"] == "2" and "run 1:" in m.meta["other_runs"]
    # the complete run alone: no 963-s wait, no aborted part counted
    assert m.end_time == pytest.approx(truth, abs=0.5)
    r = _cli("compare", str(d / "PART.NC"), str(d / "restart.txt"), "--json")
    assert r.returncode == 0, r.stderr
    c = json.loads(r.stdout)["cycle_time"]
    assert abs(c["measured"] - c["simulated"]) / c["simulated"] < 0.01


def test_a_restart_in_the_middle_counts_no_time_twice(setup, tmp_path):
    d, tw, prog = setup
    (d / "middle.txt").write_text(_restarted(tw, prog, stop_after=22.0, wait=400.0, back_to=11))
    m = read_measurement(str(d / "middle.txt"))
    assert len(m.runs) == 1 and m.runs[0].complete
    (t, was, now), = m.runs[0].restarts
    assert now == 11 and was > 11 and "from line" in m.meta["restarts"]
    # every line once, in program order: the first pass through 11.. is left out
    seq = [int(x) for x in m.line[m.line > 0]]
    assert seq == sorted(seq) or all(b >= a for a, b in zip(seq, seq[1:]))
    r = _cli("compare", str(d / "PART.NC"), str(d / "middle.txt"), "--json")
    assert r.returncode == 0, r.stderr
    c = json.loads(r.stdout)["cycle_time"]
    assert abs(c["measured"] - c["simulated"]) / c["simulated"] < 0.01, c
    # imported: the header's cycle time is the run's without the 400-s stop and the first pass
    # it repeated (compare also takes out the M01's wait, which the control logged as ACTIVE);
    # its span is end_time_s, and a file that has only cycle_time_s (written before) is read
    # with that as its span
    csv = tmp_path / "middle.csv"
    r = _cli("import", "mtconnect", str(d / "middle.txt"), "-o", str(csv), "--program", str(d / "PART.NC"))
    assert r.returncode == 0, r.stderr
    back = read_measurement(str(csv))
    assert back.end_time == pytest.approx(m.end_time, abs=1e-3) and m.end_time > 400.0
    cyc = float(back.meta["cycle_time_s"])
    assert cyc < m.end_time - 400.0 and "without" in r.stderr
    assert cyc == pytest.approx(c["measured"] + WAIT, abs=0.01)  # (the M01 wait was logged ACTIVE)


def test_a_run_cut_by_a_restart_with_no_stop_logged_ends_where_the_block_number_went_back(setup, tmp_path):
    # a logger that records no stop: the run goes to line 7 or so, then the block number is back
    # at 0 and the program loaded again, then ACTIVE — what came before that ACTIVE is the new
    # run's preamble: the cut run got to where it was before the block number went back, and the
    # complete run compares as the log of it alone does
    d, tw, prog = setup
    ev = _events(_log(tw, prog))
    head = [(t, r) for t, r in ev if t <= 6.0]
    t_go = head[-1][0] + 5.0
    again = [(t + t_go + 2.0, r) for t, r in ev]
    pre = [(t_go, "Program_Name_Running|PART.NC"), (t_go + 0.5, "Block_Number|0")]
    text = "\n".join(f"{_ts(t)}|{r}" for t, r in head + pre + again) + "\n"
    (d / "cut.txt").write_text(text)
    (d / "alone.txt").write_text(_log(tw, prog))
    m = read_measurement(str(d / "cut.txt"))
    assert [r.complete for r in m.runs] == [False, True] and m.meta["run"] == "2"
    reached = max(int(r.split("|")[1]) for t, r in head if r.startswith("Block_Number|"))
    assert reached > 5 and m.runs[0].reached == reached  # (not the 0 the new run began with)
    assert "started again from the program's start" in m.runs[0].ended
    alone = read_measurement(str(d / "alone.txt"))
    assert m.end_time == pytest.approx(alone.end_time, abs=1e-6)
    assert np.array_equal(m.line, alone.line) and np.allclose(m.t, alone.t)
    # the loop commands list the runs and take --run
    r = _cli("compare", str(d / "PART.NC"), str(d / "cut.txt"), "--json")
    assert r.returncode == 0, r.stderr
    assert "run 1: PART.NC, incomplete (stopped at line" in r.stderr and "the run chosen" in r.stderr
    r1 = _cli("compare", str(d / "PART.NC"), str(d / "cut.txt"), "--run", "1")
    assert r1.returncode == 2 and "incomplete" in r1.stderr and "--partial" in r1.stderr
    r1 = _cli("compare", str(d / "PART.NC"), str(d / "cut.txt"), "--run", "1", "--partial", "--json")
    assert r1.returncode == 0, r1.stderr
    assert json.loads(r1.stdout)["cycle_time"]["measured"] < json.loads(r.stdout)["cycle_time"]["measured"]
    r3 = _cli("compare", str(d / "PART.NC"), str(d / "cut.txt"), "--run", "3")
    assert r3.returncode == 2 and "--run 3: the log has 2 run(s)" in r3.stderr
    # calibrate: --run names a run of its first log; a measurement file to validate on has one
    r = _cli("import", "mtconnect", str(d / "alone.txt"), "-o", str(tmp_path / "alone.csv"))
    assert r.returncode == 0, r.stderr
    r = _cli("calibrate", str(d / "PART.NC"), str(d / "cut.txt"), "--run", "2", "--fit", "block-time", "--validate",
             str(tmp_path / "alone.csv"), "-o", str(tmp_path / "t.toml"))
    assert r.returncode == 0, r.stderr


def _sampled_log(tw, prog, every: float = 0.2, feed_override: float | None = None) -> str:
    """``_log`` with the path feed also sampled every ``every`` s, as a real agent samples it
    (the Hurco logs: 0.15-0.2 s); with ``feed_override``, a Feed_Override item at that value."""
    ev = _events(_log(tw, prog))
    tr = _truth(tw, prog)
    t, line, f = np.asarray(tr.t), np.asarray(tr.line), np.asarray(tr.signal("feed")) / 60.0
    # the log's times: the M01 wait shifts everything after line 14
    t14 = float(t[np.argmax(line >= 15)]) if (line >= 15).any() else math.inf
    extra = [(float(x) + (WAIT if x >= t14 else 0.0), f"Feed_Rate|{float(v):.6f}")
             for x, v in zip(t[::max(1, int(every / (t[1] - t[0])))], f[::max(1, int(every / (t[1] - t[0])))])]
    head = [(-0.4, f"Feed_Override|{feed_override:.6f}")] if feed_override is not None else []
    done = [e for e in ev if "PROGRAM_COMPLETED" in e[1]]
    body = sorted([e for e in ev if "PROGRAM_COMPLETED" not in e[1]] + extra + head, key=lambda e: e[0])
    return "\n".join(f"{_ts(x)}|{r}" for x, r in body + done) + "\n"


def test_an_unlogged_feed_override_is_found_ranked_and_calibrated(setup, tmp_path):
    from mtwin.effects import get

    d, tw, prog = setup
    fast = tw.with_effects(get("feed-override")(feed=130.0))
    (d / "ovr.txt").write_text(_sampled_log(fast, prog))
    # compare: the log's own feed against the programmed F
    r = _cli("compare", str(d / "PART.NC"), str(d / "ovr.txt"), "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    x = doc["logged_against_programmed"]["feed"]
    assert x["suspect"] and x["ratio"] == pytest.approx(1.30, abs=0.02) and x["samples"] >= 20
    assert "feed moves ran at 1.30× the programmed F" in r.stderr
    # beside it, the same estimator on a log of the twin's own run (no override): 1, kind by kind
    assert x["twin"]["ratio"] == pytest.approx(1.0, abs=0.01) and x["twin"]["samples"] >= 20
    kinds = {k["kind"]: k for k in doc["blocks"]["by_kind"]}
    assert any(k["logged_over_programmed_feed"] is not None for k in kinds.values())
    for k in kinds.values():
        if k["logged_over_programmed_feed"] is not None:
            assert k["logged_over_programmed_feed"] == pytest.approx(1.30, abs=0.03)
            assert k["twin_logged_over_programmed_feed"] == pytest.approx(1.0, abs=0.02)
    before = doc["cycle_time"]["relative_error"]
    assert abs(before) > 0.05
    # diagnose: the feed-override effect first
    r = _cli("diagnose", str(d / "PART.NC"), str(d / "ovr.txt"), "--json")
    assert r.returncode == 0, r.stderr
    cands = json.loads(r.stdout)["timing"]["candidates"]
    assert cands[0]["effect"] == "feed-override", [c["effect"] for c in cands]
    # with the evidence a person acts on: the ratio, its samples and blocks, its spread
    assert "the log's own feed: feed moves ran at 1.30× the programmed F over" in cands[0]["evidence"]
    # calibrate: recovered within 2 %, and the cycle time within 1 %
    out = tmp_path / "t.toml"
    r = _cli("calibrate", str(d / "PART.NC"), str(d / "ovr.txt"), "--fit", "feed-override", "-o", str(out), "--json")
    assert r.returncode == 0, r.stderr
    params = json.loads(r.stdout)["params"]
    assert params["effects.feed-override.feed"] == pytest.approx(130.0, rel=0.02)
    (entry,) = mtwin.loop.journal.read_journal(str(out))
    assert abs(entry["cycle_error_before"]["ovr.txt"]) > 0.05 and abs(entry["cycle_error_after"]["ovr.txt"]) < 0.01
    # the twin file says the value is the run's, not the machine's
    assert "an effective value of the run it was fitted to, not a machine property" in out.read_text()


def test_a_logged_feed_override_leaves_nothing_suspected(setup):
    from mtwin.effects import get

    d, tw, prog = setup
    fast = tw.with_effects(get("feed-override")(feed=130.0))
    (d / "ovr_logged.txt").write_text(_sampled_log(fast, prog, feed_override=130.0))
    r = _cli("compare", str(d / "PART.NC"), str(d / "ovr_logged.txt"), "--json")
    assert r.returncode == 0, r.stderr
    x = json.loads(r.stdout)["logged_against_programmed"]["feed"]
    assert not x["suspect"] and x["ratio"] == pytest.approx(1.0, abs=0.02)
    assert "the programmed F" not in r.stderr


def test_a_limit_the_log_never_shows_is_said_so_and_left_at_its_start(setup, tmp_path):
    # PART has no arcs: an arc limit is seen by no block and bounded by none, so the fit leaves
    # it where it started and says the log cannot tell it (not a value the search wandered to)
    d, tw, prog = setup
    (d / "noarcs.txt").write_text(_sampled_log(tw, prog))
    out = tmp_path / "t.toml"
    r = _cli("calibrate", str(d / "PART.NC"), str(d / "noarcs.txt"), "--fit", "arc-acceleration", "-o", str(out))
    assert r.returncode == 0, r.stderr
    assert "effects.arc-acceleration.acceleration = 2500 mm/s^2 (not identifiable from the signals fitted: left at " \
           "its start)" in " ".join(r.stderr.split())
    (entry,) = mtwin.loop.journal.read_journal(str(out))
    assert entry["not_identifiable"] == ["effects.arc-acceleration.acceleration"]


def test_feed_line_ends_find_a_wait_before_rapids_and_none_before_feed_moves():
    # a machine that stands 60 ms at the end of every feed line a rapid follows, logged every
    # ~0.19 s as the Hurco logs its line; held against a twin without the wait, the lines before a
    # rapid come out ~60 ms short and the same lines before a feed move do not (sampled alike,
    # so the sampling cancels); against the machine's own twin, neither row is off
    from mtwin.loop.asrun import feed_line_ends

    tw, prog, run, log = _waiting_machine()
    ends = feed_line_ends(prog, log, tw.simulate(prog, cutting=False))
    n, before_rapid, se = ends[("line", "rapid")]
    assert n >= 90 and before_rapid == pytest.approx(-0.06, abs=max(3 * se, 0.01)) and -before_rapid > 4 * se
    n, before_feed, se = ends[("line", "feed")]
    assert n >= 90 and abs(before_feed) < max(3 * se, 0.01)
    same = feed_line_ends(prog, log, run)
    assert all(abs(m) < max(3 * se, 0.01) for _, m, se in same.values()), same


def test_diagnose_says_what_the_line_ends_show_beside_the_wait_before_rapids():
    # the machine of the test above, diagnosed from the twin without the wait: feed-rapid-wait's
    # evidence holds the log's own line ends — straight lines a rapid follows ~60 ms longer on the
    # machine, those a feed move follows not.  (The block times alone cannot tell it from full
    # stops at this program's three corners a pass, which corner-slowdown fits as well: the line
    # ends can)
    import re

    from mtwin.loop import timing as T

    tw, prog, _, log = _waiting_machine()
    case = T.timing_case(tw, prog, log)
    d = T.diagnose_timing(tw, [case], candidates=["feed-rapid-wait"])
    top = d["candidates"][0]
    rapid, feed = re.search(r"a rapid follows take ([+-]\d+) ± \d+ ms.*feed move follows ([+-]\d+) ±",
                            top["evidence"]).groups()
    assert 40 <= int(rapid) <= 80 and abs(int(feed)) <= 15, top["evidence"]


def _waiting_machine():
    """(the default twin, a program of 100 passes, the run of a machine that stands 60 ms where
    a feed move ends and a rapid follows, its log sampled every ~0.19 s as the Hurco's)."""
    from mtwin.loop.asrun import twin_log
    from mtwin.loop.measurement import Measurement

    lines = ["G21 G90 G94", "G0 X0 Y0 Z1"]
    for i in range(100):
        y = 3.0 * i
        lines += [f"G0 X0 Y{y:g} Z1", "G1 Z0 F600", "G1 X20", f"G1 Y{y + 1:g}", "G1 X0", "G0 Z60"]
    lines.append("M30")
    tw = mtwin.Twin()
    prog = tw.load(("\n".join(lines) + "\n").encode(), path="ends.nc")
    run = tw.with_params({"controller.feed_rapid_wait": 0.06}).simulate(prog, cutting=False)
    grid = Measurement("grid", np.arange(0.0, float(run.t[-1]), 0.19), {}, np.zeros(0, np.int64))
    return tw, prog, run, twin_log(run, grid, seed=99)


def test_a_last_record_without_its_line_end_is_read_and_said_so(tmp_path):
    # a whole record may have lost digits of its value (Block_Number 18 of 1827): read as it
    # stands, with a note; with its line end, or ending in a word, no note
    from mtwin.loop.mtconnect import read_shdr

    head = "2017-02-02T18:26:44.0Z|Block_Number|10\n2017-02-02T18:26:45.0Z|Program_Status|ACTIVE\n"
    p = tmp_path / "a.txt"
    p.write_text(head + "2017-02-02T18:26:46.0Z|Block_Number|18")
    ev = read_shdr(str(p))
    assert ev[-1].value == "18" and "no line end" in ev.cut_last and "18" in ev.cut_last
    p.write_text(head + "2017-02-02T18:26:46.0Z|Block_Number|18\n")
    assert getattr(read_shdr(str(p)), "cut_last", "") == ""
    p.write_text(head + "2017-02-02T18:26:46.0Z|Program_Status|STOPPED")
    assert getattr(read_shdr(str(p)), "cut_last", "") == ""


# --- runs as the program says they ran (a trial of hostile shop logs) -----------------------

def _text(ev) -> str:
    return "\n".join(f"{_ts(t)}|{r}" for t, r in ev) + "\n"


def _json_cycle(r) -> dict:
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)["cycle_time"]


def test_a_reset_to_ready_is_not_a_finished_run(setup, tmp_path):
    # READY also follows a program's end, so the state alone cannot tell: the lines the run
    # reported can — a run that never reached the program's last moves was reset
    d, tw, prog = setup
    ev = _events(_log(tw, prog))
    head = [(t, r) for t, r in ev if t <= 6.0]
    t_go = head[-1][0] + 30.0
    text = _text(head + [(head[-1][0] + 0.1, "Program_Status|READY")] + [(t + t_go, r) for t, r in ev])
    (tmp_path / "ready.txt").write_text(text)
    m = read_measurement(str(tmp_path / "ready.txt"), program=prog)
    assert [r.complete for r in m.runs] == [False, True] and m.meta["run"] == "2"
    assert "reset, not finished" in m.runs[0].ended and "READY" in m.runs[0].ended
    # without the program the state is all there is
    assert [r.complete for r in read_measurement(str(tmp_path / "ready.txt")).runs] == [True, True]
    r = _cli("compare", str(d / "PART.NC"), str(tmp_path / "ready.txt"), "--run", "1")
    assert r.returncode == 2 and "incomplete" in r.stderr and "--partial" in r.stderr
    assert "reset, not finished" in r.stderr


def test_a_run_that_starts_in_the_middle_is_refused_or_compared_from_its_first_line(setup, tmp_path):
    # a logger started late (or a restart from a block after a reset): not the program's cycle;
    # --partial compares it from its first line, the twin taking the run as under way (its tool
    # in the spindle, at speed) — no tool change or run-up the machine never did
    d, tw, prog = setup
    ev = _events(_log(tw, prog))
    k = next(i for i, (t, r) in enumerate(ev) if r.startswith("Block_Number|15"))
    t0 = ev[k][0]
    late = [(-0.5, "Program_Name_Running|PART.NC"), (0.0, "Program_Status|ACTIVE")] + \
           [(t - t0, r) for t, r in ev[k:]]
    (tmp_path / "late.txt").write_text(_text(late))
    m = read_measurement(str(tmp_path / "late.txt"), program=prog)
    assert m.complete is False and m.meta["started_at"] == "15" and "started at line 15" in m.runs[0].ended
    r = _cli("compare", str(d / "PART.NC"), str(tmp_path / "late.txt"))
    assert r.returncode == 2 and "starts at line 15" in r.stderr and "--partial" in r.stderr
    r = _cli("compare", str(d / "PART.NC"), str(tmp_path / "late.txt"), "--partial", "--json")
    c = _json_cycle(r)
    assert "compared from that line on" in r.stderr
    assert abs(c["simulated"] - c["measured"]) < 0.1, c  # (the log's own run: ~exact)


def test_a_restart_in_the_middle_with_no_state_logged_counts_no_time_twice(setup, tmp_path):
    # the block number jumps back from the line it was at to line 11 with no stop logged: the
    # program never goes back there itself, so it is a restart, and the first pass is taken out
    d, tw, prog = setup
    ev = _events(_log(tw, prog))
    head = [(t, r) for t, r in ev if t <= 22.0 and "PROGRAM_COMPLETED" not in r]
    k = next(i for i, (t, r) in enumerate(ev) if r.startswith("Block_Number|11"))
    t_go = head[-1][0] + 40.0
    text = _text(head + [(t - ev[k][0] + t_go, r) for t, r in ev[k:]])
    (tmp_path / "nostate.txt").write_text(text)
    m = read_measurement(str(tmp_path / "nostate.txt"), program=prog)
    (t, was, now), = m.runs[0].restarts
    assert now == 11 and was > 11 and m.runs[0].complete
    r = _cli("compare", str(d / "PART.NC"), str(tmp_path / "nostate.txt"), "--json")
    c = _json_cycle(r)
    assert abs(c["measured"] - c["simulated"]) / c["simulated"] < 0.01, c
    assert "restarted in the middle" in r.stderr and "no time is counted twice" in r.stderr


def test_a_restart_from_the_start_with_no_state_logged_is_a_new_run(setup, tmp_path):
    # no status at all: the block number back at 0 after the machine stood, then the program
    # again — found with the program, and without it (the machine stood 40 s)
    d, tw, prog = setup
    ev = _events(_log(tw, prog))
    head = [(t, r) for t, r in ev if t <= 8.0]
    t_go = head[-1][0] + 40.0
    again = [(t + t_go, r) for t, r in ev if not r.startswith(("Program_Status|ACTIVE", "Program_Name"))]
    text = _text(head + [(t_go - 1.0, "Block_Number|0")] + again)
    (tmp_path / "again.txt").write_text(text)
    for m in (read_measurement(str(tmp_path / "again.txt"), program=prog),
              read_measurement(str(tmp_path / "again.txt"))):
        assert [r.complete for r in m.runs] == [False, True] and "no stop or end state logged" in m.runs[0].ended
        assert m.runs[0].reached > 5
        truth = _truth(tw, prog).summary.cycle_time + WAIT
        assert m.end_time == pytest.approx(truth, abs=0.5)


def test_an_aborted_run_ends_where_the_block_number_went_back(setup, tmp_path):
    # what the control reports of the new run before its ACTIVE (line 0, its first line) is
    # not the aborted run's: --run 1 holds only the lines it ran, and its time ends at the stop
    d, tw, prog = setup
    ev = _events(_log(tw, prog))
    head = [(t, r) for t, r in ev if t <= 8.0]
    t_stop = head[-1][0] + 0.01
    t_go = t_stop + 20.0
    again = [(t + t_go, r) for t, r in ev if t >= 0]
    pre = [(t_stop, "Program_Status|STOPPED"), (t_stop + 5.0, "Block_Number|0"), (t_stop + 5.1, "Block_Number|4")]
    (tmp_path / "abort.txt").write_text(_text(head + pre + again))
    m = read_measurement(str(tmp_path / "abort.txt"), run=1, program=prog)
    reached = m.runs[0].reached
    assert reached > 5 and int(m.line[m.line > 0][-1]) == reached
    assert m.end_time < t_stop + 5.0 + 1e-6
    m2 = read_measurement(str(tmp_path / "abort.txt"), program=prog)
    assert m2.meta["run"] == "2" and int(m2.line[m2.line > 0][0]) == 4


def test_timestamps_keep_their_zones(setup, tmp_path):
    # the same instants written in +01:00 for the first half and +02:00 for the second (a
    # daylight-saving change, or two adapters) read as the log in UTC does
    d, tw, prog = setup
    text = _log(tw, prog)
    lines = text.splitlines()
    out = []
    for i, ln in enumerate(lines):
        ts, rest = ln.split("|", 1)
        t = datetime.strptime(ts[:26], "%Y-%m-%dT%H:%M:%S.%f").replace(tzinfo=timezone.utc)
        zone = timezone(timedelta(hours=1 if i < len(lines) // 2 else 2))
        out.append(t.astimezone(zone).isoformat(timespec="microseconds") + "|" + rest)
    (tmp_path / "utc.txt").write_text(text)
    (tmp_path / "zones.txt").write_text("\n".join(out) + "\n")
    a, b = (read_measurement(str(tmp_path / f)) for f in ("utc.txt", "zones.txt"))
    assert b.end_time == pytest.approx(a.end_time, abs=1e-6) and np.allclose(a.t, b.t)


def test_an_override_at_zero_holds_the_machine_and_is_taken_out(setup, tmp_path):
    # the operator turns the feed override to 0 % for 60 s inside a feed line: a feed hold in
    # all but name — its time is the operator's, and the line runs at the override it resumed at
    d, tw, prog = setup
    ev = _events(_log(tw, prog))
    k = next(i for i, (t, r) in enumerate(ev) if r.startswith("Block_Number|12"))
    t_hold = ev[k][0] + 0.3
    ev2 = [(-0.4, "Feed_Override|100.000000")] + [(t if t < t_hold else t + 60.0, r) for t, r in ev] + \
          [(t_hold, "Feed_Override|0.000000"), (t_hold + 0.05, "Feed_Rate|0.000000"),
           (t_hold + 60.0, "Feed_Override|100.000000")]
    ev2.sort(key=lambda x: x[0])
    (tmp_path / "ovr0.txt").write_text(_text(ev2))
    r = _cli("compare", str(d / "PART.NC"), str(tmp_path / "ovr0.txt"), "--json")
    c = _json_cycle(r)
    assert abs(c["measured"] - c["simulated"]) / c["simulated"] < 0.01, c
    assert "an override at 0 % held the machine for 60.0 s" in r.stderr


def test_a_standstill_nothing_logged_explains_is_told(setup, tmp_path):
    # the machine stood 60 s inside a feed line and the log says nothing of it: not model error
    d, tw, prog = setup
    ev = _events(_log(tw, prog))
    k = next(i for i, (t, r) in enumerate(ev) if r.startswith("Block_Number|12"))
    t_hold = ev[k][0] + 0.3
    (tmp_path / "stood.txt").write_text(_text([(t if t < t_hold else t + 60.0, r) for t, r in ev]))
    r = _cli("compare", str(d / "PART.NC"), str(tmp_path / "stood.txt"))
    assert r.returncode == 0, r.stderr
    assert "line 12 took 6" in r.stderr and "with no hold or stop logged: the machine stood" in " ".join(r.stderr.split())


def _sub_events(tmp_path):
    (tmp_path / "PART.NC").write_text(SUB)
    tw = mtwin.Twin()
    prog = tw.load(str(tmp_path / "PART.NC"))
    text, _ = _sub_log(tw, prog, second_at=100.0)
    return tw, prog, _events(text)


def test_a_subprograms_return_reported_at_a_line_without_a_move_is_no_restart(tmp_path):
    # the log reports the M99 (no move) before the main program's next line: the program's own
    # jump back, not a restart, though neither end is a move line
    tw, prog, ev = _sub_events(tmp_path)
    k = next(i for i, (t, r) in enumerate(ev) if r.startswith("Block_Number|13"))
    ev = ev[:k + 1] + [(ev[k][0] + 0.05, "Block_Number|14")] + ev[k + 1:]
    (tmp_path / "m99.txt").write_text(_text(ev))
    m = read_measurement(str(tmp_path / "m99.txt"), program=prog)
    assert len(m.runs) == 1 and m.runs[0].complete and not m.runs[0].restarts
    r = _cli("compare", str(tmp_path / "PART.NC"), str(tmp_path / "m99.txt"), "--json")
    c = _json_cycle(r)
    assert abs(c["measured"] - c["simulated"]) / c["simulated"] < 0.01, c


def test_a_restart_in_a_subprograms_second_call_repeats_only_that_call(tmp_path):
    # stopped in the second call and resumed at the subprogram's first line: the repeated pass
    # began where the run last entered that line, not at the first call
    tw, prog, ev = _sub_events(tmp_path)
    calls = [i for i, (t, r) in enumerate(ev) if r.startswith(f"Block_Number|{SUB_RAPID}")]
    stop = next(i for i in range(calls[1], len(ev)) if ev[i][1].startswith("Block_Number|12"))
    t_stop = ev[stop][0] + 0.3
    head = ev[:stop + 1] + [(t_stop, "Program_Status|STOPPED")]
    t_go = t_stop + 20.0
    again = [(t - ev[calls[1]][0] + t_go, r) for t, r in ev[calls[1]:]]
    (tmp_path / "mid.txt").write_text(_text(head + [(t_go, "Program_Status|ACTIVE")] + again))
    m = read_measurement(str(tmp_path / "mid.txt"), program=prog)
    (t, was, now), = m.runs[0].restarts
    assert now == SUB_RAPID and was == 12
    r = _cli("compare", str(tmp_path / "PART.NC"), str(tmp_path / "mid.txt"), "--json")
    c = _json_cycle(r)
    assert abs(c["measured"] - c["simulated"]) / c["simulated"] < 0.01, c


def test_an_override_at_zero_inside_a_logged_stop_is_not_taken_out_twice(setup, tmp_path):
    # the operator turns the feed override to 0 during an M01 stop the control logged: the
    # stop's time is taken out once
    d, tw, prog = setup
    ev = _events(_log(tw, prog, status_stop=True))
    t_stop = next(t for t, r in ev if r.endswith("OPTIONAL_STOP"))
    ev2 = sorted(ev + [(-0.4, "Feed_Override|100.000000"), (t_stop + 1.0, "Feed_Override|0.000000"),
                       (t_stop + 1.0, "Feed_Rate|0.000000"), (t_stop + WAIT - 0.5, "Feed_Override|100.000000")],
                 key=lambda x: x[0])
    (tmp_path / "both.txt").write_text(_text(ev2))
    r = _cli("compare", str(d / "PART.NC"), str(tmp_path / "both.txt"), "--json")
    c = _json_cycle(r)
    assert abs(c["measured"] - c["simulated"]) / c["simulated"] < 0.01, c


def _line_reports(path, text: str) -> tuple:
    """(the program written to ``path``, a report of every line the default twin enters, as
    (s, "Block_Number|N"), its cycle time s)."""
    path.write_text(text)
    tw = mtwin.Twin()
    prog = tw.load(str(path))
    tr = tw.simulate(prog, cutting=False)
    t, line = np.asarray(tr.t), np.asarray(tr.line)
    reports = [(float(t[k]), f"Block_Number|{int(line[k])}")
               for k in np.flatnonzero(np.r_[True, line[1:] != line[:-1]]) if line[k] > 0]
    return prog, reports, tr.summary.cycle_time


M99_MAIN = "".join(PROGRAM.splitlines(True)[:8]) + "G1 Y40\nG0 Z50\nM99\n%\n"  # (PROGRAM's start, run again)


def test_each_pass_of_a_program_that_runs_again_is_a_complete_run(tmp_path):
    # an M99 main program runs again from its start: a pass that reached the program's end is a
    # finished run (not an aborted one), and it lasts until the next pass begins
    prog, one, cyc = _line_reports(tmp_path / "PART.NC", M99_MAIN)
    ev = [(-1.0, "Program_Name_Running|PART.NC"), (0.0, "Program_Status|ACTIVE")] + one + \
         [(x + cyc, r) for x, r in one] + [(2 * cyc, "Program_Status|READY")]
    (tmp_path / "m99.txt").write_text(_text(ev))
    m = read_measurement(str(tmp_path / "m99.txt"), run=1, program=prog)
    # (the last pass ends in a reset, at a moment the log does not place within it: not complete)
    assert [r.complete for r in m.runs] == [True, False] and "M99" in m.runs[1].ended
    assert m.end_time == pytest.approx(cyc, abs=1e-3)
    # reset 0.5 s after the last pass's last line began (within its last move): the default is
    # the pass that ran on into the next, not the cut one
    last = max(x for x, r in one)
    (tmp_path / "early.txt").write_text(_text([x for x in ev if x[0] < 2 * cyc] + [(cyc + last + 0.5,
                                                                                   "Program_Status|READY")]))
    m = read_measurement(str(tmp_path / "early.txt"), program=prog)
    assert m.meta["run"] == "1" and m.end_time == pytest.approx(cyc, abs=1e-3)
    # one pass, reset: refused, and said why
    (tmp_path / "one.txt").write_text(_text([x for x in ev if x[0] < cyc] + [(cyc, "Program_Status|READY")]))
    r = _cli("compare", str(tmp_path / "PART.NC"), str(tmp_path / "one.txt"))
    assert r.returncode == 2 and "runs again by M99 until reset" in r.stderr, r.stderr


def test_a_reset_is_told_where_the_block_numbers_are_n_words(setup, tmp_path):
    # a control that logs N words: the program's lines read as its N words, so a reset to
    # READY is told from them as from lines
    import re

    d, tw, prog = setup
    numbered = "\n".join(ln if ln.startswith(("%", "O")) or not ln else f"N{10 * i} {ln}"
                         for i, ln in enumerate(PROGRAM.splitlines(), 1)) + "\n"
    (tmp_path / "PART.NC").write_text(numbered)
    ev = _events(_log(tw, prog))
    head = [(t, r) for t, r in ev if t <= 6.0]
    t_go = head[-1][0] + 30.0
    log = head + [(head[-1][0] + 0.1, "Program_Status|READY")] + [(t + t_go, r) for t, r in ev]
    n = [(t, re.sub(r"Block_Number\|(\d+)", lambda m: f"Block_Number|{10 * int(m.group(1))}", r)) for t, r in log]
    (tmp_path / "n.txt").write_text(_text(n))
    r = _cli("import", "mtconnect", str(tmp_path / "n.txt"), "--run", "1", "--block-is", "n", "--program",
             str(tmp_path / "PART.NC"), "-o", str(tmp_path / "m.csv"))
    assert r.returncode == 0, r.stderr
    assert "reset, not finished" in r.stderr and "# complete: no" in (tmp_path / "m.csv").read_text()
    assert "reached N" in r.stderr and "reached line" not in r.stderr  # (the log's numbers, as the log has them)


def test_a_renamed_program_is_still_read_against(setup, tmp_path):
    # the log names PART.NC, the file is OTHER.NC (--any-program): the runs are still judged
    # by the program's lines — a reset to READY is not a finish
    d, tw, prog = setup
    (tmp_path / "OTHER.NC").write_text(PROGRAM)
    ev = _events(_log(tw, prog))
    head = [(t, r) for t, r in ev if t <= 6.0]
    t_go = head[-1][0] + 30.0
    (tmp_path / "ready.txt").write_text(_text(head + [(head[-1][0] + 0.1, "Program_Status|READY")]
                                              + [(t + t_go, r) for t, r in ev]))
    r = _cli("compare", str(tmp_path / "OTHER.NC"), str(tmp_path / "ready.txt"), "--any-program", "--run", "1")
    assert r.returncode == 2 and "reset, not finished" in r.stderr


def test_a_run_whose_program_name_is_not_logged_is_not_taken_by_default(setup, tmp_path):
    # PART.NC ran, then OTHER.NC was loaded (its name logged only for editing) and a run with no
    # running name followed: the names cannot tell which program it was — it is listed with
    # both, and the run of certain name is compared
    d, tw, prog = setup
    ev = _events(_log(tw, prog))
    t_go = ev[-1][0] + 20.0
    second = [(t + t_go, r) for t, r in ev if not r.startswith("Program_Name")]
    text = _text(ev + [(t_go - 5.0, "Program_Name_Editing|OTHER.NC")] + second)
    (tmp_path / "two.txt").write_text(text)
    m = read_measurement(str(tmp_path / "two.txt"), program=prog)
    assert [r.other_name for r in m.runs] == ["", "OTHER.NC"] and m.meta["run"] == "1"
    assert "or OTHER.NC" in m.runs[1].describe()


def test_an_adapter_that_reconnects_leaves_one_run_with_a_gap(setup, tmp_path):
    # the control UNAVAILABLE for 30 s and ACTIVE again on reconnect, the block number gone on:
    # one run, nothing taken out (the machine ran), the gap said
    d, tw, prog = setup
    ev = _events(_log(tw, prog))
    t0, t1 = 10.0, 40.0
    gap = [(t, r) for t, r in ev if not t0 < t < t1] + [(t0, "Program_Status|UNAVAILABLE"),
                                                        (t1, "Program_Status|ACTIVE")]
    gap.sort(key=lambda x: x[0])
    (tmp_path / "gap.txt").write_text(_text(gap))
    m = read_measurement(str(tmp_path / "gap.txt"), program=prog)
    assert len(m.runs) == 1 and m.runs[0].complete and m.runs[0].gaps
    truth = _truth(tw, prog).summary.cycle_time + WAIT
    assert m.end_time == pytest.approx(truth, abs=0.5)
    r = _cli("compare", str(d / "PART.NC"), str(tmp_path / "gap.txt"))
    assert r.returncode == 0 and "no data" in r.stderr and "UNAVAILABLE" in r.stderr


def test_a_state_word_cut_short_is_left_out(setup, tmp_path):
    d, tw, prog = setup
    text = _log(tw, prog).rstrip("\n")
    cut = text[:text.rindex("PROGRAM_COMPLETED") + 1]  # "…|Program_Status|P", no newline
    (tmp_path / "cut.txt").write_text(cut)
    r = _cli("compare", str(d / "PART.NC"), str(tmp_path / "cut.txt"))
    assert r.returncode == 2 and "its state 'P' is none the control logs" in r.stderr and "--partial" in r.stderr


def test_a_feed_off_by_a_scale_the_times_deny_is_no_override(setup, tmp_path):
    # the log's feed values 1.3× F but its times the twin's: a unit or scale, not an override
    d, tw, prog = setup
    ev = _events(_sampled_log(tw, prog))
    scaled = [(t, f"Feed_Rate|{float(r.split('|')[1]) * 1.3:.6f}" if r.startswith("Feed_Rate|") else r) for t, r in ev]
    (tmp_path / "scaled.txt").write_text(_text(scaled))
    r = _cli("compare", str(d / "PART.NC"), str(tmp_path / "scaled.txt"))
    assert r.returncode == 0, r.stderr
    assert "unit or scale is off" in r.stderr and "diagnose ranks" not in r.stderr


def test_a_reset_and_a_restart_in_the_middle_are_one_run(setup, tmp_path):
    # a control's program restart: reset (READY) at line 12 or so, the block to go on from searched
    # (line 11, logged before the cycle start) and the cycle started there — the part cut by two
    # runs, read as one run restarted in the middle: no time counted twice, the wait left out
    d, tw, prog = setup
    ev = _events(_log(tw, prog))
    t12 = next(t for t, r in ev if r.startswith("Block_Number|12"))
    head = [(t, r) for t, r in ev if t <= t12]
    t_reset = t12 + 0.5  # (the program's last moves, lines 13 on, not reached)
    k = next(i for i, (t, r) in enumerate(ev) if r.startswith("Block_Number|11"))
    shift = t_reset + 300.0 - ev[k][0]
    log = head + [(t_reset, "Program_Status|READY"), (t_reset + 299.0, "Block_Number|11"),
                  (t_reset + 300.0, "Program_Status|ACTIVE")] + [(t + shift, r) for t, r in ev[k:]]
    (tmp_path / "reset.txt").write_text(_text(log))
    m = read_measurement(str(tmp_path / "reset.txt"), program=prog)
    assert len(m.runs) == 1 and m.runs[0].complete, [r.describe() for r in m.runs]
    (t, was, now), = m.runs[0].restarts
    assert now == 11 and was > 11
    # the same as the restart with a stop logged and no reset
    (tmp_path / "stopped.txt").write_text(_restarted(tw, prog, stop_after=t12, wait=300.49, back_to=11))
    stopped = read_measurement(str(tmp_path / "stopped.txt"), program=prog)
    seq = [int(x) for x in m.line[m.line > 0]]
    assert all(b >= a for a, b in zip(seq, seq[1:]))
    r = _cli("compare", str(d / "PART.NC"), str(tmp_path / "reset.txt"), "--json")
    c = _json_cycle(r)
    assert abs(c["measured"] - c["simulated"]) / c["simulated"] < 0.01, c
    assert c["measured"] == pytest.approx(_json_cycle(_cli("compare", str(d / "PART.NC"), str(tmp_path / "stopped.txt"),
                                                            "--json"))["measured"], abs=0.05)
    assert "restarted in the middle" in r.stderr and "no time is counted twice" in r.stderr
    # restarted from the start instead: an aborted run and a new one, as before
    again = head + [(t_reset, "Program_Status|READY")] + [(t + t_reset + 300.0, r) for t, r in ev]
    (tmp_path / "again.txt").write_text(_text(again))
    assert [r.complete for r in read_measurement(str(tmp_path / "again.txt"), program=prog).runs] == [False, True]
    assert stopped.runs[0].complete
    # the program rewound (block 0) at the reset, at its moment or just before it: the same run
    for dt in (0.0, -0.01):
        zero = head + [(t_reset + dt, "Block_Number|0")] + log[len(head):]
        (tmp_path / "zero.txt").write_text(_text(sorted(zero, key=lambda x: x[0])))
        c0 = _json_cycle(_cli("compare", str(d / "PART.NC"), str(tmp_path / "zero.txt"), "--json"))
        assert c0["measured"] == pytest.approx(c["measured"], abs=0.05), (dt, c0)
    # the log went blind between (UNAVAILABLE): what ran then is not known — two runs
    blind = head + [(t_reset, "Program_Status|READY"), (t_reset + 1.0, "Program_Status|UNAVAILABLE")] + log[len(head) + 1:]
    (tmp_path / "blind.txt").write_text(_text(blind))
    assert len(read_measurement(str(tmp_path / "blind.txt"), program=prog).runs) == 2


SUB_CALLED = PROGRAM.replace("M01\n", "M98 P2000\n").replace("M30\n%\n", "M30\nO2000\nG1 X200 F300\nG1 X100\nG0 Z5\nM99\n%\n")


def test_a_restart_after_a_subprogram_it_stopped_in_is_not_joined(tmp_path):
    # reset in a subprogram (line 22, called from line 14) and started again at main line 16:
    # lower in lines, later in the program's own order — lines 15 and 23 never ran; two runs
    prog, ev, _ = _line_reports(tmp_path / "SUB.NC", SUB_CALLED)
    t22 = next(x for x, r in ev if r == "Block_Number|22")
    k16 = next(i for i, (x, r) in enumerate(ev) if r == "Block_Number|16")
    shift = t22 + 65.0 - ev[k16][0]
    log = ([(-1.0, "Program_Name_Running|SUB.NC"), (0.0, "Program_Status|ACTIVE")] + [x for x in ev if x[0] <= t22]
           + [(t22 + 5.0, "Program_Status|READY"), (t22 + 64.99, "Program_Status|ACTIVE")]
           + [(x + shift, r) for x, r in ev[k16:]] + [(ev[-1][0] + shift + 0.1, "Program_Status|PROGRAM_COMPLETED")])
    (tmp_path / "skip.txt").write_text(_text(log))
    m = read_measurement(str(tmp_path / "skip.txt"), run=1, program=prog)
    assert [r.complete for r in m.runs] == [False, False] and not m.runs[0].restarts


def test_a_clock_glitch_is_told_at_its_record(setup, tmp_path):
    # one record an hour ahead of those either side of it: the error is at that record
    d, tw, prog = setup
    lines = _log(tw, prog).splitlines()
    k = len(lines) // 2
    lines[k] = lines[k].replace(lines[k][11:13], f"{int(lines[k][11:13]) + 1:02d}", 1)
    (tmp_path / "glitch.txt").write_text("\n".join(lines) + "\n")
    r = _cli("compare", str(d / "PART.NC"), str(tmp_path / "glitch.txt"))
    assert r.returncode == 2 and f"glitch.txt:{k + 1}:1:" in r.stderr and "clock glitch" in r.stderr, r.stderr


def test_records_a_little_out_of_order_are_read_in_time_order(setup, tmp_path):
    # an agent's buffers flushed out of turn: three records written after one up to 0.3 s later
    # are read in time order, and said so; a clock set back a minute is still an error
    d, tw, prog = setup
    lines = _sampled_log(tw, prog).splitlines()
    t = [x for x, _ in _events("\n".join(lines))]
    k = next(i for i in range(len(lines) // 2, len(lines) - 4)
             if "Block_Number" in lines[i + 3] and t[i] < t[i + 1] < t[i + 2] < t[i + 3] < t[i] + 0.8)
    swapped = lines[:k] + [lines[k + 3], lines[k], lines[k + 1], lines[k + 2]] + lines[k + 4:]
    (tmp_path / "swapped.txt").write_text("\n".join(swapped) + "\n")
    (tmp_path / "plain.txt").write_text("\n".join(lines) + "\n")
    m = read_measurement(str(tmp_path / "swapped.txt"))
    plain = read_measurement(str(tmp_path / "plain.txt"))
    assert "read in time order" in m.meta["reordered"] and "reordered" not in plain.meta
    assert np.array_equal(m.line, plain.line) and np.allclose(m.t, plain.t)
    r = _cli("compare", str(d / "PART.NC"), str(tmp_path / "swapped.txt"))
    assert r.returncode == 0 and "read in time order" in r.stderr, r.stderr
    back = lines[:k] + [lines[k].replace(lines[k][:4], "2016", 1)] + lines[k + 1:]
    (tmp_path / "back.txt").write_text("\n".join(back) + "\n")
    r = _cli("compare", str(d / "PART.NC"), str(tmp_path / "back.txt"))
    assert r.returncode == 2 and f"back.txt:{k + 1}:1:" in r.stderr and "out of order" in r.stderr, r.stderr


def test_a_runs_stops_are_counted_by_state():
    # single-block mode stops at every line: the run's one line counts them, not lists them
    from mtwin.loop.mtconnect import Run

    r = Run("PART.NC", 0, 10, True, stops=[(float(k), k + 0.5, "STOPPED") for k in range(1000)]
            + [(2000.0, 2001.0, "RESTART")])
    assert r.describe() == "PART.NC, complete, 1001 program stops (1000 STOPPED, 1 RESTART)"


def test_a_reset_among_the_last_moves_then_a_restart_is_one_run(setup, tmp_path):
    # reset in line 17 (one of the program's last moves, which a log may miss) and started
    # again from line 16: the restart says the run did not finish — one run, no time twice
    d, tw, prog = setup
    ev = _events(_log(tw, prog))
    t17 = next(t for t, r in ev if r.startswith("Block_Number|17"))
    head = [(t, r) for t, r in ev if t <= t17]
    k = next(i for i, (t, r) in enumerate(ev) if r.startswith("Block_Number|16"))
    shift = t17 + 60.0 - ev[k][0]
    log = head + [(t17 + 0.3, "Program_Status|READY"), (t17 + 60.0, "Program_Status|ACTIVE")] + \
        [(t + shift, r) for t, r in ev[k:]]
    (tmp_path / "late.txt").write_text(_text(log))
    m = read_measurement(str(tmp_path / "late.txt"), program=prog)
    assert len(m.runs) == 1 and m.runs[0].complete and m.runs[0].restarts
    c = _json_cycle(_cli("compare", str(d / "PART.NC"), str(tmp_path / "late.txt"), "--json"))
    assert abs(c["measured"] - c["simulated"]) / c["simulated"] < 0.01, c


def test_passes_split_where_the_return_and_the_next_pass_share_a_moment(tmp_path):
    # the M99's report and the next pass's first lines logged at one timestamp: still two passes
    prog, one, cyc = _line_reports(tmp_path / "PART.NC", M99_MAIN)
    ev = [(-1.0, "Program_Name_Running|PART.NC"), (0.0, "Program_Status|ACTIVE")] + one + \
        [(cyc, f"Block_Number|{M99_MAIN.count(chr(10)) - 1}")] + [(max(x, 0.0) + cyc, r) for x, r in one] + \
        [(2 * cyc - 0.5, "Program_Status|READY")]
    (tmp_path / "same.txt").write_text(_text(sorted(ev, key=lambda e: e[0])))
    m = read_measurement(str(tmp_path / "same.txt"), program=prog)
    assert [r.complete for r in m.runs] == [True, False] and m.meta["run"] == "1"
    assert m.end_time == pytest.approx(cyc, abs=1e-3)
    # through a measurement file, a refusal still says why the run is incomplete
    r = _cli("import", "mtconnect", str(tmp_path / "same.txt"), "--run", "2", "--program", str(tmp_path / "PART.NC"),
             "-o", str(tmp_path / "two.csv"))
    assert r.returncode == 0, r.stderr
    r = _cli("compare", str(tmp_path / "PART.NC"), str(tmp_path / "two.csv"))
    assert r.returncode == 2 and "runs again by M99 until reset" in r.stderr, r.stderr
