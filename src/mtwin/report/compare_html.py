"""The compare report: one self-contained HTML file (inline SVG, no network) for a person.

Per signal: measured and simulated against time, the residual beneath, the worst regions
shaded with their program lines; the metrics and the worst regions as tables; and, when the
twin file has a model journal, the error across its calibrations.
"""
from __future__ import annotations

import html
import io

import numpy as np

from ..units import figure

MAX_POINTS = 4000  # per curve: plenty for a screen, keeps the file small


def _svg(fig) -> str:
    """A finished figure as inline SVG (laid out, then closed: every report figure ends here)."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    buf = io.StringIO()
    from .plots import save_figure

    save_figure(fig, buf, "svg")
    plt.close(fig)
    text = buf.getvalue()
    return text[text.index("<svg"):]


def _thin(t, *ys):
    """At most MAX_POINTS points of each curve over the times ``t``, every peak kept: each of
    MAX_POINTS / 2 buckets of samples gives its first time with the bucket's minimum and its
    middle time with the maximum (a thinned curve that skipped samples dropped the peaks the
    tables report).  A bucket with no number stays a gap; a shorter gap inside one is bridged."""
    n = len(t)
    if n <= MAX_POINTS:
        return (t, *ys)
    starts = np.linspace(0, n, MAX_POINTS // 2, endpoint=False).astype(np.int64)
    mids = np.minimum(starts + np.diff(np.r_[starts, n]) // 2, n - 1)
    tt = np.empty(2 * len(starts))
    tt[0::2], tt[1::2] = np.asarray(t)[starts], np.asarray(t)[mids]
    out = [tt]
    for y in ys:
        y = np.asarray(y, dtype=np.float64)
        with np.errstate(invalid="ignore"):
            lo = np.fmin.reduceat(y, starts)
            hi = np.fmax.reduceat(y, starts)
        v = np.empty(2 * len(starts))
        v[0::2], v[1::2] = lo, hi
        out.append(v)
    return tuple(out)


def compare_html(comparison, program: str, measurement: str, journal: list | None = None, max_signals: int = 8,
                 blocks: dict | None = None, notes=()) -> bytes:
    """The report of ``comparison`` (:class:`~mtwin.loop.compare.Comparison`); ``blocks``: its
    block timing as ``BlockTiming.as_dict`` gives it (with the program's lines), against a
    control's log; ``notes``: what the command said on the way (warnings and notes)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..loop.measurement import signal_unit

    c = comparison
    parts = [f"<h1>mtwin compare</h1><p><b>{html.escape(program)}</b> against <b>{html.escape(measurement)}</b>: "
             f"aligned by {html.escape(c.alignment)}, time offset {c.time_offset:+.3f} s.</p>"]
    ct = c.cycle_time
    if ct.get("measured") is not None:
        rel = f"{ct['relative_error']:+.2%}" if ct.get("relative_error") is not None else "–"
        parts.append(f"<p>Cycle time: measured {ct['measured']:.3f} s, simulated {ct['simulated']:.3f} s ({rel}).</p>")
    if notes:
        parts.append("<ul class='notes'>" + "".join(f"<li>{html.escape(n)}</li>" for n in notes) + "</ul>")
    if blocks and blocks.get("by_kind"):
        parts.append(_blocks_html(blocks))
    rows = "".join(
        f"<tr><td>{html.escape(s)}</td><td>{html.escape(signal_unit(s))}</td>" + "".join(
            f"<td>{'–' if m[k] is None else f(m[k])}</td>"
            for k, f in (("rms", figure), ("nrmse", lambda x: f"{x:.2%}"), ("max_error", figure),
                         ("bias", lambda x: figure(x, signed=True)), ("correlation", lambda x: f"{x:.3f}")))
        + f"<td>{m['samples']:,}</td></tr>"
        for s, m in c.signals.items())
    parts.append("<h2>Signals (measured − simulated)</h2><table><tr><th>signal</th><th>unit</th><th>RMS</th>"
                 f"<th>NRMSE</th><th>max</th><th>bias</th><th>correlation</th><th>samples</th></tr>{rows}</table>")
    if c.worst_regions:
        rows = "".join(f"<tr><td>{html.escape(r['signal'])}</td><td>{r['first_line']}"
                       + (f"–{r['last_line']}" if r["last_line"] != r["first_line"] else "")
                       + f"</td><td>{figure(r['rms'])} {html.escape(signal_unit(r['signal']))}</td>"
                       f"<td>{r['share']:.1%}</td></tr>" for r in c.worst_regions)
        parts.append("<h2>Where it fails</h2><table><tr><th>signal</th><th>lines</th><th>RMS</th>"
                     f"<th>share of the squared error</th></tr>{rows}</table>")
    if c.t is not None and c.line is not None:
        parts.append("<h2>Measured and simulated</h2>")
        for s in list(c.measured)[:max_signals]:
            parts.append(_signal_figure(plt, c, s))
    if journal:
        parts.append(_journal_figure(plt, journal))
    style = ("body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;color:#222}"
             "table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:3px 8px;"
             "text-align:right}td:first-child,th:first-child{text-align:left}svg{max-width:100%;height:auto}"
             "td.code{font-family:monospace;text-align:left}.notes{color:#555;font-size:90%}")
    doc = ("<!DOCTYPE html><html><head><meta charset='utf-8'><title>mtwin compare</title>"
           f"<style>{style}</style></head><body>{''.join(parts)}</body></html>")
    return doc.encode("utf-8")


def block_kind_table(b: dict) -> tuple[list, list]:
    """(header, rows of cells) of the error by block kind (``BlockTiming.as_dict``): what
    ``mtwin compare`` prints on stderr and the report shows, the same cells."""
    ratio = any(k.get("logged_over_programmed_feed") is not None for k in b["by_kind"])
    head = ["kind", "groups", "measured s", "simulated s", "simulated − measured s", "as logged s", "RMS s"] + \
        (["logged F / programmed F (twin's log in brackets)"] if ratio else [])
    rows = []
    for k in b["by_kind"]:
        r, r_twin = k.get("logged_over_programmed_feed"), k.get("twin_logged_over_programmed_feed")
        shown = "-" if r is None else f"{r:.2f}" + (f" ({r_twin:.2f})" if r_twin is not None else "")
        rows.append([k["kind"], f"{k['groups']:,}", f"{k['measured']:.1f}", f"{k['simulated']:.1f}", f"{k['error']:+.1f}",
                     f"{k['error_as_logged']:+.1f}", f"{k['rms']:.3f}"] + ([shown] if ratio else []))
    return head, rows


def _blocks_html(b: dict) -> str:
    """The block timing against a control's log: the error by block kind and the worst blocks
    with their G-code (what ``mtwin compare`` prints on stderr)."""
    head, cells = block_kind_table(b)
    ratio = head[-1].startswith("logged F")
    rows = ["<tr>" + "".join(f"<td>{html.escape(x)}</td>" for x in row) + "</tr>" for row in cells]
    out = (f"<h2>Block timing</h2><p>{b['groups']:,} logged block groups (a logged line and the unlogged lines "
           f"after it), RMS {b['rms']:.3f} s per group, as logged, against a noise floor of about "
           f"{b['noise_floor_per_group']:.2f} s.  <i>As logged</i>: the simulated groups as a log sampling every "
           f"{b.get('report_period') or 0:.2f} s would show them, less what logs of the twin's own run show by kind."
           + (" <i>Logged F / programmed F</i>: the log's path feed over F in the blocks where the twin runs at F "
              "for most of the block (80 % of its time); in brackets the same of logs of the twin's own run sampled "
              "alike (what the sampling alone makes of it)." if ratio else "")
           + "</p><table><tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in head) + "</tr>" + "".join(rows)
           + "</table>")
    if b.get("worst"):
        rows = "".join(
            f"<tr><td>{x['first_line']}" + (f"–{x['last_line']}" if x["last_line"] != x["first_line"] else "")
            + f"</td><td>{html.escape(x['kind'])}</td><td>{x['measured']:.2f}</td><td>{x['simulated_as_logged']:.2f}</td>"
            f"<td>{x['error']:+.2f}</td><td class='code'>{html.escape(x['text'][:60])}</td></tr>" for x in b["worst"])
        out += ("<h3>Worst blocks</h3><table><tr><th>lines</th><th>kind</th><th>measured s</th><th>simulated as logged s</th>"
                f"<th>error as logged s</th><th>G-code</th></tr>{rows}</table>")
    return out


def _signal_figure(plt, c, s) -> str:
    from ..loop.measurement import signal_unit

    t, m, sim, line = c.t, c.measured[s], c.simulated[s], c.line
    fig, (ax, ar) = plt.subplots(2, 1, figsize=(10, 4.2), dpi=100, sharex=True, gridspec_kw={"height_ratios": [2, 1]})
    tt, mm, ss = _thin(t, m, sim)
    ax.plot(tt, mm, lw=0.7, color="#444", label="measured")
    ax.plot(tt, ss, lw=0.9, color="#1f5fa8", label="simulated")
    ar.plot(tt, mm - ss, lw=0.6, color="#b03a2e")
    unit = signal_unit(s)
    ax.set_ylabel(f"{s} [{unit}]" if unit else s)
    ar.set_ylabel(f"residual [{unit}]" if unit else "residual")
    ar.set_xlabel("time [s] (measured clock)")
    for a in (ax, ar):
        a.grid(True, alpha=0.3)
    labelled: list = []  # (x of each label so far, as a share of the axis): close ones stacked
    span = float(t[-1] - t[0]) or 1.0
    for r in (r for r in c.worst_regions if r["signal"] == s):
        inside = (line >= r["first_line"]) & (line <= r["last_line"])
        if not inside.any():
            continue
        # shade every contiguous stretch of those lines, label the first
        idx = np.flatnonzero(inside)
        breaks = np.flatnonzero(np.diff(idx) > 1)
        starts = np.concatenate(([idx[0]], idx[breaks + 1]))
        ends = np.concatenate((idx[breaks], [idx[-1]]))
        label = f"line {r['first_line']}" + (f"–{r['last_line']}" if r["last_line"] != r["first_line"] else "")
        for k, (a_, b_) in enumerate(zip(starts, ends)):
            for a in (ax, ar):
                a.axvspan(t[a_], t[b_], color="#f0b400", alpha=0.25, lw=0)
            if k == 0:
                x = float(t[a_] - t[0]) / span
                row = sum(abs(x - x0) < 0.08 for x0 in labelled)
                labelled.append(x)
                ax.annotate(label, xy=(t[a_], 1.0), xycoords=("data", "axes fraction"), fontsize=7,
                            va="bottom", rotation=0, xytext=(0, 9 * row), textcoords="offset points")
    ax.legend(loc="upper right", fontsize=8)
    return _svg(fig)


def _journal_figure(plt, journal) -> str:
    signals = sorted({s for e in journal for s in e.get("rms_after", {})})
    fig, ax = plt.subplots(figsize=(7, 3), dpi=100)
    it = [0] + [int(e.get("iteration", k + 1)) for k, e in enumerate(journal)]
    for s in signals:
        first = journal[0].get("rms_before", {}).get(s)
        ys = [first] + [e.get("rms_after", {}).get(s) for e in journal]
        ax.plot(it, ys, marker="o", label=s)
    ax.set_xlabel("calibration (0: before the first)")
    ax.set_ylabel("RMS error")
    ax.set_yscale("log")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    out = _svg(fig)
    return "<h2>Model journal: the error across calibrations</h2>" + out
