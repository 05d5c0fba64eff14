"""The cutting-data catalogue: what a shop knows about the material it cuts and the tools it
cuts with, turned into the twin's coefficients and into limits (docs/catalogue.md).

* **Work materials** (``data/catalogue.toml``, ``[materials.*]``): Kienzle's specific
  cutting force ``kc = kc11·h^-mc`` and the chip-load row for the material's group, each with
  its source.  The twin's force model is linear in the chip (``Ft = Ktc·b·h + Kte·b``), so
  the Kienzle curve is fitted by a line over the chips end mills run at (``KIENZLE_FIT``);
  entries whose mechanistic coefficients were identified (al6061, al7075, al6082) keep them.
* **Chip load per tooth** by diameter for solid carbide (``[chip.*]``), linear between the
  published diameters, proportional to the diameter below the smallest and constant above
  the largest.  It is the largest chip thickness h_max the tool may see: with a radial
  width under the radius the optimiser's chip limit (on h_max, not on f_z) gives the
  radial chip-thinning allowance by itself.
* **Tool materials** (``[tool_materials.*]``): the shank as a cantilever of the effective
  diameter ``SHANK_SHARE·D`` and the stick-out ``L`` — bending stress
  ``σ = 32·F·L/(π·d³)`` against a share of the material's strength (breakage), tip
  deflection ``δ = F·L³/(3·E·I)``, ``I = π·d⁴/64``.

Nothing here imports numba or the simulator: ``mtwin materials`` lists the catalogue at once.
"""
from __future__ import annotations

import functools
import math
import re
from dataclasses import dataclass
from importlib import resources

from ..errors import ConfigError

#: the Kienzle curve is fitted over the chips the material's tools run at: from half the
#: smallest chip load of its row (not under KIENZLE_FIT_FROM mm, a finishing pass's chip) to
#: the largest (0.01-0.12 mm steel, 0.01-0.16 aluminium, 0.048-0.51 MDF)
KIENZLE_FIT_FROM = 0.01
#: Krc/Ktc of a Kienzle-derived material: the reference identification's Ke = 0.50 (al6061,
#: docs/physics.md §1) [E for other materials]; the radial edge force as the tangential one
RADIAL_SHARE = 0.5
#: the effective diameter of a fluted shank, a share of the cutting diameter [E, PHYSICS.md]
SHANK_SHARE = 0.8
#: stick-out when the tool table gives none: 4 x D [E: standard-length end mills stand 3-5 D
#: out of the holder]
STICKOUT_PER_DIAMETER = 4.0


@dataclass(frozen=True)
class WorkMaterial:
    key: str
    title: str
    iso: str
    names: tuple
    kc11: float  # N/mm^2
    mc: float
    kc_source: str
    chip: str  # the [chip.*] row
    builtin: bool  # mechanistic coefficients identified (library.BUILTIN_MATERIALS), not fitted


@dataclass(frozen=True)
class ChipRow:
    key: str
    diameter: tuple
    fz: tuple
    source: str


@dataclass(frozen=True)
class ToolMaterial:
    key: str
    youngs_modulus: float  # N/mm^2
    strength: float  # N/mm^2
    allowed_share: float
    chip_factor: float
    youngs_modulus_source: str  # a [sources] key
    strength_source: str

    @property
    def allowed_stress(self) -> float:
        return self.allowed_share * self.strength


@dataclass(frozen=True)
class Catalogue:
    materials: dict  # key -> WorkMaterial
    chips: dict  # key -> ChipRow
    tool_materials: dict  # key -> ToolMaterial
    sources: dict  # key -> citation

    def source_text(self, ref: str) -> str:
        """A value's source spelt out: ``freecad: MildSteel.FCMat …`` -> the citation + detail."""
        head, _, rest = ref.partition(":")
        base = self.sources.get(head.strip())
        if base is None:
            return ref
        return base + (f"; {rest.strip()}" if rest.strip() else "")


def _raw() -> dict:
    """The catalogue file parsed; the parse (30 ms of pure-Python TOML) kept in the user's cache
    under the file's hash, so a command pays it once per catalogue version."""
    import hashlib
    import os
    import pickle

    data = resources.files("mtwin").joinpath("data/catalogue.toml").read_bytes()
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    path = os.path.join(base, "mtwin", f"catalogue-{hashlib.sha1(data).hexdigest()[:16]}.pickle")
    try:
        with open(path, "rb") as f:
            return pickle.load(f)
    except (OSError, pickle.UnpicklingError, EOFError, AttributeError, ValueError):
        pass
    from ..config import tomllib

    raw = tomllib.loads(data.decode("utf-8"))
    try:  # (atomically: a reader never sees half a file)
        os.makedirs(os.path.dirname(path), exist_ok=True)
        tmp = f"{path}.{os.getpid()}.tmp"
        with open(tmp, "wb") as f:
            pickle.dump(raw, f)
        os.replace(tmp, path)
    except OSError:
        pass
    return raw


@functools.lru_cache(maxsize=1)
def catalogue() -> Catalogue:
    raw = _raw()
    mats = {}
    for key, m in raw["materials"].items():
        mats[key] = WorkMaterial(key, m["title"], m["iso"], tuple(m["names"]), float(m["kc11"]), float(m["mc"]),
                                 m["kc_source"], m["chip"], m.get("coefficients") == "builtin")
    chips = {k: ChipRow(k, tuple(c["diameter"]), tuple(c["fz"]), c["source"]) for k, c in raw["chip"].items()}
    tms = {k: ToolMaterial(k, float(t["youngs_modulus"]), float(t["strength"]), float(t["allowed_share"]),
                           float(t["chip_factor"]), t["youngs_modulus_source"], t["strength_source"])
           for k, t in raw["tool_materials"].items()}
    return Catalogue(mats, chips, tms, dict(raw["sources"]))


def _norm(name: str) -> str:
    return re.sub(r"[^a-z0-9.]", "", name.lower())


@functools.lru_cache(maxsize=1)
def _name_index() -> dict:
    out = {}
    for key, m in catalogue().materials.items():
        for n in (key,) + m.names:
            out.setdefault(_norm(n), key)
    return out


def find(name: str) -> str | None:
    """The catalogue key a user's or a program's name for a material stands for, or None."""
    return _name_index().get(_norm(name))


def resolve(name: str, where: str = "--material") -> str:
    """``find``, or an error that lists the known materials."""
    key = find(name)
    if key is None:
        raise ConfigError(f"{where}: unknown material {name!r}; the catalogue knows: {known_list()} "
                          f"(mtwin materials lists them with their sources; or define [materials.NAME] in the "
                          f"twin file)")
    return key


def known_list() -> str:
    return ", ".join(catalogue().materials)


def fit_range(key: str) -> tuple[float, float]:
    cat = catalogue()
    fz = cat.chips[cat.materials[key].chip].fz
    return max(KIENZLE_FIT_FROM, 0.5 * min(fz)), max(fz)


def kienzle_linear(kc11: float, mc: float, fit: tuple) -> tuple[float, float]:
    """(Ktc N/mm^2, Kte N/mm): the least-squares line ``Ktc·h + Kte`` through the Kienzle
    force per mm of edge ``kc11·h^(1-mc)`` over chips ``fit`` (mm, 64 log-spaced points:
    small chips count as much as large ones)."""
    n = 64
    lo, hi = math.log(fit[0]), math.log(fit[1])
    hs = [math.exp(lo + (hi - lo) * i / (n - 1)) for i in range(n)]
    ys = [kc11 * h ** (1.0 - mc) for h in hs]
    mh, my = sum(hs) / n, sum(ys) / n
    sxx = sum((h - mh) ** 2 for h in hs)
    sxy = sum((h - mh) * (y - my) for h, y in zip(hs, ys))
    ktc = sxy / sxx
    return ktc, my - ktc * mh


def material_coefficients(key: str):
    """The twin's ``library.Material`` for a catalogue key: the identified coefficients where
    the entry has them, else fitted to its Kienzle constants."""
    from .library import BUILTIN_MATERIALS, Material

    m = catalogue().materials[key]
    if m.builtin:
        return BUILTIN_MATERIALS[key]
    fit = fit_range(key)
    ktc, kte = kienzle_linear(m.kc11, m.mc, fit)
    src = catalogue().source_text(m.kc_source)
    return Material(ktc, RADIAL_SHARE * ktc, 0.0, kte, kte, 0.0,
                    f"fitted to Kienzle kc1.1 = {m.kc11:g} N/mm^2, mc = {m.mc:g} over h = {fit[0]:g}-"
                    f"{fit[1]:g} mm (Krc = {RADIAL_SHARE:g} Ktc, Kre = Kte [E]); {src}")


def chip_load(key: str, diameter: float, tool_material: str = "carbide") -> float:
    """Recommended chip load per tooth (mm) — the largest chip thickness — for a tool of
    ``diameter`` mm in catalogue material ``key``."""
    cat = catalogue()
    row = cat.chips[cat.materials[key].chip]
    d, fz = row.diameter, row.fz
    if diameter <= d[0]:
        h = fz[0] * diameter / d[0]
    elif diameter >= d[-1]:
        h = fz[-1]
    else:
        i = next(k for k in range(1, len(d)) if diameter <= d[k])
        h = fz[i - 1] + (fz[i] - fz[i - 1]) * (diameter - d[i - 1]) / (d[i] - d[i - 1])
    return h * cat.tool_materials[tool_material].chip_factor


def chip_source(key: str) -> str:
    cat = catalogue()
    row = cat.chips[cat.materials[key].chip]
    return f"[chip.{row.key}] {cat.source_text(row.source)}"


# ---------------------------------------------------------------------- the shank as a cantilever

def stickout(tool) -> float:
    """The tool's stick-out, mm: the tool table's, or ``STICKOUT_PER_DIAMETER`` diameters."""
    return tool.stickout if tool.stickout > 0 else STICKOUT_PER_DIAMETER * tool.diameter


def shank_diameter(tool) -> float:
    return SHANK_SHARE * tool.diameter


def bending_stress(tool, force: float) -> float:
    """N/mm^2 at the holder of a cantilever of the shank's effective diameter under a side
    force ``force`` (N) at the tip: ``32·F·L/(π·d³)``."""
    d = shank_diameter(tool)
    return 32.0 * force * stickout(tool) / (math.pi * d ** 3)


def breaking_force(tool) -> float:
    """The side force (N) at which the shank's bending stress reaches the allowed share of its
    material's strength."""
    tm = catalogue().tool_materials[tool.material]
    d = shank_diameter(tool)
    return tm.allowed_stress * math.pi * d ** 3 / (32.0 * stickout(tool))


def stiffness(tool) -> float:
    """N/mm at the tip: ``3·E·I/L³``, ``I = π·d⁴/64``."""
    tm = catalogue().tool_materials[tool.material]
    d = shank_diameter(tool)
    inertia = math.pi * d ** 4 / 64.0
    return 3.0 * tm.youngs_modulus * inertia / stickout(tool) ** 3


def deflection(tool, force: float) -> float:
    """mm the tip gives way under ``force`` N."""
    return force / stiffness(tool)


def shank_checks(cut, program, force, record) -> list[dict]:
    """Per described tool that cuts: its peak side load (N, the XY resultant) and line, the
    shank's bending stress there against the allowed stress, the breaking force and the tip's
    deflection — the closed forms above on the simulated forces."""
    import numpy as np

    from .library import describes

    if force is None or record is None or not len(force):
        return []
    rec = program.records
    ok = record >= 0
    load = np.hypot(force[:, 0].astype(np.float64), force[:, 1].astype(np.float64))
    tool = np.where(ok, rec["tool"][np.maximum(record, 0)], -1)
    out = []
    for t in np.unique(tool[ok & (load > 0)]):
        t = int(t)
        if not describes(cut, t):
            continue
        tl = cut.tool(t)
        m = tool == t
        i = int(np.flatnonzero(m)[np.argmax(load[m])])
        peak = float(load[i])
        tm = catalogue().tool_materials[tl.material]
        sigma = bending_stress(tl, peak)
        out.append({"tool": t, "peak_load": peak, "line": int(rec["line"][record[i]]),
                    "stress": sigma, "allowed_stress": tm.allowed_stress, "strength": tm.strength,
                    "breaking_force": breaking_force(tl), "deflection": deflection(tl, peak),
                    "stickout": stickout(tl), "tool_material": tl.material, "over": sigma > tm.allowed_stress})
    return out
