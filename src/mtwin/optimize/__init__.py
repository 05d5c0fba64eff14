"""``mtwin optimize``: segment the predicted power curve, choose F (and S) per segment under
load, power and machine limits, write the program back and prove it (see docs/optimize.md).

    >>> import mtwin
    >>> res = mtwin.optimize(None, "samples/contour.nc", mtwin.optimize.OptimizeOptions(force_limit=60.0))
    >>> res.after.peak_load, res.output[:20], res.as_dict()["verdict"]

``mtwin.optimize`` is this package and, called, :func:`mtwin.optimize.run.optimize` — the
use case as the other use cases are functions of ``mtwin`` (``mtwin.simulate``, …).
"""
import sys
import types

from .guards import line_ranges
from .layers import MAX_LAYERS
from .run import InfeasibleError, OptimizeOptions, OptimizeResult, optimize, parse_force_limit, record_optimised
from .search import GAOptions


class _CallablePackage(types.ModuleType):
    def __call__(self, *args, **kwargs):
        return optimize(*args, **kwargs)


sys.modules[__name__].__class__ = _CallablePackage

__all__ = ["optimize", "OptimizeOptions", "OptimizeResult", "GAOptions", "InfeasibleError", "MAX_LAYERS",
           "line_ranges", "parse_force_limit", "record_optimised"]
