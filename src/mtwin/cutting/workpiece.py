"""What a program's comments say about the workpiece and its one tool: the material, the stock
box and, for a single-tool program, the tool in its title comment (docs/catalogue.md).

Forms read, with where they were seen:

material
    ``(MATERIAL: 304)``, ``(MATERIAL = AL6061)``, Mastercam's ``(MATERIAL - ALUMINUM MM -
    2024)``: a keyword then a name the catalogue knows (any of ``mtwin materials``' names);
    Newfangled Wizard's ``(Program Posted for Aluminum )`` (pygcode_test_files/DB25.tap);
    a material name with letters in a header comment — before the first move — such as the
    title ``O1001 (POCKET 40X30 DEPTH 2 - 6MM 2FL CARBIDE - AL6061)``.  A bare number
    (``(1018)``, a Fusion program's name in fusion360_led_floor) counts only after the
    keyword.  An unknown name after the keyword is a warning (``file:line:col``), not a guess;
    two different materials in the header are a warning and neither is taken.
stock
    ``(STOCK: X0 Y0 Z-10 TO X60 Y50 Z0)`` (the corners, program units); Vectric's ``(
    Material Size )`` then ``( X=96 mm, Y=120 mm, Z=6 mm )`` (pygcode_test_files/Cross2.tap)
    or ``( X= 89.500, Y= 120.000 )``: a size, placed where it holds the toolpath — XY from the
    origin or centred on it, Z under Z0 (the material surface) or above it (the table).
tool
    A single-tool program whose tool nothing else declares: a size with a unit and a flute
    count in a header comment — ``6MM 2FL CARBIDE``, ``1/4" 3 FLUTE HSS BALL`` — is that
    tool (``flat`` unless it says ``BALL``).
"""
from __future__ import annotations

import functools
import re
from dataclasses import dataclass, field

from .catalogue import find
from .tool_comments import MM_PER_INCH, _number, _to_mm, _unit, comment_spans


@dataclass(frozen=True)
class Found:
    value: object  # a catalogue key, a stock box (mm), or a library Tool
    line: int
    col: int
    form: str
    text: str


@dataclass(frozen=True)
class Workpiece:
    material: Found | None = None
    stock: Found | None = None
    tool: Found | None = None
    warnings: tuple = field(default_factory=tuple)  # (line, col, message)


_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)"
_KEYWORD = re.compile(r"\bMAT(?:ERIAL|\.|L)?\b\s*(?:[:=\-]\s*|\bIS\b\s*)(?P<name>[^()]*)", re.I)
_POSTED = re.compile(r"\bPOSTED\s+FOR\s+(?P<name>[A-Za-z][^()]*)", re.I)
_STOCK_TO = re.compile(r"\bSTOCK\b\s*[:=\-]?\s*X\s*(?P<x0>" + _NUMBER + r")\s*,?\s*Y\s*(?P<y0>" + _NUMBER
                       + r")\s*,?\s*Z\s*(?P<z0>" + _NUMBER + r")\s*,?\s*TO\s*X\s*(?P<x1>" + _NUMBER + r")\s*,?\s*Y\s*(?P<y1>"
                       + _NUMBER + r")\s*,?\s*Z\s*(?P<z1>" + _NUMBER + r")", re.I)
_MATERIAL_SIZE = re.compile(r"^\s*MATERIAL\s+SIZE\s*$", re.I)
_SIZE = re.compile(r"^\s*X\s*=\s*(?P<x>" + _NUMBER + r")\s*(?P<ux>MM|IN(?:CH(?:ES)?)?|\")?\s*,\s*Y\s*=\s*(?P<y>"
                   + _NUMBER + r")\s*(?P<uy>MM|IN(?:CH(?:ES)?)?|\")?\s*(?:,\s*Z\s*=\s*(?P<z>" + _NUMBER
                   + r")\s*(?P<uz>MM|IN(?:CH(?:ES)?)?|\")?)?\s*$", re.I)
_FRACTION = r"\d+/\d+|\d+-\d+/\d+"
_TITLE_TOOL = re.compile(r"(?P<d>" + _FRACTION + r"|\d*\.?\d+)\s*(?P<u>MM|IN(?:CH)?|\")\s*(?:DIA\.?\s*)?,?\s*"
                         r"(?P<f>\d+)\s*-?\s*(?:FL|FLT|FLUTES?)\b", re.I)


def _comments(lines: list[str]):
    """(line, col, text) of every (...) and ; comment; col is the text's first (1-based)."""
    for i, raw in enumerate(lines, 1):
        if "(" in raw or ";" in raw:
            for a, _, text in comment_spans(raw):
                yield i, a + 2, text


def _material_in(text: str, allow_numbers: bool) -> str | None:
    """The most specific catalogue material named in ``text``: windows of 1-3 words, the
    longest first (``ALUMINUM MM - 2024`` -> the 2024 row over ``aluminum``)."""
    words = [w for w in re.split(r"[\s,;/()\-]+", text) if w]
    best = None
    for size in (3, 2, 1):
        for a in range(len(words) - size + 1):
            window = words[a:a + size]
            joined = "".join(window)
            if not allow_numbers and not re.search(r"[A-Za-z]", joined):
                continue
            if not allow_numbers and (re.fullmatch(r"\d+(?:\.\d+)?(?:MM|IN)?", joined, re.I) or "=" in joined
                                      or len(re.sub(r"[^A-Za-z0-9]", "", joined)) < 4):
                continue  # (a size, a D=2 field, a short code such as D2 or O1 only after MATERIAL)
            key = find(joined) or (find(" ".join(window)) if size > 1 else None)
            if key is None:
                continue
            # an alloy number beats a family name (aluminium, steel)
            specific = bool(re.search(r"\d", joined))
            if best is None or (specific and not best[1]):
                best = (key, specific)
        if best is not None and best[1]:
            break
    return None if best is None else best[0]


def _mm(value: float, unit: str | None, inch: bool) -> float:
    """A size with its written unit (MM, IN, INCH, ") or bare, in the program's units."""
    return _to_mm(value, _unit(unit), inch)


def read_workpiece(program) -> Workpiece:
    """The material, stock and title tool a program's comments declare (cached on its bytes)."""
    first_move = int(program.records["line"].min()) if len(program.records) else 0
    return _read(bytes(program.data), program.inch, first_move)


@functools.lru_cache(maxsize=8)
def _read(data: bytes, inch: bool, first_move: int) -> Workpiece:
    lines = data.decode("latin-1").split("\n")
    warnings = []
    keyword_hits, header_hits = [], []
    stock = tool = None
    vectric_at = None
    tool_hits = []
    for line, col, text in _comments(lines):
        header = first_move == 0 or line < first_move
        m = _KEYWORD.search(text)
        if m and not _MATERIAL_SIZE.match(text):
            name = m.group("name").strip(" -:=")
            key = _material_in(name, allow_numbers=True) if name else None
            if key is not None:
                keyword_hits.append(Found(key, line, col, "MATERIAL comment", text.strip()))
            elif name and not re.search(r"\bSIZE\b|\bREMOV|\bTHICK", name, re.I):
                warnings.append((line, col + m.start("name"),
                                 f"material {name!r} is not in the catalogue (mtwin materials lists the names it "
                                 f"knows): the material stays as the twin file or --material says"))
        elif header and not re.match(r"\s*T\d+\b", text, re.I):  # (not a tool's declaration)
            p = _POSTED.search(text)
            key = _material_in(p.group("name") if p else text, allow_numbers=False)
            if key is not None:
                header_hits.append(Found(key, line, col, "Program Posted for" if p else "header comment",
                                         text.strip()))
        if stock is None:
            s = _STOCK_TO.search(text)
            if s:
                v = [float(s.group(k)) for k in ("x0", "y0", "z0", "x1", "y1", "z1")]
                v = [x * MM_PER_INCH if inch else x for x in v]
                box = (min(v[0], v[3]), min(v[1], v[4]), min(v[2], v[5]), max(v[0], v[3]), max(v[1], v[4]),
                       max(v[2], v[5]))
                if box[0] < box[3] and box[1] < box[4] and box[2] < box[5]:
                    stock = Found(box, line, col, "STOCK ... TO ...", text.strip())
                else:
                    warnings.append((line, col, "the STOCK comment's corners make an empty box: not used"))
            elif _MATERIAL_SIZE.match(text):
                vectric_at = (line, col)
            elif vectric_at is not None and line <= vectric_at[0] + 1:
                z = _SIZE.match(text)
                if z:
                    size = (_mm(float(z.group("x")), z.group("ux"), inch),
                            _mm(float(z.group("y")), z.group("uy"), inch),
                            None if z.group("z") is None else _mm(float(z.group("z")), z.group("uz"), inch))
                    stock = Found(size, line, col, "Vectric MATERIAL SIZE", text.strip())
                else:
                    warnings.append((line, col, "a MATERIAL SIZE comment not followed by ( X=…, Y=…[, Z=…] ): no "
                                                "stock read"))
                vectric_at = None
        if header:
            t = _TITLE_TOOL.search(text)
            if t:
                tool_hits.append((t, line, col, text))
    material = None
    found = keyword_hits or header_hits
    keys = sorted({f.value for f in found})
    if len(keys) == 1:
        material = found[0]
    elif len(keys) > 1:
        f = found[1] if found[1].value != found[0].value else next(x for x in found if x.value != found[0].value)
        warnings.append((f.line, f.col, f"the comments name two materials ({', '.join(keys)}): neither is taken — "
                                        f"give --material"))
    if tool_hits:
        from .library import Tool

        t, line, col, text = tool_hits[0]
        d = _mm(_number(t.group("d")), t.group("u"), inch)
        flutes = int(t.group("f"))
        up = text.upper()
        kind = "ball" if re.search(r"\bBALL", up) else "flat"
        if 0 < d <= 80 and 1 <= flutes <= 16:
            tool = Found(Tool(type=kind, diameter=d, flutes=flutes,
                              material="hss" if re.search(r"\bHSS\b|\bHIGH.SPEED", up) else "carbide"),
                         line, col, "title comment", text.strip())
    return Workpiece(material, stock, tool, tuple(warnings))


def place_size(size: tuple, feed_box) -> tuple | None:
    """A Vectric material size (x, y[, z]) placed where it holds the feed moves' box
    ``((xmin, ymin, zmin), (xmax, ymax, zmax))``: XY from the origin, else centred on it (the
    placement whose box holds the toolpath's centre; a profile cut runs outside the edge by
    its tool's radius); Z under Z0 when the toolpath goes below Z0 (surface datum), else on
    it (table datum).  A through-cut below the bottom (into the spoilboard) takes the bottom
    down with it: the Z-map has one top surface.  None when no placement holds the toolpath."""
    lo, hi = feed_box
    x, y, z = size
    cx, cy = 0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])
    xy = None
    for x0, y0 in ((0.0, 0.0), (-x / 2, -y / 2)):
        if x0 <= cx <= x0 + x and y0 <= cy <= y0 + y:
            xy = (x0, y0)
            break
    if xy is None:
        return None
    if z is None:  # no thickness: top at Z0, bottom under the deepest move
        zlo, zhi = min(lo[2], 0.0) - 1.0, 0.0
    elif lo[2] < 0:
        zlo, zhi = min(-z, lo[2]), 0.0
    else:
        zlo, zhi = 0.0, z
    return (xy[0], xy[1], zlo, xy[0] + x, xy[1] + y, zhi)
