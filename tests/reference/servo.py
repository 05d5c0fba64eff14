"""One feed axis under the cascade the twin's drives use, as the continuous-time system it
stands for: a position P loop with velocity feed-forward, a velocity PI loop, a rigid mass
with viscous friction,

    v_ref = Kpp·(x_c − x) + FF·ẋ_c,   F = M·ω_v·(v_ref − v + ω_i·∫(v_ref − v) dt),
    M·ẍ = F − B·ẋ,

integrated by scipy's adaptive Runge-Kutta to a tolerance far below the servo period's
discretisation.  Units: mm, s, kg, N (F in N with accelerations in mm/s² → × 1e-3)."""
from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp


def follow(t: np.ndarray, xc: np.ndarray, kpp: float, wv: float, wi: float, ff: float, mass: float,
           viscous: float, period: float = 0.0) -> np.ndarray:
    """The axis position at the times ``t`` for the command ``xc(t)`` (linear between samples),
    starting at rest on the command.  A sampled control knows the command's speed as its change
    over the last ``period`` — the speed half a period ago: the feed-forward sees it that late."""
    vc = np.gradient(xc, t)
    delay = 0.5 * period

    def rhs(tt, y):
        x, v, integ = y
        c = np.interp(tt, t, xc)
        vref = kpp * (c - x) + ff * np.interp(tt - delay, t, vc, left=0.0)
        ev = vref - v
        force = mass * wv * (ev + wi * integ) * 1e-3
        return [v, (force - viscous * v * 1e-3) / mass * 1e3, ev]

    sol = solve_ivp(rhs, (t[0], t[-1]), [xc[0], 0.0, 0.0], t_eval=t, rtol=1e-9, atol=1e-12, max_step=2e-4)
    return sol.y[0]
