"""A twin file's machine, cutting part and effects (the file read by ``mtwin.config``).

Here, in the twin package, rather than in ``config`` so that imports run one way: ``config``
reads TOML and the interpreter's settings; the twin builds its parts from them."""
from __future__ import annotations

from ..config import read_twin_toml
from ..cutting.library import cutting_from_dict
from ..effects import get
from ..errors import ConfigError
from .machine import Machine, machine_from_dict


def load_machine(path: str | None):
    """The Machine of a twin file (the embedded default machine when path is None)."""
    if path is None:
        return Machine()
    return machine_from_dict(read_twin_toml(path), str(path))


def load_cutting(path: str | None):
    """Tools, materials and stock settings of a twin file (the built-in defaults when None)."""
    if path is None:
        return cutting_from_dict({})
    return cutting_from_dict(read_twin_toml(path), str(path))


def load_effects(path: str | None) -> tuple:
    """The effects of a twin file, in the file's order: ``[effects.NAME]`` tables of parameter
    values (an empty table: the effect at its defaults)."""
    if path is None:
        return ()
    raw = read_twin_toml(path).get("effects", {})
    out = []
    for name, values in raw.items():
        if not isinstance(values, dict):
            raise ConfigError(f"{path}: [effects.{name}] must be a table of parameter values")
        try:
            eff = get(name)(**values)
            eff.resolved()
        except ConfigError as exc:
            raise ConfigError(f"{path}: [effects.{name}]: {exc}") from None
        out.append(eff)
    return tuple(out)
