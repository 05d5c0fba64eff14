"""Housekeeping commands: ``config``, ``effects``, ``cache``."""
from __future__ import annotations

import contextlib
import os
from pathlib import Path
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

    from ..config import load_twin_file
    from ..twin.files import load_machine
    from ..twin.machine import machine_toml

    sys.stdout.write(machine_toml(load_machine(twin), load_twin_file(twin)))


@config_app.command("check")
@reports_errors
def config_check(path: str = typer.Argument(..., help="Twin file to validate.")):
    """Validate a twin file: exit 0 if it is valid, 2 with a message naming the key if not."""
    from ..config import load_twin_file
    from ..twin.files import load_cutting, load_effects, load_machine

    load_twin_file(path)
    m = load_machine(path)
    load_cutting(path)
    load_effects(path)
    err.print(f"{path}: valid ({m.name})")


effects_app = typer.Typer(help="The physical effects a twin can be given.",
                          invoke_without_command=True, rich_markup_mode=None)
app.add_typer(effects_app, name="effects")


def _load_effect_files(files) -> None:
    from ..effects import load_file

    for f in files or ():
        load_file(f)


@effects_app.callback()
@reports_errors
def effects_list(ctx: typer.Context, effect_file: Optional[list[str]] = EFFECT_FILES, json_out: bool = JSON):
    """List the effects: name, where it acts, what it changes."""
    _load_effect_files(effect_file)
    if ctx.invoked_subcommand is not None:
        return
    from ..effects import BUILTIN, available
    from .render import table

    builtin = {c.name for c in BUILTIN}
    rows = [{"name": n, "stage": c.stage, "origin": "built-in" if n in builtin else "user",
             "description": c.description, "signals": list(c.signals),
             "params": [p.name for p in c.params]} for n, c in available().items()]
    if json_out:
        emit_json(rows)
        return
    t = table("name", "acts", "what it is", title="effects (mtwin effects show NAME for one)")
    t.columns[0].no_wrap = t.columns[1].no_wrap = True
    for r in rows:
        t.add_row(r["name"] + ("" if r["origin"] == "built-in" else " (user)"),
                  {"loop": "in the loop", "plan": "before planning"}.get(r["stage"], "on observation"),
                  r["description"])
    err.print(t)


@effects_app.command("show")
@reports_errors
def effects_show(name: str = typer.Argument(..., help="An effect's name."),
                 effect_file: Optional[list[str]] = EFFECT_FILES):
    """One effect: what it is, how it acts, its parameters with units, bounds and defaults."""
    import sys

    from ..effects import get

    _load_effect_files(effect_file)
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
@reports_errors
def cache_warm(quiet: bool = typer.Option(False, "--quiet", help="No progress lines."),
               background: bool = typer.Option(False, "--background", hidden=True,
                                               help="Run as the background warm-up a first run starts.")):
    """Compile every kernel into the cache now (once per install; for container images)."""
    import time

    from ..warmup import AlreadyWarming, background_lock, cache_dir, compiled_count, set_notices, warm

    if background:
        # the detached warm-up a first run started: low priority, one at a time, silent
        set_notices(None, None)
        with contextlib.suppress(OSError, AttributeError):
            os.nice(10)
        with contextlib.suppress(AlreadyWarming), background_lock():
            warm()
        return
    t0 = time.perf_counter()
    warm(lambda what: None if quiet else err.print(f"warming: {what}"))
    if not quiet:
        err.print(f"{compiled_count()} kernel(s) compiled in {time.perf_counter() - t0:.1f} s; cache: {cache_dir()}")


@cache_app.command("info")
@reports_errors
def cache_info():
    """Where the cache is and how much it holds."""
    import sys

    from ..warmup import cache_dir

    d = Path(cache_dir())
    files = [p for p in d.rglob("*") if p.is_file()] if d.is_dir() else []
    size = sum(p.stat().st_size for p in files)
    sys.stdout.write(f"{d}\n{len(files)} files, {size / 1e6:.1f} MB\n")


@cache_app.command("clear")
@reports_errors
def cache_clear():
    """Delete the compiled kernels (the next run compiles what it needs again)."""
    import shutil

    from ..warmup import cache_dir

    d = Path(cache_dir())
    if d.is_dir():
        shutil.rmtree(d)
    err.print(f"removed {d}")


@app.command("materials")
@reports_errors
def materials(name: Optional[str] = typer.Argument(None, help="One material (any of its names): its constants, "
                                                                   "chip loads and sources."),
              json_out: bool = JSON):
    """The cutting-data catalogue: materials and their sources.

    The names --material and cutting.material take (docs/catalogue.md)."""
    from ..cutting import catalogue as C
    from .render import table

    cat = C.catalogue()
    keys = [C.resolve(name, "mtwin materials")] if name is not None else list(cat.materials)
    rows = []
    for k in keys:
        m = cat.materials[k]
        co = C.material_coefficients(k)
        rows.append({"name": k, "title": m.title, "iso_group": m.iso, "names": list(m.names), "kc11": m.kc11,
                     "mc": m.mc, "kc_source": cat.source_text(m.kc_source),
                     "coefficients": {"ktc": co.ktc, "krc": co.krc, "kac": co.kac, "kte": co.kte, "kre": co.kre,
                                      "kae": co.kae, "source": co.source},
                     "chip_load": {f"{d:g}": C.chip_load(k, d) for d in (3.0, 6.0, 10.0, 12.0, 20.0)},
                     "chip_source": C.chip_source(k)})
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
