"""Numba kernels of the cutting-load twin: tool engagement on a Z-map stock, and its removal.

Engagement is geometry only.  At every step along the path the cutting edge (angular bins
φ around the tool, slices along it) is tested against the stock left by earlier moves, and
the result is reduced to *force sums*: per direction factor g and force component, the sum
over engaged edge elements of ``g·w·db`` (multiplied by the feed per tooth f and a cutting
coefficient at run time) and of ``g·dS`` (multiplied by an edge coefficient).  With
``h = f·w`` the chip thickness, the revolution-averaged force is then
``F = Σ_c K_c·f·S_c + Σ_e K_e·S_e`` — so new F and S values, or another material, never
need the stock again.

Conventions (PHYSICS.md §1): feed direction x̂ (horizontal part of the motion), ŷ to its left
for M3 (to its right for M4), tooth angle φ clockwise from +ŷ; κ the angle between the tool
axis and the edge normal (90° on the cylinder, 0 at the bottom).  Edge force on the tool:
tangential −Ft·(cosφ x̂ − sinφ ŷ), radial −Fr·(sinκ d − cosκ ẑ), axial +Fa·(cosκ d + sinκ ẑ),
d = sinφ x̂ + cosφ ŷ; so on the cylinder Fz = +Fa as in PHYSICS.md.
"""
from __future__ import annotations

import math

import numpy as np

from ..jit import njit

# force-sum and per-step columns (mtwin.layout: the run kernel, the optimiser and the effects
# read them by the same names)
from ..layout import (N_Q, N_SUMS, Q_AE, Q_AP, Q_AREA, Q_CMAX, Q_CMIN, Q_DX, Q_DY, Q_UH, Q_UZ, Q_WMAX, ST_TC, ST_TE,  # noqa: E402,F401
                      SX_AC, SX_AE, SX_RC, SX_RE, SX_TC, SX_TE, SY_AC, SY_AE, SY_RC, SY_RE, SY_TC, SY_TE, SZ_AC,
                      SZ_AE, SZ_RC, SZ_RE)

SLICE_BOTTOM, SLICE_SIDE = 0, 1
# heights are float32: material thinner than this is rounding, not stock
_EPS = 1e-5


def slice_table(radius: float, nose: float, flute_length: float, grid: float, tip: float = 0.0,
                half_angle: float = 0.0):
    """Edge elements of a tool: (kind, kappa, r, z_lo, z_hi, d_rho, r_query) per slice.

    ``r_query`` is where the stock is looked up: the radius at the slice's lower end, moved
    in by half a cell diagonal.  A cell is removed when its centre is under the tool, so a
    point looked up there lies in a cell whose centre is under the tool wherever it was
    before — a second pass along the same path then finds no material (an air cut), at the
    price of a systematic wall offset of Δ/√2 in radial width.

    Bottom elements (κ = 0) lie along the flat part of the end face (ρ from 0 to R − nose);
    nose slices follow the corner (bull) or the ball; the last slice is the cylinder from the
    top of the nose to the end of the flutes.  A vee tool (``half_angle`` > 0: V-bit,
    engraving bit, chamfer mill) has a flat tip of radius ``tip``, then a cone whose edge
    stands at κ = the half angle from the axis, up to the full radius (or the flute length),
    then the cylinder."""
    rows = []
    shrink = grid / math.sqrt(2.0)
    if half_angle > 0.0:
        t = math.tan(half_angle)
        if tip > 1e-12:
            nb = max(2, min(8, int(math.ceil(tip / max(4.0 * grid, 1e-3)))))
            d = tip / nb
            for k in range(nb):
                rows.append((SLICE_BOTTOM, 0.0, (k + 0.5) * d, 0.0, 0.0, d, (k + 0.5) * d))
        cone_h = min((radius - tip) / t, flute_length)
        nc = max(4, min(24, int(math.ceil(cone_h / max(grid, 1e-3) * 0.5))))
        dz = cone_h / nc
        for k in range(nc):
            z_lo, z_hi = k * dz, (k + 1) * dz
            r = tip + 0.5 * (z_lo + z_hi) * t
            rq = max(0.0, tip + z_lo * t - shrink)
            rows.append((SLICE_SIDE, half_angle, r, z_lo, z_hi, 0.0, rq))
        if flute_length > cone_h + 1e-9:
            rows.append((SLICE_SIDE, 0.5 * math.pi, radius, cone_h, flute_length, 0.0, radius - shrink))
        a = np.array(rows, dtype=np.float64)
        return (a[:, 0].astype(np.int64), a[:, 1].copy(), a[:, 2].copy(), a[:, 3].copy(), a[:, 4].copy(),
                a[:, 5].copy(), a[:, 6].copy())
    flat = radius - nose
    if flat > 1e-12:
        nb = max(3, min(8, int(math.ceil(flat / max(4.0 * grid, 1e-3)))))
        d = flat / nb
        for k in range(nb):
            rows.append((SLICE_BOTTOM, 0.0, (k + 0.5) * d, 0.0, 0.0, d, (k + 0.5) * d))
    if nose > 1e-12:
        nn = max(4, min(16, int(math.ceil(nose / max(grid, 1e-3) * 0.5))))
        # equal steps in κ resolve the tip of a ball better than equal steps in z
        dk = 0.5 * math.pi / nn
        for k in range(nn):
            k0, k1 = k * dk, (k + 1) * dk
            kap = 0.5 * (k0 + k1)
            z_lo = nose * (1.0 - math.cos(k0))
            z_hi = nose * (1.0 - math.cos(k1))
            r = flat + nose * math.sin(kap)
            rq = max(0.0, flat + nose * math.sin(k0) - shrink)
            rows.append((SLICE_SIDE, kap, r, z_lo, z_hi, 0.0, rq))
    rows.append((SLICE_SIDE, 0.5 * math.pi, radius, nose, flute_length, 0.0, radius - shrink))
    a = np.array(rows, dtype=np.float64)
    return (a[:, 0].astype(np.int64), a[:, 1].copy(), a[:, 2].copy(), a[:, 3].copy(), a[:, 4].copy(),
            a[:, 5].copy(), a[:, 6].copy())


@njit
def _height(H, x0, y0, dx, nx, ny, x, y):
    i = int(math.floor((x - x0) / dx))
    j = int(math.floor((y - y0) / dx))
    if i < 0 or j < 0 or i >= nx or j >= ny:
        return -1e300
    return H[j, i]


@njit
def engage_step(H, x0, y0, dx, cx, cy, cz, ux, uy, uz, hand, nbins, flutes,
                skind, skap, sr, szlo, szhi, sdrho, srq, trig, sums, q, prof, n):
    """Engagement of the tool with its tip at (cx, cy, cz) moving along unit u; fills the force
    sums (revolution averages: × flutes/2π per radian of φ) and the scalars q.

    Slices are the outer loop so that each slice's sin/cos of κ is computed once; the bottom
    (κ = 0) elements, which only cut when the tool descends, use every 4th angular bin."""
    ny, nx = H.shape
    uh = math.sqrt(ux * ux + uy * uy)
    if uh > 1e-9:
        xx, xy = ux / uh, uy / uh
    else:
        xx, xy = 1.0, 0.0
    # ŷ: left of the feed for a clockwise (M3) spindle, right for M4
    yx, yy = -xy * hand, xx * hand
    dphi = 2.0 * math.pi / nbins
    for k in range(N_SUMS):
        sums[k] = 0.0
    area = 0.0
    wmax = 0.0
    ap = 0.0
    cmin = 2.0
    cmax = -2.0
    rmax = 0.0
    nsl = len(skind)
    keep = prof.shape[0] > 0  # tooth-passing resolution: keep the engaged length per slice and bin
    if keep:
        for l in range(prof.shape[1]):
            for b in range(nbins):
                prof[n, l, b] = 0.0
    for l in range(nsl):
        kap = skap[l]
        sk = math.sin(kap)
        ck = math.cos(kap)
        bottom = skind[l] == SLICE_BOTTOM
        if bottom and uz >= -1e-12:
            continue  # the end face cuts only while the tool descends
        if not bottom and uh * sk <= 1e-12 and -uz * ck <= 1e-12:
            continue
        stride = 4 if bottom else 1
        scale = flutes / (2.0 * math.pi) * dphi * stride
        r = sr[l]
        rq = srq[l]
        zlo = szlo[l]
        zhi = szhi[l]
        row = 2 if bottom else 0  # trig rows: sin, cos at bin centres; then at 4-bin centres
        for b in range(0, nbins, stride):
            sp = trig[row, b]
            w = uh * sk * sp - uz * ck
            if w <= 1e-12:
                continue
            cp = trig[row + 1, b]
            hgt = _height(H, x0, y0, dx, nx, ny, cx + rq * (sp * xx + cp * yx), cy + rq * (sp * xy + cp * yy))
            if bottom:
                if hgt <= cz + _EPS:
                    continue
                db = sdrho[l]
                if keep:
                    for bb in range(b, min(b + stride, nbins)):
                        prof[n, l, bb] = 1.0
            else:
                top = min(hgt, cz + zhi)
                eng = top - (cz + zlo)
                if eng <= _EPS:
                    continue
                db = eng / sk
                if top - cz > ap:
                    ap = top - cz
                if keep:
                    prof[n, l, b] = eng
            wc = w * db * scale
            we = db * scale
            sums[SX_TC] += -cp * wc
            sums[SX_RC] += -sk * sp * wc
            sums[SX_AC] += ck * sp * wc
            sums[SY_TC] += sp * wc
            sums[SY_RC] += -sk * cp * wc
            sums[SY_AC] += ck * cp * wc
            sums[SZ_RC] += ck * wc
            sums[SZ_AC] += sk * wc
            sums[ST_TC] += r * wc
            sums[SX_TE] += -cp * we
            sums[SX_RE] += -sk * sp * we
            sums[SX_AE] += ck * sp * we
            sums[SY_TE] += sp * we
            sums[SY_RE] += -sk * cp * we
            sums[SY_AE] += ck * cp * we
            sums[SZ_RE] += ck * we
            sums[SZ_AE] += sk * we
            sums[ST_TE] += r * we
            # projected area of the engaged edge on the plane normal to the motion (MRR = v·A)
            area += w * r * dphi * stride * db
            if w > wmax:
                wmax = w
            if not bottom:
                if cp < cmin:
                    cmin = cp
                if cp > cmax:
                    cmax = cp
                if r > rmax:
                    rmax = r
    q[Q_AREA] = area
    # the radial width at the widest engaged side slice (the cylinder of an end mill; the cone
    # of a vee tool at its depth, a ball's nose when only the nose cuts)
    q[Q_AE] = (cmax - cmin) * rmax if cmax >= cmin else 0.0
    q[Q_AP] = ap
    q[Q_WMAX] = wmax
    q[Q_DX] = xx
    q[Q_DY] = xy
    q[Q_UH] = uh
    q[Q_UZ] = uz
    q[Q_CMIN] = cmin
    q[Q_CMAX] = cmax


@njit
def tooth_forces(prof_m, q_m, theta, fz, flutes, radius, tan_helix, skind, skap, sr, szlo, szhi, sdrho,
                 nbins, kc, out):
    """Instantaneous (tooth-passing) force on the tool in the step's local frame and spindle
    torque, with the teeth at spindle angle ``theta``: out = (Fx, Fy, Fz, T [N·mm], h_max).

    Tooth j's edge at height z above the tip is at φ = θ + 2πj/N − z·tanβ/R (helix lag); it
    cuts where the engagement profile of the step says material was met at that φ."""
    uh = q_m[Q_UH]
    uz = q_m[Q_UZ]
    dphi = 2.0 * math.pi / nbins
    fx = 0.0
    fy = 0.0
    fzs = 0.0
    tq = 0.0
    hmax = 0.0
    nsl = len(skind)
    n_t = int(flutes)
    for j in range(n_t):
        th = theta + 2.0 * math.pi * j / n_t
        for l in range(nsl):
            kap = skap[l]
            sk = math.sin(kap)
            ck = math.cos(kap)
            r = sr[l]
            cyl = l == nsl - 1
            if skind[l] == SLICE_BOTTOM:
                nsub = 1
                dz = 0.0
            elif cyl:
                depth = q_m[Q_AP] - szlo[l]
                if depth <= 0.0:
                    continue
                nsub = max(1, int(math.ceil(depth / 0.05)))
                dz = depth / nsub
            else:
                nsub = 1
                dz = szhi[l] - szlo[l]
            for k in range(nsub):
                zm = szlo[l] + (k + 0.5) * dz if skind[l] != SLICE_BOTTOM else 0.0
                phi = th - zm * tan_helix / radius
                phi = phi - 2.0 * math.pi * math.floor(phi / (2.0 * math.pi))
                b = int(phi / dphi)
                if b >= nbins:
                    b = nbins - 1
                e = prof_m[l, b]
                if e <= 0.0:
                    continue
                if skind[l] == SLICE_BOTTOM:
                    db = sdrho[l]
                elif cyl:
                    # engaged part of this sub-slice along z
                    seg_lo = k * dz
                    length = min(e, seg_lo + dz) - seg_lo
                    if length <= 0.0:
                        continue
                    db = length / sk
                else:
                    db = e / sk
                sp = math.sin(phi)
                cp = math.cos(phi)
                w = uh * sk * sp - uz * ck
                if w <= 0.0:
                    continue
                h = fz * w
                if h > hmax:
                    hmax = h
                ft = kc[0] * h * db + kc[3] * db
                fr = kc[1] * h * db + kc[4] * db
                fa = kc[2] * h * db + kc[5] * db
                fx += -cp * ft - sk * sp * fr + ck * sp * fa
                fy += sp * ft - sk * cp * fr + ck * cp * fa
                fzs += ck * fr + sk * fa
                tq += r * ft
    out[0] = fx
    out[1] = fy
    out[2] = fzs
    out[3] = tq
    out[4] = hmax


def trig_table(nbins: int) -> np.ndarray:
    """sin and cos of φ at the bin centres, and at the centres of groups of 4 bins."""
    d = 2.0 * math.pi / nbins
    b = np.arange(nbins)
    return np.array([np.sin((b + 0.5) * d), np.cos((b + 0.5) * d), np.sin((b + 2.0) * d), np.cos((b + 2.0) * d)])


@njit
def _bottom_profile(d, radius, nose, tip, cotb):
    """Height of the tool's lower surface above its tip at horizontal distance d from the axis
    (a vee tool, ``cotb`` > 0: flat to the tip radius, then the cone rising cotb per mm)."""
    if cotb > 0.0:
        return 0.0 if d <= tip else (d - tip) * cotb
    flat = radius - nose
    if d <= flat:
        return 0.0
    e = d - flat
    if e >= nose:
        return nose
    return nose - math.sqrt(max(0.0, nose * nose - e * e))


@njit
def remove_line(H, x0, y0, dx, ax, ay, az, bx, by, bz, radius, nose, tip, cotb):
    """Lower the Z-map to the swept lower surface of the tool moving from A to B (tips).
    Returns the number of cells changed."""
    ny, nx = H.shape
    zlo = min(az, bz)
    i0 = max(0, int(math.floor((min(ax, bx) - radius - x0) / dx)))
    i1 = min(nx - 1, int(math.floor((max(ax, bx) + radius - x0) / dx)))
    j0 = max(0, int(math.floor((min(ay, by) - radius - y0) / dx)))
    j1 = min(ny - 1, int(math.floor((max(ay, by) + radius - y0) / dx)))
    mx, my, mz = bx - ax, by - ay, bz - az
    mm = mx * mx + my * my
    changed = 0
    r2 = radius * radius
    for j in range(j0, j1 + 1):
        py = y0 + (j + 0.5) * dx
        for i in range(i0, i1 + 1):
            h = H[j, i]
            if h <= zlo:
                continue  # nothing above the lowest point of the tool here
            px = x0 + (i + 0.5) * dx
            # parameter interval where the cell is under the tool: |p - c(t)| <= R
            qx, qy = px - ax, py - ay
            if mm > 0.0:
                tc = (qx * mx + qy * my) / mm
                ex, ey = qx - tc * mx, qy - tc * my
                d2 = ex * ex + ey * ey
                if d2 > r2:
                    continue
                half = math.sqrt((r2 - d2) / mm)
                t1 = max(0.0, tc - half)
                t2 = min(1.0, tc + half)
                if t1 > t2:
                    continue
            else:
                d2 = qx * qx + qy * qy
                if d2 > r2:
                    continue
                t1, t2 = 0.0, 1.0
            if nose <= 0.0 and cotb <= 0.0:
                # flat bottom: the lowest tip height over the interval, at one of its ends
                surf = min(az + mz * t1, az + mz * t2)
            elif mm == 0.0:
                # vertical move: the lowest position, at the cell's fixed distance
                surf = zlo + _bottom_profile(math.sqrt(d2), radius, nose, tip, cotb)
            elif mz == 0.0:
                # level move: deepest where the axis passes closest
                tb = min(max(tc, t1), t2)
                surf = az + _bottom_profile(math.sqrt((qx - tb * mx) ** 2 + (qy - tb * my) ** 2), radius, nose, tip,
                                        cotb)
            else:
                # ramp: z(t) + b(d(t)) is convex in t (d convex, b convex increasing):
                # golden-section search for its minimum
                lo_t, hi_t = t1, t2
                for _ in range(40):
                    m1 = lo_t + 0.381966 * (hi_t - lo_t)
                    m2 = hi_t - 0.381966 * (hi_t - lo_t)
                    f1 = az + mz * m1 + _bottom_profile(math.sqrt((qx - m1 * mx) ** 2 + (qy - m1 * my) ** 2),
                                                        radius, nose, tip, cotb)
                    f2 = az + mz * m2 + _bottom_profile(math.sqrt((qx - m2 * mx) ** 2 + (qy - m2 * my) ** 2),
                                                        radius, nose, tip, cotb)
                    if f1 < f2:
                        hi_t = m2
                    else:
                        lo_t = m1
                tb = 0.5 * (lo_t + hi_t)
                surf = az + mz * tb + _bottom_profile(math.sqrt((qx - tb * mx) ** 2 + (qy - tb * my) ** 2),
                                                      radius, nose, tip, cotb)
            if surf < h:
                H[j, i] = surf
                changed += 1
    return changed


@njit
def segment_point_tangent(kind, p0, p1, c, e1, e2, h, r0, r1, theta, length, i, s, pt, tg):
    """Point and unit tangent at distance s along a line or arc segment."""
    L = length[i]
    f = min(max(s / L, 0.0), 1.0) if L > 0.0 else 0.0
    if kind[i] == 0:
        for k in range(3):
            pt[k] = p0[i, k] + (p1[i, k] - p0[i, k]) * f
            tg[k] = (p1[i, k] - p0[i, k]) / L if L > 0.0 else 0.0
        return
    a = theta[i] * f
    r = r0[i] + (r1[i] - r0[i]) * f
    ca = math.cos(a)
    sa = math.sin(a)
    dr = (r1[i] - r0[i]) / theta[i] if theta[i] > 0.0 else 0.0
    nrm = 0.0
    for k in range(3):
        pt[k] = c[i, k] + r * (ca * e1[i, k] + sa * e2[i, k]) + h[i, k] * f
        tg[k] = r * (-sa * e1[i, k] + ca * e2[i, k]) + dr * (ca * e1[i, k] + sa * e2[i, k]) \
            + (h[i, k] / theta[i] if theta[i] > 0.0 else 0.0)
        nrm += tg[k] * tg[k]
    nrm = math.sqrt(nrm)
    for k in range(3):
        tg[k] /= nrm if nrm > 0.0 else 1.0


@njit
def engage_path(H, x0, y0, dx, kind, cuts, p0, p1, c, e1, e2, h, r0, r1, theta, length, tool_index,
                hand, tools, slices_start, skind, skap, sr, szlo, szhi, sdrho, srq, trig, step, nbins,
                first, count, sums, q, prof, collide):
    """Walk every segment in order: engagement at each step (midpoints of ``step``-long pieces)
    against the stock as left by earlier segments, then the segment's swept volume is removed.

    ``cuts[i]``: 1 feed move (engaged and removed), 0 rapid or pause (skipped here).
    ``tools[t]``: radius, nose radius, flutes, tip radius and cot of the half angle (vee
    tools; 0 for the others) of tool index t; its slices are
    ``slices_start[t] .. slices_start[t+1]``.  Fills first/count per segment and the per-step
    sums and scalars; returns the number of steps and of changed cells."""
    nseg = len(kind)
    n = 0
    cells = 0
    pt = np.empty(3)
    tg = np.empty(3)
    pa = np.empty(3)
    pb = np.empty(3)
    tmp_s = np.empty(N_SUMS)  # accumulate in float64, store in the (float32) output rows
    tmp_q = np.empty(N_Q)
    ny, nx = H.shape
    for i in range(nseg):
        first[i] = n
        count[i] = 0
        if kind[i] != 2 and cuts[i] == 0 and length[i] > 0.0:
            # a rapid through material is a crash: each one is marked (collide[i] = i)
            t = tool_index[i]
            rr = tools[t, 0] - dx
            m = max(1, int(math.ceil(length[i] / step)))
            for k in range(m + 1):
                segment_point_tangent(kind, p0, p1, c, e1, e2, h, r0, r1, theta, length, i,
                                      length[i] * k / m, pt, tg)
                for a in range(9):
                    ang = 2.0 * math.pi * a / 8.0
                    rad = 0.0 if a == 8 else rr
                    hh = _height(H, x0, y0, dx, nx, ny, pt[0] + rad * math.cos(ang), pt[1] + rad * math.sin(ang))
                    if hh > pt[2] + 0.01:
                        collide[i] = i
                        break
                if collide[i] >= 0:
                    break
        if kind[i] == 2 or cuts[i] == 0 or length[i] <= 0.0:
            continue
        t = tool_index[i]
        radius = tools[t, 0]
        nose = tools[t, 1]
        flutes = tools[t, 2]
        tip = tools[t, 3]
        cotb = tools[t, 4]
        s0 = slices_start[t]
        s1 = slices_start[t + 1]
        L = length[i]
        m = max(1, int(math.ceil(L / step)))
        for k in range(m):
            s = (k + 0.5) * L / m
            segment_point_tangent(kind, p0, p1, c, e1, e2, h, r0, r1, theta, length, i, s, pt, tg)
            engage_step(H, x0, y0, dx, pt[0], pt[1], pt[2], tg[0], tg[1], tg[2], hand[i], nbins, flutes,
                        skind[s0:s1], skap[s0:s1], sr[s0:s1], szlo[s0:s1], szhi[s0:s1], sdrho[s0:s1],
                        srq[s0:s1], trig, tmp_s, tmp_q, prof, n)
            for kk in range(N_SUMS):
                sums[n, kk] = tmp_s[kk]
            for kk in range(N_Q):
                q[n, kk] = tmp_q[kk]
            n += 1
        count[i] = m
        # remove the swept volume: lines at once, arcs as chords short enough that the chord
        # error stays below a quarter of a cell
        if kind[i] == 0:
            cells += remove_line(H, x0, y0, dx, p0[i, 0], p0[i, 1], p0[i, 2], p1[i, 0], p1[i, 1], p1[i, 2],
                                 radius, nose, tip, cotb)
        else:
            rad = max(r0[i], r1[i])
            chord = math.sqrt(2.0 * rad * dx) if rad > 0.0 else L
            nc = max(1, int(math.ceil(L / max(chord, 1e-6))))
            segment_point_tangent(kind, p0, p1, c, e1, e2, h, r0, r1, theta, length, i, 0.0, pa, tg)
            for k in range(1, nc + 1):
                segment_point_tangent(kind, p0, p1, c, e1, e2, h, r0, r1, theta, length, i, L * k / nc, pb, tg)
                cells += remove_line(H, x0, y0, dx, pa[0], pa[1], pa[2], pb[0], pb[1], pb[2], radius, nose, tip, cotb)
                for kk in range(3):
                    pa[kk] = pb[kk]
    return n, cells
