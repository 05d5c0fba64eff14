"""The model-against-measurement loop: ``import``, ``synth``, ``compare``, ``diagnose``,
``calibrate``, ``journal``."""
from __future__ import annotations

import math

from typing import Optional

import typer

from ..errors import MtwinError
from .app import app, err, reports_errors
from .argtypes import check_outputs, check_report, names, write_output
from .options import ALIGN, JSON, LOOP, MEASURED_PART, OBJECTIVE, PART, READING, SIGNALS, groups
from .render import emit_json, message, num, say, warn

def _loop_command(short_help: str):
    """A command against a measurement: registered, its errors reported, and the twin and
    measurement options (a TwinSetup ``setup``, a Reading ``reading``)."""

    def decorate(fn):
        return app.command(short_help=short_help)(reports_errors(groups(setup=LOOP, reading=READING)(fn)))

    return decorate


import_app = typer.Typer(help="Read machine logs into the measurement format.", no_args_is_help=True,
                         rich_markup_mode=None)
app.add_typer(import_app, name="import")


@import_app.command("mtconnect", short_help="An MTConnect log (SHDR or agent XML) as a measurement.")
@reports_errors
def import_mtconnect(
    log: str = typer.Argument(..., help="SHDR log (timestamp|item|value) or MTConnectStreams XML."),
    output: str = typer.Option(..., "-o", "--output", help="Measurement file (.csv; '-' for stdout)."),
    run: Optional[int] = typer.Option(None, "--run", help="Which program run of the log (1, 2, …; default: the "
                                                           "last complete one)."),
    block_is: str = typer.Option("line", "--block-is", help="What Block_Number counts: line (the file's line, "
                                                             "default) | n (the N word; needs --program)."),
    program: Optional[str] = typer.Option(None, "--program", help="The program the log ran (for --block-is n)."),
    ignore_item: Optional[list[str]] = typer.Option(None, "--ignore-item", metavar="NAME",
                                                    help="A data item to read past (an unknown item is an error)."),
):
    """Data items logged on change become a time series sampled at every change: t, line,
    feed (mm/min; MTConnect reports mm/s), spindle_speed, and tool and overrides where logged.
    Runs, feed holds and assumptions are listed on stderr and in the file's metadata."""
    from ..api.loop import import_log

    check_outputs(output)
    m = import_log(log, run=run, block_is=block_is, program=program, ignore_items=ignore_item or ())
    m.write(output)
    for key in ("cut_last", "reordered"):
        if key in m.meta:
            say(f"note: {m.meta[key]}")
    for k, r in enumerate(m.runs, 1):
        say(f"run {k}: {r.describe()}")
    held = m.end_time - float(m.meta["cycle_time_s"])
    say(f"run {m.meta['run']}: {len(m.t):,} samples over {m.end_time:.2f} s"
        + (f" ({float(m.meta['cycle_time_s']):.2f} s without the {held:.2f} s it stood: feed holds, program "
           f"stops, a feed override at 0 %)"
           if held > 0.0005 else "") + ", lines "
        f"{int(m.line[m.line > 0].min()) if (m.line > 0).any() else '-'}–{int(m.line.max())}"
        + (f"; overrides {m.meta['overrides']}" if "overrides" in m.meta else ""))


@app.command(short_help="A synthetic measurement: the twin, extra effects, noise.")
@reports_errors
@groups(setup=LOOP)
def synth(
    part: str = PART,
    output: str = typer.Option(..., "-o", "--output", help="Measurement file (.csv, .parquet, or '-')."),
    rate: float = typer.Option(100.0, "--rate", help="Samples per second."),
    noise: float = typer.Option(0.0, "--noise", help="Gaussian noise, a fraction of each signal's RMS (0.02 = 2 %)."),
    signals: Optional[str] = typer.Option(None, "--signals", help="Comma-separated signals (default: positions, "
                                          "spindle speed and power, axis torques, forces)."),
    seed: int = typer.Option(0, "--seed", help="Seed of the noise."),
    no_line: bool = typer.Option(False, "--no-line", help="Leave out the line column (a logger that does not record it)."),
    summary: Optional[str] = typer.Option(None, "--summary", help="line: a summary measurement instead, one row per "
                                          "line the tool cuts on (mean, RMS, max of each signal)."),
    setup=None,
):
    """Write what a machine would record running PART on the twin with extra effects (hidden
    from a plain twin) and sensor noise — for learning and testing compare/diagnose/calibrate."""
    from ..api import synthesize

    check_outputs(output)
    s = synthesize(setup, part, rate=rate, noise=noise, seed=seed, signals=names(signals), line=not no_line,
                   stock=setup.stock_box(), summary=summary, on_message=message)
    s.write(output)
    n = len(next(iter(s.columns.values())))
    err.print(f"wrote {output}: " + (f"{n:,} summary rows, {len(s.columns) - 2} statistic columns" if summary else
                                     f"{n:,} samples at {rate:g} Hz, {len(s.columns) - 1} columns")
              + f"; effects: {s.meta['effects']}", soft_wrap=True)


@_loop_command("Compare the twin with a measurement: errors, and where.")
def compare(
    part: str = MEASURED_PART,
    measurement: str = typer.Argument(..., help="Measurement file (measurement format: CSV or .parquet), or an "
                                                 "MTConnect log (SHDR or agent XML)."),
    align: str = ALIGN,
    xcorr_signal: Optional[str] = typer.Option(None, "--xcorr-signal", help="Signal for --align xcorr."),
    json_out: bool = typer.Option(False, "--json", help="The comparison as JSON on stdout."),
    report: Optional[str] = typer.Option(None, "--report", help="Write a self-contained HTML report (.html)."),
    tooth_resolution: bool = typer.Option(False, "--tooth-resolution",
                                          help="Simulate tooth-passing forces (for a dynamometer's measurement)."),
    setup=None,
    reading=None,
):
    """How far the twin is from a measurement of PART, signal by signal, and the program lines
    where it is farthest."""
    from ..api import compare as run_compare
    from ..api import journal as read_journal
    from ..report.compare_html import compare_html

    check_report(report, stdout_ok=True)
    check_outputs(report)
    c = run_compare(setup, part, measurement, align=align, xcorr_signal=xcorr_signal,
                    tooth_resolution=tooth_resolution, reading=reading, stock=setup.stock_box(), on_message=message)
    if report:
        b = c.result.blocks
        write_output(compare_html(c.result, c.program.path, measurement, read_journal(setup.twin) if setup.twin
                                  else None, blocks=b.as_dict(c.program.text_lines) if b is not None and len(b.measured)
                                  else None, notes=[text for _, text in c.messages]), report, [part, measurement])
        err.print(f"wrote {report}", soft_wrap=True)
    if json_out:
        emit_json(c.as_dict())
        return
    _print_comparison(c, measurement)


def _print_comparison(c, measurement: str) -> None:
    from ..api import signal_unit
    from .render import table

    res, prog, blocks = c.result, c.program, c.result.blocks
    if blocks is not None and len(blocks.measured):
        _print_blocks(blocks.as_dict(prog.text_lines))
    cyc = res.cycle_time
    if cyc["measured"] is None:  # a summary measurement has no clock
        err.print(f"{prog.path} against {measurement}: {len(c.measurement.rows)} summary rows by line range; "
                  f"simulated cycle time {cyc['simulated']:.3f} s", soft_wrap=True)
    else:
        rel = f"{cyc['relative_error']:+.2%}" if cyc["relative_error"] is not None else "-"
        err.print(f"{prog.path} against {measurement}: aligned by {res.alignment}, time offset "
                  f"{res.time_offset:+.3f} s; cycle time measured {cyc['measured']:.3f} s, simulated "
                  f"{cyc['simulated']:.3f} s ({rel})", soft_wrap=True)
    t = table("signal", "unit", *((col, "right") for col in ("RMS", "NRMSE", "max", "bias", "corr.", "samples")),
              title="signals (measured − simulated; RMS, max and bias in the signal's unit)")
    t.columns[0].no_wrap = True
    fmt = lambda v, f: "-" if v is None else format(v, f)  # noqa: E731
    for s, m in res.signals.items():
        t.add_row(s, signal_unit(s), num(m["rms"]), fmt(m["nrmse"], ".2%"), num(m["max_error"]),
                  num(m["bias"], signed=True), fmt(m["correlation"], ".3f"), f"{m['samples']:,}")
    err.print(t)
    if res.worst_regions:
        w = table("signal", "unit", "lines", "RMS", "share", "samples",
                  title="where it fails (share of each signal's squared error)")
        for r in res.worst_regions:
            lines = str(r["first_line"]) if r["first_line"] == r["last_line"] else f"{r['first_line']}–{r['last_line']}"
            w.add_row(r["signal"], signal_unit(r["signal"]), lines, num(r["rms"]), f"{r['share']:.1%}",
                      f"{r['samples']:,}")
        err.print(w)


def _print_blocks(b: dict) -> None:
    from rich.table import Table

    t = Table(title=f"per-block timing: {b['groups']:,} logged block groups, RMS {b['rms']:.3f} s as logged "
                    f"(noise floor ≈ {b['noise_floor_per_group']:.2f} s per group)", title_justify="left")
    from ..report.compare_html import block_kind_table

    # "as logged": the simulation's group boundaries moved by the log's own reporting delays,
    # less what the twin's own run shows logged the same way (loop/blocks.py), the fair sum by
    # kind; the raw one keeps the log's bias between kinds
    cols, rows = block_kind_table(b)
    ratio = cols[-1].startswith("logged F")
    for col in cols:
        t.add_column(col, justify="left" if col == "kind" else "right")
    for row in rows:
        t.add_row(*row)
    err.print(t)
    err.print("  as logged: the simulated groups as a log sampling every "
              f"{b.get('report_period') or 0:.2f} s would show them (a short line is reported late by about half "
              "its length, a long one by half the interval), less what logs of the twin's own run show by kind "
              "(how the groups are cut depends on where the samples fall)"
              + ("; logged F / programmed F: the log's path feed over F in the blocks where the twin runs at F "
                 "for most of the block (80 % of its time: not short blocks or plunges, whose samples fall on "
                 "the ramps), and in brackets the same of logs of the twin's own run sampled alike (what the "
                 "sampling alone makes of it)" if ratio else ""))
    w = Table(title="worst blocks", title_justify="left")
    for col in ("lines", "kind", "measured s", "simulated as logged s", "error s", "G-code"):
        w.add_column(col, justify="right" if col.endswith(" s") else "left")
    for x in b["worst"]:
        lines = f"{x['first_line']}" + (f"–{x['last_line']}" if x["last_line"] != x["first_line"] else "")
        w.add_row(lines, x["kind"], f"{x['measured']:.2f}", f"{x['simulated_as_logged']:.2f}", f"{x['error']:+.2f}", x["text"][:40])
    err.print(w)




@_loop_command("Which physical effect is missing from the twin.")
def diagnose(
    part: str = MEASURED_PART,
    measurement: str = typer.Argument(..., help="Measurement file (measurement format: CSV or .parquet), an "
                                                "MTConnect log (SHDR or agent XML), or a spectrum (freq, amplitude)."),
    signals: Optional[str] = SIGNALS,
    candidates: Optional[str] = typer.Option(None, "--candidates", help="Comma-separated effects to try (default: all "
                                             "not yet in the twin)."),
    objective: str = OBJECTIVE,
    align: str = ALIGN,
    json_out: bool = typer.Option(False, "--json", help="The diagnosis as JSON on stdout."),
    setup=None,
    reading=None,
):
    """For each signal: does the twin fit the measurement, and if not, which effect not yet in
    the twin explains the residual (each fitted alone, ranked by ΔBIC, then several together
    by forward selection).  Against a control's log of its executing line (an MTConnect log):
    which timing effect explains the block times, ranked by the error each removes."""
    from ..api import diagnose as run_diagnose

    d = run_diagnose(setup, part, measurement, signals=names(signals), candidates=names(candidates),
                     objective=objective, align=align, reading=reading, stock=setup.stock_box(), on_message=message)
    if json_out:
        emit_json(d.as_dict())
    elif d.objective == "timing":
        t = d.timing
        c0 = t["before"]["cases"][0]
        verdict = {"fits": "fits: at the noise", "explained": "explained by the effect(s) below",
                   "unexplained": "unexplained: no effect tried removes it"}.get(t["verdict"], t["verdict"])
        err.print(f"[bold]block timing[/bold]: cycle time {c0['cycle_error']:+.2%}; per-group RMS {t['rms']:.3g} s "
                  f"(noise {t['noise']:.2g} s); over {t['before']['windows']} windows: RMS {t['window_rms']:.3g} s "
                  f"(noise {t['window_noise']:.2g} s) — {verdict}", soft_wrap=True)
        for c in t["candidates"]:
            err.print(f"  {c['evidence']}", soft_wrap=True)
    elif d.objective == "chatter":
        _print_chatter(d.chatter)
    else:
        _print_diagnosis(d.signals)


def _print_chatter(ch: dict) -> None:
    for v in ch["spectra"]:
        where = f"lines {v['first_line']}-{v['last_line']}" if v["first_line"] else "the program"
        twin = "" if v.get("twin_margin") is None else (
            f"; the twin predicts {v['twin_margin']:.2f} of the stability limit — "
            + ("it agrees" if v["twin_agrees"] else "it does not agree: its modes or coefficients are off "
               "(a tap test: mtwin calibrate-frf)"))
        if v["chatter"]:
            mode = f", near the {v['nearest_mode']['direction'].upper()} mode at {v['nearest_mode']['fn']:.0f} Hz" \
                if v["nearest_mode"] else ""
            err.print(f"[bold]{where}[/bold] (T{v['tool']}, {v['speed']:.0f} rpm): chatter at "
                      f"{v['chatter_frequency']:.0f} Hz, {v['kind']}{mode} — {v['ratio']:.2g}× the strongest "
                      f"tooth-passing peak{twin}", soft_wrap=True)
        else:
            err.print(f"[bold]{where}[/bold] (T{v['tool']}, {v['speed']:.0f} rpm): no chatter — the peaks are the "
                      f"spindle's harmonics (tooth passing {v['tooth_passing']:.0f} Hz){twin}", soft_wrap=True)


def _print_diagnosis(signals: dict) -> None:
    for s, v in signals.items():
        err.print(f"[bold]{s}[/bold]: RMS {v['rms']:.4g} against noise {v['noise']:.4g} — {v['verdict']}", soft_wrap=True)
        for c in v["candidates"][:3]:
            err.print(f"  {c['evidence']}", soft_wrap=True)
        # the forward selection, where it says more than the single ranking's first line
        if v["selected"] and (len(v["selected"]) > 1 or v["selected"][0]["effect"] != v["candidates"][0]["effect"]):
            chain = " → ".join(f"{x['effect']} (ΔBIC {x['delta_bic']:+.1f})" for x in v["selected"])
            err.print(f"  together: {chain}: residual RMS {v['rms_after']:.4g} against noise {v['noise']:.4g}",
                      soft_wrap=True)


@_loop_command("Fit effects to a measurement; write the twin file.")
def calibrate(
    part: str = MEASURED_PART,
    measurement: str = typer.Argument(..., help="Measurement file (measurement format: CSV or .parquet), or an "
                                                "MTConnect log (SHDR or agent XML)."),
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
    objective: str = OBJECTIVE,
    signals: Optional[str] = SIGNALS,
    align: str = ALIGN,
    json_out: bool = typer.Option(False, "--json", help="The fit as JSON on stdout."),
    setup=None,
    reading=None,
):
    """Fit the --fit effects' parameters (and --param base parameters) to the measurement by
    bounded least squares; write the twin file with them and a journal entry.  Against a
    control's log of its executing line the fit is to the block times (--objective timing),
    over every PART MEASUREMENT pair given."""
    from ..api import calibrate as run_calibrate

    if more and len(more) % 2:
        raise MtwinError(f"more programs come in pairs PART MEASUREMENT: {more[-1]} has no measurement")
    check_outputs(output)
    cal = run_calibrate(setup, part, measurement, fit=fit_effect or (), params=param or (),
                        more=list(zip((more or [])[::2], (more or [])[1::2])), validate=validate, refit=refit,
                        objective=objective, signals=names(signals), align=align, reading=reading,
                        stock=setup.stock_box(), on_message=message)
    cal.write(output)
    if json_out:
        emit_json({**cal.as_dict(), "twin_file": output})
    else:
        _print_calibration(cal, output)


def _print_calibration(cal, output: str) -> None:
    from ..api import param_unit, signal_unit

    res = cal.result
    blind = getattr(res, "not_identifiable", [])
    unreached = getattr(res, "unreached", {})
    for k, v in res.params.items():
        u = res.uncertainty.get(k)
        unit = param_unit(k)
        unit = f" {unit}" if unit and unit not in ("1", "int", "bool", "str") else ""
        read = k in getattr(res, "rapid_rates", {})
        err.print(f"{k} = {v:.6g}" + (f" ± {u:.2g}" if u is not None and math.isfinite(u) else "") + unit
                  + (" (read off the logged rapids)" if read else "")
                  + (" (not identifiable from the signals fitted: left at its start)" if k in blind else "")
                  + (" (no standard deviation: the logs hardly bound it — a value where the search stopped, "
                     "not a measured one)" if (u is None or not math.isfinite(u)) and k not in blind
                     and k not in unreached and not read else "")
                  + (f" (no logged block reaches this limit: any value from {v:.4g} up fits the logs as well, "
                     f"the search had left it at {unreached[k]['fitted']:.4g}; set at the least, so that the twin "
                     f"promises no speed the logs have not shown)" if k in unreached else ""),
                  soft_wrap=True)
    if cal.base_params:
        err.print(f"note: the fitted base parameters are written into {output}'s sections (the file is written "
                  f"back from its parsed form: its comments are not kept, but its opening comment block is)",
                  soft_wrap=True)
    for s_ in res.rms_before:
        unit = " s" if s_ == "window_time" else (f" {signal_unit(s_)}" if signal_unit(s_) else "")
        err.print(f"{s_}: RMS {res.rms_before[s_]:.4g}{unit} → {res.rms_after[s_]:.4g}{unit} (noise "
                  f"{res.noise[s_]:.4g}{unit})", soft_wrap=True, markup=False)
    if cal.objective == "timing":
        for b_, a_ in zip(res.before["cases"], res.after["cases"]):
            err.print(f"{a_['measurement']}: cycle time {b_['cycle_error']:+.2%} → {a_['cycle_error']:+.2%} "
                      f"(measured {a_['cycle_measured']:.1f} s, simulated {a_['cycle_simulated']:.1f} s); "
                      f"windows RMS {b_['window_rms']:.3g} → {a_['window_rms']:.3g} s; per-group RMS "
                      f"{b_['rms']:.3g} → {a_['rms']:.3g} s", soft_wrap=True)
            if b_["rms"] > 0 and a_["rms"] > 1.2 * b_["rms"]:
                warn(f"{a_['measurement']}: the per-group RMS rose by {a_['rms'] / b_['rms'] - 1:.0%}: the fit holds "
                     f"~10-s windows of blocks and the sums by block kind, and here trades single block groups for "
                     f"them — the effect times the right total on other lines than the machine's (mtwin compare "
                     f"--twin {output} lists the worst blocks)")
    v = cal.validation
    if v:
        err.print(f"validation on {v['measurement']}: " + ", ".join(
            f"{k} {x:+.2%}" if k == "cycle_error" else f"{k} RMS {x:.4g}"
            for k, x in v.items() if k != "measurement"), soft_wrap=True)
    err.print(f"wrote {output} ({res.evaluations} evaluations)", soft_wrap=True)


@app.command(short_help="The model journal of a twin file: the error across calibrations.")
@reports_errors
def journal(path: str = typer.Argument(..., help="Twin file."), json_out: bool = JSON):
    """Each calibration of the twin file: effects fitted, values, and the RMS error before and after."""
    from ..api.loop import journal as read_journal
    from .render import table

    j = read_journal(path)
    if json_out:
        emit_json(j)
        return
    if not j:
        err.print(f"{path}: no journal yet (mtwin calibrate … -o {path} writes one)")
        return
    err.print(f"{path}: model journal", soft_wrap=True, highlight=False)
    t = table("#", "effects", "measurement", "RMS before → after")
    for e in j:
        rms = ", ".join(f"{s} {e['rms_before'][s]:.4g} → {e['rms_after'][s]:.4g}" for s in e.get("rms_before", {}))
        cyc = e.get("cycle_error_before", {})
        if cyc:
            rms += "; cycle time " + ", ".join(f"{cyc[k]:+.1%} → {e['cycle_error_after'].get(k, float('nan')):+.1%}"
                                                for k in cyc)
        t.add_row(str(e.get("iteration")), ", ".join(e.get("effects", [])), str(e.get("measurement", "")), rms)
    err.print(t)
