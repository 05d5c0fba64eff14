"""Orchestration of the servo-rate run: plan -> kernel -> Trace with its Summary."""
from __future__ import annotations

import math

import numpy as np

from ..errors import MtwinError
from . import _runkernel as RK
from .path import CAT_CUT, CAT_RAPID, PAUSE
from .trace import AXES, Summary, Trace

_G = 9.80665
# Samples per kernel call when a progress callback is given (about 20 s of machining)
_CHUNK = 20_000


def servo_table(machine) -> np.ndarray:
    """Per-axis servo and plant parameters in the kernel's units (N, kg, mm, s)."""
    sv = np.zeros((3, RK.N_SV))
    for k, ax in enumerate(machine.axes):
        s, f = ax.servo, ax.friction
        sv[k, RK.SV_KPP] = s.kpp * s.s_pp
        sv[k, RK.SV_WV] = s.velocity_bandwidth * s.s_vp
        sv[k, RK.SV_WI] = s.velocity_integral * s.s_vi
        sv[k, RK.SV_FF] = s.feedforward
        sv[k, RK.SV_MASS] = ax.equivalent_mass
        sv[k, RK.SV_FPT] = ax.force_per_torque
        sv[k, RK.SV_FMAX] = ax.max_torque * ax.force_per_torque
        sv[k, RK.SV_FCP], sv[k, RK.SV_FCN] = f.coulomb_pos, f.coulomb_neg
        sv[k, RK.SV_FSP] = max(f.static_pos, f.coulomb_pos)
        sv[k, RK.SV_FSN] = max(f.static_neg, f.coulomb_neg)
        sv[k, RK.SV_VS] = f.stribeck_velocity
        sv[k, RK.SV_B] = f.viscous
        sv[k, RK.SV_FG] = ax.mass * _G if ax.gravity else 0.0
    return sv


def _per_tool(program, plan) -> dict[int, dict[str, float]]:
    rec = program.records
    seg = plan.seg
    if not len(seg):
        return {}
    tools = rec["tool"][seg["rec"]]
    out: dict[int, dict[str, float]] = {}
    for t in np.unique(tools):
        m = tools == t
        out[int(t)] = {
            "cutting_time": float(plan.dur[m & (seg["cat"] == CAT_CUT)].sum()),
            "rapid_time": float(plan.dur[m & (seg["cat"] == CAT_RAPID)].sum()),
            "cutting_length": float(seg["length"][m & (seg["cat"] == CAT_CUT)].sum()),
        }
    return out


def simulate_plan(twin, program, plan, *, every: int = 1, disturbance=None, progress=None) -> Trace:
    machine = twin.machine
    c = machine.controller
    if every < 1:
        raise MtwinError(f"--every must be at least 1, got {every}")
    dt = c.servo_period
    from .planner import _filter_hold

    filt, _ = _filter_hold(c)
    nfilt = max(1, int(round(c.after_time / dt)))
    if filt == RK.FILTER_BELL:
        nfilt = max(1, nfilt // 2)
    seg = plan.seg
    total = plan.total_time
    # the last sample falls on or after the end of the plan, so the command ends exactly on
    # the last programmed point
    n_samples = int(math.ceil(total / dt - 1e-9)) + 1
    if n_samples > 500_000_000:
        raise MtwinError(f"program runs {total / 3600:.1f} h: more than 500 million servo samples")
    bytes_per_sample = 92  # t, line, cmd (float64), act/err/vel/torque/path speed (float32)
    need = (n_samples // every + 1) * bytes_per_sample
    if need > 4e9:
        suggest = int(math.ceil(need / 1e9)) * every
        raise MtwinError(f"a trace of {total / 3600:.1f} h at every {every} servo sample(s) needs {need / 1e9:.1f} GB; "
                         f"keep fewer samples (--every {suggest} or --decimate)")
    if disturbance is None:
        fd = np.zeros((0, 3))
    else:
        fd = np.ascontiguousarray(disturbance, dtype=np.float64)
        if fd.shape != (n_samples, 3):
            raise MtwinError(f"disturbance must have shape ({n_samples}, 3), got {fd.shape}")
    x0 = plan.start_point.astype(np.float64)
    sv = servo_table(machine)
    if len(seg):
        args = (seg["kind"].astype(np.int64), np.ascontiguousarray(seg["p0"]), np.ascontiguousarray(seg["p1"]),
                np.ascontiguousarray(seg["u0"]), np.ascontiguousarray(seg["c"]), np.ascontiguousarray(seg["e1"]),
                np.ascontiguousarray(seg["e2"]), np.ascontiguousarray(seg["h"]), seg["r0"].copy(),
                seg["r1"].copy(), seg["theta"].copy(), seg["length"].copy(), seg["line"].copy(),
                plan.t_start, plan.prof, plan.dur)
    else:
        z3 = np.zeros((1, 3))
        z3[0] = x0
        z = np.zeros(1)
        args = (np.array([PAUSE], np.int64), z3, z3, z3, z3, z3, z3, z3, z, z, z, z, np.zeros(1, np.int32),
                z, np.zeros((1, 10)), np.ones(1))
    state = RK.State(nfilt, x0, sv)
    outs = RK.allocate_outputs(n_samples, every)
    chunk = n_samples if progress is None else max(_CHUNK, every)
    chunk -= chunk % every  # chunks start on stored samples
    k = 0
    while k < n_samples:
        k1 = min(n_samples, k + chunk)
        RK.run_twin(*args, dt, k, k1, every, filt, nfilt, c.after_time, sv, fd,
                    state.ring1, state.ring2, state.sums, state.axes, state.seg, state.max_err, state.max_trq,
                    *outs)
        k = k1
        if progress is not None:
            progress(k, n_samples)
    t, line, cmd, act, err, vel, trq, pathv = outs
    max_err, max_trq = state.max_err, state.max_trq
    if not (np.isfinite(max_err).all() and np.isfinite(max_trq).all()):
        raise MtwinError("the servo simulation diverged (NaN or infinity): check the servo gains in the twin file")
    cats = plan.category_times()
    first, last = int(state.seg[2]), int(state.seg[3])
    # first to last sample at which the command moved (LinuxCNC's recorder counts the same way)
    motion_time = float((last - first + 1) * dt) if first >= 0 else 0.0
    summary = Summary(
        cycle_time=plan.total_time,
        cutting_time=cats["cutting"],
        rapid_time=cats["rapid"],
        dwell_time=cats["dwell"],
        tool_change_time=cats["tool_change"],
        spindle_wait_time=cats["spindle_wait"],
        motion_time=motion_time,
        max_following_error={a: float(v) for a, v in zip(AXES, max_err)},
        max_torque={a: float(v) for a, v in zip(AXES, max_trq)},
        per_tool=_per_tool(program, plan),
        samples=n_samples,
        servo_period=dt,
        machine=machine.name,
        style=c.style,
        warnings=list(plan.warnings),
    )
    kt = np.array([ax.torque_constant for ax in machine.axes])
    return Trace(t, line, cmd, act, err, vel, trq, pathv, kt, summary, every, program.path)
