"""numba kernel of position alignment: measured samples to the simulated path, forward only."""
from __future__ import annotations

from ..jit import njit

_EPS = 1e-9  # mm² per sample²: among equally near points, the one the elapsed time predicts


@njit
def nearest_forward(ps, pm, tm, dt, idx):
    """For each measured point ``pm[i]`` (times ``tm``, s from the first), the index into the
    simulated points ``ps`` (servo period ``dt``) nearest to it, never before the previous
    sample's: searched from there to a window ahead of where the elapsed time predicts
    (four times the time step, and at least 0.5 s), so a twin whose timing is off by tens of
    per cent still aligns."""
    ns = ps.shape[0]
    j = 0
    for i in range(pm.shape[0]):
        if i == 0:
            pred = 0
            gap = 0
        else:
            gap = int(round((tm[i] - tm[i - 1]) / dt))
            pred = idx[i - 1] + gap
        # the first sample may have been logged anywhere in the program: the whole path
        hi = ns - 1 if i == 0 else min(ns - 1, max(pred, j) + max(4 * gap, int(0.5 / dt)))
        best = j
        bestc = 1e300
        for k in range(j, hi + 1):
            dx = ps[k, 0] - pm[i, 0]
            dy = ps[k, 1] - pm[i, 1]
            dz = ps[k, 2] - pm[i, 2]
            c = dx * dx + dy * dy + dz * dz + _EPS * (k - pred) * (k - pred)
            if c < bestc:
                bestc = c
                best = k
        idx[i] = best
        j = best
