"""Benchmark of ``mtwin optimize``: wall time and fast-model evaluations per second.

    python3 benchmarks/bench_optimize.py [--moves 100000] [--skip-large]

Targets (issue 11, 2-core machine): GA on the reference-like sample <= 10 s; bisection on a
1-hour, 100,000-move program <= 60 s; GA on it <= 120 s.  Each figure includes the whole job:
the first full simulation, segmentation, the search, writing, verification and the
re-simulation of the output (kernels warm: run ``mtwin cache warm`` first).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))


def run(label, prog_source, path, **kw):
    import mtwin
    from mtwin.optimize.run import OptimizeOptions, optimize

    tw = mtwin.Twin()
    prog = tw.load(prog_source, path=path)
    t0 = time.perf_counter()
    r = optimize(tw, prog, OptimizeOptions(**kw))
    wall = time.perf_counter() - t0
    print(f"{label}: wall {wall:.1f} s (search {r.search_seconds:.2f} s: {r.evaluations:,} evaluations, "
          f"{r.evaluations / max(r.search_seconds, 1e-9):,.0f} per s), {len(r.segments):,} segments, "
          f"{r.rounds} round(s); cycle {r.before.cycle_time:.1f} -> {r.after.cycle_time:.1f} s "
          f"(estimate {r.estimate['cycle_time']:.1f} s); peak load {r.before.peak_load:.1f} -> {r.after.peak_load:.1f} N; "
          f"contour error {r.contour_error['before']:.3f} -> {r.contour_error['after']:.3f} mm",
          flush=True)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--moves", type=int, default=100_000)
    ap.add_argument("--skip-large", action="store_true")
    a = ap.parse_args()
    ref = dict(feed_range=(100.0, 500.0), spindle_range=(1000.0, 8000.0), force_limit=60.0)
    sample = str(ROOT / "samples" / "ga_reference.nc")
    run("GA, reference sample", sample, None, method="ga", **ref)
    run("bisect, reference sample", sample, None, method="bisect", **ref)
    if a.skip_large:
        return
    from bench_motion import make_program

    big = make_program(a.moves)
    # the raster is a finishing pass (a radial width of cut under 5 % of the tool): by default
    # it would keep its feed per tooth; the benchmark optimises it as a cut, as before issue 18
    run(f"bisect, {a.moves:,}-move raster", big, "raster.nc", method="bisect", force_limit=60.0,
        finish_feed="optimize")
    run(f"GA, {a.moves:,}-move raster", big, "raster.nc", method="ga", force_limit=60.0, finish_feed="optimize")
    # (a given load limit keeps each tool's learned chip thickness: the raster runs one chip
    # everywhere, so only lifting it lets the load limit raise the feeds)
    run(f"bisect, {a.moves:,}-move raster, --chip-limit none", big, "raster.nc", method="bisect",
        force_limit=60.0, finish_feed="optimize", chip_limit="none")
    run(f"bisect, {a.moves:,}-move raster, default options", big, "raster.nc", method="bisect")


if __name__ == "__main__":
    main()
