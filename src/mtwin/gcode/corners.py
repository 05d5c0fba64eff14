"""Fanuc corner chamfering and rounding: ``G01 X.. Y.. ,C c`` / ``,R r``.

The corner belongs to the block that carries the word: between its move and the next, a
chamfer whose ends lie ``c`` from the corner along both moves, or an arc of radius ``r``
tangent to both.  The two moves are shortened to meet it.  The interpreter marks the
record of such a block (``corner``: radius > 0, chamfer < 0); this pass inserts the corner
moves, as the control does at execution.  Between lines and arcs in the active plane: the
rounding arc's centre is where the two moves, offset by r to the inside of the turn, meet;
a chamfer next to an arc ends on the arc at chord distance c from the corner.  Out of the
plane, too large for its moves, or without a following feed move it is an error naming the
line.
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import GCodeError, SourceLocation
from .records import ARC_CCW, ARC_CW, FL_CORNER, FL_FIRST_IN_LINE, LINEAR, PLANE_AXES

_AX = "xyz"


def apply(rec: np.ndarray, path: str) -> np.ndarray:
    """Records with the corners inserted (a new array)."""
    rec = rec.copy()
    marks = np.flatnonzero(rec["corner"] != 0.0)
    pieces = []
    last = 0
    for i in marks:
        corner = _corner(rec, int(i), path)
        pieces.append(rec[last:i + 1])
        if corner is not None:
            pieces.append(corner)
        last = i + 1
    pieces.append(rec[last:])
    return np.concatenate(pieces)


def _err(rec, i, path, msg):
    return GCodeError(msg, SourceLocation(path, int(rec["line"][i]), 1))


class _Curve:
    """One move in the plane: a line s->e or an arc about c (ccw), as 2-D points."""

    def __init__(self, rec, i, ka, kb):
        self.s = np.array([rec["s" + ka][i], rec["s" + kb][i]])
        self.e = np.array([rec[ka][i], rec[kb][i]])
        self.arc = rec["kind"][i] in (ARC_CW, ARC_CCW)
        self.ccw = rec["kind"][i] == ARC_CCW
        self.c = np.array([rec["c" + ka][i], rec["c" + kb][i]])
        self.r = float(np.hypot(*(self.s - self.c))) if self.arc else 0.0
        self.turns = int(rec["turns"][i])

    def tangent(self, at_end: bool) -> np.ndarray:
        if not self.arc:
            d = self.e - self.s
            return d / np.hypot(*d)
        p = self.e if at_end else self.s
        v = (p - self.c) / self.r
        return np.array([-v[1], v[0]]) if self.ccw else np.array([v[1], -v[0]])

    def length(self) -> float:
        if not self.arc:
            return float(np.hypot(*(self.e - self.s)))
        return self.r * self._sweep_to(self.e)

    def _sweep_to(self, p) -> float:
        a0 = math.atan2(self.s[1] - self.c[1], self.s[0] - self.c[0])
        a1 = math.atan2(p[1] - self.c[1], p[0] - self.c[0])
        d = (a1 - a0) if self.ccw else (a0 - a1)
        d %= 2 * math.pi
        if d < 1e-12 and p is self.e:
            d = 2 * math.pi
        return d

    def offset_side(self, left: bool):
        """How the curve moves when offset to the left (or right) of travel: for a line its
        unit normal toward that side, for an arc the change of radius per unit offset (+1
        away from the centre, -1 toward it)."""
        if not self.arc:
            t = self.tangent(False)
            n = np.array([-t[1], t[0]]) if left else np.array([t[1], -t[0]])
            return n
        # the centre of a ccw arc is on its left
        return -1.0 if left == self.ccw else 1.0

    def contains(self, p) -> bool:
        """Is p (a point on the curve's line or circle) on the move itself?"""
        if not self.arc:
            d = self.e - self.s
            t = float(np.dot(p - self.s, d) / np.dot(d, d))
            return -1e-9 <= t <= 1 + 1e-9
        return self._sweep_to(p) * self.r <= self.length() + 1e-9


def _meet_lines(p1, n1, p2, n2):
    """Intersection of the lines through p1 (normal n1) and p2 (normal n2)."""
    a = np.array([n1, n2])
    det = float(np.linalg.det(a))
    if abs(det) < 1e-15:
        return []
    return [np.linalg.solve(a, np.array([n1 @ p1, n2 @ p2]))]


def _meet_line_circle(p, n, c, r):
    """Points x with n.(x - p) = 0 and |x - c| = r."""
    t = np.array([n[1], -n[0]])
    n = n / np.hypot(*n)
    t = np.array([n[1], -n[0]])
    foot = c + n * float(n @ (p - c))  # c's projection on the line
    d = float(np.hypot(*(foot - c)))
    if d > r + 1e-12:
        return []
    h = math.sqrt(max(r * r - d * d, 0.0))
    return [foot + h * t, foot - h * t]


def _meet_circles(c1, r1, c2, r2):
    d = float(np.hypot(*(c2 - c1)))
    if d < 1e-15 or d > r1 + r2 + 1e-12 or d < abs(r1 - r2) - 1e-12:
        return []
    a = (r1 * r1 - r2 * r2 + d * d) / (2 * d)
    h = math.sqrt(max(r1 * r1 - a * a, 0.0))
    u = (c2 - c1) / d
    m = c1 + a * u
    v = np.array([-u[1], u[0]])
    return [m + h * v, m - h * v]


def _on_curve(cv: _Curve, x) -> np.ndarray:
    """The point of cv's line or circle nearest x."""
    if not cv.arc:
        d = cv.e - cv.s
        return cv.s + d * float(np.dot(x - cv.s, d) / np.dot(d, d))
    v = x - cv.c
    return cv.c + cv.r * v / np.hypot(*v)


def _corner(rec: np.ndarray, i: int, path: str):
    value = float(rec["corner"][i])
    word = f",R{value:g}" if value > 0 else f",C{-value:g}"
    j = i + 1
    if j >= len(rec) or rec["kind"][j] not in (LINEAR, ARC_CW, ARC_CCW):
        raise _err(rec, i, path, f"corner {word}: the next move must be a G01/G02/G03 move")
    if rec["plane"][i] != rec["plane"][j]:
        raise _err(rec, i, path, f"corner {word}: the plane changes between the two moves")
    for f in ("ox", "oy", "oz", "rot", "tlo", "tox", "toy"):
        if rec[f][i] != rec[f][j]:
            raise _err(rec, i, path, f"corner {word}: the coordinate system changes between the two moves")
    if rec["turns"][i] or rec["turns"][j]:
        raise _err(rec, i, path, f"corner {word}: not next to an arc of several turns")
    a1, a2, an = PLANE_AXES[int(rec["plane"][i])]
    ka, kb, kn = _AX[a1], _AX[a2], _AX[an]
    if abs(rec[kn][i] - rec["s" + kn][i]) > 1e-9 or abs(rec[kn][j] - rec["s" + kn][j]) > 1e-9:
        raise _err(rec, i, path, f"corner {word}: both moves must lie in the plane (no {kn.upper()} motion)")
    m1, m2 = _Curve(rec, i, ka, kb), _Curve(rec, j, ka, kb)
    p = m1.e
    if m1.length() <= 0.0 or m2.length() <= 0.0:
        raise _err(rec, i, path, f"corner {word}: a move of zero length has no corner")
    u1, u2 = m1.tangent(True), m2.tangent(False)
    cross = float(u1[0] * u2[1] - u1[1] * u2[0])
    dot = float(u1 @ u2)
    if abs(cross) < 1e-9 and dot > 0:
        return None  # the moves meet tangentially: no corner to round
    if abs(cross) < 1e-9:
        raise _err(rec, i, path, f"corner {word}: the path reverses, there is no corner to round")
    left = cross > 0  # the corner turns left: what is cut off lies on the left of both moves
    if value > 0:
        r = value
        # the fillet's centre is r from both moves, on the inside of the turn
        o1, o2 = m1.offset_side(left), m2.offset_side(left)
        if not m1.arc and not m2.arc:
            cands = _meet_lines(m1.e + r * o1, o1, m2.s + r * o2, o2)
        elif not m1.arc:
            cands = _meet_line_circle(m1.e + r * o1, o1, m2.c, m2.r + o2 * r)
        elif not m2.arc:
            cands = _meet_line_circle(m2.s + r * o2, o2, m1.c, m1.r + o1 * r)
        else:
            cands = _meet_circles(m1.c, m1.r + o1 * r, m2.c, m2.r + o2 * r)
        if not cands:
            raise _err(rec, i, path, f"corner {word} does not fit between the two moves")
        centre = min(cands, key=lambda q: float(np.hypot(*(q - p))))
        t1, t2 = _on_curve(m1, centre), _on_curve(m2, centre)
    else:
        c = -value
        if not m1.arc:
            t1 = p - c * u1
        else:
            cands = _meet_circles(m1.c, m1.r, p, c)
            t1 = min(cands, key=lambda q: float(np.dot(q - p, u1))) if cands else None  # behind the corner
        if not m2.arc:
            t2 = p + c * u2
        else:
            cands = _meet_circles(m2.c, m2.r, p, c)
            t2 = max(cands, key=lambda q: float(np.dot(q - p, u2))) if cands else None  # ahead of it
        if t1 is None or t2 is None:
            raise _err(rec, i, path, f"corner {word} does not fit between the two moves")
    # both ends of the corner must lie on the moves themselves, not on their extensions
    back = _Curve(rec, i, ka, kb)
    back.s, back.e = m1.e, m1.s  # the first move walked backwards from the corner
    back.ccw = not m1.ccw
    if not back.contains(t1) or not m2.contains(t2):
        raise _err(rec, i, path, f"corner {word} is too large for the moves it joins")
    c_rec = rec[i:i + 1].copy()
    c_rec["flags"] = (c_rec["flags"] & ~np.uint32(FL_FIRST_IN_LINE)) | FL_CORNER
    c_rec["turns"] = 0
    c_rec["s" + ka], c_rec["s" + kb] = t1
    c_rec[ka], c_rec[kb] = t2
    c_rec["corner"] = 0.0
    if value > 0:
        c_rec["kind"] = ARC_CCW if left else ARC_CW
        c_rec["c" + ka], c_rec["c" + kb] = centre
        c_rec["c" + kn] = rec[kn][i]
    else:
        c_rec["kind"] = LINEAR
        c_rec["c" + ka], c_rec["c" + kb] = t2
    # the two moves now end and start at the corner's ends (an arc keeps its centre)
    rec[ka][i], rec[kb][i] = t1
    if not m1.arc:
        rec["c" + ka][i], rec["c" + kb][i] = t1
    rec["flags"][i] |= FL_CORNER
    rec["s" + ka][j], rec["s" + kb][j] = t2
    rec["flags"][j] |= FL_CORNER
    return c_rec
