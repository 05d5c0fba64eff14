"""Issue 21's figures: diagnose and calibrate of the flank-wear law on per-cut rows, and the cost of
recording a run to the tool ledger.

    python benchmarks/bench_wear.py [--passes 315] [--repeat 3]

The per-cut data are the hidden-law test's (tests/test_wear_hidden_law.py): side-milling passes,
an Archard land integrated by scipy, 3 % noise.  Times are wall-clock, warm numba cache.
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
sys.path.insert(0, str(ROOT / "tests"))


def _run(args) -> float:
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "mtwin", *args], capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(r.stderr[-2000:])
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--passes", type=int, default=315)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    import test_wear_hidden_law as H

    H.PASSES = a.passes
    with tempfile.TemporaryDirectory() as d:
        class _Factory:
            def mktemp(self, name):
                p = Path(d) / name
                p.mkdir(exist_ok=True)
                return p

        data = H.data.__wrapped__(_Factory())
        prog, meas = data["program"], data["a"]
        print(f"{data['rows']} per-cut rows, land at the end {data['vb_a']:.3f} mm")
        sig = "fx_rms,fy_rms"
        best = lambda f: min(f() for _ in range(a.repeat))  # noqa: E731
        t = best(lambda: _run(["diagnose", prog, meas, "--signals", sig, "--json"]))
        print(f"diagnose ({a.passes} rows, every candidate): {t:.1f} s  (target < 30 s)")
        twin = os.path.join(d, "t.toml")
        t = best(lambda: _run(["calibrate", prog, meas, "--fit", "flank-wear", "--signals", sig, "-o", twin]))
        print(f"calibrate flank-wear: {t:.1f} s  (target < 30 s)")
        # recording: the same simulate with and without --record (the ledger's own cost)
        wear = os.path.join(d, "wear.toml")
        Path(wear).write_text("[effects.flank-wear]\nrate = 0.003\nbreak_in = 0.05\n")
        pocket = str(ROOT / "samples" / "pocket.nc")
        ledger = os.path.join(d, "l.db")
        base = ["simulate", pocket, "--twin", wear, "--ledger", ledger, "--tool-id", "T1=EM6#1"]
        plain = best(lambda: _run(base))
        rec = best(lambda: _run(base + ["--record"]))
        print(f"simulate pocket with the ledger: {plain:.3f} s; with --record {rec:.3f} s: the record adds "
              f"{rec - plain:+.3f} s  (target < 0.2 s)")
        from mtwin.effects import ToolHistory
        from mtwin.ledger import Ledger

        t0 = time.perf_counter()
        n = 50
        for _ in range(n):
            with Ledger(ledger) as lg:
                lg.record("EM6#2", program="p.nc", tool_number=1, material="al6061", use=ToolHistory(1, 1, 1, 1))
        print(f"Ledger.record alone (open, one transaction, close): {(time.perf_counter() - t0) / n * 1e3:.1f} ms")


if __name__ == "__main__":
    main()
