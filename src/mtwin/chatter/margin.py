"""The stability margin of a program's cuts: per engagement step, its axial depth over the
limit at its spindle speed, engaged arc and feed direction — the lobes of that cut.

The engagement gives each step the cosines of its flank arc's ends (bin centres, widened by
half a bin), its axial depth and its feed direction; steps of one tool whose arcs and
directions agree within ``QUANT`` share one lobe computation over all their speeds.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .. import layout as EK
from .lobes import Cut, Lobes, directional, lobes, peak_compliance

QUANT = math.radians(5.0)  # arcs (rounded outward) and feed directions are grouped to this
# (every arc is checked, a tool's entries and exits too: chatter needs many tooth passes at one
# engagement to build up, but a cut whose arc changes all along — a circular pocket, an
# adaptive path — is made of such transients only; conservative)
#: the semi-discretisation is spent on at most this many arc groups of a program (those with the
#: most steps); ``auto`` takes the zero-order approximation for the rest, with a note — a
#: program of ever-changing low-immersion arcs (trochoidal paths) would otherwise take minutes
SDM_GROUPS = 24
#: ... and only on groups holding at least this share of the steps checked: a flip lobe needs a
#: sustained low-immersion cut; a tool's entries and exits (brief arcs) take the zero-order
#: approximation, which is checked all the same
SDM_SHARE = 0.02


def _methods(method: str, inv: np.ndarray, count: int, notes: list | None) -> list[str]:
    """The method per group: ``auto`` keeps its choice (``lobes`` decides between zoa and sdm
    by the arc) for the SDM_GROUPS largest groups of at least SDM_SHARE of the steps, and
    takes zoa for the rest."""
    if method != "auto":
        return [method] * count
    sizes = np.bincount(inv, minlength=count)
    order = np.argsort(-sizes, kind="stable")[:SDM_GROUPS]
    big = {int(g) for g in order if sizes[g] >= SDM_SHARE * len(inv)}
    if notes is not None and len(big) < count:
        notes.append(f"{count} distinct arcs: the semi-discretisation where it applies on the {len(big)} that hold "
                     f"{100 * SDM_SHARE:g} % of the steps or more (at most {SDM_GROUPS}), the zero-order "
                     f"approximation on the rest (entries, exits)")
    return ["auto" if g in big else "zoa" for g in range(count)]


#: a group whose deepest cut is under this share of a lower bound of its zero-order limit at
#: every speed (``lower_bound``) is far from any lobe: no lobes are computed for it (flip lobes
#: go below the zero-order limit, but not this far: 0.74 of its lowest at ae/D 0.1 on the
#: benchmark, docs/chatter.md)
PRUNE = 0.2


def lower_bound(d, cut: Cut, flutes: int, ktc: float, krc: float) -> float:
    """A lower bound (mm) of the zero-order limit at every speed: the characteristic equation's
    root a·(1 − e^{−iωT}) = 1/μ with |μ| ≤ ‖Φ(ω)‖·‖D‖ and |1 − e^{−iωT}| ≤ 2 gives
    a ≥ 1/(2·max‖Φ‖·‖D‖) — no lobe computation needed."""
    D = directional(cut, flutes, ktc * 1e6, krc / ktc)
    phi = peak_compliance(d)
    nd = float(np.linalg.norm(D, 2))
    return math.inf if phi * nd <= 0 else 1e3 / (2.0 * phi * nd)


def _group_lobes(d, row, flutes, ktc, krc, speeds, how: str, deepest: float):
    """The lobes of one arc group: a group whose deepest cut is under PRUNE of the zero-order
    limit's lower bound is far from every lobe, and takes that bound as its limit (its margin
    is then ≤ PRUNE); else the method ``how`` asks for (auto: by the arc)."""
    cut = _cut_of(row)
    lb = lower_bound(d, cut, flutes, ktc, krc)
    if deepest < PRUNE * lb:
        n = len(speeds)
        return Lobes(np.asarray(speeds, float), np.full(n, lb), np.zeros(n, bool), np.full(n, np.nan), "bound", cut,
                     flutes)
    return lobes(d, cut, flutes, ktc, krc, speeds, how, steps=20, refine=False)


@dataclass
class StepArcs:
    """Per engagement step: cutting or not, the arc (rad), the feed angle (rad), depth (mm)."""

    cutting: np.ndarray
    phi_st: np.ndarray
    phi_ex: np.ndarray
    feed_angle: np.ndarray
    ap: np.ndarray


def step_arcs(q: np.ndarray) -> StepArcs:
    q = np.asarray(q, np.float64)
    half = math.pi / EK.ANGLE_BINS  # half a bin: the arc's ends are bin centres
    cmin, cmax = q[:, EK.Q_CMIN], q[:, EK.Q_CMAX]
    cutting = (q[:, EK.Q_AREA] > 0) & (cmax >= cmin) & (q[:, EK.Q_AP] > 0)
    st = np.clip(np.arccos(np.clip(cmax, -1, 1)) - half, 0.0, math.pi)
    ex = np.clip(np.arccos(np.clip(cmin, -1, 1)) + half, 0.0, math.pi)
    ang = np.arctan2(q[:, EK.Q_DY], q[:, EK.Q_DX])
    return StepArcs(cutting, st, ex, ang, q[:, EK.Q_AP])


def groups(tool, hand, arcs: StepArcs, idx):
    # (the arc rounded outward: a wider arc is the safe side of the lobes)
    key = np.stack([tool[idx], hand[idx], np.floor(arcs.phi_st[idx] / QUANT), np.ceil(arcs.phi_ex[idx] / QUANT),
                    np.round(arcs.feed_angle[idx] / QUANT) % round(2 * math.pi / QUANT)], axis=1)
    uniq, inv = np.unique(key, axis=0, return_inverse=True)
    return uniq, inv.reshape(-1)


def _cut_of(row) -> Cut:
    st = row[2] * QUANT
    ex = max(row[3] * QUANT, st + 1e-3)
    return Cut(float(min(st, math.pi)), float(min(ex, math.pi)), float(row[4] * QUANT), int(row[1]))


def step_limits(dyn: dict, flutes: dict, ktc: float, krc: float, tool: np.ndarray, hand: np.ndarray,
                speed: np.ndarray, arcs: StepArcs, method: str = "auto", notes: list | None = None):
    """Per step: the limiting depth (mm; inf where the tool has no dynamics or the step does
    not cut) at its speed, and the chatter frequency there (Hz)."""
    limit = np.full(len(tool), np.inf)
    freq = np.full(len(tool), np.nan)
    idx = np.flatnonzero(arcs.cutting & np.isin(tool, [t for t, d in dyn.items() if d]) & (speed > 0))
    if not len(idx):
        return limit, freq
    uniq, inv = groups(tool, hand, arcs, idx)
    how = _methods(method, inv, len(uniq), notes)
    for g, row in enumerate(uniq):
        at = idx[inv == g]
        sp, back = np.unique(np.round(speed[at], 1), return_inverse=True)
        lb = _group_lobes(dyn[int(row[0])], row, int(flutes[int(row[0])]), ktc, krc, sp, how[g],
                          float(arcs.ap[at].max()))
        limit[at] = lb.depth_limit[back]
        freq[at] = lb.chatter_frequency[back]
    return limit, freq


def limit_tables(dyn: dict, flutes: dict, ktc: float, krc: float, tool: np.ndarray, hand: np.ndarray,
                 arcs: StepArcs, idx: np.ndarray, speeds: np.ndarray, method: str = "auto",
                 notes: list | None = None):
    """For the steps ``idx``: their group (row per step) and each group's limit (mm) over the speed grid ``speeds`` — (group of each
    step, (groups, speeds) limits)."""
    if not len(idx):
        return np.zeros(0, np.int64), np.zeros((0, len(speeds)))
    uniq, inv = groups(tool, hand, arcs, idx)
    tab = np.full((len(uniq), len(speeds)), np.inf)
    how = _methods(method, inv, len(uniq), notes)
    for g, row in enumerate(uniq):
        d = dyn.get(int(row[0]))
        if not d:
            continue
        tab[g] = _group_lobes(d, row, int(flutes[int(row[0])]), ktc, krc, speeds, how[g],
                              float(arcs.ap[idx[inv == g]].max())).depth_limit
    return inv, tab


def tool_dynamics(cut, numbers) -> tuple[dict, dict]:
    """The library tools among ``numbers`` that the twin describes (its table, --tool) and their
    tip dynamics: (number -> Tool, number -> chatter.lobes.Dynamics)."""
    from .lobes import dynamics_of

    tools = {int(t): cut.tool(int(t)) for t in sorted(set(int(x) for x in numbers))
             if int(t) in cut.tools or int(t) in cut.declared}
    return tools, {t: dynamics_of(tl) for t, tl in tools.items()}
