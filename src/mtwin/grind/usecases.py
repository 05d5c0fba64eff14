"""Plunge grinding's use cases — what ``mtwin grind design|simulate|calibrate`` run, and the
Python API (``mtwin.grind.design`` …): each returns a result object with ``as_dict()``."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from ..errors import MtwinError
from ..loop.measurement import read_measurement
from .cycle import run_cycle
from .io import cycle_gcode, cycle_toml, fit, read_cycle, trace_columns
from .model import BY_NAME, Batch, GrindTwin
from .robust import robust_design


def _twin(twin, fallback=None):
    if isinstance(twin, GrindTwin):
        return twin
    return GrindTwin.from_toml(twin if twin else fallback)


def _check_feeds(tw, stages, where: str) -> None:
    lo, hi = tw["machine.feed_min"], tw["machine.feed_max"]
    for k, s in enumerate(stages, 1):
        if not lo <= s.feed <= hi:
            raise MtwinError(f"{where}: stage {k}: feed {s.feed:g} mm/min is outside the machine's range "
                             f"{lo:g}-{hi:g} mm/min (machine.feed_min, machine.feed_max)")


@dataclass
class GrindDesign:
    """The robust time-optimal cycle: ``result`` (grind.robust: the design, the iterations,
    the validation on fresh parts)."""

    twin: object
    result: object

    @property
    def sparkout_time(self) -> float:
        d = self.result.design
        return d.sparkout * 60.0 / self.twin["work.speed"]

    def gcode(self) -> bytes:
        """The cycle as G-code."""
        return cycle_gcode(self.twin, self.result.design.stages, self.sparkout_time).encode()

    def cycle_toml(self) -> str:
        """The cycle file (TOML) for ``mtwin grind simulate``."""
        d = self.result.design
        return cycle_toml(self.twin, d.stages, f"designed by mtwin grind design, {d.cycle_time:.2f} s")

    def trace_columns(self) -> dict:
        """The designed cycle's trace on the nominal part (measurement-format columns)."""
        return trace_columns(self.twin, self.result.design.stages)

    def as_dict(self) -> dict:
        res, d = self.result, self.result.design
        return {"cycle_time": d.cycle_time, "stages": [s.as_dict() for s in d.stages], "sparkout_revolutions": d.sparkout,
                "robustness": [it.as_dict() for it in res.iterations], "robust": res.feasible,
                "validation": res.validation.as_dict() if res.validation else None, "dp_seconds": d.seconds,
                "seconds": res.seconds}


MAX_PARTS = 100_000  # parts per robustness iteration or validation


def design(twin=None, *, grid: tuple[int, int] = (40, 40), cases: int = 300, validate: int = 1000, seed: int = 0,
           iterations: int = 10, progress: Optional[Callable] = None) -> GrindDesign:
    """The time-optimal stepped cycle by dynamic programming on a ``grid`` of (feed levels,
    allowance levels), then the robustness loop: the cycle run on ``cases`` varied parts,
    defects turned into tighter limits, re-optimised until none (at most ``iterations``);
    checked on ``validate`` fresh parts.  ``progress(iteration)`` after each iteration."""
    m, n = grid
    if not (2 <= m <= 400 and 2 <= n <= 400):
        raise MtwinError(f"--grid {m}x{n}: each size must be between 2 and 400")
    # (the batch is simulated in one array: a million parts is some 40 s and a few GB; 1e12 would
    # ask for terabytes)
    if not (10 <= cases <= MAX_PARTS and 0 <= validate <= MAX_PARTS and 1 <= iterations <= 1000 and seed >= 0):
        raise MtwinError(f"--cases must be from 10 to {MAX_PARTS:,}, --validate from 0 to {MAX_PARTS:,}, "
                         f"--iterations from 1 to 1,000, --seed at least 0")
    tw = _twin(twin)
    res = robust_design(tw, m, n, cases, seed, iterations, validate, progress=progress)
    if not res.design.stages:
        raise MtwinError("no cycle holds every limit on the nominal part within the machine's feed range "
                         "(see the limits and the variation in docs/grinding.md)")
    return GrindDesign(tw, res)


@dataclass
class GrindRun:
    """A cycle run on the nominal part: its figures, each limit's ratio, the stage times."""

    twin: object
    stages: list
    figures: dict
    ratios: dict
    stage_times: list

    def trace_columns(self) -> dict:
        return trace_columns(self.twin, self.stages)

    def write_trace(self, path: str, cycle: str) -> None:
        """The trace as a measurement-format file (``mtwin grind simulate -o``; ``-``: stdout),
        its header naming the cycle file it ran."""
        from ..motion.trace import write_columns

        write_columns(path, self.trace_columns(), {"source": "mtwin grind simulate", "cycle": cycle})

    def as_dict(self) -> dict:
        return {**self.figures, "limit_ratios": self.ratios, "stage_times": self.stage_times}


def simulate(cycle: str, twin=None) -> GrindRun:
    """Run a cycle file's stages on the nominal part: time, size error, roundness, roughness
    proxy, burn and force against their limits (the twin: ``twin``, else the cycle file's)."""
    stages = read_cycle(cycle)
    tw = _twin(twin, cycle)
    _check_feeds(tw, stages, cycle)
    _, q, times = run_cycle(tw, Batch.nominal(tw), stages)
    figures = {"cycle_time": float(q.cycle_time[0]), "size_error": float(q.size_error[0]),
               "roundness": float(q.roundness[0]), "roughness_feed": float(q.roughness_feed[0]),
               "burn_qw": float(q.burn_qw[0]), "peak_force": float(q.peak_force[0]), "reached_size": bool(q.reached[0])}
    ratios = {k: float(x[0]) for k, x in q.violations(tw).items()}
    return GrindRun(tw, stages, figures, ratios, [float(x) for x in times])


@dataclass
class GrindCalibration:
    """A fit of grinding parameters to a recorded cycle: ``result`` (values, RMS before and
    after), the twin before and with the fitted values."""

    twin: object
    fitted: object
    stages: list
    result: dict

    def cycle_toml(self, source: str) -> str:
        return cycle_toml(self.fitted, self.stages, f"calibrated by mtwin grind calibrate on {source}")

    @staticmethod
    def unit(name: str) -> str:
        """A fitted parameter's unit."""
        return BY_NAME[name].unit

    def as_dict(self) -> dict:
        return self.result


def calibrate(cycle: str, measurement: str, params=("system.compliance", "work.sigma"), twin=None) -> GrindCalibration:
    """Fit grinding parameters (by dotted name) to a recorded cycle — a measurement with t,
    feed (actual radial feed, mm/min) and fx (radial force, N) — by bounded least squares."""
    unknown = [p for p in params if p not in BY_NAME]
    if unknown:
        raise MtwinError(f"--param {unknown[0]}: not a grinding parameter (known: {', '.join(BY_NAME)})")
    stages = read_cycle(cycle)
    tw = _twin(twin, cycle)
    _check_feeds(tw, stages, cycle)
    m = read_measurement(measurement)
    missing = [c for c in ("feed", "fx") if c not in m.signals]
    if m.t is None or missing:
        raise MtwinError(f"{measurement}: a recorded cycle needs the columns t, feed and fx"
                         + (f" (missing: {', '.join(missing)})" if missing else ""))
    ok = np.isfinite(m.signals["feed"]) & np.isfinite(m.signals["fx"])
    if ok.sum() < len(params) + 2:
        raise MtwinError(f"{measurement}: too few complete samples ({int(ok.sum())}) to fit {len(params)} "
                         f"parameter(s)")
    res = fit(tw, stages, m.t[ok], m.signals["feed"][ok], m.signals["fx"][ok], tuple(params))
    return GrindCalibration(tw, tw.with_params(res["values"]), stages, res)
