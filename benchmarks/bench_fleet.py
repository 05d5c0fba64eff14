"""Issue 23's figures: mtwin batch optimize on Dask against a plain loop, and what a shop's
fleet would need.

    python benchmarks/bench_fleet.py [--copies 2] [--no-cold]

The jobs: the bundled samples × two twin files (hurco-vmx24, linuxcnc-sim), ``--copies`` times
(≥ 20 jobs).  Printed:

* wall time of the batch one job at a time in this process (the plain loop), on a local
  cluster of 1 worker and of 2 workers (cluster start-up apart), and the speed-up 2 vs 1;
* the per-job overhead of Dask against the plain loop ((1 worker − loop) / jobs);
* each worker's first-task warm-up: with the user's warm kernel cache, and with an empty one
  (the cold-cache cost per worker — what a fresh cluster node pays once);
* the projection for 100 machines × 50 programs a day of 20 minutes each, at the measured
  compute time per second of machining (docs/fleet.md).
"""
from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SAMPLES = ROOT / "samples"
TWINS = [SAMPLES / "machines" / "hurco-vmx24.toml", SAMPLES / "machines" / "linuxcnc-sim.toml"]


def _jobs(copies: int, tmp: Path):
    from mtwin.fleet import jobs_from_paths

    progs = sorted(p for p in SAMPLES.iterdir() if p.suffix in (".nc", ".tap"))
    paths = []
    for c in range(copies):  # copies under other names: the jobs are distinct
        for p in progs:
            q = tmp / f"{p.stem}-{c}{p.suffix}"
            shutil.copy(p, q)
            paths.append(str(q))
    return jobs_from_paths("optimize", paths, [str(t) for t in TWINS], [])


def _batch(jobs, out, runner):
    from mtwin.cli import run_command
    from mtwin.fleet import run_batch

    t0 = time.perf_counter()
    b = run_batch("optimize", jobs, out, run_command, (), runner)
    return time.perf_counter() - t0, b


def _warm_seconds(cache_dir=None) -> list:
    """Each worker's warm-up (its first task's kernel loading or compiling), on a 1-worker
    cluster whose worker uses ``cache_dir`` (None: the user's cache)."""
    from mtwin.fleet.runner import Cluster

    c = Cluster(workers=1, env={"NUMBA_CACHE_DIR": cache_dir} if cache_dir else None)
    try:
        def warm():
            import time as _t

            from mtwin.warmup import warm as _warm

            t0 = _t.perf_counter()
            _warm()
            return _t.perf_counter() - t0

        return list(c.client.run(warm).values())
    finally:
        c.close()


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--copies", type=int, default=2, help="copies of the sample set (10 programs × 2 twins each)")
    ap.add_argument("--no-cold", action="store_true", help="skip the cold-cache measurement (it compiles for minutes)")
    a = ap.parse_args()
    from mtwin.fleet.runner import Cluster

    tmp = Path(tempfile.mkdtemp(prefix="bench-fleet-"))
    try:
        jobs = _jobs(a.copies, tmp)
        n = len(jobs)
        print(f"{n} jobs: {n // 2} programs × 2 twin files; {os.cpu_count()} cores")
        t_loop, b = _batch(jobs, tmp / "loop", None)  # (the first run also warms this process)
        t_loop, b = _batch(jobs, tmp / "loop", None)
        ok = [o for o in b.outcomes.values() if o.status == "ok"]
        machining = sum(o.record["before"]["cycle_time"] for o in ok)
        compute = sum(o.seconds for o in ok)
        print(f"plain loop, this process: {t_loop:.1f} s ({b.counts['ok']} ok, {b.counts['failed']} failed)")
        walls = {}
        for w in (1, 2):
            t0 = time.perf_counter()
            c = Cluster(workers=w)
            c.client.run(lambda: __import__("mtwin.fleet.runner").fleet.runner.warmed_job)  # (imports only)
            start = time.perf_counter() - t0
            try:
                _batch(jobs[:w], tmp / f"warm{w}", c)  # every worker's first task: its warm-up
                walls[w], bw = _batch(jobs, tmp / f"dask{w}", c)
            finally:
                c.close()
            same = all(bw.outcomes[j.name].outputs == b.outcomes[j.name].outputs for j in jobs)
            print(f"local cluster, {w} worker(s): {walls[w]:.1f} s (cluster start {start:.1f} s); outputs equal to "
                  f"the loop's: {same}")
        print(f"speed-up, 2 workers vs 1: {walls[1] / walls[2]:.2f}x")
        print(f"Dask's overhead per job against the plain loop: {(walls[1] - t_loop) / n * 1000:.0f} ms "
              f"({(walls[1] / t_loop - 1) * 100:+.1f} %)")
        warm = _warm_seconds()
        print(f"worker warm-up with the warm cache: {warm[0]:.1f} s")
        if not a.no_cold:
            cold = _warm_seconds(str(tmp / "cold-cache"))
            print(f"worker warm-up with an empty cache (the cold-cache cost per worker, once): {cold[0]:.1f} s")
        ratio = compute / machining
        day = 100 * 50 * 20 * 60 * ratio  # core-seconds a day
        print(f"compute per second of machining (optimize, default options): {ratio * 1000:.1f} ms/s "
              f"({compute:.1f} s for {machining:.0f} s of cycle time)")
        print(f"projection, 100 machines × 50 programs × 20 min a day: {day / 3600:.1f} core-hours a day; "
              f"{day / 3600 / 8:.1f} cores to finish in an 8-hour shift, {day / 3600 / 24:.2f} cores around the clock")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
