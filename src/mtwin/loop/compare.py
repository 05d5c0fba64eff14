"""Model against measurement: align a measurement with the twin's simulation, and say how
far apart they are and where.

Alignment maps each measured sample to a time of the simulation:

* ``line``: by the measured ``line`` column.  Both sides are cut into runs of one line (a
  line run several times by a loop or subprogram is several runs); runs are paired in
  order, skipping simulated runs the logger did not see (short lines between two samples),
  and time inside a pair is mapped linearly.  Right even where the twin's timing is off.
* ``position``: each measured sample goes to the nearest point of the simulated path,
  searched forward only (monotonic in path length), preferring, among equally near points,
  the one the elapsed time predicts (a standstill).
* ``xcorr``: one constant time offset, the maximum of the cross-correlation of a signal
  both sides have.

The result is data (:class:`Comparison`); the CLI and reports render it.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import MtwinError
from ..layout import T_FLUTES

ALIGNMENTS = ("line", "position", "xcorr")


@dataclass
class Comparison:
    alignment: str
    time_offset: float  # s, simulated minus measured time, median over the samples
    cycle_time: dict  # measured, simulated, relative_error
    signals: dict  # name -> {rms, nrmse, max_error, bias, correlation, samples}
    worst_regions: list  # [{signal, first_line, last_line, rms, samples}] worst first
    t: np.ndarray = field(repr=False, default=None)  # measured times used
    t_sim: np.ndarray = field(repr=False, default=None)  # the simulated time of each
    measured: dict = field(repr=False, default_factory=dict)  # signal -> measured values
    simulated: dict = field(repr=False, default_factory=dict)  # signal -> simulated values there
    line: np.ndarray = field(repr=False, default=None)  # program line of each sample (simulation's)
    notes: list = field(default_factory=list)
    blocks: object = None  # blocks.BlockTiming: per-block timing against a log of the executing line
    logged_ratio: dict = field(default_factory=dict)  # a log's own feed/speed over the program's (asrun)

    def as_dict(self, text=None) -> dict:
        out = {"alignment": self.alignment, "time_offset": self.time_offset, "cycle_time": self.cycle_time,
               "signals": self.signals, "worst_regions": self.worst_regions, "notes": self.notes,
               "units": "signals in the measurement format's units (docs/measurement-format.md); times in s"}
        if self.blocks is not None:
            out["blocks"] = self.blocks.as_dict(text)
        if self.logged_ratio:
            out["logged_against_programmed"] = self.logged_ratio
        return out


def simulate_measured(twin, program, meas, **kw):
    """The simulation a measurement is held against: one run, or for summary rows of several
    runs the batch (``Twin.simulate_batch``: the tools' wear carried from run to run).  ``kw``
    as for ``Twin.simulate`` (stock, cutting, tooth_resolution)."""
    if meas.batch > 1:
        return twin.simulate_batch(program, meas.batch, **kw)
    return twin.simulate(program, **kw)


def compare(trace, meas, align: str = "auto", xcorr_signal: str | None = None, regions: int = 10,
            program=None) -> Comparison:
    """Compare a full-rate simulated ``trace`` with a time-series measurement ``meas``.  With
    the ``program`` and a measurement of the executing line, also the per-block timing (and
    the measured cycle time without feed holds and program stops)."""
    if meas.is_summary:
        return compare_summary(trace, meas, regions)
    res = _compare_series(trace, meas, align, xcorr_signal, regions)
    if program is not None and meas.line is not None and (meas.line > 0).any():
        from .blocks import measurement_block_timing

        b = measurement_block_timing(program, meas, trace)
        res.blocks = b
        if meas.end_time is not None:
            # the run as the program made it: the operator's holds and stops taken out
            cyc_m = float(meas.end_time) - b.hold_time - b.stop_time
            c = res.cycle_time
            c["measured"] = cyc_m
            c["relative_error"] = (c["simulated"] - cyc_m) / cyc_m if cyc_m > 0 else None
            res.notes.append(f"measured cycle time: the logged run, {float(meas.end_time):.3f} s from its start to "
                             f"its end" + (f", less {b.hold_time:.1f} s of feed hold and {b.stop_time:.1f} s of "
                                           f"program stops" if b.hold_time > 0 or b.stop_time > 0 else ""))
            return res
    if res.alignment == "line":
        res.notes.append("measured cycle time: first to last sample")
    return res


def _compare_series(trace, meas, align, xcorr_signal, regions) -> Comparison:
    common = [s for s in meas.signals if _has(trace, s)]
    if not common:
        ignored = f"; columns not in the measurement format, ignored: {', '.join(meas.ignored)}" if meas.ignored else ""
        raise MtwinError(f"{meas.path}: no signal in common with the simulation "
                         f"(measured: {', '.join(meas.signals) or 'none'}{ignored}; --map SRC=DST names a column)")
    notes = [f"column {c!r} is not in the measurement format: kept, ignored" for c in meas.ignored]
    if align == "auto":
        if meas.line is not None and (meas.line >= 0).any():
            align = "line"
        elif all(a in meas.signals for a in ("x", "y", "z")):
            align = "position"
        else:
            align = "xcorr"
    if align not in ALIGNMENTS:
        raise MtwinError(f"--align must be auto, {', '.join(ALIGNMENTS)}; got {align!r}")
    ts = np.asarray(trace.t, dtype=np.float64)
    tm = meas.t
    if align == "line":
        if meas.line is None:
            raise MtwinError(f"{meas.path}: --align line needs a 'line' column")
        t_sim = line_alignment(ts, np.asarray(trace.line), tm, meas.line)
    elif align == "position":
        if not all(a in meas.signals for a in ("x", "y", "z")):
            raise MtwinError(f"{meas.path}: --align position needs x, y and z columns")
        t_sim = _align_position(ts, trace, tm, np.stack([meas.signals[a] for a in ("x", "y", "z")], axis=1))
    else:
        sig = xcorr_signal or next((s for s in ("spindle_power", "feed", "x", "y", "z") if s in common), common[0])
        if sig not in common:
            raise MtwinError(f"--xcorr-signal {sig}: not in both the measurement and the simulation")
        t_sim = tm + _xcorr_offset(ts, trace.signal(sig), tm, meas.signals[sig])
        notes.append(f"cross-correlation of {sig}")
    inside = (t_sim >= ts[0] - 1e-9) & (t_sim <= ts[-1] + 1e-9)
    if not inside.any():
        raise MtwinError(f"{meas.path}: no measured sample falls inside the simulation after {align} alignment")
    if (~inside).any():
        notes.append(f"{int((~inside).sum())} measured samples fall outside the simulation and are left out")
    tm_i, t_sim_i = tm[inside], t_sim[inside]
    line = _at(ts, np.asarray(trace.line, dtype=np.float64), t_sim_i, step=True).astype(np.int64)
    stats, measured, simulated = {}, {}, {}
    cycles = _tooth_cycles(trace, t_sim_i)
    for s in common:
        mv = meas.signals[s][inside]
        sv = _at(ts, trace.signal(s), t_sim_i)
        measured[s], simulated[s] = mv, sv
        stats[s] = _metrics(mv, sv)
        if s in ("fx", "fy", "fz") and cycles is not None:
            tooth = getattr(trace.engagement, "prof", np.zeros(0)).size > 0
            stats[s].update(_cycle_errors(mv, sv, cycles, tooth))
    cyc_m = float(tm[-1] - tm[0]) if len(tm) > 1 else 0.0
    cyc_s = float(trace.summary.cycle_time)
    cycle = {"measured": cyc_m, "simulated": cyc_s,
             "relative_error": (cyc_s - cyc_m) / cyc_m if cyc_m > 0 else None}
    worst = _worst_regions(measured, simulated, line, regions)
    offset = float(np.median(t_sim_i - tm_i))
    return Comparison(align, offset, cycle, stats, worst, tm_i, t_sim_i, measured, simulated, line, notes)


_STAT = {
    "mean": np.mean, "rms": lambda v: np.sqrt(np.mean(v * v)), "std": np.std, "max": np.max, "min": np.min,
    "p2p": np.ptp,
}


def compare_summary(trace, meas, regions: int = 10) -> Comparison:
    """A summary measurement, row by row: each row's statistic of a signal over its line
    range, against the same statistic of the simulated trace over the samples of those lines."""
    from .measurement import no_unknown_statistics, summary_base

    no_unknown_statistics(meas)
    batch = trace if isinstance(trace, list) else [trace]
    lines = [np.asarray(tr.line) for tr in batch]
    run_of = meas.run_of_rows()
    if meas.batch > len(batch):
        raise MtwinError(f"{meas.path}: rows of run {meas.batch}, and {len(batch)} run(s) simulated")
    columns = sorted({c for _, _, st in meas.rows for c in st})
    notes = []
    measured = {c: [] for c in columns}
    simulated = {c: [] for c in columns}
    where = {c: [] for c in columns}
    for (first, last, stats), run in zip(meas.rows, run_of):
        trace, line = batch[run - 1], lines[run - 1]
        sel = (line >= first) & (line <= last)
        if not sel.any():
            notes.append(f"lines {first}–{last}: the simulation runs none of them; row left out")
            continue
        for c, v in stats.items():
            base = summary_base(c)
            if np.isnan(v) or not _has(trace, base):
                continue
            stat = c[len(base) + 1:]
            measured[c].append(v)
            simulated[c].append(float(_STAT[stat](trace.signal(base)[sel])))
            where[c].append((first, last))
    stats_out, worst = {}, []
    for c in columns:
        if not measured[c]:
            continue
        m, s = np.array(measured[c]), np.array(simulated[c])
        stats_out[c] = _metrics(m, s)
        total = float(np.sum((m - s) ** 2)) or 1.0
        for (first, last), a, b in zip(where[c], m, s):
            # (each row's share of the signal's squared error: they add up to 100 %)
            worst.append({"signal": c, "first_line": first, "last_line": last, "rms": float(abs(a - b)),
                          "samples": 1, "share": float((a - b) ** 2 / total)})
    worst.sort(key=lambda d: -d["share"])
    cycle = {"measured": None, "simulated": float(trace.summary.cycle_time), "relative_error": None}
    return Comparison("line", 0.0, cycle, stats_out, worst[:regions], measured={k: np.array(v) for k, v in measured.items()},
                      simulated={k: np.array(v) for k, v in simulated.items()}, notes=notes + ["summary measurement: "
                      "one statistic per row and line range"])


def _has(trace, s: str) -> bool:
    try:
        trace.columns_of(s)
    except (KeyError, MtwinError):
        return False
    return True


def _at(ts, values, t, step: bool = False):
    """``values`` (sampled at ``ts``) at times ``t``: linear, or the sample at or before."""
    v = np.asarray(values, dtype=np.float64)
    if step:
        idx = np.clip(np.searchsorted(ts, t + 1e-12, side="right") - 1, 0, len(ts) - 1)
        return v[idx]
    return np.interp(t, ts, v)


def _run_bounds(line: np.ndarray):
    """(line, first index, end index) of each run of one line."""
    if not len(line):
        return []
    cut = np.flatnonzero(np.diff(line) != 0) + 1
    starts = np.concatenate(([0], cut))
    ends = np.concatenate((cut, [len(line)]))
    return [(int(line[a]), int(a), int(b)) for a, b in zip(starts, ends)]


def line_alignment(ts, sline, tm, mline) -> np.ndarray:
    """Measured times ``tm`` (lines ``mline``, -1: empty) -> simulated times on a trace (times
    ``ts``, lines ``sline``), run by run of the same line (``_align_line``)."""
    known = mline >= 0
    t_sim = np.full(len(tm), -np.inf)
    t_sim[known] = _align_line(ts, sline, tm[known], mline[known])
    ok = known & np.isfinite(t_sim)
    if (~known).any() and ok.sum() > 1:
        # a sample whose line cell is empty sits between its neighbours in time
        t_sim[~known] = np.interp(tm[~known], tm[ok], t_sim[ok], left=-np.inf, right=-np.inf)
    return t_sim


def _align_line(ts, sline, tm, mline) -> np.ndarray:
    """Measured times -> simulated times, run by run of the same line.

    A measured run's true start lies between its first sample and the sample before it,
    its end between its last sample and the next; the shift (simulated minus measured) at
    each end is chosen inside what those brackets allow, as close as possible to the shift
    so far — so a measurement that agrees with the twin maps to itself exactly, and one
    whose timing differs follows the difference run by run."""
    sim = _run_bounds(sline)
    t_sim = np.full(len(tm), -np.inf)
    nsim = len(ts)
    j = 0
    shift = 0.0
    for ln, a, b in _run_bounds(mline):
        jj = j
        while jj < len(sim) and sim[jj][0] != ln:
            jj += 1
        if jj == len(sim) or ln < 0:  # a line the simulation does not run (here): left out
            continue
        _, sa, sb = sim[jj]
        s0 = ts[sa]
        s1 = ts[sb] if sb < nsim else ts[-1]
        t_prev = tm[a - 1] if a > 0 else -np.inf
        t_next = tm[b] if b < len(tm) else np.inf
        d0 = min(max(shift, s0 - tm[a]), s0 - t_prev)
        d1 = min(max(d0, s1 - t_next), s1 - tm[b - 1])
        seg = slice(a, b)
        if b - 1 > a:
            f = (tm[seg] - tm[a]) / (tm[b - 1] - tm[a])
            t_sim[seg] = tm[seg] + d0 + f * (d1 - d0)
        else:
            t_sim[seg] = tm[seg] + d0
        shift = d1
        j = jj + 1
    return t_sim


def _align_position(ts, trace, tm, pm) -> np.ndarray:
    from . import _alignkernel as AK

    ps = np.ascontiguousarray(np.stack([trace.signal(a) for a in ("x", "y", "z")], axis=1))
    pm = np.ascontiguousarray(pm, dtype=np.float64)
    dt = float(ts[1] - ts[0]) if len(ts) > 1 else 1.0
    idx = np.zeros(len(tm), np.int64)
    AK.nearest_forward(ps, pm, np.ascontiguousarray(tm - tm[0]), dt, idx)
    return ts[idx]


def _xcorr_offset(ts, sv, tm, mv) -> float:
    """Time offset (s, simulated minus measured) maximising the cross-correlation, on a
    common uniform grid at the measurement's median sampling interval."""
    good = ~np.isnan(mv)
    if good.sum() < 3:
        raise MtwinError("--align xcorr: the chosen signal has fewer than 3 measured values (--xcorr-signal names another)")
    steps = np.diff(np.unique(tm))
    dt = float(np.median(steps)) if len(steps) else 0.0
    if not dt > 0:
        raise MtwinError("--align xcorr: the measurement's times do not advance")
    dt = max(dt, float(ts[1] - ts[0]) if len(ts) > 1 else dt)
    grid_s = np.arange(ts[0], ts[-1] + 1e-12, dt)
    a = np.interp(grid_s, ts, np.nan_to_num(np.asarray(sv, dtype=np.float64)))
    grid_m = np.arange(tm[0], tm[-1] + 1e-12, dt)
    b = np.interp(grid_m, tm[good], mv[good])
    a = a - a.mean()
    b = b - b.mean()
    if not a.any() or not b.any():
        return float(ts[0] - tm[0])
    n = len(a) + len(b) - 1
    nfft = 1 << (n - 1).bit_length()
    c = np.fft.irfft(np.fft.rfft(a, nfft) * np.conj(np.fft.rfft(b, nfft)), nfft)
    lags = np.concatenate((np.arange(0, len(a)), np.arange(-(len(b) - 1), 0)))
    vals = np.concatenate((c[:len(a)], c[nfft - (len(b) - 1):]))
    k = int(lags[int(np.argmax(vals))])
    return float(grid_s[0] - grid_m[0] + k * dt)


MIN_CYCLE_SAMPLES = 4  # a tooth cycle with fewer samples has no peak or amplitude worth the name


def _tooth_cycles(trace, t_sim) -> np.ndarray | None:
    """The tooth cycle (0, 1, 2 … counted from the start) each sample falls in, from the
    simulated spindle speed and the tool's flutes (one tool in the program), or None."""
    eng = getattr(trace, "engagement", None)
    if eng is None or trace.cut is None or len(eng.tools) != 1:
        return None
    flutes = float(eng.tools[0, T_FLUTES])
    ts = np.asarray(trace.t, dtype=np.float64)
    n = np.abs(trace.signal("spindle_speed"))
    teeth = np.concatenate(([0.0], np.cumsum(0.5 * (n[1:] + n[:-1]) / 60.0 * flutes * np.diff(ts))))
    return np.floor(np.interp(t_sim, ts, teeth)).astype(np.int64)


def _cycle_errors(mv, sv, cycles, tooth: bool = True) -> dict:
    """Per tooth cycle with enough samples and load: the peak error |Ps − Pm|/Ps and the
    amplitude (peak to peak) error likewise, averaged and at their worst (the impeller
    reference's per-cycle force errors)."""
    ok = ~np.isnan(mv)
    c = cycles[ok]
    m, s = mv[ok], sv[ok]
    if not len(c):
        return {"cycles": 0}
    starts = np.flatnonzero(np.diff(c, prepend=c[0] - 1))
    counts = np.diff(np.append(starts, len(c)))
    keep = counts >= MIN_CYCLE_SAMPLES
    if keep.sum() < 10:
        return {"cycles": int(keep.sum()), "note": "tooth cycles not resolved by the sampling"}
    ps = np.maximum.reduceat(np.abs(s), starts)[keep]
    pm = np.maximum.reduceat(np.abs(m), starts)[keep]
    as_ = (np.maximum.reduceat(s, starts) - np.minimum.reduceat(s, starts))[keep]
    am = (np.maximum.reduceat(m, starts) - np.minimum.reduceat(m, starts))[keep]
    loaded = ps > 1e-6 * max(float(ps.max()), 1e-300)
    pe = np.abs(ps - pm)[loaded] / ps[loaded]
    # an amplitude error needs the simulated swing of the tooth passing: revolution-averaged
    # forces have none (compare --tooth-resolution simulates it)
    swing = loaded & (as_ > 0.01 * ps) & tooth
    ae = np.abs(as_ - am)[swing] / as_[swing]
    return {"cycles": int(loaded.sum()), "peak_error_mean": float(pe.mean()) if len(pe) else None,
            "peak_error_max": float(pe.max()) if len(pe) else None,
            "amplitude_error_mean": float(ae.mean()) if len(ae) else None,
            "amplitude_error_max": float(ae.max()) if len(ae) else None}


def _metrics(mv, sv) -> dict:
    ok = ~np.isnan(mv) & ~np.isnan(sv)
    n = int(ok.sum())
    if n == 0:
        return {"rms": None, "nrmse": None, "max_error": None, "bias": None, "correlation": None, "samples": 0}
    r = mv[ok] - sv[ok]
    rms = float(np.sqrt(np.mean(r * r)))
    span = float(np.ptp(mv[ok]))
    corr = None
    if n > 1 and np.std(mv[ok]) > 0 and np.std(sv[ok]) > 0:
        corr = float(np.corrcoef(mv[ok], sv[ok])[0, 1])
    return {"rms": rms, "nrmse": rms / span if span > 0 else None, "max_error": float(np.max(np.abs(r))),
            "bias": float(np.mean(r)), "correlation": corr, "samples": n}


def _worst_regions(measured, simulated, line, k: int) -> list:
    """Per signal, the program lines whose residual contributes most (sum of squares, as a
    share of the signal's total), consecutive lines merged; the ``k`` worst over all
    signals."""
    out = []
    for s in measured:
        r = measured[s] - simulated[s]
        ok = ~np.isnan(r)
        if not ok.any():
            continue
        total = float(np.sum(r[ok] ** 2))
        if total <= 0:
            continue
        lines, inv = np.unique(line[ok], return_inverse=True)
        sse = np.bincount(inv, weights=r[ok] ** 2)
        cnt = np.bincount(inv)
        order = np.argsort(-sse)[:k]
        top = sorted(int(i) for i in order)
        # merge lines next to each other in the program into one region
        groups = []
        for i in top:
            if groups and lines[i] == lines[groups[-1][-1]] + 1:
                groups[-1].append(i)
            else:
                groups.append([i])
        for g in groups:
            e, c = float(sse[g].sum()), int(cnt[g].sum())
            out.append({"signal": s, "first_line": int(lines[g[0]]), "last_line": int(lines[g[-1]]),
                        "rms": float(np.sqrt(e / c)), "samples": c, "share": e / total})
    out.sort(key=lambda d: -d["share"])
    return out[:k]
