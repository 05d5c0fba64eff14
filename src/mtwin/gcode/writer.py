"""Byte-preserving rewrite of a program with new feeds, spindle speeds and move splits.

The output differs from the input only where asked: F/S words changed or
inserted, and moves split into pieces whose end points lie on the original path.
Every other byte — comments, N-numbers, spacing, case, blank lines, line
endings — is copied from the input.  Before returning, the result is
re-interpreted and checked: same geometry (:func:`verify.compare`) and the
requested feeds and speeds in effect on every move.  A rewrite that cannot be
expressed raises :class:`WriteError` and nothing is returned.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import WriteError
from ..units import MM_PER_INCH
from ._lexkernel import LF_BLOCK_DELETE
from .interpreter import Program, interpret
from .lexer import lex
from .numfmt import NumberStyle, detect_style
from .records import (
    is_feed_kind,
    FL_COMP,
    FL_CORNER,
    FL_MIRROR,
    FL_POLAR,
    FL_DIAMETER,
    FL_PROBE,
    FL_ROTARY,
    FL_SYNC,
    ARC_CCW, ARC_CW, DWELL, FEED_INVERSE_TIME, FEED_PER_MIN, FEED_PER_REV, FL_CANNED, FL_FIRST_IN_LINE, FL_IJK_ABSOLUTE,
    FL_F_INCH, FL_INCH, FL_INCREMENTAL, FL_R_ARC, FL_SUB, LINEAR, PLANE_AXES, RAPID, move_lengths, arc_sweep,
)
from .verify import compare

_AXIS = "XYZ"
_IJK = "IJK"


@dataclass
class Split:
    """Split one move at path fractions ``ts`` (strictly increasing, in (0, 1)).

    ``feeds`` has ``len(ts) + 1`` entries, the feed (mm/min) of each piece.
    """

    ts: list
    feeds: list


class _Edits:
    def __init__(self):
        self.items = []  # (start, end, order, bytes)

    def replace(self, start, end, text: str):
        self.items.append((int(start), int(end), 0, text.encode("latin-1")))

    def insert(self, pos, text: str, order=1):
        self.items.append((int(pos), int(pos), order, text.encode("latin-1")))

    def apply(self, data: bytes) -> bytes:
        out = []
        last = 0
        for start, end, _, text in sorted(self.items, key=lambda e: (e[0], e[1], e[2])):
            if start < last:
                raise WriteError("internal error: overlapping edits")
            out.append(data[last:start])
            out.append(text)
            last = end
        out.append(data[last:])
        return b"".join(out)


def _point_at(r, t):
    """Point at path fraction t of record r (linear or arc), mm."""
    s = np.array([r["sx"], r["sy"], r["sz"]])
    e = np.array([r["x"], r["y"], r["z"]])
    if r["kind"] == LINEAR:
        return s + t * (e - s)
    a1, a2, an = PLANE_AXES[r["plane"]]
    c = np.array([r["cx"], r["cy"], r["cz"]])
    sweep = float(arc_sweep(r.reshape(1))[0])
    th = t * sweep * (1.0 if r["kind"] == ARC_CCW else -1.0)
    v1, v2 = s[a1] - c[a1], s[a2] - c[a2]
    # a tolerated radius mismatch is a spiral: radius linear in the angle (as the twin's path)
    r0 = math.hypot(v1, v2)
    if r0 > 0:
        k = (r0 + t * (math.hypot(e[a1] - c[a1], e[a2] - c[a2]) - r0)) / r0
        v1, v2 = v1 * k, v2 * k
    p = s.copy()
    p[a1] = c[a1] + v1 * math.cos(th) - v2 * math.sin(th)
    p[a2] = c[a2] + v1 * math.sin(th) + v2 * math.cos(th)
    p[an] = s[an] + t * (e[an] - s[an])
    return p


class _WordIndex:
    """(line, letter) -> index of the line's last word with that letter, for the letters the
    writer edits — a sorted key array, not a dict of every word (an hour-long program has
    hundreds of thousands)."""

    def __init__(self, lx):
        letters = np.frombuffer(b"FSXYZIJKR", np.uint8)
        k = np.flatnonzero(np.isin(lx.w_letter, letters))
        keys = lx.w_line[k].astype(np.int64) * 256 + lx.w_letter[k].astype(np.int64)
        o = np.argsort(keys, kind="stable")
        self.keys, self.word = keys[o], k[o]

    def get(self, key, default=None):
        li, letter = key
        want = int(li) * 256 + ord(letter)
        j = int(np.searchsorted(self.keys, want, side="right")) - 1
        if j >= 0 and self.keys[j] == want:
            return int(self.word[j])
        return default

    def __contains__(self, key):
        return self.get(key) is not None

    def __getitem__(self, key):
        k = self.get(key)
        if k is None:
            raise KeyError(key)
        return k


class _Writer:
    def __init__(self, prog: Program, style: NumberStyle | None, lx=None):
        self.prog = prog
        # macro programs: the lexed source with its macro constructs blanked (same offsets)
        self.lx = lx if lx is not None else prog.lexed
        self.style = style or detect_style(self.lx)
        self.edits = _Edits()
        lx = self.lx
        nl = lx.n_lines
        self.word_of = _WordIndex(lx)  # (line, letter) -> word index
        self.nl = nl
        data = lx.data
        self.eol = "\r\n" if b"\r\n" in data[:4096] else "\n"
        self.lower = bool(lx.w_letter.size) and data[int(lx.w_start[0])] >= 97

    def letter(self, ch):
        return ch.lower() if self.lower else ch

    def sep(self, li):
        """' ' if words on this line are separated by spaces."""
        lx = self.lx
        w0 = int(lx.line_w0[li])
        nw = int(lx.line_nw[li])
        if nw >= 2:
            gap = self.lx.data[int(lx.w_end[w0]):int(lx.w_start[w0 + 1])]
            return " " if gap.strip() == b"" and gap else ""
        return " "

    def set_word(self, li, letter, text, order=1):
        k = self.word_of.get((li, letter))
        if k is not None:
            # keep the letter byte (and any space after it); replace the number
            lx = self.lx
            start = int(lx.w_start[k]) + 1
            self.edits.replace(start, int(lx.w_end[k]), text)
        else:
            self.edits.insert(int(self.lx.line_insert[li]), self.sep(li) + self.letter(letter) + text, order=order)


def _feed_word(r, feed, spindle, length, own_line=True):
    # an F on the record's own line is read in the units before that line's G20/G21;
    # on a line inserted after it, in the units in force for the move
    scale = MM_PER_INCH if r["flags"] & (FL_F_INCH if own_line else FL_INCH) else 1.0
    if r["feed_mode"] == FEED_PER_REV:
        if spindle <= 0:
            raise WriteError(f"line {r['line']}: feed per revolution (G95) with the spindle at 0 rpm")
        return feed / spindle / scale
    if r["feed_mode"] == FEED_INVERSE_TIME:
        return feed / max(length, 1e-12)
    return feed / scale


def _feed_targets(prog, st, rec, candidates, line0, new_feed, new_spindle, lengths) -> dict:
    """Per 0-based line, the F text its moves need; a line whose moves (a canned cycle, a
    subprogram, a repeat) were given different feeds is an error.  Per-minute feeds are worked
    out for all moves at once and each distinct value formatted once (an hour-long program
    rewrites 100,000 moves); per-revolution and inverse-time feeds one by one."""
    if not len(candidates):
        return {}
    r = rec[candidates]
    inch = (r["flags"] & FL_F_INCH) != 0
    vals = np.where(inch, new_feed[candidates] / MM_PER_INCH, new_feed[candidates]).astype(np.float64)
    special = np.flatnonzero((r["feed_mode"] == FEED_PER_REV) | (r["feed_mode"] == FEED_INVERSE_TIME))
    for k in special:
        i = int(candidates[k])
        vals[k] = _feed_word(rec[i], new_feed[i], new_spindle[i], lengths[i])
    inch_text = inch & (r["feed_mode"] != FEED_INVERSE_TIME)
    keys = np.column_stack([vals, inch_text.astype(np.float64)])
    uniq, inv = np.unique(keys, axis=0, return_inverse=True)
    inv = np.asarray(inv).reshape(-1)
    texts = [st.feed(float(v), bool(b)) for v, b in uniq]
    # distinct values may format alike (F1000.4 and F1000.3 both "1000" at 0 decimals)
    text_id = {t: k for k, t in enumerate(dict.fromkeys(texts))}
    tid = np.array([text_id[t] for t in texts], np.int64)[inv]
    lines = line0[candidates].astype(np.int64)
    order = np.argsort(lines, kind="stable")
    ls, ts = lines[order], tid[order]
    clash = np.flatnonzero((ls[1:] == ls[:-1]) & (ts[1:] != ts[:-1]))
    names = list(text_id)
    if len(clash):
        k = int(clash[0])
        raise WriteError(f"{prog.path}:{int(ls[k]) + 1}: this line runs several moves (canned cycle, "
                         f"subprogram or repeat) that were given different feeds ({names[ts[k]]} and "
                         f"{names[ts[k + 1]]})")
    starts = np.flatnonzero(np.r_[True, ls[1:] != ls[:-1]])
    return {int(li): names[int(t)] for li, t in zip(ls[starts], ts[starts])}


MIN_PIECE = 0.01  # mm: the shortest piece a split may leave (10 verify tolerances)


def rewrite(prog: Program, feeds=None, spindles=None, splits: dict | None = None,
            style: NumberStyle | None = None, check: bool = True) -> bytes:
    """Return the program's bytes with new feeds/speeds and split moves.

    Parameters
    ----------
    prog : Program
    feeds : array of float, optional
        Desired feed (mm/min) per record; NaN keeps it.  Only feed moves matter.
    spindles : array of float, optional
        Desired spindle speed (rpm) per record; NaN keeps it.
    splits : dict, optional
        ``{record_index: Split}``: split that move into pieces.
    style : NumberStyle, optional
        Number format; detected from the program when omitted.
    check : bool
        Re-interpret the result and prove geometry, feeds and speeds (default).
    """
    rec = prog.records
    n = rec.size
    feeds = np.full(n, np.nan) if feeds is None else np.asarray(feeds, float).copy()
    spindles = np.full(n, np.nan) if spindles is None else np.asarray(spindles, float).copy()
    if feeds.shape != (n,) or spindles.shape != (n,):
        raise WriteError(f"feeds and spindles must have one value per record ({n})")
    splits = dict(splits or {})
    locked_lines, locked_words = set(), set()
    lx_src = None
    if prog.is_macro:
        from .macro import mask_source

        if splits:
            i = min(splits)
            raise WriteError(f"{prog.path}:{int(rec['line'][i])}: cannot split moves of a macro program (their "
                             f"coordinates may be expressions or run in loops)")
        masked, locked_lines, locked_words = mask_source(prog.data, prog.dialect)
        lx_src = lex(masked, prog.path)
    w = _Writer(prog, style, lx_src)
    st = w.style
    lengths = move_lengths(rec)
    kinds = rec["kind"]
    is_feed = is_feed_kind(kinds)
    new_spindle = np.where(np.isnan(spindles), rec["spindle"], spindles)
    new_feed = np.where(np.isnan(feeds), rec["feed"], feeds)
    asked = is_feed & ~np.isnan(feeds)  # (a zero feed left to the caller, --lenient, may stay)
    sync = asked & ((rec["flags"] & FL_SYNC) != 0)
    if sync.any():
        i = int(np.argmax(sync))
        raise WriteError(f"{prog.path}:{int(rec['line'][i])}: a spindle-synchronised move (G33/G33.1) runs at its "
                         "pitch times the spindle speed: its feed cannot be changed")
    probe = asked & ((rec["flags"] & FL_PROBE) != 0)
    if probe.any():
        i = int(np.argmax(probe))
        raise WriteError(f"{prog.path}:{int(rec['line'][i])}: the feed of a probe move (G38.x) is part of the "
                         "measurement: it cannot be changed")
    is_feed = is_feed & ((rec["flags"] & (FL_SYNC | FL_PROBE)) == 0)
    if (new_feed[asked] <= 0).any() or not np.isfinite(new_feed[asked]).all():
        raise WriteError("feeds must be positive and finite")
    if (new_spindle < 0).any() or not np.isfinite(new_spindle).all():
        raise WriteError("spindle speeds must be non-negative and finite")
    for i, sp in splits.items():
        if not (0 <= i < n) or not is_feed[i]:
            raise WriteError(f"split requested on record {i}, which is not a feed move")
        new_feed[i] = sp.feeds[0]

    # ---- per-line targets (a line executed several times must agree) ----
    line0 = rec["line"].astype(np.int64) - 1
    f_target: dict = {}
    s_target: dict = {}
    changed_f = np.flatnonzero(is_feed & ~np.isclose(new_feed, rec["feed"], rtol=1e-12, atol=0))
    changed_s = np.flatnonzero(~np.isclose(new_spindle, rec["spindle"], rtol=1e-12, atol=0))
    f_lines = set(line0[changed_f].tolist()) | set(line0[changed_s].tolist())
    # Every feed line gets a target once anything changes: a line that keeps its
    # feed may still inherit a changed modal F and need its own word back.  In a macro
    # program a line may run many times with different inherited feeds: there, only the
    # lines whose feed changes, and the lines that ran with the feed a changed line had,
    # get targets (the self-check proves the result).
    # (a zero feed is one the program leaves to its caller, --lenient: nothing to keep)
    candidates = np.flatnonzero(is_feed & (new_feed > 0)) if f_lines or splits else np.zeros(0, np.int64)
    if prog.is_macro and len(candidates):
        keep = np.zeros(n, bool)
        keep[changed_f] = True
        old_changed = set(np.round(rec["feed"][changed_f], 9).tolist())
        same_line_feeds = {}
        for i in candidates:
            same_line_feeds.setdefault(int(line0[i]), set()).add(round(float(rec["feed"][i]), 9))
        for i in candidates:
            feeds_here = same_line_feeds[int(line0[i])]
            if len(feeds_here) == 1 and feeds_here & old_changed:
                keep[i] = True
        candidates = candidates[keep[candidates]]
    f_target = _feed_targets(prog, st, rec, candidates, line0, new_feed, new_spindle, lengths)
    for i in changed_s:
        li = int(line0[i])
        txt = st.spindle(new_spindle[i])
        prev = s_target.get(li)
        if prev is not None and prev != txt:
            raise WriteError(f"{prog.path}:{li + 1}: spindle speed would differ between executions of this line")
        s_target[li] = txt

    split_lines = {}
    for i, sp in splits.items():
        li = int(line0[i])
        r = rec[i]
        if r["flags"] & (FL_CANNED | FL_SUB) or not r["flags"] & FL_FIRST_IN_LINE or r["turns"] > 0:
            raise WriteError(f"{prog.path}:{li + 1}: cannot split a canned-cycle, subprogram or multi-turn move")
        if r["flags"] & FL_COMP:
            # the programmed path and the tool-centre path differ: a split point on one is not
            # the same fraction of the other
            raise WriteError(f"{prog.path}:{li + 1}: cannot split a move under cutter compensation")
        if r["flags"] & FL_DIAMETER:
            raise WriteError(f"{prog.path}:{li + 1}: cannot split a move in lathe diameter mode (G7)")
        if r["flags"] & FL_MIRROR:
            raise WriteError(f"{prog.path}:{li + 1}: cannot split a move under a mirror image (G51.1)")
        if r["flags"] & FL_CORNER:
            # its end point (or start) is where the Fanuc corner (,C ,R) begins, not where it is written
            raise WriteError(f"{prog.path}:{li + 1}: cannot split a move shortened by a corner chamfer or radius "
                             f"(,C ,R)")
        if r["flags"] & FL_ROTARY:
            raise WriteError(f"{prog.path}:{li + 1}: cannot split a move that drives an axis beyond X/Y/Z (A/B/C, U/V/W)")
        if r["flags"] & FL_POLAR:
            # a G91 polar word is relative to the polar coordinates of the move's start
            raise WriteError(f"{prog.path}:{li + 1}: cannot split a move given in polar words (@ ^)")
        if lengths[i] <= 0.0:
            raise WriteError(f"{prog.path}:{li + 1}: cannot split a zero-length move")
        if (line0 == li).sum() != 1:
            raise WriteError(f"{prog.path}:{li + 1}: cannot split a line that produces several moves")
        ts = [float(t) for t in sp.ts]
        if len(sp.feeds) != len(ts) + 1 or any(not (0 < t < 1) for t in ts) or ts != sorted(set(ts)):
            raise WriteError(f"split of line {li + 1}: fractions must be increasing in (0, 1), one more feed than "
                             "fractions")
        # a piece shorter than this is no cut of its own, and within a few verify tolerances
        # of its neighbours' ends it could not be told apart from them
        shortest = float(lengths[i]) * min(np.diff([0.0] + ts + [1.0]))
        if shortest < MIN_PIECE:
            raise WriteError(f"split of line {li + 1}: a piece would be {shortest:.4f} mm long; pieces must be at "
                             f"least {MIN_PIECE:g} mm")
        split_lines[li] = i

    if prog.is_macro:
        # a line whose F (or S) is an expression, or a macro statement, cannot be edited: it
        # may keep its value only, and the modal value after it is unknown to the writer
        for letter, targets, changed in (("F", f_target, changed_f), ("S", s_target, changed_s)):
            changed_lines = set(line0[changed].tolist())
            for li in list(targets):
                if li in locked_lines or (li, letter) in locked_words:
                    if li in changed_lines:
                        raise WriteError(f"{prog.path}:{li + 1}: the {letter} value of this line is a macro "
                                         f"expression; it cannot be rewritten")
                    del targets[li]
    _move_s_to_own_line(w, s_target, line0, locked_lines, locked_words)
    unknown = {li for li, letter in locked_words if letter == "F"} | locked_lines
    restored = _restore_after_changed(w, prog, f_target, changed_f, line0, is_feed, locked_words) \
        if prog.is_macro else {}
    _apply_modal(w, prog, "F", f_target, split_lines, splits, unknown, restored)
    _apply_modal(w, prog, "S", s_target, {}, {},
                 {li for li, letter in locked_words if letter == "S"} | locked_lines)
    for li, i in split_lines.items():
        _write_split(w, rec[i], li, splits[i], new_spindle[i], lengths[i])
    out = w.edits.apply(prog.data)
    if check:
        _self_check(prog, out, new_feed, new_spindle, splits)
    return out


def _move_s_to_own_line(w: _Writer, s_target: dict, line0: np.ndarray, locked_lines, locked_words) -> None:
    """A new speed for the first move after an S word on a line of its own (``S5000 M3``)
    replaces that word rather than adding one to the move: the spindle is started at the new
    speed, as the program intended, instead of being changed (and run up again) a line later."""
    if not s_target:
        return
    lx = w.lx
    s_lines = sorted({int(x) for x in lx.w_line[lx.w_letter == ord("S")]})
    if not s_lines:
        return
    s_set = set(s_lines)
    rec_lines = np.unique(line0)
    rec_set = set(rec_lines.tolist())
    for li in sorted(s_target):
        if li in s_set:
            continue
        k = int(np.searchsorted(s_lines, li)) - 1
        if k < 0:
            continue
        p = s_lines[k]
        if p in rec_set or p in s_target or p in locked_lines or (p, "S") in locked_words:
            continue
        j = int(np.searchsorted(rec_lines, p, side="right"))
        if j >= len(rec_lines) or rec_lines[j] != li:
            continue  # a move between the S word and this line already runs at the old speed
        s_target[p] = s_target.pop(li)


def _restore_after_changed(w: _Writer, prog: Program, f_target: dict, changed_f, line0, is_feed,
                           locked_words) -> dict:
    """In a macro program only some lines get an F target, so a changed modal F could carry
    past a changed line into a line that runs at several feeds (a loop's first line on its
    next pass, a subprogram called again after other F words): such a line cannot take a word
    of its own.  Where the next feed move after a changed line (in the order the program ran)
    is on a line that sets no F, the feed the changed line had is written back on a line of
    its own (``F10``) inserted right after it: that line runs exactly when the changed one does
    (it is no jump target) and leaves the modal F as the program had it.  A changed line runs
    at one feed in every execution (``_feed_targets``), so that feed is known.  Returns
    {line: modal feed value after it} for ``_apply_modal``.  The self-check proves the result."""
    lx = w.lx
    rec = prog.records
    has_f = set(lx.w_line[lx.w_letter == ord("F")].tolist()) | {li for li, c in locked_words if c == "F"}
    feed_idx = np.flatnonzero(is_feed)
    if not len(feed_idx):
        return {}
    fl = line0[feed_idx]
    # per feed record: the position of the next feed record on another line (the start of the
    # next run of equal lines)
    starts = np.append(np.flatnonzero(fl[1:] != fl[:-1]) + 1, len(feed_idx))
    nxt = starts[np.searchsorted(starts, np.arange(len(feed_idx)), side="right")]
    restored: dict = {}
    pos = np.searchsorted(feed_idx, changed_f)
    for i, k in zip(changed_f, pos):
        li = int(line0[i])
        if li in restored or li not in f_target or k >= len(feed_idx) or feed_idx[k] != i:
            continue
        n = nxt[k]
        if n >= len(feed_idx):
            continue
        nl = int(fl[n])
        if nl in f_target or nl in has_f:
            continue
        r = rec[i]
        if r["feed_mode"] != FEED_PER_MIN:
            continue  # per revolution or inverse time: every such move carries its own F
        inch = bool(r["flags"] & FL_INCH)
        text = w.style.feed(_feed_word(r, float(r["feed"]), float(r["spindle"]), 1.0, own_line=False), inch)
        prefix = "/" if lx.line_flags[li] & LF_BLOCK_DELETE else ""
        # after the line and after any pieces a split of it adds (order 2 + k)
        w.edits.insert(int(lx.line_end[li]), w.eol + prefix + w.letter("F") + text, order=10_000)
        restored[li] = float(text)
    return restored


def _apply_modal(w: _Writer, prog: Program, letter: str, targets: dict, split_lines: dict, splits: dict,
                 unknown: set = frozenset(), restored: dict | None = None):
    """Set F (or S) on the lines that need it, tracking the modal value in file order.
    ``unknown``: lines after which the modal value is not known (macro expressions);
    ``restored``: lines after which a line of its own sets the value back."""
    if not targets:
        return
    lx = w.lx
    ks = np.flatnonzero(lx.w_letter == ord(letter))
    word_lines = {int(lx.w_line[k]): float(lx.w_value[k]) for k in ks}
    for li in unknown:
        if li not in targets:
            word_lines[li] = float("nan")
    modal = None
    for li in sorted(set(word_lines) | set(targets)):
        tgt = targets.get(li)
        old = word_lines.get(li)
        if tgt is None:
            modal = old
            continue
        if old is not None:
            if float(tgt) != old:
                w.set_word(li, letter, tgt)
        elif modal is None or float(tgt) != modal:
            w.set_word(li, letter, tgt, order=2)
        modal = float(tgt)
        if li in split_lines:
            i = split_lines[li]
            r = prog.records[i]
            modal = float(w.style.feed(_feed_word(r, splits[i].feeds[-1], r["spindle"], 1.0, own_line=False),
                                       bool(r["flags"] & FL_INCH)))
        if restored and li in restored:
            modal = restored[li]


def _write_split(w: _Writer, r, li: int, sp: Split, spindle: float, length: float):
    lx = w.lx
    st = w.style
    inch = bool(r["flags"] & FL_INCH)
    scale = MM_PER_INCH if inch else 1.0
    dec = max(st.coord_decimals, 5 if inch else 4)
    incremental = bool(r["flags"] & FL_INCREMENTAL)
    is_arc = r["kind"] != LINEAR
    s = np.array([r["sx"], r["sy"], r["sz"]])
    e = np.array([r["x"], r["y"], r["z"]])
    c = np.array([r["cx"], r["cy"], r["cz"]])
    if is_arc:
        a1, a2, an = PLANE_AXES[r["plane"]]
        axes = sorted({int(a1), int(a2)} | ({int(an)} if abs(e[an] - s[an]) > 0 else set()))
    else:
        axes = [a for a in range(3) if e[a] != s[a]]
    for a in range(3):
        if (li, _AXIS[a]) in w.word_of and a not in axes:
            axes.append(a)
    axes.sort()
    pts = [_point_at(r, t) for t in sp.ts] + [e]
    q = 10.0 ** dec
    # positions in program units on the decimal grid, so that in G91 the written
    # increments add up exactly to the original move and nothing drifts
    if incremental:
        base = s / scale
        grid = [np.round((p / scale - base) * q) for p in pts[:-1]]
        orig = []
        for a in range(3):
            k = w.word_of.get((li, _AXIS[a]))
            orig.append(lx.w_value[k] if k is not None else (e[a] - s[a]) / scale)
        grid.append(np.round(np.array(orig) * q))
        words_at = []
        prev = np.zeros(3)
        for g in grid:
            words_at.append((g - prev) / q)
            prev = g
        written = [base + g / q for g in grid]
    else:
        words_at = [np.round(p / scale * q) / q for p in pts]
        written = [wv.copy() for wv in words_at]
    piece_start = s / scale
    # first piece: the original line, end point moved
    for a in axes:
        w.set_word(li, _AXIS[a], st.coord(words_at[0][a], dec))
    if is_arc and r["flags"] & FL_R_ARC:
        k = w.word_of[(li, "R")]
        cen = _ijk(c / scale, piece_start, r)
        txt = w.sep(li).join(w.letter(_IJK[a]) + st.coord(cen[a], dec) for a in (a1, a2))
        w.edits.replace(int(lx.w_start[k]), int(lx.w_end[k]), txt)
    # following pieces: new lines after the original one
    sep = w.sep(li)
    prefix = "/" if lx.line_flags[li] & LF_BLOCK_DELETE else ""
    gword = {LINEAR: "G1", ARC_CW: "G2", ARC_CCW: "G3"}[int(r["kind"])]
    for k in range(1, len(pts)):
        start_k = written[k - 1]
        parts = [w.letter(gword[0]) + gword[1:]]
        for a in axes:
            parts.append(w.letter(_AXIS[a]) + st.coord(words_at[k][a], dec))
        if is_arc:
            cen = _ijk(c / scale, start_k, r)
            parts += [w.letter(_IJK[a]) + st.coord(cen[a], dec) for a in (a1, a2)]
        fw = _feed_word(r, sp.feeds[k], spindle, length, own_line=False)
        parts.append(w.letter("F") + st.feed(fw, inch))
        w.edits.insert(int(lx.line_end[li]), w.eol + prefix + sep.join(parts), order=2 + k)


def _ijk(center, start, r):
    """Arc centre words: absolute (G90.1) or relative to the piece start (G91.1)."""
    if r["flags"] & FL_IJK_ABSOLUTE:
        return center
    return center - start


def _self_check(prog: Program, out: bytes, new_feed, new_spindle, splits):
    if prog.is_macro or prog.source is not None:
        from .interpreter import load_program

        new = load_program(out, prog.settings, path=prog.path)
    else:
        new = interpret(lex(out, prog.path), prog.settings)
    diff = compare(prog, new, tol=2e-3)
    if diff is not None:
        raise WriteError(f"internal check failed, nothing written: rewritten program differs in geometry: {diff}")
    # expected feeds per new record: originals expanded by the splits
    exp_f = []
    exp_s = []
    rec = prog.records
    for i in range(rec.size):
        if i in splits:
            exp_f.extend(splits[i].feeds)
            exp_s.extend([new_spindle[i]] * len(splits[i].feeds))
        else:
            exp_f.append(new_feed[i])
            exp_s.append(new_spindle[i])
    exp_f = np.asarray(exp_f)
    exp_s = np.asarray(exp_s)
    nr = new.records
    if nr.size != exp_f.size:
        raise WriteError(f"internal check failed, nothing written: {nr.size} moves instead of {exp_f.size}")
    # (spindle-synchronised moves follow the spindle speed: their feed is checked through it)
    isf = (nr["kind"] != RAPID) & (nr["kind"] != DWELL) & ((nr["flags"] & FL_SYNC) == 0)
    # tolerance: F is written to within 0.1 % of the feed asked for (NumberStyle.feed adds
    # decimals for that), or half a unit of its sixth decimal for a vanishing feed
    inch_f = (nr["flags"] & (FL_F_INCH | FL_INCH)) != 0
    res = np.where(inch_f, 0.5e-6 * MM_PER_INCH, 0.5e-6)
    res = np.where(nr["feed_mode"] == FEED_PER_REV, res * nr["spindle"], res)
    tol = res * 1.0001 + 1.0001e-3 * np.abs(exp_f)
    tol = np.where(nr["feed_mode"] == FEED_INVERSE_TIME, np.inf, tol)
    bad = np.flatnonzero(isf & (np.abs(nr["feed"] - exp_f) > tol))
    if bad.size:
        j = bad[0]
        raise WriteError(f"internal check failed, nothing written: line {nr['line'][j]} would run at "
                         f"{nr['feed'][j]:g} mm/min instead of {exp_f[j]:g}")
    # S is written as a whole number of rpm (NumberStyle.spindle).  A rapid may run at the
    # speed the written words leave modal rather than at the one asked: a new S for one tool
    # carries over a tool change into the next tool's rapids until that tool's own S word
    # (where the program had none between, the writer adds none: a macro line such as
    # G10 L2 P#501 cannot take one).  Rapids cut nothing; every cutting move is checked.
    bad = np.flatnonzero((np.abs(nr["spindle"] - exp_s) > 0.5 + 1e-9) & (nr["kind"] != RAPID))
    if bad.size:
        j = bad[0]
        raise WriteError(f"internal check failed, nothing written: line {nr['line'][j]} would run the spindle at "
                         f"{nr['spindle'][j]:g} rpm instead of {exp_s[j]:g}")


def scaled_feeds(prog: Program, feed: float = 1.0, spindle: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """The feeds (mm/min) ``scale_feeds`` asks for before any clamp, and which records it may change."""
    rec = prog.records
    is_feed = is_feed_kind(rec["kind"])
    is_feed &= rec["feed"] > 0  # a feed the program leaves to its caller (--lenient) stays as it is
    is_feed &= (rec["flags"] & FL_SYNC) == 0  # a thread or rigid tap runs at pitch x spindle speed
    is_feed &= (rec["flags"] & FL_PROBE) == 0  # a probing feed is part of the measurement
    # in G95 the feed per revolution is kept, so mm/min follows the spindle
    f = rec["feed"] * feed * np.where(rec["feed_mode"] == FEED_PER_REV, spindle, 1.0)
    return f, is_feed


def scale_feeds(prog: Program, feed: float = 1.0, spindle: float = 1.0, max_feed: float | None = None,
                style: NumberStyle | None = None, machine_max: float | None = None) -> bytes:
    """Bake a feed (and spindle) override into the program; clamp feeds to ``max_feed`` (mm/min).

    ``machine_max``: the machine's maximum cutting feed; a feed the scaling would raise above it
    is written at it (a feed the program already had above it is the program's, and stays)."""
    if not (feed > 0 and math.isfinite(feed)):
        raise WriteError("--feed must be a positive number")
    if not (spindle > 0 and math.isfinite(spindle)):
        raise WriteError("--spindle must be a positive number")
    if max_feed is not None and not (max_feed > 0):
        raise WriteError("--max-feed must be positive")
    rec = prog.records
    spindles = np.full(rec.size, np.nan)
    f, is_feed = scaled_feeds(prog, feed, spindle)
    feeds = np.full(rec.size, np.nan)
    if feed != 1.0 or max_feed is not None or spindle != 1.0:
        if max_feed is not None:
            f = np.minimum(f, max_feed)
        if machine_max is not None:
            f = np.where((f > machine_max) & (f > rec["feed"]), np.maximum(machine_max, rec["feed"]), f)
        feeds = np.where(is_feed & (f != rec["feed"]), f, np.nan)
    if spindle != 1.0:
        css = np.flatnonzero(rec["css"] > 0)
        if css.size:
            # the rpm follows X and stops at the D limit: scaling S (a surface speed) does not
            # scale it, nor the feed of a G95 move
            raise WriteError(f"{prog.path}:{int(rec['line'][css[0]])}: --spindle cannot scale a constant surface "
                             f"speed (G96) program: its spindle speed follows the diameter up to the D limit")
        spindles = rec["spindle"] * spindle
        spindles = np.where(spindles != rec["spindle"], spindles, np.nan)
    return rewrite(prog, feeds, spindles, style=style)
