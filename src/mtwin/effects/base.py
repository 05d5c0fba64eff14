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

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..errors import ConfigError
from ..units import feed_per_tooth, per_minute
from ..layout import ANGLE_BINS, Q_AE, Q_AP, Q_AREA, Q_WMAX, ST_TE, T_FLUTES, T_RADIUS
from ..params import Param

STAGES = ("loop", "observation", "plan")


class Effect:
    """Base class of every effect (see the module docstring)."""

    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    params: ClassVar[tuple[Param, ...]] = ()
    signals: ClassVar[tuple[str, ...]] = ()
    stage: ClassVar[str] = "observation"
    #: the parameters a calibration fits when not told (empty: all); the others keep their
    #: values — those the usual signals cannot tell apart (a wear law's force scale and its rate)
    fitted: ClassVar[tuple[str, ...]] = ()

    def __init__(self, **values):
        fit = values.pop("fit", None)
        self.values = dict(values)
        # which parameters to fit: ``fit="rate+sigma"`` (the CLI's ``--fit NAME:fit=rate+sigma``)
        self.fit_only: tuple[str, ...] | None = None
        if fit is not None:
            names = tuple(fit.split("+")) if isinstance(fit, str) else tuple(fit)
            known = [p.name for p in self.params]
            bad = [n for n in names if n not in known]
            if bad or not names:
                raise ConfigError(f"effect {self.name}: fit={fit!r} names no parameter of it "
                                  f"(known: {', '.join(known)})")
            self.fit_only = names

    def fit_names(self) -> tuple[str, ...]:
        """The parameters a calibration moves: ``fit=`` if given, else the class's ``fitted``,
        else all."""
        return self.fit_only or self.fitted or tuple(p.name for p in self.params)

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
        e = type(self)(**{**self.values, **values})
        e.fit_only = self.fit_only
        return e

    # ---- in the loop (stage "loop"): override what the effect changes
    def servo(self, sv: np.ndarray, p: dict[str, float]) -> None:
        """Change the per-axis servo/plant table in place (columns ``motion._runkernel.SV_*``:
        friction, mass, gravity force, gains)."""

    def cutting_scale(self, steps: "StepInfo", p: dict[str, float]) -> np.ndarray | None:
        """A factor on the cutting coefficients per engagement step: (steps,) on all six, or
        (steps, 6) one per coefficient (None: no change)."""
        return None

    def cutting_add(self, steps: "StepInfo", p: dict[str, float]) -> np.ndarray | None:
        """Increments of the six cutting coefficients (ktc, krc, kac in N/mm², kte, kre, kae in
        N/mm) per engagement step, (steps, 6), added after every effect's factors (None: no
        change) — for what adds a force of its own, as a wear land's contact."""
        return None

    def wear_land(self, steps: "StepInfo", p: dict[str, float]) -> np.ndarray | None:
        """The flank-wear land VB (mm) per engagement step, for an effect that models one (the
        trace's ``vb`` signal and the tool ledger's wear state); None: it does not."""
        return None

    # ---- before planning (stage "plan")
    def machine(self, m, p: dict[str, float]):
        """The machine the program is planned on (``twin.machine.with_params``-style copy)."""
        return m

    # ---- on observation (stage "observation")
    def observe(self, trace, p: dict[str, float]) -> None:
        """Change the trace's signals (replace its arrays; never write into them: they may be
        shared with another trace)."""


@dataclass(frozen=True)
class ToolHistory:
    """What a tool has cut before a program starts (the tool ledger's record of it): path in
    the material (mm), sliding of each flute's edge over the workpiece (m; the history a wear
    law follows), time in the cut (s) and volume removed (mm³)."""

    length: float = 0.0
    sliding: float = 0.0
    time: float = 0.0
    volume: float = 0.0

    def __add__(self, other: "ToolHistory") -> "ToolHistory":
        return ToolHistory(self.length + other.length, self.sliding + other.sliding, self.time + other.time,
                           self.volume + other.volume)

    def times(self, k: float) -> "ToolHistory":
        return ToolHistory(self.length * k, self.sliding * k, self.time * k, self.volume * k)


class StepInfo:
    """What an in-loop effect may know about the engagement steps of a program, per step (rows
    of the engagement):

    * ``cut_length``: path its tool has spent in the material before it (mm, at the step's
      middle; each tool counts its own, from the tool's history when the twin has one);
    * ``sliding``: the same history as each flute's edge sliding over the workpiece (m): per
      revolution a point of the edge passes through the engaged arc R·Δφ, and a path step ds
      takes ds/(f_z·z) revolutions;
    * ``area`` (chip area, mm² per mm of feed per tooth), ``h_max`` (largest chip thickness at
      the programmed feed per tooth, mm), ``tool`` (the step's row of the tool table),
      ``tool_number`` (its T number), ``line``, ``ds`` (path mm), ``time`` (s at the
      programmed feed), ``volume`` (mm³) and ``slide`` (m, its own edge sliding) of the step;
    * ``kc``: the material's six coefficients (ktc, krc, kac, kte, kre, kae)."""

    def __init__(self, cut_length: np.ndarray, area: np.ndarray, tool: np.ndarray, line: np.ndarray,
                 h_max: np.ndarray | None = None, *, sliding: np.ndarray | None = None,
                 tool_number: np.ndarray | None = None, ds: np.ndarray | None = None,
                 time: np.ndarray | None = None, volume: np.ndarray | None = None, kc: np.ndarray | None = None,
                 slide: np.ndarray | None = None):
        zero = np.zeros_like(area)
        self.cut_length = cut_length
        self.area = area
        self.tool = tool
        self.line = line
        # maximum chip thickness at the programmed feed per tooth (mm)
        self.h_max = h_max if h_max is not None else zero
        self.sliding = sliding if sliding is not None else zero
        self.tool_number = tool_number if tool_number is not None else tool
        self.ds = ds if ds is not None else zero
        self.time = time if time is not None else zero
        self.volume = volume if volume is not None else zero
        self.slide = slide if slide is not None else zero  # each step's own sliding, m
        self.kc = kc if kc is not None else np.zeros(6)

    @classmethod
    def from_engagement(cls, eng, plan, program=None, *, kc=None, start: dict | None = None) -> "StepInfo":
        """The steps of a simulated program.  ``start``: tool number -> :class:`ToolHistory`
        the tool brings (the ledger's), so the histories continue it."""
        seg = plan.seg
        n = len(eng.q)
        ds = np.zeros(n)
        line = np.zeros(n, np.int64)
        tool = np.zeros(n, np.int64)
        number = np.zeros(n, np.int64)
        fz = np.zeros(n)
        feed = np.zeros(n)
        for i in np.flatnonzero(eng.count > 0):
            a, c = int(eng.first[i]), int(eng.count[i])
            ds[a:a + c] = seg["length"][i] / c
            line[a:a + c] = seg["line"][i]
            tool[a:a + c] = eng.tool_index[i]
            feed[a:a + c] = seg["feed"][i]
            if program is not None:
                r = seg["rec"][i]
                number[a:a + c] = program.records["tool"][r]
                rpm = abs(float(program.records["spindle"][r]))
                flutes = float(eng.tools[eng.tool_index[i], T_FLUTES])
                if rpm > 0 and flutes > 0:
                    fz[a:a + c] = feed_per_tooth(per_minute(seg["feed"][i]), rpm, flutes)  # (seg feed: mm/s)
        area = np.asarray(eng.q[:, Q_AREA], dtype=np.float64)
        inside = area > 0
        d = np.where(inside, ds, 0.0)
        radius = np.asarray(eng.tools[tool, T_RADIUS], dtype=np.float64) if n else np.zeros(0)
        flutes = np.asarray(eng.tools[tool, T_FLUTES], dtype=np.float64) if n else np.zeros(0)
        ap = np.asarray(eng.q[:, Q_AP], dtype=np.float64)
        # the engaged arc each point of the edge slides through per revolution (mm): from the
        # engagement's edge sum Σ r·db·dφ·z/2π over the engaged angle bins, per mm of engaged
        # edge (ap), plus half a bin (a bin counts when its centre is engaged: the arc's end lies
        # half a bin beyond on average); an end face alone (ap 0) slides π·R on average
        arc = np.where(ap > 0, 2.0 * np.pi * np.asarray(eng.sums[:, ST_TE], dtype=np.float64)
                       / np.maximum(flutes * ap, 1e-12) + radius * np.pi / ANGLE_BINS, np.pi * radius)
        # edge sliding per flute (m): ds/(fz·z) revolutions of that arc
        slide = np.where(inside & (fz > 0), d * arc / np.maximum(fz * flutes, 1e-12), 0.0) * 1e-3
        time = np.where(inside & (feed > 0), d / np.maximum(feed, 1e-12), 0.0)  # (segment feeds are mm/s)
        volume = d * np.asarray(eng.q[:, Q_AE], dtype=np.float64) * ap
        length = np.zeros(n)
        sliding = np.zeros(n)
        start = start or {}
        for t in np.unique(tool):
            m = tool == t
            # each tool row is one T number here; the ledger's history is by T number
            h = start.get(int(number[m][0]), None) if program is not None and m.any() else None
            length[m] = np.cumsum(d[m]) - 0.5 * d[m] + (h.length if h else 0.0)  # at the middle of each step
            sliding[m] = np.cumsum(slide[m]) - 0.5 * slide[m] + (h.sliding if h else 0.0)
        h_max = fz * np.asarray(eng.q[:, Q_WMAX], dtype=np.float64)
        return cls(length, area, tool, line, h_max, sliding=sliding, tool_number=number if program is not None
                   else tool, ds=d, time=time, volume=volume, slide=slide,
                   kc=np.asarray(kc, dtype=np.float64) if kc is not None else None)

    def history(self) -> dict[int, ToolHistory]:
        """What this program adds to each tool's history (tool number -> ToolHistory)."""
        out = {}
        for t in np.unique(self.tool_number):
            m = self.tool_number == t
            out[int(t)] = ToolHistory(float(self.ds[m].sum()), float(self.slide[m].sum()),
                                      float(self.time[m].sum()), float(self.volume[m].sum()))
        return out
