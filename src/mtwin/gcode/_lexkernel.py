"""numba kernel of the G-code lexer.

Works on the raw bytes of a whole program and never builds a Python object per
word: it returns column arrays (one row per word, one row per line) with the
exact byte span of every word, so the writer can later replace a word without
touching a single other byte.  Errors are returned as (code, byte offset); the
Python wrapper turns them into ``file:line:col: message``.
"""
from __future__ import annotations

import numpy as np

from ..jit import njit

# Line flags
LF_BLOCK_DELETE = 1
LF_PERCENT = 2
LF_COMMENT = 4
LF_PROGRAM_NAME = 8  # a Fanuc program name such as OCIRCLE or O7997A

# Lexer error codes (messages in lexer.py)
LEX_OK = 0
LEX_NO_NUMBER = 1  # a letter not followed by a number
LEX_BAD_CHAR = 2  # a character that cannot start a word
LEX_UNCLOSED_COMMENT = 3
LEX_MACRO = 4  # '#' parameter or '[' expression
LEX_KEYWORD = 5  # a run of letters (IF, GOTO, WHILE, SQRT, ...)
LEX_OWORD = 6  # LinuxCNC O-word control flow (o100 sub, o<name> call)
LEX_NUMBER_TOO_LONG = 7

_POW10 = np.array([10.0**k for k in range(23)])


@njit
def _is_letter(c):
    return (65 <= c <= 90) or (97 <= c <= 122)


@njit
def _is_space(c):
    return c == 32 or c == 9 or c == 13 or c == 12 or c == 11


@njit
def _oname_has_letters(buf, q, end):
    # digits immediately followed by letters, e.g. O7997A (a name, not a number)
    ndig = 0
    while q < end and 48 <= buf[q] <= 57:
        q += 1
        ndig += 1
    return ndig > 0 and q < end and _is_letter(buf[q])


# Python lexes ~1 MB/s; compiling takes ~2 s and loading the cached code ~0.4 s
@njit(python_limit=1_500_000, python_fast=300_000)
def lex_kernel(buf, pow10):
    """Split ``buf`` (uint8) into lines and words.

    Returns (line_start, line_end, line_w0, line_nw, line_flags, line_insert,
    w_letter, w_value, w_start, w_end, w_ndec, w_line, nwords, err_code, err_pos).
    ``line_end`` excludes the line terminator (``\\n`` or ``\\r\\n``);
    ``w_ndec`` is the number of digits after the decimal point, -1 when the
    number has no point; ``line_insert`` is the byte offset just after the last
    word, where new words are inserted.
    """
    n = buf.size
    nl = 0
    nletters = 0
    for i in range(n):
        c = buf[i]
        if c == 10:
            nl += 1
        elif _is_letter(c) or c == 64 or c == 94:
            nletters += 1
    if n > 0 and buf[n - 1] != 10:
        nl += 1

    line_start = np.empty(nl, np.int64)
    line_end = np.empty(nl, np.int64)
    line_w0 = np.zeros(nl, np.int64)
    line_nw = np.zeros(nl, np.int32)
    line_flags = np.zeros(nl, np.uint8)
    line_insert = np.empty(nl, np.int64)

    w_letter = np.empty(nletters, np.uint8)
    w_value = np.empty(nletters, np.float64)
    w_start = np.empty(nletters, np.int64)
    w_end = np.empty(nletters, np.int64)
    w_ndec = np.empty(nletters, np.int8)
    w_line = np.empty(nletters, np.int32)

    nw = 0
    err_code = LEX_OK
    err_pos = -1
    pos = 0
    for li in range(nl):
        start = pos
        end = start
        while end < n and buf[end] != 10:
            end += 1
        nxt = end + 1
        if end > start and buf[end - 1] == 13:
            end -= 1
        line_start[li] = start
        line_end[li] = end
        line_w0[li] = nw
        line_insert[li] = end
        pos = nxt

        p = start
        first = True
        flags = 0
        while p < end:
            c = buf[p]
            if _is_space(c):
                p += 1
                continue
            if c == 40:  # '(' comment up to ')'
                q = p + 1
                while q < end and buf[q] != 41:
                    q += 1
                if q >= end:
                    err_code = LEX_UNCLOSED_COMMENT
                    err_pos = p
                    break
                flags |= LF_COMMENT
                p = q + 1
                continue
            if c == 59:  # ';' comment to end of line
                flags |= LF_COMMENT
                break
            if c == 37:  # '%' tape marker: alone it is a marker line, after words the rest is ignored
                if first:
                    flags |= LF_PERCENT
                break
            if c == 47 and first:  # '/' block delete
                flags |= LF_BLOCK_DELETE
                first = False
                p += 1
                continue
            first = False
            if c == 35 or c == 91:  # '#', '['
                err_code = LEX_MACRO
                err_pos = p
                break
            # '@' and '^' are LinuxCNC's polar distance and angle words; ',C' ',R' ',A' are
            # Fanuc's corner chamfer, corner radius and angle: one word each, letter in lower case
            lp = p
            if c == 44:
                lp = p + 1
                while lp < end and _is_space(buf[lp]):
                    lp += 1
                if lp < end and (buf[lp] | 32) in (97, 99, 114):
                    c = buf[lp] | 32
                else:
                    err_code = LEX_BAD_CHAR
                    err_pos = p
                    break
            if not (_is_letter(c) or c == 64 or c == 94):
                err_code = LEX_BAD_CHAR
                err_pos = p
                break
            letter = c if lp > p else (c - 32 if c >= 97 else c)
            if letter == 79 and nw == line_w0[li] and p + 1 < end and _is_letter(buf[p + 1]) \
                    or letter == 79 and nw == line_w0[li] and _oname_has_letters(buf, p + 1, end):
                # Fanuc program name (OCIRCLE, O7997A): not a word, but keep the
                # O-word control-flow check (o100 sub) below for LinuxCNC.
                q = p + 1
                while q < end and (_is_letter(buf[q]) or 48 <= buf[q] <= 57):
                    q += 1
                r = q
                while r < end and _is_space(buf[r]):
                    r += 1
                if r > q and r + 1 < end and _is_letter(buf[r]) and _is_letter(buf[r + 1]):
                    err_code = LEX_OWORD
                    err_pos = p
                    break
                flags |= LF_PROGRAM_NAME
                p = q
                continue
            if _is_letter(c) and lp + 1 < end and _is_letter(buf[lp + 1]):
                err_code = LEX_KEYWORD
                err_pos = lp
                break
            if letter == 79 and p + 1 < end and buf[p + 1] == 60:  # o<name>
                err_code = LEX_OWORD
                err_pos = p
                break
            q = lp + 1
            while q < end and _is_space(buf[q]):
                q += 1
            neg = False
            if q < end and (buf[q] == 45 or buf[q] == 43):
                neg = buf[q] == 45
                q += 1
                while q < end and _is_space(buf[q]):
                    q += 1
            mant = 0.0
            ndig = 0
            ndec = -1
            while q < end:
                d = buf[q]
                if 48 <= d <= 57:
                    mant = mant * 10.0 + (d - 48)
                    ndig += 1
                    if ndec >= 0:
                        ndec += 1
                    q += 1
                elif d == 46 and ndec < 0:
                    ndec = 0
                    q += 1
                else:
                    break
            if ndig == 0:
                if q < end and (buf[q] == 35 or buf[q] == 91 or (
                        q + 1 < end and _is_letter(buf[q]) and _is_letter(buf[q + 1]) and q > p + 1)):
                    err_code = LEX_MACRO
                    err_pos = q
                else:
                    err_code = LEX_NO_NUMBER
                    err_pos = p
                break
            if ndig > 17 or ndec > 22:
                err_code = LEX_NUMBER_TOO_LONG
                err_pos = p
                break
            # mant is an exact integer below 2**53 and 10**ndec is exact, so a
            # single division rounds correctly: the same double as float(text).
            v = mant / pow10[ndec] if ndec > 0 else mant
            if neg:
                v = -v
            w_letter[nw] = letter
            w_value[nw] = v
            w_start[nw] = p
            w_end[nw] = q
            w_ndec[nw] = ndec
            w_line[nw] = li
            nw += 1
            line_insert[li] = q
            p = q
            if letter == 79:
                # O-number followed by a keyword is LinuxCNC control flow.
                r = q
                while r < end and _is_space(buf[r]):
                    r += 1
                if r + 1 < end and _is_letter(buf[r]) and _is_letter(buf[r + 1]):
                    err_code = LEX_OWORD
                    err_pos = w_start[nw - 1]
                    break
        line_flags[li] = flags
        line_nw[li] = nw - line_w0[li]
        if err_code != LEX_OK:
            break

    return (line_start, line_end, line_w0, line_nw, line_flags, line_insert,
            w_letter, w_value, w_start, w_end, w_ndec, w_line, nw, err_code, err_pos)
