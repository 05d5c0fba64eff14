"""The model-against-measurement loop on a 10-minute program measured at 100 Hz.

Prints the wall time of `compare` (alignment by line, position and cross-correlation),
`diagnose` over the whole catalogue and `calibrate` of one in-loop and one observation
effect, in-process after a warm-up (kernels compiled).  Targets (issue 10): compare < 5 s,
diagnose < 60 s, calibrate of one effect < 30 s.

    python benchmarks/bench_loop.py [--minutes 10]
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def program(minutes: float) -> bytes:
    """Slots and pockets at several feeds and speeds, repeated to last about ``minutes``."""
    out = ["%", "(mtwin loop benchmark)", "(MTWIN STOCK -10,-10,-30,110,110,0)", "G21 G90 G94 G17",
           "T1 M6", "S8000 M3", "G0 X0 Y0 Z5"]
    t = 0.0
    depth = 0.0
    k = 0
    while t < minutes * 60.0:
        depth -= 0.5
        feed = (600, 900, 1200)[k % 3]
        out.append(f"S{(6000, 8000, 7000)[k % 3]} M3")
        out.append(f"G1 Z{depth:.2f} F200")
        for j in range(10):
            y = 5 + 9 * j
            out.append(f"G1 X{95 if j % 2 == 0 else 5} Y{y} F{feed}")
            out.append(f"G1 Y{y + 9}")
            t += 90 / (feed / 60) + 9 / (feed / 60)
        out.append("G0 Z5")
        out.append("G0 X5 Y5")
        k += 1
    out += ["M30", "%"]
    return ("\n".join(out) + "\n").encode()


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--minutes", type=float, default=10.0)
    a = ap.parse_args()
    import mtwin
    from mtwin.loop.compare import compare
    from mtwin.loop.fit import diagnose, fit, target
    from mtwin.loop.measurement import Measurement
    from mtwin.loop.synth import synthesize

    tw = mtwin.Twin()
    prog = tw.load(program(a.minutes), path="bench.nc")
    t0 = time.perf_counter()
    base = tw.simulate(prog)
    print(f"program: {len(prog.records):,} moves, cycle {base.summary.cycle_time / 60:.1f} min; first simulation "
          f"(compiles, engagement) {time.perf_counter() - t0:.1f} s")
    signals = ["x", "y", "z", "spindle_power", "x_torque", "y_torque", "z_torque"]
    hidden = tw.with_effects("tool-wear:rate=0.3", "coulomb-friction:fx=120")
    cols = synthesize(hidden, prog, rate=100, noise=0.02, seed=1, signals=signals)
    meas = Measurement("bench.csv", cols["t"], {s: cols[s] for s in signals}, cols["line"].astype(np.int64))
    print(f"measurement: {len(cols['t']):,} samples at 100 Hz, 2 % noise, hidden tool-wear and coulomb-friction")
    for align in ("line", "position", "xcorr"):
        t0 = time.perf_counter()
        trace = tw.simulate(prog)
        c = compare(trace, meas, align)
        dt = time.perf_counter() - t0
        print(f"compare --align {align:8} {dt:6.2f} s (target < 5 s; simulation included)  "
              f"spindle_power NRMSE {c.signals['spindle_power']['nrmse']:.3%}")
    t0 = time.perf_counter()
    tg = target(tw, prog, meas)
    d = diagnose(tg)
    dt = time.perf_counter() - t0
    top = {s: v["candidates"][0]["effect"] if v["candidates"] else "-" for s, v in d.items() if v["verdict"] != "fits"}
    print(f"diagnose (whole catalogue) {dt:6.2f} s (target < 60 s); best per signal: {top}")
    from mtwin.effects import get

    for name in ("tool-wear", "spindle-no-load"):
        t0 = time.perf_counter()
        res = fit(tg, [get(name)()], ["spindle_power"])
        dt = time.perf_counter() - t0
        print(f"calibrate {name:16} {dt:6.2f} s (target < 30 s), {res.evaluations} simulations, "
              f"{ {k.rsplit('.', 1)[-1]: round(v, 4) for k, v in res.params.items()} }")


if __name__ == "__main__":
    main()
