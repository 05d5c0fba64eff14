"""Parameter declarations: one place that says what a parameter is.

Two forms, for two kinds of owner:

* :func:`P` declares a field of a frozen dataclass (the machine's sections, tools,
  materials): default, unit, one line of documentation and a check.  Parsing the twin
  file, ``mtwin config show`` and ``docs/configuration.md`` all read these declarations.
* :class:`Param` declares a parameter of an effect (``mtwin.effects``): name, unit,
  default, the bounds a calibration may search, documentation and its source tag.

Units follow ``docs/conventions.md``; source tags follow ``docs/physics.md``: [S] from a
cited source, [E] an estimate inside the sourced range.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from .errors import ConfigError
from .units import UnitError, convert


def P(default, unit: str, doc: str, check: str = "positive", choices: tuple = ()):
    """A dataclass parameter: default, unit ('' = dimensionless, 'bool', 'str', 'int'), doc, check."""
    return field(default=default, metadata={"unit": unit, "doc": doc, "check": check, "choices": choices})


def check_value(value, meta: dict, key: str):
    """Validate (and convert to the declared unit) one value against a :func:`P` declaration."""
    unit, check = meta["unit"], meta["check"]
    if unit == "bool":
        if not isinstance(value, bool):
            raise ConfigError(f"{key}: expected true or false, got {value!r}")
        return value
    if unit == "str":
        if not isinstance(value, str):
            raise ConfigError(f"{key}: expected a string, got {value!r}")
        if check == "choice" and value not in meta["choices"]:
            raise ConfigError(f"{key}: {value!r} is not one of {', '.join(meta['choices'])}")
        return value
    if unit == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{key}: expected an integer, got {value!r}")
        if value < 1:
            raise ConfigError(f"{key}: must be at least 1, got {value}")
        return value
    try:
        x = convert(value, unit or "1", key)
    except UnitError as exc:
        raise ConfigError(str(exc)) from None
    bad = {
        "positive": x <= 0,
        "nonneg": x < 0,
        "unit_interval": not 0 <= x <= 1,
        "unit_interval_open": not 0 < x <= 1,
        "finite": False,
    }[check]
    if bad:
        want = {"positive": "> 0", "nonneg": ">= 0", "unit_interval": "between 0 and 1",
                "unit_interval_open": "in (0, 1]"}[check]
        shown = f"{value}" if not isinstance(value, str) else repr(value)
        raise ConfigError(f"{key}: must be {want}{' ' + unit if unit and check != 'unit_interval' else ''}, got {shown}")
    return x


@dataclass(frozen=True)
class Param:
    """A parameter of an effect.

    ``lower``/``upper`` bound the values a user may set and a calibration may search;
    ``default`` is the value that leaves the twin as it is where the effect allows it
    (a zero amplitude), else a typical value."""

    name: str
    unit: str
    default: float
    lower: float
    upper: float
    doc: str
    source: str = "[E]"

    def check(self, value, key: str) -> float:
        """The value in this parameter's unit, within its bounds (a ConfigError otherwise)."""
        try:
            x = convert(value, self.unit or "1", key)
        except UnitError as exc:
            raise ConfigError(str(exc)) from None
        if not (math.isfinite(x) and self.lower <= x <= self.upper):
            raise ConfigError(f"{key}: must be within [{self.lower:g}, {self.upper:g}]"
                              f"{' ' + self.unit if self.unit else ''}, got {value!r}")
        return float(x)
