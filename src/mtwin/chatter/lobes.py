"""Stability lobes: the limiting axial depth of a cut against spindle speed.

Two methods (docs/chatter.md):

* ``zoa`` — the zero-order approximation (Altintas & Budak 1995): the time-varying
  directional matrix replaced by its mean over a revolution; closed form per chatter
  frequency, solved here per speed (every boundary crossing on a fine frequency grid,
  bisected).  Fast; misses the period-doubling (flip) lobes of low radial immersion.
* ``sdm`` — semi-discretisation (Insperger & Stépán 2002, 2004): the delay equation's
  one-period map, its multipliers; exact as its steps are refined; finds flip lobes.

``auto`` takes sdm where the engaged arc is under a third of the tooth pitch (where flip
lobes appear and the mean directional matrix is a poor stand-in) and the tool has modes, zoa
elsewhere.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError
from . import _lobekernel as LK
from .modes import FRF, Mode

METHODS = ("zoa", "sdm", "auto")


@dataclass(frozen=True)
class Cut:
    """A cut's engagement for the stability model: the engaged arc [φst, φex] (rad, from the
    tool frame's +y, clockwise; x along the feed), the feed direction in the machine's XY
    (rad from +X) and the spindle's hand (1: M3, clockwise seen from above)."""

    phi_st: float
    phi_ex: float
    feed_angle: float = 0.0
    hand: int = 1

    @classmethod
    def of(cls, immersion: float, milling: str = "down", feed_angle: float = 0.0, hand: int = 1) -> "Cut":
        """A straight cut at radial immersion ae/D: up milling enters at φ = 0, down milling
        leaves at φ = π; immersion 1 is a slot."""
        if not (0.0 < immersion <= 1.0) or not math.isfinite(immersion):
            raise ConfigError(f"the radial immersion ae/D must be in (0, 1], got {immersion:g}")
        if milling not in ("down", "up"):
            raise ConfigError(f"milling must be down or up, got {milling!r}")
        sweep = math.acos(1.0 - 2.0 * immersion)
        if milling == "up":
            return cls(0.0, sweep, feed_angle, hand)
        return cls(math.pi - sweep, math.pi, feed_angle, hand)

    @property
    def rotation(self) -> np.ndarray:
        """Columns: the tool frame's x (feed) and y (left of the feed for M3) in machine XY."""
        c, s = math.cos(self.feed_angle), math.sin(self.feed_angle)
        return np.array([[c, -s * self.hand], [s, c * self.hand]])

    @property
    def immersion(self) -> float:
        return 0.5 * (math.cos(self.phi_st) - math.cos(self.phi_ex))


def directional(cut: Cut, flutes: int, kt: float, kr: float) -> np.ndarray:
    """The mean directional matrix D (machine frame, N/m² per unit depth: force per metre of
    regenerative displacement per metre of depth): K_t·(N/2π)·R·∫a(φ)dφ·Rᵀ."""
    acc = np.zeros((2, 2))
    LK.arc_integral.py_func(cut.phi_st, cut.phi_ex, kr, acc)
    R = cut.rotation
    return kt * flutes / (2.0 * math.pi) * (R @ acc @ R.T)


@dataclass
class Lobes:
    """Limiting depth (mm) per spindle speed (rpm): ``depth_limit`` the minimum over every lobe
    at each speed, ``flip`` where the limiting lobe is a period-doubling one (sdm),
    ``chatter_frequency`` (Hz) of the limiting lobe."""

    speeds: np.ndarray
    depth_limit: np.ndarray
    flip: np.ndarray
    chatter_frequency: np.ndarray
    method: str
    cut: Cut | None = None
    flutes: int = 2
    notes: list = field(default_factory=list)

    def as_dict(self) -> dict:
        def fin(a):
            return [None if not math.isfinite(x) else float(x) for x in a]

        return {"speeds": [float(x) for x in self.speeds], "depth_limit": fin(self.depth_limit),
                "flip": [bool(x) for x in self.flip], "chatter_frequency": fin(self.chatter_frequency),
                "method": self.method}

    def at(self, speed) -> np.ndarray:
        """The limit (mm) at speeds (linear interpolation on the grid; inf stays inf)."""
        d = np.where(np.isfinite(self.depth_limit), self.depth_limit, 1e9)
        return np.interp(speed, self.speeds, d)

    def pockets(self, count: int = 5) -> list[tuple[float, float]]:
        """The stable pockets: the lobe peaks (local maxima of the limit), highest first."""
        d = np.where(np.isfinite(self.depth_limit), self.depth_limit, np.nan)
        out = []
        for i in range(1, len(d) - 1):
            if d[i] >= d[i - 1] and d[i] > d[i + 1]:
                out.append((float(self.speeds[i]), float(d[i])))
        out.sort(key=lambda p: -p[1])
        return out[:count]


@dataclass(frozen=True)
class Dynamics:
    """A tool's tip dynamics: modes, or a measured FRF (which stands where both are given)."""

    modes: tuple[Mode, ...] = ()
    frf: FRF | None = None

    def __bool__(self) -> bool:
        return bool(self.modes) or self.frf is not None

    def mode_arrays(self):
        m = self.modes
        return (np.array([x.fn for x in m], float), np.array([x.zeta for x in m], float),
                np.array([x.k for x in m], float), np.array([0 if x.direction == "x" else 1 for x in m], np.int64))

    def table(self):
        if self.frf is None:
            z = np.zeros(0)
            return z, z.astype(complex), z.astype(complex)
        return self.frf.freq.astype(float), self.frf.xx.astype(complex), self.frf.yy.astype(complex)

    def frequency_grid(self) -> np.ndarray:
        """Where to look for chatter: the FRF's own frequencies (three more between each pair),
        or around the modes — a log grid over 0.3·fmin … 3·fmax (900 points, 0.3 % apart) and
        400 points within ±8ζ of every natural frequency.  (Beyond that band |Φ| is a small
        share of its peak: the limits there are far above the modes' own.)"""
        if self.frf is not None:
            f = self.frf.freq
            return np.unique(np.concatenate([f, np.interp(np.arange(0, len(f) - 1, 0.25), np.arange(len(f)), f)]))
        fn = np.array([m.fn for m in self.modes])
        parts = [np.geomspace(0.3 * fn.min(), 3.0 * fn.max(), 900)]
        for m in self.modes:
            w = 8.0 * max(m.zeta, 0.002) * m.fn
            parts.append(np.linspace(max(m.fn - w, 1e-3), m.fn + w, 400))
        return np.unique(np.concatenate(parts))


def speed_grid(lo: float, hi: float, count: int = 0) -> np.ndarray:
    from ..params import UNIT_MAX

    if not (0 < lo < hi <= UNIT_MAX["rpm"]):
        raise ConfigError(f"--speed-range: expected LO,HI rpm with 0 < LO < HI <= {UNIT_MAX['rpm']:g}, got "
                          f"{lo:g},{hi:g}")
    if count <= 0:
        count = 500
    return np.linspace(lo, hi, count)


def lobes(dyn: Dynamics, cut: Cut, flutes: int, ktc: float, krc: float, speeds: np.ndarray,
          method: str = "auto", steps: int = 40, refine: bool = True) -> Lobes:
    """The stability lobes of a cut (``ktc``, ``krc``: the material's coefficients, N/mm²)."""
    if not dyn:
        raise ConfigError("the tool has no dynamics: give it [[tools.N.modes]] or tools.N.frf in the twin file")
    if method not in METHODS:
        raise ConfigError(f"--method must be one of {', '.join(METHODS)}, got {method!r}")
    if flutes < 1:
        raise ConfigError("a tool needs at least one flute")
    speeds = np.asarray(speeds, float)
    kt = ktc * 1e6
    kr = krc / ktc
    notes = []
    pitch = 2.0 * math.pi / flutes
    chosen = method
    if method == "auto":
        narrow = (cut.phi_ex - cut.phi_st) < pitch / 3.0
        chosen = "sdm" if narrow and dyn.modes and dyn.frf is None else "zoa"
        if chosen == "sdm":
            notes.append("auto: sdm (engaged arc under a third of the tooth pitch)")
        elif narrow:
            notes.append("auto: zoa — the arc is under a third of the tooth pitch, where the semi-discretisation "
                         "finds flip lobes the zero-order approximation misses, but a measured FRF has no "
                         "state-space model: fit modes to it (mtwin calibrate-frf) for the exact method")
        else:
            notes.append("auto: zoa (arc wide enough for the mean directional matrix)")
    if chosen == "sdm" and (not dyn.modes or dyn.frf is not None):
        raise ConfigError("the semi-discretisation needs the tool's modes (a measured FRF has no state-space "
                          "model): fit them with mtwin calibrate-frf and put them in the twin file")
    D = directional(cut, flutes, kt, kr)
    mfn, mz, mk, mdir = dyn.mode_arrays()
    tf, txx, tyy = dyn.table()
    grid = _grid(dyn)

    def zoa(sp):
        depth = np.empty(len(sp))
        freq = np.empty(len(sp))
        LK.zoa_limits.auto(len(sp) * 4000, sp, float(flutes), D, grid, mfn, mz, mk, mdir, tf, txx, tyy, depth, freq)
        return depth, freq

    def compute(sp):
        depth, freq = zoa(sp)
        if chosen == "zoa":
            return depth * 1e3, np.zeros(len(sp), bool), freq
        fin = np.isfinite(depth)
        zmin = float(depth[fin].min()) if fin.any() else 1e-3
        # flip lobes lie below the zoa's limit, Hopf lobes near it: scan up to 1.6× of it
        s_hi = np.where(fin, np.minimum(1.6 * depth, 40.0 * zmin), 40.0 * zmin)
        sdepth = np.empty(len(sp))
        flip = np.zeros(len(sp), np.bool_)
        mult = np.empty(len(sp))
        LK.sdm_limits(sp, flutes, cut.phi_st, cut.phi_ex, kt, kr, cut.rotation, mfn, mz, mk, mdir, int(steps),
                      s_hi, 16, 10, sdepth, flip, mult)
        # chatter frequency of the critical multiplier e^{iθ}: ±θ/(2πT) + k/T, the one nearest
        # the zoa's (the structure's response picks which harmonic family chatters)
        T = 60.0 / (flutes * sp)
        base = np.abs(mult) / (2.0 * math.pi * T)
        ref = np.where(np.isfinite(freq), freq, mfn.mean())
        f1 = base + np.round((ref - base) * T) / T
        f2 = -base + np.round((ref + base) * T) / T
        return sdepth * 1e3, flip, np.where(np.abs(f2 - ref) < np.abs(f1 - ref), f2, f1)

    sp, d, fl, fr = refined(compute, speeds) if refine else (speeds, *compute(speeds))
    return Lobes(sp, d, fl, fr, chosen, cut, flutes, notes)


def zoa_slot_minimum(k: float, zeta: float, flutes: int, kn: float) -> float:
    """Closed form of the zero-order approximation's lowest limit (m) for a slot with one mode
    of stiffness k (N/m) and damping ζ along the feed (docs/chatter.md): the mean directional
    factor is D_xx = −N·K_n/4 per unit depth and min Re Φ = −1/(4kζ(1+ζ)) (at ω = ωn·√(1+2ζ)),
    so a_min = 2kζ(1+ζ)/|D_xx| = 8kζ(1+ζ)/(N·K_n)."""
    return 8.0 * k * zeta * (1.0 + zeta) / (flutes * kn)


@functools.lru_cache(maxsize=64)
def _grid(dyn: Dynamics) -> np.ndarray:
    """A tool's frequency grid, made once (a program's margins ask for it per arc group)."""
    return dyn.frequency_grid()


@functools.lru_cache(maxsize=64)
def peak_compliance(dyn: Dynamics) -> float:
    """max over the frequency grid of max(|Φxx|, |Φyy|), m/N."""
    from .modes import compliance

    xx, yy = compliance(dyn.modes, dyn.frf, _grid(dyn))
    return float(max(np.abs(xx).max(initial=0.0), np.abs(yy).max(initial=0.0)))


@functools.lru_cache(maxsize=16)
def _frf_file(path: str) -> FRF:
    from .modes import read_frf

    return read_frf(path)


def dynamics_of(tool) -> Dynamics:
    """A library tool's tip dynamics (empty when it has neither modes nor an FRF)."""
    return Dynamics(tuple(tool.modes), _frf_file(tool.frf) if tool.frf else None)


def refined(compute, speeds: np.ndarray, rounds: int = 5, minima: int = 8):
    """``compute(speeds) -> (depth, flip, freq)`` on a grid, then around its lowest local minima
    two more speeds per round (a ternary refinement), merged in order: the lowest limit is
    found within a small fraction of the grid's spacing."""
    d, fl, fr = compute(speeds)
    for _ in range(rounds):
        inner = np.flatnonzero((d[1:-1] <= d[:-2]) & (d[1:-1] <= d[2:])) + 1
        if not len(inner):
            break
        inner = inner[np.argsort(d[inner])[:minima]]
        new = np.unique(np.concatenate([(2 * speeds[inner] + speeds[inner - 1]) / 3,
                                        (2 * speeds[inner] + speeds[inner + 1]) / 3]))
        new = new[~np.isin(new, speeds)]
        if not len(new):
            break
        d2, fl2, fr2 = compute(new)
        speeds = np.concatenate([speeds, new])
        o = np.argsort(speeds, kind="stable")
        speeds, d, fl, fr = speeds[o], np.concatenate([d, d2])[o], np.concatenate([fl, fl2])[o], \
            np.concatenate([fr, fr2])[o]
    return speeds, d, fl, fr
