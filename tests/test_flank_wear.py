"""The flank-wear law against its closed forms, and the effect in the twin."""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from mtwin.effects import ToolHistory
from mtwin.effects.wear import FlankWear, land, life, sliding_to

LAW = {"rate": 0.004, "break_in": 0.03, "sigma": 400.0, "mu": 0.5, "vb0": 0.0, "accel": 0.0}


def test_land_solves_the_archard_rate_equation():
    # dVB/ds = r (b/VB + 1): integrated independently (scipy, from a small land with its
    # break-in asymptote VB = sqrt(2 r b s)) against the closed-form inversion
    r, b = LAW["rate"], LAW["break_in"]
    s0 = 1e-6
    sol = solve_ivp(lambda s, y: r * (b / y + 1.0), (s0, 300.0), [math.sqrt(2 * r * b * s0)], rtol=1e-10,
                    atol=1e-12, dense_output=True)
    s = np.linspace(0.01, 300.0, 50)
    assert np.allclose(land(s, 0.0, LAW), sol.sol(s)[0], rtol=1e-5)


def test_break_in_then_steady_slope():
    r, b = LAW["rate"], LAW["break_in"]
    small = np.array([1e-4, 4e-4])
    # break-in: VB = sqrt(2 r b s) while VB << b
    assert np.allclose(land(small, 0.0, LAW), np.sqrt(2 * r * b * small), rtol=0.02)
    # steady zone: the slope tends to r once VB >> b
    s = np.array([400.0, 401.0])
    vb = land(s, 0.0, LAW)
    assert vb[1] - vb[0] == pytest.approx(r * (1 + b / vb.mean()), rel=1e-3)


def test_sliding_to_inverts_land_and_life_is_the_closed_form():
    r, b = LAW["rate"], LAW["break_in"]
    vb = land(np.array([5.0, 50.0, 120.0]), 0.05, LAW)
    assert np.allclose(sliding_to(vb, 0.05, LAW), [5.0, 50.0, 120.0], rtol=1e-8)
    # life to VB 0.3 mm (ISO 8688-2's criterion) from a new tool: (VB - b ln((b+VB)/b)) / r
    assert life(0.3, LAW) == pytest.approx((0.3 - b * math.log((b + 0.3) / b)) / r, rel=1e-12)


def test_accelerated_zone_against_quadrature():
    p = {**LAW, "accel": 8.0}
    s = np.linspace(1.0, 18.0, 12)  # (the land runs away at about 20 m: the accelerated zone's end)
    sol = solve_ivp(lambda s_, y: p["rate"] * (p["break_in"] / y + 1.0) * np.exp(p["accel"] * y), (0.0, 18.0),
                    [0.02], rtol=1e-10, atol=1e-12, dense_output=True)
    assert np.allclose(land(s, 0.02, p), sol.sol(s)[0], rtol=2e-4)
    # it grows faster than the steady law
    assert (land(s, 0.02, p) > land(s, 0.02, LAW)).all()
    assert land(np.array([40.0]), 0.02, p)[0] == 2.0  # past the run-away: the law's cap, a destroyed edge


def test_the_land_adds_smithey_edge_forces():
    class Steps:
        sliding = np.array([0.0, 10.0, 100.0])

    add = FlankWear(**LAW).cutting_add(Steps(), LAW)
    vb = land(Steps.sliding, 0.0, LAW)
    assert np.allclose(add[:, 4], LAW["sigma"] * vb)  # radial edge: sigma VB, N/mm
    assert np.allclose(add[:, 3], LAW["mu"] * LAW["sigma"] * vb)  # tangential: mu sigma VB
    assert not add[:, [0, 1, 2, 5]].any()  # the rake face (shear) and the axial edge are the sharp tool's


def test_wear_carries_from_part_to_part_in_the_twin():
    from mtwin.twin import Twin

    from conftest import SAMPLES

    tw = Twin.from_toml(None).with_effects(FlankWear(rate=0.002, break_in=0.02))
    prog = tw.load((SAMPLES / "pocket.nc").read_bytes(), path=str(SAMPLES / "pocket.nc"))
    first = tw.simulate(prog)
    use = first.tool_use[1]
    # the edge sliding of a slot: per mm of path, 1/(fz z) revolutions of R*pi engaged arc
    assert use.sliding > 0 and use.length > 0 and use.time > 0
    wear = first.summary.cutting.tool_wear[1]
    assert wear["vb_end"] == pytest.approx(float(land(use.sliding, 0.0, {**LAW, "rate": 0.002, "break_in": 0.02})),
                                           rel=0.02)
    # the 20th part starts where 19 have left the tool
    worn = tw.with_tool_state({1: use.times(19)}).simulate(prog)
    w20 = worn.summary.cutting.tool_wear[1]
    assert w20["sliding_before"] == pytest.approx(19 * use.sliding, rel=1e-9)
    p = {**LAW, "rate": 0.002, "break_in": 0.02}
    assert w20["vb_end"] == pytest.approx(float(land(20 * use.sliding, 0.0, p)), rel=0.01)
    assert worn.summary.cutting.mean_load > first.summary.cutting.mean_load
    assert float(worn.vb.max()) == pytest.approx(w20["vb_end"], rel=1e-5)
    assert ToolHistory(1, 2, 3, 4) + ToolHistory(1, 1, 1, 1) == ToolHistory(2, 3, 4, 5)
