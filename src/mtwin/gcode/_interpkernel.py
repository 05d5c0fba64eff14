"""numba kernel of the interpreter: a modal state machine over lexed words.

It executes blocks in the RS274NGC order of execution (feed mode, F, S, T, M6,
spindle, coolant, dwell, plane, units, tool length, work offset, path mode,
distance modes, retract mode, G10/G28/G30/G53, motion, program flow) and writes
motion records into a preallocated structured array.  It never raises: errors
and warnings come back as codes with the word that caused them, and the Python
wrapper (``interpreter.py``) writes the message.
"""
from __future__ import annotations

import math

import numpy as np

from ..jit import njit
from ..units import MM_PER_INCH
from ._lexkernel import LF_BLOCK_DELETE, LF_PERCENT
from .records import (
    ARC_CCW, ARC_CW, DWELL, FL_CANNED, FL_FIRST_IN_LINE, FL_IJK_ABSOLUTE, FL_INCH, FL_INCREMENTAL,
    FL_DIAMETER, FL_MACHINE, FL_MIRROR, FL_POLAR, FL_PROBE, FL_R_ARC, FL_ROTARY, FL_SPLINE, FL_SUB, FL_SYNC, FL_F_INCH, LINEAR, RAPID,
)

# LinuxCNC's arc tolerances (interp_internal.hh), mm.
RADIUS_TOL_MM = 0.00127
CENTER_TOL_MM = 2 * 0.01 * math.sqrt(2.0)
CENTER_TOL_INCH_MM = 2 * 0.001 * math.sqrt(2.0) * MM_PER_INCH
SPIRAL_REL_TOL = 0.001
# --lenient accepts radius mismatches up to this fraction of the radius as a spiral
# (or up to 0.1 mm: posts that round coordinates to 0.05 mm mis-state small arcs by that much)
LENIENT_SPIRAL_REL = 0.1
LENIENT_SPIRAL_ABS_MM = 0.1
# G5/G5.1 splines are followed by lines within this chord error, mm (at most SPLINE_MAX_PIECES)
SPLINE_TOL_MM = 0.001
SPLINE_MAX_PIECES = 10000
# Peck clearance of G73/G83 (LinuxCNC: 0.010 in or 0.254 mm)
PECK_CLEAR_MM = 0.254
PECK_CLEAR_INCH_MM = 0.010 * MM_PER_INCH
MAX_SUB_DEPTH = 16
MAX_REPEATS = 9999  # an L repeat count (canned cycle, M98): Fanuc's own range L1-L9999

# ---- error codes (messages in interpreter.py) ----
E_OK = 0
E_OVERFLOW = 1
E_UNSUPPORTED_G = 2
E_UNSUPPORTED_M = 3
E_UNSUPPORTED_WORD = 4
E_DUP_WORD = 5
E_MODAL_CONFLICT = 6
E_ARC_RADIUS_MISMATCH = 7
E_ARC_R_TOO_SMALL = 8
E_ARC_NO_CENTER = 9
E_ARC_ZERO_RADIUS = 10
E_ARC_R_FULL_CIRCLE = 11
E_ZERO_FEED = 12
E_NO_MOTION_MODE = 13
E_TOOL_OFFSET_MISSING = 14
E_BAD_G_NUMBER = 15
E_CANNED_NO_Z = 16
E_CANNED_NO_R = 17
E_CANNED_Q = 18
E_CANNED_R_BELOW_Z = 19
E_SUB_NOT_FOUND = 20
E_SUB_DEPTH = 21
E_LOOP = 22
E_GEOMETRY_G = 23  # cutter comp, rotation, scaling: would change the path
E_BAD_WCS = 24
E_BAD_G10 = 25
E_INVERSE_NO_F = 26
E_BAD_VALUE = 27
E_G53_MODE = 28
E_BAD_TURNS = 29
E_UNUSED_WORD = 31
E_COMP_PLANE = 40
E_COMP_ACTIVE = 41
E_COMP_YZ = 42
E_AMBIGUOUS_R = 32
E_ROT_PLANE = 33
E_POLAR = 34
E_ROTARY_USE = 35
E_SYNC = 36
E_SPLINE = 37
E_PROBE = 38
E_THREAD = 39
E_CORNER = 43
E_NO_SAVED_STATE = 44
E_RESTORE_OFFSETS = 45
E_POLAR16 = 46
E_MIRROR = 47
E_REPEATS = 48
E_MOVES = 49
MAX_MOVES = 5_000_000  # moves a program may expand to: 1.4 GB of records, 50x a 1-hour raster (L9999 x L9999 is 1e8)
MAX_SAVED = 32  # call levels with a saved modal state (M70/M73)

# ---- warning codes ----
W_IGNORED_G = 1
W_IGNORED_M = 2
W_M99_IN_MAIN = 3
W_AXIS_LETTER_ZERO = 4
W_COMP_RADIUS_UNKNOWN = 5
W_ARC_SPIRAL = 6
W_NO_FEED = 7
W_CONTROL_BYTE = 8
W_PROBE = 9
W_F_BEFORE_UNITS = 10

# letters
_A, _B, _C, _D, _E, _F, _G, _H, _I, _J, _K, _L, _M = range(13)
_N, _O, _P, _Q, _R, _S, _T, _U, _V, _W, _X, _Y, _Z = range(13, 26)
_AT, _CARET = 26, 27  # polar words '@' (distance) and '^' (angle, degrees)
_CMA, _CMC, _CMR = 28, 29, 30  # Fanuc ',A' (angle), ',C' (corner chamfer), ',R' (corner radius)
NWORDS = 31

# ---- the G codes' modal groups: one table (LinuxCNC's _gees[] is the model) ----
# Each code (x10: G38.2 is 382) has, per dialect (row 0 Fanuc, row 1 LinuxCNC), its modal group
# (RS274NGC 3.4 and LinuxCNC's numbers; Fanuc's for its own codes) and what it sets (its slot).
# A block may hold one code of a group ("two G-codes from the same modal group" is an error);
# group -1: no conflict (G80 beside G0, as Fanuc posts write it; G9; cancel codes the twin
# passes over).  Slot -1: not a code the twin reads.
(GS_MOTION, GS_DWELL, GS_EXACT_ONCE, GS_PLANE, GS_UNITS, GS_COMP, GS_TLO, GS_WCS, GS_PATH, GS_DIST, GS_IJK,
 GS_FEEDMODE, GS_RETRACT, GS_NONMODAL, GS_ROT68, GS_CSS, GS_MIRROR, GS_POLAR, GS_DIAM, GS_CANCEL, GS_HARMLESS,
 GS_LOOKAHEAD, GS_GEOMETRY) = range(23)
N_GROUPS = 32


def _g_table() -> np.ndarray:
    """(2 dialects, 1000 codes, [slot, group]); the first rule for a code stands."""
    t = np.full((2, 1000, 2), -1, np.int8)

    def put(slot, group, codes, rows=(0, 1)):
        for r in rows:
            for c in codes:
                if t[r, c, 0] < 0:
                    t[r, c] = (slot, group)

    put(GS_CANCEL, -1, (800,))
    put(GS_MOTION, 1, (0, 10, 20, 30, 810, 820, 830, 730, 850, 890, 840, 860, 330, 331, 382, 383, 384, 385, 760))
    put(GS_MOTION, 1, (50, 51), rows=(1,))  # LinuxCNC G5 / G5.1 splines
    put(GS_DWELL, 0, (40,))
    put(GS_EXACT_ONCE, -1, (90,))  # Fanuc G09: one block's exact stop, beside any code
    put(GS_PLANE, 2, (170, 180, 190))
    put(GS_DIST, 3, (900, 910))
    put(GS_IJK, 4, (901, 911))
    put(GS_FEEDMODE, 5, (930, 940, 950))
    put(GS_UNITS, 6, (200, 210))
    put(GS_COMP, 7, (400, 410, 420, 411, 421))
    put(GS_TLO, 8, (430, 490, 431, 432))
    put(GS_RETRACT, 10, (980, 990))
    put(GS_WCS, 12, (540, 550, 560, 570, 580, 590, 591, 592, 593))
    put(GS_PATH, 13, (610, 611, 640))
    put(GS_NONMODAL, 0, (100, 280, 300, 530, 920, 921, 922, 923, 281, 301, 520))
    put(GS_CSS, 14, (960, 970))  # G96 constant surface speed / G97 rpm
    put(GS_ROT68, 16, (680, 690), rows=(0,))  # Fanuc G68 X Y R rotation / G69
    put(GS_POLAR, 17, (160, 150), rows=(0,))  # Fanuc G16 polar coordinates / G15
    put(GS_MIRROR, 22, (511, 501), rows=(0,))  # Fanuc G51.1 programmable mirror image / G50.1
    put(GS_HARMLESS, -1, (150, 500, 690, 501, 670))  # G15/G50/G69/G50.1/G67 cancel codes
    # Fanuc G08 P1/P0 look-ahead, G05.1 Q1/Q0 AI contour control, G05 P10000 high-speed
    # machining: the control's planning mode, not the path (the twin's planner is configured)
    put(GS_LOOKAHEAD, -1, (80, 51, 50), rows=(0,))
    put(GS_DIAM, 15, (70, 80), rows=(1,))  # LinuxCNC lathe G7 diameter / G8 radius mode
    # cutter compensation variants, rotation, scaling, mirror, polar, macros: would change the path
    put(GS_GEOMETRY, -1, (680, 510, 511, 160, 120, 130, 70, 681, 650, 660, 661))
    return t


#: per dialect row (0 Fanuc, 1 the others) and G code (x10): its slot and its modal group
G_TABLE = _g_table()

# ---- the M codes: one table too, with LinuxCNC's modal groups (its ems[]) ----
# Each code (x10) has, per dialect row, what it does (its slot) and its group: two codes of one
# group in a block is an error in LinuxCNC ("two M codes used from the same modal group": M3 M5,
# M7 M8); a Fanuc control checks no M groups (a block may carry up to three M codes), so its
# row has none.  Slot -1: not a code the twin reads.
(MS_TOOLCHANGE, MS_SET_TOOL, MS_SAVE, MS_IO, MS_SPINDLE, MS_COOLANT, MS_END, MS_CALL, MS_RETURN,
 MS_PASS) = range(10)
N_MGROUPS = 11


def _m_table() -> np.ndarray:
    """(2 dialects, 1000 codes, [slot, group])."""
    t = np.full((2, 1000, 2), -1, np.int8)

    def put(slot, codes, rows=(0, 1)):
        for r in rows:
            for c in codes:
                t[r, c, 0] = slot

    put(MS_TOOLCHANGE, (60,))
    put(MS_SET_TOOL, (610,), rows=(1,))  # LinuxCNC M61 Q<n>: the tool in the spindle is n
    put(MS_SAVE, (700, 710, 720, 730), rows=(1,))  # LinuxCNC M70-M73 modal state
    put(MS_IO, (620, 630, 640, 650, 660, 670, 680), rows=(1,))  # LinuxCNC digital/analog I/O
    put(MS_SPINDLE, (30, 40, 50))
    put(MS_COOLANT, (70, 80, 90))
    put(MS_END, (20, 300))
    put(MS_CALL, (980,))
    put(MS_RETURN, (990,))
    # stops, override switches, orient, rigid-tap mode: no effect on the path
    put(MS_PASS, (0, 1, 10, 190, 290, 480, 490, 500, 510, 520, 530))
    for group, codes in ((4, (0, 10, 20, 300, 600, 990)), (5, (620, 630, 640, 650, 660, 670, 680)),
                         (6, (60, 610)), (7, (30, 40, 50, 190, 700, 710, 720, 730)), (8, (70, 80, 90)),
                         (9, (480, 490, 500, 510, 520, 530))):
        for c in codes:
            t[1, c, 1] = group
    return t


#: per dialect row and M code (x10): its slot and its modal group (LinuxCNC's; none for Fanuc)
M_TABLE = _m_table()

# state indices (float)
SF_FEED, SF_SPINDLE, SF_PATH_TOL, SF_TLO, SF_CAM_TOL, SF_COMP_R, SF_TOX, SF_TOY = 0, 1, 2, 3, 4, 5, 6, 7
SF_A, SF_B, SF_C = 8, 9, 10  # rotary axis positions, degrees (not scaled by G20/G21)
SF_U, SF_V, SF_W = 11, 12, 13  # secondary linear axes, mm
SF_CSS_ON, SF_CSS_MAX = 14, 15  # G96 active (S is a surface speed), its rpm limit D (0: none)
SF_CORNER = 16  # this block's Fanuc corner: ,R radius (> 0) or ,C chamfer (< 0), mm
# state indices (int)
SI_PLANE, SI_PATH_MODE, SI_FEED_MODE, SI_SPINDLE_DIR, SI_COOLANT, SI_WCS, SI_TOOL, SI_FLAGS, SI_COMP, SI_COMP_ORIENT \
    = range(10)


@njit
def _taken(seen, group):
    """The one conflict check of the G and the M codes: was this modal group taken by another
    code of the block already?  (It is taken now; group -1 conflicts with nothing.)"""
    if group < 0:
        return False
    if seen[group]:
        return True
    seen[group] = True
    return False


@njit
def _warn(warn_code, warn_word, nwarn, code, word):
    """Note a warning (its code and the word it is about) while there is room; count it always."""
    if nwarn < warn_code.size:
        warn_code[nwarn] = code
        warn_word[nwarn] = word
    return nwarn + 1


@njit
def _emit(out, n, kind, line, s, e, c, turns, dwell, st, si, wcs_off, flags):
    """Write one record (or only count it when ``out`` is full)."""
    if n < out.size:
        r = out[n]
        r.line = line + 1
        r.kind = kind
        r.plane = si[SI_PLANE]
        r.path_mode = si[SI_PATH_MODE]
        r.feed_mode = si[SI_FEED_MODE]
        r.spindle_dir = si[SI_SPINDLE_DIR]
        r.coolant = si[SI_COOLANT]
        r.wcs = si[SI_WCS]
        r.flags = si[SI_FLAGS] | flags
        r.turns = turns
        r.tool = si[SI_TOOL]
        r.sx = s[0]
        r.sy = s[1]
        r.sz = s[2]
        r.x = e[0]
        r.y = e[1]
        r.z = e[2]
        r.cx = c[0]
        r.cy = c[1]
        r.cz = c[2]
        fw = st[SF_FEED]
        r.feed_word = fw
        rpm = st[SF_SPINDLE]
        r.css = 0.0
        if st[SF_CSS_ON] > 0.0:
            # constant surface speed: the spindle turns at S/(2 pi |X|), at most D; the record
            # holds the speed at its end point (in m/min and rpm)
            css = rpm * (0.3048 if (si[SI_FLAGS] & FL_INCH) else 1.0)
            r.css = css
            rad = abs(e[0])
            lim = st[SF_CSS_MAX]
            if rad > 0.0:
                rpm = 1000.0 * css / (2.0 * math.pi * rad)
                if lim > 0.0 and rpm > lim:
                    rpm = lim
            else:
                rpm = lim
        if kind == RAPID or kind == DWELL:
            r.feed = 0.0
        elif si[SI_FEED_MODE] == 1:
            r.feed = fw * rpm
        elif si[SI_FEED_MODE] == 2:
            r.feed = 0.0  # filled by the caller, which knows the length
        else:
            r.feed = fw
        r.spindle = rpm
        r.dwell = dwell
        r.path_tol = st[SF_PATH_TOL]
        r.cam_tol = st[SF_CAM_TOL]
        r.comp = si[SI_COMP]
        r.corner = st[SF_CORNER] if (kind == LINEAR or kind == ARC_CW or kind == ARC_CCW) else 0.0
        r.comp_orient = si[SI_COMP_ORIENT]
        r.comp_r = st[SF_COMP_R]
        r.tlo = st[SF_TLO]
        w = si[SI_WCS]
        # machine = G5x + Rot(G5x R)·(program + G92) (+ tool offsets): ox/oy/oz hold the
        # G5x offset plus the rotated G92 offset, rot the rotation (LinuxCNC's order)
        th = math.radians(wcs_off[w, 3])
        cs = math.cos(th)
        sn = math.sin(th)
        # with a Fanuc G68 rotation (angle a about c) in front: machine =
        # G5x + Rot_w·(c - Rot_a·c + G92) + Rot_(w+a)·p
        t = math.radians(wcs_off[11, 3])
        cx = wcs_off[11, 0]
        cy = wcs_off[11, 1]
        kx = cx - (math.cos(t) * cx - math.sin(t) * cy) + wcs_off[9, 0]
        ky = cy - (math.sin(t) * cx + math.cos(t) * cy) + wcs_off[9, 1]
        r.ox = wcs_off[w, 0] + cs * kx - sn * ky
        r.oy = wcs_off[w, 1] + sn * kx + cs * ky
        r.oz = wcs_off[w, 2] + wcs_off[9, 2]
        r.rot = wcs_off[w, 3] + wcs_off[11, 3]
        r.tox = st[SF_TOX]
        r.toy = st[SF_TOY]
        r.a = st[SF_A]
        r.b = st[SF_B]
        r.c = st[SF_C]
        r.u = st[SF_U]
        r.v = st[SF_V]
        r.w = st[SF_W]
    return n + 1


@njit
def _to_machine(p, w, wcs_off, m):
    """Machine position (without tool offsets) of program point ``p`` in system ``w``."""
    # Fanuc G68 first: the program point turned about its centre
    t = math.radians(wcs_off[11, 3])
    dx = p[0] - wcs_off[11, 0]
    dy = p[1] - wcs_off[11, 1]
    qx = wcs_off[11, 0] + math.cos(t) * dx - math.sin(t) * dy
    qy = wcs_off[11, 1] + math.sin(t) * dx + math.cos(t) * dy
    th = math.radians(wcs_off[w, 3])
    cs = math.cos(th)
    sn = math.sin(th)
    px = qx + wcs_off[9, 0]
    py = qy + wcs_off[9, 1]
    m[0] = wcs_off[w, 0] + cs * px - sn * py
    m[1] = wcs_off[w, 1] + sn * px + cs * py
    m[2] = wcs_off[w, 2] + p[2] + wcs_off[9, 2]


@njit
def _from_machine(m, w, wcs_off, p):
    """Inverse of :func:`_to_machine`."""
    th = math.radians(wcs_off[w, 3])
    cs = math.cos(th)
    sn = math.sin(th)
    dx = m[0] - wcs_off[w, 0]
    dy = m[1] - wcs_off[w, 1]
    qx = cs * dx + sn * dy - wcs_off[9, 0] - wcs_off[11, 0]
    qy = -sn * dx + cs * dy - wcs_off[9, 1] - wcs_off[11, 1]
    t = math.radians(wcs_off[11, 3])
    p[0] = wcs_off[11, 0] + math.cos(t) * qx + math.sin(t) * qy
    p[1] = wcs_off[11, 1] - math.sin(t) * qx + math.cos(t) * qy
    p[2] = m[2] - wcs_off[w, 2] - wcs_off[9, 2]


@njit
def _unrotate(w, wcs_off, vx, vy):
    """A machine-frame XY vector in the rotated frame of system ``w``."""
    th = math.radians(wcs_off[w, 3])
    cs = math.cos(th)
    sn = math.sin(th)
    return cs * vx + sn * vy, -sn * vx + cs * vy


@njit
def _set_tool_offset(pos, st, w, wcs_off, tlo, tox, toy):
    """G43/G49: the tool does not move, so its program position changes by the offset change."""
    dx, dy = _unrotate(w, wcs_off, tox - st[SF_TOX], toy - st[SF_TOY])
    pos[0] -= dx
    pos[1] -= dy
    pos[2] -= tlo - st[SF_TLO]
    st[SF_TLO] = tlo
    st[SF_TOX] = tox
    st[SF_TOY] = toy


@njit
def _polar_xy(px, py, has_r, r, has_t, t_deg, incremental):
    """XY end point of a polar move (LinuxCNC): distance and angle about the origin of
    the program coordinates; in G91 they add to the current point's distance and angle,
    in G90 a missing one is the current point's."""
    cr = math.hypot(px, py)
    ct = math.atan2(py, px)
    if incremental:
        rr = cr + (r if has_r else 0.0)
        tt = ct + (math.radians(t_deg) if has_t else 0.0)
    else:
        rr = r if has_r else cr
        tt = math.radians(t_deg) if has_t else ct
    return rr * math.cos(tt), rr * math.sin(tt)


@njit
def _target(e, pos, has, val, scale, incremental):
    """End point of a move from its X/Y/Z words (G90 or G91); unnamed axes stay."""
    for a, L in ((0, _X), (1, _Y), (2, _Z)):
        if has[L]:
            e[a] = pos[a] + val[L] * scale if incremental else val[L] * scale
        else:
            e[a] = pos[a]


@njit
def _sync_move(out, n, li, s, e, pitch, st, si, wcs_off, flags):
    """A spindle-synchronised line (feed = pitch x spindle speed)."""
    fmode = si[SI_FEED_MODE]
    fword = st[SF_FEED]
    si[SI_FEED_MODE] = 1
    st[SF_FEED] = pitch
    n = _emit(out, n, LINEAR, li, s, e, e, 0, 0.0, st, si, wcs_off, flags | FL_SYNC)
    si[SI_FEED_MODE] = fmode
    st[SF_FEED] = fword
    return n


@njit
def _thread_cycle(out, n, li, pos, has, val, scale, st, si, wcs_off, first_flag):
    """G76 (LinuxCNC) in G18: threading passes from the drive line (the current X) toward Z.

    Pass depth from the drive line: |I| + J·n^(1/R) while below |I| + K, then the full depth
    1 + H times; the compound angle Q shifts each pass along Z by (depth - |I|)·tan Q (the
    last pass ends on Z); E with L tapers the entry (L1), the exit (L2) or both (L3) at the
    pitch stretched by hypot(E, K)/E.  Each pass: rapid to the retract X at the start Z, in
    to the depth (or tapered in), threaded to the end, out (or tapered out), rapid back.
    Returns the new record count, or -(count)-1 for a bad word.
    """
    if si[SI_PLANE] != 1 or not (has[_P] and has[_Z] and has[_I] and has[_J] and has[_K]) or has[_X] \
            or st[SF_SPINDLE] <= 0.0:
        return -n - 1
    pitch = val[_P] * scale
    i_off = val[_I] * scale
    j = val[_J] * scale
    k = val[_K] * scale
    degr = val[_R] if has[_R] else 1.0
    q = math.radians(val[_Q]) if has[_Q] else 0.0
    springs = int(val[_H]) if has[_H] else 0
    taper = val[_E] * scale if has[_E] else 0.0
    ends = int(val[_L]) if has[_L] else 0
    if pitch <= 0.0 or j <= 0.0 or k <= 0.0 or degr < 1.0 or springs < 0 or taper < 0.0 or ends < 0 \
            or ends > 3:
        return -n - 1
    boring = i_off > 0.0
    sgn = 1.0 if boring else -1.0  # direction of cutting deeper, along X
    safe_x = pos[0]
    start_z = pos[2]
    target_z = val[_Z] * scale
    peak = abs(i_off)
    full = peak + k
    tq = math.tan(q)
    z_full = (full - peak) * tq
    entry = taper > 0.0 and (ends == 1 or ends == 3)
    exit_ = taper > 0.0 and (ends == 2 or ends == 3)
    taper_pitch = pitch * math.hypot(taper, k) / taper if taper > 0.0 else pitch
    s = np.empty(3)
    e = np.empty(3)
    for a in range(3):
        s[a] = pos[a]
        e[a] = pos[a]
    fl = first_flag | FL_CANNED
    npass = 1
    depth = peak + j
    final = 0
    while final <= springs:
        if depth >= full:
            depth = full
        zoff = (depth - peak) * tq
        x_in = safe_x + sgn * depth
        x_back = safe_x - sgn * (full - depth)
        z0 = start_z - zoff
        z1 = target_z + z_full - zoff
        # back to the retract X at the start of this pass
        e[0] = x_back
        e[2] = z0
        n = _emit(out, n, RAPID, li, s, e, e, 0, 0.0, st, si, wcs_off, fl)
        fl = FL_CANNED
        s[0] = e[0]
        s[2] = e[2]
        if entry:
            e[0] = x_in - sgn * k
            n = _sync_move(out, n, li, s, e, taper_pitch, st, si, wcs_off, fl)
            s[0] = e[0]
            e[0] = x_in
            e[2] = z0 - taper
            n = _sync_move(out, n, li, s, e, taper_pitch, st, si, wcs_off, fl)
        else:
            e[0] = x_in
            n = _emit(out, n, RAPID, li, s, e, e, 0, 0.0, st, si, wcs_off, fl)
        s[0] = e[0]
        s[2] = e[2]
        e[2] = z1 + taper if exit_ else z1
        n = _sync_move(out, n, li, s, e, pitch, st, si, wcs_off, fl)
        s[2] = e[2]
        if exit_:
            e[0] = x_in - sgn * k
            e[2] = z1
            n = _sync_move(out, n, li, s, e, taper_pitch, st, si, wcs_off, fl)
            s[0] = e[0]
            s[2] = e[2]
        e[0] = x_back
        n = _emit(out, n, RAPID, li, s, e, e, 0, 0.0, st, si, wcs_off, fl)
        s[0] = e[0]
        if depth >= full:
            final += 1
        else:
            npass += 1
            depth = peak + j * npass ** (1.0 / degr)
    e[0] = safe_x
    e[2] = target_z
    n = _emit(out, n, RAPID, li, s, e, e, 0, 0.0, st, si, wcs_off, fl)
    for a in range(3):
        pos[a] = e[a]
    return n


@njit
def _first_extra_word(has, widx):
    for L in (_A, _B, _C, _U, _V, _W):
        if has[L]:
            return widx[L]
    return -1


@njit
def _move_rotary(st, has, val, incremental, scale):
    """Apply A/B/C (degrees) and U/V/W (lengths) words in G90/G91; FL_ROTARY when one moves."""
    fl = 0
    for q, L in ((SF_A, _A), (SF_B, _B), (SF_C, _C), (SF_U, _U), (SF_V, _V), (SF_W, _W)):
        if has[L]:
            v = val[L] * scale if q >= SF_U else val[L]
            nv = st[q] + v if incremental else v
            if nv != st[q]:
                fl = FL_ROTARY
            st[q] = nv
    return fl


@njit
def _rotate(w, wcs_off, vx, vy):
    th = math.radians(wcs_off[w, 3])
    cs = math.cos(th)
    sn = math.sin(th)
    return cs * vx - sn * vy, sn * vx + cs * vy


@njit
def _has_code(codes, n, code):
    for i in range(n):
        if codes[i] == code:
            return True
    return False


@njit
def _arc_len(s, e, c, a1, a2, an, ccw, turns):
    r = math.hypot(s[a1] - c[a1], s[a2] - c[a2])
    t0 = math.atan2(s[a2] - c[a2], s[a1] - c[a1])
    t1 = math.atan2(e[a2] - c[a2], e[a1] - c[a1])
    d = (t1 - t0) if ccw else (t0 - t1)
    d = d % (2 * math.pi)
    if d * r < 1e-9:
        d = 2 * math.pi
    d += 2 * math.pi * turns
    return math.hypot(r * d, e[an] - s[an])


# Python interprets ~12,000 lines/s; compiling this kernel takes ~55 s, loading it from the
# cache ~0.4 s (numba's registries included)
@njit(python_limit=60_000, python_fast=4_000)
def interp_kernel(line_w0, line_nw, line_flags, w_letter, w_value, w_ndec,
                  sub_num, sub_line, wcs_init, tool_len, tool_known, have_tool_table,
                  home28, home30, dialect, lenient, skip_block_delete, max_steps, out,
                  warn_code, warn_word, comp_r, comp_known, last_change):
    """Interpret a lexed program.  See module docstring.
    ``last_change`` receives (tool, line index, records emitted before it) of the last tool
    change (M6), so that one after the last move can still be timed.

    Returns (n_records, err_code, err_word, err_line, err_vals, n_warnings).
    ``err_word`` is a global word index (or -1), ``err_line`` a 0-based line.
    """
    nl = line_w0.size
    n = 0
    nwarn = 0
    err_vals = np.zeros(4)
    # rows 0..8: G54..G59.3; row 9: the active G92 offset; row 10: the saved one (G92.3)
    # column 3: the XY rotation of each system, degrees (G10 L2/L20 R)
    # row 11: the Fanuc G68 program rotation (centre x, centre y, -, angle in degrees)
    wcs_off = np.zeros((12, 4))
    wcs_off[:9, :3] = wcs_init
    # the tool table can be changed by G10 L1/L10/L11: work on copies
    tool_len = tool_len.copy()
    tool_known = tool_known.copy()
    tool_xy = np.zeros((tool_len.size, 2))
    comp_r = comp_r.copy()
    comp_known = comp_known.copy()
    # Fanuc offset memory C (G10 L10-L13): geometry and wear of the H (length) and D (radius)
    # offsets; a value from the twin file is a geometry with no wear
    h_geo = tool_len.copy()
    h_wear = np.zeros(tool_len.size)
    d_geo = comp_r.copy()
    d_wear = np.zeros(comp_r.size)
    # X, Y, Z (mm), A, B, C (degrees) and U, V, W (mm) of the G28 and G30 positions
    h28 = home28
    h30 = home30
    home28 = np.zeros(9)
    home30 = np.zeros(9)
    home28[:3] = h28
    home30[:3] = h30
    mach = np.zeros(3)
    tmp = np.zeros(3)

    st = np.zeros(17)
    si = np.zeros(10, np.int64)
    # M70/M73 saved modal state per call level: ints (plane, feed mode, spindle dir, coolant,
    # wcs, path mode, comp, inch, G91, G90.1, G7, G98) and floats (F, S, P, Q, G96, D, TLO, comp R)
    sv_i = np.zeros((MAX_SAVED, 12), np.int64)
    sv_f = np.zeros((MAX_SAVED, 8))
    sv_ok = np.zeros(MAX_SAVED, np.bool_)
    si[SI_PATH_MODE] = 0
    pos = np.zeros(3)
    inch = False
    diameter = False  # G7: X words are diameters (X/2 is the position)
    polar16 = False  # Fanuc G16: X/Y words are a radius and an angle about the work zero
    mir = np.zeros(3, np.bool_)  # Fanuc G51.1: axes mirrored ...
    mirc = np.zeros(3)  # ... about these program positions, mm
    incremental = False
    ijk_abs = False
    # code*10 of the active group-1 mode; -1 = none (G80, LinuxCNC's power-on state); a Fanuc
    # control powers on in G00 (parameter 3402#0 = 0, the usual setting)
    motion = 0 if dialect == 0 else -1
    motion_base = motion  # the last G00/G01/G02/G03 mode (Fanuc restores it after G80)
    spline_c2 = np.zeros(2)  # last control point of the previous G5 (for a G5 without I J)
    spline_prev = False
    retract_old = dialect == 0  # power-on default: Fanuc G98, LinuxCNC G99
    tool_sel = 0
    canned_r = math.nan
    canned_z = math.nan
    canned_q = math.nan
    canned_p = 0.0
    # the initial level of a series of canned-cycle blocks: the drilling-axis position before
    # its first block, kept (G98 returns there, G91 R counts from it) until G80 or a motion
    # mode that is not a cycle ends the series (NaN: no series under way)
    canned_init = math.nan

    has = np.zeros(NWORDS, np.bool_)
    val = np.zeros(NWORDS)
    widx = np.zeros(NWORDS, np.int64)
    gcodes = np.zeros(16, np.int64)
    g_seen = np.zeros(N_GROUPS, np.bool_)  # the block's modal groups taken (G_TABLE)
    gword = np.zeros(16, np.int64)
    mcodes = np.zeros(16, np.int64)
    m_seen = np.zeros(N_MGROUPS, np.bool_)  # the block's M modal groups taken (M_TABLE)
    mword = np.zeros(16, np.int64)
    e = np.zeros(3)
    s = np.zeros(3)
    c = np.zeros(3)
    stack_ret = np.zeros(MAX_SUB_DEPTH, np.int64)
    stack_start = np.zeros(MAX_SUB_DEPTH, np.int64)
    stack_left = np.zeros(MAX_SUB_DEPTH, np.int64)
    depth = 0
    percents = 0
    steps = 0

    li = 0
    while li < nl:
        steps += 1
        if steps > max_steps:
            return n, E_LOOP, -1, li, err_vals, nwarn
        if n > MAX_MOVES:
            return n, E_MOVES, -1, li, err_vals, nwarn
        lf = line_flags[li]
        if lf & LF_PERCENT:
            percents += 1
            if percents >= 2 and depth == 0:
                break
            li += 1
            continue
        nw = line_nw[li]
        if nw == 0 or (skip_block_delete and (lf & LF_BLOCK_DELETE)):
            li += 1
            continue
        w0 = line_w0[li]
        # ---- gather words ----
        for k in range(NWORDS):
            has[k] = False
        ng = 0
        nm = 0
        for k in range(w0, w0 + nw):
            L = int(w_letter[k]) - 65  # int(): a uint8 would wrap in plain Python
            if L == -1:
                L = _AT
            elif L == 29:
                L = _CARET
            elif L == 32:
                L = _CMA
            elif L == 34:
                L = _CMC
            elif L == 49:
                L = _CMR
            v = w_value[k]
            if L == _G or L == _M:
                code = int(round(v * 10.0))
                if v < 0 or abs(v * 10.0 - code) > 1e-6:
                    return n, E_BAD_G_NUMBER, k, li, err_vals, nwarn
                if L == _G:
                    if ng >= 16:
                        return n, E_MODAL_CONFLICT, k, li, err_vals, nwarn
                    gcodes[ng] = code
                    gword[ng] = k
                    ng += 1
                else:
                    if nm >= 16:
                        return n, E_MODAL_CONFLICT, k, li, err_vals, nwarn
                    mcodes[nm] = code
                    mword[nm] = k
                    nm += 1
            else:
                if has[L]:
                    return n, E_DUP_WORD, k, li, err_vals, nwarn
                has[L] = True
                val[L] = v
                widx[L] = k
        e_word = has[_E]  # only G76 uses E (its taper length); checked once the mode is known

        nwarn_line = nwarn  # codes ignored by --lenient may own words we cannot check
        # ---- classify G and M codes ----
        g_feedmode = -1
        g_plane = -1
        g_units = -1
        g_diam = -1
        g_css = -1
        g_polar = -1
        g_mirror = -1
        g_mirror_w = -1
        g_rot68 = -1
        g_rot68_w = -1
        g_tlo = -1
        g_wcs = -1
        g_path = -1
        g_dist = -1
        g_ijk = -1
        g_retract = -1
        g_nonmodal = -1
        g_nonmodal_code = -1
        g_nonmodal_w = -1
        g_comp = -1
        g_comp_w = -1
        g_lookahead = False
        g_motion = -1
        g_motion_w = -1
        g_dwell = False
        g_cancel = False
        g_exact_stop_once = False
        m_tc = False
        m_spindle = -2
        m_cool = -1
        m_end = False
        m_sub = False
        m_ret = False
        m61 = False
        m_io = False
        m_save = -1  # M70/M73 save (1), M71 invalidate (2), M72 restore (3)
        g_seen[:] = False
        m_seen[:] = False
        drow = 0 if dialect == 0 else 1
        # the G codes, then the M codes, each looked up in its table (G_TABLE, M_TABLE): an
        # unknown code is an error (--lenient passes over it), one code per modal group
        for q in range(ng + nm):
            is_m = q >= ng
            code = mcodes[q - ng] if is_m else gcodes[q]
            kw = mword[q - ng] if is_m else gword[q]
            table = M_TABLE if is_m else G_TABLE
            slot = table[drow, code, 0] if code < 1000 else -1
            group = table[drow, code, 1] if code < 1000 else -1
            if slot == GS_GEOMETRY and not is_m:
                return n, E_GEOMETRY_G, kw, li, err_vals, nwarn
            if slot < 0:
                # --lenient passes over an unknown M code, and an unknown G code on a block without
                # axis words: with them it may be a motion of its own (a lathe cycle, a probe, a
                # macro call)
                if lenient and (is_m or not (has[_X] or has[_Y] or has[_Z] or has[_AT] or has[_CARET])):
                    nwarn = _warn(warn_code, warn_word, nwarn, W_IGNORED_M if is_m else W_IGNORED_G, kw)
                    continue
                return n, E_UNSUPPORTED_M if is_m else E_UNSUPPORTED_G, kw, li, err_vals, nwarn
            if _taken(m_seen if is_m else g_seen, group):  # two codes of one modal group in a block
                return n, E_MODAL_CONFLICT, kw, li, err_vals, nwarn
            # what the code sets: an M code by its slot, a G code by its group's slot
            if is_m:
                if slot == MS_TOOLCHANGE:
                    m_tc = True
                elif slot == MS_SET_TOOL:
                    m61 = True
                elif slot == MS_SAVE:
                    # M70/M73 save (M73 restored at the subroutine's return), M71 forget, M72 restore;
                    # L is the call level (given by the macro executor)
                    m_save = 1 if (code == 700 or code == 730) else (2 if code == 710 else 3)
                elif slot == MS_IO:
                    m_io = True  # M62-M65 outputs (P), M66 wait (P/E, L, Q), M67/M68 analog (E, Q)
                elif slot == MS_SPINDLE:
                    m_spindle = 1 if code == 30 else (-1 if code == 40 else 0)
                elif slot == MS_COOLANT:
                    m_cool = 1 if code == 70 else (2 if code == 80 else 0)
                elif slot == MS_END:
                    m_end = True
                elif slot == MS_CALL:
                    m_sub = True
                elif slot == MS_RETURN:
                    m_ret = True
            elif slot == GS_CANCEL:
                g_cancel = True
            elif slot == GS_MOTION:
                g_motion = code
                g_motion_w = kw
            elif slot == GS_DWELL:
                g_dwell = True
            elif slot == GS_EXACT_ONCE:
                g_exact_stop_once = True
            elif slot == GS_PLANE:
                g_plane = (code - 170) // 10
            elif slot == GS_UNITS:
                g_units = 1 if code == 200 else 0
            elif slot == GS_COMP:
                g_comp = code
                g_comp_w = kw
            elif slot == GS_TLO:
                g_tlo = code
            elif slot == GS_WCS:
                g_wcs = (code - 540) // 10 if code % 10 == 0 else 5 + code - 590
            elif slot == GS_PATH:
                g_path = code
            elif slot == GS_DIST:
                g_dist = 1 if code == 910 else 0
            elif slot == GS_IJK:
                g_ijk = 1 if code == 901 else 0
            elif slot == GS_FEEDMODE:
                g_feedmode = 2 if code == 930 else (0 if code == 940 else 1)
            elif slot == GS_RETRACT:
                g_retract = code
            elif slot == GS_NONMODAL:
                g_nonmodal_code = code
                if code == 281 or code == 301:
                    code = code - 1
                g_nonmodal = code
                g_nonmodal_w = kw
            elif slot == GS_ROT68:
                g_rot68 = 1 if code == 680 else 0
                g_rot68_w = kw
            elif slot == GS_CSS:
                g_css = 1 if code == 960 else 0
            elif slot == GS_MIRROR:
                g_mirror = 1 if code == 511 else 0
                g_mirror_w = kw
            elif slot == GS_POLAR:
                g_polar = 1 if code == 160 else 0
            elif slot == GS_LOOKAHEAD:
                g_lookahead = True
            elif slot == GS_DIAM:
                g_diam = 1 if code == 70 else 0

        # ---- Fanuc G16: X and Y become the polar words (the LinuxCNC @ ^ path interprets them)
        if g_polar >= 0:
            polar16 = g_polar == 1
        if polar16 and (has[_X] or has[_Y]) and g_nonmodal < 0 and not g_dwell:
            kw = widx[_X] if has[_X] else widx[_Y]
            plane_now = g_plane if g_plane >= 0 else si[SI_PLANE]
            inc_now = (g_dist == 1) if g_dist >= 0 else incremental
            if plane_now != 0 or has[_AT] or has[_CARET] or (inc_now and has[_X]):
                # G18/G19 polar planes and an incremental radius (G91 X: the current point as
                # the pole) are not read here
                return n, E_POLAR16, kw, li, err_vals, nwarn
            has[_AT] = has[_X]
            val[_AT] = val[_X]
            widx[_AT] = widx[_X]
            has[_CARET] = has[_Y]
            val[_CARET] = val[_Y]
            widx[_CARET] = widx[_Y]
            has[_X] = False
            has[_Y] = False

        # ---- Fanuc G51.1/G50.1 mirror image: the block's axis words set or clear the mirror;
        # on other blocks the mirrored axes' words are reflected (incremental ones negated)
        mflip = False
        if g_mirror >= 0:
            if si[SI_COMP] != 0:
                return n, E_MIRROR, g_mirror_w, li, err_vals, nwarn
            u_now = MM_PER_INCH if ((g_units == 1) if g_units >= 0 else inch) else 1.0
            anyax = has[_X] or has[_Y] or has[_Z]
            for k in range(3):
                L = _X + k
                if g_mirror == 1 and has[L]:
                    mir[k] = True
                    mirc[k] = val[L] * u_now
                elif g_mirror == 0 and (has[L] or not anyax):
                    mir[k] = False
                has[L] = False
        elif (mir[0] or mir[1] or mir[2]) and g_nonmodal < 0:
            if polar16:
                return n, E_MIRROR, widx[_X] if has[_X] else w0, li, err_vals, nwarn
            u_now = MM_PER_INCH if ((g_units == 1) if g_units >= 0 else inch) else 1.0
            inc_now = (g_dist == 1) if g_dist >= 0 else incremental
            for k in range(3):
                if not mir[k]:
                    continue
                L = _X + k
                if has[L] and not (k == 0 and g_dwell and dialect == 0):
                    val[L] = -val[L] if inc_now else 2.0 * mirc[k] / u_now - val[L]
                C = _I + k
                if has[C]:
                    val[C] = (2.0 * mirc[k] / u_now - val[C]) if ijk_abs else -val[C]
            pl_now = g_plane if g_plane >= 0 else si[SI_PLANE]
            b1 = (0, 2, 1)[pl_now]
            b2 = (1, 0, 2)[pl_now]
            mflip = mir[b1] != mir[b2]  # one axis of the plane mirrored: arcs and sides reverse

        # ---- words that no code on this block (or the active mode) uses ----
        mm = g_motion if g_motion >= 0 else motion
        if g_cancel and g_motion < 0:
            mm = -1
        is_arc = mm == 20 or mm == 30
        is_canned = mm >= 730 and mm != 800
        m19 = nm > 0 and _has_code(mcodes, nm, 190)
        ignored = nwarn > nwarn_line
        if has[_R] and m19 and g_path == 640:
            return n, E_AMBIGUOUS_R, widx[_R], li, err_vals, nwarn
        if has[_R] and not ignored and not (is_arc or is_canned or g_nonmodal == 100 or m19 or g_path == 640
                                            or g_rot68 == 1):
            return n, E_UNUSED_WORD, widx[_R], li, err_vals, nwarn
        if m61 and (not has[_Q] or val[_Q] < 0 or val[_Q] != math.floor(val[_Q])):
            return n, E_BAD_VALUE, widx[_Q] if has[_Q] else mword[0], li, err_vals, nwarn
        if has[_Q] and not ignored and not (is_canned or g_path == 640 or m19 or g_lookahead or mm == 50 or m61
                                            or m_io):
            return n, E_UNUSED_WORD, widx[_Q], li, err_vals, nwarn
        if has[_P] and not ignored and not (g_dwell or g_path == 640 or g_nonmodal == 100 or is_canned or m_sub or m19
                                            or m_io
                                            or mm == 50
                                            or g_lookahead
                            or (is_arc and (has[_X] or has[_Y] or has[_Z]))):
            return n, E_UNUSED_WORD, widx[_P], li, err_vals, nwarn
        if has[_L] and not ignored and not (g_nonmodal == 100 or is_canned or m_sub or g_comp == 411 or g_comp == 421
                                            or m_io or m_save > 0):
            return n, E_UNUSED_WORD, widx[_L], li, err_vals, nwarn
        is_sync = mm == 330 or mm == 331
        is_spline = mm == 50 or mm == 51
        for L in (_I, _J, _K):
            if has[L] and not is_arc and not (is_sync and L == _K) and not (mm == 331 and L == _I) \
                    and not (is_spline and L != _K) and mm != 760:
                return n, E_UNUSED_WORD, widx[L], li, err_vals, nwarn
        if e_word and mm != 760 and not m_io:
            return n, E_UNSUPPORTED_WORD, widx[_E], li, err_vals, nwarn
        if has[_CMA]:
            return n, E_UNSUPPORTED_WORD, widx[_CMA], li, err_vals, nwarn  # direct drawing dimensions
        st[SF_CORNER] = 0.0
        if has[_CMC] or has[_CMR]:
            kw = widx[_CMC] if has[_CMC] else widx[_CMR]
            if has[_CMC] and has[_CMR]:
                return n, E_CORNER, kw, li, err_vals, nwarn
            if not (mm == 10 or mm == 20 or mm == 30) or is_canned:
                return n, E_UNUSED_WORD, kw, li, err_vals, nwarn
            cv = val[_CMC] if has[_CMC] else val[_CMR]
            if cv <= 0.0:
                return n, E_BAD_VALUE, kw, li, err_vals, nwarn
            inch_now = (g_units == 1) if g_units >= 0 else inch
            st[SF_CORNER] = cv * (MM_PER_INCH if inch_now else 1.0) * (-1.0 if has[_CMC] else 1.0)

        if m_save > 0:
            lvl = int(val[_L]) if has[_L] else depth
            if lvl < 0 or lvl >= MAX_SAVED:
                return n, E_BAD_VALUE, widx[_L] if has[_L] else mword[0], li, err_vals, nwarn
            if m_save == 1:  # save what the block starts with
                sv_i[lvl, 0] = si[SI_PLANE]
                sv_i[lvl, 1] = si[SI_FEED_MODE]
                sv_i[lvl, 2] = si[SI_SPINDLE_DIR]
                sv_i[lvl, 3] = si[SI_COOLANT]
                sv_i[lvl, 4] = si[SI_WCS]
                sv_i[lvl, 5] = si[SI_PATH_MODE]
                sv_i[lvl, 6] = si[SI_COMP]
                sv_i[lvl, 7] = 1 if inch else 0
                sv_i[lvl, 8] = 1 if incremental else 0
                sv_i[lvl, 9] = 1 if ijk_abs else 0
                sv_i[lvl, 10] = 1 if diameter else 0
                sv_i[lvl, 11] = 1 if retract_old else 0
                sv_f[lvl, 0] = st[SF_FEED]
                sv_f[lvl, 1] = st[SF_SPINDLE]
                sv_f[lvl, 2] = st[SF_PATH_TOL]
                sv_f[lvl, 3] = st[SF_CAM_TOL]
                sv_f[lvl, 4] = st[SF_CSS_ON]
                sv_f[lvl, 5] = st[SF_CSS_MAX]
                sv_f[lvl, 6] = st[SF_TLO]
                sv_f[lvl, 7] = st[SF_COMP_R]
                sv_ok[lvl] = True
            elif m_save == 2:
                sv_ok[lvl] = False
            else:
                if not sv_ok[lvl]:
                    return n, E_NO_SAVED_STATE, mword[0], li, err_vals, nwarn
                if sv_i[lvl, 6] != si[SI_COMP] or sv_f[lvl, 7] != st[SF_COMP_R] or sv_f[lvl, 6] != st[SF_TLO]:
                    return n, E_RESTORE_OFFSETS, mword[0], li, err_vals, nwarn
                # modal codes the block does not set itself come back through their own steps
                if g_plane < 0:
                    g_plane = sv_i[lvl, 0]
                if g_feedmode < 0:
                    g_feedmode = sv_i[lvl, 1]
                if g_wcs < 0 and sv_i[lvl, 4] != si[SI_WCS]:
                    g_wcs = sv_i[lvl, 4]
                if g_units < 0:
                    g_units = sv_i[lvl, 7]
                if g_dist < 0:
                    g_dist = sv_i[lvl, 8]
                if g_ijk < 0:
                    g_ijk = sv_i[lvl, 9]
                if g_diam < 0:
                    g_diam = sv_i[lvl, 10]
                if g_retract < 0:
                    g_retract = 980 if sv_i[lvl, 11] == 1 else 990
                if m_spindle == -2:
                    m_spindle = sv_i[lvl, 2]
                if m_cool < 0:
                    m_cool = sv_i[lvl, 3]
                si[SI_PATH_MODE] = sv_i[lvl, 5]
                st[SF_FEED] = sv_f[lvl, 0]
                st[SF_SPINDLE] = sv_f[lvl, 1]
                st[SF_PATH_TOL] = sv_f[lvl, 2]
                st[SF_CAM_TOL] = sv_f[lvl, 3]
                st[SF_CSS_ON] = sv_f[lvl, 4]
                st[SF_CSS_MAX] = sv_f[lvl, 5]
        if g_diam >= 0:
            diameter = g_diam == 1
        if diameter and has[_X]:
            val[_X] *= 0.5  # every X word, also G10/G53/G92 (as LinuxCNC); I stays a radius
        scale = MM_PER_INCH if inch else 1.0
        # 1. feed mode
        if g_feedmode >= 0:
            si[SI_FEED_MODE] = g_feedmode
        # 2. F (in the units active before this block's G20/G21)
        if has[_F]:
            if val[_F] < 0:
                return n, E_BAD_VALUE, widx[_F], li, err_vals, nwarn
            st[SF_FEED] = val[_F] if si[SI_FEED_MODE] == 2 else val[_F] * scale
            if g_units >= 0 and (g_units == 1) != inch and si[SI_FEED_MODE] != 2:
                # G20 F6 on one line: F is read in the units before the switch (as LinuxCNC
                # does), which a programmer from the other system does not expect
                nwarn = _warn(warn_code, warn_word, nwarn, W_F_BEFORE_UNITS, widx[_F])
        # 3. S
        if has[_S]:
            if val[_S] < 0:
                return n, E_BAD_VALUE, widx[_S], li, err_vals, nwarn
            st[SF_SPINDLE] = val[_S]
        if g_css == 1:
            st[SF_CSS_ON] = 1.0
            st[SF_CSS_MAX] = abs(val[_D]) if has[_D] else 0.0
        elif g_css == 0:
            st[SF_CSS_ON] = 0.0
        # 4. T
        if has[_T]:
            if val[_T] < 0 or val[_T] != math.floor(val[_T]):
                return n, E_BAD_VALUE, widx[_T], li, err_vals, nwarn
            tool_sel = int(val[_T])
        # 5. tool change
        if m_tc:
            si[SI_TOOL] = tool_sel
            last_change[0] = tool_sel
            last_change[1] = li
            last_change[2] = n
        if m61:
            si[SI_TOOL] = int(val[_Q])
            tool_sel = si[SI_TOOL]
        # 6. spindle, 7. coolant
        if m_spindle != -2:
            si[SI_SPINDLE_DIR] = m_spindle
        if m_cool >= 0:
            si[SI_COOLANT] = m_cool
        # units change happens before dwell/motion but after F
        f_inch = inch
        if g_units >= 0:
            inch = g_units == 1
            scale = MM_PER_INCH if inch else 1.0
        base = 0
        if inch:
            base |= FL_INCH
        if diameter:
            base |= FL_DIAMETER
        if f_inch:
            base |= FL_F_INCH
        if mir[0] or mir[1] or mir[2]:
            base |= FL_MIRROR
        # 8. dwell
        if g_dwell:
            if has[_P]:
                dw = val[_P]
                if dialect == 0 and w_ndec[widx[_P]] < 0:
                    dw = dw / 1000.0  # Fanuc: P without a point is milliseconds
            elif has[_X] and dialect == 0:
                dw = val[_X]
            else:
                return n, E_BAD_VALUE, gword[0], li, err_vals, nwarn
            if dw < 0:
                return n, E_BAD_VALUE, widx[_P] if has[_P] else widx[_X], li, err_vals, nwarn
            si[SI_FLAGS] = base | (FL_SUB if depth > 0 else 0)
            n = _emit(out, n, DWELL, li, pos, pos, pos, 0, dw, st, si, wcs_off, FL_FIRST_IN_LINE)
        # 9. plane
        if g_plane >= 0:
            si[SI_PLANE] = g_plane
        # 10. tool length
        if g_tlo == 430:
            hn = si[SI_TOOL]
            if has[_H]:
                hn = int(val[_H])
            if hn < 0 or hn >= tool_len.size or (have_tool_table and not tool_known[hn]):
                return n, E_TOOL_OFFSET_MISSING, widx[_H] if has[_H] else -1, li, err_vals, nwarn
            _set_tool_offset(pos, st, si[SI_WCS], wcs_off, tool_len[hn], tool_xy[hn, 0], tool_xy[hn, 1])
        elif g_tlo == 490:
            _set_tool_offset(pos, st, si[SI_WCS], wcs_off, 0.0, 0.0, 0.0)
        elif g_tlo == 431:
            # G43.1: dynamic offsets given by the axis words (which do not move the tool)
            _set_tool_offset(pos, st, si[SI_WCS], wcs_off,
                             val[_Z] * scale if has[_Z] else 0.0,
                             val[_X] * scale if has[_X] else 0.0,
                             val[_Y] * scale if has[_Y] else 0.0)
        elif g_tlo == 432:
            # G43.2 H: add another tool's offsets to the active ones
            if not has[_H]:
                return n, E_TOOL_OFFSET_MISSING, -1, li, err_vals, nwarn
            hn = int(val[_H])
            if hn < 0 or hn >= tool_len.size or (have_tool_table and not tool_known[hn]):
                return n, E_TOOL_OFFSET_MISSING, widx[_H], li, err_vals, nwarn
            _set_tool_offset(pos, st, si[SI_WCS], wcs_off, st[SF_TLO] + tool_len[hn],
                             st[SF_TOX] + tool_xy[hn, 0], st[SF_TOY] + tool_xy[hn, 1])
        # 10b. cutter radius compensation (G17 only); the offset path is computed after
        # interpretation from the records' side and radius (gcode/cutcomp.py)
        if g_comp == 400:
            si[SI_COMP] = 0
            si[SI_COMP_ORIENT] = 0
            st[SF_COMP_R] = 0.0
        elif g_comp >= 410:
            if si[SI_PLANE] == 2:
                return n, E_COMP_YZ, g_comp_w, li, err_vals, nwarn
            if si[SI_COMP] != 0:
                return n, E_COMP_ACTIVE, g_comp_w, li, err_vals, nwarn
            si[SI_COMP] = 1 if (g_comp == 410 or g_comp == 411) else 2
            if mflip:
                si[SI_COMP] = 3 - si[SI_COMP]  # a mirrored path keeps the tool on the mirrored side
            if g_comp == 411 or g_comp == 421:
                # G41.1/G42.1 D<diameter> [L<lathe tool orientation>]
                if not has[_D]:
                    return n, E_COMP_PLANE, g_comp_w, li, err_vals, nwarn
                if has[_L]:
                    if val[_L] != math.floor(val[_L]) or val[_L] < 0 or val[_L] > 9:
                        return n, E_BAD_VALUE, widx[_L], li, err_vals, nwarn
                    si[SI_COMP_ORIENT] = int(val[_L])
                else:
                    si[SI_COMP_ORIENT] = 0
                st[SF_COMP_R] = 0.5 * abs(val[_D]) * scale
                if val[_D] < 0.0:
                    si[SI_COMP] = 3 - si[SI_COMP]  # a negative diameter swaps the side (as LinuxCNC)
            else:
                dn = int(val[_D]) if has[_D] else si[SI_TOOL]
                if dn < 0 or dn >= comp_r.size:
                    return n, E_BAD_VALUE, widx[_D] if has[_D] else g_comp_w, li, err_vals, nwarn
                if not comp_known[dn]:
                    # no radius known for this D: the CAM path is taken as compensated already
                    nwarn = _warn(warn_code, warn_word, nwarn, W_COMP_RADIUS_UNKNOWN, widx[_D] if has[_D] else g_comp_w)
                st[SF_COMP_R] = comp_r[dn]
        # 11. work offsets: positions stay in program coordinates of the new frame
        if g_wcs >= 0:
            _to_machine(pos, si[SI_WCS], wcs_off, mach)
            _from_machine(mach, g_wcs, wcs_off, pos)
            si[SI_WCS] = g_wcs
        # 11b. Fanuc G68/G69: the tool stays where it is; later points are turned about the centre
        if g_rot68 >= 0:
            _to_machine(pos, si[SI_WCS], wcs_off, mach)
            if g_rot68 == 1:
                if si[SI_PLANE] != 0 or not has[_R]:
                    return n, E_ROT_PLANE, g_rot68_w, li, err_vals, nwarn
                wcs_off[11, 0] = val[_X] * scale if has[_X] else pos[0]
                wcs_off[11, 1] = val[_Y] * scale if has[_Y] else pos[1]
                wcs_off[11, 3] = val[_R]
            else:
                for q in range(4):
                    wcs_off[11, q] = 0.0
            _from_machine(mach, si[SI_WCS], wcs_off, pos)
        # 12. path mode
        if g_path == 610:
            si[SI_PATH_MODE] = 1
            st[SF_PATH_TOL] = 0.0
            st[SF_CAM_TOL] = 0.0
        elif g_path == 611:
            si[SI_PATH_MODE] = 2
            st[SF_PATH_TOL] = 0.0
            st[SF_CAM_TOL] = 0.0
        elif g_path == 640:
            si[SI_PATH_MODE] = 0
            st[SF_PATH_TOL] = val[_P] * scale if has[_P] else 0.0
            # LinuxCNC's naive-CAM (collinear merge) tolerance: Q, or P when Q is absent
            st[SF_CAM_TOL] = val[_Q] * scale if has[_Q] else st[SF_PATH_TOL]
        # 13. distance modes
        if g_dist >= 0:
            incremental = g_dist == 1
        if g_ijk >= 0:
            ijk_abs = g_ijk == 1
        if incremental:
            base |= FL_INCREMENTAL
        if ijk_abs:
            base |= FL_IJK_ABSOLUTE
        if depth > 0:
            base |= FL_SUB
        si[SI_FLAGS] = base
        # 14. retract mode
        if g_retract >= 0:
            retract_old = g_retract == 980
        # motion mode update
        if g_cancel and (motion >= 730 and motion != 800):
            # RS274NGC: G80 leaves no motion mode; Fanuc: canned cycles are a group of their
            # own, so the G00/G01/G02/G03 mode from before the cycle is back in force
            motion = motion_base if dialect == 0 else -1
        if g_cancel or (g_motion >= 0 and not (g_motion == 730 or (g_motion >= 810 and g_motion <= 890))):
            canned_init = math.nan  # the series of cycles ends: the next one starts a new one
        if g_motion >= 0:
            motion = g_motion
            if g_motion < 730:
                motion_base = g_motion
        rotary = has[_A] or has[_B] or has[_C] or has[_U] or has[_V] or has[_W]
        if rotary and (g_nonmodal == 100 or g_nonmodal == 920):
            # rotary work offsets are not modelled
            return n, E_ROTARY_USE, _first_extra_word(has, widx), li, err_vals, nwarn
        polar = has[_AT] or has[_CARET]
        if polar and (has[_X] or has[_Y] or si[SI_PLANE] != 0 or g_nonmodal >= 0):
            return n, E_POLAR, widx[_AT] if has[_AT] else widx[_CARET], li, err_vals, nwarn
        has_axis = has[_X] or has[_Y] or has[_Z] or polar or rotary
        if g_tlo == 431 or g_rot68 == 1:
            has_axis = False  # G43.1 offsets, G68 centre
        if g_motion >= 382 and g_motion <= 385 and not (has[_X] or has[_Y] or has[_Z]):
            return n, E_PROBE, g_motion_w, li, err_vals, nwarn  # a probe move needs a target
        if g_dwell and dialect == 0:
            has_axis = has[_Y] or has[_Z]  # Fanuc G4 X is the dwell time
        saved_path_mode = si[SI_PATH_MODE]
        if g_exact_stop_once:
            si[SI_PATH_MODE] = 2
        first_flag = 0 if g_dwell else FL_FIRST_IN_LINE

        # 15. G10 / G28 / G30 / G53
        if g_nonmodal == 100 and dialect == 0 and has[_L] and 10 <= val[_L] <= 13 and val[_L] == int(val[_L]):
            # Fanuc G10 L10/L11 P<n> R<v>: geometry/wear of length offset Hn; L12/L13: of
            # radius offset Dn; G91 adds to the value.  Takes effect at the next H or D.
            lv = int(val[_L])
            t = int(val[_P]) if has[_P] else -1
            if not has[_P] or not has[_R] or val[_P] != t:
                return n, E_BAD_G10, g_nonmodal_w, li, err_vals, nwarn
            if t < 0 or t >= tool_len.size or t >= comp_r.size:
                return n, E_BAD_VALUE, widx[_P], li, err_vals, nwarn
            v = val[_R] * scale
            inc_now = incremental
            if lv == 10:
                h_geo[t] = h_geo[t] + v if inc_now else v
            elif lv == 11:
                h_wear[t] = h_wear[t] + v if inc_now else v
            elif lv == 12:
                d_geo[t] = d_geo[t] + v if inc_now else v
            else:
                d_wear[t] = d_wear[t] + v if inc_now else v
            if lv <= 11:
                tool_len[t] = h_geo[t] + h_wear[t]
                tool_known[t] = True
            else:
                comp_r[t] = abs(d_geo[t] + d_wear[t])
                comp_known[t] = True
        elif g_nonmodal == 100:
            lv = int(val[_L]) if has[_L] else -1
            if not has[_P] or not (lv == 1 or lv == 2 or lv == 10 or lv == 11 or lv == 20) \
                    or (has[_L] and val[_L] != lv):
                return n, E_BAD_G10, g_nonmodal_w, li, err_vals, nwarn
            if lv == 2 or lv == 20:
                p = int(val[_P])
                if p < 0 or p > 9 or val[_P] != p:
                    return n, E_BAD_WCS, widx[_P], li, err_vals, nwarn
                p = si[SI_WCS] if p == 0 else p - 1
                active = p == si[SI_WCS]
                # the machine position of the tool does not move; its program position may
                _to_machine(pos, si[SI_WCS], wcs_off, mach)
                if lv == 2:
                    if has[_R]:
                        wcs_off[p, 3] = val[_R]
                    for a, L in ((0, _X), (1, _Y), (2, _Z)):
                        if has[L]:
                            wcs_off[p, a] = val[L] * scale
                else:
                    # L20: the origin is placed so that the current point reads as the given values
                    _from_machine(mach, p, wcs_off, tmp)
                    if has[_R]:
                        wcs_off[p, 3] = val[_R]
                    for a, L in ((0, _X), (1, _Y), (2, _Z)):
                        if has[L]:
                            tmp[a] = val[L] * scale
                    rx, ry = _rotate(p, wcs_off, tmp[0] + wcs_off[9, 0], tmp[1] + wcs_off[9, 1])
                    wcs_off[p, 0] = mach[0] - rx
                    wcs_off[p, 1] = mach[1] - ry
                    wcs_off[p, 2] = mach[2] - tmp[2] - wcs_off[9, 2]
                if active:
                    _from_machine(mach, p, wcs_off, pos)
            else:
                # tool table: L1 sets the offsets, L10/L11 so that the current point reads as given
                t = int(val[_P])
                if t < 0 or t >= tool_len.size or val[_P] != t:
                    return n, E_BAD_VALUE, widx[_P], li, err_vals, nwarn
                if has[_R]:
                    if t < comp_r.size:
                        comp_r[t] = abs(val[_R]) * scale
                        comp_known[t] = True
                if lv == 1:
                    if has[_X]:
                        tool_xy[t, 0] = val[_X] * scale
                    if has[_Y]:
                        tool_xy[t, 1] = val[_Y] * scale
                    if has[_Z]:
                        tool_len[t] = val[_Z] * scale
                else:
                    # work in the rotated frame of the reference system (LinuxCNC keeps the
                    # offsets of axes not given, as seen in that frame)
                    ref = si[SI_WCS] if lv == 10 else 8
                    ox, oy = _unrotate(ref, wcs_off, tool_xy[t, 0], tool_xy[t, 1])
                    if lv == 10:
                        ax, ay = _unrotate(ref, wcs_off, st[SF_TOX], st[SF_TOY])
                        cx = pos[0] + ax
                        cy = pos[1] + ay
                        cz = pos[2] + st[SF_TLO]
                    else:
                        # G59.3 without G92: the tool-setter fixture
                        _to_machine(pos, si[SI_WCS], wcs_off, mach)
                        ax, ay = _unrotate(8, wcs_off, mach[0] + st[SF_TOX] - wcs_off[8, 0],
                                           mach[1] + st[SF_TOY] - wcs_off[8, 1])
                        cx = ax
                        cy = ay
                        cz = mach[2] + st[SF_TLO] - wcs_off[8, 2]
                    if has[_X]:
                        ox = cx - val[_X] * scale
                    if has[_Y]:
                        oy = cy - val[_Y] * scale
                    if has[_Z]:
                        tool_len[t] = cz - val[_Z] * scale
                    tool_xy[t, 0], tool_xy[t, 1] = _rotate(ref, wcs_off, ox, oy)
                tool_known[t] = True
            has_axis = False
        elif g_nonmodal == 280 or g_nonmodal == 300:
            home = home28 if g_nonmodal == 280 else home30
            if g_nonmodal_code == 281 or g_nonmodal_code == 301:
                # G28.1 / G30.1: remember the current machine position
                _to_machine(pos, si[SI_WCS], wcs_off, mach)
                home[0] = mach[0] + st[SF_TOX]
                home[1] = mach[1] + st[SF_TOY]
                home[2] = mach[2] + st[SF_TLO]
                for q in range(6):
                    home[3 + q] = st[SF_A + q]
            else:
                for a in range(3):
                    s[a] = pos[a]
                    e[a] = pos[a]
                # intermediate point, in the active distance mode (LinuxCNC moves there even
                # when it is where the tool is)
                for a, L in ((0, _X), (1, _Y), (2, _Z)):
                    if has[L]:
                        e[a] = pos[a] + val[L] * scale if incremental else val[L] * scale
                rfl = _move_rotary(st, has, val, incremental, scale) if rotary else 0
                n = _emit(out, n, RAPID, li, s, e, e, 0, 0.0, st, si, wcs_off, first_flag | rfl)
                first_flag = 0
                for a in range(3):
                    s[a] = e[a]
                # the named axes (all when none is named) go to the stored machine position
                _to_machine(e, si[SI_WCS], wcs_off, mach)
                tofs = (st[SF_TOX], st[SF_TOY], st[SF_TLO])
                for a, L in ((0, _X), (1, _Y), (2, _Z)):
                    if has[L] or not has_axis:
                        mach[a] = home[a] - tofs[a]
                _from_machine(mach, si[SI_WCS], wcs_off, e)
                rfl = 0
                for q, L in ((0, _A), (1, _B), (2, _C), (3, _U), (4, _V), (5, _W)):
                    if (has[L] or not has_axis) and st[SF_A + q] != home[3 + q]:
                        st[SF_A + q] = home[3 + q]
                        rfl = FL_ROTARY
                n = _emit(out, n, RAPID, li, s, e, e, 0, 0.0, st, si, wcs_off, FL_MACHINE | rfl)
                for a in range(3):
                    pos[a] = e[a]
            has_axis = False
        elif g_nonmodal == 920:
            # G92: offset the coordinates so that the current point reads as the given values
            for a, L in ((0, _X), (1, _Y), (2, _Z)):
                if has[L]:
                    v = val[L] * scale
                    wcs_off[9, a] = pos[a] + wcs_off[9, a] - v
                    wcs_off[10, a] = wcs_off[9, a]
                    pos[a] = v
            has_axis = False
        elif g_nonmodal == 520:
            # G52 local offset: sets the offset G92 also uses (LinuxCNC; Fanuc's local system)
            for a, L in ((0, _X), (1, _Y), (2, _Z)):
                if has[L]:
                    v = val[L] * scale
                    pos[a] += wcs_off[9, a] - v
                    wcs_off[9, a] = v
                    wcs_off[10, a] = v
            has_axis = False
        elif g_nonmodal == 921 or g_nonmodal == 922 or g_nonmodal == 923:
            # G92.1 / G92.2 cancel the offset (G92.1 also forgets it); G92.3 restores it
            for a in range(3):
                new = wcs_off[10, a] if g_nonmodal == 923 else 0.0
                pos[a] += wcs_off[9, a] - new
                wcs_off[9, a] = new
                if g_nonmodal == 921:
                    wcs_off[10, a] = 0.0
        elif g_nonmodal == 530:
            if not (motion == 0 or motion == 10) or (g_motion >= 0 and g_motion != 0 and g_motion != 10):
                return n, E_G53_MODE, g_nonmodal_w, li, err_vals, nwarn
            for a in range(3):
                s[a] = pos[a]
            _to_machine(pos, si[SI_WCS], wcs_off, mach)
            tofs = (st[SF_TOX], st[SF_TOY], st[SF_TLO])
            for a, L in ((0, _X), (1, _Y), (2, _Z)):
                if has[L]:
                    mach[a] = val[L] * scale - tofs[a]
            _from_machine(mach, si[SI_WCS], wcs_off, e)
            if rotary:
                first_flag |= _move_rotary(st, has, val, False, scale)  # no rotary offsets: machine = program
            if has_axis:
                kind = RAPID if motion == 0 else LINEAR
                if kind == LINEAR and st[SF_FEED] <= 0.0:
                    if not (lenient and not has[_F]):
                        return n, E_ZERO_FEED, g_nonmodal_w, li, err_vals, nwarn
                    nwarn = _warn(warn_code, warn_word, nwarn, W_NO_FEED, g_nonmodal_w)
                n = _emit(out, n, kind, li, s, e, e, 0, 0.0, st, si, wcs_off, first_flag | FL_MACHINE)
                for a in range(3):
                    pos[a] = e[a]
            has_axis = False

        # 16. motion
        if has_axis or (g_motion >= 20 and g_motion <= 30 and (has[_I] or has[_J] or has[_K])):
            if motion < 0:
                kw = widx[_X] if has[_X] else (widx[_Y] if has[_Y] else widx[_Z])
                return n, E_NO_MOTION_MODE, kw, li, err_vals, nwarn
            for a in range(3):
                s[a] = pos[a]
            prev_g5 = spline_prev
            spline_prev = False
            if motion == 330 or motion == 331:
                # spindle-synchronised: G33 a thread, G33.1 a rigid tap (in, spindle reversed,
                # back out to the start at the same pitch); feed = K (per rev) x S
                if polar or rotary or not has[_K] or val[_K] <= 0.0 or st[SF_SPINDLE] <= 0.0:
                    return n, E_SYNC, g_motion_w if g_motion_w >= 0 else widx[_K] if has[_K] else -1, li, \
                        err_vals, nwarn
                _target(e, pos, has, val, scale, incremental)
                fmode = si[SI_FEED_MODE]
                fword = st[SF_FEED]
                si[SI_FEED_MODE] = 1
                st[SF_FEED] = val[_K] * scale
                n = _emit(out, n, LINEAR, li, s, e, e, 0, 0.0, st, si, wcs_off, first_flag | FL_SYNC)
                if motion == 331:
                    n = _emit(out, n, LINEAR, li, e, s, s, 0, 0.0, st, si, wcs_off, FL_SYNC)
                    for a in range(3):
                        e[a] = s[a]
                si[SI_FEED_MODE] = fmode
                st[SF_FEED] = fword
                for a in range(3):
                    pos[a] = e[a]
            elif motion == 760:
                n = _thread_cycle(out, n, li, pos, has, val, scale, st, si, wcs_off, first_flag)
                if n < 0:
                    return -n - 1, E_THREAD, g_motion_w if g_motion_w >= 0 else -1, li, err_vals, nwarn
            elif motion >= 382 and motion <= 385:
                # G38.2-G38.5: where the probe trips is known only on the machine
                if not lenient:
                    return n, E_PROBE, g_motion_w if g_motion_w >= 0 else -1, li, err_vals, nwarn
                if polar or rotary:
                    return n, E_PROBE, g_motion_w if g_motion_w >= 0 else -1, li, err_vals, nwarn
                if st[SF_FEED] <= 0.0:
                    return n, E_ZERO_FEED, g_motion_w, li, err_vals, nwarn
                _target(e, pos, has, val, scale, incremental)
                n = _emit(out, n, LINEAR, li, s, e, e, 0, 0.0, st, si, wcs_off, first_flag | FL_PROBE)
                nwarn = _warn(warn_code, warn_word, nwarn, W_PROBE, g_motion_w if g_motion_w >= 0 else w0)
                for a in range(3):
                    pos[a] = e[a]
            elif motion == 50 or motion == 51:
                # G5 cubic / G5.1 quadratic B-spline in the XY plane, followed by short lines
                if si[SI_PLANE] != 0 or has[_Z] or polar or rotary or si[SI_FEED_MODE] == 2 \
                        or (motion == 51 and not (has[_I] or has[_J])) \
                        or (motion == 50 and not (has[_P] and has[_Q])) \
                        or (motion == 50 and not (has[_I] or has[_J]) and not prev_g5):
                    return n, E_SPLINE, g_motion_w if g_motion_w >= 0 else -1, li, err_vals, nwarn
                if st[SF_FEED] <= 0.0:
                    return n, E_ZERO_FEED, g_motion_w, li, err_vals, nwarn
                _target(e, pos, has, val, scale, incremental)
                if has[_I] or has[_J]:
                    c1x = pos[0] + (val[_I] * scale if has[_I] else 0.0)
                    c1y = pos[1] + (val[_J] * scale if has[_J] else 0.0)
                else:
                    # a G5 without I J continues smoothly: the last control point mirrored
                    c1x = 2 * pos[0] - spline_c2[0]
                    c1y = 2 * pos[1] - spline_c2[1]
                if motion == 50:
                    c2x = e[0] + val[_P] * scale
                    c2y = e[1] + val[_Q] * scale
                    spline_c2[0] = c2x
                    spline_c2[1] = c2y
                    ddx = max(abs(pos[0] - 2 * c1x + c2x), abs(c1x - 2 * c2x + e[0]))
                    ddy = max(abs(pos[1] - 2 * c1y + c2y), abs(c1y - 2 * c2y + e[1]))
                    curv = 6.0 * math.hypot(ddx, ddy)
                else:
                    c2x = c1x
                    c2y = c1y
                    curv = 2.0 * math.hypot(pos[0] - 2 * c1x + e[0], pos[1] - 2 * c1y + e[1])
                # chord error of a piece dt long is at most |B''| dt^2 / 8
                pieces = int(math.ceil(math.sqrt(curv / (8.0 * SPLINE_TOL_MM))))
                pieces = min(max(pieces, 1), SPLINE_MAX_PIECES)
                x0 = pos[0]
                y0 = pos[1]
                for a in range(3):
                    c[a] = pos[a]
                fl = first_flag | FL_SPLINE
                for q in range(1, pieces + 1):
                    t = q / pieces
                    u = 1.0 - t
                    if motion == 50:
                        px = u * u * u * x0 + 3 * u * u * t * c1x + 3 * u * t * t * c2x + t * t * t * e[0]
                        py = u * u * u * y0 + 3 * u * u * t * c1y + 3 * u * t * t * c2y + t * t * t * e[1]
                    else:
                        px = u * u * x0 + 2 * u * t * c1x + t * t * e[0]
                        py = u * u * y0 + 2 * u * t * c1y + t * t * e[1]
                    if q == pieces:
                        px = e[0]
                        py = e[1]
                    s[0] = c[0]
                    s[1] = c[1]
                    c[0] = px
                    c[1] = py
                    n = _emit(out, n, LINEAR, li, s, c, c, 0, 0.0, st, si, wcs_off, fl)
                    fl = FL_SPLINE
                for a in range(3):
                    pos[a] = e[a]
                spline_prev = motion == 50
            elif motion <= 30:
                _target(e, pos, has, val, scale, incremental)
                if polar:
                    e[0], e[1] = _polar_xy(pos[0], pos[1], has[_AT], val[_AT] * scale, has[_CARET], val[_CARET],
                                           incremental)
                    first_flag |= FL_POLAR
                if rotary:
                    first_flag |= _move_rotary(st, has, val, incremental, scale)
                if motion == 0:
                    n = _emit(out, n, RAPID, li, s, e, e, 0, 0.0, st, si, wcs_off, first_flag)
                else:
                    if si[SI_FEED_MODE] == 2:
                        if not has[_F]:
                            return n, E_INVERSE_NO_F, g_motion_w, li, err_vals, nwarn
                    if st[SF_FEED] <= 0.0:
                        kw = g_motion_w if g_motion >= 0 else (widx[_F] if has[_F] else -1)
                        if not (lenient and not has[_F]):
                            return n, E_ZERO_FEED, kw, li, err_vals, nwarn
                        # a called macro whose feed comes from its caller: readable, not simulable
                        nwarn = _warn(warn_code, warn_word, nwarn, W_NO_FEED, kw if kw >= 0 else w0)
                    if motion == 10:
                        n = _emit(out, n, LINEAR, li, s, e, e, 0, 0.0, st, si, wcs_off, first_flag)
                        if si[SI_FEED_MODE] == 2 and n <= out.size:
                            out[n - 1].feed = math.sqrt((e[0] - s[0]) ** 2 + (e[1] - s[1]) ** 2
                                                        + (e[2] - s[2]) ** 2) * st[SF_FEED]
                    else:
                        pl = si[SI_PLANE]
                        if pl != 0 and wcs_off[si[SI_WCS], 3] + wcs_off[11, 3] != 0.0:
                            return n, E_ROT_PLANE, g_motion_w, li, err_vals, nwarn
                        a1 = (0, 2, 1)[pl]
                        a2 = (1, 0, 2)[pl]
                        an = (2, 1, 0)[pl]
                        ccw = (motion == 30) != mflip
                        turns = 0
                        if has[_P]:
                            tp = val[_P]
                            if tp < 1 or tp != math.floor(tp):
                                return n, E_BAD_TURNS, widx[_P], li, err_vals, nwarn
                            if tp > MAX_REPEATS:  # (a helix of more turns is a typo; the records hold int16)
                                return n, E_REPEATS, widx[_P], li, err_vals, nwarn
                            turns = int(tp) - 1
                        ctol = CENTER_TOL_INCH_MM if inch else CENTER_TOL_MM
                        fl = first_flag
                        if has[_R]:
                            fl |= FL_R_ARC
                            rr = val[_R] * scale
                            d1 = e[a1] - s[a1]
                            d2 = e[a2] - s[a2]
                            chord = math.hypot(d1, d2)
                            if chord < 1e-12:
                                return n, E_ARC_R_FULL_CIRCLE, widx[_R], li, err_vals, nwarn
                            h = chord / 2.0
                            if h - abs(rr) > RADIUS_TOL_MM:
                                err_vals[0] = abs(rr)
                                err_vals[1] = h
                                return n, E_ARC_R_TOO_SMALL, widx[_R], li, err_vals, nwarn
                            dd = math.sqrt(max(rr * rr - h * h, 0.0))
                            sgn = (1.0 if ccw else -1.0) * (1.0 if rr > 0 else -1.0)
                            c[a1] = s[a1] + d1 / 2.0 - sgn * d2 / chord * dd
                            c[a2] = s[a2] + d2 / 2.0 + sgn * d1 / chord * dd
                        else:
                            L1 = (_I, _K, _J)[pl]
                            L2 = (_J, _I, _K)[pl]
                            if not (has[L1] or has[L2]):
                                return n, E_ARC_NO_CENTER, g_motion_w, li, err_vals, nwarn
                            o1 = val[L1] * scale if has[L1] else 0.0
                            o2 = val[L2] * scale if has[L2] else 0.0
                            if ijk_abs:
                                c[a1] = o1
                                c[a2] = o2
                            else:
                                c[a1] = s[a1] + o1
                                c[a2] = s[a2] + o2
                            r1 = math.hypot(s[a1] - c[a1], s[a2] - c[a2])
                            r2 = math.hypot(e[a1] - c[a1], e[a2] - c[a2])
                            if r1 < RADIUS_TOL_MM or r2 < RADIUS_TOL_MM:
                                return n, E_ARC_ZERO_RADIUS, g_motion_w, li, err_vals, nwarn
                            aerr = abs(r1 - r2)
                            bad = aerr > 100.0 * ctol or (aerr > ctol and aerr / max(r1, r2) > SPIRAL_REL_TOL)
                            if bad and lenient and (aerr <= LENIENT_SPIRAL_REL * max(r1, r2)
                                                    or aerr <= LENIENT_SPIRAL_ABS_MM):
                                # controls such as Mach3 and Grbl run these (as a spiral, or
                                # with a jump at the end): --lenient takes the spiral
                                bad = False
                                nwarn = _warn(warn_code, warn_word, nwarn, W_ARC_SPIRAL, g_motion_w if g_motion_w >= 0 else widx[L1])
                            if bad:
                                err_vals[0] = r1
                                err_vals[1] = r2
                                err_vals[2] = aerr
                                err_vals[3] = c[a1] if a1 == 0 else c[a2]
                                return n, E_ARC_RADIUS_MISMATCH, g_motion_w if g_motion_w >= 0 else -1, \
                                    li, err_vals, nwarn
                        c[an] = s[an]
                        n = _emit(out, n, ARC_CCW if ccw else ARC_CW, li, s, e, c, turns, 0.0, st, si,
                                  wcs_off, fl)
                        if si[SI_FEED_MODE] == 2 and n <= out.size:
                            out[n - 1].feed = _arc_len(s, e, c, a1, a2, an, ccw, turns) * st[SF_FEED]
                for a in range(3):
                    pos[a] = e[a]
            else:
                # ---- canned cycles ----
                if rotary:
                    return n, E_ROTARY_USE, _first_extra_word(has, widx), li, err_vals, nwarn
                pl = si[SI_PLANE]
                a1 = (0, 2, 1)[pl]
                a2 = (1, 0, 2)[pl]
                an = (2, 1, 0)[pl]
                LN = (_Z, _Y, _X)[pl]
                L1 = (_X, _Z, _Y)[pl]
                L2 = (_Y, _X, _Z)[pl]
                if has[_R]:
                    canned_r = val[_R] * scale
                if has[LN]:
                    canned_z = val[LN] * scale
                if has[_Q]:
                    canned_q = val[_Q] * scale
                if has[_P]:
                    pv = val[_P]
                    if dialect == 0 and w_ndec[widx[_P]] < 0:
                        pv = pv / 1000.0
                    canned_p = pv
                if math.isnan(canned_z):
                    return n, E_CANNED_NO_Z, g_motion_w, li, err_vals, nwarn
                if math.isnan(canned_r):
                    return n, E_CANNED_NO_R, g_motion_w, li, err_vals, nwarn
                reps = 1
                if has[_L]:
                    if val[_L] < 0 or val[_L] != math.floor(val[_L]):
                        return n, E_BAD_VALUE, widx[_L], li, err_vals, nwarn
                    if val[_L] > MAX_REPEATS:
                        return n, E_REPEATS, widx[_L], li, err_vals, nwarn
                    reps = int(val[_L])
                if math.isnan(canned_init):
                    canned_init = pos[an]  # the first block of a series
                old_n = canned_init
                if incremental:
                    r_lvl = old_n + canned_r
                    bottom = r_lvl + canned_z
                else:
                    r_lvl = canned_r
                    bottom = canned_z
                if r_lvl < bottom:
                    err_vals[0] = r_lvl
                    err_vals[1] = bottom
                    return n, E_CANNED_R_BELOW_Z, g_motion_w, li, err_vals, nwarn
                if (motion == 830 or motion == 730) and (math.isnan(canned_q) or canned_q <= 0):
                    return n, E_CANNED_Q, g_motion_w, li, err_vals, nwarn
                if st[SF_FEED] <= 0.0:
                    return n, E_ZERO_FEED, g_motion_w, li, err_vals, nwarn
                clear = max(old_n, r_lvl) if retract_old else r_lvl
                pclear = PECK_CLEAR_INCH_MM if inch else PECK_CLEAR_MM
                si[SI_PATH_MODE] = 1  # cycles run in exact-path mode
                fl = first_flag | FL_CANNED
                # preliminary move up to the R level (LinuxCNC: whenever the series' initial
                # level is below R, even from R itself or from above it)
                for a in range(3):
                    s[a] = pos[a]
                    e[a] = pos[a]
                if (old_n < r_lvl) if dialect != 0 else (pos[an] < r_lvl):
                    e[an] = r_lvl
                    n = _emit(out, n, RAPID, li, s, e, e, 0, 0.0, st, si, wcs_off, fl)
                    fl = FL_CANNED
                    pos[an] = r_lvl
                for rep in range(reps):
                    # move in the plane to the hole (Fanuc: at the current height)
                    for a in range(3):
                        s[a] = pos[a]
                        e[a] = pos[a]
                    if polar:
                        # each repetition adds the polar increments again (a bolt circle)
                        e[0], e[1] = _polar_xy(pos[0], pos[1], has[_AT], val[_AT] * scale, has[_CARET],
                                               val[_CARET], incremental)
                        fl |= FL_POLAR
                    elif incremental:
                        if has[L1]:
                            e[a1] = pos[a1] + val[L1] * scale
                        if has[L2]:
                            e[a2] = pos[a2] + val[L2] * scale
                    else:
                        if has[L1]:
                            e[a1] = val[L1] * scale
                        if has[L2]:
                            e[a2] = val[L2] * scale
                    if dialect != 0 and not (rep == 0 and pos[an] > r_lvl):
                        # LinuxCNC moves to the next hole at the clearance level, from
                        # wherever the last retract left the tool (from R after G99 up to the
                        # initial level for a G98 block: a slanting rapid)
                        e[an] = clear
                    n = _emit(out, n, RAPID, li, s, e, e, 0, 0.0, st, si, wcs_off, fl)
                    fl = FL_CANNED
                    for a in range(3):
                        pos[a] = e[a]
                        s[a] = e[a]
                    if pos[an] != r_lvl:
                        e[an] = r_lvl
                        n = _emit(out, n, RAPID, li, s, e, e, 0, 0.0, st, si, wcs_off, fl)
                        s[an] = r_lvl
                    if motion == 830 or motion == 730:
                        depth_now = r_lvl - canned_q
                        while depth_now > bottom:
                            e[an] = depth_now
                            n = _emit(out, n, LINEAR, li, s, e, e, 0, 0.0, st, si, wcs_off, fl)
                            s[an] = depth_now
                            if motion == 830:
                                e[an] = r_lvl
                                n = _emit(out, n, RAPID, li, s, e, e, 0, 0.0, st, si, wcs_off, fl)
                                s[an] = r_lvl
                            e[an] = depth_now + pclear
                            n = _emit(out, n, RAPID, li, s, e, e, 0, 0.0, st, si, wcs_off, fl)
                            s[an] = depth_now + pclear
                            depth_now -= canned_q
                            if n > MAX_MOVES:  # (R99999999. Q1.: 1e8 pecks in one block)
                                return n, E_MOVES, -1, li, err_vals, nwarn
                    e[an] = bottom
                    n = _emit(out, n, LINEAR, li, s, e, e, 0, 0.0, st, si, wcs_off, fl)
                    s[an] = bottom
                    if motion == 820 or motion == 890 or motion == 860:
                        n = _emit(out, n, DWELL, li, s, s, s, 0, canned_p, st, si, wcs_off, fl)
                    if motion == 840:
                        n = _emit(out, n, DWELL, li, s, s, s, 0, canned_p, st, si, wcs_off, fl)
                        e[an] = clear
                        n = _emit(out, n, LINEAR, li, s, e, e, 0, 0.0, st, si, wcs_off, fl)
                    elif dialect != 0 and motion == 890:
                        # LinuxCNC's G89 feeds out to the clearance level (its G85 feeds to R)
                        e[an] = clear
                        n = _emit(out, n, LINEAR, li, s, e, e, 0, 0.0, st, si, wcs_off, fl)
                    elif motion == 850 or motion == 890:
                        e[an] = r_lvl
                        n = _emit(out, n, LINEAR, li, s, e, e, 0, 0.0, st, si, wcs_off, fl)
                        s[an] = r_lvl
                        if clear != r_lvl:
                            e[an] = clear
                            n = _emit(out, n, RAPID, li, s, e, e, 0, 0.0, st, si, wcs_off, fl)
                    else:
                        e[an] = clear
                        n = _emit(out, n, RAPID, li, s, e, e, 0, 0.0, st, si, wcs_off, fl)
                    pos[an] = clear
                si[SI_PATH_MODE] = saved_path_mode
        si[SI_PATH_MODE] = saved_path_mode

        # 17. program flow
        if m_end:
            break
        if m_sub:
            if not has[_P]:
                return n, E_SUB_NOT_FOUND, mword[0], li, err_vals, nwarn
            pnum = int(val[_P])
            reps = 1
            if has[_L]:
                if val[_L] < 0 or val[_L] != math.floor(val[_L]):
                    return n, E_BAD_VALUE, widx[_L], li, err_vals, nwarn
                if val[_L] > MAX_REPEATS:
                    return n, E_REPEATS, widx[_L], li, err_vals, nwarn
                reps = int(val[_L])
            target = -1
            for q in range(sub_num.size):
                if sub_num[q] == pnum:
                    target = sub_line[q]
            if target < 0 and pnum > 9999 and not has[_L]:
                # Fanuc packs the repeat count in front of a 4-digit program number
                for q in range(sub_num.size):
                    if sub_num[q] == pnum % 10000:
                        target = sub_line[q]
                reps = pnum // 10000
            if target < 0:
                return n, E_SUB_NOT_FOUND, widx[_P], li, err_vals, nwarn
            if reps > MAX_REPEATS:
                return n, E_REPEATS, widx[_P], li, err_vals, nwarn
            if depth >= MAX_SUB_DEPTH:
                return n, E_SUB_DEPTH, widx[_P], li, err_vals, nwarn
            if reps > 0:
                stack_ret[depth] = li + 1
                stack_start[depth] = target + 1
                stack_left[depth] = reps - 1
                depth += 1
                li = target + 1
                continue
        if m_ret:
            if depth == 0:
                nwarn = _warn(warn_code, warn_word, nwarn, W_M99_IN_MAIN, mword[0])
                break
            if stack_left[depth - 1] > 0:
                stack_left[depth - 1] -= 1
                li = stack_start[depth - 1]
                continue
            depth -= 1
            li = stack_ret[depth]
            continue
        li += 1
    return n, E_OK, -1, -1, err_vals, nwarn
