"""The one place where numba is configured.

``NUMBA_CACHE_DIR`` must be set before numba is imported so that compiled kernels
are cached in a user-writable directory even when the package itself is installed
read-only.  Every kernel module imports ``njit`` from here, never numba directly,
so JIT flags live in one place.
"""
from __future__ import annotations

import os


def _default_cache_dir() -> str:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "mtwin", "numba")


os.environ.setdefault("NUMBA_CACHE_DIR", _default_cache_dir())

import numba  # noqa: E402  (must follow the environment set-up above)

#: Flags shared by every kernel: cached between runs, GIL released.
JIT_OPTIONS = {"cache": True, "nogil": True}


def njit(fn):
    """Compile ``fn`` with mtwin's standard JIT flags."""
    return numba.njit(**JIT_OPTIONS)(fn)
