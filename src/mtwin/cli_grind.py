"""``mtwin grind``: plunge-grinding cycles (on the app of ``cli_app.py``; ``cli.py`` imports this
module to register them).

Heavy modules are imported inside the commands, as in ``cli.py``."""
from __future__ import annotations

import json
import sys
from typing import Optional

import typer

from .cli_app import _reports_errors, app, check_outputs, err, write_output
from .errors import MtwinError

grind_app = typer.Typer(help="Plunge grinding: optimal stepped feed cycles.",
                        no_args_is_help=True, rich_markup_mode=None)
app.add_typer(grind_app, name="grind")

GrindTwinOpt = typer.Option(None, "--twin", help="Grind twin file (TOML); default: the reference's experiment.")


def _check_feeds(tw, stages, where: str) -> None:
    lo, hi = tw["machine.feed_min"], tw["machine.feed_max"]
    for k, s in enumerate(stages, 1):
        if not lo <= s.feed <= hi:
            raise MtwinError(f"{where}: stage {k}: feed {s.feed:g} mm/min is outside the machine's range "
                             f"{lo:g}-{hi:g} mm/min (machine.feed_min, machine.feed_max)")


def _grid(text: str) -> tuple[int, int]:
    try:
        m, n = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise MtwinError(f"--grid {text!r}: expected FEEDSxALLOWANCES, e.g. 40x40") from None
    if not (2 <= m <= 400 and 2 <= n <= 400):
        raise MtwinError(f"--grid {text!r}: each size must be between 2 and 400")
    return m, n


@grind_app.command("design", short_help="The fastest stepped cycle that every part of a batch survives.")
@_reports_errors
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
    from .grind.io import cycle_gcode, cycle_toml, trace_columns
    from .grind.model import GrindTwin
    from .grind.robust import robust_design

    M, N = _grid(grid)
    if cases < 10 or validate < 0 or iterations < 1 or seed < 0:
        raise MtwinError("--cases must be at least 10, --validate and --seed at least 0, --iterations at least 1")
    if output == "-" and json_out:
        raise MtwinError("-o - and --json both write to stdout")
    check_outputs(output, cycle_out, report)
    tw = GrindTwin.from_toml(twin)

    def show(it):
        if not json_out:
            err.print(f"iteration {len(res_iters) + 1}: cycle {it.cycle_time:.2f} s, {it.defects} of {it.cases} parts "
                      f"defective" + (f" ({', '.join(f'{k} {v}' for k, v in it.broken.items())})" if it.broken else ""),
                      highlight=False)
        res_iters.append(it)

    res_iters: list = []
    res = robust_design(tw, M, N, cases, seed, iterations, validate, progress=show)
    d = res.design
    if not d.stages:
        raise MtwinError("no cycle holds every limit on the nominal part within the machine's feed range "
                         "(see the limits and the variation in docs/grinding.md)")
    if output:
        write_output(cycle_gcode(tw, d.stages, d.sparkout * 60.0 / tw["work.speed"]).encode(), output, [])
    if cycle_out:
        write_output(cycle_toml(tw, d.stages, f"designed by mtwin grind design, {d.cycle_time:.2f} s").encode(),
                     cycle_out, [])
    if report:
        from .report.grind_html import grind_html

        write_output(grind_html(tw, res, trace_columns(tw, d.stages)), report, [])
    doc = {"cycle_time": d.cycle_time, "stages": [s.as_dict() for s in d.stages], "sparkout_revolutions": d.sparkout,
           "robustness": [it.as_dict() for it in res.iterations], "robust": res.feasible,
           "validation": res.validation.as_dict() if res.validation else None, "dp_seconds": d.seconds,
           "seconds": res.seconds}
    if json_out:
        sys.stdout.write(json.dumps(doc, indent=1) + "\n")
        return
    from rich.table import Table

    t = Table(title=f"optimal plunge cycle: {d.cycle_time:.2f} s", title_justify="left")
    for c in ("stage", "feed mm/min", "until gauge reads mm", "time s"):
        t.add_column(c, justify="right")
    for k, s in enumerate(d.stages, 1):
        t.add_row(str(k), f"{s.feed:.4g}", f"{s.switch_allowance:.4f}", f"{s.time:.2f}")
    t.add_row("spark-out", "0", "0 (size)", f"{d.sparkout * 60.0 / tw['work.speed']:.2f}")
    err.print(t)
    if res.validation is not None:
        v = res.validation
        err.print(f"validation: {v.defects} of {v.cases} fresh parts defective"
                  + (f" ({', '.join(f'{k} {c}' for k, c in v.broken.items())})" if v.broken else ""), highlight=False)
    if not res.feasible:
        err.print("[yellow]warning: the robustness loop did not remove every defect (see the iterations)[/yellow]")


@grind_app.command("simulate", short_help="Run a cycle on the nominal part: time and limits.")
@_reports_errors
def simulate(
    cycle: str = typer.Argument(..., help="Cycle file (TOML with [cycle] stages; may carry the twin's tables)."),
    twin: Optional[str] = GrindTwinOpt,
    output: Optional[str] = typer.Option(None, "-o", "--output", help="Write the trace (measurement format, .csv)."),
    json_out: bool = typer.Option(False, "--json", help="Result as JSON on stdout."),
):
    """Run a given cycle on the nominal part: time, size error, roundness, roughness proxy,
    burn and force, each against its limit, and the trace."""
    from .grind.cycle import run_cycle
    from .grind.io import read_cycle, trace_columns
    from .grind.model import Batch, GrindTwin

    check_outputs(output)
    stages = read_cycle(cycle)
    tw = GrindTwin.from_toml(twin if twin else cycle)
    _check_feeds(tw, stages, cycle)
    _, q, times = run_cycle(tw, Batch.nominal(tw), stages)
    v = q.violations(tw)
    figures = {"cycle_time": float(q.cycle_time[0]), "size_error": float(q.size_error[0]),
               "roundness": float(q.roundness[0]), "roughness_feed": float(q.roughness_feed[0]),
               "burn_qw": float(q.burn_qw[0]), "peak_force": float(q.peak_force[0]), "reached_size": bool(q.reached[0])}
    ratios = {k: float(x[0]) for k, x in v.items()}
    if output:
        from .motion.trace import write_columns

        write_columns(output, trace_columns(tw, stages), {"source": "mtwin grind simulate", "cycle": cycle})
    if json_out:
        sys.stdout.write(json.dumps({**figures, "limit_ratios": ratios,
                                     "stage_times": [float(x) for x in times]}, indent=1) + "\n")
        return
    from rich.table import Table

    t = Table(title=f"{cycle}: {figures['cycle_time']:.2f} s", title_justify="left")
    for c in ("figure", "value", "of its limit"):
        t.add_column(c, justify="right")
    for name, key, unit in (("size error", "size_error", "mm"), ("roundness", "roundness", "mm"),
                            ("roughness proxy (feed/rev)", "roughness_feed", "mm"), ("burn Q'w", "burn_qw", "mm²/s"),
                            ("peak radial force", "peak_force", "N")):
        lim = {"size_error": "size", "roughness_feed": "roughness", "burn_qw": "burn", "peak_force": "force"}.get(key, key)
        t.add_row(name, f"{figures[key]:.5g} {unit}", f"{ratios[lim]:.0%}")
    err.print(t)
    if not q.reached[0]:
        err.print("[yellow]warning: the gauge never read size (the spark-out reached cycle.sparkout_max): the part "
                  "is oversize[/yellow]")


@grind_app.command("calibrate", short_help="Fit compliance and stress intensity to a recorded cycle.")
@_reports_errors
def calibrate(
    cycle: str = typer.Argument(..., help="Cycle file the recording was made with (TOML with [cycle] stages)."),
    measurement: str = typer.Argument(..., help="Recorded cycle, measurement format: t, feed (actual radial "
                                                 "feed, mm/min) and fx (radial force, N)."),
    param: list[str] = typer.Option(["system.compliance", "work.sigma"], "--param",
                                    help="Parameter to fit, by dotted name (repeatable)."),
    twin: Optional[str] = GrindTwinOpt,
    output: Optional[str] = typer.Option(None, "-o", "--output", help="Write the fitted twin and the cycle (TOML)."),
    json_out: bool = typer.Option(False, "--json", help="Result as JSON on stdout."),
):
    """Fit grinding parameters (compliance and stress intensity by default) to a recorded
    cycle by bounded least squares on the actual feed and the radial force."""
    import numpy as np

    from .grind.io import cycle_toml, fit, read_cycle
    from .grind.model import BY_NAME, GrindTwin
    from .loop.measurement import read_measurement

    unknown = [p for p in param if p not in BY_NAME]
    if unknown:
        raise MtwinError(f"--param {unknown[0]}: not a grinding parameter (known: {', '.join(BY_NAME)})")
    check_outputs(output)
    stages = read_cycle(cycle)
    tw = GrindTwin.from_toml(twin if twin else cycle)
    _check_feeds(tw, stages, cycle)
    m = read_measurement(measurement)
    missing = [c for c in ("feed", "fx") if c not in m.signals]
    if m.t is None or missing:
        raise MtwinError(f"{measurement}: a recorded cycle needs the columns t, feed and fx"
                         + (f" (missing: {', '.join(missing)})" if missing else ""))
    ok = np.isfinite(m.signals["feed"]) & np.isfinite(m.signals["fx"])
    if ok.sum() < len(param) + 2:
        raise MtwinError(f"{measurement}: too few complete samples ({int(ok.sum())}) to fit {len(param)} parameter(s)")
    res = fit(tw, stages, m.t[ok], m.signals["feed"][ok], m.signals["fx"][ok], tuple(param))
    if output:
        fitted = tw.with_params(res["values"])
        write_output(cycle_toml(fitted, stages, f"calibrated by mtwin grind calibrate on {measurement}").encode(),
                     output, [cycle])
    if json_out:
        sys.stdout.write(json.dumps(res, indent=1) + "\n")
        return
    for k, v in res["values"].items():
        err.print(f"{k}: {tw[k]:.6g} -> {v:.6g} {BY_NAME[k].unit}", highlight=False)
    err.print(f"normalised RMS of feed and force residuals: {res['rms_before']:.4g} -> {res['rms_after']:.4g}",
              highlight=False)
