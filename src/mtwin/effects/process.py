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


class SizeEffect(Effect):
    name = "size-effect"
    description = ("the specific cutting force rises as the chip thins: K·(h/h_ref)^(−x), h the chip "
                   "thickness (Kienzle)")
    stage = "loop"
    params = (Param("x", "", 0.0, 0.0, 0.8, "exponent of the chip thickness [S: Kienzle 1-mc, 0.15-0.35]"),
              Param("h_ref", "mm", 0.1, 0.005, 1.0, "chip thickness at which the coefficients are the twin's"))
    signals = ToolWear.signals

    def cutting_scale(self, steps, p):
        if not p["x"]:
            return None
        # the chip thickness the program asks for (programmed feed per tooth × the step's
        # maximum-chip factor): the forces stay linear in the actual feed per tooth in the
        # kernel, so the factor is the size effect at the programmed feed (docs/effects.md)
        h = np.maximum(steps.h_max, 1e-4)
        return np.where(steps.area > 0, (h / p["h_ref"]) ** (-p["x"]), 1.0)
