"""Numba kernel of the servo-rate loop: profiler -> after-interpolation filter -> servo -> plant.

One pass over the samples ``t_k = k·dt``.  Each sample's command comes from the
closed-form profile of its segment (no integration, so no drift: the position at
``t`` depends only on ``t`` and the plan), goes through the per-axis acc/dec filter
after interpolation, then through the cascaded position-P / velocity-PI loop of
each axis into the feed-drive plant ``M·ẍ = F − F_friction(ẋ) − F_gravity − F_d``.
Statistics (peak following error, peak torque) are taken at the full rate; the
time series are stored every ``every``-th sample.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..jit import njit
from ..cutting._engagekernel import tooth_forces
from ..layout import (A_DIR, A_INTEG, A_POS, A_PREV_CMD, A_PREV_RAW, A_VEL, A_YEXP, C_AE, C_AP, C_HMAX, C_MRR,
                      C_POWER, C_SPEED, C_TORQUE, L_FIRST_MOVE, L_LAST_MOVE, L_SEG, L_STATUS, L_STEPS, L_STILL,
                      L_STOPPED, LOOP_FINISHED, LOOP_PUSHED, LOOP_RUNNING, LOOP_UNSETTLED, N_AXSTATE, N_CUT, N_LOOP,
                      P_A_DN, P_A_UP, P_CRUISE, P_TA_DN, P_TA_UP, P_TJ_DN, P_TJ_UP, P_VIN, P_VOUT, P_VPEAK)
from ..layout import (Q_AE, Q_AP, Q_AREA, Q_DX, Q_DY, Q_UH, Q_UZ, Q_WMAX, ST_TC, ST_TE, SX_AC, SX_AE, SX_RC, SX_RE,
                      SX_TC, SX_TE, SY_AC, SY_AE, SY_RC, SY_RE, SY_TC, SY_TE, SZ_AC, SZ_AE, SZ_RC, SZ_RE, T_FLUTES,
                      T_RADIUS)
from ._plankernel import ramp_eval

FILTER_NONE, FILTER_LINEAR, FILTER_BELL, FILTER_EXP = 0, 1, 2, 3

# servo parameter columns, per axis (mtwin.layout: effects write the table through them too)
from ..layout import (N_SV, SV_B, SV_FCN, SV_FCP, SV_FF, SV_FG, SV_FMAX, SV_FPT, SV_FSN, SV_FSP,  # noqa: E402,F401
                      SV_KPP, SV_MASS, SV_MP, SV_VS, SV_WI, SV_WV)
_V_STICK = 1e-9  # mm/s: below this an axis is at rest for the friction model


@njit
def segment_distance(prof, i, tau):
    """Distance along segment i and path speed, ``tau`` seconds after its start."""
    vin = prof[i, P_VIN]
    vp = prof[i, P_VPEAK]
    tju = prof[i, P_TJ_UP]
    tau_u = prof[i, P_TA_UP]
    t_up = 2.0 * tju + tau_u
    if tau <= t_up:
        return ramp_eval(vin, 1.0, tju, tau_u, prof[i, P_A_UP], tau)
    d_up = 0.5 * (vin + vp) * t_up
    tau -= t_up
    cruise = prof[i, P_CRUISE]
    if tau <= cruise:
        return d_up + vp * tau, vp
    tjd = prof[i, P_TJ_DN]
    tad = prof[i, P_TA_DN]
    t_dn = 2.0 * tjd + tad
    tau -= cruise
    if tau >= t_dn:
        return d_up + vp * cruise + 0.5 * (vp + prof[i, P_VOUT]) * t_dn, prof[i, P_VOUT]
    s, v = ramp_eval(vp, -1.0, tjd, tad, prof[i, P_A_DN], tau)
    return d_up + vp * cruise + s, v


@njit
def segment_point(kind, p0, p1, u, c, e1, e2, h, r0, r1, theta, length, i, s, out):
    """Point at distance s along segment i, written into out[0:3]; the end point exactly at s >= L."""
    if kind[i] == 2 or s >= length[i]:
        for k in range(3):
            out[k] = p1[i, k]
        return
    if s <= 0.0:
        for k in range(3):
            out[k] = p0[i, k]
        return
    if kind[i] == 0:
        f = s / length[i]
        for k in range(3):
            # interpolate between the exact end points: no accumulated rounding
            out[k] = p0[i, k] + (p1[i, k] - p0[i, k]) * f
        return
    f = s / length[i]
    a = theta[i] * f
    r = r0[i] + (r1[i] - r0[i]) * f
    ca = math.cos(a)
    sa = math.sin(a)
    for k in range(3):
        out[k] = c[i, k] + r * (ca * e1[i, k] + sa * e2[i, k]) + h[i, k] * f


class PathArrays(NamedTuple):
    """The plan's segments as the kernel reads them (``motion.path.SEG_DTYPE`` columns; ``line``
    the segment number, 1-based, that labels the samples)."""

    kind: np.ndarray
    p0: np.ndarray
    p1: np.ndarray
    u: np.ndarray
    c: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    h: np.ndarray
    r0: np.ndarray
    r1: np.ndarray
    theta: np.ndarray
    length: np.ndarray
    line: np.ndarray


class Profile(NamedTuple):
    """The timing of each segment: start time, S-curve phases, duration, exact stop."""

    t_start: np.ndarray
    prof: np.ndarray
    dur: np.ndarray
    stop_end: np.ndarray


class ServoInputs(NamedTuple):
    """The servo period, the trace's sampling, the after-interpolation filter, the in-position
    check, the per-axis servo table (``layout.SV_*`` columns) and an external disturbance."""

    dt: float
    every: int
    filt: int
    nfilt: int
    tfilt: float
    in_position: float
    max_wait: float
    sv: np.ndarray
    fd: np.ndarray


class LoopState(NamedTuple):
    """The loop's state between runs (a run can go in chunks): the filter's rings and sums,
    the axes' state (yexp, previous command, position, velocity, integrator, previous raw
    command, last feed direction), the segment counters, the interpolator clock, each
    segment's in-position wait, the peak following errors and torques."""

    ring1: np.ndarray
    ring2: np.ndarray
    sums: np.ndarray
    axes: np.ndarray
    seg: np.ndarray
    clock: np.ndarray
    wait: np.ndarray
    max_err: np.ndarray
    max_trq: np.ndarray


class CuttingInputs(NamedTuple):
    """The engagement of the path (steps per segment, force sums, step scalars ``layout.Q_*``),
    the tools (``layout.T_*`` columns), the material's coefficients and, when effects change
    them along the path, the coefficients per step ((steps, 6); (0, 6): the material's), the
    spindle (command, acceleration, losses, power curve) and, for tooth resolution, the edge
    profiles and slices."""

    first: np.ndarray
    count: np.ndarray
    sums: np.ndarray
    q: np.ndarray
    seg_tool: np.ndarray
    tools: np.ndarray
    kc: np.ndarray
    kpath: np.ndarray
    hand: np.ndarray
    spin_cmd: np.ndarray
    spin_acc: float
    loss: np.ndarray
    spin_curve: np.ndarray
    eprof: np.ndarray
    sl_starts: np.ndarray
    skind: np.ndarray
    skap: np.ndarray
    sr: np.ndarray
    szlo: np.ndarray
    szhi: np.ndarray
    sdrho: np.ndarray
    tan_helix: np.ndarray


class CutState(NamedTuple):
    """The spindle's state (speed rpm, angle rad) and the cut's running statistics (``CS_*``)."""

    spin: np.ndarray
    cstats: np.ndarray


class Outputs(NamedTuple):
    """The stored samples: time, segment number, commanded/actual positions, following error,
    velocity, motor torque, path speed, cutting force and the cut's channels (``C_*``)."""

    t: np.ndarray
    segno: np.ndarray
    cmd: np.ndarray
    act: np.ndarray
    err: np.ndarray
    vel: np.ndarray
    trq: np.ndarray
    pathv: np.ndarray
    force: np.ndarray
    cut: np.ndarray


def new_state(nbuf: int, x0: np.ndarray, sv: np.ndarray, nseg: int) -> LoopState:
    """The loop's state at the start point, the axes at rest."""
    ring1 = np.repeat(x0[None, :], nbuf, axis=0).astype(np.float64)
    sums = np.zeros((2, 3))
    sums[0] = x0 * nbuf
    sums[1] = x0 * nbuf
    axes = np.zeros((N_AXSTATE, 3))  # layout.A_*
    axes[A_YEXP] = x0
    axes[A_PREV_CMD] = x0
    axes[A_POS] = x0
    axes[A_PREV_RAW] = x0
    for k in range(3):
        # an axis holding a weight at the start already has it in its integrator
        gain = sv[k, SV_MASS] * sv[k, SV_WV] * sv[k, SV_WI] * 1e-3
        if gain > 0.0:
            axes[A_INTEG, k] = sv[k, SV_FG] / gain
    seg = np.zeros(N_LOOP, np.int64)  # layout.L_*
    seg[L_FIRST_MOVE] = seg[L_LAST_MOVE] = seg[L_STOPPED] = -1
    seg[L_STATUS] = LOOP_RUNNING
    return LoopState(ring1, ring1.copy(), sums, axes, seg, np.zeros(1), np.zeros(max(nseg, 1)), np.zeros(3),
                     np.zeros(3))


def bytes_per_sample() -> int:
    """Bytes a stored sample takes: the loop's outputs, widths as allocated, and the line and
    record (int32 each) a Trace keeps where the loop stores the segment number."""
    one = allocate_outputs(1)
    return sum(a.itemsize * a.size for a in one) - one.segno.itemsize + 2 * np.dtype(np.int32).itemsize


def allocate_outputs(n_out: int, cutting: bool = True) -> Outputs:
    # commanded positions stay float64 so that they can be differentiated (accelerations);
    # the other channels are stored as float32 (7 significant digits) to halve the memory
    return Outputs(np.empty(n_out), np.empty(n_out, np.int32), np.empty((n_out, 3)),
            np.empty((n_out, 3), np.float32), np.empty((n_out, 3), np.float32), np.empty((n_out, 3), np.float32),
            np.empty((n_out, 3), np.float32), np.empty(n_out, np.float32),
            np.zeros((n_out if cutting else 1, 3), np.float32), np.zeros((n_out if cutting else 1, N_CUT), np.float32))


# cut_out columns: layout.C_* (imported above)
# below 1 rpm the spindle counts as stopped: a chip per tooth of feed / (teeth x speed) would
# grow without bound as a spindle runs down
_N_STOPPED = 1.0 / 60.0  # rev/s

# cutting coefficients, in the order of cutting.library.Material (N/mm², N/mm)
K_TC, K_RC, K_AC, K_TE, K_RE, K_AE = range(6)

# cstats entries
CS_LOAD, CS_LOAD_LINE, CS_POWER, CS_POWER_LINE, CS_ENERGY, CS_CUT_TIME, CS_TORQUE, CS_TORQUE_LINE, \
    CS_SPINDLE_STOPPED_LINE, CS_MRR, CS_OVERLOAD_LINE, CS_SPINDLE_LOAD, CS_LOAD_TIME, CS_PUSHED_LINE = range(14)


@njit
def _friction(vk, sv, k):
    """Sliding friction of axis k at velocity vk (Coulomb + Stribeck + viscous), N; 0 while
    the axis sticks (|vk| below the stick velocity: the plant resolves that case itself)."""
    if abs(vk) < _V_STICK:
        return 0.0
    if vk > 0.0:
        fc, fs = sv[k, SV_FCP], sv[k, SV_FSP]
        sgn = 1.0
    else:
        fc, fs = sv[k, SV_FCN], sv[k, SV_FSN]
        sgn = -1.0
    r = vk / sv[k, SV_VS]
    # the Stribeck term has vanished (< 1e-16) beyond 6 Stribeck velocities
    strb = (fs - fc) * math.exp(-r * r) if abs(r) < 6.0 else 0.0
    return sgn * (fc + strb) + sv[k, SV_B] * vk * 1e-3


@njit
def run_twin(path, profile, servo, k0, k1, state, cut, cut_state, out):
    """Simulate servo periods k0 <= k < k1 (or until the program has ended and the axes are in
    position), continuing from the state arrays (updated in place).  Sample k is stored at
    index k // every when k is a multiple of ``every``; the last sample is always stored.

    Two clocks: wall time ``k·dt`` and the interpolator's time, which stands still at the end
    of an exact-stop segment until every axis is within ``in_position`` of the command (the
    in-position check of a real control; 0 disables it).  Returns the number of samples run.

    The inputs come in named groups (PathArrays, Profile, ServoInputs, LoopState,
    CuttingInputs, CutState, Outputs); the loop below reads them by the names they unpack to."""
    kind, p0, p1, u, c, e1, e2, h, r0, r1, theta, length, line = path
    t_start, prof, dur, stop_end = profile
    dt, every, filt, nfilt, tfilt, in_position, max_wait, sv, fd = servo
    ring1, ring2, sums, axes, segp, clock, wait, max_err, max_trq = state
    (eng_first, eng_count, eng_sums, eng_q, seg_tool, tools, kc, kpath, hand, spin_cmd, spin_acc, loss, spin_curve,
     eprof, sl_starts, skind, skap, sr, szlo, szhi, sdrho, tan_helix) = cut
    spin, cstats = cut_state
    t_out, line_out, cmd, act, err, vel, trq, pathv, force_out, cut_out = out
    nseg = len(kind)
    nbuf = ring1.shape[0]
    sum1 = sums[0]
    sum2 = sums[1]
    yexp = axes[A_YEXP]
    xc_prev = axes[A_PREV_CMD]
    x = axes[A_POS]
    v = axes[A_VEL]
    integ = axes[A_INTEG]
    cdir = axes[A_DIR]  # kept between periods: the feed direction while the command stands still
    edir = np.zeros(3)  # the engagement step's own feed direction
    rawprev = axes[A_PREV_RAW]
    # samples after which a standing command has passed through the filter completely
    settle = nbuf if filt == 1 else 2 * nbuf
    alpha = 1.0 - math.exp(-dt / tfilt) if tfilt > 0.0 else 1.0
    raw = np.empty(3)
    xc = np.empty(3)
    nfd = fd.shape[0]
    has_cut = eng_sums.shape[0] > 0
    tooth = eprof.shape[0] > 0
    ftool = np.zeros(3)
    tout = np.zeros(5)
    kk = np.zeros(6)  # the cutting coefficients at the current step
    fa = np.zeros(3)  # process force per mm of feed per tooth, N/mm
    fb = np.zeros(3)  # its edge (feed-independent) part, N
    fdrv = np.zeros(3)  # drive forces of this period, N
    nrps = 0.0
    fl = 1.0
    ta = 0.0
    tb = 0.0
    ha = 0.0
    m_ = 0
    t_end = t_start[nseg - 1] + dur[nseg - 1]
    i = segp[L_SEG]
    kstep = k0
    while kstep < k1:
        ti = clock[0]
        while i < nseg - 1 and ti > t_start[i] + dur[i]:
            i += 1
        tau = ti - t_start[i]
        if kind[i] == 2:
            s, vp = 0.0, 0.0
        else:
            s, vp = segment_distance(prof, i, tau)
        segment_point(kind, p0, p1, u, c, e1, e2, h, r0, r1, theta, length, i, s, raw)
        moved = False
        for k in range(3):
            if raw[k] != rawprev[k]:
                moved = True
            rawprev[k] = raw[k]
        segp[L_STILL] = 0 if moved else segp[L_STILL] + 1
        # ---- acc/dec after interpolation, per axis
        pos = kstep % nbuf
        if filt == 1 or filt == 2:
            for k in range(3):
                sum1[k] += raw[k] - ring1[pos, k]
                ring1[pos, k] = raw[k]
            if pos == nbuf - 1:  # re-sum once per window so rounding never accumulates
                for k in range(3):
                    acc = 0.0
                    for j in range(nbuf):
                        acc += ring1[j, k]
                    sum1[k] = acc
            for k in range(3):
                xc[k] = sum1[k] / nbuf
            if filt == 2:
                for k in range(3):
                    sum2[k] += xc[k] - ring2[pos, k]
                    ring2[pos, k] = xc[k]
                if pos == nbuf - 1:
                    for k in range(3):
                        acc = 0.0
                        for j in range(nbuf):
                            acc += ring2[j, k]
                        sum2[k] = acc
                for k in range(3):
                    xc[k] = sum2[k] / nbuf
        elif filt == 3:
            for k in range(3):
                yexp[k] += alpha * (raw[k] - yexp[k])
                xc[k] = yexp[k]
        else:
            for k in range(3):
                xc[k] = raw[k]
        # a command that has stood still long enough has left the filter exactly (a running
        # sum or an exponential never returns the input value to the last bit by itself)
        if filt != 0 and segp[L_STILL] >= settle:
            done = True
            if filt == 3:
                for k in range(3):
                    if abs(xc[k] - raw[k]) > 1e-9:
                        done = False
            if done:
                for k in range(3):
                    xc[k] = raw[k]
                    yexp[k] = raw[k]
        # ---- interpolator clock: advance, or stand at an exact stop until in position
        last = i == nseg - 1
        end_i = t_start[i] + dur[i]
        next_ti = ti + dt
        if stop_end[i] and segp[L_STOPPED] < i and ti + dt > end_i:
            if ti < end_i:
                # arrive exactly on the stop point next period; the rest of this one is idle
                next_ti = end_i
                wait[i] += dt - (end_i - ti)
            else:
                ok = True
                if in_position > 0.0:
                    for k in range(3):
                        if abs(raw[k] - x[k]) > in_position or xc[k] != raw[k]:
                            ok = False
                if ok:
                    segp[L_STOPPED] = i
                else:
                    next_ti = end_i
                    wait[i] += dt
                    if wait[i] > max_wait:
                        segp[L_STATUS] = LOOP_UNSETTLED  # reported by the caller
        finished = last and ti >= end_i and (segp[L_STOPPED] >= i or not stop_end[i])
        store = kstep % every == 0 or finished or segp[L_STATUS] >= LOOP_UNSETTLED
        o = (kstep + every - 1) // every if not kstep % every == 0 else kstep // every
        for k in range(3):
            if xc[k] != xc_prev[k]:
                if segp[L_FIRST_MOVE] < 0:
                    segp[L_FIRST_MOVE] = kstep
                segp[L_LAST_MOVE] = kstep
                break
        # ---- spindle and cutting load (forces act on the tool; the drives feel them)
        target = spin_cmd[i]
        dn = spin_acc * dt
        if spin[0] < target - dn:
            spin[0] += dn
        elif spin[0] > target + dn:
            spin[0] -= dn
        else:
            spin[0] = target
        # spindle angle, for tooth-passing forces
        spin[1] += 2.0 * math.pi * abs(spin[0]) / 60.0 * dt
        if spin[1] > 2.0 * math.pi:
            spin[1] -= 2.0 * math.pi * math.floor(spin[1] / (2.0 * math.pi))
        ftool[0] = 0.0
        ftool[1] = 0.0
        ftool[2] = 0.0
        torque_sp = 0.0
        p_cut = 0.0
        mrr = 0.0
        hmax = 0.0
        ae = 0.0
        ap = 0.0
        cutting = False
        if has_cut and eng_count[i] > 0 and kind[i] != 2:
            cnt = eng_count[i]
            mi = int(s / length[i] * cnt) if length[i] > 0.0 else 0
            if mi >= cnt:
                mi = cnt - 1
            m_ = eng_first[i] + mi
            nrps = abs(spin[0]) / 60.0
            fl = tools[seg_tool[i], T_FLUTES]
            S = eng_sums[m_]
            if eng_q[m_, Q_AREA] > 0.0 or S[ST_TE] > 0.0:
                cutting = True
                # The forces are linear in the feed per tooth: F = fz*fa + fb (tool frame
                # turned to the machine axes), torque = fz*ta + tb, h_max = fz*ha.
                if nrps < _N_STOPPED:
                    if cstats[CS_SPINDLE_STOPPED_LINE] == 0.0:  # cutting with the spindle stopped: no chip, no force
                        cstats[CS_SPINDLE_STOPPED_LINE] = line[i]  # (the first line where it happens)
                    for k in range(3):
                        fa[k] = 0.0
                        fb[k] = 0.0
                    ta = 0.0
                    tb = 0.0
                    ha = 0.0
                else:
                    # the coefficients at this step: the material's, or those the effects make
                    # of them along the path (tool wear: the edge ones grow with the wear land)
                    if kpath.shape[0] > 0:
                        for k in range(6):
                            kk[k] = kpath[m_, k]
                    else:
                        for k in range(6):
                            kk[k] = kc[k]
                    if tooth:
                        tt = seg_tool[i]
                        a0 = sl_starts[tt]
                        a1 = sl_starts[tt + 1]
                        tooth_forces(eprof[m_], eng_q[m_], spin[1], 0.0, fl, tools[tt, T_RADIUS], tan_helix[tt],
                                     skind[a0:a1], skap[a0:a1], sr[a0:a1], szlo[a0:a1], szhi[a0:a1], sdrho[a0:a1],
                                     eprof.shape[2], kk, tout)
                        bx, by, bz, tb = tout[0], tout[1], tout[2], tout[3] * 1e-3
                        tooth_forces(eprof[m_], eng_q[m_], spin[1], 1.0, fl, tools[tt, T_RADIUS], tan_helix[tt],
                                     skind[a0:a1], skap[a0:a1], sr[a0:a1], szlo[a0:a1], szhi[a0:a1], sdrho[a0:a1],
                                     eprof.shape[2], kk, tout)
                        ax_, ay_, az_, ta = tout[0] - bx, tout[1] - by, tout[2] - bz, tout[3] * 1e-3 - tb
                        ha = tout[4]
                    else:
                        ax_ = kk[K_TC] * S[SX_TC] + kk[K_RC] * S[SX_RC] + kk[K_AC] * S[SX_AC]
                        bx = kk[K_TE] * S[SX_TE] + kk[K_RE] * S[SX_RE] + kk[K_AE] * S[SX_AE]
                        ay_ = kk[K_TC] * S[SY_TC] + kk[K_RC] * S[SY_RC] + kk[K_AC] * S[SY_AC]
                        by = kk[K_TE] * S[SY_TE] + kk[K_RE] * S[SY_RE] + kk[K_AE] * S[SY_AE]
                        az_ = kk[K_RC] * S[SZ_RC] + kk[K_AC] * S[SZ_AC]
                        bz = kk[K_RE] * S[SZ_RE] + kk[K_AE] * S[SZ_AE]
                        ta = kk[K_TC] * S[ST_TC] * 1e-3  # N*m per mm of feed per tooth
                        tb = kk[K_TE] * S[ST_TE] * 1e-3
                        ha = eng_q[m_, Q_WMAX]
                    dxv = eng_q[m_, Q_DX]
                    dyv = eng_q[m_, Q_DY]
                    yxv = -dyv * hand[i]
                    yyv = dxv * hand[i]
                    fa[0] = ax_ * dxv + ay_ * yxv
                    fa[1] = ax_ * dyv + ay_ * yyv
                    fa[2] = az_
                    fb[0] = bx * dxv + by * yxv
                    fb[1] = bx * dyv + by * yyv
                    fb[2] = bz
                ae = eng_q[m_, Q_AE]
                ap = eng_q[m_, Q_AP]
        # ---- drive forces of the servo loop, per axis (they do not depend on the process)
        for k in range(3):
            m = sv[k, SV_MASS]
            e = xc[k] - x[k]
            vref = sv[k, SV_KPP] * e + sv[k, SV_FF] * (xc[k] - xc_prev[k]) / dt
            ev = vref - v[k]
            integ[k] += ev * dt
            f = m * sv[k, SV_WV] * (ev + sv[k, SV_WI] * integ[k]) * 1e-3  # N (mm/s^2 -> m/s^2)
            fmax = sv[k, SV_FMAX]
            if f > fmax or f < -fmax:
                f = fmax if f > 0.0 else -fmax
                if ev * f > 0.0:
                    integ[k] -= ev * dt  # anti-windup: no integration into the torque limit
            fdrv[k] = f
        if cutting:
            # The feed is the axes' velocity along the commanded direction at the end of this
            # period, solved for implicitly: the process force grows with the feed, and taken
            # from the velocity at the start of the period it over-corrects (and diverges)
            # once dt * dF/dv exceeds the axis mass (deep cuts at low spindle speed).  A tool
            # pushed back leaves the material instead of feeding harder into it.
            dcx = xc[0] - xc_prev[0]
            dcy = xc[1] - xc_prev[1]
            dcz = xc[2] - xc_prev[2]
            dn_ = math.sqrt(dcx * dcx + dcy * dcy + dcz * dcz)
            if dn_ > 0.0:
                cdir[0] = dcx / dn_
                cdir[1] = dcy / dn_
                cdir[2] = dcz / dn_
            # else: the command stands still (end of a move, in-position wait): the engagement
            # still belongs to the direction the tool was fed in, which cdir keeps; projecting
            # on the actual velocity instead made the normal force feed itself back
            # The chip is set by the feed along the direction the engagement step was computed
            # for (its feed direction); at a corner the after-interpolation filter still moves
            # the command along the previous move for a few periods, and projecting on that
            # blended direction fed the XY speed into a plunge's end-face engagement (2-4x
            # its torque).  In a straight cut the two directions are the same.
            euh = eng_q[m_, Q_UH]
            ed0 = eng_q[m_, Q_DX] * euh
            ed1 = eng_q[m_, Q_DY] * euh
            ed2 = eng_q[m_, Q_UZ]
            en = math.sqrt(ed0 * ed0 + ed1 * ed1 + ed2 * ed2)
            if en > 0.5:
                edir[0] = ed0 / en
                edir[1] = ed1 / en
                edir[2] = ed2 / en
            else:
                edir[0] = cdir[0]
                edir[1] = cdir[1]
                edir[2] = cdir[2]
            fz_ = 0.0
            if edir[0] * edir[0] + edir[1] * edir[1] + edir[2] * edir[2] > 0.0 and nrps >= _N_STOPPED:
                per = 1.0 / (fl * nrps)  # fz per mm/s of feed
                num = 0.0
                den = 1.0
                for k in range(3):
                    w = dt * 1e3 / sv[k, SV_MP]
                    ff = _friction(v[k], sv, k)
                    pk = v[k] + w * (fdrv[k] - sv[k, SV_FG] + fb[k] - ff - (fd[kstep, k] if kstep < nfd else 0.0))
                    num += edir[k] * pk
                    den -= edir[k] * w * fa[k] * per
                va = max(0.0, num / max(den, 1.0))
                fz_ = va * per
            else:
                va = 0.0
            for k in range(3):
                ftool[k] = fz_ * fa[k] + fb[k]
            # the engagement belongs to the commanded path: a tool pushed off it by more than
            # its radius is no longer in that cut, and the twin cannot say what it cuts
            # (sideways: lagging behind along the path is the drives' ordinary following error)
            dev2 = 0.0
            along = 0.0
            for k in range(3):
                dev2 += (xc[k] - x[k]) ** 2
                along += (xc[k] - x[k]) * cdir[k]
            rt = tools[seg_tool[i], T_RADIUS]
            if dev2 - along * along > rt * rt and (fz_ > 0.0 or fb[0] != 0.0 or fb[1] != 0.0):
                cstats[CS_PUSHED_LINE] = line[i]
                segp[L_STATUS] = LOOP_PUSHED  # reported by the caller
            torque_sp = fz_ * ta + tb
            p_cut = torque_sp * 2.0 * math.pi * nrps
            mrr = va * eng_q[m_, Q_AREA]
            hmax = fz_ * ha
        n_abs = abs(spin[0])
        p_sp = p_cut + (loss[0] + loss[1] * n_abs + loss[2] * n_abs * n_abs if n_abs > 0.0 else 0.0)
        load = math.sqrt(ftool[0] * ftool[0] + ftool[1] * ftool[1])
        if load > cstats[CS_LOAD] + 1e-9:
            cstats[CS_LOAD] = load
            cstats[CS_LOAD_LINE] = line[i]
        if p_sp > cstats[CS_POWER]:
            cstats[CS_POWER] = p_sp
            cstats[CS_POWER_LINE] = line[i]
        if p_cut > 0.0:
            cstats[CS_ENERGY] += p_cut * dt
            cstats[CS_CUT_TIME] += dt
            cstats[CS_LOAD_TIME] += load * dt
        if torque_sp > cstats[CS_TORQUE]:
            cstats[CS_TORQUE] = torque_sp
            cstats[CS_TORQUE_LINE] = line[i]
        if mrr > cstats[CS_MRR]:
            cstats[CS_MRR] = mrr
        if torque_sp > 0.0:
            # spindle curve: constant torque up to the base speed, constant power above it
            t_lim = spin_curve[0] / (2.0 * math.pi * max(n_abs, spin_curve[1]) / 60.0)
            ratio = torque_sp / t_lim
            if ratio > cstats[CS_SPINDLE_LOAD]:
                cstats[CS_SPINDLE_LOAD] = ratio
                if ratio > 1.0 and cstats[CS_OVERLOAD_LINE] == 0.0:
                    cstats[CS_OVERLOAD_LINE] = line[i]
        if store and has_cut:
            for k in range(3):
                force_out[o, k] = ftool[k]
            cut_out[o, C_SPEED] = spin[0]
            cut_out[o, C_TORQUE] = torque_sp
            cut_out[o, C_POWER] = p_sp
            cut_out[o, C_AE] = ae
            cut_out[o, C_AP] = ap
            cut_out[o, C_MRR] = mrr
            cut_out[o, C_HMAX] = hmax
        # ---- servo loop and feed-drive plant, per axis
        for k in range(3):
            m = sv[k, SV_MP]
            e = xc[k] - x[k]
            f = fdrv[k]
            fapp = f - sv[k, SV_FG]
            if kstep < nfd:
                fapp -= fd[kstep, k]
            # the force the process puts on the tool acts on the axis carrying it
            fapp += ftool[k]
            vk = v[k]
            if store:
                cmd[o, k] = xc[k]
                act[o, k] = x[k]
                err[o, k] = e
                vel[o, k] = vk
                trq[o, k] = f / sv[k, SV_FPT]
            if abs(vk) < _V_STICK:
                fs = sv[k, SV_FSP] if fapp > 0.0 else sv[k, SV_FSN]
                if abs(fapp) <= fs:
                    vnew = 0.0
                else:
                    sgn = 1.0 if fapp > 0.0 else -1.0
                    vnew = (fapp - sgn * fs) / m * 1e3 * dt
            else:
                vnew = vk + (fapp - _friction(vk, sv, k)) / m * 1e3 * dt
                if vnew * vk < 0.0:
                    # friction cannot reverse the motion: the axis stops (and sticks unless the
                    # drive force alone breaks it away next period)
                    vnew = 0.0
            x[k] += 0.5 * (vk + vnew) * dt
            v[k] = vnew
            ae = abs(e)
            if ae > max_err[k]:
                max_err[k] = ae
            tq = f / sv[k, SV_FPT]
            if abs(tq) > max_trq[k]:
                max_trq[k] = abs(tq)
            xc_prev[k] = xc[k]
        if store:
            t_out[o] = kstep * dt
            line_out[o] = line[i]
            pathv[o] = vp
        clock[0] = next_ti
        kstep += 1
        if finished or segp[L_STATUS] >= LOOP_UNSETTLED:
            segp[L_STATUS] = max(segp[L_STATUS], LOOP_FINISHED)
            break
    segp[L_SEG] = i
    segp[L_STEPS] = kstep
    return kstep


@njit
def error_stats(cmd, err, segno, seg_rapid, seg_pause, out_idx, out_val):
    """Following-error statistics over the stored samples, in one pass without temporaries.

    ``segno``: 1-based segment of each sample (0: none); per segment ``seg_rapid`` and
    ``seg_pause`` (0/1).  Fills, per axis k: ``out_idx[k]``/``out_val[k]`` the sample and
    value of the largest |error|, ``out_val[3 + k]`` the largest |error| in feed moves;
    ``out_idx[3]``/``out_val[6]`` the sample and value of the largest contour error (the
    error's part normal to the commanded direction of travel, central differences of the
    command) in feed moves."""
    n = cmd.shape[0]
    for k in range(3):
        out_idx[k] = 0
        out_val[k] = 0.0
        out_val[3 + k] = 0.0
    out_idx[3] = -1
    out_val[6] = 0.0
    for i in range(n):
        sg = segno[i]
        feed = sg > 0 and seg_rapid[sg - 1] == 0 and seg_pause[sg - 1] == 0
        for k in range(3):
            e = abs(err[i, k])
            if e > out_val[k]:
                out_val[k] = e
                out_idx[k] = i
            if feed and e > out_val[3 + k]:
                out_val[3 + k] = e
        if feed and 0 < i < n - 1:
            dx = cmd[i + 1, 0] - cmd[i - 1, 0]
            dy = cmd[i + 1, 1] - cmd[i - 1, 1]
            dz = cmd[i + 1, 2] - cmd[i - 1, 2]
            dn = math.sqrt(dx * dx + dy * dy + dz * dz)
            if dn > 1e-9:
                ux, uy, uz = dx / dn, dy / dn, dz / dn
                ex, ey, ez = err[i, 0], err[i, 1], err[i, 2]
                a = ex * ux + ey * uy + ez * uz
                nx, ny, nz = ex - a * ux, ey - a * uy, ez - a * uz
                c = math.sqrt(nx * nx + ny * ny + nz * nz)
                if c > out_val[6]:
                    out_val[6] = c
                    out_idx[3] = i
