"""Twin configuration file (TOML): the parts the G-code front end reads.

Precedence is CLI option > file > built-in default, resolved here and nowhere
else.  Unknown keys and wrong types are errors that name the key.  The machine
sections (controller, axes, spindle, timing) are declared in ``twin/machine.py``.

Example::

    [interpreter]
    dialect = "fanuc"           # auto | fanuc | linuxcnc
    block_delete = false        # true: skip lines starting with '/'
    home_g28 = [0.0, 0.0, 0.0]  # machine coordinates, mm
    home_g30 = [0.0, 0.0, 0.0]

    [work_offsets]              # mm, machine coordinates of each work zero
    G54 = [-400.0, -200.0, -350.0]

    [tool_lengths]              # tool number -> length offset, mm
    1 = 95.2
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from .errors import ConfigError

_SECTIONS = {"interpreter", "work_offsets", "tool_lengths", "cutter_comp", "machine", "controller", "axes", "spindle",
             "timing", "cost",
             "tools", "materials", "cutting", "effects", "journal"}
_INTERP_KEYS = {"dialect", "block_delete", "home_g28", "home_g30", "subroutine_path"}


def _vec3(value, key):
    if not (isinstance(value, list) and len(value) == 3 and all(isinstance(v, (int, float)) for v in value)):
        raise ConfigError(f"{key}: expected a list of three numbers in mm, got {value!r}")
    if not all(math.isfinite(v) for v in value):
        raise ConfigError(f"{key}: values must be finite")
    return tuple(float(v) for v in value)


def read_twin_toml(path: str) -> dict:
    """Parse a twin TOML file and check its section names."""
    try:
        from .io import read_input

        raw = tomllib.loads(read_input(path, "twin").decode("utf-8"))
    except OSError as exc:
        raise ConfigError(f"cannot read twin file {path}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: twin file is not UTF-8 text") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: invalid TOML: {exc}") from None
    for section, body in raw.items():
        if section not in _SECTIONS:
            raise ConfigError(f"{path}: unknown section [{section}] (known: {', '.join(sorted(_SECTIONS))})")
        if section == "journal":
            if not (isinstance(body, list) and all(isinstance(x, dict) for x in body)):
                raise ConfigError(f"{path}: journal must be an array of tables ([[journal]])")
            continue
        if not isinstance(body, dict):
            raise ConfigError(f"{path}: [{section}] must be a table")
    return raw


def load_twin_file(path: str | None) -> dict:
    """Read and validate the front-end sections of a twin TOML file (plain dict of values)."""
    if path is None:
        return {}
    raw = read_twin_toml(path)
    out: dict = {}
    interp = raw.get("interpreter", {})
    for key, value in interp.items():
        if key not in _INTERP_KEYS:
            raise ConfigError(f"{path}: unknown key interpreter.{key} (known: {', '.join(sorted(_INTERP_KEYS))})")
    if "dialect" in interp:
        if interp["dialect"] not in ("auto", "fanuc", "linuxcnc"):
            raise ConfigError(f"{path}: interpreter.dialect must be auto, fanuc or linuxcnc")
        out["dialect"] = interp["dialect"]
    if "block_delete" in interp:
        if not isinstance(interp["block_delete"], bool):
            raise ConfigError(f"{path}: interpreter.block_delete must be true or false")
        out["skip_block_delete"] = interp["block_delete"]
    if "subroutine_path" in interp:
        sp = interp["subroutine_path"]
        if isinstance(sp, str):
            sp = [sp]
        if not (isinstance(sp, list) and all(isinstance(x, str) for x in sp)):
            raise ConfigError(f"{path}: interpreter.subroutine_path: expected a directory or a list of directories")
        base = Path(path).parent
        out["subroutine_path"] = tuple(str((base / x).resolve()) for x in sp)
    for key in ("home_g28", "home_g30"):
        if key in interp:
            out[key] = _vec3(interp[key], f"{path}: interpreter.{key}")
    offsets = {}
    valid = {"G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3"}
    for key, value in raw.get("work_offsets", {}).items():
        if key.upper() not in valid:
            raise ConfigError(f"{path}: unknown key work_offsets.{key} (G54 … G59.3)")
        offsets[key.upper()] = _vec3(value, f"{path}: work_offsets.{key}")
    if offsets:
        out["work_offsets"] = offsets
    # cutter compensation radii: the tools' own (D = tool number, as LinuxCNC), then [cutter_comp]
    radii = {}
    for key, body in (raw.get("tools") or {}).items():
        if str(key).isdigit() and isinstance(body, dict) and "diameter" in body:
            d = body["diameter"]
            if isinstance(d, (int, float)) and not isinstance(d, bool) and d > 0:
                radii[int(key)] = 0.5 * float(d)
    for key, value in (raw.get("cutter_comp") or {}).items():
        k = str(key).upper().lstrip("D")
        if not k.isdigit():
            raise ConfigError(f"{path}: cutter_comp.{key}: keys are D numbers (D3 or 3)")
        from .units import UnitError, convert

        try:
            r = convert(value, "mm", f"cutter_comp.{key}")
        except UnitError as exc:
            raise ConfigError(f"{path}: {exc}") from None
        if r < 0:
            raise ConfigError(f"{path}: cutter_comp.{key}: a radius must be >= 0 mm")
        radii[int(k)] = r
    if radii:
        out["comp_radii"] = radii
    if raw.get("tool_lengths"):  # an empty table is the same as none (every length 0)
        tools = {}
        for key, value in raw["tool_lengths"].items():
            if not key.isdigit():
                raise ConfigError(f"{path}: tool_lengths.{key}: tool numbers are non-negative integers")
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ConfigError(f"{path}: tool_lengths.{key}: expected a length in mm")
            tools[int(key)] = float(value)
        out["tool_lengths"] = tools
    return out


def interpreter_settings(twin_file: str | None = None, **overrides):
    """InterpreterSettings from the twin file, with CLI overrides (None = not given)."""
    from .gcode.interpreter import InterpreterSettings

    values = load_twin_file(twin_file)
    for key, value in overrides.items():
        if value is not None:
            values[key] = value
    return InterpreterSettings(**values)
