"""The contract of a physical effect.

The twin is a base model plus an ordered list of effects.  An effect is a small class:

* ``name`` (the catalogue's, e.g. ``spindle-no-load``), a one-line physical
  ``description``, its parameters (:class:`~mtwin.params.Param`: unit, bounds, default,
  source) and the measurement signals it changes;
* how it acts — ``stage = "loop"``: by supplying data the kernels already take (the
  per-axis servo/friction/plant table, a per-engagement-step scale of the cutting
  coefficients), so the drives and the process feel it; ``stage = "observation"``: as a
  vectorised transform of the finished :class:`~mtwin.motion.trace.Trace` (what a sensor
  or an unmodelled load adds to what is measured); ``stage = "plan"``: by changing the
  controller's timing parameters before the program is planned (tool-change and spindle
  waits, block times, corner and arc speeds), so every stage after it runs on that plan.

Estimator rules (as scikit-learn's): ``__init__`` only stores the values it is given;
:meth:`Effect.resolved` checks them against the declarations.  A user effect subclasses
:class:`Effect` and is registered like a built-in (``mtwin.effects.register``, a package's
``mtwin.effects`` entry point or ``--effect-file``; ``mtwin.effects.available()`` lists them).
"""
from __future__ import annotations

from typing import ClassVar

import numpy as np

from ..errors import ConfigError
from ..layout import Q_AREA, Q_WMAX, T_FLUTES
from ..params import Param

STAGES = ("loop", "observation", "plan")


class Effect:
    """Base class of every effect (see the module docstring)."""

    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    params: ClassVar[tuple[Param, ...]] = ()
    signals: ClassVar[tuple[str, ...]] = ()
    stage: ClassVar[str] = "observation"

    def __init__(self, **values):
        self.values = dict(values)

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.values.items())
        return f"{type(self).__name__}({args})"

    def resolved(self) -> dict[str, float]:
        """Every parameter's value: the given ones checked against their declarations, the
        others at their defaults.  An unknown name is an error that lists the known ones."""
        known = {p.name: p for p in self.params}
        for key in self.values:
            if key not in known:
                raise ConfigError(f"effect {self.name}: unknown parameter {key!r} "
                                  f"(known: {', '.join(known) or 'none'})")
        return {p.name: (p.check(self.values[p.name], f"{self.name}.{p.name}") if p.name in self.values
                         else float(p.default)) for p in self.params}

    def with_values(self, **values) -> "Effect":
        """A copy with some parameters changed."""
        return type(self)(**{**self.values, **values})

    # ---- in the loop (stage "loop"): override what the effect changes
    def servo(self, sv: np.ndarray, p: dict[str, float]) -> None:
        """Change the per-axis servo/plant table in place (columns ``motion._runkernel.SV_*``:
        friction, mass, gravity force, gains)."""

    def cutting_scale(self, steps: "StepInfo", p: dict[str, float]) -> np.ndarray | None:
        """A factor on the cutting coefficients per engagement step (None: no change)."""
        return None

    # ---- before planning (stage "plan")
    def machine(self, m, p: dict[str, float]):
        """The machine the program is planned on (``twin.machine.with_params``-style copy)."""
        return m

    # ---- on observation (stage "observation")
    def observe(self, trace, p: dict[str, float]) -> None:
        """Change the trace's signals (replace its arrays; never write into them: they may be
        shared with another trace)."""


class StepInfo:
    """What an in-loop effect may know about the engagement steps of a program: per step
    (rows of the engagement), the length of path its tool has spent in the material before
    it (mm; each tool counts its own), the chip area (mm²), the tool's row and the line."""

    def __init__(self, cut_length: np.ndarray, area: np.ndarray, tool: np.ndarray, line: np.ndarray,
                 h_max: np.ndarray | None = None):
        self.cut_length = cut_length
        self.area = area
        self.tool = tool
        self.line = line
        # maximum chip thickness at the programmed feed per tooth (mm)
        self.h_max = h_max if h_max is not None else np.zeros_like(area)

    @classmethod
    def from_engagement(cls, eng, plan, program=None) -> "StepInfo":
        seg = plan.seg
        n = len(eng.q)
        ds = np.zeros(n)
        line = np.zeros(n, np.int64)
        tool = np.zeros(n, np.int64)
        fz = np.zeros(n)
        for i in np.flatnonzero(eng.count > 0):
            a, c = int(eng.first[i]), int(eng.count[i])
            ds[a:a + c] = seg["length"][i] / c
            line[a:a + c] = seg["line"][i]
            tool[a:a + c] = eng.tool_index[i]
            if program is not None:
                rpm = abs(float(program.records["spindle"][seg["rec"][i]]))
                flutes = float(eng.tools[eng.tool_index[i], T_FLUTES])
                if rpm > 0 and flutes > 0:
                    fz[a:a + c] = seg["feed"][i] / (flutes * rpm / 60.0)  # mm per tooth
        area = np.asarray(eng.q[:, Q_AREA], dtype=np.float64)
        d = np.where(area > 0, ds, 0.0)
        length = np.zeros(n)
        for t in np.unique(tool):
            m = tool == t
            length[m] = np.cumsum(d[m]) - 0.5 * d[m]  # at the middle of each step
        h_max = fz * np.asarray(eng.q[:, Q_WMAX], dtype=np.float64)
        return cls(length, area, tool, line, h_max)
