"""The NCK: from motion records to a timed, velocity-planned path (a :class:`Plan`).

Stages, in the order a controller runs them:

1. segments from records, and pauses for dwell, tool change and spindle run-up;
2. per-segment limits: programmed feed, axis velocity and acceleration projected on
   the move, arc centripetal acceleration, the shortest block time;
3. corners: LinuxCNC-style blend arcs (path changes inside the G64 tolerance), or
   corner speeds by the allowable velocity change (Fanuc) or junction deviation (Grbl);
   exact stops for G61/G9, rapids and pauses;
4. look-ahead passes over a window of blocks;
5. S-curve (or trapezoidal) timing of every segment.

Everything per segment is a numpy array; the heavy loops are the kernels in
``_plankernel``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..gcode import records as R
from ..layout import N_PROF
from . import _plankernel as K
from .path import (ARC, CAT_DWELL, CAT_SPINDLE, CAT_TOOL, CATEGORY_NAMES, LINE, PAUSE, SEG_DTYPE,
                   check_feeds, check_travel, motion_segments)

STYLE_CODES = {"fanuc": K.STYLE_FANUC, "linuxcnc": K.STYLE_LINUXCNC, "grbl": K.STYLE_GRBL}
_MIN_LENGTH = 1e-9  # mm: moves shorter than this are dropped (a nanometre is below any servo)


@dataclass
class Plan:
    """A planned program: segments with their timing, ready for the servo-rate loop."""

    seg: np.ndarray  # SEG_DTYPE
    prof: np.ndarray  # (n, 10) per-segment S-curve parameters, see _plankernel.segment_timing
    dur: np.ndarray  # (n,) s, motion + hold, or pause time
    hold: np.ndarray  # (n,) s, in-position wait after a stop (after-interpolation filter drain)
    t_start: np.ndarray  # (n,) s
    stop_end: np.ndarray  # (n,) bool: the segment ends in an exact stop (in-position check)
    start_point: np.ndarray  # (3,) mm, where the program starts
    warnings: list[str] = field(default_factory=list)
    # (records, 3) mm: axes' path minus each record's tool tip (tool offset changes); None: 0
    tip_shift: np.ndarray | None = None
    # (2, 3) mm: lowest and highest point of the feed moves' tool tip before corner blending
    # (the default stock's extent must not move with the feed-dependent blend trims); None: none
    feed_box: np.ndarray | None = None
    # the feed-independent stages' output (common-frame records, tip shift, assembled segments,
    # feed box, their warnings, the machine): a plan of the same path at other feeds starts
    # from it (plan_program's ``like``)
    geometry: tuple | None = field(default=None, repr=False, compare=False)

    @property
    def tip_seg(self) -> np.ndarray:
        """The segments as the tool tip runs them (what the cutting model needs): ``seg``
        with each segment moved back by its record's tool-offset change."""
        if self.tip_shift is None or not self.tip_shift.any() or not len(self.seg):
            return self.seg
        out = self.seg.copy()
        d = self.tip_shift[np.clip(self.seg["rec"], 0, len(self.tip_shift) - 1)]
        for name in ("p0", "p1", "c"):
            out[name] = out[name] - d
        return out

    @property
    def total_time(self) -> float:
        return float(self.t_start[-1] + self.dur[-1]) if len(self.dur) else 0.0

    def category_times(self, wait: np.ndarray | None = None) -> dict[str, float]:
        """Seconds per category (rapid, cutting, dwell, tool_change, spindle_wait); ``wait``:
        in-position waits per segment from a simulation, counted with their segment."""
        d = self.dur if wait is None else self.dur + wait
        out = {}
        for code, name in enumerate(CATEGORY_NAMES):
            out[name] = float(d[self.seg["cat"] == code].sum())
        return out


def _axis_limits(machine):
    vel = np.array([ax.max_velocity / 60.0 for ax in machine.axes])
    acc = np.array([ax.max_acceleration for ax in machine.axes])
    return vel, acc


def _motion_limits(seg: np.ndarray, machine, linuxcnc: bool = False) -> np.ndarray:
    """Fill vmax (mm/s) and amax (mm/s², tangential) of every motion segment; return each
    segment's acceleration budget on an arc (the axes' in the arc's plane; NaN elsewhere), which
    :func:`_arcs_at_their_speed` shares out again at the speed the arc runs.

    ``linuxcnc``: circles get half the acceleration as their tangential limit whatever
    their speed (LinuxCNC 2.9's tpGetScaledAccel) instead of what the centripetal part
    leaves over."""
    c = machine.controller
    vel, acc = _axis_limits(machine)
    n = len(seg)
    vmax = np.full(n, np.inf)
    amax = np.full(n, np.inf)
    line = seg["kind"] == LINE
    u = np.abs(seg["u0"])
    with np.errstate(divide="ignore"):
        vline = np.min(np.where(u > 1e-12, vel / np.maximum(u, 1e-300), np.inf), axis=1)
        aline = np.min(np.where(u > 1e-12, acc / np.maximum(u, 1e-300), np.inf), axis=1)
    vmax[line] = vline[line]
    amax[line] = aline[line]
    if getattr(c, "rapid_acceleration", 0.0) > 0:
        # rapids run on their own acc/dec (each axis' rapid acceleration, along the move)
        with np.errstate(divide="ignore"):
            arap = c.rapid_acceleration / np.maximum(np.max(u, axis=1), 1e-300)
        r = line & (seg["rapid"] == 1)
        amax[r] = arap[r]
    arc = seg["kind"] == ARC
    if arc.any():
        a = seg[arc]
        in_plane = (np.abs(a["e1"]) + np.abs(a["e2"])) > 1e-12
        v_arc = np.min(np.where(in_plane, vel, np.inf), axis=1)
        a_arc = np.min(np.where(in_plane, acc, np.inf), axis=1)
        # helical rise: the normal axis moves at rise/L of the path speed
        rise = np.abs(a["h"])
        frac = np.where(rise > 0, rise / np.maximum(a["length"], 1e-300)[:, None], 0.0)
        with np.errstate(divide="ignore"):
            v_arc = np.minimum(v_arc, np.min(np.where(frac > 1e-12, vel / np.maximum(frac, 1e-300), np.inf), axis=1))
            a_arc = np.minimum(a_arc, np.min(np.where(frac > 1e-12, acc / np.maximum(frac, 1e-300), np.inf), axis=1))
        vmax[arc] = v_arc
        amax[arc] = a_arc
    if c.max_path_velocity > 0:
        vmax = np.minimum(vmax, c.max_path_velocity / 60.0)
    if c.max_path_acceleration > 0:
        amax = np.minimum(amax, c.max_path_acceleration)
    feed = seg["feed"]
    vmax = np.where((seg["rapid"] == 0) & (feed > 0), np.minimum(vmax, feed), vmax)
    budget = np.full(n, np.nan)
    if arc.any():
        # centripetal limit: v²/r <= a·√(1 − 0.5²) and the tangential acceleration left over
        # (LinuxCNC's split of the acceleration budget on circles; the total stays <= a).  A
        # control with its own normal-acceleration limit on feed arcs uses that instead, set apart
        # from the acceleration along the path as Fanuc's AI contour control sets parameter 1735
        # apart from 1660, so it may exceed a (the Hurco's does); a spiral (an end point off the
        # circle, tolerated by the interpreter) may have its own
        a = seg[arc]
        r = np.minimum(a["r0"], a["r1"])
        a_axis = amax[arc]
        a_normal = K._ACC_RATIO_NORMAL * a_axis
        cut = a["rapid"] == 0
        if c.arc_acceleration > 0:
            a_normal = np.where(cut, c.arc_acceleration, a_normal)
        spiral = cut & (np.abs(a["r1"] - a["r0"]) > c.spiral_min)
        if c.spiral_acceleration > 0:
            a_normal = np.where(spiral, c.spiral_acceleration, a_normal)
        v = np.minimum(vmax[arc], np.sqrt(a_normal * r))
        if c.arc_jerk > 0:  # each axis' jerk on a circle is v³/r²
            v = np.where(cut, np.minimum(v, np.cbrt(c.arc_jerk * r * r)), v)
        if c.spiral_block_time > 0 or c.spiral_jerk > 0:
            # the control spends this much longer on each spiral block than its path takes — a
            # time of its own, and its normal acceleration v²/r ramped anew at spiral_jerk: a
            # block of length L run at v takes L/v + t, i.e. runs at L/(L/v + t)
            t = c.spiral_block_time + (v * v / np.maximum(r, 1e-300) / c.spiral_jerk if c.spiral_jerk > 0 else 0.0)
            v = np.where(spiral, a["length"] / (a["length"] / np.maximum(v, 1e-300) + t), v)
        vmax[arc] = v
        amax[arc] = a_axis * (K._ACC_RATIO_TAN if linuxcnc else _tangential_share(v * v / np.maximum(r, 1e-300), a_axis))
        budget[arc] = a_axis
    if c.min_block_time > 0:
        vmax = np.minimum(vmax, seg["length"] / c.min_block_time)
    seg["vmax"] = vmax
    seg["amax"] = amax
    return budget


def _tangential_share(a_n: np.ndarray, a_axis: np.ndarray) -> np.ndarray:
    """The share of an arc's acceleration budget left along the path where v²/r is ``a_n``: what
    keeps the total within it, √(1 − (a_n/a)²), and at least half (LinuxCNC's split) where the
    normal part takes more than √0.75 of it."""
    return np.where(a_n > K._ACC_RATIO_NORMAL * a_axis, K._ACC_RATIO_TAN,
                    np.sqrt(np.clip(1.0 - (a_n / a_axis) ** 2, 0.0, 1.0)))


ARC_SHARE_PASSES = 3  # look-ahead passes that share an arc's budget out at the speed it reaches


def _arcs_at_their_speed(seg, budget, vj, length, is_pause, tb, window, ve):
    """Junction speeds, with each feed arc's acceleration along the path shared out at the
    highest speed it reaches rather than at its speed limit.

    An arc's budget is split between v²/r and the acceleration along the path; the limits take
    the normal part at the arc's top speed, which an arc that runs far below it never reaches:
    a short arc into a cusp (the NIST plates' 1-mm arcs meeting at 90°, run down to 5 mm/s from
    a limit of 34) has nearly all of it to brake and accelerate with.  The top speed of each arc
    is bounded from its end speeds and length at the whole budget (no share can do more), the
    share taken there, and the look-ahead run again, a few times over (the speeds rise with the
    shares, the shares fall with the speeds, so the passes alternate about the answer).  The
    last look-ahead may leave an arc faster than the speed its share was taken at: there the
    share is taken again at the final speeds and the look-ahead run once more, which only lowers
    speeds, so every arc ends within its budget."""
    arc = np.flatnonzero(np.isfinite(budget) & (seg["rapid"] == 0) & ~is_pause)
    if not arc.size:
        return ve
    r = np.maximum(np.minimum(seg["r0"], seg["r1"])[arc], 1e-300)
    a_axis = budget[arc]

    def shares(ve):
        v_in = np.concatenate(([0.0], ve[:-1]))[arc]
        top = np.minimum(seg["vmax"][arc], np.sqrt(0.5 * (v_in ** 2 + ve[arc] ** 2) + a_axis * length[arc]))
        return a_axis * _tangential_share(top * top / r, a_axis)

    def look():
        return K.lookahead.auto(len(seg), vj, length, np.where(is_pause, 1.0, seg["amax"]), tb, window)

    for _ in range(ARC_SHARE_PASSES):
        share = shares(ve)
        if np.allclose(share, seg["amax"][arc], rtol=1e-6, atol=0.0):
            return ve
        seg["amax"][arc] = share
        ve = look()
    share = shares(ve)
    over = share < seg["amax"][arc]
    if over.any():
        seg["amax"][arc] = np.minimum(seg["amax"][arc], share)
        ve = look()
    return ve


def _m_lines(program, *codes: float) -> np.ndarray | None:
    """Sorted 1-based lines holding an M word of ``codes``, for a plain program (a macro
    program's lexed text is the expanded one, whose lines are not the file's): None when not
    known."""
    if getattr(program, "expanded", None) is not None or getattr(program, "lexed", None) is None:
        return None
    lx = program.lexed
    m = (lx.w_letter == ord("M")) & np.isin(lx.w_value, codes)
    return np.unique(lx.w_line[m].astype(np.int64) + 1)


def _last_within(lines: np.ndarray | None, lo: int, hi: int) -> int | None:
    """The last of the sorted ``lines`` within lo..hi (inclusive), None if none (or not known)."""
    if lines is None or not lines.size:
        return None
    k = int(np.searchsorted(lines, hi, "right")) - 1
    return int(lines[k]) if k >= 0 and lines[k] >= lo else None


def runup_time(n0: float, n1: float, acceleration: float, power_speed: float = 0.0, braking: float = 0.0) -> float:
    """Seconds for the spindle to go from n0 to n1 rpm (signed): at ``acceleration`` rpm/s up and
    ``braking`` down (0: ``acceleration``), and above ``power_speed`` (> 0) at rate·power_speed/|n|
    — a drive at its power limit, where the time from power_speed to n is
    (n² − power_speed²) / (2·rate·power_speed)."""
    def from_rest(n: float, rate: float) -> float:
        n = abs(n)
        if power_speed <= 0 or n <= power_speed:
            return n / rate
        return power_speed / rate + (n * n - power_speed * power_speed) / (2.0 * rate * power_speed)

    down = braking if braking > 0 else acceleration
    if n0 * n1 >= 0:  # the same way round: the difference of the times from rest
        rate = down if abs(n1) < abs(n0) else acceleration
        return abs(from_rest(n1, rate) - from_rest(n0, rate))
    return from_rest(n0, down) + from_rest(n1, acceleration)  # a reversal: down to rest, then up


def _pauses(rec: np.ndarray, machine, warnings: list[str], path: str = "<program>",
            m6: np.ndarray | None = None, stops: np.ndarray | None = None, ends: np.ndarray | None = None,
            starts: np.ndarray | None = None, end_change: int = 0, tool_changes: bool = True,
            running: bool = False):
    """(record index, category, duration) of the pauses before each record, and dwells.  ``m6``,
    ``stops``, ``ends``, ``starts``: the lines holding M6, M00/M01, M2/M30 and M3/M4 words (None
    when not known: a macro program); ``end_change``: the line of a tool change after the last
    move (0: none); ``running``: the records continue a run under way (the first record's tool
    in the spindle and its speed reached)."""
    out = []
    sp = machine.spindle
    clamped = False
    tools = rec["tool"]
    target = rec["spindle_dir"].astype(float) * np.minimum(rec["spindle"], sp.max_speed)
    over = rec["spindle"] > sp.max_speed
    if over.any():
        clamped = True
    tool0, speed0 = (tools[0], target[0]) if running and len(rec) else (0, 0.0)
    change_tool = np.nonzero(tools != np.concatenate(([tool0], tools[:-1])))[0]
    change_speed = np.nonzero(target != np.concatenate(([speed0], target[:-1])))[0]
    change_line: dict = {}  # tool-change record -> the line its time belongs to
    for i in change_tool:
        if machine.timing.tool_change > 0 and tool_changes:
            # the time belongs to the M6 line between the previous move and this one, where known
            line = int(rec["line"][i])
            line = _last_within(m6, int(rec["line"][i - 1]) if i > 0 else 0, line) or line
            first = not running and i == change_tool[0] and tools[i] != 0
            extra = getattr(machine.timing, "first_tool_change_extra", 0.0) if first else 0.0
            out.append((int(i), 0, CAT_TOOL, machine.timing.tool_change + extra, line))
            change_line[int(i)] = line
    if sp.wait_for_speed:
        prev = np.concatenate(([speed0], target[:-1]))
        for i in change_speed:
            dt = runup_time(prev[i], target[i], sp.acceleration, getattr(sp, "runup_power_speed", 0.0),
                            getattr(sp, "braking", 0.0))
            if dt <= 0:
                continue
            # a wait that overlaps motion stands later, with the record it started at (``since``):
            # _overlap_spindle takes off the time that passes between, once the plan is timed
            if target[i] == 0.0 and not getattr(sp, "wait_for_stop", True):
                # the moves run while it brakes; what is left is waited for before the next tool
                # change (M5 and M6 between the same moves: at once), before the spindle starts
                # again, or at the program's end (the Hurco completes its program only once the
                # spindle is down: 3.9 s after M30 from S12000, 0.7 s from S9000)
                later = change_tool[change_tool >= i]
                restart = change_speed[change_speed > i]
                n = len(rec) - 1
                if restart.size and (not later.size or restart[0] < later[0]):
                    out.append((int(restart[0]), 0.5, CAT_SPINDLE, dt, int(rec["line"][restart[0]]), int(i) + 1))
                    continue
                if later.size:  # at the M6's line, or at a program stop (M00/M01) before it
                    k, sub = int(later[0]), -0.25
                    line = change_line.get(k, int(rec["line"][k]))
                    lo = int(rec["line"][k - 1]) if k > 0 else 0
                elif end_change:  # the tool put away after the last move
                    k, sub, line, lo = n, 3.75, int(end_change), int(rec["line"][n])
                else:
                    k, sub, lo = n, 3.5, int(rec["line"][n])
                    line = int(ends[-1]) if ends is not None and ends.size else lo
                if sub != 3.5:  # the Hurco stands at the M01 before its tool change until the spindle is down
                    line = _last_within(stops, lo, line - 1) or line
                out.append((k, sub, CAT_SPINDLE, dt, line, int(i) + 1))
            elif getattr(sp, "runup_overlap", False) and target[i] != 0.0 and rec["kind"][i] == R.RAPID \
                    and (starts is None or int(rec["line"][i]) in starts):
                # a rapid on the block that starts the spindle (a feed move never starts before
                # the spindle is at speed; where the M3/M4 lines are not known, a macro program,
                # the rapid the speed changes on): the first record of a later block waits for
                # the rest
                nxt = i + 1
                while nxt < len(rec) and rec["line"][nxt] == rec["line"][i]:
                    nxt += 1
                if nxt < len(rec):
                    out.append((nxt, 1, CAT_SPINDLE, dt, int(rec["line"][nxt]), int(i) + 1))
                else:
                    out.append((int(i), 1, CAT_SPINDLE, dt))
            else:
                out.append((int(i), 1, CAT_SPINDLE, dt))
    for i in np.nonzero(rec["kind"] == R.DWELL)[0]:
        if rec["dwell"][i] > 0:
            out.append((int(i), 2, CAT_DWELL, float(rec["dwell"][i])))
    if clamped:
        from ..errors import warning_text

        first = int(np.argmax(over))
        warnings.append(warning_text(path, int(rec["line"][first]),
                                     f"S{rec['spindle'][first]:g} is above the machine's {sp.max_speed:g} rpm: "
                                     f"spindle speeds are clamped to it ({int(np.unique(rec['line'][over]).size)} "
                                     f"line(s))"))
    return out


def _assemble(rec: np.ndarray, moves: np.ndarray, pauses) -> np.ndarray:
    """Merge motion segments and pauses in program order."""
    ps = np.zeros(len(pauses), SEG_DTYPE)
    keys_p = np.zeros(len(pauses))
    for j, (i, sub, cat, d, *extra) in enumerate(pauses):
        ps[j]["kind"] = PAUSE
        ps[j]["cat"] = cat
        ps[j]["rec"] = i
        ps[j]["line"] = extra[0] if extra else rec["line"][i]
        ps[j]["since"] = extra[1] if len(extra) > 1 else 0
        ps[j]["duration"] = d
        keys_p[j] = 4 * i + sub
    keys_m = 4 * moves["rec"].astype(float) + 3
    allseg = np.concatenate([moves, ps])
    order = np.argsort(np.concatenate([keys_m, keys_p]), kind="stable")
    out = allseg[order]
    # pauses stand at the position reached so far: the end of the last motion before them,
    # or the start of the record they belong to when no motion came first
    pause = out["kind"] == PAUSE
    if pause.any():
        idx = np.where(~pause, np.arange(len(out)), -1)
        last = np.maximum.accumulate(idx)
        r = rec[out["rec"]]
        start = np.stack([r["sx"], r["sy"], r["sz"]], axis=1)
        pos = np.where((last >= 0)[:, None], out["p1"][np.maximum(last, 0)], start)
        out["p0"][pause] = pos[pause]
        out["p1"][pause] = pos[pause]
    return out


def _insert_blends(seg: np.ndarray, jclass: np.ndarray, machine):
    """Blend arcs at the line-line corners classed J_BLEND; corners where no blend fits
    become parabolic.  Returns the new segment table and its junction classes."""
    vel, acc = _axis_limits(machine)
    trim, radius, vplan, phi, aplane = K.linuxcnc_blends.auto(len(seg), 
        seg["kind"].astype(np.int64), seg["rapid"].astype(np.int64), seg["path_mode"].astype(np.int64),
        jclass != K.J_BLEND, seg["tol"], seg["p0"], seg["p1"], np.ascontiguousarray(seg["u0"]), seg["length"],
        seg["vmax"], np.where(seg["rapid"] == 1, 0.0, seg["feed"]), acc, vel)
    jclass = jclass.copy()
    jclass[(jclass == K.J_BLEND) & (trim <= 0)] = K.J_PARABOLIC
    corners = np.nonzero(trim > 0)[0]
    jclass[corners] = K.J_TANGENT
    if not len(corners):
        return seg, jclass
    # trim the lines
    seg = seg.copy()
    before = np.concatenate(([0.0], trim[:-1]))
    lines = seg["kind"] == LINE
    u = seg["u0"]
    seg["p0"][lines] = seg["p0"][lines] + u[lines] * before[lines][:, None]
    seg["p1"][lines] = seg["p1"][lines] - u[lines] * trim[lines][:, None]
    seg["length"][lines] = np.maximum(seg["length"][lines] - before[lines] - trim[lines], 0.0)
    # the blend arcs
    b = np.zeros(len(corners), SEG_DTYPE)
    i = corners
    u1, u2 = u[i], u[i + 1]
    corner = seg["p1"][i] + u1 * trim[i][:, None]
    theta = 0.5 * (np.pi - phi[i])
    nrm = u2 - u1
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    center = corner + nrm * (radius[i] / np.sin(theta))[:, None]
    start = corner - u1 * trim[i][:, None]
    e1 = start - center
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    b["kind"] = ARC
    b["blend"] = 1
    b["cat"] = seg["cat"][i + 1]
    b["rapid"] = seg["rapid"][i + 1]
    b["rec"] = seg["rec"][i + 1]
    b["line"] = seg["line"][i + 1]
    b["p0"] = start
    b["p1"] = corner + u2 * trim[i][:, None]
    b["u0"], b["u1"] = u1, u2
    b["c"], b["e1"], b["e2"] = center, e1, u1
    b["r0"] = b["r1"] = radius[i]
    b["theta"] = phi[i]
    b["length"] = radius[i] * phi[i]
    b["feed"] = np.maximum(seg["feed"][i], seg["feed"][i + 1])
    b["vmax"] = vplan[i]
    b["amax"] = aplane[i] * K._ACC_RATIO_TAN
    mbt = machine.controller.min_block_time
    if mbt > 0:
        b["vmax"] = np.minimum(b["vmax"], b["length"] / mbt)
    out = np.concatenate([seg, b])
    jc = np.concatenate([jclass, np.full(len(b), K.J_TANGENT)])
    key = np.concatenate([np.arange(len(seg), dtype=float), corners + 0.5])
    order = np.argsort(key, kind="stable")
    out, jc = out[order], jc[order]
    # lines eaten completely by their blends disappear; the path stays continuous
    keep = (out["kind"] != LINE) | (out["length"] > _MIN_LENGTH)
    out, jc = out[keep], jc[keep]
    # What is left of a line between two blends is "consumed" into the blend when it would
    # take fewer than ARC_BLEND_GAP_CYCLES (4) servo periods at the blend speed (LinuxCNC's
    # blendCheckConsume): it runs as part of the blend, not as a block of its own.  Other
    # trimmed lines are re-limited by the shortest block time.
    ln = out["kind"] == LINE
    nxt_blend = np.zeros(len(out), bool)
    nxt_blend[:-1] = out["blend"][1:] == 1
    prv_blend = np.zeros(len(out), bool)
    prv_blend[1:] = out["blend"][:-1] == 1
    v_next = np.zeros(len(out))
    v_next[:-1] = out["vmax"][1:]
    v_prev = np.zeros(len(out))
    v_prev[1:] = out["vmax"][:-1]
    v_blend = np.maximum(np.where(nxt_blend, v_next, 0.0), np.where(prv_blend, v_prev, 0.0))
    gap = 4 * machine.controller.servo_period
    consumed = ln & (nxt_blend | prv_blend) & (out["length"] < gap * v_blend)
    if mbt > 0:
        lim = ln & ~consumed
        out["vmax"][lim] = np.minimum(out["vmax"][lim], out["length"][lim] / mbt)
    return out, jc


def _linuxcnc_corners(seg: np.ndarray, machine):
    """LinuxCNC 2.9 term conditions: tangent (with kink), blend arc, parabolic blend or stop;
    the acceleration factors they imply (tpGetScaledAccel); junction speeds."""
    c = machine.controller
    vel, acc = _axis_limits(machine)
    is_pause = seg["kind"] == PAUSE
    feed = np.where(seg["rapid"] == 1, 0.0, seg["feed"])
    jc, fa_end, fa_next = K.linuxcnc_classify.auto(len(seg), 
        seg["kind"].astype(np.int64), seg["rapid"].astype(np.int64), seg["path_mode"].astype(np.int64),
        is_pause, np.ascontiguousarray(seg["u1"]), np.ascontiguousarray(seg["u0"]), seg["vmax"], feed, acc,
        c.servo_period)
    # acceleration factors of the original segments: own term condition, blend_prev, and the
    # 90 % that LinuxCNC 2.9 was measured to use on exact-path (G61, canned-cycle) moves
    prev = np.concatenate(([1.0], fa_next[:-1]))
    exact = np.where(seg["path_mode"] == 1, 0.9, 1.0)
    seg = seg.copy()
    seg["amax"] = seg["amax"] * fa_end * prev * exact
    arc = seg["kind"] == ARC
    if arc.any():
        # circles are limited with the acceleration they get from the previous junction
        r = np.minimum(seg["r0"], seg["r1"])[arc]
        a_base = seg["amax"][arc] / (fa_end[arc] * K._ACC_RATIO_TAN)
        seg["vmax"][arc] = np.minimum(seg["vmax"][arc], np.sqrt(K._ACC_RATIO_NORMAL * a_base * r))
    seg, jc = _insert_blends(seg, jc, machine)
    n = len(seg)
    vj = np.zeros(n)
    v_next = np.concatenate((seg["vmax"][1:], [0.0]))
    tang = jc == K.J_TANGENT
    vj[tang] = np.minimum(seg["vmax"][tang], v_next[tang])
    for i in np.nonzero(jc == K.J_PARABOLIC)[0]:
        cosang = float(np.dot(seg["u1"][i], seg["u0"][i + 1]))
        cos_half = math.cos(0.5 * math.acos(max(-1.0, min(1.0, -cosang))))
        f1 = seg["feed"][i] if seg["feed"][i] > 0 and not seg["rapid"][i] else np.inf
        f2 = seg["feed"][i + 1] if seg["feed"][i + 1] > 0 and not seg["rapid"][i + 1] else np.inf
        vj[i] = K.parabolic_blend_speed(seg["length"][i], seg["length"][i + 1], min(seg["vmax"][i], f1),
                                        min(seg["vmax"][i + 1], f2), seg["amax"][i], seg["amax"][i + 1],
                                        min(seg["tol"][i], seg["tol"][i + 1]), cos_half)
    return seg, vj


def _naive_cam(seg: np.ndarray, rec: np.ndarray, apart: np.ndarray | None = None) -> np.ndarray:
    """LinuxCNC merges nearly collinear G1 moves (G64 P… Q…) before planning; ``apart``: segments
    kept out of any chain."""
    alone = seg["kind"] == PAUSE if apart is None else (seg["kind"] == PAUSE) | apart
    keep, start = K.naive_cam_merge.auto(len(seg), seg["kind"].astype(np.int64), seg["rapid"].astype(np.int64),
                                    seg["path_mode"].astype(np.int64), alone, seg["feed"],
                                    rec["cam_tol"][seg["rec"]], np.ascontiguousarray(seg["p0"]),
                                    np.ascontiguousarray(seg["p1"]))
    if keep.all():
        return seg
    seg = seg.copy()
    merged = ~np.all(start == seg["p0"], axis=1)
    seg["p0"] = start
    d = seg["p1"][merged] - start[merged]
    length = np.linalg.norm(d, axis=1)
    seg["length"][merged] = length
    u = d / length[:, None]
    seg["u0"][merged] = u
    seg["u1"][merged] = u
    return seg[keep]


def _before_switch(seg, is_pause, to_rapid: bool) -> np.ndarray:
    """(n,) bool: a cutting-feed segment the next motion after which (pauses between skipped) is a
    rapid (``to_rapid``) — where a control checks in-position for cutting feed before it starts the
    rapid — or a rapid the next motion after which is a cutting-feed segment."""
    moving = np.flatnonzero(~is_pause)
    out = np.zeros(len(seg), bool)
    if len(moving) > 1:
        rapid = seg["rapid"][moving] == 1
        out[moving[:-1]] = (~rapid[:-1] & rapid[1:]) if to_rapid else (rapid[:-1] & ~rapid[1:])
    return out


def _filter_hold(c) -> tuple[int, float]:
    """(filter code, drain time) of the after-interpolation filter."""
    from ._runkernel import FILTER_BELL, FILTER_EXP, FILTER_LINEAR, FILTER_NONE

    if c.after_filter == "none" or c.after_time <= 0:
        return FILTER_NONE, 0.0
    n = max(1, int(round(c.after_time / c.servo_period)))
    if c.after_filter == "linear":
        return FILTER_LINEAR, n * c.servo_period
    if c.after_filter == "bell":
        return FILTER_BELL, 2 * max(1, n // 2) * c.servo_period
    # exponential: in position after 5 time constants (0.7 % of the last step left)
    return FILTER_EXP, 5.0 * c.after_time


def plan_program(program, machine, like: Plan | None = None, keep_geometry: bool = False) -> Plan:
    """Plan a program on a machine: geometry, limits, corners, look-ahead, timing.

    ``keep_geometry``: keep the feed-independent stages' output in the plan (a copy of the
    segment table) so that ``like`` can reuse it.  ``like``: a plan of the same path (same
    records but for their feeds) on the same machine, made with ``keep_geometry``; only the
    limits, corners, look-ahead and timing are planned again (how the optimiser plans a
    program at several feeds)."""
    program = _overridden(program, machine.controller)
    geom = _same_geometry(program, machine, like)
    if geom is not None:
        rec, shift, seg, feed_box, warnings = geom
        return _plan_motion(rec, shift, seg, feed_box, warnings, machine, like.geometry, program.rapid_scale,
                            program.path)
    probe = (program.records["flags"] & R.FL_PROBE) != 0
    if probe.any():
        from ..errors import GCodeError, SourceLocation
        raise GCodeError("a probe move (G38.x) stops where the probe touches, which is known only on the machine: "
                         "the program can be parsed, scaled and verified but not simulated",
                         SourceLocation(program.path, int(program.records["line"][int(np.argmax(probe))]), 1))
    if getattr(program, "unknown_calls", ()):
        from ..errors import GCodeError, SourceLocation
        raise GCodeError("this line calls a program that is not at hand (passed over with --lenient): what it "
                         "does is not known, so the program can be parsed, scaled and verified but not simulated",
                         SourceLocation(program.path, int(program.unknown_calls[0]), 1))
    rot = (program.records["flags"] & R.FL_ROTARY) != 0
    if rot.any():
        from ..errors import GCodeError, SourceLocation
        raise GCodeError("this move drives an axis beyond X/Y/Z (rotary A/B/C or secondary U/V/W): the twin "
                         "models a 3-axis machine, so the program can be parsed, scaled and verified but not "
                         "simulated",
                         SourceLocation(program.path, int(program.records["line"][int(np.argmax(rot))]), 1))
    # one continuous frame even when the program switches, moves or rotates work offsets
    # the axes' path: a G43 H or a tool change moves the program position, not the machine
    rec = R.in_common_frame(program.records, program.path, tool_offsets=True)
    shift = R.tip_shift(program.records, rec)
    warnings: list[str] = []
    motion = rec["kind"] != R.DWELL
    moves = motion_segments(rec)
    check_feeds(rec, moves, program.path)
    check_travel(rec, moves, machine, program.path, None if machine.hard_travel_limits else warnings)
    moves = moves[motion & (moves["length"] > _MIN_LENGTH)]
    end_change = getattr(program, "end_tool_change", 0)
    pauses = _pauses(rec, machine, warnings, program.path, _m_lines(program, 6.0), _m_lines(program, 0.0, 1.0),
                     _m_lines(program, 2.0, 30.0), _m_lines(program, 3.0, 4.0),
                     end_change if machine.timing.tool_change > 0 else 0,
                     tool_changes=not getattr(program, "tools_by_selection", False),
                     running=getattr(program, "running", False))
    if end_change and len(rec) and machine.timing.tool_change > 0:
        # a tool change after the last move (the tool put away before M30)
        pauses.append((len(rec) - 1, 4, CAT_TOOL, machine.timing.tool_change, end_change))
    seg = _assemble(rec, moves, pauses)
    feed_box = _feed_box(seg, shift) if len(seg) else None
    geometry = (program.records, rec, shift, seg.copy(), feed_box, list(warnings), machine, program.lexed,
                end_change) if keep_geometry else None
    return _plan_motion(rec, shift, seg, feed_box, warnings, machine, geometry, program.rapid_scale, program.path)


def _overridden(program, c):
    """The program as a run with a constant feed and rapid override runs it (the controller's
    ``feed_override``/``rapid_override``, %): feed moves' F scaled (threads and rigid taps
    follow the spindle: not), rapids' speed scaled.  100 % leaves the program as it is."""
    if c.feed_override == 100.0 and c.rapid_override == 100.0:
        return program
    from dataclasses import replace as dc_replace

    rec = program.records
    out = {}
    if c.feed_override != 100.0:
        feed = (rec["kind"] != R.RAPID) & (rec["kind"] != R.DWELL) & ((rec["flags"] & R.FL_SYNC) == 0)
        new = rec.copy()
        new["feed"] = np.where(feed, rec["feed"] * (c.feed_override / 100.0), rec["feed"])
        out["records"] = new
    if c.rapid_override != 100.0:
        base = program.rapid_scale if program.rapid_scale is not None else np.ones(len(rec))
        out["rapid_scale"] = np.where(rec["kind"] == R.RAPID, base * (c.rapid_override / 100.0), base)
    return dc_replace(program, **out)


def _clamp_cutting_feed(seg, is_pause, machine, warnings, path) -> None:
    """A feed above the control's maximum cutting feed (``controller.max_cutting_feed``) runs at
    it, as on the control; without one, a feed no path can reach (above the axes' speeds
    together) runs at the axes' limits.  Either is a warning at its first line, as an S above
    the spindle's maximum is."""
    set_max = machine.controller.max_cutting_feed
    top = (set_max if set_max > 0 else float(np.sqrt(sum(ax.max_velocity ** 2 for ax in machine.axes)))) / 60.0
    over = ~is_pause & (seg["rapid"] == 0) & (seg["feed"] > top * (1 + 1e-9))
    if not over.any():
        return
    seg["vmax"][over] = np.minimum(seg["vmax"][over], top)
    from ..errors import warning_text

    lines = np.unique(seg["line"][over])
    i = int(np.argmax(over))
    what = (f"the machine's maximum cutting feed {set_max:g} mm/min: feeds are clamped to it" if set_max > 0 else
            f"what the axes can run together ({top * 60.0:,.0f} mm/min): they run at their limits")
    # (the feed as it runs, mm/min: an F per revolution or in inverse time is not the F word)
    warnings.append(warning_text(path, int(seg["line"][i]),
                                 f"the feed of this line, {seg['feed'][i] * 60.0:,.6g} mm/min, is above {what} "
                                 f"({len(lines)} line(s))"))


def _same_geometry(program, machine, like):
    """``like``'s geometry with ``program``'s feeds, when ``program`` is its path at other feeds."""
    if like is None or like.geometry is None:
        return None
    src, rec0, shift, seg0, feed_box, warnings, machine0, lexed, end_change = like.geometry
    new = program.records
    if (machine0 is not machine and machine0 != machine) or len(new) != len(src) or lexed is not program.lexed \
            or end_change != getattr(program, "end_tool_change", 0):
        return None
    # every field the feed-independent stages read: all but the feeds
    for name in new.dtype.names:
        if name not in ("feed", "feed_word") and not np.array_equal(new[name], src[name]):
            return None
    seg = seg0.copy()  # (the later stages write limits into it)
    moving = seg["kind"] != PAUSE
    seg["feed"][moving] = new["feed"][seg["rec"][moving]] / 60.0
    bad = moving & (seg["rapid"] == 0) & (seg["feed"] <= 0) & (seg["length"] > 0)
    if bad.any():
        i = int(seg["rec"][np.argmax(bad)])
        check_feeds(new[i:i + 1], seg[bad][:1], program.path)
    # (the later stages read the records' frames, flags and tolerances, not their feeds)
    return rec0, shift, seg, feed_box, list(warnings)


def _plan_motion(rec, shift, seg, feed_box, warnings, machine, geometry, rapid_scale=None, path="<program>") -> Plan:
    """The feed-dependent stages: motion limits, corners, look-ahead, S-curve timing.
    ``rapid_scale``: per record, the fraction of the rapid speed (a replayed rapid override)."""
    c = machine.controller
    if len(rec):
        start = np.array([rec["sx"][0], rec["sy"][0], rec["sz"][0]])
    else:
        start = np.zeros(3)
    if not len(seg):
        return Plan(seg, np.zeros((0, N_PROF)), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0, bool), start,
                    warnings, shift)
    style = STYLE_CODES[c.style]
    if seg["kind"].size:
        canned = (rec["flags"][seg["rec"]] & R.FL_CANNED) != 0
        # drilling cycles position with an exact stop at every point (LinuxCNC runs them
        # in exact-path mode)
        seg["path_mode"][canned & (seg["kind"] != PAUSE)] = 1 if style == K.STYLE_LINUXCNC else 2
    if style == K.STYLE_LINUXCNC:
        # (LinuxCNC flushes its naive-CAM chain at a spindle command: a chain does not run over the
        # start of a spindle change that overlaps motion, whose time _overlap_spindle counts from)
        cut = np.isin(seg["rec"], seg["since"][seg["since"] > 0] - 1) & (seg["kind"] != PAUSE)
        seg = _naive_cam(seg, rec, cut & np.concatenate(([True], seg["rec"][1:] != seg["rec"][:-1])))
    if c.stop_angle > 0:  # (on the path as merged: LinuxCNC's naive CAM joins tiny steps first)
        _stop_at_sharp_corners(seg, c.stop_angle)
    budget = _motion_limits(seg, machine, linuxcnc=style == K.STYLE_LINUXCNC)
    is_pause = seg["kind"] == PAUSE
    _clamp_cutting_feed(seg, is_pause, machine, warnings, path)
    if rapid_scale is not None:
        # a rapid override scales the speed of rapids, not their acceleration
        r = (seg["rapid"] == 1) & ~is_pause
        seg["vmax"][r] *= np.asarray(rapid_scale, np.float64)[seg["rec"][r]]
    _, acc = _axis_limits(machine)
    filt, drain = _filter_hold(c)
    if style == K.STYLE_LINUXCNC:
        seg, vj = _linuxcnc_corners(seg, machine)
        is_pause = seg["kind"] == PAUSE
    else:
        vj = K.corner_limits.auto(len(seg), style, np.ascontiguousarray(seg["u1"]), np.ascontiguousarray(seg["u0"]), is_pause,
                             seg["rapid"].astype(np.int64), seg["path_mode"].astype(np.int64),
                             seg["kind"].astype(np.int64), seg["tol"], seg["vmax"], acc,
                             c.corner_velocity / 60.0, c.junction_deviation, drain if filt else 0.0,
                             c.exact_stop_rapids)
    tb = c.bell_time if c.before_shape == "bell" else 0.0
    acc_seg = np.where(is_pause, 1.0, seg["amax"])
    length = np.where(is_pause, 0.0, seg["length"])
    wait = np.zeros(len(seg), bool)
    if c.feed_rapid_wait > 0:
        # (a control that stands there stops there: Grbl, which blends into a rapid, too)
        wait = _before_switch(seg, is_pause, to_rapid=True)
        vj = np.where(wait, 0.0, vj)
    rapid_wait = np.zeros(len(seg), bool)
    if c.rapid_feed_wait > 0:
        # (the in-position check before cutting: the rapid a feed move follows ends at rest)
        rapid_wait = _before_switch(seg, is_pause, to_rapid=False)
        vj = np.where(rapid_wait, 0.0, vj)
    ve = K.lookahead.auto(len(seg), vj, length, acc_seg, tb, c.lookahead)
    if style != K.STYLE_LINUXCNC:
        ve = _arcs_at_their_speed(seg, budget, vj, length, is_pause, tb, c.lookahead, ve)
        acc_seg = np.where(is_pause, 1.0, seg["amax"])
    stop = (vj <= 0.0) & ~is_pause
    hold = np.where(stop, drain, 0.0)
    hold += np.where(wait, c.feed_rapid_wait, 0.0) + np.where(rapid_wait, c.rapid_feed_wait, 0.0)
    prof, dur = K.segment_timing.auto(len(seg), length, np.where(is_pause, 0.0, seg["vmax"]), acc_seg, tb, ve, hold,
                                 seg["duration"])
    _overlap_spindle(seg, rec, dur)
    t_start = np.concatenate(([0.0], np.cumsum(dur)[:-1]))
    return Plan(seg, prof, dur, hold, t_start, stop, start, warnings, shift, feed_box, geometry)


def _overlap_spindle(seg: np.ndarray, rec: np.ndarray, dur: np.ndarray) -> None:
    """A spindle wait that overlaps motion (``since`` > 0: a run-up under ``runup_overlap``, a
    braking without ``wait_for_stop``) is shortened by the time that passes from record
    ``since`` − 1 up to the wait — moves, dwells, other waits: the spindle changed speed
    meanwhile."""
    waits = np.flatnonzero((seg["kind"] == PAUSE) & (seg["since"] > 0))
    if not waits.size:
        return
    # time before each segment (segments are in program order, their records ascending)
    before = np.concatenate(([0.0], np.cumsum(dur)))
    for j in waits:
        r0 = int(seg["since"][j]) - 1
        k = int(np.searchsorted(seg["rec"], r0, "left"))
        # from the block's own action: the tool change and spindle waits standing before it (the
        # M6 ahead of a G0 X Y S M3) pass before the spindle is told
        while k < j and seg["rec"][k] == r0 and seg["kind"][k] == PAUSE and seg["cat"][k] in (CAT_TOOL, CAT_SPINDLE):
            k += 1
        passed = before[j] - before[min(k, j)]
        d = max(0.0, float(seg["duration"][j]) - float(passed))
        change = d - float(seg["duration"][j])
        dur[j] += change
        seg["duration"][j] = d
        before[j + 1:] += change  # (a later wait counts this one as it now is)


def _stop_at_sharp_corners(seg: np.ndarray, angle: float) -> None:
    """An exact stop (as G9 on the block) at the end of every feed segment whose direction
    turns by more than ``angle`` degrees into the next feed segment's: a control that will not
    blend a reversal however slow, where the corner rule alone (an allowable velocity change
    per axis) would carry a little speed through it."""
    if len(seg) < 2:
        return
    feed = (seg["kind"] != PAUSE) & (seg["rapid"] == 0)
    turn = np.einsum("ij,ij->i", seg["u1"][:-1], seg["u0"][1:])
    sharp = feed[:-1] & feed[1:] & (turn < math.cos(math.radians(angle)))
    seg["path_mode"][:-1][sharp] = R.PATH_EXACT_STOP


def _feed_box(seg: np.ndarray, shift) -> np.ndarray | None:
    """Extent of the feed moves' tool tip: the end points, and of an arc the points of its own
    sweep where an axis turns (not its whole circle's box: a quarter arc of a large radius
    would make the default stock, and its cells, many times too large)."""
    feed = (seg["kind"] != PAUSE) & (seg["rapid"] == 0)
    if not feed.any():
        return None
    s = seg[feed]
    d = shift[np.clip(s["rec"], 0, len(shift) - 1)] if shift is not None and len(shift) else np.zeros((len(s), 3))
    pts = [s["p0"] - d, s["p1"] - d]
    arcs = s["kind"] == ARC
    if arcs.any():
        a, da = s[arcs], d[arcs]
        th = np.maximum(a["theta"], 1e-300)
        for k in range(3):
            # along axis k the circle is A·cos(φ − α): its extremes at φ = α and α + π
            alpha = np.arctan2(a["e2"][:, k], a["e1"][:, k])
            for off in (0.0, np.pi):
                phi = np.mod(alpha + off, 2 * np.pi)
                inside = phi <= a["theta"]
                if not inside.any():
                    continue
                f = (phi / th)[:, None]
                r = (a["r0"] + (a["r1"] - a["r0"]) * phi / th)[:, None]
                p = a["c"] + r * (np.cos(phi)[:, None] * a["e1"] + np.sin(phi)[:, None] * a["e2"]) + a["h"] * f - da
                pts.append(p[inside])
    pts = np.concatenate(pts)
    return np.stack([pts.min(axis=0), pts.max(axis=0)])
