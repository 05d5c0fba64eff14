"""Argument types of the command line: ranges, grids, comma lists, and where outputs go —
each checked before the work, with a message that names the option."""
from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Optional

from ..errors import MtwinError


def value_range(text: Optional[str], name: str) -> Optional[tuple[float, float]]:
    """``LOW,HIGH`` (or ``LOW:HIGH``) with 0 < LOW < HIGH, or None."""
    if text is None:
        return None
    try:
        a, b = (float(x) for x in text.replace(":", ",").split(","))
    except ValueError:
        raise MtwinError(f"{name} {text!r}: expected LOW,HIGH (two numbers)") from None
    if not (math.isfinite(a) and math.isfinite(b) and 0 < a < b):
        raise MtwinError(f"{name} {text!r}: need 0 < LOW < HIGH")
    return (a, b)


def grid(text: str, name: str = "--grid") -> tuple[int, int]:
    """``MxN``: two whole sizes."""
    try:
        m, n = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise MtwinError(f"{name} {text!r}: expected FEEDSxALLOWANCES, e.g. 40x40") from None
    return m, n


def names(text: Optional[str]) -> Optional[list[str]]:
    """A comma-separated list of names, or None."""
    return [s.strip() for s in text.split(",")] if text else None


def check_outputs(*paths) -> None:
    """Where results go is checked before the work, not after it ('-' is stdout)."""
    for p in paths:
        if not p or p == "-":
            continue
        if Path(p).is_dir():
            raise MtwinError(f"{p} is a directory: give a file name")
        parent = Path(p).parent if str(Path(p).parent) else Path(".")
        if not parent.is_dir():
            raise MtwinError(f"output directory {parent} does not exist")
        if not os.access(parent, os.W_OK | os.X_OK):
            raise MtwinError(f"output directory {parent} is not writable")
        if Path(p).is_symlink():
            raise MtwinError(f"{p} is a symbolic link: writing the output would replace the link; name the file it "
                             f"points to ({os.path.realpath(p)})")


def check_report(report: Optional[str], *others: Optional[str], stdout_ok: bool = False) -> None:
    """An HTML report's file name: .html, its own (not another output's), '-' only where
    allowed."""
    if report is None:
        return
    if report == "-" and stdout_ok:
        return
    if report == "-" or report in others:
        raise MtwinError("--report needs a file name of its own")
    if not report.endswith((".html", ".htm")):
        raise MtwinError(f"--report {report}: use an .html file name")


def write_output(data: bytes, out: str, inputs: list, in_place: bool | None = None) -> None:
    """Write ``data`` to ``out`` atomically (temporary file + rename), or to stdout for ``-``;
    ``in_place`` as the command's ``--in-place`` (None: it has none)."""
    from ..io import write_bytes

    write_bytes(data, out, [str(p) for p in inputs], in_place)
