"""Timing effects: what a real control spends time on that the base planner does not know.

They act before planning (``stage = "plan"``): each changes a controller or timing parameter
of the machine the program is planned on, so the whole twin — plan, drives, trace — runs on
it.  Each parameter's default leaves the twin as it is (0: the twin file's value), so an
effect added without values changes nothing and a calibration starts from the twin."""
from __future__ import annotations

from dataclasses import replace

from ..errors import ConfigError
from ..params import Param
from .base import Effect

_TIME = ("feed", "spindle_speed")  # what a timing change shows in: when things happen


def jerk_of(normal_time: float) -> float:
    """mm/s³ of a spiral's ``normal_time`` in s³/m (the time per m/s² of v²/r), and back — the map
    is its own inverse: 1000/x, 0 (none) for 0."""
    return 1000.0 / normal_time if normal_time > 0 else 0.0


def _controller_set(m, name: str, value: float):
    """The machine with one controller parameter set; 0 (the effect's default) leaves it."""
    return replace(m, controller=replace(m.controller, **{name: value})) if value > 0 else m


class ToolChangeTime(Effect):
    name = "toolchange-time"
    description = "a tool change takes longer (or shorter) than the twin file says, the first of a program longer still"
    stage = "plan"
    params = (Param("extra", "s", 0.0, -30.0, 120.0, "time added to every tool change"),
              Param("first_extra", "s", 0.0, 0.0, 120.0, "time added to a program's first tool change"))
    signals = _TIME

    def machine(self, m, p):
        t = m.timing
        return replace(m, timing=replace(t, tool_change=max(0.0, t.tool_change + p["extra"]),
                                         first_tool_change_extra=t.first_tool_change_extra + p["first_extra"]))


class SpindleRunup(Effect):
    name = "spindle-runup"
    description = "the control waits until the spindle is at speed after a start, a speed change and a stop"
    stage = "plan"
    params = (Param("acceleration", "rpm/s", 0.0, 0.0, 100000.0,
                    "run-up rate the waits follow (and braking's, unless braking is set), 0 = the twin file's"),
              Param("power_speed", "rpm", 0.0, 0.0, 100000.0,
                    "above this speed the rate falls as power_speed/n (the drive's power limit), 0 = the twin "
                    "file's"),
              Param("braking", "rpm/s", 0.0, 0.0, 100000.0,
                    "braking rate the waits after a stop follow, 0 = the twin file's"))
    signals = _TIME

    def machine(self, m, p):
        sp = replace(m.spindle, wait_for_speed=True)
        if p["acceleration"] > 0:
            sp = replace(sp, acceleration=p["acceleration"])
        if p.get("power_speed", 0.0) > 0:
            sp = replace(sp, runup_power_speed=p["power_speed"])
        if p.get("braking", 0.0) > 0:
            sp = replace(sp, braking=p["braking"])
        return replace(m, spindle=sp)


class BlockTime(Effect):
    name = "block-time"
    description = "every block takes at least a minimum time (the control's block processing rate)"
    stage = "plan"
    params = (Param("min_time", "s", 0.0, 0.0, 1.0, "shortest time a block may take, 0 = the twin file's"),)
    signals = ("feed",)

    def machine(self, m, p):
        c = m.controller
        return replace(m, controller=replace(c, min_block_time=max(c.min_block_time, p["min_time"])))


class CornerSlowdown(Effect):
    name = "corner-slowdown"
    description = "the control slows down more (or less) at corners: its allowable velocity change per axis"
    stage = "plan"
    params = (Param("corner_velocity", "mm/min", 0.0, 0.0, 100000.0,
                    "allowable velocity change per axis at a corner, 0 = the twin file's", ceiling=True),)
    signals = ("feed",)

    def machine(self, m, p):
        return _controller_set(m, "corner_velocity", p["corner_velocity"])


class ArcAcceleration(Effect):
    name = "arc-acceleration"
    description = ("the control has its own normal-acceleration limit v²/r on feed arcs, in place of the axes' "
                   "share of it (small arcs run at it), and may hold small circles lower still by a jerk limit "
                   "v³/r²")
    stage = "plan"
    params = (Param("acceleration", "mm/s^2", 0.0, 0.0, 100000.0,
                    "normal-acceleration limit on arcs, 0 = the twin file's (controller.arc_acceleration)",
                    ceiling=True),
              Param("jerk", "mm/s^3", 0.0, 0.0, 1e6, "normal-jerk limit on arcs (v³/r², each axis' jerk on a circle: "
                    "binds on small radii first), 0 = the twin file's (controller.arc_jerk; none unless set)",
                    ceiling=True))
    signals = ("feed",)
    # the jerk limit is fitted where asked (fit=acceleration+jerk): it takes arcs on both sides of
    # the radius where the two limits cross (a³/J²) run at them to tell the two apart, and where
    # only small ones do, the v²/r limit is left to the least value the logs allow — on the NIST
    # Hurco, a fold without plate 13 set it anywhere from 356 to 481 mm/s² and predicted plate
    # 13's cycle 0.5-1.3 % long (CHANGELOG): not in its profile
    fitted = ("acceleration",)

    def machine(self, m, p):
        m = _controller_set(m, "arc_jerk", p.get("jerk", 0.0))
        return _controller_set(m, "arc_acceleration", p["acceleration"])


class SpiralAcceleration(Effect):
    name = "spiral-acceleration"
    description = ("arcs whose end point is off the programmed circle (a rounded centre: the control runs a "
                   "spiral) take a lower normal acceleration v²/r than true circles, and longer per block, the "
                   "more the higher v²/r")
    stage = "plan"
    params = (Param("acceleration", "mm/s^2", 0.0, 0.0, 100000.0,
                    "normal-acceleration limit on spiral arcs, 0 = as circles", ceiling=True),
              Param("block_time", "s", 0.0, 0.0, 0.05,
                    "time the control spends on each spiral block beyond its path's, 0 = none"),
              Param("normal_time", "s^3/m", 0.0, 0.0, 1.0,
                    "time each spiral block takes beyond its path per m/s² of its v²/r: the inverse of the jerk at "
                    "which the control ramps the normal acceleration anew at every spiral block (0.025 = 25 ms per "
                    "m/s², 40 m/s³), 0 = the twin file's (controller.spiral_jerk; none unless set)"))
    signals = ("feed",)
    # the time a spiral block takes beyond its path grows with v²/r (docs/validation.md), seen
    # wherever spirals run below the limit, at any feed; fitted as the inverse of the jerk (the
    # twin file's controller.spiral_jerk), which the time is linear in, with no pole at 0.  A
    # constant time per block (block_time) trades with the limit where it binds and is not fitted
    # unless asked (fit=acceleration+block_time)
    fitted = ("acceleration", "normal_time")

    def machine(self, m, p):
        m = _controller_set(m, "spiral_acceleration", p["acceleration"])
        m = _controller_set(m, "spiral_jerk", jerk_of(p["normal_time"]))
        return _controller_set(m, "spiral_block_time", p["block_time"])


class RapidAcceleration(Effect):
    name = "rapid-acceleration"
    description = "rapids accelerate on their own acc/dec, harder (or softer) than feed moves"
    stage = "plan"
    params = (Param("acceleration", "mm/s^2", 0.0, 0.0, 20000.0,
                    "each axis' acceleration on rapids (to 2 g), 0 = the twin file's"),)
    signals = ("feed",)

    def machine(self, m, p):
        a = p["acceleration"]
        for name, ax in zip("xyz", m.axes):  # what the drives can give (the twin file's own check)
            if a > ax.drive_acceleration:
                raise ConfigError(f"effects.rapid-acceleration: controller.rapid_acceleration: {a:g} mm/s^2 is more "
                                  f"than axes.{name}.max_torque ({ax.max_torque:g} N*m) can give "
                                  f"{ax.equivalent_mass:.0f} kg")
        return _controller_set(m, "rapid_acceleration", a)


class FeedRapidWait(Effect):
    name = "feed-rapid-wait"
    description = ("the control stands at the end of a cutting-feed block that a rapid follows (an in-position "
                   "check for cutting feed, narrower than the rapids')")
    stage = "plan"
    params = (Param("time", "s", 0.0, 0.0, 0.5,
                    "how long it stands there (a fixed time: the axes settle meanwhile, the twin's in-position "
                    "check follows), 0 = the twin file's (controller.feed_rapid_wait)"),
              Param("rapid_feed", "s", 0.0, 0.0, 0.5,
                    "how long it stands where a rapid ends and a cutting-feed block follows (its in-position check "
                    "before cutting), 0 = the twin file's (controller.rapid_feed_wait)"))
    signals = ("feed",)

    def machine(self, m, p):
        m = _controller_set(m, "rapid_feed_wait", p.get("rapid_feed", 0.0))
        return _controller_set(m, "feed_rapid_wait", p["time"])


class FeedOverride(Effect):
    name = "feed-override"
    description = ("the run went at a feed override the log did not record — or the machine ran another version "
                   "of the program: an effective value of this run, not a machine property")
    stage = "plan"
    run_property = True  # (the twin file says so: journal.calibrated_text)
    params = (Param("feed", "", 100.0, 10.0, 300.0, "feed override in force for the whole run, %"),)
    signals = _TIME

    def machine(self, m, p):
        c = m.controller
        return replace(m, controller=replace(c, feed_override=c.feed_override * p["feed"] / 100.0))
