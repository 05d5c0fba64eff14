"""Program summary (``mtwin parse``) and the motion-record CSV (``--moves``)."""
from __future__ import annotations

import io
from dataclasses import asdict, dataclass

import numpy as np

from .interpreter import Program
from .records import DWELL, KIND_NAMES, RAPID, move_lengths

#: Rapid traverse rate used for the nominal time when no twin is configured, mm/min.
DEFAULT_RAPID_RATE = 30000.0


@dataclass
class ProgramSummary:
    """What ``mtwin parse`` reports.  Lengths in mm, times in s, feeds in mm/min."""

    path: str
    lines: int
    moves: dict
    tools: list
    feed_range: list
    spindle_range: list
    bbox: dict
    rapid_length: float
    cutting_length: float
    nominal_time: float
    dwell_time: float
    units: str
    dialect: str
    warnings: list

    def as_dict(self) -> dict:
        return asdict(self)


def summarize(prog: Program, rapid_rate: float = DEFAULT_RAPID_RATE) -> ProgramSummary:
    """Summarise a program; the nominal time is length/feed plus rapids at ``rapid_rate`` plus dwells."""
    rec = prog.records
    kinds = rec["kind"]
    counts = {name: int((kinds == k).sum()) for k, name in enumerate(KIND_NAMES)}
    lengths = move_lengths(rec)
    rapid = kinds == RAPID
    dwell = kinds == DWELL
    feed = ~rapid & ~dwell
    with np.errstate(divide="ignore", invalid="ignore"):
        t_feed = np.where(feed & (rec["feed"] > 0), lengths / np.where(rec["feed"] > 0, rec["feed"], 1.0), 0.0)
    nominal = float(t_feed.sum() * 60.0 + lengths[rapid].sum() / rapid_rate * 60.0 + rec["dwell"][dwell].sum())
    moving = ~dwell
    # end points only: where the tool stands before the first move is not in the program
    pts = np.stack([rec["x"], rec["y"], rec["z"]], 1)[moving]
    if pts.size:
        lo, hi = pts.min(0), pts.max(0)
        bbox = {"min": [float(v) for v in lo], "max": [float(v) for v in hi]}
    else:
        bbox = {"min": [0.0, 0.0, 0.0], "max": [0.0, 0.0, 0.0]}
    f = rec["feed"][feed]
    cutting = rec["spindle"][feed & (rec["spindle_dir"] != 0)]
    s = rec["spindle"][rec["spindle_dir"] != 0]
    inch = bool(prog.lexed.data) and bool((rec["flags"] & 1).any())
    return ProgramSummary(
        path=prog.path,
        lines=len(prog.data.splitlines()) if prog.is_macro else prog.lexed.n_lines,
        moves=counts,
        tools=sorted(int(t) for t in np.unique(rec["tool"])) if rec.size else [],
        feed_range=[float(f.min()), float(f.max())] if f.size else [0.0, 0.0],
        spindle_range=[float(s.min()), float(s.max())] if s.size else ([float(cutting.min()), float(cutting.max())]
                                                                       if cutting.size else [0.0, 0.0]),
        bbox=bbox,
        rapid_length=float(lengths[rapid].sum()),
        cutting_length=float(lengths[feed].sum()),
        nominal_time=nominal,
        dwell_time=float(rec["dwell"][dwell].sum()),
        units="inch" if inch else "mm",
        dialect=prog.dialect,
        warnings=[str(w) for w in prog.warnings],
    )


def moves_csv(prog: Program) -> str:
    """Motion records as CSV: ``line,kind,x,y,z,cx,cy,cz,feed,spindle,tool`` (mm, mm/min, rpm)."""
    rec = prog.records
    buf = io.StringIO()
    buf.write("line,kind,x,y,z,cx,cy,cz,feed,spindle,tool\n")
    kinds = np.array(KIND_NAMES, dtype=object)[rec["kind"].astype(np.int64)]
    spindle = np.where(rec["spindle_dir"] != 0, rec["spindle"], 0.0)
    cols = [rec["x"], rec["y"], rec["z"], rec["cx"], rec["cy"], rec["cz"], rec["feed"], spindle]
    txt = [np.char.mod("%.6f", c) for c in cols]
    is_arc = (rec["kind"] == 2) | (rec["kind"] == 3)
    for j in (3, 4, 5):  # the centre columns are empty for moves that are not arcs
        txt[j] = np.where(is_arc, txt[j], "")
    for i in range(rec.size):
        buf.write(f"{rec['line'][i]},{kinds[i]},{txt[0][i]},{txt[1][i]},{txt[2][i]},{txt[3][i]},{txt[4][i]},"
                  f"{txt[5][i]},{txt[6][i]},{txt[7][i]},{rec['tool'][i]}\n")
    return buf.getvalue()
