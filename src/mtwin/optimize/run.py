"""Orchestration of ``mtwin optimize``: simulate, segment, search on the fast model, write,
verify, re-simulate on the full twin and hold the limits on that trace, not on the estimate.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import MtwinError
from ..gcode import records as R
from ..motion.path import PAUSE
from .model import feed_records, move_times, path_model
from .problem import CostRates, Limits, build_problem
from .search import GAOptions, bisect, fixed_spins, genetic
from .segment import segment_path


class VerifyError(MtwinError):
    """The written program failed its own proof: a bug (exit 3), nothing is written."""

    exit_code = 3


class InfeasibleError(MtwinError):
    """Even the lowest feed of the range breaks a limit: the program needs another strategy."""


@dataclass
class OptimizeOptions:
    objective: str = "time"
    method: str = "bisect"
    force_limit: float | None = None  # N; None: cost.force_per_diameter x tool diameter
    feed_range: tuple[float, float] | None = None  # mm/min; None: (10 % of the lowest F, machine max)
    spindle_range: tuple[float, float] | None = None  # rpm; None: S stays
    spindle_per: str = "tool"
    allow_s_changes: bool = False
    target_power: float | None = None  # W, smooth; None: the percentile below
    target_percentile: float = 75.0
    tolerance: float = 0.05  # smooth: |P/P_target - 1|
    segmentation: str = "cluster"
    min_segment: float = 5.0  # mm, the reference's C
    ga: GAOptions = field(default_factory=GAOptions)
    margin: float = 0.01
    max_rounds: int = 5


@dataclass
class Figures:
    cycle_time: float
    cost: float
    peak_load: float
    peak_power: float
    power_cv: float | None

    def as_dict(self):
        return {"cycle_time": self.cycle_time, "cost": self.cost, "peak_load": self.peak_load,
                "peak_power": self.peak_power, "power_cv": self.power_cv}


@dataclass
class OptimizeResult:
    """What ``optimize`` did, as data (the CLI prints it; the report draws it)."""

    output: bytes
    objective: str
    method: str
    before: Figures
    after: Figures
    estimate: dict  # the fast model's figures for the written program
    changed_lines: list  # (line, before text, after text)
    segments: list  # per segment: dict(lines, air, tool, feed_before, feed_after, limited_by, mean_power_*)
    verified: bool
    rounds: int
    evaluations: int
    seconds: float
    force_limit: dict  # tool -> N
    tradeoff: list  # (force limit N, estimated cycle time s)
    trace_before: object = None
    trace_after: object = None
    seg_before: np.ndarray | None = None  # segment of every sample of trace_before (-1: none)
    seg_after: np.ndarray | None = None  # the same for trace_after
    warnings: list = field(default_factory=list)
    generations: int = 0
    history: list | None = None


def optimize(twin, program, opts: OptimizeOptions, progress=None, stock=None) -> OptimizeResult:
    from ..cutting.engagement import engagement_for
    from ..gcode.verify import compare
    from ..gcode.writer import rewrite
    from ..motion.simulate import _cutting_scale, _program_cutting

    t_start = time.perf_counter()
    m = twin.machine
    before = twin.simulate(program, stock=stock)
    plan = twin.plan(program)
    eng = engagement_for(plan, program, _program_cutting(twin, program), stock, cache=twin.engagement_cache)
    # effects that scale the cutting coefficients along the path (tool wear) act on the estimate too
    resolved = [(e, e.resolved()) for e in twin.effects if e.stage == "loop"]
    kscale = _cutting_scale(eng, plan, resolved, program)
    model = path_model(twin, program, plan, eng, kscale)
    rec = program.records
    ok = feed_records(program)
    if not ok.any():
        raise MtwinError(f"{program.path}: no feed move whose feed can be set (G1/G2/G3 in mm/min or in/min)")
    max_feed = m.max_cutting_feed
    if opts.feed_range is None:
        lo = max(1.0, 0.1 * float(rec["feed"][ok].min()))
        feed_range = (lo, max_feed)
    else:
        feed_range = opts.feed_range
        if feed_range[1] > max_feed:
            feed_range = (feed_range[0], max_feed)
    if not (0 < feed_range[0] < feed_range[1]):
        raise MtwinError(f"--feed-range {feed_range[0]:g},{feed_range[1]:g}: need 0 < low < high (the machine's "
                         f"maximum cutting feed is {max_feed:g} mm/min)")
    spindle_range = opts.spindle_range
    if spindle_range is not None:
        hi = min(spindle_range[1], m.spindle.max_speed)
        if not (0 < spindle_range[0] < hi):
            raise MtwinError(f"--spindle-range {spindle_range[0]:g},{spindle_range[1]:g}: need 0 < low < high <= "
                             f"the spindle's {m.spindle.max_speed:g} rpm")
        spindle_range = (spindle_range[0], hi)
    if opts.spindle_per == "segment" and spindle_range is not None and not opts.allow_s_changes:
        raise MtwinError("--spindle-per segment changes S in mid-tool: add --allow-s-changes")
    n_step = np.minimum(rec["spindle"][model.rec], m.spindle.max_speed)
    fz0 = rec["feed"][model.rec] / (model.flutes * np.maximum(n_step, 1e-9))
    power0 = model.torque(fz0) * 2 * math.pi * n_step / 60.0
    segs = segment_path(program, model, power0, ok, min_length=opts.min_segment, method=opts.segmentation,
                        allow_splits=not getattr(program, "is_macro", False))
    fast = twin.plan(program, feeds=np.where(ok, feed_range[1], rec["feed"]))
    times = move_times(program, plan, fast)
    cut = _program_cutting(twin, program)

    def force_of_tool(tool, diameter):
        return opts.force_limit if opts.force_limit is not None else m.cost.force_per_diameter * diameter

    c = m.cost
    rates = CostRates(c.machine_rate, c.labour_rate, c.tool_price, c.tool_replace_time, c.taylor_n, c.taylor_c)
    limits = Limits(None, m.spindle.rated_power, m.spindle.base_speed, feed_range, spindle_range, opts.margin)
    prob = build_problem(model, segs, times, power0, program, limits, rates, opts.spindle_per,
                         before.summary.cycle_time, cut.spindle_loss, m.spindle.max_speed, force_of_tool)
    force_limits = {int(t): float(f) for t, f in zip(prob.seg_tool, prob.seg_force)}
    if spindle_range is not None:
        _runups(prob, program, plan, segs, m)

    # ---- a program that breaks a limit even at the lowest feed is reported, not optimised
    spins_try = fixed_spins(prob)
    if spindle_range is not None:
        spins_try = np.full(prob.nspin, spindle_range[1])
    low = prob.evaluate(np.full((1, prob.nvar), feed_range[0]), spins_try[None, :])
    over = (~prob.seg_air) & ((low["load"][0] > prob.seg_force) | (low["power"][0] > limits.power))
    if over.any() and opts.objective != "air":
        lines = segs.seg_lines(program)
        parts = []
        for s in np.flatnonzero(over)[:8]:
            parts.append(f"lines {lines[s][0]}-{lines[s][-1]}: {low['load'][0][s]:.0f} N (limit "
                         f"{prob.seg_force[s]:.0f} N), {low['power'][0][s] / 1000:.2f} kW")
        raise InfeasibleError(f"{program.path}:{lines[np.flatnonzero(over)[0]][0]}: {int(over.sum())} segment(s) break "
                              f"a limit even at the lowest feed {feed_range[0]:g} mm/min"
                              + (f" and {spins_try.max():g} rpm" if spindle_range else "") + ": "
                              + "; ".join(parts) + " — take a smaller depth or width of cut there, or a larger "
                              "--force-limit; nothing was written")

    # ---- target power for smoothing
    target = opts.target_power
    if opts.objective == "smooth" and target is None:
        ev0 = prob.evaluate(prob.f0_var[None, :], fixed_spins(prob)[None, :])
        mp = ev0["mean_power"][0][~prob.seg_air]
        if not len(mp):
            raise MtwinError(f"{program.path}: nothing is cut: no power curve to smooth")
        target = float(np.percentile(mp, opts.target_percentile))

    # ---- search
    generations, history = 0, None
    if opts.objective == "air":
        feeds = prob.f0_var.copy()
        air_var = np.zeros(prob.nvar, bool)
        np.logical_or.at(air_var, prob.seg_var, prob.seg_air)
        cut_var = np.zeros(prob.nvar, bool)
        np.logical_or.at(cut_var, prob.seg_var, ~prob.seg_air)
        top = max_feed if opts.feed_range is None else feed_range[1]
        feeds = np.where(air_var & ~cut_var, np.maximum(top, feeds), feeds)
        spins = prob.n0_spin.copy()
    elif opts.method == "bisect":
        res = bisect(prob, opts.objective, target, opts.tolerance)
        feeds, spins = res.feeds, res.spins
    else:
        seeds = [(prob.f0_var, fixed_spins(prob))]
        try:
            b = bisect(prob, "time" if opts.objective == "cost" else opts.objective, target, opts.tolerance)
            seeds.append((b.feeds, b.spins))
        except ValueError:
            pass
        if spindle_range is not None:
            # and the fastest feeds at the top and the middle of the speed range
            for n in (spindle_range[1], 0.5 * (spindle_range[0] + spindle_range[1])):
                sp = np.full(prob.nspin, n)
                f = prob.max_feasible_feed(sp)
                seeds.append((np.where(np.isnan(f), feed_range[0], f), sp))
        res = genetic(prob, opts.objective, opts.ga, seeds, target, progress)
        feeds, spins = res.feeds, res.spins
        generations, history = res.generations, res.history
    if opts.objective in ("time", "cost", "air"):
        # air segments at the top of the range (the load is zero there), never above it
        air_only = np.zeros(prob.nvar, bool)
        np.logical_or.at(air_only, prob.seg_var, prob.seg_air)
        cut_var = np.zeros(prob.nvar, bool)
        np.logical_or.at(cut_var, prob.seg_var, ~prob.seg_air)
        if opts.objective != "air":
            feeds = np.where(air_only & ~cut_var, feed_range[1], feeds)
    feeds = _approach_feeds(prob, segs, feeds)

    # ---- write, verify, re-simulate; a segment over a limit on the full twin is slowed
    round_ = 0
    scale = np.ones(prob.nvar)
    fresh = twin.machine.controller.style == "linuxcnc"
    while True:
        round_ += 1
        f_try = _round_feeds(feeds * scale, prob.f0_var, program)
        s_try = np.round(spins)
        feeds_rec, splits, spins_rec = _expand(program, segs, f_try, s_try, prob, spindle_range is not None)
        out = rewrite(program, feeds_rec, spins_rec, splits)
        new = twin.load(out, path=program.path)
        diff = compare(program, new)  # the check of `mtwin verify`
        if diff is not None:
            raise VerifyError(f"internal error: the optimised program does not cut the same path: {diff}")
        tw_after = twin if not fresh else _fresh(twin)
        after = tw_after.simulate(new, stock=stock)
        seg_after = _segment_of_samples(after, new, program, segs)
        over_v = _ratios(after, new, program, segs, prob, limits, seg_after)
        # samples outside the segments (rapids, plunges not optimised) keep the program's
        # feeds: a limit broken there is the program's own
        if round_ == 1:
            allowed = np.ones(prob.nvar)
            if opts.objective == "air":
                # the air objective leaves the cuts alone: a limit the program already breaks
                # there is the program's own, and must only not get worse
                allowed = np.maximum(allowed, _ratios(before, program, program, segs, prob, limits) * 1.001)
        bad = over_v > allowed
        if not bad.any():
            break
        if round_ >= opts.max_rounds:
            raise MtwinError(f"{program.path}: after {round_} rounds the re-simulated program still exceeds a limit "
                             f"in {int(bad.sum())} segment(s); nothing was written")
        with np.errstate(divide="ignore"):
            scale = np.where(bad, scale / over_v * (1 - opts.margin), scale)
        feeds = _approach_feeds(prob, segs, feeds * scale) / scale

    est = prob.evaluate(f_try[None, :], s_try[None, :])
    fig_before = _figures(before, program, segs, prob, rates, None)
    fig_after = _figures(after, new, segs, prob, rates, seg_after)
    lines = segs.seg_lines(program)
    limited = _limited_by(prob, f_try, s_try, est, feed_range, times, segs, program)
    ev_before = prob.evaluate(prob.f0_var[None, :], fixed_spins(prob)[None, :])
    seg_info = []
    for s in range(segs.count):
        v = prob.seg_var[s]
        seg_info.append({"lines": [lines[s][0], lines[s][-1]], "air": bool(prob.seg_air[s]), "tool": int(prob.seg_tool[s]),
                         "feed_before": float(prob.f0_var[v]), "feed_after": float(f_try[v]),
                         "spindle_after": float(s_try[prob.seg_spin[s]]), "limited_by": limited[s],
                         "mean_power_before": float(ev_before["mean_power"][0][s]),
                         "mean_power_after": float(est["mean_power"][0][s]),
                         "peak_load_estimate": float(est["load"][0][s])})
    tradeoff = _tradeoff(prob, s_try, force_limits) if opts.objective in ("time", "cost") else []
    changed = _changed_lines(program.data, out)
    return OptimizeResult(out, opts.objective, opts.method if opts.objective != "air" else "direct", fig_before,
                          fig_after, {"cycle_time": float(est["time"][0]), "cost": float(est["cost"][0]),
                                      "peak_load": float(est["load"][0][~prob.seg_air].max(initial=0.0)),
                                      "peak_power": float(est["power"][0][~prob.seg_air].max(initial=0.0))},
                          changed, seg_info, True, round_, prob.evaluations, time.perf_counter() - t_start,
                          force_limits, tradeoff, before, after, _segment_of_samples(before, program, program, segs),
                          seg_after, [], generations, history)


def _runups(prob, program, plan, segs, machine) -> None:
    """The spindle run-up pauses of the plan, tied to the spindle variables they depend on."""
    from ..motion.path import CAT_SPINDLE

    rec = program.records
    pauses = np.flatnonzero((plan.seg["kind"] == PAUSE) & (plan.seg["cat"] == CAT_SPINDLE))
    if not len(pauses) or not segs.count:
        return
    # spindle variable of every record: that of the segment of its tool's (or its own) pieces
    var_of_rec = np.full(len(rec), -1, np.int64)
    first_seg_of_tool = {}
    for s in range(segs.count):
        first_seg_of_tool.setdefault(int(prob.seg_tool[s]), s)
    for t, s in first_seg_of_tool.items():
        var_of_rec[rec["tool"] == t] = prob.seg_spin[s]
    if len(set(prob.seg_spin.tolist())) != len(first_seg_of_tool):  # per segment: by the next piece
        nxt = np.searchsorted(segs.piece_rec, np.arange(len(rec)))
        ok = nxt < len(segs.piece_rec)
        var_of_rec[ok] = prob.seg_spin[segs.piece_seg[nxt[ok]]]
    target = np.where(rec["spindle_dir"] != 0, np.minimum(rec["spindle"], machine.spindle.max_speed), 0.0)
    r = plan.seg["rec"][pauses]
    prev = np.clip(r - 1, 0, None)
    running_before = (r > 0) & (rec["spindle_dir"][prev] != 0)
    # a stop (M5) runs down to 0: a fixed speed, from the variable before it
    stopped = rec["spindle_dir"][r] == 0
    prob.runup_var = np.where(stopped, -2, var_of_rec[r])
    prob.runup_prev_var = np.where(running_before, var_of_rec[prev], -1)
    prob.runup_from = np.where(running_before, target[prev], 0.0)
    prob.runup_dur0 = plan.dur[pauses]
    keep = (prob.runup_var >= 0) | ((prob.runup_var == -2) & (prob.runup_prev_var >= 0))
    for name in ("runup_var", "runup_prev_var", "runup_from", "runup_dur0"):
        setattr(prob, name, getattr(prob, name)[keep])
    prob.runup_acc = machine.spindle.acceleration


def _ratios(trace, prog, original, segs, prob, limits, seg_of=None) -> np.ndarray:
    """Per variable, the largest ratio of load, spindle power or torque to its limit on a
    simulated trace."""
    if seg_of is None:
        seg_of = _segment_of_samples(trace, prog, original, segs)
    load = np.hypot(trace.signal("fx"), trace.signal("fy"))
    n = np.abs(np.asarray(trace.signal("spindle_speed")))
    t_lim = limits.power / (2 * math.pi * np.maximum(n, limits.base_speed) / 60.0)
    ratio = np.maximum.reduce([load / prob.seg_force[np.maximum(seg_of, 0)],
                               trace.signal("spindle_power") / limits.power,
                               trace.signal("spindle_torque") / t_lim])
    inside = seg_of >= 0
    out = np.zeros(prob.nvar)
    np.maximum.at(out, prob.seg_var[seg_of[inside]], ratio[inside])
    return out


def _approach_feeds(prob, segs, feeds: np.ndarray) -> np.ndarray:
    """An air segment that runs straight into a cut is an approach: it keeps at most the cut's
    feed (or its own programmed one).  At a higher feed the axes, lagging the command by their
    following error, would still be decelerating when the command enters the material, and
    the twin's load there would be set by the approach speed."""
    feeds = feeds.copy()
    nxt_seg = np.full(segs.count, -1)
    # the piece after the last piece of each segment, if it directly follows on the path
    last_piece = np.zeros(segs.count, np.int64)
    last_piece[segs.piece_seg] = np.arange(len(segs.piece_seg))
    for s in range(segs.count):
        k = last_piece[s] + 1
        if k < len(segs.piece_seg):
            r0, r1 = segs.piece_rec[k - 1], segs.piece_rec[k]
            if r1 == r0 or r1 == r0 + 1:
                nxt_seg[s] = segs.piece_seg[k]
    for s in np.flatnonzero(prob.seg_air & (nxt_seg >= 0)):
        n = nxt_seg[s]
        if not prob.seg_air[n]:
            v, vn = prob.seg_var[s], prob.seg_var[n]
            feeds[v] = min(feeds[v], feeds[vn])
    return feeds


def _fresh(twin):
    from ..twin import Twin

    return Twin(twin.machine, twin.interpreter, twin.path, twin.cutting, twin.effects)


def _round_feeds(f: np.ndarray, f0: np.ndarray, program) -> np.ndarray:
    """Feeds as they will be written: whole mm/min (0.1 in/min for inch programs), rounded
    down; a feed within half a step of the program's is the program's (nothing to write)."""
    inch = bool(len(program.records) and (program.records["flags"][0] & R.FL_INCH))
    step = 2.54 if inch else 1.0
    out = np.floor(f / step + 1e-6) * step
    return np.where(np.abs(f - f0) < 0.5 * step, f0, out)


def _expand(program, segs, feeds, spins, prob, spin_changes: bool):
    """Per-record feeds (NaN: keep), splits and spindle speeds of a candidate."""
    from ..gcode.writer import Split

    rec = program.records
    n = len(rec)
    out = np.full(n, np.nan)
    f_piece = feeds[prob.seg_var[segs.piece_seg]]
    splits = {}
    order = np.argsort(segs.piece_rec, kind="stable")
    pr = segs.piece_rec[order]
    bounds = np.flatnonzero(np.diff(pr)) + 1
    for grp in np.split(np.arange(len(pr)), bounds):
        if not len(grp):
            continue
        r = int(pr[grp[0]])
        idx = order[grp]
        fs = f_piece[idx]
        t1 = segs.piece_t1[idx]
        # merge neighbouring pieces with the same feed
        # merge neighbouring pieces whose feeds differ by under 1 % (the lower feed for both):
        # a split is worth its extra line only for a real change
        ts, fl = [], [fs[0]]
        for k in range(1, len(fs)):
            if abs(fs[k] - fl[-1]) > 0.01 * max(fs[k], fl[-1]):
                ts.append(float(segs.piece_t0[idx][k]))
                fl.append(fs[k])
            else:
                fl[-1] = min(fl[-1], fs[k])
        del t1
        if ts:
            splits[r] = Split(ts, [float(x) for x in fl])
        elif fl[0] != rec["feed"][r]:
            out[r] = fl[0]
    spindles = np.full(n, np.nan)
    if spin_changes:
        # one speed per tool (or segment): every record of the tool from its first cut on
        for s in range(segs.count):
            want = spins[prob.seg_spin[s]]
            rr = segs.piece_rec[segs.piece_seg == s]
            if not len(rr):
                continue
            tool = rec["tool"][rr[0]]
            same_tool = rec["tool"] == tool
            if want != min(rec["spindle"][rr[0]], np.inf):
                spindles[same_tool] = want
    return out, splits, spindles


def _segment_of_samples(trace, new_prog, program, segs) -> np.ndarray:
    """Segment of every trace sample (-1: none), by path length: the written program runs the
    same path, possibly with split moves, so a sample's distance along the path says which
    piece of which original record it is in."""
    rec_new = np.asarray(trace.record, np.int64)
    Ln = R.move_lengths(new_prog.records)
    Lo = R.move_lengths(program.records)
    cn = np.concatenate([[0.0], np.cumsum(Ln)])
    co = np.concatenate([[0.0], np.cumsum(Lo)])
    # position of each sample: its record's start + the fraction done (from the record's
    # sample range: first to last sample of the record)
    idx = np.clip(rec_new, 0, len(Ln) - 1)
    first = np.full(len(Ln), -1)
    last = np.full(len(Ln), -1)
    k = np.arange(len(idx))
    np.maximum.at(last, idx, k)
    first[::-1] = -1
    fi = np.full(len(Ln), len(idx))
    np.minimum.at(fi, idx, k)
    span = np.maximum(last[idx] - fi[idx], 1)
    frac = (k - fi[idx]) / span
    s = cn[idx] + frac * Ln[idx]
    r_o = np.clip(np.searchsorted(co, s, side="right") - 1, 0, len(Lo) - 1)
    t_o = np.where(Lo[r_o] > 0, (s - co[r_o]) / np.maximum(Lo[r_o], 1e-12), 0.0)
    key = segs.piece_rec.astype(np.float64) * 4.0 + segs.piece_t0
    o = np.argsort(key)
    skey = r_o * 4.0 + t_o
    j = np.searchsorted(key[o], skey, side="right") - 1
    cand = o[np.clip(j, 0, None)]
    valid = (j >= 0) & (segs.piece_rec[cand] == r_o) & (rec_new >= 0)
    # only feed moves belong to segments
    kind = new_prog.records["kind"][idx]
    valid &= (kind == R.LINEAR) | (kind == R.ARC_CW) | (kind == R.ARC_CCW)
    out = np.where(valid, segs.piece_seg[cand], -1)
    return out


def _figures(trace, prog, segs, prob, rates, seg_of) -> Figures:
    if seg_of is None:
        seg_of = _segment_of_samples(trace, prog, prog, segs)
    sm = trace.summary
    c = sm.cutting
    p = np.asarray(trace.signal("spindle_power"))
    n = np.abs(np.asarray(trace.signal("spindle_speed")))
    loss = prob.loss[0] + prob.loss[1] * n + prob.loss[2] * n * n
    pc = np.where(n > 0, p - loss, 0.0)
    # power CV over the cutting segments' mean powers (trace samples are evenly spaced in time)
    cutm = (seg_of >= 0)
    cutm &= ~prob.seg_air[np.maximum(seg_of, 0)]
    means = []
    if cutm.any():
        cnt = np.bincount(seg_of[cutm], minlength=segs.count)
        tot = np.bincount(seg_of[cutm], weights=pc[cutm], minlength=segs.count)
        means = tot[cnt > 0] / cnt[cnt > 0]
    cv = float(np.std(means) / np.mean(means)) if len(means) > 1 and np.mean(means) > 0 else None
    # cost from the trace: time, and per tool the time in cut at its speed
    dt = float(np.median(np.diff(trace.t))) if len(trace.t) > 1 else 0.0
    load = np.hypot(trace.signal("fx"), trace.signal("fy"))
    engaged = load > 0
    tool = prog.records["tool"][np.clip(np.asarray(trace.record, np.int64), 0, len(prog.records) - 1)]
    wear = 0.0
    diam = {int(t): float(d) for t, d in zip(prob.seg_tool, prob.seg_diam)}
    for t in np.unique(tool[engaged]):
        m = engaged & (tool == t)
        v = math.pi * diam.get(int(t), 6.0) * n[m] / 1000.0
        life = (rates.taylor_c / np.maximum(v, 1e-9)) ** (1.0 / rates.taylor_n)
        wear += float(np.sum(dt / 60.0 / life))
    cost = rates.rate * sm.cycle_time / 3600.0 + wear * (rates.tool_price + rates.rate * rates.tool_replace_time / 3600.0)
    return Figures(float(sm.cycle_time), float(cost), float(c.peak_load if c else 0.0), float(c.peak_power if c else 0.0),
                   cv)


def _limited_by(prob, feeds, spins, est, feed_range, times, segs, program) -> list:
    out = []
    m = 1.0 - prob.limits.margin
    for s in range(len(prob.seg_var)):
        f = feeds[prob.seg_var[s]]
        n = spins[prob.seg_spin[s]]
        if prob.seg_air[s]:
            out.append("feed range (air cut)" if f >= feed_range[1] - 1 else "kept")
            continue
        t_lim = prob.limits.power / (2 * math.pi * max(n, prob.limits.base_speed) / 60.0)
        r = {"load": est["load"][0][s] / (prob.seg_force[s] * m), "power": est["power"][0][s] / (prob.limits.power * m),
             "torque": est["torque"][0][s] / (t_lim * m)}
        k = max(r, key=r.get)
        if r[k] > 0.97:
            out.append(k)
        elif f >= feed_range[1] - 1:
            # at the top of the range: is the machine even reaching it?
            rr = segs.piece_rec[segs.piece_seg == s]
            v_cap = float(np.min(times.v_cap[rr])) * 60 if len(rr) else np.inf
            out.append("machine acceleration/speed" if v_cap < f * 0.95 else "feed range")
        elif f <= feed_range[0] + 1:
            out.append("feed range (minimum)")
        else:
            out.append("objective")
    return out


def _tradeoff(prob, spins, force_limits) -> list:
    """Estimated cycle time against the load limit, 10 N apart: what each extra 10 N buys."""
    base = float(np.median(prob.seg_force))
    out = []
    saved = prob.seg_force.copy()
    try:
        for lim in np.arange(max(10.0, round(base * 0.5 / 10) * 10), base * 2 + 1e-9, 10.0):
            prob.seg_force = saved * (lim / base)
            f = prob.max_feasible_feed(spins)
            f = np.where(np.isnan(f), prob.limits.feed[0], f)
            ev = prob.evaluate(f[None, :], spins[None, :])
            out.append((float(lim), float(ev["time"][0])))
    finally:
        prob.seg_force = saved
    return out


def _changed_lines(a: bytes, b: bytes) -> list:
    import difflib

    la = a.decode("latin-1").splitlines()
    lb = b.decode("latin-1").splitlines()
    out = []
    sm = difflib.SequenceMatcher(None, la, lb, autojunk=False)
    for tag, i1, i2, j1, j2 in sm.get_opcodes():
        if tag == "equal":
            continue
        out.append((i1 + 1, "\n".join(la[i1:i2]), "\n".join(lb[j1:j2])))
    return out
