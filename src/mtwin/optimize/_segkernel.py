"""Kernels of the power-curve segmentation (per path step, so compiled for long programs)."""
from __future__ import annotations

import math

import numpy as np

from ..jit import njit


@njit(python_limit=300_000, python_fast=30_000)
def sequential_clusters(p, w, min_len, k_radius, tol, out_start):
    """Sequential clustering of the power-smoothing reference: a step joins the current
    segment while its distance to the segment's (length-weighted) mean stays within the
    segment's radius — ``k_radius`` times its rms deviation, at least ``tol`` — and always
    while the segment is shorter than ``min_len`` (mm), which keeps it from fragmenting.
    Writes the first step of every segment into ``out_start``; returns their number."""
    n = p.shape[0]
    if n == 0:
        return 0
    ns = 1
    out_start[0] = 0
    sw = w[0]
    swp = w[0] * p[0]
    swp2 = w[0] * p[0] * p[0]
    for i in range(1, n):
        mean = swp / sw if sw > 0.0 else p[i]
        var = swp2 / sw - mean * mean if sw > 0.0 else 0.0
        rms = math.sqrt(var) if var > 0.0 else 0.0
        radius = max(k_radius * rms, tol)
        if sw < min_len or abs(p[i] - mean) <= radius:
            sw += w[i]
            swp += w[i] * p[i]
            swp2 += w[i] * p[i] * p[i]
        else:
            out_start[ns] = i
            ns += 1
            sw = w[i]
            swp = w[i] * p[i]
            swp2 = w[i] * p[i] * p[i]
    return ns


def binary_segmentation(p: np.ndarray, w: np.ndarray, min_len: float, penalty: float) -> np.ndarray:
    """Change points by binary segmentation with a length-weighted squared-error cost: split
    the segment whose best split lowers the cost most, while the gain exceeds ``penalty`` and
    both parts are at least ``min_len`` long.  Returns the first step of every segment.

    (Written here rather than taken from ``ruptures``: its L2 cost is unweighted — path steps
    are not all the same length at a record end — and this is 40 lines of numpy, O(n) per
    split with cumulative sums.)"""
    n = len(p)
    if n == 0:
        return np.zeros(0, np.int64)
    cw = np.concatenate([[0.0], np.cumsum(w)])
    cwp = np.concatenate([[0.0], np.cumsum(w * p)])
    cwp2 = np.concatenate([[0.0], np.cumsum(w * p * p)])

    def cost(a, b):  # over steps a..b-1, vectorised in b or a
        sw = cw[b] - cw[a]
        s1 = cwp[b] - cwp[a]
        s2 = cwp2[b] - cwp2[a]
        return s2 - np.divide(s1 * s1, sw, out=np.zeros_like(np.asarray(sw, float)), where=np.asarray(sw) > 0)

    def best(a, b):
        ks = np.arange(a + 1, b)
        if not len(ks):
            return None
        ok = ((cw[ks] - cw[a]) >= min_len) & ((cw[b] - cw[ks]) >= min_len)
        if not ok.any():
            return None
        gain = cost(a, b) - cost(a, ks) - cost(ks, b)
        gain = np.where(ok, gain, -np.inf)
        k = int(np.argmax(gain))
        return float(gain[k]), int(ks[k])

    import heapq

    starts = [0]
    heap = []
    found = best(0, n)
    if found:
        heapq.heappush(heap, (-found[0], 0, n, found[1]))
    while heap:
        g, a, b, k = heapq.heappop(heap)
        if -g <= penalty:
            break
        starts.append(k)
        for lo, hi in ((a, k), (k, b)):
            f = best(lo, hi)
            if f:
                heapq.heappush(heap, (-f[0], lo, hi, f[1]))
    return np.array(sorted(starts), np.int64)


@njit
def contour_samples(cmd, err, out):
    """Per sample, the part of the following error ``err`` normal to the commanded direction
    of travel (central differences of ``cmd``); 0 at the ends and where the command stands
    still — in one pass, for the hour-long traces the optimiser re-checks every round."""
    n = cmd.shape[0]
    out[0] = 0.0
    out[n - 1] = 0.0
    for i in range(1, n - 1):
        dx = cmd[i + 1, 0] - cmd[i - 1, 0]
        dy = cmd[i + 1, 1] - cmd[i - 1, 1]
        dz = cmd[i + 1, 2] - cmd[i - 1, 2]
        dn = math.sqrt(dx * dx + dy * dy + dz * dz)
        if dn <= 1e-9:
            out[i] = 0.0
            continue
        ux, uy, uz = dx / dn, dy / dn, dz / dn
        ex, ey, ez = err[i, 0], err[i, 1], err[i, 2]
        a = ex * ux + ey * uy + ez * uz
        nx, ny, nz = ex - a * ux, ey - a * uy, ez - a * uz
        out[i] = math.sqrt(nx * nx + ny * ny + nz * nz)


@njit
def _last_at_or_below(sorted_values, q, start):
    """The last index j with ``sorted_values[j] <= q`` (-1: none), searched forward from
    ``start`` when q has not gone back, by bisection when it has."""
    m = sorted_values.shape[0]
    j = start
    if j >= 0 and q < sorted_values[j]:
        a, b = 0, m
        while a < b:
            c = (a + b) // 2
            if sorted_values[c] <= q:
                a = c + 1
            else:
                b = c
        j = a - 1
    while j + 1 < m and sorted_values[j + 1] <= q:
        j += 1
    return j


@njit(python_limit=100_000, python_fast=20_000)
def samples_to_pieces(idx, valid, first, span, cn, ln, co, lo, key, order, piece_rec, piece_seg, seg_out, rec_out):
    """Segment and original record of every trace sample, by path length (see
    ``run._segment_of_samples``): sample i of new record r lies at ``cn[r] + (i - first[r]) /
    span[r] * ln[r]`` along the path; the original record holding that point is the last with
    ``co[j] <= s``, and its piece the last with ``key <= r_o * 4 + t``.  Samples come in time
    order, so both searches move forward; a step back falls back to bisection."""
    n = idx.shape[0]
    nlo = lo.shape[0]
    j = 0
    p = -1
    for i in range(n):
        if not valid[i]:
            seg_out[i] = -1
            rec_out[i] = -1
            continue
        r = idx[i]
        s = cn[r] + (i - first[r]) / span[r] * ln[r]
        j = max(_last_at_or_below(co, s, j), 0)
        ro = min(j, nlo - 1)
        t = (s - co[ro]) / lo[ro] if lo[ro] > 0.0 else 0.0
        p = _last_at_or_below(key, ro * 4.0 + t, p)
        rec_out[i] = ro
        if p >= 0 and piece_rec[order[p]] == ro:
            seg_out[i] = piece_seg[order[p]]
        else:
            seg_out[i] = -1
