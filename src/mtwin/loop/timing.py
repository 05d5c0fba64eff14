"""Fitting a twin's timing to a control's logged block times (one or several programs).

A control that logs its executing line gives, per block group, how long the machine took
(:mod:`.blocks`).  What decides those times is the plan — feeds, rapids, accelerations,
tool changes, spindle waits — plus the in-position waits at exact stops, which only the
servo simulation knows.  So a timing case simulates its program (no cutting: the cut does
not change when lines start) at the twin's in-position width and at twice it, to learn each
line's wait and how it grows as the width narrows; every evaluation of a fit after that is a
plan alone (~0.03 s for a 4,000-line program) with those waits added at the end of their
lines.  The waits depend a little on the axes' speeds and accelerations, so a fit refreshes
them with the fitted twin and fits again (two passes); its final figures use waits
simulated with the fitted twin.

Residuals are per window of consecutive block groups (≈ 10 s of measured time):
(simulated − measured time) / the noise of a window's length, the noise floor (0.15 s) × √2 —
only its two ends' report jitter — and per block kind of each log, the error summed over the
kind's groups (simulated as logged, :func:`.blocks.simulated_as_logged`, less what logs of the
twin's own run show, :func:`.blocks.logging_bias`) / its report jitter (the sampling interval
/ √12 at each of the kind's boundaries with another kind).  Windows
alone let errors of opposite sign cancel — rapids long, short feed moves short — wherever the
kinds share a window; the sums by kind do not.  The fit is bounded least squares (scipy's trust-region
reflective) from a start found by scanning each parameter over its range — timing
objectives have kinks (a minimum block time binds or not, an arc limit bites or not) that a
local method alone can stall on.  A fit works on copies of its cases: the caller's waits
stay those of the twin they were simulated on.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import ConfigError, MtwinError
from ..effects.timing import jerk_of
from ..params import effect_param, is_effect_param
from ..fitting import delta_bic, solve, verdict
from .blocks import (NOISE_FLOOR, Groups, logging_bias, measurement_groups, set_apart_stops,
                     simulated_as_logged, simulated_durations)

SIGNAL = "window_time"  # the name a timing fit's error (RMS over the windows) goes by in the journal
WINDOW = 10.0  # s: block groups are summed into windows of at least this much measured time…
WINDOWS = 100  # …or into this many windows over the run, where that makes them shorter (not under 1 s)


def windows(measured: np.ndarray, length: float) -> np.ndarray:
    """Consecutive groups numbered into windows of at least ``length`` s measured time."""
    out = np.zeros(len(measured), np.int64)
    k, acc = 0, 0.0
    for i, d in enumerate(measured):
        out[i] = k
        acc += d
        if acc >= length:
            k, acc = k + 1, 0.0
    return out


@dataclass
class TimingCase:
    """A program and its logged run, with what a timing fit keeps fixed."""

    program: object
    meas: object
    label: str
    groups: Groups
    cycle_measured: float  # s, the run without its feed holds and program stops
    window: np.ndarray = field(default=None)  # (groups,) the window each group belongs to
    wait_line: np.ndarray = field(default=None)  # lines with an in-position wait
    wait: np.ndarray = field(default=None)  # s, the wait of each of those lines at in_position = width
    slope: np.ndarray = field(default=None)  # s per unit of ln(width / in_position): how it grows as it narrows
    width: float = 0.0  # mm, the in-position width the waits were simulated at
    kinds: tuple = ()  # the block kinds fitted by their sums
    kind_index: np.ndarray = field(default=None)  # (groups,) index into kinds, -1 for a kind not fitted
    kind_noise: np.ndarray = field(default=None)  # (kinds,) s, the report jitter of each kind's sum
    kind_bias: np.ndarray = field(default=None)  # (kinds,) s, what the sums show of the twin's own run logged


def timing_case(twin, program, meas, label: str | None = None) -> TimingCase:
    if meas.t is None or meas.line is None or not (meas.line > 0).any():
        raise MtwinError(f"{meas.path}: a timing fit needs a measurement that logs the executing line "
                         f"(a 'line' column, or an MTConnect log's Block_Number)")
    g = measurement_groups(program, meas)
    end = float(meas.end_time) if meas.end_time is not None else float(meas.t[-1] - meas.t[0])
    case = TimingCase(program, meas, label or meas.path, g, end, np.zeros(len(g.measured), np.int64))
    refresh_waits(twin, case)
    # groups at an M00/M01 where the control waited for the operator (measured against this
    # twin's time for their lines) are left out of the fit, and their waits out of the cycle
    g = set_apart_stops(g, evaluate(twin, case)[0])
    if len(g.measured) < 3:
        raise MtwinError(f"{meas.path}: only {len(g.measured)} block groups: too few to fit timing to")
    length = min(WINDOW, max(1.0, float(np.sum(g.measured)) / WINDOWS))
    case.groups, case.window = g, windows(g.measured, length)
    case.kinds, case.kind_index, case.kind_noise = _kind_sums(g)
    refresh_bias(twin, case)
    # (the run as the program made it: the feed holds, logged stops and operator waits taken out)
    case.cycle_measured = end - g.hold_time - g.stop_time - g.wait_time
    return case


UNFITTED_KINDS = ("program end", "other")  # (an end waits on the operator; "other" moves nothing)


def _kind_sums(g: Groups):
    """(kinds, each group's index into them or -1, the noise of each kind's summed error): a
    kind's sum carries the report jitter (uniform over one sampling interval, σ = interval/√12)
    of both ends of every run of consecutive groups of that kind."""
    kinds = tuple(k for k in dict.fromkeys(g.kind) if k not in UNFITTED_KINDS)
    idx = np.array([kinds.index(k) if k in kinds else -1 for k in g.kind], np.int64)
    jitter = (g.period or 2.0 * NOISE_FLOOR) / math.sqrt(12.0)
    starts = np.concatenate(([True], idx[1:] != idx[:-1])) if len(idx) else np.zeros(0, bool)
    runs = np.bincount(idx[starts & (idx >= 0)], minlength=len(kinds))
    return kinds, idx, jitter * np.sqrt(2.0 * np.maximum(runs, 1))


def refresh_bias(twin, case: TimingCase) -> None:
    """What the sums by kind show of ``twin``'s own run, logged as the case's log samples
    (:func:`.blocks.logging_bias`): taken off the case's sums, so that they compare like with
    like.  It depends little on the parameters, so a fit takes it from the twin of each pass."""
    plan = twin.plan(case.program)
    lines, starts, end = plan_starts(plan, case.wait_line, case_waits(twin, case))
    bias = logging_bias(case.program, case.groups, lines, starts, end)
    case.kind_bias = np.array([bias.get(k, 0.0) for k in case.kinds], np.float64)


def _refresh(twin, cases) -> None:
    """The cases' in-position waits and logging bias by kind, as ``twin`` has them."""
    for c in cases:
        refresh_waits(twin, c)
        refresh_bias(twin, c)


def refresh_waits(twin, case: TimingCase) -> None:
    """The in-position waits per line, from simulations of the case's program on ``twin``: at
    its in-position width and at twice it.  The axes settle into the width about
    exponentially, so a line's wait is close to linear in the log of the width, and an
    evaluation at another width interpolates (or extrapolates) on that line."""
    width = float(twin.machine.controller.in_position)
    lines, w = _waits(twin, case.program)
    slope = np.zeros_like(w)
    if width > 0:
        lines2, w2 = _waits(twin.with_params({"controller.in_position": 2.0 * width}), case.program)
        at2 = np.zeros_like(w)
        k = np.searchsorted(lines2, lines)
        ok = (k < len(lines2)) & (lines2[np.minimum(k, len(lines2) - 1)] == lines)
        at2[ok] = w2[k[ok]]
        slope = (w - at2) / math.log(2.0)
    case.wait_line, case.wait, case.slope, case.width = lines, w, slope, width


def _waits(twin, program):
    trace = twin.simulate(program, cutting=False)
    plan = twin.plan(program)
    pl = trace.summary.per_line
    lines, inv = np.unique(plan.seg["line"], return_inverse=True)
    planned = np.bincount(inv, weights=plan.dur, minlength=len(lines))
    k = np.searchsorted(lines, pl.line)
    ok = (k < len(lines)) & (lines[np.minimum(k, len(lines) - 1)] == pl.line)
    w = np.zeros(len(pl.line))
    w[ok] = pl.time[ok] - planned[k[ok]]
    keep = w > 1e-9
    return pl.line[keep].astype(np.int64), w[keep]


def case_waits(twin, case: TimingCase) -> np.ndarray:
    """The case's waits per line at ``twin``'s in-position width."""
    width = float(twin.machine.controller.in_position)
    if width <= 0:
        return np.zeros_like(case.wait)
    if case.width <= 0 or width == case.width:
        return case.wait
    return np.maximum(case.wait + case.slope * math.log(case.width / width), 0.0)


def plan_starts(plan, wait_line: np.ndarray, wait: np.ndarray):
    """(lines sorted, the time the interpolator first reaches each, end time) of a plan with
    the waits added at the end of their lines' last segments."""
    seg_line = np.asarray(plan.seg["line"], np.int64)
    n = len(seg_line)
    if n == 0:
        return np.zeros(0, np.int64), np.zeros(0), 0.0
    lines_u, last_rev = np.unique(seg_line[::-1], return_index=True)
    last = n - 1 - last_rev  # last segment of each line
    w = np.zeros(n)
    k = np.searchsorted(lines_u, wait_line)
    ok = (k < len(lines_u)) & (lines_u[np.minimum(k, len(lines_u) - 1)] == wait_line)
    np.add.at(w, last[k[ok]], wait[ok])
    before = np.concatenate(([0.0], np.cumsum(w)[:-1]))
    start = plan.t_start + before
    first_lines, first = np.unique(seg_line, return_index=True)
    keep = first_lines > 0
    return first_lines[keep], start[first][keep], plan.total_time + float(w.sum())


def evaluate(twin, case: TimingCase):
    """(simulated duration of each group as the log would show it, simulated cycle time) of the
    case on ``twin``."""
    plan = twin.plan(case.program)
    lines, starts, end = plan_starts(plan, case.wait_line, case_waits(twin, case))
    sim = simulated_durations(case.groups, lines, starts, end)
    return simulated_as_logged(case.groups, sim, lines, starts, end), end


def _errors(twin, case: TimingCase):
    """(simulated − measured time per group, per window, per fitted kind, simulated cycle time)."""
    d, cyc = evaluate(twin, case)
    e = np.where(np.isfinite(d), d - case.groups.measured, 0.0)
    fitted = case.kind_index >= 0
    by_kind = np.bincount(case.kind_index[fitted], weights=e[fitted], minlength=len(case.kinds))
    if case.kind_bias is not None:
        by_kind = by_kind - case.kind_bias
    return e, np.bincount(case.window, weights=e), by_kind, cyc


def residuals(twin, cases) -> np.ndarray:
    """Per window of each case: (simulated − measured time) / the noise of a window's length
    (its two ends' report jitter, the noise floor × √2); then per block kind of each case, the
    summed error / the noise of that sum."""
    out = []
    for c in cases:
        _, we, ke, _ = _errors(twin, c)
        out += [we / (NOISE_FLOOR * math.sqrt(2.0)), ke / c.kind_noise]
    return np.concatenate(out)


def summary(twin, cases) -> dict:
    """Per-group and per-window RMS error (s) over all cases, and each case's cycle-time error."""
    out = {"cases": []}
    sq, n, wsq, wn = 0.0, 0, 0.0, 0
    for c in cases:
        e, we, ke, cyc = _errors(twin, c)
        sq += float(np.sum(e * e))
        n += len(e)
        wsq += float(np.sum(we * we))
        wn += len(we)
        out["cases"].append({"measurement": c.label, "cycle_measured": c.cycle_measured, "cycle_simulated": cyc,
                             "cycle_error": (cyc - c.cycle_measured) / c.cycle_measured,
                             "rms": float(np.sqrt(np.mean(e * e))) if len(e) else 0.0,
                             "window_rms": float(np.sqrt(np.mean(we * we))) if len(we) else 0.0,
                             "kind_error": dict(zip(c.kinds, map(float, ke)))})
    out["rms"] = math.sqrt(sq / n) if n else 0.0
    out["window_rms"] = math.sqrt(wsq / wn) if wn else 0.0
    out["windows"] = wn
    return out


@dataclass
class TimingFit:
    """A timing fit: the fitted effects and base parameters, and the error before and after.
    Shaped like :class:`.fit.FitResult` (what the journal writes), with the cycle times."""

    effects: list
    params: dict
    uncertainty: dict
    rms_before: dict
    rms_after: dict
    noise: dict
    evaluations: int
    before: dict  # summary() before
    after: dict  # summary() after, from re-simulated waits
    rapid_rates: dict = field(default_factory=dict)  # axes.<a>.max_velocity -> (mm/min, spread, rapids) read
    # limits no logged block reaches: key -> {"least": the value set (the least the logs allow),
    # "fitted": where the search had left it}
    unreached: dict = field(default_factory=dict)
    not_identifiable: list = field(default_factory=list)  # limits the logs do not see at all: left at their start
    signals: list = field(default_factory=lambda: [SIGNAL])

    def as_dict(self) -> dict:
        return {"objective": "timing", "params": self.params, "uncertainty": self.uncertainty,
                "rms_before": self.rms_before, "rms_after": self.rms_after, "noise": self.noise,
                "evaluations": self.evaluations, "before": self.before, "after": self.after,
                "unreached": self.unreached, "not_identifiable": self.not_identifiable,
                "effects": [{"name": e.name, "params": e.resolved()} for e in self.effects]}


TIMING_PARAMS = ("axes.", "controller.", "spindle.", "timing.")
_RAPID = re.compile(r"axes\.([xyz])\.max_velocity")
MIN_RAPID_LENGTH = 25.0  # mm: a rapid this long cruises for several log samples at 176 mm/s
MIN_RAPIDS = 3


def rapid_rates(cases) -> dict:
    """Each axis' rapid rate read off the logs: over rapids at least MIN_RAPID_LENGTH long, the
    highest path speed logged while their line ran, times the share of the path the limiting
    axis takes (the axis runs at its limit there); the median over the rapids it limits, with
    the median absolute deviation as its spread.  {"axes.x.max_velocity": (mm/min, spread, n)}.

    Observed, not fitted: the block times cannot tell a higher rapid rate from a higher
    acceleration on short rapids, the logged speed can."""
    from ..gcode import records as R

    est: dict = {"x": [], "y": [], "z": []}
    for c in cases:
        rec = c.program.records
        rap = rec[rec["kind"] == R.RAPID]
        d = np.stack([rap["x"] - rap["sx"], rap["y"] - rap["sy"], rap["z"] - rap["sz"]], axis=1)
        length = np.linalg.norm(d, axis=1)
        feed = c.meas.signals.get("feed")
        if feed is None:
            continue
        for r, dd, L in zip(rap, d, length):
            if L < MIN_RAPID_LENGTH:
                continue
            f = feed[c.meas.line == r["line"]]
            f = f[np.isfinite(f)]
            if not len(f):
                continue
            u = np.abs(dd) / L
            est["xyz"[int(np.argmax(u))]].append(float(f.max()) * float(u.max()))
    out = {}
    for a, v in est.items():
        if len(v) >= MIN_RAPIDS:
            med = float(np.median(v))
            out[f"axes.{a}.max_velocity"] = (med, float(np.median(np.abs(np.array(v) - med))), len(v))
    return out


def fit_timing(twin, cases, effects, base_params=(), passes: int = 2, scan: bool = True) -> TimingFit:
    """Fit the parameters of ``effects`` (their values are the starts) and the named base
    parameters to the block times of ``cases``."""
    from .fit import build_fitted, free_parameters

    bad = [e.name for e in effects if e.stage != "plan"]
    if bad:
        raise MtwinError(f"{', '.join(bad)}: not a timing effect (a timing fit changes only what the plan "
                         f"depends on: effects of stage 'plan', and base parameters)")
    bad = [p for p in base_params if not p.startswith(TIMING_PARAMS)]
    if bad:
        raise MtwinError(f"--param {', '.join(bad)}: a timing fit changes axes.*, controller.*, spindle.* or "
                         f"timing.* parameters")
    # the fit refreshes waits: on copies, so the caller's cases (a diagnosis's next candidate,
    # another fold) keep the waits of the twin they were simulated on
    cases = [replace(c) for c in cases]
    rapid = [p for p in base_params if _RAPID.fullmatch(p)]
    read = {p: v for p, v in rapid_rates(cases).items() if p in rapid} if rapid else {}
    for p in rapid:
        if p not in read:
            raise MtwinError(f"--param {p}: the logs hold too few long rapids that {p.split('.')[1].upper()} "
                             f"limits ({MIN_RAPIDS} needed) to read its rapid rate from")
    if read:  # observed, not fitted: the logged peak speed of long rapids
        twin = twin.with_params({p: v[0] for p, v in read.items()})
        base_params = [p for p in base_params if p not in read]
    keys, lo, hi, x0, scale = free_parameters(twin, effects, base_params, _plan_starts(twin, effects))
    count = [0]
    before = summary(twin, cases)

    size = [0]
    best = [math.inf, None]  # the lowest cost at values the machine takes, and where

    def fun_x(x):
        count[0] += 1
        try:
            tw, fitted = build_fitted(twin, effects, keys, x)
            r = residuals(tw.with_effects(*fitted), cases)
        except ConfigError:
            if not size[0]:
                raise
            # a step into values the machine refuses (an acceleration its drives cannot give):
            # as far off as can be, so the solver steps back
            return np.full(size[0], 1e3)
        size[0] = len(r)
        cost = float(np.sum(r * r))
        if cost < best[0]:
            best[0], best[1] = cost, np.array(x, np.float64)
        return r

    x = x0
    for _ in range(max(1, passes)):
        if scan:
            x = _scan(fun_x, x, lo, hi, keys)
        # (block times are not noise-scaled residuals: no identifiability cut on them)
        sol = solve(fun_x, x, lo, hi, scale, max_evaluations=60, xtol=1e-6, ftol=1e-8, blind_check=False)
        x = sol.x
        try:
            tw, fitted = build_fitted(twin, effects, keys, x)
        except ConfigError:
            # the solver ended on values the machine refuses (a step it was still trying):
            # the best point it saw instead
            if best[1] is None:
                raise
            x = best[1].copy()
            tw, fitted = build_fitted(twin, effects, keys, x)
        _refresh(tw.with_effects(*fitted), cases)  # (as the fitted twin has them)
    unc = list(sol.uncertainty)
    unreached, blind = {}, []
    ceilings = _ceilings(effects)
    moved = False
    for i, key in enumerate(keys):
        if key in ceilings and unc[i] is None:  # no logged block reaches it
            how, v = _least_unreached(fun_x, x, i, lo[i], len(keys))
            if how == "least":
                unreached[key] = {"least": v, "fitted": float(x[i])}
            elif how == "unbounded":  # the logs do not see it at all: left at its start
                v = float(x0[i])
                blind.append(key)
            # ("better": a value below that fits clearly better — reached there, a fitted value)
            moved |= v != x[i]
            x[i] = v
    tw, fitted = build_fitted(twin, effects, keys, x)
    if moved:
        _refresh(tw.with_effects(*fitted), cases)
    after = summary(tw.with_effects(*fitted), cases)
    params = {p: v[0] for p, v in read.items()} | dict(zip(keys, map(float, x)))
    uncertainty = {p: v[1] for p, v in read.items()} | dict(zip(keys, unc))
    return TimingFit(fitted, params, uncertainty, {SIGNAL: before["window_rms"]}, {SIGNAL: after["window_rms"]},
                     {SIGNAL: NOISE_FLOOR * math.sqrt(2.0)}, count[0], before, after, rapid_rates=read,
                     unreached=unreached, not_identifiable=blind)


UNREACHED_HALVINGS = 20  # an unreached limit is halved at most this often to find where it binds
UNREACHED_STEP = 0.9  # then walked down: each value this much below the last
UNREACHED_STEPS = 40
UNREACHED_BISECTIONS = 8  # then the crossing of its one-standard-deviation bound: to 0.05 % of the value


def _ceilings(effects) -> set:
    """The fitted parameters that are limits the motion may never reach (Param.ceiling)."""
    return {effect_param(e.name, d.name) for e in effects for d in e.params if d.ceiling}


def _least_unreached(fun_x, x, i, lo_i, k: int) -> tuple[str, float]:
    """Where to set limit ``i``, which no logged block reaches at the fitted value (the
    residuals do not see it there: any larger value fits as well): ("least", the least value
    the logs allow), ("better", a value below that fits clearly better: the limit is reached
    there after all, where the search did not look) or ("unbounded", nan: nothing in the logs
    bounds it from below either — a program without arcs says nothing of an arc limit).

    Halved from the fitted value until the residuals change (where the limit starts to bind;
    never: unbounded), then walked down from the last value they did not change at by
    UNREACHED_STEP until the cost (noise-scaled squared residuals) rises clearly above the
    least seen (by four times its variance per degree of freedom: two standard deviations of a
    one-parameter profile); the least value whose cost is within one variance of that (one
    standard deviation), the crossing bisected between the walk's two values either side of it.
    Set there, the twin promises no speed the logs have not shown: a limit
    fitted to programs that never reach it would keep wherever the search left it, and predict a
    program that does reach it faster than the machine."""
    def cost(v):
        y = x.copy()
        y[i] = v
        return float(np.sum(fun_x(y) ** 2))

    r0 = fun_x(x)
    c0 = float(np.sum(r0 ** 2))
    s2 = c0 / max(1, len(r0) - k)
    v = float(x[i])
    for _ in range(UNREACHED_HALVINGS):
        if v / 2 <= lo_i:
            return "unbounded", math.nan
        c = cost(v / 2)
        if not math.isfinite(c) or abs(c - c0) > 1e-12 * max(c0, 1e-300):
            break
        v /= 2
    else:
        return "unbounded", math.nan
    seen = [(v, c0)]
    least = c0
    for _ in range(UNREACHED_STEPS):
        v *= UNREACHED_STEP
        if v <= lo_i:
            break
        c = cost(v)
        if not math.isfinite(c):  # (a value the twin cannot run: as far off as can be)
            break
        seen.append((v, c))
        least = min(least, c)
        if c > least + max(4.0 * s2, 1e-9 * c0):
            break
    if least < c0 - 4.0 * s2:
        return "better", min(seen, key=lambda vc: vc[1])[0]
    # (the residuals changed below the halving's last value: the logs bound it there, whether or
    # not the walk saw the cost rise clearly before it stopped)
    bound = least + s2
    last_in = max(j for j, (v, c) in enumerate(seen) if c <= bound)
    inside = seen[last_in][0]
    if last_in + 1 < len(seen):
        # the crossing between the walk's last value within one standard deviation and the next
        # one down, found by bisection: where the search left the limit, or where the walk's grid
        # happened to fall, no longer moves the value by up to a step (in a flat cost, by more)
        outside = seen[last_in + 1][0]
        for _ in range(UNREACHED_BISECTIONS):
            mid = 0.5 * (inside + outside)
            c = cost(mid)
            if math.isfinite(c) and c <= bound:
                inside = mid
            else:
                outside = mid
    return "least", inside


def fit_timing_steps(twin, cases, steps, base_params=()) -> TimingFit:
    """A calibration procedure in one call: the effects of ``steps`` added one at a time, each
    fit refitting those before it from where they ended (``mtwin calibrate --fit NAME --refit``
    in turn, as scripts/hurco-vmx24.sh runs it); then, given ``base_params``, one more fit of
    them all with those.  (One joint fit of every effect from the twin's defaults can settle
    where parameters trade against each other — long spindle waits against a tool change of no
    time — where each step starting from the last does not.)"""
    if not steps:
        raise MtwinError("a calibration procedure needs at least one effect to fit")
    cases = [replace(c) for c in cases]  # (the caller's keep their waits)
    fitted: list = []
    for effect in steps:
        fr = fit_timing(twin, cases, fitted + [effect])
        fitted = list(fr.effects)
        _refresh(twin.with_effects(*fitted), cases)  # the next step starts from this one's twin
    return fit_timing(twin, cases, fitted, base_params) if base_params else fr


def _plan_starts(twin, effects) -> dict:
    """Where each timing effect's parameters start: the twin's own value where 0 would mean
    'the twin file's' (so the scan and the solver start from the twin as it is)."""
    m = twin.planned_machine
    own = {"spindle-runup.acceleration": m.spindle.acceleration,
           "spindle-runup.power_speed": m.spindle.runup_power_speed or m.spindle.max_speed,
           "spindle-runup.braking": m.spindle.braking or m.spindle.acceleration,
           "block-time.min_time": m.controller.min_block_time,
           "corner-slowdown.corner_velocity": m.controller.corner_velocity,
           "arc-acceleration.acceleration": (m.controller.arc_acceleration
                                             or min(a.max_acceleration for a in m.axes)),
           "arc-acceleration.jerk": m.controller.arc_jerk,  # (0: none, where the fit's scan starts)
           "spiral-acceleration.acceleration": (m.controller.spiral_acceleration or m.controller.arc_acceleration
                                                or min(a.max_acceleration for a in m.axes)),
           "spiral-acceleration.normal_time": jerk_of(m.controller.spiral_jerk),  # (its own inverse)
           "rapid-acceleration.acceleration": (m.controller.rapid_acceleration
                                               or min(a.max_acceleration for a in m.axes)),
           "feed-rapid-wait.time": m.controller.feed_rapid_wait,
           "feed-rapid-wait.rapid_feed": m.controller.rapid_feed_wait}
    out = {}
    for e in effects:
        for d in e.params:
            key = f"{e.name}.{d.name}"
            if d.name not in e.values and key in own:
                out[effect_param(e.name, d.name)] = float(own[key])
    return out


def _scan(fun_x, x, lo, hi, keys, points: int = 9) -> np.ndarray:
    """Coordinate scan: each parameter in turn over a grid of its range (geometric where the
    range is positive), the best kept — a start for the local solver past the kinks."""
    def cost(y):
        try:
            return float(np.sum(fun_x(y) ** 2))
        except ConfigError:  # a base value the machine refuses (a zero speed)
            return math.inf

    x = x.copy()
    best = cost(x)
    for i in range(len(x)):
        lo_i = lo[i] if math.isfinite(lo[i]) else -abs(x[i]) * 4
        hi_i = hi[i] if math.isfinite(hi[i]) else max(abs(x[i]) * 4, 1.0)
        if not is_effect_param(keys[i]) and lo_i == 0 and x[i] > 0:
            lo_i = x[i] / 8  # a base parameter: around its value (0 is no machine)
        if lo_i > 0:
            grid = np.geomspace(lo_i, hi_i, points)
        elif lo_i == 0 and hi_i > 0:
            grid = np.concatenate(([0.0], np.geomspace(max(hi_i * 1e-3, abs(x[i]) / 8), hi_i,
                                                       points - 1)))
        else:
            grid = np.linspace(lo_i, hi_i, points)
        for v in grid:
            y = x.copy()
            y[i] = v
            c = cost(y)
            if c < best:
                best, x = c, y
    return x


def diagnose_timing(twin, cases, candidates=None) -> dict:
    """Each timing effect not yet in the twin fitted alone to the block times, ranked by the
    squared block-time error it removes (ΔBIC for an extra parameter's price)."""
    from ..effects import available

    in_model = {e.name for e in twin.effects}
    notes: list = []
    skip = set()
    evidence = ""
    if "feed-override" not in in_model and (candidates is None or "feed-override" in candidates):
        # an override in force for the whole run fits any error of the feed blocks, real or
        # not: tried only where the log's own feed shows one (named in candidates: always)
        suspect, why, evidence = _override_evidence(twin, cases)
        notes.append(why)
        if not suspect and candidates is None:
            skip.add("feed-override")
    classes = [c for n, c in available().items()
               if c.stage == "plan" and n not in in_model and n not in skip and (candidates is None or n in candidates)]
    before = summary(twin, cases)
    n = before["windows"]
    rows = []
    for cls in classes:
        try:
            fr = fit_timing(twin, cases, [cls()], passes=1)
        except (MtwinError, ValueError, FloatingPointError):
            continue
        rss0, rss1 = n * before["window_rms"] ** 2, n * fr.after["window_rms"] ** 2
        k = len(fr.params)
        p = {key.rsplit(".", 1)[-1]: v for key, v in fr.params.items()}
        rows.append({"effect": cls.name, "params": p, "rms_after": fr.after["rms"],
                     "window_rms_after": fr.after["window_rms"],
                     "removed": rss0 - rss1, "explained_variance": 1.0 - rss1 / rss0 if rss0 > 0 else 0.0,
                     "delta_bic": delta_bic(n, rss1, rss0, k),
                     "cycle_error_after": [c["cycle_error"] for c in fr.after["cases"]]})
    rows.sort(key=lambda r: -r["removed"])
    rms0, wrms0 = before["rms"], before["window_rms"]
    said = verdict(wrms0, NOISE_FLOOR * math.sqrt(2.0), rows[0]["delta_bic"] if rows else None)
    for r in rows:
        r["evidence"] = (f"window RMS {wrms0:.3g} → {r['window_rms_after']:.3g} s with {r['effect']} "
                         f"({', '.join(f'{k}={v:.4g}' for k, v in r['params'].items())}): "
                         f"{max(r['explained_variance'], 0.0):.0%} of the squared error removed, "
                         f"ΔBIC {r['delta_bic']:+.0f}; cycle time "
                         + ", ".join(f"{e:+.1%}" for e in r["cycle_error_after"]))
        if r["effect"] == "feed-override" and evidence:
            r["evidence"] += f"; the log's own feed: {evidence}"
        if r["effect"] == "feed-rapid-wait":
            r["evidence"] += _line_end_evidence(twin, cases)
    return {"rms": rms0, "window_rms": wrms0, "noise": NOISE_FLOOR, "window_noise": NOISE_FLOOR * math.sqrt(2.0),
            "verdict": said, "before": before, "candidates": rows, "notes": notes}


def _line_end_evidence(twin, cases) -> str:
    """'; the log's own line ends: …' — straight feed lines a rapid follows against those a feed
    move follows, timed against logs of the twin's own run (:func:`.asrun.feed_line_ends`, over
    all the cases), or '' where the logs report too few of them."""
    from .asrun import feed_line_ends

    parts: dict = {}
    for c in cases:
        ends = feed_line_ends(c.program, c.meas, twin.simulate(c.program, cutting=False))
        for nxt in ("rapid", "feed"):
            n, m, se = ends.get(("line", nxt), (0, 0.0, 0.0))
            if n > 1:
                parts.setdefault(nxt, []).append((n, m, se))

    def pooled(rows):  # (lines, mean, standard error) of the cases' lines together
        n = sum(r[0] for r in rows)
        return n, sum(r[0] * r[1] for r in rows) / n, math.sqrt(sum((r[0] * r[2]) ** 2 for r in rows)) / n

    if "rapid" not in parts or "feed" not in parts:
        return ""
    (n1, m1, s1), (n2, m2, s2) = pooled(parts["rapid"]), pooled(parts["feed"])
    return (f"; the log's own line ends: straight feed lines a rapid follows take {-m1 * 1000:+.0f} ± "
            f"{s1 * 1000:.0f} ms longer on the machine than in logs of the twin's own run ({n1} lines), those a "
            f"feed move follows {-m2 * 1000:+.0f} ± {s2 * 1000:.0f} ms ({n2})")


def _override_evidence(twin, cases) -> tuple[bool, str, str]:
    """Does any case's log show a constant ratio of its own feed to the programmed F (an
    unlogged override)?  With the note that says why, or why not, and the evidence for the
    candidate's row ("" when there is none)."""
    from .asrun import logged_against_programmed, ratio_note

    for c in cases:
        x = logged_against_programmed(c.program, c.meas,
                                      twin.simulate(c.program, cutting=False, chatter=False)).get("feed")
        if x is not None and x["suspect"]:
            return True, f"{c.label}: {ratio_note('feed', x)}", ratio_note("feed", x, advice=False)
    if len(cases) == 1 and x is not None:
        return False, (f"feed-override not tried by default: the log's own feed is {x['ratio']:.2f}× the programmed F "
                       f"over {x['samples']} samples with a {x['spread']:.0%} spread — no constant override (name it "
                       f"with --candidates to try it anyway)"), ""
    return False, ("feed-override not tried by default: no log shows its own feed at a constant ratio to the programmed "
                   "F (name it with --candidates to try it anyway)"), ""
