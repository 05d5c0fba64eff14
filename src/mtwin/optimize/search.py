"""Search methods on a :class:`~mtwin.optimize.problem.Problem`: bisection and a genetic algorithm.

The GA is written here (about 100 lines of numpy) rather than taken from pymoo or DEAP: a
whole population is evaluated in one vectorised call on the problem's tables, which a
library's per-individual callbacks would turn into a Python loop, and the operators the
reference names (elitism, generation gap, a fitness limit, constraint violations as a
weighted penalty) are each a line.  scipy's differential evolution has neither a generation
gap nor elitism in that sense.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .problem import Problem

OBJECTIVES = ("time", "cost", "smooth", "air")
METHODS = ("bisect", "ga")


@dataclass
class GAOptions:
    population: int = 60
    generations: int = 200
    crossover: float = 0.9  # probability a child is a crossover of two parents
    mutation: float = 0.0  # per-gene probability; 0: 1/genes
    elitism: int = 2  # best individuals carried over unchanged
    generation_gap: float = 0.9  # fraction of the population replaced each generation
    fitness_limit: float = -np.inf  # stop when the best fitness reaches it
    stall: int = 30  # stop after this many generations without improvement
    penalty: float = 10.0  # weight of the relative constraint violation
    seed: int = 0


@dataclass
class SearchResult:
    feeds: np.ndarray  # (nvar,) mm/min
    spins: np.ndarray  # (nspin,) rpm
    evaluations: int
    generations: int = 0
    history: list | None = None  # best fitness per generation


def fixed_spins(p: Problem) -> np.ndarray:
    """The program's speeds, moved into the spindle range when one is given."""
    n = p.n0_spin.copy()
    if p.limits.spindle:
        n = _keep_locked(p, np.clip(n, *p.limits.spindle))
    return n


def _keep_locked(p: Problem, n: np.ndarray) -> np.ndarray:
    """Speeds with the locked spindle variables at the program's own (Problem.spin_locked)."""
    return n if p.spin_locked is None else np.where(p.spin_locked, p.n0_spin, n)


def start_spins(p: Problem) -> np.ndarray:
    """The speeds a search starts from: the program's (in range), except that with chatter
    tables and a spindle range a speed that chatters moves to the most stable one (a lobe's
    peak, optimize.chatter)."""
    n = fixed_spins(p)
    if p.limits.spindle and p.chatter is not None:
        from .chatter import stable_spins

        n = _keep_locked(p, stable_spins(p.chatter, p, n))
    return n


SPEED_GRID = 9  # speeds tried over a spindle range by the bisection (geometric)


def best_spins(p: Problem, objective: str, start: np.ndarray) -> np.ndarray:
    """With a spindle range, the speed of every spindle variable that gives its segments the
    least time (or cost) at their highest feeds within every limit: the start speed and a
    geometric grid over the range are tried.  A faster spindle carries the same chip at a
    higher feed, so where a chip or load limit binds the feed, a higher speed pays until the
    power, torque, chatter or the feed range stops it; the cost objective weighs the tool life
    it spends.  The choice is per variable (its segments' limits depend on its speed alone);
    the spindle's run-up waits, which tie them together, are weighed on the whole: the start
    speeds stay unless the choice wins with them counted."""
    lo_f = p.limits.feed[0]
    cut = ~p.seg_air
    cands = [start] + [np.full(p.nspin, s) for s in np.geomspace(*p.limits.spindle, SPEED_GRID)]
    if p.f_floor is not None:
        # on the program's own (learned) levels no tool runs below its programmed speed: its
        # feeds are the floor, a larger feed per tooth there (optimize.run keeps the rule)
        cands = [np.maximum(c, start) for c in cands]

    def figures(spins):
        """Per segment: the objective and how far it is over a limit at its highest feed."""
        fmax = p.max_feasible_feed(spins)
        ev = p.evaluate(np.where(np.isnan(fmax), lo_f, fmax)[None, :], spins[None, :])
        ts = ev["seg_time"][0]
        seg = ts if objective == "time" else p.rates.cost(ts, ev["seg_lives"][0])
        over = np.where(cut, ev["violation"][0], 0.0) + np.isnan(fmax[p.seg_var])
        return seg, over, ev

    # what a segment runs over a limit at the start (its own feed floor, a chatter no speed
    # cures) it may keep, as the rounds allow it; a speed that adds to any of it loses to one
    # that adds nothing
    found = [figures(spins) for spins in cands]
    over0 = found[0][1]
    scores = [np.bincount(p.seg_spin, weights=seg + 1e9 * np.maximum(over - over0, 0.0), minlength=p.nspin)
              for seg, over, _ in found]
    pick = np.argmin(np.array(scores), axis=0)
    if p.spin_locked is not None:
        pick[p.spin_locked] = 0  # (the start: the program's own speed)
    chosen = np.array([cands[k][i] for i, k in enumerate(pick)], float)

    def total(fig):
        _, over, ev = fig
        return float(ev[objective][0] + 1e9 * np.maximum(over - over0, 0.0).sum())

    return chosen if total(figures(chosen)) < total(found[0]) else start


def bisect(p: Problem, objective: str, target_power: float | None = None, tolerance: float = 0.05) -> SearchResult:
    """Per-segment bisection on the feed, as in the power-smoothing reference.

    ``time`` and ``cost``: the highest feed within the range and the limits, at the speeds
    :func:`best_spins` chooses when a spindle range is given (without chatter tables);
    ``smooth``: the feed whose segment mean power is the target within ``tolerance``
    (relative), capped by the limits; the spindle speeds stay (in range)."""
    spins = start_spins(p)
    if p.limits.spindle and objective in ("time", "cost") and p.chatter is None:
        # (with the tools' dynamics known the speed is the most stable one, a lobe's peak:
        # the headroom there also holds the moves outside the segments, which no search sees)
        spins = best_spins(p, objective, spins)
    fmax = p.max_feasible_feed(spins)
    lo_f, hi_f = p.limits.feed
    if objective in ("time", "cost"):
        feeds = np.where(np.isnan(fmax), lo_f, fmax)
        return SearchResult(feeds, spins, p.evaluations)
    if objective == "smooth":
        feeds = p.f0_var.copy()
        cut_var = np.zeros(p.nvar, bool)
        np.logical_or.at(cut_var, p.seg_var, ~p.seg_air)
        lo = np.full(p.nvar, math.log(lo_f))
        hi = np.log(np.where(np.isnan(fmax), lo_f, fmax))
        hi = np.maximum(hi, lo)
        w = p.seg_len * ~p.seg_air
        wsum = np.bincount(p.seg_var, weights=w, minlength=p.nvar)
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            ev = p.evaluate(np.exp(mid)[None, :], spins[None, :])
            mp = np.bincount(p.seg_var, weights=w * ev["mean_power"][0], minlength=p.nvar) / np.maximum(wsum, 1e-12)
            done = np.abs(mp / target_power - 1.0) <= tolerance * 0.25
            low = mp < target_power
            lo = np.where(low & ~done, mid, lo)
            hi = np.where(~low & ~done, mid, hi)
            lo = np.where(done, mid, lo)
            hi = np.where(done, mid, hi)
        feeds = np.where(cut_var, np.exp(0.5 * (lo + hi)), feeds)
        return SearchResult(feeds, spins, p.evaluations)
    raise ValueError(objective)


def fitness(p: Problem, ev: dict, objective: str, target_power: float | None, base: dict, penalty: float):
    if objective == "time":
        f = ev["time"] / base["time"]
    elif objective == "cost":
        f = ev["cost"] / base["cost"]
    else:  # smooth: length-weighted squared relative deviation of the segment mean powers
        w = p.seg_len * ~p.seg_air
        d = (ev["mean_power"] / target_power - 1.0) ** 2
        f = (d * w).sum(axis=1) / max(w.sum(), 1e-12)
    return f + penalty * ev["violation"].sum(axis=1) / max(1, int((~p.seg_air).sum())) ** 0.5


def genetic(p: Problem, objective: str, opts: GAOptions, seeds: list, target_power: float | None = None,
            progress=None) -> SearchResult:
    """Real-coded GA over log-feeds (and log-speeds when a spindle range is given).

    Tournament selection, blend crossover (BLX-0.3), Gaussian mutation, ``elitism`` best kept,
    ``generation_gap`` of the population replaced per generation, stops at the fitness limit,
    after ``stall`` generations without improvement or at ``generations``.  ``seeds``:
    (feeds, spins) individuals put into the first population (the program itself, the
    bisection answer), so the GA starts from feasible points."""
    rng = np.random.default_rng(opts.seed)
    lo_f, hi_f = p.limits.feed
    opt_spin = p.limits.spindle is not None
    lo = [math.log(lo_f)] * p.nvar
    hi = [math.log(hi_f)] * p.nvar
    if opt_spin:
        lo += [math.log(p.limits.spindle[0])] * p.nspin
        hi += [math.log(p.limits.spindle[1])] * p.nspin
    lo = np.array(lo)
    hi = np.array(hi)
    if opt_spin and p.spin_locked is not None:
        own = np.log(np.maximum(p.n0_spin, 1e-9))
        lo[p.nvar:] = np.where(p.spin_locked, own, lo[p.nvar:])
        hi[p.nvar:] = np.where(p.spin_locked, own, hi[p.nvar:])
    ng = len(lo)
    spins_fixed = fixed_spins(p)

    def split(X):
        F = np.exp(X[:, :p.nvar])
        N = np.exp(X[:, p.nvar:]) if opt_spin else np.broadcast_to(spins_fixed, (len(X), p.nspin))
        return F, N

    def score(X):
        F, N = split(X)
        ev = p.evaluate(F, N)
        return fitness(p, ev, objective, target_power, base, opts.penalty)

    F0 = np.clip(p.f0_var, lo_f, hi_f)
    base = {k: v for k, v in p.evaluate(F0[None, :], spins_fixed[None, :]).items()}
    base = {"time": float(base["time"][0]), "cost": float(base["cost"][0])}
    P = opts.population
    X = lo + (hi - lo) * rng.random((P, ng))
    for k, (f, n) in enumerate(seeds[:P]):
        row = np.log(np.clip(f, lo_f, hi_f))
        if opt_spin:
            row = np.concatenate([row, np.clip(np.log(np.maximum(n, 1e-9)), lo[p.nvar:], hi[p.nvar:])])
        X[k] = row
    fit = score(X)
    best_hist = [float(fit.min())]
    pm = opts.mutation or 1.0 / ng
    n_new = max(1, min(P - opts.elitism, int(round(opts.generation_gap * P))))
    stall = 0
    gen = 0
    for gen in range(1, opts.generations + 1):
        # tournament selection (size 2) of 2 * n_new parents
        a = rng.integers(0, P, (2, 2 * n_new))
        parents = np.where(fit[a[0]] <= fit[a[1]], a[0], a[1])
        pa, pb = X[parents[:n_new]], X[parents[n_new:]]
        # blend crossover BLX-alpha
        alpha = 0.3
        lo_c = np.minimum(pa, pb)
        hi_c = np.maximum(pa, pb)
        span = hi_c - lo_c
        child = lo_c - alpha * span + (1 + 2 * alpha) * span * rng.random(pa.shape)
        keep = rng.random(n_new) >= opts.crossover
        child[keep] = pa[keep]
        # Gaussian mutation, 10 % of the range
        mut = rng.random(child.shape) < pm
        child = child + mut * rng.normal(0.0, 0.1, child.shape) * (hi - lo)
        child = np.clip(child, lo, hi)
        cf = score(child)
        # generation gap: the children replace the worst n_new (elites survive by construction)
        order = np.argsort(fit)
        survivors = order[:P - n_new]
        X = np.concatenate([X[survivors], child])
        fit = np.concatenate([fit[survivors], cf])
        b = float(fit.min())
        if b < best_hist[-1] - 1e-9 * abs(best_hist[-1]):
            stall = 0
        else:
            stall += 1
        best_hist.append(min(b, best_hist[-1]))
        if progress is not None:
            progress(gen, opts.generations, best_hist[-1])
        if best_hist[-1] <= opts.fitness_limit or stall >= opts.stall:
            break
    k = int(np.argmin(fit))
    F, N = split(X[k:k + 1])
    return SearchResult(F[0].copy(), np.array(N[0], float), p.evaluations, gen, best_hist)
