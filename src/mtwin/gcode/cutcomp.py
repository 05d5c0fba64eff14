"""Cutter radius compensation (G41/G42 in G17, G18, G19): the tool centre path from the programmed contour.

The interpreter marks every record with its compensation side and radius; this pass turns
runs of compensated moves into the path of the tool centre, the way a control does:

* every line is moved sideways by the radius (left of the direction of travel for G41,
  right for G42); every arc keeps its centre and grows or shrinks by the radius;
* at a corner where the moved elements separate (an outside corner) an arc of the tool
  radius around the programmed corner joins them; where they cross (an inside corner)
  both are cut back to the crossing;
* the first move after G41/G42 (entry) starts at the uncompensated position, and the move
  with G40 (exit) ends at the programmed point; moves without XY motion (Z plunges)
  keep the compensated XY position.

A radius larger than an arc it must follow inside, or an inside corner whose elements do
not cross, is a gouge: an error naming the line.  Records whose geometry changed carry
``FL_COMP``; corner arcs are new records with the line of the move they lead into.
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import GCodeError, SourceLocation
from .records import ARC_CCW, ARC_CW, DWELL, FL_COMP, LINEAR, RAPID

_EPS = 1e-9
_SMALL = 0.05  # rad: corners turning less than this are straight on (RS274NGC's threshold)


def _unit(v):
    n = math.hypot(v[0], v[1])
    return (v[0] / n, v[1] / n) if n > 0 else (0.0, 0.0)


class _El:
    """One XY element of the programmed contour: line or arc (with its record index)."""

    def __init__(self, rec, i):
        r = rec[i]
        self.i = i
        self.kind = int(r["kind"])
        self.s = (float(r["sx"]), float(r["sy"]))
        self.e = (float(r["x"]), float(r["y"]))
        self.c = (float(r["cx"]), float(r["cy"]))
        self.arc = self.kind in (ARC_CW, ARC_CCW)
        self.ccw = self.kind == ARC_CCW
        self.R = math.hypot(self.s[0] - self.c[0], self.s[1] - self.c[1]) if self.arc else 0.0

    def tangent(self, at_end: bool):
        if not self.arc:
            return _unit((self.e[0] - self.s[0], self.e[1] - self.s[1]))
        p = self.e if at_end else self.s
        rx, ry = p[0] - self.c[0], p[1] - self.c[1]
        return _unit((-ry, rx) if self.ccw else (ry, -rx))


def _sweep_to(el, p):
    """Angle travelled along arc ``el`` from its start to the direction of point p (0..2π)."""
    a0 = math.atan2(el.s[1] - el.c[1], el.s[0] - el.c[0])
    a1 = math.atan2(p[1] - el.c[1], p[0] - el.c[0])
    d = (a1 - a0) if el.ccw else (a0 - a1)
    return d % (2 * math.pi)


def _param(o, p):
    """Position of p along offset element o: 0 at its start, 1 at its end."""
    if not o.el.arc:
        d = (o.e[0] - o.s[0], o.e[1] - o.s[1])
        dd = d[0] ** 2 + d[1] ** 2
        return ((p[0] - o.s[0]) * d[0] + (p[1] - o.s[1]) * d[1]) / dd if dd > 0 else 0.0
    total = _sweep_to(o.el, o.el.e) or 2 * math.pi
    return _sweep_to(o.el, p) / total


def _tool_inside(el, side: int) -> bool:
    """The tool runs inside arc ``el`` (G41 on a CCW arc, G42 on a CW one)."""
    return el.arc and ((side == 1) == el.ccw)


def _left(t):
    return (-t[1], t[0])


class _Off:
    """The offset of an element: moved line, or concentric arc, with adjustable ends."""

    def __init__(self, el: _El, side: int, r: float, path: str, line: int):
        self.el = el
        sgn = 1.0 if side == 1 else -1.0  # G41 left, G42 right
        if not el.arc:
            n = _left(el.tangent(False))
            self.s = (el.s[0] + sgn * r * n[0], el.s[1] + sgn * r * n[1])
            self.e = (el.e[0] + sgn * r * n[0], el.e[1] + sgn * r * n[1])
            self.R = 0.0
        else:
            # the centre is on the left of a CCW arc: G41 moves the tool towards it
            toward = (sgn > 0) == el.ccw
            self.R = el.R - r if toward else el.R + r
            if self.R < -1e-7:
                raise GCodeError(f"cutter compensation: the tool radius {r:.4f} mm does not fit inside the arc of "
                                 f"radius {el.R:.4f} mm (gouge)", SourceLocation(path, line, 1))
            self.R = max(self.R, 0.0)  # a tool exactly the arc's size stands at its centre
            self.s = self._on(el.s)
            self.e = self._on(el.e)

    def _on(self, p):
        c = self.el.c
        u = _unit((p[0] - c[0], p[1] - c[1]))
        return (c[0] + self.R * u[0], c[1] + self.R * u[1])


def _intersect(a: _Off, b: _Off, corner):
    """Crossing of two offset elements nearest the programmed corner, or None."""
    cands = []
    if not a.el.arc and not b.el.arc:
        d1 = (a.e[0] - a.s[0], a.e[1] - a.s[1])
        d2 = (b.e[0] - b.s[0], b.e[1] - b.s[1])
        den = d1[0] * d2[1] - d1[1] * d2[0]
        if abs(den) < 1e-15:
            return None
        t = ((b.s[0] - a.s[0]) * d2[1] - (b.s[1] - a.s[1]) * d2[0]) / den
        cands.append((a.s[0] + t * d1[0], a.s[1] + t * d1[1]))
    elif a.el.arc and b.el.arc:
        cands = _circle_circle(a.el.c, a.R, b.el.c, b.R)
    else:
        line, arc = (a, b) if not a.el.arc else (b, a)
        cands = _line_circle(line.s, line.e, arc.el.c, arc.R)
    if not cands:
        return None
    # a crossing the first element reaches before its end and the second after its start
    good = [p for p in cands if _param(a, p) <= 1 + 1e-9 and _param(b, p) >= -1e-9]
    return min(good or cands, key=lambda p: (p[0] - corner[0]) ** 2 + (p[1] - corner[1]) ** 2)


def _line_circle(p, q, c, R):
    d = (q[0] - p[0], q[1] - p[1])
    f = (p[0] - c[0], p[1] - c[1])
    A = d[0] ** 2 + d[1] ** 2
    B = 2 * (f[0] * d[0] + f[1] * d[1])
    C = f[0] ** 2 + f[1] ** 2 - R * R
    disc = B * B - 4 * A * C
    if A == 0 or disc < -1e-9 * B * B:
        return []
    disc = max(disc, 0.0)  # a tangent line touches once
    sq = math.sqrt(disc)
    return [(p[0] + t * d[0], p[1] + t * d[1]) for t in ((-B - sq) / (2 * A), (-B + sq) / (2 * A))]


def _circle_circle(c1, r1, c2, r2):
    dx, dy = c2[0] - c1[0], c2[1] - c1[1]
    d = math.hypot(dx, dy)
    if d == 0 or d > r1 + r2 or d < abs(r1 - r2):
        return []
    a = (r1 * r1 - r2 * r2 + d * d) / (2 * d)
    h = math.sqrt(max(0.0, r1 * r1 - a * a))
    mx, my = c1[0] + a * dx / d, c1[1] + a * dy / d
    return [(mx + h * dy / d, my - h * dx / d), (mx - h * dy / d, my + h * dx / d)]


def apply(rec: np.ndarray, path: str) -> np.ndarray:
    """Records with cutter compensation applied (a new array when anything changes)."""
    comp = rec["comp"]
    if not ((comp != 0) & (rec["comp_r"] > 0)).any():
        return rec
    out = []
    n = len(rec)
    i = 0
    while i < n:
        if comp[i] == 0 or rec["comp_r"][i] <= 0:
            out.append(rec[i:i + 1].copy())
            i += 1
            continue
        j = i
        side, r = int(comp[i]), float(rec["comp_r"][i])
        while j < n and comp[j] == side and rec["comp_r"][j] == r:
            j += 1
        planes = rec["plane"][i:j]
        if (planes != planes[0]).any():
            k = i + int(np.argmax(planes != planes[0]))
            raise GCodeError("cutter compensation: the plane (G17/G18/G19) cannot change while it is on",
                             SourceLocation(path, int(rec["line"][k]), 1))
        pl = int(planes[0])
        # G18/G19: compensate in the plane's own axes (first, second, normal), then map back
        block = _unpermute(_run(_permute(rec[i:j + 1], pl), 0, j - i, side, r, path), pl)
        _lathe_origin(block, pl, int(rec["comp_orient"][i]), r)
        out.append(block)
        if j < n:
            # the exit move (G40, or a change of side/radius) starts where the tool is
            if rec["kind"][j] in (ARC_CW, ARC_CCW):
                raise GCodeError("cutter compensation: the move that turns it off (G40) must be a straight line, "
                                 "not an arc", SourceLocation(path, int(rec["line"][j]), 1))
            nxt = rec[j:j + 1].copy()
            for ax in _AXES[pl][:2]:
                nxt["s" + ax] = block[ax][-1]
            nxt["flags"] |= FL_COMP
            out.append(nxt)
            i = j + 1
        else:
            i = j
    # inverse-time feeds (G93) keep the feed per minute of the programmed move, as LinuxCNC
    return np.concatenate(out)


def _lathe_origin(block: np.ndarray, plane: int, orient: int, r: float):
    """A lathe tool (orientation 1-8, XZ plane) is programmed at its imaginary tip, not at
    the centre of its nose radius that compensation steers: shift the compensated path by
    the radius along X and/or Z (the first start stays where the tool was)."""
    if plane != 1 or orient in (0, 9) or r <= 0.0:
        return
    dx = -r if orient in (1, 2, 6) else (r if orient in (3, 4, 8) else 0.0)
    dz = -r if orient in (2, 3, 7) else (r if orient in (1, 4, 5) else 0.0)
    block["x"] += dx
    block["z"] += dz
    arc = (block["kind"] == ARC_CW) | (block["kind"] == ARC_CCW)
    block["cx"][arc] += dx
    block["cz"][arc] += dz
    block["sx"][1:] += dx
    block["sz"][1:] += dz


# record columns of each plane's (first, second, normal) axis: G17 XY, G18 ZX, G19 YZ
_AXES = ("xyz", "zxy", "yzx")


def _permute(rec: np.ndarray, plane: int) -> np.ndarray:
    """A copy whose x, y, z columns hold the plane's first, second and normal axes."""
    out = rec.copy()
    if plane == 0:
        return out
    for pre in ("s", "", "c"):
        for dst, src in zip("xyz", _AXES[plane]):
            out[pre + dst] = rec[pre + src]
    return out


def _unpermute(rec: np.ndarray, plane: int) -> np.ndarray:
    if plane == 0:
        return rec
    out = rec.copy()
    for pre in ("s", "", "c"):
        for src, dst in zip("xyz", _AXES[plane]):
            out[pre + dst] = rec[pre + src]
    return out


def _run(rec, i0, i1, side, r, path):
    """Compensate records i0..i1-1 (one side, one radius); i1 (if any) is the exit move."""
    block = rec[i0:i1].copy()
    # XY elements with real XY motion; others (plunges, dwells) just follow
    xy = [k for k in range(len(block))
          if block["kind"][k] in (LINEAR, RAPID, ARC_CW, ARC_CCW)
          and (block["kind"][k] in (ARC_CW, ARC_CCW)
               or math.hypot(block["x"][k] - block["sx"][k], block["y"][k] - block["sy"][k]) > _EPS)]
    if not xy:
        return block
    els = [_El(block, k) for k in xy]
    offs = [_Off(e, side, r, path, int(block["line"][e.i])) for e in els]
    inserts = {}  # block index -> corner arc record placed before it
    # the entry move ends a tool radius to the side of its programmed end point, square to the
    # move (or where the parallel offset meets the next element), and starts where the tool is
    first = offs[0]
    if first.el.arc:
        raise GCodeError("cutter compensation: the first move after G41/G42 (the entry move) must be a line",
                         SourceLocation(path, int(block["line"][first.el.i]), 1))
    S, P = first.el.s, first.el.e
    d = math.hypot(P[0] - S[0], P[1] - S[1])
    if d <= r + _EPS:
        raise GCodeError(f"cutter compensation: the entry move ({d:.4f} mm) must be longer than the tool radius "
                         f"({r:.4f} mm)", SourceLocation(path, int(block["line"][first.el.i]), 1))
    for a, b in zip(offs[:-1], offs[1:]):
        corner = a.el.e
        # the corner is classified on the programmed path, as RS274NGC does
        t1, t2 = a.el.tangent(True), b.el.tangent(False)
        turn = math.atan2(t1[0] * t2[1] - t1[1] * t2[0], t1[0] * t2[0] + t1[1] * t2[1])
        # RS274NGC's corner angle: how far the new element turns away from the tool's side
        # (0 straight on, > 0 away from the tool: convex, < 0 towards it: concave), in
        # [-pi/2, 3pi/2), with LinuxCNC's 0.05 rad threshold
        bb = -turn if side == 1 else turn
        if bb >= 1.5 * math.pi:
            bb -= 2 * math.pi
        elif bb < -0.5 * math.pi:
            bb += 2 * math.pi
        concave = (bb < -_SMALL or bb > math.pi + _SMALL
                   # (almost) doubling back with the tool outside an arc: the offsets cross
                   # (LinuxCNC's "m" and "h" shapes: the tool stays on the outside)
                   or (b.el.arc and abs(bb - math.pi) < _SMALL and not _tool_inside(b.el, side))
                   or (not b.el.arc and a.el.arc and bb > math.pi - _SMALL and not _tool_inside(a.el, side)))
        if not concave and bb <= _SMALL:
            # (nearly) straight on: the new element starts where the tool is, no corner arc
            b.s = a.e
            continue
        if concave:
            p = _intersect(a, b, corner)
            if p is None:
                raise GCodeError("cutter compensation: the compensated moves do not meet at this inside corner "
                                 "(the tool radius is too large here: gouge)",
                                 SourceLocation(path, int(block["line"][b.el.i]), 1))
            a.e = p
            b.s = p
        else:
            inserts[b.el.i] = (a.e, b.s, corner)
    # write back; a line cut back past its own start is a gouge
    entry_start = S
    for o in offs:
        k = o.el.i
        if o.el.arc and o.R <= 1e-7:
            block["kind"][k] = LINEAR  # an arc shrunk to its centre: no motion
            block["turns"][k] = 0
        if not o.el.arc:
            d0 = (o.el.e[0] - o.el.s[0], o.el.e[1] - o.el.s[1])
            d1 = (o.e[0] - o.s[0], o.e[1] - o.s[1])
            if d0[0] * d1[0] + d0[1] * d1[1] < -_EPS:
                raise GCodeError("cutter compensation: this move is shorter than the tool radius needs at its "
                                 "corners (gouge)", SourceLocation(path, int(block["line"][k]), 1))
        if o is first:
            o.s = entry_start
        block["sx"][k], block["sy"][k] = o.s
        block["x"][k], block["y"][k] = o.e
        block["flags"][k] |= FL_COMP
    # non-XY records between elements stand at the compensated XY position
    pos = None
    for k in range(len(block)):
        if k in xy:
            pos = (block["x"][k], block["y"][k])
        elif pos is not None and block["kind"][k] != DWELL:
            block["sx"][k], block["sy"][k] = pos
            block["x"][k], block["y"][k] = pos
            block["flags"][k] |= FL_COMP
        elif pos is not None:
            block["sx"][k], block["sy"][k] = pos
            block["x"][k], block["y"][k] = pos
    rows = []
    for k in range(len(block)):
        if k in inserts:
            s, e, corner = inserts[k]
            arc = block[k:k + 1].copy()
            arc["kind"] = ARC_CCW if side == 2 else ARC_CW  # around the corner, away from the part
            arc["sx"], arc["sy"] = s
            arc["x"], arc["y"] = e
            arc["sz"] = block["sz"][k]
            arc["z"] = block["sz"][k]
            arc["cx"], arc["cy"] = corner
            arc["cz"] = block["sz"][k]
            arc["turns"] = 0
            arc["flags"] = block["flags"][k] | FL_COMP
            if arc["kind"][0] != RAPID and block["kind"][k] == RAPID:
                arc["kind"] = block["kind"][k]  # rapids corner with a straight hop
            rows.append(arc)
        rows.append(block[k:k + 1])
    return np.concatenate(rows)
