"""Effects on observation: what a sensor or an unmodelled load adds to what is measured.

Each is a vectorised transform of a finished trace; the drives and the process do not feel
it (a spindle's no-load losses do not load the cut; a delayed position sensor does not
delay the axis)."""
from __future__ import annotations

import math

import numpy as np

from ..layout import AXES
from ..params import Param
from .base import Effect

_RUNNING_RPM = 1.0  # below this the spindle counts as stopped (as in the servo loop)


class SpindleNoLoad(Effect):
    name = "spindle-no-load"
    description = "spindle drive losses while it turns: P0 + b·n + c·n² added to the measured spindle power"
    params = (
        Param("p0", "W", 0.0, 0.0, 5000.0, "constant loss while the spindle turns"),
        Param("b", "W/rpm", 0.0, 0.0, 1.0, "loss per rpm (bearings, viscous)"),
        Param("c", "W/rpm^2", 0.0, 0.0, 1e-4, "loss per rpm² (windage, fan)"),
    )
    signals = ("spindle_power",)

    def observe(self, trace, p):
        n = np.abs(trace.signal("spindle_speed"))
        loss = np.where(n >= _RUNNING_RPM, p["p0"] + p["b"] * n + p["c"] * n * n, 0.0)
        trace.set_signal("spindle_power", trace.signal("spindle_power") + loss)


class ServoDelay(Effect):
    name = "servo-delay"
    description = "the measured axis positions lag the real ones by a fixed delay (sensor, bus or logging latency)"
    params = (Param("delay", "s", 0.0, 0.0, 0.1, "position measurement delay"),)
    signals = ("x", "y", "z")

    def observe(self, trace, p):
        t = np.asarray(trace.t, dtype=np.float64)
        for a in AXES:
            trace.set_signal(a, np.interp(t - p["delay"], t, trace.signal(a)))


class ThermalDrift(Effect):
    name = "thermal-drift"
    description = "slow exponential drift of the measured positions as the machine warms: d·(1 − exp(−t/τ))"
    params = (
        Param("dx", "mm", 0.0, -0.5, 0.5, "final drift of X"),
        Param("dy", "mm", 0.0, -0.5, 0.5, "final drift of Y"),
        Param("dz", "mm", 0.0, -0.5, 0.5, "final drift of Z"),
        Param("tau", "s", 600.0, 10.0, 14400.0, "time constant of the warm-up [E: 10-60 min]"),
    )
    signals = ("x", "y", "z")

    def observe(self, trace, p):
        t = np.asarray(trace.t, dtype=np.float64)
        shape = 1.0 - np.exp(-(t - t[0]) / p["tau"]) if len(t) else t
        for a in AXES:
            d = p["d" + a]
            if d:
                trace.set_signal(a, trace.signal(a) + d * shape)


class Backlash(Effect):
    name = "backlash"
    description = "lost motion at reversals: the measured (load-side) position trails the drive by half the backlash"
    params = tuple(Param(f"b{a}", "mm", 0.0, 0.0, 0.2, f"backlash of {a.upper()} (total lost motion)") for a in AXES)
    signals = ("x", "y", "z")

    def observe(self, trace, p):
        for k, a in enumerate(AXES):
            b = p["b" + a]
            if not b:
                continue
            # the side the drive last pushed from: the sign of the last commanded movement
            d = np.sign(np.diff(trace.cmd[:, k].astype(np.float64), prepend=trace.cmd[0, k]))
            d[np.abs(np.diff(trace.cmd[:, k].astype(np.float64), prepend=trace.cmd[0, k])) < 1e-9] = 0.0
            idx = np.where(d != 0, np.arange(len(d)), 0)
            np.maximum.accumulate(idx, out=idx)
            side = d[idx]
            trace.set_signal(a, trace.signal(a) - 0.5 * b * side)


class Runout(Effect):
    name = "runout"
    description = ("tool runout: the cutting force modulated once per spindle revolution, "
                   "F·(1 + e·cos(θ + φ)) (the revolution average is unchanged)")
    params = (
        Param("e", "", 0.0, 0.0, 0.5, "relative amplitude of the once-per-revolution modulation"),
        Param("phase", "rad", 0.0, -math.pi, math.pi, "angle of the longest tooth at θ = 0"),
    )
    signals = ("fx", "fy", "fz")

    def observe(self, trace, p):
        t = np.asarray(trace.t, dtype=np.float64)
        n = trace.signal("spindle_speed")
        # spindle angle: the speed integrated over the trace's own samples
        dt = np.diff(t, prepend=t[0] if len(t) else 0.0)
        theta = 2.0 * math.pi * np.cumsum(n / 60.0 * dt)
        m = 1.0 + p["e"] * np.cos(theta + p["phase"])
        for s in self.signals:
            trace.set_signal(s, trace.signal(s) * m)
