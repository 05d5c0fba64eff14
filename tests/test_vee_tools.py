"""Vee tools (V-bits, engraving bits, chamfer mills) in the cutting model, against closed forms:
a straight groove at depth d removes a trapezoid (tip width + 2 d tan β, β the half angle),
and its revolution-averaged slotting torque is N/π · Ktc · f_z · ∫ r(z) dz with r = r_tip + z tan β
(the mechanistic model's h = f_z sin φ sin κ on an edge db = dz / sin κ, κ = β)."""
from __future__ import annotations

import math

import numpy as np
import pytest

import mtwin
from mtwin.cutting.library import Tool, cutting_from_dict, parse_tool_option
from mtwin.cutting.tool_comments import scan_tool_comments, to_library_tool
from mtwin.errors import ConfigError

DEPTH = 1.0
GROOVE = (f"G21 G90 G17 G94\n(MTWIN STOCK -10,-10,-10,60,10,0)\nT1 M6\nS8000 M3\nG0 X-5 Y0 Z5\nG0 Z-{DEPTH}\n"
          f"G1 X50 F600\nG0 Z5\nM5\nM30\n").encode()
KTC = 1230.0  # al6061, the default material (no edge terms)
FZ = 600.0 / (2 * 8000.0)


def _groove(spec: str):
    tw = mtwin.Twin().with_tools({1: spec})
    tr = tw.simulate(tw.load(GROOVE, path="groove.nc"))
    m = (tr.signal("x") > 15) & (tr.signal("x") < 35)
    return tr, m


@pytest.mark.parametrize("angle,tip", [(90.0, 0.0), (60.0, 0.2), (20.0, 0.5)])
def test_groove_mrr_width_and_torque_match_closed_forms(angle, tip):
    tr, m = _groove(f"vee:6.35:2:{angle}:{tip}")
    t = math.tan(math.radians(angle / 2))
    width = tip + 2 * DEPTH * t
    area = tip * DEPTH + DEPTH * DEPTH * t  # the trapezoid
    v = 600.0 / 60.0
    # (a 20° bit cuts a groove 0.85 mm wide: 16 cells of the 0.053 mm Z-map, 2.5 % in its area)
    assert np.median(tr.signal("mrr")[m]) == pytest.approx(area * v, rel=0.03)
    assert np.median(tr.signal("ae")[m]) == pytest.approx(width, rel=0.03)
    integral = 0.5 * tip * DEPTH + t * DEPTH * DEPTH / 2  # ∫ r(z) dz over the depth
    torque = 2 / math.pi * KTC * FZ * integral / 1000.0
    assert np.median(tr.signal("spindle_torque")[m]) == pytest.approx(torque, rel=0.03)


def test_a_flat_slot_by_the_same_route_matches_its_closed_form():
    # the reference the vee figures are measured against: a 2 mm flat end mill, full slot
    tr, m = _groove("flat:2:2")
    assert np.median(tr.signal("spindle_torque")[m]) == pytest.approx(2 / math.pi * KTC * FZ * 1.0 * DEPTH / 1000,
                                                                        rel=0.01)


def test_vee_tool_declarations():
    n, t = parse_tool_option("4=vee:6.35:2:60:0.2")
    assert n == 4 and t.type == "vee" and t.angle == 60 and t.tip_diameter == 0.2
    assert parse_tool_option("4=vee:6.35")[1].angle == 90.0
    for bad in ("4=vee:6.35:2:180", "4=vee:6.35:2:60:7", "4=flat:6:2:1", "4=bull:6:2"):
        with pytest.raises(ConfigError):
            parse_tool_option(bad)
    cut = cutting_from_dict({"tools": {"2": {"type": "vee", "diameter": 6.35, "angle": 30, "tip_diameter": 0.3}}})
    assert cut.tools[2].cot_half_angle == pytest.approx(1 / math.tan(math.radians(15)))
    with pytest.raises(ConfigError):
        cutting_from_dict({"tools": {"2": {"type": "vee", "diameter": 6.35, "angle": 200}}})
    assert Tool().cot_half_angle == 0.0 and Tool().tip_radius == 0.0


def test_comments_declare_vee_tools():
    r = scan_tool_comments(b"G20\n( TOOL=ENGRAVE {20' 0.02\" TIP DIA} )\nG0 Z0.1\nM30\n")
    t = to_library_tool(r.tools[0])
    assert t.type == "vee" and t.angle == 20 and t.tip_diameter == pytest.approx(0.508)
    r = scan_tool_comments(b"G20\n(60deg. 1/2\" V bit)\nG0 Z0.25\n")
    t = to_library_tool(r.tools[0])
    assert t.type == "vee" and t.angle == 60 and t.diameter == pytest.approx(12.7)
    # Fusion's TAPER is the half angle: a 45 deg taper chamfer mill is a 90 deg cone
    r = scan_tool_comments(b"G21\n(T2 D=6 CR=0. TAPER=45deg - ZMIN=0.05 - chamfer mill)\nT2 M6\n")
    assert to_library_tool(r.tools[2]).angle == 90
    # a V-bit whose angle nobody gives is not represented (its feeds are kept)
    r = scan_tool_comments(b"G21\n(T3 6mm V bit)\nT3 M6\n")
    assert not r.tools[3].modelled and to_library_tool(r.tools[3]) is None
