"""The tool ledger (issue 21): runs recorded carry the wear from part to part, the optimiser
plans for the tool's state, concurrent writers lose nothing, a corrupt ledger is refused."""
from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from scipy.optimize import brentq

import test_wear_hidden_law as H

LAW = {"rate": 0.001, "break_in": 0.05}
SIGMA, MU = 400.0, 0.5
LIMIT = 70.0  # N


def _mtwin(*args, code=0, cwd=None):
    r = subprocess.run([sys.executable, "-m", "mtwin", *args], capture_output=True, text=True, cwd=cwd)
    assert r.returncode == code, r.stderr[-3000:]
    return r


@pytest.fixture(scope="module")
def shop(tmp_path_factory):
    d = tmp_path_factory.mktemp("shop")
    (d / "p30.nc").write_text(H.passes_program(30))
    (d / "wear.toml").write_text("[effects.flank-wear]\n" + "".join(f"{k} = {v}\n" for k, v in LAW.items()))
    return d


def closed_form_land(s: float) -> float:
    """VB after sliding s (m) from a sharp edge: r·s = VB − b·ln((b + VB)/b), solved by bisection."""
    r, b = LAW["rate"], LAW["break_in"]
    return brentq(lambda v: v - b * math.log((b + v) / b) - r * s, 0.0, 5.0, xtol=1e-12)


def test_twenty_recorded_runs_carry_the_wear(shop):
    ledger = str(shop / "runs.db")
    out = json.loads(_mtwin("simulate", "p30.nc", "--twin", "wear.toml", "--ledger", ledger, "--tool-id", "T1=EM6#1",
                            "--record", "--runs", "20", "--json", cwd=shop).stdout)
    runs = out["runs"]
    assert len(runs) == 20 and out["recorded"] == ["EM6#1"]
    tools = json.loads(_mtwin("tools", "--ledger", ledger, "--json").stdout)["tools"]
    assert tools[0]["id"] == "EM6#1" and tools[0]["runs"] == 20
    show = json.loads(_mtwin("tools", "--ledger", ledger, "--json", "show", "EM6#1").stdout)
    per = [r["sliding"] for r in show["runs"]]
    assert max(per) - min(per) < 1e-6 * max(per)  # the same program slides the same each time
    # the land at the end of run k is the law's after k runs' sliding
    for k in (1, 10, 20):
        assert runs[k - 1]["tool_wear"]["1"]["vb_end"] == pytest.approx(closed_form_land(k * per[0]), rel=2e-3)
    # and a new simulate with the ledger starts where the 20th run left the tool
    nxt = json.loads(_mtwin("simulate", "p30.nc", "--twin", "wear.toml", "--ledger", ledger, "--tool-id", "T1=EM6#1",
                            "--json", cwd=shop).stdout)
    assert nxt["tool_wear"]["1"]["sliding_before"] == pytest.approx(20 * per[0], abs=2e-6)  # (6 decimals)


def test_the_worn_tools_force_is_the_laws_amount_above_the_new_ones(shop):
    # run 20's force minus run 1's, sample by sample, is the land's contact force: sigma·ΔVB on
    # the radial edge coefficient and mu·sigma·ΔVB on the tangential one (superposed from
    # simulations with 10 N/mm of each edge coefficient on the sharp tool)
    from mtwin.effects import ToolHistory
    from mtwin.effects.wear import FlankWear
    from mtwin.twin import Twin

    sharp_twin = Twin.from_toml(None)
    prog = sharp_twin.load((shop / "p30.nc").read_bytes(), path=str(shop / "p30.nc"))
    tw = sharp_twin.with_effects(FlankWear(**LAW))
    first = tw.simulate(prog)
    twentieth = tw.with_tool_state({1: ToolHistory().__add__(first.tool_use[1].times(19))}).simulate(prog)
    sharp = sharp_twin.simulate(prog)

    def unit(c):
        tr = sharp_twin.with_params({f"cutting.al6061.{c}": 10.0}).simulate(prog)
        return {s: (tr.signal(s) - sharp.signal(s)) / 10.0 for s in ("fx", "fy")}

    te, re = unit("kte"), unit("kre")
    dvb = twentieth.signal("vb") - first.signal("vb")
    assert dvb.max() > 0.1
    for s in ("fx", "fy"):
        want = SIGMA * dvb * re[s] + MU * SIGMA * dvb * te[s]
        got = twentieth.signal(s) - first.signal(s)
        assert float(np.sqrt(np.mean((got - want) ** 2))) < 0.02 * float(np.abs(want).max())
    assert twentieth.summary.cutting.mean_load > 1.5 * first.summary.cutting.mean_load


def _feeds(path) -> list[float]:
    """The feed of each pass's cut: the F of the first move after the plunge (the optimiser
    may split the pass where it leaves the material)."""
    lines = path.read_text().splitlines()
    return [float(lines[i + 1].split("F")[1]) for i, ln in enumerate(lines) if ln.startswith("G1 Z-2.")]


def test_optimize_plans_for_the_tools_state(shop):
    ledger = str(shop / "plan.db")
    _mtwin("simulate", "p30.nc", "--twin", "wear.toml", "--ledger", ledger, "--tool-id", "T1=EM6#2", "--record",
           "--runs", "19", cwd=shop)
    fresh = str(shop / "fresh.db")
    done = {}
    for name, db in (("new", fresh), ("worn", ledger)):
        out = json.loads(_mtwin("optimize", "p30.nc", "--twin", "wear.toml", "--ledger", db, "--tool-id", "T1=EM6#2",
                                "--force-limit", str(LIMIT), "-o", f"{name}.nc", "--json", cwd=shop).stdout)
        assert out["after"]["peak_load"] <= LIMIT * 1.005  # the limit holds on the re-simulation
        _mtwin("verify", "p30.nc", f"{name}.nc", cwd=shop)  # the same path
        done[name] = out
    new, worn = _feeds(shop / "new.nc"), _feeds(shop / "worn.nc")
    assert len(new) == len(worn) == 30
    assert np.mean(worn) < 0.8 * np.mean(new)  # the worn tool (run 20) is fed slower
    w = done["worn"]["tool_wear"]["1"]
    assert w["vb_start"] > 0.2 and done["new"]["tool_wear"]["1"]["vb_start"] < 0.01
    assert w["parts_left"] < done["new"]["tool_wear"]["1"]["parts_left"]


def test_two_processes_recording_at_once_lose_nothing(tmp_path):
    ledger = str(tmp_path / "shared.db")
    code = (f"from mtwin.ledger import Ledger\nfrom mtwin.effects import ToolHistory\nimport sys\n"
            f"for i in range(40):\n"
            f"    with Ledger({ledger!r}) as lg:\n"
            f"        lg.record(sys.argv[1], program='p.nc', tool_number=1, material='al6061', "
            f"use=ToolHistory(1.0, 0.5, 0.1, 2.0))\n")
    procs = [subprocess.Popen([sys.executable, "-c", code, ident]) for ident in ("A", "B")]
    assert all(p.wait(timeout=120) == 0 for p in procs)
    from mtwin.ledger import Ledger

    with Ledger(ledger, create=False) as lg:
        assert len(lg.runs("A")) == len(lg.runs("B")) == 40
        assert lg.history("A").sliding == pytest.approx(20.0)


def test_a_corrupt_ledger_is_refused_and_left_as_it_is(tmp_path, shop):
    bad = tmp_path / "bad.db"
    junk = b"this is not a database " * 100
    bad.write_bytes(junk)
    r = _mtwin("tools", "--ledger", str(bad), code=2)
    assert "not a readable tool ledger" in r.stderr
    r = _mtwin("simulate", "p30.nc", "--twin", "wear.toml", "--ledger", str(bad), "--tool-id", "T1=X", "--record",
               code=2, cwd=shop)
    assert str(bad) in r.stderr
    assert bad.read_bytes() == junk
    other = tmp_path / "other.db"
    import sqlite3

    with sqlite3.connect(other) as db:
        db.execute("CREATE TABLE parts (id TEXT)")
    assert "not an mtwin tool ledger" in _mtwin("tools", "--ledger", str(other), code=2).stderr
    assert "--tool-id" in _mtwin("simulate", "p30.nc", "--ledger", "x.db", code=2, cwd=shop).stderr
    assert "--runs must be at least 1" in _mtwin("simulate", "p30.nc", "--runs", "0", code=2, cwd=shop).stderr
    assert "--vb-limit" in _mtwin("tools", "--ledger", str(other), "--vb-limit", "-1", code=2).stderr
    # a ledger not yet written is read as new tools, and not created unless a run is recorded
    _mtwin("simulate", "p30.nc", "--ledger", str(tmp_path / "none.db"), "--tool-id", "T1=X", cwd=shop)
    assert not (tmp_path / "none.db").exists()
    assert "T<number>=" in _mtwin("simulate", "p30.nc", "--ledger", "x.db", "--tool-id", "one", code=2, cwd=shop).stderr


def test_calibrate_keeps_the_law_in_the_ledger(shop, tmp_path):
    meas = str(tmp_path / "cut.csv")
    _mtwin("synth", "p30.nc", "-o", meas, "--summary", "line", "--effect", "flank-wear:rate=0.002",
           "--noise", "0.02", "--seed", "3", "--signals", "fx,fy", cwd=shop)
    ledger = str(tmp_path / "cal.db")
    # (30 passes are the break-in alone: rate and break-in trade off there, so the rate alone)
    _mtwin("calibrate", "p30.nc", meas, "--fit", "flank-wear:fit=rate", "--signals", "fx_rms,fy_rms", "-o",
           str(tmp_path / "t.toml"), "--ledger", ledger, "--tool-id", "T1=EM6#3", cwd=shop)
    show = json.loads(_mtwin("tools", "--ledger", ledger, "--json", "show", "EM6#3").stdout)
    assert show["law"]["rate"] == pytest.approx(0.002, rel=0.1)
    cal = show["calibrations"][0]
    assert cal["rms_after"]["fy_rms"] < 0.5 * cal["rms_before"]["fy_rms"]


def test_the_cost_objective_prices_tool_life_by_the_wear_law(shop):
    from mtwin.twin import Twin

    out = json.loads(_mtwin("optimize", "p30.nc", "--twin", "wear.toml", "--objective", "cost", "-o", "cost.nc",
                            "--json", cwd=shop).stdout)
    sim = json.loads(_mtwin("simulate", "p30.nc", "--twin", "wear.toml", "--json", cwd=shop).stdout)
    c = Twin.from_toml(None).machine.cost
    r, b = LAW["rate"], LAW["break_in"]
    life = (0.3 - b * math.log((b + 0.3) / b)) / r  # m of sliding from new to VB 0.3 mm
    lives = sim["tool_wear"]["1"]["sliding"] / life
    rate = c.machine_rate + c.labour_rate
    want = rate * sim["cycle_time"] / 3600 + lives * (c.tool_price + rate * c.tool_replace_time / 3600)
    assert out["before"]["cost"] == pytest.approx(want, rel=1e-3)


def test_rows_of_several_runs_are_predicted_run_by_run(shop, tmp_path):
    # three parts cut one after the other with one tool, rows named by their run: the twin
    # predicts run k with the tool as the k-1 runs before left it
    from mtwin.effects.wear import FlankWear
    from mtwin.loop.fit import row_statistics
    from mtwin.twin import Twin

    hidden = Twin.from_toml(None).with_effects(FlankWear(rate=0.002))
    prog = hidden.load((shop / "p30.nc").read_bytes(), path=str(shop / "p30.nc"))
    runs = hidden.simulate_batch(prog, 3)
    assert runs[2].summary.cutting.tool_wear[1]["vb_start"] > runs[0].summary.cutting.tool_wear[1]["vb_end"]
    cut_lines = sorted({int(x) for x in runs[0].line[np.hypot(runs[0].signal("fx"), runs[0].signal("fy")) > 0]})
    rng = np.random.default_rng(5)
    text = ["# format: mtwin-measurement 1", "first_line,last_line,run,fx_rms,fy_rms"]
    for k, tr in enumerate(runs, start=1):
        ln = np.array(cut_lines)
        st = row_statistics(tr, {"fx_rms": (ln, ln), "fy_rms": (ln, ln)})
        for i, line in enumerate(cut_lines):
            text.append(f"{line},{line},{k},{st['fx_rms'][i] * (1 + 0.01 * rng.normal()):.6g},"
                        f"{st['fy_rms'][i] * (1 + 0.01 * rng.normal()):.6g}")
    meas = tmp_path / "batch.csv"
    meas.write_text("\n".join(text) + "\n")
    cal = json.loads(_mtwin("calibrate", "p30.nc", str(meas), "--fit", "flank-wear:fit=rate", "--signals",
                            "fx_rms,fy_rms", "-o", str(tmp_path / "t.toml"), "--json", cwd=shop).stdout)
    assert cal["params"]["effects.flank-wear.rate"] == pytest.approx(0.002, rel=0.03)
    # compare reads the runs too: the hidden twin meets every run's rows at the noise
    (tmp_path / "h.toml").write_text("[effects.flank-wear]\nrate = 0.002\n")
    cmp = json.loads(_mtwin("compare", "p30.nc", str(meas), "--twin", str(tmp_path / "h.toml"), "--json",
                           cwd=shop).stdout)["signals"]
    assert cmp["fy_rms"]["nrmse"] < 0.02
    bad = tmp_path / "bad.csv"
    bad.write_text("first_line,last_line,run,fy_rms\n11,11,1,5.0\n15,15,0,5.0\n")
    r = _mtwin("calibrate", "p30.nc", str(bad), "--fit", "flank-wear", "-o", str(tmp_path / "u.toml"), code=2,
               cwd=shop)
    assert f"{bad}:3:3:" in r.stderr
