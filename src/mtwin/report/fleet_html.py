"""The batch's page: one self-contained HTML file (inline SVG drawn here, no network, no
script) linking each job's outputs, with the fleet's figures — cycle time saved per machine,
a calibration's fitted parameters per machine against the fleet's median, the jobs that
failed and why."""
from __future__ import annotations

import html
from urllib.parse import quote

STYLE = ("body{font-family:system-ui,sans-serif;margin:2em;max-width:75em;color:#222}"
         "table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:.25em .6em;"
         "text-align:right}td.l,th.l{text-align:left}.ok{color:#070}.failed,.refused{color:#b00}"
         ".odd{background:#fde8e8}caption{text-align:left;font-weight:bold}")


def fleet_html(b) -> bytes:
    e = html.escape
    s = b.summary()
    rows = b.rows()
    parts = [f"<h1>mtwin batch {e(b.command)}</h1>",
             f"<p>{s['jobs']} job(s): <b class='ok'>{s['ok']} ok</b>, <b class='{'failed' if s['failed'] else ''}'>"
             f"{s['failed']} failed</b>, <b class='{'refused' if s['refused'] else ''}'>{s['refused']} refused</b>" + (f", {s['not run']} not run (interrupted)"
                                                                  if s["not run"] else "")
             + f"; {e(b.runner)}; {s['seconds']:.1f} s.</p>"]
    if s["cycle_saved_s"] is not None and b.command == "optimize":
        parts.append(f"<p>Cycle time saved over the jobs that ran: <b>{s['cycle_saved_s']:.1f} s</b> "
                     f"({s['cycle_saved_pct']:.1f} % of "
                     f"{sum(m['cycle_before_s'] or 0.0 for m in s['machines'].values()):.1f} s)."
                     "</p>")
        parts.append(_bars({m: v["saved_s"] / v["cycle_before_s"] * 100 for m, v in s["machines"].items()
                            if v["cycle_before_s"]}, "cycle time saved per machine, %"))
    parts.append(_machines(s["machines"], b.command))
    if b.command == "calibrate":
        parts.append(_parameters(b))
    parts.append(_jobs(rows, b.command))
    bad = [r for r in rows if r["status"] != "ok"]
    if bad:
        parts.append("<h2>Failed and refused jobs</h2><ul>" + "".join(
            f"<li><b>{e(r['job'])}</b> ({e(r['status'])}): {e(r['error'] or '(no message)')} — "
            f"<a href='{e(quote(r['job']))}/result.json'>log</a></li>" for r in bad) + "</ul>")
    doc = ("<!DOCTYPE html><html><head><meta charset='utf-8'><title>mtwin batch " + e(b.command) + "</title><style>"
           + STYLE + "</style></head><body>" + "".join(parts) + "</body></html>\n")
    return doc.encode()


def _bars(values: dict, title: str) -> str:
    """A horizontal bar chart as inline SVG (negative values drawn leftwards in red)."""
    if not values:
        return ""
    e = html.escape
    h, label_w, plot_w = 22, 180, 420
    lo, hi = min(0.0, *values.values()), max(0.0, *values.values())
    span = (hi - lo) or 1.0
    x0 = label_w + plot_w * (-lo / span)
    out = [f"<svg xmlns='http://www.w3.org/2000/svg' width='{label_w + plot_w + 80}' "
           f"height='{h * len(values) + 30}' role='img' aria-label='{e(title)}'>",
           f"<text x='0' y='14' font-size='13' font-weight='bold'>{e(title)}</text>"]
    for k, (name, v) in enumerate(sorted(values.items())):
        y = 24 + k * h
        w = plot_w * abs(v) / span
        x = x0 if v >= 0 else x0 - w
        out.append(f"<text x='{label_w - 6}' y='{y + 14}' font-size='12' text-anchor='end'>{e(name)}</text>"
                   f"<rect x='{x:.1f}' y='{y + 3}' width='{max(w, 0.5):.1f}' height='{h - 6}' "
                   f"fill='{'#2a7' if v >= 0 else '#c33'}'/>"
                   f"<text x='{x0 + (w if v >= 0 else 0) + 4:.1f}' y='{y + 14}' font-size='12'>{v:.1f}</text>")
    out.append(f"<line x1='{x0:.1f}' x2='{x0:.1f}' y1='20' y2='{h * len(values) + 26}' stroke='#333'/></svg>")
    return "".join(out)


def _machines(machines: dict, command: str) -> str:
    e = html.escape
    head = "<tr><th class='l'>machine</th><th>jobs</th><th>ok</th>"
    head += "<th>cycle before s</th><th>cycle after s</th><th>saved s</th></tr>" if command == "optimize" else "</tr>"
    body = ""
    for m, v in sorted(machines.items()):
        body += f"<tr><td class='l'>{e(m)}</td><td>{v['jobs']}</td><td>{v['ok']}</td>"
        if command == "optimize":
            body += "".join(f"<td>{'' if v[k] is None else f'{v[k]:.1f}'}</td>"
                            for k in ("cycle_before_s", "cycle_after_s", "saved_s"))
        body += "</tr>"
    return f"<h2>Per machine</h2><table>{head}{body}</table>"


def _parameters(b) -> str:
    """The fleet table of a calibration: each machine's fitted values, each against the
    median of the fleet (marked where it is far from it: the machine that differs)."""
    e = html.escape
    table = b.fleet_table()
    if not table:
        return ""
    machines = list(b.fitted())
    head = "<tr><th class='l'>parameter</th>" + "".join(f"<th>{e(m)}</th>" for m in machines) + "</tr>"
    body = ""
    for t in table:
        cells = ""
        for m in machines:
            x = t["machines"].get(m)
            if x is None:
                cells += "<td>—</td>"
                continue
            sd = "" if x["sd"] is None else f" ± {x['sd']:.2g}"
            ratio = "" if x["ratio"] is None else f" ({x['ratio']:.2f}×)"
            low = "≥ " if x.get("at_least") else ""
            cells += f"<td class='{'odd' if x['odd'] else ''}'>{low}{x['value']:.4g}{sd}{ratio}</td>"
        body += f"<tr><td class='l'>{e(t['parameter'])}</td>{cells}</tr>"
    return ("<h2>Fitted parameters</h2><p>Each machine's value ± its standard deviation, and its ratio to the "
            f"fleet's median (marked when more than {b.outlier:.0%} away and more than two standard deviations: a "
            f"difference the logs show); ≥: a limit no logged block of that machine reaches, set at the least "
            f"value its logs allow.</p><table>{head}{body}</table>")


# a job's figures on the page and on stderr, by command: (heading, row key, format)
FIGURES = {
    "optimize": [("before s", "cycle_before_s", "{:.2f}"), ("after s", "cycle_after_s", "{:.2f}"),
                 ("saved %", "saved_pct", "{:.1f}")],
    "simulate": [("cycle s", "cycle_before_s", "{:.2f}")],
    "compare": [("twin s", "cycle_before_s", "{:.2f}"), ("measured s", "measured_cycle_s", "{:.2f}"),
                ("cycle error %", "cycle_error_pct", "{:+.2f}")],
    "calibrate": [("fitted", "fit_measure", "{}"), ("error before", "rms_before", "{:.4g}"),
                  ("error after", "rms_after", "{:.4g}"), ("held-out %", "holdout_error_pct", "{:+.2f}")],
}


def _jobs(rows: list, command: str) -> str:
    e = html.escape
    cols = FIGURES[command]
    head = ("<tr><th class='l'>job</th><th class='l'>machine</th><th class='l'>program</th><th class='l'>status</th>"
            + "".join(f"<th>{e(h)}</th>" for h, _, _ in cols) + "<th>s</th><th class='l'>outputs</th></tr>")
    body = ""
    for r in rows:
        links = " ".join(f"<a href='{e(quote(p))}'>{e(k)}</a>" for k, p in r["outputs"].items())
        links += f" <a href='{e(quote(r['job']))}/result.json'>result</a>"
        figs = "".join(f"<td>{'' if r[k] is None else e(fmt.format(r[k]))}</td>" for _, k, fmt in cols)
        body += (f"<tr><td class='l'>{e(r['job'])}</td><td class='l'>{e(r['machine'])}</td>"
                 f"<td class='l'>{e(r['program'])}</td><td class='l {e(r['status'])}'>{e(r['status'])}</td>"
                 f"{figs}<td>{r['seconds']:.1f}</td><td class='l'>{links}</td></tr>")
    return f"<h2>Jobs</h2><table>{head}{body}</table>"
