"""mtwin's use cases as functions: what each command runs, and the Python API.

Conventions (as python-control writes its own down):

* the twin comes first — a :class:`~mtwin.Twin`, a twin file's path, or None for the
  default machine — then the program (a :class:`~mtwin.Program`, a path with ``-`` for
  stdin, or its bytes, read with the twin's interpreter settings), then what the use case
  is about (a measurement file);
* options are keywords; units are the library's (mm, s, N, W, rpm; ``docs/conventions.md``);
* each returns a result object with ``as_dict()`` — what the command prints with ``--json``;
* nothing is printed: warnings and notes go to ``on_message(kind, text)`` as they arise and
  stay on the result's ``messages``; bad input raises :class:`~mtwin.errors.MtwinError`.

The housekeeping commands' use cases (twin files, effects, materials, the kernel cache) are
in :mod:`mtwin.api.admin`.

``mtwin.optimize`` (the optimiser, :func:`mtwin.optimize.run.optimize`) and
``mtwin.grind`` (plunge grinding) follow the same rules in their own packages.
"""
from __future__ import annotations

from ..loop.measurement import signal_unit
from ..twin.setup import Messages, TwinSetup, load_part, open_twin
from ..units import SI_UNITS
from .loop import (
                   Calibration,
                   Comparison,
                   Diagnosis,
                   Reading,
                   Synthetic,
                   calibrate,
                   compare,
                   diagnose,
                   import_log,
                   journal,
                   measured_program,
                   objective_for,
                   param_unit,
                   synthesize,
)
from .program import Parsed, parse
from .simulate import Scaled, Simulation, scale, simulate, simulate_runs
from .tools import tool, tools
from .verify import PathProof, prove_path, prove_stock

__all__ = ["Calibration", "Comparison", "Diagnosis", "Messages", "Parsed", "PathProof", "Reading", "SI_UNITS", "Scaled",
           "Simulation", "Synthetic", "TwinSetup", "calibrate", "compare", "diagnose", "load_part", "measured_program",
           "objective_for", "open_twin", "parse", "prove_path", "prove_stock", "scale", "simulate", "simulate_runs",
           "synthesize", "import_log", "journal", "tools", "tool", "signal_unit", "param_unit"]
