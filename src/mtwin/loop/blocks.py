"""Per-block timing: measured block durations against simulated ones, summed by block kind.

A control that logs the executing line (MTConnect ``Block_Number``) reports only some lines —
it samples every 0.15–0.2 s — so a measured *block group* is a reported line and every line
after it up to the next reported one.  Its measured duration runs from the time its line was
first reported to the time the next group's was; its simulated duration from the time the
twin's interpolator reached its first line to the time it reached the next group's.  Durations
are independent of the two clocks' offset.  The noise floor: a line is reported up to one
sampling interval late, at both ends, so the same code run twice differs by about 0.15 s per
group; errors are meaningful summed over many groups, which is what the table by kind does.

Summed by kind, that lateness does not cancel: a line shorter than the sampling interval is
reported, when it is, late by half its own duration on average, a long line by half the
interval, so a short group's measured time takes some of the next group's, of another kind.
The simulation *as logged* shifts each simulated group boundary by the delay the log would
have had there (:func:`simulated_as_logged`), so the table by kind compares like with like.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import re

import numpy as np

from ..gcode import records as R
from .measurement import HELD, coverage, held_spans

_TOOL_CHANGE = re.compile(rb"M0*6(?!\d)")
_PROGRAM_STOP = re.compile(rb"M0*[01](?![\d.])")  # M00 / M01 (M0, M1): the control may wait for the operator
_END = re.compile(rb"M(?:0*30|0*2)(?!\d)")

KINDS = ("tool change", "program end", "drilling cycle", "plunge", "small arc", "short line", "rapid", "feed",
         "other")
NOISE_FLOOR = 0.15  # s per logged group, the same code run twice (NIST Hurco logs)
# s: a block group at an M00/M01 that took this long waited for the operator.  Shorter ones
# are the machine's own time (an M01 with optional stop off still takes 2-5 s on the NIST
# Hurco plates: the spindle and coolant stopping) and stay in the block timing.
STOP_MIN = 10.0


@dataclass
class BlockTiming:
    first_line: np.ndarray  # (groups,) the reported line
    last_line: np.ndarray  # (groups,) the last line before the next reported one
    measured: np.ndarray  # (groups,) s
    simulated: np.ndarray  # (groups,) s
    kind: list  # (groups,) KINDS
    excluded: list = field(default_factory=list)  # groups left out (run at a feed override of 0 %, not held)
    hold_time: float = 0.0  # s of feed hold taken out of the measured durations
    stops: list = field(default_factory=list)  # dicts: program stops (M00/M01 waits, logged stop states)
    feed_ratio: dict = field(default_factory=dict)  # kind -> the log's own feed over the programmed F (asrun)
    feed_ratio_twin: dict = field(default_factory=dict)  # kind -> the same of a log of the twin's own run
    logged: np.ndarray | None = None  # (groups,) s, the simulated durations as the log would show them
    period: float = 0.0  # s, the log's sampling interval of the executing line (report_period)
    bias: dict = field(default_factory=dict)  # kind -> s, what the as-logged sum shows of the twin's own run

    @property
    def stop_time(self) -> float:
        """s the program stood at program stops (taken out of the block timing)."""
        return float(sum(x["wait"] for x in self.stops))

    @property
    def error(self) -> np.ndarray:
        return self.simulated - self.measured

    @property
    def error_as_logged(self) -> np.ndarray:
        """Each group's simulated − measured s, the simulated side as the log would show it: the
        per-group figure compared like with like (what the timing fit and ``diagnose`` use; the
        raw error carries the log's reporting delays, ≈ 0.03 s RMS more per group)."""
        return (self.simulated if self.logged is None else self.logged) - self.measured

    def by_kind(self) -> list:
        out = []
        logged = self.simulated if self.logged is None else self.logged
        for k in KINDS:
            m = np.array([x == k for x in self.kind], bool)
            if m.any():
                as_logged = float(logged[m].sum()) - self.bias.get(k, 0.0)
                out.append({"kind": k, "groups": int(m.sum()), "measured": float(self.measured[m].sum()),
                            "simulated": float(self.simulated[m].sum()), "error": float(self.error[m].sum()),
                            "rms": float(np.sqrt(np.mean(self.error_as_logged[m] ** 2))),
                            "simulated_as_logged": as_logged,
                            "error_as_logged": as_logged - float(self.measured[m].sum()),
                            "logging_bias": self.bias.get(k, 0.0),
                            "logged_over_programmed_feed": self.feed_ratio.get(k),
                            "twin_logged_over_programmed_feed": self.feed_ratio_twin.get(k)})
        return sorted(out, key=lambda d: -abs(d["error"]))

    def worst(self, n: int = 10, text: list | None = None) -> list:
        e, logged = self.error_as_logged, self.simulated if self.logged is None else self.logged
        order = np.argsort(-np.abs(e))[:n]
        return [{"first_line": int(self.first_line[i]), "last_line": int(self.last_line[i]),
                 "measured": float(self.measured[i]), "simulated": float(self.simulated[i]),
                 "simulated_as_logged": float(logged[i]), "error": float(e[i]), "kind": self.kind[i],
                 "text": (text[int(self.first_line[i]) - 1].strip() if text and 0 < self.first_line[i] <= len(text)
                          else "")} for i in order]

    def as_dict(self, text=None) -> dict:
        e = self.error_as_logged
        return {"groups": len(self.measured), "rms": float(np.sqrt(np.mean(e ** 2))) if len(e) else None,
                "noise_floor_per_group": NOISE_FLOOR, "report_period": self.period, "by_kind": self.by_kind(), "worst": self.worst(10, text),
                "excluded": self.excluded, "feed_hold_s": self.hold_time, "program_stops": self.stops,
                "program_stop_s": self.stop_time}


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
    measured: np.ndarray  # (groups,) s, feed-hold and logged stop time taken out
    kind: list
    excluded: list  # dicts: groups left out (run at a feed override of 0 %, not held), with the reason
    hold_time: float  # s of feed hold inside the run (taken out of the measured durations)
    # dicts: program stops the control logged (t0, t1, state), taken out of the durations
    logged_stops: list = field(default_factory=list)
    code: list = field(default_factory=list)  # (groups,) "M00" / "M01" for a group at a program stop, else ""
    stop_line: list = field(default_factory=list)  # (groups,) the line of that M00/M01
    t0: np.ndarray | None = None  # (groups,) s, when the group began
    period: float = 0.0  # s, the log's sampling interval of the executing line (0: not known)
    jitter: float = 0.1  # its spread: each interval within ±jitter·period (report_jitter)
    # dicts: groups at an M00/M01 that waited for the operator (set_apart_stops): line, state,
    # measured, simulated, wait — left out of the arrays above
    stop_groups: list = field(default_factory=list)

    @property
    def stop_time(self) -> float:
        """s of logged program stops inside the run."""
        return float(sum(x["t1"] - x["t0"] for x in self.logged_stops))

    @property
    def wait_time(self) -> float:
        """s the set-apart M00/M01 groups waited beyond the twin's time for their lines."""
        return float(sum(x["wait"] for x in self.stop_groups))

    def take(self, keep: np.ndarray) -> "Groups":
        """The groups where ``keep`` is true (the rest of the fields as they are)."""
        keep = np.asarray(keep, bool)
        pick = (lambda seq: [x for x, k in zip(seq, keep) if k])
        return replace(self, first_line=self.first_line[keep], next_line=self.next_line[keep],
                       last_line=self.last_line[keep], measured=self.measured[keep], kind=pick(self.kind),
                       code=pick(self.code), stop_line=pick(self.stop_line),
                       t0=None if self.t0 is None else self.t0[keep])


def report_period(t: np.ndarray, line: np.ndarray, least: int = 20) -> float:
    """The interval at which the executing line is sampled, read off the log.  A control's log
    (on change) reports only at samples, so the times between consecutive changes cluster at
    one interval, two, … (0.17–0.19 s on the NIST Hurco logs): the median of the first cluster.
    A recording that holds the line at every sample, far more often than it changes (a trace at
    100 Hz), is sampled at its own rate.  0 with fewer than ``least`` changes."""
    t, line = np.asarray(t, np.float64), np.asarray(line)
    if len(t) < 2:
        return 0.0
    dt = _change_intervals(t, line)
    if len(dt) < least:
        return 0.0
    q = float(np.percentile(dt, 25))
    one = dt[(dt > 0.5 * q) & (dt < 1.5 * q)]
    period = float(np.median(one)) if len(one) else 0.0
    step = np.diff(t)
    step = float(np.median(step[step > 0])) if (step > 0).any() else period
    return step if step < 0.5 * period else period


def _change_intervals(t: np.ndarray, line: np.ndarray) -> np.ndarray:
    """The (positive) times between consecutive changes of the logged line."""
    dt = np.diff(t[np.flatnonzero(np.diff(line) != 0) + 1])
    return dt[dt > 0]


def report_jitter(t: np.ndarray, line: np.ndarray, period: float, least: int = 20) -> float:
    """How much the sampling interval ``period`` (:func:`report_period`) varies, as the
    half-width of a uniform spread relative to it (the 10th to 90th percentile of the first
    cluster spans 80 % of it): ±0.10–0.16 on the NIST Hurco logs (0.16–0.20 s around 0.19 s).
    0.1 when not known."""
    if period <= 0 or len(t) < 2:
        return 0.1
    dt = _change_intervals(np.asarray(t, np.float64), np.asarray(line))
    one = dt[(dt > 0.5 * period) & (dt < 1.5 * period)]
    if len(one) < least:
        return 0.1
    p10, p90 = np.percentile(one, [10, 90])
    return float(np.clip((p90 - p10) / 1.6 / period, 0.02, 0.5))


def simulated_as_logged(groups: Groups, sim: np.ndarray, lines: np.ndarray, starts: np.ndarray,
                        sim_end: float) -> np.ndarray:
    """Each group's simulated duration as a log sampling at ``groups.period`` would show it.

    A line is reported at the first sample after it starts — uniformly within the interval for
    a line longer than it, within its own duration for a shorter one (reported at all only if a
    sample falls inside it, which the log says happened) — so on average late by half the
    shorter of the two; a group's boundaries move by those delays.  Summed over consecutive
    groups the shifts cancel: the cycle time is unchanged."""
    period = groups.period
    if period <= 0 or not len(lines):
        return sim
    order = np.argsort(starts, kind="stable")
    dur = np.empty(len(starts))
    dur[order] = np.diff(np.append(starts[order], sim_end))

    def delay(ln):
        k = np.searchsorted(lines, ln)
        ok = k < len(lines)
        return np.where(ok, 0.5 * np.minimum(dur[np.minimum(k, len(lines) - 1)], period), 0.0)

    d1 = np.where(groups.next_line > 0, delay(groups.next_line), 0.0)
    return sim + d1 - delay(groups.first_line)


# logs of the twin's own run that :func:`logging_bias` averages: their sums by kind spread by up
# to 1.4 s on the NIST Hurco plates, so the mean of 8 was good to ~0.5 s, of 32 to ~0.25 s, for
# ~12 ms a log on a 4,000-line program
LOG_SEEDS = 32
MIN_LOG_PERIOD = 0.05  # s: a log sampling the line faster shows too little bias to correct


def logging_bias(program, groups: Groups, lines: np.ndarray, starts: np.ndarray, sim_end: float,
                 seeds: int = LOG_SEEDS) -> dict:
    """{kind: s}: the as-logged error summed by kind that a log of the twin's own run shows —
    where the true error is zero — averaged over ``seeds`` logs.

    The delays of :func:`simulated_as_logged` are a first-order picture: which lines a log
    reports, and so how the groups are cut and which kind each takes, depends on where its
    samples fall.  On the NIST Hurco plates the sums by kind of the twin's own run, logged every
    0.19 s, still show up to ±2.2 s (sd 0.05–1.4 s between logs).  So the twin's run is logged
    ``seeds`` times at ``groups.period`` (each interval uniform within ±``groups.jitter``, the
    first sample anywhere in the first interval), cut and classified as the real log is, and the
    mean of the sums is what a by-kind comparison takes off."""
    period = groups.period
    if period < MIN_LOG_PERIOD or not len(lines):
        return {}
    order = np.argsort(starts, kind="stable")
    st, ln = starts[order], lines[order]
    h = groups.jitter
    n = int((sim_end - st[0]) / ((1.0 - h) * period)) + 2
    seen: dict = {}
    sums: dict = {}
    for seed in range(seeds):
        rng = np.random.default_rng(seed)
        ts = st[0] + rng.uniform(0.0, period) + np.concatenate(([0.0], np.cumsum(rng.uniform((1.0 - h) * period,
                                                                                          (1.0 + h) * period, n))))
        ts = ts[ts < sim_end]
        at = ln[np.maximum(np.searchsorted(st, ts, "right") - 1, 0)].astype(np.int64)
        g = measured_groups(program, ts, at, sim_end, kinds_seen=seen)
        g.period = period
        sim = simulated_durations(g, lines, starts, sim_end)
        err = simulated_as_logged(g, sim, lines, starts, sim_end) - g.measured
        ok = np.isfinite(err)
        for k in set(g.kind):
            m = ok & np.array([x == k for x in g.kind], bool)
            sums.setdefault(k, [0.0] * seeds)[seed] = float(err[m].sum())
    return {k: float(np.mean(v)) for k, v in sums.items()}


def set_apart_stops(g: Groups, simulated: np.ndarray) -> Groups:
    """The groups without those at an M00/M01 that took STOP_MIN longer than the twin does for
    their lines (the control waited for the operator there), which go to ``stop_groups`` with
    their wait.  Judged against the simulation, not the measured time alone: an M01 with
    optional stop off, or beside a tool change the twin times wrongly, stays in."""
    sim = np.where(np.isfinite(simulated), simulated, 0.0)
    wait = g.measured - sim
    stop = np.array([bool(c) for c in g.code], bool) & (wait >= STOP_MIN) if len(g.code) else \
        np.zeros(len(g.measured), bool)
    if not stop.any():
        return g
    out = g.take(~stop)
    out.stop_groups = list(g.stop_groups) + [
        {"line": g.stop_line[i], "first_line": int(g.first_line[i]), "last_line": int(g.last_line[i]),
         "state": g.code[i], "t0": float(g.t0[i]) if g.t0 is not None else None, "measured": float(g.measured[i]),
         "simulated": float(sim[i]), "wait": float(wait[i])} for i in np.flatnonzero(stop)]
    return out


def measured_groups(program, meas_t: np.ndarray, meas_line: np.ndarray, meas_end: float | None = None,
                    holds=(), overrides: dict | None = None, stops=(), kinds_seen: dict | None = None) -> Groups:
    """Block groups of a measurement: each reported line and the unreported ones after it,
    with its measured duration.  ``holds``: (t0, t1) feed-hold intervals and ``stops``: (t0,
    t1, state) program stops the control logged, taken out of the durations they fall in;
    ``overrides``: signal -> % per sample (feed, rapid, spindle override), which the twin
    applies (:mod:`mtwin.loop.asrun`); the time the machine stood at a feed override of 0 % is a
    hold (:func:`.measurement.held_spans`, which :func:`measurement_groups` and the replay add),
    and a group that ran at 0 % for longer than its holds and stops cover is left out and listed.  A group at an M00 or M01 has its ``code``: against a
    simulation, :func:`set_apart_stops` sets those that waited for the operator apart.
    ``kinds_seen``: (first, last, is_last) -> kind of groups already classified (kept across
    calls on one program: the logs of :func:`logging_bias` share most of their groups)."""
    ms = line_starts(meas_t, meas_line)
    reported = sorted(ms, key=lambda ln: ms[ln])
    end = float(meas_t[-1]) if meas_end is None else float(meas_end)
    n_lines = int(program.data.count(b"\n") + 1)
    spans = tool_change_spans(program)
    text_lines = program.data.split(b"\n")
    firsts, nexts, lasts, meas, kinds, excluded, codes, at_lines, starts = [], [], [], [], [], [], [], [], []
    stop_spans = [(a, b) for a, b, _ in stops]
    # (a hold inside a logged stop is the stop's: counted once)
    stood, stopped = coverage([*holds, *stop_spans]), coverage(stop_spans)
    for k, ln in enumerate(reported):
        nxt = reported[k + 1] if k + 1 < len(reported) else None
        if nxt is not None and nxt <= ln:
            continue  # out of order (a loop or a re-report): left out
        t0, t1 = ms[ln], (ms[nxt] if nxt is not None else end)
        last = (nxt - 1) if nxt is not None else n_lines
        why = _overridden(meas_t, overrides, t0, t1, stood)
        if why:
            excluded.append({"first_line": ln, "last_line": last, "t0": t0, "t1": t1, "reason": why})
            continue
        d = t1 - t0 - stood(t0, t1)
        code, at = _stop_code(text_lines[ln - 1:last])
        codes.append(code)
        at_lines.append(ln + at)
        starts.append(t0)
        firsts.append(ln)
        nexts.append(nxt or 0)
        lasts.append(last)
        meas.append(d)
        key = (ln, last, nxt is None)
        kind = kinds_seen.get(key) if kinds_seen is not None else None
        if kind is None:
            kind = classify(program, ln, last, nxt is None, spans, text_lines)
            if kinds_seen is not None:
                kinds_seen[key] = kind
        kinds.append(kind)
    # (disjoint: a stop that overlaps the one before it keeps only its own time, counted once)
    logged: list = []
    for a, b, st in sorted(stops):
        a = max(a, logged[-1]["t1"]) if logged else a
        if a < min(b, end):
            logged.append({"t0": a, "t1": min(b, end), "state": st})
    period = report_period(meas_t, meas_line)
    return Groups(np.array(firsts, np.int64), np.array(nexts, np.int64), np.array(lasts, np.int64),
                  np.array(meas, np.float64), kinds, excluded,
                  stood(0.0, end) - stopped(0.0, end), logged, codes, at_lines,
                  np.array(starts, np.float64), period=period, jitter=report_jitter(meas_t, meas_line, period))


def _stop_code(text: list) -> tuple[str, int]:
    """('M00' or 'M01', its index in ``text``) when one of the lines stops the program
    (comments left out), else ('', 0)."""
    for k, ln in enumerate(text):
        m = _PROGRAM_STOP.search(re.sub(rb"\([^)]*\)|;.*", b"", ln).upper().replace(b" ", b""))
        if m:
            return ("M01" if m.group(0).endswith(b"1") else "M00"), k
    return "", 0


def _overridden(t: np.ndarray, overrides, t0: float, t1: float, stood) -> str:
    """Why a group's time is not the program's: the feed override below HELD % for a time
    ``stood`` (a :func:`.measurement.coverage` of holds and logged stops) does not take out.  Where it stood at 0 %,
    the time is a hold (:func:`.measurement.held_spans`, the one judge of that) and the group is
    kept, as a feed hold's is; what is left ran at 0 % while the machine moved (a Fanuc-style
    control runs rapids on at 0 %), which the twin cannot replay on the group's feed moves.  Any
    other value the twin applies; a rapid override at 0 is the slowest rapid, F0, which the twin
    replays."""
    v = (overrides or {}).get("feed_override")
    if v is None:
        return ""
    i0 = max(int(np.searchsorted(t, t0, "right")) - 1, 0)  # the value in force at t0
    i1 = max(int(np.searchsorted(t, t1, "left")), i0 + 1)  # and every value logged before t1
    edges = np.clip(np.r_[t0, t[i0 + 1:i1], t1], t0, t1)
    vals = np.nan_to_num(v[i0:i1], nan=100.0)
    left = [(b - a - stood(a, b), x) for a, b, x in zip(edges[:-1], edges[1:], vals) if x < HELD and b > a]
    moved = sum(d for d, _ in left if d > 1e-9)
    if moved > 1e-6:
        return (f"it ran at a feed override of {min(x for d, x in left if d > 1e-9):g} % for {moved:.1f} s while "
                f"the machine moved")
    return ""


def simulated_starts(sim_t: np.ndarray, sim_line: np.ndarray):
    """(lines sorted, their first times) of a simulation (its per-sample line)."""
    ss = line_starts(sim_t, sim_line)
    lines = np.array(sorted(ss), np.int64)
    return lines, np.array([ss[int(x)] for x in lines], np.float64)


def simulated_durations(groups: Groups, lines: np.ndarray, starts: np.ndarray, sim_end: float) -> np.ndarray:
    """Each group's simulated duration: from the time the interpolator reached its first line
    (or the first line after it that it reaches) to the time it reached the next group's; a
    line after the last one the simulation reaches is reached at its end (the twin spends no
    time on it: an M30 the control stands at, a park move another twin runs).  So the groups
    kept, and the measured side, are the log's whatever the twin; NaN only without a simulation."""
    def at(ln):
        k = np.searchsorted(lines, ln)
        ok = k < len(lines)
        return np.where(ok, starts[np.minimum(k, len(lines) - 1)] if len(lines) else np.nan,
                        sim_end if len(lines) else np.nan)

    s0 = at(groups.first_line)
    s1 = np.where(groups.next_line > 0, at(groups.next_line), sim_end)
    return s1 - s0


def block_timing(program, meas_t: np.ndarray, meas_line: np.ndarray, sim_t: np.ndarray, sim_line: np.ndarray,
                 meas_end: float | None = None, holds=(), overrides: dict | None = None, stops=()) -> BlockTiming:
    """Measured and simulated durations of the measurement's block groups."""
    return _against(measured_groups(program, meas_t, meas_line, meas_end, holds, overrides, stops), sim_t, sim_line,
                    program)


def _against(g: Groups, sim_t, sim_line, program=None) -> BlockTiming:
    sim_t = np.asarray(sim_t)
    lines, starts = simulated_starts(sim_t, np.asarray(sim_line))
    end = float(sim_t[-1]) if len(sim_t) else 0.0
    sim = simulated_durations(g, lines, starts, end)
    kept = set_apart_stops(g, sim)
    if kept is not g:
        sim = simulated_durations(kept, lines, starts, end)
    ok = np.isfinite(sim)
    stops = [{"state": x["state"], "t0": x["t0"], "t1": x["t1"], "wait": x["t1"] - x["t0"]} for x in g.logged_stops]
    stops += kept.stop_groups
    logged = simulated_as_logged(kept, sim, lines, starts, end)
    bias = logging_bias(program, kept, lines, starts, end) if program is not None else {}
    return BlockTiming(kept.first_line[ok], kept.last_line[ok], kept.measured[ok], sim[ok],
                       [k for k, o in zip(kept.kind, ok) if o], g.excluded, g.hold_time, stops, logged=logged[ok],
                       period=g.period, bias=bias)


def measurement_groups(program, meas) -> Groups:
    """:func:`measured_groups` of a read measurement: its end time, feed holds, logged program
    stops and override columns where it has them (a control's log)."""
    overrides = {k: np.asarray(v, np.float64) for k, v in meas.extra.items() if k.endswith("_override")}
    # (the time the machine stood at a feed override of 0 %: none new where the replay, which
    # finds the same, has made it holds already)
    holds = [*meas.holds, *held_spans(meas)]
    return measured_groups(program, meas.t, meas.line, meas.end_time, holds, overrides, meas.stops)


def measurement_block_timing(program, meas, trace) -> BlockTiming:
    """:func:`block_timing` of a read measurement against a simulation."""
    return _against(measurement_groups(program, meas), trace.t, trace.line, program)
