"""A tool's dynamics at its tip: modes in the machine's X and Y, or a measured FRF.

A mode (``[[tools.N.modes]]`` in the twin file) is a single-degree-of-freedom oscillator along
one machine axis::

    Φ(ω) = 1 / (k·(1 − r² + 2iζr)),   r = ω/ωn,  ωn = 2π·fn      (m/N)

with stiffness k (N/m) or modal mass m (kg, k = m·ωn²).  The modes of one direction add.  A
measured FRF (a tap test, ``tools.N.frf = "tap.csv"``) is the tool-tip compliance in X and Y
(m/N) at measured frequencies; where a tool has both, the FRF stands and the modes are not used.

Two FRF file layouts are read:

* CSV with a header: ``freq`` (Hz) and per direction ``re_xx, im_xx`` and/or ``re_yy, im_yy``
  (m/N; ``xx``/``yy`` may also be written ``x``/``y``); a ``#`` line is a comment;
* CutPro's text layout (``.frf``): lines ``freq  real  imag`` for one direction, optionally
  preceded by header lines (anything that is not three numbers); the file's direction comes
  from a ``direction = x|y`` (or ``X``/``Y``) header line, or from the name (``…_x.frf``).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ConfigError

DIRECTIONS = ("x", "y")


@dataclass(frozen=True)
class Mode:
    """One mode of the tool tip along a machine axis."""

    direction: str  # "x" | "y"
    fn: float  # Hz
    zeta: float  # damping ratio
    k: float  # N/m

    @property
    def mass(self) -> float:
        return self.k / (2.0 * math.pi * self.fn) ** 2

    def compliance(self, f: np.ndarray) -> np.ndarray:
        r = np.asarray(f, float) / self.fn
        return 1.0 / (self.k * (1.0 - r * r + 2j * self.zeta * r))


MODE_KEYS = {"direction": "x | y (machine axis)", "fn": "natural frequency, Hz",
             "zeta": "damping ratio (0 < ζ < 1)", "k": "modal stiffness, N/m (or m)",
             "m": "modal mass, kg (or k)"}


K_RANGE = (1e2, 1e12)  # N/m
FN_MAX = 1e5  # Hz
FN_MIN = 1.0  # Hz: below it no tool tip (a machine's frame may ring at 10-50 Hz)


def parse_modes(raw, where: str) -> tuple[Mode, ...]:
    """``[[tools.N.modes]]`` entries -> modes; every error names the entry."""
    if not isinstance(raw, list):
        raise ConfigError(f"{where}: expected an array of tables [[{where.split(': ')[-1]}]]")
    out = []
    for i, body in enumerate(raw):
        at = f"{where}[{i}]"
        if not isinstance(body, dict):
            raise ConfigError(f"{at}: each mode is a table (direction, fn, zeta, k or m)")
        for key in body:
            if key not in MODE_KEYS:
                raise ConfigError(f"{at}: unknown key {key!r} (known: {', '.join(MODE_KEYS)})")
        d = body.get("direction")
        if d not in DIRECTIONS:
            raise ConfigError(f"{at}.direction: expected \"x\" or \"y\" (machine axes), got {d!r}")
        vals = {}
        for key in ("fn", "zeta", "k", "m"):
            if key in body:
                v = body[key]
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                    raise ConfigError(f"{at}.{key}: expected a number, got {v!r}")
                vals[key] = float(v)
        if "fn" not in vals:
            raise ConfigError(f"{at}: needs fn (natural frequency, Hz)")
        if "zeta" not in vals:
            raise ConfigError(f"{at}: needs zeta (damping ratio)")
        if vals["fn"] <= 0:
            raise ConfigError(f"{at}.fn: must be > 0 Hz, got {vals['fn']:g}")
        if not 0 < vals["zeta"] < 1:
            raise ConfigError(f"{at}.zeta: the damping ratio must be in (0, 1) (a negative one is an unstable "
                              f"structure), got {vals['zeta']:g}")
        if ("k" in vals) == ("m" in vals):
            raise ConfigError(f"{at}: give one of k (stiffness, N/m) or m (modal mass, kg)")
        k = vals["k"] if "k" in vals else vals["m"] * (2.0 * math.pi * vals["fn"]) ** 2
        if k <= 0:
            raise ConfigError(f"{at}: the stiffness (or mass) must be > 0, got {vals.get('k', vals.get('m')):g}")
        # the stiffness of a real tool tip: from some 1e3 N/m (a 1 mm tool at 30 mm stick-out) to
        # 1e10 N/m (a spindle nose); beyond the range a value is a typo and overflows the run
        if not K_RANGE[0] <= k <= K_RANGE[1]:
            raise ConfigError(f"{at}: a stiffness of {k:g} N/m is outside what a tool tip has ({K_RANGE[0]:g} to "
                              f"{K_RANGE[1]:g} N/m): a typo or a unit mistake?")
        if vals["fn"] > FN_MAX:
            raise ConfigError(f"{at}.fn: {vals['fn']:g} Hz is above any tool-tip mode ({FN_MAX:g} Hz at most)")
        if vals["fn"] < FN_MIN:
            raise ConfigError(f"{at}.fn: {vals['fn']:g} Hz is below any tool-tip mode ({FN_MIN:g} Hz at least)")
        out.append(Mode(d, vals["fn"], vals["zeta"], k))
    return tuple(out)


@dataclass(frozen=True)
class FRF:
    """A measured tool-tip FRF: frequencies (Hz, increasing) and compliance per direction (m/N;
    zeros where a direction was not measured — the tool is rigid that way)."""

    freq: np.ndarray
    xx: np.ndarray
    yy: np.ndarray
    source: str = ""

    def __hash__(self):
        return hash((self.source, self.freq.tobytes(), self.xx.tobytes(), self.yy.tobytes()))

    def __eq__(self, other):
        return isinstance(other, FRF) and self.source == other.source and np.array_equal(self.freq, other.freq) \
            and np.array_equal(self.xx, other.xx) and np.array_equal(self.yy, other.yy)


def read_frf(path: str | Path, need: tuple[str, ...] = ()) -> FRF:
    """Read a tap test's FRF (CSV or CutPro text, see the module); ``need``: directions that must
    be present.  Errors carry ``file:line:col:`` and are :class:`ConfigError` (exit 2)."""
    from ..io import read_input

    if not Path(path).exists():
        raise ConfigError(f"{path}: cannot read the FRF file: no such file")
    try:
        text = read_input(path, "frf").decode("utf-8", errors="replace")
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the FRF file: {exc.strerror or exc}") from None
    lines = text.splitlines()
    first = next((ln for ln in lines if ln.strip() and not ln.lstrip().startswith("#")), "")
    if "," in first and not _numbers(first.split(",")):
        frf = _read_csv(str(path), lines)
    else:
        frf = _read_cutpro(str(path), lines)
    check_sign(frf)
    for d in need:
        if not np.any(getattr(frf, d + d)):
            raise ConfigError(f"{path}: the FRF has no {d.upper()} direction (columns re_{d}{d}, im_{d}{d}), "
                             f"which this use needs")
    return frf


def check_sign(frf: FRF) -> None:
    """A direct compliance X/F (e^{iwt}) lags the force by 90° at resonance: its imaginary part
    is negative at the peak.  A positive one is the other sign convention (e^{-iwt}, or a force
    sensor wired the other way): fitted or used as it is, it gives a stiffness off by orders of
    magnitude (k = 1.7e14 N/m for a true 8e6) and lobes at the wrong speeds."""
    for d in ("x", "y"):
        h = getattr(frf, d + d)
        if not np.any(h):
            continue
        at = int(np.argmax(np.abs(h)))
        if h[at].imag > 0:
            raise ConfigError(f"{frf.source}: the {d.upper()} FRF's imaginary part is positive at its resonance "
                              f"({frf.freq[at]:.0f} Hz, im = {h[at].imag:.3g} m/N): the other sign convention "
                              f"(e^(-iwt), or the force taken the other way); negate the im_{d}{d} column")


def _numbers(fields: list) -> bool:
    try:
        [float(x) for x in fields]
    except ValueError:
        return False
    return True


def finite_number(tok: str, where: str, expected: str = "a number", echo: bool = True) -> float:
    """``tok`` as a finite float, or a ConfigError that starts with ``where`` (and quotes ``tok``
    unless ``echo`` is false: a file's text where the file may be anyone's)."""
    try:
        v = float(tok)
    except ValueError:
        raise ConfigError(f"{where}: expected {expected}" + (f", got {tok.strip()!r}" if echo else "")) from None
    if not math.isfinite(v):
        raise ConfigError(f"{where}: " + (f"{tok.strip()} is not a finite number" if echo else "not a finite number"))
    return v


# an FRF's bounds: a tap test's band is a few kHz (the modes the twin takes are 1 Hz-100 kHz), and
# the compliance of the softest tool tip it takes (k = 1e2 N/m, zeta 0.001) peaks at 5 m/N
FRF_MAX_HZ = 1e5
FRF_MAX_COMPLIANCE = 10.0  # m/N


def _num(tok: str, path: str, ln: int, col: int, what: str, scale: float = 1.0) -> float:
    """A cell of an FRF, in Hz or m/N (``scale``: from the unit its header gives), within what a
    tap test measures."""
    # an FRF's errors name the place, not the text there: a twin file may point its FRF at any
    # file beside it, and a batch copies errors into its reports
    v = finite_number(tok, f"{path}:{ln}:{col}: {what}", echo=False) * scale
    freq = what in ("freq", "frequency")
    if abs(v) > (FRF_MAX_HZ if freq else FRF_MAX_COMPLIANCE):
        raise ConfigError(f"{path}:{ln}:{col}: {what}: beyond what a tap test measures (at most "
                          + (f"{FRF_MAX_HZ:g} Hz)" if freq else f"{FRF_MAX_COMPLIANCE:g} m/N in magnitude; a "
                             "compliance is in m/N)"))
    return v


def _check_freqs(freq: list, rows: list, path: str) -> None:
    if len(freq) < 3:
        raise ConfigError(f"{path}: an FRF needs at least 3 frequencies, got {len(freq)}")
    for i in range(1, len(freq)):
        if not freq[i] > freq[i - 1]:
            raise ConfigError(f"{path}:{rows[i]}:1: frequencies must increase: {freq[i]:g} Hz after "
                             f"{freq[i - 1]:g} Hz")
    if freq[0] < 0:
        raise ConfigError(f"{path}:{rows[0]}:1: a frequency must be >= 0 Hz, got {freq[0]:g}")


def _read_csv(path: str, lines: list[str]) -> FRF:
    header_at = next(i for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#"))
    names = [h.strip().lower() for h in lines[header_at].split(",")]
    alias, scale = {}, {}
    for i, h in enumerate(names):
        h2 = re.sub(r"\s*\(.*\)$", "", h)  # "freq (hz)", "re_xx (m/n)"
        unit = re.search(r"\(([^)]*)\)\s*$", h)
        unit = unit.group(1).strip().replace("µ", "u") if unit else ""
        h2 = {"re_x": "re_xx", "im_x": "im_xx", "re_y": "re_yy", "im_y": "im_yy", "frequency": "freq",
              "f": "freq", "freq_hz": "freq"}.get(h2, h2)
        if h2 not in ("freq", "re_xx", "im_xx", "re_yy", "im_yy"):
            raise ConfigError(f"{path}:{header_at + 1}:{_col(lines[header_at], i)}: unknown column (an FRF "
                             f"CSV has freq, re_xx, im_xx, re_yy, im_yy; m/N)")
        if h2 in alias:
            raise ConfigError(f"{path}:{header_at + 1}:{_col(lines[header_at], i)}: a column named twice")
        alias[h2] = i
        # a unit in the header is honoured (a tap test in mm/N read as m/N is 1000 times too soft)
        units = {"": 1.0, "hz": 1.0, "khz": 1e3} if h2 == "freq" else {"": 1.0, "m/n": 1.0, "mm/n": 1e-3,
                                                                         "um/n": 1e-6}
        if unit not in units:
            raise ConfigError(f"{path}:{header_at + 1}:{_col(lines[header_at], i)}: unit ({unit}) not known for "
                              f"{h2} (known: {', '.join(u for u in units if u)})")
        scale[h2] = units[unit]
    if "freq" not in alias:
        raise ConfigError(f"{path}:{header_at + 1}:1: no freq column (Hz)")
    for d in ("xx", "yy"):
        if ("re_" + d in alias) != ("im_" + d in alias):
            raise ConfigError(f"{path}:{header_at + 1}:1: direction {d[0].upper()} needs both re_{d} and im_{d}")
    if "re_xx" not in alias and "re_yy" not in alias:
        raise ConfigError(f"{path}:{header_at + 1}:1: no direction: give re_xx, im_xx and/or re_yy, im_yy (m/N)")
    freq, cols, rows = [], {k: [] for k in alias}, []
    for i in range(header_at + 1, len(lines)):
        ln = lines[i]
        if not ln.strip() or ln.lstrip().startswith("#"):
            continue
        toks = ln.split(",")
        if len(toks) != len(names):
            raise ConfigError(f"{path}:{i + 1}:1: expected {len(names)} fields, got {len(toks)}")
        for k, j in alias.items():
            cols[k].append(_num(toks[j], path, i + 1, _col(ln, j), k, scale[k]))
        rows.append(i + 1)
    freq = cols.pop("freq")
    _check_freqs(freq, rows, path)
    f = np.asarray(freq)
    out = {}
    for d in ("xx", "yy"):
        out[d] = (np.asarray(cols["re_" + d]) + 1j * np.asarray(cols["im_" + d])) if "re_" + d in cols \
            else np.zeros(len(f), complex)
    return FRF(f, out["xx"], out["yy"], path)


def _col(line: str, field: int) -> int:
    """1-based column of the ``field``-th comma-separated field of a line."""
    pos = 0
    for _ in range(field):
        pos = line.index(",", pos) + 1
    return pos + 1 + (len(line[pos:]) - len(line[pos:].lstrip()))


def _read_cutpro(path: str, lines: list[str]) -> FRF:
    direction = None
    freq, re_, im_, rows = [], [], [], []
    for i, ln in enumerate(lines):
        s = ln.strip()
        if not s or s.startswith(("#", ";", "%")):
            continue
        m = re.match(r"direction\s*[=:]\s*([xy])\b", s, re.I)
        if m:
            direction = m.group(1).lower()
            continue
        toks = s.replace(",", " ").split()
        if len(toks) == 3 and all(re.fullmatch(r"[-+0-9.eE]+|nan|NaN|inf|-inf", t) for t in toks):
            starts = [m.start() + 1 for m in re.finditer(r"\S+", ln)]
            freq.append(_num(toks[0], path, i + 1, starts[0], "frequency"))
            re_.append(_num(toks[1], path, i + 1, starts[1], "real part"))
            im_.append(_num(toks[2], path, i + 1, starts[2], "imaginary part"))
            rows.append(i + 1)
        elif freq:
            raise ConfigError(f"{path}:{i + 1}:1: expected three numbers (frequency Hz, real, imaginary m/N)")
    if not freq:
        raise ConfigError(f"{path}: no FRF rows (CSV with a freq,re_xx,im_xx… header, or CutPro lines "
                         f"'frequency real imaginary')")
    if direction is None:
        m = re.search(r"[_\-.]([xyXY])\.frf$", Path(path).name) or re.search(r"[_\-]([xyXY])[_\-.]", Path(path).name)
        direction = m.group(1).lower() if m else None
    if direction is None:
        raise ConfigError(f"{path}: a CutPro FRF file holds one direction: say which with a 'direction = x' "
                         f"line or a name ending _x.frf / _y.frf")
    _check_freqs(freq, rows, path)
    f = np.asarray(freq)
    h = np.asarray(re_) + 1j * np.asarray(im_)
    z = np.zeros(len(f), complex)
    return FRF(f, h if direction == "x" else z, h if direction == "y" else z, path)


def compliance(modes: tuple[Mode, ...], frf: FRF | None, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Φxx, Φyy (m/N) at frequencies ``f`` (Hz): the measured FRF (linear interpolation; zero
    outside its band) where there is one, else the sum of the modes."""
    f = np.asarray(f, float)
    if frf is not None:
        out = []
        for h in (frf.xx, frf.yy):
            re_ = np.interp(f, frf.freq, h.real, left=0.0, right=0.0)
            im_ = np.interp(f, frf.freq, h.imag, left=0.0, right=0.0)
            out.append(re_ + 1j * im_)
        return out[0], out[1]
    xx = np.zeros(len(f), complex)
    yy = np.zeros(len(f), complex)
    for m in modes:
        if m.direction == "x":
            xx += m.compliance(f)
        else:
            yy += m.compliance(f)
    return xx, yy


def with_mode_param(modes: tuple[Mode, ...], direction: str, index: int, name: str, value: float,
                    key: str) -> tuple[Mode, ...]:
    """A copy with one mode's fn, zeta or k changed: ``tools.N.modes.x.0.fn`` is the first X mode."""
    from dataclasses import replace

    of_dir = [i for i, m in enumerate(modes) if m.direction == direction]
    if index >= len(of_dir):
        raise ConfigError(f"{key}: the tool has {len(of_dir)} {direction.upper()} mode(s)")
    if name not in ("fn", "zeta", "k"):
        raise ConfigError(f"{key}: a mode has fn, zeta and k")
    v = float(value)
    if not math.isfinite(v) or v <= 0 or (name == "zeta" and v >= 1):
        raise ConfigError(f"{key}: must be > 0{' and < 1' if name == 'zeta' else ''}, got {value!r}")
    i = of_dir[index]
    return modes[:i] + (replace(modes[i], **{name: v}),) + modes[i + 1:]


def mode_param_names(number: int, modes: tuple[Mode, ...]) -> list[str]:
    out = []
    for d in DIRECTIONS:
        for j, _ in enumerate(m for m in modes if m.direction == d):
            out += [f"tools.{number}.modes.{d}.{j}.{p}" for p in ("fn", "zeta", "k")]
    return out


def mode_param(modes: tuple[Mode, ...], direction: str, index: int, name: str, key: str) -> float:
    of_dir = [m for m in modes if m.direction == direction]
    if index >= len(of_dir) or name not in ("fn", "zeta", "k"):
        raise ConfigError(f"{key}: no such mode parameter (the tool has {len(of_dir)} {direction.upper()} mode(s); "
                          f"each has fn, zeta, k)")
    return float(getattr(of_dir[index], name))
