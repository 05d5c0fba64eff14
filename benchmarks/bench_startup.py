"""Start-up benchmark: whole-process `mtwin` commands, cold (empty kernel cache) and warm.

Run: python benchmarks/bench_startup.py [--repeat 3] [--full]

Each figure is the wall time of a fresh `mtwin` process, as a CAM post-processing step
or a new user meets it.  "cold" runs with NUMBA_CACHE_DIR pointing at an empty directory
(a fresh container, a first install); "warm" runs again on the cache the cold run left.
--full adds a cold parse of the 200,000-line program, which compiles the interpreter
kernel (about a minute on a 2-core machine).

Targets (issue 9): cold first `simulate samples/pocket.nc` <= 20 s (goal 10 s); warm
`parse` of a small file <= 0.6 s, `simulate samples/pocket.nc` <= 1.0 s, `parse` of
200,000 lines <= 1.5 s.
"""
from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
from bench_parse import generate  # noqa: E402

SMALL = b"G21 G90\nG0 X0 Y0\nG1 X10 F100\nM30\n"


def run(args: list[str], cache: str) -> float:
    env = dict(os.environ, NUMBA_CACHE_DIR=cache)
    t = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "mtwin", *args], env=env, cwd=ROOT,
                       stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    dt = time.perf_counter() - t
    if p.returncode != 0:
        raise SystemExit(f"mtwin {' '.join(args)} failed ({p.returncode}):\n{p.stderr.decode()}")
    return dt


def wait_for_background_warm_up(cache: str) -> None:
    """A first run may have started a background compile: the warm figures wait for it."""
    lock = Path(cache) / "warming.lock"
    while lock.exists():
        time.sleep(0.5)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--full", action="store_true", help="also a cold parse of 200,000 lines (compiles the interpreter)")
    a = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="mtwin-bench-"))
    small = work / "small.nc"
    small.write_bytes(SMALL)
    big = work / "big.nc"
    big.write_bytes(generate(200_000))
    rows = []
    try:
        cache = str(work / "cache")
        rows.append(("cold", "mtwin parse small.nc (4 lines)", run(["parse", str(small)], cache), None))
        rows.append(("cold", "mtwin simulate samples/pocket.nc", run(["simulate", "samples/pocket.nc"], cache), 20.0))
        wait_for_background_warm_up(cache)
        if a.full:
            rows.append(("cold", "mtwin parse big.nc (200,000 lines)", run(["parse", str(big)], cache), None))
        else:
            # warm the interpreter for the warm figures below without timing the compile
            run(["cache", "warm", "--quiet"], cache)
        for label, args, target in (("mtwin --help", ["--help"], None),
                                    ("mtwin parse small.nc (4 lines)", ["parse", str(small)], 0.6),
                                    ("mtwin simulate samples/pocket.nc", ["simulate", "samples/pocket.nc"], 1.0),
                                    ("mtwin parse big.nc (200,000 lines)", ["parse", str(big)], 1.5)):
            times = [run(args, cache) for _ in range(a.repeat)]
            rows.append(("warm", label, statistics.median(times), target))
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print(f"{'':5} {'command':40} {'wall s':>8} {'target':>8}")
    for kind, label, t, target in rows:
        tgt = f"<= {target:g}" if target else ""
        flag = "" if target is None or t <= target else "  MISSED"
        print(f"{kind:5} {label:40} {t:8.2f} {tgt:>8}{flag}")


if __name__ == "__main__":
    main()
