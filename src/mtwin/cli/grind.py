"""``mtwin grind``: plunge-grinding cycles (``mtwin.grind``'s use cases)."""
from __future__ import annotations

from typing import Optional

import typer

from .app import app, err, reports_errors
from .argtypes import check_outputs, grid as grid_size, write_output
from .options import JSON
from .render import emit_json

grind_app = typer.Typer(help="Plunge grinding: optimal stepped feed cycles.",
                        no_args_is_help=True, rich_markup_mode=None)
app.add_typer(grind_app, name="grind")

GrindTwinOpt = typer.Option(None, "--twin", help="Grind twin file (TOML); default: the reference's experiment.")


@grind_app.command("design", short_help="The fastest stepped cycle that every part of a batch survives.")
@reports_errors
def design(
    twin: Optional[str] = GrindTwinOpt,
    grid: str = typer.Option("40x40", "--grid", help="DP grid: feed levels x allowance levels."),
    cases: int = typer.Option(300, "--cases", help="Parts per robustness iteration (Latin hypercube)."),
    validate: int = typer.Option(1000, "--validate", help="Fresh parts the final cycle is checked on (0: none)."),
    seed: int = typer.Option(0, "--seed", help="Sampling seed."),
    iterations: int = typer.Option(10, "--iterations", help="Most robustness iterations."),
    output: Optional[str] = typer.Option(None, "-o", "--output", help="Write the cycle as G-code (.nc; '-': stdout)."),
    cycle_out: Optional[str] = typer.Option(None, "--cycle-out", help="Write the cycle file (TOML) for grind simulate."),
    report: Optional[str] = typer.Option(None, "--report", help="Write a self-contained HTML report."),
    json_out: bool = typer.Option(False, "--json", help="Result as JSON on stdout."),
):
    """The time-optimal stepped cycle by dynamic programming, then the robustness loop: the
    cycle run on a varied batch, defects turned into tighter limits, re-optimised until none."""
    from ..errors import MtwinError
    from ..grind import design as run_design

    size = grid_size(grid)
    if output == "-" and json_out:
        raise MtwinError("-o - and --json both write to stdout")
    check_outputs(output, cycle_out, report)
    shown = [0]

    def show(it):
        shown[0] += 1
        if not json_out:
            err.print(f"iteration {shown[0]}: cycle {it.cycle_time:.2f} s, {it.defects} of {it.cases} parts "
                      f"defective" + (f" ({', '.join(f'{k} {v}' for k, v in it.broken.items())})" if it.broken else ""),
                      highlight=False)

    d = run_design(twin, grid=size, cases=cases, validate=validate, seed=seed, iterations=iterations, progress=show)
    if output:
        write_output(d.gcode(), output, [])
    if cycle_out:
        write_output(d.cycle_toml().encode(), cycle_out, [])
    if report:
        from ..report.grind_html import grind_html

        write_output(grind_html(d.twin, d.result, d.trace_columns()), report, [])
    if json_out:
        emit_json(d.as_dict(), indent=1)
        return
    _print_design(d)


def _print_design(g) -> None:
    from .render import table

    res, d = g.result, g.result.design
    t = table(*((c, "right") for c in ("stage", "feed mm/min", "until gauge reads mm", "time s")),
              title=f"optimal plunge cycle: {d.cycle_time:.2f} s")
    for k, s in enumerate(d.stages, 1):
        t.add_row(str(k), f"{s.feed:.4g}", f"{s.switch_allowance:.4f}", f"{s.time:.2f}")
    t.add_row("spark-out", "0", "0 (size)", f"{g.sparkout_time:.2f}")
    err.print(t)
    if res.validation is not None:
        v = res.validation
        err.print(f"validation: {v.defects} of {v.cases} fresh parts defective"
                  + (f" ({', '.join(f'{k} {c}' for k, c in v.broken.items())})" if v.broken else ""), highlight=False)
    if not res.feasible:
        err.print("[yellow]warning: the robustness loop did not remove every defect (see the iterations)[/yellow]")


@grind_app.command("simulate", short_help="Run a cycle on the nominal part: time and limits.")
@reports_errors
def simulate(
    cycle: str = typer.Argument(..., help="Cycle file (TOML with [cycle] stages; may carry the twin's tables)."),
    twin: Optional[str] = GrindTwinOpt,
    output: Optional[str] = typer.Option(None, "-o", "--output", help="Write the trace (measurement format, .csv)."),
    json_out: bool = typer.Option(False, "--json", help="Result as JSON on stdout."),
):
    """Run a given cycle on the nominal part: time, size error, roundness, roughness proxy,
    burn and force, each against its limit, and the trace."""
    from ..grind import simulate as run_cycle
    from .render import table

    check_outputs(output)
    r = run_cycle(cycle, twin)
    if output:
        r.write_trace(output, cycle)
    if json_out:
        emit_json(r.as_dict(), indent=1)
        return
    figures, ratios = r.figures, r.ratios
    t = table(*((c, "right") for c in ("figure", "value", "of its limit")), title=f"{cycle}: {figures['cycle_time']:.2f} s")
    for name, key, unit in (("size error", "size_error", "mm"), ("roundness", "roundness", "mm"),
                            ("roughness proxy (feed/rev)", "roughness_feed", "mm"), ("burn Q'w", "burn_qw", "mm²/s"),
                            ("peak radial force", "peak_force", "N")):
        lim = {"size_error": "size", "roughness_feed": "roughness", "burn_qw": "burn", "peak_force": "force"}.get(key, key)
        t.add_row(name, f"{figures[key]:.5g} {unit}", f"{ratios[lim]:.0%}")
    err.print(t)
    if not figures["reached_size"]:
        err.print("[yellow]warning: the gauge never read size (the spark-out reached cycle.sparkout_max): the part "
                  "is oversize[/yellow]")


@grind_app.command("calibrate", short_help="Fit compliance and stress intensity to a recorded cycle.")
@reports_errors
def calibrate(
    cycle: str = typer.Argument(..., help="Cycle file the recording was made with (TOML with [cycle] stages)."),
    measurement: str = typer.Argument(..., help="Recorded cycle, measurement format: t, feed (actual radial "
                                                 "feed, mm/min) and fx (radial force, N)."),
    param: list[str] = typer.Option(["system.compliance", "work.sigma"], "--param",
                                    help="Parameter to fit, by dotted name (repeatable)."),
    twin: Optional[str] = GrindTwinOpt,
    output: Optional[str] = typer.Option(None, "-o", "--output", help="Write the fitted twin and the cycle (TOML)."),
    json_out: bool = JSON,
):
    """Fit grinding parameters (compliance and stress intensity by default) to a recorded
    cycle by bounded least squares on the actual feed and the radial force."""
    from ..grind import calibrate as run_calibrate

    check_outputs(output)
    c = run_calibrate(cycle, measurement, tuple(param), twin)
    if output:
        write_output(c.cycle_toml(measurement).encode(), output, [cycle])
    if json_out:
        emit_json(c.as_dict(), indent=1)
        return
    for k, v in c.result["values"].items():
        err.print(f"{k}: {c.twin[k]:.6g} -> {v:.6g} {c.unit(k)}", highlight=False)
    err.print(f"normalised RMS of feed and force residuals: {c.result['rms_before']:.4g} -> {c.result['rms_after']:.4g}",
              highlight=False)
