"""Running a program on the twin: ``simulate``, and ``scale`` (an override baked into it)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

from ..version import __version__
from ..errors import MtwinError, warning_text
from ..gcode.writer import scale_feeds, scaled_feeds
from ..twin.setup import Messages, load_part, open_twin
from ..units import SI_UNITS


@dataclass
class Simulation:
    """A program run on the twin: the program, its trace (``trace.summary`` the figures)."""

    program: object
    trace: object
    messages: list = field(default_factory=list, repr=False)  # (kind, text) in order

    @property
    def summary(self):
        return self.trace.summary

    every: int = 1  # servo samples per trace sample
    twin: object = None
    # several runs of the program on the same tools (simulate_runs): per run, its figures
    runs: list = field(default_factory=list)
    recorded: list = field(default_factory=list)  # tool ids whose runs went into the ledger
    # with dynamics=True: the regenerative model along the trace (chatter.dynamics.Dynamics)
    dynamics: object = None

    def write_trace(self, path: str, source: str = "simulate") -> None:
        """Write the trace in the measurement format (.csv, .parquet, or '-'), its metadata
        naming the program, the machine, the planner and the sampling."""
        m = self.twin.machine
        self.trace.write(path, {"source": f"mtwin {__version__} {source}", "program": self.program.path,
                                "machine": m.name, "planner": m.controller.style,
                                "servo_period_s": f"{m.controller.servo_period:g}", "every": str(self.every)})

    @property
    def inch(self) -> bool:
        """Whether the program is written in inches (most of its moves)."""
        return self.program.inch

    def as_dict(self) -> dict:
        """The summary as ``mtwin simulate --json`` prints it (SI units whatever the program's)."""
        d = self.summary.as_dict()
        d["si_units"] = SI_UNITS
        d["program_units"] = "inch" if self.inch else "mm"
        d["program"] = self.program.path
        if self.runs:
            d["runs"] = self.runs
        if self.recorded:
            d["recorded"] = self.recorded
        if self.dynamics is not None:
            d["dynamics"] = self.dynamics.as_dict()
        return d


def simulate(twin=None, program=None, *, stock=None, cutting: bool = True, every: Optional[int] = None,
             rate: Optional[float] = None, tooth_resolution: bool = False,
             progress: Optional[Callable[[int, int], None]] = None, progress_from: int = 0,
             on_message=None, dynamics: bool = False) -> Simulation:
    """Run a program through the twin: interpreter, planner, servo loop and cutting process.

    Parameters
    ----------
    twin : Twin, str or None
        The twin, a twin file's path, or None for the default machine.
    program : Program, str or bytes
        The program, or a path (``-`` for stdin) or its text, read with the twin's settings.
    stock : tuple, optional
        The stock box (xmin, ymin, zmin, xmax, ymax, zmax), mm, over the program's comment.
    cutting : bool
        Model the cut (engagement, forces, spindle power); False: motion only.
    every : int, optional
        Keep every n-th servo sample in the trace (the figures use all of them); default 1.
    rate : float, optional
        The trace's sample rate in Hz instead (``every`` from the servo period).
    tooth_resolution : bool
        Instantaneous tooth-passing forces instead of revolution averages.
    progress : callable, optional
        ``progress(samples_done, samples_total)`` during the servo loop, for a run of more
        than ``progress_from`` servo samples (a shorter one runs in one piece).
    on_message : callable, optional
        ``on_message(kind, text)`` for each warning and note as it arises.
    dynamics : bool
        Run the regenerative chatter model along the trace for the tools with modes
        (``docs/chatter.md``): the trace's ``vib_x``/``vib_y`` and per line a verdict.

    Returns
    -------
    Simulation
    """
    msgs = Messages(on_message)
    if dynamics and not cutting:
        raise MtwinError("--dynamics needs the cutting model (what the tool cuts): do not combine it with --no-cutting")
    tw = open_twin(twin)
    every = _every(every, rate, tw.machine.controller.servo_period)
    prog = load_part(tw, program, msgs)
    plan = tw.plan(prog)
    if progress is not None and plan.total_time / tw.machine.controller.servo_period + 1 <= progress_from:
        progress = None  # (reported progress runs the servo loop in pieces)
    trace = tw.simulate(prog, plan=plan, every=every, progress=progress, cutting=cutting, stock=stock,
                        tooth_resolution=tooth_resolution)
    for w in trace.summary.warnings:
        msgs.warn(w)
    dyn = None
    if dynamics:
        from ..chatter.dynamics import trace_dynamics
        from ..motion.simulate import program_cutting

        dyn = trace_dynamics(program_cutting(tw, prog), prog, plan, trace)
        trace.vib = dyn.vib.astype(np.float32)
        for note in dyn.notes:
            msgs.note(note)
    return Simulation(prog, trace, msgs.items, every, tw, dynamics=dyn)


MAX_RUNS = 10_000  # runs in one command: a year of one part on one machine


def simulate_runs(setup, program=None, runs: int = 1, *, record: bool = False, stock=None, cutting: bool = True,
                  on_message=None) -> Simulation:
    """``runs`` runs of a program one after another on the same tools, each starting where the
    run before left them (a batch of parts: the wear carried from part to part).

    ``setup``: a TwinSetup (its ``ledger`` and ``tool_ids`` start the mapped tools in their
    recorded state); ``record``: add each run to the ledger as it finishes.  Returns the last
    run's Simulation with ``runs``: per run its cycle time, loads and each tool's land."""
    from ..ledger import record_traces, run_use

    if runs < 1:
        raise MtwinError(f"--runs must be at least 1, got {runs}")
    if runs > MAX_RUNS:
        raise MtwinError(f"--runs {runs:,} is over {MAX_RUNS:,} runs in one command (split the batch: each run "
                         f"starts where the ledger left the tools)")
    ledger = getattr(setup, "ledger", None)
    if record and not ledger:
        raise MtwinError("--record adds the run to a tool ledger: give --ledger FILE and --tool-id T3=ID")
    if record and not cutting:
        raise MtwinError("--record needs the cutting model (what the tool cut): do not combine it with --no-cutting")
    msgs = Messages(on_message)
    tw = open_twin(setup)
    prog = load_part(tw, program, msgs)
    table, uses = [], []

    def each(k, trace):
        c = trace.summary.cutting
        if record:
            uses.append(run_use(setup.tool_map, trace))  # (a few numbers per run: recorded at the end)
        table.append({"run": k, "cycle_time": trace.summary.cycle_time,
                      "peak_load": c.peak_load if c else None, "mean_load": c.mean_load if c else None,
                      "tool_wear": {str(t): w for t, w in (c.tool_wear if c else {}).items()}})

    trace = tw.simulate_batch(prog, runs, stock=stock, cutting=cutting, on_run=each, keep_all=False)[-1]
    # all runs or none: an interrupted or failed batch records nothing (one transaction)
    material = trace.summary.cutting.material if trace.summary.cutting is not None else ""
    recorded = record_traces(ledger, uses, program=prog.path, material=material) if record else []
    for w in trace.summary.warnings:
        msgs.warn(w)
    return Simulation(prog, trace, msgs.items, 1, tw, runs=table if runs > 1 else [], recorded=recorded)


EVERY_MAX = 10**9  # servo samples per trace sample (11.6 days at 1 ms)


def _every(every: Optional[int], rate: Optional[float], dt: float) -> int:
    """Servo samples per trace sample, from ``every`` or a ``rate`` in Hz."""
    if every is not None and rate is not None:
        raise MtwinError("give --every or --decimate, not both")
    if rate is not None:
        # (a rate under 1e-3 Hz keeps less than one sample in 17 minutes: no trace)
        if not (1e-3 <= rate < math.inf):
            raise MtwinError(f"--decimate must be a rate in Hz of at least 0.001, got {rate:g}")
        if rate * dt > 1.0 + 1e-9:  # (a rate above the servo's has no samples to give)
            raise MtwinError(f"--decimate {rate:g} Hz is above the servo rate, {1.0 / dt:g} Hz: at most that")
        every = max(1, int(round(1.0 / (rate * dt))))
    if every is None:
        every = 1
    if not 1 <= every <= EVERY_MAX:
        raise MtwinError(f"--every must be between 1 and {EVERY_MAX:,} servo samples, got {every}")
    return every


@dataclass
class Scaled:
    """A program with an override baked in: the new bytes (geometry and feeds proven)."""

    program: object
    output: bytes
    changed_lines: int
    messages: list = field(default_factory=list, repr=False)

    def as_dict(self) -> dict:
        return {"program": self.program.path, "changed_lines": self.changed_lines}


def scale(twin=None, program=None, *, feed: float = 1.0, spindle: float = 1.0, max_feed: Optional[float] = None,
          on_message=None) -> Scaled:
    """Bake a feed/spindle override into a program and clamp its feeds (``max_feed``, mm/min,
    and the machine's maximum cutting feed); nothing else changes.  A raised feed above the
    machine's maximum is clamped to it, with a warning that names its lines."""
    msgs = Messages(on_message)
    tw = open_twin(twin)
    limit = tw.machine.max_cutting_feed
    prog = load_part(tw, program, msgs)
    f, is_feed = scaled_feeds(prog, feed, spindle)
    raised = is_feed & (f > limit * (1 + 1e-9)) & (f > prog.records["feed"])
    if raised.any() and (max_feed is None or max_feed > limit):
        lines = np.unique(prog.records["line"][raised])
        listed = ", ".join(str(x) for x in lines[:8]) + (" …" if lines.size > 8 else "")
        msgs.warn(warning_text(prog.path, int(lines[0]),
                               f"F {float(f[raised].max()):,.0f} mm/min would exceed the machine's maximum cutting "
                               f"feed {limit:,.6g} mm/min: clamped to it on {lines.size} line(s) ({listed})"))
    top = tw.machine.spindle.max_speed
    s_new = prog.records["spindle"] * spindle
    over = (s_new > top * (1 + 1e-9)) & (s_new > prog.records["spindle"])
    if spindle != 1.0 and math.isfinite(spindle) and over.any():
        # (a spindle clamped where its feed is not would change the chip: refused, not clamped)
        ln = int(prog.records["line"][over][0])
        big = float(s_new[over].max())
        shown = f"{big:,.0f}" if big < 1e9 else f"{big:.3g}"
        raise MtwinError(f"--spindle {spindle:g}: S {shown} rpm (line {ln}) would exceed the machine's maximum "
                         f"spindle speed {top:,.6g} rpm; give a factor of at most "
                         f"{top / float(prog.records['spindle'][over].max()):.4g}")
    data = scale_feeds(prog, feed, spindle, max_feed, machine_max=limit)
    changed = sum(1 for a, b in zip(prog.data.splitlines(), data.splitlines()) if a != b)
    return Scaled(prog, data, changed, msgs.items)
