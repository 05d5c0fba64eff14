"""``mtwin simulate``: a program run on the twin."""
from __future__ import annotations

import contextlib
from typing import Optional

import typer

from ..errors import MtwinError
from .app import app, err, reports_errors
from .argtypes import check_outputs, write_output
from .options import PART, groups, twin_options
from .render import emit_json, hms, message

PROGRESS_FROM = 300_000  # servo samples from which a terminal shows a progress bar


@app.command(short_help="Run a program through the twin: time, errors, loads.")
@reports_errors
@groups(setup=twin_options(effects=True, stock=True, planner=True, tools=True, ledger=True))
def simulate(
    part: str = PART,
    output: Optional[str] = typer.Option(None, "-o", "--output",
                                         help="Write the trace (measurement format): .csv, .parquet, or '-'."),
    every: Optional[int] = typer.Option(None, "--every", help="Keep every N-th servo sample in the trace."),
    decimate: Optional[float] = typer.Option(None, "--decimate",
                                             help="Trace sample rate in Hz (e.g. 100); alternative to --every."),
    json_out: bool = typer.Option(False, "--json", help="Summary as JSON on stdout."),
    no_cutting: bool = typer.Option(False, "--no-cutting", help="Motion only: no stock, engagement or cutting forces."),
    plot: Optional[str] = typer.Option(None, "--plot", help="Write the spindle power against time: .svg, .png or .pdf "
                                       "('-': SVG on stdout)."),
    stock_out: Optional[str] = typer.Option(None, "--stock-out",
                                            help="Write the stock after the last cut: .png height map or .stl surface."),
    tooth_resolution: bool = typer.Option(False, "--tooth-resolution",
                                          help="Instantaneous tooth-passing forces instead of revolution averages."),
    runs: int = typer.Option(1, "--runs", help="Run the program N times on the same tools (a batch of parts: the "
                             "wear carried from part to part); the figures are the last run's."),
    record: bool = typer.Option(False, "--record", help="Add each run's cut to the --ledger tools' history."),
    dynamics: bool = typer.Option(False, "--dynamics", help="Regenerative chatter model at the tool tip along the "
                                  "trace (tools with modes): vib_x, vib_y and a verdict per line."),
    setup=None,
):
    """Run a program through the twin: cycle time, following errors, motor torques, trace."""
    from ..api import simulate as run_simulate, simulate_runs
    from ..report.plots import plot_format, power_svg
    from ..report.stock import stock_bytes

    plot_format(plot) if plot else None  # refused before the work, not after
    if stock_out and not stock_out.endswith((".png", ".stl")):
        raise MtwinError(f"--stock-out {stock_out}: use a .png (height map) or .stl (surface) file name")
    if stock_out and no_cutting:
        raise MtwinError("--stock-out needs the cutting model (do not combine it with --no-cutting)")
    check_outputs(output, plot, stock_out)
    if dynamics and (runs != 1 or record):
        raise MtwinError("--dynamics runs on one simulation: leave out --runs and --record")
    if runs != 1 or record:  # (simulate_runs refuses a count below 1)
        run = simulate_runs(setup, part, runs, record=record, stock=setup.stock_box(), cutting=not no_cutting,
                            on_message=message)
    else:
        with _progress() as progress:
            run = run_simulate(setup, part, stock=setup.stock_box(), cutting=not no_cutting, every=every,
                               rate=decimate, tooth_resolution=tooth_resolution,
                               progress=None if json_out else progress, progress_from=PROGRESS_FROM,
                               on_message=message, dynamics=dynamics)
    if output:
        run.write_trace(output)
    if stock_out:
        write_output(stock_bytes(run.trace.engagement.stock, stock_out), stock_out, [part])
    if plot:
        write_output(power_svg(run.trace, f"{run.program.path}: spindle power", plot_format(plot)), plot, [part])
    if json_out:
        emit_json({**run.as_dict(), "trace": output, "plot": plot})
        return
    _print_runs(run)
    _print_simulation(run.program.path, run.summary, output, run.inch)
    _print_chatter(run)


@contextlib.contextmanager
def _progress():
    """A progress callback for the servo loop: a bar on stderr, started at the first report."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    state = {}

    def progress(k: int, total: int) -> None:
        if "bar" not in state:
            state["bar"] = Progress(TextColumn("simulating"), BarColumn(), TextColumn("{task.percentage:>3.0f}%"),
                                    TimeRemainingColumn(), console=err, transient=True)
            state["bar"].start()
            state["task"] = state["bar"].add_task("sim", total=total)
        state["bar"].update(state["task"], completed=k)

    try:
        yield progress
    finally:
        if "bar" in state:
            state["bar"].stop()


def _print_simulation(path: str, s, output, inch: bool = False) -> None:
    from rich.table import Table

    err.print(f"{path} on {s.machine} ({s.style} planner)", soft_wrap=True, highlight=False)
    t = Table(show_header=False)
    t.add_column(style="bold")
    t.add_column()
    t.add_row("cycle time", f"{s.cycle_time:,.3f} s  ({hms(s.cycle_time)})")
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
        t.add_row("cutting", f"none: no feed move meets the stock, X {b[0]:g}…{b[3]:g}  Y {b[1]:g}…{b[4]:g}  "
                             f"Z {b[2]:g}…{b[5]:g} mm, {c.stock_source}")
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
                           f"{c.resolution:g} mm cells, {c.stock_source}; {c.material}")
        from rich.markup import escape

        for d in c.defaults:
            read = d.startswith("tool T") or (d.startswith("material:") and ") from " in d)
            t.add_row(d.split(" ", 1)[0].rstrip(":") if read else "default used", escape(d))
    if s.per_line is not None and s.per_line.worst(1):
        t.add_row("slowest lines", "simulated against nominal time (length/F, rapids at the axes' speed)")
        for r in s.per_line.worst(5):
            t.add_row(f"line {r['line']}", f"{r['time']:,.3f} s, nominal {r['nominal']:,.3f} s (+{r['time'] - r['nominal']:,.3f} s)"
                                           + (f": {r['reason']}" if r["reason"] else ""))
    t.add_row("servo samples", f"{s.samples:,} at {s.servo_period * 1000:g} ms")
    if output:
        t.add_row("trace", str(output))
    err.print(t)


def _print_runs(run) -> None:
    """The runs of a batch, one row each: loads and each tool's land; the tools recorded."""
    from .render import table

    if run.runs:
        tools = sorted({t for r in run.runs for t in r["tool_wear"]})
        rows = [[str(r["run"]), hms(r["cycle_time"]), f"{r['mean_load']:.1f}" if r["mean_load"] is not None else "-",
                 f"{r['peak_load']:.1f}" if r["peak_load"] is not None else "-"]
                + [f"{r['tool_wear'][t]['vb_end']:.3f}" if t in r["tool_wear"] else "-" for t in tools]
                for r in run.runs]
        t = table(*((c, "right") for c in ["run", "cycle", "mean load N", "peak load N"]
                    + [f"VB T{n} mm" for n in tools]), title="runs on the same tools")
        for r in rows:
            t.add_row(*r)
        err.print(t)
    if run.recorded:
        err.print(f"recorded the run(s) in the ledger for: {', '.join(run.recorded)}")


def _print_chatter(run) -> None:
    """The chatter margins (tools with dynamics) and the time-domain verdicts (--dynamics)."""
    c = run.summary.cutting
    ch = c.chatter if c is not None else {}
    if ch:
        over = ch["unstable_lines"]
        err.print(f"chatter: the worst cut uses {ch['worst_margin']:.2f} of its stability limit (line "
                  f"{ch['worst_line']}); " + (f"{len(over)} line(s) over the limit: "
                                               f"{', '.join(map(str, over[:12]))}{' …' if len(over) > 12 else ''}"
                                               if over else "every cut is stable"), highlight=False)
    if run.dynamics is not None:
        for x in run.dynamics.lines:
            if x.get("diverged"):
                err.print(f"  line {x['line']}: chatters in the time domain (the regenerative vibration grows without "
                          f"bound: far beyond its stability limit)", highlight=False)
            elif x["chatter"]:
                f = x.get("chatter_frequency")
                err.print(f"  line {x['line']}: chatters in the time domain (regenerative vibration "
                          f"{x['regen_start_um']:.3g} → {x['regen_end_um']:.3g} µm" + (f", {f:.0f} Hz)" if f else ")"),
                          highlight=False)
        n = sum(x["chatter"] for x in run.dynamics.lines)
        err.print(f"dynamics: {n} of {len(run.dynamics.lines)} cutting line(s) chatter in the time domain",
                  highlight=False)
