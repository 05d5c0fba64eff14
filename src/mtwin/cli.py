"""The ``mtwin`` command line.

Data goes to stdout (``--json``, CSV, rewritten programs with ``-o -``);
everything else — tables, progress, warnings, errors — to stderr.  Exit codes:
0 ok, 1 a check failed (``verify`` found a difference), 2 bad input or usage,
3 an internal error (run with ``--traceback`` and report it).

Heavy modules (numpy, numba kernels) are imported inside the commands so that
``mtwin --help`` answers at once.
"""
from __future__ import annotations

import functools
import json
import os
import sys
import tempfile
from pathlib import Path
from typing import Optional

import typer
from rich.console import Console

from .errors import EXIT_CHECK_FAILED, MtwinError

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    # Plain click help: rendering help through rich costs ~80 ms of imports
    # (rich.markdown, typer.rich_utils), which would put `mtwin --help` over
    # its 0.3 s budget. Our own messages still go through rich on stderr.
    rich_markup_mode=None,
    help="mtwin: G-code optimiser built on a digital twin of a CNC machine tool.",
    context_settings={"help_option_names": ["-h", "--help"]},
)
err = Console(stderr=True, highlight=False)
EXIT_INTERNAL = 3

_state = {"traceback": False}


@app.callback()
def _main(traceback: bool = typer.Option(False, "--traceback", help="Show Python tracebacks on errors.")):
    _state["traceback"] = traceback


def _fail(exc: BaseException) -> None:
    if _state["traceback"]:
        raise exc
    if isinstance(exc, MtwinError):
        err.print(f"[red]error:[/red] {exc}", markup=True, soft_wrap=True)
        raise typer.Exit(exc.exit_code)
    err.print(f"[red]internal error:[/red] {type(exc).__name__}: {exc} (run with --traceback and report it)")
    raise typer.Exit(EXIT_INTERNAL)


def _reports_errors(command):
    """Turn every exception of a command into a message and an exit code (see ``_fail``)."""

    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        try:
            return command(*args, **kwargs)
        except typer.Exit:
            raise
        except Exception as exc:  # noqa: BLE001 - every error becomes a message and an exit code
            _fail(exc)

    return wrapper


def _settings(twin, dialect, lenient, block_delete):
    from .config import interpreter_settings

    return interpreter_settings(twin, dialect=dialect, lenient=lenient or None,
                                skip_block_delete=block_delete)


def _load(part: str, settings):
    from .gcode.interpreter import load_program

    prog = load_program(part, settings)
    for w in prog.warnings:
        err.print(f"[yellow]{w}[/yellow]", soft_wrap=True)
    return prog


def write_output(data: bytes, out: str, inputs: list[str], in_place: bool = False) -> None:
    """Write ``data`` to ``out`` atomically (temporary file + rename), or to stdout for ``-``."""
    from .io import write_bytes

    write_bytes(data, out, inputs, in_place)


TwinOpt = typer.Option(None, "--twin", help="Twin configuration file (TOML): work offsets, tool lengths, dialect.")
DialectOpt = typer.Option(None, "--dialect", help="auto (default) | fanuc | linuxcnc: how G4/G82 P is read.")
LenientOpt = typer.Option(False, "--lenient", help="Unsupported codes that do not move the tool become warnings.")
BlockDeleteOpt = typer.Option(None, "--block-delete/--no-block-delete",
                              help="Block-delete switch: skip lines starting with '/' (default: off, lines run).")


@app.command()
@_reports_errors
def parse(
    part: str = typer.Argument(..., help="G-code program ('-' for stdin)."),
    moves: bool = typer.Option(False, "--moves", help="Write the interpreted motion records as CSV."),
    json_out: bool = typer.Option(False, "--json", help="Summary as JSON on stdout."),
    output: Optional[str] = typer.Option(None, "-o", "--output", help="File for --moves CSV (default stdout)."),
    twin: Optional[str] = TwinOpt,
    dialect: Optional[str] = DialectOpt,
    lenient: bool = LenientOpt,
    block_delete: Optional[bool] = BlockDeleteOpt,
):
    """Summarise a program: moves, tools, feeds, bounding box, lengths and nominal time."""
    from .gcode.summary import moves_csv, summarize

    prog = _load(part, _settings(twin, dialect, lenient, block_delete))
    if moves:
        write_output(moves_csv(prog).encode(), output or "-", [part])
        return
    summary = summarize(prog)
    if json_out:
        sys.stdout.write(json.dumps(summary.as_dict(), indent=2) + "\n")
        return
    _print_summary(summary)


def _print_summary(s) -> None:
    from rich.table import Table

    t = Table(title=f"{s.path}", show_header=False, title_justify="left")
    t.add_column(style="bold")
    t.add_column()
    t.add_row("lines", f"{s.lines:,}")
    t.add_row("moves", ", ".join(f"{k} {v:,}" for k, v in s.moves.items() if v))
    t.add_row("tools", ", ".join(f"T{x}" for x in s.tools) or "-")
    t.add_row("feed range", f"{s.feed_range[0]:g} – {s.feed_range[1]:g} mm/min")
    t.add_row("spindle range", f"{s.spindle_range[0]:g} – {s.spindle_range[1]:g} rpm")
    lo, hi = s.bbox["min"], s.bbox["max"]
    t.add_row("bounding box", f"X {lo[0]:.3f}…{hi[0]:.3f}  Y {lo[1]:.3f}…{hi[1]:.3f}  Z {lo[2]:.3f}…{hi[2]:.3f} mm")
    t.add_row("cutting length", f"{s.cutting_length:,.1f} mm")
    t.add_row("rapid length", f"{s.rapid_length:,.1f} mm")
    t.add_row("nominal time", f"{s.nominal_time:,.1f} s  (length/feed; rapids at 30 m/min; dwell {s.dwell_time:g} s)")
    t.add_row("program units", s.units)
    t.add_row("dialect", s.dialect)
    err.print(t)


@app.command()
@_reports_errors
def scale(
    part: str = typer.Argument(..., help="G-code program ('-' for stdin)."),
    feed: float = typer.Option(1.0, "--feed", help="Feed factor (1.0 = unchanged)."),
    spindle: float = typer.Option(1.0, "--spindle", help="Spindle-speed factor."),
    max_feed: Optional[float] = typer.Option(None, "--max-feed", help="Clamp every feed to this value, mm/min."),
    output: str = typer.Option(..., "-o", "--output", help="Output program ('-' for stdout)."),
    in_place: bool = typer.Option(False, "--in-place", help="Allow -o to be the input file."),
    twin: Optional[str] = TwinOpt,
    dialect: Optional[str] = DialectOpt,
    lenient: bool = LenientOpt,
    block_delete: Optional[bool] = BlockDeleteOpt,
):
    """Bake a feed/spindle override into the program and clamp feeds; nothing else changes."""
    from .gcode.writer import scale_feeds

    prog = _load(part, _settings(twin, dialect, lenient, block_delete))
    data = scale_feeds(prog, feed, spindle, max_feed)
    write_output(data, output, [part], in_place)
    changed = sum(1 for a, b in zip(prog.data.splitlines(), data.splitlines()) if a != b)
    err.print(f"wrote {output}: {changed} line(s) changed, geometry verified", soft_wrap=True)


@app.command()
@_reports_errors
def verify(
    original: str = typer.Argument(..., help="Original program."),
    optimised: str = typer.Argument(..., help="Rewritten program."),
    tol: float = typer.Option(0.001, "--tol", help="Geometric tolerance, mm (default 1 µm)."),
    json_out: bool = typer.Option(False, "--json", help="Result as JSON on stdout."),
    twin: Optional[str] = TwinOpt,
    dialect: Optional[str] = DialectOpt,
    lenient: bool = LenientOpt,
    block_delete: Optional[bool] = BlockDeleteOpt,
):
    """Prove two programs cut the same path (ignoring F/S words and move splits). Exit 0 same, 1 different."""
    from .gcode.verify import compare

    if not (tol > 0):
        raise MtwinError("--tol must be positive")
    settings = _settings(twin, dialect, lenient, block_delete)
    a = _load(original, settings)
    b = _load(optimised, settings)
    diff = compare(a, b, tol)
    if json_out:
        res = {"same_path": diff is None, "tolerance": tol}
        if diff is not None:
            res["difference"] = diff.as_dict()
        sys.stdout.write(json.dumps(res) + "\n")
    if diff is None:
        err.print(f"same path within {tol:g} mm ({a.records.size:,} and {b.records.size:,} moves)")
        return
    err.print(f"[red]paths differ:[/red] {diff}", soft_wrap=True)
    raise typer.Exit(EXIT_CHECK_FAILED)


def main() -> None:
    try:
        app()
    except KeyboardInterrupt:  # pragma: no cover
        err.print("interrupted")
        sys.exit(130)


if __name__ == "__main__":  # pragma: no cover
    main()

