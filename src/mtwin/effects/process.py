"""Effects in the cutting process: they change the cutting coefficients along the path, so
the forces load the drives and the spindle in the loop."""
from __future__ import annotations

import numpy as np

from ..params import Param
from .base import Effect


class ToolWear(Effect):
    name = "tool-wear"
    description = "flank wear: the cutting coefficients grow with the length the tool has cut, K·(1 + w·L)"
    stage = "loop"
    params = (Param("rate", "1/m", 0.0, 0.0, 5.0, "relative growth of the cutting coefficients per metre of cut "
                    "[E: 0.05-0.5 /m in aluminium at finishing feeds]"),)
    signals = ("spindle_power", "spindle_torque", "fx", "fy", "fz", "x_torque", "y_torque", "z_torque",
               "x_current", "y_current", "z_current")

    def cutting_scale(self, steps, p):
        if not p["rate"]:
            return None
        return 1.0 + p["rate"] * steps.cut_length / 1000.0
