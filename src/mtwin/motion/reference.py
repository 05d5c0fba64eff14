"""Comparing a simulated trace with a LinuxCNC trajectory-planner recording.

LinuxCNC's ``run_reference.sh`` records ``t,x,y,z,line,vel,motion_type`` (machine
coordinates, planner path velocity).  Two measures:

* cycle time: first to last commanded movement, the definition the recorder uses;
* path-velocity NRMSE: for every recorded sample, the simulated path speed *at the
  same place of the path* (nearest simulated point of the same program line, moving in
  the same direction — so retraced drilling strokes are told apart), RMS difference
  divided by the recorded peak speed.  Comparing at the same place rather than the same
  time keeps a small timing offset early in a program from counting at every later
  sample.
"""
from __future__ import annotations

import gzip
from dataclasses import dataclass

import numpy as np


@dataclass
class ReferenceComparison:
    cycle_time: float  # s, simulated (first to last movement)
    reference_cycle_time: float  # s
    velocity_nrmse: float  # fraction of the reference's peak path speed
    matched: float  # share of reference samples that found a simulated sample on their line

    @property
    def cycle_time_error(self) -> float:
        return self.cycle_time / self.reference_cycle_time - 1.0


def load_linuxcnc_trace(path: str) -> np.ndarray:
    """A recorded trace (.csv or .csv.gz) as a structured array."""
    opener = gzip.open if str(path).endswith(".gz") else open
    with opener(path, "rt") as fh:
        return np.genfromtxt(fh, delimiter=",", names=True)


def _features(p: np.ndarray, direction_weight: float) -> np.ndarray:
    d = np.gradient(p, axis=0) if len(p) > 1 else np.zeros_like(p)
    n = np.linalg.norm(d, axis=1, keepdims=True)
    u = np.divide(d, n, out=np.zeros_like(d), where=n > 1e-9)
    return np.hstack([p, direction_weight * u])


def compare_to_linuxcnc(trace, program, ref: np.ndarray, reference_cycle_time: float,
                        direction_weight: float = 5.0) -> ReferenceComparison:
    from scipy.spatial import cKDTree

    rec = program.records
    tlo = dict(zip(rec["line"].tolist(), rec["tlo"].tolist()))
    pts = np.asarray(trace.cmd, dtype=np.float64).copy()
    # LinuxCNC records machine coordinates: add the tool length offset of each line
    pts[:, 2] += np.array([tlo.get(int(x), 0.0) for x in trace.line])
    rxyz = np.column_stack([ref["x"], ref["y"], ref["z"]])
    fs = _features(pts, direction_weight)
    fr = _features(rxyz, direction_weight)
    speed = np.asarray(trace.path_speed, dtype=np.float64)
    v_at = np.full(len(ref), np.nan)
    for line in np.unique(ref["line"]):
        mr = ref["line"] == line
        ms = trace.line == line
        if not ms.any():
            continue
        _, idx = cKDTree(fs[ms]).query(fr[mr])
        v_at[mr] = speed[ms][idx]
    ok = ~np.isnan(v_at)
    nrmse = float(np.sqrt(np.mean((v_at[ok] - ref["vel"][ok]) ** 2)) / np.max(ref["vel"]))
    return ReferenceComparison(trace.summary.motion_time, reference_cycle_time, nrmse, float(ok.mean()))
