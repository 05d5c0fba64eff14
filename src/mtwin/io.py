"""Output files are replaced atomically: written to a temporary file beside the target,
then renamed over it, so a failure never leaves a partial file behind."""
from __future__ import annotations

import contextlib
import os
import sys
import tempfile
from pathlib import Path

from .errors import MtwinError


@contextlib.contextmanager
def atomic_output(out: str | os.PathLike, binary: bool = False, inputs: tuple = (), in_place: bool = False):
    """Context manager yielding a file handle for ``out`` ("-" = stdout)."""
    out = os.fspath(out)
    if out == "-":
        fh = sys.stdout.buffer if binary else sys.stdout
        yield fh
        fh.flush()
        return
    target = Path(out)
    for src in inputs:
        if src != "-" and Path(src).exists() and target.exists() and os.path.samefile(src, target) and not in_place:
            raise MtwinError(f"refusing to overwrite the input {src} (use --in-place)")
    directory = target.parent if str(target.parent) else Path(".")
    if not directory.is_dir():
        raise MtwinError(f"output directory {directory} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=directory)
    try:
        with os.fdopen(fd, "wb" if binary else "w", **({} if binary else {"encoding": "utf-8", "newline": "\n"})) as fh:
            yield fh
        if target.exists():
            os.chmod(tmp, target.stat().st_mode & 0o777)
        else:
            os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, target)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_bytes(data: bytes, out: str, inputs: list[str] = (), in_place: bool = False) -> None:
    with atomic_output(out, binary=True, inputs=tuple(inputs), in_place=in_place) as fh:
        fh.write(data)
