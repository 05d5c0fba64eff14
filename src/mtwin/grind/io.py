"""Grinding cycles in and out: the cycle file (TOML), the G-code cycle, the trace in the
measurement format, and fitting the twin's compliance and stress intensity to a recording."""
from __future__ import annotations

import math

import numpy as np

from ..errors import ConfigError
from ..params import UNIT_MAX
from ..tomlwrite import toml_value
from .cycle import Stage, run_cycle
from .model import Batch, GrindTwin, read_toml


MAX_ALLOWANCE = 10.0  # mm: a switch allowance beyond it is no plunge-grinding stage


def read_cycle(path: str) -> list:
    """The stages of a cycle file: ``[cycle] stages = [{feed = …, switch_allowance = …}, …]``."""
    raw = read_toml(path, "cycle file")
    cyc = raw.get("cycle", {})
    stages = cyc.get("stages") if isinstance(cyc, dict) else None
    if not isinstance(stages, list) or not stages:
        raise ConfigError(f"{path}: no [cycle] stages = [{{feed = …, switch_allowance = …}}, …]")
    out = []
    last = math.inf
    for i, s in enumerate(stages, 1):
        if not isinstance(s, dict) or set(s) - {"feed", "switch_allowance", "time"} or \
                not {"feed", "switch_allowance"} <= set(s):
            raise ConfigError(f"{path}: stage {i}: needs feed (mm/min) and switch_allowance (mm)")
        f, a = s["feed"], s["switch_allowance"]
        if not all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in (f, a)):
            raise ConfigError(f"{path}: stage {i}: feed and switch_allowance must be numbers")
        if not (0 < f <= UNIT_MAX["mm/min"] and 0 <= a <= MAX_ALLOWANCE):
            raise ConfigError(f"{path}: stage {i}: feed must be > 0 mm/min (the spark-out at zero feed follows the "
                              f"last stage) up to {UNIT_MAX['mm/min']:g}, and switch_allowance from 0 to "
                              f"{MAX_ALLOWANCE:g} mm (a grinding allowance is tenths of a mm)")
        if a > last:
            raise ConfigError(f"{path}: stage {i}: switch allowances must not increase from stage to stage")
        last = a
        out.append(Stage(float(f), float(a)))
    return out


def cycle_toml(twin: GrindTwin, stages: list, note: str = "") -> str:
    """A self-contained cycle file: the twin it was designed on, and the stages in its [cycle]."""
    out = ([f"# {note}"] if note else []) + twin.toml().rstrip().splitlines()
    out.append("stages = [  # programmed radial feed (mm/min) until the gauge reads switch_allowance (mm left)")
    for s in stages:
        out.append(f"  {{ feed = {toml_value(float(f'{s.feed:.10g}'))}, "
                   f"switch_allowance = {toml_value(float(f'{s.switch_allowance:.10g}'))} }},")
    out.append("]")
    return "\n".join(out) + "\n"


def cycle_gcode(twin: GrindTwin, stages: list, sparkout_s: float, title: str = "MTWIN PLUNGE CYCLE") -> str:
    """The cycle as G-code for a cylindrical grinder (Fanuc-style, radius programming, G91).

    Each stage is a G31 skip move: the radial infeed X- at the stage's feed, ended by the skip
    signal the in-process gauge gives at the stage's switch point.  Its distance is what the
    twin's nominal part needs programmed (the part's allowance plus the elastic deflection the
    stage builds up) plus half again and 0.01 mm: long enough that the gauge, not the distance,
    ends the stage, short enough to bound the infeed if the gauge fails.  The spark-out is a
    dwell of the nominal part's spark-out time (on the machine the gauge's size signal ends it),
    then a rapid retract."""
    cols = trace_columns(twin, stages)
    t = cols["t"]
    dt = np.diff(np.concatenate([[0.0], t]))
    programmed = np.cumsum(cols["feed_cmd"] / 60.0 * dt)  # mm of infeed at the end of each interval
    # the infeed each stage needed on the nominal part: up to the last interval it ran in
    need = []
    done = 0.0
    for k, st in enumerate(stages):
        at = np.flatnonzero(np.isclose(cols["feed_cmd"], st.feed) & (cols["feed_cmd"] > 0))
        end = float(programmed[at[-1]]) if len(at) else done
        need.append(max(end - done, 0.0))
        done = max(end, done)
    lines = ["%", f"O9001 ({title})",
             f"(WHEEL {twin['wheel.diameter']:g} X {twin['wheel.width']:g} MM AT {twin['wheel.speed']:g} RPM,"
             f" WORK D{twin['work.diameter']:g} AT {twin['work.speed']:g} RPM)",
             "(RADIUS PROGRAMMING, G91 INCREMENTAL RADIAL INFEED; G31 SKIP = GAUGE SWITCH POINT)",
             "G21 G40 G80", f"M3 S{int(round(twin['wheel.speed']))} (WHEEL)",
             f"(WORK SPINDLE {twin['work.speed']:g} RPM)", "G91"]
    for k, (s_, d) in enumerate(zip(stages, need), 1):
        lines.append(f"G31 X-{1.5 * d + 0.01:.4f} F{s_.feed:.4g} (STAGE {k}: UNTIL GAUGE READS "
                     f"{s_.switch_allowance:.4f} MM; NOMINAL INFEED {d:.4f})")
    lines.append(f"G04 X{sparkout_s:.2f} (SPARK-OUT UNTIL GAUGE READS SIZE)")
    lines += ["G00 X2. (RETRACT, INCREMENTAL)", "M30", "%"]
    return "\n".join(lines) + "\n"


def trace_columns(twin: GrindTwin, stages: list, batch: Batch | None = None) -> dict:
    """The nominal part's cycle as measurement-format columns: t, feed (actual radial feed,
    mm/min), feed_cmd (programmed), fx (radial force, N), radius (mean radius over the
    target, mm), runout (max − min radius, mm)."""
    batch = batch or Batch.nominal(twin)
    tr: list = []
    run_cycle(twin, batch, stages, trace=tr)
    if not tr:
        return {k: np.zeros(0) for k in ("t", "feed", "feed_cmd", "fx", "radius", "runout")}
    t, fc, fa, force, left, spread = (np.array([row[i][0] for row in tr]) for i in range(6))
    return {"t": t, "feed": fa, "feed_cmd": fc, "fx": force, "radius": left, "runout": spread}


def fit(twin: GrindTwin, stages: list, t: np.ndarray, feed: np.ndarray, force: np.ndarray,
        names=("system.compliance", "work.sigma")) -> dict:
    """Fit grinding parameters (by dotted name) to a recorded cycle: actual feed and radial
    force against time, by bounded least squares on the twin's own trace of the same cycle.
    Returns {name: value} and the RMS residuals before and after."""
    from ..fitting import solve
    from .model import BY_NAME

    params = [BY_NAME[n] for n in names]
    x0 = np.array([twin[n] for n in names])
    f_scale = max(float(np.std(feed)), 1e-9)
    p_scale = max(float(np.std(force)), 1e-9)

    def resid(x):
        tw = twin.with_params({n: float(v) for n, v in zip(names, x)})
        c = trace_columns(tw, stages)
        fs = np.interp(t, c["t"], c["feed"], right=0.0) if len(c["t"]) else np.zeros_like(t)
        ps = np.interp(t, c["t"], c["fx"], right=0.0) if len(c["t"]) else np.zeros_like(t)
        return np.concatenate([(fs - feed) / f_scale, (ps - force) / p_scale])

    r0 = resid(x0)
    lo = np.array([max(p.lower, 1e-12) for p in params])
    hi = np.array([p.upper for p in params])
    # (residuals scaled by each signal's spread, not its noise: no identifiability cut)
    sol = solve(resid, x0, lo, hi, np.abs(np.clip(x0, lo, hi)) + 1e-12, max_evaluations=200, blind_check=False)
    return {"values": {n: float(v) for n, v in zip(names, sol.x)},
            "uncertainty": {n: u for n, u in zip(names, sol.uncertainty)},
            "rms_before": float(np.sqrt(np.mean(r0 ** 2))), "rms_after": float(np.sqrt(np.mean(sol.fun ** 2)))}
