"""Per-block timing: measured block durations against simulated ones, summed by block kind.

A control that logs the executing line (MTConnect ``Block_Number``) reports only some lines —
it samples every 0.15–0.2 s — so a measured *block group* is a reported line and every line
after it up to the next reported one.  Its measured duration runs from the time its line was
first reported to the time the next group's was; its simulated duration from the time the
twin's interpolator reached its first line to the time it reached the next group's.  Durations
are independent of the two clocks' offset.  The noise floor: a line is reported up to one
sampling interval late, at both ends, so the same code run twice differs by about 0.15 s per
group; errors are meaningful summed over many groups, which is what the table by kind does.
"""
from __future__ import annotations

from dataclasses import dataclass

import re

import numpy as np

from ..gcode import records as R

_TOOL_CHANGE = re.compile(rb"M0*6(?!\d)")
_END = re.compile(rb"M(?:0*30|0*2)(?!\d)")

KINDS = ("tool change", "program end", "drilling cycle", "plunge", "small arc", "short line", "rapid", "feed",
         "other")
NOISE_FLOOR = 0.15  # s per logged group, the same code run twice (NIST Hurco logs)


@dataclass
class BlockTiming:
    first_line: np.ndarray  # (groups,) the reported line
    last_line: np.ndarray  # (groups,) the last line before the next reported one
    measured: np.ndarray  # (groups,) s
    simulated: np.ndarray  # (groups,) s
    kind: list  # (groups,) KINDS

    @property
    def error(self) -> np.ndarray:
        return self.simulated - self.measured

    def by_kind(self) -> list:
        out = []
        for k in KINDS:
            m = np.array([x == k for x in self.kind], bool)
            if m.any():
                out.append({"kind": k, "groups": int(m.sum()), "measured": float(self.measured[m].sum()),
                            "simulated": float(self.simulated[m].sum()), "error": float(self.error[m].sum()),
                            "rms": float(np.sqrt(np.mean(self.error[m] ** 2)))})
        return sorted(out, key=lambda d: -abs(d["error"]))

    def worst(self, n: int = 10, text: list | None = None) -> list:
        order = np.argsort(-np.abs(self.error))[:n]
        return [{"first_line": int(self.first_line[i]), "last_line": int(self.last_line[i]),
                 "measured": float(self.measured[i]), "simulated": float(self.simulated[i]),
                 "error": float(self.error[i]), "kind": self.kind[i],
                 "text": (text[int(self.first_line[i]) - 1].strip() if text and 0 < self.first_line[i] <= len(text)
                          else "")} for i in order]

    def as_dict(self, text=None) -> dict:
        return {"groups": len(self.measured), "rms": float(np.sqrt(np.mean(self.error ** 2))) if len(self.error) else None,
                "noise_floor_per_group": NOISE_FLOOR, "by_kind": self.by_kind(), "worst": self.worst(10, text)}


def line_starts(t: np.ndarray, line: np.ndarray) -> dict:
    """Time each line is first seen (reported, or reached by the interpolator)."""
    ok = line > 0
    t, line = t[ok], line[ok]
    first = np.flatnonzero(np.concatenate([[True], line[1:] != line[:-1]]))
    out: dict = {}
    for i in first:
        out.setdefault(int(line[i]), float(t[i]))
    return out


def tool_change_spans(program) -> list:
    """(first, last) lines of every tool-change sequence: from the line after the last feed
    move before an M6 to the line before the first feed move after it (spindle stop, coolant,
    home, optional stop, the change, the new tool's approach and spindle run-up)."""
    rec = program.records
    feed_lines = np.unique(rec["line"][rec["kind"] != R.RAPID])
    out = []
    for i, raw in enumerate(program.data.split(b"\n"), 1):
        if _TOOL_CHANGE.search(raw.split(b"(")[0].upper().replace(b" ", b"")):
            k = int(np.searchsorted(feed_lines, i))
            lo = int(feed_lines[k - 1]) + 1 if k > 0 else 1
            hi = int(feed_lines[k]) - 1 if k < len(feed_lines) else i
            out.append((lo, hi))
    return out


def classify(program, first: int, last: int, is_last: bool, spans=()) -> str:
    """The kind of a block group, lines first..last (1-based, inclusive)."""
    rec = program.records
    text = program.data.split(b"\n")[first - 1:last]
    code = b" ".join(ln.split(b"(")[0].upper().replace(b" ", b"") for ln in text)
    if _TOOL_CHANGE.search(code) or any(lo <= first and last <= hi for lo, hi in spans):
        return "tool change"
    if is_last or _END.search(code):
        return "program end"
    m = (rec["line"] >= first) & (rec["line"] <= last)
    r = rec[m]
    if not len(r):
        return "other"
    if (r["flags"] & R.FL_CANNED).any():
        return "drilling cycle"
    feed = r[r["kind"] != R.RAPID]
    if len(feed):
        L = R.move_lengths(feed)
        dz = feed["z"] - feed["sz"]
        if ((dz < 0) & (-dz > 0.5 * np.maximum(L, 1e-12))).any():
            return "plunge"
        arc = (feed["kind"] == R.ARC_CW) | (feed["kind"] == R.ARC_CCW)
        if arc.any():
            rad = np.hypot(feed["sx"][arc] - feed["cx"][arc], feed["sy"][arc] - feed["cy"][arc])
            if (rad < 2.0).any():
                return "small arc"
        if (L < 3.0).all():
            return "short line"
        return "feed"
    return "rapid"


def block_timing(program, meas_t: np.ndarray, meas_line: np.ndarray, sim_t: np.ndarray, sim_line: np.ndarray,
                 meas_end: float | None = None) -> BlockTiming:
    """Measured and simulated durations of the measurement's block groups."""
    ms = line_starts(meas_t, meas_line)
    ss = line_starts(sim_t, sim_line)
    reported = sorted(ms, key=lambda ln: ms[ln])
    # groups in the order they were reported; a line reported again later (a loop) starts a new group
    firsts, lasts, meas, sim, kinds = [], [], [], [], []
    sim_lines = np.array(sorted(ss))
    sim_end = float(sim_t[-1]) if len(sim_t) else 0.0
    end = float(meas_t[-1]) if meas_end is None else float(meas_end)

    def sim_start(ln: int) -> float | None:
        # the interpolator's first time at this line, or at the first line after it it reaches
        k = int(np.searchsorted(sim_lines, ln))
        return ss[int(sim_lines[k])] if k < len(sim_lines) else None

    spans = tool_change_spans(program)
    for k, ln in enumerate(reported):
        nxt = reported[k + 1] if k + 1 < len(reported) else None
        if nxt is not None and nxt <= ln:
            continue  # out of order (a loop or a re-report): left out
        t_end = ms[nxt] if nxt is not None else end
        s0 = sim_start(ln)
        s1 = sim_start(nxt) if nxt is not None else sim_end
        if s0 is None or s1 is None:
            continue
        last = (nxt - 1) if nxt is not None else int(program.data.count(b"\n") + 1)
        firsts.append(ln)
        lasts.append(last)
        meas.append(t_end - ms[ln])
        sim.append(s1 - s0)
        kinds.append(classify(program, ln, last, nxt is None, spans))
    return BlockTiming(np.array(firsts, np.int64), np.array(lasts, np.int64), np.array(meas), np.array(sim), kinds)
