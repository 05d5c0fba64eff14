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

from dataclasses import dataclass, field

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
    excluded: list = field(default_factory=list)  # groups left out (overrides), with the reason
    hold_time: float = 0.0  # s of feed hold taken out of the measured durations

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
                "noise_floor_per_group": NOISE_FLOOR, "by_kind": self.by_kind(), "worst": self.worst(10, text),
                "excluded": self.excluded, "feed_hold_s": self.hold_time}


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


def classify(program, first: int, last: int, is_last: bool, spans=(), text_lines=None) -> str:
    """The kind of a block group, lines first..last (1-based, inclusive)."""
    rec = program.records
    text = (text_lines if text_lines is not None else program.data.split(b"\n"))[first - 1:last]
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


@dataclass
class Groups:
    """The measurement's block groups, fixed once (what a timing fit compares against)."""

    first_line: np.ndarray  # (groups,) the reported line
    next_line: np.ndarray  # (groups,) the next group's reported line, 0 for the last group
    last_line: np.ndarray  # (groups,)
    measured: np.ndarray  # (groups,) s, feed-hold time taken out
    kind: list
    excluded: list  # dicts: groups left out (overrides away from 100 %), with the reason
    hold_time: float  # s of feed hold inside the run (taken out of the measured durations)


def _overlap(a0: float, a1: float, spans) -> float:
    return float(sum(max(0.0, min(a1, b1) - max(a0, b0)) for b0, b1 in spans))


def measured_groups(program, meas_t: np.ndarray, meas_line: np.ndarray, meas_end: float | None = None,
                    holds=(), overrides: dict | None = None) -> Groups:
    """Block groups of a measurement: each reported line and the unreported ones after it,
    with its measured duration.  ``holds``: (t0, t1) feed-hold intervals, taken out of the
    durations they fall in; ``overrides``: signal -> % per sample (feed, spindle override):
    a group run at anything but 100 % is left out and listed (its time is not the program's)."""
    ms = line_starts(meas_t, meas_line)
    reported = sorted(ms, key=lambda ln: ms[ln])
    end = float(meas_t[-1]) if meas_end is None else float(meas_end)
    n_lines = int(program.data.count(b"\n") + 1)
    spans = tool_change_spans(program)
    text_lines = program.data.split(b"\n")
    firsts, nexts, lasts, meas, kinds, excluded = [], [], [], [], [], []
    for k, ln in enumerate(reported):
        nxt = reported[k + 1] if k + 1 < len(reported) else None
        if nxt is not None and nxt <= ln:
            continue  # out of order (a loop or a re-report): left out
        t0, t1 = ms[ln], (ms[nxt] if nxt is not None else end)
        last = (nxt - 1) if nxt is not None else n_lines
        why = _overridden(meas_t, overrides, t0, t1)
        if why:
            excluded.append({"first_line": ln, "last_line": last, "t0": t0, "t1": t1, "reason": why})
            continue
        firsts.append(ln)
        nexts.append(nxt or 0)
        lasts.append(last)
        meas.append(t1 - t0 - _overlap(t0, t1, holds))
        kinds.append(classify(program, ln, last, nxt is None, spans, text_lines))
    return Groups(np.array(firsts, np.int64), np.array(nexts, np.int64), np.array(lasts, np.int64),
                  np.array(meas, np.float64), kinds, excluded, _overlap(0.0, end, holds))


def _overridden(t: np.ndarray, overrides, t0: float, t1: float) -> str:
    """Why a group's time is not the program's: an override away from 100 % while it ran."""
    for name, v in (overrides or {}).items():
        # the value in force at t0 and every value logged before t1
        i0 = max(int(np.searchsorted(t, t0, "right")) - 1, 0)
        i1 = max(int(np.searchsorted(t, t1, "left")), i0 + 1)
        w = v[i0:i1]
        w = w[~np.isnan(w)]
        if len(w) and (np.abs(w - 100.0) > 0.5).any():
            return f"{name} {w[np.argmax(np.abs(w - 100.0))]:g} %"
    return ""


def simulated_starts(sim_t: np.ndarray, sim_line: np.ndarray):
    """(lines sorted, their first times) of a simulation (its per-sample line)."""
    ss = line_starts(sim_t, sim_line)
    lines = np.array(sorted(ss), np.int64)
    return lines, np.array([ss[int(x)] for x in lines], np.float64)


def simulated_durations(groups: Groups, lines: np.ndarray, starts: np.ndarray, sim_end: float) -> np.ndarray:
    """Each group's simulated duration: from the time the interpolator reached its first line
    (or the first line after it that it reaches) to the time it reached the next group's;
    NaN where it never gets there."""
    def at(ln):
        k = np.searchsorted(lines, ln)
        ok = k < len(lines)
        return np.where(ok, starts[np.minimum(k, len(lines) - 1)] if len(lines) else np.nan, np.nan)

    s0 = at(groups.first_line)
    s1 = np.where(groups.next_line > 0, at(groups.next_line), sim_end)
    return s1 - s0


def block_timing(program, meas_t: np.ndarray, meas_line: np.ndarray, sim_t: np.ndarray, sim_line: np.ndarray,
                 meas_end: float | None = None, holds=(), overrides: dict | None = None) -> BlockTiming:
    """Measured and simulated durations of the measurement's block groups."""
    return _against(measured_groups(program, meas_t, meas_line, meas_end, holds, overrides), sim_t, sim_line)


def _against(g: Groups, sim_t, sim_line) -> BlockTiming:
    sim_t = np.asarray(sim_t)
    lines, starts = simulated_starts(sim_t, np.asarray(sim_line))
    sim = simulated_durations(g, lines, starts, float(sim_t[-1]) if len(sim_t) else 0.0)
    ok = np.isfinite(sim)
    return BlockTiming(g.first_line[ok], g.last_line[ok], g.measured[ok], sim[ok], [k for k, o in zip(g.kind, ok) if o],
                       g.excluded, g.hold_time)


def measurement_groups(program, meas) -> Groups:
    """:func:`measured_groups` of a read measurement: its end time, feed holds and override
    columns where it has them (an MTConnect log)."""
    extra = getattr(meas, "extra", {}) or {}
    overrides = {k: np.asarray(extra[k], np.float64) for k in ("feed_override", "spindle_override") if k in extra}
    for k in ("feed_override", "spindle_override"):
        if k in meas.signals:
            overrides[k] = meas.signals[k]
    end, holds = run_end_and_holds(meas)
    return measured_groups(program, meas.t, meas.line, end, holds, overrides)


def run_end_and_holds(meas):
    """(end of the run in s or None, feed-hold intervals) of a measurement: read from an
    MTConnect log, or from the metadata ``mtwin import mtconnect`` wrote into its file."""
    end = getattr(meas, "end_time", None)
    holds = getattr(meas, "holds", None)
    meta = meas.meta or {}
    if end is None and meta.get("cycle_time_s"):
        try:
            end = float(meta["cycle_time_s"])
        except ValueError:
            end = None
    if holds is None:
        holds = []
        for part in filter(None, (x.strip() for x in meta.get("feed_holds_s", "").split(";"))):
            a, _, b = part.partition("-")
            try:
                holds.append((float(a), float(b)))
            except ValueError:
                pass
    return end, holds


def measurement_block_timing(program, meas, trace) -> BlockTiming:
    """:func:`block_timing` of a read measurement against a simulation."""
    return _against(measurement_groups(program, meas), trace.t, trace.line)
