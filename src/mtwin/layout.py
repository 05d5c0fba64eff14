"""Data layouts that several packages share: the segment kinds of a plan, the servo table's
columns, the axes and the signals a trace can hold.

They live here, below ``motion``, ``cutting`` and ``effects``, so that those packages import
one place and not one another: an effect writes the servo table through these names
(``SV_B``, ``SV_FG``…), the engagement reads the segment kinds, and neither needs the motion
package that runs them (docs/architecture.md: one-way imports).  No imports beyond the
standard library: this module is cheap and cycle-free by construction."""
from __future__ import annotations

#: segment kinds of a plan's segment table (``motion.path.SEG_DTYPE``)
LINE, ARC, PAUSE = 0, 1, 2

#: servo parameter columns of the run kernel's per-axis table.  SV_MASS is the mass the
#: controller's gains are set for, SV_MP the mass the drive really moves (they differ when the
#: load does: the inertia effect)
SV_KPP, SV_WV, SV_WI, SV_FF, SV_MASS, SV_FPT, SV_FMAX, SV_FCP, SV_FCN, SV_FSP, SV_FSN, SV_VS, SV_B, SV_FG, \
    SV_MP = range(15)
N_SV = 15

AXES = ("x", "y", "z")
#: rows of the servo table (and columns of every per-axis array): ``sv[AXIS_Z, SV_FG]``
AXIS_X, AXIS_Y, AXIS_Z = range(3)

#: columns of the engagement's per-step scalars (``Engagement.q``): the chip's cross-section
#: (mm² per mm of feed per tooth), radial and axial depth, the widest chip's factor, the feed
#: direction (unit x, y), the uncut heights and the cosines of the engaged arc's ends on the
#: flank (bin centres; the chatter model's entry and exit angles: φ from the tool frame's +y,
#: clockwise, x along the feed — 2 and −2 where no flank cuts)
Q_AREA, Q_AE, Q_AP, Q_WMAX, Q_DX, Q_DY, Q_UH, Q_UZ, Q_CMIN, Q_CMAX = range(10)
N_Q = 10
#: columns of the engagement's force sums (``Engagement.sums``): (component, coefficient)
#: pairs — x: tangential, radial, axial | y: the same | z: radial, axial | spindle torque:
#: tangential; C the cutting (× feed per tooth), E the edge part
SX_TC, SX_RC, SX_AC, SY_TC, SY_RC, SY_AC, SZ_RC, SZ_AC, ST_TC = range(9)
SX_TE, SX_RE, SX_AE, SY_TE, SY_RE, SY_AE, SZ_RE, SZ_AE, ST_TE = range(9, 18)
N_SUMS = 18
#: angular bins per revolution of the engagement (2°; PHYSICS.md §2: 1-2°): its force sums
#: count an angle when a bin's centre is engaged
ANGLE_BINS = 180
#: columns of the engagement's tool table (``Engagement.tools``): radius, nose radius (mm), flutes
T_RADIUS, T_NOSE, T_FLUTES = range(3)
#: the cut's channels of every stored sample (the run kernel's ``cut_out``, ``Trace.cut``):
#: spindle speed (rpm), torque (N·m), power (W), ae, ap (mm), material removal (mm³/s), the
#: largest uncut chip (mm)
CUT_SIGNALS = ("spindle_speed", "spindle_torque", "spindle_power", "ae", "ap", "mrr", "h_max")
C_SPEED, C_TORQUE, C_POWER, C_AE, C_AP, C_MRR, C_HMAX = range(7)
N_CUT = len(CUT_SIGNALS)
#: every signal a trace can hold, in the measurement format's order
SIGNALS = (tuple(a + s for s in ("", "_cmd", "_err", "_vel") for a in AXES) + ("feed",)
           + tuple(a + s for s in ("_torque", "_current") for a in AXES) + CUT_SIGNALS[:3]
           + ("fx", "fy", "fz") + CUT_SIGNALS[3:] + ("vb", "vib_x", "vib_y"))

#: the planner's S-curve profile of each segment (``Plan.prof``; ``_plankernel.segment_timing``
#: writes it, the run kernel's interpolator reads it): speed in, peak and out (mm/s), the
#: acceleration phase's jerk time, its whole time and its acceleration, the cruise time, then
#: the deceleration's jerk time, whole time and deceleration
P_VIN, P_VPEAK, P_VOUT, P_TJ_UP, P_TA_UP, P_A_UP, P_CRUISE, P_TJ_DN, P_TA_DN, P_A_DN = range(10)
N_PROF = 10

#: the servo loop's counters between runs (``LoopState.seg``): the current segment, the samples
#: the raw command has stood still, the first and last sample at which the filtered command
#: moved, the last stop passed in position, the status (``LOOP_*``), the samples run
L_SEG, L_STILL, L_FIRST_MOVE, L_LAST_MOVE, L_STOPPED, L_STATUS, L_STEPS = range(7)
N_LOOP = 7
#: the loop's status: running, finished, the axes do not settle at an exact stop, the cutting
#: force drove the tool more than its radius off the path (the last two reported by the caller)
LOOP_RUNNING, LOOP_FINISHED, LOOP_UNSETTLED, LOOP_PUSHED = range(4)

#: rows of the loop's per-axis state (``LoopState.axes``): the filter's expected output, the
#: previous command, position, velocity, the velocity loop's integrator, the previous raw
#: command, the last feed direction (unit)
A_YEXP, A_PREV_CMD, A_POS, A_VEL, A_INTEG, A_PREV_RAW, A_DIR = range(7)
N_AXSTATE = 7
