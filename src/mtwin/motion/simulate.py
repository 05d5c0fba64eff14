"""Orchestration of the servo-rate run: plan -> kernel -> Trace with its Summary."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import GCodeError, MtwinError, SourceLocation, warning_text
from ..layout import (C_MRR, C_POWER, L_FIRST_MOVE, L_LAST_MOVE, L_SEG, L_STATUS, LOOP_PUSHED, LOOP_RUNNING,
                      LOOP_UNSETTLED, N_PROF, N_Q, N_SUMS)
from . import _runkernel as RK
from .path import CAT_CUT, CAT_RAPID, PAUSE, spindle_records
from .linetime import line_times
from .trace import AXES, CuttingSummary, Summary, Trace

_G = 9.80665
# Samples per kernel call when a progress callback is given (about 20 s of machining)
_CHUNK = 20_000
# servo periods run per call of the loop's kernel when no progress is reported: a compiled
# kernel does not see Ctrl-C, so a long program returns to Python every second or two of wall
# time (about 2,000 s of machine time) and an interrupt is taken there
_INTERRUPT_CHUNK = 2_000_000
# longest in-position wait at one exact stop before the simulation gives up, s
_MAX_WAIT = 10.0


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
        sv[k, RK.SV_MP] = ax.equivalent_mass
        sv[k, RK.SV_FPT] = ax.force_per_torque
        sv[k, RK.SV_FMAX] = ax.max_torque * ax.force_per_torque
        sv[k, RK.SV_FCP], sv[k, RK.SV_FCN] = f.coulomb_pos, f.coulomb_neg
        sv[k, RK.SV_FSP] = max(f.static_pos, f.coulomb_pos)
        sv[k, RK.SV_FSN] = max(f.static_neg, f.coulomb_neg)
        sv[k, RK.SV_VS] = f.stribeck_velocity
        sv[k, RK.SV_B] = f.viscous
        sv[k, RK.SV_FG] = ax.mass * _G if ax.gravity else 0.0
    return sv


def _per_tool(program, plan, wait) -> dict[int, dict[str, float]]:
    rec = program.records
    seg = plan.seg
    if not len(seg):
        return {}
    tools = rec["tool"][seg["rec"]]
    out: dict[int, dict[str, float]] = {}
    for t in np.unique(tools):
        m = tools == t
        out[int(t)] = {
            "cutting_time": float((plan.dur + wait)[m & (seg["cat"] == CAT_CUT)].sum()),
            "rapid_time": float((plan.dur + wait)[m & (seg["cat"] == CAT_RAPID)].sum()),
            "cutting_length": float(seg["length"][m & (seg["cat"] == CAT_CUT)].sum()),
        }
    return out


def program_engagement(twin, program, box=None):
    """(plan, engagement) of a program on the twin, on ``box`` (None: the program's stock as
    ``simulate`` finds it) — what the proof by the part compares."""
    from ..cutting.engagement import engagement_for

    plan = twin.plan(program)
    return plan, engagement_for(plan, program, program_cutting(twin, program), box, cache=twin.engagement_cache)


def program_cutting(twin, program):
    """The twin's cutting part with the tools this program declares (its comments, the twin's
    table), from the twin's cache (``Twin.cutting_cache``) when it has read this program."""
    from ..cutting.library import for_program

    cache = getattr(twin, "cutting_cache", None)
    hit = cache.get(program, twin.cutting) if cache is not None else None
    if hit is not None:
        return hit
    cut = for_program(twin.cutting, program)
    if cache is not None:
        cache.put(program, twin.cutting, cut)
    return cut


def share_cutting(twin, program, like) -> None:
    """Give ``program`` the cutting set-up of ``like`` on this twin: a rewrite of ``like`` that
    changed F and S words only declares the same tools (the optimiser's rounds)."""
    twin.cutting_cache.put(program, twin.cutting, program_cutting(twin, like))


def _cutting_args(m, cut, program, plan, stock, enabled: bool, tooth: bool = False, loop_effects=(),
                  tool_state=None, engagement_cache=None):
    """Engagement arrays and coefficients for the kernel (empty arrays: no cutting model): ``m``
    the machine, ``cut`` the program's cutting part (its tools, material, stock)."""
    seg = plan.seg
    nseg = max(len(seg), 1)
    rec = program.records
    spin_cmd = np.zeros(nseg)
    hand = np.ones(nseg)
    if len(seg):
        k = spindle_records(seg)
        on = k >= 0
        k = np.maximum(k, 0)
        r = rec[k]
        speed = r["spindle"] if program.spindle_scale is None else r["spindle"] * program.spindle_scale[k]
        spin_cmd[:] = np.where(on, r["spindle_dir"] * np.minimum(speed, m.spindle.max_speed), 0.0)
        hand[:] = np.where(r["spindle_dir"] < 0, -1.0, 1.0)
    curve = np.array([m.spindle.rated_power, m.spindle.base_speed])
    if not enabled or not len(seg):
        z = np.zeros(nseg, np.int64)
        z1 = np.zeros(1)
        return None, RK.CuttingInputs(z, z, np.zeros((0, N_SUMS), np.float32), np.zeros((0, N_Q), np.float32), z,
                                      np.zeros((1, 3)), np.zeros(6), np.zeros((0, 6)), hand, spin_cmd,
                                      float(m.spindle.acceleration), np.zeros(3), curve,
                                      np.zeros((0, 1, 1), np.float32), np.zeros(2, np.int64), np.zeros(1, np.int64),
                                      z1, z1, z1, z1, z1, z1), None
    turning = program.turning_line()
    if turning:
        raise MtwinError(f"{program.path}:{turning}: this is a turning program (lathe cycle G70-G72, G96 constant "
                         f"surface speed or G7 diameter mode); the cutting model is for milling tools: simulate its "
                         f"motion alone with --no-cutting")
    from ..cutting.engagement import engagement_for

    eng = engagement_for(plan, program, cut, stock, tooth=tooth, cache=engagement_cache)
    mat = cut.material
    kc = np.array(mat.coefficients)
    prof = eng.prof if tooth else np.zeros((0, 1, 1), np.float32)
    tfx = step_effects(eng, plan, loop_effects, program, tool_state, mat)
    return eng, RK.CuttingInputs(eng.first, eng.count, eng.sums, eng.q, eng.tool_index, eng.tools, kc, tfx.coefficients,
                                 hand, spin_cmd, float(m.spindle.acceleration), np.array(cut.spindle_loss), curve,
                                 prof, *eng.slices, eng.helix), tfx


@dataclass
class ToolEffects:
    """What the in-loop effects make of the engagement steps: the six cutting coefficients per
    step (``coefficients``, (steps, 6); empty: the material's everywhere), the
    flank-wear land per step (``land``, mm; None: no effect models it) and the steps
    themselves (their histories, for the tool ledger)."""

    coefficients: np.ndarray
    land: np.ndarray | None
    steps: object


def tool_effects(eng, plan, loop_effects, program=None, twin=None) -> ToolEffects:
    """:func:`step_effects` with the twin's tool state and the program's material on the twin."""
    start = getattr(twin, "tool_state", None) or {}
    material = program_cutting(twin, program).material if twin is not None and program is not None else None
    return step_effects(eng, plan, loop_effects, program, start, material)


def step_effects(eng, plan, loop_effects, program=None, start=None, material=None) -> ToolEffects:
    """The cutting coefficients per engagement step — the material's times the in-loop effects'
    factors (``cutting_scale``) plus their increments (``cutting_add``) — and the wear land of
    the effect that models one."""
    from ..effects import Effect, StepInfo

    users = [(e, p) for e, p in loop_effects if type(e).cutting_scale is not Effect.cutting_scale]
    adders = [(e, p) for e, p in loop_effects if type(e).cutting_add is not Effect.cutting_add]
    landers = [(e, p) for e, p in loop_effects if type(e).wear_land is not Effect.wear_land]
    start = start or {}  # tool number -> the history each tool starts with
    if not len(eng.q) or (not users and not adders and not landers and not start):
        return ToolEffects(np.zeros((0, 6)), None, None)
    kc = np.zeros(6)
    if material is not None:
        kc = np.array(material.coefficients)
    steps = StepInfo.from_engagement(eng, plan, program, kc=kc, start=start)
    scale = np.ones((len(eng.q), 6))
    changed = False
    for e, p in users:
        f = e.cutting_scale(steps, p)
        if f is None:
            continue
        f = np.asarray(f, dtype=np.float64)
        if f.ndim == 1:
            f = f[:, None]  # one factor on all six
        if f.shape[0] != scale.shape[0] or f.shape[1] not in (1, 6) or not np.isfinite(f).all() or (f < 0).any():
            raise MtwinError(f"effect {e.name}: cutting_scale must give one finite factor >= 0 per engagement "
                             f"step ({scale.shape[0]}), or six per step, got shape {f.shape}")
        scale *= f
        changed = True
    k = scale * kc
    for e, p in adders:
        f = e.cutting_add(steps, p)
        if f is None:
            continue
        f = np.asarray(f, dtype=np.float64)
        if f.shape != k.shape or not np.isfinite(f).all():
            raise MtwinError(f"effect {e.name}: cutting_add must give six finite increments per engagement step "
                             f"({k.shape[0]}, 6), got shape {f.shape}")
        k = k + f
        changed = True
    if changed and (k < 0).any():
        raise MtwinError("the effects make a cutting coefficient negative along the path")
    land = landers[-1][0].wear_land(steps, landers[-1][1]) if landers else None
    return ToolEffects(k if changed else np.zeros((0, 6)), land, steps)


def _wear_table(tfx: ToolEffects) -> dict:
    """Per tool number: the land at its first and last cut steps (mm) and its edge sliding
    before the program and in it (m)."""
    st = tfx.steps
    out = {}
    for t in np.unique(st.tool_number):
        m = np.flatnonzero((st.tool_number == t) & (st.slide > 0))
        if not m.size:
            continue
        before = float(st.sliding[m[0]] - 0.5 * st.slide[m[0]])
        out[int(t)] = {"vb_start": round(float(tfx.land[m[0]]), 6), "vb_end": round(float(tfx.land[m[-1]]), 6),
                       "sliding_before": round(before, 6), "sliding": round(float(st.slide[m].sum()), 6)}
    return out


def _land_by_sample(eng, plan, program, land: np.ndarray, record: np.ndarray) -> np.ndarray:
    """The wear land of the tool in the spindle at each sample (mm): the land after the
    record's last step, carried over the records that do not cut."""
    nrec = len(program.records)
    step_rec = plan.seg["rec"][eng.step_segments()]
    rec_land = np.full(nrec, -1.0)
    np.maximum.at(rec_land, step_rec, land)
    tool = program.records["tool"]
    for t in np.unique(tool):
        m = tool == t
        v = rec_land[m]
        known = v >= 0
        first = float(v[known][0]) if known.any() else 0.0
        rec_land[m] = np.maximum.accumulate(np.where(known, v, first))
    return rec_land[np.clip(record, 0, max(nrec - 1, 0))] if nrec else np.zeros(len(record))


def _duration(seconds: float) -> str:
    """A program's length as a person reads it: hours, minutes or seconds (not "0.0 h")."""
    if seconds >= 360.0:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 60:.1f} min" if seconds >= 60.0 else f"{seconds:.3g} s"


def simulate_plan(machine, program, plan, *, cut_part, effects=(), tool_state=None, engagement_cache=None,
                  every: int = 1, disturbance=None, progress=None, cutting: bool = True, stock=None, tooth: bool = False,
                  chatter: bool = True) -> Trace:
    """Run a planned program through the servo loop and the cutting process: what it uses, and
    nothing else — the machine, the program's cutting part (``cut_part``: its tools, material
    and stock), the effects, the tools' starting state and the engagement cache.  Only the twin
    calls it (``Twin.simulate``, ``Twin.simulate_batch``), which gathers these."""
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
    n_stops = int(plan.stop_end.sum())
    # samples of the plan itself; the in-position waits at exact stops add to it as they
    # happen (estimated here, the output grows if they take longer)
    n_plan = int(math.ceil(total / dt - 1e-9)) + 1
    wait_guess = 0.25 if c.in_position > 0 else 0.0
    n_est = n_plan + int(n_stops * wait_guess / dt)
    if n_plan > 500_000_000:
        # (name the move that takes longest: a G0 X99999999. or a G4 P999999999 is the usual cause)
        k = int(np.argmax(plan.dur))
        line = int(seg["line"][k])
        raise GCodeError(f"the program runs {_duration(total)}: more than 500 million servo samples of "
                         f"{dt * 1e3:g} ms; its longest move, this line's, takes {_duration(float(plan.dur[k]))}",
                         SourceLocation(program.path, line, 1))
    bytes_per_sample = RK.bytes_per_sample()  # what a trace keeps per sample
    need = (n_plan // every + 1) * bytes_per_sample
    if need > 4e9:
        suggest = int(math.ceil(need / 1e9)) * every
        raise MtwinError(f"a trace of {_duration(total)} at every {every} servo sample(s) needs {need / 1e9:.1f} GB; "
                         f"keep fewer samples (--every {suggest} or --decimate)")
    if disturbance is None:
        fd = np.zeros((0, 3))
    else:
        fd = np.ascontiguousarray(disturbance, dtype=np.float64)
        if fd.ndim != 2 or fd.shape[1] != 3:
            raise MtwinError(f"disturbance must have shape (samples, 3), got {fd.shape}")
    x0 = plan.start_point.astype(np.float64)
    sv = servo_table(machine)
    # the twin's effects, in their order: in the loop they change what the kernel reads,
    # on observation they change the finished trace
    resolved = [(e, e.resolved()) for e in effects]
    loop_effects = [(e, p) for e, p in resolved if e.stage == "loop"]
    for e, p in loop_effects:
        e.servo(sv, p)
    observed = [(e, p) for e, p in resolved if e.stage == "observation"]
    keep_every = every
    if observed:
        # observation effects act on every servo period, so the summary taken again from the
        # trace has the true peaks; the trace is thinned to the asked rate afterwards
        every = 1
        need = (n_plan + 1) * bytes_per_sample
        if need > 4e9:
            raise MtwinError(f"a program of {_duration(total)} with effects on observation ("
                             f"{', '.join(e.name for e, _ in observed)}) needs the full-rate trace: "
                             f"{need / 1e9:.1f} GB; simulate a shorter program or section")
    if len(seg):
        path = RK.PathArrays(seg["kind"].astype(np.int64), np.ascontiguousarray(seg["p0"]),
                             np.ascontiguousarray(seg["p1"]), np.ascontiguousarray(seg["u0"]),
                             np.ascontiguousarray(seg["c"]), np.ascontiguousarray(seg["e1"]),
                             np.ascontiguousarray(seg["e2"]), np.ascontiguousarray(seg["h"]), seg["r0"].copy(),
                             seg["r1"].copy(), seg["theta"].copy(), seg["length"].copy(),
                             # the kernel labels samples and statistics with this "line": the segment
                             # number (1-based, 0 = none), mapped to program line and record afterwards
                             np.arange(1, len(seg) + 1, dtype=np.int32))
        profile = RK.Profile(plan.t_start, plan.prof, plan.dur, plan.stop_end)
    else:
        z3 = np.zeros((1, 3))
        z3[0] = x0
        z = np.zeros(1)
        path = RK.PathArrays(np.array([PAUSE], np.int64), z3, z3, z3, z3, z3, z3, z3, z, z, z, z,
                             np.zeros(1, np.int32))
        profile = RK.Profile(z, np.zeros((1, N_PROF)), np.zeros(1), np.zeros(1, np.bool_))
    eng, cut_args, tfx = _cutting_args(machine, cut_part, program, plan, stock, cutting, tooth, loop_effects,
                                       tool_state, engagement_cache)
    cut_state = RK.CutState(np.zeros(2), np.zeros(16))  # spindle speed (rpm) and angle (rad); statistics
    cstats = cut_state.cstats
    state = RK.new_state(nfilt, x0, sv, len(seg))
    servo = RK.ServoInputs(float(dt), int(every), int(filt), int(nfilt), float(c.after_time), float(c.in_position),
                           float(_MAX_WAIT), sv, fd)
    cap = n_est // every + 3
    outs = RK.allocate_outputs(cap, eng is not None)
    chunk = max(_CHUNK, every) if progress is not None else max(min(_INTERRUPT_CHUNK, n_est), every)
    chunk -= chunk % every  # chunks start on stored samples
    k = 0
    while state.seg[L_STATUS] == LOOP_RUNNING:
        k1 = k + chunk
        if k < n_est < k1:  # (the chunk that passes the estimate ends there: no outputs grown for nothing)
            k1 = max(k + every, n_est + every - n_est % every)
        need_slots = k1 // every + 2
        if need_slots > cap:  # the waits took longer than estimated: grow the outputs
            cap = max(need_slots, int(cap * 1.25))
            outs = RK.Outputs(*(a if len(a) == 1 else np.concatenate([a, np.empty((cap - len(a),) + a.shape[1:],
                                                                                    a.dtype)]) for a in outs))
        k = RK.run_twin(path, profile, servo, k, k1, state, cut_args, cut_state, outs)
        if progress is not None:
            progress(min(k, n_est), n_est)
    if state.seg[L_STATUS] == LOOP_PUSHED:
        thrust = float(sv[:, RK.SV_FMAX].min())
        pushed = int(seg["line"][int(cstats[RK.CS_PUSHED_LINE]) - 1]) if cstats[RK.CS_PUSHED_LINE] else 0
        raise MtwinError(f"{program.path}:{pushed}:1: the cutting force (up to "
                         f"{float(cstats[RK.CS_LOAD]):.0f} N, the drives push {thrust:.0f} N) drives the tool more "
                         f"than its radius off the commanded path: the machine cannot hold this cut and the twin "
                         f"cannot predict it; lower the feed or the depth of cut, or raise the spindle speed")
    if state.seg[L_STATUS] == LOOP_UNSETTLED:
        i = int(state.seg[L_SEG])
        thrust = float(sv[:, RK.SV_FMAX].min())
        peak = float(cstats[RK.CS_LOAD])
        if eng is not None and peak > 0.5 * thrust:
            # the usual cause with a cutting load: the process pushes harder than the drives can
            load_line = int(seg["line"][int(cstats[RK.CS_LOAD_LINE]) - 1]) if cstats[RK.CS_LOAD_LINE] else 0
            why = (f"the cutting load reaches {peak:.0f} N at line {load_line}, "
                   f"against {thrust:.0f} N of drive thrust: lower the feed or the depth of cut, or raise "
                   f"the spindle speed")
        else:
            why = "servo gains, friction or gravity in the twin file"
        raise MtwinError(f"{program.path}:{int(seg['line'][i])}:1: the axes do not come within "
                         f"controller.in_position = {c.in_position:g} mm of the command in {_MAX_WAIT:g} s "
                         f"({why})")
    n_samples = k
    n_out = (n_samples - 1) // every + 1 + (1 if (n_samples - 1) % every else 0)
    t, segno, cmd, act, err, vel, trq, pathv, force, cut = (a[:n_out] for a in outs)
    seg_line = np.concatenate(([0], seg["line"])).astype(np.int32)
    line = seg_line[segno]
    record = np.concatenate(([-1], seg["rec"])).astype(np.int32)[segno]
    for k in (RK.CS_LOAD_LINE, RK.CS_POWER_LINE, RK.CS_TORQUE_LINE, RK.CS_SPINDLE_STOPPED_LINE,
              RK.CS_OVERLOAD_LINE, RK.CS_PUSHED_LINE):
        cstats[k] = seg_line[int(cstats[k])]
    max_err, max_trq = state.max_err, state.max_trq
    if not (np.isfinite(max_err).all() and np.isfinite(max_trq).all()):
        raise MtwinError("the servo simulation diverged (NaN or infinity): check the servo gains in the twin file")
    cats = plan.category_times(state.wait[:len(seg)])
    warnings = list(plan.warnings) + (list(eng.warnings) if eng is not None else [])
    if cstats[RK.CS_SPINDLE_STOPPED_LINE]:
        warnings.append(warning_text(program.path, int(cstats[RK.CS_SPINDLE_STOPPED_LINE]),
                                     "feed moves cut the stock with the spindle stopped (no M3/M4 or S0): their "
                                     "forces are not modelled"))
    if cstats[RK.CS_OVERLOAD_LINE]:
        warnings.append(warning_text(program.path, int(cstats[RK.CS_OVERLOAD_LINE]),
                                     f"the cutting torque exceeds the spindle curve (up to "
                                     f"{cstats[RK.CS_SPINDLE_LOAD]:.0%} of the available torque): the spindle "
                                     f"would stall"))
    rated = machine.spindle.rated_power
    if cstats[RK.CS_POWER] > rated:
        warnings.append(warning_text(program.path, int(cstats[RK.CS_POWER_LINE]),
                                     f"spindle power reaches {cstats[RK.CS_POWER]:,.0f} W, above the spindle's "
                                     f"rated {rated:,.0f} W"))
    first, last = int(state.seg[L_FIRST_MOVE]), int(state.seg[L_LAST_MOVE])
    # first to last sample at which the command moved (LinuxCNC's recorder counts the same way)
    motion_time = float((last - first + 1) * dt) if first >= 0 else 0.0
    summary = Summary(
        cycle_time=sum(cats.values()),
        cutting_time=cats["cutting"],
        rapid_time=cats["rapid"],
        dwell_time=cats["dwell"],
        tool_change_time=cats["tool_change"],
        spindle_wait_time=cats["spindle_wait"],
        motion_time=motion_time,
        max_following_error={a: float(v) for a, v in zip(AXES, max_err)},
        max_torque={a: float(v) for a, v in zip(AXES, max_trq)},
        per_tool=_per_tool(program, plan, state.wait[:len(seg)]),
        samples=n_samples,
        servo_period=dt,
        machine=machine.name,
        style=c.style,
        in_position_wait=float(state.wait[:len(seg)].sum()),
        warnings=warnings,
        per_line=line_times(plan, state.wait[:len(seg)]),
        **_error_context(cmd, err, line, segno, seg),
    )
    if eng is not None:
        from ..cutting.library import tools_used

        cut_time = cstats[RK.CS_CUT_TIME]
        feed_moves = (seg["kind"] != PAUSE) & (seg["rapid"] == 0)
        # (feed moves that meet the stock with the spindle stopped were named above: the stock
        # is met, its forces are not modelled)
        if cut_time <= 0 and feed_moves.any() and not cstats[RK.CS_SPINDLE_STOPPED_LINE]:
            b = eng.stock.box
            warnings.append(warning_text(program.path, 0,
                                         f"no feed move meets the stock (X {b[0]:g}…{b[3]:g} Y {b[1]:g}…{b[4]:g} "
                                         f"Z {b[2]:g}…{b[5]:g} mm, {eng.stock.source}): nothing is cut, so there "
                                         f"are no cutting forces; give the stock with --stock or a (MTWIN STOCK "
                                         f"xmin,ymin,zmin,xmax,ymax,zmax) comment"))
        summary.cutting = CuttingSummary(
            peak_load=float(cstats[RK.CS_LOAD]), peak_load_line=int(cstats[RK.CS_LOAD_LINE]),
            mean_load=float(cstats[RK.CS_LOAD_TIME] / cut_time) if cut_time > 0 else 0.0,
            peak_power=float(cstats[RK.CS_POWER]), peak_power_line=int(cstats[RK.CS_POWER_LINE]),
            mean_cutting_power=float(cstats[RK.CS_ENERGY] / cut_time) if cut_time > 0 else 0.0,
            peak_spindle_torque=float(cstats[RK.CS_TORQUE]), peak_spindle_torque_line=int(cstats[RK.CS_TORQUE_LINE]),
            cutting_energy=float(cstats[RK.CS_ENERGY]), engaged_time=float(cut_time),
            peak_mrr=float(cstats[RK.CS_MRR]), peak_spindle_load=float(cstats[RK.CS_SPINDLE_LOAD]),
            material=cut_part.material_name,
            stock=list(eng.stock.box), stock_source=eng.stock.source, resolution=eng.stock.resolution,
            engagement_steps=eng.steps, engagement_seconds=eng.seconds,
            defaults=list(cut_part.defaults_used), tools=tools_used(cut_part, program),
            spindle_stopped_line=int(cstats[RK.CS_SPINDLE_STOPPED_LINE]))
    if eng is not None and chatter:  # (not on an optimiser's intermediate re-simulation, as the margins)
        from ..cutting.catalogue import shank_checks

        summary.cutting.shank = shank_checks(cut_part, program, force, record)
        for c in summary.cutting.shank:
            if c["over"]:
                warnings.append(warning_text(
                    program.path, c["line"], f"T{c['tool']}'s shank is overloaded: its peak side load {c['peak_load']:.0f} N bends the "
                    f"shank to {c['stress']:.0f} N/mm², over the allowed {c['allowed_stress']:.0f} N/mm² "
                    f"({c['tool_material']}, stick-out {c['stickout']:.3g} mm: {c['breaking_force']:.0f} N at most, "
                    f"docs/catalogue.md) — take less feed, depth or width of cut"))
    if not (np.isfinite(act).all() and np.isfinite(err).all()):
        # a servo loop (or drive) the twin's values make unstable: its numbers are no answer —
        # a following error that came out NaN would read as 0 in every figure after it
        bad = np.flatnonzero(~np.isfinite(act).all(axis=1) | ~np.isfinite(err).all(axis=1))
        raise MtwinError(f"{program.path}:{int(line[bad[0]])}:1: the simulated axes diverged (positions not finite): "
                         f"the twin's servo or drive values make the loop unstable; check the [axes.*.servo] gains "
                         f"and the controller's servo_period")
    kt = np.array([ax.torque_constant for ax in machine.axes])
    trace = Trace(t, line, cmd, act, err, vel, trq, pathv, kt, summary, every, program.path,
                  force if eng is not None else None, cut if eng is not None else None, eng, record)
    if tfx is not None and tfx.steps is not None:
        trace.tool_use = tfx.steps.history()
        if tfx.land is not None:
            trace.vb = _land_by_sample(eng, plan, program, tfx.land, record).astype(np.float32)
            summary.cutting.tool_wear = _wear_table(tfx)
    if chatter and eng is not None and summary.cutting is not None:
        # (``chatter=False``: an optimiser's intermediate re-simulation, which needs no margins)
        summary.cutting.chatter = chatter_table(machine, cut_part, program, plan, eng)
    changed: set[str] = set()
    for e, p in observed:
        if eng is None and any(s in CUT_SIGNALS for s in e.signals):
            continue  # no cutting model: nothing for it to act on
        e.observe(trace, p)
        changed.update(e.signals)
    if changed:
        _summary_from_trace(trace, changed)
    if keep_every > 1 and observed:
        trace = trace.thinned(keep_every)
    return trace


def chatter_table(machine, cut, program, plan, eng) -> dict:
    """Per program line that cuts with a tool whose dynamics the twin knows: its largest
    stability margin (axial depth over the lobes' limit at its speed, arc and direction), the
    depth, limit, speed and chatter frequency there; empty when no tool has dynamics.  ``cut``:
    the program's cutting part (:func:`program_cutting`)."""
    from ..chatter.margin import step_arcs, step_limits, tool_dynamics

    rec = program.records
    tools, dyn = tool_dynamics(cut, rec["tool"])
    if not any(dyn.values()) or not eng.steps:
        return {}
    r = plan.seg["rec"][eng.step_segments()]
    tool = rec["tool"][r].astype(np.int64)
    hand = np.where(rec["spindle_dir"][r] < 0, -1, 1)
    speed = np.minimum(rec["spindle"][r].astype(float), machine.spindle.max_speed)
    arcs = step_arcs(eng.q)
    mat = cut.material
    line = rec["line"][r]
    notes: list = []
    limit, freq = step_limits(dyn, {t: tl.flutes for t, tl in tools.items()}, mat.ktc, mat.krc, tool, hand,
                              speed, arcs, notes=notes)
    margin = np.where(np.isfinite(limit) & arcs.cutting, arcs.ap / np.where(np.isfinite(limit), limit, 1.0), 0.0)
    lines = []
    for ln in np.unique(line[margin > 0]):
        at = np.flatnonzero((line == ln) & (margin > 0))
        i = at[np.argmax(margin[at])]
        lines.append({"line": int(ln), "tool": int(tool[i]), "speed": float(speed[i]), "ap": float(arcs.ap[i]),
                      "immersion": float(0.5 * (np.cos(arcs.phi_st[i]) - np.cos(arcs.phi_ex[i]))),
                      "limit": float(limit[i]), "margin": float(margin[i]),
                      "chatter_frequency": None if not np.isfinite(freq[i]) else float(freq[i])})
    worst = max(lines, key=lambda x: x["margin"]) if lines else None
    return {"tools": {str(t): {"modes": len(d.modes), "frf": d.frf.source if d.frf is not None else None}
                      for t, d in dyn.items() if d},
            "worst_margin": worst["margin"] if worst else 0.0, "worst_line": worst["line"] if worst else 0,
            "unstable_lines": [x["line"] for x in lines if x["margin"] > 1.0], "lines": lines, "notes": notes}


CUT_SIGNALS = {"spindle_speed", "spindle_torque", "spindle_power", "fx", "fy", "fz", "ae", "ap", "mrr", "h_max"}


def _summary_from_trace(trace: Trace, changed: set[str]) -> None:
    """Figures of the summary that an observation effect changed, taken again from the trace's
    samples, so the reported peaks are never out of step with the trace (from the stored
    samples: with --every N they are those of every N-th servo period)."""
    s = trace.summary
    if not len(trace.t):
        return
    if changed & {"x", "y", "z"}:
        e = np.abs(trace.err.astype(np.float64))
        for k, a in enumerate(AXES):
            i = int(np.argmax(e[:, k]))
            s.max_following_error[a] = float(e[i, k])
            s.max_following_error_line[a] = int(trace.line[i])
    c = s.cutting
    if c is None or trace.cut is None:
        return
    dt = np.diff(trace.t, append=trace.t[-1] + s.servo_period * trace.every)
    cutting = trace.cut[:, C_MRR] > 0  # material removed in this sample
    if "spindle_power" in changed:
        pw = trace.cut[:, C_POWER].astype(np.float64)
        i = int(np.argmax(pw))
        c.peak_power, c.peak_power_line = float(pw[i]), int(trace.line[i])
        c.cutting_energy = float(np.sum(np.where(cutting, pw * dt, 0.0)))
        c.mean_cutting_power = float(c.cutting_energy / max(np.sum(np.where(cutting, dt, 0.0)), 1e-300))
    if changed & {"fx", "fy"}:
        load = np.hypot(trace.force[:, 0].astype(np.float64), trace.force[:, 1].astype(np.float64))
        i = int(np.argmax(load))
        c.peak_load, c.peak_load_line = float(load[i]), int(trace.line[i]) if load[i] > 0 else 0
        c.mean_load = float(np.sum(np.where(cutting, load * dt, 0.0)) / max(np.sum(np.where(cutting, dt, 0.0)), 1e-300))


def _error_context(cmd, err, line, segno, seg) -> dict:
    """Where the largest following error of each axis occurs (line; in a rapid or a feed move),
    the largest in feed moves, and the largest contour error: the part of the error vector
    normal to the commanded direction of travel (tangent estimate), over feed moves — the
    deviation from the path a user reads as accuracy.  From the stored trace samples."""
    out = {"max_following_error_line": {}, "max_following_error_in": {}, "max_following_error_feed": {},
           "max_contour_error": 0.0, "max_contour_error_line": 0}
    if len(err) == 0 or len(seg) == 0:
        return out
    idx = np.zeros(4, np.int64)
    val = np.zeros(7)
    rapid = seg["rapid"].astype(np.int64)
    pause = (seg["kind"] == PAUSE).astype(np.int64)
    RK.error_stats(cmd, err, segno, rapid, pause, idx, val)
    for k, a in enumerate(AXES):
        i = int(idx[k])
        out["max_following_error_line"][a] = int(line[i])
        sg = int(segno[i])
        out["max_following_error_in"][a] = "rapid" if sg == 0 or rapid[sg - 1] else "feed move"
        out["max_following_error_feed"][a] = float(val[3 + k])
    if idx[3] >= 0:
        out["max_contour_error"] = float(val[6])
        out["max_contour_error_line"] = int(line[int(idx[3])])
    return out