"""The program as a control's log says it ran: the overrides in force applied, and a run the
log does not finish compared only as far as it got.

A control's log (an MTConnect log, or the file ``mtwin import mtconnect`` writes from it)
holds the operator's feed, rapid and spindle overrides as time series.  The twin runs each
block at the overrides that were in force while it ran: a record's override is the
time-weighted mean of the logged value over its block group (the reported line and the
unreported lines after it, up to the next reported one), so a ramp from 0 to 74 % within a
group gives the group the time it took.  Feed override scales the feed of feed moves, rapid
override the speed of rapids, spindle override the speed.  A record the log never reached
runs at the last value logged.

Records are matched to the log's block groups in execution order (``record_groups``): a
record entering the line the next group reports starts that group, so loops, repeats and
subprograms stored below M30 get the override of the run they were in.  A log that names no
program line gets each override's mean over the whole run, and says so.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import MtwinError, SourceLocation
from ..gcode import records as R
from .measurement import HELD, MeasurementError, held_spans, merged
from .mtconnect import Outline

#: override column -> what it scales
SCALES = {"feed_override": "feed moves' feed", "rapid_override": "rapids' speed", "spindle_override": "spindle speed"}


@dataclass
class AsRun:
    """The program to simulate for a measurement, and what was done to it."""

    program: object  # the program with the overrides applied (the program itself when none)
    measurement: object = None  # the measurement to compare with (cut at the last line reached: --partial)
    applied: dict = field(default_factory=dict)  # override column -> (lowest, highest) % applied
    not_logged: list = field(default_factory=list)  # override columns a control's log did not have
    partial_to: int = 0  # the last line compared (--partial), 0: to the program's end
    partial_from: int = 0  # the first line compared (--partial: a run started in the middle), 0: the start
    held: list = field(default_factory=list)  # (t0, t1) s an override stood at 0 %: taken out as feed holds
    whole_run: bool = False  # the log names no line: each override's mean over the run applied to all

    @property
    def notes(self) -> list:
        out = []
        for k, (lo, hi) in self.applied.items():
            what = f"{lo:g} %" if abs(hi - lo) < 0.05 else f"{lo:g}–{hi:g} %"
            out.append(f"{k.replace('_', ' ')} {what} applied to the {SCALES[k]} of the blocks it was in force for")
        if self.whole_run and self.applied:
            out.append("the log names no program line: each override's mean over the whole run is applied to every "
                       "block")
        if self.held:
            out.append(f"an override at 0 % held the machine for {sum(b - a for a, b in self.held):.1f} s ("
                       + ", ".join(f"{a:.1f}–{b:.1f} s" for a, b in self.held[:3]) + (", …" if len(self.held) > 3 else "")
                       + "): taken out of the measured times as a feed hold")
        if self.not_logged:
            out.append(f"{', '.join(k.split('_')[0] for k in self.not_logged)} override not logged: 100 % assumed "
                       f"(values calibrated from this run are effective: they include any override the operator set)")
        if self.partial_from:
            out.append(f"--partial: the run started at line {self.partial_from}; the program and the log are compared "
                       f"from that line on (the lines before it never ran in this run)")
        if self.partial_to:
            out.append(f"--partial: the run stopped at line {self.partial_to}; the program and the log are compared "
                       f"up to the start of that line (cycle times to the moment it was reached)")
        return out



def as_run(program, meas, partial: bool = False) -> AsRun:
    """The program as ``meas`` (a control's log) says it ran; ``partial``: a run the log does
    not finish is compared up to the moment its last line was reached (else it is an error)."""
    if meas.t is None:
        return AsRun(program, meas)
    out = AsRun(program, meas)
    has_lines = meas.line is not None and bool((meas.line > 0).any())
    # the log's block groups in time order, and the group each record ran in (once: the cut
    # and the overrides below both read them)
    g_t0, g_line = transitions(meas.t, meas.line) if has_lines else (np.zeros(0), np.zeros(0, np.int64))
    group = record_groups(program.records["line"], g_line) if has_lines else None
    if meas.complete is False:
        last = _last_line(meas)
        late = int(meas.meta.get("started_at", 0) or 0)
        if not partial and late:
            raise MeasurementError(f"the run in the log starts at line {late} of {program.path or 'the program'}, not at "
                                   f"its start (restarted in the middle, or logged from there) — compare the part "
                                   f"that ran with --partial", SourceLocation(meas.path, 0, 0))
        others = " (or another of the log's runs with --run K)" if len(meas.runs or ()) > 1 else ""
        if not partial:
            why = meas.meta.get("ended") or "a logger that stopped, or the run was aborted"
            where = "" if f"line {last}" in why else f"; it ran to line {last}"
            raise MeasurementError(f"the run in the log of {program.path or 'the program'} is incomplete: {why}{where} "
                                   f"— compare the part that ran with --partial{others}", SourceLocation(meas.path, 0, 0))
        if not has_lines:
            raise MeasurementError("the run in the log is incomplete and the log names no program line, so where it "
                                   "stopped is not known: --partial cannot cut the program there",
                                   SourceLocation(meas.path, 0, 0))
        # a run that started in the middle is compared from its first reported line (the
        # records before it never ran); one that reached the program's end is not cut there
        head = int(np.argmax(group >= 0)) if late and (group >= 0).any() else 0
        reached_end = late and Outline.of(program).at_end(last)
        # both sides up to the moment the last line was entered (its last entry, in execution
        # order): how long the control ran it before the log stops is not known; the records
        # kept are all in the groups before it, whose ends (g_t0 of the next) are unchanged
        t_last = float(meas.end_time if meas.end_time is not None else meas.t[-1]) if reached_end else float(g_t0[-1])
        cut = len(group) if reached_end else _cut(program.records["line"], group, len(g_t0) - 1, int(g_line[-1]))
        if cut <= head or not (program.records["kind"][head:cut] != R.DWELL).any():
            raise MeasurementError(f"the run in the log stops at line {last}, before the program's first move: there "
                                   f"is nothing to compare", SourceLocation(meas.path, 0, 0))
        program = replace(program, records=program.records[head:cut].copy(), running=head > 0,
                          end_tool_change=program.end_tool_change if reached_end else 0)
        group = group[head:cut]
        keep = meas.t <= t_last
        meas = replace(meas, t=meas.t[keep], line=np.where(meas.t[keep] < t_last, meas.line[keep], -1),
                       signals={k: v[keep] for k, v in meas.signals.items()},
                       extra={k: v[keep] for k, v in meas.extra.items()}, end_time=t_last,
                       holds=_clip(meas.holds, t_last), stops=_clip(meas.stops, t_last),
                       source_line=None if meas.source_line is None else meas.source_line[keep])
        out.measurement = meas
        out.partial_to = 0 if reached_end else last
        out.partial_from = late
    logged = {k: np.asarray(v, np.float64) for k, v in meas.extra.items() if k in SCALES}
    if meas.meta.get("source", "").startswith("MTConnect") or "overrides" in meas.meta or "block_is" in meas.meta:
        out.not_logged = [k for k in SCALES if k not in logged or np.isnan(logged[k]).all()]
    # an override at 0 % held the machine (the operator's time, as a feed hold is): taken out of
    # the measured times, and out of the overrides' means over the blocks it fell in
    held = held_spans(meas)
    if held:
        meas = replace(meas, holds=sorted(list(meas.holds or []) + held))
        out.measurement = meas
        out.held = held
    # (the overrides' values while the machine stood — held, a feed hold, a program stop — are
    # not what it ran at)
    stood = merged([*meas.holds, *(meas.stops or [])])
    active = {k: v for k, v in logged.items() if not np.isnan(v).all() and (np.abs(v[~np.isnan(v)] - 100.0) > 1e-9).any()}
    if not active:
        out.program = program
        return out
    rec = program.records
    end = meas.end_time if meas.end_time is not None else float(meas.t[-1])
    if group is not None:
        g_t1 = np.concatenate([g_t0[1:], [end]])
        t0 = np.where(group >= 0, g_t0[np.maximum(group, 0)], float(meas.t[0]))
        t1 = np.where(group >= 0, g_t1[np.maximum(group, 0)], g_t0[0] if len(g_t0) else end)
    else:
        # no program line in the log: the whole run's mean, for every record (and said so)
        t0, t1 = np.full(len(rec), float(meas.t[0])), np.full(len(rec), end)
        out.whole_run = True
    moving = rec["kind"] != R.DWELL
    new = rec.copy()
    for k, v in active.items():
        f = np.clip(_time_mean(meas.t, v, t0, t1, stood), HELD, None) / 100.0
        if k == "feed_override":
            m = moving & (rec["kind"] != R.RAPID) & ((rec["flags"] & R.FL_SYNC) == 0)
            new["feed"] = np.where(m, rec["feed"] * f, rec["feed"])
            used = f[m]
        elif k == "spindle_override":
            # (the speed the spindle is driven to, not a new S: the control does not wait for
            # the spindle when only the override turns, so the plan gets no run-up pause)
            program = replace(program, spindle_scale=f)
            used = f[rec["spindle"] > 0]
        else:
            program = replace(program, rapid_scale=np.where(rec["kind"] == R.RAPID, f, 1.0))
            used = f[rec["kind"] == R.RAPID]
        if len(used):
            out.applied[k] = (round(100.0 * float(used.min()), 1), round(100.0 * float(used.max()), 1))
    out.program = replace(program, records=new)
    return out


def _last_line(meas) -> int:
    ok = meas.line > 0 if meas.line is not None else np.zeros(0, bool)
    return int(meas.line[ok][-1]) if ok.any() else 0


def _clip(spans: list, t: float) -> list:
    """Intervals (t0, t1, …) cut back to end at ``t``."""
    return [(a, min(b, t), *rest) for a, b, *rest in spans if a < t]


def transitions(t: np.ndarray, line: np.ndarray):
    """(times, lines) of the log's block groups in time order: every change of the reported
    line (a line reported again later — a loop, a subprogram called twice — is a new group)."""
    ok = line > 0
    tt, ll = t[ok], line[ok]
    start = np.flatnonzero(np.r_[True, ll[1:] != ll[:-1]]) if len(ll) else np.zeros(0, np.int64)
    return tt[start], ll[start].astype(np.int64)


def record_groups(lines: np.ndarray, g_line: np.ndarray) -> np.ndarray:
    """Per record (in execution order), the index of the log's block group it ran in (-1:
    before the first), matching the records to the groups in step: a record that enters the
    line the next group reports starts that group; groups whose line no record has (a
    comment, an M-code line) are passed over; a record on a line the log did not report stays
    in the group before it.  ``g_line``: the groups' lines (:func:`transitions`)."""
    has = set(np.unique(lines).tolist())
    out = np.full(len(lines), -1, np.int64)
    g = -1
    prev = None
    for i, ln in enumerate(lines.tolist()):
        if ln != prev:
            j = g + 1
            while j < len(g_line) and g_line[j] not in has:
                j += 1
            if j < len(g_line) and g_line[j] == ln:
                g = j
        out[i] = g
        prev = ln
    return out


def _cut(lines: np.ndarray, group: np.ndarray, last_group: int, last_line: int) -> int:
    """The first record of the last group the log reached (the run stopped there); when that
    group's line has no record, the first record past the group before it."""
    at = np.flatnonzero(group == last_group)
    if len(at):
        return int(at[0])
    before = np.flatnonzero(group == last_group - 1) if last_group > 0 else np.zeros(0, np.int64)
    if not len(before):
        return 0
    # the records of the group before run on until the program passes the last line (or jumps)
    start = int(before[0])
    for i in range(start + 1, len(lines)):
        if lines[i] >= last_line or lines[i] < lines[i - 1]:
            return i
    return len(lines)


def _time_mean(t: np.ndarray, v: np.ndarray, a: np.ndarray, b: np.ndarray, held=()) -> np.ndarray:
    """Mean over [a, b) of the step function that holds v[i] from t[i] (NaN: 100 %) — its value
    at a where b <= a; before the first sample, the first value.  ``held``: (t0, t1) spans left
    out, disjoint (where the machine stood: their values, near 0 when it was held, are not the
    override it ran at)."""
    v = np.where(np.isnan(v), 100.0, v)
    # the integral at the sample times, then linear between them (a step's integral is linear)
    cum = np.concatenate([[0.0], np.cumsum(v[:-1] * np.diff(t))])

    def integral(x):
        i = np.clip(np.searchsorted(t, x, side="right") - 1, 0, len(t) - 1)
        return cum[i] + v[i] * (x - t[i])

    at = v[np.clip(np.searchsorted(t, a, side="right") - 1, 0, len(t) - 1)]
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    if not len(held):
        span = b - a
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(span > 1e-9, (integral(b) - integral(a)) / span, at)
    # the held spans' time and their own values' integral, taken off: what stood before x is the
    # spans x is past, whole (cumulated once), and the part of the one it is in — two binary
    # searches a record, however many spans (a single-block run stands at every line)
    s0 = np.array([h[0] for h in held], np.float64)
    s1 = np.array([h[1] for h in held], np.float64)
    whole_t = np.concatenate([[0.0], np.cumsum(s1 - s0)])
    whole_i = np.concatenate([[0.0], np.cumsum(integral(s1) - integral(s0))])

    def stood(x):
        k = np.searchsorted(s1, x, side="right")
        kk = np.minimum(k, len(s0) - 1)
        inside = (k < len(s0)) & (x > s0[kk])
        return (whole_t[k] + np.where(inside, x - s0[kk], 0.0),
                whole_i[k] + np.where(inside, integral(x) - integral(s0[kk]), 0.0))

    (ta, ia), (tb, ib) = stood(a), stood(b)
    later = b > a
    gone, gone_int = np.where(later, tb - ta, 0.0), np.where(later, ib - ia, 0.0)
    # a record held throughout ran at the value its span resumed at (at a span to the run's end,
    # the value in force just before it: a held span begins at the sample that set 0 %)
    k1 = np.searchsorted(t, s1, side="left")
    after = np.where(k1 < len(t), v[np.minimum(k1, len(t) - 1)],
                     v[np.maximum(np.searchsorted(t, s0, side="left") - 1, 0)])
    j = np.minimum(np.searchsorted(s1, a, side="right"), len(s0) - 1)
    within = (np.searchsorted(s1, a, side="right") < len(s0)) & (a >= s0[j]) & (b <= s1[j])
    resumed = np.where(within, after[j], at)
    span = b - a - gone
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = (integral(b) - integral(a) - gone_int) / span
    return np.where(span > 1e-9, mean, np.where(gone > 0, resumed, at))


HOLDS_F = 0.8  # a line's logged feed is held against F where the twin runs at F this share of its time
#: a logged/programmed ratio this far from 1, over this many samples, with this little spread,
#: is reported: an unlogged override, or another version of the program
RATIO_OFF = 0.03
RATIO_SAMPLES = 20
RATIO_SPREAD = 0.10


def programmed_lines(program, trace, sig: str) -> dict:
    """Line -> its one programmed value of ``sig`` ("feed": F, only where the twin's run holds it
    for most of the line, HOLDS_F of its time; "spindle_speed": S, where the twin's spindle is
    steady through the line): the lines whose logged samples :func:`logged_against_programmed`
    holds against the program.  Of the program and the twin's run alone, not of a log."""
    rec = program.records
    tl = np.asarray(trace.line)
    if sig == "feed":
        col = "feed"
        kinds = ((rec["kind"] == R.LINEAR) | (rec["kind"] == R.ARC_CW) | (rec["kind"] == R.ARC_CCW)) & \
            ((rec["flags"] & R.FL_SYNC) == 0)
        tf = np.asarray(trace.signal("feed"))
    else:
        col, kinds = "spindle", rec["spindle"] > 0
        try:
            ts = np.abs(np.asarray(trace.signal("spindle_speed")))
        except MtwinError:  # (a trace without the cutting model: no spindle to hold it to)
            ts = None
    by_line: dict = {}
    for ln in np.unique(rec["line"][kinds]):
        vals = np.unique(np.round(rec[col][kinds & (rec["line"] == ln)], 6))
        if len(vals) != 1 or vals[0] <= 0:
            continue  # a line run at several values (a loop, a subprogram): no one programmed value
        prog_v = float(vals[0])
        if sig == "feed" and ((rec["line"] == ln) & ((rec["kind"] == R.RAPID) |
                                                     ((rec["flags"] & R.FL_CANNED) != 0))).any():
            continue  # a canned cycle, or a line that rapids too: the logged feed is not F's
        if sig == "feed":
            reach = tf[tl == ln]
            if not len(reach) or np.mean(reach >= 0.98 * prog_v) < HOLDS_F:
                # the twin does not hold F over most of the line (a short block, a plunge that
                # accelerates and stops again): a log's samples there fall on the ramps
                continue
        elif ts is not None:
            held = ts[tl == ln]
            if not len(held) or held.min() < 0.98 * held.max():
                continue  # the spindle runs up (or brakes) in this line: no steady speed to hold
        by_line[int(ln)] = prog_v
    return by_line


STRAIGHT = ("line", "feed")  # the block kinds of straight feed moves (without and with blocks.KINDS)
STRAIGHT_SPREAD = 0.25


def _spread(r: np.ndarray) -> float:
    """The interquartile range of ratios over their median."""
    med = float(np.median(r))
    q1, q3 = np.percentile(r, [25, 75])
    return float((q3 - q1) / med) if med > 0 else math.inf


def _off(ratio: float, samples: int, spread: float, most: float = RATIO_SPREAD) -> bool:
    """A ratio far enough from 1, over enough samples, held tightly enough to report."""
    return abs(ratio - 1.0) > RATIO_OFF and samples >= RATIO_SAMPLES and spread < most


def logged_against_programmed(program, meas, trace, kind_of: dict | None = None, lines: dict | None = None) -> dict:
    """The log's own feed (and spindle speed) against the program's: per sample in a feed move
    whose programmed F the twin holds for most of that block, the logged path feed over F; for the
    spindle, the logged speed over S.  Returns {signal: {ratio, samples, blocks, spread,
    by_kind, suspect}} for the signals the log has (``program``: as run, its logged overrides
    applied — a logged override leaves a ratio of 1).  ``kind_of``: line -> block kind
    (``blocks.KINDS``) to give ``by_kind`` per block kind instead of straight moves and arcs;
    ``lines``: signal -> :func:`programmed_lines`, where already known (several logs of one run)."""
    out: dict = {}
    if meas.line is None or meas.t is None:
        return out
    rec = program.records
    line = np.asarray(meas.line)
    for sig in ("feed", "spindle_speed"):
        if sig not in meas.signals:
            continue
        logged = np.asarray(meas.signals[sig], float)
        by_line = (lines or {}).get(sig)
        if by_line is None:
            by_line = programmed_lines(program, trace, sig)
        ok = np.isin(line, list(by_line)) & np.isfinite(logged) & (logged > 0)
        if sig == "feed":
            # the first sample of a block is taken as it accelerates: steady samples only
            first = np.r_[True, line[1:] != line[:-1]]
            ok &= ~first
        idx = np.flatnonzero(ok)
        if len(idx) < 3:
            continue
        r = logged[idx] / np.array([by_line[int(x)] for x in line[idx]])
        med, spread = float(np.median(r)), _spread(r)
        kinds_here = kind_of or {int(ln): ("arc" if (rec["kind"][rec["line"] == ln] != R.LINEAR).any() else "line")
                                 for ln in by_line}
        by_kind = {}
        for k in dict.fromkeys(kinds_here.get(int(x), "other") for x in line[idx]):
            m = np.array([kinds_here.get(int(x), "other") == k for x in line[idx]])
            if m.sum() >= 3:
                by_kind[k] = {"ratio": float(np.median(r[m])), "samples": int(m.sum()), "spread": _spread(r[m])}
        suspect = _off(med, len(idx), spread)
        # the straight moves alone (blocks.KINDS' "feed": lines, and arcs of 2 mm or more, that
        # reach F): where the machine's path limits and the twin's differ least (an arc limit the
        # twin does not have spreads the pooled ratio, and hides an override).  Their spread, where
        # the twin's ramps and the machine's differ in length, may pass the pooled bound: the
        # ratio is told where 1 lies well outside its samples' middle half
        on = next((k for k in STRAIGHT if k in by_kind and _off(by_kind[k]["ratio"], by_kind[k]["samples"],
                                                                by_kind[k]["spread"], STRAIGHT_SPREAD)
                   and abs(by_kind[k]["ratio"] - 1.0) > by_kind[k]["spread"]), "")
        out[sig] = {"ratio": med, "samples": int(len(idx)), "blocks": int(len(np.unique(line[idx]))),
                    "spread": spread, "by_kind": by_kind, "suspect": bool(suspect or on),
                    "suspect_kind": "" if suspect else on}
    return out


def twin_log(trace, meas, seed: int = 0):
    """A log of the twin's own run as the real one samples it: the executing line and the path
    feed every interval of ``meas`` (its median, each within ±20 %, as the Hurco's 0.15–0.2 s).
    The same estimator on it (:func:`logged_against_programmed`) shows what the sampling alone
    makes of a block kind's ratio: samples in a short block fall on its acceleration and
    deceleration, so even a twin that runs at F logs plunges below it."""
    from .measurement import Measurement

    t, line = np.asarray(trace.t), np.asarray(trace.line)
    mt = np.asarray(meas.t, float)
    every = float(np.median(np.diff(mt))) if len(mt) > 1 else 0.0
    if every <= 0 or len(t) < 2:
        return None
    rng = np.random.default_rng(seed)
    ts = t[0] + np.cumsum(rng.uniform(0.8 * every, 1.2 * every, int((t[-1] - t[0]) / (0.8 * every)) + 2))
    ts = ts[ts < t[-1]]
    k = np.clip(np.searchsorted(t, ts, side="right") - 1, 0, len(t) - 1)
    return Measurement("the twin's own run", ts, {"feed": np.asarray(trace.signal("feed"), float)[k]},
                       line[k].astype(np.int64))


TWIN_LOGS = 8  # logs of the twin's own run the figure beside the log's is the mean of


def twin_logged_ratio(program, trace, meas, kind_of: dict | None = None, logs: int = TWIN_LOGS) -> dict | None:
    """The feed ratio of :func:`logged_against_programmed` on ``logs`` logs of the twin's own run
    (:func:`twin_log`, each sampled anew): {ratio, samples, logs, by_kind: {kind: {ratio,
    samples}}}, the ratios the mean over the logs (a kind of few short blocks has few samples
    per log, and one log's median moves with where they fall), or None."""
    runs = []
    lines = {"feed": programmed_lines(program, trace, "feed")}  # (the same for every log of the run)
    for seed in range(logs):
        own = twin_log(trace, meas, seed)
        x = logged_against_programmed(program, own, trace, kind_of, lines).get("feed") if own is not None else None
        if x is not None:
            runs.append(x)
    if not runs:
        return None
    by_kind: dict = {}
    for x in runs:
        for k, v in x["by_kind"].items():
            by_kind.setdefault(k, []).append(v)
    def mean(xs):
        return {"ratio": float(np.mean([x["ratio"] for x in xs])), "samples": int(sum(x["samples"] for x in xs))}

    return {**mean(runs), "logs": len(runs), "by_kind": {k: mean(vs) for k, vs in by_kind.items()}}


CANNED = -1  # line_kinds' kind for a drilling cycle's records


def line_kinds(rec) -> dict:
    """Line -> the set of its records' kinds (``records``' RAPID, LINEAR, …; CANNED for a drilling
    cycle's records)."""
    kinds: dict = {}
    for ln, k, fl in zip(rec["line"], rec["kind"], rec["flags"]):
        kinds.setdefault(int(ln), set()).add(CANNED if fl & R.FL_CANNED else int(k))
    return kinds


def feed_line_ends(program, meas, trace, logs: int = TWIN_LOGS) -> dict:
    """Where a feed line's time differs from the log, by what follows it: {(its record's kind
    "line" | "arc", the next line's "rapid" | "feed"): (lines, mean error s, standard error s)}.

    Each feed line of one record (no drilling cycle) whose next line with a record (comments and
    blank lines skipped) is a move, both reported by the log: the time from the line's first
    report to the next one's, in ``logs`` logs of
    the twin's own run sampled as the real one (:func:`twin_log`; a line counted where at least
    half of them report both, their mean taken) less the measured.  The sampling makes the same
    of both, so a wait at the end of a feed line — before a rapid, say, and not before a feed
    move — shows as the difference between the rows."""
    from .blocks import line_starts

    if meas.line is None or not (np.asarray(meas.line) > 0).any():
        return {}
    kinds = line_kinds(program.records)
    seen = line_starts(np.asarray(meas.t, float), np.asarray(meas.line))
    own = [line_starts(np.asarray(x.t), np.asarray(x.line))
           for x in (twin_log(trace, meas, seed) for seed in range(logs)) if x is not None]
    if not own:
        return {}
    moves = {R.RAPID, R.LINEAR, R.ARC_CW, R.ARC_CCW}
    order = sorted(kinds)
    errors: dict = {}
    for ln, after in zip(order, order[1:]):
        ks, nxt = kinds[ln], kinds[after]
        if (len(ks) != 1 or not ks <= {R.LINEAR, R.ARC_CW, R.ARC_CCW} or not nxt <= moves
                or ln not in seen or after not in seen):
            continue
        sim = [o[after] - o[ln] for o in own if ln in o and after in o]
        if 2 * len(sim) < len(own):
            continue
        key = ("line" if R.LINEAR in ks else "arc", "rapid" if R.RAPID in nxt else "feed")
        errors.setdefault(key, []).append(float(np.mean(sim)) - (seen[after] - seen[ln]))
    return {k: (len(v), float(np.mean(v)), float(np.std(v, ddof=1) / math.sqrt(len(v))) if len(v) > 1 else math.nan)
            for k, v in sorted(errors.items())}


def ratio_note(sig: str, x: dict, advice: bool = True) -> str:
    """The sentence for a person when a logged/programmed ratio is suspect (``advice``: with
    what to run next, for the feed: the effect that fits it)."""
    what = "feed moves ran" if sig == "feed" else "the spindle turned"
    prog = "programmed F" if sig == "feed" else "programmed S"
    names = {"line": "straight moves", "arc": "arcs", "feed": "feed lines and large arcs"}
    kinds = ", ".join(f"{names.get(k, k)} {v['ratio']:.2f}× over {v['samples']}" for k, v in x["by_kind"].items())
    on = x.get("suspect_kind", "")
    if on:  # (the straight moves alone: the pooled ratio is spread by limits the twin and machine set apart)
        v = x["by_kind"][on]
        head = (f"{names.get(on, on) if sig == 'feed' else what} ran at {v['ratio']:.2f}× the {prog} over "
                f"{v['samples']} logged samples (spread {v['spread']:.1%}; all feed moves {x['ratio']:.2f}× with a "
                f"{x['spread']:.0%} spread: {kinds})")
    else:
        head = (f"{what} at {x['ratio']:.2f}× the {prog} over {x['samples']} logged samples in {x['blocks']} blocks "
                f"(spread {x['spread']:.1%}{'; ' + kinds if kinds else ''})")
    return (f"{head}: an unlogged "
            f"{'feed' if sig == 'feed' else 'spindle'} override, or another version of the program"
            + (" — diagnose ranks effects.feed-override, calibrate --fit feed-override fits it"
               if advice and sig == "feed" else ""))
