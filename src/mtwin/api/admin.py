"""The housekeeping use cases: twin files (``mtwin config``), the effects a twin can be given
(``mtwin effects``) and the cutting-data catalogue (``mtwin materials``).  Each returns data;
the command renders it.  (The compiled-kernel cache's, ``mtwin cache``, are in
:mod:`mtwin.warmup`, which runs the use cases to compile their kernels.)"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional


# ---------------------------------------------------------------------- twin files

def twin_toml(twin_file: Optional[str] = None) -> str:
    """``mtwin config show``: the twin file as TOML (the embedded default machine, or the
    file with every default filled in)."""
    from ..config import load_twin_file
    from ..twin.files import load_machine
    from ..twin.machine import machine_toml

    return machine_toml(load_machine(twin_file), load_twin_file(twin_file))


def check_twin(path: str) -> str:
    """``mtwin config check``: every section of a twin file read as a run reads it (machine,
    cutting, effects); the machine's name, or :class:`~mtwin.errors.MtwinError` naming the key."""
    from ..config import load_twin_file
    from ..twin.files import load_cutting, load_effects, load_machine

    load_twin_file(path)
    m = load_machine(path)
    load_cutting(path)
    load_effects(path)
    return m.name


# ---------------------------------------------------------------------- effects

@dataclass(frozen=True)
class EffectInfo:
    """One effect: where it acts (``loop``, ``plan`` or on observation), what it changes and
    its parameters."""

    name: str
    stage: str
    origin: str  # built-in | user
    description: str
    signals: tuple
    params: tuple  # params.Param: name, unit, default, bounds, doc, source

    def as_dict(self) -> dict:
        """What ``mtwin effects --json`` prints for it (the parameters by name)."""
        return {"name": self.name, "stage": self.stage, "origin": self.origin, "description": self.description,
                "signals": list(self.signals), "params": [p.name for p in self.params]}


def _info(c, builtin: set) -> EffectInfo:
    return EffectInfo(c.name, c.stage, "built-in" if c.name in builtin else "user", c.description, tuple(c.signals),
                      tuple(c.params))


def _with_files(effect_files) -> set:
    """The user effects of ``effect_files`` registered; the built-in effects' names."""
    from ..effects import BUILTIN, load_file

    for f in effect_files or ():
        load_file(f)
    return {c.name for c in BUILTIN}


def effects(effect_files=()) -> list:
    """``mtwin effects``: the built-in effects and those of ``effect_files`` (user effects),
    as :class:`EffectInfo`."""
    from ..effects import available

    builtin = _with_files(effect_files)
    return [_info(c, builtin) for c in available().values()]


def effect(name: str, effect_files=()) -> EffectInfo:
    """``mtwin effects show NAME``: one effect (an unknown name lists the known ones)."""
    from ..effects import get

    return _info(get(name), _with_files(effect_files))


# ---------------------------------------------------------------------- materials

CHIP_DIAMETERS = (3.0, 6.0, 10.0, 12.0, 20.0)  # mm: the tool diameters a material's chip loads are shown at


def materials(name: Optional[str] = None) -> list:
    """``mtwin materials``: the cutting-data catalogue, each material as a dict (its names,
    Kienzle constants, the twin's coefficients, chip loads by diameter, every value's
    source); ``name``: that one alone (any of its names; an unknown one lists the known)."""
    from ..cutting import catalogue as C

    cat = C.catalogue()
    keys = [C.resolve(name, "mtwin materials")] if name is not None else list(cat.materials)
    rows = []
    for k in keys:
        m = cat.materials[k]
        co = C.material_coefficients(k)
        rows.append({"name": k, "title": m.title, "iso_group": m.iso, "names": list(m.names), "kc11": m.kc11,
                     "mc": m.mc, "kc_source": cat.source_text(m.kc_source),
                     "coefficients": {"ktc": co.ktc, "krc": co.krc, "kac": co.kac, "kte": co.kte, "kre": co.kre,
                                      "kae": co.kae, "source": co.source},
                     "chip_load": {f"{d:g}": C.chip_load(k, d) for d in CHIP_DIAMETERS},
                     "chip_source": C.chip_source(k)})
    return rows
