"""Fanuc corner chamfering and rounding: ``G01 X.. Y.. ,C c`` / ``,R r``.

The corner belongs to the block that carries the word: between its move and the next, a
chamfer whose ends lie ``c`` from the corner along both moves, or an arc of radius ``r``
tangent to both.  The two moves are shortened to meet it.  The interpreter marks the
record of such a block (``corner``: radius > 0, chamfer < 0); this pass inserts the corner
moves, as the control does at execution.  Supported between straight moves in the active
plane (the common case of hand-written programs); next to an arc, out of the plane, or
without a following feed move it is an error naming the line.
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


def _corner(rec: np.ndarray, i: int, path: str):
    value = float(rec["corner"][i])
    word = f",R{value:g}" if value > 0 else f",C{-value:g}"
    j = i + 1
    if j >= len(rec) or rec["kind"][j] not in (LINEAR, ARC_CW, ARC_CCW):
        raise _err(rec, i, path, f"corner {word}: the next move must be a G01/G02/G03 move")
    if rec["kind"][i] != LINEAR or rec["kind"][j] != LINEAR:
        raise _err(rec, i, path, f"corner {word} next to an arc is not supported (only between straight moves)")
    if rec["plane"][i] != rec["plane"][j]:
        raise _err(rec, i, path, f"corner {word}: the plane changes between the two moves")
    for f in ("ox", "oy", "oz", "rot", "tlo", "tox", "toy"):
        if rec[f][i] != rec[f][j]:
            raise _err(rec, i, path, f"corner {word}: the coordinate system changes between the two moves")
    a1, a2, an = PLANE_AXES[int(rec["plane"][i])]
    ka, kb, kn = _AX[a1], _AX[a2], _AX[an]
    s1 = np.array([rec["s" + ka][i], rec["s" + kb][i]])
    p = np.array([rec[ka][i], rec[kb][i]])
    e2 = np.array([rec[ka][j], rec[kb][j]])
    if abs(rec[kn][i] - rec["s" + kn][i]) > 1e-9 or abs(rec[kn][j] - rec["s" + kn][j]) > 1e-9:
        raise _err(rec, i, path, f"corner {word}: both moves must lie in the plane (no {kn.upper()} motion)")
    l1 = float(np.hypot(*(p - s1)))
    l2 = float(np.hypot(*(e2 - p)))
    if l1 <= 0.0 or l2 <= 0.0:
        raise _err(rec, i, path, f"corner {word}: a move of zero length has no corner")
    u1 = (p - s1) / l1
    u2 = (e2 - p) / l2
    cross = float(u1[0] * u2[1] - u1[1] * u2[0])
    dot = float(u1 @ u2)
    if abs(cross) < 1e-12 and dot > 0:
        return None  # straight on: no corner to round
    if abs(cross) < 1e-12:
        raise _err(rec, i, path, f"corner {word}: the path reverses, there is no corner to round")
    if value > 0:
        r = value
        t = r * math.tan(0.5 * math.atan2(abs(cross), dot))  # tangent length
    else:
        t = -value
    if t > l1 + 1e-9 or t > l2 + 1e-9:
        raise _err(rec, i, path, f"corner {word} is too large for the moves it joins (needs {t:.4f} mm along "
                                 f"each, they are {l1:.4f} and {l2:.4f} mm long)")
    t1 = p - t * u1
    t2 = p + t * u2
    c = rec[i:i + 1].copy()
    c["flags"] = (c["flags"] & ~np.uint32(FL_FIRST_IN_LINE)) | FL_CORNER
    c["turns"] = 0
    c["s" + ka], c["s" + kb] = t1
    c[ka], c[kb] = t2
    c["corner"] = 0.0
    if value > 0:
        left = np.array([-u1[1], u1[0]])
        centre = t1 + (r if cross > 0 else -r) * left
        c["kind"] = ARC_CCW if cross > 0 else ARC_CW
        c["c" + ka], c["c" + kb] = centre
        c["c" + kn] = rec[kn][i]
    else:
        c["kind"] = LINEAR
        c["c" + ka], c["c" + kb] = t2
    # the two moves now end and start at the corner's ends
    rec[ka][i], rec[kb][i] = t1
    rec["c" + ka][i], rec["c" + kb][i] = t1
    rec["flags"][i] |= FL_CORNER
    rec["s" + ka][j], rec["s" + kb][j] = t2
    rec["flags"][j] |= FL_CORNER
    return c
