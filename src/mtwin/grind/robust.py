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
    "runout": (0.0, 0.02),  # mm, absolute range
    "bluntness": 0.50,  # ± relative
    "compliance": 0.30,  # ± relative
    "sigma": 0.15,  # ± relative
    "gauge": (-0.001, 0.001),  # mm, absolute range
}


def sample(twin: GrindTwin, n: int, seed: int = 0, variation: dict | None = None) -> tuple[Batch, dict]:
    """``n`` parts by Latin hypercube over the variation; (batch, the factors per case)."""
    from scipy.stats import qmc

    var = dict(VARIATION, **(variation or {}))
    u = qmc.LatinHypercube(d=6, seed=seed).random(n)

    def rel(col, name, base):
        return base * (1.0 + var[name] * (2.0 * u[:, col] - 1.0))

    def ab(col, name):
        lo, hi = var[name]
        return lo + (hi - lo) * u[:, col]

    a1, a2 = twin.coefficients()
    sigma = rel(4, "sigma", 1.0)
    eta = rel(2, "bluntness", 1.0)
    factors = {"allowance": rel(0, "allowance", twin["work.allowance"]), "runout": ab(1, "runout"),
               "bluntness": eta * twin["wheel.bluntness"], "compliance": rel(3, "compliance", twin["system.compliance"]),
               "sigma": sigma * twin["work.sigma"], "gauge": ab(5, "gauge")}
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
    for it in range(max_iter):
        d = out.design if it == 0 else design(twin, M, N, scale)
        backoff = 0
        while not d.stages and it > 0 and backoff < 4:
            # tightened too far for any cycle: halfway back (geometrically) and again
            scale = {k: (scale[k] * prev_scale.get(k, 1.0)) ** 0.5 for k in scale}
            d = design(twin, M, N, scale)
            backoff += 1
        if not d.stages:
            # no cycle meets the tightened limits: the last one found stands, not robust
            out.feasible = False
            break
        out.design = d
        _, q, _ = run_cycle(twin, batch, d.stages, d.sparkout)
        v = q.violations(twin)
        bad = {k: v[k] > 1.0 for k in LIMIT_NAMES}
        mask = np.any(np.stack(list(bad.values())), axis=0)
        if first_mask is None:
            first_mask = mask
        out.iterations.append(Iteration(d.cycle_time, d.stages, cases, int(mask.sum()),
                                        {k: int(b.sum()) for k, b in bad.items() if b.any()}, dict(scale)))
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
        for k, b in bad.items():
            if b.any() and k != "reach":
                step = max(0.5, float(v[k][b].max()) ** -0.5) * 0.98
                scale[k] = scale.get(k, 1.0) * step
                if k == "size":
                    # the size scatter comes from the deflection left when the spark-out ends
                    # (it differs part to part): the roughness proxy, the last revolution's
                    # removal, is that deflection at work — tightened with it
                    scale["roughness"] = scale.get("roughness", 1.0) * step
    out.factors = factors
    out.defect_mask = first_mask
    if validate and out.feasible and out.design.stages:
        vb, _ = sample(twin, validate, seed + 1000, variation)
        _, q, _ = run_cycle(twin, vb, out.design.stages, out.design.sparkout)
        v = q.violations(twin)
        bad = {k: v[k] > 1.0 for k in LIMIT_NAMES}
        mask = np.any(np.stack(list(bad.values())), axis=0)
        out.validation = Iteration(out.design.cycle_time, out.design.stages, validate, int(mask.sum()),
                                   {k: int(b.sum()) for k, b in bad.items() if b.any()}, dict(scale))
    out.seconds = time.perf_counter() - t0
    return out
