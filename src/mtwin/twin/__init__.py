"""The digital twin: a machine (controller + feed drives) that runs programs.

    >>> import mtwin
    >>> twin = mtwin.Twin.from_toml("my-machine.toml")     # or mtwin.Twin() for the default
    >>> prog = twin.load("part.nc")                        # interpreter settings from the file
    >>> trace = twin.simulate(prog)
    >>> trace.summary.cycle_time
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..params import is_effect_param, split_effect_param
from .machine import Machine


class Twin:
    """A machine twin: its configuration and the stages that run a program on it."""

    def __init__(self, machine: Machine | None = None, interpreter=None, path: str | None = None, cutting=None,
                 effects=(), tool_state=None):
        from ..cutting.library import Cutting, cutting_from_dict
        from ..gcode.interpreter import InterpreterSettings

        self.machine = machine or Machine()
        self.interpreter = interpreter or InterpreterSettings()
        self.path = path
        self.cutting: Cutting = cutting or cutting_from_dict({})
        # the base model's physical effects, in order (mtwin.effects); the twin file's
        # [effects.NAME] tables, or with_effects
        self.effects: tuple = tuple(effects)
        # tool number -> effects.ToolHistory: what each tool has cut before the program (the
        # tool ledger's record), so wear effects start from the tool's state, not a new tool
        self.tool_state: dict = dict(tool_state or {})
        from ..cutting.engagement import EngagementCache

        # engagement depends only on the path: kept between simulations of this twin
        self.engagement_cache = EngagementCache()
        from ..cutting.library import ProgramCuttings

        # each program's tools as it declares them, per cutting part (motion.simulate.program_cutting)
        self.cutting_cache = ProgramCuttings()

    def replace(self, *, share_cache: bool = True, **changes) -> "Twin":
        """A copy with some of ``machine``, ``interpreter``, ``path``, ``cutting``, ``effects``
        and ``tool_state`` replaced (by name, never by position).  ``share_cache``: keep this twin's
        engagement cache (right when the path cannot change: effects, tools, drive
        parameters); a new, empty one otherwise."""
        known = ("machine", "interpreter", "path", "cutting", "effects", "tool_state")
        unknown = sorted(set(changes) - set(known))
        if unknown:
            raise TypeError(f"Twin.replace: unknown field(s) {', '.join(unknown)} (known: {', '.join(known)})")
        values = {k: changes.get(k, getattr(self, k)) for k in known}
        tw = Twin(**values)
        if share_cache:
            tw.engagement_cache = self.engagement_cache
        tw.cutting_cache = self.cutting_cache  # (keyed by the cutting part: right for any change)
        return tw

    @classmethod
    def from_toml(cls, path: str | None, **interpreter_overrides) -> "Twin":
        """Twin from a twin file (None = the embedded default machine)."""
        from ..config import interpreter_settings
        from .files import load_cutting, load_effects, load_machine

        return cls(machine=load_machine(path), interpreter=interpreter_settings(path, **interpreter_overrides),
                   path=path, cutting=load_cutting(path), effects=load_effects(path))

    def with_effects(self, *effects) -> "Twin":
        """A copy with these effects added after the twin's own (Effect instances or
        ``"name:param=value,…"`` strings).  The engagement cache is shared."""
        from ..effects import parse_effect_spec

        new = tuple(parse_effect_spec(e) if isinstance(e, str) else e for e in effects)
        for e in new:
            e.resolved()
        return self.replace(effects=self.effects + new)

    def with_tool_state(self, state: dict) -> "Twin":
        """A copy whose tools start with these histories (tool number -> ``ToolHistory``) over
        the twin's own; the engagement cache is shared (the path does not change)."""
        return self.replace(tool_state={**self.tool_state, **{int(k): v for k, v in state.items()}})

    def simulate_batch(self, program, runs: int, *, stock=None, cutting: bool = True,
                       tooth_resolution: bool = False, on_run=None, keep_all: bool = True) -> "RunTraces":
        """``runs`` runs of a program on the same tools, each starting with the tools' histories
        after the runs before (the wear carried from part to part); planned once (the tools'
        state does not change the plan).  ``on_run(k, trace)`` is called as run k finishes;
        ``keep_all=False`` keeps only the last trace (memory stays that of one run)."""
        from ..effects import ToolHistory
        from ..motion.simulate import simulate_plan

        plan = self.plan(program)
        out = RunTraces()
        tw = self
        for k in range(1, int(runs) + 1):
            tr = simulate_plan(tw.machine, program, plan, **tw._run_parts(program, cutting), cutting=cutting,
                               stock=stock, tooth=tooth_resolution)
            if not keep_all and out:
                out.clear()
            out.append(tr)
            if on_run is not None:
                on_run(k, tr)
            used = tr.tool_use or {}
            tw = tw.with_tool_state({n: tw.tool_state.get(n, ToolHistory()) + u for n, u in used.items()})
        return out

    def _run_parts(self, program, cutting: bool) -> dict:
        """What a run of ``program`` takes from this twin besides the machine: the program's
        cutting part (its declared tools over the twin's), the effects, the tools' state and
        the engagement cache (``simulate_plan`` takes them, not the twin)."""
        from ..motion.simulate import program_cutting

        return {"cut_part": program_cutting(self, program) if cutting else self.cutting, "effects": self.effects,
                "tool_state": self.tool_state, "engagement_cache": self.engagement_cache}

    def with_tools(self, tools: dict) -> "Twin":
        """A copy that knows these tools (number -> ``mtwin.cutting.library.Tool``, or a
        ``"TYPE:DIAMETER[:FLUTES[:CORNER_RADIUS]]"`` string in mm) over the twin file's table and
        the program's comments — what ``--tool N=…`` does on the command line."""
        from dataclasses import replace

        from ..cutting.library import parse_tool_option

        parsed = {}
        for n, t in tools.items():
            parsed[int(n)] = parse_tool_option(f"{int(n)}={t}")[1] if isinstance(t, str) else t
        return self.replace(cutting=replace(self.cutting, declared={**self.cutting.declared, **parsed}))

    def with_material(self, name: str) -> "Twin":
        """A copy cutting catalogue material ``name`` (``"4140"``, ``"AL6061"``, ``"mdf"``:
        any name of ``mtwin materials``) — what ``--material`` does; a known material gives
        ``optimize`` its limits from physics (docs/catalogue.md)."""
        from ..cutting.library import with_material

        return self.replace(cutting=with_material(self.cutting, name, "--material"))

    def load(self, source, *, path: str | None = None):
        """Read and interpret a program with this twin's interpreter settings."""
        from ..gcode.interpreter import load_program

        return load_program(source, self.interpreter, path=path)

    def with_controller(self, **changes) -> "Twin":
        """A copy with some controller parameters changed (e.g. ``style="grbl"``)."""
        m = replace(self.machine, controller=replace(self.machine.controller, **changes))
        return self.replace(machine=m, share_cache=False)  # (a planner change may change the path)

    def with_params(self, values: dict) -> "Twin":
        """A copy with parameters changed by dotted name: the machine's
        (``"axes.x.servo.kpp"``, ``"controller.bell_time"``), the cutting material's and table
        tools' (``"cutting.al6061.ktc"``, ``"tools.1.diameter"``) and the effects'
        (``"effects.tool-wear.rate"``) — the handle calibration uses.
        The engagement cache is shared: the path does not depend on drive parameters unless
        the planner changes it, and the cache key covers that."""
        from .machine import with_params

        from ..cutting.library import with_cutting_params

        def is_cutting(k):
            return k.startswith(("cutting.", "tools."))

        machine_values = {k: v for k, v in values.items() if not is_effect_param(k) and not is_cutting(k)}
        cutting = with_cutting_params(self.cutting, {k: v for k, v in values.items() if is_cutting(k)})
        effects = list(self.effects)
        for key, value in values.items():
            if not is_effect_param(key):
                continue
            name, param = split_effect_param(key)
            idx = [i for i, e in enumerate(effects) if e.name == name]
            if not idx:
                from ..errors import ConfigError

                raise ConfigError(f"{key}: this twin has no effect {name!r} "
                                  f"(has {', '.join(e.name for e in effects) or 'none'})")
            effects[idx[-1]] = effects[idx[-1]].with_values(**{param: value})
            effects[idx[-1]].resolved()
        return self.replace(machine=with_params(self.machine, machine_values), cutting=cutting, effects=effects)

    def plan(self, program, *, feeds=None, spindles=None, like=None, keep_geometry: bool = False):
        """NCK stages: segments, limits, corners, look-ahead, timing.

        ``feeds`` / ``spindles``: per-record feed (mm/min) and spindle speed (rpm) replacing the
        program's, without rewriting it — how an optimiser tries F and S values; the path,
        and so the cached engagement, stays the same.  ``like``: a plan of the same path (by
        this twin, made with ``keep_geometry``) whose feed-independent stages are reused when
        only the feeds differ."""
        from ..motion.planner import plan_program

        return plan_program(_with_overrides(program, feeds, spindles), self.planned_machine, like, keep_geometry)

    @property
    def planned_machine(self):
        """The machine programs are planned on: this twin's, with its plan-stage effects
        (tool-change and spindle waits, block times, corner and arc speeds) applied."""
        m = self.machine
        for e in self.effects:
            if e.stage == "plan":
                m = e.machine(m, e.resolved())
        return m

    def simulate(self, program, *, every: int = 1, disturbance: np.ndarray | None = None, progress=None,
                 cutting: bool = True, stock=None, tooth_resolution: bool = False, feeds=None, spindles=None,
                 chatter: bool = True, plan=None):
        """Run a program through the controller, feed drives and cutting process; returns a Trace.

        ``every``: keep every n-th servo sample in the trace (statistics use all of them).
        ``cutting``: compute engagement on the stock and the cutting forces, torque and power
        (they act on the feed drives); ``stock``: a box (xmin, ymin, zmin, xmax, ymax, zmax)
        overriding the program's (MTWIN STOCK) comment, the twin file and the default.
        ``tooth_resolution``: instantaneous tooth-passing forces (spindle angle, helix lag) instead
        of revolution averages — for comparison with dynamometer data; shorten the servo period
        in the twin file to resolve the tooth frequency finely.
        ``disturbance``: an extra (samples, 3) force in N against each axis, by servo sample.
        ``feeds`` / ``spindles``: per-record overrides, as for :meth:`plan`.
        ``chatter``: the cutting lines' stability margins, for tools with dynamics (docs/chatter.md).
        ``plan``: this program's plan by this twin (:meth:`plan`), when the caller has made it.

        This is the one door to a simulation (``mtwin.simulate`` is the use case over it,
        :meth:`simulate_batch` the one for parts in a row)."""
        from ..motion.simulate import simulate_plan

        program = _with_overrides(program, feeds, spindles)
        if plan is None or feeds is not None or spindles is not None:
            plan = self.plan(program)
        return simulate_plan(self.machine, program, plan, **self._run_parts(program, cutting), every=every,
                             disturbance=disturbance,
                             progress=progress, cutting=cutting, stock=stock, tooth=tooth_resolution,
                             chatter=chatter)


class RunTraces(list):
    """The traces of one program run several times on the same tools (a batch of parts: each
    run starts where the one before left the tools), first run first.  Where one trace is
    expected it stands for its first run."""

    def __getattr__(self, name):
        return getattr(self[0], name)


def _with_overrides(program, feeds, spindles):
    """The program with its records' feed and spindle speed replaced (a shallow copy)."""
    if feeds is None and spindles is None:
        return program
    from dataclasses import replace as dc_replace

    from ..errors import MtwinError
    from ..gcode import records as R

    rec = program.records.copy()
    moving = (rec["kind"] != R.RAPID) & (rec["kind"] != R.DWELL)
    for name, values in (("feed", feeds), ("spindle", spindles)):
        if values is None:
            continue
        v = np.asarray(values, dtype=np.float64)
        if v.shape != (len(rec),):
            raise MtwinError(f"{name} overrides need one value per motion record ({len(rec)}), got shape {v.shape}")
        if not np.isfinite(v).all():
            raise MtwinError(f"{name} overrides must be finite")
        if name == "feed":
            if (v[moving] <= 0).any():
                raise MtwinError("feed overrides must be positive on feed moves")
            rec["feed"] = np.where(moving, v, rec["feed"])
        else:
            if (v < 0).any():
                raise MtwinError("spindle overrides must be >= 0 rpm")
            rec["spindle"] = v
    return dc_replace(program, records=rec)
