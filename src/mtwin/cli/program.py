"""Commands on a program alone: ``parse``, ``scale``, ``verify``."""
from __future__ import annotations

from typing import Optional

import typer

from ..errors import EXIT_CHECK_FAILED
from ..units import MM_PER_INCH
from .app import app, err, reports_errors
from .argtypes import check_outputs, write_output
from .options import JSON, PART, PROGRAM, groups, twin_options
from .render import emit_json, message


@app.command(short_help="Summarise a program: moves, tools, feeds, lengths.")
@reports_errors
@groups(setup=PROGRAM)
def parse(
    part: str = PART,
    moves: bool = typer.Option(False, "--moves", help="Write the interpreted motion records as CSV."),
    json_out: bool = JSON,
    output: Optional[str] = typer.Option(None, "-o", "--output", help="File for --moves CSV (default stdout)."),
    setup=None,
):
    """Summarise a program: moves, tools, feeds, bounding box, lengths and nominal time."""
    from ..api import parse as parse_program

    check_outputs(output)
    parsed = parse_program(setup, part, on_message=message)
    if moves:
        write_output(parsed.moves_csv().encode(), output or "-", [part])
        return
    if json_out:
        emit_json(parsed.as_dict())
        return
    _print_summary(parsed.summary)


def _print_summary(s) -> None:
    from rich.table import Table

    err.print(s.path, soft_wrap=True, highlight=False)  # (above the table: a long path is not wrapped)
    t = Table(show_header=False)
    t.add_column(style="bold")
    t.add_column()
    t.add_row("lines", f"{s.lines:,}")
    t.add_row("moves", ", ".join(f"{k} {v:,}" for k, v in s.moves.items() if v))
    t.add_row("tools", ", ".join(f"T{x}" for x in s.tools) or "-")
    inch = s.units == "inch"

    def own(mm: float, fmt: str, unit: str = "in") -> str:
        # an inch program's own numbers beside the SI ones
        return f" ({mm / MM_PER_INCH:{fmt}} {unit})" if inch else ""

    t.add_row("feed range", (f"{s.feed_range[0] / MM_PER_INCH:g} – {s.feed_range[1] / MM_PER_INCH:g} in/min "
                             f"({s.feed_range[0]:g} – {s.feed_range[1]:g} mm/min)") if inch else
              f"{s.feed_range[0]:g} – {s.feed_range[1]:g} mm/min")
    t.add_row("spindle range", f"{s.spindle_range[0]:g} – {s.spindle_range[1]:g} rpm")
    lo, hi = s.bbox["min"], s.bbox["max"]
    t.add_row("bounding box", f"X {lo[0]:.3f}…{hi[0]:.3f}  Y {lo[1]:.3f}…{hi[1]:.3f}  Z {lo[2]:.3f}…{hi[2]:.3f} mm")
    if inch:
        lo_in, hi_in = [v / MM_PER_INCH for v in lo], [v / MM_PER_INCH for v in hi]
        t.add_row("", f"X {lo_in[0]:.4f}…{hi_in[0]:.4f}  Y {lo_in[1]:.4f}…{hi_in[1]:.4f}  Z {lo_in[2]:.4f}…{hi_in[2]:.4f} in")
    t.add_row("cutting length", f"{s.cutting_length:,.1f} mm" + own(s.cutting_length, ",.2f"))
    t.add_row("rapid length", f"{s.rapid_length:,.1f} mm" + own(s.rapid_length, ",.2f"))
    t.add_row("nominal time", f"{s.nominal_time:,.1f} s  (length/feed; rapids at 30 m/min; dwell {s.dwell_time:g} s)")
    t.add_row("program units", s.units)
    t.add_row("dialect", s.dialect)
    err.print(t)


@app.command(short_help="Bake a feed/spindle override into the program.")
@reports_errors
@groups(setup=PROGRAM)
def scale(
    part: str = PART,
    feed: float = typer.Option(1.0, "--feed", help="Feed factor (1.0 = unchanged)."),
    spindle: float = typer.Option(1.0, "--spindle", help="Spindle-speed factor."),
    max_feed: Optional[float] = typer.Option(None, "--max-feed", help="Clamp every feed to this value, mm/min."),
    output: str = typer.Option(..., "-o", "--output", help="Output program ('-' for stdout)."),
    in_place: bool = typer.Option(False, "--in-place", help="Allow -o to be the input file."),
    setup=None,
):
    """Bake a feed/spindle override into the program and clamp feeds; nothing else changes."""
    from ..api import scale as scale_program

    check_outputs(output)
    res = scale_program(setup, part, feed=feed, spindle=spindle, max_feed=max_feed, on_message=message)
    write_output(res.output, output, [part], in_place)
    err.print(f"wrote {output}: {res.changed_lines} line(s) changed, geometry verified", soft_wrap=True)


@app.command(short_help="Prove two programs cut the same path (or, --by-stock, the same part).")
@reports_errors
@groups(setup=twin_options(stock=True, tools=True))
def verify(
    original: str = typer.Argument(..., help="Original program."),
    optimised: str = typer.Argument(..., help="Rewritten program."),
    tol: float = typer.Option(0.001, "--tol", help="Geometric tolerance, mm (default 1 µm)."),
    by_stock: bool = typer.Option(False, "--by-stock", help="Prove the same part instead of the same path: both "
                                  "programs run on the original's stock (--stock, its comments, the twin file's, "
                                  "or the guess) leave the same Z-map within --tol, nowhere deeper, and no rapid "
                                  "of the rewritten one goes through stock (for a program cut in layers)."),
    json_out: bool = JSON,
    setup=None,
):
    """Prove two programs cut the same path (ignoring F/S words and move splits), or with
    --by-stock leave the same part. Exit 0 same, 1 different."""
    from ..api.verify import prove_path, prove_stock

    if by_stock:
        proof = prove_stock(setup, original, optimised, stock=setup.stock_box(), tol=tol, on_message=message)
        if json_out:
            emit_json(proof.as_dict(), indent=None)
        if proof.same:
            err.print(proof.reason())
            return
        err.print(f"[red]not the same part:[/red] {proof.reason()}", soft_wrap=True)
        raise typer.Exit(EXIT_CHECK_FAILED)
    proof = prove_path(setup, original, optimised, tol=tol, on_message=message)
    if json_out:
        emit_json(proof.as_dict(), indent=None)
    if proof.same:
        err.print(f"same path within {tol:g} mm ({proof.original.records.size:,} and "
                  f"{proof.optimised.records.size:,} moves)")
        return
    err.print(f"[red]paths differ:[/red] {proof.difference}", soft_wrap=True)
    raise typer.Exit(EXIT_CHECK_FAILED)
