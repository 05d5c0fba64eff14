"""Per-cut summary measurements through the loop (issue 21): a program of 315 passes, its
force statistics per pass with hidden tool wear and 3 % noise; prints the wall time of
`diagnose` over the whole catalogue and of `calibrate` of the wear effect, in-process after
a warm-up (kernels compiled).  Targets (issue 21): both < 30 s.

    python benchmarks/bench_summary.py [--passes 315]
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path


def program(passes: int) -> bytes:
    """Slots side by side, one G1 a pass, each 40 mm long at 0.5 mm depth."""
    out = ["%", "(mtwin summary benchmark)", "(MTWIN STOCK -10,-10,-5,60,600,0)", "G21 G90 G94 G17", "T1 M6",
           "S9000 M3", "G0 X0 Y0 Z5", "G1 Z-0.5 F300"]
    for k in range(passes):
        y = 1.5 * (k // 2)
        out.append(f"G1 X{40 if k % 2 == 0 else 0} Y{y:.1f} F900")
    out += ["G0 Z5", "M30", "%"]
    return ("\n".join(out) + "\n").encode()


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--passes", type=int, default=315)
    a = ap.parse_args()
    import mtwin
    from mtwin.loop.measurement import read_measurement

    with tempfile.TemporaryDirectory() as d:
        part = Path(d) / "passes.nc"
        part.write_bytes(program(a.passes))
        meas = Path(d) / "passes.csv"
        hidden = mtwin.Twin().with_effects("tool-wear:rate=0.05")
        mtwin.synthesize(hidden, str(part), summary="line", noise=0.03, seed=1, signals=["fx", "fy"]).write(str(meas))
        rows = len(read_measurement(str(meas)).rows)
        mtwin.diagnose(None, str(part), str(meas), signals=["fy_rms"], candidates=["tool-wear"])  # warm-up
        t0 = time.perf_counter()
        d_ = mtwin.diagnose(None, str(part), str(meas), signals=["fx_rms", "fy_rms"])
        t_diag = time.perf_counter() - t0
        t0 = time.perf_counter()
        cal = mtwin.calibrate(None, str(part), str(meas), fit=["tool-wear"], signals=["fx_rms", "fy_rms"])
        t_cal = time.perf_counter() - t0
    best = d_.signals["fy_rms"]["candidates"][0]
    print(f"{rows} per-cut rows: diagnose over the catalogue {t_diag:.1f} s (best on fy_rms: {best['effect']} "
          f"{best['params']}); calibrate of tool-wear {t_cal:.1f} s (rate "
          f"{cal.result.params['effects.tool-wear.rate']:.4f}, hidden 0.05)")


if __name__ == "__main__":
    main()
