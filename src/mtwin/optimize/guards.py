"""What the optimiser may change and how far, with default options (issue 18).

* **What the twin knows.**  A feed move is only raised where the twin knows the cut: its tool
  is described (the command line, the twin file's table or a comment the twin reads) and the
  spindle runs.  Under a stock the twin only guessed, an air cut is raised only where its
  air is the work of earlier cuts by described tools: inside the guessed block (under its
  top, within its box with the tool's radius).  Above the guessed top or outside the block
  the "air" is only the guess's (a router whose Z0 is the table cuts at Z > 0).
* **Limits learned from the program.**  Without an explicit limit, each tool's load limit
  and largest chip thickness are the levels the program already runs that tool at on the
  shop's machine: the 95th percentile (by path length) of its engaged steps at the
  programmed F and S.  The 95th percentile, not the peak: a level the program holds for at
  least a twentieth of its cutting length is proven, a one-step spike at a corner entry is
  not.  It is never above the program's own peak for that tool.
* **Finishing passes** keep their feed per tooth (surface finish is set by it): a CAM comment
  naming a finishing operation, or a segment whose radial width of cut is at most
  ``FINISH_AE`` of the tool's diameter (a wall pass).
* **Accuracy** (``contour_error``): the re-simulated contour error is held per segment.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from ..errors import warning_text
from ..gcode import records as R

PERCENTILE = 95.0  # of a tool's engaged steps, by length: the learned level
LONG_TRACE = 200_000  # samples from which the compiled contour kernel pays for loading
TOP_CLEARANCE = 1e-3  # mm: a tip this close to a guessed stock's top is at the top (see inside_stock)
FINISH_AE = 0.05  # radial width of cut / diameter at or under which a pass is a finishing pass
# an operation named finishing ("FINISH WALL PASS", "2D Contour finish", "semi-finish"), not
# FreeCAD's "(Finish operation: Profile)" that closes every operation, nor "program finished"
_FINISH = re.compile(rb"\b(?:semi-?)?finish(?:ing)?\b(?!\s*operation)|\bfin\b", re.I)


@dataclass
class Trust:
    """Per record: may its feed be set (the twin knows its cut)?  With the warnings to give."""

    ok: np.ndarray  # (records,) bool
    warnings: list[str]
    undescribed: dict[int, list[int]]  # tool -> lines of its feed moves that keep their feeds
    stopped: list[int]  # lines of feed moves with the spindle stopped
    blind: list[int] = field(default_factory=list)  # lines under cutter compensation of unknown radius


def trusted_records(program, cutting, candidates: np.ndarray) -> Trust:
    """Which of the ``candidates`` (feed records whose feed could be set) the twin knows."""
    from ..cutting.library import describes

    rec = program.records
    ok = candidates.copy()
    warnings: list[str] = []
    undescribed: dict[int, list[int]] = {}
    for t in np.unique(rec["tool"][candidates]):
        if describes(cutting, int(t)):
            continue
        m = candidates & (rec["tool"] == t)
        ok &= ~m
        lines = sorted(set(rec["line"][m].tolist()))
        undescribed[int(t)] = lines
        # (simulate's words for the same tool: one the program declares as a drill or a tap is
        # declared, not unknown — the cutting model just cannot represent it)
        declared_as = next((d.split(": ", 1)[1].split(", which")[0] for d in cutting.defaults_used
                            if d.startswith(f"tool T{int(t)}: declared as")), None)
        what = (f"is {declared_as}, which the cutting model cannot represent" if declared_as else
                "is not described (no tool table entry, no comment the twin reads; it would be simulated as the "
                "default 6 mm end mill)")
        warnings.append(warning_text(program.path, lines[0], f"tool T{int(t)} {what}: its "
                        f"{int(m.sum())} feed move(s) keep their programmed feeds (lines {line_ranges(lines)}); declare "
                        f"it with --tool {int(t)}=flat:DIAMETER_MM[:FLUTES] (or ball, bull, vee:D:FLUTES:ANGLE:TIP) or a "
                        f"[tools.{int(t)}] "
                        f"table in the twin file"))
    stopped_m = candidates & ((rec["spindle_dir"] == 0) | (rec["spindle"] <= 0))
    stopped = sorted(set(rec["line"][stopped_m & ok].tolist()))
    if stopped:
        warnings.append(warning_text(program.path, stopped[0], f"{int((stopped_m & ok).sum())} feed move(s) run with "
                        f"the spindle stopped (no M3/M4, or S0 — a router's hand-switched spindle?): the twin cannot "
                        f"know their cut, so they keep their programmed feeds (lines {line_ranges(stopped)})"))
    ok &= ~stopped_m
    # under cutter compensation whose radius the twin does not know (taken as 0: a path the CAM
    # system compensated already), the tool may really run a radius off the simulated path — a
    # hand-written contour with the full radius in its D register: there the twin's engagement
    # is another cut's (a finishing pass after a larger tool's roughing looks like air)
    given = program.settings.comp_radii or {}
    blind_m = candidates & ok & (rec["comp"] != 0) & (rec["comp_r"] <= 0)
    blind: list[int] = []
    if blind_m.any() and not any(float(r) == 0.0 for r in given.values()):
        blind = sorted(set(rec["line"][blind_m].tolist()))
        warnings.append(warning_text(program.path, blind[0], f"{int(blind_m.sum())} feed move(s) run under cutter "
                        f"compensation (G41/G42) whose radius the twin does not know: the tool may run a radius off "
                        f"the simulated path, so they keep their programmed feeds (lines {line_ranges(blind)}); give "
                        f"the D registers in the twin file ([cutter_comp], 0 for a path the CAM system compensated)"))
        ok &= ~blind_m
    return Trust(ok, warnings, undescribed, stopped, blind)


def inside_stock(program, cutting, box) -> np.ndarray:
    """Per record: does the tool's whole sweep lie inside the stock box (its tip below the top,
    its XY extent, grown by the tool's radius, within the box's)?  Under a guessed stock, only
    such a move's "air" is the work of earlier cuts rather than of the guess.  A move at the
    guessed top is not inside: the guess puts the top at the program's highest cut, while real
    stock stands above the finished face (a facing pass, a skim cut at Z0 cuts material)."""
    rec = program.records
    n = len(rec)
    if box is None or not n:
        return np.zeros(n, bool)
    x0, y0, _, x1, y1, top = (float(v) for v in box)
    zmax = np.maximum(rec["z"], rec["sz"])
    radius = np.array([cutting.tool(int(t)).radius for t in rec["tool"]])
    lo_x = np.minimum(rec["x"], rec["sx"])
    hi_x = np.maximum(rec["x"], rec["sx"])
    lo_y = np.minimum(rec["y"], rec["sy"])
    hi_y = np.maximum(rec["y"], rec["sy"])
    arc = (rec["kind"] == R.ARC_CW) | (rec["kind"] == R.ARC_CCW)
    if arc.any():
        # an arc by its full circle (an upper bound of its extent)
        r = np.hypot(rec["sx"] - rec["cx"], rec["sy"] - rec["cy"])
        lo_x = np.where(arc, np.minimum(lo_x, rec["cx"] - r), lo_x)
        hi_x = np.where(arc, np.maximum(hi_x, rec["cx"] + r), hi_x)
        lo_y = np.where(arc, np.minimum(lo_y, rec["cy"] - r), lo_y)
        hi_y = np.where(arc, np.maximum(hi_y, rec["cy"] + r), hi_y)
    within = (lo_x - radius >= x0 - 1e-6) & (hi_x + radius <= x1 + 1e-6) & (lo_y - radius >= y0 - 1e-6) & \
        (hi_y + radius <= y1 + 1e-6)
    # an arc in another plane bulges in Z: inside only if its circle stays under the top
    other_plane = arc & (rec["plane"] != R.PLANE_XY)
    r3 = np.hypot(np.hypot(rec["sx"] - rec["cx"], rec["sy"] - rec["cy"]), rec["sz"] - rec["cz"])
    zmax = np.where(other_plane, np.maximum(zmax, rec["cz"] + r3), zmax)
    return within & (zmax < top - TOP_CLEARANCE)


def learned_levels(model, fz0: np.ndarray, usable: np.ndarray) -> dict[int, tuple[float, float, float]]:
    """Per tool: (load level N, chip-thickness level mm, the program's peak load N) of its
    engaged, optimisable steps at the program's own feed per tooth ``fz0``."""
    load = model.load(fz0)
    chip = fz0 * model.chip
    out = {}
    for t in np.unique(model.tool):
        m = usable & (model.tool == t) & model.cutting & (load > 0)
        if not m.any():
            continue
        w = model.length[m]
        out[int(t)] = (weighted_percentile(load[m], w, PERCENTILE), weighted_percentile(chip[m], w, PERCENTILE),
                       float(load[m].max()))
    return out


def weighted_percentile(x: np.ndarray, w: np.ndarray, q: float) -> float:
    """The ``q`` th percentile of ``x`` weighted by ``w`` (the smallest x with at least q % of
    the weight at or below it); the largest x when nothing has weight."""
    if not (w > 0).any():
        return float(x.max())
    return float(percentile_by_group(np.zeros(len(x), np.int64), x, w, 1, q)[0])


def percentile_by_group(group: np.ndarray, x: np.ndarray, w: np.ndarray, n: int, q: float) -> np.ndarray:
    """Per group 0..n-1, the ``q`` th percentile of ``x`` weighted by ``w`` (the smallest x with
    at least q % of the group's weight at or below it); 0 where a group has no weight."""
    out = np.zeros(n)
    m = w > 0
    if not m.any():
        return out
    group, x, w = group[m], x[m], w[m]
    o = np.lexsort((x, group))
    group, x, w = group[o], x[o], w[o]
    starts = np.flatnonzero(np.r_[True, group[1:] != group[:-1]])
    ends = np.r_[starts[1:], len(group)]
    cw = np.cumsum(w)
    base = np.r_[0.0, cw][starts]
    total = cw[ends - 1] - base
    for a, b, b0, tot in zip(starts, ends, base, total):
        k = a + int(np.searchsorted(cw[a:b] - b0, q / 100.0 * tot, side="left"))
        out[group[a]] = x[min(k, b - 1)]
    return out


def finish_lines(program) -> np.ndarray:
    """Per record: is it in an operation a CAM comment calls finishing?  A comment line naming
    finishing opens the region; the next comment line that does not, once a move has been made
    in the region, or the end of the program closes it."""
    rec = program.records
    n_lines = int(rec["line"].max()) + 1 if len(rec) else 1
    moving = np.zeros(n_lines + 1, bool)
    moving[rec["line"]] = True
    flag = np.zeros(n_lines + 1, bool)
    state, moved = False, False
    for i, raw in enumerate(bytes(program.data).split(b"\n"), start=1):
        if i > n_lines:
            break
        text = raw.strip()
        comment_only = text[:1] in (b"(", b";") or (text[:1] in (b"N", b"n") and re.match(rb"[Nn]\d+\s*[(;]", text))
        if comment_only:
            if _FINISH.search(text):
                state, moved = True, False
            elif state and moved:
                state = False
        flag[i] = state
        if state and moving[i]:
            moved = True
    return flag[rec["line"]]


SURFACE_SHARE = 0.05  # of a segment's engaged length: from this share on, it leaves a final surface
SURFACE_DZ = 0.005  # mm: a cell's final height this close to a step's tip is the floor that step left


def final_surface_steps(program, model, stock) -> np.ndarray:
    """Per engaged step of the fast model: does it leave a final surface — the floor under its
    tip, or the wall beside its edge, that no later move cuts again?  Read off the stock after
    the whole program (``stock.heights``, the Z-map the simulation cut): the floor is final where
    the cell under the tool's centre ends at the step's tip; the wall where a cell just beyond
    the tool's radius (1.5 cells, on either side of the direction of travel) ends above the tip.
    A roughing pass whose floor or wall a later pass cuts again (a deeper layer, the finishing
    allowance) leaves neither."""
    rec = program.records
    n = len(model.rec)
    if stock is None or not n:
        return np.zeros(n, bool)
    r, p = model.rec, model.pos
    sx, sy, sz = rec["sx"][r], rec["sy"][r], rec["sz"][r]
    ex, ey, ez = rec["x"][r], rec["y"][r], rec["z"][r]
    kind = rec["kind"][r]
    x, y, z = sx + p * (ex - sx), sy + p * (ey - sy), sz + p * (ez - sz)
    tx, ty = ex - sx, ey - sy
    arc = ((kind == R.ARC_CW) | (kind == R.ARC_CCW)) & (rec["plane"][r] == R.PLANE_XY)
    if arc.any():
        cx, cy = rec["cx"][r], rec["cy"][r]
        a0 = np.arctan2(sy - cy, sx - cx)
        a1 = np.arctan2(ey - cy, ex - cx)
        ccw = kind == R.ARC_CCW
        sweep = np.where(ccw, np.mod(a1 - a0, 2 * np.pi), -np.mod(a0 - a1, 2 * np.pi))
        sweep = np.where(np.abs(sweep) < 1e-9, np.where(ccw, 2 * np.pi, -2 * np.pi), sweep)  # a full circle
        ang = a0 + p * sweep
        rad = np.hypot(sx - cx, sy - cy)
        x = np.where(arc, cx + rad * np.cos(ang), x)
        y = np.where(arc, cy + rad * np.sin(ang), y)
        tx = np.where(arc, -np.sin(ang) * np.sign(sweep), tx)
        ty = np.where(arc, np.cos(ang) * np.sign(sweep), ty)
    norm = np.hypot(tx, ty)
    moving = norm > 1e-12
    nx = np.where(moving, -ty / np.where(moving, norm, 1.0), 0.0)
    ny = np.where(moving, tx / np.where(moving, norm, 1.0), 0.0)
    h = stock.heights
    res = float(stock.resolution)
    x0, y0 = float(stock.box[0]), float(stock.box[1])

    def height(px, py):
        ix = np.floor((px - x0) / res).astype(np.int64)
        iy = np.floor((py - y0) / res).astype(np.int64)
        inside = (ix >= 0) & (iy >= 0) & (ix < h.shape[1]) & (iy < h.shape[0])
        out = np.full(len(px), -np.inf)  # (outside the stock: nothing stands there)
        out[inside] = h[iy[inside], ix[inside]]
        return out

    floor = height(x, y) >= z - SURFACE_DZ
    d = 0.5 * model.diameter + 1.5 * res
    wall = moving & ((height(x + nx * d, y + ny * d) > z + SURFACE_DZ) |
                     (height(x - nx * d, y - ny * d) > z + SURFACE_DZ))
    return model.cutting & (floor | wall)


def contour_error(trace) -> np.ndarray:
    """Per trace sample, the contour error (mm): the part of the following-error vector normal
    to the commanded direction of travel (central differences of the command) — the
    simulator's own definition (``max_contour_error``); 0 where the command stands still."""
    cmd, err = getattr(trace, "cmd", None), getattr(trace, "err", None)
    if cmd is not None and err is not None and len(cmd) >= LONG_TRACE and cmd.shape[1] == 3:
        from ._segkernel import contour_samples

        out = np.zeros(len(cmd))
        if len(cmd) > 2:
            contour_samples(np.ascontiguousarray(cmd, np.float64), np.ascontiguousarray(err, np.float64), out)
        return out
    cx, cy, cz = (np.asarray(trace.signal(a + "_cmd")) for a in "xyz")
    ex, ey, ez = (np.asarray(trace.signal(a + "_err")) for a in "xyz")
    n = len(cx)
    out = np.zeros(n)
    if n < 3:
        return out
    dx = cx[2:] - cx[:-2]
    dy = cy[2:] - cy[:-2]
    dz = cz[2:] - cz[:-2]
    dn = np.sqrt(dx * dx + dy * dy + dz * dz)
    moving = dn > 1e-9
    inv = np.where(moving, 1.0 / np.where(moving, dn, 1.0), 0.0)
    dx *= inv
    dy *= inv
    dz *= inv
    e1, e2, e3 = ex[1:-1], ey[1:-1], ez[1:-1]
    a = e1 * dx + e2 * dy + e3 * dz
    nx = e1 - a * dx
    ny = e2 - a * dy
    nz = e3 - a * dz
    out[1:-1] = np.where(moving, np.sqrt(nx * nx + ny * ny + nz * nz), 0.0)
    return out


def line_ranges(lines: list[int], most: int = 8) -> str:
    """``3-7, 12, 20-31`` (the first ``most`` runs, then ``…``)."""
    runs: list[list[int]] = []
    for ln in lines:
        if runs and ln <= runs[-1][1] + 1:
            runs[-1][1] = ln
        else:
            runs.append([ln, ln])
    txt = [f"{a}" if a == b else f"{a}-{b}" for a, b in runs[:most]]
    return ", ".join(txt) + (", …" if len(runs) > most else "")


#: cell of the clearance map the program's own rapids prove (mm); coarser for a large area
CLEAR_CELL = 0.5
CLEAR_MAX_CELLS = 4_000_000


def proven_clear(program, cutting) -> np.ndarray:
    """Per record: a feed move the program itself proves clear of material — its whole sweep
    lies where the program's own horizontal rapids (G0 with XY motion) passed at or below the
    move's lowest height.  A rapid at height h over an area says nothing stands above h there
    (else the machine would crash), whatever the stock's size.

    A clearance map on a grid of CLEAR_CELL: each rapid's centreline at its height, widened by
    the smallest tool radius (the sweep it cleared); a move's centreline widened by the largest
    radius must lie in it, everywhere at or below the move's height there (to half a cell: a
    move along a rapid's own path with the same tool is proven)."""
    from scipy import ndimage

    rec = program.records
    n = len(rec)
    out = np.zeros(n, bool)
    rapid = (rec["kind"] == R.RAPID) & (np.hypot(rec["x"] - rec["sx"], rec["y"] - rec["sy"]) > 1e-6) & placed(rec)
    feed = R.is_feed_kind(rec["kind"])
    if not rapid.any() or not feed.any():
        return out
    radii = [cutting.tool(int(t)).radius for t in np.unique(rec["tool"])]
    r_min, r_max = min(radii), max(radii)
    pts_r, z_r = _xy_samples(rec, rapid, CLEAR_CELL)
    lo = pts_r.min(axis=0) - r_min - CLEAR_CELL
    hi = pts_r.max(axis=0) + r_min + CLEAR_CELL
    cell = max(CLEAR_CELL, math.sqrt(float(np.prod(hi - lo)) / CLEAR_MAX_CELLS))
    if cell > CLEAR_CELL:
        pts_r, z_r = _xy_samples(rec, rapid, cell)
    nx, ny = (int(math.ceil(v)) + 1 for v in (hi - lo) / cell)
    field = np.full((ny, nx), np.inf)
    ij = np.floor((pts_r - lo) / cell).astype(np.int64)
    np.minimum.at(field, (ij[:, 1], ij[:, 0]), z_r)

    def disc(r):
        k = max(int(math.floor(r / cell)), 0)
        yy, xx = np.mgrid[-k:k + 1, -k:k + 1]
        return (xx * xx + yy * yy) * cell * cell <= r * r

    # the lowest rapid over each cell of the cleared sweep, then the highest of those a tool
    # of the largest radius centred there would cover
    # (to the cell: a move along a rapid's own path, with the same tool, sweeps what it swept)
    cleared = ndimage.minimum_filter(field, footprint=disc(r_min + 0.5 * cell), mode="constant", cval=np.inf)
    need = ndimage.maximum_filter(cleared, footprint=disc(max(r_max - 0.5 * cell, 0.0)), mode="constant",
                                  cval=np.inf)
    idx = np.flatnonzero(feed)
    pts_f, z_f, which = _xy_samples(rec, feed, cell, with_index=True)
    ij = np.floor((pts_f - lo) / cell).astype(np.int64)
    inside = (ij[:, 0] >= 0) & (ij[:, 0] < nx) & (ij[:, 1] >= 0) & (ij[:, 1] < ny)
    h = np.full(len(pts_f), np.inf)
    h[inside] = need[ij[inside, 1], ij[inside, 0]]
    bad = np.zeros(n, bool)
    np.logical_or.at(bad, which, h > z_f + 1e-6)
    out[idx] = ~bad[idx]
    # an arc in another plane dips below its end points: not proven
    arc = (rec["kind"] == R.ARC_CW) | (rec["kind"] == R.ARC_CCW)
    out &= ~(arc & (rec["plane"] != R.PLANE_XY))
    return out


def placed(rec, axes: tuple = ("x", "y", "z")) -> np.ndarray:
    """Per record: does it start where the program put the tool?  The interpreter starts from an
    assumed point (the origin) while the machine stands wherever it was: a move before every axis
    has moved once runs from an unknown point (a first ``G0 X Y`` at the assumed Z0 proves nothing
    about Z0)."""
    if not len(rec):
        return np.zeros(0, bool)
    # (a G28/G30/G53 move goes to a machine position the twin can only assume — home is not the
    # work origin: after one, every axis must move again in work coordinates)
    n = len(rec)
    i = np.arange(n)
    mach = (rec["flags"] & R.FL_MACHINE) != 0
    last_mach = np.r_[-1, np.maximum.accumulate(np.where(mach, i, -1))[:-1]]
    out = ~mach
    for a in axes:
        moved = (np.abs(rec[a] - rec["s" + a]) > 1e-9) & ~mach
        last_moved = np.r_[-1, np.maximum.accumulate(np.where(moved, i, -1))[:-1]]
        out &= last_moved > last_mach
    return out


def _xy_samples(rec, mask, step: float, with_index: bool = False):
    """Points every ``step`` mm along the XY path of the records ``mask`` (arcs in XY along
    their arc), with each point's height (Z along the move) and record index."""
    idx = np.flatnonzero(mask)
    r = rec[idx]
    sx, sy, ex, ey = r["sx"], r["sy"], r["x"], r["y"]
    arc = ((r["kind"] == R.ARC_CW) | (r["kind"] == R.ARC_CCW)) & (r["plane"] == R.PLANE_XY)
    rad = np.hypot(sx - r["cx"], sy - r["cy"])
    a0 = np.arctan2(sy - r["cy"], sx - r["cx"])
    a1 = np.arctan2(ey - r["cy"], ex - r["cx"])
    cw = r["kind"] == R.ARC_CW
    sweep = np.where(cw, (a0 - a1) % (2 * np.pi), (a1 - a0) % (2 * np.pi))
    sweep = np.where(sweep < 1e-9, 2 * np.pi, sweep)  # (a full circle)
    length = np.where(arc, rad * sweep, np.hypot(ex - sx, ey - sy))
    count = np.maximum(np.ceil(length / (0.5 * step)).astype(np.int64), 1) + 1
    rid = np.repeat(np.arange(len(idx)), count)
    first = np.repeat(np.cumsum(count) - count, count)
    u = (np.arange(len(rid)) - first) / np.maximum(count[rid] - 1, 1)
    ang = a0[rid] + np.where(cw[rid], -1.0, 1.0) * sweep[rid] * u
    x = np.where(arc[rid], r["cx"][rid] + rad[rid] * np.cos(ang), sx[rid] + (ex[rid] - sx[rid]) * u)
    y = np.where(arc[rid], r["cy"][rid] + rad[rid] * np.sin(ang), sy[rid] + (ey[rid] - sy[rid]) * u)
    z = r["sz"][rid] + (r["z"] - r["sz"])[rid] * u
    pts = np.stack([x, y], axis=1)
    if with_index:
        return pts, z, idx[rid]
    return pts, z


def feed_height(program) -> float:
    """The lowest height the program itself descends to fast before it slows down to plunge:
    a vertical G0 followed by a vertical G1 down at the same XY, or a vertical G1 down followed
    by a slower one (Fusion 360 for personal use writes every rapid as G1 at the cutting
    feed: ``G1 Z5 F1000`` then ``Z3.07 F333.3``).  A CAM system slows at its feed height,
    which it puts above the stock: the program treats every height from there up as clear.
    ``inf`` when the program never slows down on a descent."""
    rec = program.records
    if len(rec) < 2:
        return math.inf
    vertical = (np.hypot(rec["x"] - rec["sx"], rec["y"] - rec["sy"]) < 1e-6) & (rec["z"] < rec["sz"] - 1e-6)
    a, b = rec[:-1], rec[1:]
    va, vb = vertical[:-1], vertical[1:]
    g0_then_g1 = (a["kind"] == R.RAPID) & (b["kind"] == R.LINEAR)
    slows = (a["kind"] == R.LINEAR) & (b["kind"] == R.LINEAR) & (b["feed"] < a["feed"] * 0.999)
    pair = va & vb & (g0_then_g1 | slows)
    return float(a["z"][pair].min()) if pair.any() else math.inf


#: mm above the highest material a plunge is proven to meet: where it slows to its own feed
#: (the CAM systems' feed height is 1–5 mm over the stock; the servo's lag at a plunge feed is
#: a tenth of a millimetre)
ENTRY_CLEARANCE = 1.0
ENTRY_MIN_AIR = 1.0  # mm of proven air a plunge must have before it is split (an extra line)


@dataclass(frozen=True)
class AirEntry:
    """A plunge whose upper part is proven air: it may run there at the air feed."""

    record: int
    line: int
    z_from: float  # the plunge's start height
    z_air: float  # down to here it is air (its end: the whole move is air)
    z_to: float  # its end height
    proven_by: str  # "feed height" | "earlier cuts" | "stock top"
    material: float  # the highest material it can meet (the feed height: at most there)

    @property
    def whole(self) -> bool:
        """All of the move is air (no cutting piece is left to write)."""
        return self.z_air <= self.z_to

    def as_dict(self) -> dict:
        return {"line": self.line, "from_z": self.z_from, "air_to_z": self.z_air, "to_z": self.z_to,
                "proven_by": self.proven_by, "material_z": self.material}


def air_entries(program, cutting, plunges: np.ndarray, described: set, clear_z: float,
                stock_top: float | None) -> list[AirEntry]:
    """Plunges (straight down at a feed) whose upper part is proven clear of material, and how far.

    Three proofs, the lowest that holds wins: above the program's own feed height
    (``feed_height``, where it descends fast); above a given stock's top plus ENTRY_CLEARANCE;
    above the material the program's earlier moves left under the plunging tool plus
    ENTRY_CLEARANCE — a tool that has been at height z over a point (any earlier move, rapid or
    feed, of a described tool) removed everything above z (plus its nose: a ball or bull nose,
    a vee's cone) there, whatever the real stock, so the highest of those heights over the
    plunging tool's footprint is the highest material it can meet.  A footprint point no earlier
    move covered gives no proof.  Segment samples are discrete, so a sweep is under-counted
    between them: the proof errs on the side of material."""
    from scipy.spatial import cKDTree

    from ..gcode.writer import MIN_PIECE

    rec = program.records
    where = placed(rec)
    # (a plunge from an assumed height proves nothing; its XY may be assumed: then every move
    # compared with it stands at the same assumed XY)
    idx = np.flatnonzero(plunges & placed(rec, ("z",)))
    if not len(idx):
        return []
    tools = {int(t): cutting.tool(int(t)) for t in np.unique(rec["tool"]) if int(t) in described}
    # the moves that prove: of a described tool, from a known start, not under cutter
    # compensation (the tool's centre is not the path), in XY (an arc in another plane dips)
    moves = (R.move_lengths(rec) > 0) & np.isin(rec["tool"], list(tools)) & where & \
        ((rec["flags"] & R.FL_COMP) == 0) & ((rec["kind"] == R.RAPID) | R.is_feed_kind(rec["kind"])) & \
        ~(((rec["kind"] == R.ARC_CW) | (rec["kind"] == R.ARC_CCW)) & (rec["plane"] != R.PLANE_XY))
    # coordinates compare only within one frame: the work offset (G54…, G92, G52), its origin
    # and rotation (two fixtures run the same code at the same coordinates)
    frame_key = np.stack([rec["wcs"].astype(float), rec["ox"], rec["oy"], rec["oz"], rec["rot"]], axis=1)
    frame = np.unique(np.round(frame_key, 9), axis=0, return_inverse=True)[1].reshape(-1)
    # only moves before the last plunge whose sweep can reach a plunge's footprint are sampled
    # (a 100,000-move raster with one plunge at its start samples none)
    moves &= np.arange(len(rec)) < int(idx.max())
    if tools and moves.any():
        reach = max(t.radius for t in tools.values()) * 2.0
        arc = (rec["kind"] == R.ARC_CW) | (rec["kind"] == R.ARC_CCW)
        rad_arc = np.where(arc, np.hypot(rec["sx"] - rec["cx"], rec["sy"] - rec["cy"]), 0.0)
        lo_x = np.where(arc, rec["cx"] - rad_arc, np.minimum(rec["sx"], rec["x"])) - reach
        hi_x = np.where(arc, rec["cx"] + rad_arc, np.maximum(rec["sx"], rec["x"])) + reach
        lo_y = np.where(arc, rec["cy"] - rad_arc, np.minimum(rec["sy"], rec["y"])) - reach
        hi_y = np.where(arc, rec["cy"] + rad_arc, np.maximum(rec["sy"], rec["y"])) + reach
        near_any = np.zeros(len(rec), bool)
        for r in idx:
            px, py = rec["x"][r], rec["y"][r]
            near_any |= (lo_x <= px) & (px <= hi_x) & (lo_y <= py) & (py <= hi_y)
        moves &= near_any
    tree = None
    if tools and moves.any():
        r_min = min(t.radius for t in tools.values())
        pts, zs, which = _xy_samples(rec, moves, max(0.25 * r_min, 0.02), with_index=True)
        rad = np.array([tools[int(t)].radius for t in rec["tool"][which]])
        rise = np.array([_rise(tools[int(t)]) for t in rec["tool"][which]])
        tree = cKDTree(pts)
        r_max = float(rad.max())
        frame_of = frame[which]
    out = []
    for r in idx:
        z0, z1 = float(rec["sz"][r]), float(rec["z"][r])
        cands = []
        if math.isfinite(clear_z) and z0 > clear_z:
            cands.append((clear_z, "feed height", clear_z))
        if stock_top is not None:
            cands.append((stock_top + ENTRY_CLEARANCE, "stock top", stock_top))
        t = int(rec["tool"][r])
        if tree is not None and t in tools:
            c = np.array([rec["x"][r], rec["y"][r]])
            near = np.asarray(tree.query_ball_point(c, tools[t].radius + r_max), dtype=np.int64)
            near = near[(which[near] < r) & (frame_of[near] == frame[r])] if len(near) else near
            if len(near):
                top = _highest_left(c, tools[t].radius, pts[near], zs[near] + rise[near], rad[near])
                if math.isfinite(top):
                    cands.append((top + ENTRY_CLEARANCE, "earlier cuts", top))
        if not cands:
            continue
        z_air, why, material = min(cands)
        z_air = z1 if z_air < z1 + MIN_PIECE else z_air  # (a cutting piece too short to write: all air)
        if z0 - z_air < ENTRY_MIN_AIR:
            continue
        out.append(AirEntry(int(r), int(rec["line"][r]), z0, z_air, z1, why, material))
    return out


def _highest_left(c: np.ndarray, radius: float, pts: np.ndarray, tops: np.ndarray, rad: np.ndarray) -> float:
    """The highest material earlier sweeps can have left under a tool of ``radius`` at ``c``:
    over every point of its footprint, the lowest top of a sweep covering it; inf where one is
    not covered.  Inner grid points must be covered with the grid's half-diagonal to spare (so
    no uncut wall thinner than the grid hides between them); the rim, exactly.  In blocks of
    sweep samples (memory stays bounded near a dense raster)."""
    disc, h = _footprint(c, radius)
    margin = np.where(np.hypot(disc[:, 0] - c[0], disc[:, 1] - c[1]) < radius - 1e-9, h / math.sqrt(2.0), -1e-9)
    low = np.full(len(disc), np.inf)
    block = max(1, 4_000_000 // max(len(disc), 1))
    for k in range(0, len(pts), block):
        p, tp, rd = pts[k:k + block], tops[k:k + block], rad[k:k + block]
        d = np.hypot(disc[:, None, 0] - p[None, :, 0], disc[:, None, 1] - p[None, :, 1])
        cover = d <= rd[None, :] - margin[:, None]
        low = np.minimum(low, np.where(cover, tp[None, :], np.inf).min(axis=1))
    return float(low.max())


def _rise(tool) -> float:
    """Height above its tip at which a tool's bottom reaches its full radius."""
    if tool.type == "vee":
        return (tool.radius - tool.tip_radius) * tool.cot_half_angle
    return tool.nose_radius


def _footprint(c: np.ndarray, radius: float) -> tuple[np.ndarray, float]:
    """Points covering a tool's disc, and their spacing: a grid (at most 0.5 mm, a fifth of the
    radius apart) of the cells wholly inside the disc, and its rim (64 points)."""
    h = max(min(0.2 * radius, 0.5), 1e-3)
    k = int(math.ceil(radius / h))
    g = np.arange(-k, k + 1) * h
    xx, yy = np.meshgrid(g, g)
    inside = np.hypot(xx, yy) <= radius - h / math.sqrt(2.0)
    ang = np.linspace(0.0, 2 * np.pi, 64, endpoint=False)
    rim = np.stack([radius * np.cos(ang), radius * np.sin(ang)], axis=1)
    return c + np.concatenate([np.stack([xx[inside], yy[inside]], axis=1), rim]), h
