"""Depth layering: a cut over its limit even at the lowest feed, re-cut in N passes of equal depth.

The power-smoothing reference's second lever (after the feed): when a segment's load is over
the limit at the bottom of the feed range, divide its axial depth into N layers and cut it N
times, each pass at its own Z.  Here a *cut* is what the CAM system wrote for one depth: a
straight plunge at the cut's start point, then feed moves in the XY plane at the plunge's Z
(lines and arcs), the plunge starting from a height the program itself stood at over that
point (its clearance).  Layer k of N is written as

    (MTWIN LAYER k/N Z…)            a comment the CAM user recognises
    G1 Z<z_k> F<the plunge's feed>  the plunge, to this layer's depth
    <the cut's lines, Z set to z_k> copies (N words left out: they would repeat the program's)
    G0 Z<safe height>               the link back: up to the tool's own retract height (the
                                    highest its rapids went before the cut),
    G0 X<start> Y<start>            over to the cut's start,
    G0 Z<clearance>                 down to where the plunge starts (left out when it is there),
    G1 F<the plunge's feed>         (the plunge mode and feed the original plunge line may inherit)

and the last layer is the program's own lines, byte for byte, so the cut ends at its depth and
the program goes on in the modal state it had.  The depths are equal: z_k = top − k·(top −
depth)/N, the top being the material's highest point over the cut as the twin's stock has it
when the cut begins.  What is not a cut in this sense (a ramp or helix entry, G91, cutter
compensation, a rotated or mirrored frame, a macro program, a subprogram, a line run more than
once) is not layered, and says why.  The proof is the part: :mod:`mtwin.cutting.stockproof`.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ..gcode import records as R
from ..units import MM_PER_INCH

MAX_LAYERS = 8  # --layers auto tries up to this many
_NOT_PLAIN = (R.FL_INCREMENTAL | R.FL_CANNED | R.FL_MACHINE | R.FL_SUB | R.FL_COMP | R.FL_POLAR | R.FL_ROTARY
              | R.FL_SPLINE | R.FL_MIRROR | R.FL_CORNER | R.FL_SYNC | R.FL_DIAMETER)
_Z_WORD = re.compile(rb"([Zz])(\s*)([-+]?(?:\d+\.?\d*|\.\d+))")
_N_WORD = re.compile(rb"^(\s*)[Nn]\s*\d+\s*")
_COMMENT = re.compile(rb"\([^)]*\)|;.*$")
_OTHER_WORDS = re.compile(rb"[MmSsTt]\s*[-+]?[\d.#\[]")


class NotLayerable(Exception):
    """Why a cut cannot be layered (said with the segment the optimiser refused)."""


@dataclass
class Cut:
    """A plunge and the planar feed moves after it, at one depth."""

    plunge_line: int  # 1-based
    first_line: int  # the first planar line
    last_line: int  # the last planar line
    depth: float  # mm, the cut's Z
    clearance: float  # mm, where the plunge starts
    start: tuple  # (x, y) mm, the plunge's point
    plunge_feed: float  # mm/min
    tool: int
    safe: float = 0.0  # mm, the tool's retract height: the highest its rapids went before the cut


def find_cut(program, first: int, last: int) -> Cut:
    """The cut that holds the lines ``first``..``last`` (a segment of the optimiser): from its
    plunge to the last feed move at its depth."""
    if program.is_macro:
        raise NotLayerable("a macro program (its lines may run with other values)")
    rec = program.records
    lines = rec["line"]
    eps = 1e-6
    feed = R.is_feed_kind(rec["kind"])
    inside = np.flatnonzero((lines >= first) & (lines <= last) & feed)
    if not len(inside):
        raise NotLayerable("no feed move")
    i = int(inside[0])
    depth = float(rec["z"][i])
    if rec["sz"][i] > depth + eps:
        p = i  # the segment starts with its plunge
    else:  # back over the feed moves at this depth to the move that came down to it
        j = i
        while j > 0 and feed[j - 1] and abs(rec["z"][j - 1] - depth) < eps and abs(rec["sz"][j - 1] - depth) < eps:
            j -= 1
        p = j - 1
    if p < 0 or not feed[p] or abs(rec["z"][p] - depth) > eps or not rec["sz"][p] > depth + eps:
        raise NotLayerable("it does not start with a plunge")
    pl = rec[p]
    if abs(pl["sx"] - pl["x"]) > eps or abs(pl["sy"] - pl["y"]) > eps or pl["kind"] != R.LINEAR:
        raise NotLayerable("it is entered by a ramp or a helix (only a straight plunge is layered)")
    # forward: the planar feed moves at the depth
    k = p + 1
    while k < len(rec) and feed[k] and abs(rec["z"][k] - depth) < eps and abs(rec["sz"][k] - depth) < eps:
        k += 1
    body = rec[p + 1:k]
    if not len(body):
        raise NotLayerable("no feed move at the plunge's depth")
    if int(body["line"][-1]) < last:
        raise NotLayerable("the segment leaves the plunge's depth")
    span = rec[p:k]
    why = _frame(span)
    if why:
        raise NotLayerable(why)
    if (span["plane"] != 0).any():
        raise NotLayerable("arcs outside the XY plane")
    if len(np.unique(span["tool"])) > 1:
        raise NotLayerable("a tool change inside it")
    if _repeated(rec, int(pl["line"]), int(body["line"][-1])):
        raise NotLayerable("its lines run more than once (a loop or a subprogram)")
    text = program.data.split(b"\n")[int(body["line"][0]) - 1:int(body["line"][-1])]
    if any(_OTHER_WORDS.search(_COMMENT.sub(b"", ln)) for ln in text):
        raise NotLayerable("an M, S or T word among its lines (each layer would repeat it)")
    before = rec[:p]
    mine = (before["kind"] == R.RAPID) & (before["tool"] == pl["tool"]) & ((before["flags"] & R.FL_MACHINE) == 0)
    safe = max(float(pl["sz"]), float(before["z"][mine].max()) if mine.any() else -np.inf)
    return Cut(int(pl["line"]), int(body["line"][0]), int(body["line"][-1]), depth, float(pl["sz"]),
               (float(pl["x"]), float(pl["y"])), float(pl["feed"]), int(pl["tool"]), safe)


def _frame(span) -> str:
    if (span["flags"] & _NOT_PLAIN).any():
        return "G91, cutter compensation, a cycle or a transformed frame inside it"
    if (np.abs(span["rot"]) > 1e-12).any():
        return "a rotated coordinate system"
    return ""


def _repeated(rec, first: int, last: int) -> bool:
    ln = rec["line"][(rec["line"] >= first) & (rec["line"] <= last) & ((rec["flags"] & R.FL_FIRST_IN_LINE) != 0)]
    return len(ln) != len(np.unique(ln))


@dataclass
class Layering:
    """A cut and how many layers it gets, with the top of the material over it."""

    cut: Cut
    layers: int
    top: float  # mm

    @property
    def depths(self) -> list[float]:
        step = (self.top - self.cut.depth) / self.layers
        return [self.top - k * step for k in range(1, self.layers)] + [self.cut.depth]

    @property
    def depth_per_layer(self) -> float:
        return (self.top - self.cut.depth) / self.layers

    def as_dict(self) -> dict:
        return {"lines": [self.cut.plunge_line, self.cut.last_line], "layers": self.layers,
                "depth_per_layer": self.depth_per_layer, "z": self.depths, "top": self.top,
                "tool": self.cut.tool}


def material_top(eng, plan, cut: Cut) -> float:
    """The top of the material the cut removes, mm: its depth plus its effective axial depth
    along its feed moves (the engagement of the program as written), the cross-section the
    tool sweeps over the width it engages — not the engaged flute's extent, which on a pass
    that follows earlier step-downs reaches up a wall to the stock's top (95th percentile:
    the entry's transients left out)."""
    from ..layout import Q_AE, Q_AREA

    seg_of = eng.step_segments()
    lines = plan.seg["line"][seg_of] if len(seg_of) else np.zeros(0, np.int64)
    mine = (lines >= cut.first_line) & (lines <= cut.last_line)
    if not mine.any():
        return cut.depth
    ae = eng.q[mine, Q_AE].astype(np.float64)
    ok = ae > 1e-6
    if not ok.any():
        return cut.depth
    ap = eng.q[mine, Q_AREA][ok] / ae[ok]
    # to 0.01 mm: the cross-section is a sum over the Z-map's cells (a 6-mm slot from the stock's
    # top comes out 5.9988 mm deep), and a layer's depth is written to the program's decimals
    return round(cut.depth + float(np.percentile(ap, 95)), 2)


def layered_text(program, layerings: list[Layering]) -> tuple[bytes, np.ndarray]:
    """The program with each cut written in its layers (see the module), and for each of its
    lines the program's line it came from (1-based; a link, the cut's plunge line)."""
    from ..gcode.numfmt import detect_style

    style = detect_style(program.lexed)
    inch = bool(program.inch)
    k = MM_PER_INCH if inch else 1.0
    data = program.data
    eol = b"\r\n" if b"\r\n" in data[:4096] else b"\n"
    src = data.split(b"\n")
    strip_cr = eol == b"\r\n"
    out: list[bytes] = []
    origin: list[int] = []
    todo = {ly.cut.plunge_line: ly for ly in layerings}
    i = 0
    while i < len(src):
        ly = todo.get(i + 1)
        if ly is None:
            out.append(src[i])
            origin.append(i + 1)
            i += 1
            continue
        c = ly.cut
        body = [ln.rstrip(b"\r") if strip_cr else ln for ln in src[c.first_line - 1:c.last_line]]
        cr = b"\r" if strip_cr else b""
        fp = style.feed(c.plunge_feed / k, inch).encode()
        zc = style.coord(c.clearance / k).encode()
        zs = style.coord(max(c.safe, c.clearance) / k).encode()
        xs, ys = (style.coord(v / k).encode() for v in c.start)
        link = [b"G0 Z" + zs + cr, b"G0 X" + xs + b" Y" + ys + cr] + ([b"G0 Z" + zc + cr] if zs != zc else []) \
            + [b"G1 F" + fp + cr]
        for n, z in enumerate(ly.depths[:-1], 1):
            zt = style.coord(z / k).encode()
            out.append(b"(MTWIN LAYER %d/%d Z%s)" % (n, ly.layers, zt) + cr)
            out.append(b"G1 Z" + zt + b" F" + fp + cr)
            origin += [c.plunge_line, c.plunge_line]
            out += [_set_z(_N_WORD.sub(rb"\1", ln), zt) + cr for ln in body]
            origin += list(range(c.first_line, c.last_line + 1))
            out += link
            origin += [c.plunge_line] * len(link)
        out.append(b"(MTWIN LAYER %d/%d Z%s: THE PROGRAM'S OWN LINES)"
                   % (ly.layers, ly.layers, style.coord(c.depth / k).encode()) + cr)
        origin.append(c.plunge_line)
        # the program's own plunge and cut, byte for byte
        out += src[c.plunge_line - 1:c.last_line]
        origin += list(range(c.plunge_line, c.last_line + 1))
        i = c.last_line
    return b"\n".join(out), np.array(origin, np.int64)


_LAYER_COMMENT = re.compile(rb"\(MTWIN LAYER (\d+)/(\d+) ")


def layer_numbers(text: bytes, origin: np.ndarray, layerings: list[Layering]) -> np.ndarray:
    """Per line of a layered program (``layered_text``'s), (layer k, of N) where it is part of a
    layered cut — its plunge, its copy of the cut, its link — and (0, 0) elsewhere."""
    out = np.zeros((len(origin), 2), np.int64)
    k = (0, 0)
    for i, ln in enumerate(text.split(b"\n")):
        m = _LAYER_COMMENT.match(ln)
        if m:
            k = (int(m.group(1)), int(m.group(2)))
        if any(ly.cut.plunge_line <= origin[i] <= ly.cut.last_line for ly in layerings):
            out[i] = k
        else:
            k = (0, 0)
    return out


def _set_z(line: bytes, z: bytes) -> bytes:
    """``line`` with its Z word (outside comments) set to ``z``."""
    code = _COMMENT.sub(lambda m: b" " * len(m.group(0)), line)
    m = _Z_WORD.search(code)
    if not m:
        return line
    return line[:m.start(3)] + z + line[m.end(3):]
