"""The batch command line's arguments: programs apart from the command's own options, and those
options checked by the command's own parser before any job runs (a typo fails the batch with
exit 2, not every job with exit 1)."""
from __future__ import annotations

from ..errors import MtwinError
from .manifest import NEEDS_MEASUREMENT, own_options


def split_args(name: str, args: list[str]) -> tuple[list[str], list[str]]:
    """(the programs named, the command's options with their values) from the arguments the
    batch did not take itself."""
    from .job import option_arity

    takes_value = option_arity(name)
    programs, common, k = [], [], 0
    while k < len(args):
        a = args[k]
        if a == "--":
            programs += args[k + 1:]
            break
        if a.startswith("-") and a != "-":
            flag = a.split("=", 1)[0]
            if flag not in takes_value:
                raise MtwinError(f"no such option: {flag} (mtwin {name} has no such option; see mtwin {name} --help)")
            common.append(a)
            if takes_value[flag] and "=" not in a:
                if k + 1 >= len(args):
                    raise MtwinError(f"option {flag} needs a value")
                common.append(args[k + 1])
                k += 1
        else:
            programs.append(a)
        k += 1
    own_options(common, f"mtwin batch {name}")
    return programs, common


def check_common(name: str, common: list[str], where: str = "") -> None:
    """Parse the options as the command would (types, choices), on a stand-in program."""
    from .job import click_module, command_named

    click = click_module()

    args = ["PROGRAM"] + (["MEASUREMENT"] if name in NEEDS_MEASUREMENT else []) + list(common)
    if name in ("optimize", "calibrate"):
        args += ["-o", "OUT"]
    try:
        command_named(name).make_context(name, args, resilient_parsing=False)
    except click.ClickException as exc:
        raise MtwinError(f"{where or f'mtwin batch {name}'}: {exc.format_message()}") from None
