"""Each ``limited_by`` label is what bound the segment (issue 31): a small program that
reproduces each, and the figure that proves the label."""
from __future__ import annotations

import mtwin
from mtwin.optimize.run import OptimizeOptions, optimize


def _zigzag() -> bytes:
    lines = ["G21 G90 G17 G94", "(T1 D=6 CR=0 - flat end mill)", "(MTWIN STOCK -10,-10,-10,80,30,0)", "T1 M6",
             "S8000 M3", "G0 X0 Y0 Z5", "G0 Z-1", "G1 X40 F300"]
    x, y = 40.0, 0.0
    for _ in range(60):  # a 0.3 mm step-over raster: a finishing pass
        y += 0.3
        lines.append(f"G1 Y{y:.3f}")
        x = 0.0 if x > 20 else 40.0
        lines.append(f"G1 X{x:.3f}")
    # three 0.3-0.4 mm moves in the stock's corner: too short for the machine to reach speed
    lines += ["G0 Z5", "G0 X0 Y25", "G1 Z-1 F100", "G1 X2 Y25.3 F300", "G1 X2.3 Y25", "G1 X2 Y24.7", "G1 X2.3 Y25",
              "G0 Z5", "M30"]
    return ("\n".join(lines) + "\n").encode()


def test_labels_name_what_bound_each_segment():
    tw = mtwin.Twin()
    prog = tw.load(_zigzag(), path="zig.nc")
    # limits far above anything the cut needs: only the machine, the range and accuracy bind
    r = optimize(tw, prog, OptimizeOptions(force_limit=2000.0, chip_limit="none", limits="learned"))
    by = {(s["lines"][0], s["air"]): s for s in r.segments}
    assert by[(9, False)]["limited_by"] == "kept (finishing pass (feed per tooth kept))"
    assert by[(9, False)]["feed_after"] == 300.0
    short = by[(132, False)]
    assert short["limited_by"] == "machine acceleration/speed"
    assert short["feed_after"] == tw.machine.max_cutting_feed  # (at the top of the range, which it never reaches)
    air = by[(135, True)]
    assert air["limited_by"] == "feed range (air cut)" and air["feed_after"] == tw.machine.max_cutting_feed
    slot = by[(8, False)]
    assert slot["limited_by"] == "accuracy (contour error)" and 300.0 < slot["feed_after"] < tw.machine.max_cutting_feed
    assert slot["contour_error_after"] <= slot["contour_error_before"] + slot["contour_tolerance"] + 1e-9
    # a given load limit that binds: the slot near it (the rounds bring the re-simulated peak
    # under it, so the estimate ends a little below)
    r = optimize(tw, prog, OptimizeOptions(force_limit=60.0, chip_limit="none", limits="learned"))
    slot = [s for s in r.segments if s["lines"][0] == 8 and not s["air"]][0]
    assert slot["limited_by"] == "load" and 0.85 * 60.0 <= slot["peak_load_estimate"] <= 60.0
    assert r.after.peak_load <= 60.0
    # the chip load from physics (6061 named): the slot at the catalogue's 0.04 mm at Ø6
    r = optimize(tw.with_material("6061"), prog, OptimizeOptions())
    slot = [s for s in r.segments if s["lines"][0] == 8 and not s["air"]][0]
    assert slot["limited_by"] == "chip thickness"
    # F = 0.04 mm x 2 flutes x 8000 rpm = 640 at most; the rounds hold the re-simulated chip
    # under it (the axes overshoot the command at the slot's entry: a thicker chip there)
    assert 0.8 * 640.0 <= slot["feed_after"] <= 640.0
    from mtwin.layout import C_HMAX

    assert float(r.trace_after.cut[:, C_HMAX].max()) <= 0.04 * 1.001


def test_an_air_piece_entering_the_stock_takes_the_cut_s_feed_and_says_so():
    # a slot that starts outside the stock: its move's first piece is air and runs into the cut
    text = (b"G21 G90 G17 G94\n(T1 D=6 CR=0 - flat end mill)\n(MTWIN STOCK 0,-10,-10,80,30,0)\nT1 M6\nS8000 M3\n"
            b"G0 X-10 Y0 Z5\nG0 Z-1\nG1 X40 F300\nG0 Z5\nM30\n")
    tw = mtwin.Twin()
    prog = tw.load(text, path="entry.nc")
    r = optimize(tw, prog, OptimizeOptions(force_limit=100.0, chip_limit="none", limits="learned"))
    air = [s for s in r.segments if s["lines"][0] == 8 and s["air"]][0]
    cut = [s for s in r.segments if s["lines"][0] == 8 and not s["air"]][0]
    assert 300.0 < cut["feed_after"] < tw.machine.max_cutting_feed and cut["limited_by"] == "load"
    assert air["limited_by"] == "approach (the feed of the cut it enters)"
    assert air["feed_after"] == cut["feed_after"]
