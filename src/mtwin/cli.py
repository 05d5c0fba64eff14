"""The ``mtwin`` command line.

Data goes to stdout (``--json``, CSV, rewritten programs with ``-o -``);
everything else — tables, progress, warnings, errors — to stderr.  Exit codes:
0 ok, 1 a check failed (``verify`` found a difference), 2 bad input or usage,
3 an internal error (run with ``--traceback`` and report it).

Heavy modules (numpy, numba kernels) are imported inside the commands so that
``mtwin --help`` answers at once.
"""
from __future__ import annotations

import contextlib
import json
import os
import sys
from pathlib import Path
from typing import Optional

import typer

from .errors import EXIT_CHECK_FAILED, MtwinError

from .cli_app import (EXIT_INTERNAL, INTERRUPTED, _fail, _install_compile_notice, _reports_errors, _state,  # noqa: F401
                      app, check_outputs, err, write_output)


def _settings(twin, dialect, lenient, block_delete):
    from .config import interpreter_settings

    return interpreter_settings(twin, dialect=dialect, lenient=lenient or None,
                                skip_block_delete=block_delete)


def _load(part: str, settings, need_motion: bool = True):
    """Load a program and show its warnings.  An empty file is an error; one without a move is
    an error where the command needs motion (``need_motion``), else a warning."""
    from .errors import GCodeError, SourceLocation, warning_text
    from .gcode.interpreter import load_program

    prog = load_program(part, settings)
    for w in prog.warnings:
        _warn(str(w))
    if not prog.data.strip():
        raise GCodeError("the program is empty", SourceLocation(prog.path, 1, 1))
    if prog.records.size == 0:
        msg = "the program has no motion (no G0/G1/G2/G3, cycle or dwell is run)"
        if need_motion:
            raise GCodeError(msg, SourceLocation(prog.path, 1, 1))
        _warn(warning_text(prog.path, 0, msg))
    return prog


TwinOpt = typer.Option(None, "--twin", help="Twin configuration file (TOML): work offsets, tool lengths, dialect.")
DialectOpt = typer.Option(None, "--dialect", help="auto (default) | fanuc | linuxcnc: how G4/G82 P is read.")
LenientOpt = typer.Option(False, "--lenient", help="Unsupported codes that do not move the tool become warnings.")
BlockDeleteOpt = typer.Option(None, "--block-delete/--no-block-delete",
                              help="Block-delete switch: skip lines starting with '/' (default: off, lines run).")


@app.command(short_help="Summarise a program: moves, tools, feeds, lengths.")
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

    prog = _load(part, _settings(twin, dialect, lenient, block_delete), need_motion=False)
    if moves:
        write_output(moves_csv(prog).encode(), output or "-", [part])
        return
    summary = summarize(prog)
    if json_out:
        sys.stdout.write(json.dumps({**summary.as_dict(), "si_units": _SI_UNITS}, indent=2) + "\n")
        return
    _print_summary(summary)


# JSON is in these units whatever the program's (an inch program's F10 is 254 mm/min)
_SI_UNITS = {"length": "mm", "time": "s", "feed": "mm/min", "spindle": "rpm", "force": "N", "power": "W",
             "torque": "N·m", "energy": "J"}


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
        return f" ({mm / 25.4:{fmt}} {unit})" if inch else ""

    t.add_row("feed range", (f"{s.feed_range[0] / 25.4:g} – {s.feed_range[1] / 25.4:g} in/min "
                             f"({s.feed_range[0]:g} – {s.feed_range[1]:g} mm/min)") if inch else
              f"{s.feed_range[0]:g} – {s.feed_range[1]:g} mm/min")
    t.add_row("spindle range", f"{s.spindle_range[0]:g} – {s.spindle_range[1]:g} rpm")
    lo, hi = s.bbox["min"], s.bbox["max"]
    t.add_row("bounding box", f"X {lo[0]:.3f}…{hi[0]:.3f}  Y {lo[1]:.3f}…{hi[1]:.3f}  Z {lo[2]:.3f}…{hi[2]:.3f} mm")
    if inch:
        t.add_row("", f"X {lo[0] / 25.4:.4f}…{hi[0] / 25.4:.4f}  Y {lo[1] / 25.4:.4f}…{hi[1] / 25.4:.4f}  "
                      f"Z {lo[2] / 25.4:.4f}…{hi[2] / 25.4:.4f} in")
    t.add_row("cutting length", f"{s.cutting_length:,.1f} mm" + own(s.cutting_length, ",.2f"))
    t.add_row("rapid length", f"{s.rapid_length:,.1f} mm" + own(s.rapid_length, ",.2f"))
    t.add_row("nominal time", f"{s.nominal_time:,.1f} s  (length/feed; rapids at 30 m/min; dwell {s.dwell_time:g} s)")
    t.add_row("program units", s.units)
    t.add_row("dialect", s.dialect)
    err.print(t)


@app.command(short_help="Bake a feed/spindle override into the program.")
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
    from .twin.files import load_machine
    from .gcode.writer import scale_feeds, scaled_feeds

    limit = load_machine(twin).max_cutting_feed
    prog = _load(part, _settings(twin, dialect, lenient, block_delete))
    f, is_feed = scaled_feeds(prog, feed, spindle)
    raised = is_feed & (f > limit * (1 + 1e-9)) & (f > prog.records["feed"])
    if raised.any() and (max_feed is None or max_feed > limit):
        _warn_clamped(prog, raised, float(f[raised].max()), limit)
    data = scale_feeds(prog, feed, spindle, max_feed, machine_max=limit)
    write_output(data, output, [part], in_place)
    changed = sum(1 for a, b in zip(prog.data.splitlines(), data.splitlines()) if a != b)
    err.print(f"wrote {output}: {changed} line(s) changed, geometry verified", soft_wrap=True)


def _warn_clamped(prog, over, highest: float, limit: float) -> None:
    import numpy as np

    from .errors import warning_text

    lines = np.unique(prog.records["line"][over])
    listed = ", ".join(str(x) for x in lines[:8]) + (" …" if lines.size > 8 else "")
    _warn(warning_text(prog.path, int(lines[0]),
                       f"F {highest:,.0f} mm/min would exceed the machine's maximum cutting feed {limit:,.6g} "
                       f"mm/min: clamped to it on {lines.size} line(s) ({listed})"))


def _warn(text: str) -> None:
    from rich.markup import escape

    err.print(f"[yellow]{escape(text)}[/yellow]", soft_wrap=True)


@app.command(short_help="Prove two programs cut the same path.")
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


EffectOpt = typer.Option(None, "--effect", metavar="NAME[:P=V,…]",
                         help="Add a physical effect to the twin (repeatable), e.g. spindle-no-load:p0=150,b=0.01; "
                              "see mtwin effects.")
EffectFileOpt = typer.Option(None, "--effect-file", metavar="FILE",
                             help="A Python file defining user effects (subclasses of mtwin.effects.Effect).")


def _load_effect_files(files) -> None:
    if files:
        from .effects import load_file

        for f in files:
            load_file(f)


def _twin_inputs(twin, dialect, lenient, block_delete, effect, effect_file, stock, planner=None, tools=None):
    """The twin of the common options (the twin file, --planner, --effect-file, --effect), its
    interpreter settings and the --stock box."""
    from .config import interpreter_settings
    from .twin.files import load_cutting, load_effects, load_machine
    from .twin import Twin

    machine = load_machine(twin)
    if planner is not None:
        from dataclasses import replace

        from .twin.machine import STYLES

        if planner not in STYLES:
            raise MtwinError(f"--planner must be one of {', '.join(STYLES)}, got {planner!r}")
        machine = replace(machine, controller=replace(machine.controller, style=planner))
    settings = interpreter_settings(twin, dialect=dialect, lenient=lenient or None, skip_block_delete=block_delete)
    _load_effect_files(effect_file)
    tw = Twin(machine=machine, interpreter=settings, path=twin, cutting=load_cutting(twin), effects=load_effects(twin))
    if tools:
        from .cutting.library import parse_tool_option

        tw = tw.with_tools(dict(parse_tool_option(t) for t in tools))
    if effect:
        tw = tw.with_effects(*effect)
    box = None
    if stock is not None:
        from .cutting.library import parse_box

        box = parse_box(stock, "--stock")
    return tw, settings, box


PlannerOpt = typer.Option(None, "--planner", help="Override the twin file's planner style: fanuc | linuxcnc | grbl.")
ToolOpt = typer.Option(None, "--tool", metavar="N=TYPE:DIAMETER[:FLUTES]",
                       help="Declare a tool (mm; flat | ball | bull | vee, e.g. 1=flat:6.35:2, 2=bull:12:4:1.5 "
                            "(corner radius), 3=vee:6.35:2:60:0.2 (angle, tip)): over the twin file's table and the "
                            "program's comments.")


@app.command(short_help="Run a program through the twin: time, errors, loads.")
@_reports_errors
def simulate(
    part: str = typer.Argument(..., help="G-code program ('-' for stdin)."),
    output: Optional[str] = typer.Option(None, "-o", "--output",
                                         help="Write the trace (measurement format): .csv, .parquet, or '-'."),
    every: Optional[int] = typer.Option(None, "--every", help="Keep every N-th servo sample in the trace."),
    decimate: Optional[float] = typer.Option(None, "--decimate",
                                             help="Trace sample rate in Hz (e.g. 100); alternative to --every."),
    json_out: bool = typer.Option(False, "--json", help="Summary as JSON on stdout."),
    stock: Optional[str] = typer.Option(None, "--stock",
                                        help="Stock box xmin,ymin,zmin,xmax,ymax,zmax in mm (work coordinates)."),
    no_cutting: bool = typer.Option(False, "--no-cutting", help="Motion only: no stock, engagement or cutting forces."),
    plot: Optional[str] = typer.Option(None, "--plot", help="Write the spindle power against time: .svg, .png or .pdf ('-': SVG on stdout)."),
    stock_out: Optional[str] = typer.Option(None, "--stock-out",
                                            help="Write the stock after the last cut: .png height map or .stl surface."),
    tooth_resolution: bool = typer.Option(False, "--tooth-resolution",
                                          help="Instantaneous tooth-passing forces instead of revolution averages."),
    planner: Optional[str] = PlannerOpt,
    tool: Optional[list[str]] = ToolOpt,
    effect: Optional[list[str]] = EffectOpt,
    effect_file: Optional[list[str]] = EffectFileOpt,
    twin: Optional[str] = TwinOpt,
    dialect: Optional[str] = DialectOpt,
    lenient: bool = LenientOpt,
    block_delete: Optional[bool] = BlockDeleteOpt,
):
    """Run a program through the twin: cycle time, following errors, motor torques, trace."""
    tw, settings, box = _twin_inputs(twin, dialect, lenient, block_delete, effect, effect_file, stock, planner, tool)
    machine = tw.machine
    dt = machine.controller.servo_period
    if every is not None and decimate is not None:
        raise MtwinError("give --every or --decimate, not both")
    if decimate is not None:
        if not decimate > 0:
            raise MtwinError(f"--decimate must be a positive rate in Hz, got {decimate:g}")
        every = max(1, int(round(1.0 / (decimate * dt))))
    if every is None:
        every = 1
    if every < 1:
        raise MtwinError(f"--every must be at least 1, got {every}")
    if plot:
        from .report.plots import plot_format

        plot_format(plot)  # refused before the work, not after
    if stock_out and not stock_out.endswith((".png", ".stl")):
        raise MtwinError(f"--stock-out {stock_out}: use a .png (height map) or .stl (surface) file name")
    prog = _load(part, settings)
    plan = tw.plan(prog)
    from .motion.simulate import simulate_plan

    n = int(plan.total_time / dt) + 1
    if n > 300_000 and not json_out:
        from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

        with Progress(TextColumn("simulating"), BarColumn(), TextColumn("{task.percentage:>3.0f}%"),
                      TimeRemainingColumn(), console=err, transient=True) as bar:
            task = bar.add_task("sim", total=n)
            trace = simulate_plan(tw, prog, plan, every=every, progress=lambda k, total: bar.update(task, completed=k),
                                  cutting=not no_cutting, stock=box, tooth=tooth_resolution)
    else:
        trace = simulate_plan(tw, prog, plan, every=every, cutting=not no_cutting, stock=box, tooth=tooth_resolution)
    s = trace.summary
    for w in s.warnings:
        _warn(w)
    if output:
        from . import __version__

        trace.write(output, {"source": f"mtwin {__version__} simulate", "program": prog.path,
                             "machine": machine.name, "planner": machine.controller.style,
                             "servo_period_s": f"{dt:g}", "every": str(every)})
    if stock_out:
        if trace.engagement is None:
            raise MtwinError("--stock-out needs the cutting model (do not combine it with --no-cutting)")
        from .report.stock import stock_bytes

        write_output(stock_bytes(trace.engagement.stock, stock_out), stock_out, [part])
    if plot:
        from .report.plots import plot_format, power_svg

        write_output(power_svg(trace, f"{prog.path}: spindle power", plot_format(plot)), plot, [part])
    if json_out:
        d = s.as_dict()
        d["si_units"] = _SI_UNITS
        d["program_units"] = "inch" if _is_inch(prog) else "mm"
        d["program"] = prog.path
        d["trace"] = output
        d["plot"] = plot
        sys.stdout.write(json.dumps(d, indent=2) + "\n")
        return
    _print_simulation(prog.path, s, output, _is_inch(prog))


def _is_inch(prog) -> bool:
    from .gcode.records import FL_INCH

    rec = prog.records
    return bool(len(rec)) and bool(((rec["flags"] & FL_INCH) != 0).mean() > 0.5)


def _print_simulation(path: str, s, output, inch: bool = False) -> None:
    from rich.table import Table

    err.print(f"{path} on {s.machine} ({s.style} planner)", soft_wrap=True, highlight=False)
    t = Table(show_header=False)
    t.add_column(style="bold")
    t.add_column()
    t.add_row("cycle time", f"{s.cycle_time:,.3f} s  ({_hms(s.cycle_time)})")
    parts = [("cutting", s.cutting_time), ("rapid", s.rapid_time), ("dwell", s.dwell_time),
             ("tool change", s.tool_change_time), ("spindle run-up", s.spindle_wait_time)]
    t.add_row("  of which", ", ".join(f"{k} {v:,.3f} s" for k, v in parts if v > 0) or "-")
    t.add_row("max following error", "  ".join(
        f"{a.upper()} {v * 1000:,.1f} µm (line {s.max_following_error_line.get(a, 0)}, "
        f"{s.max_following_error_in.get(a, '-')})" for a, v in s.max_following_error.items()))
    if s.max_following_error_feed:
        t.add_row("  in feed moves", "  ".join(f"{a.upper()} {v * 1000:,.1f} µm"
                                               for a, v in s.max_following_error_feed.items()))
    t.add_row("max contour error", f"{s.max_contour_error * 1000:,.1f} µm (line {s.max_contour_error_line}; error "
                                   f"normal to the path in feed moves, from the stored samples)"
              if s.max_contour_error_line else "- (no feed moves)")
    t.add_row("max motor torque", "  ".join(f"{a.upper()} {v:,.2f} N·m" for a, v in s.max_torque.items()))
    for tool, d in sorted(s.per_tool.items()):
        t.add_row(f"tool T{tool}", f"cutting {d['cutting_time']:,.2f} s over {d['cutting_length']:,.1f} mm, "
                                   f"rapid {d['rapid_time']:,.2f} s")
    c = s.cutting
    if c is not None and c.engaged_time <= 0 and c.spindle_stopped_line:
        t.add_row("cutting", f"not modelled: the feed moves cut the stock with the spindle stopped (line "
                             f"{c.spindle_stopped_line}: no M3/M4 or S0)")
    elif c is not None and c.engaged_time <= 0:
        b = c.stock
        t.add_row("cutting", f"none: no feed move meets the stock (X {b[0]:g}…{b[3]:g}  Y {b[1]:g}…{b[4]:g}  "
                             f"Z {b[2]:g}…{b[5]:g} mm, {c.stock_source})")
    elif c is not None:
        if c.peak_load_line:
            t.add_row("cutting load (XY)", f"peak {c.peak_load:,.1f} N (line {c.peak_load_line}), mean while "
                                           f"cutting {c.mean_load:,.1f} N")
        else:  # plunges only: the load is along the tool axis
            t.add_row("cutting load (XY)", "none: the tool only plunges (its load is axial)")
        t.add_row("spindle power", f"peak {c.peak_power:,.0f} W (line {c.peak_power_line}), mean while cutting "
                                   f"{c.mean_cutting_power:,.0f} W, energy {c.cutting_energy / 1000:,.1f} kJ")
        t.add_row("spindle torque", f"peak {c.peak_spindle_torque:,.2f} N·m (line {c.peak_spindle_torque_line}); "
                                    f"up to {c.peak_spindle_load:.1%} of the spindle curve")
        t.add_row("material removal", f"peak {c.peak_mrr:,.0f} mm³/s; tool in the material {c.engaged_time:,.2f} s")
        b = c.stock
        t.add_row("stock", f"X {b[0]:g}…{b[3]:g}  Y {b[1]:g}…{b[4]:g}  Z {b[2]:g}…{b[5]:g} mm, "
                           f"{c.resolution:g} mm cells ({c.stock_source}); {c.material}")
        from rich.markup import escape

        for d in c.defaults:
            t.add_row("tool" if d.startswith("tool T") else "default used", escape(d))
    if s.per_line is not None and s.per_line.worst(1):
        t.add_row("slowest lines", "simulated against nominal time (length/F, rapids at the axes' speed)")
        for r in s.per_line.worst(5):
            t.add_row(f"line {r['line']}", f"{r['time']:,.3f} s, nominal {r['nominal']:,.3f} s (+{r['time'] - r['nominal']:,.3f} s)"
                                           + (f": {r['reason']}" if r["reason"] else ""))
    t.add_row("servo samples", f"{s.samples:,} at {s.servo_period * 1000:g} ms")
    if output:
        t.add_row("trace", str(output))
    err.print(t)


def _hms(seconds: float) -> str:
    m, sec = divmod(seconds, 60.0)
    h, m = divmod(int(m), 60)
    return f"{h}:{m:02d}:{sec:06.3f}"


config_app = typer.Typer(help="Twin configuration files.", no_args_is_help=True, rich_markup_mode=None)
app.add_typer(config_app, name="config")


@config_app.command("show")
@_reports_errors
def config_show(twin: Optional[str] = TwinOpt):
    """Print the twin file (the embedded default machine, or --twin FILE with defaults filled in)."""
    from .config import load_twin_file
    from .twin.files import load_machine
    from .twin.machine import machine_toml

    sys.stdout.write(machine_toml(load_machine(twin), load_twin_file(twin)))


@config_app.command("check")
@_reports_errors
def config_check(path: str = typer.Argument(..., help="Twin file to validate.")):
    """Validate a twin file: exit 0 if it is valid, 2 with a message naming the key if not."""
    from .config import load_twin_file
    from .twin.files import load_cutting, load_effects, load_machine

    load_twin_file(path)
    m = load_machine(path)
    load_cutting(path)
    load_effects(path)
    err.print(f"{path}: valid ({m.name})")


def _range(text: Optional[str], name: str):
    if text is None:
        return None
    try:
        a, b = (float(x) for x in text.replace(":", ",").split(","))
    except ValueError:
        raise MtwinError(f"{name} {text!r}: expected LOW,HIGH (two numbers)") from None
    import math

    if not (math.isfinite(a) and math.isfinite(b) and 0 < a < b):
        raise MtwinError(f"{name} {text!r}: need 0 < LOW < HIGH")
    return (a, b)


@app.command(short_help="Optimise F and S under the load and machine limits.")
@_reports_errors
def optimize(
    part: str = typer.Argument(..., help="G-code program ('-' for stdin)."),
    output: str = typer.Option(..., "-o", "--output", help="Optimised program ('-' for stdout)."),
    objective: str = typer.Option("time", "--objective", help="time | cost | smooth | air."),
    method: str = typer.Option("bisect", "--method", help="bisect (per-segment bisection) | ga (genetic algorithm)."),
    force_limit: Optional[float] = typer.Option(None, "--force-limit",
                                                help="Cutting-load limit, N (default: learned per tool from the "
                                                     "program — the load and chip thickness it already runs at; "
                                                     "then no feed is lowered and a result that is not faster is "
                                                     "written unchanged)."),
    feed_range: Optional[str] = typer.Option(None, "--feed-range", help="LOW,HIGH mm/min (default: 10 % of the "
                                             "lowest F up to the machine's maximum cutting feed)."),
    spindle_range: Optional[str] = typer.Option(None, "--spindle-range",
                                                help="LOW,HIGH rpm: also choose S (per tool); without it S stays."),
    spindle_per: str = typer.Option("tool", "--spindle-per", help="tool | segment (needs --allow-s-changes)."),
    allow_s_changes: bool = typer.Option(False, "--allow-s-changes", help="Allow S words in mid-tool."),
    target_power: Optional[float] = typer.Option(None, "--target-power",
                                                 help="smooth: target mean cutting power per segment, W "
                                                      "(default: the 75th percentile of the segments')."),
    tolerance: float = typer.Option(0.02, "--tolerance", help="Contour error, mm, a segment may gain over the "
                                    "program's own on the re-simulated twin."),
    power_tolerance: float = typer.Option(0.05, "--power-tolerance",
                                          help="smooth: relative tolerance K on the target power."),
    finish_feed: str = typer.Option("keep", "--finish-feed", help="keep (finishing passes keep their feed per "
                                    "tooth) | optimize (treat them as any cut)."),
    tool: Optional[list[str]] = ToolOpt,
    segmentation: str = typer.Option("cluster", "--segmentation",
                                     help="cluster (sequential clustering) | changepoint (binary segmentation)."),
    min_segment: float = typer.Option(5.0, "--min-segment", help="Shortest segment C, mm of path."),
    seed: int = typer.Option(0, "--seed", help="GA random seed (same seed, same result)."),
    population: int = typer.Option(60, "--population", help="GA population size."),
    generations: int = typer.Option(200, "--generations", help="GA generation limit."),
    report: Optional[str] = typer.Option(None, "--report", help="Write a self-contained HTML report (.html)."),
    json_out: bool = typer.Option(False, "--json", help="Result as JSON on stdout."),
    in_place: bool = typer.Option(False, "--in-place", help="Allow -o to be the input file."),
    stock: Optional[str] = typer.Option(None, "--stock",
                                        help="Stock box xmin,ymin,zmin,xmax,ymax,zmax in mm (work coordinates)."),
    planner: Optional[str] = PlannerOpt,
    twin: Optional[str] = TwinOpt,
    dialect: Optional[str] = DialectOpt,
    lenient: bool = LenientOpt,
    block_delete: Optional[bool] = BlockDeleteOpt,
):
    """Segment the predicted power curve, choose F (and S) per segment for the objective under
    the load, power, torque and feed limits, write the program through the byte-preserving
    writer, prove it cuts the same path and check the limits on its re-simulation."""
    from .optimize.run import OptimizeOptions, optimize as run_optimize
    from .optimize.search import METHODS, OBJECTIVES, GAOptions

    if objective not in OBJECTIVES:
        raise MtwinError(f"--objective must be one of {', '.join(OBJECTIVES)}, got {objective!r}")
    if method not in METHODS:
        raise MtwinError(f"--method must be one of {', '.join(METHODS)}, got {method!r}")
    if segmentation not in ("cluster", "changepoint"):
        raise MtwinError(f"--segmentation must be cluster or changepoint, got {segmentation!r}")
    if spindle_per not in ("tool", "segment"):
        raise MtwinError(f"--spindle-per must be tool or segment, got {spindle_per!r}")
    import math as _math

    if force_limit is not None and not (force_limit > 0 and _math.isfinite(force_limit)):
        raise MtwinError(f"--force-limit must be a positive number of N, got {force_limit:g}")
    if target_power is not None and not (target_power > 0 and _math.isfinite(target_power)):
        raise MtwinError(f"--target-power must be a positive number of W, got {target_power:g}")
    if output == "-" and json_out:
        raise MtwinError("-o - and --json both write to stdout: give the program a file name, or leave out --json")
    if report == "-" or (report is not None and report == output):
        raise MtwinError("--report needs a file name of its own")
    check_outputs(output, report)
    if not (0 < power_tolerance < 1):
        raise MtwinError(f"--power-tolerance must be between 0 and 1, got {power_tolerance:g}")
    if not (tolerance >= 0 and _math.isfinite(tolerance)):
        raise MtwinError(f"--tolerance must be a contour error of 0 mm or more, got {tolerance:g}")
    if finish_feed not in ("keep", "optimize"):
        raise MtwinError(f"--finish-feed must be keep or optimize, got {finish_feed!r}")
    if not min_segment >= 0:
        raise MtwinError(f"--min-segment must be >= 0, got {min_segment:g}")
    if population < 4 or generations < 1:
        raise MtwinError("--population must be at least 4 and --generations at least 1")
    if report is not None and not report.endswith((".html", ".htm")):
        raise MtwinError(f"--report {report}: use an .html file name")
    tw, settings, box = _twin_inputs(twin, dialect, lenient, block_delete, None, None, stock, planner, tool)
    prog = _load(part, settings)
    opts = OptimizeOptions(objective, method, force_limit, _range(feed_range, "--feed-range"),
                           _range(spindle_range, "--spindle-range"), spindle_per, allow_s_changes, target_power,
                           power_tolerance=power_tolerance, tolerance=tolerance, finish_feed=finish_feed,
                           segmentation=segmentation, min_segment=min_segment,
                           ga=GAOptions(population=population, generations=generations, seed=seed))
    from .optimize.run import InfeasibleError

    try:
        res = _run_with_progress(run_optimize, tw, prog, opts, box, generations if method == "ga" else 0)
    except InfeasibleError as exc:
        if json_out:
            sys.stdout.write(json.dumps({"program": prog.path, "objective": objective, "method": method,
                                         "written": False, "error": str(exc), "reasons": exc.reasons}, indent=1) + "\n")
        raise
    for w in res.warnings:
        _warn(w)
    write_output(res.output, output, [part], in_place)
    if report:
        from .report.optimize_html import optimize_html

        write_output(optimize_html(res, prog.path), report, [part])
    _print_optimize(res, prog, json_out)


def _run_with_progress(run_optimize, tw, prog, opts, box, generations: int):
    """Run the optimiser with a transient progress display on a terminal's stderr (the stage,
    and the GA's generations), shown once the run has taken a second; plain otherwise."""
    if not err.is_terminal:
        return run_optimize(tw, prog, opts, stock=box)
    import threading

    from rich.progress import BarColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    bar = Progress(SpinnerColumn(), TextColumn("{task.description}"), BarColumn(), TextColumn("{task.fields[info]}"),
                   TimeElapsedColumn(), console=err, transient=True)
    task = bar.add_task("simulating the program", total=None, info="")
    lock = threading.Lock()
    state = {"shown": False, "done": False}

    def show():
        with lock:
            if not state["done"]:
                bar.start()
                state["shown"] = True

    timer = threading.Timer(1.0, show)
    timer.daemon = True

    def stage(text: str) -> None:
        bar.update(task, description=text, total=None, completed=0, info="")

    def ga(g, n, b):
        bar.update(task, description="GA", total=n, completed=g, info=f"gen {g}/{n}, fitness {b:.4f}")

    timer.start()
    try:
        return run_optimize(tw, prog, opts, stock=box, progress=ga if generations else None, stage=stage)
    finally:
        timer.cancel()
        with lock:
            state["done"] = True
            if state["shown"]:
                bar.stop()


def _short_ranges(lines: list[int], most: int = 8) -> str:
    from .optimize.guards import _ranges

    return _ranges(lines, most)


def _verdict(before: float, after: float) -> tuple[str, float]:
    """faster / slower / unchanged, and the relative change."""
    ch = after / before - 1.0 if before else 0.0
    if abs(ch) < 5e-4:
        return "unchanged", ch
    return ("faster" if ch < 0 else "slower"), ch


def _print_optimize(res, prog, json_out: bool) -> None:
    b, a = res.before, res.after
    verdict, change = _verdict(b.cycle_time, a.cycle_time)
    if verdict == "unchanged" and res.changed_lines:
        verdict = "faster" if change < 0 else "slower" if change > 0 else "unchanged"

    def pct(x, y):
        return f"{(y / x - 1) * 100:+.1f} %" if x else "—"

    if json_out:
        doc = {"program": prog.path, "objective": res.objective, "method": res.method, "written": True,
               "verdict": verdict, "cycle_time_change": change, "before": b.as_dict(),
               "after": a.as_dict(), "estimate": res.estimate,
               "estimate_error": {"cycle_time": res.estimate["cycle_time"] - a.cycle_time},
               "changed_lines": len(res.changed_lines), "verified": res.verified, "rounds": res.rounds,
               "evaluations": res.evaluations, "generations": res.generations, "seconds": res.seconds,
               "force_limit": res.force_limit, "force_limit_source": res.force_limit_source,
               "limits": res.limits, "kept": res.kept, "contour_error": res.contour_error,
               "spindle": {str(k): v for k, v in res.spindle.items()},
               "defaults": res.defaults, "tools": res.tools, "segments": res.segments,
               "tradeoff": [{"force_limit": f, "cycle_time": t} for f, t in res.tradeoff],
               "tradeoff_source": res.tradeoff_source,
               "changes": [{"line": ln, "before": x, "after": y} for ln, x, y in res.changed_lines]}
        sys.stdout.write(json.dumps(doc, indent=1) + "\n")
        return
    from rich.table import Table

    err.print(f"{prog.path}: {res.objective} by {res.method}", soft_wrap=True, highlight=False)
    t = Table()
    for col in ("", "before", "after", "change"):
        t.add_column(col, justify="right" if col else "left")
    t.add_row("cycle time", f"{b.cycle_time:.2f} s", f"{a.cycle_time:.2f} s", pct(b.cycle_time, a.cycle_time))
    if b.cost is not None and a.cost is not None:
        # (in the currency units of the twin file's [cost] rates)
        t.add_row("cost (currency units)", f"{b.cost:.3f}", f"{a.cost:.3f}", pct(b.cost, a.cost))
    t.add_row("peak load", f"{b.peak_load:.1f} N", f"{a.peak_load:.1f} N", pct(b.peak_load, a.peak_load))
    t.add_row("peak spindle power", f"{b.peak_power / 1000:.2f} kW", f"{a.peak_power / 1000:.2f} kW",
              pct(b.peak_power, a.peak_power))
    ce = res.contour_error
    if ce:
        t.add_row("contour error (feed moves)", f"{ce['before']:.3f} mm", f"{ce['after']:.3f} mm",
                  f"{ce['after'] - ce['before']:+.3f} mm")
    cv = (lambda v: "—" if v is None else f"{v:.3f}")
    t.add_row("power CV (segment means)", cv(b.power_cv), cv(a.power_cv), "")
    err.print(t)
    word = {"faster": f"{-change * 100:.1f} % faster", "slower": f"{change * 100:.1f} % SLOWER",
            "unchanged": "cycle time unchanged"}[verdict]
    err.print(f"result: {word} ({b.cycle_time:.2f} -> {a.cycle_time:.2f} s, re-simulated)", highlight=False)
    for lim in res.limits:
        if lim.get("tool") is None:
            continue
        if lim.get("load") is None:
            err.print(f"limits T{lim['tool']}: {lim['source']}", highlight=False, soft_wrap=True)
            continue
        chip = f", chip thickness {lim['chip_thickness'] * 1000:.1f} µm" if lim.get("chip_thickness") else ""
        err.print(f"limits T{lim['tool']}: load {lim['load']:.1f} N{chip} ({lim['source']})", highlight=False,
                  soft_wrap=True)
    if res.spindle:
        err.print("spindle speed chosen: " + ", ".join(f"T{k}: S{v:.0f}" for k, v in res.spindle.items()),
                  highlight=False)
    for why, lines in res.kept.items():
        err.print(f"kept their feeds ({why}): {len(lines)} line(s)", highlight=False, soft_wrap=True)
    if res.segments:
        from collections import Counter

        held = Counter(sg["limited_by"] for sg in res.segments if not sg["air"])
        if held:
            err.print("what held the cutting segments' feeds: " + ", ".join(f"{k} {v}" for k, v in held.most_common()),
                      highlight=False, soft_wrap=True)
        top = [sg for sg in res.segments if sg["air"] and sg["limited_by"] == "feed range (air cut)"]
        if top:
            lines = sorted({ln for sg in top for ln in range(sg["lines"][0], sg["lines"][1] + 1)})
            err.print(f"air cuts raised to the top of the feed range, F{top[0]['feed_after']:g} mm/min: "
                      f"{len(top)} segment(s), lines {_short_ranges(lines)}", highlight=False, soft_wrap=True)
    for d in res.defaults:
        err.print(f"note: {d}", soft_wrap=True, highlight=False, markup=False)
    if res.segments:
        held = ce.get("worst_segment_increase", 0.0) <= ce.get("tolerance", 0.0) + 1e-9
        err.print(f"{len(res.segments)} segments, {len(res.changed_lines)} changed line group(s); verified: same path; "
                  + (f"limits and contour tolerance ({ce.get('tolerance', 0):g} mm) held" if held else
                     f"limits held, but a segment's contour error grew {ce['worst_segment_increase']:.3f} mm (over the "
                     f"{ce.get('tolerance', 0):g} mm tolerance) where the program's own feed could not be kept")
                  + " on the re-simulated program "
                  f"({res.rounds} round(s)); estimate {res.estimate['cycle_time']:.2f} s vs re-simulated "
                  f"{a.cycle_time:.2f} s; {res.evaluations} evaluations in {res.seconds:.1f} s", soft_wrap=True,
                  highlight=False)
    else:
        err.print(f"nothing changed; written as it was ({res.seconds:.1f} s)", highlight=False)


import_app = typer.Typer(help="Read machine logs into the measurement format.", no_args_is_help=True,
                         rich_markup_mode=None)
app.add_typer(import_app, name="import")


@import_app.command("mtconnect", short_help="An MTConnect log (SHDR or agent XML) as a measurement.")
@_reports_errors
def import_mtconnect(
    log: str = typer.Argument(..., help="SHDR log (timestamp|item|value) or MTConnectStreams XML."),
    output: str = typer.Option(..., "-o", "--output", help="Measurement file (.csv; '-' for stdout)."),
    run: Optional[int] = typer.Option(None, "--run", help="Which program run of the log (1, 2, …; default: the "
                                                           "first complete one)."),
    block_is: str = typer.Option("line", "--block-is", help="What Block_Number counts: line (the file's line, "
                                                             "default) | n (the N word; needs --program)."),
    program: Optional[str] = typer.Option(None, "--program", help="The program the log ran (for --block-is n)."),
    ignore_item: Optional[list[str]] = typer.Option(None, "--ignore-item", metavar="NAME",
                                                    help="A data item to read past (an unknown item is an error)."),
):
    """Data items logged on change become a time series sampled at every change: t, line,
    feed (mm/min; MTConnect reports mm/s), spindle_speed, and tool and overrides where logged.
    Runs, feed holds and assumptions are listed on stderr and in the file's metadata."""
    from pathlib import Path

    from .loop.mtconnect import read_mtconnect
    from .motion.trace import write_columns

    check_outputs(output)
    try:
        data = Path(program).read_bytes() if program else None
    except OSError as exc:
        raise MtwinError(f"cannot read --program {program}: {exc.strerror or exc}") from None
    m = read_mtconnect(log, run, block_is, data, ignore_item or ())
    cols = {"t": m.t, "line": m.line, **m.signals, **m.extra}
    write_columns(output, cols, m.meta)
    for k, r in enumerate(m.runs, 1):
        err.print(f"run {k}: {r.program or '(unnamed)'}, {'complete' if r.complete else 'incomplete'}"
                  + (f", {len(r.holds)} feed hold(s)" if r.holds else "")
                  + (f", {len(r.stops)} program stop(s) ({', '.join(st for _, _, st in r.stops)})" if r.stops else ""),
                  highlight=False)
    err.print(f"run {m.meta['run']}: {len(m.t):,} samples over {m.end_time:.2f} s, lines "
              f"{int(m.line[m.line > 0].min()) if (m.line > 0).any() else '-'}–{int(m.line.max())}"
              + (f"; overrides {m.meta['overrides']}" if "overrides" in m.meta else ""), highlight=False)


@app.command(short_help="A synthetic measurement: the twin, extra effects, noise.")
@_reports_errors
def synth(
    part: str = typer.Argument(..., help="G-code program ('-' for stdin)."),
    output: str = typer.Option(..., "-o", "--output", help="Measurement file (.csv, .parquet, or '-')."),
    effect: Optional[list[str]] = EffectOpt,
    effect_file: Optional[list[str]] = EffectFileOpt,
    rate: float = typer.Option(100.0, "--rate", help="Samples per second."),
    noise: float = typer.Option(0.0, "--noise", help="Gaussian noise, a fraction of each signal's RMS (0.02 = 2 %)."),
    signals: Optional[str] = typer.Option(None, "--signals", help="Comma-separated signals (default: positions, "
                                          "spindle speed and power, axis torques, forces)."),
    seed: int = typer.Option(0, "--seed", help="Seed of the noise."),
    no_line: bool = typer.Option(False, "--no-line", help="Leave out the line column (a logger that does not record it)."),
    stock: Optional[str] = typer.Option(None, "--stock", help="Stock box xmin,ymin,zmin,xmax,ymax,zmax in mm."),
    twin: Optional[str] = TwinOpt,
    dialect: Optional[str] = DialectOpt,
    lenient: bool = LenientOpt,
    block_delete: Optional[bool] = BlockDeleteOpt,
):
    """Write what a machine would record running PART on the twin with extra effects (hidden
    from a plain twin) and sensor noise — for learning and testing compare/diagnose/calibrate."""
    from .loop.synth import synthesize
    from .motion.trace import write_columns

    tw, settings, box = _twin_inputs(twin, dialect, lenient, block_delete, effect, effect_file, stock)
    prog = _load(part, settings)
    cols = synthesize(tw, prog, rate=rate, noise=noise, seed=seed, line=not no_line, stock=box,
                      signals=[s.strip() for s in signals.split(",")] if signals else None)
    from . import __version__

    meta = {"source": f"mtwin {__version__} synth", "program": prog.path,
            "effects": "; ".join(f"{e.name}:" + ",".join(f"{k}={v:g}" for k, v in e.resolved().items())
                                 for e in tw.effects) or "none",
            "noise": f"{noise:g} of each signal's RMS, seed {seed}", "rate_hz": f"{rate:g}"}
    write_columns(output, cols, meta)
    err.print(f"wrote {output}: {len(cols['t']):,} samples at {rate:g} Hz, {len(cols) - 1} columns; "
              f"effects: {meta['effects']}", soft_wrap=True)


def _print_blocks(b: dict) -> None:
    from rich.table import Table

    t = Table(title=f"per-block timing: {b['groups']:,} logged block groups, RMS {b['rms']:.3f} s "
                    f"(noise floor ≈ {b['noise_floor_per_group']:.2f} s per group)", title_justify="left")
    for col in ("kind", "groups", "measured s", "simulated s", "simulated − measured s", "RMS s"):
        t.add_column(col, justify="left" if col == "kind" else "right")
    for k in b["by_kind"]:
        t.add_row(k["kind"], f"{k['groups']:,}", f"{k['measured']:.1f}", f"{k['simulated']:.1f}", f"{k['error']:+.1f}",
                  f"{k['rms']:.3f}")
    err.print(t)
    w = Table(title="worst blocks", title_justify="left")
    for col in ("lines", "kind", "measured s", "simulated s", "error s", "G-code"):
        w.add_column(col, justify="right" if col.endswith(" s") else "left")
    for x in b["worst"]:
        lines = f"{x['first_line']}" + (f"–{x['last_line']}" if x["last_line"] != x["first_line"] else "")
        w.add_row(lines, x["kind"], f"{x['measured']:.2f}", f"{x['simulated']:.2f}", f"{x['error']:+.2f}", x["text"][:40])
    err.print(w)


AnyProgramOpt = typer.Option(False, "--any-program", help="Accept a log whose program name is not the file's "
                             "(a renamed file).")
IgnoreItemOpt = typer.Option(None, "--ignore-item", metavar="NAME",
                             help="A data item of an MTConnect log to read past (an unknown item is an error).")
PartialOpt = typer.Option(False, "--partial", help="A log whose run did not finish: compare the part that ran (up "
                          "to the last line reached) instead of refusing it.")


@app.command(short_help="Compare the twin with a measurement: errors, and where.")
@_reports_errors
def compare(
    part: str = typer.Argument(..., help="G-code program the measurement was recorded on."),
    measurement: str = typer.Argument(..., help="Measurement file (measurement format: CSV or .parquet), or an "
                                                 "MTConnect log (SHDR or agent XML)."),
    align: str = typer.Option("auto", "--align", help="auto | line | position | xcorr."),
    xcorr_signal: Optional[str] = typer.Option(None, "--xcorr-signal", help="Signal for --align xcorr."),
    maps: Optional[list[str]] = typer.Option(None, "--map", metavar="SRC=DST[*SCALE]",
                                             help="Read column SRC as signal DST (times SCALE)."),
    json_out: bool = typer.Option(False, "--json", help="The comparison as JSON on stdout."),
    report: Optional[str] = typer.Option(None, "--report", help="Write a self-contained HTML report (.html)."),
    tooth_resolution: bool = typer.Option(False, "--tooth-resolution",
                                          help="Simulate tooth-passing forces (for a dynamometer's measurement)."),
    any_program: bool = AnyProgramOpt,
    ignore_item: Optional[list[str]] = IgnoreItemOpt,
    partial: bool = PartialOpt,
    effect: Optional[list[str]] = EffectOpt,
    effect_file: Optional[list[str]] = EffectFileOpt,
    stock: Optional[str] = typer.Option(None, "--stock", help="Stock box xmin,ymin,zmin,xmax,ymax,zmax in mm."),
    twin: Optional[str] = TwinOpt,
    dialect: Optional[str] = DialectOpt,
    lenient: bool = LenientOpt,
    block_delete: Optional[bool] = BlockDeleteOpt,
):
    """How far the twin is from a measurement of PART, signal by signal, and the program lines
    where it is farthest."""
    if report is not None and not report.endswith((".html", ".htm")) and report != "-":
        raise MtwinError(f"--report {report}: the report is an .html file")
    from .loop.compare import compare as run_compare

    tw, prog, meas, box = _loop_inputs(part, measurement, maps, effect, effect_file, stock, twin, dialect, lenient,
                                       block_delete, any_program, ignore_item, partial)
    # the cut loads the drives too: simulate it whenever the program cuts, whatever is measured
    cutting = not prog.turning_line()
    trace = tw.simulate(prog, stock=box, cutting=cutting, tooth_resolution=tooth_resolution)
    res = run_compare(trace, meas, align, xcorr_signal, program=prog)
    for n in res.notes:
        err.print(f"note: {n}", soft_wrap=True)
    blocks = res.blocks
    if blocks is not None:
        res_blocks = blocks.as_dict(prog.data.decode("latin-1").split("\n"))
        if blocks.hold_time > 0:
            err.print(f"note: {blocks.hold_time:.1f} s of feed hold taken out of the measured times", soft_wrap=True)
        for x in blocks.stops:
            where = (f"line {x['line']} ({x['state']})" if "line" in x else
                     f"{x['t0']:.1f}–{x['t1']:.1f} s (logged {x['state']})")
            err.print(f"note: program stop at {where}: waited {x['wait']:.1f} s — the operator's time, taken out of "
                      f"the block timing and the cycle time", soft_wrap=True)
        for x in blocks.excluded[:5]:
            err.print(f"note: lines {x['first_line']}–{x['last_line']} left out of the block timing: {x['reason']} "
                      f"at {x['t0']:.1f}–{x['t1']:.1f} s", soft_wrap=True)
        if len(blocks.excluded) > 5:
            err.print(f"note: {len(blocks.excluded) - 5} more block groups left out (the machine held)", soft_wrap=True)
    if report:
        from .loop.journal import read_journal
        from .report.compare_html import compare_html

        write_output(compare_html(res, prog.path, measurement, read_journal(twin) if twin else None), report,
                     [part, measurement])
        err.print(f"wrote {report}", soft_wrap=True)
    if json_out:
        sys.stdout.write(json.dumps(res.as_dict(prog.data.decode("latin-1").split("\n")), indent=2) + "\n")
        return
    from rich.table import Table

    if blocks is not None and len(blocks.measured):
        _print_blocks(res_blocks)
    c = res.cycle_time
    if c["measured"] is None:  # a summary measurement has no clock
        err.print(f"{prog.path} against {measurement}: {len(meas.rows)} summary rows by line range; "
                  f"simulated cycle time {c['simulated']:.3f} s", soft_wrap=True)
    else:
        rel = f"{c['relative_error']:+.2%}" if c["relative_error"] is not None else "-"
        err.print(f"{prog.path} against {measurement}: aligned by {res.alignment}, time offset "
                  f"{res.time_offset:+.3f} s; cycle time measured {c['measured']:.3f} s, simulated "
                  f"{c['simulated']:.3f} s ({rel})", soft_wrap=True)
    from .loop.measurement import signal_unit

    t = Table(title="signals (measured − simulated; RMS, max and bias in the signal's unit)", title_justify="left")
    for col in ("signal", "unit", "RMS", "NRMSE", "max", "bias", "corr.", "samples"):
        t.add_column(col, justify="right" if col not in ("signal", "unit") else "left", no_wrap=col == "signal")
    fmt = lambda v, f: "-" if v is None else format(v, f)  # noqa: E731
    for s, m in res.signals.items():
        t.add_row(s, signal_unit(s), fmt(m["rms"], ".4g"), fmt(m["nrmse"], ".2%"), fmt(m["max_error"], ".4g"),
                  fmt(m["bias"], "+.4g"), fmt(m["correlation"], ".3f"), f"{m['samples']:,}")
    err.print(t)
    if res.worst_regions:
        w = Table(title="where it fails (share of each signal's squared error)", title_justify="left")
        for col in ("signal", "unit", "lines", "RMS", "share", "samples"):
            w.add_column(col)
        for r in res.worst_regions:
            lines = str(r["first_line"]) if r["first_line"] == r["last_line"] else f"{r['first_line']}–{r['last_line']}"
            w.add_row(r["signal"], signal_unit(r["signal"]), lines, f"{r['rms']:.4g}", f"{r['share']:.1%}",
                      f"{r['samples']:,}")
        err.print(w)


def _loop_inputs(part, measurement, maps, effect, effect_file, stock, twin, dialect, lenient, block_delete,
                 any_program=False, ignore_item=None, partial=False):
    """The twin (with its effects and --effect), the program as the measurement says it ran
    (a control's logged overrides applied; up to the last line reached with --partial), the
    measurement, the stock."""
    tw, settings, box = _twin_inputs(twin, dialect, lenient, block_delete, effect, effect_file, stock)
    prog, meas = _measured_program(_load(part, settings), measurement, maps, any_program, ignore_item, partial)
    return tw, prog, meas, box


def _print_case_notes(case) -> None:
    """What a timing fit leaves out of a log: the operator's stops and holds."""
    g = case.groups
    for x in g.stop_groups:
        err.print(f"note: {case.label}: program stop at line {x['line']} ({x['state']}): waited {x['wait']:.1f} s "
                  f"(the operator's time), left out of the fit", soft_wrap=True, highlight=False)
    for x in g.logged_stops:
        err.print(f"note: {case.label}: program stop {x['t0']:.1f}–{x['t1']:.1f} s (logged {x['state']}), left out "
                  f"of the fit", soft_wrap=True, highlight=False)
    if g.hold_time > 0:
        err.print(f"note: {case.label}: {g.hold_time:.1f} s of feed hold left out of the fit", soft_wrap=True,
                  highlight=False)


def _measured_program(prog, measurement, maps, any_program, ignore_item, partial):
    """(the program as it ran, the measurement) for a measurement file of ``prog``."""
    from .loop.asrun import as_run
    from .loop.measurement import check_against_program, read_measurement

    meas = read_measurement(measurement, maps, ignore_item or ())
    check_against_program(meas, prog, any_program)
    run = as_run(prog, meas, partial)
    for n in run.notes:
        err.print(f"note: {measurement}: {n}", soft_wrap=True, highlight=False)
    return run.program, run.measurement


SignalsOpt = typer.Option(None, "--signals", help="Comma-separated signals to use (default: all in both).")
MapOpt = typer.Option(None, "--map", metavar="SRC=DST[*SCALE]", help="Read column SRC as signal DST (times SCALE).")
AlignOpt = typer.Option("auto", "--align", help="auto | line | position | xcorr.")
ObjectiveOpt = typer.Option("auto", "--objective", help="signals (the residual of each signal) | timing (the block "
                            "times of a log of the executing line) | auto: timing for a control's log (line, feed "
                            "and spindle speed only) and timing effects, else signals.")

def _objective(objective: str, meas, effects) -> str:
    if objective not in ("auto", "signals", "timing"):
        raise MtwinError(f"--objective {objective}: expected auto, signals or timing")
    if objective != "auto":
        return objective
    log = (meas.t is not None and meas.line is not None and (meas.line > 0).any()
           and set(meas.signals) <= {"feed", "spindle_speed"})
    return "timing" if log and all(e.stage == "plan" for e in effects or ()) else "signals"


@app.command(short_help="Which physical effect is missing from the twin.")
@_reports_errors
def diagnose(
    part: str = typer.Argument(..., help="G-code program the measurement was recorded on."),
    measurement: str = typer.Argument(..., help="Measurement file."),
    signals: Optional[str] = SignalsOpt,
    candidates: Optional[str] = typer.Option(None, "--candidates", help="Comma-separated effects to try (default: all "
                                             "not yet in the twin)."),
    objective: str = ObjectiveOpt,
    any_program: bool = AnyProgramOpt,
    ignore_item: Optional[list[str]] = IgnoreItemOpt,
    partial: bool = PartialOpt,
    align: str = AlignOpt,
    maps: Optional[list[str]] = MapOpt,
    json_out: bool = typer.Option(False, "--json", help="The diagnosis as JSON on stdout."),
    effect: Optional[list[str]] = EffectOpt,
    effect_file: Optional[list[str]] = EffectFileOpt,
    stock: Optional[str] = typer.Option(None, "--stock", help="Stock box xmin,ymin,zmin,xmax,ymax,zmax in mm."),
    twin: Optional[str] = TwinOpt,
    dialect: Optional[str] = DialectOpt,
    lenient: bool = LenientOpt,
    block_delete: Optional[bool] = BlockDeleteOpt,
):
    """For each signal: does the twin fit the measurement, and if not, which effect not yet in
    the twin explains the residual (each fitted alone, ranked by ΔBIC).  Against a control's
    log of its executing line (an MTConnect log): which timing effect explains the block
    times, ranked by the error each removes."""
    from .loop.fit import diagnose as run_diagnose
    from .loop.fit import target

    tw, prog, meas, box = _loop_inputs(part, measurement, maps, effect, effect_file, stock, twin, dialect, lenient,
                                       block_delete, any_program, ignore_item, partial)
    if _objective(objective, meas, None) == "timing":
        from .loop.timing import diagnose_timing, timing_case

        case = timing_case(tw, prog, meas, measurement)
        _print_case_notes(case)
        d = diagnose_timing(tw, [case], [c.strip() for c in candidates.split(",")] if candidates else None)
        if json_out:
            sys.stdout.write(json.dumps({"objective": "timing", "timing": d}, indent=2) + "\n")
            return
        c0 = d["before"]["cases"][0]
        err.print(f"[bold]block timing[/bold]: cycle time {c0['cycle_error']:+.2%}; per-group RMS {d['rms']:.3g} s "
                  f"(noise {d['noise']:.2g}); over {d['before']['windows']} windows: RMS {d['window_rms']:.3g} s "
                  f"(noise {d['window_noise']:.2g}) — {d['verdict']}", soft_wrap=True)
        for c in d["candidates"]:
            err.print(f"  {c['evidence']}", soft_wrap=True)
        return
    tg = target(tw, prog, meas, align, [s.strip() for s in signals.split(",")] if signals else None, box)
    d = run_diagnose(tg, [c.strip() for c in candidates.split(",")] if candidates else None)
    if json_out:
        sys.stdout.write(json.dumps({"alignment": tg.alignment, "signals": d}, indent=2) + "\n")
        return
    for s, v in d.items():
        err.print(f"[bold]{s}[/bold]: RMS {v['rms']:.4g} against noise {v['noise']:.4g} — {v['verdict']}", soft_wrap=True)
        for c in v["candidates"][:3]:
            err.print(f"  {c['evidence']}", soft_wrap=True)
        # the forward selection, where it says more than the single ranking's first line
        if v["selected"] and (len(v["selected"]) > 1 or v["selected"][0]["effect"] != v["candidates"][0]["effect"]):
            chain = " → ".join(f"{x['effect']} (ΔBIC {x['delta_bic']:+.1f})" for x in v["selected"])
            err.print(f"  together: {chain}: residual RMS {v['rms_after']:.4g} against noise {v['noise']:.4g}",
                      soft_wrap=True)


@app.command(short_help="Fit effects to a measurement; write the twin file.")
@_reports_errors
def calibrate(
    part: str = typer.Argument(..., help="G-code program the measurement was recorded on."),
    measurement: str = typer.Argument(..., help="Measurement file, or an MTConnect log."),
    more: Optional[list[str]] = typer.Argument(None, metavar="[PART MEASUREMENT]...",
                                               help="More programs with their measurements: a timing fit over all "
                                                    "of them."),
    output: str = typer.Option(..., "-o", "--output", help="Twin file to write (the effects and the journal added)."),
    fit_effect: Optional[list[str]] = typer.Option(None, "--fit", metavar="NAME[:P=V,…]",
                                                   help="An effect to add and fit (repeatable; values are starts)."),
    param: Optional[list[str]] = typer.Option(None, "--param", help="A base parameter to fit too, e.g. "
                                              "axes.x.friction.viscous (repeatable)."),
    validate: Optional[str] = typer.Option(None, "--validate", help="A second measurement of PART: the error on it "
                                           "after the fit."),
    refit: bool = typer.Option(False, "--refit", help="Fit the twin's own effects again too, together with the new ones."),
    objective: str = ObjectiveOpt,
    any_program: bool = AnyProgramOpt,
    ignore_item: Optional[list[str]] = IgnoreItemOpt,
    partial: bool = PartialOpt,
    signals: Optional[str] = SignalsOpt,
    align: str = AlignOpt,
    maps: Optional[list[str]] = MapOpt,
    json_out: bool = typer.Option(False, "--json", help="The fit as JSON on stdout."),
    effect: Optional[list[str]] = EffectOpt,
    effect_file: Optional[list[str]] = EffectFileOpt,
    stock: Optional[str] = typer.Option(None, "--stock", help="Stock box xmin,ymin,zmin,xmax,ymax,zmax in mm."),
    twin: Optional[str] = TwinOpt,
    dialect: Optional[str] = DialectOpt,
    lenient: bool = LenientOpt,
    block_delete: Optional[bool] = BlockDeleteOpt,
):
    """Fit the --fit effects' parameters (and --param base parameters) to the measurement by
    bounded least squares; write the twin file with them and a journal entry.  Against a
    control's log of its executing line the fit is to the block times (--objective timing),
    over every PART MEASUREMENT pair given."""
    from pathlib import Path as _P

    from .effects import parse_effect_spec
    from .loop.fit import fit, target
    from .loop.journal import calibrated_text, journal_entry, read_journal
    if not fit_effect and not param and not refit:
        raise MtwinError("nothing to fit: give --fit NAME (see mtwin effects), --param NAME or --refit")
    if more and len(more) % 2:
        raise MtwinError(f"more programs come in pairs PART MEASUREMENT: {more[-1]} has no measurement")
    tw, prog, meas, box = _loop_inputs(part, measurement, maps, effect, effect_file, stock, twin, dialect, lenient,
                                       block_delete, any_program, ignore_item, partial)
    new = [parse_effect_spec(e) for e in fit_effect or ()]
    own = {e.name for e in tw.effects}
    if any(e.name in own for e in new) and not refit:
        # fitting an effect the twin already has: fit it from its current values (stacking a
        # second copy on top would write only the increment)
        keep = [e for e in tw.effects if e.name not in {x.name for x in new}]
        new = [next((e for e in tw.effects if e.name == x.name), x) if not x.values else x for x in new]
        tw = tw.replace(effects=tuple(keep), share_cache=False)
    if refit:
        # the twin's effects start from their current values and are fitted with the new ones
        new = list(tw.effects) + [e for e in new if e.name not in {x.name for x in tw.effects}]
        tw = tw.replace(effects=(), share_cache=False)
    sig = [s.strip() for s in signals.split(",")] if signals else None
    how = _objective(objective, meas, new)
    pairs = [(part, measurement)] + list(zip((more or [])[::2], (more or [])[1::2]))
    if how == "timing":
        from .loop.timing import fit_timing, summary, timing_case

        cases = [timing_case(tw, prog, meas, os.path.basename(measurement))]
        _print_case_notes(cases[0])
        for p_i, m_i in pairs[1:]:
            prog_i, meas_i = _measured_program(_load(p_i, tw.interpreter), m_i, maps, any_program, ignore_item,
                                               partial)
            cases.append(timing_case(tw, prog_i, meas_i, os.path.basename(m_i)))
            _print_case_notes(cases[-1])
        res = fit_timing(tw, cases, new, tuple(param or ()))
    else:
        if len(pairs) > 1:
            raise MtwinError("several programs are fitted together only by their block times (--objective timing)")
        tg = target(tw, prog, meas, align, sig, box)
        res = fit(tg, new, sig, tuple(param or ()))
    fitted = {e.name: e for e in res.effects}
    effects = [fitted.pop(e.name, e) for e in tw.effects] + list(fitted.values())
    base = {k: v for k, v in res.params.items() if not k.startswith("effects.")}
    validation = None
    if validate:
        fitted_base = tw.with_params(base) if base else tw
        tw2 = tw.replace(machine=fitted_base.machine, cutting=fitted_base.cutting, effects=effects, share_cache=False)
        prog, meas2 = _measured_program(_load(part, tw.interpreter), validate, maps, any_program, ignore_item,
                                        partial)
        if how == "timing":
            v = summary(tw2, [timing_case(tw2, prog, meas2, validate)])
            validation = {"measurement": validate, "block_time": v["rms"], "cycle_error": v["cases"][0]["cycle_error"]}
        else:
            from .loop.fit import _rms_by_signal

            tg2 = target(tw2, prog, meas2, align, sig, box)
            validation = {"measurement": validate, **_rms_by_signal(tg2, tg2.base, list(tg2.measured))}
    previous = read_journal(twin) if twin else []
    source = _P(twin).read_text(encoding="utf-8") if twin else ""
    label = "; ".join(os.path.basename(m) for _, m in pairs) if len(pairs) > 1 else measurement
    # a control's log that did not log its overrides: the values fitted to it are effective ones
    logs = [meas] + ([c.meas for c in cases[1:]] if how == "timing" else [])
    notes = [f"{os.path.basename(m.path)}: overrides {m.meta['overrides']}; the fitted values are effective (they "
             f"include any override the operator set)" for m in logs if "not logged" in m.meta.get("overrides", "")]
    text = calibrated_text(source, effects, journal_entry(len(previous) + 1, label, res, validation, notes), previous,
                           base, tw)
    write_output(text.encode(), output, [p for pair in pairs for p in pair])
    if json_out:
        sys.stdout.write(json.dumps({**res.as_dict(), "validation": validation, "twin_file": output}, indent=2) + "\n")
        return
    for k, v in res.params.items():
        u = res.uncertainty.get(k)
        read = k in getattr(res, "rapid_rates", {})
        err.print(f"{k} = {v:.6g}" + (f" ± {u:.2g}" if u is not None else "")
                  + (" (read off the logged rapids)" if read else ""), soft_wrap=True)
    if param:
        err.print(f"note: the fitted base parameters are written into {output}'s sections (the file is written "
                  f"back from its parsed form: its comments are not kept, but its opening comment block is)",
                  soft_wrap=True)
    for s_ in res.rms_before:
        err.print(f"{s_}: RMS {res.rms_before[s_]:.4g} → {res.rms_after[s_]:.4g} (noise {res.noise[s_]:.4g})",
                  soft_wrap=True)
    if how == "timing":
        for b_, a_ in zip(res.before["cases"], res.after["cases"]):
            err.print(f"{a_['measurement']}: cycle time {b_['cycle_error']:+.2%} → {a_['cycle_error']:+.2%} "
                      f"(measured {a_['cycle_measured']:.1f} s, simulated {a_['cycle_simulated']:.1f} s); "
                      f"windows RMS {b_['window_rms']:.3g} → {a_['window_rms']:.3g} s", soft_wrap=True)
    if validation:
        err.print("validation on " + validate + ": " + ", ".join(
            f"{k} {v:+.2%}" if k == "cycle_error" else f"{k} RMS {v:.4g}"
            for k, v in validation.items() if k != "measurement"), soft_wrap=True)
    err.print(f"wrote {output} ({res.evaluations} evaluations)", soft_wrap=True)


@app.command(short_help="The model journal of a twin file: the error across calibrations.")
@_reports_errors
def journal(path: str = typer.Argument(..., help="Twin file."),
            json_out: bool = typer.Option(False, "--json", help="The journal as JSON on stdout.")):
    """Each calibration of the twin file: effects fitted, values, and the RMS error before and after."""
    from .loop.journal import read_journal

    j = read_journal(path)
    if json_out:
        sys.stdout.write(json.dumps(j, indent=2) + "\n")
        return
    if not j:
        err.print(f"{path}: no journal yet (mtwin calibrate … -o {path} writes one)")
        return
    from rich.table import Table

    err.print(f"{path}: model journal", soft_wrap=True, highlight=False)
    t = Table()
    for col in ("#", "effects", "measurement", "RMS before → after"):
        t.add_column(col)
    for e in j:
        rms = ", ".join(f"{s} {e['rms_before'][s]:.4g} → {e['rms_after'][s]:.4g}" for s in e.get("rms_before", {}))
        cyc = e.get("cycle_error_before", {})
        if cyc:
            rms += "; cycle time " + ", ".join(f"{cyc[k]:+.1%} → {e['cycle_error_after'].get(k, float('nan')):+.1%}"
                                                for k in cyc)
        t.add_row(str(e.get("iteration")), ", ".join(e.get("effects", [])), str(e.get("measurement", "")), rms)
    err.print(t)


effects_app = typer.Typer(help="The physical effects a twin can be given.",
                          invoke_without_command=True, rich_markup_mode=None)
app.add_typer(effects_app, name="effects")


@effects_app.callback()
@_reports_errors
def effects_list(ctx: typer.Context, effect_file: Optional[list[str]] = EffectFileOpt,
                 json_out: bool = typer.Option(False, "--json", help="The list as JSON on stdout.")):
    """List the effects: name, where it acts, what it changes."""
    _load_effect_files(effect_file)
    if ctx.invoked_subcommand is not None:
        return
    from .effects import BUILTIN, available

    builtin = {c.name for c in BUILTIN}
    rows = [{"name": n, "stage": c.stage, "origin": "built-in" if n in builtin else "user",
             "description": c.description, "signals": list(c.signals),
             "params": [p.name for p in c.params]} for n, c in available().items()]
    if json_out:
        sys.stdout.write(json.dumps(rows, indent=2) + "\n")
        return
    from rich.table import Table

    t = Table(title="effects (mtwin effects show NAME for one)", title_justify="left")
    for col in ("name", "acts", "what it is"):
        t.add_column(col, no_wrap=col != "what it is")
    for r in rows:
        t.add_row(r["name"] + ("" if r["origin"] == "built-in" else " (user)"),
                  {"loop": "in the loop", "plan": "before planning"}.get(r["stage"], "on observation"),
                  r["description"])
    err.print(t)


@effects_app.command("show")
@_reports_errors
def effects_show(name: str = typer.Argument(..., help="An effect's name."),
                 effect_file: Optional[list[str]] = EffectFileOpt):
    """One effect: what it is, how it acts, its parameters with units, bounds and defaults."""
    _load_effect_files(effect_file)
    from .effects import get

    c = get(name)
    lines = [f"{c.name}: {c.description}",
             "acts " + {"loop": "in the loop (the drives and the process feel it)",
                        "plan": "before planning (the controller's timing: the whole run follows it)"}.get(
                 c.stage, "on observation (a transform of the simulated trace)"),
             f"changes: {', '.join(c.signals)}", "parameters:"]
    for p in c.params:
        unit = f" {p.unit}" if p.unit else ""
        lines.append(f"  {p.name:10} default {p.default:g}{unit}, within [{p.lower:g}, {p.upper:g}]  {p.doc} {p.source}")
    lines.append(f"use: --effect {c.name}:" + ",".join(f"{p.name}={p.default:g}" for p in c.params[:2])
                 + f"   or in a twin file: [effects.{c.name}]")
    sys.stdout.write("\n".join(lines) + "\n")


cache_app = typer.Typer(help="The compiled-kernel cache.", no_args_is_help=True, rich_markup_mode=None)
app.add_typer(cache_app, name="cache")


@cache_app.command("warm")
@_reports_errors
def cache_warm(quiet: bool = typer.Option(False, "--quiet", help="No progress lines."),
               background: bool = typer.Option(False, "--background", hidden=True,
                                               help="Run as the background warm-up a first run starts.")):
    """Compile every kernel into the cache now (once per install; for container images)."""
    import time

    from . import _jit
    from .warmup import AlreadyWarming, background_lock, warm

    if background:
        # the detached warm-up a first run started: low priority, one at a time, silent
        from . import _jit as J

        J.compile_notice = J._no_notice
        J.uncached_notice = J._no_uncached
        with contextlib.suppress(OSError, AttributeError):
            os.nice(10)
        try:
            with background_lock():
                warm()
        except AlreadyWarming:
            pass
        return

    t0 = time.perf_counter()
    warm(lambda what: None if quiet else err.print(f"warming: {what}"))
    n = len(_jit.COMPILE_LOG)
    if not quiet:
        err.print(f"{n} kernel(s) compiled in {time.perf_counter() - t0:.1f} s; cache: {_cache_dir()}")


@cache_app.command("info")
@_reports_errors
def cache_info():
    """Where the cache is and how much it holds."""
    d = Path(_cache_dir())
    files = [p for p in d.rglob("*") if p.is_file()] if d.is_dir() else []
    size = sum(p.stat().st_size for p in files)
    sys.stdout.write(f"{d}\n{len(files)} files, {size / 1e6:.1f} MB\n")


@cache_app.command("clear")
@_reports_errors
def cache_clear():
    """Delete the compiled kernels (the next run compiles what it needs again)."""
    import shutil

    d = Path(_cache_dir())
    if d.is_dir():
        shutil.rmtree(d)
    err.print(f"removed {d}")


def _cache_dir() -> str:
    from . import _jit  # noqa: F401  (sets NUMBA_CACHE_DIR)

    return os.environ["NUMBA_CACHE_DIR"]


from . import cli_grind  # noqa: E402,F401  (registers `mtwin grind` on the app)


def main() -> None:
    # --traceback is a debugging switch a user adds at the end of a failing command line:
    # accept it anywhere, not only before the command as click would
    if "--traceback" in sys.argv[1:]:
        _state["traceback"] = True
        sys.argv = [a for a in sys.argv if a != "--traceback"]
    try:
        app()
    except KeyboardInterrupt:  # pragma: no cover (an interrupt before a command started)
        err.print(INTERRUPTED, highlight=False)
        sys.exit(130)


if __name__ == "__main__":  # pragma: no cover
    main()

