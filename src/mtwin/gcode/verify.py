"""Prove that two programs cut the same path.

Both programs are interpreted and their motion records walked together: every
move of the original must be reproduced by one move of the other, or by
several consecutive pieces of the same kind (rapid, linear, arc with the same
centre and direction, same tool) whose end points lie on the original move, in
order, the last one on its end point.  Feeds and spindle speeds are ignored;
so are the number of lines and any other words.
"""
from __future__ import annotations

import math

import numpy as np

from ..jit import njit
from .records import ARC_CCW, DWELL, LINEAR, RAPID

OK, MISSING, EXTRA, KIND, TOOL, OFF_PATH, BACKWARDS, CENTER, OVERSHOOT, ROTARY = range(10)
_REASONS = {
    MISSING: "the optimised program ends before this move",
    EXTRA: "the optimised program has extra moves",
    KIND: "different kind of move (rapid/feed/arc/dwell)",
    TOOL: "different tool",
    OFF_PATH: "end point is not on the original path",
    BACKWARDS: "pieces go backwards along the original move",
    CENTER: "arc centre, plane or direction differs",
    OVERSHOOT: "piece runs past the end of the original move",
    ROTARY: "positions of the axes beyond X/Y/Z (A/B/C, U/V/W) differ",
}


@njit
def _param(kind, a1, a2, an, s, e, c, sweep, p):
    """Path fraction of point p on the move, and p's distance from the path there."""
    if kind == LINEAR or kind == RAPID or kind == DWELL:
        d0 = e[0] - s[0]
        d1 = e[1] - s[1]
        d2 = e[2] - s[2]
        ll = d0 * d0 + d1 * d1 + d2 * d2
        t = 0.0
        if ll > 0:
            t = ((p[0] - s[0]) * d0 + (p[1] - s[1]) * d1 + (p[2] - s[2]) * d2) / ll
        tc = min(max(t, 0.0), 1.0)
        dx = p[0] - (s[0] + tc * d0)
        dy = p[1] - (s[1] + tc * d1)
        dz = p[2] - (s[2] + tc * d2)
        return t, math.sqrt(dx * dx + dy * dy + dz * dz)
    r0 = math.hypot(s[a1] - c[a1], s[a2] - c[a2])
    r1 = math.hypot(e[a1] - c[a1], e[a2] - c[a2])
    t0 = math.atan2(s[a2] - c[a2], s[a1] - c[a1])
    tp = math.atan2(p[a2] - c[a2], p[a1] - c[a1])
    phi = (tp - t0) if kind == ARC_CCW else (t0 - tp)
    phi = phi % (2 * math.pi)
    t = phi / sweep
    zr = s[an] + t * (e[an] - s[an])
    # a tolerated radius mismatch makes the arc a spiral, radius linear in the angle
    dr = math.hypot(p[a1] - c[a1], p[a2] - c[a2]) - (r0 + min(max(t, 0.0), 1.0) * (r1 - r0))
    return t, math.hypot(dr, p[an] - zr)


@njit
def compare_kernel(ka, pa, sa, ea, ca, ta, sw_a, tool_a, kb, pb, sb, eb, cb, tb, tool_b, tol, abc_a, abc_b):
    na = ka.size
    nb = kb.size
    ib = 0
    for ia in range(na):
        k = ka[ia]
        pl = pa[ia]
        a1 = (0, 2, 1)[pl]
        a2 = (1, 0, 2)[pl]
        an = (2, 1, 0)[pl]
        t_prev = 0.0
        while True:
            if ib >= nb:
                return MISSING, ia, ib
            if kb[ib] != k:
                return KIND, ia, ib
            if tool_b[ib] != tool_a[ia]:
                return TOOL, ia, ib
            if k == 2 or k == 3:
                if pb[ib] != pl or math.hypot(cb[ib, a1] - ca[ia, a1], cb[ib, a2] - ca[ia, a2]) > tol:
                    return CENTER, ia, ib
            p = eb[ib]
            de = math.sqrt((p[0] - ea[ia, 0]) ** 2 + (p[1] - ea[ia, 1]) ** 2 + (p[2] - ea[ia, 2]) ** 2)
            if de <= tol and (k < 2 or tb[ib] <= ta[ia]):
                if (k == 2 or k == 3) and tb[ib] != ta[ia] and t_prev == 0.0:
                    return CENTER, ia, ib
                for q in range(6):
                    if abs(abc_b[ib, q] - abc_a[ia, q]) > tol:
                        return ROTARY, ia, ib
                ib += 1
                break
            # a piece short of the end: rotary axes still where the move started (the
            # writer never splits a move that turns one)
            for q in range(6):
                if abs(abc_b[ib, q] - (abc_a[ia - 1, q] if ia > 0 else 0.0)) > tol:
                    return ROTARY, ia, ib
            if k == DWELL:
                return OFF_PATH, ia, ib
            t, d = _param(k, a1, a2, an, sa[ia], ea[ia], ca[ia], sw_a[ia], p)
            if d > tol:
                return OFF_PATH, ia, ib
            if t < t_prev - 1e-12:
                return BACKWARDS, ia, ib
            if t > 1.0:
                return OVERSHOOT, ia, ib
            t_prev = t
            ib += 1
    if ib < nb:
        return EXTRA, na - 1, ib
    return OK, -1, -1


def _arrays(rec):
    s = np.ascontiguousarray(np.stack([rec["sx"], rec["sy"], rec["sz"]], 1))
    e = np.ascontiguousarray(np.stack([rec["x"], rec["y"], rec["z"]], 1))
    c = np.ascontiguousarray(np.stack([rec["cx"], rec["cy"], rec["cz"]], 1))
    return (rec["kind"].astype(np.int64), rec["plane"].astype(np.int64), s, e, c,
            rec["turns"].astype(np.int64), rec["tool"].astype(np.int64))


def compare(a, b, tol: float = 1e-3):
    """None if programs ``a`` and ``b`` sweep the same path within ``tol`` mm, else a message."""
    from .records import arc_sweep

    ra, rb = a.records, b.records
    ka, pa, sa, ea, ca, ta, tool_a = _arrays(ra)
    kb, pb, sb, eb, cb, tb, tool_b = _arrays(rb)
    sweep = arc_sweep(ra) if ra.size else np.zeros(0)
    extra = ("a", "b", "c", "u", "v", "w")
    abc_a = np.ascontiguousarray(np.stack([ra[k] for k in extra], 1)) if ra.size else np.zeros((0, 6))
    abc_b = np.ascontiguousarray(np.stack([rb[k] for k in extra], 1)) if rb.size else np.zeros((0, 6))
    code, ia, ib = compare_kernel(ka, pa, sa, ea, ca, ta, sweep, tool_a, kb, pb, sb, eb, cb, tb, tool_b, float(tol),
                                  abc_a, abc_b)
    if code == OK:
        return None
    la = int(ra["line"][ia]) if 0 <= ia < ra.size else 0
    lb = int(rb["line"][ib]) if 0 <= ib < rb.size else 0
    return Difference(a.path, la, b.path, lb, _REASONS[int(code)])


class Difference:
    """The first place where two programs' paths differ."""

    def __init__(self, path_a, line_a, path_b, line_b, reason):
        self.path_a, self.line_a, self.path_b, self.line_b, self.reason = path_a, line_a, path_b, line_b, reason

    def __str__(self):
        return f"{self.path_a}:{self.line_a} vs {self.path_b}:{self.line_b}: {self.reason}"

    def as_dict(self):
        return {"original_line": self.line_a, "optimised_line": self.line_b, "reason": self.reason}


def verify(original, optimised, tol: float = 1e-3, settings=None):
    """Load two programs (paths or bytes) and compare them; returns None or a :class:`Difference`."""
    from .interpreter import load_program

    a = load_program(original, settings)
    b = load_program(optimised, settings)
    return compare(a, b, tol)

