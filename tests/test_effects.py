"""Physical effects (issue 10, first part): the contract every registered effect keeps, each
built-in effect against a closed form, user effects from a file and from an installed
package's entry point, effects in the twin file, and synthetic measurements."""
from __future__ import annotations

import json
import math
import textwrap

import numpy as np
import pytest

import mtwin
from conftest import SAMPLES
from mtwin import effects as FX
from mtwin.errors import ConfigError
from mtwin.motion.trace import SIGNALS
from test_cli import mtwin as run_cli

# a slot along X in one line, then a return: constant conditions for the closed forms
SLOT = ("G21 G90 G94\nT1 M6\nS8000 M3\nG0 X-5 Y10 Z2\nG1 Z-1 F300\nG1 X150 F900\nG0 Z5\nG0 X0 Y0\nM30\n"
        "(MTWIN STOCK 0,0,-10,160,20,0)\n")
# motion only: a long constant-velocity move along +X, then back
MOVE = "G21 G90 G94\nG0 X0 Y0 Z0\nG1 X200 F3000\nG1 X0\nM30\n"


@pytest.fixture(scope="module")
def twin():
    return mtwin.Twin()


@pytest.fixture(scope="module")
def slot(twin):
    return twin.load(SLOT.encode(), path="slot.nc")


@pytest.fixture(scope="module")
def move(twin):
    return twin.load(MOVE.encode(), path="move.nc")


@pytest.fixture(scope="module")
def pocket(twin):
    return twin.load(str(SAMPLES / "pocket.nc"))


@pytest.fixture(scope="module")
def base_pocket(twin, pocket):
    return twin.simulate(pocket)


def _typical(p):
    """A value inside the bounds that is not the default (for the conformance checks)."""
    span = p.upper - p.lower
    v = p.default + 0.25 * span if p.default + 0.25 * span <= p.upper else p.default - 0.25 * span
    return v


# ---------------------------------------------------------------- the contract, for every effect

@pytest.mark.parametrize("name", sorted(FX.available()))
def test_every_effect_keeps_the_contract(name, twin, pocket, base_pocket):
    cls = FX.get(name)
    assert cls.name == name and cls.description and cls.stage in ("loop", "observation", "plan")
    assert cls.signals and set(cls.signals) <= set(SIGNALS)
    for p in cls.params:
        assert p.lower <= p.default <= p.upper and p.doc and isinstance(p.unit, str)
    # __init__ stores, resolved() checks
    with pytest.raises(ConfigError, match="unknown parameter"):
        cls(no_such_parameter=1.0).resolved()
    if cls.params:
        p = cls.params[0]
        with pytest.raises(ConfigError, match="must be within"):
            cls(**{p.name: p.upper + abs(p.upper) + 1.0}).resolved()
    # at its defaults an effect leaves the twin as it is
    same = twin.with_effects(cls()).simulate(pocket)
    assert same.summary.cycle_time == base_pocket.summary.cycle_time
    for s in cls.signals:
        if s == "vb":  # (the land: a signal only a wear effect's trace has; a new tool's is vb0)
            assert np.all(same.signal(s) == cls().resolved().get("vb0", 0.0))
            continue
        np.testing.assert_allclose(same.signal(s), base_pocket.signal(s), rtol=1e-6, atol=1e-9, err_msg=s)
    # away from its defaults it changes what it says it changes ...
    values = {p.name: _typical(p) for p in cls.params}
    tr = twin.with_effects(cls(**values)).simulate(pocket)
    # (a timing effect acts on features the pocket may not have: its closed forms are below)
    if len(tr.t) == len(base_pocket.t) and cls.stage != "plan":
        changed = [s for s in SIGNALS if s not in ("vb", "vib_x", "vib_y")  # (only --dynamics traces have vib)
                   and not np.allclose(tr.signal(s), base_pocket.signal(s), rtol=1e-9, atol=1e-12)]
        assert set(changed) & set(cls.signals), name
        # ... and on observation nothing else
        if cls.stage == "observation":
            assert set(changed) <= set(cls.signals) | {f"{a}_err" for a in "xyz"}, (name, changed)


# ---------------------------------------------------------------- closed forms

def test_spindle_no_load_adds_its_polynomial_where_the_spindle_turns(twin, pocket, base_pocket):
    tr = twin.with_effects("spindle-no-load:p0=120,b=0.02,c=2e-6").simulate(pocket)
    n = np.abs(base_pocket.signal("spindle_speed"))
    want = np.where(n >= 1.0, 120 + 0.02 * n + 2e-6 * n * n, 0.0)
    np.testing.assert_allclose(tr.signal("spindle_power") - base_pocket.signal("spindle_power"), want, atol=1e-3)
    # the summary is taken again from the trace: the peak moves with the effect
    assert tr.summary.cutting.peak_power == pytest.approx(float(tr.signal("spindle_power").max()), rel=1e-6)
    assert tr.summary.cutting.peak_power > base_pocket.summary.cutting.peak_power + 120


def test_thermal_drift_is_an_exponential_approach(twin, move):
    base = twin.simulate(move, cutting=False)
    tr = twin.with_effects("thermal-drift:dx=0.05,dz=-0.02,tau=10").simulate(move, cutting=False)
    t = base.t - base.t[0]
    # positions are stored as float32: 8 µm steps at 100 mm
    np.testing.assert_allclose(tr.signal("x") - base.signal("x"), 0.05 * (1 - np.exp(-t / 10)), atol=2e-5)
    np.testing.assert_allclose(tr.signal("z") - base.signal("z"), -0.02 * (1 - np.exp(-t / 10)), atol=2e-5)
    np.testing.assert_allclose(tr.signal("y"), base.signal("y"))
    # the measured following error follows the measured position
    np.testing.assert_allclose(tr.signal("x_err"), base.signal("x_cmd") - tr.signal("x"), atol=2e-5)


def test_servo_delay_shifts_the_positions_by_whole_samples(twin, move):
    base = twin.simulate(move, cutting=False)
    tr = twin.with_effects("servo-delay:delay=0.012").simulate(move, cutting=False)
    k = 12  # 12 ms at the 1 ms servo period
    np.testing.assert_allclose(tr.signal("x")[k:], base.signal("x")[:-k], atol=1e-6)


def test_backlash_trails_the_motion_by_half_of_it(twin, move):
    base = twin.simulate(move, cutting=False)
    tr = twin.with_effects("backlash:bx=0.04").simulate(move, cutting=False)
    d = tr.signal("x") - base.signal("x")
    assert set(np.round(np.unique(d), 4)) <= {-0.02, 0.0, 0.02}  # float32 positions
    going = np.argmax(base.signal("x") > 100)  # on the way out (+X): the load trails by -b/2
    coming = len(d) - 1 - np.argmax(base.signal("x")[::-1] > 100)  # on the way back: +b/2
    assert d[going] == pytest.approx(-0.02, abs=2e-5) and d[coming] == pytest.approx(0.02, abs=2e-5)


def test_runout_modulates_the_force_once_per_revolution(twin, slot):
    base = twin.simulate(slot)
    tr = twin.with_effects("runout:e=0.2,phase=0.5").simulate(slot)
    t = base.t
    n = base.signal("spindle_speed")
    theta = 2 * np.pi * np.cumsum(n / 60.0 * np.diff(t, prepend=t[0]))
    np.testing.assert_allclose(tr.signal("fy"), base.signal("fy") * (1 + 0.2 * np.cos(theta + 0.5)), rtol=1e-5,
                               atol=1e-4)
    # over whole revolutions the average force is the same
    cut = base.signal("mrr") > 0
    assert tr.signal("fy")[cut].mean() == pytest.approx(base.signal("fy")[cut].mean(), rel=0.01)


def test_tool_wear_grows_the_cutting_power_with_the_length_cut(twin, slot):
    base = twin.simulate(slot)
    tr = twin.with_effects("tool-wear:rate=0.5").simulate(slot)
    assert len(tr.t) == len(base.t)
    x = base.signal("x")
    steady = (base.signal("mrr") > 0) & (x > 20) & (x < 140)  # full slot, away from entry and exit
    ratio = tr.signal("spindle_power")[steady] / base.signal("spindle_power")[steady]
    # the tool enters the stock at X = -3 (X0 minus its radius): cut length ≈ x + 3 mm
    want = 1 + 0.5 * (x[steady] + 3.0) / 1000.0
    np.testing.assert_allclose(ratio, want, rtol=0.01)


def test_gravity_loads_the_z_drive_by_m_g(twin, move):
    base = twin.simulate(move, cutting=False)
    tr = twin.with_effects("gravity:mass=80").simulate(move, cutting=False)
    fpt = twin.machine.z.force_per_torque
    # at rest at the end every force is static: the drive holds the weight
    assert tr.signal("z_torque")[-1] - base.signal("z_torque")[-1] == pytest.approx(80 * 9.80665 / fpt, rel=1e-3)


def test_coulomb_and_viscous_friction_at_constant_velocity(twin, move):
    base = twin.simulate(move, cutting=False)
    fpt = twin.machine.x.force_per_torque
    def cruise_torque(tr):
        cruise = np.abs(tr.signal("x_vel") - 50.0) < 0.01  # 3000 mm/min = 50 mm/s out along +X
        assert cruise.sum() > 1000
        return float(np.median(tr.signal("x_torque")[cruise]))

    c = twin.with_effects("coulomb-friction:fx=120").simulate(move, cutting=False)
    assert cruise_torque(c) - cruise_torque(base) == pytest.approx(120 / fpt, rel=0.01)
    vb = twin.with_effects("viscous-friction:bx=4000").simulate(move, cutting=False)
    want = 4000 * 0.050 / fpt  # N·s/m × m/s
    assert cruise_torque(vb) - cruise_torque(base) == pytest.approx(want, rel=0.01)


# ---------------------------------------------------------------- user effects, twin file, CLI

USER_EFFECT = '''
import numpy as np
from mtwin.effects import Effect
from mtwin.params import Param


class CoolantPump(Effect):
    name = "coolant-pump"
    description = "a coolant pump on the spindle drive's supply: a constant power while M8 runs"
    params = (Param("power", "W", 0.0, 0.0, 3000.0, "pump power"),)
    signals = ("spindle_power",)

    def observe(self, trace, p):
        trace.set_signal("spindle_power", trace.signal("spindle_power") + p["power"])
'''


def test_a_user_effect_from_a_file_is_listed_and_used_like_a_built_in(tmp_path, twin, pocket, base_pocket):
    f = tmp_path / "pump.py"
    f.write_text(USER_EFFECT)
    r = run_cli("effects", "--effect-file", str(f), "--json")
    assert r.returncode == 0, r.stderr.decode()
    rows = {x["name"]: x for x in json.loads(r.stdout)}
    assert rows["coolant-pump"]["origin"] == "user" and "spindle-no-load" in rows
    r = run_cli("simulate", str(SAMPLES / "pocket.nc"), "--effect-file", str(f), "--effect", "coolant-pump:power=500",
                "--json")
    assert r.returncode == 0, r.stderr.decode()
    assert json.loads(r.stdout)["peak_power"] == pytest.approx(base_pocket.summary.cutting.peak_power + 500, rel=1e-4)
    bad = tmp_path / "bad.py"
    bad.write_text("x = 1\n")
    r = run_cli("effects", "--effect-file", str(bad))
    assert r.returncode == 2 and "defines no subclass" in r.stderr.decode()
    r = run_cli("effects", "--effect-file", str(tmp_path))  # (a folder: said so, not "no such file")
    assert r.returncode == 2 and "a directory" in r.stderr.decode() and "no such file" not in r.stderr.decode()


def test_an_installed_package_s_entry_point_registers_its_effect(effect_package):
    # a package as pip would install it: its module and a dist-info with the entry point
    effect_package("pump_fx", USER_EFFECT, {"coolant-pump": "CoolantPump"})
    assert "coolant-pump" in FX.available()
    assert FX.get("coolant-pump")(power=10.0).resolved() == {"power": 10.0}


def test_effects_in_the_twin_file_and_by_dotted_name(tmp_path, pocket, base_pocket):
    f = tmp_path / "m.toml"
    f.write_text(textwrap.dedent("""
        [effects.spindle-no-load]
        p0 = 100.0
        [effects.tool-wear]
        rate = 0.2
    """))
    tw = mtwin.Twin.from_toml(str(f))
    assert [e.name for e in tw.effects] == ["spindle-no-load", "tool-wear"]
    tw2 = tw.with_params({"effects.spindle-no-load.p0": 300.0})
    assert tw2.effects[0].resolved()["p0"] == 300.0 and tw.effects[0].resolved()["p0"] == 100.0
    with pytest.raises(ConfigError, match="no effect 'gravity'"):
        tw.with_params({"effects.gravity.mass": 1.0})
    f.write_text("[effects.spindle-no-load]\np0 = -5.0\n")
    with pytest.raises(ConfigError, match=r"\[effects.spindle-no-load\].*must be within"):
        mtwin.Twin.from_toml(str(f))
    f.write_text("[effects.warp-drive]\n")
    with pytest.raises(ConfigError, match="unknown effect 'warp-drive'"):
        mtwin.Twin.from_toml(str(f))


def test_effects_cli_lists_and_explains(tmp_path):
    r = run_cli("effects", "--json")
    names = [x["name"] for x in json.loads(r.stdout)]
    for want in ("spindle-no-load", "tool-wear", "runout", "coulomb-friction", "viscous-friction",
                 "stribeck-friction", "gravity", "backlash", "servo-delay", "thermal-drift"):
        assert want in names
    r = run_cli("effects", "show", "tool-wear")
    assert r.returncode == 0 and "rate" in r.stdout.decode() and "1/m" in r.stdout.decode()
    r = run_cli("effects", "show", "flux-capacitor")
    assert r.returncode == 2 and "unknown effect" in r.stderr.decode()
    r = run_cli("simulate", str(SAMPLES / "pocket.nc"), "--effect", "tool-wear:rate=99")
    assert r.returncode == 2 and "must be within [0, 5]" in r.stderr.decode()


def _read(path):
    lines = path.read_text().splitlines()
    k = next(i for i, x in enumerate(lines) if not x.startswith("#"))
    return np.genfromtxt(lines[k:], delimiter=",", names=True)


def test_synth_writes_a_noisy_measurement_of_the_hidden_effect(tmp_path):
    out = tmp_path / "meas.csv"
    args = ("synth", str(SAMPLES / "pocket.nc"), "--effect", "spindle-no-load:p0=200", "--noise", "0.02",
            "--rate", "100", "--signals", "spindle_power,x,fy", "--seed", "3", "-o", str(out))
    r = run_cli(*args)
    assert r.returncode == 0, r.stderr.decode()
    text = out.read_text()
    assert "# effects: spindle-no-load:p0=200,b=0,c=0" in text and "# noise: 0.02" in text
    data = _read(out)
    assert data.dtype.names == ("t", "line", "spindle_power", "x", "fy")
    assert np.allclose(np.diff(data["t"]), 0.01, atol=1e-9)  # 100 Hz
    # the noise: 2 % of the RMS, reproducible with the seed, different with another
    clean = tmp_path / "clean.csv"
    assert run_cli(*args[:4], "--rate", "100", "--signals", "spindle_power,x,fy", "-o", str(clean)).returncode == 0
    c = _read(clean)
    res = data["spindle_power"] - c["spindle_power"]
    rms = math.sqrt(float(np.mean(c["spindle_power"] ** 2)))
    assert res.std() == pytest.approx(0.02 * rms, rel=0.1)
    again = tmp_path / "again.csv"
    run_cli(*args[:-1], str(again))
    assert again.read_text() == text
    r = run_cli("synth", str(SAMPLES / "pocket.nc"), "--rate", "-1", "-o", str(tmp_path / "x.csv"))
    assert r.returncode == 2 and not (tmp_path / "x.csv").exists()


def test_size_effect_follows_kienzle_at_the_programmed_chip_thickness(twin, slot):
    base = twin.simulate(slot)
    tr = twin.with_effects("size-effect:x=0.25,h_ref=0.05").simulate(slot)
    x = base.signal("x")
    steady = (base.signal("mrr") > 0) & (x > 20) & (x < 140)
    # a full-width slot: the maximum chip is the feed per tooth, 900 / (2 · 8000) mm
    fz = 900.0 / (2 * 8000.0)
    ratio = tr.signal("spindle_power")[steady] / base.signal("spindle_power")[steady]
    np.testing.assert_allclose(ratio, (fz / 0.05) ** -0.25, rtol=0.01)
    # against the same law applied at the actual chip thickness of every sample (the direct
    # computation): equal where the feed is the programmed one
    h = base.signal("h_max")[steady]
    direct = base.signal("spindle_power")[steady] * (h / 0.05) ** -0.25
    assert np.median(np.abs(tr.signal("spindle_power")[steady] / direct - 1)) < 0.002


def test_inertia_moves_more_mass_with_the_same_gains(twin, move):
    base = twin.simulate(move, cutting=False)
    tr = twin.with_effects("inertia:mx=600").simulate(move, cutting=False)
    # accelerating 600 kg more takes m·a more force while the axis speeds up (3000 mm/s² max)
    n = 1000  # the first second: the move out along +X speeds up, no wait has shifted the clocks yet
    acc = np.abs(np.gradient(base.signal("x_vel")[:n], base.t[:n])) > 1000
    fpt = twin.machine.x.force_per_torque
    extra = np.median(np.abs(tr.signal("x_torque")[:n][acc] - base.signal("x_torque")[:n][acc]))
    assert extra > 0.3 * 600 * 1.0 / fpt  # at least 600 kg x 1 m/s² worth of torque


# ---------------------------------------------------------------- timing effects (before planning)

def test_arc_acceleration_limits_arcs_to_the_root_of_a_r():
    import math

    from mtwin.motion.path import ARC

    tw = mtwin.Twin()
    prog = tw.load(b"G21 G90 G94 S1000 M3\nG0 X0 Y0 Z0\nG1 X1 F3000\nG2 X1 Y0 I-1 J0\nG0 Z5\nM30\n", path="a.nc")
    base, slow = tw.plan(prog), tw.with_effects("arc-acceleration:acceleration=300").plan(prog)
    i = int(np.flatnonzero(slow.seg["kind"] == ARC)[0])
    assert slow.seg["vmax"][i] == pytest.approx(math.sqrt(300 * 1.0))
    assert base.seg["vmax"][i] == pytest.approx(50.0)  # F3000: the feed, not the arc, limits it
    assert slow.dur[i] >= 2 * math.pi / math.sqrt(300) and slow.total_time > base.total_time


def test_arc_acceleration_is_the_arcs_own_limit_set_apart_from_the_axes():
    # a control's own arc limit replaces the axes' split (√0.75·a) on feed arcs, below the axes'
    # acceleration or above it (Fanuc sets it apart, parameter 1735): small circles run at √(a·r)
    import math

    from mtwin.motion.path import ARC

    tw = mtwin.Twin().with_params({"axes.x.max_acceleration": 400.0, "axes.y.max_acceleration": 400.0})
    prog = tw.load(b"G21 G90 G94 S1000 M3\nG0 X0 Y0 Z0\nG1 X1 F3000\nG2 X1 Y0 I-1 J0\nG0 Z5\nM30\n", path="a.nc")
    i = int(np.flatnonzero(tw.plan(prog).seg["kind"] == ARC)[0])
    vmax = lambda spec: float(tw.with_effects(spec).plan(prog).seg["vmax"][i])
    assert float(tw.plan(prog).seg["vmax"][i]) == pytest.approx(math.sqrt(math.sqrt(0.75) * 400.0))
    assert vmax("arc-acceleration:acceleration=300") == pytest.approx(math.sqrt(300.0))
    assert vmax("arc-acceleration:acceleration=900") == pytest.approx(math.sqrt(900.0))


def test_arc_jerk_holds_small_circles_to_the_cube_root_of_j_r2():
    # a jerk limit on arcs: each axis runs a sinusoid on a circle, whose jerk is v³/r², so the
    # speed is held at ∛(J·r²) where that is below √(a·r): on small radii first.  At a = 500 mm/s²
    # and J = 12 m/s³ the two cross at r = a³/J² = 0.87 mm: the NIST plates' 0.35-mm helices
    # are held by the jerk (11.4 mm/s, not 13.2), their 6.5-mm corners by the acceleration.
    import math

    from mtwin.motion.path import ARC

    tw = mtwin.Twin().with_effects("arc-acceleration:acceleration=500,jerk=12000")
    for r, v in ((0.35, (12000 * 0.35 ** 2) ** (1 / 3)), (0.8, (12000 * 0.64) ** (1 / 3)),
                 (1.5, math.sqrt(500 * 1.5)), (6.5, math.sqrt(500 * 6.5))):
        prog = tw.load(f"G21 G90 G94 S1000 M3\nG0 X0 Y0 Z0\nG2 X{2 * r} Y0 I{r} J0 F6000\nG0 Z5\nM30\n".encode(),
                       path="j.nc")
        seg = tw.plan(prog).seg
        assert float(seg["vmax"][seg["kind"] == ARC][0]) == pytest.approx(v, rel=1e-9), r
    # the twin file's controller.arc_jerk is the same limit; 0 is none
    prog = tw.load(b"G21 G90 G94 S1000 M3\nG0 X0 Y0 Z0\nG2 X0.7 Y0 I0.35 J0 F6000\nG0 Z5\nM30\n", path="j.nc")
    plain = mtwin.Twin().with_effects("arc-acceleration:acceleration=500")
    seg = plain.with_params({"controller.arc_jerk": 12000.0}).plan(prog).seg
    assert float(seg["vmax"][seg["kind"] == ARC][0]) == pytest.approx((12000 * 0.35 ** 2) ** (1 / 3), rel=1e-9)
    seg = plain.plan(prog).seg
    assert float(seg["vmax"][seg["kind"] == ARC][0]) == pytest.approx(math.sqrt(500 * 0.35), rel=1e-9)


def test_arc_jerk_bounds_the_axes_jerk_on_a_circle_in_the_trace():
    # independent of the plan: three full circles of 0.5 mm at F6000, J = 8 m/s³; the commanded
    # X of the middle circle, differentiated three times, peaks at v³/r² = J (a sinusoid's
    # amplitude r·ω³), and the path runs at ∛(J·r²) = 12.6 mm/s, not √(a·r) = 15.8
    tw = mtwin.Twin().with_effects("arc-acceleration:acceleration=500,jerk=8000")
    r = 0.5
    text = (f"G21 G90 G94 S1000 M3\nG0 X0 Y0 Z0\nG1 X{r} F6000\n"
            + f"G2 X{r} Y0 I{-r} J0\n" * 3 + "G1 X0\nG0 Z5\nM30\n")
    tr = tw.simulate(tw.load(text.encode(), path="c.nc"), cutting=False)
    dt = float(np.median(np.diff(tr.t)))
    mid = np.flatnonzero(np.asarray(tr.line) == 5)[10:-10]  # the second circle, off its ends
    jerk = np.diff(tr.cmd[:, 0], n=3) / dt ** 3
    assert np.abs(jerk[mid - 1]).max() == pytest.approx(8000.0, rel=0.03)
    speed = np.linalg.norm(np.diff(tr.cmd[:, :2], axis=0), axis=1) / dt
    assert np.median(speed[mid]) == pytest.approx((8000.0 * r * r) ** (1 / 3), rel=0.01)


def test_a_spiral_is_an_arc_off_its_circle_by_more_than_2_3_micrometres():
    # one 0.0001-in increment (2.54 µm) off the circle is a spiral; 2 µm (what rounding both
    # the end point and the centre leaves on the plates' large arcs) runs as a circle
    import math

    from mtwin.motion.path import ARC

    tw = mtwin.Twin().with_effects("arc-acceleration:acceleration=400", "spiral-acceleration:acceleration=250")
    for end, a in (("2.002", 400.0), ("2.0022", 400.0), ("2.00254", 250.0), ("2.0", 400.0)):
        prog = tw.load(f"G21 G90 G94 S1000 M3\nG0 X0 Y0 Z0\nG2 X{end} Y0 I1 J0 F6000\nG0 Z5\nM30\n".encode(), path="s.nc")
        seg = tw.plan(prog).seg
        assert float(seg["vmax"][seg["kind"] == ARC][0]) == pytest.approx(math.sqrt(a * 1.0), rel=1e-9), end
    # the threshold is the twin file's (controller.spiral_min): at 1 µm the 2-µm arc is a spiral
    prog = tw.load(b"G21 G90 G94 S1000 M3\nG0 X0 Y0 Z0\nG2 X2.002 Y0 I1 J0 F6000\nG0 Z5\nM30\n", path="s.nc")
    seg = tw.with_params({"controller.spiral_min": 0.001}).plan(prog).seg
    assert float(seg["vmax"][seg["kind"] == ARC][0]) == pytest.approx(math.sqrt(250.0), rel=1e-9)


# a helix of half circles, r = 0.35 mm, as CAM writes it rounded to 0.0001 in: the centre
# halfway (true circles) or, as the NIST plates have it, 2.5 µm off the middle (a spiral)
_HELIX = "G20 G90 G94 S9000 M3\nG0 X0.6034 Y0 Z0.1\nG1 Z0 F36\n{}G0 Z0.1\nM30\n"


def _helix(i_down: str, i_up: str) -> bytes:
    rows = []
    for k in range(40):
        z = -0.005 * (k + 1)
        rows.append(f"G3 X0.6309 Z{z:.4f} I{i_up} J0\n" if k % 2 == 0 else f"G3 X0.6034 Z{z:.4f} I{i_down} J0\n")
    return _HELIX.format("".join(rows)).encode()


def test_spiral_acceleration_slows_spirals_to_the_root_of_a_r_and_leaves_circles():
    import math

    from mtwin.motion.path import ARC

    tw = mtwin.Twin().with_effects("arc-acceleration:acceleration=370")
    slow = tw.with_effects("spiral-acceleration:acceleration=290")
    spiral = tw.load(_helix("-.0138", ".0137"), path="s.nc")  # the plates' own words
    circle = tw.load(_helix("-.01375", ".01375"), path="c.nc")
    for prog, a in ((spiral, 290.0), (circle, 370.0)):
        seg = slow.plan(prog).seg
        arcs = seg[seg["kind"] == ARC]
        r = np.minimum(arcs["r0"], arcs["r1"])
        assert arcs["vmax"] == pytest.approx(np.sqrt(a * r), rel=1e-9)  # F36 (15.2 mm/s) is above both
    # the same spiral without the effect runs as a circle would
    arcs = tw.plan(spiral).seg
    arcs = arcs[arcs["kind"] == ARC]
    assert arcs["vmax"] == pytest.approx(np.sqrt(370.0 * np.minimum(arcs["r0"], arcs["r1"])), rel=1e-9)
    # the whole helix: time along the path at that speed (40 half turns at a constant speed)
    plan = slow.plan(spiral)
    on = plan.seg["kind"] == ARC
    length = float(plan.seg["length"][on].sum())
    assert float(plan.dur[on].sum()) == pytest.approx(length / math.sqrt(290.0 * 0.35), rel=0.03)


def test_spiral_block_time_adds_its_time_to_every_spiral_block_and_none_to_circles():
    # below the spiral limit (F20 in/min, 8.5 mm/s) each spiral half circle takes L/F + t: the
    # helix of 40 takes 40·t longer; the same helix drawn true is untouched
    tw = mtwin.Twin()
    slow = tw.with_effects("spiral-acceleration:block_time=0.006")  # the time alone, no limit
    from mtwin.motion.path import ARC

    for words, extra in ((("-.0138", ".0137"), 0.006), (("-.01375", ".01375"), 0.0)):
        prog = tw.load(_helix(*words).replace(b"F36", b"F20"), path="h.nc")
        base, plan = tw.plan(prog), slow.plan(prog)
        on = plan.seg["kind"] == ARC
        length = plan.seg["length"][on]
        v = plan.seg["vmax"][on]
        np.testing.assert_allclose(length / v, length / (20 * 25.4 / 60.0) + extra, rtol=1e-9)
        assert float(plan.dur[on].sum() - base.dur[on].sum()) == pytest.approx(40 * extra, abs=2e-3)


def test_spiral_normal_time_adds_v2_over_r_over_the_jerk_to_every_spiral_block():
    # below the spiral limit each spiral half circle takes L/v + (v²/r)/J: at F20 in/min (8.5 mm/s)
    # on r 0.35 mm, v²/r = 206 mm/s² and J = 40 m/s³ give 5.2 ms; at F27 (11.4 mm/s) 9.3 ms — the
    # time grows with v²/r (normal_time 0.025 s³/m: 25 ms per m/s², the inverse of 40 m/s³); with
    # block_time both add; the same helix drawn true is untouched
    tw = mtwin.Twin()
    from mtwin.motion.path import ARC

    for f_in, spec, t0 in ((20, "normal_time=0.025", 0.0), (27, "normal_time=0.025", 0.0),
                         (20, "normal_time=0.025,block_time=0.002", 0.002)):
        slow = tw.with_effects(f"spiral-acceleration:{spec}")
        v = f_in * 25.4 / 60.0
        for words, spiral in ((("-.0138", ".0137"), True), (("-.01375", ".01375"), False)):
            prog = tw.load(_helix(*words).replace(b"F36", f"F{f_in}".encode()), path="h.nc")
            plan = slow.plan(prog)
            arcs = plan.seg[plan.seg["kind"] == ARC]
            r = np.minimum(arcs["r0"], arcs["r1"])
            extra = t0 + v * v / r / 40000.0 if spiral else 0.0 * r
            np.testing.assert_allclose(arcs["length"] / arcs["vmax"], arcs["length"] / v + extra, rtol=1e-9)
    # the twin file's own controller.spiral_jerk is the same machine
    prog = tw.load(_helix("-.0138", ".0137").replace(b"F36", b"F20"), path="h.nc")
    direct = tw.with_params({"controller.spiral_jerk": 40000.0}).plan(prog).seg["vmax"]
    fitted = tw.with_effects("spiral-acceleration:normal_time=0.025").plan(prog).seg["vmax"]
    np.testing.assert_allclose(direct, fitted, rtol=1e-12)
    assert (direct < tw.plan(prog).seg["vmax"] - 0.1).any()


def _stands_exactly(text: bytes, param: str, controller_key: str, wait: float, lines: tuple):
    """(the default twin, the program): ``feed-rapid-wait``'s ``param`` at ``wait`` adds exactly
    that to the planned time of each of ``lines`` and nothing to any other line, and the twin
    file's ``controller_key`` plans the same."""
    tw = mtwin.Twin()
    prog = tw.load(text, path="w.nc")
    base, slow = tw.plan(prog), tw.with_effects(f"feed-rapid-wait:{param}={wait}").plan(prog)
    n = text.count(b"\n")
    per_line = lambda plan: {ln: float(plan.dur[plan.seg["line"] == ln].sum()) for ln in range(2, n)}
    b, s = per_line(base), per_line(slow)
    for ln in range(2, n):
        assert s[ln] == pytest.approx(b[ln] + (wait if ln in lines else 0.0), abs=1e-9), ln
    np.testing.assert_array_equal(tw.with_params({f"controller.{controller_key}": wait}).plan(prog).dur, slow.dur)
    return tw, prog


def test_feed_rapid_wait_stands_at_a_feed_move_a_rapid_follows_and_nowhere_else():
    # the wait adds exactly its time to the feed line a rapid follows (also over a dwell between
    # them) — and to no feed line a feed move follows, no rapid, no feed line after a rapid;
    # the servo simulation stands still there for that long (the trace's cycle grows by it too)
    text = (b"G21 G90 G94\nG0 X0 Y0 Z5\nG1 Z0 F600\nG1 X20\nG1 Y20\nG0 Z5\nG0 X40\nG1 Z0\nG1 X60\nG4 P0.5\n"
            b"G0 Z5\nM30\n")
    wait = 0.05
    tw, prog = _stands_exactly(text, "time", "feed_rapid_wait", wait, (5, 9))  # Y20 before G0 Z5; X60 before the dwell
    cycle = lambda twin: twin.simulate(prog, cutting=False).summary.cycle_time
    assert cycle(tw.with_effects(f"feed-rapid-wait:time={wait}")) - cycle(tw) == pytest.approx(2 * wait, abs=2e-3)
    # Grbl blends a feed move into the rapid after it; a control that stands there stops there
    grbl = tw.with_params({"controller.style": "grbl"})
    blended, standing = grbl.plan(prog), grbl.with_params({"controller.feed_rapid_wait": wait}).plan(prog)
    on = standing.seg["line"] == 5
    assert not blended.stop_end[blended.seg["line"] == 5][-1] and standing.stop_end[on][-1]
    assert standing.hold[on][-1] >= wait


def test_the_wait_before_cutting_stands_at_a_rapid_a_feed_move_follows_and_nowhere_else():
    # rapid_feed: exactly its time on the rapid a feed move follows (also over a dwell between
    # them: lines 2 and 7, and 11 before the dwell and G1) — none on a rapid another follows
    text = (b"G21 G90 G94\nG0 X0 Y0 Z5\nG1 Z0 F600\nG1 X20\nG1 Y20\nG0 Z5\nG0 X40\nG1 Z0\nG1 X60\nG0 Z5\n"
            b"G0 Z2\nG4 P0.5\nG1 Z0\nM30\n")
    wait = 0.05
    tw, prog = _stands_exactly(text, "rapid_feed", "rapid_feed_wait", wait, (2, 7, 11))
    # (the servo simulation stands that long too, where the in-position check after a rapid does
    # not outlast it: a narrow width, the default's, settles the rapid's lag meanwhile)
    wide = tw.with_params({"controller.in_position": 0.2})
    cycle = lambda twin: twin.simulate(prog, cutting=False).summary.cycle_time
    assert cycle(wide.with_params({"controller.rapid_feed_wait": wait})) - cycle(wide) == pytest.approx(3 * wait,
                                                                                                        abs=2e-3)


def test_rapid_acceleration_times_a_rapid_by_the_closed_form_and_leaves_feed_moves():
    # a long rapid without jerk: t = L/v + v/a (accelerate and brake at a, cruise between);
    # the feed move after it keeps the axes' acceleration
    tw = mtwin.Twin().with_params({"controller.bell_time": 0.0, "controller.after_filter": "none",
                                   "axes.x.max_acceleration": 400.0,
                                   "axes.x.max_velocity": 6000.0})
    prog = tw.load(b"G21 G90 G94\nG0 X0 Y0 Z0\nG0 X300\nG1 X0 F3000\nM30\n", path="r.nc")
    base, fast = tw.plan(prog), tw.with_effects("rapid-acceleration:acceleration=5000").plan(prog)
    v = 6000.0 / 60.0  # mm/s: reached after 12.5 mm at 400 mm/s²
    rapid = lambda plan: float(plan.dur[plan.seg["line"] == 3].sum())
    assert rapid(base) == pytest.approx(300 / v + v / 400.0, rel=1e-3)
    assert rapid(fast) == pytest.approx(300 / v + v / 5000.0, rel=1e-3)
    feed = lambda plan: float(plan.dur[plan.seg["line"] == 4].sum())
    assert feed(fast) == pytest.approx(feed(base), rel=1e-9)
    # more than the drives can give is refused, like an axis acceleration
    with pytest.raises(ConfigError, match="rapid_acceleration: 19000 mm/s\\^2 is more than axes.x.max_torque"):
        tw.with_effects("rapid-acceleration:acceleration=19000").plan(prog)


def test_a_spindle_at_its_power_limit_takes_the_square_of_the_speed_to_get_there():
    # torque-limited to power_speed (rate a), power-limited above (rate a*nb/n): from rest to n
    # takes nb/a + (n^2 - nb^2) / (2 a nb) -- the integral of n dn / (a nb)
    from mtwin.motion.planner import runup_time

    a, nb = 2000.0, 6000.0
    assert runup_time(0, 5000, a) == pytest.approx(2.5)
    assert runup_time(0, 5000, a, nb) == pytest.approx(2.5)  # below it: as before
    assert runup_time(0, 12000, a, nb) == pytest.approx(3.0 + (12000**2 - 6000**2) / (2 * a * nb))
    assert runup_time(9000, 12000, a, nb) == pytest.approx((12000**2 - 9000**2) / (2 * a * nb))
    assert runup_time(12000, 0, a, nb) == pytest.approx(runup_time(0, 12000, a, nb))  # braking alike
    assert runup_time(-3000, 3000, a, nb) == pytest.approx(3.0)  # a reversal: to rest, then up
    # the plan's spindle waits follow it: a 12,000-rpm start waits (12000/6000)^2 = 4x longer over
    # the power speed than a 6,000-rpm one, not 2x
    tw = mtwin.Twin().with_params({"spindle.max_speed": 12000.0})
    prog = lambda s: tw.load(f"G21 G90 G94\nS{s} M3\nG1 X10 F1000\nM30\n".encode(), path="s.nc")
    fx = tw.with_effects("spindle-runup:acceleration=2000,power_speed=6000")
    w = [float(fx.plan(prog(s)).category_times()["spindle_wait"]) for s in (6000, 12000)]
    assert w[0] == pytest.approx(3.0, rel=1e-6) and w[1] - w[0] == pytest.approx((12000**2 - 6000**2) / (2 * a * nb))


def test_a_braking_rate_apart_times_the_waits_after_m5_and_leaves_the_run_up():
    # up at 2,000 rpm/s (3 s to 6,000), down at 1,500 (4 s); a speed lowered from 6,000 to
    # 3,000 brakes too (2 s); with the power range above 3,000 rpm both rates fall as 3000/n
    tw = mtwin.Twin().with_effects("spindle-runup:acceleration=2000,braking=1500")
    prog = tw.load(b"G21 G90 G94\nS6000 M3\nG1 X10 F1000\nS3000\nG1 X0\nM5\nG0 Z50\nM30\n", path="k.nc")
    from mtwin.motion.path import PAUSE

    plan = tw.plan(prog)
    waits = plan.seg["duration"][plan.seg["kind"] == PAUSE].tolist()
    assert waits == pytest.approx([3.0, 2.0, 2.0], rel=1e-9)
    from mtwin.motion.planner import runup_time

    # from rest to n above the power speed nb: nb/a + (n² − nb²)/(2·a·nb), each way at its rate
    assert runup_time(0, 6000, 2000, 3000, 1500) == pytest.approx(1.5 + (36e6 - 9e6) / (2 * 2000 * 3000))
    assert runup_time(6000, 0, 2000, 3000, 1500) == pytest.approx(2.0 + (36e6 - 9e6) / (2 * 1500 * 3000))
    assert runup_time(6000, -6000, 2000, 3000, 1500) == pytest.approx(
        runup_time(6000, 0, 2000, 3000, 1500) + runup_time(0, -6000, 2000, 3000, 1500))


def test_without_wait_for_stop_the_moves_after_m5_run_while_the_spindle_brakes():
    # M5 then a retract: waited (the default), the braking (3 s from 6,000 rpm at 2,000 rpm/s)
    # comes before the retract; not waited (the Hurco), the retract runs while it brakes
    from mtwin.motion.path import PAUSE

    tw = mtwin.Twin().with_effects("spindle-runup:acceleration=2000")
    # a tool change after it waits, on the M6's line, for what is left of the braking when the
    # retract is done
    prog = tw.load(b"G21 G90 G94\nT1 M6\nS6000 M3\nG1 X10 F1000\nM5\nG0 Z50\nT2 M6\nG1 X0 F1000\nM30\n",
                   path="t.nc")
    free = tw.with_params({"spindle.wait_for_stop": False}).plan(prog)
    retract = float(free.dur[(free.seg["line"] == 6) & (free.seg["kind"] != PAUSE)].sum())
    assert 0.1 < retract < 3.0
    braking = (free.seg["kind"] == PAUSE) & (free.seg["since"] > 0)
    assert free.seg["line"][braking].tolist() == [7]
    assert float(free.dur[braking].sum()) == pytest.approx(3.0 - retract, rel=1e-6)
    assert float(free.category_times()["spindle_wait"]) == pytest.approx(3.0 + 3.0 - retract, rel=1e-6)
    assert tw.plan(prog).total_time - free.total_time == pytest.approx(retract, rel=1e-6)
    # at the program's end (no tool change, no restart) the program completes once the spindle
    # is down: the rest of the braking stands at the M30's line
    prog = tw.load(b"G21 G90 G94\nS6000 M3\nG1 X10 F1000\nM5\nG0 Z50\nM30\n", path="e.nc")
    free = tw.with_params({"spindle.wait_for_stop": False}).plan(prog)
    retract = float(free.dur[(free.seg["line"] == 5) & (free.seg["kind"] != PAUSE)].sum())
    braking = (free.seg["kind"] == PAUSE) & (free.seg["since"] > 0)
    assert free.seg["line"][braking].tolist() == [6]
    assert float(free.dur[braking].sum()) == pytest.approx(3.0 - retract, rel=1e-6)
    assert free.total_time == pytest.approx(tw.plan(prog).total_time - retract, rel=1e-6)


@pytest.mark.parametrize("overlap", [False, True])
def test_the_spindle_runs_up_on_the_block_that_starts_it_not_at_the_m01_or_the_m6_before(overlap):
    # M5, a retract, M01, T2 M6, then G0 X Y S6000 M3: the trace's spindle is down through the
    # M01 and the tool change and runs up from the M3 block on (the Hurco logs its Spindle_Speed
    # at 0 there)
    text = (b"G21 G90 G17 G94\nT1 M6\nS3000 M3\nG0 X0 Y0 Z5\nG1 Z-1 F300\nG1 X40 F900\nG0 Z5\nM5\nG0 Z50\n"
            b"M01\nT2 M6\nG0 X10 Y10 S6000 M3\nZ5\nG1 Z-1 F300\nG1 X40\nG0 Z5\nM30\n")
    tw = mtwin.Twin()
    if overlap:  # (as the Hurco profile: moves run while it brakes, the rapid while it runs up)
        tw = tw.with_effects("spindle-runup:acceleration=2000,braking=1500").with_params(
            {"spindle.wait_for_stop": False, "spindle.runup_overlap": True})
    prog = tw.load(text, path="tc.nc")
    tr = tw.simulate(prog)
    line, speed = np.asarray(tr.line), np.asarray(tr.signal("spindle_speed"))
    assert np.all(speed[np.isin(line, (10, 11))] <= speed[line == 9].max() + 1e-6)  # the M01 and the M6
    assert speed[line == 11].max() < 1.0  # down through the tool change
    assert speed[line == 12][0] < 100.0 and speed[line >= 14].min() == pytest.approx(6000.0, rel=1e-3)


def test_the_spindle_stays_down_when_the_tool_is_put_away_after_the_last_move():
    # M5, a retract, then T0 M6 after the last move: that tool change stands after its record's
    # motion and keeps its command (0), not the record before's S6000
    tw = mtwin.Twin()
    prog = tw.load(b"G21 G90 G94\nT1 M6\nS6000 M3\nG0 X0 Y0 Z5\nG1 Z-1 F300\nG1 X20 F900\nG0 Z20\nM5\nG0 Z50\n"
                   b"T0 M6\nM30\n", path="end.nc")
    tr = tw.simulate(prog)
    line, speed = np.asarray(tr.line), np.asarray(tr.signal("spindle_speed"))
    assert (line == 10).any() and speed[line == 10].max() < 1.0


def test_a_braking_overlapping_motion_waits_at_the_m01_at_once_before_a_restart_and_counts_dwells():
    # 3 s of braking (6,000 rpm at 2,000 rpm/s), moves allowed to run meanwhile
    from mtwin.motion.path import PAUSE

    tw = mtwin.Twin().with_effects("spindle-runup:acceleration=2000").with_params({"spindle.wait_for_stop": False})

    def braking(text):
        plan = tw.plan(tw.load(text, path="w.nc"))
        on = (plan.seg["kind"] == PAUSE) & (plan.seg["since"] > 0)
        moving = (plan.seg["kind"] != PAUSE)
        return plan, plan.seg["line"][on].tolist(), float(plan.dur[on].sum()), moving

    # reported at the M01 before the tool change, as the Hurco stands there
    plan, lines, wait, moving = braking(b"G21 G90 G94\nT1 M6\nS6000 M3\nG1 X10 F1000\nM5\nG0 Z50\nM01\nT2 M6\n"
                                        b"G1 X0 F1000\nM30\n")
    retract = float(plan.dur[moving & (plan.seg["line"] == 6)].sum())
    assert lines == [7] and wait == pytest.approx(3.0 - retract, rel=1e-9)
    # M5 and M6 with no move between: all of it, before the tool change
    plan, lines, wait, _ = braking(b"G21 G90 G94\nT1 M6\nS6000 M3\nG1 X10 F1000\nM5\nT2 M6\nG1 X0 F1000\nM30\n")
    assert lines == [6] and wait == pytest.approx(3.0, rel=1e-9)
    wait_at = int(np.flatnonzero((plan.seg["kind"] == PAUSE) & (plan.seg["since"] > 0))[0])
    from mtwin.motion.path import CAT_TOOL

    change_at = int(np.flatnonzero((plan.seg["kind"] == PAUSE) & (plan.seg["cat"] == CAT_TOOL))[-1])
    assert wait_at == change_at - 1  # the spindle is down before the tool comes out
    # a tool put away after the last move: at its M01, before that change
    plan, lines, wait, moving = braking(b"G21 G90 G94\nT1 M6\nS6000 M3\nG1 X10 F1000\nM5\nG0 Z50\nM01\nT2 M6\nM30\n")
    retract = float(plan.dur[moving & (plan.seg["line"] == 6)].sum())
    assert lines == [7] and wait == pytest.approx(3.0 - retract, rel=1e-9)
    wait_at = int(np.flatnonzero((plan.seg["kind"] == PAUSE) & (plan.seg["since"] > 0))[0])
    assert plan.seg["cat"][wait_at + 1] == CAT_TOOL and plan.seg["line"][wait_at + 1] == 8
    # started again before any tool change: the rest of the braking, then the whole run-up
    plan, lines, wait, moving = braking(b"G21 G90 G94\nS6000 M3\nG1 X10 F1000\nM5\nG0 Z50\nS6000 M3\n"
                                        b"G1 X0 F1000\nM30\n")
    retract = float(plan.dur[moving & (plan.seg["line"] == 5)].sum())
    assert lines == [7] and wait == pytest.approx(3.0 - retract, rel=1e-9)
    assert float(plan.category_times()["spindle_wait"]) == pytest.approx(3.0 + wait + 3.0, rel=1e-9)
    # a dwell while it brakes counts as the moves do (Fanuc G4 P in ms)
    plan, lines, wait, moving = braking(b"G21 G90 G94\nS6000 M3\nG1 X10 F1000\nM5\nG4 P1000\nG0 Z50\nM30\n")
    retract = float(plan.dur[moving & (plan.seg["line"] == 6)].sum())
    assert lines == [7] and wait == pytest.approx(3.0 - 1.0 - retract, rel=1e-9)


def test_a_braking_overlapping_motion_keeps_its_time_on_a_linuxcnc_path_of_merged_lines():
    # LinuxCNC's naive CAM joins collinear G1 lines; it does not join over the M5 (LinuxCNC
    # flushes the chain at a spindle command), so the braking counts only the moves after it
    from mtwin.motion.path import PAUSE

    tw = mtwin.Twin().with_controller(style="linuxcnc").with_effects("spindle-runup:acceleration=2000") \
        .with_params({"spindle.wait_for_stop": False})
    text = (b"G21 G90 G94 G64 P0.01 Q0.01\nT1 M6\nS6000 M3\nG1 X10 F600\nX20\nX30\nM5\nX40\nX50\nT2 M6\n"
            b"G0 Z10\nM30\n")
    plan = tw.plan(tw.load(text, path="l.ngc"))
    on = (plan.seg["kind"] == PAUSE) & (plan.seg["since"] > 0)
    after = float(plan.dur[(plan.seg["kind"] != PAUSE) & (plan.seg["line"] >= 8) & (plan.seg["line"] <= 9)].sum())
    assert 1.0 < after < 3.0  # 20 mm at 10 mm/s and its braking ramp
    assert float(plan.dur[on].sum()) == pytest.approx(3.0 - after, rel=1e-9)


def test_an_overlapped_run_up_waits_at_the_next_block_for_what_the_move_left():
    # S6000 M3 on a rapid: overlapped, the 3-s run-up (2,000 rpm/s) runs during the rapid and
    # the next block waits 3 s less the rapid's time; a run-up shorter than the
    # rapid leaves no wait at all
    from mtwin.motion.path import PAUSE

    tw = mtwin.Twin().with_effects("spindle-runup:acceleration=2000")
    prog = tw.load(b"G21 G90 G94\nG0 X0 Y0 Z50\nS6000 M3 G0 X100\nG0 Z0\nG1 X0 F1000\nM30\n", path="o.nc")
    base = tw.plan(prog)
    plan = tw.with_params({"spindle.runup_overlap": True}).plan(prog)
    rapid = float(plan.dur[(plan.seg["line"] == 3) & (plan.seg["kind"] != PAUSE)].sum())
    wait = plan.seg["kind"] == PAUSE
    assert 0.3 < rapid < 3.0
    assert plan.seg["line"][wait].tolist() == [4]  # stands on the next block, as the Hurco reports it
    assert float(plan.dur[wait].sum()) == pytest.approx(3.0 - rapid, rel=1e-9)
    assert base.total_time - plan.total_time == pytest.approx(rapid, rel=1e-9)
    quick = tw.with_effects("spindle-runup:acceleration=60000").with_params({"spindle.runup_overlap": True})
    plan = quick.plan(prog)
    assert float(plan.dur[plan.seg["kind"] == PAUSE].sum()) == 0.0
    # after a tool change (the Hurco's T M6, then G0 X Y S M3): only the rapid overlaps the run-up
    prog = tw.load(b"G21 G90 G94\nG0 X0 Y0 Z50\nT2 M6\nG0 X100 S6000 M3\nG0 Z0\nG1 X0 F1000\nM30\n", path="c.nc")
    plan = tw.with_params({"spindle.runup_overlap": True}).plan(prog)
    rapid = float(plan.dur[(plan.seg["line"] == 4) & (plan.seg["kind"] != PAUSE)].sum())
    wait = (plan.seg["kind"] == PAUSE) & (plan.seg["since"] > 0)
    assert plan.seg["line"][wait].tolist() == [5] and float(plan.dur[wait].sum()) == pytest.approx(3.0 - rapid)
    # S M3 on a block of its own: the rapid after it does not start the spindle, and waits
    prog = tw.load(b"G21 G90 G94\nG0 X0 Y0 Z50\nS6000 M3\nG0 X100\nG0 Z0\nM30\n", path="g.nc")
    plan = tw.with_params({"spindle.runup_overlap": True}).plan(prog)
    assert plan.total_time == pytest.approx(tw.plan(prog).total_time, rel=1e-12)
    # a feed move never starts before the spindle is at speed: S M3 on a G1 waits before it
    prog = tw.load(b"G21 G90 G94\nG0 X0 Y0 Z50\nS6000 M3 G1 X100 F1000\nG0 Z0\nM30\n", path="f.nc")
    plan = tw.with_params({"spindle.runup_overlap": True}).plan(prog)
    wait = plan.seg["kind"] == PAUSE
    assert plan.seg["line"][wait].tolist() == [3] and float(plan.dur[wait].sum()) == pytest.approx(3.0)
    assert plan.total_time == pytest.approx(tw.plan(prog).total_time, rel=1e-12)


def test_a_feed_override_runs_the_program_as_if_every_f_were_scaled():
    # an independent route: the program with each F multiplied by 1.3 by hand plans the same
    # (rapids and dwells untouched); a long move's time at speed falls as 1/1.3
    tw = mtwin.Twin()
    text = "G21 G90 G94 S1000 M3\nG0 X0 Y0 Z0\nG1 X600 F{a}\nG2 X600 Y-40 I0 J-20 F{b}\nG0 Z5\nG4 P1\nM30\n"
    prog = tw.load(text.format(a=600, b=300).encode(), path="f.nc")
    by_hand = tw.load(text.format(a=780, b=390).encode(), path="f.nc")
    over = tw.with_effects("feed-override:feed=130").plan(prog)
    ref = tw.plan(by_hand)
    np.testing.assert_allclose(over.dur, ref.dur, rtol=1e-12)
    base = tw.plan(prog)
    i = int(np.flatnonzero(base.seg["line"] == 3)[0])
    assert base.dur[i] - over.dur[i] == pytest.approx(600 / 10.0 - 600 / 13.0, rel=0.02)  # mm / (mm/s)


def test_tool_change_and_spindle_waits_add_their_times():
    tw = mtwin.Twin()
    prog = tw.load(b"G21 G90 G94\nT1 M6\nS1000 M3\nG0 X0 Y0 Z5\nT2 M6\nG0 X10\nM30\n", path="t.nc")
    base = tw.plan(prog).total_time
    assert tw.with_effects("toolchange-time:extra=2").plan(prog).total_time - base == pytest.approx(4.0)
    assert tw.with_effects("toolchange-time:first_extra=3").plan(prog).total_time - base == pytest.approx(3.0)
    # run-up to 1,000 rpm at 500 rpm/s instead of the twin file's 4,000 rpm/s
    assert tw.with_effects("spindle-runup:acceleration=500").plan(prog).total_time - base == pytest.approx(
        1000 / 500 - 1000 / 4000)


def test_block_time_and_corner_slowdown_slow_short_blocks_and_corners():
    tw = mtwin.Twin()
    moves = "".join(f"G1 X{0.2 * (k + 1):.1f} Y{0.1 * (k % 2):.1f}\n" for k in range(50))
    prog = tw.load(("G21 G90 G94 G64\nG0 X0 Y0 Z0\nF3000\n" + moves + "M30\n").encode(), path="b.nc")
    base = tw.plan(prog).total_time
    slow = tw.with_effects("block-time:min_time=0.05").plan(prog)
    # 50 blocks at no less than 50 ms each
    assert slow.total_time >= 50 * 0.05 > base
    assert tw.with_effects("corner-slowdown:corner_velocity=50").plan(prog).total_time > base


def test_an_effects_dotted_parameter_name_is_built_and_split_in_one_place():
    from mtwin.errors import ConfigError
    from mtwin.params import effect_param, is_effect_param, split_effect_param

    name = effect_param("spindle-runup", "power_speed")
    assert name == "effects.spindle-runup.power_speed" and is_effect_param(name)
    assert split_effect_param(name) == ("spindle-runup", "power_speed")
    assert not is_effect_param("x.servo.kpp")
    with pytest.raises(ConfigError):
        split_effect_param("x.servo.kpp")


def test_stop_angle_stops_at_reversals_as_g9_does_and_blends_the_rest():
    # a zig-zag: two reversals (174.3° and 168.6°) and a straight run; with stop_angle the plan is
    # the one the interpreter makes of G9 on the blocks that end at the reversals, nothing else moves
    tw = mtwin.Twin()
    body = "{g9}G1 X10 F1000\n{g9}X0 Y1\nX10 Y2\nX20 Y3\nX30 Y4.5\nG0 Z5\nM30\n"
    head = "G21 G90 G94 S1000 M3\nG0 X0 Y0 Z0\n"
    plain = tw.load((head + body.format(g9="")).encode(), path="z.nc")
    g9 = tw.load((head + body.format(g9="G9 ")).encode(), path="z9.nc")
    stop = tw.with_params({"controller.stop_angle": 120.0})
    a, b, base = stop.plan(plain), tw.plan(g9), tw.plan(plain)
    np.testing.assert_allclose(a.dur, b.dur, rtol=1e-12, atol=1e-12)
    assert a.total_time > base.total_time + 0.02  # the reversals cost the stops
    # the straight run and the shallow corner (2.8°) after the last reversal are untouched
    last = lambda plan: float(plan.dur[plan.seg["line"] == 7].sum())
    assert last(a) == pytest.approx(last(base), rel=1e-12)
    # only turns sharper than the angle stop: at 175° none of these does
    np.testing.assert_allclose(tw.with_params({"controller.stop_angle": 175.0}).plan(plain).dur, base.dur)
    # an arc's end tangent, not its chord, decides: a half circle ending heading -X, then a line
    # back along +X (a 180° turn) stops; the same half circle then a line on along -X does not
    arc = "G21 G90 G94 S1000 M3\nG0 X0 Y0 Z0\nG1 X10 F1000\n{g9}G3 X10 Y10 I0 J5\nG1 X{x}\nG0 Z5\nM30\n"
    back, on = (tw.load(arc.format(g9="", x=x).encode(), path="a.nc") for x in (20, 0))
    back9 = tw.load(arc.format(g9="G9 ", x=20).encode(), path="a9.nc")
    np.testing.assert_allclose(stop.plan(back).dur, tw.plan(back9).dur, rtol=1e-12, atol=1e-12)
    assert stop.plan(back).total_time > tw.plan(back).total_time
    np.testing.assert_allclose(stop.plan(on).dur, tw.plan(on).dur, rtol=1e-12, atol=1e-12)
