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
from .compare import compare

_FIT_FACTOR = 1.5  # a residual within this many noise levels fits
# ΔBIC below which the evidence for a model is "very strong" (Kass & Raftery 1995: a BIC
# difference over 10): what makes a candidate "explained" and what forward selection takes
STRONG_EVIDENCE = -10.0
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

    def simulated(self, trace, signals) -> dict:
        ts = np.asarray(trace.t, dtype=np.float64)
        return {s: np.interp(self.t_sim, ts, trace.signal(s)) for s in signals}


def target(twin, program, meas, align: str = "auto", signals=None, stock=None) -> Target:
    """Align ``meas`` with the twin's simulation of ``program`` and estimate each signal's
    noise; ``signals`` limits the signals used (default: every one in both)."""
    if meas.is_summary:
        raise MtwinError(f"{meas.path}: diagnose and calibrate need a time series (a summary measurement is "
                         f"compared row by row with mtwin compare)")
    # the cut loads the drives too: simulate it whenever the program cuts, whatever is measured
    cutting = not (hasattr(program, "turning_line") and program.turning_line())
    base = twin.simulate(program, stock=stock, cutting=cutting)
    c = compare(base, meas, align)
    missing = [s for s in (signals or ()) if s not in c.measured]
    if missing:
        raise MtwinError(f"--signals {', '.join(missing)}: not in both the measurement and the simulation "
                         f"(in both: {', '.join(c.measured)})")
    use = [s for s in (signals or c.measured) if s in c.measured]
    measured = {s: c.measured[s] for s in use}
    noise = {}
    for s in use:
        r = c.measured[s] - c.simulated[s]
        d = np.diff(r[~np.isnan(r)])
        sigma = float(np.std(d) / math.sqrt(2.0)) if len(d) > 2 else 0.0
        span = float(np.nanmax(np.abs(c.measured[s]))) if len(r) else 0.0
        noise[s] = max(sigma, 1e-9 * max(span, 1.0))
    return Target(twin, program, meas, c.t_sim, measured, noise, c.alignment, base, stock)



def _trace_with(tg: Target, twin, effects) -> object:
    """The simulation with ``effects`` added to ``twin`` — re-using the base simulation when
    they all act on observation and the twin is the target's."""
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

    def as_dict(self) -> dict:
        return {"params": self.params, "uncertainty": self.uncertainty, "rms_before": self.rms_before,
                "rms_after": self.rms_after, "noise": self.noise, "evaluations": self.evaluations,
                "effects": [{"name": e.name, "params": e.resolved()} for e in self.effects]}


def fit(tg: Target, effects, signals=None, base_params=(), starts: dict | None = None,
        max_evaluations: int = 80) -> FitResult:
    """Fit every parameter of ``effects`` (Effect instances: their values are the starts)
    and the named ``base_params`` of the twin to the target's signals."""
    from scipy.optimize import least_squares

    signals = [s for s in (signals or tg.measured) if s in tg.measured]
    keys, lo, hi, x0, scale = free_parameters(tg.twin, effects, base_params, starts)
    count = [0]

    def build(x):
        return build_fitted(tg.twin, effects, keys, x)

    # the solver works on u = 1 + (x - x0) / scale, starting at 1: scipy's finite-difference
    # steps are relative to u, so they are then a fixed share of each parameter's range, well
    # above the float32 resolution of the simulated signals (relative to x itself they would
    # vanish at a zero default)
    def to_x(u):
        return np.clip(x0 + (u - 1.0) * scale, lo, hi)

    def fun(u):
        count[0] += 1
        twin, fitted = build(to_x(u))
        return residuals(tg, _trace_with(tg, twin, fitted), signals)

    ulo, uhi = 1.0 + (lo - x0) / scale, 1.0 + (hi - x0) / scale
    res = least_squares(fun, np.ones(len(x0)), bounds=(ulo, uhi), method="trf", max_nfev=max_evaluations,
                        diff_step=1e-3, xtol=1e-8, ftol=1e-10)
    xfit = to_x(res.x)
    twin, fitted = build(xfit)
    after_trace = _trace_with(tg, twin, fitted)
    unc = [None if u is None else u * sc for u, sc in zip(_uncertainty(res, len(signals)), scale)]
    return FitResult(fitted, dict(zip(keys, map(float, xfit))), dict(zip(keys, unc)),
                     _rms_by_signal(tg, tg.base, signals), _rms_by_signal(tg, after_trace, signals),
                     dict(tg.noise), count[0], signals, tg.simulated(after_trace, signals),
                     _signal_jacobians(tg, signals, res.jac, scale), (lo, hi))


def _signal_jacobians(tg: Target, signals, jac, scale) -> dict:
    """The solver's Jacobian (of the scaled residuals by the scaled parameters) as, per
    signal, d simulated / d parameter: residual = (measured − simulated) / noise and
    x = x0 + (u − 1)·scale."""
    jac = np.asarray(jac.toarray() if hasattr(jac, "toarray") else jac, dtype=np.float64)
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
        for d in e.params:
            start = (starts or {}).get(f"effects.{e.name}.{d.name}", p[d.name])
            free.append((f"effects.{e.name}.{d.name}", d.lower, d.upper, float(start)))
    for name in base_params:
        v = _base_value(twin, name)
        free.append((name, 0.0 if v >= 0 else -math.inf, math.inf, v))
    if not free:
        raise MtwinError("nothing to fit: give effects with parameters or --param names")
    keys = [f[0] for f in free]
    lo = np.array([f[1] for f in free])
    hi = np.array([f[2] for f in free])
    x0 = np.clip(np.array([f[3] for f in free]), lo, hi)
    scale = np.array([_scale(lo_, hi_, x) for lo_, hi_, x in zip(lo, hi, x0)])
    return keys, lo, hi, x0, scale


def build_fitted(twin, effects, keys, x):
    """(twin with the base values of ``x``, ``effects`` re-made with theirs)."""
    values = dict(zip(keys, x))
    fitted = [type(e)(**{d.name: values[f"effects.{e.name}.{d.name}"] for d in e.params}) for e in effects]
    base = {k: v for k, v in values.items() if not k.startswith("effects.")}
    return (twin.with_params(base) if base else twin), fitted


def _scale(lo, hi, x):
    if math.isfinite(lo) and math.isfinite(hi) and hi > lo:
        return 0.1 * (hi - lo)
    return max(abs(x), 1.0)


def _uncertainty(res, nsig):
    try:
        J = res.jac
        dof = max(1, len(res.fun) - len(res.x))
        s2 = float(np.sum(res.fun ** 2)) / dof
        cov = np.linalg.pinv(J.T @ J) * s2
        seen = np.linalg.norm(J, axis=0) > 1e-12 * max(float(np.abs(J).max()), 1e-300)
        # a parameter the fitted signals do not see has no uncertainty to report (pinv would say 0)
        return [float(math.sqrt(max(v, 0.0))) if ok else None for v, ok in zip(np.diag(cov), seen)]
    except Exception:  # noqa: BLE001 - an uncertainty we cannot compute is reported as unknown
        return [None] * len(res.x)


def _rms_by_signal(tg, trace, signals) -> dict:
    sim = tg.simulated(trace, signals)
    out = {}
    for s in signals:
        r = tg.measured[s] - sim[s]
        r = r[~np.isnan(r)]
        out[s] = float(np.sqrt(np.mean(r * r))) if len(r) else 0.0
    return out


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
    jobs = [(cls, [s for s in tg.measured if s in cls.signals]) for cls in classes]
    jobs = [(cls, used) for cls, used in jobs if used and cls.params]
    # candidates are independent; the servo loop and the engagement release the GIL, so two
    # fit at once on a 2-core machine
    with ThreadPoolExecutor(max_workers=_workers(len(jobs))) as pool:
        done = list(pool.map(lambda job: _fit_candidate(tg, *job), jobs))
    fits = {cls.name: fr for (cls, _), fr in zip(jobs, done)}
    for s in tg.measured:
        rms0 = _rms_by_signal(tg, tg.base, [s])[s]
        n = int(np.sum(~np.isnan(tg.measured[s])))
        rows = []
        for name, fr in fits.items():
            if fr is None or s not in fr.rms_after:
                continue
            rss0 = n * rms0 ** 2
            rss1 = n * fr.rms_after[s] ** 2
            k = len(fr.params)
            ev = 1.0 - rss1 / rss0 if rss0 > 0 else 0.0
            dbic = _delta_bic(n, rss1, rss0, k)
            p = {key.rsplit(".", 1)[-1]: round(v, 6) for key, v in fr.params.items()}
            rows.append({"effect": name, "explained_variance": ev, "delta_bic": dbic, "params": p,
                         "rms_after": fr.rms_after[s],
                         "evidence": (f"{s} residual RMS {rms0:.4g} → {fr.rms_after[s]:.4g} with {name} "
                                      f"({', '.join(f'{k_}={v:.4g}' for k_, v in p.items())}): "
                                      f"{max(ev, 0.0):.0%} of it explained, ΔBIC {dbic:+.1f}")})
        rows.sort(key=lambda r: r["delta_bic"])
        noise = tg.noise[s]
        if rms0 <= _FIT_FACTOR * noise:
            verdict = "fits"
        elif rows and rows[0]["delta_bic"] < STRONG_EVIDENCE and rows[0]["explained_variance"] >= 0.5:
            verdict = "explained"
        else:
            verdict = "unexplained"
        selected, rms_joint = ([], rms0) if verdict == "fits" else _forward(tg, s, rows, fits, rms0, n)
        out[s] = {"rms": rms0, "noise": noise, "verdict": verdict, "candidates": rows, "selected": selected,
                  "rms_after": rms_joint}
    return out


def _workers(jobs: int) -> int:
    return max(1, min(jobs, os.cpu_count() or 1, 4))


def _delta_bic(n: int, rss_new: float, rss_old: float, k: int) -> float:
    """Bayesian information criterion of a model with ``k`` more parameters against the old
    (Gaussian residuals): negative favours the new one."""
    return n * math.log(max(rss_new, 1e-300) / max(rss_old, 1e-300)) + k * math.log(max(n, 2))


def _forward(tg: Target, s: str, rows: list, fits: dict, rms0: float, n: int):
    """Forward selection on signal ``s`` (stepwise, in the spirit of FROLS): the candidate
    whose joint fit with those already taken lowers the BIC most, one at a time, while it
    lowers it by STRONG_EVIDENCE or more and the residual is above the noise; after each, an
    earlier one the BIC prefers without is dropped again.

    The joint fits are the candidates' single fits linearised — each candidate's simulated
    change and its Jacobian, both from its single fit — and solved by bounded linear least
    squares, so a step costs no simulation; the selected effects are then evaluated once on
    the twin (and refitted there if the linearisation was poor), which gives the reported
    residual.  Returns ([{effect, params, delta_bic, rms_after}] in the order taken, the joint
    fit's residual RMS); the params are the final joint fit's."""
    measured = tg.measured[s]
    ok = ~np.isnan(measured)
    sim0 = tg.simulated(tg.base, [s])[s]
    r0 = np.where(ok, measured - sim0, 0.0)
    lin = _Linearised(r0, ok, sim0, s, [fits[r["effect"]] for r in rows])
    rss = float(r0 @ r0)
    taken: list = []
    steps: list = []
    while lin.names and len(steps) < MAX_SELECTED and (not steps or math.sqrt(rss / n) > _FIT_FACTOR * tg.noise[s]):
        trials = [(lin.rss(taken + [c]), c) for c in lin.names if c not in taken]
        if not trials:
            break
        rss_c, name = min(trials)
        dbic = _delta_bic(n, rss_c, rss, lin.k[name])
        if dbic >= STRONG_EVIDENCE:
            break
        taken.append(name)
        rss = rss_c
        steps.append({"effect": name, "delta_bic": dbic, "rms_after": math.sqrt(rss / n)})
        for old in taken[:-1]:  # the backward look: one the new effect makes redundant goes
            without = lin.rss([c for c in taken if c != old])
            if _delta_bic(n, without, rss, -lin.k[old]) < 0:
                taken.remove(old)
                rss = without
                steps = [st for st in steps if st["effect"] != old]
    if not steps:
        return [], rms0
    effects, rms = lin.evaluate(tg, taken, math.sqrt(rss / n))
    best = rows[0]
    if len(steps) > 1 and rms >= best["rms_after"] and best["delta_bic"] < STRONG_EVIDENCE:
        # the twin does not bear the linearised joint fit out (an effect far from linear over
        # the move from its single fit): the single ranking's best is what is known
        fr = lin.fit[best["effect"]]
        return [{"effect": best["effect"], "delta_bic": best["delta_bic"], "rms_after": best["rms_after"],
                 "params": {k: round(float(v), 6) for k, v in fr.effects[0].resolved().items()}}], best["rms_after"]
    final = {e.name: e.resolved() for e in effects}
    for st in steps:
        st["params"] = {k: round(float(v), 6) for k, v in final[st["effect"]].items()}
    steps[-1]["rms_after"] = rms
    return steps, rms


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
        """A parameter the single fit left against a saturation (a friction taken to zero: its
        Jacobian column is zero there) gets the secant from its default instead — the change
        its move made, less what the other parameters' columns account for."""
        e = fr.effects[0]
        x = np.array(list(fr.params.values()), dtype=np.float64)
        default = np.array([d.default for d in e.params], dtype=np.float64)
        J = self.jac[name]
        flat = [j for j in range(len(x)) if not np.any(J[:, j]) and abs(x[j] - default[j]) > 1e-12]
        if len(flat) != 1:
            return
        j = flat[0]
        rest = self.change[name] - J @ np.where(np.arange(len(x)) == j, 0.0, x - default)
        J[:, j] = rest / (x[j] - default[j])

    def solve(self, names) -> tuple[float, dict]:
        """(residual sum of squares, {name: parameter values}) of the joint fit of ``names``."""
        from scipy.optimize import lsq_linear

        target = self.r0 - sum((self.change[c] for c in names), np.zeros_like(self.r0))
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

    def rss(self, names) -> float:
        return self.solve(names)[0]

    def evaluate(self, tg: Target, names, rms_linear: float):
        """(the effects at the joint fit's values, the residual RMS of the twin with them): one
        simulation; where that residual is above the noise level, a short fit on the twin from
        there (the better of the two is kept)."""
        _, values = self.solve(names)
        effects = []
        for c in names:
            e = self.fit[c].effects[0]
            lo, hi = self.fit[c].bounds
            effects.append(type(e)(**{d.name: float(np.clip(v, a, b))
                                      for d, v, a, b in zip(e.params, values[c], lo, hi)}))
        single = len(names) == 1 and np.allclose(values[names[0]], list(self.fit[names[0]].params.values()))
        if single:
            return effects, self.fit[names[0]].rms_after[self.s]
        rms = _rms_by_signal(tg, _trace_with(tg, tg.twin, effects), [self.s])[self.s]
        if rms > _FIT_FACTOR * tg.noise[self.s] and rms < 2.0 * rms_linear:
            # not at the noise level: a fit on the twin from there (further from the linear
            # model's figure than 2×, the linearisation is not a start a short fit gets back from)
            try:
                fr = fit(tg, [copy.deepcopy(e) for e in effects], [self.s], max_evaluations=2 * TRIAL_EVALUATIONS)
            except (MtwinError, ValueError, FloatingPointError):
                fr = None
            if fr is not None and fr.rms_after[self.s] < rms:
                return list(fr.effects), fr.rms_after[self.s]
        return effects, rms


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
