"""Housekeeping commands: ``config``, ``effects``, ``cache``, ``materials`` (use cases of ``api.admin``; the cache's of ``warmup``)."""
from __future__ import annotations

from typing import Optional

import typer

from .app import app, err, reports_errors
from .options import EFFECT_FILES, JSON, TWIN
from .render import emit_json

config_app = typer.Typer(help="Twin configuration files.", no_args_is_help=True, rich_markup_mode=None)
app.add_typer(config_app, name="config")


@config_app.command("show")
@reports_errors
def config_show(twin: Optional[str] = TWIN[1]):
    """Print the twin file (the embedded default machine, or --twin FILE with defaults filled in)."""
    import sys

    from ..api.admin import twin_toml

    sys.stdout.write(twin_toml(twin))


@config_app.command("check")
@reports_errors
def config_check(path: str = typer.Argument(..., help="Twin file to validate.")):
    """Validate a twin file: exit 0 if it is valid, 2 with a message naming the key if not."""
    from ..api.admin import check_twin

    err.print(f"{path}: valid ({check_twin(path)})")


effects_app = typer.Typer(help="The physical effects a twin can be given.",
                          invoke_without_command=True, rich_markup_mode=None)
app.add_typer(effects_app, name="effects")


@effects_app.callback()
@reports_errors
def effects_list(ctx: typer.Context, effect_file: Optional[list[str]] = EFFECT_FILES, json_out: bool = JSON):
    """List the effects: name, where it acts, what it changes."""
    from ..api.admin import effects

    found = effects(effect_file)
    if ctx.invoked_subcommand is not None:
        return
    from .render import table

    if json_out:
        emit_json([e.as_dict() for e in found])
        return
    t = table("name", "acts", "what it is", title="effects (mtwin effects show NAME for one)")
    t.columns[0].no_wrap = t.columns[1].no_wrap = True
    for e in found:
        t.add_row(e.name + ("" if e.origin == "built-in" else " (user)"),
                  {"loop": "in the loop", "plan": "before planning"}.get(e.stage, "on observation"), e.description)
    err.print(t)


@effects_app.command("show")
@reports_errors
def effects_show(name: str = typer.Argument(..., help="An effect's name."),
                 effect_file: Optional[list[str]] = EFFECT_FILES):
    """One effect: what it is, how it acts, its parameters with units, bounds and defaults."""
    import sys

    from ..api.admin import effect

    c = effect(name, effect_file)
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
@reports_errors
def cache_warm(quiet: bool = typer.Option(False, "--quiet", help="No progress lines."),
               background: bool = typer.Option(False, "--background", hidden=True,
                                               help="Run as the background warm-up a first run starts.")):
    """Compile every kernel into the cache now (once per install; for container images)."""
    from ..warmup import cache_warm as warm, cache_warm_background

    if background:
        cache_warm_background()
        return
    n, seconds, where = warm(None if quiet else lambda what: err.print(f"warming: {what}"))
    if not quiet:
        err.print(f"{n} kernel(s) compiled in {seconds:.1f} s; cache: {where}")


@cache_app.command("info")
@reports_errors
def cache_info():
    """Where the cache is and how much it holds."""
    import sys

    from ..warmup import cache_info as info

    c = info()
    sys.stdout.write(f"{c.path}\n{c.files} files, {c.bytes / 1e6:.1f} MB\n")


@cache_app.command("clear")
@reports_errors
def cache_clear():
    """Delete the compiled kernels (the next run compiles what it needs again)."""
    from ..warmup import cache_clear as clear

    err.print(f"removed {clear()}")


@app.command("materials")
@reports_errors
def materials(name: Optional[str] = typer.Argument(None, help="One material (any of its names): its constants, "
                                                                   "chip loads and sources."),
              json_out: bool = JSON):
    """The cutting-data catalogue: materials and their sources.

    The names --material and cutting.material take (docs/catalogue.md)."""
    from ..api.admin import materials as catalogue
    from .render import table

    rows = catalogue(name)
    if json_out:
        emit_json(rows if name is None else rows[0])
        return
    if name is None:
        t = table("name", "ISO", "material", ("kc1.1", "right"), ("mc", "right"), ("fz Ø3/6/10/20 mm", "right"),
                  title="materials (mtwin materials NAME for one, with its sources)")
        for r in rows:
            fz = "/".join(f"{r['chip_load'][d]:.3g}" for d in ("3", "6", "10", "20"))
            t.add_row(r["name"], r["iso_group"], r["title"], f"{r['kc11']:g}", f"{r['mc']:g}", fz)
        err.print(t)
        return
    r = rows[0]
    c = r["coefficients"]
    lines = [f"{r['name']}: {r['title']} (ISO {r['iso_group']}); also read as {', '.join(r['names'])}",
             f"Kienzle kc1.1 = {r['kc11']:g} N/mm², mc = {r['mc']:g}: {r['kc_source']}",
             f"the twin's coefficients: Ktc {c['ktc']:.0f}, Krc {c['krc']:.0f}, Kac {c['kac']:.0f} N/mm²; Kte "
             f"{c['kte']:.1f}, Kre {c['kre']:.1f}, Kae {c['kae']:.1f} N/mm — {c['source']}",
             "chip load per tooth (solid carbide): " + ", ".join(f"Ø{d} mm {v:.3g} mm" for d, v in r["chip_load"].items()),
             f"  {r['chip_source']}"]
    import sys

    sys.stdout.write("\n".join(lines) + "\n")
