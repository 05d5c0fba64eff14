"""Options declared once and shared: a command names the groups it takes and receives each as
one object — the twin options as a :class:`~mtwin.twin.setup.TwinSetup`, the measurement
options as a :class:`~mtwin.api.Reading` (as ruff flattens its shared argument structs).

    @app.command()
    @reports_errors
    @groups(setup=twin_options(effects=True, stock=True), reading=READING)
    def compare(part: str = …, setup=None, reading=None): …

The group's options appear after the command's own in ``--help``."""
from __future__ import annotations

import functools
import inspect
import typing
from dataclasses import dataclass
from typing import Callable, Optional

import typer


@dataclass(frozen=True)
class Group:
    """Options (name -> (type, typer.Option)) and how their values make one object."""

    options: dict
    make: Callable


def groups(**named: Group):
    """Replace each keyword parameter of the command named here by its group's options."""

    def decorate(fn):
        hints = typing.get_type_hints(fn)
        own = [p.replace(annotation=hints.get(p.name, p.annotation))
               for p in inspect.signature(fn).parameters.values() if p.name not in named]
        extra = [inspect.Parameter(f"{g}__{o}", inspect.Parameter.KEYWORD_ONLY, default=opt, annotation=tp)
                 for g, group in named.items() for o, (tp, opt) in group.options.items()]

        @functools.wraps(fn)
        def wrapper(*args, **kwargs):
            for g, group in named.items():
                kwargs[g] = group.make(**{o: kwargs.pop(f"{g}__{o}") for o in group.options})
            return fn(*args, **kwargs)

        params = own + extra
        wrapper.__signature__ = inspect.Signature(params)
        wrapper.__annotations__ = {p.name: p.annotation for p in params}
        return wrapper

    return decorate


# ---------------------------------------------------------------------- the twin options

TWIN = (Optional[str], typer.Option(None, "--twin", help="Twin configuration file (TOML): work offsets, tool "
                                                          "lengths, dialect."))
DIALECT = (Optional[str], typer.Option(None, "--dialect", help="auto (default) | fanuc | linuxcnc: how G4/G82 P is "
                                                                "read."))
LENIENT = (bool, typer.Option(False, "--lenient", help="Unsupported codes that do not move the tool become warnings."))
BLOCK_DELETE = (Optional[bool], typer.Option(None, "--block-delete/--no-block-delete",
                                             help="Block-delete switch: skip lines starting with '/' (default: off, "
                                                  "lines run)."))
EFFECT = (Optional[list[str]], typer.Option(None, "--effect", metavar="NAME[:P=V,…]",
                                            help="Add a physical effect to the twin (repeatable), e.g. "
                                                 "spindle-no-load:p0=150,b=0.01; see mtwin effects."))
EFFECT_FILE = (Optional[list[str]], typer.Option(None, "--effect-file", metavar="FILE",
                                                 help="A Python file defining user effects (subclasses of "
                                                      "mtwin.effects.Effect)."))
STOCK = (Optional[str], typer.Option(None, "--stock", help="Stock box xmin,ymin,zmin,xmax,ymax,zmax in mm (work "
                                                            "coordinates)."))
MATERIAL = (Optional[str], typer.Option(None, "--material", metavar="NAME",
                                        help="The work material: a catalogue name (4140, 304, AL6061, mdf, acrylic, "
                                             "…; mtwin materials lists them) over the twin file's and the "
                                             "program's; optimize then takes its limits from physics."))
PLANNER = (Optional[str], typer.Option(None, "--planner", help="Override the twin file's planner style: fanuc | "
                                                                "linuxcnc | grbl."))
TOOL = (Optional[list[str]], typer.Option(None, "--tool", metavar="N=TYPE:DIAMETER[:FLUTES]",
                                          help="Declare a tool (mm; flat | ball | bull | vee, e.g. 1=flat:6.35:2, "
                                               "2=bull:12:4:1.5 (corner radius), 3=vee:6.35:2:60:0.2 (angle, tip)): "
                                               "over the twin file's table and the program's comments."))


LEDGER = (Optional[str], typer.Option(None, "--ledger", help="A tool ledger (SQLite; created by --record): the "
                                                              "--tool-id tools start in their recorded wear state "
                                                              "under their calibrated law."))
TOOL_ID = (Optional[list[str]], typer.Option(None, "--tool-id", metavar="T3=ID",
                                             help="Which physical tool of the ledger a program tool is (repeatable)."))


def twin_options(effects: bool = False, stock: bool = False, planner: bool = False, tools: bool = False,
                 ledger: bool = False) -> Group:
    """The twin options a command takes: always the twin file and the interpreter switches;
    the effects (``--effect``, ``--effect-file``), ``--stock`` (with ``--material``), ``--planner`` and ``--tool``
    where it uses them.  The object is a TwinSetup."""
    from_flags = {"planner": (planner, PLANNER), "tools": (tools, TOOL), "effects": (effects, EFFECT),
                  "effect_files": (effects, EFFECT_FILE), "stock": (stock, STOCK), "material": (stock, MATERIAL), "ledger": (ledger, LEDGER),
                  "tool_ids": (ledger, TOOL_ID)}
    options = {k: v for k, (on, v) in from_flags.items() if on}
    options.update(twin=TWIN, dialect=DIALECT, lenient=LENIENT, block_delete=BLOCK_DELETE)

    def build(**values):
        from ..api import TwinSetup

        return TwinSetup(**{k: tuple(v or ()) if k in ("effects", "effect_files", "tools", "tool_ids") else v
                            for k, v in values.items()})

    return Group(options, build)


PROGRAM = twin_options()  # a program read as the twin file says: parse, scale, verify
LOOP = twin_options(effects=True, stock=True, ledger=True)  # synth, compare, diagnose, calibrate


# ---------------------------------------------------------------------- the measurement options

def _reading(maps, ignore_item, any_program, partial, run):
    from ..api import Reading

    return Reading(tuple(maps or ()), tuple(ignore_item or ()), any_program, partial, run)


READING = Group({
    "maps": (Optional[list[str]], typer.Option(None, "--map", metavar="SRC=DST[*SCALE]",
                                                help="Read column SRC as signal DST (times SCALE).")),
    "any_program": (bool, typer.Option(False, "--any-program", help="Accept a log whose program name is not the "
                                                                     "file's (a renamed file).")),
    "ignore_item": (Optional[list[str]], typer.Option(None, "--ignore-item", metavar="NAME",
                                                       help="A data item of an MTConnect log to read past (an unknown "
                                                            "item is an error).")),
    "partial": (bool, typer.Option(False, "--partial", help="A log whose run did not finish: compare the part that "
                                                             "ran (up to the last line reached) instead of refusing it.")),
    "run": (Optional[int], typer.Option(None, "--run", metavar="K",
                                        help="Which program run of an MTConnect log (1, 2, …; default: the last "
                                             "complete one; the runs are listed on stderr). calibrate: of its first "
                                             "log; the others' last complete runs are taken.")),
}, _reading)


# ---------------------------------------------------------------------- single options shared by several commands

JSON = typer.Option(False, "--json", help="The result as JSON on stdout.")
PART = typer.Argument(..., help="G-code program ('-' for stdin).")
MEASURED_PART = typer.Argument(..., help="G-code program the measurement was recorded on.")
SIGNALS = typer.Option(None, "--signals", help="Comma-separated signals to use (default: all in both).")
ALIGN = typer.Option("auto", "--align", help="auto | line | position | xcorr.")
OBJECTIVE = typer.Option("auto", "--objective", help="signals (the residual of each signal) | timing (the block times "
                         "of a log of the executing line) | chatter (diagnose: did the cuts chatter, from a vibration "
                         "recording or a spectrum file) | auto: timing for a control's log (line, feed and spindle "
                         "speed only) and timing effects, chatter for vib_x/vib_y alone or a spectrum, else signals.")
REPORT = typer.Option(None, "--report", help="Write a self-contained HTML report (.html).")
EFFECT_FILES = EFFECT_FILE[1]
