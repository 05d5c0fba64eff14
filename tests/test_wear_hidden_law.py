"""Flank wear found and fitted from per-cut force statistics made by a hidden law that this
test writes itself (issue 21): 300 side-milling passes of one cutter, the land growing along
Archard's break-in curve — integrated here with scipy, from the edge sliding this test counts
on the samples — and the land's contact forces added to the sharp tool's by superposition of
unit edge-coefficient simulations, 3 % noise (300 passes).  diagnose must rank the wear effect first,
calibrate recover the law within 10 %, and the calibrated twin carry over to a second cutter
that wears 25 % faster."""
from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from scipy.integrate import solve_ivp

PASSES = 300
AE, FEED, RPM, RADIUS, FLUTES = 1.0, 1600.0, 8000.0, 3.0, 2
HIDDEN = {"rate": 0.0015, "break_in": 0.05}  # mm/m of edge sliding, mm
SIGMA, MU = 400.0, 0.5  # the land's stresses: the force law the twin knows (flank-wear's defaults)
SECOND_RATE = 1.25 * HIDDEN["rate"]


def passes_program(n: int) -> str:
    top = AE * n + 5
    out = ["%", "O2001 (SIDE PASSES FOR A WEAR TEST)", "(T1 D=6. CR=0. - FLAT END MILL, 2 FLUTES, CARBIDE)",
           f"(MTWIN STOCK 0,0,-2,20,{top:.1f},0)", "G21 G90 G17 G40 G49 G80 G94", "T1 M6",
           f"G54 G0 X-4. Y{top + 3:.3f} S{RPM:.0f} M3", "G43 H1 Z2."]
    for k in range(1, n + 1):
        out += [f"G0 X-4. Y{top + 3.0 - AE * k:.3f}", "G1 Z-2. F3000.", f"G1 X24. F{FEED:.0f}.", "G0 Z2."]
    return "\n".join(out + ["M5", "M30", "%"]) + "\n"


def _mtwin(*args, code=0):
    r = subprocess.run([sys.executable, "-m", "mtwin", *args], capture_output=True, text=True)
    assert r.returncode == code, r.stderr[-3000:]
    return r


def hidden_land(sliding: np.ndarray, rate: float, break_in: float) -> np.ndarray:
    """VB (mm) along the sliding (m): dVB/ds = rate·(break_in/VB + 1) from a sharp edge."""
    s0 = 1e-7
    sol = solve_ivp(lambda s, y: rate * (break_in / y + 1.0), (s0, float(sliding.max()) + 1.0),
                    [math.sqrt(2 * rate * break_in * s0)], rtol=1e-9, atol=1e-12, dense_output=True)
    return np.where(sliding > s0, sol.sol(np.maximum(sliding, s0))[0], 0.0)


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    from mtwin.twin import Twin

    d = tmp_path_factory.mktemp("wear")
    prog_path = d / "passes.nc"
    prog_path.write_text(passes_program(PASSES))
    tw = Twin.from_toml(None)
    prog = tw.load(prog_path.read_bytes(), path=str(prog_path))
    sharp = tw.simulate(prog)

    def unit(coefficient):
        # the force of 1 N/mm of this edge coefficient: the sharp tool's with 10 N/mm added, less
        # the sharp tool's (the forces are linear in the coefficients at a given feed)
        tr = tw.with_params({f"cutting.al6061.{coefficient}": 10.0}).simulate(prog)
        assert len(tr.t) == len(sharp.t)
        return {s: (tr.signal(s) - sharp.signal(s)) / 10.0 for s in ("fx", "fy")}

    te, re = unit("kte"), unit("kre")
    f = {s: sharp.signal(s) for s in ("fx", "fy")}
    engaged = np.hypot(f["fx"], f["fy"]) > 1e-9
    # each flute's edge sliding: per mm of path 1/(fz·z) revolutions, each through the arc of
    # the tool's circle that is in the material and moving into it — the front half of the
    # circle, below the wall the previous pass left (a_e deep) and over the block (0 ≤ x ≤ 20):
    # counted here on the circle's geometry, as a function of the tool centre's x
    theta = np.linspace(0.0, 2 * math.pi, 7200, endpoint=False)
    px, py = RADIUS * np.sin(theta), -RADIUS * np.cos(theta)  # about the centre; 0 = straight down
    xc_grid = np.linspace(-4.0, 24.0, 2801)
    inside = ((px[None, :] > 0) & (py[None, :] <= -RADIUS + AE)
              & (xc_grid[:, None] + px[None, :] >= 0) & (xc_grid[:, None] + px[None, :] <= 20.0))
    arc_of_x = RADIUS * inside.sum(axis=1) * (2 * math.pi / theta.size)  # mm per revolution
    fz = FEED / (FLUTES * RPM)
    x = sharp.act[:, 0].astype(np.float64)
    ds = np.where(engaged, np.linalg.norm(sharp.vel.astype(np.float64), axis=1) * np.gradient(sharp.t), 0.0)
    sliding = np.cumsum(ds * np.interp(x, xc_grid, arc_of_x) / (fz * FLUTES)) * 1e-3
    rows = sorted(set(sharp.line[engaged].tolist()))
    out = {"program": str(prog_path), "rows": len(rows), "sliding": float(sliding[-1])}
    rng = np.random.default_rng(7)
    for name, rate, noise in (("a", HIDDEN["rate"], 0.03), ("b", SECOND_RATE, 0.03), ("exact", HIDDEN["rate"], 0.0)):
        vb = hidden_land(sliding, rate, HIDDEN["break_in"])
        cols = {}
        for s in ("fx", "fy"):
            total = f[s] + SIGMA * vb * re[s] + MU * SIGMA * vb * te[s]
            cols[s] = np.array([math.sqrt(np.mean(total[sharp.line == ln] ** 2)) for ln in rows])
        text = ["# format: mtwin-measurement 1", "# source: test_wear_hidden_law", "first_line,last_line,fx_rms,fy_rms"]
        noisy = {s: v + rng.normal(0.0, noise * math.sqrt(np.mean(v * v)), len(v)) for s, v in cols.items()}
        text += [f"{ln},{ln},{noisy['fx'][i]:.6g},{noisy['fy'][i]:.6g}" for i, ln in enumerate(rows)]
        (d / f"{name}.csv").write_text("\n".join(text) + "\n")
        out[name] = str(d / f"{name}.csv")
        out[f"vb_{name}"] = float(vb[-1])
        out[f"rise_{name}"] = float(cols["fy"][-1] / cols["fy"][0])
    return out


def test_the_hidden_cutter_wears_like_a_real_one(data):
    assert data["rows"] >= 200
    assert data["rows"] >= 300
    assert 0.12 < data["vb_a"] < 0.3  # a worn but usable land (ISO 8688-2 ends a tool's life at 0.3 mm)
    assert data["rise_a"] > 1.3  # the force per cut grows by a third or more


def test_diagnose_ranks_flank_wear_first_and_calibrate_recovers_the_law(data, tmp_path):
    sig = "fx_rms,fy_rms"
    d = json.loads(_mtwin("diagnose", data["program"], data["a"], "--signals", sig, "--json").stdout)["signals"]
    for s in ("fx_rms", "fy_rms"):
        assert d[s]["candidates"][0]["effect"] == "flank-wear", [c["effect"] for c in d[s]["candidates"][:4]]
        assert d[s]["selected"][0]["effect"] == "flank-wear"
        ev = d[s]["candidates"][0]["evidence"]
        assert "grows with the tool's cumulative cut" in ev and "break-in (its growth" in ev, ev
    twin = str(tmp_path / "worn.toml")
    cal = json.loads(_mtwin("calibrate", data["program"], data["a"], "--fit", "flank-wear", "--signals", sig,
                            "-o", twin, "--validate", data["b"], "--json").stdout)
    # both within 10 %.  The break-in shows only in the passes before the land reaches b (here
    # about the first half): with 200 passes at twice the rate it spanned ~60 passes and 3 %
    # noise left it a 1-sigma uncertainty of 11 % (0.0437 +- 0.0047); this design measures it
    for k, v in HIDDEN.items():
        assert cal["params"][f"effects.flank-wear.{k}"] == pytest.approx(v, rel=0.10), k
        assert cal["uncertainty"][f"effects.flank-wear.{k}"] < 0.1 * v
    for s in ("fx_rms", "fy_rms"):
        assert cal["rms_after"][s] <= 1.5 * cal["noise"][s]
    # the second cutter wears 25 % faster: the calibrated twin is far nearer it than the as-built one
    before = json.loads(_mtwin("compare", data["program"], data["b"], "--json").stdout)["signals"]
    for s in ("fx_rms", "fy_rms"):
        assert cal["validation"][s] < 0.5 * before[s]["rms"]


def test_without_noise_the_law_comes_back_exactly(data):
    import mtwin

    cal = mtwin.calibrate(None, data["program"], data["exact"], fit=["flank-wear"], signals=["fx_rms", "fy_rms"])
    p = cal.as_dict()["params"]
    # (the rate 3-4 % low: the twin's engagement counts the engaged arc in 2-degree bins, the
    # hidden law slides over the exact circle)
    assert p["effects.flank-wear.rate"] == pytest.approx(HIDDEN["rate"], rel=0.05)
    assert p["effects.flank-wear.break_in"] == pytest.approx(HIDDEN["break_in"], rel=0.03)
