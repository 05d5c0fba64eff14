"""The grinding-cycle report: one self-contained HTML file (inline SVG, no network).

The optimal cycle on the nominal part (programmed and actual feed, radial force, remaining
allowance against time), its stages, the robustness iterations, and the defect map: the batch
sample of the first iteration over the two variation factors that separate defects best.
"""
from __future__ import annotations

import html

import numpy as np

from .compare_html import _svg


def grind_html(twin, result, cols: dict) -> bytes:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    e = html.escape
    d = result.design
    parts = [f"<h1>mtwin grind design</h1><p>Optimal stepped plunge cycle on the nominal part: "
             f"<b>{d.cycle_time:.2f} s</b> ({len(d.stages)} stage(s), spark-out {d.sparkout:.1f} rev), "
             f"DP grid {len(d.grid[0])} feeds × {len(d.grid[1]) - 1} allowance levels.</p>"]
    rows = "".join(f"<tr><td>{k}</td><td>{s.feed:.4g}</td><td>{s.switch_allowance:.4f}</td><td>{s.time:.2f}</td></tr>"
                   for k, s in enumerate(d.stages, 1))
    parts.append("<h2>Stages</h2><table><tr><th>stage</th><th>feed mm/min</th><th>until the gauge reads mm</th>"
                 f"<th>time s</th></tr>{rows}</table>")
    parts.append(_setup(twin))
    fig, axes = plt.subplots(3, 1, figsize=(10, 7), dpi=100, sharex=True)
    t = cols["t"]
    axes[0].plot(t, cols["feed_cmd"], lw=1.0, color="#888888", label="programmed")
    axes[0].plot(t, cols["feed"], lw=1.0, color="#1f5fa8", label="actual")
    axes[0].set_ylabel("radial feed [mm/min]")
    axes[0].legend(fontsize=8)
    axes[1].plot(t, cols["fx"], lw=1.0, color="#b03a2e")
    axes[1].axhline(twin["wheel.force_limit"], color="k", ls="--", lw=0.8)
    axes[1].set_ylabel("radial force [N]")
    axes[2].plot(t, cols["radius"], lw=1.0, color="#2e7d32")
    axes[2].set_ylabel("allowance left [mm]")
    axes[2].set_xlabel("time [s]")
    for a in axes:
        a.grid(True, alpha=0.3)
    parts.append("<h2>The cycle on the nominal part</h2>" + _svg(fig))
    rows = "".join(f"<tr><td>{k}</td><td>{it.cycle_time:.2f}</td><td>{it.defects} / {it.cases}</td>"
                   f"<td>{e(', '.join(f'{n}: {c}' for n, c in it.broken.items()) or '—')}</td>"
                   f"<td>{e(', '.join(_limit_text(n, v) for n, v in it.scale.items()) or '—')}</td></tr>"
                   for k, it in enumerate(result.iterations, 1))
    parts.append("<h2>Robustness iterations</h2><p>The cycle run on a batch sample (Latin hypercube over the "
                 "variation); each broken limit is tightened for the next design.</p><table><tr><th>iteration</th>"
                 "<th>cycle s</th><th>defective parts</th><th>broken limits</th><th>tightened limits</th></tr>"
                 f"{rows}</table>")
    if not result.feasible:
        parts.append("<p style='color:#b03a2e'><b>Not robust:</b> the robustness loop did not remove every defect; "
                     "the cycle shown is the iteration with the fewest defective parts.</p>")
    if result.validation is not None:
        v = result.validation
        parts.append(f"<p>Validation on a fresh sample of {v.cases} parts: <b>{v.defects}</b> defective.</p>")
    if result.factors is not None and result.defect_mask is not None:
        parts.append("<h2>Defect map (first design)</h2>" + _defect_map(plt, result.factors, result.defect_mask))
    style = ("body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;color:#222}"
             "table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:3px 8px;"
             "text-align:right}td:first-child,th:first-child{text-align:left}svg{max-width:100%;height:auto}")
    return ("<!DOCTYPE html><html><head><meta charset='utf-8'><title>mtwin grind</title>"
            f"<style>{style}</style></head><body>{''.join(parts)}</body></html>").encode("utf-8")


def _setup(twin) -> str:
    """The set-up the cycle was designed for: every parameter of the grinding twin, with its
    unit, and which ones differ from the defaults (the reference's experiment)."""
    from ..grind.model import PARAMS

    rows = "".join(f"<tr><td>{html.escape(p.name)}</td><td>{twin[p.name]:g}</td><td>{html.escape(p.unit)}</td>"
                   f"<td>{'' if twin[p.name] == p.default else f'(default {p.default:g})'}</td>"
                   f"<td style='text-align:left'>{html.escape(p.doc)}</td></tr>" for p in PARAMS)
    return ("<h2>Set-up</h2><p>Wheel, part, machine and limits the cycle was designed for (a grind file's "
            "values; the rest the defaults: the reference's experiment).</p><table><tr><th>parameter</th>"
            f"<th>value</th><th>unit</th><th></th><th>what it is</th></tr>{rows}</table>")


def _limit_text(name: str, value: float) -> str:
    # "switch" is an absolute cap on the spark-out switch point; the others scale their limit
    return f"spark-out switch ≤ {value:.4f} mm" if name == "switch" else f"{name} ×{value:.3g}"


def _defect_map(plt, factors: dict, mask: np.ndarray) -> str:
    names = list(factors)
    # the two factors whose values differ most between defective and good parts
    score = []
    for n in names:
        v = np.asarray(factors[n], float)
        s = v.std() or 1.0
        score.append(abs(v[mask].mean() - v[~mask].mean()) / s if mask.any() and (~mask).any() else 0.0)
    a, b = (names[i] for i in np.argsort(score)[::-1][:2])
    fig, ax = plt.subplots(figsize=(6.5, 4.5), dpi=100)
    ax.scatter(factors[a][~mask], factors[b][~mask], s=10, color="#2e7d32", label="good")
    ax.scatter(factors[a][mask], factors[b][mask], s=12, color="#b03a2e", marker="x", label="defect")
    ax.set_xlabel(a)
    ax.set_ylabel(b)
    ax.legend(fontsize=8)
    ax.grid(True, alpha=0.3)
    return _svg(fig)
