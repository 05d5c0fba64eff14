"""The simulated trace: time series in the measurement format, and its summary.

Column names and units are those of ``MEASUREMENT_FORMAT.md`` (version 1), so a
simulated trace can be read back as a measurement.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from ..layout import CUT_SIGNALS, AXES, SIGNALS  # noqa: F401  (the layouts, shared with effects)


@dataclass
class CuttingSummary:
    """Cutting-load results: forces in N (on the tool, XY resultant = the reference's cutting
    load), power in W, torque in N·m, lines are 1-based program lines."""

    peak_load: float
    peak_load_line: int
    mean_load: float  # over the samples where the tool cuts
    peak_power: float
    peak_power_line: int
    mean_cutting_power: float  # over the samples where the tool cuts
    peak_spindle_torque: float
    peak_spindle_torque_line: int
    cutting_energy: float  # J
    engaged_time: float  # s with the tool in the material
    peak_mrr: float  # mm³/s
    peak_spindle_load: float  # largest share of the spindle curve's available torque used
    material: str
    stock: list[float]
    stock_source: str
    resolution: float
    engagement_steps: int
    engagement_seconds: float
    defaults: list[str]
    tools: list = field(default_factory=list)  # dicts: cutting.library.tools_used
    spindle_stopped_line: int = 0  # first line where feed moves cut with the spindle stopped (0: none)
    # per tool number, with a wear effect: the flank-wear land at the program's first and last
    # cut steps (mm) and the edge sliding before and in the program (m)
    tool_wear: dict = field(default_factory=dict)
    # with tools whose dynamics the twin knows: each cutting line's chatter stability margin
    # (motion.simulate.chatter_table; docs/chatter.md)
    chatter: dict = field(default_factory=dict)
    # per described tool: the shank's bending stress at its peak load against its allowed
    # stress, and the tip's deflection there (cutting.catalogue.shank_checks; docs/catalogue.md)
    shank: list = field(default_factory=list)


@dataclass
class Summary:
    """What `mtwin simulate` reports: times in s, following error in mm, torque in N·m."""

    cycle_time: float
    cutting_time: float
    rapid_time: float
    dwell_time: float
    tool_change_time: float
    spindle_wait_time: float
    motion_time: float  # first to last commanded movement (LinuxCNC's cycle-time definition)
    max_following_error: dict[str, float]
    max_torque: dict[str, float]
    per_tool: dict[int, dict[str, float]]
    samples: int
    servo_period: float
    machine: str
    style: str
    in_position_wait: float = 0.0  # s, waits at exact stops for the axes (part of the categories)
    warnings: list[str] = field(default_factory=list)
    cutting: CuttingSummary | None = None
    per_line: object = None  # motion.linetime.LineTimes: simulated and nominal time per line
    # where each axis' largest following error occurs: line, and "rapid" or "feed move"
    max_following_error_line: dict[str, int] = field(default_factory=dict)
    max_following_error_in: dict[str, str] = field(default_factory=dict)
    max_following_error_feed: dict[str, float] = field(default_factory=dict)  # mm, in feed moves only
    max_contour_error: float = 0.0  # mm, error normal to the direction of travel, feed moves
    max_contour_error_line: int = 0

    def as_dict(self) -> dict:
        d = dict(self.__dict__)
        pl = d.pop("per_line")
        if pl is not None:
            d["slowest_lines"] = pl.worst(10)
            d["per_line"] = pl.as_dict()
        d["per_tool"] = {str(k): v for k, v in self.per_tool.items()}
        c = d.pop("cutting")
        if c is not None:
            d.update({k: v for k, v in c.__dict__.items() if k in (
                "peak_load", "peak_load_line", "mean_load", "peak_power", "peak_power_line", "mean_cutting_power",
                "peak_spindle_torque")})
            d["cutting"] = dict(c.__dict__)
            d["tools"] = c.tools
            wear = d["cutting"].pop("tool_wear")
            if wear:
                d["tool_wear"] = {str(k): v for k, v in wear.items()}
            chatter = d["cutting"].pop("chatter")
            if chatter:
                d["chatter"] = chatter
        # a line 0 does not exist: "no such place" (nothing cut, no feed move) is null
        for sub in (d, d.get("cutting") or {}):
            for k, v in sub.items():
                if k.endswith("_line") and v == 0:
                    sub[k] = None
        return d


_AXIS_SIGNALS = {"": "act", "_cmd": "cmd", "_err": "err", "_vel": "vel", "_torque": "torque", "_current": "current"}


def _source(name: str) -> tuple[str, int]:
    """(Trace attribute, column) of a measurement-format signal."""
    if name == "feed":
        return "feed", 0
    if name == "vb":
        return "vb", -1
    if name in ("vib_x", "vib_y"):
        return "vib", "xy".index(name[-1])
    if name in CUT_SIGNALS:
        return "cut", CUT_SIGNALS.index(name)
    if name in ("fx", "fy", "fz"):
        return "force", AXES.index(name[1])
    if name[:1] in AXES and name[1:] in _AXIS_SIGNALS:
        return _AXIS_SIGNALS[name[1:]], AXES.index(name[0])
    raise KeyError(f"no signal {name!r} in the measurement format")



@dataclass
class Trace:
    """Time series of one simulation (stored every ``every``-th servo period)."""

    t: np.ndarray  # s
    line: np.ndarray  # 1-based program line being executed
    cmd: np.ndarray  # (n, 3) mm, commanded position after acc/dec filtering
    act: np.ndarray  # (n, 3) mm, actual position
    err: np.ndarray  # (n, 3) mm, following error = cmd - act
    vel: np.ndarray  # (n, 3) mm/s, actual axis velocity
    torque: np.ndarray  # (n, 3) N·m, motor torque command
    path_speed: np.ndarray  # (n,) mm/s, interpolator path speed (before filters)
    torque_constant: np.ndarray  # (3,) N·m/A
    summary: Summary
    every: int = 1
    program: str = ""
    force: np.ndarray | None = None  # (n, 3) N, cutting force on the tool, machine axes
    cut: np.ndarray | None = None  # (n, 7) spindle speed, torque, power, ae, ap, mrr, h_max
    engagement: object = None  # the cutting.engagement.Engagement used (stock, steps)
    record: np.ndarray | None = None  # index of the motion record (Program.records) being run, -1 none
    vb: np.ndarray | None = None  # (n,) mm, flank-wear land of the tool in the spindle (a wear effect)
    tool_use: dict | None = None  # tool number -> effects.ToolHistory: what the program cut with it
    vib: np.ndarray | None = None  # (n, 2) mm, tool-tip deflection (simulate --dynamics)

    def __len__(self) -> int:
        return len(self.t)

    def thinned(self, every: int) -> "Trace":
        """Every ``every``-th sample of a full-rate trace (and the last), as the servo loop
        stores them with ``every``."""
        from dataclasses import replace

        n = len(self.t)
        idx = np.arange(0, n, every)
        if n and idx[-1] != n - 1:
            idx = np.append(idx, n - 1)
        pick = {k: (getattr(self, k)[idx] if getattr(self, k) is not None else None)
                for k in ("t", "line", "cmd", "act", "err", "vel", "torque", "path_speed", "force", "cut", "record", "vb", "vib")}
        return replace(self, every=every, **pick)

    def signal(self, name: str) -> np.ndarray:
        """One measurement-format signal (``docs/measurement-format.md``) as a float64 array."""
        return np.asarray(self.columns_of(name), dtype=np.float64)

    def columns_of(self, name: str) -> np.ndarray:
        attr, col = _source(name)
        if attr == "feed":
            return self.feed
        if attr == "current":
            return self.torque[:, col] / self.torque_constant[col]
        a = getattr(self, attr)
        if a is None:
            from ..errors import MtwinError

            if attr == "vb":
                raise MtwinError("signal 'vb' (the flank-wear land) needs a wear effect in the twin "
                                 "(--effect flank-wear:rate=…, or [effects.flank-wear] in the twin file)")
            if attr == "vib":
                raise MtwinError(f"signal {name!r} (the tool tip's deflection) needs simulate --dynamics and a tool "
                                 f"with modes (docs/chatter.md)")
            raise MtwinError(f"signal {name!r} needs the cutting model (this trace has none)")
        return a if col < 0 else a[:, col]

    def set_signal(self, name: str, values: np.ndarray) -> None:
        """Replace one signal (a new array: the old one may be shared).  A measured position
        (``x``, ``y``, ``z``) also changes the following error of that axis."""
        attr, col = _source(name)
        if attr in ("feed", "current", "t", "line"):
            raise ValueError(f"signal {name!r} is derived from others and cannot be set")
        if col < 0:
            setattr(self, attr, np.asarray(values, dtype=np.float32).copy())
            return
        a = getattr(self, attr).copy()
        a[:, col] = values
        setattr(self, attr, a)
        if attr == "act":
            e = self.err.copy()
            e[:, col] = self.cmd[:, col] - a[:, col]
            self.err = e

    @property
    def feed(self) -> np.ndarray:
        """Actual path feed, mm/min."""
        return np.linalg.norm(self.vel.astype(np.float64), axis=1) * 60.0

    def columns(self) -> dict[str, np.ndarray]:
        """The trace as measurement-format columns (name -> array)."""
        cols: dict[str, np.ndarray] = {"t": self.t, "line": self.line}
        for name in SIGNALS:
            src = _source(name)[0]
            if (self.cut is not None or src not in ("cut", "force")) and (src != "vb" or self.vb is not None) \
                    and (src != "vib" or self.vib is not None):
                cols[name] = self.columns_of(name)
        if self.record is not None:
            # not a measurement column (readers keep and ignore it): which record of the
            # program made the sample, for subprograms, loops and canned cycles
            cols["record"] = self.record
        return cols

    def write(self, path: str | os.PathLike, metadata: dict[str, str] | None = None) -> None:
        """Write CSV (or Parquet when the name ends in .parquet) atomically."""
        write_columns(path, self.columns(), {"source": "mtwin simulate", **(metadata or {})})


WRITE_ROWS = 65536  # samples a CSV writer formats at once


def write_columns(path: str | os.PathLike, cols: dict[str, np.ndarray], metadata: dict[str, str] | None = None) -> None:
    """Write measurement-format columns as CSV (or Parquet for a .parquet name) atomically,
    or to standard output for ``-``."""
    import io
    import sys

    from ..io import atomic_output

    path = os.fspath(path)
    if path.endswith(".parquet"):
        try:
            import pyarrow as pa
            import pyarrow.parquet as pq
        except ImportError:
            from ..errors import MtwinError

            raise MtwinError("writing .parquet needs pyarrow (pip install pyarrow); use .csv") from None
        table = pa.table({k: np.asarray(v) for k, v in cols.items()})
        with atomic_output(path, binary=True) as fh:
            pq.write_table(table, fh)
        return
    meta = {"format": "mtwin-measurement 1", **(metadata or {})}
    # enough digits that a trace read back is the trace: 9 significant digits hold a float32
    # exactly (the stored channels), 12 the float64 command to a picometre at a metre
    fmts = []
    for name in cols:
        if name in ("line", "record"):
            fmts.append("%d")
        elif name == "t":
            fmts.append("%.9f")
        elif name.endswith("_cmd"):
            fmts.append("%.12g")
        else:
            fmts.append("%.9g")
    names = list(cols)
    li = names.index("line") if "line" in names else None
    n = len(next(iter(cols.values()))) if cols else 0

    def emit(fh):
        for k, v in meta.items():
            fh.write(f"# {k}: {v}\n")
        fh.write(",".join(cols) + "\n")
        # in blocks of rows: the text of an hour's trace is never all in memory at once (a
        # 4-h trace written whole took 650 bytes a sample beside the trace's 132)
        for lo in range(0, n, WRITE_ROWS):
            data = np.column_stack([np.asarray(v[lo:lo + WRITE_ROWS], dtype=np.float64) for v in cols.values()])
            no_line = li is not None and (data[:, li] < 0).any()
            if not no_line and np.isfinite(data).all():
                np.savetxt(fh, data, fmt=fmts, delimiter=",")
                continue
            # a sample before the control reported any line (a log): its line cell is left
            # empty, which reads back as no line — "-1" is no line number, and a reader refuses
            # it; so is a value that is not finite (a vibration past divergence): missing
            buf = io.StringIO()
            np.savetxt(buf, np.where(np.isfinite(data), data, 0.0), fmt=fmts, delimiter=",")
            bad = ~np.isfinite(data)
            for r, row in enumerate(buf.getvalue().splitlines()):
                cells = row.split(",")
                if no_line and data[r, li] < 0:
                    cells[li] = ""
                for c in np.flatnonzero(bad[r]):
                    cells[c] = ""
                fh.write(",".join(cells) + "\n")

    if path == "-":
        emit(sys.stdout)
        return
    with atomic_output(path) as fh:
        emit(fh)
