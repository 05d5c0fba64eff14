"""``mtwin optimize``: segment the predicted power curve, choose F (and S) per segment under
load, power and machine limits, write the program back and prove it (see docs/optimize.md).

    >>> import mtwin
    >>> from mtwin.optimize import optimize, OptimizeOptions
    >>> twin = mtwin.Twin()
    >>> prog = twin.load("samples/contour.nc")
    >>> res = optimize(twin, prog, OptimizeOptions(objective="time", force_limit=60.0))
    >>> res.after.peak_load, res.output[:20]
"""
from .run import InfeasibleError, OptimizeOptions, OptimizeResult, optimize
from .search import GAOptions

__all__ = ["optimize", "OptimizeOptions", "OptimizeResult", "GAOptions", "InfeasibleError"]
