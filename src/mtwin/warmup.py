"""Compile every kernel into the cache ahead of use (``mtwin cache warm``).

A first run compiles only the kernels it needs and runs small work as plain Python
(``jit.Kernel.auto``), so it answers in seconds; a large program met later would then
pay the compile.  A container image or an installer runs ``mtwin cache warm`` once to
take that cost up front.  The kernels are compiled by running built-in programs through
the same code paths the commands use, so the cached signatures are exactly theirs.
"""
from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

#: set to "0" to keep a first run from compiling the kernels in a background process
BACKGROUND_ENV = "MTWIN_BACKGROUND_COMPILE"
_LOCK = "warming.lock"


def _lock_path() -> str:
    from . import jit  # noqa: F401  (sets NUMBA_CACHE_DIR)

    return os.path.join(os.environ["NUMBA_CACHE_DIR"], _LOCK)


def _alive(path: str) -> bool:
    """A warm-up holds the lock at ``path`` now."""
    try:
        with open(path) as fh:
            pid = int(fh.read().strip() or 0)
    except (OSError, ValueError):
        return False
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def warming() -> bool:
    """A background warm-up is running on this cache."""
    return _alive(_lock_path())


def start_background() -> bool:
    """Start ``mtwin cache warm --background`` as a detached process, unless it is switched
    off (``MTWIN_BACKGROUND_COMPILE=0``) or one is already running.  Returns whether it did."""
    if os.environ.get(BACKGROUND_ENV, "1") == "0" or warming():
        return False
    try:
        subprocess.Popen([sys.executable, "-m", "mtwin", "cache", "warm", "--background"],
                         stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                         start_new_session=True, env=dict(os.environ))
    except OSError:
        return False
    return True


class AlreadyWarming(Exception):
    pass


@contextlib.contextmanager
def background_lock():
    """Hold the warm-up lock of this cache (one background warm-up at a time)."""
    path = _lock_path()
    os.makedirs(os.path.dirname(path), exist_ok=True)
    if os.path.exists(path) and not _alive(path):
        with contextlib.suppress(OSError):
            os.remove(path)
    try:
        fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
    except FileExistsError:
        raise AlreadyWarming(path) from None
    with os.fdopen(fd, "w") as fh:
        fh.write(str(os.getpid()))
    try:
        yield
    finally:
        # only our own lock: a process that judged ours stale may hold the file now
        with contextlib.suppress(OSError, ValueError):
            with open(path) as fh:
                mine = int(fh.read().strip() or 0) == os.getpid()
            if mine:
                os.remove(path)

# lines, arcs, a helix, a canned cycle, a tool change, two feeds: every record kind the
# planner and the cutting model meet in a milling program
_MILLING = b"""%
O0001 (MTWIN WARM-UP)
(MTWIN STOCK 0,0,-10,40,30,0)
G21 G90 G17 G40 G49 G80 G94
T1 M6
G54 G0 X5. Y5. S9000 M3
G43 H1 Z5.
G1 Z-1. F300.
G1 X35. F900.
G2 X35. Y25. I0. J10.
G1 X5.
G3 X5. Y5. R10.
G1 X20. Y15. Z-2.
G2 X20. Y15. Z-3. I3. J0.
G0 Z5.
T2 M6
S6000 M3
G43 H2 Z5.
G98 G81 X10. Y10. Z-4. R1. F200.
X30.
G80
G0 Z20. M5
M30
%
"""

_LINUXCNC = b"""G21 G90 G17 G64 P0.01
T1 M6
S8000 M3
G0 X0 Y0 Z2
G1 Z-0.5 F200
G1 X10 F800
G1 X10.2 Y0.1
G2 X20 Y0 I4.9 J-0.1
G1 X30 Y5
M5
M2
"""


@contextlib.contextmanager
def _compiled_kernels():
    old = os.environ.get("MTWIN_KERNELS")
    os.environ["MTWIN_KERNELS"] = "compiled"
    try:
        yield
    finally:
        if old is None:
            del os.environ["MTWIN_KERNELS"]
        else:
            os.environ["MTWIN_KERNELS"] = old


def warm(step: Callable[[str], None] = lambda what: None) -> None:
    """Run the built-in programs through every stage with compiled kernels.

    ``step(what)`` is called before each stage (for a progress display)."""
    from .gcode.writer import rewrite
    from .gcode.interpreter import InterpreterSettings, load_program
    from .gcode.verify import compare
    from .twin import Twin

    with _compiled_kernels():
        step("lexer and interpreter")
        fanuc = load_program(_MILLING, InterpreterSettings(dialect="fanuc"), path="warm-up.nc")
        lcnc = load_program(_LINUXCNC, InterpreterSettings(dialect="linuxcnc"), path="warm-up.ngc")
        step("writer and verify")
        out = rewrite(fanuc, fanuc.records["feed"] * 0.9)
        compare(fanuc, load_program(out, InterpreterSettings(dialect="fanuc"), path="out.nc"), 0.001)
        twin = Twin()
        for style in ("fanuc", "linuxcnc", "grbl"):
            step(f"{style} planner and servo loop")
            tw = twin.with_controller(style=style)
            tw.simulate(lcnc, cutting=False)
        step("cutting model")
        twin.simulate(fanuc)
        step("cutting model, tooth resolution")
        twin.simulate(fanuc, tooth_resolution=True)
        step("optimiser")
        import numpy as np

        from .optimize.run import OptimizeOptions, optimize, warm_long_trace_kernels

        optimize(twin.with_tools({1: "flat:6:2", 2: "flat:6:2"}), fanuc, OptimizeOptions())
        warm_long_trace_kernels()
        step("chatter: lobes and the time-domain model")
        from .api import simulate as simulate_api
        from .chatter.lobes import Cut, Dynamics, lobes
        from .chatter.modes import Mode

        dyn = Dynamics((Mode("x", 922.0, 0.011, 1.34e6), Mode("y", 1010.0, 0.015, 8.0e6)))
        lobes(dyn, Cut.of(1.0), 2, 600.0, 200.0, np.linspace(5e3, 25e3, 8), "zoa", refine=False)
        lobes(dyn, Cut.of(0.1), 2, 600.0, 200.0, np.linspace(5e3, 25e3, 2), "sdm", steps=8, refine=False)
        lobes(Dynamics(dyn.modes[:1]), Cut.of(0.1), 2, 600.0, 200.0, np.linspace(5e3, 25e3, 2), "sdm", steps=8,
              refine=False)
        from .cutting.library import Tool

        # (stiff modes: the warm-up's cuts stay stable, so its vibration stays finite)
        tool = Tool(diameter=6.0, flutes=2, modes=(Mode("x", 922.0, 0.05, 1.34e8), Mode("y", 1010.0, 0.05, 8.0e8)))
        simulate_api(twin.with_tools({1: tool, 2: tool}), fanuc, dynamics=True)
        step("measurement alignment")
        from .loop.compare import compare
        from .loop.measurement import Measurement

        tr = twin.simulate(fanuc)
        meas = Measurement("warm-up.csv", tr.t[::10], {a: tr.signal(a)[::10] for a in ("x", "y", "z")})
        compare(tr, meas, "position")


def cache_dir() -> str:
    """Where the compiled kernels are cached (``NUMBA_CACHE_DIR``)."""
    from . import jit  # noqa: F401  (sets NUMBA_CACHE_DIR)

    return os.environ["NUMBA_CACHE_DIR"]


def set_notices(compile_notice=None, uncached_notice=None) -> None:
    """How a caller hears of kernel work: ``compile_notice(name)``, a context manager around
    each compile; ``uncached_notice(kernel)``, called when a kernel runs as Python because the
    cache lacks it.  None: silent (the library's default)."""
    from . import jit

    jit.compile_notice = compile_notice or jit.no_notice
    jit.uncached_notice = uncached_notice or jit.no_uncached


def compiled_count() -> int:
    """Kernels compiled in this process."""
    from . import jit

    return len(jit.COMPILE_LOG)


# ---------------------------------------------------------------------- the cache as use cases (mtwin cache)

@dataclass(frozen=True)
class CacheInfo:
    path: str
    files: int
    bytes: int


def cache_info() -> CacheInfo:
    """``mtwin cache info``: where the compiled kernels are and how much they hold."""
    d = Path(cache_dir())
    files = [p for p in d.rglob("*") if p.is_file()] if d.is_dir() else []
    return CacheInfo(str(d), len(files), sum(p.stat().st_size for p in files))


def cache_clear() -> str:
    """``mtwin cache clear``: the compiled kernels deleted (the next run compiles what it
    needs again); the folder's path."""
    d = Path(cache_dir())
    if d.is_dir():
        shutil.rmtree(d)
    return str(d)


def cache_warm(on_progress: Callable[[str], None] | None = None) -> tuple[int, float, str]:
    """``mtwin cache warm``: every kernel compiled into the cache now; (kernels compiled,
    seconds, the cache's folder).  ``on_progress(what)`` as each starts."""
    t0 = time.perf_counter()
    warm(on_progress or (lambda what: None))
    return compiled_count(), time.perf_counter() - t0, str(cache_dir())


def cache_warm_background() -> None:
    """The detached warm-up a first run starts: low priority, one at a time, silent."""
    set_notices(None, None)
    with contextlib.suppress(OSError, AttributeError):
        os.nice(10)
    with contextlib.suppress(AlreadyWarming), background_lock():
        warm()
