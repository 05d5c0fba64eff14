"""Depth layering: a cut over its limit even at the lowest feed, re-cut in N passes of equal depth.

The power-smoothing reference's second lever (after the feed): when a segment's load is over
the limit at the bottom of the feed range, divide its axial depth into N layers and cut it N
times, each pass at its own Z.  Here a *cut* is what the CAM system wrote for one depth: an
entry that brings the tool down to the depth (a straight plunge, a ramp or a helix), then the
feed moves in the XY plane that follow at that depth — over holding tabs and back down — up
to the last move at the depth, all between the depth and the stock's top.  Layer k of N is

    (MTWIN LAYER k/N Z…)            a comment the CAM user recognises
    <the cut's lines, every Z word  copies (N words left out: they would repeat the program's):
     raised to z_k where lower>     the entry stops at z_k, tabs stay where they stand above it
    G0 Z<safe height>               the link back: up to the highest the tool went before
                                    the cut (its rapids', or a post's feed-rate traverses),
    G0 X<start> Y<start>            over to where the entry starts,
    G0 Z<clearance>                 down to the entry's start height (left out when it is there),
    G1 F<the entry's feed>          (the mode and feed the entry's first line may inherit)

and the last layer is the program's own lines, byte for byte, so the cut ends at its depth and
the program goes on in the modal state it had.  A copy runs where the original runs or above
it, never below it nor below z_k (Z is linear along a line or a helix, and max(z, z_k) is
convex), so each layer cuts a part of what the original cuts.  The depths are equal: z_k = top
− k·(top − depth)/N, the top being the material's highest point over the cut as the twin's
stock has it when the cut begins.  What is not a cut in this sense (G91, cutter compensation,
a rotated or mirrored frame, a G code beyond G0-G3/G17/G90/G94, M, S or T words, a macro
program, a subprogram, a line run more than once, a cut the tool reaches at rapid) is not
layered, and says why.  The proof is the part: :mod:`mtwin.cutting.stockproof`.
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
# (a sign may stand apart from its digits, as the lexer reads it: "Z - 6."; an N word may be
# fractional, as LinuxCNC accepts: "N10.1")
_Z_WORD = re.compile(rb"([Zz])(\s*)([-+]?\s*(?:\d+\.?\d*|\.\d+))")
_N_WORD = re.compile(rb"^(\s*)[Nn]\s*\d+(?:\.\d*)?\s*")
_COMMENT = re.compile(rb"\([^)]*\)|;.*$")
_OTHER_WORDS = re.compile(rb"[MmSsTt]\s*[-+]?[\d.#\[]")


class NotLayerable(Exception):
    """Why a cut cannot be layered (said with the segment the optimiser refused)."""


@dataclass
class Cut:
    """One pass at one depth: its entry (a straight plunge, a ramp or a helix down to the depth),
    then the feed moves that follow it at the depth, over holding tabs and back, up to its last
    move at the depth."""

    plunge_line: int  # 1-based, the entry's first line
    first_line: int  # the line that reaches the depth
    last_line: int  # the last line at the depth
    depth: float  # mm, the cut's Z
    clearance: float  # mm, where the entry starts
    start: tuple  # (x, y) mm, where the entry starts
    plunge_feed: float  # mm/min, the entry's feed
    tool: int
    safe: float = 0.0  # mm, the tool's retract height: the highest it went before the cut


# the G codes a layered cut's lines may hold: motion, the XY plane, absolute, feed per minute
_PLAIN_G = re.compile(rb"[Gg]\s*0*(?:[0-3]|17|90|94)(?![\d.])")
_ANY_G = re.compile(rb"[Gg]\s*[-+]?[\d.]+")
_ARC_G = re.compile(rb"[Gg]\s*0*[23](?![\d.])")


def find_cut(program, first: int, last: int, stock_top: float = np.inf) -> Cut:
    """The pass that holds the deepest feed move of the lines ``first``..``last`` (a segment of
    the optimiser): the feed moves around it that stay between its depth and the stock's top,
    from the entry that first brings the tool down to the depth to the last move at it.  Holding
    tabs (up to a tab's top and back down) are inside it; a retract above the stock ends it."""
    if program.is_macro:
        raise NotLayerable("a macro program (its lines may run with other values)")
    rec = program.records
    lines = rec["line"]
    eps = 1e-6
    feed = R.is_feed_kind(rec["kind"])
    inside = np.flatnonzero((lines >= first) & (lines <= last) & feed)
    if not len(inside):
        raise NotLayerable("no feed move")
    j0 = int(inside[np.argmin(rec["z"][inside])])
    depth, tool = float(rec["z"][j0]), rec["tool"][j0]
    while True:
        ok = feed & (rec["z"] >= depth - eps) & (rec["z"] <= stock_top + eps) & (rec["tool"] == tool)
        a = b = j0
        while a > 0 and ok[a - 1]:
            a -= 1
        while b + 1 < len(rec) and ok[b + 1]:
            b += 1
        # a segment on a holding tab: the tool rose to it from the pass below, which is the cut
        if a > 0 and feed[a - 1] and rec["tool"][a - 1] == tool and rec["z"][a - 1] < depth - eps:
            depth, j0 = float(rec["z"][a - 1]), a - 1
            continue
        break
    at = np.flatnonzero(np.abs(rec["z"][a:b + 1] - depth) < eps) + a
    reach, end = int(at[0]), int(at[-1])
    s = reach  # back over the descending moves that bring the tool down to the depth
    while s > a and rec["sz"][s - 1] > rec["z"][s - 1] + eps:
        s -= 1
    if not rec["sz"][s] > depth + eps:
        raise NotLayerable("it does not start with a plunge, a ramp or a helix (the tool comes down to its depth "
                           "at rapid)")
    if not rec["flags"][s] & R.FL_FIRST_IN_LINE or (end + 1 < len(rec) and lines[end + 1] == lines[end]):
        raise NotLayerable("it starts or ends inside a line")
    span = rec[s:end + 1]
    why = _frame(span)
    if why:
        raise NotLayerable(why)
    if (span["plane"] != 0).any():
        raise NotLayerable("arcs outside the XY plane")
    # (the link restores G1 and the entry's feed in mm/min: a pass under G95 or G93, or one that
    # changes the mode, would run the program's own lines after it in another feed mode)
    if (span["feed_mode"] != R.FEED_PER_MIN).any():
        raise NotLayerable("a feed per revolution (G95) or inverse time (G93) in it")
    l0, l1 = int(lines[s]), int(lines[end])
    if _repeated(rec, l0, l1):
        raise NotLayerable("its lines run more than once (a loop or a subprogram)")
    text = [_COMMENT.sub(b"", ln) for ln in program.data.split(b"\n")[l0 - 1:l1]]
    if any(_OTHER_WORDS.search(ln) for ln in text):
        raise NotLayerable("an M, S or T word among its lines (each layer would repeat it)")
    if any(len(_ANY_G.findall(ln)) != len(_PLAIN_G.findall(ln)) for ln in text):
        raise NotLayerable("a G code other than G0-G3, G17, G90 or G94 among its lines")
    if rec["kind"][s] != R.LINEAR and not _ARC_G.search(text[0]):
        raise NotLayerable("its entry arc takes its G2/G3 from an earlier line")
    before = rec[:s]
    mine = (before["tool"] == tool) & ((before["flags"] & R.FL_MACHINE) == 0) & (before["kind"] <= R.ARC_CCW)
    # the link back rises to the highest the tool went before the cut (its rapids', or a post's
    # feed-rate traverses): a height the program itself cleared its fixtures at
    safe = max(float(rec["sz"][s]), float(before["z"][mine].max()) if mine.any() else -np.inf)
    return Cut(l0, int(lines[reach]), l1, depth, float(rec["sz"][s]), (float(rec["sx"][s]), float(rec["sy"][s])),
               float(rec["feed"][s]), int(tool), safe)


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


def layered_text(program, layerings: list[Layering]) -> tuple[bytes, np.ndarray, np.ndarray]:
    """The program with each cut written in its layers (see the module); for each of its lines
    the program's line it came from (1-based; a comment or a link: the cut's first line); and
    (layer k, of N, the cut's first line) where the line belongs to a layered cut — its copy, its
    link, its comment — (0, 0, 0) elsewhere."""
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
    layer: list[tuple[int, int, int]] = []
    todo = {ly.cut.plunge_line: ly for ly in layerings}
    i = 0
    while i < len(src):
        ly = todo.get(i + 1)
        if ly is None:
            out.append(src[i])
            origin.append(i + 1)
            layer.append((0, 0, 0))
            i += 1
            continue
        c = ly.cut
        body = [ln.rstrip(b"\r") if strip_cr else ln for ln in src[c.plunge_line - 1:c.last_line]]
        cr = b"\r" if strip_cr else b""
        fp = style.feed(c.plunge_feed / k, inch).encode()
        zc = style.coord(c.clearance / k).encode()
        zs = style.coord(max(c.safe, c.clearance) / k).encode()
        xs, ys = (style.coord(v / k).encode() for v in c.start)
        link = [b"G0 Z" + zs + cr, b"G0 X" + xs + b" Y" + ys + cr] + ([b"G0 Z" + zc + cr] if zs != zc else []) \
            + [b"G1 F" + fp + cr]
        own = list(range(c.plunge_line, c.last_line + 1))
        for n, z in enumerate(ly.depths[:-1], 1):
            zt = style.coord(z / k).encode()
            out.append(b"(MTWIN LAYER %d/%d Z%s)" % (n, ly.layers, zt) + cr)
            # the pass again, no line lower than this layer: Z = max(Z, z_k)
            out += [_floor_z(_N_WORD.sub(rb"\1", ln), z / k, zt) + cr for ln in body]
            out += link
            origin += [c.plunge_line] + own + [c.plunge_line] * len(link)
            layer += [(n, ly.layers, c.plunge_line)] * (1 + len(own) + len(link))
        out.append(b"(MTWIN LAYER %d/%d Z%s: THE PROGRAM'S OWN LINES)"
                   % (ly.layers, ly.layers, style.coord(c.depth / k).encode()) + cr)
        # the program's own pass, byte for byte
        out += src[c.plunge_line - 1:c.last_line]
        origin += [c.plunge_line] + own
        layer += [(ly.layers, ly.layers, c.plunge_line)] * (1 + len(own))
        i = c.last_line
    return b"\n".join(out), np.array(origin, np.int64), np.array(layer, np.int64).reshape(-1, 3)


def _floor_z(line: bytes, floor: float, text: bytes) -> bytes:
    """``line`` with its Z word (outside comments) raised to ``floor`` (written ``text``) where it
    is lower; byte for byte otherwise.  A move between two such ends runs where the original
    runs or above it (Z is linear along a line or a helix, and max(z, floor) is convex), so a
    layer cuts nothing the original pass does not."""
    code = _COMMENT.sub(lambda m: b" " * len(m.group(0)), line)
    m = _Z_WORD.search(code)
    if not m or float(m.group(3).replace(b" ", b"").replace(b"\t", b"")) >= floor - 1e-9:
        return line
    return line[:m.start(3)] + text + line[m.end(3):]
