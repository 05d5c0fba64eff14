"""Numba kernels of the NCK: blend arcs, corner speeds, look-ahead passes, S-curve timing.

Velocity changes are jerk-limited ramps ("S-curves") with acceleration ``a`` and
jerk ``a/tb`` (``tb`` = bell time constant; ``tb = 0`` gives the trapezoid of a
linear acc/dec).  A ramp by ``dv`` takes ``dv/a + tb`` when ``dv >= a·tb`` and
``2·sqrt(dv·tb/a)`` otherwise, and, being point-symmetric, covers the mean of its
end speeds times its duration.  The look-ahead passes use the closed-form bound
``D(v0, v1) = |v1² − v0²|/(2a) + (v0 + v1)·tb/2`` (never less than the true ramp
distance), so a speed they allow is always reachable by the executed profile.
"""
from __future__ import annotations

import math

import numpy as np

from ..jit import njit
from ..layout import (N_PROF, P_A_DN, P_A_UP, P_CRUISE, P_TA_DN, P_TA_UP, P_TJ_DN, P_TJ_UP, P_VIN, P_VOUT,
                      P_VPEAK)

# segments up to which the planner's kernels run as Python rather than loading (or compiling)
# their compiled code: ~1,000 segments take ~0.1 s in Python
PY_FAST, PY_LIMIT = 1_500, 20_000

STYLE_FANUC, STYLE_LINUXCNC, STYLE_GRBL = 0, 1, 2
_TANGENT_COS = 1.0 - 1e-12  # direction change below ~1.4 µrad counts as tangent

# LinuxCNC 2.9 blend constants (blendmath.h / tc_types.h / tc.c)
_ACC_RATIO_TAN = 0.5
_ACC_RATIO_NORMAL = math.sqrt(1.0 - 0.25)
_BLEND_DIST_FRACTION = 0.5
_TOL_RATIO = 0.25


@njit
def reach_speed(v0, length, a, tb):
    """Highest speed reachable from v0 over ``length`` (or, backwards, the highest entry speed
    that can still slow to v0): the root of D(v0, v1) = length."""
    if length <= 0.0:
        return v0
    b = a * tb
    disc = b * b + 4.0 * (v0 * v0 - b * v0 + 2.0 * a * length)
    if disc < 0.0:
        disc = 0.0
    v1 = 0.5 * (-b + math.sqrt(disc))
    return max(v1, v0)


@njit
def ramp_shape(dv, a, tb):
    """(tj, ta, peak accel) of an S-curve ramp by |dv|: jerk phases tj, constant phase ta."""
    if dv <= 0.0:
        return 0.0, 0.0, 0.0
    if tb <= 0.0:
        return 0.0, dv / a, a
    if dv >= a * tb:
        return tb, dv / a - tb, a
    tj = math.sqrt(dv * tb / a)
    return tj, 0.0, a * tj / tb


@njit
def ramp_distance(v0, v1, a, tb):
    tj, ta, _ = ramp_shape(abs(v1 - v0), a, tb)
    return 0.5 * (v0 + v1) * (2.0 * tj + ta)


@njit
def ramp_eval(v0, sgn, tj, ta, apk, tau):
    """Distance and speed ``tau`` seconds into a ramp starting at v0 (sgn +1 up, -1 down)."""
    if tj <= 0.0:  # trapezoid: constant acceleration
        return v0 * tau + 0.5 * sgn * apk * tau * tau, v0 + sgn * apk * tau
    j = sgn * apk / tj
    if tau <= tj:
        return v0 * tau + j * tau ** 3 / 6.0, v0 + 0.5 * j * tau * tau
    s1 = v0 * tj + j * tj ** 3 / 6.0
    v1 = v0 + 0.5 * j * tj * tj
    A = sgn * apk
    u = tau - tj
    if u <= ta:
        return s1 + v1 * u + 0.5 * A * u * u, v1 + A * u
    s2 = s1 + v1 * ta + 0.5 * A * ta * ta
    v2 = v1 + A * ta
    w = min(u - ta, tj)
    return s2 + v2 * w + 0.5 * A * w * w - j * w ** 3 / 6.0, v2 + A * w - 0.5 * j * w * w


@njit(python_limit=PY_LIMIT, python_fast=PY_FAST)
def corner_limits(style, u_end, u_start, is_pause, rapid, path_mode, kind, tol, vmax, amax_axis,
                  corner_v, jd, after_time, exact_stop_rapids):
    """Speed limit at the end of each segment (its junction with the next one), mm/s.

    Zero means an exact stop: end of program, pauses, G61.1/G9, G61 corners,
    rapid/feed changes, rapids with an in-position check.  ``amax_axis`` holds the
    per-axis acceleration limits (for Grbl's junction deviation)."""
    n = len(vmax)
    vj = np.zeros(n)
    for i in range(n - 1):
        if is_pause[i] or is_pause[i + 1]:
            continue
        if path_mode[i] == 2:  # exact stop (G61.1 / G9)
            continue
        if rapid[i] != rapid[i + 1] and style != STYLE_GRBL:
            continue
        if rapid[i] and exact_stop_rapids:
            continue
        v = min(vmax[i], vmax[i + 1])
        c = 0.0
        for k in range(3):
            c += u_end[i, k] * u_start[i + 1, k]
        if c >= _TANGENT_COS:
            vj[i] = v
            continue
        if path_mode[i] == 1:  # G61 exact path: stop at every corner
            continue
        if style == STYLE_FANUC:
            # allowable velocity change per axis: v * |du_k| <= corner_v for every axis
            dmax = 0.0
            for k in range(3):
                dmax = max(dmax, abs(u_start[i + 1, k] - u_end[i, k]))
            v = min(v, corner_v / dmax)
            if tol[i] > 0.0 and after_time > 0.0:
                # a moving-average filter of length T rounds a corner of turning angle phi by
                # at most v*T/4*sin(phi/2) (distance of the filtered point from the corner)
                s_half = math.sqrt(max(0.0, 0.5 * (1.0 - c)))
                if s_half > 0.0:
                    v = min(v, 4.0 * tol[i] / (after_time * s_half))
        elif style == STYLE_GRBL:
            # junction deviation: v^2 = a * delta * sin(theta/2) / (1 - sin(theta/2)),
            # theta the angle between the two moves (cos theta = -u1.u2)
            s_half = math.sqrt(max(0.0, 0.5 * (1.0 + c)))
            acc = 1e300
            dn = 0.0
            for k in range(3):
                dn += (u_start[i + 1, k] - u_end[i, k]) ** 2
            dn = math.sqrt(dn)
            for k in range(3):
                comp = abs(u_start[i + 1, k] - u_end[i, k]) / dn
                if comp > 1e-12:
                    acc = min(acc, amax_axis[k] / comp)
            if s_half < 1.0 - 1e-9:
                v = min(v, math.sqrt(acc * jd * s_half / (1.0 - s_half)))
        else:
            # LinuxCNC: line-line corners were replaced by blend arcs before this point;
            # a corner left here (arc involved, or blend impossible) is an exact stop.
            continue
        vj[i] = v
    return vj


@njit(python_limit=PY_LIMIT, python_fast=PY_FAST)
def lookahead(vj, length, acc, tb, window):
    """Junction speeds after the look-ahead passes (backward over ``window`` blocks, ending in
    a stop at the window's end, as a control that sees only that many blocks must; forward
    from rest)."""
    n = len(vj)
    ve = np.empty(n)
    for i in range(n):
        last = min(i + window, n - 1)
        v = 0.0 if last < n - 1 else vj[n - 1]
        for j in range(last, i, -1):
            v = min(reach_speed(v, length[j], acc[j], tb), vj[j - 1])
        ve[i] = min(v, vj[i])
    vs = 0.0
    for i in range(n):
        v = min(ve[i], reach_speed(vs, length[i], acc[i], tb))
        ve[i] = v
        vs = v
    return ve


@njit(python_limit=PY_LIMIT, python_fast=PY_FAST)
def segment_timing(length, vmax, acc, tb, ve, hold, duration):
    """Per segment: start speed, peak speed, end speed, ramp shapes and phase times.

    Returns an (n, N_PROF) array (``layout.P_*``: v_in, v_peak, v_out, tj_up, ta_up, a_up,
    t_cruise, tj_dn, ta_dn, a_dn) and an (n,) array of segment durations (motion + hold, or the
    pause time)."""
    n = len(length)
    prof = np.zeros((n, N_PROF))
    dur = np.zeros(n)
    vin = 0.0
    for i in range(n):
        L = length[i]
        if duration[i] > 0.0 or L <= 0.0:
            prof[i, P_VIN] = vin
            prof[i, P_VOUT] = vin
            dur[i] = duration[i] + hold[i]
            continue
        vout = ve[i]
        a = acc[i]
        lo = max(vin, vout)
        hi = max(vmax[i], lo)
        if ramp_distance(vin, hi, a, tb) + ramp_distance(hi, vout, a, tb) <= L:
            vp = hi
        else:
            for _ in range(60):
                mid = 0.5 * (lo + hi)
                if ramp_distance(vin, mid, a, tb) + ramp_distance(mid, vout, a, tb) <= L:
                    lo = mid
                else:
                    hi = mid
            vp = lo
        tju, tau, au = ramp_shape(vp - vin, a, tb)
        tjd, tad, ad = ramp_shape(vp - vout, a, tb)
        d_up = 0.5 * (vin + vp) * (2 * tju + tau)
        d_dn = 0.5 * (vp + vout) * (2 * tjd + tad)
        cruise = max(0.0, L - d_up - d_dn) / vp if vp > 0.0 else 0.0
        prof[i, P_VIN] = vin
        prof[i, P_VPEAK] = vp
        prof[i, P_VOUT] = vout
        prof[i, P_TJ_UP] = tju
        prof[i, P_TA_UP] = tau
        prof[i, P_A_UP] = au
        prof[i, P_CRUISE] = cruise
        prof[i, P_TJ_DN] = tjd
        prof[i, P_TA_DN] = tad
        prof[i, P_A_DN] = ad
        dur[i] = 2 * tju + tau + cruise + 2 * tjd + tad + hold[i]
        vin = vout
    return prof, dur


@njit
def _norm3(v):
    return math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


@njit(python_limit=PY_LIMIT, python_fast=PY_FAST)
def linuxcnc_blends(kind, rapid, path_mode, skip, tol, p0, p1, u, length, vmax, feed, acc_axis, vel_axis):
    """Replace line-line corners by tangent blend arcs, as LinuxCNC 2.9's planner does
    at the corners not marked in ``skip`` (blendmath.c: tolerance from G64 P, or a quarter of
    the shorter line when P is 0;
    at most half of each line; radius from v_plan = sqrt(a_n·R) and the parabolic-equivalent
    length).  Returns per corner i (between segment i and i+1): trim (mm cut from the end of
    i and the start of i+1), blend radius, blend speed, turning angle and the plane's
    acceleration limit; trim 0 where no blend is made."""
    n = len(kind)
    trim = np.zeros(n)
    radius = np.zeros(n)
    vplan = np.zeros(n)
    phi_out = np.zeros(n)
    aplane = np.zeros(n)
    remaining = length.copy()  # LinuxCNC's tc->target after earlier trims
    for i in range(n - 1):
        if kind[i] != 0 or kind[i + 1] != 0 or skip[i]:
            continue
        if path_mode[i] != 0 or rapid[i] != rapid[i + 1]:
            continue
        if length[i] <= 0.0 or length[i + 1] <= 0.0:
            continue
        c = u[i, 0] * u[i + 1, 0] + u[i, 1] * u[i + 1, 1] + u[i, 2] * u[i + 1, 2]
        if c >= _TANGENT_COS:
            continue
        # theta: half of the angle between the two lines at the corner
        theta = 0.5 * math.acos(max(-1.0, min(1.0, -c)))
        if theta < 1e-6 or math.pi / 2 - theta < 1e-6:
            continue
        phi = math.pi - 2.0 * theta
        # binormal of the corner's plane and the acceleration limit in that plane
        b = np.empty(3)
        b[0] = u[i, 1] * u[i + 1, 2] - u[i, 2] * u[i + 1, 1]
        b[1] = u[i, 2] * u[i + 1, 0] - u[i, 0] * u[i + 1, 2]
        b[2] = u[i, 0] * u[i + 1, 1] - u[i, 1] * u[i + 1, 0]
        bn = _norm3(b)
        a_max = 1e300
        v_planar = 1e300
        for k in range(3):
            s = math.sqrt(max(0.0, 1.0 - (b[k] / bn) ** 2))
            if s > 1e-12:
                a_max = min(a_max, acc_axis[k] / s)
                v_planar = min(v_planar, vel_axis[k] / s)
        a_n = a_max * _ACC_RATIO_NORMAL
        t1 = tol[i] if tol[i] > 0.0 else length[i] * _TOL_RATIO
        t2 = tol[i + 1] if tol[i + 1] > 0.0 else length[i + 1] * _TOL_RATIO
        tolerance = min(min(t1, t2), min(length[i], length[i + 1]) * _TOL_RATIO)
        L1 = min(remaining[i], length[i] * _BLEND_DIST_FRACTION)
        L2 = remaining[i + 1] * _BLEND_DIST_FRACTION
        v_req1 = min(feed[i], vmax[i]) if feed[i] > 0.0 else vmax[i]
        v_req2 = min(feed[i + 1], vmax[i + 1]) if feed[i + 1] > 0.0 else vmax[i + 1]
        v_goal = min(max(v_req1, v_req2), v_planar)
        h_tol = tolerance / (1.0 - math.sin(theta))
        d_tol = math.cos(theta) * h_tol
        d_geom = min(min(L1, L2), d_tol)
        r_geom = math.tan(theta) * d_geom
        v_plan = min(math.sqrt(a_n * r_geom), v_goal)
        a_par = 0.5 * a_max
        v_tri = math.sqrt(2.0 * a_par * d_geom)
        t_blend = min(v_tri, v_plan) / a_par
        r_blend = min(t_blend * v_plan / phi, r_geom)
        r_acc = v_plan * v_plan / a_n
        r_plan = max(r_acc, r_blend)
        d_plan = r_plan / math.tan(theta)
        if r_plan < 1e-12 or r_plan * phi < 1e-6 or d_plan > remaining[i] + 1e-12 \
                or d_plan > remaining[i + 1] + 1e-12:
            continue
        trim[i] = d_plan
        radius[i] = r_plan
        vplan[i] = min(v_plan, max(v_req1, v_req2))
        phi_out[i] = phi
        aplane[i] = a_max
        remaining[i] -= d_plan
        remaining[i + 1] -= d_plan
    return trim, radius, vplan, phi_out, aplane


# LinuxCNC junction classes (term conditions)
J_STOP, J_TANGENT, J_BLEND, J_PARABOLIC = 0, 1, 2, 3
_SHARP_CORNER_COS = math.cos(math.pi * (1.0 - 2.0 / 180.0))  # reversal within 2 degrees
_KINK_RATIO = 0.1  # [TRAJ] ARC_BLEND_KINK_RATIO default


@njit(python_limit=PY_LIMIT, python_fast=PY_FAST)
def linuxcnc_classify(kind, rapid, path_mode, is_pause, u_end, u_start, vmax, feed, acc_axis, dt):
    """Term condition of every junction as LinuxCNC 2.9 sets it (tp.c tpSetupTangent,
    tpHandleBlendArc, tpCheckCanonType), and the acceleration factor of each segment.

    Returns (jclass, afac_end, afac_start): the class of the junction after segment i, the
    factor on segment i's acceleration from that junction (kinks, parabolic blends) and the
    factor on segment i+1's acceleration from it (``blend_prev``)."""
    n = len(kind)
    jc = np.full(n, J_STOP, np.int64)
    fa_end = np.ones(n)
    fa_next = np.ones(n)
    for i in range(n):
        if is_pause[i]:
            continue
        last = i == n - 1 or is_pause[i + 1]
        if last:
            # nothing follows in the queue: the term condition stays parabolic (G64), which
            # halves the segment's acceleration (tpGetScaledAccel)
            if path_mode[i] == 0:
                fa_end[i] = 0.5
            continue
        if rapid[i] != rapid[i + 1] or path_mode[i] == 2:
            continue
        dot = 0.0
        for k in range(3):
            dot += u_end[i, k] * u_start[i + 1, k]
        if dot < _SHARP_CORNER_COS:
            continue
        vm1 = min(vmax[i], feed[i]) if feed[i] > 0.0 else vmax[i]
        vm2 = min(vmax[i + 1], feed[i + 1]) if feed[i + 1] > 0.0 else vmax[i + 1]
        v = min(vm1, vm2)
        a_inst = v / dt
        scale = 0.0
        for k in range(3):
            scale = max(scale, abs(a_inst * (u_start[i + 1, k] - u_end[i, k])) / acc_axis[k])
        if kind[i] == 1 or kind[i + 1] == 1:
            scale /= _ACC_RATIO_TAN
        if scale < _KINK_RATIO:
            jc[i] = J_TANGENT
            fa_end[i] = 1.0 - scale
            fa_next[i] = 1.0 - scale
            continue
        if path_mode[i] == 1:  # G61 exact path: stop at every corner that is not tangent
            continue
        if kind[i] == 0 and kind[i + 1] == 0:
            jc[i] = J_BLEND
        else:
            jc[i] = J_PARABOLIC
            fa_end[i] = 0.5
            fa_next[i] = 0.5
    return jc, fa_end, fa_next


@njit
def parabolic_blend_speed(L1, L2, v1, v2, a1, a2, tol, cos_half):
    """Speed at which a parabolic blend hands over from one segment to the next
    (tp.c tpComputeBlendVelocity), a1 and a2 already the scaled accelerations."""
    vr1 = min(math.sqrt(a1 * L1), v1)
    vr2 = min(math.sqrt(a2 * L2), v2)
    if vr1 <= 0.0 or vr2 <= 0.0:
        return 0.0
    t_reach = min(L1 / vr1, L2 / vr2)
    t_blend = min(t_reach, max(vr1 / a1, vr2 / a2))
    vb1 = min(vr1, t_blend * a1)
    vb2 = min(vr2, t_blend * a2)
    if tol > 0.0 and cos_half > math.cos(math.pi / 2.0 - 1e-3):
        vt = 2.0 * math.sqrt(a1 * tol / cos_half)
        vb1 = min(vb1, vt)
        vb2 = min(vb2, vt)
    return min(vb1, vb2)


_NAIVECAM_MAX_POINTS = 100  # emccanon.cc: a chain is flushed after 100 points


@njit(python_limit=PY_LIMIT, python_fast=PY_FAST)
def naive_cam_merge(kind, rapid, path_mode, is_pause, feed, cam_tol, p0, p1):
    """LinuxCNC's naive-CAM detector (emccanon.cc): consecutive G1 lines are merged into one
    while every intermediate point stays within the Q tolerance of the straight line from
    the chain's start to the newest point.  Returns (keep, start): keep[i] is False for
    lines absorbed into a later one, and start[i] is the start point of each kept line."""
    n = len(kind)
    keep = np.ones(n, np.bool_)
    start = p0.copy()
    i = 0
    while i < n:
        if kind[i] != 0 or rapid[i] or is_pause[i] or path_mode[i] != 0 or cam_tol[i] <= 0.0:
            i += 1
            continue
        s = i  # chain start segment; the chain holds the end points of s .. j-1
        j = i + 1
        while j < n and j - s < _NAIVECAM_MAX_POINTS:
            if kind[j] != 0 or rapid[j] or is_pause[j] or path_mode[j] != 0 or cam_tol[j] != cam_tol[s] \
                    or feed[j] != feed[s]:
                break
            tol = cam_tol[s]
            m0 = p1[j, 0] - p0[s, 0]
            m1 = p1[j, 1] - p0[s, 1]
            m2 = p1[j, 2] - p0[s, 2]
            mm = m0 * m0 + m1 * m1 + m2 * m2
            if mm == 0.0:
                break
            ok = True
            for q in range(s, j):
                d0 = p1[q, 0] - p0[s, 0]
                d1 = p1[q, 1] - p0[s, 1]
                d2 = p1[q, 2] - p0[s, 2]
                t = (d0 * m0 + d1 * m1 + d2 * m2) / mm
                t = min(1.0, max(0.0, t))
                e0 = d0 - t * m0
                e1 = d1 - t * m1
                e2 = d2 - t * m2
                if e0 * e0 + e1 * e1 + e2 * e2 > tol * tol:
                    ok = False
                    break
            if not ok:
                break
            j += 1
        # segments s .. j-1 become one line from p0[s] to p1[j-1]
        for q in range(s, j - 1):
            keep[q] = False
        for k in range(3):
            start[j - 1, k] = p0[s, k]
        i = j
    return keep, start
