"""Stock and engagement along a planned path, computed once and reused.

``engagement_for(plan, program, cutting, cache=...)`` returns an :class:`Engagement`: per
path step the force sums of ``_engagekernel`` (independent of F, S and the material) and the
Z-map after the last cut.  An :class:`EngagementCache` (each ``Twin`` owns one) keys it on the
path geometry, the tools, the stock and the resolution, so a re-simulation with new F and S
values — what the optimiser does thousands of times — never touches the stock.  The cache's
``computations`` counts real computations (a test watches it).
"""
from __future__ import annotations

import hashlib
import math
import re
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError, GCodeError, SourceLocation
from ..layout import ANGLE_BINS, PAUSE
from . import _engagekernel as EK
from .library import Cutting, parse_box

MAX_CELLS = 60_000_000  # 240 MB of float32 heights
N_BINS = ANGLE_BINS  # 2° angular bins (layout: the wear's sliding counts them too)


@dataclass
class Stock:
    box: tuple[float, ...]  # xmin, ymin, zmin, xmax, ymax, zmax (mm, work coordinates)
    resolution: float  # mm
    heights: np.ndarray  # (ny, nx) float32, top of the remaining material per cell
    source: str  # where the box came from

    @property
    def origin(self) -> tuple[float, float]:
        return self.box[0], self.box[1]


@dataclass
class Engagement:
    first: np.ndarray  # (nseg,) first step of each segment
    count: np.ndarray  # (nseg,) steps of each segment (0: not cutting)
    sums: np.ndarray  # (steps, 18) float32 force sums, see _engagekernel
    q: np.ndarray  # (steps, 6) float32 area, ae, ap, w_max, feed direction x, y
    tools: np.ndarray  # (ntools, 3) radius, nose radius, flutes
    tool_index: np.ndarray  # (nseg,) row of ``tools`` for each segment
    tool_numbers: tuple[int, ...]
    stock: Stock
    step: float
    cells_changed: int
    seconds: float
    prof: np.ndarray  # (steps, slices, bins) engaged lengths for tooth-passing resolution, or empty
    slices: tuple  # (starts, kind, kappa, r, z_lo, z_hi, d_rho) of every tool's edge slices
    helix: np.ndarray  # (ntools,) tan of the helix angle
    warnings: list
    motion: np.ndarray | None = None  # indices of the plan's motion segments the arrays were made for
    # the plan segments of every rapid that goes through stock standing then (a crash; the
    # stock proof holds a rewrite's against the original's)
    rapid_segments: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    @property
    def steps(self) -> int:
        return len(self.sums)

    def step_segments(self) -> np.ndarray:
        """The plan segment of every step (a segment's steps are ``first[i]`` … ``first[i] +
        count[i] − 1``)."""
        has = np.flatnonzero(self.count > 0)
        c = self.count[has]
        out = np.empty(int(c.sum()), np.int64)
        if len(has):
            within = np.arange(len(out)) - np.repeat(np.cumsum(c) - c, c)
            out[np.repeat(self.first[has], c) + within] = np.repeat(has, c)
        return out

    def for_plan(self, plan) -> "Engagement":
        """This engagement for a plan with the same motion segments but other pauses (a spindle
        speed change adds a run-up pause): the per-segment arrays re-indexed."""
        motion = np.flatnonzero(plan.seg["kind"] != PAUSE)
        if self.motion is None or (len(motion) == len(self.motion) and len(plan.seg) == len(self.first)
                                   and np.array_equal(motion, self.motion)):
            return self
        n = len(plan.seg)
        first = np.zeros(n, np.int64)
        count = np.zeros(n, np.int64)
        tool_index = np.zeros(n, np.int64)
        first[motion] = self.first[self.motion]
        count[motion] = self.count[self.motion]
        tool_index[motion] = self.tool_index[self.motion]
        from dataclasses import replace

        return replace(self, first=first, count=count, tool_index=tool_index, motion=motion)


_STOCK_COMMENT = re.compile(rb"\(\s*MTWIN\s+STOCK\s+([^)]*)\)", re.IGNORECASE)


def stock_from_program(program) -> tuple[tuple[float, ...], int] | None:
    """The ``(MTWIN STOCK xmin,ymin,zmin,xmax,ymax,zmax)`` comment of a program, with its line."""
    m = _STOCK_COMMENT.search(program.data)
    if not m:
        return None
    line = program.data.count(b"\n", 0, m.start()) + 1
    try:
        box = parse_box(m.group(1).decode("ascii", "replace"), "MTWIN STOCK comment")
    except ConfigError as exc:
        raise GCodeError(str(exc), SourceLocation(program.path, line, m.start() - program.data.rfind(b"\n", 0, m.start())))
    return box, line


def _tool_rows(plan, program, cutting: Cutting):
    rec = program.records
    seg = plan.seg
    nums = rec["tool"][seg["rec"]] if len(seg) else np.zeros(0, np.int32)
    cutting_seg = (seg["kind"] != PAUSE) & (seg["rapid"] == 0)
    used = [int(t) for t in np.unique(nums[cutting_seg])]
    table = []
    for t in used:
        where_i = int(np.nonzero(cutting_seg & (nums == t))[0][0])
        table.append(cutting.tool(t, f"{program.path}:{int(seg['line'][where_i])}: "))
    if not table:  # no feed move: any tool row will do, none is read
        table.append(next(iter(cutting.tools.values()), None) or cutting.tool(0))
    # (the row of each segment's tool; a tool that never cuts reads row 0, like no tool)
    tool_index = np.zeros(len(nums), np.int64)
    if used:
        ua = np.array(used)
        pos = np.minimum(np.searchsorted(ua, nums), len(ua) - 1)
        found = ua[pos] == nums
        tool_index[found] = pos[found]  # (row k holds used[k])
    return table, tool_index, tuple(used)


#: where a stock nobody gave comes from: the one wording every message uses
GUESSED_STOCK = "guessed from the feed moves (their extent and the tool radius, top at Z0)"


def default_stock(plan, tools) -> tuple[float, ...]:
    """XY: bounding box of the feed moves grown by the largest tool radius; top at Z0 (the usual
    CAM convention); bottom 1 mm below the deepest feed move (or at Z-1)."""
    box = getattr(plan, "feed_box", None)
    if box is None:
        return (-1.0, -1.0, -1.0, 1.0, 1.0, 0.0)
    lo, hi = box[0], box[1]
    rmax = max(t.radius for t in tools)
    return (float(lo[0] - rmax), float(lo[1] - rmax), float(min(lo[2], 0.0) - 1.0),
            float(hi[0] + rmax), float(hi[1] + rmax), 0.0)


def stock_box(plan, program, cutting: Cutting, tools, box=None) -> tuple[tuple[float, ...], float, str]:
    """(box, resolution, where the box came from): --stock > program comment > twin file > default."""
    source = "--stock"
    if box is None:
        found = stock_from_program(program)
        read = _stock_comment(program, plan) if not found else None
        if found:
            box, line = found
            source = f"(MTWIN STOCK) comment, line {line}"
        elif read is not None:
            box, source = read
        elif cutting.stock is not None:
            box, source = cutting.stock, "twin file cutting.stock"
        else:
            box, source = default_stock(plan, tools), GUESSED_STOCK
    from ..params import UNIT_MAX

    far = [v for v in box if not abs(v) <= UNIT_MAX["mm"]]
    if far:  # (a box of 1e99 mm overflows the Z-map's cell count)
        raise ConfigError(f"stock box ({source}): {far[0]:g} mm is beyond what a machine has (at most "
                          f"{UNIT_MAX['mm']:g} mm): a typo or a unit mistake?")
    res = cutting.resolution
    area = (box[3] - box[0]) * (box[4] - box[1])
    if res <= 0:
        dmin = min(t.diameter for t in tools)
        res = min(0.1, max(0.02, dmin / 120.0))
        # a large stock gets coarser cells rather than more memory than MAX_CELLS allows
        res = max(res, math.sqrt(area / MAX_CELLS) * 1.001)
    nx = int(math.ceil((box[3] - box[0]) / res))
    ny = int(math.ceil((box[4] - box[1]) / res))
    if nx * ny > MAX_CELLS:
        res_new = math.sqrt((box[3] - box[0]) * (box[4] - box[1]) / MAX_CELLS) * 1.001
        raise ConfigError(f"stock {box[3] - box[0]:g} x {box[4] - box[1]:g} mm at {res:g} mm needs {nx * ny / 1e6:.0f} "
                          f"million cells (limit {MAX_CELLS / 1e6:.0f}); set cutting.resolution to {res_new:.3f} mm or more")
    return tuple(box), res, source


def _stock_comment(program, plan):
    """(box, source) of a stock the program's comments give in a CAM system's form
    (``cutting.workpiece``), or None."""
    from .workpiece import place_size, read_workpiece

    f = read_workpiece(program).stock
    if f is None:
        return None
    box = f.value
    if len(box) == 3:  # a size (Vectric): placed where it holds the toolpath
        fb = getattr(plan, "feed_box", None)
        box = place_size(box, fb) if fb is not None else None
        if box is None:
            return None
    return tuple(box), f"{f.form} comment, line {f.line}"


def new_stock(box, res, source) -> Stock:
    nx = int(math.ceil((box[3] - box[0]) / res))
    ny = int(math.ceil((box[4] - box[1]) / res))
    return Stock(tuple(box), res, np.full((ny, nx), box[5], np.float32), source)


def _check_inside(plan, b, source: str, path: str) -> None:
    """A feed move whose tip goes below the stock bottom inside its footprint means the stock
    does not contain the toolpath (wrong box, units or offsets)."""
    seg = plan.tip_seg
    feed = (seg["kind"] != PAUSE) & (seg["rapid"] == 0)
    for pts in (seg["p0"], seg["p1"]):
        inside = feed & (pts[:, 0] >= b[0]) & (pts[:, 0] <= b[3]) & (pts[:, 1] >= b[1]) & (pts[:, 1] <= b[4])
        below = inside & (pts[:, 2] < b[2] - 1e-9)
        if below.any():
            i = int(np.argmax(below))
            raise GCodeError(f"the tool reaches Z = {pts[i, 2]:.3f} mm, below the stock bottom Z = {b[2]:g} mm "
                             f"(stock {b} from {source}): the stock does not contain the toolpath",
                             SourceLocation(path, int(seg["line"][i]), 1))


def _key(plan, program, tools, tool_index, box, res, step) -> str:
    """What the engagement depends on, and nothing that a new F or S changes.

    The motion segments only: pauses (a spindle speed change's run-up) do not change what is
    cut, and :meth:`Engagement.for_plan` re-indexes around them.  Segments by their
    *structure* (kind, record, blend arc or not) and the records' programmed geometry, not by
    the planner's trimmed end points: under the LinuxCNC planner a blend's size depends on the
    feed (up to 0.9 mm of trim on pocket.nc between F and 1.2 F), which must not make every
    optimiser candidate compute its own engagement.  The kernel maps a segment's steps by the
    fraction of its length, so a plan with the same structure and other trims reads the cached
    steps at the same fraction of each segment — an error bounded by the trim change, itself
    within the G64 tolerance.  A feed that makes a blend swallow a whole line changes the
    structure, and that plan gets its own engagement."""
    seg = plan.tip_seg
    motion = seg["kind"] != PAUSE
    seg = seg[motion]
    tool_index = tool_index[motion]
    rec = program.records[seg["rec"]] if len(seg) else program.records[:0]
    h = hashlib.blake2b(digest_size=20)
    for name in ("kind", "rapid", "rec", "blend"):
        h.update(np.ascontiguousarray(seg[name]).tobytes())
    for name in ("kind", "plane", "turns", "sx", "sy", "sz", "x", "y", "z", "cx", "cy", "cz", "ox", "oy", "oz",
                 "rot", "comp", "comp_r", "path_tol", "cam_tol"):
        h.update(np.ascontiguousarray(rec[name]).tobytes())
    if plan.tip_shift is not None and len(seg):
        h.update(np.ascontiguousarray(plan.tip_shift[seg["rec"]]).tobytes())
    h.update(tool_index.tobytes())
    h.update(np.asarray(rec["spindle_dir"] < 0).tobytes())
    h.update(repr((tuple((t.type, t.diameter, t.corner_radius, t.flutes, t.flute_length, t.angle, t.tip_diameter)
                         for t in tools),
                   tuple(box), res, step)).encode())
    return h.hexdigest()


MAX_PROFILE_BYTES = 1.5e9


class EngagementCache:
    """The few most recent engagements of a twin, by path key; ``computations`` counts misses."""

    def __init__(self, size: int = 4):
        self.size = size
        self.entries: dict[str, Engagement] = {}
        self.computations = 0

    def get(self, key: str) -> Engagement | None:
        return self.entries.get(key)

    def put(self, key: str, eng: Engagement) -> None:
        if len(self.entries) >= self.size:
            self.entries.pop(next(iter(self.entries)))
        self.entries[key] = eng


def engagement_for(plan, program, cutting: Cutting, box=None, tooth: bool = False,
                   cache: EngagementCache | None = None) -> Engagement:
    """Engagement of a planned program, from the cache when the geometry is unchanged.

    ``tooth``: also keep the engaged length per slice and angular bin of every step, for
    instantaneous (tooth-passing) forces."""
    tools, tool_index, numbers = _tool_rows(plan, program, cutting)
    box, res, source = stock_box(plan, program, cutting, tools, box)
    _check_inside(plan, box, source, program.path)
    step = cutting.step if cutting.step > 0 else 2.0 * res
    key = _key(plan, program, tools, tool_index, box, res, step) + ("-tooth" if tooth else "")
    if cache is not None:
        hit = cache.get(key)
        if hit is not None:
            return hit.for_plan(plan)
        cache.computations += 1
    stock = new_stock(box, res, source)
    t0 = time.perf_counter()
    seg = plan.tip_seg  # the tool tip cuts, wherever the tool offsets put the axes
    cuts = ((seg["kind"] != PAUSE) & (seg["rapid"] == 0)).astype(np.int64)
    n_steps = int(np.sum(np.where(cuts == 1, np.maximum(1, np.ceil(seg["length"] / step)), 0)))
    table = np.array([[t.radius, t.nose_radius, t.flutes, t.tip_radius, t.cot_half_angle] for t in tools], np.float64)
    starts = [0]
    cols = [[], [], [], [], [], [], []]
    for t in tools:
        parts = EK.slice_table(t.radius, t.nose_radius, t.flute_length, stock.resolution, t.tip_radius, t.half_angle)
        for c, p in zip(cols, parts):
            c.append(p)
        starts.append(starts[-1] + len(parts[0]))
    skind, skap, sr, szlo, szhi, sdrho, srq = (np.concatenate(c) for c in cols)
    hand = np.where(program.records["spindle_dir"][seg["rec"]] < 0, -1.0, 1.0) if len(seg) else np.zeros(0)
    first = np.zeros(len(seg), np.int64)
    count = np.zeros(len(seg), np.int64)
    # float32 halves the memory of an hour's million steps; 7 digits are plenty for force sums
    sums = np.zeros((max(n_steps, 1), EK.N_SUMS), np.float32)
    q = np.zeros((max(n_steps, 1), EK.N_Q), np.float32)
    nsl_max = max(starts[k + 1] - starts[k] for k in range(len(tools)))
    if tooth:
        need = n_steps * nsl_max * N_BINS * 4
        if need > MAX_PROFILE_BYTES:
            raise ConfigError(f"tooth-passing resolution over {n_steps:,} path steps needs {need / 1e9:.1f} GB of "
                              f"engagement profiles (limit {MAX_PROFILE_BYTES / 1e9:.1f} GB): simulate a shorter "
                              f"program or section, or use the revolution average")
        prof = np.zeros((max(n_steps, 1), nsl_max, N_BINS), np.float32)
    else:
        prof = np.zeros((0, nsl_max, N_BINS), np.float32)
    H = stock.heights
    collide = np.full(max(len(seg), 1), -1, np.int64)  # per segment: a rapid through stock
    n, cells = EK.engage_path(H, stock.box[0], stock.box[1], stock.resolution,
                              seg["kind"].astype(np.int64), cuts, np.ascontiguousarray(seg["p0"]),
                              np.ascontiguousarray(seg["p1"]), np.ascontiguousarray(seg["c"]),
                              np.ascontiguousarray(seg["e1"]), np.ascontiguousarray(seg["e2"]),
                              np.ascontiguousarray(seg["h"]), seg["r0"].copy(), seg["r1"].copy(),
                              seg["theta"].copy(), seg["length"].copy(), tool_index, hand, table,
                              np.array(starts, np.int64), skind, skap, sr, szlo, szhi, sdrho, srq,
                              EK.trig_table(N_BINS), step, N_BINS, first, count, sums, q, prof, collide)
    helix = np.array([math.tan(math.radians(t.helix)) for t in tools])
    warnings = []
    crashes = np.flatnonzero(collide[:len(seg)] >= 0)
    if crashes.size:
        from ..errors import warning_text

        warnings.append(warning_text(program.path, int(seg['line'][crashes[0]]),
                                     "a rapid move goes through the stock (the tool would crash; rapids remove "
                                     "no material in the twin)"))
    eng = Engagement(first, count, sums[:n], q[:n], table, tool_index, numbers, stock, step, int(cells),
                     time.perf_counter() - t0, prof[:n] if tooth else prof,
                     (np.array(starts, np.int64), skind, skap, sr, szlo, szhi, sdrho), helix, warnings,
                     np.flatnonzero(seg["kind"] != PAUSE),
                     crashes)
    if cache is not None:
        cache.put(key, eng)
    return eng
