"""Kernels of the chatter model: the zero-order approximation's limit per speed, the
semi-discretisation's Floquet multipliers, and the regenerative time-domain integration.

Conventions (docs/chatter.md): the tool frame has x along the feed and y to its left, φ the
tooth angle from +y, clockwise (the engagement's); a tooth at φ cuts the chip
h = f_z·sin φ + [sin φ, cos φ]·(u(t) − u(t − T)) and the force on the tool is
F = a·K_t·h·[−cos φ − K_r sin φ, sin φ − K_r cos φ].  Per unit depth the dynamic force is
a·H(t)·(u(t) − u(t − T)); its mean over a revolution is the directional matrix D.  Units SI.
"""
from __future__ import annotations

import math

import numpy as np

from ..jit import njit


@njit
def arc_integral(p0, p1, kr, out):
    """Adds ∫_{p0}^{p1} a(φ) dφ (the tool-frame directional matrix per unit K_t) to ``out``."""
    if p1 <= p0:
        return
    s0 = math.sin(p0)
    s1 = math.sin(p1)
    iss = 0.5 * (p1 - p0) - 0.25 * (math.sin(2.0 * p1) - math.sin(2.0 * p0))
    icc = 0.5 * (p1 - p0) + 0.25 * (math.sin(2.0 * p1) - math.sin(2.0 * p0))
    isc = 0.5 * (s1 * s1 - s0 * s0)
    out[0, 0] += -isc - kr * iss
    out[0, 1] += -icc - kr * isc
    out[1, 0] += iss - kr * isc
    out[1, 1] += isc - kr * icc


@njit
def _arc_in_window(a0, a1, pst, pex, kr, out):
    """Adds the integral over the part of the angle interval [a0, a1] (any real angles,
    a1 − a0 < 2π) that lies in the engaged arc [pst, pex] ⊂ [0, 2π)."""
    two_pi = 2.0 * math.pi
    k = math.floor(a0 / two_pi)
    b0 = a0 - k * two_pi
    b1 = a1 - k * two_pi
    for shift in (0.0, two_pi):
        lo = max(b0, pst + shift)
        hi = min(b1, pex + shift)
        if hi > lo:
            arc_integral(lo - shift, hi - shift, kr, out)


@njit
def frf_at(f, mfn, mz, mk, mdir, tf, txx, tyy):
    """Φxx, Φyy (m/N) at frequency f (Hz): the table (linear interpolation) when it has rows,
    else the modes' sum."""
    hx = 0.0 + 0.0j
    hy = 0.0 + 0.0j
    if tf.shape[0] > 0:
        if f < tf[0] or f > tf[-1]:
            return hx, hy
        j = np.searchsorted(tf, f) - 1
        if j < 0:
            j = 0
        if j > tf.shape[0] - 2:
            j = tf.shape[0] - 2
        a = (f - tf[j]) / (tf[j + 1] - tf[j])
        return txx[j] * (1.0 - a) + txx[j + 1] * a, tyy[j] * (1.0 - a) + tyy[j + 1] * a
    for i in range(mfn.shape[0]):
        r = f / mfn[i]
        h = 1.0 / (mk[i] * (1.0 - r * r + 2j * mz[i] * r))
        if mdir[i] == 0:
            hx += h
        else:
            hy += h
    return hx, hy


@njit
def _eig_mu(f, D, mfn, mz, mk, mdir, tf, txx, tyy, branch):
    """One eigenvalue (branch 0 or 1) of Φ(f)·D."""
    hx, hy = frf_at(f, mfn, mz, mk, mdir, tf, txx, tyy)
    m00 = hx * D[0, 0]
    m01 = hx * D[0, 1]
    m10 = hy * D[1, 0]
    m11 = hy * D[1, 1]
    tr = m00 + m11
    det = m00 * m11 - m01 * m10
    disc = np.sqrt(0.25 * tr * tr - det + 0.0j)
    return 0.5 * tr + disc if branch == 0 else 0.5 * tr - disc


@njit
def _g(f, T, D, mfn, mz, mk, mdir, tf, txx, tyy, branch):
    mu = _eig_mu(f, D, mfn, mz, mk, mdir, tf, txx, tyy, branch)
    w = 2.0 * math.pi * f * T
    c = complex(1.0 - math.cos(w), math.sin(w))  # 1 − e^{−iωT}
    return mu * c


@njit(python_limit=20_000, python_fast=2_000)
def zoa_limits(speeds, flutes, D, fgrid, mfn, mz, mk, mdir, tf, txx, tyy, depth, freq):
    """Zero-order approximation: per spindle speed (rpm) the smallest depth (m) at which
    det[I − a(1 − e^{−iωT})Φ(ω)D] = 0 has a real root a > 0, and its chatter frequency (Hz).
    For every eigenvalue μ(ω) of Φ·D the boundary is where μ·(1 − e^{−iωT}) is real and
    positive (a = 1/that); its sign changes are bracketed on ``fgrid`` (μ computed there once
    for all speeds) and refined by false position (Illinois) with the FRF evaluated exactly.
    inf where no frequency of the grid gives a boundary."""
    nf = fgrid.shape[0]
    MU = np.empty((2, nf), np.complex128)
    for br in range(2):
        for i in range(nf):
            MU[br, i] = _eig_mu(fgrid[i], D, mfn, mz, mk, mdir, tf, txx, tyy, br)
    C = np.empty(nf, np.complex128)
    for s in range(speeds.shape[0]):
        T = 60.0 / (flutes * speeds[s])
        best = np.inf
        bf = np.nan
        for i in range(nf):
            w = 2.0 * math.pi * fgrid[i] * T
            C[i] = complex(1.0 - math.cos(w), math.sin(w))  # 1 − e^{−iωT}, for both branches
        for br in range(2):
            g_prev = MU[br, 0] * C[0]
            for i in range(1, nf):
                g = MU[br, i] * C[i]
                if g.imag * g_prev.imag < 0.0 and (g.real > 0.0 or g_prev.real > 0.0):
                    # the interpolated root's depth: refine only a candidate for the minimum
                    t = g_prev.imag / (g_prev.imag - g.imag)
                    re = g_prev.real + t * (g.real - g_prev.real)
                    if re > 0.0 and 1.0 / re < 1.5 * best:
                        lo = fgrid[i - 1]
                        hi = fgrid[i]
                        ylo = g_prev.imag
                        yhi = g.imag
                        gm = g
                        mid = hi
                        side = 0
                        for _ in range(30):
                            mid = (lo * yhi - hi * ylo) / (yhi - ylo)
                            gm = _g(mid, T, D, mfn, mz, mk, mdir, tf, txx, tyy, br)
                            if abs(gm.imag) <= 1e-9 * abs(gm):
                                break
                            if gm.imag * ylo < 0.0:
                                hi = mid
                                yhi = gm.imag
                                if side == -1:
                                    ylo *= 0.5
                                side = -1
                            else:
                                lo = mid
                                ylo = gm.imag
                                if side == 1:
                                    yhi *= 0.5
                                side = 1
                        # a branch jump (the eigenvalues swapping) is no root: the residual stays large
                        if gm.real > 0.0 and abs(gm.imag) <= 1e-6 * abs(gm):
                            a = 1.0 / gm.real
                            if a < best:
                                best = a
                                bf = mid
                g_prev = g
        depth[s] = best
        freq[s] = bf


@njit
def _expm(A):
    """Matrix exponential by scaling and squaring with an order-16 Taylor series (the
    matrices here are small and their scaled norm ≤ 0.5: error below 1e-16)."""
    n = A.shape[0]
    nrm = 0.0
    for i in range(n):
        r = 0.0
        for j in range(n):
            r += abs(A[i, j])
        nrm = max(nrm, r)
    sq = 0
    if nrm > 0.5:
        sq = int(math.ceil(math.log2(nrm / 0.5)))
    X = A / (2.0 ** sq)
    E = np.eye(n)
    for k in range(16, 0, -1):
        E = np.eye(n) + (X @ E) / k
    for _ in range(sq):
        E = E @ E
    return E


#: the semi-discretisation's floor on its steps: per period of the fastest mode over the cut
#: window, and the most it takes (a 1 rpm speed would otherwise ask for thousands)
PER_PERIOD = 12
MAX_STEPS = 320


@njit
def _window_H(n_rpm, flutes, pst, pex, kt, kr, R, steps):
    """The cut window of one tooth period and the mean directional matrix (machine frame, per
    unit depth, N/m²) of each of its ``steps`` steps; returns (H (steps,2,2), dt, t_free)."""
    omega = 2.0 * math.pi * n_rpm / 60.0
    T = 60.0 / (flutes * n_rpm)
    pitch = 2.0 * math.pi / flutes
    arc = pex - pst
    if arc >= pitch:
        tc = T
    else:
        tc = arc / omega
    dt = tc / steps
    H = np.zeros((steps, 2, 2))
    tmp = np.zeros((2, 2))
    for i in range(steps):
        tmp[:, :] = 0.0
        a0 = pst + omega * dt * i
        a1 = pst + omega * dt * (i + 1)
        for j in range(flutes):
            _arc_in_window(a0 + j * pitch, a1 + j * pitch, pst, pex, kr, tmp)
        scale = kt / (omega * dt)  # mean over the step's time
        Ht = tmp * scale
        H[i] = R @ Ht @ R.T
    return H, dt, T - tc


@njit
def _monodromy_radius(s, H, dt, mfn, mz, mk, mloc, act, Pfree):
    """Spectral radius and dominant multiplier of the semi-discretised one-period map at
    depth s (m).  Only the machine directions that have modes (``act``; ``mloc``: each mode's
    index in it) carry a delayed displacement: the state is the modes' (q, q̇) and the
    previous period's displacement at the steps' ends."""
    nm = mfn.shape[0]
    nd = act.shape[0]
    n = 2 * nm
    steps = H.shape[0]
    dim = n + nd * (steps + 1)
    E = np.zeros((nd, nm))
    minv = np.zeros(nm)
    A0 = np.zeros((n, n))
    for j in range(nm):
        E[mloc[j], j] = 1.0
        w = 2.0 * math.pi * mfn[j]
        minv[j] = w * w / mk[j]
        A0[j, nm + j] = 1.0
        A0[nm + j, j] = -w * w
        A0[nm + j, nm + j] = -2.0 * mz[j] * w
    Y = np.zeros((n, dim))
    for i in range(n):
        Y[i, i] = 1.0
    Phi = np.zeros((dim, dim))
    aug = np.zeros((n + 2 * nd, n + 2 * nd))
    K = np.zeros((nd, nd))
    for i in range(steps):
        # u_i = E q_i: this period's displacement at the step's start
        for r in range(nd):
            for j in range(nm):
                if mloc[j] == r:
                    for c in range(dim):
                        Phi[n + nd * i + r, c] += Y[j, c]
        for a in range(nd):
            for b in range(nd):
                K[a, b] = H[i, act[a], act[b]]
        aug[:, :] = 0.0
        aug[:n, :n] = A0 * dt
        for a in range(nm):
            for b in range(nm):
                aug[nm + a, b] += s * minv[a] * K[mloc[a], mloc[b]] * dt
            for b in range(nd):
                aug[nm + a, n + b] = -s * minv[a] * K[mloc[a], b] * dt
        for b in range(nd):
            aug[n + b, n + nd + b] = 1.0
        Ex = _expm(aug)
        P = np.ascontiguousarray(Ex[:n, :n])
        Yn = P @ Y
        for r in range(n):
            for c in range(nd):
                ga = Ex[r, n + c]
                gb = Ex[r, n + nd + c]
                Yn[r, n + nd * i + c] += ga - gb
                Yn[r, n + nd * (i + 1) + c] += gb
        Y = Yn
    for r in range(nd):
        for j in range(nm):
            if mloc[j] == r:
                for c in range(dim):
                    Phi[n + nd * steps + r, c] += Y[j, c]
    Phi[:n, :] = Pfree @ Y
    ev = np.linalg.eigvals(Phi.astype(np.complex128))
    k = 0
    for i in range(ev.shape[0]):
        if abs(ev[i]) > abs(ev[k]):
            k = i
    return abs(ev[k]), ev[k]


@njit(python_limit=0)
def sdm_limits(speeds, flutes, pst, pex, kt, kr, R, mfn, mz, mk, mdir, steps, s_hi, scan, iters,
               depth, flip, mult):
    """Semi-discretisation (first order: the periodic coefficients averaged over each step, the
    delayed displacement interpolated linearly, the free flight integrated exactly): per speed
    the smallest depth (m) whose one-period map has a multiplier outside the unit circle —
    ``scan`` depths up to ``s_hi[s]`` (then up to 4× it), then ``iters`` bisections in the
    first unstable bracket; ``flip`` where the critical multiplier is real negative (period
    doubling); ``mult`` its argument (rad).  inf where every scanned depth is stable."""
    nm = mfn.shape[0]
    n = 2 * nm
    used = np.zeros(2, np.bool_)
    for j in range(nm):
        used[mdir[j]] = True
    nd = int(used[0]) + int(used[1])
    act = np.empty(nd, np.int64)
    k = 0
    for d in range(2):
        if used[d]:
            act[k] = d
            k += 1
    mloc = np.empty(nm, np.int64)
    for j in range(nm):
        mloc[j] = 0 if (nd == 1 or mdir[j] == 0) else 1
    A0 = np.zeros((n, n))
    for j in range(nm):
        w = 2.0 * math.pi * mfn[j]
        A0[j, nm + j] = 1.0
        A0[nm + j, j] = -w * w
        A0[nm + j, nm + j] = -2.0 * mz[j] * w
    fmax = 0.0
    for j in range(nm):
        fmax = max(fmax, mfn[j])
    for si in range(speeds.shape[0]):
        # at least PER_PERIOD steps per period of the fastest mode over the cut window (a
        # window of many vibration periods — low speeds — needs more than ``steps``)
        omega = 2.0 * math.pi * speeds[si] / 60.0
        tc = min(pex - pst, 2.0 * math.pi / flutes) / omega
        st = min(max(steps, int(math.ceil(PER_PERIOD * fmax * tc))), MAX_STEPS)
        H, dt, tfree = _window_H(speeds[si], flutes, pst, pex, kt, kr, R, st)
        Pfree = _expm(A0 * tfree) if tfree > 0.0 else np.eye(n)
        lo = 0.0
        hi = -1.0
        top = s_hi[si]
        for rnd in range(2):
            base = lo
            for kk in range(1, scan + 1):
                a = base + (top - base) * kk / scan
                rad, _ = _monodromy_radius(a, H, dt, mfn, mz, mk, mloc, act, Pfree)
                if rad > 1.0:
                    hi = a
                    break
                lo = a
            if hi > 0.0:
                break
            top = 4.0 * top
        if hi < 0.0:
            depth[si] = np.inf
            flip[si] = False
            mult[si] = np.nan
            continue
        for _ in range(iters):
            mid = 0.5 * (lo + hi)
            rad, _ = _monodromy_radius(mid, H, dt, mfn, mz, mk, mloc, act, Pfree)
            if rad > 1.0:
                hi = mid
            else:
                lo = mid
        rad, ev = _monodromy_radius(hi, H, dt, mfn, mz, mk, mloc, act, Pfree)
        depth[si] = 0.5 * (lo + hi)
        ang = math.atan2(ev.imag, ev.real)
        mult[si] = ang
        flip[si] = abs(abs(ang) - math.pi) < 1e-3


@njit
def _modal_zoh(mfn, mz, mk, dt, Ad, Bd):
    for j in range(mfn.shape[0]):
        w = 2.0 * math.pi * mfn[j]
        A = np.zeros((3, 3))
        A[0, 1] = 1.0
        A[1, 0] = -w * w
        A[1, 1] = -2.0 * mz[j] * w
        A[1, 2] = w * w / mk[j]
        Ex = _expm(A * dt)
        Ad[j, 0, 0] = Ex[0, 0]
        Ad[j, 0, 1] = Ex[0, 1]
        Ad[j, 1, 0] = Ex[1, 0]
        Ad[j, 1, 1] = Ex[1, 1]
        Bd[j, 0] = Ex[0, 2]
        Bd[j, 1] = Ex[1, 2]


@njit(python_limit=0)
def regen_trace(dt, rpm, fz, ap, pst, pex, fang, hand, active, flutes, kt, kr, mfn, mz, mk, mdir, m, cap,
                ux, uy, amp, sub_x, sub_y, sub_first):
    """The regenerative model along a trace: per sample k (duration ``dt[k]`` s, speed
    ``rpm[k]``, feed per tooth ``fz[k]`` and depth ``ap[k]`` (m), arc [pst, pex], feed angle
    ``fang`` (rad), spindle hand, ``active`` where this tool cuts) the tool tip's modes are
    integrated in the angle domain, ``m`` sub-steps per tooth pitch (the delay is exactly one
    pitch at any speed): exact zero-order hold per sub-step, the force at the sub-step's
    middle.  The surface is kept per angle bin of the tool frame (N·m bins): a tooth at bin b
    cuts h = f_z sin φ + (its radial displacement − the surface there); where h > 0 the surface
    becomes where the tooth is, where h ≤ 0 the tooth is out of the cut and the uncut chip
    carries over to the next tooth (the surface stays, one feed further away) — the
    nonlinearity that bounds chatter.  Writes the displacement (m) at each sample's end
    (``ux``, ``uy``), the RMS over the sample of u(t) − u(t − T) (``amp``, the regenerative
    part: it decays in a stable cut), and the first ``cap`` sub-steps' displacement
    (``sub_x``, ``sub_y``; ``sub_first[k]`` the first of sample k, −1 past cap)."""
    nm = mfn.shape[0]
    pitch = 2.0 * math.pi / flutes
    dth = pitch / m
    nb = m * flutes
    Ad = np.zeros((nm, 2, 2))
    Bd = np.zeros((nm, 2))
    q = np.zeros((nm, 2))
    hist = np.zeros((m + 1, 2))
    surf = np.zeros(nb)
    ib = 0  # bin of tooth 0
    n_prev = -1.0
    dts = 0.0
    carry = 0.0  # fraction of a sub-step left from the last sample
    i_sub = 0
    for k in range(dt.shape[0]):
        sub_first[k] = i_sub if i_sub < cap else -1
        n = rpm[k]
        if n <= 0.0:
            ux[k] = 0.0
            uy[k] = 0.0
            amp[k] = 0.0
            continue
        omega = 2.0 * math.pi * n / 60.0
        if abs(n - n_prev) > 1e-9 * n:
            dts = dth / omega
            _modal_zoh(mfn, mz, mk, dts, Ad, Bd)
            n_prev = n
        want = dt[k] / dts + carry
        count = int(want)
        carry = want - count
        c = math.cos(fang[k])
        s = math.sin(fang[k])
        r00 = c
        r01 = -s * hand[k]
        r10 = s
        r11 = c * hand[k]
        acc = 0.0
        n_acc = 0
        for _ in range(count):
            ucx = 0.0
            ucy = 0.0
            umx = 0.0
            umy = 0.0
            for j in range(nm):
                if mdir[j] == 0:
                    ucx += q[j, 0]
                    umx += q[j, 0] + 0.5 * dts * q[j, 1]
                else:
                    ucy += q[j, 0]
                    umy += q[j, 0] + 0.5 * dts * q[j, 1]
            ring = i_sub % (m + 1)
            hist[ring, 0] = ucx
            hist[ring, 1] = ucy
            if i_sub >= m:
                a0 = hist[(i_sub - m) % (m + 1)]
                ex = ucx - a0[0]
                ey = ucy - a0[1]
                acc += ex * ex + ey * ey
                n_acc += 1
            fx = 0.0
            fy = 0.0
            # the tip's displacement in the tool frame (x along the feed, y to its left)
            dtx = r00 * umx + r10 * umy
            dty = r01 * umx + r11 * umy
            ftx = 0.0
            fty = 0.0
            for z in range(flutes):
                b = (ib + z * m) % nb
                phi = (b + 0.5) * dth
                if not active[k] or phi < pst[k] or phi > pex[k]:
                    surf[b] = 0.0  # no material here: no memory
                    continue
                sp = math.sin(phi)
                cp = math.cos(phi)
                radial = sp * dtx + cp * dty
                h = fz[k] * sp + radial - surf[b]
                if h <= 0.0:
                    surf[b] -= fz[k] * sp  # out of the cut: the next tooth meets this chip too
                    continue
                surf[b] = radial
                ft = kt * ap[k] * h
                ftx += -ft * cp - kr * ft * sp
                fty += ft * sp - kr * ft * cp
            fx = r00 * ftx + r01 * fty
            fy = r10 * ftx + r11 * fty
            for j in range(nm):
                fj = fx if mdir[j] == 0 else fy
                q0 = Ad[j, 0, 0] * q[j, 0] + Ad[j, 0, 1] * q[j, 1] + Bd[j, 0] * fj
                q1 = Ad[j, 1, 0] * q[j, 0] + Ad[j, 1, 1] * q[j, 1] + Bd[j, 1] * fj
                q[j, 0] = q0
                q[j, 1] = q1
            if i_sub < cap:
                sub_x[i_sub] = ucx
                sub_y[i_sub] = ucy
            i_sub += 1
            ib = (ib + 1) % nb
        x = 0.0
        y = 0.0
        for j in range(nm):
            if mdir[j] == 0:
                x += q[j, 0]
            else:
                y += q[j, 0]
        ux[k] = x
        uy[k] = y
        amp[k] = math.sqrt(acc / n_acc) if n_acc > 0 else 0.0
    return i_sub
