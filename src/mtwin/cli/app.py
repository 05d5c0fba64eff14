"""The ``mtwin`` application object and what every command shares: the stderr console, the
mapping of errors to messages and exit codes, Ctrl-C, and the kernel-compile notices.

The command modules import it and not one another; ``cli/__init__`` imports them all, which
registers their commands on :data:`app`."""
from __future__ import annotations

import contextlib
import functools
import os
import sys

import typer
from rich.console import Console

from ..errors import MtwinError


def _conventional_help() -> None:
    """Usage lines as Unix tools write them (``mtwin scale [OPTIONS] PART``, ``--feed FLOAT``)
    rather than this typer release's ``{part}`` and ``<float>``, which read as literal text."""
    try:
        from typer import core

        def usage_name(self) -> str:
            name = self.display_name_raw.upper()
            return name if self.required else f"[{name}]"

        plain = core.TyperArgument.display_type

        def display_type(self, ctx) -> str:
            s = plain(self, ctx)
            if isinstance(self, core.TyperArgument):
                return ""
            return s[1:-1].upper() if s.startswith("<") and s.endswith(">") else s

        core.TyperArgument._usage_display_name = usage_name
        for cls in (core.TyperArgument, core.TyperOption):
            cls.display_type = display_type
    except (ImportError, AttributeError):  # another typer release: its own style stays
        pass


_conventional_help()

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    # Plain click help: rendering help through rich costs ~80 ms of imports
    # (rich.markdown, typer.rich_utils), which would put `mtwin --help` over
    # its 0.3 s budget. Our own messages still go through rich on stderr.
    rich_markup_mode=None,
    help="mtwin: G-code optimiser built on a digital twin of a CNC machine tool.",
    context_settings={"help_option_names": ["-h", "--help"]},
)
# piped or redirected (a CI log, a file), rich would cut tables at 80 columns, breaking file
# names mid-word: there the width is the content's (up to a generous bound)
err = Console(stderr=True, highlight=False, width=None if sys.stderr.isatty() else 240)
EXIT_INTERNAL = 3

state = {"traceback": False, "signal": "Ctrl-C"}  # (the signal that interrupts a run: its name)


def _version(value: bool):
    if value:
        from ..version import __version__

        sys.stdout.write(f"mtwin {__version__}\n")
        raise typer.Exit(0)


@app.callback()
def _options(traceback: bool = typer.Option(False, "--traceback",
                                         help="Show Python tracebacks on errors (also after the command)."),
          version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                       help="Print the version and exit.")):
    state["traceback"] = state["traceback"] or traceback
    install_compile_notice()


def install_compile_notice() -> None:
    """Say on stderr, once per process, that kernels are being compiled, with a live line per
    kernel on a terminal: a first run compiles what it needs (seconds), later runs load it."""
    import time

    from ..warmup import set_notices

    said = {"n": 0, "t": 0.0}

    @contextlib.contextmanager
    def notice(name: str):
        if said["n"] == 0:
            err.print("compiling the twin's kernels, first run only "
                      f"(cached in {os.environ.get('NUMBA_CACHE_DIR')}) …", soft_wrap=True)
        said["n"] += 1
        t0 = time.perf_counter()
        if err.is_terminal:
            with err.status(f"compiling kernel {said['n']}: {name} …"):
                yield
        else:
            yield
        dt = time.perf_counter() - t0
        said["t"] += dt
        if err.is_terminal or dt > 1.0:
            err.print(f"  compiled {name} in {dt:.1f} s", soft_wrap=True)

    def uncached(kernel) -> None:
        # once per process: a kernel ran as Python because the cache lacks it
        if said.get("bg") is None:
            from ..warmup import start_background

            said["bg"] = start_background()
            if said["bg"]:
                err.print("compiling the twin's kernels in the background for the next runs "
                          f"(first run only; cached in {os.environ.get('NUMBA_CACHE_DIR')})", soft_wrap=True)

    set_notices(notice, uncached)


def fail(exc: BaseException) -> None:
    if state["traceback"]:
        import traceback as tb

        tb.print_exception(exc)
        if isinstance(exc, MtwinError):
            raise typer.Exit(exc.exit_code)
        raise typer.Exit(EXIT_INTERNAL)
    if isinstance(exc, MtwinError):
        from rich.markup import escape

        err.print(f"[red]error:[/red] {escape(str(exc))}", markup=True, soft_wrap=True)
        raise typer.Exit(exc.exit_code)
    from rich.markup import escape

    err.print(f"[red]internal error:[/red] {type(exc).__name__}: {escape(str(exc))} (run with --traceback and report it)")
    raise typer.Exit(EXIT_INTERNAL)


def interrupted() -> str:
    """What an interrupted run says: by which signal, and that no output is left half-written."""
    return (f"interrupted ({state['signal']}): no output is left half-written (an output not yet complete was not "
            "written; one written before the interrupt is whole)")


@contextlib.contextmanager
def _numeric_warnings():
    """numpy's RuntimeWarnings (a division by zero, an overflow inside a computation) are not a
    user's business in numpy's words, nor silence: each distinct one becomes one note naming
    where it arose, after the command (every figure mtwin prints is checked finite, so the note
    is for the developers).  Other warnings pass through as they are."""
    import warnings

    seen: dict = {}
    with warnings.catch_warnings():
        warnings.simplefilter("always", RuntimeWarning)  # (each counted; none printed as numpy words it)
        shown = warnings.showwarning

        def collect(message, category, filename, lineno, file=None, line=None):
            if issubclass(category, RuntimeWarning):
                key = (str(message), f"{os.path.basename(filename)}:{lineno}")
                seen[key] = seen.get(key, 0) + 1
            else:
                shown(message, category, filename, lineno, file, line)

        warnings.showwarning = collect
        try:
            yield
        finally:
            warnings.showwarning = shown
            for (msg, where), n in list(seen.items())[:3]:
                err.print(f"note: a numerical warning inside mtwin ({msg}, at {where}{f', {n} times' if n > 1 else ''}); "
                          f"the figures it printed are checked finite — please report it", highlight=False)


def reports_errors(command):
    """Turn every exception of a command into a message and an exit code (see ``fail``)."""

    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        from ..io import command_scope

        try:
            with command_scope(), _numeric_warnings():  # (the inputs it reads, so that no output replaces one)
                return command(*args, **kwargs)
        except typer.Exit:
            raise
        except KeyboardInterrupt:
            # every output is written atomically: an interrupted run leaves none half-written
            err.print(interrupted(), highlight=False)
            state["signal"] = "Ctrl-C"  # (a command run again in this process starts afresh)
            raise typer.Exit(130) from None
        except Exception as exc:  # noqa: BLE001 - every error becomes a message and an exit code
            fail(exc)

    return wrapper
