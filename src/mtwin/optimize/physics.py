"""Limits from physics when the material is known (docs/catalogue.md): per tool the chip
thickness ceiling of the catalogue, the side force that would break the shank, and the side
force that would bend it by more than the tolerance on a final surface.

They replace the limits learned from the program (the program's own levels) for every tool
the twin describes, once a material is named (``--material``, ``cutting.material``, the
program's comments).  Breakage is a limit the program itself may break: the optimiser then
lowers the feed to it and says so.  The chip ceiling and the deflection only cap a raise: a
program that already runs above them keeps its feed there (a shop's proven feed is not
slowed by a chart)."""
from __future__ import annotations

from dataclasses import dataclass

from ..cutting import catalogue as C
from ..cutting.library import describes


@dataclass(frozen=True)
class ToolPhysics:
    tool: int
    diameter: float  # mm
    tool_material: str
    stickout: float  # mm
    chip: float  # mm, the largest chip thickness (catalogue chip load x scale)
    breaking_force: float  # N x scale
    stiffness: float  # N/mm at the tip
    allowed_stress: float  # N/mm^2 (x scale)
    scale: float

    def as_dict(self, material: str) -> dict:
        cat = C.catalogue()
        tm = cat.tool_materials[self.tool_material]
        return {
            "tool": self.tool, "source": "physics", "material": material, "scale": self.scale,
            "chip_thickness": self.chip,
            "chip_thickness_source": f"{C.chip_source(material)} x {self.scale:g}",
            "load": self.breaking_force,
            "load_source": (f"shank breakage: bending stress 32·F·L/(π·d³) at {self.allowed_stress:.0f} N/mm² "
                            f"({tm.allowed_share:g} of {tm.strength:g} N/mm², {self.tool_material}; "
                            f"{cat.source_text(tm.strength_source)}) x {self.scale:g}, "
                            f"d = {C.SHANK_SHARE:g}·D = {C.SHANK_SHARE * self.diameter:.3g} mm, "
                            f"L = {self.stickout:.3g} mm"),
            "stiffness": self.stiffness,
            "stiffness_source": (f"3·E·I/L³, E = {tm.youngs_modulus:g} N/mm² ({self.tool_material}; "
                                 f"{cat.source_text(tm.youngs_modulus_source)})"),
        }


def tool_physics(cut, tools, scale: float = 1.0) -> dict[int, ToolPhysics]:
    """Per described tool of ``tools``: its physics limits in ``cut``'s material (a catalogue
    one), each scaled by ``scale`` (a cautious shop takes 0.8 of the catalogue)."""
    if cut.material_name not in C.catalogue().materials:
        return {}
    out = {}
    for t in tools:
        t = int(t)
        if not describes(cut, t):
            continue
        tool = cut.tool(t)
        tm = C.catalogue().tool_materials[tool.material]
        out[t] = ToolPhysics(t, tool.diameter, tool.material, C.stickout(tool),
                             scale * C.chip_load(cut.material_name, tool.diameter, tool.material),
                             scale * C.breaking_force(tool), C.stiffness(tool), scale * tm.allowed_stress, scale)
    return out
