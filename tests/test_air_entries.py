"""Plunges through proven air (optimize.guards.air_entries): a contour cut in depth passes, each
plunging from a clearance height at the cutting feed (as Fusion 360 for personal use writes its
rapids), runs the part of each plunge above what earlier passes cut at the air feed and slows to
its own feed ENTRY_CLEARANCE above the material — never where a pass meets uncut stock."""
from __future__ import annotations

import numpy as np
import pytest

import mtwin
from mtwin.gcode.verify import compare
from mtwin.motion.simulate import program_cutting
from mtwin.optimize.guards import ENTRY_CLEARANCE, air_entries, placed
from mtwin.optimize.run import OptimizeOptions, optimize


def passes(n: int, step: float = 1.0, stock: str = "", tool: str = "(T1 D=6 CR=0 - flat end mill)") -> bytes:
    """A square contour in ``n`` passes ``step`` deep, each entered by a plunge from Z10."""
    out = ["G21 G90 G17 G94", tool, stock, "T1 M6", "S10000 M3", "G0 X0 Y0", "G0 Z10"]
    for k in range(1, n + 1):
        out += [f"G1 Z{-k * step:g} F200", "G1 X40 F800", "Y30", "X0", "Y0", "G1 Z10 F800"]
    out += ["M5", "M30"]
    return "\n".join(x for x in out if x).encode() + b"\n"


def _line(prog_bytes: bytes, text: str) -> int:
    return [ln.strip() for ln in prog_bytes.decode().splitlines()].index(text) + 1


def test_each_later_plunge_runs_its_air_fast_and_slows_above_the_last_pass():
    tw = mtwin.Twin()
    src = passes(4)
    prog = tw.load(src, path="passes.nc")
    r = optimize(tw, prog, OptimizeOptions())
    out = r.output.decode()
    assert compare(prog, tw.load(r.output, path="out.nc")) is None  # the same path
    ent = {e["line"]: e for e in r.air_entries}
    # the first plunge meets uncut stock of a guessed size: nothing proves its air
    assert _line(src, "G1 Z-1 F200") not in ent
    for k in (2, 3, 4):
        e = ent[_line(src, f"G1 Z{-k} F200")]
        assert e["proven_by"] == "earlier cuts"
        # the pass before cut down to -(k-1): slow from 1 mm above it, its own feed below
        assert e["air_to_z"] == pytest.approx(-(k - 1) + ENTRY_CLEARANCE)
        assert e["feed"] == 200.0 and e["air_feed"] > 200.0
    # the plunge line is split: the air part at the air feed, then the program's own words
    lines = out.splitlines()
    for k in (2, 3, 4):
        i = lines.index(f"G1 Z{-k}. F200")
        air = float(lines[i - 1].split()[1][1:])
        assert lines[i - 1].startswith("G1 Z") and air == pytest.approx(-(k - 1) + ENTRY_CLEARANCE)
        assert lines[i - 1].endswith(f"F{e['air_feed']:g}")
    assert r.after.cycle_time < r.before.cycle_time
    # the cutting part of each plunge keeps its feed: the load on entry is the program's own
    assert r.after.peak_load <= r.before.peak_load * 1.001
    # kept means kept: the split plunges are no longer listed as kept
    kept = r.kept.get("plunges, canned cycles, parameter feeds (never set)", [])
    assert not set(kept) & set(ent)


def test_a_given_stock_top_proves_the_air_above_it():
    tw = mtwin.Twin()
    src = passes(1, stock="(MTWIN STOCK -10,-10,-20,50,40,-3)")
    prog = tw.load(src, path="stock.nc")
    r = optimize(tw, prog, OptimizeOptions())
    (e,) = [e for e in r.air_entries if e["line"] == _line(src, "G1 Z-1 F200")]
    # the stock's top is at -3: the whole plunge to -1 is above it by more than the clearance
    assert e["proven_by"] == "stock top" and e["air_to_z"] == pytest.approx(-1.0)


def test_a_ball_nose_leaves_material_above_its_tip_and_the_proof_counts_it():
    tw = mtwin.Twin()
    src = passes(2, tool="(T1 D=6 CR=3 - ball end mill)")
    prog = tw.load(src, path="ball.nc")
    rec = prog.records
    plunge = np.zeros(len(rec), bool)
    second = int(np.flatnonzero(rec["line"] == _line(src, "G1 Z-2 F200"))[0])
    plunge[second] = True
    (e,) = air_entries(prog, program_cutting(tw, prog), plunge, {1}, float("inf"), None)
    # a ball 3 mm in radius at -1 clears full width only 3 mm higher: material can stand at +2
    assert e.material == pytest.approx(-1.0 + 3.0)
    assert e.z_air == pytest.approx(2.0 + ENTRY_CLEARANCE)


def test_a_move_from_the_assumed_start_proves_nothing():
    tw = mtwin.Twin()
    # the first G0 X Y runs at the interpreter's assumed Z0: the machine may be anywhere
    prog = tw.load(b"G21 G90\n(T1 D=6 CR=0 - flat end mill)\nT1 M6\nS9000 M3\nG0 X5 Y5\nG0 Z10\nG1 Z-2 F100\n"
                   b"G1 X30 F500\nM30\n", path="first.nc")
    ok = placed(prog.records)
    assert not ok[0] and not ok[1] and ok[2]
    plunge = (prog.records["line"] == 7)
    assert air_entries(prog, program_cutting(tw, prog), plunge, {1}, float("inf"), None) == []


def _entries(src: bytes, line_text: str):
    tw = mtwin.Twin()
    prog = tw.load(src, path="p.nc")
    rec = prog.records
    plunge = np.zeros(len(rec), bool)
    plunge[int(np.flatnonzero(rec["line"] == _line(src, line_text))[-1])] = True
    cut = program_cutting(tw, prog)
    from mtwin.cutting.library import describes

    described = {int(t) for t in np.unique(rec["tool"]) if describes(cut, int(t))}
    return air_entries(prog, cut, plunge, described, float("inf"), None)


def test_a_second_fixtures_plunge_is_not_proven_by_the_firsts_cuts():
    # the same code on G54 and G55: the coordinates agree, the places do not (a review found
    # the G55 plunge "proven" 9 mm into uncut stock)
    part = "G0 X20 Y20\nG0 Z5\nG1 Z-5 F100\nG1 X40 F300\nG0 Z5\n"
    src = ("G21 G90 G17 G94\n(T1 D=6 CR=0 - flat end mill)\nT1 M6\nS8000 M3\nG54\n" + part + "G55\n" + part
           .replace("G1 Z-5 F100", "G1 Z-5. F100") + "M30\n").encode()
    assert _entries(src, "G1 Z-5. F100") == []


def test_a_thin_wall_between_two_slots_is_not_taken_for_air():
    # slots at Y0 and Y6.4 with a 6 mm end mill leave a 0.4 mm wall at Y3-3.4
    src = ("G21 G90 G17 G94\n(T1 D=6 CR=0 - flat end mill)\nT1 M6\nS8000 M3\nG0 X0 Y0\nG0 Z5\n"
           "G1 Z-4 F100\nG1 X40 F300\nG0 Z5\nG0 X0 Y6.4\nG1 Z-4 F100\nG1 X40 F300\nG0 Z5\nG0 X20 Y3.45\n"
           "G1 Z-5 F100\nM30\n").encode()
    assert _entries(src, "G1 Z-5 F100") == []


def test_a_drills_hole_proves_nothing_for_an_end_mill():
    # a 3 mm drill's hole (canned cycle) is no 6 mm end mill's sweep
    src = ("G21 G90 G17 G94\n(T1 D=3 CR=0 - drill)\n(T2 D=6 CR=0 - flat end mill)\nT1 M6\nS3000 M3\nG0 X20 Y20 Z5\n"
           "G81 X20 Y20 Z-10 R2 F100\nG80\nG0 Z5\nT2 M6\nS8000 M3\nG0 X20 Y20\nG0 Z5\nG1 Z-8 F100\nG1 X40 F300\n"
           "M30\n").encode()
    assert _entries(src, "G1 Z-8 F100") == []
