"""Synthetic measurements: the twin, with extra effects, seen through a sensor.

How users learn the loop, and how tests get data with a hidden effect: simulate the
program on a twin with the effects to hide, keep the samples a data logger at ``rate`` Hz
would keep, add Gaussian sensor noise, and write the measurement format.
"""
from __future__ import annotations

import numpy as np

from ..errors import MtwinError
from .compare import _STAT
from .fit import row_statistics

#: the signals a machine's logger or a dynamometer usually records
DEFAULT_SIGNALS = ("x", "y", "z", "spindle_speed", "spindle_power", "x_torque", "y_torque", "z_torque",
                   "fx", "fy", "fz")


def synthesize(twin, program, *, rate: float = 100.0, noise: float = 0.0, signals=None, seed: int = 0,
               line: bool = True, stock=None) -> dict[str, np.ndarray]:
    """Measurement columns (name -> array): ``t``, ``line`` (unless ``line=False``) and
    ``signals`` sampled at ``rate`` Hz from the twin's simulation of ``program``.

    ``noise``: standard deviation of the added Gaussian noise, as a fraction of each
    signal's RMS over the measurement (0.02 = 2 %); ``seed`` makes it reproducible."""
    from ..motion.trace import SIGNALS

    if not (1e-3 <= rate < np.inf):  # (under 1e-3 Hz: less than one sample in 17 minutes)
        raise MtwinError(f"--rate must be a number of samples per second of at least 0.001, got {rate:g}")
    if not (0 <= noise < 1):
        raise MtwinError(f"--noise is a fraction of each signal's RMS in [0, 1), got {noise:g}")
    signals = tuple(signals or DEFAULT_SIGNALS)
    bad = [s for s in signals if s not in SIGNALS]
    if bad:
        raise MtwinError(f"unknown signal(s) {', '.join(bad)} (known: {', '.join(SIGNALS)})")
    dt = twin.machine.controller.servo_period
    every = max(1, int(round(1.0 / (rate * dt))))
    if abs(every * dt * rate - 1.0) > 1e-6:
        raise MtwinError(f"--rate {rate:g} Hz is not the servo rate ({1 / dt:g} Hz) divided by a whole number "
                         f"(e.g. {1 / (every * dt):g} Hz)")
    trace = twin.simulate(program, every=every, stock=stock,
                          cutting=not program.turning_line())
    rng = np.random.default_rng(seed)
    t = np.asarray(trace.t, dtype=np.float64)
    # a logger samples on its own clock: the trace's extra last sample is off that grid
    on_grid = (np.round(t / dt).astype(np.int64) % every) == 0
    cols: dict[str, np.ndarray] = {"t": t[on_grid]}
    if line:
        cols["line"] = np.asarray(trace.line)[on_grid]
    for s in signals:
        v = trace.signal(s)[on_grid]
        if noise > 0:
            rms = float(np.sqrt(np.mean(v * v))) if len(v) else 0.0
            v = v + rng.normal(0.0, noise * rms, size=v.shape)
        cols[s] = v
    return cols



#: the statistics a synthetic summary measurement holds per signal
SUMMARY_STATS = ("mean", "rms", "max")


def synthesize_summary(twin, program, *, signals=None, noise: float = 0.0, seed: int = 0, stock=None,
                       stats=SUMMARY_STATS) -> dict[str, np.ndarray]:
    """A summary measurement (columns ``first_line``, ``last_line``, ``SIGNAL_STAT``): one row
    per program line the tool cuts on (every line with samples when there is no cutting
    model), in the order the lines first run — what a dynamometer post-processed per pass, or
    a tool monitor, records.  Each statistic is taken over the full-rate simulation of the
    line's samples; ``noise`` adds Gaussian noise of that fraction of each column's RMS."""
    signals = tuple(signals or ("fx", "fy", "fz", "spindle_power"))
    bad = [s for s in stats if s not in _STAT]
    if bad:
        raise MtwinError(f"unknown statistic(s) {', '.join(bad)} (known: {', '.join(_STAT)})")
    if not (0 <= noise < 1):
        raise MtwinError(f"--noise is a fraction of each column's RMS in [0, 1), got {noise:g}")
    trace = twin.simulate(program, stock=stock, cutting=not program.turning_line())
    line = np.asarray(trace.line)
    run = line > 0
    if trace.cut is not None:
        run &= np.asarray(trace.signal("ae")) > 0
    if not run.any():
        raise MtwinError(f"{program.path}: no line of the program cuts (no summary rows to write)")
    first_seen = np.unique(line[run], return_index=True)
    lines = first_seen[0][np.argsort(first_seen[1])]  # in the order the lines first run
    rows = {f"{s}_{st}": (lines, lines) for s in signals for st in stats}
    values = row_statistics(trace, rows)
    rng = np.random.default_rng(seed)
    cols: dict[str, np.ndarray] = {"first_line": lines.astype(np.float64), "last_line": lines.astype(np.float64)}
    for c, v in values.items():
        if noise > 0:
            rms = float(np.sqrt(np.nanmean(v * v))) if len(v) else 0.0
            v = v + rng.normal(0.0, noise * rms, size=v.shape)
        cols[c] = v
    return cols
