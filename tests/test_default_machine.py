"""The default machine contours like a control of today (issue 31): velocity feed-forward makes
its circular-test and corner errors those published for production machining centres, not
the 0.15-0.4 mm of a drive that lags v/Kv behind the command.

Published ranges (docs/motion.md, "Accuracy of the default machine"):

* ISO 230-4 circular test, R 50-150 mm at 1,000-2,000 mm/min: circular deviation of
  production VMCs 5-30 um (Kakino et al. 1993, ballbar examples 10-20 um; ISO 10791-6 K4
  acceptance tolerance 0.03 mm on such circles);
* a 90-degree corner at 2,000 mm/min under look-ahead acc/dec before interpolation with
  feed-forward: a few um to tens of um (Erkorkmaz & Altintas 2001, Part III).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import mtwin
from mtwin.twin import Twin

CIRCLE = b"""G21 G90 G17
G0 X{r} Y0 Z5
G1 Z0 F500
G1 F{f}
G3 X{r} Y0 I-{r} J0
G3 X{r} Y0 I-{r} J0
M30
"""

CORNER = b"""G21 G90 G17
G0 X0 Y0 Z5
G1 Z0 F500
G1 X100 F2000
G1 Y100
M30
"""


def _trace(prog: bytes, twin=None):
    return mtwin.simulate(twin, prog, cutting=False).trace


def _no_feedforward() -> Twin:
    tw = Twin.from_toml(None)
    m = tw.machine
    axes = {a: replace(getattr(m, a), servo=replace(getattr(m, a).servo, feedforward=0.0)) for a in "xyz"}
    return tw.replace(machine=replace(m, **axes))


def _circular_deviation(r: float, f: float, twin=None) -> float:
    tr = _trace(CIRCLE.replace(b"{r}", str(r).encode()).replace(b"{f}", str(f).encode()), twin)
    x, y, line = tr.signal("x"), tr.signal("y"), np.asarray(tr.line)
    m = line == 6  # the second full circle: the first one's entry transient is over
    rad = np.hypot(x[m], y[m])
    return float(rad.max() - rad.min())


def _corner_deviation(twin=None) -> float:
    """Largest distance of the actual tool position from the commanded path (the two legs)."""
    tr = _trace(CORNER, twin)
    x, y = tr.signal("x"), tr.signal("y")
    m = np.asarray(tr.line) >= 4
    d1 = np.hypot(x - np.clip(x, 0, 100), y)
    d2 = np.hypot(x - 100, y - np.clip(y, 0, 100))
    return float(np.minimum(d1, d2)[m].max())


@pytest.mark.parametrize("r,f", [(50.0, 1000.0), (50.0, 2000.0), (150.0, 2000.0)])
def test_the_circular_test_is_within_the_published_range(r, f):
    dev = _circular_deviation(r, f)
    assert 0.002 <= dev <= 0.030, f"circular deviation {dev * 1e3:.1f} um at R{r:g} F{f:g}"


def test_a_corner_is_within_the_published_range_and_feedforward_is_why():
    with_ff = _corner_deviation()
    assert 0.001 <= with_ff <= 0.030, f"{with_ff * 1e3:.1f} um"
    # the same machine without feed-forward lags v/Kv (0.83 mm at 2,000 mm/min, Kv 40) and cuts
    # the corner by well over 0.1 mm: the property the default is chosen for
    assert _corner_deviation(_no_feedforward()) > 0.1


def test_the_calibrated_profiles_keep_their_values():
    from mtwin.twin.files import load_machine
    from conftest import ROOT

    m = load_machine(str(ROOT / "samples" / "machines" / "linuxcnc-sim.toml"))
    assert [ax.servo.feedforward for ax in m.axes] == [0.0, 0.0, 0.0]
    # the Hurco profile was recalibrated with the default's feed-forward (scripts/hurco-vmx24.sh
    # says why): it keeps what it was calibrated with by not setting it
    m = load_machine(str(ROOT / "samples" / "machines" / "hurco-vmx24.toml"))
    assert [ax.servo.feedforward for ax in m.axes] == [0.9, 0.9, 0.9]
    assert "feedforward" not in (ROOT / "samples" / "machines" / "hurco-vmx24.toml").read_text()
    assert [ax.servo.feedforward for ax in Twin.from_toml(None).machine.axes] == [0.9, 0.9, 0.9]
