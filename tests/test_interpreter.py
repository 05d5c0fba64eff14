"""End points and arc centres for every supported code, checked against hand-computed values."""
import math
import re
import shutil
import subprocess

import numpy as np
import pytest

from mtwin.errors import GCodeError, WriteError
from mtwin.gcode.interpreter import InterpreterSettings, load_program
from mtwin.gcode.records import ARC_CCW, ARC_CW, DWELL, FL_MIRROR, FL_POLAR, LINEAR, RAPID, arc_sweep, move_lengths


def run(text, **kw):
    return load_program(text.encode(), InterpreterSettings(**kw), path="t.nc").records


def xyz(r):
    return [float(r["x"]), float(r["y"]), float(r["z"])]


def ctr(r):
    return [float(r["cx"]), float(r["cy"]), float(r["cz"])]


def test_linear_rapid_feed_spindle_tool():
    r = run("G21 G90\nT3 M6\nS5000 M3\nG0 X1 Y2 Z3\nG1X10Y-2.5F300\nx.5 y10. z-0.5\nM30\n")
    assert [int(k) for k in r["kind"]] == [RAPID, LINEAR, LINEAR]
    assert xyz(r[1]) == [10, -2.5, 3] and xyz(r[2]) == [0.5, 10, -0.5]
    assert r["feed"][1] == 300 and r["feed"][0] == 0
    assert (r["spindle"] == 5000).all() and (r["tool"] == 3).all() and (r["spindle_dir"] == 1).all()
    assert list(r["line"]) == [4, 5, 6]


def test_inch_program_converts_to_mm():
    r = run("G20 G90\nG0 X1 Y2\nG1 X2.5 F10.\n")
    assert xyz(r[0]) == pytest.approx([25.4, 50.8, 0])
    assert xyz(r[1]) == pytest.approx([63.5, 50.8, 0])
    assert r["feed"][1] == pytest.approx(254.0)


def test_feed_applied_before_unit_change():
    # RS274NGC: F is read in the units in force before this block's G20
    r = run("G21\nG0 X0\nG20 G1 X1 F20\n")
    assert r["feed"][1] == pytest.approx(20.0)


def test_g91_incremental_and_g91_arc():
    r = run("G21 G90 G0 X10 Y10\nG91 G1 X5 Y-5 F100\nG2 X10 Y0 I5 J0\n")
    assert xyz(r[1]) == [15, 5, 0]
    assert xyz(r[2]) == [25, 5, 0] and ctr(r[2]) == [20, 5, 0]
    assert arc_sweep(r)[2] == pytest.approx(math.pi)


def test_ijk_absolute_g90_1():
    r = run("G90 G90.1 G0 X0 Y0\nG3 X10 Y0 I5 J0 F100\n")
    assert ctr(r[1]) == [5, 0, 0] and r["kind"][1] == ARC_CCW


@pytest.mark.parametrize("rval,cw,center,sweep", [
    (5.0, True, (5, 0), math.pi),  # semicircle
    # CW along +X: a short arc has its centre right of the chord (below), a long one (R<0) above
    (-10.0, True, (5, 8.660254), 2 * math.pi - 2 * math.asin(0.5)),
    (10.0, True, (5, -8.660254), 2 * math.asin(0.5)),
    (10.0, False, (5, 8.660254), 2 * math.asin(0.5)),  # CCW: left of the chord
])
def test_r_format_arcs(rval, cw, center, sweep):
    g = "G2" if cw else "G3"
    r = run(f"G0 X0 Y0\n{g} X10 Y0 R{rval} F100\n")
    assert ctr(r[1])[:2] == pytest.approx(center, abs=1e-6)
    assert arc_sweep(r)[1] == pytest.approx(sweep)
    c = np.array(ctr(r[1]))
    assert np.hypot(*(c[:2])) == pytest.approx(abs(rval))


def test_full_circle_and_helix():
    r = run("G0 X10 Y0 Z0\nG3 X10 Y0 Z-2 I-10 J0 F100\n")
    assert arc_sweep(r)[1] == pytest.approx(2 * math.pi)
    assert move_lengths(r)[1] == pytest.approx(math.hypot(2 * math.pi * 10, 2))
    assert xyz(r[1]) == [10, 0, -2]


@pytest.mark.parametrize("plane,words,end,center", [
    ("G18", "X10 Z0 I5 K0", [10, 0, 0], [5, 0, 0]),
    ("G19", "Y10 Z0 J5 K0", [0, 10, 0], [0, 5, 0]),
])
def test_g18_g19_arcs(plane, words, end, center):
    r = run(f"G0 X0 Y0 Z0\n{plane} G2 {words} F100\n")
    assert xyz(r[1]) == end and ctr(r[1]) == center


def test_g18_direction_matches_linuxcnc():
    # G18 looks from +Y: CW from (0,0,0) around (5,0,0) passes through Z>0... check the midpoint
    r = run("G0 X0 Y0 Z0\nG18 G2 X10 I5 F100\n")
    assert r["kind"][1] == ARC_CW and r["plane"][1] == 1


def test_arc_radius_mismatch_rejected():
    with pytest.raises(GCodeError, match="radius") as e:
        run("G0 X0 Y0\nG2 X10 Y0 I4 J0 F100\n")
    assert e.value.location.line == 2


def test_dwell_fanuc_and_linuxcnc():
    assert run("G4 P500\n", dialect="fanuc")["dwell"][0] == pytest.approx(0.5)
    assert run("G4 P1.5\n", dialect="fanuc")["dwell"][0] == pytest.approx(1.5)
    assert run("G4 X2.\n", dialect="fanuc")["dwell"][0] == pytest.approx(2.0)
    assert run("G4 P2\n", dialect="linuxcnc")["dwell"][0] == pytest.approx(2.0)


def test_g81_g98_g99():
    r = run("G90 G0 X0 Y0 Z10\nG98 G81 X5 Y5 Z-3 R2 F100\nG99 X6\nG80\n")
    ends = [xyz(x) for x in r]
    assert ends == [[0, 0, 10], [5, 5, 10], [5, 5, 2], [5, 5, -3], [5, 5, 10],  # G98: back to old Z 10
                    [6, 5, 10], [6, 5, 2], [6, 5, -3], [6, 5, 2]]  # G99: back to R
    assert [int(k) for k in r["kind"]][1:5] == [RAPID, RAPID, LINEAR, RAPID]


def test_g83_peck_g98():
    r = run("G90 G0 X0 Y0 Z10\nG98 G83 X1 Y1 Z-7 R1 Q3 F100\n")
    z = [float(v) for v in r["z"][2:]]
    # R=1: feed to -2, out to R, down to -2+0.254, feed -5, out, down -5+0.254, feed -7, out to 10
    assert z == pytest.approx([1, -2, 1, -1.746, -5, 1, -4.746, -7, 10])
    kinds = [int(k) for k in r["kind"][3:]]
    assert kinds == [LINEAR, RAPID, RAPID, LINEAR, RAPID, RAPID, LINEAR, RAPID]


def test_g83_g99_and_g73_g85_g89_g82():
    r = run("G0 Z5\nG99 G83 X0 Z-4 R1 Q2.5 F50\n")
    assert float(r["z"][-1]) == 1.0
    r = run("G0 Z5\nG73 X0 Y0 Z-4 R1 Q2 F50\n")
    # Fanuc's power-on retract mode is G98: back to the old Z (5)
    assert [round(float(v), 3) for v in r["z"][2:]] == [1, -1, -0.746, -3, -2.746, -4, 5]
    r = run("G0 Z5\nG73 X0 Y0 Z-4 R1 Q2 F50\n", dialect="linuxcnc")
    assert float(r["z"][-1]) == 1.0  # LinuxCNC starts in G99
    r = run("G0 Z5\nG85 X0 Y0 Z-4 R1 F50\n")
    assert [int(k) for k in r["kind"][-3:]] == [LINEAR, LINEAR, RAPID]
    r = run("G0 Z5\nG89 X0 Y0 Z-4 R1 P250 F50\n")
    assert [int(k) for k in r["kind"][-4:]] == [LINEAR, DWELL, LINEAR, RAPID] and r["dwell"][-3] == 0.25
    r = run("G0 Z5\nG82 X0 Y0 Z-4 R1 P1000 F50\n")
    assert r["dwell"][-2] == 1.0


def test_g91_canned_with_repeats():
    # LinuxCNC crazy-paths number 4 in mm: R relative to old Z, Z relative to R, L repeats
    r = run("G90 G0 X10 Y0 Z2\nG91 G98 G81 X1 Y1 Z-2 R-1 L2 F100\n")
    ends = [xyz(x) for x in r[1:]]
    assert ends == [[11, 1, 2], [11, 1, 1], [11, 1, -1], [11, 1, 2], [12, 2, 2], [12, 2, 1], [12, 2, -1], [12, 2, 2]]


# A series of canned cycles with no G80 between: G99 blocks, then a G98 block at another X/Y
# (issue 9 point 7); a G80 starts a new series; a G91 series.  _CYCLE_SERIES_LINUXCNC is what
# LinuxCNC 2.9's rs274 printed for it (X, Y, Z of each STRAIGHT_TRAVERSE "R" / STRAIGHT_FEED "F").
_CYCLE_SERIES = """G21 G90 G17 F100
G0 X0 Y0 Z20
G99 G81 X10 Y0 Z-5 R2
X20
G98 X30 Y10
G80
G0 Z12
G98 G81 X70 Z-5 R2
G99 X80
G98 X90
G0 X0 Z10
G91 G99 G81 X1 Z-3 R-5
X1
G98 X1
G90 G80
M2
"""
_CYCLE_SERIES_LINUXCNC = [
    ("R", 0, 0, 20),
    ("R", 10, 0, 20), ("R", 10, 0, 2), ("F", 10, 0, -5), ("R", 10, 0, 2),  # G99 G81
    ("R", 20, 0, 2), ("F", 20, 0, -5), ("R", 20, 0, 2),  # G99
    # G98: up to the initial level 20 kept from before the first block (a slanting rapid from
    # R), down to R, drill, back to 20
    ("R", 30, 10, 20), ("R", 30, 10, 2), ("F", 30, 10, -5), ("R", 30, 10, 20),
    ("R", 30, 10, 12),  # G80, G0 Z12: a new series, initial level 12
    ("R", 70, 10, 12), ("R", 70, 10, 2), ("F", 70, 10, -5), ("R", 70, 10, 12),
    ("R", 80, 10, 12), ("R", 80, 10, 2), ("F", 80, 10, -5), ("R", 80, 10, 2),
    ("R", 90, 10, 12), ("R", 90, 10, 2), ("F", 90, 10, -5), ("R", 90, 10, 12),
    ("R", 0, 10, 10),
    # G91: R counts from the series' initial level 10 in every block (R at 5, bottom at 2)
    ("R", 1, 10, 10), ("R", 1, 10, 5), ("F", 1, 10, 2), ("R", 1, 10, 5),
    ("R", 2, 10, 5), ("F", 2, 10, 2), ("R", 2, 10, 5),
    ("R", 3, 10, 10), ("R", 3, 10, 5), ("F", 3, 10, 2), ("R", 3, 10, 10),
]


def _moves(r):
    """(kind, x, y, z) of each record: R rapid, F feed, D dwell (with its time, not a point)."""
    return [("D", float(d)) if int(k) == DWELL else ("R" if int(k) == RAPID else "F", float(x), float(y), float(z))
            for k, x, y, z, d in zip(r["kind"], r["x"], r["y"], r["z"], r["dwell"])]


def test_g98_after_g99_in_one_cycle_series_returns_to_the_initial_level():
    for dialect in ("linuxcnc", "fanuc"):
        r = run(_CYCLE_SERIES, dialect=dialect)
        third = r[r["line"] == 5]  # G98 X30 Y10 after two G99 blocks
        assert float(third["z"][-1]) == 20.0, dialect  # the level before the first cycle block
        assert int(third["kind"][-1]) == RAPID
        assert float(r[r["line"] == 10]["z"][-1]) == 12.0  # the series G80 ended is not used
        g91 = r[r["line"] == 14]  # G91 G98 X1
        assert [float(z) for z in g91["z"]][-3:] == [5.0, 2.0, 10.0], dialect
    assert _moves(run(_CYCLE_SERIES, dialect="linuxcnc")) == _CYCLE_SERIES_LINUXCNC
    # Fanuc positions at the level it is at (R after G99), then drills and returns to the
    # initial point level
    assert _moves(run(_CYCLE_SERIES, dialect="fanuc"))[8:12] == [
        ("R", 30, 10, 2), ("F", 30, 10, -5), ("R", 30, 10, 20), ("R", 30, 10, 12)]


def test_linuxcnc_g89_feeds_out_to_the_clearance_level():
    # rs274: G89 under G98 feeds from the bottom straight to the initial level (G85 feeds to
    # R and rapids up); Fanuc's G89 feeds to R like its G85
    r = run("G21 G0 X0 Y0 Z15\nG98 G89 X1 Z-6 R1 P0.3 F100\n", dialect="linuxcnc")
    assert _moves(r)[-3:] == [("F", 1, 0, -6), ("D", 0.3), ("F", 1, 0, 15)]
    r = run("G21 G0 X0 Y0 Z15\nG98 G89 X1 Z-6 R1 P300 F100\n", dialect="fanuc")
    assert _moves(r)[-4:] == [("F", 1, 0, -6), ("D", 0.3), ("F", 1, 0, 1), ("R", 1, 0, 15)]


_CYCLES_VS_RS274 = _CYCLE_SERIES.replace("M2\n", """S1000 M3
G0 X0 Y0 Z15
G99 G83 X5 Y5 Z-6 R1 Q2
G98 G73 X10 Z-6 R1 Q1.5
G99 G82 X15 Z-6 R1 P0.5
G98 G85 X20 Y0 Z-6 R1
G99 G86 X25 Z-6 R1 P0.2
G98 G89 X30 Z-6 R1 P0.3
G99 G81 X35 Z-6 R1 L2
G98 X40 L3
G0 Z0
G99 G81 X1 Z-1 R2
X2
G98 X3
G91 G98 G81 X1 Z-1 R1
G99 X1
G90 G0 Z20
G18 G99 G81 X5 Z5 Y-3 R4
G98 X10
G80
G19 G0 X5
G99 G81 Y1 Z1 X-2 R1
G98 Y2
G17 G80
M2
""")


@pytest.mark.skipif(shutil.which("rs274") is None, reason="LinuxCNC's rs274 is not installed")
def test_canned_cycle_series_match_rs274(tmp_path):
    """Every cycle, G98/G99 switched inside series, L repeats, G91, an initial level below R,
    G18 and G19: the same moves as LinuxCNC's own interpreter."""
    (tmp_path / "t.ngc").write_text(_CYCLES_VS_RS274)
    (tmp_path / "tool.tbl").write_text("T1 P1 Z0 D0 ;\n")
    subprocess.run(["rs274", "-g", "-t", "tool.tbl", "t.ngc", "out.txt"], cwd=tmp_path, capture_output=True,
                   timeout=60, check=True)
    want = []
    for line in (tmp_path / "out.txt").read_text().splitlines():
        m = re.search(r"(STRAIGHT_TRAVERSE|STRAIGHT_FEED|DWELL)\(([^)]*)\)", line)
        if m:
            v = [float(x) for x in m.group(2).split(",")]
            want.append(("D", v[0]) if m.group(1) == "DWELL" else ("R" if "TRAV" in m.group(1) else "F", *v[:3]))
    got = _moves(run(_CYCLES_VS_RS274, dialect="linuxcnc"))
    assert len(got) == len(want)
    for g, w in zip(got, want):
        assert g[0] == w[0] and g[1:] == pytest.approx(w[1:], abs=1e-4), (g, w)


def test_work_offsets_and_tool_length():
    s = dict(work_offsets={"G54": (100, 50, -300), "G55": (200, 50, -300)}, tool_lengths={1: 80.0})
    r = run("G54 G0 X0 Y0\nT1 M6\nG43 H1 Z10\nG55 G0 X0\n", **s)
    m = r[1]
    assert r["tlo"][1] == 80.0 and r["oz"][1] == -300
    assert float(m["z"] + m["oz"] + m["tlo"]) == pytest.approx(-210)
    # G55: position expressed in the new frame; the move is 100 mm in machine X
    assert float(r["x"][2] + r["ox"][2]) == pytest.approx(200)
    assert float(r["sx"][2] + r["ox"][2]) == pytest.approx(100)


def test_missing_tool_offset_is_an_error():
    with pytest.raises(GCodeError, match="tool length offset") as e:
        run("G43 H7 Z10\n", tool_lengths={1: 80.0})
    assert (e.value.location.line, e.value.location.col) == (1, 5)


def test_g28_and_g53():
    s = dict(work_offsets={"G54": (0, 0, -400)}, home_g28=(0, 0, 0))
    r = run("G0 X10 Y10 Z5\nG91 G28 Z0\nG90 G53 G0 X-50\n", **s)
    assert xyz(r[1]) == [10, 10, 5]  # intermediate point (incremental 0)
    assert xyz(r[2]) == [10, 10, 400]  # machine Z0 is 400 mm above work zero
    assert xyz(r[3]) == [-50, 10, 400]


def test_g61_g64_path_modes():
    r = run("G1 X1 F10\nG61 X2\nG64 P0.05 X3\nG61.1 X4\nG64 X5\n")
    assert list(r["path_mode"]) == [0, 1, 0, 2, 0]
    assert r["path_tol"][2] == pytest.approx(0.05) and r["path_tol"][4] == 0


def test_g95_feed_per_rev_and_g93_inverse_time():
    r = run("S1000 M3\nG95 G1 X10 F0.1\n")
    assert r["feed"][0] == pytest.approx(100.0)
    r = run("G93 G1 X10 F2\n")
    assert r["feed"][0] == pytest.approx(20.0)


def test_m98_m99_subprogram_with_repeats():
    prog = "O1\nG0 X0 Y0\nM98 P100 L2\nM30\nO100\nG91 G1 X1 F100\nG90\nM99\n"
    r = run(prog)
    assert [float(v) for v in r["x"]] == [0, 1, 2]
    assert list(r["line"]) == [2, 6, 6]


def test_coolant_and_spindle_stop():
    r = run("M3 S100 M8\nG0 X1\nM5 M9\nG0 X2\n")
    assert list(r["coolant"]) == [2, 0] and list(r["spindle_dir"]) == [1, 0]


@pytest.mark.parametrize("text,match,line,col", [
    ("G1 X1 F100 G0\n", "same modal group", 1, 12),
    ("G1 X1 X2 F1\n", "twice", 1, 7),
    ("G1 F100\nG1 X1 Q2\n", "not used", 2, 7),
    ("G1 X1\n", "zero feed", 1, 1),
    ("G2 X1 F1\n", "neither", 1, 1),
    ("G19 G41 D1\n", "XY and XZ planes", 1, 5),
    ("G92 A5\n", "work offsets", 1, 5),
    ("G99.5 X1\n", "unsupported G-code", 1, 1),
    ("M123\n", "unsupported M-code", 1, 1),
    ("G1 X[1+2 F10\n", "expected ']'", 1, 10),
    ("#1=5\nG1 X#<nope> F10\n", "#<nope> is not defined", 2, 11),
    ("G1 X1 (open\n", "not closed", 1, 7),
    ("G1 X F10\n", "malformed", 1, 4),
    ("IF [#1 LT 2] GOTO 5\n", "no block N5", 1, 1),
    ("o100 sub\n", "no matching o100 endsub", 1, 1),
    ("M98 P77\n", "not found", 1, 5),
    ("G81 X1 Y1 Z-1 F10\n", "R \\(retract", 1, 1),
    ("G0 Z5\nG83 X0 Z-4 R1 F50\n", "Q", 2, 1),
])
def test_errors_name_line_and_column(text, match, line, col):
    with pytest.raises(GCodeError, match=match) as e:
        run(text)
    assert (e.value.location.line, e.value.location.col) == (line, col)


def test_lenient_turns_unsupported_codes_into_warnings():
    p = load_program(b"G1 X1 F10\nM123\nG5.2 Q1\n", InterpreterSettings(lenient=True), path="t.nc")
    assert len(p.records) == 1 and len(p.warnings) == 2
    assert "t.nc:2:1" in str(p.warnings[0])


def test_lowercase_block_delete_comments_and_percent():
    text = "%\n(header)\ng0 x1 ; comment\n/G0 X5\nN10 G1 X2 F10 (cut)\n%\nG0 X99\n"
    r = run(text)
    assert [float(v) for v in r["x"]] == [1, 5, 2]
    r = run(text, skip_block_delete=True)
    assert [float(v) for v in r["x"]] == [1, 2]


def test_runaway_subprograms_end_with_an_error():
    with pytest.raises(GCodeError, match="nesting"):
        run("O1\nM98 P1\n")
    # a repeat count beyond Fanuc's own range (L1-L9999) stops at once, at its word (issue 33)
    with pytest.raises(GCodeError, match=r"1:10: a repeat count L99999999 over 9999"):
        run("M98 P100 L99999999\nM30\nO100\nG4 P1\nM99\n")
    with pytest.raises(GCodeError, match=r"a repeat count L10000 over 9999"):
        run("G21 G91\nG81 X1 Z-1 R1 L10000 F100\nM30\n")


def test_g92_offsets_program_coordinates():
    # G92 makes the current point read as the given values; machine position = program + offset
    prog = load_program(b"G21 G90\nG0 X10 Y5\nG92 X0 Y0\nG1 X5 F100\nG92.1\nG1 X20\nG92 X0\nG92.2\nG1 Y0\n"
                        b"G92.3\nG1 X1\nM2\n", path="t.ngc")
    r = prog.records
    assert list(zip(r["x"], r["y"])) == [(10, 5), (5, 0), (20, 5), (20, 0), (1, 0)]
    assert list(zip(r["ox"], r["oy"])) == [(0, 0), (10, 5), (0, 0), (0, 0), (20, 0)]
    # a G28 return is a machine position: the G92 offset is taken out of it
    prog = load_program(b"G21 G90\nG0 X10\nG92 X0\nG28\nM2\n", path="t.ngc")
    assert prog.records["x"][-1] == -10.0 and prog.records["ox"][-1] == 10.0


def test_fanuc_g80_restores_the_motion_mode_and_g08_is_a_control_switch():
    text = b"G20 G90 G0 X0 Y0 Z1\nG08 P1\nG99 G81 X1 Z-0.1 R0.1 F10\nG80\nZ0.5\nG05.1 Q1\nX2\nM30\n"
    prog = load_program(text, InterpreterSettings(dialect="fanuc"), path="t.nc")
    last = prog.records[-2:]
    assert last["kind"].tolist() == [RAPID, RAPID] and last["line"].tolist() == [5, 7]
    # RS274NGC: G80 leaves no motion mode, and G8 is the lathe radius mode (a P word is unused)
    with pytest.raises(GCodeError, match="without an active motion mode"):
        load_program(text.replace(b"G08 P1\n", b"").replace(b"G05.1 Q1\n", b""),
                     InterpreterSettings(dialect="linuxcnc"), path="t.ngc")
    with pytest.raises(GCodeError, match="P1 is not used"):
        load_program(b"G8 P1\n", InterpreterSettings(dialect="linuxcnc"), path="t.ngc")


def test_coordinate_rotation_g10_r():
    """G10 L2 R rotates the system about its origin: machine = G5x + Rot(R)·(program + G92)."""
    from mtwin.gcode.records import machine_xyz

    r = run("G21 G90 G10 L2 P1 X100 Y50 R30\nG54 G0 X0 Y0\nG1 X10 F100\nG2 X20 Y0 I5 J0\nM2\n",
            dialect="linuxcnc")
    m = machine_xyz(r)
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    # program coordinates stay those written; the machine sees them rotated about (100, 50)
    assert xyz(r[1]) == [10, 0, 0] and r["rot"][1] == 30
    np.testing.assert_allclose(m[1], [100 + 10 * c, 50 + 10 * s, 0], atol=1e-12)
    np.testing.assert_allclose(m[2], [100 + 20 * c, 50 + 20 * s, 0], atol=1e-12)
    # G18/G19 arcs in a rotated system would leave the machine's planes: refused
    with pytest.raises(GCodeError, match="XY plane only"):
        run("G10 L2 P1 R30\nG54 G18 G1 X0 Z0 F100\nG2 X10 Z0 I5 K0\n", dialect="linuxcnc")


def test_g10_l20_and_l2_on_the_active_system_keep_the_machine_position():
    # LinuxCNC g10-l20-while-active: after L20 X-1 the current point reads X-1
    r = run("G20 G54\nG10 L2 P1 X0 Y0 Z0 R45\nG0 G53 X0 Y0 Z0\nG10 L20 P1 X-1\nG1 X0 F60\nM2\n",
            dialect="linuxcnc")
    assert float(r["sx"][1]) == pytest.approx(-25.4) and xyz(r[1])[:2] == [0.0, 0.0]
    np.testing.assert_allclose([r["ox"][1] / 25.4, r["oy"][1] / 25.4], [0.70710678, 0.70710678])


def test_tool_length_change_keeps_the_tool_where_it_is():
    # G43 does not move the machine: the program position changes, so an incremental move
    # after it moves 1 mm, not 1 mm plus the tool length
    from mtwin.gcode.records import machine_xyz

    r = run("G21 G90 G0 Z0\nT1 M6\nG43 H1\nG91 G1 Z-1 F100\nM2\n", tool_lengths={1: 80.0})
    m = machine_xyz(r)
    assert m[0][2] == 0.0 and m[1][2] == pytest.approx(-1.0)
    assert float(r["sz"][1]) == -80.0 and float(r["z"][1]) == -81.0


def test_g10_tool_table_forms_and_g43_1():
    # L1 sets, L10 sets so the current point reads as given, G43.1 gives the offset directly
    r = run("G21 G90 G0 X0 Y0 Z0\nG10 L1 P1 Z50\nT1 M6 G43\nG0 Z10\nG10 L10 P2 Z0\nT2 M6 G43\nG0 Z10\n"
            "G43.1 Z5\nG0 Z10\nM2\n", dialect="linuxcnc")
    assert list(r["tlo"][1:]) == [50.0, 60.0, 5.0]
    # G10 L10 P2 Z0 at program Z10 with 50 active: tool 2 = 50 + 10 = 60
    from mtwin.gcode.records import machine_xyz
    assert list(machine_xyz(r)[1:, 2]) == [60.0, 70.0, 15.0]


def test_g28_1_stores_the_current_machine_position():
    r = run("G21 G90 G0 X10 Y20 Z5\nG28.1\nG0 X0 Y0 Z0\nG28\nM2\n", dialect="linuxcnc")
    assert xyz(r[-1]) == [10, 20, 5]


def test_polar_words():
    # LinuxCNC manual: "G1 @.5 ^90" then "G91 ^90" four times is a square (diamond) about the
    # origin; "G91 @.5 ^90" grows the distance each time
    r = run("G20 F100 G1 @.5 ^90\nG91 ^90\n^90\n^90\n^90\nG90 G0 X0 Y0\nM2\n", dialect="linuxcnc")
    pts = np.round(np.stack([r["x"], r["y"]], 1)[:5] / 25.4, 12)
    np.testing.assert_allclose(pts, [[0, .5], [-.5, 0], [0, -.5], [.5, 0], [0, .5]], atol=1e-12)
    assert all(r["flags"][:5] & FL_POLAR)
    r = run("G20 F100 G1 @.5 ^90\nG91 @.5 ^90\n@.5 ^90\nM2\n", dialect="linuxcnc")
    np.testing.assert_allclose(np.hypot(r["x"], r["y"]) / 25.4, [.5, 1.0, 1.5], atol=1e-12)
    # G90 with one word: the other is the current point's (polar.ngc's bolt holes)
    r = run("G21 G0 X10 Y0\nG1 ^90 F100\n@20\nM2\n", dialect="linuxcnc")
    np.testing.assert_allclose([xyz(r[1])[:2], xyz(r[2])[:2]], [[0, 10], [0, 20]], atol=1e-12)
    # a bolt circle: G91 canned cycle with ^ and L repeats adds the angle each time
    r = run("G20 G17 G90 G0 X1.5 Y0 Z0\nG91 G81 R.1 Z-.5 ^60 L6 F10\nM2\n", dialect="linuxcnc")
    holes = r[r["kind"] == LINEAR]
    np.testing.assert_allclose(np.hypot(holes["x"], holes["y"]) / 25.4, 1.5, atol=1e-12)
    ang = np.degrees(np.arctan2(holes["y"], holes["x"]))
    np.testing.assert_allclose((ang - [60, 120, 180, 240, 300, 360] + 180) % 360 - 180, 0, atol=1e-9)
    with pytest.raises(GCodeError, match="polar"):
        run("G1 X1 @1 F100\n", dialect="linuxcnc")
    with pytest.raises(GCodeError, match="polar"):
        run("G18 G1 @1 F100\n", dialect="linuxcnc")


def test_g5_splines_followed_within_a_micron():
    r = run("G21 G17 G90 F100\nG0 X0 Y0\nG5.1 X10 Y0 I5 J5\nG5 X20 Y0 I2 J5 P-2 Q5\nG5 X30 Y0 P-2 Q-5\nM2\n",
            dialect="linuxcnc")

    def bez(ctrl, t):
        ctrl = np.asarray(ctrl, float)
        k = len(ctrl) - 1
        coef = [math.comb(k, i) * t ** i * (1 - t) ** (k - i) for i in range(k + 1)]
        return sum(c[:, None] * p[None, :] for c, p in zip(coef, ctrl))

    curves = {3: [(0, 0), (5, 5), (10, 0)], 4: [(10, 0), (12, 5), (18, 5), (20, 0)],
              # no I J: the first control point mirrors the last one of the G5 before
              5: [(20, 0), (22, -5), (28, -5), (30, 0)]}
    t = np.linspace(0, 1, 20001)
    for line, ctrl in curves.items():
        seg = r[r["line"] == line]
        assert seg[0]["sx"] == ctrl[0][0] and (seg["x"][-1], seg["y"][-1]) == ctrl[-1]
        dense = bez(ctrl, t)
        pts = np.stack([seg["x"], seg["y"]], 1)
        # every piece end lies on the curve, every piece within 1 um of it
        assert np.min(np.linalg.norm(dense[None, :, :] - pts[:, None, :], axis=2), axis=1).max() < 1e-3
        mids = 0.5 * (pts + np.stack([seg["sx"], seg["sy"]], 1))
        assert np.min(np.linalg.norm(dense[None, :, :] - mids[:, None, :], axis=2), axis=1).max() < 1.01e-3
    with pytest.raises(GCodeError, match="G5"):
        run("G21 G17 F100\nG5 X1 Y1 P1 Q1\n", dialect="linuxcnc")  # no I J and no G5 before


def test_lenient_never_guesses_an_unknown_code_with_axis_words():
    # an unknown code alone is passed over; with axis words it may be a motion of its own
    r = run("G21 G1 X1 F100\nG17.1\nX2\nM2\n", lenient=True)
    assert list(r["x"]) == [1.0, 2.0]
    with pytest.raises(GCodeError, match="unsupported G-code G17.1"):
        run("G21 G1 X1 F100\nG17.1 X2\nM2\n", lenient=True)


def test_fanuc_g68_rotation_about_a_centre():
    # G68 X10 Y10 R90: later points are turned 90 degrees about (10, 10); G69 cancels
    from mtwin.gcode.records import machine_xyz

    r = run("G21 G90 G17 G0 X0 Y0 Z5\nG68 X10 Y10 R90\nG1 X20 Y10 F100\nG91 X0 Y5\nG90 G2 X20 Y25 I0 J5\nG69\n"
            "G1 X0 Y0\nM30\n", dialect="fanuc")
    np.testing.assert_allclose(machine_xyz(r)[:, :2], [[0, 0], [10, 20], [5, 20], [-5, 20], [0, 0]], atol=1e-12)
    assert list(r["rot"]) == [0, 90, 90, 90, 0]
    # the arc's centre (20, 20) in the program lies at (0, 20) on the machine
    centre = r[3:4].copy()
    centre["x"], centre["y"] = r["cx"][3], r["cy"][3]
    np.testing.assert_allclose(machine_xyz(centre)[0, :2], [0, 20], atol=1e-12)
    with pytest.raises(GCodeError, match="G68 needs its R"):
        run("G17 G68 X1 Y1\n", dialect="fanuc")


def test_g52_local_offset_shares_the_g92_register():
    # program coordinates as LinuxCNC's rs274 prints them for this program; machine = program + offset
    from mtwin.gcode.records import machine_xyz

    r = run("G21 G90\nG0 X10 Y10 Z0\nG52 X5 Y2\nG0 X0 Y0\nG52 Z-1\nG1 Z0 F100\nG52 X0 Y0 Z0\nG0 X0 Y0\n"
            "G92 X1\nG52 X3\nG0 X0\nM2\n", dialect="linuxcnc")
    np.testing.assert_allclose(np.stack([r["x"], r["y"], r["z"]], 1),
                               [[10, 10, 0], [0, 0, 0], [0, 0, 0], [0, 0, -1], [0, 0, -1]], atol=1e-12)
    np.testing.assert_allclose(machine_xyz(r), [[10, 10, 0], [5, 2, 0], [5, 2, -1], [0, 0, -1], [3, 0, -1]],
                               atol=1e-12)


def test_m61_sets_the_tool_number_without_a_change():
    # LinuxCNC M61 Q<n>: the spindle holds tool n (no tool change); G43 then takes its length
    prog = load_program(b"G21 G90\nM61 Q2 G43\nG0 Z10\nG49\nM61 Q0 G43\nG0 Z5\n",
                        InterpreterSettings(dialect="linuxcnc", tool_lengths={2: 25.0}), path="m61.ngc")
    r = prog.records
    assert list(r["tool"]) == [2, 0] and list(r["tlo"]) == [25.0, 0.0]  # T0: no tool, no offset
    with pytest.raises(GCodeError, match="M61"):
        load_program(b"G21\nM61\n", InterpreterSettings(dialect="linuxcnc"), path="m61.ngc")


def test_linuxcnc_io_m_codes_leave_the_path_alone():
    # M62-M65 digital outputs, M66 wait on input, M67/M68 analog outputs (LinuxCNC)
    text = b"G21 F100\nM64 P1\nG1 X10\nM65 P1\nM66 P0 L3 Q5\nM67 E0 Q2.5\nM68 E1 Q3\nM62 P2\nM63 P2\nG1 X20\n"
    prog = load_program(text, InterpreterSettings(dialect="linuxcnc"), path="io.ngc")
    assert list(prog.records["x"]) == [10.0, 20.0] and not prog.warnings
    with pytest.raises(GCodeError, match="unsupported M-code M64"):
        load_program(b"G21\nM64 P1\n", InterpreterSettings(dialect="fanuc"), path="io.nc")


def test_fanuc_g16_polar_coordinates():
    # G16 (G17): X is the radius, Y the angle about the work zero; G91 makes the angle
    # incremental; G15 ends it.  A bolt circle in a drilling cycle, then polar G01 moves.
    text = (b"G21 G90 G17 G54\nG0 X0 Y0 Z5\nG16\nG81 X50 Y0 Z-5 R2 F100\nY90\nY180\nG80\n"
            b"G1 X20 Y45\nG91 Y45\nG90 G4 X0.5\nG15\nG0 X10 Y10\nM30\n")
    prog = load_program(text, InterpreterSettings(dialect="fanuc"), path="polar.nc")
    r = prog.records
    holes = r[(r["kind"] == LINEAR) & (r["z"] == -5.0)]
    np.testing.assert_allclose(np.c_[holes["x"], holes["y"]], [[50, 0], [0, 50], [-50, 0]], atol=1e-9)
    moves = r[(r["kind"] == LINEAR) & (r["z"] != -5.0)]
    np.testing.assert_allclose(np.c_[moves["x"], moves["y"]], [[20 / 2 ** 0.5, 20 / 2 ** 0.5], [0, 20]], atol=1e-9)
    assert r[r["kind"] == DWELL]["dwell"][0] == 0.5  # X on a dwell is its time, not a radius
    assert (r["x"][-1], r["y"][-1]) == (10.0, 10.0)  # after G15: cartesian again
    for bad in (b"G21 G90 G17\nG16\nG91 G1 X5 Y10 F100\n", b"G21 G90 G18\nG16\nG1 X5 Y10 F100\n"):
        with pytest.raises(GCodeError, match="G16 polar"):
            load_program(bad, InterpreterSettings(dialect="fanuc"), path="polar.nc")


def test_fanuc_g51_1_mirror_image():
    # mirror about X = 0: X words reflect (incremental ones change sign), a G02 becomes a
    # G03 about the reflected centre, a G41 cuts on the right; G50.1 ends it
    src = (b"G21 G90 G17 G54\nG0 X0 Y0 Z5\nG1 Z-1 F100\nG1 X10 Y5\nG2 X20 Y15 I10 J0\nG51.1 X0\n"
           b"G1 X10 Y5\nG2 X20 Y15 I10 J0\nG91 G1 X5\nG90 G41 D0 X10 Y0\nG40 X0\nG50.1 X0\nG1 X30 Y0\nM30\n")
    prog = load_program(src, InterpreterSettings(dialect="fanuc"), path="m.nc")
    r = prog.records
    assert (r["x"][3], r["cx"][3], r["kind"][3]) == (20.0, 20.0, ARC_CW)  # before: as written
    assert (r["x"][4], r["y"][4]) == (-10.0, 5.0)
    assert (r["x"][5], r["y"][5], r["cx"][5], r["cy"][5], r["kind"][5]) == (-20.0, 15.0, -20.0, 5.0, ARC_CCW)
    assert r["x"][6] == -25.0  # G91 X5 -> X-5
    assert r["x"][7] == -10.0 and r["comp"][7] == 2  # G41 under a one-axis mirror: right of the path
    assert r["x"][-1] == 30.0 and not r["flags"][-1] & FL_MIRROR
    from mtwin.gcode.writer import Split, rewrite, scale_feeds
    assert scale_feeds(prog, 1.0) == src
    with pytest.raises(WriteError, match="mirror"):
        rewrite(prog, splits={4: Split([0.5], [100.0, 50.0])})


def test_fanuc_powers_on_in_g00_linuxcnc_in_no_motion_mode():
    prog = load_program(b"G21 G90\nG43 H1 Z10.\n", InterpreterSettings(dialect="fanuc", tool_lengths={1: 50.0}),
                        path="on.nc")
    assert prog.records["kind"][0] == RAPID and prog.records["z"][0] == 10.0
    with pytest.raises(GCodeError, match="without an active motion mode") as e:
        load_program(b"G21 G90\nG43 H1 Z10.\n", InterpreterSettings(dialect="linuxcnc", tool_lengths={1: 50.0}),
                     path="on.ngc")
    assert (e.value.location.line, e.value.location.col) == (2, 8)


def test_fanuc_g10_offset_memory_c():
    # G10 L10/L11 set the geometry/wear of length offset H, L12/L13 of radius offset D; G91
    # adds; the length in force is geometry + wear, taken at the next G43 H
    src = (b"G21 G90 G17\nG10 L10 P3 R100.\nG10 L11 P3 R-0.2\nG91 G10 L11 P3 R-0.05\nG90\n"
           b"G10 L12 P7 R3.\nG10 L13 P7 R-0.01\nG0 X0 Y0\nG43 H3 Z50.\nG41 D7 G1 X10 F100\nY10\nG40 X0\n")
    prog = load_program(src, InterpreterSettings(dialect="fanuc"), path="g10.nc")
    r = prog.records
    assert r["tlo"][1] == pytest.approx(99.75)
    assert r["comp_r"][2] == pytest.approx(2.99)
    with pytest.raises(GCodeError, match="Fanuc's L10/L11/L12/L13"):
        load_program(b"G21\nG10 L12 P7\n", InterpreterSettings(dialect="fanuc"), path="g10.nc")


def test_an_f_word_on_the_line_that_switches_units_is_read_before_the_switch_and_warned():
    # G20 F6 on one line: 6 mm/min (the feed is set before the units change, as LinuxCNC does),
    # where a programmer from the inch world expects 6 in/min — warned once, at the F word
    prog = load_program(b"G21 G90\nG0 X0 Y0 Z1\nG20 F6\nG1 X1\nM30\n", path="u.nc")
    assert prog.records["feed"][-1] == pytest.approx(6.0)
    msgs = [str(w) for w in prog.warnings]
    assert any(m.startswith("u.nc:3:5: warning: F6 on the line that switches units") for m in msgs), msgs
    # the F word on a line after the switch, or on a line that switches nothing: no warning
    for text in (b"G20\nG0 X0 Y0 Z1\nF6\nG1 X1\nM30\n", b"G20\nG0 X0 Y0 Z1\nG20 F6\nG1 X1\nM30\n"):
        prog = load_program(text, path="u.nc")
        assert not any("switches units" in str(w) for w in prog.warnings)


def test_repeats_inside_repeats_stop_at_the_move_limit(tmp_path):
    # M98 ... L9999 calling a G81 ... L9999: 1e8 cycles, hours; stopped at 5,000,000 moves in
    # seconds with the place and the limit named (issue 33)
    import time

    from mtwin.errors import GCodeError
    from mtwin.gcode.interpreter import load_program

    p = tmp_path / "mult.nc"
    p.write_text("O1000\nG21 G90 G17\nG0 X0 Y0 Z5\nM98 P2000 L9999\nM30\nO2000\n"
                 "G91 G81 X0.001 Z-1 R1 L9999 F100\nG80 G90\nM99\n")
    t0 = time.monotonic()
    with pytest.raises(GCodeError, match="more than 5,000,000 moves"):
        load_program(str(p))
    assert time.monotonic() - t0 < 60
