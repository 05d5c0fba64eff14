"""The cutting-data catalogue against its sources, its physics against closed forms, the
program-comment forms it reads, and the limits optimize takes from it (docs/catalogue.md)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import integrate

import mtwin
from mtwin.cutting import catalogue as C
from mtwin.cutting.library import Tool, cutting_from_dict
from mtwin.errors import ConfigError, MtwinError
from mtwin.optimize.run import OptimizeOptions, optimize

REAL = Path(__file__).resolve().parents[2] / "shared" / "realdata" / "gcode_corpus"


# ---------------------------------------------------------------------- values against their sources

# transcribed from the FreeCAD machining cards (UnitCuttingForce, ChipThicknessExponent) with
# the card's own arithmetic: book value x 1.2 / (1 - rake/100)
FREECAD = {  # key: (card, book kc1.1, rake deg, card value, mc)
    "steel1018": ("MildSteel", 1800, 6, 2298, 0.20),
    "steel4140": ("LowAlloySteel", 2200, 6, 2809, 0.24),
    "ss304": ("AusteniticStainlessSteel", 2000, 6, 2553, 0.20),
    "aluminium": ("AluminumWroughtAlloy", 470, 12, 641, 0.27),
    "cast_aluminium": ("AluminumCastAlloy", 680, 12, 927, 0.27),
    "grey_iron": ("GrayCastIron", 1050, 2, 1286, 0.23),
    "tool_steel": ("ToolSteel", 2500, 6, 3191, 0.27),
}


@pytest.mark.parametrize("key", sorted(FREECAD))
def test_kienzle_constants_are_the_cards(key):
    card, book, rake, value, mc = FREECAD[key]
    m = C.catalogue().materials[key]
    assert (m.kc11, m.mc) == (value, mc)
    assert card in m.kc_source
    # the card's value is the book's x 1.2 (milling) normalised to 0 deg rake, to the newton
    assert abs(book * 1.2 / (1 - rake / 100) - value) <= 1.0


def test_wood_and_chip_loads_are_the_published_figures():
    cat = C.catalogue()
    assert (cat.materials["mdf"].kc11, cat.materials["mdf"].mc) == (31.25, 0.5)  # MDF.FCMat: 25 / (1 - 20/100)
    assert cat.materials["hardwood"].kc11 == 52.5  # HardWood.FCMat: 42 / (1 - 20/100)
    # ATA 2022 p. 1301, solid carbide, feed per tooth (mm)
    assert [C.chip_load("steel1045", d) for d in (3, 6, 10, 20)] == [0.01, 0.04, 0.08, 0.12]
    assert [C.chip_load("ss304", d) for d in (6, 10, 20)] == [0.025, 0.05, 0.08]
    assert C.chip_load("ti6al4v", 6) == 0.025  # titanium < 1100 N/mm²: the stainless row
    assert [C.chip_load("al6061", d) for d in (6, 12, 20)] == [0.04, 0.12, 0.16]
    assert C.chip_load("hardened_steel", 6) == 0.015
    # AST Tooling router bits, lower end in inches: MDF 1/4" .012, hardwood 1/2" .017
    assert C.chip_load("mdf", 6.35) == pytest.approx(0.012 * 25.4)
    assert C.chip_load("hardwood", 12.7) == pytest.approx(0.017 * 25.4)
    # between the published diameters linear, below the smallest proportional, above constant
    assert C.chip_load("steel1045", 7.0) == pytest.approx(0.05)
    assert C.chip_load("steel1045", 1.5) == pytest.approx(0.005)
    assert C.chip_load("steel1045", 32.0) == 0.12
    assert C.chip_load("steel1045", 6.0, "hss") == pytest.approx(0.02)
    # every value names a source that the catalogue spells out
    for m in cat.materials.values():
        assert cat.source_text(m.kc_source) != m.kc_source or m.kc_source in cat.sources
    for row in cat.chips.values():
        assert row.source in cat.sources and list(row.diameter) == sorted(row.diameter)


def test_names_resolve_and_an_unknown_one_lists_the_known():
    for name, key in [("4140", "steel4140"), ("42CrMo4", "steel4140"), ("AL6061", "al6061"), ("6061-T6", "al6061"),
                      ("Al 6061", "al6061"), ("SS304", "ss304"), ("MDF", "mdf"), ("Plexiglas", "acrylic"),
                      ("mild_steel", "steel1018"), ("ti64", "ti6al4v")]:
        assert C.find(name) == key, name
    with pytest.raises(ConfigError, match="catalogue knows: al6061.*mdf"):
        C.resolve("unobtainium")
    with pytest.raises(ConfigError, match="cutting.material"):
        cutting_from_dict({"cutting": {"material": "unobtainium"}})
    assert cutting_from_dict({"cutting": {"material": "304"}}).material_name == "ss304"


def test_kienzle_line_follows_the_curve_over_the_fitted_chips():
    for key in ("steel1045", "ss304", "aluminium", "mdf", "acrylic"):
        m = C.catalogue().materials[key]
        lo, hi = C.fit_range(key)
        ktc, kte = C.kienzle_linear(m.kc11, m.mc, (lo, hi))
        for h in np.geomspace(2 * lo, hi, 25):
            assert (ktc * h + kte) / (m.kc11 * h ** (1 - m.mc)) == pytest.approx(1.0, abs=0.09), (key, h)
        co = C.material_coefficients(key)
        assert (co.ktc, co.kte, co.krc) == pytest.approx((ktc, kte, 0.5 * ktc))


# ---------------------------------------------------------------------- the shank as a cantilever

def test_shank_stress_and_deflection_against_the_cantilever():
    tool = Tool(diameter=6.0, stickout=30.0)
    d, L, E = 0.8 * 6.0, 30.0, 600000.0
    inertia = math.pi * d ** 4 / 64
    F = 100.0
    # stress at the fixed end: M·c/I with M = F·L, c = d/2
    assert C.bending_stress(tool, F) == pytest.approx(F * L * (d / 2) / inertia)
    # deflection by integrating the curvature M(x)/EI twice along the beam (Euler-Bernoulli)
    slope = lambda x: integrate.quad(lambda s: F * (L - s) / (E * inertia), 0, x)[0]  # noqa: E731
    tip = integrate.quad(slope, 0, L)[0]
    assert C.deflection(tool, F) == pytest.approx(tip, rel=1e-6)
    # the breaking force brings the stress to the allowed share of the strength
    assert C.bending_stress(tool, C.breaking_force(tool)) == pytest.approx(0.5 * 2413.0)
    # stick-out not given: 4 x D; a 3 mm carbide tool then takes 136 N
    assert C.stickout(Tool(diameter=3.0)) == 12.0
    assert C.breaking_force(Tool(diameter=3.0)) == pytest.approx(136.45, abs=0.05)
    # HSS is less stiff: E 207 against 600 GPa
    assert C.stiffness(Tool(diameter=6.0, material="hss")) == pytest.approx(C.stiffness(Tool(diameter=6.0)) * 207 / 600)


SLOT_4140 = """(MATERIAL: 4140)
(T1 D=3 CR=0 - flat end mill)
G21 G90 G17
T1 M6
S6000 M3
G0 X-5 Y10 Z5
G0 Z{depth}
G1 X60 F720
G0 Z5
M30
"""


def test_a_slot_that_breaks_a_3mm_end_mill_in_4140_is_reported_and_lowered():
    tw = mtwin.Twin()
    stock = (0, 0, -10, 60, 20, 0)
    prog = tw.load(SLOT_4140.format(depth=-1).encode(), path="slot.nc")
    tr = tw.simulate(prog, stock=stock)
    s = tr.summary.cutting
    assert s.material == "steel4140"
    check = s.shank[0]
    assert check["tool"] == 1 and check["over"] and check["stress"] > check["allowed_stress"]
    assert any("shank is overloaded" in w and "slot.nc:8:" in w for w in tr.summary.warnings)
    r = optimize(tw, prog, OptimizeOptions(), stock=stock)
    assert r.after.peak_load <= C.breaking_force(Tool(diameter=3.0)) * 1.01
    assert r.after.peak_load < r.before.peak_load
    assert r.slower_because and r.slower_because[0]["tool"] == 1
    # the same slot 3 mm deep: over the limit even at the lowest feed: refused, nothing written
    deep = tw.load(SLOT_4140.format(depth=-3).encode(), path="deep.nc")
    with pytest.raises(MtwinError, match="shank would break"):
        optimize(tw, deep, OptimizeOptions(), stock=stock)


# ---------------------------------------------------------------------- read from the program

TITLE = """O1001 (POCKET 40X30 DEPTH 2 - 6MM 2FL CARBIDE - AL6061)
(STOCK: X0 Y0 Z-10 TO X60 Y50 Z0)
G21 G90 G17
T1 M6
S8000 M3
G0 X10 Y10 Z5
G1 Z-2 F200
G1 X50 F800
G1 Y40
G1 X10
G1 Y10
G0 Z5
M30
"""


def test_title_comment_gives_tool_material_and_stock():
    tw = mtwin.Twin()
    tr = tw.simulate(tw.load(TITLE.encode(), path="title.nc"))
    s = tr.summary.cutting
    assert s.material == "al6061"
    assert s.stock == [0, 0, -10, 60, 50, 0] and "STOCK" in s.stock_source and "line 2" in s.stock_source
    assert s.tools[0]["diameter"] == 6.0 and s.tools[0]["flutes"] == 2 and s.tools[0]["line"] == 1
    assert any("material: al6061" in d and "line 1" in d for d in s.defaults)
    # --material stands over the comment
    tr = tw.with_material("ss304").simulate(tw.load(TITLE.encode(), path="title.nc"))
    assert tr.summary.cutting.material == "ss304"
    assert tr.summary.cutting.peak_load > 3 * s.peak_load


def _warnings(text: str, tmp_path) -> list:
    from mtwin.twin.setup import Messages, load_part

    f = tmp_path / "p.nc"
    f.write_text(text)
    msgs = Messages()
    load_part(mtwin.Twin(), str(f), msgs)
    return [w.replace(str(f), "p.nc") for w in msgs.warnings]


def test_malformed_forms_are_warnings_with_their_place_not_guesses(tmp_path):
    from mtwin.cutting.workpiece import read_workpiece

    w = _warnings("(MATERIAL: UNOBTAINIUM)\n" + TITLE, tmp_path)
    assert any(x.startswith("p.nc:1:12: warning: material 'UNOBTAINIUM'") for x in w), w
    two = "(MATERIAL: 304)\n(MATERIAL: 6061)\n" + TITLE.split("\n", 1)[1]
    assert any("p.nc:2:" in x and "two materials" in x for x in _warnings(two, tmp_path))
    assert read_workpiece(mtwin.Twin().load(two.encode(), path="p.nc")).material is None
    # Mastercam's header: the alloy number wins over the family name
    mc = "(MATERIAL - ALUMINUM MM - 2024)\n" + TITLE.split("\n", 1)[1]
    assert read_workpiece(mtwin.Twin().load(mc.encode(), path="p.nc")).material.value == "aluminium"


@pytest.mark.skipif(not REAL.exists(), reason="../shared/realdata not beside the checkout")
def test_real_programs_forms():
    from mtwin.cutting.workpiece import read_workpiece

    tw = mtwin.Twin()
    # Newfangled Wizard: (Program Posted for Aluminum )
    wp = read_workpiece(tw.load(str(REAL / "pygcode_test_files" / "DB25.tap")))
    assert wp.material.value == "aluminium" and wp.material.form == "Program Posted for"
    # Vectric: ( Material Size ) ( X=96 mm, Y=120 mm, Z=6 mm ), placed to hold the toolpath
    prog = tw.load(str(REAL / "pygcode_test_files" / "Cross2.tap"))
    assert read_workpiece(prog).stock.value == (96.0, 120.0, 6.0)
    s = tw.simulate(prog).summary.cutting
    assert "Vectric MATERIAL SIZE" in s.stock_source
    # from the origin, top at Z0; the through-cut 0.25 mm into the spoilboard takes the bottom with it
    assert s.stock[:2] == [0.0, 0.0] and s.stock[3:] == [96.0, 120.0, 0.0] and s.stock[2] == -6.25
    # Fusion writes the program's name first: (1018) is not steel
    wp = read_workpiece(tw.load(str(REAL / "fusion360_led_floor" / "6mm" / "1018_puz_18_bit.nc")))
    assert wp.material is None


# ---------------------------------------------------------------------- options and limits

def test_limits_options_and_a_twin_files_per_tool_force_limit(tmp_path):
    tw = mtwin.Twin()
    plain = TITLE.replace(" - AL6061", "")
    prog = tw.load(plain.encode(), path="p.nc")
    with pytest.raises(MtwinError, match="--limits physics needs the work material"):
        optimize(tw, prog, OptimizeOptions(limits="physics"))
    with pytest.raises(MtwinError, match="--limit-scale"):
        OptimizeOptions(limit_scale=0.0)
    # no material named: the learned limits, as before
    r = optimize(tw, prog, OptimizeOptions())
    assert "learned" in [x for x in r.limits if x.get("tool") == 1][0]["source"]
    # the material named: physics, with sources
    r = optimize(tw.with_material("6061"), prog, OptimizeOptions())
    lim = [x for x in r.limits if x.get("tool") == 1][0]
    # (the program runs its 6 mm tool at 0.05 mm a tooth, over the chart's 0.04: its own level stands)
    assert lim["source"] == "physics" and lim["chip_thickness_catalogue"] == 0.04 and "ATA" in lim["chip_thickness_source"]
    assert lim["chip_thickness"] == pytest.approx(0.05, rel=0.02) and "own level" in lim["chip_thickness_source"]
    assert lim["load"] == pytest.approx(C.breaking_force(Tool(diameter=6.0)))
    # a scale of 0.8 takes 80 % of each
    r8 = optimize(tw.with_material("6061"), prog, OptimizeOptions(limit_scale=0.8))
    l8 = [x for x in r8.limits if x.get("tool") == 1][0]
    assert l8["load"] == pytest.approx(0.8 * lim["load"]) and l8["chip_thickness_catalogue"] == pytest.approx(0.032)
    # [tools.1] force_limit in the twin file is a given limit for that tool
    f = tmp_path / "t.toml"
    f.write_text('[tools.1]\ntype = "flat"\ndiameter = 6.0\nflutes = 2\nforce_limit = 30.0\n')
    tw2 = mtwin.Twin.from_toml(str(f))
    r = optimize(tw2, tw2.load(plain.encode(), path="p.nc"), OptimizeOptions())
    assert r.force_limit[1] == 30.0
    assert r.after.peak_load <= 30.0 * 1.01


CLEAR = """(T1 D=6 CR=0 - flat end mill)
G21 G90 G17
T1 M6
S8000 M3
G0 X-10 Y0 Z5
G0 X70 Y0
G0 X70 Y20
G0 X-10 Y20
G1 X70 Y20 Z5 F300
G0 X70 Y21
G1 X70 Y40 Z5 F300
G0 X-10 Y0
G1 Z0 F100
G1 X60 F300
G1 Y10
G1 X0
G0 Z5
M30
"""


def test_air_the_programs_own_rapids_prove_clear_goes_to_the_top_of_the_range():
    tw = mtwin.Twin()
    prog = tw.load(CLEAR.encode(), path="clear.nc")
    r = optimize(tw, prog, OptimizeOptions())
    out = r.output.decode().splitlines()
    src = CLEAR.splitlines()
    # line 9 runs where the program's own G0 at Z5 passed (line 8): raised to the top of the range
    assert out[8].startswith("G1 X70 Y20 Z5 F") and float(out[8].split("F")[1]) == tw.machine.max_cutting_feed
    # line 11 runs at Z5 where no rapid passed, the facing pass at Z0 under the rapids: kept
    assert out[10] == src[10] and out[13:16] == src[13:16]
    assert r.after.cycle_time < r.before.cycle_time
