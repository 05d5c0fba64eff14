"""Flank wear: a wear land that grows with the edge's sliding over the workpiece, and the edge
forces the land adds.

The wear law (``docs/wear.md`` derives it).  Archard's law (Archard 1953) for the flank: the
volume worn per unit edge length grows with the normal load per unit length on the flank and
the distance slid, dw = (k_A/H)·f_n·ds.  The worn-off flank is a triangle of land width VB and
clearance angle α, w = ½·VB²·tan α, so VB·tan α·dVB = (k_A/H)·f_n·ds.  The flank's normal load
is the sharp edge's own (the ploughing force, per unit length) plus the land's contact,
f_n = f_e + σ·VB (Waldorf, DeVor & Kapoor 1998; Smithey, Kapoor & DeVor 2001).  Dividing:

    dVB/ds = r·(b/VB + 1),   r = k_A·σ/(H·tan α),  b = f_e/σ

— a break-in zone where the sharp edge's load wears a narrow land fast (VB ≈ √(2·r·b·s)), then
a steady zone of constant slope r where the land's own contact dominates.  Its solution from
VB₁ is closed:  r·s = (VB − VB₁) − b·ln((b + VB)/(b + VB₁)).  The accelerated zone comes from
temperature: the land's friction heats the flank, and Usui's rate law makes the wear rate
exponential in temperature; with a temperature rising with the land that is an extra factor
exp(a·VB) (``accel`` a; 0 leaves it out).

The force law (Smithey, Kapoor & DeVor 2001): on a land narrower than the critical width the
contact stresses are uniform, normal σ and shear μ·σ, so per unit length of engaged edge the
land adds σ·VB to the radial (ploughing) edge coefficient and μ·σ·VB to the tangential one;
the rake face, and so the shearing coefficients, are those of the sharp tool.

``s`` is each flute's sliding (m), ``StepInfo.sliding``: the history of the tool carried from
program to program by the tool ledger.
"""
from __future__ import annotations

import numpy as np

from ..params import Param
from .base import Effect

#: a land this wide is a destroyed edge: the law stops there
VB_CAP = 2.0  # mm
_GRID = 4001

# coefficient columns (ktc, krc, kac, kte, kre, kae)
_TE, _RE = 3, 4


def sliding_to(vb, vb_start: float, p: dict) -> np.ndarray:
    """Sliding (m) that takes the land from ``vb_start`` to ``vb`` (mm) under the law ``p``."""
    vb = np.asarray(vb, dtype=np.float64)
    r, b, a = p["rate"], p["break_in"], p["accel"]
    if r <= 0:
        return np.where(vb > vb_start, np.inf, 0.0)
    if a == 0:
        return ((vb - vb_start) - b * np.log((b + vb) / (b + vb_start))) / r
    grid, s = _table(vb_start, p)
    return np.interp(vb, grid, s, right=np.inf)


def _table(vb_start: float, p: dict) -> tuple[np.ndarray, np.ndarray]:
    """(VB grid, sliding to each) from ``vb_start`` to the cap: the integral of dVB / rate,
    by the trapezoid rule on a grid dense at the start, where the break-in curves most."""
    r, b, a = p["rate"], p["break_in"], p["accel"]
    u = np.linspace(0.0, 1.0, _GRID)
    grid = vb_start + (VB_CAP - vb_start) * u ** 2
    inv = grid * np.exp(-a * grid) / (r * (b + grid))  # ds/dVB
    s = np.concatenate(([0.0], np.cumsum(0.5 * (inv[1:] + inv[:-1]) * np.diff(grid))))
    return grid, s


def land(s, vb_start: float, p: dict) -> np.ndarray:
    """The land VB (mm) after sliding ``s`` (m, ≥ 0) from ``vb_start``, capped at VB_CAP."""
    s = np.maximum(np.asarray(s, dtype=np.float64), 0.0)
    r, b, a = p["rate"], p["break_in"], p["accel"]
    if r <= 0 or not s.size:
        return np.full(s.shape, float(vb_start))
    grid, table = _table(vb_start, p)
    vb = np.interp(s, table, grid, right=VB_CAP)
    if a == 0:
        # two Newton steps on the closed form take the interpolation to rounding error
        for _ in range(2):
            g = (vb - vb_start) - b * np.log((b + vb) / (b + vb_start)) - r * s
            vb = np.where(vb < VB_CAP, vb - g * (b + vb) / np.maximum(vb, 1e-12), vb)
        vb = np.clip(vb, vb_start, VB_CAP)
    return vb


class FlankWear(Effect):
    name = "flank-wear"
    description = ("flank-wear land VB growing with the edge's sliding (Archard: break-in, steady, "
                   "accelerated), adding σ·VB to the edge forces (Smithey)")
    stage = "loop"
    params = (
        Param("rate", "mm/m", 0.0, 0.0, 0.01, "steady-zone growth of the land per metre of edge sliding "
              "[E: 1e-4-5e-3 mm/m; carbide in steel 60-300 m of sliding to VB 0.3 mm]"),
        Param("break_in", "mm", 0.02, 0.001, 0.3, "land at which the land's contact load equals the sharp "
              "edge's, f_e/σ: the break-in's size [E: 0.01-0.08 mm]"),
        Param("sigma", "N/mm^2", 400.0, 0.0, 3000.0, "normal stress on the wear land [S: Smithey 2001, about "
              "the work material's flow stress: 300-500 aluminium, 800-1500 steel]"),
        Param("mu", "", 0.5, 0.0, 1.5, "friction on the land, shear over normal stress [S: Smithey 2001, 0.3-0.7]"),
        Param("vb0", "mm", 0.0, 0.0, 0.3, "land of a new tool (its edge hone)"),
        Param("accel", "1/mm", 0.0, 0.0, 20.0, "accelerated zone: the rate grows as exp(accel·VB) "
              "(Usui's temperature law; 0: none) [E: 5-20 /mm]"),
    )
    # per-cut forces see the land only through σ·VB: the law's rate and break-in are fitted
    # from them, σ, μ and the rest from a measured land (``fit=rate+break_in+sigma``)
    fitted = ("rate", "break_in")
    signals = ("spindle_power", "spindle_torque", "fx", "fy", "fz", "x_torque", "y_torque", "z_torque",
               "x_current", "y_current", "z_current", "vb")

    def wear_land(self, steps, p):
        return land(steps.sliding, p["vb0"], p)

    def cutting_add(self, steps, p):
        if not p["sigma"] or (not p["rate"] and not p["vb0"]):
            return None
        vb = self.wear_land(steps, p)
        add = np.zeros((len(vb), 6))
        add[:, _TE] = p["mu"] * p["sigma"] * vb  # N/mm: the land's friction, tangential
        add[:, _RE] = p["sigma"] * vb  # N/mm: its normal load, radial (ploughing)
        return add


def law_of(effects) -> dict | None:
    """The resolved parameters of the last flank-wear effect among ``effects`` (a twin's), or
    None."""
    laws = [e for e in effects if e.name == FlankWear.name]
    return laws[-1].resolved() if laws else None


def life(vb_limit: float, p: dict, vb_start: float | None = None) -> float:
    """Sliding (m) from ``vb_start`` (default the new tool's land) to the land ``vb_limit``."""
    start = p["vb0"] if vb_start is None else vb_start
    if vb_limit <= start:
        return 0.0
    return float(sliding_to(vb_limit, start, p))


def parts_to_limit(p: dict, vb_now: float, sliding_per_part: float, vb_limit: float) -> int | None:
    """Whole parts (each sliding ``sliding_per_part`` m) a tool at the land ``vb_now`` cuts before
    the land passes ``vb_limit``; None when the law does not wear it (rate 0) or a part does
    not slide."""
    if vb_now >= vb_limit:
        return 0
    left = float(sliding_to(vb_limit, vb_now, p))
    if not np.isfinite(left) or sliding_per_part <= 0:
        return None
    return int(left // sliding_per_part)
