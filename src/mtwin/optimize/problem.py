"""The optimisation problem on the fast model: per-segment tables, objectives, constraints.

A candidate is a feed per variable (segments sharing a line share one) and a spindle speed
per spindle variable (per tool, or per segment).  Its evaluation touches only per-segment
tables, never the path steps, so a population of hundreds is evaluated in microseconds per
candidate:

* the peak load and peak spindle torque of a segment as functions of the feed per tooth —
  maxima over its steps of convex functions (``|f_z·a + b|`` and ``f_z·t_a + t_b``), tabulated
  on a grid and interpolated linearly in f_z, so the interpolation lies on or above the true
  maximum (a chord of a convex function): an upper bound, never an optimistic estimate;
* the mean cutting torque of a segment, exactly affine in f_z (length-weighted);
* the segment time as a function of the feed, tabulated on a grid and interpolated in 1/F
  (exact for the L/F part).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from .guards import percentile_by_group
from .model import cutting_speed, taylor_life

GRID = 64


@dataclass
class Limits:
    force: np.ndarray  # (tools,) N, by seg_tool index -> see Problem.force_of_seg
    power: float  # W, spindle rated power
    base_speed: float  # rpm, end of the constant-torque range
    feed: tuple[float, float]  # mm/min
    spindle: tuple[float, float] | None  # rpm; None: S stays as programmed
    margin: float = 0.01  # the estimate is held this far under the limits


@dataclass
class CostRates:
    machine_rate: float  # per hour
    labour_rate: float  # per hour
    tool_price: float  # per tool (edge set)
    tool_replace_time: float  # s, to replace a worn tool
    taylor_n: float
    taylor_c: float  # m/min for one minute of life
    currency: str = "$"
    # with a calibrated flank-wear law: a tool's life as each flute's edge sliding (m) from new
    # to the end-of-life land; tool life is then used by sliding, not by Taylor's time
    slide_life: float | None = None

    @property
    def rate(self) -> float:
        return self.machine_rate + self.labour_rate

    def lives_used(self, cut_seconds, v_m_min):
        """Tool lives a cut uses: its time over the Taylor life at its cutting speed."""
        return (np.asarray(cut_seconds) / 60.0) / taylor_life(np.asarray(v_m_min, dtype=np.float64), self.taylor_n,
                                                               self.taylor_c)

    def cost(self, time_s, lives):
        """Gilbert's cost: the rate over the time, and per tool life used its price and the
        rate over the time to replace it."""
        return self.rate * time_s / 3600.0 + lives * (self.tool_price + self.rate * self.tool_replace_time / 3600.0)


@dataclass(frozen=True)
class Runups:
    """Spindle run-ups the program waits for: per pause, the spindle variable whose speed it
    runs up to (−2: a stop, down to 0 rpm), the one it starts from (−1: a fixed speed,
    ``start``, rpm), its duration in the program's own plan (s), and the spindle's
    acceleration (rpm/s)."""

    var: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    prev_var: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    start: np.ndarray = field(default_factory=lambda: np.zeros(0))
    dur0: np.ndarray = field(default_factory=lambda: np.zeros(0))
    acc: float = 1.0


@dataclass
class Problem:
    """The optimisation problem on the fast model: per segment its variables, tools, limits
    and tables, built once by :func:`build_problem` (copies with :func:`dataclasses.replace`
    for a variant: another load limit, the learned chip limits)."""

    nvar: int
    seg_var: np.ndarray  # (S,)
    seg_spin: np.ndarray  # (S,) spindle variable of each segment
    nspin: int
    seg_air: np.ndarray  # (S,)
    seg_flutes: np.ndarray  # (S,)
    seg_diam: np.ndarray  # (S,)
    seg_force: np.ndarray  # (S,) load limit, N
    seg_tool: np.ndarray  # (S,)
    seg_len: np.ndarray  # (S,) mm
    fz_grid: np.ndarray  # (G,)
    load_tab: np.ndarray  # (S, G)
    torque_tab: np.ndarray  # (S, G)
    mta: np.ndarray  # (S,) mean torque per mm of f_z
    mtb: np.ndarray  # (S,)
    f_grid: np.ndarray  # (G,) mm/min
    time_tab: np.ndarray  # (S, G) s
    t_base: np.ndarray  # (S,) s at the program's feeds
    f0_var: np.ndarray  # (nvar,) the program's feed (first piece)
    n0_spin: np.ndarray  # (nspin,) the program's speed
    cycle_before: float
    limits: Limits
    rates: CostRates
    loss: np.ndarray  # spindle no-load loss polynomial, W: c0 + c1 n + c2 n^2
    evaluations: int = field(default=0)  # (a running count of the model's evaluations)
    runups: Runups = field(default_factory=lambda: Runups())
    # the largest chip thickness of a segment per mm of feed per tooth, and its limit (mm;
    # inf: none) — the chip load a program's own cuts run at, when the limits are learned
    seg_chip: np.ndarray | None = None
    seg_hlim: np.ndarray | None = None
    # (S,) the chip ceilings the re-simulation checks too (physics; inf elsewhere), mm
    seg_hchecked: np.ndarray | None = None
    # (nspin,) with a spindle range, the spindle variables whose new speed the writer could not
    # place (its S word would fall on a line the program runs more than once, at another speed
    # or for another tool): they keep the program's speeds, every S word as written
    spin_locked: np.ndarray | None = None
    # per variable, the lowest feed the answer may have (0: the feed range's; the program's
    # own feed when the limits are learned from it: nothing is slowed)
    f_floor: np.ndarray | None = None
    # per segment, the arc each flute's edge slides through per revolution (mm; R·Δφ of its
    # engagement): with ``rates.slide_life`` the tool life a segment uses is its sliding,
    # seconds × rev/s × arc, over the life
    seg_arc: np.ndarray | None = None
    # with tools whose dynamics the twin knows: the segments' stability tables
    # (optimize.chatter.ChatterTables); a segment is held within the chatter margin
    chatter: object = None

    # ---- the model -------------------------------------------------------------------
    def _interp(self, tab: np.ndarray, fz: np.ndarray) -> np.ndarray:
        g = self.fz_grid
        fz = np.clip(fz, g[0], g[-1])
        i = np.clip(np.searchsorted(g, fz, side="right") - 1, 0, len(g) - 2)
        a = (fz - g[i]) / (g[i + 1] - g[i])
        rows = np.arange(tab.shape[0])
        rows = np.broadcast_to(rows, fz.shape)
        return tab[rows, i] * (1.0 - a) + tab[rows, i + 1] * a

    def seg_time(self, F: np.ndarray) -> np.ndarray:
        u = 1.0 / self.f_grid  # decreasing
        x = np.clip(1.0 / F, u[-1], u[0])
        ur = u[::-1]
        i = np.clip(np.searchsorted(ur, x, side="right") - 1, 0, len(ur) - 2)
        a = (x - ur[i]) / (ur[i + 1] - ur[i])
        tab = self.time_tab[:, ::-1]
        rows = np.broadcast_to(np.arange(tab.shape[0]), F.shape)
        return tab[rows, i] * (1.0 - a) + tab[rows, i + 1] * a

    def _mechanics(self, feeds: np.ndarray, spins: np.ndarray):
        """Per candidate and segment: feed, speed, feed per tooth, peak load and torque (the
        tables), peak spindle power, angular speed and the spindle's torque limit."""
        F = feeds[:, self.seg_var]
        n = spins[:, self.seg_spin]
        fz = F / (self.seg_flutes * np.maximum(n, 1e-9))
        load = self._interp(self.load_tab, fz)
        torque = self._interp(self.torque_tab, fz)
        omega = 2.0 * math.pi * n / 60.0
        power = torque * omega + self.loss[0] + self.loss[1] * n + self.loss[2] * n * n
        t_lim = self.limits.power / (2.0 * math.pi * np.maximum(n, self.limits.base_speed) / 60.0)
        return F, n, fz, load, torque, power, omega, t_lim

    def chip(self, fz: np.ndarray) -> np.ndarray:
        """Largest chip thickness (mm) of every segment at feeds per tooth ``fz``."""
        chip = self.seg_chip if self.seg_chip is not None else np.zeros(len(self.seg_var))
        return fz * chip

    def _excess(self, load, power, torque, t_lim, fz=None):
        """Relative excess over the load, power, torque and chip-thickness limits (each held
        the margin under them); -1 on air segments."""
        m = 1.0 - self.limits.margin
        cut = ~self.seg_air
        pairs = [(load, self.seg_force), (power, self.limits.power), (torque, t_lim)]
        if fz is not None:
            hlim = self.seg_hlim if self.seg_hlim is not None else np.full(len(self.seg_var), np.inf)
            pairs.append((self.chip(fz), hlim))
        return tuple(np.where(cut, x / (lim * m) - 1.0, -1.0) for x, lim in pairs)

    def evaluate(self, feeds: np.ndarray, spins: np.ndarray) -> dict:
        """Figures of candidates: ``feeds`` (P, nvar) mm/min, ``spins`` (P, nspin) rpm."""
        feeds = np.atleast_2d(feeds)
        spins = np.atleast_2d(spins)
        self.evaluations += feeds.shape[0]
        F, n, fz, load, torque, power, omega, t_lim = self._mechanics(feeds, spins)
        mean_power = (self.mta * fz + self.mtb) * omega
        ts = self.seg_time(F)
        time = self.cycle_before + (ts - self.t_base).sum(axis=1) + self.runup_change(spins)
        cut = ~self.seg_air
        v_load, v_power, v_torque, v_chip = (np.maximum(x, 0.0) for x in self._excess(load, power, torque, t_lim, fz))
        # cost (Gilbert): rate x time + per tool (cut time / life) x (price + rate x change time)
        if self.seg_arc is not None and self.rates.slide_life:
            used = ts * (n / 60.0) * self.seg_arc * 1e-3 / self.rates.slide_life  # the wear law's life
        else:
            used = self.rates.lives_used(ts, cutting_speed(self.seg_diam, n))
        used = np.where(cut, used, 0.0)
        wear = used.sum(axis=1)
        cost = self.rates.cost(time, wear)
        v_chatter = np.zeros_like(v_load)
        if self.chatter is not None:
            r = self.chatter.at(n)
            v_chatter = np.where(cut, np.maximum(r / self.chatter.margin - 1.0, 0.0), 0.0)
        return {"time": time, "cost": cost, "load": load, "power": power, "torque": torque, "fz": fz,
                "mean_power": mean_power, "seg_time": ts,
                "violation": v_load + v_power + v_torque + v_chip + v_chatter, "v_chatter": v_chatter,
                "v_load": v_load, "v_power": v_power, "v_torque": v_torque, "v_chip": v_chip, "tool_lives": wear,
                "seg_lives": used}

    def runup_change(self, spins: np.ndarray) -> np.ndarray:
        """Change of the spindle run-up waits (s) at these speeds against the program's."""
        r = self.runups
        if not len(r.var):
            return np.zeros(spins.shape[0])
        # var -2: a stop, down to 0 rpm
        to = np.where(r.var >= 0, spins[:, np.maximum(r.var, 0)], 0.0)
        frm = np.where(r.prev_var >= 0, spins[:, np.maximum(r.prev_var, 0)], r.start)
        same = (r.prev_var == r.var) & (r.var >= 0)
        new = np.where(same, 0.0, np.abs(to - frm) / r.acc)
        return (new - r.dur0).sum(axis=1)

    def max_feasible_feed(self, spins: np.ndarray) -> np.ndarray:
        """Per variable, the highest feed in the range that keeps every cutting segment of it
        within the limits at these spindle speeds (bisection on the tables, 40 halvings);
        NaN where even the lowest feed is over a limit."""
        lo_f, hi_f = self.limits.feed
        lo = np.full(self.nvar, math.log(lo_f))
        hi = np.full(self.nvar, math.log(hi_f))
        spins = np.atleast_2d(spins)

        def ok(logf):
            _, _, fz, load, torque, power, _, t_lim = self._mechanics(np.exp(logf)[None, :], spins)
            over = np.maximum.reduce(self._excess(load, power, torque, t_lim, fz))[0] > 0
            bad = np.zeros(self.nvar, bool)
            np.logical_or.at(bad, self.seg_var, over)
            return ~bad

        top = ok(hi)
        bottom = ok(lo)
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            good = ok(mid)
            lo = np.where(good, mid, lo)
            hi = np.where(good, hi, mid)
        out = np.where(top, math.exp(math.log(hi_f)), np.exp(lo))
        out = np.where(bottom, out, np.nan)
        if self.f_floor is not None:
            # never under the floor (the program's own feed per tooth, when the limits are its own)
            fl = self.floor_feeds(spins[0])
            out = np.where(fl > 0, np.fmax(out, fl), out)
        return out

    def floor_feeds(self, spins: np.ndarray) -> np.ndarray:
        """Per variable, the lowest feed at these spindle speeds: the program's own feed, or at
        a lower speed than the program's (a spindle range below it) the same feed per tooth;
        zeros without a floor."""
        if self.f_floor is None:
            return np.zeros(self.nvar)
        vs = self.var_spin
        ratio = np.minimum(1.0, np.asarray(spins, float)[vs] / np.maximum(self.n0_spin[vs], 1e-9))
        return self.f_floor * ratio

    @property
    def var_spin(self) -> np.ndarray:
        """Per feed variable, its spindle variable (the segments sharing a line share both)."""
        out = np.zeros(self.nvar, np.int64)
        out[self.seg_var] = self.seg_spin
        return out


def build_problem(model, segs, times, power0: np.ndarray, program, limits: Limits, rates: CostRates,
                  spindle_per: str, cycle_before: float, loss, max_speed: float, force_of_tool) -> Problem:
    """Tables of the segments from the path model (``power0``: step power at the program's F/S)."""
    rec = program.records
    S = segs.count
    ok = segs.step_seg >= 0
    st = segs.step_seg[ok]
    o = np.argsort(st, kind="stable")
    st = st[o]
    idx = np.flatnonzero(ok)[o]
    bounds = np.searchsorted(st, np.arange(S))
    present = np.bincount(st, minlength=S) > 0
    flutes_seg = np.full(S, 2.0)
    diam_seg = np.full(S, 6.0)
    if len(idx):
        first_step = idx[np.minimum(bounds, len(idx) - 1)]
        flutes_seg = np.where(present, model.flutes[first_step], 2.0)
        diam_seg = np.where(present, model.diameter[first_step], 6.0)
    lo_f, hi_f = limits.feed
    n_lo, n_hi = limits.spindle if limits.spindle else (float(np.min(rec["spindle"][rec["spindle"] > 0], initial=max_speed)),
                                                        max_speed)
    n_lo = min(n_lo, float(np.min(np.minimum(rec["spindle"][segs.piece_rec], max_speed), initial=n_lo)))
    n_lo = max(n_lo, 1.0)
    fz_lo = lo_f / (flutes_seg.max() * max(n_hi, n_lo)) * 0.5
    fz_hi = hi_f / (flutes_seg.min() * n_lo) * 2.0
    fz_grid = np.concatenate([[0.0], np.geomspace(fz_lo, fz_hi, GRID - 1)])
    load_tab = np.zeros((S, GRID))
    torque_tab = np.zeros((S, GRID))
    if len(idx):
        b = np.minimum(bounds, len(idx) - 1)
        # (the steps gathered once, not once per grid point; a step that does not cut adds 0)
        cut = model.cutting[idx]
        ax, ay = model.fa[idx, 0] * cut, model.fa[idx, 1] * cut
        bx, by = model.fb[idx, 0] * cut, model.fb[idx, 1] * cut
        ta, tb = model.ta[idx] * cut, model.tb[idx] * cut
        L, u, v = np.empty(len(idx)), np.empty(len(idx)), np.empty(len(idx))
        for g, fz in enumerate(fz_grid):
            np.multiply(ax, fz, out=u)
            u += bx
            np.multiply(ay, fz, out=v)
            v += by
            np.hypot(u, v, out=L)
            load_tab[:, g] = np.maximum.reduceat(L, b)
            np.multiply(ta, fz, out=u)
            u += tb
            torque_tab[:, g] = np.maximum.reduceat(u, b)
        load_tab[~present] = 0.0
        torque_tab[~present] = 0.0
    # (its 95th percentile by length, like the learned level it is held to: the chip a program
    # runs at for a twentieth of a cut, not at a one-step entry)
    seg_chip = percentile_by_group(st, model.chip[idx], model.length[idx] * model.cutting[idx], S, 95.0)
    w = model.length[idx] * model.cutting[idx]
    seg_len = np.bincount(st, weights=model.length[idx], minlength=S)
    mta = np.bincount(st, weights=w * model.ta[idx], minlength=S) / np.maximum(seg_len, 1e-12)
    mtb = np.bincount(st, weights=w * model.tb[idx], minlength=S) / np.maximum(seg_len, 1e-12)
    # time tables
    f_grid = np.geomspace(lo_f * 0.999, max(hi_f, lo_f * 1.001) * 1.001, GRID)
    frac = segs.piece_t1 - segs.piece_t0
    time_tab = np.zeros((S, GRID))
    tab = times.table(segs.piece_rec, f_grid, frac)
    for g in range(GRID):
        time_tab[:, g] = np.bincount(segs.piece_seg, weights=tab[:, g], minlength=S)
    nvar = segs.variables
    f0_var = np.zeros(nvar)
    f0_var[segs.seg_var[segs.piece_seg[::-1]]] = rec["feed"][segs.piece_rec[::-1]]
    if spindle_per == "segment" or limits.spindle is None:
        # S per segment; with no spindle range each segment keeps its own programmed speed
        seg_spin = np.arange(S)
    else:
        tools = np.unique(segs.seg_tool)
        seg_spin = np.searchsorted(tools, segs.seg_tool)
    nspin = int(seg_spin.max()) + 1 if S else 0
    # the program's speed of a spindle variable: the lowest over its pieces (the highest feed
    # per tooth, so the load estimate stays an upper bound)
    n0 = np.full(max(nspin, 1), np.inf)
    np.minimum.at(n0, seg_spin[segs.piece_seg], np.minimum(rec["spindle"][segs.piece_rec], max_speed))
    n0 = np.where(np.isfinite(n0), n0, max_speed)
    seg_force = np.array([force_of_tool(int(t), float(d)) for t, d in zip(segs.seg_tool, diam_seg)])
    p = Problem(nvar=nvar, seg_var=segs.seg_var, seg_spin=seg_spin, nspin=nspin, seg_air=segs.seg_air,
                seg_flutes=flutes_seg, seg_diam=diam_seg, seg_force=seg_force, seg_tool=segs.seg_tool, seg_len=seg_len,
                fz_grid=fz_grid, load_tab=load_tab, torque_tab=torque_tab, mta=mta, mtb=mtb, f_grid=f_grid,
                time_tab=time_tab, t_base=np.zeros(S), f0_var=f0_var, n0_spin=n0[:nspin], cycle_before=cycle_before,
                limits=limits, rates=rates, loss=np.asarray(loss, float), seg_chip=seg_chip)
    # the segments' times at the program's feeds, read off the same tables: a candidate's time
    # is the program's cycle plus the change the tables see, so the table's own interpolation
    # error cancels at (and near) the program's feeds
    return replace(p, t_base=p.seg_time(f0_var[segs.seg_var][None, :])[0])

