"""The interpreter: lexed words -> motion records (numpy structured array).

:func:`load_program` is the public entry point.  The modal state machine itself
is the numba kernel in ``_interpkernel.py``; this module validates settings,
builds the small lookup tables the kernel needs, and turns its error codes into
``file:line:col: message``.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from ..errors import GCodeError, SourceLocation
from . import _interpkernel as K
from .lexer import ControlByteError, Lexed, lex
from .macro import M99_MAIN_NOTE
from .records import FL_SUB, MOVE_DTYPE

DIALECTS = ("auto", "fanuc", "linuxcnc")
_WCS_NAMES = ("G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3")


@dataclass
class InterpreterSettings:
    """What the interpreter needs to know about the machine and the shop.

    Parameters
    ----------
    dialect : "auto" | "fanuc" | "linuxcnc"
        Only dwell words differ: Fanuc ``G4 P1000`` is milliseconds (a P without
        a decimal point), LinuxCNC ``G4 P1`` is seconds.  ``auto`` picks
        ``linuxcnc`` for ``.ngc`` files and ``fanuc`` otherwise.
    lenient : bool
        Unsupported G/M codes that cannot change the path become warnings.
    skip_block_delete : bool
        The block-delete switch: when on, lines starting with ``/`` are skipped.
    work_offsets : dict
        ``{"G54": (x, y, z), ...}`` in mm; missing ones are zero.
    tool_lengths : dict or None
        ``{tool_number: length_mm}``.  None means no tool table: every length is 0
        and G43 is accepted; with a table, G43 on a missing tool is an error.
    home_g28, home_g30 : tuple
        Machine coordinates (mm) of the G28 and G30 positions.
    """

    dialect: str = "auto"
    lenient: bool = False
    skip_block_delete: bool = False
    work_offsets: dict = field(default_factory=dict)
    tool_lengths: dict | None = None
    home_g28: tuple = (0.0, 0.0, 0.0)
    home_g30: tuple = (0.0, 0.0, 0.0)
    comp_radii: dict = field(default_factory=dict)
    subroutine_path: tuple = ()  # directories searched for o<name> subroutine files


@dataclass
class GCodeWarning:
    location: SourceLocation
    message: str

    def __str__(self) -> str:
        return f"{self.location}: warning: {self.message}"


@dataclass
class Program:
    """A lexed and interpreted program.  ``records`` is a MOVE_DTYPE array."""

    lexed: Lexed
    records: np.ndarray
    settings: InterpreterSettings
    dialect: str
    warnings: list
    source: bytes | None = None  # the file as written, when it was a macro program
    expanded: object = None  # gcode.macro.Expanded: the straight-line program that was run
    unknown_calls: tuple = ()  # lines calling a program not at hand (--lenient): not simulable
    end_tool_change: int = 0  # line of a tool change after the last move (0: none)
    # the tools come from T words alone (no M6 in the program: a router's post): nothing is
    # changed by the machine, so no tool-change time is spent
    tools_by_selection: bool = False
    # per record, the fraction of the machine's rapid speed its rapids run at (a logged rapid
    # override the twin replays, mtwin.loop.asrun); None: 100 %
    rapid_scale: np.ndarray | None = None
    # per record, the factor on the spindle speed (a logged spindle override); None: 1
    spindle_scale: np.ndarray | None = None
    # the records are the rest of a run already under way (a log that starts in the middle of the
    # program, mtwin.loop.asrun): the first record's tool is in the spindle, at its speed
    running: bool = False
    # the main program ends in M99: a Fanuc control runs it again from its start until reset (the
    # records are one pass)
    loops: bool = False

    @property
    def path(self) -> str:
        return self.lexed.path

    @property
    def data(self) -> bytes:
        return self.source if self.source is not None else self.lexed.data

    @property
    def is_macro(self) -> bool:
        return self.expanded is not None

    @property
    def inch(self) -> bool:
        """Whether the program is written in inches (G20 on most of its moves)."""
        from .records import FL_INCH

        rec = self.records
        return bool(len(rec)) and bool(((rec["flags"] & FL_INCH) != 0).mean() > 0.5)

    @property
    def text_lines(self) -> list[str]:
        """The program's lines as text (Latin-1: every byte stands for itself)."""
        return self.data.decode("latin-1").split("\n")

    def turning_line(self) -> int:
        """The first line that makes this a turning (lathe) program — a G70-G72 profile cycle,
        G96 constant surface speed or G7 diameter mode — or 0."""
        from .records import FL_DIAMETER

        lines = list(getattr(self.expanded, "turning", None) or [])
        rec = self.records
        mark = ((rec["flags"] & FL_DIAMETER) != 0) | (rec["css"] > 0)
        if mark.any():
            lines.append(int(rec["line"][int(np.argmax(mark))]))
        return min(lines) if lines else 0


def read_source(path: str | os.PathLike) -> bytes:
    """Read a program file, or standard input for ``-``."""
    from ..io import read_input

    try:
        return read_input(path, "program")  # (a regular file or stdin, within the size limit)
    except OSError as exc:
        raise GCodeError(f"cannot read {path}: {exc.strerror or exc}") from None


def load_program(source, settings: InterpreterSettings | None = None, *, path: str | None = None) -> Program:
    """Lex and interpret a program.

    Parameters
    ----------
    source : str | os.PathLike | bytes
        A file path (``-`` for stdin) or the program text itself as bytes.
    settings : InterpreterSettings, optional
    path : str, optional
        Name used in messages when ``source`` is bytes.
    """
    settings = settings or InterpreterSettings()
    if isinstance(source, (bytes, bytearray)):
        data = bytes(source)
        name = path or "<string>"
    else:
        name = str(source) if path is None else path
        data = read_source(source)
        if name == "-":
            name = "<stdin>"
    from dataclasses import replace as dc_replace

    from .macro import looks_like_macro

    clean, where = _blank_control_bytes(data) if settings.lenient else (data, -1)
    # The numba lexer stops at every macro construct ('#', '[', keywords, O-word control
    # flow); a plain program lexes through, and only a G65 call can hide in it.  So the
    # slower whole-file macro scan runs only when the lexer says there may be one.
    try:
        lexed = lex(clean, name)
        maybe_macro = bool(np.any((lexed.w_letter == ord("G")) & (lexed.w_value == 65.0)))
    except ControlByteError:
        raise
    except GCodeError:
        lexed = None
        maybe_macro = True
    if maybe_macro and looks_like_macro(clean):
        prog = _load_macro(clean, name, settings)
    else:
        try:
            prog = interpret(lexed if lexed is not None else lex(clean, name), settings)
        except GCodeError as exc:
            if "not found in this file" not in exc.message:
                raise
            # an M98 of a program kept in a file of its own (or, with --lenient, passed over):
            # the macro executor knows where to look
            prog = _load_macro(clean, name, settings)
    if where >= 0:
        # control characters (tape leaders, a stray SOH) read as blanks; the file keeps them
        line = data.count(b"\n", 0, where) + 1
        col = where - (data.rfind(b"\n", 0, where) + 1) + 1
        w = GCodeWarning(SourceLocation(name, line, col),
                         f"control byte 0x{data[where]:02x} read as a blank (--lenient)")
        prog = dc_replace(prog, source=data, warnings=[w] + prog.warnings)
    return prog


_CONTROL = bytes(range(0, 9)) + b"\x0b\x0c" + bytes(range(14, 32)) + b"\x7f"


def _blank_control_bytes(data: bytes) -> tuple[bytes, int]:
    """``data`` with ASCII control bytes (other than tab, CR, LF) replaced by spaces, and the
    offset of the first one (-1 when there is none)."""
    table = bytes.maketrans(_CONTROL, b" " * len(_CONTROL))
    clean = data.translate(table)
    if clean == data:
        return data, -1
    return clean, next(i for i, (a, b) in enumerate(zip(data, clean)) if a != b)


def _load_macro(data: bytes, name: str, settings: InterpreterSettings) -> Program:
    """Run a macro program into plain blocks, interpret those, and point every record and
    message back at the source line it came from."""
    from dataclasses import replace as dc_replace

    from .macro import expand

    dialect = _resolve_dialect(settings, name)
    offsets = [tuple(v) for v in _offsets_array(settings)]
    ex = expand(data, name, dialect, settings.skip_block_delete, offsets, settings.subroutine_path,
                lenient=settings.lenient)
    lexed = lex(ex.data, name)
    try:
        prog = interpret(lexed, dc_replace(settings, dialect=dialect))
    except GCodeError as exc:
        loc = exc.location
        if loc is not None and 1 <= loc.line <= len(ex.line_map):
            raise GCodeError(f"{exc.message} (in the macro-expanded block {ex.data.splitlines()[loc.line - 1].decode()!r})",
                             SourceLocation(loc.path, int(ex.line_map[loc.line - 1]), 1)) from None
        raise
    rec = prog.records
    idx = rec["line"].astype(np.int64) - 1
    rec["line"] = ex.line_map[idx]
    rec["flags"] = np.where(ex.in_sub[idx], rec["flags"] | FL_SUB, rec["flags"])
    warnings = []
    for w in prog.warnings:
        loc = w.location
        if 1 <= loc.line <= len(ex.line_map):
            loc = SourceLocation(loc.path, int(ex.line_map[loc.line - 1]), loc.col)
        warnings.append(GCodeWarning(loc, w.message))
    warnings = [GCodeWarning(SourceLocation(name, no, col), msg) for no, col, msg in ex.notes] + warnings
    warnings.sort(key=lambda w: (w.location.line, w.location.col))  # in the order of the file
    end_change = prog.end_tool_change
    if 1 <= end_change <= len(ex.line_map):
        end_change = int(ex.line_map[end_change - 1])
    return dc_replace(prog, warnings=warnings, source=data, expanded=ex, unknown_calls=tuple(ex.unknown_calls),
                      end_tool_change=end_change, loops=prog.loops or ex.loops)


def _resolve_dialect(settings: InterpreterSettings, path: str) -> str:
    if settings.dialect not in DIALECTS:
        raise GCodeError(f"unknown dialect {settings.dialect!r} (choose from {', '.join(DIALECTS)})")
    if settings.dialect != "auto":
        return settings.dialect
    return "linuxcnc" if path.lower().endswith(".ngc") else "fanuc"


def _offsets_array(settings: InterpreterSettings) -> np.ndarray:
    arr = np.zeros((9, 3))
    for key, xyz in settings.work_offsets.items():
        name = key.upper()
        if name not in _WCS_NAMES:
            raise GCodeError(f"unknown work offset {key!r} (expected one of {', '.join(_WCS_NAMES)})")
        arr[_WCS_NAMES.index(name)] = np.asarray(xyz, dtype=float)
    return arr


def _tool_arrays(settings: InterpreterSettings):
    table = settings.tool_lengths
    if not table:
        return np.zeros(1000), np.zeros(1000, np.bool_), table is not None
    size = max(1000, max(int(t) for t in table) + 1)
    lengths = np.zeros(size)
    known = np.zeros(size, np.bool_)
    for t, length in table.items():
        lengths[int(t)] = float(length)
        known[int(t)] = True
    known[0] = True  # T0 / H0: no tool, no offset (LinuxCNC's empty spindle, Fanuc's H00)
    return lengths, known, True


def _subprogram_table(lexed: Lexed):
    """O-numbers that start a line, as candidate M98 targets."""
    is_o = lexed.w_letter == ord("O")
    if not is_o.any():
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    ks = np.flatnonzero(is_o)
    first = lexed.line_w0[lexed.w_line[ks]] == ks
    ks = ks[first]
    return lexed.w_value[ks].astype(np.int64), lexed.w_line[ks].astype(np.int64)


def interpret(lexed: Lexed, settings: InterpreterSettings) -> Program:
    dialect = _resolve_dialect(settings, lexed.path)
    wcs = _offsets_array(settings)
    tool_len, tool_known, have_table = _tool_arrays(settings)
    sub_num, sub_line = _subprogram_table(lexed)
    comp_r = np.zeros(1000)
    comp_known = np.zeros(1000, np.bool_)
    for d, radius in (settings.comp_radii or {}).items():
        if 0 <= int(d) < 1000:
            comp_r[int(d)] = float(radius)
            comp_known[int(d)] = True
    cap = max(64, 2 * int(lexed.line_nw.size) + 16)
    max_steps = 200 * lexed.n_lines + 1_000_000
    warn_code = np.zeros(256, np.int64)
    warn_word = np.zeros(256, np.int64)
    last_change = np.full(3, -1, np.int64)
    while True:
        out = np.zeros(cap, MOVE_DTYPE)
        n, err, ew, eline, evals, nwarn = K.interp_kernel.auto(
            lexed.n_lines,
            lexed.line_w0, lexed.line_nw, lexed.line_flags, lexed.w_letter, lexed.w_value, lexed.w_ndec,
            sub_num, sub_line, wcs, tool_len, tool_known, have_table,
            np.asarray(settings.home_g28, float), np.asarray(settings.home_g30, float),
            0 if dialect == "fanuc" else 1, settings.lenient, settings.skip_block_delete, max_steps,
            out, warn_code, warn_word, comp_r, comp_known, last_change)
        if err != K.E_OK:  # an error is reported even if a buffer also overflowed
            break
        more_warnings = warn_code.size < nwarn <= 1_000_000
        if n <= cap and not more_warnings:
            break
        if n > K.MAX_MOVES:
            raise GCodeError(f"program expands to more than {K.MAX_MOVES:,} moves")
        cap = max(cap, n + 16)
        if more_warnings:  # run again with room for all of them, so each is counted where it occurs
            warn_code = np.zeros(nwarn, np.int64)
            warn_word = np.zeros(nwarn, np.int64)
    if err != K.E_OK:
        raise _interp_error(lexed, int(err), int(ew), int(eline), evals, settings.lenient)
    nw = min(nwarn, warn_code.size)
    warnings = _dedupe([_warning(lexed, int(warn_code[i]), int(warn_word[i])) for i in range(nw)])
    if nwarn > nw:
        warnings.append(GCodeWarning(SourceLocation(lexed.path, 0, 0), f"{nwarn - nw} more warnings"))
    records = out[:n]
    if (records["corner"] != 0).any():
        from .corners import apply as corners

        records = corners(records, lexed.path)
    if (records["comp"] != 0).any():
        from .cutcomp import apply

        records = apply(records, lexed.path)
    selected = False
    if last_change[1] < 0:
        old = records
        records = _tool_without_m6(lexed, records, warnings)
        selected = records is not old
    # a tool change after the last move (a post that puts the tool away before M30): no
    # record carries it, so the program says where it is for the twin to time it
    end_change = 0
    if last_change[1] >= 0 and last_change[2] >= n and (n == 0 or records["tool"][-1] != last_change[0]):
        end_change = int(last_change[1]) + 1
    return Program(lexed, records, settings, dialect, warnings, end_tool_change=end_change,
                   tools_by_selection=selected, loops=bool(np.any(warn_code[:nw] == K.W_M99_IN_MAIN)))


def _tool_without_m6(lexed: Lexed, records, warnings: list):
    """A program that selects tools (``T1``) but never changes one (no M6 anywhere) — what
    Fusion 360's and other router posts write for a machine without a changer, where the T word
    names the bit the operator put in — runs each move with the tool last selected above it, as
    its control does; warned once.  Only a program run top to bottom (no subprogram or loop
    sends it back) and milling tool numbers (a lathe's T0101 selects and offsets)."""
    letter, value = lexed.w_letter, lexed.w_value
    is_t = letter == ord("T")
    # (M61 Q sets the tool without a change: the program says which tool is in the spindle)
    if not is_t.any() or ((letter == ord("M")) & ((value == 6) | (value == 61))).any() or not len(records):
        return records
    t_val = value[is_t]
    if (t_val != np.floor(t_val)).any() or (t_val < 0).any() or (t_val >= 100).any():
        return records
    if (np.diff(records["line"]) < 0).any():
        return records
    t_line = lexed.w_line[is_t].astype(np.int64) + 1  # (1-based, as the records')
    k = np.searchsorted(t_line, records["line"], side="right") - 1
    tool = np.where(k >= 0, t_val[np.maximum(k, 0)].astype(records["tool"].dtype), records["tool"])
    if np.array_equal(tool, records["tool"]):
        return records
    records = records.copy()
    records["tool"] = tool
    first = int(np.flatnonzero(is_t)[0])
    warnings.append(GCodeWarning(SourceLocation(lexed.path, int(lexed.w_line[first]) + 1, 1),
                                 f"T{int(value[first])} and no M6 in the program (a router post for a machine "
                                 f"without a tool changer): each move runs with the tool last selected above it"))
    return records


def _dedupe(warnings: list) -> list:
    """One warning per message: the first place it occurs, and how often."""
    seen: dict = {}
    for w in warnings:
        if w.message in seen:
            seen[w.message][1] += 1
        else:
            seen[w.message] = [w, 1]
    return [w if n == 1 else GCodeWarning(w.location, f"{w.message} ({n} times)") for w, n in seen.values()]


def _warning(lexed: Lexed, code: int, k: int) -> GCodeWarning:
    loc = lexed.word_location(k)
    w = lexed.word_text(k)
    if code == K.W_IGNORED_G:
        msg = f"unsupported G-code {w} ignored (--lenient)"
    elif code == K.W_IGNORED_M:
        msg = f"unsupported M-code {w} ignored (--lenient)"
    elif code == K.W_COMP_RADIUS_UNKNOWN:
        msg = (f"cutter compensation with {w or 'the current tool'}: no radius known ([cutter_comp] in the twin "
               f"file), taken as 0 (a CAM-compensated path)")
    elif code == K.W_NO_FEED:
        msg = ("feed move with no F word in effect, kept with feed 0 (--lenient): the program can be read, "
               "scaled and verified, but not simulated")
    elif code == K.W_F_BEFORE_UNITS:
        msg = (f"{w} on the line that switches units (G20/G21) is read in the units in force before the "
               f"switch, as LinuxCNC reads it: put the F word after the G20/G21 line if it is meant in the new units")
    elif code == K.W_PROBE:
        msg = ("probe move taken to its programmed end (--lenient; G38.2/G38.4 trip there, G38.3/G38.5 do not, "
               "and #5061-#5070 say so): where the probe touches is known only on the machine; the program can be "
               "read, scaled and verified, not simulated")
    elif code == K.W_ARC_SPIRAL:
        msg = ("arc end point is off the circle by more than the control's tolerance: taken as a spiral "
               "from the start radius to the end radius (--lenient)")
    elif code == K.W_M99_IN_MAIN:
        msg = M99_MAIN_NOTE
    else:
        msg = f"warning {code}"
    return GCodeWarning(loc, msg)


def _has_axis_words(lexed: Lexed, li: int) -> bool:
    """Whether 0-based line ``li`` has an X, Y or Z word (or LinuxCNC's polar @ ^)."""
    w = lexed.w_letter[lexed.w_line == li]
    return bool(np.isin(w, np.frombuffer(b"XYZ@^", np.uint8)).any())


def _interp_error(lexed: Lexed, code: int, k: int, li: int, vals, lenient: bool = False) -> GCodeError:
    if k >= 0:
        loc = lexed.word_location(k)
        w = lexed.word_text(k).strip()
    else:
        loc = SourceLocation(lexed.path, li + 1, 1)
        w = ""
    # --lenient is offered only where it would help: it passes over an unknown G-code only on a
    # block without axis words (with them the code may move the tool), and not at all twice
    if lenient:
        g_hint = " (with axis words on its block it may move the tool: not passed over, even with --lenient)"
    elif _has_axis_words(lexed, loc.line - 1):
        g_hint = (" (with axis words on its block it may move the tool, so --lenient does not pass over it: "
                  "the program cannot be run as written)")
    else:
        g_hint = " (--lenient passes over codes that do not move the tool)"
    msgs = {
        K.E_UNSUPPORTED_G: f"unsupported G-code {w}{g_hint}",
        K.E_UNSUPPORTED_M: f"unsupported M-code {w}" + ("" if lenient else " (--lenient passes it over)"),
        K.E_UNSUPPORTED_WORD: f"unsupported word {w}",
        K.E_CORNER: f"{w}: a corner takes either ,C (chamfer) or ,R (radius), not both",
        K.E_POLAR16: f"{w}: G16 polar coordinates are read in G17 with an absolute radius (X) and an absolute or "
                     f"incremental angle (Y); an incremental radius (the current point as the pole) or another "
                     f"plane is not supported",
        K.E_MIRROR: f"{w}: a mirror image (G51.1) cannot change while cutter compensation is on, nor combine "
                    f"with G16 polar coordinates here",
        K.E_NO_SAVED_STATE: f"{w}: no modal state saved (M70/M73) at this call level",
        K.E_RESTORE_OFFSETS: f"{w}: the tool length offset or cutter compensation changed since the state was "
                             f"saved; restoring them is not supported",
        K.E_DUP_WORD: f"word {w[:1].upper()} appears twice in one block",
        K.E_MODAL_CONFLICT: f"{w}: two codes from the same modal group in one block",
        K.E_ARC_RADIUS_MISMATCH: (f"arc radius to end differs from radius to start: r1={vals[0]:.4f} mm "
                                  f"r2={vals[1]:.4f} mm abs_err={vals[2]:.4g} mm"),
        K.E_ARC_R_TOO_SMALL: (f"arc radius {vals[0]:.4f} mm is too small to reach the end point "
                              f"(half chord {vals[1]:.4f} mm)"),
        K.E_ARC_NO_CENTER: "arc has neither I/J/K nor R",
        K.E_ARC_ZERO_RADIUS: "arc has zero radius",
        K.E_ARC_R_FULL_CIRCLE: "R-format arc whose start and end are the same point (a full circle needs I/J/K)",
        K.E_ZERO_FEED: "feed move with zero feed rate (no F word in effect)",
        K.E_NO_MOTION_MODE: f"axis word {w} without an active motion mode (G0/G1/G2/G3/G8x)",
        K.E_TOOL_OFFSET_MISSING: f"tool length offset {w or '(current tool)'} is not in the tool table",
        K.E_BAD_G_NUMBER: f"malformed code {w}",
        K.E_CANNED_NO_Z: "canned cycle without a depth (Z) word",
        K.E_CANNED_NO_R: "canned cycle without an R (retract level) word",
        K.E_CANNED_Q: "peck cycle needs a positive Q (peck depth)",
        K.E_CANNED_R_BELOW_Z: f"canned cycle R level {vals[0]:.4f} mm is below the bottom {vals[1]:.4f} mm",
        K.E_SUB_NOT_FOUND: f"M98 subprogram {w} not found in this file",
        K.E_SUB_DEPTH: f"subprogram nesting deeper than {K.MAX_SUB_DEPTH} (a program that calls itself without end?), "
                       f"the limit of the interpreter",
        K.E_REPEATS: f"a repeat count {w} over {K.MAX_REPEATS} (Fanuc's own range L1-L9999), the limit of the "
                     f"interpreter",
        K.E_LOOP: "program does not terminate (subprogram loop)",
        K.E_MOVES: f"the program expands to more than {K.MAX_MOVES:,} moves here (repeats inside repeats, or a "
                   f"peck cycle whose Q is tiny against its depth?), the limit of the interpreter",
        K.E_GEOMETRY_G: (f"{w} is not supported: it changes the toolpath geometry (cutter compensation, "
                         "rotation, scaling, polar or lathe modes), which mtwin does not model yet"),
        K.E_BAD_WCS: f"work offset number {w} out of range",
        K.E_BAD_G10: (f"{w}: supported G10 forms are L2/L20 P<n> (work offsets, R rotation), LinuxCNC's "
                      "L1/L10/L11 P<tool> (tool table) and Fanuc's L10/L11/L12/L13 P<n> R<value> (H/D offset "
                      "geometry/wear)"),
        K.E_POLAR: (f"polar word {w}: polar moves (@ distance, ^ angle) need G17 and no X or Y word on the "
                    "block, and cannot be G10/G28/G30/G53/G92"),
        K.E_ROTARY_USE: (f"axis word {w}: work offsets (G10, G92) and canned cycles for the axes beyond "
                         "X/Y/Z (A/B/C, U/V/W) are not supported"),
        K.E_SYNC: (f"{w}: spindle-synchronised motion (G33, G33.1) needs a positive K pitch, a turning spindle "
                   "(S) and plain X/Y/Z words"),
        K.E_SPLINE: (f"{w}: G5.1 needs X/Y and I/J, G5 X/Y, I/J (or a G5 just before) and P/Q; splines are "
                     "XY-plane only (G17), with no Z, polar or rotary words, and not in inverse time (G93)"),
        K.E_PROBE: (f"{w}: a probe move stops where the probe touches, which is known only on the machine; "
                    "--lenient takes it to its programmed end (plain X/Y/Z words)"),
        K.E_THREAD: (f"{w}: G76 needs G18, a turning spindle, P (pitch), Z, I, J > 0 and K > 0 (no X); "
                     "R >= 1, H >= 0, E >= 0 and L 0-3 when given"),
        K.E_ROT_PLANE: ("coordinate rotation (G10 R, Fanuc G68 X Y R) is supported in the XY plane only, and "
                        "G68 needs its R angle"),
        K.E_INVERSE_NO_F: "inverse-time feed (G93) needs an F word on every feed move",
        K.E_BAD_VALUE: f"invalid value in word {w}",
        K.E_G53_MODE: "G53 needs G0 or G1 motion",
        K.E_BAD_TURNS: f"arc turn count {w} must be a positive integer",
        K.E_UNUSED_WORD: f"word {w} is not used by any code on this block",
        K.E_AMBIGUOUS_R: "R word is ambiguous on a block with both G64 and M19; use separate blocks",
        K.E_COMP_PLANE: "G41.1/G42.1 need a D word (the tool diameter)",
        K.E_COMP_YZ: "cutter compensation is allowed in the XY and XZ planes only (G17, G18), as in LinuxCNC",
        K.E_COMP_ACTIVE: "cutter compensation is already on: G40 first (a control refuses to switch sides here)",
    }
    return GCodeError(msgs.get(code, f"interpreter error {code}"), loc)
