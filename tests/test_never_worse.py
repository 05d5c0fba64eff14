"""`mtwin optimize` never makes a program worse (issue 31): no guard lowers a feed that no
broken limit requires, kept means kept, no guessed air at a facing pass, ramps and helices keep
their feeds, limits per tool."""
from __future__ import annotations

import pytest

import mtwin
from mtwin.errors import MtwinError
from mtwin.optimize import OptimizeOptions, optimize
from mtwin.optimize.run import parse_force_limit
from conftest import SAMPLES


def _lines(data: bytes) -> list[bytes]:
    return data.split(b"\n")


@pytest.fixture(scope="module")
def pocket():
    tw = mtwin.Twin()
    return tw, tw.load(str(SAMPLES / "pocket.nc"))


@pytest.mark.parametrize("limit", [100.0, 200.0])
def test_a_higher_limit_never_gives_a_slower_program(pocket, limit):
    tw, prog = pocket
    r = optimize(tw, prog, OptimizeOptions(force_limit=limit))
    assert r.after.cycle_time <= r.before.cycle_time
    assert not r.slower_because
    # nothing below its programmed feed: the program breaks no 100 N limit (it peaks at 77.5 N)
    assert all(s["feed_after"] >= s["feed_before"] - 1e-9 for s in r.segments)
    # every raised segment holds its contour promise, flagged per segment
    assert all(s["contour_held"] for s in r.segments)
    assert all(s["contour_tolerance"] in (0.02, 0.1) for s in r.segments)


def test_a_limit_the_program_breaks_slows_only_those_segments_and_says_so(pocket):
    tw, prog = pocket
    r = optimize(tw, prog, OptimizeOptions(force_limit=60.0))
    assert r.verdict[0] == "slower"
    assert r.slower_because and all(x["limit"] == "load" and x["program_ratio"] > 1.0 for x in r.slower_because)
    assert any("slower than the program" in w and "load limit 60.0 N" in w for w in r.warnings)
    lowered = [s for s in r.segments if s["feed_after"] < s["feed_before"]]
    assert lowered and all(s["limited_by"] in ("load", "chip thickness") for s in lowered)
    assert r.after.peak_load <= 60.0 * 1.01


def test_kept_segments_are_byte_identical(pocket):
    tw, prog = pocket
    r = optimize(tw, prog, OptimizeOptions(force_limit=200.0))
    a, b = _lines(bytes(prog.data)), _lines(r.output)
    # (a plunge split in its air adds one line: the lines after it move down by one)
    split = [e["line"] for e in r.air_entries if e["air_to_z"] > e["to_z"]]
    assert len(b) == len(a) + len(split)
    kept = [s for s in r.segments if s["limited_by"].startswith("kept") or s["limited_by"].startswith("program's feed")]
    assert kept
    for s in kept:
        for ln in range(s["lines"][0], s["lines"][1] + 1):
            if s["lines"][0] == s["lines"][1] or ln not in (s["lines"][0], s["lines"][1]):
                new_ln = ln + sum(1 for x in split if x < ln)
                assert a[ln - 1] == b[new_ln - 1] or s["feed_after"] == s["feed_before"], (ln, a[ln - 1], b[new_ln - 1])


FACE = b"""G21 G90 G17 G94
T1 M6
S6000 M3
G0 X-10 Y0 Z5
G1 Z0 F300
G1 X60 F300
G1 Y6
G1 X-10
G0 Z5
G1 X-10 Y20 Z-1 F300
G1 X60 F300
G0 Z25
M5
M30
"""


def test_a_facing_pass_at_the_guessed_top_keeps_its_feed():
    tw = mtwin.Twin().with_tools({1: "flat:12:3"})
    prog = tw.load(FACE, path="face.nc")
    r = optimize(tw, prog)
    a, b = _lines(FACE), _lines(r.output)
    for ln in (6, 7, 8):  # the pass at Z0: the real stock stands above the guessed top
        assert a[ln - 1] == b[ln - 1], (ln, b[ln - 1])


HELIX = b"""G21 G90 G17 G94
T1 M6
S8000 M3
G0 X10 Y0 Z5
G1 Z0.5 F300
G3 X10 Y0 Z-0.5 I-10 J0 F80
G3 X10 Y0 Z-1.5 I-10 J0 F80
G1 X30 Y0 Z-2 F80
G1 X60 F300
G0 Z25
M5
M30
(MTWIN STOCK -20,-20,-10,70,20,0)
"""


def test_helical_and_ramped_entries_keep_their_feed():
    tw = mtwin.Twin().with_tools({1: "flat:6:2"})
    prog = tw.load(HELIX, path="helix.nc")
    r = optimize(tw, prog, OptimizeOptions(force_limit=200.0, chip_limit="none"))
    a, b = _lines(HELIX), _lines(r.output)
    shift = sum(1 for e in r.air_entries if e["line"] < 6 and e["air_to_z"] > e["to_z"])  # (a plunge split in air)
    for ln in (6, 7, 8):
        assert a[ln - 1] == b[ln - 1 + shift], (ln, b[ln - 1 + shift])
    assert any("helical" in k for k in r.kept)
    r2 = optimize(tw, prog, OptimizeOptions(force_limit=200.0, chip_limit="none", ramp_feed="optimize"))
    shift2 = sum(1 for e in r2.air_entries if e["line"] < 6 and e["air_to_z"] > e["to_z"])
    assert _lines(r2.output)[5 + shift2] != a[5]  # asked for: the helix is set like any cut


def test_force_limit_per_tool():
    assert parse_force_limit("60") == 60.0
    assert parse_force_limit("T1=40,t3=120") == {1: 40.0, 3: 120.0}
    for bad in ("T1=x", "T1=40,T1=50", "sixty"):
        with pytest.raises(MtwinError):
            parse_force_limit(bad)
    with pytest.raises(MtwinError):
        OptimizeOptions(force_limit={1: -5.0})
    tw = mtwin.Twin().with_tools({1: "flat:6:2"})
    prog = tw.load(HELIX, path="helix.nc")
    r = optimize(tw, prog, OptimizeOptions(force_limit={1: 150.0, 5: 40.0}))
    assert any("T5" in w and "no feed move" in w for w in r.warnings)
    notes = {n["tool"]: n for n in r.limits if n.get("tool") is not None}
    assert notes[1]["load"] == 150.0 and notes[1]["source"].startswith("--force-limit")
    # the learned chip thickness holds under a given load limit
    assert notes[1]["chip_thickness"] is not None


def test_report_curves_keep_every_peak():
    import numpy as np
    from mtwin.report.compare_html import MAX_POINTS, _thin

    t = np.arange(200_000) * 1e-3
    y = np.zeros_like(t)
    y[123_457] = 460.2  # a one-sample peak (the table's peak load) between any thinning grid
    z = np.full_like(t, np.nan)
    z[1000:2000] = 5.0
    tt, yy, zz = _thin(t, y, z)
    assert len(tt) <= MAX_POINTS and yy.max() == 460.2
    assert np.isnan(zz).any() and np.nanmax(zz) == 5.0


def test_report_draws_each_tools_limit_over_its_own_segments(pocket):
    from mtwin.report.optimize_html import optimize_html

    tw, prog = pocket
    r = optimize(tw, prog, OptimizeOptions(force_limit=200.0))
    html = optimize_html(r, "pocket.nc").decode()
    assert "limit per tool" in html


ROUTER = b"""G21 G90
T1
S10000 M3
G0 X0 Y0 Z5
G1 Z-1 F200
G1 X20 F800
G0 Z5
T2
G0 X0 Y10
G1 Z-1 F200
G1 X20 F600
G0 Z5
M30
"""


def test_a_t_word_without_m6_is_the_tool_in_the_spindle():
    tw = mtwin.Twin().with_tools({1: "flat:3:2", 2: "flat:6:2"})
    prog = tw.load(ROUTER, path="router.nc")
    r = prog.records
    assert set(r["tool"][r["line"] <= 7].tolist()) == {1} and set(r["tool"][r["line"] >= 9].tolist()) == {2}
    assert any("no M6" in str(w) for w in prog.warnings)
    run = mtwin.simulate(tw, prog).as_dict()
    assert run["tool_change_time"] == 0.0  # no changer: the operator put the bits in
    # the tools --tool declares are the tools it cuts with: T1's 3 mm bit, not the default 6 mm
    assert {t["number"]: t["diameter"] for t in run["tools"]} == {1: 3.0, 2: 6.0}
    assert set(run["per_tool"]) == {"1", "2"}


def test_a_tool_option_for_a_tool_the_program_never_uses_is_a_warning(tmp_path):
    from conftest import ROOT
    import subprocess
    import sys

    p = tmp_path / "r.nc"
    p.write_bytes(ROUTER)
    r = subprocess.run([sys.executable, "-m", "mtwin", "simulate", str(p), "--tool", "5=flat:3:2", "--tool",
                        "1=flat:3:2"], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    assert "--tool 5=…: the program never uses T5" in r.stderr and "T1" in r.stderr


def test_final_surfaces_are_read_off_the_stock(pocket):
    """The pocket's three layers: the inner loops of the first two leave nothing final (the next
    loop and the next layer cut their walls and floors again); each layer's outer loop leaves
    the pocket's wall; the last layer leaves its floor — held to --tolerance, the rest to
    --rough-tolerance."""
    tw, prog = pocket
    r = optimize(tw, prog, OptimizeOptions())
    by_line = {}
    for s in r.segments:
        if not s["air"]:
            for ln in range(s["lines"][0], s["lines"][1] + 1):
                by_line.setdefault(ln, []).append(s)
    assert not any(s["final_surface"] for s in by_line[14])  # layer 1, first loop
    assert all(s["final_surface"] for s in by_line[36])  # layer 1, outer loop: the wall
    assert all(s["final_surface"] for ln in (76, 86, 98) for s in by_line[ln])  # the last layer: the floor
    assert {s["contour_tolerance"] for s in r.segments if s["final_surface"]} == {0.02}
    assert {s["contour_tolerance"] for s in r.segments if not s["final_surface"] and not s["finishing"]} == {0.1}
