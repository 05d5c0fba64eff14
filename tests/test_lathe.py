"""Lathe codes of LinuxCNC that milling-centre programs and the corpus use: G76 threading
passes and G7/G8 diameter mode, against traces LinuxCNC 2.9's ``rs274`` printed for our own
program (``tests/data/lathe``); live checks on LinuxCNC's example files when rs274 is here."""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from conftest import REALDATA
from mtwin.errors import GCodeError, WriteError
from mtwin.gcode.interpreter import InterpreterSettings, load_program
from mtwin.gcode.records import FL_DIAMETER, FL_SYNC
from mtwin.gcode.writer import Split, rewrite, scale_feeds
from test_linuxcnc_interp import canon_motion, our_motion

DATA = Path(__file__).parent / "data" / "lathe"


def _agree(prog, expected):
    ours = our_motion(prog)
    assert [k for k, _, _ in ours] == [k for k, _, _ in expected]
    for (k, ev, ef), (_, ov, of) in zip(expected, ours):
        n = 9 if k == "ARC_FEED" else 6
        np.testing.assert_allclose(ov[:n], ev[:n], atol=6e-5, err_msg=k)
        if k in ("STRAIGHT_FEED", "ARC_FEED"):
            assert of == pytest.approx(ef, abs=1e-4)  # F, or the (taper) pitch of a threading move


def test_threading_and_diameter_mode_match_linuxcnc():
    prog = load_program(DATA / "lathe_cycles.ngc", InterpreterSettings(dialect="linuxcnc"))
    expected = canon_motion(DATA / "lathe_cycles.expected")
    assert len(expected) == 297
    _agree(prog, expected)
    r = prog.records
    # threading moves run at pitch x spindle speed: 0.05 in x 800 rpm
    sync = r[(r["flags"] & FL_SYNC) != 0]
    assert sync["feed"].min() == pytest.approx(0.05 * 25.4 * 800)
    assert ((r["flags"] & FL_DIAMETER) != 0).sum() == 5


def test_thread_feeds_are_left_alone_and_diameter_moves_not_split():
    prog = load_program(DATA / "lathe_cycles.ngc", InterpreterSettings(dialect="linuxcnc"))
    data = (DATA / "lathe_cycles.ngc").read_bytes()
    assert scale_feeds(prog, 1.0) == data
    assert scale_feeds(prog, 0.5) == data.replace(b"F10", b"F5")
    k = int(np.flatnonzero((prog.records["flags"] & FL_DIAMETER) != 0)[1])
    with pytest.raises(WriteError, match="diameter"):
        rewrite(prog, splits={k: Split([0.5], [5.0, 5.0])})


def test_g76_errors():
    with pytest.raises(GCodeError, match="G76 needs"):
        load_program(b"G20 G17 S500 M3\nG0 X.2 Z.2\nG76 P.05 Z-.5 I-.07 J.01 K.04\n", path="t.ngc")  # G17
    with pytest.raises(GCodeError, match="G76 needs"):
        load_program(b"G20 G18 S500 M3\nG0 X.2 Z.2\nG76 P.05 Z-.5 I-.07 K.04\n", path="t.ngc")  # no J


@pytest.mark.skipif(shutil.which("rs274") is None, reason="LinuxCNC's rs274 is not installed")
@pytest.mark.parametrize("name", ["g76.ngc", "lathe-g76.ngc", "lathe_pawn.ngc"])
def test_linuxcnc_lathe_examples_live(name, tmp_path):
    ngc = REALDATA / "gcode_corpus" / "linuxcnc_nc_files" / name
    if not ngc.is_file():
        pytest.skip("shared LinuxCNC files not present")
    # the examples' tools: zero radius and length (a lathe table's own offsets are not modelled)
    (tmp_path / "tool.tbl").write_text("T1 P1 Z0 D0 ;\nT4 P4 Z0 D0 ;\nT9 P9 Z0 D0 ;\n")
    subprocess.run(["rs274", "-g", "-t", "tool.tbl", str(ngc), "out.txt"], cwd=tmp_path, capture_output=True,
                   timeout=60, check=True)
    prog = load_program(ngc, InterpreterSettings(dialect="linuxcnc", tool_lengths={1: 0.0, 4: 0.0, 9: 0.0},
                                                 comp_radii={1: 0.0, 4: 0.0, 9: 0.0}))
    _agree(prog, canon_motion(tmp_path / "out.txt"))


# ---------------------------------------------------------------- G70 / G71 / G72
def test_g7x_profile_cycles_match_linuxcnc():
    """G71 (with stock allowance D: offset profile, connecting arcs), G71.1, G71.2 and
    G70 in several passes from D to E, on two profiles with arcs, against rs274."""
    prog = load_program(DATA / "g7x_cycles.ngc", InterpreterSettings(dialect="linuxcnc"))
    expected = canon_motion(DATA / "g7x_cycles.expected")
    assert len(expected) == 325
    _agree(prog, expected)


def _profile_distance(p, segs):
    """Distance from point p = (x, z) to a profile of lines and arcs (independent of the cycle code)."""
    best = np.inf
    for s in segs:
        if s[0] == "line":
            a, b = np.array(s[1]), np.array(s[2])
            t = np.clip(np.dot(p - a, b - a) / np.dot(b - a, b - a), 0, 1)
            best = min(best, np.linalg.norm(p - (a + t * (b - a))))
        else:
            _, c, r, a0, a1 = s  # centre, radius, angle range (radians, a0 < a1)
            ang = np.arctan2(p[1] - c[1], p[0] - c[0])
            if a0 <= ang <= a1:
                best = min(best, abs(np.linalg.norm(p - np.array(c)) - r))
            else:
                for a in (a0, a1):
                    best = min(best, np.linalg.norm(p - (np.array(c) + r * np.array([np.cos(a), np.sin(a)]))))
    return best


def test_g71_roughing_leaves_the_stock_allowance():
    # profile of g7x_cycles.ngc's O10 (radius mode), in (x, z); the G2 arc from (8, -12)
    # to (12, -16) about (12, -12) spans angles pi .. 3pi/2 measured as atan2(z - cz, x - cx)
    segs = [("line", (5, 1), (5, 0)), ("line", (5, 0), (8, -3)), ("line", (8, -3), (8, -12)),
            ("arc", (12, -12), 4.0, -np.pi, -np.pi / 2), ("line", (12, -16), (12, -22)),
            ("line", (12, -22), (16, -26)), ("line", (16, -26), (16, -32)), ("line", (16, -32), (18, -32))]
    src = (DATA / "g7x_cycles.ngc").read_text().split("G0 X20 Z3\nG70", 1)[0] + "M2\n"
    prog = load_program(src.encode(), InterpreterSettings(dialect="linuxcnc"), path="g71.ngc")
    r = prog.records
    cyc = (r["line"] == 20) & (r["kind"] == 1)
    assert cyc.sum() > 10
    d = [_profile_distance(np.array([x, z]), segs) for x, z in zip(r["x"][cyc], r["z"][cyc])]
    assert min(d) == pytest.approx(0.4, abs=1e-6)  # D0.4: the last pass follows the offset profile
    # the roughing passes (feeds along Z) lie on levels I = 1.5 apart, down from the start X20
    along_z = cyc & (np.abs(r["x"] - r["sx"]) < 1e-9) & (np.abs(r["z"] - r["sz"]) > 0.5)
    levels = np.unique(np.round(r["x"][along_z], 6))
    contour = np.isin(levels, [5.4, 8.4, 12.4, 16.4])  # the final pass along the offset profile
    rough = levels[~contour]
    assert np.allclose((20.0 - rough) / 1.5, np.round((20.0 - rough) / 1.5))
    assert len(rough) >= 8


def test_g7x_fillet_corner_is_tangent():
    # A on a profile corner: a fillet of that radius, tangent to both sides (LinuxCNC's A word)
    src = (b"G18 G21 G90 G8 F200\nO1 SUB\nG1 X4 Z0\nG1 Z-10 A2\nG1 X12\nO1 ENDSUB\n"
           b"G70 Q1 X14 Z2 P1\nM2\n")
    prog = load_program(src, InterpreterSettings(dialect="linuxcnc"), path="fillet.ngc")
    arcs = prog.records[(prog.records["kind"] == 2) | (prog.records["kind"] == 3)]
    assert len(arcs) == 1
    a = arcs[0]
    assert (a["sx"], a["sz"]) == pytest.approx((4.0, -8.0))  # leaves Z-10 2 mm early
    assert (a["x"], a["z"]) == pytest.approx((6.0, -10.0))  # meets the shoulder 2 mm up
    assert (a["cx"], a["cz"]) == pytest.approx((6.0, -8.0))


def test_g7x_current_position_in_the_profile():
    # #<_x>/#<_z> follow the profile as it is read (LinuxCNC moves the position with it)
    src = (b"G18 G21 G90 F200\nO1 SUB\nG0 X0 Z-10\nO2 REPEAT [2]\nG1 X[#<_x>+5] Z[#<_z>+3]\nG1 X[#<_x>+5]\n"
           b"O2 ENDREPEAT\nO1 ENDSUB\nG70 Q1 X25 Z1 P1\nM2\n")
    prog = load_program(src, InterpreterSettings(dialect="linuxcnc"), path="pos.ngc")
    pts = {(round(x, 6), round(z, 6)) for x, z in zip(prog.records["x"], prog.records["z"])}
    assert {(5.0, -7.0), (10.0, -7.0), (15.0, -4.0), (20.0, -4.0)} <= pts


def test_g7x_errors():
    prof = b"O1 SUB\nG1 X4 Z0\nZ-10\nX12\nO1 ENDSUB\n"
    with pytest.raises(GCodeError, match="XZ plane"):
        load_program(b"G17 G21 F100\n" + prof + b"G71 Q1 X14 Z2\n", path="t.ngc")
    with pytest.raises(GCodeError, match="needs X and Z"):
        load_program(b"G18 G21 F100\n" + prof + b"G71 Q1 X14\n", path="t.ngc")
    with pytest.raises(GCodeError, match="no o7 sub"):
        load_program(b"G18 G21 F100\n" + prof + b"G71 Q7 X14 Z2\n", path="t.ngc")
    with pytest.raises(GCodeError, match="cutter compensation"):
        load_program(b"G18 G21 F100\n" + prof + b"G42.1 D1\nG71 Q1 X14 Z2\n", path="t.ngc")
    with pytest.raises(GCodeError, match="I must be greater than zero") as info:
        load_program(b"G18 G21 F100\n" + prof + b"G71 Q1 X14 Z2 I0\n", path="t.ngc")
    assert info.value.location.line == 7
    # a profile that doubles back in Z cannot be roughed (LinuxCNC: "Not monotonic")
    with pytest.raises(GCodeError, match="Not monotonic"):
        load_program(b"G18 G21 F100\nO1 SUB\nG1 X4 Z0\nZ-10\nX8\nZ-5\nX12\nO1 ENDSUB\nG71 Q1 X14 Z2\n", path="t.ngc")


def test_g7x_program_scales_and_round_trips():
    data = (DATA / "g7x_cycles.ngc").read_bytes()
    prog = load_program(data, InterpreterSettings(dialect="linuxcnc"), path="g7x.ngc")
    assert scale_feeds(prog, 1.0) == data
    out = scale_feeds(prog, 0.5)
    new = load_program(out, InterpreterSettings(dialect="linuxcnc"), path="g7x.ngc")
    from mtwin.gcode.verify import compare
    assert compare(prog, new) is None
    feed = prog.records["kind"] != 0
    assert np.allclose(new.records["feed"][feed], 0.5 * prog.records["feed"][feed])


def test_css_spindle_speed_follows_the_diameter():
    # G96 S<m/min> D<max rpm>: rpm = 1000 S / (2 pi r), at most D
    prog = load_program(b"G18 G21 G90 F0.1 G95\nG96 S200 D8000 M3\nG0 X40 Z2\nG1 Z-5\nG1 X5\nG1 X0.5\n"
                        b"G97 S500\nG1 Z-6\n", InterpreterSettings(dialect="linuxcnc"), path="css.ngc")
    r = prog.records
    assert r["spindle"][1] == pytest.approx(1000 * 200 / (2 * np.pi * 40))
    assert r["spindle"][2] == pytest.approx(1000 * 200 / (2 * np.pi * 5))
    assert r["spindle"][3] == pytest.approx(8000)  # clamped by D
    assert r["css"][3] == pytest.approx(200) and r["css"][4] == 0.0 and r["spindle"][4] == 500
    assert r["feed"][1] == pytest.approx(0.1 * 1000 * 200 / (2 * np.pi * 40))  # mm/rev x rpm


def test_turning_programs_are_not_given_milling_forces():
    # the cutting model is for milling tools: a lathe program simulates its motion only
    from mtwin.errors import MtwinError
    from mtwin.twin import Twin

    twin = Twin()
    prog = twin.load((DATA / "g7x_cycles.ngc").read_bytes(), path="g7x.ngc")
    with pytest.raises(MtwinError, match="turning program") as info:
        twin.simulate(prog, every=50)
    assert "g7x.ngc:20" in str(info.value)
    tr = twin.simulate(prog, cutting=False, every=50)
    assert tr.summary.cycle_time > 100


@pytest.mark.skipif(shutil.which("rs274") is None, reason="LinuxCNC's rs274 is not installed")
def test_linuxcnc_g71_demo_live(tmp_path):
    # LinuxCNC's lathe_g70_71_demo.ngc: its G71.1 and G71.2 roughing (the first 190 moves)
    # equal rs274 2.9 run here; its G70 runs under G42.1, which is not compared (see docs/gcode.md)
    ngc = REALDATA / "gcode_corpus" / "linuxcnc_nc_files" / "lathe_g70_71_demo.ngc"
    if not ngc.is_file():
        pytest.skip("shared LinuxCNC files not present")
    (tmp_path / "tool.tbl").write_text("T2 P2 Z0 D0 ;\nT10 P10 Z0 D0 ;\n")
    subprocess.run(["rs274", "-g", "-t", "tool.tbl", str(ngc), "out.txt"], cwd=tmp_path, capture_output=True,
                   timeout=60, check=True)
    prog = load_program(ngc, InterpreterSettings(dialect="linuxcnc", tool_lengths={2: 0.0, 10: 0.0},
                                                 comp_radii={2: 0.0, 10: 0.0}))
    expected = canon_motion(tmp_path / "out.txt")
    ours = our_motion(prog)
    assert len(expected) == len(ours) == 244
    for (k, ev, ef), (k2, ov, of) in list(zip(expected, ours))[:190]:
        assert k == k2
        n = 9 if k == "ARC_FEED" else 6
        np.testing.assert_allclose(ov[:n], ev[:n], atol=6e-5, err_msg=k)


def test_spindle_scaling_of_a_css_program_is_refused_clearly():
    prog = load_program(b"G18 G21 G90 F0.1 G95\nG96 S200 D3000 M3\nG0 X40 Z2\nG1 Z-5\nG1 X5\n",
                        InterpreterSettings(dialect="linuxcnc"), path="css.ngc")
    with pytest.raises(WriteError, match="constant surface speed"):
        scale_feeds(prog, spindle=1.2)
    assert scale_feeds(prog, feed=0.5).count(b"F0.05") == 1  # the feed per revolution still scales
