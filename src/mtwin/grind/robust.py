"""The twin testing the cycle: batch variation, defects, tightened constraints, re-optimisation.

The optimal cycle for the nominal part is run (gauge-switched, as the machine would) on
hundreds of parts whose allowance, run-out, wheel bluntness, compliance, material stress
intensity and gauge error vary within documented ranges (a Latin hypercube).  Every limit a
part breaks becomes a tighter limit for the nominal design — by the ratio the worst part
missed it by — and the DP runs again, until the sample shows no defect or the tightening
cannot make the cycle feasible any more.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .cycle import LIMIT_NAMES, run_cycle
from .dp import Design, design
from .model import Batch, GrindTwin

#: Default variation, relative (±) or absolute ranges (docs/grinding.md).
VARIATION = {
    "allowance": 0.30,  # ± relative
    "runout": 2.0,  # from 0 to this many times the twin's run-out
    "bluntness": 0.50,  # ± relative
    "compliance": 0.30,  # ± relative
    "sigma": 0.15,  # ± relative
    "gauge": 0.001,  # mm, ± around the twin's gauge error
}


def sample(twin: GrindTwin, n: int, seed: int = 0, variation: dict | None = None) -> tuple[Batch, dict]:
    """``n`` parts by Latin hypercube over the variation; (batch, the factors per case)."""
    from scipy.stats import qmc

    var = dict(VARIATION, **(variation or {}))
    u = qmc.LatinHypercube(d=6, seed=seed).random(n)

    def rel(col, name, base):
        return base * (1.0 + var[name] * (2.0 * u[:, col] - 1.0))


    a1, a2 = twin.coefficients()
    sigma = rel(4, "sigma", 1.0)
    eta = rel(2, "bluntness", 1.0)
    factors = {"allowance": rel(0, "allowance", twin["work.allowance"]),
               "runout": var["runout"] * twin["work.runout"] * u[:, 1],
               "bluntness": eta * twin["wheel.bluntness"], "compliance": rel(3, "compliance", twin["system.compliance"]),
               "sigma": sigma * twin["work.sigma"],
               "gauge": twin["gauge.error"] + var["gauge"] * (2.0 * u[:, 5] - 1.0)}
    b = Batch(a1 * sigma, a2 * sigma * eta, factors["compliance"], factors["allowance"], factors["runout"],
              factors["gauge"])
    return b, factors


@dataclass
class Iteration:
    cycle_time: float
    stages: list
    cases: int
    defects: int
    broken: dict  # limit -> number of parts that break it
    scale: dict  # the tightened limits the design was made with

    def as_dict(self):
        return {"cycle_time": self.cycle_time, "stages": [s.as_dict() for s in self.stages], "cases": self.cases,
                "defects": self.defects, "broken": self.broken, "scale": self.scale}


@dataclass
class Robust:
    design: Design
    iterations: list = field(default_factory=list)
    feasible: bool = True
    validation: Iteration | None = None
    factors: dict | None = None  # the sample of the last iteration, for the defect map
    defect_mask: np.ndarray | None = None  # defects of the first iteration's sample
    seconds: float = 0.0


def robust_design(twin: GrindTwin, M: int = 40, N: int = 40, cases: int = 300, seed: int = 0,
                  max_iter: int = 10, validate: int = 1000, variation: dict | None = None, progress=None) -> Robust:
    import time

    t0 = time.perf_counter()
    batch, factors = sample(twin, cases, seed, variation)
    scale: dict = {}
    out = Robust(design(twin, M, N))
    first_mask = None
    prev_scale: dict = {}  # the limits before the last tightening
    best = None  # (defects, cycle time, design) of the best iteration
    for it in range(max_iter):
        d = out.design if it == 0 else design(twin, M, N, scale)
        backoff = 0
        while not d.stages and it > 0 and backoff < 4:
            # tightened too far for any cycle: halfway back (geometrically) and again
            scale = {k: (scale[k] * prev_scale.get(k, 1.0 if k != "switch" else 2.0 * scale[k])) ** 0.5
                     for k in scale}
            d = design(twin, M, N, scale)
            backoff += 1
        if not d.stages:
            out.feasible = False
            break
        out.design = d
        _, q, _ = run_cycle(twin, batch, d.stages)
        v = q.violations(twin)
        bad = {k: v[k] > 1.0 for k in LIMIT_NAMES}
        mask = np.any(np.stack(list(bad.values())), axis=0)
        if first_mask is None:
            first_mask = mask
        out.iterations.append(Iteration(d.cycle_time, d.stages, cases, int(mask.sum()),
                                        {k: int(b.sum()) for k, b in bad.items() if b.any()}, dict(scale)))
        if best is None or (int(mask.sum()), d.cycle_time) < best[:2]:
            best = (int(mask.sum()), d.cycle_time, d)
        if progress:
            progress(out.iterations[-1])
        if not mask.any():
            break
        if it == max_iter - 1:
            out.feasible = False
            break
        # each broken limit tightened for the nominal design, damped: by the square root of how
        # far the worst part missed it (at most halved per iteration), so the loop closes in
        # on the cycle rather than jumping past every feasible one
        prev_scale = dict(scale)

        def step(ratio):
            return max(0.5, float(ratio) ** -0.5) * 0.98

        for k in ("roundness", "roughness", "burn", "force"):
            if bad[k].any():
                scale[k] = scale.get(k, 1.0) * step(v[k][bad[k]].max())
        over = bad["size"] & (q.size_error > 0) | bad["reach"]
        under = bad["size"] & (q.size_error < 0)
        if over.any():
            # oversize: a part that stores less deflection than the nominal (a sharper wheel,
            # a stiffer set-up) cannot grind the allowance left at the switch to spark-out
            # away: the spark-out starts nearer size (an absolute cap on that switch point)
            scale["switch"] = min(scale.get("switch", np.inf), d.stages[-1].switch_allowance * 0.85)
        if under.any():
            scale["size"] = scale.get("size", 1.0) * step(v["size"][under].max())
    if best is not None and best[2] is not out.design and out.iterations and out.iterations[-1].defects > best[0]:
        out.design = best[2]  # not robust: the iteration with the fewest defects stands
    out.factors = factors
    out.defect_mask = first_mask
    if validate and out.design.stages:
        vb, _ = sample(twin, validate, seed + 1000, variation)
        _, q, _ = run_cycle(twin, vb, out.design.stages)
        v = q.violations(twin)
        bad = {k: v[k] > 1.0 for k in LIMIT_NAMES}
        mask = np.any(np.stack(list(bad.values())), axis=0)
        out.validation = Iteration(out.design.cycle_time, out.design.stages, validate, int(mask.sum()),
                                   {k: int(b.sum()) for k, b in bad.items() if b.any()}, dict(scale))
    out.seconds = time.perf_counter() - t0
    return out
