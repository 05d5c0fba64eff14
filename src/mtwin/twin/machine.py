"""The machine part of the twin file: controller, feed axes, spindle, machine times.

Each parameter is declared once, as a dataclass field whose metadata carries its
unit, its check and one line of documentation.  Parsing, validation, the
embedded default machine (``mtwin config show``) and ``docs/configuration.md``
all come from these declarations, so they cannot disagree.

Default values describe a three-axis vertical machining centre like the one in the
reference (11 kW, 8,000 rpm spindle, Fanuc-style control).  Tags as in
``docs/physics.md``: [S] from a cited source, [E] an estimate inside the sourced range.
"""
from __future__ import annotations

import os

import dataclasses
import math
from dataclasses import dataclass, field, fields, replace

from ..errors import ConfigError
from ..params import P
from ..params import check_value as _check
from ..tomlwrite import toml_string

STYLES = ("fanuc", "linuxcnc", "grbl")
BEFORE_SHAPES = ("bell", "linear")
AFTER_FILTERS = ("linear", "bell", "exponential", "none")
AXES = ("x", "y", "z")


@dataclass(frozen=True)
class Controller:
    style: str = P("fanuc", "str", "planner style: fanuc | linuxcnc | grbl", "choice", STYLES)
    servo_period: float = P(0.001, "s", "interpolation and servo period [S: 1 ms, LinuxCNC; Fanuc ~1 ms]", lo=1e-6)
    lookahead: int = P(40, "int", "look-ahead window in blocks [S: Fanuc AI contour up to 40]")
    min_block_time: float = P(0.001, "s", "shortest time a block may take (block processing rate) [E]", "nonneg",
                                hi=1.0)
    max_path_velocity: float = P(0.0, "mm/min", "path (vector) velocity limit for all moves, 0 = axis limits only", "nonneg")
    max_cutting_feed: float = P(0.0, "mm/min", "highest F the control runs and mtwin writes, 0 = the slowest "
                                "axis' max_velocity", "nonneg")
    max_path_acceleration: float = P(0.0, "mm/s^2", "path acceleration limit, 0 = axis limits only", "nonneg")
    before_shape: str = P("bell", "str", "acc/dec before interpolation: bell (jerk-limited) | linear", "choice", BEFORE_SHAPES)
    bell_time: float = P(0.032, "s", "bell time constant tb (jerk = a/tb) [S: 16-64 ms]", "nonneg", hi=1.0)
    after_filter: str = P("linear", "str", "per-axis acc/dec after interpolation: linear | bell | exponential | none",
                          "choice", AFTER_FILTERS)
    after_time: float = P(0.008, "s", "after-interpolation time constant T1 [S: 8-64 ms]", "nonneg",
                          hi=1.0)
    corner_velocity: float = P(400.0, "mm/min",
                               "fanuc: allowable velocity change per axis at a corner [E]")
    # a control may refuse to blend a reversal at any speed: the NIST Hurco VMX24 loses a near
    # constant ~0.09 s at each of its plates' 150-170 degree zig-zag turns from F508 to F1016
    # mm/min, as a full stop does, where an allowable velocity change carries speed through
    stop_angle: float = P(0.0, "deg", "feed corners that turn by more than this are exact stops (as G9 on the "
                          "block), 0 = none [E: 120 on a Hurco VMX24, docs/validation.md]", "nonneg", hi=180.0)
    junction_deviation: float = P(0.01, "mm", "grbl: junction deviation [S: Grbl default 0.01 mm]")
    exact_stop_rapids: bool = P(True, "bool", "decelerate to a stop at the end of every rapid (in-position check)", "bool")
    in_position: float = P(0.02, "mm", "in-position width: at an exact stop the next block waits until every "
                           "axis is this close to the command, 0 = no check [E: 0.01-0.05 mm]", "nonneg",
                           hi=10.0)
    # a control may check in-position after a cutting-feed block more narrowly than after a rapid
    # (Fanuc's in-position width in cutting feed, parameter 1827, apart from 1826): the NIST Hurco
    # VMX24's straight feed lines a rapid follows run 50-75 ms longer than the twin's without it,
    # on every plate, where the lines a feed move follows run alike, and its rapids' ends show no
    # wait (docs/validation.md).  Modelled as a fixed time, not a width: the axes settle meanwhile
    feed_rapid_wait: float = P(0.0, "s", "the control stops at the end of a cutting-feed block that a rapid follows "
                               "(pauses between them skipped; a drilling cycle's hole bottom too) and stands this "
                               "long before the rapid starts: its in-position check for cutting feed, as a fixed "
                               "time, 0 = none [E: 42 ms fitted on a Hurco VMX24, docs/validation.md]", "nonneg",
                               hi=1.0)
    # and where a rapid ends and a cutting move follows (the approach before a plunge): the NIST
    # Hurco's approaches run 40-55 ms longer than the twin's without it, on every plate, where its
    # rapids that another rapid follows show no wait (docs/validation.md)
    rapid_feed_wait: float = P(0.0, "s", "the control stands this long at the end of a rapid that a cutting-feed "
                               "block follows (pauses between them skipped) before the feed move starts: its "
                               "in-position check before cutting, as a fixed time, 0 = none [E: 46 ms fitted on a "
                               "Hurco VMX24, docs/validation.md]", "nonneg", hi=1.0)
    # Fanuc sets the acc/dec of rapids apart from that of cutting feed (the rapid and the cutting
    # time constants are separate parameters, 1620 and 1622 on a 0i/30i): a control accelerates its
    # rapids harder than it lets its feed moves (which carry the contour's accuracy)
    rapid_acceleration: float = P(0.0, "mm/s^2", "acceleration of each axis on rapids, 0 = its max_acceleration "
                                  "[S: separate rapid and cutting acc/dec, Fanuc parameters 1620/1622]", "nonneg")
    arc_acceleration: float = P(0.0, "mm/s^2", "normal-acceleration limit on feed arcs (v^2/r), in place of the "
                                "axes' share (sqrt(0.75) of their acceleration) and set apart from it as Fanuc's "
                                "parameter 1735 is, 0 = the axes' share [E: circles of 0.35-6.5 mm radius on a Hurco "
                                "VMX24 run at ~370-400 mm/s^2]", "nonneg")
    # a control that limits each axis' jerk holds a circle's speed where v³/r² (the jerk of the
    # axes' sinusoids) reaches it, a bound that bites on small radii first: the NIST Hurco's
    # 0.35-0.42-mm helices run at 10-12 m/s³ (354-366 mm/s²), its 6.5-mm corners at ~500 mm/s²
    # and 4-5 m/s³ (docs/effects.md: why its profile does not use it)
    arc_jerk: float = P(0.0, "mm/s^3", "normal-jerk limit on feed arcs: v^3/r^2, the amplitude of each axis' jerk "
                        "on a circle, 0 = none [S: the path speed held where a contour's curvature gives the axes "
                        "more jerk than their limit: Heidenhain MP_axPathJerk, ISG kernel P-CHAN-00110] "
                        "[E: 10-12 m/s^3 on a Hurco VMX24's 0.35-0.42-mm helices; not in its profile: docs/effects.md]",
                        "nonneg", hi=1e9)
    # a centre rounded to 0.0001 in leaves the end point off by one such increment (2.54 um): the
    # Hurco VMX24's logs show these arcs run slower than true circles, while arcs off by up to
    # 2.2 um (end point and centre both rounded) run as circles (docs/validation.md)
    spiral_min: float = P(0.0023, "mm", "an arc whose end radius differs from its start radius by more than this is "
                          "a spiral (spiral_acceleration, spiral_block_time) [E: between 2.2 and 2.54 um on a Hurco "
                          "VMX24]", "positive", hi=1.0)
    # a CAM that rounds an arc's centre leaves its end point off the circle (radius mismatch, e.g.
    # 0.0001 in): the control runs it as a spiral, outside its circular interpolation, and the
    # NIST Hurco VMX24 does so at a lower normal acceleration than the same circle drawn true
    spiral_acceleration: float = P(0.0, "mm/s^2", "normal-acceleration limit on feed arcs whose end radius differs "
                                   "from their start radius by more than spiral_min (a spiral: a rounded centre), 0 = as "
                                   "circles [E: a Hurco VMX24 runs them at ~350-370 mm/s^2 (with spiral_jerk), true "
                                   "circles at ~400]", "nonneg")
    # below that limit the same spirals still run 3-4 % under F where true circles reach it: on
    # the NIST plate 12's 0.35-0.42 mm helices at F508, 4.8-5.6 ms more per half circle
    spiral_block_time: float = P(0.0, "s", "time the control spends on each spiral block beyond what its path takes "
                                 "(the block runs at L/(L/v + t): t whole where it reaches its speed), 0 = none "
                                 "[E: 0 on a Hurco VMX24, whose spirals' extra time grows with v²/r: spiral_jerk]",
                                 "nonneg", hi=0.05)
    # and the extra grows with the normal acceleration v²/r, not the speed alone: ~5 ms a half
    # circle at ~190 mm/s² (plate 12's helices), twice that fitted as a constant on plates 13 and
    # 14, 5-8 ms on plate 12's 1.7-mm spirals at 23 mm/s (309 mm/s², where a time growing as v²
    # would give 38): as if the control ramped the normal acceleration anew at every spiral
    # block, at a jerk
    spiral_jerk: float = P(0.0, "mm/s^3", "each spiral block takes (v²/r)/spiral_jerk longer than its path takes (the "
                           "control ramps the normal acceleration anew at every spiral block, at this jerk), on top of "
                           "spiral_block_time, 0 = none [E: 40-50 m/s^3 on a Hurco VMX24, docs/validation.md]", "nonneg",
                           hi=1e9)
    feed_override: float = P(100.0, "", "feed override in % in force for the whole run (a run's, not the "
                             "machine's: what effects.feed-override fits to a log that did not record it)",
                             lo=1.0, hi=1000.0)
    rapid_override: float = P(100.0, "", "rapid override in % in force for the whole run (as feed_override)",
                              lo=1.0, hi=100.0)


@dataclass(frozen=True)
class Friction:
    coulomb_pos: float = P(150.0, "N", "Coulomb friction moving +  [E: 50-300 N]", "nonneg")
    coulomb_neg: float = P(150.0, "N", "Coulomb friction moving -", "nonneg")
    static_pos: float = P(195.0, "N", "static (breakaway) friction moving +  [E: 1.1-1.5 x Coulomb]", "nonneg")
    static_neg: float = P(195.0, "N", "static (breakaway) friction moving -", "nonneg")
    stribeck_velocity: float = P(1.0, "mm/s", "Stribeck velocity vs [E: 0.1-5 mm/s]")
    viscous: float = P(500.0, "N*s/m", "viscous friction B [E: 100-2000 N*s/m]", "nonneg")


@dataclass(frozen=True)
class Servo:
    kpp: float = P(40.0, "1/s", "position loop gain Kv [S: 30-50 1/s general VMCs; example 40]")
    velocity_bandwidth: float = P(240.0, "rad/s", "velocity loop proportional bandwidth (Kvp = M*w) [S: example 240 rad/s]")
    velocity_integral: float = P(60.0, "rad/s", "velocity loop integral corner frequency Kvi [S: example 60 rad/s]", "nonneg")
    # a control of today runs its position loop with velocity feed-forward (Fanuc's "feed-forward
    # coefficient", Siemens DSC/FFW, Heidenhain's velocity feedforward); without it the lag
    # v/Kv (0.17 mm at 400 mm/min, Kv 40) would cut every corner (docs/motion.md, "accuracy")
    feedforward: float = P(0.9, "", "velocity feed-forward ratio alpha, 0..1 [E: feed-forward as on contouring "
                           "controls, Koren & Lo 1992, Erkorkmaz & Altintas 2001; 0.9 chosen, not a cited value]", "unit_interval")
    s_pp: float = P(1.0, "", "scale factor on the position gain (reference S_pp)", hi=100.0)
    s_vp: float = P(1.0, "", "scale factor on the velocity proportional gain (S_vp)", hi=100.0)
    s_vi: float = P(1.0, "", "scale factor on the velocity integral gain (S_vi)", "nonneg", hi=100.0)


@dataclass(frozen=True)
class Axis:
    max_velocity: float = P(36000.0, "mm/min", "rapid / maximum axis velocity [S: 30-40 m/min]")
    max_acceleration: float = P(3000.0, "mm/s^2", "maximum axis acceleration [E: 1-5 m/s^2]")
    min_travel: float = P(-400.0, "mm", "lower travel limit, machine coordinates", "finite")
    max_travel: float = P(400.0, "mm", "upper travel limit, machine coordinates", "finite")
    mass: float = P(300.0, "kg", "moving mass carried by the axis [S: table 100-500 kg]")
    rotor_inertia: float = P(0.0012, "kg*m^2", "motor rotor + coupling + screw inertia [E]", "nonneg")
    screw_lead: float = P(10.0, "mm", "ball-screw lead [S: 10-20 mm]")
    efficiency: float = P(0.9, "", "ball-screw efficiency eta [E: 0.9]", "unit_interval_open")
    torque_constant: float = P(1.0, "N*m/A", "motor torque constant Kt [S: ~1 N*m/A]")
    max_torque: float = P(20.0, "N*m", "motor torque limit [E]")
    gravity: bool = P(False, "bool", "vertical axis carrying its mass against gravity (no counterbalance)", "bool")
    friction: Friction = field(default_factory=Friction)
    servo: Servo = field(default_factory=Servo)

    # Derived quantities used by the kernels (SI-ish: kg, N, mm).
    @property
    def equivalent_mass(self) -> float:
        """Mass seen at the table, kg: M + J*(2*pi/l)^2."""
        lead_m = self.screw_lead * 1e-3
        return self.mass + self.rotor_inertia * (2 * math.pi / lead_m) ** 2

    @property
    def force_per_torque(self) -> float:
        """Axial force per motor torque, N/(N*m): 2*pi*eta/l."""
        return 2 * math.pi * self.efficiency / (self.screw_lead * 1e-3)

    @property
    def drive_acceleration(self) -> float:
        """The most the motor's torque limit gives the equivalent mass, mm/s^2."""
        return self.max_torque * self.force_per_torque / self.equivalent_mass * 1e3


@dataclass(frozen=True)
class Spindle:
    max_speed: float = P(8000.0, "rpm", "maximum spindle speed [S: reference VMC 8,000 rpm]")
    rated_power: float = P(11000.0, "W", "rated spindle power [S: reference VMC 11 kW]")
    base_speed: float = P(1500.0, "rpm", "end of the constant-torque range: torque limit = rated power / "
                          "(2*pi*max(n, base)/60) [E]")
    acceleration: float = P(4000.0, "rpm/s", "run-up / braking rate [E]")
    # a spindle drive accelerates at its torque limit up to its base speed and at its power limit
    # above it, where the torque falls as 1/n: the rate falls as power_speed/n, so the time to
    # speed grows with n^2 (a 12,000-rpm start takes far longer than 4/3 of a 9,000-rpm one)
    runup_power_speed: float = P(0.0, "rpm", "above this speed the run-up and braking rate falls as "
                                 "runup_power_speed/n (the drive's constant-power range), 0 = a constant rate",
                                 "nonneg")
    # a control may confirm a stop later than it confirms a speed (the Hurco's waits from M5 are
    # longer than its waits after M3 at the same speed): a braking rate of its own
    braking: float = P(0.0, "rpm/s", "braking rate the waits after M5 or a lower S follow, 0 = acceleration "
                       "(above runup_power_speed it falls as 1/n too)", "nonneg")
    wait_for_speed: bool = P(True, "bool", "feed moves wait until the spindle is at speed after M3/M4/S", "bool")
    # a control may move the axes while the spindle brakes or runs up: the NIST Hurco VMX24 starts
    # its G28 retract at once after M5, and rapids to X/Y on the block that starts the spindle,
    # standing at the next block (the Z approach) for the rest of the run-up (both logged)
    wait_for_stop: bool = P(True, "bool", "moves after M5 wait until the spindle has stopped (false: they run while "
                            "it brakes, and the next tool change, spindle start or the program's end waits for what "
                            "is left)", "bool")
    runup_overlap: bool = P(False, "bool", "a rapid on the block that starts the spindle moves while it runs up, and "
                            "the next block waits for what is left (false: the block waits before it moves)", "bool")


@dataclass(frozen=True)
class Timing:
    tool_change: float = P(4.0, "s", "tool change, chip to chip [S: 1.5-4 s]", "nonneg")
    first_tool_change_extra: float = P(0.0, "s", "extra time of a program's first tool change (the magazine "
                                       "comes from its home position) [E: Hurco VMX24 about 2 s]", "nonneg")


@dataclass(frozen=True)
class Cost:
    """Production-cost rates for ``mtwin optimize --objective cost`` (Gilbert's cost per part,
    docs/physics.md section 5) and the optimiser's default load limit."""

    machine_rate: float = P(50.0, "1/h", "machine depreciation and overhead per hour, currency units [E: C_o 60-150 $/h "
                            "with labour]", "nonneg")
    labour_rate: float = P(30.0, "1/h", "operator per hour, currency units [E]", "nonneg")
    tool_price: float = P(40.0, "1", "price of a tool (or a set of edges), currency units [E: carbide end mill 30-150 $]",
                          "nonneg")
    tool_replace_time: float = P(120.0, "s", "time to replace a worn tool and set its offset [E: 1-5 min]", "nonneg")
    taylor_n: float = P(0.35, "1", "Taylor exponent n in V*T^n = C [E: aluminium 0.3-0.4, carbide in steel 0.25]",
                        hi=1.0)
    taylor_c: float = P(1200.0, "m/min", "Taylor constant C (cutting speed for one minute of life) [E: aluminium "
                        "1100-1500, carbide in mild steel 300]")
    force_per_diameter: float = P(10.0, "N/mm", "default cutting-load limit per mm of tool diameter, when no "
                                  "--force-limit is given [E: the reference's 60 N for a 6 mm end mill]")


_AXIS_DEFAULTS = {
    "x": Axis(),
    "y": Axis(mass=500.0, min_travel=-250.0, max_travel=250.0),
    "z": Axis(max_velocity=30000.0, max_acceleration=2500.0, min_travel=-400.0, max_travel=100.0, mass=200.0),
}


@dataclass(frozen=True)
class Machine:
    name: str = "mtwin default VMC: 3 axes, 11 kW / 8,000 rpm spindle, Fanuc-style control"
    controller: Controller = field(default_factory=Controller)
    x: Axis = field(default_factory=lambda: _AXIS_DEFAULTS["x"])
    y: Axis = field(default_factory=lambda: _AXIS_DEFAULTS["y"])
    z: Axis = field(default_factory=lambda: _AXIS_DEFAULTS["z"])
    spindle: Spindle = field(default_factory=Spindle)
    timing: Timing = field(default_factory=Timing)
    cost: Cost = field(default_factory=Cost)
    # The embedded default machine is nobody's machine: a move beyond its travel is a warning.
    # A twin file that names its machine or gives its travel describes a real machine, whose
    # limits are hard, as on its control.
    hard_travel_limits: bool = False

    @property
    def max_cutting_feed(self) -> float:
        """The highest feed (mm/min) a rewritten program may ask for on this machine."""
        c = self.controller.max_cutting_feed
        return c if c > 0 else min(ax.max_velocity for ax in self.axes)

    @property
    def axes(self) -> tuple[Axis, Axis, Axis]:
        return (self.x, self.y, self.z)

    def describe(self) -> str:
        """The machine in a line, from its values: axes, spindle, control."""
        sp = self.spindle
        travel = "  ".join(f"{a.upper()} {ax.min_travel:g}…{ax.max_travel:g}" for a, ax in zip("xyz", self.axes))
        rapid = min(ax.max_velocity for ax in self.axes) / 1000.0
        return (f"3 axes ({travel} mm, rapids {rapid:g} m/min), {sp.rated_power / 1000:g} kW / {sp.max_speed:,.0f} rpm "
                f"spindle, {self.controller.style}-style control")


MACHINE_SECTIONS = ("machine", "controller", "axes", "spindle", "timing", "cost")


def _parse_into(obj, table: dict, prefix: str, where: str):
    if not isinstance(table, dict):
        raise ConfigError(f"{where}: [{prefix}] must be a table")
    known = {f.name: f for f in fields(obj)}
    changes = {}
    for key, value in table.items():
        f = known.get(key)
        full = f"{prefix}.{key}"
        if f is None:
            raise ConfigError(f"{where}: unknown key {full} (known: {', '.join(known)})")
        if dataclasses.is_dataclass(f.default_factory() if f.default_factory is not dataclasses.MISSING else None):
            changes[key] = _parse_into(getattr(obj, key), value, full, where)
        else:
            try:
                changes[key] = _check(value, f.metadata, full)
            except ConfigError as exc:
                raise ConfigError(f"{where}: {exc}") from None
    return replace(obj, **changes)


def machine_from_dict(raw: dict, where: str = "twin file") -> Machine:
    """Build a Machine from the machine sections of a parsed twin file (other sections ignored)."""
    m = Machine()
    changes: dict = {}
    if "machine" in raw:
        body = raw["machine"]
        if not isinstance(body, dict) or set(body) - {"name"}:
            raise ConfigError(f"{where}: [machine] takes only 'name'")
        if "name" in body:
            changes["name"] = str(body["name"])
    for sec in ("controller", "spindle", "timing", "cost"):
        if sec in raw:
            changes[sec] = _parse_into(getattr(m, sec), raw[sec], sec, where)
    axes = raw.get("axes", {})
    if not isinstance(axes, dict):
        raise ConfigError(f"{where}: [axes] must be a table of [axes.x], [axes.y], [axes.z]")
    for name, body in axes.items():
        if name not in AXES:
            raise ConfigError(f"{where}: unknown axis axes.{name} (x, y, z)")
        changes[name] = _parse_into(getattr(m, name), body, f"axes.{name}", where)
    # a file that names its machine or gives travel describes a real one: hard limits; one of
    # effects, offsets and a journal alone (calibrate's output from the default machine) runs
    # on the default's travel, still nobody's
    hard = "name" in changes or any(isinstance(b, dict) and ({"min_travel", "max_travel"} & set(b))
                                    for b in axes.values())
    m = replace(m, hard_travel_limits=hard, **changes)
    if "name" not in changes:
        # a file that names no machine is described by its own values, never by the default's
        m = replace(m, name=f"{os.path.basename(str(where))}: {m.describe()}")
    validate_machine(m, where)
    return m


def validate_machine(m: Machine, where: str = "twin file") -> None:
    """Checks that involve more than one parameter."""
    c = m.controller
    if c.servo_period > 0.01:
        raise ConfigError(f"{where}: controller.servo_period: {c.servo_period} s is longer than 10 ms")
    for name, ax in zip(AXES, m.axes):
        if ax.min_travel >= ax.max_travel:
            raise ConfigError(f"{where}: axes.{name}: min_travel must be below max_travel")
        s = ax.servo
        # The discrete velocity loop is stable for w*dt < 2; keep a wide margin.
        if s.velocity_bandwidth * s.s_vp * c.servo_period > 1.0:
            raise ConfigError(f"{where}: axes.{name}.servo.velocity_bandwidth: {s.velocity_bandwidth * s.s_vp:g} rad/s "
                              f"is too high for a {c.servo_period * 1e3:g} ms servo period (limit {1 / c.servo_period:g})")
        if s.kpp * s.s_pp >= s.velocity_bandwidth * s.s_vp:
            raise ConfigError(f"{where}: axes.{name}.servo.kpp must be below the velocity loop bandwidth")
        if ax.max_acceleration > ax.drive_acceleration:
            raise ConfigError(f"{where}: axes.{name}.max_torque: {ax.max_torque} N*m cannot give "
                              f"{ax.max_acceleration} mm/s^2 to {ax.equivalent_mass:.0f} kg (equivalent mass)")
        if c.rapid_acceleration > ax.drive_acceleration:
            raise ConfigError(f"{where}: controller.rapid_acceleration: {c.rapid_acceleration} mm/s^2 is more than "
                              f"axes.{name}.max_torque ({ax.max_torque} N*m) can give {ax.equivalent_mass:.0f} kg")


def _fmt(value, unit) -> str:
    if unit == "bool":
        return "true" if value else "false"
    if unit == "str":
        return toml_string(str(value))
    if unit == "int":
        return str(int(value))
    return repr(float(value)) if not float(value).is_integer() else f"{float(value):.1f}"


def _table_lines(obj, header: str) -> list[str]:
    lines = [f"[{header}]"]
    nested = []
    width = max(len(f.name) for f in fields(obj))
    for f in fields(obj):
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(value):
            nested.append((f.name, value))
            continue
        meta = f.metadata
        unit = meta["unit"] if meta["unit"] not in ("bool", "str", "int", "") else ""
        left = f"{f.name.ljust(width)} = {_fmt(value, meta['unit'])}"
        lines.append(f"{left.ljust(width + 14)} # {('[' + unit + '] ') if unit else ''}{meta['doc']}")
    for name, value in nested:
        lines.append("")
        lines += _table_lines(value, f"{header}.{name}")
    return lines


def machine_toml(m: Machine | None = None, front: dict | None = None) -> str:
    """The twin file as a commented TOML document (what ``mtwin config show`` prints).

    ``front``: the validated interpreter sections (``config.load_twin_file``)."""
    m = m or Machine()
    front = front or {}
    out = [
        "# mtwin twin file: the machine the program runs on.",
        "# Numbers are in the unit in brackets; a string with a unit is converted (\"30 m/min\").",
        "# Tags: [S] value from a source cited in docs/physics.md, [E] estimate within the sourced range.",
        "",
        "[machine]",
        f"name = {toml_string(m.name)}",
        "",
        "[interpreter]",
        f'dialect = {toml_string(front.get("dialect", "auto"))}          # auto (.ngc -> linuxcnc, else fanuc) | fanuc | linuxcnc',
        f'block_delete = {"true" if front.get("skip_block_delete") else "false"}         # true: skip lines starting with /',
    ]
    for key in ("home_g28", "home_g30"):
        v = front.get(key, (0.0, 0.0, 0.0))
        out.append(f"{key} = [{', '.join(repr(float(x)) for x in v)}]   # machine coordinates, mm")
    out += ["", "[work_offsets]                # machine coordinates of each work zero, mm (missing = 0)"]
    offsets = front.get("work_offsets", {})
    if offsets:
        out += [f"{k} = [{', '.join(repr(float(x)) for x in v)}]" for k, v in offsets.items()]
    else:
        out.append("# G54 = [-400.0, -200.0, -350.0]")
    out += ["", "[tool_lengths]                # tool (H) number -> length offset, mm (absent: all 0)"]
    tools = front.get("tool_lengths", {})
    if tools:
        out += [f"{k} = {float(v)!r}" for k, v in sorted(tools.items())]
    else:
        out.append("# 1 = 95.2")
    out.append("")
    out += _table_lines(m.controller, "controller") + [""]
    for name, ax in zip(AXES, m.axes):
        out += _table_lines(ax, f"axes.{name}") + [""]
    out += _table_lines(m.spindle, "spindle") + [""]
    out += _table_lines(m.timing, "timing") + [""]
    out += _table_lines(m.cost, "cost")
    out += ["", "# Cutting: tools, material and stock (docs/cutting.md). Without [tools.*] every tool is a",
            "# 6 mm two-flute carbide flat end mill; without [cutting] material, al6061 (reference Kt, Ke).",
            "# [cutting]",
            '# material = "al6061"          # a catalogue name (mtwin materials: 4140, 304, mdf, ...) or a',
            "#                              # [materials.*] name; named, optimize takes its limits from physics",
            "# stock = [0, 0, -20, 60, 50, 0]   # xmin, ymin, zmin, xmax, ymax, zmax, mm (else the program's",
            "#                                  # stock comment, else feed moves' extent, top Z0)",
            "# [tools.1]",
            '# type = "flat"                # flat | ball | bull | vee',
            "# diameter = 6.0",
            "# flutes = 2",
            '# material = "carbide"         # carbide | hss (docs/catalogue.md)',
            "# stickout = 24.0              # mm out of the holder (0: 4 x diameter)",
            "# force_limit = 0.0            # N optimize holds this tool to (0: none given)"]
    return "\n".join(out) + "\n"


def param_names(m: Machine | None = None) -> list[str]:
    """Every numeric parameter of a machine by dotted name ("axes.x.servo.kpp", ...)."""
    m = m or Machine()
    out = []

    def walk(obj, prefix):
        for f in fields(obj):
            v = getattr(obj, f.name)
            if dataclasses.is_dataclass(v):
                walk(v, f"{prefix}{f.name}.")
            elif isinstance(v, (int, float)) and not isinstance(v, bool):
                out.append(prefix + f.name)

    for sec in ("controller", "spindle", "timing", "cost"):
        walk(getattr(m, sec), sec + ".")
    for a in AXES:
        walk(getattr(m, a), f"axes.{a}.")
    return out


def get_param(m: Machine, name: str):
    obj = m
    for part in _path(name):
        obj = getattr(obj, part)
    return obj


def _path(name: str) -> list[str]:
    parts = name.split(".")
    if parts[0] == "axes" and len(parts) > 1:
        parts = parts[1:]
    return parts


def param_unit(name: str) -> str:
    """The unit of a machine parameter by its dotted name (``axes.x.max_acceleration``: mm/s^2;
    '' for a dimensionless one); a ConfigError for a name the machine does not have."""
    return _walk(Machine(), name)[2].metadata.get("unit", "")


def _walk(m: Machine, name: str):
    """(the tables from ``m`` down to the one holding parameter ``name``, the dotted path's
    parts, the parameter's field); a ConfigError for a name the machine does not have."""
    parts = _path(name)
    objs = [m]
    for part in parts[:-1]:
        if not hasattr(objs[-1], part) or not dataclasses.is_dataclass(getattr(objs[-1], part)):
            raise ConfigError(f"unknown machine parameter {name!r}")
        objs.append(getattr(objs[-1], part))
    known = {f.name: f for f in fields(objs[-1])}
    if parts[-1] not in known or dataclasses.is_dataclass(getattr(objs[-1], parts[-1])):
        raise ConfigError(f"unknown machine parameter {name!r}")
    return objs, parts, known[parts[-1]]


def with_params(m: Machine, values: dict) -> Machine:
    """A copy of ``m`` with parameters set by dotted name, validated like the twin file."""
    for name, value in values.items():
        objs, parts, f = _walk(m, name)
        new = replace(objs[-1], **{parts[-1]: _check(value, f.metadata, name)})
        for obj, part in zip(reversed(objs[:-1]), reversed(parts[:-1])):
            new = replace(obj, **{part: new})
        m = new
    validate_machine(m, "parameters")
    return m
