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

from .machine import Machine


class Twin:
    """A machine twin: its configuration and the stages that run a program on it."""

    def __init__(self, machine: Machine | None = None, interpreter=None, path: str | None = None):
        from ..gcode.interpreter import InterpreterSettings

        self.machine = machine or Machine()
        self.interpreter = interpreter or InterpreterSettings()
        self.path = path

    @classmethod
    def from_toml(cls, path: str | None, **interpreter_overrides) -> "Twin":
        """Twin from a twin file (None = the embedded default machine)."""
        from ..config import interpreter_settings, load_machine

        return cls(load_machine(path), interpreter_settings(path, **interpreter_overrides), path)

    def load(self, source, *, path: str | None = None):
        """Read and interpret a program with this twin's interpreter settings."""
        from ..gcode.interpreter import load_program

        return load_program(source, self.interpreter, path=path)

    def with_controller(self, **changes) -> "Twin":
        """A copy with some controller parameters changed (e.g. ``style="grbl"``)."""
        m = replace(self.machine, controller=replace(self.machine.controller, **changes))
        return Twin(m, self.interpreter, self.path)

    def plan(self, program):
        """NCK stages: segments, limits, corners, look-ahead, timing."""
        from ..motion.planner import plan_program

        return plan_program(program, self.machine)

    def simulate(self, program, *, every: int = 1, disturbance: np.ndarray | None = None, progress=None):
        """Run a program through the controller and feed drives; returns a Trace.

        ``every``: keep every n-th servo sample in the trace (statistics use all of them).
        ``disturbance``: optional (samples, 3) cutting-force input in N, acting against
        each axis (the cutting-load model fills it)."""
        from ..motion.simulate import simulate_plan

        return simulate_plan(self, program, self.plan(program), every=every, disturbance=disturbance,
                             progress=progress)
