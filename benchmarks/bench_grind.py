"""Benchmark of ``mtwin grind``: DP wall time on a 40 × 40 grid, and the robustness loop's
run of the cycle on 1,000 batch combinations.

    python3 benchmarks/bench_grind.py

Targets (issue 13, 2-core machine): DP under 10 s; 1,000 combinations under 10 s.
"""
from __future__ import annotations

import time


def main() -> None:
    from mtwin.grind.cycle import run_cycle
    from mtwin.grind.dp import design
    from mtwin.grind.model import GrindTwin
    from mtwin.grind.robust import robust_design, sample

    tw = GrindTwin()
    design(tw, 10, 10)  # imports and first touches out of the timing
    for M, N in ((20, 20), (40, 40), (80, 80)):
        t0 = time.perf_counter()
        d = design(tw, M, N)
        print(f"DP {M} x {N}: {time.perf_counter() - t0:.2f} s, cycle {d.cycle_time:.2f} s, {len(d.stages)} stage(s)")
    d = design(tw, 40, 40)
    batch, _ = sample(tw, 1000, seed=7)
    t0 = time.perf_counter()
    _, q, _ = run_cycle(tw, batch, d.stages)
    print(f"cycle on 1,000 combinations: {time.perf_counter() - t0:.2f} s, {int(q.defects(tw).sum())} defective")
    t0 = time.perf_counter()
    r = robust_design(tw, 40, 40, cases=300, seed=0, validate=1000)
    print(f"robustness loop (300 parts per iteration, {len(r.iterations)} iterations, then 1,000 fresh): "
          f"{time.perf_counter() - t0:.2f} s; cycle {r.iterations[0].cycle_time:.2f} -> {r.design.cycle_time:.2f} s, "
          f"defects {r.iterations[0].defects}/{r.iterations[0].cases} -> "
          f"{r.validation.defects if r.validation else '-'}/{r.validation.cases if r.validation else '-'}")


if __name__ == "__main__":
    main()
