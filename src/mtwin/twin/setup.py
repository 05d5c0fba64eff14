"""What every use case starts from: the twin a user names (a Twin, a twin file, or the common
command-line options over one) and the program it runs on it, with the messages that leave
beside a result (library code never prints)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from ..cutting.library import parse_box, parse_tool_option
from ..effects import load_file
from ..errors import GCodeError, MtwinError, SourceLocation, warning_text
from ..gcode.interpreter import Program
from . import Twin
from .machine import STYLES


class Messages:
    """Warnings and notes of a use case, in the order they arose; each is also handed at once
    to ``sink(kind, text)`` when one is given (the CLI prints them as the work goes on)."""

    def __init__(self, sink: Optional[Callable[[str, str], None]] = None):
        self.sink = sink
        self.items: list[tuple[str, str]] = []

    def warn(self, text: str) -> None:
        self._say("warning", text)

    def note(self, text: str) -> None:
        self._say("note", text)

    def _say(self, kind: str, text: str) -> None:
        self.items.append((kind, text))
        if self.sink is not None:
            self.sink(kind, text)

    @property
    def warnings(self) -> list[str]:
        return [t for k, t in self.items if k == "warning"]

    @property
    def notes(self) -> list[str]:
        return [t for k, t in self.items if k == "note"]


@dataclass(frozen=True)
class TwinSetup:
    """The twin as the common command-line options describe it: a twin file, the interpreter
    switches over it, effects added by specification (``"name:p=v,…"``) or from user files, a
    planner style and tools declared over the file's table; and the stock box."""

    twin: Optional[str] = None  # twin file (TOML); None: the embedded default machine
    dialect: Optional[str] = None  # auto | fanuc | linuxcnc
    lenient: bool = False
    block_delete: Optional[bool] = None
    effects: tuple = ()
    effect_files: tuple = ()
    planner: Optional[str] = None  # fanuc | linuxcnc | grbl
    tools: tuple = ()  # "N=TYPE:DIAMETER[:FLUTES…]"
    stock: Optional[str] = None  # "xmin,ymin,zmin,xmax,ymax,zmax" (mm, work coordinates)
    material: Optional[str] = None  # a catalogue name, over the twin file's and the program's
    ledger: Optional[str] = None  # a tool ledger: the mapped tools start in their recorded state
    tool_ids: tuple = ()  # "T3=ID": which physical tool of the ledger each tool number is

    def build(self):
        """The Twin: the twin file's (its effects may be the user files' ones, loaded first),
        with the switches, planner, tools and effects given over it."""
        if self.planner is not None and self.planner not in STYLES:
            raise MtwinError(f"--planner must be one of {', '.join(STYLES)}, got {self.planner!r}")
        for f in self.effect_files:
            load_file(f)
        tw = Twin.from_toml(self.twin, dialect=self.dialect, lenient=self.lenient or None,
                            skip_block_delete=self.block_delete)
        if self.planner is not None:
            tw = tw.with_controller(style=self.planner)
        declared = ()
        if self.tools:
            tools = dict(parse_tool_option(t) for t in self.tools)
            tw = tw.with_tools(tools)
            declared = tuple(sorted(int(n) for n in tools))
        if self.material is not None:
            tw = tw.with_material(self.material)
        if self.effects:
            tw = tw.with_effects(*self.effects)
        if self.tool_ids and not self.ledger:
            raise MtwinError("--tool-id maps tools to a ledger's: give --ledger FILE too")
        if self.ledger:
            from ..ledger import apply, parse_tool_ids

            ids = parse_tool_ids(self.tool_ids)
            if not ids:
                raise MtwinError(f"--ledger {self.ledger}: say which tools are the ledger's with --tool-id T3=ID")
            tw = apply(tw, self.ledger, ids)
        tw.declared_tools = declared  # (load_part says which of them the program never uses)
        return tw

    @property
    def tool_map(self) -> dict:
        from ..ledger import parse_tool_ids

        return parse_tool_ids(self.tool_ids)

    def stock_box(self):
        """The --stock box as a tuple, or None."""
        if self.stock is None:
            return None

        return parse_box(self.stock, "--stock")


def open_twin(twin=None):
    """A Twin from a Twin (as it is), a twin file's path, or None (the default machine)."""
    if isinstance(twin, Twin):
        return twin
    if isinstance(twin, TwinSetup):
        return twin.build()
    return Twin.from_toml(None if twin is None else str(twin))


NO_MOTION = "the program has no motion (no G0/G1/G2/G3, cycle or dwell is run)"


def load_part(twin, program, messages: Optional[Messages] = None, need_motion: bool = True):
    """The program (a Program as it is; a path, ``-`` for stdin, or bytes read with the twin's
    interpreter settings), its warnings told.  An empty file is an error; one without a move
    is an error where the use case needs motion (``need_motion``), else a warning."""
    if isinstance(program, Program):
        # (a Program the caller read: the motion it needs is checked all the same — an API
        # optimize of a program that only defines a subroutine failed inside the optimiser)
        if need_motion and program.records.size == 0:
            raise GCodeError(NO_MOTION, SourceLocation(program.path, 1, 1))
        return program
    messages = messages if messages is not None else Messages()
    tw = open_twin(twin)
    prog = tw.load(program)
    for w in prog.warnings:
        messages.warn(str(w))
    # a --tool for a tool the program never uses is a typo or the wrong program: said, not silent
    unused = sorted(set(getattr(tw, "declared_tools", ())) - set(int(t) for t in np.unique(prog.records["tool"])))
    if unused and prog.records.size:
        messages.warn(warning_text(prog.path, 0, f"--tool {', '.join(f'{t}=…' for t in unused)}: the program never "
                                   f"uses {', '.join(f'T{t}' for t in unused)} (its tools: "
                                   f"{', '.join(f'T{int(t)}' for t in np.unique(prog.records['tool']))})"))
    if not prog.data.strip():
        raise GCodeError("the program is empty", SourceLocation(prog.path, 1, 1))
    # what the comments say about the material, stock and tool, where a form is malformed
    from ..cutting.workpiece import read_workpiece

    for line, col, text in read_workpiece(prog).warnings:
        messages.warn(warning_text(prog.path, line, text, col))
    if prog.records.size == 0:
        if need_motion:
            raise GCodeError(NO_MOTION, SourceLocation(prog.path, 1, 1))
        messages.warn(warning_text(prog.path, 0, NO_MOTION))
    return prog
