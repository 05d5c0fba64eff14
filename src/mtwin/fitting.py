"""The one fitting core: every least-squares fit of mtwin — effects to signals
(``loop.fit``), to block times (``loop.timing``), grinding parameters to a recorded cycle
(``grind.io``) — solves, reports its uncertainties and its blind parameters, and judges the
evidence here, by the same rules and the same named constants.

* :func:`solve`: bounded least squares (scipy's trust-region reflective) on
  ``residuals(x)`` (already divided by each sample's noise), in scaled coordinates
  ``u = 1 + (x − x0)/scale`` so that the finite-difference steps are a fixed share of each
  parameter's range (relative to ``x`` itself they would vanish at a zero default);
* one standard deviation per parameter from the Jacobian (``cov = s²·(JᵀJ)⁻¹``), none for a
  parameter the residuals do not see;
* identifiability (Brun et al. 2001): a parameter whose scaled sensitivity at the solution is
  below :data:`BLIND_SENSITIVITY` noise levels, or below :data:`BLIND_RELATIVE` of the most
  sensitive parameter's, and whose move bought less than :data:`BLIND_GAIN` of the residual,
  is *not identifiable* from the data fitted and stays at its start;
* :func:`delta_bic` and :func:`verdict`: the Bayesian information criterion of one model
  against another, and the words a diagnosis uses (``fits``, ``explained``, ``unexplained``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

#: a residual within this many noise levels fits (RMS against the noise estimate)
FIT_FACTOR = 1.5
#: ΔBIC below which the evidence for a model is "very strong" (Kass & Raftery 1995: a BIC
#: difference over 10) — what makes a candidate "explained" and what forward selection takes
STRONG_EVIDENCE = -10.0
#: a parameter is not identifiable when a tenth of its range moves the noise-scaled residuals
#: by less than this (RMS over the samples) …
BLIND_SENSITIVITY = 0.1
#: … or by less than this share of what the most sensitive parameter's tenth does
BLIND_RELATIVE = 1e-2
#: … and its move from the start bought less than this share of the residual sum of squares
BLIND_GAIN = 1e-2


@dataclass
class Solution:
    """A least-squares solution: the parameters (blind ones back at their starts), one standard
    deviation each (None where unknown or blind), which are not identifiable, the residuals'
    Jacobian by the scaled parameters at the solution, and the evaluations it took."""

    x: np.ndarray
    uncertainty: list
    blind: np.ndarray
    jac: np.ndarray
    fun: np.ndarray
    evaluations: int


def default_scale(lo: float, hi: float, x: float) -> float:
    """A parameter's scale: a tenth of a finite range, else its size (at least 1)."""
    if math.isfinite(lo) and math.isfinite(hi) and hi > lo:
        return 0.1 * (hi - lo)
    return max(abs(x), 1.0)


def solve(residuals: Callable[[np.ndarray], np.ndarray], x0, lo, hi, scale=None, *, max_evaluations: int = 80,
          xtol: float = 1e-8, ftol: float = 1e-10, blind_check: bool = True) -> Solution:
    """Minimise ``sum(residuals(x)**2)`` within ``lo <= x <= hi`` from ``x0`` (see the module)."""
    from scipy.optimize import least_squares

    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    x0 = np.clip(np.asarray(x0, dtype=np.float64), lo, hi)
    if scale is None:
        scale = np.array([default_scale(a, b, x) for a, b, x in zip(lo, hi, x0)])
    scale = np.asarray(scale, dtype=np.float64)
    count = [0]

    def to_x(u):
        return np.clip(x0 + (u - 1.0) * scale, lo, hi)

    def fun(u):
        count[0] += 1
        return residuals(to_x(u))

    res = least_squares(fun, np.ones(len(x0)), bounds=(1.0 + (lo - x0) / scale, 1.0 + (hi - x0) / scale),
                        method="trf", max_nfev=max_evaluations, diff_step=1e-3, xtol=xtol, ftol=ftol)
    jac = np.asarray(res.jac.toarray() if hasattr(res.jac, "toarray") else res.jac, dtype=np.float64)
    x = to_x(res.x)
    fun_x = np.asarray(res.fun)
    blind = np.zeros(len(x), dtype=bool)
    if blind_check:
        blind = _blind(residuals, x, x0, fun_x, not_identifiable(jac), count)
        if blind.any():
            x[blind] = x0[blind]
            fun_x = residuals(x)
            count[0] += 1
    unc = [None if u is None or b else u * sc for u, sc, b in zip(uncertainty(jac, res.fun, len(x)), scale, blind)]
    return Solution(x, unc, blind, jac, fun_x, count[0])


def _blind(residuals, x, x0, fun, flagged: np.ndarray, count) -> np.ndarray:
    """The flagged parameters that are blind indeed: a parameter insensitive at the solution
    is blind unless its move from the start bought more than BLIND_GAIN of the residual — a
    friction fitted into a saturation (zero slope there) has earned its value."""
    moved = flagged & (x != x0)
    if not moved.any():
        return flagged
    rss = float(np.sum(fun ** 2))

    def bought(mask) -> bool:
        y = x.copy()
        y[mask] = x0[mask]
        count[0] += 1
        return float(np.sum(residuals(y) ** 2)) > (1.0 + BLIND_GAIN) * rss

    if not bought(moved):
        return flagged
    out = flagged.copy()
    for j in np.flatnonzero(moved):
        one = np.zeros(len(x), dtype=bool)
        one[j] = True
        out[j] = not bought(one)
    return out


def uncertainty(jac: np.ndarray, fun: np.ndarray, k: int) -> list:
    """One standard deviation per (scaled) parameter from the Jacobian; None for one the
    residuals do not see (the pseudo-inverse would say 0) or when it cannot be computed."""
    try:
        dof = max(1, len(fun) - k)
        s2 = float(np.sum(np.asarray(fun) ** 2)) / dof
        cov = np.linalg.pinv(jac.T @ jac) * s2
        seen = np.linalg.norm(jac, axis=0) > 1e-12 * max(float(np.abs(jac).max()), 1e-300)
        return [float(math.sqrt(max(v, 0.0))) if ok else None for v, ok in zip(np.diag(cov), seen)]
    except (ValueError, np.linalg.LinAlgError):
        return [None] * k


def not_identifiable(jac: np.ndarray) -> np.ndarray:
    """Per parameter, whether the fitted data cannot see it: its scaled sensitivity (the RMS
    change of the noise-scaled residuals for a tenth of its range; ``jac`` is by the scaled
    parameters) under BLIND_SENSITIVITY, or under BLIND_RELATIVE of the most sensitive one's.
    Such a parameter moves only on what the model gets wrong elsewhere (a y-axis friction
    fitted to the x torque)."""
    if jac.size == 0:
        return np.zeros(jac.shape[1] if jac.ndim == 2 else 0, dtype=bool)
    delta = np.linalg.norm(jac, axis=0) / math.sqrt(max(jac.shape[0], 1))
    return (delta < BLIND_SENSITIVITY) | (delta < BLIND_RELATIVE * float(delta.max()))


def delta_bic(n: int, rss_new: float, rss_old: float, k: int) -> float:
    """Bayesian information criterion of a model with ``k`` more parameters than the old one
    (Gaussian residuals, ``n`` samples): negative favours the new one."""
    return n * math.log(max(rss_new, 1e-300) / max(rss_old, 1e-300)) + k * math.log(max(n, 2))


def verdict(rms: float, noise: float, best_delta_bic: Optional[float], explained: float = 1.0) -> str:
    """``fits`` (the residual within FIT_FACTOR noise levels), ``explained`` (the best candidate
    has very strong evidence and explains at least half the residual's variance) or
    ``unexplained``."""
    if rms <= FIT_FACTOR * noise:
        return "fits"
    if best_delta_bic is not None and best_delta_bic < STRONG_EVIDENCE and explained >= 0.5:
        return "explained"
    return "unexplained"
