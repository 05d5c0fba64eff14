"""Macro programs: parameters, expressions and control flow, executed into plain blocks.

Programs with ``#`` parameters, ``[ ]`` expressions, LinuxCNC O-word control flow
(``o100 sub``/``call``/``if``/``while``/``repeat``…) or Fanuc Macro B statements (``IF […]
GOTO n``, ``WHILE […] DO m`` … ``END m``, ``G65`` calls) are run here, line by line, into a
straight-line program whose words are all literal numbers.  That program goes through the
ordinary lexer and interpreter; every block keeps the number of the source line it came
from, so messages and motion records point into the file as written.

Semantics follow RS274NGC (LinuxCNC) and Fanuc Macro B where they agree: numbered
parameters #1–#5999 (unset reads as 0), named parameters ``#<name>`` (``#<_name>`` global,
others local to a subroutine call; reading an unset one is an error), expressions with
``**``, ``* / MOD``, ``+ -``, comparisons ``EQ NE GT GE LT LE``, ``AND OR XOR`` and the
functions ABS ACOS ASIN ATAN[y]/[x] COS EXP FIX FUP LN ROUND SIN SQRT TAN EXISTS (degrees).
Parameter assignments on a line take effect after the line's words are read.  Calls pass
arguments in #1…#30 (O-word ``call [a] [b]``; ``G65 P… A… B…`` with Fanuc's letter map); an
O-word sub returns a value with ``return [expr]`` or ``endsub [expr]`` in ``#<_value>``
(``#<_value_returned>`` 1; both 0 after a return without one, or an M99).  A LinuxCNC program
may open with a bare ``O<name>`` line: a program name, passed over.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from ..errors import GCodeError, SourceLocation

# Bounds on what a program may make the interpreter do (docs/conventions.md): each is met in
# seconds, with the line where it was reached.
MAX_EXECUTED_LINES = 2_000_000  # lines executed in all
MAX_IDLE_LINES = 200_000  # lines executed in a row with nothing to run (no move, no code word)
MAX_REPEATS = 9999  # an M98/G65 L repeat count: Fanuc's own range (L1-L9999)
MAX_CALL_DEPTH = 16  # nested subprogram and macro calls (as the plain interpreter, MAX_SUB_DEPTH)
M99_MAIN_NOTE = "M99 in the main program ends it here (a Fanuc control would loop to the start)"

# G65 argument letters -> local parameter numbers (Fanuc argument specification I)
_G65_ARGS = {"A": 1, "B": 2, "C": 3, "I": 4, "J": 5, "K": 6, "D": 7, "E": 8, "F": 9, "H": 11, "M": 13,
             "Q": 17, "R": 18, "S": 19, "T": 20, "U": 21, "V": 22, "W": 23, "X": 24, "Y": 25, "Z": 26}
_G7X = {70.0, 71.0, 71.1, 71.2, 72.0, 72.1, 72.2}  # LinuxCNC lathe profile cycles
_G_WORD = re.compile(r"G([-+]?\d*\.?\d*)")
_WORD = re.compile(r"([A-Z])([-+]?[\d.]*)")
_CODE_WORDS = re.compile(r"(,?[A-Z])([-+]?\d*\.?\d*)")
_BLANKS = re.compile(r"[ \t\r]+")
_LITERAL_LINE = re.compile(r"(?:[A-Z][-+]?(?:\d+\.?\d*|\.\d+))+")
_M7X = re.compile(r"M7[0-3](?![\d.])")
_M73 = re.compile(r"M73(?![\d.])")
_FUNCS = {"ABS", "ACOS", "ASIN", "ATAN", "COS", "EXP", "FIX", "FUP", "LN", "ROUND", "SIN", "SQRT", "TAN", "EXISTS"}
_BINOPS = [("OR", "XOR", "AND"), ("EQ", "NE", "GT", "GE", "LT", "LE"), ("+", "-"), ("*", "/", "MOD"), ("**",)]
_MACRO_HINT = re.compile(rb"#|\[|^[ \t]*/?[ \t]*[oO][ \t]*(<[^>\n]*>|\d+)[ \t]*(sub|endsub|call|return|if|elseif|else|"
                         rb"endif|while|endwhile|do|repeat|endrepeat|break|continue)\b"
                         rb"|^[ \t]*/?[ \t]*(N\d+[ \t]*)?[oO][ \t]*<[^>\n]*>[ \t\r]*$"  # an O<name> program header
                         rb"|^[ \t]*/?[ \t]*(N\d+[ \t]*)?(IF|WHILE|GOTO|END\d|G65)", re.MULTILINE | re.IGNORECASE)


# a word value that is an expression: [..], #.., or a function call, possibly signed
_FUNC_CALL = re.compile(r"((?:ABS|ACOS|ASIN|ATAN|COS|EXP|FIX|FUP|ROUND|LN|SIN|SQRT|TAN|EXISTS|BIN|BCD)[ \t]*)\[")
_EXPR_START = re.compile(r"[-+]?[ \t]*(#|\[|" + _FUNC_CALL.pattern + ")")


def looks_like_macro(data: bytes) -> bool:
    """Does the program use anything this module handles?  (A regular-expression scan of
    the whole file: the interpreter asks only when the fast lexer has stopped at a macro
    construct or found a G65.)"""
    return _MACRO_HINT.search(_strip_comments_bytes(data)) is not None


def _strip_comments_bytes(data: bytes) -> bytes:
    return re.sub(rb"\([^)\n]*\)|;[^\n]*", b"", data)


@dataclass
class Expanded:
    data: bytes  # the straight-line program
    line_map: np.ndarray  # expanded line index -> 1-based source line
    in_sub: np.ndarray  # expanded line index -> executed inside a subroutine call
    notes: list = field(default_factory=list)  # (source line, column, message): --lenient warnings
    unknown_calls: list = field(default_factory=list)  # source lines calling a program not at hand
    turning: list = field(default_factory=list)  # source lines of lathe profile cycles (G70-G72)
    loops: bool = False  # the main program ends in M99: a Fanuc control runs it again from its start


class _Err(Exception):
    def __init__(self, msg, col=1):
        super().__init__(msg)
        self.col = col


@dataclass
class _Line:
    no: int  # 1-based source line
    text: str  # code without comments, upper case, no spaces
    raw: str
    block_delete: bool
    nnum: int | None = None  # N number (Fanuc GOTO target)
    cols: list | None = None  # 1-based column in ``raw`` of each character of ``text`` (None: not yet)
    src: str | None = None  # another file this line was read from (an external subroutine)

    def col(self, i: int) -> int:
        """Source column of position i (1-based) of ``text``."""
        if self.cols is None:
            self.cols = _code_and_cols(self.raw)[1][1 if self.block_delete else 0:]
        if not self.cols:
            return 1
        return self.cols[min(max(i, 1), len(self.cols)) - 1]


def _code_and_cols(raw: str) -> tuple[str, list]:
    """A line's code (comments and blanks removed, upper case) and the source column of
    each of its characters."""
    chars = []
    cols = []
    depth = 0
    for j, ch in enumerate(raw):
        if depth:
            if ch == ")":
                depth = 0
            continue
        if ch == "(":
            depth = 1
            continue
        if ch == ";":
            break
        if ch in " \t\r":
            continue
        chars.append(ch.upper())
        cols.append(j + 1)
    return "".join(chars), cols


@dataclass
class _Frame:
    ret: int  # line index to return to
    locals_: dict = field(default_factory=dict)  # #1..#30 of this call
    named: dict = field(default_factory=dict)
    name: str = ""
    site: int = 0  # line of the program (not of a subroutine file) the call chain started from
    autorestore: bool = False  # an M73 ran in this call: its modal state comes back at the return
    loops: int | None = None  # O-word call: the caller's loop-stack depth (a return leaves the sub's loops)
    repeat: bool = False  # a second or later run of an M98 L repeat (not a deeper call)


class _Expr:
    """Recursive-descent evaluator over one line's text, starting at ``pos``."""

    def __init__(self, ex: "_Executor", text: str, pos: int):
        self.ex = ex
        self.t = text
        self.p = pos

    def peek(self, s):
        return self.t.startswith(s, self.p)

    def expect(self, s):
        if not self.peek(s):
            raise _Err(f"expected {s!r} in expression", self.p + 1)
        self.p += len(s)

    def bracket(self) -> float:
        self.expect("[")
        v = self.binary(0)
        self.expect("]")
        return v

    def binary(self, level) -> float:
        if level == len(_BINOPS):
            return self.unary()
        v = self.binary(level + 1)
        while True:
            op = next((o for o in sorted(_BINOPS[level], key=len, reverse=True) if self.peek(o)), None)
            if op is None:
                return v
            # "**" must not be read as "*" at the multiplication level
            if op == "*" and self.peek("**"):
                return v
            self.p += len(op)
            w = self.binary(level + 1) if op != "**" else self.unary()
            v = self.apply(op, v, w)
            if not math.isfinite(v):  # (1e200 * 1e200: a value no control holds)
                raise _Err(f"{op} gives a value beyond any number a control holds", self.p)

    def apply(self, op, a, b):
        if op == "+":
            return a + b
        if op == "-":
            return a - b
        if op == "*":
            return a * b
        if op == "/":
            if b == 0:
                raise _Err("division by zero", self.p)
            return a / b
        if op == "MOD":
            if b == 0:
                raise _Err("MOD by zero", self.p)
            return math.fmod(a, b) if a * b >= 0 else a - b * math.floor(a / b)
        if op == "**":
            if a < 0 and b != math.floor(b):
                raise _Err(f"{a:g} ** {b:g}: a negative number to a fractional power", self.p)
            try:
                return float(a ** b)
            except (OverflowError, ZeroDivisionError):
                raise _Err(f"{a:g} ** {b:g} is beyond any number a control holds", self.p) from None
        tol = 1e-6
        if op == "EQ":
            return float(abs(a - b) < tol)
        if op == "NE":
            return float(abs(a - b) >= tol)
        if op == "GT":
            return float(a > b)
        if op == "GE":
            return float(a >= b)
        if op == "LT":
            return float(a < b)
        if op == "LE":
            return float(a <= b)
        if op == "AND":
            return float(a != 0 and b != 0)
        if op == "OR":
            return float(a != 0 or b != 0)
        return float((a != 0) != (b != 0))  # XOR

    def unary(self) -> float:
        if self.peek("-"):
            self.p += 1
            return -self.unary()
        if self.peek("+"):
            self.p += 1
            return self.unary()
        return self.primary()

    def primary(self) -> float:
        t = self.t
        if self.peek("["):
            return self.bracket()
        if self.peek("#"):
            return self.ex.read_param(self)
        for name in sorted(_FUNCS, key=len, reverse=True):
            if self.peek(name + "["):
                self.p += len(name)
                if name == "EXISTS":
                    self.expect("[")
                    m = re.match(r"#<([^>]*)>", t[self.p:])
                    if m:
                        self.p += m.end()
                        self.expect("]")
                        return float(self.ex.named_exists(m.group(1)))
                    # numbered: EXISTS[#n], EXISTS[##n] ...: is the (computed) number a parameter?
                    hashes = 0
                    while self.peek("#"):
                        hashes += 1
                        self.p += 1
                    m = re.match(r"\d+", t[self.p:])
                    if not hashes or not m:
                        raise _Err("EXISTS needs a parameter: EXISTS[#<name>] or EXISTS[#n]", self.p + 1)
                    self.p += m.end()
                    self.expect("]")
                    n = int(m.group(0))
                    for _ in range(hashes - 1):
                        n = int(round(self.ex.get_num(n, self.p)))  # out of range is an error here
                    return float(1 <= n <= 5999)
                a = self.bracket()
                if name == "ATAN":
                    self.expect("/")
                    b = self.bracket()
                    return math.degrees(math.atan2(a, b))
                return self.func(name, a)
        m = re.match(r"\d+\.?\d*|\.\d+", t[self.p:])
        if m:
            self.p += m.end()
            return float(m.group(0))
        raise _Err(f"cannot read an expression at {t[self.p:self.p + 12]!r}", self.p + 1)

    def func(self, name, a):
        try:
            if name == "ABS":
                return abs(a)
            if name == "ACOS":
                return math.degrees(math.acos(a))
            if name == "ASIN":
                return math.degrees(math.asin(a))
            if name == "COS":
                return math.cos(math.radians(a))
            if name == "SIN":
                return math.sin(math.radians(a))
            if name == "TAN":
                return math.tan(math.radians(a))
            if name == "EXP":
                return math.exp(a)
            if name == "FIX":
                return float(math.floor(a))
            if name == "FUP":
                return float(math.ceil(a))
            if name == "LN":
                return math.log(a)
            if name == "ROUND":
                return float(math.floor(a + 0.5)) if a >= 0 else -float(math.floor(-a + 0.5))
            if name == "SQRT":
                return math.sqrt(a)
        except (ValueError, OverflowError):
            raise _Err(f"{name}[{a:g}] is outside its domain", self.p) from None
        raise _Err(f"unknown function {name}", self.p)


class _Executor:
    def __init__(self, data: bytes, path: str, dialect: str, skip_block_delete: bool, offsets: dict,
                 sub_path: tuple = ()):
        self.path = path
        self.sub_path = sub_path
        self.lenient = False
        self.probe: dict = {}  # #5061.. of the last probe move (--lenient: it ends where programmed)
        self.absolute = True  # G90/G91 as emitted so far (for probe results)
        self.notes: list = []
        self.unknown_calls: list = []
        self.turning: list = []
        self.loops = False
        self.loaded: set = set()
        self.dialect = dialect
        self.skip_bd = skip_block_delete
        self.params: dict[int, float] = {}
        # #<_value>: what the last O-word sub returned (o<name> return [expr] / endsub [expr]),
        # #<_value_returned>: 1 if it returned a value; both 0 before any call (LinuxCNC)
        self.globals_: dict[str, float] = {"_value": 0.0, "_value_returned": 0.0}
        self.frames: list[_Frame] = [_Frame(-1)]
        self.idle = 0  # lines executed since the last one that gave the interpreter code to run
        self.lines = self._split(data)
        self.current: _Line | None = None
        self.out: list[str] = []
        self.profile_pos: complex | None = None  # Z + iX while a G7x profile is read
        self.out_line: list[int] = []
        self.out_sub: list[bool] = []
        # G54..G59.3 offsets readable as #5221.. (20 apart), as the control keeps them
        for k, (x, y, z) in enumerate(offsets.get("list", [])):
            base = 5221 + 20 * k
            self.params[base], self.params[base + 1], self.params[base + 2] = x, y, z
        self._index()

    # ---------------------------------------------------------------- source
    def _split(self, data: bytes, src: str | None = None) -> list[_Line]:
        text = data.decode("latin-1")
        out = []
        for no, raw in enumerate(text.splitlines(), start=1):
            if "(" in raw or ";" in raw:
                code, cols = _code_and_cols(raw)
            else:  # the common line: no comment, so only blanks go (columns found when needed)
                code, cols = _BLANKS.sub("", raw).upper(), None
            bd = False
            if code.startswith("/"):
                bd = True
                code = code[1:]
                if cols is not None:
                    cols = cols[1:]
            nnum = None
            if code.startswith("N"):
                m = re.match(r"N(\d+)", code)
                if m:
                    nnum = int(m.group(1))
            out.append(_Line(no, code, raw, bd, nnum, cols, src))
        return out

    def _index(self, start: int = 0):
        """Positions of subroutine definitions and of every O-word, for jumps."""
        if start == 0:
            self.subs: dict[str, int] = {}
            self.fanuc_progs: dict[int, int] = {}
            self.nlines: dict[int, int] = {}
        for k in range(start, len(self.lines)):
            ln = self.lines[k]
            if ln.nnum is not None and ln.src is None:
                self.nlines.setdefault(ln.nnum, k)
            if not ln.text.startswith("O"):
                continue
            if ln.src is not None and not re.match(r"O(<[^>]*>|\d+)(SUB|$|\D)", ln.text):
                continue  # of another file only its subroutine and program headers count
            m = re.match(r"O(<[^>]*>|\d+)SUB", ln.text)
            if m:
                self.subs[m.group(1).strip("<>").lower()] = k
            m = re.fullmatch(r"O(\d+)", ln.text) or re.match(r"O(\d+)(?![A-Z<])", ln.text)
            if m and not re.match(r"O\d+[A-Z]", ln.text):
                self.fanuc_progs.setdefault(int(m.group(1)), k)

    # ---------------------------------------------------------------- parameters
    def read_param(self, e: _Expr) -> float:
        e.expect("#")
        t = e.t
        if e.peek("<"):
            j = t.find(">", e.p)
            if j < 0:
                raise _Err("named parameter without '>'", e.p + 1)
            name = t[e.p + 1:j].lower()
            e.p = j + 1
            return self.get_named(name, e.p)
        if e.peek("["):
            n = e.bracket()
        elif e.peek("#"):
            n = self.read_param(e)
        elif any(e.peek(f + "[") for f in _FUNCS):
            n = e.primary()
        else:
            m = re.match(r"\d+", t[e.p:])
            if not m:
                raise _Err("'#' must be followed by a number, '<name>' or '[expr]'", e.p + 1)
            e.p += m.end()
            n = int(m.group(0))
        return self.get_num(int(round(n)), e.p)

    def get_num(self, n: int, col: int) -> float:
        if not 0 <= n <= 5999:
            raise _Err(f"parameter #{n} does not exist (1..5999)", col)
        if 5420 <= n <= 5428 or n in (5400, 5401, 5403):
            raise _Err(f"parameter #{n} (current position / tool state) is not supported", col)
        if 5061 <= n <= 5070:
            if self.lenient and n in self.params:  # set by the last probe move, or by the program
                return self.params[n]
            if self.lenient and self.probe:
                raise _Err(f"parameter #{n} (probe result): the last probe move did not program that axis, so "
                           f"where it stopped is not known here", col)
            raise _Err(f"parameter #{n} (probe result) is not supported: where the probe touches is known only on the "
                       f"machine (with --lenient, probe moves end at their programmed end, G38.2/G38.4 tripping "
                       f"there and G38.3/G38.5 not)", col)
        if 1 <= n <= 30 and len(self.frames) > 1:
            return self.frames[-1].locals_.get(n, 0.0)
        return self.params.get(n, 0.0)

    def get_named(self, name: str, col: int) -> float:
        if name.startswith("_ini[") or name.startswith("_hal["):
            raise _Err(f"#<{name}>: INI-file and HAL parameters are not supported", col)
        if name.startswith("_"):
            if name in ("_x", "_z") and name not in self.globals_:
                # the current position: known here while a G7x profile is read (LinuxCNC
                # moves it along the profile as it reads it)
                if self.profile_pos is None:
                    raise _Err(f"#<{name}> (the current position) is known here only inside a G70-G72 "
                               f"profile", col)
                return self.profile_pos.imag if name == "_x" else self.profile_pos.real
            if name not in self.globals_:
                raise _Err(f"named parameter #<{name}> is not defined", col)
            return self.globals_[name]
        fr = self.frames[-1]
        if name not in fr.named:
            raise _Err(f"named parameter #<{name}> is not defined", col)
        return fr.named[name]

    def named_exists(self, name: str) -> bool:
        name = name.lower()
        return name in self.globals_ if name.startswith("_") else name in self.frames[-1].named

    def set_param(self, key, value):
        if isinstance(key, str):
            if key in ("_value", "_value_returned"):
                raise _Err(f"cannot assign to read-only parameter #<{key}>")
            if key.startswith("_"):
                self.globals_[key] = value
            else:
                self.frames[-1].named[key] = value
        elif not 1 <= key <= 5999:
            raise _Err(f"parameter #{key} does not exist (1..5999)")
        elif 1 <= key <= 30 and len(self.frames) > 1:
            self.frames[-1].locals_[key] = value
        else:
            self.params[key] = value

    # ---------------------------------------------------------------- lines
    def eval_at(self, text: str, pos: int) -> tuple[float, int]:
        """A word's value: a number, parameter, function or [expr] — followed, as Fanuc-style
        controls accept (X#140/2), by arithmetic without brackets up to the next address."""
        e = _Expr(self, text, pos)
        v = e.binary(2)  # + - * / MOD ** (no comparisons: their letters would eat addresses)
        return v, e.p

    def cond(self, text: str, pos: int) -> tuple[float, int]:
        e = _Expr(self, text, pos)
        v = e.bracket()
        return v, e.p

    def push(self, frame: _Frame, what: str):
        """Enter a call, within MAX_CALL_DEPTH (a program that calls itself without end stops
        here, at once, rather than at the line guard)."""
        if not frame.repeat and sum(not f.repeat for f in self.frames) > MAX_CALL_DEPTH:
            raise _Err(f"{what}: calls nested deeper than {MAX_CALL_DEPTH} (a program that calls itself without "
                       f"end?), the limit of the interpreter")
        self.frames.append(frame)

    def emit(self, words: str, no: int):
        if "G9" in words or "G38" in words:
            self._track_probe(words)
        if self.profile_pos is not None:  # reading a G7x profile: follow its position
            p = self.profile_pos
            for c, v in _WORD.findall(words):
                if v in ("", "+", "-", "."):
                    continue
                if c == "X":
                    p = complex(p.real, float(v))
                elif c == "Z":
                    p = complex(float(v), p.imag)
                elif c == "U":
                    p += 1j * float(v)
                elif c == "W":
                    p += float(v)
            self.profile_pos = p
        # moves of a subroutine from another file belong to the line that called it
        ln_src = self.current.src if self.current is not None else None
        self.idle = 0
        self.out.append(words)
        self.out_line.append(self.frames[-1].site if ln_src is not None else no)
        self.out_sub.append(len(self.frames) > 1)

    def _track_probe(self, words: str):
        """Distance mode, and the result of a G38.x move: with --lenient every probe move ends
        at its programmed end; G38.2/G38.4 (which must trip) trip there, G38.3/G38.5 do not."""
        for v in _G_WORD.findall(words):
            if v in ("90", "91"):
                self.absolute = v == "90"
        g = [float(v) for v in _G_WORD.findall(words) if v.startswith("38")]
        if not g:
            return
        vals = {c: float(v) for c, v in _WORD.findall(words) if v not in ("", "+", "-", ".")}
        self.probe = {5070: 1.0 if g[0] in (38.2, 38.4) else 0.0}
        for k, ax in enumerate("XYZABCUVW"):
            if ax in vals and self.absolute:
                self.probe[5061 + k] = vals[ax]
        for n in range(5061, 5071):
            if n in self.probe:
                self.params[n] = self.probe[n]
            else:
                self.params.pop(n, None)

    def load_external(self, label: str) -> bool:
        """Find ``<label>.ngc`` beside the program, in its subs/ folder or on the configured
        subroutine path (as LinuxCNC's SUBROUTINE_PATH), and add its lines."""
        names = (f"{label}.ngc", f"{label.upper()}.ngc", f"{label.lower()}.ngc")
        return self._load_file(names, lambda: label in self.subs)

    def load_fanuc_program(self, prog: int) -> bool:
        """Find a Fanuc program O<prog> kept in a file of its own (``O9010``, ``O9010.nc``,
        ``9010.nc`` …) beside the program, in its subs/ folder or on the subroutine path: a
        control's resident macros exported from its memory."""
        stems = {f"O{prog}", f"O{prog:04d}", f"{prog}", f"{prog:04d}"}
        names = [st + ext for st in sorted(stems) for ext in ("", ".nc", ".NC", ".ngc", ".tap", ".TAP", ".txt")]
        names += [n.lower() for n in names if n.startswith("O")]
        return self._load_file(names, lambda: prog in self.fanuc_progs)

    def _load_file(self, names, found) -> bool:
        """Add the lines of the first not yet loaded file of these names in the search
        directories that makes ``found()`` true."""
        import os

        base = os.path.dirname(os.path.abspath(self.path)) if self.path and not self.path.startswith("<") else None
        dirs = ([base, os.path.join(base, "subs")] if base else []) + list(self.sub_path)
        for d in dirs:
            for name in names:
                f = os.path.join(d, name)
                if os.path.isfile(f) and f not in self.loaded:
                    self.loaded.add(f)
                    from ..io import check_input

                    check_input(f, "program")
                    with open(f, "rb") as fh:
                        start = len(self.lines)
                        self.lines.extend(self._split(fh.read(), f))
                    self._index(start)
                    if found():
                        return True
        return False

    def missing_program(self, word: str, prog, no: int) -> bool:
        """A call of a program that is neither in the file nor beside it: an error, or with
        --lenient a warning and the call passed over (True)."""
        where = f"{word} P{prog}: program O{prog} not found in this file, nor in a file O{prog}(.nc) beside it or " \
                f"on the subroutine path"
        if not self.lenient or prog is None:
            t = _strip_n(self.current.text)
            col = t.find("P", max(t.find(word), 0)) + 1 or 1
            raise _Err(where + " (a control-resident program: export it beside the program, or use --lenient)",
                       col)
        self.notes.append((no, 1, where + ": the call is passed over (--lenient); what it does is not known, so the "
                                          "program can be read, scaled and verified but not simulated"))
        self.unknown_calls.append(no)
        return True

    def expand_words(self, text: str, no: int) -> str:
        """Evaluate every word's value and the line's assignments; return literal words."""
        if _LITERAL_LINE.fullmatch(text) and not text.startswith("O"):
            return text  # plain words with plain numbers: nothing to evaluate (kept as written)
        out = []
        assigns = []
        p = 0
        n = len(text)
        while p < n:
            c = text[p]
            if c == "#":
                # assignment: #n = expr  |  #<name> = expr  |  #[expr] = expr
                e = _Expr(self, text, p + 1)
                if e.peek("<"):
                    j = text.find(">", e.p)
                    key = text[e.p + 1:j].lower()
                    e.p = j + 1
                elif e.peek("["):
                    key = int(round(e.bracket()))
                elif any(e.peek(f + "[") for f in _FUNCS):
                    key = int(round(e.primary()))
                else:
                    m = re.match(r"\d+", text[e.p:])
                    if not m:
                        raise _Err("'#' must be followed by a number or '<name>'", p + 1)
                    key = int(m.group(0))
                    e.p += m.end()
                e.expect("=")
                v = e.binary(0)  # Fanuc allows #1 = #2/2 + 3 without brackets
                assigns.append((key, v))
                p = e.p
                continue
            if c == "," and p + 1 < n and text[p + 1] in "ACR":
                # Fanuc corner chamfer/radius (,C ,R) and angle (,A): kept as one word
                v, q = self.eval_at(text, p + 2)
                out.append(f",{text[p + 1]}{_fmt(v)}")
                p = q
                continue
            if not (c.isalpha() or c in "@^"):  # @ ^: LinuxCNC polar words
                raise _Err(f"unexpected {c!r}", p + 1)
            letter = c
            if letter == "O" and p == 0:
                # a Fanuc program number (or name) at the start of a line: not a word to run
                m = re.match(r"O[0-9A-Z]*", text)
                p = m.end()
                continue
            v, q = self.eval_at(text, p + 1)
            out.append(f"{letter}{_fmt(v)}")
            p = q
        for key, v in assigns:
            self.set_param(key, v)
        return "".join(out)

    # ---------------------------------------------------------------- run
    def run(self, k: int = 0, depth: int = 0):
        """Execute from line index k; with ``depth``, return once the subroutine call that
        made the frame stack that deep has returned (a G7x profile is read this way)."""
        lines = self.lines
        executed = 0
        loops: list = []  # LinuxCNC loop stack entries: (kind, start index, label, count)
        fanuc_loops: dict[int, int] = {}
        seen_percent = False
        while 0 <= k < len(lines):
            executed += 1
            self.idle += 1
            if executed > MAX_EXECUTED_LINES:
                raise GCodeError(f"more than {MAX_EXECUTED_LINES:,} lines executed (endless loop?), the limit "
                                 f"of the macro interpreter", SourceLocation(self.path, lines[k].no, 1))
            if self.idle > MAX_IDLE_LINES:
                raise GCodeError(f"{MAX_IDLE_LINES:,} lines executed in a row without a move or any code to run "
                                 f"(endless loop?), the limit of the macro interpreter",
                                 SourceLocation(self.path, lines[k].no, 1))
            ln = lines[k]
            self.current = ln
            t = ln.text
            try:
                if ln.block_delete and self.skip_bd:
                    k += 1
                    continue
                if t.startswith("%"):
                    if seen_percent:
                        break  # the second % ends the program
                    seen_percent = True
                    k += 1
                    continue
                if not t:
                    k += 1
                    continue
                if t.startswith("N") and ln.nnum is not None:
                    t = t[re.match(r"N\d+", t).end():]
                # ---- LinuxCNC O-words
                if t.startswith("O#") or t.startswith("O["):
                    # o#<n> call / o[expr] call: the number is computed (LinuxCNC)
                    e = _Expr(self, t, 1)
                    v = e.primary()
                    if not t[e.p:].startswith("CALL") or v != int(v) or v < 0:
                        raise _Err("a computed O-word number is only allowed for a call of a numbered sub", 2)
                    t = f"O{int(v)}{t[e.p:]}"
                m = t.startswith("O") and re.match(r"O(<[^>]*>|\d+)(SUB|ENDSUB|CALL|RETURN|IF|ELSEIF|ELSE|ENDIF|WHILE|ENDWHILE|DO|"
                             r"REPEAT|ENDREPEAT|BREAK|CONTINUE)(.*)$", t)
                if m:
                    k = self.oword(m, k, loops)
                    if len(self.frames) < depth:
                        return
                    continue
                # ---- Fanuc Macro B
                if t.startswith("IF["):
                    e = _Expr(self, t, 2)
                    v = e.binary(0)  # IF [a] AND [b] GOTO n is accepted too
                    q = e.p
                    rest = t[q:]
                    if rest.startswith("GOTO"):
                        if v:
                            k = self.goto(rest[4:], k)
                            continue
                    elif rest.startswith("THEN"):
                        if v:
                            self.expand_words(rest[4:], ln.no)
                    else:
                        raise _Err("IF [...] must be followed by GOTO n or THEN", q + 1)
                    k += 1
                    continue
                if t.startswith("GOTO"):
                    k = self.goto(t[4:], k)
                    continue
                m = t.startswith("WHILE") and re.match(r"WHILE(\[.*\])DO(\d+)$", t)
                if m:
                    v, _ = self.cond(t, 5)
                    label = int(m.group(2))
                    if v:
                        fanuc_loops[label] = k
                        k += 1
                    else:
                        k = self._find_end(k, label) + 1
                    continue
                m = t.startswith("END") and re.fullmatch(r"END(\d+)", t)
                if m:
                    label = int(m.group(1))
                    if label not in fanuc_loops:
                        raise _Err(f"END{label} without a running WHILE … DO{label}")
                    k = fanuc_loops.pop(label)
                    continue
                m = t.startswith("DO") and re.fullmatch(r"DO(\d+)", t)
                if m:  # DO without WHILE: an endless loop until GOTO leaves it
                    fanuc_loops[int(m.group(1))] = k
                    k += 1
                    continue
                # ---- Fanuc subprograms and macro calls (M98 / M99 / G65)
                if t.startswith("O") and re.fullmatch(r"O(\d+|<[^>]*>)", t):
                    # a program number, or a LinuxCNC program name O<name> alone on its line:
                    # the program runs on through it
                    k += 1
                    continue
                words = self.expand_words(t, ln.no)
                codes = _CODE_WORDS.findall(words)
                gs = [float(v) for c, v in codes if c == "G" and v]
                ms = [float(v) for c, v in codes if c == "M" and v]
                if 65.0 in gs:
                    k = self.g65(codes, k)
                    continue
                g7 = [g for g in gs if g in _G7X]
                if g7 and self.dialect != "fanuc" and any(c == "Q" for c, _ in codes):
                    self.g7x(g7[0], codes, words, k, ln.no)
                    k += 1
                    continue
                if 98.0 in ms:
                    k = self.m98(codes, words, k, ln.no)
                    continue
                if 99.0 in ms:
                    rest = _drop(words, {"M": 99.0})
                    if rest:
                        self.emit(rest, ln.no)
                    if len(self.frames) > 1:
                        self._returned(None)  # LinuxCNC: an M99 return clears #<_value>
                        fr = self._pop_frame(ln.no)
                        k = fr.ret
                        if len(self.frames) < depth:
                            return
                        continue
                    # M99 in the main program: end (no endless rerun here), said as the plain
                    # interpreter says it
                    self.loops = True
                    self.notes.append((ln.no, 1, M99_MAIN_NOTE))
                    break
                if 30.0 in ms or 2.0 in ms:
                    self.emit(words, ln.no)
                    break
                if words:
                    if "M7" in words and _M7X.search(words):
                        # LinuxCNC's modal state save/restore works per call level: tell the
                        # interpreter which one
                        words += f"L{len(self.frames) - 1}"
                        if _M73.search(words):
                            self.frames[-1].autorestore = True
                    self.emit(words, ln.no)
                k += 1
            except _Err as exc:
                col = exc.col + (len(ln.text) - len(t))  # t may have lost its N word
                raise GCodeError(str(exc), SourceLocation(ln.src or self.path, ln.no, ln.col(col))) from None

    def _modal(self) -> dict:
        """The modes a lathe cycle depends on, as the program has set them so far."""
        groups = {"plane": {17.0, 18.0, 19.0}, "dist": {90.0, 91.0}, "ijk": {90.1, 91.1}, "diam": {7.0, 8.0},
                  "comp": {40.0, 41.0, 42.0, 41.1, 42.1}}
        found = {"plane": 17.0, "dist": 90.0, "ijk": 91.1, "diam": 8.0, "comp": 40.0}
        seen: set = set()
        for words in reversed(self.out):
            if "G" not in words:
                continue
            for v in reversed(_G_WORD.findall(words)):
                g = float(v)
                for key, codes in groups.items():
                    if key not in seen and g in codes:
                        found[key] = g
                        seen.add(key)
            if len(seen) == len(groups):
                break
        return found

    def g7x(self, code: float, codes: list, words: str, k: int, no: int):
        """LinuxCNC's G70/G71/G72 lathe profile cycles (see lathe_g7x): read the profile
        subroutine named by Q, emit the cycle's moves."""
        from .lathe_g7x import Arc, Chamfer, Fillet, G7xError, Line, run_cycle

        name = f"G{code:g}"
        self.turning.append(no)
        vals = {c: float(v) for c, v in codes if c not in "GMN" and v not in ("", "+", "-", ".")}
        modal = self._modal()
        if modal["plane"] != 18.0:
            raise _Err(f"{name} can only be used in the XZ plane (G18)")
        if modal["comp"] != 40.0 and code >= 71.0:
            raise _Err(f"{name} cannot be used with cutter compensation enabled")
        if modal["dist"] == 91.0:
            raise _Err(f"{name} in incremental distance mode (G91) is not supported")
        if "X" not in vals or "Z" not in vals:
            raise _Err(f"{name} needs X and Z (where the cycle starts) on its line")
        if modal["comp"] != 40.0:
            self.notes.append((no, 1, f"{name} under cutter compensation: its approach rapids are compensated "
                                      f"here, LinuxCNC makes them without; the passes after them were not checked "
                                      f"against LinuxCNC with a nonzero radius"))
        rest = _drop(words, {"G": code}, tuple("QXZDEIPRUWKAC"))
        if rest:
            self.emit(rest, no)  # feed, spindle and modes of the line act before the cycle
        x, z = vals["X"], vals["Z"]
        self.emit(f"G0X{_fmt(x)}Z{_fmt(z)}", no)
        # in diameter mode (G7) the cycle works on radii, as LinuxCNC reads X words; the
        # moves go out as diameters again
        diam = modal["diam"] == 7.0
        xs = 0.5 if diam else 1.0
        x *= xs
        vals["X"] = x
        label = str(int(round(vals["Q"])))
        if label not in self.subs and not self.load_external(label):
            raise _Err(f"{name} Q{label}: no o{label} sub holds the profile")
        # the profile: the subroutine run as a call (its parameters and control flow act),
        # its blocks read as geometry, not executed
        saved = (self.out, self.out_line, self.out_sub)
        self.out, self.out_line, self.out_sub = [], [], []
        site = self.frames[-1].site if self.current.src is not None else no
        self.frames.append(_Frame(k + 1, {}, {}, label, site))
        here = self.current
        self.profile_pos = complex(z, x / xs)  # in the units of the words (diameters under G7)
        try:
            self.run(self.subs[label] + 1, len(self.frames))
            blocks = self.out
        finally:
            self.out, self.out_line, self.out_sub = saved
            self.current = here
            self.profile_pos = None
        ijk_inc = modal["ijk"] == 91.1
        segs: list = []
        start = complex(z, x)
        mode = None
        for b in blocks:
            bc = _WORD.findall(b)
            bv = {c: float(v) for c, v in bc if c not in "GMN" and v not in ("", "+", "-", ".")}
            for c, v in bc:
                if c == "G" and v and float(v) in (0.0, 1.0, 2.0, 3.0):
                    mode = int(float(v))
            if mode is None:
                mode = 1  # a profile line without a motion code is a feed line
            end = start
            if "U" in bv:
                if "X" in bv:
                    raise _Err(f"{name} profile: U and X in the same block")
                end += 1j * (bv["U"] / 2 if diam else bv["U"])
            elif "X" in bv:
                end = complex(end.real, bv["X"] * xs)
            if "W" in bv:
                if "Z" in bv:
                    raise _Err(f"{name} profile: W and Z in the same block")
                end += bv["W"]
            elif "Z" in bv:
                end = complex(bv["Z"], end.imag)
            if end == start:
                continue
            if mode <= 1:
                segs.append(Line(start, end))
            else:
                centre = complex(bv.get("K", 0.0), bv.get("I", 0.0))
                if "R" in bv:
                    if "I" in bv or "K" in bv:
                        raise _Err(f"{name} profile: an arc with both R and I or K")
                    rr = bv["R"]
                    n2 = abs(end - start) ** 2
                    if rr * rr < n2 / 4 - 1e-9:
                        raise _Err(f"{name} profile: arc radius R{rr:g} too small to reach its end point")
                    dd = 1j * math.sqrt(max(rr * rr - n2 / 4, 0.0) / n2) * (end - start)
                    centre = (start + end) / 2 + (dd if mode == 3 else -dd)
                else:
                    if "I" not in bv and "K" not in bv:
                        raise _Err(f"{name} profile: an arc needs I or K")
                    if ijk_inc:
                        centre += start
                segs.append(Arc(mode == 3, start, centre, end))
            if "A" in bv and "C" in bv:
                raise _Err(f"{name} profile: both A (fillet) and C (chamfer) on one corner")
            if "A" in bv:
                segs.append(Fillet(bv["A"], end))
            if "C" in bv:
                segs.append(Chamfer(bv["C"], end))
            start = end
        try:
            moves = run_cycle(code, segs, start, vals)
        except (G7xError, ZeroDivisionError, ValueError) as exc:
            raise _Err(f"{name} error: {exc}") from None
        arcs = any(m[0] in ("G2", "G3") for m in moves)
        if arcs and ijk_inc:
            self.emit("G90.1", no)  # the cycle's arc centres are absolute (as LinuxCNC's)
        for m in moves:
            p = m[1]
            xw = _fmt(p.imag / xs)
            if len(m) == 2:
                self.emit(f"{m[0]}X{xw}Z{_fmt(p.real)}", no)
            else:
                c = m[2]  # an absolute I stays a radius in diameter mode (LinuxCNC)
                self.emit(f"{m[0]}X{xw}Z{_fmt(p.real)}I{_fmt(c.imag)}K{_fmt(c.real)}", no)
        if arcs and ijk_inc:
            self.emit("G91.1", no)
        if mode is not None and mode <= 1:
            self.emit(f"G{mode}", no)  # the motion mode the profile left (LinuxCNC)

    def _returned(self, value: float | None):
        """A subroutine returns, with a value (o<name> return [expr]) or without one."""
        self.globals_["_value"] = 0.0 if value is None else value
        self.globals_["_value_returned"] = 0.0 if value is None else 1.0

    def _pop_frame(self, no: int) -> _Frame:
        fr = self.frames.pop()
        if fr.autorestore:  # M73: the caller's modal state comes back with the return
            self.emit(f"M72L{len(self.frames)}", no)
        return fr

    def goto(self, target: str, k: int) -> int:
        v, _ = self.eval_at(target, 0)
        n = int(round(v))
        if n not in self.nlines:
            raise _Err(f"GOTO {n}: no block N{n} in the program")
        return self.nlines[n]

    def _find_end(self, k: int, label: int) -> int:
        depth = 0
        for j in range(k + 1, len(self.lines)):
            t = self.lines[j].text
            t = t[re.match(r"N\d+", t).end():] if re.match(r"N\d+", t) else t
            if re.match(rf"WHILE\[.*\]DO{label}$", t):
                depth += 1
            if t == f"END{label}":
                if depth == 0:
                    return j
                depth -= 1
        raise _Err(f"WHILE … DO{label} without END{label}")

    def g65(self, codes, k):
        args = {}
        prog = None
        for c, v in codes:
            if c == "P":
                prog = int(float(v))
            elif c in _G65_ARGS and c != "G":
                args[_G65_ARGS[c]] = float(v)
        if prog is None or (prog not in self.fanuc_progs and not self.load_fanuc_program(prog)):
            self.missing_program("G65", prog, self.current.no)
            return k + 1
        site = self.frames[-1].site if self.current.src is not None else self.current.no
        self.push(_Frame(k + 1, args, {}, f"O{prog}", site), f"G65 P{prog}")
        return self.fanuc_progs[prog] + 1

    def m98(self, codes, words, k, no):
        prog = None
        reps = 1
        for c, v in codes:
            if c == "P":
                prog = int(float(v))
            if c == "L":
                if float(v) != int(float(v)) or float(v) < 0:
                    raise _Err(f"M98 L{v}: a repeat count is a whole number >= 0")
                reps = int(float(v))
        if prog is not None and prog not in self.fanuc_progs and prog > 9999:
            # packed form P<repeats><4-digit program>
            reps, prog = prog // 10000, prog % 10000
        if reps > MAX_REPEATS:
            raise _Err(f"M98 L{reps}: a repeat count over {MAX_REPEATS} (Fanuc's own range L1-L9999), the limit of the "
                       f"interpreter")
        if prog is not None and prog not in self.fanuc_progs:
            self.load_fanuc_program(prog)
        if prog is None:
            t = _strip_n(self.current.text)
            mm = re.search(r"M0*98(?![\d.])", t)
            raise _Err("M98 without a P word: P names the program to call (M98 P1000)", mm.start() + 1 if mm else 1)
        rest = _drop(words, {"M": 98.0}, ("P", "L"))
        if prog not in self.fanuc_progs:
            self.missing_program("M98", prog, no)
            if rest:
                self.emit(rest, no)
            return k + 1
        if rest:
            self.emit(rest, no)
        # run the subprogram `reps` times: stack one frame per repetition
        site = self.frames[-1].site if self.current.src is not None else no
        for _ in range(max(1, reps)):
            self.push(_Frame(k + 1 if _ == 0 else self.fanuc_progs[prog] + 1, {}, {}, f"O{prog}", site,
                             repeat=_ > 0), f"M98 P{prog}")
        # frames are popped by M99 in order; the last pushed runs first
        return self.fanuc_progs[prog] + 1

    def oword(self, m, k, loops) -> int:
        label, kw, rest = m.group(1).strip("<>").lower(), m.group(2), m.group(3)
        if kw == "SUB":
            # skip the definition in normal flow
            return self._skip_to(k, label, "ENDSUB") + 1
        if kw == "ENDSUB" or kw == "RETURN":
            if len(self.frames) <= 1:
                raise _Err(f"o{label} {kw.lower()} outside a subroutine call")
            value = None
            if rest.startswith("["):
                # a return value, evaluated in the sub (its #1..#30 and local names)
                try:
                    value, end = self.cond(rest, 0)
                except _Err as exc:
                    exc.col += m.start(3)
                    raise
                if end < len(rest):
                    raise _Err(f"unexpected {rest[end:]!r} after the value of o{label} {kw.lower()}",
                               m.start(3) + end + 1)
            elif rest:
                raise _Err(f"o{label} {kw.lower()}: a return value is written in brackets: "
                           f"o{label} {kw.lower()} [expression]", m.start(3) + 1)
            self._returned(value)
            fr = self._pop_frame(self.current.no)
            if fr.loops is not None:
                del loops[fr.loops:]  # loops of the sub that a return left
            return fr.ret
        if kw == "CALL":
            if label not in self.subs and not self.load_external(label):
                raise _Err(f"o<{label}> call: no o<{label}> sub in this file, beside it or in its subs/ folder "
                           f"(Python remaps are not supported)")
            args = {}
            pos = 0
            idx = 1
            while pos < len(rest):
                if rest[pos] != "[":
                    raise _Err("call arguments must be [expressions]", pos + 1)
                v, pos = self.cond(rest, pos)
                args[idx] = v
                idx += 1
            site = self.frames[-1].site if self.current.src is not None else self.current.no
            self.push(_Frame(k + 1, args, {}, label, site, loops=len(loops)), f"o{label} call")
            return self.subs[label] + 1
        if kw in ("IF", "ELSEIF"):
            if kw == "ELSEIF":
                # reached after a taken branch: skip to the endif
                return self._skip_to(k, label, "ENDIF") + 1
            v, _ = self.cond(rest, 0)
            j = k
            while not v:
                j = self._next_branch(j, label)
                t = _strip_n(self.lines[j].text)
                mm = re.match(r"O(<[^>]*>|\d+)(ELSEIF|ELSE|ENDIF)(.*)$", t)
                if mm.group(2) == "ELSEIF":
                    v, _ = self.cond(mm.group(3), 0)
                else:
                    return j + 1
            return j + 1
        if kw == "ELSE":
            return self._skip_to(k, label, "ENDIF") + 1
        if kw == "ENDIF":
            return k + 1
        if kw == "WHILE":
            # a "do … while" ends here
            if loops and loops[-1][0] == "do" and loops[-1][2] == label:
                v, _ = self.cond(rest, 0)
                start = loops[-1][1]
                if v:
                    return start + 1
                loops.pop()
                return k + 1
            v, _ = self.cond(rest, 0)
            if v:
                loops.append(("while", k, label, 0))
                return k + 1
            return self._skip_to(k, label, "ENDWHILE") + 1
        if kw == "ENDWHILE":
            for j in range(len(loops) - 1, -1, -1):
                if loops[j][2] == label:
                    start = loops[j][1]
                    del loops[j:]
                    return start
            raise _Err(f"o{label} endwhile without while")
        if kw == "DO":
            loops.append(("do", k, label, 0))
            return k + 1
        if kw == "REPEAT":
            v, _ = self.cond(rest, 0)
            n = int(round(v))
            if n <= 0:
                return self._skip_to(k, label, "ENDREPEAT") + 1
            loops.append(("repeat", k, label, n))
            return k + 1
        if kw == "ENDREPEAT":
            for j in range(len(loops) - 1, -1, -1):
                if loops[j][2] == label and loops[j][0] == "repeat":
                    kind, start, lab, n = loops[j]
                    if n > 1:
                        loops[j] = (kind, start, lab, n - 1)
                        return start + 1
                    del loops[j:]
                    return k + 1
            raise _Err(f"o{label} endrepeat without repeat")
        if kw in ("BREAK", "CONTINUE"):
            for j in range(len(loops) - 1, -1, -1):
                if loops[j][2] == label:
                    kind, start, lab, n = loops[j]
                    if kw == "CONTINUE":
                        del loops[j + 1:]
                        if kind == "while":
                            loops.pop()
                            return start
                        end = {"do": "WHILE", "repeat": "ENDREPEAT"}[kind]
                        return self._skip_to(start, label, end)
                    del loops[j:]
                    end = {"while": "ENDWHILE", "do": "WHILE", "repeat": "ENDREPEAT"}[kind]
                    return self._skip_to(start, label, end) + 1
            raise _Err(f"o{label} {kw.lower()} outside a loop")
        raise _Err(f"o{label} {kw.lower()} is not supported")

    def _skip_to(self, k, label, kw) -> int:
        for j in range(k + 1, len(self.lines)):
            t = _strip_n(self.lines[j].text)
            mm = re.match(r"O(<[^>]*>|\d+)([A-Z]+)", t)
            if mm and mm.group(1).strip("<>").lower() == label and mm.group(2) == kw:
                return j
        raise _Err(f"o{label}: no matching o{label} {kw.lower()}")

    def _next_branch(self, k, label) -> int:
        for j in range(k + 1, len(self.lines)):
            t = _strip_n(self.lines[j].text)
            mm = re.match(r"O(<[^>]*>|\d+)(ELSEIF|ELSE|ENDIF)", t)
            if mm and mm.group(1).strip("<>").lower() == label:
                return j
        raise _Err(f"o{label} if: no matching o{label} endif")


def _strip_n(t: str) -> str:
    m = re.match(r"N\d+", t)
    return t[m.end():] if m else t


def _fmt(v: float) -> str:
    if not math.isfinite(v):
        raise _Err(f"a word evaluates to {v}")
    s = f"{v:.10f}".rstrip("0")
    if s.endswith("."):
        s = s[:-1]
    if s in ("-0", ""):
        s = "0"
    return s


def _drop(words: str, codes: dict, letters: tuple = ()) -> str:
    """Remove the given code words (e.g. M98) and letters (P, L) from an expanded line."""
    out = []
    for c, v in re.findall(r"(,?[A-Z])([-+]?[\d.]*)", words):
        if c in codes and v and float(v) == codes[c]:
            continue
        if c in letters:
            continue
        out.append(c + v)
    return "".join(out)


def expand(data: bytes, path: str, dialect: str, skip_block_delete: bool, offsets: list,
           sub_path: tuple = (), lenient: bool = False) -> Expanded:
    """Run a macro program into a straight-line one (see the module docstring)."""
    ex = _Executor(data, path, dialect, skip_block_delete, {"list": offsets}, tuple(sub_path))
    ex.lenient = lenient
    try:
        ex.run()
    except _Err as exc:
        raise GCodeError(str(exc), SourceLocation(path, 1, exc.col)) from None
    except RecursionError:
        raise GCodeError("expression nested too deeply", SourceLocation(path, 1, 1)) from None
    text = "\n".join(ex.out) + "\n"
    return Expanded(text.encode("ascii"), np.array(ex.out_line, np.int64), np.array(ex.out_sub, bool),
                    ex.notes, ex.unknown_calls, ex.turning, ex.loops)


_STATEMENT = re.compile(r"^(N\d+)?(O(<[^>]*>|\d+)(SUB|ENDSUB|CALL|RETURN|IF|ELSEIF|ELSE|ENDIF|WHILE|ENDWHILE|DO|REPEAT|"
                        r"ENDREPEAT|BREAK|CONTINUE)|O<[^>]*>\r?$|O[#\[].*CALL|IF\[|WHILE\[|GOTO|END\d|DO\d)")


def mask_source(data: bytes, dialect: str) -> tuple[bytes, set, set]:
    """The source with every macro construct blanked out, byte for byte the same length, so
    that the ordinary lexer finds the literal words at their true positions (the writer edits
    those).  Returns (masked bytes, locked lines, locked (line, letter) pairs): a locked line
    is a statement or assignment, a locked word has an expression for its value."""
    out = bytearray(data)
    locked_lines: set = set()
    locked_words: set = set()
    pos = 0
    for li, raw in enumerate(data.split(b"\n")):
        text = raw.decode("latin-1")
        n = len(text)
        code_idx = []  # indices of code characters (outside comments)
        depth = 0
        for j, ch in enumerate(text):
            if depth:
                if ch == ")":
                    depth = 0
                continue
            if ch == "(":
                depth = 1
                continue
            if ch == ";" and dialect == "linuxcnc":
                break
            code_idx.append(j)
        code = "".join(text[j] for j in code_idx).upper()
        squeezed = code.replace(" ", "").replace("\t", "").replace("\r", "").lstrip("/")
        whole = (bool(_STATEMENT.match(squeezed)) or "=" in squeezed or bool(re.search(r"G65(?!\d)", squeezed))
                 or bool(re.search(r"M9[89](?!\d)", squeezed)))
        if whole and ("#" in squeezed or "[" in squeezed or _STATEMENT.match(squeezed)
                      or re.search(r"G65|M9[89]", squeezed)):
            locked_lines.add(li)
            for j in code_idx:
                if text[j] not in "\r\t":
                    out[pos + j] = 0x20
        else:
            # blank each word whose value is an expression
            k = 0
            while k < len(code_idx):
                j = code_idx[k]
                ch = text[j].upper()
                if not (ch.isalpha() or ch in "@^"):
                    k += 1
                    continue
                m = k + 1
                while m < len(code_idx) and text[code_idx[m]] in " \t":
                    m += 1
                rest = "".join(text[q] for q in code_idx[m:]).upper()
                if _EXPR_START.match(rest):
                    d = 0
                    e = m
                    while e < len(code_idx):
                        c2 = text[code_idx[e]]
                        if c2 == "[":
                            d += 1
                        elif c2 == "]":
                            d -= 1
                        elif d == 0 and c2.isalpha() and text[code_idx[e - 1]] not in "#<":
                            tail = "".join(text[q] for q in code_idx[e:]).upper()
                            fn = _FUNC_CALL.match(tail)
                            if fn:
                                e += len(fn.group(1))  # a function name: its [ follows
                                continue
                            if not re.match(r"[A-Z_0-9]*>", text[code_idx[e]:].upper()):
                                break
                        e += 1
                    if k > 0 and text[code_idx[k - 1]] == ",":
                        out[pos + code_idx[k - 1]] = 0x20  # the comma of a Fanuc ,C/,R word goes with it
                    for q in range(k, e):
                        out[pos + code_idx[q]] = 0x20
                    locked_words.add((li, ch))
                    k = e
                    continue
                k += 1
        pos += len(raw) + 1
    return bytes(out), locked_lines, locked_words
