"""``simulate --dynamics``: the regenerative model along a simulated trace.

After the servo loop has run, every trace sample where a tool with modes cuts is integrated
again at the tool tip (``_lobekernel.regen_trace``): the sample's spindle speed and path feed
(the servo loop's), the engagement step under it (its arc, axial depth and feed direction),
the modes, and the chip cut against the surface the previous tooth left.  The trace gets the
tip's deflection (``vib_x``, ``vib_y``, mm) and each cutting line a verdict: the regenerative
part u(t) − u(t − T) decaying (stable) or growing (chatter), and the spectrum's peaks —
tooth-passing harmonics against a chatter frequency off them.

The tip's deflection does not feed back into the servo loop's forces (the machine axes see
the revolution-averaged force as before): the model is one-way, which is what the stability
question needs — the lobes are the linear stability of exactly this tip model.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .. import layout as EK
from ..units import feed_per_tooth
from . import _lobekernel as LK
from .lobes import dynamics_of
from .margin import step_arcs

SUB_STEPS = 64  # per tooth pitch
SPECTRUM_CAP = 4_000_000  # sub-steps kept for the lines' spectra
DIVERGED_MM = 1.0  # a regenerative vibration beyond this has diverged (chip loads are tenths of a millimetre)


@dataclass
class Dynamics:
    vib: np.ndarray  # (n, 2) mm, tip deflection at every sample
    regen: np.ndarray  # (n,) mm, RMS of u(t) − u(t − T) over the sample
    lines: list = field(default_factory=list)
    notes: list = field(default_factory=list)

    def as_dict(self) -> dict:
        return {"lines": self.lines, "notes": self.notes,
                "chatter_lines": [x["line"] for x in self.lines if x["chatter"]]}


def _sample_steps(trace, plan, program, eng) -> np.ndarray:
    """The engagement step under each trace sample (−1: none): the step of the sample's record
    nearest its fraction along the record (commanded path length)."""
    seg = plan.seg
    steps_seg = eng.step_segments()
    rec_of = seg["rec"]
    nrec = len(program.records)
    length = seg["length"]
    rec_len = np.bincount(rec_of, weights=length, minlength=nrec)
    # position of each step along its record: earlier segments of the record, then within
    cum = np.cumsum(length)
    start_of_rec = np.full(nrec, np.inf)
    np.minimum.at(start_of_rec, rec_of, cum - length)
    before = (cum - length) - start_of_rec[rec_of]
    count = eng.count
    first = eng.first
    j = np.arange(len(steps_seg)) - first[steps_seg]
    pos = (before[steps_seg] + (j + 0.5) / np.maximum(count[steps_seg], 1) * length[steps_seg]) / \
        np.maximum(rec_len[rec_of[steps_seg]], 1e-12)
    step_key = rec_of[steps_seg] + np.clip(pos, 0, 0.999999)
    order = np.argsort(step_key, kind="stable")
    sk = step_key[order]
    rec = np.asarray(trace.record)
    out = np.full(len(rec), -1, np.int64)
    ok = rec >= 0
    if not ok.any() or not len(sk):
        return out
    cmd = np.asarray(trace.cmd, float)
    d = np.r_[0.0, np.linalg.norm(np.diff(cmd, axis=0), axis=1)]
    new = np.r_[True, rec[1:] != rec[:-1]]
    grp = np.cumsum(new) - 1
    c = np.cumsum(d)
    frac = (c - c[np.flatnonzero(new)][grp]) / np.maximum(rec_len[np.clip(rec, 0, None)], 1e-12)
    key = rec + np.clip(frac, 0, 0.999999)
    i = np.clip(np.searchsorted(sk, key[ok]), 1, len(sk) - 1)
    pick = np.where(np.abs(sk[i] - key[ok]) < np.abs(sk[i - 1] - key[ok]), i, i - 1)
    same = np.floor(sk[pick]) == rec[ok]
    out[np.flatnonzero(ok)[same]] = order[pick[same]]
    return out


def trace_dynamics(cut, program, plan, trace) -> Dynamics:
    """Run the regenerative model along ``trace`` (a simulation with the cutting model;
    ``cut``: the program's cutting part of the twin — tools, material)."""
    eng = trace.engagement
    n = len(trace.t)
    vib = np.zeros((n, 2))
    regen = np.zeros(n)
    out = Dynamics(vib, regen)
    if eng is None or trace.cut is None:
        out.notes.append("no cutting model: nothing to integrate")
        return out
    rec = program.records
    r = np.clip(np.asarray(trace.record), 0, None)
    tool_of = np.where(np.asarray(trace.record) >= 0, rec["tool"][r], -1)
    step = _sample_steps(trace, plan, program, eng)
    arcs = step_arcs(eng.q)
    t = np.asarray(trace.t, float)
    dt = np.diff(t, append=t[-1] + (t[-1] - t[-2] if n > 1 else 0.001))
    rpm = np.abs(np.asarray(trace.signal("spindle_speed")))
    feed = np.asarray(trace.feed)  # mm/min
    mat = cut.material
    for tn in sorted(set(int(x) for x in np.unique(tool_of) if x >= 0)):
        if not (tn in cut.tools or tn in cut.declared):
            continue
        tl = cut.tool(tn)
        dyn = dynamics_of(tl)
        if not dyn:
            continue
        if not dyn.modes:
            out.notes.append(f"T{tn}: a measured FRF has no state-space model: fit modes to it (mtwin calibrate-frf) "
                             f"for --dynamics")
            continue
        mine = tool_of == tn
        s = np.where(mine, step, -1)
        has = s >= 0
        st = np.clip(s, 0, None)
        active = has & arcs.cutting[st] & (rpm > 0)
        fz = feed_per_tooth(feed, rpm, tl.flutes) * 1e-3  # m
        fang = np.arctan2(eng.q[st, EK.Q_DY], eng.q[st, EK.Q_DX]).astype(float)
        hand = np.where(rec["spindle_dir"][r] < 0, -1, 1).astype(np.int64)
        mfn, mz, mk, mdir = dyn.mode_arrays()
        ux = np.zeros(n)
        uy = np.zeros(n)
        amp = np.zeros(n)
        total = int(np.sum(dt[mine] * rpm[mine] / 60.0 * tl.flutes * SUB_STEPS)) + 16
        cap = min(total, SPECTRUM_CAP)
        sub_x = np.zeros(cap)
        sub_y = np.zeros(cap)
        sub_first = np.full(n, -1, np.int64)
        LK.regen_trace(np.where(mine, dt, 0.0), np.where(mine, rpm, 0.0), fz, arcs.ap[st] * 1e-3,
                       arcs.phi_st[st], arcs.phi_ex[st], fang, hand, active, int(tl.flutes), mat.ktc * 1e6,
                       mat.krc / mat.ktc, mfn, mz, mk, mdir, SUB_STEPS, cap, ux, uy, amp, sub_x, sub_y, sub_first)
        vib[mine, 0] = ux[mine] * 1e3
        vib[mine, 1] = uy[mine] * 1e3
        regen[mine] = amp[mine] * 1e3
        out.lines += _line_verdicts(trace, active, regen, rpm, tl.flutes, sub_x, sub_y, sub_first, tn)
    out.lines.sort(key=lambda x: x["line"])
    if not out.lines and not out.notes:
        out.notes.append("no tool this program cuts with has modes in the twin file: nothing to integrate "
                         "([[tools.N.modes]], docs/chatter.md)")
    return out


def _line_verdicts(trace, active, regen, rpm, flutes, sub_x, sub_y, sub_first, tool) -> list:
    lines = np.asarray(trace.line)
    out = []
    for ln in np.unique(lines[active]):
        at = np.flatnonzero(active & (lines == ln))
        if len(at) < 4:
            continue
        k = max(len(at) // 5, 1)
        seg = regen[at]
        finite = np.isfinite(seg)
        # a vibration that leaves the numbers (overflow, NaN) or grows past a millimetre has
        # diverged: the cut is unstable far beyond its limit (a very soft mode), which is chatter
        # — never "no chatter" because a comparison with NaN came out false
        diverged = bool(not finite.all() or np.abs(seg).max() > DIVERGED_MM)
        seg = np.where(finite, seg, np.nan)
        start = float(np.nanmean(seg[:k])) if finite[:k].any() else 0.0
        end = float(np.nanmean(seg[-k:])) if finite[-k:].any() else float(np.nanmax(np.abs(seg), initial=0.0))
        n = float(np.median(rpm[at]))
        tp = flutes * n / 60.0
        entry = {"line": int(ln), "tool": tool, "speed": n, "tooth_passing": tp,
                 "regen_start_um": start * 1e3, "regen_end_um": end * 1e3,
                 "growth": end / start if start > 0 else (math.inf if end > 0 else 1.0)}
        a, b = int(sub_first[at[0]]), int(sub_first[at[-1]])
        peak = None
        if diverged:
            entry["diverged"] = True
        elif a >= 0 and b > a + 256:
            x = sub_x[a:b]
            y = sub_y[a:b]
            x = x[-32768:]
            y = y[-32768:]
            fs = SUB_STEPS * tp  # sub-steps per second at the line's speed
            w = np.hanning(len(x))
            spec = np.abs(np.fft.rfft((x - x.mean()) * w)) + np.abs(np.fft.rfft((y - y.mean()) * w))
            f = np.fft.rfftfreq(len(x), 1.0 / fs)
            harmonic = np.abs(f / tp - np.round(f / tp)) < 0.02
            off = np.where(harmonic | (f < 0.5 * tp), 0.0, spec)
            if off.max() > 0:
                peak = float(f[int(np.argmax(off))])
            entry["spectrum_peak"] = float(f[int(np.argmax(np.where(f > 0.5 * tp, spec, 0)))])
            entry["off_harmonic_share"] = float(off.max() / max(spec[f > 0.5 * tp].max(), 1e-300))
        # chatter: the regenerative part grows, or it holds a vibration off the tooth-passing
        # harmonics that dominates the spectrum (grown and saturated: the tooth leaving the cut)
        grows = end > 3.0 * start and end > 1e-4
        holds = entry.get("off_harmonic_share", 0.0) > 0.5 and end > 5e-4
        entry["chatter"] = bool(grows or holds or diverged)
        # (a stable line's leakage near a harmonic is no chatter frequency)
        entry["chatter_frequency"] = peak if entry["chatter"] else None
        out.append(entry)
    return out
