"""Reading a program: ``parse`` (what it holds, before any simulation)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Optional

from ..twin.setup import Messages, load_part
from ..units import SI_UNITS


@dataclass
class Parsed:
    """A program as read: ``summary`` its moves, tools, feeds, box, lengths and nominal time."""

    program: object
    summary: object
    messages: list = field(default_factory=list, repr=False)

    def moves_csv(self) -> str:
        """The interpreted motion records as CSV (``mtwin parse --moves``)."""
        from ..gcode.summary import moves_csv

        return moves_csv(self.program)

    def as_dict(self) -> dict:
        return {**self.summary.as_dict(), "si_units": SI_UNITS}


def parse(twin=None, program=None, *, on_message: Optional[Callable[[str, str], None]] = None) -> Parsed:
    """Read and summarise a program with the twin's interpreter settings; a program without
    motion (a macro library, a header) is read too."""
    from ..gcode.summary import summarize

    msgs = Messages(on_message)
    prog = load_part(twin, program, msgs, need_motion=False)
    return Parsed(prog, summarize(prog), msgs.items)
