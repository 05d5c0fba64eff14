"""Feeds the program does not set on the line itself: a subprogram entered at several feeds,
and cutter compensation whose radius the twin does not know (a real program, LinuxCNC's
``mmount.ngc``, was refused "internal check failed" and then raised a finishing contour 17x)."""
from __future__ import annotations

import numpy as np

import mtwin
from mtwin.gcode.writer import rewrite
from mtwin.optimize.run import OptimizeOptions, optimize

SUB_TWICE = b"""G21 G90 G17 G94
(T1 D=6 CR=0 - flat end mill)
(MTWIN STOCK -10,-10,-10,90,30,0)
o100 sub
G1 X#1 F#2
G1 Y5
G1 X0
G1 Y0
o100 endsub
T1 M6
S8000 M3
G0 X0 Y0 Z5
G1 Z-1 F100
F300
o100 call [40] [300]
F150
o100 call [60] [150]
G0 Z5
M30
"""


def test_a_subprogram_entered_at_two_feeds_keeps_its_callers_feeds():
    tw = mtwin.Twin()
    prog = tw.load(SUB_TWICE, path="sub.ngc")
    r = optimize(tw, prog, OptimizeOptions(force_limit=2000.0, chip_limit="none", limits="learned"))
    # lines 6-8 run at 300 in the first call and 150 in the second: one F word cannot give each
    # run its own, so they keep the caller's feed (before, the writer refused the answer)
    why = "runs at its caller's feeds (a subprogram or loop entered at several feeds)"
    assert set(r.kept[why]) >= {6, 7, 8}
    new = tw.load(r.output, path="sub.ngc")
    for li in (6, 7, 8):
        assert sorted(set(new.records["feed"][new.records["line"] == li].tolist())) == [150.0, 300.0]


LOOP = b"""G21 G90 G17 G94
#1=0
G0 X0 Y0 Z1
G1 Z0 F100
o1 while [#1 LT 2]
G1 X10
G1 Y10 F200
G1 X0
#1=[#1+1]
o1 endwhile
M30
"""


def test_the_writer_puts_the_modal_feed_back_after_a_changed_macro_line():
    # line 8 runs at 200 on both passes; the loop then goes back to line 6, which ran at 100
    # on the first pass and at line 8's feed on the second: it takes no word of its own, so a
    # changed F on line 8 must not carry into it
    tw = mtwin.Twin()
    prog = tw.load(LOOP, path="loop.ngc")
    rec = prog.records
    feeds = np.full(rec.size, np.nan)
    feeds[rec["line"] == 8] = 300.0
    out = rewrite(prog, feeds)  # (its self-check proves every move's feed; before, it refused)
    new = tw.load(out, path="loop.ngc").records
    assert new["feed"][new["line"] == 8].tolist() == [300.0, 300.0]
    assert new["feed"][(new["line"] == 6) & (new["kind"] != 0)].tolist() == [100.0, 200.0]
    assert b"G1 X0 F300\nF200\n" in out


COMP = b"""G21 G90 G17 G94
(T1 D=6 CR=0 - flat end mill)
(MTWIN STOCK -20,-20,-10,60,60,0)
T1 M6
S8000 M3
G0 X-10 Y-10 Z5
G1 Z-1 F300
G41 D1 G1 X0 Y0
G1 X40
G1 Y40
G1 X0
G1 Y0
G40 G0 Z5
M30
"""


def test_cuts_under_compensation_of_unknown_radius_keep_their_feeds(tmp_path):
    tw = mtwin.Twin()
    prog = tw.load(COMP, path="comp.nc")
    r = optimize(tw, prog, OptimizeOptions(force_limit=2000.0, chip_limit="none", limits="learned", tolerance=0.5,
                                           rough_tolerance=0.5))
    assert set(r.kept["cutter compensation of unknown radius"]) >= {9, 10, 11, 12}
    assert any("cutter compensation (G41/G42) whose radius the twin does not know" in w for w in r.warnings)
    new = tw.load(r.output, path="comp.nc").records
    for li in (9, 10, 11, 12):
        assert new["feed"][new["line"] == li].tolist() == [300.0]
    # with the register given (0: a path the CAM system compensated), the twin knows the cut
    twin_file = tmp_path / "t.toml"
    twin_file.write_text("[cutter_comp]\nD1 = 0\n")
    tw0 = mtwin.Twin.from_toml(str(twin_file))
    # (a loose tolerance: the slot's corners would hold it at its feed on the default machine)
    loose = OptimizeOptions(force_limit=2000.0, chip_limit="none", limits="learned", tolerance=0.5,
                            rough_tolerance=0.5)
    r0 = optimize(tw0, tw0.load(COMP, path="comp.nc"), loose)
    assert "cutter compensation of unknown radius" not in r0.kept
    assert r0.after.cycle_time < r0.before.cycle_time
