"""Fitting effects to a measurement, and finding which effect is missing.

Both work on residuals: measured minus simulated, at the simulated times the alignment
gave each measured sample (aligned once, with the twin as it is), per signal divided by
that signal's noise level — estimated from the measurement itself as the scatter of
successive samples (``std(diff(r))/√2``), which a smooth model error does not reach.

* :func:`fit` fits the parameters of some effects (and named base parameters) by bounded
  least squares (scipy's trust-region reflective), from their defaults or given starts;
  an observation effect is re-applied to one stored simulation, an in-loop effect needs a
  re-simulation (the engagement is reused).
* :func:`diagnose` fits each candidate effect alone and ranks them per signal by ΔBIC
  (an extra parameter has to earn its place) and explained variance, with a verdict:
  ``fits`` (the residual is at the noise level already), ``explained`` (a candidate brings
  it there, or most of the way), ``unexplained``.
"""
from __future__ import annotations

import copy
import math
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from ..errors import MtwinError
from ..params import effect_param, is_effect_param
from ..fitting import FIT_FACTOR, STRONG_EVIDENCE, default_scale, delta_bic, solve, verdict
from .compare import _STAT, _has, compare, simulate_measured
from .measurement import no_unknown_statistics, summary_base

MAX_SELECTED = 4  # effects forward selection takes at most, per signal
TRIAL_EVALUATIONS = 24  # the short fit each candidate of a forward-selection step gets


@dataclass
class Target:
    """A measurement aligned to a program on a twin: what fitting needs, computed once."""

    twin: object
    program: object
    meas: object
    t_sim: np.ndarray  # simulated time of each used measured sample
    measured: dict  # signal -> values
    noise: dict  # signal -> noise level (same unit)
    alignment: str
    base: object = None  # the base simulation (full rate)
    stock: tuple | None = None  # the stock box every simulation of the fit uses
    # a summary measurement: per statistic column (``fy_rms``), the line range of each row
    rows: dict | None = None
    # aligned by line: the used samples' measured times and lines, to align each candidate's
    # trace afresh — an effect that changes the settling at exact stops moves the lines by
    # milliseconds, and a signal with sharp steps (torque under feed-forward) is read at the
    # wrong instant if the base simulation's alignment is kept
    line_meas: tuple | None = None

    def simulated(self, trace, signals) -> dict:
        """The model's prediction of each measured value: the simulated signal at each sample's
        aligned time or, for a summary measurement, each row's statistic of the simulated
        signal over the samples of its line range."""
        if self.rows is not None:
            return row_statistics(trace, {s: self.rows[s] for s in signals})
        ts = np.asarray(trace.t, dtype=np.float64)
        t_sim = self.t_sim
        if self.line_meas is not None and trace is not self.base and hasattr(trace, "line"):
            from .compare import line_alignment

            t_sim = line_alignment(ts, np.asarray(trace.line), *self.line_meas)
            # (a sample the candidate's run leaves outside: read at the base alignment's time)
            t_sim = np.where(np.isfinite(t_sim), t_sim, self.t_sim)
        return {s: np.interp(t_sim, ts, trace.signal(s)) for s in signals}


def row_statistics(trace, rows: dict) -> dict:
    """Per statistic column (``fy_rms``: the RMS of ``fy``), each row's statistic of the
    simulated signal over the samples whose line is in the row's range (NaN: none).  The
    samples are sorted by line once, so each row reads only its own samples.  Rows given as
    (first, last, run) with a batch of runs (``twin.RunTraces``) read their own run's trace."""
    if any(len(r) == 3 for r in rows.values()):
        out = {c: np.full(len(r[0]), np.nan) for c, r in rows.items()}
        runs = trace if isinstance(trace, list) else [trace]
        for k, tr in enumerate(runs, start=1):
            part = {c: (r[0][r[2] == k], r[1][r[2] == k]) for c, r in rows.items()}
            got = row_statistics(tr, part)
            for c, r in rows.items():
                out[c][r[2] == k] = got[c]
        return out
    line = np.asarray(trace.line)
    order = np.argsort(line, kind="stable")
    by_line = line[order]
    out = {}
    for column, (first, last) in rows.items():
        base = summary_base(column)
        values = np.asarray(trace.signal(base), dtype=np.float64)[order]
        stat = _STAT[column[len(base) + 1:]]
        a = np.searchsorted(by_line, first, side="left")
        b = np.searchsorted(by_line, last, side="right")
        out[column] = np.array([stat(values[i:j]) if j > i else np.nan for i, j in zip(a, b)])
    return out


def _noise(r: np.ndarray, values: np.ndarray) -> float:
    """A signal's noise level from its residual: the scatter of successive residuals
    (``std(diff(r))/√2``), which a smooth model error does not reach — for a time series its
    samples, for a summary measurement its rows in the file's order."""
    d = np.diff(r[~np.isnan(r)])
    sigma = float(np.std(d) / math.sqrt(2.0)) if len(d) > 2 else 0.0
    span = float(np.nanmax(np.abs(values))) if len(values) else 0.0
    return max(sigma, 1e-9 * max(span, 1.0))


def target(twin, program, meas, align: str = "auto", signals=None, stock=None) -> Target:
    """Align ``meas`` with the twin's simulation of ``program`` and estimate each signal's
    noise; ``signals`` limits the signals used (default: every one in both)."""
    # the cut loads the drives too: simulate it whenever the program cuts, whatever is measured
    cutting = not program.turning_line()
    base = simulate_measured(twin, program, meas, stock=stock, cutting=cutting)
    if meas.is_summary:
        return _summary_target(twin, program, meas, signals, stock, base)
    c = compare(base, meas, align)
    missing = [s for s in (signals or ()) if s not in c.measured]
    if missing:
        raise MtwinError(f"--signals {', '.join(missing)}: not in both the measurement and the simulation "
                         f"(in both: {', '.join(c.measured)})")
    use = [s for s in (signals or c.measured) if s in c.measured]
    measured = {s: c.measured[s] for s in use}
    noise = {s: _noise(c.measured[s] - c.simulated[s], c.measured[s]) for s in use}
    line_meas = None
    if c.alignment == "line" and meas.line is not None and not isinstance(base, list):
        idx = np.searchsorted(meas.t, c.t)
        if len(idx) and idx.max() < len(meas.t) and np.array_equal(meas.t[idx], c.t):
            line_meas = (c.t, meas.line[idx])
    return Target(twin, program, meas, c.t_sim, measured, noise, c.alignment, base, stock, line_meas=line_meas)


def _summary_target(twin, program, meas, signals, stock, base) -> Target:
    """A summary measurement as a target: each row's value of each statistic column against
    the same statistic of the simulation over the row's lines (a row whose lines the
    simulation never runs is left out); the noise per column from the rows, or from the file's
    ``# noise: COLUMN=VALUE; …`` metadata line."""
    no_unknown_statistics(meas)
    available = {c for _, _, st in meas.rows for c in st if _has(base, summary_base(c))}
    missing = [s for s in (signals or ()) if s not in available]
    if missing:
        raise MtwinError(f"--signals {', '.join(missing)}: not a statistic column of the measurement that the "
                         f"twin simulates (there: {', '.join(sorted(available)) or 'none'})")
    use = [s for s in (signals or sorted(available)) if s in available]
    ranges = {c: ([], [], [], []) for c in use}
    for (first, last, stats), run in zip(meas.rows, meas.run_of_rows()):
        for c in use:
            v = stats.get(c, math.nan)
            if not math.isnan(v):
                ranges[c][0].append(first)
                ranges[c][1].append(last)
                ranges[c][2].append(v)
                ranges[c][3].append(run)
    batch = isinstance(base, list)
    rows = {c: (np.array(f, np.int64), np.array(la, np.int64)) + ((np.array(r, np.int64),) if batch else ())
            for c, (f, la, _, r) in ranges.items()}
    sim = row_statistics(base, rows)
    measured, kept = {}, {}
    for c in use:
        ran = ~np.isnan(sim[c])  # rows whose lines the simulation runs
        kept[c] = tuple(a[ran] for a in rows[c])
        measured[c] = np.array(ranges[c][2])[ran]
        sim[c] = sim[c][ran]
    given = _noise_meta(meas)
    noise = {c: given.get(c) or _row_noise(measured[c] - sim[c], sim[c], measured[c]) for c in use}
    return Target(twin, program, meas, np.zeros(0), measured, noise, "line", base, stock, kept)


def _row_noise(r: np.ndarray, sim: np.ndarray, values: np.ndarray) -> float:
    """A statistic column's noise level from its rows: the scatter of the residual about a
    smooth model of it — a level, a drift along the rows, a share of the simulated value and a
    share growing along the rows (what a missing level change, drift or wear leaves) — by
    least squares; the successive-difference estimate where there are too few rows.  (Rows
    are different cuts: successive residuals differ by the model's error too, and their
    scatter alone overstates the noise.)"""
    ok = ~np.isnan(r) & ~np.isnan(sim)
    n = int(ok.sum())
    if n < 12:
        return _noise(r, values)
    k = np.linspace(0.0, 1.0, len(r))[ok]
    s = sim[ok] / max(float(np.max(np.abs(sim[ok]))), 1e-300)
    X = np.stack([np.ones(n), k, s, s * k], axis=1)
    coef, *_ = np.linalg.lstsq(X, r[ok], rcond=None)
    rss = float(np.sum((r[ok] - X @ coef) ** 2))
    span = float(np.nanmax(np.abs(values))) if len(values) else 0.0
    return max(math.sqrt(rss / (n - X.shape[1])), 1e-9 * max(span, 1.0))


def _noise_meta(meas) -> dict:
    """``# noise: fy_rms=3.1; fz_rms=1.2`` (the statistic columns' noise, in their units)."""
    out = {}
    for part in (meas.meta or {}).get("noise", "").replace(",", ";").split(";"):
        name, eq, value = part.partition("=")
        try:
            if eq and float(value) > 0:
                out[name.strip()] = float(value)
        except ValueError:
            continue
    return out



def _trace_with(tg: Target, twin, effects) -> object:
    """The simulation with ``effects`` added to ``twin`` — re-using the base simulation when
    they all act on observation and the twin is the target's."""
    if isinstance(tg.base, list):  # a batch of runs on the same tools: the batch again
        return twin.with_effects(*effects).simulate_batch(tg.program, len(tg.base), stock=tg.stock,
                                                          cutting=tg.base.cut is not None)
    if twin is tg.twin and all(e.stage == "observation" for e in effects):
        tr = copy.copy(tg.base)
        for e in effects:
            e.observe(tr, e.resolved())
        return tr
    return twin.with_effects(*effects).simulate(tg.program, stock=tg.stock, cutting=tg.base.cut is not None)


def residuals(tg: Target, trace, signals) -> np.ndarray:
    sim = tg.simulated(trace, signals)
    parts = []
    for s in signals:
        r = (tg.measured[s] - sim[s]) / tg.noise[s]
        parts.append(np.where(np.isnan(r), 0.0, r))
    return np.concatenate(parts) if parts else np.zeros(0)


@dataclass
class FitResult:
    effects: list  # fitted Effect instances
    params: dict  # "effects.NAME.param" or base name -> value
    uncertainty: dict  # same keys -> one standard deviation (from the Jacobian), or None
    rms_before: dict  # signal -> RMS of measured − simulated
    rms_after: dict
    noise: dict
    evaluations: int
    signals: list = field(default_factory=list)
    # the fitted model on the target's time base, per signal: the simulated values and their
    # derivatives by each parameter (d simulated / d params[key], columns in params' order),
    # from the solver's last Jacobian — what forward selection's linearised joint fits use
    simulated: dict = field(default_factory=dict, repr=False)
    jacobian: dict = field(default_factory=dict, repr=False)
    bounds: tuple = ((), ())
    # parameters the fitted signals cannot see: left at their starting values, no uncertainty
    not_identifiable: list = field(default_factory=list)

    def as_dict(self) -> dict:
        return {"params": self.params, "uncertainty": self.uncertainty, "rms_before": self.rms_before,
                "rms_after": self.rms_after, "noise": self.noise, "evaluations": self.evaluations,
                "not_identifiable": self.not_identifiable,
                "effects": [{"name": e.name, "params": e.resolved()} for e in self.effects]}


def fit(tg: Target, effects, signals=None, base_params=(), starts: dict | None = None,
        max_evaluations: int = 80) -> FitResult:
    """Fit every parameter of ``effects`` (Effect instances: their values are the starts)
    and the named ``base_params`` of the twin to the target's signals."""
    signals = [s for s in (signals or tg.measured) if s in tg.measured]
    keys, lo, hi, x0, scale = free_parameters(tg.twin, effects, base_params, starts)

    def fun(x):
        twin, fitted = build_fitted(tg.twin, effects, keys, x)
        return residuals(tg, _trace_with(tg, twin, fitted), signals)

    sol = solve(fun, x0, lo, hi, scale, max_evaluations=max_evaluations)
    xfit = sol.x  # (what the signals cannot see stays where it started: sol.blind)
    twin, fitted = build_fitted(tg.twin, effects, keys, xfit)
    after_trace = _trace_with(tg, twin, fitted)
    unc = sol.uncertainty
    return FitResult(fitted, dict(zip(keys, map(float, xfit))), dict(zip(keys, unc)),
                     rms_by_signal(tg, tg.base, signals), rms_by_signal(tg, after_trace, signals),
                     dict(tg.noise), sol.evaluations, signals, tg.simulated(after_trace, signals),
                     _signal_jacobians(tg, signals, sol.jac, scale), (lo, hi),
                     [k for k, b in zip(keys, sol.blind) if b])


def _signal_jacobians(tg: Target, signals, jac, scale) -> dict:
    """The solver's Jacobian (of the scaled residuals by the scaled parameters) as, per
    signal, d simulated / d parameter: residual = (measured − simulated) / noise and
    x = x0 + (u − 1)·scale."""
    out, row = {}, 0
    for s in signals:
        m = len(tg.measured[s])
        out[s] = -jac[row:row + m] * tg.noise[s] / scale
        row += m
    return out


def free_parameters(twin, effects, base_params=(), starts: dict | None = None):
    """(keys, lower, upper, start, scale) of the parameters a fit moves: every parameter of
    ``effects`` ("effects.NAME.param", starting from the effect's value or ``starts``) and the
    named base parameters of ``twin`` (from the twin's value)."""
    free = []  # (key, lower, upper, start)
    for e in effects:
        p = e.resolved()
        moved = e.fit_names()
        for d in e.params:
            if d.name not in moved:
                continue
            start = (starts or {}).get(effect_param(e.name, d.name), p[d.name])
            free.append((effect_param(e.name, d.name), d.lower, d.upper, float(start)))
    for name in base_params:
        v = _base_value(twin, name)
        free.append((name, 0.0 if v >= 0 else -math.inf, math.inf, v))
    if not free:
        raise MtwinError("nothing to fit: give effects with parameters or --param names")
    keys = [f[0] for f in free]
    lo = np.array([f[1] for f in free])
    hi = np.array([f[2] for f in free])
    x0 = np.clip(np.array([f[3] for f in free]), lo, hi)
    scale = np.array([default_scale(lo_, hi_, x) for lo_, hi_, x in zip(lo, hi, x0)])
    return keys, lo, hi, x0, scale


def build_fitted(twin, effects, keys, x):
    """(twin with the base values of ``x``, ``effects`` re-made with theirs)."""
    values = dict(zip(keys, x))
    fitted = [e.with_values(**{d.name: values[effect_param(e.name, d.name)] for d in e.params
                               if effect_param(e.name, d.name) in values}) for e in effects]
    base = {k: v for k, v in values.items() if not is_effect_param(k)}
    return (twin.with_params(base) if base else twin), fitted


def rms_by_signal(tg, trace, signals) -> dict:
    sim = tg.simulated(trace, signals)
    return {s: _rms(tg.measured[s], sim[s], ~np.isnan(tg.measured[s] - sim[s])) for s in signals}


def _base_value(twin, name: str) -> float:
    from ..twin.machine import get_param, param_names

    if name.startswith(("cutting.", "tools.")):
        from ..cutting.library import cutting_param

        return cutting_param(twin.cutting, name)
    if name not in param_names(twin.machine):
        raise MtwinError(f"--param {name}: not a parameter of the twin (e.g. axes.x.servo.kpp, cutting.al6061.ktc, "
                         f"tools.1.diameter)")
    return float(get_param(twin.machine, name))


# ------------------------------------------------------------------------------ diagnose

def diagnose(tg: Target, candidates=None) -> dict:
    """Per signal of the target: RMS, noise, verdict and the candidate effects ranked."""
    from ..effects import available

    in_model = {e.name for e in getattr(tg.twin, "effects", ())}
    classes = [c for n, c in available().items() if n not in in_model and (candidates is None or n in candidates)]
    out = {}
    jobs = [(cls, [s for s in tg.measured if _signal_of(s) in cls.signals]) for cls in classes]
    jobs = [(cls, used) for cls, used in jobs if used and cls.params]
    # candidates are independent; the servo loop and the engagement release the GIL, so two
    # fit at once on a 2-core machine
    with ThreadPoolExecutor(max_workers=_workers(len(jobs))) as pool:
        done = list(pool.map(lambda job: _fit_candidate(tg, *job), jobs))
    fits = {cls.name: fr for (cls, _), fr in zip(jobs, done)}
    for s in tg.measured:
        rms0 = rms_by_signal(tg, tg.base, [s])[s]
        n = int(np.sum(~np.isnan(tg.measured[s])))
        rows = []
        for name, fr in fits.items():
            if fr is None or s not in fr.rms_after:
                continue
            rss0 = n * rms0 ** 2
            rss1 = n * fr.rms_after[s] ** 2
            k = len(fr.params)
            ev = 1.0 - rss1 / rss0 if rss0 > 0 else 0.0
            dbic = delta_bic(n, rss1, rss0, k)
            p = {key.rsplit(".", 1)[-1]: round(v, 6) for key, v in fr.params.items()}
            rows.append({"effect": name, "explained_variance": ev, "delta_bic": dbic, "params": p,
                         "rms_after": fr.rms_after[s],
                         "evidence": (f"{s} residual RMS {rms0:.4g} → {fr.rms_after[s]:.4g} with {name} "
                                      f"({', '.join(f'{k_}={v:.4g}' for k_, v in p.items())}): "
                                      f"{max(ev, 0.0):.0%} of it explained, ΔBIC {dbic:+.1f}")
                                      + (_wear_evidence(tg, s, name, fr) if ev > 0.5 else "")})
        rows.sort(key=lambda r: r["delta_bic"])
        noise = tg.noise[s]
        said = verdict(rms0, noise, rows[0]["delta_bic"] if rows else None,
                       rows[0]["explained_variance"] if rows else 0.0)
        selected, rms_joint = ([], rms0) if said == "fits" else _forward(tg, s, rows, fits, rms0, n)
        out[s] = {"rms": rms0, "noise": noise, "verdict": said, "candidates": rows, "selected": selected,
                  "rms_after": rms_joint}
    return out


def _wear_evidence(tg: Target, s: str, name: str, fr) -> str:
    """For a wear effect that explains most of a per-cut residual: how the statistic grows along
    the tool's cuts, and over how many cuts the break-in lasts — until the fitted share's slope
    falls to twice its slope over the last third (in the Archard law the rate is twice the
    steady one where the land's load equals the sharp edge's, VB = b)."""
    if tg.rows is None or "wear" not in name or s not in fr.simulated:
        return ""
    base = tg.simulated(tg.base, [s])[s]
    share = np.asarray(fr.simulated[s], dtype=np.float64) - base
    ok = ~np.isnan(tg.measured[s])
    share = share[ok]
    n = len(share)
    if n < 10 or not np.any(share):
        return ""
    tenth = max(n // 10, 1)
    first, last = float(np.mean(share[:tenth])), float(np.mean(share[-tenth:]))
    text = (f"; {s} per cut grows with the tool's cumulative cut: the wear's share rises from {first:.3g} "
            f"over the first tenth of the {n} cuts to {last:.3g} over the last")
    if effect_param(name, "break_in") in fr.params:
        w = max(n // 20, 2)
        slope = np.convolve(np.diff(share), np.ones(w) / w, mode="valid")
        steady = float(np.mean(slope[-max(len(slope) // 3, 1):]))
        if steady > 0 and slope[0] > 2 * steady:
            k = int(np.argmax(slope <= 2 * steady))
            text += f", break-in (its growth above twice its final rate) over the first {k + w // 2} cuts"
    return text


def _signal_of(name: str) -> str:
    """The signal a measured column is of (``fy_rms``: ``fy``)."""
    return summary_base(name) or name


def _workers(jobs: int) -> int:
    return max(1, min(jobs, os.cpu_count() or 1, 4))


def _forward(tg: Target, s: str, rows: list, fits: dict, rms0: float, n: int):
    """Forward selection on signal ``s`` (stepwise, in the spirit of FROLS): one at a time, the
    candidate that lowers the BIC most when added to those already taken, while it lowers it
    by STRONG_EVIDENCE or more and the residual is above the noise; after each, an earlier one
    the BIC prefers without is dropped again.

    A step screens the candidates without simulating: each one's single fit linearised (its
    simulated change and Jacobian), fitted by bounded linear least squares to the residual of
    the effects already taken.  The best is then added on the twin — the joint model simulated
    once, and refitted there when its residual is above the noise — and kept only if the twin
    bears the evidence out; the next step screens against that residual.  Returns
    ([{effect, params, delta_bic, rms_after}] in the order taken, the joint fit's residual RMS);
    the params are the final joint fit's."""
    measured = tg.measured[s]
    ok = ~np.isnan(measured)
    sim0 = tg.simulated(tg.base, [s])[s]
    lin = _Linearised(np.where(ok, measured - sim0, 0.0), ok, sim0, s, [fits[r["effect"]] for r in rows])
    state = _Joint([], sim0, rms0)
    steps: list = []
    noise = FIT_FACTOR * tg.noise[s]
    while len(steps) < MAX_SELECTED and (not steps or state.rms > noise):
        residual = np.where(ok, measured - state.sim, 0.0)
        trials = [(*lin.solve([c], residual), c) for c in lin.names if c not in state.names]
        if not trials:
            break
        rss_c, values, name = min(trials, key=lambda t: (t[0], t[2]))
        if delta_bic(n, rss_c, n * state.rms ** 2, lin.k[name]) >= STRONG_EVIDENCE:
            break
        joint = lin.on_twin(tg, state.effects + [lin.effect(name, values[name])], noise, ok)
        dbic = delta_bic(n, n * joint.rms ** 2, n * state.rms ** 2, lin.k[name])
        if dbic >= STRONG_EVIDENCE:  # the twin does not bear the screening out
            break
        state = joint
        steps.append({"effect": name, "delta_bic": dbic, "rms_after": joint.rms})
        for old in [st["effect"] for st in steps[:-1]]:  # the backward look
            without = lin.on_twin(tg, [e for e in state.effects if e.name != old], noise, ok)
            if delta_bic(n, n * without.rms ** 2, n * state.rms ** 2, -lin.k[old]) < 0:
                state = without
                steps = [st for st in steps if st["effect"] != old]
    final = {e.name: e.resolved() for e in state.effects}
    for st in steps:
        st["params"] = {k: round(float(v), 6) for k, v in final[st["effect"]].items()}
    if steps:
        steps[-1]["rms_after"] = state.rms
    return steps, state.rms


@dataclass
class _Joint:
    """Effects fitted together on the twin: the signal they simulate and its residual RMS."""

    effects: list
    sim: np.ndarray
    rms: float

    @property
    def names(self) -> list:
        return [e.name for e in self.effects]


class _Linearised:
    """Candidates' single fits on one signal as a linear model around their fitted values:
    simulated ≈ base + Σ (change_c + J_c·δ_c), δ_c the move of candidate c's parameters from
    its fitted ones, within their bounds."""

    def __init__(self, r0, ok, sim0, s: str, fitted):
        self.r0, self.s = r0, s
        self.change, self.jac, self.fit, self.k = {}, {}, {}, {}
        for fr in fitted:
            if fr is None or s not in fr.simulated or s not in fr.jacobian or len(fr.effects) != 1:
                continue
            name = fr.effects[0].name
            change = np.where(ok, fr.simulated[s] - sim0, 0.0)
            if len(fr.params) > 1 and np.linalg.norm(change) < 1e-3 * np.linalg.norm(r0):
                # a single fit that stayed where it started (a shape parameter at zero amplitude
                # has no gradient): its tangent says nothing of the effect's shape
                continue
            self.change[name] = change
            self.jac[name] = np.where(ok[:, None], fr.jacobian[s], 0.0)
            self._secant(name, fr)
            self.fit[name] = fr
            self.k[name] = len(fr.params)
        self.names = list(self.change)

    def _secant(self, name: str, fr) -> None:
        """Where the single fit moved one parameter alone from its default (the effect off
        there, as most are), that parameter's column is the secant from the default to the fit
        instead of the tangent at the fit: exact at both ends, so a joint fit that moves the
        parameter back toward the default (the single fit compensated for another effect) is
        still predicted — and a parameter left against a saturation (a friction taken to zero,
        whose tangent is zero) gets a column at all."""
        e = fr.effects[0]
        x = np.array(list(fr.params.values()), dtype=np.float64)
        defaults = {d.name: d.default for d in e.params}
        default = np.array([defaults[k.rsplit(".", 1)[-1]] for k in fr.params], dtype=np.float64)
        moved = np.flatnonzero(np.abs(x - default) > 1e-9 * np.maximum(1.0, np.abs(default)))
        if len(moved) == 1:
            j = int(moved[0])
            self.jac[name][:, j] = self.change[name] / (x[j] - default[j])

    def solve(self, names, residual=None) -> tuple[float, dict]:
        """(residual sum of squares, {name: parameter values}) of ``names`` fitted together to
        ``residual`` (default: the base simulation's) on the linear model."""
        from scipy.optimize import lsq_linear

        target = (self.r0 if residual is None else residual) - sum((self.change[c] for c in names),
                                                                   np.zeros_like(self.r0))
        cols, lo, hi, where = [], [], [], []
        for c in names:
            fr = self.fit[c]
            x = np.array(list(fr.params.values()))
            blo, bhi = fr.bounds
            for j in range(len(x)):
                if np.any(self.jac[c][:, j]) and bhi[j] > blo[j]:
                    cols.append(self.jac[c][:, j])
                    lo.append(blo[j] - x[j])
                    hi.append(bhi[j] - x[j])
                    where.append((c, j))
        delta = np.zeros(len(cols))
        if cols:
            A = np.stack(cols, axis=1)
            norm = np.linalg.norm(A, axis=0)
            sol = lsq_linear(A / norm, target, bounds=(np.minimum(np.array(lo) * norm, -1e-300),
                                                        np.maximum(np.array(hi) * norm, 1e-300)))
            delta = sol.x / norm
            target = target - A @ delta
        values = {c: np.array(list(self.fit[c].params.values()), dtype=np.float64) for c in names}
        for (c, j), d in zip(where, delta):
            values[c][j] += d
        return float(target @ target), values

    def effect(self, name: str, values):
        """Candidate ``name``'s effect at ``values`` (within its bounds)."""
        fr = self.fit[name]
        lo, hi = fr.bounds
        return fr.effects[0].with_values(**{k.rsplit(".", 1)[-1]: float(np.clip(v, a, b))
                                            for k, v, a, b in zip(fr.params, values, lo, hi)})

    def on_twin(self, tg: Target, effects: list, noise: float, ok) -> _Joint:
        """``effects`` simulated together on the twin.  Where there are several and the residual
        is above ``noise``: all of them moved together on the linear model, then, if still above,
        a short fit on the twin from the better values (the best is kept).  One effect alone is
        its single fit already, moved by the linear model."""
        if not effects:
            sim = tg.simulated(tg.base, [self.s])[self.s]
        elif len(effects) == 1 and effects[0].resolved() == self.fit[effects[0].name].effects[0].resolved():
            sim = self.fit[effects[0].name].simulated[self.s]  # the single fit itself
        else:
            sim = tg.simulated(_trace_with(tg, tg.twin, effects), [self.s])[self.s]
        joint = _Joint(effects, sim, _rms(tg.measured[self.s], sim, ok))
        names = [e.name for e in effects]
        if len(effects) > 1 and joint.rms > noise and all(c in self.fit for c in names):
            # all of them moved together on the linear model first (one simulation)
            values = self.solve(names)[1]
            again = [self.effect(c, values[c]) for c in names]
            sim = tg.simulated(_trace_with(tg, tg.twin, again), [self.s])[self.s]
            rms = _rms(tg.measured[self.s], sim, ok)
            if rms < joint.rms:
                joint = _Joint(again, sim, rms)
        if len(effects) > 1 and joint.rms > noise:
            try:
                fr = fit(tg, effects, [self.s], max_evaluations=2 * TRIAL_EVALUATIONS)
            except (MtwinError, ValueError, FloatingPointError):
                return joint
            if fr.rms_after[self.s] < joint.rms:
                return _Joint(list(fr.effects), fr.simulated[self.s], fr.rms_after[self.s])
        return joint


def _rms(measured, sim, ok) -> float:
    r = (measured - sim)[ok]
    return float(np.sqrt(np.mean(r * r))) if len(r) else 0.0


def _fit_candidate(tg: Target, cls, signals):
    """One candidate fitted alone from a few starts (the best kept); None if it fails."""
    best = None
    for start in _starts(cls):
        try:
            fr = fit(tg, [cls(**start)], signals)
        except (MtwinError, ValueError, FloatingPointError):
            continue
        cost = sum(fr.rms_after[s] ** 2 / tg.noise[s] ** 2 for s in signals)
        if best is None or cost < best[0]:
            best = (cost, fr)
    return best[1] if best else None


def _starts(cls):
    """Starting points: the defaults; for an effect on observation (cheap to evaluate) also a
    few spread over the range of each parameter whose default is not zero (a phase, a time
    constant, a period: where least squares alone finds the nearest local minimum)."""
    starts = [{}]
    if cls.stage != "observation":
        return starts
    # the amplitudes (zero by default) start away from zero there, or the gradient along a
    # period or a phase would vanish
    lift = {d.name: 0.1 * d.upper for d in cls.params if d.default == 0 and d.upper > 0}
    for d in cls.params:
        if d.default == 0 or not (np.isfinite(d.lower) and np.isfinite(d.upper)):
            continue
        if d.lower > 0:
            grid = np.geomspace(d.lower, d.upper, 14)[1:-1]
        else:
            grid = np.linspace(d.lower, d.upper, 14)[1:-1]
        starts += [{**lift, d.name: float(v)} for v in grid]
    return starts
