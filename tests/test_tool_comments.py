"""Tools declared in program comments (issue 9 point 4): each post-processor form on inline
comments (values exact, inch -> mm), tying descriptions to tool changes, merging and
conflicts, the library mapping, and the tools read from real programs in ../shared/realdata."""
from __future__ import annotations

import pytest

from conftest import REALDATA, realdata_files
from mtwin.cutting.library import Tool, cutting_from_dict
from mtwin.cutting.tool_comments import (
    KINDS, LETTER_DRILLS_IN, MAX_DIAMETER_MM, NUMBER_DRILLS_IN, DeclaredTool, Rejected, parse_tool_comment,
    scan_tool_comments, to_library_tool, to_tool_table, tools_from_comments,
)

IN = 25.4


def one(text, inch=False, **kw) -> DeclaredTool:
    t = parse_tool_comment(text, inch, **kw)
    assert isinstance(t, DeclaredTool), t
    return t


def rejected(text, inch=False) -> Rejected:
    r = parse_tool_comment(text, inch)
    assert isinstance(r, Rejected), r
    return r


# ---------------------------------------------------------------- Fusion 360

def test_fusion_flat_end_mill_mm():
    t = one("T1 D=6 CR=0 - ZMIN=-5 - flat end mill")
    assert (t.number, t.diameter_mm, t.corner_radius_mm, t.kind, t.flutes) == (1, 6.0, 0.0, "flat", None)
    assert t.form == "Fusion 360" and t.name == "flat end mill" and t.program_units


def test_fusion_two_spaces_and_decimals_as_in_the_led_floor_files():
    t = one("T1  D=2.7 CR=0 - ZMIN=-12.55 - flat end mill")
    assert (t.number, t.diameter_mm, t.kind) == (1, 2.7, "flat")


def test_fusion_inch_bullnose_ball_face():
    t = one("T2 D=0.5 CR=0.03 - ZMIN=-1 - bullnose end mill", inch=True)
    assert (t.kind, t.diameter_mm, t.corner_radius_mm) == ("bull", 12.7, pytest.approx(0.762))
    t = one("T3 D=10 CR=5 - ZMIN=-3 - ball end mill")
    assert (t.kind, t.diameter_mm, t.corner_radius_mm) == ("ball", 10.0, 5.0)
    t = one("T1 D=2. CR=0.125 - ZMIN=5.99 - FACE MILL", inch=True)  # uppercase post
    assert (t.kind, t.diameter_mm, t.corner_radius_mm) == ("face", 50.8, 3.175)


def test_fusion_taper_and_kinds_the_library_cannot_model():
    t = one("T2 D=0.25 CR=0. TAPER=45deg - ZMIN=0.05 - CHAMFER MILL", inch=True)
    assert (t.kind, t.diameter_mm, t.angle_deg) == ("chamfer", 6.35, 45.0)
    # a cone: the library's vee tool, Fusion's TAPER being the half angle
    assert t.modelled and (to_library_tool(t).type, to_library_tool(t).angle) == ("vee", 90.0)
    assert one("T4 D=3 CR=0 - ZMIN=-1 - spot drill").kind == "drill"
    assert one("T5 D=6 CR=0 - ZMIN=-9 - right hand tap").kind == "tap"
    assert one("T6 D=8 CR=0 - ZMIN=-9 - counter bore").kind == "other"
    assert one("T7 D=8 CR=0 - ZMIN=-9 - tapered mill").kind == "other"
    assert one("T8 D=8 CR=0 - ZMIN=-9 - reamer").kind == "reamer"


def test_fusion_needs_the_program_units():
    r = rejected("T1 D=6 CR=0 - ZMIN=-5 - flat end mill", inch=None)
    assert "units" in r.reason and r.number == 1


# ---------------------------------------------------------------- Mastercam

def test_mastercam_tool_table_pipe_form():
    t = one("T3| 1/2 FLAT ENDMILL|H0|XY STOCK TO LEAVE - -.0005|Z STOCK TO LEAVE - 0.", inch=True)
    assert (t.number, t.diameter_mm, t.kind, t.form, t.name) == (3, 12.7, "flat", "Mastercam tool table", "1/2 FLAT ENDMILL")
    t = one("T1|.093 FLAT ENDMILL|H0|XY STOCK TO LEAVE - -.0005|Z STOCK TO LEAVE - 0.", inch=True)
    assert t.diameter_mm == pytest.approx(0.093 * IN)
    t = one("T2| 1/2 BULL ENDMILL 0.125 RAD|H0|XY STOCK TO LEAVE - 0.|Z STOCK TO LEAVE - .0007", inch=True)
    assert (t.kind, t.diameter_mm, t.corner_radius_mm) == ("bull", 12.7, 3.175)
    t = one("T7| 1/2 SPOTDRILL|H0", inch=True)
    assert (t.kind, t.diameter_mm) == ("drill", 12.7)
    t = one("T5| NO. 33 DRILL|H0", inch=True)
    assert (t.kind, t.diameter_mm) == ("drill", pytest.approx(0.113 * IN))
    t = one("T3|6MM EM|H0", inch=True)
    assert (t.kind, t.diameter_mm, t.program_units) == ("flat", 6.0, False)


def test_mastercam_explicit_inch_holds_in_a_metric_program():
    t = one('T15|3" FACE MILL|H313', inch=False)
    assert (t.number, t.kind, t.diameter_mm, t.corner_radius_mm) == (15, "face", 76.2, None)


def test_mastercam_metric_name_in_an_inch_program_is_not_guessed():
    r = rejected("T5|   6. FLAT ENDMILL|H0", inch=True)
    assert r.number == 5 and "implausible" in r.reason and "152.4" in r.reason
    assert one("T5|   6. FLAT ENDMILL|H0", inch=False).diameter_mm == 6.0


def test_mastercam_pipe_form_with_a_tool_dia_field():
    t = one("T1 | 1/2 FLAT ENDMILL | H1 | D1 | WEAR COMP | TOOL DIA. - .5", inch=True)
    assert (t.number, t.diameter_mm, t.kind) == (1, 12.7, "flat")


def test_mastercam_mpfan():
    t = one("TOOL - 1 DIA. OFF. - 1 LEN. - 1 DIA. - .25", inch=True)
    assert (t.number, t.diameter_mm, t.kind, t.form) == (1, 6.35, "unspecified", "Mastercam MPFAN")
    t = one(" 1/16 FLAT ENDMILL TOOL - 1 DIA. OFF. - 1 LEN. - 1 DIA. - .0625", inch=True)
    assert (t.number, t.diameter_mm, t.kind) == (1, 1.5875, "flat")
    t = one(' TOOL - 6 2"  MITSUBISIHI FACE MILL    DIA. OFF. - 6  LEN. - 6  DIA. - 2. ', inch=True)
    assert (t.number, t.diameter_mm, t.kind) == (6, 50.8, "face")
    t = one(" 1/8 X 900 CHAMFER MILL TOOL - 14 DIA. OFF. - 14 LEN. - 14 TOOL DIA. - .125 ", inch=True)
    assert (t.number, t.diameter_mm, t.kind) == (14, 3.175, "chamfer")


def test_mastercam_mpfan_name_checked_against_the_diameter():
    # a metric tool name in an inch program: 6 (mm) = .2362 (in), accepted
    t = one("6. FLAT ENDMILL TOOL - 5 DIA. OFF. - 5 LEN. - 5 DIA. - .2362", inch=True)
    assert t.diameter_mm == pytest.approx(5.99948)
    r = rejected("1/2 FLAT ENDMILL TOOL - 3 DIA. OFF. - 3 LEN. - 3 DIA. - .25", inch=True)
    assert r.number == 3 and "12.7" in r.reason and "6.35" in r.reason


# ---------------------------------------------------------------- descriptions at a tool change

def test_mastercam_fanuc_descriptions_d2mi():
    t = one('1/4" DIA. X .032" RADIUS 2 FLUTE STUBBY BULLNOSE E.M.   ', inch=True)
    assert t.number is None and t.form == "description at tool change"
    assert (t.kind, t.diameter_mm, t.corner_radius_mm, t.flutes) == ("bull", 6.35, pytest.approx(0.8128), 2)
    t = one('1/2" DIA. 2 FLUTE STUBBY FULLERTON E.M.', inch=True)
    assert (t.kind, t.diameter_mm, t.flutes) == ("flat", 12.7, 2)
    assert (one('3" FACE MILL   ').kind, one('3" FACE MILL').diameter_mm) == ("face", 76.2)
    t = one('5/16" X 90\u00b0 SPOT DRILL', inch=True)
    assert (t.kind, t.diameter_mm, t.angle_deg) == ("drill", 7.9375, 90.0)
    assert one("LET. B DRILL", inch=True).diameter_mm == pytest.approx(LETTER_DRILLS_IN["B"] * IN)
    assert one("#30 DRILL", inch=True).diameter_mm == pytest.approx(NUMBER_DRILLS_IN[30] * IN)
    t = one('1/4"-20 ROLL FORM TAP', inch=True)
    assert (t.kind, t.diameter_mm) == ("tap", 6.35)
    assert (one('.2495" REAMER').kind, one('.2495" REAMER').diameter_mm) == ("reamer", pytest.approx(6.3373))
    assert one("5.75MM DRILL", inch=True).diameter_mm == 5.75
    t = one('1/4" 2 FLUTE E.M. WITH .020" X 45\u00b0 CHAMFERS', inch=True)
    assert (t.kind, t.diameter_mm, t.flutes) == ("chamfer", 6.35, 2)
    t = one('1/4" X .093" CORNER ROUNDING E.M.', inch=True)
    assert (t.kind, t.diameter_mm) == ("other", 6.35)


def test_other_posts_descriptions():
    t = one("Tool: 1/4 in Carbide End Mill", inch=False)  # CAMotics
    assert (t.kind, t.diameter_mm) == ("flat", 6.35)
    t = one("TOOL DIA. 3", inch=False)  # Newfangled Wizard (Mach3)
    assert (t.kind, t.diameter_mm, t.program_units) == ("unspecified", 3.0, True)
    t = one('TOOL: V-BIT {90 DEG 0.5"}', inch=True)  # Vectric
    assert (t.kind, t.diameter_mm, t.angle_deg) == ("engrave", 12.7, 90.0)
    t = one("Tool 2mm dia.", inch=True)
    assert (t.kind, t.diameter_mm) == ("unspecified", 2.0)
    t = one(" and Cutter is assumed to be a 10mm ball nose ", inch=False)
    assert (t.kind, t.diameter_mm, t.corner_radius_mm) == ("ball", 10.0, 5.0)
    t = one(" 0.0625 mill ", inch=True)  # M06 T7 ( 0.0625 mill ), CAMotics genes-encoder.ngc
    assert (t.kind, t.diameter_mm) == ("unspecified", 1.5875)
    t = one("1/4 FLAT ENDMILL", inch=True)  # bare size: program units
    assert (t.kind, t.diameter_mm, t.program_units) == ("flat", 6.35, True)
    assert one("1/4 FLAT ENDMILL", inch=False).diameter_mm == 0.25


def test_comments_that_are_not_tools():
    for text in ('ROUGH CONTOUR OF BOSSES TO .168 DEEP STEP LEFT OVER BY 1/2" E.M.', "Xcen=0 Ycen=0 Dia=10",
                 "SPOT 4X \u00d8.128 \u00b1.005 HOLES", 'DRILL 4X 1/4"-20 BOLT HOLES', "REV.", "2D Pocket tabs",
                 'Cutter does not descend more than 0.94" below top', "Tool one && Tool change", "T1 M6",
                 "t1 is for facing and left turning, t4 is threading tool, t9 parting", "CW-climb mill",
                 "1070_wall_27bit", "NIST_MTC_CRADA_PLATE-12", "Set units to Inches [G21 to set units to Millimeters]"):
        assert parse_tool_comment(text, True) is None, text


def test_ambiguous_descriptions_are_rejected():
    assert parse_tool_comment("for 1/8\"dia cutter or 'V' cutter", True) is None  # Alien.tap: not a declaration
    assert "alternatives" in rejected("T1 = 1/8\" end mill or V cutter", inch=True).reason
    assert "more than one size" in rejected("T2 = 1/4 3/8 end mill", inch=True).reason
    assert "units" in rejected("T2 = 1/4 end mill", inch=None).reason
    assert one("T2 = 6mm end mill", inch=None).diameter_mm == 6.0  # explicit unit needs no program units


def test_numbered_descriptions():
    t = one(" T1 = End Mill 4 mm ", inch=True)  # Vectric header list
    assert (t.number, t.kind, t.diameter_mm, t.form) == (1, "flat", 4.0, "numbered description")
    t = one("Tool 8 = .250 Vee bit", inch=True)
    assert (t.number, t.kind, t.diameter_mm) == (8, "engrave", 6.35)
    t = one("T1 6mm endmill", inch=True)
    assert (t.number, t.kind, t.diameter_mm) == (1, "flat", 6.0)
    t = one('tool 4 is 1" in diameter and must be defined in the tool table', inch=True)
    assert (t.number, t.kind, t.diameter_mm) == (4, "unspecified", 25.4)
    assert one("T3 = Ball Nose (1/4\")", inch=False).kind == "ball"
    assert "no diameter" in rejected("T1 = End Mill", inch=True).reason


def test_linuxcnc_tool_table_rows():
    t = one("5       5       -1.5042     0.5     1/2 end mill", inch=True)
    assert (t.number, t.kind, t.diameter_mm, t.form) == (5, "flat", 12.7, "LinuxCNC tool table")
    t = one("2       2       -0.2875     0.209   #4 tap drill", inch=True)
    assert (t.kind, t.diameter_mm) == ("drill", pytest.approx(0.209 * IN))
    r = rejected("15      15      -1.5042     0.55    same 1/2 end mill oversize roughing", inch=True)
    assert r.number == 15 and "13.97" in r.reason


# ---------------------------------------------------------------- whole programs

def test_description_tied_to_the_next_tool_change():
    prog = b"""%
O1001
N100 G20
( 3" FACE MILL   )
( REV. )
( ROUGH DATUM -A- SURFACE )
N102 T1
N103 G91 G28 Z0 M6
N104 T2 M01
N106 G0 G90 G54 X5.787 Y-3.4579 S10000 M3
( 1/2" DIA. 2 FLUTE STUBBY FULLERTON E.M.   )
( REV. )
( ROUGH CONTOUR TO .268 THICKNESS LEFT OVER BY 1/2" E.M. )
N146 T2
N147 G91 G28 Z0 M06
N148 G0 X1 Y1
"""
    r = scan_tool_comments(prog)
    assert r.inch is True and not r.rejected
    assert {n: (t.kind, t.diameter_mm, t.line) for n, t in r.tools.items()} == {
        1: ("face", 76.2, 4), 2: ("flat", 12.7, 11)}


def test_tie_on_the_same_block_after_the_change_and_to_a_prepared_tool():
    assert tools_from_comments(b"G21\nM6 T7(TOOL DIA. 3)\nG0 X1\n")[7].diameter_mm == 3.0
    t = tools_from_comments(b'G20\nN120T1M06\nN130(TOOL: V-BIT {90 DEG 0.5"})\nN140G00G43Z0.8H1\n')[1]
    assert (t.kind, t.diameter_mm) == ("engrave", 12.7)
    assert tools_from_comments(b'G20\nT2\n(1/4" FLAT ENDMILL)\nM6\nG0 X0\n')[2].diameter_mm == 6.35


def test_no_tie_across_motion_or_without_a_tool():
    r = scan_tool_comments(b'G20\n(1/4" FLAT ENDMILL)\nG1 X1 Y1 F10\nT1 M6\n')
    assert not r.tools and r.rejected[0].reason == "no tool selection next to it" and r.rejected[0].line == 2
    # a program that selects no tool at all (a router's hand-changed bit): its one description
    # is the spindle's tool, T0 to the interpreter (Vectric's "Letter A (V-Carve)")
    r = scan_tool_comments(b'G20\n(60deg. 1/2" V bit)\nG0 Z0.25\n')
    assert r.tools[0].kind == "engrave" and r.tools[0].diameter_mm == pytest.approx(12.7) and not r.rejected
    r = scan_tool_comments(b"G21\n(Tool 2mm dia.)\nM06 T0\n")
    assert not r.tools and r.rejected[0].reason == "T0 is no tool"


def test_vectric_forms():
    # pygcode's Vectric programs: a name and a labelled diameter; an engraving bit's angle and tip
    r = scan_tool_comments(b"G20\n(Endmill Dia. 0.250)\nG0 Z0.1\nG1 Z-0.01 F24\nM30\n")
    t = r.tools[0]
    assert t.kind == "flat" and t.diameter_mm == pytest.approx(6.35) and t.form == "Vectric"
    r = scan_tool_comments(b"G20\n( TOOL=ENGRAVE {20' 0.02\" TIP DIA} )\nG0 Z0.1\nG1 Z-0.01 F24\nM30\n")
    t = r.tools[0]
    assert t.kind == "engrave" and t.angle_deg == 20.0 and t.diameter_mm == pytest.approx(0.508)
    assert t.modelled  # a cone of known angle and tip: the library's vee tool
    assert parse_tool_comment("Note Dia 3", True, None, 1) is None  # no tool kind named: not a tool


def test_tool_selected_by_a_parameter():
    prog = b"(Cutter is assumed to be a 10mm ball nose)\n#<toolno> = 1\nN50T#<toolno>M6\nG0 X0\n"
    assert tools_from_comments(prog, inch=False)[1].kind == "ball"
    twice = prog.replace(b"N50", b"#<toolno> = 2\nN50")
    r = scan_tool_comments(twice, inch=False)
    assert not r.tools and "expression" in r.rejected[0].reason


def test_header_and_tool_change_declarations_merge_when_they_agree():
    prog = b"""(T1 D=6.35 CR=0 - ZMIN=-5 - flat end mill)
G21
(1/4" 2 FLUTE E.M.)
T1 M6
G0 X0
"""
    t = tools_from_comments(prog)[1]
    assert (t.form, t.line, t.diameter_mm, t.kind, t.flutes, t.also) == ("Fusion 360", 1, 6.35, "flat", 2, (3,))
    prog = b"( T7 = End Mill 3 mm )\nG21\nM6 T7(TOOL DIA. 3)\n"
    t = tools_from_comments(prog)[7]
    assert (t.kind, t.diameter_mm) == ("flat", 3.0)


def test_conflicting_declarations_leave_the_tool_out():
    prog = b"""(T1 D=6 CR=0 - ZMIN=-5 - flat end mill)
G21
(1/2" E.M.)
T1 M6
G0 X0
(T2 D=6 CR=0 - ZMIN=-5 - flat end mill)
(T2 D=6 CR=0 - ZMIN=-5 - ball end mill)
"""
    r = scan_tool_comments(prog)
    assert r.tools == {}
    assert [(j.number, j.line) for j in r.rejected] == [(1, 1), (2, 6)]
    assert "declared differently" in r.rejected[0].reason and "12.7" in r.rejected[0].reason


def test_pycam_settings_block():
    prog = b""";PYCAM_TOOLPATH_SETTINGS: START
;[Tool]
;torus_radius = 0.25
;shape = ToroidalCutter
;tool_radius = 3.0
;
;PYCAM_TOOLPATH_SETTINGS: END
G21
T4 M6
"""
    t = tools_from_comments(prog)[4]
    assert (t.kind, t.diameter_mm, t.corner_radius_mm, t.form, t.line) == ("bull", 6.0, 0.25, "PyCAM settings", 2)


def test_latin1_and_utf8_degree_signs_and_semicolon_comments():
    t = tools_from_comments(b'G20\n( 5/16" X 90\xb0 SPOT DRILL   )\r\nN295 T8\r\n')[8]
    assert (t.kind, t.angle_deg) == ("drill", 90.0)
    t = tools_from_comments('G20\n( 5/16" X 90° SPOT DRILL )\nT8\n'.encode())[8]
    assert t.angle_deg == 90.0
    assert tools_from_comments(b"G21\n;T3 = End Mill 4 mm\n")[3].diameter_mm == 4.0


def test_units_detected_or_given():
    prog = b"(T1 D=0.25 CR=0 - ZMIN=-1 - flat end mill)\nG20\nT1 M6\n"
    assert tools_from_comments(prog)[1].diameter_mm == 6.35
    assert tools_from_comments(prog, inch=False)[1].diameter_mm == 0.25
    r = scan_tool_comments(b"(T1 D=6 CR=0 - ZMIN=-1 - flat end mill)\nT1 M6\n")
    assert r.inch is None and not r.tools and "units" in r.rejected[0].reason


# ---------------------------------------------------------------- library mapping

def test_to_library_tool():
    base = Tool(helix=45.0)
    t = to_library_tool(one("T1 D=8 CR=0 - ZMIN=-5 - flat end mill"), base)
    assert (t.type, t.diameter, t.corner_radius, t.flutes, t.helix) == ("flat", 8.0, 0.0, 2, 45.0)
    t = to_library_tool(one("T1 D=8 CR=4 - ZMIN=-5 - ball end mill"))
    assert (t.type, t.diameter, t.nose_radius) == ("ball", 8.0, 4.0)
    t = to_library_tool(one('1/4" DIA. X .032" RADIUS 2 FLUTE STUBBY BULLNOSE E.M.', inch=True))
    assert (t.type, t.diameter, t.corner_radius, t.flutes) == ("bull", 6.35, pytest.approx(0.8128), 2)
    t = to_library_tool(one('3" FACE MILL'))
    assert (t.type, t.diameter) == ("flat", 76.2)
    t = to_library_tool(one("T1 D=2. CR=0.125 - ZMIN=5.99 - FACE MILL", inch=True))
    assert (t.type, t.diameter, t.corner_radius) == ("bull", 50.8, 3.175)
    assert to_library_tool(one("T1 D=6 CR=0 - ZMIN=-5 - bullnose end mill")).type == "flat"
    t = one("T1 = 1/2 FLAT ENDMILL 0.03 RAD", inch=True)  # a "flat" end mill with a corner radius
    assert (t.kind, t.corner_radius_mm) == ("bull", 0.762)
    assert to_library_tool(t).corner_radius == 0.762


def test_kinds_the_library_cannot_model_say_so():
    # (a V-bit or chamfer mill without an angle; a chamfer angle that could be half or whole)
    for text in ("#30 DRILL", "1/4\"-20 ROLL FORM TAP", ".2495\" REAMER", "1/4\" X 60\u00b0 CHAMFER MILL",
                 "Tool 8 = .250 Vee bit", "1/4\" X .093\" CORNER ROUNDING E.M.", "T1 = 1/2 bull end mill"):
        t = one(text, inch=True)
        assert not t.modelled and to_library_tool(t) is None and to_tool_table(t) is None, text
    t = one("TOOL DIA. 3")
    assert to_library_tool(t) is None
    assert to_library_tool(t, unspecified_as_flat=True).diameter == 3.0


def test_tool_table_entries_pass_the_twin_file_validation():
    decl = [one("T1 D=8 CR=0 - ZMIN=-5 - flat end mill"), one("T2 D=8 CR=4 - ZMIN=-5 - ball end mill"),
            one("T3 D=10 CR=1 - ZMIN=-5 - bullnose end mill"), one("T4| 1/2 FLAT ENDMILL|H0", inch=True),
            one('1/2" DIA. 2 FLUTE STUBBY FULLERTON E.M.', inch=True, number=5)]
    table = {str(t.number): to_tool_table(t) for t in decl}
    cut = cutting_from_dict({"tools": table})
    for t in decl:
        assert cut.tools[t.number] == to_library_tool(t)
    assert cut.tools[5].flutes == 2


# ---------------------------------------------------------------- real programs

def need(rel: str):
    path = REALDATA / rel
    if not REALDATA.is_dir():
        pytest.skip(f"{REALDATA} not present (real programs live in ../shared)")
    if not path.is_file():
        pytest.skip(f"{path} not present")
    return path.read_bytes()


def summary(tools):
    return {n: (round(t.diameter_mm, 4), t.kind) for n, t in tools.items()}


def test_real_fusion360():
    data = need("gcode_corpus/fusion360_led_floor/1070_wall_27bit.nc")
    r = scan_tool_comments(data)
    assert r.inch is False and summary(r.tools) == {1: (2.7, "flat")} and not r.rejected
    assert r.tools[1].line == 2 and r.tools[1].form == "Fusion 360"
    data = need("gcode_corpus/fusion360_led_floor/1071_surface_40mm_10overlap.nc")
    assert summary(tools_from_comments(data)) == {1: (40.0, "face")}
    data = need("gcode_corpus/fanuc_macroB_and_fusion_cnc_sprayer/fusion-fully-working.tap")
    t = tools_from_comments(data)[1]
    assert (t.kind, t.diameter_mm, t.corner_radius_mm) == ("face", 50.8, 3.175)
    # mm values under G20 (an edited file): D=152.4 would be a 3.9 m face mill, not taken
    r = scan_tool_comments(need("gcode_corpus/fanuc_macroB_and_fusion_cnc_sprayer/fusion-output.nc"))
    assert not r.tools and "implausible" in r.rejected[0].reason


def test_real_mastercam_hurco_plate():
    data = need("nist_smstestbed_mtc_hurco/NC-Code/NIST_MTC_CRADA_PLATE-12.NC")
    r = scan_tool_comments(data)
    assert r.inch is True and not r.rejected
    assert summary(r.tools) == {1: (2.3622, "flat"), 3: (12.7, "flat"), 4: (6.35, "flat"), 5: (3.175, "flat"),
                                7: (12.7, "drill"), 15: (76.2, "face"), 23: (3.175, "drill")}
    assert {t.form for t in r.tools.values()} == {"Mastercam tool table"}
    assert r.tools[15].line == 4 and r.tools[15].comment == 'T15|3" FACE MILL|H313'


def test_real_mastercam_hurco_box_metric_names_are_left_out():
    r = scan_tool_comments(need("nist_smstestbed_mtc_hurco/NC-Code/NIST_MTC_CRADA_BOX_REV-A OP1 (Bottom).NC"))
    assert summary(r.tools) == {1: (19.05, "flat"), 2: (12.7, "bull"), 21: (3.175, "drill")}
    assert r.tools[2].corner_radius_mm == 3.175
    assert [(j.number, j.line) for j in r.rejected] == [(5, 5)] and "6. FLAT ENDMILL" in r.rejected[0].comment


def test_real_mastercam_fanuc_d2mi():
    r = scan_tool_comments(need("nist_smstestbed_d2mi_gcode/827-9999-904, OP1.NC"))
    assert r.inch is True and not r.rejected
    assert summary(r.tools) == {
        1: (76.2, "face"), 2: (12.7, "flat"), 3: (6.35, "flat"), 4: (6.35, "bull"), 5: (6.35, "chamfer"),
        6: (6.35, "drill"), 7: (3.2639, "drill"), 8: (7.9375, "drill"), 9: (6.0452, "drill"),
        10: (6.3627, "reamer"), 11: (7.1437, "drill")}
    assert r.tools[4].corner_radius_mm == pytest.approx(0.8128) and r.tools[4].flutes == 2
    assert r.tools[2].line == 67 and r.tools[2].form == "description at tool change"


def test_real_other_posts():
    t = tools_from_comments(need("gcode_corpus/linuxcnc_nc_files/3D_Chips.ngc"))
    assert summary(t) == {1: (10.0, "ball")}
    t = tools_from_comments(need("gcode_corpus/camotics_examples/botomata_bottom.nc"))
    assert summary(t) == {1: (6.35, "flat"), 2: (3.175, "flat"), 3: (1.5875, "flat")}
    t = tools_from_comments(need("gcode_corpus/camotics_examples/tiny_cat_outline.ngc"))
    assert summary(t) == {1: (1.5875, "flat")} and t[1].form == "PyCAM settings"
    t = tools_from_comments(need("gcode_corpus/pygcode_test_files/Cross2.tap"))
    assert summary(t) == {1: (4.0, "flat")} and t[1].form == "numbered description"
    assert summary(tools_from_comments(need("gcode_corpus/pygcode_test_files/DB25.tap"))) == {7: (3.0, "unspecified")}
    r = scan_tool_comments(need("gcode_corpus/linuxcnc_nc_files/mmount.ngc"))
    assert summary(r.tools) == {2: (5.3086, "drill"), 3: (3.5712, "drill"), 4: (6.35, "flat"), 5: (12.7, "flat"),
                                6: (6.35, "tap")}
    assert sorted(j.number for j in r.rejected) == [1, 15]


def test_every_real_program_scans_and_every_tool_is_sane():
    files = realdata_files()
    if not files:
        pytest.skip(f"{REALDATA} not present (real programs live in ../shared)")
    with_tools = n_tools = 0
    for path in files:
        r = scan_tool_comments(path.read_bytes())
        for n, t in r.tools.items():
            # T0: the one tool of a program that selects none (a router's spindle)
            assert n == t.number and (n > 0 or set(r.tools) == {0}) and t.kind in KINDS, (path, t)
            assert 0 < t.diameter_mm <= MAX_DIAMETER_MM.get(t.kind, MAX_DIAMETER_MM["default"]), (path, t)
            if t.modelled:
                assert to_library_tool(t) is not None, (path, t)
        with_tools += bool(r.tools)
        n_tools += len(r.tools)
    assert with_tools >= 150 and n_tools >= 300, (with_tools, n_tools)
