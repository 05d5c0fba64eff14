"""Physical effects: the catalogue, user effects, and the one registry for both.

``available()`` maps every effect name to its class: the built-in catalogue, then the
effects that installed packages declare under the entry-point group ``mtwin.effects``,
then those loaded from files (``--effect-file my_effect.py``, :func:`load_file`).  A user
effect goes through exactly the path a built-in takes.  See ``docs/effects.md``.
"""
from __future__ import annotations

import importlib.util
import os
import sys

from ..errors import ConfigError
from .base import Effect, StepInfo, ToolHistory
from .drives import CoulombFriction, Gravity, Inertia, StribeckFriction, ViscousFriction
from .observation import Backlash, Runout, ServoDelay, SpindleNoLoad, ThermalDrift
from .process import SizeEffect, ToolWear
from .wear import FlankWear
from .timing import (ArcAcceleration, BlockTime, CornerSlowdown, FeedOverride, FeedRapidWait, RapidAcceleration,
                     SpindleRunup, SpiralAcceleration, ToolChangeTime)

__all__ = ["Effect", "StepInfo", "ToolHistory", "available", "get", "load_file", "register", "parse_effect_spec"]

ENTRY_POINT_GROUP = "mtwin.effects"

BUILTIN: tuple[type[Effect], ...] = (
    SpindleNoLoad, ToolWear, FlankWear, SizeEffect, Runout, CoulombFriction, ViscousFriction, StribeckFriction, Gravity,
    Backlash, ServoDelay, ThermalDrift, Inertia,
    ToolChangeTime, SpindleRunup, BlockTime, CornerSlowdown, ArcAcceleration, SpiralAcceleration, RapidAcceleration,
    FeedRapidWait, FeedOverride,
)

# effects registered in this process (files, tests, register()): name -> class
_extra: dict[str, type[Effect]] = {}
_entry_points_loaded: dict[str, type[Effect]] | None = None


def _validate(cls, origin: str) -> type[Effect]:
    if not (isinstance(cls, type) and issubclass(cls, Effect)):
        raise ConfigError(f"{origin}: {cls!r} is not a subclass of mtwin.effects.Effect")
    if not cls.name or not cls.description:
        raise ConfigError(f"{origin}: effect class {cls.__name__} needs a name and a one-line description")
    from .base import STAGES

    if cls.stage not in STAGES:
        raise ConfigError(f"{origin}: effect {cls.name}: stage must be one of {', '.join(STAGES)}")
    from ..layout import SIGNALS

    bad = [s for s in cls.signals if s not in SIGNALS]
    if bad:
        raise ConfigError(f"{origin}: effect {cls.name} changes unknown signal(s) {', '.join(bad)}")
    return cls


def register(cls: type[Effect], origin: str = "register()") -> type[Effect]:
    """Register a user effect class in this process (what files and entry points do)."""
    _validate(cls, origin)
    builtin = {c.name for c in BUILTIN}
    if cls.name in builtin:
        raise ConfigError(f"{origin}: effect name {cls.name!r} is a built-in effect's")
    _extra[cls.name] = cls
    return cls


def _entry_points() -> dict[str, type[Effect]]:
    global _entry_points_loaded
    if _entry_points_loaded is None:
        from importlib.metadata import entry_points

        found = {}
        for ep in entry_points(group=ENTRY_POINT_GROUP):
            cls = _validate(ep.load(), f"entry point {ep.name} ({ep.value})")
            found[cls.name] = cls
        _entry_points_loaded = found
    return _entry_points_loaded


def available() -> dict[str, type[Effect]]:
    """Every effect by name: built-ins, entry points, then this process's registrations."""
    out = {c.name: c for c in BUILTIN}
    out.update(_entry_points())
    out.update(_extra)
    return out


def get(name: str) -> type[Effect]:
    known = available()
    if name not in known:
        raise ConfigError(f"unknown effect {name!r} (known: {', '.join(sorted(known))}; "
                          f"a user effect comes from --effect-file or a package's '{ENTRY_POINT_GROUP}' entry point)")
    return known[name]


def load_file(path: str) -> list[type[Effect]]:
    """Import a Python file and register every Effect subclass defined in it."""
    if not os.path.isfile(path):
        raise ConfigError(f"--effect-file {path}: " + ("a directory: name the .py file in it" if os.path.isdir(path)
                                                       else "no such file"))
    from ..io import check_input

    check_input(path, "effects")  # (Python code, run as a plugin is: docs/effects.md)
    modname = f"mtwin_user_effects_{abs(hash(os.path.abspath(path)))}"
    if not path.endswith(".py"):  # (Python imports only a .py file by its name; say so, not a traceback)
        raise ConfigError(f"--effect-file {path}: not a Python file (an effect file is Python code ending in .py)")
    spec = importlib.util.spec_from_file_location(modname, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[modname] = module
    try:
        spec.loader.exec_module(module)
    except Exception as exc:  # noqa: BLE001 - a user's file: say what failed, with its name
        raise ConfigError(f"--effect-file {path}: {type(exc).__name__}: {exc}") from None
    found = [v for v in vars(module).values()
             if isinstance(v, type) and issubclass(v, Effect) and v is not Effect and v.__module__ == modname]
    if not found:
        raise ConfigError(f"--effect-file {path}: defines no subclass of mtwin.effects.Effect")
    return [register(c, f"--effect-file {path}") for c in found]


def parse_effect_spec(spec: str) -> Effect:
    """``NAME`` or ``NAME:param=value,param=value`` (the CLI's --effect) -> an Effect."""
    name, _, rest = spec.partition(":")
    cls = get(name.strip())
    values = {}
    for item in filter(None, (x.strip() for x in rest.split(","))):
        key, eq, value = item.partition("=")
        if not eq:
            raise ConfigError(f"--effect {spec}: expected param=value, got {item!r}")
        try:
            values[key.strip()] = float(value)
        except ValueError:
            values[key.strip()] = value.strip()  # a quantity with a unit ("0.02 mm")
    eff = cls(**values)
    eff.resolved()  # unknown names and out-of-bounds values are errors now, not later
    return eff
