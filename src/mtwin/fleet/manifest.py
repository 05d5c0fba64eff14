"""What a batch runs: jobs from a manifest (CSV or TOML) or from programs × twin files.

A job is one command line of mtwin (``optimize``, ``simulate``, ``compare``, ``calibrate``)
on one program and one twin file.  Its paths are kept as the user wrote them, relative to
``base`` (the manifest's folder, or the working directory for programs named on the
command line): the job runs with ``base`` as its working directory, so that what its outputs
name (the program in a report, the measurement in a journal entry) is what the same command
run alone from there would name — the outputs are the same bytes.

Every check is made before any job runs: a missing file, a duplicate job, an unknown column,
an option a job may not set — ``manifest:line:col:`` where it applies, exit 2, nothing
written.
"""
from __future__ import annotations

import csv
import glob
import os
import re
import shlex
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

from ..errors import MtwinError, SourceLocation

COMMANDS = ("optimize", "simulate", "compare", "calibrate")
COLUMNS = ("program", "twin", "measurement", "options", "name", "holdout")
YES = ("yes", "true", "1", "y")
NO = ("", "no", "false", "0", "n")
# names a job's folder may not take: the summary's files
RESERVED = ("index.html", "summary.csv", "summary.json", "parameters.csv")
NEEDS_MEASUREMENT = ("compare", "calibrate")
PROGRAM_SUFFIXES = (".nc", ".ngc", ".tap", ".gcode", ".gc", ".cnc", ".txt", ".mpf", ".eia", ".min")
# options a job may not set: the batch decides where outputs go and reads the JSON itself
OWN_OPTIONS = ("-o", "--output", "--report", "--json", "--plot", "--stock-out", "--in-place", "--record",
               "--traceback", "--twin")
# options naming files a job would read or write outside its inputs: they do not travel with
# the task, and a ledger written by every job at once would be a shared mutable file
FILE_OPTIONS = {"--effect-file": "put the effect in a package (entry point mtwin.effects) installed on the workers",
                "--ledger": "a batch does not read or write a tool ledger", "--tool-id": "it belongs to --ledger",
                "--validate": "batch calibrate holds rows out with the manifest's holdout column"}


class ManifestError(MtwinError):
    """A manifest or job list that cannot be run, with where."""

    def __init__(self, message: str, location: Optional[SourceLocation] = None):
        super().__init__(f"{location}: {message}" if location else message)


@dataclass(frozen=True)
class Job:
    """One command on one program and twin file; paths as written, relative to ``base``."""

    name: str
    command: str
    program: str
    twin: Optional[str] = None  # None: the default machine
    measurement: Optional[str] = None
    options: tuple = ()  # the job's own flags, after the batch's common ones
    base: str = "."  # absolute folder the relative paths are read from (the job's working directory)
    origin: str = ""  # manifest:line, for messages
    # calibrate: more (program, measurement) pairs fitted together; pairs held out (the
    # calibrated twin compared with them after the fit); the procedure's steps (each one's
    # options; each step starts from the twin file the one before wrote)
    pairs: tuple = ()
    holdout: tuple = ()
    steps: tuple = ()
    compare_options: tuple = ()  # the options of the batch that the held-out comparisons take
    date_epoch: Optional[int] = None  # the batch's start: the date of a calibrated twin file's journal entry

    @property
    def machine(self) -> str:
        """The twin file's name: what the fleet figures are grouped by."""
        return Path(self.twin).stem if self.twin else "default"

    def files(self) -> list[str]:
        """The input files the job reads (travel with the task)."""
        more = [p for pair in self.pairs + self.holdout for p in pair]
        return list(dict.fromkeys(p for p in (self.program, self.twin, self.measurement, *more) if p))

    def key(self) -> tuple:
        res = (lambda p: os.path.normpath(os.path.join(self.base, p)) if p else None)
        return (res(self.program), res(self.twin), res(self.measurement), self.options,
                tuple((res(a), res(b)) for a, b in self.pairs))


def read_manifest(path: str, command: str) -> list[Job]:
    """The jobs of a manifest: CSV with a header row, or TOML with ``[[job]]`` tables."""
    p = Path(path)
    try:
        from ..io import check_input

        check_input(path, "manifest")
        text = p.read_text(encoding="utf-8-sig")  # (a byte-order mark, as spreadsheets write it)
    except OSError as exc:
        raise ManifestError(f"cannot read the manifest {path}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise ManifestError(f"{path}: the manifest is not UTF-8 text") from None
    base = str(p.resolve().parent)
    rows = _toml_rows(path, text) if p.suffix.lower() == ".toml" else _csv_rows(path, text)
    if not rows:
        raise ManifestError(f"{path}: the manifest lists no job")
    jobs = [_job(command, row, base, where) for row, where in rows]
    if command == "calibrate":
        jobs = _machines(jobs, [row for row, _ in rows])
    return check_jobs(jobs)


def _machines(jobs: list[Job], rows: list) -> list[Job]:
    """calibrate: the rows of one name are one machine's job — its pairs fitted together (the
    first row's twin file and options), its ``holdout`` rows compared after the fit."""
    from dataclasses import replace

    out: dict = {}
    for j, row in zip(jobs, rows):
        held = row.get("holdout", ("", 1))[0].strip().lower() in YES
        key = j.name or f"#{len(out)}"
        if key not in out:
            if held:
                raise ManifestError(f"{j.origin}: a held-out row of {j.name or 'a job'!r} before any row fitted for "
                                    f"it (list a machine's fitted rows first)")
            out[key] = j
            continue
        first = out[key]
        if (j.twin, j.options) != (first.twin, first.options):
            raise ManifestError(f"{j.origin}: the rows of {j.name!r} differ in twin file or options from "
                                f"{first.origin} (one machine, one twin file and one set of options)")
        pair = ((j.program, j.measurement),)
        out[key] = replace(first, holdout=first.holdout + pair) if held else replace(first, pairs=first.pairs + pair)
    return list(out.values())


def _csv_rows(path: str, text: str) -> list:
    reader = csv.reader(text.splitlines())
    try:
        lines = [ln for ln in reader]
    except csv.Error as exc:
        raise MtwinError(f"{path}:{reader.line_num}:1: not a CSV row: {exc}") from None
    head_at = next((i for i, ln in enumerate(lines) if ln and not ln[0].lstrip().startswith("#")), None)
    if head_at is None:
        return []
    raw_head = list(lines[head_at])
    while raw_head and not raw_head[-1].strip():  # (a trailing comma, as spreadsheets write it)
        raw_head.pop()
    head = [h.strip().lower() for h in raw_head]
    col = 1
    for h, raw in zip(head, raw_head):
        if h not in COLUMNS:
            raise ManifestError(f"unknown column {raw.strip()!r} (known: {', '.join(COLUMNS)})",
                                SourceLocation(path, head_at + 1, col))
        col += len(raw) + 1
    if "program" not in head:
        raise ManifestError("the header names no 'program' column", SourceLocation(path, head_at + 1, 1))
    if len(set(head)) < len(head):
        raise ManifestError("a column is named twice", SourceLocation(path, head_at + 1, 1))
    rows = []
    for i, ln in enumerate(lines[head_at + 1:], start=head_at + 2):
        if not any(c.strip() for c in ln) or ln[0].lstrip().startswith("#"):
            continue
        while len(ln) > len(head) and not ln[-1].strip():
            ln = ln[:-1]
        if len(ln) > len(head):
            raise ManifestError(f"{len(ln)} fields, the header has {len(head)}", SourceLocation(path, i, 1))
        cols, at = {}, 1
        for h, v in zip(head, ln):
            cols[h] = (v.strip(), at)
            at += len(v) + 1
        rows.append((cols, (path, i)))
    return rows


def _toml_rows(path: str, text: str) -> list:
    from ..config import tomllib

    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ManifestError(f"{path}: invalid TOML: {exc}") from None
    unknown = [k for k in doc if k != "job"]
    if unknown:
        raise ManifestError(f"{path}: unknown key {unknown[0]!r} (a manifest is [[job]] tables)")
    jobs = doc.get("job", [])
    if not (isinstance(jobs, list) and all(isinstance(j, dict) for j in jobs)):
        raise ManifestError(f"{path}: 'job' must be an array of tables ([[job]])")
    rows = []
    for k, j in enumerate(jobs, start=1):
        for key in j:
            if key not in COLUMNS:
                raise ManifestError(f"{path}: job {k}: unknown key {key!r} (known: {', '.join(COLUMNS)})")
        opts = j.get("options", "")
        if isinstance(opts, list) and all(isinstance(o, str) for o in opts):
            opts = shlex.join(opts)
        cols = {}
        for key, v in {**j, "options": opts}.items():
            if key == "holdout" and isinstance(v, bool):
                v = "yes" if v else ""
            if not isinstance(v, str):
                raise ManifestError(f"{path}: job {k}: {key} must be a string")
            cols[key] = (v, 1)
        rows.append((cols, (path, f"job {k}")))
    return rows


def _job(command: str, cols: dict, base: str, where) -> Job:
    path, line = where
    loc = (lambda c: SourceLocation(path, line, cols[c][1])) if isinstance(line, int) else (lambda _: None)
    pre = "" if isinstance(line, int) else f"{path}: {line}: "
    val = (lambda c: cols.get(c, ("", 1))[0] or None)
    if not val("program"):
        raise ManifestError(f"{pre}no program", loc("program") if "program" in cols else None)
    for c in ("program", "twin", "measurement"):
        v = val(c)
        if v and c == "twin" and not v.lower().endswith(".toml"):
            raise ManifestError(f"{pre}twin {v!r}: a twin file is TOML (.toml)", loc(c))
        if v and not os.path.isfile(os.path.join(base, v)):
            raise ManifestError(f"{pre}{c} {v!r} does not exist (relative paths are read from {base})", loc(c))
    if val("holdout") and command != "calibrate":
        raise ManifestError(f"{pre}'holdout' marks a calibration's held-out logs (batch calibrate)", loc("holdout"))
    if (val("holdout") or "").lower() not in YES + NO:
        raise ManifestError(f"{pre}holdout {val('holdout')!r}: yes or no", loc("holdout"))
    if val("measurement") and command not in NEEDS_MEASUREMENT:
        raise ManifestError(f"{pre}batch {command} takes no measurement (compare and calibrate do)",
                            loc("measurement"))
    if command in NEEDS_MEASUREMENT and not val("measurement"):
        raise ManifestError(f"{pre}batch {command} needs a 'measurement' for every job",
                            loc("program"))
    try:
        opts = tuple(shlex.split(val("options") or ""))
    except ValueError as exc:
        raise ManifestError(f"{pre}options: {exc}", loc("options")) from None
    own_options(opts, f"{pre}options", loc("options") if "options" in cols else None)
    origin = f"{path}:{line}" if isinstance(line, int) else f"{path} {line}"
    if val("name") and (val("name").lower() in RESERVED):
        raise ManifestError(f"{pre}the name {val('name')!r} is the summary's file", loc("name"))
    return Job(val("name") or "", command, val("program"), val("twin"), val("measurement"), opts, base, origin)


def own_options(opts, what: str, loc=None) -> None:
    """Refuse the options the batch sets itself (where outputs go, --json)."""
    for o in opts:
        flag = o.split("=", 1)[0]
        if flag in OWN_OPTIONS:
            raise ManifestError(f"{what}: {flag} is the batch's to set (outputs go to each job's folder; "
                                f"the twin file is the 'twin' column)", loc)
        if flag in FILE_OPTIONS:
            raise ManifestError(f"{what}: {flag} names a file that does not travel with a job: "
                                f"{FILE_OPTIONS[flag]}", loc)


def jobs_from_paths(command: str, programs: list[str], twins: list[str], measurements: list[str]) -> list[Job]:
    """Programs (files, folders, glob patterns) × twin files (none: the default machine);
    compare and calibrate take one measurement per program, in order."""
    found = []
    for p in programs:
        if os.path.isdir(p):
            found += sorted(str(Path(p) / f) for f in os.listdir(p) if f.lower().endswith(PROGRAM_SUFFIXES)
                            and os.path.isfile(os.path.join(p, f)))
        elif any(ch in p for ch in "*?["):
            hits = sorted(glob.glob(p))
            if not hits:
                raise ManifestError(f"{p}: the pattern matches no file")
            found += hits
        elif os.path.isfile(p):
            found.append(p)
        else:
            raise ManifestError(f"{p}: no such program file or folder")
    if not found:
        raise ManifestError("no program to run: name files, folders or patterns, or give --manifest")
    for t in twins:
        if not os.path.isfile(t):
            raise ManifestError(f"--twin {t}: no such twin file")
        if not t.lower().endswith(".toml"):
            raise ManifestError(f"--twin {t}: a twin file is TOML (.toml)")
    if measurements and command not in NEEDS_MEASUREMENT:
        raise ManifestError(f"batch {command} takes no --measurement (compare and calibrate do)")
    if command in NEEDS_MEASUREMENT and len(measurements) != len(found):
        raise ManifestError(f"batch {command} pairs each program with a measurement (--measurement, in order): "
                            f"{len(found)} program(s), {len(measurements)} measurement(s)")
    for m in measurements:
        if not os.path.isfile(m):
            raise ManifestError(f"--measurement {m}: no such file")
    base = os.getcwd()
    meas = measurements or [None] * len(found)
    jobs = [Job("", command, p, t, m, (), base, "command line") for p, m in zip(found, meas) for t in (twins or [None])]
    return check_jobs(jobs)


def check_jobs(jobs: list[Job]) -> list[Job]:
    """Refuse a job listed twice; give every job a name of its own (its folder)."""
    from dataclasses import replace

    seen: dict = {}
    for j in jobs:
        k = j.key()
        if k in seen:
            raise ManifestError(f"{j.origin}: duplicate job: {j.program} on {j.twin or 'the default machine'} "
                                f"with the same measurement and options as {seen[k]}")
        seen[k] = j.origin
    names: dict = {}
    out = []
    for j in jobs:
        name = _safe(j.name) if j.name else f"{_safe(Path(j.program).stem)}@{_safe(j.machine)}"
        if j.name and name.lower() in names:  # (case-folded: one folder on macOS and Windows)
            raise ManifestError(f"{j.origin}: the job name {j.name!r} is taken by {names[name.lower()]}")
        n, k = name, 2
        while n.lower() in names:
            n, k = f"{name}-{k}", k + 1
        names[n.lower()] = j.origin
        out.append(replace(j, name=n))
    return out


def _safe(text: str) -> str:
    """A folder name: letters, digits and ._-@ kept, the rest one underscore."""
    return re.sub(r"[^A-Za-z0-9._@-]+", "_", text).strip("_.") or "job"


def read_recipe(path: str) -> tuple:
    """A calibration procedure: ``[[step]]`` tables, each with the ``options`` of one
    ``mtwin calibrate`` run (a string or a list); each step starts from the twin file the step
    before wrote — the procedure run on every machine of a batch calibrate."""
    from ..config import tomllib

    try:
        from ..io import read_input

        doc = tomllib.loads(read_input(path, "manifest").decode("utf-8"))
    except OSError as exc:
        raise ManifestError(f"cannot read the recipe {path}: {exc.strerror or exc}") from None
    except (UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise ManifestError(f"{path}: not a TOML recipe: {exc}") from None
    unknown = [k for k in doc if k not in ("step", "description")]
    steps = doc.get("step")
    if unknown or not (isinstance(steps, list) and steps and all(isinstance(x, dict) for x in steps)):
        raise ManifestError(f"{path}: a recipe is [[step]] tables with options (and a description)")
    out = []
    for k, st in enumerate(steps, start=1):
        bad = [x for x in st if x not in ("options", "description")]
        if bad:
            raise ManifestError(f"{path}: step {k}: unknown key {bad[0]!r} (options, description)")
        o = st.get("options", "")
        try:
            opts = tuple(o) if isinstance(o, list) and all(isinstance(x, str) for x in o) else tuple(shlex.split(o))
        except (TypeError, AttributeError, ValueError):
            raise ManifestError(f"{path}: step {k}: options must be a string or a list of strings") from None
        own_options(opts, f"{path}: step {k}")
        out.append(opts)
    return tuple(out)
