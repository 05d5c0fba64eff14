"""``mtwin optimize part.nc`` with default options on programs as CAM systems and people write
them (issue 18): limits learned from the program, feeds kept where the twin does not know
the cut, finishing passes, accuracy, estimates that hold, refusals that say why."""
from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

import mtwin
from conftest import REALDATA
from mtwin.gcode.verify import compare
from mtwin.optimize import OptimizeOptions, optimize
from mtwin.optimize.guards import contour_error, weighted_percentile
from mtwin.optimize.run import _feed_samples

SAMPLES = Path(__file__).resolve().parents[1] / "samples"


def run_cli(*args):
    import subprocess
    import sys

    return subprocess.run([sys.executable, "-m", "mtwin", *args], capture_output=True, text=True)

# a Vectric-style engraving job on a router (samples/router_engrave.tap): inch, no tool
# declared, no M3 (a hand-switched spindle), strokes at Z-0.010" at F50 — the twin cannot
# know this cut
ENGRAVE = (SAMPLES / "router_engrave.tap").read_bytes()


def _changed_feed_lines(a: bytes, b: bytes) -> list[str]:
    la, lb = a.decode().splitlines(), b.decode().splitlines()
    return [y for x, y in zip(la, lb) if x != y] + lb[len(la):]


def test_engraving_without_m3_or_a_tool_keeps_every_feed():
    tw = mtwin.Twin()
    prog = tw.load(ENGRAVE, path="engrave.tap")
    r = optimize(tw, prog, OptimizeOptions())
    assert r.output == ENGRAVE and not r.changed_lines
    assert r.after.cycle_time == r.before.cycle_time
    text = " ".join(r.warnings)
    assert "T0 is not described" in text and "--tool" in text
    assert r.kept and all(len(v) for v in r.kept.values())


def test_spindle_stopped_keeps_feeds_even_with_a_described_tool():
    prog_text = ENGRAVE.replace(b"G00Z0.2000\nG00X0", b"(Endmill Dia. 0.125)\nG00Z0.2000\nG00X0", 1)
    tw = mtwin.Twin()
    prog = tw.load(prog_text, path="engrave.tap")
    r = optimize(tw, prog, OptimizeOptions())
    assert r.output == prog_text
    assert "spindle stopped" in r.kept and "spindle stopped" in " ".join(r.warnings)


def test_an_unrecognised_or_unmodelled_tool_comment_keeps_its_feeds():
    # a tool the program names but the cutting model cannot represent (a dovetail cutter, a
    # V-bit without its angle), and one it names in words nothing reads: all keep every feed,
    # with the spindle running — on a program whose light second pass a described tool raises
    body = (b"\nS18000 M3\n(MTWIN STOCK -10,-10,-10,80,30,0)\nG0 X-8 Y0 Z5\nG0 Z-2\nG1 X70 F400\nG0 Z5\n"
            b"G0 X-8 Y1\nG0 Z-2\nG1 X70 F400\nG0 Z5\nM5\nM30\n")
    tw = mtwin.Twin()
    for comment in (b"(Tool: 1/4 in dovetail cutter)", b"(Tool: 1/4 in V-bit)", b"(Bit: the sharp one from the blue box)"):
        text = b"G21 G90 G17 G94\n" + comment + body
        prog = tw.load(text, path="t.nc")
        r = optimize(tw, prog, OptimizeOptions())
        # (not described, or declared as a tool the model cannot represent — named as simulate names it)
        assert r.output == text and any(k.startswith("tool T0 not ") for k in r.kept), (comment, r.kept)
    # the control: the same program with the tool declared is optimised
    text = b"G21 G90 G17 G94\n(Bit: the sharp one from the blue box)" + body
    r = optimize(mtwin.Twin().with_tools({0: "flat:6:2"}), tw.load(text, path="t.nc"), OptimizeOptions())
    assert r.output != text and r.after.cycle_time < r.before.cycle_time


def _feeds_along_path(prog_a, prog_b):
    """(feed in a, feed in b) at the middle of every feed move of b, matched by path length
    (b may split a's moves)."""
    from mtwin.gcode import records as GR

    out = []
    la, lb = GR.move_lengths(prog_a.records), GR.move_lengths(prog_b.records)
    ca, cb = np.concatenate([[0], np.cumsum(la)]), np.concatenate([[0], np.cumsum(lb)])
    for i, r in enumerate(prog_b.records):
        if r["kind"] not in (GR.LINEAR, GR.ARC_CW, GR.ARC_CCW) or lb[i] <= 0:
            continue
        j = int(np.searchsorted(ca, cb[i] + 0.5 * lb[i], side="right") - 1)
        out.append((float(prog_a.records["feed"][j]), float(r["feed"])))
    return out


def test_a_declared_tool_lets_the_same_program_be_optimised():
    text = (b"G21 G90 G17 G94\nT1 M6\nS8000 M3\n(MTWIN STOCK -10,-10,-10,80,30,0)\nG0 X-8 Y0 Z5\nG0 Z-2\n"
            b"G1 X70 F400\nG0 Z5\nG0 X-8 Y1\nG0 Z-2\nG1 X70 F400\nG0 Z5\nM5\nM30\n")
    tw = mtwin.Twin()
    prog = tw.load(text, path="slot.nc")
    assert optimize(tw, prog, OptimizeOptions()).output == text  # T1 undescribed: kept
    tw = mtwin.Twin().with_tools({1: "flat:6:2"})
    r = optimize(tw, prog, OptimizeOptions())
    assert r.output != text and r.after.cycle_time < r.before.cycle_time
    assert compare(prog, tw.load(r.output, path="o.nc")) is None


def _wall_program(finish_comment: bool) -> bytes:
    # a 6 mm flat end mill: a full slot (roughing) at F300, then a 0.2 mm wall pass at F300
    head = b"G21 G90 G17 G94\n(T1 D=6 CR=0 - flat end mill)\n(MTWIN STOCK 0,-10,-6,60,10,0)\nT1 M6\nS8000 M3\n"
    rough = b"(ROUGH SLOT)\nG0 X-5 Y0 Z5\nG0 Z-2\nG1 X65 F300\nG0 Z5\n"
    fin = (b"(FINISH WALL PASS)\n" if finish_comment else b"") + b"G0 X-5 Y0.2\nG0 Z-2\nG1 X65 F300\nG0 Z5\n"
    return head + rough + fin + b"M5\nM30\n"


def test_the_finish_wall_sample():
    # samples/finish_wall.nc: the slot is the program's level, the side pass is raised to it,
    # the finishing pass keeps its feed
    # (with the limits learned from it: the sample names its material, Al 6061, below)
    tw = mtwin.Twin()
    prog = tw.load(str(SAMPLES / "finish_wall.nc"))
    r = optimize(tw, prog, OptimizeOptions(limits="learned"))
    out = r.output.decode().splitlines()
    after = lambda marker: out[out.index(marker) + 3]  # noqa: E731 — the cut after the approach
    assert after("(ROUGH SLOT)").endswith("F300.") and after("(FINISH WALL PASS)").endswith("F300.")
    side = after("(SIDE PASS)")
    assert not side.endswith("F300.") and r.after.cycle_time < r.before.cycle_time
    # with the limits from physics (6061 named in the comments): the slot goes to the catalogue's
    # 0.04 mm chip at Ø6 (F640 at S8000, two flutes, less the margin), and the 0.2 mm finishing
    # pass, whose largest chip is a third of its feed per tooth (radial chip thinning), higher
    r = optimize(tw, prog, OptimizeOptions())
    out = r.output.decode().splitlines()
    feed = lambda marker: float(out[out.index(marker) + 3].split("F")[1])  # noqa: E731
    assert 600 <= feed("(ROUGH SLOT)") <= 640
    assert feed("(FINISH WALL PASS)") > 2 * feed("(ROUGH SLOT)")
    assert any(x.get("source") == "physics" for x in r.limits)


@pytest.mark.parametrize("comment", [True, False])
def test_a_finishing_pass_keeps_its_feed_per_tooth(comment):
    text = _wall_program(comment)
    tw = mtwin.Twin()
    prog = tw.load(text, path="wall.nc")
    r = optimize(tw, prog, OptimizeOptions())
    src = text.decode().splitlines()
    fin_line = src.index("G1 X65 F300", src.index("G0 X-5 Y0.2")) + 1
    fins = [s for s in r.segments if s["finishing"]]
    assert fins and all(s["lines"][0] <= fin_line <= s["lines"][1] for s in fins)
    assert all(s["feed_after"] == s["feed_before"] for s in fins)

    def wall_pass(out: bytes) -> str:  # the line after the wall pass's approach (splits shift lines)
        lines = out.decode().splitlines()
        return lines[lines.index("G0 X-5 Y0.2") + 2]

    # (the pass runs on past the stock's end at X60: that air tail may be split off and raised)
    assert re.fullmatch(r"G1 X(65|59\.9) F300", wall_pass(r.output)), wall_pass(r.output)
    # --finish-feed optimize treats it as any cut: the light wall pass is raised
    r2 = optimize(tw, prog, OptimizeOptions(finish_feed="optimize"))
    assert not wall_pass(r2.output).endswith(" F300")


def test_arc_heavy_contour_holds_its_accuracy_on_the_rewritten_program():
    tw = mtwin.Twin()
    prog = tw.load(str(SAMPLES / "contour.nc"))
    # by default its helical ramp (lines 24-26) keeps its feed, as a plunge does (issue 31)
    default = optimize(tw, prog, OptimizeOptions(limits="learned"))
    shift = sum(1 for e in default.air_entries if e["line"] < 24 and e["air_to_z"] > e["to_z"])  # (split in air)
    assert default.output.split(b"\n")[23 + shift:26 + shift] == bytes(prog.data).split(b"\n")[23:26]
    # set like any cut, with the roughing allowance held as tight as a finish
    r = optimize(tw, prog, OptimizeOptions(ramp_feed="optimize", rough_tolerance=0.02, limits="learned"))
    assert r.after.cycle_time < r.before.cycle_time
    for s in r.segments:
        assert s["contour_error_after"] <= s["contour_error_before"] + 0.02 + 1e-9, s
        assert s["contour_held"]
    # independently: the written program's largest contour error in feed moves, re-simulated
    new = tw.load(r.output, path="out.nc")
    after = mtwin.Twin().simulate(new)
    before = mtwin.Twin().simulate(prog)
    ca = float(contour_error(after)[_feed_samples(after, new)].max())
    cb = float(contour_error(before)[_feed_samples(before, prog)].max())
    assert ca <= cb + 0.02
    # the tolerance binds on a machine without feed-forward (its lag v/Kv cuts the arcs more
    # the faster they run): opened up, the same program runs faster and less accurately
    lag = mtwin.Twin().with_params({f"axes.{a}.servo.feedforward": 0.0 for a in "xyz"})
    prog = lag.load(str(SAMPLES / "contour.nc"))
    # (the learned limits: the sample names its material, whose deflection limit would bind first)
    strict = optimize(lag, prog, OptimizeOptions(ramp_feed="optimize", rough_tolerance=0.02, limits="learned"))
    loose = optimize(lag, prog, OptimizeOptions(tolerance=5.0, rough_tolerance=5.0, ramp_feed="optimize",
                                                limits="learned"))
    assert loose.after.cycle_time < strict.after.cycle_time
    assert any(s["limited_by"] == "accuracy (contour error)" for s in strict.segments)


def test_contour_error_matches_the_simulators_own_maximum():
    tr = mtwin.Twin().simulate(mtwin.Twin().load(str(SAMPLES / "contour.nc")))
    prog = mtwin.Twin().load(str(SAMPLES / "contour.nc"))
    ce = contour_error(tr)[_feed_samples(tr, prog)]
    assert ce.max() == pytest.approx(tr.summary.max_contour_error, rel=1e-6)


def test_learned_limit_is_a_weighted_percentile_and_never_lowers_a_feed():
    x = np.array([1.0, 2.0, 3.0, 100.0])
    assert weighted_percentile(x, np.array([1.0, 1.0, 1.0, 1.0]), 95) == 100.0
    assert weighted_percentile(x, np.array([10.0, 10.0, 79.0, 1.0]), 95) == 3.0  # 1 % at 100: a spike
    tw = mtwin.Twin()
    prog = tw.load(str(SAMPLES / "pocket.nc"))
    r = optimize(tw, prog, OptimizeOptions(limits="learned"))
    assert r.after.cycle_time < r.before.cycle_time  # the README's promise: faster, not slower
    pairs = _feeds_along_path(prog, tw.load(r.output, path="o.nc"))
    assert pairs and all(b >= a - 1e-9 for a, b in pairs)  # no move slower than written
    lim = [x for x in r.limits if x.get("tool") == 1][0]
    assert lim["load"] <= lim["program_peak_load"] and "learned" in lim["source"]


def test_readme_python_api_example_gets_faster():
    twin = mtwin.Twin.from_toml(str(SAMPLES / "machines" / "linuxcnc-sim.toml"))
    prog = twin.load(str(SAMPLES / "contour.nc"))
    from mtwin.optimize import GAOptions

    res = optimize(twin, prog, OptimizeOptions(objective="time", method="ga", ga=GAOptions(seed=1)))
    assert res.after.cycle_time < res.before.cycle_time


def _raster(n_moves: int) -> bytes:
    out = ["%", "(T1 D=6. CR=0. - FLAT END MILL, 2 FLUTES)", "G21 G90 G94 G17 G64 P0.01", "T1 M6", "S8000 M3",
           "G0 X0 Y0 Z5", "G1 Z0 F600", "F1500"]
    k = row = 0
    while k < n_moves:
        y = row * 0.5
        for j in range(250):
            i = j if row % 2 == 0 else 249 - j
            x = i * 0.9
            out.append(f"G1 X{x:.3f} Y{y:.3f} Z{-0.5 + 0.4 * math.sin(x / 7.0) * math.cos(y / 5.0):.4f}")
            k += 1
        row += 1
    return ("\n".join(out + ["G0 Z5", "M30", "%"]) + "\n").encode()


def test_estimate_within_2_percent_on_a_100000_move_program():
    # 0.9 mm moves raised from F1500 towards the machine's maximum: acceleration, jerk and
    # look-ahead set their times, which a formula in L/F got 4x wrong; the planner's own
    # times at a few feeds do not
    tw = mtwin.Twin()
    prog = tw.load(_raster(100_000), path="raster.nc")
    r = optimize(tw, prog, OptimizeOptions(force_limit=1000.0, finish_feed="optimize", tolerance=10.0, chip_limit="none"))
    assert r.after.cycle_time < 0.92 * r.before.cycle_time  # (−9.9 %: the axes' acceleration sets it)
    assert abs(r.estimate["cycle_time"] / r.after.cycle_time - 1) < 0.02, (r.estimate, r.after.cycle_time)


def test_refusal_with_json_names_the_limit_segment_lines_and_excess(tmp_path):
    out = tmp_path / "o.nc"
    p = run_cli("optimize", str(SAMPLES / "contour.nc"), "-o", str(out), "--force-limit", "5", "--json")
    assert p.returncode == 2 and not out.exists()
    doc = json.loads(p.stdout)
    assert doc["written"] is False and doc["reasons"]
    r0 = doc["reasons"][0]
    assert r0["limit"] == "load" and r0["limit_value"] == 5.0 and r0["value"] > 5.0
    assert r0["over_by"] == pytest.approx(r0["value"] / 5.0 - 1) and len(r0["lines"]) == 2
    assert re.search(r"contour\.nc:\d+: .*load [\d.]+ N over its limit 5\.0 N by \d+ %", p.stderr)


def test_cli_summary_says_faster_and_which_limits(tmp_path):
    p = run_cli("optimize", str(SAMPLES / "pocket.nc"), "-o", str(tmp_path / "o.nc"), "--limits", "learned")
    assert p.returncode == 0, p.stderr
    assert re.search(r"result: [\d.]+ % faster", p.stderr)
    doc = json.loads(run_cli("optimize", str(SAMPLES / "pocket.nc"), "-o", str(tmp_path / "o2.nc"), "--json", "--limits", "learned").stdout)
    assert doc["verdict"] == "faster" and doc["cycle_time_change"] < 0 and doc["tradeoff"] == []
    assert [x["tool"] for x in doc["limits"] if x["tool"] is not None] == [1] and doc["force_limit"]
    assert re.search(r"limits T1: load [\d.]+ N, chip thickness [\d.]+ µm \(learned", p.stderr)
    p = run_cli("optimize", str(SAMPLES / "ga_reference.nc"), "-o", str(tmp_path / "g.nc"), "--spindle-range",
                "1000,8000", "--force-limit", "60", "--json")
    doc = json.loads(p.stdout)
    assert doc["spindle"] and doc["written"] is True and doc["tradeoff"]
    assert doc["verdict"] == ("faster" if doc["after"]["cycle_time"] < doc["before"]["cycle_time"] else "slower")


def test_parameter_feeds_stay_and_integer_feeds_stay_integers():
    text = (b"(T1 D=6 CR=0 - flat end mill)\n(MTWIN STOCK -10,-10,-10,60,20,0)\nG21 G90 G17 G94\n#1122 = 300\n"
            b"T1 M6\nS6000 M3\nG0 X-10 Y0 Z5\nG0 Z-1\nG1 X20 F#1122\nG1 X40 F1000\nG1 X50 F250\nG0 Z5\nM5\nM2\n")
    tw = mtwin.Twin()
    prog = tw.load(text, path="p.ngc")
    r = optimize(tw, prog, OptimizeOptions())
    lines = r.output.decode().splitlines()
    assert "G1 X20 F#1122" in lines
    changed = [ln for ln in lines if ln.startswith("G1 X50")]
    assert changed and re.fullmatch(r"G1 X50 F\d+", changed[0]), changed  # no "F990."


def test_air_cuts_under_a_guessed_stock():
    # a pass at Z-1, then the same pass back: under a guessed stock the return pass is air
    # because the first pass removed the material — as it does on the machine, whatever the
    # real stock's size — so it is raised
    text = (b"G21 G90 G17 G94\n(T1 D=6 CR=0 - flat end mill)\nT1 M6\nS8000 M3\nG0 X0 Y0 Z5\nG0 Z-1\n"
            b"G1 X50 F300\nG1 X0 F300\nG0 Z5\nM5\nM30\n")
    tw = mtwin.Twin()
    prog = tw.load(text, path="twice.nc")
    r = optimize(tw, prog, OptimizeOptions())
    back = [s for s in r.segments if s["air"]]
    assert back and back[0]["feed_after"] > 300 and "air cut under a guessed stock" not in r.kept
    # after a cut by a tool nothing describes (simulated as an imaginary 6 mm end mill), the
    # "air" it left may be material the real tool did not remove: kept
    text2 = (b"G21 G90 G17 G94\n(T2 D=6 CR=0 - flat end mill)\nT1 M6\nS8000 M3\nG0 X0 Y0 Z5\nG0 Z-1\n"
             b"G1 X50 F300\nG0 Z5\nT2 M6\nS8000 M3\nG0 X50 Y0 Z5\nG0 Z-1\nG1 X0 F300\nG0 Z5\nM5\nM30\n")
    prog2 = tw.load(text2, path="two_tools.nc")
    r2 = optimize(tw, prog2, OptimizeOptions())
    assert "G1 X0 F300" in r2.output.decode().splitlines()
    assert "air cut under a guessed stock" in r2.kept and "tool T1 not described" in r2.kept


@pytest.mark.skipif(not (REALDATA / "gcode_corpus").is_dir(), reason=f"{REALDATA} not present (real programs "
                    "live in ../shared)")
@pytest.mark.parametrize("name", ["pygcode_test_files/Letter A  (V-Carve).tap", "pygcode_test_files/Cross2.tap",
                                  "fusion360_led_floor/1092_wall_fix_only_permiter.nc",
                                  "camotics_examples/tiny_cat_outline.ngc"])
def test_real_programs_with_default_options(name):
    path = REALDATA / "gcode_corpus" / name
    tw = mtwin.Twin()
    prog = tw.load(str(path))
    r = optimize(tw, prog, OptimizeOptions())
    new = tw.load(r.output, path=str(path))
    assert compare(prog, new) is None
    assert r.after.cycle_time <= r.before.cycle_time * (1 + 1e-6)
    assert r.contour_error["after"] <= r.contour_error["before"] + 0.02 + 1e-9
    if "Cross2" in name:  # one 4 mm end mill through the whole depth at one feed: nothing to even out
        # but its stock is read (Vectric's MATERIAL SIZE): the edge of the stock is known, and
        # where the cut leaves it the chip thins below the program's own level, so it speeds up
        assert "Vectric" in r.trace_before.summary.cutting.stock_source
        assert all(sg["feed_after"] >= sg["feed_before"] for sg in r.segments)
        assert all(sg["limited_by"] == "chip thickness" for sg in r.segments
                   if sg["feed_after"] != sg["feed_before"] and not sg["air"])


def test_sample_to_segment_map_kernel_matches_numpy():
    # the compiled map of trace samples to segments (long traces) against the numpy original
    import mtwin.optimize.run as R

    seen = []
    orig = R._segment_of_samples

    def both(trace, new_prog, program, segs):
        saved = R.FAST_MAP
        try:
            R.FAST_MAP = 10**12
            a = orig(trace, new_prog, program, segs)
            R.FAST_MAP = 0
            b = orig(trace, new_prog, program, segs)
        finally:
            R.FAST_MAP = saved
        seen.append(len(a[0]))
        np.testing.assert_array_equal(a[0], b[0])
        np.testing.assert_array_equal(np.where(a[0] >= 0, a[1], -1), np.where(b[0] >= 0, b[1], -1))
        return a

    R._segment_of_samples = both
    try:
        tw = mtwin.Twin()
        optimize(tw, tw.load(str(SAMPLES / "contour.nc")), OptimizeOptions(force_limit=60.0))
    finally:
        R._segment_of_samples = orig
    assert seen and min(seen) > 1000


def test_a_straight_retract_at_feed_is_air_whatever_the_stock():
    # up out of the slot at F200, no XY motion: it cannot cut (it stays in its own footprint)
    text = (b"G21 G90 G17 G94\n(T1 D=6 CR=0 - flat end mill)\nT1 M6\nS8000 M3\nG0 X0 Y0 Z5\nG1 Z-2 F100\n"
            b"G1 X50 F300\nG1 Z20 F200\nM5\nM30\n")
    tw = mtwin.Twin()
    r = optimize(tw, tw.load(text, path="retract.nc"), OptimizeOptions())
    lines = r.output.decode().splitlines()
    up = [ln for ln in lines if ln.startswith("G1 Z20")]
    assert up and up[0] != "G1 Z20 F200" and "air cut under a guessed stock" not in r.kept


def test_a_router_whose_z0_is_the_table_keeps_its_feeds():
    # no stock given, cuts at Z15 over a table at Z0: the guessed stock (top at Z0) is below
    # the cuts, whose "air" is only the guess's — they keep their feeds
    text = (b"G21 G90 G17 G94\n(T1 D=6 CR=0 - flat end mill)\nT1 M6\nS18000 M3\nG0 X0 Y0 Z25\nG1 Z15 F300\n"
            b"G1 X400 F1200\nG0 Z25\nG0 X0 Y20\nG1 Z15 F300\nG1 X400 F1200\nG0 Z25\nM5\nM30\n")
    tw = mtwin.Twin()
    r = optimize(tw, tw.load(text, path="table_zero.nc"), OptimizeOptions())
    assert r.output == text and "air cut under a guessed stock" in r.kept


def test_a_fast_move_inside_a_slow_stretch_is_not_slowed_nor_a_slow_one_raised_past_its_level():
    # one line at F1500 between lines at F300: segments break where the programmed feed changes,
    # so no move is written slower than the program, and the F300 moves are not lifted to F1500
    text = (b"G21 G90 G17 G94\n(T1 D=6 CR=0 - flat end mill)\n(MTWIN STOCK 0,-20,-10,100,20,0)\nT1 M6\n"
            b"S8000 M3\nG0 X-5 Y0 Z5\nG0 Z-3\nG1 X105 F300\nG0 Z5\nG0 X5 Y3.3\nG0 Z-1\nG1 X40 F300\n"
            b"G1 X43 F1500\nG1 X80 F300\nG0 Z5\nM5\nM30\n")
    tw = mtwin.Twin()
    prog = tw.load(text, path="mixed.nc")
    r = optimize(tw, prog, OptimizeOptions())
    new = tw.load(r.output, path="o.nc")
    pairs = _feeds_along_path(prog, new)
    assert all(b >= a - 1e-9 for a, b in pairs), pairs
    assert r.after.peak_load <= r.before.peak_load * 1.001


def test_spindle_range_with_learned_limits_keeps_the_feed_per_tooth():
    # a range below the program's S8000 forces a lower speed: the floor is then the program's
    # feed per tooth, not its feed, so the load stays the program's
    tw = mtwin.Twin()
    prog = tw.load(str(SAMPLES / "pocket.nc"))
    r = optimize(tw, prog, OptimizeOptions(spindle_range=(1000.0, 4000.0), limits="learned"))
    assert r.after.peak_load <= r.before.peak_load * 1.01
    # a range around it: S is never lowered below the program's own
    r = optimize(tw, prog, OptimizeOptions(spindle_range=(1000.0, 8000.0), limits="learned"))
    new = tw.load(r.output, path="o.nc")
    assert new.records["spindle"][new.records["kind"] != 0].min() == 8000.0


def test_finishing_comments_open_and_close_regions():
    from mtwin.optimize.guards import finish_lines

    text = (b"G21 G90 G17 G94\n(T1 D=6 CR=0 - flat end mill)\nT1 M6\nS8000 M3\n(ROUGH)\nG0 X0 Y0 Z5\nG1 Z-1 F100\n"
            b"G1 X10 F300\n(FINISH WALL PASS)\nG1 X20 F300\nG1 X30 F300\n(Finish operation: Rough)\n(Next op)\n"
            b"G1 X40 F300\n(PROGRAM FINISHED)\nM30\n")
    prog = mtwin.Twin().load(text, path="f.nc")
    flag = dict(zip(prog.records["line"].tolist(), finish_lines(prog).tolist()))
    assert flag[8] is False and flag[10] is True and flag[11] is True and flag[14] is False
