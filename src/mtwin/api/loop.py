"""The model-against-measurement loop as use cases: ``synthesize`` a recording, ``compare``
the twin with one, ``diagnose`` which effect is missing, ``calibrate`` it (the twin file
written back with a journal entry)."""
from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Optional

import numpy as np

from ..version import __version__
from ..effects import Effect, parse_effect_spec
from ..errors import MtwinError, warning_text
from ..params import is_effect_param
from ..io import write_bytes
from ..loop.asrun import as_run
from ..loop.compare import compare as run_compare
from ..loop.compare import simulate_measured
from ..loop.fit import diagnose as run_diagnose
from ..loop.fit import fit as run_fit
from ..loop.fit import rms_by_signal, target
from ..loop.journal import calibrated_text, journal_entry, read_journal
from ..loop.measurement import check_against_program, read_measurement
from ..loop.synth import synthesize as sample
from ..loop.synth import synthesize_summary
from ..loop.timing import diagnose_timing, fit_timing, summary, timing_case
from ..motion.trace import write_columns
from ..twin.setup import Messages, load_part, open_twin


@dataclass(frozen=True)
class Reading:
    """How a measurement is read and set against its program: columns read as signals
    (``maps``: ``"SRC=DST[*SCALE]"``), MTConnect items read past, whether a log of another
    program name is accepted (a renamed file), and whether a run that did not finish is
    compared up to where it got (``partial``)."""

    maps: tuple = ()
    ignore_items: tuple = ()
    any_program: bool = False
    partial: bool = False
    run: Optional[int] = None  # which program run of an MTConnect log (1, 2, …; None: the last complete one)


AGREES = 0.02  # a cycle this close to the twin's: the log's times show no override
TOLD = 5  # notes of one kind told one by one, the rest counted (single-block mode stops at every line)
STOOD = 30.0  # s a block group outlasts the twin's by, with nothing logged, that is told as a standstill


def measured_program(program, measurement, reading: Reading, messages: Messages):
    """(the program as the measurement says it ran — a control's logged overrides applied, cut
    at the last line reached with ``partial`` — and the measurement as read)."""
    meas = read_measurement(measurement, reading.maps, reading.ignore_items, reading.run, program)
    for key in ("cut_last", "reordered"):
        if meas.meta.get(key) and meas.meta.get("source", "").startswith("MTConnect"):
            messages.note(f"{measurement}: {meas.meta[key]}")
    if meas.runs and len(meas.runs) > 1:  # (a log of several runs: which one this is, and the others)
        for k, r in enumerate(meas.runs, 1):
            chosen = str(k) == meas.meta.get("run")
            messages.note(f"{measurement}: run {k}: {r.describe()}"
                          + (" — the run chosen" if chosen else ""))
    if meas.meta.get("data_gaps_s"):
        messages.note(f"{measurement}: no data {meas.meta['data_gaps_s']} s (the control UNAVAILABLE: an adapter's "
                      f"reconnect; the run went on, and the lines it ran meanwhile are timed as one group)")
    if meas.meta.get("restarts"):
        messages.note(f"{measurement}: restarted in the middle: {meas.meta['restarts']} (its first pass through the "
                      f"lines it ran again is taken out)")
    check_against_program(meas, program, reading.any_program)
    run = as_run(program, meas, reading.partial)
    for n in run.notes:
        messages.note(f"{measurement}: {n}")
    return run.program, run.measurement


def _inputs(twin, program, measurement, reading, msgs):
    tw = open_twin(twin)
    prog, meas = measured_program(load_part(tw, program, msgs), measurement, reading or Reading(), msgs)
    return tw, prog, meas


def _plan_warnings(tw, prog, msgs) -> None:
    """What the machine's plan says of the program (speeds clamped to the spindle's, a move
    beyond the default machine's travel), told as simulate tells it: a fit to a run the twin
    cannot reproduce is no surprise then."""
    for w in tw.plan(prog).warnings:
        msgs.warn(w)


# ------------------------------------------------------------------------------ synthesize

@dataclass
class Synthetic:
    """A synthetic measurement: columns (name -> array) and the metadata lines of its file."""

    program: object
    columns: dict
    meta: dict
    messages: list = field(default_factory=list, repr=False)

    def write(self, path: str) -> None:
        """Write it in the measurement format (.csv, .parquet, or '-')."""
        write_columns(path, self.columns, self.meta)

    def as_dict(self) -> dict:
        return {"program": self.program.path, "rows": len(next(iter(self.columns.values()))),
                "columns": list(self.columns), "meta": self.meta}


def synthesize(twin=None, program=None, *, rate: float = 100.0, noise: float = 0.0, seed: int = 0,
               signals=None, line: bool = True, stock=None, summary: Optional[str] = None,
               on_message=None) -> Synthetic:
    """What a machine would record running ``program`` on ``twin`` (with the effects to hide
    in it: ``twin.with_effects(…)``): the signals sampled at ``rate`` Hz, with Gaussian noise
    of ``noise`` × each signal's RMS (``seed``); ``line=False`` leaves out the line column.
    ``summary="line"``: a summary measurement instead — per line the tool cuts on, the mean,
    RMS and maximum of each signal (``fy_rms`` …), noise on each column."""
    msgs = Messages(on_message)
    tw = open_twin(twin)
    prog = load_part(tw, program, msgs)
    if summary not in (None, "line"):
        raise MtwinError(f"--summary {summary}: expected line (one row per line the tool cuts on)")
    if summary:
        cols = synthesize_summary(tw, prog, signals=signals, noise=noise, seed=seed, stock=stock)
    else:
        cols = sample(tw, prog, rate=rate, noise=noise, seed=seed, line=line, stock=stock, signals=signals)
    meta = {"source": f"mtwin {__version__} synth", "program": prog.path,
            "effects": "; ".join(f"{e.name}:" + ",".join(f"{k}={v:g}" for k, v in e.resolved().items())
                                 for e in tw.effects) or "none",
            "noise": f"{noise:g} of each {'column' if summary else 'signal'}'s RMS, seed {seed}"}
    meta.update({"summary": "one row per line the tool cuts on"} if summary else {"rate_hz": f"{rate:g}"})
    return Synthetic(prog, cols, meta, msgs.items)


# ------------------------------------------------------------------------------ compare

@dataclass
class Comparison:
    """The twin against a measurement: ``result`` (mtwin.loop.compare.CompareResult), the
    program as it ran, the measurement and the simulation."""

    program: object
    measurement: object
    result: object
    trace: object
    messages: list = field(default_factory=list, repr=False)

    def as_dict(self) -> dict:
        """As ``mtwin compare --json`` prints it."""
        return self.result.as_dict(self.program.text_lines)


def compare(twin=None, program=None, measurement=None, *, align: str = "auto", xcorr_signal: Optional[str] = None,
            tooth_resolution: bool = False, reading: Optional[Reading] = None, stock=None,
            on_message=None) -> Comparison:
    """How far the twin is from a measurement of ``program``, signal by signal, and the lines
    where it is farthest; against a control's log of its executing line, the block timing.

    Parameters
    ----------
    twin : Twin, str or None
    program : Program, str or bytes
    measurement : str
        A measurement file (measurement format, CSV or .parquet) or an MTConnect log.
    align : str
        auto | line | position | xcorr.
    xcorr_signal : str, optional
        The signal ``align="xcorr"`` correlates.
    tooth_resolution : bool
        Simulate tooth-passing forces (for a dynamometer's measurement).
    reading : Reading, optional
        How the measurement is read against the program.
    stock : tuple, optional
        The stock box, mm.

    Returns
    -------
    Comparison
    """
    msgs = Messages(on_message)
    tw, prog, meas = _inputs(twin, program, measurement, reading, msgs)
    # the cut loads the drives too: simulate it whenever the program cuts, whatever is measured
    trace = simulate_measured(tw, prog, meas, stock=stock, cutting=not prog.turning_line(),
                              tooth_resolution=tooth_resolution)
    for w in trace.summary.warnings:  # (what simulate says of the program on this machine: clamped speeds …)
        msgs.warn(w)
    res = run_compare(trace, meas, align, xcorr_signal, program=prog)
    for n in res.notes:
        msgs.note(n)
    from ..loop.asrun import logged_against_programmed, ratio_note, twin_logged_ratio

    kind_of = None
    if res.blocks is not None:  # (the ratios per block kind, for the block timing's table)
        b = res.blocks
        kind_of = {ln: k for a, z, k in zip(b.first_line, b.last_line, b.kind) for ln in range(int(a), int(z) + 1)}
    res.logged_ratio = {} if meas.is_summary else logged_against_programmed(prog, meas, trace, kind_of)
    if "feed" in res.logged_ratio:
        # the same estimator on logs of the twin's own run: what sampling alone makes of a kind's ratio
        x = twin_logged_ratio(prog, trace, meas, kind_of)
        if x is not None:
            res.logged_ratio["feed"]["twin"] = x
    if res.blocks is not None and "feed" in res.logged_ratio:
        res.blocks.feed_ratio = {k: v["ratio"] for k, v in res.logged_ratio["feed"]["by_kind"].items()}
        res.blocks.feed_ratio_twin = {k: v["ratio"] for k, v in
                                      res.logged_ratio["feed"].get("twin", {}).get("by_kind", {}).items()}
    rel = (res.cycle_time or {}).get("relative_error")
    for sig, x in res.logged_ratio.items():
        if not x["suspect"]:
            continue
        if sig == "feed" and rel is not None and abs(rel) < AGREES and abs(x["ratio"] - 1.0) > 3 * AGREES:
            # an override would change the times, and they agree: the logged values are off
            msgs.note(f"the log's feed is {x['ratio']:.2f}× the programmed F over {x['samples']} logged samples, yet "
                      f"its times agree with the twin's (cycle {rel:+.2%}): the logged feed's unit or scale is off, "
                      f"not the machine's speed — no override to fit")
            continue
        msgs.note(ratio_note(sig, x))
    blocks = res.blocks
    if blocks is not None:
        if blocks.hold_time > 0:
            msgs.note(f"{blocks.hold_time:.1f} s of feed hold taken out of the measured times")
        for x in blocks.stops[:TOLD]:
            if x.get("state") == "RESTART":
                msgs.note(f"{x['t0']:.1f}–{x['t1']:.1f} s ({x['wait']:.1f} s): a restart's first pass through the "
                          f"lines it ran again, and the stop before it, taken out of the block timing and the cycle "
                          f"time: no time is counted twice")
                continue
            where = (f"line {x['line']} ({x['state']})" if "line" in x else
                     f"{x['t0']:.1f}–{x['t1']:.1f} s (logged {x['state']})")
            msgs.note(f"program stop at {where}: waited {x['wait']:.1f} s — the operator's time, taken out of the "
                      f"block timing and the cycle time")
        if len(blocks.stops) > TOLD:
            rest = blocks.stops[TOLD:]
            msgs.note(f"{len(rest)} more program stops ({sum(x['wait'] for x in rest):.1f} s in all; single block?), "
                      f"taken out alike")
        for x in blocks.excluded[:TOLD]:
            lines = (f"line {x['first_line']}" if x["first_line"] == x["last_line"] else
                     f"lines {x['first_line']}–{x['last_line']}")
            msgs.note(f"{lines}, at {x['t0']:.1f}–{x['t1']:.1f} s, left out of the block timing: {x['reason']}")
        if len(blocks.excluded) > TOLD:
            msgs.note(f"{len(blocks.excluded) - TOLD} more block groups left out for the same reason")
        # a group far longer than the twin's, with nothing logged to say why: the machine stood
        # (a hold or stop the control did not log) — no model error, and said so
        long = np.flatnonzero(blocks.measured - blocks.simulated > STOOD)
        for i in long[:TOLD]:
            a, z = int(blocks.first_line[i]), int(blocks.last_line[i])
            msgs.warn(warning_text(str(measurement), 0,
                                   f"{f'lines {a}–{z}' if z > a else f'line {a}'} took {blocks.measured[i]:.1f} s on "
                                   f"the log where the twin takes {blocks.simulated[i]:.1f} s, with no hold or stop "
                                   f"logged: the machine stood (an unlogged feed hold or stop?) — that time is in the "
                                   f"measured cycle"))
        if len(long) > TOLD:
            msgs.warn(warning_text(str(measurement), 0, f"{len(long) - TOLD} more block groups took over {STOOD:.0f} s "
                                   f"longer on the log than in the twin with no hold or stop logged"))
    return Comparison(prog, meas, res, trace, msgs.items)


# ------------------------------------------------------------------------------ diagnose

OBJECTIVES = ("auto", "signals", "timing", "chatter")


def objective_for(objective: str, meas, effects=None) -> str:
    """``signals``, ``timing`` or ``chatter``: ``auto`` is chatter for a vibration recording
    alone (vib_x/vib_y), timing for a control's log of its executing line (line, feed and
    spindle speed only) and timing effects, else signals."""
    if objective not in OBJECTIVES:
        raise MtwinError(f"--objective {objective}: expected auto, signals, timing or chatter")
    if objective != "auto":
        return objective
    if meas.t is not None and meas.signals and set(meas.signals) <= {"vib_x", "vib_y", "spindle_speed"} \
            and ("vib_x" in meas.signals or "vib_y" in meas.signals):
        return "chatter"  # a vibration recording alone: did the cuts chatter?
    log = (meas.t is not None and meas.line is not None and (meas.line > 0).any()
           and set(meas.signals) <= {"feed", "spindle_speed"})
    return "timing" if log and all(e.stage == "plan" for e in effects or ()) else "signals"


def _case_notes(case, msgs: Messages) -> None:
    """What a timing fit leaves out of a log: the operator's stops and holds."""
    g = case.groups
    for x in g.stop_groups:
        msgs.note(f"{case.label}: program stop at line {x['line']} ({x['state']}): waited {x['wait']:.1f} s (the "
                  f"operator's time), left out of the fit")
    for x in g.logged_stops[:TOLD]:
        what = ("a restart's first pass through the lines it ran again, and the stop before it" if x["state"] == "RESTART"
                else f"program stop (logged {x['state']})")
        msgs.note(f"{case.label}: {x['t0']:.1f}–{x['t1']:.1f} s, {what}, left out of the fit")
    if len(g.logged_stops) > TOLD:
        msgs.note(f"{case.label}: {len(g.logged_stops) - TOLD} more program stops left out of the fit")
    if g.hold_time > 0:
        msgs.note(f"{case.label}: {g.hold_time:.1f} s of feed hold left out of the fit")


@dataclass
class Diagnosis:
    """Which effect is missing: per signal (``signals``: rms, noise, verdict, candidates ranked,
    selected, rms_after) or, against a control's log, by block timing (``timing``)."""

    objective: str  # signals | timing | chatter
    signals: dict = field(default_factory=dict)
    timing: dict = field(default_factory=dict)
    chatter: dict = field(default_factory=dict)
    alignment: str = ""
    messages: list = field(default_factory=list, repr=False)

    def as_dict(self) -> dict:
        """As ``mtwin diagnose --json`` prints it."""
        if self.objective == "timing":
            return {"objective": "timing", "timing": self.timing}
        if self.objective == "chatter":
            return {"objective": "chatter", "chatter": self.chatter}
        return {"alignment": self.alignment, "signals": self.signals}


def diagnose(twin=None, program=None, measurement=None, *, signals=None, candidates=None, objective: str = "auto",
             align: str = "auto", reading: Optional[Reading] = None, stock=None, on_message=None) -> Diagnosis:
    """For each signal: does the twin fit the measurement, and if not, which effect not yet in
    the twin explains the residual — each candidate fitted alone and ranked by ΔBIC, then the
    forward selection of several together (``selected``).  Against a control's log of its
    executing line: which timing effect explains the block times.

    ``signals``, ``candidates``: lists of names limiting what is used and tried (default: every
    signal in both, every effect not yet in the twin); ``objective``: auto | signals | timing.
    Other parameters as for :func:`compare`."""
    msgs = Messages(on_message)
    if objective in ("auto", "chatter") and _is_spectrum(measurement):
        return _chatter_diagnosis(twin, program, measurement, None, stock, msgs)
    tw, prog, meas = _inputs(twin, program, measurement, reading, msgs)
    if objective_for(objective, meas) == "chatter":
        return _chatter_diagnosis(tw, prog, measurement, meas, stock, msgs)
    if objective_for(objective, meas) == "timing":
        _plan_warnings(tw, prog, msgs)
        case = timing_case(tw, prog, meas, str(measurement))
        _case_notes(case, msgs)
        t = diagnose_timing(tw, [case], list(candidates) if candidates else None)
        for n in t.get("notes", ()):
            msgs.note(n)
        return Diagnosis("timing", timing=t, messages=msgs.items)

    tg = target(tw, prog, meas, align, list(signals) if signals else None, stock)
    d = run_diagnose(tg, list(candidates) if candidates else None)
    return Diagnosis("signals", signals=d, alignment=tg.alignment, messages=msgs.items)


def _is_spectrum(path) -> bool:
    """A spectrum file (chatter.detect): a CSV whose header has freq and amplitude."""
    import stat

    try:
        if not stat.S_ISREG(os.stat(str(path)).st_mode):
            return False  # (the reader says what it is)
        with open(str(path), encoding="utf-8", errors="replace") as fh:
            for ln in fh:
                if ln.strip() and not ln.lstrip().startswith("#"):
                    head = {h.strip().lower() for h in ln.split(",")}
                    return {"freq", "amplitude"} <= head
    except OSError:
        return False
    return False


def _chatter_diagnosis(twin, program, measurement, meas, stock, msgs) -> Diagnosis:
    """Did the cuts chatter (a measured spectrum, or the spectra of a vibration recording per
    line), at what frequency, and does the twin's stability margin agree?"""
    import numpy as np

    from ..chatter.detect import read_spectrum, spectra_of_trace, verdict
    from ..chatter.lobes import dynamics_of
    from .simulate import simulate as run

    tw = open_twin(twin)
    prog = load_part(tw, program, msgs)
    sim = run(tw, prog, stock=stock)
    tr = sim.trace
    rec = prog.records
    cut_lines = sorted(set(int(x) for x in np.asarray(tr.line)[np.asarray(tr.signal("ap")) > 0]))
    if meas is None:
        spectra = read_spectrum(str(measurement))
    else:
        spectra = []
        vib = [s for s in ("vib_x", "vib_y") if s in meas.signals]
        if meas.t is None:
            raise MtwinError(f"{measurement}: a summary measurement holds no spectrum: give a vibration recording "
                             f"(t, line, vib_x/vib_y) or a spectrum file (freq, amplitude)")
        if not vib:
            raise MtwinError(f"{measurement}: no vib_x or vib_y column to take spectra of (map a vibration "
                             f"sensor's column with --map NAME=vib_x)")
        if meas.line is None:
            raise MtwinError(f"{measurement}: a vibration recording needs its line column to tell the cuts apart")
        per = [spectra_of_trace(meas.t, meas.line, meas.signals[s], cut_lines) for s in vib]
        for parts in zip(*per):
            spectra.append(parts[0] if len(parts) == 1 else type(parts[0])(
                parts[0].first_line, parts[0].last_line, parts[0].freq, parts[0].amp + parts[1].amp))
        rate = 1.0 / float(np.median(np.diff(meas.t))) if len(meas.t) > 1 else 0.0
        top = max((m.fn for t in set(int(x) for x in rec["tool"]) if t in tw.cutting.tools
                   for m in tw.cutting.tools[t].modes), default=0.0)
        if top and rate < 2.2 * top:
            msgs.warn(f"{measurement}: sampled at {rate:.0f} Hz, under twice the tool's highest mode ({top:.0f} Hz): "
                      f"a chatter frequency there folds back (aliases) into the band")
    if not spectra:
        raise MtwinError(f"{measurement}: no cutting line has 64 samples or more of vibration: no spectrum to read")
    chatter = (sim.summary.cutting.chatter or {}) if sim.summary.cutting else {}
    margins = {x["line"]: x["margin"] for x in chatter.get("lines", [])}
    line = np.asarray(tr.line)
    speed = np.abs(np.asarray(tr.signal("spindle_speed")))
    cutting = np.asarray(tr.signal("ap")) > 0
    out = []
    for sp in spectra:
        a, b = (sp.first_line, sp.last_line) if sp.first_line else (1, int(line.max(initial=1)))
        m = cutting & (line >= a) & (line <= b)
        if not m.any():
            msgs.warn(f"{measurement}: lines {a}-{b} do not cut in the twin's simulation: no speed to read "
                      f"their spectrum against")
            continue
        n = float(np.median(speed[m]))
        tools = rec["tool"][np.clip(np.asarray(tr.record)[m], 0, None)]
        tn = int(np.bincount(tools.astype(np.int64)).argmax())
        tl = tw.cutting.tool(tn) if (tn in tw.cutting.tools or not tw.cutting.tools) else None
        flutes = tl.flutes if tl is not None else 2
        modes = dynamics_of(tl).modes if tl is not None else ()
        v = verdict(sp, n, flutes, modes)
        v["tool"] = tn
        pred = [margins[ln] for ln in range(a, b + 1) if ln in margins]
        v["twin_margin"] = max(pred) if pred else None
        if v["twin_margin"] is not None:
            says = v["twin_margin"] > 1.0
            v["twin_agrees"] = says == v["chatter"]
        out.append(v)
    return Diagnosis("chatter", chatter={"spectra": out, "chattered": [[v["first_line"], v["last_line"]]
                                                                      for v in out if v["chatter"]]},
                     messages=msgs.items)


# ------------------------------------------------------------------------------ calibrate

@dataclass
class Calibration:
    """A fit of effects (and base parameters) to measurements: ``result`` (FitResult or
    TimingFit: values, uncertainties, RMS before and after), the error on a validation
    measurement, and the twin file's new text (effects, fitted values, the journal entry)."""

    objective: str  # signals | timing
    result: object
    validation: Optional[dict]
    twin_text: str
    inputs: list  # every file read (programs and measurements)
    base_params: tuple = ()
    messages: list = field(default_factory=list, repr=False)

    def as_dict(self) -> dict:
        """As ``mtwin calibrate --json`` prints it (less the file written)."""
        return {**self.result.as_dict(), "validation": self.validation}

    def write(self, path: str, in_place: bool | None = None) -> None:
        """Write the calibrated twin file (atomically)."""
        write_bytes(self.twin_text.encode(), path, self.inputs, in_place)


def calibrate(twin=None, program=None, measurement=None, *, fit=(), params=(), more=(), validate=None,
              refit: bool = False, objective: str = "auto", signals=None, align: str = "auto",
              reading: Optional[Reading] = None, stock=None, on_message=None) -> Calibration:
    """Fit effects to a measurement and give the twin file with them and a journal entry.

    Parameters
    ----------
    fit : list of str or Effect
        Effects to add and fit (``"name:p=v"`` values are starts); an effect the twin already
        has is fitted from its current values.
    params : list of str
        Base parameters fitted too, by dotted name (``axes.x.friction.viscous``).
    more : list of (program, measurement)
        More runs: a timing fit over all of them.
    validate : str, optional
        A second measurement of ``program``: the error on it after the fit.
    refit : bool
        Fit the twin's own effects again too, together with the new ones.
    objective, signals, align, reading, stock
        As for :func:`diagnose`.

    Returns
    -------
    Calibration
    """
    if not fit and not params and not refit:
        raise MtwinError("nothing to fit: give --fit NAME (see mtwin effects), --param NAME or --refit")
    msgs = Messages(on_message)
    reading = reading or Reading()
    tw, prog, meas = _inputs(twin, program, measurement, reading, msgs)
    tw, new = _fit_set(tw, [e if isinstance(e, Effect) else parse_effect_spec(e) for e in fit], refit)
    how = objective_for(objective, meas, new)
    if how == "chatter":
        raise MtwinError(f"{measurement}: a vibration recording tells whether the cuts chattered (mtwin diagnose); "
                         f"a tool's modes are fitted to a tap test's FRF (mtwin calibrate-frf)")
    pairs = [(program, measurement)] + [tuple(p) for p in more]
    sig = list(signals) if signals else None
    if how == "timing":
        _plan_warnings(tw, prog, msgs)
        cases = [timing_case(tw, prog, meas, os.path.basename(str(measurement)))]
        _case_notes(cases[0], msgs)
        more_reading = replace(reading, run=None)  # (--run names a run of the first log)
        for p_i, m_i in pairs[1:]:
            prog_i, meas_i = measured_program(load_part(tw, p_i, msgs), m_i, more_reading, msgs)
            _plan_warnings(tw, prog_i, msgs)
            cases.append(timing_case(tw, prog_i, meas_i, os.path.basename(str(m_i))))
            _case_notes(cases[-1], msgs)
        res = fit_timing(tw, cases, new, tuple(params))
        logs = [c.meas for c in cases]
    else:
        if len(pairs) > 1:
            raise MtwinError("several programs are fitted together only by their block times (--objective timing)")

        res = run_fit(target(tw, prog, meas, align, sig, stock), new, sig, tuple(params))
        logs = [meas]
    fitted = {e.name: e for e in res.effects}
    effects = [fitted.pop(e.name, e) for e in tw.effects] + list(fitted.values())
    base = {k: v for k, v in res.params.items() if not is_effect_param(k)}
    validation = None
    if validate:
        fitted_base = tw.with_params(base) if base else tw
        tw2 = tw.replace(machine=fitted_base.machine, cutting=fitted_base.cutting, effects=effects, share_cache=False)
        validation = _validation(tw2, program, validate, how, replace(reading, run=None), align, sig, stock, msgs)
    path = tw.path
    previous = read_journal(path) if path else []
    source = Path(path).read_text(encoding="utf-8") if path else ""
    label = "; ".join(os.path.basename(str(m)) for _, m in pairs) if len(pairs) > 1 else str(measurement)
    # a control's log that did not log its overrides: the values fitted to it are effective ones
    notes = [f"{os.path.basename(m.path)}: overrides {m.meta['overrides']}; the fitted values are effective (they "
             f"include any override the operator set)" for m in logs if "not logged" in m.meta.get("overrides", "")]
    text = calibrated_text(source, effects, journal_entry(len(previous) + 1, label, res, validation, notes), previous,
                           base, tw)
    inputs = [str(p) for pair in pairs for p in pair if isinstance(p, (str, os.PathLike))]
    _to_ledger(twin, effects, res, str(measurement), msgs)
    return Calibration(how, res, validation, text, inputs, tuple(params), msgs.items)


def _to_ledger(setup, effects, res, measurement: str, msgs) -> None:
    """With a ledger (``--ledger FILE --tool-id T3=ID``): the calibrated flank-wear law becomes
    the mapped tools' law, with the journal entry (the error before and after)."""
    ledger = getattr(setup, "ledger", None)
    if not ledger:
        return
    from ..ledger import Ledger

    from ..effects.wear import law_of

    law = law_of(effects)
    if law is None:
        raise MtwinError("--ledger with calibrate keeps a tool's wear law: fit flank-wear (--fit flank-wear)")
    with Ledger(ledger) as lg:
        for ident in setup.tool_map.values():
            lg.set_law(ident, law, measurement=measurement, rms_before=res.rms_before, rms_after=res.rms_after)
            msgs.note(f"{ledger}: tool {ident}'s wear law is the calibrated one now")


def _fit_set(tw, new: list, refit: bool):
    """(the twin the fit starts from, the effects it fits): an effect the twin already has is
    fitted from its current values (stacking a second copy would write only the increment);
    ``refit``: the twin's own effects are fitted again with the new ones."""
    own = {e.name for e in tw.effects}
    if any(e.name in own for e in new) and not refit:
        keep = [e for e in tw.effects if e.name not in {x.name for x in new}]
        new = [next((e for e in tw.effects if e.name == x.name), x) if not x.values else x for x in new]
        tw = tw.replace(effects=tuple(keep), share_cache=False)
    if refit:
        new = list(tw.effects) + [e for e in new if e.name not in {x.name for x in tw.effects}]
        tw = tw.replace(effects=(), share_cache=False)
    return tw, new


def _validation(tw2, program, validate, how, reading, align, sig, stock, msgs) -> dict:
    """The calibrated twin's error on a second measurement of the program."""
    prog, meas2 = measured_program(load_part(tw2, program, msgs), validate, reading, msgs)
    if how == "timing":
        v = summary(tw2, [timing_case(tw2, prog, meas2, str(validate))])
        return {"measurement": str(validate), "block_time": v["rms"], "cycle_error": v["cases"][0]["cycle_error"]}

    tg2 = target(tw2, prog, meas2, align, sig, stock)
    return {"measurement": str(validate), **rms_by_signal(tg2, tg2.base, list(tg2.measured))}


def import_log(log: str, *, run: Optional[int] = None, block_is: str = "line", program: Optional[str] = None,
               ignore_items=()):
    """``mtwin import mtconnect``: a control's log (SHDR or MTConnectStreams XML) as a measurement
    (:class:`~mtwin.loop.measurement.Measurement`; ``write(path)`` writes it, ``runs`` lists the
    program runs the log holds).  ``program``: the program the log ran, a path (for
    ``block_is="n"``: the N words the log's block numbers count)."""
    from ..io import read_input
    from ..loop.mtconnect import Outline, read_mtconnect

    try:
        data = read_input(program, "program") if program else None
    except OSError as exc:
        raise MtwinError(f"cannot read --program {program}: {exc.strerror or exc}") from None
    # (the program, where given, tells the runs that ran all of it from those that did not; one
    # the twin cannot interpret — a subprogram not at hand — leaves the log read on its own terms)
    outline = None
    if data:
        try:
            outline = Outline.of(load_part(None, program if program != "-" else data, need_motion=False))
        except MtwinError:
            outline = None
    return read_mtconnect(log, run, block_is, data, tuple(ignore_items or ()), outline)


def param_unit(name: str) -> str:
    """The unit of a fitted parameter by its dotted name (an effect's, ``effects.NAME.PARAM``, or
    the machine's, ``axes.x.max_acceleration``); '' where it has none or the name is not known."""
    from ..effects import get
    from ..errors import ConfigError
    from ..params import is_effect_param, split_effect_param
    from ..twin.machine import param_unit as machine_unit

    try:
        if is_effect_param(name):
            effect, param = split_effect_param(name)
            return next((d.unit for d in get(effect).params if d.name == param), "")
        return machine_unit(name)
    except (ConfigError, KeyError, ValueError):
        return ""


def journal(twin_file: str) -> list:
    """``mtwin journal``: each calibration a twin file records (effects fitted, values, the RMS
    error before and after), oldest first; empty when it has none."""
    return read_journal(twin_file)
