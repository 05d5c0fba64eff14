"""Writing TOML: the one writer of every file mtwin writes in TOML (the calibrated twin file
and its journal, ``mtwin config show``, the grinding twin and cycle files).  Reading is the
standard library's ``tomllib``; a value written here reads back as itself (tests/test_tomlwrite.py)."""
from __future__ import annotations

import math
import re


def toml_string(v: str) -> str:
    """A TOML basic string: quotes and backslashes escaped, control characters as \\uXXXX."""
    out = []
    for ch in v:
        if ch in ('"', "\\"):
            out.append("\\" + ch)
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04X}")  # TOML basic strings allow no control characters
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


def toml_value(v) -> str:
    """A bool, number (nan and inf as TOML has them), string or list as TOML."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        if isinstance(v, float) and math.isnan(v):
            return "nan"
        if isinstance(v, float) and math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(float(v)) if isinstance(v, float) else str(v)
    if isinstance(v, str):
        return toml_string(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    raise TypeError(v)


def inline_table(d: dict) -> str:
    """An inline table; a None value is written as nan (TOML has no null)."""
    return "{ " + ", ".join(f'{toml_string(str(k))} = {toml_value(v if v is not None else float("nan"))}'
                            for k, v in d.items()) + " }"


def dump_tables(d: dict, prefix: str = "") -> list[str]:
    """A parsed TOML document (no effects, no journal) written back: scalars and lists first,
    then each sub-table as [a.b]."""
    out, scalars, tables, arrays = [], [], [], []
    for k, v in d.items():
        if isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            arrays.append((k, v))  # an array of tables ([[tools.1.modes]])
        else:
            (tables if isinstance(v, dict) else scalars).append((k, v))
    if prefix and scalars:
        out.append(f"[{prefix}]")
    for k, v in scalars:
        out.append(f"{toml_key(k)} = {toml_value(v)}")
    if scalars:
        out.append("")
    if prefix and not scalars and arrays and not tables:
        out += [f"[{prefix}]", ""]  # (the table itself, before its arrays)
    for k, v in arrays:
        name = f"{prefix}.{toml_key(k)}" if prefix else toml_key(k)
        for item in v:
            out.append(f"[[{name}]]")
            out += [f"{toml_key(a)} = {toml_value(b)}" for a, b in item.items() if not isinstance(b, dict)]
            out.append("")
    for k, v in tables:
        out += dump_tables(v, f"{prefix}.{toml_key(k)}" if prefix else toml_key(k))
    return out


def toml_key(k: str) -> str:
    """A bare key where TOML allows one, else a quoted key."""
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else toml_string(k)
