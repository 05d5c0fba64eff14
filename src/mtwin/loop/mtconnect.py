"""MTConnect logs into the measurement format: SHDR (``timestamp|item|value``, several
item/value pairs on a line, values logged on change) and agent XML streams
(``MTConnectStreams``).

What a control reports is a set of data items, each logged when it changes.  The reader turns
them into a time series sampled at every change: ``t`` (s since the program started),
``line`` (the program line being executed), ``feed`` (the actual path feed, converted from
the mm/s MTConnect reports to mm/min), ``spindle_speed`` (rpm), and extra columns ``tool``,
``feed_override``, ``rapid_override`` and ``spindle_override`` (%) where the log has them.

Quirks handled (seen in the NIST Hurco VMX24 logs, docs/validation.md):

* ``Block_Number`` is the 1-based line of the program file, not its N word (``--block-is
  line``, the default); ``--block-is n`` maps N words to lines, in program order, so N
  numbers that wrap (every 990 lines in those posts) still find their line;
* lines the control never reports (sampled every 0.15–0.2 s) belong to the block before: the
  ``line`` column holds the last reported line until the next;
* a broken record — a value alone on the next line after ``|Block_Number|`` — is joined back;
* ``Program_Runtime_Seconds`` first repeats the previous program's total: it is not used;
* program names may switch before the start: a run is named by ``Program_Name_Running`` at
  its ``Program_Status`` ACTIVE;
* several programs (or repeats) in one log are separate runs, from ACTIVE to the next
  PROGRAM_COMPLETED or READY; ``run`` picks one (the last complete one by default); a run
  the log ends in, or one reset to READY from a stop or a feed hold (aborted), is incomplete;
* a restart: after a stop, execution resumes with the block number back near the run's first
  — an aborted run followed by a new one (listed, with how far the aborted one got and
  when); resumed further back than it stopped but not at the start, lines ran twice — the
  first pass through them is taken out with the stop (state RESTART), never counted twice;
* feed holds (``Execution`` FEED_HOLD until ACTIVE again) and program stops (STOPPED,
  OPTIONAL_STOP, PROGRAM_STOPPED, INTERRUPTED until ACTIVE again: M00, M01, an operator's
  stop) are intervals of the run, in the metadata as ``feed_holds_s`` and ``program_stops_s``;
* overrides are read as time series (``feed_override``, ``rapid_override``,
  ``spindle_override``, %): the standard's ``PathFeedrateOverride`` (subType PROGRAMMED or
  RAPID) and ``RotaryVelocityOverride``, Hurco's ``Feed_Override``, ``Rapid_Override``,
  ``Spindle_Override`` and the short names adapters use (Fovr, Rovr, Sovr); one the log does
  not have is 100 %, and the metadata says which were not logged.
"""
from __future__ import annotations

import math
import os

import re
from dataclasses import dataclass, field
from datetime import datetime, timezone

import numpy as np

from ..errors import SourceLocation
from .measurement import Measurement, MeasurementError, covered, held_spans, max_override, same_program

_NAMES = ("Block_Number", "Feed_Rate", "Spindle_Speed", "Current_Tool", "Program_Status", "Execution",
          "Program_Name_Running", "Program", "Line", "PathFeedrate", "RotaryVelocity", "ToolNumber",
          "PathFeedrateOverride", "RapidOverride", "RotaryVelocityOverride", "Feed_Override", "Rapid_Override",
          "Spindle_Override")
_TS = re.compile(r"^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(?:\.\d+)?Z?")
# the end of a run: completed, or reset to READY (after a stop: aborted)
_END = {"PROGRAM_COMPLETED", "READY"}
# a program stop (M00, M01 with optional stop on, an operator's stop or interruption): the run
# goes on when the control is ACTIVE again; READY next means it was aborted
_STOP = {"STOPPED", "INTERRUPTED", "PROGRAM_STOPPED", "OPTIONAL_STOP", "PROGRAM_OPTIONAL_STOP"}
_STATES = _END | _STOP | {"ACTIVE", "FEED_HOLD", "WAIT", "UNAVAILABLE"}  # MTConnect's Execution values
# data item names (SHDR item names or XML element names / names) -> what they are; the
# MTConnect standard's types (PathFeedrateOverride with subType PROGRAMMED or RAPID,
# RotaryVelocityOverride, Execution), the Hurco WinMax adapter's names and the short names
# common adapters give them (Fovr, Rovr, Sovr)
_ITEMS = {
    "block_number": "block", "line": "block", "linenumber": "block", "line_number": "block",
    "feed_rate": "feed", "pathfeedrate": "feed", "path_feedrate": "feed", "actual_feed": "feed",
    "spindle_speed": "spindle", "rotaryvelocity": "spindle", "spindlespeed": "spindle",
    "current_tool": "tool", "toolnumber": "tool", "tool_number": "tool",
    "program_status": "status", "execution": "status",
    "program_name_running": "program", "program": "program", "program_name_editing": "program_editing",
    "feed_override": "feed_ovr", "pathfeedrateoverride": "feed_ovr", "feedrate_override": "feed_ovr",
    "feedrateoverride": "feed_ovr", "path_feedrate_override": "feed_ovr", "feedoverride": "feed_ovr",
    "fovr": "feed_ovr", "feed_ovr": "feed_ovr",
    "rapid_override": "rapid_ovr", "rapidoverride": "rapid_ovr", "rapid_feed_override": "rapid_ovr",
    "rapidfeedoverride": "rapid_ovr", "rapid_traverse_override": "rapid_ovr", "rovr": "rapid_ovr",
    "frapidovr": "rapid_ovr", "rapid_ovr": "rapid_ovr",
    "spindle_override": "spindle_ovr", "rotaryvelocityoverride": "spindle_ovr", "spindleoverride": "spindle_ovr",
    "spindle_speed_override": "spindle_ovr", "rotary_velocity_override": "spindle_ovr", "sovr": "spindle_ovr",
    "spindle_ovr": "spindle_ovr",
}
#: the override items, by the measurement column they become
OVERRIDES = {"feed_ovr": "feed_override", "rapid_ovr": "rapid_override", "spindle_ovr": "spindle_override"}


# data items a log may hold that a comparison does not use (read past, not errors); anything
# else is an unknown item: an error, since it may be one of ours under a name we do not know
_UNUSED = re.compile(
    r"(program_runtime_seconds|spindle_time|part_?count|avail(ability)?|e_?stop|emergency_?stop|"
    r"(controller_?)?mode|[xyzabcuvw](act|com|pos|load|temp|_?position|_?load|_?temperature)|"
    r"(path_?)?position|.*_?(load|temperature|temp|alarm|message|fault|warning|condition)|"
    r"spindle_load|axis_?.*|door.*|coolant.*|operator.*|user.*|block|block_?text|block_?content|"
    r"program_?comment|line_?label|tool_?(life|offset|length|radius).*|work_?offset.*|"
    r"asset.*|device.*|functional_?mode|power.*|serial.*|clock.*|uptime.*|cycle_?time.*)", re.I)


def is_mtconnect(path: str) -> bool:
    """A file that looks like an SHDR log or an MTConnectStreams document."""
    import stat as _stat

    try:
        if not _stat.S_ISREG(os.stat(path).st_mode):
            return False  # (the reader says what it is)
        with open(path, "rb") as fh:
            head = fh.read(4096).decode("utf-8", "replace")
    except OSError:
        return False
    first = head.lstrip("\ufeff").lstrip().splitlines()[0] if head.strip() else ""
    return bool(_TS.match(first) and "|" in first) or "<MTConnectStreams" in head


@dataclass
class Event:
    t: float  # s since the epoch
    item: str  # normalised kind (see _ITEMS), or the raw name
    value: str
    line: int  # line of the log file


@dataclass
class Run:
    program: str
    start: int  # index into the events
    end: int  # one past the last event
    complete: bool
    holds: list = field(default_factory=list)  # (t0, t1) s since the run's start
    stops: list = field(default_factory=list)  # (t0, t1, state) s since the run's start
    reached: int = -1  # the last block number the run reported (how far an aborted run got)
    ended: str = ""  # how an incomplete run ended, in words
    skip: list = field(default_factory=list)  # (k0, k1) events of a first pass a restart repeated
    restarts: list = field(default_factory=list)  # (t s since the run's start, from line, back to line)
    late: int = 0  # the first line a run reported that started past the program's start (0: it did not)
    end_state: str = ""  # the end state logged (PROGRAM_COMPLETED, READY)
    until: float = 0.0  # s since the epoch the run ended at, where later than its last event (an M99 pass)
    gaps: list = field(default_factory=list)  # (t0, t1) s since the run's start the control's data was UNAVAILABLE
    other_name: str = ""  # where the run logs no running name: the other name it may have had
    label: str = "line"  # what its block numbers are, for a person ("line", or "N" for N words)

    def describe(self) -> str:
        """One line for a person: the program, complete or how it ended, its pauses."""
        what = "complete" if self.complete else f"incomplete ({self.ended or 'the log ends in it'})"
        out = f"{self.program or '(unnamed)'}, {what}"
        if self.reached >= 0 and not self.complete:
            out += f", reached {_word(self.label, self.reached)}"
        if self.holds:
            out += f", {len(self.holds)} feed hold(s)"
        if self.stops:
            states = [st for _, _, st in self.stops]  # (counted: single-block mode stops at every line)
            kinds = dict.fromkeys(states)
            out += (f", 1 program stop ({states[0]})" if len(states) == 1 else f", {len(states)} program stops ("
                    + (next(iter(kinds)) if len(kinds) == 1 else ", ".join(f"{states.count(x)} {x}" for x in kinds)) + ")")
        for a, b in self.gaps:
            out += f", no data {a:.0f}–{b:.0f} s (the control UNAVAILABLE: an adapter's reconnect; the run went on)"
        if self.other_name:
            out += (f" (its running program is not logged: {self.program} or {self.other_name}, by the names "
                    f"logged before it)")
        for t, a, b in self.restarts:
            span = f"lines {b}–{a}" if self.label == "line" else f"N{b}–N{a}"
            out += (f"; stopped at {t:.0f} s at {_word(self.label, a)} and started again from {_word(self.label, b)} "
                    f"(its first pass through {span} is taken out: no time is counted twice)")
        return out


# a run whose first reported line lies past the lines of the program's first few moves started
# in the middle (or its logger late); one whose last lies before the lines of its last few did
# not finish (a reset to READY looks like an end): the lines a log may miss at either end
EDGE_LINES = 5
EDGE_LEAST = 2  # (and at least these, however short the program)
# lines a program's own jump back (a loop, a subprogram's return) may lie from where the log saw
# it go back: the lines the log did not report either side of it
JUMP_LINES = 50


@dataclass(frozen=True)
class Outline:
    """What a log's runs are read against: the program's file name, where a run must start and
    end to be its whole cycle, and where the program itself goes back in lines (a loop, a
    subprogram's return), which a restart is not."""

    name: str
    start_line: int  # a run that first reports a line past this one did not start at the start
    back: np.ndarray  # (jumps, 2): (from line, to line) of each jump back of the execution order
    window: int = JUMP_LINES  # how far either side of a jump the log may have seen it (in block numbers)
    label: str = "line"  # what the block numbers are, for a person ("line", or "N" for N words)
    last_line: int = 0  # the line of the program's last move: a pass that reached it ran to the end
    loops: bool = False  # the program ends in M99: it runs again until reset, and never ends by itself
    tail: tuple = ()  # the lines of its last few moves (distinct, in the order last run): a run that reports none
    # of them, nor a line of the main program after its last move, did not reach the end
    main_end: int = 0  # the first subprogram line after the last move (0: none): the main program's lines end there

    @property
    def end_line(self) -> int:
        """The first of the lines of its last few moves (0: none), for a person."""
        return self.tail[-1] if self.tail else 0

    def finished(self, block: int) -> bool:
        """Whether a run that reported ``block`` reached the program's last move (its line, or a
        line of the main program after it: M30) — not a subprogram's line further down the file."""
        return block >= self.last_line and (not self.main_end or block < self.main_end)

    def at_end(self, block: int) -> bool:
        """Whether ``block`` is one of the program's last few moves' lines, or after them."""
        return block in self.tail or self.finished(block)

    @classmethod
    def of(cls, program) -> "Outline":
        from ..gcode import records as R

        rec = program.records
        ok = rec["line"] > 0
        lines = np.asarray(rec["line"][ok], np.int64)  # (dwells too: a G4 may end a loop's body)
        moves = np.asarray(rec["line"][ok & (rec["kind"] != R.DWELL)], np.int64)
        if not len(moves):
            return cls(os.path.basename(program.path or ""), 0, np.zeros((0, 2), np.int64))
        _, first = np.unique(moves, return_index=True)
        ahead = moves[np.sort(first)]  # distinct lines in the order first run
        _, last = np.unique(moves[::-1], return_index=True)
        behind = moves[::-1][np.sort(last)]  # distinct lines, the last run first
        k = np.flatnonzero(lines[1:] < lines[:-1])
        # (on a short program, a tenth of its lines: five of twenty would take a reset a quarter
        # from its end for a finish)
        edge = min(EDGE_LINES, max(EDGE_LEAST, len(ahead) // 10))
        sub = np.asarray(rec["line"][ok & ((rec["flags"] & R.FL_SUB) != 0)], np.int64)
        below = sub[sub > moves[-1]]
        return cls(os.path.basename(program.path or ""), int(ahead[min(edge, len(ahead)) - 1]),
                   np.stack([lines[k], lines[k + 1]], axis=1),
                   last_line=int(moves[-1]), loops=bool(getattr(program, "loops", False)),
                   tail=tuple(int(x) for x in behind[:edge]), main_end=int(below.min()) if below.size else 0)

    def in_n_words(self, program_data: bytes) -> "Outline | None":
        """The outline with N numbers for lines (a log whose block numbers are N words): each
        line as the N word on it or the last before it.  None where the N words do not rise
        through the file (numbers that repeat or wrap cannot be told apart)."""
        table = n_to_lines(program_data)
        if not table or any(len(v) > 1 for v in table.values()):
            return None
        ns = sorted((v[0], n) for n, v in table.items())
        if any(b[1] <= a[1] for a, b in zip(ns, ns[1:])):
            return None
        at, num = np.array([x for x, _ in ns]), np.array([n for _, n in ns])

        def n_of(line):
            k = np.searchsorted(at, np.asarray(line), side="right") - 1
            return np.where(k >= 0, num[np.maximum(k, 0)], 0)

        step = max(int(np.median(np.diff(num) / np.maximum(np.diff(at), 1))), 1) if len(num) > 1 else 1
        return Outline(self.name, int(n_of(self.start_line)),
                       n_of(self.back).reshape(-1, 2) if len(self.back) else self.back, JUMP_LINES * step, "N",
                       int(n_of(self.last_line)), self.loops, tuple(int(n_of(x)) for x in self.tail),
                       int(n_of(self.main_end)) if self.main_end else 0)

    def goes_back(self, was: int, now: int) -> bool:
        """Whether the program itself jumps back from about ``was`` to about ``now`` (the log
        reported ``was`` last before going back and ``now`` first after it: lines either side
        of the jump may go unreported, or carry no move — an M99, a T M6 after the return)."""
        a, b = self.back[:, 0], self.back[:, 1]
        return bool(np.any((np.abs(a - was) <= self.window) & (np.abs(b - now) <= self.window)))

    def names(self, logged: str) -> bool:
        """Whether a logged program name is this program's."""
        return bool(self.name) and bool(logged) and same_program(logged, self.name)


_ZONE = re.compile(r"(Z|[+-]\d\d:?\d\d)$", re.IGNORECASE)


def _seconds(ts: str, path: str, ln: int) -> float:
    """s since the epoch of an ISO 8601 timestamp.  Its zone is honoured (+01:00, +0200, Z): a
    log written across a daylight-saving change, or one adapter in local time beside another in
    UTC, keeps its true durations; one without a zone is UTC (what MTConnect writes), never the
    zone of the computer that reads it."""
    m = _ZONE.search(ts)
    s, zone = (ts[:m.start()], m.group(1)) if m else (ts, "")
    if "." in s:
        head, frac = s.split(".", 1)
        # (datetime takes microseconds — 7-digit .NET ticks are common — and, before Python
        # 3.11, only 3 or 6 digits)
        s = f"{head}.{frac[:6].ljust(6, '0')}"
    if zone and zone.upper() != "Z":
        s += zone if ":" in zone else f"{zone[:3]}:{zone[3:]}"
    try:
        d = datetime.fromisoformat(s)
    except ValueError:
        raise MeasurementError(f"cannot read the timestamp {ts!r}", SourceLocation(path, ln, 1)) from None
    return (d if d.tzinfo else d.replace(tzinfo=timezone.utc)).timestamp()


def read_shdr(path: str, ignore=()) -> list:
    """Events of an SHDR log, in file order.  An item neither used nor known to be unused is
    an error (``ignore``: names to read past); so is a timestamp before the previous one."""
    ignore = {x.lower() for x in ignore}
    try:
        from ..io import read_input

        text = read_input(path, "log").decode("utf-8", "replace")
    except OSError as exc:
        raise MeasurementError(f"cannot read {path}: {exc.strerror or exc}", SourceLocation(path, 0, 0)) from None
    out: list = []
    lines = text.splitlines()
    # a log copied while the agent still wrote it ends in a record cut short: no newline after
    # it, and not a whole record — left out (and said so) rather than refusing the whole log
    last = len(lines) if lines and not text.endswith(("\n", "\r")) else 0
    for i, raw in enumerate(lines, 1):
        ln = raw.strip().lstrip("\ufeff")
        if not ln:
            continue
        if i == last:
            try:
                n = len(out)
                _record(ln, out, path, i, ignore)
            except MeasurementError as exc:
                if not out:
                    raise
                out = Events(out)
                out.cut_last = f"line {i}, the last, is not a whole record ({exc.message}): cut short, a log still " \
                               f"being written when it was copied — left out"
            else:
                # a whole record may still have lost digits of its value (Block_Number 18 of 1827):
                # nothing in the record tells, so it is read as it stands, and said so
                if len(out) > n and out[-1].item == "status" and out[-1].value.upper() not in _STATES:
                    # a state word cut short (PROGRAM_COMPLETED as "P"): no state, left out
                    cut = out.pop()
                    out = Events(out)
                    out.cut_last = (f"line {i}, the last, has no line end and its state {cut.value!r} is none the "
                                    f"control logs: cut short, a log still being written when it was copied — left out")
                elif len(out) > n and _NUMBER.match(out[-1].value or ""):
                    out = Events(out)
                    out.cut_last = f"line {i}, the last, has no line end: if the log was copied while still being " \
                                   f"written its value may be cut short (it reads {out[-1].value}); read as it stands"
            continue
        _record(ln, out, path, i, ignore)
    if not out:
        raise MeasurementError("the log holds no records", SourceLocation(path, 1, 1))
    return _in_time_order(out, path)


# s a record may lie before one written above it: an agent's buffers flushed out of turn, read in
# time order; further back the log's clock was set back, or two logs were joined
DISORDER = 1.0


def _in_time_order(out: list, path: str) -> list:
    """The events in time order, where records lie at most DISORDER s before one above them (said
    in ``reordered``); further back is an error at the first such record."""
    top, late, back, first = -math.inf, 0, 0.0, None
    for i, e in enumerate(out):
        if e.t < top - 1e-6:
            if top - e.t > DISORDER:
                j = next(j for j in range(i) if out[j].t == top)
                above = out[j]
                prev = max((x.t for x in out[:j] if x.line != above.line), default=-math.inf)
                on = out[i + 1].t if i + 1 < len(out) else -math.inf
                if prev <= e.t + DISORDER and on < top - DISORDER:
                    # (the records before it and the two after it agree: it is the one out of line)
                    raise MeasurementError(f"the record's timestamp is {top - e.t:.3f} s after the next record's "
                                           f"(line {e.line}) and {top - prev:.3f} s after the one before it: a clock "
                                           f"glitch, or a record written wrong", SourceLocation(path, above.line, 1))
                raise MeasurementError(f"the record's timestamp is {top - e.t:.3f} s before that of line {above.line} "
                                       f"above it: the log's records are out of order (its clock set back, or two "
                                       f"logs joined)", SourceLocation(path, e.line, 1))
            late, back, first = late + 1, max(back, top - e.t), first or e.line
        top = max(top, e.t)
    if not late:
        return out
    res = Events(sorted(out, key=lambda e: e.t))  # (stable: records of one moment keep their order)
    res.cut_last = getattr(out, "cut_last", "")
    res.reordered = (f"{late} record(s) lie up to {back:.3f} s before one written above them (the first at line "
                     f"{first}): read in time order")
    return res


_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")


class Events(list):
    """A log's events, with what reading them left out (``cut_last``: a last record cut short)."""

    cut_last: str = ""
    reordered: str = ""  # records read in time order, not the file's


def _record(ln: str, out: list, path: str, i: int, ignore: set) -> None:
    """The events of SHDR line ``i`` (``ln``, stripped), appended to ``out``."""
    if "|" not in ln:
        # a broken record: a value alone on the line after an item logged without one
        if out and out[-1].value == "" and out[-1].line == i - 1:
            out[-1].value = ln
            return
        raise MeasurementError(f"not an SHDR record (timestamp|item|value): {ln[:40]!r}", SourceLocation(path, i, 1))
    parts = ln.split("|")
    if not _TS.match(parts[0]):
        raise MeasurementError(f"not an SHDR timestamp: {parts[0][:40]!r}", SourceLocation(path, i, 1))
    t = _seconds(parts[0], path, i)
    pairs = parts[1:]
    if len(pairs) % 2:
        pairs.append("")
    col = len(parts[0]) + 2
    for k in range(0, len(pairs), 2):
        name = pairs[k].strip()
        key = name.lower()
        if key not in _ITEMS and key not in ignore and not _UNUSED.fullmatch(key):
            raise MeasurementError(f"unknown data item {name!r} (read: {', '.join(sorted(_NAMES))}, and items "
                                   f"known to be unused such as positions, loads and alarms): --ignore-item "
                                   f"{name} reads past it", SourceLocation(path, i, col))
        out.append(Event(t, _ITEMS.get(key, name), pairs[k + 1].strip(), i))
        col += len(pairs[k]) + len(pairs[k + 1]) + 2


def read_streams(path: str) -> list:
    """Events of an MTConnectStreams XML document (any namespace), by timestamp."""
    import xml.etree.ElementTree as ET

    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        # (the parser's own position, 1-based line and column; its message repeats it)
        line, col = getattr(exc, "position", (1, 0))
        why = str(exc).split(":", 1)[0]
        raise MeasurementError(f"cannot read the MTConnect XML: {why}", SourceLocation(path, max(line, 1),
                                                                                      col + 1)) from None
    except OSError as exc:
        raise MeasurementError(f"cannot read the MTConnect XML: {exc.strerror or exc}", SourceLocation(path, 1, 1)) \
            from None
    out = []
    for el in root.iter():
        ts = el.attrib.get("timestamp")
        if ts is None:
            continue
        tag = el.tag.split("}", 1)[-1]
        name = el.attrib.get("name") or el.attrib.get("dataItemId") or tag
        kind = _ITEMS.get(name.lower()) or _ITEMS.get(tag.lower()) or name
        sub = el.attrib.get("subType", "").upper()
        if tag == "PathFeedrateOverride":
            # the standard's one type for three overrides, told apart by subType
            kind = {"RAPID": "rapid_ovr", "JOG": "jog_ovr"}.get(sub, "feed_ovr")
        elif tag == "RotaryVelocityOverride" or (tag == "RotaryVelocity" and "override" in name.lower()):
            kind = "spindle_ovr"
        elif tag == "PathFeedrate" and sub not in ("", "ACTUAL"):
            kind = "feed_" + sub.lower()  # the commanded or programmed feed: not the actual one
        elif tag == "Block" and _ITEMS.get(name.lower()) != "block":
            kind = "block_text"  # the standard's Block is the block's text (unless named as a number)
        elif tag in ("LineNumber", "Line") and sub == "INCREMENTAL":
            kind = "line_incremental"  # lines counted from the program's start of execution: not a line
        out.append(Event(_seconds(ts, path, 0), kind, (el.text or "").strip(), 0))
    if not out:
        raise MeasurementError("no timestamped data items in the MTConnect XML", SourceLocation(path, 0, 0))
    out.sort(key=lambda e: e.t)
    return out


def runs(events: list, outline: Outline | None = None, label: str | None = None) -> list:
    """The program runs in a log: ACTIVE to the next end state.  A feed hold (FEED_HOLD) or a
    program stop (STOPPED, OPTIONAL_STOP, PROGRAM_STOPPED, INTERRUPTED) followed by ACTIVE is an
    interval of the run; a stop or a feed hold followed by READY ends it, incomplete (aborted).  ``outline``:
    the program the log is read against — a run is complete only where it ran the program from
    its start to its end, and a jump back it does not make itself is a restart.  ``label``: what
    the block numbers are, for a person ("line", "N"; the outline's by default)."""
    label = label or (outline.label if outline is not None else "line")
    out = []
    name = ""
    start = None
    paused = None  # (t0, state) of a hold or stop in progress
    holds: list = []
    stops: list = []
    gap = None  # t the control's data went UNAVAILABLE (an adapter's reconnect), in a run
    gaps: list = []
    for k, e in enumerate(events):
        if e.item == "program" and e.value:
            if start is not None and paused is not None and name and e.value != name:
                # another program loaded while this one stood stopped: this run was abandoned
                out.append(Run(name, start, k, False, holds, stops))
                start, holds, stops, paused = None, [], [], None
            name = e.value
        if e.item != "status":
            continue
        v = e.value.upper()
        if v == "UNAVAILABLE":
            gap = e.t if start is not None and gap is None else gap
            continue
        if gap is not None and start is not None and v == "ACTIVE":
            # the adapter came back with the state it had: the run went on (no data between)
            gaps.append((gap - events[start].t, e.t - events[start].t))
            gap = None
            continue
        gap = None
        if v == "ACTIVE":
            if paused is not None and start is not None:
                t0, state = paused
                span = (t0 - events[start].t, e.t - events[start].t)
                (holds.append(span) if state == "FEED_HOLD" else stops.append((*span, state)))
                paused = None
                continue
            if start is not None:  # ACTIVE again without an end: the earlier run was cut
                out.append(_cut_run(events, name, start, k, holds, stops, label))
                out[-1].gaps = gaps
            start, holds, stops, gaps = k, [], [], []
        elif start is not None and (v == "FEED_HOLD" or v in _STOP):
            # (the pause began at the first of them; a stop after a feed hold makes it a stop)
            paused = (e.t, v) if paused is None else (paused[0], v if v in _STOP else paused[1])
        elif start is not None and v in _END:
            # (a reset from a stop, or from a feed hold, aborts the run: a program does not end while
            # it is held; PROGRAM_COMPLETED after a hold is an end whose resume the log missed)
            aborted = paused is not None and (paused[1] != "FEED_HOLD" or v == "READY")
            ended = ""
            if aborted:
                last = _blocks(events, start, k)
                ended = (f"{paused[1]} at {_word(label, last[-1][1]) if last else 'an unlogged line'} at "
                         f"{paused[0] - events[start].t:.0f} s, then reset to {v}")
            out.append(Run(name, start, k + 1, not aborted, holds, stops, end_state=v, ended=ended, gaps=gaps))
            start, holds, stops, paused, gaps = None, [], [], None, []
    if start is not None:
        out.append(Run(name, start, len(events), False, holds, stops, gaps=gaps))
    # the name running at the start of each run (names may switch before it); else the one
    # carried from before it — or the name loaded for editing since, where that one is the
    # program read against and the carried one is not (a control that logs only the loaded
    # name for a second program)
    for r in out:
        r.program, r.other_name = _run_name(events, r, outline)
    out = _joined(events, out, outline)
    # (the outline is the program's: a run of another program in the same log is read on its own
    # terms — where the log names the program at all: a renamed file, --any-program, names none)
    ours = outline is not None and any(outline.names(r.program) or outline.names(r.other_name) for r in out)
    split = []
    prev_end = 0
    for r in out:
        mine = outline if outline is not None and (not ours or not r.program or outline.names(r.program)
                                                   or outline.names(r.other_name)) else None
        for x in _restarts(events, r, mine, label):
            _against(events, x, mine, _lead(events, prev_end, x.start))
            x.label = label
            split.append(x)
            prev_end = x.end
    return split


def _joined(events: list, out: list, outline: Outline | None) -> list:
    """``out`` with each run reset and started again in the middle made one with the run that
    goes on from there (a control's program restart: the operator resets, searches the block
    to go on from — at or before where the run stopped — and starts the cycle there).  The part
    was cut by the two: the one run is read as a restart in the middle (:func:`_restarts`: the
    first pass through the repeated lines and the time between are taken out); kept apart, neither
    would be a whole cycle."""
    if outline is None or not outline.start_line:
        return out  # (without the program, a reset is not told from a finish: READY ends both)
    res: list = []
    for r in out:
        a = res[-1] if res else None
        done = [(k, b) for k, b in _blocks(events, a.start, a.end) if b > 0] if a is not None else []
        if a is None or not done or not _goes_on(events, a, r, done[-1][1], outline):
            res.append(r)
            continue
        t0 = events[a.start].t
        dt = events[r.start].t - t0
        # (the reset began at the first block number logged after the last line run: a 0, the
        # program rewound)
        stop = min((events[k].t for k, b in _blocks(events, done[-1][0] + 1, a.end)), default=events[a.end - 1].t)
        res[-1] = Run(a.program or r.program, a.start, r.end, r.complete,
                      a.holds + [(h0 + dt, h1 + dt) for h0, h1 in r.holds],
                      a.stops + [(stop - t0, dt, "RESET")]
                      + [(x0 + dt, x1 + dt, st) for x0, x1, st in r.stops],
                      ended=r.ended, end_state=r.end_state, gaps=a.gaps + [(g0 + dt, g1 + dt) for g0, g1 in r.gaps],
                      other_name=a.other_name or r.other_name)
    return res


def _goes_on(events: list, a: Run, r: Run, was: int, outline: Outline) -> bool:
    """Whether run ``r`` goes on from where run ``a`` stopped, at line ``was``: a program
    restart.  Not where ``a`` finished — its end state logged, or it reached the program's last
    moves (a run stopped among the lines a log may miss at the end and then gone on from the
    middle was reset, not finished: what it cut is timed whole either way); nor where ``r`` runs
    another program, or the log went blind between them (what ran then is not known); nor where
    ``r`` starts past where ``a`` stopped (lines never cut), at the program's start (a new run),
    or from there in the program's own order (a subprogram's return)."""
    if a.end_state == "PROGRAM_COMPLETED" or outline.finished(was):
        return False
    if a.program and r.program and not same_program(a.program, r.program):
        return False
    if any(e.item == "status" and e.value.upper() == "UNAVAILABLE" for e in events[a.end:r.start]):
        return False
    first = next((b for _, b in _blocks(events, r.start, r.end) if b > 0), 0) or _lead(events, a.end, r.start)
    return bool(first) and outline.start_line < first <= was and not outline.goes_back(was, first)


def _blocks(events: list, k0: int, k1: int) -> list:
    """(event index, block number) of the block numbers logged in events[k0:k1]."""
    return [(k, b) for k in range(k0, k1) if events[k].item == "block" and (b := _block(events[k])) is not None]


# s before a run's ACTIVE the control may report the run's first line; one logged earlier is
# what it showed while it stood (the program rewound at a reset, before a search to another block)
LEAD_S = 2.0


def _lead(events: list, k0: int, k1: int) -> int:
    """The block number logged last in events[k0:k1] within LEAD_S of events[k1] (a run's first
    line, which the control may report just before its ACTIVE), 0 where none."""
    b = _blocks(events, k0, k1)
    return b[-1][1] if b and (k1 >= len(events) or events[k1].t - events[b[-1][0]].t <= LEAD_S) else 0


def _run_name(events: list, r: Run, outline: Outline | None) -> tuple[str, str]:
    """(the run's program name, the other name it may have had).  The name running at its start;
    where it logs none, the one carried from before it — or, where another was loaded for editing
    since, that one if it is the program read against and the carried one is not.  The names
    alone cannot tell a second program logged only as loaded from the same program run again
    with another open in the editor: the other is kept, and such a run is not taken by default
    where a run of certain name is there."""
    running = next((e.value for e in events[r.start:min(r.start + 20, r.end)] if e.item == "program" and e.value), "")
    if running:
        return running, ""
    carried, edited = r.program, ""
    for e in events[:r.start]:
        if e.item == "program" and e.value:
            carried, edited = e.value, ""
        elif e.item == "program_editing" and e.value:
            edited = e.value
    if not carried or not edited or same_program(carried, edited):
        return carried or edited, ""
    if outline is not None and outline.names(edited) and not outline.names(carried):
        return edited, carried
    return carried, edited


def _back_over_names(events: list, end: int, floor: int) -> int:
    """``end`` moved back over the program names logged just before it (the program loaded
    again: the next run's), not below ``floor``."""
    while end > floor and events[end - 1].item in ("program", "program_editing"):
        end -= 1
    return end


def _cut_run(events: list, name: str, start: int, k: int, holds: list, stops: list, label: str = "line") -> Run:
    """The run from ``start`` that the control started again at ``k`` (ACTIVE) with no end state
    logged between.  What the log reported for the new run before its ACTIVE — the block number
    back at the program's start, the program loaded — belongs to the new run, not to how far the
    cut one got."""
    blocks = _blocks(events, start, k)
    nxt = next((b for _, b in _blocks(events, k, min(k + 200, len(events)))), None)
    end = k
    if blocks and nxt is not None:
        low = max(nxt, blocks[0][1]) + RESTART_SLACK
        tail = len(blocks)
        while tail > 0 and blocks[tail - 1][1] <= low:
            tail -= 1
        if 0 < tail < len(blocks):  # it went back to the start before the new ACTIVE
            end = _back_over_names(events, blocks[tail][0], blocks[tail - 1][0] + 1)
    t0 = events[start].t
    last = [b for j, b in blocks if j < end]
    if end < k:
        ended = (f"stopped at {_word(label, last[-1])} at {events[end - 1].t - t0:.0f} s and started again from the "
                 f"program's start {events[k].t - events[end - 1].t:.0f} s later; no stop or end state logged")
    else:
        ended = f"cut at {events[k - 1].t - t0:.0f} s: the control started a run again with no end state logged"
    return Run(name, start, end, False, holds, stops, reached=last[-1] if last else -1, ended=ended)


# a run that resumes after a stop at a block number within this many of its first one — or
# within this share of where it stopped — started again from the program's start
RESTART_SLACK = 2
RESTART_SHARE = 0.02
# s between the last report before a jump back to the start and the first after it, with no
# state logged and no program to tell a subprogram's return from a restart: the machine stood
RESTART_GAP = 10.0


def _block(e: Event) -> int | None:
    try:
        v = float(e.value)
    except ValueError:
        return None
    return int(v) if math.isfinite(v) and v >= 0 and v == int(v) else None


def _restarts(events: list, r: Run, outline: Outline | None = None, label: str = "line") -> list:
    """A run as the control ran it.  Where execution resumes — after a logged program stop, or
    where the block number goes back with no state logged — with the block number back near the
    run's first block, a new run began from the start (the one before was aborted: a restart,
    often with the runtime counter reset; or, where it had reached the program's end, a pass
    of a program that runs again, M99); where it resumes further back than where it was, but
    not at the start, it repeated lines — a restart in the middle: the first pass through the
    repeated lines is set to be skipped (``skip``) and taken out of the timing with the stop
    (state RESTART), so no time is counted twice.  A jump back that the program itself makes (a
    loop, a subprogram's return: ``outline``) is neither; without an outline only a jump back to
    the start after the machine stood is taken for a restart."""
    blocks = _blocks(events, r.start, r.end)
    if blocks and r.reached < 0:
        r.reached = blocks[-1][1]
    if len(blocks) < 2:
        return [r]
    t_start = events[r.start].t
    first = next((b for _, b in blocks if b > 0), blocks[0][1])

    def at_start(now: int, was: int) -> bool:
        return now <= first + RESTART_SLACK or now <= RESTART_SHARE * was

    # where execution resumed: (t before, t after, the event it resumed at or None, the state
    # logged: None where none was, and then the block events either side of the jump)
    resumed = []
    for t0, t1, state in r.stops:
        k_res = next((k for k in range(r.start, r.end) if events[k].item == "status" and events[k].t >= t_start + t1 - 1e-9
                      and events[k].value.upper() == "ACTIVE"), None)
        resumed.append((t_start + t0, t_start + t1, k_res, state, None))
    spans = [(t_start + a, t_start + b) for a, b, _ in r.stops] + [(t_start + a, t_start + b) for a, b in r.holds]
    for (k0, was), (k1, now) in zip(blocks, blocks[1:]):
        if now >= was - RESTART_SLACK:
            continue
        t0, t1 = events[k0].t, events[k1].t
        if any(a <= t1 and b >= t0 for a, b in spans):
            continue  # (a logged stop: taken above)
        if outline is not None and outline.goes_back(was, now) or outline is None and not (
                at_start(now, was) and t1 - t0 >= RESTART_GAP):
            continue  # the program's own jump (or, with no program to tell, perhaps one: a subprogram's return)
        if now == 0:  # (block 0: the program reset; the new run starts at its first line)
            k1 = next((k for k, v in blocks if k > k1 and v > 0), k1)
        k_res = k1
        while k_res > k0 + 1 and events[k_res - 1].t == events[k_res].t:
            k_res -= 1
        resumed.append((t0, t1, k_res, None, (k0, k1)))
    resumed.sort(key=lambda x: x[0])
    for ta, tb, k_res, state, pair in resumed:
        logged = state is not None
        if pair is None:  # (a 0: the program rewound)
            before = [x for x in blocks if events[x[0]].t <= ta and x[1] > 0]
            after = [x for x in blocks if events[x[0]].t >= tb]
        else:  # (by the events themselves: the lines either side of a jump may share a timestamp)
            before = [x for x in blocks if x[0] <= pair[0] and x[1] > 0]
            after = [x for x in blocks if x[0] >= pair[1]]
        if not before or not after:
            continue
        was, now = before[-1][1], after[0][1]
        if now > was or now == was and state != "RESET":
            continue  # it went on where it stopped (an M00/M01 wait; after a reset, it ran the line again)
        if k_res is None:
            k_res = after[0][0]
        stop_at, go_at = ta - t_start, tb - t_start  # s since the run's start
        if at_start(now, was):
            # the run before ends where the block number went back (what the control logged
            # for the new run before its ACTIVE — line 0, its first line — is the new run's)
            end = next((k for k, v in blocks if ta <= events[k].t and k <= k_res and v < was - RESTART_SLACK), k_res)
            end = _back_over_names(events, end, before[-1][0] + 1)
            # (a pass that ran to the program's last move and went on from its start with no stop:
            # an M99 program running again)
            finished = outline is not None and not logged and outline.finished(was)
            how = "" if logged else "; no stop or end state logged"
            ended = "" if finished else (f"stopped at {_word(label, was)} at {stop_at:.0f} s and started again from the "
                                         f"program's start {go_at - stop_at:.0f} s later{how}")
            done = Run(r.program, r.start, end, finished, [h for h in r.holds if h[1] <= stop_at],
                       [x for x in r.stops if x[1] <= stop_at], reached=was, ended=ended,
                       skip=[x for x in r.skip if x[1] <= end], restarts=[x for x in r.restarts if x[0] <= stop_at],
                       until=events[k_res].t if finished else 0.0)  # (a pass lasts until the next begins)
            dt = events[k_res].t - t_start
            rest = Run(r.program, k_res, r.end, r.complete, [(h0 - dt, h1 - dt) for h0, h1 in r.holds if h0 >= go_at],
                       [(x0 - dt, x1 - dt, st) for x0, x1, st in r.stops if x0 >= go_at], ended=r.ended,
                       end_state=r.end_state)
            return [done] + _restarts(events, rest, outline, label)
        # in the middle: the repeated pass began where the run last entered the line it resumed
        # at (in a loop, or after an earlier call of a subprogram, not where it first did)
        i = len(before) - 1
        while i > 0 and before[i - 1][1] >= now:
            i -= 1
        k_first = before[i][0] if before[i][1] >= now else None
        if k_first is None:
            continue
        while k_first > r.start and events[k_first - 1].t == events[k_first].t:
            k_first -= 1  # (what was logged at the same moment belongs to the repeated pass)
        t_first = events[k_first].t - t_start
        r.skip.append((k_first, k_res))
        r.stops = [x for x in r.stops if not (x[0] >= t_first and x[1] <= go_at)] + [(t_first, go_at, "RESTART")]
        r.stops.sort()
        r.holds = [h for h in r.holds if not (h[0] >= t_first and h[1] <= go_at)]
        r.restarts.append((stop_at, was, now))
    return [r]


def _against(events: list, r: Run, outline: Outline | None, lead: int = 0) -> None:
    """Whether ``r`` is the program's whole cycle, told from the lines it reported (``lead``:
    the line logged just before its ACTIVE): a run that started past the program's first moves
    (``late``) or ended before its last ones — reset to READY, which a log also writes at a
    program's end — is not complete.  (A PROGRAM_COMPLETED is the control's word.)"""
    if outline is None or not outline.start_line:
        return
    skipped = set()
    for k0, k1 in r.skip:
        skipped.update(range(k0, k1))
    blocks = ([lead] if lead > 0 else []) + [b for k, b in _blocks(events, r.start, r.end) if k not in skipped and b > 0]
    if not blocks:
        return
    if blocks[0] > outline.start_line:
        r.late = blocks[0]
        if r.complete:
            r.complete = False
            r.ended = (f"started at {_word(outline.label, blocks[0])}, past the program's first moves, which run "
                       f"to {_word(outline.label, outline.start_line)}: restarted in the middle, or logged from there")
    if r.complete and r.end_state != "PROGRAM_COMPLETED" and not any(outline.at_end(b) for b in blocks):
        r.complete = False
        r.ended = (f"ended at {_word(outline.label, r.reached)} with {r.end_state or 'its end state'}, before the "
                   f"program's last moves from {_word(outline.label, outline.end_line)}: reset, not finished")
    elif r.complete and outline.loops and not r.until and r.end_state != "PROGRAM_COMPLETED":
        # (a pass that ran on into the next one ended there; the last one was reset at a moment
        # the log does not place: within its last move, or after it)
        r.complete = False
        r.ended = (f"reset to {r.end_state or 'its end state'} at {_word(outline.label, r.reached)}: the program runs "
                   f"again by M99 until reset, so where its last pass stopped is not logged — a pass that ran on into the "
                   f"next is complete")


def _word(label: str, block) -> str:
    """A block number for a person: "line 12", or "N120" where the log's block numbers are N words."""
    return f"line {block}" if label == "line" else f"N{block}"


def n_to_lines(program_data: bytes) -> dict:
    """N number -> the lines that carry it, in file order."""
    table: dict = {}
    for i, raw in enumerate(program_data.split(b"\n"), 1):
        m = re.match(rb"\s*/?\s*[Nn](\d+)", raw)
        if m:
            table.setdefault(int(m.group(1)), []).append(i)
    return table


def to_measurement(path: str, events: list, run: int | None = None, block_is: str = "line",
                   program_data: bytes | None = None, outline: Outline | None = None) -> Measurement:
    """The chosen run of a log as a measurement (a sample at every logged change); ``outline``:
    the program it is read against (:func:`runs`; in N words where the block numbers are)."""
    if outline is not None and block_is == "n":
        outline = outline.in_n_words(program_data) if program_data is not None else None
    all_runs = runs(events, outline, "N" if block_is == "n" else "line")
    if not all_runs:
        raise MeasurementError("no program run in the log (no Program_Status / Execution ACTIVE)",
                               SourceLocation(path, events[0].line, 1))
    if run is None:
        # the last complete run (of the program read against, where the log names it): an
        # aborted run before it, restarted from the start, is the operator's false start, the
        # complete one the part
        complete = [r for r in all_runs if r.complete]
        if outline is not None and any(outline.names(r.program) for r in complete):
            complete = [r for r in complete if outline.names(r.program)]
            complete = [r for r in complete if not r.other_name] or complete
        chosen = complete[-1] if complete else all_runs[0]
    else:
        if not 1 <= run <= len(all_runs):
            raise MeasurementError(f"--run {run}: the log has {len(all_runs)} run(s)", SourceLocation(path, 0, 0))
        chosen = all_runs[run - 1]
    ev = events[chosen.start:chosen.end]
    t0 = ev[0].t
    n_map = n_to_lines(program_data) if block_is == "n" and program_data is not None else None
    if block_is == "n" and n_map is None:
        raise MeasurementError("--block-is n needs the program (to map N words to lines)", SourceLocation(path, 0, 0))
    state = {"line": -1.0, "feed": np.nan, "spindle_speed": np.nan, "tool": np.nan,
             **{col: np.nan for col in OVERRIDES.values()}}
    rows_t: list = []
    rows: list = []
    # the state before the run: the last value of each item logged before ACTIVE — the block
    # number only from what was logged after the run before it ended (a new run reports its
    # line anew; the line an aborted run stopped at is not where this one starts)
    prev_end = max((r.end for r in all_runs if r.end <= chosen.start), default=0)
    for k, e in enumerate(events[:chosen.start]):
        if e.item != "block" or k >= prev_end:
            _apply(state, e, path, None, [0])
    pos = [0]  # the line an N word was last mapped to
    src: list = []  # the log line of each sample
    if any(np.isfinite(state[col]) for col in OVERRIDES.values()):
        # an override set before the cycle start (a prove-out begun at 0 %) is in force from
        # the run's first moment, not from the first change logged in it; the line it reports
        # comes with its own report
        rows_t.append(0.0)
        rows.append({**state, "line": -1.0})
        src.append(ev[0].line)
    skipped = np.zeros(len(ev), bool)
    for k0, k1 in chosen.skip:  # (a restart's repeated first pass: its state, not its samples)
        skipped[max(k0 - chosen.start, 0):max(k1 - chosen.start, 0)] = True
    for e, skip in zip(ev, skipped):
        if not _apply(state, e, path, n_map, pos) or skip:
            continue
        if rows_t and rows_t[-1] == e.t - t0:
            rows[-1] = dict(state)
            src[-1] = e.line if e.item == "block" else src[-1]
        else:
            rows_t.append(e.t - t0)
            rows.append(dict(state))
            src.append(e.line)
    if not rows:
        raise MeasurementError("the run holds no samples: the control went ACTIVE and ended before it logged a line, "
                               "a feed or a speed", SourceLocation(path, ev[0].line, 1))
    t = np.array(rows_t)
    signals = {"feed": np.array([r["feed"] for r in rows]), "spindle_speed": np.array([r["spindle_speed"] for r in rows])}
    extra = {k: np.array([r[k] for r in rows]) for k in ("tool", *OVERRIDES.values())
             if not np.all(np.isnan([r[k] for r in rows]))}
    line = np.array([int(r["line"]) for r in rows], np.int64)
    end_t = max(ev[-1].t, chosen.until) - t0
    meta = {"source": f"MTConnect log {path}", "program": chosen.program, "run": str(all_runs.index(chosen) + 1),
            "runs": str(len(all_runs)), "complete": "yes" if chosen.complete else "no",
            "end_time_s": f"{end_t:.4f}", "cycle_time_s": "",
            "block_is": block_is}
    if chosen.late:
        meta["started_at"] = str(chosen.late)
    if not chosen.complete and chosen.ended:
        meta["ended"] = chosen.ended  # (why it is incomplete: a measurement file of it says so too)
    if chosen.gaps:
        meta["data_gaps_s"] = "; ".join(f"{a:.3f}-{b:.3f}" for a, b in chosen.gaps)
    missing = [col.split("_")[0] for col in OVERRIDES.values() if col not in extra]
    if missing:
        meta["overrides"] = f"{', '.join(missing)} not logged: 100 % assumed"
    if chosen.restarts:
        meta["restarts"] = "; ".join(f"stopped at {t:.3f} s at {_word(chosen.label, a)}, started again from "
                                     f"{_word(chosen.label, b)}" for t, a, b in chosen.restarts)
    others = [f"run {k}: {r.describe()}" for k, r in enumerate(all_runs, 1) if r is not chosen and not r.complete]
    if others:
        meta["other_runs"] = "; ".join(others)
    if getattr(events, "cut_last", ""):
        meta["cut_last"] = events.cut_last
    if getattr(events, "reordered", ""):
        meta["reordered"] = events.reordered
    if chosen.holds:
        meta["feed_holds_s"] = "; ".join(f"{a:.3f}-{b:.3f}" for a, b in chosen.holds)
    if chosen.stops:
        meta["program_stops_s"] = "; ".join(f"{a:.3f}-{b:.3f} {st}" for a, b, st in chosen.stops)
    m = Measurement(path, t, signals, line, meta, [], extra=extra, end_time=end_t, holds=list(chosen.holds),
                    stops=list(chosen.stops), complete=chosen.complete, runs=all_runs,
                    source_line=np.array(src, np.int64))
    # the cycle: the span less the time the machine stood — feed holds, logged program stops (a
    # restart's repeated first pass among them), a feed override at 0 % with the machine still
    stood = covered([*chosen.holds, *chosen.stops, *held_spans(m)], 0.0, end_t)
    meta["cycle_time_s"] = f"{max(end_t - stood, 0.0):.4f}"  # (never "-0.0000")
    return m


def _apply(state: dict, e: Event, path: str, n_map, pos) -> bool:
    """Update the state with one event; True when it changed a column."""
    v = e.value
    if e.item == "block":
        if v in ("", "UNAVAILABLE"):
            return False
        try:
            fb = float(v)
        except ValueError:
            raise MeasurementError(f"Block_Number {v!r} is not a number", SourceLocation(path, e.line, 1)) from None
        if not (math.isfinite(fb) and fb == int(fb) and 0 <= fb < 1e9):
            raise MeasurementError(f"Block_Number {v!r} is not a block number (a whole number from 0 to 1e9)",
                                   SourceLocation(path, e.line, 1))
        b = int(fb)
        if n_map is not None:
            lines = n_map.get(b)
            if not lines:
                return False  # an N the program does not have (a subprogram's): not a line
            nxt = [x for x in lines if x >= pos[0]]
            b = nxt[0] if nxt else lines[0]
            pos[0] = b
        state["line"] = float(b)
        return True
    key = {"feed": "feed", "spindle": "spindle_speed", "tool": "tool", **OVERRIDES}.get(e.item)
    if key is None:
        return False
    if v in ("", "UNAVAILABLE"):
        state[key] = np.nan
        return True
    try:
        x = float(v)
    except ValueError:
        raise MeasurementError(f"{e.item} value {v!r} is not a number", SourceLocation(path, e.line, 1)) from None
    # a feed, speed, tool number or override a control reports is finite, >= 0 and below
    # these (1,000 m/min in mm/s; 1e6 rpm; 1e6 for a tool number; an override 1,000 %, the most
    # the twin's controller.feed_override takes)
    top = {"feed": 1e6 / 60.0}.get(key, max_override() if key in OVERRIDES.values() else 1e6)
    if not (math.isfinite(x) and 0 <= x <= top):
        raise MeasurementError(f"{e.item} value {v!r} is not a value a control reports (finite, >= 0, within "
                               f"any machine's range)", SourceLocation(path, e.line, 1))
    state[key] = x * 60.0 if key == "feed" else x  # MTConnect path feed: mm/s
    return True


def read_mtconnect(path: str, run: int | None = None, block_is: str = "line", program_data: bytes | None = None,
                   ignore_items=(), outline: Outline | None = None):
    """Read an SHDR log or an MTConnectStreams XML into a measurement (``outline``: the program
    it is read against, :func:`runs`)."""
    if block_is not in ("line", "n"):
        raise MeasurementError(f"--block-is must be line or n, got {block_is!r}", SourceLocation(path, 0, 0))
    try:
        from ..io import check_input

        check_input(path, "log")
        with open(path, "rb") as fh:
            head = fh.read(4096)
    except OSError as exc:
        raise MeasurementError(f"cannot read {path}: {exc.strerror or exc}", SourceLocation(path, 0, 0)) from None
    events = read_streams(path) if b"<MTConnectStreams" in head else read_shdr(path, ignore_items)
    return to_measurement(path, events, run, block_is, program_data, outline)
