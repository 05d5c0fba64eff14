"""Where the time goes: simulated against nominal time per program line, with the reason.

A CAM programmer's first question after the cycle time is which lines take it.  Nominal
time is what the program's words say — path length over F for feed moves, length over the
machine's speed along the move for rapids, the dwell for G4 — and a tool change or a
spindle run-up is nominally free.  The simulated time is the planner's segment times plus
the in-position waits the servo simulation found.  Where a line is slower than nominal,
the reason is the planner's own: which limit kept each of its segments below its feed.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..layout import P_VPEAK
from .path import ARC, CAT_DWELL, CAT_SPINDLE, CAT_TOOL, PAUSE

# reasons, by code (0: none — the line runs at its nominal time)
REASONS = (
    "",
    "tool change",
    "spindle run-up / speed change",
    "exact stop: in-position wait",
    "F above the machine's speed along this move",
    "arc speed limit (centripetal acceleration v²/r)",
    "too short to reach its speed (acceleration)",
    "slows down at its ends (corner speed or stop)",
)
R_NONE, R_TOOL, R_SPINDLE, R_WAIT, R_VLIMIT, R_ARC, R_SHORT, R_ENDS = range(len(REASONS))


@dataclass
class LineTimes:
    """Per program line (1-based ``line``): simulated and nominal seconds and the reason code
    (``REASONS``) of the largest loss.  Arrays of equal length, sorted by line."""

    line: np.ndarray
    time: np.ndarray
    nominal: np.ndarray
    reason: np.ndarray

    @property
    def lost(self) -> np.ndarray:
        """Seconds over nominal per line."""
        return self.time - self.nominal

    def worst(self, n: int = 5) -> list[dict]:
        """The ``n`` lines that lose the most time against nominal (losses above 1 ms)."""
        order = np.argsort(-self.lost, kind="stable")[:n]
        return [self.row(int(i)) for i in order if self.lost[i] > 1e-3]

    def row(self, i: int) -> dict:
        return {"line": int(self.line[i]), "time": float(self.time[i]), "nominal": float(self.nominal[i]),
                "reason": REASONS[int(self.reason[i])]}

    def as_dict(self) -> dict:
        """Column lists (seconds), for JSON."""
        return {"line": self.line.tolist(), "time": np.round(self.time, 6).tolist(),
                "nominal": np.round(self.nominal, 6).tolist(),
                "reason": [REASONS[int(r)] for r in self.reason]}


def line_times(plan, wait: np.ndarray) -> LineTimes:
    """Per-line times of a plan; ``wait``: in-position wait per segment from the simulation."""
    seg = plan.seg
    n = len(seg)
    if n == 0:
        z = np.zeros(0)
        return LineTimes(np.zeros(0, np.int64), z, z, np.zeros(0, np.int8))
    t = plan.dur + wait
    pause = seg["kind"] == PAUSE
    rapid = seg["rapid"] != 0
    length = seg["length"]
    # nominal: F for feed moves; for rapids the speed the axes allow along the move (vmax
    # is the rapid limit there); dwells count in full; tool changes and run-ups are free
    with np.errstate(divide="ignore", invalid="ignore"):
        speed = np.where(rapid, seg["vmax"], seg["feed"])
        nominal = np.where(pause, np.where(seg["cat"] == CAT_DWELL, seg["duration"], 0.0),
                           np.where(speed > 0, length / speed, 0.0))
    nominal = np.where(np.isfinite(nominal), nominal, 0.0)
    reason = np.full(n, R_ENDS, np.int8)
    peak = plan.prof[:, P_VPEAK]
    limit = np.where(rapid, seg["vmax"], np.minimum(seg["vmax"], np.where(seg["feed"] > 0, seg["feed"], np.inf)))
    below_f = ~rapid & ~pause & (seg["vmax"] < seg["feed"] * (1 - 1e-6))
    reason[below_f] = R_VLIMIT
    reason[below_f & (seg["kind"] == ARC)] = R_ARC
    short = ~pause & ~below_f & (peak < limit * 0.99)
    reason[short] = R_SHORT
    waits = wait + plan.hold
    reason[~pause & (waits > 0.5 * np.maximum(t - nominal, 0.0)) & (waits > 1e-4)] = R_WAIT
    reason[pause & (seg["cat"] == CAT_TOOL)] = R_TOOL
    reason[pause & (seg["cat"] == CAT_SPINDLE)] = R_SPINDLE
    reason[pause & (seg["cat"] == CAT_DWELL)] = R_NONE
    lost = t - nominal
    reason[lost <= 1e-6] = R_NONE
    # per line: sums of times; the reason of the segment that loses the most
    lines, inv = np.unique(seg["line"], return_inverse=True)
    time = np.bincount(inv, weights=t, minlength=len(lines))
    nom = np.bincount(inv, weights=nominal, minlength=len(lines))
    order = np.lexsort((-lost, inv))  # by line, largest loss first
    first = np.ones(n, bool)
    first[1:] = inv[order][1:] != inv[order][:-1]
    why = np.zeros(len(lines), np.int8)
    why[inv[order][first]] = reason[order][first]
    why[time - nom <= 1e-6] = R_NONE
    return LineTimes(lines.astype(np.int64), time, nom, why)
