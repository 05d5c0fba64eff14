"""The batch command line's arguments: programs apart from the command's own options, and those
options checked by the command's own parser before any job runs (a typo fails the batch with
exit 2, not every job with exit 1)."""
from __future__ import annotations

from ..errors import MtwinError
from ..fleet import NEEDS_MEASUREMENT, own_options


def option_arity(name: str) -> dict:
    """A command's options: flag -> whether it takes a value."""
    from . import command

    return {o: not (getattr(p, "is_flag", False) or getattr(p, "count", False))
            for p in command(name).params for o in list(p.opts) + list(p.secondary_opts) if o.startswith("-")}


def _tokens(args: list, arity: dict):
    """(flag, [the option and its value]) for each option, (None, [the argument]) for each
    other argument; ``--`` ends the options (what follows it comes as one (None, rest))."""
    k = 0
    while k < len(args):
        a = args[k]
        if a == "--":
            yield None, list(args[k + 1:])
            return
        flag = a.split("=", 1)[0] if a.startswith("-") and a != "-" else None
        n = 2 if flag and arity.get(flag) and "=" not in a else 1
        yield flag, list(args[k:k + n])
        k += n


def shared_options(name: str, opts: list, source: str) -> tuple:
    """The options of ``opts`` (``source``'s, with their values) that command ``name`` takes too."""
    known = option_arity(name)
    return tuple(t for flag, toks in _tokens(opts, option_arity(source)) if flag in known for t in toks)


def split_args(name: str, args: list[str]) -> tuple[list[str], list[str]]:
    """(the programs named, the command's options with their values) from the arguments the
    batch did not take itself."""
    takes_value = option_arity(name)
    programs, common = [], []
    for flag, toks in _tokens(args, takes_value):
        if flag is None:
            programs += toks
            continue
        if flag not in takes_value:
            import difflib

            near = difflib.get_close_matches(flag, list(takes_value), n=1)
            raise MtwinError(f"no such option: {flag}" + (f" (did you mean {near[0]}?)" if near else
                                                          f" (see mtwin {name} --help)"))
        if takes_value[flag] and len(toks) == 1 and "=" not in toks[0]:
            raise MtwinError(f"option {flag} needs a value")
        common += toks
    own_options(common, f"mtwin batch {name}")
    return programs, common


def check_common(name: str, common: list[str], where: str = "") -> None:
    """Parse the options as the command would (types, choices), on a stand-in program."""
    from . import command

    args = ["PROGRAM"] + (["MEASUREMENT"] if name in NEEDS_MEASUREMENT else []) + list(common)
    if name in ("optimize", "calibrate"):
        args += ["-o", "OUT"]
    try:
        command(name).make_context(name, args, resilient_parsing=False)
    except Exception as exc:  # noqa: BLE001 (click's usage errors, whichever click typer carries)
        if not hasattr(exc, "format_message"):
            raise
        raise MtwinError(f"{where or f'mtwin batch {name}'}: {exc.format_message()}") from None
