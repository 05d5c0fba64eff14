"""The one place where numba is configured, and where kernels are compiled — or not.

``NUMBA_CACHE_DIR`` must be set before numba is imported so that compiled kernels
are cached in a user-writable directory even when the package itself is installed
read-only.  Every kernel module decorates its kernels with :func:`njit` from here,
never with numba's own, so JIT flags and start-up policy live in one place.

Start-up is a feature (``docs/performance.md``).  A kernel is a :class:`Kernel`: the
plain Python function until compiled code is asked for.  numba is imported only then, so
a command that needs no compiled kernel never pays for it (≈0.6 s per process: the import
and numba's target registries).  A call through :meth:`Kernel.auto` picks, for the work at
hand:

1. the compiled code when it is already in this process;
2. the plain Python original (``py_func``) when the work is small enough that Python is
   faster than loading the compiled code from the cache;
3. the compiled code from the on-disk cache when it is there;
4. the Python original when compiling would cost more than running in Python
   (the kernel's ``python_limit``), so a first run of a small program does not wait for
   a minute of LLVM (``uncached_notice`` is told, and the CLI compiles the kernels in a
   background process for the next run);
5. otherwise a compile, announced through :data:`compile_notice` (the CLI shows a
   status line on stderr; library code never prints).

Kernels call one another as module globals.  In Python mode those globals are
:class:`Kernel` objects that run their originals; when numba compiles a caller it types
them through ``_numba_type_`` as the dispatchers they stand for.
"""
from __future__ import annotations

import contextlib
import os
import threading
import time


def _default_cache_dir() -> str:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "mtwin", "numba")


os.environ.setdefault("NUMBA_CACHE_DIR", _default_cache_dir())

#: Flags shared by every kernel: cached between runs, GIL released.
JIT_OPTIONS = {"cache": True, "nogil": True}

#: Environment switch for tests and debugging: "python" runs every kernel as plain Python,
#: "compiled" never takes the Python path (the policy of earlier releases).
MODE_ENV = "MTWIN_KERNELS"


@contextlib.contextmanager
def no_notice(name: str):
    yield


def no_uncached(kernel: "Kernel") -> None:
    return None


#: ``uncached_notice(kernel)`` is called when a kernel runs as Python because its compiled
#: code is not in the cache (route 4 above).  The CLI starts a background compile there, so
#: that the next run finds the cache warm.
uncached_notice = no_uncached

#: ``compile_notice(kernel_name)`` is entered around every compile that :meth:`Kernel.auto`
#: or a direct call starts.  The CLI replaces it with a status line on stderr.
compile_notice = no_notice

# Python mode is per thread: a kernel running as plain Python calls its helper kernels
# as plain Python too, while another thread may be running compiled code.
_python = threading.local()

#: Every kernel made by :func:`njit`, by qualified name (for ``mtwin cache warm``).
REGISTRY: dict[str, "Kernel"] = {}


def _as_python_arg(a):
    """numba reads a structured-array element's fields as attributes (``r.line``); numpy
    does that on a record array view, which shares the data."""
    import numpy as np

    if isinstance(a, np.ndarray) and a.dtype.names is not None and not isinstance(a, np.recarray):
        return a.view(np.recarray)
    return a


class Kernel:
    """A numba kernel compiled on first need.

    Parameters
    ----------
    fn : function
        The kernel as plain Python (numba's ``nopython`` subset).
    python_limit : int
        Work units (the caller's measure: lines, segments, samples) up to which running
        ``fn`` in Python costs less than compiling it; 0 means always compile.
    python_fast : int
        Work units up to which Python is faster than even loading the compiled code from
        the cache.
    """

    def __init__(self, fn, python_limit: int = 0, python_fast: int = 0):
        self.py_func = fn
        self.python_limit = python_limit
        self.python_fast = python_fast
        self._dispatcher = None
        self._python_seconds = 0.0  # spent in this process running py_func through auto()
        self.__name__ = fn.__name__
        self.__qualname__ = fn.__qualname__
        self.__module__ = fn.__module__
        self.__doc__ = fn.__doc__

    def __repr__(self) -> str:
        return f"<kernel {self.__module__}.{self.__name__}>"

    @property
    def dispatcher(self):
        """numba's dispatcher for this kernel (imports numba on first use)."""
        if self._dispatcher is None:
            import numba

            self._dispatcher = numba.njit(**JIT_OPTIONS)(self.py_func)
        return self._dispatcher

    @property
    def _numba_type_(self):
        # how numba types this object when it meets it as a global in a kernel it compiles
        from numba.core import types

        return types.Dispatcher(self.dispatcher)

    def __call__(self, *args):
        if getattr(_python, "on", False):
            return self.py_func(*args)
        if os.environ.get(MODE_ENV) == "python":
            return self.run_python(*args)
        return self._compiled(args)

    def run_python(self, *args):
        """Run the plain Python original (helpers it calls run as Python too)."""
        outer = getattr(_python, "on", False)
        _python.on = True
        try:
            return self.py_func(*(_as_python_arg(a) for a in args))
        finally:
            _python.on = outer

    def auto(self, work: int, *args):
        """Run on ``args`` by the cheapest route for ``work`` units (see the module docstring)."""
        mode = os.environ.get(MODE_ENV)
        if getattr(_python, "on", False) or mode == "python":
            return self.run_python(*args)
        if mode != "compiled":
            if self._dispatcher is not None and self._signature(args) in self._dispatcher.overloads:
                return self._dispatcher(*args)
            # a process that keeps calling (a test session, an optimiser) soon spends more in
            # Python than loading or compiling would cost: then it loads or compiles
            if work <= self.python_fast and self._python_seconds < PYTHON_BUDGET_FAST:
                return self._timed_python(args)
            if (not self.load_cached(args) and work <= self.python_limit
                    and self._python_seconds < PYTHON_BUDGET_COMPILE):
                uncached_notice(self)
                return self._timed_python(args)
        return self._compiled(args)

    def _timed_python(self, args):
        t0 = time.perf_counter()
        try:
            return self.run_python(*args)
        finally:
            self._python_seconds += time.perf_counter() - t0

    def _signature(self, args):
        d = self.dispatcher
        return tuple(d.typeof_pyval(a) for a in args)

    def load_cached(self, args) -> bool:
        """Load the compiled code for ``args``' types from the on-disk cache, if it is there."""
        d = self.dispatcher
        sig = self._signature(args)
        if sig in d.overloads:
            return True
        try:
            # what numba's Dispatcher.compile does first, without its fall-back to compiling
            cres = d._cache.load_overload(sig, d.targetctx)
        except Exception:  # noqa: BLE001 - a cache we cannot read is a cache we do not have
            return False
        if cres is None:
            return False
        # as numba's own Dispatcher.compile does after a cache hit, so that a kernel compiled
        # later can call this one
        from numba.core.compiler_lock import global_compiler_lock

        with global_compiler_lock:
            d.targetctx.insert_user_function(cres.entry_point, cres.fndesc, [cres.library])
            d.add_overload(cres)
        return True

    def _compiled(self, args):
        d = self.dispatcher
        sig = self._signature(args)
        if sig in d.overloads or self.load_cached(args):
            return d(*args)
        with compile_notice(self.__name__):
            t0 = time.perf_counter()
            d.compile(sig)
            COMPILE_LOG.append((f"{self.__module__}.{self.__name__}", time.perf_counter() - t0))
        return d(*args)


#: Seconds of Python a kernel may spend in one process on small work before it loads its
#: compiled code from the cache (which costs ~0.2-0.5 s), and on work it would otherwise
#: compile for (which costs seconds to a minute).
PYTHON_BUDGET_FAST = 0.5
PYTHON_BUDGET_COMPILE = 10.0

#: (kernel, seconds) of every compile this process started through a Kernel.
COMPILE_LOG: list[tuple[str, float]] = []


def njit(fn=None, *, python_limit: int = 0, python_fast: int = 0):
    """Make ``fn`` a :class:`Kernel` with mtwin's standard JIT flags.

    ``@njit`` for helpers and kernels that always compile; ``@njit(python_limit=…,
    python_fast=…)`` for kernels that may run as Python on small work (see :class:`Kernel`).
    """
    def wrap(f):
        k = Kernel(f, python_limit, python_fast)
        REGISTRY[f"{f.__module__}.{f.__qualname__}"] = k
        return k

    return wrap(fn) if fn is not None else wrap
