"""Write docs/validation.md: the twin against the NIST Hurco VMX24 logs (plates 12, 13, 14).

    python scripts/validation.py [REALDATA]      (REALDATA: ../shared/realdata by default)

Per plate: the plain length/feed estimate's cycle-time error, the default twin's and the
calibrated profile's (samples/machines/hurco-vmx24.toml, made by scripts/hurco-vmx24.sh),
the profile calibrated on the two other plates predicting this one (leave-one-out), per-block
timing RMS and the error by block kind, and the feed-profile NRMSE; a figure of measured
against simulated feed for plate 13.  Every table and every figure in the bullets is computed
here; the prose describing the programs themselves (radii, turn angles, path lengths) was read
off them and is typed.
"""
from __future__ import annotations

import datetime as dt
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PLATES = (12, 13, 14)
PROFILE = ROOT / "samples" / "machines" / "hurco-vmx24.toml"
START = ROOT / "samples" / "machines" / "hurco-vmx24-start.toml"  # the hand-set base of scripts/hurco-vmx24.sh
RECIPE = ("spindle-runup", "toolchange-time", "rapid-acceleration", "arc-acceleration",
          "spiral-acceleration", "block-time", "feed-rapid-wait")  # scripts/hurco-vmx24.sh
# the plates whose spiral helices run below both v²/r limits (F508 mm/min): where a spiral block's
# own extra time shows alone in the helix table
BELOW_LIMIT = (12,)
FIT_PARAMS = ["axes.x.max_velocity", "axes.y.max_velocity", "axes.x.max_acceleration", "axes.y.max_acceleration",
              "axes.z.max_acceleration", "controller.bell_time"]


def main(realdata: Path) -> None:
    import mtwin
    from mtwin.effects import get
    from mtwin.loop import timing as T
    from mtwin.loop.asrun import feed_line_ends
    from mtwin.loop.blocks import line_starts, measurement_block_timing
    from mtwin.loop.compare import compare
    from mtwin.loop.measurement import read_measurement

    hurco = realdata / "nist_smstestbed_mtc_hurco"
    program = {p: str(hurco / "NC-Code" / f"NIST_MTC_CRADA_PLATE-{p}.NC") for p in PLATES}
    logs = {p: read_measurement(str(hurco / "Split" / f"Plate-Op1-Hurco04-{p}of20.txt")) for p in PLATES}
    default, profile = mtwin.Twin(), mtwin.Twin.from_toml(str(PROFILE))
    rows, kinds, traces = [], {}, {}
    t0 = time.time()
    for p in PLATES:
        nc, meas = program[p], logs[p]
        row = {"plate": p, "began": _log_start(hurco / "Split" / f"Plate-Op1-Hurco04-{p}of20.txt")}
        for name, tw in (("default", default), ("profile", profile)):
            prog = tw.load(nc)
            tr = tw.simulate(prog)
            case = T.timing_case(tw, prog, meas)
            if name == "default":
                row["measured"] = case.cycle_measured
                row["estimate"] = float(tr.summary.per_line.nominal.sum())
            row[name] = tr.summary.cycle_time
            b = measurement_block_timing(prog, meas, tr)
            row[f"{name}_block_rms"] = float(np.sqrt(np.mean(b.error_as_logged ** 2)))
            row[f"{name}_window_rms"] = T.summary(tw, [case])["window_rms"]
            kinds[(p, name)] = {k["kind"]: k["error_as_logged"] for k in b.by_kind()}
            if name == "profile":
                row["bias"] = max(abs(v) for v in b.bias.values()) if b.bias else 0.0
                kn, _, noise = T._kind_sums(case.groups)
                row["kind_noise"] = dict(zip(kn, (float(x) for x in noise)))
                seen, sim = (line_starts(np.asarray(x.t), np.asarray(x.line)) for x in (meas, tr))
                row["helices"] = _helices(prog, seen, tw.machine.controller.spiral_min)
                row["rapids"] = _rapid_sequences(prog, seen, sim)
                row["sequences_by_tool"] = _sequences_by_tool(prog, seen, sim)
                row["sequence_parts"] = _sequence_parts(prog, seen, sim)
                # the same without the profile's wait before cutting
                nowait = tw.replace(effects=[e.with_values(rapid_feed=0.0) if e.name == "feed-rapid-wait" else e
                                             for e in tw.effects])
                tn = nowait.simulate(prog, cutting=False)
                row["sequence_parts_bare"] = _sequence_parts(prog, seen, line_starts(np.asarray(tn.t),
                                                                                     np.asarray(tn.line)))
                row["rapid_feed_wait"] = tw.planned_machine.controller.rapid_feed_wait
                row["corners"] = _corner_feed(prog, meas, tr, tw.planned_machine.controller.arc_acceleration)
                row["sequence_times"] = _sequence_times(prog, seen)
                row["stands"] = _spindle_stands(prog, seen, sim)
                row["passes"] = _passes(prog, seen, sim)
                row["pass_ends"] = _pass_ends(prog, seen, sim)
                # feed lines' ends, timed against logs of the twin's own run, with its wait before a
                # rapid (the profile's feed-rapid-wait) and without it
                row["feed_ends"] = feed_line_ends(prog, meas, tr)
                bare = tw.replace(effects=[e.with_values(time=0.0) if e.name == "feed-rapid-wait" else e
                                           for e in tw.effects])
                row["feed_ends_bare"] = feed_line_ends(prog, meas, bare.simulate(prog, cutting=False))
                row["reversals"] = _reversals(prog, seen, sim)
                # the retract at the program's end (the last G28 line): the twin's time against the log's
                text = prog.data.split(b"\n")
                end = max(i for i, t in enumerate(text, 1) if b"G28" in t.upper() and i in seen and i + 1 in seen)
                row["end_retract"] = (seen[end + 1] - seen[end], sim[end + 1] - sim[end])
                # the same twin without its stops at reversals
                blend = tw.with_params({"controller.stop_angle": 0.0})
                tb = blend.simulate(blend.load(nc))
                row["reversals_blended"] = _reversals(prog, seen, line_starts(np.asarray(tb.t), np.asarray(tb.line)))
                # the longest pass (the contour with 6.5-mm corner arcs whose end points are 0.3-2.2 µm
                # off their circles), and the same twin running those arcs as spirals
                longest = max(_pass_list(prog, seen, sim), key=lambda x: x[2])
                row["contour"] = (longest[5], longest[3], longest[4], _as_spirals(tw, nc, seen, longest[0]))
            row[f"{name}_feed_nrmse"] = compare(tr, meas, "auto").signals["feed"]["nrmse"]
            traces[(p, name)] = tr
        rows.append(row)
    # leave one out: the profile's recipe, step by step as the script runs it, on the two other plates
    base = mtwin.Twin.from_toml(str(START))
    cases = {p: T.timing_case(base, base.load(program[p]), logs[p], f"plate {p}") for p in PLATES}
    for row in rows:
        p = row["plate"]
        fr = T.fit_timing_steps(base, [cases[q] for q in PLATES if q != p], [get(n)() for n in RECIPE], FIT_PARAMS)
        normal_time = fr.params["effects.spiral-acceleration.normal_time"]  # s per m/s²: the inverse of the jerk
        row["loo_spiral_jerk"] = 1000.0 / normal_time if normal_time > 0 else 0.0
        fitted_base = base.with_params({k: v for k, v in fr.params.items() if not k.startswith("effects.")})
        tw = fitted_base.with_effects(*fr.effects)
        prog = tw.load(program[p])
        tr = tw.simulate(prog)
        row["loo"] = tr.summary.cycle_time
        b = measurement_block_timing(prog, logs[p], tr)
        kinds[(p, "loo")] = {k["kind"]: k["error_as_logged"] for k in b.by_kind()}
        # limits the two training plates never reach (set at the least they allow): the held-out
        # plate's small arcs at that value and at the one the search had left
        row["unreached"] = []
        for key, u in fr.unreached.items():
            name, param = key.split(".")[1:]
            left = fitted_base.with_effects(*[e.with_values(**{param: u["fitted"]}) if e.name == name else e
                                              for e in fr.effects])
            bl = measurement_block_timing(prog, logs[p], left.simulate(prog))
            row["unreached"].append((name, u["least"], u["fitted"], kinds[(p, "loo")].get("small arc", 0.0),
                                     {k["kind"]: k["error_as_logged"] for k in bl.by_kind()}.get("small arc", 0.0)))
    elapsed = time.time() - t0
    _figure(logs[13], traces, ROOT / "docs" / "validation-plate13.svg")
    (ROOT / "docs" / "validation.md").write_text(_markdown(rows, kinds, elapsed), encoding="utf-8")
    print(f"wrote docs/validation.md and docs/validation-plate13.svg in {elapsed:.0f} s", file=sys.stderr)


def _half_circle(radius: float) -> float:
    """mm along one of the plates' helical half circles (0.0075 in down per half turn)."""
    return float(np.hypot(np.pi * radius, 0.0075 * 25.4))


def _both_ways(helices: list) -> dict:
    """{(radius mm, F mm/s): {spiral: [logged speeds]}} of :func:`_helices`' runs, for the radii and
    feeds that run both as spirals and as true circles."""
    by: dict = {}
    for rad, spiral, f, v in helices:
        by.setdefault((round(rad, 2), round(f, 2)), {}).setdefault(spiral, []).append(v)
    return {k: d for k, d in sorted(by.items()) if True in d and False in d}


def _spiral_extra(radius: float, speeds: dict) -> float:
    """s a spiral half circle takes beyond the same half circle drawn true (median speeds)."""
    return _half_circle(radius) / np.median(speeds[True]) - _half_circle(radius) / np.median(speeds[False])


def _jerk_ms(jerk: float, a_n: float) -> float:
    """ms a spiral block takes beyond its path at normal acceleration ``a_n`` (mm/s²)."""
    return a_n / jerk * 1000.0 if jerk > 0 else 0.0


def _spiral_block_time(helices: list) -> float:
    """s a spiral half circle takes beyond the same half circle drawn true, mean over the radii
    that run both ways."""
    extra = [_spiral_extra(rad, d) for (rad, _), d in _both_ways(helices).items()]
    return float(np.mean(extra)) if extra else 0.0


def _as_spirals(tw, nc: str, seen: dict, first: int) -> float:
    """The error (s) of the pass starting at line ``first`` when every arc off its circle by
    more than 0.1 µm is run as a spiral (the spiral threshold before it was measured)."""
    from mtwin.loop.blocks import line_starts

    tw = tw.with_params({"controller.spiral_min": 1e-4})
    prog = tw.load(nc)
    tr = tw.simulate(prog)
    sim = line_starts(np.asarray(tr.t), np.asarray(tr.line))
    return next(x[4] for x in _pass_list(prog, seen, sim) if x[0] == first)


def _helices(prog, seen: dict, spiral_min: float, least: int = 20) -> list:
    """Runs of at least ``least`` consecutive helical half circles of one radius and feed: (radius
    mm, spiral, F mm/s, logged speed mm/s) — the speed the path length over the time from the
    first report (``seen``: line -> s) of the run's first line to the first report of the line
    after it.  A spiral has its end point off the circle (|end radius − start radius| >
    ``spiral_min``, the twin's controller.spiral_min)."""
    from mtwin.gcode import records as R

    rec = prog.records
    reported = np.array(sorted(seen), np.int64)

    def first_report(ln):
        k = int(np.searchsorted(reported, ln))
        return seen[int(reported[k])] if k < len(reported) else np.nan

    arc = ((rec["kind"] == R.ARC_CW) | (rec["kind"] == R.ARC_CCW)) & (np.abs(rec["z"] - rec["sz"]) > 1e-6)
    r0 = np.hypot(rec["sx"] - rec["cx"], rec["sy"] - rec["cy"])
    r1 = np.hypot(rec["x"] - rec["cx"], rec["y"] - rec["cy"])
    key = np.where(arc, np.round(np.minimum(r0, r1), 2) * 1e4 + np.round(rec["feed"]), -1.0)
    out, i = [], 0
    while i < len(rec):
        j = i
        while j + 1 < len(rec) and key[j + 1] == key[i] and rec["line"][j + 1] == rec["line"][j] + 1:
            j += 1
        if key[i] >= 0 and j - i + 1 >= least:
            run = rec[i:j + 1]
            dt = first_report(int(run["line"][-1]) + 1) - first_report(int(run["line"][0]))
            out.append((float(np.median(np.minimum(r0, r1)[i:j + 1])),
                        bool(np.median(np.abs(r1 - r0)[i:j + 1]) > spiral_min), float(run["feed"][0]) / 60.0,
                        float(R.move_lengths(run).sum()) / dt))
        i = j + 1
    return out


def _spindle_stands(prog, seen: dict, sim: dict) -> dict:
    """Per spindle speed and way ("stop": braking from it, "start": running up to it): (count,
    mean logged, mean simulated s) of the line the control stands at while the spindle changes
    speed — the M01 before a tool change (timed from its report to the next line's), and the
    block after the one that starts the spindle (G0 X Y S M3, then Z.25 M8: the stand and the Z
    approach, to the next line's report)."""
    import re

    text = [t.split(b"(")[0].upper().replace(b" ", b"") for t in prog.data.split(b"\n")]
    rec = prog.records
    out: dict = {}

    def speed_at(line: int) -> float:  # the commanded speed of the last record before the line
        i = int(np.searchsorted(rec["line"], line)) - 1
        return float(rec["spindle"][i]) if i >= 0 else 0.0

    for ln, code in enumerate(text, 1):
        if re.search(rb"M0?1(?!\d)", code) and ln + 1 < len(text) and b"M6" in text[ln]:
            key, stand = ("stop", speed_at(ln)), ln
        elif re.search(rb"M0?3(?!\d)", code) and b"S" in code:
            key, stand = ("start", float(re.search(rb"S([\d.]+)", code).group(1))), ln + 1
        else:
            continue
        if all(x in d for x in (stand, stand + 1) for d in (seen, sim)):
            out.setdefault(key, []).append((seen[stand + 1] - seen[stand], sim[stand + 1] - sim[stand]))
    return {k: (len(v), float(np.mean([a for a, _ in v])), float(np.mean([b for _, b in v])))
            for k, v in sorted(out.items())}


def _sequence_starts(prog, seen: dict, sim: dict) -> list:
    """The first line of every retract-reposition-approach reported on both ``seen`` and ``sim``
    (line -> s): three rapid lines without M words between a feed move and the next one."""
    from mtwin.gcode import records as R
    from mtwin.loop.asrun import CANNED, line_kinds

    text = prog.data.split(b"\n")
    kinds = line_kinds(prog.records)
    out = []
    for a in sorted(kinds):
        rapid = all(kinds.get(a + i) == {R.RAPID} and b"M" not in text[a + i - 1].upper() for i in range(3))
        after = kinds.get(a + 3, {R.RAPID})
        if rapid and R.RAPID not in after and CANNED not in after and all(x in d for x in (a, a + 3)
                                                                              for d in (seen, sim)):
            out.append(a)
    return out


def _rapid_sequences(prog, seen: dict, sim: dict) -> tuple:
    """(sequences, summed error s, sd per sequence s) of every retract-reposition-approach, timed
    from the first report (``seen``, and ``sim`` for the twin: line -> s) of the first rapid to
    that of the feed line after them (two report delays, whose expectations cancel over many
    sequences: no group cutting or kind involved)."""
    err = list(_sequence_errors(prog, seen, sim).values())
    return len(err), float(np.sum(err)), float(np.std(err)) if err else 0.0


def _sequence_errors(prog, seen: dict, sim: dict) -> dict:
    """First line -> simulated − logged s of each retract-reposition-approach, from the first
    report of its first rapid to that of the feed line after them."""
    return {a: (sim[a + 3] - sim[a]) - (seen[a + 3] - seen[a]) for a in _sequence_starts(prog, seen, sim)}


def _sequence_parts(prog, seen: dict, sim: dict) -> list:
    """[(sequences, logged mean s, twin mean s)] of each of the retract-reposition-approach's
    three lines — the retract from its first report to the reposition's, the reposition to the
    approach's, the approach to the feed line's first report — over the sequences whose log
    reports both ends of that line."""
    out = []
    for k in range(3):
        pairs = [(seen[a + k + 1] - seen[a + k], sim[a + k + 1] - sim[a + k]) for a in _sequence_starts(prog, seen, sim)
                 if all(x in d for x in (a + k, a + k + 1) for d in (seen, sim))]
        out.append((len(pairs), float(np.mean([m for m, _ in pairs])), float(np.mean([t for _, t in pairs]))))
    return out


def _sequences_by_tool(prog, seen: dict, sim: dict, least: int = 20) -> dict:
    """{tool: (sequences, mean error ms, its standard error ms, F mm/min)} of the
    retract-reposition-approach sequences of each tool that runs at least ``least`` of them, timed as
    :func:`_rapid_sequences` does; F is the most common of the feed lines' that end them."""
    rec = prog.records
    out: dict = {}
    for a, err in _sequence_errors(prog, seen, sim).items():
        first = np.flatnonzero(rec["line"] == a + 3)
        if not first.size:
            continue
        i = int(first[0])
        out.setdefault(int(rec["tool"][i]), []).append((err, int(round(float(rec["feed"][i])))))
    res = {}
    for tool, v in sorted(out.items()):
        if len(v) >= least:
            e = np.array([x for x, _ in v])
            feeds, counts = np.unique([f for _, f in v], return_counts=True)
            res[tool] = (len(v), float(e.mean() * 1000), float(e.std(ddof=1) / np.sqrt(len(e)) * 1000),
                         int(feeds[np.argmax(counts)]))
    return res


def _corner_feed(prog, meas, trace, arc_limit: float, least_radius: float = 5.0):
    """The logged feed on the arcs of at least ``least_radius`` mm whose F the arc limit holds
    back (F²/r above ``arc_limit``): (arcs, radius mm, F mm/min, the log's median and 90th
    percentile of its feed samples labelled with their lines, the same of logs of the twin's own
    run sampled as it, mm/min), or None where there are none."""
    from mtwin.gcode import records as R
    from mtwin.loop.asrun import TWIN_LOGS, twin_log

    rec = prog.records
    r = np.hypot(rec["sx"] - rec["cx"], rec["sy"] - rec["cy"])
    v = rec["feed"] / 60.0
    on = (np.isin(rec["kind"], [R.ARC_CW, R.ARC_CCW]) & (r >= least_radius)
          & (v * v / np.maximum(r, 1e-9) > arc_limit))
    if not on.any() or "feed" not in meas.signals:
        return None
    lines = np.unique(rec["line"][on])

    def stats(m):
        f = np.asarray(m.signals["feed"], float)[np.isin(np.asarray(m.line), lines)]
        return (float(np.median(f)), float(np.percentile(f, 90))) if f.size else (np.nan, np.nan)

    own = [stats(x) for x in (twin_log(trace, meas, seed) for seed in range(TWIN_LOGS)) if x is not None]
    return (len(lines), float(np.median(r[on])), float(np.median(rec["feed"][on])), *stats(meas),
            *np.mean(own, axis=0).tolist())


def _sequence_times(prog, seen: dict) -> dict:
    """First line -> logged s of each retract-reposition-approach: the plates run the same
    sequences (the same lines), compared pairwise."""
    return {a: seen[a + 3] - seen[a] for a in _sequence_starts(prog, seen, seen)}


def _pass_list(prog, seen: dict, sim: dict) -> list:
    """(first line, F mm/min, path mm, measured s, error s, highest F mm/min, the rapid's line after
    it) of every cutting pass — consecutive
    feed lines (no drilling cycle) between two rapids — timed from the first report (``seen``,
    ``sim``) of its first line to that of the rapid after it; F is the pass's first line's."""
    from mtwin.gcode import records as R
    from mtwin.loop.asrun import CANNED, line_kinds

    rec = prog.records
    kinds = line_kinds(rec)
    lengths = R.move_lengths(rec)
    lines = sorted(kinds)
    out = []
    i = 0
    while i < len(lines):
        if R.RAPID in kinds[lines[i]] or CANNED in kinds[lines[i]]:
            i += 1
            continue
        j = i
        while (j + 1 < len(lines) and lines[j + 1] == lines[j] + 1 and R.RAPID not in kinds[lines[j + 1]]
               and CANNED not in kinds[lines[j + 1]]):
            j += 1
        a, b = lines[i], lines[j] + 1
        if all(x in d for x in (a, b) for d in (seen, sim)):
            on = (rec["line"] >= a) & (rec["line"] < b)
            out.append((a, int(round(float(rec["feed"][rec["line"] == a].max()))), float(lengths[on].sum()),
                        seen[b] - seen[a], (sim[b] - sim[a]) - (seen[b] - seen[a]),
                        int(round(float(rec["feed"][on].max()))), b))
        i = j + 1
    return out


def _passes(prog, seen: dict, sim: dict) -> dict:
    """{F mm/min: (passes, measured s, error s)} of the cutting passes (:func:`_pass_list`),
    grouped by the feed of the pass's first line."""
    out: dict = {}
    for _, f, _, m, e, *_ in _pass_list(prog, seen, sim):
        n, mm, ee = out.get(f, (0, 0.0, 0.0))
        out[f] = (n + 1, mm + m, ee + e)
    return out


def _pass_ends(prog, seen: dict, sim: dict) -> tuple:
    """(F mm/min, passes, mean error s and its standard error at the pass's start, the same at its
    end) over the cutting passes at the plate's most common pass feed: the error of the span from
    the first report of the pass's first line to that of the next reported line, and of the span
    from the last reported line of the pass to the first report of the rapid after it."""
    passes = _pass_list(prog, seen, sim)
    common = max(_passes(prog, seen, sim).items(), key=lambda kv: kv[1][0])[0]
    head, tail = [], []
    for a, f, *_, rapid in passes:
        lines = [ln for ln in range(a, rapid + 1) if ln in seen and ln in sim]
        if f != common or len(lines) < 3:
            continue
        err = lambda x, y: (sim[y] - sim[x]) - (seen[y] - seen[x])
        head.append(err(lines[0], lines[1]))
        tail.append(err(lines[-2], lines[-1]))
    se = lambda v: float(np.std(v, ddof=1) / np.sqrt(len(v))) if len(v) > 1 else float("nan")
    return common, len(head), float(np.mean(head)), se(head), float(np.mean(tail)), se(tail)


def _feed_ends_text(rows, key: str) -> str:
    """'plate 12 -55 ± 10 ms (65), …' for the feed ends ``key`` of each plate."""
    out = []
    for r in rows:
        parts = []
        for (last, nxt), (n, m, se) in r[key].items():
            parts.append(f"{last} → {nxt} {m * 1000:+.0f} ± {se * 1000:.0f} ms ({n})")
        out.append(f"plate {r['plate']}: " + ", ".join(parts))
    return "; ".join(out)


def _reversals(prog, seen: dict, sim: dict, turn: float = 120.0) -> dict:
    """{F mm/min: (lines, mean measured − nominal s, mean simulated − nominal s)} of the straight
    feed lines that begin and end at a turn sharper than ``turn`` degrees (the plates' zig-zags),
    each timed from its first report to the next line's (nominal: length over F)."""
    from mtwin.gcode import records as R

    rec = prog.records
    d = np.stack([rec["x"] - rec["sx"], rec["y"] - rec["sy"], rec["z"] - rec["sz"]], axis=1)
    u = d / np.maximum(np.linalg.norm(d, axis=1), 1e-12)[:, None]
    cos = np.einsum("ij,ij->i", u[:-1], u[1:])
    line = rec["kind"] == R.LINEAR
    sharp = line[:-1] & line[1:] & (cos < np.cos(np.radians(turn)))
    lengths = R.move_lengths(rec)
    out: dict = {}
    for i in np.flatnonzero(sharp[:-1] & sharp[1:]) + 1:
        ln = int(rec["line"][i])
        if rec["line"][i - 1] == ln or rec["line"][i + 1] == ln or not all(x in s for x in (ln, ln + 1)
                                                                           for s in (seen, sim)):
            continue
        nominal = float(lengths[i]) / float(rec["feed"][i]) * 60.0
        out.setdefault(int(round(float(rec["feed"][i]))), []).append(
            (seen[ln + 1] - seen[ln] - nominal, sim[ln + 1] - sim[ln] - nominal))
    return {f: (len(v), float(np.mean([a for a, _ in v])), float(np.mean([b for _, b in v]))) for f, v in out.items()}


def _tool_pairs(rows) -> str:
    """Per tool that every plate runs 20 sequences or more with, the measured difference of its
    sequences between each two plates (the difference of the twin's errors, the twin timing the
    same lines alike on every plate), ms a sequence."""
    out = []
    for t in sorted(set.intersection(*(set(r["sequences_by_tool"]) for r in rows))):
        pairs = []
        for i in range(len(rows)):
            for j in range(i + 1, len(rows)):
                a, b = rows[i]["sequences_by_tool"][t], rows[j]["sequences_by_tool"][t]
                pairs.append(f"{rows[i]['plate']} − {rows[j]['plate']} {b[1] - a[1]:+.0f} ± {np.hypot(a[2], b[2]):.0f}")
        out.append(f"tool {t}: " + ", ".join(pairs) + " ms")
    return "; ".join(out)


def _log_start(path: Path) -> tuple:
    """The log's first timestamp: (its date, its time to the minute, UTC)."""
    with open(path, encoding="utf-8", errors="replace") as f:
        ts = f.readline().split("|", 1)[0]
    return ts[:10], ts[11:16]


def _starts(rows) -> str:
    """When the logs began ("17:58, 18:26 and 19:03 UTC on 2017-02-02")."""
    days = dict.fromkeys(d for d, _ in (r["began"] for r in rows))
    times = [hm if len(days) == 1 else f"{d} {hm}" for d, hm in (r["began"] for r in rows)]
    return (", ".join(times[:-1]) + " and " + times[-1] + " UTC"
            + (f" on {next(iter(days))}" if len(days) == 1 else ""))


def _paired_sequences(rows) -> str:
    """The logged times of the retract-reposition-approach sequences every plate reports,
    per plate and as paired differences with their standard errors."""
    common = sorted(set.intersection(*(set(r["sequence_times"]) for r in rows)))
    t = np.array([[r["sequence_times"][a] for a in common] for r in rows])
    mean = " / ".join(f"{m:.3f}" for m in t.mean(axis=1))
    pairs = []
    for i in range(len(rows)):
        for j in range(i + 1, len(rows)):
            d = t[i] - t[j]
            se = d.std(ddof=1) / np.sqrt(len(d))
            pairs.append(f"plate {rows[i]['plate']} − plate {rows[j]['plate']} {d.mean() * 1000:+.0f} ± "
                         f"{se * 1000:.0f} ms ({d.sum():+.1f} ± {se * len(d):.1f} s over the {len(d)})")
    return (f"the {len(common)} that every log reports took {mean} s on average (plates "
            + " / ".join(str(r["plate"]) for r in rows) + "); paired, sequence by sequence: " + ", ".join(pairs))


def _pct(sim, meas):
    return f"{(sim - meas) / meas:+.2%}"


def _markdown(rows, kinds, elapsed) -> str:
    import mtwin
    from mtwin.loop.blocks import LOG_SEEDS
    from mtwin.loop.journal import read_journal

    m = mtwin.Twin.from_toml(str(PROFILE)).planned_machine
    acc_xy, acc_rapid = m.axes[0].max_acceleration, m.controller.rapid_acceleration

    out = [
        "# Validation: the twin against a real machine (Hurco VMX24, NIST test bed)",
        "",
        f"Generated by `python scripts/validation.py` on {dt.date.today().isoformat()} (mtwin {mtwin.__version__}, "
        f"{elapsed:.0f} s); do not edit by hand.  Data: the NIST smart-manufacturing test bed's MTConnect logs of a "
        "Hurco VMX24 running plates 12, 13 and 14 of its CRADA study (`../shared/realdata/nist_smstestbed_mtc_hurco`, "
        "not part of this repository).  The profile is `samples/machines/hurco-vmx24.toml`, made by "
        "`bash scripts/hurco-vmx24.sh` (`mtwin calibrate` on all three plates' block times).",
        "",
        "## Cycle time",
        "",
        "Simulated minus measured, relative to measured.  *Length/feed*: path length over F, rapids at the default "
        "machine's speed along the move, tool changes and spindle waits free.  *Leave-one-out*: the profile's recipe "
        "(same effects and parameters, fitted step by step as scripts/hurco-vmx24.sh does: `fit_timing_steps`) "
        "calibrated on the two other plates only, predicting this one.  The values the recipe sets by hand — the "
        "in-position width, the stop angle, the spiral threshold, the spindle's overlap with motion, the Z work "
        "offset — were chosen looking at all three plates.",
        "",
        "| plate | measured s | length/feed | default twin | calibrated profile | leave-one-out |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        out.append(f"| {r['plate']} | {r['measured']:.1f} | {_pct(r['estimate'], r['measured'])} | "
                   f"{_pct(r['default'], r['measured'])} | {_pct(r['profile'], r['measured'])} | "
                   f"{_pct(r['loo'], r['measured'])} |")
    out += ["", "## Per-block timing", "",
            "A block group is a logged line and the unlogged lines after it (the control reports the executing line "
            "every 0.15–0.2 s); the same code run twice differs by about 0.15 s per group (the noise floor).  "
            "*Windows*: consecutive groups summed to ≈ 10 s — what the calibration fits (a window's measured length "
            "carries only its two ends' report jitter, ≈ 0.21 s).",
            "",
            "| plate | group RMS as logged, default → profile s | window RMS default → profile s | feed NRMSE default → profile |",
            "|---|---:|---:|---:|"]
    for r in rows:
        out.append(f"| {r['plate']} | {r['default_block_rms']:.3f} → {r['profile_block_rms']:.3f} | "
                   f"{r['default_window_rms']:.2f} → {r['profile_window_rms']:.2f} | "
                   f"{r['default_feed_nrmse']:.1%} → {r['profile_feed_nrmse']:.1%} |")
    all_kinds = sorted({k for v in kinds.values() for k in v if k != "program end"},
                       key=lambda k: -abs(kinds[(13, "default")].get(k, 0)))
    worst = {name: max(abs(kinds[(r["plate"], name)].get(k, 0)) for r in rows for k in all_kinds)
             for name in ("default", "profile", "loo")}
    out += ["", "Error summed by block kind, s (simulated as logged − measured; `mtwin compare`'s *as logged* "
            "column): default twin → calibrated profile → leave-one-out.  *As logged*: the log reports a line at "
            "the first sample after it starts, so a short group's measured time takes some of the next group's, of "
            "another kind; the simulation's group boundaries are shifted by the delays the log would have had "
            "(half the shorter of the line and the sampling interval, read off the log: 0.18 s), which leaves the "
            "cycle time as it is; less the logging's bias (below).  Largest |error| of any kind on any plate: "
            f"{worst['default']:.1f} s default, {worst['profile']:.1f} s profile, {worst['loo']:.1f} s leave-one-out "
            "(the target is 2 s).", "",
            "| kind | " + " | ".join(f"plate {r['plate']}" for r in rows) + " |",
            "|---|" + "---:|" * len(rows)]
    for k in all_kinds:
        out.append(f"| {k} | " + " | ".join(f"{kinds[(r['plate'], 'default')].get(k, 0):+.1f} → "
                                            f"{kinds[(r['plate'], 'profile')].get(k, 0):+.1f} → "
                                            f"{kinds[(r['plate'], 'loo')].get(k, 0):+.1f}" for r in rows) + " |")
    out += ["", "The as-logged sums take off what logs of the twin's own run show by kind (`logging_bias`: the run "
            f"logged {LOG_SEEDS} times at the log's interval and spread, cut into groups and classified as the real log "
            "is): which lines a log reports decides how its groups are cut and which kind each takes, a bias the "
            "delays alone leave.  Largest such bias of any kind with the profile: "
            + ", ".join(f"plate {r['plate']} {r['bias']:.1f} s" for r in rows) + ".  Its spread between logs is the "
            "sums' own sampling noise (0.05–1.4 s by kind on these plates).  The real log is one such log: its "
            "report jitter (uniform over one interval) at both ends of every run of groups of a kind leaves each "
            "kind's measured sum uncertain by, s (σ; the same on the three plates within 0.07 s): "
            + ", ".join(f"{k} {v:.1f}" for k, v in rows[0]["kind_noise"].items())
            + ", against which a 2-s target is judged.",
            "", "## Spiral arcs against true circles", "",
            "The plates enter their pockets on helices of half circles.  The CAM rounds their centres to 0.0001 in: "
            "where the two ends of a half circle lie symmetric about its centre the arc is a true circle, elsewhere "
            "its end point is 2.5 µm off the circle and the control runs a spiral.  The same tool, radius and feed "
            "run both ways on each plate.  Logged speed over runs of at least 20 half circles (path length over the "
            "time from the first report of the run's first line to that of the line after it), and v²/r:",
            "", "| plate | F mm/s | radius mm | true circles: speed, v²/r | spirals: speed, v²/r | spiral − circle, per "
            "half circle |", "|---|---:|---:|---|---|---:|"]
    for r in rows:
        for (rad, f), d in _both_ways(r["helices"]).items():
            cells = [f"{np.median(d[s]):.1f} mm/s, {np.median(d[s]) ** 2 / rad:.0f} mm/s² ({len(d[s])} runs)"
                     for s in (False, True)]
            out.append(f"| {r['plate']} | {f:.1f} | {rad:.2f} | {cells[0]} | {cells[1]} | "
                       f"{_spiral_extra(rad, d) * 1000:.1f} ms |")
    out += ["", "Where the feed is above what either allows (plate 13) spirals run at 15–22 % less v²/r than true circles.  The "
            f"profile runs true circles at {m.controller.arc_acceleration:.0f} mm/s² (`arc-acceleration`, set apart "
            f"from the axes' {acc_xy:.0f} along the path, as Fanuc's parameter 1735 is from 1660) and spirals at "
            f"{m.controller.spiral_acceleration:.0f} mm/s² (`spiral-acceleration`), each spiral block longer "
            "besides by its v²/r over a jerk (below).",
            "", "## Arcs a hair off their circle", "",
            "Plates 13 and 14 cut the part's outside in one long pass (2.7 m: long lines joined by 6.5-mm corner arcs, "
            "54 of them).  Rounding both the end points and the centres leaves those arcs' end points 0.3–2.2 µm off "
            "their circles, where the helices' spirals are off by one 0.0001-in increment (2.54 µm).  Timed report to "
            "report over the pass (simulated − measured):", "",
            "| plate | F mm/min (its lines and arcs) | measured s | profile | the same, these arcs as spirals |", "|---|---:|---:|---:|---:|"]
    for r in rows:
        if r["plate"] in (13, 14):
            f, meas, e, e_spiral = r["contour"]
            out.append(f"| {r['plate']} | {f} | {meas:.1f} | {e:+.2f} s | {e_spiral:+.2f} s |")
    corner = [(r["plate"], r["corners"]) for r in rows if r.get("corners")]
    out += ["", "So an arc counts as a spiral only from 2.3 µm off its circle (`controller.spiral_min`).  The "
            "profile runs these arcs at its circles' limit, v²/r = "
            f"{m.controller.arc_acceleration:.0f} mm/s², above the path acceleration the short moves fit "
            f"({acc_xy:.0f}): the arc limit is the control's own, not a share of the axes'.  But the machine takes "
            "them faster still, where its small true circles run slower (plate 13's in the table above: 354–366 "
            "mm/s²): "
            + "; ".join(f"plate {p}'s {c[0]} arcs of {c[1]:.1f} mm held back at F{c[2]:.0f} log a median feed of "
                        f"{c[3]:.0f} mm/min ({(c[3] / 60) ** 2 / c[1]:.0f} mm/s²), a 90th percentile of {c[4]:.0f}, "
                        f"where logs of the twin's own run, labelled alike, give {c[5]:.0f} and {c[6]:.0f}"
                        for p, c in corner)
            + ": the control's limit on v²/r is not one value, and the profile's is a compromise between these "
            "corners and the small circles, which only plate 13 shows both of.",
            "", "## Reversals", "",
            "The plates' zig-zag passes turn by 150–170° at the end of every 6–7-mm line.  Mean time of such a line "
            "(from its first report to the next line's) beyond its length over F:", "",
            "| plate | F mm/min | lines | measured | profile (a stop at turns over 120°) | profile, blending them |",
            "|---|---:|---:|---:|---:|---:|"]
    for r in rows:
        for f, (n, meas, sim) in sorted(r["reversals"].items()):
            out.append(f"| {r['plate']} | {f} | {n} | {meas:+.3f} s | {sim:+.3f} s | "
                       f"{r['reversals_blended'][f][2]:+.3f} s |")
    out += ["", "The machine loses about the same at every feed, as a full stop does (the ramps' jerk time "
            "dominates); blending with an allowable velocity change per axis loses less, and more as the feed "
            "rises.  The profile stops at turns sharper than 120° (`controller.stop_angle`, set by hand: the "
            "plates' other corners turn by 90–100°, none by 100–150°).",
            "", "## The calibration, step by step (the profile's journal)", "",
            "| step | effects | window RMS s | cycle time, plates 12 / 13 / 14 |", "|---|---|---:|---|"]
    for e in read_journal(str(PROFILE)):
        b, a = e.get("cycle_error_before", {}), e.get("cycle_error_after", {})
        out.append(f"| {e['iteration']} | {', '.join(e['effects'])} | {e['rms_before']['window_time']:.2f} → "
                   f"{e['rms_after']['window_time']:.2f} | "
                   + " / ".join(f"{b[k]:+.1%} → {a[k]:+.1%}" for k in b) + " |")
    out += ["", "## Measured against simulated feed, plate 13", "", "![feed](validation-plate13.svg)", "",
            "## What is not modelled", "",
            "- The programs' work offsets are unknown.  The profile sets G54 Z at -411 mm by hand, so that the G28 "
            "retracts and the approaches after a tool change have about the length their 2.0–2.8 s at the logged "
            "rapid rate give; X and Y are left at 0.  After each tool change the block G0 X Y S M3 takes 1.4–2.1 s on "
            "the log whatever its programmed length (19–166 mm, 0.2–1.1 s in the twin): the machine comes from a "
            "tool-change position the programs do not give.  That time sits inside `toolchange-time` (its fitted "
            "extra makes a change longer than the 5.8–6.4 s the M6 line stands on the log) and shortens the run-up "
            "the twin leaves for the next block (below).",
            "- The rapid rate of Z is not in the logs (no long Z rapid) and is set equal to X's and Y's.",
            "- No override or feed-hold item appears in these logs: 100 % overrides are assumed.",
            f"- The fitted X and Y accelerations (≈ {acc_xy / 1000:.2f} and {m.axes[1].max_acceleration / 1000:.2f} "
            "m/s²; fitted without a wait before cutting — the `rapid_feed` below — Y came out at about twice X, 0.48 "
            "against 0.25, taking up the approaches' missing time) are the control's effective path "
            "acceleration on these programs' short feed moves, not a drive's capability; rapids run on their own "
            f"(`rapid-acceleration`, ≈ {acc_rapid / 1000:.1f} m/s²), as a Fanuc-style control sets rapid and cutting "
            "acc/dec apart.  Before it was separate, "
            "rapids ran ≈ 21 s long per plate while small arcs and short lines ran 8–13 s short each, errors that "
            "cancelled in the cycle time; the calibration now also fits the error summed by block kind.",
            "- The spindle overlaps motion (`spindle.wait_for_stop = false`, `spindle.runup_overlap = true`, set "
            "by hand from the logs): after M5 the Hurco starts the G28 retract at once and stands at the M01 before "
            "the next tool change for the rest of the braking; it rapids to X/Y on the block that starts the spindle "
            "and stands at the next block (Z.25 M8) for the rest of the run-up.  The time it stands grows faster "
            "than the speed (logged Spindle_Speed reaches S9000 in ≈ 1.4 s and S12000 in ≈ 2.0 s, yet the control "
            "waits far longer at S12000): `spindle-runup`'s rates fall as power_speed/n above "
            f"{m.spindle.runup_power_speed:,.0f} rpm in the profile, and it brakes at a rate of its own "
            f"({m.spindle.braking:,.0f} rpm/s against {m.spindle.acceleration:,.0f} up: the control stands longer after "
            "M5 than after M3 at the same speed).  Logged against simulated stand, mean s (count; a start's stand "
            "is its next block, Z.25 M8, with that block's ≈ 2-s Z approach): "
            + "; ".join(f"plate {r['plate']}: " + ", ".join(f"{way} S{sp:g} {lg:.2f} / {sm:.2f} ({n})"
                                                           for (way, sp), (n, lg, sm) in r["stands"].items()
                                                           if sp >= 3000)
                        for r in rows)
            + ".  The run-up stands still run long, by about the XY block's missing second (above), which the "
            "run-up rate cannot take up without the braking stands; both are in the tool-change kind.  Plates 13 and "
            "14 alone (S750–S9000) now pin the power range: the leave-one-out prediction of plate 12's tool changes "
            f"(S12000) is {kinds[(12, 'loo')].get('tool change', 0):+.1f} s off.",
            "- Below the spiral limit, spirals still run 3–4 % under F where circles reach it (plate 12's helices "
            "in the table above, F508): "
            + ", ".join(f"{_spiral_block_time(r['helices']) * 1000:.1f} ms per half circle on plate {r['plate']}"
                        for r in rows if r["plate"] in BELOW_LIMIT)
            + ", which a limit on v²/r does not describe.  A constant time per spiral block describes plate 12 but "
            "not the others: where the limit binds it trades with the limit, and fitted with it on plates 13 and 14 "
            "(`fit=acceleration+block_time`) it comes out at 10.0 ± 1.8 ms, twice plate 12's.  The time grows with "
            "v²/r (≈ 190 mm/s² on plate 12's spirals, 260–300 on plates 13 and 14's), not with the speed alone: plate "
            "12's 1.7-mm spirals at F2032 log 23.0 mm/s (309 mm/s²), which 5–8 ms a block gives, where a time "
            "growing as v² from plate 12's helices would be 38 ms and 20 mm/s.  As if the control ramped the normal "
            "acceleration anew at every spiral block, at a jerk.  The profile's `spiral-acceleration` jerk is "
            f"{m.controller.spiral_jerk / 1000:.0f} m/s³ ({_jerk_ms(m.controller.spiral_jerk, 206.0):.1f} ms a block "
            f"at 206 mm/s², {_jerk_ms(m.controller.spiral_jerk, m.controller.spiral_acceleration):.1f} ms at the "
            "spiral limit), fitted with the limit; every plate's spirals below the limit show it, so the "
            "leave-one-out fits find it without the plate they predict: "
            + ", ".join(f"{r['loo_spiral_jerk'] / 1000:.0f} m/s³ predicting plate {r['plate']}" for r in rows)
            + ".  The small arcs, with the profile, are off by "
            + " / ".join(f"{kinds[(r['plate'], 'profile')].get('small arc', 0):+.1f}" for r in rows)
            + " s (plates " + " / ".join(str(r["plate"]) for r in rows) + ").",
            "- Limits the training plates never reach: "
            + ("; ".join(f"predicting plate {r['plate']}, no block of the two other plates reaches `{name}`'s limit "
                         f"(their residuals do not change above it): the fit sets it at {least:.0f} mm/s², the "
                         f"least they allow (the search had left it at {left:.0f}), and plate {r['plate']}'s small "
                         f"arcs are {e_least:+.1f} s off ({e_left:+.1f} s at the search's value)"
                         for r in rows for name, least, left, e_least, e_left in r["unreached"])
               or "none")
            + ".  Only a plate whose arcs run at the limit shows where it is: the profile's true-circle limit comes "
            "from plate 13 alone, the one plate whose true circles run at it (its F3658 contour's corners, its "
            "helices at F914; plate 14's, at F686, run at F, and plate 12's slower still).",
            "- Off by more than 2 s with the profile: "
            + ("; ".join(f"plate {r['plate']}: " + ", ".join(f"{k} {v:+.1f} s" for k, v in
                                                           kinds[(r["plate"], "profile")].items()
                                                           if abs(v) > 2.0 and k != "program end")
                         for r in rows if any(abs(v) > 2.0 for k, v in kinds[(r["plate"], "profile")].items()
                                              if k != "program end"))
               or "no kind on any plate")
            + ".  The retract at the program's end (M5, then G91 G28 Z0 M9), which the Hurco runs while the spindle "
            "brakes (it parks and completes the program once the spindle is down: 3.9 s after M30 from S12000, "
            "0.7 s from S9000; the park move's G58 offset is set by hand to its logged length): "
            + ", ".join(f"{sim_ - meas_:+.1f} s (plate {r['plate']}: {meas_:.1f} s logged)"
                        for r in rows for meas_, sim_ in [r["end_retract"]])
            + ".  The rapids themselves, timed from report to report over each retract–reposition–approach "
            "(three rapids between a feed move and the next, no groups or kinds involved): the profile is off by "
            + ", ".join(f"{r['rapids'][1]:+.1f} s over {r['rapids'][0]} sequences "
                        f"({r['rapids'][1] / r['rapids'][0] * 1000:+.0f} ms each, plate {r['plate']})" for r in rows)
            + f"; a sequence's sd is {max(r['rapids'][2] for r in rows):.2f} s, the two reports' jitter, so a sum "
            "over ~110 of them is good to about ±0.9 s.  Where a plate's rapids run long by more, that is most of "
            "its rapid kind's error.  The plates run the same sequences (the same lines, lengths and heights), "
            "which the twin times alike on all three; "
            + _paired_sequences(rows)
            + ": the machine ran plate 13's faster by about two of their standard errors, which nothing in the "
            "sequences themselves says.  The three logs begin at " + _starts(rows)
            + ": the plates were cut one after another the same day.  By tool (the tools that run 20 sequences "
            "or more; there the plates' programs differ only in S and F), the error per sequence, mean ± its standard error, at the F of the "
            "feed lines that end them: "
            + "; ".join(f"tool {t}: " + ", ".join(f"plate {r['plate']} F{r['sequences_by_tool'][t][3]} "
                                                  f"{r['sequences_by_tool'][t][1]:+.0f} ± "
                                                  f"{r['sequences_by_tool'][t][2]:.0f} ms"
                                                  f" ({r['sequences_by_tool'][t][0]})"
                                                  for r in rows if t in r["sequences_by_tool"])
                        for t in sorted(set.intersection(*(set(r["sequences_by_tool"]) for r in rows))))
            + ".  Split at its three lines' reports (the approach timed to the feed line's first report; logged / "
            "twin, mean s over the sequences whose log reports both ends of the line): "
            + "; ".join(f"plate {r['plate']}: " + ", ".join(f"{name} {m:.3f} / {t:.3f} ({n})" for name, (n, m, t) in
                                                          zip(("retract", "reposition", "approach"), r["sequence_parts"]))
                        for r in rows)
            + f".  Without a wait there the twin's approach — a 3.8-mm Z rapid that the plunge follows — is "
            f"{min(1000 * (m - t) for r in rows for n, m, t in r['sequence_parts_bare'][2:]):.0f}–"
            f"{max(1000 * (m - t) for r in rows for n, m, t in r['sequence_parts_bare'][2:]):.0f} ms short on every "
            "plate: the machine stands where a rapid ends and a cutting move follows "
            "(its in-position check before it cuts), as it does where a feed move ends and a rapid follows (below).  "
            f"The profile stands there {rows[0]['rapid_feed_wait'] * 1000:.0f} ms (`feed-rapid-wait`'s `rapid_feed`, "
            "fitted with the rest, the figures above with it).  Neither the plate's spindle speed (plate 12 "
            "S12000, the others S9000) nor its feed orders what is left; by tool, how much longer the machine "
            "took a sequence on one plate than on another (the twin times them alike; mean ± standard error): "
            + _tool_pairs(rows)
            + ".  Sequences the programs time alike took up to 2 s longer in all on one run than on "
            "another half an hour later (plates 12 and 13: the paired sums above): that is the rapid kind's run-to-run scatter on "
            "this machine, which no setting the three runs share takes up, and which a leave-one-out "
            "prediction of one plate's rapid kind carries whole.  (A rapid run into its collinear plunge at the plunge's feed, "
            "in place of "
            "a stop, would shorten plate 13's most, its plunges being the fastest; tried, it makes every plate's "
            "plunges 5–9 s short of the log, which shows them starting from rest: not kept.)",
            "- Where the cycle-time error sits, timed report to report over whole cutting passes (consecutive "
            "feed lines between two rapids; the pass's first feed): "
            + "; ".join(f"plate {r['plate']}: " + (", ".join(f"F{f} {e:+.1f} s of {m:.0f} s ({n} passes)"
                                                            for f, (n, m, e) in sorted(r["passes"].items())
                                                            if abs(e) >= 1.0) or "none")
                        for r in rows)
            + " (simulated − measured; a feed whose passes are off by less than 1 s in all is not listed).  "
            "Where in a pass, at the plate's most common pass feed (the span from the "
            "pass's first report to the next line's, and from its last reported line to the retract's first "
            "report; mean per pass ± its standard error): "
            + "; ".join(f"plate {r['plate']} (F{f}, {n} passes): start {h * 1000:+.0f} ± {hs * 1000:.0f} ms, end "
                        f"{t * 1000:+.0f} ± {ts * 1000:.0f} ms" for r in rows
                        for f, n, h, hs, t, ts in [r["pass_ends"]])
            + ".  Every feed line's end, against logs of the twin's own run sampled as the real one (the mean "
            "of eight; the time from the line's first report to the next line's, simulated − measured, mean ± its "
            "standard error (lines)), by the feed line's kind and the next line's, without the wait before a "
            "rapid: " + _feed_ends_text(rows, "feed_ends_bare")
            + ".  Where a straight feed line ends and a rapid follows, the machine stands some 50–75 ms longer "
            "than the twin on every plate, where the same lines followed by a feed line run alike: as if the "
            "control checked the axes in position there at a width of its own for cutting feed (Fanuc's "
            "parameter 1827 sets one apart), while the rapids' ends show no wait.  (Both times are taken in the "
            "same way from the same reports, so the sampling cancels between the rows; a line counts where "
            "the log reports it and the next, which favours lines the machine spent longer on: the arcs, "
            "shorter, come out some 10–20 ms short before a feed move too.)  The profile stands there "
            f"{m.controller.feed_rapid_wait * 1000:.0f} ms (`feed-rapid-wait`, fitted with the rest: the "
            "block times of whole kinds and windows want less than these line ends alone); with it: "
            + _feed_ends_text(rows, "feed_ends") + ".",
            "- Per-group RMS falls with the profile now that the spindle's waits stand on the lines the control "
            "reports them at (the M01, the approach after M3); before, they stood on the M5 and M3 lines and the "
            "group RMS rose above the default twin's.",
            ""]
    return "\n".join(out)


def _figure(meas, traces, path: Path) -> None:
    """Plate 13's logged feed (``meas``) against the default twin's and the profile's."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 1, figsize=(10, 6.5))
    zoom = (300.0, 360.0)
    for ax, span in zip(axes, (None, zoom)):
        lo, hi = span or (0.0, np.inf)
        m = (meas.t >= lo) & (meas.t <= hi)
        ax.step(meas.t[m], meas.signals["feed"][m], where="post", color="black", lw=0.8, label="measured (Feed_Rate)")
        for name, color in (("default", "tab:red"), ("profile", "tab:blue")):
            tr = traces[(13, name)]
            t = np.asarray(tr.t)
            # a point every 0.2 s over the whole run, every 0.02 s in the zoom (the file stays small)
            step = max(1, int(round((0.02 if span else 0.2) / max(t[1] - t[0], 1e-9)))) if len(t) > 1 else 1
            k = np.flatnonzero((t >= lo) & (t <= hi))[::step]
            ax.plot(t[k], np.asarray(tr.signal("feed"))[k], color=color, lw=0.7, alpha=0.8,
                    label=f"{'default twin' if name == 'default' else 'calibrated profile'}")
        ax.set_ylabel("path feed, mm/min")
        if span:
            ax.set_xlim(*span)
            ax.set_title(f"{span[0]:.0f}–{span[1]:.0f} s", fontsize=9)
        else:
            ax.axvspan(*zoom, color="0.9")
            ax.set_title("plate 13, whole run (shaded: the zoom below)", fontsize=9)
    axes[1].set_xlabel("time since the program started, s")
    axes[0].legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, format="svg")
    plt.close(fig)


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT.parent / "shared" / "realdata")
