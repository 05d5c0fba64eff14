"""Depth layering on the corpus: which real programs a given load limit refuses, and which of
them ``--layers auto`` makes feasible, at what cost in time.

    python3 benchmarks/layers_corpus.py [--corpus ../shared/realdata/gcode_corpus]
        [--materials benchmarks/corpus_materials.toml] [--force-limit 60] [--out layers.jsonl]

Each program is optimised as a user who sets a load limit would (``--force-limit``, the material
named as ``corpus_materials.toml`` says).  A program refused because a cut is over the limit
even at the lowest feed is optimised again with ``--layers auto``.  Each layered answer is
checked from outside: re-simulated on a fresh twin, its peak load is within the limit; it
leaves the original's part (``prove_stock``, run here again).  Prints one line per refused
program and the totals: refused, made feasible, why the rest are not, and the time each layered
answer takes against the program as written (which breaks the limit).
"""
from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from optimize_corpus import Timeout, _alarm, material_for, programs  # noqa: E402


def one(path: Path, limit: float, material: str | None, timeout: int) -> dict:
    import mtwin
    from mtwin.api.verify import prove_stock
    from mtwin.errors import MtwinError
    from mtwin.optimize.run import InfeasibleError, OptimizeOptions, optimize

    rec: dict = {"program": str(path), "material": material, "force_limit": limit}
    tw = mtwin.Twin()
    if material:
        tw = tw.with_material(material)
    signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(timeout)
    try:
        prog = tw.load(str(path))
        try:
            optimize(tw, prog, OptimizeOptions(force_limit=limit))
            rec["status"] = "feasible"
            return rec
        except InfeasibleError as exc:
            rec["refused"] = str(exc).splitlines()[0][:300]
        t0 = time.perf_counter()
        try:
            res = optimize(tw, prog, OptimizeOptions(force_limit=limit, max_layers=8))
        except InfeasibleError as exc:
            why = str(exc)  # (the layering's own reason is the last part: "… — and lines a-b cannot …")
            rec.update(status="still refused", reason=why[why.rfind(" — ") + 3:][:300] if " — " in why else why[:300])
            return rec
        rec["seconds"] = time.perf_counter() - t0
        written = tw.load(res.output, path=str(path))
        again = mtwin.Twin().with_material(material) if material else mtwin.Twin()
        after = again.simulate(again.load(res.output, path=str(path))).summary
        before = again.simulate(again.load(str(path))).summary
        proof = prove_stock(again, prog, written)
        rec.update(status="layered", layers=[ly["layers"] for ly in res.layers],
                   cycle_as_written=before.cycle_time, cycle_layered=after.cycle_time,
                   peak_load=float(after.cutting.peak_load) if after.cutting else 0.0,
                   within_limit=bool(after.cutting is None or after.cutting.peak_load <= limit * 1.001),
                   same_part=proof.same)
        return rec
    except Timeout:
        rec["status"] = "timeout"
        return rec
    except MtwinError as exc:
        rec.update(status="error", reason=str(exc).splitlines()[0][:200])
        return rec
    finally:
        signal.alarm(0)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--corpus", default=str(ROOT.parent / "shared" / "realdata" / "gcode_corpus"))
    ap.add_argument("--materials", default=str(ROOT / "benchmarks" / "corpus_materials.toml"))
    ap.add_argument("--force-limit", type=float, default=60.0)
    ap.add_argument("--timeout", type=int, default=300)
    ap.add_argument("--out", default=None)
    ap.add_argument("--resume", action="store_true", help="skip the programs already in --out")
    ap.add_argument("--programs", default=None, help="a file of program paths, one a line: only these")
    a = ap.parse_args()
    import tomllib

    rules = tomllib.loads(Path(a.materials).read_text(encoding="utf-8"))["rule"] if a.materials else []
    recs = []
    if a.resume and a.out and Path(a.out).exists():
        recs = [json.loads(line) for line in Path(a.out).read_text(encoding="utf-8").splitlines() if line.strip()]
    seen = {r["program"] for r in recs}
    only = set(Path(a.programs).read_text(encoding="utf-8").split("\n")) if a.programs else None
    for p in programs(Path(a.corpus)):
        if str(p) in seen or (only is not None and str(p) not in only):
            continue
        m = material_for(p, rules)
        r = one(p, a.force_limit, m[0] if m else None, a.timeout)
        recs.append(r)
        if r["status"] not in ("feasible", "error"):
            extra = (f"layers {r['layers']}, {r['cycle_as_written']:.1f} -> {r['cycle_layered']:.1f} s "
                     f"({r['cycle_layered'] / r['cycle_as_written'] - 1:+.1%}), peak {r['peak_load']:.1f} N, "
                     f"same part {r['same_part']}" if r["status"] == "layered" else r.get("reason", ""))
            print(f"{p.name}: {r['status']}: {extra}", flush=True)
        if a.out:
            with open(a.out, "a", encoding="utf-8") as f:
                f.write(json.dumps(r) + "\n")
    done = [r for r in recs if r["status"] == "layered"]
    refused = [r for r in recs if r["status"] in ("layered", "still refused")]
    print(f"\n{len(recs)} programs at --force-limit {a.force_limit:g} N: {len(refused)} refused; "
          f"{len(done)} feasible with --layers auto, {len(refused) - len(done)} still refused; "
          f"{sum(r['status'] == 'error' for r in recs)} errors, {sum(r['status'] == 'timeout' for r in recs)} "
          f"timeouts")
    if done:
        ch = sorted(r["cycle_layered"] / r["cycle_as_written"] - 1 for r in done)
        print(f"time against the program as written (over the limit): min {ch[0]:+.1%}, median "
              f"{ch[len(ch) // 2]:+.1%}, max {ch[-1]:+.1%}; within the limit {sum(r['within_limit'] for r in done)}"
              f"/{len(done)}, same part {sum(r['same_part'] for r in done)}/{len(done)}")
    why: dict = {}
    for r in refused:
        if r["status"] == "still refused":
            why[r["reason"][:80]] = why.get(r["reason"][:80], 0) + 1
    for k, v in sorted(why.items(), key=lambda x: -x[1]):
        print(f"  still refused ({v}): {k}")


if __name__ == "__main__":
    main()
