"""``mtwin optimize``: F and S chosen under the load and machine limits, the program written
back, proven and re-simulated."""
from __future__ import annotations

from typing import Optional

import typer

from ..errors import MtwinError
from .app import app, err, reports_errors
from .argtypes import check_outputs, check_report, value_range, write_output
from .options import PART, Group, groups, twin_options
from .render import emit_json, message


def _ga_options(**values):
    from ..optimize import GAOptions

    return GAOptions(**values)


# the genetic algorithm's options, as one GAOptions
GA = Group({"seed": (int, typer.Option(0, "--seed", help="GA random seed (same seed, same result).")),
            "population": (int, typer.Option(60, "--population", help="GA population size.")),
            "generations": (int, typer.Option(200, "--generations", help="GA generation limit."))}, _ga_options)


def _limit_options(force_limit, chip_limit, tolerance, rough_tolerance, finish_feed, ramp_feed, limits,
                   limit_scale) -> dict:
    from ..optimize import parse_force_limit

    return {"force_limit": parse_force_limit(force_limit) if force_limit is not None else None,
            "chip_limit": chip_limit, "tolerance": tolerance, "rough_tolerance": rough_tolerance,
            "finish_feed": finish_feed, "ramp_feed": ramp_feed, "limits": limits, "limit_scale": limit_scale}


# the command's own options (declared apart, as HTTPie declares its own)
OUTPUT = typer.Option(..., "-o", "--output", help="Optimised program ('-' for stdout).")
OBJECTIVE = typer.Option("time", "--objective", help="time | cost | smooth | air.")
METHOD = typer.Option("bisect", "--method", help="bisect (per-segment bisection) | ga (genetic algorithm).")
FORCE_LIMIT = typer.Option(None, "--force-limit",
                           help="Cutting-load limit, N, for every tool (60) or per tool (T1=40,T3=120; "
                           "the others learned). Default: learned per tool from the program — the load "
                           "and chip thickness it already runs at. A feed goes below the program's own "
                           "only where the program breaks a given limit.")
CHIP_LIMIT = typer.Option("learned", "--chip-limit", help="learned (each tool's chip thickness held to the "
                          "program's own level, with a given --force-limit too) | none.")
ROUGH_TOLERANCE = typer.Option(None, "--rough-tolerance", help="Contour error, mm, a roughing segment (one whose "
                               "surface later passes cut again) may gain over the program's own (default 0.1, "
                               "or --tolerance where larger).")
RAMP_FEED = typer.Option("keep", "--ramp-feed", help="keep (ramps and helical entries keep their feed, as "
                         "plunges do) | optimize.")
FEED_RANGE = typer.Option(None, "--feed-range", help="LOW,HIGH mm/min (default: 10 % of the "
                          "lowest F up to the machine's maximum cutting feed).")
SPINDLE_RANGE = typer.Option(None, "--spindle-range",
                             help="LOW,HIGH rpm: also choose S (per tool); without it S stays.")
SPINDLE_PER = typer.Option("tool", "--spindle-per", help="tool | segment (needs --allow-s-changes).")
ALLOW_S_CHANGES = typer.Option(False, "--allow-s-changes", help="Allow S words in mid-tool.")
TARGET_POWER = typer.Option(None, "--target-power",
                            help="smooth: target mean cutting power per segment, W "
                            "(default: the 75th percentile of the segments').")
TOLERANCE = typer.Option(0.02, "--tolerance", help="Contour error, mm, a segment that leaves a final "
                         "surface (a finishing pass) may gain over the program's own on the re-simulated twin.")
POWER_TOLERANCE = typer.Option(0.05, "--power-tolerance",
                               help="smooth: relative tolerance K on the target power.")
FINISH_FEED = typer.Option("auto", "--finish-feed", help="auto (finishing passes keep their feed per tooth, "
                           "except a tool held to limits from physics: its chip load with radial chip thinning and "
                           "the deflection allowed on a final surface) | keep | optimize (treat them as any cut).")
SEGMENTATION = typer.Option("cluster", "--segmentation",
                            help="cluster (sequential clustering) | changepoint (binary segmentation).")
MIN_SEGMENT = typer.Option(5.0, "--min-segment", help="Shortest segment C, mm of path.")
# what the answer is held to: the load and chip limits, the accuracy, what keeps its feed
LIMITS_FROM = typer.Option("auto", "--limits", help="auto (from physics — the catalogue's chip load, the shank's "
                           "strength and stiffness — once the material is named: --material, cutting.material or "
                           "the program's comments; else learned from the program) | learned | physics.")
LIMIT_SCALE = typer.Option(1.0, "--limit-scale", help="Take this share of each physics limit (0.8: a cautious "
                           "80 % of the catalogue).")
LIMITS = Group({"force_limit": (Optional[str], FORCE_LIMIT), "chip_limit": (str, CHIP_LIMIT),
                "tolerance": (float, TOLERANCE), "rough_tolerance": (Optional[float], ROUGH_TOLERANCE),
                "finish_feed": (str, FINISH_FEED), "ramp_feed": (str, RAMP_FEED), "limits": (str, LIMITS_FROM),
                "limit_scale": (float, LIMIT_SCALE)}, _limit_options)
REPORT = typer.Option(None, "--report", help="Write a self-contained HTML report (.html).")
JSON_OUT = typer.Option(False, "--json", help="Result as JSON on stdout.")
IN_PLACE = typer.Option(False, "--in-place", help="Allow -o to be the input file.")
CHATTER_MARGIN = typer.Option(0.8, "--chatter-margin", help="With tools whose modes or FRF the twin knows: hold "
                              "every cut's axial depth at most this share of the stability limit at its speed "
                              "(docs/chatter.md); S moves into stable pockets with --spindle-range.")
CHATTER_METHOD = typer.Option("auto", "--chatter-method", help="zoa | sdm | auto: how the lobes are computed.")
LAYERS = typer.Option("off", "--layers", help="off | auto: a cut over a given limit even at the lowest feed is "
                      "re-cut in layers of equal depth (the fewest that meet it, up to --max-layers), proven to "
                      "leave the same part (docs/optimize.md, depth layering).")
MAX_LAYERS = typer.Option(None, "--max-layers", help="With --layers auto: at most this many layers per cut "
                          "(default 8); alone, it turns layering on.")
RECORD = typer.Option(False, "--record", help="Add the optimised program's run to the --ledger tools' history.")


@app.command(short_help="Optimise F and S under the load and machine limits.")
@reports_errors
@groups(setup=twin_options(stock=True, planner=True, tools=True, ledger=True), ga=GA, limits=LIMITS)
def optimize(
    part: str = PART,
    output: str = OUTPUT,
    objective: str = OBJECTIVE,
    method: str = METHOD,
    feed_range: Optional[str] = FEED_RANGE,
    spindle_range: Optional[str] = SPINDLE_RANGE,
    spindle_per: str = SPINDLE_PER,
    allow_s_changes: bool = ALLOW_S_CHANGES,
    target_power: Optional[float] = TARGET_POWER,
    power_tolerance: float = POWER_TOLERANCE,
    segmentation: str = SEGMENTATION,
    min_segment: float = MIN_SEGMENT,
    report: Optional[str] = REPORT,
    json_out: bool = JSON_OUT,
    in_place: bool = IN_PLACE,
    record: bool = RECORD,
    chatter_margin: float = CHATTER_MARGIN,
    chatter_method: str = CHATTER_METHOD,
    layers: str = LAYERS,
    max_layers: Optional[int] = MAX_LAYERS,
    setup=None, ga=None, limits=None,
):
    """Segment the predicted power curve, choose F (and S) per segment for the objective under
    the load, power, torque and feed limits, write the program through the byte-preserving
    writer, prove it cuts the same path and check the limits on its re-simulation."""
    from ..optimize import InfeasibleError, OptimizeOptions, record_optimised
    from ..report.optimize_html import optimize_html

    _check_outputs(output, report, json_out)
    if record and not setup.ledger:
        raise MtwinError("--record adds the run to a tool ledger: give --ledger FILE and --tool-id T3=ID")
    opts = OptimizeOptions(objective, method, feed_range=value_range(feed_range, "--feed-range"),
                           spindle_range=value_range(spindle_range, "--spindle-range"), spindle_per=spindle_per,
                           allow_s_changes=allow_s_changes, target_power=target_power,
                           power_tolerance=power_tolerance, segmentation=segmentation, min_segment=min_segment, ga=ga,
                           chatter_margin=chatter_margin, chatter_method=chatter_method, max_layers=_max_layers(layers, max_layers),
                           tradeoff_resimulated=report is not None, **limits)
    try:
        res = _run_with_progress(setup, part, opts, ga.generations if method == "ga" else 0)
    except InfeasibleError as exc:
        if json_out:  # (what was refused, as data, before the message on stderr)
            emit_json({"program": exc.program, "objective": objective, "method": method, "written": False,
                       "error": str(exc), "reasons": exc.reasons}, indent=1)
        raise
    for w in res.warnings:
        message("warning", w)
    write_output(res.output, output, [part], in_place)
    if record:  # the optimised program's run, as re-simulated, into the tools' history
        record_optimised(setup, res, output)
    path = res.program.path
    if report:
        write_output(optimize_html(res, path), report, [part])
    if json_out:
        emit_json(res.as_dict(path), indent=1)
        return
    _print_optimize(res, path)


def _max_layers(layers: str, max_layers) -> int:
    """--layers and --max-layers as OptimizeOptions.max_layers (0: off)."""
    from ..optimize import MAX_LAYERS

    if layers not in ("off", "auto"):
        raise MtwinError(f"--layers must be off or auto, got {layers!r}")
    if layers == "off" and max_layers is None:
        return 0
    return MAX_LAYERS if max_layers is None else max_layers


def _check_outputs(output: str, report, json_out: bool) -> None:
    if output == "-" and json_out:
        raise MtwinError("-o - and --json both write to stdout: give the program a file name, or leave out --json")
    check_report(report, output)
    check_outputs(output, report)


def _run_with_progress(setup, part, opts, generations: int):
    """Run the optimiser with a transient progress display on a terminal's stderr (the stage,
    and the GA's generations), shown once the run has taken a second; plain otherwise."""
    from ..optimize import optimize

    stock = setup.stock_box()
    if not err.is_terminal:
        return optimize(setup, part, opts, stock=stock, on_message=message)
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
        return optimize(setup, part, opts, stock=stock, progress=ga if generations else None, stage=stage,
                        on_message=message)
    finally:
        timer.cancel()
        with lock:
            state["done"] = True
            if state["shown"]:
                bar.stop()


def _print_optimize(res, path: str) -> None:
    from ..optimize import line_ranges

    b, a = res.before, res.after
    verdict, change = res.verdict

    def pct(x, y):
        return f"{(y / x - 1) * 100:+.1f} %" if x else "—"

    from rich.table import Table

    err.print(f"{path}: {res.objective} by {res.method}", soft_wrap=True, highlight=False)
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
        src = lim["source"]
        if src == "physics":
            src = (f"physics: {lim['material']} from {lim['material_from']}; shank breakage, catalogue chip load; "
                   f"{lim['deflection_load']:.1f} N on final surfaces (deflection {lim['deflection_tolerance']:g} mm)"
                   + (f", x {lim['scale']:g}" if lim["scale"] != 1.0 else ""))
        err.print(f"limits T{lim['tool']}: load {lim['load']:.1f} N{chip} ({src})", highlight=False,
                  soft_wrap=True)
    if res.tradeoff_scale:
        pts = [x for x in res.tradeoff_scale if x["resimulated"] is not None] or res.tradeoff_scale
        err.print("at a share of the physics limits: " + ", ".join(
            f"{x['scale']:.0%} {x['resimulated'] if x['resimulated'] is not None else x['estimate']:.2f} s"
            for x in pts) + (" (re-simulated)" if pts[0]["resimulated"] is not None else " (estimated)"),
            highlight=False, soft_wrap=True)
    if res.spindle:
        err.print("spindle speed chosen: " + ", ".join(f"T{k}: S{v:.0f}" for k, v in res.spindle.items()),
                  highlight=False)
    for why, lines in res.kept.items():
        err.print(f"kept their feeds ({why}): {len(lines)} line(s)", highlight=False, soft_wrap=True)
    if res.air_entries:
        air = res.air_entries
        err.print(f"plunges through proven air: {len(air)} run their upper part at the air feed and their own feed "
                  f"from just above the material (lines {line_ranges([x['line'] for x in air])})",
                  highlight=False, soft_wrap=True)
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
                      f"{len(top)} segment(s), lines {line_ranges(lines)}", highlight=False, soft_wrap=True)
    for d in res.defaults:
        err.print(f"note: {d}", soft_wrap=True, highlight=False, markup=False)
    if res.segments:
        # (every written answer holds it: the optimiser proves it per segment before writing)
        tol = f"{ce.get('tolerance', 0):g} mm on final surfaces, {ce.get('rough_tolerance', 0):g} mm roughing"
        err.print(f"{len(res.segments)} segments, {len(res.changed_lines)} changed line group(s); verified: same path; "
                  + f"limits and contour tolerance ({tol}) held"
                  + " on the re-simulated program "
                  f"({res.rounds} round(s)); estimate {res.estimate['cycle_time']:.2f} s vs re-simulated "
                  f"{a.cycle_time:.2f} s; {res.evaluations} evaluations in {res.seconds:.1f} s", soft_wrap=True,
                  highlight=False)
    else:
        err.print(f"nothing changed; written as it was ({res.seconds:.1f} s)", highlight=False)
