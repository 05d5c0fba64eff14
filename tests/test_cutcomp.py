"""Cutter radius compensation (G41/G42) against hand geometry and LinuxCNC 2.9's interpreter.

``tests/data/cutcomp/*.expected`` are the canonical traces ``rs274`` (LinuxCNC 2.9) printed
for our own programs with ``tool.tbl`` (T1: 0.25 in diameter); the live test re-runs rs274
when it is installed.
"""
from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from mtwin.errors import GCodeError, WriteError
from mtwin.gcode.interpreter import InterpreterSettings, load_program
from mtwin.gcode.records import ARC_CW, FL_COMP
from mtwin.gcode.writer import Split, rewrite

DATA = Path(__file__).parent / "data" / "cutcomp"
CANON = re.compile(r"(STRAIGHT_FEED|ARC_FEED|STRAIGHT_TRAVERSE)\(([^)]*)\)")
INCH = 25.4


def canon_points(text: str):
    pts = []
    for ln in text.splitlines():
        m = CANON.search(ln)
        if m:
            v = [float(x) for x in m.group(2).split(",")]
            z = v[5] if m.group(1) == "ARC_FEED" else v[2]
            centre = (v[2], v[3]) if m.group(1) == "ARC_FEED" else None
            pts.append((v[0], v[1], z, centre))
    return pts


@pytest.mark.parametrize("name", ["pocket_g41", "contour_g42"])
def test_compensated_path_matches_linuxcnc(name):
    prog = load_program(str(DATA / f"{name}.ngc"), InterpreterSettings(comp_radii={1: 0.125 * INCH}))
    ref = canon_points((DATA / f"{name}.expected").read_text())
    r = prog.records
    assert len(r) == len(ref)
    for k, (x, y, z, centre) in enumerate(ref):
        assert (r["x"][k] / INCH, r["y"][k] / INCH, r["z"][k] / INCH) == pytest.approx((x, y, z), abs=1e-4)
        if centre is not None:
            assert (r["cx"][k] / INCH, r["cy"][k] / INCH) == pytest.approx(centre, abs=1e-4)


def test_square_inside_by_hand():
    # CCW square with G41 (tool on the left = inside): entry ends square to the entry move,
    # the outside corner after the entry gets an arc around the programmed corner, inside
    # corners meet at the offset lines' crossings
    text = b"G21 G90 F100\nG0 X-10 Y-10\nG41 D1 G1 X0 Y0\nG1 X20\nG1 Y10\nG1 X0\nG1 Y0\nG40 G1 X-10 Y-10\nM2\n"
    prog = load_program(text, InterpreterSettings(comp_radii={1: 2.0}), path="t.nc")
    r = prog.records
    ends = np.stack([r["x"], r["y"]], axis=1)
    s2 = 2 ** 0.5
    np.testing.assert_allclose(ends, [[-10, -10], [-s2, s2], [0, 2], [18, 2], [18, 8], [2, 8], [2, 0], [-10, -10]],
                               atol=1e-12)
    assert r["kind"][2] == ARC_CW and (r["cx"][2], r["cy"][2]) == (0.0, 0.0)
    assert np.all(r["flags"][1:] & FL_COMP)
    assert r["line"].tolist() == [2, 3, 4, 4, 5, 6, 7, 8]


def test_unknown_d_is_radius_zero_with_a_warning():
    prog = load_program(b"G21 G90 F100\nG0 X-10 Y-10\nG41 D7 G1 X0 Y0\nG1 X20\nG40 G1 X30 Y-10\nM2\n", path="t.nc")
    assert prog.records["y"].tolist() == [-10.0, 0.0, 0.0, -10.0]
    assert any("no radius known" in w.message for w in prog.warnings)


@pytest.mark.parametrize("text,message", [
    (b"G21 G90 F100\nG41 D1 G1 X1 Y0\nG1 X20\nM2\n", "must be longer than the tool radius"),
    (b"G21 G90 F100\nG0 X-10\nG41 D1 G1 X0 Y0\nG3 X0 Y0 I1 J0\nM2\n", "does not fit inside the arc"),
    (b"G21 G90 F100\nG19 G41 D1 G1 Y10\nM2\n", "XY and XZ planes"),
    (b"G21 G90 F100\nG0 X-10\nG41 D1 G1 X0\nG42 D1 G1 X5\nM2\n", "already on"),
    (b"G21 G90 F100\nG0 X-10 Y-10\nG41 D1 G2 X0 Y0 I5 J5\nG1 X10\nM2\n", r"entry move\) must be a line"),
])
def test_compensation_errors(text, message):
    with pytest.raises(GCodeError, match=message):
        load_program(text, InterpreterSettings(comp_radii={1: 2.0}), path="t.nc")


def test_twin_file_radii_and_writer_limits(tmp_path):
    from mtwin.config import interpreter_settings

    f = tmp_path / "t.toml"
    f.write_text('[cutter_comp]\nD1 = "0.125 in"\n[tools.2]\ndiameter = 8.0\n')
    st = interpreter_settings(str(f))
    assert st.comp_radii == {1: pytest.approx(3.175), 2: 4.0}
    prog = load_program(str(DATA / "pocket_g41.ngc"), st)
    # F changes are fine; splitting a compensated move is refused
    assert rewrite(prog) == (DATA / "pocket_g41.ngc").read_bytes()
    k = int(np.flatnonzero(prog.records["flags"] & FL_COMP)[3])
    with pytest.raises(WriteError, match="cutter compensation"):
        rewrite(prog, splits={k: Split([0.5], [500.0, 600.0])})


@pytest.mark.skipif(shutil.which("rs274") is None, reason="LinuxCNC's rs274 is not installed; stored traces are used")
@pytest.mark.parametrize("name", ["pocket_g41", "contour_g42"])
def test_stored_traces_are_what_rs274_prints(name, tmp_path):
    for f in (f"{name}.ngc", "tool.tbl"):
        shutil.copy(DATA / f, tmp_path / f)
    subprocess.run(["rs274", "-g", "-t", "tool.tbl", f"{name}.ngc", "out.txt"], cwd=tmp_path, capture_output=True,
                   timeout=60, check=True)
    assert canon_points((tmp_path / "out.txt").read_text()) == canon_points((DATA / f"{name}.expected").read_text())


def _canon_xz(text: str):
    """(x, y, z, centre x, centre z) of each motion in an XZ-plane trace (ARC_FEED lists Z first)."""
    pts = []
    for ln in text.splitlines():
        m = CANON.search(ln)
        if m:
            v = [float(x) for x in m.group(2).split(",")]
            if m.group(1) == "ARC_FEED":
                pts.append((v[1], v[5], v[0], v[3], v[2]))
            else:
                pts.append((v[0], v[1], v[2], None, None))
    return pts


def test_g18_compensation_matches_linuxcnc():
    # compensation in the XZ plane: the same rules in the plane's own axes (Z first, X second)
    prog = load_program(str(DATA / "g18_comp.ngc"))
    ref = _canon_xz((DATA / "g18_comp.expected").read_text())
    r = prog.records
    assert len(r) == len(ref) == 13
    for k, (x, y, z, cx, cz) in enumerate(ref):
        assert (r["x"][k], r["y"][k], r["z"][k]) == pytest.approx((x, y, z), abs=1e-4)
        if cx is not None:
            assert (r["cx"][k], r["cz"][k]) == pytest.approx((cx, cz), abs=1e-4)
    # G19 compensation is refused, as LinuxCNC does
    with pytest.raises(GCodeError, match="XY and XZ planes"):
        load_program(b"G21 G19 G41.1 D2 G1 Y10 Z0 F100\n", path="t.ngc")


@pytest.mark.skipif(shutil.which("rs274") is None, reason="LinuxCNC's rs274 is not installed; stored traces are used")
def test_stored_g18_trace_is_what_rs274_prints(tmp_path):
    shutil.copy(DATA / "g18_comp.ngc", tmp_path / "g18_comp.ngc")
    subprocess.run(["rs274", "-g", "g18_comp.ngc", "out.txt"], cwd=tmp_path, capture_output=True, timeout=60,
                   check=True)
    assert _canon_xz((tmp_path / "out.txt").read_text()) == _canon_xz((DATA / "g18_comp.expected").read_text())


@pytest.mark.skipif(shutil.which("rs274") is None, reason="LinuxCNC's rs274 is not installed")
def test_linuxcnc_comp_example_g17_and_g18_live(tmp_path):
    """LinuxCNC's own comp.ngc (G17 and G18 compensation, read from ../shared) against rs274 run
    on it here with the shared inch tool table (T1: D 6 mm)."""
    from conftest import REALDATA, SHARED

    ngc = REALDATA / "gcode_corpus" / "linuxcnc_nc_files" / "comp.ngc"
    tbl = SHARED / "linuxcnc" / "config" / "tool_rs274_inch.tbl"
    if not (ngc.is_file() and tbl.is_file()):
        pytest.skip("shared LinuxCNC files not present")
    import sys
    sys.path.insert(0, str(Path(__file__).parent))
    from test_linuxcnc_interp import canon_motion, our_motion

    shutil.copy(tbl, tmp_path / "tool.tbl")
    subprocess.run(["rs274", "-g", "-t", "tool.tbl", str(ngc), "out.txt"], cwd=tmp_path, capture_output=True,
                   timeout=60, check=True)
    expected = canon_motion(tmp_path / "out.txt")
    radii = {1: 0.23622047 / 2 * INCH, 2: 0.11811024 / 2 * INCH, 3: 0.39370079 / 2 * INCH}
    ours = our_motion(load_program(ngc, InterpreterSettings(dialect="linuxcnc", comp_radii=radii)))
    assert [k for k, _, _ in ours] == [k for k, _, _ in expected] and len(ours) == 45
    for (k, ev, _), (_, ov, _) in zip(expected, ours):
        n = 9 if k == "ARC_FEED" else 6
        np.testing.assert_allclose(ov[:n], ev[:n], atol=2e-4)


def test_lathe_tool_orientation_moves_the_controlled_point():
    # G42.1 D0.6 L2 in G18: LinuxCNC 2.9's rs274 (run here) puts the path 0.3 lower in X and Z
    # than with L0 (the imaginary tool tip of orientation 2 is the controlled point)
    src = b"G18 G21 G90 F100\nG0 X10 Z5\nG42.1 D0.6 L{}\nG1 X10 Z0\nG1 X12 Z-5\nG1 Z-10\nG40\nG0 X20\nM2\n"
    rs274 = {0: [(10.3, 0.0578), (12.2785, -4.8886), (12.3, -5.0), (12.3, -10.0)],
             2: [(10.0, -0.2422), (11.9785, -5.1886), (12.0, -5.3), (12.0, -10.3)]}
    for orient, ends in rs274.items():
        prog = load_program(src.replace(b"{}", str(orient).encode()), InterpreterSettings(dialect="linuxcnc"),
                            path="l.ngc")
        r = prog.records[(prog.records["kind"] != 0)][:4]
        np.testing.assert_allclose(np.c_[r["x"], r["z"]], ends, atol=1e-4)
