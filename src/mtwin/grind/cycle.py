"""A stepped plunge-grinding cycle run on the removal twin, and its quality figures.

A cycle is a list of stages, each a programmed radial feed (mm/min) held until the in-process
gauge reads the stage's switch allowance (mm on the radius); the last stage ends at size
(switch allowance 0), then ``sparkout`` revolutions at zero feed grind the stored deflection
away, and the wheel retracts.  The gauge is read gauge.reads_per_rev times a revolution.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .model import Batch, GrindTwin, State, advance, allowance_left, gauge_reading, gauge_steps, runout_profile

MAX_REVOLUTIONS = 20_000

LIMIT_NAMES = ("size", "roundness", "roughness", "burn", "force", "reach")


@dataclass
class Stage:
    feed: float  # mm/min
    switch_allowance: float  # mm: the stage ends when the gauge reads this much left
    time: float = 0.0  # s, on the nominal part

    def as_dict(self):
        return {"feed": self.feed, "switch_allowance": self.switch_allowance, "time": self.time}


@dataclass
class Quality:
    """Per case: the figures the limits are held against."""

    cycle_time: np.ndarray  # s
    size_error: np.ndarray  # mm, final mean radius − target (+ oversize)
    roundness: np.ndarray  # mm
    roughness_feed: np.ndarray  # mm per revolution in the last revolution
    burn_qw: np.ndarray  # mm²/s, largest specific removal rate
    peak_force: np.ndarray  # N
    reached: np.ndarray  # bool: the gauge read size (not stopped by a revolution limit)
    switch_force: np.ndarray | None = None  # N, the force when the gauge switched to spark-out

    def violations(self, twin: GrindTwin, scale: dict | None = None) -> dict:
        """Per limit, the ratio of each case's figure to the limit (> 1: a defect).
        ``scale``: tightened limits (a factor per limit name) for the optimiser."""
        s = scale or {}
        return {
            "size": np.abs(self.size_error) / (twin["limits.size"] * s.get("size", 1.0)),
            "roundness": self.roundness / (twin["limits.roundness"] * s.get("roundness", 1.0)),
            "roughness": self.roughness_feed / (twin["limits.roughness_feed"] * s.get("roughness", 1.0)),
            "burn": self.burn_qw / (twin["limits.burn_qw"] * s.get("burn", 1.0)),
            "force": self.peak_force / (twin["wheel.force_limit"] * s.get("force", 1.0)),
            "reach": np.where(self.reached, 0.0, 2.0),
        }

    def defects(self, twin: GrindTwin, scale: dict | None = None) -> np.ndarray:
        v = self.violations(twin, scale)
        return np.any(np.stack([v[k] > 1.0 for k in LIMIT_NAMES]), axis=0)


def run_cycle(twin: GrindTwin, batch: Batch, stages: list, trace: list | None = None):
    """Run the cycle on every part of the batch; returns (final State, Quality, stage times of case 0).

    After the last stage the feed is zero (spark-out) until the gauge reads size, for at least
    cycle.sparkout and at most cycle.sparkout_max revolutions; then the wheel retracts."""
    n = batch.size
    feeds = np.tile(np.array([s.feed for s in stages], float), (n, 1))
    switch = np.tile(np.array([s.switch_allowance for s in stages], float), (n, 1))
    return run_cycles(twin, batch, feeds, switch, trace)


def run_cycles(twin: GrindTwin, batch: Batch, feeds: np.ndarray, switch: np.ndarray, trace: list | None = None):
    """Each part its own cycle: ``feeds`` and ``switch`` (cases, stages), mm/min and mm (a
    shorter cycle repeats its last stage: a switch no lower than the one before ends at once)."""
    K = int(twin["system.positions"])
    n_w = twin["work.speed"]
    lo_rev = twin["cycle.sparkout"]
    hi_rev = max(twin["cycle.sparkout_max"], lo_rev)
    n, S = feeds.shape
    feeds = np.concatenate([feeds, np.zeros((n, 1))], axis=1)
    switch = np.concatenate([switch, np.full((n, 1), -np.inf)], axis=1)
    rows = np.arange(n)
    st = State.start(batch, K)
    dR = runout_profile(batch, K)
    stage = np.zeros(n, np.int64)
    spark = np.zeros(n, np.int64)
    done = np.zeros(n, bool)
    stage_time = np.zeros(S + 1)
    switch_force = np.zeros(n)
    steps = gauge_steps(twin)
    per_rev = K / steps  # gauge intervals per revolution
    for _ in range(int(MAX_REVOLUTIONS * per_rev)):
        active = ~done
        if not active.any():
            break
        feed = np.where(active, feeds[rows, stage], 0.0)
        before_t = st.t.copy()
        # a finished part stands still: its state is put back after the revolution
        keep = st.take(done) if done.any() else None
        advance(batch, st, feed, n_w, dR, steps, trace)
        if keep is not None:
            st.put(done, keep)
        stage_time[min(stage[0], S)] += (st.t[0] - before_t[0]) if active[0] else 0.0
        g = gauge_reading(batch, st)
        # switch (possibly past several stages) where the gauge says so
        for _k in range(S):
            go = active & (stage < S) & (g <= switch[rows, np.minimum(stage, S)])
            if not go.any():
                break
            stage = np.where(go, stage + 1, stage)
        newly = active & (stage == S) & (spark == 0)
        switch_force[newly] = st.last_force[newly]
        spark = np.where(active & (stage == S), spark + 1, spark)
        # spark-out: zero feed after the switch until the gauge reads size (within the bounds)
        out_ = active & (stage == S) & (spark > 0)
        done |= out_ & (((spark - 1 >= lo_rev * per_rev) & (g <= 0.0)) | (spark - 1 >= hi_rev * per_rev))
    reached = (stage == S) & (gauge_reading(batch, st) <= 0.0)
    K_ = st.removed.shape[1]
    radius_dev = dR - st.removed  # each position's radius over the target, minus the allowance
    q = Quality(
        cycle_time=st.t + twin["machine.retract"],
        size_error=allowance_left(batch, st),
        roundness=radius_dev.max(axis=1) - radius_dev.min(axis=1) if K_ else np.zeros(n),
        roughness_feed=st.last_f,
        burn_qw=math.pi * twin["work.diameter"] * st.peak_rate / 60.0,
        peak_force=st.peak_force,
        reached=reached,
        switch_force=switch_force,
    )
    return st, q, stage_time


def stages_from(feeds, switches, times=None) -> list:
    times = times if times is not None else [0.0] * len(feeds)
    return [Stage(float(f), float(a), float(t)) for f, a, t in zip(feeds, switches, times)]
