"""``mtwin lobes`` and ``mtwin calibrate-frf``: a tool's stability lobes, and its modes fitted
to a tap test (docs/chatter.md)."""
from __future__ import annotations

from typing import Optional

import typer

from .app import app, err, reports_errors
from .argtypes import check_outputs, value_range, write_output
from .options import JSON
from .render import emit_json


@app.command(short_help="Stability lobes of a tool: axial depth limit against spindle speed.")
@reports_errors
def lobes(
    twin: str = typer.Option(..., "--twin", help="Twin file with the tool's [[tools.N.modes]] or tools.N.frf."),
    tool: int = typer.Option(1, "--tool", help="Tool number."),
    immersion: Optional[float] = typer.Option(None, "--immersion", help="Radial immersion ae/D, (0, 1] (default 1: "
                                              "a slot)."),
    ae: Optional[float] = typer.Option(None, "--ae", help="Radial width of cut, mm (instead of --immersion)."),
    milling: str = typer.Option("down", "--milling", help="down | up."),
    feed_direction: str = typer.Option("x", "--feed-direction", help="x | y | -x | -y | ANGLE (degrees from +X)."),
    speed_range: Optional[str] = typer.Option(None, "--speed-range", help="LO,HI rpm (default: a tenth of the "
                                              "spindle's maximum up to it)."),
    method: str = typer.Option("auto", "--method", help="zoa (zero-order approximation) | sdm "
                               "(semi-discretisation) | auto (sdm where the arc is under a third of the pitch)."),
    points: int = typer.Option(0, "--points", help="Speeds on the grid (default 500 zoa, 200 sdm; the minima are "
                               "refined further)."),
    steps: int = typer.Option(40, "--steps", help="sdm: steps over the cut window of a tooth period."),
    plot: Optional[str] = typer.Option(None, "--plot", help="Write the lobes as .svg, .png or .pdf."),
    json_out: bool = JSON,
):
    """The limiting axial depth of a straight cut against spindle speed, from the tool's modes
    (or measured FRF) and the twin's cutting coefficients: the stable pockets are the peaks."""
    from ..api.chatter import lobes_plot, stability_lobes
    from ..report.plots import plot_format

    fmt = plot_format(plot) if plot else None
    if plot:
        check_outputs(plot)
    res = stability_lobes(twin, tool=tool, immersion=immersion, ae=ae, milling=milling,
                          feed_direction=feed_direction, speed_range=value_range(speed_range, "--speed-range"),
                          method=method, points=points, steps=steps)
    if plot:
        write_output(lobes_plot(res, fmt), plot, [twin])
    for n in res.notes:
        err.print(f"note: {n}", highlight=False)
    if json_out:
        emit_json(res.as_dict())
        return
    import numpy as np

    d = res.depth_limit
    i = int(np.nanargmin(np.where(np.isfinite(d), d, np.nan))) if np.isfinite(d).any() else 0
    cut = "a slot" if res.cut.immersion > 0.999 else f"ae/D {res.cut.immersion:.3g} ({milling} milling)"
    err.print(f"T{tool}, {cut}, {res.method}: the lowest limit "
              f"{d[i]:.3f} mm at {res.speeds[i]:.0f} rpm (chatter at {res.chatter_frequency[i]:.0f} Hz"
              f"{', a flip lobe' if res.flip[i] else ''})", highlight=False)
    pk = res.pockets(5)
    if pk:
        err.print("stable pockets (lobe peaks): " + ", ".join(f"{s:.0f} rpm → {a:.2f} mm" for s, a in pk),
                  highlight=False)
    if res.flip.any():
        err.print(f"flip (period-doubling) lobes limit {int(res.flip.sum())} of the {len(d)} speeds", highlight=False)


@app.command("calibrate-frf", short_help="Fit a tool's modes to a tap test's FRF.")
@reports_errors
def calibrate_frf(
    frf: str = typer.Argument(..., help="Tap-test FRF: CSV (freq, re_xx, im_xx, re_yy, im_yy; m/N) or CutPro text."),
    modes: int = typer.Option(2, "--modes", help="Most modes per direction."),
    tool: int = typer.Option(1, "--tool", help="Tool number of the [[tools.N.modes]] tables printed."),
    json_out: bool = JSON,
):
    """Peak picking, then least squares on the compliance: the modes as [[tools.N.modes]]
    tables for the twin file (stdout), each parameter with its standard deviation (stderr)."""
    from ..api.chatter import calibrate_frf as fit

    res = fit(frf, modes_per_direction=modes)
    if json_out:
        emit_json(res.as_dict())
        return
    for m, s in zip(res.modes, res.sigma):
        err.print(f"{m.direction.upper()}: fn {m.fn:.2f} ± {s['fn']:.2f} Hz, ζ {m.zeta:.4f} ± {s['zeta']:.4f}, "
                  f"k {m.k:.4g} ± {s['k']:.2g} N/m", highlight=False)
    err.print("relative RMS residual: " + ", ".join(f"{d.upper()} {v:.3g}" for d, v in res.rms.items()),
              highlight=False)
    typer.echo(res.toml(tool))

