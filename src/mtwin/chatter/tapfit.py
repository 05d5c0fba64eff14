"""Modal parameters from a tap test: peak picking, then a least-squares fit of the modes'
compliance to the measured FRF (real and imaginary parts, every frequency).

Start: in each direction the peaks of |Φ| (local maxima above a fifth of the largest, at
least 3 half-power bandwidths apart, ``modes`` per direction at most); per peak fn at the
peak, ζ from the half-power bandwidth, k from the peak height (|Φ|max = 1/(2kζ)).  Then
``mtwin.fitting.solve`` on log fn, log ζ, log k of all modes of a direction at once,
residuals relative to the FRF's largest magnitude.  The parameters' standard deviations come
from the Jacobian and the residual scatter.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError
from .modes import FN_MAX, FN_MIN, FRF, K_RANGE, Mode, check_sign


@dataclass
class TapFit:
    modes: tuple[Mode, ...]
    sigma: list = field(default_factory=list)  # per mode: {"fn", "zeta", "k"} one standard deviation
    rms: dict = field(default_factory=dict)  # direction -> relative RMS residual after the fit

    def as_dict(self) -> dict:
        return {"modes": [{"direction": m.direction, "fn": m.fn, "zeta": m.zeta, "k": m.k, "sigma": s}
                          for m, s in zip(self.modes, self.sigma)], "rms": self.rms}

    def toml(self, tool: int) -> str:
        out = []
        for m in self.modes:
            out += [f"[[tools.{tool}.modes]]", f'direction = "{m.direction}"', f"fn = {m.fn:.6g}",
                    f"zeta = {m.zeta:.6g}", f"k = {m.k:.6g}", ""]
        return "\n".join(out)


def _peaks(f: np.ndarray, h: np.ndarray, most: int) -> list[tuple[float, float, float]]:
    a = np.abs(h)
    top = a.max()
    cand = [i for i in range(1, len(a) - 1) if a[i] >= a[i - 1] and a[i] > a[i + 1] and a[i] > 0.2 * top]
    cand.sort(key=lambda i: -a[i])
    out: list = []
    for i in cand:
        half = a[i] / math.sqrt(2.0)
        lo = i
        while lo > 0 and a[lo] > half:
            lo -= 1
        hi = i
        while hi < len(a) - 1 and a[hi] > half:
            hi += 1
        fn = f[i]
        zeta = max((f[hi] - f[lo]) / (2.0 * fn), 1e-4)
        if any(abs(fn - p[0]) < 3 * zeta * fn + 3 * p[1] * p[0] for p in out):
            continue
        out.append((fn, zeta, 1.0 / (2.0 * zeta * a[i])))
        if len(out) >= most:
            break
    return out


def fit_frf(frf: FRF, modes_per_direction: int = 2) -> TapFit:
    from ..fitting import solve

    modes: list[Mode] = []
    sigmas: list = []
    rms: dict = {}
    check_sign(frf)  # (read_frf checks it too: an FRF built in Python comes here directly)
    for d, h in (("x", frf.xx), ("y", frf.yy)):
        if not np.any(h):
            continue
        f = frf.freq
        start = _peaks(f, h, modes_per_direction)
        if not start:
            raise ConfigError(f"{frf.source}: no resonance peak in the {d.upper()} FRF to fit a mode to")
        scale = float(np.abs(h).max())
        x0 = np.log(np.array([v for p in start for v in p]))

        def model(x):
            out = np.zeros(len(f), complex)
            for j in range(len(x) // 3):
                fn, z, k = np.exp(x[3 * j:3 * j + 3])
                r = f / fn
                out += 1.0 / (k * (1.0 - r * r + 2j * z * r))
            return out

        def resid(x):
            e = (model(x) - h) / scale
            return np.concatenate([e.real, e.imag])

        # the one fitting core (mtwin.fitting), unbounded in the logs: its uncertainty is one
        # standard deviation of each log, i.e. a relative one of fn, ζ and k
        n = len(x0)
        # (a scale of 0.01 in the logs: the core's finite-difference step, 1e-3 of the scale, is
        # then 1e-5 — fine enough for a sharp mode's Jacobian, ζ ≈ 0.005)
        sol = solve(resid, x0, np.full(n, -np.inf), np.full(n, np.inf), np.full(n, 0.01),
                    max_evaluations=200 * (n + 1), xtol=1e-12, ftol=1e-12, blind_check=False)
        r = sol.fun
        sd_log = np.array([np.nan if u is None else u for u in sol.uncertainty])
        rms[d] = float(np.sqrt(np.mean(r * r)))
        for j in range(len(sol.x) // 3):
            fn, z, k = np.exp(sol.x[3 * j:3 * j + 3])
            if not (0 < z < 1):
                raise ConfigError(f"{frf.source}: the {d.upper()} fit gives a damping ratio {z:.3g} outside (0, 1): "
                                  f"the FRF does not look like a structure's")
            if not (K_RANGE[0] <= k <= K_RANGE[1] and FN_MIN <= fn <= FN_MAX):
                # what a twin file would refuse: an outlier in the FRF, or its units (m/N) wrong
                raise ConfigError(f"{frf.source}: the {d.upper()} fit gives a mode at {fn:.4g} Hz with a stiffness of "
                                  f"{k:.3g} N/m, outside what a tool tip has ({K_RANGE[0]:g} to {K_RANGE[1]:g} N/m, "
                                  f"{FN_MIN:g} to {FN_MAX:g} Hz): an outlier in the file, or its units not m/N?")
            modes.append(Mode(d, float(fn), float(z), float(k)))
            sigmas.append({"fn": float(fn * sd_log[3 * j]), "zeta": float(z * sd_log[3 * j + 1]),
                           "k": float(k * sd_log[3 * j + 2])})
    if not modes:
        raise ConfigError(f"{frf.source}: the FRF has no direction to fit")
    return TapFit(tuple(modes), sigmas, rms)
