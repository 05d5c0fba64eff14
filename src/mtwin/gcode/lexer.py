"""Byte-preserving G-code lexer.

``lex(data, path)`` returns a :class:`Lexed` holding the original bytes and
column arrays describing every line and word with its exact byte span.  Nothing
is normalised: the writer rebuilds the file from these spans, so every byte we
do not mean to change stays as it was (line endings, case, spacing, comments).
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ..errors import GCodeError, SourceLocation
from . import _lexkernel as K

_MACRO_KEYWORDS = {
    "IF", "GOTO", "WHILE", "DO", "END", "THEN", "SUB", "ENDSUB", "CALL", "RETURN", "ELSE",
    "ELSEIF", "ENDIF", "ENDWHILE", "REPEAT", "ENDREPEAT", "BREAK", "CONTINUE", "EQ", "NE",
    "GT", "GE", "LT", "LE", "AND", "OR", "XOR", "MOD", "SIN", "COS", "TAN", "ASIN", "ACOS",
    "ATAN", "SQRT", "ABS", "FIX", "FUP", "ROUND", "LN", "EXP", "POPEN", "PCLOS", "DPRNT",
    "BPRNT", "SETVN", "EXISTS",
}


@dataclass
class Lexed:
    """Lexer output: the original bytes plus per-line and per-word column arrays."""

    path: str
    data: bytes
    line_start: np.ndarray  # byte offset of each line
    line_end: np.ndarray  # byte offset of the end of its content (before \r\n)
    line_w0: np.ndarray  # index of the line's first word
    line_nw: np.ndarray  # number of words on the line
    line_flags: np.ndarray  # LF_* bits
    line_insert: np.ndarray  # byte offset after the last word
    w_letter: np.ndarray  # ASCII code, upper case
    w_value: np.ndarray
    w_start: np.ndarray  # byte offset of the letter
    w_end: np.ndarray  # byte offset after the number
    w_ndec: np.ndarray  # digits after the point, -1 if no point
    w_line: np.ndarray  # 0-based line of each word

    @property
    def n_lines(self) -> int:
        return int(self.line_start.size)

    def location(self, offset: int) -> SourceLocation:
        """``file:line:col`` of a byte offset (1-based line and column)."""
        li = int(np.searchsorted(self.line_start, offset, side="right")) - 1
        li = max(li, 0)
        col = offset - int(self.line_start[li]) + 1 if self.line_start.size else 1
        return SourceLocation(self.path, li + 1, col)

    def word_location(self, k: int) -> SourceLocation:
        return self.location(int(self.w_start[k]))

    def word_text(self, k: int) -> str:
        return self.data[int(self.w_start[k]):int(self.w_end[k])].decode("latin-1")

    def line_text(self, li: int) -> str:
        return self.data[int(self.line_start[li]):int(self.line_end[li])].decode("latin-1")


class ControlByteError(GCodeError):
    """A control byte outside a comment (a NUL, a binary file's bytes): no reading of the
    program, macro or not, gets past it, so nothing else need scan the file (a 300-MB file of
    NULs is refused in the time the lexer takes to reach its first byte)."""


def lex(data: bytes, path: str = "<string>") -> Lexed:
    """Lex a whole program.  Raises :class:`GCodeError` with the first bad spot."""
    buf = np.frombuffer(data, dtype=np.uint8)
    (ls, le, lw0, lnw, lfl, lins, wl, wv, ws, we, wd, wli, nw, err, epos) = K.lex_kernel.auto(buf.size, buf, K._POW10)
    if err != K.LEX_OK:
        # line arrays are only valid up to the failing line; rebuild offsets cheaply
        starts = np.concatenate(([0], np.flatnonzero(buf == 10) + 1)).astype(np.int64)
        tmp = Lexed(path, data, starts, starts, lw0, lnw, lfl, lins, wl, wv, ws, we, wd, wli)
        loc = tmp.location(int(epos))
        if err == K.LEX_BAD_CHAR and (data[int(epos)] < 32 or data[int(epos)] == 127):
            raise ControlByteError(_lex_message(err, data, int(epos)), loc)
        raise GCodeError(_lex_message(err, data, int(epos)), loc)
    return Lexed(path, data, ls, le, lw0, lnw, lfl, lins, wl[:nw], wv[:nw], ws[:nw], we[:nw],
                 wd[:nw], wli[:nw])


def _lex_message(code: int, data: bytes, pos: int) -> str:
    end = data.find(b"\n", pos)
    rest = data[pos:end if end >= 0 else len(data)].decode("latin-1").rstrip("\r")
    ch = rest[:1]
    if code == K.LEX_NO_NUMBER:
        if ch == ",":  # a Fanuc ,C / ,R / ,A word
            return f"malformed word: {rest[:2]!r} is not followed by a number"
        return f"malformed word: letter {ch!r} is not followed by a number"
    if code == K.LEX_BAD_CHAR:
        if ch.isprintable() and ch.isascii():
            return f"unexpected character {ch!r}"
        return f"unexpected byte 0x{data[pos]:02x} outside a comment"
    if code == K.LEX_UNCLOSED_COMMENT:
        return "comment '(' is not closed on this line"
    if code == K.LEX_MACRO:
        return (f"macro parameter or expression {rest[:20]!r} is not supported "
                "(programs with # variables or [ ] expressions cannot be interpreted yet)")
    if code == K.LEX_KEYWORD:
        m = re.match(r"[A-Za-z]+", rest)
        word = m.group(0) if m else rest[:10]
        if word.upper() in _MACRO_KEYWORDS:
            return f"macro statement {word.upper()!r} is not supported (no macro/control-flow support yet)"
        return f"unknown word {word!r}: a word is one letter followed by a number"
    if code == K.LEX_OWORD:
        return f"O-word control flow {rest[:30]!r} is not supported (LinuxCNC subroutines/loops)"
    if code == K.LEX_NUMBER_TOO_LONG:
        return "number has too many digits"
    return f"lexer error {code}"
