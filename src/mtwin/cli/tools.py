"""``mtwin tools``: the tool ledger — each physical tool's history, wear and calibrated law."""
from __future__ import annotations

from typing import Optional

import typer

from .app import app, err, reports_errors
from .options import JSON
from .render import emit_json, table

tools_app = typer.Typer(help="The tool ledger: tools, their wear and remaining life.", rich_markup_mode=None,
                        invoke_without_command=True)
app.add_typer(tools_app, name="tools")

LEDGER = typer.Option(..., "--ledger", help="The tool ledger (written by simulate/optimize --record).")
VB_LIMIT = typer.Option(None, "--vb-limit", help="End of a tool's life: flank-wear land in mm (default 0.3, "
                        "ISO 8688-2).")


@tools_app.callback()
@reports_errors
def tools_list(ctx: typer.Context, ledger: str = LEDGER, vb_limit: Optional[float] = VB_LIMIT,
               json_out: bool = JSON):
    """List the ledger's tools: runs, path cut, the land now and the parts left to the limit."""
    from ..api.tools import tools
    from ..api.tools import VB_LIMIT as LIMIT

    limit = vb_limit if vb_limit is not None else LIMIT
    ctx.obj = {"ledger": ledger, "vb_limit": limit, "json": json_out}
    if ctx.invoked_subcommand is not None:  # (its use case checks the limit)
        return
    doc = tools(ledger, vb_limit=limit)
    rows = doc["tools"]
    if json_out:
        emit_json(doc)
        return
    t = table("tool", ("runs", "right"), ("cut m", "right"), ("sliding m", "right"), ("VB mm", "right"),
              ("parts left", "right"), "law", title=f"{ledger}: tools (VB limit {limit:g} mm)")
    for r in rows:
        t.add_row(r["id"], str(r["runs"]), f"{r['length_mm'] / 1000:.3f}", f"{r['sliding_m']:.2f}",
                  "-" if r["vb"] is None else f"{r['vb']:.3f}", "-" if r["parts_left"] is None else str(r["parts_left"]),
                  "calibrated" if r["calibrated"] else "none (the twin's)")
    err.print(t)


@tools_app.command("show")
@reports_errors
def tools_show(ctx: typer.Context, ident: str = typer.Argument(..., help="The tool's id.")):
    """One tool: its runs, its wear law and the calibrations' error falling."""
    from ..api.tools import tool

    o = ctx.obj
    doc = tool(o["ledger"], ident, vb_limit=o["vb_limit"])
    if o["json"]:
        emit_json(doc)
        return
    w, h, runs, cals = doc["wear"], doc["history"], doc["runs"], doc["calibrations"]
    err.print(f"[bold]{doc['id']}[/]: {len(runs)} run(s), {h['length'] / 1000:.3f} m cut, "
              f"{h['sliding']:.2f} m of edge sliding, {h['time']:.1f} s in the cut")
    if doc["law"]:
        err.print(f"law: flank-wear {', '.join(f'{k}={v:g}' for k, v in doc['law'].items())}; land now "
                  f"{w['vb']:.3f} mm, {w['parts_left'] if w['parts_left'] is not None else '?'} part(s) left to "
                  f"VB {w['vb_limit']:g} mm")
    else:
        err.print("law: none calibrated for this tool (calibrate … --ledger FILE --tool-id T3=ID); the twin's applies")
    t = table(("run", "right"), "at", "program", ("T", "right"), ("cut mm", "right"), ("sliding m", "right"),
              ("VB before", "right"), ("VB after", "right"), title="runs")
    for r in runs:
        t.add_row(str(r["n"]), r["at"], r["program"], str(r["tool_number"]), f"{r['length']:.1f}",
                  f"{r['sliding']:.3f}", _mm(r["vb_start"]), _mm(r["vb_end"]))
    err.print(t)
    if cals:
        t = table(("#", "right"), "at", "measurement", "RMS error before → after", title="calibrations")
        for c in cals:
            t.add_row(str(c["n"]), c["at"], c["measurement"],
                      ", ".join(f"{s} {c['rms_before'][s]:.3g} → {c['rms_after'].get(s, float('nan')):.3g}"
                                for s in c["rms_before"]))
        err.print(t)


def _mm(v) -> str:
    return "-" if v is None else f"{v:.3f}"
