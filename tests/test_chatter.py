"""Chatter (issue 22): lobes against closed forms and independent integrations, the
semi-discretisation's convergence and flip lobes, the time-domain twin against the lobes, the
optimiser keeping every cut stable, the tap-test fit, and bad input."""
from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from conftest import SAMPLES

from mtwin.chatter.lobes import Cut, Dynamics, directional, lobes, zoa_slot_minimum
from mtwin.chatter.modes import Mode

# the classic benchmark (Insperger & Stépán 2004; Ding et al. 2010): N = 2, Kt = 6e8 N/m²,
# Kn = 2e8 N/m², one mode along the feed: 922 Hz, ζ 0.011, m 0.03993 kg
FN, ZETA, MASS = 922.0, 0.011, 0.03993
K = MASS * (2 * math.pi * FN) ** 2
BENCH = Dynamics((Mode("x", FN, ZETA, K),))
KTC, KRC = 600.0, 200.0  # N/mm²
DEMO = SAMPLES / "machines" / "chatter-demo.toml"


def mtwin(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "mtwin", *map(str, args)], capture_output=True, text=True, cwd=cwd)


def test_directional_matrix_is_the_mean_of_the_periodic_one():
    """D = Kt·N/(2π)·∫a(φ)dφ against scipy's quadrature of the force model itself, any arc."""
    from scipy.integrate import quad

    kr = KRC / KTC
    for st, ex in ((0.0, math.pi), (0.0, 0.9), (2.4, math.pi), (0.5, 1.7)):
        D = directional(Cut(st, ex), 2, KTC * 1e6, kr)

        def a(phi, i, j):
            s, c = math.sin(phi), math.cos(phi)
            force = (-c - kr * s, s - kr * c)  # per unit K_t·a·h, tool frame
            chip = (s, c)  # h per unit displacement x, y
            return force[i] * chip[j]

        for i in range(2):
            for j in range(2):
                ref = KTC * 1e6 * 2 / (2 * math.pi) * quad(a, st, ex, args=(i, j))[0]
                assert D[i, j] == pytest.approx(ref, rel=1e-9, abs=1e-3)
    # slot, mode along the feed: D_xx = −N·Kn/4
    assert directional(Cut.of(1.0), 2, KTC * 1e6, kr)[0, 0] == pytest.approx(-2 * KRC * 1e6 / 4, rel=1e-12)


def test_zoa_slot_minimum_equals_its_closed_form():
    """min over 5,000–25,000 rpm of the zoa limit = 8kζ(1+ζ)/(N·Kn) (docs/chatter.md), at the
    chatter frequency ωn·√(1+2ζ) where Re Φ is most negative; found within 0.5 %."""
    res = lobes(BENCH, Cut.of(1.0, "down"), 2, KTC, KRC, np.linspace(5000, 25000, 500), "zoa")
    closed = zoa_slot_minimum(K, ZETA, 2, KRC * 1e6) * 1e3
    assert closed == pytest.approx(0.29805, rel=1e-4)
    i = int(np.argmin(res.depth_limit))
    assert res.depth_limit[i] == pytest.approx(closed, rel=5e-3)
    assert res.depth_limit[i] >= closed * (1 - 1e-6)  # (a bound: no speed goes below it)
    assert res.chatter_frequency[i] == pytest.approx(FN * math.sqrt(1 + 2 * ZETA), rel=5e-3)
    assert not res.flip.any()


def test_sdm_converges_and_finds_the_flip_lobes_the_zoa_misses():
    """ae/D 0.1 down-milling at 18,166 rpm: the semi-discretisation's limit settles as its
    steps double (10, 20, 40, 80: 0.7640, 0.7598, 0.7585, 0.7583 mm), its critical multiplier
    is −1 (a flip lobe), and the zoa's limit there is over three times higher."""
    sp = np.array([18166.0])
    cut = Cut.of(0.1, "down")
    d = [float(lobes(BENCH, cut, 2, KTC, KRC, sp, "sdm", steps=s, refine=False).depth_limit[0])
         for s in (10, 20, 40, 80)]
    steps = np.abs(np.diff(d))
    assert steps[0] > steps[1] > steps[2]
    assert abs(d[-1] - d[-2]) / d[-1] < 1e-3
    last = lobes(BENCH, cut, 2, KTC, KRC, sp, "sdm", steps=40, refine=False)
    assert last.flip[0]
    # a flip lobe chatters at half a tooth-passing harmonic: (k + ½)·N·n/60
    tp = 2 * 18166 / 60
    assert (last.chatter_frequency[0] / tp) % 1 == pytest.approx(0.5, abs=0.01)
    zoa = lobes(BENCH, cut, 2, KTC, KRC, sp, "zoa", refine=False).depth_limit[0]
    assert zoa > 3 * d[-1]
    # over the speed range: flip lobes limit some speeds, and the lowest limit is one of them
    full = lobes(BENCH, cut, 2, KTC, KRC, np.linspace(5000, 25000, 120), "sdm", steps=20)
    assert full.flip.any() and full.flip[int(np.argmin(full.depth_limit))]


def test_time_domain_slot_bounded_below_the_lobe_and_chatters_above():
    """simulate --dynamics on a slot at 10,000 rpm (the sample twin, two modes): at 0.95 of
    the lobes' limit the regenerative vibration dies out, at 1.05 it grows to chatter at a
    frequency off the tooth-passing harmonics, near the modes."""
    from mtwin.api import simulate
    from mtwin.chatter.lobes import dynamics_of
    from mtwin.twin import Twin

    tw = Twin.from_toml(str(DEMO))
    mat = tw.cutting.material
    lim = lobes(dynamics_of(tw.cutting.tools[1]), Cut.of(1.0), 2, mat.ktc, mat.krc, np.array([10000.0]), "sdm",
                steps=80, refine=False).depth_limit[0]
    out = {}
    for r in (0.95, 1.05):
        prog = (f"(MTWIN STOCK 0,0,-5,300,60,0)\nG21 G90 G17 G94\nT1 M6\nG0 X-6. Y30. S10000 M3\nG0 Z2.\n"
                f"G1 Z-{r * lim:.4f} F600.\nG1 X306. F1000.\nG0 Z5.\nM30\n")
        sim = simulate(tw, prog.encode(), dynamics=True)
        out[r] = next(x for x in sim.dynamics.lines if x["line"] == 7)
        assert sim.trace.vib is not None and "vib_x" in sim.trace.columns()
    below, above = out[0.95], out[1.05]
    assert not below["chatter"] and below["regen_end_um"] < 0.05 * below["regen_start_um"] + 1e-3
    assert above["chatter"] and above["regen_end_um"] > 100 * max(below["regen_end_um"], 1e-3)
    f = above["chatter_frequency"]
    assert 880 < f < 1060 and abs(f / above["tooth_passing"] - round(f / above["tooth_passing"])) > 0.05


def test_optimize_keeps_every_cut_stable_and_reports_the_rest(tmp_path):
    """The sample: the programmed 10,000 rpm makes the slots chatter; with a spindle range the
    answer's speed holds every cut that can be made stable within the margin — checked again
    on the answer by simulate's own margins — and reports the cuts no speed saves; the HTML
    report renders in headless Chromium with the lobes and the cuts."""
    out, rep = tmp_path / "o.nc", tmp_path / "r.html"
    r = mtwin("optimize", SAMPLES / "chatter_demo.nc", "--twin", DEMO, "--spindle-range", "8000,24000", "-o", out,
              "--report", rep, "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    ch = d["chatter"]
    assert ch["margin"] == 0.8
    movable = [s for s in ch["segments"] if not s["unstable_everywhere"]]
    assert any(s["margin_before"] > 1.0 for s in movable)  # the program chattered
    assert all(s["margin_after"] <= 0.8 for s in movable)
    assert {tuple(u["lines"]) for u in ch["unstable"]} == {(22, 22), (27, 27)}
    assert all(u["deepest_stable"] < u["ap"] for u in ch["unstable"])
    assert "chatter at every allowed speed" in r.stderr
    assert ch["check"]["lines_over_margin"] == []
    # independently: simulate the answer and read its per-line margins
    s = mtwin("simulate", out, "--twin", DEMO, "--json")
    lines = json.loads(s.stdout)["chatter"]["lines"]
    reported = [x for x in lines if x["immersion"] > 0.9 and x["ap"] > 1.9]  # the 2 and 4.5 mm slots
    saved = [x for x in lines if x not in reported]
    assert len(reported) == 2 and len(saved) == 2 and all(x["margin"] <= 0.8 for x in saved), lines
    assert mtwin("verify", SAMPLES / "chatter_demo.nc", out).returncode == 0
    assert "Chatter stability" in rep.read_text() and rep.read_text().count("<svg") >= 3
    # the report in a real browser: no console message, the lobes and the cuts drawn
    from test_optimize_report import CHROMIUM

    if CHROMIUM is None:
        pytest.skip("no headless Chromium on this machine (Debian: apt-get install chromium)")
    run = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--enable-logging=stderr", "--v=0",
                          "--dump-dom", rep.as_uri()], capture_output=True, text=True, timeout=120)
    dom = run.stdout
    assert [ln for ln in run.stderr.splitlines() if ":CONSOLE" in ln or "Uncaught" in ln] == []
    assert "Chatter stability" in dom and "Cannot be made stable" in dom
    assert dom[dom.index("Chatter stability"):].count("<path") > 20  # the lobes' curves and the cuts' markers


def test_tap_test_fit_recovers_two_modes_through_noise(tmp_path):
    """An FRF from two X modes and one Y mode with 3 % noise: fn within 2 %, ζ and k within 10 %."""
    rng = np.random.default_rng(22)
    true = (Mode("x", 650.0, 0.03, 2.0e7), Mode("x", 1450.0, 0.02, 3.0e7), Mode("y", 820.0, 0.025, 2.5e7))
    f = np.arange(200.0, 2500.0, 2.0)
    cols = {}
    for d in ("x", "y"):
        h = sum(m.compliance(f) for m in true if m.direction == d)
        h = h + 0.03 * np.abs(h) * (rng.standard_normal(len(f)) + 1j * rng.standard_normal(len(f))) / math.sqrt(2)
        cols[d] = h
    path = tmp_path / "tap.csv"
    with open(path, "w") as fh:
        fh.write("freq,re_xx,im_xx,re_yy,im_yy\n")
        for i in range(len(f)):
            fh.write(f"{f[i]},{cols['x'][i].real:.9e},{cols['x'][i].imag:.9e},{cols['y'][i].real:.9e},{cols['y'][i].imag:.9e}\n")
    r = mtwin("calibrate-frf", path, "--json")
    assert r.returncode == 0, r.stderr
    got = json.loads(r.stdout)["modes"]
    assert len(got) == 3
    for m in true:
        g = min((x for x in got if x["direction"] == m.direction), key=lambda x: abs(x["fn"] - m.fn))
        assert g["fn"] == pytest.approx(m.fn, rel=0.02)
        assert g["zeta"] == pytest.approx(m.zeta, rel=0.10)
        assert g["k"] == pytest.approx(m.k, rel=0.10)
    # the same FRF in the other sign convention (the imaginary part negated) is refused: fitted
    # as it was, it gave k = 1.7e14 N/m for a true 8e6 (issue 33)
    flipped = tmp_path / "flipped.csv"
    rows = path.read_text().splitlines()
    out = [rows[0]]
    for row in rows[1:]:
        v = row.split(",")
        out.append(",".join([v[0], v[1], repr(-float(v[2])), v[3], repr(-float(v[4]))]))
    flipped.write_text("\n".join(out) + "\n")
    r = mtwin("calibrate-frf", flipped)
    assert r.returncode == 2 and "imaginary part is positive at its resonance" in r.stderr, r.stderr
    # and so wherever it is read: a twin file's FRF for the lobes too (it gave the lowest limit at
    # 11,943 rpm instead of 7,615)
    (tmp_path / "tf.toml").write_text('[tools.3]\ntype = "flat"\ndiameter = 8.0\nfrf = "flipped.csv"\n')
    r = mtwin("lobes", "--twin", tmp_path / "tf.toml", "--tool", "3", "--immersion", "0.5")
    assert r.returncode == 2 and "imaginary part is positive at its resonance" in r.stderr, r.stderr
    # one outlier row (1e300 m/N) fitted a mode no tool tip has (k = 1e-295): the cell is refused
    # where it stands, beyond any compliance a tap test measures
    spiked = tmp_path / "spiked.csv"
    rows = path.read_text().splitlines()
    v = rows[len(rows) // 2].split(",")
    rows[len(rows) // 2] = ",".join([v[0], "1e300", *v[2:]])
    spiked.write_text("\n".join(rows) + "\n")
    r = mtwin("calibrate-frf", spiked)
    assert r.returncode == 2 and f"spiked.csv:{len(rows) // 2 + 1}:" in r.stderr \
        and "beyond what a tap test measures" in r.stderr, r.stderr
    # the printed tables read back as a twin file's modes
    toml = mtwin("calibrate-frf", path, "--tool", "3").stdout
    twin = tmp_path / "t.toml"
    twin.write_text("[tools.3]\ntype = \"flat\"\ndiameter = 8.0\n" + toml)
    j = mtwin("lobes", "--twin", twin, "--tool", "3", "--immersion", "0.5", "--method", "zoa", "--json")
    assert j.returncode == 0, j.stderr
    doc = json.loads(j.stdout)
    assert set(doc) == {"speeds", "depth_limit", "flip", "chatter_frequency", "method"}
    assert doc["method"] == "zoa" and len(doc["speeds"]) >= 500


@pytest.mark.parametrize("text,needle", [
    ("freq,re_xx,im_xx\n100,1e-7,-1e-7\n90,1e-7,-1e-7\n110,1e-7,-1e-7\n", ":3:1: frequencies must increase"),
    ("freq,re_xx,im_xx\n100,1e-7,-1e-7\n110,nan,-1e-7\n120,1e-7,-1e-7\n", ":3:5: re_xx: not a finite number"),
    ("freq,re_xx\n100,1e-7\n110,1e-7\n120,1e-7\n", "direction X needs both re_xx and im_xx"),
    ("freq,re_xx,im_xx,phase\n100,1e-7,-1e-7,1\n", ":1:18: unknown column (an FRF"),
    # the place, never the text there: a twin file may point its FRF at any file beside it
    ("freq,re_xx,im_xx\n100,1e-7,-1e-7\n110,SECRET_KEY=abc123,-1e-7\n", ":3:5: re_xx: expected a number"),
])
def test_bad_frf_files_exit_2_with_their_place(tmp_path, text, needle):
    p = tmp_path / "tap.csv"
    p.write_text(text)
    r = mtwin("calibrate-frf", p)
    assert r.returncode == 2 and needle in r.stderr, r.stderr
    assert "SECRET" not in r.stderr and "phase" not in r.stderr


def test_bad_modes_and_options_exit_2(tmp_path):
    twin = tmp_path / "t.toml"
    base = "[tools.1]\ntype = \"flat\"\ndiameter = 10.0\n[[tools.1.modes]]\n"
    cases = [
        (base + "direction = \"x\"\nfn = 900.0\nzeta = -0.01\nk = 1e7\n", (), "zeta: the damping ratio must be in (0, 1)"),
        (base + "direction = \"z\"\nfn = 900.0\nzeta = 0.01\nk = 1e7\n", (), "direction: expected \"x\" or \"y\""),
        (base + "direction = \"x\"\nfn = 900.0\nzeta = 0.01\n", (), "give one of k"),
        (base + "direction = \"x\"\nfn = 900.0\nzeta = 0.01\nk = 1e7\n", ("--immersion", "1.2"), "in (0, 1]"),
        (base + "direction = \"x\"\nfn = 900.0\nzeta = 0.01\nk = 1e7\n", ("--immersion", "0"), "in (0, 1]"),
        (base + "direction = \"x\"\nfn = 900.0\nzeta = 0.01\nk = 1e7\n", ("--ae", "12"), "wider than the tool"),
        (base + "direction = \"x\"\nfn = 900.0\nzeta = 0.01\nk = 1e7\n", ("--speed-range", "9000,5000"), "LO"),
        ("[tools.1]\ntype = \"flat\"\nfrf = \"missing.csv\"\n", (), "cannot read the FRF file"),
    ]
    for text, extra, needle in cases:
        twin.write_text(text)
        r = mtwin("lobes", "--twin", twin, "--tool", "1", *extra)
        assert r.returncode == 2 and needle in r.stderr, (text, extra, r.stderr)
    # a CutPro file whose direction cannot be told
    p = tmp_path / "tap.frf"
    p.write_text("100 1e-7 -1e-7\n110 1e-7 -1e-7\n120 1e-7 -1e-7\n")
    r = mtwin("calibrate-frf", p)
    assert r.returncode == 2 and "say which with a 'direction = x'" in r.stderr


def test_mode_parameters_are_parameters_of_the_twin(tmp_path):
    """tools.N.modes.D.J.P: read, changed and written back into the twin file's tables."""
    from mtwin.loop.journal import with_base_values
    from mtwin.twin import Twin

    tw = Twin.from_toml(str(DEMO))
    from mtwin.cutting.library import cutting_param, cutting_param_names

    names = cutting_param_names(tw.cutting)
    assert "tools.1.modes.x.0.fn" in names and "tools.1.modes.y.0.k" in names
    tw2 = tw.with_params({"tools.1.modes.y.0.k": 9.0e6, "tools.1.modes.x.0.zeta": 0.02})
    assert cutting_param(tw2.cutting, "tools.1.modes.y.0.k") == 9.0e6
    text = with_base_values(DEMO.read_text(), {"tools.1.modes.y.0.k": 9.0e6, "tools.1.modes.x.0.zeta": 0.02}, tw)
    p = tmp_path / "c.toml"
    p.write_text(text)
    modes = Twin.from_toml(str(p)).cutting.tools[1].modes
    assert modes[0].zeta == 0.02 and modes[1].k == 9.0e6 and modes[1].fn == 1010.0


def test_diagnose_tells_chatter_from_a_vibration_recording_and_a_spectrum(tmp_path):
    """A vibration recording (simulate --dynamics at a 5 kHz servo rate, its vib_x/vib_y only)
    and a spectrum file: the slots chattered near the 922 Hz mode, the wall pass did not, and
    the twin's margins agree; a twin with a stiffer tool does not agree."""
    fast = tmp_path / "fast.toml"
    fast.write_text(DEMO.read_text().replace("[spindle]", "[controller]\nservo_period = 0.0002\n\n[spindle]"))
    rec = tmp_path / "rec.csv"
    r = mtwin("simulate", SAMPLES / "chatter_demo.nc", "--twin", fast, "--dynamics", "-o", rec)
    assert r.returncode == 0, r.stderr
    rows = [ln for ln in rec.read_text().splitlines() if not ln.startswith("#")]
    head = rows[0].split(",")
    keep = [head.index(c) for c in ("t", "line", "vib_x", "vib_y")]
    vib = tmp_path / "vib.csv"
    vib.write_text("\n".join(",".join(ln.split(",")[i] for i in keep) for ln in rows) + "\n")
    d = mtwin("diagnose", SAMPLES / "chatter_demo.nc", vib, "--twin", DEMO, "--json")
    assert d.returncode == 0, d.stderr
    spectra = {v["first_line"]: v for v in json.loads(d.stdout)["chatter"]["spectra"]}
    assert [ln for ln, v in sorted(spectra.items()) if v["chatter"]] == [12, 22, 27]
    assert all(880 < spectra[ln]["chatter_frequency"] < 960 for ln in (12, 22, 27))
    assert all(v["twin_agrees"] for v in spectra.values())
    # a spectrum file; and a twin whose tool is four times stiffer says line 12 is stable
    f = np.arange(0.0, 3000.0, 2.0)
    spec = tmp_path / "spec.csv"
    with open(spec, "w") as fh:
        fh.write("first_line,last_line,freq,amplitude\n")
        for ln, chat in ((12, True), (17, False)):
            amp = 0.01 + sum(np.exp(-0.5 * ((f - k * 1e4 / 30) / 3) ** 2) / k for k in range(1, 9))
            amp = amp + (0.8 * np.exp(-0.5 * ((f - 930) / 3) ** 2) if chat else 0)
            fh.writelines(f"{ln},{ln},{x},{y:.6g}\n" for x, y in zip(f, amp))
    stiff = tmp_path / "stiff.toml"
    stiff.write_text(DEMO.read_text().replace("k = 8.0e6", "k = 3.2e7").replace("m = 0.2 ", "m = 0.8 "))
    for twin, agrees in ((DEMO, True), (stiff, False)):
        d = mtwin("diagnose", SAMPLES / "chatter_demo.nc", spec, "--twin", twin, "--json")
        v = {x["first_line"]: x for x in json.loads(d.stdout)["chatter"]["spectra"]}
        assert v[12]["chatter"] and not v[17]["chatter"] and v[12]["chatter_frequency"] == pytest.approx(930, abs=3)
        assert v[12]["twin_agrees"] is agrees


def test_an_frf_headers_units_are_honoured_and_its_bounds_held_in_m_per_n(tmp_path):
    """A tap test written in µm/N (or mm/N, kHz) reads as the same FRF in m/N and Hz; its bounds
    hold on the converted values (a soft tool's 2,000 µm/N is 2e-3 m/N, no 'beyond' value); an
    unknown unit is an error at its header cell."""
    from mtwin.chatter.modes import read_frf
    from mtwin.errors import ConfigError

    f = np.arange(200.0, 2500.0, 5.0)
    h = Mode("x", 650.0, 0.03, 5.0e3).compliance(f)  # (a soft tip: 3.3e-3 m/N at its peak)
    si, um = tmp_path / "si.csv", tmp_path / "um.csv"
    si.write_text("freq,re_xx,im_xx\n" + "".join(f"{a:.15g},{b.real:.15e},{b.imag:.15e}\n" for a, b in zip(f, h)))
    um.write_text("freq (kHz),re_xx (um/N),im_xx (µm/N)\n"
                  + "".join(f"{a / 1e3:.15g},{b.real * 1e6:.15e},{b.imag * 1e6:.15e}\n" for a, b in zip(f, h)))
    a, b = read_frf(si), read_frf(um)
    assert np.allclose(a.freq, b.freq) and np.allclose(a.xx, b.xx, rtol=1e-12)
    bad = tmp_path / "bad.csv"
    bad.write_text("freq,re_xx (in/lbf),im_xx\n100,1e-7,-1e-8\n200,1e-7,-1e-8\n300,1e-7,-1e-8\n")
    with pytest.raises(ConfigError, match=r"bad.csv:1:6: unit \(in/lbf\) not known"):
        read_frf(bad)
