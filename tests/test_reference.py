"""The kernels held against slow, obviously correct references (``tests/reference``): the
interpreter's modal-group rule (RS274NGC's table), the planner's time-optimal profile of a short
straight path, one servo axis as the continuous cascade it samples, and the engagement's
removal rate against a cell-by-cell Z-map.  Random inputs with fixed seeds, and the codes real
programs use."""
from __future__ import annotations

import itertools
import math
import random

import numpy as np
import pytest

from mtwin.errors import MtwinError
from mtwin.gcode.interpreter import InterpreterSettings, load_program
from reference import modal, planner, servo, zmap

# ---------------------------------------------------------------- the modal-group rule

CONFLICT = "two codes from the same modal group"


def _codes(dialect: str) -> list[str]:
    table = dict(modal.LINUXCNC)
    if dialect == "fanuc":
        table.update(modal.FANUC_OWN)
    codes = sorted({c for cs in table.values() for c in cs} | set(modal.FREE[dialect]))
    return [c for c in codes if _group_known(c, dialect)]


def _group_known(code: str, dialect: str) -> bool:
    try:
        modal.group_of(code, dialect)
        return True
    except KeyError:
        return False


def _refused_for_conflict(block: str, dialect: str) -> bool:
    try:
        load_program(f"G21 G90 G17\n{block}\nM30\n".encode(), InterpreterSettings(dialect=dialect), path="block.ngc")
    except MtwinError as exc:
        return CONFLICT in str(exc)
    return False


@pytest.mark.parametrize("dialect", ["linuxcnc", "fanuc"])
def test_two_codes_conflict_exactly_when_the_reference_puts_them_in_one_group(dialect):
    codes = _codes(dialect)
    pairs = list(itertools.combinations(codes, 2))
    random.Random(36).shuffle(pairs)
    checked = conflicting = 0
    for a, b in pairs[:400]:
        want = modal.conflicts([a, b], dialect)
        got = _refused_for_conflict(f"{a} {b} P1 X1 Z-1 R1 F100", dialect)
        assert got == want, f"{dialect}: {a} {b}: the reference says {'a' if want else 'no'} conflict"
        checked += 1
        conflicting += want
    assert checked == min(400, len(pairs)) and conflicting > 20  # (both kinds were met)


@pytest.mark.parametrize("block,dialect", [("G0 G80 X1", "fanuc"), ("G0 G80 X1", "linuxcnc"), ("G4 P1 G28", "linuxcnc"),
                                           ("G90 G91 X1", "fanuc"), ("G17 G18", "linuxcnc"), ("G54 G55", "fanuc")])
def test_the_blocks_real_programs_write(block, dialect):
    codes = [w for w in block.split() if w.startswith("G")]
    assert _refused_for_conflict(block, dialect) == modal.conflicts(codes, dialect)


@pytest.mark.parametrize("dialect", ["linuxcnc", "fanuc"])
def test_two_m_codes_conflict_exactly_when_the_reference_puts_them_in_one_group(dialect):
    # (the words each needs beside it: M61 its tool, the I/O codes their pin, M50-M53 a switch)
    extra = {"M61": "Q1", "M66": "P0 L0", "M67": "E0 Q0", "M68": "E0 Q0", "M62": "P0", "M63": "P0", "M64": "P0",
             "M65": "P0"}
    codes = [c for cs in modal.LINUXCNC_M.values() for c in cs]
    if dialect == "fanuc":  # LinuxCNC's own codes are not Fanuc's
        codes = [c for c in codes if c not in ("M61", "M70", "M71", "M72", "M73", "M62", "M63", "M64", "M65",
                                               "M66", "M67", "M68")]
    pairs = list(itertools.combinations(codes, 2))
    random.Random(36).shuffle(pairs)
    conflicting = 0
    for a, b in pairs[:150]:
        want = modal.m_conflicts([a, b], dialect)
        words = " ".join(dict.fromkeys(w for c in (a, b) for w in extra.get(c, "").split()))
        got = _refused_for_conflict(f"{a} {b} {words}".strip(), dialect)
        assert got == want, f"{dialect}: {a} {b}: the reference says {'a' if want else 'no'} conflict"
        conflicting += want
    assert conflicting > 5 if dialect == "linuxcnc" else conflicting == 0


# ---------------------------------------------------------------- the planner

def _random_path(rng: random.Random):
    n = rng.randint(1, 7)
    length = np.array([rng.choice([rng.uniform(0.05, 1.0), rng.uniform(1.0, 60.0)]) for _ in range(n)])
    vmax = np.array([rng.uniform(5.0, 500.0) for _ in range(n)])
    acc = rng.uniform(100.0, 5000.0)
    # a junction's limit: at most the slower of the two moves' speeds; the path ends at rest
    vj = np.array([rng.uniform(0.0, 1.0) * min(vmax[i], vmax[i + 1]) if i + 1 < n else 0.0 for i in range(n)])
    return length, vmax, acc, vj


@pytest.mark.parametrize("seed", range(40))
def test_the_trapezoid_planner_is_the_time_optimal_profile(seed):
    from mtwin.motion import _plankernel as K

    length, vmax, acc, vj = _random_path(random.Random(seed))
    n = len(length)
    a = np.full(n, acc)
    ve = K.lookahead(vj, length, a, 0.0, n)
    prof, dur = K.segment_timing(length, vmax, a, 0.0, ve, np.zeros(n), np.zeros(n))
    ref = planner.junction_times(length, vmax, acc, vj)
    # each junction is passed when the time-optimal motion passes it (to 1e-4 of the total)
    np.testing.assert_allclose(np.cumsum(dur), ref, rtol=1e-4, atol=1e-6)
    # and the profile's own distance at each of its phases is the reference's
    total = float(np.sum(dur))
    assert total == pytest.approx(ref[-1], rel=1e-4)


def test_the_reference_planner_has_its_closed_forms():
    # one move from rest to rest: L/v + v/a when it reaches v, 2·sqrt(L/a) when it cannot
    assert planner.junction_times(np.array([100.0]), np.array([50.0]), 500.0, np.array([0.0]))[-1] == \
        pytest.approx(100.0 / 50.0 + 50.0 / 500.0, rel=1e-6)
    assert planner.junction_times(np.array([1.0]), np.array([500.0]), 500.0, np.array([0.0]))[-1] == \
        pytest.approx(2.0 * math.sqrt(1.0 / 500.0), rel=1e-6)


# ---------------------------------------------------------------- the servo loop of one axis

def _x_axis(twin, feedforward: float):
    """The twin with its X axis free of dry friction (the reference is linear), at this feed-forward."""
    from dataclasses import replace

    x = twin.machine.x
    fr = replace(x.friction, coulomb_pos=0.0, coulomb_neg=0.0, static_pos=0.0, static_neg=0.0)
    x = replace(x, friction=fr, servo=replace(x.servo, feedforward=feedforward))
    return twin.replace(machine=replace(twin.machine, x=x))


@pytest.mark.parametrize("feed,ff", [(3000.0, 0.0), (3000.0, 0.9), (12000.0, 0.9)])
def test_one_axis_follows_its_command_as_the_continuous_cascade_does(feed, ff):
    import mtwin
    from mtwin.layout import SV_B, SV_FF, SV_KPP, SV_MASS, SV_WI, SV_WV
    from mtwin.motion.simulate import servo_table

    tw = _x_axis(mtwin.Twin(), ff)
    prog = tw.load(f"G21 G90 G94\nG1 X80 F{feed:g}\nG4 P0.2\nM30\n".encode(), path="x.nc")
    tr = tw.simulate(prog, cutting=False)
    sv = servo_table(tw.machine)
    t, xc, x = tr.t, tr.cmd[:, 0], tr.act[:, 0].astype(float)
    ref = servo.follow(t, xc, sv[0, SV_KPP], sv[0, SV_WV], sv[0, SV_WI], sv[0, SV_FF], sv[0, SV_MASS], sv[0, SV_B],
                       tw.machine.controller.servo_period)
    err_k, err_r = xc - x, xc - ref
    peak = float(np.abs(err_r).max())
    # the 1 ms sampled loop against the continuous one: within 5 % of the peak following error
    # (ω_v·dt = 0.24: the sampling's own share), and the same steady error while cruising
    assert float(np.abs(err_k - err_r).max()) <= 0.05 * peak + 1e-4
    cruise = np.abs(np.gradient(xc, t) - feed / 60.0) < 1e-6
    if cruise.sum() > 50:
        mid = np.flatnonzero(cruise)[len(np.flatnonzero(cruise)) // 2]
        assert err_k[mid] == pytest.approx(err_r[mid], rel=0.02, abs=2e-5)


# ---------------------------------------------------------------- the engagement on a Z-map

PASSES = [((2.0, 10.0), (38.0, 10.0), -2.0),   # a slot
          ((2.0, 14.0), (38.0, 14.0), -3.0),   # beside it, deeper: part of its width already cut
          ((4.0, 3.0), (36.0, 27.0), -1.5),    # across both, shallower: material only between them
          ((20.0, 2.0), (20.0, 28.0), -4.0)]   # across all three, deepest


def test_each_moves_removed_volume_is_the_cell_by_cell_z_maps():
    import mtwin
    from mtwin.layout import Q_AREA
    from mtwin.motion.simulate import program_engagement

    box = (0.0, 0.0, -10.0, 40.0, 30.0, 0.0)
    lines = ["G21 G90 G17 G94", "(T1 D=6 CR=0 - flat end mill)", "T1 M6", "S8000 M3"]
    for (a, b, z) in PASSES:
        lines += [f"G0 Z5", f"G0 X{a[0]:g} Y{a[1]:g}", f"G1 Z{z:g} F100", f"G1 X{b[0]:g} Y{b[1]:g} F300"]
    lines += ["G0 Z5", "M30"]
    tw = mtwin.Twin()
    prog = tw.load("\n".join(lines).encode(), path="passes.nc")
    plan, eng = program_engagement(tw, prog, box)
    ref = zmap.ZMap(box, 0.02)
    seg = plan.seg
    vols = []
    for k, (a, b, z) in enumerate(PASSES):
        # the plunge, then the pass: the pass is the move that ends at b
        ref.sweep(a, a, z, 3.0)
        want = ref.sweep(a, b, z, 3.0)
        i = int(np.flatnonzero((np.abs(seg["p1"][:, 0] - b[0]) < 1e-9) & (np.abs(seg["p1"][:, 1] - b[1]) < 1e-9)
                               & (np.abs(seg["p1"][:, 2] - z) < 1e-9))[0])
        steps = slice(int(eng.first[i]), int(eng.first[i] + eng.count[i]))
        got = float(eng.q[steps, Q_AREA].astype(float).sum() * seg["length"][i] / max(int(eng.count[i]), 1))
        vols.append((got, want))
        assert got == pytest.approx(want, rel=0.01), (k, got, want)  # (measured: within 0.32 %)
    # the reference's own closed form: the slot, 36 x 6 mm, 2 deep, less the circular segment of its
    # end beyond the stock's edge at X40 (2 mm from the tool's centre)
    segment = 9.0 * math.acos(2.0 / 3.0) - 2.0 * math.sqrt(5.0)
    assert vols[0][1] == pytest.approx((36.0 * 6.0 - segment) * 2.0, rel=2e-3)

