"""Number formatting in the style of the program being rewritten.

A controller reads ``X10.`` and ``X10.0`` alike, but a Fanuc control without
"calculator-style" input reads ``X10`` as 10 least increments (10 µm), so
coordinates are always written with a decimal point.  No exponent notation and
no ``-0``.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from .lexer import Lexed

_COORD = np.array([ord(c) for c in "XYZIJKR"], dtype=np.uint8)


@dataclass(frozen=True)
class NumberStyle:
    coord_decimals: int = 3  # digits after the point for coordinates
    feed_decimals: int = 0  # digits after the point for F and S
    fixed: bool = False  # keep trailing zeros (X10.500)
    leading_zero: bool = True  # 0.5 rather than .5
    trailing_point: bool = True  # 10. rather than 10.0
    feed_point: bool = False  # F300. rather than F300

    def coord(self, v: float, decimals: int | None = None) -> str:
        return _fmt(v, self.coord_decimals if decimals is None else decimals, self.fixed, self.leading_zero,
                    self.trailing_point, True)

    def feed_decimals_for(self, inch: bool) -> int:
        # an inch feed rounded to whole in/min would be off by up to 1.3 %
        return max(self.feed_decimals, 1) if inch else self.feed_decimals

    def feed(self, v: float, inch: bool = False) -> str:
        # an optimised hour of machining writes the same few feeds 100,000 times
        return _feed_text(self, float(v), bool(inch))


    @staticmethod
    def spindle(v: float) -> str:
        # S is an integer address: a Fanuc control raises an alarm on a decimal point there
        # (as on T, M, H, D), whatever style the program's F words have
        return str(int(round(v)))


@functools.lru_cache(maxsize=4096)
def _feed_text(style: NumberStyle, v: float, inch: bool) -> str:
    # the program's own number of decimals, and more when rounding to it would be more
    # than 0.1 % off the value asked for (a slow feed written F1 or F0.12 by its post)
    dec = style.feed_decimals_for(inch)
    while dec < 6 and abs(round(v, dec) - v) > 1e-3 * abs(v):
        dec += 1
    return _fmt(v, dec, style.fixed, style.leading_zero, True, style.feed_point)


def _fmt(v: float, dec: int, fixed: bool, leading_zero: bool, trailing_point: bool, point: bool) -> str:
    s = f"{v:.{dec}f}"
    if s.lstrip("-").strip("0.") == "":
        s = s.lstrip("-")  # never -0
    if dec > 0 and not fixed:
        s = s.rstrip("0")
    if s.endswith("."):
        if not point:
            s = s[:-1]
        elif not trailing_point:
            s += "0"
    elif point and "." not in s:
        s += "." if trailing_point else ".0"
    if not leading_zero:
        # .5 for 0.5, but zero stays 0. (a bare '.' is no number)
        if s.startswith("0.") and len(s) > 2:
            s = s[1:]
        elif s.startswith("-0.") and len(s) > 3:
            s = "-" + s[2:]
    return s


def detect_style(lexed: Lexed, inch_only: bool = False) -> NumberStyle:
    """Infer the program's number style from its own words."""
    data = lexed.data
    letters = lexed.w_letter
    is_coord = np.isin(letters, _COORD)
    nd = lexed.w_ndec[is_coord]
    with_point = nd[nd >= 0]
    coord_dec = int(with_point.max()) if with_point.size else 3
    fixed = bool(with_point.size > 5 and (with_point == with_point[0]).all() and with_point[0] > 0)
    trailing_point = bool((with_point == 0).any()) or not with_point.size
    leading_zero = True
    ks = np.flatnonzero(is_coord)[:2000]
    for k in ks:
        t = data[int(lexed.w_start[k]) + 1:int(lexed.w_end[k])].lstrip(b" \t+-")
        if t.startswith(b"."):
            leading_zero = False
            break
        if t.startswith(b"0."):
            break
    fk = letters == ord("F")
    fnd = lexed.w_ndec[fk]
    # integer feeds as the program writes them: F1000 stays F1000, F1000. stays F1000. (by the
    # majority of its whole-number F words; only decimals, then whether any has a point)
    whole = fnd[fnd <= 0]
    feed_point = bool((whole == 0).sum() > (whole < 0).sum()) if whole.size else bool((fnd >= 0).any())
    feed_dec = int(fnd.max()) if fnd.size and fnd.max() > 0 else 0
    return NumberStyle(coord_decimals=min(max(coord_dec, 3), 6), feed_decimals=min(feed_dec, 4), fixed=fixed,
                       leading_zero=leading_zero, trailing_point=trailing_point, feed_point=feed_point)
