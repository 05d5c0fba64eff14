"""Plunge grinding: the process model, optimal stepped feed cycles by dynamic programming, the
robustness loop and calibration to a recorded cycle (docs/grinding.md).

    >>> import mtwin
    >>> d = mtwin.grind.design(grid=(40, 40))          # the default twin: the reference's experiment
    >>> d.as_dict()["cycle_time"], d.gcode()[:40]
"""
from .usecases import (GrindCalibration, GrindDesign, GrindRun, calibrate, design, simulate)

__all__ = ["GrindCalibration", "GrindDesign", "GrindRun", "calibrate", "design", "simulate"]
