"""Cutting-load twin against closed forms (PHYSICS.md §1): slot forces and torque, up/down
milling, air cuts, ball-end plunge, power = torque × ω; engagement reuse; clear errors."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import quad

from mtwin.cutting.library import BUILTIN_MATERIALS as MATERIALS, cutting_from_dict
from mtwin.errors import MtwinError
from mtwin.layout import C_POWER, C_SPEED, C_TORQUE
from mtwin.twin import Twin
from mtwin.twin.machine import Machine

AL7075 = MATERIALS["al7075"]  # all six coefficients non-zero


def twin_with(material="al7075", tools=None) -> Twin:
    m = Machine()
    m = replace(m, timing=replace(m.timing, tool_change=0.0))
    raw = {"cutting": {"material": material}}
    if tools:
        raw["tools"] = tools
    return Twin(m, cutting=cutting_from_dict(raw))


def run(tw, text, **kw):
    prog = tw.load(text.encode(), path="cut.nc")
    return prog, tw.simulate(prog, **kw)


def steady(trace, x_lo, x_hi):
    """Samples while the tool is between x_lo and x_hi at constant speed."""
    x = trace.cmd[:, 0]
    return (x > x_lo) & (x < x_hi)


N, R, A_P = 2, 3.0, 2.0
F_MM_MIN, S_RPM = 600.0, 8000.0
FZ = F_MM_MIN / 60.0 / (N * S_RPM / 60.0)  # feed per tooth, mm


def slot_forces(k, fz, a, phi_st, phi_ex):
    """Revolution-averaged Fx, Fy, Fz (N) and torque (N·m) of a flat end mill, local frame."""
    def avg(g):
        return N * a / (2 * math.pi) * quad(g, phi_st, phi_ex)[0]

    ft = lambda p: k.ktc * fz * math.sin(p) + k.kte  # noqa: E731
    fr = lambda p: k.krc * fz * math.sin(p) + k.kre  # noqa: E731
    fa = lambda p: k.kac * fz * math.sin(p) + k.kae  # noqa: E731
    fx = avg(lambda p: -ft(p) * math.cos(p) - fr(p) * math.sin(p))
    fy = avg(lambda p: ft(p) * math.sin(p) - fr(p) * math.cos(p))
    fz_ = avg(fa)
    torque = avg(ft) * R * 1e-3
    return fx, fy, fz_, torque


def test_full_slot_matches_the_closed_form():
    tw = twin_with()
    _, tr = run(tw, f"G21 G90 G94 S{S_RPM:g} M3\nG0 X-10 Y0 Z5\nG0 Z-{A_P}\nG1 X40 F{F_MM_MIN:g}\nG0 Z5\nM30\n"
                    "(MTWIN STOCK 0,-10,-10,50,10,0)\n")
    m = steady(tr, 15, 35)
    fx, fy, fz, torque = slot_forces(AL7075, FZ, A_P, 0.0, math.pi)
    # PHYSICS.md's own closed form for the full slot, as a second check of the reference
    assert fx == pytest.approx(-N * A_P * AL7075.krc * FZ / 4 - N * A_P * AL7075.kre / math.pi)
    assert fy == pytest.approx(N * A_P * AL7075.ktc * FZ / 4 + N * A_P * AL7075.kte / math.pi)
    assert fz == pytest.approx(N * A_P * AL7075.kac * FZ / math.pi + N * A_P * AL7075.kae / 2)
    assert tr.force[m, 0].mean() == pytest.approx(fx, rel=0.02)
    assert tr.force[m, 1].mean() == pytest.approx(fy, rel=0.02)
    assert tr.force[m, 2].mean() == pytest.approx(fz, rel=0.02)
    assert tr.cut[m, 1].mean() == pytest.approx(torque, rel=0.02)
    assert tr.cut[m, 3].mean() == pytest.approx(2 * R, rel=0.02)  # ae
    assert tr.cut[m, 4].mean() == pytest.approx(A_P, rel=1e-6)  # ap
    assert tr.cut[m, 5].mean() == pytest.approx(F_MM_MIN / 60 * 2 * R * A_P, rel=0.02)  # mrr


@pytest.mark.parametrize("side,phi", [("up", (0.0, math.pi / 2)), ("down", (math.pi / 2, math.pi))])
def test_half_immersion_up_and_down_milling(side, phi):
    # feed +X with M3: material on the left (+Y) is up-milling (the chip starts at zero
    # thickness, φ from 0 to π/2), on the right (−Y) down-milling (φ from π/2 to π)
    box = "0,0,-10,50,10,0" if side == "up" else "0,-10,-10,50,0,0"
    tw = twin_with()
    _, tr = run(tw, f"G21 G90 G94 S{S_RPM:g} M3\nG0 X-10 Y0 Z5\nG0 Z-{A_P}\nG1 X40 F{F_MM_MIN:g}\nG0 Z5\nM30\n"
                    f"(MTWIN STOCK {box})\n")
    m = steady(tr, 15, 35)
    fx, fy, _, torque = slot_forces(AL7075, FZ, A_P, *phi)
    assert tr.force[m, 0].mean() == pytest.approx(fx, rel=0.02)
    assert tr.force[m, 1].mean() == pytest.approx(fy, rel=0.02)
    assert tr.cut[m, 1].mean() == pytest.approx(torque, rel=0.02)
    # the sign that tells them apart: down-milling pulls the tool along the feed
    assert (tr.force[m, 0].mean() > 0) == (side == "down")


def test_second_identical_pass_is_an_air_cut():
    tw = twin_with()
    pas = f"G0 X-10 Y0 Z5\nG0 Z-{A_P}\nG1 X40 F{F_MM_MIN:g}\nG0 Z5\n"
    prog, tr = run(tw, f"G21 G90 G94 S{S_RPM:g} M3\n{pas}{pas}M30\n(MTWIN STOCK 0,-10,-10,50,10,0)\n")
    first = tr.line == 4
    second = tr.line == 8
    assert np.abs(tr.force[first]).max() > 10.0
    assert np.abs(tr.force[second]).max() == 0.0
    assert tr.cut[second, 1].max() == 0.0


def test_ball_end_plunge_axial_force():
    depth = 1.5
    tools = {"1": {"type": "ball", "diameter": 6.0, "flutes": 2}}
    tw = twin_with(tools=tools)
    prog, tr = run(tw, f"G21 G90 G94 T1 M6\nS{S_RPM:g} M3\nG0 X10 Y10 Z2\nG1 Z-3 F{F_MM_MIN:g}\nG0 Z5\nM30\n"
                       "(MTWIN STOCK 0,0,-10,20,20,0)\n")
    k = AL7075
    # sample where the tip is `depth` below the surface, moving at constant speed
    z = tr.cmd[:, 2]
    i = int(np.argmin(np.abs(z + depth)))
    v = np.linalg.norm(tr.vel[i])
    fz_t = v / (N * S_RPM / 60.0)
    kap_a = math.acos(1 - depth / R)
    # h = f·cosκ, db = dS = R·dκ; on the tool Fz = cosκ·Fr + sinκ·Fa, over N flutes
    integrand = lambda kap: (math.cos(kap) * (k.krc * fz_t * math.cos(kap) + k.kre)  # noqa: E731
                             + math.sin(kap) * (k.kac * fz_t * math.cos(kap) + k.kae))
    expected = N * R * quad(integrand, 0.0, kap_a)[0]
    assert tr.force[i, 2] == pytest.approx(expected, rel=0.02)
    assert abs(tr.force[i, 0]) < 1e-6 * expected and abs(tr.force[i, 1]) < 1e-6 * expected


def test_power_equals_torque_times_omega():
    tw = twin_with()
    _, tr = run(tw, f"G21 G90 G94 S{S_RPM:g} M3\nG0 X-10 Y0 Z5\nG0 Z-{A_P}\nG1 X40 F{F_MM_MIN:g}\nG0 Z5\nM30\n"
                    "(MTWIN STOCK 0,-10,-10,50,10,0)\n")
    speed, torque, power = (tr.cut[:, c].astype(float) for c in (C_SPEED, C_TORQUE, C_POWER))
    assert np.allclose(power, torque * 2 * math.pi * np.abs(speed) / 60.0, rtol=1e-5, atol=1e-6)
    assert power.max() > 50.0


def test_engagement_is_computed_once_per_path():
    tw = twin_with()
    base = "G21 G90 G94 S{s} M3\nG0 X-10 Y0 Z5\nG0 Z-2\nG1 X40 F{f}\nG0 Z5\nM30\n(MTWIN STOCK 0,-10,-10,50,10,0)\n"
    _, a = run(tw, base.format(s=8000, f=600))
    assert tw.engagement_cache.computations == 1
    _, b = run(tw, base.format(s=6000, f=900))  # new F and S only
    assert tw.engagement_cache.computations == 1
    assert b.summary.cutting.peak_load != a.summary.cutting.peak_load  # the forces did change
    _, c = run(tw, base.format(s=6000, f=900).replace("Z-2", "Z-3"))  # new geometry
    assert tw.engagement_cache.computations == 2
    # a twin with other drive parameters shares the cache: the path is the same
    tw2 = tw.with_params({"axes.x.servo.kpp": 30.0})
    run(tw2, base.format(s=7000, f=700))
    assert tw2.engagement_cache.computations == 2


def test_stock_not_containing_the_toolpath_names_the_line():
    tw = twin_with()
    with pytest.raises(MtwinError, match=r"cut\.nc:4:.*below the stock bottom"):
        run(tw, "G21 G90 G94 S8000 M3\nG0 X5 Y5 Z5\nG1 Z-1 F300\nG1 Z-12\nM30\n(MTWIN STOCK 0,0,-10,10,10,0)\n")


def test_tool_missing_from_the_table_names_the_line():
    tw = twin_with(tools={"1": {"type": "flat", "diameter": 10.0, "flutes": 3}})
    with pytest.raises(MtwinError, match=r"cut\.nc:5:.*T2 is not in the tool table"):
        run(tw, "G21 G90 G94 T1 M6\nS8000 M3\nG1 X5 F300\nT2 M6\nG1 X10 Y1 Z-1\nM30\n")


def test_material_without_coefficients_names_the_key():
    with pytest.raises(MtwinError, match=r"cutting\.material: no coefficients for 'inconel'"):
        cutting_from_dict({"cutting": {"material": "inconel"}})
    with pytest.raises(MtwinError, match=r"materials\.mine: needs at least ktc"):
        cutting_from_dict({"materials": {"mine": {"krc": 100.0}}, "cutting": {"material": "mine"}})
    with pytest.raises(MtwinError, match=r"tools\.3\.flutes"):
        cutting_from_dict({"tools": {"3": {"flutes": 0}}})


def test_cutting_force_loads_the_feed_drive():
    # in a slot the X drive must push against Fx: more torque than the same move in air
    tw = twin_with()
    text = f"G21 G90 G94 S{S_RPM:g} M3\nG0 X-10 Y0 Z5\nG0 Z-{A_P}\nG1 X40 F{F_MM_MIN:g}\nG0 Z5\nM30\n"
    _, cut = run(tw, text + "(MTWIN STOCK 0,-10,-10,50,10,0)\n")
    _, air = run(tw, text, cutting=False)
    m_c, m_a = steady(cut, 15, 35), steady(air, 15, 35)
    fpt = tw.machine.x.force_per_torque
    extra = cut.torque[m_c, 0].mean() - air.torque[m_a, 0].mean()
    assert extra == pytest.approx(-cut.force[m_c, 0].mean() / fpt, rel=0.01)


def _tooth_twin(helix):
    m = Machine()
    # a 0.097 ms servo period samples the 267 Hz tooth passing ~39 times per tooth, at angles
    # that do not repeat from one revolution to the next (no aliasing of the entry/exit jumps)
    m = replace(m, controller=replace(m.controller, servo_period=0.000097), timing=replace(m.timing, tool_change=0.0))
    return Twin(m, cutting=cutting_from_dict({"cutting": {"material": "al7075"},
                                              "tools": {"1": {"diameter": 6.0, "flutes": 2, "helix": helix}}}))


SLOT = (f"G21 G90 G94 T1 M6\nS{S_RPM:g} M3\nG0 X-10 Y0 Z5\nG0 Z-{A_P}\nG1 X40 F{F_MM_MIN:g}\nG0 Z5\nM30\n"
        "(MTWIN STOCK 0,-10,-10,50,10,0)\n")


@pytest.mark.parametrize("helix", [0.0, 30.0])
def test_tooth_resolution_averages_to_the_revolution_model(helix):
    tw = _tooth_twin(helix)
    prog = tw.load(SLOT.encode(), path="cut.nc")
    avg = tw.simulate(prog)
    inst = tw.simulate(prog, tooth_resolution=True)
    ma, mi = steady(avg, 15, 35), steady(inst, 15, 35)
    for k in range(3):
        assert inst.force[mi, k].mean() == pytest.approx(avg.force[ma, k].mean(), rel=0.01, abs=0.05)
    assert inst.cut[mi, 1].mean() == pytest.approx(avg.cut[ma, 1].mean(), rel=0.01)
    # the instantaneous force really varies with the tooth angle
    assert np.ptp(inst.force[mi, 1]) > 0.5 * abs(avg.force[ma, 1].mean())


def test_tooth_resolution_straight_flute_slot_peak():
    # straight flutes (helix 0), two teeth at 180°: one tooth in the slot at a time, so
    # Fy(φ) = a·[(Ktc·h + Kte)·sinφ − (Krc·h + Kre)·cosφ] with h = f·sinφ, φ in (0, π)
    tw = _tooth_twin(0.0)
    prog = tw.load(SLOT.encode(), path="cut.nc")
    tr = tw.simulate(prog, tooth_resolution=True)
    m = steady(tr, 15, 35)
    k = AL7075
    phi = np.linspace(0.0, math.pi, 20001)
    h = FZ * np.sin(phi)
    fy = A_P * ((k.ktc * h + k.kte) * np.sin(phi) - (k.krc * h + k.kre) * np.cos(phi))
    fx = A_P * (-(k.ktc * h + k.kte) * np.cos(phi) - (k.krc * h + k.kre) * np.sin(phi))
    assert tr.force[m, 1].max() == pytest.approx(fy.max(), rel=0.03)
    assert tr.force[m, 1].min() == pytest.approx(fy.min(), rel=0.03, abs=0.5)
    assert tr.force[m, 0].min() == pytest.approx(fx.min(), rel=0.03)


def test_rapid_through_the_stock_is_reported():
    tw = twin_with()
    _, tr = run(tw, "G21 G90 G94 S8000 M3\nG0 X-10 Y0 Z5\nG0 Z-2\nG0 X30\nG1 X40 F600\nM30\n"
                    "(MTWIN STOCK 0,-10,-10,50,10,0)\n")
    assert any("cut.nc:4:1: warning: a rapid move goes through the stock" in w for w in tr.summary.warnings)


def test_pocket_sample_clears_its_pocket():
    # the sample is meant to be a realistic program: no island of material left in the pocket
    from conftest import SAMPLES

    tw = Twin()
    tr = tw.simulate(tw.load(str(SAMPLES / "pocket.nc")))
    st = tr.engagement.stock
    H = st.heights
    xs = st.box[0] + (np.arange(H.shape[1]) + 0.5) * st.resolution
    ys = st.box[1] + (np.arange(H.shape[0]) + 0.5) * st.resolution
    X, Y = np.meshgrid(xs, ys)
    core = (X > 13) & (X < 47) & (Y > 13) & (Y < 37)
    assert H[core].max() == pytest.approx(-6.0, abs=1e-6)


def test_feed_and_spindle_overrides_match_the_rewritten_program():
    # simulating with per-record overrides is the same as simulating the program the writer
    # produces with those feeds and speeds — and needs no new engagement
    import mtwin
    from conftest import SAMPLES

    tw = Twin()
    prog = tw.load(str(SAMPLES / "pocket.nc"))
    base = tw.simulate(prog, every=50)
    n = tw.engagement_cache.computations
    rec = prog.records
    over = tw.simulate(prog, every=50, feeds=rec["feed"] * 1.2, spindles=rec["spindle"] * 0.875)
    assert tw.engagement_cache.computations == n
    text = mtwin.scale_feeds(prog, feed=1.2, spindle=0.875)  # integer F values: no rounding
    rewritten = tw.simulate(tw.load(text, path=prog.path), every=50)
    assert over.summary.cycle_time == pytest.approx(rewritten.summary.cycle_time, abs=1e-9)
    assert over.summary.cutting.peak_load == pytest.approx(rewritten.summary.cutting.peak_load, rel=1e-6)
    assert over.summary.cycle_time < base.summary.cycle_time
    with pytest.raises(MtwinError):
        tw.simulate(prog, feeds=rec["feed"][:-1])


def test_a_force_beyond_the_drives_thrust_does_not_run_away():
    # a 6 mm end mill buried 58 mm deep at 0.1 mm/tooth: ~2 kN, more than the X drive can
    # push; the axis lags and the chip thins (the feed is measured along the commanded
    # direction), instead of a force that feeds itself to infinity (found by fuzzing)
    prog_text = "G21 F100\nG0 X0 Y0 Z-50\nS3000 M3\nG91 X-8.0 Z-0.75\nS500 M3 Z-7.75\nG2 I-12.25\nM2\n"
    twin = Twin()
    tr = twin.simulate(twin.load(prog_text.encode(), path="deep.nc"), every=10)
    assert np.isfinite(tr.act).all() and np.isfinite(tr.torque).all()
    assert 500.0 < tr.summary.cutting.peak_load < 5000.0


def test_a_stiff_cut_at_low_spindle_speed_stays_stable():
    # 20 mm deep slot at S200: dF/dv of the process is ~7x what one explicit servo period
    # of the axis mass can absorb; the feed is solved implicitly with the force, so the
    # simulation neither diverges nor rings (found by fuzzing: it raised "diverged"), and
    # the force stays within what the X drive can push against.
    text = "G21 G90 G17\nT1 M6\nS200 M3\nG0 X-10 Y0 Z5\nG1 Z-20 F300\nG1 X30\nG0 Z5\nM30\n"
    twin = Twin()
    tr = twin.simulate(twin.load(text.encode(), path="stiff.nc"), every=1)
    assert np.isfinite(tr.act).all() and np.isfinite(tr.force).all()
    from mtwin.motion.simulate import servo_table
    import mtwin.motion._runkernel as RK
    thrust = servo_table(twin.machine)[0, RK.SV_FMAX]
    fx = tr.force[:, 0]
    assert -fx.min() <= 1.05 * thrust  # resisting the +X feed; never beyond what X can push
    assert fx.max() <= 0.05 * thrust  # no sign flips from ringing
    assert abs(tr.act[tr.line == 6, 0][-1] - 30.0) < 0.05  # and the cut is completed


def test_a_cut_the_drives_cannot_hold_is_reported_not_simulated():
    # a 6 mm end mill 25 mm deep at S100 and 3 m/min: tens of kN against 11.3 kN of thrust.
    # The tool is pushed sideways off the commanded path (whose engagement the forces come
    # from), so the twin stops with the line instead of reporting a runaway (3D_Chips.ngc
    # at its own F of 2,250 m/min reported an infinite load)
    from mtwin.errors import MtwinError

    twin = Twin()
    prog = twin.load(b"G21 G90 G17\nS100 M3\nG0 X-10 Y0 Z5\nG1 Z-25 F3000\nG1 X30\nG2 X50 Y20 R20\nG1 Y60\nG0 Z5\nM30\n",
                     path="x.nc")
    with pytest.raises(MtwinError, match=r"x.nc:5:1: the cutting force .* more than its radius off"):
        twin.simulate(prog, every=10)


def test_a_mid_program_spindle_change_reuses_the_engagement():
    # a new S halfway adds a spindle run-up pause to the plan; the engagement (motion only)
    # is the same and is reused, with the result a fresh twin computes
    import mtwin
    from conftest import SAMPLES

    tw = mtwin.Twin()
    prog = tw.load(str(SAMPLES / "pocket.nc"))
    tw.simulate(prog)
    s = prog.records["spindle"].copy()
    s[len(s) // 2:] = 7000.0
    b = tw.simulate(prog, spindles=s)
    assert tw.engagement_cache.computations == 1
    fresh = mtwin.Twin().simulate(prog, spindles=s)
    assert b.summary.cycle_time == fresh.summary.cycle_time
    assert b.summary.cutting.cutting_energy == fresh.summary.cutting.cutting_energy
    np.testing.assert_array_equal(b.signal("spindle_power"), fresh.signal("spindle_power"))


def test_new_feeds_reuse_the_engagement_under_the_linuxcnc_planner():
    # the LinuxCNC planner's blend trims grow with the feed (same segments, other end points):
    # the engagement is keyed on the structure and the programmed geometry, so three feed
    # variants share one computation, and the result stays close to a fresh computation
    import mtwin
    from conftest import SAMPLES

    tw = mtwin.Twin.from_toml(str(SAMPLES / "machines" / "linuxcnc-sim.toml"))
    prog = tw.load(str(SAMPLES / "pocket.nc"))
    f = prog.records["feed"]
    plans = [tw.plan(prog, feeds=f * k) for k in (1.0, 1.2, 0.8)]
    assert any(not np.array_equal(plans[0].seg["p1"], p.seg["p1"]) for p in plans[1:])  # the trims do move
    for k in (1.0, 1.2, 0.8):
        tr = tw.simulate(prog, every=50, feeds=f * k)
    assert tw.engagement_cache.computations == 1
    fresh = mtwin.Twin.from_toml(tw.path).simulate(prog, every=50, feeds=f * 0.8)
    assert tr.summary.cutting.peak_load == pytest.approx(fresh.summary.cutting.peak_load, rel=0.02)
    assert tr.summary.cutting.cutting_energy == pytest.approx(fresh.summary.cutting.cutting_energy, rel=0.02)
