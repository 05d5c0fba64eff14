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
