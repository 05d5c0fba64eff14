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

Mapping time to records goes by line: records are taken in program order and matched to the
reported line at or before theirs, which holds for programs that run top to bottom
(subprogram loops and repeats get the override of their line's first run).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import SourceLocation
from ..gcode import records as R
from .blocks import HELD, line_starts
from .measurement import MeasurementError

#: override column -> what it scales
SCALES = {"feed_override": "feed moves' feed", "rapid_override": "rapids' speed", "spindle_override": "spindle speed"}


@dataclass
class AsRun:
    """The program to simulate for a measurement, and what was done to it."""

    program: object  # the program with the overrides applied (the program itself when none)
    measurement: object = None  # the measurement to compare with (cut at the last line reached: --partial)
    applied: dict = field(default_factory=dict)  # override column -> (lowest, highest) % applied
    not_logged: list = field(default_factory=list)  # override columns a control's log did not have
    partial_to: int = 0  # the last line compared (--partial), 0: the whole program

    @property
    def notes(self) -> list:
        out = []
        for k, (lo, hi) in self.applied.items():
            what = f"{lo:g} %" if abs(hi - lo) < 0.05 else f"{lo:g}–{hi:g} %"
            out.append(f"{k.replace('_', ' ')} {what} applied to the {SCALES[k]} of the blocks it was in force for")
        if self.not_logged:
            out.append(f"{', '.join(k.split('_')[0] for k in self.not_logged)} override not logged: 100 % assumed "
                       f"(values calibrated from this run are effective: they include any override the operator set)")
        if self.partial_to:
            out.append(f"--partial: the run stopped at line {self.partial_to}; the program and the log are compared "
                       f"up to the start of that line (cycle times to the moment it was reached)")
        return out

    def as_dict(self) -> dict:
        return {"overrides_applied": {k: list(v) for k, v in self.applied.items()}, "overrides_not_logged":
                self.not_logged, "partial_to_line": self.partial_to or None}


def as_run(program, meas, partial: bool = False) -> AsRun:
    """The program as ``meas`` (a control's log) says it ran; ``partial``: a run the log does
    not finish is compared up to its last line (else it is an error)."""
    if meas.t is None:
        return AsRun(program, meas)
    out = AsRun(program, meas)
    if meas.complete is False:
        last = _last_line(meas)
        if not partial:
            raise MeasurementError(f"the run in the log is incomplete: it stops at line {last} of "
                                   f"{program.path or 'the program'} (a logger that stopped, or the run was aborted) — "
                                   f"compare the part that ran with --partial", SourceLocation(meas.path, 0, 0))
        # both sides up to the moment the last line was reached: how long the control ran it
        # before the log stops is not known
        t_last = line_starts(meas.t, meas.line)[last]
        program = _before(program, last)
        keep = meas.t <= t_last
        meas = replace(meas, t=meas.t[keep], line=np.where(meas.t[keep] < t_last, meas.line[keep], -1),
                       signals={k: v[keep] for k, v in meas.signals.items()},
                       extra={k: v[keep] for k, v in meas.extra.items()}, end_time=float(t_last),
                       source_line=None if meas.source_line is None else meas.source_line[keep])
        out.measurement = meas
        out.partial_to = last
    logged = {k: np.asarray(v, np.float64) for k, v in meas.extra.items() if k in SCALES}
    if meas.meta.get("source", "").startswith("MTConnect") or "overrides" in meas.meta or "block_is" in meas.meta:
        out.not_logged = [k for k in SCALES if k not in logged or np.isnan(logged[k]).all()]
    active = {k: v for k, v in logged.items() if not np.isnan(v).all() and (np.abs(v[~np.isnan(v)] - 100.0) > 1e-9).any()}
    if not active or meas.line is None or not (meas.line > 0).any():
        out.program = program
        return out
    rec = program.records
    t0, t1 = _record_spans(rec["line"], meas)
    new = rec.copy()
    moving = rec["kind"] != R.DWELL
    for k, v in active.items():
        f = np.clip(_time_mean(meas.t, v, t0, t1), HELD, None) / 100.0
        if k == "feed_override":
            m = moving & (rec["kind"] != R.RAPID) & ((rec["flags"] & R.FL_SYNC) == 0)
            new["feed"] = np.where(m, rec["feed"] * f, rec["feed"])
            used = f[m]
        elif k == "spindle_override":
            new["spindle"] = rec["spindle"] * f
            used = f[rec["spindle"] > 0]
        else:
            used = f[rec["kind"] == R.RAPID]
        if len(used):
            out.applied[k] = (round(100.0 * float(used.min()), 1), round(100.0 * float(used.max()), 1))
        if k == "rapid_override":
            program = replace(program, rapid_scale=np.where(rec["kind"] == R.RAPID, f, 1.0))
    out.program = replace(program, records=new)
    return out


def _last_line(meas) -> int:
    ok = meas.line > 0 if meas.line is not None else np.zeros(0, bool)
    return int(meas.line[ok][-1]) if ok.any() else 0


def _before(program, last: int):
    """The program's records before the first record of line ``last`` or after it."""
    rec = program.records
    keep = rec["line"] < last
    if keep.all():
        return program
    k = int(np.argmin(keep))  # the run is cut where the program first reaches that line
    return replace(program, records=rec[:k].copy(), end_tool_change=0)


def _record_spans(lines: np.ndarray, meas):
    """Per record (by its line), the measured (start, end) of the block group it ran in: the
    reported line at or before its own, to the next reported line's first time."""
    starts = line_starts(meas.t, meas.line)
    rep = np.array(sorted(starts), np.int64)
    rt = np.array([starts[int(x)] for x in rep], np.float64)
    if not len(rep):
        t = np.full(len(lines), float(meas.t[0]))
        return t, t
    # times in line order: a reported line's group ends where the next (by line) begins
    end = meas.end_time if meas.end_time is not None else float(meas.t[-1])
    nxt = np.concatenate([rt[1:], [end]])
    k = np.searchsorted(rep, lines, side="right") - 1
    before = k < 0
    k = np.maximum(k, 0)
    t0 = np.where(before, float(meas.t[0]), rt[k])
    t1 = np.where(before, rt[0], np.maximum(nxt[k], rt[k]))
    return t0, t1


def _time_mean(t: np.ndarray, v: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Mean over [a, b) of the step function that holds v[i] from t[i] (NaN: 100 %) — its value
    at a where b <= a; before the first sample, the first value."""
    v = np.where(np.isnan(v), 100.0, v)
    # the integral at the sample times, then linear between them (a step's integral is linear)
    cum = np.concatenate([[0.0], np.cumsum(v[:-1] * np.diff(t))])

    def integral(x):
        i = np.clip(np.searchsorted(t, x, side="right") - 1, 0, len(t) - 1)
        return cum[i] + v[i] * (x - t[i])

    at = v[np.clip(np.searchsorted(t, a, side="right") - 1, 0, len(t) - 1)]
    span = b - a
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = (integral(b) - integral(a)) / span
    return np.where(span > 1e-9, mean, at)
