"""Tools and work materials: the cutting half of the twin file.

    [cutting]
    material = "al6061"            # a built-in name or one of [materials.*]
    stock = [0, 0, -20, 60, 50, 0] # xmin, ymin, zmin, xmax, ymax, zmax (mm, work coordinates)
    resolution = 0.05              # Z-map cell size, mm
    step = 0.1                     # engagement step along the path, mm

    [tools.1]
    type = "flat"                  # flat | ball | bull
    diameter = 6.0
    flutes = 2

    [materials.my_steel]
    ktc = 2100.0                   # N/mm^2 (cutting coefficients), N/mm (edge coefficients)

Coefficients follow ``docs/physics.md`` section 1: Ktc, Krc, Kac in N/mm², Kte, Kre, Kae in
N/mm.  With no tool table every tool is the reference's 6 mm two-flute carbide flat end
mill, and the material is ``al6061`` with the reference's identified Kt and Ke.
"""
from __future__ import annotations

import os

import functools
import math
import re
from dataclasses import dataclass, field, fields, replace

from ..errors import ConfigError
from ..params import P
from ..params import check_value as _check

TOOL_TYPES = ("flat", "ball", "bull", "vee")


@dataclass(frozen=True)
class Tool:
    type: str = P("flat", "str", "flat | ball | bull (corner radius) | vee (V-bit, engraving or chamfer cone: "
                                 "angle, tip_diameter)", "choice", TOOL_TYPES)
    diameter: float = P(6.0, "mm", "cutting diameter [S: reference 6 mm end mill]", hi=1000.0)
    flutes: int = P(2, "int", "number of flutes [S: reference two-flute]", hi=64)
    helix: float = P(30.0, "", "helix angle, degrees [E: 30 deg typical for aluminium end mills]", "nonneg",
                     hi=89.0)
    corner_radius: float = P(0.0, "mm", "corner radius (bull-nose); a ball's is diameter/2", "nonneg")
    angle: float = P(90.0, "", "included angle of a vee tool's cone, degrees (V-bit 60-90, engraving 10-30, "
                               "chamfer 90)", "positive")
    tip_diameter: float = P(0.0, "mm", "flat tip of a vee tool (engraving bits: 0.1-0.5 mm)", "nonneg")
    flute_length: float = P(15.0, "mm", "length of cut; deeper engagement is an error", hi=1000.0)
    stickout: float = P(0.0, "mm", "length out of the holder: the cantilever of the breakage and deflection limits "
                                   "(0: 4 x diameter [E], docs/catalogue.md)", "nonneg", hi=1000.0)
    force_limit: float = P(0.0, "N", "the side load this tool may take in optimize (0: none given; --force-limit "
                                     "stands over it)", "nonneg")
    material: str = P("carbide", "str", "tool material: carbide | hss (its stiffness, strength and chip-load share, "
                                        "docs/catalogue.md)", "choice", ("carbide", "hss"))
    price: float = P(30.0, "", "price per tool or edge, currency units [E: 30-150 $ carbide end mill]", "nonneg")
    taylor_n: float = P(0.35, "", "Taylor exponent n in V*T^n = C [E: aluminium 0.3-0.4]", hi=1.0)
    taylor_c: float = P(1300.0, "", "Taylor constant C, m/min for T in min [E: aluminium 1100-1500]")
    # the tool tip's dynamics (docs/chatter.md): [[tools.N.modes]] tables, or a tap test's FRF
    modes: tuple = field(default=(), metadata={"unit": "modes", "check": "modes", "choices": (),
                                                "doc": "tool-tip modes: [[tools.N.modes]] direction, fn, zeta, k|m"})
    frf: str = P("", "str", "a tap test's FRF file (CSV or CutPro text, relative to the twin file): the tool "
                            "tip's compliance in X and Y; stands over the modes", "any")

    @property
    def radius(self) -> float:
        return 0.5 * self.diameter

    @property
    def tip_radius(self) -> float:
        """A vee tool's flat tip radius (0 for the others)."""
        return 0.5 * self.tip_diameter if self.type == "vee" else 0.0

    @property
    def cot_half_angle(self) -> float:
        """cot of a vee tool's half angle: the cone's rise per mm of radius (0: no cone)."""
        return 1.0 / math.tan(self.half_angle) if self.type == "vee" else 0.0

    @property
    def half_angle(self) -> float:
        """A vee tool's half angle, radians (0: no cone)."""
        return math.radians(0.5 * self.angle) if self.type == "vee" else 0.0

    @property
    def nose_radius(self) -> float:
        """Radius of the rounded bottom edge: 0 flat, D/2 ball, the corner radius for bull."""
        if self.type == "ball":
            return self.radius
        if self.type == "bull":
            return self.corner_radius
        return 0.0


@dataclass(frozen=True)
class Material:
    ktc: float = P(1230.0, "N/mm^2", "tangential cutting coefficient")
    krc: float = P(615.0, "N/mm^2", "radial cutting coefficient", "nonneg")
    kac: float = P(0.0, "N/mm^2", "axial cutting coefficient", "nonneg")
    kte: float = P(0.0, "N/mm", "tangential edge coefficient", "nonneg")
    kre: float = P(0.0, "N/mm", "radial edge coefficient", "nonneg")
    kae: float = P(0.0, "N/mm", "axial edge coefficient", "nonneg")
    source: str = P("", "str", "where the values come from", "any")

    @property
    def coefficients(self) -> tuple:
        """(ktc, krc, kac, kte, kre, kae): the order the kernels and the fast model read them in."""
        return (self.ktc, self.krc, self.kac, self.kte, self.kre, self.kae)


# PHYSICS.md section 1 table: the materials whose mechanistic coefficients were identified
# (the catalogue's other materials are fitted to their Kienzle constants: catalogue.py)
BUILTIN_MATERIALS = {
    "al6061": Material(1230.0, 615.0, 0.0, 0.0, 0.0, 0.0,
                       "[S] reference identification, 6 mm 2-flute carbide: Kt = 1.23e9 N/m^2, Ke = 0.50 "
                       "(Krc = Ke*Kt); axial and edge terms not identified (0)"),
    "al7075": Material(767.0, 168.8, 222.0, 27.7, 26.6, 0.7, "[S] Al 7075-T6 dry, CJME review 2021, Table 5"),
    "al6082": Material(631.0, 99.0, 273.0, 13.0, 10.0, 2.8, "[S] Al 6082-T6, CJME review 2021"),
}


def material_key(name: str, custom=()) -> str | None:
    """A twin file's or a user's material name as the key of ``custom`` ([materials.*]) or of
    the catalogue (any of its names: ``AL6061``, ``mild steel``, ``42CrMo4``), or None."""
    if name in custom:
        return name
    from .catalogue import find

    return find(name)


@dataclass(frozen=True)
class Cutting:
    """The cutting part of a twin: tools, material, stock and resolution."""

    tools: dict[int, Tool] = field(default_factory=dict)  # empty: every tool is the default
    material_name: str = "al6061"
    material: Material = BUILTIN_MATERIALS["al6061"]
    stock: tuple[float, ...] | None = None
    resolution: float = 0.0  # 0: automatic (smallest tool diameter / 120, within 0.02..0.1 mm)
    step: float = 0.0  # 0: automatic (twice the resolution)
    spindle_loss: tuple[float, float, float] = (0.0, 0.0, 0.0)  # W: a + b*n + c*n^2 (n in rpm)
    defaults_used: tuple[str, ...] = ()
    # with no tool table in the twin file: the tools the program's comments declare (the rest
    # are the default tool); see for_program
    program_tools: dict[int, Tool] = field(default_factory=dict)
    # tools declared on the command line (``--tool N=TYPE:DIAMETER[:FLUTES]``): over the
    # twin file's table and the program's comments
    declared: dict[int, Tool] = field(default_factory=dict)
    # where each program tool's description was read: number -> (comment line, form); see for_program
    program_tool_lines: dict[int, tuple] = field(default_factory=dict)
    # where the material was named: "" (nobody did: the default al6061), "twin file",
    # "--material" or "program line N (FORM)" — a known material gives physics limits
    material_from: str = ""

    def tool(self, number: int, where: str = "") -> Tool:
        if number in self.declared:
            return self.declared[number]
        if not self.tools:
            return self.program_tools.get(number, Tool())
        if number not in self.tools:
            raise ConfigError(f"{where}tool T{number} is not in the tool table [tools.*] of the twin file "
                              f"(has {', '.join(f'T{k}' for k in sorted(self.tools))})")
        return self.tools[number]


def describes(cutting: Cutting, number: int) -> bool:
    """Whether the twin knows tool ``number`` (the command line, the twin file's table or the
    program's comments describe it) rather than standing the default end mill in for it.
    Call on the cutting part of one program (``for_program``)."""
    return number in cutting.declared or number in cutting.tools or number in cutting.program_tools


def parse_tool_option(text: str) -> tuple[int, Tool]:
    """``N=TYPE:DIAMETER[:FLUTES[:MORE]]`` (``--tool``), lengths in mm: ``3=flat:6.35:2``,
    ``1=ball:10``, ``2=bull:12:4:1.5`` (a bull-nose's corner radius), ``4=vee:6.35:2:60:0.2``
    (a vee tool's included angle in degrees, then its tip diameter)."""
    num = r"([0-9.eE+-]+)"
    m = re.fullmatch(r"\s*T?(\d+)\s*=\s*([A-Za-z]+)\s*:\s*" + num + r"(?:\s*:\s*(\d+))?(?:\s*:\s*" + num
                     + r")?(?:\s*:\s*" + num + r")?\s*", text)
    if not m:
        raise ConfigError(f"--tool {text!r}: expected N=TYPE:DIAMETER[:FLUTES[:CORNER_RADIUS | :ANGLE[:TIP]]] (mm, "
                          f"degrees), e.g. 1=flat:6:2, 3=bull:12:4:1.5 or 4=vee:6.35:2:60:0.2")
    typ = m.group(2).lower()
    if typ not in TOOL_TYPES:
        raise ConfigError(f"--tool {text!r}: type must be one of {', '.join(TOOL_TYPES)} (the shapes the cutting "
                          f"model represents), got {typ!r}")
    try:
        d = float(m.group(3))
        x5 = float(m.group(5)) if m.group(5) else None
        x6 = float(m.group(6)) if m.group(6) else None
    except ValueError:
        raise ConfigError(f"--tool {text!r}: the sizes must be numbers (mm, degrees)") from None
    if not (0 < d < 1000 and math.isfinite(d)):
        raise ConfigError(f"--tool {text!r}: the diameter must be a positive number of mm under 1000")
    flutes = int(m.group(4)) if m.group(4) else 2
    if not 1 <= flutes <= 64:
        raise ConfigError(f"--tool {text!r}: flutes must be 1 to 64")
    if typ == "bull":
        if x5 is None or not 0 < x5 < d / 2 or x6 is not None:
            raise ConfigError(f"--tool {text!r}: a bull-nose tool needs a corner radius between 0 and D/2 (fifth "
                              f"field)")
        return int(m.group(1)), Tool(type=typ, diameter=d, flutes=flutes, corner_radius=x5)
    if typ == "vee":
        angle = 90.0 if x5 is None else x5
        tip = 0.0 if x6 is None else x6
        _check_vee(angle, tip, d, f"--tool {text!r}")
        return int(m.group(1)), Tool(type=typ, diameter=d, flutes=flutes, angle=angle, tip_diameter=tip)
    if x5 is not None:
        raise ConfigError(f"--tool {text!r}: a {typ} tool takes TYPE:DIAMETER[:FLUTES] only")
    return int(m.group(1)), Tool(type=typ, diameter=d, flutes=flutes)


def _check_vee(angle: float, tip: float, diameter: float, where: str) -> None:
    if not 0 < angle < 180:
        raise ConfigError(f"{where}: a vee tool's included angle must be between 0 and 180 degrees, got {angle:g}")
    if not 0 <= tip < diameter:
        raise ConfigError(f"{where}: a vee tool's tip diameter must be at least 0 and under its diameter "
                          f"{diameter:g} mm, got {tip:g}")


def cutting_param_names(cutting: Cutting) -> list[str]:
    """The cutting part's numeric parameters by dotted name: the active material's
    coefficients (``cutting.<material>.ktc``) and each table tool's (``tools.<n>.diameter``)."""
    out = [f"cutting.{cutting.material_name}.{f.name}" for f in fields(Material) if f.name != "source"]
    for n, t in sorted(cutting.tools.items()):
        out += [f"tools.{n}.{f.name}" for f in fields(Tool) if isinstance(getattr(t, f.name), (int, float))]
        if t.modes:
            from ..chatter.modes import mode_param_names

            out += mode_param_names(n, t.modes)
    return out


def cutting_param(cutting: Cutting, name: str) -> float:
    if _is_mode_param(name):
        from ..chatter.modes import mode_param

        n, d, j, p = _mode_key(cutting, name)
        return mode_param(cutting.tools[n].modes, d, j, p, name)
    obj, field_name = _cutting_target(cutting, name)
    return float(getattr(obj, field_name))


def with_cutting_params(cutting: Cutting, values: dict) -> Cutting:
    """A copy with cutting parameters changed by dotted name (see ``cutting_param_names``)."""
    for name, value in values.items():
        if _is_mode_param(name):
            from ..chatter.modes import with_mode_param

            n, d, j, p = _mode_key(cutting, name)
            tool = cutting.tools[n]
            cutting = replace(cutting, tools={**cutting.tools, n: replace(
                tool, modes=with_mode_param(tool.modes, d, j, p, value, name))})
            continue
        obj, field_name = _cutting_target(cutting, name)
        meta = {f.name: f for f in fields(obj)}[field_name].metadata
        new = replace(obj, **{field_name: _check(value, meta, name)})
        if isinstance(obj, Material):
            cutting = replace(cutting, material=new)
        else:
            n = int(name.split(".")[1])
            cutting = replace(cutting, tools={**cutting.tools, n: new})
    return cutting


def _is_mode_param(name: str) -> bool:
    parts = name.split(".")
    return len(parts) == 6 and parts[0] == "tools" and parts[2] == "modes"


def _mode_key(cutting: Cutting, name: str):
    """``tools.N.modes.D.J.P`` -> (N, D, J, P): the J-th mode (from 0) in direction D."""
    parts = name.split(".")
    if not (parts[1].isdigit() and parts[3] in ("x", "y") and parts[4].isdigit()):
        raise ConfigError(f"{name}: a mode parameter is tools.<n>.modes.<x|y>.<index>.<fn|zeta|k>")
    n = int(parts[1])
    if n not in cutting.tools or not cutting.tools[n].modes:
        raise ConfigError(f"{name}: tool T{n} has no modes in the twin file's tool table")
    return n, parts[3], int(parts[4]), parts[5]


def _cutting_target(cutting: Cutting, name: str):
    parts = name.split(".")
    if len(parts) == 3 and parts[0] == "cutting":
        mat = parts[1] if parts[1] == cutting.material_name else material_key(parts[1])
        if mat != cutting.material_name:
            raise ConfigError(f"{name}: the twin cuts {cutting.material_name} (cutting.{cutting.material_name}.<coefficient>)")
        if parts[2] not in {f.name for f in fields(Material)} - {"source"}:
            raise ConfigError(f"{name}: no coefficient {parts[2]!r} (ktc krc kac kte kre kae)")
        return cutting.material, parts[2]
    if len(parts) == 3 and parts[0] == "tools" and parts[1].isdigit():
        n = int(parts[1])
        if n not in cutting.tools:
            raise ConfigError(f"{name}: tool T{n} is not in the twin file's tool table"
                              + ("" if cutting.tools else " (it has none: tools come from the program or the default)"))
        if parts[2] not in {f.name for f in fields(Tool)}:
            raise ConfigError(f"{name}: a tool has no {parts[2]!r}")
        return cutting.tools[n], parts[2]
    raise ConfigError(f"unknown cutting parameter {name!r} (cutting.<material>.<coefficient> or tools.<n>.<field>)")


@functools.lru_cache(maxsize=8)
def _scan(data: bytes):
    # an optimiser re-simulates one program many times, each time as a new Program object
    from .tool_comments import scan_tool_comments

    return scan_tool_comments(data)


class ProgramCuttings:
    """Each program's cutting set-up (``for_program``), per cutting part it was made from: a
    twin owns one (``Twin.cutting_cache``, shared by its copies), so a program loaded once is
    read for its tools once.  An entry lives as long as its program, and holds the set-ups of
    the last ``PER_PROGRAM`` cutting parts it met: a calibration that tries a twin copy per
    evaluation (each with a cutting part of its own) keeps a few, not one per evaluation."""

    PER_PROGRAM = 4

    def __init__(self):
        self._entries: dict = {}

    def get(self, program, cutting: Cutting) -> Cutting | None:
        e = self._entries.get(id(program))
        if e is None or e[0]() is not program:
            return None
        hit = e[1].get(id(cutting))
        if hit is None or hit[0] is not cutting:
            return None
        e[1].move_to_end(id(cutting))
        return hit[1]

    def put(self, program, cutting: Cutting, cut: Cutting) -> None:
        import weakref
        from collections import OrderedDict

        key, entries = id(program), self._entries
        e = entries.get(key)
        if e is None or e[0]() is not program:
            e = entries[key] = (weakref.ref(program, lambda _ref: entries.pop(key, None)), OrderedDict())
        parts = e[1]
        parts[id(cutting)] = (cutting, cut)  # (the cutting part held: its id stays its own)
        parts.move_to_end(id(cutting))
        while len(parts) > self.PER_PROGRAM:
            parts.popitem(last=False)

    def __len__(self) -> int:
        """The set-ups held, over every live program."""
        return sum(len(e[1]) for e in self._entries.values() if e[0]() is not None)


def for_program(cutting: Cutting, program) -> Cutting:
    """The cutting part for one program: a twin file's tool table stands; without one, the
    tools the program's comments declare (CAM post-processors write them: Fusion 360's
    ``(T1 D=6 CR=0 - flat end mill)``, Mastercam's tool table, …) replace the default tool,
    and ``defaults_used`` says for each tool the program uses where its description came from.
    A material the program's comments name (``cutting.workpiece``) stands over the twin
    file's catalogue name (not over ``--material``, nor over a twin file's own
    [materials.*]), and a single-tool program's title comment describes its tool."""
    from .workpiece import read_workpiece

    wp = read_workpiece(program)
    cutting = _program_material(cutting, wp)
    if cutting.tools:
        if cutting.declared:
            used = sorted(set(int(t) for t in program.records["tool"]))
            notes = [f"tool T{t}: {cutting.declared[t].diameter:g} mm {cutting.declared[t].type}, "
                     f"{cutting.declared[t].flutes} flutes, from --tool" for t in used if t in cutting.declared]
            return replace(cutting, defaults_used=tuple(notes) + cutting.defaults_used)
        return cutting
    from .tool_comments import to_library_tool

    used = sorted(set(int(t) for t in program.records["tool"]))
    found = _scan(bytes(program.data))
    tools: dict[int, Tool] = {}
    notes = []
    only = None
    if used == [0] and len(found.tools) == 1:
        # no M6 at all (a router's single spindle): the one tool the program declares and
        # selects with a bare T word is the one in the spindle
        only = next(iter(found.tools.values()))
    lines = {}
    for t in used:
        if t in cutting.declared:
            lib = cutting.declared[t]
            notes.append(f"tool T{t}: {lib.diameter:g} mm {lib.type}, {lib.flutes} flutes, from --tool")
            continue
        d = found.tools.get(t) if only is None else only
        lib = to_library_tool(d) if d is not None else None
        if d is None and wp.tool is not None and len(used) == 1:
            lib = wp.tool.value
            tools[t] = lib
            lines[t] = (wp.tool.line, wp.tool.form)
            notes.append(f"tool T{t}: {lib.diameter:g} mm {lib.type} end mill, {lib.flutes} flutes, {lib.material}, "
                         f"from the program's title comment line {wp.tool.line} ({wp.tool.text})")
            continue
        if lib is not None:
            tools[t] = lib
            lines[t] = (d.line, d.form)
            shape = {"flat": "flat end mill", "ball": "ball end mill", "bull": f"bull-nose end mill, corner "
                     f"radius {lib.corner_radius:g} mm", "vee": f"{lib.angle:g}° vee (V-bit/engraving/chamfer), tip "
                     f"{lib.tip_diameter:g} mm"}[lib.type]
            flutes = f"{lib.flutes} flutes" + ("" if d.flutes else " (not given: default)")
            held = "" if only is None else f" (no M6: T{only.number}, the program's one tool, is in the spindle)"
            notes.append(f"tool T{t}: {lib.diameter:g} mm {shape}, {flutes}, from the program's comment "
                         f"line {d.line} ({d.form}){held}")
        elif d is not None:
            notes.append(f"tool T{t}: declared as {d.kind} {d.diameter_mm:g} mm (line {d.line}), which the "
                         f"cutting model cannot represent: simulated as the default 6 mm flat end mill")
        elif t > 0 or len(used) == 1:
            notes.append(f"tool T{t}: no description in the program or the twin file: the default 6 mm "
                         f"two-flute carbide flat end mill")
    rest = [d for d in cutting.defaults_used if not d.startswith("tool:")]
    return replace(cutting, program_tools=tools, defaults_used=tuple(notes + rest), program_tool_lines=lines)


def _program_material(cutting: Cutting, wp) -> Cutting:
    """The material the program's comments name, over a twin file's catalogue name."""
    f = wp.material
    if f is None or cutting.material_from == "--material" or (
            cutting.material_from == "twin file" and material_key(cutting.material_name) != cutting.material_name):
        return cutting
    return _named_material(cutting, f.value, f"program line {f.line} ({f.form})",
                           f"the program's comment line {f.line} ({f.text})")


def tools_used(cutting: Cutting, program) -> list[dict]:
    """The tools a program's feed moves use, as data: ``number``, ``type``, ``diameter``,
    ``flutes``, ``corner_radius`` (mm), ``angle`` and ``tip_diameter`` (vee tools), ``source``
    (``--tool``, ``twin file``, ``program comment`` or ``default``), ``line`` and ``form`` of
    a program comment.  Call on the cutting part of the program (``for_program``)."""
    from ..gcode import records as R

    rec = program.records
    used = sorted(set(int(t) for t in rec["tool"][R.is_feed_kind(rec["kind"])]))
    out = []
    for t in used:
        tool = cutting.tool(t) if (t in cutting.declared or t in cutting.tools or not cutting.tools) else None
        if tool is None:
            continue
        entry = {"number": t, "type": tool.type, "diameter": tool.diameter, "flutes": tool.flutes,
                 "corner_radius": tool.nose_radius}  # (a ball's is its radius)
        if tool.type == "vee":
            entry.update(angle=tool.angle, tip_diameter=tool.tip_diameter)
        if t in cutting.declared:
            entry.update(source="--tool", line=None)
        elif t in cutting.tools:
            entry.update(source="twin file", line=None)
        elif t in cutting.program_tools:
            line, form = cutting.program_tool_lines.get(t, (None, None))
            entry.update(source="program comment", line=line, form=form)
        else:
            entry.update(source="default", line=None)
        out.append(entry)
    return out


def _parse(cls, table, prefix, where):
    if not isinstance(table, dict):
        raise ConfigError(f"{where}: [{prefix}] must be a table")
    known = {f.name: f for f in fields(cls)}
    values = {}
    for key, value in table.items():
        if key not in known:
            raise ConfigError(f"{where}: unknown key {prefix}.{key} (known: {', '.join(known)})")
        meta = known[key].metadata
        if meta["check"] == "modes":
            from ..chatter.modes import parse_modes

            values[key] = parse_modes(value, f"{where}: {prefix}.{key}")
        elif meta["check"] == "any":
            values[key] = str(value)
        else:
            try:
                values[key] = _check(value, meta, f"{prefix}.{key}")
            except ConfigError as exc:
                raise ConfigError(f"{where}: {exc}") from None
    return values


def cutting_from_dict(raw: dict, where: str = "twin file") -> Cutting:
    """Tools, materials and [cutting] of a parsed twin file."""
    defaults = []
    materials = {}
    for name, body in raw.get("materials", {}).items():
        values = _parse(Material, body, f"materials.{name}", where)
        if "ktc" not in values:
            raise ConfigError(f"{where}: materials.{name}: needs at least ktc (tangential cutting coefficient, N/mm^2)")
        base = Material(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, "")
        materials[name] = replace(base, **values)
    tools = {}
    for key, body in raw.get("tools", {}).items():
        if not str(key).isdigit():
            raise ConfigError(f"{where}: tools.{key}: tool numbers are non-negative integers")
        values = _parse(Tool, body, f"tools.{key}", where)
        t = replace(Tool(), **values)
        if t.type == "bull" and not 0 < t.corner_radius < t.radius:
            raise ConfigError(f"{where}: tools.{key}.corner_radius must be between 0 and diameter/2 for a bull-nose tool")
        if t.type == "flat" and t.corner_radius:
            raise ConfigError(f"{where}: tools.{key}.corner_radius is only for type = \"bull\"")
        if t.type == "vee":
            _check_vee(t.angle, t.tip_diameter, t.diameter, f"{where}: tools.{key}")
        if t.frf:
            from pathlib import Path

            from ..chatter.modes import read_frf

            base = (Path(where).parent if where not in ("twin file", "") else Path(".")).resolve()
            path = str((base / t.frf).resolve())
            # a twin file names files beside it: one that reaches elsewhere (../../secret.env, an
            # absolute path) could put another file's content into a batch's report; the user
            # running the command allows it, not the file (docs/conventions.md)
            if not Path(path).is_relative_to(base) and os.environ.get("MTWIN_TRUST_TWIN_PATHS") != "1":
                raise ConfigError(f"{where}: tools.{key}.frf = {t.frf!r} is outside the twin file's folder ({base}); "
                                  f"put the FRF beside the twin file, or set MTWIN_TRUST_TWIN_PATHS=1 to allow it")
            read_frf(path)  # (a bad file is an error of the twin file, now)
            t = replace(t, frf=path)
        tools[int(key)] = t
    if not tools:
        defaults.append("tool: every tool is a 6 mm two-flute carbide flat end mill (no [tools.*] table)")
    cut = raw.get("cutting", {})
    if not isinstance(cut, dict):
        raise ConfigError(f"{where}: [cutting] must be a table")
    known = {"material", "stock", "resolution", "step", "spindle_loss"}
    for key in cut:
        if key not in known:
            raise ConfigError(f"{where}: unknown key cutting.{key} (known: {', '.join(sorted(known))})")
    given = cut.get("material", "al6061")
    if "material" not in cut:
        defaults.append("material: al6061 with the reference's Kt = 1230 N/mm^2, Ke = 0.50 (no material named: "
                        "optimize learns its limits from the program)")
    if not isinstance(given, str):
        raise ConfigError(f"{where}: cutting.material must be a name (a string), got {given!r}")
    name = material_key(given, materials)
    if name is None:
        from .catalogue import known_list

        raise ConfigError(f"{where}: cutting.material: no coefficients for {given!r} "
                          f"(the catalogue knows: {known_list()}; or define [materials.{given}])")
    mat = materials[name] if name in materials else _catalogue_material(name)
    stock = None
    if "stock" in cut:
        stock = parse_box(cut["stock"], f"{where}: cutting.stock")
    res = _check(cut["resolution"], {"unit": "mm", "check": "positive", "choices": ()}, "cutting.resolution") \
        if "resolution" in cut else 0.0
    step = _check(cut["step"], {"unit": "mm", "check": "positive", "choices": ()}, "cutting.step") \
        if "step" in cut else 0.0
    loss = (0.0, 0.0, 0.0)
    if "spindle_loss" in cut:
        v = cut["spindle_loss"]
        if not (isinstance(v, list) and len(v) == 3 and all(isinstance(x, (int, float)) for x in v)):
            raise ConfigError(f"{where}: cutting.spindle_loss: expected [a, b, c] for a + b*n + c*n^2 W (n in rpm)")
        loss = tuple(float(x) for x in v)
        # (the loss at 10,000 rpm within the 10 MW any spindle has: 1e99 is a typo, not a drive)
        if not abs(loss[0]) + abs(loss[1]) * 1e4 + abs(loss[2]) * 1e8 <= 1e7:
            raise ConfigError(f"{where}: cutting.spindle_loss {list(loss)}: a loss beyond what a real spindle has "
                              f"(over 10 MW at 10,000 rpm): a typo or a unit mistake?")
    return Cutting(tools, name, mat, stock, res, step, loss, tuple(defaults),
                   material_from="twin file" if "material" in cut else "")


def _catalogue_material(key: str) -> Material:
    from .catalogue import material_coefficients

    return material_coefficients(key)


def with_material(cutting: Cutting, name: str, where: str) -> Cutting:
    """The cutting part cutting ``name`` (a catalogue name), said to come from ``where``."""
    from .catalogue import resolve

    key = resolve(name, where if where == "--material" else f"{where}: material")
    return _named_material(cutting, key, where, where)


def _named_material(cutting: Cutting, key: str, where: str, said: str) -> Cutting:
    """The cutting part cutting catalogue material ``key``, named at ``where`` (its
    ``material_from``), with a note that it was read from ``said``.  The same material as the
    twin's keeps the twin's coefficients (a calibration's)."""
    from .catalogue import catalogue

    rest = tuple(d for d in cutting.defaults_used if not d.startswith("material:"))
    mat = cutting.material if key == cutting.material_name else _catalogue_material(key)
    note = f"material: {key} ({catalogue().materials[key].title}) from {said}"
    return replace(cutting, material_name=key, material=mat, material_from=where, defaults_used=rest + (note,))


def parse_box(value, key: str) -> tuple[float, ...]:
    """xmin, ymin, zmin, xmax, ymax, zmax from a list or a 'a,b,c,d,e,f' string."""
    if isinstance(value, str):
        try:
            value = [float(x) for x in value.replace(" ", "").split(",")]
        except ValueError:
            raise ConfigError(f"{key}: expected six numbers xmin,ymin,zmin,xmax,ymax,zmax (mm)") from None
    if not (isinstance(value, (list, tuple)) and len(value) == 6
            and all(isinstance(x, (int, float)) and math.isfinite(x) for x in value)):
        raise ConfigError(f"{key}: expected six numbers xmin,ymin,zmin,xmax,ymax,zmax (mm)")
    box = tuple(float(x) for x in value)
    if not (box[0] < box[3] and box[1] < box[4] and box[2] < box[5]):
        raise ConfigError(f"{key}: each min must be below its max, got {box}")
    return box
