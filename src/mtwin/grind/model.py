"""The plunge-grinding twin: parameters and the allowance-removal model (docs/grinding.md).

Per gauge interval and per angular position k (K positions around the part, so an initial
run-out ΔR_k is modelled), the radial force with the feed per revolution f = Δt_f (mm/rev):

    P_y(f) = a1·f + a2·√f,   a1 = 1.9·σ·B·(π·d·n_w) / (π·D·n_s),   a2 = η·B·(σ/3)·√(d·D / (D + d))

This is PHYSICS.md section 7's wide-range force model reinterpreted [D]: its second term with
S_f = f·n_w as written (a2 = η·K2·√n_w); its first term divided by n_w — read literally, with
V in the workpiece speed's units, it is not a force (N/min), and 1.9·σ·B·h_eq with the
equivalent chip thickness h_eq = f·v_w/V is the force it stands for (the literal reading is
180 times larger here, about 5,500 N at 3 mm/min, which would make the reference's own
experiment infeasible).  The system deflects by y = γ·P_y, so what the wheel has been fed but
not yet removed at position k is t_p − t_f,k − ΔR_k = f + γ·P_y(f), a quadratic in x = √f:

    (1 + γ·a1)·x² + γ·a2·x − (t_p − t_f,k − ΔR_k) = 0.

Its positive root is the reference's closed form, which therefore gives √Δt_f (the square is
missing there); f = x².  Where the wheel is not yet in contact (the right-hand side ≤ 0)
nothing is removed and the force is 0.  A zero programmed feed (spark-out) lets the stored
deflection grind itself away.

Every array is (cases, K): batches of parts (the robustness loop, the DP's transitions) run
as one numpy computation.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError
from ..params import Param
from ..tomlwrite import toml_value

#: Every parameter of the grinding twin, by dotted name (units, bounds, sources).
PARAMS = (
    Param("wheel.diameter", "mm", 600.0, 50.0, 1500.0, "wheel diameter D", "[S] reference experiment"),
    Param("wheel.width", "mm", 40.0, 1.0, 300.0, "wheel width B (plunge: the ground width)", "[S] reference"),
    Param("wheel.speed", "rpm", 1480.0, 100.0, 20000.0, "wheel speed", "[S] reference experiment"),
    Param("wheel.bluntness", "", 0.02, 0.0, 0.5, "η: share of the wheel surface worn to flats", "[E]"),
    Param("wheel.force_limit", "N", 600.0, 1.0, 1e5, "largest radial force the wheel may take", "[E]"),
    Param("work.diameter", "mm", 60.0, 1.0, 1000.0, "workpiece diameter d", "[E] reference-like part"),
    Param("work.speed", "rpm", 180.0, 1.0, 3000.0, "workpiece speed n_w", "[S] reference experiment"),
    Param("work.sigma", "N/mm^2", 2000.0, 100.0, 10000.0, "σ: stress intensity of the work material",
          "[E] hardened steel"),
    Param("work.allowance", "mm", 0.15, 0.001, 5.0, "grinding allowance on the radius", "[E]"),
    Param("work.runout", "mm", 0.01, 0.0, 1.0, "initial radial run-out (amplitude of ΔR_k)", "[E]"),
    Param("system.compliance", "mm/N", 0.0002, 0.0, 0.01, "γ: wheel-work system compliance",
          "[S] reference experiment"),
    Param("system.positions", "", 36.0, 4.0, 720.0, "angular positions K around the part", "[E]"),
    Param("gauge.error", "mm", 0.0, -0.1, 0.1, "in-process gauge error (reads this much over the size)", "[E]"),
    Param("gauge.reads_per_rev", "", 12.0, 1.0, 720.0, "gauge readings per workpiece revolution", "[E]"),
    Param("machine.feed_min", "mm/min", 0.05, 0.001, 100.0, "lowest programmed radial feed", "[E]"),
    Param("machine.feed_max", "mm/min", 3.0, 0.001, 100.0, "highest programmed radial feed", "[E]"),
    Param("machine.retract", "s", 0.5, 0.0, 60.0, "rapid approach and retract, per cycle", "[E]"),
    Param("limits.size", "mm", 0.004, 1e-5, 1.0, "size tolerance on the radius (|final − target|)", "[E]"),
    Param("limits.roundness", "mm", 0.003, 1e-5, 1.0, "roundness (max − min radius at the end)", "[E]"),
    Param("limits.roughness_feed", "mm", 0.002, 1e-6, 0.1,
          "roughness proxy: largest actual feed per revolution at the end (the last gauge interval)", "[E]"),
    Param("limits.burn_qw", "mm^2/s", 4.0, 0.01, 100.0,
          "burn: largest specific removal rate Q'w = π·d·(actual feed, mm/s)", "[E] ~3-6 for hardened steel"),
    Param("cycle.sparkout", "", 4.0, 0.0, 200.0, "fewest spark-out revolutions after the last stage", "[E]"),
    Param("cycle.sparkout_max", "", 150.0, 0.0, 1000.0,
          "most spark-out revolutions the design may choose (it takes the fewest that hold the limits)", "[E]"),
)
BY_NAME = {p.name: p for p in PARAMS}


@dataclass(frozen=True)
class GrindTwin:
    """A grinding machine, wheel and part: values by dotted name (defaults: the reference's
    experiment, 600 × 40 mm wheel at 1,480 rpm, part at 180 rpm, γ = 0.0002 mm/N)."""

    values: dict = field(default_factory=lambda: {p.name: p.default for p in PARAMS})

    def __getitem__(self, name: str) -> float:
        return self.values[name]

    def with_params(self, changes: dict) -> "GrindTwin":
        """A copy with parameters set by dotted name (checked against their bounds)."""
        v = dict(self.values)
        for k, x in changes.items():
            p = BY_NAME.get(k)
            if p is None:
                raise ConfigError(f"unknown grinding parameter {k!r} (known: {', '.join(BY_NAME)})")
            v[k] = p.check(x, k)
        if v["machine.feed_min"] >= v["machine.feed_max"]:
            raise ConfigError("machine.feed_min must be below machine.feed_max")
        if v["cycle.sparkout_max"] < v["cycle.sparkout"]:
            raise ConfigError("cycle.sparkout_max must not be below cycle.sparkout")
        for k in ("system.positions", "gauge.reads_per_rev", "cycle.sparkout", "cycle.sparkout_max"):
            if v[k] != int(v[k]):
                raise ConfigError(f"{k} must be a whole number, got {v[k]:g}")
        if int(v["system.positions"]) % int(v["gauge.reads_per_rev"]):
            raise ConfigError("gauge.reads_per_rev must divide system.positions (a reading every so many positions)")
        return GrindTwin(v)

    @classmethod
    def from_toml(cls, path: str | None) -> "GrindTwin":
        """The twin of a grind file ([wheel], [work], [system], [gauge], [machine], [limits],
        [cycle] tables); None: the defaults."""
        if path is None:
            return cls()
        raw = read_toml(path, "grind file")
        flat = {}
        for sec, body in raw.items():
            if sec == "cycle" and isinstance(body, dict) and "stages" in body:
                body = {k: v for k, v in body.items() if k != "stages"}
            if not isinstance(body, dict):
                raise ConfigError(f"{path}: [{sec}] must be a table")
            for k, x in body.items():
                flat[f"{sec}.{k}"] = x
        try:
            return cls().with_params(flat)
        except ConfigError as exc:
            raise ConfigError(f"{path}: {exc}") from None

    def toml(self) -> str:
        """The twin as a commented grind file."""
        out = ["# mtwin grind twin: wheel, part, system, gauge, machine, limits (mtwin grind design --twin FILE)"]
        sec = None
        for p in PARAMS:
            s, k = p.name.split(".", 1)
            if s != sec:
                out += ["", f"[{s}]"]
                sec = s
            out.append(f"{k:<15} = {toml_value(self.values[p.name]):<10}  # [{p.unit or '1'}] {p.doc} {p.source}")
        return "\n".join(out) + "\n"

    # ---- derived coefficients
    def coefficients(self) -> tuple[float, float]:
        """(a1 N/mm, a2 N/mm^0.5) of the force model."""
        D, B, nw = self["wheel.diameter"], self["wheel.width"], self["work.speed"]
        d, sigma, eta = self["work.diameter"], self["work.sigma"], self["wheel.bluntness"]
        ratio = (math.pi * d * nw) / (math.pi * D * self["wheel.speed"])  # work / wheel surface speed
        a1 = 1.9 * sigma * B * ratio
        a2 = eta * B * (sigma / 3.0) * math.sqrt(d * D / (D + d))
        return a1, a2


def read_toml(path: str, what: str) -> dict:
    """A TOML file's tables, or a ConfigError naming the file."""
    import sys
    from pathlib import Path

    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover
        import tomli as tomllib
    try:
        from ..io import read_input

        return tomllib.loads(read_input(path, "cycle").decode("utf-8"))
    except OSError as exc:
        raise ConfigError(f"cannot read {what} {path}: {exc.strerror or exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: invalid TOML: {exc}") from None


def removal_step(rhs: np.ndarray, a1, a2, gamma):
    """Feed per revolution actually removed (mm) and radial force (N) for the infeed not yet
    removed ``rhs`` = t_p − t_f,k − ΔR_k (arrays broadcast; a1, a2, γ per case)."""
    c = 1.0 + gamma * a1
    b = gamma * a2
    r = np.maximum(rhs, 0.0)
    # x = −b/2c + √((b/2c)² + r/c), written without the cancellation for small r
    x = 2.0 * r / (b + np.sqrt(b * b + 4.0 * c * r) + 1e-300)
    f = x * x
    return f, a1 * f + a2 * x


@dataclass
class Batch:
    """Per-case parameters of a batch of parts (arrays of shape (cases,))."""

    a1: np.ndarray
    a2: np.ndarray
    gamma: np.ndarray
    allowance: np.ndarray
    runout: np.ndarray
    gauge: np.ndarray

    @classmethod
    def nominal(cls, twin: GrindTwin, n: int = 1) -> "Batch":
        a1, a2 = twin.coefficients()
        one = np.ones(n)
        return cls(a1 * one, a2 * one, twin["system.compliance"] * one, twin["work.allowance"] * one,
                   twin["work.runout"] * one, twin["gauge.error"] * one)

    @property
    def size(self) -> int:
        return len(self.a1)


@dataclass
class State:
    """Where each part of a batch is: programmed infeed, material removed per position."""

    tp: np.ndarray  # (cases,) programmed infeed since first contact possible, mm
    removed: np.ndarray  # (cases, K) mm removed at each position
    t: np.ndarray  # (cases,) s
    last_f: np.ndarray  # (cases,) largest actual feed per revolution in the last gauge interval, mm
    peak_force: np.ndarray  # (cases,) N
    peak_rate: np.ndarray  # (cases,) largest actual feed, mm/min
    last_force: np.ndarray  # (cases,) largest radial force in the last gauge interval, N
    phase: np.ndarray  # (cases,) int, the angular position the wheel meets next

    @classmethod
    def start(cls, batch: Batch, K: int) -> "State":
        n = batch.size
        return cls(np.zeros(n), np.zeros((n, K)), *(np.zeros(n) for _ in range(5)), np.zeros(n, np.int64))

    def copy(self) -> "State":
        return State(*(getattr(self, f).copy() for f in STATE_FIELDS))

    def take(self, idx) -> "State":
        return State(*(getattr(self, f)[idx] for f in STATE_FIELDS))

    def put(self, idx, other: "State") -> None:
        """Write ``other`` (a state of len(idx) cases) into the cases ``idx``."""
        for f in STATE_FIELDS:
            getattr(self, f)[idx] = getattr(other, f)

    @classmethod
    def concat(cls, parts: list) -> "State":
        return cls(*(np.concatenate([getattr(p, f) for p in parts]) for f in STATE_FIELDS))


STATE_FIELDS = ("tp", "removed", "t", "last_f", "peak_force", "peak_rate", "last_force", "phase")


def runout_profile(batch: Batch, K: int) -> np.ndarray:
    """ΔR_k (cases, K): the part's initial excess radius over its mean at each position."""
    phi = 2.0 * np.pi * np.arange(K) / K
    return batch.runout[:, None] * np.cos(phi)[None, :]


def allowance_left(batch: Batch, st: State) -> np.ndarray:
    """The mean radial allowance still on the part (mm)."""
    return batch.allowance - st.removed.mean(axis=1)


def gauge_reading(batch: Batch, st: State) -> np.ndarray:
    """What the in-process gauge reports as the remaining allowance."""
    return allowance_left(batch, st) + batch.gauge


def advance(batch: Batch, st: State, feed_mm_min: np.ndarray, n_w: float, dR: np.ndarray, steps: int,
            trace=None) -> None:
    """Grind the next ``steps`` angular positions of every part (K: one revolution) at the
    programmed feed (mm/min, per case), in place.

    The programmed infeed grows by feed / n_w per revolution, each position taking 1/K of it;
    the wheel starts the allowance above the part's mean radius plus the run-out, so it
    touches the highest point first.  Each part keeps its own angular phase (a gauge switch
    falls mid-revolution)."""
    n, K = st.removed.shape
    f_rev = feed_mm_min / n_w  # mm per revolution
    j = np.arange(steps)
    pos = (st.phase[:, None] + j[None, :]) % K
    rows = np.arange(n)[:, None]
    tp_k = st.tp[:, None] + f_rev[:, None] * (j[None, :] + 1.0) / K
    rhs = tp_k - (batch.runout[:, None] - dR[rows, pos]) - st.removed[rows, pos]
    f, force = removal_step(rhs, batch.a1[:, None], batch.a2[:, None], batch.gamma[:, None])
    st.removed[rows, pos] += f
    st.tp = st.tp + f_rev * steps / K
    st.phase = (st.phase + steps) % K
    st.t = st.t + 60.0 / n_w * steps / K
    st.last_f = f.max(axis=1)
    st.peak_force = np.maximum(st.peak_force, force.max(axis=1))
    st.peak_rate = np.maximum(st.peak_rate, f.max(axis=1) * n_w)
    st.last_force = force.max(axis=1)
    if trace is not None:
        trace.append((st.t.copy(), feed_mm_min.copy(), (f.sum(axis=1) / steps * n_w), force.max(axis=1),
                      allowance_left(batch, st), st.removed.max(axis=1) - st.removed.min(axis=1)))


def gauge_steps(twin) -> int:
    """Angular positions between two gauge readings (the gauge is read this often)."""
    K = int(twin["system.positions"])
    return max(1, int(round(K / twin["gauge.reads_per_rev"])))


