"""The time-optimal motion along a straight chain of moves with a trapezoidal profile (no jerk
limit): the speed may never exceed a move's own maximum, a junction's limit where two moves
meet, or what the acceleration allows from the start at rest and towards every later
limit (and away from every earlier one) — and is the largest speed that obeys them all.  Integrated over a fine grid of
distance, each small step at constant acceleration."""
from __future__ import annotations

import numpy as np


def speed_limit(s: np.ndarray, length: np.ndarray, vmax: np.ndarray, acc: float, vj: np.ndarray) -> np.ndarray:
    """The largest speed (mm/s) allowed at each distance ``s`` along the chain."""
    ends = np.cumsum(length)
    starts = ends - length
    v = np.full(len(s), np.inf)
    for i in range(len(length)):
        inside = (s >= starts[i] - 1e-12) & (s <= ends[i] + 1e-12)
        v[inside] = np.minimum(v[inside], vmax[i])
    v = np.minimum(v, np.sqrt(2.0 * acc * s))  # from rest at the start
    for k in range(len(length)):  # towards each junction's limit (and the stop at the end), and away from it
        before = s <= ends[k] + 1e-12
        v[before] = np.minimum(v[before], np.sqrt(vj[k] ** 2 + 2.0 * acc * np.maximum(ends[k] - s[before], 0.0)))
        after = ~before | (s >= ends[k] - 1e-12)
        v[after] = np.minimum(v[after], np.sqrt(vj[k] ** 2 + 2.0 * acc * np.maximum(s[after] - ends[k], 0.0)))
    return v


def junction_times(length, vmax, acc: float, vj, points: int = 400_000) -> np.ndarray:
    """The time (s) at which the time-optimal motion reaches the end of each move."""
    length = np.asarray(length, float)
    ends = np.cumsum(length)
    s = np.unique(np.concatenate([np.linspace(0.0, ends[-1], points), ends, ends - length]))
    v = speed_limit(s, length, np.asarray(vmax, float), acc, np.asarray(vj, float))
    # between grid points the speed changes at constant acceleration (or stays): dt = 2 ds / (v0 + v1)
    ds = np.diff(s)
    dt = np.where(ds > 0, 2.0 * ds / np.maximum(v[:-1] + v[1:], 1e-300), 0.0)
    t = np.concatenate([[0.0], np.cumsum(dt)])
    return np.interp(ends, s, t)
