"""Effects in the feed drives: friction, gravity.  They change the per-axis table the servo
loop reads (``motion._runkernel.SV_*``), so the drives feel them and the motor torques,
currents and following errors change with them."""
from __future__ import annotations

from .. import layout as RK  # the servo table's columns (mtwin.layout)
from ..layout import AXES, AXIS_Z
from ..params import Param
from .base import Effect

G = 9.80665  # m/s²

_TORQUES = tuple(f"{a}_torque" for a in AXES) + tuple(f"{a}_current" for a in AXES)
# what a change in an axis' drive shows in: its motor torque and current, its following error
_DRIVE_SIGNALS = _TORQUES + tuple(f"{a}_err" for a in AXES)


def _per_axis(prefix: str, unit: str, lower: float, upper: float, doc: str) -> tuple[Param, ...]:
    """One parameter per axis (``fx``, ``fy``, ``fz``), zero by default: the twin as it is."""
    return tuple(Param(f"{prefix}{a}", unit, 0.0, lower, upper, f"{doc} {a.upper()}") for a in AXES)


class CoulombFriction(Effect):
    name = "coulomb-friction"
    description = "more (or less) Coulomb friction in an axis' guideways and screw than the twin file has"
    stage = "loop"
    params = _per_axis("f", "N", -300.0, 2000.0, "Coulomb friction (both directions) added to")
    signals = _DRIVE_SIGNALS

    def servo(self, sv, p):
        for k, a in enumerate(AXES):
            d = p["f" + a]
            for c_col, s_col in ((RK.SV_FCP, RK.SV_FSP), (RK.SV_FCN, RK.SV_FSN)):
                sv[k, c_col] = max(0.0, sv[k, c_col] + d)
                sv[k, s_col] = max(sv[k, c_col], sv[k, s_col] + d)


class ViscousFriction(Effect):
    name = "viscous-friction"
    description = "more (or less) viscous friction B·v in an axis than the twin file has"
    stage = "loop"
    params = _per_axis("b", "N*s/m", -1000.0, 20000.0, "viscous coefficient added to")
    signals = _DRIVE_SIGNALS

    def servo(self, sv, p):
        for k, a in enumerate(AXES):
            sv[k, RK.SV_B] = max(0.0, sv[k, RK.SV_B] + p["b" + a])


class StribeckFriction(Effect):
    name = "stribeck-friction"
    description = "breakaway (static) friction above Coulomb, decaying over the Stribeck velocity"
    stage = "loop"
    params = _per_axis("s", "N", 0.0, 2000.0, "breakaway friction added to") + (
        Param("vs_scale", "", 1.0, 0.1, 10.0, "factor on every axis' Stribeck velocity"),)
    signals = _DRIVE_SIGNALS

    def servo(self, sv, p):
        for k, a in enumerate(AXES):
            sv[k, RK.SV_FSP] += p["s" + a]
            sv[k, RK.SV_FSN] += p["s" + a]
            sv[k, RK.SV_VS] *= p["vs_scale"]


class Gravity(Effect):
    name = "gravity"
    description = "the Z axis carries a weight no counterbalance takes: m·g on its drive"
    stage = "loop"
    params = (Param("mass", "kg", 0.0, 0.0, 2000.0, "uncompensated mass on Z"),)
    signals = ("z_torque", "z_current", "z_err")

    def servo(self, sv, p):
        sv[AXIS_Z, RK.SV_FG] += p["mass"] * G


class Inertia(Effect):
    name = "inertia"
    description = "the drive moves more (or less) mass than its gains were set for: a heavy part or fixture"
    stage = "loop"
    params = _per_axis("m", "kg", -100.0, 2000.0, "mass (the gains stay as they are) added to")
    signals = _DRIVE_SIGNALS

    def servo(self, sv, p):
        for k, a in enumerate(AXES):
            sv[k, RK.SV_MP] = max(1.0, sv[k, RK.SV_MP] + p["m" + a])
