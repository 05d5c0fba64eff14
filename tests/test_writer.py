"""Writer: byte-identical round trips on real programs, feed changes, splits, and self-proof."""
import math
import re
import subprocess
import sys

import numpy as np
import pytest

from conftest import SAMPLES, realdata_files
from mtwin.errors import GCodeError, WriteError
from mtwin.gcode.interpreter import InterpreterSettings, load_program
from mtwin.gcode.records import ARC_CCW, ARC_CW, FL_PROBE, FL_ROTARY, FL_SYNC, LINEAR, move_lengths
from mtwin.gcode.verify import compare
from mtwin.gcode.writer import Split, rewrite, scale_feeds

PROGRAMS = sorted(SAMPLES.glob("*.nc")) + realdata_files()


def _load(path):
    try:
        return load_program(path, InterpreterSettings(lenient=True))
    except GCodeError as exc:
        pytest.skip(f"rejected: {exc.message[:60]}")


@pytest.mark.parametrize("path", PROGRAMS, ids=[p.name for p in PROGRAMS])
def test_scale_1_is_byte_identical(path):
    prog = _load(path)
    assert scale_feeds(prog, 1.0) == path.read_bytes()


@pytest.mark.parametrize("path", PROGRAMS, ids=[p.name for p in PROGRAMS])
def test_scale_changes_only_feeds_and_keeps_geometry(path):
    prog = _load(path)
    if prog.is_macro:
        try:
            out = scale_feeds(prog, 0.8)
        except WriteError as exc:
            # an F that is an expression, or a loop line run with different feeds: refused clearly
            assert re.search(r"macro expression|runs several moves|cannot split", str(exc)), str(exc)
            pytest.skip(f"macro program, rewrite refused: {exc}")
    else:
        out = scale_feeds(prog, 0.8)
    new = load_program(out, InterpreterSettings(lenient=True), path=str(path))
    assert compare(prog, new) is None
    feed = (prog.records["kind"] == LINEAR) | (prog.records["kind"] >= ARC_CW) & (prog.records["kind"] <= ARC_CCW)
    feed &= prog.records["feed"] > 0  # (--lenient: a feed left to the calling program stays 0)
    # threads and rigid taps run at pitch x spindle speed, probing feeds are part of the
    # measurement: the writer leaves both alone
    feed &= (prog.records["flags"] & (FL_SYNC | FL_PROBE)) == 0
    if feed.any():
        ratio = new.records["feed"][feed] / prog.records["feed"][feed]
        assert np.all(np.abs(ratio - 0.8) < 0.8e-3 * 1.001)  # F written to within 0.1 %
    # lines that differ contain an F word
    for a, b in zip(prog.data.splitlines(), out.splitlines()):
        if a != b:
            assert b"F" in b.upper()


def test_max_feed_clamps_and_inserts_f_where_needed():
    src = b"G21 G90\nG1 X10 F2000\nX20\nG0 X0\nG1 X5 F100\n"
    prog = load_program(src, path="t.nc")
    out = scale_feeds(prog, 1.0, max_feed=1500)
    assert out == b"G21 G90\nG1 X10 F1500\nX20\nG0 X0\nG1 X5 F100\n"


def test_f_inserted_when_modal_feed_must_change():
    src = b"G1 X1 F100\nX2\nX3\n"
    prog = load_program(src, path="t.nc")
    feeds = np.array([np.nan, 200.0, np.nan])
    out = rewrite(prog, feeds)
    # line 3 inherits 200 from the inserted word unless told otherwise: it must get F100 back
    assert out == b"G1 X1 F100\nX2 F200\nX3 F100\n"


def test_crlf_comments_and_case_preserved():
    src = b"%\r\n(hdr)\r\nn10 g1 x1 f100 (cut)\r\nn20 x2\r\n%\r\n"
    prog = load_program(src, path="t.nc")
    out = scale_feeds(prog, 1.5)
    assert out == b"%\r\n(hdr)\r\nn10 g1 x1 f150 (cut)\r\nn20 x2\r\n%\r\n"


def test_split_linear_and_arcs_on_path():
    src = (b"G21 G90 G17\nF500\nG0 X0 Y0 Z5\nG1 Z-1\nG1 X10 Y5\nG2 X20 Y5 R5\nG3 X10 Y5 R-5\n"
           b"G91 G1 X1.5 Y1.5\nG2 X2 I1\nG90 G20 G1 X1.2345 Y0.5 F20\nM30\n")
    prog = load_program(src, path="t.nc")
    splits = {i: Split([0.25, 0.6], [400.0, 300.0, 200.0]) for i, r in enumerate(prog.records)
              if r["kind"] in (LINEAR, ARC_CW, ARC_CCW) and r["line"] > 4}
    out = rewrite(prog, splits=splits)
    new = load_program(out, path="t.nc")
    assert compare(prog, new, tol=1e-3) is None
    assert new.records.size == prog.records.size + 2 * len(splits)
    # the G91 line after the split still ends where it did: increments add up exactly
    assert new.records["x"][-1] == pytest.approx(prog.records["x"][-1], abs=1e-9)


def test_split_refused_inside_canned_cycle():
    prog = load_program(b"G0 Z5\nG81 X1 Y1 Z-2 R1 F100\n", path="t.nc")
    i = int(np.flatnonzero(prog.records["kind"] == LINEAR)[0])
    with pytest.raises(WriteError, match="canned"):
        rewrite(prog, splits={i: Split([0.5], [100.0, 50.0])})


def test_conflicting_feeds_on_one_line_refused():
    prog = load_program(b"G0 Z5\nG81 X1 Y1 Z-2 R1 F100\nX2\n", path="t.nc")
    feed = np.full(prog.records.size, np.nan)
    lin = np.flatnonzero(prog.records["kind"] == LINEAR)
    feed[lin[0]] = 50.0
    feed[lin[1]] = 60.0
    out = rewrite(prog, feed)  # different lines: fine
    assert b"F50" in out and b"F60" in out
    prog = load_program(b"G0 Z5\nG91 G81 X1 Y1 Z-2 R-1 L2 F100\n", path="t.nc")
    lin = np.flatnonzero(prog.records["kind"] == LINEAR)
    feed = np.full(prog.records.size, np.nan)
    feed[lin[0]], feed[lin[1]] = 50.0, 60.0
    with pytest.raises(WriteError, match="different feeds"):
        rewrite(prog, feed)


def test_verify_detects_changed_geometry():
    a = load_program(b"G1 X10 Y0 F100\nG1 Y10\n", path="a.nc")
    b = load_program(b"G1 X10 Y0 F300\nG1 Y10.01\n", path="b.nc")
    diff = compare(a, b)
    assert diff is not None and diff.line_a == 2 and diff.line_b == 2
    c = load_program(b"G1 X5 F100\nX10\nG1 Y10\n", path="c.nc")
    assert compare(a, c) is None  # a split of line 1
    d = load_program(b"G0 X10 Y0\nG1 Y10 F100\n", path="d.nc")
    assert compare(a, d) is not None  # rapid instead of feed


def test_spiral_arcs_split_on_the_spiral():
    # a radius mismatch within LinuxCNC's tolerance (10 -> 10.02 mm) is a spiral; --lenient
    # takes larger ones (a post rounding to 0.05 mm) the same way, with a warning
    src = b"G21 G90 G17 F500\nG0 X10 Y0 Z0\nG3 X0 Y10.02 I-10 J0\nM30\n"
    prog = load_program(src, path="t.nc")
    out = rewrite(prog, splits={1: Split([0.5], [400.0, 300.0])})
    new = load_program(out, path="t.nc")
    assert compare(prog, new) is None
    mid = new.records[1]
    assert math.hypot(mid["x"], mid["y"]) == pytest.approx(10.01, abs=2e-4)
    coarse = b"G21 G90 G17 F500\nG0 X0.3 Y0 Z0\nG3 X0 Y0.27 I-0.3 J0\nM30\n"
    with pytest.raises(GCodeError, match="radius"):
        load_program(coarse, path="t.nc")
    lenient = load_program(coarse, InterpreterSettings(lenient=True), path="t.nc")
    assert "spiral" in str(lenient.warnings[0])
    with pytest.raises(GCodeError, match="radius"):  # 3 mm off: not a rounding error
        load_program(b"G0 X10 Y0\nG3 X0 Y13 I-10 J0 F100\n", InterpreterSettings(lenient=True), path="t.nc")


def test_rotary_axes_are_kept_and_compared():
    src = b"G21 G90 G0 X0 Y0 Z5 A0\nG1 X10 A90 F300\nG91 B15\nG90 G1 Y10 F200\nM30\n"
    prog = load_program(src, path="t.nc")
    r = prog.records
    assert list(r["a"]) == [0, 90, 90, 90] and list(r["b"]) == [0, 0, 15, 15]
    assert scale_feeds(prog, 1.0) == src
    # the same path with a different A end: verify names the rotary axis
    other = load_program(src.replace(b"A90", b"A45"), path="u.nc")
    assert "A/B/C" in str(compare(prog, other))
    # feeds scale; a move turning a rotary axis is never split; the 3-axis twin refuses it
    assert compare(prog, load_program(scale_feeds(prog, 0.5), path="t.nc")) is None
    with pytest.raises(WriteError, match="beyond X/Y/Z"):
        rewrite(prog, splits={1: Split([0.5], [100.0, 50.0])})
    out = rewrite(prog, splits={3: Split([0.5], [100.0, 50.0])})
    assert compare(prog, load_program(out, path="t.nc")) is None
    from mtwin.twin import Twin
    with pytest.raises(GCodeError, match="rotary A/B/C"):
        Twin().plan(prog)


def test_lenient_control_bytes_and_feeds_left_to_the_caller():
    src = b"\x01G21 G90\nG0 X0 Y0\nG1 X10\nG1 Y10 F100\nM30\n"
    with pytest.raises(GCodeError, match="0x01"):
        load_program(src, path="t.nc")
    with pytest.raises(GCodeError, match="zero feed"):
        load_program(src[1:], path="t.nc")
    prog = load_program(src, InterpreterSettings(lenient=True), path="t.nc")
    msgs = " | ".join(str(w) for w in prog.warnings)
    assert "t.nc:1:1: warning: control byte 0x01" in msgs and "t.nc:3:1: warning: feed move with no F" in msgs
    assert list(prog.records["feed"]) == [0.0, 0.0, 100.0]
    # the file is written back byte for byte, the known feed scaled, the unknown one left alone
    assert scale_feeds(prog, 1.0) == src
    assert scale_feeds(prog, 0.5) == src.replace(b"F100", b"F50")
    from mtwin.twin import Twin
    with pytest.raises(GCodeError, match="feed rate 0"):
        Twin().plan(prog)


def test_spindle_synchronised_moves():
    # G33.1 rigid tap: in and back out at pitch x speed; G33 a single thread pass
    src = b"G21 G90 G0 X0 Y0 Z1\nS1000 M3\nG1 X5 F300\nG33.1 Z-1.2 K0.1\nG0 Z5\nG33 Z-10 K1.5\nM2\n"
    prog = load_program(src, InterpreterSettings(dialect="linuxcnc"), path="t.ngc")
    r = prog.records
    assert [float(z) for z in r["z"][2:4]] == [-1.2, 1.0]
    assert list(r["feed"][2:4]) == [100.0, 100.0] and r["feed"][-1] == 1500.0
    # a feed override leaves them alone; a spindle override moves them with the spindle
    out = scale_feeds(prog, 0.5)
    assert out == src.replace(b"F300", b"F150")
    new = load_program(scale_feeds(prog, 1.0, spindle=2.0), InterpreterSettings(dialect="linuxcnc"), path="t.ngc")
    assert new.records["feed"][-1] == 3000.0
    feeds = np.full(r.size, np.nan)
    feeds[2] = 50.0
    with pytest.raises(WriteError, match="synchronised"):
        rewrite(prog, feeds)
    with pytest.raises(GCodeError, match="pitch"):
        load_program(b"G33.1 Z-1 K0.1\n", path="t.ngc")  # no spindle speed


def test_secondary_linear_axes_follow_the_units():
    prog = load_program(b"G20 G90 G0 X0 W0\nG1 W1 F10\nG91 W-0.5\nM30\n", path="t.ngc")
    assert list(prog.records["w"]) == [0.0, 25.4, 12.7]
    assert list(prog.records["flags"] & FL_ROTARY != 0) == [False, True, True]


def test_probe_moves_under_lenient():
    src = b"G21 G90 G0 X0 Y0 Z5\nG38.2 Z-10 F50\nG0 Z5\nG1 X10 F300\nM30\n"
    with pytest.raises(GCodeError, match="probe"):
        load_program(src, path="t.ngc")
    prog = load_program(src, InterpreterSettings(lenient=True), path="t.ngc")
    r = prog.records
    assert r["z"][1] == -10.0 and r["feed"][1] == 50.0 and "probe move taken" in str(prog.warnings[0])
    # the probing feed is part of the measurement: scaling leaves it, changing it is refused
    assert scale_feeds(prog, 0.5) == src.replace(b"F300", b"F150")
    feeds = np.full(r.size, np.nan)
    feeds[1] = 100.0
    with pytest.raises(WriteError, match="probe"):
        rewrite(prog, feeds)
    from mtwin.twin import Twin
    with pytest.raises(GCodeError, match="probe"):
        Twin().plan(prog)


# The real programs that are rejected (with --lenient), each for the reason that is really its
# cause (issue 2:
# "every one must parse, or be rejected with a clear, correct message").  Anything else
# rejected, or one of these accepted, fails: the list is kept true.
REJECTED = {
    # a Fusion 360 post that wrote '#' (no number) on its first line
    "fusion360_led_floor/6mm/1002.nc": "'#' must be followed by a number",
    # LinuxCNC rejects these too, or they are not programs to run on their own
    "linuxcnc_nc_files/nestedcall.ngc": "callsub",
    "linuxcnc_tests_interp/oword-unwind/test.ngc": "division by zero",
    "linuxcnc_tests_interp/python/error/error.ngc": "arc radius",
    "linuxcnc_tests_interp/python-self/test.ngc": "retainparam1",
    "linuxcnc_tests_interp/subroutine-return/orig.ngc": "o<sub> call",
    "linuxcnc_tests_interp/value-returned/test.ngc": "returns4711",
    "linuxcnc_tests_interp/iniparam/test.ngc": "INI-file",
}


def test_every_real_program_parses_or_is_rejected_for_its_real_cause():
    from conftest import REALDATA, require_realdata

    require_realdata()
    rejected = {}
    n = 0
    for path in realdata_files():
        if "/bad/" in str(path):
            continue
        n += 1
        try:
            load_program(path, InterpreterSettings(lenient=True))
        except GCodeError as exc:
            assert exc.location is not None and exc.location.line >= 1
            rejected[str(path.relative_to(REALDATA / "gcode_corpus")) if "gcode_corpus" in str(path)
                     else str(path)] = exc.message
    assert set(rejected) == set(REJECTED), rejected
    for name, why in REJECTED.items():
        assert why in rejected[name], (name, rejected[name])
    assert n - len(rejected) >= 272  # of the 280 good files


def test_zero_in_a_program_without_leading_zeros_is_written_as_a_number():
    # (found by splitting every move of the real programs: an R arc of face_slot_inch.nc,
    # written back in IJK form, got 'I.' for I = 0 — no number at all)
    from mtwin.gcode.numfmt import NumberStyle

    st = NumberStyle(leading_zero=False)
    assert [st.coord(v) for v in (0.0, 0.5, -0.5, -0.0)] == ["0.", ".5", "-.5", "0."]
    path = SAMPLES / "face_slot_inch.nc"
    prog = load_program(path)
    i = int(np.flatnonzero(prog.records["line"] == 29)[0])  # N340G91G2X0.Y.25R.125
    out = rewrite(prog, splits={i: Split([0.37], [450.0, 550.0])})
    assert b"I0.J.125" in out
    assert compare(prog, load_program(out, path=str(path))) is None


def test_a_split_piece_under_10_um_is_refused():
    # (found by splitting moves of the real programs: a 2 um last piece of a 10 um move was
    # within the verify tolerance of the move's end, and the self-proof failed)
    prog = load_program(b"G21 G90\nG0 X0 Y0\nG1 X0.0105 F300\nX10\n", path="s.nc")
    with pytest.raises(WriteError, match="pieces must be at least 0.01 mm"):
        rewrite(prog, splits={1: Split([0.81], [300.0, 200.0])})
    out = rewrite(prog, splits={2: Split([0.5], [300.0, 200.0])})
    assert compare(prog, load_program(out, path="s.nc")) is None


def test_random_splits_of_every_real_program_verify():
    # up to 15 moves of every plain real program split at 1-3 random fractions with random
    # feeds: the writer proves its output (raises otherwise) and verify agrees
    import random

    from mtwin.gcode.records import (FL_CANNED, FL_COMP, FL_CORNER, FL_DIAMETER, FL_FIRST_IN_LINE, FL_MIRROR,
                                     FL_POLAR, FL_SUB)

    rng = random.Random(7)
    done = 0
    locked = FL_CANNED | FL_SUB | FL_COMP | FL_DIAMETER | FL_ROTARY | FL_POLAR | FL_CORNER | FL_MIRROR | FL_SYNC | FL_PROBE
    for path in PROGRAMS:
        try:
            prog = load_program(path, InterpreterSettings(lenient=True))
        except GCodeError:
            continue
        r = prog.records
        if prog.is_macro or not r.size:
            continue
        lens = move_lengths(r)
        _, counts = np.unique(r["line"], return_counts=True)
        once = set(np.unique(r["line"])[counts == 1].tolist())
        cand = [int(i) for i in np.flatnonzero(np.isin(r["kind"], [LINEAR, ARC_CW, ARC_CCW])
                                               & ((r["flags"] & FL_FIRST_IN_LINE) != 0) & ((r["flags"] & locked) == 0)
                                               & (r["turns"] == 0) & (r["feed"] > 0) & (lens > 0.1))
                if int(r["line"][i]) in once]
        if not cand:
            continue
        splits = {}
        for i in rng.sample(cand, min(15, len(cand))):
            ts = sorted(rng.sample([0.13, 0.37, 0.5, 0.81], rng.randint(1, 3)))
            splits[i] = Split(ts, [float(r["feed"][i]) * rng.uniform(0.5, 1.5) for _ in range(len(ts) + 1)])
        out = rewrite(prog, None, None, splits)
        assert compare(prog, load_program(out, InterpreterSettings(lenient=True), path=str(path))) is None, path.name
        done += 1
    from conftest import REALDATA

    if not REALDATA.is_dir():  # a plain clone: the bundled samples were split above
        assert done >= 3
        pytest.skip(f"{REALDATA} not present: only {done} bundled samples were split")
    assert done >= 150
