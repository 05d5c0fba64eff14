"""What a new user meets in the first hour (issue 9): per-line timing, no silent wrong output,
tools from program comments, the CLI's conventions (the kernels' tests are in test_kernels.py)."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

from conftest import REALDATA, SAMPLES
from test_cli import mtwin

WARNING = re.compile(r"^\S+?(:\d+:\d+)?: warning: ")


# ------------------------------------------------------------- where the time goes (point 6)

def test_a_very_short_move_is_far_below_nominal_and_says_why(tmp_path):
    f = tmp_path / "short.nc"
    f.write_text("G21 G90 G94\nG0 X0 Y0 Z0\nG1 X0.5 F3000\nG1 X200.5\nM30\n")
    r = mtwin("simulate", str(f), "--no-cutting", "--json")
    assert r.returncode == 0, r.stderr.decode()
    d = json.loads(r.stdout)
    pl = d["per_line"]
    i3, i4 = pl["line"].index(3), pl["line"].index(4)
    # 0.5 mm at 50 mm/s is 10 ms nominal; from standstill at 3000 mm/s^2 it takes far longer
    assert pl["nominal"][i3] == pytest.approx(0.5 / 50.0)
    assert pl["time"][i3] > 2.5 * pl["nominal"][i3]
    assert pl["reason"][i3].startswith("too short to reach its speed")
    # the long move runs close to nominal (200 mm at 50 mm/s)
    assert pl["nominal"][i4] == pytest.approx(4.0)
    assert pl["time"][i4] < 1.1 * pl["nominal"][i4]
    assert d["slowest_lines"][0]["line"] in (3, 4)
    # the table shows the lines that lose the most
    r = mtwin("simulate", str(f), "--no-cutting")
    table = " ".join(r.stderr.decode().split())  # rich wraps long cells
    assert "slowest lines" in table and "line 3 │ 0.0" in table


def test_per_line_times_add_up_to_the_cycle_time_and_the_trace_keeps_records():
    import mtwin as api

    tw = api.Twin()
    prog = tw.load(str(SAMPLES / "drilling.nc"))
    tr = tw.simulate(prog, cutting=False)
    pl = tr.summary.per_line
    assert pl.time.sum() == pytest.approx(tr.summary.cycle_time, rel=1e-9)
    # a canned cycle line makes several records; the trace says which one made each sample
    assert tr.record is not None and len(tr.record) == len(tr.t)
    moving = tr.record >= 0
    # a tool change's time is on its M6 line, while its record is the move it precedes
    m6 = [i + 1 for i, x in enumerate(prog.data.splitlines()) if re.search(rb"M0?6\b", x)]
    assert m6 and set(tr.line[moving & (prog.records["line"][np.maximum(tr.record, 0)] != tr.line)]) <= set(m6)
    moving &= ~np.isin(tr.line, m6)
    np.testing.assert_array_equal(prog.records["line"][tr.record[moving]], tr.line[moving])
    per_line_records = {}
    for li, ri in zip(tr.line[moving], tr.record[moving]):
        per_line_records.setdefault(int(li), set()).add(int(ri))
    assert max(len(v) for v in per_line_records.values()) >= 3  # a drilling line: rapid, feed, retract


# ------------------------------------------------------------------ silent wrong output (point 5)

def test_scale_writes_spindle_speeds_as_integers(tmp_path):
    out = tmp_path / "o.nc"
    r = mtwin("scale", str(SAMPLES / "pocket.nc"), "--feed", "0.9", "--spindle", "0.9", "-o", str(out))
    assert r.returncode == 0, r.stderr.decode()
    s_words = re.findall(rb"S[0-9.]+", out.read_bytes())
    assert s_words and all(b"." not in w for w in s_words)
    assert b"S7200" in out.read_bytes()


def test_scale_never_writes_a_feed_above_the_machine_maximum(tmp_path):
    out = tmp_path / "o.nc"
    r = mtwin("scale", str(SAMPLES / "pocket.nc"), "--feed", "1e9", "-o", str(out))
    assert r.returncode == 0, r.stderr.decode()
    msg = r.stderr.decode()
    assert "maximum cutting feed" in msg and re.search(r"pocket\.nc:\d+:1: warning: ", msg)
    feeds = [float(x) for x in re.findall(rb"F([0-9.]+)", out.read_bytes())]
    import mtwin as api

    assert max(feeds) == pytest.approx(api.Machine().max_cutting_feed)


@pytest.mark.parametrize("ext,magic", [("svg", b"<?xml"), ("png", b"\x89PNG"), ("pdf", b"%PDF")])
def test_plot_writes_the_format_its_name_asks_for(tmp_path, ext, magic):
    p = tmp_path / f"power.{ext}"
    r = mtwin("simulate", str(SAMPLES / "contour.nc"), "--plot", str(p))
    assert r.returncode == 0, r.stderr.decode()
    assert p.read_bytes().startswith(magic)


def test_plot_with_an_unknown_extension_is_refused_and_nothing_written(tmp_path):
    p = tmp_path / "power.jpg"
    r = mtwin("simulate", str(SAMPLES / "contour.nc"), "--plot", str(p))
    assert r.returncode == 2 and "--plot" in r.stderr.decode() and not p.exists()


def test_empty_and_motionless_programs(tmp_path):
    empty = tmp_path / "empty.nc"
    empty.write_text("")
    still = tmp_path / "still.nc"
    still.write_text("(setup only)\nG21 G90\nM30\n")
    out = tmp_path / "o.nc"
    for cmd in (("parse",), ("simulate",), ("scale", "--feed", "0.9", "-o", str(out))):
        r = mtwin(cmd[0], str(empty), *cmd[1:])
        assert r.returncode == 2 and "empty.nc:1:1: the program is empty" in r.stderr.decode(), cmd
    assert not out.exists()
    r = mtwin("parse", str(still))
    assert r.returncode == 0 and "still.nc: warning: the program has no motion" in r.stderr.decode()
    for cmd in (("simulate",), ("scale", "--feed", "0.9", "-o", str(out))):
        r = mtwin(cmd[0], str(still), *cmd[1:])
        assert r.returncode == 2 and "no motion" in r.stderr.decode(), cmd
    assert not out.exists()


def test_a_program_that_never_meets_the_stock_says_so(tmp_path):
    f = tmp_path / "air.nc"
    f.write_text("G21 G90 G94\nS8000 M3\nG0 X0 Y0 Z5\nG1 X20 F600\nM30\n(MTWIN STOCK 0,0,-10,20,20,0)\n")
    r = mtwin("simulate", str(f), "--json")
    assert r.returncode == 0
    d = json.loads(r.stdout)
    assert d["cutting"]["engaged_time"] == 0.0
    assert any("air.nc: warning: no feed move meets the stock" in w for w in d["warnings"])
    r = mtwin("simulate", str(f))
    assert "(line 0)" not in r.stderr.decode() and "none: no feed move meets the stock" in r.stderr.decode()


def test_inch_programs_show_their_own_units_and_json_says_si():
    r = mtwin("parse", str(SAMPLES / "face_slot_inch.nc"))
    assert "10 – 40 in/min (254 – 1016 mm/min)" in r.stderr.decode()
    d = json.loads(mtwin("parse", str(SAMPLES / "face_slot_inch.nc"), "--json").stdout)
    assert d["si_units"]["feed"] == "mm/min" and d["feed_range"] == [254.0, 1016.0]


def test_following_error_has_its_line_and_context_and_the_contour_error_beside_it():
    d = json.loads(mtwin("simulate", str(SAMPLES / "contour.nc"), "--json").stdout)
    assert set(d["max_following_error_line"]) == {"x", "y", "z"}
    assert set(d["max_following_error_in"].values()) <= {"rapid", "feed move"}
    # the largest lag is in a rapid: rapid speed / Kv, far above the lag while cutting
    assert d["max_following_error_in"]["x"] == "rapid"
    assert d["max_following_error_feed"]["x"] < d["max_following_error"]["x"]
    assert 0 < d["max_contour_error"] <= max(d["max_following_error_feed"].values()) * 1.0001
    assert d["max_contour_error_line"] > 0


def test_every_warning_has_one_form(tmp_path):
    f = tmp_path / "w.nc"
    # spindle clamp, travel of the default machine, a rapid through the stock
    f.write_text("G21 G90 G94\nS12000 M3\nG0 X0 Y0 Z-2\nG0 X30\nG1 Y300 F600\nM30\n"
                 "(MTWIN STOCK -5,-5,-10,40,10,0)\n")
    r = mtwin("simulate", str(f))
    lines = [x for x in r.stderr.decode().splitlines() if "warning:" in x and not x.startswith(("│", "┌", "└"))]
    assert len(lines) >= 3
    for x in lines:
        assert WARNING.match(x), x
    assert any("w.nc:3:1: warning: S12000" in x for x in lines)  # the first move at that speed


def test_cli_conventions():
    from mtwin import __version__

    r = mtwin("--version")
    assert r.returncode == 0 and r.stdout.decode().strip() == f"mtwin {__version__}"
    r = mtwin("--help")
    commands = r.stdout.decode().split("Commands:")[1]
    assert "..." not in commands and "simulate" in commands
    r = mtwin("scale", "--help")
    usage = r.stdout.decode().splitlines()[0]
    assert usage.endswith(" scale [OPTIONS] PART")
    assert "<" not in r.stdout.decode() and "{" not in r.stdout.decode()


def test_traceback_after_the_command_keeps_the_exit_code(tmp_path):
    f = tmp_path / "bad.nc"
    f.write_text("G21\nG1 X1 Q$\n")
    r = mtwin("parse", str(f), "--traceback")
    assert r.returncode == 2 and "Traceback" in r.stderr.decode()
    r = mtwin("parse", str(f))
    assert r.returncode == 2 and "Traceback" not in r.stderr.decode()


# ------------------------------------------------------------------ tools from comments (point 4)

def test_the_tools_a_program_declares_are_the_tools_it_is_simulated_with(tmp_path):
    f = tmp_path / "fusion.nc"
    f.write_text("(T1  D=10 CR=5 - ZMIN=-3 - ball end mill)\n(T2  D=6 CR=0 - flat end mill)\nG90 G94 G21\n"
                 "T1 M6\nS8000 M3\nG0 X0 Y0 Z5\nG1 Z-1 F300\nG1 X20 F800\nG0 Z5\nT2 M6\nG0 X0 Y10\nG1 Z-1 F300\n"
                 "G1 X20 F800\nG0 Z5\nT3 M6\nG0 X0 Y20\nG1 Z-1 F300\nG1 X20 F800\nG0 Z5\nM30\n"
                 "(MTWIN STOCK -10,-10,-10,30,30,0)\n")
    import mtwin as api

    tw = api.Twin()
    prog = tw.load(str(f))
    tr = tw.simulate(prog)
    # rows: radius, nose radius, flutes
    by_number = dict(zip(tr.engagement.tool_numbers, tr.engagement.tools.tolist()))
    assert by_number[1][:2] == [5.0, 5.0]  # 10 mm ball
    assert by_number[2][:2] == [3.0, 0.0]  # 6 mm flat
    assert by_number[3][:2] == [3.0, 0.0]  # nothing declared: the default, and it says so
    notes = tr.summary.cutting.defaults
    assert any(n.startswith("tool T1: 10 mm ball end mill") and "line 1" in n for n in notes)
    assert any(n.startswith("tool T3: no description") for n in notes)
    # a twin file's tool table stands over the comments
    twin = tmp_path / "m.toml"
    twin.write_text("[tools.1]\ntype = 'flat'\ndiameter = 8.0\n[tools.2]\ndiameter = 6.0\n[tools.3]\ndiameter = 4.0\n")
    tw2 = api.Twin.from_toml(str(twin))
    tr2 = tw2.simulate(tw2.load(str(f)))
    assert dict(zip(tr2.engagement.tool_numbers, tr2.engagement.tools.tolist()))[1][:2] == [4.0, 0.0]


@pytest.mark.parametrize("folder,pattern", [("gcode_corpus/fusion360_led_floor", "*.nc"),
                                            ("nist_smstestbed_mtc_hurco", "*.NC"),
                                            ("nist_smstestbed_d2mi_gcode", "*")])
def test_real_programs_are_simulated_with_their_declared_tools(folder, pattern):
    base = REALDATA / folder
    if not base.is_dir():
        pytest.skip(f"{base} not present")
    from mtwin.cutting.library import cutting_from_dict, for_program
    from mtwin.gcode.interpreter import InterpreterSettings, load_program

    exts = (".nc", ".ngc", ".tap", ".gcode")
    files = [p for p in sorted(base.rglob(pattern)) if p.is_file() and p.suffix.lower() in exts][:3]
    assert files
    read = 0
    for p in files:
        prog = load_program(str(p), InterpreterSettings(lenient=True))
        cut = for_program(cutting_from_dict({}), prog)
        read += len(cut.program_tools)
        for n in cut.defaults_used:
            assert n.startswith(("tool T", "material")), n
    assert read >= 1


# ------------------------------------------------------------ real programs, default machine (point 3)

@pytest.mark.parametrize("rel", ["nist_smstestbed_mtc_hurco/NC-Code/NIST_MTC_CRADA_PLATE-4.NC",
                                 "gcode_corpus/fanuc_macroB_and_fusion_cnc_sprayer/fusion-inch.nc",
                                 "nist_smstestbed_d2mi_gcode/827-9999-904, FIXT.NC"])
def test_real_programs_beyond_the_default_travel_are_simulated_with_a_warning(rel):
    path = REALDATA / rel
    if not path.is_file():
        pytest.skip(f"{path} not present")
    r = mtwin("simulate", str(path), "--lenient", "--no-cutting", "--json")
    assert r.returncode == 0, r.stderr.decode()[-800:]
    assert json.loads(r.stdout)["cycle_time"] > 60
    msg = r.stderr.decode()
    assert re.search(r":\d+:1: warning: move reaches [XYZ] = .* travel limit .* of the default machine", msg)
