"""Tools a program declares in its comments.

CAM post-processors describe each tool in a comment.  This module reads those
descriptions so that a program can be simulated with the tools it says it uses
instead of the default 6 mm flat end mill.  It reads; it does not wire anything into
the simulator (``to_library_tool`` gives the ``library.Tool`` of one declaration).

Forms recognised (``DeclaredTool.form``), with the real programs they were seen in
(``../shared/realdata``):

``Fusion 360``
    ``(T1  D=2.7 CR=0 - ZMIN=-13.3 - flat end mill)``, ``(T2 D=0.25 CR=0. TAPER=45deg -
    ZMIN=0.05 - chamfer mill)``.  D, CR in program units; the tool type names are
    Fusion's (``flat end mill``, ``ball end mill``, ``bullnose end mill``, ``face mill``,
    ``chamfer mill``, ``spot drill`` ...).  Seen: gcode_corpus/fusion360_led_floor/**,
    fanuc_macroB_and_fusion_cnc_sprayer/fusion-output.nc, fusion-fully-working.tap.
``Mastercam tool table``
    ``(T3| 1/2 FLAT ENDMILL|H0|XY STOCK TO LEAVE - -.0005|...)``: the tool's name, whose
    leading size is in program units unless it carries a unit (``3" FACE MILL``).
    An optional ``TOOL DIA. - .5`` field is the diameter.  Seen: nist_smstestbed_mtc_hurco.
``Mastercam MPFAN``
    ``( 1/16 FLAT ENDMILL TOOL - 1 DIA. OFF. - 1 LEN. - 1 DIA. - .0625)``,
    ``(TOOL - 1 DIA. OFF. - 1 LEN. - 1 DIA. - .25)``: ``DIA. -`` is the diameter in
    program units; the name, if any, gives the kind.  Not in the corpus (unit tests only).
``LinuxCNC tool table``
    ``(5       5       -1.5042     0.5     1/2 end mill)``: a row of the old LinuxCNC tool
    table (pocket, tool, length, diameter, comment) copied into a comment; diameter in
    program units.  Seen: gcode_corpus/linuxcnc_nc_files/mmount.ngc.
``PyCAM settings``
    ``;[Tool]`` ... ``;shape = CylindricalCutter`` ``;tool_radius = 0.79375``
    (``torus_radius`` for ``ToroidalCutter``), program units; tied to the tool
    selection next to it.  Seen: gcode_corpus/camotics_examples/tiny_cat_outline.ngc.
``numbered description``
    A tool number then a description: ``( T1 = End Mill 4 mm )`` (Vectric),
    ``(Tool 8 = .250 Vee bit)``, ``(tool 4 is 1" in diameter ...)``.  Seen:
    pygcode_test_files/Cross2.tap, Heart.tap, Smiley face.tap; linuxcnc_nc_files/comp-g1.ngc.
``description at tool change``
    A description without a tool number, tied to the tool selection next to it (see
    below): ``( 1/4" DIA. 2 FLUTE STUBBY FULLERTON E.M. )`` before ``N669 T3`` (Mastercam,
    nist_smstestbed_d2mi_gcode), ``(Tool: 1/4 in Carbide End Mill)`` before ``T1 M6``
    (camotics_examples/botomata_bottom.nc), ``M6 T7(TOOL DIA. 3)`` (pygcode DB25.tap,
    Circular Pocket.tap), ``N120T1M06`` then ``N130(TOOL: V-BIT {90 DEG 0.5"})``
    (Chucks Deer), ``M06 T7 ( 0.0625 mill )`` (camotics_examples/genes-encoder.ngc; a bare
    ``mill``/``cutter``/``bit`` is a cutter of unstated shape, ``unspecified``), ``(Tool 2mm
    dia.)`` (Tweakie's CNC Cube), ``( and Cutter is assumed to
    be a 10mm ball nose )`` before ``N50T#<toolno>M6`` (linuxcnc_nc_files/3D_Chips.ngc).
    A description must start with its size (after an optional ``Tool:``), or say
    ``cutter/tool is (assumed to be) a <size>``, so operation comments such as
    ``( ROUGH CONTOUR ... LEFT OVER BY 1/2" E.M. )`` are not read as tools.

Sizes: ``1/4``, ``1-1/4``, ``.093``, ``6.``, with ``"``, ``in``, ``inch``, ``mm`` or bare
(bare = the program's units, ``inch``).  ``#30`` and ``LET. B`` drills are read from the
standard number/letter drill tables.  Beside the diameter a description may give flutes
(``2 FLUTE``), a corner radius (``X .032" RADIUS``, ``0.125 RAD``, ``CR=``), an angle
(``X 90°``, ``90 DEG``, ``TAPER=45deg``); thread pitches (``1/4"-20``), lengths
(``3/4 LOC``), counts (``4X``) and features (``WITH .020" X 45° CHAMFERS``) are skipped.

Never guessed:

* a description with two sizes that cannot be told apart, or none, gives no tool;
* a labelled diameter (``D=``, ``DIA. -``, the table column) that disagrees with the size
  in the name gives no tool (``(15 15 -1.5042 0.55 same 1/2 end mill oversize roughing)``:
  0.55 is a cutter-compensation diameter, not the cutter's).  A bare name size that
  agrees once read in the other unit system is accepted (a metric ``6. FLAT ENDMILL`` in
  an inch program whose ``DIA. - .2362``);
* a diameter beyond ``MAX_DIAMETER_MM`` for its kind gives no tool (``(T5| 6. FLAT
  ENDMILL|H0)`` in an inch program would be a 152.4 mm end mill: the name is metric,
  but nothing in the program says so);
* a description that no tool selection can be tied to gives no tool;
* bare numbers when the program's units are unknown give no tool.

One tool number, several declarations (a header list and a comment at the tool change,
e.g. Fusion's header line and a description before ``T1 M6``): the library keeps one
entry per tool number (``Cutting.tools``), so they are merged.  The most exact form wins
(a labelled diameter field over a size read from a name; then the first in the file)
and the others must agree with it (diameter within 0.01 mm + 0.5 %, same kind unless one
is ``unspecified``); they may add what it lacks (flutes, kind).  If they disagree the
tool is left out and the reason recorded: a disagreement means a typo or a tool number
reused for a different cutter (manual tool change on a router), and taking "the comment
nearest the tool change" would silently simulate the rest of the program with the wrong
cutter.

Tying a description without a number to a tool: the T word on the comment's own block;
else the first T word after it, provided no motion block (X/Y/Z/A/B/C/U/V/W words outside
G10/G28/G30/G53/G92) comes first (an ``M6`` met first means the tool prepared before
the comment); else, going back with no motion in between, the last tool change (``M6``)
before it.  ``T#<name>`` / ``T#n`` is resolved when the parameter is assigned a literal
exactly once in the file.  ``T0`` (no tool) is never a tool.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, replace
from fractions import Fraction

from ..units import MM_PER_INCH
from .library import Tool

KINDS = ("flat", "ball", "bull", "face", "unspecified", "drill", "tap", "reamer", "chamfer", "engrave", "other")
"""flat/ball/bull/face (and, on request, unspecified) map onto the library's tool shapes;
the rest (drills, taps, reamers, chamfer mills and countersinks, V-bits, and ``other``:
corner-rounding, slot, dovetail, lollipop, thread mills, boring bars, counterbores,
probes ...) cannot be modelled by the flat/ball/bull Z-map cutter."""

MODELLED_KINDS = ("flat", "ball", "bull", "face")
VEE_KINDS = ("engrave", "chamfer")  # cones: the library's vee tool, when the angle is given
ENGRAVE_BODY_MM = 3.175  # [E] an engraving bit whose comment gives only its tip: a 1/8" shank

MAX_DIAMETER_MM = {"face": 320.0, "default": 80.0}
"""Plausibility bounds [E]: face mills up to ~12", any other cutter up to 80 mm."""

FORM_RANK = {  # how exact a form is: a labelled diameter field beats a size in a name
    "Fusion 360": 2,
    "Mastercam MPFAN": 2,
    "LinuxCNC tool table": 2,
    "PyCAM settings": 2,
}

# Standard twist-drill sizes, inches (ASME B94.11M): number drills #1-#80, letter drills A-Z.
NUMBER_DRILLS_IN = {
    1: 0.228, 2: 0.221, 3: 0.213, 4: 0.209, 5: 0.2055, 6: 0.204, 7: 0.201, 8: 0.199, 9: 0.196,
    10: 0.1935, 11: 0.191, 12: 0.189, 13: 0.185, 14: 0.182, 15: 0.18, 16: 0.177, 17: 0.173,
    18: 0.1695, 19: 0.166, 20: 0.161, 21: 0.159, 22: 0.157, 23: 0.154, 24: 0.152, 25: 0.1495,
    26: 0.147, 27: 0.144, 28: 0.1405, 29: 0.136, 30: 0.1285, 31: 0.12, 32: 0.116, 33: 0.113,
    34: 0.111, 35: 0.11, 36: 0.1065, 37: 0.104, 38: 0.1015, 39: 0.0995, 40: 0.098, 41: 0.096,
    42: 0.0935, 43: 0.089, 44: 0.086, 45: 0.082, 46: 0.081, 47: 0.0785, 48: 0.076, 49: 0.073,
    50: 0.07, 51: 0.067, 52: 0.0635, 53: 0.0595, 54: 0.055, 55: 0.052, 56: 0.0465, 57: 0.043,
    58: 0.042, 59: 0.041, 60: 0.04, 61: 0.039, 62: 0.038, 63: 0.037, 64: 0.036, 65: 0.035,
    66: 0.033, 67: 0.032, 68: 0.031, 69: 0.0292, 70: 0.028, 71: 0.026, 72: 0.025, 73: 0.024,
    74: 0.0225, 75: 0.021, 76: 0.02, 77: 0.018, 78: 0.016, 79: 0.0145, 80: 0.0135,
}
LETTER_DRILLS_IN = {
    "A": 0.234, "B": 0.238, "C": 0.242, "D": 0.246, "E": 0.25, "F": 0.257, "G": 0.261,
    "H": 0.266, "I": 0.272, "J": 0.277, "K": 0.281, "L": 0.29, "M": 0.295, "N": 0.302,
    "O": 0.316, "P": 0.323, "Q": 0.332, "R": 0.339, "S": 0.348, "T": 0.358, "U": 0.368,
    "V": 0.377, "W": 0.386, "X": 0.397, "Y": 0.404, "Z": 0.413,
}


@dataclass(frozen=True)
class DeclaredTool:
    """One tool as a program's comments declare it (lengths in mm)."""

    number: int | None  # None only from parse_tool_comment on a description without a number
    diameter_mm: float
    corner_radius_mm: float | None  # 0 flat, D/2 ball, given for bull; None: not given (bull, face)
    kind: str  # one of KINDS
    flutes: int | None
    line: int  # 1-based line of the comment (0 from parse_tool_comment)
    comment: str  # the comment text
    form: str  # which form matched (module docstring)
    name: str = ""  # the tool's name or type text as written ("1/2 FLAT ENDMILL", "flat end mill")
    angle_deg: float | None = None  # point / taper / V angle when given
    program_units: bool = False  # the diameter was a bare number read in the program's units
    also: tuple[int, ...] = ()  # lines of further declarations of this tool that agree
    tip_mm: float | None = None  # a vee tool's flat tip diameter, when given

    @property
    def included_angle(self) -> float | None:
        """A cone's included angle, degrees: Fusion's TAPER is the half angle from the axis;
        a V-bit's or engraving bit's "60 DEG" is the included angle; a chamfer mill's name
        may give either (see below)."""
        if self.angle_deg is None:
            return None
        if self.form == "Fusion 360":
            return 2.0 * self.angle_deg
        if self.kind == "chamfer":
            # "45° CHAMFER MILL" names the chamfer (half) angle, "90 DEG CHAMFER MILL" the
            # included one: only 45°/90° read the same both ways; the rest is not guessed
            return 90.0 if self.angle_deg in (45.0, 90.0) else None
        return self.angle_deg

    @property
    def modelled(self) -> bool:
        """True when the library's cutters can represent this tool: flat/ball/bull (a bull nose
        needs its corner radius), or a cone of known angle (V-bit, engraving bit, chamfer mill)."""
        if self.kind in VEE_KINDS:
            a = self.included_angle
            return a is not None and 0 < a < 180
        return self.kind in MODELLED_KINDS and not (self.kind == "bull" and self.corner_radius_mm is None)


@dataclass(frozen=True)
class Rejected:
    """A comment that declares a tool which was left out, and why."""

    line: int
    comment: str
    reason: str
    number: int | None = None


@dataclass(frozen=True)
class ToolComments:
    tools: dict[int, DeclaredTool]
    rejected: tuple[Rejected, ...]
    inch: bool | None  # the units bare numbers were read in (None: unknown)


# --------------------------------------------------------------------------- sizes

_NUM = r"(?:\d+-\d+/\d+|\d+ \d+/\d+|\d+/\d+|\d*\.\d+|\d+\.?)"
_QTY = re.compile(r"(?<![A-Z0-9_.#/\-])(?P<num>" + _NUM + r")(?P<unit>\s*(?:\"|''|INCH(?:ES)?\b|IN\b|MM\b|°|º|DEG(?:REES?)?\b\.?))?",
                  re.I)
_DRILL_NO = re.compile(r"(?<![A-Z0-9_])(?:#|NO\.?\s*)(\d{1,2})(?=\s*(?:TAP\s+)?DRILL)", re.I)
_DRILL_LETTER = re.compile(r"\bLET(?:TER)?\.?\s*([A-Z])\b(?=\s*(?:TAP\s+)?DRILL)", re.I)

_KIND_RULES = [
    ("other", r"CORNER\s*-?\s*ROUND|DOVETAIL|LOLLIPOP|T-?\s*SLOT|KEY\s*SEAT|WOODRUFF|THREAD\s*-?\s*MILL|BORING|"
              r"C'?\s*BORE|COUNTER\s*-?\s*BORE|FORM\s+(?:MILL|TOOL)|TAPERED\s+MILL|PROBE|PLASMA|LASER|WATER\s*-?\s*JET|"
              r"\bSAW\b|SLITTING|RADIUS\s+MILL|SLOT\s+MILL|HOLDER|\bWIRE\b"),
    ("chamfer", r"CHAMFER|COUNTER\s*-?\s*SINK|C'?SINK|\bCSK\b"),
    ("engrave", r"\bV\s*-?\s*BIT|\bVEE\b|'V'|\bV\s*-?\s*CUTTER|V\s*-?\s*GROOVE|ENGRAV"),
    ("drill", r"TAP\s+DRILL"),
    ("tap", r"\bTAPS?\b|ROLL\s*-?\s*FORM"),
    ("reamer", r"\bREAM"),
    ("drill", r"DRILL"),
    ("face", r"FACE\s*-?\s*MILL|SHELL\s*-?\s*MILL|FLY\s*-?\s*CUT"),
    ("ball", r"BALL"),
    ("bull", r"BULL|TORUS|TOROID|CORNER\s*RAD"),
    ("flat", r"FLAT|END\s*-?\s*MILL|E\.\s*M\.|\bEM\b|CYLINDRICAL"),
    ("unspecified", r"\bUNSPECIFIED\b|\bMILL\b|\bCUTTER\b|\bBIT\b"),  # a cutter of unstated shape
]
_KIND_RES = [(k, re.compile(p, re.I)) for k, p in _KIND_RULES]


def _kind_of(text: str) -> str | None:
    for kind, rx in _KIND_RES:
        if rx.search(text):
            return kind
    return None


def _number(s: str) -> float:
    s = s.strip()
    m = re.fullmatch(r"(\d+)[- ](\d+)/(\d+)", s)
    if m:
        return int(m.group(1)) + float(Fraction(int(m.group(2)), int(m.group(3))))
    if "/" in s:
        a, b = s.split("/")
        return float(Fraction(int(a), int(b)))
    return float(s)


@dataclass
class _Qty:
    value: float
    unit: str | None  # "in" | "mm" | "deg" | None (bare)
    start: int
    end: int
    role: str = "size"  # size | dia | radius | angle | flutes | skip


def _unit(u: str | None) -> str | None:
    if not u:
        return None
    u = u.strip().upper()
    if u in ('"', "''") or u.startswith("IN"):
        return "in"
    if u == "MM":
        return "mm"
    return "deg"


_AFTER = [
    ("angle", re.compile(r"\s*(?:°|º|DEG\b)", re.I)),
    ("flutes", re.compile(r"\s*-?\s*(?:FLUTES?\b|FL\b|FLT\b)", re.I)),
    ("radius", re.compile(r"\s*(?:R\b|RAD\b|RAD\.|RADIUS|CR\b|CORNER\s+RAD)", re.I)),
    ("skip", re.compile(r"\s*(?:LONG\b|LG\b|LOC\b|OAL\b|LENGTH|REACH|SHANK|DEEP\b|DP\b|STICK)", re.I)),
    ("dia", re.compile(r"\s*(?:IN\s+)?(?:DIA\b|DIA\.|DIAM|Ø|⌀)", re.I)),
]
_BEFORE = [
    ("angle", re.compile(r"(?:TAPER|ANGLE)\s*[=:]?\s*$", re.I)),
    ("radius", re.compile(r"(?:\bCR|\bR|\bRAD|RADIUS)\s*[=:.]?\s*$", re.I)),
    ("skip", re.compile(r"(?:\bLOC|\bOAL|LENGTH|REACH|SHANK|ZMIN|ZMAX|\bLEN\.?)\s*[-=:]?\s*$", re.I)),
    ("dia", re.compile(r"(?:\bDIA\b\.?|\bDIAM\b\.?|DIAMETER|Ø|⌀|\bD)\s*[-=:]?\s*$", re.I)),
    ("skip", re.compile(r"\bWITH\s*$", re.I)),  # "WITH .020" X 45° CHAMFERS": a feature, not the cutter
    ("second", re.compile(r"\bX\s*$", re.I)),  # "1/4" X .032" RADIUS": a second dimension
]


def _quantities(text: str) -> list[_Qty]:
    out: list[_Qty] = []
    for m in _QTY.finditer(text):
        unit = _unit(m.group("unit"))
        end = m.end()
        if unit is None and end < len(text) and (text[end].isalnum() or text[end] == "_"):
            continue  # "2D", "4X", "100x100": not a size
        q = _Qty(_number(m.group("num")), unit, m.start(), end)
        before, after = text[:m.start()], text[end:]
        if unit == "deg":
            q.role = "angle"
        else:  # (a number right after '-' is never a size: thread pitches 1/4"-20, M4 4.00-0.7)
            for role, rx in _AFTER:
                if rx.match(after):
                    q.role = role
                    break
            else:
                for role, rx in _BEFORE:
                    if rx.search(before):
                        q.role = role
                        break
        if q.role == "flutes" and (unit or q.value != int(q.value)):
            q.role = "skip"
        if q.role == "second":
            q.role = "skip"
        out.append(q)
    return out


def _to_mm(value: float, unit: str | None, inch: bool | None) -> float | None:
    if unit == "mm":
        return value
    if unit == "in":
        return value * MM_PER_INCH
    if inch is None:
        return None
    return value * MM_PER_INCH if inch else value


def _agree(a: float, b: float) -> bool:
    return abs(a - b) <= 0.01 + 0.005 * max(a, b)


@dataclass
class _Desc:
    diameter_mm: float | None = None
    radius_mm: float | None = None
    angle: float | None = None
    flutes: int | None = None
    kind: str | None = None
    labelled: bool = False
    program_units: bool = False
    problem: str = ""


def _describe(text: str, inch: bool | None, dia: tuple[float, bool] | None = None) -> _Desc:
    """Sizes and kind of a tool description.  ``dia`` = (diameter in program units or mm,
    is_bare) from a labelled field of the form, checked against the name's size."""
    d = _Desc(kind=_kind_of(text))
    if re.search(r"\bOR\b", text, re.I):
        d.problem = "the description names alternatives ('or')"
        return d
    qs = _quantities(text)
    for q in qs:
        if q.role == "angle" and d.angle is None:
            d.angle = q.value
        elif q.role == "flutes" and d.flutes is None:
            d.flutes = int(q.value)
        elif q.role == "radius" and d.radius_mm is None:
            d.radius_mm = _to_mm(q.value, q.unit, inch)
    labelled = [q for q in qs if q.role == "dia"]
    plain = [q for q in qs if q.role == "size"]
    drill = None
    m = _DRILL_NO.search(text)
    if m and 1 <= int(m.group(1)) <= 80:
        drill = NUMBER_DRILLS_IN[int(m.group(1))] * MM_PER_INCH
        plain = [q for q in plain if not m.start() <= q.start < m.end()]  # "NO. 33": the drill's number
    m = _DRILL_LETTER.search(text)
    if m:
        drill = LETTER_DRILLS_IN[m.group(1).upper()] * MM_PER_INCH

    # the name's own size (one plain size, or a drill designation)
    name_size: list[tuple[float, _Qty | None]] = []
    if drill is not None:
        name_size.append((drill, None))
    for q in plain:
        mm = _to_mm(q.value, q.unit, inch)
        if mm is None:
            d.problem = "a bare size and the program's units are unknown"
            return d
        name_size.append((mm, q))
    if dia is not None or labelled:
        if dia is not None:
            value, bare = dia
            ref = _to_mm(value, None, inch) if bare else value
            if ref is None:
                d.problem = "the diameter is in the program's units, which are unknown"
                return d
            d.program_units = bare
        else:
            refs = []
            for q in labelled:
                mm = _to_mm(q.value, q.unit, inch)
                if mm is None:
                    d.problem = "the diameter is in the program's units, which are unknown"
                    return d
                refs.append(mm)
            if any(not _agree(r, refs[0]) for r in refs):
                d.problem = "two different diameters"
                return d
            ref = refs[0]
            d.program_units = labelled[0].unit is None
        for mm, q in name_size:
            if _agree(mm, ref):
                continue
            if q is not None and q.unit is None and inch is not None:
                other = q.value if inch else q.value * MM_PER_INCH  # read in the other unit system
                if _agree(other, ref):
                    continue
            d.problem = (f"the name says {_fmt(mm)} mm but the diameter is {_fmt(ref)} mm")
            return d
        d.diameter_mm, d.labelled = ref, True
        return d
    if len(name_size) > 1:
        d.problem = "more than one size, none labelled as the diameter: " + \
                    ", ".join(text[q.start:q.end].strip() if q else "drill size" for _, q in name_size)
        return d
    if not name_size:
        d.problem = "no diameter"
        return d
    d.diameter_mm, q = name_size[0]
    d.program_units = q is not None and q.unit is None
    return d


def _fmt(x: float) -> str:
    return f"{x:.4g}"


# --------------------------------------------------------------------------- forms

_FUSION = re.compile(
    r"^\s*T(?P<n>\d+)\s+D\s*=\s*(?P<d>" + _NUM + r")(?:\s+CR\s*=\s*(?P<cr>" + _NUM + r"))?"
    r"(?:\s+TAPER\s*=\s*(?P<taper>" + _NUM + r")\s*(?:DEG|°)?)?"
    r"(?:\s*-\s*ZMIN\s*=\s*-?" + _NUM + r")?(?:\s*-\s*(?P<type>.*?))?\s*$", re.I)
_MPFAN = re.compile(
    r"^(?P<pre>.*?)\bTOOL\s*-\s*(?P<n>\d+)(?P<name>.*?)\bDIA\.?\s*OFF\.?\s*-\s*\d+\s*LEN\.?\s*-\s*\d+\s*"
    r"(?:TOOL\s+)?DIA\.?\s*-\s*(?P<d>" + _NUM + r")\s*$", re.I)
_PIPE = re.compile(r"^\s*T(?P<n>\d+)\s*\|(?P<name>[^|]*)\|\s*H\d+\s*(?P<rest>(?:\|.*)?)$", re.I)
_PIPE_DIA = re.compile(r"\|\s*TOOL\s+DIA\.?\s*-\s*(?P<d>" + _NUM + r")\s*(?:\||$)", re.I)
_TABLE = re.compile(r"^\s*(?P<p>\d+)\s+(?P<n>\d+)\s+[-+]?(?:\d+\.?\d*|\.\d+)\s+(?P<d>\d+\.?\d*|\.\d+)\s+(?P<name>\S.*?)\s*$")
_NUMBERED = re.compile(r"^\s*(?:T|TOOL\s*(?:NO\.?|#)?)\s*(?P<n>\d+)(?:\s*(?:=|:|-|\bIS\b)\s*|\s+)(?P<name>\S.*?)\s*$",
                       re.I)
# Vectric (pygcode's files): "( Endmill Dia. 0.250 )", "( TOOL=ENGRAVE {20' 0.02" TIP DIA} )"
_NAME_DIA = re.compile(r"^\s*(?P<name>[A-Z][A-Z \-]*?)\s+DIA(?:METER|\.)?\s*[:=]?\s*(?P<d>" + _NUM + r")\s*$", re.I)
_VECTRIC_TIP = re.compile(r"^\s*TOOL\s*=\s*(?P<name>[^{]*?)\s*\{\s*(?P<a>" + _NUM + r")\s*(?:'|°|º|DEG\.?)\s*(?P<d>"
                          + _NUM + r")\s*(?P<unit>\"|MM|IN)?\s*TIP\s+DIA\.?\s*\}\s*$", re.I)
_PREFIX = re.compile(r"^\s*(?:TOOL|CUTTER|BIT)\b\s*(?:[:=\-]|\bIS\b)?\s*", re.I)
_PROSE = re.compile(r"\b(?:CUTTER|TOOL|BIT|END\s*MILL|ENDMILL)\b[^.;]{0,30}?\b(?:IS|BE)\s+(?:AN?\s+)?(?=[\d.])", re.I)


def _declared(number, desc: _Desc, comment: str, form: str, name: str, line: int,
              cr_mm: float | None = None):
    """A DeclaredTool from a parsed description, or a Rejected."""
    if desc.problem:
        return Rejected(line, comment, desc.problem, number)
    kind = desc.kind or "unspecified"
    dia = desc.diameter_mm
    limit = MAX_DIAMETER_MM.get(kind, MAX_DIAMETER_MM["default"])
    if not dia or dia <= 0:
        return Rejected(line, comment, "no diameter", number)
    if dia > limit:
        why = " (a bare size read in the program's units: inch)" if desc.program_units else ""
        return Rejected(line, comment, f"diameter {_fmt(dia)} mm is implausible for a {kind} tool{why}", number)
    cr = cr_mm if cr_mm is not None else desc.radius_mm
    if kind == "flat" and cr:
        kind = "bull"  # a "flat" end mill with a corner radius
    if kind == "ball":
        cr = dia / 2
    elif kind in ("flat", "drill", "tap", "reamer", "chamfer", "engrave", "unspecified") and cr is None:
        cr = 0.0
    if cr is not None and not 0 <= cr <= dia / 2 + 1e-9:
        return Rejected(line, comment, f"corner radius {_fmt(cr)} mm does not fit a {_fmt(dia)} mm tool", number)
    return DeclaredTool(number, round(dia, 6), None if cr is None else round(cr, 6), kind, desc.flutes, line,
                        comment.strip(), form, name.strip(), desc.angle, desc.program_units)


def parse_tool_comment(comment: str, inch: bool | None, number: int | None = None, line: int = 0,
                       at_tool_change: bool = True):
    """One comment's text (without the parentheses or ';').

    Returns a DeclaredTool, a Rejected (a tool declaration that cannot be read without
    guessing) or None (not a tool declaration).  ``number`` is the tool a description
    without a number of its own belongs to (None: leave it None); ``at_tool_change``
    False refuses descriptions without a number.
    """
    text = comment.strip()
    m = _FUSION.match(text)
    if m:
        n = int(m.group("n"))
        type_text = (m.group("type") or "").strip()
        desc = _describe(type_text, inch, (_number(m.group("d")), True))
        if m.group("taper"):
            desc.angle = _number(m.group("taper"))
        cr = None
        if m.group("cr") is not None:
            cr = _to_mm(_number(m.group("cr")), None, inch)
        if desc.kind is None and type_text:
            desc.kind = "other"
        return _declared(n, desc, text, "Fusion 360", type_text, line, cr)
    m = _MPFAN.match(text)
    if m:
        n = int(m.group("n"))
        name = f"{m.group('pre')} {m.group('name')}".strip()
        desc = _describe(name, inch, (_number(m.group("d")), True))
        return _declared(n, desc, text, "Mastercam MPFAN", name, line)
    m = _PIPE.match(text)
    if m:
        n = int(m.group("n"))
        name = m.group("name").strip()
        dm = _PIPE_DIA.search(m.group("rest") or "")
        desc = _describe(name, inch, (_number(dm.group("d")), True) if dm else None)
        return _declared(n, desc, text, "Mastercam tool table", name, line)
    m = _TABLE.match(text)
    if m and _kind_of(m.group("name")):
        n = int(m.group("n"))
        name = m.group("name")
        desc = _describe(name, inch, (_number(m.group("d")), True))
        return _declared(n, desc, text, "LinuxCNC tool table", name, line)
    m = _NAME_DIA.match(text)
    if m and _kind_of(m.group("name")) and at_tool_change:
        desc = _describe(m.group("name"), inch, (_number(m.group("d")), True))
        return _declared(number, desc, text, "Vectric", m.group("name").strip(), line)
    m = _VECTRIC_TIP.match(text)
    if m and at_tool_change:
        name = m.group("name").strip()
        unit = {'"': "in", "IN": "in", "MM": "mm"}.get((m.group("unit") or "").upper())
        dia = _to_mm(_number(m.group("d")), unit, inch)
        if dia is None:
            return None
        desc = _describe(name, None, (dia, False))
        desc.kind = desc.kind or "engrave"
        desc.angle = _number(m.group("a"))
        r = _declared(number, desc, text, "Vectric", f"{name} tip {m.group('d')}", line)
        return replace(r, tip_mm=dia) if isinstance(r, DeclaredTool) else r
    m = _NUMBERED.match(text)
    if m:
        n = int(m.group("n"))
        name = m.group("name")
        desc = _describe(name, inch)
        if desc.diameter_mm is None and desc.kind is None and not desc.labelled:
            return None  # "t1 is for facing and left turning": not a declaration
        return _declared(n, desc, text, "numbered description", name, line)
    if not at_tool_change:
        return None
    # a description without a number: "( 1/4" DIA. 2 FLUTE ... E.M. )", "Tool: 1/4 in End Mill",
    # "TOOL DIA. 3", "Cutter is assumed to be a 10mm ball nose"
    prose = _PROSE.search(text)
    prefix = _PREFIX.match(text)
    if prose:
        body, introduced = text[prose.end():], True
    elif prefix:
        body, introduced = text[prefix.end():], True
    else:
        body, introduced = text, False
    qs = [q for q in _quantities(body) if q.role in ("size", "dia")]
    designated = bool(_DRILL_NO.search(body) or _DRILL_LETTER.search(body))
    desc = _describe(body, inch)
    lead = body.lstrip()
    first = _quantities(body)
    starts = (bool(first) and first[0].start == len(body) - len(lead)) or \
        bool(re.match(r"(?:#\d|NO\.?\s*\d|LET(?:TER)?\.?\s*[A-Z]\b)", lead, re.I))
    if not (qs or designated):
        return None
    if introduced:  # "Tool: 1/4 in End Mill", "Tool 2mm dia.", "TOOL DIA. 3", "TOOL: V-BIT {90 DEG 0.5"}"
        if not (desc.kind or desc.labelled or (starts and any(q.unit in ("in", "mm") for q in qs))):
            return None
    elif not (starts and (desc.kind or desc.labelled)):  # "( 3" FACE MILL )", "( LET. B DRILL )"
        return None
    return _declared(number, desc, text, "description at tool change", body, line)


# --------------------------------------------------------------------------- program scan

def _decode(data: bytes | str) -> str:
    if isinstance(data, str):
        return data
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def comment_spans(line: str) -> list[tuple[int, int, str]]:
    """The comments of one line as (start, end, text): ``line[start:end]`` is the comment with
    its delimiters — a (...) comment (to the end of the line if it is not closed) and a ';'
    comment to the end — and ``text`` what is inside."""
    out, i, n = [], 0, len(line)
    while i < n:
        c = line[i]
        if c == "(":
            j = line.find(")", i + 1)
            j = n if j < 0 else j
            out.append((i, j + 1, line[i + 1:j]))
            i = j + 1
        elif c == ";":
            out.append((i, n, line[i + 1:]))
            break
        else:
            i += 1
    return out


def _split(line: str) -> tuple[str, list[str]]:
    """Code and comments of one line: (...) comments and a ';' comment to the end."""
    if "(" not in line and ";" not in line:  # most lines of a long program: no comment
        return line, []
    spans = comment_spans(line)
    code, at = [], 0
    for a, b, _ in spans:
        code.append(line[at:a])
        at = b
    code.append(line[at:])
    return "".join(code), [t for _, _, t in spans]


_WORD = re.compile(r"([A-Z])\s*([-+]?\s*(?:\d+\.?\d*|\.\d+)|#\s*\{\d+\}|#\s*\d+|\[)")
_ASSIGN = re.compile(r"^\s*(?:N\d+\s*)?#\s*(<[^>]+>|\d+)\s*=\s*(.*?)\s*$", re.I)
_NON_MOTION_G = {10, 28, 30, 53, 92}


@dataclass
class _Block:
    tool: int | str | None = None  # literal number, "#name" to resolve, None
    m6: bool = False
    motion: bool = False
    g20: bool | None = None


def _block(code: str) -> _Block:
    b = _Block()
    u = code.upper()
    if _ASSIGN.match(u):
        return b
    names: list[str] = []

    def keep(m):
        names.append(m.group(1).strip().lower())
        return "#{" + str(len(names) - 1) + "}"

    u = re.sub(r"#\s*<([^>]*)>", keep, u)
    u = re.sub(r"[A-Z]{2,}", " ", u)  # O-word and macro keywords (SUB, IF, GOTO, SQRT ...)
    gs, axis = set(), False
    for letter, value in _WORD.findall(u):
        v = value.replace(" ", "")
        if letter == "T":
            if v.startswith("#{"):
                b.tool = "#<" + names[int(v[2:-1])] + ">"
            elif v.startswith("#"):
                b.tool = "#" + v[1:]
            elif v != "[":
                try:
                    b.tool = int(float(v))
                except ValueError:
                    b.tool = "?"
            else:
                b.tool = "?"
        elif letter == "M" and v not in ("[",) and not v.startswith("#"):
            try:
                if float(v) == 6:
                    b.m6 = True
            except ValueError:
                pass
        elif letter == "G" and not v.startswith("#") and v != "[":
            try:
                g = float(v)
            except ValueError:
                continue
            gs.add(int(g) if g == int(g) else g)
            if g == 20:
                b.g20 = True
            elif g == 21:
                b.g20 = False
        elif letter in "XYZABCUVW":
            axis = True
    b.motion = axis and not (gs & _NON_MOTION_G)
    return b


class _Blocks:
    """``_block`` of each code line, computed when first asked for."""

    def __init__(self, codes: list[str]):
        self._codes = codes
        self._done: dict[int, _Block] = {}

    def __len__(self) -> int:
        return len(self._codes)

    def __getitem__(self, i: int) -> _Block:
        b = self._done.get(i)
        if b is None:
            b = self._done[i] = _block(self._codes[i])
        return b


def scan_tool_comments(data: bytes | str, inch: bool | None = None) -> ToolComments:
    """Every tool declared in the comments of a program.

    ``inch``: whether bare numbers are inches (the program's units); None detects it from
    the first G20/G21 in the program (if there is none, bare numbers give no tool).
    """
    lines = _decode(data).split("\n")
    codes: list[str] = []
    comments: list[list[str]] = []
    for raw in lines:
        code, cs = _split(raw.rstrip("\r"))
        codes.append(code)
        comments.append(cs)
    # blocks are read only where a comment needs them (near it), so a long program without
    # tool comments costs one pass of string splitting
    blocks = _Blocks(codes)
    if inch is None:
        inch = next((b.g20 for b in (blocks[i] for i, c in enumerate(codes) if "G" in c.upper())
                     if b.g20 is not None), None)

    # parameters assigned exactly once with a literal, for T#<name>
    assigned: dict[str, list[str]] = {}
    for code in codes:
        if "#" not in code or "=" not in code:
            continue
        m = _ASSIGN.match(code)
        if m:
            key = m.group(1).replace(" ", "").lower()
            key = "#" + key if key.startswith("<") else "#" + key
            assigned.setdefault(key, []).append(m.group(2))

    def resolve(tool) -> int | None:
        if isinstance(tool, int):
            return tool
        if isinstance(tool, str) and tool in assigned and len(assigned[tool]) == 1:
            try:
                v = float(assigned[tool][0])
            except ValueError:
                return None
            return int(v) if v == int(v) else None
        return None

    def tie(i: int) -> tuple[int | None, str]:
        """The tool a description on line index i belongs to."""
        if blocks[i].tool is not None:
            t = resolve(blocks[i].tool)
            return (t, "") if t is not None else (None, f"the tool is selected by an expression (T{blocks[i].tool})")
        last_t = None
        for k in range(i - 1, -1, -1):  # tool prepared before the comment, for a later bare M6
            if blocks[k].tool is not None:
                last_t = blocks[k].tool
                break
        for k in range(i + 1, len(blocks)):
            b = blocks[k]
            if b.tool is not None:
                t = resolve(b.tool)
                return (t, "") if t is not None else (None, f"the tool is selected by an expression (T{b.tool})")
            if b.m6:
                t = resolve(last_t) if last_t is not None else None
                return (t, "") if t is not None else (None, "M6 with no tool prepared")
            if b.motion:
                break
        for k in range(i - 1, -1, -1):
            b = blocks[k]
            if b.motion:
                break
            if b.m6:
                for j in range(k, -1, -1):
                    if blocks[j].tool is not None:
                        t = resolve(blocks[j].tool)
                        return (t, "") if t is not None else (None, "the tool is selected by an expression")
                break
        return None, "no tool selection next to it"

    _no_t: list[bool] = []

    def no_tool_words() -> bool:
        if not _no_t:
            _no_t.append(not any(re.search(r"(?<![A-Z])T\s*[#\d]", c, re.I) for c in codes))
        return _no_t[0]

    found: list[DeclaredTool] = []
    rejected: list[Rejected] = []
    pycam: dict[str, str] = {}
    pycam_line = 0
    for i, cs in enumerate(comments):
        for c in cs:
            s = c.strip()
            # PyCAM settings block
            if s.upper() == "[TOOL]":
                pycam, pycam_line = {"_": "1"}, i + 1
                continue
            if pycam:
                kv = re.match(r"^(\w+)\s*=\s*(.*?)\s*$", s)
                if kv:
                    pycam[kv.group(1).lower()] = kv.group(2)
                    continue
                r = _pycam(pycam, pycam_line, inch, tie)
                if r is not None:
                    (found if isinstance(r, DeclaredTool) else rejected).append(r)
                pycam = {}
            r = parse_tool_comment(s, inch, None, i + 1)
            if r is None:
                continue
            if (isinstance(r, DeclaredTool) and r.number is None) or (isinstance(r, Rejected) and r.number is None):
                n, why = tie(i)
                if n is None and isinstance(r, DeclaredTool) and no_tool_words():
                    # a program that selects no tool at all (a router's one spindle, changed by
                    # hand): its description is of the tool in the spindle, T0 to the interpreter
                    found.append(replace(r, number=0))
                    continue
                if n is None:
                    rejected.append(Rejected(i + 1, s, why if isinstance(r, DeclaredTool) else r.reason))
                    continue
                r = replace(r, number=n)
            if r.number == 0:
                rejected.append(Rejected(r.line, r.comment, "T0 is no tool", 0))
            else:
                (found if isinstance(r, DeclaredTool) else rejected).append(r)
    if pycam:
        r = _pycam(pycam, pycam_line, inch, tie)
        if r is not None:
            (found if isinstance(r, DeclaredTool) else rejected).append(r)
    tools, more = _merge(found)
    return ToolComments(tools, tuple(sorted(rejected + more, key=lambda r: r.line)), inch)


def _pycam(kv: dict[str, str], line: int, inch: bool | None, tie):
    shape = kv.get("shape", "")
    comment = "[Tool] " + ", ".join(f"{k} = {v}" for k, v in kv.items() if k != "_")
    if "tool_radius" not in kv:
        return None
    kind = {"cylindricalcutter": "flat", "sphericalcutter": "ball", "toroidalcutter": "bull"}.get(shape.lower(), "other")
    try:
        radius = float(kv["tool_radius"])
    except ValueError:
        return Rejected(line, comment, "tool_radius is not a number")
    dia = _to_mm(2 * radius, None, inch)
    if dia is None:
        return Rejected(line, comment, "tool_radius is in the program's units, which are unknown")
    cr = None
    if kind == "bull":
        try:
            cr = _to_mm(float(kv.get("torus_radius", "")), None, inch)
        except ValueError:
            return Rejected(line, comment, "a ToroidalCutter without a torus_radius")
    n, why = tie(line - 1)
    if n is None:
        return Rejected(line, comment, why)
    desc = _Desc(diameter_mm=dia, kind=kind, labelled=True, program_units=True)
    return _declared(n, desc, comment, "PyCAM settings", shape, line, cr)


def _merge(found: list[DeclaredTool]) -> tuple[dict[int, DeclaredTool], list[Rejected]]:
    by: dict[int, list[DeclaredTool]] = {}
    for t in found:
        by.setdefault(t.number, []).append(t)
    tools, rejected = {}, []
    for n, ds in sorted(by.items()):
        primary = sorted(ds, key=lambda t: (-FORM_RANK.get(t.form, 1), t.line))[0]
        others = [t for t in ds if t is not primary]
        clash = [t for t in others
                 if not _agree(t.diameter_mm, primary.diameter_mm)
                 or (t.kind != primary.kind and "unspecified" not in (t.kind, primary.kind))]
        if clash:
            desc = "; ".join(f"line {t.line}: {_fmt(t.diameter_mm)} mm {t.kind}" for t in [primary] + clash)
            rejected.append(Rejected(primary.line, primary.comment,
                                     f"T{n} is declared differently ({desc})", n))
            continue
        t = primary
        for o in sorted(others, key=lambda t: t.line):
            if t.kind == "unspecified" and o.kind != "unspecified":
                t = replace(t, kind=o.kind, corner_radius_mm=o.corner_radius_mm if o.kind != "ball" else t.diameter_mm / 2)
            if t.flutes is None and o.flutes is not None:
                t = replace(t, flutes=o.flutes)
            if t.corner_radius_mm is None and o.corner_radius_mm is not None and o.kind == t.kind:
                t = replace(t, corner_radius_mm=o.corner_radius_mm)
            if t.angle_deg is None and o.angle_deg is not None:
                t = replace(t, angle_deg=o.angle_deg)
        tools[n] = replace(t, also=tuple(sorted(o.line for o in others)))
    return tools, rejected


def tools_from_comments(data: bytes | str, inch: bool | None = None) -> dict[int, DeclaredTool]:
    """Tool number -> DeclaredTool for every tool the program's comments declare readably."""
    return scan_tool_comments(data, inch).tools


# --------------------------------------------------------------------------- library

def to_tool_table(declared: DeclaredTool, unspecified_as_flat: bool = False) -> dict | None:
    """The ``[tools.N]`` twin-file entry for a declared tool, or None when the library's
    flat/ball/bull cutter cannot model it (drills, taps, chamfer mills, V-bits, a bull nose
    or face mill whose corner radius is not given...).  A tool whose shape is not declared
    (``unspecified``, e.g. ``(TOOL DIA. 3)``) becomes a flat end mill only if asked."""
    kind, d, cr = declared.kind, declared.diameter_mm, declared.corner_radius_mm
    if kind in VEE_KINDS:
        if not declared.modelled:
            return None
        tip = declared.tip_mm or 0.0
        if tip >= d - 1e-9:  # only the tip is known: the cone up to a typical shank
            d = max(ENGRAVE_BODY_MM, 2.0 * tip)
        entry = {"type": "vee", "diameter": d, "angle": declared.included_angle, "tip_diameter": tip}
        if declared.flutes:
            entry["flutes"] = declared.flutes
        return entry
    if kind == "unspecified" and unspecified_as_flat:
        kind = "flat"
    if kind in ("bull", "face"):
        if cr is None:
            if kind == "bull":
                return None
            cr = 0.0  # a face mill without CR: flat-bottomed
        if cr <= 1e-9:
            kind, cr = "flat", 0.0
        elif cr >= d / 2 - 1e-9:
            kind = "ball"
        else:
            kind = "bull"
    if kind not in ("flat", "ball", "bull"):
        return None
    entry: dict = {"type": kind, "diameter": d}
    if kind == "bull":
        entry["corner_radius"] = cr
    if declared.flutes:
        entry["flutes"] = declared.flutes
    return entry


def to_library_tool(declared: DeclaredTool, base: Tool | None = None, unspecified_as_flat: bool = False) -> Tool | None:
    """``library.Tool`` for a declared tool (fields not declared, such as flutes, helix and
    flute length, come from ``base``, default ``Tool()``), or None (see ``to_tool_table``)."""
    entry = to_tool_table(declared, unspecified_as_flat)
    if entry is None:
        return None
    base = base or Tool()
    if entry["type"] != "bull":
        entry["corner_radius"] = 0.0
    if entry["type"] != "vee":
        entry.setdefault("angle", Tool().angle)
        entry.setdefault("tip_diameter", 0.0)
    return replace(base, **entry)
