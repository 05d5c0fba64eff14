"""Run the tutorial's commands and write what they print into docs/tutorial.md.

    python scripts/tutorial.py            # rewrite docs/tutorial.md from real runs
    python scripts/tutorial.py --check    # exit 1 (and show the difference) if it is stale

The tutorial's numbers are what the commands print: its output blocks, the comparison
table, the cycle times, the figures of step 4 and the recovered values are filled in here
from runs of the tutorial's own commands (in a scratch folder, with ``samples`` linked in,
so the paths print as the reader's do); the prose around them stays as written.  About
30 s on a 2-core machine.
"""
from __future__ import annotations

import argparse
import difflib
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "tutorial.md"
PART, MEAS = "samples/pocket.nc", "samples/measurements/pocket_hidden.csv"
UNITS = {"spindle_speed": "rpm", "spindle_power": "W", "x_torque": "N·m", "y_torque": "N·m"}


def _run(cwd: str, *args: str) -> subprocess.CompletedProcess:
    r = subprocess.run([sys.executable, "-m", "mtwin", *args], cwd=cwd, capture_output=True, text=True,
                       env={**os.environ, "MTWIN_BACKGROUND_COMPILE": "0"})
    if r.returncode != 0:
        raise SystemExit(f"mtwin {' '.join(args)} failed:\n{r.stderr}")
    return r


def _lines(text: str, keep) -> list[str]:
    return [ln for ln in text.splitlines() if keep(ln) and not ln.startswith("compiling ")]


# figures may differ in their last printed digit between numpy/scipy/numba versions (the
# fits run to a tolerance): --check takes a number within this relative difference (or, with
# decimals, one unit of its last) as the same; whole numbers (counts) must agree
REL_TOL = 1e-3
_NUM = re.compile(r"[-+−]?\d+(?:[.,]\d+)*(?:\.\d+)?(?:e[-+]?\d+)?")


def _same_but_last_digits(old: str, new: str) -> bool:
    """The two texts alike but for numbers within REL_TOL (or a unit of their last decimal)."""
    if _NUM.sub("#", old) != _NUM.sub("#", new):
        return False
    for a, b in zip(_NUM.findall(old), _NUM.findall(new)):
        if a == b:
            continue
        x, y = (float(v.replace("−", "-").replace(",", "")) for v in (a, b))
        dec = len(a.split(".")[1]) if "." in a and "e" not in a else 0
        if abs(x - y) > max(REL_TOL * max(abs(x), abs(y)), 1.0001 * 10.0 ** -dec if dec else 0.0):
            return False
    return True


def _diagnose_block(text: str, most: dict | None = None) -> list[str]:
    """Each signal's verdict and its first candidates (``most``: how many per signal, 1 by
    default; more shown as '…'); a signal that fits shows its verdict alone."""
    out, shown, more, per_signal = [], 0, False, 1
    for ln in text.splitlines():
        if not ln.startswith("  "):
            if more:
                out.append("  …")
            out.append(ln)
            shown, more = 0, False
            per_signal = (most or {}).get(ln.split(":")[0], 1)
        elif ln.startswith("  together:"):
            if more:
                out.append("  …")
                more = False
            out.append(ln)  # the forward selection's answer, always shown
        elif out and out[-1].endswith("— fits"):
            continue
        elif shown < per_signal:
            out.append(ln)
            shown += 1
        else:
            more = True
    if more:
        out.append("  …")
    return out


def _signed(v: float, fmt: str) -> str:
    return format(v, "+" + fmt).replace("-", "−")


def _fill_output_blocks(doc: str, blocks: list) -> str:
    """Replace the contents of the fenced blocks without a language (the commands' output,
    in the tutorial's order) by ``blocks``."""
    out, inside, k = [], None, 0
    for ln in doc.split("\n"):
        if inside is None and ln.startswith("```"):
            inside = ln[3:].strip()
            out.append(ln)
            if inside == "" and k < len(blocks):
                out.extend(blocks[k])
            continue
        if inside is not None and ln.strip() == "```":
            if inside == "":
                k += 1
            inside = None
            out.append(ln)
            continue
        if inside == "" and k < len(blocks):
            continue  # the old output, replaced above
        out.append(ln)
    return "\n".join(out)


def figures() -> dict:
    """Everything the tutorial shows, from real runs."""
    with tempfile.TemporaryDirectory() as tmp:
        os.symlink(ROOT / "samples", Path(tmp) / "samples")
        os.mkdir(Path(tmp) / "tutorial-out")
        c0 = json.loads(_run(tmp, "compare", PART, MEAS, "--json").stdout)
        d0 = _run(tmp, "diagnose", PART, MEAS).stderr
        cal1 = _run(tmp, "calibrate", PART, MEAS, "--fit", "spindle-no-load", "--signals", "spindle_power", "-o",
                    "tutorial-out/twin1.toml").stderr
        d1 = _run(tmp, "diagnose", PART, MEAS, "--twin", "tutorial-out/twin1.toml", "--signals",
                  "spindle_power").stderr
        cal2 = _run(tmp, "calibrate", PART, MEAS, "--twin", "tutorial-out/twin1.toml", "--fit", "tool-wear",
                    "--refit", "--signals", "spindle_power", "-o", "tutorial-out/twin2.toml").stderr
        d2 = json.loads(_run(tmp, "diagnose", PART, MEAS, "--twin", "tutorial-out/twin2.toml", "--json").stdout)
        journal = json.loads(_run(tmp, "journal", "tutorial-out/twin2.toml", "--json").stdout)
        fit2 = json.loads(_run(tmp, "calibrate", PART, MEAS, "--twin", "tutorial-out/twin1.toml", "--fit",
                               "tool-wear", "--refit", "--signals", "spindle_power", "-o", "tutorial-out/twin3.toml",
                               "--json").stdout)
    not_note = (lambda ln: not ln.startswith("note:"))
    return {"compare": c0, "diagnose0": _diagnose_block(d0, {"spindle_power": 3}), "cal1": _lines(cal1, not_note),
            "diagnose1": _diagnose_block(d1), "cal2": _lines(cal2, not_note), "diagnose2": d2["signals"],
            "journal": journal, "params": fit2["params"]}


def render(doc: str, f: dict) -> str:
    c = f["compare"]
    doc = re.sub(r"the cycle times agree \([0-9.]+ s measured, first to last sample;\s+[0-9.]+ s simulated\)",
                 lambda m: m.group(0).split("(")[0] + f"({c['cycle_time']['measured']:.3f} s measured, first to last "
                 f"sample;\n{c['cycle_time']['simulated']:.3f} s simulated)", doc, count=1)
    rows = ["| signal | RMS | NRMSE | bias | correlation |", "|---|---|---|---|---|"]
    for s, u in UNITS.items():
        m = c["signals"][s]
        unit = f" {u}"
        rows.append(f"| {s} | {m['rms']:.4g}{unit} | {100 * m['nrmse']:.2f} % | {_signed(m['bias'], '.2g' if abs(m['bias']) < 1 else '.4g')}"
                    f"{unit if s != 'x_torque' and s != 'y_torque' else ''} | {m['correlation']:.3f} |")
    doc = re.sub(r"\| signal \| RMS \| NRMSE \| bias \| correlation \|\n(?:\|.*\|\n)+", "\n".join(rows) + "\n", doc,
                 count=1)
    doc = _fill_output_blocks(doc, [f["diagnose0"], f["cal1"] + ["…"] + f["diagnose1"], f["cal2"]])
    d2 = f["diagnose2"]
    sp, xt, yt = d2["spindle_power"], d2["x_torque"], d2["y_torque"]
    doc = re.sub(r"Every signal now `fits` \(spindle power [^)]*\)",
                 f"Every signal now `fits` (spindle power {sp['rms']:.3g} W RMS against {sp['noise']:.3g} W of noise; "
                 f"the X and Y torques,\nwhich tool wear also loads, {xt['rms']:.3g} and {yt['rms']:.3g} N·m against "
                 f"{xt['noise']:.3g} and {yt['noise']:.3g})", doc, count=1, flags=re.S)
    jrows = ["| # | effects | spindle_power RMS |", "|---|---|---|"]
    for e in f["journal"]:
        b, a = e["rms_before"]["spindle_power"], e["rms_after"]["spindle_power"]
        jrows.append(f"| {e['entry'] if 'entry' in e else len(jrows) - 1} | {', '.join(e['effects'])} | "
                     f"{b:.4g} → {a:.4g} W |")
    doc = re.sub(r"\| # \| effects \| spindle_power RMS \|\n(?:\|.*\|\n)+", "\n".join(jrows) + "\n", doc, count=1)
    p = f["params"]
    doc = re.sub(r"Recovered: [^\n]*\n[^\n]*", f"Recovered: {p['effects.spindle-no-load.p0']:.1f} W, "
                 f"{p['effects.spindle-no-load.b']:.5f} W/rpm,\n{p['effects.tool-wear.rate']:.3g} /m.", doc, count=1)
    return doc


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--check", action="store_true", help="exit 1 if docs/tutorial.md is not what the runs give")
    a = ap.parse_args()
    old = DOC.read_text(encoding="utf-8")
    new = render(old, figures())
    if a.check:
        if new != old and not _same_but_last_digits(old, new):
            sys.stdout.writelines(difflib.unified_diff(old.splitlines(True), new.splitlines(True), "docs/tutorial.md",
                                                       "from the runs"))
            raise SystemExit(1)
        return
    DOC.write_text(new, encoding="utf-8")


if __name__ == "__main__":
    main()
