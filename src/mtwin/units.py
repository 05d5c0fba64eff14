"""Quantities with units in the twin file: ``max_velocity = "30 m/min"``.

A bare number is read in the key's documented unit; a string is a number and a
unit expression (products ``*``, quotients ``/``, powers ``^``), converted to the
key's unit.  A unit of the wrong dimension is an error naming the key, so that a
velocity given in m/s² cannot slip through as a velocity.
"""
from __future__ import annotations

import math
import re

# name -> (factor to SI, dimension exponents over (m, kg, s, A, rad)).
# Angles are dimensionless, counted in revolutions so that 1 Hz = 60 rpm = 2π rad/s.
_BASE = {
    "m": (1.0, (1, 0, 0, 0)),
    "mm": (1e-3, (1, 0, 0, 0)),
    "um": (1e-6, (1, 0, 0, 0)),
    "µm": (1e-6, (1, 0, 0, 0)),
    "cm": (1e-2, (1, 0, 0, 0)),
    "in": (0.0254, (1, 0, 0, 0)),
    "kg": (1.0, (0, 1, 0, 0)),
    "g": (1e-3, (0, 1, 0, 0)),
    "s": (1.0, (0, 0, 1, 0)),
    "ms": (1e-3, (0, 0, 1, 0)),
    "us": (1e-6, (0, 0, 1, 0)),
    "min": (60.0, (0, 0, 1, 0)),
    "h": (3600.0, (0, 0, 1, 0)),
    "A": (1.0, (0, 0, 0, 1)),
    "N": (1.0, (1, 1, -2, 0)),
    "kN": (1e3, (1, 1, -2, 0)),
    "W": (1.0, (2, 1, -3, 0)),
    "kW": (1e3, (2, 1, -3, 0)),
    "Hz": (1.0, (0, 0, -1, 0)),
    "rad": (1.0 / (2 * math.pi), (0, 0, 0, 0)),
    "rev": (1.0, (0, 0, 0, 0)),
    "rpm": (1.0 / 60.0, (0, 0, -1, 0)),
    "%": (0.01, (0, 0, 0, 0)),
    "1": (1.0, (0, 0, 0, 0)),
}

_TOKEN = re.compile(r"\s*([A-Za-zµ%1]+)(?:\^(-?\d+))?\s*")
_QUANTITY = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*(.*?)\s*$")


class UnitError(ValueError):
    pass


#: millimetres in an inch (exact: the international inch of 1959)
MM_PER_INCH = 25.4


def per_second(per_minute):
    """A rate per minute as per second: mm/min → mm/s, rpm → rev/s."""
    return per_minute / 60.0


def per_minute(per_second_):
    """A rate per second as per minute: mm/s → mm/min, rev/s → rpm."""
    return per_second_ * 60.0


def rad_per_second(rpm):
    """A rotational speed in rpm as rad/s."""
    return rpm * (2.0 * math.pi / 60.0)


def feed_per_tooth(feed_mm_min, rpm, flutes):
    """The feed per tooth (mm) of a feed (mm/min) at a spindle speed (rpm) with so many flutes:
    f_z = v_f / (z·n); 0 where the spindle stands (arrays or numbers)."""
    import numpy as np

    n = np.asarray(rpm, dtype=float) * np.asarray(flutes, dtype=float)
    out = np.where(n > 0, np.asarray(feed_mm_min, dtype=float) / np.where(n > 0, n, 1.0), 0.0)
    return float(out) if np.ndim(out) == 0 else out


def parse_unit(text: str) -> tuple[float, tuple[int, ...]]:
    """Factor to SI and dimension of a unit expression like ``N*s/m`` or ``mm/s^2``."""
    text = text.replace("·", "*").replace("²", "^2").replace("³", "^3").replace(" ", "")
    if not text:
        return 1.0, (0, 0, 0, 0)
    factor, dims = 1.0, [0, 0, 0, 0]
    sign = 1
    pos = 0
    first = True
    while pos < len(text):
        if not first:
            op = text[pos]
            if op not in "*/":
                raise UnitError(f"cannot read unit {text!r}")
            sign = 1 if op == "*" else -1
            pos += 1
        first = False
        m = _TOKEN.match(text, pos)
        if not m or m.group(1) not in _BASE:
            bad = m.group(1) if m else text[pos:]
            raise UnitError(f"unknown unit {bad!r} in {text!r}")
        f, d = _BASE[m.group(1)]
        p = sign * int(m.group(2) or 1)
        factor *= f**p
        dims = [a + p * b for a, b in zip(dims, d)]
        pos = m.end()
    return factor, tuple(dims)


def convert(value, unit: str, key: str) -> float:
    """Read ``value`` (number in ``unit``, or "number unit" string) as a float in ``unit``."""
    if isinstance(value, bool):
        raise UnitError(f"{key}: expected a number in {unit}, got {value!r}")
    if isinstance(value, (int, float)):
        out = float(value)
    elif isinstance(value, str):
        m = _QUANTITY.match(value)
        if not m:
            raise UnitError(f"{key}: cannot read {value!r} as a quantity (e.g. \"12.5 {unit}\")")
        number, given = float(m.group(1)), m.group(2)
        if not given:
            out = number
        else:
            try:
                f_given, d_given = parse_unit(given)
                f_want, d_want = parse_unit(unit)
            except UnitError as exc:
                raise UnitError(f"{key}: {exc}") from None
            if d_given != d_want:
                raise UnitError(f"{key}: unit {given!r} is not a {unit} quantity (wrong dimension)")
            out = number * f_given / f_want
    else:
        raise UnitError(f"{key}: expected a number in {unit}, got {value!r}")
    if not math.isfinite(out):
        raise UnitError(f"{key}: value must be finite")
    return out


#: The units of every JSON output, whatever the program's (an inch program's F10 is 254 mm/min).
SI_UNITS = {"length": "mm", "time": "s", "feed": "mm/min", "spindle": "rpm", "force": "N", "power": "W",
            "torque": "N·m", "energy": "J"}


def figure(x, signed: bool = False) -> str:
    """A figure to four significant digits, never in exponent form between 1e4 and 1e12
    (14,820 mm/min, not 1.482e+04); '-' for None."""
    if x is None:
        return "-"
    x = float(x)
    sign = "+" if signed else ""
    if 9999.5 <= abs(x) < 1e12:
        return format(x, f"{sign},.0f")
    return format(x, f"{sign}.4g")
