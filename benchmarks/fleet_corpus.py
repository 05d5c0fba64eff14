"""mtwin batch optimize over the real-program corpus (../shared/realdata) × two twin files,
each ok job's outputs checked byte for byte against the same command run alone (a process of
its own), each failure against the single command's exit code and message.

    python benchmarks/fleet_corpus.py [--max-lines 400] [--limit 60] [--workers 2]

Programs are the corpus's G-code files (LinuxCNC's ``bad/`` cases left out, they are meant to
fail) of at most ``--max-lines`` lines, the first ``--limit`` by path.  Prints the counts, the
wall time of the batch, and every mismatch (none expected).
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
REALDATA = Path(os.environ.get("MTWIN_SHARED", ROOT.parent / "shared")) / "realdata"
TWINS = [ROOT / "samples" / "machines" / "hurco-vmx24.toml", ROOT / "samples" / "machines" / "linuxcnc-sim.toml"]


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--max-lines", type=int, default=400)
    ap.add_argument("--limit", type=int, default=60)
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args()
    if not REALDATA.is_dir():
        print(f"{REALDATA} not present")
        return 0
    from mtwin.cli import run_command
    from mtwin.fleet import jobs_from_paths, run_batch
    from mtwin.fleet.runner import Cluster

    exts = (".nc", ".ngc", ".tap", ".gcode")
    progs = []
    for p in sorted(REALDATA.rglob("*")):
        if p.is_file() and p.suffix.lower() in exts and "/bad/" not in str(p):
            with open(p, "rb") as fh:
                if sum(1 for _ in fh) <= a.max_lines:
                    progs.append(str(p))
    progs = progs[:a.limit]
    jobs = jobs_from_paths("optimize", progs, [str(t) for t in TWINS], [])
    out = Path(tempfile.mkdtemp(prefix="fleet-corpus-"))
    c = Cluster(workers=a.workers) if a.workers else None
    t0 = time.perf_counter()
    try:
        b = run_batch("optimize", jobs, str(out / "batch"), run_command, (), c)
    finally:
        if c is not None:
            c.close()
    wall = time.perf_counter() - t0
    print(f"{len(jobs)} jobs ({len(progs)} programs × 2 twin files): {b.counts} in {wall:.1f} s "
          f"on {b.runner}")
    bad = 0
    t1 = time.perf_counter()
    for j in jobs:
        o = b.outcomes[j.name]
        prog, rep = out / "p.out", out / "r.html"
        for f in (prog, rep):
            f.unlink(missing_ok=True)
        r = subprocess.run([sys.executable, "-m", "mtwin", "optimize", j.program, "--twin", j.twin, "-o", str(prog),
                            "--report", str(rep)], capture_output=True, text=True)
        if o.status == "ok":
            same = (r.returncode == 0 and prog.read_bytes() == o.outputs["program"][1]
                    and rep.read_bytes() == o.outputs["report"][1])
        else:
            same = r.returncode != 0 and o.error in r.stderr
        if not same:
            bad += 1
            print(f"MISMATCH {j.name}: batch {o.status} {o.error[:120]!r}; alone exit {r.returncode} "
                  f"{r.stderr.strip().splitlines()[-1][:120] if r.stderr.strip() else ''!r}")
    print(f"single commands: {time.perf_counter() - t1:.1f} s; {len(jobs) - bad} of {len(jobs)} jobs equal "
          f"(ok: outputs byte for byte; failed/refused: same exit and message), {bad} mismatch(es)")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
