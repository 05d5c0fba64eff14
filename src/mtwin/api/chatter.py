"""Chatter use cases: the stability lobes of a twin's tool (``mtwin lobes``) and modes fitted
to a tap test (``mtwin calibrate-frf``)."""
from __future__ import annotations

import math
from typing import Optional

from ..errors import ConfigError, MtwinError


def _feed_angle(text: str) -> float:
    t = str(text).strip().lower()
    if t in ("x", "+x"):
        return 0.0
    if t in ("y", "+y"):
        return math.pi / 2
    if t == "-x":
        return math.pi
    if t == "-y":
        return -math.pi / 2
    from ..chatter.modes import finite_number

    deg = finite_number(t, "--feed-direction", "x, y, -x, -y or an angle in degrees from +X")
    if not -360.0 <= deg <= 360.0:  # (1e99 degrees is no direction: its remainder is noise)
        raise MtwinError(f"--feed-direction: an angle from -360 to 360 degrees, got {deg:g}")
    return math.radians(deg)


MIN_POINTS, MAX_POINTS = 10, 20_000


def stability_lobes(twin=None, *, tool: int = 1, immersion: Optional[float] = None, ae: Optional[float] = None,
                    milling: str = "down", feed_direction: str = "x",
                    speed_range: Optional[tuple[float, float]] = None, method: str = "auto", points: int = 0,
                    steps: int = 40):
    """The lobes of tool ``tool`` of a twin (a Twin or a twin file's path): limiting axial depth
    (mm) per spindle speed (rpm) for a straight cut at radial immersion ``immersion`` (ae/D) or
    width ``ae`` (mm), the twin's material.  ``speed_range`` defaults to a tenth of the
    spindle's maximum speed up to it."""
    from ..chatter.lobes import Cut, dynamics_of, lobes, speed_grid
    from ..twin.setup import open_twin

    tw = open_twin(twin)
    cut = tw.cutting
    if tool not in cut.tools:
        raise ConfigError(f"--tool {tool}: the twin file has no [tools.{tool}] table" +
                          (f" (it has {', '.join(f'T{k}' for k in sorted(cut.tools))})" if cut.tools else ""))
    tl = cut.tools[tool]
    dyn = dynamics_of(tl)
    if not dyn:
        raise ConfigError(f"tool T{tool} has no dynamics: give it [[tools.{tool}.modes]] (direction, fn, zeta, k) or "
                          f"tools.{tool}.frf in the twin file")
    if (immersion is None) == (ae is None):
        if immersion is None:
            immersion = 1.0
        else:
            raise ConfigError("give one of --immersion (ae/D) and --ae (mm)")
    if ae is not None:
        if not (ae > 0 and math.isfinite(ae)):
            raise ConfigError(f"--ae must be a positive width in mm, got {ae:g}")
        immersion = ae / tl.diameter
        if immersion > 1.0:
            raise ConfigError(f"--ae {ae:g} mm is wider than the tool ({tl.diameter:g} mm): ae/D must be in (0, 1]")
    c = Cut.of(float(immersion), milling, _feed_angle(feed_direction))
    top = tw.machine.spindle.max_speed
    lo, hi = speed_range if speed_range is not None else (0.1 * top, top)
    if steps < 4 or steps > 400:
        raise ConfigError(f"--steps must be 4..400, got {steps}")
    if points and not MIN_POINTS <= points <= MAX_POINTS:
        # (each point is a root search over the chatter frequency: 100,000 points take minutes)
        raise ConfigError(f"--points must be {MIN_POINTS}..{MAX_POINTS:,} speeds, got {points:,}")
    grid = speed_grid(lo, hi, points if points else (500 if method == "zoa" else 200))
    mat = cut.material
    res = lobes(dyn, c, tl.flutes, mat.ktc, mat.krc, grid, method, steps=steps)
    if hi > top:
        res.notes.append(f"the range goes above the spindle's maximum speed {top:g} rpm")
    return res


def calibrate_frf(path: str, *, modes_per_direction: int = 2):
    """Modes fitted to a tap test's FRF file (``mtwin calibrate-frf``)."""
    from ..chatter.modes import read_frf
    from ..chatter.tapfit import fit_frf

    if not 1 <= modes_per_direction <= 6:
        raise ConfigError(f"--modes must be 1..6 per direction, got {modes_per_direction}")
    return fit_frf(read_frf(path), modes_per_direction)


def lobes_plot(res, fmt: str = "svg", points: dict | None = None) -> bytes:
    """The lobes as a figure (svg/png/pdf bytes); ``points``: label -> (speeds, depths) drawn on it."""
    from ..report.plots import lobes_figure

    return lobes_figure({f"{res.method}": (res.speeds, res.depth_limit)}, res.flip, fmt, points or {},
                        title=f"stability lobes ({res.method})")


__all__ = ["calibrate_frf", "lobes_plot", "stability_lobes"]
