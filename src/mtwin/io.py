"""The one door for the files a user names.

Outputs are replaced atomically: written to a temporary file beside the target, then renamed
over it, so a failure never leaves a partial file behind.  An output is never one of the
command's inputs (by path, link or inode: every input a reader checked in the command's
``command_scope`` counts, the twin file and the files it names included), never a symbolic
link (the rename would replace the link), and a device or FIFO (``/dev/null``) is written
through rather than replaced.

Inputs (``check_input``, ``read_input``) are regular files only — a device, FIFO or directory
is refused before a byte is read, so nothing reads ``/dev/zero`` to the end — each kind with
a size limit (``INPUT_LIMITS``, MB; ``MTWIN_MAX_<KIND>_MB`` in the environment raises one).
"""
from __future__ import annotations

import contextlib
import os
import signal
import stat
import sys
import tempfile
from pathlib import Path

from .errors import MtwinError

#: the largest file of each kind a reader takes, MB (docs/conventions.md); the environment's
#: MTWIN_MAX_<KIND>_MB stands over it
INPUT_LIMITS = {"program": 512, "twin": 8, "measurement": 4096, "log": 4096, "manifest": 64, "frf": 64,
                "spectrum": 256, "effects": 8, "cycle": 8}

# the (device, inode) of every input checked in the running command (None: no command runs)
_inputs: set | None = None


@contextlib.contextmanager
def command_scope():
    """The inputs a command reads, gathered while it runs, so its outputs can refuse them."""
    global _inputs
    outer = _inputs
    _inputs = set()
    try:
        yield
    finally:
        _inputs = outer


def input_limit(kind: str) -> int:
    """Bytes a reader of ``kind`` takes at most."""
    env = os.environ.get(f"MTWIN_MAX_{kind.upper()}_MB")
    try:
        mb = float(env) if env else INPUT_LIMITS[kind]
    except ValueError:
        raise MtwinError(f"MTWIN_MAX_{kind.upper()}_MB={env!r}: expected a number of MB") from None
    return int(mb * 1024 * 1024)


def check_input(path, kind: str) -> int:
    """A file a user named, before it is read: a regular file within ``kind``'s size limit;
    remembered as an input of the running command.  Returns its size in bytes."""
    path = os.fspath(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise MtwinError(f"cannot read {path}: no such file") from None
    except OSError as exc:
        raise MtwinError(f"cannot read {path}: {exc.strerror}") from None
    if not stat.S_ISREG(st.st_mode):
        what = "a directory" if stat.S_ISDIR(st.st_mode) else "a FIFO" if stat.S_ISFIFO(st.st_mode) else \
            "a device" if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode) else "not a regular file"
        raise MtwinError(f"{path}: {what}: a {kind} is read from a regular file ('-' for stdin where the command "
                         f"takes it)")
    limit = input_limit(kind)
    if st.st_size > limit:
        raise MtwinError(f"{path}: {st.st_size / 1048576:.0f} MB, over the {limit / 1048576:.0f} MB a {kind} may have "
                         f"(MTWIN_MAX_{kind.upper()}_MB raises it)")
    if _inputs is not None:
        _inputs.add((st.st_dev, st.st_ino))
    return st.st_size


def read_input(path, kind: str) -> bytes:
    """The bytes of a file a user named (see ``check_input``); '-' reads stdin, within the same
    limit."""
    path = os.fspath(path)
    limit = input_limit(kind)
    try:
        if path == "-":
            data = _read_within(sys.stdin.buffer, limit)
        else:
            check_input(path, kind)
            with open(path, "rb") as fh:
                data = _read_within(fh, limit)  # (a file that grows while it is read stops at the limit too)
    except MemoryError:
        raise MtwinError(f"{path}: not enough memory to read it (a {kind} may have {limit / 1048576:.0f} MB; "
                         f"MTWIN_MAX_{kind.upper()}_MB lowers it)") from None
    if len(data) > limit:
        raise MtwinError(f"{path}: over the {limit / 1048576:.0f} MB a {kind} may have "
                         f"(MTWIN_MAX_{kind.upper()}_MB raises it)")
    return data


def _read_within(fh, limit: int) -> bytes:
    """At most ``limit`` + 1 bytes of ``fh``, read in 1-MB pieces: what it holds, not the limit,
    is what it takes in memory (``read(limit + 1)`` reserves the whole limit at once)."""
    buf = bytearray()
    while len(buf) <= limit:
        chunk = fh.read(min(1 << 20, limit + 1 - len(buf)))
        if not chunk:
            break
        buf += chunk
    return bytes(buf)


@contextlib.contextmanager
def atomic_output(out: str | os.PathLike, binary: bool = False, inputs: tuple = (), in_place: bool | None = None):
    """Context manager yielding a file handle for ``out`` ("-" = stdout).  ``in_place``: may ``out``
    be one of the ``inputs`` (None: the command has no ``--in-place``, so no message offers it)."""
    out = os.fspath(out)
    if out == "-":
        fh = sys.stdout.buffer if binary else sys.stdout
        yield fh
        try:
            fh.flush()
        except OSError as exc:
            raise MtwinError(f"cannot write to stdout: {exc.strerror}") from None
        return
    target = Path(out)
    named = False
    for src in inputs:
        if src != "-" and Path(src).exists() and target.exists() and os.path.samefile(src, target):
            if not in_place:
                raise MtwinError(f"refusing to overwrite the input {src}" +
                                 (" (use --in-place)" if in_place is not None else ": name another output file"))
            named = True
    try:
        lst = os.lstat(target)
    except OSError:
        lst = None
    if lst is not None:
        if stat.S_ISLNK(lst.st_mode):
            raise MtwinError(f"{out} is a symbolic link: writing the output would replace the link; name the file "
                             f"it points to ({os.path.realpath(out)})")
        if _inputs is not None and (lst.st_dev, lst.st_ino) in _inputs and not named:
            raise MtwinError(f"refusing to overwrite {out}: the command reads it as an input")
        if stat.S_ISCHR(lst.st_mode) or stat.S_ISFIFO(lst.st_mode):
            yield from _write_through(out, binary)  # (/dev/null, a pipe: written, never replaced)
            return
        if not stat.S_ISREG(lst.st_mode):
            raise MtwinError(f"{out} is not a regular file: give a file name")
    directory = target.parent if str(target.parent) else Path(".")
    if not directory.is_dir():
        raise MtwinError(f"output directory {directory} does not exist")
    # the signals that end a run are held while the temporary file is made, and let through
    # inside the try that removes it: one arriving in between would leave the file behind
    held = _hold_signals()
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=directory)
    except OSError as exc:
        _release_signals(held)
        raise MtwinError(f"{out}: cannot write in {directory}: {exc.strerror}") from None
    try:
        _release_signals(held)
        with os.fdopen(fd, "wb" if binary else "w", **({} if binary else {"encoding": "utf-8", "newline": "\n"})) as fh:
            yield fh
        if target.exists():
            os.chmod(tmp, target.stat().st_mode & 0o777)
        else:
            os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, target)
    except OSError as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise MtwinError(f"{out}: cannot write it: {exc.strerror}") from None
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _write_through(out: str, binary: bool):
    try:
        with open(out, "wb" if binary else "w", **({} if binary else {"encoding": "utf-8", "newline": "\n"})) as fh:
            yield fh
    except OSError as exc:
        raise MtwinError(f"{out}: cannot write it: {exc.strerror}") from None


def _hold_signals():
    """Block SIGINT, SIGTERM and SIGHUP (where the platform can): the mask to restore."""
    if not hasattr(signal, "pthread_sigmask"):
        return None
    sigs = {getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n)}
    return signal.pthread_sigmask(signal.SIG_BLOCK, sigs)


def _release_signals(mask) -> None:
    if mask is not None:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_bytes(data: bytes, out: str, inputs: list[str] = (), in_place: bool | None = None) -> None:
    with atomic_output(out, binary=True, inputs=tuple(inputs), in_place=in_place) as fh:
        fh.write(data)
