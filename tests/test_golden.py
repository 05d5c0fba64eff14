"""Golden outputs of the CLI on the bundled samples (issue 20: taken before the commands move
over a use-case API, so that the move can be shown to change nothing).

Each case runs one command and compares its stdout — JSON (numbers within a relative 1e-6, as
another CPU's last bits may differ; keys that hold run times left out) or bytes (a rewritten
program) — with ``tests/golden/<name>``.  After an intended change of an output:

    MTWIN_UPDATE_GOLDEN=1 python -m pytest tests/test_golden.py

rewrites them; the diff of tests/golden/ is then the change, for review."""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import pytest
from conftest import ROOT

GOLDEN = ROOT / "tests" / "golden"
S = "samples/"
# (name, arguments, kind): kind "json" or "bytes"
CASES = [
    ("parse_pocket.json", ["parse", S + "pocket.nc", "--json"], "json"),
    ("simulate_pocket.json", ["simulate", S + "pocket.nc", "--json"], "json"),
    ("simulate_contour.json", ["simulate", S + "contour.nc", "--json"], "json"),
    ("simulate_face_slot_inch.json", ["simulate", S + "face_slot_inch.nc", "--json"], "json"),
    ("simulate_drilling.json", ["simulate", S + "drilling.nc", "--json"], "json"),
    ("simulate_finish_wall_linuxcnc.json", ["simulate", S + "finish_wall.nc", "--json", "--twin",
                                            S + "machines/linuxcnc-sim.toml"], "json"),
    ("optimize_pocket.nc", ["optimize", S + "pocket.nc", "-o", "-"], "bytes"),
    ("optimize_pocket.json", ["optimize", S + "pocket.nc", "-o", "{tmp}/o.nc", "--json"], "json"),
    ("optimize_ga_reference.nc", ["optimize", S + "ga_reference.nc", "-o", "-", "--method", "ga", "--force-limit",
                                  "60", "--feed-range", "100,500", "--spindle-range", "1000,8000"], "bytes"),
    ("scale_contour.nc", ["scale", S + "contour.nc", "--feed", "1.25", "-o", "-"], "bytes"),
    ("compare_pocket_hidden.json", ["compare", S + "pocket.nc", S + "measurements/pocket_hidden.csv", "--json"],
     "json"),
    ("grind_design.json", ["grind", "design", "--json"], "json"),
]
# keys whose values are run times or cache figures, not outputs
VOLATILE = {"seconds", "search_seconds", "dp_seconds", "engagement_seconds", "trace", "plot"}


def _strip(doc):
    if isinstance(doc, dict):
        return {k: _strip(v) for k, v in doc.items() if k not in VOLATILE}
    if isinstance(doc, list):
        return [_strip(v) for v in doc]
    return doc


def _same(a, b, where="") -> str:
    """'' when ``a`` and ``b`` agree (numbers within a relative 1e-6), else where they first differ."""
    if isinstance(a, dict) and isinstance(b, dict):
        if set(a) != set(b):
            return f"{where}: keys {sorted(set(a) ^ set(b))}"
        for k in a:
            d = _same(a[k], b[k], f"{where}.{k}")
            if d:
                return d
        return ""
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return f"{where}: {len(a)} items, golden {len(b)}"
        for i, (x, y) in enumerate(zip(a, b)):
            d = _same(x, y, f"{where}[{i}]")
            if d:
                return d
        return ""
    if isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        ok = math.isclose(a, b, rel_tol=1e-6, abs_tol=1e-9) or (math.isnan(a) and math.isnan(b))
        return "" if ok else f"{where}: {a!r}, golden {b!r}"
    return "" if a == b else f"{where}: {a!r}, golden {b!r}"


@pytest.mark.parametrize("name,args,kind", CASES, ids=[c[0] for c in CASES])
def test_cli_output_is_the_golden_one(name, args, kind, tmp_path):
    args = [a.replace("{tmp}", str(tmp_path)) for a in args]
    r = subprocess.run([sys.executable, "-m", "mtwin", *args], cwd=ROOT, capture_output=True,
                       env={**os.environ, "MTWIN_BACKGROUND_COMPILE": "0"})
    assert r.returncode == 0, r.stderr.decode()[-2000:]
    path = GOLDEN / name
    got = r.stdout if kind == "bytes" else _strip(json.loads(r.stdout))
    if os.environ.get("MTWIN_UPDATE_GOLDEN") == "1":
        path.write_bytes(got if kind == "bytes" else (json.dumps(got, indent=1, sort_keys=True) + "\n").encode())
        pytest.skip(f"wrote {path}")
    assert path.is_file(), f"no golden output {path}: MTWIN_UPDATE_GOLDEN=1 writes it"
    if kind == "bytes":
        assert got == path.read_bytes(), f"{name}: the output differs from tests/golden/{name}"
    else:
        diff = _same(got, json.loads(path.read_text(encoding="utf-8")))
        assert not diff, f"{name}: {diff}"
