"""Writing a calibrated twin file, with its model journal.

The twin file keeps everything it had; its ``[effects.NAME]`` tables are written anew (the
twin's effects, with the calibrated values) and a ``[[journal]]`` entry is appended for each
calibration: the effects fitted, the values with their uncertainty, the measurement, and
the RMS error per signal before and after — so ``mtwin journal FILE`` shows the error
falling across iterations.
"""
from __future__ import annotations

import datetime as _dt
import re

from ..errors import ConfigError
from ..tomlwrite import dump_tables, inline_table, toml_value


def _strip_effects_and_journal(text: str) -> str:
    """The file without its [effects.*] tables and [[journal]] entries (re-written after)."""
    out, skip = [], False
    for line in text.splitlines():
        s = line.strip()
        if s.startswith("["):
            skip = bool(re.match(r"^\[\s*effects\s*[.\]]", s) or re.match(r"^\[\[\s*journal\s*\]\]", s))
        if not skip:
            out.append(line)
    while out and not out[-1].strip():
        out.pop()
    return "\n".join(out)


def _leading_comments(text: str) -> str:
    out = []
    for line in text.splitlines():
        if line.strip().startswith("#") or (out and not line.strip()):
            out.append(line)
        else:
            break
    while out and not out[-1].strip():
        out.pop()
    return "\n".join(out)


def read_journal(path: str) -> list[dict]:
    from ..config import read_twin_toml

    raw = read_twin_toml(path)
    j = raw.get("journal", [])
    if not isinstance(j, list):
        raise ConfigError(f"{path}: journal must be an array of tables ([[journal]])")
    return j


def with_base_values(source_text: str, values: dict, twin) -> str:
    """The twin file's text with fitted base parameters written into its sections: machine
    parameters by their dotted names, ``cutting.<material>.<coef>`` as a ``[materials.<name>]``
    table holding all six coefficients, ``tools.<n>.<field>`` into ``[tools.<n>]``.  The file is
    written back from its parsed form (its comments are not kept)."""
    from ..config import tomllib

    doc = tomllib.loads(source_text) if source_text.strip() else {}
    doc.pop("effects", None)
    doc.pop("journal", None)
    for name, v in values.items():
        parts = name.split(".")
        if parts[0] == "cutting":
            mat = twin.cutting.material
            table = doc.setdefault("materials", {}).setdefault(parts[1], {})
            for f in ("ktc", "krc", "kac", "kte", "kre", "kae"):
                table.setdefault(f, float(getattr(mat, f)))
            table[parts[2]] = float(v)
            doc.setdefault("cutting", {})["material"] = parts[1]
            continue
        if len(parts) == 6 and parts[0] == "tools" and parts[2] == "modes":
            # tools.N.modes.D.J.P: the J-th [[tools.N.modes]] entry of direction D
            entries = [e for e in doc["tools"][parts[1]]["modes"] if e.get("direction") == parts[3]]
            entry = entries[int(parts[4])]
            if parts[5] == "k":
                entry.pop("m", None)
            entry[parts[5]] = float(v)
            continue
        node = doc
        for p in parts[:-1]:
            node = node.setdefault(p, {})
        node[parts[-1]] = float(v)
    return "\n".join(dump_tables(doc)).rstrip() + "\n"


def calibrated_text(source_text: str, effects, entry: dict, previous: list[dict], base: dict | None = None,
                    twin=None) -> str:
    """The twin file's new text: its own sections (with fitted ``base`` parameter values), the
    effects, the journal with ``entry``."""
    head = _leading_comments(source_text)
    if base:
        source_text = with_base_values(source_text, base, twin)
        if head:  # the file's opening comment block (how it was made) survives the rewrite
            source_text = head + "\n\n" + source_text
    parts = [_strip_effects_and_journal(source_text)] if source_text.strip() else []
    for e in effects:
        values = e.resolved()
        lines = [f"[effects.{e.name}]"] + [f"{k} = {toml_value(v)}" for k, v in values.items()]
        if getattr(e, "run_property", False):
            # (a value of the run it was fitted to — an operator's override — not of the machine)
            lines.insert(0, f"# {e.name}: an effective value of the run it was fitted to, not a machine property: "
                            f"remove it before predicting another run")
        parts.append("\n".join(lines))
    for j in list(previous) + [entry]:
        lines = ["[[journal]]"]
        for k, v in j.items():
            lines.append(f"{k} = {inline_table(v) if isinstance(v, dict) else toml_value(v)}")
        parts.append("\n".join(lines))
    return "\n\n".join(p for p in parts if p) + "\n"


def _journal_date() -> str:
    """Now, UTC — or the reproducible-builds convention's ``SOURCE_DATE_EPOCH`` where it is set
    (a batch sets its start, so a calibrated twin file is the same bytes as the command run
    alone with the same epoch)."""
    import os

    epoch = os.environ.get("SOURCE_DATE_EPOCH", "").strip()
    when = (_dt.datetime.fromtimestamp(int(epoch), _dt.timezone.utc) if epoch.isdigit()
            else _dt.datetime.now(_dt.timezone.utc))
    return when.strftime("%Y-%m-%dT%H:%M:%SZ")


def journal_entry(iteration: int, measurement: str, fit, validation: dict | None = None,
                  notes: list | None = None) -> dict:
    e = {"iteration": iteration, "date": _journal_date(),
         "measurement": measurement, "effects": [x.name for x in fit.effects],
         "params": {k: v for k, v in fit.params.items()},
         "uncertainty": {k: (v if v is not None else float("nan")) for k, v in fit.uncertainty.items()},
         "rms_before": fit.rms_before, "rms_after": fit.rms_after, "noise": fit.noise}
    if getattr(fit, "before", None) is not None:  # a timing fit: the cycle times too
        e["objective"] = "timing"
        e["cycle_error_before"] = {c["measurement"]: c["cycle_error"] for c in fit.before["cases"]}
        e["cycle_error_after"] = {c["measurement"]: c["cycle_error"] for c in fit.after["cases"]}
        e["block_rms_before"] = fit.before["rms"]  # per logged block group
        e["block_rms_after"] = fit.after["rms"]
    if getattr(fit, "not_identifiable", None):  # left at their starts: the signals cannot see them
        e["not_identifiable"] = list(fit.not_identifiable)
    if getattr(fit, "unreached", None):  # limits no logged block reaches: set at the least the logs allow
        e["unreached"] = list(fit.unreached)
    if validation:
        e["validation"] = validation
    if notes:
        e["notes"] = list(notes)
    return e
