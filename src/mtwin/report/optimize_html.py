"""The optimisation report: one self-contained HTML file (inline SVG, no network).

Before and after, each from its own full simulation: spindle cutting power and cutting load
against time with the segments coloured and the load limit drawn, the path feed, the
trade-off of cycle time against the load limit, what limited each segment, and the table of
changed lines (before → after).
"""
from __future__ import annotations

import html

import numpy as np

from .compare_html import _svg, _thin

MAX_SPANS = 400  # coloured segment bands per plot; more are merged (the file stays small)
MAX_CHANGES = 1000  # rows of the changed-lines table
_PALETTE = ("#4e79a7", "#f28e2b", "#59a14f", "#e15759", "#76b7b2", "#edc948", "#b07aa1", "#ff9da7",
            "#9c755f")


def optimize_html(res, program: str) -> bytes:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    b, a = res.before, res.after
    e = html.escape

    def pct(x, y):
        return f"{(y / x - 1) * 100:+.1f} %" if x else "–"

    def cv(v):
        return "–" if v is None else f"{v:.3f}"

    rows = [("cycle time", f"{b.cycle_time:.2f} s", f"{a.cycle_time:.2f} s", pct(b.cycle_time, a.cycle_time)),
            ("cost", "–" if b.cost is None else f"{b.cost:.3f}", "–" if a.cost is None else f"{a.cost:.3f}",
             pct(b.cost, a.cost) if b.cost is not None and a.cost is not None else ""),
            ("peak cutting load", f"{b.peak_load:.1f} N", f"{a.peak_load:.1f} N", pct(b.peak_load, a.peak_load)),
            ("peak spindle power", f"{b.peak_power / 1000:.3f} kW", f"{a.peak_power / 1000:.3f} kW",
             pct(b.peak_power, a.peak_power)),
            ("power CV of the segment means", cv(b.power_cv), cv(a.power_cv), "")]
    ce = res.contour_error or {}
    if ce:
        rows.append(("largest contour error, feed moves", f"{ce['before']:.3f} mm", f"{ce['after']:.3f} mm",
                     f"{ce['after'] - ce['before']:+.3f} mm (tolerance {ce['tolerance']:g} mm per segment)"))
    if res.seg_before is None and res.trace_before is not None:  # written unchanged: no segments
        import dataclasses

        none = np.full(len(res.trace_before.t), -1)
        res = dataclasses.replace(res, seg_before=none, seg_after=none)
    limits = ", ".join(f"T{k}: {v:.0f} N" for k, v in res.force_limit.items())
    parts = [f"<h1>mtwin optimize</h1><p><b>{e(program)}</b>: objective <b>{e(res.objective)}</b> by "
             f"<b>{e(res.method)}</b>; load limit {e(limits)}. Both columns are full simulations of the twin "
             f"(the optimised program re-simulated after it was written and proved to cut the same path; "
             f"{res.rounds} round(s)). The fast model estimated {res.estimate['cycle_time']:.2f} s for it.</p>",
             "<table><tr><th></th><th>before</th><th>after</th><th>change</th></tr>"
             + "".join(f"<tr><td>{e(r[0])}</td><td>{r[1]}</td><td>{r[2]}</td><td>{r[3]}</td></tr>" for r in rows)
             + "</table>"]
    lim_rows = []
    for lim in res.limits or []:
        if lim.get("tool") is None:
            continue
        load = "–" if lim.get("load") is None else f"{lim['load']:.1f} N"
        chip = "–" if not lim.get("chip_thickness") else f"{lim['chip_thickness'] * 1000:.1f} µm"
        src = lim["source"]
        if src == "physics":  # each value with its own source
            src = (f"physics, {lim['material']} ({lim['material_from']}): load — {lim['load_source']}; chip — "
                   f"{lim['chip_thickness_source']}; on final surfaces at most {lim['deflection_load']:.1f} N (the "
                   f"shank bends {lim['deflection_tolerance']:g} mm: {lim['stiffness_source']})")
        lim_rows.append(f"<tr><td>T{lim['tool']}</td><td>{load}</td><td>{chip}</td><td>{e(src)}</td></tr>")
    if lim_rows:
        parts.append("<h2>Limits</h2><table><tr><th>tool</th><th>load</th><th>chip thickness</th><th>where from</th>"
                     "</tr>" + "".join(lim_rows) + "</table>")
    if res.kept:
        parts.append("<h2>Moves that kept their feeds</h2><ul>" + "".join(
            f"<li>{e(why)}: {len(lines)} line(s), {e(', '.join(str(x) for x in lines[:20]))}"
            f"{' …' if len(lines) > 20 else ''}</li>" for why, lines in res.kept.items()) + "</ul>")
    if res.air_entries:
        parts.append("<h2>Plunges through proven air</h2><p>Each runs its upper part at the air feed and its own "
                     "feed from just above the highest material it can meet (1 mm, or the program's own feed height).</p><table><tr><th>line</th><th>from Z"
                     "</th><th>air to Z</th><th>to Z</th><th>material at most at Z</th><th>proven by</th></tr>" +
                     "".join(f"<tr><td>{x['line']}</td><td>{x['from_z']:.3f}</td><td>{x['air_to_z']:.3f}</td>"
                             f"<td>{x['to_z']:.3f}</td><td>{x['material_z']:.3f}</td><td>{e(x['proven_by'])}</td></tr>"
                             for x in res.air_entries) + "</table>")
    parts.append("<h2>Power and load over time</h2>")
    parts.append(_curves(plt, res))
    parts.append("<h2>Path feed over time</h2>")
    parts.append(_feed(plt, res))
    if res.tradeoff:
        parts.append("<h2>Cycle time against the load limit</h2><p>From the same segments (fast model): what "
                     "each extra 10 N of permitted load buys.</p>")
        parts.append(_tradeoff(plt, res))
    if res.tradeoff_scale:
        parts.append("<h2>Cycle time against the physics limits</h2><p>The answer's feeds held to a share of each "
                     "limit from physics (chip thickness, shank load): what a cautious shop gives up by taking 60 or 80 % "
                     "of the catalogue. Line: the fast model; dots: full re-simulations.</p>")
        parts.append(_scale_plot(plt, res))
    if res.chatter:
        parts.append(_chatter(res))
    if res.layers:
        parts.append(_layers(plt, res))
    parts.append(_segments_table(res))
    parts.append(_changes_table(res))
    style = ("body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;color:#222}"
             "table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:3px 8px;"
             "text-align:right;vertical-align:top}td:first-child,th:first-child{text-align:left}"
             "td.code{text-align:left;font-family:monospace;white-space:pre}svg{max-width:100%;height:auto}")
    doc = ("<!DOCTYPE html><html><head><meta charset='utf-8'><title>mtwin optimize</title>"
           f"<style>{style}</style></head><body>{''.join(parts)}</body></html>")
    return doc.encode("utf-8")


def _spans(seg: np.ndarray):
    """(start, end, segment) runs of the per-sample segment index (-1 runs left out)."""
    if not len(seg):
        return []
    edges = np.flatnonzero(np.diff(seg)) + 1
    starts = np.concatenate(([0], edges))
    ends = np.concatenate((edges, [len(seg)]))
    runs = [(int(s), int(t), int(seg[s])) for s, t in zip(starts, ends) if seg[s] >= 0]
    if len(runs) > MAX_SPANS:
        step = int(np.ceil(len(runs) / MAX_SPANS))
        runs = runs[::step]
    return runs


def _shade(ax, t, seg, air):
    for s, u, k in _spans(seg):
        color = "#bbbbbb" if air[k] else _PALETTE[k % len(_PALETTE)]
        ax.axvspan(t[s], t[min(u, len(t) - 1)], color=color, alpha=0.18 if not air[k] else 0.25, lw=0)


def _curves(plt, res) -> str:
    air = np.array([s["air"] for s in res.segments] + [True], bool)
    fig, axes = plt.subplots(4, 1, figsize=(10, 9), dpi=100)
    for row, (tr, seg, label) in enumerate(((res.trace_before, res.seg_before, "before"),
                                            (res.trace_after, res.seg_after, "after"))):
        t = np.asarray(tr.t)
        p = np.asarray(tr.signal("spindle_power"))
        load = np.hypot(tr.signal("fx"), tr.signal("fy"))
        ap, al = axes[row], axes[2 + row]
        tt, pp, ll = _thin(t, p, load)
        _shade(ap, t, seg, air)
        _shade(al, t, seg, air)
        ap.plot(tt, pp, lw=0.7, color="#1f5fa8")
        al.plot(tt, ll, lw=0.7, color="#b03a2e")
        if res.force_limit:
            # each tool's limit over its own segments (one dashed line for all would put a
            # 2.9 N limit under a 100 N tool's cuts)
            first = True
            for s_, u_, k in _spans(seg):
                lim = res.force_limit.get(res.segments[k]["tool"]) if k < len(res.segments) else None
                if lim is None or res.segments[k]["air"]:
                    continue
                al.hlines(lim, t[s_], t[min(u_, len(t) - 1)], colors="k", linestyles="--", lw=0.8,
                          label="limit per tool" if first else None)
                first = False
            if not first:
                al.legend(loc="upper right", fontsize=8)
        ap.set_ylabel(f"power {label} [W]")
        al.set_ylabel(f"load {label} [N]")
        for ax in (ap, al):
            ax.grid(True, alpha=0.3)
            ax.set_xlim(t[0] if len(t) else 0, t[-1] if len(t) else 1)
    axes[-1].set_xlabel("time [s]; bands: segments (grey: air cuts)")
    return _svg(fig)


def _feed(plt, res) -> str:
    fig, ax = plt.subplots(figsize=(10, 3), dpi=100)
    for tr, seg, label, color in ((res.trace_before, res.seg_before, "before", "#888888"),
                                  (res.trace_after, res.seg_after, "after", "#1f5fa8")):
        t = np.asarray(tr.t)
        # in the optimised segments only: rapids would flatten the scale
        f = np.where(seg >= 0, np.asarray(tr.signal("feed")), np.nan)
        tt, ff = _thin(t, f)
        ax.plot(tt, ff, lw=0.7, color=color, label=label)
    ax.set_ylabel("path feed in the segments [mm/min]")
    ax.set_xlabel("time [s]")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    return _svg(fig)


def _chatter(res) -> str:
    """Per tool with dynamics: its cuts' lobes (the most limiting arcs) with every cutting
    segment's (S, ap) before (hollow) and after (filled); the segments no speed makes stable."""
    from .plots import lobes_figure

    e = html.escape
    ch = res.chatter
    out = [f"<h2>Chatter stability</h2><p>Each cut's axial depth is held at most {ch['margin']:g} of the lobes' "
           f"limit at its speed ({e(ch['method'])}; a chosen speed keeps it over ±1 % of itself). The curves are the "
           f"limits of the tool's cuts' engaged arcs; the points the segments' deepest cuts.</p>"]
    for tool, (grid, curves) in sorted(res.chatter_curves.items()):
        rows = [r for r in ch["segments"] if r["tool"] == tool]
        pts = {"before": (np.array([r["speed_before"] for r in rows]), np.array([r["ap"] for r in rows]), "o"),
               "after": (np.array([r["speed_after"] for r in rows]), np.array([r["ap"] for r in rows]), "s")}
        svg = lobes_figure({f"T{tool} {lab}": (grid, lim) for lab, lim in curves}, None, "svg", pts,
                           title=f"T{tool}: stability lobes and the cuts", size=(10, 4))
        out.append(svg.decode("utf-8")[svg.decode("utf-8").find("<svg"):])
    def cell(v):
        return "–" if v is None else f"{v:.2f}"

    rows = "".join(f"<tr><td>{r['lines'][0]}-{r['lines'][1]}</td><td>T{r['tool']}</td><td>{r['ap']:.2f} mm</td>"
                   f"<td>{r['speed_before']:.0f} → {r['speed_after']:.0f}</td><td>{cell(r['margin_before'])}</td>"
                   f"<td>{'unstable at every speed' if r['unstable_everywhere'] else cell(r['margin_after'])}</td></tr>"
                   for r in ch["segments"])
    out.append("<table><tr><th>lines</th><th>tool</th><th>ap</th><th>S rpm</th><th>depth/limit before</th>"
               f"<th>after</th></tr>{rows}</table>")
    if ch["unstable"]:
        out.append("<p><b>Cannot be made stable</b> by any allowed speed (the CAM must take less depth): " + "; ".join(
            f"lines {u['lines'][0]}-{u['lines'][1]} (T{u['tool']}, ap {u['ap']:.2f} mm; at most "
            f"{u['deepest_stable']:.2f} mm at {u['at_speed']:.0f} rpm)" for u in ch["unstable"]) + "</p>")
    return "".join(out)


def _layers(plt, res) -> str:
    """The cuts written in layers, and the proof by the part: the two Z-maps and their difference."""
    e = html.escape
    p = res.stock_proof
    rows = "".join(f"<tr><td>{ly['lines'][0]}–{ly['lines'][1]}</td><td>T{ly['tool']}</td><td>{ly['layers']}</td>"
                   f"<td>{ly['depth_per_layer']:.3f} mm</td><td>{', '.join(f'{z:.3f}' for z in ly['z'])}</td>"
                   f"<td>{ly['time_added_at_program_feeds']:+.1f} s</td></tr>" for ly in res.layers)
    out = [f"<h2>Cuts in layers</h2><p>Over the limit even at the lowest feed, so cut again in layers of equal "
           f"depth (docs/optimize.md, depth layering). The proof by the part: {e(p.reason())}.</p>"
           "<table><tr><th>lines</th><th>tool</th><th>layers</th><th>depth per layer</th><th>Z of each layer</th>"
           "<th>time the layers add at the program's feeds</th></tr>" + rows + "</table>"]
    step = max(1, int(np.ceil(max(p.original.shape) / 300)))  # at most ~300 cells a side drawn
    a, b = p.original[::step, ::step], p.optimised[::step, ::step]
    box = p.box
    ext = (box[0], box[0] + p.original.shape[1] * p.resolution, box[1], box[1] + p.original.shape[0] * p.resolution)
    fig, axes = plt.subplots(1, 3, figsize=(11, 3.4), dpi=100)
    lo, hi = float(min(a.min(), b.min())), float(max(a.max(), b.max()))
    for ax, z, title in ((axes[0], a, "the original leaves"), (axes[1], b, "the optimised program leaves")):
        im = ax.imshow(z, origin="lower", extent=ext, vmin=lo, vmax=hi, cmap="viridis", interpolation="nearest")
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("X [mm]")
    axes[0].set_ylabel("Y [mm]")
    fig.colorbar(im, ax=axes[1], label="Z [mm]")
    d = (b - a).astype(np.float64)
    m = max(float(np.abs(d).max()), p.tolerance)
    im = axes[2].imshow(d, origin="lower", extent=ext, vmin=-m, vmax=m, cmap="coolwarm", interpolation="nearest")
    axes[2].set_title(f"difference (largest {p.max_difference:.3g} mm)", fontsize=9)
    axes[2].set_xlabel("X [mm]")
    fig.colorbar(im, ax=axes[2], label="optimised − original [mm]")
    fig.tight_layout()
    out.append(_svg(fig))
    return "".join(out)


def _tradeoff(plt, res) -> str:
    f = np.array([x[0] for x in res.tradeoff])
    t = np.array([x[1] for x in res.tradeoff])
    fig, ax = plt.subplots(figsize=(7, 3.2), dpi=100)
    ax.plot(f, t, marker="o", color="#1f5fa8")
    for k in range(1, len(f)):
        ax.annotate(f"{t[k] - t[k - 1]:+.1f} s", ((f[k] + f[k - 1]) / 2, (t[k] + t[k - 1]) / 2), fontsize=7,
                    ha="center", va="bottom")
    if res.force_limit:
        ax.axvline(max(res.force_limit.values()), color="k", ls="--", lw=0.8, label="chosen limit")
        ax.legend(fontsize=8)
    ax.set_xlabel("load limit [N]")
    ax.set_ylabel("estimated cycle time [s]")
    ax.grid(True, alpha=0.3)
    return _svg(fig)


def _scale_plot(plt, res) -> str:
    sc = np.array([x["scale"] for x in res.tradeoff_scale])
    t = np.array([x["estimate"] for x in res.tradeoff_scale])
    fig, ax = plt.subplots(figsize=(7, 3.2), dpi=100)
    ax.plot(sc * 100, t, marker="o", color="#1f5fa8", label="estimate")
    rs = [(x["scale"] * 100, x["resimulated"]) for x in res.tradeoff_scale if x["resimulated"] is not None]
    if rs:
        ax.plot([a for a, _ in rs], [b for _, b in rs], "s", color="#c0392b", label="re-simulated")
    ax.axhline(res.before.cycle_time, color="k", ls="--", lw=0.8, label="program as written")
    ax.legend(fontsize=8)
    ax.set_xlabel("share of the physics limits [%]")
    ax.set_ylabel("cycle time [s]")
    ax.grid(True, alpha=0.3)
    return _svg(fig)


def _segments_table(res) -> str:
    e = html.escape
    rows = []
    for k, s in enumerate(res.segments):
        lines = f"{s['lines'][0]}" + (f"–{s['lines'][1]}" if s["lines"][1] != s["lines"][0] else "")
        color = "#bbbbbb" if s["air"] else _PALETTE[k % len(_PALETTE)]
        rows.append(f"<tr><td><span style='color:{color}'>&#9632;</span> {k}</td><td>{lines}</td>"
                    f"<td>{'air' if s['air'] else 'cut'}{_layer_mark(s)}</td><td>T{s['tool']}</td>"
                    f"<td>{s['feed_before']:g} → {s['feed_after']:g}</td><td>{s['spindle_after']:g}</td>"
                    f"<td>{s['mean_power_before']:.0f} → {s['mean_power_after']:.0f}</td>"
                    f"<td>{s['peak_load_estimate']:.1f}</td><td>{e(s['limited_by'])}</td></tr>")
    return ("<h2>Segments</h2><table><tr><th>segment</th><th>lines</th><th></th><th>tool</th>"
            "<th>feed mm/min</th><th>S rpm</th><th>mean power W (estimate)</th><th>peak load N (estimate)</th>"
            "<th>limited by</th></tr>" + "".join(rows) + "</table>")


def _layer_mark(seg) -> str:
    """', layer k of N' for a segment of a cut written in layers."""
    if "layer" not in seg:
        return ""
    k, n = seg["layer"]
    return f", layer {k} of {n}"


def _changes_table(res) -> str:
    e = html.escape
    rows = "".join(f"<tr><td>{ln}</td><td class='code'>{e(x)}</td><td class='code'>{e(y)}</td></tr>"
                   for ln, x, y in res.changed_lines[:MAX_CHANGES])
    more = (f"<p>… and {len(res.changed_lines) - MAX_CHANGES} more.</p>"
            if len(res.changed_lines) > MAX_CHANGES else "")
    return (f"<h2>Changed lines ({len(res.changed_lines)})</h2><table><tr><th>line</th><th>before</th>"
            f"<th>after</th></tr>{rows}</table>{more}")
