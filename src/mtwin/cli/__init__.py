"""The ``mtwin`` command line: commands over the use-case API (``mtwin.api``).

Data goes to stdout (``--json``, CSV, rewritten programs with ``-o -``); everything else —
tables, progress, warnings, errors — to stderr.  Exit codes: 0 ok, 1 a check failed
(``verify`` found a difference), 2 bad input or usage, 3 an internal error (run with
``--traceback`` and report it), 130 interrupted.

The package: ``app`` (the application, error mapping, compile notices), ``options`` (option
groups declared once: the twin, the measurement reading), ``argtypes`` (ranges, grids, lists,
output checks), ``render`` (the JSON emitter, messages), and one module per command family.
A command parses its options, calls one library function and renders its result; it never
builds a twin itself and imports nothing private from the library (tests/test_architecture.py).
Heavy modules are imported inside the commands, so that ``mtwin --help`` answers at once.
"""
from __future__ import annotations

import contextlib
import sys

# (imported in the order their commands are listed in --help)
from . import program, simulate, optimize, batch, loop, chatter, tools, admin, grind  # noqa: F401,I001  (register their commands)
from .app import app, err, interrupted, state

__all__ = ["app", "main", "run_command"]

_CLICK = {}


def command(name: str = ""):
    """The click command of ``mtwin NAME`` (the whole application for "")."""
    if "app" not in _CLICK:
        import typer

        _CLICK["app"] = typer.main.get_command(app)
    return _CLICK["app"].get_command(None, name) if name else _CLICK["app"]


def run_command(args: list) -> tuple:
    """``mtwin ARGS…`` in this process, as from a shell: (exit code, stdout, stderr) — what a
    batch job runs (mtwin.fleet), so that its outputs are the command's own."""
    import contextlib
    import io

    so, se = io.StringIO(), io.StringIO()
    traceback = state["traceback"]
    state["traceback"] = False  # (the batch's --traceback is the batch's, not every job's)
    with contextlib.redirect_stdout(so), contextlib.redirect_stderr(se):
        try:
            code = command().main(args=[str(a) for a in args], prog_name="mtwin", standalone_mode=False)
        except Exception as exc:  # noqa: BLE001 (click's usage errors; the command's own are mapped by it)
            if not hasattr(exc, "format_message"):
                raise
            se.write(f"error: {exc.format_message()}\n")  # a usage error: an unknown option, a bad value
            code = getattr(exc, "exit_code", 2)
        finally:
            state["traceback"] = traceback
    return int(code or 0), so.getvalue(), se.getvalue()


def main() -> None:
    # --traceback is a debugging switch a user adds at the end of a failing command line:
    # accept it anywhere, not only before the command as click would
    if "--traceback" in sys.argv[1:]:
        state["traceback"] = True
        sys.argv = [a for a in sys.argv if a != "--traceback"]
    import signal

    def _terminated(signum, frame):
        # SIGTERM (a job's end) and SIGHUP (the terminal closed) unwind like Ctrl-C: every
        # output's temporary file is removed on the way out; the message names the signal
        state["signal"] = "SIGTERM" if signum == signal.SIGTERM else "SIGHUP, the terminal closed"
        raise KeyboardInterrupt

    with contextlib.suppress(ValueError):  # (not in the main thread: an embedding program's business)
        signal.signal(signal.SIGTERM, _terminated)
        if hasattr(signal, "SIGHUP") and signal.getsignal(signal.SIGHUP) is not signal.SIG_IGN:
            signal.signal(signal.SIGHUP, _terminated)  # (left ignored under nohup)
    try:
        app()
    except KeyboardInterrupt:  # pragma: no cover (an interrupt before a command started)
        err.print(interrupted(), highlight=False)
        sys.exit(130)
