"""Did a cut chatter?  The spectrum of a measured vibration (an accelerometer, a microphone, a
displacement probe — any signal that vibrates with the tool) or a spectrum a user already
has, read against the spindle speed the program ran at.

A stable cut's vibration is forced: its peaks sit on the spindle's harmonics (k·n/60, the
tooth-passing ones k·N·n/60 strongest).  Regenerative chatter adds a peak off them, near a
mode of the structure; a flip (period-doubling) chatter sits at half a tooth-passing
harmonic.  A spectrum chattered when its strongest peak off the spindle harmonics stands
``FLOOR`` times over the spectrum's median and at least ``SHARE`` of the strongest
tooth-passing peak.

The spectrum file (``mtwin diagnose PROGRAM spectrum.csv``): CSV with ``freq`` (Hz) and
``amplitude`` (any unit), and optionally ``line`` or ``first_line``/``last_line`` giving the
program lines a row's spectrum was taken over (rows with the same lines are one spectrum).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError
from .modes import finite_number

FLOOR = 10.0  # an off-harmonic peak at least this many times the median level
SHARE = 0.3  # and this share of the strongest tooth-passing peak


@dataclass
class Spectrum:
    first_line: int  # 0: the whole program
    last_line: int
    freq: np.ndarray
    amp: np.ndarray


def read_spectrum(path: str) -> list[Spectrum]:
    import csv

    from ..io import check_input

    check_input(path, "spectrum")
    try:
        fh = open(path, newline="", encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the spectrum file: {exc.strerror or exc}") from None
    with fh:
        reader = csv.reader(fh)
        try:
            rows = [r for r in reader if r and not r[0].lstrip().startswith("#")]
        except (csv.Error, UnicodeDecodeError) as exc:
            raise ConfigError(f"{path}:{reader.line_num}:1: not a CSV row: {exc}") from None
    if not rows:
        raise ConfigError(f"{path}: empty spectrum file")
    head = [h.strip().lower() for h in rows[0]]
    for i, h in enumerate(head):
        if h not in ("freq", "amplitude", "line", "first_line", "last_line"):
            raise ConfigError(f"{path}:1:{i + 1}: unknown column {h!r} (a spectrum has freq, amplitude and "
                              f"optionally line or first_line, last_line)")
    if "freq" not in head or "amplitude" not in head:
        raise ConfigError(f"{path}:1:1: a spectrum needs the columns freq (Hz) and amplitude")
    col = {h: i for i, h in enumerate(head)}
    groups: dict = {}
    for n, r in enumerate(rows[1:], start=2):
        if len(r) != len(head):
            raise ConfigError(f"{path}:{n}:1: expected {len(head)} fields, got {len(r)}")
        vals = {}
        for h, i in col.items():
            vals[h] = finite_number(r[i], f"{path}:{n}:{i + 1}: {h}")
        a = int(vals.get("first_line", vals.get("line", 0)))
        b = int(vals.get("last_line", vals.get("line", 0)))
        g = groups.setdefault((a, b), ([], [], n))
        if g[0] and vals["freq"] <= g[0][-1]:
            raise ConfigError(f"{path}:{n}:{col['freq'] + 1}: frequencies must increase within a spectrum")
        g[0].append(vals["freq"])
        g[1].append(vals["amplitude"])
    out = []
    for (a, b), (f, amp, _) in groups.items():
        if len(f) < 8:
            raise ConfigError(f"{path}: the spectrum of lines {a}-{b} has {len(f)} frequencies; at least 8 are needed")
        out.append(Spectrum(a, b, np.asarray(f), np.abs(np.asarray(amp))))
    return out


def spectra_of_trace(t: np.ndarray, line: np.ndarray, values: np.ndarray, lines: list[int]) -> list[Spectrum]:
    """Per program line, the amplitude spectrum (Hann window) of a vibration signal's samples
    while that line ran (at least 64)."""
    out = []
    for ln in lines:
        m = (line == ln) & np.isfinite(values)
        if m.sum() < 64:
            continue
        tt = t[m]
        x = values[m]
        dt = float(np.median(np.diff(tt)))
        if not dt > 0:
            continue
        x = x - x.mean()
        w = np.hanning(len(x))
        amp = np.abs(np.fft.rfft(x * w)) * 2 / w.sum()
        out.append(Spectrum(ln, ln, np.fft.rfftfreq(len(x), dt), amp))
    return out


def verdict(sp: Spectrum, speed: float, flutes: int, modes=()) -> dict:
    """Chatter or not, from one spectrum at spindle speed ``speed`` (rpm) with ``flutes``."""
    f, a = sp.freq, sp.amp
    fs = speed / 60.0
    tp = flutes * fs
    df = float(np.median(np.diff(f))) if len(f) > 1 else 1.0
    tol = max(0.01, 2.5 * df / max(fs, 1e-9))
    peak = np.zeros(len(a), bool)
    peak[1:-1] = (a[1:-1] >= a[:-2]) & (a[1:-1] > a[2:])
    floor = float(np.median(a[f > 0])) if (f > 0).any() else 0.0
    on_spindle = np.abs(f / fs - np.round(f / fs)) < tol if fs > 0 else np.zeros(len(f), bool)
    on_tooth = np.abs(f / tp - np.round(f / tp)) < tol / flutes if tp > 0 else np.zeros(len(f), bool)
    half = np.abs((f / tp) % 1.0 - 0.5) < tol / flutes if tp > 0 else np.zeros(len(f), bool)
    usable = peak & (f > 0.5 * fs)
    tooth = usable & on_tooth & (f > 0.5 * tp)
    # off the forced lines — but a flip chatters at half a tooth-passing harmonic, which with an
    # even number of flutes is a spindle harmonic too: those count (a run-out line there is
    # weak; the share of the tooth-passing peak below tells them apart)
    off = usable & (~on_spindle | half)
    top_tooth = float(a[tooth].max()) if tooth.any() else 0.0
    out = {"first_line": sp.first_line, "last_line": sp.last_line, "speed": speed, "tooth_passing": tp,
           "chatter": False, "chatter_frequency": None, "kind": None, "ratio": None, "nearest_mode": None}
    if not off.any():
        return out
    i = int(np.flatnonzero(off)[np.argmax(a[off])])
    ratio = float(a[i] / top_tooth) if top_tooth > 0 else math.inf
    out["ratio"] = ratio
    if a[i] >= FLOOR * max(floor, 1e-300) and ratio >= SHARE:
        out["chatter"] = True
        out["chatter_frequency"] = float(f[i])
        out["kind"] = "flip (period doubling: half a tooth-passing harmonic)" if half[i] else \
            "Hopf (off the harmonics)"
        if modes:
            m = min(modes, key=lambda m: abs(m.fn - f[i]))
            out["nearest_mode"] = {"direction": m.direction, "fn": m.fn}
    return out
