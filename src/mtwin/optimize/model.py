"""The optimiser's fast model: cutting load, torque and power along the path as functions of
the feed per tooth, and move times as functions of the feed — from one full simulation.

The engagement sums make every path step's revolution-averaged force affine in the feed per
tooth f_z (``F = f_z·a + b``, the same arithmetic as the servo kernel's), so a candidate's
load at a step is ``|f_z·a + b|`` and its spindle torque ``f_z·t_a + t_b`` — no stock, no servo
loop.  The feed the estimate puts into f_z is the commanded one: the drives never run faster
than it along a move (up to the servo's overshoot, which the confirmation on the full twin
catches), so the estimated load is an upper bound of the real one.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import layout as EK  # the engagement's columns (Q_*, S*_*, T_*)
from ..gcode import records as R
from ..motion.path import PAUSE


@dataclass
class PathModel:
    """Per engagement step (path order): where it is and how the load follows the feed."""

    rec: np.ndarray  # (m,) motion record of the step
    pos: np.ndarray  # (m,) position along the record, fraction 0..1 (step centre)
    length: np.ndarray  # (m,) mm of path the step stands for
    fa: np.ndarray  # (m, 2) horizontal force per mm of feed per tooth, N/mm (machine X, Y)
    fb: np.ndarray  # (m, 2) horizontal edge force, N
    ta: np.ndarray  # (m,) spindle torque per mm of feed per tooth, N·m/mm
    tb: np.ndarray  # (m,) edge torque, N·m
    flutes: np.ndarray  # (m,) flutes of the cutting tool
    cutting: np.ndarray  # (m,) bool: the step meets material
    tool: np.ndarray  # (m,) tool number
    diameter: np.ndarray  # (m,) tool diameter, mm
    chip: np.ndarray  # (m,) largest chip thickness per mm of feed per tooth (h_max = f_z·chip)
    ae: np.ndarray  # (m,) radial width of cut, mm

    @property
    def steps(self) -> int:
        return len(self.rec)

    def load(self, fz: np.ndarray) -> np.ndarray:
        """Horizontal cutting load (N) of every step at feeds per tooth ``fz`` (mm)."""
        x = fz * self.fa[:, 0] + self.fb[:, 0]
        y = fz * self.fa[:, 1] + self.fb[:, 1]
        return np.hypot(x, y) * self.cutting

    def torque(self, fz: np.ndarray) -> np.ndarray:
        return (fz * self.ta + self.tb) * self.cutting


def path_model(twin, program, plan, eng, kstep=None) -> PathModel:
    """The fast model of a program from its plan and (cached) engagement; ``kstep``: the
    cutting coefficients per step when effects change them along the path ((steps, 6))."""
    from ..motion.simulate import program_cutting

    seg = plan.seg
    count = eng.count
    step_seg = eng.step_segments()
    j = np.arange(len(step_seg)) - eng.first[step_seg]  # (the step's place in its segment)
    # position of each step along its segment, then along its record (a record may be
    # several segments under the LinuxCNC planner: blend arcs, trimmed lines)
    seg_len = seg["length"]
    cnt = np.maximum(count[step_seg], 1)
    s_in = (j + 0.5) / cnt * seg_len[step_seg]
    rec_of = seg["rec"]
    motion = seg["kind"] != PAUSE
    nrec = len(program.records)
    rec_len = np.bincount(rec_of[motion], weights=seg_len[motion], minlength=nrec)
    before = np.zeros(len(seg))
    if len(seg):
        # path length of the same record's earlier segments
        cum = np.cumsum(np.where(motion, seg_len, 0.0))
        start_of_rec = np.full(nrec, np.inf)
        np.minimum.at(start_of_rec, rec_of[motion], (cum - seg_len)[motion])
        before = (cum - seg_len) - start_of_rec[rec_of]
        before = np.where(motion, before, 0.0)
    step_rec = rec_of[step_seg]
    pos = np.clip((before[step_seg] + s_in) / np.maximum(rec_len[step_rec], 1e-12), 0.0, 1.0)
    length = seg_len[step_seg] / cnt

    S, q = eng.sums, eng.q  # (float32 step tables: only the columns used are widened)
    k = program_cutting(twin, program).material.coefficients
    if kstep is not None and len(kstep):
        k = tuple(kstep[:, j] for j in range(6))  # (tool wear: the edge ones grow along the path)
    ax = k[0] * _f64(S, EK.SX_TC) + k[1] * _f64(S, EK.SX_RC) + k[2] * _f64(S, EK.SX_AC)
    bx = k[3] * _f64(S, EK.SX_TE) + k[4] * _f64(S, EK.SX_RE) + k[5] * _f64(S, EK.SX_AE)
    ay = k[0] * _f64(S, EK.SY_TC) + k[1] * _f64(S, EK.SY_RC) + k[2] * _f64(S, EK.SY_AC)
    by = k[3] * _f64(S, EK.SY_TE) + k[4] * _f64(S, EK.SY_RE) + k[5] * _f64(S, EK.SY_AE)
    ta = k[0] * _f64(S, EK.ST_TC) * 1e-3
    tb = k[3] * _f64(S, EK.ST_TE) * 1e-3
    hand = np.where(program.records["spindle_dir"][step_rec] < 0, -1.0, 1.0)
    dx, dy = _f64(q, EK.Q_DX), _f64(q, EK.Q_DY)
    yx, yy = -dy * hand, dx * hand
    fa = np.stack([ax * dx + ay * yx, ax * dy + ay * yy], axis=1)
    fb = np.stack([bx * dx + by * yx, bx * dy + by * yy], axis=1)
    cutting = (_f64(q, EK.Q_AREA) > 0.0) | (_f64(S, EK.ST_TE) > 0.0)
    trow = eng.tool_index[step_seg]
    flutes = eng.tools[trow, EK.T_FLUTES]
    diameter = 2.0 * eng.tools[trow, EK.T_RADIUS]
    return PathModel(step_rec, pos, length, fa, fb, ta, tb, flutes, cutting,
                     program.records["tool"][step_rec].astype(np.int64), diameter,
                     np.where(cutting, _f64(q, EK.Q_WMAX), 0.0), np.where(cutting, _f64(q, EK.Q_AE), 0.0))


def _f64(a: np.ndarray, col: int) -> np.ndarray:
    """One column of a float32 step table, widened."""
    return a[:, col].astype(np.float64)


_TABLE_BLOCK = 8192  # records per block of MoveTimes.table


@dataclass
class MoveTimes:
    """Per record, its planned time as a function of the feed: the planner's own durations at
    a few uniform feeds (every settable feed move at F_k, the rest as programmed) and at the
    program's own feed, interpolated linearly in 1/F.  A plan, not a formula, so acceleration,
    jerk, look-ahead over short blocks and arc limits are all in it; above the highest feed
    planned a move takes its time there (the machine is at its limits), below the lowest the
    line through the last two points (the L/F part dominates) extends it.

    ``v_cap``: the planner's speed limit along the record that is not the feed (arc limits,
    axis speeds, short blocks), read off the plan at the highest feed, mm/s."""

    u: np.ndarray  # (records, K) s/mm: 60 / F of each point, ascending
    dur: np.ndarray  # (records, K) s
    v_cap: np.ndarray  # (records,) mm/s
    length: np.ndarray  # (records,) mm

    def table(self, rec: np.ndarray, feeds_mm_min: np.ndarray, frac: np.ndarray | float = 1.0) -> np.ndarray:
        """Times of the records ``rec`` at each of ``feeds_mm_min`` (one grid for all): (n, G)."""
        ug = 60.0 / np.maximum(np.asarray(feeds_mm_min, float), 1e-9)
        rec = np.asarray(rec)
        frac = np.broadcast_to(np.asarray(frac, float), rec.shape)
        out = np.empty((len(rec), len(ug)))
        # in blocks of rows: the (rows, G) temporaries stay small and are reused, where an hour's
        # 100,000 records at once would spend most of the time faulting in fresh pages
        for a in range(0, len(rec), _TABLE_BLOCK):
            b = min(a + _TABLE_BLOCK, len(rec))
            out[a:b] = self._table(rec[a:b], ug, frac[a:b])
        return out

    def _table(self, rec: np.ndarray, ug: np.ndarray, frac: np.ndarray) -> np.ndarray:
        U = self.u[rec]
        D = self.dur[rec]
        K = U.shape[1]
        i = np.zeros((len(rec), len(ug)), np.int64)
        for k in range(1, K - 1):
            i += U[:, k, None] <= ug[None, :]
        u0 = np.take_along_axis(U, i, 1)
        u1 = np.take_along_axis(U, i + 1, 1)
        d0 = np.take_along_axis(D, i, 1)
        d1 = np.take_along_axis(D, i + 1, 1)
        with np.errstate(divide="ignore", invalid="ignore"):
            a = np.where(u1 > u0, (ug[None, :] - u0) / (u1 - u0), 0.0)
        t = np.maximum(d0 + np.maximum(a, 0.0) * (d1 - d0), 0.0)
        scale = np.where(self.length[rec] > 0, 1.0, 0.0) * frac
        return t * scale[:, None]


def move_times(program, plan, plans_at: list[tuple[float, object]]) -> MoveTimes:
    """Time models of the records from the program's own plan and plans at uniform feeds
    (``plans_at``: (feed mm/min, plan) pairs, the highest feed first or anywhere)."""
    nrec = len(program.records)

    def per_record(p):
        seg = p.seg
        m = (seg["kind"] != PAUSE) & (seg["rapid"] == 0)
        L = np.bincount(seg["rec"][m], weights=seg["length"][m], minlength=nrec)
        with np.errstate(divide="ignore"):
            inv = np.bincount(seg["rec"][m], weights=seg["length"][m] / np.maximum(seg["vmax"][m], 1e-9),
                              minlength=nrec)
        dur = np.bincount(seg["rec"][m], weights=p.dur[m], minlength=nrec)
        return L, inv, dur

    L, _, dur0 = per_record(plan)
    f0 = np.maximum(program.records["feed"], 1e-9)
    us, ds = [60.0 / f0], [dur0]
    top = max(plans_at, key=lambda fp: fp[0])
    for F, p in plans_at:
        Lf, inv, dur = per_record(p)
        us.append(np.full(nrec, 60.0 / F))
        ds.append(dur)
        if p is top[1]:
            with np.errstate(divide="ignore", invalid="ignore"):
                v_cap = np.where(inv > 0, Lf / inv, np.inf)
    U = np.stack(us, axis=1)
    D = np.stack(ds, axis=1)
    o = np.argsort(U, axis=1, kind="stable")
    return MoveTimes(np.take_along_axis(U, o, 1), np.take_along_axis(D, o, 1), v_cap, L)


def feed_records(program) -> np.ndarray:
    """Which records' feed the optimiser may set: feed moves with a feed of their own (not a
    spindle-synchronised thread or tap, not a probe, not inverse-time or per-revolution feed)."""
    rec = program.records
    k = rec["kind"]
    ok = R.is_feed_kind(k)
    ok &= rec["feed"] > 0
    ok &= (rec["flags"] & (R.FL_SYNC | R.FL_PROBE)) == 0
    ok &= rec["feed_mode"] == R.FEED_PER_MIN
    # a canned cycle's feeds (in and, for G85/G89, out) are one F word on one line, chosen for
    # drilling or boring: they stay
    ok &= (rec["flags"] & R.FL_CANNED) == 0
    if getattr(program, "is_macro", False) and len(rec):
        # a line whose F is a macro expression, or a macro statement, cannot be rewritten
        from ..gcode.macro import mask_source

        _, locked_lines, locked_words = mask_source(program.data, program.dialect)
        locked = {li + 1 for li in locked_lines} | {li + 1 for li, letter in locked_words if letter == "F"}
        if locked:
            ok &= ~np.isin(rec["line"], np.array(sorted(locked)))
    # plunges (mostly downward) keep the programmed feed: the CAM chose it for a tool entering
    # the material with its end face (centre cutting, chip evacuation), which the load model
    # does not judge
    dz = rec["z"] - rec["sz"]
    L = R.move_lengths(rec)
    ok &= ~((dz < 0) & (-dz > 0.5 * np.maximum(L, 1e-12)))
    return ok


RAMP_DZ = 0.01  # mm: a feed move that goes down by more than this is an entry (a ramp, a helix)


def entry_records(program) -> np.ndarray:
    """Ramps and helical entries: feed moves that go down while they move sideways (a G1 ramp,
    a G2/G3 helix).  The CAM chose their feed, as a plunge's, for a tool entering material with
    its end face as well as its side, which the load model does not judge."""
    rec = program.records
    # (down by more than CAM rounding: a few µm of descent on a 3D surface move is not an entry)
    return R.is_feed_kind(rec["kind"]) & (rec["z"] - rec["sz"] < -RAMP_DZ)


def taylor_life(v_m_min: np.ndarray, n: float, c: float) -> np.ndarray:
    """Tool life (min) from Taylor's equation V·T^n = C."""
    with np.errstate(divide="ignore"):
        return np.where(v_m_min > 0, (c / np.maximum(v_m_min, 1e-12)) ** (1.0 / n), np.inf)


def cutting_speed(diameter_mm, rpm):
    return math.pi * np.asarray(diameter_mm) * np.asarray(rpm) / 1000.0
