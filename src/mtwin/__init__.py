"""mtwin: a G-code optimiser built on a digital twin of a CNC machine tool.

The Python API mirrors the CLI; heavy modules (numba kernels) load on first use
so that ``import mtwin`` and ``mtwin --help`` stay fast.
"""
from __future__ import annotations

from .version import __version__

__all__ = ["load_program", "InterpreterSettings", "Program", "rewrite", "verify", "summarize", "scale_feeds",
           "Twin", "Machine", "TwinSetup", "Reading", "simulate", "scale", "optimize", "synthesize", "compare",
           "diagnose", "calibrate", "grind", "parse", "prove_path", "prove_stock", "import_log", "journal", "tools",
           "tool"]

# the use cases (mtwin.api): what each command runs, as functions
_USE_CASES = ("simulate", "scale", "synthesize", "compare", "diagnose", "calibrate", "Reading", "TwinSetup", "parse",
              "prove_path", "prove_stock", "import_log", "journal", "tools", "tool")


def __getattr__(name):
    if name in _USE_CASES:
        from . import api
        return getattr(api, name)
    if name in ("optimize", "grind"):
        # packages that are (optimize) or hold (grind) their use cases
        import importlib
        return importlib.import_module(f".{name}", __name__)
    if name in ("load_program", "InterpreterSettings", "Program"):
        from .gcode import interpreter
        return getattr(interpreter, name)
    if name in ("rewrite", "scale_feeds"):
        from .gcode import writer
        return getattr(writer, name)
    if name == "verify":
        from .gcode.verify import verify
        return verify
    if name == "Twin":
        from .twin import Twin
        return Twin
    if name == "Machine":
        from .twin.machine import Machine
        return Machine
    if name == "summarize":
        from .gcode.summary import summarize
        return summarize
    raise AttributeError(name)
