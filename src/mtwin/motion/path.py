"""From motion records to the planner's segment table.

A *segment* is one piece of path the interpolator moves along: a straight line or
a circular/helical arc in 3-D (G17/G18/G19 arcs and LinuxCNC-style blend arcs
share one representation), or a *pause* (dwell, tool change, spindle run-up)
during which the axes stand still.  Segments live in one numpy structured array;
the kernels read its fields as plain arrays.

Arc geometry: ``p(a) = c + R(a)·(cos a·e1 + sin a·e2) + h·a/θ`` for ``a`` in
``[0, θ]``, with ``R(a)`` linear from ``r0`` to ``r1`` (an interpreter-tolerated
radius mismatch becomes a slight spiral, ending exactly on the programmed point)
and ``h`` the helical rise along the plane normal.
"""
from __future__ import annotations

import math

import numpy as np

from ..errors import GCodeError, SourceLocation
from ..gcode import records as R

from ..layout import ARC, LINE, PAUSE  # noqa: F401  (segment kinds, shared with the engagement)
# Time categories for the cycle-time breakdown
CAT_RAPID, CAT_CUT, CAT_DWELL, CAT_TOOL, CAT_SPINDLE = 0, 1, 2, 3, 4
CATEGORY_NAMES = ("rapid", "cutting", "dwell", "tool_change", "spindle_wait")

# How a segment may end
END_CONTINUE, END_STOP = 0, 1

def spindle_records(seg: np.ndarray) -> np.ndarray:
    """The record whose spindle command is in force during each segment (-1: none yet, the
    spindle stopped).  A segment's own record's, except for pauses that stand before their
    record's block has started the spindle: during a tool change (the block after the M6
    carries the new S and M3) the record before's; during a wait for the spindle to stop
    (``since``: 1 + the record the braking began at) the braking record's, 0 rpm.  So the
    run-up starts with the block that asks for it, not at the M01 or the M6 before it."""
    r = seg["rec"].astype(np.int64).copy()
    pause = seg["kind"] == PAUSE
    # (a pause before its record's first motion; the tool put away after the last move stands
    # after its record's motion, and keeps that record's command)
    idx = np.arange(len(seg))
    first_motion = np.full(int(r.max(initial=0)) + 1, len(seg))
    np.minimum.at(first_motion, r[~pause], idx[~pause])
    tool = pause & (seg["cat"] == CAT_TOOL) & (idx < first_motion[r])
    r[tool] -= 1
    since = pause & (seg["cat"] == CAT_SPINDLE) & (seg["since"] > 0)
    r[since] = seg["since"][since] - 1
    return r


SEG_DTYPE = np.dtype(
    [
        ("kind", np.int8),
        ("cat", np.int8),
        ("rapid", np.int8),
        ("path_mode", np.int8),
        ("blend", np.int8),  # 1 = a blend arc inserted by the planner
        ("rec", np.int64),  # index of the source motion record
        ("line", np.int32),
        ("p0", np.float64, 3),
        ("p1", np.float64, 3),
        ("u0", np.float64, 3),  # unit tangent at the start
        ("u1", np.float64, 3),  # unit tangent at the end
        ("c", np.float64, 3),
        ("e1", np.float64, 3),
        ("e2", np.float64, 3),
        ("h", np.float64, 3),
        ("r0", np.float64),
        ("r1", np.float64),
        ("theta", np.float64),
        ("length", np.float64),
        ("feed", np.float64),  # programmed path speed, mm/s (rapids: 0 = machine limit)
        ("vmax", np.float64),  # planner's speed limit, mm/s
        ("amax", np.float64),  # tangential acceleration limit, mm/s^2
        ("duration", np.float64),  # pauses, s
        ("tol", np.float64),  # G64 P tolerance, mm (0 = none given)
        ("since", np.int64),  # a spindle wait overlapping moves: 1 + the first record it overlaps (0: none)
    ]
)


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.divide(v, n, out=np.zeros_like(v), where=n > 0)


def motion_segments(rec: np.ndarray) -> np.ndarray:
    """Geometry of every motion record (rapids, lines, arcs); pauses come later."""
    n = len(rec)
    seg = np.zeros(n, SEG_DTYPE)
    kind = rec["kind"]
    s = R.start_points(rec)
    e = R.end_points(rec)
    seg["p0"], seg["p1"] = s, e
    seg["rec"] = np.arange(n)
    seg["line"] = rec["line"]
    seg["path_mode"] = rec["path_mode"]
    seg["tol"] = rec["path_tol"]
    seg["rapid"] = kind == R.RAPID
    seg["cat"] = np.where(kind == R.RAPID, CAT_RAPID, CAT_CUT)
    seg["feed"] = rec["feed"] / 60.0
    isarc = (kind == R.ARC_CW) | (kind == R.ARC_CCW)
    seg["kind"] = np.where(isarc, ARC, LINE)
    d = e - s
    u = _unit(d)
    seg["u0"] = u
    seg["u1"] = u
    seg["length"] = np.linalg.norm(d, axis=1)
    if isarc.any():
        idx = np.nonzero(isarc)[0]
        a = rec[idx]
        axes = R.PLANE_AXES[a["plane"].astype(np.int64)]
        k = np.arange(len(idx))
        a1, a2, an = axes[:, 0], axes[:, 1], axes[:, 2]
        c = np.stack([a["cx"], a["cy"], a["cz"]], axis=1)
        sp, ep = s[idx], e[idx]
        # centre at the start height along the plane normal
        c[k, an] = sp[k, an]
        nrm = np.zeros((len(idx), 3))
        nrm[k, an] = 1.0
        rs = sp - c
        rs[k, an] = 0.0
        re = ep - c
        re[k, an] = 0.0
        r0 = np.linalg.norm(rs, axis=1)
        r1 = np.linalg.norm(re, axis=1)
        e1 = _unit(rs)
        sgn = np.where(a["kind"] == R.ARC_CCW, 1.0, -1.0)[:, None]
        e2 = sgn * np.cross(nrm, e1)
        theta = R.arc_sweep(a)
        rise = ep[k, an] - sp[k, an]
        h = nrm * rise[:, None]
        seg["c"][idx] = c
        seg["e1"][idx] = e1
        seg["e2"][idx] = e2
        seg["h"][idx] = h
        seg["r0"][idx] = r0
        seg["r1"][idx] = r1
        seg["theta"][idx] = theta
        # mean radius times sweep, with the rise: exact for circles and helices,
        # within (r1-r0)^2 terms for the tolerated spiral
        seg["length"][idx] = np.hypot(0.5 * (r0 + r1) * theta, rise)
        # tangents d p / d a at a = 0 and a = theta
        th = np.maximum(theta, 1e-300)[:, None]
        dr = ((r1 - r0) / th[:, 0])[:, None]
        t0 = r0[:, None] * e2 + dr * e1 + h / th
        ct, st = np.cos(theta)[:, None], np.sin(theta)[:, None]
        t1 = r1[:, None] * (-st * e1 + ct * e2) + dr * (ct * e1 + st * e2) + h / th
        seg["u0"][idx] = _unit(t0)
        seg["u1"][idx] = _unit(t1)
    return seg


def check_feeds(rec: np.ndarray, seg: np.ndarray, path: str) -> None:
    """A feed move needs a positive feed (F0 would take forever)."""
    bad = (seg["rapid"] == 0) & (seg["feed"] <= 0) & (seg["length"] > 0)
    if bad.any():
        i = int(np.argmax(bad))
        raise GCodeError(f"feed move with feed rate {rec['feed'][i]:g} mm/min (F0 or no F word)",
                         SourceLocation(path, int(rec["line"][i]), 1))


def check_travel(rec: np.ndarray, seg: np.ndarray, machine, path: str, warnings: list | None = None) -> None:
    """Every point of the path (end points and arc extremes) must lie inside the axis travel.

    With ``warnings`` (a machine whose limits are not a real machine's: the embedded
    default), the first move beyond them is a warning appended there instead of an error."""
    lo = np.array([ax.min_travel for ax in machine.axes])
    hi = np.array([ax.max_travel for ax in machine.axes])
    th = np.radians(rec["rot"])
    cs, sn = np.cos(th), np.sin(th)

    def to_machine(p, rows):
        """Program points of records ``rows`` in machine coordinates (with the tool offsets)."""
        r = rec[rows]
        return np.stack([r["ox"] + r["tox"] + cs[rows] * p[:, 0] - sn[rows] * p[:, 1],
                         r["oy"] + r["toy"] + sn[rows] * p[:, 0] + cs[rows] * p[:, 1],
                         r["oz"] + r["tlo"] + p[:, 2]], axis=1)

    every = np.arange(len(rec))
    pts = [to_machine(seg["p0"], every), to_machine(seg["p1"], every)]
    arcs = np.nonzero(seg["kind"] == ARC)[0]
    if len(arcs):
        # extremes of a circle along each axis: c ± r·|component of the in-plane basis|
        a = seg[arcs]
        rmax = np.maximum(a["r0"], a["r1"])[:, None]
        span = rmax * np.sqrt(a["e1"] ** 2 + a["e2"] ** 2)
        # only full or large arcs reach the extremes; checking the whole circle is the safe side
        # (a rotated frame only carries G17 arcs, whose span is r along X and Y either way)
        lo_pt = to_machine(a["c"] + np.minimum(a["h"], 0), arcs) - span
        hi_pt = to_machine(a["c"] + np.maximum(a["h"], 0), arcs) + span
        full = a["theta"] >= math.pi  # for short arcs the end points bound it well enough
        pts.append(np.where(full[:, None], lo_pt, to_machine(a["p0"], arcs)))
        pts.append(np.where(full[:, None], hi_pt, to_machine(a["p1"], arcs)))
        recs = [np.arange(len(rec)), np.arange(len(rec)), arcs, arcs]
    else:
        recs = [np.arange(len(rec)), np.arange(len(rec))]
    # the first move that goes beyond: its end point or arc, where the start of the move after it
    # is found first in the table (the end points before the start points at the same record)
    first = []
    for order, (p, r) in enumerate(zip(pts, recs)):
        below, above = p < lo - 1e-9, p > hi + 1e-9
        badrow = (below | above).any(axis=1)
        if badrow.any():
            j = int(np.argmax(badrow))
            first.append((int(r[j]) - (order == 0), order == 0, p, r, j, below, above))
    if first:
        *_, p, r, j, below, above = min(first, key=lambda x: x[:2])
        ax = int(np.argmax(below[j] | above[j]))
        limit = lo[ax] if below[j, ax] else hi[ax]
        name = "XYZ"[ax]
        msg = (f"move reaches {name} = {p[j, ax]:.3f} mm in machine coordinates, beyond the "
               f"{'lower' if below[j, ax] else 'upper'} travel limit {limit:g} mm of axis {name} "
               f"(axes.{name.lower()}.{'min' if below[j, ax] else 'max'}_travel)")
        line = int(rec["line"][r[j]])
        if warnings is None:
            raise GCodeError(msg, SourceLocation(path, line, 1))
        from ..errors import warning_text

        warnings.append(warning_text(path, line, msg + " of the default machine; simulated anyway (give "
                                     "your machine's travel, [axes.x] min_travel and max_travel …, in a twin "
                                     "file, --twin, to make it an error)"))
