"""Segmentation of the predicted power curve into the stretches of path that get one feed each.

The curve is the cutting power along the path (one value per engagement step, at the
program's own F and S), the reference's "sample the path at intervals".  A segment never
spans a rapid, a dwell, a tool change or a change of the programmed feed; air cuts (no material met) are segments of their
own; its boundaries fall on move ends where possible, otherwise the move is split (the
writer's :class:`~mtwin.gcode.writer.Split`); a line that makes several moves (canned
cycles, splines, loop bodies) stays whole, and a line run more than once (subprogram, loop)
gets one feed in every segment it appears in — those segments share one variable.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..gcode import records as R
from ..gcode.writer import MIN_PIECE
from . import _segkernel as SK


@dataclass
class Segments:
    """The optimiser's segments: pieces of feed records, in path order."""

    piece_rec: np.ndarray  # (pieces,) record
    piece_t0: np.ndarray  # (pieces,) start fraction along the record
    piece_t1: np.ndarray  # (pieces,) end fraction
    piece_seg: np.ndarray  # (pieces,) segment
    seg_var: np.ndarray  # (segments,) feed variable (segments that share a line share one)
    seg_air: np.ndarray  # (segments,) bool: no material met
    seg_tool: np.ndarray  # (segments,) tool number
    step_seg: np.ndarray  # (steps,) segment of every engagement step (-1: not in a segment)

    @property
    def count(self) -> int:
        return len(self.seg_var)

    @property
    def variables(self) -> int:
        return int(self.seg_var.max()) + 1 if len(self.seg_var) else 0

    def seg_lines(self, program) -> list[list[int]]:
        """The program lines of every segment."""
        out: list[list[int]] = [[] for _ in range(self.count)]
        for r, s in zip(self.piece_rec, self.piece_seg):
            ln = int(program.records["line"][r])
            if not out[s] or out[s][-1] != ln:
                out[s].append(ln)
        return out


def locate(piece_rec: np.ndarray, piece_t0: np.ndarray, piece_seg: np.ndarray, rec: np.ndarray,
           t: np.ndarray) -> np.ndarray:
    """The segment holding each point (record ``rec``, fraction ``t`` along it): the piece of
    that record that starts at or before t; -1 where the record is in no segment."""
    out = np.full(len(rec), -1, np.int64)
    if not len(piece_rec):
        return out
    key = piece_rec.astype(np.float64) * 4.0 + piece_t0  # records in order, pieces within each
    o = np.argsort(key)
    j = np.searchsorted(key[o], rec.astype(np.float64) * 4.0 + t, side="right") - 1
    cand = o[np.clip(j, 0, None)]
    valid = (j >= 0) & (piece_rec[cand] == rec)
    out[valid] = piece_seg[cand[valid]]
    return out


def splittable(program) -> np.ndarray:
    """Records the writer can split (a single move of its own line, plain geometry)."""
    rec = program.records
    bad = R.FL_CANNED | R.FL_SUB | R.FL_COMP | R.FL_DIAMETER | R.FL_MIRROR | R.FL_CORNER | R.FL_ROTARY | \
        R.FL_POLAR | R.FL_SPLINE
    ok = ((rec["flags"] & bad) == 0) & ((rec["flags"] & R.FL_FIRST_IN_LINE) != 0) & (rec["turns"] == 0)
    lines, counts = np.unique(rec["line"], return_counts=True)
    multi = np.isin(rec["line"], lines[counts > 1])
    ok &= ~multi
    if getattr(program, "is_macro", False):
        ok[:] = False
    return ok


def segment_path(program, model, power: np.ndarray, optimisable: np.ndarray, *, min_length: float = 5.0,
                 method: str = "cluster", k_radius: float = 2.0, tolerance: float = 0.05,
                 allow_splits: bool = True) -> Segments:
    """Segments of the path model's steps.

    ``power``: cutting power of every step (W); ``optimisable``: per record, whether its feed
    may be set; ``min_length``: the reference's C, in mm of path; ``tolerance``: the smallest
    radius of a cluster, as a fraction of the program's peak cutting power (a ramp closer than
    that is one segment); ``method``: ``cluster`` (sequential clustering) or ``changepoint``
    (binary segmentation, penalty from the same tolerance)."""
    rec = program.records
    n_rec = len(rec)
    steps_rec = model.rec
    ok_step = optimisable[steps_rec]
    # records without engagement steps (zero length) cannot start segments of their own
    order_ok = np.flatnonzero(ok_step)
    peak = float(power.max()) if len(power) else 0.0
    tol = tolerance * peak if peak > 0 else 1.0
    split_ok = splittable(program) if allow_splits else np.zeros(n_rec, bool)
    lengths = R.move_lengths(rec)

    # stretches: consecutive optimisable records of one tool, no other record between
    brk = np.zeros(len(order_ok), bool)
    if len(order_ok):
        r = steps_rec[order_ok]
        gap = np.diff(r) > 1  # a non-optimisable record (rapid, dwell, ...) in between
        # (a record between with no steps of its own is a zero-length move: not a break)
        if gap.any():
            between = [bool(np.any(~optimisable[a + 1:b] & (lengths[a + 1:b] > 0))) for a, b in
                       zip(r[:-1][gap], r[1:][gap])]
            gi = np.flatnonzero(gap)
            gap[gi[~np.array(between, bool)]] = False
        tool_change = np.diff(rec["tool"][r]) != 0
        # nor a change of the programmed feed: a segment's moves have one feed in the program,
        # so "the program's own feed" (the floor of learned limits, the time base) is one number
        feed_change = np.diff(rec["feed"][r]) != 0
        brk[1:] = gap | tool_change | feed_change
        brk[0] = True
    stretch_starts = np.flatnonzero(brk)
    stretch_ends = np.append(stretch_starts[1:], len(order_ok))

    seg_first_step: list[int] = []  # index into order_ok
    cut = power[order_ok] > 0.0
    w_all = model.length[order_ok]
    for a, b in zip(stretch_starts, stretch_ends):
        # cut / air runs; an air run shorter than C inside a cut is part of it
        c = cut[a:b].copy()
        w = w_all[a:b]
        runs = _runs(c)
        for s, e, v in runs:
            if not v and w[s:e].sum() < min_length and 0 < s and e < len(c):
                c[s:e] = True
        for s, e, v in _runs(c):
            if not v:
                seg_first_step.append(a + s)
                continue
            p = power[order_ok][a + s:a + e]
            ww = w[s:e]
            if method == "changepoint":
                var = tol * tol
                starts = SK.binary_segmentation(p, ww, min_length, penalty=var * max(ww.sum(), 1.0))
            else:
                out = np.zeros(len(p), np.int64)
                ns = SK.sequential_clusters.auto(len(p), p, ww, min_length, k_radius, tol, out)
                starts = out[:ns]
                # a last segment shorter than C joins the one before
                cw = np.cumsum(ww)
                if len(starts) > 1 and cw[-1] - (cw[starts[-1] - 1]) < min_length:
                    starts = starts[:-1]
                starts = _merge_close(starts, p, ww, tol)
            for s0 in starts:
                seg_first_step.append(a + s + int(s0))

    # boundaries -> pieces of records, snapped to move ends or splitting the move
    nseg = len(seg_first_step)
    first = np.array(seg_first_step, np.int64)
    seg_is_start = np.zeros(len(order_ok), np.int64) - 1
    seg_is_start[first] = np.arange(nseg)
    step_seg_ok = np.maximum.accumulate(np.where(seg_is_start >= 0, seg_is_start, -1)) if nseg else \
        np.zeros(0, np.int64)
    # boundary position: (record, fraction) between the last step of one and the first of the next
    cuts: dict[int, list[tuple[float, int]]] = {}  # record -> [(fraction, segment starting there)]
    rec_seg_start: dict[int, int] = {}  # record -> segment that starts at its beginning
    r_ok = steps_rec[order_ok]
    pos_ok = model.pos[order_ok]
    for si in range(nseg):
        k = first[si]
        r = int(r_ok[k])
        if k == 0 or r_ok[k - 1] != r:
            rec_seg_start[r] = si
            continue
        t = 0.5 * (pos_ok[k - 1] + pos_ok[k])
        L = lengths[r]
        if split_ok[r] and t * L >= max(MIN_PIECE, 0.5) and (1 - t) * L >= max(MIN_PIECE, 0.5) and \
                min(t, 1 - t) * L >= min(min_length / 2, 2.0):
            cuts.setdefault(r, []).append((float(t), si))
        elif t < 0.5:
            rec_seg_start[r] = si  # snap to the move's start
        # else: snap to its end — the segment starts at the next record
    # a line with several records: boundaries only at the line's first record
    seg_of_rec = np.full(n_rec, -1, np.int64)
    uniq, first_idx = np.unique(r_ok, return_index=True)
    cur = -1
    last_line = -1
    for r, k in zip(uniq, first_idx):
        ln = int(rec["line"][r])
        if not (ln == last_line and (rec["flags"][r] & R.FL_FIRST_IN_LINE) == 0 and cur >= 0):
            cur = rec_seg_start.get(int(r), int(step_seg_ok[k]))
        seg_of_rec[r] = cur
        last_line = ln
    # zero-length or stepless optimisable records between: the segment of the record before
    for r in np.flatnonzero(optimisable & (seg_of_rec < 0)):
        prev = seg_of_rec[:r][seg_of_rec[:r] >= 0]
        if len(prev) and rec["tool"][r] == rec["tool"][np.flatnonzero(seg_of_rec[:r] >= 0)[-1]]:
            seg_of_rec[r] = prev[-1]

    pr, p0, p1, ps = [], [], [], []
    for r in np.flatnonzero(seg_of_rec >= 0):
        s = int(seg_of_rec[r])
        t_prev = 0.0
        for t, s_next in sorted(cuts.get(int(r), [])):
            pr.append(r), p0.append(t_prev), p1.append(t), ps.append(s)
            s, t_prev = s_next, t
        pr.append(r), p0.append(t_prev), p1.append(1.0), ps.append(s)
    piece_rec = np.array(pr, np.int64)
    piece_seg = np.array(ps, np.int64)
    # segments that lost every piece to snapping disappear; renumber
    used = np.unique(piece_seg)
    renum = np.full(max(nseg, 1), -1, np.int64)
    renum[used] = np.arange(len(used))
    piece_seg = renum[piece_seg]
    nseg = len(used)
    # a segment is air when none of the steps its pieces hold after snapping meets material
    step_seg = locate(piece_rec, np.array(p0, float), piece_seg, steps_rec, model.pos)
    cut_steps = np.bincount(step_seg[(step_seg >= 0) & (power > 0)], minlength=nseg)
    air = cut_steps == 0
    seg_tool = np.zeros(nseg, np.int64)
    seg_tool[piece_seg] = rec["tool"][piece_rec]
    # lines that run in several segments (subprograms, loops): one variable
    parent = np.arange(nseg)

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    line_seg: dict[int, int] = {}
    multi_lines = set(np.unique(rec["line"])[np.bincount(np.unique(rec["line"], return_inverse=True)[1]) > 1].tolist())
    seen_rec = set()
    for r, s in zip(piece_rec, piece_seg):
        # the pieces of a split move are written apart; a line that makes several moves
        # (or runs several times) must have one feed
        ln = int(rec["line"][r])
        if r in seen_rec or ln not in multi_lines:
            seen_rec.add(int(r))
            continue
        seen_rec.add(int(r))
        if ln in line_seg:
            a, b = find(line_seg[ln]), find(int(s))
            if a != b:
                parent[max(a, b)] = min(a, b)
        else:
            line_seg[ln] = int(s)
    roots = np.array([find(i) for i in range(nseg)], np.int64)
    _, seg_var = np.unique(roots, return_inverse=True)
    return Segments(piece_rec, np.array(p0, float), np.array(p1, float), piece_seg, seg_var.astype(np.int64),
                    air, seg_tool, step_seg)


def _runs(v: np.ndarray):
    """(start, end, value) of the runs of equal values."""
    if not len(v):
        return []
    edges = np.flatnonzero(np.diff(v.astype(np.int8))) + 1
    starts = np.concatenate([[0], edges])
    ends = np.concatenate([edges, [len(v)]])
    return [(int(s), int(e), bool(v[s])) for s, e in zip(starts, ends)]


def _merge_close(starts: np.ndarray, p: np.ndarray, w: np.ndarray, tol: float) -> np.ndarray:
    """Adjacent clusters whose means differ by less than ``tol`` are one segment (a short
    spike at a corner opens a cluster that then returns to the level before)."""
    if len(starts) < 2:
        return starts
    keep = [int(starts[0])]
    ends = list(starts[1:]) + [len(p)]
    sw = float(w[starts[0]:ends[0]].sum())
    swp = float((w * p)[starts[0]:ends[0]].sum())
    for k in range(1, len(starts)):
        a, b = int(starts[k]), int(ends[k])
        w2 = float(w[a:b].sum())
        m2 = float((w * p)[a:b].sum()) / w2 if w2 > 0 else 0.0
        m1 = swp / sw if sw > 0 else 0.0
        if abs(m2 - m1) <= tol:
            sw += w2
            swp += m2 * w2
        else:
            keep.append(a)
            sw, swp = w2, m2 * w2
    return np.array(keep, np.int64)
