"""``mtwin optimize`` with default options on every real program of the corpus, checked from outside.

    python3 benchmarks/optimize_corpus.py [--corpus ../shared/realdata/gcode_corpus] [--out corpus.jsonl]
                                          [--only SUBSTRING] [--timeout 300]

For each program that reads and has feed moves: optimise it as a new user would (``mtwin
optimize part.nc -o out.nc``, nothing else), then check the answer independently of what the
optimiser says about it:

* the output cuts the same path (``mtwin verify``'s check);
* re-simulated on a fresh twin, it is not slower than the program;
* no feed was raised on a line whose tool the twin does not describe;
* its largest contour error in feed moves is at most the roughing tolerance (0.1 mm) above
  the program's own, and every segment the optimiser raised holds its own tolerance;
* no line whose feed the optimiser says it kept (``kept`` in ``--json``) is changed;
* no facing or skim pass raised: under a guessed stock, no feed move at or above the stock's
  top changed; no ramp or helical entry (a feed move going down while moving sideways) changed;
* slower only where the optimiser names the limit the program breaks (``slower_because``).

``--materials benchmarks/corpus_materials.toml`` names each program's material as a user would
(``--material``; the rules say which and why): the limits then come from physics, and each
answer is checked against them from outside too — no described tool's shank over its allowed
stress unless the program already was (and the answer names it), no chip thickness over the
catalogue's (or the program's own where it already ran above it).  The totals add the
programs whose cutting tools the twin describes.  ``--forms`` counts, without optimising, the
programs that declare each form of material, stock and title tool the twin reads.

``--force-limit-factor 1.5`` runs each program a second time with ``--force-limit`` at 1.5x
the program's own peak load; ``--twin`` and ``--also FILE`` (e.g. NIST's PLATE-15 on
``samples/machines/hurco-vmx24.toml``) add a twin and programs outside the corpus.

Prints one line per program and the distribution of time changes; ``--out`` keeps the records.
"""
from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
EXTS = {".nc", ".ngc", ".tap", ".gcode", ".NC", ".TAP", ".cnc"}


def programs(corpus: Path) -> list[Path]:
    out = []
    for p in sorted(corpus.rglob("*")):
        if p.is_file() and p.suffix in EXTS and "/bad/" not in str(p):
            out.append(p)
    return out


class Timeout(Exception):
    pass


def _alarm(signum, frame):
    raise Timeout()


def material_for(path: Path, rules: list) -> tuple[str, str] | None:
    for r in rules:
        if r["match"] in str(path):
            return r["material"], r["why"]
    return None


def check_one(path: Path, timeout: int, tol: float = 0.1, twin_file: str | None = None,
              factor: float | None = None, material: str | None = None,
              spindle_range: tuple | None = None) -> dict:
    import mtwin
    from mtwin.cutting.library import describes
    from mtwin.errors import MtwinError
    from mtwin.gcode import records as R
    from mtwin.gcode.verify import compare
    from mtwin.motion.simulate import program_cutting
    from mtwin.optimize.guards import contour_error, feed_height
    from mtwin.cutting.engagement import GUESSED_STOCK
    from mtwin.optimize.run import OptimizeOptions, _feed_samples, optimize

    rec: dict = {"program": str(path), "force_limit_factor": factor, "material": material}
    tw = mtwin.Twin.from_toml(twin_file)
    if material is not None:
        tw = tw.with_material(material)
    try:
        prog = tw.load(str(path))
    except MtwinError as exc:
        rec.update(status="unreadable", reason=str(exc).splitlines()[0][:200])
        return rec
    k = prog.records["kind"]
    feed = (k == R.LINEAR) | (k == R.ARC_CW) | (k == R.ARC_CCW)
    if not feed.any():
        rec.update(status="no feed moves")
        return rec
    rec["feed_moves"] = int(feed.sum())
    signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(timeout)
    t0 = time.perf_counter()
    try:
        opts = OptimizeOptions(spindle_range=spindle_range)
        if factor is not None:
            peak = tw.simulate(prog).summary.cutting
            peak = float(peak.peak_load) if peak is not None else 0.0
            if not peak > 0:
                rec.update(status="no load")
                return rec
            rec["force_limit"] = factor * peak
            opts = OptimizeOptions(force_limit=factor * peak, spindle_range=spindle_range)
        res = optimize(tw, prog, opts)
    except Timeout:
        rec.update(status="timeout")
        return rec
    except MtwinError as exc:
        rec.update(status="refused", reason=str(exc)[:300], seconds=time.perf_counter() - t0)
        return rec
    finally:
        signal.alarm(0)
    rec["seconds"] = time.perf_counter() - t0
    new = tw.load(res.output, path=str(path))
    rec["verified"] = compare(prog, new) is None
    try:
        # the program's own simulation is the optimiser's first step (a plain simulate); the
        # output is simulated afresh, on a new twin, unless it is the program byte for byte
        before = res.trace_before
        fresh = mtwin.Twin.from_toml(twin_file)
        fresh = fresh.with_material(material) if material is not None else fresh
        after = before if res.output == bytes(prog.data) else fresh.simulate(new)
    except MtwinError as exc:
        rec.update(status="re-simulation failed", reason=str(exc)[:300])
        return rec
    rec["before"] = before.summary.cycle_time
    rec["after"] = after.summary.cycle_time
    rec["change"] = after.summary.cycle_time / before.summary.cycle_time - 1.0 if before.summary.cycle_time else 0.0
    rec["changed_lines"] = len(res.changed_lines)
    rec["status"] = "unchanged" if res.output == bytes(prog.data) else "optimised"
    # feeds raised on a line whose tool the twin does not describe
    cut = program_cutting(tw, prog)
    undescribed = {int(t) for t in np.unique(prog.records["tool"]) if not describes(cut, int(t))}
    raised = []
    f_old: dict[int, float] = {}
    for r in prog.records[feed]:
        f_old[int(r["line"])] = max(f_old.get(int(r["line"]), 0.0), float(r["feed"]))
    # the written program's lines shift where moves are split: compare by the text of F words
    # on the original lines instead — every changed line group is listed by the optimiser's diff,
    # which is recomputed here from the bytes
    import difflib

    a = bytes(prog.data).decode("latin-1").splitlines()
    b = res.output.decode("latin-1").splitlines()
    for tag, i1, i2, j1, j2 in difflib.SequenceMatcher(None, a, b, autojunk=False).get_opcodes():
        if tag == "equal":
            continue
        for ln in range(i1 + 1, i2 + 1):
            m = prog.records["line"] == ln
            if m.any() and int(prog.records["tool"][m][0]) in undescribed:
                raised.append(ln)
    rec["changed_on_undescribed_tool"] = raised[:20]
    # a line counts as changed unless it is the same text, or the same text with an F word that
    # restores its own programmed feed (the modal F a raised move before it changed)
    import re

    f_word = re.compile(r"\s*F[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)", re.I)
    f_line = {int(r["line"]): float(r["feed"]) for r in prog.records}
    inch = {int(r["line"]): bool(r["flags"] & R.FL_F_INCH) for r in prog.records}
    # each original move paired with the written program's moves by where they end (a split
    # move is several that end where it ended): a line is changed if one of its moves was split,
    # runs at another feed, or its text differs other than by an F word restoring its own feed
    changed = set()
    ro, rn = prog.records, new.records
    pieces: dict[int, list[int]] = {}  # original record -> the written program's records
    k = 0
    for i in range(len(ro)):
        start = k
        end = np.array([ro["x"][i], ro["y"][i], ro["z"][i]])
        while k < len(rn) and not np.allclose([rn["x"][k], rn["y"][k], rn["z"][k]], end, atol=1e-6):
            k += 1
        if k >= len(rn):
            changed.update(ro["line"][i:].tolist())  # (cannot pair: counted as changed)
            break
        pieces[i] = list(range(start, k + 1))
        ln, ln_new = int(ro["line"][i]), int(rn["line"][k])
        if k > start or abs(rn["feed"][k] - ro["feed"][i]) > 0.01:
            changed.add(ln)
        elif a[ln - 1] != b[ln_new - 1]:
            m = re.search(r"F([-+]?[0-9]*\.?[0-9]+)", b[ln_new - 1], re.I)
            restored = f_word.sub("", a[ln - 1]) == f_word.sub("", b[ln_new - 1]) and m and \
                abs(float(m.group(1)) * (25.4 if inch.get(ln) else 1.0) - f_line[ln]) < 0.01
            if not restored:
                changed.add(ln)
        k += 1
    kept_lines = {ln for lines in res.kept.values() for ln in lines}
    rec["kept_changed"] = sorted(changed & kept_lines)[:20]
    r_ = prog.records
    from mtwin.optimize.model import RAMP_DZ

    entries = feed & (r_["z"] - r_["sz"] < -RAMP_DZ)  # (the optimiser's own rule: CAM rounding is no entry)
    # a plunge the optimiser says runs its upper part in proven air (air_entries) may change there
    # only: checked here — every piece above its air height cuts nothing in the re-simulation, and
    # the piece that meets material runs at the program's own feed
    air = {e["line"]: e for e in res.air_entries}
    air_bad = []
    mrr = after.signal("mrr") if after.cut is not None else None
    for i in np.flatnonzero(entries & np.isin(r_["line"], list(air))):
        e, ps = air[int(r_["line"][i])], pieces.get(int(i), [])
        last = ps[-1] if ps else None
        ok = last is not None and abs(rn["feed"][last] - r_["feed"][i]) <= 0.01 if e["air_to_z"] > e["to_z"] + 1e-6 \
            else bool(ps)
        fast = ps[:-1] if e["air_to_z"] > e["to_z"] + 1e-6 else ps
        ok &= all(rn["z"][q] >= e["air_to_z"] - 1e-3 for q in fast)  # (the written coordinates are rounded)
        if ok and mrr is not None and fast:
            ok = not (mrr[np.isin(after.record, fast)] > 0).any()
        if not ok:
            air_bad.append(int(r_["line"][i]))
    rec["air_entry_bad"] = air_bad[:20]
    rec["air_entries"] = len(air)
    rec["entry_changed"] = sorted((changed - set(air)) & set(r_["line"][entries].tolist()))[:20]
    c = before.summary.cutting
    faces = []
    if c is not None and c.stock_source == GUESSED_STOCK and c.stock is not None:
        top = float(c.stock[5])
        at_top = feed & (np.minimum(r_["z"], r_["sz"]) >= top - 1e-3) & (np.maximum(r_["z"], r_["sz"]) <= top + 0.5)
        faces = sorted(changed & set(r_["line"][at_top].tolist()))
    rec["face_changed"] = faces[:20]
    rec["slower_because"] = len(res.slower_because)
    rec["segments_contour_held"] = all(sg.get("contour_held", True) for sg in res.segments)
    ce_b = contour_error(before)
    ce_a = contour_error(after)
    rec["contour_before"] = float(np.max(ce_b[_feed_samples(before, prog)], initial=0.0))
    # (where the tool cannot reach the part its following error is in air: the pieces of a plunge
    # in air all the way, while the command less the error stays above the material it is proven
    # to stay above — its load there is checked to be none above)
    # nor above the program's own feed height (where it descends fast before it slows to plunge,
    # when above the stock's top) or a given stock's top: a corner taken fast up there is in air
    reach = _feed_samples(after, new)
    if c is not None and c.stock is not None:
        clear = feed_height(prog)
        clear = clear if clear > float(c.stock[5]) else np.inf
        if c.stock_source != GUESSED_STOCK:
            clear = min(clear, float(c.stock[5]))
        reach &= after.cmd[:, 2] - ce_a < clear
    for i, ps in pieces.items():
        e = air.get(int(r_["line"][i]))
        if e is not None and e["air_to_z"] <= e["to_z"] + 1e-6:
            m = np.isin(after.record, ps)
            reach[m] &= after.cmd[m, 2] - ce_a[m] < e["material_z"]
    rec["contour_after"] = float(np.max(ce_a[reach], initial=0.0))
    rec["contour_ok"] = rec["contour_after"] <= rec["contour_before"] + tol + 1e-9 and rec["segments_contour_held"]
    rec["kept"] = {k: len(v) for k, v in res.kept.items()}
    rec["described"] = bool(c is not None and c.tools and all(t["source"] != "default" for t in c.tools))
    rec["physics"] = any(x.get("source") == "physics" for x in res.limits)
    rec["physics_broken"] = _physics_broken(prog, new, before, after, res) if rec["physics"] else []
    own_s = {int(t): float(prog.records["spindle"][feed & (prog.records["tool"] == t)].max(initial=0.0))
             for t in np.unique(prog.records["tool"][feed])}
    rec["spindle"] = {str(k): v for k, v in res.spindle.items() if abs(v - own_s.get(int(k), v)) > 0.5}
    rec["machine_broken"] = _machine_broken(tw, before, after)
    return rec


def _machine_broken(tw, before, after) -> list:
    """The spindle's rated power and its torque curve, checked on the re-simulated answer:
    over them, unless the program itself already was (whole-program peaks: a higher speed
    carries a chip at more power)."""
    sp = tw.machine.spindle
    out = []
    cb, ca = before.summary.cutting, after.summary.cutting
    if ca is None:
        return out
    pb = cb.peak_power if cb is not None else 0.0
    if ca.peak_power > sp.rated_power * 1.001 and ca.peak_power > pb * 1.001:
        out.append(f"spindle power {ca.peak_power:.0f} W > {sp.rated_power:.0f} W (line {ca.peak_power_line})")
    lb = cb.peak_spindle_load if cb is not None else 0.0
    if ca.peak_spindle_load > 1.001 and ca.peak_spindle_load > lb * 1.001:
        out.append(f"spindle torque {100 * ca.peak_spindle_load:.0f} % of the curve (line {ca.peak_spindle_torque_line})")
    return out


def _physics_broken(prog, new, before, after, res) -> list:
    """The physics limits the re-simulated answer breaks, checked on its trace: a described
    tool's shank over its allowed stress where the program's was not (or the answer does not
    say why), a chip thicker than the catalogue's where the program's was not."""
    out = []
    a_shank = {c["tool"]: c for c in after.summary.cutting.shank}
    b_shank = {c["tool"]: c for c in before.summary.cutting.shank}
    for t, c in a_shank.items():
        if c["over"] and not (b_shank.get(t, {}).get("over") and res.slower_because):
            out.append(f"T{t} shank {c['stress']:.0f} > {c['allowed_stress']:.0f} N/mm2")
    phys = {x["tool"]: x for x in res.limits if x.get("source") == "physics"}

    def hmax(trace, program):
        rec = trace.record
        ok = rec >= 0
        tool = np.where(ok, program.records["tool"][np.maximum(rec, 0)], -1)
        h = trace.signal("h_max")
        return {int(t): float(h[tool == t].max(initial=0.0)) for t in np.unique(tool[ok])}

    hb, ha = hmax(before, prog), hmax(after, new)
    for t, lim in phys.items():
        allowed = max(lim["chip_thickness"], hb.get(t, 0.0)) * 1.03
        if ha.get(t, 0.0) > allowed:
            out.append(f"T{t} chip {ha[t] * 1000:.1f} > {allowed * 1000:.1f} um")
    return out


def count_forms(files: list) -> None:
    """How many programs declare each form of material, stock and title tool."""
    from collections import Counter

    import mtwin
    from mtwin.cutting.workpiece import read_workpiece
    from mtwin.errors import MtwinError

    tw = mtwin.Twin()
    forms, n, warned = Counter(), 0, 0
    for p in files:
        try:
            wp = read_workpiece(tw.load(str(p)))
        except MtwinError:
            continue
        n += 1
        for what, f in (("material", wp.material), ("stock", wp.stock), ("tool", wp.tool)):
            if f is not None:
                forms[f"{what}: {f.form}"] += 1
                print(f"{p.name}: {what} {f.value if what != 'tool' else f.value.diameter} ({f.form}, line {f.line})")
        warned += bool(wp.warnings)
    print(f"\n{n} programs read; " + "; ".join(f"{k} {v}" for k, v in sorted(forms.items()))
          + f"; with a malformed form (warning) {warned}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--corpus", default=str(ROOT.parent / "shared" / "realdata" / "gcode_corpus"))
    ap.add_argument("--out", default=None)
    ap.add_argument("--only", default=None)
    ap.add_argument("--timeout", type=int, default=300)
    ap.add_argument("--twin", default=None)
    ap.add_argument("--also", action="append", default=[])
    ap.add_argument("--no-corpus", action="store_true")
    ap.add_argument("--force-limit-factor", type=float, default=None)
    ap.add_argument("--materials", default=None)
    ap.add_argument("--forms", action="store_true")
    ap.add_argument("--spindle-range", default=None, help="LOW,HIGH rpm: --spindle-range for every program")
    a = ap.parse_args()
    rules = []
    if a.materials:
        import tomllib

        rules = tomllib.loads(Path(a.materials).read_text(encoding="utf-8"))["rule"]
    corpus = Path(a.corpus)
    if not corpus.is_dir() and not a.no_corpus:
        sys.exit(f"no corpus at {corpus}")
    files = [] if a.no_corpus else [p for p in programs(corpus) if a.only is None or a.only in str(p)]
    files += [Path(x).resolve() for x in a.also]
    if a.forms:
        count_forms(files)
        return
    spindle_range = tuple(float(x) for x in a.spindle_range.replace(":", ",").split(",")) if a.spindle_range else None
    out = open(a.out, "w") if a.out else None
    recs = []
    runs = [(p, None) for p in files] + ([(p, a.force_limit_factor) for p in files] if a.force_limit_factor else [])
    for p, factor in runs:
        m = material_for(p, rules) if rules else None
        r = check_one(p, a.timeout, twin_file=a.twin, factor=factor, material=m[0] if m else None,
                      spindle_range=spindle_range)
        recs.append(r)
        rel = (str(p.relative_to(corpus)) if corpus in p.parents else str(p)) + \
            (f" [--force-limit {r.get('force_limit', 0):.1f}]" if factor else "")
        if r["status"] in ("optimised", "unchanged"):
            flags = []
            if not r["verified"]:
                flags.append("NOT VERIFIED")
            if r["change"] > 1e-4 and not r["slower_because"]:
                flags.append("SLOWER")
            elif r["change"] > 1e-4:
                flags.append(f"slower: the program breaks the given limit ({r['slower_because']} segment(s))")
            for key, what in (("kept_changed", "KEPT LINE CHANGED"), ("entry_changed", "RAMP/HELIX CHANGED"),
                              ("air_entry_bad", "AIR ENTRY NOT IN AIR"),
                              ("face_changed", "FACING PASS CHANGED")):
                if r[key]:
                    flags.append(f"{what} {r[key][:5]}")
            if r["changed_on_undescribed_tool"]:
                flags.append(f"CHANGED ON UNDESCRIBED TOOL {r['changed_on_undescribed_tool'][:5]}")
            if not r["contour_ok"]:
                flags.append("CONTOUR WORSE")
            if r.get("machine_broken"):
                flags.append(f"SPINDLE LIMIT BROKEN {r['machine_broken'][:2]}")
            if r.get("spindle"):
                flags.append(f"S {r['spindle']}")
            if r.get("physics_broken"):
                flags.append(f"PHYSICS LIMIT BROKEN {r['physics_broken'][:3]}")
            if r.get("material"):
                flags.append(f"[{r['material']}{', physics' if r.get('physics') else ''}]")
            print(f"{rel}: {r['status']} {r['before']:.2f} -> {r['after']:.2f} s ({100 * r['change']:+.1f} %), contour "
                  f"{r['contour_before']:.3f} -> {r['contour_after']:.3f} mm, {r['seconds']:.1f} s "
                  f"{' '.join(flags)}", flush=True)
        elif r["status"] != "no feed moves":
            print(f"{rel}: {r['status']}: {r.get('reason', '')}", flush=True)
        if out:
            out.write(json.dumps(r) + "\n")
            out.flush()
    for factor in sorted({r["force_limit_factor"] for r in recs}, key=lambda f: f or 0):
        _totals([r for r in recs if r["force_limit_factor"] == factor], files, factor, bool(rules))


def _totals(recs: list, files: list, factor, materials: bool = False) -> None:
    what = 'default options' if factor is None else f'--force-limit {factor:g} x the program peak'
    print(f"\n== {what}{' and --material as corpus_materials.toml names it' if materials else ''}")
    done = [r for r in recs if r["status"] in ("optimised", "unchanged")]
    with_feed = [r for r in recs if "feed_moves" in r]
    ch = np.array([r["change"] for r in done]) * 100
    print(f"\n{len(files)} files; {len(with_feed)} read with feed moves; {len(done)} written "
          f"({sum(r['status'] == 'optimised' for r in done)} changed, {sum(r['status'] == 'unchanged' for r in done)} "
          f"unchanged); refused {sum(r['status'] == 'refused' for r in recs)}; timeouts "
          f"{sum(r['status'] == 'timeout' for r in recs)}; unreadable {sum(r['status'] == 'unreadable' for r in recs)}")
    if len(ch):
        unnamed = sum(r["change"] > 1e-4 and not r["slower_because"] for r in done)
        print(f"cycle time change %: min {ch.min():+.1f}, median {np.median(ch):+.1f}, max {ch.max():+.1f}; "
              f">= 5 % faster: {int((ch <= -5).sum())}; slower: {int((ch > 0.01).sum())} "
              f"({unnamed} without a broken limit named)")
        print(f"kept line changed: {sum(bool(r['kept_changed']) for r in done)}; ramp/helix changed: "
              f"{sum(bool(r['entry_changed']) for r in done)}; plunge air not proven: "
              f"{sum(bool(r.get('air_entry_bad')) for r in done)}; plunges run faster in proven air: "
              f"{sum(1 for r in done if r.get('air_entries'))}; facing pass changed: "
              f"{sum(bool(r['face_changed']) for r in done)}")
        desc = np.array([r["change"] for r in done if r.get("described")]) * 100
        if len(desc):
            print(f"programs whose cutting tools the twin describes: {len(desc)}; change %: min {desc.min():+.1f}, "
                  f"median {np.median(desc):+.1f}, max {desc.max():+.1f}; >= 5 % faster: {int((desc <= -5).sum())}")
        print(f"spindle speed changed: {sum(bool(r.get('spindle')) for r in done)}; "
              f"spindle power or torque over the machine's (the program itself under it): "
              f"{sum(bool(r.get('machine_broken')) for r in done)}")
        print(f"physics limits used: {sum(bool(r.get('physics')) for r in done)}; a physics limit broken on the "
              f"re-simulated answer: {sum(bool(r.get('physics_broken')) for r in done)}")
        print(f"not verified: {sum(not r['verified'] for r in done)}; changed on an undescribed tool: "
              f"{sum(bool(r['changed_on_undescribed_tool']) for r in done)}; contour worse than tolerance: "
              f"{sum(not r['contour_ok'] for r in done)}")
    for r in recs:
        if r["status"] == "refused":
            print(f"refused: {r['program']}: {r['reason'][:200]}")


if __name__ == "__main__":
    main()
