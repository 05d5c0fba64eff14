"""``mtwin batch optimize|simulate|compare|calibrate``: one command over many programs × twin
files, on Dask (a local cluster, or an existing one) or one by one in this process.

Options the batch does not know are the command's own and apply to every job (checked by the
command's own parser before anything runs); a manifest's ``options`` column adds a job's own.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Optional

import typer

from ..errors import MtwinError
from .app import app, err, reports_errors
from .render import emit_json, say

batch_app = typer.Typer(help="Run a command over many programs × twin files (a fleet), on Dask or one by one.",
                        no_args_is_help=True, rich_markup_mode=None)
app.add_typer(batch_app, name="batch", short_help="Run a command over many programs × machines, on Dask.")

EXTRA = {"allow_extra_args": True, "ignore_unknown_options": True, "help_option_names": ["-h", "--help"]}
MANIFEST = typer.Option(None, "--manifest", help="Jobs as CSV (header: program, twin[, measurement, options, name]) "
                        "or TOML ([[job]] tables); relative paths are read from the manifest's folder.")
OUT_DIR = typer.Option(..., "-o", "--output", help="Output folder: one subfolder per job, summary.csv, summary.json, "
                       "index.html.")
TWINS = typer.Option(None, "--twin", help="Twin file (repeatable: every program on every twin file).")
MEASUREMENTS = typer.Option(None, "--measurement", help="compare/calibrate: each program's measurement, in order "
                            "(repeatable).")
WORKERS = typer.Option(None, "--workers", help="Local Dask workers, one single-threaded process each (default: one per "
                       "core; 0: one job at a time in this process).")
SCHEDULER = typer.Option(None, "--scheduler", help="An existing Dask scheduler's address, e.g. tcp://host:8786.")
SCHEDULER_FILE = typer.Option(None, "--scheduler-file", help="An existing Dask cluster's scheduler file.")
RETRIES = typer.Option(1, "--retries", help="Times a job is run again after its worker died (or the task failed).")
JSON_OUT = typer.Option(False, "--json", help="The jobs and the summary as JSON on stdout.")
RECIPE = typer.Option(None, "--recipe", help="calibrate: a procedure of steps ([[step]] options = \"--fit …\"), "
                      "each from the twin file the step before wrote, run on every machine (docs/fleet.md).")


def _command(name: str):
    @batch_app.command(name, context_settings=EXTRA, short_help=f"mtwin {name} over many programs × twin files.",
                       options_metavar=f"[OPTIONS] [PROGRAM]... [MTWIN-{name.upper()} OPTIONS]")
    @reports_errors
    def command(ctx: typer.Context, manifest: Optional[str] = MANIFEST, output: str = OUT_DIR,
                twin: Optional[list[str]] = TWINS, measurement: Optional[list[str]] = MEASUREMENTS,
                workers: Optional[int] = WORKERS, scheduler: Optional[str] = SCHEDULER,
                scheduler_file: Optional[str] = SCHEDULER_FILE, retries: int = RETRIES, json_out: bool = JSON_OUT,
                recipe: Optional[str] = RECIPE):
        from ..fleet import check_out_dir, choose_runner, read_batch_jobs
        from .batchargs import check_common, split_args

        programs, common = split_args(name, ctx.args)
        jobs = read_batch_jobs(name, manifest, programs, twin or (), measurement or ())
        check_common(name, common)
        for j in {j.options: j for j in jobs if j.options}.values():  # each job's own, before anything runs
            check_common(name, common + list(j.options), f"{j.origin}: options")
        jobs = _with_recipe(name, jobs, recipe, common)
        if name == "calibrate":  # the held-out comparisons take the options compare knows
            from .batchargs import shared_options

            jobs = [replace(j, compare_options=shared_options("compare", common + list(j.options), name))
                    for j in jobs]
        if retries < 0:
            raise MtwinError(f"--retries {retries}: give 0 or more")
        check_out_dir(output, jobs, [manifest, recipe])
        import time

        jobs = [replace(j, date_epoch=int(time.time())) for j in jobs]
        runner = choose_runner(workers, scheduler, scheduler_file, retries, len(jobs), say)
        try:
            b = _run(name, jobs, output, tuple(common), runner)
        finally:
            if runner is not None:
                runner.close()
        if json_out:
            emit_json(b.as_dict(), indent=1)
        _print_batch(b)
        raise typer.Exit(b.exit_code)

    command.__doc__ = (f"Run `mtwin {name}` on every job — programs (files, folders, patterns) × --twin files, or a "
                       f"--manifest — writing each job's outputs into its own folder of -o, and a summary. Other "
                       f"options are `mtwin {name}`'s and apply to every job. Exit 0: every job ok; 1: some failed or "
                       f"were refused; 2: bad input (nothing is written).")
    return command


for _name in ("optimize", "simulate", "compare", "calibrate"):
    _command(_name)


def _with_recipe(name, jobs, recipe, common):
    if recipe is None:
        return jobs
    if name != "calibrate":
        raise MtwinError("--recipe is a calibration procedure: batch calibrate")
    from ..fleet import read_recipe
    from .batchargs import check_common

    steps = read_recipe(recipe)
    for k, opts in enumerate(steps, start=1):
        check_common(name, list(common) + list(opts), f"{recipe}: step {k}")
    return [replace(j, steps=steps) for j in jobs]


def _run(name, jobs, output, common, runner):
    """The batch with a progress display: a bar with done/failed and the time left on a
    terminal, a line per finished job otherwise."""
    from ..fleet import run_batch
    from . import run_command

    say(f"{len(jobs)} job(s) on {runner.describe() if runner is not None else 'this process, one at a time'}")
    counts = {"done": 0, "bad": 0}
    if not err.is_terminal:
        def line(o):
            counts["done"] += 1
            say(f"[{counts['done']}/{len(jobs)}] {o.name}: {o.status}" + (f" ({o.error})" if o.error else "")
                + f", {o.seconds:.1f} s")

        return run_batch(name, jobs, output, run_command, common, runner, on_done=line)
    import sys

    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    # the bar on this process's stderr as it is now: a job run in this process captures
    # sys.stderr for its command, and the bar must not draw into the job's log
    screen = Console(file=sys.stderr)
    with Progress(TextColumn(f"batch {name}"), BarColumn(), MofNCompleteColumn(), TextColumn("{task.fields[bad]}"),
                  TimeRemainingColumn(), console=screen, transient=True, redirect_stdout=False,
                  redirect_stderr=False) as bar:
        task = bar.add_task(name, total=len(jobs), bad="")

        def tick(o):
            counts["bad"] += o.status != "ok"
            bar.update(task, advance=1, bad=f"{counts['bad']} failed" if counts["bad"] else "")

        return run_batch(name, jobs, output, run_command, common, runner, on_done=tick)


def _print_batch(b) -> None:
    from ..report.fleet_html import FIGURES
    from .render import table

    cols = FIGURES[b.command]
    t = table("job", "status", *((h, "right") for h, _, _ in cols), ("s", "right"),
              title=f"batch {b.command}: {b.out_dir}")
    for r in b.rows():
        t.add_row(r["job"], r["status"], *("" if r[k] is None else fmt.format(r[k]) for _, k, fmt in cols),
                  f"{r['seconds']:.1f}")
    err.print(t)
    if b.command == "calibrate":
        _print_parameters(b)
    s = b.summary()
    for r in b.rows():
        if r["status"] != "ok":
            say(f"{r['job']} {r['status']}: {r['error']}")
    saved = (f"; cycle time saved {s['cycle_saved_s']:.1f} s ({s['cycle_saved_pct']:.1f} %)"
             if s["cycle_saved_s"] is not None and b.command == "optimize" else "")
    say(f"{s['ok']} ok, {s['failed']} failed, {s['refused']} refused" + (f", {s['not run']} not run (interrupted)"
                                                                           if s["not run"] else "")
        + f" in {s['seconds']:.1f} s{saved}; summary: {b.out_dir}/index.html")


def _print_parameters(b) -> None:
    """The fleet table: each fitted parameter per machine, with its ratio to the fleet's median
    where the fleet has three machines or more (the machine that differs stands out)."""
    from .render import table

    rows = b.fleet_table()
    if not rows:
        return
    machines = list(b.fitted())
    held = {r["job"]: r["holdout_error_pct"] for r in b.rows()}
    title = "fitted per machine" + (" (± sd, × the fleet's median)" if len(machines) > 2 else " (± sd)")
    t = table("parameter", *((m, "right") for m in machines), title=title)
    for row in rows:
        cells = []
        for m in machines:
            x = row["machines"].get(m)
            cells.append("—" if x is None else ("≥ " if x.get("at_least") else "") + f"{x['value']:.4g}"
                         + ("" if x["sd"] is None else f" ± {x['sd']:.2g}")
                         + ("" if x["ratio"] is None else f" ({x['ratio']:.2f}×)"))
        t.add_row(row["parameter"], *cells)
    if any(v is not None for v in held.values()):
        t.add_row("held-out cycle error", *("" if held.get(m) is None else f"{held[m]:+.2f} %" for m in machines))
    err.print(t)
    if any(x.get("at_least") for row in rows for x in row["machines"].values()):
        err.print("  ≥: a limit no logged block of that machine reaches, set at the least value its logs allow",
                  soft_wrap=True)
