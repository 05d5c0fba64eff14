"""Dynamic programming over (allowance level × program feed level), as in the grinding-cycle
reference: T[n, m] = min_l T[n−1, l] + τ(n−1, l → n, m), each move simulated with the removal
twin from the state its best predecessor reached; moves that break a limit are inadmissible;
the cycle is recovered by back-tracking.

Every move out of one allowance level — all M predecessor states × M feeds — runs as one
batch of the vectorised removal model, so a 40 × 40 grid is 40 batch runs of 1,600 parts.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from .cycle import Stage, run_cycle
from .model import Batch, GrindTwin, State, advance, gauge_reading, gauge_steps, runout_profile

MAX_MOVE_REVS = 4000


@dataclass
class Design:
    stages: list  # [Stage]
    cycle_time: float  # s, nominal part, including spark-out and retract
    grid: tuple  # (feed levels, allowance levels)
    table: np.ndarray  # T[n, m], inf where unreachable
    seconds: float
    sparkout: float = 0.0  # spark-out revolutions the nominal part takes to reach size
    predicted: float = math.inf  # the DP's own cycle time (T + spark-out + retract), s


def feed_levels(twin: GrindTwin, M: int) -> np.ndarray:
    return np.geomspace(twin["machine.feed_min"], twin["machine.feed_max"], M)


def design(twin: GrindTwin, M: int = 40, N: int = 40, scale: dict | None = None, batch: Batch | None = None) -> Design:
    """The time-optimal stepped cycle under the twin's limits.

    ``batch``: case 0 is the nominal part, whose time is minimised; every other case is a part
    the cycle must also keep within the limits (the robustness loop's defective parts, turned
    into constraints): each runs every move from its own state, switched by its own gauge
    reading, and a move or an end that breaks a limit on any of them is inadmissible.
    ``scale``: a factor per limit name tightening it."""
    import time as _time

    t0 = _time.perf_counter()
    s = scale or {}
    batch = batch or Batch.nominal(twin, 1)
    P = batch.size
    K = int(twin["system.positions"])
    n_w = twin["work.speed"]
    feeds = feed_levels(twin, M)
    A = float(batch.allowance[0] + batch.gauge[0])  # what the gauge reads at the start
    levels = A * (1.0 - np.arange(N + 1) / N)  # n = 0 … N; N: the gauge reads size
    force_lim = twin["wheel.force_limit"] * s.get("force", 1.0)
    burn_lim = twin["limits.burn_qw"] * s.get("burn", 1.0)
    T = np.full((N + 1, M), np.inf)
    pred = np.full((N + 1, M), -1, np.int64)
    # the states at each level: M nodes × P parts, index m·P + p; level 0: the untouched parts
    states = [State.start(batch, K).take(np.tile(np.arange(P), M))]
    T[0, :] = 0.0
    B1 = _tile(batch, M * M)  # move cases ((l·M) + m)·P + p
    dR = runout_profile(B1, K)
    steps = gauge_steps(twin)
    case = np.arange(M * M * P)
    l_of, m_of, p_of = case // (M * P), (case // P) % M, case % P
    for n in range(1, N + 1):
        prev = states[-1]
        alive = np.isfinite(T[n - 1])
        feed = feeds[m_of]
        st = prev.take(l_of * P + p_of)
        st.peak_force = np.zeros(len(case))
        st.peak_rate = np.zeros(len(case))
        t_start = st.t.copy()
        running = alive[l_of] & (gauge_reading(B1, st) > levels[n])
        if n > 1:
            # a stepped cycle slows down stage by stage (rough, semi-finish, finish): the feed
            # never rises again; without this the model's lag invites pulsed feeds
            running &= m_of <= l_of
        for _ in range(int(MAX_MOVE_REVS * K / steps)):
            if not running.any():
                break
            sub = np.flatnonzero(running)
            s_sub = st.take(sub)
            b_sub = _take(B1, sub)
            advance(b_sub, s_sub, feed[sub], n_w, dR[sub], steps)
            st.put(sub, s_sub)
            running[sub] = gauge_reading(b_sub, s_sub) > levels[n]
        burn = math.pi * twin["work.diameter"] * st.peak_rate / 60.0
        ok = alive[l_of] & ~running & (st.peak_force <= force_lim) & (burn <= burn_lim)
        if n > 1:
            ok &= m_of <= l_of
        ok_lm = ok.reshape(M, M, P).all(axis=2)
        tau = (st.t - t_start).reshape(M, M, P)[:, :, 0]  # the nominal part's time
        total = np.where(ok_lm, T[n - 1][:, None] + tau, np.inf)  # [l, m]
        best_l = np.argmin(total, axis=0)
        T[n] = total[best_l, np.arange(M)]
        pred[n] = np.where(np.isfinite(T[n]), best_l, -1)
        states.append(st.take(((best_l[:, None] * M + np.arange(M)[:, None]) * P + np.arange(P)[None, :]).ravel()))
    # the end: spark-out may start at any node (n, m) — the gauge switch to zero feed — for as
    # many revolutions as the quality limits need; all nodes at once, as one batch
    # (the robustness loop may cap the switch point: s["switch"], mm the gauge reads)
    nodes = [(n, m) for n in range(1, N + 1) for m in np.flatnonzero(np.isfinite(T[n]))
             if levels[n] <= s.get("switch", np.inf) + 1e-12]
    if not nodes:
        return Design([], math.inf, (feeds, levels), T, _time.perf_counter() - t0)
    nn = np.array([x[0] for x in nodes])
    mm = np.array([x[1] for x in nodes])
    st_end = State.concat([states[n].take(m * P + np.arange(P)) for n, m in zip(nn, mm)])
    extra, revs, ok = _finish(twin, _tile(batch, len(nodes)), st_end, K, s)
    ok_node = ok.reshape(len(nodes), P).all(axis=1)
    extra0 = extra.reshape(len(nodes), P)[:, 0]
    total = np.where(ok_node, T[nn, mm] + extra0, np.inf)
    k = int(np.argmin(total))
    if not np.isfinite(total[k]):
        return Design([], math.inf, (feeds, levels), T, _time.perf_counter() - t0)
    n_end, best_m = int(nn[k]), int(mm[k])
    # back-track
    path = [best_m]
    for n in range(n_end, 1, -1):
        path.append(int(pred[n, path[-1]]))
    path = path[::-1]  # feed level of the move into n = 1 … n_end
    stages = []
    for n, m in enumerate(path, start=1):
        if stages and stages[-1][0] == m:
            stages[-1][1] = n
        else:
            stages.append([m, n])
    out = [Stage(float(feeds[m]), float(levels[n])) for m, n in stages]
    sparkout = float(revs.reshape(len(nodes), P)[k, 0])
    # stage times and the cycle time from one run of the finished cycle on the nominal part
    _, q, times = run_cycle(twin, _take(batch, np.array([0])), out)
    for st_, t in zip(out, times):
        st_.time = float(t)
    return Design(out, float(q.cycle_time[0]), (feeds, levels), T, _time.perf_counter() - t0, sparkout,
                  float(total[k]))


def _finish(twin, batch, st: State, K: int, scale: dict):
    """Spark-out from each state of a batch as the machine runs it (``cycle.run_cycles``): zero
    feed until the gauge reads size, at least cycle.sparkout and at most cycle.sparkout_max
    revolutions; (time
    added per case, revolutions, whether the size, roundness and roughness limits hold)."""
    from .cycle import Quality

    n_w = twin["work.speed"]
    dR = runout_profile(batch, K)
    steps = gauge_steps(twin)
    per_rev = K / steps
    lo = twin["cycle.sparkout"] * per_rev
    hi = twin["cycle.sparkout_max"] * per_rev
    n = batch.size
    count = np.zeros(n)
    t0 = st.t.copy()
    # the same test as run_cycles: zero-feed intervals done so far, then the gauge
    done = ((count >= lo) & (gauge_reading(batch, st) <= 0.0)) | (count >= hi)
    while not done.all():
        active = ~done
        keep = st.take(done) if done.any() else None
        advance(batch, st, np.zeros(n), n_w, dR, steps)
        if keep is not None:
            st.put(done, keep)
        count = np.where(active, count + 1, count)
        done |= active & (((count >= lo) & (gauge_reading(batch, st) <= 0.0)) | (count >= hi))
    radius_dev = dR - st.removed
    q = Quality(st.t, batch.allowance - st.removed.mean(axis=1), radius_dev.max(axis=1) - radius_dev.min(axis=1),
                st.last_f, math.pi * twin["work.diameter"] * st.peak_rate / 60.0, st.peak_force,
                gauge_reading(batch, st) <= 0.0)
    v = q.violations(twin, scale)
    ok = (v["size"] <= 1.0) & (v["roundness"] <= 1.0) & (v["roughness"] <= 1.0) & q.reached
    return st.t - t0 + twin["machine.retract"], count / per_rev, ok


def _rep(batch: Batch, n: int) -> Batch:
    """``n`` copies of the batch's first part."""
    return _tile(_take(batch, np.array([0])), n)


def _tile(batch: Batch, n: int) -> Batch:
    """The whole batch ``n`` times over (case i is part i % size)."""
    return Batch(*(np.tile(getattr(batch, f.name), n) for f in fields(Batch)))


def _take(batch: Batch, idx) -> Batch:
    return Batch(*(getattr(batch, f.name)[idx] for f in fields(Batch)))
