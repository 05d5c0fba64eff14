"""Plots of a simulated trace, as SVG, PNG or PDF (matplotlib, no display needed)."""
from __future__ import annotations

import io

import numpy as np

from ..layout import C_POWER

FORMATS = ("svg", "png", "pdf")


def plot_format(path: str) -> str:
    """The file format a plot's name asks for (``-``, standard output, is SVG)."""
    if path == "-":
        return "svg"
    ext = path.rsplit(".", 1)[-1].lower() if "." in path.rsplit("/", 1)[-1] else ""
    if ext not in FORMATS:
        from ..errors import MtwinError

        raise MtwinError(f"--plot {path}: the file name must end in .svg, .png or .pdf")
    return ext


def power_svg(trace, title: str = "", fmt: str = "svg") -> bytes:
    """Spindle power against time, with the program line being executed on a secondary axis
    at the top (ticks where the peak-power line and other landmarks are)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if trace.cut is None:
        from ..errors import MtwinError

        raise MtwinError("--plot needs the cutting model (do not combine it with --no-cutting)")
    t = np.asarray(trace.t)
    power = np.asarray(trace.cut[:, C_POWER], dtype=float)
    fig, ax = plt.subplots(figsize=(10, 4), dpi=100)
    ax.plot(t, power, lw=0.8, color="#1f5fa8", label="spindle power")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("spindle power [W]")
    ax.grid(True, alpha=0.3)
    ax.set_xlim(t[0] if len(t) else 0.0, t[-1] if len(t) else 1.0)
    s = trace.summary
    if s.cutting is not None and s.cutting.peak_power > 0:
        k = int(np.argmax(power))
        ax.annotate(f"peak {s.cutting.peak_power:,.0f} W (line {s.cutting.peak_power_line})",
                    xy=(t[k], power[k]), xytext=(10, -12), textcoords="offset points", fontsize=8)
    # secondary axis: program line numbers at evenly spaced times
    top = ax.twiny()
    top.set_xlim(ax.get_xlim())
    if len(t):
        ticks = np.linspace(t[0], t[-1], 9)
        idx = np.clip(np.searchsorted(t, ticks), 0, len(t) - 1)
        top.set_xticks(ticks)
        top.set_xticklabels([str(int(trace.line[i])) for i in idx], fontsize=8)
    top.set_xlabel("program line")
    if title:
        fig.suptitle(title, fontsize=10)
    return _figure_bytes(plt, fig, fmt)


def lobes_figure(curves: dict, flip=None, fmt: str = "svg", points: dict | None = None, title: str = "",
                 size=(9, 4)) -> bytes:
    """Stability lobes: limiting axial depth (mm) against spindle speed (rpm), one line per
    curve (label -> (speeds, depths)); ``flip``: where the first curve's limiting lobe is a
    period-doubling one (marked); ``points``: label -> (speeds, depths, marker) drawn over it
    (a program's cuts before and after)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=size, dpi=100)
    colours = ["#1f5fa8", "#8a5fbf", "#3a9a5b", "#c07a1f"]
    top = 0.0
    for i, (label, (sp, d)) in enumerate(curves.items()):
        d = np.where(np.isfinite(d), d, np.nan)
        ax.plot(sp, d, lw=1.0, color=colours[i % 4], label=label)
        ax.fill_between(sp, 0, d, color=colours[i % 4], alpha=0.06 if i else 0.12)
        top = max(top, float(np.nanpercentile(d, 95)) if np.isfinite(d).any() else 0.0)
        if i == 0 and flip is not None and np.any(flip):
            f = np.asarray(flip, bool)
            ax.plot(np.asarray(sp)[f], d[f], ".", ms=2.5, color="#c0392b", label="flip (period-doubling) lobe")
    for label, (sp, d, marker) in (points or {}).items():
        ax.plot(sp, d, marker, ms=6, label=label, mfc="none" if "before" in label else None)
        top = max(top, float(np.max(d, initial=0.0)) * 1.1)
    ax.set_xlabel("spindle speed [rpm]")
    ax.set_ylabel("axial depth limit [mm]")
    ax.set_ylim(0, top * 1.1 if top > 0 else 1.0)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    if title:
        ax.set_title(title, fontsize=10)
    return _figure_bytes(plt, fig, fmt)


def _figure_bytes(plt, fig, fmt: str) -> bytes:
    """A finished figure as svg/png/pdf bytes (closed)."""
    fig.tight_layout()
    buf = io.BytesIO()
    save_figure(fig, buf, fmt, dpi=150 if fmt == "png" else None)
    plt.close(fig)
    return buf.getvalue()


# no date in the file, and the SVG's element ids from a fixed salt: the same figure is the
# same bytes (a report written twice, or by a batch job, equals the one written alone)
_NO_DATE = {"svg": {"Date": None}, "pdf": {"CreationDate": None, "ModDate": None}, "png": {}}


def save_figure(fig, buf, fmt: str, **kw) -> None:
    """``fig.savefig`` with reproducible bytes (every report and plot writes through here)."""
    import matplotlib

    with matplotlib.rc_context({"svg.hashsalt": "mtwin"}):
        fig.savefig(buf, format=fmt, metadata=_NO_DATE.get(fmt, {}), **kw)
