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


# The largest magnitude a value may have, per declared unit: beyond it a value is a typo or a
# unit mistake, not a machine (the fastest linear-motor machines run some 300 m/min at 5 g;
# spindles 200,000 rpm; cutting-force constants reach 5,000 N/mm^2) — and a number such as
# 1e308 would overflow the run into NaN.  A parameter may declare its own (``hi=``).
UNIT_MAX = {"mm/min": 1e6, "mm/s": 1e5, "mm/s^2": 1e6, "mm/s^3": 1e9, "1/s": 1e4, "rad/s": 1e5, "N": 1e6,
            "N*m": 1e5, "N*m/A": 1e3, "N*s/m": 1e8, "N/mm": 1e5, "N/mm^2": 1e5, "W": 1e7, "kg": 1e6,
            "kg*m^2": 1e3, "m/min": 1e5, "mm": 1e6, "rpm": 1e6, "rpm/s": 1e7, "s": 1e6, "1/h": 1e6, "": 1e6, "1": 1e6,
            "int": 1e6, "A": 1e5, "%": 1e4, "mm^3/s": 1e9}


def P(default, unit: str, doc: str, check: str = "positive", choices: tuple = (), lo: float | None = None,
      hi: float | None = None):
    """A dataclass parameter: default, unit ('' = dimensionless, 'bool', 'str', 'int'), doc, check;
    ``lo``/``hi``: the range a real machine or tool has (``hi`` defaults to ``UNIT_MAX``)."""
    return field(default=default, metadata={"unit": unit, "doc": doc, "check": check, "choices": choices,
                                            "lo": lo, "hi": hi})


def _in_range(x, meta: dict, key: str, unit: str, value) -> None:
    lo = meta.get("lo")
    hi = meta.get("hi")
    hi = UNIT_MAX.get(unit) if hi is None else hi
    u = f" {unit}" if unit and unit not in ("1", "int") else ""
    if hi is not None and abs(x) > hi:
        raise ConfigError(f"{key}: {value} is beyond what a real machine or tool has (at most {hi:g}{u}): a typo or a "
                          f"unit mistake?")
    if lo is not None and x < lo:
        raise ConfigError(f"{key}: {value} is below what a real machine or tool has (at least {lo:g}{u}): a typo or "
                          f"a unit mistake?")


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
        _in_range(value, meta, key, "int", value)
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
    _in_range(x, meta, key, unit, value)
    return x


@dataclass(frozen=True)
class Param:
    """A parameter of an effect.

    ``lower``/``upper`` bound the values a user may set and a calibration may search;
    ``default`` is the value that leaves the twin as it is where the effect allows it
    (a zero amplitude), else a typical value.  ``ceiling``: a limit the motion may never
    reach (an arc's v²/r limit on a program whose arcs all run below it); a calibration that
    finds no logged block reaching it says so and sets the least value the logs allow."""

    name: str
    unit: str
    default: float
    lower: float
    upper: float
    doc: str
    source: str = "[E]"
    ceiling: bool = False

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


# ---- dotted parameter names: the one place they are built and taken apart
#
# A fitted or calibrated value is named by where it lives in the twin file: an effect's
# parameter ``effects.NAME.PARAM`` (effect names hold '-', never '.'), a machine parameter
# ``x.servo.kpp``, a cutting one ``cutting.<material>.ktc`` or ``tools.<N>.<field>``.
EFFECTS = "effects"


def effect_param(effect: str, param: str) -> str:
    """``effects.NAME.PARAM``: the dotted name of an effect's parameter."""
    return f"{EFFECTS}.{effect}.{param}"


def is_effect_param(name: str) -> bool:
    return name.startswith(EFFECTS + ".")


def split_effect_param(name: str) -> tuple[str, str]:
    """(effect, parameter) of ``effects.NAME.PARAM``."""
    if not is_effect_param(name) or name.count(".") < 2:
        raise ConfigError(f"{name}: not an effect's parameter (effects.NAME.PARAM)")
    param = name.rsplit(".", 1)[-1]
    return name[len(EFFECTS) + 1:-(len(param) + 1)], param
