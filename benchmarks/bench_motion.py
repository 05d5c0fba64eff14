"""Twin throughput: an hour of machining made of >= 100,000 short moves.

Prints, per planner style: interpretation, planning and servo-loop times (motion only),
machining seconds simulated per wall-clock second, and the process's peak memory; then,
for the default machine, the cutting-load stages side by side: engagement on the stock
(once per path), the full twin (motion + stock + forces), and a re-simulation with new F
and S values (engagement reused).  Kernel compilation (or loading from the numba cache)
is timed separately on a tiny program first.  Targets: motion >= 1,000x real time with
< 1 GB (issue 3); full twin < 30 s and F/S re-simulation < 3 s for an hour (issue 4).

    python3 benchmarks/bench_motion.py [--moves 100000] [--every 1]
"""
from __future__ import annotations

import argparse
import math
import resource
import sys
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def make_program(n_moves: int) -> bytes:
    """A finishing raster over a wavy surface: 0.9 mm moves at F1500, zig-zag rows."""
    out = ["%", "(mtwin motion benchmark: finishing raster)", "G21 G90 G94 G17 G64 P0.01",
           "(T1 D=6. CR=0. - FLAT END MILL, 2 FLUTES)", "T1 M6", "S8000 M3", "G0 X0 Y0 Z5", "G1 Z0 F600", "F1500"]
    per_row = 250
    step = 0.9
    k = 0
    row = 0
    while k < n_moves:
        y = row * 0.5
        for j in range(per_row):
            i = j if row % 2 == 0 else per_row - 1 - j
            x = i * step
            z = -0.5 + 0.4 * math.sin(x / 7.0) * math.cos(y / 5.0)
            out.append(f"G1 X{x:.3f} Y{y:.3f} Z{z:.4f}")
            k += 1
        row += 1
        if row * 0.5 > 240:
            row = 0
    out += ["G0 Z5", "M30", "%"]
    return ("\n".join(out) + "\n").encode()


def peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--moves", type=int, default=100_000)
    ap.add_argument("--every", type=int, default=1, help="keep every n-th sample in the trace")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT / "src"))
    from mtwin.twin import Twin

    t0 = time.perf_counter()
    tiny = Twin()
    tiny.simulate(tiny.load(b"G21 G90 G94 G1 X1 F600\nG2 X2 Y0 I0.5 J0\nM30\n", path="warm.nc"))
    lc = Twin.from_toml(str(ROOT / "samples" / "machines" / "linuxcnc-sim.toml"))
    lc.simulate(lc.load(b"G21 G90 G94 G1 X1 F600\nG1 Y1\nG1 X2\nG2 X3 Y1 I0.5 J0\nM30\n", path="warm.ngc"))
    print(f"kernel compile / cache load: {time.perf_counter() - t0:.2f} s (cached in ~/.cache/mtwin/numba)")

    data = make_program(args.moves)
    print(f"program: {args.moves:,} moves, {len(data) / 1e6:.1f} MB; trace every {args.every} sample(s)")
    for label, twin in (("fanuc (default)", Twin()), ("linuxcnc-sim", lc),
                        ("grbl", Twin(replace(Twin().machine, controller=replace(Twin().machine.controller, style="grbl"))))):
        t0 = time.perf_counter()
        prog = twin.load(data, path="bench.nc")
        t1 = time.perf_counter()
        plan = twin.plan(prog)
        t2 = time.perf_counter()
        trace = twin.simulate(prog, every=args.every, cutting=False)
        t3 = time.perf_counter()
        machining = trace.summary.cycle_time
        sim = t3 - t2
        print(f"{label:16s} machining {machining:8.1f} s ({machining / 3600:.2f} h) | interpret {t1 - t0:5.2f} s"
              f" | plan {t2 - t1:5.2f} s | plan+servo loop {t3 - t1:5.2f} s -> {machining / (t3 - t1):7.0f}x real time"
              f" | servo loop alone {machining / sim:7.0f}x | {trace.summary.samples:,} samples | peak RSS {peak_mb():6.0f} MB")
        del trace, plan, prog

    # ---- cutting load: engagement once, full twin, re-simulation with new F and S
    from mtwin.cutting import engagement as E

    twin = Twin()
    cache = twin.engagement_cache
    prog = twin.load(data, path="bench.nc")
    t0 = time.perf_counter()
    plan = twin.plan(prog)
    t1 = time.perf_counter()
    eng = E.engagement_for(plan, prog, twin.cutting, cache=cache)
    t2 = time.perf_counter()
    trace = twin.simulate(prog, every=args.every)
    t3 = time.perf_counter()
    machining = trace.summary.cycle_time
    c = trace.summary.cutting
    print(f"engagement      {eng.steps:,} steps of {eng.step:g} mm on a {eng.stock.heights.shape[1]}x"
          f"{eng.stock.heights.shape[0]} Z-map ({eng.stock.resolution:g} mm): {t2 - t1:.2f} s = "
          f"{eng.steps / (t2 - t1):,.0f} steps/s, {eng.cells_changed:,} cell updates")
    print(f"full twin       plan + servo loop with forces {t3 - t2:.2f} s (engagement cached) -> "
          f"{trace.summary.samples / (t3 - t2):,.0f} samples/s; from program to trace "
          f"{t1 - t0 + t2 - t1 + t3 - t2:.2f} s for {machining / 3600:.2f} h ({machining / (t3 - t0):,.0f}x real time); "
          f"peak load {c.peak_load:.0f} N, peak power {c.peak_power:.0f} W | peak RSS {peak_mb():.0f} MB")
    del trace
    faster = data.replace(b"F1500", b"F1800").replace(b"S8000", b"S7000")
    n0 = cache.computations
    t4 = time.perf_counter()
    prog2 = twin.load(faster, path="bench2.nc")
    trace2 = twin.simulate(prog2, every=args.every)
    t5 = time.perf_counter()
    print(f"new F and S     interpret + plan + servo loop with forces {t5 - t4:.2f} s "
          f"(engagement recomputed: {cache.computations - n0}); cycle {trace2.summary.cycle_time:.1f} s | "
          f"peak RSS {peak_mb():.0f} MB")


if __name__ == "__main__":
    main()
