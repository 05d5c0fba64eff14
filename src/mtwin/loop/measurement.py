"""Reading measurements: the measurement format (``docs/measurement-format.md``).

A time series (a ``t`` column and named signals, units fixed by name) or a summary
measurement (one row per cut: ``first_line``, ``last_line`` and ``SIGNAL_STAT`` columns).
Everything a file can get wrong is an :class:`~mtwin.errors.MtwinError` naming the file,
the line and the column: an empty file, no time column, time going backwards, text in a
numeric column, a unit that is not the signal's, a mapping to a name the twin cannot
produce.  Empty cells and ``nan`` are missing values; irregular sampling and gaps are
fine.
"""
from __future__ import annotations

import csv
import functools
import io
import math
import os
import re
from dataclasses import dataclass, field

import numpy as np

from ..errors import GCodeError, MtwinError, SourceLocation
from ..motion.trace import SIGNALS

#: each signal's unit (the format fixes them by name)
UNITS = {**{a: "mm" for a in ("x", "y", "z")}, **{f"{a}_cmd": "mm" for a in "xyz"},
         **{f"{a}_err": "mm" for a in "xyz"}, **{f"{a}_vel": "mm/s" for a in "xyz"}, "feed": "mm/min",
         **{f"{a}_torque": "N*m" for a in "xyz"}, **{f"{a}_current": "A" for a in "xyz"},
         "spindle_speed": "rpm", "spindle_power": "W", "spindle_torque": "N*m", "spindle_load": "%",
         "fx": "N", "fy": "N", "fz": "N", "ae": "mm", "ap": "mm", "mrr": "mm^3/s", "h_max": "mm",
         "vb": "mm", "vib_x": "mm", "vib_y": "mm"}
STATS = ("mean", "rms", "std", "max", "min", "p2p")
#: columns of a control's log that are not signals, and their units
LOG_COLUMNS = {"tool": "", "feed_override": "%", "rapid_override": "%", "spindle_override": "%"}
_KNOWN = set(SIGNALS) | {"spindle_load"}
_HEADER_UNIT = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*(?:\[([^\]]*)\])?\s*$")


class MeasurementError(GCodeError):
    """A measurement file that cannot be read (exit 2), with its location."""


@dataclass
class Measurement:
    """A read measurement.  ``signals``: name -> float64 array (NaN where missing), in the
    format's units; ``line``: the program line of each sample (None when not recorded);
    for a summary measurement ``t`` is None and ``rows`` holds (first_line, last_line,
    {column: value})."""

    path: str
    t: np.ndarray | None
    signals: dict[str, np.ndarray]
    line: np.ndarray | None = None
    meta: dict[str, str] = field(default_factory=dict)
    ignored: list[str] = field(default_factory=list)
    rows: list = field(default_factory=list)
    # a control's log (an MTConnect log, or a file `mtwin import mtconnect` wrote):
    #: columns that are not signals, per sample: ``tool``, ``feed_override``,
    #: ``rapid_override``, ``spindle_override`` (%)
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    end_time: float | None = None  #: s, the end of the run (its last record may be after the last sample)
    holds: list = field(default_factory=list)  #: (t0, t1) s: feed holds
    stops: list = field(default_factory=list)  #: (t0, t1, state) s: program stops the control logged
    complete: bool | None = None  #: whether the run reached its end (None: not known)
    runs: list = field(default_factory=list)  #: the runs of the log (mtconnect.Run)
    source_line: np.ndarray | None = None  #: the file line of each sample (of each row: a summary)
    header: tuple = ()  #: a summary measurement's column names, in the file's order
    header_row: int = 0  #: the file line of its header
    #: a summary measurement's ``run`` column: the execution of the program (1, 2, …: a batch
    #: on the same tools) each row was cut in; None: every row is of one run
    row_runs: np.ndarray | None = None

    @property
    def is_summary(self) -> bool:
        return self.t is None

    def run_of_rows(self) -> np.ndarray:
        """Each summary row's run (all 1 without a ``run`` column)."""
        return self.row_runs if self.row_runs is not None else np.ones(len(self.rows), np.int64)

    @property
    def batch(self) -> int:
        """How many runs of the program the measurement's rows come from (1: one run)."""
        return int(self.row_runs.max()) if self.row_runs is not None and len(self.row_runs) else 1

    def write(self, path: str) -> None:
        """Write a time series in the measurement format (t, line, the signals, then the
        control's columns), its metadata as the file's comment lines."""
        from ..motion.trace import write_columns

        if self.t is None:
            raise MtwinError(f"{self.path}: a summary measurement is not written as a time series")
        cols = {"t": self.t, **({"line": self.line} if self.line is not None else {}), **self.signals, **self.extra}
        write_columns(path, cols, self.meta)


def signal_unit(name: str) -> str:
    """The unit of a signal or of a summary column (``fx_rms``: N)."""
    return UNITS.get(name) or UNITS.get(summary_base(name) or "", "")


def parse_maps(maps) -> dict[str, tuple[str, float]]:
    """``SRC=DST`` or ``SRC=DST*SCALE`` -> {SRC: (DST, SCALE)}."""
    out = {}
    for m in maps or ():
        src, eq, rest = m.partition("=")
        if not eq or not src.strip() or not rest.strip():
            raise MtwinError(f"--map {m}: expected SRC=DST or SRC=DST*SCALE")
        dst, _, scale = rest.partition("*")
        dst = dst.strip()
        base = summary_base(dst)
        if dst not in _KNOWN and base is None and dst not in ("t", "line"):
            raise MtwinError(f"--map {m}: {dst!r} is not a signal the twin produces "
                             f"(known: {', '.join(sorted(_KNOWN))})")
        try:
            k = float(scale) if scale else 1.0
        except ValueError:
            raise MtwinError(f"--map {m}: the scale {scale!r} is not a number") from None
        if not math.isfinite(k) or k == 0:
            raise MtwinError(f"--map {m}: the scale must be a finite non-zero number")
        out[src.strip()] = (dst, k)
    return out


def summary_base(name: str) -> str | None:
    """The signal a statistic column is of (``fy_rms``: ``fy``), or None."""
    for s in STATS:
        if name.endswith("_" + s) and name[:-len(s) - 1] in _KNOWN:
            return name[:-len(s) - 1]
    return None


def no_unknown_statistics(meas) -> None:
    """A column of a summary measurement that reads as a statistic of a signal but is not one
    the format knows (``fx_rmsx``, ``fq_rms``) is an error here: fitted, it would be left out
    silently, by a fit and by a comparison alike."""
    for c in meas.ignored:
        head, _, tail = c.rpartition("_")
        if head in _KNOWN or tail in STATS or any(c.startswith(k + "_") for k in _KNOWN):
            col = meas.header.index(c) + 1 if c in meas.header else 0
            raise MeasurementError(f"column {c!r} is not a statistic the measurement format knows (SIGNAL_STAT, "
                                   f"STAT one of {', '.join(STATS)}; signals: docs/measurement-format.md)",
                                   SourceLocation(meas.path, meas.header_row, col))


def same_program(logged: str, path: str) -> bool:
    """Whether a program name a control logged is the file's (its name, with or without the
    extension, in any case)."""
    a, b = os.path.basename(logged).lower(), os.path.basename(path).lower()
    return a == b or os.path.splitext(a)[0] == os.path.splitext(b)[0]


def check_against_program(meas: Measurement, program, any_program: bool = False) -> None:
    """A measurement recorded on another program is an error: a logged program name that is
    not the program file's (unless ``any_program``: a renamed file), a line beyond its end."""
    logged = (meas.meta or {}).get("program", "")
    if logged and not any_program and program.path:
        if not same_program(logged, program.path):
            raise MeasurementError(f"the log ran {logged}, not {os.path.basename(program.path)}: compare it with that "
                                   f"program (--any-program if this file is it, renamed)",
                                   SourceLocation(meas.path, 0, 0))
    n = int(program.data.count(b"\n")) + (0 if program.data.endswith(b"\n") else 1)
    beyond = [k for k, (_, last, _) in enumerate(meas.rows) if last > n]
    if beyond:
        k = beyond[0]
        col = meas.header.index("last_line") + 1 if "last_line" in meas.header else 0
        raise MeasurementError(f"last_line {meas.rows[k][1]} is beyond the end of {os.path.basename(program.path or '')} "
                               f"({n} lines): the measurement is of another program",
                               SourceLocation(meas.path, int(meas.source_line[k]) if meas.source_line is not None
                                              else 0, col))
    if meas.line is None or not len(meas.line):
        return
    beyond = np.flatnonzero(meas.line > n)
    if len(beyond):
        i = int(beyond[0])
        src = meas.source_line
        where = SourceLocation(meas.path, int(src[i]) if src is not None else 0, 0 if src is None else 1)
        raise MeasurementError(f"line {int(meas.line[i])} is beyond the end of {os.path.basename(program.path or '')} "
                               f"({n} lines): the measurement is of another program"
                               + (" (or its block numbers are N words: read it with `mtwin import mtconnect --block-is n "
                                  "--program PROGRAM` and compare the file that writes)" if src is not None else ""),
                               where)


def read_measurement(path: str, maps=(), ignore_items=(), run: int | None = None, program=None) -> Measurement:
    """Read a measurement file (CSV; Parquet when it ends in .parquet and pyarrow is there), or
    an MTConnect log (``ignore_items``: its data items to read past; ``run``: which program run
    of it, 1, 2, …, the last complete one by default; ``program``: the loaded program it is read
    against, which tells a log's runs that ran all of it from those that did not)."""
    mapping = parse_maps(maps)
    name = str(path)
    if not name.endswith(".parquet") and name != "-":
        from .mtconnect import Outline, is_mtconnect, read_mtconnect

        if is_mtconnect(name):  # an MTConnect log (SHDR or agent XML): read directly
            return read_mtconnect(name, run=run, ignore_items=ignore_items,
                                  outline=Outline.of(program) if program is not None else None)
    if run is not None:
        raise MeasurementError(f"--run {run}: only an MTConnect log holds several program runs; {name} is a "
                               f"measurement file of one", SourceLocation(name, 0, 0))
    if name.endswith(".parquet"):
        header, rows, meta, first_row = _read_parquet(name)
    else:
        header, rows, meta, first_row = _read_csv(name)
    # column names: maps, then units in brackets
    cols: list[tuple[str, float]] = []
    for j, h in enumerate(header):
        h = str(h).lstrip("\ufeff")
        if h.strip() in mapping:  # a mapped column may be named anything
            target, scale = mapping[h.strip()]
            cols.append((target, scale))
            continue
        m = _HEADER_UNIT.match(h)
        if not m:  # not a signal name: a column the twin does not know, kept out
            cols.append((f"<column {j + 1}: {h.strip()}>", 1.0))
            continue
        base, unit = m.group(1), m.group(2)
        # (a 'tool' column is a control log's only in a file `import mtconnect` wrote; elsewhere
        # it may hold anything, and is kept out like any column the twin does not know)
        if base.lower() in LOG_COLUMNS and (base.lower() != "tool" or "block_is" in meta):
            # a control's log as `mtwin import mtconnect` writes it: the tool and the overrides
            if unit is not None and unit.strip() != LOG_COLUMNS[base.lower()]:
                raise MeasurementError(f"column {base!r} is in {LOG_COLUMNS[base.lower()] or 'no unit'}, got [{unit}]",
                                       SourceLocation(name, first_row - 1, j + 1))
            cols.append((base.lower(), 1.0))
            continue
        target, scale = mapping.get(base, (base.lower(), 1.0))
        if unit is not None:
            scale *= _unit_scale(unit, target, name, first_row - 1, j)
        cols.append((target, scale))
    names = [c for c, _ in cols]
    dup = sorted({c for c in names if names.count(c) > 1})
    if dup:
        raise MeasurementError(f"column(s) {', '.join(dup)} appear twice", SourceLocation(name, first_row - 1, 1))
    summary = "first_line" in names and "last_line" in names
    if "t" not in names and not summary:
        raise MeasurementError("no time column 't' (and no first_line/last_line of a summary measurement); "
                               "--map SRC=t names another", SourceLocation(name, first_row - 1, 1))
    ignored = [c for c in names if c not in _KNOWN and c not in ("t", "line", "first_line", "last_line")
               and not (summary and c == "run")
               and summary_base(c) is None and c not in LOG_COLUMNS]
    # a column the twin does not know is kept out of the numbers: whatever it holds is fine
    data = _numbers(rows, header, name, first_row, [c not in ignored for c in names],
                    [(*_bound(c), c, k) for c, k in cols])
    if summary:
        return _summary(name, names, cols, data, meta, ignored, first_row)
    if len(data) == 0:
        raise MeasurementError("no samples (the file has a header but no rows)", SourceLocation(name, first_row, 1))
    k = names.index("t")
    t = data[:, k] * cols[k][1]
    if np.isnan(t).any():
        i = int(np.argmax(np.isnan(t)))
        raise MeasurementError("a sample without a time (t is empty or nan)", SourceLocation(name, first_row + i, k + 1))
    back = np.flatnonzero(np.diff(t) < 0)
    if back.size:
        i = int(back[0]) + 1
        raise MeasurementError(f"time goes backwards: t = {t[i]:g} s after {t[i - 1]:g} s",
                               SourceLocation(name, first_row + i, k + 1))
    signals = {}
    line = None
    for j, (c, scale) in enumerate(cols):
        if c == "line":
            v = data[:, j]
            bad = ~np.isnan(v) & ((v != np.round(v)) | (v < 0))
            if bad.any():
                i = int(np.argmax(bad))
                raise MeasurementError(f"line {v[i]:g} is not a line number", SourceLocation(name, first_row + i, j + 1))
            line = np.where(np.isnan(v), -1, v).astype(np.int64)
        elif c in _KNOWN:
            signals[c] = data[:, j] * scale
    extra = {c: data[:, j] for j, (c, _) in enumerate(cols) if c in LOG_COLUMNS}
    fields = log_fields(meta, name)
    # (the metadata's times are written to 0.1 ms, the samples' to 1 ns: a span rounded down to
    # the sample it ends at is no error)
    if fields.get("end_time") is not None and len(t) and fields["end_time"] < float(t[-1]) - 1e-4:
        key = "end_time_s" if "end_time_s" in meta else "cycle_time_s"
        raise MeasurementError(f"metadata {key}: the run ends at {fields['end_time']:g} s, before its last "
                               f"sample at {float(t[-1]):g} s", SourceLocation(name, 0, 0))
    return Measurement(name, t, signals, line, meta, ignored, extra=extra, **fields)


def log_fields(meta: dict, path: str = "") -> dict:
    """The run's end, feed holds, program stops and completeness a control's log had, from the
    metadata `mtwin import mtconnect` writes (``end_time_s``, ``feed_holds_s``,
    ``program_stops_s``, ``complete``)."""
    out: dict = {}
    # the run's span: ``end_time_s``; files written before it had the span as ``cycle_time_s``
    # (which now is the span less the holds and stops): each is checked where it is given
    # (a cycle of 0 s beside its span: the machine stood the whole run; alone, it is the span)
    times = {key: _seconds(meta, key, path, zero=key == "cycle_time_s" and "end_time_s" in meta)
             for key in ("end_time_s", "cycle_time_s") if key in meta}
    if times:
        out["end_time"] = times.get("end_time_s", times.get("cycle_time_s"))
        if len(times) == 2 and times["cycle_time_s"] > times["end_time_s"] + 1e-6:
            raise MeasurementError(f"metadata cycle_time_s: {meta['cycle_time_s']!r} is longer than the run's span, "
                                   f"end_time_s {meta['end_time_s']!r}", SourceLocation(path, 0, 0))
    holds, stops = [], []
    for key, into in (("feed_holds_s", holds), ("program_stops_s", stops)):
        for part in filter(None, (x.strip() for x in meta.get(key, "").split(";"))):
            span, _, state = part.partition(" ")
            a, _, b = span.partition("-")
            try:
                iv = (float(a), float(b))
            except ValueError:
                raise MeasurementError(f"metadata {key}: {part!r} is not an interval t0-t1 in s",
                                       SourceLocation(path, 0, 0)) from None
            into.append(iv if key == "feed_holds_s" else (*iv, state or "STOPPED"))
    out["holds"], out["stops"] = holds, stops
    if meta.get("complete") in ("yes", "no"):
        out["complete"] = meta["complete"] == "yes"
    return out


_SECONDS = re.compile(r"[+]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?")


def _seconds(meta: dict, key: str, path: str, zero: bool = False) -> float:
    """A metadata time in s: a plain decimal number, finite and above 0 (or 0 itself, ``zero``:
    a cycle whose whole span the machine stood)."""
    text = meta[key].strip()
    v = float(text) if _SECONDS.fullmatch(text) else math.nan
    if not (math.isfinite(v) and (v > 0 or (zero and v == 0))):
        raise MeasurementError(f"metadata {key}: {meta[key]!r} is not a time in s (a number "
                               f"{'of 0 or more' if zero else 'above 0'})", SourceLocation(path, 0, 0))
    return v


# -- when the machine stood: one judge, for the reading, the replay and the block timing

HELD = 1.0  # %: a feed override below this holds the machine (its time is the operator's)
MOVING = 1.0  # mm/min: a logged path feed above this is motion


def merged(spans) -> list:
    """The (t0, t1) spans (further fields ignored) as a sorted list of disjoint ones."""
    out: list = []
    for a, b, *_ in sorted(spans):
        if b <= a:
            continue
        if out and a <= out[-1][1]:
            out[-1] = (out[-1][0], max(out[-1][1], b))
        else:
            out.append((a, b))
    return out


def coverage(spans):
    """A function of (a, b): the s of [a, b) inside the spans, their union (a time in two of them
    counts once).  The spans are merged once and each query is two binary searches: a log's
    every block group asks it (a single-block run has a stop at every line)."""
    m = merged(spans)
    s0 = np.array([a for a, _ in m], np.float64)
    s1 = np.array([b for _, b in m], np.float64)
    done = np.concatenate([[0.0], np.cumsum(s1 - s0)])  # the time covered up to each span's start

    def before(x: float) -> float:  # s covered before x
        k = int(np.searchsorted(s1, x, "right"))  # (the spans ended by x)
        return float(done[k]) + (max(0.0, x - float(s0[k])) if k < len(s0) else 0.0)

    return lambda a, b: before(b) - before(a) if b > a else 0.0


def covered(spans, a: float, b: float) -> float:
    """s of [a, b) inside the spans (their union: a time in two of them counts once)."""
    return coverage(spans)(a, b)


def held_spans(meas: Measurement) -> list:
    """(t0, t1) spans where the feed override stood below HELD % and the machine stood (its
    logged feed 0, where it logs one: on a Fanuc-style control rapids run on at a feed override
    of 0), less what the log's own holds and stops already take out (never counted twice).  A
    rapid override at 0 is the control's slowest rapid (F0), not a hold."""
    v = meas.extra.get("feed_override")
    if v is None or meas.t is None or not len(meas.t):
        return []
    v = np.asarray(v, np.float64)
    t = np.asarray(meas.t, float)
    end = float(meas.end_time) if meas.end_time is not None else float(t[-1])
    low = np.nan_to_num(v, nan=100.0) < HELD
    feed = meas.signals.get("feed")
    out: list = []
    edges = np.flatnonzero(np.diff(np.r_[False, low, False].astype(np.int8)))
    for i, j in zip(edges[::2], edges[1::2]):
        if feed is not None:
            f = np.nan_to_num(np.asarray(feed, float)[i:j], nan=0.0)
            still = np.flatnonzero(f <= MOVING)  # (the feed logged at the turn of the knob is the last one's)
            if not len(still) or (f[still[0]:] > MOVING).any():
                continue  # (it moved: not held)
        out.append((float(t[i]), float(t[j]) if j < len(t) else end))
    cover = merged([*(meas.holds or []), *(meas.stops or [])])
    return [x for a, b in out for x in _minus(a, b, cover) if x[1] > x[0]]


def _minus(a: float, b: float, cover: list) -> list:
    """[a, b) less the spans of ``cover`` (sorted, disjoint)."""
    out, at = [], a
    for c0, c1 in cover:
        if c1 <= at or c0 >= b:
            continue
        if c0 > at:
            out.append((at, c0))
        at = max(at, c1)
    if at < b:
        out.append((at, b))
    return out


def _unit_scale(unit: str, target: str, path: str, line: int, col: int) -> float:
    want = UNITS.get(target) or UNITS.get(summary_base(target) or "", None)
    if target in ("t",):
        want = "s"
    if want is None:
        raise MeasurementError(f"column {target!r} takes no unit, got [{unit}]", SourceLocation(path, line, col + 1))
    from ..units import UnitError, convert

    try:
        return float(convert(f"1 {unit}", want, target))
    except UnitError as exc:
        raise MeasurementError(f"unknown or wrong unit [{unit}] for {target} (its unit is {want}): {exc}",
                               SourceLocation(path, line, col + 1)) from None


def _read_csv(path: str):
    from ..io import read_input

    try:
        # (stdin within the same limit as a file; a spreadsheet's BOM taken off)
        text = read_input(path, "measurement").decode("utf-8").lstrip("\ufeff")
    except OSError as exc:
        raise MtwinError(f"cannot read {path}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise MtwinError(f"{path}: not UTF-8 text (a measurement is a CSV file of the measurement format, or "
                         f"a control's MTConnect log: SHDR timestamp|item|value lines or agent XML)") from None
    lines = text.splitlines()
    meta = {}
    k = 0
    while k < len(lines) and (lines[k].startswith("#") or not lines[k].strip()):
        m = re.match(r"#\s*([^:]+):\s*(.*)$", lines[k])
        if m:
            meta[m.group(1).strip()] = m.group(2).strip()
        k += 1
    if k >= len(lines):
        raise MeasurementError("the file is empty: neither a measurement (no header row) nor an MTConnect log (no "
                               "timestamp|item|value record)", SourceLocation(path, max(k, 1), 1))
    reader = csv.reader(io.StringIO("\n".join(lines[k:])))
    try:
        header = next(reader)
        rows = list(reader)
    except csv.Error as exc:  # (a field over the csv module's limit, a NUL byte)
        raise MeasurementError(f"not a CSV row: {exc}", SourceLocation(path, k + reader.line_num, 1)) from None
    return header, rows, meta, k + 2


def _read_parquet(path: str):
    try:
        import pyarrow.parquet as pq
    except ImportError:
        raise MtwinError(f"{path}: reading .parquet needs pyarrow (pip install pyarrow)") from None
    from ..io import check_input

    check_input(path, "measurement")
    import pyarrow as pa

    table = pq.read_table(path)
    header = list(table.column_names)
    cols = []
    for c in header:
        col = table.column(c)
        if pa.types.is_timestamp(col.type) or pa.types.is_duration(col.type):
            # a clock column: seconds from the first sample
            ns = np.asarray(col.cast(pa.int64()).to_numpy(zero_copy_only=False), dtype=np.float64)
            unit = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}[col.type.unit]
            cols.append(list((ns - ns[0]) * unit) if len(ns) else [])
        else:
            cols.append(col.to_pylist())
    rows = [list(r) for r in zip(*cols)]
    return header, rows, {}, 2


MAX_MAGNITUDE = 1e100  # (epoch nanoseconds are 1.7e18: a bound on magnitude only)
# the largest time a recording's t may hold, s: epoch seconds (1.7e9) pass, 1e99 does not
MAX_TIME = 1e10
# a line number, run number or tool number beyond this is not one
MAX_COUNT = 1e9


@functools.lru_cache(maxsize=None)  # (asked for every override item of a log)
def max_override() -> float:
    """The largest override a log may hold, %: the most the twin's ``controller.feed_override``
    takes (its declaration's bound), so a log's override can always be replayed."""
    from dataclasses import fields

    from ..twin.machine import Controller

    return float(next(f for f in fields(Controller) if f.name == "feed_override").metadata["hi"])


def _bound(column: str) -> tuple[float, str]:
    """The largest magnitude a column may hold in the format's unit, and that unit: an
    instrument records no 1e99 W (the bounds are the parameters' own, ``params.UNIT_MAX``)."""
    from ..params import UNIT_MAX

    if column == "t":
        top, unit = MAX_TIME, "s"
    elif column in ("line", "first_line", "last_line", "run", "tool"):
        top, unit = MAX_COUNT, ""
    elif column in LOG_COLUMNS:  # an override: at most what the twin's controller takes
        top, unit = max_override(), "%"
    else:
        unit = UNITS.get(column) or UNITS.get(summary_base(column) or "", "")
        top = UNIT_MAX.get(unit, MAX_MAGNITUDE) if unit else MAX_MAGNITUDE
    return top, unit


def _numbers(rows, header, path, first_row, read, bounds=None) -> np.ndarray:
    n, m = len(rows), len(header)
    out = np.full((n, m), np.nan)
    for i, r in enumerate(rows):
        if len(r) != m:
            if not any(str(x).strip() for x in r):
                continue  # a blank line
            raise MeasurementError(f"{len(r)} cells where the header has {m}", SourceLocation(path, first_row + i, 1))
        for j, cell in enumerate(r):
            if cell is None or not read[j]:
                continue
            if isinstance(cell, (int, float)):
                v = float(cell)
                if math.isnan(v):
                    continue
            else:
                s = cell.strip()
                if not s or s.lower() == "nan":
                    continue  # a missing value
                try:
                    v = float(s)
                except ValueError:
                    raise MeasurementError(f"{s!r} in column {header[j]!r} is not a number",
                                           SourceLocation(path, first_row + i, j + 1)) from None
            # an infinite value (or one no instrument gives in any unit) would make every figure
            # after it inf or NaN: it is an error of the file, not a measurement
            if not abs(v) <= MAX_MAGNITUDE:
                raise MeasurementError(f"{cell!s} in column {header[j]!r} is not a finite measured value (at most "
                                       f"{MAX_MAGNITUDE:g} in magnitude; leave the cell empty for a missing value)",
                                       SourceLocation(path, first_row + i, j + 1))
            if bounds is not None and abs(v * bounds[j][3]) > bounds[j][0]:  # (in the format's unit)
                top, unit, target, scale = bounds[j]
                # (a column renamed or scaled on the way in says so: --map, or a unit in brackets)
                read_as = f" (read as {target} × {scale:g} = {v * scale:g})" if scale != 1.0 else \
                    (f" (read as {target})" if target != str(header[j]).strip() else "")
                raise MeasurementError(f"{cell!s} in column {header[j]!r}{read_as} is beyond what a machine records "
                                       f"(at most {top:g}{' ' + unit if unit else ''}): a typo or a unit mistake?",
                                       SourceLocation(path, first_row + i, j + 1))
            out[i, j] = v
    keep = ~np.all(np.isnan(out), axis=1) if n else np.zeros(0, bool)
    return out[keep]


def _summary(name, names, cols, data, meta, ignored, first_row) -> Measurement:
    a, b = names.index("first_line"), names.index("last_line")
    k_run = names.index("run") if "run" in names else None
    runs = []
    rows = []
    stat_cols = [j for j, (c, _) in enumerate(cols) if summary_base(c) is not None]
    for i in range(len(data)):
        f, l_ = data[i, a], data[i, b]
        if not (f >= 1 and l_ >= f and f == int(f) and l_ == int(l_)):
            raise MeasurementError(f"first_line {f:g} / last_line {l_:g} is not a range of program lines",
                                   SourceLocation(name, first_row + i, a + 1))
        stats = {cols[j][0]: data[i, j] * cols[j][1] for j in stat_cols}
        if stat_cols and all(math.isnan(v) for v in stats.values()):
            raise MeasurementError(f"the row of lines {int(f)}–{int(l_)} has no value in any statistic column",
                                   SourceLocation(name, first_row + i, stat_cols[0] + 1))
        rows.append((int(f), int(l_), stats))
        if k_run is not None:
            r = data[i, k_run]
            if not (r >= 1 and r == int(r)):
                raise MeasurementError(f"run {r:g}: the run of a row is the execution of the program it was cut in, "
                                       f"1, 2, …", SourceLocation(name, first_row + i, k_run + 1))
            runs.append(int(r))
    if not rows:
        raise MeasurementError("no rows (the file has a header but no rows)", SourceLocation(name, first_row, 1))
    return Measurement(name, None, {}, None, meta, ignored, rows,
                       source_line=np.arange(first_row, first_row + len(rows), dtype=np.int64),
                       header=tuple(names), header_row=first_row - 1,
                       row_runs=np.array(runs, np.int64) if k_run is not None else None)
