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

    def __init__(self, machine: Machine | None = None, interpreter=None, path: str | None = None, cutting=None):
        from ..cutting.library import Cutting, cutting_from_dict
        from ..gcode.interpreter import InterpreterSettings

        self.machine = machine or Machine()
        self.interpreter = interpreter or InterpreterSettings()
        self.path = path
        self.cutting: Cutting = cutting or cutting_from_dict({})

    @classmethod
    def from_toml(cls, path: str | None, **interpreter_overrides) -> "Twin":
        """Twin from a twin file (None = the embedded default machine)."""
        from ..config import interpreter_settings, load_cutting, load_machine

        return cls(load_machine(path), interpreter_settings(path, **interpreter_overrides), path, load_cutting(path))

    def load(self, source, *, path: str | None = None):
        """Read and interpret a program with this twin's interpreter settings."""
        from ..gcode.interpreter import load_program

        return load_program(source, self.interpreter, path=path)

    def with_controller(self, **changes) -> "Twin":
        """A copy with some controller parameters changed (e.g. ``style="grbl"``)."""
        m = replace(self.machine, controller=replace(self.machine.controller, **changes))
        return Twin(m, self.interpreter, self.path, self.cutting)

    def plan(self, program):
        """NCK stages: segments, limits, corners, look-ahead, timing."""
        from ..motion.planner import plan_program

        return plan_program(program, self.machine)

    def simulate(self, program, *, every: int = 1, disturbance: np.ndarray | None = None, progress=None,
                 cutting: bool = True, stock=None, tooth_resolution: bool = False):
        """Run a program through the controller, feed drives and cutting process; returns a Trace.

        ``every``: keep every n-th servo sample in the trace (statistics use all of them).
        ``cutting``: compute engagement on the stock and the cutting forces, torque and power
        (they act on the feed drives); ``stock``: a box (xmin, ymin, zmin, xmax, ymax, zmax)
        overriding the program's (MTWIN STOCK) comment, the twin file and the default.
        ``tooth_resolution``: instantaneous tooth-passing forces (spindle angle, helix lag) instead
        of revolution averages — for comparison with dynamometer data; shorten the servo period
        in the twin file to resolve the tooth frequency finely.
        ``disturbance``: an extra (samples, 3) force in N against each axis, by servo sample."""
        from ..motion.simulate import simulate_plan

        return simulate_plan(self, program, self.plan(program), every=every, disturbance=disturbance,
                             progress=progress, cutting=cutting, stock=stock, tooth=tooth_resolution)
