"""Orchestration of ``mtwin optimize``: simulate, segment, search on the fast model, write,
verify, re-simulate on the full twin and hold the limits on that trace, not on the estimate.
"""
from __future__ import annotations

import math
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from types import SimpleNamespace

import numpy as np

from ..errors import MtwinError
from ..gcode import records as R
from ..cutting.engagement import GUESSED_STOCK
from ..motion.path import PAUSE
from ..units import rad_per_second
from .model import cutting_speed, entry_records, feed_records, move_times, path_model
from .problem import CostRates, Limits, Runups, build_problem
from .chatter import chatter_tables, var_stable
from .chatter import report as chatter_report
from .search import GAOptions, bisect, fixed_spins, genetic
from .guards import (ENTRY_MIN_AIR, FINISH_AE, SURFACE_SHARE, air_entries, contour_error, feed_height,
                     final_surface_steps, finish_lines, inside_stock, learned_levels, percentile_by_group, proven_clear,
                     trusted_records)
from .segment import locate, segment_path


FAST_MAP = 50_000  # trace samples from which the sample-to-segment map runs as a kernel
TIME_LEVELS = 5  # uniform feeds the planner is asked for move times at
# mm: the contour error a roughing segment may gain by default — half of a 0.2 mm finishing
# allowance, the low end of the 0.2-0.5 mm CAM systems leave for a finishing pass to remove
ROUGH_TOLERANCE = 0.1


class VerifyError(MtwinError):
    """The written program failed its own proof: a bug (exit 3), nothing is written."""

    exit_code = 3


class InfeasibleError(MtwinError):
    """Even the lowest feed of the range breaks a limit: the program needs another strategy.
    ``reasons``: per segment, the limit, its lines and tool, the value against the limit."""

    def __init__(self, message: str, reasons: list | None = None, before=None):
        super().__init__(message)
        self.reasons = reasons or []
        self.program = ""  # the program's name (optimize() sets it)
        self.before = before  # the refused program's simulation (a Trace), where it was made


# bounds on the options, beyond which a value is a typo, not a wish: a contour error of 10 mm is
# no tolerance, and a GA of a million individuals would fill the memory (60 and 200 by default)
MAX_TOLERANCE = 10.0
MAX_POPULATION = 10_000
MAX_GENERATIONS = 100_000
MAX_SPIN_TRIALS = 64  # spindle variables tried one by one for a speed the writer can place


@dataclass
class OptimizeOptions:
    objective: str = "time"
    method: str = "bisect"
    # N, for every tool; or {tool: N} for some (the others' limits learned from the program);
    # None: every tool's learned from the program
    force_limit: float | dict | None = None
    feed_range: tuple[float, float] | None = None  # mm/min; None: (10 % of the lowest F, machine max)
    spindle_range: tuple[float, float] | None = None  # rpm; None: S stays
    spindle_per: str = "tool"
    allow_s_changes: bool = False
    target_power: float | None = None  # W, smooth; None: the percentile below
    target_percentile: float = 75.0
    power_tolerance: float = 0.05  # smooth: |P/P_target - 1|
    # mm: the contour error a raised segment may gain over the program's own on the re-simulated
    # twin — ``tolerance`` where the segment leaves a final surface (a finishing pass, the last
    # pass over a floor), ``rough_tolerance`` on roughing moves whose surface later passes cut
    # again.  A guard never takes a feed below the program's own for accuracy: at its own
    # feed a segment is as accurate as the program is
    tolerance: float = 0.02
    rough_tolerance: float | None = None  # None: ROUGH_TOLERANCE, or ``tolerance`` where that is larger
    ramp_feed: str = "keep"  # keep: ramps and helical entries keep their feed like plunges; optimize
    chip_limit: str = "learned"  # learned: a tool's chip thickness held to the program's own level; none
    # where the limits come from: auto (physics for the tools the twin describes once the
    # material is named — --material, cutting.material, the program's comments — else learned
    # from the program), learned (always the program's own levels), physics (the material must
    # be named); limit_scale: the physics limits' share (a cautious shop takes 0.8)
    limits: str = "auto"
    limit_scale: float = 1.0
    # the trade-off against the physics limits, estimated and re-simulated at the scales
    # TRADEOFF_SCALES (two more runs of the twin: what a report shows); off: not drawn
    tradeoff_resimulated: bool = False
    # keep: finishing passes keep their feed per tooth; optimize: treated as any cut; auto: keep,
    # but a tool held to limits from physics takes them there too (its chip ceiling with radial
    # chip thinning, and the deflection allowed on a final surface)
    finish_feed: str = "auto"
    segmentation: str = "cluster"
    min_segment: float = 5.0  # mm, the reference's C
    ga: GAOptions = field(default_factory=GAOptions)
    margin: float = 0.01
    max_rounds: int = 8
    # with tools whose dynamics the twin knows: each cutting segment's axial depth is held at
    # most this share of the lobes' limit at its speed (docs/chatter.md); None: no check
    chatter_margin: float | None = 0.8
    chatter_method: str = "auto"  # zoa | sdm | auto (chatter.lobes)
    # depth layering (optimize.layers): a cut over its limit even at the lowest feed is re-cut in
    # up to this many layers of equal depth; 0: off (a program is refused there, as it always was)
    max_layers: int = 0

    def __post_init__(self):
        # every option within its domain, named as the command line names it
        from .search import METHODS, OBJECTIVES

        from ..params import UNIT_MAX

        def positive(v, unit: str = "") -> bool:  # (and no more than a machine has: params.UNIT_MAX)
            return v is None or (0 < v <= UNIT_MAX.get(unit, math.inf))

        o = self
        checks = [  # (holds, the message when it does not: built only then)
            (o.objective in OBJECTIVES, lambda: f"--objective must be one of {', '.join(OBJECTIVES)}, got {o.objective!r}"),
            (o.method in METHODS, lambda: f"--method must be one of {', '.join(METHODS)}, got {o.method!r}"),
            (o.segmentation in ("cluster", "changepoint"),
             lambda: f"--segmentation must be cluster or changepoint, got {o.segmentation!r}"),
            (o.spindle_per in ("tool", "segment"), lambda: f"--spindle-per must be tool or segment, got {o.spindle_per!r}"),
            (o.chatter_margin is None or 0 < o.chatter_margin <= 1,
             lambda: f"--chatter-margin must be in (0, 1] (a share of the stability limit), got {o.chatter_margin}"),
            (o.chatter_method in ("zoa", "sdm", "auto"),
             lambda: f"--chatter-method must be zoa, sdm or auto, got {o.chatter_method!r}"),
            (all(positive(v, "N") for v in _force_values(o.force_limit)),
             lambda: f"--force-limit must be a positive number of N up to {UNIT_MAX['N']:g} (or T1=N,T3=N per tool), "
                     f"got {o.force_limit}"),
            (positive(o.target_power, "W"),
             lambda: f"--target-power must be a positive number of W up to {UNIT_MAX['W']:g}, got {o.target_power:g}"),
            (0 < o.power_tolerance < 1, lambda: f"--power-tolerance must be between 0 and 1, got {o.power_tolerance:g}"),
            (0 <= o.tolerance <= MAX_TOLERANCE,
             lambda: f"--tolerance must be a contour error from 0 to {MAX_TOLERANCE:g} mm, got {o.tolerance:g}"),
            (o.finish_feed in ("keep", "optimize", "auto"),
             lambda: f"--finish-feed must be auto, keep or optimize, got {o.finish_feed!r}"),
            (o.rough_tolerance is None or 0 <= o.rough_tolerance <= MAX_TOLERANCE,
             lambda: f"--rough-tolerance must be a contour error from 0 to {MAX_TOLERANCE:g} mm, got "
                     f"{o.rough_tolerance:g}"),
            (o.ramp_feed in ("keep", "optimize"), lambda: f"--ramp-feed must be keep or optimize, got {o.ramp_feed!r}"),
            (o.chip_limit in ("learned", "none"), lambda: f"--chip-limit must be learned or none, got {o.chip_limit!r}"),
            (o.limits in ("auto", "learned", "physics"),
             lambda: f"--limits must be auto, learned or physics, got {o.limits!r}"),
            (0.1 <= o.limit_scale <= 1.5 and math.isfinite(o.limit_scale),
             lambda: f"--limit-scale must be between 0.1 and 1.5 (a share of the physics limits), got {o.limit_scale:g}"),
            (0 <= o.min_segment <= UNIT_MAX["mm"],
             lambda: f"--min-segment must be from 0 to {UNIT_MAX['mm']:g} mm, got {o.min_segment:g}"),
            (o.max_layers == 0 or 2 <= o.max_layers <= 20,
             lambda: f"--max-layers must be between 2 and 20 (or --layers off), got {o.max_layers}"),
            (4 <= o.ga.population <= MAX_POPULATION and 1 <= o.ga.generations <= MAX_GENERATIONS,
             lambda: f"--population must be from 4 to {MAX_POPULATION:,} and --generations from 1 to "
                     f"{MAX_GENERATIONS:,}, got {o.ga.population} and {o.ga.generations}"),
        ]
        for ok, message in checks:
            if not ok:
                raise MtwinError(message())


def _force_values(limit) -> list:
    if limit is None:
        return []
    return list(limit.values()) if isinstance(limit, dict) else [limit]


def parse_force_limit(text: str):
    """``--force-limit``: ``60`` (N, every tool) or ``T1=40,T3=120`` (per tool)."""
    text = text.strip()
    if "=" not in text:
        try:
            return float(text)
        except ValueError:
            raise MtwinError(f"--force-limit {text!r}: give N (60) or per tool T1=40,T3=120") from None
    out = {}
    for part in text.split(","):
        key, _, value = part.partition("=")
        key = key.strip().upper().lstrip("T")
        try:
            tool, n = int(key), float(value)
        except ValueError:
            raise MtwinError(f"--force-limit {text!r}: {part.strip()!r} is not TOOL=N (T1=40)") from None
        if tool in out:
            raise MtwinError(f"--force-limit {text!r}: T{tool} is given twice")
        out[tool] = n
    return out


@dataclass
class Figures:
    cycle_time: float
    cost: float | None
    peak_load: float
    peak_power: float
    power_cv: float | None

    def as_dict(self):
        return {"cycle_time": self.cycle_time, "cost": self.cost, "peak_load": self.peak_load,
                "peak_power": self.peak_power, "power_cv": self.power_cv}


@dataclass
class OptimizeResult:
    """What ``optimize`` did, as data (the CLI prints it; the report draws it)."""

    output: bytes
    objective: str
    method: str
    before: Figures
    after: Figures
    estimate: dict  # the fast model's figures for the written program
    changed_lines: list  # (line, before text, after text)
    segments: list  # per segment: dict(lines, air, tool, feed_before, feed_after, limited_by, mean_power_*)
    verified: bool
    rounds: int
    evaluations: int
    seconds: float
    force_limit: dict  # tool -> N
    tradeoff: list  # (force limit N, estimated cycle time s)
    trace_before: object = None
    trace_after: object = None
    seg_before: np.ndarray | None = None  # segment of every sample of trace_before (-1: none)
    seg_after: np.ndarray | None = None  # the same for trace_after
    warnings: list = field(default_factory=list)
    generations: int = 0
    history: list | None = None
    force_limit_source: str = ""  # "" (given) or where the default came from
    defaults: list = field(default_factory=list)  # what the twin assumed (tools, material)
    search_seconds: float = 0.0  # the search on the fast model alone
    limits: list = field(default_factory=list)  # per tool: which limits were used and where they came from
    kept: dict = field(default_factory=dict)  # why moves kept their feeds: reason -> lines
    contour_error: dict = field(default_factory=dict)  # before/after max contour error in feed moves, mm
    spindle: dict = field(default_factory=dict)  # tool -> chosen S (rpm), with --spindle-range
    tradeoff_source: str = "estimated"  # the trade-off curve's times: "estimated" (fast model)
    # per tool with a wear effect: the land the plan starts and ends with, and the parts like
    # this one left before the land reaches the end-of-life limit (ISO 8688-2: 0.3 mm)
    tool_wear: dict = field(default_factory=dict)
    # with tools whose dynamics the twin knows: per segment the depth, speeds and stability
    # margin before and after, the segments no speed makes stable (optimize.chatter.report)
    chatter: dict = field(default_factory=dict)
    # the lobes behind it, for the report: tool -> (speed grid rpm, [(label, limits mm)])
    chatter_curves: dict = field(default_factory=dict)
    # an answer slower than the program: per segment written below its own feed, the limit the
    # program breaks there (empty: the answer is not slower, or only for the chatter margin)
    slower_because: list = field(default_factory=list)
    # with limits from physics: cycle time against their scale (0.6-1.0 of each), estimated, and
    # re-simulated at a few scales ({"scale", "estimate", "resimulated" or None})
    tradeoff_scale: list = field(default_factory=list)
    # with --layers: per layered cut its lines, layers, depths and feeds (optimize.layers), and
    # the proof that the written program leaves the original's part (cutting.stockproof)
    layers: list = field(default_factory=list)
    stock_proof: object = None
    # plunges that run their upper part in proven air at the air feed (guards.air_entries)
    air_entries: list = field(default_factory=list)
    program: object = None  # the program as read (optimize() sets it)

    @property
    def tools(self) -> list:
        """The program's tools as the twin took them (cutting.library.tools_used)."""
        c = self.trace_before.summary.cutting if self.trace_before is not None else None
        return list(c.tools) if c is not None else []

    @property
    def verdict(self) -> tuple[str, float]:
        """("faster" | "slower" | "unchanged", the relative change of the cycle time); a change
        under 0.05 % is "unchanged" unless lines were changed."""
        before, after = self.before.cycle_time, self.after.cycle_time
        change = after / before - 1.0 if before else 0.0
        if abs(change) >= 5e-4 or self.changed_lines:
            return ("faster" if change < 0 else "slower" if change > 0 else "unchanged"), change
        return "unchanged", change

    def as_dict(self, program_path: str = "") -> dict:
        """As ``mtwin optimize --json`` prints it."""
        verdict, change = self.verdict
        b, a = self.before, self.after
        return {"program": program_path, "objective": self.objective, "method": self.method, "written": True,
                "verdict": verdict, "cycle_time_change": change, "before": b.as_dict(), "after": a.as_dict(),
                "estimate": self.estimate, "estimate_error": {"cycle_time": self.estimate["cycle_time"] - a.cycle_time},
                "changed_lines": len(self.changed_lines), "verified": self.verified, "rounds": self.rounds,
                "evaluations": self.evaluations, "generations": self.generations, "seconds": self.seconds,
                "force_limit": self.force_limit, "force_limit_source": self.force_limit_source,
                "limits": self.limits, "kept": self.kept, "contour_error": self.contour_error,
                "spindle": {str(k): v for k, v in self.spindle.items()}, "defaults": self.defaults,
                "tools": self.tools, "segments": self.segments,
                "tradeoff": [{"force_limit": f, "cycle_time": t} for f, t in self.tradeoff],
                "tradeoff_source": self.tradeoff_source, "tradeoff_scale": self.tradeoff_scale,
                **({"tool_wear": {str(k): v for k, v in self.tool_wear.items()}} if self.tool_wear else {}),
                **({"chatter": self.chatter} if self.chatter else {}),
                **({"layers": self.layers, "stock_proof": self.stock_proof.as_dict()} if self.layers else {}),
                "slower_because": self.slower_because, "air_entries": self.air_entries,
                "changes": [{"line": ln, "before": x, "after": y} for ln, x, y in self.changed_lines]}


def optimize(twin=None, program=None, opts: OptimizeOptions | None = None, progress=None, stock=None,
             stage=None, on_message=None) -> OptimizeResult:
    """Optimise a program's F (and S) words on a twin (see the module and docs/optimize.md).

    Parameters
    ----------
    twin, program
        As for every use case (:mod:`mtwin.api`): a Twin, a twin file or None; a Program, a
        path or the program's bytes.
    opts : OptimizeOptions, optional
        Objective, method, limits and ranges (default: time by bisection, learned limits).
    progress : callable, optional
        Called with (generation, generations, best fitness) by the GA.
    stock : tuple, optional
        The stock box (xmin, ymin, zmin, xmax, ymax, zmax), mm.
    stage : callable, optional
        Called with a short description of each stage (simulating, searching, re-simulating).
    on_message : callable, optional
        ``on_message(kind, text)`` for the program's own warnings as it is read (before the
        run); without it they open the result's ``warnings``.

    Returns
    -------
    OptimizeResult
        ``output`` the proven program's bytes; ``as_dict()`` what ``--json`` prints;
        ``program`` the program as read.  An :class:`InfeasibleError` carries the program's
        name (``program``) and, per segment, why (``reasons``).
    """
    from ..twin.setup import Messages, load_part, open_twin

    msgs = Messages(on_message)
    twin = open_twin(twin)
    program = load_part(twin, program, msgs)
    opts = opts or OptimizeOptions()
    try:
        try:
            res = _optimize(twin, program, opts, progress, stock, stage)
        except InfeasibleError as exc:
            if not opts.max_layers:
                raise
            res = _layered(twin, program, opts, progress, stock, stage, exc)
    except InfeasibleError as exc:
        exc.program = program.path
        raise
    if on_message is None:
        res.warnings[:0] = msgs.warnings
    res.program = program
    return res


def record_optimised(setup, res: OptimizeResult, program: str) -> list[str]:
    """``optimize --record``: the optimised program's run, as re-simulated, into the tool ledger
    of ``setup`` (a TwinSetup: ``ledger`` and ``tool_map``), under the name ``program`` (where
    it was written).  Returns the tool ids recorded."""
    from ..ledger import record_trace

    if not getattr(setup, "ledger", None):
        raise MtwinError("--record adds the run to a tool ledger: give --ledger FILE and --tool-id T3=ID")
    return record_trace(setup.ledger, setup.tool_map, res.trace_after, program=program, source="optimize")


def _layered(twin, program, opts: OptimizeOptions, progress, stock, stage, refused: InfeasibleError) -> OptimizeResult:
    """The program with each cut that is over a limit even at the lowest feed written in layers
    (:mod:`.layers`: the fewest, from the load's excess, one more wherever the layered program is
    still over), optimised as any program, and proven to leave the original's part."""
    from ..cutting.stockproof import prove_same_stock
    from ..motion.simulate import program_engagement
    from .layers import Layering, NotLayerable, find_cut, layered_text, material_top

    stage = stage or (lambda text: None)
    stage("layering the cuts over the limit")
    plan0, eng0 = program_engagement(twin, program, stock)
    layerings: dict[int, Layering] = {}
    reasons, origin = refused.reasons, None
    stock_top = float(eng0.stock.box[5])
    for _ in range(opts.max_layers):
        this_round: dict[int, int] = {}  # cut -> layers it needs by its worst segment's excess
        new_cuts: dict[int, object] = {}
        for r in reasons:
            a, b = r["lines"]
            if origin is not None:  # a line of the layered program: the program's line it came from
                a, b = int(origin[a - 1]), int(origin[b - 1])
            try:
                cut = find_cut(program, a, b, stock_top)
            except NotLayerable as why:
                raise InfeasibleError(f"{refused} — and lines {a}-{b} cannot be cut in layers: {why}",
                                      reasons=refused.reasons) from None
            ly = layerings.get(cut.plunge_line)
            # the load falls about as the depth: the fewest layers that bring it under; a cut
            # already layered and still over gets one more (once a round, however many of its
            # segments are over)
            n = max(2, math.ceil(r["value"] / r["limit_value"] - 1e-9)) if ly is None else ly.layers + 1
            this_round[cut.plunge_line] = max(n, this_round.get(cut.plunge_line, 0))
            new_cuts.setdefault(cut.plunge_line, cut)
        for line, n in this_round.items():
            if line not in layerings:
                layerings[line] = Layering(new_cuts[line], n, material_top(eng0, plan0, new_cuts[line]))
            ly = layerings[line]
            ly.layers = n
            a, b = ly.cut.plunge_line, ly.cut.last_line
            if ly.layers > opts.max_layers:
                raise InfeasibleError(f"{refused} — lines {a}-{b} are still over it in {opts.max_layers} layers "
                                      f"(--max-layers)", reasons=refused.reasons)
        text, origin, layer_of = layered_text(program, list(layerings.values()))
        layered = twin.load(text, path=program.path)
        try:
            res = _optimize(twin, layered, opts, progress, stock, stage)
        except InfeasibleError as again:
            reasons = again.reasons
            continue
        break
    else:
        raise InfeasibleError(f"{refused} — still over it in {opts.max_layers} layers (--max-layers)",
                              reasons=refused.reasons)
    if opts.method == "ga":
        res, layered, origin, layer_of = _more_layers(twin, program, opts, progress, stock, stage, layerings,
                                                      (res, layered, origin, layer_of))
    stage("proving the layered program leaves the same part")
    plan1, eng1 = program_engagement(twin, twin.load(res.output, path=program.path), eng0.stock.box)
    proof = prove_same_stock(eng0, plan0, eng1, plan1)
    if not proof.same:  # (the layering's limit, not a bug: the program is refused as it was)
        raise InfeasibleError(f"{refused} — and the program cut in layers would not leave the same part "
                              f"({proof.reason()}), so it is not written in layers", reasons=refused.reasons)
    # per cut, the time its lines take (the layered program's lines counted as the lines they
    # came from: copies, links and comments as the cut's own) at the program's feeds, added
    plan_l = twin.plan(layered)
    came_from = origin[np.asarray(plan_l.seg["line"], np.int64) - 1]

    def within(lines, dur, c):
        return float(dur[(lines >= c.plunge_line) & (lines <= c.last_line)].sum())

    # each segment of the answer says which layer of which cut it is (the report marks it)
    feeds: dict[int, list] = {line: [[] for _ in range(ly.layers)] for line, ly in layerings.items()}
    for seg in res.segments:
        k, n, cut_line = layer_of[seg["lines"][0] - 1]
        if n:
            seg["layer"] = [int(k), int(n)]
            if not seg["air"]:
                feeds[int(cut_line)][k - 1].append(seg["feed_after"])
    res.layers = [ly.as_dict() | {"feeds": [sorted(set(f)) for f in feeds[line]],
                                  "time_added_at_program_feeds":
                                  within(came_from, plan_l.dur, ly.cut) - within(plan0.seg["line"], plan0.dur, ly.cut)}
                  for line, ly in layerings.items()]
    res.stock_proof = proof
    # "before" is the program as written (which breaks the limit), not the layered one at the
    # program's feeds: the verdict says what the limit costs against what the user had (its
    # simulation is the one the refusal was made on)
    orig = refused.before.summary
    c = orig.cutting
    res.before = Figures(float(orig.cycle_time), None, float(c.peak_load if c else 0.0),
                         float(c.peak_power if c else 0.0), None)
    res.warnings.append(f"{program.path}: {len(layerings)} cut(s) written in layers to meet the limit: "
                        + "; ".join(f"lines {ly.cut.plunge_line}-{ly.cut.last_line} in {ly.layers} layers of "
                                    f"{ly.depth_per_layer:.3g} mm" for ly in layerings.values())
                        + f" ({proof.reason()})")
    return res


def _more_layers(twin, program, opts: OptimizeOptions, progress, stock, stage, layerings: dict, best: tuple):
    """N as a discrete variable of the GA's search: per layered cut, one layer more while the
    optimised answer gets better by the objective (a shallower layer may run at a feed so much
    higher that it pays for its link).  Bisection keeps the fewest layers that meet the limit,
    the reference's rule (feed first, then N = 2, 3, …).  Returns (result, layered program,
    origin and layer of its lines) of the best."""
    from .layers import layered_text

    def score(r) -> float:
        f = r.after
        if opts.objective == "cost" and f.cost is not None:
            return f.cost
        if opts.objective == "smooth" and f.power_cv is not None:
            return f.power_cv
        return f.cycle_time

    better = True
    while better:
        better = False
        for ly in layerings.values():
            if ly.layers >= opts.max_layers:
                continue
            ly.layers += 1
            stage(f"trying lines {ly.cut.plunge_line}-{ly.cut.last_line} in {ly.layers} layers")
            text, origin, layer_of = layered_text(program, list(layerings.values()))
            layered = twin.load(text, path=program.path)
            try:
                r = _optimize(twin, layered, opts, progress, stock, stage)
            except MtwinError:  # (infeasible, or a layered program that cannot be read: not better)
                r = None
            # (by more than the re-simulation's own spread: a layer more is moves more)
            if r is not None and score(r) < score(best[0]) * (1 - 1e-3):
                best, better = (r, layered, origin, layer_of), True
            else:
                ly.layers -= 1
    return best


def _optimize(twin, program, opts: OptimizeOptions, progress, stock, stage) -> OptimizeResult:
    """The stages in turn on one run's state; a stage that settles the answer (nothing to set,
    no answer better than the program) returns it, the last one always does."""
    run = _Run(twin=twin, program=program, opts=opts, progress=progress, stock=stock, stage=stage)
    for step in STAGES:
        done = step(run)
        if done is not None:
            return done
    raise AssertionError("the last stage returns the result")


class _Run(SimpleNamespace):
    """One optimisation's state, filled stage by stage (each stage takes what it reads by name
    and puts what later stages read): the program and its simulation (``_baseline``), the
    limits and the problem (``_limits``), the search's feeds and speeds (``_search``), what
    keeps its feed and each segment's tolerance (``_guards``), the written, re-simulated answer
    (``_rounds``)."""

    def take(self, names: str) -> tuple:
        return tuple(getattr(self, n) for n in names.split())

    def put(self, **values) -> None:
        vars(self).update(values)


def _baseline(run: _Run) -> OptimizeResult | None:
    """The program as written: its plan and simulation, the fast model, what the optimiser may set (trusted
    records, ramps), the feed range, the segments and the planner's move times at other feeds."""
    from ..motion.simulate import program_cutting, tool_effects

    opts, program, stage, stock, twin = run.take("opts program stage stock twin")
    t_start = time.perf_counter()
    m = twin.machine
    stage = stage or (lambda text: None)
    stage("simulating the program")
    plan = twin.plan(program, keep_geometry=True)  # (the plans at other feeds below reuse its geometry)
    rec = program.records
    cut = program_cutting(twin, program)
    candidates = feed_records(program)
    ramps = entry_records(program) & candidates if opts.ramp_feed == "keep" else np.zeros(len(rec), bool)
    candidates &= ~ramps
    trust = trusted_records(program, cut, candidates)  # only where the twin knows the cut
    ok = trust.ok
    max_feed = m.max_cutting_feed
    range_warnings: list = []
    if opts.feed_range is None:
        # (a programmed feed above the machine's maximum runs at that maximum: the range is the machine's)
        lo = max(1.0, 0.1 * min(float(rec["feed"][ok].min()), max_feed)) if ok.any() else 1.0
        feed_range = (lo, max_feed)
    else:
        feed_range = _within_machine(opts.feed_range, max_feed, "--feed-range", "mm/min",
                                     "the machine's maximum cutting feed", program.path, range_warnings)
    times_job = None
    if ok.any():
        # the planner's own times at a few uniform feeds over the range (acceleration, jerk and
        # look-ahead over short blocks are in them; a formula in L/F misses them on short moves),
        # planned in a second thread while the program's simulation runs: the kernels of both
        # release the GIL, and the plans need only the path
        levels_f = np.geomspace(feed_range[0], feed_range[1], TIME_LEVELS)
        pool = ThreadPoolExecutor(max_workers=1)
        times_job = pool.submit(lambda: move_times(program, plan, [
            (float(F), twin.plan(program, feeds=np.where(ok, F, rec["feed"]), like=plan)) for F in levels_f]))
        pool.shutdown(wait=False)  # (the job runs on; the executor takes no more)
    before = twin.simulate(program, plan=plan, stock=stock, chatter=False)
    eng = before.engagement  # the one the simulation cut with (computed once, cached on the twin)
    # effects that change the cutting coefficients along the path (tool wear) act on the estimate too
    resolved = [(e, e.resolved()) for e in twin.effects if e.stage == "loop"]
    kstep = tool_effects(eng, plan, resolved, program, twin).coefficients
    model = path_model(twin, program, plan, eng, kstep)
    # the program's own simulation's warnings (a spindle speed clamped to the machine's, a
    # travel limit…) hold for the optimiser's figures too
    warnings: list = list(getattr(before.summary, "warnings", []) or [])
    never = R.is_feed_kind(rec["kind"]) & ~candidates & ~ramps & (R.move_lengths(rec) > 0)
    never_set = {"plunges, canned cycles, parameter feeds (never set)": sorted(set(rec["line"][never].tolist()))} \
        if never.any() else {}
    if ramps.any():
        never_set["ramps and helical entries (feed kept; --ramp-feed optimize sets them)"] = \
            sorted(set(rec["line"][ramps].tolist()))
    if not candidates.any():
        # a drilling program, plunges only, inverse-time feeds: nothing the optimiser sets; in a
        # post-processing pipeline that is not an error — the program goes through unchanged
        return _unchanged(program, before, opts, warnings, dict(never_set), t_start,
                          "no feed move whose feed can be set (G1/G2/G3 in mm/min or in/min that are not plunges, "
                          "canned cycles, synchronised or macro-expression feeds): the program is written unchanged")
    warnings += trust.warnings
    kept = {_undescribed_reason(cut, t): lines for t, lines in trust.undescribed.items()}
    kept.update(never_set)
    if trust.stopped:
        kept["spindle stopped"] = trust.stopped
    if trust.blind:
        kept["cutter compensation of unknown radius"] = trust.blind
    if not ok.any():
        return _unchanged(program, before, opts, warnings, kept, t_start,
                          "no feed move the twin knows the cut of: the program is written unchanged")
    warnings += range_warnings
    spindle_range = opts.spindle_range if opts.objective != "air" else None
    if spindle_range is not None:
        spindle_range = _within_machine(spindle_range, m.spindle.max_speed, "--spindle-range", "rpm",
                                        "the spindle's maximum speed", program.path, warnings)
    if opts.spindle_per == "segment" and spindle_range is not None and not opts.allow_s_changes:
        raise MtwinError("--spindle-per segment changes S in mid-tool: add --allow-s-changes")
    n_step = np.minimum(rec["spindle"][model.rec], m.spindle.max_speed)
    fz0 = rec["feed"][model.rec] / (model.flutes * np.maximum(n_step, 1e-9))  # (units.feed_per_tooth, n > 0)
    power0 = model.torque(fz0) * rad_per_second(n_step)
    # a split move has one speed: with a speed per segment, boundaries stay on move ends
    per_segment_s = opts.spindle_per == "segment" and spindle_range is not None
    segs = segment_path(program, model, power0, ok, min_length=opts.min_segment, method=opts.segmentation,
                        allow_splits=not getattr(program, "is_macro", False) and not per_segment_s)
    times = times_job.result()
    run.put(before=before, candidates=candidates, cut=cut, eng=eng, feed_range=feed_range, fz0=fz0, kept=kept, m=m,
            max_feed=max_feed, model=model, ok=ok, plan=plan, power0=power0, rec=rec, resolved=resolved, segs=segs,
            spindle_range=spindle_range, stage=stage, t_start=t_start, times=times, trust=trust, warnings=warnings)


def _limits(run: _Run) -> OptimizeResult | None:
    """The limits each segment is held to (given per tool, or learned), the problem on the fast model, the
    floor (the program's own feed where it breaks no limit), the refusal of a program over a given limit at
    the lowest feed, and the smoothing target."""
    from ..motion.simulate import tool_effects
    (before, candidates, cut, eng, feed_range, fz0, m, model, ok, opts, plan, power0, program, rec, resolved, segs,
     spindle_range, stage, times, twin, warnings) = \
        run.take("before candidates cut eng feed_range fz0 m model ok opts plan power0 program rec resolved segs "
                 "spindle_range stage times twin warnings")
    # ---- the limits: given (for every tool, or per tool), or learned per tool from the
    # program as written
    user = opts.force_limit
    if isinstance(user, dict):
        unused = sorted(set(user) - set(int(t) for t in np.unique(rec["tool"][candidates])))
        if unused:
            warnings.append(f"{program.path}: warning: --force-limit names "
                            f"{', '.join(f'T{t}' for t in unused)}, which no feed move of the program uses")
    used_tools = sorted(set(int(t) for t in np.unique(rec["tool"][ok])))
    # a twin file's [tools.N] force_limit, under --force-limit
    table = {t: cut.tool(t).force_limit for t in used_tools
             if (t in cut.tools or t in cut.declared) and cut.tool(t).force_limit > 0}
    # limits from physics: the material named, for the tools the twin describes
    phys = _physics(opts, cut, used_tools, program)

    def user_for(tool: int) -> tuple:
        """(the load a user gave this tool, where): --force-limit over the twin file's table."""
        g = user.get(tool) if isinstance(user, dict) else user
        if g is not None:
            return g, "--force-limit"
        return table.get(tool), "twin file tools.N.force_limit"

    def given_for(tool: int):
        g = user_for(tool)[0]
        if tool in phys:
            g = phys[tool].breaking_force if g is None else min(g, phys[tool].breaking_force)
        return g

    given = user if not (table or phys) else {t: given_for(t) for t in used_tools if given_for(t) is not None}
    learned = not given  # every tool's load limit learned
    # the load the program as written puts on a new tool is the load it may have: a tool that
    # starts worn (a ledger's) is held to it, so its feeds come down (docs/wear.md)
    new_tool = model
    worn = any(h.sliding > 0 for h in twin.tool_state.values())
    if learned and worn:
        fresh = twin.replace(tool_state={})
        new_tool = path_model(fresh, program, plan, eng, tool_effects(eng, plan, resolved, program, fresh).coefficients)
    # (learned for every tool: a tool without a given load limit takes its learned one, and the
    # learned chip thickness holds with a given load limit too — a 300 N limit meant for a face
    # mill does not give a 2.4 mm end mill a chip it never ran at)
    levels = learned_levels(new_tool, fz0, ok[model.rec])

    def force_of_tool(tool, diameter):
        g = given_for(int(tool))
        if g is not None:
            return g
        return max(levels[tool][0], 1e-3) if tool in levels else max(m.cost.force_per_diameter * diameter, 1e-3)

    c = m.cost
    rates = CostRates(c.machine_rate, c.labour_rate, c.tool_price, c.tool_replace_time, c.taylor_n, c.taylor_c,
                      slide_life=_slide_life(twin))
    limits = Limits(None, m.spindle.rated_power, m.spindle.base_speed, feed_range, spindle_range, opts.margin)
    prob = build_problem(model, segs, times, power0, program, limits, rates, opts.spindle_per,
                         before.summary.cycle_time, cut.spindle_loss, m.spindle.max_speed, force_of_tool)
    if spindle_range is not None:
        prob = _lock_unwritable_spins(prob, program, segs, warnings)
    seg_given = np.array([given_for(int(t)) is not None for t in prob.seg_tool], bool)
    # finishing passes, and the last pass over a floor or a wall read off the stock the
    # program leaves: the segments that leave a final surface (the guards' and the deflection's)
    fin_seg = _finishing_segments(program, model, segs, prob)
    surface_seg = fin_seg | _surface_segments(program, model, segs, before)
    if phys:
        # the program's own feed per tooth and load per segment (its F and S)
        ev0 = prob.evaluate(prob.f0_var[None, :], fixed_spins(prob)[None, :])
        fz_own, load_own = ev0["fz"], ev0["load"]
        # the chip ceiling of the catalogue for described tools (the others keep their learned
        # one) caps a raise: a segment already above it keeps its own chip as its ceiling, and
        # one lowered for a broken limit goes down only as far as that limit needs
        own_h = prob.chip(fz_own)[0] / (1.0 - opts.margin)
        # (and the level the program proves for the tool — its 95th percentile chip — where that
        # is above the chart's: a shop's proven chip is not cut back by a chart, on any of its cuts)
        cat_h = np.array([max(phys[int(t)].chip, levels[int(t)][1] if int(t) in levels else 0.0) if int(t) in phys
                          else np.nan for t in prob.seg_tool])
        other = np.array([levels[int(t)][1] if int(t) in levels and opts.chip_limit == "learned" else np.inf
                          for t in prob.seg_tool])
        hlim = np.where(np.isnan(cat_h), other, np.maximum(np.nan_to_num(cat_h), own_h))
        prob = replace(prob, seg_hlim=hlim, seg_hchecked=np.where(np.isnan(cat_h), np.inf, hlim))
    elif opts.chip_limit == "learned" or learned:
        prob = replace(prob, seg_hlim=np.array([levels[int(t)][1] if int(t) in levels else np.inf
                                                for t in prob.seg_tool]))
    tool_force = prob.seg_force.copy()  # (each tool's own limit, before the deflection cap on surfaces)
    if phys:
        # on a final surface the shank may bend at most the tolerance: a cap on a raise (a
        # segment already over it at its own feed keeps its own load as the limit)
        own = load_own[0] / (1.0 - opts.margin)
        defl = np.array([phys[int(t)].stiffness * opts.tolerance if int(t) in phys else np.inf
                         for t in prob.seg_tool])
        cap = np.where(surface_seg & np.isfinite(defl), np.maximum(defl, own), np.inf)
        capped = cap < prob.seg_force
        prob = replace(prob, seg_force=np.minimum(prob.seg_force, cap))
        # a capped segment's limit is its own load or the deflection, neither of which may
        # lower it: it counts as given only where the program breaks the tool's own limit
        seg_given &= ~capped | (own * (1.0 - opts.margin) > tool_force)
    if rates.slide_life:
        prob = replace(prob, seg_arc=_segment_arcs(model, segs, prob))
    force_limits = {int(t): float(f) for t, f, g in zip(prob.seg_tool, tool_force, seg_given)
                    if g or int(t) in levels}
    limit_notes = _limit_notes(prob, levels, given_for, opts, m, phys, cut, user_for)
    if spindle_range is not None:
        prob = replace(prob, runups=_runups(prob, program, plan, segs, m))
    if opts.chatter_margin is not None and opts.objective != "air":
        stage("stability lobes")
        chat = chatter_tables(twin, program, model, eng, segs, prob, spindle_range, opts.chatter_margin,
                              opts.chatter_method)
        if chat is not None:
            prob = replace(prob, chatter=chat)
            _chatter_warnings(chat, prob, segs, program, spindle_range, warnings)
    # ---- the floor: no feed goes below the program's own unless a limit the program as
    # written breaks there requires it — a given load limit, the spindle's power or torque, the
    # chatter margin (a learned level is the program's own: it never requires it).  A tool
    # that starts worn is held to its new load, so its floor goes.
    breaks = _breaks_given(prob, seg_given)
    broken = np.zeros(prob.nvar, bool)  # per variable: the program breaks a limit there (its floor is gone)
    np.logical_or.at(broken, prob.seg_var, breaks)
    if opts.objective in ("time", "cost") and not (learned and worn):
        prob = replace(prob, f_floor=np.where(broken, 0.0, prob.f0_var))
    else:
        broken[:] = True  # (no floor: smoothing, the air objective, a worn tool held to its new load)

    # ---- a program that breaks a limit even at the lowest feed is reported, not optimised
    # (with learned limits the program's own feeds are the floor and its own levels the limits)
    spins_try = fixed_spins(prob)
    if spindle_range is not None:
        spins_try = np.full(prob.nspin, spindle_range[1])
    low = prob.evaluate(np.full((1, prob.nvar), feed_range[0]), spins_try[None, :])
    over = (~prob.seg_air) & (((low["load"][0] > prob.seg_force) & (seg_given | worn)) |
                              (low["power"][0] > limits.power))
    if over.any() and opts.objective != "air" and (not learned or worn):
        lines = segs.seg_lines(program)
        reasons = []
        for s in np.flatnonzero(over):
            ld, pw = float(low["load"][0][s]), float(low["power"][0][s])
            which = "load" if ld > prob.seg_force[s] else "spindle power"
            lim_v = float(prob.seg_force[s]) if which == "load" else float(limits.power)
            val = ld if which == "load" else pw
            reasons.append({"limit": which, "segment": int(s), "lines": [lines[s][0], lines[s][-1]],
                            "tool": int(prob.seg_tool[s]), "value": val, "limit_value": lim_v,
                            "unit": "N" if which == "load" else "W", "over_by": val / lim_v - 1.0,
                            "at_feed": feed_range[0], "at_spindle": float(spins_try[prob.seg_spin[s]])})
        parts = [f"segment {r['segment']} (lines {r['lines'][0]}-{r['lines'][1]}, T{r['tool']}): {r['limit']} "
                 f"{_q(r['value'], r['unit'])} over its limit {_q(r['limit_value'], r['unit'])} by "
                 f"{100 * r['over_by']:.0f} %" for r in reasons[:8]]
        raise InfeasibleError(f"{program.path}:{reasons[0]['lines'][0]}: {len(reasons)} segment(s) break a limit even "
                              f"at the lowest feed {feed_range[0]:g} mm/min"
                              + (f" and {spins_try.max():g} rpm" if spindle_range else "") + ": "
                              + "; ".join(parts) + (" …" if len(reasons) > 8 else "")
                              + (" — the tool starts worn (its ledger's history): the land's edge force alone is "
                                 "over the load the program puts on a new tool, which it is held to; change the tool, "
                                 "or give a --force-limit; nothing was written" if learned else
                                 " — the tool's shank would break there (its limit from physics, docs/catalogue.md): "
                                 "take a smaller depth or width of cut, a shorter stick-out (tools.N.stickout) or a "
                                 "stronger tool; nothing was written"
                                 if any(int(r["tool"]) in phys and r["limit"] == "load" for r in reasons) else
                                 " — take a smaller depth or width of cut there, or a larger --force-limit "
                                 "(or leave it out: the limits are then learned from the program); nothing was written"),
                              reasons=reasons, before=before)

    # ---- target power for smoothing
    target = opts.target_power
    if opts.objective == "smooth" and target is None:
        ev0 = prob.evaluate(prob.f0_var[None, :], fixed_spins(prob)[None, :])
        mp = ev0["mean_power"][0][~prob.seg_air]
        if not len(mp):
            raise MtwinError(f"{program.path}: nothing is cut: no power curve to smooth")
        target = float(np.percentile(mp, opts.target_percentile))
    run.put(broken=broken, fin_seg=fin_seg, force_limits=force_limits, given=given, learned=learned,
            limit_notes=limit_notes, limits=limits, phys=phys, prob=prob, rates=rates, seg_given=seg_given,
            surface_seg=surface_seg, target=target, worn=worn)


def _search(run: _Run) -> OptimizeResult | None:
    """Feeds (and speeds) by bisection or the genetic algorithm on the fast model; the floors; air cuts to the
    top of the range; what the objective leaves alone."""
    feed_range, learned, max_feed, opts, prob, progress, spindle_range, stage, target = \
        run.take("feed_range learned max_feed opts prob progress spindle_range stage target")
    # ---- search
    stage("searching")
    generations, history = 0, None
    t_search = time.perf_counter()
    if opts.objective == "air":
        feeds = prob.f0_var.copy()
        air_var = np.zeros(prob.nvar, bool)
        np.logical_or.at(air_var, prob.seg_var, prob.seg_air)
        cut_var = np.zeros(prob.nvar, bool)
        np.logical_or.at(cut_var, prob.seg_var, ~prob.seg_air)
        top = max_feed if opts.feed_range is None else feed_range[1]
        feeds = np.where(air_var & ~cut_var, np.maximum(top, feeds), feeds)
        spins = prob.n0_spin.copy()
    elif opts.method == "bisect":
        res = bisect(prob, opts.objective, target, opts.power_tolerance)
        feeds, spins = res.feeds, res.spins
    else:
        seeds = [(prob.f0_var, fixed_spins(prob))]
        try:
            b = bisect(prob, "time" if opts.objective == "cost" else opts.objective, target, opts.power_tolerance)
            seeds.append((b.feeds, b.spins))
        except ValueError:
            pass
        if spindle_range is not None:
            # and the fastest feeds at the top and the middle of the speed range
            for n in (spindle_range[1], 0.5 * (spindle_range[0] + spindle_range[1])):
                sp = np.full(prob.nspin, n)
                f = prob.max_feasible_feed(sp)
                seeds.append((np.where(np.isnan(f), feed_range[0], f), sp))
        res = genetic(prob, opts.objective, opts.ga, seeds, target, progress)
        feeds, spins = res.feeds, res.spins
        generations, history = res.generations, res.history
    search_seconds = time.perf_counter() - t_search
    if learned and spindle_range is not None and opts.objective in ("time", "cost"):
        # the program's feeds are the floor: at a lower speed they would be a larger feed per
        # tooth than the program's own, so no tool runs below its programmed speed (a higher
        # speed at the same feed only thins the chip; the re-simulation checks the rest)
        raised = np.maximum(spins, np.minimum(prob.n0_spin, spindle_range[1]))
        # (not where the programmed speed would chatter: the search moved it to a stable one)
        spins = raised if prob.chatter is None else np.where(var_stable(prob.chatter, prob, raised), raised, spins)
    air_var = np.zeros(prob.nvar, bool)
    np.logical_or.at(air_var, prob.seg_var, prob.seg_air)
    cut_var = np.zeros(prob.nvar, bool)
    np.logical_or.at(cut_var, prob.seg_var, ~prob.seg_air)
    floor = np.full(prob.nvar, feed_range[0])
    if prob.f_floor is not None:
        floor = np.maximum(floor, prob.floor_feeds(np.round(spins)))
        feeds = np.maximum(feeds, floor)
    if opts.objective in ("time", "cost"):
        # air segments at the top of the range (the load is zero there), never above it
        feeds = np.where(air_var & ~cut_var, feed_range[1], feeds)
    # variables the objective leaves alone keep every record's own programmed feed
    keep = np.zeros(prob.nvar, bool)
    if opts.objective == "air":
        keep = cut_var.copy()
    elif opts.objective == "smooth":
        keep = air_var & ~cut_var
    run.put(air_var=air_var, cut_var=cut_var, feeds=feeds, floor=floor, generations=generations, history=history,
            keep=keep, search_seconds=search_seconds, spins=spins)


def _guards(run: _Run) -> OptimizeResult | None:
    """What keeps its feed: air under a guessed stock, finishing passes, approaches into a cut; the contour
    tolerance of each segment (final surface or roughing)."""
    (air_var, before, candidates, cut, cut_var, feeds, keep, kept, opts, prob, program, rec, segs,
     spindle_range, spins, stock, trust, warnings) = \
        run.take("air_var before candidates cut cut_var feeds keep kept opts prob program rec segs "
                 "spindle_range spins stock trust warnings")
    # an air cut under a stock the twin only guessed is raised only where the tool is provably
    # clear of that stock: the guess may hold material the program really cuts
    stock_box = before.summary.cutting.stock if before.summary.cutting else None
    stock_guessed = stock is None and before.summary.cutting is not None and \
        before.summary.cutting.stock_source == GUESSED_STOCK
    # the height from which the program itself descends slowly: above it, it treats the space
    # as clear (guards.feed_height); only above the stock's top, guessed or given
    clear_z = feed_height(program)
    if stock_box is None or not clear_z > float(stock_box[5]):
        clear_z = math.inf
    # the height above which a move cannot touch the part: the program's own feed height, or a
    # given (not guessed) stock's top — a following error there moves the tool in air
    clear_level = clear_z if stock_guessed or stock_box is None else min(clear_z, float(stock_box[5]))
    # plunges whose upper part is proven air run it at the air feed, and their own feed from
    # just above the material they can meet (guards.air_entries)
    entries = _air_entries(run, clear_z, None if stock_guessed or stock_box is None else float(stock_box[5]))
    if entries:
        plunge_key = "plunges, canned cycles, parameter feeds (never set)"
        split_lines = {e.line for e in entries.values()}
        if plunge_key in kept:
            kept[plunge_key] = [ln for ln in kept[plunge_key] if ln not in split_lines]
            if not kept[plunge_key]:
                del kept[plunge_key]
    if stock_guessed:
        # inside the guessed block, a move is air only because earlier cuts removed the material
        # there, which they also do on the machine, whatever the real stock's size — provided
        # the twin knew the tools that cut it: after a cut by an undescribed tool (an imaginary
        # 6 mm end mill), "air" may be material the real, smaller tool left.  Above the guessed
        # top (Z0) or outside the block, "air" is only the guess's word: a router whose Z0 is
        # the table cuts at Z > 0
        inside = inside_stock(program, cut, stock_box)
        undescribed_cut = candidates & ~trust.ok & np.isin(rec["tool"], list(trust.undescribed))
        first_unknown = int(np.argmax(undescribed_cut)) if undescribed_cut.any() else len(rec)
        known_air = inside & (np.arange(len(rec)) < first_unknown)
        # where the program's own horizontal rapids passed at or below a move, it is clear of
        # any stock, guessed or real (guards.proven_clear)
        known_air |= proven_clear(program, cut)
        # and above the height it descends to fast before it slows to plunge, the top of its
        # feed moves (guards.feed_height): there it moves as it rapids
        if math.isfinite(clear_z):
            known_air |= np.minimum(rec["z"], rec["sz"]) >= clear_z - 1e-6
        # a straight retract (up, no XY motion) stays in the tool's own footprint, which it came
        # down through: it cuts nothing, whatever the stock
        known_air |= (rec["z"] > rec["sz"]) & (np.hypot(rec["x"] - rec["sx"], rec["y"] - rec["sy"]) < 1e-6) & \
            (rec["kind"] == R.LINEAR)
        var_known = np.ones(prob.nvar, bool)
        np.logical_and.at(var_known, prob.seg_var[segs.piece_seg], known_air[segs.piece_rec])
        unclear = air_var & ~cut_var & ~var_known & ~keep
        if unclear.any():
            keep |= unclear
            kept["air cut under a guessed stock"] = _var_lines(program, segs, prob, unclear)
            warnings.append(f"{program.path}: warning: the stock was {GUESSED_STOCK}: "
                            f"{int(unclear.sum())} air-cut segment(s) outside or above it, or after a cut by an "
                            f"undescribed tool, keep their feeds; give the stock (--stock, (MTWIN STOCK …) or "
                            f"cutting.stock) or declare the tool (--tool) to let them be raised")
    # a line that runs at several programmed feeds (a subprogram called after different F
    # words, a loop whose feed its body changes) takes its feed from its caller: one F word on
    # it cannot give each run its own, and a word added to it would change every run
    inherited = _caller_fed(program, segs, prob) & ~keep
    if inherited.any():
        keep |= inherited
        kept["runs at its caller's feeds (a subprogram or loop entered at several feeds)"] = \
            _var_lines(program, segs, prob, inherited)
    # finishing passes keep their feed per tooth
    fin_var = np.zeros(prob.nvar, bool)
    if opts.finish_feed in ("keep", "auto") and opts.objective != "air":
        fin_seg = run.fin_seg.copy()
        if opts.finish_feed == "auto" and run.phys:
            fin_seg &= ~np.isin(prob.seg_tool, list(run.phys))
        np.logical_or.at(fin_var, prob.seg_var, fin_seg)
        fin_var &= ~keep
        if fin_var.any():
            kept["finishing pass (feed per tooth kept)"] = _var_lines(program, segs, prob, fin_var)
            vs = prob.var_spin
            feeds = np.where(fin_var, prob.f0_var * np.round(spins)[vs] / np.maximum(prob.n0_spin[vs], 1e-9), feeds)
            if spindle_range is None:
                keep |= fin_var
    feeds = _approach_feeds(prob, segs, feeds, program, keep, clear_z)

    # accuracy where it reaches the part: the tolerance on segments that leave a final surface,
    # the roughing allowance on the others
    surface_var = np.zeros(prob.nvar, bool)
    np.logical_or.at(surface_var, prob.seg_var, run.surface_seg)
    rough = max(ROUGH_TOLERANCE, opts.tolerance) if opts.rough_tolerance is None else opts.rough_tolerance
    tol_v = np.where(surface_var, opts.tolerance, rough)
    run.put(clear_level=clear_level, clear_z=clear_z, entries=entries, feeds=feeds, fin_var=fin_var, keep=keep,
            kept=kept, rough=rough, surface_var=surface_var,
            tol_v=tol_v)


def _rounds(run: _Run) -> OptimizeResult | None:
    """Write, verify and re-simulate until the limits and the accuracy hold on the full twin: a guard lowers a
    feed below the program's own only for a limit the program breaks there."""
    from ..gcode.verify import compare
    from ..gcode.writer import rewrite
    from ..motion.simulate import share_cutting
    (before, broken, cut, entries, feed_range, feeds, floor, keep, kept, learned, limit_notes, limits, opts, prob,
     program, rec, seg_given, segs, spindle_range, spins, stage, stock, t_start, tol_v, twin, warnings, worn) = \
        run.take("before broken cut entries feed_range feeds floor keep kept learned limit_notes limits opts prob "
                 "program rec seg_given segs spindle_range spins stage stock t_start tol_v twin warnings worn")
    entries = dict(entries)
    # per record, the height above which its following error moves the tool in air: the clear
    # level, or the material a plunge in air all the way is proven to stay above
    air_floor = np.full(len(rec), run.clear_level)
    for r, e in entries.items():
        if e.whole:
            air_floor[r] = min(air_floor[r], e.material)
    # ---- write, verify, re-simulate: the limits and the accuracy are held on the full twin.
    # A guard lowers a feed below the program's own only for a limit the program itself breaks
    # there (its floor is gone); for anything else — a move after it entered faster, accuracy —
    # it goes at most back to the program's own feed, where the program was fine
    round_ = 0
    # under the LinuxCNC planner the written program's blends differ from the estimate's:
    # its engagement is computed afresh (once: the rounds change only feeds)
    tw_after = _fresh(twin) if twin.machine.controller.style == "linuxcnc" else twin
    f0 = prob.f0_var
    lo = feed_range[0]
    # per variable, the load's and the machine's (spindle power, torque) ratios to their limits
    # a segment may reach: 1, or what the program itself runs at where it only must not get
    # worse — each on its own (a load the program runs over its learned level allows no power
    # over the spindle's rating)
    allowed_l = np.ones(prob.nvar)
    allowed_m = np.ones(prob.nvar)
    base_outside = None
    force_min = 1.0
    cap = np.full(prob.nvar, np.inf)
    cur = feeds.copy()
    lowered_for = np.full(prob.nvar, "", dtype=object)  # what a guard lowered each variable for
    c_prev = np.full(prob.nvar, np.nan)  # the last round's contour error and feed, per variable
    f_prev = np.full(prob.nvar, np.nan)
    prev = _previous_var(segs, prob)  # the segment run just before each variable's first
    var_given = np.zeros(prob.nvar, bool)
    np.logical_or.at(var_given, prob.seg_var, seg_given)
    ce_before = contour_error(before)
    loads_before = _Loads.of(before, limits)
    settled_back = False
    while True:
        round_ += 1
        stage(f"writing and re-simulating (round {round_})")
        f_try = _round_feeds(np.minimum(np.maximum(cur, floor), cap), f0, program, segs, prob)
        f_try = np.where(keep, f0, f_try)
        s_try = np.round(spins)
        feeds_rec, splits, spins_rec = _expand(program, segs, f_try, _unlocked(prob, s_try), prob,
                                               spindle_range is not None, keep,
                                               entries, feed_range[1])
        out = rewrite(program, feeds_rec, spins_rec, splits)
        new = twin.load(out, path=program.path)
        # the writer changed F and S words only: the tools the comments declare are the same
        share_cutting(tw_after, new, program)
        diff = compare(program, new)  # the check of `mtwin verify`
        if diff is not None:
            raise VerifyError(f"internal error: the optimised program does not cut the same path: {diff}")
        if out == bytes(program.data):
            after = before  # nothing changed: the program's own simulation is the answer's
        else:
            after = tw_after.simulate(new, stock=stock, chatter=False)
        seg_after, rec_after = _segment_of_samples(after, new, program, segs)
        loads_after = loads_before if after is before else _Loads.of(after, limits)
        after_l, after_m = _ratio_pair(loads_after, prob, seg_after)
        chip_v = _chip_ratios(loads_after, prob, seg_after)
        ce_after = ce_before if after is before else contour_error(after)
        if round_ == 1:
            seg_before, rec_before = _segment_of_samples(before, program, program, segs)
            force_min = float(prob.seg_force.min()) if len(prob.seg_force) else 1.0
            base_outside = _outside_ratios(loads_before, seg_before, rec_before, len(rec), force_min)
            cb = _reaching(ce_before, before, rec_before, air_floor)
            contour_before = _per_var(cb, seg_before, prob)
            contour_rec_before = _per_rec(cb, seg_before, rec_before, program)
            own_l, own_m = (r * 1.001 for r in _ratio_pair(loads_before, prob, seg_before))
            # the chip ceilings from physics cap a raise only: a segment may keep its own chip
            chip_ok = np.maximum(1.0, _chip_ratios(loads_before, prob, seg_before) * 1.001)
            # what the program runs at on a learned level, on a kept segment, or (the air
            # objective) on a cut it leaves alone is its own: it must only not get worse
            # (not a tool that starts worn: it is held to the load of a new tool, docs/wear.md)
            own_ok = (~var_given & ~(learned and worn)) | keep
            if opts.objective == "air":
                own_ok[:] = True
            allowed_l = np.where(own_ok, np.maximum(allowed_l, own_l), allowed_l)
            allowed_m = np.where(own_ok, np.maximum(allowed_m, own_m), allowed_m)
            own = np.maximum(own_l / allowed_l, own_m / allowed_m)  # over 1: the program breaks a limit there
        over_v = np.maximum(after_l / allowed_l, after_m / allowed_m)  # (over 1: over what is allowed)
        raised = (f_try > f0 * (1 + 1e-9)) & ~keep
        at_floor = (f_try <= floor * (1 + 1e-9)) | keep
        # 1. the limits on each segment itself
        over = (over_v > 1.0) & ~keep
        # at its own feed over a given limit it also breaks in the program: its floor goes
        # — or over a given limit with no raised segment before it to blame: its own entry is
        # over the limit in the written program, so it must come down too
        prev_raised = (prev >= 0) & raised[np.maximum(prev, 0)]
        drop = over & at_floor & (floor > lo) & ((own > 1.0) | (var_given & ~prev_raised))
        if drop.any():
            floor = np.where(drop, lo, floor)
            broken |= drop
            at_floor &= ~drop
        blame = np.zeros(prob.nvar)
        # at its floor over a limit the program did not break there: the faster segment before
        # it brought the load in (its entry), and that one is slowed
        for v in np.flatnonzero(over & at_floor):
            if prev[v] >= 0:
                blame[prev[v]] = max(blame[prev[v]], float(over_v[v]))
        # moves outside the segments (plunges, canned cycles, rapids) keep their feeds, but a
        # faster move before them changes how they are entered: each must stay within the
        # limits, or within what it had in the program; otherwise the segment before is slowed
        out_now = _outside_ratios(loads_after, seg_after, rec_after, len(rec), force_min)
        worse = out_now > np.maximum(1.0, base_outside * 1.01)
        if worse.any():
            blame = np.maximum(blame, _blame_previous(seg_after, rec_after, worse, prob,
                                                      out_now / np.maximum(1.0, base_outside)))
        # 2. accuracy: the contour error in a segment, and in the moves outside after it
        ca = _reaching(ce_after, after, rec_after, air_floor)
        contour_after = _per_var(ca, seg_after, prob)
        # (on every segment, kept ones too: a kept segment entered faster by a raised one before
        # it loses accuracy to that one, which is slowed)
        c_ratio = contour_after / np.maximum(contour_before + tol_v, 1e-12)
        c_rec = _per_rec(ca, seg_after, rec_after, program)
        c_worse = c_rec > contour_rec_before + opts.tolerance
        cblame = np.zeros(prob.nvar)
        if c_worse.any():
            excess = np.concatenate([c_rec / np.maximum(contour_rec_before + opts.tolerance, 1e-12),
                                     np.zeros(len(rec))])
            cblame = _blame_previous(seg_after, rec_after, np.concatenate([c_worse, np.zeros(len(rec), bool)]),
                                     prob, excess)
        # a segment not raised that lost accuracy lost it to the raised segment run before it
        for v in np.flatnonzero(~raised & (c_ratio > 1.0)):
            if prev[v] >= 0:
                cblame[prev[v]] = max(cblame[prev[v]], float(c_ratio[v]))
        # a plunge entered faster through its air that is worse for it (load or contour) keeps
        # its feed all the way: the air proof had too little margin for this machine
        missed = [r for r in entries if worse[r] or worse[len(rec) + r] or c_worse[r]]
        if missed:
            for r in missed:
                kept.setdefault("plunges, canned cycles, parameter feeds (never set)", []).append(entries.pop(r).line)
            continue
        load_bad = over & ~at_floor
        chip_bad = (chip_v > chip_ok) & raised & ~load_bad
        blame_bad = (blame > 1.0) & raised
        acc_bad = (c_ratio > 1.0) & raised
        cblame_bad = (cblame > 1.0) & raised
        bad = load_bad | chip_bad | blame_bad | acc_bad | cblame_bad
        if not bad.any():
            break
        if round_ >= opts.max_rounds:
            if not settled_back:
                # the raised segments that would not settle (and the ones run just before them)
                # go back to the program's own feeds, and one more round checks
                back = (bad & raised) | np.isin(np.arange(prob.nvar), prev[bad & (prev >= 0)]) & raised
                keep |= back
                if back.any():
                    kept["would not settle (program's feed)"] = _var_lines(program, segs, prob, back)
                cur = np.where(back, f0, cur)
                settled_back = True
                if not (load_bad & ~back).any():
                    continue
            if not (load_bad & broken).any():
                # nothing the program breaks is left over: the program as it was is the answer
                return _unchanged(program, before, opts, warnings, kept, t_start,
                                  f"after {round_} rounds the re-simulated answer still broke a limit or the contour "
                                  f"tolerance: the program is written unchanged", limit_notes)
            lines = segs.seg_lines(program)
            where = [f"lines {lines[np.flatnonzero(prob.seg_var == v)[0]][0]}-"
                     f"{lines[np.flatnonzero(prob.seg_var == v)[0]][-1]}" for v in np.flatnonzero(bad)[:6]]
            raise MtwinError(f"{program.path}: after {round_} rounds the re-simulated program still exceeds a limit "
                             f"or the contour tolerance in {int(bad.sum())} segment(s) ({', '.join(where)}); nothing "
                             f"was written")
        # the load is f_z·a + b, not proportional to the feed: after the first round the
        # correction is squared, so a segment with a large edge term still converges
        power = 1.0 if round_ == 1 else 2.0
        new_f = cur.copy()
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio_l = np.where(over, over_v, 1.0)
            # a limit on the segment itself: as low as it needs, down to its floor
            new_f = np.where(load_bad, np.minimum(new_f, f_try / ratio_l ** power * (1 - opts.margin)), new_f)
            lowered_for = np.where(load_bad, "load", lowered_for)
            # the chip ceiling (linear in the feed): down to it, at most back to the program's feed
            f_chip = np.maximum(f0, f_try / np.maximum(chip_v / chip_ok, 1.0) * (1 - opts.margin))
            new_f = np.where(chip_bad, np.minimum(new_f, f_chip), new_f)
            lowered_for = np.where(chip_bad, "chip thickness", lowered_for)
            # the entry of the move after it: at most back to the program's own feed
            back_to = np.maximum(f0, 0.0)
            f_blame = np.maximum(back_to, f_try / np.maximum(blame, 1.0) ** power * (1 - opts.margin))
            new_f = np.where(blame_bad, np.minimum(new_f, f_blame), new_f)
            lowered_for = np.where(blame_bad & ~load_bad, "entry into the next move", lowered_for)
            # accuracy: the feed where the chord from the program's (feed, contour error) to
            # this round's reaches the tolerance — the error grows faster than linearly with the
            # feed, so the chord's answer is on the safe side; from the second round the secant
            # through the last two rounds' points (an error that jumps as soon as a segment is
            # raised at all, then grows slowly, is undershot by the chord)
            target_c = contour_before + 0.9 * tol_v
            grew = contour_after > contour_before + 1e-9
            frac_c = np.clip((target_c - contour_before) / np.maximum(contour_after - contour_before, 1e-12), 0.0, 1.0)
            f_acc = f0 + (f_try - f0) * np.where(grew, frac_c, 0.0)
            two = acc_bad & np.isfinite(c_prev) & (c_prev > contour_after + 1e-9) & (f_prev > f_try * 1.001)
            slope = (c_prev - contour_after) / np.maximum(f_prev - f_try, 1e-9)
            f_sec = f_try - (contour_after - target_c) / np.maximum(slope, 1e-12)
            f_acc = np.where(two, np.clip(f_sec, f0, f_try), f_acc)
            c_prev = np.where(acc_bad, contour_after, np.nan)
            f_prev = np.where(acc_bad, f_try, np.nan)
            f_cb = np.maximum(f0, f_try / np.maximum(cblame, 1.0) ** power)
            acc_f = np.where(acc_bad, f_acc, np.where(cblame_bad, f_cb, np.inf))
            new_f = np.minimum(new_f, np.maximum(acc_f, f0))
            lowered_for = np.where((acc_bad | cblame_bad) & ~load_bad & ~blame_bad, "accuracy (contour error)",
                                   lowered_for)
            if round_ >= opts.max_rounds - 3:
                # accuracy that slowing has not brought back: the program's own feed
                stuck = (acc_bad | cblame_bad) & ~load_bad
                cap = np.where(stuck, np.minimum(cap, f0), cap)
        cur = _approach_feeds(prob, segs, new_f, program, keep, run.clear_z)
    run.put(after=after, broken=broken, entries=entries, ce_after=ce_after, ce_before=ce_before,
            contour_after=contour_after, contour_before=contour_before, f0=f0, f_try=f_try, keep=keep, kept=kept,
            loads_after=loads_after, loads_before=loads_before, lowered_for=lowered_for, new=new, out=out,
            prev=prev, round_=round_, s_try=s_try, seg_after=seg_after, seg_before=seg_before, tw_after=tw_after,
            var_given=var_given)


def _result(run: _Run) -> OptimizeResult | None:
    """The promise checked from outside the rounds (not slower for nothing, nothing lowered without a broken
    limit, the contour held), the labels, and the result."""
    (after, before, broken, ce_after, ce_before, contour_after, contour_before, f0, f_try, feed_range, fin_var,
     force_limits, generations, given, history, keep, kept, learned, limit_notes, loads_after, loads_before,
     lowered_for, new, opts, out, prev, prob, program, rates, rough, round_, s_try, search_seconds, seg_after,
     seg_before, segs, spindle_range, surface_var, t_start, times, tol_v, tw_after, twin, var_given, warnings, worn) = \
        run.take("after before broken ce_after ce_before contour_after contour_before f0 f_try feed_range fin_var "
                 "force_limits generations given history keep kept learned limit_notes loads_after loads_before "
                 "lowered_for new opts out prev prob program rates rough round_ s_try search_seconds seg_after "
                 "seg_before segs spindle_range surface_var t_start times tol_v tw_after twin var_given warnings worn")
    est = prob.evaluate(f_try[None, :], s_try[None, :])
    fig_before = _figures(before, program, segs, prob, rates, seg_before, loads_before.load)
    fig_after = _figures(after, new, segs, prob, rates, seg_after, loads_after.load)
    # (a segment is held to its tolerance where it, or the segment run before it, was raised:
    # elsewhere its contour error is the program's own)
    raised_v = (f_try > f0 * (1 + 1e-9)) & ~keep
    touched = raised_v | ((prev >= 0) & raised_v[np.maximum(prev, 0)])
    contour_held = (contour_after <= contour_before + tol_v + 1e-9) | ~touched
    contour = {"before": float(np.max(ce_before[seg_before >= 0], initial=0.0)),
               "after": float(np.max(ce_after[seg_after >= 0], initial=0.0)), "tolerance": opts.tolerance,
               "rough_tolerance": rough, "segments_held": int(contour_held.sum()),
               "worst_segment_increase": float(np.max(contour_after - contour_before, initial=0.0))}
    chatter = {}
    if prob.chatter is not None:
        # the answer's own margins, line by line (the rounds' re-simulations skipped them)
        from ..motion.simulate import chatter_table, program_cutting

        if after.summary.cutting is not None:
            after.summary.cutting.chatter = chatter_table(tw_after.machine, program_cutting(tw_after, new), new,
                                                          tw_after.plan(new), after.engagement)
        on = seg_after >= 0
        line_segs: dict = {}
        for ln, sg in np.unique(np.stack([np.asarray(after.line)[on], seg_after[on]], axis=1), axis=0):
            line_segs.setdefault(int(ln), []).append(int(sg))
        chatter = chatter_report(prob.chatter, prob, segs, program, fixed_spins(prob), s_try, after.summary,
                                 line_segs)
    fixes_chatter = bool(chatter) and any(r["margin_before"] is not None and r["margin_before"] > prob.chatter.margin
                                          for r in chatter["segments"])
    if fixes_chatter and _worse(opts.objective, fig_before, fig_after):
        warnings.append(f"{program.path}: warning: the answer is {'slower' if opts.objective == 'time' else 'dearer'} "
                        f"than the program ({fig_before.cycle_time:.2f} -> {fig_after.cycle_time:.2f} s): its "
                        f"spindle speeds move to where the cuts are stable (the program's would chatter)")
    if chatter.get("check", {}).get("lines_over_margin"):
        over = chatter["check"]["lines_over_margin"]
        warnings.append(f"{program.path}: warning: on the re-simulated answer, line(s) "
                        f"{', '.join(map(str, over[:10]))}{f' and {len(over) - 10} more' if len(over) > 10 else ''} "
                        f"are over the chatter margin {prob.chatter.margin:g} at their speeds")
    # lowered below the program's own feed for a limit the program breaks there (named)
    # (a spindle range that excludes the program's own speed is a given limit it breaks: a feed
    # held to its feed per tooth at the lower speed is what that range asks for)
    off_range = np.zeros(prob.nvar, bool)
    if spindle_range is not None:
        n0 = prob.n0_spin[prob.var_spin]
        off_range = (n0 < spindle_range[0] - 0.5) | (n0 > spindle_range[1] + 0.5)
    required = (f_try < f0 * (1 - 1e-9)) & (broken | off_range) & ~keep
    own_load = _ratio_pair(loads_before, prob, seg_before)[0]
    slower_because = _slower_because(prob, segs, program, required, own_load, var_given, off_range, spindle_range,
                                     learned and worn)
    if not fixes_chatter and _worse(opts.objective, fig_before, fig_after) and opts.objective in ("time", "cost"):
        figs = (f"{fig_before.cycle_time:.2f} -> {fig_after.cycle_time:.2f} s" if opts.objective == "time" else
                f"cost {fig_before.cost:.3f} -> {fig_after.cost:.3f}")
        what = "slower" if opts.objective == "time" else "dearer"
        if not slower_because:
            # nothing the program breaks asks for a slower program: it stays as it was
            return _unchanged(program, before, opts, warnings + [
                f"{program.path}: warning: the re-simulated answer was {what} than the program "
                f"({figs}): the program is written unchanged"],
                kept, t_start, "", limit_notes)
        warnings.append(f"{program.path}: warning: the answer is {what} than the program ({figs}): the program "
                        f"breaks " + "; ".join(r["text"] for r in slower_because[:6])
                        + (" …" if len(slower_because) > 6 else "") + " — those segments are slowed to the limit")
    # the promise on every written answer, held from outside the rounds: no raised segment
    # less accurate than its tolerance allows, nothing lowered below its own feed that no
    # broken limit asks for
    # (below the program's feed per tooth, where a spindle range lowers S: one rounding step)
    fz_floor = f0 * np.minimum(1.0, s_try[prob.var_spin] / np.maximum(prob.n0_spin[prob.var_spin], 1e-9))
    unasked = (f_try < fz_floor - 2.55) & ~required & ~keep
    if unasked.any() and opts.objective in ("time", "cost"):
        raise VerifyError(f"internal error: {int(unasked.sum())} segment(s) were written below the program's own "
                          f"feed with no limit the program breaks there (lines "
                          f"{', '.join(map(str, _var_lines(program, segs, prob, unasked)[:8]))}); nothing was written")
    if not contour_held.all():
        raise VerifyError(f"internal error: {int((~contour_held).sum())} segment(s) raised, or after a raised one, "
                          f"are less accurate than the tolerance allows on the re-simulated answer (lines "
                          f"{', '.join(map(str, _var_lines(program, segs, prob, ~contour_held)[:8]))}); nothing was "
                          f"written")
    lines = segs.seg_lines(program)
    keep_why = _keep_reasons(program, segs, prob, keep, kept)
    approach_cap = _approach_feeds(prob, segs, np.full(prob.nvar, feed_range[1]), program, keep,
                                   run.clear_z) < feed_range[1] - 1
    limited = _limited_by(prob, f_try, s_try, feed_range, times, segs, keep, keep_why, lowered_for, approach_cap)
    fin_seg = fin_var[prob.seg_var]
    ev_before = prob.evaluate(prob.f0_var[None, :], fixed_spins(prob)[None, :])
    seg_info = []
    for s in range(segs.count):
        v = prob.seg_var[s]
        why = limited[s]
        if fin_seg[s] and not keep[v]:
            why = "finishing pass (feed per tooth kept)"
        seg_info.append({"lines": [lines[s][0], lines[s][-1]], "air": bool(prob.seg_air[s]), "tool": int(prob.seg_tool[s]),
                         "feed_before": float(prob.f0_var[v]), "feed_after": float(f_try[v]),
                         "spindle_after": float(s_try[prob.seg_spin[s]]), "limited_by": why,
                         "finishing": bool(fin_seg[s]), "final_surface": bool(surface_var[v]),
                         "contour_tolerance": float(tol_v[v]), "contour_held": bool(contour_held[v]),
                         "mean_power_before": float(ev_before["mean_power"][0][s]),
                         "mean_power_after": float(est["mean_power"][0][s]),
                         "peak_load_estimate": float(est["load"][0][s]),
                         "contour_error_before": float(contour_before[v]),
                         "contour_error_after": float(contour_after[v])})
    # (with learned limits the load limit is not the binding knob — the chip thickness and the
    # program's own feeds are — so a curve over the load limit alone would mislead)
    tradeoff = _tradeoff(prob, s_try) if opts.objective in ("time", "cost") and isinstance(opts.force_limit, (int, float)) \
        else []
    phys = run.phys
    tradeoff_scale = []
    if phys and opts.objective in ("time", "cost") and opts.tradeoff_resimulated:
        run.stage("the trade-off against the physics limits")
        tradeoff_scale = _scale_tradeoff(run, est, fig_after)
    changed = _changed_lines(program.data, out)
    spindle_chosen = {}
    if spindle_range is not None:
        for s in range(segs.count):
            spindle_chosen.setdefault(int(prob.seg_tool[s]), float(s_try[prob.seg_spin[s]]))
    # (the fast model has the segments; a plunge's air at the air feed, L/F, is taken off its own)
    air_saved = sum((e.z_from - e.z_air) * 60.0 * (1.0 / float(program.records["feed"][r]) -
                                                     1.0 / float(feed_range[1])) for r, e in run.entries.items())
    estimate = {"cycle_time": float(est["time"][0]) - air_saved, "cost": float(est["cost"][0]),
                "peak_load": float(est["load"][0][~prob.seg_air].max(initial=0.0)),
                "peak_power": float(est["power"][0][~prob.seg_air].max(initial=0.0))}
    return OptimizeResult(
        output=out, objective=opts.objective, method=opts.method if opts.objective != "air" else "direct",
        before=fig_before, after=fig_after, estimate=estimate, changed_lines=changed, segments=seg_info,
        verified=True, rounds=round_, evaluations=prob.evaluations, seconds=time.perf_counter() - t_start,
        force_limit=force_limits, tradeoff=tradeoff, trace_before=before, trace_after=after, seg_before=seg_before,
        seg_after=seg_after, warnings=warnings, generations=generations, history=history,
        force_limit_source="" if not learned else "learned from the program (95th percentile of each tool's "
        "engaged steps at its programmed F and S); --force-limit sets one",
        defaults=list(before.summary.cutting.defaults or []), search_seconds=search_seconds, limits=limit_notes,
        kept=kept, contour_error=contour, spindle=spindle_chosen,
        tool_wear=_wear_warnings(wear_plan(twin, after), warnings), chatter=chatter,
        chatter_curves={} if prob.chatter is None else {t: (prob.chatter.grid, c) for t, c in prob.chatter.curves.items()},
        slower_because=[{k: v for k, v in r.items() if k != "text"} for r in slower_because],
        tradeoff_scale=tradeoff_scale,
        air_entries=[{**e.as_dict(), "air_feed": float(feed_range[1]), "feed": float(program.records["feed"][r])}
                     for r, e in sorted(run.entries.items())])


STAGES = (_baseline, _limits, _search, _guards, _rounds, _result)


def _undescribed_reason(cut, tool: int) -> str:
    """Why a tool's moves keep their feeds: nothing describes it, or the program declares a
    tool the cutting model cannot represent (a drill) — as ``simulate`` says it."""
    note = next((d for d in cut.defaults_used if d.startswith(f"tool T{tool}: declared as ")), None)
    if note is None:
        return f"tool T{tool} not described"
    return f"tool T{tool} not modelled ({note.split(': ', 1)[1].split(' (line')[0]})"


def _breaks_given(prob, seg_given: np.ndarray) -> np.ndarray:
    """Per segment: does the program at its own F and S break a limit that is not its own — a
    given load limit (``seg_given``), the spindle's power or torque, the chatter margin?"""
    ev = prob.evaluate(prob.f0_var[None, :], fixed_spins(prob)[None, :])
    over = 1.0 / (1.0 - prob.limits.margin) - 1.0 + 1e-9  # (the excess is over the limit x (1 - margin))
    return (~prob.seg_air) & (((ev["v_load"][0] > over) & seg_given) | (ev["v_power"][0] > over) |
                              (ev["v_torque"][0] > over) | (ev["v_chatter"][0] > 1e-9))


def _chatter_warnings(chat, prob, segs, program, spindle_range, warnings: list) -> None:
    """Segments no allowed speed makes stable: with a spindle range the CAM must take less
    depth; without one, the programmed speed chatters (a range may find a stable pocket)."""
    lines = segs.seg_lines(program)
    bad = np.flatnonzero(chat.unstable)
    for s in bad[:12]:
        where = f"{program.path}:{lines[s][0]}: warning: lines {lines[s][0]}-{lines[s][-1]} (T{prob.seg_tool[s]}, " \
                f"axial depth {chat.seg_ap[s]:.2f} mm)"
        if spindle_range is None:
            warnings.append(f"{where} chatter at the programmed {chat.best_speed[s]:.0f} rpm (over the margin "
                            f"{chat.margin:g}): give --spindle-range to let S move into a stable pocket, or take at "
                            f"most {chat.best_ap[s]:.2f} mm there")
        else:
            warnings.append(f"{where} chatter at every allowed speed with the margin {chat.margin:g}: the CAM must "
                            f"take a smaller depth (at most {chat.best_ap[s]:.2f} mm at {chat.best_speed[s]:.0f} "
                            f"rpm); the optimiser leaves their speed to the rest of the tool's cuts")
    if len(bad) > 12:
        warnings.append(f"{program.path}: warning: and {len(bad) - 12} more segment(s) that chatter (--json: "
                        f"chatter.unstable)")


def _worse(objective: str, before: Figures, after: Figures) -> bool:
    if objective == "cost":
        return after.cost > before.cost * (1 + 1e-6)
    return after.cycle_time > before.cycle_time * (1 + 1e-6)


def _unchanged(program, before, opts, warnings, kept, t_start, reason: str, limits=None) -> OptimizeResult:
    """The result of writing the program as it was (nothing the optimiser may change, or no
    answer better than the program): before = after, no changed line."""
    sm = before.summary
    c = sm.cutting
    fig = Figures(float(sm.cycle_time), None, float(c.peak_load if c else 0.0),
                  float(c.peak_power if c else 0.0), None)
    if reason:
        warnings = warnings + [f"{program.path}: warning: {reason}"]
    ce = contour_error(before)
    feed = _feed_samples(before, program)
    cmax = float(np.max(ce[feed], initial=0.0))
    rough = opts.rough_tolerance if opts.rough_tolerance is not None else max(ROUGH_TOLERANCE, opts.tolerance)
    return OptimizeResult(
        output=bytes(program.data), objective=opts.objective, method=opts.method, before=fig, after=fig,
        estimate={"cycle_time": float(sm.cycle_time), "cost": None, "peak_load": fig.peak_load,
                  "peak_power": fig.peak_power},
        changed_lines=[], segments=[], verified=True, rounds=0, evaluations=0,
        seconds=time.perf_counter() - t_start, force_limit={}, tradeoff=[], trace_before=before, trace_after=before,
        warnings=warnings, defaults=list(c.defaults or []) if c else [], limits=limits or [], kept=kept,
        contour_error={"before": cmax, "after": cmax, "tolerance": opts.tolerance, "rough_tolerance": rough,
                       "worst_segment_increase": 0.0})


def _slide_life(twin) -> float | None:
    """A tool's life as edge sliding (m) under the twin's flank-wear law, from a new tool to the
    end-of-life land (ISO 8688-2's 0.3 mm); None without a law that wears."""
    from ..effects.wear import law_of, life
    from ..ledger import VB_LIMIT

    p = law_of(twin.effects)
    if p is None or not p["rate"]:
        return None
    s = life(VB_LIMIT, p)
    return s if 0 < s < float("inf") else None


def _segment_arcs(model, segs, prob) -> np.ndarray:
    """Per segment, the length-weighted engaged arc R·arccos(1 − a_e/R) of its cutting steps (mm)."""
    radius = 0.5 * model.diameter
    arc = radius * np.arccos(np.clip(1.0 - model.ae / np.maximum(radius, 1e-9), -1.0, 1.0))
    inside = segs.step_seg >= 0
    w = np.where(model.cutting & inside, model.length, 0.0)
    k = np.maximum(segs.step_seg, 0)
    tot = np.bincount(k, weights=w * arc, minlength=len(prob.seg_diam))
    cnt = np.bincount(k, weights=w, minlength=len(prob.seg_diam))
    return np.where(cnt > 0, tot / np.maximum(cnt, 1e-12), 0.0)


def _wear_warnings(plan: dict, warnings: list) -> dict:
    for t, w in plan.items():
        if w["parts_left"] == 0:
            warnings.append(f"tool T{t} ends this program with a flank-wear land of {w['vb_end']:.3f} mm, at or past "
                            f"the end of its life ({w['vb_limit']:g} mm): change it before the next part")
    return plan


def wear_plan(twin, trace, vb_limit: float | None = None) -> dict:
    """Per tool with a wear effect: the land at the first and last cut (mm), and how many more
    parts like this one the tool cuts before the land reaches ``vb_limit`` (the tool-change
    recommendation)."""
    from ..effects.wear import law_of, parts_to_limit
    from ..ledger import VB_LIMIT

    c = trace.summary.cutting if trace is not None else None
    p = law_of(twin.effects)
    if c is None or not c.tool_wear or p is None:
        return {}
    limit = VB_LIMIT if vb_limit is None else vb_limit
    return {t: {**w, "vb_limit": limit, "parts_left": parts_to_limit(p, w["vb_end"], w["sliding"], limit)}
            for t, w in c.tool_wear.items()}


def _feed_samples(trace, program) -> np.ndarray:
    r = np.asarray(trace.record, np.int64)
    kind = program.records["kind"][np.clip(r, 0, len(program.records) - 1)]
    return (r >= 0) & R.is_feed_kind(kind)


def _max_into(out: np.ndarray, index: np.ndarray, values: np.ndarray) -> None:
    """``np.maximum.at(out, index, values)`` for trace samples, whose index comes in long runs
    (a segment, a record): the maximum of every run first, then one ``at`` over the runs."""
    if not len(index):
        return
    starts = np.flatnonzero(np.r_[True, index[1:] != index[:-1]])
    np.maximum.at(out, index[starts], np.maximum.reduceat(values, starts))


def _per_var(values: np.ndarray, seg_of: np.ndarray, prob) -> np.ndarray:
    """Per variable, the largest value over the samples in its segments."""
    out = np.zeros(prob.nvar)
    m = seg_of >= 0
    _max_into(out, prob.seg_var[seg_of[m]], values[m])
    return out


def _reaching(ce: np.ndarray, trace, rec_of: np.ndarray, air_floor: np.ndarray) -> np.ndarray:
    """The contour error where it can reach the part: 0 on samples whose command, lowered by the
    error, stays above their move's air floor (the feed height, a given stock's top, the material
    a plunge in air is proven to stay above) — a corner taken fast in air moves the tool in air."""
    r = np.asarray(rec_of, np.int64)
    floor = np.where(r >= 0, air_floor[np.clip(r, 0, len(air_floor) - 1)], np.inf)
    return np.where(trace.cmd[:, 2] - ce >= floor, 0.0, ce)


def _per_rec(values: np.ndarray, seg_of: np.ndarray, rec_of: np.ndarray, program) -> np.ndarray:
    """Per original feed record, the largest value over its samples outside the segments (a
    sample mapped by path length onto a rapid is the end of the feed move before it: left out)."""
    kind = program.records["kind"]
    out = np.zeros(len(kind))
    r = np.clip(rec_of, 0, len(kind) - 1)
    m = (seg_of < 0) & (rec_of >= 0) & R.is_feed_kind(kind[r])
    _max_into(out, rec_of[m], values[m])
    return out


def _previous_var(segs, prob) -> np.ndarray:
    """Per variable, the variable of the segment run just before its first segment (-1: none)."""
    first_piece = np.full(segs.count, len(segs.piece_seg))
    np.minimum.at(first_piece, segs.piece_seg, np.arange(len(segs.piece_seg)))
    out = np.full(prob.nvar, -1, np.int64)
    for s in range(segs.count):
        k = first_piece[s]
        v = prob.seg_var[s]
        if 0 < k < len(segs.piece_seg) and out[v] < 0:
            pv = prob.seg_var[segs.piece_seg[k - 1]]
            if pv != v:
                out[v] = pv
    return out


def _caller_fed(program, segs, prob) -> np.ndarray:
    """Per variable: it holds a line whose moves run at more than one programmed feed."""
    rec = program.records
    line, feed = rec["line"][segs.piece_rec], rec["feed"][segs.piece_rec]
    order = np.lexsort((feed, line))
    ls, fs = line[order], feed[order]
    differ = (ls[1:] == ls[:-1]) & (fs[1:] > fs[:-1] * (1 + 1e-9))
    lines = np.unique(ls[1:][differ])
    out = np.zeros(prob.nvar, bool)
    if len(lines):
        np.logical_or.at(out, prob.seg_var[segs.piece_seg], np.isin(line, lines))
    return out


def _var_lines(program, segs, prob, var_mask: np.ndarray) -> list[int]:
    m = var_mask[prob.seg_var[segs.piece_seg]]
    return sorted(set(program.records["line"][segs.piece_rec[m]].tolist()))


def _finishing_segments(program, model, segs, prob) -> np.ndarray:
    """Per segment: a finishing pass (a CAM comment calls its operation finishing, or its
    median radial width of cut, by length, is at most FINISH_AE of the tool's diameter)."""
    flag = finish_lines(program)
    out = np.zeros(segs.count, bool)
    np.logical_or.at(out, segs.piece_seg, flag[segs.piece_rec])
    m = (segs.step_seg >= 0) & model.cutting
    if m.any():
        st = segs.step_seg[m]
        ratio = model.ae[m] / np.maximum(model.diameter[m], 1e-9)
        median = percentile_by_group(st, ratio, model.length[m], segs.count, 50.0)
        has = np.bincount(st, weights=model.length[m], minlength=segs.count) > 0
        out |= has & (median <= FINISH_AE)
    return out & ~prob.seg_air


def _surface_segments(program, model, segs, before) -> np.ndarray:
    """Per segment: at least SURFACE_SHARE of its engaged length leaves a final floor or wall
    (``guards.final_surface_steps`` on the stock the program's simulation left)."""
    eng = getattr(before, "engagement", None)
    final = final_surface_steps(program, model, getattr(eng, "stock", None))
    m = (segs.step_seg >= 0) & model.cutting
    out = np.zeros(segs.count, bool)
    if m.any():
        w = model.length[m]
        tot = np.bincount(segs.step_seg[m], weights=w, minlength=segs.count)
        fin = np.bincount(segs.step_seg[m], weights=w * final[m], minlength=segs.count)
        out = (tot > 0) & (fin >= SURFACE_SHARE * tot)
    return out


def _physics(opts, cut, used_tools, program) -> dict:
    """The physics limits per described tool, when the options and the material allow them."""
    from .physics import tool_physics

    if opts.limits == "learned" or opts.objective == "air":
        return {}
    from ..cutting.catalogue import catalogue

    known = cut.material_from != "" and cut.material_name in catalogue().materials
    if opts.limits == "physics" and not known:
        raise MtwinError(f"{program.path}: --limits physics needs the work material: give --material NAME (mtwin "
                         f"materials lists them), cutting.material in the twin file, or a (MATERIAL: NAME) comment")
    if not known:
        return {}
    phys = tool_physics(cut, used_tools, opts.limit_scale)
    if opts.limits == "physics" and not phys:
        raise MtwinError(f"{program.path}: --limits physics: no tool of the program is described (--tool, the twin "
                         f"file's [tools.*] or the program's comments)")
    return phys


def _limit_notes(prob, levels: dict, given_for, opts, m, phys=None, cut=None, user_for=None) -> list:
    """Per tool: the load (and chip) limit used and where it came from."""
    out = []
    phys = phys or {}
    for t in sorted(set(int(x) for x in prob.seg_tool)):
        g = given_for(t)
        h = levels[t][1] if t in levels and opts.chip_limit == "learned" else None
        if t in phys:
            d = phys[t].as_dict(cut.material_name)
            d["material_from"] = cut.material_from
            u, where = user_for(t)
            if u is not None and u < d["load"]:
                d.update(load=float(u), load_source=where)
            if t in levels and levels[t][1] > d["chip_thickness"]:
                d["chip_thickness_catalogue"] = d["chip_thickness"]
                d["chip_thickness"] = float(levels[t][1])
                d["chip_thickness_source"] = ("the program's own level, its 95th percentile (by length) — over the "
                                              "catalogue's " + f"{1000 * d['chip_thickness_catalogue']:.1f} µm ("
                                              + d["chip_thickness_source"] + "): a proven chip stands")
            d["deflection_tolerance"] = opts.tolerance
            d["deflection_load"] = d["stiffness"] * opts.tolerance
            out.append(d)
            continue
        if g is not None:
            out.append({"tool": t, "load": float(g), "chip_thickness": h, "source": "--force-limit"
                        + ("; chip thickness learned from the program (--chip-limit none lifts it)" if h else "")})
        elif t in levels:
            lv, h, peak = levels[t]
            out.append({"tool": t, "load": lv, "chip_thickness": h, "program_peak_load": peak,
                        "source": "learned: the program's 95th percentile (by length) of this tool's engaged steps"})
        else:
            out.append({"tool": t, "load": None, "chip_thickness": None,
                        "source": "none learned: the tool cuts no material in the twin (its air cuts only)"})
    out.append({"tool": None, "spindle_power": float(m.spindle.rated_power), "source": "the machine's rated power"})
    return out


def _slower_because(prob, segs, program, required, own_load, var_given, off_range, spindle_range,
                    worn_held: bool) -> list:
    """The segments written below the program's own feed and the limit the program breaks
    there, as data and as a phrase: what makes an answer slower than the program allowed."""
    out = []
    lines = segs.seg_lines(program)
    for v in np.flatnonzero(required):
        ss = np.flatnonzero(prob.seg_var == v)
        if not len(ss):
            continue
        s = ss[np.argmax(prob.seg_force[ss])]
        ratio = float(own_load[v] / 1.001) if own_load[v] > 1.001 else float(own_load[v])
        if var_given[v] and ratio > 1.0:
            what, text = "load", f"the load limit {prob.seg_force[s]:.1f} N of T{prob.seg_tool[s]} by {100 * (ratio - 1):.0f} %"
        elif off_range[v]:
            n0 = float(prob.n0_spin[prob.var_spin[v]])
            what, text = "spindle range", (f"the --spindle-range {spindle_range[0]:g}-{spindle_range[1]:g} rpm with its "
                                           f"S{n0:g} (the feed per tooth is kept at the new speed)")
        elif worn_held:
            what, text = "worn tool", (f"the load of a new tool ({prob.seg_force[s]:.1f} N, T{prob.seg_tool[s]}), which "
                                       f"a tool that starts worn is held to")
        else:
            what, text = "machine", "the spindle's power or torque, or the chatter margin"
        out.append({"limit": what, "tool": int(prob.seg_tool[s]), "lines": [lines[s][0], lines[s][-1]],
                    "limit_value": float(prob.seg_force[s]) if what in ("load", "worn tool") else None,
                    "program_ratio": ratio, "text": f"{text} (lines {lines[s][0]}-{lines[s][-1]})"})
    return out


def _keep_reasons(program, segs, prob, keep: np.ndarray, kept: dict) -> np.ndarray:
    """Per variable: why it kept its feeds ('' where it did not) — the first of the ``kept``
    notes that names one of its lines.  (By line, once: a loop over the kept variables, each
    scanning every piece, took seconds on a 100,000-move program.)"""
    out = np.full(prob.nvar, "", dtype=object)
    if not keep.any():
        return out
    reasons = list(kept)
    piece_line = program.records["line"][segs.piece_rec]
    first = np.full(int(piece_line.max(initial=0)) + 1, len(reasons), np.int64)  # per line: its first note
    for k in range(len(reasons) - 1, -1, -1):
        where = np.asarray(kept[reasons[k]], np.int64)
        where = where[(where >= 0) & (where < len(first))]
        first[where] = k
    per_var = np.full(prob.nvar, len(reasons), np.int64)
    np.minimum.at(per_var, prob.seg_var[segs.piece_seg], first[piece_line])
    names = np.array(reasons + ["not this objective's"], dtype=object)
    out[keep] = names[per_var[keep]]
    return out


def _q(v: float, unit: str) -> str:
    return f"{v / 1000:.2f} kW" if unit == "W" else f"{v:.1f} {unit}"


def _within_machine(rng: tuple, top: float, option: str, unit: str, what: str, path: str, warnings: list) -> tuple:
    """A user's range held to the machine: an error when nothing of it is within ``top``, the
    high end cut to ``top`` with a warning otherwise."""
    if not (0 < rng[0] < rng[1]) or rng[0] >= top:
        raise MtwinError(f"{option} {rng[0]:g},{rng[1]:g}: need 0 < low < high, with the low end below {what}, "
                         f"{top:g} {unit}")
    if rng[1] > top:
        warnings.append(f"{path}: warning: {option} high end {rng[1]:g} {unit} is above {what}: {top:g} {unit} is used")
        return (rng[0], top)
    return rng


def _runups(prob, program, plan, segs, machine) -> Runups:
    """The spindle run-up pauses of the plan, tied to the spindle variables they depend on."""
    from ..motion.path import CAT_SPINDLE

    rec = program.records
    pauses = np.flatnonzero((plan.seg["kind"] == PAUSE) & (plan.seg["cat"] == CAT_SPINDLE))
    if not len(pauses) or not segs.count:  # (a machine that does not wait for the spindle: none)
        return Runups()
    # spindle variable of every record: that of the segment of its tool's (or its own) pieces
    var_of_rec = np.full(len(rec), -1, np.int64)
    first_seg_of_tool = {}
    for s in range(segs.count):
        first_seg_of_tool.setdefault(int(prob.seg_tool[s]), s)
    for t, s in first_seg_of_tool.items():
        var_of_rec[rec["tool"] == t] = prob.seg_spin[s]
    if len(set(prob.seg_spin.tolist())) != len(first_seg_of_tool):  # per segment: by the next piece
        nxt = np.searchsorted(segs.piece_rec, np.arange(len(rec)))
        ok = nxt < len(segs.piece_rec)
        var_of_rec[ok] = prob.seg_spin[segs.piece_seg[nxt[ok]]]
    target = np.where(rec["spindle_dir"] != 0, np.minimum(rec["spindle"], machine.spindle.max_speed), 0.0)
    r = plan.seg["rec"][pauses]
    prev = np.clip(r - 1, 0, None)
    running_before = (r > 0) & (rec["spindle_dir"][prev] != 0)
    # a stop (M5) runs down to 0: a fixed speed, from the variable before it
    stopped = rec["spindle_dir"][r] == 0
    var = np.where(stopped, -2, var_of_rec[r])
    prev_var = np.where(running_before, var_of_rec[prev], -1)
    keep = (var >= 0) | ((var == -2) & (prev_var >= 0))
    return Runups(var[keep], prev_var[keep], np.where(running_before, target[prev], 0.0)[keep],
                  plan.dur[pauses][keep], machine.spindle.acceleration)


@dataclass
class _Loads:
    """Per sample of a simulated trace, worked out once: the horizontal cutting load (N) and
    the larger of spindle power and torque over the machine's limits."""

    load: np.ndarray
    machine: np.ndarray
    chip: np.ndarray  # the largest chip thickness, mm

    @classmethod
    def of(cls, trace, limits) -> "_Loads":
        from ..layout import C_HMAX

        chip = trace.cut[:, C_HMAX].astype(np.float64) if trace.cut is not None else np.zeros(len(trace.t))
        return cls(np.hypot(trace.signal("fx"), trace.signal("fy")), _sample_ratio(trace, limits), chip)


def _chip_ratios(loads: _Loads, prob, seg_of: np.ndarray) -> np.ndarray:
    """Per variable, the largest simulated chip thickness over its ceiling from physics (0
    where there is none)."""
    out = np.zeros(prob.nvar)
    if prob.seg_hchecked is None:
        return out
    inside = seg_of >= 0
    h = prob.seg_hchecked[seg_of[inside]]
    _max_into(out, prob.seg_var[seg_of[inside]], np.where(np.isfinite(h), loads.chip[inside] / h, 0.0))
    return out


def _ratio_pair(loads: _Loads, prob, seg_of: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per variable, the largest ratio of the load to its limit, and of spindle power or torque
    to theirs, on a simulated trace (``seg_of``: the segment of every sample)."""
    inside = seg_of >= 0
    var = prob.seg_var[seg_of[inside]]
    load, machine = np.zeros(prob.nvar), np.zeros(prob.nvar)
    _max_into(load, var, loads.load[inside] / prob.seg_force[seg_of[inside]])
    _max_into(machine, var, loads.machine[inside])
    return load, machine


def _air_entries(run: _Run, clear_z: float, stock_top: float | None) -> dict:
    """Per record, the plunges that may run their upper part at the air feed (guards.air_entries):
    straight down at a feed per minute, a line of their own the writer can split."""
    from .segment import splittable

    from ..cutting.library import describes

    program, cut, candidates, feed_range, opts = run.take("program cut candidates feed_range opts")
    if opts.objective == "smooth":
        return {}  # (the smoothing objective keeps air at its own feed)
    rec = program.records
    # (the air feed, the top of the range, must be a raise: a range below the plunge's feed is not)
    plunges = R.is_feed_kind(rec["kind"]) & (rec["kind"] == R.LINEAR) & ~candidates & (rec["feed"] > 0) & \
        (rec["feed"] * 1.01 < feed_range[1]) & \
        (rec["feed_mode"] == R.FEED_PER_MIN) & ((rec["flags"] & (R.FL_SYNC | R.FL_PROBE)) == 0) & \
        (np.hypot(rec["x"] - rec["sx"], rec["y"] - rec["sy"]) < 1e-6) & (rec["sz"] - rec["z"] >= ENTRY_MIN_AIR) & \
        splittable(program)
    if not plunges.any():
        return {}
    # (every tool the twin knows — not only those with feeds to set: a drill that ran only
    # canned cycles is no 6 mm end mill, and its hole proves nothing of the sweep it would have)
    described = {int(t) for t in np.unique(rec["tool"]) if describes(cut, int(t))}
    return {e.record: e for e in air_entries(program, cut, plunges, described, clear_z, stock_top)}


def _approach_feeds(prob, segs, feeds: np.ndarray, program, keep: np.ndarray, clear_z: float = math.inf) -> np.ndarray:
    """An air segment that runs straight into a cut, or into a feed move the optimiser does not
    set (a plunge), is an approach: it runs at most at that move's feed (or its own programmed
    one).  At a higher feed the
    axes, lagging the command by their following error, would still be decelerating when the
    command enters the material, and the twin's load there would be set by the approach speed."""
    from ..gcode import records as R

    rec = program.records
    feeds = feeds.copy()
    last_piece = np.zeros(segs.count, np.int64)
    last_piece[segs.piece_seg] = np.arange(len(segs.piece_seg))
    is_feed = R.is_feed_kind(rec["kind"])
    piece_of_rec = {}
    for k, r in enumerate(segs.piece_rec):
        piece_of_rec.setdefault(int(r), k)
    for s in np.flatnonzero(prob.seg_air):
        v = prob.seg_var[s]
        if keep[v]:
            continue
        k = last_piece[s]
        r = int(segs.piece_rec[k])
        if segs.piece_t1[k] < 1.0 and k + 1 < len(segs.piece_seg):  # the same move goes on
            nxt = segs.piece_seg[k + 1]
            cap = feeds[prob.seg_var[nxt]] if not keep[prob.seg_var[nxt]] else rec["feed"][r]
        else:
            # the next move with a length, skipping zero-length ones
            r2 = r + 1
            while r2 < len(rec) and rec["kind"][r2] != R.DWELL and R.move_lengths(rec[r2:r2 + 1])[0] <= 0:
                r2 += 1
            if r2 >= len(rec) or not is_feed[r2]:
                continue  # a rapid, a dwell or the end follows: nothing is entered at this feed
            if rec["sz"][r2] >= clear_z - 1e-6 and rec["z"][r2] < rec["sz"][r2] and \
                    np.hypot(rec["x"][r2] - rec["sx"][r2], rec["y"][r2] - rec["sy"][r2]) < 1e-6:
                continue  # a plunge from the height the program treats as clear: it starts in air
            if r2 in piece_of_rec:
                nxt = segs.piece_seg[piece_of_rec[r2]]
                if prob.seg_air[nxt]:
                    continue
                cap = feeds[prob.seg_var[nxt]] if not keep[prob.seg_var[nxt]] else rec["feed"][r2]
            else:
                cap = rec["feed"][r2]  # a plunge or another move the optimiser leaves alone
        # (never below the air move's own programmed feed: that entry the program already had)
        feeds[v] = min(feeds[v], max(cap, prob.f0_var[v]))
    return feeds


def warm_long_trace_kernels() -> None:
    """Compile the kernels the optimiser runs only on long traces (from 50,000 / 200,000 samples:
    the sample-to-piece map, the contour error), on tiny inputs: ``mtwin cache warm``."""
    from ._segkernel import contour_samples, samples_to_pieces

    n = 4
    contour_samples(np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n))
    i64 = np.zeros(n, np.int64)
    samples_to_pieces(i64, np.ones(n, bool), np.zeros(1, np.int64), np.ones(1), np.zeros(2), np.ones(1),
                      np.zeros(2), np.ones(1), np.zeros(1), np.zeros(1, np.int64), np.zeros(1, np.int64),
                      np.zeros(1, np.int64), i64.copy(), i64.copy())


def _fresh(twin):
    return twin.replace(share_cache=False)  # (an engagement of its own: see its caller)


def _round_feeds(f: np.ndarray, f0: np.ndarray, program, segs, prob) -> np.ndarray:
    """Feeds as they will be written: whole mm/min (0.1 in/min where the variable's F is read
    in inches), rounded down; a feed within half a step of the program's is the program's."""
    inch = np.zeros(prob.nvar, bool)
    flags = program.records["flags"][segs.piece_rec]
    np.logical_or.at(inch, prob.seg_var[segs.piece_seg], (flags & R.FL_F_INCH) != 0)
    step = np.where(inch, 2.54, 1.0)
    out = np.floor(f / step + 1e-6) * step
    # rounding down must not take a feed asked at or above the program's own below it
    out = np.where((out < f0) & (f >= f0), f0, out)
    # a raise under 1 % is not worth an F word (nor a split move): the program's own
    return np.where((np.abs(f - f0) < 0.5 * step) | ((f > f0) & (f < 1.01 * f0)), f0, out)


def _unlocked(prob, spins: np.ndarray) -> np.ndarray:
    """The speeds to write: NaN (the program's own, every S word as written) for the locked
    spindle variables."""
    return spins if prob.spin_locked is None else np.where(prob.spin_locked, np.nan, spins)


def _lock_unwritable_spins(prob, program, segs, warnings: list):
    """With a spindle range: the spindle variables whose new speed cannot be written.  Where a
    line runs more than once (a subprogram, a loop), a variable's first move may be on a line
    that also runs for another tool, or at another speed; an S word there would change that
    run too, and the writer refuses it.  Each variable is tried alone with a changed speed
    (the others writing nothing), then all of them together (only in such programs:
    elsewhere every line runs once).  A refused one keeps the program's speeds, every S word
    as written, with a warning; with a speed per segment, one refused keeps them all."""
    from ..gcode.records import FL_FIRST_IN_LINE
    from ..gcode.writer import WriteError, rewrite

    rec = program.records
    first = rec["line"][(rec["flags"] & FL_FIRST_IN_LINE) != 0]
    if not prob.nspin or len(np.unique(first)) == len(first):
        return prob
    keep_all = np.ones(prob.nvar, bool)

    def writable(spins) -> bool:
        _, _, spins_rec = _expand(program, segs, prob.f0_var, spins, prob, True, keep_all)
        try:
            rewrite(program, None, np.where(np.isnan(spins_rec), np.nan, np.round(spins_rec)), {})
        except WriteError:
            return False
        return True

    # (any other speed: the writer's placement is what is tried; each variable its own)
    other = prob.n0_spin + 100.0 * (1 + np.arange(prob.nspin))
    per_tool = prob.nspin == len(np.unique(prob.seg_tool))
    locked = np.zeros(prob.nspin, bool)
    if not per_tool and prob.nspin > MAX_SPIN_TRIALS:
        locked[:] = True  # (a speed per segment in such a program: none is tried)
    else:
        for v in range(prob.nspin):
            locked[v] = not writable(np.where(np.arange(prob.nspin) == v, other, np.nan))
    if not locked.all() and not writable(np.where(locked, np.nan, other)):
        locked[:] = True  # (each alone, but not together)
    if locked.any() and not per_tool:
        locked[:] = True
    if locked.any():
        tools = sorted({int(t) for t, s in zip(prob.seg_tool, prob.seg_spin) if locked[s]})
        warnings.append(f"{program.path}: warning: --spindle-range: {', '.join(f'T{t}' for t in tools)} "
                        f"keep{'s' if len(tools) == 1 else ''} the programmed speed{'' if per_tool else 's'} — a "
                        f"new S word would fall on a line the program runs more than once (a subprogram or a "
                        f"loop) at another speed or for another tool")
    return replace(prob, spin_locked=locked)


def _expand(program, segs, feeds, spins, prob, spin_changes: bool, keep: np.ndarray, entries: dict | None = None,
            air_feed: float = 0.0):
    """Per-record feeds (NaN: keep), splits and spindle speeds of a candidate (a spindle
    variable at NaN keeps the program's own speeds, every S word as written); ``entries``: the
    plunges whose upper part runs at ``air_feed`` (guards.AirEntry)."""
    from ..gcode.writer import Split

    rec = program.records
    n = len(rec)
    out = np.full(n, np.nan)
    var = prob.seg_var[segs.piece_seg]
    # a kept variable keeps each record's own feed (a segment may hold several)
    f_piece = np.where(keep[var], rec["feed"][segs.piece_rec], feeds[var])
    splits = {}
    order = np.argsort(segs.piece_rec, kind="stable")
    pr = segs.piece_rec[order]
    starts = np.flatnonzero(np.r_[True, pr[1:] != pr[:-1]]) if len(pr) else np.zeros(0, np.int64)
    count = np.diff(np.r_[starts, len(pr)])
    # a record in one piece (most) takes its piece's feed; only split records are walked
    one = starts[count == 1]
    r1, f1 = pr[one], f_piece[order[one]]
    moved = f1 != rec["feed"][r1]
    out[r1[moved]] = f1[moved]
    whole = []
    for b, c in zip(starts[count > 1], count[count > 1]):
        r = int(pr[b])
        idx = order[b:b + c]
        if keep[var[idx]].any():
            whole.append(r)  # a move part of which is kept is kept whole: kept means byte-identical
            continue
        fs = f_piece[idx]
        # merge neighbouring pieces whose feeds differ by under 1 % (the lower feed for both):
        # a split is worth its extra line only for a real change
        ts, fl = [], [fs[0]]
        for k in range(1, len(fs)):
            if abs(fs[k] - fl[-1]) > 0.01 * max(fs[k], fl[-1]):
                ts.append(float(segs.piece_t0[idx][k]))
                fl.append(fs[k])
            else:
                fl[-1] = min(fl[-1], fs[k])
        if ts:
            splits[r] = Split(ts, [float(x) for x in fl])
        elif fl[0] != rec["feed"][r]:
            out[r] = fl[0]
    for r, e in (entries or {}).items():
        if e.whole:
            out[r] = air_feed  # all of it in air
        else:
            splits[r] = Split([(e.z_from - e.z_air) / (e.z_from - e.z_to)], [air_feed, float(rec["feed"][r])])
    if whole:
        # a line the program runs more than once (a loop, a subprogram) has one F word: kept
        # whole on one run, it is kept on every run
        lines = np.isin(rec["line"], rec["line"][whole])
        out[lines] = np.nan
        for r in np.flatnonzero(lines):
            splits.pop(int(r), None)
    spindles = np.full(n, np.nan)
    if spin_changes and segs.count:
        # every record of a tool, from its first move, runs at the speed of the segment it is
        # in or, between segments, of the segment before (the first one for the tool's start)
        first_rec = np.array([segs.piece_rec[segs.piece_seg == s].min() for s in range(segs.count)])
        order_s = np.argsort(first_rec, kind="stable")
        want = np.full(n, np.nan)
        for s in order_s:
            v = spins[prob.seg_spin[s]]
            want[first_rec[s]] = -1.0 if np.isnan(v) else v  # (NaN, -1 here: the program's own speeds)
        tool = rec["tool"]
        # (carried forward within each run of one tool: a tool change starts with none)
        fresh = ~np.isnan(want) | np.r_[True, tool[1:] != tool[:-1]]
        want = want[np.maximum.accumulate(np.where(fresh, np.arange(n), 0))]
        # a tool's records before its first segment: that segment's speed
        for t in np.unique(tool):
            m = np.flatnonzero(tool == t)
            ok = m[~np.isnan(want[m])]
            if len(ok):
                want[m[m < ok[0]]] = want[ok[0]]
        # (stopped records too: S is modal, M5 does not clear it)
        change = (want >= 0) & (want != rec["spindle"])
        spindles[change] = want[change]
    return out, splits, spindles


def _segment_of_samples(trace, new_prog, program, segs):
    """Segment of every trace sample (-1: none), by path length: the written program runs the
    same path, possibly with split moves, so a sample's distance along the path says which
    piece of which original record it is in.  Returns (segment, original feed record) of every
    sample, -1 where none."""
    rec_new = np.asarray(trace.record, np.int64)
    Ln = R.move_lengths(new_prog.records)
    Lo = R.move_lengths(program.records)
    cn = np.concatenate([[0.0], np.cumsum(Ln)])
    co = np.concatenate([[0.0], np.cumsum(Lo)])
    # position of each sample: its record's start + the fraction done (from the record's
    # sample range: first to last sample of the record)
    idx = np.clip(rec_new, 0, len(Ln) - 1)
    k = np.arange(len(idx))
    last = np.full(len(Ln), -1)
    fi = np.full(len(Ln), len(idx))
    if len(idx):
        # the samples of a record come in runs (in time order): first and last of every run
        starts = np.flatnonzero(np.r_[True, idx[1:] != idx[:-1]])
        ends = np.r_[starts[1:], len(idx)] - 1
        np.maximum.at(last, idx[starts], ends)
        np.minimum.at(fi, idx[starts], starts)
    kind = new_prog.records["kind"][idx]
    is_feed = R.is_feed_kind(kind)
    valid = (rec_new >= 0) & is_feed
    if len(idx) >= FAST_MAP and len(Lo):
        from ._segkernel import samples_to_pieces

        key = segs.piece_rec.astype(np.float64) * 4.0 + segs.piece_t0
        order = np.argsort(key, kind="stable")
        seg = np.empty(len(idx), np.int64)
        r_out = np.empty(len(idx), np.int64)
        samples_to_pieces.auto(len(idx), idx, valid, fi, np.maximum(last - fi, 1).astype(np.float64), cn, Ln, co,
                               Lo, np.ascontiguousarray(key[order]), order, segs.piece_rec, segs.piece_seg, seg, r_out)
        return seg, r_out
    span = np.maximum(last[idx] - fi[idx], 1)
    frac = (k - fi[idx]) / span
    s = cn[idx] + frac * Ln[idx]
    r_o = np.clip(np.searchsorted(co, s, side="right") - 1, 0, len(Lo) - 1)
    # a zero-length record of the new program (a dwell, a pause) maps by its own index order
    t_o = np.where(Lo[r_o] > 0, (s - co[r_o]) / np.maximum(Lo[r_o], 1e-12), 0.0)
    # only feed moves belong to segments
    seg = np.where(valid, locate(segs.piece_rec, segs.piece_t0, segs.piece_seg, r_o, t_o), -1)
    return seg, np.where(valid, r_o, -1)


def _sample_ratio(trace, limits) -> np.ndarray:
    """Per sample, the larger of spindle power and spindle torque over their limits (the
    machine's own; the load limit is per segment)."""
    n = np.abs(np.asarray(trace.signal("spindle_speed")))
    t_lim = limits.power / (2 * math.pi * np.maximum(n, limits.base_speed) / 60.0)
    return np.maximum(np.asarray(trace.signal("spindle_power")) / limits.power,
                      np.asarray(trace.signal("spindle_torque")) / t_lim)


def _outside_ratios(loads: _Loads, seg_of, rec_of, nrec, force) -> np.ndarray:
    """Per original record, the largest machine-limit ratio (spindle power, torque) and the
    largest cutting load over the load limit ``force``, over the samples outside the
    segments, as one array of (2 * nrec) — compared between the program and its rewrite."""
    out = np.zeros(2 * nrec)
    m = (seg_of < 0) & (rec_of >= 0)
    if not m.any():
        return out
    r = rec_of[m]
    _max_into(out, r, loads.machine[m])
    _max_into(out, nrec + r, loads.load[m] / force)
    return out


def _blame_previous(seg_of, rec_of, worse, prob, excess) -> np.ndarray:
    """For records outside the segments that got worse, the ratio to slow the segment run
    just before them by (per variable)."""
    nrec = len(worse) // 2
    bad_rec = np.flatnonzero(worse[:nrec] | worse[nrec:])
    out = np.zeros(prob.nvar)
    # the segment of the last segment sample before each sample
    idx = np.where(seg_of >= 0, np.arange(len(seg_of)), -1)
    prev = np.maximum.accumulate(idx)
    for r in bad_rec:
        where = np.flatnonzero(rec_of == r)
        if not len(where):
            continue
        p = prev[where[0]]
        if p < 0:
            continue
        v = prob.seg_var[seg_of[p]]
        out[v] = max(out[v], float(max(excess[r], excess[nrec + r])))
    return out


def _figures(trace, prog, segs, prob, rates, seg_of: np.ndarray, load: np.ndarray) -> Figures:
    """Before/after figures of a simulated trace (``seg_of``: the segment of every sample,
    ``load``: its horizontal cutting load)."""
    sm = trace.summary
    c = sm.cutting
    p = np.asarray(trace.signal("spindle_power"))
    n = np.abs(np.asarray(trace.signal("spindle_speed")))
    loss = prob.loss[0] + prob.loss[1] * n + prob.loss[2] * n * n
    pc = np.where(n > 0, p - loss, 0.0)
    # power CV over the cutting segments' mean powers (trace samples are evenly spaced in time)
    cutm = (seg_of >= 0)
    cutm &= ~prob.seg_air[np.maximum(seg_of, 0)]
    means = []
    if cutm.any():
        cnt = np.bincount(seg_of[cutm], minlength=segs.count)
        tot = np.bincount(seg_of[cutm], weights=pc[cutm], minlength=segs.count)
        means = tot[cnt > 0] / cnt[cnt > 0]
    cv = float(np.std(means) / np.mean(means)) if len(means) > 1 and np.mean(means) > 0 else None
    # cost from the trace: time, and per tool the time in cut at its speed
    dt = float(np.median(np.diff(trace.t))) if len(trace.t) > 1 else 0.0
    engaged = load > 0
    tool = prog.records["tool"][np.clip(np.asarray(trace.record, np.int64), 0, len(prog.records) - 1)]
    wear = 0.0
    diam = {int(t): float(d) for t, d in zip(prob.seg_tool, prob.seg_diam)}
    if rates.slide_life and trace.tool_use:
        # the wear law's life: what each tool slid in this program over its sliding life
        wear = sum(h.sliding for h in trace.tool_use.values()) / rates.slide_life
        engaged = np.zeros_like(engaged)
    for t in np.unique(tool[engaged]):
        m = engaged & (tool == t)
        wear += float(np.sum(rates.lives_used(dt, cutting_speed(diam.get(int(t), 6.0), n[m]))))
    cost = rates.cost(sm.cycle_time, wear)
    return Figures(float(sm.cycle_time), float(cost), float(c.peak_load if c else 0.0), float(c.peak_power if c else 0.0),
                   cv)


def _limited_by(prob, feeds, spins, feed_range, times, segs, keep, keep_why, lowered_for, approach_cap) -> list:
    """What held each segment's feed where it is: the label names what bound it."""
    out = []
    _, _, fz, load, torque, power, _, t_lim = prob._mechanics(feeds[None, :], spins[None, :])
    excess = dict(zip(("load", "power", "torque", "chip thickness"), prob._excess(load, power, torque, t_lim, fz)))
    v_chat = None
    if prob.chatter is not None:
        v_chat = prob.chatter.at(spins[None, prob.seg_spin])[0] / prob.chatter.margin
    for s in range(len(prob.seg_var)):
        v = prob.seg_var[s]
        f = feeds[v]
        f0 = prob.f0_var[v]
        if keep[v]:
            out.append(f"kept ({keep_why[v]})")
            continue
        if lowered_for[v] and f < feed_range[1] - 2.6:
            out.append(lowered_for[v])
            continue
        # (at the top of the range: within one rounding step of it — 2.54 mm/min where F is in inches)
        top = f >= feed_range[1] - 2.6
        if prob.seg_air[s]:
            if top:
                out.append("feed range (air cut)")
            elif f <= f0 + 1e-9:
                out.append("program's feed (the feed of the cut it enters)" if approach_cap[v] else "program's feed")
            else:
                # raised, but not to the top: only the cut it runs into holds an air cut there
                # (the next move, or the rest of its own move when the move enters the stock)
                out.append("approach (the feed of the cut it enters)")
            continue
        r = {name: float(e[0][s]) + 1.0 for name, e in excess.items()}  # value / (limit x margin)
        if v_chat is not None:
            r["chatter margin"] = float(v_chat[s])
        k = max(r, key=r.get)
        if r[k] > 0.97:
            out.append(k)
        elif top:
            # at the top of the range: is the machine even reaching it?
            rr = segs.piece_rec[segs.piece_seg == s]
            v_cap = float(np.min(times.v_cap[rr])) * 60 if len(rr) else np.inf
            out.append("machine acceleration/speed" if v_cap < f * 0.95 else "feed range")
        elif f <= feed_range[0] + 1:
            out.append("feed range (minimum)")
        elif abs(f - f0) <= 0.011 * f0 and prob.f_floor is not None:
            # held at the program's own feed: a limit the program already runs at (its chip
            # thickness or load level is at its learned one on some step of the segment)
            out.append("program's feed (its own level)")
        else:
            out.append("objective")
    return out


#: the scales of the physics limits the trade-off curve is drawn at (each re-simulated)
TRADEOFF_SCALES = (0.6, 0.8, 1.0)
#: above this many motion records the curve is estimated only (each re-simulation costs a run)
TRADEOFF_MAX_RECORDS = 50_000


def _scale_tradeoff(run: _Run, est, fig_after) -> list:
    """Cycle time against a scale of the physics limits: at each scale the answer's feeds, each
    no higher than the scaled limits allow (the rounds' guards still hold: a lower feed is no
    less accurate) and no lower than its floor, estimated on the fast model and re-simulated
    (programs of up to TRADEOFF_MAX_RECORDS moves)."""
    from ..gcode.writer import rewrite

    (f_try, floor, keep, opts, phys, prob, program, s_try, segs, stock, tw_after, twin, new) = \
        run.take("f_try floor keep opts phys prob program s_try segs stock tw_after twin new")
    on = np.array([int(t) in phys for t in prob.seg_tool])
    out = []
    for scale in TRADEOFF_SCALES:
        k = scale / opts.limit_scale
        if abs(k - 1.0) < 1e-9:  # the answer itself
            out.append({"scale": scale, "estimate": float(est["time"][0]), "resimulated": fig_after.cycle_time})
            continue
        at = replace(prob, seg_force=np.where(on, prob.seg_force * k, prob.seg_force),
                     seg_hlim=np.where(on, prob.seg_hlim * k, prob.seg_hlim) if prob.seg_hlim is not None else None)
        f = at.max_feasible_feed(s_try)
        f = np.where(np.isnan(f), floor, f)
        f = np.where(keep, f_try, np.maximum(np.minimum(f, f_try), floor))
        t_est = float(at.evaluate(f[None, :], s_try[None, :])["time"][0])
        resim = None
        if len(program.records) <= TRADEOFF_MAX_RECORDS:
            fr = _round_feeds(f, prob.f0_var, program, segs, prob)
            feeds_rec, splits, spins_rec = _expand(program, segs, np.where(keep, prob.f0_var, fr),
                                                   _unlocked(prob, np.round(s_try)),
                                                   prob, False, keep, run.entries, run.feed_range[1])
            text = rewrite(program, feeds_rec, spins_rec, splits)
            resim = float(tw_after.simulate(twin.load(text, path=program.path), stock=stock,
                                            chatter=False).summary.cycle_time)
        out.append({"scale": scale, "estimate": t_est, "resimulated": resim})
    return out


def _tradeoff(prob, spins) -> list:
    """Estimated cycle time against the load limit, 10 N apart (coarser for large limits, at
    most 16 points): what each extra 10 N buys."""
    base = float(np.median(prob.seg_force))
    lo = max(10.0, round(base * 0.5 / 10) * 10)
    step = max(10.0, math.ceil((2 * base - lo) / 15 / 10) * 10)
    out = []
    for lim in np.arange(lo, base * 2 + 1e-9, step)[:16]:
        at = replace(prob, seg_force=prob.seg_force * (lim / base))
        f = at.max_feasible_feed(spins)
        f = np.where(np.isnan(f), prob.limits.feed[0], f)
        ev = at.evaluate(f[None, :], spins[None, :])
        out.append((float(lim), float(ev["time"][0])))
    return out


def _changed_lines(a: bytes, b: bytes) -> list:
    import difflib

    la = a.decode("latin-1").splitlines()
    lb = b.decode("latin-1").splitlines()
    out = []
    sm = difflib.SequenceMatcher(None, la, lb, autojunk=False)
    for tag, i1, i2, j1, j2 in sm.get_opcodes():
        if tag == "equal":
            continue
        out.append((i1 + 1, "\n".join(la[i1:i2]), "\n".join(lb[j1:j2])))
    return out
