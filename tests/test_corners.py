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
    with pytest.raises(GCodeError, match="arc is not supported"):
        _load(b"G21 G90\nG0 X0 Y0\nG1 X20 F300 ,R5\nG2 X30 Y10 R10\n")
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
