"""Rendering shared by the commands: the one JSON emitter, messages on stderr, small
formatters.  Command-specific tables live beside their command."""
from __future__ import annotations

import json
import sys

from ..units import figure as num  # noqa: F401  (the commands' one number format)
from .app import err


def emit_json(doc, indent: int = 2) -> None:
    """A result as JSON on stdout (the one place the commands write JSON)."""
    sys.stdout.write(json.dumps(doc, indent=indent) + "\n")


def warn(text: str) -> None:
    from rich.markup import escape

    err.print(f"[yellow]{escape(text)}[/yellow]", soft_wrap=True)


def message(kind: str, text: str) -> None:
    """A use case's warning or note, as it arises (the ``on_message`` of the API)."""
    if kind == "warning":
        warn(text)
    else:
        err.print(f"note: {text}", soft_wrap=True, highlight=False, markup=False)


def say(text: str) -> None:
    """A plain line on stderr (no markup read into it)."""
    err.print(text, soft_wrap=True, highlight=False, markup=False)


def hms(seconds: float) -> str:
    m, sec = divmod(seconds, 60.0)
    h, m = divmod(int(m), 60)
    return f"{h}:{m:02d}:{sec:06.3f}"


def table(*columns, title: str | None = None, header: bool = True, **kw):
    """A rich table with these columns (a name, or (name, justify))."""
    from rich.table import Table

    t = Table(title=title, title_justify="left", show_header=header, **kw)
    for c in columns:
        name, justify = (c, "left") if isinstance(c, str) else c
        t.add_column(name, justify=justify)
    return t
