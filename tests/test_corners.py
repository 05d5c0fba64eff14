"""Fanuc corner chamfering and rounding (,C / ,R): closed-form geometry, errors, writer."""
import math

import numpy as np
import pytest

from mtwin.errors import GCodeError, WriteError
from mtwin.gcode.interpreter import InterpreterSettings, load_program
from mtwin.gcode.records import ARC_CCW, ARC_CW, FL_CORNER, LINEAR
from mtwin.gcode.writer import Split, rewrite, scale_feeds

FANUC = InterpreterSettings(dialect="fanuc")


def _load(text: bytes, **kw):
    return load_program(text, InterpreterSettings(dialect="fanuc", **kw), path="corner.nc")


def test_radius_at_a_60_degree_turn_is_tangent_to_both_moves():
    prog = _load(b"G21 G90 G17\nG0 X0 Y0\nG1 X20 F300 ,R5\nG1 X30 Y17.320508075688775\nM30\n")
    r = prog.records
    assert list(r["kind"]) == [0, LINEAR, ARC_CCW, LINEAR]
    t = 5 * math.tan(math.radians(30))  # tangent length for a 60-degree change of direction
    assert (r["x"][1], r["y"][1]) == pytest.approx((20 - t, 0))
    u2 = np.array([0.5, math.sqrt(3) / 2])
    t2 = np.array([20, 0]) + t * u2
    arc = r[2]
    assert (arc["sx"], arc["sy"]) == pytest.approx((20 - t, 0))
    assert (arc["x"], arc["y"]) == pytest.approx(tuple(t2))
    c = np.array([arc["cx"], arc["cy"]])
    assert c == pytest.approx([20 - t, 5])  # square to the first move, r away
    assert np.linalg.norm(t2 - c) == pytest.approx(5)
    assert abs(np.dot(t2 - c, u2)) < 1e-9  # square to the second move at its start: tangent
    assert (r["sx"][3], r["sy"][3]) == pytest.approx(tuple(t2))
    assert r["line"][2] == 3 and r["feed"][2] == 300  # the corner belongs to the ,R block
    assert (r["flags"][1:] & FL_CORNER != 0).all()


def test_chamfer_and_clockwise_radius_and_inch():
    prog = _load(b"G20 G90 G17\nG0 X0 Y0\nG1 X1. F10 ,C.1\nY-1. ,R.2\nX0\nM30\n")
    r = prog.records
    assert list(r["kind"]) == [0, LINEAR, LINEAR, LINEAR, ARC_CW, LINEAR]
    mm = 25.4
    assert (r["sx"][2], r["sy"][2], r["x"][2], r["y"][2]) == pytest.approx((0.9 * mm, 0, mm, -0.1 * mm))
    arc = r[4]
    assert (arc["sx"], arc["sy"], arc["x"], arc["y"]) == pytest.approx((mm, -0.8 * mm, 0.8 * mm, -mm))
    assert (arc["cx"], arc["cy"]) == pytest.approx((0.8 * mm, -0.8 * mm))


def test_corner_in_a_macro_program_and_the_writer():
    src = b"%\nO1\n#1=5.\nG21 G90 G17\nG0 X0 Y0\nG1 X20 F300 ,R#1\nY10 ,C2.\nX0\nM30\n%\n"
    prog = _load(src)
    assert list(prog.records["kind"]) == [0, LINEAR, ARC_CCW, LINEAR, LINEAR, LINEAR]
    assert scale_feeds(prog, 1.0) == src
    out = scale_feeds(prog, 0.5)
    assert b"F150 ,R#1" in out and b",C2." in out
    with pytest.raises(WriteError, match="corner"):
        rewrite(_load(b"G21 G90\nG0 X0 Y0\nG1 X20 F300 ,R5\nY10\nM30\n"), splits={1: Split([0.5], [300.0, 200.0])})


def test_corner_errors():
    with pytest.raises(GCodeError, match="next move must be a G01") as info:
        _load(b"G21 G90\nG0 X0 Y0\nG1 X20 F300 ,R5\nG0 Y10\n")
    assert info.value.location.line == 3
    with pytest.raises(GCodeError, match="too large"):
        _load(b"G21 G90\nG0 X0 Y0\nG1 X20 F300 ,R5\nY3\n")
    with pytest.raises(GCodeError, match="too large"):
        _load(b"G21 G90\nG0 X-20 Y0\nG1 X0 F300 ,R100\nG2 X10 Y10 I10 J0\n")
    with pytest.raises(GCodeError, match="either ,C"):
        _load(b"G21 G90\nG0 X0 Y0\nG1 X20 F300 ,R5 ,C1\nY10\n")
    with pytest.raises(GCodeError, match="unsupported word ,A"):
        _load(b"G21 G90\nG0 X0 Y0\nG1 X20 F300 ,A30\n")
    with pytest.raises(GCodeError, match="not used"):
        _load(b"G21 G90\nG0 X0 Y0 ,R5\nG1 Y10 F100\n")


def test_a_cornered_program_simulates():
    from mtwin.twin import Twin

    twin = Twin()
    prog = twin.load(b"G21 G90 G17\nS8000 M3\nG0 X0 Y0 Z5\nG1 Z-1 F300\nG1 X20 ,R5\nY10 ,C2\nX0 ,R3\nY0\nG0 Z5\nM30\n",
                     path="c.nc")
    tr = twin.simulate(prog, cutting=False)
    assert tr.summary.cycle_time > 0


def test_radius_between_a_line_and_an_arc():
    # a line along +X into (0, 0), then a clockwise arc about (10, 0) heading +Y: a left turn
    # of 90 degrees.  The fillet's centre is 2 from the line (y = 2) and 10 + 2 from the arc's
    # centre: x = 10 - sqrt(12^2 - 2^2); it touches the arc on the line from (10, 0) to it.
    prog = _load(b"G21 G90 G17\nG0 X-20 Y0\nG1 X0 F300 ,R2\nG2 X10 Y10 I10 J0\nM30\n")
    r = prog.records
    assert list(r["kind"]) == [0, LINEAR, ARC_CCW, ARC_CW]
    ox, oy = 10 - math.sqrt(140), 2.0
    fil = r[2]
    assert (fil["cx"], fil["cy"]) == pytest.approx((ox, oy))
    assert (fil["sx"], fil["sy"]) == pytest.approx((ox, 0.0))
    t2 = np.array([10.0, 0.0]) + 10 * (np.array([ox, oy]) - [10, 0]) / 12
    assert (fil["x"], fil["y"]) == pytest.approx(tuple(t2))
    arc = r[3]
    assert (arc["sx"], arc["sy"]) == pytest.approx(tuple(t2)) and (arc["cx"], arc["cy"]) == (10.0, 0.0)
    assert (arc["x"], arc["y"]) == (10.0, 10.0)
    from mtwin.gcode.verify import compare
    assert compare(prog, _load(scale_feeds(prog, 0.5))) is None


def test_radius_between_two_arcs_and_chamfer_after_an_arc():
    # two clockwise quarter circles of radius 10 meeting at (10, 10): the first (about
    # (10, 0)) ends heading +X, the second (about (20, 10)) starts heading +Y, a left turn.
    # The fillet lies outside both circles: its centre is 11 from both centres.
    prog = _load(b"G21 G90 G17\nG0 X0 Y0\nG2 X10 Y10 I10 J0 F300 ,R1\nG2 X20 Y20 I10 J0\nM30\n")
    r = prog.records
    assert list(r["kind"]) == [0, ARC_CW, ARC_CCW, ARC_CW]
    fil = r[2]
    c = np.array([fil["cx"], fil["cy"]])
    h = math.sqrt(121 - 50)
    assert c == pytest.approx([15 - h / math.sqrt(2), 5 + h / math.sqrt(2)])
    for (sx, sy), cc in (((fil["sx"], fil["sy"]), [10, 0]), ((fil["x"], fil["y"]), [20, 10])):
        assert np.hypot(sx - c[0], sy - c[1]) == pytest.approx(1.0)  # on the fillet
        assert np.hypot(sx - cc[0], sy - cc[1]) == pytest.approx(10.0)  # and on its arc
    assert (r["x"][1], r["y"][1]) == pytest.approx((fil["sx"], fil["sy"]))
    assert (r["sx"][3], r["sy"][3]) == pytest.approx((fil["x"], fil["y"]))
    # a chamfer after an arc ends on the arc at chord distance c from the corner
    prog = _load(b"G21 G90 G17\nG0 X0 Y0\nG2 X10 Y10 I10 J0 F300 ,C2\nG1 X10 Y20\nM30\n")
    ch = prog.records[2]
    assert ch["kind"] == LINEAR
    assert np.hypot(ch["sx"] - 10, ch["sy"] - 10) == pytest.approx(2.0)
    assert np.hypot(ch["sx"] - 10, ch["sy"] - 0) == pytest.approx(10.0) and ch["sx"] < 10
    assert (ch["x"], ch["y"]) == pytest.approx((10.0, 12.0))


from hypothesis import HealthCheck, assume, given, settings, strategies as st  # noqa: E402

from mtwin.gcode.records import move_lengths  # noqa: E402
from mtwin.gcode.verify import compare  # noqa: E402

_coord = st.integers(-3000, 3000).map(lambda v: v / 100.0)


@st.composite
def _cornered(draw):
    lines = ["G21 G90 G17", "S5000 M3", "G0 X0 Y0 Z1", "G1 Z-1 F300"]
    for _ in range(draw(st.integers(2, 8))):
        corner = draw(st.sampled_from(["", "", " ,R1.5", " ,C1.", ",R0.5", " ,C0.3"]))
        if draw(st.booleans()):
            lines.append(f"G1 X{draw(_coord):.2f} Y{draw(_coord):.2f}{corner}")
        else:
            lines.append(f"G{draw(st.sampled_from([2, 3]))} X{draw(_coord):.2f} Y{draw(_coord):.2f} "
                         f"R{draw(st.integers(40, 90))}{corner}")
    lines.append("G1 X40 Y40\nM30")
    return ("\n".join(lines) + "\n").encode()


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(_cornered(), st.data())
def test_random_cornered_programs_rewrite_and_verify(src, data):
    try:
        prog = load_program(src, FANUC, path="c.nc")
    except GCodeError:
        assume(False)  # a corner too large for its moves, or an arc that cannot reach its end
    rec = prog.records
    feeds = np.full(rec.size, np.nan)
    splits = {}
    lines_done = set()
    for i in np.flatnonzero(np.isin(rec["kind"], [LINEAR, ARC_CW, ARC_CCW])):
        li = int(rec["line"][i])
        if li in lines_done:
            continue
        lines_done.add(li)
        same = np.flatnonzero(rec["line"] == li)
        if data.draw(st.booleans()):
            feeds[same] = data.draw(st.integers(20, 5000))  # a line's moves (with its corner) share F
        if (len(same) == 1 and not rec["flags"][i] & FL_CORNER and i > 1 and move_lengths(rec[i:i + 1])[0] > 0.05
                and data.draw(st.booleans())):
            splits[i] = Split([0.5], [300.0, 200.0])
    out = rewrite(prog, feeds, None, splits)  # raises if its own proof fails
    assert compare(prog, load_program(out, FANUC, path="c.nc"), tol=1e-3) is None


def test_malformed_comma_words_are_clear_errors():
    # (found by fuzzing: a comma before two letters made the message itself fail)
    for text, msg, col in ((b",CD G213.6\n", "unknown word 'CD'", 2), (b"G1 X1 ,R\n", "',R' is not followed", 7),
                           (b"G1 X1 ,\n", "unexpected character ','", 7)):
        with pytest.raises(GCodeError, match=msg) as info:
            _load(text)
        assert info.value.location.col == col
