"""The Python API without the CLI (issue 20): ``mtwin.simulate``, ``mtwin.optimize``,
``mtwin.compare``, ``mtwin.diagnose``, ``mtwin.calibrate``, ``mtwin.grind.design`` — each
returns a result object whose ``as_dict()`` is what the command prints with ``--json`` (held
against the golden outputs the CLI is held against), and prints nothing."""
from __future__ import annotations

import json
import tomllib

import pytest
from conftest import ROOT, SAMPLES
from test_golden import GOLDEN, _same, _strip

import mtwin

# relative, from the checkout, as the golden outputs were made
POCKET = "samples/pocket.nc"
HIDDEN = "samples/measurements/pocket_hidden.csv"


@pytest.fixture(autouse=True)
def _in_the_checkout(monkeypatch):
    monkeypatch.chdir(ROOT)


def _golden(name: str):
    return json.loads((GOLDEN / name).read_text(encoding="utf-8"))


def test_simulate_is_the_command_without_the_command(capfd):
    run = mtwin.simulate(None, POCKET)
    doc = _strip({**run.as_dict(), "trace": None, "plot": None})
    assert not _same(doc, _golden("simulate_pocket.json")), _same(doc, _golden("simulate_pocket.json"))
    assert run.trace.summary.cycle_time == pytest.approx(doc["cycle_time"])
    out = capfd.readouterr()
    assert out.out == "" and out.err == ""  # library code never prints


def test_optimize_is_callable_as_mtwin_optimize():
    res = mtwin.optimize(None, POCKET)
    assert res.output == (GOLDEN / "optimize_pocket.nc").read_bytes()
    doc = _strip(res.as_dict(POCKET))
    golden = _golden("optimize_pocket.json")
    assert doc["verdict"] == golden["verdict"] and doc["changed_lines"] == golden["changed_lines"]
    assert not _same(doc["after"], golden["after"])
    # bad options are refused by the library, naming the option
    with pytest.raises(mtwin.errors.MtwinError, match="--objective"):
        mtwin.optimize.OptimizeOptions(objective="fastest")


def test_compare_returns_the_comparison_the_command_prints():
    messages = []
    c = mtwin.compare(None, POCKET, HIDDEN, on_message=lambda kind, text: messages.append((kind, text)))
    doc = _strip(c.as_dict())
    golden = _golden("compare_pocket_hidden.json")
    assert not _same(doc, golden), _same(doc, golden)
    assert c.result.signals["spindle_power"]["rms"] > 100  # the hidden effects show
    assert c.messages == messages  # what the sink heard is what the result keeps


def test_diagnose_names_the_hidden_effects_in_order():
    d = mtwin.diagnose(None, POCKET, HIDDEN, signals=["spindle_power"])
    assert d.objective == "signals" and set(d.as_dict()) == {"alignment", "signals"}
    v = d.signals["spindle_power"]
    assert v["verdict"] == "explained"
    assert [x["effect"] for x in v["selected"]] == ["spindle-no-load", "tool-wear"]
    assert v["rms_after"] <= 1.5 * v["noise"]


def test_calibrate_fits_the_hidden_laws_and_gives_the_twin_file(tmp_path):
    # the tutorial's recording: p0 = 180 W, b = 0.012 W/rpm, tool wear 0.35 /m (docs/tutorial.md)
    cal = mtwin.calibrate(None, POCKET, HIDDEN, fit=["spindle-no-load", "tool-wear"], signals=["spindle_power"])
    p = cal.result.params
    assert p["effects.spindle-no-load.p0"] == pytest.approx(180.0, rel=0.05)
    assert p["effects.spindle-no-load.b"] == pytest.approx(0.012, rel=0.1)
    assert p["effects.tool-wear.rate"] == pytest.approx(0.35, rel=0.05)
    assert cal.result.rms_after["spindle_power"] <= 1.5 * cal.result.noise["spindle_power"]
    doc = tomllib.loads(cal.twin_text)
    assert set(doc["effects"]) == {"spindle-no-load", "tool-wear"}
    out = tmp_path / "twin.toml"
    cal.write(str(out))
    tw = mtwin.Twin.from_toml(str(out))
    assert [e.name for e in tw.effects] == ["spindle-no-load", "tool-wear"]
    # the calibrated twin fits its recording: nothing more to explain on spindle power
    again = mtwin.diagnose(tw, POCKET, HIDDEN, signals=["spindle_power"], candidates=["size-effect"])
    assert again.signals["spindle_power"]["verdict"] == "fits"


def test_calibrate_refuses_nothing_to_fit():
    with pytest.raises(mtwin.errors.MtwinError, match="nothing to fit"):
        mtwin.calibrate(None, POCKET, HIDDEN)


def test_twin_setup_is_the_common_options():
    setup = mtwin.TwinSetup(twin=str(SAMPLES / "machines" / "linuxcnc-sim.toml"), effects=("gravity:mass=3",),
                            planner="grbl", stock="0,0,-10,50,50,0")
    tw = setup.build()
    assert [e.name for e in tw.effects][-1] == "gravity" and tw.machine.controller.style == "grbl"
    assert setup.stock_box() == (0.0, 0.0, -10.0, 50.0, 50.0, 0.0)
    with pytest.raises(mtwin.errors.MtwinError, match="--planner"):
        mtwin.TwinSetup(planner="haas").build()


def test_grind_design_is_the_command_without_the_command():
    d = mtwin.grind.design()
    doc = _strip(d.as_dict())
    golden = _golden("grind_design.json")
    assert not _same(doc, golden), _same(doc, golden)
    assert d.gcode().startswith(b"%") or b"G" in d.gcode()


def test_the_readme_names_the_api(tmp_path):
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    for name in ("mtwin.simulate", "mtwin.optimize", "mtwin.compare", "mtwin.diagnose", "mtwin.calibrate"):
        assert name in text, name


def test_a_parameter_the_signals_cannot_see_is_not_identifiable():
    # the X torque cannot see the Y and Z axes' friction: before the identifiability check the
    # fit moved coulomb-friction.fy to hundreds of N on what the model got wrong elsewhere
    cal = mtwin.calibrate(None, POCKET, HIDDEN, fit=["coulomb-friction"], signals=["x_torque"])
    r = cal.result
    assert r.not_identifiable == ["effects.coulomb-friction.fy", "effects.coulomb-friction.fz"]
    assert r.params["effects.coulomb-friction.fy"] == 0.0 and r.uncertainty["effects.coulomb-friction.fy"] is None
    assert "effects.coulomb-friction.fx" not in r.not_identifiable and r.uncertainty["effects.coulomb-friction.fx"]
    assert cal.as_dict()["not_identifiable"] == r.not_identifiable
    assert tomllib.loads(cal.twin_text)["journal"][-1]["not_identifiable"] == r.not_identifiable


def test_the_fitting_core_on_a_closed_form():
    # y = a·x + b with noise 1, and c that the residuals do not see: a and b recovered with
    # their textbook standard errors, c left at its start and reported blind
    import numpy as np

    from mtwin.fitting import delta_bic, solve, verdict

    rng = np.random.default_rng(0)
    x = np.linspace(0.0, 10.0, 200)
    y = 2.0 * x + 1.0 + rng.normal(0.0, 1.0, x.size)
    sol = solve(lambda p: (y - (p[0] * x + p[1] + 1e-12 * p[2])), [0.0, 0.0, 5.0], [-10, -10, -10], [10, 10, 10])
    A = np.stack([x, np.ones_like(x)], axis=1)
    exact, *_ = np.linalg.lstsq(A, y, rcond=None)
    assert sol.x[:2] == pytest.approx(exact, abs=1e-5)
    s2 = float(np.sum((y - A @ exact) ** 2)) / (x.size - 3)
    se = np.sqrt(np.diag(np.linalg.inv(A.T @ A)) * s2)
    assert sol.uncertainty[0] == pytest.approx(se[0], rel=0.02) and sol.uncertainty[1] == pytest.approx(se[1], rel=0.02)
    assert list(sol.blind) == [False, False, True] and sol.x[2] == 5.0 and sol.uncertainty[2] is None
    assert delta_bic(100, 50.0, 100.0, 1) == pytest.approx(100 * np.log(0.5) + np.log(100))
    assert verdict(1.0, 1.0, None) == "fits" and verdict(3.0, 1.0, -11.0, 0.6) == "explained"
    assert verdict(3.0, 1.0, -9.0, 0.9) == "unexplained"


def test_a_program_read_by_the_caller_without_motion_is_refused_like_a_file():
    # an API optimize of a Program that only defines a subroutine (LinuxCNC's factorial.ngc)
    # failed inside the optimiser (AttributeError); the command said "no motion" (exit 2)
    from mtwin.errors import GCodeError
    from mtwin.optimize.run import optimize

    tw = mtwin.Twin()
    prog = tw.load(b"o<f> sub\no<f> endsub\nm2\n", path="f.ngc")
    for run in (lambda: optimize(tw, prog), lambda: mtwin.simulate(tw, prog)):
        with pytest.raises(GCodeError, match="f.ngc:1:1: the program has no motion"):
            run()


def test_parse_verify_import_journal_and_tools_are_use_cases_too(tmp_path, capfd):
    """What `parse`, `verify`, `import mtconnect`, `journal` and `tools` print with --json, from
    the library alone (issue 36: the API as the only door)."""
    import subprocess
    import sys

    def command(*args):
        r = subprocess.run([sys.executable, "-m", "mtwin", *args], capture_output=True, text=True, cwd=ROOT)
        assert r.returncode == 0, r.stderr
        return json.loads(r.stdout)

    parsed = mtwin.parse(None, POCKET)
    assert parsed.as_dict() == command("parse", POCKET, "--json")
    assert parsed.moves_csv().splitlines()[0].startswith("line,kind,x,y,z")
    same = mtwin.prove_path(None, POCKET, POCKET)
    assert same.same and same.as_dict() == command("verify", POCKET, POCKET, "--json")
    moved = tmp_path / "moved.nc"
    moved.write_text((ROOT / POCKET).read_text().replace("X24.500 Y25.000", "X24.600 Y25.000"))
    assert not mtwin.prove_path(None, POCKET, str(moved)).same
    assert mtwin.journal(str(ROOT / "samples/machines/hurco-vmx24.toml"))  # (the profile's calibrations)
    log = tmp_path / "log.txt"
    log.write_text("2024-01-01T00:00:00.000Z|execution|ACTIVE\n2024-01-01T00:00:00.000Z|Block_Number|1\n"
                   "2024-01-01T00:00:01.000Z|Block_Number|5\n2024-01-01T00:00:02.000Z|execution|STOPPED\n")
    m = mtwin.import_log(str(log))
    assert list(m.line) and int(m.line.max()) == 5
    with pytest.raises(mtwin.errors.MtwinError):  # (no ledger there: none is created by reading)
        mtwin.tools(str(tmp_path / "none.db"))
    with pytest.raises(mtwin.errors.MtwinError, match="vb-limit"):
        mtwin.tools(str(tmp_path / "none.db"), vb_limit=1e99)
    assert capfd.readouterr().out == ""  # (the library prints nothing)


def test_the_housekeeping_commands_are_use_cases_too(capfd):
    """`materials`, `effects`, `config` and `cache` as data from the library (issue 36): what
    the commands print with --json, or their text, comes from these."""
    import subprocess
    import sys

    from mtwin.api import admin
    from mtwin import warmup

    def command(*args):
        r = subprocess.run([sys.executable, "-m", "mtwin", *args], capture_output=True, text=True, cwd=ROOT)
        assert r.returncode == 0, r.stderr
        return r.stdout

    assert admin.materials() == json.loads(command("materials", "--json"))
    assert admin.materials("304")[0]["name"] == json.loads(command("materials", "304", "--json"))["name"]
    # (less the effects other tests registered in this process, which a new process has not)
    from mtwin.effects import _extra as registered_here

    listed = [e.as_dict() for e in admin.effects() if e.name not in registered_here]
    assert listed == json.loads(command("effects", "--json"))
    assert [p.name for p in admin.effect("backlash").params] and admin.effect("backlash").stage == "observation"
    assert admin.twin_toml(None) == command("config", "show")
    hurco = str(ROOT / "samples/machines/hurco-vmx24.toml")
    assert admin.check_twin(hurco).startswith("hurco")
    info = warmup.cache_info()
    assert command("cache", "info").splitlines()[0] == info.path
    with pytest.raises(mtwin.errors.MtwinError):
        admin.materials("unobtainium")
    assert capfd.readouterr().out == ""
