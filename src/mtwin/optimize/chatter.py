"""Chatter in the optimiser: every cutting segment of a tool whose dynamics the twin knows is
kept inside the stable region of its lobes, with a safety factor.

Per segment, over a grid of spindle speeds: the largest ratio of a step's axial depth to the
lobes' limit for that step's arc and direction (``ratio``), made *robust* — the worst over
±``ROBUST`` of each speed, so that a speed chosen at a lobe's peak keeps its margin when the
spindle or the model is a little off.  A segment is stable at a speed when its ratio is at
most the margin (``--chatter-margin``, default 0.8 of the limit).  The spindle variables
start at the speeds of most headroom (the lobe peaks) where the program's own is not
stable; the search then keeps the constraint (``Problem.evaluate``'s ``v_chatter``).  A
segment over the margin at every allowed speed cannot be made stable by F or S: it is
reported with its lines (its axial depth must come down) and takes no part in the choice.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

ROBUST = 0.01  # relative speed band a chosen speed must be stable over
GRID = 240  # speeds over the spindle range


@dataclass
class ChatterTables:
    grid: np.ndarray  # (G,) rpm
    ratio: np.ndarray  # (S, G) robust ratio depth / limit (0: air or no dynamics)
    margin: float
    seg_ap: np.ndarray  # (S,) largest axial depth, mm
    unstable: np.ndarray  # (S,) bool: over the margin at every allowed speed
    best_ap: np.ndarray  # (S,) the deepest cut the margin allows at the best allowed speed, mm
    best_speed: np.ndarray  # (S,) that speed, rpm
    curves: dict  # tool -> list of (label, limits over grid (mm)) of its cuts' arcs, most limiting first
    method: str
    notes: list

    def at(self, n: np.ndarray) -> np.ndarray:
        """Ratio per segment at speeds ``n`` ((P, S) rpm), linear between grid speeds (0 on
        the segments reported unstable)."""
        g = self.grid
        if len(g) == 1:
            return np.broadcast_to(self.ratio[:, 0], n.shape).copy()
        x = np.clip(n, g[0], g[-1])
        i = np.clip(np.searchsorted(g, x, side="right") - 1, 0, len(g) - 2)
        a = (x - g[i]) / (g[i + 1] - g[i])
        rows = np.broadcast_to(np.arange(self.ratio.shape[0]), n.shape)
        return self.ratio[rows, i] * (1.0 - a) + self.ratio[rows, i + 1] * a


def chatter_tables(twin, program, model, eng, segs, prob, speed_range, margin: float,
                   method: str = "auto") -> ChatterTables | None:
    """The segments' stability tables, or None when no cutting tool has dynamics."""
    from ..chatter.margin import limit_tables, step_arcs, tool_dynamics
    from ..motion.simulate import program_cutting

    cut = program_cutting(twin, program)
    tools, dyn = tool_dynamics(cut, prob.seg_tool[~prob.seg_air])
    if not any(dyn.values()):
        return None
    rec = program.records
    n_prog = np.minimum(rec["spindle"][segs.piece_rec], twin.machine.spindle.max_speed)
    if speed_range is not None:
        grid = np.unique(np.concatenate([np.linspace(speed_range[0], speed_range[1], GRID),
                                         np.clip(n_prog, *speed_range)]))
    else:
        grid = np.unique(n_prog[n_prog > 0])
    arcs = step_arcs(eng.q)
    st = segs.step_seg
    tool = rec["tool"][model.rec].astype(np.int64)
    hand = np.where(rec["spindle_dir"][model.rec] < 0, -1, 1)
    idx = np.flatnonzero((st >= 0) & arcs.cutting & np.isin(tool, [t for t, d in dyn.items() if d]))
    mat = cut.material
    notes: list = []
    group, tab = limit_tables(dyn, {t: tl.flutes for t, tl in tools.items()}, mat.ktc, mat.krc, tool, hand, arcs,
                              idx, grid, method, notes)
    S = segs.count
    ratio = np.zeros((S, len(grid)))
    seg_ap = np.zeros(S)
    np.maximum.at(seg_ap, st[idx], arcs.ap[idx])
    # per (segment, group): the deepest step, then its ratio over the grid
    if len(idx):
        key = st[idx] * (len(tab) + 1) + group
        uk = np.unique(key)
        deep = np.zeros(len(uk))
        np.maximum.at(deep, np.searchsorted(uk, key), arcs.ap[idx])
        for k, d in zip(uk, deep):
            s, g = divmod(int(k), len(tab) + 1)
            ratio[s] = np.maximum(ratio[s], d / tab[g])
    ratio = _robust(ratio, grid)
    if speed_range is None:
        # S stays: each segment is judged at its own programmed speed only
        own = np.searchsorted(grid, prob.n0_spin[prob.seg_spin].clip(grid[0], grid[-1]))
        j = np.clip(own, 0, len(grid) - 1)
    else:
        j = np.argmin(ratio, axis=1)
    lowest = ratio[np.arange(S), j]
    best_ap = np.where(lowest > 0, seg_ap * margin / np.maximum(lowest, 1e-12), np.inf)
    best_speed = grid[j]
    unstable = (~prob.seg_air) & (lowest > margin)
    ratio[unstable] = 0.0
    curves: dict = {}
    if len(idx):
        tg = tool[idx]
        for g in np.unique(group):
            t = int(tg[group == g][0])
            im = float(np.median(0.5 * (np.cos(arcs.phi_st[idx][group == g]) - np.cos(arcs.phi_ex[idx][group == g]))))
            curves.setdefault(t, []).append((f"ae/D {im:.2f}", tab[g]))
        for t in curves:
            curves[t].sort(key=lambda c: float(np.min(c[1])))
            curves[t] = curves[t][:4]
    return ChatterTables(grid, ratio, margin, seg_ap, unstable, best_ap, best_speed, curves, method, notes)


def _robust(ratio: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """The worst ratio within ±ROBUST of each speed."""
    if len(grid) < 2:
        return ratio
    lo = np.searchsorted(grid, grid * (1 - ROBUST), side="left")
    hi = np.searchsorted(grid, grid * (1 + ROBUST), side="right")
    out = np.empty_like(ratio)
    for j in range(len(grid)):
        out[:, j] = ratio[:, lo[j]:hi[j]].max(axis=1)
    return out


def var_stable(tabs: ChatterTables, prob, spins: np.ndarray) -> np.ndarray:
    """Per spindle variable: all its cutting segments within the margin at these speeds."""
    r = tabs.at(np.asarray(spins, float)[prob.seg_spin][None, :])[0]
    ok = np.ones(prob.nspin, bool)
    np.logical_and.at(ok, prob.seg_spin, r <= tabs.margin)
    return ok


def stable_spins(tabs: ChatterTables, prob, spins: np.ndarray, keep_stable: bool = True) -> np.ndarray:
    """Spindle speeds per spindle variable: the given one where all its segments are stable
    with the margin (``keep_stable``), else the grid speed of most headroom (the highest
    lobe peak its segments allow)."""
    out = np.array(spins, float)
    for v in range(prob.nspin):
        segs = np.flatnonzero(prob.seg_spin == v)
        if not len(segs):
            continue
        worst = tabs.ratio[segs].max(axis=0)  # (G,)
        now = float(tabs.at(np.full((1, prob.seg_spin.shape[0]), out[v]))[0, segs].max())
        if keep_stable and now <= tabs.margin:
            continue
        ok = worst <= tabs.margin
        if ok.any():
            # most headroom; among near-equals (within 2 % of the margin) the fastest
            best = worst[ok].min()
            cand = np.flatnonzero(ok & (worst <= best + 0.02 * tabs.margin))
            out[v] = float(tabs.grid[cand[-1]])
    return out


def report(tabs: ChatterTables, prob, segs, program, spins_before: np.ndarray, spins_after: np.ndarray,
           after_summary=None, after_line_segs: dict | None = None) -> dict:
    """The ``chatter`` block of the result: per cutting segment its depth, speeds and margin
    (depth over limit) before and after, the segments that cannot be made stable, and the
    re-simulated answer's own check (``mtwin simulate``'s per-line margins)."""
    lines = segs.seg_lines(program)
    rb = tabs.at(spins_before[prob.seg_spin][None, :])[0]
    ra = tabs.at(spins_after[prob.seg_spin][None, :])[0]
    rows = []
    for s in np.flatnonzero(~prob.seg_air & (tabs.seg_ap > 0)):
        rows.append({"segment": int(s), "lines": [lines[s][0], lines[s][-1]], "tool": int(prob.seg_tool[s]),
                     "ap": float(tabs.seg_ap[s]), "speed_before": float(spins_before[prob.seg_spin[s]]),
                     "speed_after": float(spins_after[prob.seg_spin[s]]),
                     "margin_before": None if tabs.unstable[s] else float(rb[s]),
                     "margin_after": None if tabs.unstable[s] else float(ra[s]),
                     "unstable_everywhere": bool(tabs.unstable[s])})
    unstable = [r for r in rows if r["unstable_everywhere"]]
    check = {}
    if after_summary is not None and after_summary.cutting is not None and after_summary.cutting.chatter:
        ch = after_summary.cutting.chatter
        # (the answer's lines: a split move shifts them; each maps to the segments it runs in;
        # a line that runs in a segment no speed makes stable is that segment's, reported)
        segs_of = after_line_segs or {}
        over = [x for x in ch["lines"] if x["margin"] > tabs.margin
                and not any(tabs.unstable[s] for s in segs_of.get(x["line"], ()))]
        check = {"worst_margin": ch["worst_margin"], "lines_over_margin": [x["line"] for x in over]}
    return {"margin": tabs.margin, "method": tabs.method, "speed_grid": [float(tabs.grid[0]), float(tabs.grid[-1]),
                                                                         len(tabs.grid)],
            "segments": rows,
            "unstable": [{"lines": r["lines"], "tool": r["tool"], "ap": r["ap"],
                          "deepest_stable": float(tabs.best_ap[r["segment"]]),
                          "at_speed": float(tabs.best_speed[r["segment"]])} for r in unstable],
            "check": check, "notes": tabs.notes}
