"""Record LinuxCNC 2.9 trajectory-planner reference traces for the motion-twin tests.

Runs every ``tests/data/linuxcnc/*.ngc`` through ``../shared/linuxcnc/run_reference.sh``
(the real LinuxCNC task + tpmod at a 1 ms servo period, limits of ``ref_sim_mm.ini``)
and stores, next to each program, a 100 Hz trace ``<name>.ref.csv.gz``
(t,x,y,z,line,vel,motion_type) and ``<name>.ref.json`` (cycle time and ini limits).
The tests compare ``samples/machines/linuxcnc-sim.toml`` against these files, so CI
does not need LinuxCNC.  Needs linuxcnc-uspace; takes about real time + 3 s per program.

    python3 benchmarks/record_linuxcnc_refs.py [NAME ...]
"""

from __future__ import annotations

import gzip
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / "tests" / "data" / "linuxcnc"
SCRIPT = ROOT.parent / "shared" / "linuxcnc" / "run_reference.sh"


def record(ngc: Path) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, DECIMATE="10")
        out = subprocess.run(["bash", str(SCRIPT), str(ngc), tmp], env=env,
                             capture_output=True, text=True, check=False)
        if out.returncode != 0:
            raise SystemExit(f"{ngc.name}: LinuxCNC run failed:\n{out.stderr}")
        name = ngc.stem
        with open(Path(tmp) / f"{name}.csv", "rb") as src, \
                gzip.GzipFile(DATA / f"{name}.ref.csv.gz", "wb", mtime=0) as dst:
            shutil.copyfileobj(src, dst)
        summary = json.loads((Path(tmp) / f"{name}.summary.json").read_text())
        (DATA / f"{name}.ref.json").write_text(json.dumps(summary, indent=1) + "\n")
        return float(out.stdout.strip().split()[-1])


def main(names: list[str]) -> None:
    progs = sorted(DATA.glob("*.ngc"))
    if names:
        progs = [p for p in progs if p.stem in names]
    for ngc in progs:
        print(f"{ngc.name:28s} cycle time {record(ngc):9.3f} s", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
