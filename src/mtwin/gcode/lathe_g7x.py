"""LinuxCNC's lathe profile cycles G70 (finishing), G71/G72 (roughing along Z / along X).

The profile is the body of an O-word subroutine named by Q, read in the XZ plane.  The
cycle offsets it by the stock allowance, turns it so that it always falls toward -Z and
-X (``flip``: mirrored in Z and/or X, turned by 90 degrees for G72), then cuts it: G71/G72
in passes ``I`` apart that run toward the profile and retract by ``R`` at 45 degrees, each
pocket the profile dips into in turn (G7x.1: no pockets, G7x.2: only the pockets), G70 in
``P`` passes from distance ``D`` to ``E``.  Moves are produced in the turned frame and
mapped back.

The rules follow LinuxCNC's interpreter (src/emc/rs274ngc/interp_g7x.cc, the version
whose traces are in LinuxCNC's own test suite, with its later rule that a profile line
without a motion code is a feed line) move for move, so that a program reads here as it
does on that control; they are written afresh (complex numbers: real part Z, imaginary
part X), and checked against those traces.  Corners may carry a fillet (``A``) or chamfer
(``C``) of the given size; ``U``/``W`` in the profile are incremental X/Z.
"""
from __future__ import annotations

import copy
import math

TOL = 1e-6


class G7xError(Exception):
    pass


def _conj(z: complex) -> complex:
    return z.conjugate()


def _norm(z: complex) -> float:
    return z.real * z.real + z.imag * z.imag


class _Out:
    """Collects moves as ("G0"|"G1", end) and ("G2"|"G3", end, centre), in program units."""

    def __init__(self, start: complex):
        self.moves: list = []
        self.here = start  # the cycle only skips an arc that goes nowhere

    def rapid(self, p: complex):
        self.moves.append(("G0", p))
        self.here = p

    def feed(self, p: complex):
        self.moves.append(("G1", p))
        self.here = p

    def arc(self, ccw: bool, c: complex, p: complex):
        # an arc that ends where the tool is goes nowhere (LinuxCNC compares each axis within
        # its TOLERANCE_EQUAL, 1e-4 in program units)
        if abs(p.real - self.here.real) < 1e-4 and abs(p.imag - self.here.imag) < 1e-4:
            return
        self.moves.append(("G3" if ccw else "G2", p, c))
        self.here = p


class _Mapped:
    """Maps moves of the turned/mirrored frame back to the program's frame."""

    def __init__(self, out: _Out, state: int):
        self.out = out
        self.state = state

    def _map(self, p: complex) -> complex:
        s = self.state
        if s == 0:
            return p
        if s == 1:
            return -_conj(p)
        if s == 2:
            return _conj(p)
        if s == 3:
            return -p
        if s == 4:
            return 1j * p
        if s == 5:
            return _conj(1j * p)
        if s == 6:
            return -_conj(1j * p)
        return -1j * p

    def rapid(self, p):
        self.out.rapid(self._map(p))

    def feed(self, p):
        self.out.feed(self._map(p))

    def arc(self, ccw, c, p):
        mirrored = self.state in (1, 2, 5, 6)
        self.out.arc(ccw != mirrored, self._map(c), self._map(p))


# ------------------------------------------------------------------ segments
class Line:
    finish = 0.0

    def __init__(self, s: complex, e: complex):
        self.s = s
        self.e = e

    def dup(self):
        return copy.copy(self)

    def radius(self) -> float:
        return abs(self.s - self.e)

    def monotonic(self) -> bool:
        return (self.e - self.s).real <= 1e-3

    def flip_imag(self):
        self.s, self.e = _conj(self.s), _conj(self.e)

    def flip_real(self):
        self.s, self.e = -_conj(self.s), -_conj(self.e)

    def rotate(self):
        self.s, self.e = -1j * self.s, -1j * self.e

    def move(self, d: complex):
        self.s += d
        self.e += d

    def offset(self, dist: float):
        d = 1j * dist * (self.s - self.e) / abs(self.s - self.e)
        self.s += d
        self.e += d

    def draw(self, out):
        out.feed(self.e)

    def do_finish(self, prev, nxt):
        pass

    def crossings(self, x: float) -> list:
        """Z of the points at height X (both ends of a level line)."""
        s, e = self.s, self.e
        if min(s.imag, e.imag) > x + TOL or max(s.imag, e.imag) < x - TOL:
            return []
        if abs((s - e).imag) < TOL:
            return [s.real, e.real]
        return [(x - s.imag) / (e.imag - s.imag) * (e.real - s.real) + s.real]

    def climb(self, loc, out):
        if self.e.imag + TOL < self.s.imag:
            return True, loc  # not climbing
        if abs(loc - self.s) > TOL:
            raise G7xError("How did we get here?")
        out.feed(self.e)
        return False, self.e

    def climb_only(self, loc, out):
        if self.e.imag < self.s.imag:
            return loc
        zs = self.crossings(loc.imag)
        if not zs:
            return loc
        loc = complex(zs[0], loc.imag)
        out.feed(loc)
        out.feed(self.e)
        return self.e

    def dive(self, loc, x, out, fast):
        if self.s.imag <= self.e.imag + TOL:
            return True, loc  # not diving
        go = out.rapid if fast else out.feed
        if x < self.e.imag:
            go(self.e)
            return False, self.e
        zs = self.crossings(x)
        if not zs:
            raise G7xError("x too large in straight dive")
        ep = complex(zs[0], x)
        go(ep)
        return False, ep


class Arc(Line):
    def __init__(self, ccw: bool, s: complex, c: complex, e: complex):
        super().__init__(s, e)
        self.ccw = bool(ccw)
        self.c = c

    def radius(self) -> float:
        return min(abs(self.s - self.e), abs(self.s - self.c))

    def monotonic(self) -> bool:
        if self.finish != 0:
            return True
        entry = (self.s - self.c).imag
        leave = (self.e - self.c).imag
        dz = (self.e - self.s).real
        if self.ccw:
            return entry >= -1e-3 and leave >= -1e-3 and dz <= -1e-3
        return entry <= 1e-3 and leave <= 1e-3 and dz <= -1e-3

    def flip_imag(self):
        super().flip_imag()
        self.c = _conj(self.c)
        self.ccw = not self.ccw

    def flip_real(self):
        super().flip_real()
        self.c = -_conj(self.c)
        self.ccw = not self.ccw

    def rotate(self):
        super().rotate()
        self.c = -1j * self.c

    def move(self, d):
        super().move(d)
        self.c += d

    def offset(self, dist):
        r = abs(self.s - self.c)
        f = (r + (1 if self.ccw else -1) * dist) / r
        self.s = f * (self.s - self.c) + self.c
        self.e = f * (self.e - self.c) + self.c

    def draw(self, out):
        out.arc(self.ccw, self.c, self.e)

    def _on(self, p: complex) -> bool:
        a = (_conj(self.s - self.c) * (p - self.c)).imag
        b = (_conj(self.e - self.c) * (p - self.c)).imag
        if self.ccw:
            return a >= -TOL and b <= TOL
        return a <= TOL and b >= -TOL

    def crossings(self, x):
        r = abs(self.s - self.c)
        c = self.c
        q = -(x - r - c.imag) * (x + r - c.imag)
        if q < -TOL:
            return []
        q = math.sqrt(max(q, 0.0))
        out = []
        for z in (c.real + q, c.real - q):
            if self._on(complex(z, x)):
                out.append(z)
        return out

    def climb(self, loc, out):
        c = self.c
        if not self.ccw:
            if loc.real > c.real:
                return True, loc
            if abs(loc - self.e) > 1e-3:
                out.arc(False, c, self.e)
            return False, self.e
        if loc.real < c.real:
            return True, loc
        ep = self.e
        if self.e.real < c.real:
            ep = complex(c.real, c.imag + abs(self.s - c))
        if abs(loc - ep) > 1e-3:
            out.arc(True, c, ep)
        return True, ep

    def climb_only(self, loc, out):
        zs = self.crossings(loc.imag)
        if not zs:
            return loc
        c = self.c
        if not self.ccw:
            if zs[-1] > c.real:
                return loc
            loc = complex(zs[-1], loc.imag)
            out.feed(loc)
            if abs(loc - self.e) > 1e-3:
                out.arc(False, c, self.e)
            return self.e
        if zs[0] < c.real:
            return loc
        loc = complex(zs[0], loc.imag)
        out.feed(loc)
        ep = self.e
        if self.e.real < c.real:
            ep = complex(c.real, c.imag + abs(self.s - c))
        if abs(loc - ep) > 1e-3:
            out.arc(True, c, ep)
        return ep

    def dive(self, loc, x, out, fast):
        if abs(loc - self.e) < TOL or (loc - self.e).real <= TOL:
            return False, self.e
        zs = self.crossings(x) or self.crossings(x - TOL)
        c = self.c
        if self.ccw:
            if loc.real - TOL > c.real:
                return True, loc
            if not zs or zs[-1] > c.real:
                out.arc(True, c, self.e)
                return False, self.e
            ep = complex(zs[-1], x)
            out.arc(True, c, ep)
            return False, ep
        if loc.real <= c.real:
            return True, loc  # already climbing
        if not zs:
            out.arc(False, c, self.e)
            return False, self.e
        if zs[0] < c.real:
            return False, loc  # the arc is met on its far side only: the next pass is lower
        ep = complex(zs[0], x)
        out.arc(False, c, ep)
        return False, ep


def _line_meets_circle(ls: complex, le: complex, on: complex, c: complex, near: complex) -> complex:
    """Where the line ls-le meets the circle about c through ``on`` (the point nearer
    ``near``; the closest approach when they miss)."""
    rot = _conj(ls - le) / abs(ls - le)
    pe = (on - le) * rot
    pc = (c - le) * rot
    b = _norm(pc - pe) - pc.imag * pc.imag
    b = math.sqrt(b) if b >= 0 else 0.0
    s1 = (pc.real + b) / rot + le
    s2 = (pc.real - b) / rot + le
    return s1 if abs(near - s1) < abs(near - s2) else s2


def _join(p, n):
    """Move the end of p and the start of n to where they intersect."""
    if isinstance(n, Arc) and isinstance(p, Arc):
        a = abs(n.s - n.c)
        b = abs(p.s - p.c)
        c = abs(n.c - p.c)
        cos_b = (c * c + a * a - b * b) / 2.0 / a / c
        rot = complex(cos_b, math.sqrt(1 - min(cos_b * cos_b, 1.0)))
        p.e = n.s = rot * (p.c - n.c) / c * a + n.c
    elif isinstance(n, Arc):  # a line followed by an arc
        if abs(n.s - p.e) >= TOL:
            n.s = p.e = _line_meets_circle(p.s, p.e, n.e, n.c, n.s)
    elif isinstance(p, Arc):  # an arc followed by a line
        if abs(n.s - p.e) >= TOL:
            n.s = p.e = _line_meets_circle(n.s, n.e, p.e, p.c, n.s)
    else:
        rot = _conj(n.s - n.e) / abs(n.s - n.e)
        ps = (p.s - n.e) * rot
        pe = (p.e - n.e) * rot
        if (ps - pe).imag == 0:
            raise G7xError("Cannot intersect parallel lines")
        f = ps.imag / (ps - pe).imag
        n.s = p.e = (ps + f * (pe - ps)) / rot + n.e


def _corner_finish(seg, prev, nxt) -> complex:
    p, n = prev.dup(), nxt.dup()
    p.offset(seg.finish)
    n.offset(seg.finish)
    if (p.e - n.s).real > 1e-2:
        seg.finish = -seg.finish
        p, n = prev.dup(), nxt.dup()
        p.offset(seg.finish)
        n.offset(seg.finish)
    if (p.e - n.s).real > 1e-2:
        raise G7xError(f"Corner finish failed at ({prev.e.imag:g}, {prev.e.real:g})")
    _join(p, n)
    centre = (p.e + n.s) / 2.0
    p.offset(-seg.finish)
    n.offset(-seg.finish)
    seg.s = prev.e = p.e
    seg.e = nxt.s = n.s
    return centre


class Fillet(Arc):
    def __init__(self, size: float, at: complex):
        super().__init__(False, at, at, at)
        self.finish = size

    def do_finish(self, prev, nxt):
        self.c = _corner_finish(self, prev, nxt)
        self.ccw = (self.s - self.c).imag > 0 or (self.e - self.c).imag > 0
        self.finish = 0.0


class Chamfer(Line):
    def __init__(self, size: float, at: complex):
        super().__init__(at, at)
        self.finish = size

    def do_finish(self, prev, nxt):
        _corner_finish(self, prev, nxt)


# ------------------------------------------------------------------ the cycle
class Profile:
    def __init__(self, segs):
        self.segs = list(segs)
        self.flip = 0
        self.delta = 0.5
        self.escape = complex(0.3, 0.3)
        self.starts: list = []

    def dup(self):
        q = Profile([s.dup() for s in self.segs])
        q.flip, q.delta, q.escape = self.flip, self.delta, self.escape
        return q

    def rotate(self):
        for s in self.segs:
            s.rotate()
        self.flip ^= 4

    def swap(self):
        """Mirror so that the profile runs toward -Z and -X."""
        d = self.segs[0].e - self.segs[-1].e
        if d.imag > 0:
            for s in self.segs:
                s.flip_imag()
            self.flip ^= 2
        if d.real < 0:
            for s in self.segs:
                s.flip_real()
            self.flip ^= 1

    def monotonic(self):
        f = self.segs[0]
        if (f.e - f.s).real > 0:
            f.s = complex(f.e.real, f.s.imag)
        if not all(s.monotonic() for s in self.segs):
            raise G7xError("Not monotonic: the profile must keep running one way along the cycle's cutting "
                           "axis (Z for G70/G71, X for G72), without turning back")

    def do_finish(self):
        segs = self.segs
        for h in range(1, len(segs) - 1):
            segs[h].do_finish(segs[h - 1], segs[h + 1])
        self.segs = [s for s in segs if s.radius() >= 1e-3]

    def add_distance(self, distance: float):
        segs = self.segs
        v1 = segs[0].e - segs[0].s
        v2 = segs[-1].s - segs[0].s
        if (v1 / v2).imag < 0:
            distance = -distance
        first = segs.pop(0)
        done = 0.0
        steps = 0
        while done != distance:
            steps += 1
            if steps > 100000 or not segs:
                raise G7xError("the stock allowance cannot be applied to this profile")
            step = min(min(s.radius() / 2 for s in segs), abs(distance - done))
            if distance < 0:
                step = -step
            for s in segs:
                s.offset(step)
            segs[:] = [s for s in segs if s.radius() >= 1e-3]
            i = 0
            while i < len(segs) - 1:
                p, n = segs[i], segs[i + 1]
                if (p.e - n.s).real > 1e-2:
                    # a gap opened at a convex corner: close it with an arc about the corner
                    a, b = p.dup(), n.dup()
                    a.offset(-step)
                    b.offset(-step)
                    segs.insert(i + 1, Arc(distance > 0, p.e, (a.e + b.s) / 2.0, n.s))
                    i += 1
                i += 1
            i = 0
            while i < len(segs) - 1:
                if not segs[i].monotonic():
                    if i == 0:
                        raise G7xError("Not monotonic after the stock allowance")
                    if segs[i].radius() < segs[i - 1].radius():
                        del segs[i]
                    else:
                        del segs[i - 1]
                    i = 0
                    if len(segs) < 2:
                        break
                if segs[i].radius() < 1e-3:
                    del segs[i]
                    i = 0
                else:
                    _join(segs[i], segs[i + 1])
                i += 1
            done += step
        for i in range(len(segs) - 1):
            mid = (segs[i].e + segs[i + 1].s) / 2.0
            segs[i].e = segs[i + 1].s = mid
        if not segs:
            raise G7xError("the stock allowance leaves no profile")
        first.e = segs[0].s
        segs.insert(0, first)

    def pocket(self, cycle, loc, p, out, budget):
        segs = self.segs
        x = self.starts[-1].imag
        if cycle == 2:  # skip the first roughing pass
            while p < len(segs):
                stop, loc = segs[p].dive(loc, -1e9, out, p == 0)
                if stop:
                    break
                p += 1
            cycle = 3
        while p < len(segs):
            budget[0] -= 1
            if budget[0] < 0:
                raise G7xError("the roughing passes do not progress (LinuxCNC loops endlessly on this profile)")
            while x - TOL > loc.imag:
                x -= self.delta
            stop, loc = segs[p].dive(loc, x, out, p == 0)
            if stop:
                if cycle == 1:
                    # after the roughing passes, along the final contour and done
                    while p < len(segs):
                        loc = segs[p].climb_only(loc, out)
                        p += 1
                else:
                    # along the contour until it dips again: that pocket is next
                    while p < len(segs):
                        stop, loc = segs[p].climb(loc, out)
                        if stop:
                            if cycle == 3:
                                if loc.imag > self.starts[-1].imag and len(self.starts) > 1:
                                    self.starts.pop()
                                if len(self.starts) == 1:
                                    self.starts.append(loc)
                            self.pocket(cycle, loc, p, out, budget)
                            return
                        p += 1
                return
            if abs(loc.imag - x) > TOL:
                p += 1  # this pass lies below the current segment
                continue
            for ip in range(p, len(segs)):
                zs = segs[ip].crossings(loc.imag)
                if not zs:
                    continue
                dz = zs[0] if ip != p else zs[-1]
                dist = abs(dz - loc.real)
                if dz - TOL > loc.real:
                    continue  # meets the diving curve only at its start
                if dist < TOL:
                    if ip == p:
                        continue
                    if abs(loc - segs[ip].s) < TOL:
                        p = ip  # on to the next segment, at its entry point
                        break
                    x -= self.delta  # a zero-length segment: done with this level
                    break
                dest = complex(dz, loc.imag)
                out.feed(dest)
                k = min(1.0, dist / 2 / self.escape.real)  # retract less on a short pass
                dest += k * self.escape
                out.rapid(dest)
                out.rapid(loc - _conj(k * self.escape))
                if p == 0:
                    out.rapid(loc)
                else:
                    out.feed(loc)
                x -= self.delta
                break
            else:
                # nothing left to cut at this level beyond this segment (it ends exactly on
                # the level): on to the next one.  LinuxCNC 2.9 looped here for ever.
                p += 1

    def g70(self, out, x, z, d, e, passes):
        self.segs[0].s = complex(z, x)
        probe = self.dup()
        probe.segs.pop(0)
        probe.swap()
        if not all(s.monotonic() for s in probe.segs):
            probe.rotate()
            probe.swap()
        probe.monotonic()
        if probe.flip & 4:
            self.rotate()
        self.swap()
        self.do_finish()
        self.monotonic()
        mo = _Mapped(out, self.flip)
        for k in range(int(passes), 0, -1):
            dist = (k - 1) * (d - e) / passes + e
            path = self.dup()
            path.add_distance(dist)
            mo.rapid(path.segs[0].s)  # LinuxCNC: without cutter compensation
            mo.rapid(path.segs[0].e)
            for s in path.segs[1:]:
                s.draw(mo)

    def g71(self, out, cycle, x, z, u, w, d, i, r, rotate=False):
        self.segs[0].s = complex(z, x)
        if rotate:
            self.rotate()
        self.swap()
        self.do_finish()
        self.monotonic()
        self.add_distance(d)
        for s in self.segs:
            s.move(complex(w, u))
        mo = _Mapped(out, self.flip)
        self.delta = max(i, 2 * TOL)
        self.escape = r * complex(1, 1)
        mo.rapid(self.segs[0].s)
        if self.segs[-1].e.imag < self.segs[0].s.imag:
            last = self.segs[-1].e
            self.segs.append(Line(last, complex(last.real, self.segs[0].s.imag)))
        self.starts = [self.segs[0].s]
        budget = [max(100000, int(4 * abs(self.segs[0].s.imag - min(s.e.imag for s in self.segs)) / self.delta)
                      * (len(self.segs) + 1))]
        self.pocket(cycle, self.segs[0].s, 0, mo, budget)


def run_cycle(code: float, segs: list, last: complex, params: dict) -> list:
    """Moves of a G70/G71/G72(.1/.2) cycle.  ``segs``: the profile, which ends at ``last``
    (Z + iX), ``params``: the cycle's words (X Z D E I P R U W).  Returns [("G0"|"G1", end) |
    ("G2"|"G3", end, centre)] with points as Z + iX, in program units."""
    cycle = int(round(code * 10))
    kind, sub = cycle // 10, cycle % 10
    x = params["X"]
    z = params["Z"]
    d = params.get("D", 0.0)
    e = params.get("E", 0.0)
    i = params.get("I", 1.0)
    p = params.get("P", 1.0)
    r = params.get("R", 0.5)
    u = params.get("U", 0.0)
    w = params.get("W", 0.0)
    if i <= 0:
        raise G7xError("I must be greater than zero.")
    if len(segs) <= 1:
        return []
    segs = [s.dup() for s in segs]
    dfront = segs[0].e - segs[0].s
    dback = segs[-1].e - segs[-1].s
    out = _Out(complex(z, x))
    if kind == 70:
        if p >= 1:
            Profile(segs).g70(out, x, z, d, e, p)
        return out.moves
    # an open profile is closed back to the cycle's X (G71) or Z (G72), as LinuxCNC does
    if kind == 71 and abs(dback.real) > 0 and dfront.imag * (x - last.imag) < 0:
        segs.append(Line(last, complex(last.real, x)))
    elif kind == 72 and abs(dback.imag) > 0 and dfront.real * (z - last.real) < 0:
        segs.append(Line(last, complex(z, last.imag)))
    Profile(segs).g71(out, sub, x, z, u, w, d, i, r, rotate=kind == 72)
    return out.moves
