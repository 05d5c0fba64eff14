"""Before/after figures of issue 20's reshaping (commands over a use-case API, the typed
kernel boundary, the one fitting core): none may be worse than before by more than 5 %.

    python benchmarks/bench_reshape.py [--ref 7c34e06] [--repeat 3] [--only NAME]

Each figure is measured in fresh processes, alternately for the reference commit (checked out
into a temporary git worktree, run from its own ``src``) and for this checkout, so that a
drift of the machine's speed falls on both alike; the median is printed.

* warm ``mtwin simulate samples/pocket.nc --json``: the whole process, kernels cached;
* re-simulation of the 1-hour, 100,000-move raster with new feeds (``twin.simulate(prog,
  feeds=…)`` after a first simulation: the engagement reused, as the optimiser does);
* cold compile of the run kernel, the interpreter kernel and the planner kernels: an empty
  cache directory, ``MTWIN_KERNELS=compiled``, the seconds numba spends compiling ``run_twin``
  (with the kernels it calls), ``interp_kernel``, the planner's kernels;
* ``diagnose`` over the whole catalogue on the tutorial's recording (``samples/measurements/
  pocket_hidden.csv``: two hidden effects), in-process after a warm-up.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

RESIM = r"""
import sys, time, json
sys.path.insert(0, sys.argv[1] + "/benchmarks")
from bench_motion import make_program
import mtwin
tw = mtwin.Twin()
prog = tw.load(make_program(100_000), path="raster.nc")
tw.simulate(prog)
t0 = time.perf_counter()
tw.simulate(prog, feeds=prog.records["feed"] * 1.1)
print(json.dumps(time.perf_counter() - t0))
"""

COLD = r"""
import json, os, sys
os.environ["MTWIN_KERNELS"] = "compiled"
import mtwin
try:
    from mtwin import jit as _jit
except ImportError:  # (before issue 36: the module was mtwin._jit)
    from mtwin import _jit
tw = mtwin.Twin()
tw.simulate(tw.load(open(os.path.join(os.environ["MTWIN_ROOT"], "samples", "contour.nc"), "rb").read(), path="c.nc"))
print(json.dumps(sum(s for name, s in _jit.COMPILE_LOG if sys.argv[2] in name)))
"""

DIAGNOSE = r"""
import json, os, time
import mtwin
from mtwin.loop.fit import diagnose, target
from mtwin.loop.measurement import read_measurement
root = os.environ["MTWIN_ROOT"]
tw = mtwin.Twin()
prog = tw.load(os.path.join(root, "samples", "pocket.nc"))
meas = read_measurement(os.path.join(root, "samples", "measurements", "pocket_hidden.csv"))
diagnose(target(tw, prog, meas), ["spindle-no-load"])  # (warm-up: kernels loaded)
t0 = time.perf_counter()
diagnose(target(tw, prog, meas))
print(json.dumps(time.perf_counter() - t0))
"""


def _env(src: Path, **extra) -> dict:
    return {**os.environ, "PYTHONPATH": str(src / "src"), "MTWIN_ROOT": str(src), "MTWIN_BACKGROUND_COMPILE": "0",
            **extra}


def _python(src: Path, code: str, *args, **env) -> float:
    r = subprocess.run([sys.executable, "-c", code, str(src), *args], capture_output=True, text=True,
                       env=_env(src, **env), cwd=src)
    if r.returncode != 0:
        raise SystemExit(f"{src}: {r.stderr[-2000:]}")
    return float(json.loads(r.stdout.strip().splitlines()[-1]))


def warm_simulate(src: Path) -> float:
    import time

    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "mtwin", "simulate", "samples/pocket.nc", "--json"], cwd=src,
                       env=_env(src), capture_output=True)
    if r.returncode != 0:
        raise SystemExit(r.stderr.decode()[-2000:])
    return time.perf_counter() - t0


def cold_compile(src: Path, kernel: str = "run_twin") -> float:
    """Seconds numba spends compiling the kernels whose name holds ``kernel``, on an empty cache."""
    with tempfile.TemporaryDirectory() as cache:
        return _python(src, COLD, kernel, NUMBA_CACHE_DIR=cache)


FIGURES = {
    "warm simulate samples/pocket.nc (process), s": warm_simulate,
    "re-simulation of the 1-hour raster with new feeds, s": lambda src: _python(src, RESIM),
    "cold compile of the run kernel, s": cold_compile,
    "cold compile of the interpreter kernel, s": lambda src: cold_compile(src, "interp_kernel"),
    "cold compile of the planner kernels, s": lambda src: cold_compile(src, "_plankernel"),
    "diagnose over the catalogue (tutorial recording), s": lambda src: _python(src, DIAGNOSE),
}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--ref", default="7c34e06", help="the commit before issue 20's reshaping")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--only", default=None, help="a substring of the figures to measure")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        ref = Path(tmp) / "ref"
        subprocess.run(["git", "worktree", "add", "--detach", str(ref), a.ref], cwd=ROOT, check=True,
                       capture_output=True)
        try:
            print(f"{'figure':56} {'before (' + a.ref + ')':>16} {'after':>10} {'change':>8}")
            for name, measure in FIGURES.items():
                if a.only and a.only not in name:
                    continue
                runs = {ref: [], ROOT: []}
                if "cold" not in name:  # an untimed run first: each side's kernels compiled and cached
                    for src in (ref, ROOT):
                        measure(src)
                for _ in range(a.repeat):
                    for src in (ref, ROOT):
                        runs[src].append(measure(src))
                b, f = statistics.median(runs[ref]), statistics.median(runs[ROOT])
                print(f"{name:56} {b:16.3f} {f:10.3f} {f / b - 1:+8.1%}", flush=True)
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(ref)], cwd=ROOT, capture_output=True)


if __name__ == "__main__":
    main()
