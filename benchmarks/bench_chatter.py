"""Issue 22's figures: stability lobes by the zero-order approximation and by
semi-discretisation, chatter-aware optimisation of the sample, the time-domain model, and the
chatter kernels' cold compile.

    python benchmarks/bench_chatter.py [--repeat 3]

The lobes are the classic benchmark's (2 flutes, Kt 6e8, Kn 2e8 N/m², 922 Hz, ζ 0.011,
m 0.03993 kg, one mode along the feed, down-milling, 5,000–25,000 rpm).  Warm times are the
median of ``--repeat`` runs in this process (kernels compiled once before); the cold compile
runs in a fresh process with an empty numba cache.
"""
from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "samples"


def _median(fn, repeat: int) -> float:
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return float(np.median(out))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    from mtwin.chatter.lobes import Cut, Dynamics, lobes
    from mtwin.chatter.modes import Mode

    bench = Dynamics((Mode("x", 922.0, 0.011, 0.03993 * (2 * math.pi * 922.0) ** 2),))
    slot, low = Cut.of(1.0, "down"), Cut.of(0.1, "down")
    sp500 = np.linspace(5000, 25000, 500)
    sp200 = np.linspace(5000, 25000, 200)
    lobes(bench, slot, 2, 600, 200, sp500[:4], "zoa")
    lobes(bench, low, 2, 600, 200, sp200[:2], "sdm", refine=False)
    t_zoa = _median(lambda: lobes(bench, slot, 2, 600, 200, sp500, "zoa", refine=False), a.repeat)
    t_zoa_ref = _median(lambda: lobes(bench, slot, 2, 600, 200, sp500, "zoa"), a.repeat)
    print(f"lobes, zero-order approximation, 500 speeds: {t_zoa:.3f} s warm ({t_zoa_ref:.3f} s with the refinement "
          f"of the minima)  [target < 0.5 s]")
    for steps in (20, 40):
        t = _median(lambda: lobes(bench, low, 2, 600, 200, sp200, "sdm", steps=steps, refine=False), 1)
        res = lobes(bench, low, 2, 600, 200, sp200, "sdm", steps=steps, refine=False)
        print(f"lobes, semi-discretisation, ae/D 0.1, 200 speeds, {steps} steps (a bisection per speed): {t:.2f} s "
              f"warm; lowest limit {res.depth_limit.min():.4f} mm, {int(res.flip.sum())} speeds on flip lobes  "
              f"[target < 10 s]")

    def optimise():
        with tempfile.TemporaryDirectory() as d:
            r = subprocess.run([sys.executable, "-m", "mtwin", "optimize", str(SAMPLES / "chatter_demo.nc"), "--twin",
                                str(SAMPLES / "machines" / "chatter-demo.toml"), "--spindle-range", "8000,24000",
                                "-o", os.path.join(d, "o.nc")], capture_output=True, text=True)
            if r.returncode != 0:
                raise SystemExit(r.stderr[-2000:])

    optimise()
    print(f"optimize samples/chatter_demo.nc with chatter (spindle range 8,000-24,000 rpm), whole command: "
          f"{_median(optimise, a.repeat):.2f} s warm  [target < 5 s]")

    def run(*extra):
        r = subprocess.run([sys.executable, "-m", "mtwin", "simulate", str(SAMPLES / "chatter_demo.nc"), "--twin",
                            str(SAMPLES / "machines" / "chatter-demo.toml"), *extra], capture_output=True, text=True)
        if r.returncode != 0:
            raise SystemExit(r.stderr[-2000:])

    run("--dynamics")
    t0, t1 = _median(run, a.repeat), _median(lambda: run("--dynamics"), a.repeat)
    print(f"simulate samples/chatter_demo.nc (36 s program): {t0:.2f} s; with --dynamics {t1:.2f} s "
          f"(+{t1 - t0:.2f} s for the regenerative model at 64 steps per tooth)")
    code = ("import time, math, numpy as np\n"
            "from mtwin.chatter.lobes import Cut, Dynamics, lobes\n"
            "from mtwin.chatter.modes import Mode\n"
            "d = Dynamics((Mode('x', 922.0, 0.011, 1.34e6),))\n"
            "t = time.perf_counter(); lobes(d, Cut.of(1.0), 2, 600, 200, np.linspace(5e3, 25e3, 4), 'zoa')\n"
            "z = time.perf_counter() - t; t = time.perf_counter()\n"
            "lobes(d, Cut.of(0.1), 2, 600, 200, np.linspace(5e3, 25e3, 2), 'sdm', refine=False)\n"
            "s = time.perf_counter() - t\n"
            "from mtwin.chatter import _lobekernel as LK\n"
            "n = 10; a = np.zeros(n); t = time.perf_counter()\n"
            "LK.regen_trace(np.full(n, 1e-3), np.full(n, 1e4), np.full(n, 1e-4), np.full(n, 1e-3), np.zeros(n), "
            "np.full(n, 3.0), np.zeros(n), np.ones(n, np.int64), np.ones(n, np.bool_), 2, 6e8, 0.3, np.array([922.0]), "
            "np.array([0.011]), np.array([1.34e6]), np.array([0]), 64, 10, a.copy(), a.copy(), a.copy(), np.zeros(10), "
            "np.zeros(10), np.zeros(n, np.int64))\n"
            "print(z, s, time.perf_counter() - t)\n")
    with tempfile.TemporaryDirectory() as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache, "MTWIN_KERNELS": "compiled"}
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
        if out.returncode != 0:
            raise SystemExit(out.stderr[-2000:])
        z, s, r = (float(x) for x in out.stdout.split())
    print(f"cold compile (empty cache): zoa {z:.2f} s, sdm {s:.2f} s, time-domain {r:.2f} s "
          f"(total {z + s + r:.2f} s, once per installation)")


if __name__ == "__main__":
    main()
